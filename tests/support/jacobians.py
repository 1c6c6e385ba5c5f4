"""Central differences of a system's f: the independent truth its generated Jacobians are
held to."""

from __future__ import annotations

import numpy as np


def central_differences(system, x: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(df/dx, df/du)`` at ``(x, u)`` by central differences, steps ``1e-6 max(1, |v|)``."""
    n, m = system.n_states, system.n_inputs
    A, B = np.zeros((n, n)), np.zeros((n, m))
    for j in range(n):
        h = 1e-6 * max(1.0, abs(x[j]))
        e = np.zeros(n)
        e[j] = h
        A[:, j] = (system.f(x + e, u) - system.f(x - e, u)) / (2 * h)
    for j in range(m):
        h = 1e-6 * max(1.0, abs(u[j]))
        e = np.zeros(m)
        e[j] = h
        B[:, j] = (system.f(x, u + e) - system.f(x, u - e)) / (2 * h)
    return A, B
