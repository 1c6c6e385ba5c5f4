"""A rig's effects in the compiled core, each checked against its own definition computed
here from the recorded run (numpy), and the perturbations against an independent
integration (RK4 on a finer grid in numpy, the mass matrix solved by numpy)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.controllers import kinds
from equilibrist.errors import SimulationError
from equilibrist.sim.batch import simulate_batch
from equilibrist.sim.rig import Rig
from equilibrist.sim.run import simulate

RATE = 100.0
START = {"theta1": math.pi + 0.05}


@pytest.fixture(scope="module")
def loop():
    system = get_system("acrobot")
    request = kinds.ControllerRequest(system=system, rate=RATE, design_options={},
                                      tracking=False, options={})
    return system, kinds.get("lqr", "simulate").make(request)


def _run(loop, rig=None, **kw):
    system, ctrl = loop
    return simulate(system, ctrl, duration=kw.pop("duration", 1.0), x0=START, rig=rig, **kw)


def test_no_rig_is_the_same_bits(loop):
    plain, empty = _run(loop), _run(loop, Rig())
    assert np.array_equal(plain.states, empty.states)
    assert np.array_equal(plain.applied, empty.applied)
    assert "rig" not in plain.settings and "rig" not in empty.settings


def test_torque_response_and_actuation_delay(loop):
    k, d = 0.3, 2
    res = _run(loop, Rig(torque_response=k, actuation_delay=d))
    sat = res.saturated[:, 0]
    want = np.zeros_like(sat)
    prev = 0.0  # the operating point's input
    for i in range(len(sat)):
        desired = sat[i - d] if i >= d else 0.0
        prev = prev + k * (desired - prev)
        want[i] = prev
    np.testing.assert_allclose(res.applied[:, 0], want, rtol=0, atol=1e-12)
    assert res.settings["rig"] == {"torque_response": k, "actuation_delay": d}


def test_time_constant_is_the_sampled_first_order_lag(loop):
    tc = 0.05
    a = _run(loop, Rig(torque_time_constant=tc))
    b = _run(loop, Rig(torque_response=1 - math.exp(-1 / (RATE * tc))))
    np.testing.assert_allclose(a.applied, b.applied, rtol=0, atol=1e-12)


def test_measurement_delay_in_seconds_and_samples(loop):
    res = _run(loop, Rig(measurement_delay_time=0.03))
    y, x = res.measurements, res.states
    idx = [res.state_names.index(o) for o in res.output_names]
    np.testing.assert_array_equal(y[3:], x[:-3, idx])
    np.testing.assert_array_equal(y[:3], np.repeat(x[:1, idx], 3, axis=0))
    with pytest.raises(SimulationError, match="whole number of periods"):
        _run(loop, Rig(measurement_delay_time=0.015))


def test_encoder_and_velocity_filter(loop):
    step, fc = 2 * math.pi / 4096, 20.0
    res = _run(loop, Rig(encoder_step=step, velocity_filter=fc))
    x, y = res.states, res.measurements
    names = list(res.output_names)
    a = 1 - math.exp(-2 * math.pi * fc / RATE)
    for j, q in enumerate(("theta1", "theta2")):
        pos = step * np.floor(x[:, j] / step)
        np.testing.assert_array_equal(y[:, names.index(q)], pos)
        raw = np.concatenate([[0.0], np.diff(pos) * RATE])
        filt = np.empty_like(raw)
        filt[0] = raw[0]
        for i in range(1, len(raw)):
            filt[i] = filt[i - 1] + a * (raw[i] - filt[i - 1])
        np.testing.assert_allclose(y[:, names.index(q + "_dot")], filt, rtol=0, atol=1e-9)


def test_noise_statistics(loop):
    res = _run(loop, Rig(torque_noise=0.2, velocity_noise=0.1), duration=20.0, seed=3)
    names = list(res.output_names)
    x = res.states
    for q in ("theta1", "theta2"):
        assert np.array_equal(res.measurements[:, names.index(q)], x[:, names.index(q)])
        e = res.measurements[:, names.index(q + "_dot")] - x[:, names.index(q + "_dot")]
        assert abs(np.std(e) - 0.1) < 0.01 and abs(np.mean(e)) < 0.01
    lo, hi = -20.0, 20.0
    inside = (res.applied[:, 0] > lo) & (res.applied[:, 0] < hi)
    e = (res.applied[:, 0] - res.saturated[:, 0])[inside]
    assert abs(np.std(e) - 0.2) < 0.02 and abs(np.mean(e)) < 0.02
    again = _run(loop, Rig(torque_noise=0.2, velocity_noise=0.1), duration=20.0, seed=3)
    assert np.array_equal(res.states, again.states)


def test_perturbations_match_an_independent_integration(loop):
    system, _ = loop
    rig = Rig(perturbations=1, perturbation_gap=0.2, perturbation_amplitude=(0.5, 1.0),
              perturbation_joints=("theta1",))
    res = simulate(system, None, duration=1.0, rate=RATE, x0=START, rig=rig, seed=5)
    pulses = res.settings["rig"]["pulses"]
    assert pulses["joints"] == ["theta1"]
    mu, sig, amp = (pulses[k][0][0] for k in ("times", "widths", "amplitudes"))
    u = np.zeros(system.n_inputs)

    def rhs(s, tau):
        dx = system.f(s, u)
        mass = np.zeros((2, 2))
        system.functions.mass_matrix(s, system.p, mass)
        dx[2:] += np.linalg.solve(mass, tau)
        return dx

    # RK4 with steps half the core's (1 ms): the same ODE, another grid.
    x = np.array(res.states[0])
    h = 1 / RATE / 20
    for k in range(len(res.time) - 1):
        tau = np.array([amp * math.exp(-((k / RATE - mu) ** 2) / (2 * sig**2)), 0.0])
        for _ in range(20):
            k1 = rhs(x, tau)
            k2 = rhs(x + h / 2 * k1, tau)
            k3 = rhs(x + h / 2 * k2, tau)
            k4 = rhs(x + h * k3, tau)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    np.testing.assert_allclose(res.states[-1], x, rtol=0, atol=1e-7)
    free = simulate(system, None, duration=1.0, rate=RATE, x0=START)
    assert np.abs(free.states[-1] - res.states[-1]).max() > 1e-2


def test_batch_run_is_the_single_run(loop):
    system, ctrl = loop
    rig = Rig(torque_noise=0.1, perturbations=1, perturbation_gap=0.2,
              perturbation_amplitude=(0.1, 0.2), measurement_delay=1)
    batch = simulate_batch(system, ctrl, runs=3, duration=1.0, x0=START, rig=rig, seed=9,
                           workers=2)
    one = simulate(system, ctrl, duration=1.0, x0=START, rig=rig, seed=batch.seed(2))
    assert np.array_equal(batch.final_state[2], one.final_state)


def test_bad_rigs_are_refused_in_one_message(loop):
    with pytest.raises(SimulationError) as err:
        _run(loop, Rig(torque_noise=-1.0, actuation_delay=-2, perturbation_joints=("x",)))
    text = str(err.value)
    assert "torque_noise" in text and "actuation_delay" in text and "'x'" in text


def test_pulses_on_passive_joints_dropped_when_asked(loop):
    from equilibrist.sim.rig import actuated

    system, _ctrl = loop
    # The acrobot's motor is at the elbow, the pendubot's at the shoulder.
    assert actuated(system).tolist() == [False, True]
    assert actuated(get_system("pendubot")).tolist() == [True, False]
    rig = Rig(perturbations=1, perturbation_gap=0.2, perturbation_joints=("theta1",),
              perturb_passive=False)
    pushed = _run(loop, rig, seed=2)
    assert np.array_equal(pushed.states, _run(loop).states)


def test_a_controller_in_python_meets_the_same_rig(loop):
    system, _ = loop
    k, d = 0.4, 3

    def push(t, y, r):
        return [2.0 if t < 0.5 else -1.0]

    res = simulate(system, push, duration=1.0, rate=RATE, x0=START,
                   rig=Rig(torque_response=k, measurement_delay=d, perturbations=1,
                           perturbation_gap=0.2, perturbation_amplitude=(0.1, 0.2)), seed=1)
    want, prev = [], 0.0
    for u in res.saturated[:, 0]:
        prev = prev + k * (u - prev)
        want.append(prev)
    np.testing.assert_allclose(res.applied[:, 0], want, rtol=0, atol=1e-12)
    idx = [res.state_names.index(o) for o in res.output_names]
    np.testing.assert_array_equal(res.measurements[d:], res.states[:-d, idx])
    assert "pulses" in res.settings["rig"]
