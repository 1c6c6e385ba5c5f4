"""Controllers the simulator runs: descriptions that become the one controller contract.

The simulator runs three kinds of controller (:mod:`equilibrist.control.controller`):
a :class:`~equilibrist.control.controller.LinearController` and a
:class:`~equilibrist.control.controller.NonlinearController` run compiled
(single runs and batches on all cores); a
:class:`~equilibrist.control.controller.PythonController` is called from
Python once per sample (batches in worker processes).

The descriptions here are the convenient ways to say which linear
controller: :class:`StateFeedback` (LQR), :class:`LQG` and
:class:`OpenLoop`. Each becomes a ``LinearController`` for the system it
runs on (:func:`as_controller`); nothing else in the simulator knows them.

All work in deviation coordinates about the operating point ``(x_op, u_op)``,
take absolute measurements and return absolute inputs. A user-written
controller follows the ``PythonController`` protocol (``reset``,
``output(t, y, r)``, ``update(t, y, r, u_applied)``, ``rate``, ``outputs``,
``estimate``); an object with the older ``step(t, y, r)`` (and optional
``reset``, ``applied``, ``estimate``, ``rate``, ``outputs``) or a plain
function ``(t, y, r) -> u`` still runs, through
:class:`~equilibrist.control.controller.StepAdapter`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import FrozenInstanceError, dataclass, replace
from typing import Any, Protocol, cast, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from equilibrist.control.checks import given_text, real_array
from equilibrist.control.controller import as_python_controller, python_controller_name
from equilibrist.control.design_record import Design
from equilibrist.control.linear import LinearController, LinearRuntime
from equilibrist.control.nonlinear import NonlinearController
from equilibrist.control.python_controller import PythonController, StepAdapter
from equilibrist.errors import ControllerError, DimensionError, EquilibristError, SimulationError
from equilibrist.numeric.linear import LinearModel
from equilibrist.numeric.system import System
from equilibrist.sim.signals import Signal, Value, as_signal

#: What an open loop's inputs follow (see :class:`OpenLoop`).
_InputSignal = Signal | Callable[[float], Value] | float | Sequence[float] | None
#: The plant a description was made a ``LinearController`` for: its state and input names.
_FormKey = tuple[tuple[str, ...], tuple[str, ...] | None]


@runtime_checkable
class Controller(Protocol):
    """The older step interface of a controller written in Python (see :class:`StepAdapter`)."""

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

    signal: _InputSignal = None

    kind = "none"

    def describe(self) -> dict[str, object]:
        sig = None if self.signal is None else as_signal(self.signal).describe()
        return {"kind": self.kind, "signal": sig}


class _Description:
    """What :class:`StateFeedback` and :class:`LQG` share: read-only, compared by identity,
    and built into their ``LinearController`` once per plant.

    A description holds either the arguments its user gave (``_given``, read-only float
    copies checked for shape) or the :class:`Design` it came from (``_given`` None), whose
    gains it reads; it has no numbers of its own.
    """

    kind = ""
    design: Design | None
    _given: dict[str, Any] | None
    _tracking: bool
    _forms: dict[_FormKey, LinearController]

    def _hold(self, given: dict[str, Any] | None, design: Design | None, *,
              tracking: bool = False) -> None:
        """Hold the user's arguments *given*, or (None) the *design* and whether it tracks."""
        held = {"_given": given, "design": design, "_tracking": tracking, "_forms": {}}
        for name, value in held.items():
            object.__setattr__(self, name, value)

    def __setattr__(self, name: str, value: object) -> None:
        raise FrozenInstanceError(f"cannot assign to field {name!r}")

    def __delattr__(self, name: str) -> None:
        raise FrozenInstanceError(f"cannot delete field {name!r}")

    def _source(self) -> Design:
        """The design the description reads (it was made by ``from_design``)."""
        assert self.design is not None
        return self.design

    def _read(self, key: str, of_design: Callable[[Design], Any]) -> Any:
        """The argument *key* the user gave, or what *of_design* reads of the design."""
        return of_design(self._source()) if self._given is None else self._given[key]

    @classmethod
    def _of_design(cls, design: Design, *, tracking: bool) -> Any:
        """A description that reads *design* (checked, and its reference gain with *tracking*)."""
        _check_design(design)
        if tracking:
            _design_kc(design)
        made = cls.__new__(cls)
        made._hold(None, design, tracking=tracking)
        return made

    def linear(self, state_names: Sequence[str], input_names: Sequence[str] | None = None
               ) -> LinearController:
        """This controller in the one linear form, for a plant with these states and inputs.

        Made from a design whose model extends the plant (:attr:`Design.extended`: a design
        for a delayed loop, whose controller holds the commands in flight), it is the
        design's own controller, :meth:`LinearController.from_design` (the one the ``lqr``
        and ``lqg`` kinds build), named for the plant it runs on."""
        key = (tuple(state_names), None if input_names is None else tuple(input_names))
        if key not in self._forms:
            self._forms[key] = (self._of_extended(state_names, input_names) if self._extended
                                else self._build(state_names, input_names))
        return self._forms[key]

    @property
    def _extended(self) -> bool:
        """Whether the description reads a design whose model extends the plant."""
        return self._given is None and self._source().extended

    def _of_extended(self, state_names: Sequence[str], input_names: Sequence[str] | None
                     ) -> LinearController:
        """:meth:`LinearController.from_design` of the design, named for the plant."""
        design = self._source()
        try:
            made = LinearController.from_design(design, kind=self.kind, tracking=self._tracking)
        except EquilibristError as exc:
            raise SimulationError(str(exc)) from exc
        states = tuple(state_names)
        inputs = made.input_names if input_names is None else tuple(input_names)
        if (states, inputs) == (made.state_names, made.input_names):
            return made
        try:
            return replace(made, state_names=states, input_names=inputs)
        except EquilibristError as exc:
            raise SimulationError(str(exc)) from exc

    def _build(self, state_names: Sequence[str], input_names: Sequence[str] | None
               ) -> LinearController:
        raise NotImplementedError

    def _described(self) -> dict[str, object]:
        """What a result records of a design whose model extends the plant: the linear form
        that runs, :meth:`LinearController.describe` (as the kinds record it; ``K``, ``Ad``,
        ``Kf`` of the extended model are the design's, not the controller's form)."""
        design = self._source()
        return self.linear(design.plant.state_names, design.plant.input_names).describe()

    def runtime(self, state_names: Sequence[str]) -> LinearRuntime:
        """A Python controller doing the same as the compiled core (for checks)."""
        return self.linear(state_names).runtime()

    def __repr__(self) -> str:
        if self._given is None:
            return f"{type(self).__name__}.from_design(<{self._source().system_key} design>, " \
                   f"tracking={self._tracking!r})"
        args = ", ".join(f"{k}={v!r}" for k, v in self._given.items())
        return f"{type(self).__name__}({args})"

    # -- what the user gave, or the design's --------------------------------------------------
    @property
    def x_op(self) -> np.ndarray:
        """The operating point's states (the design's plant's)."""
        return np.asarray(self._read("x_op", lambda d: d.plant.x0))

    @property
    def u_op(self) -> np.ndarray:
        """The operating point's inputs (the design's plant's)."""
        return np.asarray(self._read("u_op", lambda d: d.plant.u0))

    @property
    def K(self) -> np.ndarray:
        """The state-feedback gain (the design's: its discrete gain when it has a rate)."""
        return np.asarray(self._read("K", lambda d: d.K))

    @property
    def Kc(self) -> np.ndarray | None:
        """The reference gain, None without references (the design's when it tracks)."""
        kc = self._read("Kc", lambda d: _design_kc(d) if self._tracking else None)
        return None if kc is None else np.asarray(kc)

    @property
    def tracked(self) -> tuple[str, ...]:
        """The outputs ``Kc`` makes follow the reference."""
        return tuple(self._read("tracked", lambda d: d.tracked if self._tracking else ()))


class StateFeedback(_Description):
    """``u = u_op - K (x - x_op) + K_c (r - r_op)`` from the full (measured) state.

    ``K`` is applied at the simulation's sample rate with zero-order hold,
    whether it was designed in continuous time or for that rate.
    ``tracked`` names the outputs ``K_c`` makes follow the reference.

    A description: :meth:`linear` builds the one
    :class:`~equilibrist.control.linear.LinearController`
    (:meth:`~equilibrist.control.linear.LinearController.state_feedback`) for a plant.
    """

    kind = "lqr"

    def __init__(self, K: ArrayLike, x_op: ArrayLike, u_op: ArrayLike, Kc: ArrayLike | None = None,
                 tracked: Sequence[str] = (), rate: float | None = None,
                 design: Design | None = None) -> None:
        xo = _frozen(x_op, None, "x_op").reshape(-1)
        uo = _frozen(u_op, None, "u_op").reshape(-1)
        n, m = xo.size, uo.size
        kc, names = _tracking_args(Kc, tracked, m)
        self._hold({"K": _frozen(np.reshape(K, (m, n)), (m, n), "K"), "x_op": xo, "u_op": uo,
                    "Kc": kc, "tracked": names, "rate": rate}, design)

    @classmethod
    def from_design(cls, design: Design, *, tracking: bool = False) -> StateFeedback:
        """The design's gain (its discrete gain when it has a rate) and operating point."""
        return cast(StateFeedback, cls._of_design(design, tracking=tracking))

    @property
    def rate(self) -> float | None:
        """The rate the gain was designed for (the design's), None for a continuous gain."""
        return cast("float | None", self._read("rate", lambda d: d.rate))

    def _build(self, state_names: Sequence[str], input_names: Sequence[str] | None
               ) -> LinearController:
        return LinearController.state_feedback(
            self.K, x_op=self.x_op, u_op=self.u_op, state_names=state_names,
            input_names=input_names, Kc=self.Kc, tracked=self.tracked, rate=self.rate,
            design=self.design,
        )

    def describe(self) -> dict[str, object]:
        if self._extended:
            return self._described()
        kc = self.Kc
        return {"kind": self.kind, "K": self.K.tolist(),
                "Kc": None if kc is None else kc.tolist(),
                "tracked": list(self.tracked), "rate": self.rate}


class LQG(_Description):
    """Discrete Kalman filter on the measured ``outputs`` plus state feedback on its estimate.

    ``form`` "current": ``x_hat = x_pred + K_f (y - C x_pred)``, then
    ``u = u_op - K x_hat (+ K_c (r - r_op))`` and ``x_pred+ = A_d x_hat + B_d du``;
    "predictor": ``u`` from ``x_hat``, then
    ``x_hat+ = A_d x_hat + B_d du + K_f (y - C x_hat)``. ``du`` is the input
    actually applied (saturated, and delayed when the run delays). The filter
    starts at ``x_hat0`` (deviation; default the operating point).
    ``rate`` is the filter's sample rate, which the run must use.

    A description: :meth:`linear` builds the one
    :class:`~equilibrist.control.linear.LinearController`
    (:meth:`~equilibrist.control.linear.LinearController.lqg`) for a plant. Made by
    :meth:`from_design`, it holds the design and reads ``K``, ``A_d``, ``B_d`` and ``K_f``
    from it.
    """

    kind = "lqg"

    def __init__(self, K: ArrayLike, Ad: ArrayLike, Bd: ArrayLike, Kf: ArrayLike, outputs: Sequence[str],
                 x_op: ArrayLike, u_op: ArrayLike, rate: float, form: str = "current",
                 Kc: ArrayLike | None = None, tracked: Sequence[str] = (),
                 x_hat0: ArrayLike | None = None, design: Design | None = None) -> None:
        xo = _frozen(x_op, None, "x_op").reshape(-1)
        uo = _frozen(u_op, None, "u_op").reshape(-1)
        n, m, ny = xo.size, uo.size, len(outputs)
        given: dict[str, Any] = {
            "K": _frozen(np.reshape(K, (m, n)), (m, n), "K"),
            "Ad": _frozen(Ad, (n, n), "A_d"),
            "Bd": _frozen(np.reshape(Bd, (n, m)), (n, m), "B_d"),
            "Kf": _frozen(np.reshape(Kf, (n, ny)), (n, ny), "K_f"),
            "outputs": tuple(outputs), "x_op": xo, "u_op": uo,
        }
        given["x_hat0"] = None if x_hat0 is None else _frozen(x_hat0, (n,), "x_hat0")
        if form not in ("current", "predictor"):
            raise SimulationError(
                f"Kalman filter form {form!r}: expected 'current' or 'predictor'"
            )
        if not (np.isfinite(rate) and rate > 0):
            raise SimulationError(f"the filter's rate must be positive, got {rate!r}")
        given["Kc"], given["tracked"] = _tracking_args(Kc, tracked, m)
        given.update(rate=rate, form=form)
        self._hold(given, design)

    @classmethod
    def from_design(cls, design: Design, *, tracking: bool = False) -> LQG:
        """The design's discrete Kalman filter and gain (it needs a sample rate)."""
        _check_design(design)
        if design.discrete is None or design.rate is None:
            raise SimulationError(
                "an LQG controller needs a design with a sample rate (its discrete Kalman "
                "filter): design(system, rate=...)"
            )
        return cast(LQG, cls._of_design(design, tracking=tracking))

    def _discrete(self) -> LinearModel:
        disc = self._source().discrete
        assert disc is not None  # from_design refuses a continuous design
        return disc

    @property
    def Ad(self) -> np.ndarray:
        """The sampled plant's ``A`` (the design's discrete plant's)."""
        return np.asarray(self._read("Ad", lambda d: self._discrete().A))

    @property
    def Bd(self) -> np.ndarray:
        """The sampled plant's ``B`` (the design's discrete plant's)."""
        return np.asarray(self._read("Bd", lambda d: self._discrete().B))

    @property
    def Kf(self) -> np.ndarray:
        """The Kalman gain (``M`` in the current form, ``L`` in the predictor form)."""
        return np.asarray(self._read("Kf", lambda d: d.Kf))

    @property
    def outputs(self) -> tuple[str, ...]:
        """The measured states, in the order of ``y``."""
        return tuple(self._read("outputs", lambda d: d.plant.output_names))

    @property
    def rate(self) -> float:
        """The filter's sample rate [Hz] (the design's; from_design refuses a design without)."""
        return cast(float, self._read("rate", lambda d: float(cast(float, d.rate))))

    @property
    def form(self) -> str:
        """``"current"`` or ``"predictor"`` (the design's Kalman form)."""
        return cast(str, self._read("form", lambda d: d.kalman_form))

    @property
    def x_hat0(self) -> np.ndarray | None:
        """The filter's starting estimate (deviation) the user gave; None: the operating point."""
        return cast("np.ndarray | None", self._read("x_hat0", lambda d: None))

    def _build(self, state_names: Sequence[str], input_names: Sequence[str] | None
               ) -> LinearController:
        try:
            return LinearController.lqg(
                self.K, Ad=self.Ad, Bd=self.Bd, Kf=self.Kf, outputs=self.outputs,
                x_op=self.x_op, u_op=self.u_op, rate=self.rate, form=self.form,
                state_names=state_names, input_names=input_names, Kc=self.Kc,
                tracked=self.tracked, x_hat0=self.x_hat0, design=self.design,
            )
        except EquilibristError as exc:
            raise SimulationError(str(exc)) from exc

    def describe(self) -> dict[str, object]:
        if self._extended:
            return self._described()
        kc = self.Kc
        return {"kind": self.kind, "form": self.form, "outputs": list(self.outputs),
                "rate": self.rate, "K": self.K.tolist(), "Kf": self.Kf.tolist(),
                "Ad": self.Ad.tolist(), "Bd": self.Bd.tolist(),
                "Kc": None if kc is None else kc.tolist(),
                "tracked": list(self.tracked)}


def _check_design(design: object) -> None:
    if not isinstance(design, Design):
        raise SimulationError(f"design: expected a Design (equilibrist.control.design.design), "
                              f"got {type(design).__name__}")


def _design_kc(design: Design) -> np.ndarray:
    kc = design.Kc
    if kc is None:
        note = design.kc_note or "the design has no reference gain"
        raise SimulationError(f"reference tracking needs K_c: {note}")
    return np.asarray(kc, dtype=float)


def _tracking_args(Kc: ArrayLike | None, tracked: Sequence[str], m: int
                   ) -> tuple[np.ndarray | None, tuple[str, ...]]:
    """The reference gain and tracked outputs a user gave, checked (``K_c`` read-only)."""
    if Kc is None:
        if tracked:
            raise SimulationError("tracked outputs given without a reference gain K_c")
        return None, tuple(tracked)
    nr = len(tracked)
    if nr == 0:
        raise SimulationError("a reference gain K_c needs the names of the tracked outputs")
    return _frozen(np.reshape(Kc, (m, nr)), (m, nr), "K_c"), tuple(tracked)


BuiltIn = OpenLoop | StateFeedback | LQG


@dataclass(frozen=True, eq=False)
class Resolved:
    """A controller as the simulator runs it.

    ``controller`` is the contract's value; ``signal`` the open-loop input
    (None: none); ``description`` what the result records.
    """

    controller: LinearController | NonlinearController | PythonController
    signal: _InputSignal
    description: dict[str, object]

    @property
    def compiled(self) -> bool:
        return isinstance(self.controller, LinearController | NonlinearController)


def as_controller(obj: object, system: System | None = None,
                  x_op: np.ndarray | None = None, u_op: np.ndarray | None = None) -> Resolved:
    """What the simulator runs for *obj* on *system* (with its operating point *x_op*, *u_op*).

    None and :class:`OpenLoop` become the open loop at the operating
    point, :class:`StateFeedback` and :class:`LQG` their
    ``LinearController``, a contract value itself, and anything else a
    ``PythonController`` (directly, or through the step adapter).
    """
    if obj is None:
        obj = OpenLoop()
    if isinstance(obj, OpenLoop):
        if system is None or x_op is None or u_op is None:
            raise SimulationError("an open loop needs the system and its operating point")
        lin = LinearController.open_loop(x_op=x_op, u_op=u_op, state_names=system.state_names,
                                         input_names=system.input_names)
        return Resolved(lin, obj.signal, obj.describe())
    if isinstance(obj, StateFeedback | LQG):
        names = system.state_names if system is not None else tuple(f"x{i}" for i in range(obj.x_op.size))
        inputs = system.input_names if system is not None else None
        if len(names) != obj.x_op.size or (inputs is not None and len(inputs) != obj.u_op.size):
            raise SimulationError(
                f"the controller is for {obj.x_op.size} states and {obj.u_op.size} inputs; "
                f"{system.key if system is not None else 'the system'} has {len(names)} and "
                f"{len(inputs or ())}"
            )
        return Resolved(obj.linear(names, inputs), None, obj.describe())
    if isinstance(obj, LinearController | NonlinearController):
        return Resolved(obj, None, obj.describe())
    try:
        py = as_python_controller(obj)
    except ControllerError as exc:
        hint = ""
        if hasattr(obj, "Kf") and hasattr(obj, "plant"):
            hint = (" (for a design: LinearController.from_design(design), LQG.from_design(design) "
                    "or StateFeedback.from_design(design))")
        raise SimulationError(f"{exc}{hint}") from exc
    name = python_controller_name(py)
    if isinstance(py, StepAdapter):
        if not isinstance(py._step, _CheckedCommand):  # checked before the adapter converts it
            py._step = _CheckedCommand(py._step, name)
        return Resolved(py, None, {"kind": "python", "name": name})
    return Resolved(_CheckedOutput(py, name), None, {"kind": "python", "name": name})


def _command(raw: object, name: str, t: float) -> np.ndarray:
    """What a Python controller returned, as real numbers, or one line naming it."""
    u, held = real_array(raw)
    if u is None:
        raise SimulationError(
            f"the controller {name} returned {given_text(raw)} at t = {t:g} s, which holds {held}: "
            "expected its inputs as real numbers (a float array, one value per input)"
        )
    return u


class _CheckedCommand:
    """A user's ``step(t, y, r)`` (or function) whose command is checked to be real numbers."""

    def __init__(self, call: Callable[[float, np.ndarray, np.ndarray], object],
                 name: str) -> None:
        self.call = call
        self.name = name

    def __call__(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        return _command(self.call(t, y, r), self.name, t)


class _CheckedOutput(StepAdapter):
    """A :class:`PythonController` whose command is checked to be real numbers.

    Everything else is the user's controller's own (``target``, which the
    run's state, such as an MPC's solve times, stays on); a step adapter only
    in type, so that the controller is named as the user's.
    """

    def __init__(self, py: PythonController, name: str) -> None:  # no adapter of a step
        self.target = py
        self.name = name
        self.rate = py.rate
        self.outputs = py.outputs
        self.estimate = py.estimate

    def reset(self) -> None:
        self.target.reset()
        self.estimate = self.target.estimate

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        u = _command(self.target.output(t, y, r), self.name, t)
        self.estimate = self.target.estimate
        return u

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        self.target.update(t, y, r, u_applied)
        self.estimate = self.target.estimate
