"""Template of the environments' compiled steps (numba).

This file is not imported by equilibrist. :mod:`equilibrist.sim.kernel`
appends everything below the marker line to the simulation core's body
(``_kernel_template.py``), in the same generated module per system, so
these steps call the core's RK4 step, generator and region check (the
names this file uses without defining them are that body's).
"""

# mypy: ignore-errors
# ruff: noqa: F405
import math

import numpy as np
from numba import prange

from equilibrist.numeric.libm import eq_cos  # stands in for the core's compiled one
from equilibrist.sim.layout import *  # noqa: F403

# ---8<--- kernel body: everything below is appended to the simulation core's body

# --- environments ---
# The compiled steps of the Gymnasium environments (equilibrist.envs). This
# section uses the core's RK4 step and generator, so that a control period
# of an environment is, number for number, a sample of ``simulate`` with a
# Python controller: zero-order hold of the saturated input, RK4 physics
# steps with process noise held over each, the region checked after each
# physics step, the sensors read with noise at the next sample.
#
# Every entry takes the same few arrays (a call from Python costs about a
# tenth of a microsecond per array argument, more than stepping a copy):
#   fs (copies, n + n_p + 2) float64: per copy [x | p | energy upright, energy hanging]
#   us (copies, 6) uint64: per copy [xoshiro256** words (4) | periods taken | autoreset due]
#   cf float64 and ci int64: the settings, written by ``equilibrist.envs._core``
#     (the only Python code that knows the slots below); ci's head holds the
#     sizes and the offsets of cf's blocks and of ci's own index blocks.
# ``status`` of a copy's step: 0 running, 1 fell (terminated), 2 out of time
# (truncated).

_CI_N_SUB = 0
_CI_N_SAMPLES = 1
_CI_OBSERVE_STATE = 2
_CI_REWARD = 3
_CI_PHYSICAL = 4
_CI_CHUNKS = 5
_CI_AUTORESET = 6
_CI_NY = 7
_CI_NW = 8
_CI_NLV = 9
_CI_NHANG = 10
_CI_NRND = 11
_CI_NP = 12
_CI_O_C_IDX = 13
_CI_O_HANG = 14
_CI_O_RND_IDX = 15
_CI_O_REGION = 16
_CI_O_OP = 17
_CI_O_ISCALE = 18
_CI_O_START = 19
_CI_O_SPREAD = 20
_CI_O_P_NOM = 21
_CI_O_RND_SPREAD = 22
_CI_O_LV = 23
_CI_O_LW = 24
_CF_H = 0
_CF_DT = 1
_CF_BONUS = 2
_US_K = 4
_US_AUTO = 5
_U0 = np.uint64(0)
_U1 = np.uint64(1)

_ENV_SCR = 9  # scratch rows: u, w, zbuf, k1, k2, k3, k4, xt, xprev
# A parallel step gives each block of copies its scratch rows, this many
# doubles apart at least (two cache lines of 64 bytes, the span the
# adjacent-line prefetcher fetches): scratch written by two threads in one
# cache line would bounce the line between the cores at every RK4 stage.
_ENV_GAP = 16
_env_energy = _bare(energy)


@_inline
def _env_width(fs, ci):
    return max(_N, _M, ci[_CI_NY], ci[_CI_NW]) + 2


# The settings a copy's step reads, taken from ``ci`` and ``cf`` once per call
# (``_env_settings``) rather than once per copy: the compiler can not keep
# them in registers across the copies' stores, which might alias them, and
# a block of ``cf`` indexed through an offset read from ``ci`` pays a
# negative-index check at every access; a view of the block does not.
# Indices into the tuple:
_S_N_SUB = 0
_S_N_SAMPLES = 1
_S_OBSERVE_STATE = 2
_S_REWARD = 3
_S_PHYSICAL = 4
_S_AUTORESET = 5
_S_NY = 6
_S_NW = 7
_S_NLV = 8
_S_NP = 9
_S_H = 10
_S_DT = 11
_S_BONUS = 12
_S_REGION = 13  # the region: lower bounds, upper bounds (2 x n, a view of cf)
_S_OP = 14  # operating point: state then input
_S_ISCALE = 15  # 1 / scales: state then input
_S_C_IDX = 16  # the measured states (a view of ci)
_S_HANG = 17  # the swing-up's hanging coordinates (a view of ci)
_S_LV = 18  # sensor noise's square root, ny x ny, row-major (a view of cf)
_S_LW = 19  # process noise's gain, n x nw, row-major (a view of cf)


@_inline
def _env_settings(cf, ci):
    """The tuple of settings indexed by ``_S_*``."""
    ny = ci[_CI_NY]
    nw = ci[_CI_NW]
    nlv = ci[_CI_NLV]
    o_r = ci[_CI_O_REGION]
    o_op = ci[_CI_O_OP]
    o_s = ci[_CI_O_ISCALE]
    o_c = ci[_CI_O_C_IDX]
    o_h = ci[_CI_O_HANG]
    o_lv = ci[_CI_O_LV]
    o_lw = ci[_CI_O_LW]
    return (ci[_CI_N_SUB], ci[_CI_N_SAMPLES], ci[_CI_OBSERVE_STATE], ci[_CI_REWARD],
            ci[_CI_PHYSICAL], ci[_CI_AUTORESET], ny, nw, nlv, ci[_CI_NP],
            cf[_CF_H], cf[_CF_DT], cf[_CF_BONUS],
            cf[o_r: o_r + 2 * _N].reshape((2, _N)), cf[o_op: o_op + _N + _M],
            cf[o_s: o_s + _N + _M], ci[o_c: o_c + ny], ci[o_h: o_h + ci[_CI_NHANG]],
            cf[o_lv: o_lv + nlv * ny], cf[o_lw: o_lw + _N * nw])


@_inline
def _env_observe(x, rng, orow, S, zbuf):
    """*orow*: the state, or the measured outputs with sensor noise (as ``_measure``).

    The sensor noise is drawn either way, so that an environment observing
    the state follows the same run as one observing the outputs.
    """
    ny = S[_S_NY]
    nlv = S[_S_NLV]
    if nlv > 0:
        _normals(rng, zbuf, ny)
    if S[_S_OBSERVE_STATE] != 0:
        for i in range(_N):
            orow[i] = x[i]
        return
    c_idx = S[_S_C_IDX]
    lv = S[_S_LV]
    for j in range(ny):
        y = x[c_idx[j]]
        if nlv > 0:
            v = 0.0
            for c in range(ny):
                v += lv[j * ny + c] * zbuf[c]
            y += v
        orow[j] = y


@_inline
def _env_input(a, p, physical, u):
    """The saturated input of action *a* (limits from *p*, as the core saturates)."""
    base = p.shape[0] - 2 * _M
    for i in range(_M):
        lo = p[base + 2 * i]
        hi = p[base + 2 * i + 1]
        v = a[i] if physical != 0 else lo + 0.5 * (a[i] + 1.0) * (hi - lo)
        u[i] = min(max(v, lo), hi)


@_inline
def _env_physics(x, u, p, rng, S, w, zbuf, k1, k2, k3, k4, xt, xprev):
    """One control period; the region code at a fall (the last finite state kept), else -1.

    *w* is zero on entry and stays so without process noise.
    """
    nw = S[_S_NW]
    lw = S[_S_LW]
    region = S[_S_REGION]
    h = S[_S_H]
    for _s in range(S[_S_N_SUB]):
        if nw > 0:
            _normals(rng, zbuf, nw)
            for i in range(_N):
                v = 0.0
                for c in range(nw):
                    v += lw[i * nw + c] * zbuf[c]
                w[i] = v
        for i in range(_N):
            xprev[i] = x[i]
        _rk4_step(x, u, p, w, nw, h, k1, k2, k3, k4, xt)
        code = _outside(x, region)
        if code != -1:
            if code == -2:
                for i in range(_N):
                    x[i] = xprev[i]
            return code
    return -1


@_inline
def _env_reward(x, u, p, eref0, eref1, S):
    """Reward of a period ending in *x* with *u* applied (see ``equilibrist.envs``)."""
    dt = S[_S_DT]
    op = S[_S_OP]
    if S[_S_REWARD] == 0:
        isc = S[_S_ISCALE]
        c = 0.0
        for i in range(_N):
            d = (x[i] - op[i]) * isc[i]
            c += d * d
        for i in range(_M):
            d = (u[i] - op[_N + i]) * isc[_N + i]
            c += d * d
        # Never below zero: struggling must not earn less than falling at once.
        return dt * max(0.0, S[_S_BONUS] - c)
    hang = S[_S_HANG]
    nh = hang.shape[0]
    up = 0.0
    for j in range(nh):
        q = hang[j]
        up += 0.5 * (1.0 + eq_cos(x[q] - op[q]))
    if nh > 0:
        up /= nh
    gap = eref0 - eref1
    if gap == 0.0:
        gap = 1.0
    e = (_env_energy(x, p) - eref0) / gap
    return dt * 0.5 * (up + max(0.0, 1.0 - e * e))


@_inline
def _env_begin(r, fs, us, orow, cf, ci, zbuf):
    """Start copy *r*'s episode from the state and parameters in its row: the
    shaping's reference energies, the step count, the first observation."""
    n_p = ci[_CI_NP]
    p = fs[r, _N: _N + n_p]
    if ci[_CI_REWARD] == 1:
        o_op = ci[_CI_O_OP]
        o_st = ci[_CI_O_START]
        fs[r, _N + n_p] = _env_energy(cf[o_op: o_op + _N], p)
        fs[r, _N + n_p + 1] = _env_energy(cf[o_st: o_st + _N], p)
    us[r, _US_K] = _U0
    us[r, _US_AUTO] = _U0
    _env_observe(fs[r, :_N], us[r, :4], orow, _env_settings(cf, ci), zbuf)


@_inline
def _env_draw(r, fs, us, cf, ci):
    """Copy *r*'s start from the task's distribution and its randomized parameters,
    drawn from its own generator."""
    rng = us[r, :4]
    o_st = ci[_CI_O_START]
    o_sp = ci[_CI_O_SPREAD]
    for i in range(_N):
        fs[r, i] = cf[o_st + i] + (2.0 * _uniform(rng) - 1.0) * cf[o_sp + i]
    o_pn = ci[_CI_O_P_NOM]
    n_p = ci[_CI_NP]
    for i in range(n_p):
        fs[r, _N + i] = cf[o_pn + i]
    o_ri = ci[_CI_O_RND_IDX]
    o_rs = ci[_CI_O_RND_SPREAD]
    for j in range(ci[_CI_NRND]):
        q = ci[o_ri + j]
        fs[r, _N + q] = cf[o_pn + q] * (1.0 + (2.0 * _uniform(rng) - 1.0) * cf[o_rs + j])


@_inline
def _env_step_copy(r, a, fs, us, orow, cf, ci, S, u, w, zbuf, k1, k2, k3, k4, xt, xprev):
    """One control period of copy *r* with action *a*: ``(reward, status)``; *S* is
    ``_env_settings(cf, ci)``.

    A copy whose episode ended at its previous step (autoreset due) is reset
    instead: its action is ignored, its reward is 0.
    """
    if us[r, _US_AUTO] != _U0:
        _env_draw(r, fs, us, cf, ci)
        _env_begin(r, fs, us, orow, cf, ci, zbuf)
        return 0.0, 0
    n_p = S[_S_NP]
    x = fs[r, :_N]
    p = fs[r, _N: _N + n_p]
    rng = us[r, :4]
    _env_input(a, p, S[_S_PHYSICAL], u)
    code = _env_physics(x, u, p, rng, S, w, zbuf, k1, k2, k3, k4, xt, xprev)
    k = np.int64(us[r, _US_K]) + 1
    us[r, _US_K] = np.uint64(k)
    _env_observe(x, rng, orow, S, zbuf)
    reward = _env_reward(x, u, p, fs[r, _N + n_p], fs[r, _N + n_p + 1], S)
    status = 1 if code != -1 else 2 if k >= S[_S_N_SAMPLES] else 0
    if status != 0 and S[_S_AUTORESET] != 0:
        us[r, _US_AUTO] = _U1
    return reward, status


@_inline
def _env_bad_actions(actions):
    """How many actions are not finite numbers (then no copy is stepped)."""
    bad = 0
    for r in range(actions.shape[0]):
        for i in range(actions.shape[1]):
            if not math.isfinite(actions[r, i]):
                bad += 1
    return bad


@_bare
def _env_step_range(lo, hi, actions, fs, us, obs, rewards, flags, cf, ci, scr):
    """Copies ``lo .. hi - 1`` of a vector step.

    Compiled without reference counting (a reference-counted loop handing
    arrays to the dynamics runs several times slower; row views cost
    nothing here): *scr* (``_ENV_SCR`` zeroed rows) comes from the entry.
    """
    u = scr[0]
    w = scr[1]
    zbuf = scr[2]
    k1 = scr[3]
    k2 = scr[4]
    k3 = scr[5]
    k4 = scr[6]
    xt = scr[7]
    xprev = scr[8]
    S = _env_settings(cf, ci)
    for r in range(lo, hi):
        reward, status = _env_step_copy(r, actions[r], fs, us, obs[r], cf, ci, S, u, w, zbuf,
                                        k1, k2, k3, k4, xt, xprev)
        rewards[r] = reward
        flags[0, r] = status == 1
        flags[1, r] = status == 2


@_jit
def _env_scratch(blocks, width):
    """Zeroed scratch, a row per block of copies: each block's scratch rows followed
    by _ENV_GAP unused doubles (see _ENV_GAP). Made outside the parallel function,
    where ``np.zeros`` would be a parallel loop of its own, with a launch of its own."""
    return np.zeros((blocks, width))


@njit(cache=True, error_model="numpy", parallel=True)
def env_step_many(actions, fs, us, obs, rewards, flags, cf, ci):
    """One control period of every copy, in parallel (``ci``'s chunk count of
    contiguous blocks of copies); Gymnasium's next-step autoreset.

    Returns the number of actions that are not finite numbers: when there
    is one, nothing is done.
    """
    bad = _env_bad_actions(actions)
    if bad > 0:
        return bad
    n_copies = fs.shape[0]
    chunks = max(1, min(ci[_CI_CHUNKS], n_copies))
    width = _env_width(fs, ci)
    scrs = _env_scratch(chunks, _ENV_SCR * width + _ENV_GAP)
    for c in prange(chunks):
        _env_step_range(c * n_copies // chunks, (c + 1) * n_copies // chunks, actions, fs, us,
                        obs, rewards, flags, cf, ci,
                        scrs[c, :_ENV_SCR * width].reshape((_ENV_SCR, width)))
    return 0


@_jit
def env_step_serial(actions, fs, us, obs, rewards, flags, cf, ci):
    """``env_step_many`` on one thread (few copies: a parallel region costs more than it saves)."""
    bad = _env_bad_actions(actions)
    if bad > 0:
        return bad
    scr = np.zeros((_ENV_SCR, _env_width(fs, ci)))
    _env_step_range(0, fs.shape[0], actions, fs, us, obs, rewards, flags, cf, ci, scr)
    return 0


@_bare
def _env_one(a, fs, us, obs, cf, ci, scr):
    return _env_step_copy(0, a, fs, us, obs, cf, ci, _env_settings(cf, ci), scr[0], scr[1],
                          scr[2], scr[3], scr[4], scr[5], scr[6], scr[7], scr[8])


@_jit
def env_step_one(a, fs, us, obs, cf, ci):
    """One control period of the single environment in row 0: ``(reward, status)``,
    status 3 when the action is not a finite number (nothing done)."""
    for i in range(a.shape[0]):
        if not math.isfinite(a[i]):
            return 0.0, 3
    scr = np.zeros((_ENV_SCR, _env_width(fs, ci)))
    return _env_one(a, fs, us, obs, cf, ci, scr)


@_jit
def env_begin(fs, us, obs, cf, ci):
    """Start row 0's episode from the state and parameters written in it (the
    single environment's reset); *obs* receives the first observation."""
    zbuf = np.zeros(_env_width(fs, ci))
    _env_begin(0, fs, us, obs, cf, ci, zbuf)


@_bare
def _env_reset_range(lo, hi, fs, us, obs, cf, ci, zbuf):
    for r in range(lo, hi):
        _env_draw(r, fs, us, cf, ci)
        _env_begin(r, fs, us, obs[r], cf, ci, zbuf)


@_jit
def env_reset_many(fs, us, obs, cf, ci):
    """Reset every copy: draw each one's start and parameters from its own
    generator and observe it into its row of *obs*."""
    zbuf = np.zeros(_env_width(fs, ci))
    _env_reset_range(0, fs.shape[0], fs, us, obs, cf, ci, zbuf)
