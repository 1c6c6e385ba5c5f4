"""Results: names and units with the arrays, lossless files, metrics from first principles."""

from __future__ import annotations

import numpy as np
import pytest

from equilibrist.errors import SimulationError, UnknownNameError
from equilibrist.sim import Kick, SimResult, Step, simulate
from equilibrist.sim.controllers import StateFeedback
from support.sim import cartpole, lqg, state_feedback
from support.sim import cartpole_noise as _noise


@pytest.fixture(scope="module")
def noisy_run():
    sysm = cartpole(F_max=40.0, F_min=-40.0)
    ctrl = lqg(sysm, rate=200.0, qd_scale=1e-4, rd_scale=1e-5)
    return simulate(sysm, ctrl, duration=2.0, x0={"theta": 0.2}, noise=_noise(sysm, 200.0),
                    seed=1, events=[Kick(1.0, "theta_dot", 0.05)])


def test_names_units_and_shapes(noisy_run):
    r = noisy_run
    assert not r.fell
    assert r.states.shape == (401, 4) and r.applied.shape == (401, 1)
    assert r.output_names == ("x", "theta")
    assert r.unit("theta") == "rad" and r.unit("theta_dot") == "rad/s" and r.unit("F") == "N"
    assert r.output_units == ("m", "rad")
    np.testing.assert_array_equal(r.state("theta"), r.states[:, 1])
    np.testing.assert_array_equal(r.measurement("theta"), r.measurements[:, 1])
    np.testing.assert_array_equal(r.command("F"), r.commanded[:, 0])
    assert r.time[1] == pytest.approx(0.005)
    with pytest.raises(UnknownNameError, match="did you mean 'theta'"):
        r.state("thetaa")
    with pytest.raises(ValueError, match="read-only"):
        r.states[0, 0] = 1.0


def test_saturated_and_applied_follow_the_limits(noisy_run):
    r = noisy_run
    np.testing.assert_array_equal(r.saturated, np.clip(r.commanded, -40.0, 40.0))
    np.testing.assert_array_equal(r.applied, r.saturated)  # no delay
    assert np.any(r.commanded != r.saturated)


def test_npz_round_trip_is_lossless(noisy_run, tmp_path):
    r = noisy_run
    back = SimResult.load(r.save(tmp_path / "run.npz"))
    for name in ("time", "states", "estimates", "measurements", "commanded", "saturated",
                 "applied", "reference", "x_op", "u_op", "final_state"):
        np.testing.assert_array_equal(getattr(back, name), getattr(r, name))
    assert back.settings == r.settings
    assert back.params == r.params
    assert back.metrics() == r.metrics()


def test_csv_round_trip_is_lossless(noisy_run, tmp_path):
    r = noisy_run
    cols = SimResult.read_csv(r.to_csv(tmp_path / "run.csv"))
    header = (tmp_path / "run.csv").read_text().splitlines()[2]
    # The log of the run first (t, inputs, measured outputs), as identify reads it.
    assert header.startswith("t [s],F [N],x [m],theta [rad],x_true [m]")
    np.testing.assert_array_equal(cols["theta_true"], r.state("theta"))
    np.testing.assert_array_equal(cols["theta_hat"], r.estimate("theta"))
    np.testing.assert_array_equal(cols["F_commanded"], r.command("F"))
    np.testing.assert_array_equal(cols["F"], r.input("F"))
    np.testing.assert_array_equal(cols["x"], r.measurement("x"))
    back = SimResult.load(tmp_path / "run.csv")
    for name in ("time", "states", "estimates", "measurements", "commanded", "saturated",
                 "applied", "reference", "x_op", "u_op", "final_state"):
        np.testing.assert_array_equal(getattr(back, name), getattr(r, name))
    assert back.metrics() == r.metrics()


def test_loading_something_else_is_a_clear_error(tmp_path):
    (tmp_path / "x.npz").write_bytes(b"nope")
    with pytest.raises(SimulationError, match="not a saved simulation result"):
        SimResult.load(tmp_path / "x.npz")
    with pytest.raises(SimulationError, match="no result file"):
        SimResult.load(tmp_path / "missing.npz")


def test_metrics_of_a_step_response_from_first_principles():
    sysm = cartpole()
    base = state_feedback(sysm, rate=500.0)
    ctrl = StateFeedback(K=base.K, x_op=base.x_op, u_op=base.u_op,
                         Kc=[[base.K[0, 0]]], tracked=("x",), rate=500.0)
    r = simulate(sysm, ctrl, duration=15.0, reference=Step(1.0))
    m = r.metrics()
    x = r.state("x")
    e = x - 1.0
    # Settling: the first sample after which |e| stays within 2 % of its peak (1.0).
    outside = np.nonzero(np.abs(e) > 0.02 * np.abs(e).max())[0]
    assert m["settling_time"] == pytest.approx(r.time[outside[-1] + 1])
    assert m["overshoot"]["x"] == pytest.approx(max(0.0, x.max() - 1.0))
    assert m["final_error"]["x"] == pytest.approx(e[-1])
    assert m["peak_input"]["F"] == pytest.approx(np.abs(r.command("F")).max())
    assert m["rms_input"]["F"] == pytest.approx(np.sqrt(np.mean(r.input("F") ** 2)))
    assert m["time_saturated"] == 0.0
    assert m["stayed_up"] and m["fell_at"] is None
    assert m["estimation_error_rms"] == {"x": 0.0, "theta": 0.0, "x_dot": 0.0, "theta_dot": 0.0}


def test_time_in_saturation_counts_samples():
    sysm = cartpole(F_max=5.0, F_min=-5.0)
    r = simulate(sysm, state_feedback(sysm, rate=100.0), duration=2.0, x0={"theta": 0.05})
    n_sat = np.count_nonzero(np.abs(r.command("F")) > 5.0)
    assert n_sat > 0
    assert r.metrics()["time_saturated"] == pytest.approx(n_sat / 100.0)
