"""A nonlinear controller's functions compiled alone, called sample by sample from Python.

The same translation as in the simulation core (:mod:`equilibrist.native.pyc`),
without a system: a small library with ``eq_output``, ``eq_update`` and
``eq_estimate`` (written by :func:`equilibrist.native.controller_c.unit_source`), built and
cached like the cores (:mod:`equilibrist.native.build`). :class:`ControllerFunctions` calls them
with the signatures of the Python source (``output(t, z, y, r, params,
u_out)``...), so a Python runtime of a controller (the swing-up's, for
studies of single runs) runs the compiled arithmetic of the simulation core.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable
from typing import Any

import numpy as np

from equilibrist.native import build
from equilibrist.native.controller_c import CONTRACT_TYPES, unit_source


class ControllerFunctions:
    """``output``, ``update`` (and ``estimate``) of a controller's source, compiled."""

    def __init__(self, source: str, names: tuple[str, ...] = ("output", "update")) -> None:
        self.lib, self.path = build.load(unit_source(source, names), "controller")
        self.fns: dict[str, Any] = {}
        for name in names:
            fn = getattr(self.lib, f"eq_{name}")
            argtypes: list[type[ctypes.c_double | ctypes.c_void_p | ctypes.c_int64]] = []
            for t in CONTRACT_TYPES[name]:
                argtypes += [ctypes.c_double] if t == "f" else [ctypes.c_void_p, ctypes.c_int64]
            fn.argtypes = argtypes
            fn.restype = None
            self.fns[name] = fn

    def __getitem__(self, name: str) -> Callable[..., None]:
        fn = self.fns[name]

        def call(t: float, *arrays: np.ndarray) -> None:
            args: list[float | int | None] = [float(t)]
            for a in arrays:
                if a.dtype != np.float64 or not a.flags.c_contiguous:
                    raise TypeError("the compiled controller takes C-contiguous float64 arrays")
                args += [a.ctypes.data if a.size else None, a.shape[0]]
            fn(*args)

        return call


_LOADED: dict[tuple[str, tuple[str, ...]], ControllerFunctions] = {}


def controller_functions(source: str, names: tuple[str, ...] = ("output", "update")
                         ) -> ControllerFunctions:
    """The compiled functions *names* of *source* (built once per process)."""
    key = (source, names)
    if key not in _LOADED:
        _LOADED[key] = ControllerFunctions(source, names)
    return _LOADED[key]


__all__ = ["ControllerFunctions", "controller_functions"]
