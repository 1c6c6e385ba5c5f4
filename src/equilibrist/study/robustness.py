"""A controller's robustness scorecard: RealAIGym's families, run on the compiled batch.

RealAIGym's double-pendulum benchmark (``double_pendulum.analysis.benchmark``
and the v2 leaderboards' ``benchmark_controller.py``) scores a controller
by runs of 10 s at 500 Hz from a start (hanging at rest for a swing-up),
each a *success* when its final state is within ``(0.35, 0.35, 1, 1)`` of
the goal (the angles taken modulo a turn), over these families:

* **model**: each model parameter one at a time over 21 values (the rig's
  ``Ir`` 0 to 1e-4, ``m1 r1``, ``I1``, ``m2 r2``, ``m2``, ``I2`` from 0.75 to
  1.25 times their value, damping ``b`` -0.1 to 0.1, Coulomb ``cf`` -0.2 to
  0.2), the controller designed for the nominal plant; score: the share of
  successes over all 210 runs;
* **velocity noise**: noise of 0 to 0.5 rad/s on the measured velocities,
  21 values, 10 runs each; score: the share of values where more than
  half the runs succeed;
* **torque noise**: 0 to 1.1 N m on the actuated torque, the same way;
* **torque response**: the motor's ``k`` from 0.1 to 2.0, 21 runs; score:
  the share of successes;
* **delay**: the measurement 0 to 40 ms late (``int(d / T)`` periods), 21 runs;
* **perturbation**: 50 runs with three random Gaussian torque pulses drawn
  for each joint (widths 0.05 to 0.1 s, peaks 0.5 to 5 N m, at least 1 s
  apart), of which the benchmark's plant applies the actuated joint's only
  (its input matrix zeroes the passive joint's torque).

Here every family is one or more calls of :func:`~equilibrist.sim.batch.simulate_batch`
with the rig's effects of :mod:`equilibrist.sim.rig`, and a family of our own
beside them: **velocity noise, filtered** (the same noise through a
first-order low-pass of the velocities, ``filter_cutoff`` Hz), which the
benchmark's code names but does not run. Where the system is not the
rig, the model family varies each of its own parameters (not its inputs'
limits or gravity) from 0.75 to 1.25 times a nonzero value. See
docs/robustness.md for where this differs from the benchmark.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from equilibrist.errors import SimulationError
from equilibrist.numeric.system import System
from equilibrist.sim.batch import simulate_batch
from equilibrist.sim.batch_inputs import child_seed
from equilibrist.sim.noise import SeedLike, seed_sequence
from equilibrist.sim.rig import Rig

#: The benchmark's tolerance of the final state: positions, then velocities.
POSITION_TOLERANCE = 0.35
VELOCITY_TOLERANCE = 1.0
#: Values per family (the benchmark's ``N_var``).
N_VALUES = 21
#: The families in the benchmark's order, and ours after.
FAMILIES = ("model", "velocity_noise", "torque_noise", "torque_response", "delay",
            "perturbation", "velocity_noise_filtered")
#: The families the benchmark scores (the others are reported beside them).
BENCHMARK_FAMILIES = FAMILIES[:6]
#: The rig's parameters varied in the model family, in the benchmark's order.
RIG_PARAMETERS = ("Ir", "m1r1", "I1", "b1", "cf1", "m2r2", "m2", "I2", "b2", "cf2")


def relative_values(value: float, n: int = N_VALUES) -> np.ndarray:
    """The benchmark's ``get_par_list(value, 0.75, 1.25, n)``."""
    if n % 2 == 0:
        n += 1
    base = np.linspace(0.75, 1.25, n) if value != 0 else np.linspace(0, 1.25, n)
    return base * value


@dataclass(frozen=True)
class ModelCurve:
    """One model parameter's values and the parameters each run had."""

    name: str
    values: np.ndarray
    params: dict[str, np.ndarray]


def model_curves(system: System) -> list[ModelCurve]:
    """The model family's parameters, values and per-run parameter vectors: the rig's list
    where the system has its parameters, else each physical parameter at +-25 %."""
    p = dict(system.params)
    names = set(p)
    rig = {"Ir", "m1", "r1", "I1", "b1", "cf1", "m2", "r2", "I2", "b2", "cf2"} <= names
    curves: list[ModelCurve] = []
    if rig:
        lists: dict[str, np.ndarray] = {
            "Ir": np.linspace(0.0, 1e-4, N_VALUES),
            "m1r1": relative_values(p["m1"] * p["r1"]), "I1": relative_values(p["I1"]),
            "b1": np.linspace(-0.1, 0.1, N_VALUES), "cf1": np.linspace(-0.2, 0.2, N_VALUES),
            "m2r2": relative_values(p["m2"] * p["r2"]), "m2": relative_values(p["m2"]),
            "I2": relative_values(p["I2"]), "b2": np.linspace(-0.1, 0.1, N_VALUES),
            "cf2": np.linspace(-0.2, 0.2, N_VALUES)}
        for name, values in lists.items():
            if name in ("m1r1", "m2r2"):  # the mass kept, the centre of mass moved
                j = name[1]
                varied = {f"r{j}": values / p[f"m{j}"]}
            else:
                varied = {name: values}
            curves.append(ModelCurve(name, values, varied))
        return curves
    limits = {f"{n}_{b}" for n in system.input_names for b in ("min", "max")}
    for name, value in p.items():
        if name in limits or name == "g" or value == 0:
            continue
        curves.append(ModelCurve(name, relative_values(float(value)),
                                 {name: relative_values(float(value))}))
    return curves


def success(system: System, final: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """Per run, whether its final state is within the benchmark's tolerance of *goal*
    (positions within 0.35, an angle modulo a turn; velocities within 1)."""
    nq = int(system.functions.N_Q)
    d = np.atleast_2d(final) - goal
    ok = np.ones(d.shape[0], dtype=bool)
    for i in range(system.n_states):
        di = d[:, i]
        if i < nq and system.state_units[i] == "rad":
            di = di - 2 * math.pi * np.round(di / (2 * math.pi))
        tol = POSITION_TOLERANCE if i < nq else VELOCITY_TOLERANCE
        ok &= np.abs(di) < tol
    return ok


@dataclass(frozen=True)
class Family:
    """One family's values, each value's successes (one per run) and its score."""

    name: str
    values: list[float]
    successes: list[list[bool]]
    score: float
    repeated: bool
    curves: dict[str, list[bool]] = field(default_factory=dict)
    skipped: dict[str, list[float]] = field(default_factory=dict)

    def describe(self) -> dict[str, object]:
        out: dict[str, object] = {"score": self.score, "values": self.values,
                                  "successes": self.successes}
        if self.curves:
            out["parameters"] = self.curves
        if self.skipped:
            out["skipped"] = self.skipped
        return out


@dataclass(frozen=True)
class Robustness:
    """The scorecard: every family, the benchmark's mean over its six, the settings."""

    system: str
    families: dict[str, Family]
    settings: dict[str, object]
    elapsed: float

    @property
    def scores(self) -> dict[str, float]:
        return {name: f.score for name, f in self.families.items()}

    @property
    def benchmark_score(self) -> float:
        """The mean of the benchmark's families that were run."""
        own = [f.score for n, f in self.families.items() if n in BENCHMARK_FAMILIES]
        return float(np.mean(own)) if own else float("nan")

    def describe(self) -> dict[str, object]:
        return {"system": self.system, "scores": self.scores,
                "benchmark_score": self.benchmark_score, "elapsed_s": self.elapsed,
                "settings": self.settings,
                "families": {n: f.describe() for n, f in self.families.items()}}


def _score(successes: list[list[bool]], repeated: bool) -> float:
    if not successes:
        return float("nan")
    if repeated:  # the share of values where more than half the runs succeed
        return float(np.mean([np.mean(s) > 0.5 for s in successes]))
    return float(np.mean([v for s in successes for v in s]))


def robustness(system: System, controller: object, *, x0: object = None,
               goal: Sequence[float] | None = None, rate: float = 500.0, duration: float = 10.0,
               repetitions: int = 10, perturbation_runs: int = 50, filter_cutoff: float = 50.0,
               families: Sequence[str] = FAMILIES, seed: SeedLike = 0,
               workers: int | None = None,
               progress: Callable[[str], None] | None = None) -> Robustness:
    """The robustness scorecard of *controller* on *system* (see the module).

    *x0*: the start (as :func:`~equilibrist.sim.run.simulate` takes it; default the
    operating point); *goal*: the state to end at (default the operating point);
    *rate*: the control rate, with one RK4 step per period as the benchmark; *families*:
    those to run (of :data:`FAMILIES`).
    """
    import time

    unknown = [f for f in families if f not in FAMILIES]
    if unknown:
        raise SimulationError(f"robustness families {unknown}: expected some of {', '.join(FAMILIES)}")
    nq = int(system.functions.N_Q)
    if nq == 0 or system.n_states != 2 * nq:
        raise SimulationError(f"{system.key} has no joints' positions and velocities (a state "
                              "[q, q_dot]): the robustness families need them")
    for name, value in (("repetitions", repetitions), ("perturbation_runs", perturbation_runs)):
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise SimulationError(f"{name} = {value!r}: expected a whole number >= 1")
    base = seed_sequence(seed)
    goal_x = np.asarray(system.operating_point().x if goal is None else goal, dtype=float)
    common: dict[str, object] = dict(duration=duration, rate=rate, physics_step=1.0 / rate,
                                     region={}, x0=x0, workers=workers)
    start = time.perf_counter()

    def finals(runs: int, key: int, **kw: object) -> np.ndarray:
        batch = simulate_batch(system, controller, runs=runs, seed=child_seed(base, key),
                               **common, **kw)  # type: ignore[arg-type]
        return success(system, batch.final_state, goal_x)

    out: dict[str, Family] = {}
    for key, name in enumerate(FAMILIES):
        if name not in families:
            continue
        if progress is not None:
            progress(name)
        out[name] = _family(name, system, finals, key, rate=rate, repetitions=repetitions,
                            perturbation_runs=perturbation_runs, filter_cutoff=filter_cutoff)
    settings: dict[str, object] = {
        "rate": rate, "duration": duration, "repetitions": repetitions,
        "perturbation_runs": perturbation_runs, "filter_cutoff": filter_cutoff,
        "goal": goal_x.tolist(),
        "x0": None if x0 is None else ({k: float(v) for k, v in x0.items()}
                                       if isinstance(x0, Mapping)
                                       else np.asarray(x0, dtype=float).tolist()),
        "tolerance": [POSITION_TOLERANCE] * nq + [VELOCITY_TOLERANCE] * nq}
    return Robustness(system.key, out, settings, time.perf_counter() - start)


def _family(name: str, system: System, finals: Callable[..., np.ndarray], key: int, *,
            rate: float, repetitions: int, perturbation_runs: int,
            filter_cutoff: float) -> Family:
    """One family's runs."""
    sub = 1000 * key
    if name == "model":
        return _model(system, finals, sub)
    if name == "perturbation":
        rig = Rig(perturbations=3, perturbation_gap=1.0, perturbation_width=(0.05, 0.1),
                  perturbation_amplitude=(0.5, 5.0), perturb_passive=False)
        ok = finals(perturbation_runs, sub, rig=rig)
        return Family(name, [], [[bool(v)] for v in ok], float(np.mean(ok)), False)
    values: np.ndarray
    make: Callable[[float], Rig]
    repeated = name in ("velocity_noise", "torque_noise", "velocity_noise_filtered")
    if name == "velocity_noise":
        values, make = np.linspace(0.0, 0.5, N_VALUES), lambda v: Rig(velocity_noise=v)
    elif name == "velocity_noise_filtered":
        values = np.linspace(0.0, 0.5, N_VALUES)
        make = lambda v: Rig(velocity_noise=v, velocity_filter=filter_cutoff)  # noqa: E731
    elif name == "torque_noise":
        values, make = np.linspace(0.0, 1.1, N_VALUES), lambda v: Rig(torque_noise=v)
    elif name == "torque_response":
        values, make = np.linspace(0.1, 2.0, N_VALUES), lambda v: Rig(torque_response=v)
    else:  # delay: the benchmark's int(d / dt) periods of the whole measurement
        values = np.linspace(0.0, 0.04, N_VALUES)
        make = lambda v: Rig(measurement_delay=int(v / (1.0 / rate)))  # noqa: E731
    successes = [[bool(s) for s in finals(repetitions if repeated else 1, sub + i,
                                          rig=make(float(v)))]
                 for i, v in enumerate(values)]
    return Family(name, [float(v) for v in values], successes, _score(successes, repeated),
                  repeated)


def _model(system: System, finals: Callable[..., np.ndarray], sub: int) -> Family:
    """The model family in one batch: every parameter's values, one run each."""
    spec = {p.name: p for p in system.spec.parameters}
    curves = model_curves(system)
    columns: dict[str, list[float]] = {n: [] for n in system.params}
    owners: list[tuple[str, float]] = []
    skipped: dict[str, list[float]] = {}
    for curve in curves:
        for i, value in enumerate(curve.values):
            row = dict(system.params)
            for pname, vals in curve.params.items():
                row[pname] = float(vals[i])
            bad = [spec[n].check(v) for n, v in row.items() if n in spec]
            if any(b is not None for b in bad):
                skipped.setdefault(curve.name, []).append(float(value))
                continue
            for n, column in columns.items():
                column.append(float(row[n]))
            owners.append((curve.name, float(value)))
    ok = finals(len(owners), sub, params={n: np.array(v) for n, v in columns.items()}) \
        if owners else np.zeros(0, dtype=bool)
    per: dict[str, list[bool]] = {c.name: [] for c in curves}
    values: list[float] = []
    for (cname, value), s in zip(owners, ok, strict=True):
        per[cname].append(bool(s))
        values.append(value)
    successes = [[bool(s)] for s in ok]
    # A value a parameter's own range refuses cannot run: it counts as a failure, as the
    # benchmark's run of an impossible plant would not end at the goal.
    n_all = len(owners) + sum(len(v) for v in skipped.values())
    score = float(np.sum(ok) / n_all) if n_all else float("nan")
    return Family("model", values, successes, score, False, curves=per, skipped=skipped)


__all__ = ["BENCHMARK_FAMILIES", "FAMILIES", "Family", "ModelCurve", "Robustness",
           "model_curves", "relative_values", "robustness", "success"]
