"""The playground's nonlinear and optimizing controllers, run sample by sample.

LQR and LQG run in :mod:`equilibrist.web.session` as the linear contract's state-space
form. Every other kind is built here from the design the page tuned and wrapped in a
runner with one calling convention for the session's loop: ``output(t, y)`` (then
:attr:`estimate` holds the controller's estimate), ``update(t, y, u_applied)``, and
``adopt(previous)``, which takes over the previous runner's running state after a retune.
A nonlinear controller runs in its plain-Python runtime: compiling it would hold the
interpreter that streams every other session's frames, and a sample costs under 1 % of a
core. The MPC keeps its last solve times for the page (``docs/playground.md``).
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.errors import EquilibristError
from equilibrist.web.protocol import kind_name

if TYPE_CHECKING:
    from equilibrist.control.design_record import Design
    from equilibrist.control.mpc_runtime import MPCRuntime
    from equilibrist.control.nonlinear import NonlinearController, NonlinearRuntime
    from equilibrist.control.trajopt import Trajectory
    from equilibrist.controllers.kinds import ControllerKind
    from equilibrist.numeric.system import System


def runner_kinds() -> tuple[str, ...]:
    """The playground's kinds built here: every kind of the registry offered on the
    playground that is not LQR/LQG (``linear``, run by the session's own filter) or the open
    loop."""
    from equilibrist.controllers import kinds

    return tuple(k.name for k in kinds.all_kinds("playground") if not (k.linear or k.open_loop))

#: Solve times kept for the page's median and worst (samples).
SOLVE_WINDOW = 400
_EMPTY = np.zeros(0)


def planned(controller: str) -> bool:
    """Whether the picked *controller* tracks a plan (its record's
    :attr:`~equilibrist.controllers.kinds.ControllerKind.planned`): the session plans the
    swing-up before it builds it (:mod:`equilibrist.web.session_plan`)."""
    return _record(controller).planned


def from_any_state(controller: str) -> bool:
    """Whether the picked *controller* brings the system up from any state (its record's
    :attr:`~equilibrist.controllers.kinds.ControllerKind.from_any_state`: the swing-up)."""
    return _record(controller).from_any_state


def _record(controller: str) -> ControllerKind:
    """The registry's record of the picker's *controller* (``off``: the open loop)."""
    from equilibrist.controllers import kinds

    return kinds.get(kind_name(controller))


def unavailable(system: System) -> dict[str, str]:
    """``{controller: reason}`` of the playground's controllers that do not apply to *system*
    (each kind's own :attr:`~equilibrist.controllers.kinds.ControllerKind.applies`; a kind that
    tracks a plan needs a swing-up to plan and CasADi to plan it)."""
    import importlib.util

    from equilibrist.controllers import kinds

    out: dict[str, str] = {}
    for kind in kinds.all_kinds("playground"):
        why = kind.applies(system)
        if why is None and kind.planned:
            why = hanging_refusal(system)
            if why is None and importlib.util.find_spec("casadi") is None:
                why = ("planning the swing-up needs CasADi with IPOPT: pip install "
                       "'equilibrist[trajopt]'")
        if why is not None:
            out["off" if kind.open_loop else kind.name] = why
    return out


def hanging_refusal(system: System) -> str | None:
    """Why *system* cannot start hanging (None: it can)."""
    from equilibrist.tasks import task_names

    if "swingup" in task_names(system):
        return None
    return f"{system.key} has no hanging position (the swing-up task exists for the rigs that state one)"


class NonlinearRunner:
    """Any :class:`~equilibrist.control.controller.NonlinearController` in the session's loop
    (a kind of one's own, the swing-up), run by its plain-Python runtime."""

    #: What takes the sample's time, for the page's warning that the loop lags.
    busy = "the controller"

    def __init__(self, ctrl: NonlinearController, system: System, kind: str) -> None:
        self.kind = kind
        self.ctrl = ctrl
        self.outputs = tuple(ctrl.output_names)
        self.idx = np.array([system.state_index(o) for o in self.outputs], dtype=np.int64)
        self.runtime: NonlinearRuntime = ctrl.runtime()
        self.estimate: np.ndarray | None = None

    @property
    def mode(self) -> str:
        return "running"

    def reset(self) -> None:
        self.runtime.reset()
        self.estimate = None

    def adopt(self, previous: Runner | None) -> None:
        if (isinstance(previous, NonlinearRunner) and previous.kind == self.kind
                and previous.runtime.z.shape == self.runtime.z.shape):
            self.runtime.z = previous.runtime.z.copy()

    def start_at(self, x_estimate: np.ndarray) -> None:
        """Nothing to carry: the tracker starts from the first measurement."""

    def output(self, t: float, y: np.ndarray) -> np.ndarray:
        u = self.runtime.output(t, y, _EMPTY)
        self.estimate = self.runtime.estimate
        return u

    def update(self, t: float, y: np.ndarray, u_applied: np.ndarray) -> None:
        self.runtime.update(t, y, _EMPTY, u_applied)

    def solve_stats(self) -> dict[str, object] | None:
        return None

    def describe(self) -> dict[str, object]:
        return {"kind": self.kind, **dict(self.ctrl.settings)}


class SwingUpRunner(NonlinearRunner):
    """The swing-up (a kind that brings the system up from any state): a nonlinear controller
    whose state holds the supervisor's mode. Its ``controller_info`` is the swing-up's
    (its law and thresholds), ``kind`` the kind's own name: the page reads what it shows of
    it from the kind's record (the ``system`` frame's ``controller_options``)."""

    def __init__(self, ctrl: NonlinearController, system: System, kind: str) -> None:
        from equilibrist.control.swingup_law import MODE_BALANCE, Z

        super().__init__(ctrl, system, kind)
        self._mode_slot = int(Z["mode"])
        self._balance = float(MODE_BALANCE)

    @property
    def mode(self) -> str:
        """``"balancing"`` or ``"pumping"``: the supervisor's choice for the next sample."""
        return "balancing" if self.runtime.z[self._mode_slot] == self._balance else "pumping"

    def describe(self) -> dict[str, object]:
        s = self.ctrl.settings
        tuning = s.get("tuning", {})
        return {"kind": self.kind, "law": s.get("law"), "c_in": s.get("c_in"), "c_out": s.get("c_out"),
                "tuning": dict(tuning) if isinstance(tuning, Mapping) else tuning}


class PlanRunner(NonlinearRunner):
    """The time-varying LQR on a plan of the session (a kind whose record is
    :attr:`~equilibrist.controllers.kinds.ControllerKind.planned`), on a clock of its own.

    Its time is the plan's: it starts at the first sample after a reset or a switch, from
    the plan's beginning when the state is nearer the plan's start than its end (a run
    started hanging), else from the plan's end (the balancing LQR: a reset upright). A
    retune on the same plan goes on at the same plan time (:meth:`adopt`).
    """

    def __init__(self, ctrl: NonlinearController, system: System, kind: str,
                 trajectory: Trajectory, scales: np.ndarray) -> None:
        super().__init__(ctrl, system, kind)
        from equilibrist.control.tvlqr import plan_samples

        self.trajectory = trajectory
        self.duration = float(trajectory.duration)
        _t, self.xs, self.us = plan_samples(ctrl)
        self.rate = float(ctrl.rate)
        self.scales = np.asarray(scales, dtype=float)
        self.t0: float | None = None  # the session's time at the plan's beginning
        self.tau = 0.0  # the plan's time of the last sample
        self.ghost_keys: frozenset[str] | None = None  # the drawing's shapes the plan moves

    @property
    def caught(self) -> bool:
        """The balancing law acts: the plan has ended, or the state entered the catch region
        before (the controller's latch, the last slot of its state)."""
        return self.t0 is not None and (self.tau >= self.duration or self.runtime.z[-1] >= 0.5)

    @property
    def mode(self) -> str:
        """``"tracking"`` while the plan runs, ``"balancing"`` after it or its catch."""
        return "balancing" if self.caught else "tracking"

    def reset(self) -> None:
        super().reset()
        self.t0 = None

    def adopt(self, previous: Runner | None) -> None:
        if isinstance(previous, PlanRunner) and previous.trajectory is self.trajectory:
            self.t0, self.tau = previous.t0, previous.tau
            self.runtime.z[-1] = previous.runtime.z[-1]  # a retune keeps the catch

    def start_at(self, x_estimate: np.ndarray) -> None:
        self.t0 = None

    def plan_state(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The plan's state and input at the plan time of the last sample (None: no plan
        runs, before the first sample or after the plan's end)."""
        if self.t0 is None or not 0.0 <= self.tau <= self.duration or self.caught:
            return None
        k = min(int(np.floor(self.tau * self.rate + 0.5)), self.xs.shape[0] - 1)
        return self.xs[k], self.us[k]

    def output(self, t: float, y: np.ndarray) -> np.ndarray:
        if self.t0 is None:
            far_start = np.abs((y - self.xs[0][self.idx]) / self.scales[self.idx]).max()
            far_end = np.abs((y - self.xs[-1][self.idx]) / self.scales[self.idx]).max()
            self.t0 = t if far_start <= far_end else t - self.duration
        self.tau = t - self.t0
        return super().output(self.tau, y)

    def update(self, t: float, y: np.ndarray, u_applied: np.ndarray) -> None:
        super().update(t - (self.t0 or 0.0), y, u_applied)

    def describe(self) -> dict[str, object]:
        traj = self.trajectory
        return {"kind": self.kind, "plan_duration": self.duration, "knots": traj.knots,
                "solve_time": traj.solve_time, "samples": int(self.ctrl.params[0]),
                "balance": "lqr"}


def build_plan_runner(kind: str, system: System, design: Design, trajectory: Trajectory) -> PlanRunner:
    """The time-varying LQR of *kind* along *trajectory* on the page's *design* (its weights,
    its rate, its balancing LQR at the end)."""
    from equilibrist.control.tvlqr import tvlqr

    if design.discrete is None:
        raise EquilibristError("the time-varying LQR needs a discrete design (a rate)")
    ctrl = tvlqr(system, trajectory, rate=float(design.rate or system.spec.control_rate),
                 Q=design.Q, R=design.R, S_end=design.S, K_end=design.K,
                 x_op=np.asarray(design.plant.x0, dtype=float),
                 u_op=np.asarray(design.plant.u0, dtype=float))
    scales = np.array([float(system.spec.design_scales.get(s, 1.0)) or 1.0
                       for s in system.state_names])
    return PlanRunner(ctrl, system, kind, trajectory, scales)


class MPCRunner:
    """The constrained MPC in the session's loop (see the module docstring)."""

    busy = "the MPC's solves"

    def __init__(self, runtime: MPCRuntime, system: System, setup_seconds: float,
                 kind: str) -> None:
        self.kind = kind
        self.runtime = runtime
        self.ctrl = runtime.ctrl
        self.outputs = tuple(runtime.ctrl.output_names)
        self.idx = np.array([system.state_index(o) for o in self.outputs], dtype=np.int64)
        self.setup_seconds = setup_seconds
        self.times: deque[float] = deque(maxlen=SOLVE_WINDOW)
        self.solved = 0  # samples that called DAQP (not the exact unconstrained case)
        self.estimate: np.ndarray | None = None

    @property
    def mode(self) -> str:
        """``"constrained"`` when the last sample solved the QP, ``"unconstrained"`` when the
        LQR's own move was the QP's minimizer (no constraint active over the horizon)."""
        return "unconstrained" if self.runtime.last_status in ("unconstrained", "") else "constrained"

    def reset(self) -> None:
        self.runtime.reset()
        self.estimate = None

    def adopt(self, previous: Runner | None) -> None:
        if isinstance(previous, MPCRunner) and previous.runtime.z.shape == self.runtime.z.shape:
            self._set_filter(previous.runtime.z)

    def start_at(self, x_estimate: np.ndarray) -> None:
        """Start the MPC's filter at *x_estimate* (a bumpless switch from another controller)."""
        self._set_filter(np.asarray(x_estimate, dtype=float) - self.ctrl.x_op)

    def _set_filter(self, z: np.ndarray) -> None:
        # The filter's predicted deviation.
        self.runtime.z = np.array(z, dtype=float)

    def output(self, t: float, y: np.ndarray) -> np.ndarray:
        rt = self.runtime
        began = time.perf_counter()
        u = rt.output(t, y, _EMPTY)
        self.times.append(time.perf_counter() - began)
        if rt.last_status != "unconstrained":
            self.solved += 1
        # The runtime keeps every solve time; the window above is what the page needs.
        rt.solve_times.clear()
        self.estimate = rt.estimate
        return u

    def update(self, t: float, y: np.ndarray, u_applied: np.ndarray) -> None:
        self.runtime.update(t, y, _EMPTY, u_applied)

    def solve_stats(self) -> dict[str, object] | None:
        """Median and worst time of a sample's solve over the last samples [ms]."""
        if not self.times:
            return None
        arr = np.fromiter(self.times, dtype=float)
        return {"median_ms": round(float(np.median(arr)) * 1e3, 4),
                "worst_ms": round(float(np.max(arr)) * 1e3, 4),
                "samples": int(arr.size), "qp_samples": self.solved,
                "status": self.runtime.last_status}

    def describe(self) -> dict[str, object]:
        d = dict(self.ctrl.describe())
        d["setup_milliseconds"] = round(self.setup_seconds * 1e3, 2)
        return d


Runner = NonlinearRunner | MPCRunner


def build_runner(kind: str, system: System, design: Design) -> Runner:
    """The runner of the registry's controller *kind* built as ``simulate`` builds it, on the
    page's *design* for *system*; the record says how it runs (``solves_qp``: the MPC's
    runtime, solves timed; ``from_any_state``: with its supervisor's mode shown; else the
    ``NonlinearController``'s Python runtime). One-line ``EquilibristError`` when it does not
    apply, cannot be built, or is not of the form its record says.
    """
    from equilibrist.control.mpc_runtime import MPCRuntime
    from equilibrist.control.nonlinear import NonlinearController
    from equilibrist.controllers import kinds

    record = kinds.get(kind, "playground")
    request = kinds.ControllerRequest.of_design(system, design)  # the page's own, tuned there
    began = time.perf_counter()
    built = record.make(request)
    if record.solves_qp:
        if isinstance(built, MPCRuntime):
            return MPCRunner(built, system, time.perf_counter() - began, kind)
        expected = "the MPC's runtime"
    elif isinstance(built, NonlinearController):
        if record.from_any_state:
            return SwingUpRunner(built, system, kind)
        return NonlinearRunner(built, system, kind)
    else:
        expected = "a NonlinearController"
    raise EquilibristError(f"the {kind} controller is a {type(built).__name__}: the playground "
                           f"runs it as {expected}")


def export_folder(runner: Runner, system: System, folder: str) -> Mapping[str, str]:
    """Write the C export of *runner*'s controller into *folder* (as ``equilibrist export`` does:
    the exporter of the value's type)."""
    from equilibrist.export.writer import export_controller

    value = runner.runtime if isinstance(runner, MPCRunner) else runner.ctrl
    done = export_controller(value, folder, system=system, precision="double")
    return dict(done.files)


__all__ = [
    "MPCRunner",
    "NonlinearRunner",
    "PlanRunner",
    "Runner",
    "SwingUpRunner",
    "build_plan_runner",
    "build_runner",
    "export_folder",
    "from_any_state",
    "hanging_refusal",
    "planned",
    "runner_kinds",
    "unavailable",
]
