"""``equilibrist batch``: many runs at once, on all cores.

``--runs N [--x0 NAME=LOW:HIGH ...] [--spread PARAM=REL ...]`` plus every
option of ``equilibrist simulate`` (a contract with outside scripts).
"""

from __future__ import annotations

import argparse

from equilibrist.cli import common
from equilibrist.cli.simulate import _seed, add_run_options, build_run, check_out, show_progress
from equilibrist.errors import UsageError

_EPILOG = """\
Run i starts from initial states drawn uniformly from the --x0 ranges
(NAME=LOW:HIGH; NAME=VALUE fixes a component) with the plant's parameters
drawn uniformly within nominal * (1 +- REL) for each --spread PARAM=REL; the
controller keeps its nominal design. Draws and noise come from --seed. A
spread is checked as a whole before anything runs: its range must stay within
the parameter's valid range (REL < 1 for a parameter that must stay positive).
--json prints {"runs", "stayed_up", "fraction_up", "steps_per_second", ...};
--out FILE.npz saves every run's initial state, parameters and outcome;
--out FILE.csv writes them as a table, one row per run (run, the initial
states NAME_0, the parameters, fell, fell_at, peak_INPUT, rms_INPUT,
time_saturated, peak_dev_STATE). --max-steps bounds runs x physics steps.
"""


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = common.command(
        sub, "batch",
        help="run many simulations at once (initial states, parameters, seeds)",
        description="Run N closed-loop simulations with random initial states and "
        "perturbed parameters, in parallel.",
        epilog=_EPILOG)
    add_run_options(p)
    common.add_rig_options(p)
    p.add_argument("--runs", required=True, metavar="N", help="number of runs")
    common.add_items(p, "--spread", marker="=", metavar="PARAM=REL",
                   help="relative spread of a parameter (uniform)")
    p.add_argument("--workers", metavar="N", help="threads (default: all cores)")
    p.add_argument("--trajectories", action="store_true",
                   help="keep every run's trajectory in memory (checked before it starts)")
    p.set_defaults(func=run)


def _count(text: str, option: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise UsageError(f"{option} {text!r}: expected a whole number >= 1") from None
    if v < 1:
        raise UsageError(f"{option} {text!r}: expected a whole number >= 1")
    return v


def _ranges(items: list[str]) -> dict[str, tuple[float, float]]:
    out: dict[str, tuple[float, float]] = {}
    for name, text in common.parse_assignments(items, "--x0").items():
        lo, sep, hi = text.partition(":")
        low = common.parse_number(lo, f"--x0 {name}")
        high = common.parse_number(hi, f"--x0 {name}") if sep else low
        if low > high:
            raise UsageError(f"--x0 {name}={text}: LOW must not exceed HIGH")
        out[name] = (low, high)
    return out


def run(args: argparse.Namespace) -> int:
    from equilibrist.cli.simulate import start_of
    from equilibrist.sim.batch import simulate_batch
    from equilibrist.sim.batch_inputs import child_seed, sample_uniform
    from equilibrist.sim.noise import seed_sequence
    from equilibrist.sim.setup_checks import operating_point

    runs = _count(args.runs, "--runs")
    workers = None if args.workers is None else _count(args.workers, "--workers")
    check_out(args, "a batch")
    system, options = build_run(args)
    spread = {k: common.parse_number(v, f"--spread {k}")
              for k, v in common.parse_assignments(args.spread, "--spread").items()}
    base = seed_sequence(_seed(args.seed))
    x_op, _ = operating_point(system, options["controller"])
    # A tracked plan's runs start where the plan starts (the states no --x0 range names).
    planned = start_of(options, {})
    if planned:
        x_op = x_op.copy()
        for i, name in enumerate(system.state_names):
            x_op[i] = float(planned.get(name, x_op[i]))
    x0s, params = sample_uniform(system, runs, ranges=_ranges(args.x0), spread=spread,
                                 seed=child_seed(base, 0), x_op=x_op)
    options["seed"] = child_seed(base, 1)
    options.pop("outputs")
    batch = simulate_batch(system, runs=runs, x0=x0s, params=params, workers=workers,
                           record=args.trajectories, progress=show_progress(args), **options)
    saved = batch.save(args.out) if args.out is not None else None
    summary = batch.summary()
    summary["seed"] = _seed(args.seed)
    if "rig" in batch.settings:
        summary["rig"] = batch.settings["rig"]
    if args.json:
        if saved is not None:
            summary["saved"] = str(saved)
        common.print_json(summary)
        return 0
    print(f"{system.key}: {batch.stayed_up} of {runs} runs stayed up "
          f"({100 * batch.fraction_up:.1f} %), "
          f"{batch.steps_per_second / 1e6:.1f} M steps/s")
    if saved is not None:
        print(f"saved {saved}")
    return 0
