"""C code generation of the digital controllers: the controller that ships is the one simulated.

:func:`export_c` writes a self-contained C99 library (one header, one
source, no dynamic memory, nothing beyond the C standard library) of a
discrete design's LQG or LQR controller, with a desktop example, an
Arduino sketch, test vectors from a recorded closed-loop run, a test
program and a Makefile. :func:`compile_controller` builds the same code
into a shared library and loads it, and
:func:`c_controller` wraps it as a controller of
equilibrist's simulation, so the exported code closes the loop on the
nonlinear plant.

Importing this package does no work; the submodules load on first use.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

_LAZY = {
    "export_c": "equilibrist.export.writer",
    "Export": "equilibrist.export.writer",
    "controller_data": "equilibrist.export.data",
    "compile_controller": "equilibrist.export.vectors",
    "c_controller": "equilibrist.export.vectors",
    "CController": "equilibrist.export.vectors",
}

if TYPE_CHECKING:
    from equilibrist.export.data import controller_data
    from equilibrist.export.vectors import CController, c_controller, compile_controller
    from equilibrist.export.writer import Export, export_c

__all__ = [
    "CController",
    "Export",
    "c_controller",
    "compile_controller",
    "controller_data",
    "export_c",
]


def __getattr__(name: str) -> object:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(module), name)
