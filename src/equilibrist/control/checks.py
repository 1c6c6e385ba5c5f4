"""Validation at the boundary of the control layer (private).

Every public function of :mod:`equilibrist.control` converts its arguments
here: to float arrays of the expected shape, finite, and -- for weights and
covariances -- symmetric and (semi)definite. Problems are collected and
raised once, naming the matrix, what was found and what was expected.
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence

import numpy as np

from equilibrist.errors import DesignError, DimensionError

# Relative tolerance of the symmetry test of weights and covariances.
SYMMETRY_TOL = 1e-9
# Relative tolerance of the definiteness tests (eigenvalues scaled by the largest).
DEFINITE_TOL = 1e-12


def real_array(value: object) -> tuple[np.ndarray | None, str]:
    """*value* as a float array, or None and what it holds instead of real numbers.

    Complex numbers (whose imaginary part a float conversion would drop),
    text, booleans and objects that are not real numbers are refused, as are
    nested lists of unequal lengths.
    """
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError):
        return None, "nested lists of unequal lengths" if isinstance(value, list | tuple) else _a(value)
    kind = raw.dtype.kind
    if kind in "iuf":
        return raw.astype(float, copy=False), ""
    if kind == "c":
        return None, f"complex numbers ({raw.dtype})"
    if kind in "USa":
        return None, "text"
    if kind == "b":
        return None, "booleans"
    if kind == "O":
        wrong = [v for v in raw.flat if not isinstance(v, numbers.Real) or isinstance(v, bool)][:1]
        if not wrong:
            return raw.astype(float), ""
        return None, _a(wrong[0])
    return None, f"values of type {raw.dtype}"


def _a(value: object) -> str:
    name = type(value).__name__
    return f"{'an' if name[:1].lower() in 'aeiou' else 'a'} {name}"


def given_text(value: object) -> str:
    """*value* in a few words on one line: an array by its dtype and shape, else its repr."""
    if isinstance(value, np.ndarray):
        return f"an array of {value.dtype}, shape {value.shape}"
    text = " ".join(repr(value).split())
    return f"{text[:77]}..." if len(text) > 80 else text


def _floats(value: object, name: str) -> np.ndarray:
    """*value* as a float array: a complex one is refused, not cut to its real part."""
    try:
        complex_values = np.iscomplexobj(value)  # type: ignore[arg-type]  # any value
    except (TypeError, ValueError):
        complex_values = False
    if complex_values:
        raise DesignError(
            f"{name} has complex entries: the matrices must be real (got {np.asarray(value).dtype})"
        )
    try:
        return np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise DimensionError(f"{name} must be a matrix of real numbers, got {value!r:.200}") from None


def matrix(value: object, name: str, shape: tuple[int, int], meaning: str = "") -> np.ndarray:
    """*value* as a finite float array of *shape* (a scalar is accepted for 1 x 1)."""
    arr = _floats(value, name)
    if arr.ndim == 0 and shape == (1, 1):
        arr = arr.reshape(1, 1)
    if arr.ndim == 1 and 0 in shape and arr.size == 0:
        arr = arr.reshape(shape)
    if arr.shape != shape:
        extra = f" ({meaning})" if meaning else ""
        raise DimensionError(f"{name} has shape {arr.shape}, expected {shape}{extra}")
    if not np.all(np.isfinite(arr)):
        raise DesignError(f"{name} has an entry that is not a finite number")
    return arr


def square(value: object, name: str) -> np.ndarray:
    """A finite square float matrix (its size is taken from *value*)."""
    arr = _floats(value, name)
    if arr.ndim == 0:
        arr = arr.reshape(1, 1)
    if arr.ndim != 2 or arr.shape[0] != arr.shape[1]:
        raise DimensionError(f"{name} has shape {arr.shape}, expected a square matrix")
    if not np.all(np.isfinite(arr)):
        raise DesignError(f"{name} has an entry that is not a finite number")
    return arr


def with_rows(value: object, name: str, n_rows: int, meaning: str) -> np.ndarray:
    """A finite ``n_rows x k`` float matrix, any ``k`` (a 1-D value is one column)."""
    arr = _floats(value, name)
    if arr.ndim == 1 and arr.size == n_rows:
        arr = arr.reshape(n_rows, 1)
    if arr.ndim != 2 or arr.shape[0] != n_rows:
        raise DimensionError(f"{name} has shape {arr.shape}, expected {n_rows} rows ({meaning})")
    return matrix(arr, name, arr.shape)


def with_columns(value: object, name: str, n_cols: int, meaning: str) -> np.ndarray:
    """A finite ``k x n_cols`` float matrix, any ``k`` (a 1-D value is one row)."""
    arr = _floats(value, name)
    if arr.ndim == 1 and arr.size == n_cols:
        arr = arr.reshape(1, n_cols)
    if arr.ndim != 2 or arr.shape[1] != n_cols:
        raise DimensionError(f"{name} has shape {arr.shape}, expected {n_cols} columns ({meaning})")
    return matrix(arr, name, arr.shape)


def weight_problems(mat: np.ndarray, name: str, *, definite: bool) -> list[str]:
    """Problems of a weight or covariance: not symmetric, not (semi)definite."""
    problems: list[str] = []
    size = float(np.max(np.abs(mat))) if mat.size else 0.0
    asym = float(np.max(np.abs(mat - mat.T))) if mat.size else 0.0
    if asym > SYMMETRY_TOL * max(size, 1e-300):
        problems.append(f"{name} is not symmetric (largest |{name} - {name}'| = {asym:.3g})")
        return problems
    if mat.size == 0:
        return problems
    eig = np.linalg.eigvalsh(0.5 * (mat + mat.T))
    scale = max(float(np.max(np.abs(eig))), 1e-300)
    low = float(eig[0])
    if definite and not low > DEFINITE_TOL * scale:
        problems.append(
            f"{name} is not positive definite: its smallest eigenvalue is {low:.3g} "
            f"(expected every eigenvalue > 0)"
        )
    elif not definite and low < -DEFINITE_TOL * scale:
        problems.append(
            f"{name} is not positive semidefinite: its smallest eigenvalue is {low:.3g} "
            f"(expected every eigenvalue >= 0)"
        )
    return problems


def raise_if(problems: Sequence[str]) -> None:
    if problems:
        raise DesignError("; ".join(problems))


def symmetric(mat: np.ndarray) -> np.ndarray:
    """The symmetric part (removes round-off asymmetry of Riccati solutions)."""
    sym: np.ndarray = 0.5 * (mat + mat.T)
    return sym


def names(given: Sequence[str] | None, n: int, prefix: str) -> tuple[str, ...]:
    """*given* names, or ``prefix0, prefix1, ...``; the count must match."""
    if given is None:
        return tuple(f"{prefix}{i}" for i in range(n))
    out = tuple(given)
    if len(out) != n:
        raise DimensionError(f"{len(out)} {prefix} names given for {n} {prefix}s")
    return out


def positive_period(dt: object, name: str = "dt") -> float:
    try:
        value = float(dt)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise DesignError(f"{name} must be a positive number of seconds, got {dt!r}") from None
    if not np.isfinite(value) or value <= 0:
        raise DesignError(f"{name} must be a positive number of seconds, got {value:g}")
    return value
