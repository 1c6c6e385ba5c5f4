"""The controllers in force in a playground session (the one controller contract's linear
forms, built by their kind records and run in the compiled core's order of sums; the
swing-up, MPC or other runner) and the record of the last run; used by :mod:`equilibrist.web.session`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.native.linear_layout import python_linear
from equilibrist.web.protocol import kind_name
from equilibrist.web.runners import Runner

if TYPE_CHECKING:
    from equilibrist.control.design_record import Design
    from equilibrist.control.linear import LinearController
    from equilibrist.numeric.system import System


# -- the running loop ----------------------------------------------------------------


class _Linear:
    """One :class:`~equilibrist.control.controller.LinearController` run sample by sample.

    The contract's form in deviation coordinates (``dy = y - y_op``, no
    reference: ``dr = 0``)::

        u = u_op + Cc z + Dy dy,   x_hat = x_op + Ez z + Ey dy,
        z+ = Ac z + By dy + Bu (u_applied - u_op)

    by the linear library's sums written out for this controller's pattern
    (:func:`~equilibrist.native.linear_layout.python_linear`, run
    as Python on lists): the compiled core's sums in the core's order, so a
    session's LQG gives the bits of ``simulate`` (numpy's products follow the
    BLAS kernel of the CPU).
    """

    def __init__(self, ctrl: LinearController, system: System) -> None:
        self.ctrl = ctrl
        self.idx = np.array([system.state_index(o) for o in ctrl.output_names], dtype=np.int64)
        #: Whether it reads the sensors through a Kalman filter (their noise included);
        #: without a filter it reads the true state of the states it names (``LQR (true
        #: state)``), which is then the page's estimate.
        self.reads_sensors = bool(ctrl.form)
        #: Where its measurements are among the sensors' (when it reads them).
        self.pick = np.zeros(0, dtype=np.int64)
        self.z = np.array(ctrl.z0, dtype=float)
        self._y: list[float] = np.asarray(ctrl.y_op, dtype=float).tolist()
        packed = ctrl.packed()
        self._p = packed.tolist()
        self._fns = python_linear(packed)
        self._m, self._nz, self._n = ctrl.n_inputs, ctrl.n_z, ctrl.n_states

    def start_at(self, x_estimate: np.ndarray) -> None:
        self.z = self.ctrl.state_map @ (np.asarray(x_estimate, dtype=float) - self.ctrl.x_op)

    def output(self, y: np.ndarray) -> np.ndarray:
        self._y = np.asarray(y, dtype=float).tolist()
        u = [0.0] * self._m
        self._fns["linear_output"](0.0, self.z.tolist(), self._y, (), self._p, u)
        return np.array(u)

    def estimate(self) -> np.ndarray:
        if not self.ctrl.has_estimate:
            return np.array(self.ctrl.x_op, dtype=float)
        x = [0.0] * self._n
        self._fns["linear_estimate"](0.0, self.z.tolist(), self._y, (), self._p, x)
        return np.array(x)

    def update(self, u_applied: np.ndarray) -> None:
        z = [0.0] * self._nz
        self._fns["linear_update"](0.0, self.z.tolist(), self._y, (),
                                   np.asarray(u_applied, dtype=float).tolist(), self._p, z)
        self.z = np.array(z)


class _Loop:
    """The controllers of one design: its Kalman filter (:attr:`filter`, always running, for
    the page's estimate and a bumpless switch), the linear controller of each linear kind
    picked (built by its kind record, as ``simulate`` builds it) and the swing-up, MPC or
    other runner in charge."""

    def __init__(self, d: Design, system: System, previous: _Loop | None = None,
                 runner: Runner | None = None, x_estimate: np.ndarray | None = None) -> None:
        from equilibrist.control.linear import LinearController

        self.design = d
        self.system = system
        self.x_op = np.array(d.plant.x0, dtype=float)
        self.u_op = np.array(d.plant.u0, dtype=float)
        self.outputs = tuple(d.plant.output_names)
        self.out_idx = np.array([system.state_index(o) for o in self.outputs], dtype=np.int64)
        self.filter = _Linear(LinearController.from_design(d, kind="lqg"), system)
        self._linear: dict[str, _Linear | None] = {}
        if previous is not None:
            # The new filter goes on from the previous one's estimate.
            self.filter.start_at(previous.filter.estimate())
        # The swing-up or the MPC, when one is in charge: it goes on from the previous
        # one of its kind (a retune), or starts at the estimate in force (a switch).
        self.runner = runner
        self.runner_pick: np.ndarray | None = None
        self.runner_sigma = np.zeros(0)
        if runner is not None:
            prev = previous.runner if previous is not None else None
            if prev is not None and prev.kind == runner.kind:
                runner.adopt(prev)
            elif x_estimate is not None:
                runner.start_at(x_estimate)
            if all(o in self.outputs for o in runner.outputs):
                # The runner reads the same noisy measurement as the filter.
                self.runner_pick = np.array([self.outputs.index(o) for o in runner.outputs],
                                            dtype=np.int64)
            else:
                noise = system.spec.sensor_noise
                self.runner_sigma = np.array([float(noise.get(o, 0.0)) for o in runner.outputs])

    def linear(self, controller: str) -> _Linear | None:
        """The linear controller the picker's *controller* runs (None: the kind is not a
        linear one, or is the open loop), built once per design by its kind record. The
        design's own LQG is :attr:`filter` itself, so that it runs once and switching to it
        is bumpless."""
        if controller not in self._linear:
            self._linear[controller] = self._build_linear(controller)
        return self._linear[controller]

    def _build_linear(self, controller: str) -> _Linear | None:
        from equilibrist.control.linear import LinearController
        from equilibrist.controllers import kinds
        from equilibrist.errors import EquilibristError

        record = kinds.get(kind_name(controller), "playground")
        if not record.linear or record.open_loop:
            return None
        built = record.make(kinds.ControllerRequest.of_design(self.system, self.design))
        if not isinstance(built, LinearController):
            raise EquilibristError(f"the {record.name} kind is linear but built a "
                                   f"{type(built).__name__}, not a LinearController")
        if _same_controller(built, self.filter.ctrl):
            return self.filter
        linear = _Linear(built, self.system)
        if linear.reads_sensors:
            missing = [o for o in built.output_names if o not in self.outputs]
            if missing:
                raise EquilibristError(f"the {record.name} controller measures "
                                       f"{', '.join(missing)}, which the design does not")
            linear.pick = np.array([self.outputs.index(o) for o in built.output_names],
                                   dtype=np.int64)
        return linear

    def reset(self) -> None:
        self.filter.z = np.array(self.filter.ctrl.z0, dtype=float)
        for linear in self._linear.values():
            if linear is not None:
                linear.z = np.array(linear.ctrl.z0, dtype=float)
        if self.runner is not None:
            self.runner.reset()


def _same_controller(a: LinearController, b: LinearController) -> bool:
    """Whether *a* and *b* are the same controller (numbers, names, form, start, limits)."""
    return (a.fingerprint == b.fingerprint and a.form == b.form and a.rate == b.rate
            and np.array_equal(a.z0, b.z0)
            and np.array_equal(np.asarray(a.u_min), np.asarray(b.u_min))
            and np.array_equal(np.asarray(a.u_max), np.asarray(b.u_max)))


@dataclass
class _Record:
    """The samples of the last run (since a reset, a rate change or a new system)."""

    capacity: int
    n: int
    m: int
    ny: int
    rows: int = 0
    start: int = 0

    def __post_init__(self) -> None:
        self.time = np.empty(self.capacity)
        self.states = np.empty((self.capacity, self.n))
        self.estimates = np.empty((self.capacity, self.n))
        self.measurements = np.empty((self.capacity, self.ny))
        self.commanded = np.empty((self.capacity, self.m))
        self.saturated = np.empty((self.capacity, self.m))
        self.applied = np.empty((self.capacity, self.m))

    def add(self, t: float, x: np.ndarray, xhat: np.ndarray, y: np.ndarray, u_cmd: np.ndarray,
            u_sat: np.ndarray, u_app: np.ndarray) -> None:
        i = (self.start + self.rows) % self.capacity
        if self.rows == self.capacity:
            self.start = (self.start + 1) % self.capacity
        else:
            self.rows += 1
        self.time[i] = t
        self.states[i] = x
        self.estimates[i] = xhat
        self.measurements[i] = y
        self.commanded[i] = u_cmd
        self.saturated[i] = u_sat
        self.applied[i] = u_app

    def ordered(self, arr: np.ndarray) -> np.ndarray:
        idx = (self.start + np.arange(self.rows)) % self.capacity
        return arr[idx]
