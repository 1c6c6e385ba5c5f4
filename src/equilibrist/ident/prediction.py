"""The prediction-error stage of :func:`equilibrist.ident.fit.identify`: the one-step
prediction errors of the model's Kalman filter as residuals (:class:`_Predictor`),
and the filter's loops (compiled, or scipy's ``solve_ivp``)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from equilibrist.control.discretize import sampled_noise
from equilibrist.ident.noise import _negative_log_likelihood, _steady_gain
from equilibrist.ident.shooting import _Unknowns
from equilibrist.numeric.system import System


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
    # (K, S) by (p, q, q_factor, sigma_y), and (A_d, Q_d) by (p, q): see gain()
    memo: dict[tuple[bytes | float, ...], tuple[np.ndarray, np.ndarray]] = field(
        default_factory=dict)

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
            known: tuple[np.ndarray, np.ndarray] = self.memo[key]
            return known
        n, ny = self.n, self.ny
        lin_key = key[:2]
        if lin_key not in self.memo:
            A = np.empty((n, n))
            B = np.empty((n, self.system.n_inputs))
            with np.errstate(all="ignore"):
                self.system.functions.jac(self.x_lin, self.u_lin, p, A, B)
            if not np.all(np.isfinite(A)):
                A = np.zeros((n, n))
            self.memo[lin_key] = sampled_noise(A, np.diag(self.q), self.dt)
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

        has_q = bool(np.any(self.q > 0))

        def nll(v: np.ndarray) -> float:
            return _negative_log_likelihood(
                *self.errors(z, math.exp(v[0]) if has_q else 1.0, self.sigma_y * np.exp(v[1:])))

        v0 = np.zeros(1 + self.ny)
        simplex = np.vstack([v0, 0.2 * np.eye(v0.size)])  # factors of 1.2 to start
        res = minimize(nll, v0, method="Nelder-Mead",
                       options={"xatol": 0.005, "fatol": 0.05, "maxfev": 400,
                                "initial_simplex": simplex})
        v = np.clip(res.x, -math.log(1e3), math.log(1e3)) if math.isfinite(res.fun) else v0
        return (math.exp(v[0]) if has_q else 1.0), np.exp(v[1:])


def _solve_ivp_filter(system: System) -> Callable[..., None]:
    """The Kalman filter's prediction errors with :func:`scipy.integrate.solve_ivp`
    over each sample interval (the same loop as the compiled filter). The measurement
    update is the estimator's own (:func:`equilibrist.control.kalman.estimator_namespace`:
    ``kf_innovation`` and ``kf_estimate``, the functions every controller's filter runs), on
    the measurements less the sensors' offsets."""
    from scipy.integrate import solve_ivp

    from equilibrist.control.kalman import estimator_namespace

    fn = system.functions.f
    n = system.n_states
    kf = estimator_namespace()
    innovation, estimate = kf["kf_innovation"], kf["kf_estimate"]
    empty = np.zeros(0)

    def innovations(p: np.ndarray, x0: np.ndarray, t: np.ndarray, u: np.ndarray, n_sub: np.ndarray,
                    c_idx: np.ndarray, gain: np.ndarray, y: np.ndarray, off: np.ndarray,
                    e: np.ndarray) -> None:
        x = x0.copy()
        ny = c_idx.shape[0]
        sel = np.asarray(c_idx, dtype=float)
        g = np.ascontiguousarray(gain, dtype=float).reshape(-1)
        for k in range(t.shape[0]):
            yk = y[k] - off
            e[k] = [innovation(j, x, yk, sel, empty, empty) for j in range(ny)]
            x = np.array([estimate(i, x, yk, g, ny, sel, empty, empty, 1) for i in range(n)])
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


def _filter(system: System, backend: str) -> Callable[..., None]:
    if backend == "compiled":
        from equilibrist.ident.kernel import load_shooting

        filt: Callable[..., None] = load_shooting(system).innovations
        return filt
    return _solve_ivp_filter(system)
