"""The on-disk cache of derived models: reuse, invalidation, agreement with a fresh derivation."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from equilibrist.numeric import cache
from equilibrist.systems import registry


@pytest.fixture
def fresh_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("EQUILIBRIST_CACHE", str(tmp_path))
    monkeypatch.setattr(cache, "_MEMO", {})
    return tmp_path


def test_second_load_reads_the_cache_without_deriving(fresh_cache, monkeypatch) -> None:
    # Without the shipped derivations (tests/numeric/test_packaged_models.py covers those): derived.
    monkeypatch.setattr(cache, "PACKAGED", fresh_cache / "nothing-shipped")
    entry = registry.lookup("cartpole")
    first = cache.load(entry)
    files = sorted(p.name for p in fresh_cache.iterdir())
    assert any(f.endswith(".py") for f in files) and any(f.endswith(".pkl") for f in files)

    monkeypatch.setattr(cache, "_MEMO", {})

    def refuse(_entry):
        raise AssertionError("derived again although the cache was valid")

    monkeypatch.setattr(cache, "derive", refuse)
    second = cache.load(entry)
    assert second.key == first.key
    x, u = np.array([0.1, 0.2, -0.3, 0.4]), np.array([1.5])
    out1, out2 = np.empty(4), np.empty(4)
    first.functions.f(x, u, np.array([10, 1, 0.5, 0.08333, 0.1, 0.2, 9.8, -1, 1.0]), out1)
    second.functions.f(x, u, np.array([10, 1, 0.5, 0.08333, 0.1, 0.2, 9.8, -1, 1.0]), out2)
    assert np.array_equal(out1, out2)


def test_changed_model_source_changes_the_key(fresh_cache, monkeypatch) -> None:
    entry = registry.lookup("cartpole")
    key = cache.model_key(entry)
    original = cache._source_of

    def edited(name: str) -> bytes:
        data = original(name)
        return data + b"\n# edited\n" if name == entry.module else data

    monkeypatch.setattr(cache, "_source_of", edited)
    assert cache.model_key(entry) != key
    calls = []
    real_derive = cache.derive

    def counting(e):
        calls.append(e.spec.key)
        return real_derive(e)

    monkeypatch.setattr(cache, "derive", counting)
    cache.load(entry)
    assert calls == ["cartpole"]


def test_cached_symbolic_model_equals_a_fresh_derivation(fresh_cache) -> None:
    entry = registry.lookup("cartpole")
    cached = cache.load(entry).symbolic
    fresh = cache.derive(entry)
    diff = (cached.f - fresh.f).applyfunc(sp.simplify)
    assert diff == sp.zeros(*diff.shape)
    assert (cached.A - fresh.A).applyfunc(sp.simplify) == sp.zeros(*cached.A.shape)


@pytest.mark.parametrize(
    "damage",
    [b"", b"N_STATES = 4\n", b"def f(:\n", b"raise RuntimeError('planted')\n",
     b"N_STATES = 7\nN_INPUTS = 1\nN_Q = 2\nCONSERVED = ()\n"
     b"f = jac = mass_matrix = energy = conserved = None\n"],
    ids=["empty", "truncated", "syntax", "raises", "wrong-size"],
)
def test_damaged_generated_model_is_rebuilt(fresh_cache, damage) -> None:
    entry = registry.lookup("cartpole")
    compiled = cache.load(entry)
    compiled.module_path.write_bytes(damage)
    cache._MEMO.clear()
    again = cache.load(entry)
    out = np.empty(4)
    p = np.array([10, 1, 0.5, 0.08333, 0.0, 0.0, 9.8, 1.0, -200, 200.0])
    again.functions.f(np.array([0.0, 0.1, 0.0, 0.0]), np.array([0.0]), p, out)
    # The pole falls away from upright: the independent textbook value of theta_ddot.
    m_c, m_p, l, I_p, g = 10, 1, 0.5, 0.08333, 9.8
    d = I_p * (m_c + m_p) + m_c * m_p * l**2
    expected = m_p * g * l * (m_c + m_p) * np.sin(0.1) / (d + m_p**2 * l**2 * np.sin(0.1) ** 2)
    assert out[3] == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("damage", [b"", b"garbage", b"\x80\x05K\x03."], ids=["empty", "garbage", "an-int"])
def test_damaged_symbolic_model_is_rebuilt(fresh_cache, damage) -> None:
    entry = registry.lookup("cartpole")
    compiled = cache.load(entry)
    compiled.pickle_path.write_bytes(damage)
    cache._MEMO.clear()
    model = cache.load(entry).symbolic
    assert model.spec_key == "cartpole" and model.M.shape == (2, 2)


def test_cache_folder_problems_name_the_variable(tmp_path, monkeypatch) -> None:
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o777)
    for where, expected in ((a_file, "is not a folder"), (a_file / "below", "cannot be created"),
                            (shared, "can be written by other users")):
        monkeypatch.setenv("EQUILIBRIST_CACHE", str(where))
        with pytest.raises(cache.CacheError, match="EQUILIBRIST_CACHE") as info:
            cache.cache_dir()
        assert expected in str(info.value)


# -- damaged files of the compiled core: rebuilt, not a traceback ---------------------------
# A fresh process loads the core from the cache folder and steps it: RK4 steps
# of the cart-pole (the smallest entry to compile again).
_STEP_SCRIPT = """
import numpy as np
from equilibrist import get_system
from equilibrist.sim.kernel import load_kernel
system = get_system("cartpole")
x = np.array([0.0, 0.1, 0.0, 0.0])
load_kernel(system).rk4_steps(x, np.array([0.5]), np.array(system.p, dtype=float), 0.001, 100)
print(repr(x.tolist()))
"""


def _step_in_a_process(folder) -> tuple[list[float], str]:
    import ast
    import os
    import subprocess
    import sys

    env = {**os.environ, "EQUILIBRIST_CACHE": str(folder)}
    proc = subprocess.run([sys.executable, "-c", _STEP_SCRIPT], capture_output=True, text=True,
                          env=env, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    return ast.literal_eval(proc.stdout.strip()), proc.stderr


def _step_here(folder) -> list[float]:
    """:data:`_STEP_SCRIPT`'s numbers from *folder* in this process, as a fresh process gets
    them: the libraries loaded so far (by path, and the cores by system) are forgotten
    within the call, so the core is looked up in *folder* and built there if it is not whole
    (the build's own checks; :func:`_step_in_a_process` pays Python's start for the same)."""
    from equilibrist import get_system
    from equilibrist.native import build
    from equilibrist.sim import simcore
    from equilibrist.sim.kernel import load_kernel

    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("EQUILIBRIST_CACHE", str(folder))
        patch.setattr(build, "_LOADED", {})
        patch.setattr(simcore, "_CORES", {})
        system = get_system("cartpole")
        x = np.array([0.0, 0.1, 0.0, 0.0])
        load_kernel(system).rk4_steps(x, np.array([0.5]), np.array(system.p, dtype=float),
                                      0.001, 100)
    return x.tolist()


@pytest.fixture(scope="module")
def compiled_cache(tmp_path_factory):
    folder = tmp_path_factory.mktemp("pristine")
    folder.chmod(0o700)
    numbers, _ = _step_in_a_process(folder)
    return folder, numbers


def test_a_core_loaded_in_this_process_equals_a_fresh_process(compiled_cache) -> None:
    """What the damage tests below rely on: :func:`_step_here` on a whole cache gets a fresh
    process's numbers, and compiles nothing (the folder's library is loaded as it is)."""
    pristine, expected = compiled_cache
    before = {p.name: p.stat().st_mtime_ns for p in pristine.glob("native/*")}
    assert _step_here(pristine) == expected
    assert {p.name: p.stat().st_mtime_ns for p in pristine.glob("native/*")} == before


def _truncate(path) -> None:
    path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])


_CORE_DAMAGE = {
    # the compiled library: cut short, garbage, another library in its place
    "library-truncated": ("native/*.so", _truncate),
    "library-garbage": ("native/*.so", lambda p: p.write_bytes(b"garbage\n")),
    "library-emptied": ("native/*.so", lambda p: p.write_bytes(b"")),
    # its digest: garbage, or gone
    "digest-garbage": ("native/*.so.sha256", lambda p: p.write_text("0" * 64)),
    "digest-missing": ("native/*.so.sha256", lambda p: p.unlink()),
}


@pytest.mark.parametrize("damage", sorted(_CORE_DAMAGE))
def test_damaged_compiled_core_is_rebuilt(compiled_cache, tmp_path, damage) -> None:
    import hashlib
    import shutil

    pristine, expected = compiled_cache
    folder = tmp_path / "cache"
    shutil.copytree(pristine, folder)
    pattern, harm = _CORE_DAMAGE[damage]
    damaged = sorted(folder.glob(pattern))
    assert damaged, pattern
    for path in damaged:
        harm(path)
    numbers = _step_here(folder)
    assert numbers == expected  # the same numbers, to the bit, as a fresh process's
    for lib in folder.glob("native/*.so"):  # rebuilt whole, its digest beside it
        digest = lib.with_suffix(".so.sha256").read_text().strip()
        assert digest == hashlib.sha256(lib.read_bytes()).hexdigest(), lib.name


def test_two_processes_build_the_same_core_at_once(tmp_path) -> None:
    """Two fresh processes that build the same core into one empty cache: neither fails,
    both get the same numbers, the library left behind is whole, and it was compiled once
    (the second waits on the first's build lock, then loads its library)."""
    import hashlib
    import os
    import shutil
    import subprocess
    import sys

    folder = tmp_path / "cache"
    folder.mkdir(mode=0o700)
    log = tmp_path / "compiles.log"
    cc = tmp_path / "cc"  # the machine's compiler, slowed and counted for a build
    cc.write_text("#!/bin/sh\n"
                  f'case "$*" in *" -o "*) echo build >> "{log}"; sleep 1;; esac\n'
                  f'exec {shutil.which("cc") or shutil.which("gcc")} "$@"\n')
    cc.chmod(0o755)
    env = {**os.environ, "EQUILIBRIST_CACHE": str(folder), "CC": str(cc)}
    procs = [subprocess.Popen([sys.executable, "-c", _STEP_SCRIPT], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=env) for _ in range(2)]
    outs = [p.communicate(timeout=600) for p in procs]
    assert [p.returncode for p in procs] == [0, 0], [e for _o, e in outs]
    assert outs[0][0] == outs[1][0]
    libs = sorted(folder.glob("native/*.so"))
    assert len(libs) == 1
    digest = libs[0].with_suffix(".so.sha256").read_text().strip()
    assert digest == hashlib.sha256(libs[0].read_bytes()).hexdigest()
    assert not [p.name for p in folder.glob("native/*")
                if p.suffix not in (".so", ".c", ".sha256", ".lock")]
    assert log.read_text().split() == ["build"]  # one compile for two processes


def test_without_a_c_compiler_the_command_says_what_to_install(tmp_path) -> None:
    """No C compiler (and no ziglang package): one line naming what to install, no traceback."""
    import os
    import subprocess
    import sys

    folder = tmp_path / "cache"
    folder.mkdir(mode=0o700)
    stub = tmp_path / "stub"
    stub.mkdir()
    (stub / "ziglang.py").write_text("raise ImportError('not installed here')\n")
    env = {**os.environ, "EQUILIBRIST_CACHE": str(folder), "CC": str(tmp_path / "no-cc"),
           "PYTHONPATH": os.pathsep.join([str(stub), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "-m", "equilibrist.cli.main", "simulate", "cartpole",
                           "--duration", "1"], capture_output=True, text=True, env=env,
                          timeout=300, check=False)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "no C compiler" in lines[0]
    assert "gcc" in lines[0] and "ziglang" in lines[0]
