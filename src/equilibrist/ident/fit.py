"""Grey-box identification of physical parameters: multiple shooting, then prediction error.

The model is the system's own derived ``x_dot = f(x, u; p)``; the free parameters (and,
optionally, a constant offset per sensor) are fitted to a log with
:func:`scipy.optimize.least_squares`. Multiple shooting (:mod:`equilibrist.ident.shooting`)
converges from far on an unstable closed-loop log and gives the start and the noise levels;
the estimate minimizes the one-step prediction errors of the model's Kalman filter
(:mod:`equilibrist.ident.prediction`), which stay unbiased in closed loop. Why each stage,
and how the uncertainty and the whiteness test are computed: ``docs/identification.md``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from equilibrist.errors import nearest
from equilibrist.ident.answer import _answer
from equilibrist.ident.log import IdentificationError, Log
from equilibrist.ident.noise import (
    _linearization,
    _process_prior,
    _sensor_prior,
    _state_floor,
)
from equilibrist.ident.prediction import _filter, _Predictor
from equilibrist.ident.result import Identification
from equilibrist.ident.shooting import (
    _boundaries,
    _guess_states,
    _leverage,
    _Problem,
    _process_scale,
    _segment_samples,
    _shooter,
    _whitening,
)
from equilibrist.numeric.system import System

# The longest RK4 step [s] (the simulator's default physics step).
DEFAULT_MAX_STEP = 1e-3
# RK4 steps per sample of the log at most (the --max-step it accepts is the longest sample
# over this): the replay's work grows with them, and no rig's log needs more.
MAX_SUBSTEPS = 1000
# Rounds of noise re-estimation (each followed by a fit).
NOISE_PASSES = 3


def check_free(system: System, free: Sequence[str]) -> tuple[str, ...]:
    """The free parameter names, checked (every problem at once)."""
    physical = [p.name for p in system.spec.parameters]
    limits = [n for n in system.spec.parameter_names if n not in physical]
    problems = []
    seen: list[str] = []
    for name in free:
        if name in limits:
            problems.append(f"{name} is an input limit, not a parameter of the dynamics")
        elif name not in physical:
            problems.append(f"unknown parameter {name!r} of {system.key}: {nearest(name, physical)}")
        elif name in seen:
            problems.append(f"parameter {name} is free twice")
        else:
            seen.append(name)
    if problems:
        raise IdentificationError("; ".join(problems))
    if not seen:
        raise IdentificationError(
            f"no free parameter: name the parameters to fit ({', '.join(physical)})"
        )
    return tuple(seen)


def identify(
    system: System,
    log: Log,
    free: Sequence[str],
    *,
    offsets: bool = False,
    segment: float | None = None,
    max_step: float = DEFAULT_MAX_STEP,
    sensor_noise: Mapping[str, float] | None = None,
    process_noise: Mapping[str, float] | None = None,
    backend: str = "compiled",
    reestimate_noise: bool = True,
    max_nfev: int = 200,
) -> Identification:
    """Fit the parameters *free* of *system* (known ones at their values, free ones at
    their start values) to *log*, with a constant offset per sensor if *offsets*.

    *segment* is the shooting segments' length [s], by default the longest over which the
    process noise moves the outputs by at most half a sensor standard deviation (at least 5
    samples). *sensor_noise* (standard deviations per output) and *process_noise* (intensities
    per state rate) weight the first fit, by default the spec's; *reestimate_noise* refits
    with levels estimated from the residuals. *backend* is ``"compiled"`` or ``"solve_ivp"``.
    """
    if log.system != system.key:
        raise IdentificationError(f"the log was checked against {log.system}, not {system.key}")
    free = check_free(system, free)
    if not (math.isfinite(max_step) and max_step > 0):
        raise IdentificationError(f"the integration step must be positive, got {max_step!r}")
    n, n_rows = system.n_states, log.n_rows
    names = system.spec.parameter_names
    free_idx = np.array([names.index(f) for f in free], dtype=np.int64)
    c_idx = np.array([system.state_index(o) for o in log.output_names], dtype=np.int64)
    dt, n_sub = _substeps(log, max_step)
    _check_outputs_move(log)

    sigma_y = _sensor_prior(system, log, sensor_noise)
    q = _process_prior(system, process_noise)
    guess = _guess_states(system, log)
    u_mean = log.inputs.mean(axis=0) if system.n_inputs else np.zeros(0)
    A = _linearization(system, guess, u_mean)
    L = _segment_length(segment, A=A, q=q, c_idx=c_idx, sigma_y=sigma_y, dt=dt, n_rows=n_rows)
    bounds = _boundaries(n_rows, L)
    _check_enough_rows(log, free, n_states=n, n_seg=bounds.size - 1, offsets=offsets)
    floor = _state_floor(system)
    durations = log.time[bounds[1:-1]] - log.time[bounds[:-2]]
    p0 = np.array(system.p, dtype=float)
    theta0 = p0[free_idx].copy()
    scales = system.spec.design_scales
    step_x = np.array([1e-6 * float(scales.get(s, 1.0)) for s in system.state_names])
    prob = _Problem(
        system=system, log=log, free=free, offsets=offsets, bounds=bounds, n_sub=n_sub,
        c_idx=c_idx, sigma_y=sigma_y, W=_whitening(A, q, floor, durations),
        shoot=_shooter(system, backend), free_idx=free_idx, p_base=p0,
        step_theta=np.full(len(free), 1e-6), step_x=step_x,
    )
    z0 = np.concatenate([theta0, np.zeros(prob.n_off), guess[bounds[:-1]].ravel()])
    lo, hi = _parameter_bounds(system, free, theta0, z0)
    passes = NOISE_PASSES if reestimate_noise else 0
    sol, q, q_scale = _fit_shooting(system, log, prob, z0, (lo, hi), q=q, u_mean=u_mean,
                                    floor=floor, durations=durations, dt=dt, passes=passes,
                                    max_nfev=max_nfev)

    # The estimate: the prediction errors of the model's Kalman filter, from the
    # multiple-shooting solution. The shooting residuals leave the process noise
    # acting inside a segment unmodelled, and the closed loop's input answers
    # that noise, so their minimum is biased where the process noise matters;
    # the filter's errors are white at the truth, whatever the feedback.
    theta, off, xs = prob.split(sol.x)
    nh = prob.n_head
    sigma_y = prob.sigma_y
    pred = _Predictor(
        system=system, log=log, free_idx=free_idx, offsets=offsets, p_base=p0,
        c_idx=c_idx, n_sub=n_sub, dt=dt, x_lin=np.median(xs, axis=0), u_lin=u_mean, floor=floor,
        q=q.copy(), sigma_y=sigma_y.copy(), filter=_filter(system, backend),
        step=np.concatenate([1e-6 * np.where(theta0 != 0, np.abs(theta0), 1.0),
                             1e-4 * sigma_y[: prob.n_off], step_x]),
    )
    lo_p = np.concatenate([lo[:nh], np.full(n, -np.inf)])
    hi_p = np.concatenate([hi[:nh], np.full(n, np.inf)])
    z_p = np.clip(np.concatenate([theta, off[: prob.n_off], xs[0]]), lo_p, hi_p)
    psol, nfev, q_scale = _fit_prediction(pred, z_p, (lo_p, hi_p), q_scale=q_scale,
                                          passes=passes, max_nfev=max_nfev)
    nfev += int(sol.nfev)
    return _answer(system, log, prob, sol, pred, psol, theta0, q_scale, L, dt, backend, max_step,
                   (lo, hi), nfev)


def _substeps(log: Log, max_step: float) -> tuple[float, np.ndarray]:
    """The log's median sample period, and the RK4 steps of each sample (each at most
    *max_step* long); a step too short for :data:`MAX_SUBSTEPS` is refused."""
    dts = np.diff(log.time)
    dt = float(np.median(dts))
    # Bounded before the division: a step of 1e-300 s would be billions of steps a sample.
    shortest = float(np.max(dts)) / MAX_SUBSTEPS
    if max_step < shortest:
        raise IdentificationError(
            f"--max-step {max_step:g} s: at most {MAX_SUBSTEPS} RK4 steps per sample of the log "
            f"(its longest sample is {float(np.max(dts)):g} s): expected a step >= {shortest:.3g} s")
    n_sub = np.maximum(1, np.ceil(dts / max_step - 1e-9)).astype(np.int64)
    return dt, n_sub


def _segment_length(segment: float | None, *, A: np.ndarray, q: np.ndarray, c_idx: np.ndarray,
                    sigma_y: np.ndarray, dt: float, n_rows: int) -> int:
    """The shooting segments' length in samples: *segment* seconds, or by default the
    longest over which the process noise moves the outputs by at most half a sensor
    standard deviation."""
    if segment is None:
        return _segment_samples(A, q, c_idx, sigma_y, dt, n_rows)
    if not (math.isfinite(segment) and segment > 0):
        raise IdentificationError(f"the segment length must be positive, got {segment!r} s")
    return max(1, round(segment / dt))


def _check_enough_rows(log: Log, free: tuple[str, ...], *, n_states: int, n_seg: int,
                       offsets: bool) -> None:
    """Refuses a log with no more residuals than multiple shooting has decision variables."""
    n, ny, n_rows = n_states, len(log.output_names), log.n_rows
    n_dec = len(free) + (ny if offsets else 0) + n_seg * n
    n_res = n_rows * ny + (n_seg - 1) * n
    if n_res <= n_dec:
        raise IdentificationError(
            f"the log has {n_rows} rows of {ny} output{'s' if ny != 1 else ''}: too few for "
            f"{len(free)} free parameter{'s' if len(free) != 1 else ''} and the "
            f"{n_seg * n} segment states of multiple shooting"
        )


def _check_outputs_move(log: Log) -> None:
    """Refuses a log with an output that is constant throughout."""
    for j, name in enumerate(log.output_names):
        column = log.outputs[:, j]
        if not np.ptp(column) > 0:
            raise IdentificationError(
                f"the log's output {name} is {float(column[0]):g} throughout: a constant output "
                "says nothing about the parameters and its noise cannot be estimated (log a run "
                "that moves, or leave that column out)")


def _parameter_bounds(system: System, free: tuple[str, ...], theta0: np.ndarray,
                      z0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The bounds of the decision variables (the free parameters' ranges, open ends moved
    inside; the rest unbounded), with the parameters' start values of *z0* clipped into
    them in place."""
    lo = np.full(z0.size, -np.inf)
    hi = np.full(z0.size, np.inf)
    by_name = {p.name: p for p in system.spec.parameters}
    for a, name in enumerate(free):
        par = by_name[name]
        span = max(abs(theta0[a]), 1e-12)
        lo[a] = par.low + (1e-9 * span if par.low_open else 0.0)
        hi[a] = par.high - (1e-9 * span if par.high_open else 0.0)
        z0[a] = min(max(z0[a], lo[a]), hi[a])
    return lo, hi


def _fit_shooting(
    system: System, log: Log, prob: _Problem, z0: np.ndarray,
    bounds: tuple[np.ndarray, np.ndarray], *, q: np.ndarray, u_mean: np.ndarray,
    floor: np.ndarray, durations: np.ndarray, dt: float, passes: int, max_nfev: int,
) -> tuple[Any, np.ndarray, float]:
    """The multiple-shooting fit from *z0*, refitted after each of at most *passes*
    re-estimations of the noise levels (which it sets in *prob*): the solution, the
    process noise and the scale it was multiplied by."""
    from scipy.optimize import least_squares

    lo, hi = bounds
    n_rows, ny = log.n_rows, len(log.output_names)

    def fit(z_start: np.ndarray) -> Any:
        with np.errstate(all="ignore"):
            return least_squares(
                prob.residuals, z_start, jac=prob.jacobian, bounds=(lo, hi), method="trf",
                x_scale="jac", tr_solver="lsmr", ftol=1e-12, xtol=1e-12, gtol=1e-10,
                max_nfev=max_nfev,
            )

    sol = fit(z0)
    sigma_y = prob.sigma_y
    q_scale = 1.0
    for _ in range(passes):
        # Variance components (Helmert): each group's sum of squares over its
        # redundancy (its rows minus their leverage), so that the states
        # fitted to the residuals do not make the noise look smaller.
        theta, off, xs = prob.split(sol.x)
        r = prob.residuals(sol.x)
        n_out = n_rows * ny
        groups = [np.arange(j, n_out, ny) for j in range(ny)]
        lev = _leverage(prob.jacobian(sol.x), groups)
        ry = r[:n_out].reshape(n_rows, ny)
        ratio_y = np.sum(ry**2, axis=0) / np.maximum(n_rows - lev[:ny], 1.0)
        sigma_y = sigma_y * np.sqrt(ratio_y)
        A = _linearization(system, xs, u_mean)
        prob.sigma_y = sigma_y
        # The process noise: the scale that makes the fitted model's Kalman
        # filter most likely (the segment defects alone understate it: the
        # segment states absorb part of the noise acting inside a segment).
        ratio_q = 1.0
        if np.any(q > 0):
            ratio_q = _process_scale(system, log, prob, theta, off, xs[0], A, q, floor, dt)
            q = q * ratio_q
            q_scale *= ratio_q
        prob.W = _whitening(A, q, floor, durations)
        sol = fit(sol.x)
        if max(abs(ratio_q - 1.0), float(np.max(np.abs(ratio_y - 1.0)))) < 0.05:
            break
    return sol, q, q_scale


def _fit_prediction(
    pred: _Predictor, z_p: np.ndarray, bounds: tuple[np.ndarray, np.ndarray], *,
    q_scale: float, passes: int, max_nfev: int,
) -> tuple[Any, int, float]:
    """The prediction-error fit from *z_p*, refitted after each of at most *passes*
    re-estimations of the noise levels (set in *pred*) until they settle: the solution,
    the residual evaluations it took, and *q_scale* times the process noise's changes."""
    from scipy.optimize import least_squares

    lo_p, hi_p = bounds

    def fit_errors(z_start: np.ndarray) -> Any:
        pred.set_weight(z_start)
        with np.errstate(all="ignore"):
            return least_squares(
                pred.residuals, z_start, jac=pred.jacobian, bounds=(lo_p, hi_p), method="trf",
                x_scale="jac", ftol=1e-10, xtol=1e-10, gtol=1e-10, max_nfev=max_nfev,
            )

    psol = fit_errors(z_p)
    nfev = int(psol.nfev)
    for _ in range(passes):
        ratio_q, ratio_y = pred.noise_levels(psol.x)
        pred.q = pred.q * ratio_q
        pred.sigma_y = pred.sigma_y * ratio_y
        q_scale *= ratio_q
        if max(abs(ratio_q - 1.0), float(np.max(np.abs(ratio_y - 1.0)))) < 0.05:
            break
        psol = fit_errors(psol.x)
        nfev += int(psol.nfev)
    return psol, nfev, q_scale


__all__ = [
    "check_free",
    "identify",
]
