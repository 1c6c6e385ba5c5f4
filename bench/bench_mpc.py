"""MPC: solve time per sample against the control period, python-control's MPC, regions of attraction.

1. Cart-pole, 200 Hz, horizon 30: closed-loop runs from starts that drive
   the input into its limits and the cart towards the end of its track;
   every sample's solve time (wall clock and this process's CPU time),
   median and worst, against the 5 ms period. Samples whose LQR trajectory
   meets every constraint are answered exactly without the solver (counted
   apart).
2. The same QP (horizon 30, Q, R, terminal cost S, input bounds) solved
   by python-control's ``control.optimal.solve_ocp`` (the optimizer behind
   ``create_mpc_iosystem``): time per step and the first move against ours.
3. Regions of attraction (cart-pole at 50 Hz, horizon 40 = 0.8 s, track
   constrained to 0.95 m; fall region ``|x| > 1 m`` or ``|theta| > 1.2``):
   a grid of starts (cart at the centre, initial cart speed x pole angle),
   clipped LQR and MPC side by side, saved as ``docs/images/mpc_roa.png``.

``--solve-only`` runs part 1 alone, timing each sample's solve by this
thread's CPU time (``time.thread_time``: what the solver itself costs,
whatever else runs on the machine) and by the wall clock, and reports the
median, the 99th percentile and the worst of both against the 5 ms period,
with DAQP's iteration count (median, worst), how many solves ended at its
cap and how many samples fell back to the clipped LQR.

    python bench/bench_mpc.py [--json] [--grid 9] [--no-figure] [--solve-only] [--repeat 1]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import time
from pathlib import Path

import numpy as np

from equilibrist import get_system
from equilibrist.control.design import design
from equilibrist.control.mpc import mpc
from equilibrist.control.mpc_runtime import MPCRuntime
from equilibrist.sim.run import simulate

ROOT = Path(__file__).resolve().parents[1]


class _Timed(MPCRuntime):
    """The MPC runtime timing each sample's whole solve (wall clock and this thread's CPU)."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.cpu_times: list[float] = []
        self.wall_times: list[float] = []
        self.statuses: list[str] = []
        self.iterations: list[int] = []

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        c0, w0 = time.thread_time(), time.perf_counter()
        u = super().output(t, y, r)
        w1, c1 = time.perf_counter(), time.thread_time()
        self.cpu_times.append(c1 - c0)
        self.wall_times.append(w1 - w0)
        self.statuses.append(self.last_status)
        self.iterations.append(self.last_iterations)
        return u


STARTS = [{"theta": 0.5}, {"theta": -0.4, "theta_dot": 1.0}, {"x_dot": 2.0},
          {"x": 0.6, "x_dot": 1.5, "theta": 0.1}]


def _ms(values: list[float]) -> dict[str, float]:
    a = 1e3 * np.asarray(values)
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99)),
            "worst": float(a.max())}


def solve_times(horizon: int = 30, repeat: int = 1) -> dict[str, object]:
    """Per-sample solve times only (thread CPU and wall), *repeat* passes over the starts."""
    import os

    from equilibrist.native.daqp_library import ITER_LIMIT

    system = get_system("cartpole")
    d = design(system, rate=200.0)
    ctrl = mpc(system, design=d, horizon=horizon, estimator="state")
    cpu: list[float] = []
    wall: list[float] = []
    qp_cpu: list[float] = []
    qp_wall: list[float] = []
    iters: list[int] = []
    fallbacks = 0
    for _ in range(repeat):
        for x0 in STARTS:
            rt = _Timed(ctrl)
            simulate(system, rt, duration=2.0, x0=x0, region={})
            fallbacks += rt.fallbacks
            cpu += rt.cpu_times
            wall += rt.wall_times
            for c, w, st, it in zip(rt.cpu_times, rt.wall_times, rt.statuses, rt.iterations,
                                    strict=True):
                if st != "unconstrained":
                    qp_cpu.append(c)
                    qp_wall.append(w)
                    iters.append(it)
    period = 5.0
    return {
        "horizon": horizon, "rate": 200.0, "period_ms": period, "samples": len(cpu),
        "samples_solved_by_daqp": len(qp_cpu), "iter_limit": ITER_LIMIT,
        "load_average": [round(v, 2) for v in os.getloadavg()],
        "cpu_ms": _ms(cpu), "wall_ms": _ms(wall),
        "daqp_cpu_ms": _ms(qp_cpu), "daqp_wall_ms": _ms(qp_wall),
        "daqp_iterations": {"median": float(np.median(iters)), "p99": float(np.percentile(iters, 99)),
                            "worst": int(max(iters)), "at_cap": int(sum(i >= ITER_LIMIT for i in iters))},
        # Solves that ended without a solution: the clipped LQR was applied.
        "fallbacks_to_lqr": fallbacks,
        "cpu_over_period": int(sum(1e3 * c > period for c in cpu)),
        "wall_over_period": int(sum(1e3 * w > period for w in wall)),
    }


def python_control(horizon: int = 30, steps: int = 3) -> dict[str, object]:
    import control
    import control.optimal as opt

    system = get_system("cartpole")
    d = design(system, rate=200.0)
    disc = d.discrete
    dt = 1.0 / 200.0
    sysd = control.ss(disc.A, disc.B, np.eye(4), np.zeros((4, 1)), dt)
    lo, hi = system.input_limits
    cost = opt.quadratic_cost(sysd, d.Q, d.R)
    terminal = opt.quadratic_cost(sysd, d.S, None)
    constraints = [opt.input_range_constraint(sysd, lo, hi)]
    timepts = np.arange(horizon + 1) * dt
    ours = mpc(system, design=d, horizon=horizon, estimator="state")
    rt = MPCRuntime(ours, exact_unconstrained=False)
    times, diffs, our_times = [], [], []
    for k in range(steps):
        x0 = np.array([0.0, 0.5 - 0.1 * k, 0.0, 0.0])
        t0 = time.perf_counter()
        with contextlib.redirect_stdout(io.StringIO()):  # its summary would spoil --json
            res = opt.solve_ocp(sysd, timepts, x0, cost, constraints, terminal_cost=terminal)
        times.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        du = rt.solve(x0)
        our_times.append(time.perf_counter() - t0)
        diffs.append(float(abs(res.inputs[0, 0] - du[0])))
    return {"python_control_version": control.__version__, "horizon": horizon,
            "python_control_ms_per_step": 1e3 * float(np.median(times)),
            "equilibrist_ms_per_step": 1e3 * float(np.median(our_times)),
            "ratio": float(np.median(times) / np.median(our_times)),
            "first_move_difference_N": max(diffs)}


def regions(grid: int, figure: bool) -> dict[str, object]:
    """Both regions of attraction (equilibrist.apps.mpc_demo, the report's own figure)."""
    from equilibrist.apps.mpc_demo import plot_regions
    from equilibrist.apps.mpc_demo import regions as kept_starts

    system = get_system("cartpole")
    speeds, angles, kept = kept_starts(system, grid)
    lqr, ours = kept.values()
    if figure:
        out = ROOT / "docs" / "images" / "mpc_roa.png"
        out.parent.mkdir(parents=True, exist_ok=True)
        plot_regions(system, speeds, angles, kept, out)
    return {"grid": grid, "lqr_kept": int(lqr.sum()), "mpc_kept": int(ours.sum()),
            "mpc_only": int((ours & ~lqr).sum()), "lqr_only": int((lqr & ~ours).sum())}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--grid", type=int, default=9)
    ap.add_argument("--no-figure", action="store_true")
    ap.add_argument("--solve-only", action="store_true",
                    help="only the per-sample solve times (thread CPU and wall)")
    ap.add_argument("--repeat", type=int, default=1, help="passes over the starts (--solve-only)")
    args = ap.parse_args(argv)
    out: dict[str, dict[str, object]]
    if args.solve_only:
        out = {"solve_only": solve_times(repeat=args.repeat)}
    else:
        out = {"solve_times": solve_times(), "python_control": python_control(),
               "regions": regions(args.grid, not args.no_figure)}
    if args.json:
        json.dump(out, sys.stdout, indent=2)
        print()
    else:
        for section, values in out.items():
            print(section)
            for k, v in values.items():
                print(f"  {k}: {v:.4g}" if isinstance(v, float) else f"  {k}: {v}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
