"""Template of the compiled simulation core (numba).

This file is not imported by equilibrist. :mod:`equilibrist.sim.kernel`
copies everything below the marker line into one generated module per
system, right after that system's generated ``f`` (the numeric layer's
pure-Python dynamics), so numba compiles each loop with that system's
dynamics inlined and caches the machine code on disk beside the module.

Conventions of the core (all arrays float64 unless said otherwise):

- ``x`` absolute state, ``u`` absolute input; the controller works in
  deviation coordinates about ``x_op``, ``u_op``.
- A *sample* ``k`` is a controller instant ``t_k = k T``; a *physics step*
  ``s`` of length ``h = T / n_sub`` runs from ``s h`` to ``(s + 1) h``.
  Events are given by physics-step index.
- The option slots (``iopts``, ``fopts``), the ``status`` slots, the
  columns of a recorded row and of the accumulators, and the rows of the
  scratch array are named in :mod:`equilibrist.sim.layout`; the generator
  writes them into the kernel as constants (``_IO_DELAY``, ``_REC_U_APP``,
  ...). Column blocks whose width depends on the run start at
  ``rec_cols[_REC_<NAME>]`` / ``acc_cols[_ACC_<NAME>]``. The fell code is the
  index of the state that left its region, ``-2`` for a state that stopped
  being a finite number, ``-3`` for the adaptive integrator giving up.
- The controller is the generated module's ``controller_output``,
  ``controller_update`` and ``controller_estimate`` with its parameter
  vector ``cp`` and state ``z``: the linear controller of
  :mod:`equilibrist.control.controller` unless the kernel was generated for
  a nonlinear one. One loop runs them all.
- Randomness: xoshiro256** on a 4-word ``uint64`` state per run, normal
  deviates by Marsaglia's polar method, drawn in a fixed order (the measurement noise of a
  sample, then the process noise of each of its physics steps). Its logarithm is
  the project's (``eq_log``), so the deviates are the same bits on every CPU;
  nothing of ``numpy.random`` runs in the core (the seed only fixes the four
  words, through ``SeedSequence``, which is integer arithmetic).
- Work is done only when asked: the trajectory is written with
  ``iopts[_IO_RECORD]``, the accumulators (peaks, sums) with
  ``iopts[_IO_ACCUMULATE]``, and the controller's estimate is computed only
  for one of them. A noise-free RK4 step skips the (zero) noise terms when
  that gives the same bits (no state is a negative zero).
- Stopping: ``run_one`` and ``run_many`` read a one-element ``int64`` array
  *stop* at every sample and every 4096 physics steps and return when it is
  non-zero. They release the GIL, so another Python thread (the one that
  receives Ctrl-C) can set it while they run.

Nothing allocates inside the loops over samples and physics steps; scratch
space is allocated once per run (or per call of a Python-facing entry).
"""

# The names below the imports only stand in for the generated module's: the
# system's dynamics, the layout's constants (equilibrist.sim.layout) and the
# controller's compiled functions (equilibrist.control.controller).
# mypy: ignore-errors
# ruff: noqa: F405
import math

import numpy as np
from numba import njit, prange

from equilibrist.sim.layout import *  # noqa: F403

N_STATES = 1
N_INPUTS = 1


def f(x, u, p, out):
    """Placeholder of the system's generated dynamics."""
    raise NotImplementedError


# Placeholders of the generated module's copy of equilibrist.numeric.libm.
from equilibrist.numeric.libm import eq_cos, eq_kcos, eq_ksin, eq_log, eq_rem_pio2, eq_sin  # noqa: E402


def controller_output(t, z, y, r, params, u_out):
    """Placeholder of the controller's compiled ``output``."""
    raise NotImplementedError


def controller_update(t, z, y, r, u_applied, params, z_out):
    """Placeholder of the controller's compiled ``update``."""
    raise NotImplementedError


def controller_estimate(t, z, y, r, params, x_out):
    """Placeholder of the controller's compiled ``estimate``."""
    raise NotImplementedError


# ---8<--- kernel body: everything below is copied into each system's kernel

# error_model="numpy": a division by zero gives inf or nan (caught as a
# state that is no longer finite) instead of raising, and the loops run
# without the checks. The loops themselves are compiled without numba's
# reference counting (_nrt=False): every array they touch is allocated by
# the entry that calls them, and helpers called per step or per sample are
# inlined. With reference counting the same loop runs four times slower
# (each array handed to an inlined helper costs atomic increments).
_jit = njit(cache=True, error_model="numpy")
_bare = njit(cache=True, error_model="numpy", _nrt=False)  # type: ignore[call-overload]  # private numba option
_inline = njit(cache=True, error_model="numpy", inline="always")
# The generated module defines the project's own sin, cos and log (copied from
# equilibrist.numeric.libm) as plain Python; compiled here, the dynamics and
# the noise call no C library function whose bits depend on the CPU (glibc
# picks sin, cos, log by the CPU's features). numba compiles without
# fastmath, so LLVM neither contracts a*b+c into a fused multiply-add nor
# reorders a sum: the bits are those of the source's operations.
eq_ksin = _bare(eq_ksin)
eq_kcos = _bare(eq_kcos)
eq_rem_pio2 = _bare(eq_rem_pio2)
eq_sin = _bare(eq_sin)
eq_cos = _bare(eq_cos)
eq_log = _bare(eq_log)
_fjit = _bare(f)
_N = N_STATES
_M = N_INPUTS

_U7 = np.uint64(7)
_U9 = np.uint64(9)
_U5 = np.uint64(5)
_U11 = np.uint64(11)
_U17 = np.uint64(17)
_U45 = np.uint64(45)
_U64 = np.uint64(64)
_TWO_M53 = 1.0 / 9007199254740992.0

# Dormand-Prince 5(4) tableau.
_A21 = 1.0 / 5.0
_A31, _A32 = 3.0 / 40.0, 9.0 / 40.0
_A41, _A42, _A43 = 44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0
_A51, _A52, _A53, _A54 = 19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0
_A61, _A62, _A63 = 9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0
_A64, _A65 = 49.0 / 176.0, -5103.0 / 18656.0
_B1, _B3, _B4 = 35.0 / 384.0, 500.0 / 1113.0, 125.0 / 192.0
_B5, _B6 = -2187.0 / 6784.0, 11.0 / 84.0
_E1, _E3, _E4 = 71.0 / 57600.0, -71.0 / 16695.0, 71.0 / 1920.0
_E5, _E6, _E7 = -17253.0 / 339200.0, 22.0 / 525.0, -1.0 / 40.0
_DOPRI_MAX_STEPS = 100000


@_inline
def _rotl(v, k):
    return (v << k) | (v >> (_U64 - k))


@_inline
def _next_u64(s):
    result = _rotl(s[1] * _U5, _U7) * _U9
    t = s[1] << _U17
    s[2] ^= s[0]
    s[3] ^= s[1]
    s[1] ^= s[2]
    s[0] ^= s[3]
    s[2] ^= t
    s[3] = _rotl(s[3], _U45)
    return result


@_inline
def _uniform(s):
    """A uniform deviate in (0, 1]."""
    return (float(_next_u64(s) >> _U11) + 1.0) * _TWO_M53


@_inline
def _normals(s, out, count):
    """Fill ``out[:count]`` with standard normal deviates (Marsaglia's polar method:
    pairs from points uniform in the unit disc; no sine or cosine)."""
    i = 0
    while i < count:
        v1 = 2.0 * _uniform(s) - 1.0
        v2 = 2.0 * _uniform(s) - 1.0
        r2 = v1 * v1 + v2 * v2
        if r2 >= 1.0 or r2 == 0.0:
            continue
        scale = math.sqrt(-2.0 * eq_log(r2) / r2)  # sqrt is IEEE's, correctly rounded
        out[i] = v1 * scale
        if i + 1 < count:
            out[i + 1] = v2 * scale
        i += 2


@_inline
def _deriv(x, u, p, w, out):
    _fjit(x, u, p, out)
    for i in range(_N):
        out[i] += w[i]


@_bare
def _dopri(x, u, p, w, h, rtol, atol, wk):
    """Integrate over ``[0, h]`` with adaptive Dormand-Prince steps; False if it gives up."""
    n = _N
    k1 = wk[0]
    k2 = wk[1]
    k3 = wk[2]
    k4 = wk[3]
    k5 = wk[4]
    k6 = wk[5]
    k7 = wk[6]
    yt = wk[7]
    yn = wk[8]
    hstate = wk[12]
    t = 0.0
    dt = min(hstate[0], h)
    _deriv(x, u, p, w, k1)
    steps = 0
    while t < h:
        steps += 1
        if steps > _DOPRI_MAX_STEPS:
            return False
        last = False
        if t + dt >= h * (1.0 - 1e-12):
            dt = h - t
            last = True
        for i in range(n):
            yt[i] = x[i] + dt * _A21 * k1[i]
        _deriv(yt, u, p, w, k2)
        for i in range(n):
            yt[i] = x[i] + dt * (_A31 * k1[i] + _A32 * k2[i])
        _deriv(yt, u, p, w, k3)
        for i in range(n):
            yt[i] = x[i] + dt * (_A41 * k1[i] + _A42 * k2[i] + _A43 * k3[i])
        _deriv(yt, u, p, w, k4)
        for i in range(n):
            yt[i] = x[i] + dt * (_A51 * k1[i] + _A52 * k2[i] + _A53 * k3[i] + _A54 * k4[i])
        _deriv(yt, u, p, w, k5)
        for i in range(n):
            yt[i] = x[i] + dt * (
                _A61 * k1[i] + _A62 * k2[i] + _A63 * k3[i] + _A64 * k4[i] + _A65 * k5[i]
            )
        _deriv(yt, u, p, w, k6)
        for i in range(n):
            yn[i] = x[i] + dt * (
                _B1 * k1[i] + _B3 * k3[i] + _B4 * k4[i] + _B5 * k5[i] + _B6 * k6[i]
            )
        _deriv(yn, u, p, w, k7)
        err = 0.0
        for i in range(n):
            e = dt * (
                _E1 * k1[i] + _E3 * k3[i] + _E4 * k4[i] + _E5 * k5[i] + _E6 * k6[i]
                + _E7 * k7[i]
            )
            sc = atol + rtol * max(abs(x[i]), abs(yn[i]))
            err += (e / sc) ** 2
        err = math.sqrt(err / n)
        if not math.isfinite(err):
            dt *= 0.2
            if dt < h * 1e-14:
                return False
            continue
        if err <= 1.0:
            t = h if last else t + dt
            for i in range(n):
                x[i] = yn[i]
                k1[i] = k7[i]
            fac = 5.0 if err == 0.0 else min(5.0, max(0.2, 0.9 * err ** -0.2))
            if not last:
                hstate[0] = dt * fac
            dt = dt * fac
        else:
            dt *= max(0.2, 0.9 * err ** -0.2)
            if dt < h * 1e-14:
                return False
    return True


@_inline
def _linear(x, u, op, w, lin_s, ps, dx):
    """Exact step of the affine model ``dx' = A dx + B du + f0 + w`` (held ``u``, ``w``).

    ``lin_s[ps]`` is ``[Phi | E | Gamma | f0]`` of the physics step:
    ``Phi = e^(A h)``, ``E = int_0^h e^(A s) ds``, ``Gamma = E B``.
    """
    n = _N
    m = _M
    for i in range(n):
        dx[i] = x[i] - op[i]
    for i in range(n):
        v = 0.0
        for j in range(n):
            v += lin_s[ps, i, j] * dx[j] + lin_s[ps, i, n + j] * (lin_s[ps, j, 2 * n + m] + w[j])
        for j in range(m):
            v += lin_s[ps, i, 2 * n + j] * (u[j] - op[n + j])
        x[i] = op[i] + v


@_inline
def _outside(x, region):
    """-1 inside; the index of the first state outside its region; -2 if not finite."""
    for i in range(_N):
        if not math.isfinite(x[i]):
            return -2
    for i in range(_N):
        if x[i] <= region[0, i] or x[i] >= region[1, i]:
            return i
    return -1


@_inline
def _pset(p_switch, s):
    """Index of the parameter set in force during physics step *s*."""
    j = p_switch.shape[0] - 1
    while j > 0 and p_switch[j] > s:
        j -= 1
    return j


@_inline
def _switch(p_sets, p_switch, s, pcur):
    """Copy the parameter set that starts at physics step *s* (if one does) into *pcur*."""
    for j in range(1, p_switch.shape[0]):
        if p_switch[j] == s:
            for i in range(pcur.shape[0]):
                pcur[i] = p_sets[j, i]


@_inline
def _measure(x, c_idx, lv, rng, y, zbuf):
    ny = c_idx.shape[0]
    for j in range(ny):
        y[j] = x[c_idx[j]]
    if lv.shape[0] > 0:
        _normals(rng, zbuf, ny)
        for j in range(ny):
            v = 0.0
            for k in range(ny):
                v += lv[j, k] * zbuf[k]
            y[j] += v


@_inline
def _advance(
    k, x, u_app, op, p_sets, p_switch, lin_s, region, kicks, kick_value, pulses, pulse_value,
    lw, rng, iopts, fopts, status, pcur, k1, k2, k3, k4, xt, ubuf, wvec, zbuf, xprev, fell_x, wk,
    stop,
):
    """The physics steps between samples *k* and *k + 1*; True when the run fell or was stopped.

    *pcur* holds the parameter set in force; *wk* is the adaptive
    integrator's scratch (its row 12 carries the step size from one physics
    step to the next within the sample). *stop* is read every 4096 steps.
    """
    n = _N
    m = _M
    nw = lw.shape[1]
    n_sub = iopts[_IO_N_SUB]
    integrator = iopts[_IO_INTEGRATOR]
    h = fopts[_FO_H]
    ok = True
    # The adaptive step restarts at h each sample (the held input jumps there),
    # so a run cut into pieces, or driven from Python, takes the same steps.
    wk[12, 0] = h
    for j in range(n_sub):
        s = k * n_sub + j
        if (j & 4095) == 4095 and stop[0] != 0:
            return True
        _switch(p_sets, p_switch, s, pcur)
        for e in range(kicks.shape[0]):
            if kicks[e, 0] == s:
                x[kicks[e, 1]] += kick_value[e]
        for i in range(m):
            ubuf[i] = u_app[i]
        for e in range(pulses.shape[0]):
            if pulses[e, 0] <= s < pulses[e, 1]:
                ubuf[pulses[e, 2]] += pulse_value[e]
        if nw > 0:
            _normals(rng, zbuf, nw)
            for i in range(n):
                v = 0.0
                for c in range(nw):
                    v += lw[i, c] * zbuf[c]
                wvec[i] = v
        for i in range(n):
            xprev[i] = x[i]
        if integrator == _INT_RK4:
            _rk4_step(x, ubuf, pcur, wvec, nw, h, k1, k2, k3, k4, xt)
        elif integrator == _INT_ADAPTIVE:
            ok = _dopri(x, ubuf, pcur, wvec, h, fopts[_FO_RTOL], fopts[_FO_ATOL], wk)
        else:
            _linear(x, ubuf, op, wvec, lin_s, _pset(p_switch, s), xt)
        code = _outside(x, region)
        if not ok:
            code = -3
        if code != -1:
            status[_ST_FELL] = 1
            status[_ST_FELL_CODE] = code
            status[_ST_FELL_STEP] = s + 1
            finite = code >= 0
            for i in range(n):
                fell_x[i] = x[i] if finite else xprev[i]
            return True
    return False


@_inline
def _scratch(p_len, ny, nw, nz):
    return np.zeros((_SCR_ROWS, max(_N, _M, p_len, ny + 2, nw + 2, nz, 1)))


@_bare
def _run(
    k_start, k_end, iopts, fopts, x, z, u_prev, rng,
    op, c_idx, cp, ref, uff, lv, lw,
    p_sets, p_switch, lin_s, region, kicks, kick_value, pulses, pulse_value,
    rec_cols, acc_cols, rec, acc, status, scr, stop,
):
    """Samples ``k_start .. k_end - 1`` of one closed-loop run (resumable).

    *x*, *z* (the controller's state), *u_prev* (the last saturated
    command), *rng*, *acc* and *status* carry the run from one call to the
    next. ``op = [x_op, u_op]``; *cp* the controller's parameters; *ref* and
    *uff* the references and the open-loop input added to the command, one
    row per sample. *scr* is zeroed scratch from ``_scratch``; its row
    ``_S_FELL_X`` receives the state at a fall.

    At each sample: measure, ``controller_output`` (plus *uff*), saturate
    with the limits of the parameter set in force (and delay), record and
    accumulate (each only if asked), then ``controller_update`` with the
    input that acts. A non-zero ``stop[0]`` ends the call at the next
    sample (or within 4096 physics steps); the run is then unfinished.
    """
    n = _N
    m = _M
    n_samples = iopts[_IO_N_SAMPLES]
    record = iopts[_IO_RECORD] != 0
    accumulate = iopts[_IO_ACCUMULATE] != 0
    delay = iopts[_IO_DELAY] != 0
    n_sub = iopts[_IO_N_SUB]
    has_estimate = iopts[_IO_ESTIMATES] != 0
    # The estimate is computed only where it is recorded or accumulated.
    estimates = has_estimate and (record or accumulate)
    rate = fopts[_FO_RATE]
    ny = c_idx.shape[0]
    nz = z.shape[0]
    y = scr[_S_Y, :ny]
    xhat = scr[_S_X_HAT, :n]
    u_cmd = scr[_S_U_CMD, :m]
    u_sat = scr[_S_U_SAT, :m]
    u_app = scr[_S_U_APP, :m]
    znew = scr[_S_Z_NEW, :nz]
    k1 = scr[_S_K1]
    k2 = scr[_S_K2]
    k3 = scr[_S_K3]
    k4 = scr[_S_K4]
    xt = scr[_S_XT]
    xprev = scr[_S_XPREV]
    ubuf = scr[_S_UBUF]
    wvec = scr[_S_WVEC]
    zbuf = scr[_S_ZBUF]
    pcur = scr[_S_PCUR]
    fell_x = scr[_S_FELL_X]
    wk = scr[_S_WK:_SCR_ROWS]
    ps0 = _pset(p_switch, k_start * n_sub)
    for i in range(p_sets.shape[1]):
        pcur[i] = p_sets[ps0, i]
    base = p_sets.shape[1] - 2 * m
    c_x = rec_cols[_REC_X]
    c_xhat = rec_cols[_REC_X_HAT]
    c_y = rec_cols[_REC_Y]
    c_cmd = rec_cols[_REC_U_CMD]
    c_sat = rec_cols[_REC_U_SAT]
    c_app = rec_cols[_REC_U_APP]
    a_peak = acc_cols[_ACC_PEAK_U]
    a_u2 = acc_cols[_ACC_SUM_U2]
    a_sat = acc_cols[_ACC_N_SAT]
    a_dx = acc_cols[_ACC_PEAK_DX]
    a_est = acc_cols[_ACC_SUM_EST2]
    a_peak_app = acc_cols[_ACC_PEAK_U_APP]
    for k in range(k_start, k_end):
        if stop[0] != 0:
            return
        _switch(p_sets, p_switch, k * n_sub, pcur)
        if k == 0:
            for i in range(m):
                u_prev[i] = min(max(op[n + i], pcur[base + 2 * i]), pcur[base + 2 * i + 1])
        _measure(x, c_idx, lv, rng, y, zbuf)
        t = k / rate
        r = ref[k]
        controller_output(t, z, y, r, cp, u_cmd)
        if estimates:
            controller_estimate(t, z, y, r, cp, xhat)
        saturated = False
        for i in range(m):
            u_cmd[i] = u_cmd[i] + uff[k, i]
            u_sat[i] = min(max(u_cmd[i], pcur[base + 2 * i]), pcur[base + 2 * i + 1])
            if u_sat[i] != u_cmd[i]:
                saturated = True
            u_app[i] = u_prev[i] if delay else u_sat[i]
            u_prev[i] = u_sat[i]
        if record:
            for i in range(n):
                rec[k, c_x + i] = x[i]
                rec[k, c_xhat + i] = xhat[i] if estimates else np.nan
            for j in range(ny):
                rec[k, c_y + j] = y[j]
            for i in range(m):
                rec[k, c_cmd + i] = u_cmd[i]
                rec[k, c_sat + i] = u_sat[i]
                rec[k, c_app + i] = u_app[i]
        if accumulate:
            for i in range(m):
                acc[a_peak + i] = max(acc[a_peak + i], abs(u_cmd[i]))
                acc[a_peak_app + i] = max(acc[a_peak_app + i], abs(u_app[i]))
                acc[a_u2 + i] += u_app[i] * u_app[i]
            if saturated:
                acc[a_sat] += 1.0
            for i in range(n):
                acc[a_dx + i] = max(acc[a_dx + i], abs(x[i] - op[i]))
                if estimates:
                    e = xhat[i] - x[i]
                    acc[a_est + i] += e * e
        status[_ST_ROWS] = k + 1
        if nz > 0:
            controller_update(t, z, y, r, u_app, cp, znew)
            for i in range(nz):
                z[i] = znew[i]
        if k == 0:
            code = _outside(x, region)
            if code != -1:
                status[_ST_FELL] = 1
                status[_ST_FELL_CODE] = code
                status[_ST_FELL_STEP] = 0
                for i in range(n):
                    fell_x[i] = x[i]
                return
        if k >= n_samples:
            return
        if _advance(
            k, x, u_app, op, p_sets, p_switch, lin_s, region, kicks, kick_value, pulses,
            pulse_value, lw, rng, iopts, fopts, status, pcur, k1, k2, k3, k4, xt, ubuf, wvec,
            zbuf, xprev, fell_x, wk, stop,
        ):
            return


# Never set: the stop flag of the entries that are not stopped (advance_one).
_NO_STOP = np.zeros(1, dtype=np.int64)


@njit(cache=True, error_model="numpy", nogil=True)
def run_one(
    k_start, k_end, iopts, fopts, x, z, u_prev, rng,
    op, c_idx, cp, ref, uff, lv, lw,
    p_sets, p_switch, lin_s, region, kicks, kick_value, pulses, pulse_value,
    rec_cols, acc_cols, rec, acc, status, fell_x, stop,
):
    """One run (or a resumable piece of one): see ``_run``; *fell_x* gets the state at a fall."""
    scr = _scratch(p_sets.shape[1], c_idx.shape[0], lw.shape[1], z.shape[0])
    _run(
        k_start, k_end, iopts, fopts, x, z, u_prev, rng,
        op, c_idx, cp, ref, uff, lv, lw,
        p_sets, p_switch, lin_s, region, kicks, kick_value, pulses, pulse_value,
        rec_cols, acc_cols, rec, acc, status, scr, stop,
    )
    for i in range(_N):
        fell_x[i] = scr[_S_FELL_X, i]


@njit(cache=True, error_model="numpy", parallel=True, nogil=True)
def run_many(
    iopts, fopts, x0s, z0, rngs,
    op, c_idx, cp, ref, uff, lv, lw,
    p_sets_r, p_switch, lin_r, region, kicks, kick_value, pulses, pulse_value,
    rec_cols, acc_cols, recs, accs, statuses, fell_xs, x_ends, stop,
):
    """Independent runs over the leading axis of the per-run arrays, in parallel (each
    stops at a non-zero ``stop[0]``)."""
    n_runs = x0s.shape[0]
    n_rows = iopts[_IO_N_SAMPLES] + 1
    for r in prange(n_runs):
        x = x0s[r].copy()
        z = z0.copy()
        u_prev = np.zeros(_M)
        rng = rngs[r].copy()
        scr = _scratch(p_sets_r.shape[2], c_idx.shape[0], lw.shape[1], z0.shape[0])
        _run(
            0, n_rows, iopts, fopts, x, z, u_prev, rng,
            op, c_idx, cp, ref, uff, lv, lw,
            p_sets_r[r], p_switch, lin_r[r], region, kicks, kick_value, pulses, pulse_value,
            rec_cols, acc_cols, recs[r], accs[r], statuses[r], scr, stop,
        )
        for i in range(_N):
            x_ends[r, i] = x[i]
            fell_xs[r, i] = scr[_S_FELL_X, i]


@_jit
def measure_one(x, c_idx, lv, rng, y):
    """Measured outputs of *x* with noise (the Python-controller path)."""
    zbuf = np.empty(c_idx.shape[0] + 2)
    _measure(x, c_idx, lv, rng, y, zbuf)


@_bare
def _advance_bare(
    k, x, u_app, op, p_sets, p_switch, lin_s, region,
    kicks, kick_value, pulses, pulse_value, lw, rng, iopts, fopts, status, scr,
):
    k1 = scr[_S_K1]
    k2 = scr[_S_K2]
    k3 = scr[_S_K3]
    k4 = scr[_S_K4]
    xt = scr[_S_XT]
    xprev = scr[_S_XPREV]
    ubuf = scr[_S_UBUF]
    wvec = scr[_S_WVEC]
    zbuf = scr[_S_ZBUF]
    pcur = scr[_S_PCUR]
    fell_x = scr[_S_FELL_X]
    wk = scr[_S_WK:_SCR_ROWS]
    ps = _pset(p_switch, k * iopts[_IO_N_SUB])
    for i in range(p_sets.shape[1]):
        pcur[i] = p_sets[ps, i]
    return _advance(
        k, x, u_app, op, p_sets, p_switch, lin_s, region, kicks, kick_value, pulses,
        pulse_value, lw, rng, iopts, fopts, status, pcur, k1, k2, k3, k4, xt, ubuf, wvec,
        zbuf, xprev, fell_x, wk, _NO_STOP,
    )


@_jit
def scratch(p_len, ny, nw):
    """Scratch for ``advance_one`` (its row ``_S_FELL_X`` receives the state at a fall)."""
    scr = _scratch(p_len, ny, nw, 0)
    return scr


@_jit
def advance_one(
    k, x, u_app, op, p_sets, p_switch, lin_s, region,
    kicks, kick_value, pulses, pulse_value, lw, rng, iopts, fopts, status, scr,
):
    """The physics steps after sample *k* (the Python-controller path); True if it fell.

    *scr* comes from ``scratch`` and is kept for the whole run.
    """
    return _advance_bare(
        k, x, u_app, op, p_sets, p_switch, lin_s, region,
        kicks, kick_value, pulses, pulse_value, lw, rng, iopts, fopts, status, scr,
    )


@_jit
def rk4_steps(x, u, p, h, n_steps):
    """*n_steps* RK4 steps of length *h* from *x* (in place) with *u* held."""
    w = np.zeros(_N)
    k1 = np.empty(_N)
    k2 = np.empty(_N)
    k3 = np.empty(_N)
    k4 = np.empty(_N)
    xt = np.empty(_N)
    for _ in range(n_steps):
        _rk4(x, u, p, w, h, k1, k2, k3, k4, xt)


@_jit
def normals(rng, out):
    """Standard normal deviates from the core's generator (for tests)."""
    _normals(rng, out, out.shape[0])
