"""The fixed-order linear algebra of the designs (equilibrist.control.fixed) against LAPACK:
as accurate, and the same bits whatever BLAS kernel numpy's own routines would use."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sl

from equilibrist.control import fixed
from equilibrist.errors import DesignError


def _random(n: int, m: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, n)), rng.normal(size=(n, m))


@pytest.mark.parametrize("n", [1, 4, 9])
def test_matmul_and_solve_agree_with_numpy(n: int) -> None:
    A, B = _random(n, 3, n)
    np.testing.assert_allclose(fixed.matmul(A, B), A @ B, rtol=1e-13, atol=1e-14)
    X = fixed.solve(A, B)
    np.testing.assert_allclose(A @ X, B, atol=1e-12)
    x = fixed.solve(A, B[:, 0])
    assert x.shape == (n,)
    np.testing.assert_allclose(A @ x, B[:, 0], atol=1e-12)
    with pytest.raises(np.linalg.LinAlgError):
        fixed.solve(np.zeros((n, n)), B)


@pytest.mark.parametrize("scale", [1e-3, 0.5, 4.0, 60.0])
def test_expm_agrees_with_scipy_and_with_exp_on_a_diagonal(scale: float) -> None:
    A, _ = _random(6, 1, 3)
    A = A * scale / np.abs(A).max()
    E = fixed.expm(A)
    np.testing.assert_allclose(E, sl.expm(A), rtol=1e-11, atol=1e-13 * np.abs(E).max())
    # A second truth: a diagonalizable matrix V diag(d) V^-1 has exponential V diag(e^d) V^-1.
    d = np.linspace(-scale, scale / 2, 5)
    V = np.eye(5) + np.triu(np.full((5, 5), 0.3), 1)
    M = V @ np.diag(d) @ np.linalg.inv(V)
    np.testing.assert_allclose(fixed.expm(M), V @ np.diag(np.exp(d)) @ np.linalg.inv(V),
                               rtol=1e-10, atol=1e-12 * np.exp(np.abs(d).max()))


@pytest.mark.parametrize(("n", "m", "seed"), [(2, 1, 0), (4, 1, 1), (6, 2, 2), (10, 3, 3)])
def test_dare_solves_the_riccati_equation_as_well_as_lapack(n: int, m: int, seed: int) -> None:
    A, B = _random(n, m, seed)
    Ad = sl.expm(A * 0.1)  # unstable modes, as a balancing rig's sampled plant
    Q = np.eye(n)
    R = np.eye(m) * 0.1
    X = fixed.dare(Ad, B, Q, R)
    ref = sl.solve_discrete_are(Ad, B, Q, R)

    def residual(S: np.ndarray) -> float:
        gain = np.linalg.solve(R + B.T @ S @ B, B.T @ S @ Ad)
        return float(np.abs(Ad.T @ S @ Ad - Ad.T @ S @ B @ gain + Q - S).max())

    assert np.array_equal(X, X.T)
    assert residual(X) <= max(10 * residual(ref), 1e-12 * np.abs(X).max())
    np.testing.assert_allclose(X, ref, rtol=1e-8, atol=1e-10 * np.abs(ref).max())
    K = np.linalg.solve(R + B.T @ X @ B, B.T @ X @ Ad)
    assert np.abs(np.linalg.eigvals(Ad - B @ K)).max() < 1.0  # stabilizing


def test_dare_that_cannot_settle_is_one_line() -> None:
    # An unstable mode the input cannot move: the cost grows without bound, no solution.
    # (riccati.py names such modes before it calls dare; this is dare's own guard.)
    with pytest.raises(DesignError, match="did not converge") as info:
        fixed.dare(np.diag([2.0, 0.5]), np.array([[0.0], [1.0]]), np.eye(2), np.eye(1))
    assert "\n" not in str(info.value)


def test_the_same_bits_whatever_order_numpy_would_sum_in() -> None:
    """The products are accumulated in increasing k, element by element: a product computed
    by hand in that order gives the same bits, a reordered sum need not."""
    rng = np.random.default_rng(7)
    a, b = rng.normal(size=(1, 7)), rng.normal(size=(7, 1))
    by_hand = 0.0
    for k in range(7):
        by_hand = by_hand + a[0, k] * b[k, 0]
    assert fixed.matmul(a, b)[0, 0] == by_hand
