"""``equilibrist linkage``: the servo-to-platform four-bar linkage of the ball-balancing rig."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

from equilibrist.cli import common
from equilibrist.errors import UsageError

LENGTHS = ("a", "b", "c", "d", "e")


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "linkage",
        help="four-bar linkage: platform angle from motor angle, or the reverse",
        description="Solve the four-bar linkage between the servo and the ball-balancing "
        "platform exactly (loop closure), with the rate ratio d theta / d phi and the seed's "
        "near-parallelogram approximation for comparison. Angles in radians from +x, "
        "counter-clockwise; lengths in metres.",
    )
    p.add_argument("--geometry", required=True, metavar="a=..,b=..,c=..,d=..,e=..",
                   help="motor axis at (-a, 0), platform pivot at (0, b), hinge at c from the "
                   "pivot, motor arm d, coupler e")
    given = p.add_mutually_exclusive_group(required=True)
    given.add_argument("--motor-angle", metavar="THETA", help="solve the platform angle from this")
    given.add_argument("--platform-angle", metavar="PHI", help="solve the motor angle from this")
    p.add_argument("--branch", choices=("plus", "minus"),
                   help="assembly branch (default: the working pose, plus for the platform "
                   "angle, minus for the motor angle)")
    common.add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from equilibrist.mechanics.linkage import FourBar

    raw = common.parse_assignments(args.geometry.split(","), "--geometry")
    unknown = sorted(set(raw) - set(LENGTHS))
    missing = [n for n in LENGTHS if n not in raw]
    problems = []
    if unknown:
        problems.append(f"unknown length(s) {', '.join(unknown)}")
    if missing:
        problems.append(f"missing {', '.join(missing)}")
    if problems:
        raise UsageError(f"--geometry: {'; '.join(problems)} (expected a, b, c, d, e)")
    bar = FourBar(**{n: common.parse_number(raw[n], f"--geometry {n}") for n in LENGTHS})
    if args.motor_angle is not None:
        theta = common.parse_number(args.motor_angle, "--motor-angle")
        branch = args.branch or "plus"
        phi = float(bar.platform_angle(theta, branch=branch))
        approx = _approximate(lambda: bar.approximate_platform_angle(theta, branch=branch))
        solved, exact, label = "phi", phi, "platform angle"
    else:
        phi = common.parse_number(args.platform_angle, "--platform-angle")
        branch = args.branch or "minus"
        theta = float(bar.motor_angle(phi, branch=branch))
        approx = _approximate(lambda: bar.approximate_motor_angle(phi, branch=branch))
        solved, exact, label = "theta", theta, "motor angle"
    ratio = float(bar.rate_ratio(theta, phi))
    out = {
        "geometry": {n: getattr(bar, n) for n in LENGTHS},
        "branch": branch,
        "theta": theta,
        "phi": phi,
        "rate_ratio": ratio,
        "approximate": {solved: approx, "error": None if approx is None else approx - exact},
        "residual": float(bar.closure_residual(theta, phi)),
    }
    if args.json:
        common.print_json(out)
        return 0
    print(f"{label} ({branch} branch): {solved} = {exact:.6g} rad ({math.degrees(exact):.4g} deg)")
    print(f"pose: theta = {theta:.6g} rad, phi = {phi:.6g} rad; loop closure residual {out['residual']:.2g}")
    print(f"rate ratio d theta / d phi = {ratio:.6g}")
    if approx is None:
        print("seed's near-parallelogram approximation: no pose (its closed form has no "
              "solution here, although the exact linkage reaches it)")
    else:
        print(f"seed's near-parallelogram approximation: {solved} = {approx:.6g} rad "
              f"(error {approx - exact:+.3g} rad)")
    return 0


def _approximate(solve: Callable[[], object]) -> float | None:
    """The seed's approximate answer, or None where its closed form has none."""
    from equilibrist.mechanics.linkage import UnreachablePoseError

    try:
        return float(solve())  # type: ignore[arg-type]
    except UnreachablePoseError:
        return None
