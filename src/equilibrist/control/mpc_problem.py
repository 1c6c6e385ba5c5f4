"""The MPC's quadratic program: DAQP's exit flags (its bound, cap and tolerance are
:mod:`equilibrist.native.daqp_library`'s) and the solver's availability, and
:class:`MPCProblem` (predictions, the condensed QP, the soft limits and bounds); used by :mod:`equilibrist.control.mpc`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from equilibrist.native.daqp_library import INF

#: DAQP's exit flags: > 0 solved.
STATUS = {1: "solved", 2: "solved (soft)", -1: "infeasible", -2: "cycling", -3: "unbounded",
          -4: "iteration limit", -5: "nonconvex", -6: "overdetermined working set"}
#: Default horizon [samples].
HORIZON = 30
#: Default soft-constraint weights, relative to the largest diagonal entry of Q.
RHO_L1, RHO_L2 = 1e2, 4.0
#: Track parameter bounding the cart's coordinate.
TRACK = ("x_max", "x")


@dataclass(frozen=True, eq=False)
class MPCProblem:
    """The QP of one MPC controller (everything but the current state).

    Attributes
    ----------
    A, B:
        Sampled model (deviation coordinates).
    Q, R, P:
        Stage and terminal weights.
    horizon:
        ``N`` samples.
    u_lo, u_hi:
        Hard bounds of ``du`` (``u_min - u_op``, ``u_max - u_op``).
    soft_index, soft_lo, soft_hi:
        Constrained states and their bounds (deviation).
    rho_l1, rho_l2:
        Penalties of the slacks.
    """

    A: np.ndarray
    B: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    P: np.ndarray
    horizon: int
    u_lo: np.ndarray
    u_hi: np.ndarray
    soft_index: tuple[int, ...]
    soft_lo: np.ndarray
    soft_hi: np.ndarray
    rho_l1: float
    rho_l2: float

    @property
    def n(self) -> int:
        return int(self.A.shape[0])

    @property
    def m(self) -> int:
        return int(self.B.shape[1])

    @property
    def n_soft(self) -> int:
        return len(self.soft_index)

    K: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))

    @property
    def n_variables(self) -> int:
        """The QP's variables: the corrections ``v`` and the slacks ``s``."""
        return self.horizon * (self.m + self.n_soft)

    def predictions(self) -> tuple[np.ndarray, np.ndarray]:
        """``Fx, Gx`` with the stacked states ``[dx_0..dx_N] = Fx dx_0 + Gx v``.

        The moves are ``du_k = -K dx_k + v_k`` (the LQR plus a correction).
        """
        n, m, N = self.n, self.m, self.horizon
        Acl = self.A - self.B @ self.K
        Fx = np.zeros(((N + 1) * n, n))
        Gx = np.zeros(((N + 1) * n, N * m))
        Fx[:n] = np.eye(n)
        for k in range(N):
            rows = slice((k + 1) * n, (k + 2) * n)
            prev = slice(k * n, (k + 1) * n)
            Fx[rows] = Acl @ Fx[prev]
            Gx[rows] = Acl @ Gx[prev]
            Gx[rows, k * m:(k + 1) * m] += self.B
        return Fx, Gx

    @cached_property
    def soft_predictions(self) -> tuple[np.ndarray, np.ndarray]:
        """``Fu, Fs``: the LQR's own trajectory from ``dx_0`` (``du_k = -K dx_k``) has the
        stacked moves ``Fu dx_0`` (``k = 0..N-1``) and constrained states ``Fs dx_0``
        (``k = 1..N``, step-major: ``[k * n_soft + j]`` is ``soft_index[j]`` at step ``k + 1``)."""
        n, m, N = self.n, self.m, self.horizon
        Fx, _ = self.predictions()
        Fu = np.vstack([-self.K @ Fx[k * n:(k + 1) * n] for k in range(N)]).reshape(N * m, n)
        Fs = Fx[n:][[k * n + i for k in range(N) for i in self.soft_index]]
        return Fu, Fs

    @cached_property
    def condensed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``H, f, A`` of the condensed QP ``min 1/2 z'Hz + f'z``, ``bl <= [z; Az] <= bu``.

        Variables ``z = [v_0..v_{N-1}, s_1..s_N]``. The cost is
        ``dx_0' P dx_0 + sum v_k' (R + B'PB) v_k`` plus the slacks' penalty
        (``P`` solves the Riccati equation, so the prestabilized moves leave
        ``H`` block diagonal). The rows of ``A``: the moves
        ``du_k = -K dx_k + v_k`` (hard bounds), then ``C dx_k + s_k`` (lower
        soft bounds) and ``C dx_k - s_k`` (upper soft bounds), ``k = 1..N``;
        :meth:`qp_bounds` gives their bounds at ``dx_0``.
        """
        n, m, N, ns = self.n, self.m, self.horizon, self.n_soft
        nv, nsl = N * m, N * ns
        _, Gx = self.predictions()
        W = self.R + self.B.T @ self.P @ self.B
        H = np.zeros((nv + nsl, nv + nsl))
        H[:nv, :nv] = np.kron(np.eye(N), 2.0 * W)
        H[nv:, nv:] = np.diag(np.tile(2.0 * np.broadcast_to(self.rho_l2, (ns,)), N))
        f = np.concatenate([np.zeros(nv), np.tile(np.broadcast_to(self.rho_l1, (ns,)), N)])
        Mu = np.eye(nv) - np.kron(np.eye(N), self.K) @ Gx[: N * n]
        Ms = Gx[n:][[k * n + i for k in range(N) for i in self.soft_index]]
        eye = np.eye(nsl)
        A = np.block([[Mu, np.zeros((nv, nsl))], [Ms, eye], [Ms, -eye]])
        return H, f, A

    def soft_limits(self, dx0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The soft bounds over the horizon at *dx0* (deviations, ordered as ``Fs``'s rows).

        ``soft_lo, soft_hi`` at every step, with one relaxation: a soft bound
        that the state already violates now cannot be met in the first
        samples (the cart-pole is non-minimum phase: returning a cart starts
        by moving it further out), so its bound over the horizon is widened
        to the LQR's own trajectory from *dx0*. The QP then only improves on
        the LQR's return instead of demanding the impossible.
        """
        N, ns = self.horizon, self.n_soft
        lows = np.tile(self.soft_lo, (N, 1))
        highs = np.tile(self.soft_hi, (N, 1))
        if ns:
            c = dx0[list(self.soft_index)]
            out = (c > self.soft_hi) | (c < self.soft_lo)
            if np.any(out):
                _, Fs = self.soft_predictions
                xs = (Fs @ dx0).reshape(N, ns)
                lows[:, out] = np.minimum(lows[:, out], xs[:, out])
                highs[:, out] = np.maximum(highs[:, out], xs[:, out])
        return lows.reshape(-1), highs.reshape(-1)

    @cached_property
    def _bound_map(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``bu0, bl0, E``: the bounds of :meth:`qp_bounds` are ``bu0 - E dx0``, ``bl0 - E dx0``
        (before the widening of violated soft bounds)."""
        N, m, ns = self.horizon, self.m, self.n_soft
        nv, nsl = N * m, N * ns
        Fu, Fs = self.soft_predictions
        inf_v, inf_s = np.full(nv, INF), np.full(nsl, INF)
        bu = np.concatenate([inf_v, inf_s, np.tile(self.u_hi, N), inf_s, np.tile(self.soft_hi, N)])
        bl = np.concatenate([-inf_v, np.zeros(nsl), np.tile(self.u_lo, N), np.tile(self.soft_lo, N),
                             -inf_s])
        E = np.vstack([np.zeros((self.n_variables, self.n)), Fu, Fs, Fs])
        return bu, bl, E

    def qp_bounds(self, dx0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``bu, bl`` of the condensed QP at *dx0*: first the variables' own bounds
        (``v`` free, ``s >= 0``), then the rows of :attr:`condensed`'s ``A``
        (infinite bounds are :data:`INF`, DAQP's): the moves' hard bounds
        less the LQR's moves ``Fu dx0``, the soft bounds (:meth:`soft_limits`)
        less the LQR's constrained states ``Fs dx0``."""
        dx0 = np.asarray(dx0, dtype=float)
        bu0, bl0, E = self._bound_map
        shift = E @ dx0
        bu, bl = bu0 - shift, bl0 - shift
        ns = self.n_soft
        if ns:
            c = dx0[list(self.soft_index)]
            if np.any((c > self.soft_hi) | (c < self.soft_lo)):
                N, nsl = self.horizon, self.horizon * ns
                lower = self.n_variables + N * self.m
                xs = shift[lower:lower + nsl]
                lo_s, hi_s = self.soft_limits(dx0)
                bl[lower:lower + nsl] = lo_s - xs
                bu[lower + nsl:] = hi_s - xs
        return bu, bl
