"""The time-varying LQR's gains shared by several plants (``plants=``).

Truths: one plant counted twice is the plain recursion's gains (the sum of two equal costs
has the same minimizer); the last sample's shared gain worked by hand (numpy and scipy's
``expm``).
"""

from __future__ import annotations

import numpy as np

import equilibrist
from equilibrist.control.design import design
from equilibrist.control.trajopt import Trajectory
from equilibrist.control.tvlqr import LAYOUT, shared_gains, tvlqr


def _swing(system) -> Trajectory:
    """A short made-up motion of the acrobot near upright, tracked as given."""
    times = np.linspace(0.0, 0.2, 5)
    states = np.array([system.operating_point().x + np.array([0.05, -0.1, 0.3, -0.2])
                       * (1 - t / 0.2) for t in times])
    return Trajectory(
        system=system.key, params=dict(system.params), state_names=system.state_names,
        input_names=system.input_names, times=times, states=states,
        inputs=np.linspace(1.0, 0.0, 5)[:, None], mid_inputs=np.full((4, 1), 0.5),
        converged=True, cost=0.0, max_defect=0.0, solve_time=0.0, iterations=0,
        solver="by hand", system_digest=system.digest)


def test_one_plant_twice_is_the_plain_recursion_and_another_moves_the_gains() -> None:
    system = equilibrist.get_system("acrobot")
    heavy = equilibrist.get_system("acrobot", m2=1.5 * float(system.params["m2"]))
    plan = _swing(system)
    d = design(system, rate=200.0)
    kw = dict(rate=200.0, Q=d.Q, R=d.R, S_end=d.S, K_end=d.K, x_op=d.plant.x0, u_op=d.plant.u0)
    plain = LAYOUT.read(np.asarray(tvlqr(system, plan, **kw).params), "gains")
    twice = LAYOUT.read(np.asarray(tvlqr(system, plan, plants=[system], **kw).params), "gains")
    np.testing.assert_allclose(twice, plain, rtol=1e-8, atol=1e-9 * np.abs(plain).max())
    spread = LAYOUT.read(np.asarray(tvlqr(system, plan, plants=[heavy], **kw).params), "gains")
    assert not np.allclose(spread, plain)
    # The last sample by hand: both plants' costs-to-go are the balance's S there, the gain
    # minimizes their sum; each plant sampled with zero-order hold by scipy's expm.
    from scipy.linalg import expm

    p = np.asarray(tvlqr(system, plan, **kw).params)
    x, u = LAYOUT.read(p, "xs")[-2], LAYOUT.read(p, "us")[-2]
    G, H = np.array(d.R, dtype=float), np.zeros((1, 4))
    G = 2 * G
    for plant in (system, heavy):
        A, B = plant.jacobians(x, u)
        block = expm(np.block([[A, B], [np.zeros((1, 5))]]) / 200.0)
        Ad, Bd = block[:4, :4], block[:4, 4:]
        G = G + Bd.T @ d.S @ Bd
        H = H + Bd.T @ d.S @ Ad
    np.testing.assert_allclose(spread[-1], np.linalg.solve(G, H), rtol=1e-9)
    assert shared_gains([system], LAYOUT.read(p, "xs"), LAYOUT.read(p, "us"), dt=1 / 200.0,
                        Q=d.Q, R=d.R, S_end=d.S).shape == plain.shape
