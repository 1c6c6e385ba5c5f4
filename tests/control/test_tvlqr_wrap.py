"""The time-varying LQR with ``wrap``: its angles compared modulo a turn.

Truths: the law ``u = u_plan - K (x - x_plan)`` computed here from the controller's own
tables with the angle's deviation reduced by hand, and the unwrapped controller, which
differs from it a turn away.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import equilibrist
from equilibrist.control.trajopt import Trajectory
from equilibrist.control.tvlqr import LAYOUT_WRAP, plan_samples
from equilibrist.errors import ControllerError


def _held_upright(system) -> Trajectory:
    """A plan that holds the acrobot upright for 0.2 s (an equilibrium: exact)."""
    x_op = system.operating_point().x
    knots = 4
    return Trajectory(
        system=system.key, params=dict(system.params), state_names=system.state_names,
        input_names=system.input_names, times=np.linspace(0.0, 0.2, knots + 1),
        states=np.tile(x_op, (knots + 1, 1)), inputs=np.zeros((knots + 1, 1)),
        mid_inputs=np.zeros((knots, 1)), converged=True, cost=0.0, max_defect=0.0,
        solve_time=0.0, iterations=0, solver="by hand", system_digest=system.digest)


def test_a_wrapped_tracker_sees_an_angle_a_turn_away_where_it_is() -> None:
    system = equilibrist.get_system("acrobot")
    plan = _held_upright(system)
    wrapped = equilibrist.policy(system, controller="tvlqr", trajectory=plan, wrap="on",
                                 catch="off")
    raw = equilibrist.policy(system, controller="tvlqr", trajectory=plan, catch="off")
    c = wrapped.controller
    gains = LAYOUT_WRAP.read(np.asarray(c.params), "gains")
    _, xs, us = plan_samples(c)
    x = xs[0] + np.array([0.002, -0.001, 0.01, 0.0])
    turned = x + np.array([2 * math.pi, -2 * math.pi, 0.0, 0.0])
    want = np.clip(us[0] - gains[0] @ (x - xs[0]), -20.0, 20.0)
    assert abs(want[0]) < 15.0  # not saturated: the law itself
    np.testing.assert_allclose(wrapped(0.0, turned), want, rtol=1e-12, atol=1e-12)
    assert not np.allclose(raw(0.0, turned), want)
    assert c.settings["wrap"] is True and "wrap" not in raw.controller.settings


def test_wrap_takes_the_full_state() -> None:
    system = equilibrist.get_system("acrobot")
    with pytest.raises(ControllerError, match="--balance lqr"):
        equilibrist.policy(system, controller="tvlqr", trajectory=_held_upright(system),
                           wrap="on", balance="lqg")
