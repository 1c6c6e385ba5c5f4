"""Grey-box identification of physical parameters: multiple shooting, then prediction error.

The model is the system's own derived ``x_dot = f(x, u; p)``; the chosen free
parameters (and, optionally, a constant offset per sensor) are fitted to a
log with :func:`scipy.optimize.least_squares`, in two stages.

The start: multiple shooting. The balancing systems are unstable and their
logs are closed-loop: replaying the logged input open loop from one initial
state diverges within a second, whatever the parameters. The log is cut into
segments of a fraction of a second; each segment's initial state is a
decision variable, the segment is integrated with the logged input held
between samples (zero-order hold, as the rig applied it), and the residuals
are

- the output errors ``(y_k - y_hat_k - offset) / sigma_y`` at every sample,
- the continuity defects ``x_{s+1} - x_end,s`` where one segment ends and the
  next starts, whitened by the covariance the process noise builds over a
  segment (``Q_seg``, from the linearization by Van Loan's method).

Segments are kept short: by default as long as the process noise moves the
outputs by at most half a sensor standard deviation over one segment, at
least 5 samples. The noise levels start from the system's spec (sensor and
process noise) and are re-estimated after a first fit: each sensor's
variance from its residuals over their redundancy (rows minus leverage), the
process noise's scale as the one that makes the fitted model's Kalman filter
most likely; then the fit is repeated. This stage converges from far (the
segments never diverge), and gives the second its start and noise levels.

The estimate: prediction error. Multiple shooting is not the estimate,
because it is biased where process noise matters: the noise acting inside a
segment is not in its model (it is lumped at the segment's end), so the
output errors inside a segment carry it, and in closed loop the logged input
answers that same noise through the controller. The input the fit regresses
on is then correlated with its residuals, and the parameters absorb the
correlation (on the control-moment-gyroscope robot, whose process noise is
large, the body's mass came out 1.7 standard errors high on average over 20
logs; with 1-sample segments, 0.9 over 6 logs: shorter segments do not remove it, as the
joint estimate of states and parameters is not the likelihood of the
parameters). The second stage minimizes the one-step prediction errors of a
Kalman filter of the model instead: the nonlinear model predicts over each
sample interval (RK4, the input held), the steady-state gain of its
linearization at the current parameters (and the current noise levels)
corrects; the decision variables are the parameters, the offsets and the
filter's initial state. The errors are weighted by their covariance (held
fixed during a fit) and, at the true parameters, are white whatever the
feedback: this is the prediction-error (innovations) form of the likelihood,
consistent in closed loop. The noise levels (a scale of the process noise,
each sensor's standard deviation) are then set to those that make the
filter's errors most likely (their Gaussian likelihood, Nelder-Mead) and the
fit is repeated until they settle.

Integration: RK4 with the input held, at most ``max_step`` per step (1 ms by
default, as the simulator), compiled in the system's C core over its generated
``f`` (:mod:`equilibrist.ident.kernel`); ``backend="solve_ivp"`` runs the same
loops with :func:`scipy.integrate.solve_ivp` (for comparison). The Jacobians
are by central differences: for the shooting residuals all segments at once
(segments are independent given their initial states), assembled sparse; for
the filter's errors one column at a time (a handful of decision variables).

Whiteness: a Ljung-Box test of the final filter's prediction errors, per
output. White errors say the model and its noise levels explain the data.

Uncertainty: the covariance of the decision variables is ``s^2 (J' J)^-1``
at the solution (``J`` the Jacobian of the weighted prediction errors, ``s^2``
their variance); the filter's initial state is eliminated (Schur complement)
to give the parameters' covariance, their standard errors and correlations.
Directions the data cannot tell apart are found from the eigen-decomposition
of that information matrix in log-parameters, where a product or ratio
structure (``m_p`` and ``l`` entering only as ``m_p*l``) is a null direction
with entries ``(1, -1)``.

The replay (NRMSE, the plot) is the shooting segments' integration from
their states at the final parameters.

The pieces: the answer's types in :mod:`equilibrist.ident.result`, the
multiple-shooting stage in :mod:`equilibrist.ident.shooting`, the
prediction-error stage in :mod:`equilibrist.ident.prediction`, the noise
models and the Kalman gain in :mod:`equilibrist.ident.noise`, the
uncertainty and the report's numbers in :mod:`equilibrist.ident.answer`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from equilibrist.errors import nearest

# The names marked F401 are not used here: imported so that they stay importable
# from this module, where they were defined before it was split.
from equilibrist.ident.answer import (
    _answer,
)
from equilibrist.ident.log import IdentificationError, Log
from equilibrist.ident.noise import (
    _linearization,
    _process_prior,
    _sensor_prior,
    _state_floor,
)
from equilibrist.ident.prediction import _filter, _Predictor
from equilibrist.ident.result import (
    Identification,
)
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
    """Fit the parameters *free* of *system* to *log* by multiple shooting.

    Parameters
    ----------
    system : System
        The model, with every parameter at its known value and the free ones
        at their start values.
    log : Log
        The measured data (:func:`equilibrist.ident.read_log`).
    free : sequence of str
        The physical parameters to fit.
    offsets : bool
        Also fit a constant offset of each sensor.
    segment : float, optional
        Length of the shooting segments [s]; by default the longest over
        which process noise moves the outputs by at most half a sensor
        standard deviation (at least 5 samples).
    max_step : float
        Longest RK4 step [s].
    sensor_noise, process_noise : mapping, optional
        Standard deviations of the sensors per output, and intensities of
        the process noise per state rate (as in the system's spec), for the
        first fit's weights (default: the spec's).
    backend : {"compiled", "solve_ivp"}
        The integrator of the segments.
    reestimate_noise : bool
        Re-estimate the noise levels from the first fit's residuals and fit
        again.

    Returns
    -------
    Identification
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
