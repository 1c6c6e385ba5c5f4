"""Model files: deriving an MJCF/URDF model, and evaluating its dynamics against MuJoCo.

For each shipped model file: the first load with an empty cache (MuJoCo's
compiler, the derivation with sympy, code generation), and one evaluation
of the accelerations, ``f(x, u)`` of the generated code (plain Python and
the C core's, through ctypes) against MuJoCo's ``mj_forward`` on the same file (the
peer a user of the file would otherwise call). Ratios are MuJoCo's time
over equilibrist's (> 1: equilibrist faster).

Run: ``.venv/bin/python bench/bench_import.py``
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
FILES = [ROOT / "examples" / "furuta.xml", ROOT / "examples" / "pendubot.urdf",
         ROOT / "tests" / "models" / "slides.xml"]


def _cold(path: Path) -> float:
    with tempfile.TemporaryDirectory() as cache:
        code = (
            "import time; t = time.perf_counter(); from equilibrist import get_system; "
            f"get_system({str(path)!r}); print(time.perf_counter() - t)"
        )
        env = {**os.environ, "EQUILIBRIST_CACHE": cache}
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True)
        return float(out.stdout.strip())


def _per_call(fn, repeat: int = 20000) -> float:
    fn()
    best = float("inf")
    for _ in range(5):
        t = time.perf_counter()
        for _ in range(repeat):
            fn()
        best = min(best, (time.perf_counter() - t) / repeat)
    return best * 1e6


def main() -> None:
    import mujoco

    from equilibrist.numeric.lookup import get_system
    from equilibrist.sim.simcore import load_core

    print(f"{'model':16s} {'cold s':>7s} {'f py us':>8s} {'f core us':>10s} {'mj_forward us':>13s} "
          f"{'mj/py':>6s} {'mj/core':>8s}")
    for path in FILES:
        cold = _cold(path)
        system = get_system(str(path))
        n = system.n_states
        x = np.linspace(0.1, 0.4, n)
        u = np.zeros(system.n_inputs)
        out = np.empty(n)
        p = np.asarray(system.p)
        f = system.functions.f
        f_core = load_core(system).f  # the C core's f, called through ctypes
        args = (x, u, p, out)
        py = _per_call(lambda f=f, a=args: f(*a))
        nb = _per_call(lambda f=f_core, a=args: f(*a))
        model = mujoco.MjModel.from_xml_path(str(path))
        data = mujoco.MjData(model)
        data.qpos[:] = x[: n // 2]
        data.qvel[:] = x[n // 2:]
        mj = _per_call(lambda m=model, d=data: mujoco.mj_forward(m, d))
        print(f"{path.name:16s} {cold:7.2f} {py:8.2f} {nb:10.2f} {mj:13.2f} {mj / py:6.2f} {mj / nb:8.2f}")


if __name__ == "__main__":
    main()
