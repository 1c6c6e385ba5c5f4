"""The exported MPC on this machine: its memory footprint measured with the C compiler and
``size``, and the library compiled and called through ctypes (:class:`CompiledMPC`); split
from :mod:`equilibrist.export.mpc_c`, which re-exports them.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.errors import ExportError
from equilibrist.export._mpc_c_library import _daqp_c_files, library_files

if TYPE_CHECKING:
    from equilibrist.control.mpc import MPC


#: A program that sets the exported MPC up once, counting what it allocates.
_HEAP_PROGRAM = """#include <stdio.h>
#include <stdlib.h>
#include "{name}.h"
static size_t total = 0;
void *__real_malloc(size_t n);
void *__real_calloc(size_t k, size_t n);
void *__wrap_malloc(size_t n) {{ total += n; return __real_malloc(n); }}
void *__wrap_calloc(size_t k, size_t n) {{ total += k * n; return __real_calloc(k, n); }}
int main(void) {{
    double x[{n}] = {{0.0}}, u[{m}];
    if ({name}_setup() != 0) return 1;
    {name}_step(x, u);
    printf("%lu\\n", (unsigned long)total);
    return 0;
}}
"""


def footprint(folder: str | Path, *, name: str = "mpc", n: int = 4, m: int = 1,
              precision: str = "double") -> dict[str, int]:
    """Bytes of the library alone (DAQP's sources and the driver; without the test and its
    vectors): code (``text``), initialized and zeroed static data (``data``, ``bss``), measured
    with the C compiler and ``size`` on the object files, and ``heap``: what
    ``<name>_setup`` allocates (DAQP's workspace), counted by a program linked with
    ``malloc`` and ``calloc`` wrapped (none since DAQP's workspace is static). *n*, *m*: the
    controller's states and inputs; *precision* the library's (``"float"``: DAQP in single
    precision). ``make size`` (:mod:`equilibrist.export._size`) prints the same code and data
    and the stack."""
    import subprocess
    import tempfile

    from equilibrist.export.native import compiler

    src = Path(folder)
    files = [*_daqp_c_files(src), src / f"{name}.c"]
    inc = [f"-I{src / 'daqp' / 'include'}", f"-I{src}"]
    total = {"text": 0, "data": 0, "bss": 0}
    flags = ["-O2", "-std=c99", "-ffp-contract=off",
             *(["-DDAQP_SINGLE_PRECISION"] if precision == "float" else [])]
    with tempfile.TemporaryDirectory() as tmp:
        for i, f in enumerate(files):
            obj = Path(tmp) / f"{i}.o"
            subprocess.run([*compiler(), *flags, *inc, "-c", str(f),
                            "-o", str(obj)],
                           check=True, capture_output=True)
            out = subprocess.run(["size", str(obj)], check=True, capture_output=True, text=True)
            text, data, bss = (int(v) for v in out.stdout.splitlines()[1].split()[:3])
            total["text"] += text
            total["data"] += data
            total["bss"] += bss
        prog = Path(tmp) / "heap.c"
        prog.write_text(_HEAP_PROGRAM.format(name=name, n=n, m=m))
        exe = Path(tmp) / "heap"
        subprocess.run([*compiler(), *flags, *inc, str(prog),
                        *map(str, files),
                        "-Wl,--wrap=malloc,--wrap=calloc", "-o", str(exe), "-lm"],
                       check=True, capture_output=True)
        run = subprocess.run([str(exe)], check=True, capture_output=True, text=True)
        total["heap"] = int(run.stdout.strip())
    return total


class CompiledMPC:
    """The exported C MPC compiled into a shared library and called through ctypes.

    A :class:`~equilibrist.control.controller.PythonController` (``reset``,
    ``output``, ``update``) on the controller's measured outputs, so the
    code that runs on the robot closes the loop in the simulation. Each
    instance compiles its own copy (the driver's workspace is static data).
    """

    def __init__(self, ctrl: MPC, *, name: str = "mpc") -> None:
        import ctypes
        import subprocess
        import tempfile

        from equilibrist.export.native import compiler

        self.ctrl = ctrl
        self.rate: float | None = ctrl.rate
        self.outputs: tuple[str, ...] | None = ctrl.output_names
        self.estimate: np.ndarray | None = None
        self._kalman = ctrl.estimator == "kalman"
        self._dir = tempfile.TemporaryDirectory(prefix="equilibrist-mpc-")
        folder = Path(self._dir.name)
        for rel, text in library_files(ctrl, name=name).items():
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            (folder / rel).write_text(text)
        sources = [*_daqp_c_files(folder), folder / f"{name}.c"]
        lib = folder / f"lib{name}.so"
        inc = [f"-I{folder / 'daqp' / 'include'}", f"-I{folder}"]
        proc = subprocess.run([*compiler(), "-O2", "-std=c99", "-ffp-contract=off", "-fPIC",
                               "-shared", *inc, *map(str, sources), "-o", str(lib), "-lm"],
                              capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            raise ExportError("the exported MPC does not compile: "
                              + " | ".join((proc.stderr or proc.stdout).strip().splitlines()[:6]))
        self._lib: Any = ctypes.CDLL(str(lib))
        dp = ctypes.POINTER(ctypes.c_double)
        self._setup = self._lib[f"{name}_setup"]
        self._setup.argtypes, self._setup.restype = [], ctypes.c_int
        self._step = self._lib[f"{name}_step"]
        self._step.argtypes, self._step.restype = [dp, dp], ctypes.c_int
        if self._kalman:
            for fn, count, res in (("init", 1, None), ("output", 3, ctypes.c_int),
                                   ("update", 3, None), ("estimate", 3, None)):
                f = self._lib[f"{name}_{fn}"]
                f.argtypes, f.restype = [dp] * count, res
                setattr(self, f"_{fn}", f)
        self._z = np.zeros(ctrl.problem.n)
        self.reset()

    def _call(self, fn: str, *args: np.ndarray) -> Any:
        return getattr(self, f"_{fn}")(*(self._ptr(a) for a in args))

    @staticmethod
    def _ptr(a: np.ndarray) -> Any:
        import ctypes

        return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))

    @property
    def z(self) -> np.ndarray:
        """The C filter's state (a copy)."""
        return self._z.copy()

    def reset(self) -> None:
        flag = int(self._setup())
        if flag != 0:
            raise ExportError(f"the exported MPC's DAQP setup failed (flag {flag})")
        if self._kalman:
            self._call("init", self._z)
        self.estimate = None

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        yv = np.ascontiguousarray(y, dtype=np.float64)
        u = np.zeros(self.ctrl.problem.m)
        if self._kalman:
            x = np.zeros(self.ctrl.problem.n)
            self._call("estimate", self._z, yv, x)
            self._call("output", self._z, yv, u)
            self.estimate = x
        else:
            self._step(self._ptr(yv), self._ptr(u))
            self.estimate = yv.copy()
        return u

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        if self._kalman:
            yv = np.ascontiguousarray(y, dtype=np.float64)
            ua = np.ascontiguousarray(u_applied, dtype=np.float64)
            self._call("update", self._z, yv, ua)

    def close(self) -> None:
        self._dir.cleanup()
