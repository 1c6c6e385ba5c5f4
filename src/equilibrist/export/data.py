"""What an exported controller is made of: the numbers and names of a digital controller.

:class:`ControllerData` is taken from a design (the control layer's
``Design``) and holds exactly what the generated C code needs, already
checked: sizes, finite values, input limits around the operating input.
Everything downstream (the C text, the test vectors, the ctypes wrapper)
reads this one object, so the numbers that ship are the numbers that were
simulated.

The controller is the one the simulation core runs: the design's
:class:`~equilibrist.control.controller.LinearController` (``linear``), one
state-space form that the C code runs with one fixed step function
(:mod:`equilibrist.control.linear_c`). In deviation coordinates about the
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
    """A digital controller ready to be written as C.

    All matrices are float64 arrays; vectors are 1-D. Sizes: ``n`` states,
    ``m`` inputs, ``p`` measurements (the full state for ``lqr``), ``nr``
    references (``m`` when the design has a reference gain, else 0).

    Attributes
    ----------
    system:
        The system's key (``cartpole``).
    controller:
        ``"lqg"`` or ``"lqr"``.
    form:
        Kalman form ``"current"`` or ``"predictor"`` (``lqg``); ``""`` for ``lqr``.
    dt:
        Sample period [s].
    x0, u0:
        Operating point (absolute state and input).
    y0, r0:
        Measurements and tracked outputs at the operating point.
    Ad, Bd, C:
        Discrete plant and measurement matrix (``C`` selects the measured states).
    K, Kf, Kc:
        State feedback (``m x n``), estimator gain (``n x p``, zero-sized for
        ``lqr``), reference gain (``m x nr``).
    u_min, u_max:
        Input limits the controller saturates to.
    params:
        The system's parameter values the design was made with.
    weights:
        The design weights (``Q``, ``R``, ``QN``, ``RN``, ``G``) for the record.
    settings:
        The generating settings (rate, discretization, Kalman form, ...).
    linear:
        The controller as the one linear form (what the C step runs).
    """

    system: str
    controller: str
    form: str
    dt: float
    state_names: tuple[str, ...]
    state_units: tuple[str, ...]
    input_names: tuple[str, ...]
    input_units: tuple[str, ...]
    measured_names: tuple[str, ...]
    measured_units: tuple[str, ...]
    tracked_names: tuple[str, ...]
    x0: np.ndarray
    u0: np.ndarray
    y0: np.ndarray
    r0: np.ndarray
    Ad: np.ndarray
    Bd: np.ndarray
    C: np.ndarray
    K: np.ndarray
    Kf: np.ndarray
    Kc: np.ndarray
    u_min: np.ndarray
    u_max: np.ndarray
    params: Mapping[str, float] = field(default_factory=dict)
    weights: Mapping[str, np.ndarray] = field(default_factory=dict)
    settings: Mapping[str, str] = field(default_factory=dict)
    linear: LinearController | None = field(default=None, repr=False)

    @property
    def form_controller(self) -> LinearController:
        """:attr:`linear`, which :func:`from_design` always fills in."""
        if self.linear is None:
            raise ExportError("the controller data has no linear form")
        return self.linear

    @property
    def n_z(self) -> int:
        """States of the controller (the Kalman prediction; 0 for LQR)."""
        return self.form_controller.n_z

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
        """Index of the state each measurement reads (``C`` is a selection matrix)."""
        return tuple(int(np.argmax(np.abs(row))) for row in self.C)

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
    """The :class:`ControllerData` of a design.

    Parameters
    ----------
    design:
        A control-layer ``Design`` (``equilibrist.control``): its discrete
        plant, gains, operating point, weights and settings are read.
    controller:
        ``"lqg"`` (measurements through the Kalman filter) or ``"lqr"``
        (the full state measured, no estimator).

    Returns
    -------
    ControllerData

    Raises
    ------
    ExportError
        A system without an input, an unknown controller, a design whose
        matrices are not finite or not of matching sizes, an operating
        input outside the input limits. Every problem is named at once.
    """
    check_controller(controller)
    plant = design.plant
    discrete = design.discrete
    system = design.system_key
    state_names = tuple(plant.state_names)
    input_names = tuple(plant.input_names)
    n, m = len(state_names), len(input_names)
    if m == 0:
        raise ExportError(f"{system} has no input: there is no controller to export")
    problems: list[str] = []
    if discrete is None or design.dt is None:
        raise ExportError(f"the design of {system} is continuous: export needs a digital design (a rate)")
    params = dict(design.params)
    state_units = _units(state_names, tuple(plant.state_units))
    input_units = _units(input_names, tuple(plant.input_units))
    dt = float(design.dt)
    if not (math.isfinite(dt) and dt > 0):
        problems.append(f"the sample period {dt!r} s is not a positive number")
    x0 = _array(plant.x0, "x0", (n,), problems)
    u0 = _array(plant.u0, "u0", (m,), problems)
    Ad = _array(discrete.A, "Ad", (n, n), problems)
    Bd = _array(discrete.B, "Bd", (n, m), problems)
    K = _array(design.K, "K", (m, n), problems)

    if controller == "lqg":
        form = design.kalman_form
        if form not in FORMS:
            problems.append(f"Kalman form {form!r} is unknown: expected one of {', '.join(FORMS)}")
        measured = tuple(discrete.output_names)
        p = len(measured)
        C = _array(discrete.C, "C", (p, n), problems)
        Kf = _array(design.Kf, "Kf", (n, p), problems)
        D = np.asarray(discrete.D, dtype=float)
        if D.size and np.any(D != 0):
            problems.append("the measurements depend on the input (D != 0): not supported")
        if p == 0:
            problems.append("the design measures no output: an LQG controller needs measurements")
    else:
        form = ""
        measured = state_names
        C = np.eye(n)
        C.setflags(write=False)
        Kf = np.zeros((n, 0))
        Kf.setflags(write=False)
    selection = all(
        np.count_nonzero(row) == 1 and float(np.max(row)) == 1.0 for row in np.asarray(C)
    )
    if not selection:
        problems.append("C is not a selection of states (each measurement one state)")
    measured_units = tuple(
        state_units[int(np.argmax(row))] if selection else "" for row in np.asarray(C)
    )

    Kc_raw = design.Kc
    tracked = tuple(design.tracked) if Kc_raw is not None else ()
    if Kc_raw is None:
        Kc = np.zeros((m, 0))
        r0 = np.zeros(0)
    else:
        Kc = _array(Kc_raw, "Kc", (m, len(tracked)), problems)
        if len(tracked) != m:
            problems.append(f"{len(tracked)} tracked outputs for {m} inputs")
        rows = []
        for t in tracked:
            if t not in state_names:
                problems.append(f"tracked output {t!r} is not a state of {system}")
            else:
                rows.append(state_names.index(t))
        r0 = np.asarray(x0)[rows] if len(rows) == len(tracked) else np.zeros(len(tracked))
    u_min = np.array([float(params.get(f"{i}_min", -math.inf)) for i in input_names])
    u_max = np.array([float(params.get(f"{i}_max", math.inf)) for i in input_names])
    for i, name in enumerate(input_names):
        if not (math.isfinite(u_min[i]) and math.isfinite(u_max[i])):
            problems.append(f"input {name} has no finite limits {name}_min, {name}_max")
        elif not u_min[i] <= u0[i] <= u_max[i]:
            problems.append(
                f"the operating input {name} = {u0[i]:g} is outside its limits "
                f"[{u_min[i]:g}, {u_max[i]:g}]"
            )
    if problems:
        raise ExportError(f"cannot export the {controller} controller of {system}: " + "; ".join(problems))

    y0 = np.asarray(C) @ np.asarray(x0)
    weights = {label: np.asarray(value, dtype=float) for label, value in
               (("Q", design.Q), ("R", design.R), ("QN", design.QN), ("RN", design.RN), ("G", design.G))}
    if controller == "lqr":
        weights = {k: v for k, v in weights.items() if k in ("Q", "R")}
    rate = float(design.rate) if design.rate else 1.0 / dt
    settings = {
        "system": system,
        "controller": controller,
        "rate": f"{rate:.12g} Hz",
        "discretization": design.discretization,
    }
    if controller == "lqg":
        settings["kalman_form"] = form
    settings["reference"] = ", ".join(tracked) if tracked else "none"
    for arr in (y0, r0, u_min, u_max):
        arr.setflags(write=False)
    try:
        linear = LinearController.from_design(design, kind=controller, tracking=bool(tracked),
                                              u_min=u_min, u_max=u_max)
    except EquilibristError as exc:
        raise ExportError(f"cannot export the {controller} controller of {system}: {exc}") from exc
    return ControllerData(
        system=system,
        controller=controller,
        form=form,
        dt=dt,
        state_names=state_names,
        state_units=state_units,
        input_names=input_names,
        input_units=input_units,
        measured_names=measured,
        measured_units=measured_units,
        tracked_names=tracked,
        x0=x0,
        u0=u0,
        y0=y0,
        r0=np.asarray(r0, dtype=float),
        Ad=Ad,
        Bd=Bd,
        C=np.asarray(C, dtype=float),
        K=K,
        Kf=np.asarray(Kf, dtype=float),
        Kc=np.asarray(Kc, dtype=float),
        u_min=u_min,
        u_max=u_max,
        params=params,
        weights=weights,
        settings=settings,
        linear=linear,
    )


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
