"""Grey-box identification of physical parameters: multiple shooting, then prediction error.

The model is the system's own derived ``x_dot = f(x, u; p)``; the chosen free
parameters (and, optionally, a constant offset per sensor) are fitted to a
log with :func:`scipy.optimize.least_squares`, in two stages.

The start: multiple shooting. The balancing systems are unstable and their
logs are closed-loop: replaying the logged input open loop from one initial
state diverges within a second, whatever the parameters. The log is cut into
segments of a fraction of a second; each segment's initial state is a
decision variable, the segment is integrated with the logged input held
between samples (zero-order hold, as the rig applied it), and the residuals
are

- the output errors ``(y_k - y_hat_k - offset) / sigma_y`` at every sample,
- the continuity defects ``x_{s+1} - x_end,s`` where one segment ends and the
  next starts, whitened by the covariance the process noise builds over a
  segment (``Q_seg``, from the linearization by Van Loan's method).

Segments are kept short: by default as long as the process noise moves the
outputs by at most half a sensor standard deviation over one segment, at
least 5 samples. The noise levels start from the system's spec (sensor and
process noise) and are re-estimated after a first fit: each sensor's
variance from its residuals over their redundancy (rows minus leverage), the
process noise's scale as the one that makes the fitted model's Kalman filter
most likely; then the fit is repeated. This stage converges from far (the
segments never diverge), and gives the second its start and noise levels.

The estimate: prediction error. Multiple shooting is not the estimate,
because it is biased where process noise matters: the noise acting inside a
segment is not in its model (it is lumped at the segment's end), so the
output errors inside a segment carry it, and in closed loop the logged input
answers that same noise through the controller. The input the fit regresses
on is then correlated with its residuals, and the parameters absorb the
correlation (on the control-moment-gyroscope robot, whose process noise is
large, the body's mass came out 1.7 standard errors high on average over 20
logs; with 1-sample segments, 0.9 over 6 logs: shorter segments do not remove it, as the
joint estimate of states and parameters is not the likelihood of the
parameters). The second stage minimizes the one-step prediction errors of a
Kalman filter of the model instead: the nonlinear model predicts over each
sample interval (RK4, the input held), the steady-state gain of its
linearization at the current parameters (and the current noise levels)
corrects; the decision variables are the parameters, the offsets and the
filter's initial state. The errors are weighted by their covariance (held
fixed during a fit) and, at the true parameters, are white whatever the
feedback: this is the prediction-error (innovations) form of the likelihood,
consistent in closed loop. The noise levels (a scale of the process noise,
each sensor's standard deviation) are then set to those that make the
filter's errors most likely (their Gaussian likelihood, Nelder-Mead) and the
fit is repeated until they settle.

Integration: RK4 with the input held, at most ``max_step`` per step (1 ms by
default, as the simulator), compiled in the system's C core over its generated
``f`` (:mod:`equilibrist.ident.kernel`); ``backend="solve_ivp"`` runs the same
loops with :func:`scipy.integrate.solve_ivp` (for comparison). The Jacobians
are by central differences: for the shooting residuals all segments at once
(segments are independent given their initial states), assembled sparse; for
the filter's errors one column at a time (a handful of decision variables).

Whiteness: a Ljung-Box test of the final filter's prediction errors, per
output. White errors say the model and its noise levels explain the data.

Uncertainty: the covariance of the decision variables is ``s^2 (J' J)^-1``
at the solution (``J`` the Jacobian of the weighted prediction errors, ``s^2``
their variance); the filter's initial state is eliminated (Schur complement)
to give the parameters' covariance, their standard errors and correlations.
Directions the data cannot tell apart are found from the eigen-decomposition
of that information matrix in log-parameters, where a product or ratio
structure (``m_p`` and ``l`` entering only as ``m_p*l``) is a null direction
with entries ``(1, -1)``.

The replay (NRMSE, the plot) is the shooting segments' integration from
their states at the final parameters.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from equilibrist.errors import EquilibristError, nearest
from equilibrist.ident.log import IdentificationError, Log
from equilibrist.numeric.system import System

BACKENDS = ("compiled", "solve_ivp")
# The longest RK4 step [s] (the simulator's default physics step).
DEFAULT_MAX_STEP = 1e-3
# Segment length rule: process noise may move an output by this fraction of
# the sensor variance over one segment.
SEGMENT_NOISE_RATIO = 0.25
# The shortest default segment, in samples: shorter ones multiply the
# decision variables for little gain where the sensors are far finer than
# the process noise.
MIN_SEGMENT_SAMPLES = 5
MAX_SEGMENT_SECONDS = 1.0
# RK4 steps per sample of the log at most (the --max-step it accepts is the longest sample
# over this): the replay's work grows with them, and no rig's log needs more.
MAX_SUBSTEPS = 1000
# RK4 steps of one call of the compiled integrator at most (a few tens of ms): Ctrl-C
# is answered between calls.
CALL_STEPS = 1_000_000
# A log-parameter direction whose information is below this fraction of the
# largest is not determined at all; one whose standard deviation exceeds
# WEAK_LOG_STD (50 % relative) is not determined by this log.
STRUCTURAL_RATIO = 1e-9
WEAK_LOG_STD = 0.5
# Lags of the Ljung-Box whiteness test, and its level.
WHITENESS_LAGS = 20
WHITENESS_LEVEL = 0.05
# Rounds of noise re-estimation (each followed by a fit).
NOISE_PASSES = 3
FORMAT = "equilibrist-params-1"

ShootFunction = Callable[..., None]


@dataclass(frozen=True)
class Estimate:
    """One fitted quantity: value, standard error, start value and unit."""

    name: str
    value: float
    std_error: float
    start: float
    unit: str

    @property
    def relative_error(self) -> float:
        """Standard error over estimate (infinite for an estimate at zero)."""
        if abs(self.value) <= 1e-9 * max(abs(self.std_error), abs(self.start), 1e-300):
            return math.inf
        return abs(self.std_error / self.value)


@dataclass(frozen=True)
class OutputFit:
    """Fit quality of one measured output."""

    name: str
    unit: str
    nrmse: float
    rms_residual: float
    sensor_std: float
    ljung_box_q: float
    ljung_box_p: float
    lags: int

    @property
    def fit_percent(self) -> float:
        return 100.0 * (1.0 - self.nrmse)

    @property
    def white(self) -> bool:
        return self.ljung_box_p >= WHITENESS_LEVEL


@dataclass(frozen=True, eq=False)
class Identification:
    """The answer of :func:`identify`.

    Attributes
    ----------
    system : str
        The system's key.
    params : mapping
        Every parameter of the system, the free ones at their estimates.
    estimates : tuple of Estimate
        The free parameters, then the sensor offsets (``offset_<output>``).
    correlation : ndarray
        Correlation matrix of the estimates, in their order.
    unidentifiable : tuple of str
        The directions the data cannot tell apart, in words.
    warnings : tuple of str
        Everything that makes a number less trustworthy.
    outputs : tuple of OutputFit
        NRMSE and the whiteness test of each measured output.
    time, measured, replayed : ndarray
        The log's times, its measurements and the fitted model's replay
        (each segment from its estimated initial state).
    segment_starts : ndarray
        The sample index where each segment starts.
    method : mapping
        How the fit was made (JSON-able).
    """

    system: str
    params: Mapping[str, float]
    free: tuple[str, ...]
    estimates: tuple[Estimate, ...]
    correlation: np.ndarray
    unidentifiable: tuple[str, ...]
    warnings: tuple[str, ...]
    outputs: tuple[OutputFit, ...]
    output_names: tuple[str, ...]
    time: np.ndarray
    measured: np.ndarray
    replayed: np.ndarray
    segment_starts: np.ndarray
    initial_state: Mapping[str, float]
    method: Mapping[str, Any]
    source: str = ""
    noise: Mapping[str, Any] = field(default_factory=dict)

    def estimate(self, name: str) -> Estimate:
        for e in self.estimates:
            if e.name == name:
                return e
        raise IdentificationError(f"no estimate {name!r}: {nearest(name, [e.name for e in self.estimates])}")

    def to_dict(self) -> dict[str, Any]:
        """Everything as JSON-able data (``--json``)."""
        names = [e.name for e in self.estimates]
        return {
            "system": self.system,
            "log": self.source,
            "method": dict(self.method),
            "estimates": {
                e.name: {"value": e.value, "std_error": _finite_or_none(e.std_error),
                         "relative_error": _finite_or_none(e.relative_error),
                         "start": e.start, "unit": e.unit}
                for e in self.estimates
            },
            "correlation": {"names": names, "matrix": self.correlation.tolist()},
            "unidentifiable": list(self.unidentifiable),
            "warnings": list(self.warnings),
            "outputs": {
                o.name: {"nrmse": o.nrmse, "fit_percent": o.fit_percent,
                         "rms_residual": o.rms_residual, "sensor_std": o.sensor_std,
                         "unit": o.unit,
                         "whiteness": {"test": "Ljung-Box", "lags": o.lags, "q": o.ljung_box_q,
                                       "p_value": o.ljung_box_p, "white": o.white,
                                       "level": WHITENESS_LEVEL}}
                for o in self.outputs
            },
            "initial_state": dict(self.initial_state),
            "noise": dict(self.noise),
            "params": dict(self.params),
        }

    def params_document(self) -> dict[str, Any]:
        """What ``--out params.json`` holds (read back by ``--params``)."""
        return {
            "format": FORMAT,
            "system": self.system,
            "params": dict(self.params),
            "identified": {e.name: {"value": e.value, "std_error": _finite_or_none(e.std_error)}
                           for e in self.estimates if e.name in self.free},
            "log": self.source,
            "method": self.method.get("name"),
        }

    def summary(self) -> str:
        """A report for people."""
        m = self.method
        lines = [
            f"{self.system}: {len(self.free)} parameter{'s' if len(self.free) != 1 else ''} "
            f"identified from {self.source or 'the log'} ({m['samples']} samples, "
            f"{m['duration']:g} s; outputs {', '.join(self.output_names)})",
            f"method: {m['description']}",
            "",
        ]
        rows = []
        for e in self.estimates:
            rel = "-" if not math.isfinite(e.relative_error) else f"{100 * e.relative_error:.2g} %"
            se = "not determined" if not math.isfinite(e.std_error) else f"{e.std_error:.4g}"
            rows.append((e.name, f"{e.value:.6g}", se, rel, f"{e.start:.6g}", e.unit))
        lines.append(_table(("estimate", "value", "std error", "relative", "start", "unit"), rows))
        if len(self.estimates) > 1:
            lines += ["", "correlation:"]
            names = [e.name for e in self.estimates]
            width = max(len(n) for n in names)
            col = max(10, width + 2)
            lines.append(" " * (width + 2) + "".join(f"{n:>{col}}" for n in names))
            for n, row in zip(names, self.correlation, strict=True):
                lines.append(f"  {n:<{width}}" + "".join(
                    f"{v:>{col}.3f}" if math.isfinite(v) else f"{'-':>{col}}" for v in row))
        lines += ["", "fit per output (replayed segment by segment):"]
        rows = [(o.name, f"{o.nrmse:.4f}", f"{o.fit_percent:.1f} %", f"{o.rms_residual:.3g} {o.unit}",
                 f"{o.sensor_std:.3g} {o.unit}",
                 f"Q({o.lags}) = {o.ljung_box_q:.1f}, p = {o.ljung_box_p:.3f}: "
                 f"{'white' if o.white else 'NOT white'}")
                for o in self.outputs]
        lines.append(_table(("output", "NRMSE", "fit", "residual rms", "sensor std",
                             "whiteness (Ljung-Box)"), rows))
        if self.unidentifiable:
            lines += ["", "not identifiable from this log:"]
            lines += [f"  - {w}" for w in self.unidentifiable]
        if self.warnings:
            lines += ["", "warnings:"]
            lines += [f"  - {w}" for w in self.warnings]
        return "\n".join(lines)


def _finite_or_none(v: float) -> float | None:
    return float(v) if math.isfinite(v) else None


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    cells = [list(header)] + [list(r) for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(header))]
    out = []
    for k, r in enumerate(cells):
        out.append("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip())
        if k == 0:
            out.append("  ".join("-" * w for w in widths))
    return "\n".join(out)


# -- the problem ------------------------------------------------------------------


def check_free(system: System, free: Sequence[str]) -> tuple[str, ...]:
    """The free parameter names, checked (every problem at once)."""
    physical = [p.name for p in system.spec.parameters]
    limits = [n for n in system.spec.parameter_names if n not in physical]
    problems = []
    seen: list[str] = []
    for name in free:
        if name in limits:
            problems.append(f"{name} is an input limit, not a parameter of the dynamics")
        elif name not in physical:
            problems.append(f"unknown parameter {name!r} of {system.key}: {nearest(name, physical)}")
        elif name in seen:
            problems.append(f"parameter {name} is free twice")
        else:
            seen.append(name)
    if problems:
        raise IdentificationError("; ".join(problems))
    if not seen:
        raise IdentificationError(
            f"no free parameter: name the parameters to fit ({', '.join(physical)})"
        )
    return tuple(seen)


def _van_loan(A: np.ndarray, GQG: np.ndarray, T: float) -> np.ndarray:
    """``int_0^T e^(A s) GQG e^(A' s) ds``."""
    return _discretize(A, GQG, T)[1]


def _discretize(A: np.ndarray, GQG: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    """``e^(A T)`` and ``int_0^T e^(A s) GQG e^(A' s) ds`` (Van Loan: one exponential)."""
    from scipy.linalg import expm

    n = A.shape[0]
    M = np.zeros((2 * n, 2 * n))
    M[:n, :n] = -A
    M[:n, n:] = GQG
    M[n:, n:] = A.T
    E = expm(M * T)
    Ad = E[n:, n:].T
    Q = Ad @ E[:n, n:]
    return Ad, (Q + Q.T) / 2


def _guess_states(system: System, log: Log) -> np.ndarray:
    """A state trajectory to start from: measured states as logged, rates of measured
    coordinates by a smoothed derivative, the rest at the operating point."""
    from scipy.signal import savgol_filter

    n_rows = log.n_rows
    try:
        base = np.array(system.operating_point().x)
    except EquilibristError:  # a system without an operating point starts at zero
        base = np.zeros(system.n_states)
    x = np.tile(base, (n_rows, 1))
    dt = float(np.median(np.diff(log.time)))
    for j, name in enumerate(log.output_names):
        x[:, system.state_index(name)] = log.outputs[:, j]
    for j, name in enumerate(log.output_names):
        rate = f"{name}_dot"
        if rate in system.state_names and rate not in log.output_names:
            y = log.outputs[:, j]
            window = min(n_rows - (1 - n_rows % 2), 11)
            if window >= 5:
                d = savgol_filter(y, window, 2, deriv=1, delta=dt)
            else:
                d = np.gradient(y, log.time)
            x[:, system.state_index(rate)] = d
    return x


@dataclass
class _Unknowns:
    """What both fits share: the decision vector's head (the free parameters, then the
    sensor offsets with ``offsets``) and the parameter vector it sets."""

    system: System
    log: Log
    free_idx: np.ndarray
    offsets: bool
    p_base: np.ndarray
    c_idx: np.ndarray
    n_sub: np.ndarray
    sigma_y: np.ndarray

    @property
    def n(self) -> int:
        return self.system.n_states

    @property
    def ny(self) -> int:
        return self.c_idx.shape[0]

    @property
    def n_theta(self) -> int:
        return len(self.free_idx)

    @property
    def n_off(self) -> int:
        return self.ny if self.offsets else 0

    @property
    def n_head(self) -> int:
        return self.n_theta + self.n_off

    def head(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(theta, offsets, rest)`` of a decision vector (zero offsets without ``offsets``)."""
        theta = z[: self.n_theta]
        off = z[self.n_theta : self.n_head] if self.offsets else np.zeros(self.ny)
        return theta, off, z[self.n_head :]

    def p_of(self, theta: np.ndarray) -> np.ndarray:
        p = self.p_base.copy()
        p[self.free_idx] = theta
        return p


@dataclass
class _Problem(_Unknowns):
    """Multiple shooting: the head, then the state at the start of each segment."""

    free: tuple[str, ...]
    bounds: np.ndarray
    W: np.ndarray  # (n_seg - 1, n, n) whitening of the defects
    shoot: ShootFunction
    step_theta: np.ndarray
    step_x: np.ndarray
    cache: dict[str, Any] = field(default_factory=dict)

    @property
    def n_seg(self) -> int:
        return self.bounds.shape[0] - 1

    def split(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        theta, off, rest = self.head(z)
        return theta, off, rest.reshape(self.n_seg, self.n)

    def run(self, P: np.ndarray, XS: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every segment for each case, in calls of at most :data:`CALL_STEPS` RK4 steps.

        Ctrl-C reaches Python only between calls of the compiled loop: so
        the cases go one by one and their segments in runs of bounded work,
        in order (a run's last row is its next run's first, written again
        there). Each segment's arithmetic is the same however they are grouped.
        """
        from equilibrist import interrupt

        K = P.shape[0]
        yhat = np.empty((K, self.log.n_rows, self.ny))
        xend = np.empty((K, self.n_seg, self.n))
        P = np.ascontiguousarray(P)
        for c in range(K):
            for a, b in self.runs_of_segments():
                ends = np.empty((1, b - a, self.n))
                self.shoot(P[c:c + 1], np.ascontiguousarray(XS[c:c + 1, a:b]),
                           np.ascontiguousarray(self.bounds[a:b + 1]), self.log.time,
                           self.log.inputs, self.n_sub, self.c_idx, yhat[c:c + 1], ends)
                xend[c, a:b] = ends[0]
                interrupt.raise_if_requested()  # one a finalizer swallowed
        return yhat, xend

    def runs_of_segments(self) -> list[tuple[int, int]]:
        """Consecutive segments ``[a, b)`` of at most :data:`CALL_STEPS` RK4 steps (one at least)."""
        per_row = np.concatenate([[0], np.cumsum(self.n_sub)])
        seg_steps = per_row[self.bounds[1:]] - per_row[self.bounds[:-1]]
        out, a, total = [], 0, 0
        for s, steps in enumerate(seg_steps):
            if s > a and total + steps > CALL_STEPS:
                out.append((a, s))
                a, total = s, 0
            total += int(steps)
        out.append((a, self.n_seg))
        return out

    def residual_parts(self, yhat: np.ndarray, xend: np.ndarray, off: np.ndarray,
                       xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ry = (self.log.outputs - yhat - off) / self.sigma_y
        d = xs[1:] - xend[:-1]
        rd = np.einsum("sij,sj->si", self.W, d)
        return ry, rd

    def residuals(self, z: np.ndarray) -> np.ndarray:
        theta, off, xs = self.split(z)
        yhat, xend = self.run(self.p_of(theta)[None, :], xs[None])
        ry, rd = self.residual_parts(yhat[0], xend[0], off, xs)
        r = np.concatenate([ry.ravel(), rd.ravel()])
        return np.where(np.isfinite(r), r, 1e10)

    def jacobian(self, z: np.ndarray) -> Any:
        from scipy.sparse import coo_matrix

        theta, _off, xs = self.split(z)
        nt, n, ny, S = self.n_theta, self.n, self.ny, self.n_seg
        N = self.log.n_rows
        p0 = self.p_of(theta)
        K = 2 * nt + 2 * n
        P = np.tile(p0, (K, 1))
        XS = np.tile(xs, (K, 1, 1))
        ht = self.step_theta * np.maximum(np.abs(theta), 1.0)
        for a in range(nt):
            P[2 * a, self.free_idx[a]] += ht[a]
            P[2 * a + 1, self.free_idx[a]] -= ht[a]
        hx = self.step_x
        for i in range(n):
            XS[2 * nt + 2 * i, :, i] += hx[i]
            XS[2 * nt + 2 * i + 1, :, i] -= hx[i]
        yhat, xend = self.run(P, XS)
        dy_t = (yhat[0:2 * nt:2] - yhat[1:2 * nt:2]) / (2 * ht)[:, None, None]  # (nt, N, ny)
        dx_t = (xend[0:2 * nt:2] - xend[1:2 * nt:2]) / (2 * ht)[:, None, None]  # (nt, S, n)
        dy_x = (yhat[2 * nt::2] - yhat[2 * nt + 1::2]) / hx[:, None, None] / 2  # (n, N, ny)
        dx_x = (xend[2 * nt::2] - xend[2 * nt + 1::2]) / hx[:, None, None] / 2  # (n, S, n)
        rows, cols, vals = [], [], []
        n_out = N * ny
        r_out = np.arange(n_out).reshape(N, ny)
        # Output rows.
        for a in range(nt):
            rows.append(r_out.ravel())
            cols.append(np.full(n_out, a))
            vals.append((-dy_t[a] / self.sigma_y).ravel())
        if self.offsets:
            for j in range(ny):
                rows.append(r_out[:, j])
                cols.append(np.full(N, nt + j))
                vals.append(np.full(N, -1.0 / self.sigma_y[j]))
        seg_of = np.repeat(np.arange(S), np.diff(self.bounds))
        seg_of = np.concatenate([seg_of, [S - 1]])  # the last sample, from the last segment's end
        for i in range(n):
            colx = self.n_head + seg_of * n + i
            rows.append(r_out.ravel())
            cols.append(np.repeat(colx, ny))
            vals.append((-dy_x[i] / self.sigma_y).ravel())
        # Defect rows: W (x_{s+1} - x_end,s).
        if S > 1:
            r_def = n_out + np.arange((S - 1) * n).reshape(S - 1, n)
            W = self.W
            for a in range(nt):
                rows.append(r_def.ravel())
                cols.append(np.full((S - 1) * n, a))
                vals.append((-np.einsum("sij,sj->si", W, dx_t[a, :-1])).ravel())
            # d x_end,s / d x_s: column i is dx_x[i, s, :].
            Dss = np.transpose(dx_x[:, :-1, :], (1, 2, 0))  # (S-1, n, n): [s, row, col]
            blk = -np.einsum("sij,sjk->sik", W, Dss)
            srange = np.arange(S - 1)
            rr = r_def[:, :, None].repeat(n, axis=2)
            cc_self = (self.n_head + srange[:, None, None] * n + np.arange(n)[None, None, :]).repeat(n, axis=1)
            rows.append(rr.ravel())
            cols.append(cc_self.ravel())
            vals.append(blk.ravel())
            cc_next = cc_self + n
            rows.append(rr.ravel())
            cols.append(cc_next.ravel())
            vals.append(W.ravel())
        J = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(n_out + (S - 1) * n, self.n_head + S * n)).tocsr()
        J.data[~np.isfinite(J.data)] = 0.0
        return J


def _solve_ivp_shoot(system: System) -> ShootFunction:
    """The same loop as the compiled integrator, with ``scipy.integrate.solve_ivp``
    over each sample interval (the input changes there)."""
    from scipy.integrate import solve_ivp

    fn = system.functions.f
    n = system.n_states

    def shoot_many(P: np.ndarray, XS: np.ndarray, bounds: np.ndarray, t: np.ndarray, u: np.ndarray,
                   n_sub: np.ndarray, c_idx: np.ndarray, yhat: np.ndarray, xend: np.ndarray) -> None:
        n_seg = bounds.shape[0] - 1
        for c in range(P.shape[0]):
            p = P[c]
            for s in range(n_seg):
                x = XS[c, s].copy()
                for k in range(bounds[s], bounds[s + 1]):
                    yhat[c, k] = x[c_idx]
                    uk = u[k]

                    def rhs(_t: float, xx: np.ndarray, uk: np.ndarray = uk,
                            p: np.ndarray = p) -> np.ndarray:
                        out = np.empty(n)
                        fn(xx, uk, p, out)
                        return out

                    sol = solve_ivp(rhs, (t[k], t[k + 1]), x, method="RK45", rtol=1e-8, atol=1e-10)
                    x = sol.y[:, -1] if sol.success else np.full(n, np.nan)
                xend[c, s] = x
            yhat[c, bounds[n_seg]] = xend[c, n_seg - 1, c_idx]

    return shoot_many


def _shooter(system: System, backend: str) -> ShootFunction:
    if backend == "compiled":
        from equilibrist.ident.kernel import load_shooting

        return load_shooting(system).shoot_many
    if backend == "solve_ivp":
        return _solve_ivp_shoot(system)
    raise IdentificationError(f"backend {backend!r}: expected one of {', '.join(BACKENDS)}")



def _filter(system: System, backend: str) -> Callable[..., None]:
    if backend == "compiled":
        from equilibrist.ident.kernel import load_shooting

        filt: Callable[..., None] = load_shooting(system).innovations
        return filt
    return _solve_ivp_filter(system)

def _sensor_prior(system: System, log: Log, given: Mapping[str, float] | None) -> np.ndarray:
    given = dict(given or {})
    sigma = []
    for j, name in enumerate(log.output_names):
        if name in given:
            v = float(given[name])
            if not (math.isfinite(v) and v > 0):
                # A perfect sensor has infinite weight: the fit would chase it without end.
                raise IdentificationError(f"--sensor-noise {name}={v:g}: a sensor's standard "
                                          "deviation must be a finite number > 0")
        elif name in system.spec.sensor_noise:
            v = float(system.spec.sensor_noise[name])
        else:  # white sensor noise dominates second differences at a rig's rate
            d2 = np.diff(log.outputs[:, j], 2)
            v = float(np.std(d2) / math.sqrt(6.0)) if d2.size else 0.0
        if not (math.isfinite(v) and v > 0):
            scale = float(np.std(log.outputs[:, j]))
            v = max(1e-6 * scale, 1e-9)
        sigma.append(v)
    return np.array(sigma)


def _process_prior(system: System, given: Mapping[str, float] | None) -> np.ndarray:
    given = dict(given or {})
    spec = system.spec
    q = np.zeros(system.n_states)
    for i, s in enumerate(system.state_names):
        if s in given:
            q[i] = float(given[s]) ** 2
        elif s in spec.process_noise:
            q[i] = float(spec.process_noise[s]) ** 2
    return q


def _state_floor(system: System) -> np.ndarray:
    """A tiny variance per state, so that a state without process noise stays weighted finitely."""
    scales = system.spec.design_scales
    return np.array([(1e-4 * float(scales.get(s, 1.0))) ** 2 for s in system.state_names])


def _linearization(system: System, xs: np.ndarray, u_mean: np.ndarray) -> np.ndarray:
    x_mid = np.median(xs, axis=0)
    try:
        A, _B = system.jacobians(x_mid, u_mean)
    except EquilibristError:  # a singular point: the segments' covariance without drift
        A = np.zeros((system.n_states, system.n_states))
    return A


def _segment_samples(A: np.ndarray, q: np.ndarray, c_idx: np.ndarray, sigma_y: np.ndarray,
                     dt: float, n_rows: int) -> int:
    """Samples per segment: the longest over which process noise moves each output
    by at most SEGMENT_NOISE_RATIO of its sensor variance (at least
    MIN_SEGMENT_SAMPLES)."""
    cap = max(MIN_SEGMENT_SAMPLES, min(n_rows - 1, int(MAX_SEGMENT_SECONDS / dt)))
    if not np.any(q > 0):
        return cap
    best = MIN_SEGMENT_SAMPLES
    for L in range(MIN_SEGMENT_SAMPLES, cap + 1):
        Q = _van_loan(A, np.diag(q), L * dt)
        ratio = np.diag(Q)[c_idx] / sigma_y**2
        if np.max(ratio) > SEGMENT_NOISE_RATIO:
            break
        best = L
    return best


def _boundaries(n_rows: int, L: int) -> np.ndarray:
    b = [*list(range(0, n_rows - 1, L)), n_rows - 1]
    if len(b) > 2 and b[-1] - b[-2] < max(1, L // 2):
        del b[-2]
    return np.array(b, dtype=np.int64)


def _whitening(A: np.ndarray, q: np.ndarray, floor: np.ndarray, durations: np.ndarray) -> np.ndarray:
    out = np.empty((durations.size, A.shape[0], A.shape[0]))
    memo: dict[float, np.ndarray] = {}
    for s, T in enumerate(durations):
        key = round(float(T), 12)
        if key not in memo:
            Q = _van_loan(A, np.diag(q), float(T)) + np.diag(floor)
            L = np.linalg.cholesky(Q)
            memo[key] = np.linalg.inv(L)
        out[s] = memo[key]
    return out


def identify(
    system: System,
    log: Log,
    free: Sequence[str],
    *,
    offsets: bool = False,
    segment: float | None = None,
    max_step: float = DEFAULT_MAX_STEP,
    sensor_noise: Mapping[str, float] | None = None,
    process_noise: Mapping[str, float] | None = None,
    backend: str = "compiled",
    reestimate_noise: bool = True,
    max_nfev: int = 200,
) -> Identification:
    """Fit the parameters *free* of *system* to *log* by multiple shooting.

    Parameters
    ----------
    system : System
        The model, with every parameter at its known value and the free ones
        at their start values.
    log : Log
        The measured data (:func:`equilibrist.ident.read_log`).
    free : sequence of str
        The physical parameters to fit.
    offsets : bool
        Also fit a constant offset of each sensor.
    segment : float, optional
        Length of the shooting segments [s]; by default the longest over
        which process noise moves the outputs by at most half a sensor
        standard deviation (at least 5 samples).
    max_step : float
        Longest RK4 step [s].
    sensor_noise, process_noise : mapping, optional
        Standard deviations of the sensors per output, and intensities of
        the process noise per state rate (as in the system's spec), for the
        first fit's weights (default: the spec's).
    backend : {"compiled", "solve_ivp"}
        The integrator of the segments.
    reestimate_noise : bool
        Re-estimate the noise levels from the first fit's residuals and fit
        again.

    Returns
    -------
    Identification
    """
    from scipy.optimize import least_squares

    if log.system != system.key:
        raise IdentificationError(f"the log was checked against {log.system}, not {system.key}")
    free = check_free(system, free)
    if not (math.isfinite(max_step) and max_step > 0):
        raise IdentificationError(f"the integration step must be positive, got {max_step!r}")
    n, ny, n_rows = system.n_states, len(log.output_names), log.n_rows
    names = system.spec.parameter_names
    free_idx = np.array([names.index(f) for f in free], dtype=np.int64)
    c_idx = np.array([system.state_index(o) for o in log.output_names], dtype=np.int64)
    dts = np.diff(log.time)
    dt = float(np.median(dts))
    # Bounded before the division: a step of 1e-300 s would be billions of steps a sample.
    shortest = float(np.max(dts)) / MAX_SUBSTEPS
    if max_step < shortest:
        raise IdentificationError(
            f"--max-step {max_step:g} s: at most {MAX_SUBSTEPS} RK4 steps per sample of the log "
            f"(its longest sample is {float(np.max(dts)):g} s): expected a step >= {shortest:.3g} s")
    n_sub = np.maximum(1, np.ceil(dts / max_step - 1e-9)).astype(np.int64)
    for j, name in enumerate(log.output_names):
        column = log.outputs[:, j]
        if not np.ptp(column) > 0:
            raise IdentificationError(
                f"the log's output {name} is {float(column[0]):g} throughout: a constant output "
                "says nothing about the parameters and its noise cannot be estimated (log a run "
                "that moves, or leave that column out)")

    sigma_y = _sensor_prior(system, log, sensor_noise)
    q = _process_prior(system, process_noise)
    guess = _guess_states(system, log)
    u_mean = log.inputs.mean(axis=0) if system.n_inputs else np.zeros(0)
    A = _linearization(system, guess, u_mean)
    if segment is None:
        L = _segment_samples(A, q, c_idx, sigma_y, dt, n_rows)
    else:
        if not (math.isfinite(segment) and segment > 0):
            raise IdentificationError(f"the segment length must be positive, got {segment!r} s")
        L = max(1, round(segment / dt))
    bounds = _boundaries(n_rows, L)
    n_seg = bounds.size - 1
    n_dec = len(free) + (ny if offsets else 0) + n_seg * n
    n_res = n_rows * ny + (n_seg - 1) * n
    if n_res <= n_dec:
        raise IdentificationError(
            f"the log has {n_rows} rows of {ny} output{'s' if ny != 1 else ''}: too few for "
            f"{len(free)} free parameter{'s' if len(free) != 1 else ''} and the "
            f"{n_seg * n} segment states of multiple shooting"
        )
    floor = _state_floor(system)
    durations = log.time[bounds[1:-1]] - log.time[bounds[:-2]]
    p0 = np.array(system.p, dtype=float)
    theta0 = p0[free_idx].copy()
    scales = system.spec.design_scales
    step_x = np.array([1e-6 * float(scales.get(s, 1.0)) for s in system.state_names])
    prob = _Problem(
        system=system, log=log, free=free, offsets=offsets, bounds=bounds, n_sub=n_sub,
        c_idx=c_idx, sigma_y=sigma_y, W=_whitening(A, q, floor, durations),
        shoot=_shooter(system, backend), free_idx=free_idx, p_base=p0,
        step_theta=np.full(len(free), 1e-6), step_x=step_x,
    )
    z0 = np.concatenate([theta0, np.zeros(prob.n_off), guess[bounds[:-1]].ravel()])
    lo = np.full(z0.size, -np.inf)
    hi = np.full(z0.size, np.inf)
    by_name = {p.name: p for p in system.spec.parameters}
    for a, name in enumerate(free):
        par = by_name[name]
        span = max(abs(theta0[a]), 1e-12)
        lo[a] = par.low + (1e-9 * span if par.low_open else 0.0)
        hi[a] = par.high - (1e-9 * span if par.high_open else 0.0)
        z0[a] = min(max(z0[a], lo[a]), hi[a])

    def fit(z_start: np.ndarray) -> Any:
        with np.errstate(all="ignore"):
            return least_squares(
                prob.residuals, z_start, jac=prob.jacobian, bounds=(lo, hi), method="trf",
                x_scale="jac", tr_solver="lsmr", ftol=1e-12, xtol=1e-12, gtol=1e-10,
                max_nfev=max_nfev,
            )

    sol = fit(z0)
    q_scale = 1.0
    for _ in range(NOISE_PASSES if reestimate_noise else 0):
        # Variance components (Helmert): each group's sum of squares over its
        # redundancy (its rows minus their leverage), so that the states
        # fitted to the residuals do not make the noise look smaller.
        theta, off, xs = prob.split(sol.x)
        r = prob.residuals(sol.x)
        n_out = n_rows * ny
        groups = [np.arange(j, n_out, ny) for j in range(ny)]
        lev = _leverage(prob.jacobian(sol.x), groups)
        ry = r[:n_out].reshape(n_rows, ny)
        ratio_y = np.sum(ry**2, axis=0) / np.maximum(n_rows - lev[:ny], 1.0)
        sigma_y = sigma_y * np.sqrt(ratio_y)
        A = _linearization(system, xs, u_mean)
        prob.sigma_y = sigma_y
        # The process noise: the scale that makes the fitted model's Kalman
        # filter most likely (the segment defects alone understate it: the
        # segment states absorb part of the noise acting inside a segment).
        ratio_q = 1.0
        if np.any(q > 0):
            ratio_q = _process_scale(system, log, prob, theta, off, xs[0], A, q, floor, dt)
            q = q * ratio_q
            q_scale *= ratio_q
        prob.W = _whitening(A, q, floor, durations)
        sol = fit(sol.x)
        if max(abs(ratio_q - 1.0), float(np.max(np.abs(ratio_y - 1.0)))) < 0.05:
            break

    # The estimate: the prediction errors of the model's Kalman filter, from the
    # multiple-shooting solution. The shooting residuals leave the process noise
    # acting inside a segment unmodelled, and the closed loop's input answers
    # that noise, so their minimum is biased where the process noise matters;
    # the filter's errors are white at the truth, whatever the feedback.
    theta, off, xs = prob.split(sol.x)
    nh = prob.n_head
    pred = _Predictor(
        system=system, log=log, free_idx=free_idx, offsets=offsets, p_base=p0,
        c_idx=c_idx, n_sub=n_sub, dt=dt, x_lin=np.median(xs, axis=0), u_lin=u_mean, floor=floor,
        q=q.copy(), sigma_y=sigma_y.copy(), filter=_filter(system, backend),
        step=np.concatenate([1e-6 * np.where(theta0 != 0, np.abs(theta0), 1.0),
                             1e-4 * sigma_y[: prob.n_off], step_x]),
    )
    lo_p = np.concatenate([lo[:nh], np.full(n, -np.inf)])
    hi_p = np.concatenate([hi[:nh], np.full(n, np.inf)])

    def fit_errors(z_start: np.ndarray) -> Any:
        pred.set_weight(z_start)
        with np.errstate(all="ignore"):
            return least_squares(
                pred.residuals, z_start, jac=pred.jacobian, bounds=(lo_p, hi_p), method="trf",
                x_scale="jac", ftol=1e-10, xtol=1e-10, gtol=1e-10, max_nfev=max_nfev,
            )

    z_p = np.clip(np.concatenate([theta, off[: prob.n_off], xs[0]]), lo_p, hi_p)
    psol = fit_errors(z_p)
    nfev = int(sol.nfev) + int(psol.nfev)
    for _ in range(NOISE_PASSES if reestimate_noise else 0):
        ratio_q, ratio_y = pred.noise_levels(psol.x)
        pred.q = pred.q * ratio_q
        pred.sigma_y = pred.sigma_y * ratio_y
        q_scale *= ratio_q
        if max(abs(ratio_q - 1.0), float(np.max(np.abs(ratio_y - 1.0)))) < 0.05:
            break
        psol = fit_errors(psol.x)
        nfev += int(psol.nfev)
    return _answer(system, log, prob, sol, pred, psol, theta0, q_scale, L, dt, backend, max_step,
                   (lo, hi), nfev)


# -- the prediction-error stage ------------------------------------------------------


@dataclass
class _Predictor(_Unknowns):
    """The one-step prediction errors of a Kalman filter of the model, as residuals.

    The filter predicts with the nonlinear model (RK4, the logged input held)
    and corrects with the steady-state gain of the model's linearization,
    recomputed for every parameter vector; the decision variables are the
    free parameters, the sensor offsets (with ``offsets``) and the filter's
    initial state.
    """

    dt: float
    x_lin: np.ndarray
    u_lin: np.ndarray
    floor: np.ndarray
    q: np.ndarray
    filter: Callable[..., None]
    step: np.ndarray = field(default_factory=lambda: np.zeros(0))  # the least difference step
    weight: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    memo: dict[tuple[Any, ...], Any] = field(default_factory=dict)

    def split(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.head(z)

    def gain(self, p: np.ndarray, q_factor: float = 1.0,
             sigma_y: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The steady-state gain ``K`` and innovation covariance ``S`` at parameters *p*,
        with the process noise ``q_factor * q`` and the sensors' *sigma_y*.

        Remembered per parameter vector (the Jacobian's columns of the initial
        state and offsets share one), the discretization too (the noise search
        shares one): both are small dense problems, solved thousands of times.
        """

        sigma_y = self.sigma_y if sigma_y is None else sigma_y
        if len(self.memo) > 256:
            self.memo.clear()
        key = (p.tobytes(), self.q.tobytes(), float(q_factor), sigma_y.tobytes())
        if key in self.memo:
            return self.memo[key]
        n, ny = self.n, self.ny
        lin_key = key[:2]
        if lin_key not in self.memo:
            A = np.empty((n, n))
            B = np.empty((n, self.system.n_inputs))
            with np.errstate(all="ignore"):
                self.system.functions.jac(self.x_lin, self.u_lin, p, A, B)
            if not np.all(np.isfinite(A)):
                A = np.zeros((n, n))
            self.memo[lin_key] = _discretize(A, np.diag(self.q), self.dt)
        Ad, Qv = self.memo[lin_key]
        C = np.zeros((ny, n))
        C[np.arange(ny), self.c_idx] = 1.0
        Qd = q_factor * Qv + np.diag(self.floor)
        out = _steady_gain(Ad, C, Qd, np.diag(sigma_y**2))
        self.memo[key] = out
        return out

    def errors(self, z: np.ndarray, q_factor: float = 1.0,
               sigma_y: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The prediction errors (n_rows, ny) at *z*, and their covariance ``S``."""
        theta, off, x0 = self.split(z)
        p = self.p_of(theta)
        K, S = self.gain(p, q_factor, sigma_y)
        e = np.empty((self.log.n_rows, self.ny))
        with np.errstate(all="ignore"):
            self.filter(p, np.ascontiguousarray(x0, dtype=float), self.log.time, self.log.inputs,
                        self.n_sub, self.c_idx, np.ascontiguousarray(K), self.log.outputs,
                        np.ascontiguousarray(off, dtype=float), e)
        return e, S

    def set_weight(self, z: np.ndarray) -> None:
        """Weight the errors by the innovation covariance at *z* (held during a fit)."""
        _e, S = self.errors(z)
        self.weight = np.linalg.inv(np.linalg.cholesky(S))

    def residuals(self, z: np.ndarray) -> np.ndarray:
        e, _S = self.errors(z)
        r = (e @ self.weight.T).ravel()
        return np.where(np.isfinite(r), r, 1e10)

    def jacobian(self, z: np.ndarray) -> np.ndarray:
        """Central differences, column by column (the filter runs once per column and side)."""
        h = np.maximum(1e-6 * np.abs(z), self.step)
        cols = []
        for a in range(z.size):
            zp = z.copy()
            zm = z.copy()
            zp[a] += h[a]
            zm[a] -= h[a]
            cols.append((self.residuals(zp) - self.residuals(zm)) / (2 * h[a]))
        J = np.column_stack(cols)
        J[~np.isfinite(J)] = 0.0
        return J

    def noise_levels(self, z: np.ndarray) -> tuple[float, np.ndarray]:
        """The process noise's scale and the sensors' standard deviations that make the
        filter's prediction errors most likely at *z* (factors on the current ones)."""
        from scipy.optimize import minimize

        n_rows = self.log.n_rows
        has_q = bool(np.any(self.q > 0))

        def nll(v: np.ndarray) -> float:
            e, S = self.errors(z, math.exp(v[0]) if has_q else 1.0, self.sigma_y * np.exp(v[1:]))
            if not np.all(np.isfinite(e)):
                return math.inf
            _sign, logdet = np.linalg.slogdet(S)
            return float(n_rows * logdet + np.einsum("ki,ij,kj->", e, np.linalg.inv(S), e))

        v0 = np.zeros(1 + self.ny)
        simplex = np.vstack([v0, 0.2 * np.eye(v0.size)])  # factors of 1.2 to start
        res = minimize(nll, v0, method="Nelder-Mead",
                       options={"xatol": 0.005, "fatol": 0.05, "maxfev": 400,
                                "initial_simplex": simplex})
        v = np.clip(res.x, -math.log(1e3), math.log(1e3)) if math.isfinite(res.fun) else v0
        return (math.exp(v[0]) if has_q else 1.0), np.exp(v[1:])


def _solve_ivp_filter(system: System) -> Callable[..., None]:
    """The Kalman filter's prediction errors with :func:`scipy.integrate.solve_ivp`
    over each sample interval (the same loop as the compiled filter)."""
    from scipy.integrate import solve_ivp

    fn = system.functions.f
    n = system.n_states

    def innovations(p: np.ndarray, x0: np.ndarray, t: np.ndarray, u: np.ndarray, n_sub: np.ndarray,
                    c_idx: np.ndarray, gain: np.ndarray, y: np.ndarray, off: np.ndarray,
                    e: np.ndarray) -> None:
        x = x0.copy()
        for k in range(t.shape[0]):
            e[k] = y[k] - off - x[c_idx]
            x = x + gain @ e[k]
            if k + 1 < t.shape[0]:
                uk = u[k]

                def rhs(_t: float, xx: np.ndarray, uk: np.ndarray = uk) -> np.ndarray:
                    out = np.empty(n)
                    fn(xx, uk, p, out)
                    return out

                if not np.all(np.isfinite(x)):
                    e[k + 1:] = np.nan
                    return
                sol = solve_ivp(rhs, (t[k], t[k + 1]), x, method="RK45", rtol=1e-8, atol=1e-10)
                x = sol.y[:, -1] if sol.success else np.full(n, np.nan)

    return innovations


def _information_inverse(H: np.ndarray) -> np.ndarray:
    """``H^-1`` by Cholesky, or the pseudo-inverse on the determined directions."""
    from scipy.linalg import LinAlgError, cho_factor, cho_solve

    H = (H + H.T) / 2
    try:
        return cho_solve(cho_factor(H), np.eye(H.shape[0]))
    except LinAlgError:
        lam, V = np.linalg.eigh(H)
        keep = lam > STRUCTURAL_RATIO * max(float(lam.max()), 1e-300)
        return (V[:, keep] / lam[keep]) @ V[:, keep].T


def _leverage(J: Any, groups: Sequence[np.ndarray]) -> np.ndarray:
    """The leverage of each group of residual rows: ``tr(J_g (J'J)^-1 J_g')``.

    Computed as the sum of ``(J'J)^-1 * (J_g' J_g)`` (both symmetric), with
    ``J_g' J_g`` sparse.
    """
    M = _information_inverse((J.T @ J).toarray())
    out = []
    for rows in groups:
        Jg = J[rows]
        Hg = (Jg.T @ Jg).tocoo()
        out.append(float(np.sum(M[Hg.row, Hg.col] * Hg.data)))
    return np.array(out)


def _answer(system: System, log: Log, prob: _Problem, sol: Any, pred: _Predictor, psol: Any,
            theta0: np.ndarray, q_scale: float, L: int, dt: float, backend: str, max_step: float,
            lo_hi: tuple[np.ndarray, np.ndarray], nfev: int) -> Identification:
    from scipy.stats import chi2

    theta, off, x0 = pred.split(psol.x)
    # A parameter that ended at a bound is reported at the bound itself.
    theta = np.where(psol.active_mask[: pred.n_theta] < 0, lo_hi[0][: pred.n_theta], theta)
    theta = np.where(psol.active_mask[: pred.n_theta] > 0, lo_hi[1][: pred.n_theta], theta)
    z = np.concatenate([theta, psol.x[pred.n_theta:]])
    # The replay: each shooting segment from its state, with the estimated parameters.
    _theta_ms, _off_ms, xs = prob.split(sol.x)
    yhat, _xend = prob.run(prob.p_of(theta)[None], xs[None])
    replayed = yhat[0] + off
    pred.set_weight(z)
    r = pred.residuals(z)
    J = pred.jacobian(z)
    n_res, n_dec = J.shape
    s2 = float(r @ r) / max(1, n_res - n_dec)
    H = J.T @ J
    nh = pred.n_head
    Haa, Hab, Hbb = H[:nh, :nh], H[:nh, nh:], H[nh:, nh:]
    try:
        from scipy.linalg import cho_factor, cho_solve

        S = Haa - Hab @ cho_solve(cho_factor(Hbb), Hab.T)
    except np.linalg.LinAlgError:
        S = Haa - Hab @ np.linalg.pinv(Hbb) @ Hab.T
    S = (S + S.T) / 2
    names = list(prob.free) + [f"offset_{o}" for o in log.output_names][: prob.n_off]
    values = np.concatenate([theta, off[: prob.n_off]])
    # Log-parameters for the parameters (relative changes), noise units for
    # offsets; a parameter at (or near) zero is measured in its own standard error.
    sd_abs = np.sqrt(np.clip(np.diag(_information_inverse(S)) * s2, 0.0, None))
    mag = np.abs(theta)
    sd_t = sd_abs[: prob.n_theta]
    theta_scale = np.where(mag > 0.1 * sd_t, mag, np.where(sd_t > 0, sd_t, 1.0))
    scale = np.concatenate([theta_scale, pred.sigma_y[: prob.n_off]])
    Sl = S * np.outer(scale, scale)
    lam, V = np.linalg.eigh(Sl)
    lam_max = float(max(lam.max(), 1e-300))
    undetermined = np.zeros(nh, dtype=bool)
    directions: list[str] = []
    weak = np.zeros(nh, dtype=bool)
    weakest = 0.0
    for k in range(nh):
        structural = lam[k] <= STRUCTURAL_RATIO * lam_max
        std_log = math.sqrt(s2 / lam[k]) if lam[k] > 0 else math.inf
        v = V[:, k]
        involved = np.abs(v) >= 0.2 * np.abs(v).max()
        if structural:
            directions.append(_name_direction(names, v, prob.n_theta))
            undetermined |= involved
        elif std_log > WEAK_LOG_STD:
            weak |= involved
            weakest = max(weakest, std_log)
    weak &= ~undetermined
    if weak.any():
        who = [n for n, w in zip(names, weak, strict=True) if w]
        directions.append(
            f"{_and(who)} {'is' if len(who) == 1 else 'are'} not determined by this log: "
            f"relative changes of up to +-{100 * min(weakest, 99.99):.0f} % "
            f"{'of it' if len(who) == 1 else 'along a combination of them'} fit as well "
            "(excite the rig more, or fix what you know with --set)")
    # Covariance: the pseudo-inverse on the determined directions.
    keep = lam > STRUCTURAL_RATIO * lam_max
    cov_l = (V[:, keep] / lam[keep]) @ V[:, keep].T * s2
    cov = cov_l * np.outer(scale, scale)
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    se[undetermined] = math.inf
    with np.errstate(all="ignore"):
        d = np.sqrt(np.diag(cov))
        corr = cov / np.outer(d, d)
    corr = np.where(np.isfinite(corr), corr, 0.0)
    corr[undetermined, :] = np.nan  # no correlation of what is not determined
    corr[:, undetermined] = np.nan
    np.fill_diagonal(corr, 1.0)
    units = {p.name: p.unit for p in system.spec.parameters}
    estimates = []
    for a, name in enumerate(names):
        if a < prob.n_theta:
            unit, start = units[name], float(theta0[a])
        else:
            unit, start = system.state_units[prob.c_idx[a - prob.n_theta]], 0.0
        estimates.append(Estimate(name, float(values[a]), float(se[a]), start, unit))
    warnings = []
    for i in range(nh):
        for j in range(i):
            if math.isfinite(corr[i, j]) and abs(corr[i, j]) > 0.99 and not (undetermined[i] or undetermined[j]):
                warnings.append(f"{names[i]} and {names[j]} are correlated {corr[i, j]:+.3f}: "
                                "the log barely tells them apart")
    at_bound = {name for a, name in enumerate(prob.free) if psol.active_mask[a] != 0}
    for e in estimates:
        if (math.isfinite(e.std_error) and math.isfinite(e.relative_error)
                and e.relative_error > WEAK_LOG_STD and e.name in prob.free
                and e.name not in at_bound):
            warnings.append(f"{e.name} is uncertain by {100 * e.relative_error:.0f} % "
                            "(standard error over estimate)")
    for a, name in enumerate(prob.free):
        if name in at_bound:
            bound = lo_hi[0][a] if psol.active_mask[a] < 0 else lo_hi[1][a]
            warnings.append(f"{name} ended at the bound of its valid range ({bound:g}): the log "
                            "asks for a value outside it (or the data do not determine it)")
    if not psol.success:
        warnings.append(f"the optimizer stopped before converging: {psol.message}")
    e_pred, S_pred = pred.errors(z)
    innov = e_pred / np.sqrt(np.diag(S_pred))
    fits = []
    for j, name in enumerate(log.output_names):
        y = log.outputs[:, j]
        e = y - replayed[:, j]
        denom = float(np.linalg.norm(y - y.mean()))
        nrmse = float(np.linalg.norm(e) / denom) if denom > 0 else math.inf
        qv, pv, lags = _ljung_box(innov[:, j], chi2)
        fits.append(OutputFit(name, system.state_units[prob.c_idx[j]], nrmse,
                              float(np.sqrt(np.mean(e**2))), float(pred.sigma_y[j]), qv, pv, lags))
    not_white = [f.name for f in fits if not f.white]
    if not_white:
        warnings.append(
            f"the residuals of {', '.join(not_white)} are not white (Ljung-Box, {WHITENESS_LEVEL:g} "
            "level): the model leaves structure in the data (a missing effect, or parameters "
            "held at wrong values)"
        )
    seg_seconds = L * dt
    n_seg = prob.n_seg
    desc = (
        f"prediction error: the one-step prediction errors of a Kalman filter of the model (the "
        f"nonlinear model predicts, the steady-state gain of its linearization at the parameters "
        f"corrects), weighted by their covariance, the filter's initial state estimated; started "
        f"from a multiple-shooting fit ({n_seg} segments of {L} samples, {seg_seconds:g} s); the "
        f"logged input replayed with zero-order hold; RK4 at <= {max_step:g} s "
        f"({'compiled' if backend == 'compiled' else 'scipy solve_ivp'}); "
        f"scipy least_squares (trf), {nfev} evaluations"
    )
    params = dict(system.params)
    for a, name in enumerate(prob.free):
        params[name] = float(theta[a])
    x_init = dict(zip(system.state_names, x0.tolist(), strict=True))
    return Identification(
        system=system.key,
        params=params,
        free=prob.free,
        estimates=tuple(estimates),
        correlation=corr,
        unidentifiable=tuple(directions),
        warnings=tuple(warnings),
        outputs=tuple(fits),
        output_names=log.output_names,
        time=log.time,
        measured=log.outputs,
        replayed=replayed,
        segment_starts=prob.bounds[:-1].copy(),
        initial_state=x_init,
        method={
            "name": "prediction error",
            "start": "multiple shooting",
            "description": desc,
            "segments": n_seg,
            "segment_samples": L,
            "segment_seconds": seg_seconds,
            "integrator": "rk4",
            "max_step": max_step,
            "backend": backend,
            "samples": log.n_rows,
            "duration": log.duration,
            "evaluations": nfev,
            "residual_variance": s2,
            "converged": bool(psol.success),
        },
        source=log.source,
        noise={
            "sensor_std": dict(zip(log.output_names, pred.sigma_y.tolist(), strict=True)),
            "process_intensity": dict(zip(system.state_names, pred.q.tolist(), strict=True)),
            "process_scale": q_scale,
        },
    )


def _process_scale(system: System, log: Log, prob: _Problem, theta: np.ndarray, off: np.ndarray,
                   x0: np.ndarray, A: np.ndarray, q: np.ndarray, floor: np.ndarray,
                   dt: float) -> float:
    """The factor on the process noise *q* that maximizes the likelihood of the
    fitted model's Kalman filter prediction errors."""
    from scipy.optimize import minimize_scalar

    n_rows = log.n_rows

    def nll(log_scale: float) -> float:
        e, S = _kalman(system, log, prob, theta, off, x0, A, q * math.exp(log_scale), floor, dt)
        if not np.all(np.isfinite(e)):
            return math.inf
        _sign, logdet = np.linalg.slogdet(S)
        return float(n_rows * logdet + np.einsum("ki,ij,kj->", e, np.linalg.inv(S), e))

    res = minimize_scalar(nll, bounds=(math.log(1e-3), math.log(1e3)), method="bounded",
                          options={"xatol": 0.02})
    return float(math.exp(res.x))


def _kalman(system: System, log: Log, prob: _Problem, theta: np.ndarray, off: np.ndarray,
            x0: np.ndarray, A: np.ndarray, q: np.ndarray, floor: np.ndarray,
            dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Prediction errors of a Kalman filter of the model, and their covariance."""
    from scipy.linalg import expm

    from equilibrist.ident.kernel import load_shooting

    n, ny = system.n_states, prob.ny
    C = np.zeros((ny, n))
    C[np.arange(ny), prob.c_idx] = 1.0
    Ad = expm(A * dt)
    Qd = _van_loan(A, np.diag(q), dt) + np.diag(floor)
    gain, Sinn = _steady_gain(Ad, C, Qd, np.diag(prob.sigma_y**2))
    e = np.empty((log.n_rows, ny))
    load_shooting(system).innovations(
        prob.p_of(theta), np.ascontiguousarray(x0, dtype=float), log.time, log.inputs,
        prob.n_sub, prob.c_idx, np.ascontiguousarray(gain), log.outputs,
        np.ascontiguousarray(off, dtype=float), e)
    return e, Sinn


def _steady_gain(Ad: np.ndarray, C: np.ndarray, Qd: np.ndarray,
                 R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The steady-state Kalman gain ``K`` and innovation covariance ``S`` of the sampled
    model (the filter Riccati equation by iteration, else scipy's DARE, else ``P = Qd``)."""
    from scipy.linalg import solve_discrete_are

    P = _filter_riccati(Ad, C, Qd, R)
    if P is None:
        try:
            P = solve_discrete_are(Ad.T, C.T, Qd, R)
        except (ValueError, np.linalg.LinAlgError):
            P = Qd.copy()
    S = C @ P @ C.T + R
    return P @ C.T @ np.linalg.inv(S), (S + S.T) / 2


def _filter_riccati(Ad: np.ndarray, C: np.ndarray, Qd: np.ndarray, R: np.ndarray) -> np.ndarray | None:
    """The Kalman predictor's steady covariance ``P = Ad P (I + C'R^-1 C P)^-1 Ad' + Qd`` by
    the structure-preserving doubling algorithm (quadratic convergence; None if it does not)."""
    n = Ad.shape[0]
    A = Ad.T.copy()
    G = C.T @ np.linalg.solve(R, C)
    H = Qd.copy()
    eye = np.eye(n)
    for _ in range(60):
        W = eye + G @ H
        try:
            WA = np.linalg.solve(W, A)
            WG = np.linalg.solve(W, G)
        except np.linalg.LinAlgError:
            return None
        H_next = H + A.T @ H @ WA
        G = G + A @ WG @ A.T
        A = A @ WA
        if not np.all(np.isfinite(H_next)):
            return None
        if np.max(np.abs(H_next - H)) <= 1e-13 * max(1.0, float(np.max(np.abs(H_next)))):
            return (H_next + H_next.T) / 2
        H = H_next
    return None


def _ljung_box(e: np.ndarray, chi2: Any) -> tuple[float, float, int]:
    N = e.size
    h = int(min(WHITENESS_LAGS, max(1, N // 5)))
    x = e - e.mean()
    var = float(x @ x)
    if var == 0 or N < 3:
        return 0.0, 1.0, h
    rho = np.array([float(x[k:] @ x[:-k]) / var for k in range(1, h + 1)])
    qv = float(N * (N + 2) * np.sum(rho**2 / (N - np.arange(1, h + 1))))
    return qv, float(chi2.sf(qv, h)), h


def _and(names: Sequence[str]) -> str:
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _name_direction(names: list[str], v: np.ndarray, n_theta: int) -> str:
    """A direction of (log-)parameters that changes nothing, in words."""
    mags = np.abs(v)
    idx = [int(i) for i in np.argsort(-mags) if mags[i] >= 0.2 * mags.max()]
    if len(idx) == 1:
        name = names[idx[0]]
        if idx[0] >= n_theta:
            return f"{name} cannot be told apart from the states themselves: it is not identifiable"
        return f"{name} does not change the measured outputs: it cannot be identified from them"
    if len(idx) == 2 and all(i < n_theta for i in idx):
        a, b = idx
        exponent = -v[a] / v[b]  # the data depend on names[a] * names[b]**exponent only
        na, nb = names[a], names[b]
        forms = {1.0: f"{na}*{nb}", -1.0: f"{na}/{nb}", 2.0: f"{na}*{nb}^2",
                 -2.0: f"{na}/{nb}^2", 0.5: f"{na}*sqrt({nb})", -0.5: f"{na}/sqrt({nb})"}
        combo = next((f for e, f in forms.items() if abs(exponent - e) < 0.05 * max(1.0, abs(e))),
                     f"{na}*{nb}^{exponent:.3g}")
        return f"{na} and {nb} only appear as {combo} here: fix one of them (--set) to identify the other"
    parts = ", ".join(f"{names[i]} {v[i] / mags.max():+.2f}" for i in idx)
    return (f"{_and([names[i] for i in idx])} are determined only in combination: the data "
            f"cannot tell apart relative changes along ({parts})")


__all__ = ["BACKENDS", "FORMAT", "Estimate", "Identification", "OutputFit", "check_free", "identify"]
