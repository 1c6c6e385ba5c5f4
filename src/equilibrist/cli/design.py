"""``equilibrist design``: LQR, Kalman filter and reference gain at the canonical point."""

from __future__ import annotations

import argparse

from equilibrist.cli import common

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
    p.add_argument("--rate", metavar="HZ", help="sample rate of a discrete design [Hz]")
    common.add_design_options(p)
    common.add_set(p)
    common.add_params(p)
    common.add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from equilibrist.control.design import design

    system = common.load_system(args)
    rate = None if args.rate is None else common.parse_number(args.rate, "--rate")
    result = design(system, rate=rate, **common.design_options(args))
    if args.json:
        common.print_json(result.to_dict())
    else:
        print(result.summary())
    return 0
