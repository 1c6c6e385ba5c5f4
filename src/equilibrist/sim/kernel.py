"""The compiled simulation core: one numba module per system, cached on disk.

The core's source is written once, in ``_kernel_template.py``. For each
system it is appended to a copy of the system's generated dynamics (the
numeric layer's ``f``) and written to the numeric cache folder, keyed by the
generated module's hash and the template's hash, as
``<system>_<hash>_sim_<hash>.py``. Its functions are ``njit(cache=True)``,
so numba keeps their machine code in that folder's ``__pycache__``: a
process compiles a system's core once, later processes load it.

The entries (see the template's docstring for the array conventions):

``run_one``
    One closed-loop run with a built-in controller (resumable by sample range).
``run_many``
    Many independent runs in parallel (``numba.prange`` over runs).
``measure_one``, ``advance_one``
    The two halves of a sample, for controllers written in Python.
``rk4_steps``
    Plain RK4 steps with the input held (environments, playground).
``normals``
    The core's normal deviates (tests of the generator).

Importing this module does no work; numba is imported when a kernel is
first loaded.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import sys
import tempfile
import types
from pathlib import Path

from equilibrist.numeric.system import System

_MARKER = "# ---8<--- kernel body"
_HEADER = (
    "\n\n# --- simulation core (equilibrist.sim._kernel_template) ---\n"
    "import numpy as np  # noqa: E402\n"
    "from numba import njit, prange  # noqa: E402\n\n"
)
_LOADED: dict[Path, types.ModuleType] = {}
_PATHS: dict[Path, Path] = {}


def _template_body() -> str:
    text = (Path(__file__).parent / "_kernel_template.py").read_text()
    _head, sep, body = text.partition(_MARKER)
    if not sep:  # pragma: no cover - a broken install
        raise RuntimeError("the simulation kernel template has lost its marker line")
    return body.split("\n", 1)[1]


def kernel_path(system: System) -> Path:
    """Where the kernel module of *system* lives in the cache (written if missing)."""
    known = _PATHS.get(system.compiled.module_path)
    if known is not None and known.exists():
        return known
    body = _template_body()
    digest = hashlib.sha256(body.encode()).hexdigest()[:12]
    module_path = system.compiled.module_path
    path = module_path.with_name(f"{module_path.stem}_sim_{digest}.py")
    if not path.exists():
        source = module_path.read_text() + _HEADER + body
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".")
        try:
            with os.fdopen(fd, "w") as fh:
                fh.write(source)
            # Never replace a kernel another process wrote: numba's on-disk
            # cache is keyed on the source file's time stamp.
            if path.exists():
                Path(tmp).unlink()
            else:
                os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
    _PATHS[module_path] = path
    return path


def load_kernel(system: System) -> types.ModuleType:
    """The compiled core of *system* (a module whose entries compile on first call)."""
    path = kernel_path(system)
    if path in _LOADED:
        return _LOADED[path]
    name = f"equilibrist_simkernel_{path.stem}"
    module = sys.modules.get(name)
    if module is None:
        spec = importlib.util.spec_from_file_location(name, path)
        if spec is None or spec.loader is None:  # pragma: no cover
            raise RuntimeError(f"cannot load the simulation kernel {path}")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[name]
            raise
    _LOADED[path] = module
    return module


def set_workers(workers: int | None) -> int:
    """Set numba's thread count for parallel entries; returns the count in force."""
    import numba

    available = numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]  # set at import by numba.config
    count = available if workers is None else max(1, min(int(workers), available))
    numba.set_num_threads(count)
    return count


__all__ = ["kernel_path", "load_kernel", "set_workers"]
