"""Events (pushes, parameter changes, initial conditions) and falling over."""

from __future__ import annotations

import math

import numpy as np
import pytest

from equilibrist.errors import SimulationError
from equilibrist.sim import (
    Impulse,
    Kick,
    OpenLoop,
    ParameterChange,
    Pulse,
    Samples,
    Stepper,
    simulate,
)
from support.sim import cartpole, state_feedback


def _rk4_reference(sysm, x, u, h, n):
    """RK4 in numpy on the validated ``System.f``: an independent integrator."""
    x = np.array(x, dtype=float)
    for _ in range(n):
        k1 = sysm.f(x, u)
        k2 = sysm.f(x + h / 2 * k1, u)
        k3 = sysm.f(x + h / 2 * k2, u)
        k4 = sysm.f(x + h * k3, u)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x


def test_stepper_matches_numpy_rk4():
    sysm = cartpole()
    x0 = [0.1, 0.3, -0.2, 0.5]
    got = Stepper(sysm, physics_step=2e-3).advance(x0, [3.0], n_steps=50)
    np.testing.assert_allclose(got, _rk4_reference(sysm, x0, [3.0], 2e-3, 50), rtol=1e-12,
                               atol=1e-13)


def test_open_loop_run_matches_numpy_rk4():
    sysm = cartpole()
    x0 = np.array([0.0, 0.1, 0.0, 0.0])
    res = simulate(sysm, None, duration=0.2, rate=100.0, physics_step=2.5e-3, x0=x0)
    np.testing.assert_allclose(res.states[-1], _rk4_reference(sysm, x0, [0.0], 2.5e-3, 80),
                               rtol=1e-12, atol=1e-13)


def test_kick_changes_the_state_by_its_value():
    sysm = cartpole()
    res = simulate(sysm, None, duration=0.1, rate=100.0, events=[Kick(0.05, "theta_dot", 0.4)],
                   region={})
    k = 5
    before = res.states[k]
    after = _rk4_reference(sysm, before + np.array([0, 0, 0, 0.4]), [0.0], 1e-3, 10)
    np.testing.assert_allclose(res.states[k + 1], after, rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(res.states[: k + 1], 0.0)


def test_pulse_is_a_force_added_to_the_input_channel():
    sysm = cartpole()
    pulse = simulate(sysm, None, duration=0.5, rate=100.0, events=[Pulse(0.1, 7.0, 0.2)],
                     region={})
    signal = Samples([0.0, 0.1 - 1e-9, 0.1, 0.3 - 1e-9, 0.3], [0, 0, 7.0, 7.0, 0])
    driven = simulate(sysm, OpenLoop(signal), duration=0.5, rate=100.0, region={})
    np.testing.assert_allclose(pulse.states, driven.states, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(pulse.applied, 0.0)  # the actuator did nothing


def test_pulse_bypasses_actuator_saturation():
    sysm = cartpole(F_max=1.0, F_min=-1.0)
    res = simulate(sysm, None, duration=0.3, rate=100.0, events=[Pulse(0.0, 50.0, 0.1)],
                   region={})
    # a_cart = F / (m_c + m_p (1 - ...)) ~ 50 / 10.x: far beyond what 1 N gives.
    assert res.state("x_dot")[-1] > 0.3


def test_impulse_gives_its_momentum():
    sysm = cartpole(m_p=1e-6, I_p=1e-9)  # a bare cart: momentum = m_c * v
    res = simulate(sysm, None, duration=0.1, rate=100.0, events=[Impulse(0.02, 5.0)],
                   region={})
    assert res.state("x_dot")[-1] * sysm.params["m_c"] == pytest.approx(5.0, rel=1e-5)


def test_parameter_change_equals_a_run_continued_with_new_parameters():
    sysm = cartpole()
    ctrl = state_feedback(sysm, rate=200.0)
    x0 = {"theta": 0.1}
    whole = simulate(sysm, ctrl, duration=2.0, x0=x0,
                     events=[ParameterChange(1.0, {"m_p": 3.0, "l": 0.7})])
    first = simulate(sysm, ctrl, duration=1.0, x0=x0)
    second = simulate(sysm.with_params(m_p=3.0, l=0.7), ctrl, duration=1.0,
                      x0=first.final_state)
    np.testing.assert_array_equal(whole.states[:201], first.states)
    np.testing.assert_allclose(whole.states[200:], second.states, rtol=0, atol=1e-15)
    assert whole.params["m_p"] == 1.0  # the result records the starting parameters


def test_fall_stops_the_run_with_flag_and_time():
    sysm = cartpole()
    res = simulate(sysm, None, duration=5.0, rate=100.0, x0={"theta": 0.1})
    free = simulate(sysm, None, duration=5.0, rate=100.0, x0={"theta": 0.1}, region={})
    assert res.fell and res.fell_state == "theta"
    assert not np.isnan(res.states).any()
    first_out = np.nonzero(free.state("theta") >= math.pi / 2)[0][0]
    # It fell during the physics step before the first sample past horizontal.
    assert free.time[first_out - 1] < res.fell_at <= free.time[first_out]
    assert res.n_rows == first_out
    assert res.fell_x[1] >= math.pi / 2
    assert res.metrics()["fell"] is True
    assert res.metrics()["fell_at"] == res.fell_at


def test_diverged_run_is_a_fall_not_nans():
    sysm = cartpole()
    res = simulate(sysm, None, duration=1.0, rate=10.0, physics_step=0.1,
                   x0={"theta_dot": 1e200}, region={})
    assert res.fell and res.fell_state == "not finite"
    assert np.all(np.isfinite(res.states))


def test_start_outside_region_falls_at_zero():
    sysm = cartpole()
    res = simulate(sysm, None, duration=1.0, rate=100.0, x0={"theta": 2.0})
    assert res.fell and res.fell_at == 0.0 and res.n_rows == 1


def test_event_problems_are_collected():
    sysm = cartpole()
    with pytest.raises(SimulationError) as info:
        simulate(sysm, None, duration=1.0, rate=100.0,
                 events=[Kick(0.1, "phi_dot", 1.0), Pulse(2.0, 1.0, 0.1),
                         ParameterChange(0.5, {"m_p": -1.0})])
    msg = str(info.value)
    assert "phi_dot" in msg and "after the end" in msg and "m_p" in msg
