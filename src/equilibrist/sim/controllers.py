"""Controllers the simulator runs: open loop, state feedback, LQG, and yours.

The built-in controllers are frozen descriptions (gains, filter matrices,
operating point); the compiled core runs them. Each also has a plain-Python
:meth:`runtime` with the same step interface as a user-written controller,
which is what the core's results are checked against.

All work in deviation coordinates about the operating point ``(x_op, u_op)``
(``dx = x - x_op``), take absolute measurements and return absolute inputs.

A user-written controller is any object with a method
``step(t, y, r) -> u`` (or a plain function ``(t, y, r) -> u``): ``t`` the
sample time in seconds, ``y`` the measured outputs (absolute, noisy, in the
order of the run's ``outputs``), ``r`` the reference (absolute; empty when
the run has none); it returns the commanded inputs, which the simulator
then saturates (and delays, when asked). An optional ``reset()`` is called
before the run; an optional ``estimate`` attribute (absolute state vector)
is recorded as the run's estimate after each step; an optional ``rate``
attribute (Hz) is the sample rate the run then uses (and must agree with);
an optional ``outputs`` attribute names the states it measures; an
optional ``applied(u)`` method is told the input that actually acted
(saturated, delayed) after each step, as a Kalman filter needs.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable

import numpy as np

from equilibrist.errors import DimensionError, SimulationError
from equilibrist.sim.signals import Signal, as_signal


@runtime_checkable
class Controller(Protocol):
    """The step interface of a controller written in Python."""

    def step(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray: ...


def _frozen(arr: object, shape: tuple[int, ...] | None, what: str) -> np.ndarray:
    a = np.array(arr, dtype=float)
    if shape is not None and a.shape != shape:
        raise DimensionError(f"{what} has shape {a.shape}, expected {shape}")
    if not np.all(np.isfinite(a)):
        raise SimulationError(f"{what} has a value that is not finite")
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class OpenLoop:
    """No feedback: the inputs follow ``signal`` (absolute; None holds ``u_op``).

    ``signal`` is a :mod:`~equilibrist.sim.signals` signal, a Python
    function of time, or a constant.
    """

    signal: Signal | Callable[[float], Any] | float | Sequence[float] | None = None

    kind = "none"

    def describe(self) -> dict[str, object]:
        sig = None if self.signal is None else as_signal(self.signal).describe()
        return {"kind": self.kind, "signal": sig}


@dataclass(frozen=True, eq=False)
class StateFeedback:
    """``u = u_op - K (x - x_op) + K_c (r - r_op)`` from the full (measured) state.

    ``K`` is applied at the simulation's sample rate with zero-order hold,
    whether it was designed in continuous time or for that rate.
    ``tracked`` names the outputs ``K_c`` makes follow the reference.
    """

    K: np.ndarray
    x_op: np.ndarray
    u_op: np.ndarray
    Kc: np.ndarray | None = None
    tracked: tuple[str, ...] = ()
    rate: float | None = None
    design: Any = field(default=None, repr=False)

    kind = "lqr"

    def __post_init__(self) -> None:
        x_op = _frozen(self.x_op, None, "x_op").reshape(-1)
        u_op = _frozen(self.u_op, None, "u_op").reshape(-1)
        n, m = x_op.size, u_op.size
        object.__setattr__(self, "x_op", x_op)
        object.__setattr__(self, "u_op", u_op)
        object.__setattr__(self, "K", _frozen(np.reshape(self.K, (m, n)), (m, n), "K"))
        _check_tracking(self, m)

    @classmethod
    def from_design(cls, design: Any, *, tracking: bool = False) -> StateFeedback:
        """The design's gain (its discrete gain when it has a rate) and operating point."""
        plant = design.plant
        kc = _design_kc(design) if tracking else None
        return cls(
            K=design.K, x_op=plant.x0, u_op=plant.u0, Kc=kc,
            tracked=tuple(design.tracked) if tracking else (),
            rate=getattr(design, "rate", None), design=design,
        )

    def runtime(self, state_names: Sequence[str]) -> _StateFeedbackRuntime:
        """A Python controller doing the same as the compiled core (for checks)."""
        return _StateFeedbackRuntime(
            self, tuple(state_names), [list(state_names).index(o) for o in self.tracked]
        )

    def describe(self) -> dict[str, object]:
        return {"kind": self.kind, "K": self.K.tolist(),
                "Kc": None if self.Kc is None else self.Kc.tolist(),
                "tracked": list(self.tracked), "rate": self.rate}


@dataclass(frozen=True, eq=False)
class LQG:
    """Discrete Kalman filter on the measured ``outputs`` plus state feedback on its estimate.

    ``form`` "current": ``x_hat = x_pred + K_f (y - C x_pred)``, then
    ``u = u_op - K x_hat (+ K_c (r - r_op))`` and ``x_pred+ = A_d x_hat + B_d du``;
    "predictor": ``u`` from ``x_hat``, then
    ``x_hat+ = A_d x_hat + B_d du + K_f (y - C x_hat)``. ``du`` is the input
    actually applied (saturated, and delayed when the run delays). The filter
    starts at ``x_hat0`` (deviation; default the operating point).
    ``rate`` is the filter's sample rate, which the run must use.
    """

    K: np.ndarray
    Ad: np.ndarray
    Bd: np.ndarray
    Kf: np.ndarray
    outputs: tuple[str, ...]
    x_op: np.ndarray
    u_op: np.ndarray
    rate: float
    form: str = "current"
    Kc: np.ndarray | None = None
    tracked: tuple[str, ...] = ()
    x_hat0: np.ndarray | None = None
    design: Any = field(default=None, repr=False)

    kind = "lqg"

    def __post_init__(self) -> None:
        x_op = _frozen(self.x_op, None, "x_op").reshape(-1)
        u_op = _frozen(self.u_op, None, "u_op").reshape(-1)
        n, m, ny = x_op.size, u_op.size, len(self.outputs)
        object.__setattr__(self, "x_op", x_op)
        object.__setattr__(self, "u_op", u_op)
        object.__setattr__(self, "K", _frozen(np.reshape(self.K, (m, n)), (m, n), "K"))
        object.__setattr__(self, "Ad", _frozen(self.Ad, (n, n), "A_d"))
        object.__setattr__(self, "Bd", _frozen(np.reshape(self.Bd, (n, m)), (n, m), "B_d"))
        object.__setattr__(self, "Kf", _frozen(np.reshape(self.Kf, (n, ny)), (n, ny), "K_f"))
        object.__setattr__(self, "outputs", tuple(self.outputs))
        x0 = np.zeros(n) if self.x_hat0 is None else self.x_hat0
        object.__setattr__(self, "x_hat0", _frozen(x0, (n,), "x_hat0"))
        if self.form not in ("current", "predictor"):
            raise SimulationError(
                f"Kalman filter form {self.form!r}: expected 'current' or 'predictor'"
            )
        if not (np.isfinite(self.rate) and self.rate > 0):
            raise SimulationError(f"the filter's rate must be positive, got {self.rate!r}")
        _check_tracking(self, m)

    @classmethod
    def from_design(cls, design: Any, *, tracking: bool = False) -> LQG:
        """The design's discrete Kalman filter and gain (it needs a sample rate)."""
        if getattr(design, "discrete", None) is None or getattr(design, "Kf", None) is None:
            raise SimulationError(
                "an LQG controller needs a design with a sample rate (its discrete Kalman "
                "filter): design(system, rate=...)"
            )
        plant = design.plant
        disc = design.discrete
        kc = _design_kc(design) if tracking else None
        return cls(
            K=design.K, Ad=disc.A, Bd=disc.B, Kf=design.Kf, outputs=tuple(plant.output_names),
            x_op=plant.x0, u_op=plant.u0, rate=float(design.rate),
            form=getattr(design, "kalman_form", "current"), Kc=kc,
            tracked=tuple(design.tracked) if tracking else (), design=design,
        )

    def runtime(self, state_names: Sequence[str]) -> _LQGRuntime:
        """A Python controller doing the same as the compiled core (for checks)."""
        names = list(state_names)
        return _LQGRuntime(
            self, [names.index(o) for o in self.outputs], [names.index(o) for o in self.tracked]
        )

    def describe(self) -> dict[str, object]:
        return {"kind": self.kind, "form": self.form, "outputs": list(self.outputs),
                "rate": self.rate, "K": self.K.tolist(), "Kf": self.Kf.tolist(),
                "Ad": self.Ad.tolist(), "Bd": self.Bd.tolist(),
                "Kc": None if self.Kc is None else self.Kc.tolist(),
                "tracked": list(self.tracked)}


def _design_kc(design: Any) -> np.ndarray:
    kc = getattr(design, "Kc", None)
    if kc is None:
        note = getattr(design, "kc_note", "") or "the design has no reference gain"
        raise SimulationError(f"reference tracking needs K_c: {note}")
    return np.asarray(kc, dtype=float)


def _check_tracking(ctrl: Any, m: int) -> None:
    if ctrl.Kc is None:
        if ctrl.tracked:
            raise SimulationError("tracked outputs given without a reference gain K_c")
        return
    nr = len(ctrl.tracked)
    if nr == 0:
        raise SimulationError("a reference gain K_c needs the names of the tracked outputs")
    object.__setattr__(ctrl, "Kc", _frozen(np.reshape(ctrl.Kc, (m, nr)), (m, nr), "K_c"))
    object.__setattr__(ctrl, "tracked", tuple(ctrl.tracked))


BuiltIn = OpenLoop | StateFeedback | LQG


class _StateFeedbackRuntime:
    def __init__(self, ctrl: StateFeedback, names: tuple[str, ...], tracked_idx: list[int]) -> None:
        self.c = ctrl
        self.rate = ctrl.rate
        self.outputs = names
        self.tracked_idx = tracked_idx
        self.estimate = ctrl.x_op.copy()

    def reset(self) -> None:
        self.estimate = self.c.x_op.copy()

    def step(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        dx = np.asarray(y, dtype=float) - self.c.x_op
        self.estimate = self.c.x_op + dx
        du = -self.c.K @ dx
        if self.c.Kc is not None:
            du = du + self.c.Kc @ (np.asarray(r) - self.c.x_op[self.tracked_idx])
        return self.c.u_op + du


class _LQGRuntime:
    """The LQG controller in plain Python. It needs the input actually applied:
    the simulator calls :meth:`applied` after saturating (and delaying)."""

    def __init__(self, ctrl: LQG, out_idx: list[int], tracked_idx: list[int]) -> None:
        self.c = ctrl
        self.rate = ctrl.rate
        self.outputs = ctrl.outputs
        self.idx = out_idx
        self.tracked_idx = tracked_idx
        self.reset()

    def reset(self) -> None:
        self.z = _initial_estimate(self.c).copy()
        self.estimate = self.c.x_op + self.z
        self._y = np.zeros(len(self.idx))
        self._xhat = self.z.copy()

    def step(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        c = self.c
        dy = np.asarray(y, dtype=float) - c.x_op[self.idx]
        self._y = dy
        xhat = self.z + c.Kf @ (dy - self.z[self.idx]) if c.form == "current" else self.z.copy()
        self._xhat = xhat
        self.estimate = c.x_op + xhat
        du = -c.K @ xhat
        if c.Kc is not None:
            du = du + c.Kc @ (np.asarray(r) - c.x_op[self.tracked_idx])
        return c.u_op + du

    def applied(self, u: np.ndarray) -> None:
        c = self.c
        du = np.asarray(u, dtype=float) - c.u_op
        if c.form == "current":
            self.z = c.Ad @ self._xhat + c.Bd @ du
        else:
            self.z = c.Ad @ self.z + c.Bd @ du + c.Kf @ (self._y - self.z[self.idx])


def _initial_estimate(ctrl: LQG) -> np.ndarray:
    """``ctrl.x_hat0``, which ``LQG.__post_init__`` always fills in."""
    if ctrl.x_hat0 is None:
        raise SimulationError("the LQG controller has no initial estimate x_hat0")
    return ctrl.x_hat0


def as_controller(obj: object) -> BuiltIn | Controller:
    """A controller from a built-in, an object with ``step``, or a function ``(t, y, r)``."""
    if obj is None:
        return OpenLoop()
    if isinstance(obj, OpenLoop | StateFeedback | LQG):
        return obj
    if hasattr(obj, "step") and callable(obj.step):
        return obj
    if callable(obj):
        return _FunctionController(obj)
    hint = ""
    if hasattr(obj, "Kf") and hasattr(obj, "plant"):
        hint = " (for a design: LQG.from_design(design) or StateFeedback.from_design(design))"
    raise SimulationError(
        f"{type(obj).__name__} is not a controller: expected OpenLoop, StateFeedback, LQG, "
        f"an object with step(t, y, r), or a function (t, y, r) -> u{hint}"
    )


class _FunctionController:
    def __init__(self, fn: Callable[..., Any]) -> None:
        self.fn = fn

    def step(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        return np.asarray(self.fn(t, y, r), dtype=float)
