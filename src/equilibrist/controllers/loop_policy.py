"""Any controller kind in any loop: a policy object stepped by a foreign simulation or a robot.

:func:`policy` builds a controller of any kind (``lqr``, ``lqg``, ``swingup``, ``tvlqr``,
``mpc``... as ``--controller`` names them) for a system and returns a :class:`Policy`: called
with the time and the measurements once per sample, it returns the input to apply, in the
actuator's units (the system's inputs, N*m or N), saturated at the system's limits. It steps the
controller's own source compiled (:mod:`equilibrist.control.compiled`): the same translation
to C the simulation core runs and the C export ships, so a foreign loop sees the same
arithmetic as ``equilibrist simulate`` and the robot's firmware.

What the loop must know, the policy does for it: the controller's clock starts at 0 at
:meth:`Policy.reset` (or at the first call), the controller is built at the loop's rate, and
the saturated input is what its state is updated with. A loop that applies something else
(a motor's own limit, a filter) tells the policy with :meth:`Policy.applied`.

Example (a MuJoCo loop; ``docs/policy.md`` has the whole recipe)::

    import equilibrist
    pi = equilibrist.policy("acrobot", controller="lqr", rate=200.0)
    pi.reset()
    u = pi(data.time, [data.qpos[0], data.qpos[1], data.qvel[0], data.qvel[1]])
    data.ctrl[:] = pi.mujoco_ctrl(u, gear=model.actuator_gear[:, 0])
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.errors import ControllerError

if TYPE_CHECKING:
    from equilibrist.control.nonlinear import NonlinearController
    from equilibrist.numeric.system import System

#: Keyword options of :func:`policy` that are the design's
#: (:func:`equilibrist.control.design.design`), not the kind's.
DESIGN_OPTIONS = ("q", "r", "qn", "rn", "outputs", "kalman_form", "discretization", "at")


class Policy:
    """A controller stepped sample by sample from a foreign loop (see the module's text).

    Attributes
    ----------
    controller : NonlinearController
        The controller as the simulation core and the C export run it.
    rate : float
        The sample rate it was built for [Hz]: call it once per ``1 / rate`` seconds.
    outputs : tuple of str
        The measurements it takes, in order (states of the system).
    input_names, input_units : tuple of str
        The inputs it returns, in order, and their units (the actuator's: N*m, N).
    low, high : numpy.ndarray
        The inputs' limits: what a call returns is saturated at them.
    """

    def __init__(self, controller: NonlinearController, *, low: np.ndarray, high: np.ndarray,
                 input_units: Sequence[str]) -> None:
        from equilibrist.control.compiled import controller_functions

        self.controller = controller
        names = ("output", "update") + (("estimate",) if controller.has_estimate else ())
        fns = controller_functions(controller.source, names)
        self._output, self._update = fns.fns["output"], fns.fns["update"]
        self.rate = float(controller.rate)
        self.outputs = tuple(controller.output_names)
        self.input_names = tuple(controller.input_names)
        self.input_units = tuple(input_units)
        self.low, self.high = np.array(low, dtype=float), np.array(high, dtype=float)
        self._low, self._high = self.low.tolist(), self.high.tolist()
        # The arrays the compiled functions read and write live as long as the policy: their
        # addresses are taken once (a ctypes call with ready arguments is most of a step).
        self._params = np.array(controller.params, dtype=float)
        self._r = np.zeros(len(controller.tracked_names))
        self._u = np.zeros(len(self.input_names))
        self._y = np.zeros(len(self.outputs))
        self._zs = (np.zeros(controller.n_z), np.zeros(controller.n_z))
        p, r, y, u = (self._arg(a) for a in (self._params, self._r, self._y, self._u))
        za, zb = (self._arg(a) for a in self._zs)
        # (z, y, r, params, u_out) and (z, y, r, u_applied, params, z_out), from buffer 0 or 1.
        self._out_args = ((*za, *y, *r, *p, *u), (*zb, *y, *r, *p, *u))
        self._upd_args = ((*za, *y, *r, *u, *p, *zb), (*zb, *y, *r, *u, *p, *za))
        self.reset()

    @staticmethod
    def _arg(a: np.ndarray) -> tuple[int | None, int]:
        return (a.ctypes.data if a.size else None, a.shape[0])

    def reset(self) -> None:
        """Start again: the controller's state as built, its clock at 0 at the next call."""
        self._zs[0][:] = self.controller.z0
        self._which = 0
        self._t0: float | None = None
        self._t = 0.0
        self._pending = False

    @property
    def state(self) -> np.ndarray:
        """The controller's state now (a copy)."""
        return self._zs[self._which].copy()

    def __call__(self, t: float, y: Sequence[float] | np.ndarray,
                 r: Sequence[float] | np.ndarray | None = None) -> np.ndarray:
        """The input to apply at the loop's time *t* [s], from the measurements *y*.

        *t* is the loop's own clock: the controller's starts at 0 at the first call after
        :meth:`reset`. *y* holds :attr:`outputs` in order; *r* the tracked references, if
        the controller tracks any. Returns a new array of the inputs, saturated.
        """
        if self._pending:  # the last sample's update, with the input that acted
            self._update(self._t, *self._upd_args[self._which])
            self._which ^= 1
        if self._t0 is None:
            self._t0 = float(t)
        self._t = float(t) - self._t0
        self._y[:] = y
        if r is not None:
            self._r[:] = r
        u = self._u
        self._output(self._t, *self._out_args[self._which])
        for i, (lo, hi) in enumerate(zip(self._low, self._high, strict=True)):
            v = u[i]
            u[i] = lo if v < lo else hi if v > hi else v
        self._pending = True
        return u.copy()

    def applied(self, u: Sequence[float] | np.ndarray) -> None:
        """Tell the policy the input that acted since the last call, if not what it returned
        (the controller's state is updated with it at the next call)."""
        self._u[:] = u

    @staticmethod
    def mujoco_ctrl(u: Sequence[float] | np.ndarray, gear: Sequence[float] | np.ndarray | float
                    ) -> np.ndarray:
        """MuJoCo's ``data.ctrl`` for the inputs *u*: ``u / gear`` (a motor's force or torque
        is ``gear * ctrl``), *gear* per input (``model.actuator_gear[:, 0]``) or one for all."""
        g = np.asarray(gear, dtype=float)
        if np.any(g == 0) or not np.all(np.isfinite(g)):
            raise ControllerError(f"gear {g.tolist()}: expected finite, non-zero ratios")
        out: np.ndarray = np.asarray(u, dtype=float) / g
        return out


def _request(system: System, rate: float | None, options: Mapping[str, Any]) -> Any:
    from equilibrist.controllers.kinds import ControllerRequest

    design_options = {k: v for k, v in options.items() if k in DESIGN_OPTIONS}
    kind_options = {k: v for k, v in options.items() if k not in DESIGN_OPTIONS}
    return ControllerRequest(system=system, rate=rate, design_options=design_options,
                             options=kind_options)


def policy(system: System | str, *, controller: str = "lqr", rate: float | None = None,
           **options: Any) -> Policy:
    """The controller of kind *controller* for *system* as a :class:`Policy`.

    Parameters
    ----------
    system : System or str
        A bound system, or a catalogue name or system file (built with its defaults).
    controller : str
        The kind, as ``--controller`` names it (``lqr``, ``lqg``, ``swingup``, ``tvlqr``...).
    rate : float, optional
        The loop's rate [Hz] (default: the system's control rate).
    **options
        The design's options (``q``, ``r``, ``qn``, ``rn``, ``outputs``, ``kalman_form``,
        ``discretization``, ``at``) and the kind's by their keys (``trajectory``,
        ``balance``, ``catch`` for ``tvlqr``; ``trajectory`` takes a file or a plan of
        :func:`equilibrist.control.trajopt.plan`).

    Raises
    ------
    ControllerError
        An unknown kind, a kind that does not apply, a rate that is not a positive number,
        the open loop (``none``), or a kind whose controller is not a compiled one (a Python
        controller: call it).
    """
    from equilibrist.control.linear import LinearController
    from equilibrist.control.nonlinear import NonlinearController
    from equilibrist.controllers.kinds import build_controller

    if isinstance(system, str):
        from equilibrist.numeric.lookup import get_system

        system = get_system(system)
    if rate is not None and not (isinstance(rate, int | float) and math.isfinite(rate)
                                 and rate > 0):
        raise ControllerError(f"rate = {rate!r}: expected a positive number of Hz")
    built = build_controller(controller, _request(system, rate, options))
    if built is None:
        raise ControllerError(f"the {controller} controller is the open loop: there is no "
                              "feedback to step (apply the operating point's input)")
    if isinstance(built, LinearController):
        built = built.as_nonlinear()
    if not isinstance(built, NonlinearController):
        raise ControllerError(f"the {controller} controller is a {type(built).__name__}, not "
                              "a compiled controller: call its output and update directly")
    spec = system.spec
    low = np.array([float(system.params[f"{i}_min"]) for i in system.input_names])
    high = np.array([float(system.params[f"{i}_max"]) for i in system.input_names])
    units = tuple(next(i.unit for i in spec.inputs if i.name == name)
                  for name in system.input_names)
    return Policy(built, low=low, high=high, input_units=units)


__all__ = ["DESIGN_OPTIONS", "Policy", "policy"]
