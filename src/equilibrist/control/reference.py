"""The reference gain ``Kc`` that makes the tracked outputs settle at ``r``.

With ``u = -K x + Kc r`` (seeds/002, "Control with desired point") the
steady state of ``x_dot = A x + B u`` is ``x_d = -(A - BK)^-1 B Kc r``;
asking ``C_r x_d = r`` gives

    continuous  ``Kc = -(C_r (A - B K)^-1 B)^-1``
    discrete    ``Kc = (C_r (I - (F - G K))^-1 G)^-1``

with ``C_r`` the rows of the tracked outputs, as many as inputs (the matrix
inverse for several). A tracked output that a constant input cannot hold
away from its operating value (a pendulum's angle) has zero DC gain: the
inverse does not exist, and that is an error, not an infinity.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from equilibrist.control import checks, fixed
from equilibrist.errors import DesignError, DimensionError

# A DC gain below this fraction of ||C_r|| ||(A - BK)^-1 B|| counts as zero.
ZERO_GAIN_TOL = 1e-9


def _gain(
    closed: np.ndarray,
    Bm: np.ndarray,
    Cr: np.ndarray,
    tracked: tuple[str, ...],
    inputs: tuple[str, ...],
    sign: float,
    what: str,
) -> np.ndarray:
    try:
        cond = np.linalg.cond(closed)
    except np.linalg.LinAlgError:
        cond = np.inf
    if not np.isfinite(cond) or cond > 1e14:
        raise DesignError(
            f"{what} is singular: the state feedback leaves a pole at "
            f"{'z = 1' if sign > 0 else 's = 0'}, so no reference gain exists"
        )
    XB = fixed.solve(closed, Bm)  # (A - BK)^-1 B or (I - F + GK)^-1 G
    dc = fixed.matmul(Cr, XB)
    scale = max(float(np.linalg.norm(Cr, 2) * np.linalg.norm(XB, 2)), 1e-300)
    zero_rows = [
        tracked[i] for i in range(dc.shape[0]) if np.linalg.norm(dc[i]) <= ZERO_GAIN_TOL * scale
    ]
    if zero_rows:
        many = len(zero_rows) > 1
        raise DesignError(
            f"tracked output{'s' if many else ''} {', '.join(zero_rows)} "
            f"{'have' if many else 'has'} zero DC gain from {', '.join(inputs)}: a constant "
            f"input cannot hold {'them' if many else 'it'} away from the operating point, "
            f"so there is no reference gain Kc (track another output, listed first)"
        )
    s = np.linalg.svd(dc, compute_uv=False)
    if s[-1] <= ZERO_GAIN_TOL * scale:
        raise DesignError(
            f"the DC gains from {', '.join(inputs)} to the tracked outputs "
            f"{', '.join(tracked)} are dependent (smallest singular value {s[-1]:.3g}), "
            f"so there is no reference gain Kc"
        )
    return sign * fixed.solve(dc, np.eye(dc.shape[0]))


def _args(
    A: object,
    B: object,
    C_r: object,
    K: object,
    tracked_names: Sequence[str] | None,
    input_names: Sequence[str] | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, tuple[str, ...], tuple[str, ...]]:
    Am = checks.square(A, "A")
    n = Am.shape[0]
    Bm = checks.with_rows(B, "B", n, "one per state")
    m = Bm.shape[1]
    Cr = checks.with_columns(C_r, "C_r", n, "one per state")
    if Cr.shape[0] != m:
        raise DimensionError(
            f"C_r has {Cr.shape[0]} rows, expected one tracked output per input ({m})"
        )
    Km = checks.matrix(K, "K", (m, n), "one row per input, one column per state")
    tracked = checks.names(tracked_names, m, "tracked output")
    inputs = checks.names(input_names, m, "input")
    return Am, Bm, Cr, Km, tracked, inputs


def reference_gain(
    A: object,
    B: object,
    C_r: object,
    K: object,
    *,
    tracked_names: Sequence[str] | None = None,
    input_names: Sequence[str] | None = None,
) -> np.ndarray:
    """Continuous reference gain ``Kc = -(C_r (A - B K)^-1 B)^-1``.

    Parameters
    ----------
    A, B:
        Continuous plant (``n x n``, ``n x m``).
    C_r:
        ``m x n`` rows of the tracked outputs (one per input).
    K:
        ``m x n`` state-feedback gain, ``u = -K x + Kc r``.
    tracked_names, input_names:
        Names for the error messages.

    Returns
    -------
    numpy.ndarray
        ``m x m`` gain ``Kc``.

    Raises
    ------
    DesignError
        ``A - B K`` singular, or a tracked output with zero DC gain (named).
    """
    Am, Bm, Cr, Km, tracked, inputs = _args(A, B, C_r, K, tracked_names, input_names)
    return _gain(Am - fixed.matmul(Bm, Km), Bm, Cr, tracked, inputs, -1.0, "A - B K")


def discrete_reference_gain(
    F: object,
    G: object,
    C_r: object,
    K: object,
    *,
    tracked_names: Sequence[str] | None = None,
    input_names: Sequence[str] | None = None,
) -> np.ndarray:
    """Discrete reference gain ``Kc = (C_r (I - (F - G K))^-1 G)^-1``.

    ``F, G`` are the discrete plant's transition and input matrices; the
    other arguments and the errors are those of :func:`reference_gain`.
    """
    Fm, Gm, Cr, Km, tracked, inputs = _args(F, G, C_r, K, tracked_names, input_names)
    n = Fm.shape[0]
    return _gain(np.eye(n) - (Fm - fixed.matmul(Gm, Km)), Gm, Cr, tracked, inputs, 1.0, "I - (F - G K)")
