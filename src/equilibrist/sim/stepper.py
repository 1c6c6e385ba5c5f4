"""The plant alone, advanced with a held input: the step the environments share.

:class:`Stepper` runs the same compiled RK4 as the closed-loop core, for
callers that make their own decisions between steps (Gymnasium
environments, the web playground).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.errors import DimensionError, SimulationError
from equilibrist.numeric.system import System
from equilibrist.sim.kernel import load_kernel

if TYPE_CHECKING:
    from equilibrist.sim.simcore import NativeCore


@dataclass(frozen=True, eq=False)
class Stepper:
    """RK4 steps of ``physics_step`` seconds of *system*'s own dynamics.

    Examples
    --------
    >>> stepper = Stepper(get_system("cartpole"), physics_step=1e-3)  # doctest: +SKIP
    >>> x = stepper.advance([0, 0.1, 0, 0], [0.0], n_steps=20)        # doctest: +SKIP
    """

    system: System
    physics_step: float = 1e-3
    _kernel: NativeCore = field(init=False, repr=False)  # set in __post_init__
    _p: np.ndarray = field(init=False, repr=False)  # set in __post_init__

    def __post_init__(self) -> None:
        h = float(self.physics_step)
        if not math.isfinite(h) or h <= 0:
            raise SimulationError(f"physics step must be a positive number of seconds, got {h!r}")
        object.__setattr__(self, "physics_step", h)
        object.__setattr__(self, "_kernel", load_kernel(self.system))
        object.__setattr__(self, "_p", np.array(self.system.p, dtype=float))

    def advance(self, x: object, u: object, *, n_steps: int = 1) -> np.ndarray:
        """The state after *n_steps* steps from *x* with input *u* held (a new array)."""
        xv = np.array(x, dtype=float).reshape(-1)
        uv = np.array(u, dtype=float).reshape(-1)
        if xv.size != self.system.n_states:
            raise DimensionError(f"state has {xv.size} values, expected {self.system.n_states}")
        if uv.size != self.system.n_inputs:
            raise DimensionError(f"input has {uv.size} values, expected {self.system.n_inputs}")
        if not (np.all(np.isfinite(xv)) and np.all(np.isfinite(uv))):
            raise SimulationError("the state and input must be finite numbers")
        if int(n_steps) < 0:
            raise SimulationError(f"n_steps must be >= 0, got {n_steps}")
        self._kernel.rk4_steps(xv, uv, self._p, self.physics_step, int(n_steps))
        return xv
