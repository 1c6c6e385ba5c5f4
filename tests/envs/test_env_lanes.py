"""The vector environment's lanes (native/lanes.py): eight copies at once in AVX-512, the
bits of one copy at a time.

Independent truth: the same environment stepped one copy at a time (the core without
lanes). The lanes' C on its own (a widened dynamics, the lanes' sine and cosine) is tested in
tests/native/test_native_lanes.py.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest

from equilibrist.envs import vector as vector_module
from equilibrist.envs.vector import EquilibristVectorEnv
from equilibrist.native import lanes


def _avx512() -> bool:
    flags = next((line for line in Path("/proc/cpuinfo").read_text().splitlines()
                  if line.startswith("flags")), "")
    return all(f in flags.split() for f in ("avx512f", "avx512dq", "avx512vl", "avx512bw"))


def _trace(monkeypatch, with_lanes: bool, system: str, task: str, n: int, steps: int,
           scale: float, **options) -> tuple[list[np.ndarray], EquilibristVectorEnv]:
    original = vector_module.open_core
    monkeypatch.setattr(vector_module, "open_core",
                        functools.partial(lambda *a, **k: original(*a, **{**k, "lanes": with_lanes})))
    env = EquilibristVectorEnv(n, system, task, **options)
    monkeypatch.setattr(vector_module, "open_core", original)
    obs, _ = env.reset(seed=3)
    rng = np.random.default_rng(0)
    out = [obs.copy()]
    for _ in range(steps):
        action = rng.uniform(-scale, scale, (n, env.single_action_space.shape[0]))
        obs, reward, terminated, truncated, _ = env.step(action)
        out += [obs.copy(), reward.copy(), terminated.copy(), truncated.copy(), env.states.copy()]
    return out, env


@pytest.mark.parametrize(("system", "task", "options"), [
    ("cartpole", "balance", {}),  # sensor and process noise, falls and autoresets
    ("cartpole", "balance", {"noise": False, "physics_step": 0.02, "rate": 50}),
    ("cartpole", "swingup", {"randomize": {"m_p": 0.2}}),  # large angles: the reduction
    ("furuta", "balance", {}),
    ("acrobot", "swingup", {}),
], ids=["cartpole-noise", "cartpole-gym", "cartpole-swingup", "furuta", "acrobot"])
def test_lanes_give_the_bits_of_one_copy_at_a_time(monkeypatch, system, task, options) -> None:
    # 21 copies: two blocks of eight and five stepped one at a time.
    fast, env = _trace(monkeypatch, True, system, task, 21, 150, 1.0, **options)
    slow, plain = _trace(monkeypatch, False, system, task, 21, 150, 1.0, **options)
    assert env.core.kernel.lanes == (lanes.LANES if _avx512() else 1)
    assert plain.core.kernel.lanes == 1
    for a, b in zip(fast, slow, strict=True):
        np.testing.assert_array_equal(a, b)
    ended = sum(int(t.sum()) for t in fast[3::5])
    if task == "balance":
        assert ended > 0  # autoresets happened inside the blocks
