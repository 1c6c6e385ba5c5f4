"""Python -> C (native/pyc.py) checked by what the C computes: a function using the
translation's rules (loops, branches, a callee, floor division and modulo of floats and
integers with Python's signs, integer powers, min/max, int(), abs, 2-D arrays and their shape,
math functions and the project's eq_ functions) is translated, compiled as the core compiles
(``-O2 -ffp-contract=off``) and run on random inputs: every output must be the bits of the same
source run as Python (numpy arrays, libm's Python eq_ functions), the reference the module's
docstring promises.
"""

from __future__ import annotations

import ctypes
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest

from equilibrist.native import pyc
from equilibrist.numeric import libm
from support import require

SOURCE = """
def helper(a, k):
    return a * k - 1.0


def f(x, m, out):
    n = x.shape[0]
    acc = 0.0
    for i in range(n):
        if x[i] > 0.0:
            acc += x[i] * x[i] * x[i]
        else:
            acc -= helper(x[i], 2.0)
    out[0] = acc
    out[1] = x[0] // x[1]
    out[2] = x[0] % x[1]
    k = int(x[2] * 10.0)
    out[3] = k // 3 + (k % 3) * 100 + (-k) // 4 + (-k) % 4
    out[4] = max(x[3], x[4]) - 2.0 * min(x[3], x[4])
    out[5] = abs(x[5]) + math.sqrt(abs(x[6])) + math.floor(x[0])
    out[6] = eq_sin(x[0]) * eq_cos(x[1]) + eq_exp(x[2] * 0.1) + eq_log(abs(x[3]) + 1.0)
    out[7] = m[0, 1] * m[1, 0] - m[1, 1] * m.shape[1] + x[1] * x[1] / (1.0 + x[2] * x[2])
    out[8] = x[2] ** 5
    out[9] = x[1] ** 2
"""

WRAPPER = """
void run(double *x, int64_t nx, double *m, int64_t m0, int64_t m1, double *out, int64_t n_out)
{
    t_f(x, nx, m, m0, m1, out, n_out);
}
"""

N_OUT = 10


@pytest.fixture(scope="module")
def compiled(tmp_path_factory: pytest.TempPathFactory) -> ctypes.CDLL:
    cc = require("cc", "gcc")
    module = pyc.Module(SOURCE, prefix="t_")
    module.function("f", ("F1", "F2", "F1"))
    folder = tmp_path_factory.mktemp("pyc")
    src = folder / "unit.c"
    src.write_text("#include <math.h>\n#include <stdint.h>\n"
                   + libm.c_source(log=True, exp=True) + pyc.PRELUDE + module.c_source() + WRAPPER)
    lib = folder / "unit.so"
    done = subprocess.run([cc, "-std=c99", "-O2", "-ffp-contract=off", "-fPIC", "-shared",
                           "-Wno-unused-function", str(src), "-o", str(lib), "-lm"],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    return ctypes.CDLL(str(lib))


def _python(x: np.ndarray, m: np.ndarray) -> np.ndarray:
    namespace: dict[str, object] = {"math": math, "eq_sin": libm.sin, "eq_cos": libm.cos,
                                    "eq_log": libm.log, "eq_exp": libm.eq_exp}
    exec(compile(SOURCE, "source", "exec"), namespace)
    out = np.full(N_OUT, np.nan)
    namespace["f"](x, m, out)  # type: ignore[operator]
    return out


def _c(lib: ctypes.CDLL, x: np.ndarray, m: np.ndarray) -> np.ndarray:
    out = np.full(N_OUT, np.nan)
    ptr = ctypes.POINTER(ctypes.c_double)
    x, m = np.ascontiguousarray(x), np.ascontiguousarray(m)
    lib.run(x.ctypes.data_as(ptr), ctypes.c_int64(x.size), m.ctypes.data_as(ptr),
            ctypes.c_int64(m.shape[0]), ctypes.c_int64(m.shape[1]), out.ctypes.data_as(ptr),
            ctypes.c_int64(N_OUT))
    return out


def test_the_translation_computes_the_python_bits(compiled: ctypes.CDLL) -> None:
    rng = np.random.default_rng(31)
    signs = set()
    for k in range(400):
        scale = (0.5, 3.0, 40.0, 1e4)[k % 4]
        x = rng.uniform(-scale, scale, 7)
        if k % 5 == 0:
            x[1] = -x[1]
        if k % 7 == 0:
            x[4] = x[3]  # a tie of min and max
        m = rng.standard_normal((2, 3))
        want, got = _python(x, m), _c(compiled, x, m)
        # An integer power is the documented repeated squaring, by hand: x ** 5 is
        # x * (x x)(x x), x ** 2 is x x. (CPython's ** calls the C library's pow, which
        # this glibc rounds otherwise now and then: within an ulp or so, not to the bit.)
        assert got[8] == x[2] * ((x[2] * x[2]) * (x[2] * x[2])), (k, x[2])
        assert got[9] == x[1] * x[1], (k, x[1])
        np.testing.assert_allclose(got[8:], want[8:], rtol=1e-15, atol=0)
        assert got[:8].tobytes() == want[:8].tobytes(), (k, x, got, want)
        signs.add((np.sign(x[0]), np.sign(x[1])))
    assert len(signs) == 4  # floor division and modulo in every sign combination


def test_the_python_reference_is_the_arithmetic_it_states(compiled: ctypes.CDLL) -> None:
    """The reference itself, at a hand-computed point (so the bit comparison above compares
    with numbers that mean something): x = (-7.5, 2, 0.55, ...)."""
    x = np.array([-7.5, 2.0, 0.55, -1.0, 3.0, -0.25, 16.0])
    m = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]])
    out = _c(compiled, x, m)
    # acc: positives cubed (8 + 0.55**3 + 27 + 16**3), minus (2 v - 1) of the others.
    acc = 8.0 + 0.55**3 + 27.0 + 4096.0 - ((-15.0 - 1.0) + (-2.0 - 1.0) + (-0.5 - 1.0))
    assert out[0] == pytest.approx(acc, rel=1e-15)
    assert (out[1], out[2]) == (-4.0, 0.5)  # Python's floor division and modulo, not C's
    # k = int(5.5) = 5: 5 // 3 + 2 * 100 + (-5) // 4 + (-5) % 4 = 1 + 200 - 2 + 3
    assert out[3] == 202.0
    assert out[4] == 3.0 + 2.0
    assert out[5] == 0.25 + 4.0 - 8.0
    assert out[6] == pytest.approx(math.sin(-7.5) * math.cos(2.0) + math.exp(0.055) + math.log(2.0),
                                   rel=1e-15)
    assert out[7] == pytest.approx(2.0 * 4.0 - 5.0 * 3.0 + 4.0 / (1.0 + 0.55 * 0.55), rel=1e-15)
    assert out[8] == pytest.approx(0.55**5, rel=1e-15) and out[9] == 4.0


def test_an_unknown_construct_is_refused_with_its_line() -> None:
    module = pyc.Module("def f(x, out):\n    out[0] = x[0]\n    out[1] = sorted(x)[0]\n")
    with pytest.raises(pyc.TranslationError, match="line 3"):
        module.function("f", ("F1", "F1"))


def test_unit_is_self_contained(tmp_path: Path) -> None:
    """The translated unit needs nothing from the C library but <math.h>'s functions."""
    module = pyc.Module(SOURCE, prefix="t_")
    module.function("f", ("F1", "F2", "F1"))
    src = tmp_path / "u.c"
    src.write_text("#include <math.h>\n#include <stdint.h>\n" + libm.c_source(log=True, exp=True)
                   + pyc.PRELUDE + module.c_source() + WRAPPER)
    subprocess.run([require("cc", "gcc"), "-std=c99", "-O2", "-fno-builtin", "-c", str(src), "-o",
                    str(tmp_path / "u.o")], check=True, capture_output=True)
    nm = subprocess.run(["nm", "-u", str(tmp_path / "u.o")], capture_output=True, text=True,
                        check=True).stdout.split()
    undefined = {s for s in nm if s != "U"}
    assert undefined <= {"copysign", "fabs", "floor", "fmod", "sqrt", "frexp", "ldexp", "pow"}, undefined
    assert not undefined & {"sin", "cos", "exp", "log"}
