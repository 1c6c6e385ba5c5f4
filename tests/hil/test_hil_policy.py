"""Hardware in the loop of a trained network: ``equilibrist export --policy FILE`` built as the
device's program (``make hil-host``) on a pseudo-terminal, run by ``equilibrist hil --policy
FILE`` like any controller kind. The truth is PyTorch's forward pass of the same network on
the states the run went through: every command the device answered is the network's action
on that sample's state, mapped onto the force's limits."""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch

from equilibrist.cli.main import main
from equilibrist.control.design import design
from equilibrist.numeric.lookup import get_system
from equilibrist.sim import SimResult
from support import require
from support.hil import host_on_link
from support.networks import CARTPOLE_F_MAX, CARTPOLE_SCALES


def _network(path: Path) -> torch.nn.Sequential:
    """A tanh MLP (4-16-1) that balances: near upright it is the LQR (its output layer undoes
    the hidden layer's linear part), farther out its tanh units bend it."""
    torch.manual_seed(3)
    k = design(get_system("cartpole"), rate=200.0).K  # (1, 4)
    hidden = torch.nn.Linear(4, 16).double()
    out = torch.nn.Linear(16, 1).double()
    with torch.no_grad():
        w1 = hidden.weight.numpy() * 4.0
        hidden.weight.copy_(torch.from_numpy(w1))
        hidden.bias.zero_()
        lqr = -k * CARTPOLE_SCALES / CARTPOLE_F_MAX  # the LQR in the network's units
        out.weight.copy_(torch.from_numpy(lqr @ np.linalg.pinv(w1)))
        out.bias.zero_()
    net = torch.nn.Sequential(hidden, torch.nn.Tanh(), out)
    torch.save(net.state_dict(), path)
    return net


@pytest.mark.slow
def test_a_policy_on_the_device_answers_its_torch_forward_pass(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    require("cc")
    require("make")
    torch.set_num_threads(1)
    path = tmp_path / "net.pt"
    net = _network(path)
    folder = tmp_path / "device"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["export", "cartpole", "--policy", str(path), "--out", str(folder),
                     "--duration", "0.2"]) == 0
    made = subprocess.run(["make", "-s", "-C", str(folder), "hil-host"], capture_output=True,
                          text=True, check=False)
    assert made.returncode == 0, made.stderr
    capsys.readouterr()
    with host_on_link(folder / "hil_host") as port:
        status = main(["hil", "cartpole", "--port", port, "--policy", str(path),
                       "--payload", "float64", "--noise", "off", "--duration", "1",
                       "--x0", "theta=0.25", "--x0", "x=-0.3", "--json",
                       "--out", str(tmp_path / "hil.npz")])
    out = capsys.readouterr()
    assert status == 0, out.err
    figures = json.loads(out.out)
    assert figures["fault"] is None and figures["late"] == 0 and figures["steps"] == 201
    run = SimResult.load(tmp_path / "hil.npz")
    with torch.no_grad():
        action = net(torch.from_numpy(run.states / CARTPOLE_SCALES)).clamp(-1, 1).numpy()
    want = CARTPOLE_F_MAX * action
    np.testing.assert_allclose(run.applied, want, rtol=0, atol=1e-6 * CARTPOLE_F_MAX)
    # The run was the network's and not a line (its tanh units bent it away from the LQR it
    # is near upright), and it held the pole, bringing it back toward upright.
    lqr = -run.states @ design(get_system("cartpole"), rate=200.0).K.T
    assert np.abs(want - lqr).max() > 0.05 * np.abs(lqr).max()
    assert not run.fell and abs(run.states[-1, 1]) < 0.25
