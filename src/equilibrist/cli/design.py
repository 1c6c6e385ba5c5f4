"""``equilibrist design``: LQR, Kalman filter and reference gain at the canonical point."""

from __future__ import annotations

import argparse

from equilibrist.cli import common

# The names of equilibrist.control.discretize.METHODS and kalman.FORMS,
# written out so that building the parser does not import scipy.
METHODS = ("zoh", "euler")
FORMS = ("current", "predictor")

_EPILOG = """\
Weights are diagonals, comma-separated: --q one value per state, --r one per
input, --qn one per state (QN = diag(qn), G = I), --rn one per measured
output (a list that starts with a minus sign is written --q=-1,2,...).
Defaults: Bryson's rule from the system's design scales and the spec's
sensor and process noise.

--json prints every matrix as a list of rows and every pole as
{"re": ..., "im": ...} (also when real); numbers that are not finite (an
infinite time constant) are null. Keys include K, S, poles, Kf, P, Kc
(null when the tracked output has zero DC gain; kc_note says why),
estimator_poles, Q, R, QN, RN, G, Qd, Rd, plant, discrete, margins.
"""


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "design",
        help="design LQR + Kalman (LQG) controllers at the canonical operating point",
        description="Design an LQR state feedback, a Kalman estimator and a reference gain "
        "for a system at its canonical operating point, continuous or sampled at --rate.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    common.add_system(p)
    p.add_argument("--q", metavar="Q1,Q2,...", help="LQR state weights, one per state")
    p.add_argument("--r", metavar="R1,...", help="LQR input weights, one per input")
    p.add_argument("--qn", metavar="QN1,...", help="process noise intensities, one per state")
    p.add_argument("--rn", metavar="RN1,...", help="measurement noise intensities, one per output")
    p.add_argument(
        "--outputs",
        metavar="NAME,...",
        help="measured outputs (state names); the first ones are tracked",
    )
    p.add_argument("--rate", metavar="HZ", help="sample rate of a discrete design [Hz]")
    p.add_argument(
        "--discretization",
        choices=METHODS,
        default="zoh",
        help="how the plant is sampled (default zoh)",
    )
    p.add_argument(
        "--kalman",
        choices=FORMS,
        default="current",
        help="discrete Kalman gain form (default current)",
    )
    common.add_set(p)
    common.add_json(p)
    p.set_defaults(func=run)


def _names(text: str | None, option: str) -> tuple[str, ...] | None:
    if text is None:
        return None
    parts = [t.strip() for t in text.split(",")]
    if not all(parts):
        raise common.UsageError(f"{option} {text!r}: expected comma-separated names")
    return tuple(parts)


def run(args: argparse.Namespace) -> int:
    from equilibrist.control.design import design

    system = common.load_system(args)
    rate = None if args.rate is None else common.parse_number(args.rate, "--rate")
    result = design(
        system,
        q=common.parse_vector(args.q, "--q"),
        r=common.parse_vector(args.r, "--r"),
        qn=common.parse_vector(args.qn, "--qn"),
        rn=common.parse_vector(args.rn, "--rn"),
        outputs=_names(args.outputs, "--outputs"),
        rate=rate,
        discretization=args.discretization,
        kalman_form=args.kalman,
    )
    if args.json:
        common.print_json(result.to_dict())
    else:
        print(result.summary())
    return 0
