"""The same bits on aarch64: the core's numerics and the exported controllers, compiled by
Debian's cross compiler (``aarch64-linux-gnu-gcc``) and run under ``qemu-aarch64``, give the
x86-64 results to the bit (docs/reproducibility.md). CI installs both (.ci/run).

What runs on the other architecture: the project's sin, cos, log, exp, atan and tanh; the system's
generated dynamics integrated by the core's RK4 with a held input; the core's normal
deviates (xoshiro256** and the polar method); an exported LQG controller and an exported
swing-up (its trigonometry the project's own) replaying their recorded test vectors.
"""

from __future__ import annotations

import re
import subprocess
import textwrap
from pathlib import Path

import numpy as np
import pytest
from tests.support import require

from equilibrist.numeric import libm

CROSS_FLAGS = ["-std=c99", "-O2", "-ffp-contract=off", "-static"]


def _tools() -> tuple[str, str]:
    return require("aarch64-linux-gnu-gcc"), require("qemu-aarch64")


def _build(tmp: Path, sources: list[Path], name: str, *extra: str) -> Path:
    cc, _ = _tools()
    exe = tmp / name
    proc = subprocess.run([cc, *CROSS_FLAGS, *extra, *map(str, sources), "-o", str(exe), "-lm"],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return exe


def _run(exe: Path, cwd: Path) -> subprocess.CompletedProcess[str]:
    _, qemu = _tools()
    return subprocess.run([qemu, str(exe)], cwd=cwd, capture_output=True, text=True,
                          timeout=600, check=False)


def test_the_projects_math_functions_give_the_python_bits(tmp_path: Path) -> None:
    xs = np.random.default_rng(20261202).uniform(-50.0, 50.0, 4000)
    xs = np.concatenate([xs, np.arange(-40, 40) * (np.pi / 2), [0.0, -0.0, 1e-300, 7.5e5]])
    (tmp_path / "in.bin").write_bytes(xs.tobytes())
    (tmp_path / "m.c").write_text("#include <math.h>\n#include <stdio.h>\n"
                                  + libm.c_source(log=True, exp=True, atan=True, tanh=True)
                                  + textwrap.dedent("""
        int main(void)
        {
            double x, y[6];
            FILE *in = fopen("in.bin", "rb"), *out = fopen("out.bin", "wb");
            while (fread(&x, sizeof x, 1, in) == 1) {
                y[0] = eq_sin(x); y[1] = eq_cos(x); y[2] = eq_log(fabs(x));
                y[3] = eq_exp(x * 1e-2); y[4] = eq_atan(x * 0.1); y[5] = eq_tanh(x * 0.1);
                fwrite(y, sizeof y[0], 6, out);
            }
            fclose(in); fclose(out);
            return 0;
        }
    """))
    exe = _build(tmp_path, [tmp_path / "m.c"], "m")
    assert _run(exe, tmp_path).returncode == 0
    want = np.array([[libm.sin(float(x)), libm.cos(float(x)), libm.log(abs(float(x))),
                      libm.eq_exp(float(x) * 1e-2), libm.eq_atan(float(x) * 0.1),
                      libm.eq_tanh(float(x) * 0.1)] for x in xs])
    assert (tmp_path / "out.bin").read_bytes() == want.tobytes()


def test_the_cores_plant_and_noise_give_the_x86_bits(tmp_path: Path) -> None:
    from equilibrist.numeric.lookup import get_system
    from equilibrist.sim.core_unit import unit_source
    from equilibrist.sim.simcore import load_core

    system = get_system("cartpole")
    core = load_core(system)  # this machine's (x86-64) compiled core
    p = np.array(system.p, dtype=float)
    starts = np.random.default_rng(5).uniform(-1.0, 1.0, (20, 4)) * [0.5, 3.0, 2.0, 6.0]
    want = []
    for x0 in starts:
        x = np.array(x0)
        core.rk4_steps(x, np.array([3.5]), p, 1e-3, 1500)
        want.append(x)
    rng = np.array([0x9E3779B97F4A7C15, 0xBF58476D1CE4E5B9, 0x94D049BB133111EB, 42],
                   dtype=np.uint64)
    normals = np.empty(5001)
    core.normals(rng.copy(), normals)
    (tmp_path / "in.bin").write_bytes(starts.tobytes() + p.tobytes() + rng.tobytes())
    unit = unit_source(system).replace('__attribute__((visibility("default")))', "")
    (tmp_path / "core.c").write_text(unit + textwrap.dedent(f"""
        #include <stdio.h>
        int main(void)
        {{
            double starts[20][4], p[{p.size}], u[1] = {{3.5}}, normals[5001];
            uint64_t rng[4];
            int i;
            FILE *in = fopen("in.bin", "rb"), *out = fopen("out.bin", "wb");
            if (fread(starts, sizeof starts, 1, in) != 1 || fread(p, sizeof p, 1, in) != 1
                || fread(rng, sizeof rng, 1, in) != 1) return 2;
            for (i = 0; i < 20; i++) eq_rk4_steps(starts[i], u, p, 1e-3, 1500);
            eq_normals_into(rng, normals, 5001);
            fwrite(starts, sizeof starts, 1, out);
            fwrite(normals, sizeof normals, 1, out);
            fclose(in); fclose(out);
            return 0;
        }}
    """))
    exe = _build(tmp_path, [tmp_path / "core.c"], "core", "-D_POSIX_C_SOURCE=200809L",
                 "-std=gnu99", "-Wno-unknown-pragmas")
    proc = _run(exe, tmp_path)
    assert proc.returncode == 0, proc.stderr
    got = (tmp_path / "out.bin").read_bytes()
    assert got == np.array(want).tobytes() + normals.tobytes()
    assert np.abs(np.array(want) - starts).max() > 0.1  # it did move


@pytest.mark.parametrize("controller", ["lqg", "swingup"])
def test_an_exported_controller_replays_its_vectors_to_the_bit(tmp_path: Path,
                                                               controller: str) -> None:
    from equilibrist.cli.main import main

    out = tmp_path / controller
    assert main(["export", "cartpole", "--controller", controller, "--duration", "2",
                 "--out", str(out)]) == 0
    name = f"cartpole_{controller}" if controller == "lqg" else "swingup"
    sources = [out / f"{name}.c", out / f"test_{name}.c"]
    exe = _build(out, sources, "check_a64", "-I", str(out))
    proc = _run(exe, out)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    if controller == "lqg":  # the linear library's check reports its worst error: none
        worst = re.search(r"(\d+) steps match the vectors \(worst error ([0-9.eE+-]+)", proc.stdout)
        assert worst is not None and int(worst.group(1)) > 300, proc.stdout
        assert float(worst.group(2)) == 0.0, proc.stdout
    else:  # the translated controller's check is exact: every command to the bit
        done = re.search(r"(\d+) samples, (\d+) mismatches", proc.stdout)
        assert done is not None and int(done.group(1)) > 300, proc.stdout
        assert done.group(2) == "0", proc.stdout
