"""The closed loop's Lyapunov rate, bounded over boxes: ``dV/dt`` and its gradient in the
whitened coordinates ``z`` of :func:`equilibrist.control.certify.certify`, evaluated in
interval arithmetic on the model's exact equations under saturated state feedback, on
batches of boxes at once."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.numeric.interval import Interval, Operand, UnsupportedError, lambdify

if TYPE_CHECKING:
    from equilibrist.numeric.system import System

# The level's safety against the rounding of T (the ball in z covers the ellipsoid in x).
COVER = 1e-9


class CertificateUnavailable(ValueError):
    """The controller or the model has nothing this method can prove."""


def _imat(a: np.ndarray) -> list[list[Interval]]:
    return [[Interval(float(v)) for v in row] for row in np.atleast_2d(a)]


def _imatmul(a: list[list[Interval]], b: list[list[Interval]]) -> list[list[Interval]]:
    n, k, m = len(a), len(b), len(b[0])
    out = []
    for i in range(n):
        row = []
        for j in range(m):
            acc = a[i][0] * b[0][j]
            for t in range(1, k):
                acc = acc + a[i][t] * b[t][j]
            row.append(acc)
        out.append(row)
    return out


def _transpose(a: list[list[Interval]]) -> list[list[Interval]]:
    return [list(col) for col in zip(*a, strict=True)]


class LyapunovRate:
    """The closed loop's ``dV/dt`` and its gradient in ``z``, on batches of boxes."""

    def __init__(self, system: System, K: np.ndarray, S: np.ndarray, x_op: np.ndarray,
                 u_op: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
        model = system.symbolic
        if model.f is None or len(model.states) != S.shape[0]:
            raise CertificateUnavailable(f"{system.key}'s model has no explicit equations of "
                                         "the design's states")
        args = [*model.states, *model.inputs, *model.params]
        try:
            self._f = lambdify(args, model.f)
            self._fab = lambdify(args, [model.f, model.A, model.B])
        except UnsupportedError as err:
            raise CertificateUnavailable(f"{system.key}'s equations: {err}") from None
        self.n, self.m = S.shape[0], K.shape[0]
        self.params = [Interval(float(v)) for v in np.asarray(system.p, dtype=float)]
        self.x_op, self.u_op, self.lo, self.hi = x_op, u_op, lo, hi
        self.S, self.K = S, K
        L = np.linalg.cholesky(S)
        self.T = np.linalg.inv(L.T)
        off = float(np.abs(self.T.T @ S @ self.T - np.eye(self.n)).sum())
        if off > 0.1 * COVER:
            raise CertificateUnavailable("S is too badly conditioned to be certified here "
                                         f"(T'ST - I is {off:.2g})")
        T_i = _imat(self.T)
        self.ST = _imatmul(_imat(S), T_i)  # enclosures of the products
        self.KT = _imatmul(_imat(K), T_i)
        self.T_i = T_i
        self._linear_part()

    def A_cl(self, i: int, j: int) -> Interval:
        return self._acl[i][j]

    # -- pieces ------------------------------------------------------------------
    def _lin(self, rows: list[list[Interval]], z: list[Interval]) -> list[Interval]:
        out = []
        for row in rows:
            acc = row[0] * z[0]
            for j in range(1, len(z)):
                acc = acc + row[j] * z[j]
            out.append(acc)
        return out

    def _state(self, z: list[Interval]) -> tuple[list[Interval], list[Interval], list[Interval],
                                                   list[Interval], list[Interval]]:
        dx = self._lin(self.T_i, z)
        x = [dx[i] + float(self.x_op[i]) for i in range(self.n)]
        v = [float(self.u_op[k]) - w for k, w in enumerate(self._lin(self.KT, z))]
        u, s = [], []
        for k, vk in enumerate(v):
            lo, hi = float(self.lo[k]), float(self.hi[k])
            u.append(Interval(np.clip(vk.lo, lo, hi), np.clip(vk.hi, lo, hi)))
            inside = (vk.lo > lo) & (vk.hi < hi)
            outside = (vk.hi <= lo) | (vk.lo >= hi)
            s.append(Interval(np.where(inside, 1.0, 0.0), np.where(outside, 0.0, 1.0)))
        sdx = self._lin(self.ST, z)
        return dx, x, u, s, sdx

    def vdot_point(self, c: np.ndarray) -> Interval:
        """An enclosure of ``dV/dt`` at the points *c* (rows, in z)."""
        return self._at(c)[0]

    def _at(self, c: np.ndarray) -> tuple[Interval, list[Interval]]:
        """``dV/dt`` and ``f`` enclosed at the points *c*."""
        z = [Interval(c[:, j]) for j in range(self.n)]
        _dx, x, u, _s, sdx = self._state(z)
        out = self._f(*x, *u, *self.params)
        f = [_row(out, i) for i in range(self.n)]
        acc = sdx[0] * f[0]
        for i in range(1, self.n):
            acc = acc + sdx[i] * f[i]
        return 2.0 * acc, f

    def _linear_part(self) -> None:
        """``A_cl``, the closed loop's Jacobian at the operating point (unsaturated), and
        ``P = T'S A_cl T + (T'S A_cl T)'``: ``dV/dt = z'P z + R(z)`` with ``R`` of third
        order. Where
        every matrix of ``P``'s enclosure is negative definite, :meth:`vdot_box` bounds the
        quadratic part exactly (a concave quadratic is at most its tangent plane) and only
        the remainder by intervals: boxes near the operating point prove as easily as far."""
        n, m = self.n, self.m
        self.quad = False
        inside = np.all((self.u_op > self.lo) & (self.u_op < self.hi))
        if not inside:
            return
        x = [Interval(np.array([float(v)])) for v in self.x_op]
        u = [Interval(np.array([float(v)])) for v in self.u_op]
        _f, A, B = self._fab(*x, *u, *self.params)
        acl = [[Interval.of(_cell(A, i, j)) - _sum(
            [_cell(B, i, k) * float(self.K[k, j]) for k in range(m)]) for j in range(n)]
            for i in range(n)]
        self._acl = acl
        self.AclT = _imatmul(acl, self.T_i)
        half = _imatmul(_transpose(self.ST), self.AclT)
        lo = np.array([[_first((half[i][j] + half[j][i]).lo) for j in range(n)] for i in range(n)])
        hi = np.array([[_first((half[i][j] + half[j][i]).hi) for j in range(n)] for i in range(n)])
        mid, rad = 0.5 * (lo + hi), 0.5 * (hi - lo)
        top = float(np.linalg.eigvalsh(0.5 * (mid + mid.T)).max()) + float(np.linalg.norm(rad))
        self.P = [[Interval(lo[i, j], hi[i, j]) for j in range(n)] for i in range(n)]
        self.quad = bool(top + 1e-12 * float(np.linalg.norm(mid)) < 0.0)
        if not self.quad:
            return
        # For the ball bound: P's midpoint in its eigenbasis, and what the enclosure and the
        # rounding of the decomposition may add to z'P z per |z|^2.
        pm = mid
        lam, V = np.linalg.eigh(0.5 * (pm + pm.T))
        self._eig = (lam, V)
        self._slack = (float(np.linalg.norm(rad)) + float(np.linalg.norm(
            V @ np.diag(lam) @ V.T - pm)) + 1e-12 * float(np.linalg.norm(pm)))
        # Multipliers tried in the dual bound, spread over the scales of P's eigenvalues.
        self._mu = np.geomspace(1e-3 * float(-lam.max()), 1e3 * float(-lam.min()), 48)

    def _quadratic_bound(self, z: list[Interval], c: np.ndarray, f: list[Interval],
                         J: list[list[Interval]], sdx: list[Interval], vc: Interval,
                         fc: list[Interval]) -> tuple[np.ndarray, np.ndarray]:
        """An upper bound of ``dV/dt`` over the boxes: the quadratic part's tangent plane at
        the centre plus the remainder's mean-value form (see :meth:`_linear_part`)."""
        n = self.n
        ci = [Interval(c[:, j]) for j in range(n)]
        w = [z[j] - c[:, j] for j in range(n)]
        Pc = [_sum([self.P[i][j] * ci[j] for j in range(n)]) for i in range(n)]
        cPc = _sum([ci[i] * Pc[i] for i in range(n)])
        D = [[J[i][j] - self.A_cl(i, j) for j in range(n)] for i in range(n)]
        DT = _imatmul(D, self.T_i)
        e = [fc[i] - _sum([self.AclT[i][j] * ci[j] for j in range(n)])
             + _sum([DT[i][j] * w[j] for j in range(n)]) for i in range(n)]
        R = vc - cPc
        upper_lin = cPc.hi
        smear = np.empty_like(c)
        for j in range(n):
            g = 2.0 * _sum([self.ST[i][j] * e[i] + DT[i][j] * sdx[i] for i in range(n)])
            R = R + g * w[j]
            half = 0.5 * (z[j].hi - z[j].lo)
            lin = np.maximum(np.abs(Pc[j].lo), np.abs(Pc[j].hi)) * 2.0 * half
            upper_lin = upper_lin + lin
            smear[:, j] = lin + np.maximum(np.abs(g.lo), np.abs(g.hi)) * 2.0 * half
        # Better where the box is not small beside its distance: the concave quadratic's
        # largest value on the ball about the centre that holds the box, bounded by Lagrange
        # duality (any multiplier mu >= 0 bounds it from above: the least of a few is kept).
        lam, V = self._eig
        ct = c @ V
        rho2 = sum((0.5 * (z[j].hi - z[j].lo)) ** 2 for j in range(n))
        far2 = sum(np.maximum(np.abs(z[j].lo), np.abs(z[j].hi)) ** 2 for j in range(n))
        mu = self._mu[None, :]
        g = mu * rho2[:, None] + ((ct**2)[:, None, :] * (mu[..., None] * lam)
                                  / (mu[..., None] - lam)).sum(axis=2)
        ball = g.min(axis=1)
        ball = ball + np.abs(ball) * 1e-12 + self._slack * far2
        upper_lin = np.minimum(upper_lin, ball)
        bound: np.ndarray = np.nextafter(np.nextafter(upper_lin, np.inf) + R.hi, np.inf)
        return np.nan_to_num(bound, nan=np.inf), smear

    def jacobian(self, z: list[Interval]) -> tuple[list[Interval], list[list[Interval]],
                                                   list[Interval]]:
        """``f``, the closed loop's Jacobian ``A - B diag(s) K`` and ``S dx`` over boxes."""
        _dx, x, u, s, sdx = self._state(z)
        f, A, B = self._fab(*x, *u, *self.params)
        n, m = self.n, self.m
        fl = [_row(f, i) for i in range(n)]
        J = []
        for i in range(n):
            row = []
            for j in range(n):
                acc = Interval.of(_cell(A, i, j))
                for k in range(m):
                    acc = acc - _cell(B, i, k) * s[k] * float(self.K[k, j])
                row.append(acc)
            J.append(row)
        return fl, J, sdx

    def vdot_box(self, lo: np.ndarray, hi: np.ndarray) -> tuple[Interval, np.ndarray]:
        """An enclosure of ``dV/dt`` over each box ``[lo, hi]`` (rows, in z), and each box's
        smear per coordinate (the gradient's bound times the width: where to split)."""
        z = [Interval(lo[:, j], hi[:, j]) for j in range(self.n)]
        f, J, sdx = self.jacobian(z)
        n = self.n
        direct = sdx[0] * f[0]
        for i in range(1, n):
            direct = direct + sdx[i] * f[i]
        direct = 2.0 * direct
        # The gradient in z: 2 (ST)' f + 2 (J T)' (S dx).
        JT = _imatmul(J, self.T_i)
        c = 0.5 * lo + 0.5 * hi
        vc, fc = self._at(c)
        mv = vc
        smear = np.empty_like(lo)
        for j in range(n):
            g = self.ST[0][j] * f[0] + JT[0][j] * sdx[0]
            for i in range(1, n):
                g = g + self.ST[i][j] * f[i] + JT[i][j] * sdx[i]
            mv = mv + 2.0 * g * (z[j] - c[:, j])
            smear[:, j] = np.maximum(np.abs(g.lo), np.abs(g.hi)) * (hi[:, j] - lo[:, j])
        out = direct.intersect(mv)
        if self.quad:
            bound, qsmear = self._quadratic_bound(z, c, f, J, sdx, vc, fc)
            better = bound < out.hi
            out = Interval(out.lo, np.minimum(out.hi, bound))
            smear = np.where(better[:, None], qsmear, smear)
        return out, np.nan_to_num(smear, nan=np.inf)

    def cones(self, r: float, plo: np.ndarray, phi: np.ndarray) -> np.ndarray:
        """For patches ``[plo, phi]`` of the unit cube's surface: an upper bound of
        ``dV/dt / t^2`` (less its ``f0`` part) on each cone ``{t w : w in patch, t <= r}``."""
        n = self.n
        hull = [Interval(np.minimum(0.0, r * plo[:, j]), np.maximum(0.0, r * phi[:, j]))
                for j in range(n)]
        _f, J, _sdx = self.jacobian(hull)
        JT = _imatmul(J, self.T_i)
        w = [Interval(plo[:, j], phi[:, j]) for j in range(n)]
        q = Interval(np.zeros(plo.shape[0]))
        for i in range(n):
            for j in range(i, n):
                qij = self.ST[0][i] * JT[0][j]
                qji = self.ST[0][j] * JT[0][i]
                for t in range(1, n):
                    qij = qij + self.ST[t][i] * JT[t][j]
                    qji = qji + self.ST[t][j] * JT[t][i]
                q = q + (2.0 * qij * w[i].square() if i == j else 2.0 * (qij + qji) * w[i] * w[j])
        bound: np.ndarray = np.nan_to_num(q.hi, nan=np.inf)
        return bound

    def inner(self, r0: float) -> tuple[float, float]:
        """``(Lambda, b)``: ``dV/dt <= Lambda |z|^2 + b |z|`` on ``|z| <= r0``."""
        n = self.n
        box = [Interval(np.array([-r0]), np.array([r0])) for _ in range(n)]
        _f, J, _sdx = self.jacobian(box)
        Q = _imatmul(_transpose(self.ST), _imatmul(J, self.T_i))
        lo = np.array([[_first(Q[i][j].lo) + _first(Q[j][i].lo) for j in range(n)]
                       for i in range(n)])
        hi = np.array([[_first(Q[i][j].hi) + _first(Q[j][i].hi) for j in range(n)]
                       for i in range(n)])
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            return math.inf, math.inf
        mid, rad = 0.5 * (lo + hi), 0.5 * (hi - lo)
        lam = float(np.linalg.eigvalsh(0.5 * (mid + mid.T)).max())
        lam += float(np.linalg.norm(rad)) * (1 + 1e-12) + 1e-12 * float(np.linalg.norm(mid))
        z0 = [Interval(np.zeros(1)) for _ in range(n)]
        f0, _J, _s = self.jacobian(z0)
        b2 = Interval(0.0)
        for j in range(n):
            g = self.ST[0][j] * f0[0]
            for i in range(1, n):
                g = g + self.ST[i][j] * f0[i]
            b2 = b2 + g.square()
        b = 2.0 * float(np.sqrt(_first(b2.hi))) * (1 + 1e-12)
        return lam, b


def _sum(terms: list[Interval]) -> Interval:
    acc = terms[0]
    for t in terms[1:]:
        acc = acc + t
    return acc


def _first(a: np.ndarray) -> float:
    return float(np.ravel(a)[0])


def _row(f: Sequence[Operand | list[Operand]], i: int) -> Interval:
    v = f[i]
    return Interval.of(v[0] if isinstance(v, list) else v)


def _cell(a: Sequence[Sequence[Operand]], i: int, j: int) -> Interval:
    return Interval.of(a[i][j])


