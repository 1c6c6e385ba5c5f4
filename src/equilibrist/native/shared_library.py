"""The exported C controller, compiled and called from Python.

:func:`compile_library` writes the linear library that the export ships,
compiles it with the system C compiler into a temporary shared library
(``$CC``, else ``cc``) with the export's strict flags, and loads it with
:mod:`ctypes`. The :class:`CompiledController` it returns calls the
library's own ``init``/``step``, so what runs in equilibrist's simulation is
the code that runs on the robot.
"""

from __future__ import annotations

import ctypes
import os
import shlex
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from equilibrist.errors import ExportError
from equilibrist.native import linear_library
from equilibrist.native.c_text import check_precision
from equilibrist.native.linear_c import ControllerData

# The flags of the export's Makefile, plus position-independent code for a shared library.
STRICT_FLAGS = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")
# No fused multiply-add: the simulation core's arithmetic rounds every product.
BUILD_FLAGS = ("-O2", "-ffp-contract=off", "-fPIC", "-shared")

_SHIM = """\
#include <stddef.h>
#include "{name}.h"

size_t equilibrist_state_size(void)
{{
    return sizeof({name}_state);
}}
"""


def compiler() -> list[str]:
    """The C compiler command: ``$CC`` split as a shell would, else ``cc``.

    Raises
    ------
    ExportError
        When no such program is on the ``PATH``.
    """
    words = shlex.split(os.environ.get("CC", "") or "cc")
    if not words or shutil.which(words[0]) is None:
        raise ExportError(
            f"no C compiler found ({' '.join(words) or 'cc'}): install gcc or set CC"
        )
    return words


def build_shared_library(
    sources: Sequence[Path], out: Path, *, include: Path, extra_flags: Sequence[str] = ()
) -> Path:
    """Compile C *sources* into the shared library *out* with the strict flags.

    Raises
    ------
    ExportError
        The compiler's first lines of error output when it fails.
    """
    cmd = [*compiler(), *STRICT_FLAGS, *BUILD_FLAGS, *extra_flags, f"-I{include}",
           *(str(s) for s in sources), "-o", str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        detail = (proc.stderr or proc.stdout).strip().splitlines()
        raise ExportError(
            "the exported C code does not compile: " + " | ".join(detail[:6])
            + f" (command: {' '.join(cmd)})"
        )
    return out


class CompiledController:
    """The exported C controller loaded into this process.

    Every call goes to the compiled ``<name>_init``/``_init_at``/``_step``/
    ``_estimate``; inputs and outputs are numpy arrays in absolute units.
    Use it as a context manager, or call :meth:`close`, to unload it.

    Parameters
    ----------
    data:
        The controller the library was generated from.
    precision:
        ``"double"`` or ``"float"``: the library's arithmetic.
    library:
        Path of the compiled shared library.
    """

    def __init__(self, data: ControllerData, precision: str, library: Path) -> None:
        self.data = data
        self.precision = check_precision(precision)
        self._ctype = ctypes.c_double if precision == "double" else ctypes.c_float
        self._dtype = np.float64 if precision == "double" else np.float32
        self._lib: ctypes.CDLL | None = ctypes.CDLL(str(library))
        name = data.name
        real_p = ctypes.POINTER(self._ctype)
        self._init = getattr(self._lib, f"{name}_init")
        self._init.argtypes = [ctypes.c_void_p]
        self._init.restype = None
        self._init_at = getattr(self._lib, f"{name}_init_at")
        self._init_at.argtypes = [ctypes.c_void_p, real_p]
        self._init_at.restype = None
        self._step = getattr(self._lib, f"{name}_step")
        self._step.argtypes = [ctypes.c_void_p, real_p, real_p, real_p]
        self._step.restype = ctypes.c_int
        self._estimate = getattr(self._lib, f"{name}_estimate")
        self._estimate.argtypes = [ctypes.c_void_p, real_p]
        self._estimate.restype = None
        self._version = getattr(self._lib, f"{name}_version")
        self._version.argtypes = []
        self._version.restype = ctypes.c_char_p
        size = int(self._lib.equilibrist_state_size())
        # Doubles for the alignment of any member.
        self._state = (ctypes.c_double * (size // 8 + 1))()
        self._y = np.zeros(data.n_measured, dtype=self._dtype)
        self._r = np.zeros(max(data.n_references, 1), dtype=self._dtype)
        self._u = np.zeros(data.n_inputs, dtype=self._dtype)
        self._x = np.zeros(data.n_states, dtype=self._dtype)
        self.saturated = 0
        self.reset()

    def _ptr(self, arr: np.ndarray) -> object:
        return arr.ctypes.data_as(ctypes.POINTER(self._ctype))

    @property
    def version(self) -> str:
        """The library's version line (generator, design id and settings)."""
        line: bytes = self._version()  # ctypes.c_char_p: bytes
        return line.decode()

    def reset(self, x_estimate: object | None = None) -> None:
        """``init`` (at the operating point) or ``init_at`` (an absolute state estimate)."""
        if x_estimate is None:
            self._init(self._state)
            return
        x = np.asarray(x_estimate, dtype=self._dtype).reshape(-1)
        if x.size != self.data.n_states:
            raise ExportError(
                f"the initial estimate has {x.size} values, expected {self.data.n_states} "
                f"({', '.join(self.data.state_names)})"
            )
        self._x[:] = x
        self._init_at(self._state, self._ptr(self._x))

    def step(self, y: object, r: object | None = None) -> np.ndarray:
        """One sample: absolute measurements (and references) in, saturated input out."""
        self._y[:] = np.asarray(y, dtype=float).reshape(-1)
        ref = None
        if self.data.n_references and r is not None:
            self._r[:] = np.asarray(r, dtype=float).reshape(-1)
            ref = self._ptr(self._r)
        self.saturated = int(self._step(self._state, self._ptr(self._y), ref, self._ptr(self._u)))
        return self._u.astype(np.float64)

    def estimate(self) -> np.ndarray:
        """The state estimate used at the last step, absolute."""
        self._estimate(self._state, self._ptr(self._x))
        return self._x.astype(np.float64)

    def close(self) -> None:
        """Forget the library (the process may keep it mapped until exit)."""
        self._lib = None

    def __enter__(self) -> CompiledController:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def compile_library(data: ControllerData, *, precision: str, version: str) -> CompiledController:
    """Write, compile and load *data*'s C library in *precision*, *version* its generator.

    Raises
    ------
    ExportError
        No C compiler, or code that does not compile.
    """
    check_precision(precision)
    with tempfile.TemporaryDirectory(prefix="equilibrist-c-") as tmp:
        folder = Path(tmp)
        (folder / f"{data.name}.h").write_text(
            linear_library.header(data, precision=precision, version=version))
        (folder / f"{data.name}.c").write_text(
            linear_library.source(data, precision=precision, version=version))
        (folder / "equilibrist_shim.c").write_text(_SHIM.format(name=data.name))
        library = build_shared_library(
            [folder / f"{data.name}.c", folder / "equilibrist_shim.c"],
            folder / f"lib{data.name}.so",
            include=folder,
        )
        # Loaded before the folder goes: the mapping outlives the file.
        return CompiledController(data, precision, library)
