"""Closed loops stepped from Python on a core: the plant around a Python controller, and
the environments' copies (:mod:`equilibrist.sim.simcore` builds the cores)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from equilibrist.sim import integrators, layout

if TYPE_CHECKING:
    from equilibrist.sim.simcore import NativeCore


class PlantSteps:
    """The plant of a closed loop whose controller runs in Python, one sample at a time.

    The same two halves of a sample as ``simulate`` with a Python controller
    (:func:`equilibrist.sim.run.simulate`): :meth:`measure` reads the
    sensors with their noise (``y = x[outputs] + lv z``), :meth:`advance`
    holds the applied input over the period's *n_sub* steps of *integrator*
    (a name of :mod:`equilibrist.sim.integrators`' table), each with
    its process noise ``lw z`` (``lw``: ``n x nw``, the noise gain over the
    root of the step), drawn from the generator state *rng* in the same
    order. Same seed, same inputs: the same bits as ``simulate``. *x*, *p*
    and *rng* are the caller's arrays (updated in place, kept by reference);
    the arrays' addresses are taken once, a call costs one ctypes call.
    """

    def __init__(self, core: NativeCore, *, x: np.ndarray, p: np.ndarray, rate: float,
                 n_sub: int, lw: np.ndarray, outputs: np.ndarray, lv: np.ndarray,
                 rng: np.ndarray, integrator: str = integrators.DEFAULT) -> None:
        n, m = core.system.n_states, core.system.n_inputs
        core._out(x, np.float64, "x")
        core._out(rng, np.uint64, "rng")
        h = 1.0 / (rate * n_sub)
        self.core = core
        self.x, self.rng = x, rng
        self.status = np.zeros(len(layout.STATUS), dtype=np.int64)
        p_sets = np.concatenate([np.asarray(p, dtype=float), np.zeros(2 * m)])[None, :]
        self.lw = np.ascontiguousarray(lw, dtype=float).reshape(n, -1)
        self.c_idx = np.ascontiguousarray(outputs, dtype=np.int64)
        self.lv = np.ascontiguousarray(lv, dtype=float)
        self.y = np.zeros(len(self.c_idx))
        self.u = np.zeros(m)
        region = np.array([[-np.inf] * n, [np.inf] * n])
        self._advance = core.advancer(
            x=x, u_app=self.u, op=np.zeros(n + m), p_sets=p_sets,
            p_switch=np.zeros(1, dtype=np.int64), lin_s=None, region=region,
            kicks=np.zeros((0, 2), dtype=np.int64), kick_value=np.zeros(0),
            pulses=np.zeros((0, 3), dtype=np.int64), pulse_value=np.zeros(0), lw=self.lw,
            rng=rng,
            iopts=layout.IOPTS.pack(int, n_samples=0, record=0, delay=0, n_sub=int(n_sub),
                                    integrator=integrators.number(integrator), estimates=0,
                                    accumulate=0),
            fopts=layout.FOPTS.pack(h=h, rtol=integrators.RTOL, atol=integrators.ATOL,
                                    rate=float(rate)),
            status=self.status, scr=core.scratch(p_sets.shape[1], 0, self.lw.shape[1]))
        self._measure = core.measurer(x=x, c_idx=self.c_idx, lv=self.lv, rng=rng, y=self.y)

    def measure(self) -> np.ndarray:
        """The sensors now, with their noise (a new array)."""
        self._measure()
        return self.y.copy()

    def advance(self, k: int, u_app: np.ndarray) -> None:
        """The period after sample *k* with *u_app* held (x updated in place)."""
        self.u[:] = u_app
        self._advance(k)


class EnvSteps:
    """The environments' compiled steps bound to one environment's arrays.

    The pointers of the environment's rows (*fs*, *us*) and settings (*cf*,
    *ci*) are taken once; an action is copied into :attr:`a`, and the step
    writes :attr:`obs`, :attr:`rewards` and :attr:`flags` (terminated, then
    truncated), which the caller copies out (a call through ctypes costs
    about a microsecond, taking an array's address as much again).
    """

    def __init__(self, core: NativeCore, fs: np.ndarray, us: np.ndarray, cf: np.ndarray,
                 ci: np.ndarray, n_obs: int) -> None:
        for arr, dtype, what in ((fs, np.float64, "fs"), (us, np.uint64, "us"),
                                 (cf, np.float64, "cf"), (ci, np.int64, "ci")):
            core._out(arr, dtype, what)
        self.core = core
        self.fs, self.us, self.cf, self.ci = fs, us, cf, ci
        copies = fs.shape[0]
        self.copies = copies
        self.n_obs = n_obs
        self.a = np.zeros((copies, core.system.n_inputs))
        self.obs = np.zeros((copies, n_obs))
        self.rewards = np.zeros(copies)
        self.flags = np.zeros((2, copies), dtype=np.bool_)
        self.status = np.zeros(1, dtype=np.int64)
        self._p = [int(arr.ctypes.data) for arr in (self.a, fs, us, self.obs, self.rewards,
                                                     self.flags, cf, ci, self.status)]
        self._many = core.lib.eq_env_step_many
        self._one = core.lib.eq_env_step_one

    def step_many(self, chunks: int) -> int:
        """Every copy, action :attr:`a`, in *chunks* parallel blocks: the count of actions
        that are not finite numbers (then nothing is done)."""
        a, fs, us, obs, rewards, flags, cf, ci, _st = self._p
        bad = self._many(a, fs, us, obs, self.n_obs, rewards, flags, self.copies, cf, ci, chunks)
        if bad < 0:
            raise MemoryError("the environments' step ran out of memory")
        return int(bad)

    def step_one(self) -> tuple[float, int]:
        """Row 0 with action ``a[0]``: ``(reward, status)``, observation in ``obs[0]``."""
        a, fs, us, obs, _r, _f, cf, ci, st = self._p
        reward = self._one(a, fs, us, obs, cf, ci, st)
        return reward, int(self.status[0])

    def begin_one(self) -> np.ndarray:
        """Row 0's episode started from its row: its first observation (a new array)."""
        _a, fs, us, obs, _r, _f, cf, ci, _st = self._p
        self.core.lib.eq_env_begin_one(fs, us, obs, cf, ci)
        first: np.ndarray = self.obs[0].copy()
        return first

    def reset_rows(self, rows: np.ndarray) -> None:
        """The copies *rows* (indices) drawn from their own generators and started now, each
        observed into its row of :attr:`obs` (the others untouched): a trainer's
        same-step reset of the copies whose episode just ended."""
        _a, fs, us, obs, _r, _f, cf, ci, _st = self._p
        fw, uw, ow = self.fs.strides[0], self.us.strides[0], self.obs.strides[0]
        reset = self.core.lib.eq_env_reset_many
        for r in rows.tolist():
            reset(fs + r * fw, us + r * uw, obs + r * ow, self.n_obs, 1, cf, ci)

    def reset_many(self) -> np.ndarray:
        """Every copy drawn and started: the first observations (a new array)."""
        _a, fs, us, obs, _r, _f, cf, ci, _st = self._p
        self.core.lib.eq_env_reset_many(fs, us, obs, self.n_obs, self.copies, cf, ci)
        return self.obs.copy()


__all__ = ["EnvSteps", "PlantSteps"]
