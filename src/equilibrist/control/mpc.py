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
sample updates only the bounds. The iteration cap
(:data:`~equilibrist.native.daqp_library.ITER_LIMIT`) bounds the solve time; a QP that ends without a solution (the cap, or a failure)
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
estimate; with ``"state"`` the measured full state is used. The filter is
the LQG controller's own estimator (:meth:`MPC.filter_form`), run by the linear
controller's library.

*One definition.* The runtime (:class:`MPCRuntime`) is the C library that
``export`` writes (:mod:`equilibrist.native.mpc_library`: DAQP's sources, the
generated driver and the filter), compiled once per cache folder and called
through ctypes at every sample: the simulated MPC is the shipped one, to the
bit. It is a :class:`~equilibrist.control.controller.PythonController`, so
batches of it run in worker processes.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control.mpc_problem import (
    HORIZON,
    RHO_L1,
    RHO_L2,
    TRACK,
    MPCProblem,
)
from equilibrist.control.mpc_runtime import MPCRuntime
from equilibrist.errors import ControllerError
from equilibrist.native.daqp_library import EPS

if TYPE_CHECKING:
    from equilibrist.control.design_record import Design
    from equilibrist.control.linear import LinearController
    from equilibrist.numeric.system import System


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
    design: Design | None = field(default=None, repr=False)

    kind = "mpc"

    @property
    def outputs(self) -> tuple[str, ...]:
        return self.output_names

    def runtime(self) -> MPCRuntime:
        """A new running controller (its own DAQP workspace)."""
        return MPCRuntime(self)

    def filter_form(self) -> LinearController:
        """The Kalman filter in front of the MPC as a linear controller: the design's LQG
        controller (``LinearController.lqg``), whose estimator the MPC runs, so one filter serves
        the LQG and the MPC. ``z+ = Ac z + By dy + Bu du_applied`` and ``dx = Ez z + Ey dy``: the
        linear map of the one estimator's source (:func:`equilibrist.control.kalman.realize`, the
        estimator of :func:`~equilibrist.control.kalman.estimator` when the library is written):
        for the Kalman filter's ``current`` form ``Ez = I - M C``, ``Ey = M``, ``Ac = Ad Ez``,
        ``By = Ad M``; for the ``predictor`` form ``Ez = I``, ``Ey = 0``, ``Ac = Ad - L C``,
        ``By = L``; ``Bu = Bd`` in both. The C that runs it is the linear library's translation
        (the LQG's own sums, to the bit), not the estimator's functions translated again: their
        unfolded sums (``z + M e``, then ``Ad`` times that) round otherwise than the LQG's
        precomputed products."""
        from equilibrist.control.linear import LinearController

        if self.estimator == "state" or self.Kf is None or self.design is None:
            raise ControllerError("the MPC measures the full state: it has no Kalman filter")
        disc = self.design.discrete
        assert disc is not None  # mpc() takes a discrete design only
        return LinearController.lqg(
            self.problem.K, Ad=np.asarray(disc.A, dtype=float),
            Bd=np.asarray(disc.B, dtype=float), Kf=self.Kf,
            outputs=self.output_names, x_op=self.x_op, u_op=self.u_op, rate=self.rate,
            form=self.form, state_names=self.state_names)

    def describe(self) -> dict[str, object]:
        p = self.problem
        return {"kind": self.kind, "rate": self.rate, "horizon": p.horizon,
                "estimator": self.estimator, "outputs": list(self.output_names),
                "soft": [self.state_names[i] for i in p.soft_index],
                "soft_lo": p.soft_lo.tolist(), "soft_hi": p.soft_hi.tolist(),
                "rho_l1": p.rho_l1, "rho_l2": p.rho_l2, "eps": EPS, "solver": "daqp"}


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


__all__ = [
    "MPC",
    "mpc",
    "soft_bounds",
]
