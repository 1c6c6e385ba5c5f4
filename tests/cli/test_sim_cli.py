"""The ``simulate`` and ``batch`` commands: the contract flags, files, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from equilibrist.cli.main import main
from equilibrist.sim import SimResult
from equilibrist.sim.batch_result import BatchResult


def _json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_simulate_json_has_fell_and_fell_at(capsys):
    up = _json(capsys, ["simulate", "cartpole", "--controller", "lqg", "--duration", "2",
                        "--rate", "200", "--x0", "theta=0.05", "--noise", "on", "--seed", "3",
                        "--json"])
    assert up["fell"] is False and up["fell_at"] is None
    assert set(up) >= {"settling_time", "overshoot", "peak_input", "rms_input",
                       "time_saturated", "final_error", "estimation_error_rms", "stayed_up"}
    down = _json(capsys, ["simulate", "cartpole", "--controller", "none", "--duration", "3",
                          "--x0", "theta=0.1", "--noise", "off", "--json"])
    assert down["fell"] is True and 0 < down["fell_at"] < 3
    assert down["fell_state"] == "theta"


def test_simulate_is_reproducible_and_seeds_matter(capsys):
    argv = ["simulate", "cartpole", "--duration", "1", "--x0", "theta=0.05", "--json"]
    a = _json(capsys, [*argv, "--seed", "1"])
    b = _json(capsys, [*argv, "--seed", "1"])
    c = _json(capsys, [*argv, "--seed", "2"])
    assert a == b
    assert a["rms_input"] != c["rms_input"]


def test_simulate_saves_and_pushes(tmp_path, capsys):
    out = tmp_path / "run.npz"
    assert main(["simulate", "cartpole", "--controller", "lqr", "--duration", "2",
                 "--push", "0.5:30", "--noise", "off", "--set", "m_p=1.2", "--q", "10,10,1,1",
                 "--r", "0.1", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "stayed up" in text
    res = SimResult.load(out)
    assert res.params["m_p"] == 1.2
    assert res.settings["events"][0] == {"kind": "pulse", "time": 0.5, "value": 30.0,
                                         "duration": 0.1, "input": None}
    k = int(np.searchsorted(res.time, 0.6))
    assert res.state("x_dot")[k] > 0.05  # the push moved the cart
    assert np.all(res.states[res.time < 0.5] == 0.0)
    csv = tmp_path / "run.csv"
    assert main(["simulate", "cartpole", "--duration", "0.5", "--out", str(csv)]) == 0
    assert csv.read_text().splitlines()[2].startswith("t [s],F [N],x [m],theta [rad]")


def test_simulate_tracks_a_reference(capsys):
    m = _json(capsys, ["simulate", "cartpole", "--controller", "lqr", "--duration", "15",
                       "--rate", "200", "--reference", "step:0.3", "--noise", "off", "--json"])
    assert m["final_error"]["x"] == pytest.approx(0.0, abs=2e-3)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--physics-step", "0.0003"], "does not divide the control period"),
        (["--x0", "theta=nan"], "not a finite number"),
        (["--duration", "0"], "--duration must be positive"),
        (["--duration", "-1"], "--duration must be positive"),
        (["--rate", "0"], "--rate must be positive"),
        (["--x0", "phi=1"], "no state 'phi'"),
        (["--push", "9:5"], "after the end of the run"),
    ],
)
def test_bad_input_is_one_line_and_status_2(capsys, argv, message):
    code = main(["simulate", "cartpole", "--duration", "1", "--rate", "1000", "--noise", "off",
                 *argv])
    err = capsys.readouterr().err
    assert code == 2
    assert message in err
    assert len(err.strip().splitlines()) == 1


def test_batch_json_and_file(tmp_path, capsys):
    out = tmp_path / "b.npz"
    s = _json(capsys, ["batch", "cartpole", "--runs", "40", "--x0", "theta=-1.4:1.4",
                       "--spread", "m_p=0.2", "--duration", "2", "--rate", "200",
                       "--out", str(out), "--json"])
    assert s["runs"] == 40
    assert 0 < s["stayed_up"] < 40
    assert s["fraction_up"] == pytest.approx(s["stayed_up"] / 40)
    assert s["steps_per_second"] > 0
    b = BatchResult.load(out)
    th = b.x0[:, 1]
    assert th.min() >= -1.4 and th.max() <= 1.4
    # The runs that fell started further out than those that stayed up.
    assert np.abs(th[b.fell]).min() > np.abs(th[~b.fell]).min()
    mp = b.param("m_p")
    assert mp.min() >= 0.8 and mp.max() <= 1.2


def test_batch_too_large_is_refused(capsys):
    code = main(["batch", "cartpole", "--runs", "2000000", "--duration", "100", "--rate",
                 "1000", "--trajectories", "--noise", "off", "--max-steps", "inf"])
    err = capsys.readouterr().err
    assert code == 2
    assert "of memory" in err and "TiB" in err and len(err.strip().splitlines()) == 1
