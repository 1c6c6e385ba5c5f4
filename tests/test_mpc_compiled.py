"""The MPC as it runs: the C library that ships, compiled once per cache folder. Each runtime
has its own workspace, and DAQP's objects in the cache are checked and rebuilt when damaged."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.control._mpc_c import daqp_objects
from equilibrist.control.design import design
from equilibrist.control.mpc import MPCRuntime, mpc
from support.mpc_reference import ReferenceMPC


def _states(seed: int, count: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.normal(size=4) * np.array([0.3, 0.3, 1.5, 2.0]) for _ in range(count)]


def test_each_runtime_keeps_its_own_working_set() -> None:
    """Two runtimes of one MPC, interleaved, each give what it gives alone (moves to the bit,
    DAQP's iterations: a shared workspace would warm-start one from the other's set)."""
    system = get_system("cartpole", F_min=-20.0, F_max=20.0)
    ctrl = mpc(system, design=design(system, rate=200.0), horizon=15, estimator="state")
    first, second = _states(1, 60), _states(2, 60)
    alone = []
    solo = MPCRuntime(ctrl)
    for dx in first:
        alone.append((solo.solve(dx).tolist(), solo.last_iterations))
    a, b = MPCRuntime(ctrl), MPCRuntime(ctrl)
    together, solved = [], 0
    for dx, other in zip(first, second, strict=True):
        together.append((a.solve(dx).tolist(), a.last_iterations))
        b.solve(other)
        solved += b.last_iterations > 0
    assert solved > 10  # the other runtime's working set moved meanwhile
    assert together == alone


def test_damaged_daqp_objects_are_rebuilt(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """An object file of DAQP cut short in the cache: its digest no longer matches, it is
    compiled again, and a new MPC linked with it solves as DAQP's Python package does."""
    monkeypatch.setenv("EQUILIBRIST_CACHE", str(tmp_path / "cache"))
    objs = daqp_objects()
    pristine = {p.name: p.read_bytes() for p in objs}
    victim = next(p for p in objs if "daqp" in p.stem)
    victim.write_bytes(victim.read_bytes()[:100])
    again = daqp_objects()
    assert again == objs and {p.name: p.read_bytes() for p in again} == pristine
    system = get_system("cartpole", F_min=-20.0, F_max=20.0)
    ctrl = mpc(system, design=design(system, rate=200.0), horizon=9, estimator="state")
    rt, ref = MPCRuntime(ctrl), ReferenceMPC(ctrl)
    for dx in _states(3, 40):
        np.testing.assert_allclose(rt.solve(dx), ref.solve(dx), rtol=0, atol=1e-9)
        assert rt.last_status == ref.last_status
