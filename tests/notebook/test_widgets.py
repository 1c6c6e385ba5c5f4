"""The sliders redesign and simulate with the same calls a script makes: what they hold
is what ``design`` and ``simulate`` return for the same values, to the bit."""

from __future__ import annotations

import numpy as np
import pytest

from equilibrist.control.design import design
from equilibrist.errors import EquilibristError
from equilibrist.notebook.widgets import explore
from equilibrist.numeric.lookup import get_system
from equilibrist.sim import LQG, Noise, simulate


def test_moving_the_sliders_redesigns_and_simulates_again() -> None:
    cart = get_system("cartpole")
    explorer = explore(cart, duration=0.4, x0={"theta": 0.05}, parameters=["m_p"], seed=4)
    assert explorer.design is not None and explorer.error == ""
    start_gain = explorer.design.K.copy()
    explorer.q_sliders[1].value = 10 * explorer.q_sliders[1].value  # the angle's weight
    explorer.parameter_sliders["m_p"].value = 0.15
    made, run = explorer.design, explorer.result
    assert made is not None and run is not None
    assert made.params["m_p"] == explorer.params["m_p"] != cart.params["m_p"]
    assert not np.allclose(made.K, start_gain)
    # The script's path with the sliders' values gives the same design and run, bit for bit.
    system = cart.with_params(m_p=explorer.params["m_p"])
    expected = design(system, q=explorer.q, r=explorer.r, rate=cart.spec.control_rate)
    np.testing.assert_array_equal(made.K, expected.K)
    again = simulate(system, LQG.from_design(expected), duration=0.4, x0={"theta": 0.05},
                     noise=Noise.from_design(expected), seed=4)
    np.testing.assert_array_equal(run.states, again.states)
    assert "slowest pole" in explorer.summary.value


def test_an_unknown_parameter_is_named() -> None:
    with pytest.raises(EquilibristError, match="no parameter 'mass' in cartpole"):
        explore(get_system("cartpole"), duration=0.2, parameters=["mass"])
