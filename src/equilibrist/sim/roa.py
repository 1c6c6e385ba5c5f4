"""How far can it lean, how hard can it be pushed: the region of attraction, estimated.

Everything here runs the real loop (the compiled batch: the sampled,
saturated, nonlinear loop as ``simulate`` runs it) and finds where it
catches the state:

* :func:`estimate_slice`: a 2-D slice of the state (the others at the
  operating point) sampled on a grid, then refined where neighbours
  disagree (a quadtree along the boundary), so the rollouts go where the
  boundary is, not on a uniform grid;
* :func:`max_tilt`: the largest initial deviation of one coordinate (from
  rest) recovered on both sides, by bracketing and refining;
* :func:`max_push`: the largest impulse on the first input (the input's unit
  times seconds) recovered from rest. An impulse ``J`` at the operating
  point changes the velocities at once by ``M(q)^-1 B_u J``, which is
  ``B J`` with ``B`` the linearization's input matrix there (exact: the
  mass matrix depends on the configuration, which an impulse does not
  move); the run starts from ``x_op + B J``.

Sampling finds counterexamples; it proves nothing (docs/roa.md). The
largest level set of the LQR's Riccati solution that no sample falsifies is
reported as ``rho_sampled``, an estimate, not a certificate.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from equilibrist.errors import SimulationError
from equilibrist.numeric.system import System


@dataclass(frozen=True, eq=False)
class SliceEstimate:
    """The sampled starts of a 2-D slice and whether the loop caught each.

    Attributes
    ----------
    states:
        The two states of the slice.
    bounds:
        ``((low, high), (low, high))`` of each (absolute values).
    points:
        ``(samples, 2)`` starts (absolute values of the two states).
    caught:
        Whether each run stayed in the system's region and ended balanced
        (:func:`equilibrist.tasks.balance_box`).
    x0s:
        ``(samples, n)`` the whole initial states.
    levels:
        Refinements made after the first grid.
    """

    states: tuple[str, str]
    bounds: tuple[tuple[float, float], tuple[float, float]]
    points: np.ndarray
    caught: np.ndarray
    x0s: np.ndarray
    levels: int

    @property
    def samples(self) -> int:
        return int(self.caught.size)

    @property
    def fraction_caught(self) -> float:
        return float(self.caught.mean()) if self.caught.size else math.nan


def default_slice(system: System) -> tuple[str, str] | None:
    """The slice ``roa`` draws by default: the first coordinate of the system's fall region
    and its rate (or the first other state when it has none); None when there is no region."""
    region = list(system.spec.region)
    if not region:
        return None
    first = region[0]
    rate = f"{first}_dot"
    second = rate if rate in system.state_names else next(
        s for s in system.state_names if s != first)
    return first, second


def default_bounds(system: System, states: tuple[str, ...],
                   x_op: np.ndarray) -> dict[str, tuple[float, float]]:
    """The default bounds of those *states* that have one (absolute values): a state of the
    fall region its region's; the rate of one, three times that region's width per second
    about the operating point (``1.5`` widths each side)."""
    region = system.spec.region
    out: dict[str, tuple[float, float]] = {}
    for s in states:
        if s in region:
            lo, hi = region[s]
            out[s] = (float(lo), float(hi))
    for s in states:
        base = s[:-4] if s.endswith("_dot") else None
        if s not in out and base in region:
            half = 1.5 * (float(region[base][1]) - float(region[base][0]))
            c = float(x_op[system.state_index(s)])
            out[s] = (c - half, c + half)
    return out


def outcomes(system: System, controller: object, x0s: np.ndarray, options: Mapping[str, Any],
             seed: int) -> np.ndarray:
    """Whether the loop catches each start (see :class:`SliceEstimate`'s ``caught``)."""
    from equilibrist.sim.batch import simulate_batch

    if x0s.shape[0] == 0:
        return np.zeros(0, dtype=bool)
    batch = simulate_batch(system, controller, runs=x0s.shape[0], x0=x0s, seed=seed,
                           **dict(options))
    # Caught: never left the region, and ended balanced (equilibrist.tasks.balance_box).
    assert batch.balanced_since is not None
    caught: np.ndarray = ~np.asarray(batch.fell, dtype=bool) & np.isfinite(batch.balanced_since)
    return caught


def estimate_slice(system: System, controller: object, states: tuple[str, str],
                   bounds: tuple[tuple[float, float], tuple[float, float]], *, x_op: np.ndarray,
                   grid: int = 24, max_samples: int = 100_000, seed: int = 0,
                   **options: object) -> SliceEstimate:
    """The slice *states* over *bounds*, refined along the boundary up to *max_samples* runs.

    A first ``(grid + 1)^2`` grid; then each cell whose corners disagree
    (caught and not) is split in four, its new corners run, until no cell
    disagrees or the next level would pass *max_samples*. *options* go to
    :func:`~equilibrist.sim.batch.simulate_batch` (``duration`` is required).
    """
    idx = [system.state_names.index(s) for s in states]
    (lo0, hi0), (lo1, hi1) = bounds
    if not (hi0 > lo0 and hi1 > lo1):
        raise SimulationError(f"the slice's bounds {bounds} are empty")
    levels_max = 12
    scale = 2**levels_max  # lattice: grid * scale steps per side
    known: dict[tuple[int, int], bool] = {}

    def run(keys: list[tuple[int, int]]) -> None:
        keys = [k for k in dict.fromkeys(keys) if k not in known]
        if not keys:
            return
        lat = np.array(keys, dtype=float) / (grid * scale)
        x0s = np.tile(np.asarray(x_op, dtype=float), (len(keys), 1))
        x0s[:, idx[0]] = lo0 + lat[:, 0] * (hi0 - lo0)
        x0s[:, idx[1]] = lo1 + lat[:, 1] * (hi1 - lo1)
        got = outcomes(system, controller, x0s, options, seed + len(known))
        known.update(zip(keys, got.tolist(), strict=True))

    step = scale
    run([(i * step, j * step) for i in range(grid + 1) for j in range(grid + 1)])
    cells = [(i * step, j * step) for i in range(grid) for j in range(grid)]
    level = 0
    while level < levels_max:
        mixed = [(i, j) for i, j in cells
                 if len({known[(i, j)], known[(i + step, j)], known[(i, j + step)],
                         known[(i + step, j + step)]}) > 1]
        if not mixed:
            break
        half = step // 2
        new = [(i + a, j + b) for i, j in mixed for a, b in
               ((half, 0), (0, half), (half, half), (step, half), (half, step))]
        if len(known) + len(set(new) - set(known)) > max_samples:
            break
        run(new)
        cells = [(i + a, j + b) for i, j in mixed for a in (0, half) for b in (0, half)]
        step = half
        level += 1
    keys = list(known)
    lat = np.array(keys, dtype=float) / (grid * scale)
    points = np.column_stack([lo0 + lat[:, 0] * (hi0 - lo0), lo1 + lat[:, 1] * (hi1 - lo1)])
    x0s = np.tile(np.asarray(x_op, dtype=float), (len(keys), 1))
    x0s[:, idx[0]], x0s[:, idx[1]] = points[:, 0], points[:, 1]
    return SliceEstimate(states=states, bounds=bounds, points=points,
                         caught=np.array([known[k] for k in keys], dtype=bool), x0s=x0s,
                         levels=level)


def _largest(system: System, controller: object, start: np.ndarray, direction: np.ndarray,
             limit: float, options: Mapping[str, object], seed: int, rounds: int = 3,
             per_round: int = 32) -> tuple[float, list[np.ndarray], list[bool]]:
    """The largest ``a`` in ``[0, limit]`` with every sampled ``start + s direction``,
    ``0 <= s <= a``, caught: a grid of *per_round* values, then the same inside the bracket
    where the first fall is, *rounds* times. Returns ``a`` and every start run."""
    runs: list[np.ndarray] = []
    seen: list[bool] = []
    lo, hi = 0.0, float(limit)
    for r in range(rounds):
        s = np.linspace(lo, hi, per_round + 1)[1:]
        x0s = start + np.outer(s, direction)
        got = outcomes(system, controller, x0s, options, seed + r)
        runs += list(x0s)
        seen += got.tolist()
        fell = np.nonzero(~got)[0]
        if fell.size == 0:
            return hi, runs, seen
        first = int(fell[0])
        lo, hi = (s[first - 1] if first > 0 else lo), s[first]
    return lo, runs, seen


def max_tilt(system: System, controller: object, state: str, limit: float, *,
             x_op: np.ndarray, seed: int = 0,
             **options: object) -> tuple[float, float, list[np.ndarray], list[bool]]:
    """``(down, up)``: the largest deviation of *state* below and above the operating point
    recovered from rest (every sampled smaller one recovered too), and the starts run."""
    i = system.state_names.index(state)
    e = np.zeros(system.n_states)
    e[i] = 1.0
    start = np.asarray(x_op, dtype=float)
    up, r1, o1 = _largest(system, controller, start, e, limit, options, seed)
    down, r2, o2 = _largest(system, controller, start, -e, limit, options, seed + 10)
    return down, up, r1 + r2, o1 + o2


def max_push(system: System, controller: object, limit: float, *, x_op: np.ndarray,
             u_op: np.ndarray, seed: int = 0,
             **options: object) -> tuple[float, float, list[np.ndarray], list[bool]]:
    """``(negative, positive)``: the largest impulse on the first input [its unit x s]
    recovered from rest at the operating point, each way, and the starts run."""
    lm = system.linearize(np.asarray(x_op, dtype=float), np.asarray(u_op, dtype=float))
    b = np.asarray(lm.B, dtype=float)[:, 0]
    if not np.any(b):
        raise SimulationError(f"the first input of {system.key} moves nothing at the operating "
                              "point: no push to measure")
    start = np.asarray(x_op, dtype=float)
    pos, r1, o1 = _largest(system, controller, start, b, limit, options, seed + 20)
    neg, r2, o2 = _largest(system, controller, start, -b, limit, options, seed + 30)
    return neg, pos, r1 + r2, o1 + o2


def rho_sampled(S: np.ndarray, x_op: np.ndarray, x0s: np.ndarray,
                caught: np.ndarray) -> float:
    """The largest level ``rho`` of ``V = dx' S dx`` that no sampled start falsifies: the
    least ``V`` of a start that fell (inf when none fell). An estimate, not a proof."""
    fell = ~np.asarray(caught, dtype=bool)
    if not fell.any():
        return math.inf
    return float(np.min(levels_of(S, x_op, np.asarray(x0s, dtype=float)[fell])))


def levels_of(S: np.ndarray, x_op: np.ndarray, x0s: np.ndarray) -> np.ndarray:
    """``V = dx' S dx`` of each start."""
    dx = np.asarray(x0s, dtype=float) - x_op
    v: np.ndarray = np.einsum("ij,jk,ik->i", dx, S, dx)
    return v


def sample_level(S: np.ndarray, x_op: np.ndarray, rho: float, count: int,
                 seed: int = 0) -> np.ndarray:
    """*count* starts drawn uniformly from the ellipsoid ``dx' S dx <= rho`` (half of them on
    its surface, where a falsifying start is likeliest)."""
    n = S.shape[0]
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(count, n))
    z /= np.linalg.norm(z, axis=1)[:, None]
    radius = np.sqrt(rho) * rng.uniform(size=count) ** (1.0 / n)
    radius[: count // 2] = np.sqrt(rho) * (1.0 - 1e-9)
    T = np.linalg.inv(np.linalg.cholesky(S).T)
    starts: np.ndarray = x_op + (z * radius[:, None]) @ T.T
    return starts


def slice_coverage(est: SliceEstimate, S: np.ndarray, x_op: np.ndarray, idx: tuple[int, int],
                   rho: float, resolution: int = 201) -> float:
    """The share of the slice's caught area inside the section ``dx' S dx <= rho`` (the
    other states at the operating point): each point of a uniform grid takes the outcome of
    its nearest sampled start."""
    from scipy.spatial import cKDTree

    (lo0, hi0), (lo1, hi1) = est.bounds
    g0, g1 = np.meshgrid(np.linspace(lo0, hi0, resolution), np.linspace(lo1, hi1, resolution))
    grid = np.column_stack([g0.ravel(), g1.ravel()])
    scale = np.array([hi0 - lo0, hi1 - lo1])
    _d, near = cKDTree(est.points / scale).query(grid / scale)
    caught = est.caught[near]
    if not caught.any():
        return math.nan
    sub = S[np.ix_(idx, idx)]
    d = grid - np.asarray(x_op, dtype=float)[list(idx)]
    inside = np.einsum("ij,jk,ik->i", d, sub, d) <= rho
    return float((caught & inside).sum() / caught.sum())


__all__ = [
    "SliceEstimate",
    "default_bounds",
    "default_slice",
    "estimate_slice",
    "levels_of",
    "max_push",
    "max_tilt",
    "outcomes",
    "rho_sampled",
    "sample_level",
    "slice_coverage",
]
