"""LQR and LQE (Kalman) gains, continuous and discrete.

The seed's ``lrq`` and ``lre`` (seeds/002, "Control theory")::

    K, S, E = lqr(A, B, Q, R)        # u = -K x minimises int x'Qx + u'Ru
    L, P, E = lqe(A, G, C, QN, RN)   # xhat_dot = A xhat + B u + L (y - C xhat)

and their discrete counterparts :func:`dlqr` and :func:`dlqe`, with the same
conventions as python-control (whose ``lqr/lqe/dlqr/dlqe`` they reproduce)
but without slycot: the continuous Riccati equation is solved by
:func:`scipy.linalg.solve_continuous_are`, the discrete one (what every
sampled design, and so every simulation, runs) by
:func:`equilibrist.control.fixed.dare`, in a fixed order of IEEE operations
that gives the same bits on every CPU, as do the gains computed from it.

Before solving, the problem is checked so that a failure says why:

* sizes, symmetry and definiteness of the weights (``Q, QN >= 0``,
  ``R, RN > 0``);
* ``(A, B)`` stabilizable (``(A, C)`` detectable): an uncontrollable
  (unobservable) mode on or beyond the stability boundary is named with the
  states it involves;
* no mode on the stability boundary hidden from the weight ``Q`` (not excited
  by the noise ``G QN G'``): such a mode makes the Riccati equation lose its
  stabilizing solution (its Hamiltonian has eigenvalues on the boundary).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from equilibrist.control import checks, fixed
from equilibrist.control.analysis import (
    Mode,
    _pbh_modes,
    _strictly_stable,
    describe_modes,
)
from equilibrist.errors import DesignError


class LQRSolution(NamedTuple):
    """``K`` the gain (``u = -K x``), ``S`` the Riccati solution, ``E`` the closed-loop poles."""

    K: np.ndarray
    S: np.ndarray
    E: np.ndarray


class LQESolution(NamedTuple):
    """``L`` the estimator gain, ``P`` the error covariance, ``E`` the estimator poles.

    For :func:`dlqe`, ``L`` is the predictor gain ``A M`` and ``P`` the
    a-priori (predicted) covariance, as python-control's ``dlqe``.
    """

    L: np.ndarray
    P: np.ndarray
    E: np.ndarray


def _boundary_modes(modes: Sequence[Mode], discrete: bool, scale: float) -> list[Mode]:
    """Modes on the stability boundary (``Re s = 0`` or ``|z| = 1``)."""
    tol = 1e-6
    out = []
    for m in modes:
        lam = m.eigenvalue
        on = abs(abs(lam) - 1.0) <= tol if discrete else abs(lam.real) <= tol * max(scale, 1.0)
        if on:
            out.append(m)
    return out


def _sqrt_psd(mat: np.ndarray) -> np.ndarray:
    """A factor ``F`` with ``F F' = mat`` for a symmetric PSD matrix."""
    w, v = np.linalg.eigh(checks.symmetric(mat))
    factor: np.ndarray = v * np.sqrt(np.clip(w, 0.0, None))
    return factor


def _solve(
    A: object,
    B: object,
    Q: object,
    R: object,
    *,
    discrete: bool,
    estimator: bool,
    state_names: Sequence[str] | None,
    input_names: Sequence[str] | None,
) -> LQRSolution:
    """The regulator problem; *estimator* only changes the words of errors.

    For the estimator, the caller passes the dual ``(A', C', G QN G', RN)``.
    """
    Am = checks.square(A, "A")
    n = Am.shape[0]
    bname, qname, rname = ("C'", "G QN G'", "RN") if estimator else ("B", "Q", "R")
    Bm = checks.with_rows(B, bname, n, "one per state")
    m = Bm.shape[1]
    if m == 0:
        what = "outputs" if estimator else "inputs"
        raise DesignError(f"there are no {what}: {bname} has no columns")
    Qm = checks.matrix(Q, qname, (n, n), f"one row and column per state, {n} states")
    Rm = checks.matrix(
        R,
        rname,
        (m, m),
        f"one row and column per {'output' if estimator else 'input'}, {m} of them",
    )
    checks.raise_if(
        checks.weight_problems(Qm, qname, definite=False)
        + checks.weight_problems(Rm, rname, definite=True)
    )
    names = checks.names(state_names, n, "state")
    scale = float(np.linalg.norm(Am, 2)) if n else 1.0

    # (A, B) stabilizable / (A, C) detectable.
    failing = [
        mode
        for mode in _pbh_modes(Am, Bm, names, discrete)
        if not _strictly_stable(mode.eigenvalue, discrete, scale)
    ]
    if failing:
        if estimator:
            outs = f" ({', '.join(input_names)})" if input_names else ""
            raise DesignError(
                f"(A, C) is not detectable: the outputs{outs} cannot see the unstable or "
                f"marginal mode(s) {describe_modes(failing)}; measure one of those states"
            )
        raise DesignError(
            f"(A, B) is not stabilizable: the input cannot move the unstable or marginal "
            f"mode(s) {describe_modes(failing)}"
        )
    # No mode on the boundary hidden from Q (not excited by the noise).
    hidden = _boundary_modes(_pbh_modes(Am.T, _sqrt_psd(Qm), names, discrete), discrete, scale)
    if hidden:
        if estimator:
            raise DesignError(
                f"the process noise G QN G' does not excite the marginal mode(s) "
                f"{describe_modes(hidden)}, so the Kalman Riccati equation has no stabilizing "
                f"solution: give those states some process noise"
            )
        raise DesignError(
            f"Q does not weight the marginal mode(s) {describe_modes(hidden)}, so the LQR "
            f"Riccati equation has no stabilizing solution: give those states a positive weight"
        )

    try:
        if discrete:
            S = fixed.dare(Am, Bm, Qm, Rm)
        else:
            import scipy.linalg  # here: only a continuous design needs it

            S = scipy.linalg.solve_continuous_are(Am, Bm, Qm, Rm)
    except (np.linalg.LinAlgError, ValueError) as exc:
        kind = "Kalman" if estimator else "LQR"
        raise DesignError(
            f"the {kind} Riccati equation has no stabilizing solution: {exc}"
        ) from None
    S = checks.symmetric(S)
    if discrete:
        K = fixed.solve(fixed.mm(Bm.T, S, Bm) + Rm, fixed.mm(Bm.T, S, Am))
    else:
        K = np.linalg.solve(Rm, Bm.T @ S)
    E = np.linalg.eigvals(Am - Bm @ K)
    if not np.all([_strictly_stable(complex(e), discrete, scale) for e in E]):
        kind = "Kalman" if estimator else "LQR"
        raise DesignError(
            f"the {kind} Riccati solution is not stabilizing (poles {np.round(E, 6).tolist()}): "
            f"the problem is numerically ill-posed; rescale the weights"
        )
    return LQRSolution(K, S, E)


def lqr(
    A: object,
    B: object,
    Q: object,
    R: object,
    *,
    state_names: Sequence[str] | None = None,
) -> LQRSolution:
    """Continuous linear-quadratic regulator.

    Minimises ``int_0^inf x'Qx + u'Ru dt`` for ``x_dot = A x + B u`` with
    ``u = -K x``.

    Parameters
    ----------
    A, B:
        Plant matrices (``n x n``, ``n x m``).
    Q, R:
        State weight (symmetric ``>= 0``) and input weight (symmetric ``> 0``).
    state_names:
        Used to name the modes in error messages.

    Returns
    -------
    LQRSolution
        ``(K, S, E)``: ``K = R^-1 B' S``, ``S`` the stabilizing solution of
        ``A'S + SA - S B R^-1 B' S + Q = 0`` (the optimal cost is
        ``x0' S x0``), ``E`` the eigenvalues of ``A - B K``.

    Raises
    ------
    DimensionError
        Sizes that do not match.
    DesignError
        Weights not symmetric or not (semi)definite; ``(A, B)`` not
        stabilizable; a marginal mode unweighted by ``Q``.
    """
    return _solve(
        A, B, Q, R, discrete=False, estimator=False, state_names=state_names, input_names=None
    )


def dlqr(
    A: object,
    B: object,
    Q: object,
    R: object,
    *,
    state_names: Sequence[str] | None = None,
) -> LQRSolution:
    """Discrete linear-quadratic regulator.

    Minimises ``sum_k x_k'Q x_k + u_k'R u_k`` for ``x_{k+1} = A x_k + B u_k``
    with ``u_k = -K x_k``; ``K = (B'SB + R)^-1 B'SA`` and ``E`` the
    eigenvalues of ``A - B K``. Checks and errors as :func:`lqr`.
    """
    return _solve(
        A, B, Q, R, discrete=True, estimator=False, state_names=state_names, input_names=None
    )


def _estimator(
    A: object, G: object, C: object, QN: object, RN: object, *, discrete: bool,
    state_names: Sequence[str] | None, output_names: Sequence[str] | None,
) -> LQESolution:
    """The estimator as the dual regulator: ``(A', C', G QN G', RN)``, its gain transposed."""
    Am = checks.square(A, "A")
    n = Am.shape[0]
    Cm = checks.with_columns(C, "C", n, "one per state")
    p = Cm.shape[0]
    Gm = checks.with_rows(G, "G", n, "one per state")
    k = Gm.shape[1]
    QNm = checks.matrix(QN, "QN", (k, k), f"one row and column per noise input, {k} of them")
    RNm = checks.matrix(RN, "RN", (p, p), f"one row and column per output, {p} outputs")
    checks.raise_if(
        checks.weight_problems(QNm, "QN", definite=False)
        + checks.weight_problems(RNm, "RN", definite=True)
    )
    W = checks.symmetric(fixed.mm(Gm, QNm, Gm.T))
    K, P, E = _solve(Am.T, Cm.T, W, RNm, discrete=discrete, estimator=True,
                     state_names=state_names, input_names=output_names)
    return LQESolution(K.T, P, E)


def lqe(
    A: object,
    G: object,
    C: object,
    QN: object,
    RN: object,
    *,
    state_names: Sequence[str] | None = None,
    output_names: Sequence[str] | None = None,
) -> LQESolution:
    """Continuous linear-quadratic estimator (Kalman-Bucy filter).

    For ``x_dot = A x + B u + G w``, ``y = C x + v`` with white noises of
    intensities ``QN`` (of ``w``) and ``RN`` (of ``v``), the estimator
    ``xhat_dot = A xhat + B u + L (y - C xhat)`` has the least error
    covariance ``P`` in steady state.

    Returns
    -------
    LQESolution
        ``(L, P, E)``: ``L = P C' RN^-1``, ``P`` the stabilizing solution of
        ``A P + P A' - P C' RN^-1 C P + G QN G' = 0``, ``E`` the
        eigenvalues of ``A - L C``.

    Raises
    ------
    DimensionError, DesignError
        As :func:`lqr`, with ``(A, C)`` detectability (unobservable modes
        named) and the noise exciting every marginal mode.
    """
    return _estimator(A, G, C, QN, RN, discrete=False, state_names=state_names,
                      output_names=output_names)


def dlqe(
    A: object,
    G: object,
    C: object,
    QN: object,
    RN: object,
    *,
    state_names: Sequence[str] | None = None,
    output_names: Sequence[str] | None = None,
) -> LQESolution:
    """Discrete linear-quadratic estimator (steady-state Kalman filter).

    For ``x_{k+1} = A x_k + B u_k + G w_k``, ``y_k = C x_k + v_k`` with
    ``cov(w) = QN``, ``cov(v) = RN``.

    Returns
    -------
    LQESolution
        ``(L, P, E)`` as python-control's ``dlqe``: ``P`` the steady-state
        a-priori covariance (``P = A P A' - A P C'(C P C' + RN)^-1 C P A' + G QN G'``),
        ``L = A M`` the predictor gain with ``M = P C'(C P C' + RN)^-1`` the
        current-form gain, and ``E`` the eigenvalues of ``A - L C``.
    """
    return _estimator(A, G, C, QN, RN, discrete=True, state_names=state_names,
                      output_names=output_names)


def current_gain(P: np.ndarray, C: np.ndarray, RN: np.ndarray) -> np.ndarray:
    """``M = P C'(C P C' + RN)^-1``: the update gain from an a-priori covariance ``P``."""
    S = fixed.mm(C, P, C.T) + RN
    return fixed.solve(S.T, fixed.mm(P, C.T).T).T
