"""Helpers of the C export's tests: the controller's documented equations in numpy."""

from __future__ import annotations

import numpy as np


def reference_run(data, ys, rs):
    """The controller of the ControllerData docstring, in numpy double precision."""
    z = np.zeros(data.n_states)
    us, xs = [], []
    for y, r in zip(ys, rs, strict=True):
        dy = y - data.y0
        if data.controller == "lqr":
            xhat = y - data.x0
        elif data.form == "current":
            xhat = z + data.Kf @ (dy - data.C @ z)
        else:
            xhat = z
        u = np.clip(data.u0 - data.K @ xhat + data.Kc @ (r - data.r0), data.u_min, data.u_max)
        if data.controller == "lqg" and data.form == "current":
            z = data.Ad @ xhat + data.Bd @ (u - data.u0)
        elif data.controller == "lqg":
            z = data.Ad @ z + data.Bd @ (u - data.u0) + data.Kf @ (dy - data.C @ z)
        us.append(u)
        xs.append(data.x0 + xhat)
    return np.array(us), np.array(xs)


def measurements(data, n_steps: int, seed: int):
    """Noisy measurements around a slow excursion, with references that move."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_steps)[:, None]
    span = np.maximum(np.abs(data.y0), 0.05)
    ys = data.y0 + 0.5 * span * np.sin(0.05 * t + np.arange(data.n_measured)) + \
        0.01 * span * rng.standard_normal((n_steps, data.n_measured))
    rs = data.r0 + 0.05 * np.sign(np.sin(0.02 * t)) * np.ones(data.n_references)
    return ys, rs
