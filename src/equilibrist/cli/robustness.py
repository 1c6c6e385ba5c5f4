"""``equilibrist robustness``: RealAIGym's robustness families of one controller, in seconds."""

from __future__ import annotations

import argparse

from equilibrist.cli import common
from equilibrist.errors import UsageError

_EPILOG = """\
The families of RealAIGym's robustness benchmark (its v2 leaderboards), each
run on the compiled batch: the model's parameters one at a time over their
ranges (the rig's list where the system is the DFKI rig, else each physical
parameter from 0.75 to 1.25 times its value), velocity noise (0 to 0.5 rad/s,
--repetitions runs each), torque noise (0 to 1.1 N m), the motor's torque
response (k from 0.1 to 2), the measurement's delay (0 to 40 ms) and random
torque pulses on every joint (--perturbation-runs runs); and, beside them,
velocity noise through a low-pass filter (--filter-cutoff Hz). A run succeeds
when its final state is within 0.35 of the goal in each position (an angle
modulo a turn) and 1 in each velocity. Scores as the benchmark's: the share
of successes, and for the noise families the share of noise levels where
more than half the runs succeed. Runs last --duration seconds (default 10) at
--rate Hz (default 500, one RK4 step per period), from --x0 (default: hanging
at rest for a swing-up, else where the controller's plan starts, else the
operating point), with no fall region. docs/robustness.md says where this
differs from the benchmark.

--json prints every family's values, successes and score; --plot FILE.png
draws the scores and the model's per-parameter curves.
"""


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from equilibrist.study.robustness import FAMILIES

    p = sub.add_parser("robustness", help="RealAIGym's robustness scorecard of a controller",
                       description=__doc__, epilog=_EPILOG,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    common.add_system(p)
    common.add_controller(p, "simulate", default=None,
                          help="the controller (default lqg)")
    p.add_argument("--rate", default="500", metavar="HZ", help="control rate [Hz] (default 500)")
    p.add_argument("--duration", default="10", metavar="S", help="seconds per run (default 10)")
    common.add_items(p, "--x0", marker="=", metavar="NAME=VALUE", help="the runs' start")
    p.add_argument("--repetitions", default="10", metavar="N",
                   help="runs per noise level (default 10)")
    p.add_argument("--perturbation-runs", default="50", metavar="N",
                   help="runs with random pulses (default 50)")
    p.add_argument("--filter-cutoff", default="50", metavar="HZ",
                   help="the filtered velocity noise family's cutoff (default 50)")
    p.add_argument("--families", metavar="NAME,...",
                   help=f"the families to run (default all: {', '.join(FAMILIES)})")
    p.add_argument("--seed", default="0", metavar="N", help="the noise's seed (default 0)")
    p.add_argument("--workers", metavar="N", help="threads (default all cores)")
    p.add_argument("--plot", metavar="FILE.png", help="draw the scorecard")
    common.add_set(p)
    common.add_params(p)
    common.add_design_options(p)
    common.add_json(p)
    # What simulate's controller construction reads and this command fixes.
    p.set_defaults(func=run, physics_step=None, integrator="rk4", plant="nonlinear", delay=False,
                   noise="off", reference=None, push=[], kick=[], change=[], max_steps="inf",
                   out=None, no_progress=True)


def run(args: argparse.Namespace) -> int:
    from equilibrist.cli.simulate import build_run, controller_name, parse_x0, start_of
    from equilibrist.controllers import kinds
    from equilibrist.study.robustness import FAMILIES, robustness

    plot = None if args.plot is None else common.check_output_path(args.plot, "--plot")
    families = common.parse_names(args.families, "--families") or FAMILIES
    unknown = [f for f in families if f not in FAMILIES]
    if unknown:
        raise UsageError(f"--families {args.families!r}: {', '.join(unknown)} unknown; "
                         f"expected some of {', '.join(FAMILIES)}")
    repetitions = common.parse_whole(args.repetitions, "--repetitions")
    perturbation_runs = common.parse_whole(args.perturbation_runs, "--perturbation-runs")
    workers = None if args.workers is None else common.parse_whole(args.workers, "--workers")
    seed = common.parse_whole(args.seed, "--seed", minimum=0)
    cutoff = common.parse_number(args.filter_cutoff, "--filter-cutoff")
    if cutoff <= 0:
        raise UsageError(f"--filter-cutoff {args.filter_cutoff}: expected a frequency > 0")
    system, options = build_run(args)
    x0: dict[str, float] = start_of(options, parse_x0(args.x0))
    kind = kinds.get(controller_name(args, system), "simulate")
    if not x0 and kind.task is not None and system.spec.hanging:
        x0 = {name: float(value) for name, value in system.spec.hanging.items()}
    card = robustness(system, options["controller"], x0=x0 or None, rate=float(options["rate"]),
                      duration=float(options["duration"]), repetitions=repetitions,
                      perturbation_runs=perturbation_runs, filter_cutoff=cutoff,
                      families=families, seed=seed, workers=workers)
    if plot is not None:
        from equilibrist.viz.plots_robustness import plot_robustness

        plot_robustness(card.describe(), plot)
    if args.json:
        common.print_json({"controller": kind.name, **card.describe()})
        return 0
    rows = [(name, f"{score:.3f}") for name, score in card.scores.items()]
    print(f"{system.key}, {kind.name}: benchmark score {card.benchmark_score:.3f} "
          f"({card.elapsed:.1f} s)")
    print(common.format_table(("family", "score"), rows))
    if plot is not None:
        print(f"saved {plot}")
    return 0
