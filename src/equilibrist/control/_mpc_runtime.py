"""The MPC running: :class:`MPCRuntime` (the QP solved each sample, warm-started) and the
Kalman estimator in front of it (:class:`KalmanFront`); split from
:mod:`equilibrist.control.mpc`, which re-exports them.
"""

from __future__ import annotations

import math
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.control._mpc_problem import EPS, ITER_LIMIT, STATUS, _daqp
from equilibrist.control.controller import ControllerError

if TYPE_CHECKING:
    from equilibrist.control.mpc import MPC

#: DAQP's sense of a constraint active at its lower bound (DAQP_ACTIVE + DAQP_LOWER).
COLD_SLACK = 3
# Looked up once: a solve takes a few microseconds of numpy calls.
_least, _matmul = np.minimum.reduce, np.matmul


class MPCRuntime:
    """The MPC running: ``reset``, ``output``, ``update`` (a PythonController).

    Also records ``solve_times`` (seconds per QP) and ``last_status``.
    """

    def __init__(self, ctrl: MPC, *, exact_unconstrained: bool = True) -> None:
        self.ctrl = ctrl
        self.exact_unconstrained = exact_unconstrained
        self.rate: float | None = ctrl.rate
        self.outputs: tuple[str, ...] | None = ctrl.output_names
        self.estimate: np.ndarray | None = None
        prob = ctrl.problem
        H, f, A = prob.condensed
        bu, bl = prob.qp_bounds(np.zeros(prob.n))
        self._cold = np.zeros(bu.size, dtype=np.intc)
        # A cold start's working set holds the slacks' bounds s >= 0 (DAQP's sense: active,
        # at the lower bound): the LQR's plan has zero slack, and a start from an empty set
        # spent an iteration on each of them (91 iterations instead of 31 on the cart-pole
        # at N = 30 after a push).
        self._cold[prob.horizon * prob.m:prob.n_variables] = COLD_SLACK
        self._solver = _daqp().Model()
        self._solver.setup(H, f, A, bu, bl, self._cold)
        self._solver.settings = {"iter_limit": ITER_LIMIT, "primal_tol": EPS}
        self._rows = prob.n_variables
        self._fast_path()
        self.front = KalmanFront(ctrl)
        self.solve_times: list[float] = []
        self.reset()

    def __reduce__(self) -> tuple[Any, ...]:
        # DAQP's workspace does not pickle: a copy sent to a batch's worker is a new runtime
        # of the same MPC, fresh as a run starts (the batch resets each run's controller).
        return (MPCRuntime, (self.ctrl,), {"exact_unconstrained": self.exact_unconstrained})

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.exact_unconstrained = bool(state["exact_unconstrained"])

    @property
    def z(self) -> np.ndarray:
        """The filter's state: the predicted deviation ``xhat_{k|k-1} - x_op``."""
        return self.front.z

    @z.setter
    def z(self, value: np.ndarray) -> None:
        self.front.z = np.array(value, dtype=float)

    def reset(self) -> None:
        self.front.reset()
        self._solver.update(sense=self._cold)  # a cold start: the slacks' bounds only
        self.estimate = None
        self.last_status = ""
        self.last_iterations = 0
        self.fallbacks = 0

    def _state(self, y: np.ndarray) -> np.ndarray:
        return self.front.estimate(y)

    def _fast_path(self) -> None:
        """What :meth:`solve` computes once: the matrix ``W`` whose product with
        ``[dx0; 1]`` gives ``-K dx0`` (the LQR's move), then ``bu`` and ``-bl`` of
        :meth:`MPCProblem.qp_bounds` (``bu0 - E dx0``, ``bl0 - E dx0``) with, between them, the
        margins ``hi - c``, ``c - lo`` of the constrained states ``c`` now to their soft
        bounds: the LQR's trajectory meets every constraint (and no soft bound is violated
        now) exactly when all of them are ``>= 0``; then ``bl`` itself, for DAQP."""
        prob = self.ctrl.problem
        bu0, bl0, E = prob._bound_map
        n, m, ns = prob.n, prob.m, prob.n_soft
        pick = np.zeros((ns, n))
        pick[np.arange(ns), list(prob.soft_index)] = 1.0
        self._W = np.ascontiguousarray(np.block([
            [-prob.K, np.zeros((m, 1))], [-E, bu0[:, None]], [-pick, prob.soft_hi[:, None]],
            [pick, -prob.soft_lo[:, None]], [E, -bl0[:, None]], [-E, bl0[:, None]]]))
        self._x1 = np.ones(n + 1)
        nb = bu0.size
        # The product's rows, and views of them: the move, every bound to check, the soft
        # margins, then bu and bl for DAQP.
        w = self._w = np.zeros(self._W.shape[0])
        self._move, self._checked = w[:m], w[m:m + 3 * nb + 2 * ns - nb]
        self._margins = w[m + nb:m + nb + 2 * ns]
        self._bu, self._bl = w[m:m + nb], w[m + 2 * nb + 2 * ns:]
        self._m, self._ns = m, ns
        # Where the first move's margins sit in the product: its rows of bu and of -bl.
        nv = prob.n_variables
        self._first = tuple(i for j in range(m) for i in (m + nv + j, m + nb + 2 * ns + nv + j))
        self._u_lo, self._u_hi = prob.u_lo.tolist(), prob.u_hi.tolist()

    def _zero_feasible(self, bu: np.ndarray, bl: np.ndarray) -> bool:
        rows = slice(self._rows, None)
        return bool(np.all(bl[rows] <= 0.0) and np.all(bu[rows] >= 0.0))

    def lqr_feasible(self, dx0: np.ndarray) -> bool:
        """Whether the LQR's own trajectory from *dx0* meets every constraint over the horizon.

        Then it is the QP's minimizer (``v = 0``, the unconstrained minimizer
        of the quadratic part, with zero slack), and the controller applies
        it exactly instead of solving: ``z = 0`` within the bounds of
        :meth:`MPCProblem.qp_bounds` (one product with the precomputed
        predictions ``Fu`` and ``Fs``).
        """
        return self._zero_feasible(*self.ctrl.problem.qp_bounds(dx0))

    def solve(self, dx0: np.ndarray) -> np.ndarray:
        """The first move ``du_0`` of the QP from the deviation *dx0*.

        The QP's bounds of :meth:`MPCProblem.qp_bounds` in few numpy calls (so that a solve
        costs about what DAQP costs): one product with ``[dx0; 1]`` gives the LQR's move and
        every bound; when the LQR's trajectory meets them all, it is the minimizer. A soft
        bound violated now takes the widening of :meth:`MPCProblem.soft_limits`.
        """
        x1 = self._x1
        t0 = time.perf_counter()
        x1[:-1] = dx0
        w = self._w
        _matmul(self._W, x1, out=w)
        # The first move's own margins first (two floats): after a push it is the LQR's
        # first move that meets the limit, and the whole check is then not needed.
        if (self.exact_unconstrained and all(w.item(i) >= 0.0 for i in self._first)
                and _least(self._checked) >= 0.0):
            self.solve_times.append(time.perf_counter() - t0)
            self.last_status = "unconstrained"
            self.last_iterations = 0
            return self._move.copy()
        if self._ns and _least(self._margins) < 0.0:
            # A soft bound violated now: widened over the horizon (rare; the general path).
            bu, bl = self.ctrl.problem.qp_bounds(np.asarray(dx0, dtype=float))
            if self.exact_unconstrained and self._zero_feasible(bu, bl):
                self.solve_times.append(time.perf_counter() - t0)
                self.last_status = "unconstrained"
                self.last_iterations = 0
                return self._move.copy()
        else:
            bu, bl = self._bu, self._bl
        # Only the bounds change: DAQP keeps its factorization and starts from the last
        # sample's working set.
        self._solver.update(None, None, None, bu, bl)
        sol, _, flag, info = self._solver.solve()
        self.solve_times.append(time.perf_counter() - t0)
        self.last_status = STATUS.get(flag) or f"exit flag {flag}"
        self.last_iterations = info["iterations"]
        # The solution meets the hard bounds to DAQP's primal tolerance; the clip makes it exact.
        if self._m == 1:  # the common case, in Python floats
            d = self._move.item(0) + sol.item(0)
            if flag > 0 and math.isfinite(d):
                return np.array((min(max(d, self._u_lo[0]), self._u_hi[0]),))
        else:
            move = self._move.tolist()
            du = [a + b for a, b in zip(move, sol[:self._m].tolist(), strict=True)]
            if flag > 0 and all(map(math.isfinite, du)):
                return np.array([min(max(a, lo), hi)
                                 for a, lo, hi in zip(du, self._u_lo, self._u_hi, strict=True)])
        # No solution (cannot happen for a feasible QP short of the cap): the LQR, inside the
        # hard limits, and a cold start next time.
        self.fallbacks += 1
        self._solver.update(sense=self._cold)
        return np.array([min(max(a, lo), hi)
                         for a, lo, hi in zip(self._move.tolist(), self._u_lo, self._u_hi,
                                              strict=True)])

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        dx = self._state(y)
        self.estimate = self.ctrl.x_op + dx
        u: np.ndarray = self.ctrl.u_op + self.solve(dx)
        return u

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        self.front.update(y, u_applied)


class KalmanFront:
    """The estimator in front of the MPC: the design's discrete Kalman filter, or the state itself.

    ``estimate(y)`` is the deviation ``dx`` the QP starts from (the filter's
    ``current`` form corrects the prediction with this sample's measurement,
    the ``predictor`` form uses the prediction), ``update(y, u_applied)``
    predicts the next sample. Its state ``z`` is the predicted deviation
    ``xhat_{k|k-1} - x_op`` (zero at the start). With ``estimator="state"``
    the measurement is the full state and ``z`` stays empty of meaning.
    """

    def __init__(self, ctrl: MPC) -> None:
        self.ctrl = ctrl
        self._idx = [ctrl.state_names.index(o) for o in ctrl.output_names]
        self.reset()

    def reset(self) -> None:
        n = self.ctrl.problem.n
        self.z = np.zeros(n)
        self._xhat = np.zeros(n)

    def estimate(self, y: np.ndarray) -> np.ndarray:
        """The deviation of the state estimate at this sample, from the measurement *y*."""
        c = self.ctrl
        dy = np.asarray(y, dtype=float) - c.x_op[self._idx]
        dx: np.ndarray
        if c.estimator == "state":
            dx = dy.copy()
        elif c.form == "current":
            assert c.Kf is not None
            dx = self.z + c.Kf @ (dy - self.z[self._idx])
        else:
            dx = self.z.copy()
        self._xhat = dx
        return dx

    def update(self, y: np.ndarray, u_applied: np.ndarray) -> None:
        """Predict the next sample's state (after :meth:`estimate` of this one)."""
        c = self.ctrl
        if c.estimator == "state" or c.Kf is None or c.design is None:
            return
        Ad = np.asarray(c.design.discrete.A)
        Bd = np.asarray(c.design.discrete.B)
        du = np.asarray(u_applied, dtype=float) - c.u_op
        if c.form == "current":
            self.z = Ad @ self._xhat + Bd @ du
        else:
            dy = np.asarray(y, dtype=float) - c.x_op[self._idx]
            self.z = Ad @ self.z + Bd @ du + c.Kf @ (dy - self.z[self._idx])

    def linear_form(self) -> dict[str, np.ndarray]:
        """The filter as blocks of the linear controller form (deviations, row-major).

        ``z+ = Ac z + By dy + Bu du_applied`` and ``dx = Ez z + Ey dy``: for the
        ``current`` form ``Ez = I - M C``, ``Ey = M``, ``Ac = Ad Ez``,
        ``By = Ad M``; for the ``predictor`` form ``Ez = I``, ``Ey = 0``,
        ``Ac = Ad - L C``, ``By = L``; ``Bu = Bd`` in both. The same filter as
        :meth:`estimate` and :meth:`update`, with its products taken in
        another order (equal to round-off).
        """
        c = self.ctrl
        if c.estimator == "state" or c.Kf is None or c.design is None:
            raise ControllerError("the MPC measures the full state: it has no Kalman filter")
        n = c.problem.n
        Ad = np.asarray(c.design.discrete.A, dtype=float)
        Bd = np.asarray(c.design.discrete.B, dtype=float)
        Kf = np.asarray(c.Kf, dtype=float)
        C = np.zeros((len(self._idx), n))
        for row, i in enumerate(self._idx):
            C[row, i] = 1.0
        if c.form == "current":
            Ez, Ey = np.eye(n) - Kf @ C, Kf
            Ac, By = Ad @ Ez, Ad @ Kf
        else:
            Ez, Ey = np.eye(n), np.zeros_like(Kf)
            Ac, By = Ad - Kf @ C, Kf
        return {"Ac": Ac, "By": By, "Bu": Bd, "Ez": Ez, "Ey": Ey,
                "y_op": c.x_op[self._idx]}
