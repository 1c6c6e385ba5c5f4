"""The hybrid loop against exact discrete-time solutions and the continuous closed loop."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from equilibrist.sim import LQG, StateFeedback, simulate
from support.sim import Q_REF, R_REF, cartpole, lqg, lqr, state_feedback, zoh

X0 = np.array([0.1, 0.15, -0.2, 0.3])


@pytest.mark.parametrize("substeps", [1, 4])
def test_linear_state_feedback_matches_exact_discrete_solution(substeps):
    rate = 100.0
    sysm = cartpole()
    ctrl = state_feedback(sysm, rate=rate)
    res = simulate(sysm, ctrl, duration=1.0, rate=rate, plant="linear", x0=X0,
                   physics_step=1.0 / (rate * substeps), region={})
    lm = sysm.linearize()
    Ad, Bd = zoh(lm.A, lm.B, 1.0 / rate)
    x = X0.copy()
    expected = [x]
    for _ in range(res.n_rows - 1):
        x = (Ad - Bd @ ctrl.K) @ x
        expected.append(x)
    expected = np.array(expected)
    np.testing.assert_allclose(res.states, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.applied[:, 0], -(expected @ ctrl.K.T)[:, 0], atol=1e-10)


@pytest.mark.parametrize("form", ["current", "predictor"])
@pytest.mark.parametrize("delay", [False, True])
def test_linear_lqg_matches_exact_closed_loop_recursion(form, delay):
    rate = 200.0
    sysm = cartpole()
    ctrl = lqg(sysm, rate=rate, form=form)
    res = simulate(sysm, ctrl, duration=0.5, rate=rate, plant="linear", x0=X0, delay=delay,
                   region={})
    lm = sysm.linearize()
    Ad, Bd = zoh(lm.A, lm.B, 1.0 / rate)
    idx = [0, 1]
    x, z, u_prev = X0.copy(), np.zeros(4), np.zeros(1)
    xs, us = [], []
    for _ in range(res.n_rows):
        y = x[idx]
        xhat = z + ctrl.Kf @ (y - z[idx]) if form == "current" else z
        u = -ctrl.K @ xhat
        u_app = u_prev if delay else u
        u_prev = u
        xs.append(x.copy())
        us.append(u_app.copy())
        if form == "current":
            z = Ad @ xhat + Bd @ u_app
        else:
            z = Ad @ z + Bd @ u_app + ctrl.Kf @ (y - z[idx])
        x = Ad @ x + Bd @ u_app
    np.testing.assert_allclose(res.states, np.array(xs), rtol=0, atol=1e-11)
    np.testing.assert_allclose(res.applied, np.array(us), rtol=0, atol=1e-9)


def test_hybrid_loop_converges_to_continuous_closed_loop():
    sysm = cartpole()
    lm = sysm.linearize()
    K = lqr(lm.A, lm.B, Q_REF, R_REF)
    ctrl = StateFeedback(K=K, x_op=lm.x0, u_op=lm.u0)
    x0 = np.array([0.0, 0.2, 0.0, 0.0])

    def closed(t, x):
        return sysm.f(x, -K @ x)

    sol = solve_ivp(closed, (0, 2.0), x0, rtol=1e-12, atol=1e-12, dense_output=True)
    errors = []
    for rate in (100.0, 400.0, 1600.0):
        res = simulate(sysm, ctrl, duration=2.0, rate=rate, x0=x0, physics_step=1 / 3200)
        ref = sol.sol(res.time).T
        errors.append(np.abs(res.states - ref).max())
    # Zero-order hold costs O(T): each quadrupling of the rate divides the error by 4.
    assert 3.6 < errors[0] / errors[1] < 4.4
    assert 3.6 < errors[1] / errors[2] < 4.4
    assert errors[2] < 2e-3


def test_adaptive_integrator_matches_reference_solution():
    sysm = cartpole()
    x0 = np.array([0.0, 0.3, 0.0, 0.0])
    res = simulate(sysm, None, duration=0.5, rate=50.0, integrator="adaptive", x0=x0,
                   rtol=1e-10, atol=1e-12, region={})
    sol = solve_ivp(lambda t, x: sysm.f(x, [0.0]), (0, 0.5), x0, rtol=1e-12, atol=1e-12,
                    dense_output=True)
    np.testing.assert_allclose(res.states, sol.sol(res.time).T, atol=1e-8)
    rk = simulate(sysm, None, duration=0.5, rate=50.0, x0=x0, physics_step=1e-3, region={})
    np.testing.assert_allclose(rk.states, res.states, atol=1e-9)


def test_operating_point_is_held_without_disturbance():
    sysm = cartpole()
    for ctrl in (state_feedback(sysm, rate=500.0), lqg(sysm, rate=500.0)):
        res = simulate(sysm, ctrl, duration=1.0)
        assert not res.fell
        np.testing.assert_array_equal(res.states, np.zeros_like(res.states))
        assert isinstance(ctrl, StateFeedback | LQG)
