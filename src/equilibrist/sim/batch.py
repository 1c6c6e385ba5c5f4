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

The batch's result is in :mod:`equilibrist.sim.batch_result`, its initial
states, parameters and draws in :mod:`equilibrist.sim.batch_inputs`, the runs
of a Python controller in :mod:`equilibrist.sim.batch_python`.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from equilibrist.errors import SimulationError, nearest
from equilibrist.numeric.system import System
from equilibrist.sim import budget, integrators, layout, setup_checks
from equilibrist.sim import setup as _setup
from equilibrist.sim.batch_inputs import (
    _count,
    _floats,
    _initial_states,
    _mapping,
    _parameter_matrix,
    child_descriptions,
    child_seed,
    sample_uniform,
)
from equilibrist.sim.batch_python import _python_batch
from equilibrist.sim.batch_result import BatchResult, _batch_result
from equilibrist.sim.events import Event
from equilibrist.sim.kernel import Kernel, thread_count, threads_for
from equilibrist.sim.noise import Noise, SeedLike, describe_seed, generator_state, seed_sequence
from equilibrist.sim.rig import Rig
from equilibrist.sim.run import _progress_bar, call_interruptibly
from equilibrist.sim.setup_checks import _has_operating_point
from equilibrist.sim.setup_data import Setup
from equilibrist.tasks import balance_box


def _threads(workers: object) -> int:
    """The threads a batch would use (for the estimate of a refused batch's time)."""
    count = os.cpu_count() or 1
    if isinstance(workers, int | np.integer) and not isinstance(workers, bool) and workers >= 1:
        count = min(count, int(workers))
    return count


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
    integrator: str = integrators.DEFAULT,
    rtol: float = integrators.RTOL,
    atol: float = integrators.ATOL,
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
    max_steps: float | None = budget.DEFAULT_MAX_STEPS,
    rig: Rig | None = None,
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
        (default :data:`~equilibrist.sim.setup.DEFAULT_MAX_STEPS`); a batch
        that needs more is refused before it starts. None: no bound.
    rig : Rig, optional
        A rig's effects (:mod:`equilibrist.sim.rig`), the same for every run;
        its noise and perturbations are drawn from each run's seed.

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
    setup_checks.check_system(system)
    runs = _count(runs, "runs")
    if workers is not None:
        workers = _count(workers, "workers")
    if params is not None and not isinstance(params, Mapping):
        raise SimulationError(f"params = {params!r}: expected a mapping {{parameter: values per run}}")
    # A system without a canonical point (the zxz gyroscope) has no default
    # initial state: the settings are checked on the first run's.
    template_x0 = None
    if x0 is not None and not _has_operating_point(system):
        given = _floats(x0, "initial states x0")
        template_x0 = given[0] if given.ndim == 2 else given
    setup = _setup.build(
        system, controller, duration=duration, rate=rate, physics_step=physics_step,
        integrator=integrator, rtol=rtol, atol=atol, plant=plant, x0=template_x0, delay=delay,
        noise=noise, reference=reference, events=events, outputs=None, region=region,
        max_steps=max_steps, runs=runs, threads=_threads(workers), rig=rig,
    )
    _check_memory(setup, runs, record, max_memory)
    x0s = _initial_states(system, x0, runs, setup.x_op)
    pmat = _parameter_matrix(system, params, runs)
    draws = noise is not None or (setup.rig is not None and setup.rig.draws)
    base_seq = seed_sequence(seed) if (draws or seed is not None) else None
    seqs, seeds, rngs = _run_seeds(setup, base_seq, runs)
    if not setup.compiled:
        return _python_batch(setup, x0s, pmat, seqs, record, progress, workers)
    p_sets_r = setup.p_sets(pmat)
    if setup.plant == "linear":
        lin_r = np.stack([setup.linear_blocks(p_sets_r[i]) for i in range(runs)])
    else:
        lin_r = np.zeros((runs, p_sets_r.shape[1], 0, 0))
    runs_in = dict(x0s=x0s, rngs=rngs, p_sets_r=p_sets_r, lin_r=lin_r)
    if setup.rig is not None and setup.rig.perturbations > 0:
        runs_in["gforce"] = np.stack([setup.rig.pulses(system, setup.rate, setup.n_rows, s)[0]
                                      for s in seqs if s is not None])
    return _run_compiled_batch(setup, runs_in, pmat, seeds, record=record, workers=workers,
                               progress=progress)


def _check_memory(setup: Setup, runs: int, record: bool, max_memory: float | None) -> None:
    """Refuse a batch whose arrays would not fit in *max_memory* (before any is made)."""
    n, m = setup.system.n_states, setup.system.n_inputs
    n_sets = len(setup.change_values) + 1
    n_p = len(setup.system.spec.parameter_names)
    per_run = (3 * n + n_sets * n_p + setup.acc_len + n + 8) * 8.0
    if setup.plant == "linear":
        per_run += n_sets * n * (2 * n + m + 1) * 8.0
    if record:
        per_run += setup.n_rows * setup.record_width * 8.0
    what = f"a batch of {runs} runs" + (f" of {setup.n_rows} samples with trajectories" if record else "")
    budget.check_memory(runs * per_run, what, max_memory)


def _run_seeds(setup: Setup, base_seq: np.random.SeedSequence | None, runs: int
               ) -> tuple[list[np.random.SeedSequence | None], Sequence[dict[str, object] | None],
                          np.ndarray]:
    """Each run's seed sequence (where a Python controller's run needs it), its seed's
    description, and its generator state (zeros where the core draws nothing)."""
    # The runs' generators are made only where the core draws from them (noise); otherwise
    # each run's seed is only named (the same names, without making 10^5 SeedSequences).
    draws = setup.lv.shape[0] > 0 or (setup.lw.ndim == 2 and setup.lw.shape[1] > 0) \
        or (setup.rig is not None and setup.rig.draws)
    seqs: list[np.random.SeedSequence | None] = [None] * runs
    seeds: Sequence[dict[str, object] | None] = [None] * runs
    rngs = np.zeros((runs, 4), dtype=np.uint64)
    if base_seq is not None and (draws or not setup.compiled):
        children = [child_seed(base_seq, i) for i in range(runs)]
        seqs = list(children)
        seeds = [describe_seed(s) for s in children]
        if draws:
            rngs = np.stack([generator_state(s) for s in children])
    elif base_seq is not None:
        seeds = child_descriptions(base_seq, runs)
    return seqs, seeds, rngs


def _run_compiled_batch(setup: Setup, runs_in: dict[str, np.ndarray], pmat: np.ndarray,
                        seeds: Sequence[dict[str, object] | None], *, record: bool,
                        workers: int | None, progress: bool) -> BatchResult:
    """The runs of a compiled controller in one call of the core's ``run_many`` (*runs_in*:
    the per-run ``x0s``, ``rngs``, ``p_sets_r`` and ``lin_r``), stopped by Ctrl-C."""
    system = setup.system
    x0s = runs_in["x0s"]
    runs, n = x0s.shape
    kernel = Kernel(system, setup.nonlinear)
    outs = dict(recs=np.empty((runs, setup.n_rows if record else 0, setup.record_width)),
                accs=np.zeros((runs, setup.acc_len)),
                statuses=np.zeros((runs, len(layout.STATUS)), dtype=np.int64),
                fell_xs=np.zeros((runs, n)), x_ends=np.zeros((runs, n)))
    stop = np.zeros(1, dtype=np.int64)
    core = kernel.core(setup.cp)
    rig_i, rig_f = setup.rig_arrays()
    shared: dict[str, Any] = dict(
        rig_i=rig_i, rig_f=rig_f,
        iopts=setup.iopts(record=record), fopts=setup.fopts, z0=setup.z0, op=setup.op,
        c_idx=setup.c_idx, cp=setup.cp, ref=setup.ref, uff=setup.uff, lv=setup.lv, lw=setup.lw,
        p_switch=setup.p_switch, region=setup.region, kicks=setup.kicks,
        kick_value=setup.kick_value, pulses=setup.pulses, pulse_value=setup.pulse_value,
        rec_cols=setup.rec_cols, acc_cols=setup.acc_cols, stop=stop,
        bal=np.ascontiguousarray(balance_box(system)),
    )

    def run_arrays(sl: slice) -> dict[str, np.ndarray]:
        return {name: arr[sl] for name, arr in (*runs_in.items(), *outs.items())}

    if not kernel.compiled(setup.cp):
        # Load (or compile) the core here, outside the timing (steps_per_second is the
        # runs' speed) and where Ctrl-C reaches it.
        core.run_many(**shared, **run_arrays(slice(0, 0)), threads=thread_count())
    timing: list[float] = []

    # The batch's own thread count: asking for workers changes no other run's.
    threads = threads_for(workers)

    def work() -> None:
        # The core hands the runs out one at a time (dynamic scheduling): runs that fall
        # early leave no thread idle, and the hand-out costs nothing next to a run.
        t0 = time.perf_counter()
        try:
            core.run_many(**shared, **run_arrays(slice(0, runs)), threads=threads)
        finally:
            timing.append(time.perf_counter() - t0)

    bar = _progress_bar(runs, progress, "runs")
    st = layout.STATUS
    statuses = outs["statuses"]

    def show() -> None:
        if bar is not None:
            done = (statuses[:, st["fell"]] != 0) | (statuses[:, st["rows"]] >= setup.n_rows)
            bar.update(int(np.count_nonzero(done)) - bar.n)

    try:
        call_interruptibly(work, stop, show)
    finally:
        if bar is not None:
            bar.close()
    return _batch_result(setup, x0s, pmat, seeds, statuses, outs["accs"], outs["fell_xs"],
                         outs["x_ends"], outs["recs"] if record else None, timing[0])


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
    setup_checks.check_system(system)
    if (grid is None) == (samples is None):
        raise SimulationError("give either grid={state: (low, high, count)} or samples={state: (low, high)}")
    ctrl_x_op, _ = setup_checks.operating_point(system, controller)
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


__all__ = [
    "MonteCarloResult",
    "RegionOfAttraction",
    "monte_carlo",
    "region_of_attraction",
    "simulate_batch",
]
