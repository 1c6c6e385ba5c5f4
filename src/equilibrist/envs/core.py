"""The settings an environment hands the compiled core, validated once.

:class:`Core` is built from a system, a task and the environment's options;
the single environment and the vector environment read the same one, so
both step exactly the same numbers. It is the only Python code that packs
the core's settings arrays (``ci``, ``cf``) and a copy's rows (``fs``,
``us``), whose slots are named once in :mod:`equilibrist.sim.layout`
(``ENV_CI``, ``ENV_CF``, ``ENV_US``: ``EQ_CI_*``, ``EQ_CF_*``, ``EQ_US_*`` in
``native/env.c``).

The single and the vector environment take the same options,
:data:`OPTION_DEFAULTS`, and both check them through one function
(:func:`equilibrist.envs.env.open_core`, which builds the core here).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control import fixed
from equilibrist.control.checks import given_text, real_array
from equilibrist.envs.learnable import Learnable, learnable, learnable_rate
from equilibrist.errors import DesignError, EquilibristError, UnknownNameError, nearest
from equilibrist.numeric.lookup import get_system
from equilibrist.numeric.system import System
from equilibrist.sim import integrators, layout
from equilibrist.sim.noise import Noise, square_root
from equilibrist.sim.rig import Rig
from equilibrist.sim.setup_checks import positive
from equilibrist.sim.setup_steps import split_period
from equilibrist.sim.simcore import load_core
from equilibrist.tasks import TASK_NAMES, Task, check_point, get_task

if TYPE_CHECKING:
    from equilibrist.sim.simcore import NativeCore

OBSERVE = ("outputs", "state")
ACTION_UNITS = ("normalized", "physical")
# Reward per second for staying inside the region (balance).
ALIVE_BONUS = 1.0
# The observation space's bound: half the largest double, so "any finite
# value" and ``observation_space.sample()`` does not overflow (high - low).
FINITE = float(np.finfo(np.float64).max) / 2
#: The slots of ``ci``'s head: sizes, switches, and the offsets of ``cf``'s
#: blocks and of ``ci``'s own index blocks (:data:`equilibrist.sim.layout.ENV_CI`).
CI_SLOTS = layout.ENV_CI.names
#: The slots of ``cf``'s head; its blocks follow.
CF_SLOTS = layout.ENV_CF.names
#: A copy's ``us`` row: four generator words, then these.
US_SLOTS = layout.ENV_US
US_WIDTH = 4 + len(US_SLOTS)
#: The environments' options and their defaults (the single and the vector
#: environment take the same ones).
OPTION_DEFAULTS: dict[str, object] = {
    "params": None, "rate": None, "physics_step": None, "observe": "outputs", "noise": True,
    "randomize": None, "action_units": "normalized", "alive_bonus": ALIVE_BONUS, "at": None,
    "integrator": integrators.DEFAULT, "version": 0, "dtype": None, "rig": None,
}
#: The task's versions: 0 the rig's own units and cost, 1 the learnable form
#: (:mod:`equilibrist.envs.learnable`).
VERSIONS = (0, 1)


class EnvError(EquilibristError, ValueError):
    """An environment was asked for something it can not be or do."""


def bind_system(system: object, params: Mapping[str, object] | None) -> System:
    """*system* (a catalogue name, a file's path or a :class:`System`) with *params* bound."""
    if system is None:
        raise EnvError(
            "give the system: a catalogue name (system='cartpole') or a model file "
            "(system='robot.xml')"
        )
    if params is not None and not isinstance(params, Mapping):
        raise EnvError(f"params: expected a mapping of parameter values, got {type(params).__name__}")
    values = dict(params or {})
    names = [k for k in values if not isinstance(k, str)]
    if names:
        raise EnvError(f"params: parameter names are text, got {names[0]!r}")
    if isinstance(system, System):
        return system.with_params(**values) if values else system  # type: ignore[arg-type]
    if not isinstance(system, str):
        raise EnvError(
            f"system: expected a system name or the path of a model file, got {type(system).__name__}"
        )
    return get_system(system, **values)


@dataclass(frozen=True, eq=False)
class Core:
    """One environment's validated settings and the core's arrays.

    Attributes
    ----------
    system, task:
        The bound system and the task posed on it.
    rate, physics_step, n_sub, n_samples:
        Control rate [Hz], physics step [s], steps per period, periods per episode.
    integrator:
        The physics steps' integrator (a name of :mod:`equilibrist.sim.integrators`' table;
        an adaptive one with its default tolerances). The vector environment's lanes step
        those whose entry says ``lanes`` (RK4); the others' copies one at a time.
    observe:
        ``"outputs"`` (the rig's sensors, with their noise) or ``"state"``.
    observation_names:
        What each observation component is.
    action_units:
        ``"normalized"`` (``[-1, 1]`` onto each input's limits) or ``"physical"``.
    noise:
        The rig's process and sensor noise, or None.
    randomize:
        ``{parameter: relative spread}`` drawn per reset.
    at:
        The states of the balance task's operating point (``{state: value}``), or None for
        the canonical one; the expert designs there too.
    version:
        The task's version: 0 (the rig's units, the task's cost) or 1 (``learnable``).
    dtype:
        The observations' and the spaces' floating type.
    learnable:
        Version 1's observation and reward (None for version 0).
    rig:
        A rig's effects between the plant and the agent (:class:`~equilibrist.sim.rig.Rig`:
        torque response, delays, torque and velocity noise, encoders, perturbations), or
        None. With one, each copy's episode is the loop ``simulate`` runs around a controller
        written in Python, a sample a step (:class:`~equilibrist.envs.rig_episode.RigEpisode`).
    """

    system: System
    task: Task
    rate: float
    physics_step: float
    n_sub: int
    n_samples: int
    integrator: str
    observe: str
    observation_names: tuple[str, ...]
    action_units: str
    noise: Noise | None
    randomize: Mapping[str, float]
    alive_bonus: float
    at: Mapping[str, float] | None
    version: int
    dtype: np.dtype[np.floating]
    learnable: Learnable | None
    rig: Rig | None
    kernel: NativeCore
    c_idx: np.ndarray
    lv: np.ndarray
    lw: np.ndarray
    region: np.ndarray
    op: np.ndarray
    sc: np.ndarray
    hang: np.ndarray
    p_nom: np.ndarray
    rnd_idx: np.ndarray
    rnd_spread: np.ndarray
    ci: np.ndarray
    cf: np.ndarray

    @property
    def period(self) -> float:
        return 1.0 / self.rate

    @property
    def n_obs(self) -> int:
        """The core's raw observation components (before version 1's scaling)."""
        return len(self.observation_names)

    @property
    def agent_observation_names(self) -> tuple[str, ...]:
        """What each component of an agent's observation is."""
        return self.observation_names if self.learnable is None else self.learnable.names

    @property
    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        return self.system.input_limits

    def action_text(self) -> str:
        """What one action is: its size, dtype, the inputs and their range."""
        names = ", ".join(self.system.input_names)
        m = self.system.n_inputs
        if self.action_units == "physical":
            lo, hi = self.limits
            span = ", ".join(f"{n} in [{a:g}, {b:g}]" for n, a, b in
                             zip(self.system.input_names, lo, hi, strict=True))
        else:
            span = f"{names} in [-1, 1] onto their limits"
        return f"{m} real number(s) ({span}; beyond the range, saturated), {self.dtype.name}"

    def physical_input(self, action: np.ndarray) -> np.ndarray:
        """The saturated input an action applies (as the core computes it)."""
        lo, hi = self.limits
        a = np.asarray(action, dtype=float)
        u = a if self.action_units == "physical" else lo + 0.5 * (a + 1.0) * (hi - lo)
        applied: np.ndarray = np.minimum(np.maximum(u, lo), hi)
        return applied

    @property
    def n_params(self) -> int:
        return int(self.p_nom.shape[0])

    def settings(self, *, chunks: int = 1, autoreset: bool = False) -> np.ndarray:
        """``ci`` for a step of blocks of *chunks* copies, with or without autoreset."""
        ci = self.ci.copy()
        ci[CI_SLOTS.index("chunks")] = max(1, int(chunks))
        ci[CI_SLOTS.index("autoreset")] = int(autoreset)
        return ci

    def rows(self, copies: int) -> tuple[np.ndarray, np.ndarray]:
        """Fresh per-copy rows ``fs`` ``[x | p | energy upright, hanging]`` and ``us``
        ``[generator words | periods taken | autoreset due]``, at the task's start."""
        n = self.system.n_states
        fs = np.zeros((copies, n + self.n_params + 2))
        fs[:, :n] = np.asarray(self.task.start, dtype=float)
        fs[:, n:n + self.n_params] = self.p_nom
        return fs, np.zeros((copies, US_WIDTH), dtype=np.uint64)

    def state_of(self, fs: np.ndarray) -> np.ndarray:
        """The states in rows *fs* (a view)."""
        return fs[:, :self.system.n_states]

    def params_of(self, fs: np.ndarray) -> np.ndarray:
        """The parameter vectors in rows *fs* (a view)."""
        n = self.system.n_states
        return fs[:, n:n + self.n_params]

    def describe(self) -> dict[str, object]:
        return {
            "system": self.system.key,
            "task": self.task.name,
            "rate": self.rate,
            "physics_step": self.physics_step,
            "integrator": self.integrator,
            "n_samples": self.n_samples,
            "observe": self.observe,
            "observation": list(self.observation_names),
            "action_units": self.action_units,
            "noise": self.noise is not None,
            "randomize": dict(self.randomize),
            "alive_bonus": self.alive_bonus,
            "at": dict(self.at) if self.at else None,
            "rig": self.rig.describe() if self.rig is not None else None,
        }

    def draw_episode(self, generator: np.random.Generator) -> tuple[np.ndarray, np.ndarray, int]:
        """An episode's start drawn from *generator*, in this order: the initial state from
        the task's distribution, the randomized parameters, the noise seed (an integer:
        ``simulate(..., seed=it)`` draws the same noise)."""
        x0 = self.task.draw_initial(generator)
        p = self.p_nom.copy()
        if self.rnd_idx.size:
            p[self.rnd_idx] *= 1.0 + self.rnd_spread * generator.uniform(-1.0, 1.0,
                                                                         self.rnd_idx.size)
        return np.asarray(x0, dtype=float), p, int(generator.integers(0, 2**63 - 1))


def build_core(
    system: object,
    task: str,
    *,
    params: Mapping[str, object] | None = None,
    rate: float | None = None,
    physics_step: float | None = None,
    observe: str = "outputs",
    noise: bool = True,
    randomize: Mapping[str, object] | None = None,
    action_units: str = "normalized",
    alive_bonus: float = ALIVE_BONUS,
    at: Mapping[str, object] | None = None,
    integrator: str = integrators.DEFAULT,
    version: int = 0,
    dtype: object = None,
    rig: object = None,
    lanes: bool = False,
) -> Core:
    """Validate an environment's options (every problem at once) and pack them. *lanes*:
    the core steps copies eight at a time (a vector environment's; the same bits) where the
    integrator has a lanes step (its table entry's ``lanes``)."""
    sysm = bind_system(system, params)
    if not sysm.n_inputs:
        raise EnvError(f"{sysm.key} has no input: there is nothing for an agent to do")
    point = _point(sysm, at)
    if point is None:
        tsk = get_task(sysm, task)
    else:
        try:
            tsk = get_task(sysm, task, at=point)
        except DesignError as exc:  # no equilibrium there, or a swing-up
            raise EnvError(str(exc)) from None
    problems: list[str] = []
    if rate is None:  # the learnable form may slow a rig that falls slowly (learnable_rate)
        run_rate: float | None = learnable_rate(sysm, tsk) if version == 1 else tsk.rate
    else:
        run_rate = positive(rate, "rate [Hz]", problems)
    wrong = integrators.check(integrator, what="integrator=")
    if wrong is not None:
        problems.append(wrong)
        integrator = integrators.DEFAULT
    h, n_sub = _physics_step(run_rate, physics_step, integrator, problems)
    bonus = _check_options(observe, action_units, noise, alive_bonus, problems)
    rnd = _randomization(sysm, randomize, problems)
    float_type = _version_dtype(version, dtype, problems)
    effects = _rig(sysm, rig, run_rate, problems)
    if problems or run_rate is None or h is None or n_sub is None or bonus is None:
        raise EnvError("; ".join(problems) if problems else "invalid environment settings")
    return _packed(sysm, tsk, point, run_rate=run_rate, h=h, n_sub=n_sub, integrator=integrator,
                   observe=observe, noise=noise, rnd=rnd, action_units=action_units,
                   bonus=bonus, lanes=lanes, version=int(version), dtype=float_type,
                   rig=effects)


def _rig(sysm: System, rig: object, rate: float | None, problems: list[str]) -> Rig | None:
    """The option ``rig``: a :class:`~equilibrist.sim.rig.Rig` or a mapping of its options
    (``{"torque_response": 0.5, "measurement_delay": 2}``), checked on *sysm* at *rate*;
    None for none (or one that adds nothing)."""
    if rig is None:
        return None
    if isinstance(rig, Mapping):
        known = [f for f in Rig.__dataclass_fields__]
        unknown = [k for k in rig if k not in known]
        if unknown:
            problems.extend(f"rig: unknown effect {k!r} ({nearest(str(k), known)})"
                            for k in unknown)
            return None
        values = {k: tuple(v) if isinstance(v, list) else v for k, v in rig.items()}
        rig = Rig(**values)  # type: ignore[arg-type]
    if not isinstance(rig, Rig):
        problems.append(f"rig: expected an equilibrist.sim.rig.Rig or a mapping of its options, "
                        f"got {type(rig).__name__}")
        return None
    found = rig.problems(sysm, rate)
    problems.extend(found)
    return None if found or rig.off else rig


def _physics_step(run_rate: float | None, physics_step: float | None, integrator: str,
                  problems: list[str]) -> tuple[float | None, int | None]:
    """The physics step and the steps per period, as a run splits its period
    (:func:`~equilibrist.sim.setup_steps.split_period`), for the option ``physics_step``."""
    if run_rate is None:
        return None, None
    return split_period(run_rate, physics_step, integrator, problems, option="physics_step")


def _check_options(observe: str, action_units: str, noise: bool, alive_bonus: float,
                   problems: list[str]) -> float | None:
    """The switches checked by value; the alive bonus (None if it is not a finite number)."""
    if observe not in OBSERVE:
        problems.append(f"observe={observe!r}: expected one of {', '.join(map(repr, OBSERVE))}")
    if action_units not in ACTION_UNITS:
        problems.append(
            f"action_units={action_units!r}: expected one of {', '.join(map(repr, ACTION_UNITS))}"
        )
    if not isinstance(noise, bool):
        problems.append(f"noise={noise!r}: expected True or False")
    try:
        bonus = float(alive_bonus)
        if not math.isfinite(bonus):
            raise ValueError
    except (TypeError, ValueError):
        problems.append(f"alive_bonus={alive_bonus!r}: expected a finite number (reward per second)")
        return None
    return bonus


def _version_dtype(version: object, dtype: object, problems: list[str]) -> np.dtype[np.floating]:
    """The option ``dtype`` (float32 by default from version 1 on, float64 before), checked
    with ``version``."""
    if isinstance(version, bool) or version not in VERSIONS:
        problems.append(f"version={version!r}: expected one of {', '.join(map(str, VERSIONS))}")
        version = 0
    if dtype is None:
        return np.dtype(np.float32 if version else np.float64)
    try:
        given = np.dtype(dtype)  # type: ignore[call-overload]
    except TypeError:
        given = None
    if given not in (np.dtype(np.float32), np.dtype(np.float64)):
        problems.append(f"dtype={dtype!r}: expected numpy.float32 or numpy.float64")
        return np.dtype(np.float64)
    out: np.dtype[np.floating] = given
    return out


def _randomization(sysm: System, randomize: Mapping[str, object] | None,
                   problems: list[str]) -> dict[str, float]:
    """Domain randomization: the relative spreads of physical parameters, checked."""
    pnames = sysm.spec.parameter_names
    limit_names = {f"{i}_{s}" for i in sysm.input_names for s in ("min", "max")}
    rnd: dict[str, float] = {}
    if randomize is not None and not isinstance(randomize, Mapping):
        problems.append(f"randomize: expected {{parameter: relative spread}}, got {type(randomize).__name__}")
        return rnd
    for name, spread in (randomize or {}).items():
        if name not in pnames:
            problems.append(f"randomize: {sysm.key} has no parameter {name!r} ({nearest(name, pnames)})")
            continue
        if name in limit_names:
            problems.append(
                f"randomize: {name} is an input limit (the action's scale), not a physical parameter"
            )
            continue
        try:
            s = float(spread)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            s = math.nan
        if not (math.isfinite(s) and 0.0 <= s < 1.0):
            problems.append(
                f"randomize: the spread of {name} is {spread!r}; expected a relative spread "
                "in [0, 1) (0.2 draws it within +-20 % of its value)"
            )
            continue
        if sysm.params[name] == 0.0 and s > 0:
            problems.append(f"randomize: {name} is 0, so a relative spread can not change it")
            continue
        rnd[name] = s
    return rnd


def _packed(sysm: System, tsk: Task, point: dict[str, float] | None, *, run_rate: float,
            h: float, n_sub: int, integrator: str, observe: str, noise: bool,
            rnd: dict[str, float], action_units: str, bonus: float, lanes: bool, version: int,
            dtype: np.dtype[np.floating], rig: Rig | None = None) -> Core:
    """The validated settings packed into the core's arrays (``ci``, ``cf``)."""
    names = sysm.state_names
    n = sysm.n_states
    outputs = tuple(sysm.spec.outputs) or tuple(names)
    c_idx = np.array([names.index(o) for o in outputs], dtype=np.int64)
    lw = np.zeros((n, 0))
    lv = np.zeros((0, 0))
    spec_noise = None
    if noise:
        # The rig's own noise, as simulate draws it: process noise held over
        # each physics step with covariance QN / h, sensor noise per sample.
        spec_noise = Noise.from_spec(sysm, outputs=outputs, rate=run_rate)
        lw = fixed.matmul(spec_noise.process_gain, spec_noise.process_root) / math.sqrt(h)
        lw = lw[:, np.any(lw != 0.0, axis=0)]
        lv = square_root(spec_noise.measurement_covariance, "the measurement noise covariance")
    region = np.array([[-np.inf] * n, [np.inf] * n])
    for name, (lo, hi) in tsk.region.items():
        region[0, names.index(name)] = lo
        region[1, names.index(name)] = hi
    hang = np.array(
        [sysm.state_index(c) for c in (sysm.spec.hanging or {})],
        dtype=np.int64,
    )
    n_samples = max(1, math.ceil(tsk.duration * run_rate - 1e-9))
    pnames = sysm.spec.parameter_names
    rnd_idx = np.array([pnames.index(k) for k in rnd], dtype=np.int64)
    op = np.concatenate([tsk.x_op, tsk.u_op]).astype(float)
    sc = np.concatenate([tsk.state_scales, tsk.input_scales]).astype(float)
    rnd_spread = np.array(list(rnd.values()), dtype=float)
    p_nom = np.array(sysm.p, dtype=float)
    ci, cf = _pack(
        ints={"n_sub": n_sub, "n_samples": n_samples, "observe_state": int(observe == "state"),
              "reward": TASK_NAMES.index(tsk.name), "physical": int(action_units == "physical"),
              "chunks": 1, "autoreset": 0, "integrator": integrators.number(integrator),
              "ny": len(c_idx), "nw": lw.shape[1], "nlv": lv.shape[0], "nhang": len(hang),
              "nrnd": len(rnd_idx), "np": len(p_nom)},
        index_blocks={"c_idx": c_idx, "hang": hang, "rnd_idx": rnd_idx},
        floats={"h": h, "dt": 1.0 / run_rate, "bonus": bonus, "rtol": integrators.RTOL,
                "atol": integrators.ATOL},
        float_blocks={"region": region, "op": op, "iscale": 1.0 / sc,
                      "start": np.asarray(tsk.start, dtype=float),
                      "spread": np.asarray(tsk.spread, dtype=float), "p_nom": p_nom,
                      "rnd_spread": rnd_spread, "lv": lv, "lw": lw},
    )
    return Core(
        system=sysm, task=tsk, rate=float(run_rate), physics_step=float(h), n_sub=int(n_sub),
        n_samples=int(n_samples), integrator=integrator, observe=observe,
        observation_names=tuple(names) if observe == "state" else outputs,
        action_units=action_units, noise=spec_noise, randomize=dict(rnd), alive_bonus=bonus,
        at=point, version=version, dtype=dtype,
        learnable=learnable(sysm, tsk, names if observe == "state" else outputs, dtype)
        if version else None, rig=rig,
        kernel=load_core(sysm, lanes=lanes and integrators.get(integrator).lanes), c_idx=c_idx, lv=np.ascontiguousarray(lv),
        lw=np.ascontiguousarray(lw), region=region,
        op=op, sc=sc, hang=hang, p_nom=p_nom, rnd_idx=rnd_idx, rnd_spread=rnd_spread,
        ci=ci, cf=cf,
    )


_F64 = np.dtype(np.float64)
_F32 = np.dtype(np.float32)


def as_actions(value: object, shape: tuple[int, int] | tuple[int], core: Core, what: str) -> np.ndarray:
    """*value* as the C-contiguous float64 array of *shape* a step takes, or an :class:`EnvError`.

    An array of float64 of the shape passes as it is (the common case, kept
    fast); anything else is converted if it holds real numbers only: text,
    mappings, objects and complex numbers (whose imaginary part a float
    conversion would drop) are refused with what was given and what is expected.
    """
    if type(value) is np.ndarray and value.dtype is _F64 and value.flags.c_contiguous \
            and value.shape == shape:
        return value  # as fast as numpy's own conversion was: a step takes microseconds
    if type(value) is np.ndarray and value.dtype is _F32 and value.shape == shape:
        return value.astype(np.float64)  # a float32 policy's actions
    per = core.action_text()
    expected = (f"expected {per}, shape {shape}" if len(shape) == 1
                else f"expected shape {shape} (num_envs, inputs), each row {per}")
    arr, held = real_array(value)
    if arr is None:
        raise EnvError(f"{what} {given_text(value)} holds {held}, not real numbers: {expected}")
    if arr.shape != shape:
        if arr.size != math.prod(shape):
            raise EnvError(f"{what}: {arr.size} value(s) of shape {arr.shape}, {expected}")
        arr = arr.reshape(shape)
    return np.ascontiguousarray(arr, dtype=np.float64)


def _pack(ints: Mapping[str, int], index_blocks: Mapping[str, np.ndarray],
          floats: Mapping[str, float], float_blocks: Mapping[str, np.ndarray]
          ) -> tuple[np.ndarray, np.ndarray]:
    """``ci`` and ``cf``: the heads in slot order, then the blocks (row-major), each
    block's offset written in ``ci``'s slot ``o_<name>``."""
    head = dict(ints)
    ci_tail: list[int] = []
    for name, block in index_blocks.items():
        head[f"o_{name}"] = len(CI_SLOTS) + len(ci_tail)
        ci_tail.extend(int(v) for v in np.asarray(block).ravel())
    cf_list = [float(floats[name]) for name in CF_SLOTS]
    for name, block in float_blocks.items():
        head[f"o_{name}"] = len(cf_list)
        cf_list.extend(float(v) for v in np.asarray(block, dtype=float).ravel())
    ci = np.array([int(head[name]) for name in CI_SLOTS] + ci_tail, dtype=np.int64)
    return ci, np.array(cf_list, dtype=np.float64)


def _point(system: System, at: object) -> dict[str, float] | None:
    """The option ``at`` checked (a mapping of the system's states to finite numbers), or
    None when it is not given; every problem in one :class:`EnvError`."""
    if at is None:
        return None
    problems = check_point(system, at)
    if problems:
        raise EnvError("; ".join(problems))
    assert isinstance(at, Mapping)
    return {str(k): float(v) for k, v in at.items()} or None


def unknown_task(task: object) -> UnknownNameError:
    return UnknownNameError(f"task: expected 'balance' or 'swingup', got {task!r}")
