"""The fixed C code of the linear controller form, on its own, against the Python controller.

The C text (``export.linear_c.LINEAR_C``) is compiled with the export's strict flags
behind a small harness and run on random forms of every shape (with and without a
controller state, references, measurements): in double precision it must give the
very numbers of ``LinearController.output/update/estimate`` (the source the
simulation core compiles), in single precision numbers within float rounding.
"""

from __future__ import annotations

import ctypes
import tempfile
from pathlib import Path

import numpy as np
import pytest

from equilibrist.control.controller import LinearController
from equilibrist.export.linear_c import LINEAR_C
from equilibrist.export.native import build_shared_library

HARNESS = """
#include <stddef.h>
#define EQ_REAL {real}
{code}
static eq_linear_form make(const int *sizes, const EQ_REAL *const *blocks)
{{
    eq_linear_form f;
    f.nz = sizes[0]; f.ny = sizes[1]; f.nr = sizes[2]; f.m = sizes[3]; f.n = sizes[4];
    f.Ac = blocks[0]; f.By = blocks[1]; f.Br = blocks[2]; f.Bu = blocks[3]; f.Cc = blocks[4];
    f.Dy = blocks[5]; f.Dr = blocks[6]; f.Ez = blocks[7]; f.Ey = blocks[8];
    f.u_op = blocks[9]; f.y_op = blocks[10]; f.r_op = blocks[11];
    return f;
}}
void h_output(const int *s, const EQ_REAL *const *b, const EQ_REAL *z, const EQ_REAL *y,
              const EQ_REAL *r, EQ_REAL *u)
{{
    eq_linear_form f = make(s, b);
    eq_linear_output(&f, z, y, r, u);
}}
void h_update(const int *s, const EQ_REAL *const *b, const EQ_REAL *z, const EQ_REAL *y,
              const EQ_REAL *r, const EQ_REAL *ua, EQ_REAL *zo)
{{
    eq_linear_form f = make(s, b);
    eq_linear_update(&f, z, y, r, ua, zo);
}}
void h_estimate(const int *s, const EQ_REAL *const *b, const EQ_REAL *z, const EQ_REAL *y,
                EQ_REAL *dx)
{{
    eq_linear_form f = make(s, b);
    eq_linear_estimate(&f, z, y, dx);
}}
"""

BLOCKS = ("Ac", "By", "Br", "Bu", "Cc", "Dy", "Dr", "Ez", "Ey", "u_op", "y_op", "r_op")


@pytest.fixture(scope="module", params=["double", "float"])
def harness(request):
    real = request.param
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "h.c"
        src.write_text(HARNESS.format(real=real, code=LINEAR_C))
        lib = build_shared_library([src], Path(tmp) / "libh.so", include=Path(tmp))
        yield real, ctypes.CDLL(str(lib))


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
def test_fixed_c_step_is_the_python_controller(harness, sizes):
    real, lib = harness
    ctype = ctypes.c_double if real == "double" else ctypes.c_float
    dtype = np.float64 if real == "double" else np.float32
    rng = np.random.default_rng(sum(sizes))
    nz, ny, nr, m, n = sizes
    ctrl = random_form(rng, *sizes)
    # The C side reads the form's numbers rounded to its precision; so does the reference.
    keep = [np.ascontiguousarray(np.asarray(getattr(ctrl, b), dtype=dtype).reshape(-1)) for b in BLOCKS]
    ptrs = (ctypes.POINTER(ctype) * len(BLOCKS))(*[
        a.ctypes.data_as(ctypes.POINTER(ctype)) if a.size else ctypes.POINTER(ctype)() for a in keep
    ])
    c_sizes = (ctypes.c_int * 5)(nz, ny, nr, m, n)

    def ptr(a):
        return a.ctypes.data_as(ctypes.POINTER(ctype))

    z = rng.standard_normal(nz).astype(dtype)
    for step in range(20):
        y = rng.standard_normal(ny).astype(dtype)
        r = rng.standard_normal(nr).astype(dtype)
        u = np.zeros(max(m, 1), dtype=dtype)
        lib.h_output(c_sizes, ptrs, ptr(z), ptr(y), ptr(r) if nr else None, ptr(u))
        ua = (u[:m] + 0.1 * rng.standard_normal(m)).astype(dtype)
        zo = np.zeros(max(nz, 1), dtype=dtype)
        lib.h_update(c_sizes, ptrs, ptr(z), ptr(y), ptr(r) if nr else None, ptr(ua), ptr(zo))
        dx = np.zeros(n, dtype=dtype)
        lib.h_estimate(c_sizes, ptrs, ptr(z), ptr(y), ptr(dx))
        if real == "double":
            np.testing.assert_array_equal(u[:m], ctrl.output(z, y, r))
            np.testing.assert_array_equal(zo[:nz], ctrl.update(z, y, r, ua))
            np.testing.assert_array_equal(ctrl.x_op + dx, ctrl.estimate(z, y))
        else:
            scale = 1e-4 * (1 + np.abs(ctrl.output(z, y, r)))
            assert np.all(np.abs(u[:m] - ctrl.output(z, y, r)) <= scale), step
            assert np.allclose(zo[:nz], ctrl.update(z, y, r, ua), rtol=1e-4, atol=1e-4)
        z = zo[:nz].copy()


def test_null_reference_holds_the_operating_reference(harness):
    real, lib = harness
    if real != "double":
        return
    rng = np.random.default_rng(5)
    ctrl = random_form(rng, 2, 2, 1, 1, 3)
    keep = [np.ascontiguousarray(np.asarray(getattr(ctrl, b), dtype=float).reshape(-1)) for b in BLOCKS]
    P = ctypes.POINTER(ctypes.c_double)
    ptrs = (P * len(BLOCKS))(*[a.ctypes.data_as(P) for a in keep])
    c_sizes = (ctypes.c_int * 5)(2, 2, 1, 1, 3)
    z, y, u = rng.standard_normal(2), rng.standard_normal(2), np.zeros(1)
    lib.h_output(c_sizes, ptrs, z.ctypes.data_as(P), y.ctypes.data_as(P), None, u.ctypes.data_as(P))
    np.testing.assert_array_equal(u, ctrl.output(z, y, ctrl.r_op))
