"""The environment peers of bench/bench_peers.py, run in their own environment
(bench/peers_envs.sh): Gymnasium's vector CartPole, gymnax's CartPole on the CPU
(``jit`` of ``vmap(step)``, and ``lax.scan`` over steps inside one ``jit``) and
EnvPool's CartPole. It answers one JSON line per JSON line read on stdin:

* ``{"cmd": "versions"}``: each peer's version, or why it does not import;
* ``{"cmd": "make", "peer": P, "n": N}``: builds *P* with *N* copies and
  resets it: ``ready`` (seconds to make and reset) and ``first`` (the first
  step, which for gymnax compiles);
* ``{"cmd": "time", "peer": P, "n": N, "seconds": S}``: ``per_step``, seconds
  per step of all *N* copies, over about *S* seconds of steps, and ``cpu_per_step``,
  the CPU seconds of every thread of this process per step.

Every peer steps with a fixed action (push right) through its own autoresets,
at its 0.02 s step.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Callable
from typing import Any

SCAN_STEPS = 65536  # env-steps per call of the scanned form (copies x steps)


def versions() -> dict[str, str]:
    import importlib
    from importlib import metadata

    out = {}
    for name in ("gymnasium", "jax", "gymnax", "envpool", "numpy"):
        try:
            importlib.import_module(name)
            out[name] = metadata.version(name)
        except Exception as exc:
            out[name] = f"missing: {type(exc).__name__}: {exc}".splitlines()[0]
    return out


def make(peer: str, n: int) -> Callable[[], Any]:
    """A step of all *n* copies of *peer* (made and reset), returning when it is done."""
    import numpy as np

    if peer == "gymnasium":
        import gymnasium as gym

        env = gym.make_vec("CartPole-v1", num_envs=n, vectorization_mode="vector_entry_point")
        env.reset(seed=0)
        actions = np.ones(n, dtype=np.int64)
        return lambda: env.step(actions)
    if peer == "envpool":
        import envpool

        pool = envpool.make_gymnasium("CartPole-v1", num_envs=n, batch_size=n, seed=0)
        pool.reset()
        ints = np.ones(n, dtype=np.int32)
        return lambda: pool.step(ints)
    import gymnax
    import jax
    import jax.numpy as jnp

    env, params = gymnax.make("CartPole-v1")
    key = jax.random.PRNGKey(0)
    _, state = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(jax.random.split(key, n), params)
    actions = jnp.ones(n, dtype=jnp.int32)
    stepv = jax.vmap(env.step, in_axes=(0, 0, 0, None))

    def one(key: Any, state: Any) -> Any:
        key, sub = jax.random.split(key)
        obs, state, reward, done, *_ = stepv(jax.random.split(sub, n), state, actions, params)
        return key, state, obs, reward, done

    box = {"key": key, "state": state}
    if peer == "gymnax":
        step = jax.jit(one)

        def run() -> Any:
            box["key"], box["state"], obs, _, _ = step(box["key"], box["state"])
            return obs.block_until_ready()

        return run
    length = max(1, SCAN_STEPS // n)

    def body(carry: Any, _: Any) -> Any:
        key, state, _, reward, _ = one(*carry)
        return (key, state), reward.sum()

    scanned = jax.jit(lambda key, state: jax.lax.scan(body, (key, state), None, length=length))

    def run_scan() -> Any:
        (box["key"], box["state"]), rewards = scanned(box["key"], box["state"])
        return rewards.block_until_ready()

    run_scan.steps = length  # type: ignore[attr-defined]
    return run_scan


def main() -> int:
    made: dict[tuple[str, int], Callable[[], Any]] = {}
    for line in sys.stdin:
        ask = json.loads(line)
        try:
            if ask["cmd"] == "versions":
                answer: dict[str, Any] = versions()
            elif ask["cmd"] == "make":
                t0 = time.perf_counter()
                step = make(ask["peer"], int(ask["n"]))
                t1 = time.perf_counter()
                step()
                t2 = time.perf_counter()
                made[(ask["peer"], int(ask["n"]))] = step
                answer = {"ready": t1 - t0, "first": t2 - t1,
                          "steps_per_call": getattr(step, "steps", 1)}
            else:
                step = made[(ask["peer"], int(ask["n"]))]
                per = getattr(step, "steps", 1)
                t0 = time.perf_counter()
                step()
                count = max(3, int(float(ask["seconds"]) / max(time.perf_counter() - t0, 1e-9)))
                t0, c0 = time.perf_counter(), time.process_time()
                for _ in range(count):
                    step()
                answer = {"per_step": (time.perf_counter() - t0) / (count * per),
                          "cpu_per_step": (time.process_time() - c0) / (count * per)}
        except Exception as exc:
            answer = {"error": f"{type(exc).__name__}: {exc}".splitlines()[0][:300]}
        print(json.dumps(answer), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
