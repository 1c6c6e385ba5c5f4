"""Closed loops stepped from Python on a core: the plant around a Python controller, and
the environments' copies (:mod:`equilibrist.sim.simcore` builds the cores)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from equilibrist.sim import integrators, layout

if TYPE_CHECKING:
    from equilibrist.sim.kernel import Kernel
    from equilibrist.sim.rig import Rig
    from equilibrist.sim.setup_data import Setup
    from equilibrist.sim.simcore import NativeCore


class PlantSteps:
    """The plant of a closed loop whose controller runs in Python, one sample at a time.

    The same three parts of a sample as ``simulate`` with a Python controller
    (:func:`equilibrist.sim.run.simulate`): :meth:`measure` reads the
    sensors with their noise (``y = x[outputs] + lv z``), :meth:`actuate` gives the
    torque that acts for a command and :meth:`advance` holds it over the period's *n_sub*
    steps of *integrator* (a name of :mod:`equilibrist.sim.integrators`' table), each with
    its process noise ``lw z`` (``lw``: ``n x nw``, the noise gain over the
    root of the step), drawn from the generator state *rng* in the same
    order. With a *rig* (:class:`~equilibrist.sim.rig.Rig`) the sensors and the
    actuator go through its effects about the operating point *op* (state, then input),
    by the core's rig functions that ``simulate``'s loops call. Same seed, same inputs: the
    same bits as ``simulate``. *x*, *p* and *rng* are the caller's arrays (updated in
    place, kept by reference); the arrays' addresses are taken once, a call costs one
    ctypes call.
    """

    def __init__(self, core: NativeCore, *, x: np.ndarray, p: np.ndarray, rate: float,
                 n_sub: int, lw: np.ndarray, outputs: np.ndarray, lv: np.ndarray,
                 rng: np.ndarray, integrator: str = integrators.DEFAULT,
                 rig: Rig | None = None, op: np.ndarray | None = None) -> None:
        system = core.system
        n, m = system.n_states, system.n_inputs
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
        self.u = np.zeros(m)  # the input held over a period
        op = np.zeros(n + m) if op is None else np.asarray(op, dtype=float)
        fopts = layout.FOPTS.pack(h=h, rtol=integrators.RTOL, atol=integrators.ATOL,
                                  rate=float(rate))
        rig_i = rig_f = None
        if rig is not None:
            rig_i, rig_f = rig.pack(system, rate, len(self.c_idx))
        self._advance = core.advancer(
            x=x, u_app=self.u, op=op, p_sets=p_sets,
            p_switch=np.zeros(1, dtype=np.int64), lin_s=None,
            region=np.array([[-np.inf] * n, [np.inf] * n]),
            kicks=np.zeros((0, 2), dtype=np.int64), kick_value=np.zeros(0),
            pulses=np.zeros((0, 3), dtype=np.int64), pulse_value=np.zeros(0), lw=self.lw,
            rng=rng,
            iopts=layout.IOPTS.pack(int, n_samples=0, record=0, delay=0, n_sub=int(n_sub),
                                    integrator=integrators.number(integrator), estimates=0,
                                    accumulate=0),
            fopts=fopts, status=self.status,
            scr=core.scratch(p_sets.shape[1], 0, self.lw.shape[1]), rig_i=rig_i)
        self._command, self._acted = np.zeros(m), np.zeros(m)
        self._lim = np.zeros(2 * m)
        self._lim[0::2], self._lim[1::2] = system.input_limits
        self.rig = rig
        if rig is not None:
            assert rig_i is not None and rig_f is not None
            self._rig_measure, self._rig_actuate = core.rig_steps(
                x=x, c_idx=self.c_idx, lv=self.lv, op=op, fopts=fopts, rig_i=rig_i,
                rig_f=rig_f, rig_s=np.zeros(rig.state_len(system, rate, len(self.c_idx))),
                rng=rng, y=self.y, u_app=self._command, u_act=self._acted, lim=self._lim)
        self._measure = core.measurer(x=x, c_idx=self.c_idx, lv=self.lv, rng=rng, y=self.y)

    def measure(self, k: int = 0) -> np.ndarray:
        """The sensors at sample *k*, with their noise and the rig's effects (a new array)."""
        if self.rig is not None:
            self._rig_measure(k)
        else:
            self._measure()
        return self.y.copy()

    def actuate(self, k: int, u_sat: np.ndarray, u_app: np.ndarray) -> np.ndarray:
        """What acts over sample *k*'s period, held for :meth:`advance` (a new array):
        *u_app*, the saturated command *u_sat* with whatever acts beside the actuator;
        through a rig, the torque that acts for *u_sat* (its delay, response, noise and the
        system's limits) with that beside it added."""
        if self.rig is not None:
            self._command[:] = u_sat
            self._rig_actuate(k)
            self.u[:] = self._acted + (np.asarray(u_app, dtype=float) - u_sat)
        else:
            self.u[:] = u_app
        return self.u.copy()

    def advance(self, k: int, u_app: np.ndarray | None = None) -> None:
        """The period after sample *k* with the input :meth:`actuate` held, or *u_app*
        (x updated in place)."""
        if u_app is not None:
            self.u[:] = u_app
        self._advance(k)


class SetupSteps:
    """The plant of a run's settings *setup* (:func:`equilibrist.sim.setup.build`), one
    sample at a time, for a loop whose decisions are made in Python: ``simulate`` around a
    :class:`~equilibrist.control.controller.PythonController`, and an environment's episode
    through a rig. A sample is :meth:`measure` (the sensors of :attr:`x` into :attr:`y`,
    through the rig's encoders, delay and filter when the settings have a rig),
    :meth:`actuate` (the torque that acts for a saturated command: through the rig's delay,
    response, noise and limits, or the command itself) and :meth:`advance` (the period's
    physics with that torque held, the rig's pushes acting). Noise is drawn from the
    generator state *rng* in ``simulate``'s order, the pushes from the seed sequence *seq*:
    the same settings, seed and commands give the same bits wherever the loop runs.
    """

    def __init__(self, setup: Setup, kernel: Kernel, rng: np.ndarray,
                 seq: np.random.SeedSequence | None) -> None:
        system = setup.system
        m = system.n_inputs
        core = kernel.generic
        self.x = setup.x0.copy()
        self.y = np.empty(len(setup.outputs))
        self.p_sets = setup.p_sets(np.array(system.p))
        self.status = np.zeros(len(layout.STATUS), dtype=np.int64)
        self.scr = kernel.scratch(p_len=self.p_sets.shape[1], ny=len(setup.outputs),
                                  nw=setup.lw.shape[1])
        self.held = np.zeros(m)  # the input held over a period, as the core reads it
        plain = core.measurer(x=self.x, c_idx=setup.c_idx, lv=setup.lv, rng=rng, y=self.y)
        rig_i, rig_f = setup.rig_arrays()
        gforce, self.pulses = setup.rig_forces(seq)
        self._advance = core.advancer(
            x=self.x, u_app=self.held, op=setup.op, p_sets=self.p_sets,
            p_switch=setup.p_switch, lin_s=setup.linear_blocks(self.p_sets),
            region=setup.region, kicks=setup.kicks, kick_value=setup.kick_value,
            pulses=setup.pulses, pulse_value=setup.pulse_value, lw=setup.lw, rng=rng,
            iopts=setup.iopts(), fopts=setup.fopts, status=self.status, scr=self.scr,
            rig_i=rig_i, gforce=gforce)
        self._command, self._acted, self._lim = np.zeros(m), np.zeros(m), np.zeros(2 * m)
        self.rig_on = rig_i is not None and bool(rig_i[layout.RIG_I["on"]])
        if self.rig_on:
            rig_state = setup.rig_state()
            assert rig_i is not None and rig_f is not None and rig_state is not None
            self._measure, self._actuate = core.rig_steps(
                x=self.x, c_idx=setup.c_idx, lv=setup.lv, op=setup.op, fopts=setup.fopts,
                rig_i=rig_i, rig_f=rig_f, rig_s=rig_state, rng=rng, y=self.y,
                u_app=self._command, u_act=self._acted, lim=self._lim)
        else:
            self._measure = lambda k: plain()

    def measure(self, k: int) -> None:
        """The sensors at sample *k* into :attr:`y`."""
        self._measure(k)

    def actuate(self, k: int, u_app: np.ndarray, low: np.ndarray, high: np.ndarray
                ) -> np.ndarray:
        """The torque that acts over sample *k*'s period for the command *u_app* (within
        the limits *low*, *high*), held for :meth:`advance` (a new array)."""
        if self.rig_on:
            self._command[:] = u_app
            self._lim[0::2], self._lim[1::2] = low, high
            self._actuate(k)
            self.held[:] = self._acted
        else:
            self.held[:] = u_app
        return self.held.copy()

    def advance(self, k: int) -> bool:
        """The period after sample *k* with the held torque: True if the state left its
        region."""
        return bool(self._advance(k))


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


__all__ = ["EnvSteps", "PlantSteps", "SetupSteps"]
