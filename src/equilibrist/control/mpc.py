"""Constrained linear model predictive control (MPC), solved exactly by DAQP.

At every sample the controller solves, for the deviation ``dx_0`` of the
(estimated) state from the operating point, the quadratic program

.. math::

    \\min \\sum_{k=0}^{N-1} (dx_k' Q dx_k + du_k' R du_k) + dx_N' P dx_N
          + \\sum_{k=1}^{N} (\\rho_1 1's_k + \\rho_2 s_k's_k)

    dx_{k+1} = A_d dx_k + B_d du_k,\\quad
    u_{min} - u_{op} \\le du_k \\le u_{max} - u_{op}\\ \\text{(hard)},\\quad
    lo - s_k \\le C_s dx_k \\le hi + s_k,\\ s_k \\ge 0\\ \\text{(soft)}

and applies ``u = u_op + du_0`` (receding horizon). ``A_d, B_d`` are the
design's zero-order-hold sampled linearization, ``Q`` and ``R`` its weights
(``--q``, ``--r``; Bryson's rule by default), ``P`` the discrete Riccati
solution ``S`` of the same weights: with no constraint active the
minimizer is the discrete LQR's ``du_0 = -K dx_0`` whatever the horizon.

*Soft state constraints* (the cart's track ``|x| <= x_max``, the system's
region of each angle) carry a slack ``s_k`` per constrained state and step,
penalized by ``rho_1 s + rho_2 s^2``. The L1 weight ``rho_1`` makes the
penalty exact: as long as a trajectory that meets the constraints exists,
the slack stays zero; the L2 weight keeps the problem strictly convex.
Defaults: ``rho_1 = 100`` and ``rho_2 = 4`` times the largest diagonal
entry of ``Q``. The input limits are hard: the command never leaves them.

*A bound already violated.* A soft bound that the (estimated) state
violates now cannot be met in the first samples, and on a non-minimum-phase
plant (the cart-pole: returning a cart starts by moving it further out) a
short horizon with a heavy slack penalty then prefers plans that keep the
violation small over the next samples and lose the cart for good (a cart
carried past the track's end by a 250 N push ran away to 12 m at 200 Hz, ``N = 30``).
So such a bound is widened over the horizon to the LQR's own trajectory
from the current state (:meth:`MPCProblem.soft_limits`): the LQR's return is
always a plan with zero slack, and the QP only improves on it.
Bounds the state meets keep their full weight.

*The QP.* The moves are written ``du_k = -K dx_k + v_k`` (the LQR plus a
correction) and the states are eliminated (:attr:`MPCProblem.condensed`):
the variables are the ``N m`` corrections and the ``N`` slack vectors, the
Hessian is block diagonal (``2 (R + B'PB)`` per move: the Riccati
solution absorbs the states' cost) and only the constraints' bounds depend
on ``dx_0`` (:meth:`MPCProblem.qp_bounds`).

*Solver.* First the unconstrained case is solved exactly: the LQR's own
trajectory from ``dx_0`` (``v = 0``) minimizes the quadratic part of the
cost, so when it meets every constraint over the horizon (slack zero) it
is the QP's minimizer, and the controller applies ``-K dx_0`` to
round-off without calling the solver. Otherwise DAQP, a dual active-set
solver: it ends on the exact optimal active set (the solution solves that
set's KKT system to round-off, not to an iterative tolerance), and starts
from the previous sample's working set, so a sample whose active set did
not change costs one or two iterations. The data are factorized once; each
sample updates only the bounds. The iteration cap :data:`ITER_LIMIT` bounds
the solve time; a QP that ends without a solution (the cap, or a failure)
gets the clipped LQR and the next sample a cold start (counted in
``fallbacks``). ``exact_unconstrained=False`` on the runtime sends every
sample to DAQP.

An earlier release solved the sparse form of the same QP with OSQP (ADMM).
Its slack penalty's scale made ADMM slow: on the cart-pole at 200 Hz,
``N = 30``, about two thirds of the constrained samples stopped at its
iteration cap with first moves up to 70 N from the optimum. DAQP solves all
of them: 0.08 ms median, 0.6 ms worst per sample (bench/README.md).

*Estimator.* With ``estimator="kalman"`` (the default when the measured
outputs are not the full state) the design's discrete Kalman filter (its
``current`` or ``predictor`` form) runs in front and the QP starts at its
estimate; with ``"state"`` the measured full state is used.

The controller is a :class:`~equilibrist.control.controller.PythonController`:
the solver is C code called from Python at every sample, so batches of it
run in worker processes.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.control.controller import ControllerError

if TYPE_CHECKING:
    from equilibrist.control.design import Design
    from equilibrist.numeric.system import System

#: DAQP's bound for "no bound".
INF = 1e30
#: DAQP's iteration cap (a bounded solve time). A cold start of the cart-pole's QP at
#: N = 30 takes at most about 75 iterations; a warm one a few (bench/README.md).
ITER_LIMIT = 1000
#: DAQP's primal feasibility tolerance (the constraints of its exact active set hold to it).
EPS = 1e-6
#: DAQP's exit flags: > 0 solved.
STATUS = {1: "solved", 2: "solved (soft)", -1: "infeasible", -2: "cycling", -3: "unbounded",
          -4: "iteration limit", -5: "nonconvex", -6: "overdetermined working set"}
#: Default horizon [samples].
HORIZON = 30
#: Default soft-constraint weights, relative to the largest diagonal entry of Q.
RHO_L1, RHO_L2 = 1e2, 4.0
#: Track parameter bounding the cart's coordinate.
TRACK = ("x_max", "x")


#: Why the MPC cannot run when its solver is not installed.
MISSING_SOLVER = "the MPC controller needs DAQP: pip install 'equilibrist[mpc]'"


def solver_missing() -> str | None:
    """:data:`MISSING_SOLVER` when DAQP is not installed (without importing it), else None."""
    import importlib.util

    return MISSING_SOLVER if importlib.util.find_spec("daqp") is None else None


def _daqp() -> Any:
    try:
        import daqp
    except ModuleNotFoundError as exc:  # pragma: no cover - the extra is missing
        raise ControllerError(MISSING_SOLVER) from exc
    return daqp


@dataclass(frozen=True, eq=False)
class MPCProblem:
    """The QP of one MPC controller (everything but the current state).

    Attributes
    ----------
    A, B:
        Sampled model (deviation coordinates).
    Q, R, P:
        Stage and terminal weights.
    horizon:
        ``N`` samples.
    u_lo, u_hi:
        Hard bounds of ``du`` (``u_min - u_op``, ``u_max - u_op``).
    soft_index, soft_lo, soft_hi:
        Constrained states and their bounds (deviation).
    rho_l1, rho_l2:
        Penalties of the slacks.
    """

    A: np.ndarray
    B: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    P: np.ndarray
    horizon: int
    u_lo: np.ndarray
    u_hi: np.ndarray
    soft_index: tuple[int, ...]
    soft_lo: np.ndarray
    soft_hi: np.ndarray
    rho_l1: float
    rho_l2: float

    @property
    def n(self) -> int:
        return int(self.A.shape[0])

    @property
    def m(self) -> int:
        return int(self.B.shape[1])

    @property
    def n_soft(self) -> int:
        return len(self.soft_index)

    K: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    @property
    def n_variables(self) -> int:
        """The QP's variables: the corrections ``v`` and the slacks ``s``."""
        return self.horizon * (self.m + self.n_soft)

    def predictions(self) -> tuple[np.ndarray, np.ndarray]:
        """``Fx, Gx`` with the stacked states ``[dx_0..dx_N] = Fx dx_0 + Gx v``.

        The moves are ``du_k = -K dx_k + v_k`` (the LQR plus a correction).
        """
        n, m, N = self.n, self.m, self.horizon
        Acl = self.A - self.B @ self.K
        Fx = np.zeros(((N + 1) * n, n))
        Gx = np.zeros(((N + 1) * n, N * m))
        Fx[:n] = np.eye(n)
        for k in range(N):
            rows = slice((k + 1) * n, (k + 2) * n)
            prev = slice(k * n, (k + 1) * n)
            Fx[rows] = Acl @ Fx[prev]
            Gx[rows] = Acl @ Gx[prev]
            Gx[rows, k * m:(k + 1) * m] += self.B
        return Fx, Gx

    @cached_property
    def soft_predictions(self) -> tuple[np.ndarray, np.ndarray]:
        """``Fu, Fs``: the LQR's own trajectory from ``dx_0`` (``du_k = -K dx_k``) has the
        stacked moves ``Fu dx_0`` (``k = 0..N-1``) and constrained states ``Fs dx_0``
        (``k = 1..N``, step-major: ``[k * n_soft + j]`` is ``soft_index[j]`` at step ``k + 1``)."""
        n, m, N = self.n, self.m, self.horizon
        Fx, _ = self.predictions()
        Fu = np.vstack([-self.K @ Fx[k * n:(k + 1) * n] for k in range(N)]).reshape(N * m, n)
        Fs = Fx[n:][[k * n + i for k in range(N) for i in self.soft_index]]
        return Fu, Fs

    @cached_property
    def condensed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``H, f, A`` of the condensed QP ``min 1/2 z'Hz + f'z``, ``bl <= [z; Az] <= bu``.

        Variables ``z = [v_0..v_{N-1}, s_1..s_N]``. The cost is
        ``dx_0' P dx_0 + sum v_k' (R + B'PB) v_k`` plus the slacks' penalty
        (``P`` solves the Riccati equation, so the prestabilized moves leave
        ``H`` block diagonal). The rows of ``A``: the moves
        ``du_k = -K dx_k + v_k`` (hard bounds), then ``C dx_k + s_k`` (lower
        soft bounds) and ``C dx_k - s_k`` (upper soft bounds), ``k = 1..N``;
        :meth:`qp_bounds` gives their bounds at ``dx_0``.
        """
        n, m, N, ns = self.n, self.m, self.horizon, self.n_soft
        nv, nsl = N * m, N * ns
        _, Gx = self.predictions()
        W = self.R + self.B.T @ self.P @ self.B
        H = np.zeros((nv + nsl, nv + nsl))
        H[:nv, :nv] = np.kron(np.eye(N), 2.0 * W)
        H[nv:, nv:] = np.diag(np.tile(2.0 * np.broadcast_to(self.rho_l2, (ns,)), N))
        f = np.concatenate([np.zeros(nv), np.tile(np.broadcast_to(self.rho_l1, (ns,)), N)])
        Mu = np.eye(nv) - np.kron(np.eye(N), self.K) @ Gx[: N * n]
        Ms = Gx[n:][[k * n + i for k in range(N) for i in self.soft_index]]
        eye = np.eye(nsl)
        A = np.block([[Mu, np.zeros((nv, nsl))], [Ms, eye], [Ms, -eye]])
        return H, f, A

    def soft_limits(self, dx0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The soft bounds over the horizon at *dx0* (deviations, ordered as ``Fs``'s rows).

        ``soft_lo, soft_hi`` at every step, with one relaxation: a soft bound
        that the state already violates now cannot be met in the first
        samples (the cart-pole is non-minimum phase: returning a cart starts
        by moving it further out), so its bound over the horizon is widened
        to the LQR's own trajectory from *dx0*. The QP then only improves on
        the LQR's return instead of demanding the impossible.
        """
        N, ns = self.horizon, self.n_soft
        lows = np.tile(self.soft_lo, (N, 1))
        highs = np.tile(self.soft_hi, (N, 1))
        if ns:
            c = dx0[list(self.soft_index)]
            out = (c > self.soft_hi) | (c < self.soft_lo)
            if np.any(out):
                _, Fs = self.soft_predictions
                xs = (Fs @ dx0).reshape(N, ns)
                lows[:, out] = np.minimum(lows[:, out], xs[:, out])
                highs[:, out] = np.maximum(highs[:, out], xs[:, out])
        return lows.reshape(-1), highs.reshape(-1)

    @cached_property
    def _bound_map(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``bu0, bl0, E``: the bounds of :meth:`qp_bounds` are ``bu0 - E dx0``, ``bl0 - E dx0``
        (before the widening of violated soft bounds)."""
        N, m, ns = self.horizon, self.m, self.n_soft
        nv, nsl = N * m, N * ns
        Fu, Fs = self.soft_predictions
        inf_v, inf_s = np.full(nv, INF), np.full(nsl, INF)
        bu = np.concatenate([inf_v, inf_s, np.tile(self.u_hi, N), inf_s, np.tile(self.soft_hi, N)])
        bl = np.concatenate([-inf_v, np.zeros(nsl), np.tile(self.u_lo, N), np.tile(self.soft_lo, N),
                             -inf_s])
        E = np.vstack([np.zeros((self.n_variables, self.n)), Fu, Fs, Fs])
        return bu, bl, E

    def qp_bounds(self, dx0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``bu, bl`` of the condensed QP at *dx0*: first the variables' own bounds
        (``v`` free, ``s >= 0``), then the rows of :attr:`condensed`'s ``A``
        (infinite bounds are :data:`INF`, DAQP's): the moves' hard bounds
        less the LQR's moves ``Fu dx0``, the soft bounds (:meth:`soft_limits`)
        less the LQR's constrained states ``Fs dx0``."""
        dx0 = np.asarray(dx0, dtype=float)
        bu0, bl0, E = self._bound_map
        shift = E @ dx0
        bu, bl = bu0 - shift, bl0 - shift
        ns = self.n_soft
        if ns:
            c = dx0[list(self.soft_index)]
            if np.any((c > self.soft_hi) | (c < self.soft_lo)):
                N, nsl = self.horizon, self.horizon * ns
                lower = self.n_variables + N * self.m
                xs = shift[lower:lower + nsl]
                lo_s, hi_s = self.soft_limits(dx0)
                bl[lower:lower + nsl] = lo_s - xs
                bu[lower + nsl:] = hi_s - xs
        return bu, bl


@dataclass(frozen=True, eq=False)
class MPC:
    """A constrained MPC controller (a value; :meth:`runtime` makes the running one).

    Attributes
    ----------
    problem:
        The QP.
    x_op, u_op:
        Operating point.
    rate:
        Sample rate [Hz].
    state_names, input_names, output_names:
        The plant's states and inputs, and the measured outputs.
    estimator:
        ``"kalman"`` or ``"state"``.
    Ad, Bd, Kf, form:
        The Kalman filter (``estimator="kalman"``).
    K:
        The discrete LQR gain (what the unconstrained MPC equals).
    design:
        The design it was made from.
    """

    problem: MPCProblem
    x_op: np.ndarray
    u_op: np.ndarray
    rate: float
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    estimator: str
    Kf: np.ndarray | None
    form: str
    K: np.ndarray
    design: Any = field(default=None, repr=False)

    kind = "mpc"

    @property
    def outputs(self) -> tuple[str, ...]:
        return self.output_names

    def runtime(self) -> MPCRuntime:
        """A new running controller (its own DAQP workspace)."""
        return MPCRuntime(self)

    def describe(self) -> dict[str, object]:
        p = self.problem
        return {"kind": self.kind, "rate": self.rate, "horizon": p.horizon,
                "estimator": self.estimator, "outputs": list(self.output_names),
                "soft": [self.state_names[i] for i in p.soft_index],
                "soft_lo": p.soft_lo.tolist(), "soft_hi": p.soft_hi.tolist(),
                "rho_l1": p.rho_l1, "rho_l2": p.rho_l2, "eps": EPS, "solver": "daqp"}


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
        self._solver = _daqp().Model()
        self._solver.setup(H, f, A, bu, bl, self._cold)
        self._solver.settings = {"iter_limit": ITER_LIMIT, "primal_tol": EPS}
        self._rows = prob.n_variables
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
        self._solver.update(sense=self._cold)  # an empty working set
        self.estimate = None
        self.last_status = ""
        self.last_iterations = 0
        self.fallbacks = 0

    def _state(self, y: np.ndarray) -> np.ndarray:
        return self.front.estimate(y)

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
        """The first move ``du_0`` of the QP from the deviation *dx0*."""
        prob = self.ctrl.problem
        m = prob.m
        dx0 = np.asarray(dx0, dtype=float)
        t0 = time.perf_counter()
        bu, bl = prob.qp_bounds(dx0)
        du_lqr: np.ndarray = -self.ctrl.K @ dx0
        if self.exact_unconstrained and self._zero_feasible(bu, bl):
            self.solve_times.append(time.perf_counter() - t0)
            self.last_status = "unconstrained"
            self.last_iterations = 0
            return du_lqr
        # Only the bounds change: DAQP keeps its factorization and starts from the last
        # sample's working set.
        self._solver.update(bupper=bu, blower=bl)
        sol, _, flag, info = self._solver.solve()
        self.solve_times.append(time.perf_counter() - t0)
        self.last_status = STATUS.get(int(flag), f"exit flag {flag}")
        self.last_iterations = int(info["iterations"])
        if flag <= 0 or not np.all(np.isfinite(sol[:m])):
            # No solution (cannot happen for a feasible QP short of the cap): the LQR, inside
            # the hard limits, and a cold start next time.
            self.fallbacks += 1
            self._solver.update(sense=self._cold)
            held: np.ndarray = np.clip(du_lqr, prob.u_lo, prob.u_hi)
            return held
        # The solution meets the hard bounds to DAQP's primal tolerance; the clip makes it exact.
        du: np.ndarray = np.clip(du_lqr + sol[:m], prob.u_lo, prob.u_hi)
        return du

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


def soft_bounds(system: System, x_op: np.ndarray) -> dict[str, tuple[float, float]]:
    """The soft state constraints (absolute): the system's region and the cart's track."""
    out = {k: (float(lo), float(hi)) for k, (lo, hi) in system.spec.region.items()}
    param, state = TRACK
    if param in system.params and state in system.state_names:
        bound = float(system.params[param])
        out[state] = (-bound, bound)
    return out


def mpc(
    system: System,
    *,
    design: Design | None = None,
    horizon: int = HORIZON,
    estimator: str | None = None,
    constraints: Mapping[str, tuple[float, float]] | None = None,
    rho: tuple[float, float] | None = None,
    rate: float | None = None,
) -> MPC:
    """The constrained MPC of *system* (see the module docstring).

    Parameters
    ----------
    design:
        A discrete design (weights, model, Riccati solution, Kalman filter);
        default ``design(system, rate=rate)``.
    horizon:
        Prediction horizon ``N`` in samples (at least 1).
    estimator:
        ``"kalman"`` or ``"state"``; default ``"state"`` when the design's
        outputs are the full state, else ``"kalman"``.
    constraints:
        Soft state constraints ``{state: (low, high)}`` (absolute); default
        :func:`soft_bounds`. ``{}`` for none.
    rho:
        ``(rho_1, rho_2)`` of the slack penalty; default :data:`RHO_L1`,
        :data:`RHO_L2` times the largest diagonal entry of ``Q``.
    rate:
        Sample rate [Hz]; default the design's, else the rig's.
    """
    from equilibrist.control.design import design as make_design

    problems: list[str] = []
    if isinstance(horizon, bool) or not isinstance(horizon, int | np.integer) or horizon < 1:
        problems.append(f"horizon must be a whole number of samples >= 1, got {horizon!r}")
    if estimator not in (None, "kalman", "state"):
        problems.append(f"estimator {estimator!r}: expected 'kalman' or 'state'")
    if problems:
        raise ControllerError("; ".join(problems))
    hz = float(rate if rate is not None else (design.rate if design is not None and design.rate
                                               else system.spec.control_rate))
    if design is None:
        design = make_design(system, rate=hz)
    if design.discrete is None or design.rate is None:
        raise ControllerError("the MPC needs a discrete design: design(system, rate=...)")
    plant = design.plant
    names = plant.state_names
    n, m = plant.n_states, plant.n_inputs
    x_op, u_op = np.asarray(plant.x0, dtype=float), np.asarray(plant.u0, dtype=float)
    lo, hi = system.input_limits
    bounds = soft_bounds(system, x_op) if constraints is None else dict(constraints)
    unknown = [k for k in bounds if k not in names]
    if unknown:
        raise ControllerError(
            f"constraint on {', '.join(unknown)}: not a state of {system.key} ({', '.join(names)})"
        )
    idx = tuple(names.index(k) for k in bounds)
    s_lo = np.array([bounds[names[i]][0] - x_op[i] for i in idx])
    s_hi = np.array([bounds[names[i]][1] - x_op[i] for i in idx])
    Q = np.asarray(design.Q, dtype=float)
    qmax = float(np.max(np.diag(Q)))
    r1, r2 = rho if rho is not None else (RHO_L1 * qmax, RHO_L2 * qmax)
    prob = MPCProblem(
        A=np.asarray(design.discrete.A, dtype=float), B=np.asarray(design.discrete.B, dtype=float),
        Q=Q, R=np.asarray(design.R, dtype=float), P=np.asarray(design.S, dtype=float),
        horizon=int(horizon), u_lo=lo - u_op, u_hi=hi - u_op, soft_index=idx,
        soft_lo=s_lo, soft_hi=s_hi, rho_l1=float(r1), rho_l2=float(r2),
        K=np.asarray(design.K, dtype=float).reshape(m, n),
    )
    outs = tuple(plant.output_names)
    est = estimator or ("state" if outs == tuple(names) else "kalman")
    if est == "state" and outs != tuple(names):
        outs = tuple(names)
    return MPC(
        problem=prob, x_op=x_op, u_op=u_op, rate=float(design.rate), state_names=tuple(names),
        input_names=tuple(plant.input_names), output_names=outs, estimator=est,
        Kf=None if est == "state" else np.asarray(design.Kf, dtype=float),
        form=design.kalman_form, K=np.asarray(design.K, dtype=float).reshape(m, n),
        design=design,
    )


__all__ = ["EPS", "HORIZON", "INF", "ITER_LIMIT", "MISSING_SOLVER", "MPC", "KalmanFront", "MPCProblem", "MPCRuntime", "mpc",
           "soft_bounds", "solver_missing"]
