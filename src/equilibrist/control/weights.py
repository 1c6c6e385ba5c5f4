"""A design's arguments: weights given or taken from the spec (Bryson's rule), the default
process noise with its floor where a mode would be left unexcited, and the fastest rate; used by
:mod:`equilibrist.control.design`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control import checks
from equilibrist.control.analysis import (
    _pbh_modes,
    describe_modes,
)
from equilibrist.control.riccati import (
    _boundary_modes,
    _sqrt_psd,
)
from equilibrist.errors import DesignError, DimensionError
from equilibrist.numeric.linear import LinearModel

if TYPE_CHECKING:
    from equilibrist.numeric.system import System


# Floor of the default process noise on states the spec gives none, as a
# fraction of the state's design scale (used only when needed; see above).
NOISE_FLOOR = 1e-3


# -- argument handling ---------------------------------------------------------------------


def _weight(
    value: object, name: str, labels: Sequence[str], *, definite: bool, problems: list[str]
) -> np.ndarray:
    """A vector (the diagonal) or a square matrix over *labels*; sign problems collected."""
    n = len(labels)
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise DimensionError(f"{name} must be numbers, got {value!r}") from None
    if arr.ndim == 0 and n == 1:
        arr = arr.reshape(1)
    if arr.ndim == 1:
        if arr.size != n:
            raise DimensionError(
                f"{name} has {arr.size} values, expected {n} (one per {', '.join(labels)})"
            )
        if not np.all(np.isfinite(arr)):
            raise DesignError(f"{name} has a value that is not a finite number")
        for label, v in zip(labels, arr, strict=True):
            if definite and not v > 0:
                problems.append(f"{name} for {label} is {v:g}: expected > 0")
            elif not definite and v < 0:
                problems.append(f"{name} for {label} is {v:g}: expected >= 0")
        return np.diag(arr)
    mat = checks.matrix(arr, name, (n, n), f"one row and column per {', '.join(labels)}")
    problems.extend(checks.weight_problems(mat, name, definite=definite))
    return mat


def _bryson(system: System, names: Sequence[str], missing: list[str]) -> np.ndarray:
    scales = system.spec.design_scales
    values = []
    for n in names:
        s = scales.get(n)
        if s is None or not s > 0:
            missing.append(n)
            values.append(1.0)
        else:
            values.append(1.0 / float(s) ** 2)
    return np.diag(values)


def _default_process_noise(
    system: System, plant: LinearModel
) -> tuple[np.ndarray, tuple[str, ...]]:
    spec, states = system.spec, plant.state_names
    if not spec.process_noise:
        raise DesignError(
            f"{system.key} gives no process noise in its spec: give qn "
            f"(one value per state: {', '.join(states)})"
        )
    unknown = [k for k in spec.process_noise if k not in states]
    if unknown:
        raise DesignError(
            f"{system.key}'s process noise names {', '.join(unknown)}, which are not states "
            f"({', '.join(states)}): give qn"
        )
    sigma = np.array([float(spec.process_noise.get(s, 0.0)) for s in states])
    QN = np.diag(sigma**2)
    scale = float(np.linalg.norm(plant.A, 2)) if plant.n_states else 1.0
    hidden = _boundary_modes(_pbh_modes(plant.A, _sqrt_psd(QN), states, False), False, scale)
    if not hidden:
        return QN, ()
    quiet = [s for s, v in zip(states, sigma, strict=True) if v == 0]
    involved = {s for mode in hidden for s in mode.states}
    if any(s in involved for s in quiet):
        quiet = [s for s in quiet if s in involved]
    missing = [s for s in quiet if not spec.design_scales.get(s, 0) > 0]
    if missing:
        raise DesignError(
            f"{system.key}'s process noise leaves the marginal mode(s) {describe_modes(hidden)} "
            f"unexcited and there is no design scale for {', '.join(missing)} to set a floor: "
            f"give qn"
        )
    for s in quiet:
        i = states.index(s)
        QN[i, i] = (NOISE_FLOOR * float(spec.design_scales[s])) ** 2
    still = _boundary_modes(_pbh_modes(plant.A, _sqrt_psd(QN), states, False), False, scale)
    if still:
        raise DesignError(
            f"{system.key}'s process noise leaves the marginal mode(s) {describe_modes(still)} "
            f"unexcited: give qn"
        )
    note = (
        f"process noise floor (1e-3 x design scale)^2 added on {', '.join(quiet)}: the spec's "
        f"process noise leaves the marginal mode(s) {describe_modes(hidden)} unexcited, and the "
        f"Kalman Riccati equation would have no stabilizing solution"
    )
    return QN, (note,)


# The fastest sample rate a design accepts [Hz].
MAX_RATE = 1e6
