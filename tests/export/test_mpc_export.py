"""The MPC exported as C (DAQP's sources and a generated driver), with or without its Kalman filter:
the commands equal the simulated controller's to round-off, the filter too, make check, in the loop."""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.cli.main import main
from equilibrist.control.design import design
from equilibrist.control.mpc import mpc
from equilibrist.control.mpc_runtime import MPCRuntime
from equilibrist.export.mpc_c import export_mpc
from equilibrist.native.mpc_footprint import footprint
from equilibrist.sim.run import simulate
from support import cc_cache
from support.cc_cache import cached_cc, cached_measure, environment
from support.mpc_reference import ReferenceMPC


@pytest.fixture(scope="module")
def daqp_objects(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Where DAQP's sources, the same in every export, compile once (``support.cc_cache``):
    each ``make check`` still builds and runs its own program from its folder's sources."""
    return cc_cache.folder(tmp_path_factory)


def _make_check(folder: Path, daqp_objects: Path) -> str:
    assert shutil.which("make") and shutil.which("cc"), "make check needs make and a C compiler"
    proc = subprocess.run(["make", "check"], cwd=folder, capture_output=True, text=True, check=False,
                          env=environment(daqp_objects))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


def test_exported_solver_is_the_simulated_one_and_make_check_passes(tmp_path: Path,
                                                               daqp_objects: Path) -> None:
    system = get_system("cartpole")
    ctrl = mpc(system, horizon=30, estimator="state")
    folder = export_mpc(ctrl, tmp_path / "mpc", duration=0.5, x0={"theta": 0.5})
    out = _make_check(folder, daqp_objects)
    worst = float(re.search(r"worst difference (\S+),", out).group(1))  # type: ignore[union-attr]
    assert worst == 0.0  # the simulated MPC is this library: the same bits
    # The recorded commands reach the input limit (a constrained case) and stay inside it.
    text = (folder / "mpc_vectors.h").read_text()
    u = np.array([float(v) for v in re.findall(r"\{([-0-9.e+]+)\}", text.split("vec_u")[1])])
    assert np.isclose(np.abs(u).max(), 200.0, atol=1e-6) and np.all(np.abs(u) <= 200.0 + 1e-9)
    with cached_cc(daqp_objects):
        size = footprint(folder)
    assert size["text"] > 0 and size["bss"] > 0
    # DAQP's workspace is static: no malloc. The least-distance rows (rows x variables
    # doubles) are constants (text); the RAM holds the working set's factor, not the rows.
    H, _, A = ctrl.problem.condensed
    rows = 8 * A.shape[0] * H.shape[0]
    assert size["heap"] == 0
    assert size["text"] >= rows and size["data"] + size["bss"] < rows


@pytest.mark.parametrize("form", ["current", "predictor"])
def test_kalman_filter_in_front_make_check(tmp_path: Path, form: str, daqp_objects: Path) -> None:
    """The MPC on the measured outputs: the exported C filter and QP give the simulated
    controller's bits on a noisy run."""
    system = get_system("cartpole")
    ctrl = mpc(system, design=design(system, rate=200.0, kalman_form=form), horizon=30)
    assert ctrl.estimator == "kalman" and ctrl.outputs == ("x", "theta") and ctrl.form == form
    folder = export_mpc(ctrl, tmp_path / "mpc", duration=0.5, seed=3)
    out = _make_check(folder, daqp_objects)
    worst = float(re.search(r"worst difference (\S+),", out).group(1))  # type: ignore[union-attr]
    worst_z = float(re.search(r"filter state: worst (\S+),", out).group(1))  # type: ignore[union-attr]
    assert worst == 0.0 and worst_z == 0.0  # the simulated MPC and filter are this library
    header = (folder / "mpc.h").read_text()
    assert "mpc_output(const mpc_filter *f, const double y[2], double u[1])" in header
    # The recorded run is constrained: the commands reach the input limit.
    text = (folder / "mpc_vectors.h").read_text()
    u = np.array([float(v) for v in re.findall(r"\{([-0-9.e+]+)\}",
                                                text.split("vec_u[")[1].split("vec_z")[0])])
    assert np.isclose(np.abs(u).max(), 200.0, atol=1e-6)


def test_the_compiled_filter_is_the_kalman_filter() -> None:
    """The filter in front of the compiled MPC (the LQG's estimator in the linear library's C)
    equals the design's Kalman filter written out with numpy products (round-off), both forms,
    on random measurements and applied inputs."""
    system = get_system("cartpole")
    for form in ("current", "predictor"):
        ctrl = mpc(system, design=design(system, rate=200.0, kalman_form=form), horizon=5)
        rt, ref = MPCRuntime(ctrl), ReferenceMPC(ctrl)
        rng = np.random.default_rng(4)
        for _ in range(50):
            y = ctrl.x_op[[0, 1]] + rng.normal(scale=0.1, size=2)
            ua = ctrl.u_op + rng.normal(scale=10.0, size=1)
            rt.output(0.0, y, np.zeros(0))
            ref.output(0.0, y, np.zeros(0))
            np.testing.assert_allclose(rt.estimate, ref.estimate, rtol=0, atol=1e-12)
            rt.update(0.0, y, np.zeros(0), ua)
            ref.update(0.0, y, np.zeros(0), ua)
            np.testing.assert_allclose(rt.z, ref.z, rtol=0, atol=1e-12)


def test_compiled_mpc_with_filter_closes_the_loop() -> None:
    """The compiled MPC with its Kalman filter balances the nonlinear cart-pole from noisy
    measurements, inside the hard limits, and follows the run of the MPC written out in Python
    on DAQP's Python package (support.mpc_reference) to round-off."""
    from equilibrist.sim.noise import Noise

    system = get_system("cartpole")
    d = design(system, rate=200.0)
    ctrl = mpc(system, design=d, horizon=30)
    x0 = {"theta": 0.4}
    res = simulate(system, MPCRuntime(ctrl), duration=2.0, x0=x0, noise=Noise.from_design(d),
                   seed=1)
    ref = simulate(system, ReferenceMPC(ctrl), duration=2.0, x0=x0, noise=Noise.from_design(d),
                   seed=1)
    assert not res.fell and abs(res.final_state[1]) < 0.05
    lo, hi = system.input_limits
    assert np.all(res.commanded >= lo - 1e-9) and np.all(res.commanded <= hi + 1e-9)
    assert np.isclose(np.abs(res.commanded).max(), hi[0])
    span = np.ptp(ref.states, axis=0)
    assert np.all(np.abs(res.states - ref.states) <= 1e-9 * span)


def test_command_line_export_has_the_filter(tmp_path: Path, daqp_objects: Path, capsys) -> None:
    # The command's main() in this process: what is tested is what it writes (the console
    # script in a process of its own, its exit status, is test_cli_core's).
    # Its measurement (make size) compiles DAQP's sources once a run (support.cc_cache).
    out = tmp_path / "cart"
    argv = ["export", "cartpole", "--controller", "mpc", "--horizon", "20", "--out", str(out)]
    with cached_measure(daqp_objects):
        assert main(argv) == 0, capsys.readouterr().err
    assert "mpc_update" in (out / "mpc.h").read_text()
    assert "Footprint ('make size' at export" in (out / "README.txt").read_text()
    assert "filter state: worst" in _make_check(out, daqp_objects)
    with cached_measure(daqp_objects):
        assert main(argv) == 0, capsys.readouterr().err


@pytest.mark.parametrize("name", ["double_cartpole", "acrobot", "reaction_wheel_pendulum"])
def test_every_kind_of_rig_exports_from_its_default_start(tmp_path: Path, name: str,
                                                          daqp_objects: Path) -> None:
    """Rigs without a 'theta' state, and the wheel's fast filter state: the default recorded
    run (default_start) asks for more than the input allows, and make check passes."""
    system = get_system(name)
    ctrl = mpc(system)
    folder = export_mpc(ctrl, tmp_path / name, duration=0.5)
    out = _make_check(folder, daqp_objects)
    worst = float(re.search(r"worst difference (\S+),", out).group(1))  # type: ignore[union-attr]
    assert worst < 1e-8
    text = (folder / "mpc_vectors.h").read_text()
    u = np.array([float(v) for v in re.findall(r"\{([-0-9.e+]+)\}",
                                                text.split("vec_u[")[1].split("vec_z")[0])])
    _, hi = system.input_limits
    assert np.isclose(np.abs(u).max(), hi[0], rtol=1e-9) and np.all(np.abs(u) <= hi[0] * (1 + 1e-12))
