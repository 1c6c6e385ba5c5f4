"""The compiled multiple-shooting integrator: one numba module per system, cached on disk.

The integrator's source is written once, in ``_shoot_template.py`` (its RK4
step is the simulation core's, ``equilibrist/sim/_rk4_template.py``). For each
system it is appended to a copy of the system's generated dynamics (the
numeric layer's ``f``, which compiles unchanged with numba) and written to
the numeric cache folder as ``<system>_<hash>_shoot_<hash>.py``; its
functions are ``njit(cache=True)``, so a process compiles a system's
integrator once and later processes load the machine code.

Importing this module does no work; numba is imported when an integrator is
first loaded.
"""

from __future__ import annotations

import hashlib
import types
from pathlib import Path

from equilibrist.numeric.cache import import_generated, template_body, write_generated
from equilibrist.numeric.system import System

_HEADER = (
    "\n\n# --- multiple-shooting integrator (equilibrist.ident._shoot_template) ---\n"
    "import math  # noqa: E402\n"
    "import numpy as np  # noqa: E402\n"
    "from numba import njit  # noqa: E402\n\n"
)
_LOADED: dict[Path, types.ModuleType] = {}


def _body() -> str:
    """The integrator's loops, then the simulation core's RK4 step (the same arithmetic)."""
    return template_body(Path(__file__).parent / "_shoot_template.py",
                         Path(__file__).parents[1] / "sim" / "_rk4_template.py")


def shooting_path(system: System) -> Path:
    """Where the integrator module of *system* lives in the cache (written if missing)."""
    body = _body()
    digest = hashlib.sha256(body.encode()).hexdigest()[:12]
    module_path = system.compiled.module_path
    path = module_path.with_name(f"{module_path.stem}_shoot_{digest}.py")
    write_generated(path, module_path.read_text() + _HEADER + body)  # kept if whole, rewritten if damaged
    return path


def load_shooting(system: System) -> types.ModuleType:
    """The compiled integrator of *system* (its entry compiles on first call)."""
    path = shooting_path(system)
    if path in _LOADED:
        return _LOADED[path]
    module = import_generated(f"equilibrist_shoot_{path.stem}", path)
    _LOADED[path] = module
    return module


__all__ = ["load_shooting", "shooting_path"]
