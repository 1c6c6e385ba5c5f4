"""A playground session's plant, sample by sample: the core's plant steps, or the same plant
through a rig's effects (:class:`~equilibrist.sim.rig.Rig`: the core's ``eq_rig_measure_one``
and ``eq_rig_actuate_one``, the functions ``simulate``'s loops call), so that a session with
a rig is ``simulate``'s run with that rig and seed; used by :mod:`equilibrist.web.session`.

A sample is three calls: :meth:`measure` (the sensors, through the rig's encoders, delay,
velocity noise and filter), :meth:`actuate` (the saturated command through the rig's delay,
torque response, torque noise and limits; the page's push added beyond them) and
:meth:`advance` (the period's physics with that input held).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np

from equilibrist.sim import integrators, layout

if TYPE_CHECKING:
    from equilibrist.numeric.system import System
    from equilibrist.sim.rig import Rig
    from equilibrist.sim.simcore import NativeCore
    from equilibrist.sim.steps import PlantSteps

#: The rig's effects a session takes (its random pushes are the page's push button's).
EFFECTS = ("torque_response", "torque_time_constant", "measurement_delay",
           "measurement_delay_time", "actuation_delay", "actuation_delay_time", "torque_noise",
           "velocity_noise", "encoder_step", "velocity_filter")


class Plant(Protocol):
    """A session's plant: the three calls of a sample (see the module)."""

    def measure(self, k: int) -> np.ndarray: ...

    def actuate(self, k: int, u_sat: np.ndarray, u_app: np.ndarray) -> np.ndarray: ...

    def advance(self, k: int) -> None: ...


class PlainPlant:
    """The core's plant steps without a rig: the command and the push act as they are."""

    def __init__(self, steps: PlantSteps) -> None:
        self.steps = steps
        self._held = np.zeros(0)

    def measure(self, k: int) -> np.ndarray:
        return self.steps.measure()

    def actuate(self, k: int, u_sat: np.ndarray, u_app: np.ndarray) -> np.ndarray:
        self._held = u_app
        return u_app

    def advance(self, k: int) -> None:
        self.steps.advance(k, self._held)


class RigPlant:
    """The plant through *rig*: the core's plant steps of *system* at *rate* (*n_sub* steps of
    RK4 a period with the process noise gain *lw*, sensors *outputs* with the noise root *lv*,
    drawn from *rng*) with the rig's effects between it and the controller, about the
    operating point *op* (state, then input: the input the actuation delay starts with)."""

    def __init__(self, kernel: NativeCore, *, system: System, x: np.ndarray, p: np.ndarray,
                 rate: float, n_sub: int, lw: np.ndarray, outputs: np.ndarray, lv: np.ndarray,
                 rng: np.ndarray, rig: Rig, op: np.ndarray) -> None:
        n, m = system.n_states, system.n_inputs
        self.x = x
        self.y = np.zeros(len(outputs))
        self._u_cmd, self._u_act, self._held = np.zeros(m), np.zeros(m), np.zeros(m)
        self._lim = np.zeros(2 * m)
        low, high = system.input_limits
        self._lim[0::2], self._lim[1::2] = low, high
        lw = np.ascontiguousarray(lw, dtype=float).reshape(n, -1)
        lv = np.ascontiguousarray(lv, dtype=float)
        c_idx = np.ascontiguousarray(outputs, dtype=np.int64)
        fopts = layout.FOPTS.pack(h=1.0 / (rate * n_sub), rtol=integrators.RTOL,
                                  atol=integrators.ATOL, rate=float(rate))
        rig_i, rig_f = rig.pack(system, rate, len(c_idx))
        self._rig_state = np.zeros(rig.state_len(system, rate, len(c_idx)))
        p_sets = np.concatenate([np.asarray(p, dtype=float), np.zeros(2 * m)])[None, :]
        self._advance = kernel.advancer(
            x=x, u_app=self._held, op=np.asarray(op, dtype=float), p_sets=p_sets,
            p_switch=np.zeros(1, dtype=np.int64), lin_s=None,
            region=np.array([[-np.inf] * n, [np.inf] * n]),
            kicks=np.zeros((0, 2), dtype=np.int64), kick_value=np.zeros(0),
            pulses=np.zeros((0, 3), dtype=np.int64), pulse_value=np.zeros(0), lw=lw, rng=rng,
            iopts=layout.IOPTS.pack(int, n_samples=0, record=0, delay=0, n_sub=int(n_sub),
                                    integrator=integrators.number(integrators.DEFAULT),
                                    estimates=0, accumulate=0),
            fopts=fopts, status=np.zeros(len(layout.STATUS), dtype=np.int64),
            scr=kernel.scratch(p_sets.shape[1], 0, lw.shape[1]), rig_i=rig_i)
        self._measure, self._actuate = kernel.rig_steps(
            x=x, c_idx=c_idx, lv=lv, op=np.asarray(op, dtype=float), fopts=fopts, rig_i=rig_i,
            rig_f=rig_f, rig_s=self._rig_state, rng=rng, y=self.y, u_app=self._u_cmd,
            u_act=self._u_act, lim=self._lim)

    def measure(self, k: int) -> np.ndarray:
        self._measure(k)
        return self.y.copy()

    def actuate(self, k: int, u_sat: np.ndarray, u_app: np.ndarray) -> np.ndarray:
        self._u_cmd[:] = u_sat
        self._actuate(k)
        # The page's push acts beside the actuator (beyond its limits), as without a rig.
        self._held[:] = self._u_act + (np.asarray(u_app, dtype=float) - u_sat)
        return self._held.copy()

    def advance(self, k: int) -> None:
        self._advance(k)


__all__ = ["EFFECTS", "PlainPlant", "Plant", "RigPlant"]
