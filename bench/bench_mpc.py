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

    python bench/bench_mpc.py [--json] [--grid 9] [--no-figure]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from equilibrist import get_system
from equilibrist.control.controller import LinearController
from equilibrist.control.design import design
from equilibrist.control.mpc import MPCRuntime, mpc
from equilibrist.sim.run import simulate

ROOT = Path(__file__).resolve().parents[1]


class _Timed(MPCRuntime):
    """The MPC runtime recording each sample's CPU time as well."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.cpu_times: list[float] = []
        self.statuses: list[str] = []

    def solve(self, dx0: np.ndarray) -> np.ndarray:
        c0 = time.process_time()
        du = super().solve(dx0)
        self.cpu_times.append(time.process_time() - c0)
        self.statuses.append(self.last_status)
        return du


def solve_times(horizon: int = 30) -> dict[str, object]:
    system = get_system("cartpole")
    d = design(system, rate=200.0)
    ctrl = mpc(system, design=d, horizon=horizon, estimator="state")
    starts = [{"theta": 0.5}, {"theta": -0.4, "theta_dot": 1.0}, {"x_dot": 2.0},
              {"x": 0.6, "x_dot": 1.5, "theta": 0.1}]
    wall: list[float] = []
    cpu: list[float] = []
    solved: list[float] = []
    statuses: list[str] = []
    for x0 in starts:
        rt = _Timed(ctrl)
        simulate(system, rt, duration=2.0, x0=x0, region={})
        wall += rt.solve_times
        cpu += rt.cpu_times
        statuses += rt.statuses
        solved += [t for t, s in zip(rt.solve_times, rt.statuses, strict=True) if s != "unconstrained"]
    w, c = np.array(wall), np.array(cpu)
    return {
        "horizon": horizon, "rate": 200.0, "period_ms": 5.0, "samples": len(w),
        "samples_solved_by_osqp": len(solved),
        "wall_median_ms": 1e3 * float(np.median(w)), "wall_worst_ms": 1e3 * float(w.max()),
        "cpu_median_ms": 1e3 * float(np.median(c)), "cpu_worst_ms": 1e3 * float(c.max()),
        "osqp_wall_median_ms": 1e3 * float(np.median(solved)) if solved else None,
        "osqp_wall_worst_ms": 1e3 * float(np.max(solved)) if solved else None,
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
    system = get_system("cartpole")
    d = design(system, rate=50.0)
    region = {"x": (-1.0, 1.0), "theta": (-1.2, 1.2)}
    lqr = LinearController.from_design(d, kind="lqr")
    ctrl = mpc(system, design=d, horizon=40, estimator="state",
               constraints={"x": (-0.95, 0.95), "theta": (-1.2, 1.2)})
    speeds = np.linspace(-3.0, 3.0, grid)
    angles = np.linspace(-0.6, 0.6, grid)
    up = {"lqr": np.zeros((grid, grid), dtype=bool), "mpc": np.zeros((grid, grid), dtype=bool)}
    for i, th in enumerate(angles):
        for j, v in enumerate(speeds):
            x0 = {"x": 0.0, "x_dot": float(v), "theta": float(th)}
            up["lqr"][i, j] = not simulate(system, lqr, duration=4.0, x0=x0, region=region).fell
            up["mpc"][i, j] = not simulate(system, ctrl.runtime(), duration=4.0, x0=x0,
                                           region=region).fell
    if figure:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, 2, figsize=(9, 4), sharey=True)
        for ax, key, title in ((axes[0], "lqr", "clipped LQR"), (axes[1], "mpc", "MPC, N = 40")):
            ax.pcolormesh(speeds, angles, up[key], cmap="RdYlGn", vmin=0, vmax=1, shading="nearest")
            ax.set_title(f"{title}: {int(up[key].sum())} of {up[key].size} kept")
            ax.set_xlabel("initial cart speed [m/s]")
        axes[0].set_ylabel("initial pole angle [rad]")
        fig.suptitle("Cart-pole at 50 Hz, cart at the centre of a 2 m track: green stays up and on it")
        fig.tight_layout()
        out = ROOT / "docs" / "images" / "mpc_roa.png"
        out.parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=90)
        plt.close(fig)
    return {"grid": grid, "lqr_kept": int(up["lqr"].sum()), "mpc_kept": int(up["mpc"].sum()),
            "mpc_only": int((up["mpc"] & ~up["lqr"]).sum()),
            "lqr_only": int((up["lqr"] & ~up["mpc"]).sum())}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--grid", type=int, default=9)
    ap.add_argument("--no-figure", action="store_true")
    args = ap.parse_args(argv)
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
