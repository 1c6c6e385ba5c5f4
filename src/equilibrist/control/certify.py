"""A certified region of attraction: the largest level set of the LQR's ``V`` that provably shrinks.

For a state feedback ``u = sat(u_op - K (x - x_op))`` (the LQR, or the LQG's state feedback)
and the Riccati solution ``S`` of its design, :func:`certify` finds a level ``rho`` such that
on the whole set ``{x : (x - x_op)' S (x - x_op) <= rho}`` the derivative of ``V`` along the
exact equations of motion with the input's saturation is negative (outside a ball about the
operating point whose radius the rounding of the operating point sets): the set is invariant
and every start in it is caught. The method (interval branch-and-bound in the coordinates
where the level set is a ball, :mod:`equilibrist.numeric.interval`), what it assumes (a
continuous feedback, the simulation's parameters) and how ``equilibrist roa`` checks it are
in docs/roa.md.
"""

from __future__ import annotations

import contextlib
import math
import sys
import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control.lyapunov_rate import COVER, CertificateUnavailable, LyapunovRate

if TYPE_CHECKING:
    from equilibrist.numeric.system import System

METHOD = "interval branch-and-bound on the exact dynamics"
ASSUMES = ("continuous-time state feedback u = sat(u_op - K (x - x_op)) with the design's K "
           "(no zero-order hold, no estimator), the model's exact equations, the input limits")

# Where dV/dt >= 0 was found at radius r, the search goes on at _SHY r: right at the
# boundary the decrease vanishes and no box is small enough to prove it.
_SHY = 0.97


@dataclass(frozen=True)
class Certificate:
    """A certified level of ``V = dx' S dx`` (see the module).

    ``rho`` is the level; ``limited_by`` says what stopped it from being larger:
    ``"region"`` (the ellipsoid reached the fall region), ``"decrease"`` (a point where
    ``dV/dt >= 0`` was found just outside), ``"resolution"`` (boxes of the finest width did
    not prove it there), ``"budget"`` (the box budget ran out).
    """

    rho: float
    method: str
    assumes: str
    limited_by: str
    rho_region: float
    inner: float
    inner_floor: float
    boxes: int
    levels: int  # rounds of the branch-and-bound
    seconds: float
    violation: list[float] | None

    def to_dict(self) -> dict[str, object]:
        return {"rho": self.rho, "method": self.method, "assumes": self.assumes,
                "limited_by": self.limited_by, "rho_region": self.rho_region,
                "inner_level": self.inner, "inner_floor": self.inner_floor,
                "boxes": self.boxes, "levels": self.levels, "seconds": self.seconds,
                "violation": self.violation}


def _cone_ball(loop: LyapunovRate, r0: float, lam: float, R: float,
               max_patches: int) -> tuple[float, float]:
    """The ball about the operating point grown by cones: the unit cube's surface in patches,
    each cone ``{t w : t <= r}`` proven where ``w' sym(T'S M T) w < 0`` for every ``M`` in the
    closed loop's Jacobian over the cone's box hull; patches that fail are split. The radius
    grows by half while every patch is proven within *max_patches* evaluations."""
    n = loop.n
    faces_lo, faces_hi = [], []
    for j in range(n):
        for sign in (-1.0, 1.0):
            lo, hi = -np.ones(n), np.ones(n)
            lo[j] = hi[j] = sign
            faces_lo.append(lo)
            faces_hi.append(hi)
    plo, phi = np.array(faces_lo), np.array(faces_hi)
    best_r, best_lam = r0, lam
    r = 1.5 * r0
    while r < R:
        lo, hi, spent, worst, ok = plo, phi, 0, -math.inf, True
        while lo.shape[0]:
            spent += lo.shape[0]
            if spent > max_patches:
                ok = False
                break
            q = loop.cones(r, lo, hi)
            proven = q < 0.0
            if proven.any():
                worst = max(worst, float(q[proven].max()))
            lo, hi = lo[~proven], hi[~proven]
            if not lo.shape[0]:
                break
            # Split each open patch across its widest free coordinate.
            j = np.argmax(hi - lo, axis=1)
            rows = np.arange(lo.shape[0])
            if float((hi - lo)[rows, j].min()) < 1e-3:
                ok = False
                break
            mid = 0.5 * (lo[rows, j] + hi[rows, j])
            lo2, hi1 = lo.copy(), hi.copy()
            hi1[rows, j] = mid
            lo2[rows, j] = mid
            lo, hi = np.concatenate([lo, lo2]), np.concatenate([hi1, hi])
        if not ok:
            break
        best_r, best_lam = r, worst
        r *= 1.5
    return best_r, best_lam


def region_level(S: np.ndarray, x_op: np.ndarray, names: tuple[str, ...],
                 region: Mapping[str, tuple[float, float]]) -> float:
    """The largest ``rho`` whose ellipsoid lies inside the fall region (its extent along
    state ``i`` is ``sqrt(rho (S^-1)_ii)``)."""
    inv = np.linalg.inv(S)
    best = math.inf
    for coord, (lo, hi) in region.items():
        k = names.index(coord)
        d = min(float(x_op[k]) - float(lo), float(hi) - float(x_op[k]))
        best = min(best, d * d / float(inv[k, k]))
    return best


def certify(system: System, K: np.ndarray, S: np.ndarray, *, x_op: np.ndarray,
            u_op: np.ndarray, rho_max: float | None = None, max_boxes: int = 1_000_000,
            min_width: float = 1 / 256, grid: int | None = None, chunk: int = 20_000,
            progress: Callable[[str], None] | None = None,
            counted: Callable[[int], None] | None = None) -> Certificate:
    """The largest level ``rho`` of ``dx' S dx`` proven to shrink (see the module).

    *rho_max* caps the search (e.g. a level sampling has already falsified); *max_boxes*
    caps the boxes evaluated (nearest first, *chunk* at a time); *min_width* is the finest box's
    width relative to its distance from the operating point. *progress* is told each stage
    of the search in words, *counted* the boxes evaluated so far after each round of them
    (:func:`boxes_bar`).
    """
    t0 = time.perf_counter()
    K = np.atleast_2d(np.asarray(K, dtype=float))
    S = np.asarray(S, dtype=float)
    x_op, u_op = np.asarray(x_op, dtype=float), np.asarray(u_op, dtype=float)
    n = S.shape[0]
    if K.shape != (system.n_inputs, n) or n != system.n_states:
        raise CertificateUnavailable(f"the gain is {K.shape}, expected ({system.n_inputs}, "
                                     f"{system.n_states}): a full-state feedback")
    try:
        np.linalg.cholesky(S)
    except np.linalg.LinAlgError:
        raise CertificateUnavailable("S is not positive definite") from None
    lo, hi = (np.asarray(v, dtype=float) for v in system.input_limits)
    loop = LyapunovRate(system, K, S, x_op, u_op, lo, hi)
    rho_region = region_level(S, x_op, system.state_names, system.spec.region)
    cap = rho_region if rho_max is None else min(rho_region, float(rho_max))
    if not math.isfinite(cap):
        raise CertificateUnavailable("no fall region and no cap: the level is unbounded")
    R = math.sqrt(cap)
    r0, lam, b = _inner_ball(loop, R)
    say = progress or (lambda _m: None)
    say(f"inner ball |z| <= {r0:.3g} (level {r0 * r0:.3g}), Lambda {lam:.3g}")
    r0, lam = _cone_ball(loop, r0, lam, R, max_patches=min(20_000, max(2_000, max_boxes // 5)))
    floor = b * math.sqrt(n) / -lam
    say(f"cones: ball |z| <= {r0:.3g} (level {r0 * r0:.3g})")
    search = _Search(R=R, limited="region", violation=None)
    _sampled_decrease(loop, search, x_op)
    g = grid or (8 if n <= 4 else 4 if n <= 6 else 2)
    _boxes(loop, search, x_op, r0=r0, g=g, max_boxes=max_boxes, chunk=chunk,
           min_width=min_width, say=say, counted=counted)
    rho = max(search.R, r0) ** 2 * (1.0 - COVER)
    return Certificate(rho=rho, method=METHOD, assumes=ASSUMES, limited_by=search.limited,
                       rho_region=rho_region, inner=r0 * r0, inner_floor=floor * floor,
                       boxes=search.boxes, levels=search.rounds,
                       seconds=time.perf_counter() - t0, violation=search.violation)


def _inner_ball(loop: LyapunovRate, R: float) -> tuple[float, float, float]:
    """The ball about the operating point proven at once: its radius (halved from *R* until
    the decrease holds there), and the bounds ``Lambda`` and ``b`` of :meth:`LyapunovRate.inner`."""
    r0, lam, b = R, math.inf, math.inf
    for _ in range(60):
        lam, b = loop.inner(r0)
        if lam < 0 and b / -lam < 0.5 * r0:
            break
        r0 *= 0.5
    else:
        raise CertificateUnavailable("dV/dt is not negative definite at the operating point: "
                                     "the design does not stabilize the continuous loop")
    return r0, lam, b


@dataclass
class _Search:
    """The search's state: the radius still claimed, what limits it (``region``,
    ``decrease``, ``resolution``, ``budget``), the state where dV/dt was seen >= 0, and the
    boxes evaluated in how many rounds."""

    R: float
    limited: str
    violation: list[float] | None
    boxes: int = 0
    rounds: int = 0


def _sampled_decrease(loop: LyapunovRate, search: _Search, x_op: np.ndarray) -> None:
    """Points first (cheap): the nearest sampled point where dV/dt >= 0 bounds any level this
    V can have; the search starts a little inside it, where the decrease is not marginal."""
    n = loop.n
    R = search.R
    rng = np.random.default_rng(0)
    dirs = rng.normal(size=(4096, n))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    for r in np.linspace(R / 64, R, 64):
        pts = dirs * r
        bad = loop.vdot_point(pts).lo >= 0.0
        if bad.any():
            search.R, search.limited = _SHY * float(r), "decrease"
            search.violation = (x_op + loop.T @ pts[int(np.argmax(bad))]).tolist()
            break


def _boxes(loop: LyapunovRate, search: _Search, x_op: np.ndarray, *, r0: float, g: int,
           max_boxes: int, chunk: int, min_width: float, say: Callable[[str], None],
           counted: Callable[[int], None] | None) -> None:
    """Branch and bound over boxes of the shell between *r0* and the radius, from a grid of
    *g* boxes a side: each box's enclosure of dV/dt proves it, or its centre shows a
    violation, or it is split; the radius shrinks to what is proven."""
    R = search.R
    n = loop.n
    edges = np.linspace(-R, R, g + 1)
    idx = np.array(np.meshgrid(*[np.arange(g)] * n, indexing="ij")).reshape(n, -1).T
    # The pending boxes, nearest first: when the budget runs out, every box nearer than the
    # nearest pending one is proven, and that is the radius.
    blo, bhi = edges[idx], edges[idx + 1]
    total, rounds = 0, 0
    while blo.shape[0] and total < max_boxes:
        rounds += 1
        a2 = np.where((blo <= 0) & (bhi >= 0), 0.0, np.minimum(blo * blo, bhi * bhi))
        near = np.sqrt(a2.sum(axis=1))
        far = np.sqrt(np.maximum(blo * blo, bhi * bhi).sum(axis=1))
        keep = (near < search.R) & (far > r0)
        blo, bhi, near = blo[keep], bhi[keep], near[keep]
        take = min(blo.shape[0], chunk, max_boxes - total)
        if take < blo.shape[0]:
            part = np.argpartition(near, take - 1)
            now, later = part[:take], part[take:]
        else:
            now, later = np.arange(blo.shape[0]), np.arange(0)
        rest_lo, rest_hi = blo[later], bhi[later]
        blo, bhi, near = blo[now], bhi[now], near[now]
        if not blo.shape[0]:
            break
        total += blo.shape[0]
        if counted is not None:
            counted(total)
        enclosure, smear = loop.vdot_box(blo, bhi)
        open_ = ~(enclosure.hi < 0.0)
        blo, bhi, near, smear = blo[open_], bhi[open_], near[open_], smear[open_]
        c = 0.5 * (blo + bhi)
        bad = loop.vdot_point(c).lo >= 0.0 if blo.shape[0] else np.zeros(0, dtype=bool)
        if bad.any():
            rc = np.sqrt((c[bad] ** 2).sum(axis=1))
            k = int(np.argmin(rc))
            if _SHY * rc[k] < search.R:
                search.R, search.limited = _SHY * float(rc[k]), "decrease"
                search.violation = (x_op + loop.T @ c[bad][k]).tolist()
        width = (bhi - blo).max(axis=1)
        fine = width <= min_width * np.maximum(near, r0)
        if fine.any():
            m = float(near[fine].min())
            if m < search.R:
                search.R, search.limited = m, "resolution"
        split = ~fine & (near < search.R)
        blo, bhi, smear = blo[split], bhi[split], smear[split]
        # Each box in two across the coordinate that smears its enclosure most.
        j = np.argmax(smear, axis=1)
        rows = np.arange(blo.shape[0])
        mid = 0.5 * (blo[rows, j] + bhi[rows, j])
        lo2, hi1 = blo.copy(), bhi.copy()
        hi1[rows, j] = mid
        lo2[rows, j] = mid
        blo = np.concatenate([rest_lo, blo, lo2])
        bhi = np.concatenate([rest_hi, hi1, bhi])
        if rounds % 10 == 0:
            say(f"{total} boxes, {blo.shape[0]} pending, radius {search.R:.4g}")
    if blo.shape[0]:
        a2 = np.where((blo <= 0) & (bhi >= 0), 0.0, np.minimum(blo * blo, bhi * bhi))
        near = np.sqrt(a2.sum(axis=1))
        far = np.sqrt(np.maximum(blo * blo, bhi * bhi).sum(axis=1))
        pending = (near < search.R) & (far > r0)
        if pending.any() and float(near[pending].min()) < search.R:
            search.R, search.limited = float(near[pending].min()), "budget"
    search.boxes, search.rounds = total, rounds


@contextlib.contextmanager
def boxes_bar(max_boxes: int, enabled: bool) -> Iterator[Callable[[int], None] | None]:
    """A progress bar on stderr of the boxes :func:`certify` evaluates, out of *max_boxes*
    (its ``counted``; None when not *enabled*): shown after a second, as a batch's, and
    gone when the block ends."""
    if not enabled:
        yield None
        return
    from tqdm import tqdm

    bar = tqdm(total=max_boxes, desc="certificate", unit="boxes", file=sys.stderr, delay=1.0,
               leave=False, dynamic_ncols=True)
    try:
        yield lambda total: bar.update(total - bar.n)
    finally:
        bar.close()


__all__ = ["ASSUMES", "METHOD", "Certificate", "CertificateUnavailable", "boxes_bar", "certify",
           "region_level"]
