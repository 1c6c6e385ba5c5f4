"""The LQG compensator: an estimator and a state feedback as one linear system.

Exactly as seeds/002 ("Control theory") writes it, with inputs ``(u, y, r)``
and output ``u``::

    xhat_dot = (A - Kf C) xhat + [B - Kf D, Kf, 0] [u; y; r]
    u        = -K xhat          + [0, 0, Kc]       [u; y; r]

The ``u`` input is the input actually applied to the plant (after
saturation, if any), fed back so that the estimator predicts with it.

Discrete equivalents (``Ad, Bd`` the sampled plant):

``"predictor"`` (``Kf = L``): the compensator state is ``xhat_{k|k-1}``::

    xhat_{k+1} = (Ad - L C) xhat_k + [Bd - L D, L, 0] [u_k; y_k; r_k]
    u_k        = -K xhat_k + [0, 0, Kc] [u_k; y_k; r_k]

``"current"`` (``Kf = M``, needs ``D = 0``): the compensator state is the
prediction ``xpred_k = xhat_{k|k-1}`` and the feedback uses the corrected
``xhat_{k|k} = (I - M C) xpred_k + M y_k``::

    xpred_{k+1} = Ad (I - M C) xpred_k + [Bd, Ad M, 0] [u_k; y_k; r_k]
    u_k         = -K (I - M C) xpred_k + [0, -K M, Kc] [u_k; y_k; r_k]

The discrete forms are the estimator's own arithmetic: for a plant whose outputs are states
(``C`` selects them, ``D = 0``) the estimator's matrices are
:func:`equilibrist.control.kalman.realize`'s, the one filter's source read off as a linear
map (the same numbers as the products above, to the bit); only a plant measuring other
combinations of its states takes the products of matrices.

All signals are deviations from the operating point: ``du = u - u0``,
``dy = y - y0``, ``dr = r - r0`` with ``r0`` the tracked outputs at the
operating point. Without a reference gain (a tracked output with zero DC
gain) the compensator has no ``r`` inputs.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from equilibrist.control import checks, fixed
from equilibrist.control.kalman import check_form, measured_states, realize
from equilibrist.errors import DesignError, DimensionError
from equilibrist.numeric.linear import LinearModel


@dataclass(frozen=True, eq=False)
class Compensator:
    """An output-feedback controller as a state-space system.

    For a discrete design this is where the LQG's arithmetic is: the one
    :class:`~equilibrist.control.linear.LinearController`
    (:meth:`~equilibrist.control.linear.LinearController.lqg`) takes its blocks from these
    matrices, so the two are one form split two ways, not two computations. A continuous
    design (and a plant measuring other than its states) has only this matrix form.

    Inputs are ``u_<input>`` (the applied plant inputs), ``y_<output>`` (the
    measurements) and ``r_<tracked output>`` (references), in that order;
    outputs are the plant inputs; states ``xhat_<state>``.

    Attributes
    ----------
    A, B, C, D:
        The compensator's matrices.
    form:
        ``"continuous"``, ``"current"`` or ``"predictor"``.
    dt:
        Sample period [s], None for a continuous compensator.
    u0, y0, r0:
        Operating values of the plant inputs, measured outputs and tracked
        outputs: the compensator works on deviations from them.
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    plant_state_names: tuple[str, ...]
    plant_input_names: tuple[str, ...]
    measured_names: tuple[str, ...]
    tracked_names: tuple[str, ...]
    form: str
    dt: float | None
    u0: np.ndarray
    y0: np.ndarray
    r0: np.ndarray
    #: The estimate ``dx = Ez xhat + Ey dy`` behind the command (discrete forms; None for a
    #: continuous compensator).
    Ez: np.ndarray | None = None
    Ey: np.ndarray | None = None

    def __repr__(self) -> str:  # one line; a notebook shows the matrices (equilibrist.notebook)
        timebase = "continuous" if self.dt is None else f"dt={self.dt:g} s"
        return (f"Compensator({self.form}, {timebase}, inputs={list(self.input_names)}, "
                f"outputs={list(self.output_names)})")

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(f"xhat_{s}" for s in self.plant_state_names)

    @property
    def input_names(self) -> tuple[str, ...]:
        return (
            tuple(f"u_{n}" for n in self.plant_input_names)
            + tuple(f"y_{n}" for n in self.measured_names)
            + tuple(f"r_{n}" for n in self.tracked_names)
        )

    @property
    def output_names(self) -> tuple[str, ...]:
        return self.plant_input_names

    @property
    def n_states(self) -> int:
        return len(self.plant_state_names)

    @property
    def is_discrete(self) -> bool:
        return self.dt is not None

    @property
    def poles(self) -> np.ndarray:
        """Eigenvalues of the compensator's ``A`` (with the ``u`` input left open)."""
        return np.linalg.eigvals(self.A)

    def output(self, xhat: object, u: object, y: object, r: object | None = None) -> np.ndarray:
        """``du = C xhat + D [du; dy; dr]`` (all in deviations)."""
        parts = [np.asarray(u, dtype=float).reshape(-1), np.asarray(y, dtype=float).reshape(-1)]
        if self.tracked_names:
            if r is None:
                raise DimensionError("this compensator has references: give r")
            parts.append(np.asarray(r, dtype=float).reshape(-1))
        w = np.concatenate(parts)
        du: np.ndarray = self.C @ np.asarray(xhat, dtype=float) + self.D @ w
        return du


def lqg_compensator(
    plant: LinearModel,
    K: object,
    Kf: object,
    Kc: object | None = None,
    *,
    tracked: Sequence[str] = (),
    form: str | None = None,
) -> Compensator:
    """Build the LQG compensator of *plant* (see the module docstring).

    Parameters
    ----------
    plant:
        Continuous or discrete :class:`LinearModel` with the measured outputs.
    K:
        State-feedback gain (``m x n``), ``u = -K xhat``.
    Kf:
        Estimator gain (``n x p``): ``lqe``'s gain for a continuous plant;
        ``M`` for the discrete ``"current"`` form, ``L = Ad M`` for
        ``"predictor"``.
    Kc:
        Reference gain (``m x m``), or None for no reference inputs.
    tracked:
        Names of the tracked outputs (among the plant's outputs), one per
        input, when *Kc* is given.
    form:
        ``"current"`` or ``"predictor"`` for a discrete plant (default
        ``"current"``); must be None (or ``"continuous"``) for a continuous one.
    """
    n, m, p = plant.n_states, plant.n_inputs, plant.n_outputs
    Km = checks.matrix(K, "K", (m, n), "one row per input, one column per state")
    Lm = checks.matrix(Kf, "Kf", (n, p), "one row per state, one column per output")
    if plant.dt is None:
        if form not in (None, "continuous"):
            raise DesignError(f"a continuous plant has no Kalman form {form!r}")
        kind = "continuous"
    else:
        kind = check_form("current" if form is None else form)
    tracked = tuple(tracked)
    if Kc is None:
        if tracked:
            raise DimensionError("tracked outputs given without a reference gain Kc")
        Kcm = np.zeros((m, 0))
        r0 = np.zeros(0)
    else:
        Kcm = checks.matrix(Kc, "Kc", (m, m), "one row and column per input")
        if len(tracked) != m:
            raise DimensionError(
                f"{len(tracked)} tracked outputs given, expected one per input ({m})"
            )
        missing = [t for t in tracked if t not in plant.output_names]
        if missing:
            raise DesignError(
                f"tracked output(s) {', '.join(missing)} are not outputs of the plant "
                f"({', '.join(plant.output_names)})"
            )
        rows = [plant.output_names.index(t) for t in tracked]
        r0 = plant.y0[rows]
    k = Kcm.shape[1]
    A, B, C, D = plant.A, plant.B, plant.C, plant.D
    zeros_r = np.zeros((n, k))
    sel = measured_states(C)
    Ez = Ey = None
    if kind != "continuous" and sel is not None and not np.any(D != 0):
        # The estimator's own arithmetic, read off as matrices.
        est = realize(A, B, Lm, sel, kind)
        Ez, Ey = est.Ez, est.Ey
        Ac = est.Ac
        Bc = np.hstack([est.Bu, est.By, zeros_r])
        if kind == "predictor":
            Cc = -Km
            Dc = np.hstack([np.zeros((m, m)), np.zeros((m, p)), Kcm])
        else:
            Cc = -fixed.matmul(Km, Ez)
            Dc = np.hstack([np.zeros((m, m)), -fixed.matmul(Km, Ey), Kcm])
    elif kind in ("continuous", "predictor"):
        Ac = A - fixed.matmul(Lm, C)
        Bc = np.hstack([B - fixed.matmul(Lm, D), Lm, zeros_r])
        Cc = -Km
        Dc = np.hstack([np.zeros((m, m)), np.zeros((m, p)), Kcm])
    else:
        if np.any(D != 0):
            raise DesignError("the current-form compensator needs a plant with D = 0")
        correct = np.eye(n) - fixed.matmul(Lm, C)
        Ac = fixed.matmul(A, correct)
        Bc = np.hstack([B, fixed.matmul(A, Lm), zeros_r])
        Cc = -fixed.matmul(Km, correct)
        Dc = np.hstack([np.zeros((m, m)), -fixed.matmul(Km, Lm), Kcm])
    return Compensator(
        A=Ac,
        B=Bc,
        C=Cc,
        D=Dc,
        plant_state_names=plant.state_names,
        plant_input_names=plant.input_names,
        measured_names=plant.output_names,
        tracked_names=tracked if Kc is not None else (),
        form=kind,
        dt=plant.dt,
        u0=np.asarray(plant.u0, dtype=float),
        y0=np.asarray(plant.y0, dtype=float),
        r0=r0,
        Ez=Ez,
        Ey=Ey,
    )

