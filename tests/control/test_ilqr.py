"""Iterative LQR: its plans checked against the system's own dynamics and against IPOPT.

The truths: the system's compiled ``f`` integrated by scipy's adaptive Runge-Kutta over
every interval with the plan's input (each interval lands on the next knot to RK4's
accuracy); IPOPT's collocation polishing the same problem from the iLQR's plan (the effort
it reaches is the optimum iLQR must be near); scipy's L-BFGS-B on each box-constrained QP
of the backward pass.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import minimize

from equilibrist import get_system
from equilibrist.cli.main import main
from equilibrist.control.ilqr import _box_qp, plan_ilqr
from equilibrist.control.trajectory_file import load_trajectory
from equilibrist.control.trajopt import plan
from equilibrist.tasks import get_task, planning_bounds


def test_the_cart_pole_swing_up_lands_on_its_knots_keeps_its_limits_and_is_optimal() -> None:
    cart = get_system("cartpole")
    task = get_task(cart, "swingup")
    bounds = planning_bounds(task, 0.3)
    traj = plan_ilqr(cart, start=task.start, goal=task.x_op, knots=40, duration=4.0, bounds=bounds)
    assert traj.converged and traj.max_defect < 1e-6
    np.testing.assert_array_equal(traj.states[0], task.start)
    np.testing.assert_allclose(traj.states[-1], task.x_op, atol=1e-6)
    t = np.linspace(0, traj.duration, 2001)
    assert np.max(np.abs(traj.input_at(t))) <= cart.params["F_max"] + 1e-9
    assert np.max(np.abs(traj.states[:, 0])) <= 0.7 * cart.params["x_max"] + 1e-6
    scale = np.array([cart.params["x_max"], np.pi, 5.0, 10.0])
    for k in range(traj.knots):
        sol = solve_ivp(lambda s, x: cart.f(x, traj.input_at(s)), traj.times[k:k + 2],
                        traj.states[k], rtol=1e-10, atol=1e-12)
        err = np.max(np.abs(sol.y[:, -1] - traj.states[k + 1]) / scale)
        assert err < 2e-3, (k, err)
    # IPOPT from this plan: the collocation's optimum of the same problem is within 2 %.
    polished = plan(cart, start=task.start, goal=task.x_op, knots=40, duration=4.0,
                    bounds=bounds, guess=traj)
    assert polished.converged
    assert abs(traj.cost - polished.cost) < 0.02 * polished.cost, (traj.cost, polished.cost)


def test_the_box_constrained_step_is_the_qp_minimizer() -> None:
    rng = np.random.default_rng(5)
    lo, hi = -np.ones(3), np.ones(3)
    clamped = 0
    for _ in range(100):
        M = rng.normal(size=(3, 3))
        Q, q, v = M @ M.T + 0.1 * np.eye(3), 3 * rng.normal(size=3), rng.uniform(-1, 1, 3)
        d, K = _box_qp(Q, q, np.ones((3, 4)), v, lo, hi)
        ref = minimize(lambda x, Q=Q, q=q: 0.5 * x @ Q @ x + q @ x, np.zeros(3),
                       jac=lambda x, Q=Q, q=q: Q @ x + q,
                       bounds=list(zip(lo - v, hi - v, strict=True)), method="L-BFGS-B",
                       options={"ftol": 1e-15, "gtol": 1e-12})
        np.testing.assert_allclose(d, ref.x, atol=1e-5)
        at_limit = (np.abs(v + d - lo) < 1e-9) | (np.abs(v + d - hi) < 1e-9)
        clamped += int(at_limit.any())
        assert np.all(K[at_limit] == 0) and np.all(K[~at_limit] != 0)
    assert clamped > 20  # the limits were reached often enough to be tested


def test_the_command_line_plans_by_ilqr_and_refuses_a_free_time(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "up.npz"
    assert main(["trajopt", "cartpole", "--method", "ilqr", "--knots", "30", "--duration", "4",
                 "--json", "--out", str(out)]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["converged"] and summary["solver"].startswith("ilqr")
    traj = load_trajectory(out)
    assert traj.knots == 30 and traj.settings["method"] == "ilqr"
    np.testing.assert_allclose(traj.states[-1], [0, 0, 0, 0], atol=1e-6)
    assert main(["trajopt", "cartpole", "--method", "ilqr", "--duration-max", "4"]) == 2
    assert "--duration-max" in capsys.readouterr().err
