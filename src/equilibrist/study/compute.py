"""One point of a study: its design, its batch of runs, its metrics (one table row).

The columns are listed in ``docs/studies.md`` ("The table"); NaN where a metric does not
apply. Percentiles are sample values (``inverted_cdf``), never interpolated; a run that
fell or never settles has an infinite settling time. The cost is
``T * sum_k (dx' Q dx + du' R du)`` from the operating point with the *spec's* Bryson
weights, so that costs compare across points.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, NotRequired, TypedDict

import numpy as np

from equilibrist.errors import EquilibristError
from equilibrist.study.choice import parse_choice
from equilibrist.study.record import Axis, AxisValue, Study, kind_options

if TYPE_CHECKING:
    from equilibrist.control.controller import AnyController
    from equilibrist.control.design_record import Design
    from equilibrist.numeric.system import System
    from equilibrist.sim.batch_result import BatchResult
    from equilibrist.sim.noise import Noise

SETTLE_FRACTION = 0.02


def metric_names(input_names: Sequence[str]) -> list[str]:
    """The metric columns (floats) of a system with *input_names*."""
    return [
        "fraction_up", "fell_at_median", "settled_fraction", "settling_p50", "settling_p90",
        "settling_max",
        *(f"peak_input_p50.{u}" for u in input_names),
        *(f"peak_input_max.{u}" for u in input_names),
        "time_saturated_mean", "time_saturated_max", "cost_mean", "cost_p90", "roa_fraction",
        "fraction_balanced", "time_to_balance_p50", "time_to_balance_p90",
    ]


def _quantile(values: np.ndarray, q: float) -> float:
    if values.size == 0:
        return math.nan
    return float(np.quantile(values, q, method="inverted_cdf"))


def settling_times(states: np.ndarray, times: np.ndarray, watched: Sequence[int],
                   x_op: np.ndarray) -> np.ndarray:
    """Settling time of each run of ``states`` (runs, rows, n), ``inf`` if never settled:
    the rule of :meth:`~equilibrist.sim.result.SimResult.metrics` over runs that ran to the end."""
    runs, rows = states.shape[0], states.shape[1]
    settle_idx = np.zeros(runs, dtype=np.int64)
    settled = np.ones(runs, dtype=bool)
    for j in watched:
        e = states[:, :, j] - x_op[j]
        scale = np.abs(e).max(axis=1)
        tail = e[:, int(0.8 * rows):]
        if tail.shape[1] > 1:
            floor = np.abs(tail.mean(axis=1)) + 4.0 * tail.std(axis=1)
        else:
            floor = np.zeros(runs)
        band = np.maximum(SETTLE_FRACTION * scale, floor)
        outside = np.abs(e) > band[:, None]
        anywhere = outside.any(axis=1) & (scale != 0)
        last = rows - 1 - np.argmax(outside[:, ::-1], axis=1)
        settled &= ~(anywhere & (last == rows - 1))
        settle_idx = np.where(anywhere, np.maximum(settle_idx, last + 1), settle_idx)
    t = times[np.minimum(settle_idx, rows - 1)]
    return np.where(settled, t, np.inf)


def _bryson_weights(system: System, names: Sequence[str]) -> np.ndarray | None:
    scales = system.spec.design_scales
    if not all(scales.get(n, 0) > 0 for n in names):
        return None
    return np.array([1.0 / float(scales[n]) ** 2 for n in names])


def _start(system: System, controller: object, x_op: np.ndarray) -> np.ndarray:
    """Where the states the study's ``x0`` leaves out start: where the controller's plan
    starts (a tracked trajectory's ``settings["start"]``), else the operating point."""
    settings = getattr(controller, "settings", None)
    planned = settings.get("start") if isinstance(settings, Mapping) else None
    if not isinstance(planned, Mapping):
        return x_op
    start = np.array(x_op, dtype=float)
    for state, value in planned.items():
        if state in system.state_names:
            start[system.state_names.index(state)] = float(value)
    return start


class _RunOptions(TypedDict):
    """What every batch of a point (and its region of attraction) is run with."""

    duration: float
    rate: float
    delay: bool
    noise: Noise | None
    region: NotRequired[dict[str, tuple[float, float]]]


def evaluate_point(study: Study, index: int, *,
                   threads: int | None = None) -> dict[str, object]:
    """The table row of point *index* (a mapping column -> value)."""
    from equilibrist.control.design import design
    from equilibrist.controllers import kinds as registry
    from equilibrist.numeric.lookup import get_system

    values = study.point(index)
    nominal = get_system(study.system, **study.settings)
    inputs = nominal.input_names
    row: dict[str, object] = {"point": index, **values}
    row.update(dict.fromkeys(metric_names(inputs), math.nan))
    row.update({"runs": 0, "stayed_up": 0, "steps": 0, "status": "ok", "error": None})
    kinds = {a.name: a for a in study.axes}

    def failed(status: str, exc: Exception) -> dict[str, object]:
        row["status"] = status
        row["error"] = str(exc).replace("\n", " ")
        return row

    physical = {k: float(v) for k, v in values.items() if kinds[k].kind == "parameter"}
    try:
        plant = nominal.with_params(**physical) if physical else nominal
    except EquilibristError as exc:
        return failed("invalid point", exc)
    rate = float(values.get("rate", study.rate))
    choice = parse_choice(str(values.get("controller", study.controller)))
    kind = choice.kind
    if "controller" in values:  # the table names a file by its name (policy:ppo.zip)
        row["controller"] = choice.label
    noise_scale = float(values.get("noise", study.noise))
    delay = bool(values.get("delay", study.delay))
    base = plant if study.design_for == "point" else nominal
    q, r = _point_weights(values, kinds, base)
    try:
        d = design(base, q=q, r=r, rate=rate)
    except EquilibristError as exc:
        return failed("design failed", exc)
    record = registry.get(kind, "study")
    try:
        # The point's design, made above, and the kind's own options (a plan to track...).
        request = registry.ControllerRequest.of_design(
            base, d, options=kind_options(kind, choice.options(dict(study.controller_options))))
        controller = record.make(request)
    except EquilibristError as exc:
        return failed("design failed", exc)
    noise = _point_noise(noise_scale, from_design=record.noise == "design", design=d,
                         system=base, controller=controller, rate=rate)
    options: _RunOptions = {"duration": study.duration, "rate": rate, "delay": delay,
                            "noise": noise}
    try:
        tally, roa_fraction = _simulate_point(study, index, plant, nominal, controller,
                                              task=record.task, options=options, threads=threads)
    except EquilibristError as exc:
        return failed("simulation failed", exc)
    _fill_metrics(row, tally, inputs, runs=study.runs, full=study.metrics == "full",
                  roa_fraction=roa_fraction)
    return row


def _point_weights(values: Mapping[str, AxisValue], kinds: Mapping[str, Axis],
                   base: System) -> tuple[list[float] | None, list[float] | None]:
    """The LQR weights of a point that varies Bryson scales (None: the design's default),
    the scales it does not vary taken from *base*'s spec."""
    q = r = None
    q_scales = {kinds[k].target: float(v) for k, v in values.items() if kinds[k].kind == "q"}
    r_scales = {kinds[k].target: float(v) for k, v in values.items() if kinds[k].kind == "r"}
    scales = base.spec.design_scales
    if q_scales:
        q = [1.0 / (q_scales.get(s) or float(scales.get(s, math.nan))) ** 2 for s in base.state_names]
    if r_scales:
        r = [1.0 / (r_scales.get(u) or float(scales.get(u, math.nan))) ** 2 for u in base.input_names]
    return q, r


def _point_noise(scale: float, *, from_design: bool, design: Design, system: System,
                 controller: AnyController | None, rate: float) -> Noise | None:
    """The noise of a point's runs: the design's (or the spec's, for the controller's
    measured outputs) with its standard deviations times *scale*; None at scale 0."""
    from equilibrist.control.controller import measured_outputs
    from equilibrist.sim.noise import Noise

    if not scale > 0:
        return None
    if from_design:
        nd = Noise.from_design(design)
    else:
        nd = Noise.from_spec(system, outputs=measured_outputs(controller), rate=rate)
    s2 = scale**2
    return Noise(nd.process_gain, nd.process_intensity * s2,
                 nd.measurement_covariance * s2, nd.outputs)


@dataclass
class _Tally:
    """What a point's runs measured, run by run, and the physics steps they took."""

    fell: np.ndarray
    fell_at: np.ndarray
    balanced_since: np.ndarray
    settle: np.ndarray
    peak: np.ndarray
    saturated: np.ndarray
    cost: np.ndarray
    steps: int = 0

    @classmethod
    def empty(cls, runs: int, n_inputs: int) -> _Tally:
        """Nothing measured yet: no fall, never settled, no cost."""
        return cls(fell=np.zeros(runs, dtype=bool), fell_at=np.full(runs, np.nan),
                   balanced_since=np.full(runs, np.nan), settle=np.full(runs, np.inf),
                   peak=np.zeros((runs, n_inputs)), saturated=np.zeros(runs),
                   cost=np.full(runs, np.nan))


def _simulate_point(study: Study, index: int, plant: System, nominal: System,
                    controller: object, *, task: str | None, options: _RunOptions,
                    threads: int | None) -> tuple[_Tally, float]:
    """A point's runs, batch by batch, and its region of attraction (NaN without ``roa``)."""
    from equilibrist.sim.batch import region_of_attraction, simulate_batch
    from equilibrist.sim.batch_inputs import sample_uniform
    from equilibrist.sim.setup_checks import operating_point
    from equilibrist.tasks import get_task, task_names

    full = study.metrics == "full"
    runs = study.runs
    x_op, _u_op = operating_point(plant, controller)
    x0s, spread = sample_uniform(plant, runs, ranges=dict(study.x0), spread=dict(study.spread),
                                 seed=study.point_seed(index, 1),
                                 x_op=_start(plant, controller, x_op))
    tally = _Tally.empty(runs, len(nominal.input_names))
    qw = _bryson_weights(nominal, nominal.state_names)
    rw = _bryson_weights(nominal, nominal.input_names)
    if task is not None and task in task_names(plant):
        # A swing-up starts hanging: only the task's region (the cart's track) ends it,
        # as simulate and batch run it.
        options["region"] = dict(get_task(plant, task).region)
    for b, start in enumerate(range(0, runs, study.batch_size)):
        sl = slice(start, min(runs, start + study.batch_size))
        batch = simulate_batch(
            plant, controller, runs=sl.stop - sl.start, x0=x0s[sl],
            params={k: v[sl] for k, v in spread.items()}, seed=study.point_seed(index, 2, b),
            record=full, workers=threads, **options)
        tally.steps += batch.steps
        tally.fell[sl] = batch.fell
        tally.fell_at[sl] = batch.fell_at
        if batch.balanced_since is not None:
            tally.balanced_since[sl] = batch.balanced_since
        tally.peak[sl] = batch.peak_input
        tally.saturated[sl] = batch.time_saturated
        if full and batch.trajectories is not None:
            _tally_trajectories(tally, batch, plant, start, qw=qw, rw=rw, rate=options["rate"])
    roa_fraction = math.nan
    if study.roa:
        roa = region_of_attraction(
            plant, controller, grid={k: (lo, hi, n) for k, (lo, hi, n) in study.roa.items()},
            seed=study.point_seed(index, 3), workers=threads, **options)
        roa_fraction = roa.fraction_caught
        tally.steps += roa.batch.steps
    return tally, roa_fraction


def _tally_trajectories(tally: _Tally, batch: BatchResult, plant: System, start: int, *,
                        qw: np.ndarray | None, rw: np.ndarray | None, rate: float) -> None:
    """The settling times and (with the spec's weights) the costs of a batch's runs that
    stayed up, from its recorded trajectories; its first run is run *start* of the point."""
    setup = batch._setup
    assert setup is not None  # a batch that recorded its runs keeps its setup
    assert batch.trajectories is not None
    n, m = plant.n_states, plant.n_inputs
    up = ~batch.fell
    traj = batch.trajectories[up]
    states = traj[:, :, :n]
    names = setup.outputs or plant.state_names
    watched = [plant.state_names.index(o) for o in names]
    idx = np.nonzero(up)[0] + start
    tally.settle[idx] = settling_times(states, setup.times, watched, setup.x_op)
    if qw is not None and rw is not None:
        c_u = 2 * n + len(setup.outputs)
        dx = states - setup.x_op
        du = traj[:, :, c_u + 2 * m : c_u + 3 * m] - setup.u_op
        tally.cost[idx] = ((dx**2 * qw).sum(axis=(1, 2)) + (du**2 * rw).sum(axis=(1, 2))) / rate


def _fill_metrics(row: dict[str, object], tally: _Tally, inputs: Sequence[str], *, runs: int,
                  full: bool, roa_fraction: float) -> None:
    """The metric columns of *row* from what the point's runs measured."""
    fell, balanced_since, peak = tally.fell, tally.balanced_since, tally.peak
    up = ~fell
    row.update({
        "runs": runs,
        "stayed_up": int(up.sum()),
        "fraction_up": float(up.mean()),
        "fell_at_median": float(np.median(tally.fell_at[fell])) if fell.any() else math.nan,
        "time_saturated_mean": float(tally.saturated.mean()),
        "time_saturated_max": float(tally.saturated.max()),
        "roa_fraction": roa_fraction,
        "steps": int(tally.steps),
        # Ends balanced and stays (equilibrist.tasks.balance_box): a swing-up's success.
        "fraction_balanced": float(np.isfinite(balanced_since).mean()),
        "time_to_balance_p50": _quantile(balanced_since[np.isfinite(balanced_since)], 0.5),
        "time_to_balance_p90": _quantile(balanced_since[np.isfinite(balanced_since)], 0.9),
    })
    for j, u in enumerate(inputs):
        row[f"peak_input_p50.{u}"] = _quantile(peak[:, j], 0.5)
        row[f"peak_input_max.{u}"] = float(peak[:, j].max())
    if full:
        settle, cost = tally.settle, tally.cost
        row["settled_fraction"] = float(np.isfinite(settle).mean())
        row["settling_p50"] = _quantile(settle, 0.5)
        row["settling_p90"] = _quantile(settle, 0.9)
        row["settling_max"] = float(settle.max())
        kept = cost[up & np.isfinite(cost)]
        row["cost_mean"] = float(kept.mean()) if kept.size else math.nan
        row["cost_p90"] = _quantile(kept, 0.9)


def evaluate_chunk(study: Study, chunk: int, chunk_size: int, *,
                   threads: int | None = None) -> list[dict[str, object]]:
    """The rows of points ``chunk * chunk_size`` up to the next chunk."""
    start = chunk * chunk_size
    stop = min(study.n_points, start + chunk_size)
    return [evaluate_point(study, i, threads=threads) for i in range(start, stop)]


def chunk_task(study_json: str, chunk: int, chunk_size: int,
               threads: int) -> list[dict[str, object]]:
    """A chunk as a cluster task: plain arguments in, plain rows out."""
    study = Study.from_json(study_json)
    return evaluate_chunk(study, chunk, chunk_size, threads=threads)
