"""Time-varying LQR: track a planned trajectory, then balance (``--controller tvlqr``).

Along a plan of :mod:`equilibrist.control.trajopt`, sampled at the
controller's rate, the dynamics are linearized at each sample's planned
state and input (the system's exact Jacobians) and sampled with zero-order
hold; the discrete finite-horizon Riccati recursion runs backward from the
balancing LQR's own Riccati solution at the end,

    K_k = (R + B_k' S_k+1 B_k)^-1 B_k' S_k+1 A_k
    S_k = Q + A_k' S_k+1 (A_k - B_k K_k),

with the balancing design's weights (Bryson's rule), so the hand-over to the
balancing LQR at the plan's end is seamless. The command is

    u_k = u_plan(t_k) - K_k (x_k - x_plan(t_k))          while the plan runs,
    u_k = u_op - K (x_k - x_op)                           after it,

on the full measured state; both stages are one
:class:`~equilibrist.control.controller.NonlinearController` whose tables are
its parameters, so it runs in the compiled core like the swing-up.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control import fixed
from equilibrist.control.controller import (
    ControllerError,
    NonlinearController,
)
from equilibrist.control.discretize import discrete_matrices

if TYPE_CHECKING:
    from equilibrist.control.kinds import ControllerRequest
    from equilibrist.control.trajopt import Trajectory
    from equilibrist.numeric.system import System

#: The most samples a plan may span at the controller's rate (its tables are parameters).
MAX_SAMPLES = 200_000

SOURCE = '''
def tvlqr_offsets(params):
    n = int(params[2])
    m = int(params[3])
    K = int(params[0])
    ox = 4
    ou = ox + (K + 1) * n
    og = ou + (K + 1) * m
    oop = og + K * m * n
    oup = oop + n
    okb = oup + m
    return K, n, m, ox, ou, og, oop, oup, okb


def output(t, z, y, r, params, u_out):
    K, n, m, ox, ou, og, oop, oup, okb = tvlqr_offsets(params)
    k = int(math.floor(t * params[1] + 0.5))
    if k < K:
        for i in range(m):
            acc = params[ou + k * m + i]
            for j in range(n):
                acc -= params[og + (k * m + i) * n + j] * (y[j] - params[ox + k * n + j])
            u_out[i] = acc
    else:
        for i in range(m):
            acc = params[oup + i]
            for j in range(n):
                acc -= params[okb + i * n + j] * (y[j] - params[oop + j])
            u_out[i] = acc


def update(t, z, y, r, u_applied, params, z_out):
    return
'''


def _hermite_states(system: System, traj: Trajectory, t: np.ndarray) -> np.ndarray:
    """The plan's states at times *t*: the cubic Hermite interpolant of the knots and their rates."""
    f = np.array([system.f(x, u) for x, u in zip(traj.states, traj.inputs, strict=True)])
    k = np.clip(np.searchsorted(traj.times, t, side="right") - 1, 0, traj.knots - 1)
    h = (traj.times[k + 1] - traj.times[k])[:, None]
    s = ((t - traj.times[k]) / h[:, 0])[:, None]
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    states: np.ndarray = (h00 * traj.states[k] + h10 * h * f[k] + h01 * traj.states[k + 1]
                          + h11 * h * f[k + 1])
    return states


def tvlqr(system: System, traj: Trajectory, *, rate: float, Q: np.ndarray, R: np.ndarray,
          S_end: np.ndarray, K_end: np.ndarray, x_op: np.ndarray, u_op: np.ndarray
          ) -> NonlinearController:
    """The time-varying LQR along *traj* at *rate*, handing over to ``K_end`` at the end."""
    if traj.state_names != system.state_names or traj.input_names != system.input_names:
        raise ControllerError(f"the trajectory is of states {', '.join(traj.state_names)} and inputs "
                              f"{', '.join(traj.input_names)}: not {system.key}'s")
    steps = int(np.floor(traj.duration * rate + 1e-9))
    if not 1 <= steps <= MAX_SAMPLES:
        raise ControllerError(f"the trajectory spans {steps} samples at {rate:g} Hz: expected 1 to "
                              f"{MAX_SAMPLES}")
    n, m = system.n_states, system.n_inputs
    dt = 1.0 / rate
    t = traj.times[0] + np.arange(steps + 1) * dt
    xs = _hermite_states(system, traj, t)
    us = traj.input_at(t).reshape(steps + 1, m)
    S = np.array(S_end, dtype=float)
    gains = np.zeros((steps, m, n))
    for k in range(steps - 1, -1, -1):
        A, B = system.jacobians(xs[k], us[k])
        Ad, Bd = discrete_matrices(A, B, dt)
        # In the fixed order of control.fixed, as every sampled design: the same bits on
        # every CPU (numpy's @ and LAPACK follow the BLAS kernel the CPU selects).
        G = R + fixed.mm(Bd.T, S, Bd)
        Kk = fixed.solve(G, fixed.mm(Bd.T, S, Ad))
        S = fixed.symmetric(Q + fixed.mm(Ad.T, S, Ad - fixed.matmul(Bd, Kk)))
        gains[k] = Kk
    if not np.all(np.isfinite(gains)):
        raise ControllerError("the time-varying LQR's Riccati recursion did not stay finite along "
                              "the trajectory")
    params = np.concatenate([[steps, rate, n, m], xs.reshape(-1), us.reshape(-1), gains.reshape(-1),
                             x_op, u_op, np.asarray(K_end, dtype=float).reshape(-1)])
    return NonlinearController(
        name="tvlqr", source=SOURCE, params=params, z0=np.zeros(0), rate=float(rate),
        x_op=x_op, u_op=u_op, state_names=system.state_names, input_names=system.input_names,
        output_names=system.state_names,
        settings={"kind": "tvlqr", "trajectory_duration": traj.duration, "samples": steps,
                  "start": dict(zip(system.state_names, traj.states[0].tolist(), strict=True)),
                  "balance": "lqr"},
    )


def build_request(request: ControllerRequest) -> NonlinearController:
    from equilibrist.control.trajopt import load_trajectory

    path = request.options.get("trajectory")
    if path is None:
        raise ControllerError("--controller tvlqr tracks a planned trajectory: give --trajectory "
                              "FILE.npz (equilibrist trajopt SYSTEM --out FILE.npz)")
    traj = load_trajectory(path)
    system = request.system
    if traj.state_names != system.state_names or traj.input_names != system.input_names:
        raise ControllerError(f"{path} is a trajectory of {traj.system}, not of {system.key} "
                              "(its states or inputs differ)")
    design = request.design()
    if design.discrete is None:
        raise ControllerError("the time-varying LQR needs a discrete design (a rate)")
    rate = float(design.rate or system.spec.control_rate)
    return tvlqr(system, traj, rate=rate, Q=design.Q, R=design.R, S_end=design.S, K_end=design.K,
                 x_op=design.plant.x0, u_op=design.plant.u0)
