"""Simulation speed against its peers, measured side by side in one run.

Reference workload (issue 4): the cart-pole with the seed-001 parameters,
continuous LQR with Q = diag(10, 10, 1, 1), R = 0.1 applied at 1 kHz with
zero-order hold, RK4 at 1 ms, x0 = [0, 0.2, 0, 0], 10 s (10,000 steps).

Peers, all run here:

* a hand-written C RK4 loop of the same cart-pole and controller
  (``bench/c_reference/cartpole_rk4.c``, gcc -O2), one run recorded, and a
  batch of 10,000 runs (initial angle evenly spread over [-0.3, 0.3]) on all
  cores with OpenMP;
* python-control's ``input_output_response`` of the same closed loop
  (continuous, solve_ivp's RK45 with its default tolerances, 10,001 output
  times).

equilibrist runs the same single run (``simulate``), the full LQG loop
(discrete Kalman filter, process and sensor noise, the design's matrices at
1 kHz) and the 10,000-run batch (``simulate_batch``, outcomes only, both
cores). Timings are the best of several repetitions, interleaved so that a
busy machine slows all contenders alike; the first (compiling) call is not
timed. The C and equilibrist final states are compared, so the two loops are
the same workload.

Usage: ``python bench/bench_sim.py [--repeats N] [--batch-runs N] [--rounds N] [--json]``
(a shorter run: ``--rounds 1 --batch-runs 2000``). The machine's load average
before and after is printed with the figures.
Goals (issue 4): single run >= 0.4 of C's speed (>= 100x python-control);
LQG <= 2x the LQR loop; batch >= 0.5 of C's two-core speed.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import scipy.linalg as sl

HERE = Path(__file__).resolve().parent
C_SOURCE = HERE / "c_reference" / "cartpole_rk4.c"
BUILD = HERE / "_build"

DURATION = 10.0
DT = 1e-3
THETA0 = 0.2
SPAN = 0.3


def build_c() -> Path:
    if shutil.which("gcc") is None:
        raise SystemExit("bench_sim: gcc is needed for the C reference")
    BUILD.mkdir(exist_ok=True)
    exe = BUILD / "cartpole_rk4"
    if not exe.exists() or exe.stat().st_mtime < C_SOURCE.stat().st_mtime:
        subprocess.run(["gcc", "-O2", "-fopenmp", "-o", str(exe), str(C_SOURCE), "-lm"],
                       check=True)
    return exe


def run_c(exe: Path, K: np.ndarray, repeats: int, batch_runs: int) -> dict:
    args = [str(exe), *(repr(float(k)) for k in K.ravel()), repr(THETA0), repr(DURATION),
            repr(DT), str(repeats), str(batch_runs), repr(SPAN)]
    out = subprocess.run(args, check=True, capture_output=True, text=True).stdout
    return json.loads(out)


def best_of(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=30, help="repetitions of single runs")
    parser.add_argument("--batch-runs", type=int, default=10_000)
    parser.add_argument("--rounds", type=int, default=3,
                        help="interleaved rounds (the best round's figures are kept)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    load_before = os.getloadavg()[0]

    import control as ct

    from equilibrist.control import design
    from equilibrist.numeric.lookup import get_system
    from equilibrist.sim import LQG, Noise, StateFeedback, simulate, simulate_batch

    system = get_system("cartpole")
    lm = system.linearize()
    Q, R = np.diag([10.0, 10.0, 1.0, 1.0]), np.array([[0.1]])
    P = sl.solve_continuous_are(lm.A, lm.B, Q, R)
    K = np.linalg.solve(R, lm.B.T @ P)
    lqr = StateFeedback(K=K, x_op=lm.x0, u_op=lm.u0)
    x0 = np.array([0.0, THETA0, 0.0, 0.0])
    d = design(system, q=np.diag(Q), r=np.diag(R), rate=1.0 / DT)
    lqg = LQG.from_design(d)
    noise = Noise.from_design(d)
    thetas = np.linspace(-SPAN, SPAN, args.batch_runs)

    def eq_single():
        return simulate(system, lqr, duration=DURATION, rate=1 / DT, physics_step=DT, x0=x0)

    def eq_lqg():
        return simulate(system, lqg, duration=DURATION, physics_step=DT, x0=x0, noise=noise,
                        seed=1)

    def eq_batch():
        return simulate_batch(system, lqr, runs=args.batch_runs, duration=DURATION,
                              rate=1 / DT, physics_step=DT, x0={"theta": thetas})

    f = system.functions.f
    p = np.array(system.p)

    def plant_rhs(t, x, u, params):
        out = np.empty(4)
        f(x, u, p, out)
        return out

    plant = ct.nlsys(plant_rhs, None, inputs=1, outputs=4, states=4, name="plant")
    ctrl = ct.ss(np.zeros((0, 0)), np.zeros((0, 4)), np.zeros((1, 0)), -K, name="lqr")
    loop = ct.feedback(plant, ctrl, sign=1)
    t_eval = np.linspace(0.0, DURATION, round(DURATION / DT) + 1)

    def pc_single():
        return ct.input_output_response(loop, t_eval, 0.0, X0=x0)

    exe = build_c()
    # Warm up: compile (or load) the kernels, and check the workloads agree.
    single = eq_single()
    eq_lqg()
    simulate_batch(system, lqr, runs=4, duration=0.01, rate=1 / DT, x0={"theta": thetas[:4]})
    pc = pc_single()

    rounds = []
    for _ in range(args.rounds):
        c = run_c(exe, K, args.repeats, args.batch_runs)
        r = {
            "c_single_s": c["single_s"],
            "eq_single_s": best_of(eq_single, args.repeats),
            "eq_lqg_s": best_of(eq_lqg, args.repeats),
            "pc_single_s": best_of(pc_single, 2),
            "c_batch_s": c["batch_s"],
            "c_threads": c["threads"],
            "c_final": c["final"],
        }
        t0 = time.perf_counter()
        b = eq_batch()
        r["eq_batch_s"] = time.perf_counter() - t0
        r["eq_batch_kernel_s"] = b.elapsed
        r["eq_batch_fell"] = int(b.fell.sum())
        r["c_batch_fell"] = c["batch_fell"]
        rounds.append(r)

    def best(key: str) -> float:
        return min(r[key] for r in rounds)

    steps = round(DURATION / DT)
    n_batch = args.batch_runs * steps
    res = {
        "load_average": [load_before, os.getloadavg()[0]],
        "cores": os.cpu_count(),
        "workload": "cartpole, continuous LQR Q=diag(10,10,1,1) R=0.1 at 1 kHz ZOH, RK4 1 ms, "
                    "x0=[0,0.2,0,0], 10 s",
        "steps_per_run": steps,
        "c_single_ms": 1e3 * best("c_single_s"),
        "equilibrist_single_ms": 1e3 * best("eq_single_s"),
        "equilibrist_lqg_ms": 1e3 * best("eq_lqg_s"),
        "python_control_single_ms": 1e3 * best("pc_single_s"),
        "c_batch_s": best("c_batch_s"),
        "equilibrist_batch_s": best("eq_batch_s"),
        "equilibrist_batch_kernel_s": best("eq_batch_kernel_s"),
        "batch_runs": args.batch_runs,
        "threads": rounds[0]["c_threads"],
        "steps_per_second": {
            "c_single": steps / best("c_single_s"),
            "equilibrist_single": steps / best("eq_single_s"),
            "equilibrist_lqg": steps / best("eq_lqg_s"),
            "python_control": steps / best("pc_single_s"),
            "c_batch": n_batch / best("c_batch_s"),
            "equilibrist_batch": n_batch / best("eq_batch_s"),
        },
        "ratios": {
            "single_vs_c": best("c_single_s") / best("eq_single_s"),
            "single_vs_python_control": best("pc_single_s") / best("eq_single_s"),
            "lqg_over_lqr": best("eq_lqg_s") / best("eq_single_s"),
            "batch_vs_c": best("c_batch_s") / best("eq_batch_s"),
        },
        "goals": {"single_vs_c": 0.4, "single_vs_python_control": 100.0,
                  "lqg_over_lqr_at_most": 2.0, "batch_vs_c": 0.5},
        "same_workload": {
            "max_final_state_difference_vs_c": float(np.abs(single.final_state
                                                            - np.array(rounds[0]["c_final"])).max()),
            "python_control_final_difference": float(np.abs(pc.states[:, -1]
                                                            - single.final_state).max()),
            "batch_fell": [rounds[0]["eq_batch_fell"], rounds[0]["c_batch_fell"]],
        },
    }
    if args.json:
        json.dump(res, sys.stdout, indent=2)
        print()
        return 0
    rt = res["ratios"]
    sps = res["steps_per_second"]
    print(f"load average of the machine: {res['load_average'][0]:.1f} before, "
          f"{res['load_average'][1]:.1f} after ({res['cores']} cores)")
    print(f"workload: {res['workload']} ({steps} steps per run)")
    print(f"  C (gcc -O2)          single {res['c_single_ms']:8.3f} ms  {sps['c_single'] / 1e6:6.2f} M steps/s")
    print(f"  equilibrist LQR      single {res['equilibrist_single_ms']:8.3f} ms  "
          f"{sps['equilibrist_single'] / 1e6:6.2f} M steps/s   {rt['single_vs_c']:.2f} of C (goal >= 0.4)")
    print(f"  equilibrist LQG      single {res['equilibrist_lqg_ms']:8.3f} ms  "
          f"{sps['equilibrist_lqg'] / 1e6:6.2f} M steps/s   {rt['lqg_over_lqr']:.2f}x the LQR loop (goal <= 2)")
    print(f"  python-control       single {res['python_control_single_ms']:8.1f} ms  "
          f"{sps['python_control'] / 1e3:6.1f} k steps/s   equilibrist is {rt['single_vs_python_control']:.0f}x faster (goal >= 100)")
    print(f"  C batch of {args.batch_runs} on {res['threads']} threads   {res['c_batch_s']:7.3f} s  "
          f"{sps['c_batch'] / 1e6:6.2f} M steps/s")
    print(f"  equilibrist batch of {args.batch_runs}    {res['equilibrist_batch_s']:7.3f} s  "
          f"{sps['equilibrist_batch'] / 1e6:6.2f} M steps/s   {rt['batch_vs_c']:.2f} of C (goal >= 0.5)")
    same = res["same_workload"]
    print(f"  same workload: |final state - C| = {same['max_final_state_difference_vs_c']:.2e}, "
          f"|python-control - equilibrist| = {same['python_control_final_difference']:.2e}, "
          f"batch fell (equilibrist, C) = {same['batch_fell']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
