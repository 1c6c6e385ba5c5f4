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
# Settings (written by ``equilibrist.envs._core.Layout``, the only Python
# code that knows these slots):
#   ei = [n_sub, n_samples, observe_state, reward_kind, action_physical, n_chunks]
#   ef = [h, dt, alive_bonus]
#   op = [x_op | u_op]; sc = [state scales | input scales] (the task's cost)
#   hang: indices of the coordinates a swing-up raises
#   rnd_idx, rnd_spread: randomized parameters and their relative spreads
# Per copy: x (state), p (parameters), k (periods taken), rng (xoshiro256**
# words), eref = [energy upright, energy hanging] (swing-up shaping).
# ``status`` of a step: 0 running, 1 fell (terminated), 2 out of time
# (truncated), 3 the action was not a finite number (nothing was done).

_ENV_SCR = 12
_env_energy = _bare(energy)


@_inline
def _env_region(x, region):
    """-1 inside; the first state outside its region; -2 if not finite (as ``simulate``)."""
    for i in range(_N):
        if not math.isfinite(x[i]):
            return -2
    for i in range(_N):
        if x[i] <= region[0, i] or x[i] >= region[1, i]:
            return i
    return -1


@_inline
def _env_observe(x, c_idx, lv, rng, observe_state, obs, r, zbuf):
    """Row *r* of *obs*: the state, or the measured outputs with sensor noise.

    The sensor noise is drawn either way, so that an environment observing
    the state follows the same run as one observing the outputs.
    """
    ny = c_idx.shape[0]
    if lv.shape[0] > 0:
        _normals(rng, zbuf, ny)
    if observe_state != 0:
        for i in range(_N):
            obs[r, i] = x[i]
        return
    for j in range(ny):
        v = 0.0
        if lv.shape[0] > 0:
            for c in range(ny):
                v += lv[j, c] * zbuf[c]
        obs[r, j] = x[c_idx[j]] + v


@_inline
def _env_input(a, p, physical, u):
    """The saturated input of action *a*; False if *a* is not finite."""
    base = p.shape[0] - 2 * _M
    for i in range(_M):
        if not math.isfinite(a[i]):
            return False
        lo = p[base + 2 * i]
        hi = p[base + 2 * i + 1]
        v = a[i] if physical != 0 else lo + 0.5 * (a[i] + 1.0) * (hi - lo)
        u[i] = min(max(v, lo), hi)
    return True


@_inline
def _env_physics(x, u, p, lw, rng, n_sub, h, region, w, zbuf, k1, k2, k3, k4, xt, xprev):
    """One control period; the region code at a fall (the last finite state kept), else -1."""
    nw = lw.shape[1]
    for i in range(_N):
        w[i] = 0.0
    for _s in range(n_sub):
        if nw > 0:
            _normals(rng, zbuf, nw)
            for i in range(_N):
                v = 0.0
                for c in range(nw):
                    v += lw[i, c] * zbuf[c]
                w[i] = v
        for i in range(_N):
            xprev[i] = x[i]
        _rk4(x, u, p, w, h, k1, k2, k3, k4, xt)
        code = _env_region(x, region)
        if code != -1:
            if code == -2:
                for i in range(_N):
                    x[i] = xprev[i]
            return code
    return -1


@_inline
def _env_reward(x, u, p, kind, ef, op, sc, hang, eref0, eref1):
    """Reward of a period ending in *x* with *u* applied (see ``equilibrist.envs``)."""
    dt = ef[1]
    if kind == 0:
        c = 0.0
        for i in range(_N):
            d = (x[i] - op[i]) / sc[i]
            c += d * d
        for i in range(_M):
            d = (u[i] - op[_N + i]) / sc[_N + i]
            c += d * d
        # Never below zero: struggling must not earn less than falling at once.
        return dt * max(0.0, ef[2] - c)
    up = 0.0
    for j in range(hang.shape[0]):
        up += 0.5 * (1.0 + math.cos(x[hang[j]] - op[hang[j]]))
    if hang.shape[0] > 0:
        up /= hang.shape[0]
    gap = eref0 - eref1
    if gap == 0.0:
        gap = 1.0
    e = (_env_energy(x, p) - eref0) / gap
    return dt * 0.5 * (up + max(0.0, 1.0 - e * e))


@_inline
def _env_draw(x, p, rng, start, spread, p_nom, rnd_idx, rnd_spread):
    """A start drawn from the task's distribution and randomized parameters."""
    for i in range(_N):
        x[i] = start[i] + (2.0 * _uniform(rng) - 1.0) * spread[i]
    for i in range(p.shape[0]):
        p[i] = p_nom[i]
    for j in range(rnd_idx.shape[0]):
        p[rnd_idx[j]] = p_nom[rnd_idx[j]] * (1.0 + (2.0 * _uniform(rng) - 1.0) * rnd_spread[j])


@_jit
def env_energy(x, p):
    """The model's energy (the swing-up's shaping reads it)."""
    return _env_energy(x, p)


@_jit
def env_observe(x, c_idx, lv, rng, observe_state, obs):
    """The observation of *x* into ``obs[0]`` (draws the sensor noise)."""
    zbuf = np.zeros(max(c_idx.shape[0], 1) + 2)
    _env_observe(x, c_idx, lv, rng, observe_state, obs, 0, zbuf)


@_jit
def env_step_one(a, x, p, rng, k, eref, obs, ei, ef, c_idx, lv, lw, region, op, sc, hang):
    """One control period of one environment: ``(reward, status)`` (see the section's notes).

    *x*, *rng* and ``k[0]`` carry the episode; ``obs[0]`` receives the observation.
    """
    scr = np.zeros((_ENV_SCR, max(_N, _M, lw.shape[1], c_idx.shape[0]) + 2))
    u = scr[0]
    if not _env_input(a, p, ei[4], u):
        return 0.0, 3
    code = _env_physics(x, u, p, lw, rng, ei[0], ef[0], region, scr[1], scr[2], scr[3],
                        scr[4], scr[5], scr[6], scr[7], scr[8])
    k[0] += 1
    _env_observe(x, c_idx, lv, rng, ei[2], obs, 0, scr[2])
    reward = _env_reward(x, u, p, ei[3], ef, op, sc, hang, eref[0], eref[1])
    if code != -1:
        return reward, 1
    if k[0] >= ei[1]:
        return reward, 2
    return reward, 0


@_inline
def _env_reset_copy(r, xs, ps, rng, ks, erefs, obs, x, p, ei, c_idx, lv, start, spread,
                    p_nom, rnd_idx, rnd_spread, op, zbuf):
    _env_draw(x, p, rng, start, spread, p_nom, rnd_idx, rnd_spread)
    for i in range(_N):
        xs[r, i] = x[i]
    for i in range(p.shape[0]):
        ps[r, i] = p[i]
    ks[r] = 0
    if ei[3] == 1:
        erefs[r, 0] = _env_energy(op, p)
        erefs[r, 1] = _env_energy(start, p)
    _env_observe(x, c_idx, lv, rng, ei[2], obs, r, zbuf)


@_inline
def _env_width(ps, lw, c_idx):
    return max(_N, _M, lw.shape[1], c_idx.shape[0], ps.shape[1]) + 2


@_bare
def _env_reset_range(lo, hi, mask, xs, ps, rngs, ks, erefs, obs, ei, c_idx, lv, start, spread,
                     p_nom, rnd_idx, rnd_spread, op, scr, rng):
    # Compiled without reference counting, like the core's loops: *scr*
    # (rows x, p, zbuf) and *rng* are made by the entry that calls it.
    x = scr[0]
    p = scr[1, : ps.shape[1]]
    zbuf = scr[2]
    for r in range(lo, hi):
        if mask[r]:
            for i in range(4):
                rng[i] = rngs[r, i]
            _env_reset_copy(r, xs, ps, rng, ks, erefs, obs, x, p, ei, c_idx, lv, start,
                            spread, p_nom, rnd_idx, rnd_spread, op, zbuf)
            for i in range(4):
                rngs[r, i] = rng[i]


@njit(cache=True, error_model="numpy", parallel=True)
def env_reset_many(mask, xs, ps, rngs, ks, erefs, obs, ei, c_idx, lv, start, spread,
                   p_nom, rnd_idx, rnd_spread, op):
    """Reset the copies where *mask* is set: draw each one's start and parameters
    from its own generator and observe it into its row of *obs*."""
    n_copies = xs.shape[0]
    chunks = max(1, min(ei[5], n_copies))
    scrs = np.zeros((chunks, 3, _env_width(ps, lv, c_idx)))
    rbuf = np.zeros((chunks, 4), dtype=np.uint64)
    for c in prange(chunks):
        _env_reset_range(c * n_copies // chunks, (c + 1) * n_copies // chunks, mask, xs, ps,
                         rngs, ks, erefs, obs, ei, c_idx, lv, start, spread, p_nom, rnd_idx,
                         rnd_spread, op, scrs[c], rbuf[c])


@_bare
def _env_step_range(lo, hi, actions, xs, ps, rngs, ks, erefs, auto, obs, rewards, terminated,
                    truncated, ei, ef, c_idx, lv, lw, region, op, sc, hang, start, spread,
                    p_nom, rnd_idx, rnd_spread, scr, rng):
    """Copies ``lo .. hi - 1`` of a vector step; the number of non-finite actions.

    Compiled without reference counting (a reference-counted loop handing
    arrays to the dynamics runs several times slower): *scr* (``_ENV_SCR``
    rows of ``_env_width``) and *rng* (4 words) come from the entry.
    """
    # Rows of the copies' arrays are used in place (views cost nothing here).
    u = scr[1]
    w = scr[2]
    zbuf = scr[3]
    k1 = scr[4]
    k2 = scr[5]
    k3 = scr[6]
    k4 = scr[7]
    xt = scr[8]
    xprev = scr[9]
    bad = 0
    for r in range(lo, hi):
        terminated[r] = False
        truncated[r] = False
        x = xs[r]
        p = ps[r]
        rng_r = rngs[r]
        if auto[r]:
            _env_reset_copy(r, xs, ps, rng_r, ks, erefs, obs, x, p, ei, c_idx, lv,
                            start, spread, p_nom, rnd_idx, rnd_spread, op, zbuf)
            rewards[r] = 0.0
            auto[r] = False
            continue
        if not _env_input(actions[r], p, ei[4], u):
            bad += 1
            continue
        code = _env_physics(x, u, p, lw, rng_r, ei[0], ef[0], region, w, zbuf,
                            k1, k2, k3, k4, xt, xprev)
        ks[r] += 1
        _env_observe(x, c_idx, lv, rng_r, ei[2], obs, r, zbuf)
        rewards[r] = _env_reward(x, u, p, ei[3], ef, op, sc, hang, erefs[r, 0], erefs[r, 1])
        if code != -1:
            terminated[r] = True
            auto[r] = True
        elif ks[r] >= ei[1]:
            truncated[r] = True
            auto[r] = True
    return bad


@njit(cache=True, error_model="numpy", parallel=True)
def env_step_many(actions, xs, ps, rngs, ks, erefs, auto, obs, rewards, terminated,
                  truncated, ei, ef, c_idx, lv, lw, region, op, sc, hang, start, spread,
                  p_nom, rnd_idx, rnd_spread):
    """One control period of every copy, in parallel; Gymnasium's next-step autoreset.

    A copy whose previous step ended (``auto``) is reset instead of stepped
    (its action ignored, reward 0); a copy that ends now is flagged in
    ``auto`` for the next call. Returns the number of copies whose action
    was not a finite number (they are left as they were).
    """
    n_copies = xs.shape[0]
    chunks = max(1, min(ei[5], n_copies))
    bad = np.zeros(chunks, dtype=np.int64)
    scrs = np.zeros((chunks, _ENV_SCR, _env_width(ps, lw, c_idx)))
    rbuf = np.zeros((chunks, 4), dtype=np.uint64)
    for c in prange(chunks):
        bad[c] = _env_step_range(
            c * n_copies // chunks, (c + 1) * n_copies // chunks, actions, xs, ps, rngs, ks,
            erefs, auto, obs, rewards, terminated, truncated, ei, ef, c_idx, lv, lw, region, op,
            sc, hang, start, spread, p_nom, rnd_idx, rnd_spread, scrs[c], rbuf[c],
        )
    total = 0
    for c in range(chunks):
        total += bad[c]
    return total


@_jit
def env_step_serial(actions, xs, ps, rngs, ks, erefs, auto, obs, rewards, terminated,
                    truncated, ei, ef, c_idx, lv, lw, region, op, sc, hang, start, spread,
                    p_nom, rnd_idx, rnd_spread):
    """``env_step_many`` on one thread (few copies: a parallel region costs more than it saves)."""
    scr = np.zeros((_ENV_SCR, _env_width(ps, lw, c_idx)))
    rng = np.zeros(4, dtype=np.uint64)
    return _env_step_range(
        0, xs.shape[0], actions, xs, ps, rngs, ks, erefs, auto, obs, rewards, terminated,
        truncated, ei, ef, c_idx, lv, lw, region, op, sc, hang, start, spread, p_nom, rnd_idx,
        rnd_spread, scr, rng,
    )
