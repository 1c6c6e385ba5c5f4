"""Friction compensation (``--friction-compensation on``): the model's friction on the
actuated joint added to the time-varying LQR's command.

Truths: the DFKI rig's friction law written here independently, as the RealAIGym
benchmark's plant writes it (``b v + cf arctan(100 v)`` on each joint), the C library's own
replay of the recorded vectors (``make check``), and the last second of a simulated run on
the rig with its identified friction on the motor's joint (its distance from upright).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import equilibrist
from equilibrist.control import compensation
from equilibrist.control.nonlinear import contract_namespace
from equilibrist.control.trajopt import Trajectory
from equilibrist.errors import ControllerError
from equilibrist.export.writer import export_controller
from equilibrist.sim.run import simulate
from equilibrist.systems.dfki_double_pendulum import MODEL_1_0
from support.export import make_check

#: The rig's actuated joint (0: shoulder, 1: elbow) for each robot.
ACTUATED = {"acrobot": 1, "pendubot": 0}


def _rig(robot: str, **params: float):
    return equilibrist.get_system("dfki_double_pendulum", robot=robot, **params)


def _held_upright(system, duration: float = 0.1) -> Trajectory:
    """A plan that holds the rig upright (an equilibrium: exact)."""
    x_op = system.operating_point().x
    knots = 4
    return Trajectory(
        system=system.key, params=dict(system.params), state_names=system.state_names,
        input_names=system.input_names, times=np.linspace(0.0, duration, knots + 1),
        states=np.tile(x_op, (knots + 1, 1)), inputs=np.zeros((knots + 1, 1)),
        mid_inputs=np.zeros((knots, 1)), converged=True, cost=0.0, max_defect=0.0,
        solve_time=0.0, iterations=0, solver="by hand", system_digest=system.digest)


def _benchmark_friction(v: float, b: float, cf: float) -> float:
    """The benchmark plant's joint friction (double_pendulum's ``b * v + cf * arctan(100 * v)``)."""
    return b * v + cf * float(np.arctan(100.0 * v))


@pytest.mark.parametrize("robot", ["acrobot", "pendubot"])
def test_the_compensation_is_the_rigs_friction_law_on_the_motors_joint(robot: str) -> None:
    rig = _rig(robot, **MODEL_1_0)
    a = ACTUATED[robot]
    comp = compensation.compensation(rig)
    # The motor's joint's damping and Coulomb friction; the passive joint's is not the
    # motor's to cancel.
    assert set(comp.parameters) == {f"b{a + 1}", f"cf{a + 1}"}
    ctrl = equilibrist.policy(rig, controller="tvlqr", trajectory=_held_upright(rig),
                              friction_compensation="on").controller
    namespace = contract_namespace()
    exec(compile(ctrl.source, "<tvlqr>", "exec"), namespace)
    rng = np.random.default_rng(3)
    for v in (0.0, 0.004, -0.02, 0.3, -2.5, 9.0):
        y = np.concatenate([rng.uniform(-3.0, 3.0, 2), rng.uniform(-5.0, 5.0, 2)])
        y[2 + a] = v
        want = _benchmark_friction(v, MODEL_1_0[f"b{a + 1}"], MODEL_1_0[f"cf{a + 1}"])
        got = namespace["fc_torque"](0, 0.0, np.array(ctrl.z0), y, np.array(ctrl.params))
        assert got == pytest.approx(want, rel=1e-10, abs=1e-13)
        assert compensation.torque(rig, comp, y)[0] == pytest.approx(want, rel=1e-10, abs=1e-13)


def test_without_friction_the_controller_is_the_one_without() -> None:
    rig = _rig("pendubot")
    plan = _held_upright(rig)
    on = equilibrist.policy(rig, controller="tvlqr", trajectory=plan,
                            friction_compensation="on").controller
    off = equilibrist.policy(rig, controller="tvlqr", trajectory=plan).controller
    assert on.source == off.source
    assert np.array_equal(on.params, off.params)
    assert on.settings["friction_compensation"] == []
    assert "friction_compensation" not in off.settings


def test_a_passive_joints_coulomb_friction_is_designed_as_its_secant() -> None:
    """The passive elbow's friction is not the motor's to cancel: nothing is added to the
    command, and the balance's gains see it as the damping ``cf atan(100 V) / V`` at half the
    rate's design scale, ``V`` = 0.5 rad/s, added to the joint's own, not as its slope at
    rest."""
    rig = _rig("pendubot", b2=0.001, cf2=0.12)
    plan = _held_upright(rig)
    on = equilibrist.policy(rig, controller="tvlqr", trajectory=plan,
                            friction_compensation="on").controller
    off = equilibrist.policy(rig, controller="tvlqr", trajectory=plan).controller
    assert on.source == off.source
    assert on.settings["friction_compensation"] == []
    secant = 0.001 + _benchmark_friction(0.5, 0.0, 0.12) / 0.5
    assert on.settings["friction_design"] == {"b2": pytest.approx(secant, rel=1e-9), "cf2": 0.0}
    assert not np.array_equal(on.params, off.params)


def test_compensation_takes_the_full_state() -> None:
    rig = _rig("pendubot", **MODEL_1_0)
    with pytest.raises(ControllerError, match="--balance lqr"):
        equilibrist.policy(rig, controller="tvlqr", trajectory=_held_upright(rig),
                           friction_compensation="on", balance="lqg")


def _final_distance(result) -> float:
    """The largest distance from upright (an angle modulo a turn; each state's) over the
    run's last second."""
    d = np.asarray(result.states[-500:]) - np.array([np.pi, 0.0, 0.0, 0.0])
    d[:, :2] = (d[:, :2] + np.pi) % (2 * np.pi) - np.pi
    return float(np.max(np.abs(d)))


def test_the_rig_with_its_motors_friction_balances_with_compensation_and_not_without() -> None:
    """The pendubot with its identified rotor, and its shoulder's damping and Coulomb friction,
    started 0.05 rad off upright: the LQR alone is held off upright by the friction (it
    sticks or cycles around the top); compensated, the rig settles upright."""
    rig = _rig("pendubot", Ir=MODEL_1_0["Ir"], b1=MODEL_1_0["b1"], cf1=MODEL_1_0["cf1"])
    plan = _held_upright(rig)
    start = np.array([np.pi + 0.05, 0.0, 0.0, 0.0])
    distance = {}
    for setting in ("on", "off"):
        ctrl = equilibrist.policy(rig, controller="tvlqr", trajectory=plan, rates="differenced",
                                  friction_compensation=setting).controller
        result = simulate(rig, ctrl, duration=4.0, x0=start, region={})
        distance[setting] = _final_distance(result)
    assert distance["on"] < 1e-3, distance
    assert distance["off"] > 0.02, distance


def test_the_rig_as_identified_balances_compensated_and_falls_without() -> None:
    """The pendubot with its identified rotor, damping and Coulomb friction on both joints
    (the RealAIGym pendubot file's weights), link 1 started 0.03 rad off upright: the LQR
    designed on the friction's slope at rest (the elbow looks locked to it) loses the rig;
    compensated (the shoulder's friction cancelled, the elbow's designed as its secant) it
    settles upright."""
    rig = _rig("pendubot", **MODEL_1_0)
    plan = _held_upright(rig)
    start = np.array([np.pi + 0.03, 0.0, 0.0, 0.0])
    distance = {}
    for setting in ("on", "off"):
        ctrl = equilibrist.policy(rig, controller="tvlqr", trajectory=plan, rates="differenced",
                                  r=[8.0], q=[25.0, 25.0, 1.0, 1.0], catch="off",
                                  friction_compensation=setting).controller
        distance[setting] = _final_distance(simulate(rig, ctrl, duration=4.0, x0=start,
                                                     region={}))
    assert distance["on"] < 0.01, distance
    assert distance["off"] > 1.0, distance


def test_the_compensated_controller_exports_with_make_check_exact(tmp_path: Path) -> None:
    """The acrobot as identified, compensated, its rates differenced and its motor's lag in
    the design too (the two options' sources together): the C library replays the recorded
    vectors exactly."""
    rig = _rig("acrobot", **MODEL_1_0)
    ctrl = equilibrist.policy(rig, controller="tvlqr", trajectory=_held_upright(rig),
                              rates="differenced", wrap="on", design_torque_response="10ms",
                              friction_compensation="on").controller
    assert ctrl.settings["friction_compensation"] == ["b2", "cf2"]
    assert "torque_response" in ctrl.settings
    out = tmp_path / "fc"
    export_controller(ctrl, out, system=rig, duration=0.5)
    assert " 0 mismatches" in make_check(out)
