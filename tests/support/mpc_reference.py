"""A second MPC, written out in Python from the QP's definition: DAQP's Python package (its own
build of the solver) on ``MPCProblem.condensed`` and ``qp_bounds``, and the design's Kalman
filter as numpy products. The compiled MPC (the C that ships) is checked against it."""

from __future__ import annotations

import numpy as np

from equilibrist.control.mpc import MPC
from equilibrist.control.mpc_problem import STATUS
from equilibrist.native.daqp_library import EPS, ITER_LIMIT
from equilibrist.native.mpc_library import COLD_SLACK


class ReferenceMPC:
    """``reset``, ``output``, ``update``, ``solve`` and ``last_status`` as ``MPCRuntime``."""

    def __init__(self, ctrl: MPC, *, exact_unconstrained: bool = True) -> None:
        import daqp

        self.ctrl, self.exact = ctrl, exact_unconstrained
        self.rate, self.outputs = ctrl.rate, ctrl.output_names
        prob = ctrl.problem
        H, f, A = prob.condensed
        bu, bl = prob.qp_bounds(np.zeros(prob.n))
        self.cold = np.zeros(bu.size, dtype=np.intc)
        self.cold[prob.horizon * prob.m:prob.n_variables] = COLD_SLACK
        self.solver = daqp.Model()
        self.solver.setup(H, f, A, bu, bl, self.cold)
        self.solver.settings = {"iter_limit": ITER_LIMIT, "primal_tol": EPS}
        self.idx = [ctrl.state_names.index(o) for o in ctrl.output_names]
        self.estimate: np.ndarray | None = None
        self.reset()

    def reset(self) -> None:
        self.solver.update(sense=self.cold)
        n = self.ctrl.problem.n
        self.z, self.xhat = np.zeros(n), np.zeros(n)
        self.last_status = ""

    def solve(self, dx0: np.ndarray) -> np.ndarray:
        prob = self.ctrl.problem
        bu, bl = prob.qp_bounds(np.asarray(dx0, dtype=float))
        lqr = -prob.K @ dx0
        rows = slice(prob.n_variables, None)
        if self.exact and np.all(bl[rows] <= 0.0) and np.all(bu[rows] >= 0.0):
            self.last_status = "unconstrained"
            return lqr
        self.solver.update(bupper=bu, blower=bl)
        sol, _, flag, _ = self.solver.solve()
        self.last_status = STATUS.get(int(flag), f"exit flag {flag}")
        if flag <= 0:
            self.solver.update(sense=self.cold)
            return np.clip(lqr, prob.u_lo, prob.u_hi)
        return np.clip(lqr + sol[:prob.m], prob.u_lo, prob.u_hi)

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        c = self.ctrl
        dy = np.asarray(y, dtype=float) - c.x_op[self.idx]
        if c.estimator == "state":
            dx = dy
        elif c.form == "current":
            dx = self.z + c.Kf @ (dy - self.z[self.idx])
        else:
            dx = self.z.copy()
        self.xhat = dx
        self.estimate = c.x_op + dx
        return c.u_op + self.solve(dx)

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        c = self.ctrl
        if c.estimator == "state":
            return
        Ad, Bd = np.asarray(c.design.discrete.A), np.asarray(c.design.discrete.B)
        du = np.asarray(u_applied, dtype=float) - c.u_op
        if c.form == "current":
            self.z = Ad @ self.xhat + Bd @ du
        else:
            dy = np.asarray(y, dtype=float) - c.x_op[self.idx]
            self.z = Ad @ self.z + Bd @ du + c.Kf @ (dy - self.z[self.idx])
