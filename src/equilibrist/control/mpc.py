"""Constrained linear model predictive control (MPC), solved exactly by DAQP.

At every sample the controller solves a QP over the horizon for the deviation of the
(estimated) state from the operating point and applies its first move (receding horizon):
the design's sampled linearization, weights and Riccati solution as terminal cost, hard
input limits, soft state bounds with an exact L1 plus L2 slack penalty, a bound the state
already violates widened to the LQR's own trajectory (:meth:`MPCProblem.soft_limits`). The
moves are the LQR plus a correction and the states are eliminated
(:attr:`MPCProblem.condensed`, :meth:`MPCProblem.qp_bounds`); when the LQR's trajectory meets
every constraint the QP is not called (``exact_unconstrained=False`` on the runtime sends
every sample to DAQP), and a QP without a solution gets the clipped LQR (counted in
``fallbacks``). docs/mpc.md writes the problem out and says why each choice was made (and
why not OSQP).

The runtime (:class:`MPCRuntime`) is the C library that ``export`` writes
(:mod:`equilibrist.native.mpc_library`: DAQP's sources, the generated driver and the filter,
the LQG's own estimator, :meth:`MPC.filter_form`), compiled once per cache folder and called
through ctypes at every sample: the simulated MPC is the shipped one, to the bit. It is a
:class:`~equilibrist.control.controller.PythonController`, so batches of it run in worker
processes.
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
