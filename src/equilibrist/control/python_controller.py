"""Controllers written in Python: the :class:`PythonController` protocol, its defaults
(:class:`PythonControllerBase`) and the adapter of the older ``step`` interface
(:class:`StepAdapter`); used by :mod:`equilibrist.control.controller`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol, runtime_checkable

import numpy as np


# -- controllers written in Python ----------------------------------------------------------
@runtime_checkable
class PythonController(Protocol):
    """A controller written in Python, called once per sample by the simulator.

    Attributes
    ----------
    rate:
        The sample rate [Hz] it was written for, or None (the run's rate).
    outputs:
        The states it measures, in the order of ``y``, or None (the run's
        ``outputs``, else the system's default outputs).
    estimate:
        Its absolute state estimate after the last :meth:`output`, or None.
    """

    rate: float | None
    outputs: tuple[str, ...] | None
    estimate: np.ndarray | None

    def reset(self) -> None:
        """Start again (called before every run)."""

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        """The command (absolute inputs) at sample time *t* from measurements *y* and references *r*."""
        ...

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        """Advance the controller's state: *u_applied* is what acted (saturated, delayed)."""


class PythonControllerBase:
    """Defaults of the :class:`PythonController` protocol: subclass and write ``output``.

    ``rate``, ``outputs`` and ``estimate`` are None; ``reset`` and
    ``update`` do nothing.
    """

    rate: float | None = None
    outputs: tuple[str, ...] | None = None
    estimate: np.ndarray | None = None

    def reset(self) -> None:
        """Nothing to reset."""

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        """No state to advance."""


class StepAdapter(PythonControllerBase):
    """The older step interface as a :class:`PythonController` (kept for existing code).

    Wraps an object with ``step(t, y, r) -> u`` (and, optionally, the old
    ``reset()``, ``applied(u)``, ``estimate``, ``rate`` and ``outputs``
    attributes) or a plain function ``(t, y, r) -> u``. This adapter is the
    only place those optional attributes are looked up.
    """

    def __init__(self, target: Any) -> None:
        self.target = target
        is_function = not (hasattr(target, "step") and callable(target.step))
        self._step: Callable[[float, np.ndarray, np.ndarray], object] = (
            target if is_function else target.step)
        self._reset = None if is_function else getattr(target, "reset", None)
        self._applied = None if is_function else getattr(target, "applied", None)
        self.rate = None if is_function else getattr(target, "rate", None)
        declared = None if is_function else getattr(target, "outputs", None)
        self.outputs = None if declared is None else tuple(declared)
        self._has_estimate = (not is_function) and hasattr(target, "estimate")
        self.estimate = None

    def reset(self) -> None:
        if callable(self._reset):
            self._reset()
        self.estimate = None

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        u = self._step(t, y, r)
        est = getattr(self.target, "estimate", None) if self._has_estimate else None
        self.estimate = None if est is None else np.asarray(est, dtype=float)
        return np.asarray(u, dtype=float)

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        if callable(self._applied):
            self._applied(u_applied)
