"""The catalogue's derived models shipped with the package: today's derivation, and its numbers.

``numeric/derived/`` holds each catalogue system's generated module, so that
a first use needs neither sympy nor a derivation. Here every system is
derived again (sympy.physics.mechanics, as on first use without the shipped
files), and

* its generated text is compared with the shipped one, character for
  character: a build-freshness check (a change to a system, the mechanics
  layer or the code generation that is not followed by ``make derived``
  fails here);
* the shipped module is run and its numbers (``f``, ``jac``, ``mass_matrix``,
  ``energy``, ``conserved``, ``points`` and the scalar functions a
  controller copies) are compared with the fresh derivation's expressions
  evaluated by sympy's ``lambdify`` with numpy, at random states, inputs and
  parameters: a correctness check that does not go through the generated
  text (a wrong printing, common-subexpression step or ``eq_sin`` fails here
  even where the text was regenerated).
"""

from __future__ import annotations

import os
import subprocess
import sys
import zlib

import numpy as np
import pytest

from equilibrist.mechanics.definition import Entry
from equilibrist.numeric import cache
from equilibrist.systems import registry

ENTRIES = registry.all_entries()
IDS = [e.spec.key for e in ENTRIES]

#: The fresh derivations, one per system for the module (both checks use them: deriving
#: takes seconds).
_DERIVED: dict[str, object] = {}


def _fresh(entry: Entry):
    """The symbolic model of *entry* derived now (its Jacobians formed, as the generator does)."""
    if entry.spec.key not in _DERIVED:
        model = cache.derive(entry)
        _ = model.A, model.B
        _DERIVED[entry.spec.key] = model
    return _DERIVED[entry.spec.key]


@pytest.mark.slow
@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_the_shipped_derivation_is_todays(entry: Entry) -> None:
    from equilibrist.numeric.codegen import generate_source

    shipped = cache.packaged_path(entry)
    assert shipped is not None
    assert shipped.is_file(), f"{shipped.name} is missing: run make derived"
    assert shipped.read_text() == generate_source(_fresh(entry)), (
        f"{shipped.name} differs from today's derivation: run make derived")


def _shipped_module(entry: Entry) -> dict[str, object]:
    """The shipped module of *entry*, run as the cache runs it (plain Python)."""
    path = cache.packaged_path(entry)
    assert path is not None and path.is_file(), path
    namespace: dict[str, object] = {"__name__": f"shipped_{path.stem.replace('.', '_')}"}
    exec(compile(path.read_text(), str(path), "exec"), namespace)  # the package's own file
    return namespace


def _random_parameters(entry: Entry, model, rng: np.random.Generator) -> np.ndarray:
    """The model's parameter vector: each spec default scaled by a random factor in
    [0.7, 1.3] (a zero default, a friction or an offset, drawn in [0.01, 0.1]); the input
    limits, which no expression reads, 1."""
    defaults = {p.name: p.default for p in entry.spec.parameters}
    out = []
    for s in model.params:
        d = defaults.get(s.name, 1.0)
        out.append(d * rng.uniform(0.7, 1.3) if d != 0.0 else rng.uniform(0.01, 0.1))
    return np.array(out)


def _close(got: np.ndarray, want: np.ndarray, what: str) -> None:
    want = np.asarray(want, dtype=float)
    scale = max(1.0, float(np.max(np.abs(want)))) if want.size else 1.0
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-9 * scale, err_msg=what)


@pytest.mark.slow
@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_the_shipped_model_computes_todays_derivation(entry: Entry) -> None:
    import sympy as sp

    model = _fresh(entry)
    gen = _shipped_module(entry)
    xs, us, ps = model.states, model.inputs, model.params
    n, m, nq = len(xs), len(us), model.n_q
    args = (xs, us, ps)
    f_of = sp.lambdify(args, model.f, "numpy")
    A_of = sp.lambdify(args, model.A, "numpy")
    B_of = sp.lambdify(args, model.B, "numpy") if m else None
    energy = sp.nan if model.energy is None else model.energy
    E_of = sp.lambdify((xs, ps), energy, "numpy")
    cons = list(model.conserved.values())
    C_of = sp.lambdify((xs, ps), cons, "numpy")
    M_of = sp.lambdify((xs, ps), model.M, "numpy") if model.M is not None else None
    coords = [v for pt in model.points.values() for v in pt]
    P_of = sp.lambdify((xs, ps), coords, "numpy")
    assert (gen["N_STATES"], gen["N_INPUTS"], gen["N_Q"]) == (n, m, nq)
    assert gen["CONSERVED"] == tuple(model.conserved)

    rng = np.random.default_rng(zlib.crc32(entry.spec.key.encode()))
    for _ in range(8):
        x = rng.uniform(-4.0, 4.0, n)
        u = rng.uniform(-2.0, 2.0, m)
        p = _random_parameters(entry, model, rng)
        out = np.full(n, np.nan)
        gen["f"](x, u, p, out)
        _close(out, np.ravel(f_of(x, u, p)), "f")
        A, B = np.full((n, n), np.nan), np.full((n, m), np.nan)
        gen["jac"](x, u, p, A, B)
        _close(A, np.array(A_of(x, u, p), dtype=float), "df/dx")
        if m:
            _close(B, np.array(B_of(x, u, p), dtype=float), "df/du")
        e = gen["energy"](x, p)
        want_e = float(E_of(x, p))
        if np.isnan(want_e):
            assert np.isnan(e)
        else:
            _close(np.array([e]), np.array([want_e]), "energy")
        c = np.full(len(cons), np.nan)
        gen["conserved"](x, p, c)
        _close(c, np.array(C_of(x, p), dtype=float), "conserved")
        pts = np.full((len(model.points), 3), np.nan)
        gen["points"](x, p, pts)
        _close(pts.ravel(), np.array(P_of(x, p), dtype=float), "points")
        if M_of is None:
            continue
        M = np.full((nq, nq), np.nan)
        gen["mass_matrix"](x, p, M)
        want_M = np.array(M_of(x, p), dtype=float)
        _close(M, want_M, "mass matrix")
        # The scalar functions, their parameters read at an offset of a longer vector.
        o = 3
        padded = np.concatenate([rng.uniform(-9.0, 9.0, o), p])
        qdd = [gen["scalar_qdd"](i, *x, *u, padded, o) for i in range(nq)]
        _close(np.array(qdd), np.ravel(f_of(x, u, p))[nq:2 * nq], "scalar_qdd")
        mass = [[gen["scalar_mass"](i, j, *x, padded, o) for j in range(nq)] for i in range(nq)]
        _close(np.array(mass), want_M, "scalar_mass")
        if not np.isnan(want_e):
            _close(np.array([gen["scalar_energy"](*x, padded, o)]), np.array([want_e]),
                   "scalar_energy")


def test_no_stale_files_are_shipped() -> None:
    wanted = {cache.packaged_path(e) for e in ENTRIES}
    assert set(cache.PACKAGED.glob("*.py.txt")) == wanted


def test_a_first_use_of_a_catalogue_system_needs_no_sympy(tmp_path) -> None:
    """Empty cache: the cart-pole's module comes from the package; sympy is not imported
    until the symbolic model is asked for, and then it is derived."""
    folder = tmp_path / "cache"
    folder.mkdir(mode=0o700)
    code = """
import sys
import numpy as np
from equilibrist import get_system
s = get_system("cartpole")
out = np.empty(4)
s.functions.f(np.array([0.0, 0.1, 0.0, 0.0]), np.zeros(1), s.p, out)
print("sympy" in sys.modules)
print(s.symbolic.M.shape)
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env={**os.environ, "EQUILIBRIST_CACHE": str(folder)}, check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split("\n")[:2] == ["False", "(2, 2)"]
    assert sorted(p.suffix for p in folder.glob("cartpole_*")) == [".pkl", ".py"]
