"""The motor's lag in the time-varying LQR (``--design-torque-response``).

Truths: the exactly sampled first-order lag ``k = 1 - exp(-T / tc)``; SciPy's discrete Riccati
solver on the augmented model built here by hand; the rig's own torque response in the
compiled core (the torque that acts at the first sample is the plan's when the tracker leads
it by the lag's inverse); the scorecard's torque-response family (the benchmark's values of
``k``), on which the lag-aware tracker succeeds where the plain one does not. (Its C export,
with the friction compensation, is replayed by ``make check`` in test_compensation.py.)
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

import equilibrist
from equilibrist.control import torque_lag
from equilibrist.control.discretize import discrete_matrices
from equilibrist.control.trajopt import Trajectory, plan
from equilibrist.errors import ControllerError
from equilibrist.sim.rig import Rig
from equilibrist.sim.run import simulate
from equilibrist.study.robustness import robustness


def test_the_design_response_is_k_or_the_sampled_time_constant() -> None:
    assert torque_lag.response_k("0.4", 500.0) == 0.4
    assert torque_lag.response_k("20ms", 500.0) == pytest.approx(1.0 - math.exp(-0.002 / 0.02),
                                                                rel=1e-15)
    assert torque_lag.response_k("0.05s", 100.0) == pytest.approx(1.0 - math.exp(-0.2), rel=1e-15)
    for bad in ("0", "2", "-0.1", "abc", "0ms", "nan"):
        with pytest.raises(ControllerError, match="--design-torque-response"):
            torque_lag.response_k(bad, 500.0)


def test_the_balance_is_the_riccati_solution_of_the_model_with_the_torque_state() -> None:
    rig = equilibrist.get_system("dfki_double_pendulum", robot="pendubot")
    x_op, u_op = rig.operating_point().x, rig.operating_point().u
    Q, R, kappa, rate = np.diag([25.0, 25.0, 1.0, 1.0]), np.array([[8.0]]), 0.4, 500.0
    K, S = torque_lag.balance(rig, x_op, u_op, rate=rate, Q=Q, R=R, kappa=kappa)
    Ad, Bd = discrete_matrices(*rig.jacobians(x_op, u_op), 1.0 / rate)
    # The motor: tau_k = tau_k-1 + kappa (u_k - tau_k-1), and x_k+1 = Ad x_k + Bd tau_k.
    A = np.block([[Ad, (1 - kappa) * Bd], [np.zeros((1, 4)), np.array([[1 - kappa]])]])
    B = np.vstack([kappa * Bd, [[kappa]]])
    Qa = scipy.linalg.block_diag(Q, 0.0)
    want = scipy.linalg.solve_discrete_are(A, B, Qa, R)
    np.testing.assert_allclose(S, want, rtol=1e-7, atol=1e-9 * np.abs(want).max())
    np.testing.assert_allclose(K, np.linalg.solve(R + B.T @ want @ B, B.T @ want @ A), rtol=1e-7)


def _pushing(system, torque: float) -> Trajectory:
    """A short plan from hanging whose torque is *torque* throughout (only its first sample
    matters here)."""
    knots = 4
    return Trajectory(
        system=system.key, params=dict(system.params), state_names=system.state_names,
        input_names=system.input_names, times=np.linspace(0.0, 0.1, knots + 1),
        states=np.zeros((knots + 1, 4)), inputs=np.full((knots + 1, 1), torque),
        mid_inputs=np.full((knots, 1), torque), converged=True, cost=0.0, max_defect=0.0,
        solve_time=0.0, iterations=0, solver="by hand", system_digest=system.digest)


def test_the_plans_torque_acts_through_the_lag_when_the_tracker_leads_it() -> None:
    rig = equilibrist.get_system("dfki_double_pendulum", robot="pendubot")
    kappa = 0.25
    path = _pushing(rig, 1.0)
    lagged = equilibrist.policy(rig, controller="tvlqr", trajectory=path, wrap="on",
                                design_torque_response=str(kappa)).controller
    plain = equilibrist.policy(rig, controller="tvlqr", trajectory=path, wrap="on").controller
    motor = Rig(torque_response=kappa)
    first = {name: simulate(rig, c, duration=0.01, x0=np.zeros(4), rig=motor, region={})
             for name, c in (("lagged", lagged), ("plain", plain))}
    # The motor starts at the operating point's torque (0): what acts is kappa times the
    # command; the lead commands 1 / kappa of the plan's torque.
    assert first["lagged"].commanded[0, 0] == pytest.approx(1.0 / kappa, rel=1e-12)
    assert first["lagged"].applied[0, 0] == pytest.approx(1.0, rel=1e-12)
    assert first["plain"].applied[0, 0] == pytest.approx(kappa, rel=1e-12)
    assert lagged.settings["torque_response"] == kappa
    with pytest.raises(ControllerError, match="--balance lqr"):
        equilibrist.policy(rig, controller="tvlqr", trajectory=path, balance="lqg",
                           design_torque_response="0.5")


def test_the_lag_aware_tracker_scores_above_the_plain_one_on_the_torque_response_family(
) -> None:
    """The pendubot's swing-up at 100 Hz with gentle gains (torque weight 40): the plain
    tracker swings up only for a motor a little slower than immediate; designed for a lag
    of k = 0.5 it swings up from k = 0.2 to past 1.5."""
    rig = equilibrist.get_system("dfki_double_pendulum", robot="pendubot")
    path = plan(rig, start=np.zeros(4), goal=np.array([math.pi, 0.0, 0.0, 0.0]), knots=40,
                duration=2.0, state_cost={"theta1_dot": 0.1, "theta2_dot": 0.1})
    scores = {}
    for design in (None, "0.5"):
        kw = {} if design is None else {"design_torque_response": design}
        ctrl = equilibrist.policy(rig, controller="tvlqr", trajectory=path, rate=100.0, r=[40.0],
                                  wrap="on", **kw).controller
        card = robustness(rig, ctrl, x0=np.zeros(4), rate=100.0, families=("torque_response",))
        scores[design] = card.scores["torque_response"]
    assert scores["0.5"] >= scores[None] + 0.4, scores
