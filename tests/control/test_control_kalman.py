"""The discrete Kalman filter on simulated data with the stated noise.

Independent truth: Monte Carlo runs of the sampled cart-pole under LQG
control with process noise drawn from ``Qd`` and sensor noise from ``Rd``.
The estimation error must be unbiased and its covariance across runs must be
the filter's own ``P`` (a-posteriori for the current form, a-priori for the
predictor form) within sampling error.
"""

from __future__ import annotations

import functools

import control
import numpy as np
import pytest

from equilibrist.control import DiscreteKalmanFilter, Estimate, design
from equilibrist.control.riccati import current_gain
from equilibrist.errors import DesignError, DimensionError
from equilibrist.numeric.lookup import get_system

RUNS = 4000


@functools.cache
def _design(form: str):
    # Precise sensors at 50 Hz: each update shrinks the covariance by about half,
    # so confusing the a-priori and a-posteriori covariances would show.
    return design(get_system("cartpole"), rate=50.0, rn=[1e-8, 1e-8], kalman_form=form)


def _factor(cov: np.ndarray) -> np.ndarray:
    w, v = np.linalg.eigh(cov)
    return v * np.sqrt(np.clip(w, 0, None))


def _check_errors(errors: np.ndarray, P: np.ndarray) -> None:
    """Unbiased, and covariance P: per-state and normalized (NEES) checks at 5 sigma."""
    runs, n = errors.shape
    sd = np.sqrt(np.diag(P))
    mean = errors.mean(axis=0)
    assert np.all(np.abs(mean) < 5 * sd / np.sqrt(runs)), (mean, sd)
    var = errors.var(axis=0)
    assert np.all(np.abs(var / np.diag(P) - 1) < 5 * np.sqrt(2 / runs)), var / np.diag(P)
    nees = np.einsum("ri,ij,rj->r", errors, np.linalg.inv(P), errors)
    assert abs(nees.mean() - n) < 5 * np.sqrt(2 * n / runs), nees.mean()


def _simulate(form: str, steps: int, P0: np.ndarray, *, steady: bool, seed: int):
    d = _design(form)
    kf = d.kalman_filter
    F, B, H = kf.F, kf.B, kf.H
    n = F.shape[0]
    rng = np.random.default_rng(seed)
    w_factor, v_factor = _factor(kf.Qd), _factor(kf.Rd)
    x = rng.normal(size=(RUNS, n)) @ _factor(P0).T  # truth ~ N(0, P0) around the prior 0
    est = Estimate(np.zeros((RUNS, n)), P0)
    u_prev = np.zeros((RUNS, 1))
    for k in range(steps):
        y = x @ H.T + rng.normal(size=(RUNS, H.shape[0])) @ v_factor.T
        if form == "current":
            # xhat_{k|k} from xhat_{k-1|k-1}, u_{k-1}, y_k; covariance a-posteriori.
            if k:
                est = kf.step(est, u=u_prev, y=y, steady=steady)
            else:
                est = kf.update(est, y, gain=kf.steady_state.M if steady else None)
            used = est
        else:
            used = est  # xhat_{k|k-1}: computed before y_k
        u = -used.x @ d.K.T
        if k == steps - 1:
            return x - used.x, used.P, kf
        if form == "predictor":
            est = kf.step(est, u=u, y=y, steady=steady)
        x = x @ F.T + u @ B.T + rng.normal(size=(RUNS, n)) @ w_factor.T
        u_prev = u
    raise AssertionError("unreachable")


@pytest.mark.parametrize("form", ["current", "predictor"])
def test_steady_filter_error_is_unbiased_with_covariance_P(form: str) -> None:
    kf = _design(form).kalman_filter
    gains = kf.steady_state
    # The two covariances differ enough that a mix-up would be caught.
    ratio = np.diag(gains.P_posterior) / np.diag(gains.P_prior)
    assert ratio.min() < 0.7
    errors, P, _ = _simulate(form, 60, gains.P_prior, steady=True, seed=11)
    expected = gains.P_posterior if form == "current" else gains.P_prior
    np.testing.assert_allclose(P, expected, rtol=1e-6, atol=1e-9 * np.abs(expected).max())
    np.testing.assert_allclose(kf.steady_covariance, expected)
    _check_errors(errors, expected)


@pytest.mark.parametrize("form", ["current", "predictor"])
@pytest.mark.parametrize("steps", [4, 40])
def test_time_varying_filter_covariance_matches_the_errors(form: str, steps: int) -> None:
    """From a wide prior, the filter's own P_k describes the error during the transient too."""
    P0 = np.diag([0.2, 0.05, 0.5, 0.5]) ** 2
    errors, P, _ = _simulate(form, steps, P0, steady=False, seed=5 + steps)
    _check_errors(errors, P)


def test_gains_agree_with_python_control_dlqe() -> None:
    d = _design("predictor")
    kf = d.kalman_filter
    L, P, _ = control.dlqe(kf.F, np.eye(4), kf.H, kf.Qd, kf.Rd)
    np.testing.assert_allclose(kf.steady_state.P_prior, P, rtol=1e-8, atol=1e-16)
    # L = F P H' (H P H' + Rd)^-1 multiplies P's last bits by about 1/Rd: the gains agree
    # to that conditioning, and the Riccati residual of the project's P is no larger than
    # python-control's (an independent measure of which is more accurate).
    tol = 1e-10 * float(np.abs(L).max())
    np.testing.assert_allclose(kf.steady_state.L, L, rtol=1e-8, atol=tol)
    np.testing.assert_allclose(d.Kf, L, rtol=1e-8, atol=tol)

    def residual(X: np.ndarray) -> float:
        F, H, Qd, Rd = kf.F, kf.H, kf.Qd, kf.Rd
        S = H @ X @ H.T + Rd
        return float(np.abs(F @ X @ F.T - F @ X @ H.T @ np.linalg.solve(S, H @ X @ F.T)
                            + Qd - X).max())

    assert residual(kf.steady_state.P_prior) <= residual(P) + 1e-19
    np.testing.assert_allclose(d.P, P, rtol=1e-8, atol=1e-16)
    current = _design("current")
    np.testing.assert_allclose(current.Kf, kf.steady_state.M, rtol=1e-8, atol=1e-12)
    np.testing.assert_allclose(kf.steady_state.L, kf.F @ kf.steady_state.M, rtol=1e-12)


def test_riccati_iteration_converges_to_the_steady_state() -> None:
    kf = _design("current").kalman_filter
    est = Estimate(np.zeros(4), np.eye(4))
    for _ in range(3000):
        est = kf.update(kf.predict(est, np.zeros(1)), np.zeros(2))
    np.testing.assert_allclose(est.P, kf.steady_state.P_posterior, rtol=1e-7, atol=1e-16)
    prior = kf.predict(est, np.zeros(1)).P
    np.testing.assert_allclose(prior, kf.steady_state.P_prior, rtol=1e-7, atol=1e-16)


def test_joseph_form_equals_the_short_form_for_the_optimal_gain() -> None:
    kf = _design("current").kalman_filter
    rng = np.random.default_rng(0)
    X = rng.normal(size=(4, 4))
    P = X @ X.T
    updated = kf.update(Estimate(np.zeros(4), P), np.zeros(2))
    M = current_gain(P, kf.H, kf.Rd)
    np.testing.assert_allclose(updated.P, (np.eye(4) - M @ kf.H) @ P, rtol=1e-9, atol=1e-12)
    # For a gain that is not optimal, only the Joseph form is a covariance.
    bad = kf.update(Estimate(np.zeros(4), P), np.zeros(2), gain=3 * M)
    assert np.all(np.linalg.eigvalsh(bad.P) > 0)


@pytest.mark.parametrize("form", ["current", "predictor"])
def test_run_equals_stepping(form: str) -> None:
    kf = _design(form).kalman_filter
    rng = np.random.default_rng(1)
    y = rng.normal(size=(20, 2)) * 0.01
    u = rng.normal(size=(20, 1))
    run = kf.run(y, u, x0=np.full(4, 0.01))
    assert run.x.shape == (20, 4)
    assert run.P.shape == (20, 4, 4)
    est = Estimate(np.full(4, 0.01), kf.steady_state.P_prior)
    for k in range(20):
        if form == "current":
            est = kf.update(est, y[0]) if k == 0 else kf.step(est, u=u[k - 1], y=y[k])
            np.testing.assert_allclose(run.x[k], est.x)
        else:
            np.testing.assert_allclose(run.x[k], est.x)
            est = kf.step(est, u=u[k], y=y[k])
    np.testing.assert_array_equal(run.state("theta"), run.x[:, 1])


def test_filter_validation() -> None:
    kf = _design("current").kalman_filter
    with pytest.raises(DesignError, match="Kalman form 'smoother' is unknown"):
        DiscreteKalmanFilter.from_model(_design("current").discrete, kf.Qd, kf.Rd, form="smoother")
    with pytest.raises(DesignError, match="Rd is not positive definite"):
        DiscreteKalmanFilter.from_model(_design("current").discrete, kf.Qd, np.zeros((2, 2)))
    with pytest.raises(DimensionError, match=r"Qd has shape \(3, 3\), expected \(4, 4\)"):
        DiscreteKalmanFilter.from_model(_design("current").discrete, np.eye(3), kf.Rd)
    with pytest.raises(DesignError, match="needs a discrete model"):
        DiscreteKalmanFilter.from_model(_design("current").plant, kf.Qd, kf.Rd)
    with pytest.raises(DimensionError, match="y has shape"):
        kf.run(np.zeros((5, 3)), np.zeros((5, 1)))
