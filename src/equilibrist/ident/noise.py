"""The linear-Gaussian pieces of the fit: the noise levels to start from, the
steady-state Kalman gain, the likelihood of prediction errors, and the inverse
of an information matrix on its determined directions."""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from equilibrist.errors import EquilibristError
from equilibrist.ident.log import IdentificationError, Log
from equilibrist.numeric.system import System

# A log-parameter direction whose information is below this fraction of the
# largest is not determined at all.
STRUCTURAL_RATIO = 1e-9


class FilterFallbackWarning(UserWarning):
    """The model's Kalman filter has no steady state at some parameters: its gain there is the
    one of the process noise alone (``P = Qd``), which the warning names."""


def _steady_gain(Ad: np.ndarray, C: np.ndarray, Qd: np.ndarray,
                 R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The steady-state Kalman gain ``K`` and innovation covariance ``S`` of the sampled
    model: the predictor's covariance from the designs' Riccati solver, else scipy's; where
    neither finds a stabilizing solution, ``P = Qd`` with a :class:`FilterFallbackWarning`."""
    import warnings

    from scipy.linalg import solve_discrete_are

    from equilibrist.control import fixed
    from equilibrist.control.kalman import gain
    from equilibrist.errors import DesignError

    try:
        P = fixed.dare(Ad.T, C.T, Qd, R)
    except (DesignError, np.linalg.LinAlgError):
        try:
            P = solve_discrete_are(Ad.T, C.T, Qd, R)
        except (ValueError, np.linalg.LinAlgError) as exc:
            warnings.warn(FilterFallbackWarning(
                f"the model's Kalman filter has no steady state at these parameters ({exc}): "
                "its prediction errors are weighted with the process noise of one sample "
                "(P = Qd) instead"), stacklevel=2)
            P = Qd.copy()
    S = fixed.symmetric(fixed.mm(C, P, C.T) + R)
    return gain(P, C, R), S


def _negative_log_likelihood(e: np.ndarray, S: np.ndarray) -> float:
    """Twice the negative log-likelihood (less its constant) of Gaussian prediction errors
    *e* (n_rows, ny) of covariance *S*; infinite where an error is not finite."""
    if not np.all(np.isfinite(e)):
        return math.inf
    _sign, logdet = np.linalg.slogdet(S)
    return float(e.shape[0] * logdet + np.einsum("ki,ij,kj->", e, np.linalg.inv(S), e))


def _information_inverse(H: np.ndarray) -> np.ndarray:
    """``H^-1`` by Cholesky, or the pseudo-inverse on the determined directions."""
    from scipy.linalg import LinAlgError, cho_factor, cho_solve

    H = (H + H.T) / 2
    try:
        inverse: np.ndarray = cho_solve(cho_factor(H), np.eye(H.shape[0]))
    except LinAlgError:
        lam, V = np.linalg.eigh(H)
        keep = lam > STRUCTURAL_RATIO * max(float(lam.max()), 1e-300)
        inverse = (V[:, keep] / lam[keep]) @ V[:, keep].T
    return inverse


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
