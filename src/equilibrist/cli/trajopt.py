"""``equilibrist trajopt``: plan a swing-up (or any transfer) under the rig's limits.

Direct collocation (Hermite-Simpson) of the system's derived dynamics,
solved by IPOPT through CasADi with exact derivatives
(:mod:`equilibrist.control.trajopt`). The JSON keys ``converged``,
``duration``, ``cost``, ``peak_input``, ``max_defect``, ``solve_time``,
``iterations``, ``solver`` are a contract with scripts.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.cli import common
from equilibrist.errors import UsageError

if TYPE_CHECKING:
    from equilibrist.control.trajopt import Trajectory
    from equilibrist.numeric.system import System

_EPILOG = """\
By default the system's swing-up task (where it has one): from hanging at
rest to the operating point, within the task's bounds less --margin (default
0.3: the cart-pole plans within 70 % of its track |x| <= x_max, so that the
time-varying LQR that tracks the plan has room to correct a perturbed start)
and the input limits, in --duration seconds (default 5), with
the least effort (integral of (u / scale)^2, the inputs' Bryson scales).
--to NAME=VALUE,... plans a transfer to the operating point with those
components changed (from --from, by default the operating point).
--duration-max S frees the final time (up to S); --minimize time needs it.
--guess random (seeded by --seed) | straight | FILE.npz (an earlier plan; with
--duration-max its duration must be within [0.05, 1] x that bound).
--max-time S stops IPOPT after S seconds of wall-clock time (default 120,
the solver's set-up included). A plan that does not converge, or that
reaches --max-time, is one line on stderr and exit status 1 (nothing
written); Ctrl-C or SIGTERM stops it at IPOPT's next iteration ("equilibrist:
interrupted", exit status 130 or 143). Every output (--out, --plot,
--animate) is checked before the plan is solved. --out FILE.npz writes the
trajectory (times, states, inputs at the knots and midpoints, the system,
its parameters and the settings); a reader names its system and never runs
a Python system file it names, and refuses an array of more than 2,000,000
numbers before reading it (docs/trajopt.md).
"""


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from equilibrist.viz.cli_hooks import add_output_options

    p = common.command(
        sub, "trajopt",
        help="plan a swing-up or a transfer by direct collocation (CasADi + IPOPT)",
        description="Plan an optimal motion of a system under its input limits and its task's "
        "state bounds, by direct collocation of its derived dynamics.",
        epilog=_EPILOG)
    common.add_system(p)
    p.add_argument("--task", choices=("swingup",), help="the task planned (default swingup)")
    p.add_argument("--to", metavar="NAME=VALUE,...", help="a transfer to these state values")
    p.add_argument("--from", dest="start", metavar="NAME=VALUE,...",
                   help="with --to: where the transfer starts (default the operating point)")
    time_group = p.add_mutually_exclusive_group()
    time_group.add_argument("--duration", metavar="S", help="a fixed final time (default 5 s)")
    time_group.add_argument("--duration-max", metavar="S", help="a free final time, at most S")
    p.add_argument("--minimize", choices=("effort", "time"), default="effort")
    p.add_argument("--margin", metavar="FRACTION", default="0.3",
                   help="share of the task's state bounds kept free for the tracker to correct "
                   "in (default 0.3: the cart-pole plans within 70 %% of its track)")
    p.add_argument("--knots", default="60", metavar="N", help="collocation intervals (default 60)")
    p.add_argument("--seed", default="0", metavar="S", help="seed of a random guess (default 0)")
    p.add_argument("--guess", default="straight", metavar="random|straight|FILE",
                   help="the initial guess (default straight)")
    p.add_argument("--max-time", metavar="S", default="120",
                   help="wall-clock seconds the solve may take (default 120): a plan that "
                   "reaches it is not converged (exit status 1)")
    p.add_argument("--out", metavar="FILE.npz", help="write the trajectory")
    common.add_set(p)
    common.add_params(p)
    common.add_json(p)
    add_output_options(p)
    p.set_defaults(func=run)


def _count(text: str, option: str, low: int, high: int) -> int:
    try:
        v = int(text)
    except ValueError:
        raise UsageError(f"{option} {text!r}: expected a whole number from {low} to {high}") from None
    if not low <= v <= high:
        raise UsageError(f"{option} {text!r}: expected a whole number from {low} to {high}")
    return v


def _states(system: System, text: str, option: str, base: np.ndarray) -> np.ndarray:
    x = base.copy()
    items = [t for t in text.split(",") if t.strip()]
    if not items:
        raise UsageError(f"{option} {text!r}: expected NAME=VALUE,...")
    for name, value in common.parse_assignments(items, option).items():
        if name not in system.state_names:
            from equilibrist.errors import nearest

            raise UsageError(f"{option}: unknown state {name!r}: {nearest(name, system.state_names)}")
        x[system.state_index(name)] = common.parse_number(value, f"{option} {name}")
    return x


def _check_outputs(args: argparse.Namespace) -> None:
    """Every output named (--out, --plot, --animate), before any work: a file name whose
    folder exists and takes new files (:func:`common.check_output_path`), not a folder."""
    if args.out is not None and (not args.out.strip() or Path(args.out).suffix.lower() != ".npz"):
        raise UsageError(f"--out {args.out!r}: expected a trajectory file NAME.npz")
    for option, value in (("--out", args.out), ("--plot", args.plot), ("--animate", args.animate)):
        if value is None:
            continue
        path = common.check_output_path(str(value), option)
        folder = path.parent
        if not os.access(folder, os.W_OK | os.X_OK):
            raise UsageError(f"{option} {path}: the folder {folder} is not writable")


def run(args: argparse.Namespace) -> int:
    from equilibrist.control.trajectory_file import load_trajectory
    from equilibrist.control.trajopt import TIMED_OUT, check_guess, plan, require_casadi

    require_casadi()
    knots = _count(args.knots, "--knots", 4, 2000)
    seed = _count(args.seed, "--seed", 0, 2**63 - 1)
    max_time = common.parse_number(args.max_time, "--max-time")
    if not 0 < max_time <= 1e6:
        raise UsageError(f"--max-time {args.max_time}: expected seconds in (0, 1000000]")
    _check_outputs(args)
    if args.minimize == "time" and args.duration_max is None:
        raise UsageError("--minimize time needs a free final time: give --duration-max S")
    if args.start is not None and args.to is None:
        raise UsageError("--from is the start of a transfer: give --to as well")
    if args.task is not None and args.to is not None:
        raise UsageError("--task and --to are two kinds of plan: give one")
    duration = duration_max = None
    if args.duration_max is not None:
        duration_max = common.parse_number(args.duration_max, "--duration-max")
    else:
        duration = common.parse_number(args.duration or "5", "--duration")
    for name, v in (("--duration", duration), ("--duration-max", duration_max)):
        if v is not None and not 0 < v <= 1e4:
            raise UsageError(f"{name} {v:g}: expected seconds in (0, 10000]")
    system = common.load_system(args)
    if system.n_inputs == 0:
        raise UsageError(f"{system.key} has no input: there is no motion to plan")
    guess: str | Trajectory = args.guess
    if args.guess not in ("random", "straight"):
        guess = load_trajectory(args.guess)
        if guess.state_names != system.state_names or guess.input_names != system.input_names:
            raise UsageError(f"--guess {args.guess}: a trajectory of other states or inputs")
        check_guess(guess, n=system.n_states, m=system.n_inputs, duration_max=duration_max,
                    what=f"--guess {args.guess}", bound="--duration-max")
    x_op = system.operating_point().x
    if args.to is not None:
        start = x_op if args.start is None else _states(system, args.start, "--from", x_op)
        goal = _states(system, args.to, "--to", x_op)
        bounds: dict[str, tuple[float, float]] = {}
    else:
        from equilibrist.tasks import get_task, task_names

        if "swingup" not in task_names(system):
            raise UsageError(f"{system.key} has no swing-up task (it states no hanging "
                                    "pose): give --to NAME=VALUE,... for a transfer")
        task = get_task(system, "swingup")
        from equilibrist.tasks import planning_bounds

        margin = common.parse_number(args.margin, "--margin")
        if not 0.0 <= margin < 1.0:
            raise UsageError(f"--margin {args.margin}: expected a fraction in [0, 1)")
        start, goal, bounds = task.start, task.x_op, planning_bounds(task, margin)
    traj = plan(system, start=start, goal=goal, knots=knots, duration=duration,
                duration_max=duration_max, minimize=args.minimize, guess=guess, seed=seed,
                bounds=bounds, max_time=max_time)
    summary = traj.summary()
    if args.json:
        common.print_json(summary)
    if traj.status == TIMED_OUT:
        print(f"equilibrist: the plan reached --max-time {max_time:g} s before it converged "
              f"({traj.iterations} iterations, largest defect {traj.max_defect:.3g}): give a "
              "larger --max-time, fewer --knots or another --guess", file=sys.stderr)
        return 1
    if not traj.converged:
        print(f"equilibrist: the plan did not converge ({traj.iterations} iterations, largest "
              f"defect {traj.max_defect:.3g}): try more --knots, a longer --duration or another "
              "--guess", file=sys.stderr)
        return 1
    written = traj.save(args.out) if args.out is not None else None
    _pictures(args, system, traj)
    if not args.json:
        print(f"{system.key}: planned in {traj.solve_time:.2f} s of CPU ({traj.iterations} "
              f"iterations of {traj.solver}): {traj.duration:.3g} s, cost {traj.cost:.6g}, peak "
              + ", ".join(f"{k} {v:.4g}" for k, v in traj.peak_input.items())
              + f", largest defect {traj.max_defect:.2g}")
        if written is not None:
            print(f"wrote {written}")
    return 0


def _pictures(args: argparse.Namespace, system: System, traj: Trajectory) -> None:
    if args.plot is None and args.animate is None:
        return
    t = np.linspace(traj.times[0], traj.times[-1], max(200, 10 * traj.knots + 1))
    x = np.column_stack([np.interp(t, traj.times, traj.states[:, i]) for i in range(system.n_states)])
    u = traj.input_at(t).reshape(t.size, system.n_inputs)
    if args.plot is not None:
        from equilibrist.viz.plots_runs import plot_response
        from equilibrist.viz.runs import Run

        run = Run.from_arrays(system, t, x, u=u, label="planned")
        plot_response(run, args.plot)
        print(f"wrote {args.plot}")
    if args.animate is not None:
        from equilibrist.viz.animation import animate

        animate(system, t, x, args.animate, inputs=u, fps=args.fps, max_frames=args.max_frames,
                width=args.size[0], height=args.size[1])
        print(f"wrote {args.animate}")
