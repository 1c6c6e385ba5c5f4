"""The command-line contract of systems / show / dynamics / linearize, and its errors."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from equilibrist.cli.main import main
from equilibrist.numeric.lookup import get_system
from equilibrist.systems import registry


def run_json(capsys, *argv: str):
    assert main(list(argv)) == 0
    return json.loads(capsys.readouterr().out)


def test_systems_json_lists_every_system(capsys) -> None:
    data = run_json(capsys, "systems", "--json")
    assert list(data) == registry.family_names()
    cart = data["cartpole"]
    assert cart["states"] == ["x", "theta", "x_dot", "theta_dot"]
    assert cart["inputs"] == ["F"]
    assert cart["outputs"] == ["x", "theta"]
    m_c = cart["parameters"]["m_c"]
    assert m_c["default"] == 10.0 and m_c["unit"] == "kg" and m_c["range"] == [0.0, None]
    assert "F_min" in cart["parameters"] and "F_max" in cart["parameters"]


def test_systems_text_is_readable(capsys) -> None:
    assert main(["systems"]) == 0
    out = capsys.readouterr().out
    for name in registry.family_names():
        assert f"{name}:" in out


def test_dynamics_json_matches_the_model(capsys) -> None:
    data = run_json(capsys, "dynamics", "cartpole", "--state", "0.1,0.2,0.3,-0.4",
                    "--input", "2.5", "--set", "m_p=2", "--json")
    assert data["states"] == ["x", "theta", "x_dot", "theta_dot"]
    assert data["inputs"] == ["F"]
    expected = get_system("cartpole", m_p=2.0).f([0.1, 0.2, 0.3, -0.4], [2.5])
    assert np.allclose(data["xdot"], expected, rtol=0, atol=0)


def test_linearize_json_contract(capsys) -> None:
    data = run_json(capsys, "linearize", "cartpole", "--json")
    for key in ("system", "states", "inputs", "outputs", "params", "x0", "u0", "A", "B", "C", "D", "residual"):
        assert key in data
    lm = get_system("cartpole").linearize()
    assert np.allclose(data["A"], lm.A) and np.allclose(data["B"], lm.B)
    assert np.array(data["C"]).shape == (2, 4) and np.array(data["D"]).shape == (2, 1)
    assert data["residual"] == 0.0


def test_linearize_away_from_equilibrium_reports_the_residual(capsys) -> None:
    data = run_json(capsys, "linearize", "cartpole", "--at", "theta=0.3", "--json")
    assert data["x0"][1] == 0.3
    # The pole is not balanced at 0.3 rad: f(x0, u0) is the falling acceleration.
    assert data["residual"] == pytest.approx(np.linalg.norm(get_system("cartpole").f([0, 0.3, 0, 0], [0])))
    assert data["residual"] > 0.1


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["linearize", "cartpol"], "did you mean 'cartpole'"),
        (["linearize", "nonsense"], "expected one of: seesaw, cartpole"),
        (["linearize", "cartpole", "--set", "m_cc=1"], "did you mean 'm_c'"),
        (["linearize", "cartpole", "--set", "m_c=-1"], "out of range"),
        (["linearize", "cartpole", "--set", "m_c=inf"], "not a finite number"),
        (["linearize", "cartpole", "--set", "m_c"], "expected NAME=VALUE"),
        (["linearize", "cartpole", "--at", "thetaa=0.1"], "did you mean 'theta'"),
        (["dynamics", "cartpole", "--state", "1,2,3", "--input", "0"], "has 3 values, expected 4"),
        (["dynamics", "cartpole", "--state", "1,2,3,4", "--input", "0,1"], "has 2 values, expected 1"),
        (["dynamics", "cartpole", "--state", "1,nan,3,4", "--input", "0"], "not a finite number"),
        (["dynamics", "cartpole", "--state", "1,2,3,4"], "needs --input"),
        (["dynamics", "cartpole", "--state", "a,2,3,4", "--input", "0"], "not a number"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(capsys, argv, needle) -> None:
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert needle in lines[0]
    assert "Traceback" not in captured.err


def test_unknown_option_is_one_line(capsys) -> None:
    assert main(["linearize", "cartpole", "--frobnicate"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unrecognized arguments" in err[0]


def test_console_script_exit_status_and_no_traceback() -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "equilibrist.cli.main", "linearize", "cartpole", "--set", "l=0"],
        capture_output=True, text=True, check=False,
    )
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and "parameter l = 0 is out of range" in proc.stderr


def test_show_prints_equations_and_linearization(capsys) -> None:
    assert main(["show", "cartpole"]) == 0
    out = capsys.readouterr().out
    assert "M(q) q_ddot = F(q, q_dot, u)" in out
    assert "θ̈" in out and "open-loop poles" in out
    assert main(["show", "cartpole", "--latex"]) == 0
    out = capsys.readouterr().out
    assert r"\ddot{\theta}" in out and r"\begin{aligned}" in out


def test_first_order_model_prints_rates_with_accents(capsys) -> None:
    assert main(["show", "ball_beam_servo"]) == 0
    out = capsys.readouterr().out
    assert "x_dot = f(x, u)" in out
    assert "R̈ =" in out and "θ̇ = ω" in out
    assert "R_dot" not in out.split("x_dot = f(x, u):")[1].split("linearization")[0]
