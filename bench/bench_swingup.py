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

The two-link rigs (the catalogue's acrobot and pendubot, DFKI's acrobot and
pendubot, named by their keys: ``dfki_double_pendulum[robot=pendubot]``) are
also run from hanging exactly at rest without noise, RealAIGym's start
(``from_rest``: whether that one run ends balancing, and when it was caught);
``--duration 10`` gives every run RealAIGym's 10 s instead of the task's.

    python bench/bench_swingup.py [--runs 1000] [--json] [--balance lqr|lqg]
        [--systems acrobot,dfki_double_pendulum[robot=acrobot]] [--duration S]
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


def _system(key: str) -> object:
    """A catalogue system by its key (``name`` or ``name[option=value]``)."""
    name, _, rest = key.partition("[")
    options = dict(kv.split("=", 1) for kv in rest.rstrip("]").split(",")) if rest else {}
    return get_system(name, **options)


def from_rest(system: object, ctrl: object, duration: float) -> tuple[bool, float | None]:
    """One noise-free run from hanging exactly at rest: whether it ends balancing (both links
    within 0.1 rad of upright, rates under 0.5 rad/s, the supervisor balancing) and the time of
    its last hand-over to the balance."""
    b = simulate_batch(system, ctrl, runs=1, duration=duration,  # type: ignore[arg-type]
                       x0=np.zeros((1, 4)), seed=0, region={}, record=True)
    t = float(swing_times(ctrl, b, len(ctrl.output_names), 1)[0])  # type: ignore[attr-defined]
    end = np.asarray(b.final_state)[0] - system.operating_point().x  # type: ignore[attr-defined]
    angles = np.abs(np.remainder(end[:2] + np.pi, 2 * np.pi) - np.pi)
    up = bool(angles.max() < 0.1 and np.abs(end[2:]).max() < 0.5 and np.isfinite(t))
    return up, (t if np.isfinite(t) else None)


def bench_system(name: str, runs: int, seed: int, balance: str = "lqr",
                 duration: float | None = None) -> dict[str, object]:
    system = _system(name)
    task = get_task(system, "swingup")
    horizon = float(duration if duration is not None else task.duration)
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
        b = simulate_batch(system, ctrl, runs=stop - start, duration=horizon,
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
    sb = simulate_batch(system, ctrl, runs=speed_runs, duration=horizon,
                        x0=x0[:speed_runs], seed=seed, noise=noise, region=task.region)
    t_su = time.perf_counter() - t0
    t0 = time.perf_counter()
    lb = simulate_batch(system, lqr, runs=speed_runs, duration=horizon,
                        x0=bal.draw_initials(rng, speed_runs), seed=seed, noise=noise, region={})
    t_lqr = time.perf_counter() - t0
    su_rate = sb.steps / t_su
    lqr_rate = lb.steps / t_lqr
    good = times[ok]
    rest: dict[str, object] = {}
    if system.spec.swingup.law in ("acrobot", "pendubot"):  # type: ignore[attr-defined]
        up, caught = from_rest(system, ctrl, horizon)
        rest = {"from_rest": up, "from_rest_time": caught}
    return {
        "system": name, "balance": balance, "runs": runs, "duration": horizon,
        "success": float(ok.mean()), **rest,
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
    ap.add_argument("--duration", type=float, default=None,
                    help="seconds per run (default the task's)")
    args = ap.parse_args(argv)
    rows = []
    for name in args.systems.split(","):
        row = bench_system(name, args.runs, args.seed, args.balance, args.duration)
        rows.append(row)
        if not args.json:
            med = row["swingup_time_median"]
            print(f"{name:26s} success {100 * row['success']:5.1f} %  median "  # type: ignore[operator]
                  f"{'-' if med is None else f'{med:.2f} s'}  p90 "
                  f"{row['swingup_time_p90'] if row['swingup_time_p90'] is None else round(row['swingup_time_p90'], 2)}"
                  f"  steps/s {row['steps_per_second_swingup']:.3g} vs LQR "
                  f"{row['steps_per_second_lqr']:.3g} (ratio {row['speed_ratio']:.2f})"
                  + (f"  from rest: {'caught' if row['from_rest'] else 'not caught'}"
                     f" ({row['from_rest_time']} s)" if "from_rest" in row else ""), flush=True)
    if args.json:
        json.dump(rows, sys.stdout, indent=2)
        print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
