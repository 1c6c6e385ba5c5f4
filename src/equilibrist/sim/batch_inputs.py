"""What a batch runs from: its counts and mappings checked, the initial states and
parameters of every run, the seeds of its runs (:func:`child_seed`), and draws of
initial states and parameters (:func:`sample_uniform`)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from equilibrist.errors import SimulationError, nearest
from equilibrist.mechanics.spec import Parameter
from equilibrist.numeric.system import System
from equilibrist.sim import budget, setup_checks
from equilibrist.sim.noise import SeedLike, describe_seed, seed_sequence


def _count(value: object, name: str) -> int:
    """*value* as a whole number >= 1, or a :class:`SimulationError` naming *name*."""
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < 1:
        raise SimulationError(f"{name} = {value!r}: expected a whole number >= 1")
    return int(value)


def _floats(value: object, what: str) -> np.ndarray:
    """*value* as an array of floats, or a :class:`SimulationError` naming *what*."""
    try:
        return np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SimulationError(f"{what} = {value!r}: expected numbers") from None


def _mapping(value: object, what: str, expected: str) -> Mapping[object, object]:
    if not isinstance(value, Mapping):
        raise SimulationError(f"{what} = {value!r}: expected a mapping {expected}")
    return value


def child_seed(base: np.random.SeedSequence, index: int) -> np.random.SeedSequence:
    """The *index*-th child of *base*, independent of how often *base* was spawned."""
    return np.random.SeedSequence(base.entropy, spawn_key=(*base.spawn_key, int(index)))


def child_descriptions(base: np.random.SeedSequence, runs: int) -> list[dict[str, object]]:
    """``describe_seed(child_seed(base, i))`` for ``i < runs``, without making the children
    (a batch whose runs draw nothing needs their names only: some 40 us a run saved)."""
    entropy = describe_seed(base)["entropy"]
    key = [int(k) for k in base.spawn_key]
    if isinstance(entropy, list):
        return [{"entropy": list(entropy), "spawn_key": [*key, i]} for i in range(runs)]
    return [{"entropy": entropy, "spawn_key": [*key, i]} for i in range(runs)]


def _initial_states(system: System, x0: object, runs: int, x_op: np.ndarray) -> np.ndarray:
    n = system.n_states
    if x0 is None:
        return np.tile(x_op, (runs, 1))
    if isinstance(x0, Mapping):
        out = np.tile(x_op, (runs, 1))
        for name, values in x0.items():
            if name not in system.state_names:
                raise SimulationError(f"initial state: no state {name!r} ({nearest(str(name), system.state_names)})")
            v = _floats(values, f"initial {name}")
            if v.ndim == 0:
                v = np.full(runs, float(v))
            if v.shape != (runs,):
                raise SimulationError(f"initial {name} has {v.size} values for {runs} runs")
            out[:, system.state_names.index(name)] = v
        arr = out
    else:
        arr = _floats(x0, "initial states x0")
        if arr.ndim == 1:
            arr = np.tile(arr, (runs, 1))
        if arr.shape != (runs, n):
            raise SimulationError(f"initial states have shape {arr.shape}, expected ({runs}, {n})")
    bad = ~np.all(np.isfinite(arr), axis=1)
    if bad.any():
        i = int(np.nonzero(bad)[0][0])
        raise SimulationError(
            f"{int(bad.sum())} initial states are not finite (first: run {i}, {arr[i].tolist()})"
        )
    return np.ascontiguousarray(arr)


def _parameter_matrix(system: System, params: Mapping[str, object] | None, runs: int) -> np.ndarray:
    names = system.spec.parameter_names
    base = np.tile(np.array(system.p, dtype=float), (runs, 1))
    if not params:
        return base
    by_name = {p.name: p for p in system.spec.all_parameters}
    problems = []
    for name, values in params.items():
        if name not in by_name:
            problems.append(f"unknown parameter {name!r} of {system.key}: {nearest(str(name), names)}")
            continue
        try:
            v = np.asarray(values, dtype=float)
        except (TypeError, ValueError):
            problems.append(f"parameter {name} = {values!r}: expected a number or one number per run")
            continue
        if v.ndim == 0:
            v = np.full(runs, float(v))
        if v.shape != (runs,):
            problems.append(f"parameter {name} has {v.size} values for {runs} runs")
            continue
        if not np.all(np.isfinite(v)):
            problems.append(f"parameter {name} has values that are not finite")
            continue
        for extreme in (v.min(), v.max()):
            problem = by_name[name].check(float(extreme))
            if problem:
                problems.append(problem)
                break
        base[:, names.index(name)] = v
    for inp in system.input_names:
        lo = base[:, names.index(f"{inp}_min")]
        hi = base[:, names.index(f"{inp}_max")]
        if np.any(lo >= hi):
            problems.append(f"input limits of {inp}: some runs have {inp}_min >= {inp}_max")
    if problems:
        raise SimulationError("; ".join(problems))
    return base


def _spread_problem(param: Parameter, nominal: float, rel: float) -> str | None:
    """Why a relative spread *rel* of *param* about *nominal* is refused, or None.

    The draws lie within ``nominal * (1 +- rel)``: the whole of that range
    must be valid, whatever the draw, so a spread is checked as a spread.
    """
    ends = sorted((nominal * (1.0 - rel), nominal * (1.0 + rel)))
    if all(param.check(v) is None for v in ends):
        return None
    hint = ""
    if param.low == 0.0 and rel >= 1.0 and nominal > 0:
        hint = "; a parameter that must stay positive takes a relative spread below 1"
    return (f"spread {param.name}={rel:g} draws {param.name} from {ends[0]:g} to {ends[1]:g} "
            f"(nominal {nominal:g} times 1 +- {rel:g}), outside its valid range "
            f"{param.range_text}{hint}")


def sample_uniform(
    system: System, runs: int, *, ranges: Mapping[str, tuple[float, float]] | None = None,
    spread: Mapping[str, float] | None = None, seed: SeedLike = None,
    x_op: np.ndarray | None = None,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Initial states uniform in *ranges* and parameters uniform within ``(1 +- spread)``.

    Returns ``(x0s, params)`` for :func:`simulate_batch`. States not in
    *ranges* stay at *x_op* (default: the canonical operating point).
    """
    setup_checks.check_system(system)
    runs = _count(runs, "runs")
    if ranges is not None:
        _mapping(ranges, "ranges", "{state: (low, high)}")
    if spread is not None:
        _mapping(spread, "spread", "{parameter: relative spread}")
    if x_op is None:
        x_op, _ = setup_checks.operating_point(system, None)
    budget.check_memory(runs * (system.n_states + len(spread or {})) * 8.0,
                        f"a batch of {runs} runs", None)
    gen = np.random.default_rng(seed_sequence(seed))
    x0s = np.tile(np.asarray(x_op, dtype=float), (runs, 1))
    problems = []
    for name, bounds in (ranges or {}).items():
        if name not in system.state_names:
            problems.append(f"no state {name!r} ({nearest(str(name), system.state_names)})")
            continue
        try:
            lo, hi = (float(b) for b in bounds)
        except (TypeError, ValueError):
            problems.append(f"range of {name} = {bounds!r}: expected (low, high)")
            continue
        if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
            problems.append(f"range of {name}: {lo}:{hi} must be finite with low <= high")
            continue
        x0s[:, system.state_names.index(name)] = gen.uniform(lo, hi, runs)
    params: dict[str, np.ndarray] = {}
    by_name = {p.name: p for p in system.spec.all_parameters}
    for name, rel in (spread or {}).items():
        if name not in system.params or name not in by_name:
            problems.append(f"unknown parameter {name!r} of {system.key}: "
                            f"{nearest(str(name), list(system.params))}")
            continue
        if isinstance(rel, bool) or not isinstance(rel, int | float | np.integer | np.floating):
            problems.append(f"spread of {name} = {rel!r}: expected a relative spread, a number >= 0")
            continue
        if not (math.isfinite(rel) and rel >= 0):
            problems.append(f"spread of {name} must be a number >= 0, got {rel}")
            continue
        problem = _spread_problem(by_name[name], float(system.params[name]), float(rel))
        if problem:
            problems.append(problem)
            continue
        nominal = system.params[name]
        params[name] = nominal * (1.0 + gen.uniform(-rel, rel, runs))
    if problems:
        raise SimulationError("; ".join(problems))
    return x0s, params
