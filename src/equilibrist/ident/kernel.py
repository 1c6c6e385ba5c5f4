"""The compiled multiple-shooting integrator: entries of the system's C core.

The loops are written once in C (``equilibrist/native/shoot.c``), in the
same translation unit as the simulation core, and call its steps (any
integrator of :mod:`equilibrist.sim.integrators`' table, RK4 by default):
the identification predicts with the very arithmetic that the simulation
and the environments integrate with. :func:`load_shooting` gives them numpy
signatures.

Importing this module does no work; the core is built (or loaded from the
cache) when an integrator is first asked for.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from equilibrist.ident.log import IdentificationError
from equilibrist.numeric.system import System
from equilibrist.sim import integrators

if TYPE_CHECKING:
    from pathlib import Path

    from equilibrist.sim.simcore import NativeCore


def _f64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def _i64(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.int64)


class Shooting:
    """``shoot_many`` and ``innovations`` of one system's core, with the steps of
    *integrator* (a name of :mod:`equilibrist.sim.integrators`' table)."""

    def __init__(self, system: System, integrator: str = integrators.DEFAULT) -> None:
        wrong = integrators.check(integrator)
        if wrong is not None:
            raise IdentificationError(wrong)
        self.system = system
        self.integrator = integrator

    @property
    def core(self) -> NativeCore:
        """The system's core (the one holding the integrators registered by now)."""
        from equilibrist.sim.simcore import load_core

        return load_core(self.system)

    def shoot_many(self, P: np.ndarray, XS: np.ndarray, bounds: np.ndarray, t: np.ndarray,
                   u: np.ndarray, n_sub: np.ndarray, c_idx: np.ndarray, yhat: np.ndarray,
                   xend: np.ndarray) -> None:
        """Run every segment for each of ``K`` cases: ``P`` (K, n_p) parameter vectors,
        ``XS`` (K, n_seg, n) segment initial states; writes ``yhat`` (K, n_rows, ny) and
        ``xend`` (K, n_seg, n)."""
        core = self.core
        core._out(yhat, np.float64, "yhat")
        core._out(xend, np.float64, "xend")
        P, XS, t, u = _f64(P), _f64(XS), _f64(t), _f64(u)
        bounds, n_sub, c_idx = _i64(bounds), _i64(n_sub), _i64(c_idx)
        core.shoot_many(P, XS, bounds, t, u, n_sub, c_idx, yhat, xend,
                        integrator=self.integrator)

    def innovations(self, p: np.ndarray, x0: np.ndarray, t: np.ndarray, u: np.ndarray,
                    n_sub: np.ndarray, c_idx: np.ndarray, gain: np.ndarray, y: np.ndarray,
                    off: np.ndarray, e: np.ndarray) -> None:
        """One-step prediction errors of a Kalman filter with the fixed *gain* (n, ny)."""
        core = self.core
        core._out(e, np.float64, "e")
        core.innovations(_f64(p), _f64(x0), _f64(t), _f64(u), _i64(n_sub), _i64(c_idx),
                         _f64(gain), _f64(y), _f64(off), e, integrator=self.integrator)


_LOADED: dict[tuple[Path, str], Shooting] = {}


def load_shooting(system: System, integrator: str = integrators.DEFAULT) -> Shooting:
    """The compiled integrator of *system* with the steps of *integrator*."""
    key = (system.compiled.module_path, integrator)
    if key not in _LOADED:
        _LOADED[key] = Shooting(system, integrator)
    return _LOADED[key]


__all__ = ["Shooting", "load_shooting"]
