"""``equilibrist robustness`` and the rig's options of ``simulate`` and ``batch``: JSON,
the plot, and bad input refused in one line."""

from __future__ import annotations

import json

import pytest

from equilibrist.cli.main import main

_BASE = ["robustness", "acrobot", "--controller", "lqr", "--rate", "100", "--duration", "1",
         "--x0", "theta1=3.2416", "--x0", "theta2=-0.1"]


def test_robustness_json_and_plot(capsys, tmp_path):
    plot = tmp_path / "card.png"
    assert main([*_BASE, "--families", "torque_response,delay", "--plot", str(plot),
                 "--json"]) == 0
    card = json.loads(capsys.readouterr().out)
    assert set(card["scores"]) == {"torque_response", "delay"}
    assert len(card["families"]["delay"]["successes"]) == 21
    assert card["settings"]["rate"] == 100.0 and card["settings"]["duration"] == 1.0
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("argv, words", [
    (["--families", "model,wind"], "wind unknown"),
    (["--repetitions", "0"], "--repetitions"),
    (["--filter-cutoff", "-3"], "--filter-cutoff"),
])
def test_robustness_bad_input(capsys, argv, words):
    assert main([*_BASE, *argv]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_simulate_records_the_rig(capsys, tmp_path):
    out = tmp_path / "run.npz"
    assert main(["simulate", "acrobot", "--controller", "lqr", "--rate", "100", "--duration",
                 "0.5", "--x0", "theta1=3.2", "--noise", "off", "--torque-response", "0.5",
                 "--actuation-delay", "20ms", "--torque-noise", "0.1", "--out", str(out),
                 "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["rig"] == {"torque_response": 0.5, "actuation_delay_time": 0.02,
                          "torque_noise": 0.1}
    from equilibrist.sim import SimResult

    assert SimResult.load(out).settings["rig"] == got["rig"]
    assert main(["batch", "acrobot", "--controller", "lqr", "--rate", "100", "--duration",
                 "0.5", "--runs", "2", "--x0", "theta1=3.2", "--perturbations", "1",
                 "--perturbation-amplitude", "0.1:0.2", "--json"]) == 2
    assert "do not fit" in capsys.readouterr().err


@pytest.mark.parametrize("argv, words", [
    (["--measurement-delay", "3ms"], "whole number of periods"),
    (["--torque-noise", "-1"], "--torque-noise"),
    (["--perturbation-amplitude", "2"], "LOW:HIGH"),
    (["--perturb-joints", "x", "--perturbations", "1"], "'x'"),
])
def test_simulate_bad_rig_options(capsys, argv, words):
    assert main(["simulate", "acrobot", "--controller", "lqr", "--rate", "100", "--duration",
                 "3", *argv]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err
