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

The filter as it runs, sample by sample, is one source (:data:`ESTIMATOR_SOURCE`, the
:class:`Estimator` of :func:`estimator`), read by every consumer (docs/controllers.md, "The
estimator and the catch"); its covariances and gains (:func:`gain`, :func:`joseph`,
:func:`predict_covariance`) are written once below, in :mod:`equilibrist.control.fixed`'s order.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from equilibrist.control import checks, fixed
from equilibrist.control.riccati import current_gain, dlqe
from equilibrist.errors import DesignError, DimensionError, UnknownNameError, nearest
from equilibrist.numeric.linear import LinearModel

FORMS = ("current", "predictor")

#: The Kalman filter as it runs, one sample at a time: the source every consumer's controller
#: embeds (the C core and the exports translate it, :func:`estimator_namespace` runs it as
#: Python). The estimate is kept as the prediction ``z = xhat_{k|k-1}`` (``n`` values); a
#: filter measures ``ny`` states, output ``l`` the state ``sel[l]``. Arrays are the
#: controller's own (slices of its parameters and state), so one definition serves the
#: stationary filter (one gain) and the time-varying one (the gain of sample ``k``: the
#: caller passes that slice). ``current`` is 1 for the current form (the estimate used at
#: step k is corrected by ``y_k``: ``xhat = z + M (y - C z)``) and 0 for the predictor
#: (``xhat = z``, the correction ``L (y - C z)`` enters the next prediction). Every sum runs
#: in one written order; it is the order of the bits the recorded runs pin. No value is
#: updated in place (``v = v + ...``, never ``v += ...``): its Python form also runs on the
#: rows of a batch of estimates (numpy's element-wise operations, one per operation).
ESTIMATOR_SOURCE = '''
def kf_wrap(a):
    """*a* within half a turn of zero."""
    return a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))


def kf_innovation(l, z, y, sel, ref, wrap):
    """Output l's innovation y - C z: its measurement y[l], less the reference ref[j] of the
    state j it measures (where ref has values: a filter of deviations from a held point),
    wrapped to half a turn where wrap[j] is not 0, minus the prediction z[j]."""
    j = int(sel[l])
    d = y[l]
    if ref.shape[0] > 0:
        d = d - ref[j]
        if wrap[j] != 0.0:
            d = kf_wrap(d)
    return d - z[j]


def kf_estimate(i, z, y, gain, ny, sel, ref, wrap, current):
    """State i of the estimate the step uses: the prediction z[i], corrected in the current
    form by row i of the gain (n x ny) times the innovations, output by output."""
    x = z[i]
    if current != 0:
        for l in range(ny):
            x = x + gain[i * ny + l] * kf_innovation(l, z, y, sel, ref, wrap)
    return x


def kf_predict(i, acc, z, y, A, B, gain, n, m, ny, sel, ref, wrap, current, xr, u, ur):
    """State i of the next prediction: acc (the reference's own next value) plus row i of A
    (n x n) times the estimate's deviation from xr (none where xr is empty), plus row i of B
    (n x m) times the input's deviation u - ur, plus, in the predictor form, row i of the
    gain times the innovations."""
    v = acc
    for j in range(n):
        d = kf_estimate(j, z, y, gain, ny, sel, ref, wrap, current)
        if xr.shape[0] > 0:
            d = d - xr[j]
        v = v + A[i * n + j] * d
    for l in range(m):
        v = v + B[i * m + l] * (u[l] - ur[l])
    if current == 0:
        for l in range(ny):
            v = v + gain[i * ny + l] * kf_innovation(l, z, y, sel, ref, wrap)
    return v
'''

#: The functions an estimator's source defines (the consumers call them by these names).
ESTIMATOR_FUNCTIONS = ("kf_innovation", "kf_estimate", "kf_predict")


@dataclass(frozen=True)
class Estimator:
    """An estimator every consumer runs: its *source* defines :data:`ESTIMATOR_FUNCTIONS`
    with :data:`ESTIMATOR_SOURCE`'s signatures (in the subset :mod:`equilibrist.native.pyc`
    translates); *gain* is its gain rule, ``M = gain(P, C, Rd)`` from an a-priori covariance
    (the time-varying filters' gains along a plan are computed with it)."""

    name: str
    source: str
    gain: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def _kalman_gain(P: np.ndarray, C: np.ndarray, Rd: np.ndarray) -> np.ndarray:
    return gain(P, C, Rd)


#: The Kalman filter: the estimator every consumer runs unless told otherwise.
KALMAN = Estimator("kalman", ESTIMATOR_SOURCE, _kalman_gain)
_ACTIVE: list[Estimator] = [KALMAN]


def estimator() -> Estimator:
    """The estimator the consumers build with (:data:`KALMAN`, unless :func:`using_estimator`
    says otherwise)."""
    return _ACTIVE[-1]


@contextlib.contextmanager
def using_estimator(est: Estimator) -> Iterator[Estimator]:
    """Build every consumer (the LQG, the time-varying LQR's filter, the swing-up's
    hand-over, the MPC's filter, the identification's predictions) with *est* inside the
    block: the estimator is one definition, plugged in once."""
    _ACTIVE.append(est)
    try:
        yield est
    finally:
        _ACTIVE.remove(est)


_NAMESPACES: dict[str, dict[str, Any]] = {}


def estimator_namespace(source: str | None = None) -> dict[str, Any]:
    """An estimator's *source* (default :func:`estimator`'s) executed as plain Python: its
    functions by name, the same operations in the same order as the C the core runs."""
    text = estimator().source if source is None else source
    if text not in _NAMESPACES:
        ns: dict[str, Any] = {"math": math, "np": np}
        exec(compile(text, "<equilibrist estimator>", "exec"), ns)
        if len(_NAMESPACES) > 16:
            _NAMESPACES.clear()
        _NAMESPACES[text] = ns
    return _NAMESPACES[text]


@dataclass(frozen=True, eq=False)
class Realization:
    """An estimator's stationary filter as a linear map (deviations, ``z`` the prediction):
    ``xhat = Ez z + Ey dy`` and ``z+ = Ac z + By dy + Bu du``."""

    Ac: np.ndarray
    Bu: np.ndarray
    By: np.ndarray
    Ez: np.ndarray
    Ey: np.ndarray


def realize(Ad: object, Bd: object, Kf: object, sel: object, form: str,
            est: Estimator | None = None) -> Realization:
    """The stationary filter of *est* (default :func:`estimator`) as matrices: its
    ``kf_estimate`` and ``kf_predict`` run on each unit vector of ``z``, ``dy`` and ``du``
    (the others zero), so the LQG's linear form is that source's map, column by column.

    For the Kalman filter this is ``Ez = I - M C``, ``Ey = M``, ``Ac = Ad Ez``, ``By = Ad M``
    (current form) or ``Ez = I``, ``Ey = 0``, ``Ac = Ad - L C``, ``By = L`` (predictor),
    ``Bu = Bd``: the same sums in the same order as :mod:`equilibrist.control.fixed`'s
    products of those matrices (one output per state), so the same bits.
    """
    ns = estimator_namespace((est or estimator()).source)
    A = np.asarray(Ad, dtype=float)
    n = A.shape[0]
    B = np.asarray(Bd, dtype=float).reshape(n, -1)
    G = np.asarray(Kf, dtype=float).reshape(n, -1)
    m, ny = B.shape[1], G.shape[1]
    S = np.asarray(sel, dtype=float).reshape(ny)
    current = 1 if check_form(form) == "current" else 0
    empty, ur = np.zeros(0), np.zeros(m)
    a, b, g = A.reshape(-1), B.reshape(-1), G.reshape(-1)
    estimate, predict = ns["kf_estimate"], ns["kf_predict"]

    def columns(size: int, which: str) -> tuple[np.ndarray, np.ndarray]:
        xs, zs = np.zeros((n, size)), np.zeros((n, size))
        for c in range(size):
            z, y, u = np.zeros(n), np.zeros(ny), np.zeros(m)
            {"z": z, "y": y, "u": u}[which][c] = 1.0
            for i in range(n):
                xs[i, c] = estimate(i, z, y, g, ny, S, empty, empty, current)
                zs[i, c] = predict(i, 0.0, z, y, a, b, g, n, m, ny, S, empty, empty, current,
                                   empty, u, ur)
        return xs, zs

    Ez, Ac = columns(n, "z")
    Ey, By = columns(ny, "y")
    _, Bu = columns(m, "u")
    return Realization(Ac=Ac, Bu=Bu, By=By, Ez=Ez, Ey=Ey)


# -- the covariances and gains, once (control.fixed's order: the same bits on every CPU) ------
def gain(P: np.ndarray, C: np.ndarray, Rd: np.ndarray) -> np.ndarray:
    """``M = P C' (C P C' + Rd)^-1``: the current form's gain from an a-priori ``P``."""
    return current_gain(np.asarray(P, dtype=float), np.asarray(C, dtype=float),
                        np.asarray(Rd, dtype=float))


def joseph(P: np.ndarray, M: np.ndarray, C: np.ndarray, Rd: np.ndarray) -> np.ndarray:
    """The a-posteriori covariance for the gain *M* (Joseph form, symmetric and positive
    semidefinite for any gain): ``(I - M C) P (I - M C)' + M Rd M'``."""
    I_MC = np.eye(np.shape(P)[0]) - fixed.matmul(M, C)
    return fixed.symmetric(fixed.mm(I_MC, P, I_MC.T) + fixed.mm(M, Rd, np.asarray(M).T))


def predict_covariance(P: np.ndarray, Ad: np.ndarray, Qd: np.ndarray) -> np.ndarray:
    """The a-priori covariance of the next sample: ``Ad P Ad' + Qd``."""
    return fixed.symmetric(fixed.mm(Ad, P, np.asarray(Ad).T) + Qd)


def measured_states(C: np.ndarray) -> np.ndarray | None:
    """The state each output measures, where every row of *C* is one state itself (a one, the
    rest zeros); else None."""
    out = []
    for row in np.asarray(C, dtype=float):
        ones = np.flatnonzero(row == 1.0)
        if ones.size != 1 or np.count_nonzero(row) != 1:
            return None
        out.append(float(ones[0]))
    return np.array(out)


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
        P = predict_covariance(estimate.P, self.F, self.Qd)
        return Estimate(self._predicted(x, uu), P)

    # The state's arithmetic is the estimator's own source, run as Python on the rows of the
    # transposed estimates: numpy's element-wise operations, one per operation of the source,
    # so a batch of runs gets each run's bits at once.
    def _predicted(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        predict = estimator_namespace()["kf_predict"]
        n, m = self.n_states, len(self.input_names)
        empty = np.zeros(0)
        rows = [predict(i, 0.0, x.T, empty, self.F.reshape(-1), self.B.reshape(-1), empty, n,
                        m, 0, empty, empty, empty, 1, empty, u.T, np.zeros(m))
                for i in range(n)]
        return np.stack(np.broadcast_arrays(*rows), axis=-1)

    def _corrected(self, x: np.ndarray, y: np.ndarray, u: np.ndarray | None,
                   M: np.ndarray) -> np.ndarray:
        estimate = estimator_namespace()["kf_estimate"]
        n, p = self.n_states, len(self.output_names)
        sel = measured_states(self.H) if not np.any(self.D != 0) else None
        if sel is not None:
            z = x.T
        else:  # outputs that are not states: the filter measures H x + D u, predicted here
            Hx = x @ self.H.T if u is None else x @ self.H.T + u @ self.D.T
            z = np.concatenate([x.T, Hx.T])
            sel = n + np.arange(p, dtype=float)
        empty = np.zeros(0)
        rows = [estimate(i, z, y.T, M.reshape(-1), p, sel, empty, empty, 1) for i in range(n)]
        return np.stack(np.broadcast_arrays(*rows), axis=-1)

    def gain(self, P_prior: np.ndarray) -> np.ndarray:
        """``M = P H' (H P H' + Rd)^-1`` for an a-priori covariance ``P``."""
        return gain(P_prior, self.H, self.Rd)

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
        uu = None
        if np.any(self.D != 0):
            if u is None:
                raise DimensionError("this plant has D != 0: update needs u")
            uu = self._vec(u, len(self.input_names), "u")
        M = self.gain(estimate.P) if gain is None else np.asarray(gain, dtype=float)
        return Estimate(self._corrected(x, yy, uu, M), joseph(estimate.P, M, self.H, self.Rd))

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
        return SteadyStateGains(P, joseph(P, M, self.H, self.Rd), M, L, E)

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
