"""The exported MPC's memory footprint, measured with the C compiler and ``size``. (The
library compiled and called through ctypes is the simulated MPC itself:
:class:`~equilibrist.control.mpc_runtime.MPCRuntime`.)
"""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

from equilibrist.native.mpc_library import _daqp_c_files
from equilibrist.native.shared_library import compiler

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
    precision). ``make size`` (:mod:`equilibrist.native.size`) prints the same code and data
    and the stack."""
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
