"""Swing-up: success rate and swing-up time over seeded hanging starts, and batch speed.

For each rig with a swing-up (cart-pole, reaction wheel, rotary pendulum,
acrobot): ``--runs`` starts drawn from the task ``swingup`` (hanging at
rest, each hanging angle offset uniformly by up to 0.05 rad), with the
design's sensor and process noise, for the task's 15 s, in one compiled
batch. A run succeeds when it never leaves its region (the cart-pole's
track ``|x| <= x_max``) and ends balancing. Its swing-up time is the time
at which the supervisor handed over to the balance for the last time (the
mode is replayed from the recorded measurements and applied inputs through
the controller's own functions, which the batch ran compiled).

Speed: the swing-up batch's physics steps per second against the LQR
balance batch of the same system, runs and duration (one run of this
script, same machine).

``--balance lqg`` measures the swing-up that hands over to the design's
LQG instead of the LQR on its own tracker (docs/swingup.md).

    python bench/bench_swingup.py [--runs 1000] [--json] [--balance lqr|lqg]
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from equilibrist import get_system
from equilibrist.control.design import design
from equilibrist.control.linear import LinearController
from equilibrist.control.swingup import swingup, swingup_laws
from equilibrist.control.swingup_law import Z, python_namespace
from equilibrist.sim.batch import simulate_batch
from equilibrist.sim.noise import Noise
from equilibrist.tasks import get_task

CHUNK = 200  # runs per recorded batch (memory)


def swing_times(ctrl: object, batch: object, n_out: int, m: int) -> np.ndarray:
    """Time of the last hand-over to the balance per run (NaN when it ends pumping).

    The controller's own compiled functions replay each run's recorded
    measurements and applied inputs, so the mode is the one the batch had.
    """
    # The law compiled to C, as the core runs it.
    fns = python_namespace(ctrl.source, compiled=True)  # type: ignore[attr-defined]
    output, update = fns["output"], fns["update"]
    traj = batch.trajectories  # type: ignore[attr-defined]
    n = len(batch.state_names)  # type: ignore[attr-defined]
    c_y = 2 * n
    c_app = c_y + n_out + 2 * m
    ys = np.ascontiguousarray(traj[:, :, c_y:c_y + n_out])
    uas = np.ascontiguousarray(traj[:, :, c_app:c_app + m])
    runs = ys.shape[0]
    last = np.zeros(runs, dtype=np.int64)
    mode = np.zeros(runs)
    p = np.array(ctrl.params)  # type: ignore[attr-defined]
    z0 = np.array(ctrl.z0)  # type: ignore[attr-defined]
    mode_slot = Z["mode"]
    for i in range(runs):
        z = z0.copy()
        zn = z0.copy()
        u = np.zeros(1)
        r = np.zeros(0)
        last_pump = -1
        for k in range(int(batch.rows[i])):  # type: ignore[attr-defined]
            y = np.ascontiguousarray(ys[i, k])
            output(0.0, z, y, r, p, u)
            update(0.0, z, y, r, np.ascontiguousarray(uas[i, k]), p, zn)
            z[:] = zn
            if z[mode_slot] != 1.0:
                last_pump = k
        last[i] = last_pump
        mode[i] = z[mode_slot]
    return np.where(mode == 1.0, (last + 1) / ctrl.rate, np.nan)  # type: ignore[attr-defined]


def bench_system(name: str, runs: int, seed: int, balance: str = "lqr") -> dict[str, object]:
    system = get_system(name)
    task = get_task(system, "swingup")
    d = design(system, rate=task.rate)
    ctrl = swingup(system, design=d, balance=balance)
    noise = Noise.from_design(d)
    rng = np.random.default_rng(seed)
    x0 = task.draw_initials(rng, runs)
    ok = np.zeros(runs, dtype=bool)
    times = np.full(runs, np.nan)
    elapsed = 0.0
    steps = 0
    for start in range(0, runs, CHUNK):
        stop = min(runs, start + CHUNK)
        b = simulate_batch(system, ctrl, runs=stop - start, duration=task.duration,
                           x0=x0[start:stop], seed=seed * 100_000 + start, noise=noise,
                           region=task.region, record=True)
        elapsed += b.elapsed
        steps += b.steps
        t = swing_times(ctrl, b, len(ctrl.output_names), system.n_inputs)
        times[start:stop] = t
        ok[start:stop] = ~np.asarray(b.fell) & np.isfinite(t)
    # Speed: the same batch without recording, against the LQR balance batch.
    speed_runs = min(runs, 200)
    bal = get_task(system, "balance")
    lqr = LinearController.from_design(d, kind="lqr")
    for warm in (ctrl, lqr):  # compile (or load) both cores before timing
        simulate_batch(system, warm, runs=2, duration=0.1, x0=x0[:2] if warm is ctrl else None,
                       seed=seed, noise=noise, region={})
    t0 = time.perf_counter()
    sb = simulate_batch(system, ctrl, runs=speed_runs, duration=task.duration,
                        x0=x0[:speed_runs], seed=seed, noise=noise, region=task.region)
    t_su = time.perf_counter() - t0
    t0 = time.perf_counter()
    lb = simulate_batch(system, lqr, runs=speed_runs, duration=task.duration,
                        x0=bal.draw_initials(rng, speed_runs), seed=seed, noise=noise, region={})
    t_lqr = time.perf_counter() - t0
    su_rate = sb.steps / t_su
    lqr_rate = lb.steps / t_lqr
    good = times[ok]
    return {
        "system": name, "balance": balance, "runs": runs, "success": float(ok.mean()),
        "swingup_time_median": float(np.median(good)) if good.size else None,
        "swingup_time_p90": float(np.percentile(good, 90)) if good.size else None,
        "swingup_time_max": float(good.max()) if good.size else None,
        "steps_per_second_swingup": su_rate, "steps_per_second_lqr": lqr_rate,
        "speed_ratio": su_rate / lqr_rate,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--systems", default=",".join(swingup_laws()))
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--balance", choices=("lqr", "lqg"), default="lqr",
                    help="what balances after the catch (default lqr)")
    args = ap.parse_args(argv)
    rows = []
    for name in args.systems.split(","):
        row = bench_system(name, args.runs, args.seed, args.balance)
        rows.append(row)
        if not args.json:
            med = row["swingup_time_median"]
            print(f"{name:26s} success {100 * row['success']:5.1f} %  median "  # type: ignore[operator]
                  f"{'-' if med is None else f'{med:.2f} s'}  p90 "
                  f"{row['swingup_time_p90'] if row['swingup_time_p90'] is None else round(row['swingup_time_p90'], 2)}"
                  f"  steps/s {row['steps_per_second_swingup']:.3g} vs LQR "
                  f"{row['steps_per_second_lqr']:.3g} (ratio {row['speed_ratio']:.2f})", flush=True)
    if args.json:
        json.dump(rows, sys.stdout, indent=2)
        print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
