"""equilibrist.policy: any kind stepped from a foreign loop, by its compiled source.

Held to independent truths: the LQR's law computed here from the design's gain, and the
LQG's plain-Python runtime (the controller's source run by the interpreter, not compiled).
"""

from __future__ import annotations

import numpy as np
import pytest

import equilibrist
from equilibrist.control.design import design
from equilibrist.controllers.kinds import ControllerRequest, build_controller
from equilibrist.controllers.loop_policy import Policy
from equilibrist.errors import ControllerError


def test_the_lqr_policy_is_the_designs_law_saturated() -> None:
    system = equilibrist.get_system("acrobot")
    pi = equilibrist.policy(system, controller="lqr", rate=200.0)
    d = design(system, rate=200.0)
    K, x_op = np.asarray(d.K), np.asarray(d.plant.x0)
    assert pi.outputs == system.state_names and pi.input_units == ("N*m",)
    rng = np.random.default_rng(3)
    for k in range(20):
        x = x_op + rng.normal(0.0, 0.3, 4)
        want = np.clip(-K @ (x - x_op), -20.0, 20.0)
        np.testing.assert_allclose(pi(100.0 + k / 200.0, x), want, rtol=1e-12, atol=1e-12)


def test_the_lqg_policy_steps_as_its_source_run_in_python() -> None:
    system = equilibrist.get_system("acrobot")
    ctrl = build_controller("lqg", ControllerRequest(system=system, rate=200.0))
    reference = ctrl.runtime()
    pi = equilibrist.policy(system, controller="lqg", rate=200.0)
    rng = np.random.default_rng(5)
    ys = np.pi * np.array([1.0, 0.0]) + rng.normal(0.0, 0.05, (30, 2))
    got = [pi(7.0 + k / 200.0, y) for k, y in enumerate(ys)]
    for k, y in enumerate(ys):
        u = np.clip(reference.output(k / 200.0, y, np.zeros(0)), -20.0, 20.0)
        reference.update(k / 200.0, y, np.zeros(0), u)
        np.testing.assert_allclose(got[k], u, rtol=1e-12, atol=1e-12)
    pi.reset()  # the controller's state and clock start again
    np.testing.assert_allclose(pi(99.0, ys[0]), got[0], rtol=0, atol=0)


def test_mujoco_ctrl_divides_by_the_gear_and_bad_settings_are_refused() -> None:
    np.testing.assert_allclose(Policy.mujoco_ctrl(
        [300.0, -2.0], gear=[100.0, 4.0]), [3.0, -0.5])
    with pytest.raises(ControllerError, match="non-zero"):
        Policy.mujoco_ctrl([1.0], gear=0.0)
    with pytest.raises(ControllerError, match="positive number of Hz"):
        equilibrist.policy("acrobot", rate=-5.0)
    with pytest.raises(ControllerError, match="open loop"):
        equilibrist.policy("acrobot", controller="none")
