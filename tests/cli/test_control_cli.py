"""``equilibrist design``: JSON, text, and one-line errors with exit status 2."""

from __future__ import annotations

import json

import numpy as np
import pytest

from equilibrist.cli import common
from equilibrist.cli.main import main
from equilibrist.control import design
from equilibrist.control.discretize import METHODS
from equilibrist.control.kalman import FORMS
from equilibrist.numeric.lookup import get_system


def _json(capsys: pytest.CaptureFixture[str], *args: str) -> dict:
    assert main(["design", *args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_json_has_the_gains_and_matches_the_library(capsys: pytest.CaptureFixture[str]) -> None:
    data = _json(capsys, "cartpole")
    for key in (
        "K",
        "S",
        "poles",
        "Kf",
        "P",
        "Kc",
        "kc_note",
        "estimator_poles",
        "Q",
        "R",
        "QN",
        "RN",
        "G",
        "Qd",
        "Rd",
        "tracked",
        "states",
        "inputs",
        "outputs",
    ):
        assert key in data, key
    d = design(get_system("cartpole"))
    np.testing.assert_allclose(data["K"], d.K)
    np.testing.assert_allclose(data["Kf"], d.Kf)
    np.testing.assert_allclose(data["Kc"], d.Kc)
    assert data["rate"] is None
    assert data["Qd"] is None
    assert all(p.keys() == {"re", "im"} for p in data["poles"])
    assert all(p["re"] < 0 for p in data["poles"])


def test_json_options_reach_the_design(capsys: pytest.CaptureFixture[str]) -> None:
    data = _json(
        capsys,
        "cartpole",
        "--rate",
        "200",
        "--kalman",
        "predictor",
        "--discretization",
        "euler",
        "--q",
        "1,2,3,4",
        "--r",
        "0.5",
        "--qn",
        "0,0,1e-2,1e-2",
        "--rn",
        "1e-6,2e-6",
        "--set",
        "m_c=2",
    )
    assert data["rate"] == 200.0
    assert data["dt"] == pytest.approx(0.005)
    assert data["kalman_form"] == "predictor"
    assert data["discretization"] == "euler"
    assert np.diag(data["Q"]).tolist() == [1, 2, 3, 4]
    assert data["R"] == [[0.5]]
    assert np.diag(data["RN"]).tolist() == [1e-6, 2e-6]
    assert data["params"]["m_c"] == 2.0
    assert all(abs(complex(p["re"], p["im"])) < 1 for p in data["poles"])
    d = design(
        get_system("cartpole", m_c=2.0),
        q=[1, 2, 3, 4],
        r=[0.5],
        qn=[0, 0, 1e-2, 1e-2],
        rn=[1e-6, 2e-6],
        rate=200,
        kalman_form="predictor",
        discretization="euler",
    )
    np.testing.assert_allclose(data["Kf"], d.Kf)
    np.testing.assert_allclose(data["K"], d.K)


def test_zero_dc_gain_output_gives_null_kc(capsys: pytest.CaptureFixture[str]) -> None:
    data = _json(capsys, "cartpole", "--outputs", "theta,x")
    assert data["Kc"] is None
    assert "zero DC gain" in data["kc_note"]
    assert data["tracked"] == ["theta"]


def test_text_report(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["design", "cartpole", "--rate", "100"]) == 0
    out = capsys.readouterr().out
    assert "LQG design for cartpole: discrete at 100 Hz" in out
    assert "LQR gain K" in out
    assert "closed-loop poles (z)" in out
    assert "Kalman gain M (current form)" in out
    assert "phase margin" in out


def test_cli_choices_are_the_librarys() -> None:
    assert common.DISCRETIZATIONS == METHODS
    assert common.KALMAN_FORMS == FORMS


BAD = {
    # A list that starts with a minus sign needs the --q=... spelling (argparse).
    "q not psd": (["cartpole", "--q=-1,1,1,1"], "q for x is -1: expected >= 0"),
    "r negative": (["cartpole", "--r=-2"], "r for F is -2: expected > 0"),
    "r not pd": (["cartpole", "--r", "0"], "r for F is 0: expected > 0"),
    "q wrong size": (["cartpole", "--q", "1,2,3"], "q has 3 values, expected 4"),
    "rn wrong size": (["cartpole", "--rn", "1e-6"], "rn has 1 values, expected 2"),
    "qn wrong size": (["cartpole", "--qn", "1,1"], "qn has 2 values, expected 4"),
    "uncontrollable": (
        ["cmg_robot", "--set", "Omega=0"],
        "(A, B) is not stabilizable",
    ),
    "unobservable": (["cartpole", "--outputs", "theta"], "(A, C) is not detectable"),
    "unknown output": (["cartpole", "--outputs", "x,phi"], "unknown output 'phi'"),
    "rate zero": (["cartpole", "--rate", "0"], "rate must be a positive number"),
    "rate negative": (["cartpole", "--rate", "-10"], "rate must be a positive number"),
    "rate not a number": (["cartpole", "--rate", "fast"], "--rate: 'fast' is not a number"),
    "bad method": (["cartpole", "--discretization", "tustin"], "invalid choice: 'tustin'"),
    "bad form": (["cartpole", "--kalman", "smoother"], "invalid choice: 'smoother'"),
    "no input": (["gyroscope"], "has no input"),
    "unknown system": (["cartpol"], "unknown system 'cartpol'"),
}


@pytest.mark.parametrize("case", list(BAD), ids=list(BAD))
def test_bad_input_is_one_line_and_exit_2(case: str, capsys: pytest.CaptureFixture[str]) -> None:
    args, message = BAD[case]
    assert main(["design", *args]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert message in lines[0]
