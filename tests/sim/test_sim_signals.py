"""Reference signals, their command-line syntax, and settings refused before a run."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from equilibrist.cli.simulate import show_progress
from equilibrist.errors import DimensionError, SimulationError
from equilibrist.numeric.lookup import get_system
from equilibrist.sim import Noise, Ramp, Samples, Square, Step, simulate
from equilibrist.sim.signals import parse_signal
from support.sim import cartpole, state_feedback

T = np.array([0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 2.5])
BASE = np.array([0.1])


def test_step_ramp_square_values():
    np.testing.assert_array_equal(Step(2.0, at=0.5).evaluate(T, BASE)[:, 0],
                                  [0.1, 0.1, 2, 2, 2, 2, 2])
    np.testing.assert_allclose(Ramp(2.0, start=0.5).evaluate(T, BASE)[:, 0],
                               [0.1, 0.1, 0.1, 0.6, 1.1, 1.6, 4.1])
    np.testing.assert_array_equal(Square(1.0, period=1.0).evaluate(T, BASE)[:, 0],
                                  [1.1, 1.1, -0.9, -0.9, 1.1, 1.1, -0.9])
    with pytest.raises(DimensionError, match="2 values, expected 1"):
        Step([1.0, 2.0]).evaluate(T, BASE)


def test_samples_from_csv_file_interpolate_and_hold(tmp_path):
    path = tmp_path / "ref.csv"
    path.write_text("time,x\n0,0\n1,2\n2,2\n")
    sig = Samples.from_file(path)
    np.testing.assert_allclose(sig.evaluate(np.array([0.0, 0.5, 1.5, 3.0]), BASE)[:, 0],
                               [0.0, 1.0, 2.0, 2.0])
    assert parse_signal(f"file:{path}").describe()["count"] == 3
    (tmp_path / "bad.csv").write_text("0,1\n0,2\n")
    with pytest.raises(SimulationError, match="do not increase"):
        Samples.from_file(tmp_path / "bad.csv")
    with pytest.raises(SimulationError, match="does not exist"):
        Samples.from_file(tmp_path / "missing.csv")


def test_signal_syntax():
    assert parse_signal("step:0.5@2") == Step(0.5, at=2.0)
    assert parse_signal("0.3") == Step(0.3)
    assert parse_signal("ramp:0.1") == Ramp(0.1)
    assert parse_signal("square:0.2:4") == Square(0.2, 4.0)
    with pytest.raises(SimulationError, match="expected step:VALUE"):
        parse_signal("sine:1")


def test_tracking_from_a_file_follows_it(tmp_path):
    from equilibrist.sim.controllers import StateFeedback

    sysm = cartpole()
    base = state_feedback(sysm, rate=200.0)
    ctrl = StateFeedback(K=base.K, x_op=base.x_op, u_op=base.u_op, Kc=[[base.K[0, 0]]],
                         tracked=("x",), rate=200.0)
    path = tmp_path / "ref.csv"
    path.write_text("0,0\n1,0.4\n20,0.4\n")
    res = simulate(sysm, ctrl, duration=15.0, reference=Samples.from_file(path))
    assert res.reference_of("x")[res.time >= 1.0].min() == pytest.approx(0.4)
    assert res.state("x")[-1] == pytest.approx(0.4, abs=2e-3)


def test_progress_is_off_when_json_goes_to_a_pipe(capsys):
    args = argparse.Namespace(json=True, no_progress=False)
    assert show_progress(args) is False  # pytest's stdout is not a terminal
    assert show_progress(argparse.Namespace(json=False, no_progress=False)) is True
    assert show_progress(argparse.Namespace(json=False, no_progress=True)) is False


def test_settings_problems_are_collected_in_one_error():
    sysm = cartpole()
    with pytest.raises(SimulationError) as info:
        simulate(sysm, None, duration=-1.0, rate=1000.0, physics_step=3e-4,
                 x0=[0.0, np.inf, 0.0, 0.0])
    msg = str(info.value)
    assert "duration" in msg and "does not divide" in msg and "not a finite number" in msg
    with pytest.raises(SimulationError, match="rate"):
        simulate(sysm, None, duration=1.0)
    with pytest.raises(SimulationError, match="rate"):
        simulate(sysm, None, duration=1.0, rate=0.0)


def test_runs_refused_before_they_start():
    with pytest.raises(SimulationError, match="no canonical operating point"):
        simulate(get_system("gyroscope"), None, duration=1.0, rate=100.0)
    with pytest.raises(SimulationError, match="singular"):
        simulate(get_system("gyroscope"), None, duration=1.0, rate=100.0, x0={"phi": 1.0})
    with pytest.raises(SimulationError, match="outside its limits"):
        simulate(get_system("seesaw", F_max=0.01), None, duration=1.0, rate=100.0)
    with pytest.raises(SimulationError, match="not a controller"):
        simulate(cartpole(), object(), duration=1.0, rate=100.0)
    with pytest.raises(SimulationError, match="positive semi-definite"):
        Noise(np.eye(4), -np.eye(4), np.eye(2), ("x", "theta"))
