"""The playground's nonlinear and optimizing controllers, run sample by sample.

LQR and LQG run in :mod:`equilibrist.web.session` as the linear contract's
state-space form. The swing-up and the MPC are built here from the same
design the page tuned, and each is wrapped in a small runner with one
calling convention for the session's loop:

``output(t, y)``
    The command for the measurement *y* (the runner's :attr:`outputs`);
    :attr:`estimate` then holds the controller's state estimate.
``update(t, y, u_applied)``
    Advance the controller's own state with the saturated command.
``adopt(previous)``
    Take over the running state of the previous runner of the same kind
    (after a redesign), so that a retune does not restart a swing-up or
    empty the MPC's filter.

*Swing-up* (:mod:`equilibrist.control.swingup`): the
:class:`~equilibrist.control.controller.NonlinearController`'s source run
by its plain-Python runtime
(:class:`~equilibrist.control.controller.NonlinearRuntime`). The same
functions compiled to C (:mod:`equilibrist.native.ctrl`) cost less per
sample but take a compiler run on first use, which would hold the interpreter
that streams every other session's frames; the plain-Python sample (some
40 microseconds on the cart-pole, 200 Hz) is under 1 % of a core.
The supervisor's mode (pumping or balancing) is the controller state's
``mode`` slot.

*MPC* (:mod:`equilibrist.control.mpc`): the constrained MPC of the design
(Kalman filter in front where the sensors do not measure the full state),
DAQP solving its QP at every sample where the LQR's own move does not
meet every constraint. The runner keeps the last solve times for the page
(median and worst over the last :data:`SOLVE_WINDOW` samples).
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.errors import EquilibristError

if TYPE_CHECKING:
    from equilibrist.control.controller import NonlinearController, NonlinearRuntime
    from equilibrist.control.design import Design
    from equilibrist.control.mpc import MPCRuntime
    from equilibrist.numeric.system import System

#: Controllers built here (the others run in the session itself).
KINDS = ("swingup", "mpc")
#: Solve times kept for the page's median and worst (samples).
SOLVE_WINDOW = 400
_EMPTY = np.zeros(0)


def unavailable(system: System) -> dict[str, str]:
    """``{controller: reason}`` of the controllers of :data:`KINDS` that do not apply to *system*."""
    from equilibrist.control.mpc import solver_missing
    from equilibrist.control.swingup import LAWS
    from equilibrist.tasks import task_names

    out: dict[str, str] = {}
    if "swingup" not in task_names(system):
        out["swingup"] = f"{system.key} has no hanging position to swing up from"
    elif system.name not in LAWS:
        out["swingup"] = f"{system.key} has no swing-up law: it exists for {', '.join(LAWS)}"
    missing = solver_missing()
    if missing:
        out["mpc"] = missing
    return out


def hanging_refusal(system: System) -> str | None:
    """Why *system* cannot start hanging (None: it can)."""
    from equilibrist.tasks import task_names

    if "swingup" in task_names(system):
        return None
    return f"{system.key} has no hanging position (the swing-up task exists for the rigs that state one)"


class SwingUpRunner:
    """The swing-up controller in the session's loop (see the module docstring)."""

    kind = "swingup"

    def __init__(self, ctrl: NonlinearController, system: System) -> None:
        from equilibrist.control.swingup import MODE_BALANCE, Z

        self.ctrl = ctrl
        self.outputs = tuple(ctrl.output_names)
        self.idx = np.array([system.state_index(o) for o in self.outputs], dtype=np.int64)
        self.runtime: NonlinearRuntime = ctrl.runtime()
        self._mode_slot = int(Z["mode"])
        self._balance = float(MODE_BALANCE)
        self.estimate: np.ndarray | None = None

    @property
    def mode(self) -> str:
        """``"balancing"`` or ``"pumping"``: the supervisor's choice for the next sample."""
        return "balancing" if self.runtime.z[self._mode_slot] == self._balance else "pumping"

    def reset(self) -> None:
        self.runtime.reset()
        self.estimate = None

    def adopt(self, previous: Runner | None) -> None:
        if isinstance(previous, SwingUpRunner) and previous.runtime.z.shape == self.runtime.z.shape:
            self.runtime.z = previous.runtime.z.copy()

    def start_at(self, x_estimate: np.ndarray) -> None:
        """Nothing to carry: the tracker starts from the first measurement."""

    def output(self, t: float, y: np.ndarray) -> np.ndarray:
        u = self.runtime.output(t, y, _EMPTY)
        self.estimate = self.runtime.estimate
        return u

    def update(self, t: float, y: np.ndarray, u_applied: np.ndarray) -> None:
        self.runtime.update(t, y, _EMPTY, u_applied)

    def solve_stats(self) -> dict[str, Any] | None:
        return None

    def describe(self) -> dict[str, Any]:
        s = self.ctrl.settings
        return {"kind": "swingup", "law": s.get("law"), "c_in": s.get("c_in"), "c_out": s.get("c_out"),
                "tuning": dict(s.get("tuning", {}))}


class MPCRunner:
    """The constrained MPC in the session's loop (see the module docstring)."""

    kind = "mpc"

    def __init__(self, runtime: MPCRuntime, system: System, setup_seconds: float) -> None:
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
        # The filter's predicted deviation: its Kalman front's state.
        self.runtime.front.z = np.array(z, dtype=float)

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

    def solve_stats(self) -> dict[str, Any] | None:
        """Median and worst time of a sample's solve over the last samples [ms]."""
        if not self.times:
            return None
        arr = np.fromiter(self.times, dtype=float)
        return {"median_ms": round(float(np.median(arr)) * 1e3, 4),
                "worst_ms": round(float(np.max(arr)) * 1e3, 4),
                "samples": int(arr.size), "qp_samples": self.solved,
                "status": self.runtime.last_status}

    def describe(self) -> dict[str, Any]:
        d = dict(self.ctrl.describe())
        d["setup_milliseconds"] = round(self.setup_seconds * 1e3, 2)
        return d


Runner = SwingUpRunner | MPCRunner


def build_runner(kind: str, system: System, design: Design) -> Runner:
    """The runner of controller *kind* (``"swingup"``, ``"mpc"``) for *design* on *system*.

    Raises an ``EquilibristError`` (one line) when the controller does not
    apply or cannot be built.
    """
    if kind == "swingup":
        from equilibrist.control.swingup import swingup

        return SwingUpRunner(swingup(system, design=design), system)
    if kind == "mpc":
        from equilibrist.control.mpc import mpc

        began = time.perf_counter()
        runtime = mpc(system, design=design).runtime()
        return MPCRunner(runtime, system, time.perf_counter() - began)
    raise EquilibristError(f"controller {kind!r} is not one of {', '.join(KINDS)}")


def export_folder(runner: Runner, system: System, folder: str) -> Mapping[str, str]:
    """Write the C export of *runner*'s controller into *folder* (as ``equilibrist export`` does)."""
    from equilibrist.export.writer import load_exporter

    exporter = load_exporter(runner.kind)
    if exporter is None:
        raise EquilibristError(f"the {runner.kind} controller has no C export in this installation")
    built: Any = runner.ctrl if runner.kind == "swingup" else runner.runtime
    done = exporter(built, folder, system=system, precision="double")
    return dict(done.files)


__all__ = ["KINDS", "MPCRunner", "Runner", "SwingUpRunner", "build_runner", "export_folder",
           "hanging_refusal", "unavailable"]
