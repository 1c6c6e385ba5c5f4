"""The smooth Coulomb law, against the plain arithmetic of its definition."""

import math

import pytest
import sympy as sp

from equilibrist.errors import DefinitionError
from equilibrist.mechanics.friction import FORMS, coulomb_friction


@pytest.mark.parametrize("v", [-3.0, -0.01, -1e-4, 0.0, 2e-3, 0.5, 40.0])
def test_atan_is_the_benchmarks_law(v: float) -> None:
    # RealAIGym's plant: coulomb_fric * arctan(100 * vel)
    vel, cf = sp.symbols("vel cf", real=True)
    law = coulomb_friction(vel, cf)
    assert float(law.subs({vel: v, cf: 0.093})) == pytest.approx(
        0.093 * math.atan(100 * v), rel=1e-15, abs=0
    )


def test_tanh_tends_to_the_coefficient_and_atan_to_its_half_pi() -> None:
    vel = sp.Symbol("vel", real=True)
    assert float(coulomb_friction(vel, 2.0, "tanh").subs(vel, 10.0)) == pytest.approx(
        2.0, rel=1e-12
    )
    assert float(coulomb_friction(vel, 2.0).subs(vel, 1e9)) == pytest.approx(math.pi, rel=1e-9)
    assert FORMS[0] == "atan"


@pytest.mark.parametrize("form", ["atan", "tanh"])
def test_slope_at_rest_is_coefficient_times_sharpness(form: str) -> None:
    vel = sp.Symbol("vel", real=True)
    slope = sp.diff(coulomb_friction(vel, 0.5, form, sharpness=40), vel).subs(vel, 0)
    assert float(slope) == pytest.approx(20.0, rel=1e-15)
    # odd, and resisting: positive along the velocity
    law = coulomb_friction(vel, 0.5, form)
    assert float(law.subs(vel, 0.3)) > 0
    assert float(law.subs(vel, 0.3) + law.subs(vel, -0.3)) == 0


def test_unknown_form_is_named() -> None:
    with pytest.raises(DefinitionError, match=r"'sign' is not known: expected one of atan, tanh"):
        coulomb_friction(sp.Symbol("v"), 1.0, "sign")
