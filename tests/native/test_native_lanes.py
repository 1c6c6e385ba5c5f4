"""The lanes' C (native/lanes.py): a translated dynamics widened to eight copies at once, and the
lanes' sine and cosine, compiled and run against the scalar code they widen.

Independent truths: the scalar translation of the same function compiled beside it (each lane
must give its bits), the function run as plain Python with libm's Python ``sin``/``cos``, and,
for the lanes' sine and cosine, libm's scalar eq_sin/eq_cos over every range (first range,
reduced, tiny, signed zeros, near multiples of pi/2, huge, NaN), compiled apart.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from equilibrist.native import lanes, pyc
from equilibrist.numeric import libm


def _avx512() -> bool:
    flags = next((line for line in Path("/proc/cpuinfo").read_text().splitlines()
                  if line.startswith("flags")), "")
    return all(f in flags.split() for f in ("avx512f", "avx512dq", "avx512vl", "avx512bw"))


def _gcc() -> str:
    gcc = shutil.which("gcc")
    if gcc is None:
        pytest.fail("gcc is needed (CI installs it)")
    return gcc


def _target() -> str:
    """Compiled for AVX-512 where the CPU has it (as the lanes run), else for the machine's
    baseline (GCC's vector operations lane by lane: the same arithmetic)."""
    return lanes._PUSH_POP if _avx512() else "#define EQ_LANES_PUSH\n#define EQ_LANES_POP\n"


def _run_c(tmp_path: Path, text: str, *stdin_arrays: np.ndarray) -> subprocess.CompletedProcess:
    (tmp_path / "t.c").write_text("#include <math.h>\n#include <stdint.h>\n#include <stdio.h>\n"
                                  "#include <string.h>\n" + text)
    subprocess.run([_gcc(), "-std=gnu99", "-O2", "-ffp-contract=off", "-fno-math-errno", "t.c",
                    "-o", "t", "-lm"], cwd=tmp_path, check=True, capture_output=True)
    data = b"".join(np.ascontiguousarray(a, dtype=np.float64).tobytes() for a in stdin_arrays)
    return subprocess.run([str(tmp_path / "t")], input=data, capture_output=True, check=True)


def test_a_dynamics_with_a_branch_is_not_widened() -> None:
    source = ("def f(x, u, p, out):\n    if x[0] > 0.0:\n        out[0] = x[1]\n"
              "    else:\n        out[0] = -x[1]\n")
    module = pyc.Module(source, prefix="t_")
    assert lanes.widen(module.function("f", ("F1", "F1", "F1", "F1"))) is None


#: A dynamics of two states: a sine and a cosine of one variable (shared: one eqv_sincos), of
#: a sum, and of an array element, with the input and parameters in the arithmetic.
DYNAMICS = """
def f(x, u, p, out):
    a = x[0]
    b = a * p[0] + u[0]
    out[0] = eq_sin(a) + 2.0 * eq_cos(a) * p[1]
    out[1] = eq_sin(b) - 0.5 * eq_cos(x[1]) * p[1] / (1.0 + a * a)
"""

WIDE_HARNESS = r"""
int main(void)
{
    static double in[%(K)d][%(L)d][5], scalar[%(K)d][%(L)d][2];
    long bad = 0;
    int k, l;
    if (fread(in, sizeof in, 1, stdin) != 1) return 2;
    for (k = 0; k < %(K)d; k++) {
        eqv x[2], u[1], p[2], out[2];
        for (l = 0; l < EQ_LANES; l++) {
            x[0][l] = in[k][l][0]; x[1][l] = in[k][l][1]; u[0][l] = in[k][l][2];
            p[0][l] = in[k][l][3]; p[1][l] = in[k][l][4];
        }
        t_f_lanes(x, 2, u, 1, p, 2, out, 2);
        for (l = 0; l < EQ_LANES; l++) {
            double xs[2] = {in[k][l][0], in[k][l][1]}, us[1] = {in[k][l][2]};
            double ps[2] = {in[k][l][3], in[k][l][4]};
            double a = out[0][l], b = out[1][l];
            t_f(xs, 2, us, 1, ps, 2, scalar[k][l], 2);
            bad += memcmp(&a, &scalar[k][l][0], 8) != 0 || memcmp(&b, &scalar[k][l][1], 8) != 0;
        }
    }
    fwrite(scalar, sizeof scalar, 1, stdout);
    fprintf(stderr, "%%ld\n", bad);
    return 0;
}
"""


def test_a_widened_dynamics_gives_each_lane_the_scalar_bits(tmp_path: Path) -> None:
    """The widened f, run on eight copies at once, gives each copy the bits of the scalar f
    (compiled beside it), which are those of the same source run as Python with libm's
    sin and cos: in the first range (|x| < pi/4, the lanes' fast path), after the reduction,
    and lane by lane (a lane beyond 1e6)."""
    module = pyc.Module(DYNAMICS, prefix="t_")
    scalar = module.function("f", ("F1", "F1", "F1", "F1"))
    wide = lanes.widen(scalar)
    assert wide is not None
    # One shared sine and cosine for a, none computed twice (what the widening saves).
    assert wide.count("eqv_sincos(v_a,") == 1 and "eqv_sin(v_a)" not in wide
    n_blocks, n_lanes = 60, lanes.LANES
    rng = np.random.default_rng(8)
    inputs = rng.uniform(-1.0, 1.0, (n_blocks, n_lanes, 5))
    inputs[:, :, 3:] = rng.uniform(0.5, 2.0, (n_blocks, n_lanes, 2))
    inputs[:20, :, :3] *= 0.7   # every lane in the first range
    inputs[20:40, :, :3] *= 9.0  # reduced
    inputs[40:, 3, 0] = 3.0e6    # one lane too large: all eight lane by lane
    text = (libm.c_source() + pyc.PRELUDE + scalar.source + "\n" + _target() + lanes.PRELUDE
            + wide + "\n" + WIDE_HARNESS % {"K": n_blocks, "L": n_lanes} + "EQ_LANES_POP\n")
    done = _run_c(tmp_path, text, inputs)
    assert done.stderr.decode().strip() == "0"  # every lane, the scalar bits
    got = np.frombuffer(done.stdout, dtype=np.float64).reshape(n_blocks, n_lanes, 2)
    namespace: dict[str, object] = {"eq_sin": libm.sin, "eq_cos": libm.cos}
    exec(compile(DYNAMICS, "dynamics", "exec"), namespace)  # the same source, as Python
    want = np.empty_like(got)
    for k in range(n_blocks):
        for lane in range(n_lanes):
            row = inputs[k, lane]
            namespace["f"](row[:2], row[2:3], row[3:], want[k, lane])  # type: ignore[operator]
    assert got.tobytes() == want.tobytes()
    # ... and that is the function written out with the C library's sine and cosine.
    a, b = inputs[..., 0], inputs[..., 0] * inputs[..., 3] + inputs[..., 2]
    assert np.allclose(got[..., 0], np.sin(a) + 2.0 * np.cos(a) * inputs[..., 4], rtol=1e-13, atol=1e-13)
    assert np.allclose(got[..., 1], np.sin(b) - 0.5 * np.cos(inputs[..., 1]) * inputs[..., 4]
                       / (1.0 + a * a), rtol=1e-13, atol=1e-13)


SINCOS_HARNESS = r"""
static uint64_t st = 88172645463325252ull;
static double rnd(void) { st ^= st << 13; st ^= st >> 7; st ^= st << 17;
                          return (double)(st >> 11) * (1.0 / 9007199254740992.0); }
int main(void) {
    long bad = 0; int k, l;
    const double scales[] = {1e-9, 1e-7, 0.5, 0.8, 2.0, 10.0, 1e3, 1e5, 1e7, 1e300};
    for (k = 0; k < 400000; k++) {
        eqv x, s, c;
        for (l = 0; l < EQ_LANES; l++) x[l] = (2 * rnd() - 1) * scales[(k + l) % 10];
        if (k % 100 == 0) x[k % EQ_LANES] = 1.5707963267948966 * (k % 7);
        if (k % 99 == 0) x[k % EQ_LANES] = -0.0;
        if (k % 97 == 0) x[k % EQ_LANES] = NAN;
        if (k % 3 == 0) for (l = 0; l < EQ_LANES; l++) x[l] = (2 * rnd() - 1) * 0.78;
        eqv_sincos(x, &s, &c);
        for (l = 0; l < EQ_LANES; l++) {
            double a = eq_sin(x[l]), b = eq_cos(x[l]);
            bad += memcmp(&a, &s[l], 8) != 0 || memcmp(&b, &c[l], 8) != 0;
        }
    }
    printf("%ld\n", bad);
    return 0;
}
"""


def test_the_lanes_sine_and_cosine_are_libms_to_the_bit(tmp_path: Path) -> None:
    text = libm.c_source() + _target() + lanes.PRELUDE + SINCOS_HARNESS
    assert _run_c(tmp_path, text).stdout.decode().strip() == "0"
