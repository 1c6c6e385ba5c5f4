"""Hardware in the loop of the time-varying LQR: its export (the NonlinearController's source
translated to C) on a device over a pseudo-terminal, lockstep, equals ``simulate`` of the same
planned swing-up."""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from equilibrist.cli.main import main
from equilibrist.control.trajopt import plan
from equilibrist.numeric.lookup import get_system
from equilibrist.sim import SimResult
from equilibrist.tasks import get_task
from support import require
from support.hil import host_on_link


@pytest.mark.slow
def test_a_planned_swing_up_on_the_device_equals_simulate(tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    require("cc")
    require("make")
    cart = get_system("cartpole")
    task = get_task(cart, "swingup")
    traj = plan(cart, start=task.start, goal=task.x_op, knots=60, duration=4.0)
    path = str(traj.save(tmp_path / "up.npz"))
    folder = tmp_path / "device"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["export", "cartpole", "--controller", "tvlqr", "--trajectory", path,
                     "--out", str(folder), "--duration", "0.5"]) == 0
    made = subprocess.run(["make", "-s", "-C", str(folder), "hil-host"], capture_output=True,
                          text=True, check=False)
    assert made.returncode == 0, made.stderr
    args = ["--controller", "tvlqr", "--trajectory", path, "--duration", "5"]
    assert main(["simulate", "cartpole", *args, "--out", str(tmp_path / "sim.npz")]) == 0
    want = SimResult.load(tmp_path / "sim.npz")
    capsys.readouterr()
    with host_on_link(folder / "hil_host") as port:
        status = main(["hil", "cartpole", "--port", port, "--payload", "float64",
                       "--out", str(tmp_path / "hil.npz"), "--json", *args])
    out = capsys.readouterr()
    assert status == 0, out.err
    figures = json.loads(out.out)
    got = SimResult.load(tmp_path / "hil.npz")
    assert figures["late"] == 0 and figures["lost"] == 0 and figures["fault"] is None
    assert got.states.shape == want.states.shape
    # float64 payloads: the device's commands are the simulated controller's, to the bit.
    np.testing.assert_array_equal(got.applied, want.applied)
    np.testing.assert_array_equal(got.states, want.states)
    # The run swung up from hanging (where the plan starts) and ended balanced.
    assert abs(want.states[0, 1] - np.pi) < 1e-9 and abs(np.remainder(want.states[-1, 1] + np.pi,
                                                                        2 * np.pi) - np.pi) < 0.05
