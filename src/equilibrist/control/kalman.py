"""The discrete Kalman filter (seeds/002, "Discrete Kalman filter").

For ``x_k = F x_{k-1} + B u_{k-1} + w``, ``y_k = H x_k + D u_k + v`` with
``cov(w) = Qd`` and ``cov(v) = Rd``:

predict
    ``xhat_{k|k-1} = F xhat_{k-1|k-1} + B u_{k-1}``,
    ``P_{k|k-1} = F P_{k-1|k-1} F' + Qd``
update
    ``S = H P H' + Rd``, ``M = P H' S^-1``,
    ``xhat_{k|k} = xhat_{k|k-1} + M (y_k - H xhat_{k|k-1} - D u_k)``,
    ``P_{k|k} = (I - M H) P (I - M H)' + M Rd M'`` (Joseph form: symmetric
    and positive semidefinite for any gain, unlike ``(I - M H) P``).

Two forms, named:

``"current"`` (filter form)
    One step is predict-then-update: the estimate used at step ``k`` is
    ``xhat_{k|k}``, which already contains ``y_k``. Its covariance is the
    a-posteriori ``P_{k|k}``. Requires ``D = 0`` (the measurement may not
    depend on the input it is used to compute).
``"predictor"``
    One step is update-then-predict: the estimate used at step ``k`` is
    ``xhat_{k|k-1}``, computed before ``y_k`` arrives (a full period for the
    computation). With the steady gain this is
    ``xhat_{k+1} = F xhat_k + B u_k + L (y_k - H xhat_k - D u_k)``,
    ``L = F M``. Its covariance is the a-priori ``P_{k|k-1}``.

The filter holds no state: every method takes an :class:`Estimate` and
returns a new one. Estimates may be batched: ``x`` of shape ``(n,)`` or
``(n_runs, n)`` (with inputs and measurements batched the same way); the
covariance does not depend on the data and is shared.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from equilibrist.control import checks
from equilibrist.control.riccati import current_gain, dlqe
from equilibrist.errors import DesignError, DimensionError, UnknownNameError, nearest
from equilibrist.numeric.linear import LinearModel

FORMS = ("current", "predictor")


def check_form(form: str) -> str:
    if form not in FORMS:
        raise DesignError(f"Kalman form {form!r} is unknown: expected one of {', '.join(FORMS)}")
    return form


@dataclass(frozen=True, eq=False)
class Estimate:
    """A state estimate ``x`` (``(n,)`` or ``(n_runs, n)``) and its error covariance ``P``."""

    x: np.ndarray
    P: np.ndarray


@dataclass(frozen=True, eq=False)
class SteadyStateGains:
    """The constant gains the filter converges to.

    Attributes
    ----------
    P_prior:
        Steady a-priori covariance ``P_{k|k-1}`` (the discrete Riccati solution).
    P_posterior:
        Steady a-posteriori covariance ``P_{k|k} = (I - M H) P_prior``.
    M:
        Current-form gain ``P_prior H' (H P_prior H' + Rd)^-1``.
    L:
        Predictor-form gain ``F M``.
    poles:
        Eigenvalues of ``F - L H`` (the same for both forms).
    """

    P_prior: np.ndarray
    P_posterior: np.ndarray
    M: np.ndarray
    L: np.ndarray
    poles: np.ndarray


@dataclass(frozen=True, eq=False)
class KalmanRun:
    """The estimates of :meth:`DiscreteKalmanFilter.run`, time-major.

    ``x[k]`` is the estimate used at step ``k`` (``xhat_{k|k}`` for the
    current form, ``xhat_{k|k-1}`` for the predictor form) and ``P[k]`` its
    covariance.
    """

    x: np.ndarray
    P: np.ndarray
    form: str
    state_names: tuple[str, ...]

    def state(self, name: str) -> np.ndarray:
        if name not in self.state_names:
            raise UnknownNameError(f"unknown state {name!r}: {nearest(name, self.state_names)}")
        return self.x[:, self.state_names.index(name)]


@dataclass(frozen=True, eq=False)
class DiscreteKalmanFilter:
    """A discrete Kalman filter for a sampled linear plant.

    Build it with :meth:`from_model`, or with the matrices directly. All
    quantities are in deviation coordinates about the plant's operating
    point.

    Attributes
    ----------
    F, B, H, D:
        Discrete plant (``n x n``, ``n x m``, ``p x n``, ``p x m``).
    Qd, Rd:
        Per-sample covariances of the process and measurement noises.
    dt:
        Sample period [s].
    form:
        ``"current"`` or ``"predictor"`` (see the module docstring).
    """

    F: np.ndarray
    B: np.ndarray
    H: np.ndarray
    D: np.ndarray
    Qd: np.ndarray
    Rd: np.ndarray
    dt: float
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    form: str = "current"

    def __post_init__(self) -> None:
        check_form(self.form)
        n, m, p = len(self.state_names), len(self.input_names), len(self.output_names)
        fields = (
            ("F", (n, n), "one row and column per state"),
            ("B", (n, m), "one row per state, one column per input"),
            ("H", (p, n), "one row per output, one column per state"),
            ("D", (p, m), "one row per output, one column per input"),
            ("Qd", (n, n), "one row and column per state"),
            ("Rd", (p, p), "one row and column per output"),
        )
        for name, shape, meaning in fields:
            object.__setattr__(
                self, name, checks.matrix(getattr(self, name), name, shape, meaning)
            )
        object.__setattr__(self, "dt", checks.positive_period(self.dt))
        checks.raise_if(
            checks.weight_problems(self.Qd, "Qd", definite=False)
            + checks.weight_problems(self.Rd, "Rd", definite=True)
        )
        if self.form == "current" and np.any(self.D != 0):
            raise DesignError(
                "the current form needs D = 0: its update uses y_k before u_k is computed; "
                "use the predictor form"
            )

    @classmethod
    def from_model(
        cls, model: LinearModel, Qd: object, Rd: object, *, form: str = "current"
    ) -> DiscreteKalmanFilter:
        """The filter of a discrete :class:`LinearModel` with noise covariances ``Qd, Rd``."""
        if model.dt is None:
            raise DesignError(
                "a discrete Kalman filter needs a discrete model: discretize it first"
            )
        return cls(
            F=model.A,
            B=model.B,
            H=model.C,
            D=model.D,
            Qd=Qd,  # type: ignore[arg-type]  # checked and converted in __post_init__
            Rd=Rd,  # type: ignore[arg-type]  # checked and converted in __post_init__
            dt=model.dt,
            state_names=model.state_names,
            input_names=model.input_names,
            output_names=model.output_names,
            form=form,
        )

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    # -- one step ------------------------------------------------------------------
    def _vec(self, value: object, n: int, what: str) -> np.ndarray:
        arr = np.asarray(value, dtype=float)
        if arr.shape[-1:] != (n,):
            raise DimensionError(f"{what} has shape {arr.shape}, expected (..., {n})")
        return arr

    def predict(self, estimate: Estimate, u: object) -> Estimate:
        """``x = F x + B u``, ``P = F P F' + Qd``."""
        x = self._vec(estimate.x, self.n_states, "the estimate")
        uu = self._vec(u, len(self.input_names), "u")
        P = self.F @ estimate.P @ self.F.T + self.Qd
        return Estimate(x @ self.F.T + uu @ self.B.T, checks.symmetric(P))

    def gain(self, P_prior: np.ndarray) -> np.ndarray:
        """``M = P H' (H P H' + Rd)^-1`` for an a-priori covariance ``P``."""
        return current_gain(np.asarray(P_prior, dtype=float), self.H, self.Rd)

    def update(
        self,
        estimate: Estimate,
        y: object,
        *,
        u: object | None = None,
        gain: np.ndarray | None = None,
    ) -> Estimate:
        """Correct an a-priori estimate with the measurement *y* (Joseph form).

        Parameters
        ----------
        estimate:
            ``xhat_{k|k-1}`` and ``P_{k|k-1}``.
        y:
            The measurement ``y_k`` (deviation from the operating outputs).
        u:
            ``u_k``, needed only when ``D`` is not zero.
        gain:
            A fixed gain to use instead of the optimal one (the steady ``M``);
            the covariance is still propagated exactly for that gain.
        """
        x = self._vec(estimate.x, self.n_states, "the estimate")
        yy = self._vec(y, len(self.output_names), "y")
        innovation = yy - x @ self.H.T
        if np.any(self.D != 0):
            if u is None:
                raise DimensionError("this plant has D != 0: update needs u")
            innovation = innovation - self._vec(u, len(self.input_names), "u") @ self.D.T
        M = self.gain(estimate.P) if gain is None else np.asarray(gain, dtype=float)
        I_MH = np.eye(self.n_states) - M @ self.H
        P = I_MH @ estimate.P @ I_MH.T + M @ self.Rd @ M.T
        return Estimate(x + innovation @ M.T, checks.symmetric(P))

    def step(self, estimate: Estimate, *, u: object, y: object, steady: bool = False) -> Estimate:
        """One period of the filter in its form.

        ``"current"``: *estimate* is ``xhat_{k-1|k-1}``, *u* is ``u_{k-1}``
        and *y* is ``y_k``; returns ``xhat_{k|k}``.
        ``"predictor"``: *estimate* is ``xhat_{k|k-1}``, *u* is ``u_k`` and
        *y* is ``y_k``; returns ``xhat_{k+1|k}``.
        With *steady*, the steady-state gain is used.
        """
        gain = self.steady_state.M if steady else None
        if self.form == "current":
            return self.update(self.predict(estimate, u), y, gain=gain)
        return self.predict(self.update(estimate, y, u=u, gain=gain), u)

    # -- steady state ----------------------------------------------------------------
    @cached_property
    def steady_state(self) -> SteadyStateGains:
        """The steady-state covariances and gains of both forms."""
        L, P, E = dlqe(
            self.F,
            np.eye(self.n_states),
            self.H,
            self.Qd,
            self.Rd,
            state_names=self.state_names,
            output_names=self.output_names,
        )
        M = self.gain(P)
        I_MH = np.eye(self.n_states) - M @ self.H
        post = checks.symmetric(I_MH @ P @ I_MH.T + M @ self.Rd @ M.T)
        return SteadyStateGains(P, post, M, L, E)

    @property
    def steady_gain(self) -> np.ndarray:
        """The gain of this form: ``M`` (current) or ``L = F M`` (predictor)."""
        gains = self.steady_state
        return gains.M if self.form == "current" else gains.L

    @property
    def steady_covariance(self) -> np.ndarray:
        """This form's covariance: a-posteriori (current) or a-priori (predictor)."""
        gains = self.steady_state
        return gains.P_posterior if self.form == "current" else gains.P_prior

    # -- a whole record ------------------------------------------------------------
    def run(
        self,
        y: object,
        u: object,
        *,
        x0: object | None = None,
        P0: object | None = None,
        steady: bool = False,
    ) -> KalmanRun:
        """Filter a record of measurements and inputs.

        Parameters
        ----------
        y:
            ``(n_steps, p)`` measurements, ``y[k] = y_k``.
        u:
            ``(n_steps, m)`` inputs, ``u[k]`` applied at step ``k`` (after
            ``y_k`` is measured).
        x0, P0:
            Prior of the state at step 0 (``xhat_{0|-1}``, ``P_{0|-1}``);
            default zero and the steady a-priori covariance.
        steady:
            Use the steady-state gain throughout.

        Returns
        -------
        KalmanRun
            ``x[k]``, ``P[k]``: the estimate used at step ``k`` in this form.
        """
        n, m, p = self.n_states, len(self.input_names), len(self.output_names)
        ys = np.asarray(y, dtype=float)
        us = np.asarray(u, dtype=float)
        if ys.ndim != 2 or ys.shape[1] != p:
            raise DimensionError(f"y has shape {ys.shape}, expected (n_steps, {p})")
        if us.shape != (ys.shape[0], m):
            raise DimensionError(f"u has shape {us.shape}, expected ({ys.shape[0]}, {m})")
        prior = Estimate(
            np.zeros(n) if x0 is None else checks.matrix(np.reshape(np.asarray(x0), (1, -1)), "x0", (1, n))[0],
            self.steady_state.P_prior if P0 is None else checks.matrix(P0, "P0", (n, n)),
        )
        steps = ys.shape[0]
        xs = np.empty((steps, n))
        Ps = np.empty((steps, n, n))
        gain = self.steady_state.M if steady else None
        if self.form == "current":
            est = self.update(prior, ys[0], gain=gain) if steps else prior
            for k in range(steps):
                if k:
                    est = self.update(self.predict(est, us[k - 1]), ys[k], gain=gain)
                xs[k], Ps[k] = est.x, est.P
        else:
            est = prior
            for k in range(steps):
                xs[k], Ps[k] = est.x, est.P
                est = self.predict(self.update(est, ys[k], u=us[k], gain=gain), us[k])
        return KalmanRun(xs, Ps, self.form, self.state_names)
