"""Structural and modal analysis of linear models.

* Controllability and observability: the rank of the Kalman matrices, and
  the modes that fail the Popov-Belevitch-Hautus (PBH) test -- an
  eigenvalue ``lambda`` of ``A`` with ``rank [A - lambda I, B] < n`` is an
  uncontrollable mode; ``rank [A - lambda I; C] < n`` an unobservable one.
  Each failing mode is named by its eigenvalue and the states its direction
  involves, which is what an error message needs to say.
* Poles: natural frequency, damping ratio and time constant (discrete poles
  through their continuous equivalent ``s = ln(z) / dt``).
* Margins of a single-input loop broken at the plant input (the state
  feedback's ``K (sI - A)^-1 B``, or any loop given by its state-space
  matrices, such as an LQG compensator in series with its plant).
"""

from __future__ import annotations

import cmath
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from equilibrist.control import checks
from equilibrist.errors import DesignError

# A mode counts as uncontrollable (unobservable) when the smallest singular
# value of the PBH matrix is below this fraction of ||A||. Defective
# eigenvalues (Jordan blocks of integrators) are computed with errors of
# order sqrt(eps) ||A|| ~ 1.5e-8 ||A||, so the threshold sits above that.
PBH_TOL = 1e-7
# Eigenvalues closer than this fraction of ||A|| are tested as one cluster.
CLUSTER_TOL = 1e-4
# Poles this close (relative to ||A||) to the stability boundary count as on it.
BOUNDARY_TOL = 1e-8


@dataclass(frozen=True)
class Mode:
    """One eigenvalue of ``A`` that fails a PBH test.

    Attributes
    ----------
    eigenvalue:
        The eigenvalue (``s`` in continuous time, ``z`` in discrete time);
        a complex pair is reported once, with a positive imaginary part.
    count:
        How many independent directions fail at this eigenvalue.
    states:
        The states that dominate the failing direction (entries at least a
        quarter of the largest).
    discrete:
        Whether the eigenvalue is a ``z`` (discrete) rather than an ``s``.
    """

    eigenvalue: complex
    count: int
    states: tuple[str, ...]
    discrete: bool = False

    @property
    def is_pair(self) -> bool:
        return abs(self.eigenvalue.imag) > 0.0

    def describe(self) -> str:
        """``s = 3.96 (theta, theta_dot)``, ``s = -0.1 +/- 2j (x, x_dot)``."""
        var = "z" if self.discrete else "s"
        re, im = self.eigenvalue.real, self.eigenvalue.imag
        value = f"{re:.4g} +/- {abs(im):.4g}j" if self.is_pair else f"{re:.4g}"
        times = f" (x{self.count})" if self.count > 1 else ""
        return f"{var} = {value}{times} ({', '.join(self.states)})"


@dataclass(frozen=True)
class Structure:
    """Controllability of ``(A, B)`` or observability of ``(A, C)``.

    Attributes
    ----------
    kind:
        ``"controllability"`` or ``"observability"``.
    n_states:
        Size of ``A``.
    rank:
        Numerical rank of the Kalman matrix ``[B, AB, ...]`` (or its dual),
        computed with ``A`` scaled to unit norm and each column of ``B``
        (row of ``C``) normalised.
    modes:
        Eigenvalues that fail the PBH test, with the states they involve.
    """

    kind: str
    n_states: int
    rank: int
    modes: tuple[Mode, ...]
    discrete: bool = False

    @property
    def full(self) -> bool:
        """Controllable (observable): no mode fails the PBH test."""
        return not self.modes

    @property
    def unstable_modes(self) -> tuple[Mode, ...]:
        """Failing modes on or beyond the stability boundary."""
        return tuple(m for m in self.modes if not _strictly_stable(m.eigenvalue, self.discrete))

    @property
    def stabilizable(self) -> bool:
        """Stabilizable (detectable): every failing mode is strictly stable."""
        return not self.unstable_modes

    def to_dict(self) -> dict[str, object]:
        return {
            "rank": self.rank,
            "n_states": self.n_states,
            "full": self.full,
            "stabilizable" if self.kind == "controllability" else "detectable": self.stabilizable,
            "modes": [
                {
                    "re": m.eigenvalue.real,
                    "im": m.eigenvalue.imag,
                    "count": m.count,
                    "states": list(m.states),
                }
                for m in self.modes
            ],
        }


def _strictly_stable(value: complex, discrete: bool, scale: float = 1.0) -> bool:
    if discrete:
        return abs(value) < 1.0 - BOUNDARY_TOL
    return value.real < -BOUNDARY_TOL * max(scale, 1.0)


def _norm(A: np.ndarray) -> float:
    value = float(np.linalg.norm(A, 2)) if A.size else 0.0
    return value if value > 0 else 1.0


def _normalised_columns(B: np.ndarray, size: float) -> np.ndarray:
    norms = np.linalg.norm(B, axis=0)
    safe = np.where(norms > 0, norms, 1.0)
    return B / safe * size


def _clusters(eigs: np.ndarray, tol: float) -> list[np.ndarray]:
    remaining = list(range(len(eigs)))
    groups: list[np.ndarray] = []
    while remaining:
        seed = remaining.pop(0)
        members = [seed]
        changed = True
        while changed:
            changed = False
            for j in list(remaining):
                if min(abs(eigs[j] - eigs[i]) for i in members) <= tol:
                    members.append(j)
                    remaining.remove(j)
                    changed = True
        groups.append(eigs[members])
    return groups


def _pbh_modes(
    A: np.ndarray, B: np.ndarray, state_names: tuple[str, ...], discrete: bool
) -> tuple[Mode, ...]:
    """Modes of ``A`` with ``rank [A - lambda I, B] < n`` (left null directions)."""
    n = A.shape[0]
    if n == 0:
        return ()
    size = _norm(A)
    Bn = _normalised_columns(B, size)
    eigs = np.linalg.eigvals(A)
    modes: list[Mode] = []
    for group in _clusters(eigs, CLUSTER_TOL * size):
        if np.mean(group).imag < -CLUSTER_TOL * size:
            continue  # its conjugate is reported
        best_count, best_u = 0, None
        for lam in (np.mean(group), *group):
            M = np.hstack([A - lam * np.eye(n), Bn])
            U, s, _ = np.linalg.svd(M)
            count = int(np.sum(s <= PBH_TOL * size)) + max(0, n - s.size)
            if count > best_count:
                best_count, best_u = count, U[:, n - count :]
        if best_count == 0 or best_u is None:
            continue
        lam = complex(np.mean(group))
        if abs(lam.imag) <= CLUSTER_TOL * size:
            lam = complex(lam.real, 0.0)
        weight = np.linalg.norm(best_u, axis=1)
        involved = tuple(
            name for name, w in zip(state_names, weight, strict=True) if w >= 0.25 * weight.max()
        )
        modes.append(Mode(lam, min(best_count, group.size), involved, discrete))
    modes.sort(key=lambda m: -abs(m.eigenvalue) if discrete else -m.eigenvalue.real)
    return tuple(modes)


def _kalman_rank(A: np.ndarray, B: np.ndarray) -> int:
    n = A.shape[0]
    if n == 0:
        return 0
    if B.shape[1] == 0:
        return 0
    As = A / _norm(A)
    Bn = _normalised_columns(B, 1.0)
    blocks = [Bn]
    for _ in range(n - 1):
        blocks.append(As @ blocks[-1])
    return int(np.linalg.matrix_rank(np.hstack(blocks)))


def controllability(
    A: object,
    B: object,
    *,
    state_names: Sequence[str] | None = None,
    discrete: bool = False,
) -> Structure:
    """Controllability of ``(A, B)``: Kalman rank and the PBH-uncontrollable modes.

    Parameters
    ----------
    A, B:
        State and input matrices (``n x n``, ``n x m``).
    state_names:
        Names used to say which states a failing mode involves.
    discrete:
        Whether ``A`` is a discrete-time transition matrix (decides what
        counts as stabilizable: ``|z| < 1`` instead of ``Re s < 0``).

    Returns
    -------
    Structure
    """
    Am = checks.square(A, "A")
    n = Am.shape[0]
    Bm = checks.with_rows(B, "B", n, "one per state")
    names = checks.names(state_names, n, "state")
    return Structure(
        "controllability", n, _kalman_rank(Am, Bm), _pbh_modes(Am, Bm, names, discrete), discrete
    )


def observability(
    A: object,
    C: object,
    *,
    state_names: Sequence[str] | None = None,
    discrete: bool = False,
) -> Structure:
    """Observability of ``(A, C)``: Kalman rank and the PBH-unobservable modes.

    The dual of :func:`controllability` (``(A', C')``); a failing mode is
    named by the states of its (right) eigenvector, the states that the
    outputs cannot see.
    """
    Am = checks.square(A, "A")
    n = Am.shape[0]
    Cm = checks.with_columns(C, "C", n, "one per state")
    names = checks.names(state_names, n, "state")
    return Structure(
        "observability",
        n,
        _kalman_rank(Am.T, Cm.T),
        _pbh_modes(Am.T, Cm.T, names, discrete),
        discrete,
    )


def describe_modes(modes: Sequence[Mode]) -> str:
    return "; ".join(m.describe() for m in modes)


# -- poles -------------------------------------------------------------------------


@dataclass(frozen=True)
class PoleInfo:
    """One pole with its continuous-time equivalent and derived figures.

    ``natural_frequency`` [rad/s] is ``|s|``; ``damping`` is ``-Re(s)/|s|``
    (NaN for ``s = 0``); ``time_constant`` [s] is ``-1/Re(s)`` for a decaying
    pole and infinity otherwise. For a discrete pole ``z``, ``s = ln(z)/dt``
    (``z = 0`` decays at once: ``s = -inf``, time constant 0, damping 1).
    """

    pole: complex
    s: complex
    natural_frequency: float
    damping: float
    time_constant: float

    def to_dict(self) -> dict[str, object]:
        return {
            "re": self.pole.real,
            "im": self.pole.imag,
            "natural_frequency": self.natural_frequency,
            "damping": self.damping,
            "time_constant": self.time_constant,
        }


def pole_table(
    poles: Sequence[complex] | np.ndarray, *, dt: float | None = None
) -> tuple[PoleInfo, ...]:
    """Natural frequency, damping ratio and time constant of each pole.

    Parameters
    ----------
    poles:
        Continuous poles ``s``, or discrete poles ``z`` when *dt* is given.
    dt:
        Sample period [s] of discrete poles; None for continuous ones.
    """
    out: list[PoleInfo] = []
    for raw in np.asarray(poles, dtype=complex).reshape(-1):
        p = complex(raw)
        if dt is not None:
            if p == 0:
                out.append(PoleInfo(p, complex(-math.inf, 0.0), math.inf, 1.0, 0.0))
                continue
            s = cmath.log(p) / dt
        else:
            s = p
        wn = abs(s)
        damping = -s.real / wn if wn > 0 else math.nan
        tau = -1.0 / s.real if s.real < 0 else math.inf
        out.append(PoleInfo(p, s, wn, damping, tau))
    return tuple(out)


# -- margins -----------------------------------------------------------------------


@dataclass(frozen=True)
class Margins:
    """Margins of a single-input loop ``L`` broken at the plant input.

    ``L`` is in negative feedback: the loop closes as ``1 + L = 0``. For a
    state feedback ``u = -K x`` it is ``L = K (sI - A)^-1 B``; for an LQG
    design, the compensator (its estimator fed its own command) in series
    with the plant (:func:`equilibrist.control.interop.loop_at_input`).

    Attributes
    ----------
    gain_lower, gain_upper:
        The loop stays stable while its gain is scaled by a factor between
        these two (the nearest points where ``L`` is real and negative on
        either side of -1). For an open-loop unstable plant ``gain_lower``
        is above 0 (reducing the gain destabilizes); ``gain_upper`` is
        infinite for a continuous LQR loop.
    lower_crossover, upper_crossover:
        Their phase-crossover frequencies [rad/s] (NaN when there is none).
    phase_margin:
        Degrees of extra lag tolerated at the gain crossover ``|L| = 1``
        (infinity when there is none; the smallest in magnitude when there
        are several).
    gain_crossover:
        Its frequency [rad/s].
    return_difference:
        The smallest ``|1 + L|`` over the frequencies (the distance of the
        Nyquist plot from -1; at least 1 for a continuous single-input LQR
        by Kalman's inequality, with no such bound for an LQG loop).
    """

    gain_lower: float
    gain_upper: float
    lower_crossover: float
    upper_crossover: float
    phase_margin: float
    gain_crossover: float
    return_difference: float

    @staticmethod
    def _db(value: float) -> float:
        if value == 0:
            return -math.inf
        return 20.0 * math.log10(value) if math.isfinite(value) else math.inf

    @property
    def gain_lower_db(self) -> float:
        return self._db(self.gain_lower)

    @property
    def gain_upper_db(self) -> float:
        return self._db(self.gain_upper)

    def to_dict(self) -> dict[str, float]:
        return {
            "gain_lower": self.gain_lower,
            "gain_lower_db": self.gain_lower_db,
            "lower_crossover": self.lower_crossover,
            "gain_upper": self.gain_upper,
            "gain_upper_db": self.gain_upper_db,
            "upper_crossover": self.upper_crossover,
            "phase_margin_deg": self.phase_margin,
            "gain_crossover": self.gain_crossover,
            "return_difference": self.return_difference,
        }


def _response(
    A: np.ndarray, B: np.ndarray, K: np.ndarray, D: float, dt: float | None, w: np.ndarray
) -> np.ndarray:
    """``L = K (pI - A)^-1 B + D`` at ``p = jw`` (or ``e^{jw dt}``) for an array of ``w``."""
    n = A.shape[0]
    p = np.exp(1j * w * dt) if dt is not None else 1j * w
    X = np.linalg.solve(p[:, None, None] * np.eye(n) - A, np.broadcast_to(B, (w.size, n, 1)))
    return (K @ X)[:, 0, 0] + D


def _roots(f: Callable[[float], float], w: np.ndarray, values: np.ndarray) -> list[float]:
    """Frequencies where *values* (= f on the grid *w*) change sign, refined by Brent's method."""
    from scipy.optimize import brentq

    out = []
    for i in np.nonzero(np.sign(values[:-1]) * np.sign(values[1:]) < 0)[0]:
        out.append(float(brentq(f, w[i], w[i + 1], xtol=1e-14 * w[i + 1], rtol=1e-13)))
    return out


def loop_margins(
    A: object, B: object, K: object, *, dt: float | None = None, D: float = 0.0
) -> Margins:
    """Gain and phase margins of a single-input loop broken at the plant input.

    The loop is ``L(s) = K (sI - A)^-1 B + D`` (``L(z)`` with
    ``z = e^{j w dt}`` for a discrete loop, up to the Nyquist frequency
    ``pi / dt``) in negative feedback: a state feedback ``u = -K x`` with
    ``A, B`` the plant's, or any single-input single-output loop given by
    its state-space matrices (``K`` its output row, ``D`` its
    feedthrough), such as an LQG compensator in series with its plant
    (:func:`equilibrist.control.interop.loop_at_input`). Crossovers are
    located on a dense logarithmic grid (and at ``w = 0`` and the Nyquist
    frequency) and refined by Brent's method, the closest approach to -1
    by a bounded minimization. python-control's ``stability_margins``
    agrees for continuous loops, but for sampled loops with poles at
    ``z = 1`` (the cart's position and speed) its polynomial method finds
    spurious crossovers (it reports a negative phase margin for the
    cart-pole's stable 50 Hz state feedback; ``method="frd"`` agrees),
    hence this direct computation.

    Raises
    ------
    DesignError
        For a plant with more than one input (the margins of a
        multi-input loop are not a pair of numbers).
    """
    from scipy.optimize import minimize_scalar

    Am = checks.square(A, "A")
    n = Am.shape[0]
    Bm = checks.with_rows(B, "B", n, "one per state")
    m = Bm.shape[1]
    if m != 1:
        raise DesignError(f"loop margins need a single-input plant, this one has {m} inputs")
    Km = checks.matrix(np.reshape(np.asarray(K, dtype=float), (1, -1)), "K", (1, n))
    Dv = float(np.asarray(D, dtype=float).reshape(-1)[0]) if np.size(D) == 1 else math.nan
    if not math.isfinite(Dv):
        raise DesignError(f"the loop's feedthrough D must be one finite number, got {D!r}")
    if dt is not None:
        dt = checks.positive_period(dt)
        top = math.pi / dt
    else:
        top = 1e4 * max(_norm(Am), float(np.abs(Km @ Bm).max()), 1.0)
    w = np.logspace(-4, math.log10(top), 6000)
    w[-1] = top
    L = _response(Am, Bm, Km, Dv, dt, w)

    def at(x: float) -> complex:
        return complex(_response(Am, Bm, Km, Dv, dt, np.array([x]))[0])

    # Gain crossovers |L| = 1: phase margin 180 deg + arg L, in (-180, 180].
    gain_cross = _roots(lambda x: abs(at(x)) - 1.0, w, np.abs(L) - 1.0)
    pm, wgc = math.inf, math.nan
    for x in gain_cross:
        margin = (math.degrees(cmath.phase(at(x))) + 360.0) % 360.0 - 180.0
        if abs(margin) < abs(pm):
            pm, wgc = margin, x
    # Phase crossovers: L real and negative (also at w = 0, at Nyquist, and at
    # infinity for a continuous loop with a feedthrough).
    candidates = [(x, at(x).real) for x in _roots(lambda x: at(x).imag, w, L.imag)]
    closed0 = (np.eye(n) if dt is not None else np.zeros((n, n))) - Am
    if np.linalg.cond(closed0) < 1e12:
        candidates.append((0.0, float((Km @ np.linalg.solve(closed0, Bm))[0, 0]) + Dv))
    if dt is not None:
        candidates.append((top, L[-1].real))
    elif Dv < 0:
        candidates.append((math.inf, Dv))
    lower, w_lower, upper, w_upper = 0.0, math.nan, math.inf, math.nan
    for x, re in candidates:
        if re >= 0:
            continue
        factor = -1.0 / re
        if 1.0 > factor > lower:
            lower, w_lower = factor, x
        elif 1.0 <= factor < upper:
            upper, w_upper = factor, x
    # The closest approach to -1: the grid's, refined between its neighbours.
    distance = np.abs(1.0 + L)
    i = int(np.argmin(distance))
    closest = float(distance[i])
    if 0 < i < w.size - 1:
        found = minimize_scalar(lambda x: abs(1.0 + at(x)), bounds=(w[i - 1], w[i + 1]),
                                method="bounded", options={"xatol": 1e-12 * w[i + 1]})
        closest = min(closest, float(found.fun))
    return Margins(lower, upper, w_lower, w_upper, pm, wgc, closest)
