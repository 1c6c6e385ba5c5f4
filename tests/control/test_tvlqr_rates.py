"""The time-varying LQR with ``rates="differenced"``: its rates differenced from the angles.

Truth: the same tracker on measured rates, handed rates differenced here by hand,
``(3 q_k - 4 q_k-1 + q_k-2) / (2 T)`` (the measured ones for the first two samples).
"""

from __future__ import annotations

import numpy as np
import pytest

import equilibrist
from equilibrist.control.trajopt import Trajectory
from equilibrist.errors import ControllerError


def _swing(system) -> Trajectory:
    """A short made-up motion of the acrobot (a trajectory the tracker follows as given)."""
    knots = 4
    times = np.linspace(0.0, 0.2, knots + 1)
    x_op = system.operating_point().x
    states = np.array([x_op + np.array([0.05, -0.1, 0.3, -0.2]) * (1 - t / 0.2) for t in times])
    return Trajectory(
        system=system.key, params=dict(system.params), state_names=system.state_names,
        input_names=system.input_names, times=times, states=states,
        inputs=np.linspace(1.0, 0.0, knots + 1)[:, None], mid_inputs=np.full((knots, 1), 0.5),
        converged=True, cost=0.0, max_defect=0.0, solve_time=0.0, iterations=0,
        solver="by hand", system_digest=system.digest)


@pytest.mark.parametrize("wrap", ["on", "off"])
def test_differenced_rates_are_the_measured_law_on_differenced_angles(wrap: str) -> None:
    system = equilibrist.get_system("acrobot")
    plan = _swing(system)
    diff = equilibrist.policy(system, controller="tvlqr", trajectory=plan, wrap=wrap,
                              rates="differenced", catch="off")
    meas = equilibrist.policy(system, controller="tvlqr", trajectory=plan, wrap=wrap,
                              catch="off")
    rng = np.random.default_rng(3)
    dt = 1.0 / diff.rate
    previous: list[np.ndarray] = []
    moved = False
    for k in range(int(0.3 / dt)):  # along the plan, and past its end (the balance)
        t = k * dt
        x = plan.states[0] + np.array([0.1 * t, -0.05 * t, 0.1, -0.05])
        y = x + rng.normal(0.0, [1e-3, 1e-3, 0.5, 0.5])  # noisy measured rates
        by_hand = y.copy()
        if len(previous) == 2:
            by_hand[2:] = (3 * y[:2] - 4 * previous[0] + previous[1]) / (2 * dt)
        previous = [y[:2].copy(), *previous[:1]]
        got, want = diff(t, y), meas(t, by_hand)
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
        moved |= not np.allclose(got, meas(t, y))  # the noisy rates would give another torque
    assert moved
    assert diff.controller.settings["rates"] == "differenced"


def test_differenced_rates_take_the_full_state() -> None:
    system = equilibrist.get_system("acrobot")
    with pytest.raises(ControllerError, match="--balance lqr"):
        equilibrist.policy(system, controller="tvlqr", trajectory=_swing(system),
                           rates="differenced", balance="lqg")
    with pytest.raises(ControllerError, match="expected one of measured, differenced"):
        equilibrist.policy(system, controller="tvlqr", trajectory=_swing(system), rates="both")


def test_the_kind_offers_what_the_controller_takes() -> None:
    from equilibrist.control.tvlqr import RATES
    from equilibrist.controllers.tvlqr import RATES as OFFERED

    assert OFFERED == RATES
