"""What an exported linear controller is made of, checked.

:func:`of_controller` makes the :class:`~equilibrist.native.linear_c.ControllerData` the C
library is written from out of the one controller value the simulation runs, a
:class:`~equilibrist.control.linear.LinearController` made by its design
(:func:`controller_data`), checked for what the generated C code needs: sizes, finite values,
input limits around the operating input. The numbers that ship are the numbers that were
simulated; the library's header states its equations (LQR, or LQG in the ``current`` or
``predictor`` Kalman form).
"""

from __future__ import annotations

import math

import numpy as np

from equilibrist.control.design_record import Design
from equilibrist.control.linear import LinearController
from equilibrist.errors import EquilibristError, ExportError
from equilibrist.native.linear_c import ControllerData, deviation_vector

CONTROLLERS = ("lqg", "lqr")
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


def of_controller(linear: LinearController) -> ControllerData:
    """The :class:`ControllerData` of *linear*, a controller its discrete design made
    (:meth:`LinearController.from_design`): the view the C library is written from.

    Raises
    ------
    ExportError
        A controller without a discrete design, or anything :func:`checked_linear` refuses.
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
    plant, discrete = design.plant, design.discrete
    assert discrete is not None  # _check_digital
    n = linear.n_states
    return ControllerData(
        system=system, controller=linear.kind, form=linear.form, dt=float(design.dt or 0.0),
        state_names=linear.state_names, input_names=linear.input_names,
        measured_names=linear.output_names, tracked_names=linear.tracked_names,
        state_units=_units(linear.state_names, tuple(plant.state_units)),
        input_units=_units(linear.input_names, tuple(plant.input_units)),
        x0=linear.x_op, u0=linear.u_op, r0=linear.r_op,
        Ad=_readonly(np.array(discrete.A, dtype=float)),
        Bd=_readonly(np.array(discrete.B, dtype=float)),
        K=_readonly(np.array(design.K, dtype=float)),
        Kf=_readonly(np.array(design.Kf, dtype=float) if linear.form else np.zeros((n, 0))),
        Kc=linear.Dr, u_min=_limit(linear.u_min), u_max=_limit(linear.u_max),
        packed=deviation_vector(linear.packed()), z0=np.asarray(linear.z0),
        state_map=np.asarray(linear.state_map),
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
    """The :class:`ControllerData` of a discrete design's controller (:func:`checked_linear`)."""
    return of_controller(checked_linear(design, controller=controller))


def checked_linear(design: Design | object, *, controller: str = "lqg") -> LinearController:
    """The controller a discrete design's export runs, checked.

    Parameters
    ----------
    design:
        A control-layer ``Design`` with a rate: its controller (with its reference gain
        when it has one) is :meth:`LinearController.from_design`'s, limited to the
        parameters' input limits.
    controller:
        ``"lqg"`` (measurements through the Kalman filter) or ``"lqr"``
        (the full state measured, no estimator).

    Raises
    ------
    ExportError
        Not a design, a continuous design, a system without an input, an unknown
        controller, a design whose matrices are not finite or not of matching sizes, an
        operating input outside the input limits. Every problem is named at once.
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
    return linear
