"""The linear controller's library in C, on its own, against the Python controller.

The C the exports write (``native.linear_c.linear_c``: the library's Python source translated
for one controller's sizes) is compiled with the export's strict flags behind a small harness
and run on random forms of every shape (with and without a controller state, references,
measurements): in double precision it must give the very numbers of
``LinearController.output/update/estimate`` (the source the simulation core compiles), in
single precision numbers within float rounding.
"""

from __future__ import annotations

import ctypes
import tempfile
from pathlib import Path

import numpy as np
import pytest

from equilibrist.control.linear import LinearController
from equilibrist.native.linear_c import deviation_vector, linear_c
from equilibrist.native.shared_library import build_shared_library

HARNESS = """
#include <stddef.h>
#include <stdint.h>
typedef {real} real;
{code}
void h_output(real *p, int64_t np, real *z, real *y, real *r, real *u)
{{
    eq_linear_output(0.0, z, {nz}, y, {ny}, r, {nr}, p, np, u, {m});
}}
void h_update(real *p, int64_t np, real *z, real *y, real *r, real *ua, real *zo)
{{
    eq_linear_update(0.0, z, {nz}, y, {ny}, r, {nr}, ua, {m}, p, np, zo, {nz});
}}
void h_estimate(real *p, int64_t np, real *z, real *y, real *dx)
{{
    eq_linear_estimate(0.0, z, {nz}, y, {ny}, NULL, 0, p, np, dx, {n});
}}
"""


def _harness(tmp: Path, real: str, sizes: tuple[int, int, int, int, int]) -> ctypes.CDLL:
    nz, ny, nr, m, n = sizes
    src = tmp / f"h_{real}_{'_'.join(map(str, sizes))}.c"
    code = linear_c({"nz": nz, "ny": ny, "nr": nr, "m": m, "n": n}, real)
    src.write_text(HARNESS.format(real=real, code=code, nz=nz, ny=ny, nr=nr, m=m, n=n))
    return ctypes.CDLL(str(build_shared_library([src], src.with_suffix(".so"), include=tmp)))


@pytest.fixture(scope="module", params=["double", "float"])
def harness(request):
    with tempfile.TemporaryDirectory() as tmp:
        yield request.param, lambda sizes: _harness(Path(tmp), request.param, sizes)


def random_form(rng, nz, ny, nr, m, n) -> LinearController:
    states = tuple(f"s{i}" for i in range(n))
    outs = states[:ny]
    tracked = states[:nr]

    def mat(r, c):
        return rng.standard_normal((r, c))

    return LinearController(
        Ac=mat(nz, nz), By=mat(nz, ny), Br=mat(nz, nr), Bu=mat(nz, m), Cc=mat(m, nz),
        Dy=mat(m, ny), Dr=mat(m, nr), Ez=mat(n, nz), Ey=mat(n, ny), x_op=rng.standard_normal(n),
        u_op=rng.standard_normal(m), y_op=rng.standard_normal(ny), r_op=rng.standard_normal(nr),
        z0=np.zeros(nz), state_map=np.zeros((nz, n)), rate=100.0, state_names=states,
        input_names=tuple(f"u{i}" for i in range(m)), output_names=outs, tracked_names=tracked,
    )


@pytest.mark.parametrize("sizes", [(4, 2, 1, 1, 4), (0, 4, 0, 1, 4), (6, 3, 2, 2, 6),
                                   (1, 1, 0, 1, 2), (3, 2, 2, 2, 3)])
def test_c_library_is_the_python_controller(harness, sizes):
    real, build = harness
    lib = build(sizes)
    ctype = ctypes.c_double if real == "double" else ctypes.c_float
    dtype = np.float64 if real == "double" else np.float32
    rng = np.random.default_rng(sum(sizes))
    nz, ny, nr, m, n = sizes
    ctrl = random_form(rng, *sizes)
    # The C side reads the form's numbers rounded to its precision; so does the reference.
    packed = np.ascontiguousarray(deviation_vector(ctrl.packed()).astype(dtype))
    np_ = ctypes.c_int64(packed.size)

    def ptr(a):
        return a.ctypes.data_as(ctypes.POINTER(ctype)) if a.size else None

    z = rng.standard_normal(nz).astype(dtype)
    for step in range(20):
        y = rng.standard_normal(ny).astype(dtype)
        r = rng.standard_normal(nr).astype(dtype)
        u = np.zeros(m, dtype=dtype)
        lib.h_output(ptr(packed), np_, ptr(z), ptr(y), ptr(r), ptr(u))
        ua = (u + 0.1 * rng.standard_normal(m)).astype(dtype)
        zo = np.zeros(nz, dtype=dtype)
        lib.h_update(ptr(packed), np_, ptr(z), ptr(y), ptr(r), ptr(ua), ptr(zo))
        dx = np.zeros(n, dtype=dtype)
        lib.h_estimate(ptr(packed), np_, ptr(z), ptr(y), ptr(dx))
        if real == "double":
            np.testing.assert_array_equal(u, ctrl.output(z, y, r))
            np.testing.assert_array_equal(zo, ctrl.update(z, y, r, ua))
            np.testing.assert_array_equal(ctrl.x_op + dx, ctrl.estimate(z, y))
        else:
            scale = 1e-4 * (1 + np.abs(ctrl.output(z, y, r)))
            assert np.all(np.abs(u - ctrl.output(z, y, r)) <= scale), step
            assert np.allclose(zo, ctrl.update(z, y, r, ua), rtol=1e-4, atol=1e-4)
            assert np.allclose(ctrl.x_op + dx, ctrl.estimate(z, y), rtol=1e-4, atol=1e-4)
        z = zo.copy()


NULL_HARNESS = """
#include "cartpole_lqg.h"
int n_references(void) { return CARTPOLE_LQG_N_REFERENCES; }
int same_without_reference(const double *y, int steps)
{
    cartpole_lqg_state a, b;
    double ua[CARTPOLE_LQG_N_INPUTS], ub[CARTPOLE_LQG_N_INPUTS];
    int k, i, differ = 0;
    cartpole_lqg_init(&a);
    cartpole_lqg_init(&b);
    for (k = 0; k < steps; ++k) {
        cartpole_lqg_step(&a, y + k * CARTPOLE_LQG_N_MEASUREMENTS, NULL, ua);
        cartpole_lqg_step(&b, y + k * CARTPOLE_LQG_N_MEASUREMENTS, cartpole_lqg_R0, ub);
        for (i = 0; i < CARTPOLE_LQG_N_INPUTS; ++i) differ += ua[i] != ub[i];
    }
    return differ;
}
"""


def test_null_reference_holds_the_operating_reference(tmp_path: Path) -> None:
    """An exported tracking LQG stepped with ``r = NULL`` commands what it commands with the
    operating reference ``R0``, to the bit, sample after sample."""
    from equilibrist.cli.main import main

    out = tmp_path / "lqg"
    assert main(["export", "cartpole", "--out", str(out)]) == 0
    (out / "h.c").write_text(NULL_HARNESS)
    lib = ctypes.CDLL(str(build_shared_library([out / "h.c", out / "cartpole_lqg.c"],
                                               out / "libh.so", include=out)))
    assert lib.n_references() == 1  # the compiled library tracks one reference (the cart's)
    y = np.random.default_rng(2).normal(scale=0.05, size=(50, 2))
    P = ctypes.POINTER(ctypes.c_double)
    assert lib.same_without_reference(np.ascontiguousarray(y).ctypes.data_as(P), 50) == 0
