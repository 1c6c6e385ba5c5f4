"""The MPC as it runs: the C library that ships, compiled once per cache folder. Each runtime
has its own workspace. DAQP is the library the install built from its sources; where there
is none (or one from other sources), DAQP's objects in the cache, checked and rebuilt when
damaged, with the same bits."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.control.design import design
from equilibrist.control.mpc import mpc
from equilibrist.control.mpc_runtime import MPCRuntime
from equilibrist.native import daqp_library
from equilibrist.native.mpc_library import compiled_library, daqp_objects
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


def test_the_install_built_daqp_and_the_mpc_links_it(tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """``pip install`` built DAQP from these very sources (setup.py): a first MPC in an empty
    cache compiles its driver only, and links that library."""
    path = daqp_library.installed()
    assert path is not None, "the install built no DAQP library (setup.py's extension failed)"
    assert daqp_library.built_from(path) == daqp_library.digest()
    monkeypatch.setenv("EQUILIBRIST_CACHE", str(tmp_path / "cache"))
    system = get_system("cartpole", F_min=-20.0, F_max=20.0)
    ctrl = mpc(system, design=design(system, rate=200.0), horizon=9, estimator="state")
    driver = compiled_library(ctrl)
    assert str(path).encode() in driver.read_bytes()  # its DT_NEEDED entry: the library's path
    assert not list((tmp_path / "cache").rglob("*.o"))  # no DAQP object compiled


def test_a_daqp_library_of_other_sources_or_damaged_is_not_used(tmp_path: Path,
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    path = daqp_library.installed()
    assert path is not None
    copy = tmp_path / path.name
    shutil.copy(path, copy)
    assert daqp_library.built_from(copy) == daqp_library.digest()
    cut = tmp_path / "cut.so"
    cut.write_bytes(path.read_bytes()[:4000])
    assert daqp_library.built_from(cut) is None
    assert daqp_library.built_from(tmp_path / "missing.so") is None
    # The sources changed since the install (an edited checkout): the library is not used.
    monkeypatch.setattr(daqp_library, "digest", lambda: "0" * 32)
    monkeypatch.setattr(daqp_library, "_INSTALLED", [])
    assert daqp_library.installed() is None


def test_damaged_daqp_objects_are_rebuilt(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Without the install's library: an object file of DAQP cut short in the cache, its digest
    no longer matches, it is compiled again, and a new MPC linked with it solves as DAQP's
    Python package does, and to the bit as the MPC on the install's library."""
    monkeypatch.setenv("EQUILIBRIST_CACHE", str(tmp_path / "cache"))
    system = get_system("cartpole", F_min=-20.0, F_max=20.0)
    ctrl = mpc(system, design=design(system, rate=200.0), horizon=9, estimator="state")
    installed = MPCRuntime(ctrl)
    monkeypatch.setattr(daqp_library, "_INSTALLED", [None])
    objs = daqp_objects()
    pristine = {p.name: p.read_bytes() for p in objs}
    victim = next(p for p in objs if "daqp" in p.stem)
    victim.write_bytes(victim.read_bytes()[:100])
    again = daqp_objects()
    assert again == objs and {p.name: p.read_bytes() for p in again} == pristine
    rt, ref = MPCRuntime(ctrl), ReferenceMPC(ctrl)
    assert b"_daqp." not in compiled_library(ctrl).read_bytes()  # DAQP linked in, not needed
    for dx in _states(3, 40):
        move = rt.solve(dx)
        np.testing.assert_allclose(move, ref.solve(dx), rtol=0, atol=1e-9)
        assert rt.last_status == ref.last_status
        assert move.tolist() == installed.solve(dx).tolist()
