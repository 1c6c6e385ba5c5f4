"""The compiled simulation core: one numba module per system, cached on disk.

The core's source is written once, in ``_kernel_template.py`` (and the
environments' steps in ``_env_template.py``). For each
system it is appended to a copy of the system's generated dynamics (the
numeric layer's ``f``), after the calling convention's constants
(:mod:`equilibrist.sim.layout`) and the controller's source: the linear
controller's (:data:`equilibrist.control.controller.LINEAR_SOURCE`) for
every built-in linear controller, or a
:class:`~equilibrist.control.controller.NonlinearController`'s own source
(with the linear library beside it). The result is written to the numeric
cache folder, keyed by the generated module's hash and the hash of
everything appended, as ``<system>_<hash>_sim_<hash>.py``.

The core that runs a linear controller in ``simulate`` and
``simulate_batch`` is generated for that controller's *pattern*
(:func:`~equilibrist.control.controller.linear_pattern`: its sizes, and
which coefficients are exact zeros and ones): the linear library is then
written out term by term
(:func:`~equilibrist.control.controller.linear_unrolled_source`), with the
same results to the bit as the generic loops. An LQR and an LQG of a
system are two cores, each compiled once and cached on disk; designs of the
same kind for the same system share one (their zeros and ones are those of
the form, not of the weights). Its functions
are ``njit(cache=True)``, so numba keeps their machine code in that
folder's ``__pycache__``: a process compiles a system's core once (per
nonlinear controller source), later processes load it.

:class:`Kernel` wraps a loaded module: its methods take keyword arguments
and are the only code that knows the entries' argument order.

The entries (see the template's docstring for the array conventions):

``run_one``
    One closed-loop run with a compiled controller (resumable by sample range).
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

import ast
import hashlib
import os
import sys
import types
from pathlib import Path
from typing import Any

from equilibrist.control.controller import (
    LINEAR_FUNCTIONS,
    LINEAR_SOURCE,
    NonlinearController,
    check_source,
    linear_layout_source,
    linear_pattern,
    linear_sizes,
    linear_unrolled_source,
)
from equilibrist.numeric.cache import import_generated, template_body, write_generated
from equilibrist.numeric.system import System
from equilibrist.sim import layout

_HEADER = (
    "\n\n# --- simulation core (equilibrist.sim._kernel_template) ---\n"
    "import math  # noqa: E402\n"
    "import numpy as np  # noqa: E402\n"
    "from numba import njit, prange  # noqa: E402\n\n"
)
_CONTROLLER_JIT = (
    "_ctrl_jit = njit(cache=True, error_model=\"numpy\", _nrt=False, inline=\"always\")  # noqa: E402\n"
)
_LOADED: dict[Path, types.ModuleType] = {}
_PATHS: dict[tuple[Path, str], Path] = {}  # (system module, section) -> kernel
_BY_SECTION: dict[tuple[Path, str], types.ModuleType] = {}  # the same key -> loaded module
#: The sizes of a linear controller, ``(nz, ny, nr, m, n)``.
Sizes = tuple[int, int, int, int, int]
_SIZE_KEYS = ("nz", "ny", "nr", "m", "n")
#: What the linear library of a core is specialized to: a controller's sizes (its loops
#: with literal trip counts), or its :func:`linear_pattern` (written out term by term).
Linear = Sizes | bytes


def _template_body() -> str:
    """The simulation core's body, its RK4 step, then the environments' steps."""
    here = Path(__file__).parent
    return template_body(*(here / name for name in
                           ("_kernel_template.py", "_rk4_template.py", "_env_template.py")))


_SECTIONS: dict[str, str] = {}


def controller_section(controller: NonlinearController | None = None,
                       sizes: Linear | None = None) -> str:
    """The generated source between the system's ``f`` and the core's body.

    The layout's constants, the linear library, and the functions the core
    calls (``controller_output``, ``controller_update``,
    ``controller_estimate``): the linear library's own, or *controller*'s.
    Every function of the section is compiled like the core's helpers
    (no reference counting), so a controller may slice its arrays freely.

    Only without *controller*: with *sizes* a linear controller's
    ``nz, ny, nr, m, n``, the linear library's sizes and offsets are
    literals of the section
    (:func:`~equilibrist.control.controller.linear_layout_source`), so
    numba unrolls its loops; with a pattern (bytes, from
    :func:`~equilibrist.control.controller.linear_pattern`) the library is
    written out term by term for that pattern
    (:func:`~equilibrist.control.controller.linear_unrolled_source`).
    Without either, they are read from the packed vector (any linear
    controller, and the linear controllers a nonlinear one embeds).
    """
    if controller is not None and sizes is not None:
        raise ValueError("fixed linear sizes are for the linear controller's own core")
    key = (repr(sizes) if controller is None
           else controller.source + repr(controller.has_estimate))
    known = _SECTIONS.get(key)
    if known is not None:
        return known
    if isinstance(sizes, bytes):
        library = linear_unrolled_source(sizes)
    else:
        fixed = None if sizes is None else dict(zip(_SIZE_KEYS, sizes, strict=True))
        library = linear_layout_source(fixed) + LINEAR_SOURCE
    parts = ["# --- calling convention (equilibrist.sim.layout) ---\n",
             layout.constants_source(), "\n", _CONTROLLER_JIT, library, "\n"]
    names = ["linear_layout", *LINEAR_FUNCTIONS]
    if controller is None:
        binding = ("controller_output = linear_output\n"
                   "controller_update = linear_update\n"
                   "controller_estimate = linear_estimate\n")
    else:
        own = check_source(controller.source, has_estimate=controller.has_estimate)
        parts += [f"\n# --- controller {controller.name} ---\n", controller.source, "\n"]
        names += list(own)
        estimate = "estimate" if controller.has_estimate else "linear_estimate"
        binding = ("controller_output = output\n"
                   "controller_update = update\n"
                   f"controller_estimate = {estimate}\n")
    parts += [f"{name} = _ctrl_jit({name})\n" for name in names]
    parts.append(binding)
    _SECTIONS[key] = "".join(parts)
    return _SECTIONS[key]


def kernel_path(system: System, controller: NonlinearController | None = None,
                sizes: Linear | None = None) -> Path:
    """Where the kernel module of *system* (and *controller*, or a linear controller's
    *sizes*) lives in the cache (written if missing)."""
    module_path = system.compiled.module_path
    section = controller_section(controller, sizes)
    key = (module_path, section)
    known = _PATHS.get(key)
    if known is not None and known.exists():
        return known
    body = _template_body()
    digest = hashlib.sha256((section + body).encode()).hexdigest()[:12]
    path = module_path.with_name(f"{module_path.stem}_sim_{digest}.py")
    source = module_path.read_text() + _HEADER + section + "\n" + body
    if not path.exists():
        ast.parse(source)  # a broken controller source fails here, not inside numba
    write_generated(path, source)  # kept if whole, rewritten if damaged
    _PATHS[key] = path
    return path


def load_kernel(system: System, controller: NonlinearController | None = None,
                sizes: Linear | None = None) -> types.ModuleType:
    """The compiled core of *system* (a module whose entries compile on first call).

    With a nonlinear *controller*, the core that runs it (one per source);
    with a linear controller's *sizes* or pattern, the core specialized to
    them (see :func:`controller_section`).
    """
    key = (system.compiled.module_path, controller_section(controller, sizes))
    loaded = _BY_SECTION.get(key)
    if loaded is not None:  # in memory already: no look at the disk
        return loaded
    path = kernel_path(system, controller, sizes)
    if path in _LOADED:
        _BY_SECTION[key] = _LOADED[path]
        return _LOADED[path]
    module = import_generated(f"equilibrist_simkernel_{path.stem}", path)
    _LOADED[path] = module
    _BY_SECTION[key] = module
    return module


_KEYS: dict[bytes, Linear | None] = {}  # packed controller -> what its core is made for


def _linear_key(cp: Any) -> Linear | None:
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


class Kernel:
    """A loaded core, called with keyword arguments only.

    The array arguments are those of the template's entries (see its
    docstring and :mod:`equilibrist.sim.layout`); this class is the one
    place that passes them in order.

    Without a nonlinear controller, ``run_one`` and ``run_many`` run in the
    core specialized to the packed linear controller they are given (``cp``:
    its :func:`~equilibrist.control.controller.linear_pattern`, or its sizes
    when it is too large to write out; one module per system and pattern,
    loaded on first use); the other entries, and a nonlinear controller's
    runs, in :attr:`module`.

    ``run_one`` and ``run_many`` release the GIL and return early when
    ``stop[0]`` (a one-element ``int64`` array) is set, from another thread.
    """

    def __init__(self, system: System, controller: NonlinearController | None = None) -> None:
        self.system = system
        self.controller = controller
        self._module: types.ModuleType | None = None
        self._cores: dict[Linear | None, Any] = {}
        self._nl: Any = None

    @property
    def module(self) -> types.ModuleType:
        """The numba module that runs a nonlinear controller (loaded on first use)."""
        if self._module is None:
            self._module = load_kernel(self.system, self.controller)
        return self._module

    def _native(self, key: Linear | None) -> Any:
        core = self._cores.get(key)
        if core is None:
            from equilibrist.native.simcore import load_core

            core = self._cores[key] = load_core(self.system, key)
        return core

    def _nonlinear(self) -> Any:
        """The C core of the nonlinear controller, or its numba module when its source uses
        what the C translation does not know."""
        if self._nl is None:
            from equilibrist.native.pyc import TranslationError
            from equilibrist.native.simcore import load_core

            try:
                self._nl = load_core(self.system, None, self.controller)
            except TranslationError:
                self._nl = self.module
        return self._nl

    @property
    def generic(self) -> Any:
        """The C core with the generic linear library (the entries that run no controller)."""
        return self._native(None)

    def core(self, cp: Any) -> Any:
        """The core whose ``run_one``/``run_many`` run controller parameters *cp*: the C core
        made for a linear controller's pattern, or the numba module of a nonlinear one."""
        if self.controller is not None:
            return self._nonlinear()
        return self._native(_linear_key(cp))

    def compiled(self, cp: Any) -> bool:
        """Whether ``run_one`` and ``run_many`` for controller parameters *cp* are compiled
        (or loaded from the cache) in this process already."""
        if self.controller is not None:
            if self._nl is None:
                return False
            if isinstance(self._nl, types.ModuleType):
                return bool(self._nl.run_one.overloads) and bool(self._nl.run_many.overloads)
            return True
        return (self.system.compiled.module_path, _linear_key(cp), None) in _native_loaded()

    def run_one(self, *, k_start: int, k_end: int, iopts: Any, fopts: Any, x: Any, z: Any,
                u_prev: Any, rng: Any, op: Any, c_idx: Any, cp: Any, ref: Any, uff: Any,
                lv: Any, lw: Any, p_sets: Any, p_switch: Any, lin_s: Any, region: Any,
                kicks: Any, kick_value: Any, pulses: Any, pulse_value: Any, rec_cols: Any,
                acc_cols: Any, rec: Any, acc: Any, status: Any, fell_x: Any,
                stop: Any, core: Any = None) -> None:
        """One run, or samples ``k_start .. k_end - 1`` of one (*core*: :meth:`core` of *cp*,
        if the caller has it already)."""
        (core or self.core(cp)).run_one(
            k_start, k_end, iopts, fopts, x, z, u_prev, rng, op, c_idx, cp, ref, uff, lv, lw,
            p_sets, p_switch, lin_s, region, kicks, kick_value, pulses, pulse_value,
            rec_cols, acc_cols, rec, acc, status, fell_x, stop,
        )

    def run_many(self, *, iopts: Any, fopts: Any, x0s: Any, z0: Any, rngs: Any, op: Any,
                 c_idx: Any, cp: Any, ref: Any, uff: Any, lv: Any, lw: Any, p_sets_r: Any,
                 p_switch: Any, lin_r: Any, region: Any, kicks: Any, kick_value: Any,
                 pulses: Any, pulse_value: Any, rec_cols: Any, acc_cols: Any, recs: Any,
                 accs: Any, statuses: Any, fell_xs: Any, x_ends: Any, stop: Any,
                 core: Any = None) -> None:
        target = core or self.core(cp)
        extra = {} if isinstance(target, types.ModuleType) else {"threads": _THREADS[0]}
        target.run_many(
            iopts, fopts, x0s, z0, rngs, op, c_idx, cp, ref, uff, lv, lw, p_sets_r, p_switch,
            lin_r, region, kicks, kick_value, pulses, pulse_value, rec_cols, acc_cols, recs,
            accs, statuses, fell_xs, x_ends, stop, **extra,
        )

    def measure_one(self, *, x: Any, c_idx: Any, lv: Any, rng: Any, y: Any) -> None:
        self.generic.measure_one(x, c_idx, lv, rng, y)

    def scratch(self, *, p_len: int, ny: int, nw: int) -> Any:
        return self.generic.scratch(p_len, ny, nw)

    def advance_one(self, *, k: int, x: Any, u_app: Any, op: Any, p_sets: Any, p_switch: Any,
                    lin_s: Any, region: Any, kicks: Any, kick_value: Any, pulses: Any,
                    pulse_value: Any, lw: Any, rng: Any, iopts: Any, fopts: Any, status: Any,
                    scr: Any) -> bool:
        return bool(self.generic.advance_one(
            k, x, u_app, op, p_sets, p_switch, lin_s, region, kicks, kick_value, pulses,
            pulse_value, lw, rng, iopts, fopts, status, scr,
        ))

    def rk4_steps(self, *, x: Any, u: Any, p: Any, h: float, n_steps: int) -> None:
        self.generic.rk4_steps(x, u, p, h, n_steps)


def _native_loaded() -> Any:
    from equilibrist.native.simcore import _CORES

    return _CORES


# The batch's thread count (set_workers): OpenMP threads of the C core's run_many.
_THREADS = [os.cpu_count() or 1]


def thread_count() -> int:
    """The thread count of parallel entries in force (:func:`set_workers`)."""
    return _THREADS[0]


def set_workers(workers: int | None) -> int:
    """Set the thread count of parallel entries (the C core's OpenMP threads, numba's for a
    nonlinear controller's core); returns the count in force."""
    available = os.cpu_count() or 1
    count = available if workers is None else max(1, min(int(workers), available))
    _THREADS[0] = count
    numba = sys.modules.get("numba")
    if numba is not None:
        numba.set_num_threads(min(count, numba.config.NUMBA_NUM_THREADS))
    return count


__all__ = ["Kernel", "controller_section", "kernel_path", "load_kernel", "set_workers"]
