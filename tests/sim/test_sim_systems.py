"""Every system with an input: its default design catches it, nonlinear, with noise on."""

from __future__ import annotations

import numpy as np
import pytest

from equilibrist.control import design
from equilibrist.numeric.lookup import get_system
from equilibrist.sim import LQG, Noise, StateFeedback, simulate
from equilibrist.systems import registry

WITH_INPUT = [name for name in registry.family_names()
              if registry.lookup(name).spec.inputs]


def _small_deviation(system, x_op):
    """10 % of each coordinate's design scale (the largest acceptable deviation)."""
    scales = system.spec.design_scales
    coords = system.spec.coordinates if system.spec.states is None else system.state_names
    return {q: float(x_op[system.state_names.index(q)]) + 0.1 * scales[q]
            for q in coords if q in scales}


def test_every_system_with_an_input_is_listed():
    assert {"cartpole", "seesaw", "double_cartpole"} <= set(WITH_INPUT)
    assert "gyroscope" not in WITH_INPUT


# Slow only the first time: each system's core is compiled (then cached on disk).
@pytest.mark.slow
@pytest.mark.parametrize("name", WITH_INPUT)
def test_default_lqg_catches_the_system_with_noise(name):
    system = get_system(name)
    d = design(system, rate=system.spec.control_rate)
    ctrl = LQG.from_design(d)
    x0 = _small_deviation(system, ctrl.x_op)
    assert x0, f"{name} has no design scale to start away from the operating point"
    res = simulate(system, ctrl, duration=5.0, x0=x0, noise=Noise.from_design(d), seed=1)
    assert not res.fell, f"{name} fell at {res.fell_at} s ({res.fell_state})"
    assert not np.array_equal(res.states[0], res.x_op)
    # Brought back: every scaled coordinate ends within its acceptable deviation.
    for q, scale in system.spec.design_scales.items():
        if q in system.state_names:
            i = system.state_names.index(q)
            assert abs(res.final_state[i] - res.x_op[i]) < scale, q
    # The noise was on: the sensors read something other than the truth.
    idx = [system.state_names.index(o) for o in res.output_names]
    assert np.any(res.measurements != res.states[:, idx])


@pytest.mark.slow
@pytest.mark.parametrize("name", WITH_INPUT)
def test_default_lqr_catches_the_system_without_noise(name):
    system = get_system(name)
    d = design(system, rate=system.spec.control_rate)
    ctrl = StateFeedback.from_design(d)
    res = simulate(system, ctrl, duration=5.0, x0=_small_deviation(system, ctrl.x_op))
    assert not res.fell, f"{name} fell at {res.fell_at} s ({res.fell_state})"
    dev = np.abs(res.final_state - res.x_op)
    start = np.abs(res.states[0] - res.x_op)
    assert dev.max() < start.max()
