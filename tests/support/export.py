"""Helpers of the C export's tests: ``make check`` in an exported folder, and the
controller's documented equations in numpy."""

from __future__ import annotations

import subprocess
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from support import require


def make_check(folder: Path, env: Mapping[str, str] | None = None) -> str:
    """``make check`` in the exported *folder*: the recorded vectors replayed by the
    compiled controller, its exit status 0 (what it printed, for the caller's checks of
    its count of mismatches)."""
    require("make")
    require("cc")
    done = subprocess.run(["make", "check"], cwd=folder, capture_output=True, text=True,
                          timeout=600, check=False, env=None if env is None else dict(env))
    assert done.returncode == 0, done.stdout + done.stderr
    return done.stdout


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
