"""``equilibrist demo``: the main job, a tour of the catalogue.

Designs each system's default controller, simulates a realistic run
(digital LQG, sensor noise, saturation, a push in the middle; the gyroscope
in a steady and a nutating precession), prints a short table and writes a
report folder with plots, an animation per system and an ``index.html``.
"""

from __future__ import annotations

import argparse
import sys
import time

from equilibrist.cli import common
from equilibrist.errors import UsageError


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "demo",
        help="a tour of the catalogue with a report folder (what 'make demo' runs)",
        description="Design each system's default controller, simulate a realistic run "
        "(digital LQG, sensor noise, saturation, a push in the middle), print a summary "
        "and write a report folder: plots, an animation per system and index.html.",
    )
    p.add_argument("system", nargs="?", metavar="SYSTEM",
                   help="one system only (default: the whole catalogue)")
    common.add_set(p)
    common.add_items(p, "--at", marker="=", metavar="STATE=VALUE",
                     help="design at the equilibrium with these states (the others solved) and "
                     "run the scenario about it; one SYSTEM only (default: its canonical point)")
    p.add_argument("--out", default="report", metavar="DIR",
                   help="report folder (default: ./report); its parent folder must exist, and "
                   "an existing folder is replaced only when it holds an earlier report and "
                   "nothing this one would lose")
    p.add_argument("--force", action="store_true",
                   help="replace the --out folder whatever it holds")
    p.add_argument("--size", default="400x300", metavar="WxH",
                   help="animation frame size in pixels (default 400x300)")
    p.add_argument("--jobs", default=None, metavar="N",
                   help="systems toured at once, one process each (default: the cores, at most 4)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from equilibrist.numeric.lookup import get_system
    from equilibrist.systems import registry
    from equilibrist.viz.cli_hooks import frame_size

    try:
        size = frame_size(args.size)
    except argparse.ArgumentTypeError as exc:
        raise UsageError(f"--size {exc}") from None
    if args.system is None:
        if args.settings:
            raise UsageError("--set needs a SYSTEM: parameters belong to one system")
        if args.at:
            raise UsageError("--at needs a SYSTEM: an operating point belongs to one system")
        systems = [get_system(name) for name in registry.family_names()]
    else:
        systems = [common.load_system(args)]
    at = common.operating_point_option(args.at)
    if at:
        _check_point(systems[0], at)
    import os

    if args.jobs is None:
        jobs = min(4, os.cpu_count() or 1)
    else:
        try:
            jobs = int(args.jobs)
        except ValueError:
            jobs = 0
        if jobs < 1:
            raise UsageError(f"--jobs {args.jobs!r}: expected a whole number >= 1")
    if not args.out.strip():
        raise UsageError("--out '': expected the report folder")
    out = Path(args.out)
    began = time.perf_counter()
    progress = sys.stderr.isatty()
    from equilibrist.apps.tour import run_tour
    from equilibrist.apps.tour_common import SUMMARY_HEADER

    def say(line: str) -> None:
        print(line, file=sys.stderr)

    def study(folder: Path) -> None:
        from equilibrist.study.demo import add_study_to_report

        add_study_to_report(folder, log=say)

    with_study = any(s.key == "cartpole" for s in systems)
    outcomes = run_tour(systems, out, size=size, jobs=jobs, progress=progress, log=say, at=at,
                        force=args.force, then=study if with_study else None,
                        then_writes=("study",) if with_study else ())
    print("Each system balanced by its default digital LQG controller (a Kalman filter on its")
    print("sensors, LQR feedback at the rig's sample rate) on the nonlinear model, with sensor")
    print("and process noise, actuator limits and a push halfway through the run:")
    print()
    print(common.format_table(SUMMARY_HEADER, [o.row for o in outcomes]))
    print()
    print("settling after push: time until the states that decide a fall are back near the")
    print("operating point; peak input: largest force or torque applied (share of its limit);")
    print("final error: the measured outputs at the end of the run, from their targets.")
    print(f"report with plots, animations and equations: {out / 'index.html'} "
          f"(made in {time.perf_counter() - began:.0f} s of wall time)")
    return 0


def _check_point(system: object, at: dict[str, float]) -> None:
    """Refuse, before the tour begins, an ``--at`` for a system without input or naming a
    state the system does not have (the design says when there is no equilibrium there)."""
    from equilibrist.numeric.system import System

    assert isinstance(system, System)
    if not system.n_inputs:
        raise UsageError(f"--at: {system.key} has no input, so no design to make at "
                                "another operating point")
    for name in at:
        system.state_index(name)  # an unknown state: named with the nearest ones
