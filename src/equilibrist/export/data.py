"""What an exported controller is made of: the numbers and names of a digital controller.

:class:`ControllerData` is a view of the one controller value the
simulation runs, a :class:`~equilibrist.control.linear.LinearController`
made by its design (:func:`of_controller`, or :func:`from_design` from the
design), checked for what the generated C code needs: sizes, finite values,
input limits around the operating input. Everything downstream (the C
text, the test vectors, the ctypes wrapper, the hardware-in-the-loop
files) reads it, so the numbers that ship are the numbers that were
simulated.

The controller is the one the simulation core runs: the design's
:class:`~equilibrist.control.controller.LinearController` (``linear``), one
state-space form that the C code runs with one fixed step function
(:mod:`equilibrist.native.linear_c`). In deviation coordinates about the
operating point ``(x0, u0)``, with ``z`` the carried prediction
``xhat_{k|k-1}``, it is:

``lqg``, ``current`` Kalman form::

    xhat = z + Kf (dy - C z)                  dy = y - y0
    u    = u0 - K xhat + Kc (r - r0)          then saturated to [u_min, u_max]
    z    = Ad xhat + Bd (u - u0)              with the saturated u

``lqg``, ``predictor`` form::

    xhat = z
    u    = u0 - K xhat + Kc (r - r0)          saturated
    z    = Ad z + Bd (u - u0) + Kf (dy - C z)

``lqr`` (full state measured)::

    u    = u0 - K (x - x0) + Kc (r - r0)      saturated
"""

from __future__ import annotations

import hashlib
import math
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import PurePath

import numpy as np

from equilibrist.control.design_record import Design
from equilibrist.control.linear import LinearController
from equilibrist.errors import EquilibristError, ExportError

CONTROLLERS = ("lqg", "lqr")
PRECISIONS = ("double", "float")
FORMS = ("current", "predictor")

# Largest magnitude a constant may have in single precision.
_FLOAT_MAX = float(np.finfo(np.float32).max)


def check_controller(controller: str) -> str:
    """Return *controller* if it is ``"lqg"`` or ``"lqr"``, else raise :class:`ExportError`."""
    if controller not in CONTROLLERS:
        raise ExportError(
            f"controller {controller!r} is unknown: expected one of {', '.join(CONTROLLERS)}"
        )
    return controller


def check_precision(precision: str) -> str:
    """Return *precision* if it is ``"double"`` or ``"float"``, else raise :class:`ExportError`."""
    if precision not in PRECISIONS:
        raise ExportError(
            f"precision {precision!r} is unknown: expected one of {', '.join(PRECISIONS)}"
        )
    return precision


def c_identifier(text: str) -> str:
    """*text* made into a lower-case C identifier (``gyroscope[euler=xyz]`` -> ``gyroscope_euler_xyz``).

    A system file's key (its path) gives the file's own name
    (``/home/me/robots/furuta.xml`` -> ``furuta``).
    """
    from equilibrist.systems.files import looks_like_path

    if looks_like_path(text):
        text = PurePath(text).stem
    ident = re.sub(r"[^0-9A-Za-z]+", "_", text).strip("_").lower()
    if not ident:
        ident = "controller"
    if ident[0].isdigit():
        ident = "c_" + ident
    return ident


@dataclass(frozen=True, eq=False)
class ControllerData:
    """A digital controller ready to be written as C: the one linear controller the
    simulation runs (:attr:`linear`, made by its design) and what the C text adds to it
    (units, the design's parameters, weights and settings, for the record).

    Every number is read from :attr:`linear` (and, for what the header documents but
    the step does not run, the plant and gains of the design it carries): this is a
    view of the controller, not a second record of it. Sizes: ``n`` states, ``m``
    inputs, ``p`` measurements (the full state without a Kalman filter), ``nr``
    references (``m`` when the design has a reference gain, else 0).

    Attributes
    ----------
    linear:
        The controller (what the C step runs), with its discrete design.
    system:
        The system's key (``cartpole``).
    state_units, input_units:
        Units of the states and inputs (``""`` where unknown).
    params:
        The system's parameter values the design was made with.
    weights:
        The design weights (``Q``, ``R``, ``QN``, ``RN``, ``G``) for the record.
    settings:
        The generating settings (rate, discretization, Kalman form, ...).
    """

    linear: LinearController
    system: str
    state_units: tuple[str, ...]
    input_units: tuple[str, ...]
    params: Mapping[str, float] = field(default_factory=dict)
    weights: Mapping[str, np.ndarray] = field(default_factory=dict)
    settings: Mapping[str, str] = field(default_factory=dict)

    @property
    def design(self) -> Design:
        """The discrete design :attr:`linear` was made from (:func:`of_controller` checks it)."""
        design = self.linear.design
        if design is None or design.discrete is None or design.dt is None:
            raise ExportError("the controller has no discrete design to export")
        return design

    @property
    def controller(self) -> str:
        """The controller's form as :meth:`LinearController.from_design` names it (``"lqg"``,
        ``"lqr"``): the library's name and C prefix end with it."""
        return self.linear.kind

    @property
    def form(self) -> str:
        """The Kalman form (``"current"``, ``"predictor"``), ``""`` without a Kalman filter."""
        return self.linear.form

    @property
    def filtered(self) -> bool:
        """Whether a Kalman filter estimates the state from the measurements."""
        return bool(self.linear.form)

    @property
    def dt(self) -> float:
        """Sample period [s]."""
        return float(self.design.dt)  # type: ignore[arg-type]  # checked by design

    @property
    def state_names(self) -> tuple[str, ...]:
        return self.linear.state_names

    @property
    def input_names(self) -> tuple[str, ...]:
        return self.linear.input_names

    @property
    def measured_names(self) -> tuple[str, ...]:
        return self.linear.output_names

    @property
    def tracked_names(self) -> tuple[str, ...]:
        return self.linear.tracked_names

    @property
    def measured_units(self) -> tuple[str, ...]:
        return tuple(self.state_units[i] for i in self.measured_index)

    @property
    def x0(self) -> np.ndarray:
        """Operating state (absolute)."""
        return self.linear.x_op

    @property
    def u0(self) -> np.ndarray:
        """Operating input (absolute)."""
        return self.linear.u_op

    @property
    def y0(self) -> np.ndarray:
        """Measurements at the operating point."""
        return _readonly(self.C @ self.x0)

    @property
    def r0(self) -> np.ndarray:
        """Tracked outputs at the operating point."""
        return self.linear.r_op

    @property
    def Ad(self) -> np.ndarray:
        """The design's discrete plant matrix."""
        return _readonly(np.array(self.design.discrete.A, dtype=float))  # type: ignore[union-attr]

    @property
    def Bd(self) -> np.ndarray:
        """The design's discrete input matrix."""
        return _readonly(np.array(self.design.discrete.B, dtype=float))  # type: ignore[union-attr]

    @property
    def C(self) -> np.ndarray:
        """The measurement matrix: a selection of the states."""
        return _readonly(np.eye(self.n_states)[list(self.measured_index)].reshape(
            self.n_measured, self.n_states))

    @property
    def K(self) -> np.ndarray:
        """The state feedback (``m x n``) of the design."""
        return _readonly(np.array(self.design.K, dtype=float))

    @property
    def Kf(self) -> np.ndarray:
        """The Kalman filter's gain (``n x p``; zero-sized without a filter)."""
        if not self.filtered:
            return _readonly(np.zeros((self.n_states, 0)))
        return _readonly(np.array(self.design.Kf, dtype=float))

    @property
    def Kc(self) -> np.ndarray:
        """The reference gain (``m x nr``): the controller's ``Dr``."""
        return self.linear.Dr

    @property
    def u_min(self) -> np.ndarray:
        return _limit(self.linear.u_min)

    @property
    def u_max(self) -> np.ndarray:
        return _limit(self.linear.u_max)

    @property
    def n_z(self) -> int:
        """States of the controller (the Kalman prediction; 0 for LQR)."""
        return self.linear.n_z

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        return len(self.input_names)

    @property
    def n_measured(self) -> int:
        return len(self.measured_names)

    @property
    def n_references(self) -> int:
        return len(self.tracked_names)

    @property
    def rate(self) -> float:
        """Sample rate [Hz]."""
        return 1.0 / self.dt

    @property
    def measured_index(self) -> tuple[int, ...]:
        """Index of the state each measurement reads."""
        return tuple(self.state_names.index(o) for o in self.measured_names)

    @property
    def name(self) -> str:
        """The library's name and C prefix (``cartpole_lqg``)."""
        return f"{c_identifier(self.system)}_{self.controller}"

    @property
    def fingerprint(self) -> str:
        """12 hex digits identifying the controller's numbers and names."""
        h = hashlib.sha256()
        for label in ("controller", "form", "system"):
            h.update(str(getattr(self, label)).encode())
        for names in (self.state_names, self.input_names, self.measured_names, self.tracked_names):
            h.update(",".join(names).encode() + b";")
        h.update(np.float64(self.dt).tobytes())
        for arr in (self.x0, self.u0, self.y0, self.r0, self.Ad, self.Bd, self.C, self.K,
                    self.Kf, self.Kc, self.u_min, self.u_max):
            h.update(np.ascontiguousarray(arr, dtype=np.float64).tobytes())
        return h.hexdigest()[:12]


def _readonly(arr: np.ndarray) -> np.ndarray:
    arr.setflags(write=False)
    return arr


def _limit(arr: np.ndarray | None) -> np.ndarray:
    if arr is None:  # LinearController fills its limits in
        raise ExportError("the controller has no input limits")
    return arr


def _array(value: object, name: str, shape: tuple[int, ...], problems: list[str]) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        problems.append(f"{name} is not numeric")
        return np.zeros(shape)
    if arr.size == 0 and int(np.prod(shape)) == 0:
        return arr.reshape(shape)
    if arr.shape != shape:
        problems.append(f"{name} has shape {arr.shape}, expected {shape}")
        return np.zeros(shape)
    if not np.all(np.isfinite(arr)):
        problems.append(f"{name} has a value that is not a finite number")
    elif arr.size and float(np.max(np.abs(arr))) > _FLOAT_MAX:
        problems.append(f"{name} has a value beyond the range of single precision")
    arr.setflags(write=False)
    return arr


def _units(names: tuple[str, ...], default: tuple[str, ...]) -> tuple[str, ...]:
    if default and len(default) == len(names):
        return tuple(default)
    return tuple("" for _ in names)


def from_design(design: Design, *, controller: str = "lqg") -> ControllerData:
    """The :class:`ControllerData` of a design's controller.

    Parameters
    ----------
    design:
        A control-layer ``Design``: its controller (with its reference gain when it has
        one) is :meth:`LinearController.from_design`'s, limited to the parameters'
        input limits.
    controller:
        ``"lqg"`` (measurements through the Kalman filter) or ``"lqr"``
        (the full state measured, no estimator).

    Raises
    ------
    ExportError
        A system without an input, an unknown controller, a design whose
        matrices are not finite or not of matching sizes, an operating
        input outside the input limits. Every problem is named at once.
    """
    check_controller(controller)
    _check_digital(design)
    problems = _design_problems(design)
    if problems:
        raise ExportError(f"cannot export the {controller} controller of {design.system_key}: "
                          + "; ".join(problems))
    params = dict(design.params)
    names = design.plant.input_names
    try:
        linear = LinearController.from_design(
            design, kind=controller, tracking=design.Kc is not None,
            u_min=[float(params.get(f"{i}_min", -math.inf)) for i in names],
            u_max=[float(params.get(f"{i}_max", math.inf)) for i in names])
    except EquilibristError as exc:
        raise ExportError(f"cannot export the {controller} controller of "
                          f"{design.system_key}: {exc}") from exc
    return of_controller(linear)


def of_controller(linear: LinearController) -> ControllerData:
    """The :class:`ControllerData` of *linear*, a controller its discrete design made
    (:meth:`LinearController.from_design`): the view the C library is written from.

    Raises
    ------
    ExportError
        A controller without a discrete design, or anything :func:`from_design` refuses.
    """
    design = linear.design
    if not isinstance(design, Design):
        raise ExportError(f"the {linear.kind} controller has no design: its library is "
                          "written from the design that made it")
    _check_digital(design)
    system = design.system_key
    problems = _design_problems(design) + _controller_problems(linear, design)
    if problems:
        raise ExportError(f"cannot export the {linear.kind} controller of {system}: "
                          + "; ".join(problems))
    plant = design.plant
    return ControllerData(
        linear=linear, system=system,
        state_units=_units(linear.state_names, tuple(plant.state_units)),
        input_units=_units(linear.input_names, tuple(plant.input_units)),
        params=dict(design.params), weights=_weights(design, filtered=bool(linear.form)),
        settings=_settings(design, linear))


def _check_digital(design: Design) -> None:
    """A design with an input and a sample rate, or an :class:`ExportError`."""
    if not design.plant.input_names:
        raise ExportError(f"{design.system_key} has no input: there is no controller to export")
    if design.discrete is None or design.dt is None:
        raise ExportError(f"the design of {design.system_key} is continuous: export needs a "
                          "digital design (a rate)")


def _design_problems(design: Design) -> list[str]:
    """What in *design*'s numbers the C code cannot hold: every problem, in words."""
    plant, discrete = design.plant, design.discrete
    assert discrete is not None  # _check_digital
    n, m = len(plant.state_names), len(plant.input_names)
    problems: list[str] = []
    dt = float(design.dt or 0.0)
    if not (math.isfinite(dt) and dt > 0):
        problems.append(f"the sample period {dt!r} s is not a positive number")
    _array(plant.x0, "x0", (n,), problems)
    u0 = _array(plant.u0, "u0", (m,), problems)
    _array(discrete.A, "Ad", (n, n), problems)
    _array(discrete.B, "Bd", (n, m), problems)
    _array(design.K, "K", (m, n), problems)
    if design.Kc is not None:
        tracked = tuple(design.tracked)
        _array(design.Kc, "Kc", (m, len(tracked)), problems)
        if len(tracked) != m:
            problems.append(f"{len(tracked)} tracked outputs for {m} inputs")
        problems += [f"tracked output {t!r} is not a state of {design.system_key}"
                     for t in tracked if t not in plant.state_names]
    params = dict(design.params)
    for i, name in enumerate(plant.input_names):
        low = float(params.get(f"{name}_min", -math.inf))
        high = float(params.get(f"{name}_max", math.inf))
        if not (math.isfinite(low) and math.isfinite(high)):
            problems.append(f"input {name} has no finite limits {name}_min, {name}_max")
        elif not low <= u0[i] <= high:
            problems.append(f"the operating input {name} = {u0[i]:g} is outside its limits "
                            f"[{low:g}, {high:g}]")
    return problems


def _controller_problems(linear: LinearController, design: Design) -> list[str]:
    """What the C library cannot run of *linear*: a Kalman filter's gain, its measurements."""
    problems: list[str] = []
    if linear.n_z and not linear.form:
        problems.append("a controller with a state of its own that is no Kalman filter")
    if not linear.form:
        return problems
    if linear.form not in FORMS:
        problems.append(f"Kalman form {linear.form!r} is unknown: expected one of "
                        f"{', '.join(FORMS)}")
    discrete = design.discrete
    assert discrete is not None  # _check_digital
    n, p = linear.n_states, linear.n_outputs
    C = _array(discrete.C, "C", (p, n), problems)
    _array(design.Kf, "Kf", (n, p), problems)
    D = np.asarray(discrete.D, dtype=float)
    if D.size and np.any(D != 0):
        problems.append("the measurements depend on the input (D != 0): not supported")
    if p == 0:
        problems.append("the design measures no output: an LQG controller needs measurements")
    if not all(np.count_nonzero(row) == 1 and float(np.max(row)) == 1.0 for row in C):
        problems.append("C is not a selection of states (each measurement one state)")
    return problems


def _weights(design: Design, *, filtered: bool) -> dict[str, np.ndarray]:
    """The design's weights for the record: the noise intensities only with a filter."""
    labels = ("Q", "R", "QN", "RN", "G") if filtered else ("Q", "R")
    return {label: np.asarray(getattr(design, label), dtype=float) for label in labels}


def _settings(design: Design, linear: LinearController) -> dict[str, str]:
    """The generating settings the library's header and README record."""
    rate = float(design.rate) if design.rate else 1.0 / float(design.dt or 1.0)
    settings = {"system": design.system_key, "controller": linear.kind,
                "rate": f"{rate:.12g} Hz", "discretization": design.discretization}
    if linear.form:
        settings["kalman_form"] = linear.form
    tracked = linear.tracked_names
    settings["reference"] = ", ".join(tracked) if tracked else "none"
    return settings


def controller_data(design: Design | object, *, controller: str = "lqg") -> ControllerData:
    """:func:`~equilibrist.export.data.from_design` for a discrete design.

    Raises
    ------
    ExportError
        A continuous design (no rate), or anything :func:`from_design` refuses.
    """
    check_controller(controller)
    if not isinstance(design, Design):
        raise ExportError(f"design = {design!r}: expected a Design (equilibrist.control.design."
                          f"design(system, rate=...)), not {type(design).__name__}")
    if design.discrete is None or not design.rate:
        raise ExportError(
            f"the design of {design.system_key} is continuous: "
            "a digital controller needs a sample rate (design it with rate=...)"
        )
    return from_design(design, controller=controller)
