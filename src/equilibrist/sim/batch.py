"""Many runs at once: batches, regions of attraction, Monte Carlo robustness.

A batch runs the same controller and settings from many initial states,
parameter sets and noise seeds, in parallel on all cores by default (the
compiled core's ``run_many``, OpenMP threads over runs). Run ``i`` is
exactly the run :func:`~equilibrist.sim.run.simulate` makes with the same
initial state, parameters and ``seed=result.seed(i)``.

By default a batch keeps, per run, the outcome and the metrics that can be
accumulated while running (fell and when, final state, peak and RMS input,
time saturated, peak deviation, estimation error RMS); ``record=True``
keeps every trajectory too, after checking that they fit in memory.
"""

from __future__ import annotations

import json
import math
import multiprocessing
import os
import pickle
import time
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from equilibrist.atomic import atomic_path, write_text
from equilibrist.control.controller import PythonController, python_controller_name
from equilibrist.errors import SimulationError, nearest
from equilibrist.mechanics.spec import Parameter
from equilibrist.numeric.system import System
from equilibrist.sim import _setup, layout
from equilibrist.sim.events import Event
from equilibrist.sim.kernel import Kernel, set_workers
from equilibrist.sim.noise import (
    Noise,
    SeedLike,
    describe_seed,
    generator_state,
    seed_from_description,
    seed_sequence,
)
from equilibrist.sim.result import SimResult, check_result_path, digest_field, read_npz
from equilibrist.sim.run import (
    _progress_bar,
    _result,
    _run_python,
    call_interruptibly,
    fall_reason,
)

# Format 2 adds the peak command beside the peak input applied.
FORMAT = "equilibrist-batch-2"


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


def _mapping(value: object, what: str, expected: str) -> Mapping[Any, Any]:
    if not isinstance(value, Mapping):
        raise SimulationError(f"{what} = {value!r}: expected a mapping {expected}")
    return value


def _threads(workers: object) -> int:
    """The threads a batch would use (for the estimate of a refused batch's time)."""
    count = os.cpu_count() or 1
    if isinstance(workers, int | np.integer) and not isinstance(workers, bool) and workers >= 1:
        count = min(count, int(workers))
    return count


def child_seed(base: np.random.SeedSequence, index: int) -> np.random.SeedSequence:
    """The *index*-th child of *base*, independent of how often *base* was spawned."""
    return np.random.SeedSequence(base.entropy, spawn_key=(*base.spawn_key, int(index)))


@dataclass(frozen=True, eq=False)
class BatchResult:
    """Outcomes of many runs (arrays with one row per run).

    Attributes
    ----------
    x0 : ndarray, shape (runs, n_states)
        Initial states.
    params : ndarray, shape (runs, n_params)
        The plant's parameters of each run (``parameter_names`` order).
    fell, fell_at, fell_code :
        Whether each run fell, when (NaN if it did not), and the index of the
        state that left its region (-2 not finite, -3 integrator failed, -1 none).
    final_state, fell_x : ndarray, shape (runs, n_states)
    peak_input, rms_input : ndarray, shape (runs, n_inputs)
        Largest ``|input|`` applied (after the actuator's limits) and RMS of
        the applied input.
    peak_command : ndarray, shape (runs, n_inputs)
        Largest ``|command|`` (the controller's, before the limits).
    time_saturated : ndarray, shape (runs,)
    peak_deviation, estimation_error_rms : ndarray, shape (runs, n_states)
    rows : ndarray, shape (runs,)
        Samples recorded per run.
    trajectories : ndarray or None, shape (runs, n_rows, width)
        With ``record=True``: the packed rows (see :meth:`run`).
    elapsed : float
        Wall time of the compiled runs [s]; ``steps`` physics steps in all.
    """

    system: str
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    parameter_names: tuple[str, ...]
    x0: np.ndarray
    params: np.ndarray
    fell: np.ndarray
    fell_at: np.ndarray
    fell_code: np.ndarray
    fell_x: np.ndarray
    final_state: np.ndarray
    peak_input: np.ndarray
    peak_command: np.ndarray
    rms_input: np.ndarray
    time_saturated: np.ndarray
    peak_deviation: np.ndarray
    estimation_error_rms: np.ndarray | None
    rows: np.ndarray
    seeds: tuple[dict[str, Any] | None, ...]
    settings: Mapping[str, Any]
    elapsed: float = 0.0
    steps: int = 0
    trajectories: np.ndarray | None = None
    system_digest: str | None = None
    _setup: Any = field(default=None, repr=False)

    def __post_init__(self) -> None:
        for name in ("x0", "params", "fell", "fell_at", "fell_code", "fell_x", "final_state",
                     "peak_input", "peak_command", "rms_input", "time_saturated",
                     "peak_deviation", "estimation_error_rms", "rows", "trajectories"):
            v = getattr(self, name)
            if v is not None:
                v = np.asarray(v)
                v.setflags(write=False)
                object.__setattr__(self, name, v)
        object.__setattr__(self, "settings", MappingProxyType(dict(self.settings)))

    def __repr__(self) -> str:
        return (f"BatchResult({self.system}, {self.runs} runs, {self.stayed_up} stayed up, "
                f"{self.steps_per_second / 1e6:.1f} M steps/s)")

    @property
    def runs(self) -> int:
        return int(self.fell.shape[0])

    @property
    def stayed_up(self) -> int:
        """How many runs stayed up."""
        return int(self.runs - np.count_nonzero(self.fell))

    @property
    def fraction_up(self) -> float:
        return self.stayed_up / self.runs if self.runs else math.nan

    @property
    def steps_per_second(self) -> float:
        return self.steps / self.elapsed if self.elapsed > 0 else math.inf

    def seed(self, index: int) -> np.random.SeedSequence | None:
        """The seed that reproduces run *index* alone with :func:`simulate`."""
        desc = self.seeds[index]
        return None if desc is None else seed_from_description(desc)

    def param(self, name: str) -> np.ndarray:
        """The values of parameter *name* over the runs."""
        if name not in self.parameter_names:
            raise SimulationError(f"no parameter {name!r}: {nearest(name, self.parameter_names)}")
        return self.params[:, self.parameter_names.index(name)]

    def fell_states(self) -> list[str | None]:
        """Per run, the state that left its region (None for runs that stayed up)."""
        return [fall_reason(int(c), self.state_names) if f else None
                for f, c in zip(self.fell, self.fell_code, strict=True)]

    def run(self, index: int) -> SimResult:
        """Run *index* as a :class:`SimResult` (needs ``record=True``)."""
        if self.trajectories is None or self._setup is None:
            raise SimulationError("the batch kept no trajectories: run it with record=True")
        if not 0 <= index < self.runs:
            raise SimulationError(f"run {index} out of range 0..{self.runs - 1}")
        setup = self._setup
        status = layout.STATUS.pack(
            np.int64, rows=self.rows[index], fell=int(self.fell[index]),
            fell_code=self.fell_code[index],
            fell_step=0 if not self.fell[index] else round(self.fell_at[index] / setup.h))
        sysm = setup.system.with_params(**dict(zip(self.parameter_names,
                                                   self.params[index].tolist(), strict=True)))
        s = _setup.Setup(**{**setup.__dict__, "system": sysm, "x0": self.x0[index]})
        seq = self.seed(index)
        return _result(s, np.asarray(self.trajectories[index]), int(self.rows[index]), status,
                       np.asarray(self.fell_x[index]), np.asarray(self.final_state[index]), seq,
                       estimates=setup.estimates)

    def summary(self) -> dict[str, Any]:
        """``runs``, ``stayed_up``, ``fraction_up``, ``steps_per_second`` and friends."""
        fell_at = self.fell_at[self.fell]
        return {
            "system": self.system,
            "runs": self.runs,
            "stayed_up": self.stayed_up,
            # A count (a single run's "fell" is a flag: another name, another type).
            "fallen": int(np.count_nonzero(self.fell)),
            "fraction_up": self.fraction_up,
            "steps": int(self.steps),
            "elapsed": self.elapsed,
            "steps_per_second": self.steps_per_second,
            "fell_at_median": float(np.median(fell_at)) if fell_at.size else None,
            "peak_input_max": dict(zip(self.input_names, self.peak_input.max(axis=0).tolist(), strict=True)) if self.runs else {},
            "time_saturated_mean": float(self.time_saturated.mean()) if self.runs else None,
        }

    def save(self, path: str | Path) -> Path:
        """Write the batch's per-run arrays to ``.npz`` (trajectories are not saved)."""
        p = Path(path)
        if p.suffix.lower() == ".csv":
            return self.to_csv(p)
        check_result_path(p, "a batch")
        meta = {
            "format": FORMAT, "system": self.system, "system_digest": self.system_digest,
            "state_names": list(self.state_names),
            "input_names": list(self.input_names), "parameter_names": list(self.parameter_names),
            "seeds": list(self.seeds), "settings": dict(self.settings), "elapsed": self.elapsed,
            "steps": self.steps,
        }
        arrays = {k: getattr(self, k) for k in (
            "x0", "params", "fell", "fell_at", "fell_code", "fell_x", "final_state", "peak_input",
            "peak_command",
            "rms_input", "time_saturated", "peak_deviation", "rows")}
        if self.estimation_error_rms is not None:
            arrays["estimation_error_rms"] = self.estimation_error_rms
        with atomic_path(p) as tmp:
            np.savez(tmp, meta=np.array(json.dumps(meta)), **arrays)
        return p

    def to_csv(self, path: str | Path) -> Path:
        """A table, one row per run: its initial state, parameters, outcome and metrics."""
        p = Path(path)
        cols: list[tuple[str, np.ndarray]] = [("run", np.arange(self.runs, dtype=float))]
        cols += [(f"{n}_0", self.x0[:, i]) for i, n in enumerate(self.state_names)]
        cols += [(n, self.params[:, i]) for i, n in enumerate(self.parameter_names)]
        cols += [("fell", self.fell.astype(float)), ("fell_at", self.fell_at)]
        cols += [(f"peak_{n}", self.peak_input[:, i]) for i, n in enumerate(self.input_names)]
        cols += [(f"peak_command_{n}", self.peak_command[:, i]) for i, n in enumerate(self.input_names)]
        cols += [(f"rms_{n}", self.rms_input[:, i]) for i, n in enumerate(self.input_names)]
        cols += [("time_saturated", self.time_saturated)]
        cols += [(f"peak_dev_{n}", self.peak_deviation[:, i]) for i, n in enumerate(self.state_names)]
        lines = [f"# {self.system}: {self.runs} runs; fell_at is nan for a run that stayed up",
                 ",".join(n for n, _ in cols)]
        table = np.column_stack([np.asarray(v, dtype=float).reshape(self.runs) for _, v in cols])
        lines += [",".join("nan" if math.isnan(v) else repr(float(v)) for v in row) for row in table]
        write_text(p, "\n".join(lines) + "\n")
        return p

    @classmethod
    def load(cls, path: str | Path) -> BatchResult:
        """Read a batch written by :meth:`save`."""
        p = Path(path)
        try:
            meta, arrays = read_npz(p)
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
            raise SimulationError(f"{p} is not a saved batch: {exc}") from None
        if not isinstance(meta, dict) or meta.get("format") != FORMAT:
            found = meta.get("format") if isinstance(meta, dict) else None
            raise SimulationError(f"{p} is not a saved batch of this version (format {found!r}, "
                                  f"expected {FORMAT!r}): run the batch again")
        _check_batch_file(p, meta, arrays)
        return cls(
            system=meta["system"], state_names=tuple(meta["state_names"]),
            input_names=tuple(meta["input_names"]),
            parameter_names=tuple(meta["parameter_names"]),
            estimation_error_rms=arrays.pop("estimation_error_rms", None),
            seeds=tuple(meta["seeds"]), settings=meta["settings"], elapsed=meta["elapsed"],
            steps=meta["steps"], system_digest=digest_field(meta, f"{p} is not a valid saved batch"),
            **arrays,
        )


_BATCH_ARRAYS = ("x0", "params", "fell", "fell_at", "fell_code", "fell_x", "final_state",
                 "peak_input", "peak_command", "rms_input", "time_saturated", "peak_deviation",
                 "rows")


def _check_batch_file(p: Path, meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
    """Refuse a batch file whose contents are not what :meth:`BatchResult.save` writes."""
    bad = f"{p} is not a valid saved batch"
    for key in ("state_names", "input_names", "parameter_names"):
        v = meta.get(key)
        if not isinstance(v, list) or not all(isinstance(n, str) for n in v):
            raise SimulationError(f"{bad}: {key} should be a list of names")
    if not isinstance(meta.get("system"), str) or not isinstance(meta.get("settings"), dict):
        raise SimulationError(f"{bad}: system and settings are missing or of the wrong type")
    if not isinstance(meta.get("seeds"), list):
        raise SimulationError(f"{bad}: seeds should be a list")
    for key in ("elapsed", "steps"):
        if not isinstance(meta.get(key), (int, float)) or isinstance(meta.get(key), bool):
            raise SimulationError(f"{bad}: {key} should be a number")
    missing = [k for k in _BATCH_ARRAYS if k not in arrays]
    if missing:
        raise SimulationError(f"{bad}: the arrays {', '.join(missing)} are missing")
    runs = arrays["x0"].shape[0] if arrays["x0"].ndim == 2 else -1
    for key, a in arrays.items():
        if a.dtype.kind not in "fiub" or a.ndim == 0 or a.shape[0] != runs:
            raise SimulationError(f"{bad}: {key} is not one row of numbers per run")


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


def simulate_batch(
    system: System,
    controller: object = None,
    *,
    runs: int,
    duration: float,
    x0: object = None,
    params: Mapping[str, object] | None = None,
    seed: SeedLike = None,
    rate: float | None = None,
    physics_step: float | None = None,
    integrator: str = "rk4",
    rtol: float = 1e-8,
    atol: float = 1e-10,
    plant: str = "nonlinear",
    delay: bool = False,
    noise: Noise | None = None,
    reference: object = None,
    events: Sequence[Event] = (),
    region: Mapping[str, tuple[float, float]] | None = None,
    record: bool = False,
    workers: int | None = None,
    max_memory: float | None = None,
    progress: bool = False,
    max_steps: float | None = _setup.DEFAULT_MAX_STEPS,
) -> BatchResult:
    """*runs* independent runs of the same closed loop, in parallel.

    Parameters
    ----------
    runs : int
        Number of runs.
    x0 : array (runs, n_states) or (n_states,), or mapping name -> values, optional
        Initial states (absolute); a mapping overrides components of the
        operating point per run.
    params : mapping name -> values (runs,), optional
        The plant's parameters per run (the controller keeps its design).
    seed : int or SeedSequence, optional
        Run ``i`` uses the ``i``-th child of this seed's sequence.
    record : bool
        Keep every trajectory (checked against *max_memory*, default half
        the available memory, before anything is allocated).
    workers : int, optional
        Threads (default: all cores).
    max_steps : float or None
        The most physics steps the batch may take over all its runs
        (default :data:`~equilibrist.sim._setup.DEFAULT_MAX_STEPS`); a batch
        that needs more is refused before it starts. None: no bound.

    The runs are made in one call of the compiled core, which hands them
    to the threads a few at a time (so that runs that end early, having
    fallen, leave no thread idle) and reads a stop flag at every sample:
    Ctrl-C stops a batch at once, however long its runs
    (:func:`~equilibrist.sim.run.call_interruptibly`).

    Other parameters are those of :func:`~equilibrist.sim.run.simulate`.
    Linear and nonlinear controllers run compiled, in threads; Python
    controllers in worker processes (*workers* of them; the controller is
    pickled to them, so it must be defined at module level), or one by
    one in this process with ``workers=1``.
    """
    _setup.check_system(system)
    runs = _count(runs, "runs")
    if workers is not None:
        workers = _count(workers, "workers")
    if params is not None and not isinstance(params, Mapping):
        raise SimulationError(f"params = {params!r}: expected a mapping {{parameter: values per run}}")
    # A system without a canonical point (the zxz gyroscope) has no default
    # initial state: the settings are checked on the first run's.
    template_x0 = None
    if x0 is not None and not _setup._has_operating_point(system):
        given = _floats(x0, "initial states x0")
        template_x0 = given[0] if given.ndim == 2 else given
    setup = _setup.build(
        system, controller, duration=duration, rate=rate, physics_step=physics_step,
        integrator=integrator, rtol=rtol, atol=atol, plant=plant, x0=template_x0, delay=delay,
        noise=noise, reference=reference, events=events, outputs=None, region=region,
        max_steps=max_steps, runs=runs, threads=_threads(workers),
    )
    n, m = system.n_states, system.n_inputs
    n_sets = len(setup.change_values) + 1
    n_p = len(system.spec.parameter_names)
    per_run = (3 * n + n_sets * n_p + setup.acc_len + n + 8) * 8.0
    if plant == "linear":
        per_run += n_sets * n * (2 * n + m + 1) * 8.0
    if record:
        per_run += setup.n_rows * setup.record_width * 8.0
    what = f"a batch of {runs} runs" + (f" of {setup.n_rows} samples with trajectories" if record else "")
    _setup.check_memory(runs * per_run, what, max_memory)

    x0s = _initial_states(system, x0, runs, setup.x_op)
    pmat = _parameter_matrix(system, params, runs)
    base_seq = seed_sequence(seed) if (noise is not None or seed is not None) else None
    seqs: list[np.random.SeedSequence | None]
    if base_seq is not None:
        children = [child_seed(base_seq, i) for i in range(runs)]
        seqs = list(children)
        rngs = np.stack([generator_state(s) for s in children])
    else:
        seqs = [None] * runs
        rngs = np.zeros((runs, 4), dtype=np.uint64)
    p_sets_r = setup.p_sets(pmat)
    if plant == "linear":
        lin_r = np.stack([setup.linear_blocks(p_sets_r[i]) for i in range(runs)])
    else:
        lin_r = np.zeros((runs, n_sets, 0, 0))

    if not setup.compiled:
        return _python_batch(setup, x0s, pmat, seqs, record, progress, workers)

    kernel = Kernel(system, setup.nonlinear)
    recs = np.empty((runs, setup.n_rows if record else 0, setup.record_width))
    accs = np.zeros((runs, setup.acc_len))
    statuses = np.zeros((runs, len(layout.STATUS)), dtype=np.int64)
    fell_xs = np.zeros((runs, n))
    x_ends = np.zeros((runs, n))
    stop = np.zeros(1, dtype=np.int64)
    shared = dict(
        iopts=setup.iopts(record=record), fopts=setup.fopts, z0=setup.z0, op=setup.op,
        c_idx=setup.c_idx, cp=setup.cp, ref=setup.ref, uff=setup.uff, lv=setup.lv, lw=setup.lw,
        p_switch=setup.p_switch, region=setup.region, kicks=setup.kicks,
        kick_value=setup.kick_value, pulses=setup.pulses, pulse_value=setup.pulse_value,
        rec_cols=setup.rec_cols, acc_cols=setup.acc_cols, stop=stop,
        core=kernel.core(setup.cp),
    )

    def run_arrays(sl: slice) -> dict[str, np.ndarray]:
        return dict(x0s=x0s[sl], rngs=rngs[sl], p_sets_r=p_sets_r[sl], lin_r=lin_r[sl],
                    recs=recs[sl], accs=accs[sl], statuses=statuses[sl], fell_xs=fell_xs[sl],
                    x_ends=x_ends[sl])

    if not kernel.compiled(setup.cp):
        # Load (or compile) the core here, outside the timing (steps_per_second is the
        # runs' speed) and where Ctrl-C reaches it.
        kernel.run_many(**shared, **run_arrays(slice(0, 0)))
    timing: list[float] = []

    def work() -> None:
        # The thread count belongs to the thread that calls the core.
        # The core hands the runs out one at a time (dynamic scheduling): runs that fall
        # early leave no thread idle, and the hand-out costs nothing next to a run.
        set_workers(workers)
        t0 = time.perf_counter()
        try:
            kernel.run_many(**shared, **run_arrays(slice(0, runs)))
        finally:
            timing.append(time.perf_counter() - t0)

    bar = _progress_bar(runs, progress, "runs")
    st = layout.STATUS

    def show() -> None:
        if bar is not None:
            done = (statuses[:, st["fell"]] != 0) | (statuses[:, st["rows"]] >= setup.n_rows)
            bar.update(int(np.count_nonzero(done)) - bar.n)

    try:
        call_interruptibly(work, stop, show)
    finally:
        if bar is not None:
            bar.close()
    elapsed = timing[0]
    return _batch_result(setup, x0s, pmat, seqs, statuses, accs, fell_xs, x_ends,
                         recs if record else None, elapsed)


def _batch_result(setup: _setup.Setup, x0s: np.ndarray, pmat: np.ndarray,
                  seqs: list[np.random.SeedSequence | None], statuses: np.ndarray,
                  accs: np.ndarray, fell_xs: np.ndarray, x_ends: np.ndarray,
                  recs: np.ndarray | None, elapsed: float) -> BatchResult:
    sysm = setup.system
    st = layout.STATUS
    acc = layout.ACC.slices(**setup.sizes)
    rows = statuses[:, st["rows"]]
    fell = statuses[:, st["fell"]].astype(bool)
    fell_at = np.where(fell, statuses[:, st["fell_step"]] * setup.h, np.nan)
    code = np.where(fell, statuses[:, st["fell_code"]], -1)
    steps_done = np.where(fell, statuses[:, st["fell_step"]], setup.n_samples * setup.n_sub)
    settings = setup.describe()
    settings["x0"] = None
    count = np.maximum(rows, 1)[:, None]
    return BatchResult(
        system=sysm.key, system_digest=sysm.digest, state_names=sysm.state_names,
        input_names=sysm.input_names, parameter_names=sysm.spec.parameter_names, x0=x0s, params=pmat, fell=fell,
        fell_at=fell_at, fell_code=code, fell_x=fell_xs, final_state=x_ends,
        peak_input=accs[:, acc["peak_u_app"]], peak_command=accs[:, acc["peak_u"]],
        rms_input=np.sqrt(accs[:, acc["sum_u2"]] / count),
        time_saturated=accs[:, acc["n_sat"].start] / setup.rate,
        peak_deviation=accs[:, acc["peak_dx"]],
        estimation_error_rms=(np.sqrt(accs[:, acc["sum_est2"]] / count)
                              if setup.estimates else None),
        rows=rows, seeds=tuple(None if s is None else describe_seed(s) for s in seqs),
        settings=settings, elapsed=elapsed, steps=int(steps_done.sum()), trajectories=recs,
        _setup=setup,
    )


def _python_batch(setup: _setup.Setup, x0s: np.ndarray, pmat: np.ndarray,
                  seqs: list[np.random.SeedSequence | None], record: bool,
                  progress: bool, workers: int | None) -> BatchResult:
    """Runs of a Python controller: in worker processes, or here with ``workers=1``."""
    runs = x0s.shape[0]
    count = (os.cpu_count() or 1) if workers is None else max(1, int(workers))
    count = min(count, runs)
    t0 = time.perf_counter()
    if count <= 1:
        parts = [_python_runs(setup, x0s, pmat, seqs, record)]
    else:
        payload = _portable(setup)
        chunks = np.array_split(np.arange(runs), count)
        ctx = multiprocessing.get_context("spawn")
        pool = ctx.Pool(count)
        try:
            pending = [pool.apply_async(_python_worker, (payload, x0s[c], pmat[c],
                                                         [seqs[i] for i in c], record))
                       for c in chunks]
            parts = []
            for job in pending:
                while not job.ready():  # short waits: Ctrl-C is seen at once
                    job.wait(0.1)
                parts.append(job.get())
        except BaseException:
            pool.terminate()  # the workers' runs are not waited for
            raise
        else:
            pool.close()
        finally:
            pool.join()
    elapsed = time.perf_counter() - t0
    statuses, accs, fell_xs, x_ends, recs = (np.concatenate(a) for a in zip(*parts, strict=True))
    setup0 = _setup.Setup(**{**setup.__dict__, "estimates": False})
    return _batch_result(setup0, x0s, pmat, seqs, statuses, accs, fell_xs, x_ends,
                         recs if record else None, elapsed)


def _portable(setup: _setup.Setup) -> bytes:
    """*setup* pickled for a worker process (the system as its key and parameters)."""
    fields = {k: v for k, v in setup.__dict__.items() if k != "system"}
    try:
        return pickle.dumps((setup.system.key, dict(setup.system.params), setup.system.digest,
                             fields))
    except (pickle.PicklingError, TypeError, AttributeError) as exc:
        name = (python_controller_name(setup.controller)
                if isinstance(setup.controller, PythonController) else type(setup.controller).__name__)
        raise SimulationError(
            f"the Python controller {name} cannot be sent to worker processes ({exc}): define "
            "it at module level (not in a function, not a lambda), or run the batch in this "
            "process with workers=1"
        ) from exc


def _python_worker(payload: bytes, x0s: np.ndarray, pmat: np.ndarray,
                   seqs: list[np.random.SeedSequence | None], record: bool
                   ) -> tuple[np.ndarray, ...]:
    from equilibrist.numeric.system import rebuild_system

    key, params, digest, fields = pickle.loads(payload)
    setup = _setup.Setup(system=rebuild_system(key, params, digest), **fields)
    return _python_runs(setup, x0s, pmat, seqs, record)


def _python_runs(setup: _setup.Setup, x0s: np.ndarray, pmat: np.ndarray,
                 seqs: list[np.random.SeedSequence | None], record: bool
                 ) -> tuple[np.ndarray, ...]:
    """Runs of a Python controller one after the other: the batch's per-run arrays."""
    sysm = setup.system
    names = sysm.spec.parameter_names
    runs = x0s.shape[0]
    n = sysm.n_states
    st = layout.STATUS
    statuses = np.zeros((runs, len(st)), dtype=np.int64)
    accs = np.zeros((runs, setup.acc_len))
    acc = layout.ACC.slices(**setup.sizes)
    cols = layout.RECORD.slices(**setup.sizes)
    fell_xs = np.zeros((runs, n))
    x_ends = np.zeros((runs, n))
    recs = np.empty((runs, setup.n_rows if record else 0, setup.record_width))
    for i in range(runs):
        sysi = sysm.with_params(**dict(zip(names, pmat[i].tolist(), strict=True)))
        s = _setup.Setup(**{**setup.__dict__, "system": sysi, "x0": x0s[i]})
        seq = seqs[i]
        rng = generator_state(seq) if seq is not None else np.zeros(4, dtype=np.uint64)
        res = _run_python(s, Kernel(sysi), rng, seq, progress=False)
        k = res.n_rows
        statuses[i] = st.pack(np.int64, rows=k, fell=int(res.fell),
                              fell_code=_code(res, sysm.state_names),
                              fell_step=0 if res.fell_at is None else round(res.fell_at / setup.h))
        accs[i, acc["peak_u"]] = np.abs(res.commanded).max(axis=0)
        accs[i, acc["peak_u_app"]] = np.abs(res.applied).max(axis=0)
        accs[i, acc["sum_u2"]] = (res.applied**2).sum(axis=0)
        accs[i, acc["n_sat"]] = np.count_nonzero(np.any(res.saturated != res.commanded, axis=1))
        accs[i, acc["peak_dx"]] = np.abs(res.states - res.x_op).max(axis=0)
        if res.fell_x is not None:
            fell_xs[i] = res.fell_x
        x_ends[i] = res.final_state
        if record:
            recs[i, :k, cols["x"]] = res.states
            recs[i, :k, cols["x_hat"]] = np.nan if res.estimates is None else res.estimates
            recs[i, :k, cols["y"]] = res.measurements
            recs[i, :k, cols["u_cmd"]] = res.commanded
            recs[i, :k, cols["u_sat"]] = res.saturated
            recs[i, :k, cols["u_app"]] = res.applied
    return statuses, accs, fell_xs, x_ends, recs


def _code(res: SimResult, names: Sequence[str]) -> int:
    if not res.fell:
        return -1
    if res.fell_state in names:
        return list(names).index(res.fell_state)  # type: ignore[arg-type]
    return {"not finite": -2, "integrator failed": -3}.get(res.fell_state or "", -1)


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
    _setup.check_system(system)
    runs = _count(runs, "runs")
    if ranges is not None:
        _mapping(ranges, "ranges", "{state: (low, high)}")
    if spread is not None:
        _mapping(spread, "spread", "{parameter: relative spread}")
    if x_op is None:
        x_op, _ = _setup.operating_point(system, None)
    _setup.check_memory(runs * (system.n_states + len(spread or {})) * 8.0,
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


@dataclass(frozen=True, eq=False)
class RegionOfAttraction:
    """Initial conditions, each marked caught (stayed up) or fallen."""

    names: tuple[str, ...]
    points: np.ndarray
    caught: np.ndarray
    batch: BatchResult

    @property
    def fraction_caught(self) -> float:
        return float(np.mean(self.caught)) if self.caught.size else math.nan


def region_of_attraction(
    system: System,
    controller: object,
    *,
    grid: Mapping[str, tuple[float, float, int]] | None = None,
    samples: Mapping[str, tuple[float, float]] | None = None,
    runs: int | None = None,
    seed: SeedLike = None,
    **options: Any,
) -> RegionOfAttraction:
    """Which initial conditions the controller catches.

    Either a *grid* ``{state: (low, high, count)}`` (every combination) or
    *runs* random *samples* ``{state: (low, high)}`` drawn uniformly with
    *seed*. The other states start at the operating point. *options* go to
    :func:`simulate_batch` (``duration`` is required).
    """
    _setup.check_system(system)
    if (grid is None) == (samples is None):
        raise SimulationError("give either grid={state: (low, high, count)} or samples={state: (low, high)}")
    ctrl_x_op, _ = _setup.operating_point(system, controller)
    if grid is not None:
        _mapping(grid, "grid", "{state: (low, high, count)}")
        if not grid:
            raise SimulationError("grid = {}: expected at least one state {state: (low, high, count)}")
        names = tuple(grid)
        axes = []
        for name, spec in grid.items():
            try:
                lo, hi, count = spec
                lo_f, hi_f = float(lo), float(hi)
            except (TypeError, ValueError):
                raise SimulationError(f"grid of {name} = {spec!r}: expected (low, high, count)") from None
            count = _count(count, f"the grid's count of {name}")
            if not (math.isfinite(lo_f) and math.isfinite(hi_f)):
                raise SimulationError(f"grid of {name}: low and high must be finite, got {spec!r}")
            axes.append(np.linspace(lo_f, hi_f, count))
        mesh = np.meshgrid(*axes, indexing="ij")
        points = np.column_stack([g.reshape(-1) for g in mesh])
        x0s = np.tile(ctrl_x_op, (points.shape[0], 1))
        for j, name in enumerate(names):
            if name not in system.state_names:
                raise SimulationError(f"no state {name!r} ({nearest(name, system.state_names)})")
            x0s[:, system.state_names.index(name)] = points[:, j]
    else:
        if runs is None:
            raise SimulationError("random samples need runs=...")
        _mapping(samples, "samples", "{state: (low, high)}")
        if not samples:
            raise SimulationError("samples = {}: expected at least one state {state: (low, high)}")
        names = tuple(samples)
        x0s, _ = sample_uniform(system, runs, ranges=samples, seed=seed, x_op=ctrl_x_op)
        points = x0s[:, [system.state_names.index(n) for n in names]]
    batch = simulate_batch(system, controller, runs=points.shape[0], x0=x0s, seed=seed, **options)
    return RegionOfAttraction(names, points, ~batch.fell, batch)


@dataclass(frozen=True, eq=False)
class MonteCarloResult:
    """Robustness to parameter uncertainty: the fraction of runs that stay up."""

    spread: Mapping[str, float]
    batch: BatchResult

    @property
    def fraction_up(self) -> float:
        return self.batch.fraction_up


def monte_carlo(
    system: System,
    controller: object,
    *,
    spread: Mapping[str, float],
    runs: int,
    seed: SeedLike = None,
    x0: object = None,
    **options: Any,
) -> MonteCarloResult:
    """Runs with each parameter drawn uniformly in ``nominal * (1 +- spread)``.

    The controller keeps its nominal design; *options* go to
    :func:`simulate_batch` (``duration`` is required). The draws and the
    noise seeds come from two children of *seed*.
    """
    _mapping(spread, "spread", "{parameter: relative spread}")
    base = seed_sequence(seed)
    _, params = sample_uniform(system, runs, spread=spread, seed=child_seed(base, 0))
    batch = simulate_batch(system, controller, runs=runs, x0=x0, params=params,
                           seed=child_seed(base, 1), **options)
    return MonteCarloResult(dict(spread), batch)
