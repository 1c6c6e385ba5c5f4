"""Inputs that once went wrong: flat starts of the equilibrium solver, huge
numbers, negative lists on the command line, damaged cache files."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from equilibrist.cli.main import main
from equilibrist.errors import NoEquilibriumError, ParameterError
from equilibrist.numeric import cache
from equilibrist.numeric.lookup import get_system
from equilibrist.systems import registry
from equilibrist.systems._gyro_tools import NoSteadyPrecessionError, steady_precession_rates


@pytest.mark.parametrize("thrust", [0.1, 0.3, 0.49])
def test_seesaw_angle_held_by_a_given_thrust(thrust: float) -> None:
    # Seed 000: cos(theta_e) = -delta F_e / gamma with gamma = (m1 - m2) g L / (2 I)
    # and delta = L / (2 I), i.e. cos(theta_e) = F_e / ((m2 - m1) g). The solver
    # starts at theta = 0, where f does not change with theta to first order.
    seesaw = get_system("seesaw")
    p = seesaw.params
    eq = seesaw.equilibrium(inputs={"F": thrust}, free=("theta",))
    expected = math.acos(thrust / ((p["m2"] - p["m1"]) * p["g"]))
    assert eq.state("theta") == pytest.approx(expected, abs=1e-9)
    assert eq.residual < 1e-9


def test_seesaw_thrust_beyond_the_weight_has_no_equilibrium() -> None:
    seesaw = get_system("seesaw")
    too_much = 1.5 * (seesaw.params["m2"] - seesaw.params["m1"]) * seesaw.params["g"]
    with pytest.raises(NoEquilibriumError, match="no equilibrium"):
        seesaw.equilibrium(inputs={"F": too_much}, free=("theta",))


def test_overflowing_state_is_an_error_not_a_nan() -> None:
    cart = get_system("cartpole")
    with pytest.raises(ParameterError, match="not finite"):
        cart.f([0, 0, 0, 1e200], [0])
    with pytest.raises(ParameterError, match="not finite"):
        cart.jacobians([0, 0, 0, 1e200], [0])


@pytest.mark.parametrize(
    "argv",
    [
        ["linearize", "cartpole", "--at", "theta_dot=1e200", "--json"],
        ["linearize", "cartpole", "--set", "I_p=1e308", "m_p=1e308", "--json"],
        ["dynamics", "cartpole", "--state", "0,0,0,1e200", "--input", "0", "--json"],
        ["design", "cartpole", "--q", "1e300,1,1,1"],
    ],
)
def test_huge_numbers_are_one_line(capsys, argv) -> None:
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert len(captured.err.strip().splitlines()) == 1


def test_negative_first_value_of_a_list(capsys) -> None:
    assert main(["dynamics", "cartpole", "--state", "-0.1,0.2,0,0", "--input", "-1", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert np.allclose(data["xdot"], get_system("cartpole").f([-0.1, 0.2, 0, 0], [-1]))
    assert main(["design", "cartpole", "--qn", "-1,1,1,1"]) == 2
    assert "qn for x is -1" in capsys.readouterr().err


def test_linearize_poles_are_always_re_im(capsys) -> None:
    assert main(["linearize", "cartpole", "--json"]) == 0
    poles = json.loads(capsys.readouterr().out)["poles"]
    assert all(set(p) == {"re", "im"} for p in poles)
    assert sorted(p["re"] for p in poles) == pytest.approx(
        sorted(get_system("cartpole").linearize().poles.real))


def test_horizontal_axis_has_only_the_slow_precession() -> None:
    gyro = get_system("gyroscope")
    with pytest.raises(NoSteadyPrecessionError, match="cos\\(theta\\) = 0"):
        steady_precession_rates(gyro, math.pi / 2, 250.0)


def test_damaged_cache_files_are_rebuilt(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("EQUILIBRIST_CACHE", str(tmp_path))
    monkeypatch.setattr(cache, "_MEMO", {})
    entry = registry.lookup("cartpole")
    first = cache.load(entry)
    expected = first.functions  # noqa: F841 - loads the module once
    for path in (first.module_path, first.pickle_path):
        path.write_bytes(b"\x00garbage(")
    monkeypatch.setattr(cache, "_MEMO", {})
    import sys

    sys.modules.pop(f"equilibrist_generated_{first.module_path.stem}", None)
    again = cache.load(entry)
    out = np.empty(4)
    again.functions.f(np.array([0, 0.1, 0, 0.0]), np.zeros(1), get_system("cartpole").p, out)
    assert np.allclose(out, get_system("cartpole").f([0, 0.1, 0, 0], [0]))
    assert again.symbolic.M.shape == (2, 2)


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["simulate", "cartpole", "--duration", "1e9", "--max-steps", "inf", "--json"], "TiB of memory"),
        (["batch", "cartpole", "--runs", "4", "--duration", "1e9", "--max-steps", "inf", "--json"], "TiB of memory"),
        (["batch", "cartpole", "--runs", "100000000000", "--duration", "1", "--json"], "TiB of memory"),
        (["simulate", "cartpole", "--rate", "0.01", "--json"], "too slow for cartpole"),
        (["export", "cartpole", "--rate", "1e-6", "--out", "unused"], "too slow for cartpole"),
        (["simulate", "cartpole", "--reference", "file:/nonexistent.csv"], "does not exist"),
    ],
)
def test_refused_before_anything_is_allocated(capsys, argv, needle) -> None:
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0]


def test_results_that_are_not_results(tmp_path, capsys) -> None:
    empty = tmp_path / "empty"
    empty.touch()
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip file")
    for command in ("plot", "animate"):
        for path in (empty, junk):
            assert main([command, str(path)]) == 2
            err = capsys.readouterr().err.strip().splitlines()
            assert len(err) == 1 and "is not a saved result" in err[0]


def test_reference_file_with_spaces_and_its_errors(tmp_path, capsys) -> None:
    spaced = tmp_path / "ref.txt"
    spaced.write_text("# t r\n0 0\n1 0.1\n2 0.2\n")
    assert main(["simulate", "cartpole", "--reference", f"file:{spaced}", "--duration", "0.5",
                 "--noise", "off", "--json"]) == 0
    capsys.readouterr()
    unsorted = tmp_path / "bad.csv"
    unsorted.write_text("0,0\n2,0.1\n1,0.2\n")
    assert main(["simulate", "cartpole", "--reference", f"file:{unsorted}"]) == 2
    assert "times that do not increase" in capsys.readouterr().err


def test_batch_of_a_system_without_operating_point(capsys) -> None:
    argv = ["batch", "gyroscope", "--runs", "3", "--x0", "phi=0", "theta=0.4:0.6", "psi=0",
            "phi_dot=0", "theta_dot=0", "psi_dot=300", "--duration", "0.5", "--json"]
    assert main(argv) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["runs"] == 3 and data["stayed_up"] == 3 and data["fallen"] == 0


def test_fallen_run_metrics_fit_inside_the_run(capsys) -> None:
    argv = ["simulate", "cartpole", "--x0", "theta=1.2", "--controller", "lqr", "--duration", "3", "--json"]
    assert main(argv) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["fell"] is True
    # Samples clipped times the period: at most one period past the last row's time.
    assert data["time_saturated"] <= data["duration"] + 0.005 + 1e-12
    assert data["fell_at"] == round(data["fell_at"], 12)
