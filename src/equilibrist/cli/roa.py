"""``equilibrist roa``: how far it can lean and how hard it can be pushed, from the real loop."""

from __future__ import annotations

import argparse
import math
import os
import sys
from typing import TYPE_CHECKING

from equilibrist.cli import common
from equilibrist.errors import UsageError

if TYPE_CHECKING:
    import numpy as np

    from equilibrist.numeric.system import System

_EPILOG = """\
Every figure comes from the sampled, saturated, nonlinear loop as 'simulate'
runs it (the compiled batch, --noise off by default here), each run --duration
seconds; a run is caught when it never leaves the system's region and ends
balanced (the fall region's angles within 0.1 rad of the operating point, their
rates within 0.5 rad/s).

--slice A,B: the two states of the slice (default: the first coordinate of the
system's region and its rate), the others at the operating point, over --range
A=LO:HI,B=LO:HI (absolute values; default the region's width for an angle and
three times that per second for its rate). The slice is sampled on a grid and
refined where neighbouring starts disagree, up to --samples runs.
max_tilt: the largest deviation of the slice's first state recovered from rest
on both sides; max_push: the largest impulse on the first input (its unit x s)
recovered from rest, both ways (an impulse J changes the velocities by B J).
rho_sampled: the largest level of the LQR's Riccati function dx' S dx below
which no run was lost (the least V of a lost start), an estimate: sampling
finds counterexamples, it proves nothing.
rho (LQR, and the LQG's state feedback): the largest level of dx' S dx on which
dV/dt is proven negative for the exact equations with the input's saturation,
by interval branch-and-bound (--certify off skips it; --boxes N caps its boxes).
It assumes the feedback acts continuously, without the estimator. It is then
checked: --falsify N runs start inside it (half on its surface), and every run
of the slice, tilt and push searches that starts inside counts;
counterexamples is how many of them fell (a certificate is reported only when
it is 0), coverage the share of the slice's caught area inside it.
--json prints the figures; --plot FILE.png draws the slice; --out FILE.parquet
keeps every run's start and outcome.

Work is bounded: when the most runs the analysis may start (the slice's --samples,
the tilt's and the push's searches, the --falsify runs) need more than --max-steps
physics steps (default 1e10; runs x duration x rate x physics steps per period),
it is refused before any run, with the count and the least time it would take;
--max-steps N (or inf) asks for it anyway. A progress bar of each batch of runs
and of the certificate's boxes shows on a terminal's stderr (not with --json to a
pipe, nor with --no-progress).
"""

#: The runs of the tilt's and the push's searches: each both ways, 3 rounds of 32
#: (:func:`equilibrist.sim.roa.max_tilt`, :func:`~equilibrist.sim.roa.max_push`).
SEARCH_RUNS = 2 * 2 * 3 * 32
#: The slice's first grid, run whatever --samples (:func:`equilibrist.sim.roa.estimate_slice`).
FIRST_GRID_RUNS = (24 + 1) ** 2


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = common.command(
        sub, "roa", help="region of attraction: the largest tilt and push recovered, a slice",
        description="Estimate the region of attraction of a closed loop from the real loop: "
        "a 2-D slice refined along its boundary, the largest tilt and the largest push.",
        epilog=_EPILOG)
    common.add_system(p)
    common.add_controller(p, "simulate", default=None,
                          help="the controller (default lqg, lqr shown best with --noise off)")
    p.add_argument("--rate", metavar="HZ", help="controller rate (default the system's)")
    p.add_argument("--noise", choices=("on", "off"), default="off",
                   help="the rig's noise in the runs (default off)")
    p.add_argument("--slice", metavar="A,B", help="the slice's two states")
    p.add_argument("--range", metavar="A=LO:HI,B=LO:HI", help="the slice's bounds (absolute)")
    p.add_argument("--samples", default="100000", metavar="N",
                   help="most runs of the slice (default 100000)")
    p.add_argument("--duration", default="3", metavar="S", help="seconds per run (default 3)")
    p.add_argument("--physics-step", metavar="S",
                   help="integration step [s], dividing 1/rate (default as simulate: at most 1 ms)")
    p.add_argument("--seed", default="0", metavar="N", help="noise seed (default 0)")
    p.add_argument("--certify", choices=("on", "off"), default="on",
                   help="prove a level of the LQR's V (default on, for lqr and lqg)")
    p.add_argument("--boxes", default="1000000", metavar="N",
                   help="most boxes of the certificate's branch-and-bound (default 1000000)")
    p.add_argument("--falsify", default="2000", metavar="N",
                   help="runs started inside the certified level to check it (default 2000)")
    p.add_argument("--plot", metavar="FILE.png", help="draw the slice")
    p.add_argument("--out", metavar="FILE.parquet", help="every run's start and outcome")
    p.add_argument("--max-steps", metavar="N",
                   help="the most physics steps the analysis may take, over all its runs "
                   "(default 1e+10; 'inf' for no bound): more is refused before any run, with "
                   "the count and an estimate of the time")
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    common.add_design_options(p)
    common.add_set(p)
    common.add_params(p)
    common.add_json(p)
    p.set_defaults(func=run)


def _slice(system: System, text: str | None) -> tuple[str, str]:
    if text is None:
        from equilibrist.sim.roa import default_slice

        pair = default_slice(system)
        if pair is None:
            raise UsageError(f"{system.key} states no fall region: give --slice A,B")
        return pair
    names = common.parse_names(text, "--slice")
    assert names is not None
    if len(names) != 2 or names[0] == names[1]:
        raise UsageError(f"--slice {text!r}: expected two different states A,B")
    for n in names:
        if n not in system.state_names:
            raise UsageError(f"--slice: {system.key} has no state {n!r} (its states: "
                                    f"{', '.join(system.state_names)})")
    return names[0], names[1]


def _bounds(system: System, states: tuple[str, str], x_op: np.ndarray,
            text: str | None) -> tuple[tuple[float, float], tuple[float, float]]:
    from equilibrist.sim.roa import default_bounds

    out = default_bounds(system, states, x_op)
    if text is not None:
        for item, value in common.parse_assignments(text.split(","), "--range").items():
            if item not in states:
                raise UsageError(f"--range {item}: not a state of the slice "
                                        f"({', '.join(states)})")
            lo_t, sep, hi_t = value.partition(":")
            lo = common.parse_number(lo_t, f"--range {item}")
            hi = common.parse_number(hi_t, f"--range {item}") if sep else math.nan
            if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
                raise UsageError(f"--range {item}={value}: expected LO:HI, LO < HI")
            out[item] = (lo, hi)
    missing = [s for s in states if s not in out]
    if missing:
        raise UsageError(f"--range: give the bounds of {', '.join(missing)} "
                                "(A=LO:HI,B=LO:HI)")
    return out[states[0]], out[states[1]]


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from equilibrist.cli.simulate import parse_max_steps, show_progress
    from equilibrist.controllers import kinds
    from equilibrist.sim.noise import Noise
    from equilibrist.sim.roa_report import analyse

    if args.out is not None and not args.out.lower().endswith(".parquet"):
        raise UsageError(f"--out {args.out!r}: expected FILE.parquet")
    if args.plot is not None and not args.plot.lower().endswith(".png"):
        raise UsageError(f"--plot {args.plot!r}: expected FILE.png")
    samples = common.parse_whole(args.samples, "--samples", 100)
    boxes = common.parse_whole(args.boxes, "--boxes", 1000)
    falsify = common.parse_whole(args.falsify, "--falsify", 0)
    seed = common.parse_whole(args.seed, "--seed", 0)
    max_steps = parse_max_steps(args.max_steps)
    duration = common.parse_positive(args.duration, "--duration")
    system = common.load_system(args)
    if system.n_inputs == 0:
        raise UsageError(f"{system.key} has no input: there is no loop to catch anything")
    rate = (common.parse_positive(args.rate, "--rate") if args.rate is not None
            else float(system.spec.control_rate))
    name = args.controller or "lqg"
    kind = kinds.get(name, "simulate")
    if kind.open_loop:
        raise UsageError("--controller none is the open loop: it catches nothing")
    request = kinds.ControllerRequest(system=system, rate=rate,
                                      design_options=common.design_options(args),
                                      options=common.controller_options(args, name, "simulate"))
    controller = kind.make(request)
    states = _slice(system, args.slice)
    eq = system.operating_point()
    x_op, u_op = np.asarray(eq.x, dtype=float), np.asarray(eq.u, dtype=float)
    bounds = _bounds(system, states, x_op, args.range)
    noise = None
    if args.noise == "on":
        from equilibrist.control.controller import measured_outputs

        noise = (Noise.from_design(request.design()) if kind.noise == "design"
                 else Noise.from_spec(system, outputs=measured_outputs(controller), rate=rate))
    # The batches' bound is the whole analysis's, checked here: none of them passes it.
    options: dict[str, object] = {"duration": duration, "rate": rate, "noise": noise,
                                  "max_steps": max_steps,
                                  "progress": show_progress(args) and sys.stderr.isatty()}
    step = None
    if args.physics_step is not None:
        step = common.parse_positive(args.physics_step, "--physics-step")
        options["physics_step"] = step
    runs = max(samples, FIRST_GRID_RUNS) + SEARCH_RUNS + (falsify if args.certify == "on" else 0)
    _check_work(runs, duration=duration, rate=rate, physics_step=step, max_steps=max_steps)
    report = analyse(system, controller, states=states, bounds=bounds, x_op=x_op, u_op=u_op,
                     samples=samples, boxes=boxes if args.certify == "on" else None,
                     falsify=falsify, seed=seed, options=options, name=name)
    est, x0s, caught, figures = report.est, report.x0s, report.caught, report.figures
    figures.update({"duration": duration, "rate": rate, "noise": args.noise,
                    "physics_step": options.get("physics_step")})
    if args.out is not None:
        _write_parquet(args.out, system, x0s, caught)
    if args.plot is not None:
        from equilibrist.viz.plots_maps import plot_roa_slice

        plot_roa_slice(report, args.plot)
    if args.json:
        common.print_json(figures)
        return 0
    f = figures
    print(f"{system.key}, {name}: {est.samples} starts of the slice {states[0]}, {states[1]} "
          f"({est.levels} refinements), {est.fraction_caught:.1%} caught")
    print(f"  largest tilt recovered: {f['max_tilt']:.4g} {f['tilt_unit']} (down "
          f"{f['max_tilt_down']:.4g}, up {f['max_tilt_up']:.4g})")
    print(f"  largest push recovered: {f['max_push']:.4g} {f['push_unit']} "
          f"(negative {f['max_push_negative']:.4g}, positive {f['max_push_positive']:.4g})")
    if f["rho_sampled"] is not None:
        print(f"  largest level of dx' S dx no run falsifies: {f['rho_sampled']:.4g} (an estimate)")
    if figures["certified"]:
        print(f"  certified level of dx' S dx: {figures['rho']:.4g} ({figures['method']}; "
              f"assumes {figures['certificate']['assumes']}); limited by "
              f"{figures['certificate']['limited_by']}; {figures['falsify_runs']} runs inside "
              f"it, {figures['counterexamples']} fell; it covers {figures['coverage']:.1%} of "
              "the slice's caught area")
    elif figures["certificate_note"]:
        print(f"  no certificate: {figures['certificate_note']}")
    return 0


def _check_work(runs: int, *, duration: float, rate: float, physics_step: float | None,
                max_steps: float | None) -> None:
    """Refuse, before any run, an analysis of at most *runs* runs that may take more than
    *max_steps* physics steps; the advice names this command's options."""
    from equilibrist.errors import SimulationError
    from equilibrist.sim.budget import check_steps
    from equilibrist.sim.integrators import DEFAULT
    from equilibrist.sim.setup_steps import timing

    problems: list[str] = []  # a physics step that does not divide the period: the runs say so
    _h, n_sub, n_samples = timing(rate, duration, physics_step, DEFAULT, runs=runs, bound=None,
                                  threads=1, problems=problems)
    if n_sub is None or n_samples is None:
        return
    too_many = check_steps(
        float(n_samples) * n_sub * runs, f"the analysis, at most {runs} runs,", max_steps,
        os.cpu_count() or 1,
        advice="use a larger --physics-step, a shorter --duration or fewer --samples, or ask "
        "for it anyway with --max-steps {steps}")
    if too_many:
        raise SimulationError(too_many)


def _write_parquet(path: str, system: System, x0s: np.ndarray, caught: np.ndarray) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    from equilibrist.atomic import atomic_path

    cols = {f"{n}_0": x0s[:, i] for i, n in enumerate(system.state_names)}
    cols["caught"] = caught
    with atomic_path(path) as tmp:
        pq.write_table(pa.table(cols), str(tmp))
