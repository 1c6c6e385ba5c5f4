"""Template of the fixed-step RK4 step shared by the compiled cores (numba).

This file is not imported by equilibrist. Everything below the marker line
is appended to the simulation core's generated module
(:mod:`equilibrist.sim.kernel`, after ``_kernel_template.py``) and to the
multiple-shooting integrator's (:mod:`equilibrist.ident.kernel`), each of
which defines the names it uses: ``_inline`` (numba's ``njit``, inlined),
``_fjit`` (the system's compiled dynamics) and ``_N`` (its number of
states). So the identification predicts with the very arithmetic that the
simulation and the environments integrate with.
"""

# mypy: ignore-errors
# ruff: noqa: F821
import math

# ---8<--- kernel body: everything below is appended to the compiled cores' bodies

@_inline
def _rk4(x, u, p, w, h, k1, k2, k3, k4, xt):
    # The scratch vectors are separate arrays made once per run: a row view
    # made here, in the innermost loop, would cost reference counting.
    _fjit(x, u, p, k1)
    for i in range(_N):
        xt[i] = x[i] + 0.5 * h * (k1[i] + w[i])
    _fjit(xt, u, p, k2)
    for i in range(_N):
        xt[i] = x[i] + 0.5 * h * (k2[i] + w[i])
    _fjit(xt, u, p, k3)
    for i in range(_N):
        xt[i] = x[i] + h * (k3[i] + w[i])
    _fjit(xt, u, p, k4)
    for i in range(_N):
        x[i] += (h / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i] + 6.0 * w[i])


@_inline
def _rk4_free(x, u, p, h, k1, k2, k3, k4, xt):
    """``_rk4`` without process noise: the same bits as ``_rk4`` with ``w = 0`` unless a
    state is a negative zero (see ``_no_negative_zero``)."""
    _fjit(x, u, p, k1)
    for i in range(_N):
        xt[i] = x[i] + 0.5 * h * k1[i]
    _fjit(xt, u, p, k2)
    for i in range(_N):
        xt[i] = x[i] + 0.5 * h * k2[i]
    _fjit(xt, u, p, k3)
    for i in range(_N):
        xt[i] = x[i] + h * k3[i]
    _fjit(xt, u, p, k4)
    for i in range(_N):
        x[i] += (h / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@_inline
def _no_negative_zero(x):
    """True unless a state is ``-0.0``: the only case where adding a zero noise term
    (``k + 0.0`` turns ``-0.0`` into ``+0.0``) changes an RK4 step's result."""
    clean = True
    for i in range(_N):
        if x[i] == 0.0 and math.copysign(1.0, x[i]) < 0.0:
            clean = False
    return clean


@_inline
def _rk4_step(x, u, p, w, nw, h, k1, k2, k3, k4, xt):
    """One RK4 step with the process noise *w* (``nw`` channels) held over it; without
    noise the noise-free form when it gives the same bits (no state is a negative zero)."""
    if nw == 0 and _no_negative_zero(x):
        _rk4_free(x, u, p, h, k1, k2, k3, k4, xt)
    else:
        _rk4(x, u, p, w, h, k1, k2, k3, k4, xt)
