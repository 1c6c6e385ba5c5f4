"""The shipped derived model in Python and in the compiled core: the same bits.

Each catalogue system's ``f`` runs as plain Python (the shipped module, as
the cache runs it) and, translated to C (:mod:`equilibrist.native.pyc`), in
the simulation core. The two must perform the same IEEE operations in the
same order (docs/reproducibility.md): here they are compared byte for byte
at random states, inputs and parameters. An integer power is where they
once parted: Python's ``x ** 2`` calls the C library's ``pow`` (glibc 2.36
rounds some inputs differently from ``x * x``) while the C computes the
product, so the generated text writes the product
(:func:`equilibrist.numeric.libm.power_product`). The core computes ``f``
in C; the Jacobians and the other functions are Python only.
"""

from __future__ import annotations

import zlib

import numpy as np
import pytest

from equilibrist.mechanics.definition import Entry
from equilibrist.numeric import cache, libm
from equilibrist.systems import registry

ENTRIES = registry.all_entries()
IDS = [e.spec.key for e in ENTRIES]

#: Random points per system: before the products, about 1 in 1,000 (the cart-pole) to 1 in
#: 5 (the gyroscope) of them differed in the last bit.
N_POINTS = 2000


def _shipped_f(entry: Entry):
    path = cache.packaged_path(entry)
    assert path is not None and path.is_file(), path
    namespace: dict[str, object] = {"__name__": f"shipped_{path.stem.replace('.', '_')}"}
    exec(compile(path.read_text(), str(path), "exec"), namespace)  # the package's own file
    return namespace["f"]


@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_the_python_f_is_the_compiled_f_to_the_bit(entry: Entry) -> None:
    from equilibrist.numeric.lookup import system_from_key
    from equilibrist.sim.simcore import load_core

    system = system_from_key(entry.spec.key)
    # The core is compiled from the system's module: the shipped text, copied.
    assert system.compiled.module_path.read_text() == cache.packaged_path(entry).read_text()
    core = load_core(system)
    f = _shipped_f(entry)
    n, m = system.n_states, system.n_inputs
    p0 = np.array(system.p, dtype=float)
    rng = np.random.default_rng(zlib.crc32(entry.spec.key.encode()))
    mine, theirs = np.empty(n), np.empty(n)
    differ = []
    for _ in range(N_POINTS):
        x = rng.uniform(-4.0, 4.0, n)
        u = rng.uniform(-2.0, 2.0, m)
        # Each default scaled in [0.7, 1.3] (a zero one, a friction, drawn in [0.01, 0.1]).
        p = np.where(p0 != 0.0, p0 * rng.uniform(0.7, 1.3, p0.size),
                     rng.uniform(0.01, 0.1, p0.size))
        f(x, u, p, mine)
        core.f(x, u, p, theirs)
        if mine.tobytes() != theirs.tobytes():
            differ.append((x.tolist(), u.tolist(), p.tolist(), (mine - theirs).tolist()))
    assert not differ, f"{len(differ)} of {N_POINTS} points differ, the first: {differ[0]}"


def test_a_power_is_the_product_the_c_translation_writes() -> None:
    """One rule, written once: the squares and their order, for both forms."""
    square = lambda v: f"({v} * {v})"  # noqa: E731
    assert libm.power_product("x", 2, square) == "(x * x)"
    assert libm.power_product("x", 3, square) == "(x * (x * x))"
    assert libm.power_product("x", 4, square) == "((x * x) * (x * x))"
    assert libm.power_product("x", -2, square) == "(1.0 / (x * x))"
    with pytest.raises(ValueError):
        libm.power_product("x", libm.PRODUCT_POWER_MAX + 1, square)
    rng = np.random.default_rng(7)
    for k in (2, 3, 4, 5, 6, 7, 13, -2, -3, 64):
        text = libm.power_product("x", k, square)
        for x in rng.uniform(-3.0, 3.0, 20):
            assert abs(eval(text, {"x": float(x)}) - x**k) <= 1e-13 * abs(x**k)


def test_the_generated_text_has_no_integer_power() -> None:
    """No ``**`` with an integer exponent in a shipped model's code (comments aside)."""
    import io
    import itertools
    import tokenize

    for entry in ENTRIES:
        path = cache.packaged_path(entry)
        assert path is not None
        tokens = [t for t in tokenize.generate_tokens(io.StringIO(path.read_text()).readline)
                  if t.string not in ("(", "-")]
        for op, exponent in itertools.pairwise(tokens):
            if op.string == "**":
                assert not (exponent.type == tokenize.NUMBER and exponent.string.isdigit()), (
                    path.name, op.start)
