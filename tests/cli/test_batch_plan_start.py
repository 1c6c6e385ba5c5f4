"""``batch --controller tvlqr`` without ``--x0`` starts its runs where the plan starts."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from equilibrist import get_system
from equilibrist.cli.main import main
from equilibrist.control.trajopt import Trajectory
from equilibrist.sim.batch_result import BatchResult


def test_a_planned_batch_starts_where_its_plan_starts(tmp_path: Path) -> None:
    cart = get_system("cartpole")
    x_op = cart.operating_point().x
    start = x_op.copy()
    start[0] = 0.3  # the cart's position is free: upright at rest there is a plan of its own
    knots = 10
    plan = Trajectory(
        system=cart.key, params=dict(cart.params), state_names=cart.state_names,
        input_names=cart.input_names, times=np.linspace(0.0, 0.5, knots + 1),
        states=np.tile(start, (knots + 1, 1)), inputs=np.zeros((knots + 1, 1)),
        mid_inputs=np.zeros((knots, 1)), converged=True, cost=0.0, max_defect=0.0,
        solve_time=0.0, iterations=0, solver="by hand", system_digest=cart.digest)
    path = plan.save(tmp_path / "plan.npz")
    out = tmp_path / "batch.npz"
    assert main(["batch", "cartpole", "--controller", "tvlqr", "--trajectory", str(path),
                 "--runs", "2", "--duration", "0.1", "--out", str(out)]) == 0
    np.testing.assert_allclose(BatchResult.load(out).x0, np.tile(start, (2, 1)))
