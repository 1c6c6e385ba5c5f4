"""From the two stages' solutions to an :class:`~equilibrist.ident.fit.Identification`:
the covariance of the estimates, the directions the log cannot tell apart (in
words), the warnings, the replay and the whiteness test of each output."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from equilibrist.ident.log import Log
from equilibrist.ident.noise import STRUCTURAL_RATIO, _information_inverse
from equilibrist.ident.prediction import _Predictor
from equilibrist.ident.result import (
    WHITENESS_LAGS,
    WHITENESS_LEVEL,
    Estimate,
    Identification,
    OutputFit,
)
from equilibrist.ident.shooting import _Problem
from equilibrist.numeric.system import System

# A log-parameter direction whose standard deviation exceeds this (50 %
# relative) is not determined by this log.
WEAK_LOG_STD = 0.5


def _answer(system: System, log: Log, prob: _Problem, sol: Any, pred: _Predictor, psol: Any,
            theta0: np.ndarray, q_scale: float, L: int, dt: float, backend: str, max_step: float,
            lo_hi: tuple[np.ndarray, np.ndarray], nfev: int) -> Identification:
    theta, off, x0 = pred.split(psol.x)
    # A parameter that ended at a bound is reported at the bound itself.
    theta = np.where(psol.active_mask[: pred.n_theta] < 0, lo_hi[0][: pred.n_theta], theta)
    theta = np.where(psol.active_mask[: pred.n_theta] > 0, lo_hi[1][: pred.n_theta], theta)
    z = np.concatenate([theta, psol.x[pred.n_theta:]])
    # The replay: each shooting segment from its state, with the estimated parameters.
    _theta_ms, _off_ms, xs = prob.split(sol.x)
    yhat, _xend = prob.run(prob.p_of(theta)[None], xs[None])
    replayed = yhat[0] + off
    s2, S = _information(pred, z)
    names = list(prob.free) + [f"offset_{o}" for o in log.output_names][: prob.n_off]
    values = np.concatenate([theta, off[: prob.n_off]])
    # Log-parameters for the parameters (relative changes), noise units for
    # offsets; a parameter at (or near) zero is measured in its own standard error.
    sd_abs = np.sqrt(np.clip(np.diag(_information_inverse(S)) * s2, 0.0, None))
    mag = np.abs(theta)
    sd_t = sd_abs[: prob.n_theta]
    theta_scale = np.where(mag > 0.1 * sd_t, mag, np.where(sd_t > 0, sd_t, 1.0))
    scale = np.concatenate([theta_scale, pred.sigma_y[: prob.n_off]])
    lam, V = np.linalg.eigh(S * np.outer(scale, scale))
    undetermined, directions = _directions(names, lam, V, s2, n_theta=prob.n_theta)
    se, corr = _covariance(lam, V, s2, scale, undetermined)
    units = {p.name: p.unit for p in system.spec.parameters}
    estimates = []
    for a, name in enumerate(names):
        if a < prob.n_theta:
            unit, start = units[name], float(theta0[a])
        else:
            unit, start = system.state_units[prob.c_idx[a - prob.n_theta]], 0.0
        estimates.append(Estimate(name, float(values[a]), float(se[a]), start, unit))
    warnings = _estimate_warnings(names, corr, undetermined, estimates, prob.free, psol, lo_hi)
    fits = _output_fits(system, log, prob, pred, z, replayed)
    not_white = [f.name for f in fits if not f.white]
    if not_white:
        warnings.append(
            f"the residuals of {', '.join(not_white)} are not white (Ljung-Box, {WHITENESS_LEVEL:g} "
            "level): the model leaves structure in the data (a missing effect, or parameters "
            "held at wrong values)"
        )
    params = dict(system.params)
    for a, name in enumerate(prob.free):
        params[name] = float(theta[a])
    x_init = dict(zip(system.state_names, x0.tolist(), strict=True))
    return Identification(
        system=system.key,
        params=params,
        free=prob.free,
        estimates=tuple(estimates),
        correlation=corr,
        unidentifiable=tuple(directions),
        warnings=tuple(warnings),
        outputs=tuple(fits),
        output_names=log.output_names,
        time=log.time,
        measured=log.outputs,
        replayed=replayed,
        segment_starts=prob.bounds[:-1].copy(),
        initial_state=x_init,
        method=_method(log, n_seg=prob.n_seg, L=L, dt=dt, max_step=max_step, backend=backend,
                       nfev=nfev, s2=s2, converged=bool(psol.success)),
        source=log.source,
        noise={
            "sensor_std": dict(zip(log.output_names, pred.sigma_y.tolist(), strict=True)),
            "process_intensity": dict(zip(system.state_names, pred.q.tolist(), strict=True)),
            "process_scale": q_scale,
        },
    )


def _information(pred: _Predictor, z: np.ndarray) -> tuple[float, np.ndarray]:
    """The variance of the weighted prediction errors at *z*, and the information matrix
    of the parameters and offsets, the filter's initial state eliminated (its Schur
    complement)."""
    pred.set_weight(z)
    r = pred.residuals(z)
    J = pred.jacobian(z)
    n_res, n_dec = J.shape
    s2 = float(r @ r) / max(1, n_res - n_dec)
    H = J.T @ J
    nh = pred.n_head
    Haa, Hab, Hbb = H[:nh, :nh], H[:nh, nh:], H[nh:, nh:]
    try:
        from scipy.linalg import cho_factor, cho_solve

        S = Haa - Hab @ cho_solve(cho_factor(Hbb), Hab.T)
    except np.linalg.LinAlgError:
        S = Haa - Hab @ np.linalg.pinv(Hbb) @ Hab.T
    S = (S + S.T) / 2
    return s2, S


def _directions(names: list[str], lam: np.ndarray, V: np.ndarray, s2: float, *,
                n_theta: int) -> tuple[np.ndarray, list[str]]:
    """From the eigen-decomposition (*lam*, *V*) of the scaled information: which estimates
    the log does not determine, and in words the directions it cannot tell apart (a
    structural one, then the weak ones together)."""
    nh = len(names)
    lam_max = float(max(lam.max(), 1e-300))
    undetermined = np.zeros(nh, dtype=bool)
    directions: list[str] = []
    weak = np.zeros(nh, dtype=bool)
    weakest = 0.0
    for k in range(nh):
        structural = lam[k] <= STRUCTURAL_RATIO * lam_max
        std_log = math.sqrt(s2 / lam[k]) if lam[k] > 0 else math.inf
        v = V[:, k]
        involved = np.abs(v) >= 0.2 * np.abs(v).max()
        if structural:
            directions.append(_name_direction(names, v, n_theta))
            undetermined |= involved
        elif std_log > WEAK_LOG_STD:
            weak |= involved
            weakest = max(weakest, std_log)
    weak &= ~undetermined
    if weak.any():
        who = [n for n, w in zip(names, weak, strict=True) if w]
        directions.append(
            f"{_and(who)} {'is' if len(who) == 1 else 'are'} not determined by this log: "
            f"relative changes of up to +-{100 * min(weakest, 99.99):.0f} % "
            f"{'of it' if len(who) == 1 else 'along a combination of them'} fit as well "
            "(excite the rig more, or fix what you know with --set)")
    return undetermined, directions


def _covariance(lam: np.ndarray, V: np.ndarray, s2: float, scale: np.ndarray,
                undetermined: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The standard errors and the correlations of the estimates: the pseudo-inverse of the
    information on the determined directions (infinite errors, no correlations, for the
    undetermined estimates)."""
    lam_max = float(max(lam.max(), 1e-300))
    keep = lam > STRUCTURAL_RATIO * lam_max
    cov_l = (V[:, keep] / lam[keep]) @ V[:, keep].T * s2
    cov = cov_l * np.outer(scale, scale)
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    se[undetermined] = math.inf
    with np.errstate(all="ignore"):
        d = np.sqrt(np.diag(cov))
        corr = cov / np.outer(d, d)
    corr = np.where(np.isfinite(corr), corr, 0.0)
    corr[undetermined, :] = np.nan  # no correlation of what is not determined
    corr[:, undetermined] = np.nan
    np.fill_diagonal(corr, 1.0)
    return se, corr


def _estimate_warnings(names: Sequence[str], corr: np.ndarray, undetermined: np.ndarray,
                       estimates: Sequence[Estimate], free: Sequence[str], psol: Any,
                       lo_hi: tuple[np.ndarray, np.ndarray]) -> list[str]:
    """The warnings on the estimates: pairs the log barely tells apart, uncertain ones,
    those that ended at a bound, and an optimizer that did not converge."""
    nh = len(names)
    warnings = []
    for i in range(nh):
        for j in range(i):
            if math.isfinite(corr[i, j]) and abs(corr[i, j]) > 0.99 and not (undetermined[i] or undetermined[j]):
                warnings.append(f"{names[i]} and {names[j]} are correlated {corr[i, j]:+.3f}: "
                                "the log barely tells them apart")
    at_bound = {name for a, name in enumerate(free) if psol.active_mask[a] != 0}
    for e in estimates:
        if (math.isfinite(e.std_error) and math.isfinite(e.relative_error)
                and e.relative_error > WEAK_LOG_STD and e.name in free
                and e.name not in at_bound):
            warnings.append(f"{e.name} is uncertain by {100 * e.relative_error:.0f} % "
                            "(standard error over estimate)")
    for a, name in enumerate(free):
        if name in at_bound:
            bound = lo_hi[0][a] if psol.active_mask[a] < 0 else lo_hi[1][a]
            warnings.append(f"{name} ended at the bound of its valid range ({bound:g}): the log "
                            "asks for a value outside it (or the data do not determine it)")
    if not psol.success:
        warnings.append(f"the optimizer stopped before converging: {psol.message}")
    return warnings


def _output_fits(system: System, log: Log, prob: _Problem, pred: _Predictor, z: np.ndarray,
                 replayed: np.ndarray) -> list[OutputFit]:
    """Each output's fit: the replay's NRMSE and RMS error, the sensor's noise, and the
    Ljung-Box test of the filter's normalized prediction errors."""
    from scipy.stats import chi2

    e_pred, S_pred = pred.errors(z)
    innov = e_pred / np.sqrt(np.diag(S_pred))
    fits = []
    for j, name in enumerate(log.output_names):
        y = log.outputs[:, j]
        e = y - replayed[:, j]
        denom = float(np.linalg.norm(y - y.mean()))
        nrmse = float(np.linalg.norm(e) / denom) if denom > 0 else math.inf
        qv, pv, lags = _ljung_box(innov[:, j], chi2)
        fits.append(OutputFit(name, system.state_units[prob.c_idx[j]], nrmse,
                              float(np.sqrt(np.mean(e**2))), float(pred.sigma_y[j]), qv, pv, lags))
    return fits


def _method(log: Log, *, n_seg: int, L: int, dt: float, max_step: float, backend: str,
            nfev: int, s2: float, converged: bool) -> dict[str, Any]:
    """The record of how the estimate was made (:attr:`Identification.method`)."""
    seg_seconds = L * dt
    desc = (
        f"prediction error: the one-step prediction errors of a Kalman filter of the model (the "
        f"nonlinear model predicts, the steady-state gain of its linearization at the parameters "
        f"corrects), weighted by their covariance, the filter's initial state estimated; started "
        f"from a multiple-shooting fit ({n_seg} segments of {L} samples, {seg_seconds:g} s); the "
        f"logged input replayed with zero-order hold; RK4 at <= {max_step:g} s "
        f"({'compiled' if backend == 'compiled' else 'scipy solve_ivp'}); "
        f"scipy least_squares (trf), {nfev} evaluations"
    )
    return {
        "name": "prediction error",
        "start": "multiple shooting",
        "description": desc,
        "segments": n_seg,
        "segment_samples": L,
        "segment_seconds": seg_seconds,
        "integrator": "rk4",
        "max_step": max_step,
        "backend": backend,
        "samples": log.n_rows,
        "duration": log.duration,
        "evaluations": nfev,
        "residual_variance": s2,
        "converged": converged,
    }


def _ljung_box(e: np.ndarray, chi2: Any) -> tuple[float, float, int]:
    N = e.size
    h = int(min(WHITENESS_LAGS, max(1, N // 5)))
    x = e - e.mean()
    var = float(x @ x)
    if var == 0 or N < 3:
        return 0.0, 1.0, h
    rho = np.array([float(x[k:] @ x[:-k]) / var for k in range(1, h + 1)])
    qv = float(N * (N + 2) * np.sum(rho**2 / (N - np.arange(1, h + 1))))
    return qv, float(chi2.sf(qv, h)), h


def _and(names: Sequence[str]) -> str:
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _name_direction(names: list[str], v: np.ndarray, n_theta: int) -> str:
    """A direction of (log-)parameters that changes nothing, in words."""
    mags = np.abs(v)
    idx = [int(i) for i in np.argsort(-mags) if mags[i] >= 0.2 * mags.max()]
    if len(idx) == 1:
        name = names[idx[0]]
        if idx[0] >= n_theta:
            return f"{name} cannot be told apart from the states themselves: it is not identifiable"
        return f"{name} does not change the measured outputs: it cannot be identified from them"
    if len(idx) == 2 and all(i < n_theta for i in idx):
        a, b = idx
        exponent = -v[a] / v[b]  # the data depend on names[a] * names[b]**exponent only
        na, nb = names[a], names[b]
        forms = {1.0: f"{na}*{nb}", -1.0: f"{na}/{nb}", 2.0: f"{na}*{nb}^2",
                 -2.0: f"{na}/{nb}^2", 0.5: f"{na}*sqrt({nb})", -0.5: f"{na}/sqrt({nb})"}
        combo = next((f for e, f in forms.items() if abs(exponent - e) < 0.05 * max(1.0, abs(e))),
                     f"{na}*{nb}^{exponent:.3g}")
        return f"{na} and {nb} only appear as {combo} here: fix one of them (--set) to identify the other"
    parts = ", ".join(f"{names[i]} {v[i] / mags.max():+.2f}" for i in idx)
    return (f"{_and([names[i] for i in idx])} are determined only in combination: the data "
            f"cannot tell apart relative changes along ({parts})")
