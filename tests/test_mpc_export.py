"""The MPC through OSQP's generated C code: within the solver's tolerance of Python, make check."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np

from equilibrist import get_system
from equilibrist.control.mpc import mpc
from equilibrist.export.mpc_c import PythonReference, export_mpc, footprint


def test_generated_solver_matches_python_and_make_check_passes(tmp_path: Path) -> None:
    system = get_system("cartpole")
    ctrl = mpc(system, horizon=30, estimator="state")
    folder = export_mpc(ctrl, tmp_path / "mpc", duration=0.5)
    assert shutil.which("make") and shutil.which("cc"), "make check needs make and a C compiler"
    proc = subprocess.run(["make", "check"], cwd=folder, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    worst = float(re.search(r"worst difference (\S+),", proc.stdout).group(1))  # type: ignore[union-attr]
    assert worst < 1e-5  # OSQP's eps 1e-6 on the QP's variables
    # The recorded commands reach the input limit (a constrained case) and stay inside it.
    text = (folder / "mpc_vectors.h").read_text()
    u = np.array([float(v) for v in re.findall(r"\{([-0-9.e+]+)\}", text.split("vec_u")[1])])
    assert np.isclose(np.abs(u).max(), 200.0, atol=1e-6) and np.all(np.abs(u) <= 200.0 + 1e-9)
    size = footprint(folder)
    assert size["text"] > 0 and size["data"] > 0


def test_reference_is_the_runtime_on_unconstrained_states() -> None:
    system = get_system("cartpole")
    ctrl = mpc(system, horizon=20, estimator="state")
    ref = PythonReference(ctrl)
    x = ctrl.x_op + np.array([0.02, 0.01, 0.0, 0.0])
    np.testing.assert_allclose(ref.step(x), ctrl.u_op - ctrl.K @ (x - ctrl.x_op), atol=1e-3)
