"""Environment speed against Gymnasium, measured side by side in one run.

Workload (issue 11): the cart-pole's balance task at 50 Hz with one RK4
step per period (``rate=50, physics_step=0.02, noise=False``: the 0.02 s
step of Gymnasium's CartPole, which has no noise), against

* ``gymnasium.make_vec("CartPole-v1", num_envs=N, vectorization_mode="vector_entry_point")``
  (Gymnasium's own numpy vector cart-pole, explicit Euler) for N = 16, 256, 4096;
* the same vector environment kept on one thread (below 256 copies it is
  on one thread anyway), to separate the compiled loop from the threads
  (from 256 copies up the vector environment itself steps on one thread or
  on all, whichever has been faster lately; the "thr" column is the number
  of threads it ended on);
* Gymnasium's ``SyncVectorEnv`` of the same equilibrist environment
  (``vectorization_mode="sync"``: the generic way to vectorize an environment);
* a single environment's ``step()`` against Gymnasium's ``CartPole-v1``
  ``step()``, both made by ``gymnasium.make`` (with the wrappers it adds).

Every contender keeps stepping with a fixed action through its own
autoresets. Timings are the best of several repetitions, interleaved so a
busy machine slows all alike; the first (compiling) calls are not timed.
Ratios are steps per second of equilibrist over the peer's.

Usage: ``python bench/bench_envs.py [--repeats N] [--seconds S] [--json]``.
Goals: vector env >= 1x Gymnasium's vector CartPole at every N, >= 50x
SyncVectorEnv; single step <= 2x the time of CartPole's.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Callable

import gymnasium as gym
import numpy as np

import equilibrist.envs  # noqa: F401  (registers the environments)
from equilibrist.envs import vector as vector_module

ENV_ID = "equilibrist/cartpole-balance-v0"
OPTIONS = {"rate": 50.0, "physics_step": 0.02, "noise": False}
SIZES = (16, 256, 4096)


def _steps_for(seconds: float, per_step: float) -> int:
    return max(10, int(seconds / max(per_step, 1e-9)))


def _timer(step: Callable[[], object], seconds: float) -> Callable[[], float]:
    """A timing of *step*: seconds per call, over about *seconds* of calls."""
    for _ in range(5):
        step()
    t = time.perf_counter()
    step()
    count = _steps_for(seconds, time.perf_counter() - t)

    def run() -> float:
        start = time.perf_counter()
        for _ in range(count):
            step()
        return (time.perf_counter() - start) / count

    return run


def best_of(timers: dict[str, Callable[[], float]], repeats: int) -> dict[str, float]:
    best = {k: float("inf") for k in timers}
    for _ in range(repeats):
        for k, fn in timers.items():
            best[k] = min(best[k], fn())
    return best


def vector_case(n: int, seconds: float, repeats: int) -> dict[str, float]:
    ours = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="vector_entry_point", **OPTIONS)
    ours.reset(seed=0)
    a_ours = np.zeros((n, 1))
    # The same environment kept on one thread: what the compiled loop does per core.
    keep = vector_module.PARALLEL_MIN
    vector_module.PARALLEL_MIN = 10**12
    serial = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="vector_entry_point", **OPTIONS)
    vector_module.PARALLEL_MIN = keep
    serial.reset(seed=0)
    theirs = gym.make_vec("CartPole-v1", num_envs=n, vectorization_mode="vector_entry_point")
    theirs.reset(seed=0)
    a_theirs = np.ones(n, dtype=np.int64)
    sync = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="sync", **OPTIONS)
    sync.reset(seed=0)
    timers = {
        "ours": _timer(lambda: ours.step(a_ours), seconds),
        "one_thread": _timer(lambda: serial.step(a_ours), seconds),
        "gymnasium": _timer(lambda: theirs.step(a_theirs), seconds),
        # The generic wrapper is slow: time fewer of its steps.
        "sync": _timer(lambda: sync.step(a_ours), seconds / 4),
    }
    t = best_of(timers, repeats)
    threads = ours.unwrapped.threads_in_use  # type: ignore[attr-defined]
    for env in (ours, serial, theirs, sync):
        env.close()
    return {**{k: n / v for k, v in t.items()}, "threads": threads}  # env-steps per second


def single_case(seconds: float, repeats: int) -> dict[str, float]:
    ours = gym.make(ENV_ID, **OPTIONS)
    theirs = gym.make("CartPole-v1")
    a_ours = np.zeros(1)

    def step_ours() -> None:
        _, _, terminated, truncated, _ = ours.step(a_ours)
        if terminated or truncated:
            ours.reset()

    def step_theirs() -> None:
        _, _, terminated, truncated, _ = theirs.step(1)
        if terminated or truncated:
            theirs.reset()

    ours.reset(seed=0)
    theirs.reset(seed=0)
    t = best_of({"ours": _timer(step_ours, seconds), "gymnasium": _timer(step_theirs, seconds)},
                repeats)
    return {k: v * 1e6 for k, v in t.items()}  # microseconds per step


def puffer_case(n: int, seconds: float, repeats: int) -> dict[str, float]:
    """PufferLib's native environment over the vector one (``envs.puffer``, its buffers
    filled every step) against the vector environment alone: env-steps per second."""
    from equilibrist.envs.puffer import EquilibristPufferEnv

    alone = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="vector_entry_point", **OPTIONS)
    alone.reset(seed=0)
    puffer = EquilibristPufferEnv(ENV_ID, num_envs=n, **OPTIONS)
    puffer.reset(seed=0)
    a = np.zeros((n, 1))
    t = best_of({"alone": _timer(lambda: alone.step(a), seconds),
                 "puffer": _timer(lambda: puffer.step(a), seconds)}, repeats)
    alone.close()
    puffer.close()
    return {k: n / v for k, v in t.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--seconds", type=float, default=0.3, help="per timing")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--puffer", action="store_true",
                        help="PufferLib's native environment over the vector one, against it alone")
    args = parser.parse_args()
    if args.puffer:
        print(f"load average {os.getloadavg()[0]:.1f}; env-steps per second (M/s)")
        for n in SIZES:
            r = puffer_case(n, args.seconds, args.repeats)
            print(f"{n:5d} vector env alone {r['alone'] / 1e6:8.3f}  as a PufferEnv "
                  f"{r['puffer'] / 1e6:8.3f}  ({r['puffer'] / r['alone']:.2f} x)")
        return

    from equilibrist.sim.kernel import thread_count

    threads = thread_count()
    results: dict[str, object] = {"threads": threads, "load_before": os.getloadavg()[0]}
    rows = []
    for n in SIZES:
        r = vector_case(n, args.seconds, args.repeats)
        rows.append((n, r))
        results[f"vector_{n}"] = r
    single = single_case(args.seconds, args.repeats)
    results["single_us"] = single
    results["load_after"] = os.getloadavg()[0]
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(f"cart-pole balance, 50 Hz, one RK4 step per period, no noise; {threads} threads; "
          f"load average {results['load_before']:.1f} -> {results['load_after']:.1f}")
    print("env-steps per second (M/s); ratios are equilibrist's vector env over the peer")
    print(f"{'N':>5s} {'ours':>8s} {'thr':>4s} {'1 thread':>9s} {'gym vec':>8s} {'x gym vec':>10s} "
          f"{'1 thr x gym':>12s} {'sync':>8s} {'x sync':>8s}")
    for n, r in rows:
        print(f"{n:5d} {r['ours'] / 1e6:8.3f} {r['threads']:4d} {r['one_thread'] / 1e6:9.3f} "
              f"{r['gymnasium'] / 1e6:8.3f} {r['ours'] / r['gymnasium']:10.2f} "
              f"{r['one_thread'] / r['gymnasium']:12.2f} {r['sync'] / 1e6:8.4f} "
              f"{r['ours'] / r['sync']:8.1f}")
    print(f"single step(): ours {single['ours']:.2f} us, Gymnasium CartPole {single['gymnasium']:.2f} us "
          f"({single['ours'] / single['gymnasium']:.2f} x its time)")


if __name__ == "__main__":
    main()
