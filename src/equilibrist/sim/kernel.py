"""The compiled simulation core, as the simulator, the batches and the playground call it.

The core is C generated per system and controller
(:mod:`equilibrist.sim.simcore`): the system's dynamics and the
controller translated from their one Python definition, the loops written
once in ``equilibrist/native/core.c``, compiled by the machine's C compiler
and cached by content. :class:`Kernel` picks the library for a run
(:meth:`Kernel.core`); the callers pass its entries the arrays by keyword,
and the library (:class:`~equilibrist.sim.simcore.NativeCore`) is the one
place that knows the entries' argument order.

The entries (see ``core.c`` for the array conventions):

``run_one``
    One closed-loop run with a compiled controller (resumable by sample range).
``run_many``
    Many independent runs in parallel (OpenMP threads over runs).
``measurer``, ``advancer`` (of :attr:`Kernel.generic`)
    The two halves of a sample, for controllers written in Python.
``rk4_steps``
    Plain RK4 steps with the input held (playground, stepper).

A linear controller runs in the core made for its *pattern*
(:func:`~equilibrist.native.linear_layout.linear_pattern`: its sizes, and
which coefficients are exact zeros and ones), with the linear library
written out term by term; an LQR and an LQG of a system are two libraries,
each compiled once. A nonlinear controller runs in the core made for its
source.

Importing this module does no work; a library is built or loaded on first use.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control.nonlinear import NonlinearController
from equilibrist.native.linear_layout import linear_pattern, linear_sizes
from equilibrist.numeric.system import System

if TYPE_CHECKING:
    from equilibrist.sim.simcore import NativeCore

#: What the linear library of a core is specialized to: a controller's sizes
#: ``(nz, ny, nr, m, n)`` (its loops with literal trip counts), or its
#: :func:`linear_pattern` (written out term by term).
Linear = tuple[int, int, int, int, int] | bytes

_KEYS: dict[bytes, Linear | None] = {}  # packed controller -> what its core is made for


def _linear_key(cp: np.ndarray) -> Linear | None:
    """The pattern (or the sizes) the core of packed linear controller *cp* is made for."""
    raw = cp.tobytes()
    if raw in _KEYS:
        return _KEYS[raw]
    key: Linear | None = linear_pattern(cp)
    if key is None:
        found = linear_sizes(cp)
        if found is not None:
            key = (found["nz"], found["ny"], found["nr"], found["m"], found["n"])
    if len(_KEYS) > 1024:
        _KEYS.clear()
    _KEYS[raw] = key
    return key


def load_kernel(system: System) -> NativeCore:
    """The core of *system* with the generic linear library: the entries that run no
    controller of their own (``rk4_steps``, ``normals``, ``f``, the environments')."""
    from equilibrist.sim.simcore import load_core

    return load_core(system)


class Kernel:
    """The cores of one system (and nonlinear controller), called with keyword arguments.

    The library's ``run_one`` and ``run_many`` (:meth:`core`; ``run_many`` on
    :func:`thread_count` threads) release the GIL and return early when
    ``stop[0]`` (a one-element ``int64`` array) is set, from another thread.
    """

    def __init__(self, system: System, controller: NonlinearController | None = None) -> None:
        self.system = system
        self.controller = controller

    def core(self, cp: np.ndarray) -> NativeCore:
        """The library whose ``run_one``/``run_many`` run controller parameters *cp*."""
        from equilibrist.sim.simcore import load_core

        if self.controller is not None:
            return load_core(self.system, None, self.controller)
        return load_core(self.system, _linear_key(cp))

    @property
    def generic(self) -> NativeCore:
        return load_kernel(self.system)

    def compiled(self, cp: np.ndarray) -> bool:
        """Whether the library for controller parameters *cp* is loaded in this process."""
        from equilibrist.sim.simcore import loaded

        if self.controller is not None:
            return loaded(self.system, None, self.controller)
        return loaded(self.system, _linear_key(cp))

    def scratch(self, *, p_len: int, ny: int, nw: int) -> np.ndarray:
        return self.generic.scratch(p_len, ny, nw)

    def rk4_steps(self, *, x: np.ndarray, u: np.ndarray, p: np.ndarray, h: float,
                  n_steps: int) -> None:
        self.generic.rk4_steps(x, u, p, h, n_steps)


# The thread count of parallel entries (set_workers): the C core's OpenMP threads.
_THREADS = [os.cpu_count() or 1]


def thread_count() -> int:
    """The thread count of parallel entries in force (:func:`set_workers`)."""
    return _THREADS[0]


def threads_for(workers: int | None) -> int:
    """The thread count *workers* asks for, within the machine's cores (None: every core)."""
    available = os.cpu_count() or 1
    return available if workers is None else max(1, min(int(workers), available))


def set_workers(workers: int | None) -> int:
    """Set the thread count of parallel entries (None: every core); returns it."""
    _THREADS[0] = threads_for(workers)
    return _THREADS[0]


__all__ = ["Kernel", "load_kernel", "set_workers", "thread_count", "threads_for"]
