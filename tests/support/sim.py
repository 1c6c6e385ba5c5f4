"""Helpers for the simulation tests: controllers built from scratch with scipy.

They do not use :mod:`equilibrist.control`, so the simulator's tests check
it against matrices computed independently.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sl

from equilibrist.numeric.lookup import get_system
from equilibrist.sim import LQG, StateFeedback
from equilibrist.sim.noise import Noise

Q_REF = np.diag([10.0, 10.0, 1.0, 1.0])
R_REF = np.array([[0.1]])


def cartpole(**params: float):
    return get_system("cartpole", **params)


def zoh(A: np.ndarray, B: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    n, m = B.shape
    big = np.zeros((n + m, n + m))
    big[:n, :n] = A
    big[:n, n:] = B
    e = sl.expm(big * T)
    return e[:n, :n], e[:n, n:]


def lqr(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray) -> np.ndarray:
    P = sl.solve_continuous_are(A, B, Q, R)
    return np.linalg.solve(R, B.T @ P)


def dlqr(Ad: np.ndarray, Bd: np.ndarray, Q: np.ndarray, R: np.ndarray) -> np.ndarray:
    P = sl.solve_discrete_are(Ad, Bd, Q, R)
    return np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad)


def dlqe_current(Ad: np.ndarray, C: np.ndarray, Qd: np.ndarray, Rd: np.ndarray) -> np.ndarray:
    """``M`` of the current-estimate filter ``xhat = xpred + M (y - C xpred)``."""
    P = sl.solve_discrete_are(Ad.T, C.T, Qd, Rd)
    return P @ C.T @ np.linalg.inv(C @ P @ C.T + Rd)


def state_feedback(system=None, *, rate: float | None = None) -> StateFeedback:
    system = system or cartpole()
    lm = system.linearize()
    if rate is None:
        K = lqr(lm.A, lm.B, Q_REF, R_REF)
    else:
        Ad, Bd = zoh(lm.A, lm.B, 1.0 / rate)
        K = dlqr(Ad, Bd, Q_REF, R_REF)
    return StateFeedback(K=K, x_op=lm.x0, u_op=lm.u0, rate=rate)


def lqg(system=None, *, rate: float = 200.0, form: str = "current",
        outputs: tuple[str, ...] = ("x", "theta"), qd_scale: float = 1e-6,
        rd_scale: float = 1e-6) -> LQG:
    system = system or cartpole()
    lm = system.linearize(outputs=outputs)
    Ad, Bd = zoh(lm.A, lm.B, 1.0 / rate)
    K = dlqr(Ad, Bd, Q_REF, R_REF)
    Qd = qd_scale * np.eye(lm.n_states)
    Rd = rd_scale * np.eye(len(outputs))
    M = dlqe_current(Ad, lm.C, Qd, Rd)
    Kf = M if form == "current" else Ad @ M
    return LQG(K=K, Ad=Ad, Bd=Bd, Kf=Kf, outputs=outputs, x_op=lm.x0, u_op=lm.u0,
               rate=rate, form=form)


def cartpole_noise(sysm, rate):
    """Process noise on the cart-pole's two rates, sensor noise on x and theta."""
    names = sysm.state_names
    g = np.zeros((4, 2))
    g[names.index("x_dot"), 0] = 1.0
    g[names.index("theta_dot"), 1] = 1.0
    return Noise(process_gain=g, process_intensity=np.diag([0.01, 0.02]),
                 measurement_covariance=np.diag([1e-6, 4e-6]), outputs=("x", "theta"))
