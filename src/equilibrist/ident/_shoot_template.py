"""Template of the compiled multiple-shooting integrator (numba).

This file is not imported by equilibrist. :mod:`equilibrist.ident.kernel`
copies everything below the marker line into one generated module per
system, right after that system's generated ``f``, so numba compiles the
loops with that system's dynamics inlined and caches the machine code on
disk beside the module.

Conventions (float64 arrays unless said otherwise):

- ``t`` (n_rows,) sample times, ``u`` (n_rows, m) the logged input, held
  from ``t[k]`` to ``t[k + 1]`` (zero-order hold).
- ``bounds`` (n_seg + 1,) int64 sample indices ``b_0 = 0 < b_1 < ... < b_S
  = n_rows - 1``: segment ``s`` starts from the state ``xs[s]`` at
  ``t[b_s]`` and runs to ``t[b_{s+1}]``.
- ``n_sub`` (n_rows - 1,) int64 RK4 steps per sample interval.
- Outputs: ``yhat[k]`` the predicted measured states (``c_idx``) at every
  sample (the last one from the last segment's end), ``xend[s]`` each
  segment's state at its end (compared with ``xs[s + 1]``: the continuity
  defect).
"""

# The RK4 step (_rk4_free) is appended from equilibrist/sim/_rk4_template.py.
# ruff: noqa: F821
import numpy as np
from numba import njit

N_STATES = 1
N_INPUTS = 1


def f(x, u, p, out):
    """Placeholder of the system's generated dynamics."""
    raise NotImplementedError


# Placeholders of the generated module's copy of equilibrist.numeric.libm.
from equilibrist.numeric.libm import eq_cos, eq_kcos, eq_ksin, eq_log, eq_rem_pio2, eq_sin  # noqa: E402

# ---8<--- shooting body: everything below is copied into each system's module

_sjit = njit(cache=True, error_model="numpy")
# The names the RK4 step (equilibrist.sim._rk4_template, appended below) uses.
_inline = njit(cache=True, error_model="numpy", inline="always")
# The project's sin and cos (equilibrist.numeric.libm, copied into the
# system's module with f), compiled: the same bits on every CPU, those of
# the simulation core.
eq_ksin = _sjit(eq_ksin)
eq_kcos = _sjit(eq_kcos)
eq_rem_pio2 = _sjit(eq_rem_pio2)
eq_sin = _sjit(eq_sin)
eq_cos = _sjit(eq_cos)
eq_log = _sjit(eq_log)
_fjit = _inline(f)
_N = N_STATES


@_sjit
def shoot_many(P, XS, bounds, t, u, n_sub, c_idx, yhat, xend):
    """Run every segment for each of ``K`` cases.

    ``P`` (K, n_p) parameter vectors, ``XS`` (K, n_seg, n) segment initial
    states; ``yhat`` (K, n_rows, ny) and ``xend`` (K, n_seg, n) are written.
    A state that stops being finite stays so (the residuals say it).
    """
    n = _N
    ny = c_idx.shape[0]
    n_seg = bounds.shape[0] - 1
    x = np.empty(n)
    k1 = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    xt = np.empty(n)
    for c in range(P.shape[0]):
        p = P[c]
        for s in range(n_seg):
            for i in range(n):
                x[i] = XS[c, s, i]
            for k in range(bounds[s], bounds[s + 1]):
                for j in range(ny):
                    yhat[c, k, j] = x[c_idx[j]]
                steps = n_sub[k]
                h = (t[k + 1] - t[k]) / steps
                uk = u[k]
                for _ in range(steps):
                    _rk4_free(x, uk, p, h, k1, k2, k3, k4, xt)
            for i in range(n):
                xend[c, s, i] = x[i]
        last = bounds[n_seg]
        for j in range(ny):
            yhat[c, last, j] = xend[c, n_seg - 1, c_idx[j]]


@_sjit
def innovations(p, x0, t, u, n_sub, c_idx, gain, y, off, e):
    """One-step prediction errors of a Kalman filter with a fixed *gain* (n, ny).

    The state is predicted with the model (RK4, the logged input held) and
    corrected by ``gain`` times the error; ``e[k]`` is the measurement at
    ``t[k]`` minus ``off`` minus its prediction.
    """
    n = _N
    ny = c_idx.shape[0]
    x = x0.copy()
    k1 = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    xt = np.empty(n)
    n_rows = t.shape[0]
    for k in range(n_rows):
        for j in range(ny):
            e[k, j] = y[k, j] - off[j] - x[c_idx[j]]
        for i in range(n):
            v = 0.0
            for j in range(ny):
                v += gain[i, j] * e[k, j]
            x[i] += v
        if k + 1 < n_rows:
            steps = n_sub[k]
            h = (t[k + 1] - t[k]) / steps
            uk = u[k]
            for _ in range(steps):
                _rk4_free(x, uk, p, h, k1, k2, k3, k4, xt)
