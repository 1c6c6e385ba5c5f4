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
from equilibrist.numeric.system import get_system
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
