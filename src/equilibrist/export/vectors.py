"""Test vectors of an exported controller, and the compiled controller in the simulation.

:func:`record` runs the simulation's own digital controller in closed loop
on the nonlinear plant, with sensor and process noise, and keeps what the
controller saw and did: the measurements and references in, the saturated
commands out. Shipped with the export, they let the test program check the
C code on the user's target.

:func:`tolerance` says how close the C code must come: a fraction of the
input's activity over the run (its largest excursion from the operating
input), ``1e-9`` in double precision (room for another compiler's fused
multiply-adds) and ``1e-4`` in single precision (the C code in float
differs from the simulation's double-precision controller by a few
millionths of the activity over a noisy run).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from equilibrist.control.design_record import Design
from equilibrist.errors import ExportError, nearest
from equilibrist.export.data import check_controller, checked_linear, controller_data, of_controller
from equilibrist.native.c_text import Vectors, check_precision
from equilibrist.native.linear_c import ControllerData
from equilibrist.native.shared_library import CompiledController, compile_library
from equilibrist.numeric.system import System

if TYPE_CHECKING:
    from typing import TypedDict

    from equilibrist.sim.noise import Noise
    from equilibrist.sim.signals import Step

    class _Scenario(TypedDict):
        """:func:`scenario`: keyword arguments of :func:`~equilibrist.sim.run.simulate`."""

        duration: float
        rate: float
        x0: np.ndarray
        noise: Noise
        reference: Step | None


# Fractions of the input's activity accepted by the shipped test program.
RELATIVE_TOLERANCE = {"double": 1e-9, "float": 1e-4}
# The recorded run: its length [s] by default, the start away from the
# operating point and the reference step, as fractions of the spec's design
# scales (the largest deviations the rig accepts).
DEFAULT_DURATION = 4.0
START_FRACTION = 0.25
STEP_FRACTION = 0.5
# Samples of a recorded run at most: the test program holds them as text (10,000 samples
# are 50 s at 200 Hz, a header of a few MB); more only makes the run and the build slow.
MAX_SAMPLES = 10_000


def displaced(x: npt.ArrayLike, names: Sequence[str], system: System, *,
              fraction: float = START_FRACTION) -> np.ndarray:
    """*x* (states *names*) with each coordinate that has a design scale displaced by
    *fraction* of it: where every recorded run starts by default."""
    scales, coordinates = system.spec.design_scales, system.spec.coordinates
    out = np.array(x, dtype=float)
    for i, name in enumerate(names):
        if name in coordinates and scales.get(name):
            out[i] += fraction * float(scales[name])
    return out


def check_duration(duration: object, rate: float, option: str = "duration") -> float | None:
    """*duration* [s] of a recorded run at *rate* [Hz], if positive, finite and within
    :data:`MAX_SAMPLES` samples (None stays None: the exporter's default), else
    :class:`ExportError` naming the longest accepted."""
    if duration is None:
        return None
    try:
        value = float(duration)  # type: ignore[arg-type]
    except (TypeError, ValueError, OverflowError):
        raise ExportError(f"{option} must be a positive number of seconds, got {duration!r}") from None
    if not (np.isfinite(value) and value > 0):
        raise ExportError(f"{option} must be a positive number of seconds, got {value:g}")
    longest = MAX_SAMPLES / float(rate)
    if value > longest:
        raise ExportError(f"{option} {value:g} s: the recorded test vectors take at most "
                          f"{MAX_SAMPLES} samples, {longest:g} s at {float(rate):g} Hz")
    return value
# Without a given start, the run starts START_FRACTION of each design scale
# off; when the design does not hold that, each of these smaller fractions in
# turn (down to a 128th: a weak motor, dm_control's acrobot's, holds a few
# thousandths of a radian), and the first the design holds is recorded. The
# reference step shrinks with the start.
FALLBACK_FRACTIONS = (0.125, 0.0625, 0.03125, 0.015625, 0.0078125)


@dataclass
class RecordedStart:
    """The start of the recorded run: given (``export --x0``) and as used.

    ``given`` holds absolute state values by name (the others at the
    operating point), or None for the default start; ``used`` is filled
    by :func:`record` with the start of the run it recorded.
    """

    given: Mapping[str, float] | None = None
    used: dict[str, float] = field(default_factory=dict)


_START: ContextVar[RecordedStart | None] = ContextVar("recorded_start", default=None)


@contextmanager
def recorded_start(start: RecordedStart) -> Iterator[RecordedStart]:
    """Record the test vectors of exports inside the block from *start*."""
    token = _START.set(start)
    try:
        yield start
    finally:
        _START.reset(token)


def tolerance(data: ControllerData, u: np.ndarray, precision: str) -> np.ndarray:
    """Per input, the largest accepted ``|u_C - u|`` for the commands *u* of a run.

    The scale is the input's largest excursion from the operating input
    over the run, at least a millionth of its range, and the tolerance
    :data:`RELATIVE_TOLERANCE` of it.
    """
    u = np.atleast_2d(np.asarray(u, dtype=float))
    activity = np.max(np.abs(u - data.u0), axis=0) if u.size else np.zeros(data.n_inputs)
    floor = 1e-6 * (data.u_max - data.u_min)
    scale = np.maximum(np.maximum(activity, floor), np.abs(data.u0) * 1e-6)
    tolerance: np.ndarray = RELATIVE_TOLERANCE[precision] * scale
    return tolerance


def make_vectors(data: ControllerData, y: npt.ArrayLike, r: npt.ArrayLike, u: npt.ArrayLike,
                 x_init: npt.ArrayLike, *,
                 precision: str) -> Vectors:
    """:class:`Vectors` from arrays, with the tolerance of :func:`tolerance`."""
    ys = np.asarray(y, dtype=float).reshape(-1, data.n_measured)
    us = np.asarray(u, dtype=float).reshape(-1, data.n_inputs)
    rs = np.asarray(r, dtype=float).reshape(len(us), data.n_references)
    x0 = np.asarray(x_init, dtype=float).reshape(data.n_states)
    return Vectors(y=ys, r=rs, u=us, x_init=x0, tolerance=tolerance(data, us, precision))


class CController:
    """The compiled C controller as a controller of equilibrist's simulation.

    It has the simulator's step interface for controllers written by the
    user (``step(t, y, r) -> u``, ``reset()``, ``estimate``): each step
    calls the C library's ``step`` with the absolute measurements and
    references, and returns the command the C code computed (already
    saturated, so the simulator's own saturation leaves it unchanged). The
    C code predicts with the input it returned: run it without an input
    delay.

    Parameters
    ----------
    compiled:
        A loaded :class:`~equilibrist.native.shared_library.CompiledController`.
    x_estimate:
        Initial estimate (absolute state) for ``init_at``; None starts at
        the operating point (``init``), as the simulation's LQG does.
    """

    def __init__(self, compiled: CompiledController, x_estimate: npt.ArrayLike | None = None) -> None:
        self.compiled = compiled
        self.x_estimate = None if x_estimate is None else np.asarray(x_estimate, dtype=float)
        self.reset()

    @property
    def data(self) -> ControllerData:
        return self.compiled.data

    @property
    def outputs(self) -> tuple[str, ...]:
        """The measured states, in the order ``step`` takes them (the simulator reads this)."""
        return self.compiled.data.measured_names

    @property
    def rate(self) -> float:
        """The sample rate [Hz] the controller was generated for (the simulator reads this)."""
        return self.compiled.data.rate

    def reset(self) -> None:
        """Start the C controller again (``init`` or ``init_at``)."""
        self.compiled.reset(self.x_estimate)
        self.estimate = self.compiled.estimate()

    def step(self, t: float, y: npt.ArrayLike, r: npt.ArrayLike | None) -> np.ndarray:
        """One sample of the C code: absolute ``y`` (and ``r``) in, saturated ``u`` out."""
        ref = np.asarray(r, dtype=float).reshape(-1) if r is not None else np.zeros(0)
        u = self.compiled.step(y, ref if ref.size else None)
        self.estimate = self.compiled.estimate()
        return u

    def close(self) -> None:
        self.compiled.close()


def compile_controller(design: Design | ControllerData, *, controller: str = "lqg",
                       precision: str = "double", version: str | None = None) -> CompiledController:
    """Generate, compile and load the C controller of *design*.

    Parameters
    ----------
    design:
        A discrete control-layer ``Design``, or a :class:`ControllerData`.
    controller:
        ``"lqg"`` or ``"lqr"`` (ignored for a :class:`ControllerData`).
    precision:
        ``"double"`` or ``"float"``.
    version:
        The generator string written into the library (default equilibrist's version).

    Raises
    ------
    ExportError
        A design that cannot be exported, no C compiler, code that does not compile.
    """
    from equilibrist.export.folder import generator_version

    check_precision(precision)
    data = design if isinstance(design, ControllerData) else controller_data(design, controller=controller)
    return compile_library(data, precision=precision, version=version or generator_version())


def c_controller(design: Design, *, controller: str = "lqg", precision: str = "double",
                 x_estimate: npt.ArrayLike | None = None) -> CController:
    """Generate, compile and load *design*'s C controller as a simulation controller.

    See :func:`compile_controller` for the build and :class:`CController` for the interface.
    """
    return CController(compile_controller(design, controller=controller, precision=precision),
                       x_estimate)


def scenario(design: Design, system: System, *, duration: float | None = None,
             start: Mapping[str, float] | None = None,
             fraction: float = START_FRACTION) -> _Scenario:
    """The settings of the recorded run: start, reference step, noise, rate.

    The run starts with each coordinate that has a design scale displaced by
    :data:`START_FRACTION` of it, steps the reference of the tracked outputs
    (when the design has a reference gain) by :data:`STEP_FRACTION` of their
    scales half way, and has the sensor and process noise the design assumed.
    """
    from equilibrist.sim import Noise, Step

    if design.rate is None:
        raise ExportError(f"the design of {design.system_key} is continuous: test vectors need a rate")
    plant = design.plant
    scales = system.spec.design_scales
    given = check_duration(duration, design.rate)
    length = DEFAULT_DURATION if given is None else given
    if start is None:
        x0 = displaced(plant.x0, plant.state_names, system, fraction=fraction)
    else:
        x0 = np.array(plant.x0, dtype=float)
        for name, value in start.items():
            if name not in plant.state_names:
                raise ExportError(f"--x0 {name}: {design.system_key} has no state {name!r}: "
                                  f"{nearest(name, plant.state_names)}")
            x0[plant.state_names.index(name)] = float(value)
    reference = None
    if design.Kc is not None:
        r0 = np.asarray(design.r0, dtype=float)
        share = STEP_FRACTION * (1.0 if start is not None else fraction / START_FRACTION)
        step = np.array([share * float(scales.get(t, 0.0)) for t in design.tracked])
        reference = Step(value=r0 + step, at=0.5 * length)
    return {
        "duration": length,
        "rate": design.rate,
        "x0": x0,
        "noise": Noise.from_design(design),
        "reference": reference,
    }


def _start_text(x: npt.ArrayLike, design: Design) -> str:
    return ",".join(f"{n}={float(v):.6g}" for n, v in zip(design.plant.state_names, np.asarray(x, float),
                                                          strict=True))


def record(design: Design, system: System, *, controller: str = "lqg", precision: str = "double",
           duration: float | None = None, seed: int = 0) -> Vectors:
    """Test vectors from a noisy closed-loop run of the simulation's own controller.

    The simulation runs the export's own controller
    (:func:`~equilibrist.export.data.checked_linear`: the design's linear form, with its
    reference gain when it has one) on the nonlinear plant through the run of
    :func:`scenario`; the vectors are the measurements and references it read and the
    saturated commands it returned.

    Raises
    ------
    ExportError
        When the recorded run falls (the design does not hold the plant).
    """
    from equilibrist.sim import simulate

    check_controller(controller)
    check_precision(precision)
    linear = checked_linear(design, controller=controller)
    data = of_controller(linear)
    tracking = design.Kc is not None
    given = _START.get()
    if given is not None and given.given is not None:
        run = scenario(design, system, duration=duration, start=given.given)
        result = simulate(system, linear, seed=seed, **run)
        if result.fell:
            raise ExportError(
                f"the recorded run of the {controller} controller of {data.system} from --x0 "
                f"{_start_text(run['x0'], design)} fell at t = {result.fell_at:.3g} s "
                f"({result.fell_state} left its region): give an --x0 nearer the operating point "
                f"({_start_text(design.plant.x0, design)})"
            )
    else:
        for fraction in (START_FRACTION, *FALLBACK_FRACTIONS):
            run = scenario(design, system, duration=duration, fraction=fraction)
            result = simulate(system, linear, seed=seed, **run)
            if not result.fell:
                break
        if result.fell:
            raise ExportError(
                f"the recorded run of the {controller} controller of {data.system} fell at "
                f"t = {result.fell_at:.3g} s ({result.fell_state} left its region) from every "
                f"default start ({', '.join(f'{f:g}' for f in (START_FRACTION, *FALLBACK_FRACTIONS))} "
                "of each coordinate's design scale off the operating point): the design does not "
                "hold the plant; a larger --r (a gentler design) or --x0 NAME=VALUE,... nearer "
                f"the operating point ({_start_text(design.plant.x0, design)}) may hold it"
            )
    if given is not None:
        given.used = {n: float(v) for n, v in zip(design.plant.state_names, run["x0"], strict=True)}
    r = result.reference if tracking else np.zeros((result.n_rows, 0))
    estimate0 = linear.z0 if linear.n_z else None
    x_init = data.x0 + (0.0 if estimate0 is None else estimate0)
    return make_vectors(data, result.measurements, r, result.saturated, x_init,
                        precision=precision)
