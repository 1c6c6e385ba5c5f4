"""The compiled MPC's solve (the C that ships): the same moves and statuses as the QP of
MPCProblem.qp_bounds written out in Python and solved by DAQP's Python package, on states
inside, at and past every limit."""

from __future__ import annotations

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.control.design import design
from equilibrist.control.mpc import mpc
from equilibrist.control.mpc_runtime import MPCRuntime
from support.mpc_reference import ReferenceMPC


def _states(rng: np.random.Generator, count: int) -> np.ndarray:
    """Small states, pushes that saturate the input, carts past the track's end, poles past
    their region."""
    scale = np.array([0.3, 0.3, 1.5, 2.0])
    out = rng.normal(size=(count, 4)) * scale
    out[::7, 0] = rng.choice([-1.3, 1.2], size=out[::7].shape[0])  # past the track (1 m)
    out[::11, 1] = rng.choice([-1.7, 1.8], size=out[::11].shape[0])  # past the region
    out[::5] *= 0.05
    return out


@pytest.mark.parametrize("limit", [20.0, 200.0])
@pytest.mark.parametrize("soft", [True, False])
@pytest.mark.parametrize("exact", [True, False])
def test_solve_equals_the_written_out_qp(limit: float, soft: bool, exact: bool) -> None:
    system = get_system("cartpole", F_min=-limit, F_max=limit)
    d = design(system, rate=200.0)
    ctrl = mpc(system, design=d, horizon=15, estimator="state", constraints=None if soft else {})
    ours = MPCRuntime(ctrl, exact_unconstrained=exact)
    ref = ReferenceMPC(ctrl, exact_unconstrained=exact)
    statuses = set()
    for dx in _states(np.random.default_rng(3), 160):
        du = ours.solve(dx)
        want, status = ref.solve(dx), ref.last_status
        statuses.add(status)
        assert ours.last_status == status
        np.testing.assert_allclose(du, want, rtol=0, atol=1e-9)
        assert du.shape == (1,) and float(du[0]) >= -limit and float(du[0]) <= limit
    assert "solved" in statuses or "solved (soft)" in statuses
    assert ("unconstrained" in statuses) == exact


def test_the_move_is_a_fresh_array_each_sample() -> None:
    system = get_system("cartpole")
    rt = MPCRuntime(mpc(system, design=design(system, rate=200.0), horizon=10,
                        estimator="state"))
    a = rt.solve(np.array([0.01, 0.01, 0.0, 0.0]))
    kept = a.copy()
    rt.solve(np.array([-0.02, 0.02, 0.1, 0.0]))
    np.testing.assert_array_equal(a, kept)


def test_two_inputs() -> None:
    """Two inputs (the cart-pole with a second, made-up torque on the pole) take the general
    path of the moves."""
    import dataclasses

    from equilibrist.control.riccati import dlqr

    system = get_system("cartpole", F_min=-20.0, F_max=20.0)
    ctrl = mpc(system, design=design(system, rate=200.0), horizon=10, estimator="state")
    p = ctrl.problem
    B = np.hstack([p.B, 0.5 * p.B[:, ::-1]])
    R = np.diag([float(p.R[0, 0]), 2.0 * float(p.R[0, 0])])
    lqr = dlqr(p.A, B, p.Q, R)
    prob = dataclasses.replace(p, B=B, R=R, P=lqr.S, K=lqr.K, u_lo=np.array([-20.0, -3.0]),
                               u_hi=np.array([20.0, 3.0]))
    two = dataclasses.replace(ctrl, problem=prob, K=lqr.K, u_op=np.zeros(2))
    ours, ref = MPCRuntime(two), ReferenceMPC(two)
    statuses = set()
    for dx in _states(np.random.default_rng(5), 120):
        want, status = ref.solve(dx), ref.last_status
        du = ours.solve(dx)
        statuses.add(status)
        assert du.shape == (2,)
        np.testing.assert_allclose(du, want, rtol=0, atol=1e-9)
        assert ours.last_status == status
    assert {"unconstrained", "solved"} <= statuses
