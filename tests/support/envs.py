"""A vector environment whose two ways of stepping run on a fake clock (the thread choice's
tests: tests/envs/test_envs.py, tests/envs/test_env_threads.py)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

from equilibrist.envs import vector as vector_module
from equilibrist.envs.vector import EquilibristVectorEnv


def on_fake_clock(monkeypatch: pytest.MonkeyPatch, seconds: Callable[[int], float]) -> Any:
    """4 cart-pole copies that may run parallel, whose two ways (0: one thread, 1: all) take
    ``seconds(way)`` of a fake clock per step and do nothing else."""
    monkeypatch.setattr(vector_module, "PARALLEL_MIN", 1)
    vec = EquilibristVectorEnv(4, "cartpole", noise=False)
    vec.reset(seed=0)
    now = [0.0]

    def way(mode: int) -> Callable[..., int]:
        def entry(*args: object) -> int:
            now[0] += seconds(mode)
            return 0
        return entry

    vec._ways[:] = [way(0), way(1)]
    monkeypatch.setattr(vector_module.time, "perf_counter", lambda: now[0])
    return vec
