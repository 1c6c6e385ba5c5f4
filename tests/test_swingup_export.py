"""The exported C swing-up: exact against the Python controller, `make check`, and in the loop."""

from __future__ import annotations

import math
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.control.swingup import SwingUpRuntime, swingup
from equilibrist.export.swingup_c import (
    MATH_FUNCTIONS,
    CompiledSwingUp,
    export_swingup,
    recorded_vectors,
    swingup_files,
)
from equilibrist.sim.run import simulate
from equilibrist.tasks import get_task


@pytest.mark.parametrize(("name", "balance", "form"), [
    ("cartpole", "lqr", "current"), ("acrobot", "lqr", "current"), ("furuta", "lqr", "current"),
    ("reaction_wheel_pendulum", "lqr", "current"), ("cartpole", "lqg", "current"),
    ("reaction_wheel_pendulum", "lqg", "predictor"), ("furuta", "lqg", "current"),
])
def test_c_commands_equal_python_exactly(name: str, balance: str, form: str) -> None:
    """On recorded vectors (noisy swing-up), every C command is the Python one, bit for bit
    (and its estimate; with the LQG hand-over, the filter's state too)."""
    from equilibrist.control.design import design
    from equilibrist.control.swingup import Z

    system = get_system(name)
    d = design(system, rate=system.spec.control_rate, kalman_form=form)
    ctrl = swingup(system, design=d, balance=balance)
    vec = recorded_vectors(ctrl, system, duration=3.0, seed=2)
    py = SwingUpRuntime(ctrl, compiled=False)
    c = CompiledSwingUp(ctrl)
    try:
        for y, ua, u in zip(vec["y"], vec["u_applied"], vec["u"], strict=True):
            a = py.output(0.0, y, np.zeros(0))
            b = c.output(0.0, y, np.zeros(0))
            assert a[0] == b[0] == u[0]
            np.testing.assert_array_equal(py.estimate, c.estimate)
            py.update(0.0, y, np.zeros(0), ua)
            c.update(0.0, y, np.zeros(0), ua)
            np.testing.assert_array_equal(py.z, c._z)
        assert py.mode == "balance" or name == "acrobot"
        if balance == "lqg":
            assert np.any(py.z[Z["kz"]:Z["kz"] + 4] != 0.0), "the filter must have run"
    finally:
        c.close()


def test_make_check_in_the_exported_folder(tmp_path: Path) -> None:
    system = get_system("cartpole")
    folder = export_swingup(swingup(system), system, tmp_path / "out")
    assert shutil.which("make") and shutil.which("cc"), "make check needs make and a C compiler"
    proc = subprocess.run(["make", "check"], cwd=folder, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "0 mismatches" in proc.stdout


def test_needs_only_the_stated_math_functions() -> None:
    source = swingup_files(swingup(get_system("cartpole")))["swingup.c"]
    called = {f for f in ("cos", "sin", "floor", "sqrt", "exp", "atan2", "fabs", "pow", "tan")
              if f"{f}(" in source.replace("su_", "")}
    assert called == set(MATH_FUNCTIONS)


def test_exported_code_closes_the_loop() -> None:
    """The C library swings the cart-pole up on the nonlinear plant, on its track."""
    system = get_system("cartpole")
    ctrl = swingup(system)
    task = get_task(system, "swingup")
    c = CompiledSwingUp(ctrl)
    try:
        res = simulate(system, c, duration=6.0, x0=task.draw_initial(np.random.default_rng(5)),
                       region=task.region)
    finally:
        c.close()
    assert not res.fell
    assert abs(math.remainder(res.final_state[1], 2 * math.pi)) < 0.02


def test_command_line_export_and_refusal(tmp_path: Path) -> None:
    cmd = [sys.executable, "-m", "equilibrist.cli.main"]
    out = tmp_path / "cart"
    proc = subprocess.run([*cmd, "export", "cartpole", "--controller", "swingup", "--out", str(out)],
                          capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    check = subprocess.run(["make", "check"], cwd=out, capture_output=True, text=True, check=False)
    assert check.returncode == 0 and "0 mismatches" in check.stdout
    bad = subprocess.run([*cmd, "export", "ball_beam", "--controller", "swingup", "--out",
                          str(tmp_path / "bb")], capture_output=True, text=True, check=False)
    assert bad.returncode == 2
    assert bad.stderr.strip().count("\n") == 0 and "no swing-up" in bad.stderr
    assert not (tmp_path / "bb").exists()


def test_command_line_lqg_hand_over(tmp_path: Path) -> None:
    """``--balance lqg`` reaches the builder: the exported library balances with the LQG."""
    cmd = [sys.executable, "-m", "equilibrist.cli.main"]
    out = tmp_path / "furuta"
    proc = subprocess.run([*cmd, "export", "furuta", "--controller", "swingup", "--balance", "lqg",
                           "--out", str(out)], capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stderr
    assert "balanced by the LQG" in (out / "swingup.h").read_text()
    check = subprocess.run(["make", "check"], cwd=out, capture_output=True, text=True, check=False)
    assert check.returncode == 0 and "0 mismatches" in check.stdout
    bad = subprocess.run([*cmd, "export", "furuta", "--controller", "swingup", "--balance", "pid",
                          "--out", str(tmp_path / "x")], capture_output=True, text=True, check=False)
    assert bad.returncode == 2 and not (tmp_path / "x").exists()
