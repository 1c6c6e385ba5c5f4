"""Tasks: what a controller is asked to do with a system.

A system is the physics (parameters, inputs, sensors); a task says where a
run starts, what counts as a fall, what it costs, at what rate the
controller runs and for how long (dm_control's domain/task split). The
environments, the demo, batches and studies read tasks; systems do not know
about them.

Two tasks exist:

``balance``
    Every system with an input and an operating point. A run starts at the
    operating point (the canonical one, or the equilibrium with the states
    given as ``at``), each coordinate that decides a fall (``spec.region``)
    drawn uniformly within a quarter of its Bryson scale
    (``spec.design_scales``; the others and the rates start there); it falls
    when a state leaves the system's region (``spec.region``; moved with the
    operating point, by the distance between the two, for a state whose
    ``at`` value lies outside it).
``swingup``
    Rigs that state where they hang (``spec.hanging``: the cart-pole, the
    reaction-wheel pendulum, the rotary pendulum, the acrobot). A run starts
    hanging at rest with each hanging coordinate offset uniformly by up to
    0.05 rad, and ends balanced at the operating point. Only the track
    bounds a swing-up: the cart-pole leaves its track at ``|x| > x_max``.

The cost is the quadratic one of the default design: ``Q`` and ``R`` from
Bryson's rule, ``1 / scale^2`` on the diagonal.

Examples
--------
>>> from equilibrist import get_system
>>> task = get_task(get_system("cartpole"), "swingup")      # doctest: +SKIP
>>> x0 = task.draw_initial(np.random.default_rng(1))         # doctest: +SKIP
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from equilibrist.errors import DesignError, UnknownNameError, nearest
from equilibrist.mechanics.spec import SystemSpec
from equilibrist.numeric.system import System

# The balance start: each coordinate within this share of its Bryson scale.
BALANCE_SPREAD = 0.25
# The swing-up start: hanging, each hanging coordinate offset by up to this [rad].
SWINGUP_OFFSET = 0.05
# A track parameter bounds the cart's coordinate during a swing-up.
TRACK_PARAMETER, TRACK_STATE = "x_max", "x"

#: The arguments of a task's reward function (``reward_<task>``) and their types, all plain
#: numbers and arrays as the environments' core holds them: the state ``x`` at the end of the
#: period, the input ``u`` applied during it, the parameters ``p``, the operating point ``op``
#: (``[x_op; u_op]``), the inverse Bryson scales ``iscale`` (states, then inputs), the indices
#: ``hang`` of the coordinates that hang (``spec.hanging``, integers), ``eref`` (the energy at
#: the operating point and at the task's nominal start), the period ``dt`` [s] and the alive
#: bonus ``bonus`` [1/s]. It may call ``energy(x, p)`` (the system's generated energy) and
#: ``eq_cos``/``eq_sin`` (:mod:`equilibrist.numeric.libm`). The environments translate it to C
#: into each system's core (:mod:`equilibrist.native.pyc`); tests run it as Python.
REWARD_ARGUMENTS = {"x": "F1", "u": "F1", "p": "F1", "op": "F1", "iscale": "F1", "hang": "I1",
                    "eref": "F1", "dt": "f", "bonus": "f"}
#: Their types in the C translation (:mod:`equilibrist.native.pyc`: arrays of doubles ``F1``,
#: of integers ``I1``, doubles ``f``), in order.
REWARD_TYPES = tuple(REWARD_ARGUMENTS.values())

_BALANCE_REWARD = '''
def reward_balance(x, u, p, op, iscale, hang, eref, dt, bonus):
    """dt * max(0, bonus - cost): the alive bonus less the task's quadratic cost (Bryson's
    weights), never below zero (struggling must not earn less than falling at once)."""
    n = x.shape[0]
    c = 0.0
    for i in range(n):
        d = (x[i] - op[i]) * iscale[i]
        c += d * d
    for i in range(u.shape[0]):
        d = (u[i] - op[n + i]) * iscale[n + i]
        c += d * d
    return dt * max(0.0, bonus - c)
'''

_SWINGUP_REWARD = '''
def reward_swingup(x, u, p, op, iscale, hang, eref, dt, bonus):
    """dt * (up + shaping) / 2: the mean height of the hanging coordinates (1 upright, 0
    hanging) and the energy's closeness to the upright's, 1 - e^2 clipped at zero, with e
    the energy's distance from the upright's in units of the hanging-to-upright gap."""
    up = 0.0
    nh = hang.shape[0]
    for j in range(nh):
        q = hang[j]
        up += 0.5 * (1.0 + eq_cos(x[q] - op[q]))
    if nh > 0:
        up /= nh
    gap = eref[0] - eref[1]
    if gap == 0.0:
        gap = 1.0
    e = (energy(x, p) - eref[0]) / gap
    return dt * 0.5 * (up + max(0.0, 1.0 - e * e))
'''


def _offers_balance(spec: SystemSpec) -> bool:
    return bool(spec.inputs) and spec.operating_point is not None


def _offers_swingup(spec: SystemSpec) -> bool:
    return _offers_balance(spec) and spec.hanging is not None


def _pose_balance(system: System, x_op: np.ndarray, state_scales: np.ndarray, moved: bool
                  ) -> tuple[np.ndarray, np.ndarray, dict[str, tuple[float, float]]]:
    names = system.state_names
    spread = np.zeros(system.n_states)
    for k in range(len(system.spec.coordinates)):
        if names[k] in system.spec.region:
            spread[k] = BALANCE_SPREAD * state_scales[k]
    region = _moved_region(system, x_op) if moved else dict(system.spec.region)
    return x_op.copy(), spread, region


def _pose_swingup(system: System, x_op: np.ndarray, state_scales: np.ndarray, moved: bool
                  ) -> tuple[np.ndarray, np.ndarray, dict[str, tuple[float, float]]]:
    start, spread = np.zeros(system.n_states), np.zeros(system.n_states)
    for coord, value in (system.spec.hanging or {}).items():
        k = system.state_index(coord)
        start[k] = float(value)
        spread[k] = SWINGUP_OFFSET
    region: dict[str, tuple[float, float]] = {}
    if TRACK_PARAMETER in system.params and TRACK_STATE in system.state_names:
        bound = float(system.params[TRACK_PARAMETER])
        region[TRACK_STATE] = (-bound, bound)
    return start, spread, region


@dataclass(frozen=True)
class TaskKind:
    """What a task asks, in one record: its name, how long a run lasts, which systems offer
    it, where a run starts and what counts as a fall (``pose``), and its reward (the Python
    source of ``reward_<name>``, :data:`REWARD_ARGUMENTS`). The environments, the demo,
    batches and studies read these; a new task is a new record in :data:`TASK_KINDS`."""

    name: str
    #: Seconds a run lasts (an environment's truncation, the demo's run).
    duration: float
    offered: Callable[[SystemSpec], bool]
    #: ``pose(system, x_op, state_scales, moved)`` -> start, spread, region.
    pose: Callable[[System, np.ndarray, np.ndarray, bool],
                   tuple[np.ndarray, np.ndarray, dict[str, tuple[float, float]]]]
    reward_source: str
    #: Whether the task may be posed about another equilibrium (``at``).
    movable: bool = False

    @property
    def reward_function(self) -> str:
        """The name of the function :attr:`reward_source` defines."""
        return f"reward_{self.name}"


TASK_KINDS: tuple[TaskKind, ...] = (
    TaskKind("balance", 10.0, _offers_balance, _pose_balance, _BALANCE_REWARD, movable=True),
    TaskKind("swingup", 15.0, _offers_swingup, _pose_swingup, _SWINGUP_REWARD),
)
TASK_NAMES = tuple(k.name for k in TASK_KINDS)
# Seconds a run of each task lasts.
DURATION = {k.name: k.duration for k in TASK_KINDS}


def task_kind(name: str) -> TaskKind:
    """The record of the task *name*."""
    for kind in TASK_KINDS:
        if kind.name == name:
            return kind
    raise UnknownNameError(f"unknown task {name!r}: {nearest(name, TASK_NAMES)}")


def rewards_source() -> str:
    """Every task's reward function, one source (what the environments' core translates)."""
    return "".join(k.reward_source for k in TASK_KINDS)


def python_reward(kind: TaskKind, system: System) -> Callable[..., float]:
    """The reward of *kind* on *system* as plain Python (the reference the core's translation
    is checked on): ``reward(x, u, p, op, iscale, hang, eref, dt, bonus)``."""
    from equilibrist.numeric import libm

    ns: dict[str, object] = {"eq_cos": libm.eq_cos, "eq_sin": libm.eq_sin,
                             "energy": system.functions.energy}
    exec(compile(kind.reward_source, f"<equilibrist {kind.name} reward>", "exec"), ns)
    fn = ns[kind.reward_function]
    assert callable(fn)
    return fn


@dataclass(frozen=True, eq=False)
class Task:
    """One task on one bound system.

    Attributes
    ----------
    name:
        ``"balance"`` or ``"swingup"``.
    system:
        The bound system the task is posed on.
    rate:
        The controller's sample rate [Hz] (the rig's ``control_rate``).
    duration:
        Length of a run [s].
    start:
        The nominal initial state (absolute).
    spread:
        Half-width of the uniform draw around ``start``, per state.
    region:
        ``{state: (low, high)}`` (absolute) outside which the run has fallen.
    x_op, u_op:
        The operating point the task ends at.
    state_scales, input_scales:
        Bryson scales of the cost (largest acceptable deviations).
    """

    name: str
    system: System
    rate: float
    duration: float
    start: np.ndarray
    spread: np.ndarray
    region: Mapping[str, tuple[float, float]]
    x_op: np.ndarray
    u_op: np.ndarray
    state_scales: np.ndarray
    input_scales: np.ndarray

    @property
    def id(self) -> str:
        """``<system>-<task>`` (the environment id's middle part)."""
        return f"{self.system.name}-{self.name}"

    @property
    def Q(self) -> np.ndarray:
        """State weight of the quadratic cost (Bryson's rule)."""
        return np.diag(1.0 / self.state_scales**2)

    @property
    def R(self) -> np.ndarray:
        """Input weight of the quadratic cost (Bryson's rule)."""
        return np.diag(1.0 / self.input_scales**2)

    @property
    def period(self) -> float:
        return 1.0 / self.rate

    @property
    def n_samples(self) -> int:
        """Controller samples in a run."""
        return math.ceil(self.duration * self.rate - 1e-9)

    def draw_initial(self, rng: np.random.Generator) -> np.ndarray:
        """An initial state drawn from the task's distribution with *rng*."""
        x0: np.ndarray = self.start + rng.uniform(-1.0, 1.0, self.start.size) * self.spread
        return x0

    def draw_initials(self, rng: np.random.Generator, runs: int) -> np.ndarray:
        """``runs`` initial states (rows) drawn with *rng*."""
        x0: np.ndarray = self.start + rng.uniform(-1.0, 1.0, (int(runs), self.start.size)) * self.spread
        return x0

    def cost(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Quadratic stage cost ``dx' Q dx + du' R du`` (rows of *x*, *u*; or one pair)."""
        dx = (np.asarray(x, dtype=float) - self.x_op) / self.state_scales
        du = (np.asarray(u, dtype=float) - self.u_op) / self.input_scales
        stage: np.ndarray = np.sum(dx * dx, axis=-1) + np.sum(du * du, axis=-1)
        return stage

    def fallen(self, x: np.ndarray) -> bool:
        """Whether the state *x* is outside the task's region."""
        for name, (lo, hi) in self.region.items():
            v = float(x[self.system.state_index(name)])
            if not lo <= v <= hi:
                return True
        return False

    def describe(self) -> dict[str, object]:
        names = self.system.state_names
        return {
            "task": self.name,
            "system": self.system.key,
            "rate": self.rate,
            "duration": self.duration,
            "start": dict(zip(names, self.start.tolist(), strict=True)),
            "spread": dict(zip(names, self.spread.tolist(), strict=True)),
            "region": {k: [lo, hi] for k, (lo, hi) in self.region.items()},
        }


def task_names(system: System) -> tuple[str, ...]:
    """The tasks *system* offers."""
    return spec_task_names(system.spec)


def spec_task_names(spec: SystemSpec) -> tuple[str, ...]:
    """The tasks a system of *spec* offers (read from the spec alone, without deriving it)."""
    return tuple(k.name for k in TASK_KINDS if k.offered(spec))


def _scales(system: System, names: tuple[str, ...]) -> np.ndarray:
    scales = system.spec.design_scales
    missing = [n for n in names if not scales.get(n, 0.0) > 0]
    if missing:
        raise DesignError(
            f"{system.key} has no design scale for {', '.join(missing)}: a task's cost needs "
            "the largest acceptable deviation of every state and input"
        )
    return np.array([float(scales[n]) for n in names])


def check_point(system: System, at: object) -> list[str]:
    """What is wrong with *at* as the states of an operating point of *system* (a mapping
    ``{state: number}``), every problem at once; empty when nothing is."""
    if at is None:
        return []
    if not isinstance(at, Mapping):
        return [f"at: expected a mapping {{state: value}} of {system.key}'s states "
                f"({', '.join(system.state_names)}), got {type(at).__name__}"]
    problems = []
    for key, value in at.items():
        if not isinstance(key, str) or key not in system.state_names:
            problems.append(f"at: {system.key} has no state {key!r} "
                            f"({nearest(str(key), system.state_names)})")
        elif isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating) \
                or not math.isfinite(float(value)):
            problems.append(f"at: {key} = {value!r} is not a finite number")
    return problems


def operating_point(system: System, at: Mapping[str, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(x_op, u_op)``: the canonical operating point of *system*, or the equilibrium with
    the states *at* (its other components solved as for the canonical one, as
    ``design(at=...)`` finds it)."""
    problems = check_point(system, at)
    if problems:
        raise DesignError("; ".join(problems))
    if not at:
        eq = system.operating_point()
        return eq.x, eq.u
    eq = system.equilibrium(state={k: float(v) for k, v in at.items()})
    if eq.residual > 1e-6 * (1.0 + float(np.max(np.abs(eq.x)))):
        raise DesignError(
            f"{system.key} has no equilibrium with " + ", ".join(f"{k} = {v:g}" for k, v in at.items())
            + f" (the closest point leaves |f| = {eq.residual:.3g})")
    lo, hi = system.input_limits
    for i, name in enumerate(system.input_names):
        if not lo[i] <= eq.u[i] <= hi[i]:
            raise DesignError(
                "at: the operating point with " + ", ".join(f"{k} = {v:g}" for k, v in at.items())
                + f" needs {name} = {eq.u[i]:g}, outside its limits "
                f"[{lo[i]:g}, {hi[i]:g}] ({name}_min, {name}_max)")
    return eq.x, eq.u


def _moved_region(system: System, x_op: np.ndarray) -> dict[str, tuple[float, float]]:
    """The system's region, each bound whose state lies outside it at *x_op* moved by the
    distance from the canonical point (as ``simulate`` moves it for a design ``--at``)."""
    names = system.state_names
    region = dict(system.spec.region)
    canonical = system.operating_point().x
    for name, (lo, hi) in system.spec.region.items():
        k = names.index(name)
        if not lo < x_op[k] < hi:
            shift = float(x_op[k] - canonical[k])
            region[name] = (float(lo) + shift, float(hi) + shift)
    return region


def get_task(system: System, name: str, *, at: Mapping[str, float] | None = None) -> Task:
    """The task *name* (``"balance"``, ``"swingup"``) posed on *system*.

    *at* (``{state: value}``, balance only) poses it about the equilibrium with those states
    instead of the canonical operating point: the start, the cost and the region move there.
    """
    if not isinstance(system, System):
        raise UnknownNameError(f"task: system = {system!r}: expected a System "
                               f"(equilibrist.get_system(name)), not {type(system).__name__}")
    if not isinstance(name, str):
        raise UnknownNameError(f"task: expected a task name, got {type(name).__name__}")
    offered = task_names(system)
    if name not in offered:
        if name in TASK_NAMES:
            why = "it has no input" if not system.n_inputs else f"it offers {', '.join(offered) or 'none'}"
            raise UnknownNameError(f"{system.key} has no task {name!r}: {why}")
        raise UnknownNameError(f"unknown task {name!r}: {nearest(name, TASK_NAMES)}")
    kind = task_kind(name)
    if at and not kind.movable:
        raise DesignError(f"at: the {name} task ends at {system.key}'s canonical operating "
                          "point; another point is posed for the balance task only")
    x_op, u_op = operating_point(system, at)
    state_scales = _scales(system, system.state_names)
    input_scales = _scales(system, system.input_names)
    start, spread, region = kind.pose(system, x_op, state_scales, bool(at))
    for arr in (start, spread):
        arr.setflags(write=False)
    return Task(
        name=name, system=system, rate=float(system.spec.control_rate), duration=kind.duration,
        start=start, spread=spread, region=region, x_op=x_op, u_op=u_op,
        state_scales=state_scales, input_scales=input_scales,
    )


#: Share of a task's state bounds a plan leaves free for the tracker to correct in.
PLAN_MARGIN = 0.3


def planning_bounds(task: Task, margin: float = PLAN_MARGIN) -> dict[str, tuple[float, float]]:
    """The task's region shrunk about its centre by *margin* (a share of its width): where a
    plan (``equilibrist trajopt``) keeps its states, so that the time-varying LQR tracking
    it has room to correct (the cart-pole plans within 70 % of its track by default)."""
    if not 0.0 <= margin < 1.0:
        raise ValueError(f"margin {margin!r}: expected a fraction in [0, 1)")
    keep = 1.0 - margin
    return {k: (0.5 * (lo + hi) - 0.5 * (hi - lo) * keep, 0.5 * (lo + hi) + 0.5 * (hi - lo) * keep)
            for k, (lo, hi) in task.region.items()}


#: "Balanced": every coordinate of the system's fall region within this of the operating
#: point (an angle in rad, taken modulo a turn), its rate within :data:`BALANCED_RATE`.
BALANCED_ANGLE = 0.1
#: [rad/s] (or the rate's own unit for a coordinate that is not an angle).
BALANCED_RATE = 0.5
#: A coordinate of the fall region that is not an angle: within this share of its half-width.
BALANCED_SHARE = 0.05


def balance_box(system: System) -> np.ndarray:
    """Per state, ``(low, high, period)`` of the deviation from the operating point that
    counts as balanced (``period`` 2 pi for an angle, taken modulo a turn; 0 otherwise;
    unbounded states have ``(-inf, inf, 0)``). A run *ends balanced* when its state is in
    the box from some time to its end (the batch's ``balanced_since``)."""
    names, units = system.state_names, system.state_units
    box = np.tile(np.array([-math.inf, math.inf, 0.0]), (system.n_states, 1))
    for coord, (lo, hi) in system.spec.region.items():
        k = names.index(coord)
        if units[k] == "rad":
            box[k] = (-BALANCED_ANGLE, BALANCED_ANGLE, 2.0 * math.pi)
        else:
            half = BALANCED_SHARE * 0.5 * (float(hi) - float(lo))
            box[k] = (-half, half, 0.0)
        rate = f"{coord}_dot"
        if rate in names:
            box[names.index(rate)] = (-BALANCED_RATE, BALANCED_RATE, 0.0)
    return box


def balance_criterion(system: System) -> dict[str, str]:
    """:func:`balance_box` in words, by state (what JSON and tables report)."""
    out = {}
    for name, (_lo, hi, period), unit in zip(system.state_names, balance_box(system),
                                            system.state_units, strict=True):
        if math.isfinite(hi):
            turn = " (modulo a turn)" if period else ""
            out[name] = f"within {hi:g} {unit} of the operating point{turn}"
    return out


def in_box(x: np.ndarray, x_op: np.ndarray, box: np.ndarray) -> np.ndarray:
    """Whether each row of *x* is in *box* (:func:`balance_box`), with the core's operations
    in the core's order (the Python twin of its accumulator)."""
    d = np.asarray(x, dtype=float) - x_op
    period = box[:, 2]
    wrapped = np.where(period > 0.0, d - period * np.floor(d / np.where(period > 0, period, 1.0)
                                                           + 0.5), d)
    inside: np.ndarray = np.all((wrapped >= box[:, 0]) & (wrapped <= box[:, 1]), axis=-1)
    return inside


def all_tasks(system: System) -> tuple[Task, ...]:
    """Every task *system* offers."""
    return tuple(get_task(system, n) for n in task_names(system))
