"""Controllers: the compiled built-ins against their plain-Python twins; user controllers."""

from __future__ import annotations

import numpy as np
import pytest

from equilibrist.errors import SimulationError
from equilibrist.sim import OpenLoop, Pulse, Ramp, Step, simulate
from equilibrist.sim.controllers import StateFeedback
from support.sim import cartpole, lqg, state_feedback
from support.sim import cartpole_noise as _noise


@pytest.mark.parametrize("form", ["current", "predictor"])
def test_python_path_reproduces_compiled_lqg(form):
    sysm = cartpole(F_max=15.0, F_min=-15.0)
    ctrl = lqg(sysm, rate=250.0, form=form, qd_scale=1e-4, rd_scale=1e-5)
    noise = _noise(sysm, 250.0)
    opts = dict(duration=2.0, x0={"theta": 0.15}, noise=noise, seed=42, delay=True,
                physics_step=1e-3, events=[Pulse(0.5, 30.0, 0.05)])
    compiled = simulate(sysm, ctrl, **opts)
    python = simulate(sysm, ctrl.runtime(sysm.state_names), **opts)
    assert np.any(compiled.saturated != compiled.commanded)  # saturation was exercised
    np.testing.assert_allclose(python.states, compiled.states, rtol=0, atol=1e-10)
    np.testing.assert_allclose(python.estimates, compiled.estimates, rtol=0, atol=1e-10)
    np.testing.assert_allclose(python.applied, compiled.applied, rtol=0, atol=1e-8)
    np.testing.assert_array_equal(python.measurements - python.states[:, :2],
                                  compiled.measurements - compiled.states[:, :2])


def test_python_path_reproduces_compiled_tracking():
    sysm = cartpole()
    base = state_feedback(sysm, rate=500.0)
    # Kc for the cart position: -1 / (C (A - B K)^-1 B) of the sampled loop.
    from support.sim import zoh

    lm = sysm.linearize()
    Ad, Bd = zoh(lm.A, lm.B, 1 / 500)
    C = np.array([[1.0, 0, 0, 0]])
    kc = 1.0 / (C @ np.linalg.solve(np.eye(4) - (Ad - Bd @ base.K), Bd))
    ctrl = StateFeedback(K=base.K, x_op=base.x_op, u_op=base.u_op, Kc=kc, tracked=("x",),
                         rate=500.0)
    compiled = simulate(sysm, ctrl, duration=15.0, reference=Step(0.5, at=0.5))
    python = simulate(sysm, ctrl.runtime(sysm.state_names), duration=15.0, rate=500.0,
                      reference=Step(0.5, at=0.5))
    np.testing.assert_allclose(python.states, compiled.states, atol=1e-10)
    assert compiled.state("x")[-1] == pytest.approx(0.5, abs=1e-3)
    assert compiled.reference_of("x")[0] == 0.0
    assert compiled.reference_of("x")[-1] == 0.5
    ramp = simulate(sysm, ctrl, duration=1.0, reference=Ramp(0.1))
    np.testing.assert_allclose(ramp.reference[:, 0], 0.1 * ramp.time)


def test_user_function_controller_and_its_measurements():
    sysm = cartpole()
    K = state_feedback(sysm).K
    seen = []

    def pd(t, y, r):
        seen.append((t, y.copy(), r.copy()))
        return -(K @ np.r_[y, 0.0, 0.0])

    res = simulate(sysm, pd, duration=0.1, rate=100.0, x0={"theta": 0.05})
    assert len(seen) == res.n_rows
    assert seen[0][0] == 0.0 and seen[1][0] == pytest.approx(0.01)
    np.testing.assert_array_equal(seen[0][1], [0.0, 0.05])  # the default outputs x, theta
    assert seen[0][2].shape == (0,)
    assert res.estimates is None


def test_user_controller_class_with_reset_and_estimate():
    sysm = cartpole()

    class Hold:
        def __init__(self):
            self.resets = 0
            self.estimate = np.zeros(4)

        def reset(self):
            self.resets += 1

        def step(self, t, y, r):
            self.estimate = np.array([y[0], y[1], 0.0, 0.0])
            return [0.0]

    ctrl = Hold()
    res = simulate(sysm, ctrl, duration=0.05, rate=100.0, x0={"theta": 0.01})
    assert ctrl.resets == 1
    np.testing.assert_allclose(res.estimate("theta"), res.state("theta"))


def test_user_controller_returning_garbage_is_a_clear_error():
    sysm = cartpole()
    with pytest.raises(SimulationError, match=r"t = 0 s.*1 finite input"):
        simulate(sysm, lambda t, y, r: [np.nan], duration=0.1, rate=100.0)
    with pytest.raises(SimulationError, match="1 finite input"):
        simulate(sysm, lambda t, y, r: [1.0, 2.0], duration=0.1, rate=100.0)


def test_open_loop_signal_drives_the_input():
    sysm = cartpole()
    res = simulate(sysm, OpenLoop(Step(5.0, at=0.1)), duration=0.3, rate=100.0, region={})
    assert np.all(res.input("F")[res.time < 0.1 - 1e-12] == 0.0)
    assert np.all(res.input("F")[res.time >= 0.1 - 1e-12] == 5.0)
    assert res.state("x_dot")[-1] > 0  # pushed to the right


def test_lqg_needs_its_design_rate():
    sysm = cartpole()
    with pytest.raises(SimulationError, match="designed for 200 Hz"):
        simulate(sysm, lqg(sysm, rate=200.0), duration=1.0, rate=1000.0)


@pytest.mark.parametrize("integrator", ["rk4", "adaptive"])
def test_run_cut_into_pieces_equals_one_piece(monkeypatch, integrator):
    from equilibrist.sim import run as run_module

    sysm = cartpole()
    ctrl = lqg(sysm, rate=100.0, qd_scale=1e-4, rd_scale=1e-5)
    opts = dict(duration=1.0, x0={"theta": 0.1}, noise=_noise(sysm, 100.0), seed=4,
                integrator=integrator, physics_step=2.5e-3, rtol=1e-6, atol=1e-9)
    whole = simulate(sysm, ctrl, **opts)
    monkeypatch.setattr(run_module, "_FIRST_CHUNK_STEPS", 28)  # a first piece of 7 samples,
    monkeypatch.setattr(run_module, "CHUNK_SECONDS", 1e-12)  # then pieces of one sample
    pieces = simulate(sysm, ctrl, progress=True, **opts)
    np.testing.assert_array_equal(pieces.states, whole.states)
    np.testing.assert_array_equal(pieces.estimates, whole.estimates)
    python = simulate(sysm, ctrl.runtime(sysm.state_names), **opts)
    np.testing.assert_allclose(python.states, whole.states, rtol=0, atol=1e-10)


def test_settings_asked_again_run_the_same_and_check_each_initial_state():
    # simulate remembers validated settings; another initial state is still checked.
    sysm = cartpole()
    ctrl = lqg(sysm, rate=100.0)
    opts = dict(duration=0.3, noise=_noise(sysm, 100.0), seed=2)
    first = simulate(sysm, ctrl, x0={"theta": 0.1}, **opts)
    other = simulate(sysm, ctrl, x0={"theta": -0.15}, **opts)
    again = simulate(sysm, ctrl, x0={"theta": 0.1}, **opts)
    np.testing.assert_array_equal(again.states, first.states)
    np.testing.assert_array_equal(again.estimates, first.estimates)
    assert other.states[0, sysm.state_names.index("theta")] == -0.15
    assert other.settings["x0"][sysm.state_names.index("theta")] == -0.15
    with pytest.raises(SimulationError, match="no state 'thet'"):
        simulate(sysm, ctrl, x0={"thet": 0.1}, **opts)
    with pytest.raises(SimulationError, match="initial state has 3 values"):
        simulate(sysm, ctrl, x0=[0.0, 0.1, 0.0], **opts)
    with pytest.raises(SimulationError, match="not a finite number"):
        simulate(sysm, ctrl, x0={"theta": float("nan")}, **opts)


def test_descriptions_from_a_design_read_the_design():
    from equilibrist.control.design import design
    from equilibrist.sim.controllers import LQG

    d = design(cartpole(), rate=200.0)
    lqg_d, sf_d = LQG.from_design(d), StateFeedback.from_design(d)
    # The gains are the design's own arrays, not copies.
    assert np.shares_memory(lqg_d.K, d.K) and np.shares_memory(lqg_d.Kf, d.Kf)
    assert np.shares_memory(lqg_d.Ad, d.discrete.A) and np.shares_memory(lqg_d.Bd, d.discrete.B)
    assert np.shares_memory(sf_d.K, d.K)
    # Written out by hand, the same description and the same controller.
    given = LQG(K=d.K, Ad=d.discrete.A, Bd=d.discrete.B, Kf=d.Kf,
                outputs=d.plant.output_names, x_op=d.plant.x0, u_op=d.plant.u0,
                rate=200.0, form=d.kalman_form)
    assert given.describe() == lqg_d.describe()
    names = d.plant.state_names
    assert given.linear(names).fingerprint == lqg_d.linear(names).fingerprint
    assert lqg_d.linear(names) is lqg_d.linear(names)
    with pytest.raises(AttributeError):
        lqg_d.K = d.K
