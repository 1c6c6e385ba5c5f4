"""What a system is, as data: parameters, inputs, coordinates, operating point.

A :class:`SystemSpec` is the product specification of one system of the
catalogue (``SYSTEMS.md``) written as frozen data. The derivation of its
equations of motion lives beside it in the system's module; the numeric layer
combines both.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field

from equilibrist.errors import DefinitionError


def _real(value: object) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


@dataclass(frozen=True)
class Parameter:
    """One physical parameter.

    ``low``/``high`` bound the valid range; ``low_open``/``high_open`` say
    whether the bound itself is excluded (a mass must be > 0, a friction >= 0).
    ``dissipative``: the parameter only takes energy out of the system (a
    friction): with every dissipative parameter at zero and no input, the
    system's energy is conserved (the contract test checks both ways).
    ``coulomb``: a Coulomb friction in a smooth law (:mod:`equilibrist.mechanics.friction`),
    whose steep slope at rest is no damping a controller can count on: designs linearize
    with it at zero (the friction then acts on the loop as the disturbance it is).
    """

    name: str
    default: float
    unit: str
    meaning: str
    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False
    high_open: bool = False
    note: str = ""
    dissipative: bool = False
    coulomb: bool = False

    def __post_init__(self) -> None:
        # A spec is refused where it is written: a default outside its own
        # range would be taken as valid until a check of the bound values.
        where = f"parameter {self.name!r}"
        for what in ("default", "low", "high"):
            value = getattr(self, what)
            if not _real(value):
                raise DefinitionError(f"{where}: {what} = {value!r} is not a number: expected a real number")
        if math.isnan(self.low) or math.isnan(self.high) or self.low > self.high:
            raise DefinitionError(
                f"{where}: its range [{self.low}, {self.high}] is empty: expected low <= high"
            )
        problem = self.check(self.default)
        if problem is not None:
            raise DefinitionError(
                f"{where}: its default {self.default!r} is outside its own range: expected a finite "
                f"value in {self.range_text}"
            )

    def check(self, value: float) -> str | None:
        """Return a problem description, or None when *value* is valid."""
        if not math.isfinite(value):
            return f"parameter {self.name} = {value} is not a finite number"
        too_low = value <= self.low if self.low_open else value < self.low
        too_high = value >= self.high if self.high_open else value > self.high
        if too_low or too_high:
            return f"parameter {self.name} = {value:g} is out of range: expected {self.range_text}"
        return None

    @property
    def range_text(self) -> str:
        lo = "(" if self.low_open or self.low == -math.inf else "["
        hi = ")" if self.high_open or self.high == math.inf else "]"
        return f"{lo}{_fmt(self.low)}, {_fmt(self.high)}{hi}"


def _fmt(v: float) -> str:
    if v == math.inf:
        return "inf"
    if v == -math.inf:
        return "-inf"
    return f"{v:g}"


def positive(name: str, default: float, unit: str, meaning: str, note: str = "") -> Parameter:
    """A strictly positive parameter (masses, lengths, inertias, g)."""
    return Parameter(name, default, unit, meaning, low=0.0, low_open=True, note=note)


def nonnegative(name: str, default: float, unit: str, meaning: str, note: str = "") -> Parameter:
    """A parameter that may be zero but not negative (frictions)."""
    return Parameter(name, default, unit, meaning, low=0.0, note=note)


def friction(name: str, default: float, unit: str, meaning: str, note: str = "", *,
             coulomb: bool = False) -> Parameter:
    """A friction: non-negative, and dissipative (see :class:`Parameter`)."""
    return Parameter(name, default, unit, meaning, low=0.0, note=note, dissipative=True,
                     coulomb=coulomb)


@dataclass(frozen=True)
class Input:
    """One actuator input with its default saturation limits."""

    name: str
    unit: str
    meaning: str
    low: float
    high: float

    def __post_init__(self) -> None:
        where = f"input {self.name!r}"
        if not (_real(self.low) and _real(self.high)):
            raise DefinitionError(
                f"{where}: limits {self.low!r}, {self.high!r}: expected two finite numbers, low < high"
            )
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low < self.high):
            raise DefinitionError(
                f"{where}: limits [{self.low:g}, {self.high:g}]: expected two finite numbers, low < high"
            )

    def limit_parameters(self) -> tuple[Parameter, Parameter]:
        """The ``<input>_min`` / ``<input>_max`` parameters of this input."""
        return (
            Parameter(f"{self.name}_min", self.low, self.unit, f"lower limit of {self.name}"),
            Parameter(f"{self.name}_max", self.high, self.unit, f"upper limit of {self.name}"),
        )


@dataclass(frozen=True)
class SwingUp:
    """The rig's energy-pumping swing-up, as its definition states it.

    ``law``: which law pumps (``cart``, ``wheel``, ``rotary``, ``acrobot``: the laws of
    :mod:`equilibrist.control.swingup`); ``gains``: its default tuning, by the names of
    :class:`~equilibrist.control.swingup.SwingUpTuning` (``k_energy``, ``a_max`` and the
    others it needs); ``free``: the coordinates whose value does not matter (a reaction
    wheel's angle, a rotary arm's), which the balance catches where they are.
    """

    law: str
    gains: dict[str, float]
    free: tuple[str, ...] = ()


@dataclass(frozen=True)
class Scenario:
    """What the demo does to the rig (``equilibrist demo``): its start, a push, a reference step.

    Attributes
    ----------
    duration : float
        Seconds simulated.
    start : dict
        Initial offsets from the operating point, by state name (state units).
    push : float
        A push added to the first input's channel (beside the actuator, which
        does not limit it) at half the duration, in the input's unit.
    push_duration : float
        How long the push lasts [s].
    step : dict
        Offsets of the tracked outputs' reference from the operating point,
        from ``step_at`` seconds on (empty: no reference change).
    step_at : float
        When the reference steps [s].
    push_name : str
        What the push is, in words ("a 40 N shove on the cart").
    note : str
        What the reader should know to read the run (shown in the report).
    """

    duration: float = 8.0
    start: dict[str, float] = field(default_factory=dict)
    push: float = 0.0
    push_duration: float = 0.1
    step: dict[str, float] = field(default_factory=dict)
    step_at: float = 1.0
    push_name: str = "a push"
    note: str = ""


@dataclass(frozen=True)
class OperatingPoint:
    """The canonical operating point.

    ``state`` fixes state components (missing ones are zero), ``inputs``
    fixes inputs, and ``free`` names the components (inputs or states) that
    are solved for so that ``f(x, u) = 0``. Values may be parameter names
    (e.g. ``"R_d"``), resolved against the bound parameters.
    """

    state: dict[str, float | str] = field(default_factory=dict)
    inputs: dict[str, float | str] = field(default_factory=dict)
    free: tuple[str, ...] = ()


@dataclass(frozen=True)
class SystemSpec:
    """Everything SYSTEMS.md says about one system, except its equations.

    Attributes
    ----------
    name:
        Registry name (``cartpole``); with ``variant`` set, the family name.
    variant:
        ``(option, value)`` for families of parameterizations (the
        gyroscope's ``("euler", "zxz")``), else None.
    coordinates:
        Generalized coordinates in state order; rates are ``<name>_dot``.
    states:
        Override of the state names for first-order models that are not
        ``[q, q_dot]`` (the servo ball-and-beam).
    units:
        Unit of each coordinate (rates get ``/s``).
    region:
        Bounds per state outside which a balancing run counts as fallen.
    drawing:
        The class that draws the rig, as ``"module:Class"`` (a
        :class:`~equilibrist.viz.scenes.Scene` taking the bound system),
        imported only when a picture is made; None: drawn from the derivation's
        recorded points where it records them (model files), else not drawn.
    scenario:
        What the demo does to the rig; None: a scenario from the design
        scales and the input's limit (``apps.tour.default_scenario``).
    position:
        Where the catalogue lists the rig (and the demo's tour visits it),
        lower first; None: after the numbered ones, by name.
    """

    name: str
    title: str
    description: str
    coordinates: tuple[str, ...]
    units: dict[str, str]
    parameters: tuple[Parameter, ...]
    inputs: tuple[Input, ...] = ()
    outputs: tuple[str, ...] = ()
    operating_point: OperatingPoint | None = None
    source: str = ""
    seed_slips: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    variant: tuple[str, str] | None = None
    states: tuple[str, ...] | None = None
    region: dict[str, tuple[float, float]] = field(default_factory=dict)
    symbols_latex: dict[str, str] = field(default_factory=dict)
    singularity: str = ""
    # Bryson's rule: the largest acceptable deviation of each state and input
    # from the operating point on the real rig (default LQR weights).
    design_scales: dict[str, float] = field(default_factory=dict)
    # Standard deviation of each default output's sensor noise per sample, in
    # the output's unit (default measurement noise covariance), and the
    # intensity of the process noise on each state rate, in the rate's unit
    # per sqrt(s) (default process noise covariance).
    sensor_noise: dict[str, float] = field(default_factory=dict)
    process_noise: dict[str, float] = field(default_factory=dict)
    # The rig's digital controller rate [Hz]: the default sample rate of
    # designs and simulations, and the rate at which ``sensor_noise`` is
    # sampled (its standard deviations are per sample).
    control_rate: float = 200.0
    # The stable rest configuration a swing-up starts from (coordinates not
    # named are zero, rates zero); None when the rig has no swing-up task.
    # What a controller is asked to do lives in :mod:`equilibrist.tasks`;
    # the rig only states where it hangs.
    hanging: dict[str, float] | None = None
    # The energy-pumping swing-up from there, if the rig has one: its law and gains.
    swingup: SwingUp | None = None
    drawing: str | None = None
    scenario: Scenario | None = None
    position: int | None = None

    @property
    def key(self) -> str:
        """Unique key of this spec (family name plus variant)."""
        if self.variant is None:
            return self.name
        return f"{self.name}[{self.variant[0]}={self.variant[1]}]"

    @property
    def state_names(self) -> tuple[str, ...]:
        if self.states is not None:
            return self.states
        return self.coordinates + tuple(f"{c}_dot" for c in self.coordinates)

    @property
    def input_names(self) -> tuple[str, ...]:
        return tuple(i.name for i in self.inputs)

    @property
    def all_parameters(self) -> tuple[Parameter, ...]:
        """Physical parameters followed by the input-limit parameters."""
        limits = tuple(p for i in self.inputs for p in i.limit_parameters())
        return self.parameters + limits

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.all_parameters)

    def state_unit(self, name: str) -> str:
        if name in self.units:
            return self.units[name]
        if name.endswith("_dot") and name[:-4] in self.units:
            base = self.units[name[:-4]]
            return f"{base}/s"
        return ""
