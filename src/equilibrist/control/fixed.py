"""Small dense linear algebra in a fixed order of IEEE operations: the same bits on every CPU.

numpy's ``@`` and LAPACK (``solve``, ``expm``, ``solve_discrete_are``) run
the BLAS kernels OpenBLAS picks by the CPU (``OPENBLAS_CORETYPE``): with FMA
or without, blocked in other orders, they round differently, so a design
made on two machines differs in its last bits, and every closed loop
amplifies that. The discrete designs (what a simulation, a batch, a study
and an export run) are made here instead: every result element is a sum
of products accumulated in one written order with numpy's element-wise
``+``, ``-``, ``*`` and ``/`` (single IEEE operations, never contracted),
so the bits depend only on the inputs.

* :func:`matmul`, :func:`solve` (Gaussian elimination with partial
  pivoting), :func:`expm` (scaling and squaring with the [13/13] Padé
  approximant, Higham 2005, the algorithm of :func:`scipy.linalg.expm`);
* :func:`dare`: the discrete algebraic Riccati equation's stabilizing
  solution by the structure-preserving doubling algorithm (Chu, Fan, Lin,
  Wang 2004), quadratically convergent.

The matrices of a balancing rig are small (a few to a few tens of rows):
the loops over one dimension cost microseconds each. Accuracy is that of
the LAPACK routines (checked against them in tests/control/test_control_fixed.py).
"""

from __future__ import annotations

import math

import numpy as np

from equilibrist.errors import DesignError


def _f(a: object) -> np.ndarray:
    return np.array(a, dtype=float, ndmin=2, copy=True)


def matmul(a: object, b: object) -> np.ndarray:
    """``a @ b``, each element ``sum_k a[i, k] b[k, j]`` accumulated in increasing ``k``."""
    A, B = _view(a), _view(b)
    if A.shape[1] != B.shape[0]:
        raise ValueError(f"matmul: shapes {A.shape} and {B.shape} do not match")
    out = np.zeros((A.shape[0], B.shape[1]))
    term = np.empty_like(out)
    for k in range(A.shape[1]):  # in place: the same products and sums, fewer arrays
        np.multiply(A[:, k, None], B[k], out=term)
        out += term
    return out


def _view(a: object) -> np.ndarray:
    """*a* as a float array of at least two dimensions, not copied where it is one."""
    A = np.asarray(a, dtype=float)
    return A if A.ndim >= 2 else A.reshape(1, -1)


def mm(*factors: object) -> np.ndarray:
    """The product of *factors*, left to right."""
    out = _f(factors[0])
    for f in factors[1:]:
        out = matmul(out, f)
    return out


def matvec(a: object, x: object) -> np.ndarray:
    """``a @ x`` for a vector *x* (a vector)."""
    return matmul(a, np.asarray(x, dtype=float).reshape(-1, 1))[:, 0]


def symmetric(a: object) -> np.ndarray:
    """``(a + a') / 2``: exactly symmetric."""
    A = _f(a)
    sym: np.ndarray = (A + A.T) * 0.5
    return sym


def solve(a: object, b: object) -> np.ndarray:
    """``x`` with ``a x = b`` (Gaussian elimination with partial pivoting); *b* a matrix
    or a vector (then a vector)."""
    A = _f(a)
    vector = np.asarray(b).ndim == 1
    B = np.asarray(b, dtype=float).reshape(A.shape[0], -1) if vector else _f(b)
    n = A.shape[0]
    if A.shape != (n, n) or B.shape[0] != n:
        raise ValueError(f"solve: shapes {A.shape} and {B.shape} do not match")
    M = np.concatenate([A, B], axis=1)
    for c in range(n):
        col = np.abs(M[c:, c])
        p = c + int(np.argmax(col))
        if not M[p, c] != 0.0 or not math.isfinite(M[p, c]):
            raise np.linalg.LinAlgError("solve: the matrix is singular")
        if p != c:
            M[[c, p]] = M[[p, c]]
        if c + 1 < n:
            f = M[c + 1:, c] / M[c, c]
            M[c + 1:, c:] = M[c + 1:, c:] - np.multiply.outer(f, M[c, c:])
    X = np.zeros((n, B.shape[1]))
    for r in range(n - 1, -1, -1):
        s = M[r, n:].copy()
        for c in range(r + 1, n):
            s = s - M[r, c] * X[c]
        X[r] = s / M[r, r]
    return X[:, 0] if vector else X


def norm1(a: object) -> float:
    """The largest column sum of absolute values (rows added in order)."""
    A = _f(a)
    s = np.zeros(A.shape[1])
    for i in range(A.shape[0]):
        s = s + np.abs(A[i])
    return float(s.max()) if s.size else 0.0


# Higham (2005), "The scaling and squaring method for the matrix exponential revisited".
_PADE13 = (64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0,
           129060195264000.0, 10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0,
           40840800.0, 960960.0, 16380.0, 182.0, 1.0)
_THETA13 = 5.371920351148152


def expm(a: object) -> np.ndarray:
    """The matrix exponential (scaling and squaring, the [13/13] Padé approximant)."""
    A = _f(a)
    n = A.shape[0]
    nrm = norm1(A)
    if not math.isfinite(nrm):
        raise DesignError("expm: the matrix has a value that is not finite")
    s = max(0, math.ceil(math.log2(nrm / _THETA13))) if nrm > _THETA13 else 0
    A = A * (0.5**s)
    b = _PADE13
    ident = np.eye(n)
    A2 = matmul(A, A)
    A4 = matmul(A2, A2)
    A6 = matmul(A4, A2)
    U = matmul(A, matmul(A6, b[13] * A6 + b[11] * A4 + b[9] * A2)
               + b[7] * A6 + b[5] * A4 + b[3] * A2 + b[1] * ident)
    V = (matmul(A6, b[12] * A6 + b[10] * A4 + b[8] * A2)
         + b[6] * A6 + b[4] * A4 + b[2] * A2 + b[0] * ident)
    E = solve(V - U, V + U)
    for _ in range(s):
        E = matmul(E, E)
    return E


#: Iterations of :func:`dare` before it gives up (it converges quadratically: some ten).
DARE_ITERATIONS = 200


def dare(a: object, b: object, q: object, r: object) -> np.ndarray:
    """The stabilizing solution ``X`` of ``X = A'XA - A'XB (R + B'XB)^-1 B'XA + Q``.

    Structure-preserving doubling: ``A_{k+1} = A_k W^-1 A_k``, ``G_{k+1} =
    G_k + A_k W^-1 G_k A_k'``, ``H_{k+1} = H_k + A_k' H_k W^-1 A_k`` with
    ``W = I + G_k H_k``, from ``A``, ``G = B R^-1 B'``, ``H = Q``; ``H_k``
    tends to ``X``. The caller checks stabilizability and detectability
    first (:mod:`equilibrist.control.riccati`); a run that does not settle
    is a :class:`DesignError`.
    """
    A, B, Q, R = _f(a), _f(b), symmetric(q), symmetric(r)
    n = A.shape[0]
    G = symmetric(matmul(B, solve(R, B.T)))
    H = Q
    ident = np.eye(n)
    with np.errstate(over="ignore", invalid="ignore"):  # a diverging run is told below
        return _doubling(A, G, H, ident)


def _doubling(A: np.ndarray, G: np.ndarray, H: np.ndarray, ident: np.ndarray) -> np.ndarray:
    for _ in range(DARE_ITERATIONS):
        W = ident + matmul(G, H)
        try:
            # One elimination for both right-hand sides: each column's own operations, so
            # the same bits as two solves.
            V = solve(W, np.concatenate([A, G], axis=1))
        except np.linalg.LinAlgError:
            break
        n = A.shape[1]
        V1, V2 = V[:, :n], V[:, n:]
        H_next = symmetric(H + matmul(A.T, matmul(H, V1)))
        G = symmetric(G + matmul(matmul(A, V2), A.T))
        A = matmul(A, V1)
        change = norm1(H_next - H)
        H = H_next
        if not math.isfinite(change):
            break
        if change <= 1e-14 * max(norm1(H), 1e-300) or norm1(A) < 1e-300:
            return H
    raise DesignError("the discrete Riccati equation did not converge: its doubling "
                      f"iteration did not settle in {DARE_ITERATIONS} steps")


__all__ = ["DARE_ITERATIONS", "dare", "expm", "matmul", "matvec", "mm", "norm1", "solve",
           "symmetric"]
