"""iLQR against direct collocation: the swing-ups from the straight guess and 20 random guesses, then tracked.

    nice -n 10 .venv/bin/python bench/bench_ilqr.py [--only acrobot,cartpole,...] [--starts 200]

Each case plans the same problem both ways: N = 60 intervals of a fixed duration, the
least effort (integral of (u / scale)^2), the input limits, the cart-pole's track less
the default margin; collocation by ``plan`` (Hermite-Simpson, IPOPT), iLQR by
``plan_ilqr`` (RK4 steps, control-limited backward pass, the final state by an augmented
Lagrangian; at most 1000 backward passes and 30 s). For each method: the number converged
of the straight guess and of 20 seeded random guesses, the median and worst CPU time, the
median final-state miss (largest component), the median effort of the converged plans.
Then each method's plan from the straight guess is tracked by the time-varying LQR (its
catch on) from *starts* noisy starts about hanging (+-0.05 rad, +-0.1 rad/s), with the
rig's sensor and process noise, 15 s: the fraction that ends balanced and the median time
to balance, as bench_tracking.py measures them, nominal and with every mass drawn within
+-20 % per run. Last, collocation polishing the iLQR's plan (``--guess`` its file).
"""

from __future__ import annotations

import argparse
import os
import statistics

import numpy as np

from equilibrist import get_system
from equilibrist.control.ilqr import plan_ilqr
from equilibrist.control.trajopt import plan
from equilibrist.control.tvlqr import build_request
from equilibrist.controllers.kinds import ControllerRequest
from equilibrist.errors import ControllerError
from equilibrist.sim import Noise, simulate_batch
from equilibrist.sim.batch import monte_carlo
from equilibrist.tasks import get_task, planning_bounds

DRAKE = {"m1": 1.0, "m2": 1.0, "l1": 1.0, "l2": 2.0, "lc1": 0.5, "lc2": 1.0, "I1": 0.083,
         "I2": 0.33, "b1": 0.1, "b2": 0.1, "g": 9.81, "tau_min": -8.0, "tau_max": 8.0}
#: label: (system, parameters, duration [s])
CASES = {
    "acrobot": ("acrobot", {}, 4.0),
    "cartpole": ("cartpole", {}, 4.0),
    "acrobot-drake-4s": ("acrobot", DRAKE, 4.0),
    "dfki_acrobot": ("dfki_double_pendulum", {}, 5.0),
}


def solve(method: str, system, task, bounds, duration: float, guess: str, seed: int):
    if method == "collocation":
        return plan(system, start=task.start, goal=task.x_op, knots=60, duration=duration,
                    guess=guess, seed=seed, bounds=bounds)
    return plan_ilqr(system, start=task.start, goal=task.x_op, knots=60, duration=duration,
                     guess=guess, seed=seed, bounds=bounds, max_iterations=1000, max_time=30.0)


def miss(traj, goal: np.ndarray) -> float:
    return float(np.max(np.abs(traj.states[-1] - goal)))


def tracked(system, task, traj, label: str, starts: int) -> str:
    path = traj.save(f"/tmp/equilibrist_bench_ilqr_{label}.npz")
    try:
        ctrl = build_request(ControllerRequest(system=system, rate=float(system.spec.control_rate),
                                               options={"trajectory": str(path)}))
    except ControllerError as exc:
        return f"no tracker: {exc}"
    rng = np.random.default_rng(2026)
    x0 = np.tile(np.asarray(task.start, dtype=float), (starts, 1))
    for i, unit in enumerate(system.state_units):
        half = 0.05 if unit == "rad" else 0.1 if unit == "rad/s" else 0.0
        x0[:, i] += rng.uniform(-half, half, starts)
    noise = Noise.from_spec(system, outputs=ctrl.output_names, rate=ctrl.rate)
    batch = simulate_batch(system, ctrl, runs=starts, x0=x0, duration=15.0, noise=noise, seed=7,
                           region=dict(task.region))
    spread = {p.name: 0.2 for p in system.spec.all_parameters if p.unit == "kg"}
    mc = monte_carlo(system, ctrl, spread=spread, runs=starts, x0=x0, duration=15.0,
                     noise=noise, seed=7, region=dict(task.region)).batch
    t50, m50 = batch.time_to_balance(0.5), mc.time_to_balance(0.5)
    return (f"tracked: fraction_balanced {batch.fraction_balanced:.3f} ({batch.balanced}/"
            f"{batch.runs}), time to balance median {'-' if t50 is None else f'{t50:.2f} s'}; "
            f"masses +-20 %: {mc.fraction_balanced:.3f}, {'-' if m50 is None else f'{m50:.2f} s'}")


def case(label: str, starts: int) -> None:
    name, params, duration = CASES[label]
    system = get_system(name, **params)
    task = get_task(system, "swingup")
    bounds = planning_bounds(task, 0.3)
    print(f"{label}: {system.key}, N = 60, {duration:g} s, limits "
          + ", ".join(f"|{i}| <= {system.params[i + '_max']:g}" for i in system.input_names))
    solve("collocation", system, task, bounds, duration, "straight", 0)  # CasADi's set-up
    for method in ("collocation", "ilqr"):
        straight = solve(method, system, task, bounds, duration, "straight", 0)
        runs = [solve(method, system, task, bounds, duration, "random", s) for s in range(20)]
        ok = [t for t in runs if t.converged]
        times = [t.solve_time for t in runs]
        print(f"  {method:<11} straight: {'converged' if straight.converged else 'NOT converged'}"
              f" in {straight.solve_time:.3f} s, {straight.iterations} iterations, miss "
              f"{miss(straight, task.x_op):.1e}, effort {straight.cost:.4g}")
        print(f"  {'':<11} random: {len(ok)}/20 converged; CPU median {statistics.median(times):.3f}"
              f" s, worst {max(times):.3f} s; iterations median "
              f"{statistics.median(t.iterations for t in runs):.0f}; miss median "
              f"{statistics.median(miss(t, task.x_op) for t in runs):.1e}; effort of the "
              f"converged median {statistics.median(t.cost for t in ok) if ok else float('nan'):.4g}"
              f" (min {min((t.cost for t in ok), default=float('nan')):.4g})")
        if straight.converged and starts:
            print(f"  {'':<11} {tracked(system, task, straight, f'{label}_{method}', starts)}")
        if method == "ilqr" and straight.converged:
            polished = plan(system, start=task.start, goal=task.x_op, knots=60,
                            duration=duration, guess=straight, bounds=bounds)
            print(f"  {'':<11} collocation from this plan: "
                  f"{'converged' if polished.converged else 'NOT converged'} in "
                  f"{polished.solve_time:.3f} s, {polished.iterations} iterations, effort "
                  f"{polished.cost:.4g}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", default=",".join(CASES))
    parser.add_argument("--starts", type=int, default=200)
    args = parser.parse_args()
    print(f"load average of the machine: {os.getloadavg()[0]:.1f} (2 cores)")
    for label in args.only.split(","):
        case(label, args.starts)
    print(f"load average of the machine after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
