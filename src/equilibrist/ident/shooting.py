"""The multiple-shooting stage of :func:`equilibrist.ident.fit.identify`.

The decision vector's head that both stages share (:class:`_Unknowns`), the
shooting problem with its residuals and sparse Jacobian (:class:`_Problem`),
its integrators (compiled, or scipy's ``solve_ivp``), the start trajectory,
the segments and the whitening of their defects, and what re-estimates the
noise levels between its fits (the leverage of the residuals, the process
noise's scale from the model's Kalman filter).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from equilibrist.control.discretize import sampled_noise
from equilibrist.errors import EquilibristError
from equilibrist.ident.log import IdentificationError, Log
from equilibrist.ident.noise import _information_inverse, _negative_log_likelihood, _steady_gain
from equilibrist.numeric.system import System
from equilibrist.sim.integrators import DEFAULT

BACKENDS = ("compiled", "solve_ivp")
# Segment length rule: process noise may move an output by this fraction of
# the sensor variance over one segment.
SEGMENT_NOISE_RATIO = 0.25
# The shortest default segment, in samples: shorter ones multiply the
# decision variables for little gain where the sensors are far finer than
# the process noise.
MIN_SEGMENT_SAMPLES = 5
MAX_SEGMENT_SECONDS = 1.0
# Steps of one call of the compiled integrator at most (a few tens of ms): Ctrl-C
# is answered between calls.
CALL_STEPS = 1_000_000

ShootFunction = Callable[..., None]


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
        return int(self.c_idx.shape[0])

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

    @property
    def n_seg(self) -> int:
        return int(self.bounds.shape[0]) - 1

    def split(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        theta, off, rest = self.head(z)
        return theta, off, rest.reshape(self.n_seg, self.n)

    def run(self, P: np.ndarray, XS: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every segment for each case, in calls of at most :data:`CALL_STEPS` steps.

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
        """Consecutive segments ``[a, b)`` of at most :data:`CALL_STEPS` steps (one at least)."""
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


def _shooter(system: System, backend: str, integrator: str = DEFAULT) -> ShootFunction:
    """The shooting loop of *backend*: the compiled one steps with *integrator* (a name of
    :mod:`equilibrist.sim.integrators`' table)."""
    if backend == "compiled":
        from equilibrist.ident.kernel import load_shooting

        return load_shooting(system, integrator).shoot_many
    if backend == "solve_ivp":
        return _solve_ivp_shoot(system)
    raise IdentificationError(f"backend {backend!r}: expected one of {', '.join(BACKENDS)}")


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
        _F, Q = sampled_noise(A, np.diag(q), L * dt)
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
            Q = sampled_noise(A, np.diag(q), float(T))[1] + np.diag(floor)
            L = np.linalg.cholesky(Q)
            memo[key] = np.linalg.inv(L)
        out[s] = memo[key]
    return out


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


def _process_scale(system: System, log: Log, prob: _Problem, theta: np.ndarray, off: np.ndarray,
                   x0: np.ndarray, A: np.ndarray, q: np.ndarray, floor: np.ndarray,
                   dt: float) -> float:
    """The factor on the process noise *q* that maximizes the likelihood of the
    fitted model's Kalman filter prediction errors."""
    from scipy.optimize import minimize_scalar

    def nll(log_scale: float) -> float:
        return _negative_log_likelihood(
            *_kalman(system, log, prob, theta, off, x0, A, q * math.exp(log_scale), floor, dt))

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
    Qd = sampled_noise(A, np.diag(q), dt)[1] + np.diag(floor)
    gain, Sinn = _steady_gain(Ad, C, Qd, np.diag(prob.sigma_y**2))
    e = np.empty((log.n_rows, ny))
    load_shooting(system).innovations(
        prob.p_of(theta), np.ascontiguousarray(x0, dtype=float), log.time, log.inputs,
        prob.n_sub, prob.c_idx, np.ascontiguousarray(gain), log.outputs,
        np.ascontiguousarray(off, dtype=float), e)
    return e, Sinn
