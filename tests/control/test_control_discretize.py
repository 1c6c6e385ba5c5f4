"""Sampling a plant and its noise: ZOH against scipy, Van Loan against quadrature."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
import scipy.signal

from equilibrist.control import discrete_noise, discretize, van_loan
from equilibrist.errors import DesignError
from equilibrist.numeric.lookup import get_system
from equilibrist.systems import registry

ACTUATED = [e.spec.name for e in registry.all_entries() if e.spec.inputs and e.spec.variant is None]


@functools.cache
def _plant(name: str):
    return get_system(name).linearize()


@pytest.mark.parametrize("name", ACTUATED)
@pytest.mark.parametrize("dt", [0.001, 0.02])
def test_zoh_equals_scipy_cont2discrete(name: str, dt: float) -> None:
    lm = _plant(name)
    disc = discretize(lm, dt)
    Ad, Bd, Cd, _, dt_out = scipy.signal.cont2discrete((lm.A, lm.B, lm.C, lm.D), dt, method="zoh")
    np.testing.assert_allclose(disc.A, Ad, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(disc.B, Bd, rtol=1e-12, atol=1e-14 * np.abs(Bd).max())
    np.testing.assert_array_equal(disc.C, Cd)
    assert disc.dt == dt_out == dt
    assert disc.state_names == lm.state_names
    assert disc.output_names == lm.output_names
    np.testing.assert_array_equal(disc.x0, lm.x0)


def test_euler_is_the_seeds_forward_step() -> None:
    lm = _plant("cartpole")
    disc = discretize(lm, 0.01, method="euler")
    np.testing.assert_array_equal(disc.A, np.eye(4) + lm.A * 0.01)
    np.testing.assert_array_equal(disc.B, lm.B * 0.01)


def test_zoh_step_matches_integrating_the_ode() -> None:
    """A held input over one period: the ODE's solution equals Ad x + Bd u."""
    lm = _plant("cartpole")
    dt = 0.05
    disc = discretize(lm, dt)
    x0 = np.array([0.1, 0.05, -0.2, 0.3])
    u = np.array([1.5])
    sol = scipy.integrate.solve_ivp(
        lambda _t, x: lm.A @ x + lm.B @ u, (0, dt), x0, rtol=1e-12, atol=1e-14
    )
    np.testing.assert_allclose(sol.y[:, -1], disc.A @ x0 + disc.B @ u, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("name", ["cartpole", *[n for n in ACTUATED if n != "cartpole"][:2]])
def test_van_loan_equals_quadrature(name: str) -> None:
    lm = _plant(name)
    n = lm.n_states
    rng = np.random.default_rng(3)
    G = rng.normal(size=(n, 2))
    W = G @ np.diag([0.3, 2.0]) @ G.T
    T = 0.02
    Qd = van_loan(lm.A, W, T)
    integral, _ = scipy.integrate.quad_vec(
        lambda t: scipy.linalg.expm(lm.A * t) @ W @ scipy.linalg.expm(lm.A.T * t),
        0.0,
        T,
        epsabs=1e-14,
        epsrel=1e-12,
    )
    np.testing.assert_allclose(Qd, integral, rtol=1e-9, atol=1e-14 * np.abs(integral).max())
    np.testing.assert_array_equal(Qd, Qd.T)


def test_discrete_noise_methods_and_measurement_scaling() -> None:
    lm = _plant("cartpole")
    QN = np.diag([0.0, 0.0, 0.04, 0.09])
    RN = np.diag([1e-6, 4e-6])
    T = 0.005
    Qd, Rd = discrete_noise(lm.A, np.eye(4), QN, RN, T)
    np.testing.assert_allclose(Qd, van_loan(lm.A, QN, T))
    np.testing.assert_allclose(Rd, RN / T)
    Qe, Re = discrete_noise(lm.A, np.eye(4), QN, RN, T, method="euler")
    np.testing.assert_allclose(Qe, QN * T)
    np.testing.assert_allclose(Re, RN / T)
    # Van Loan's covariance reaches the positions by integration; Euler's does not.
    assert Qd[0, 0] > 0
    assert Qe[0, 0] == 0
    # Both agree to first order in T.
    np.testing.assert_allclose(Qd, Qe, atol=0.1 * np.abs(Qe).max())


def test_discretize_refuses_bad_requests() -> None:
    lm = _plant("cartpole")
    with pytest.raises(DesignError, match="positive number of seconds, got 0"):
        discretize(lm, 0.0)
    with pytest.raises(DesignError, match=r"positive number of seconds, got -0\.1"):
        discretize(lm, -0.1)
    with pytest.raises(DesignError, match="'tustin' is unknown: expected one of zoh, euler"):
        discretize(lm, 0.01, method="tustin")
    with pytest.raises(DesignError, match="already discrete"):
        discretize(discretize(lm, 0.01), 0.01)
