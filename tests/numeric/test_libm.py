"""The project's atan and tanh: Python and C give the same bits, both close to the exact value.

glibc picks ``atan`` by the CPU's features (and another C library's ``tanh`` may round
differently), so the derived models' smooth Coulomb friction calls the project's own
(:mod:`equilibrist.numeric.libm`, fdlibm's ``s_atan.c``, ``s_tanh.c`` and ``s_expm1.c``). The
Python form and its C transcription are compared bit for bit, compiled by the system's C
compiler with the core's flags; both are compared with mpmath's value at 120 bits.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import mpmath
import numpy as np
import pytest

from equilibrist.numeric import cache, libm
from equilibrist.systems import registry


def _arguments() -> np.ndarray:
    """Every branch of both functions: each of atan's reduction intervals and its edges, tanh's
    and expm1's, tiny, subnormal, huge, infinite, NaN and signed zeros."""
    rng = np.random.default_rng(20261207)
    edges = [0.0, 2.0**-1074, 2.0**-1022, 2.0**-55, 2.0**-54, 2.0**-27, 0.4375, 0.6875, 1.0,
             1.1875, 2.4375, 0.34657359, 1.0397205, 22.0, 2.0**66, 1.7976931348623157e308]
    near = [math.nextafter(e, d) for e in edges for d in (0.0, math.inf)]
    values = np.concatenate([
        rng.uniform(-3.0, 3.0, 20000),
        rng.uniform(-30.0, 30.0, 5000),
        np.exp2(rng.uniform(-1074.0, 1023.0, 5000)),
        np.array(edges + near + [math.inf, math.nan]),
    ])
    return np.concatenate([values, -values])


def _c_values(xs: np.ndarray, tmp: Path) -> np.ndarray:
    cc = shutil.which("cc")
    assert cc is not None, "a C compiler (cc) is needed"
    (tmp / "m.c").write_text(
        "#include <math.h>\n#include <stdio.h>\n" + libm.c_source(atan=True, tanh=True) + """
int main(void)
{
    double x, y[2];
    while (fread(&x, sizeof x, 1, stdin) == 1) {
        y[0] = eq_atan(x);
        y[1] = eq_tanh(x);
        fwrite(y, sizeof y[0], 2, stdout);
    }
    return 0;
}
""")
    # The core's flags (equilibrist.native.build): no contraction, no -ffast-math.
    subprocess.run([cc, "-std=c99", "-O2", "-ffp-contract=off", "-Wall", "-Wno-unused-function",
                    "-Werror", str(tmp / "m.c"), "-o", str(tmp / "m"), "-lm"], check=True)
    out = subprocess.run([str(tmp / "m")], input=xs.tobytes(), capture_output=True, check=True)
    return np.frombuffer(out.stdout, dtype=float).reshape(-1, 2)


def test_python_and_c_give_the_same_bits(tmp_path: Path) -> None:
    xs = _arguments()
    c = _c_values(xs, tmp_path)
    python = np.array([[libm.eq_atan(float(x)), libm.eq_tanh(float(x))] for x in xs])
    assert python.tobytes() == c.tobytes()


def test_the_special_values() -> None:
    for fn in (libm.eq_atan, libm.eq_tanh):
        assert math.copysign(1.0, fn(0.0)) == 1.0 and math.copysign(1.0, fn(-0.0)) == -1.0
        assert math.isnan(fn(math.nan))
        assert fn(5e-324) == 5e-324 and fn(-5e-324) == -5e-324
    assert libm.eq_atan(math.inf) == -libm.eq_atan(-math.inf) == math.pi / 2
    assert libm.eq_atan(1e300) == math.pi / 2  # pi/2 rounded: atan's limit
    assert libm.eq_tanh(math.inf) == -libm.eq_tanh(-math.inf) == libm.eq_tanh(30.0) == 1.0


def _ulps(got: float, exact: mpmath.mpf) -> float:
    if math.isinf(got) or math.isnan(got):
        return math.inf
    nearest = float(exact)
    return float(abs(mpmath.mpf(got) - exact) / mpmath.mpf(math.ulp(nearest)))


@pytest.mark.parametrize(("name", "bound"), [("atan", 1.0), ("tanh", 2.5)])
def test_within_a_few_ulps_of_mpmath(name: str, bound: float) -> None:
    """atan within 1 ulp of the exact value (fdlibm's bound), tanh within fdlibm's 2.5."""
    fn = getattr(libm, f"eq_{name}")
    exact = getattr(mpmath, name)
    rng = np.random.default_rng(7)
    xs = np.concatenate([rng.uniform(-3.0, 3.0, 2500), np.exp2(rng.uniform(-60.0, 70.0, 1500)),
                         [0.4375, 0.6875, 1.1875, 2.4375, 0.34657359, 1.0397205, 21.9]])
    with mpmath.workprec(120):
        worst = max(_ulps(fn(float(x)), exact(mpmath.mpf(float(x)))) for x in np.concatenate([xs, -xs]))
    assert worst <= bound, worst


def test_the_shipped_models_call_no_rounded_c_library_function() -> None:
    """Every shipped model's math is the project's: of ``math``, only exact functions (frexp,
    ldexp, isnan); its atan and tanh the project's; a model with friction calls ``eq_atan``."""
    uses_atan = []
    for entry in registry.all_entries():
        path = cache.packaged_path(entry)
        assert path is not None and path.is_file(), path
        text = path.read_text()
        called = set(re.findall(r"\bmath\.(\w+)\(", text))
        assert called <= {"frexp", "ldexp", "isnan"}, (path.name, called)
        if "eq_atan(" in text:
            assert "def eq_atan(" in text
            uses_atan.append(entry.spec.key)
    assert any(key.startswith("dfki_double_pendulum") for key in uses_atan), uses_atan


def test_a_model_with_friction_is_the_same_bits_in_python_and_compiled() -> None:
    """The DFKI pendulum's ``f`` (``cf atan(100 q_dot)`` at each joint) at rates that take
    atan through each of its branches, in the shipped Python and in the compiled core."""
    from equilibrist.numeric.lookup import system_from_key
    from equilibrist.sim.simcore import load_core

    key = "dfki_double_pendulum[robot=acrobot]"
    entry = next(e for e in registry.all_entries() if e.spec.key == key)
    path = cache.packaged_path(entry)
    assert path is not None
    namespace: dict[str, object] = {"__name__": "shipped_dfki"}
    exec(compile(path.read_text(), str(path), "exec"), namespace)  # the package's own file
    f = namespace["f"]
    system = system_from_key(key)
    core = load_core(system)
    rng = np.random.default_rng(11)
    p = np.array(system.p, dtype=float)
    mine, theirs = np.empty(4), np.empty(4)
    differ = 0
    for _ in range(1000):
        rates = rng.choice((-1.0, 1.0), 2) * np.exp2(rng.uniform(-40.0, 4.0, 2))  # 100 v: 1e-10..1600
        x = np.concatenate([rng.uniform(-3.0, 3.0, 2), rates])
        u = rng.uniform(-2.0, 2.0, 1)
        f(x, u, p, mine)  # type: ignore[operator]
        core.f(x, u, p, theirs)
        differ += mine.tobytes() != theirs.tobytes()
    assert differ == 0


#: Arguments at which glibc 2.36's atan and tanh round differently with FMA and AVX2 than on its
#: SSE2 paths (found by comparing four million arguments in [-5, 5] and 2**[-20, 20] under the
#: two settings: 1,541 of them for atan, 853 for tanh).
GLIBC_DIFFERS = {"atan": ["0x1.4a3d2c25a20d4p-4", "0x1.0830fd9b8c6d4p-4", "0x1.68058a5cf5d33p-4"],
                 "tanh": ["-0x1.2e546d1e41e60p-3", "0x1.17287f89bf380p-4", "-0x1.391726227cf00p-3"]}
#: glibc's SSE2 paths on the same machine (as tests/sim/test_bits_cpu.py sets them).
TUNED_DOWN = "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX512F,-AVX512VL,-AVX512DQ,-AVX512BW"

_PROBE = """
import json, math, sys
import numpy as np
from equilibrist.numeric import libm
from equilibrist.numeric.lookup import get_system
from equilibrist.sim.simcore import load_core
args = json.loads(sys.argv[1])
out = {name: [[getattr(math, name)(float.fromhex(h)).hex(),
               getattr(libm, "eq_" + name)(float.fromhex(h)).hex()] for h in hs]
       for name, hs in args.items()}
system = get_system("dfki_double_pendulum")
core = load_core(system)
rows = []
for h in args["atan"]:  # atan(100 v) at those arguments, at both joints
    x = np.array([0.3, -0.2, float.fromhex(h) / 100.0, -float.fromhex(h) / 100.0])
    a, b = np.empty(4), np.empty(4)
    system.functions.f(x, np.array([0.5]), system.p, a)
    core.f(x, np.array([0.5]), system.p, b)
    rows.append([v.hex() for v in (*a, *b)])
out["f"] = rows
print(json.dumps(out))
"""


def test_the_other_cpu_setting_changes_glibc_and_not_the_model() -> None:
    """Under glibc's SSE2 paths, its atan and tanh change at the arguments above (on a CPU with
    FMA, whose paths they are); the project's, and the friction model's f in Python and
    compiled, give the same bits under both settings."""

    def run(tunables: str | None) -> dict[str, list[list[str]]]:
        env = {k: v for k, v in os.environ.items() if k != "GLIBC_TUNABLES"}
        if tunables is not None:
            env["GLIBC_TUNABLES"] = tunables
        proc = subprocess.run([sys.executable, "-c", _PROBE, json.dumps(GLIBC_DIFFERS)], env=env,
                              capture_output=True, text=True, check=False)
        assert proc.returncode == 0, proc.stderr[-3000:]
        result: dict[str, list[list[str]]] = json.loads(proc.stdout)
        return result

    here, there = run(None), run(TUNED_DOWN)
    for name in GLIBC_DIFFERS:
        assert [ours for _, ours in here[name]] == [ours for _, ours in there[name]]
        for (glibc_here, ours), (glibc_there, _) in zip(here[name], there[name], strict=True):
            assert ours in (glibc_here, glibc_there)  # both within an ulp: one of the two
    assert here["f"] == there["f"]
    assert all(row[:4] == row[4:] for row in here["f"])  # Python and compiled
    flags = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    if re.search(r"\bfma\b", flags) and re.search(r"\bavx2\b", flags):
        differ = sum(a[0] != b[0] for n in GLIBC_DIFFERS for a, b in zip(here[n], there[n], strict=True))
        assert differ > 0, "the tunable changed nothing: glibc's dispatch was not exercised"
