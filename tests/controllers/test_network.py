"""``--controller policy``: a trained network as a controller, checked against PyTorch's own
forward pass (and Stable-Baselines3's ``predict``), in Python and compiled to C with no C
library function; read errors are one line."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3 import PPO, SAC

import equilibrist.envs  # noqa: F401  (registers the environments)
from equilibrist import get_system
from equilibrist.controllers.kinds import KindError
from equilibrist.controllers.network import network_controller, read_network
from equilibrist.native.nonlinear_library import CompiledNonlinear, math_functions, nonlinear_files

SCALES = np.array([0.5, 0.2, 1.0, 1.0])  # the cart-pole's Bryson scales; upright at 0


def _mlp(n_in: int, activation: type[torch.nn.Module], seed: int) -> torch.nn.Sequential:
    torch.manual_seed(seed)
    net = torch.nn.Sequential(torch.nn.Linear(n_in, 64), activation(), torch.nn.Linear(64, 64),
                              activation(), torch.nn.Linear(64, 1))
    with torch.no_grad():  # weights large enough that the actions reach the clip
        for p in net.parameters():
            p.mul_(3.0)
    return net


def _states(n: int) -> np.ndarray:
    return np.random.default_rng(0).normal(size=(n, 4)) * SCALES


@pytest.mark.parametrize(("activation", "name"), [(torch.nn.Tanh, "tanh"),
                                                  (torch.nn.ReLU, "relu")])
def test_a_2x64_state_dict_is_its_torch_forward_pass_in_python_and_in_c(
        tmp_path, activation: type[torch.nn.Module], name: str) -> None:
    torch.set_num_threads(1)
    net = _mlp(4, activation, seed=1)
    path = tmp_path / "net.pt"
    torch.save(net.state_dict(), path)
    system = get_system("cartpole")
    ctrl = network_controller(system, read_network(path, activation=name), rate=200.0)
    runtime = ctrl.runtime()
    compiled = CompiledNonlinear(ctrl)
    # No C library function: tanh is the project's eq_exp (fabs and frexp are exact).
    assert set(math_functions(nonlinear_files(ctrl)["policy.c"])) <= {"fabs", "frexp"}
    xs = _states(200)
    with torch.no_grad():
        want = net.double()(torch.from_numpy(xs / SCALES)).clamp(-1, 1).numpy()[:, 0] * 200.0
    got_py = np.array([runtime.output(0.0, x, np.zeros(0))[0] for x in xs])
    got_c = np.array([compiled.output(0.0, x, np.zeros(0))[0] for x in xs])
    compiled.close()
    assert np.abs(got_py - want).max() <= 1e-6 * 200.0
    np.testing.assert_array_equal(got_c, got_py)  # the C is the Python, to the bit
    assert (np.abs(want) == 200.0).any() and (np.abs(want) < 200.0).any()  # clip and not


def test_stable_baselines3_models_are_their_predict(tmp_path) -> None:
    """PPO's actor (tanh, the mean clipped) and SAC's (ReLU, tanh of the mean), as saved by
    Stable-Baselines3, act as ``model.predict(obs, deterministic=True)`` does."""
    torch.set_num_threads(1)
    system = get_system("cartpole")
    balance = gym.make("equilibrist/cartpole-balance-v1", dtype=np.float64)
    swingup = gym.make("equilibrist/cartpole-swingup-v1", dtype=np.float64)
    xs = _states(30)
    for model in (PPO("MlpPolicy", balance, seed=0, device="cpu"),
                  SAC("MlpPolicy", swingup, seed=0, device="cpu")):
        path = tmp_path / f"{type(model).__name__}.zip"
        model.save(path)
        ctrl = network_controller(system, read_network(path), rate=200.0)
        runtime = ctrl.runtime()
        for x in xs:
            if isinstance(model, SAC):
                obs = np.array([x[0] / 0.5, math.cos(x[1]), math.sin(x[1]), x[2], x[3]])
            else:
                obs = x / SCALES
            action = model.predict(obs, deterministic=True)[0]
            u = runtime.output(0.0, x, np.zeros(0))
            assert u[0] == pytest.approx(200.0 * float(action[0]), abs=1e-4)
        assert ctrl.settings["task"] == ("swingup" if isinstance(model, SAC) else "balance")


def test_bad_files_are_one_line(tmp_path) -> None:
    with pytest.raises(KindError, match="no such file"):
        read_network(tmp_path / "missing.zip")
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a network")
    with pytest.raises(KindError, match="not a PyTorch state dict"):
        read_network(junk)
    wrong = tmp_path / "wrong.pt"
    torch.save(_mlp(3, torch.nn.Tanh, seed=0).state_dict(), wrong)
    with pytest.raises(KindError, match=r"takes 3 observation\(s\).*4 \(balance\), 5 \(swingup\)"):
        network_controller(get_system("cartpole"), read_network(wrong), rate=200.0)


def test_policy_alone_picks_the_kind_on_the_command_line(tmp_path, capsys) -> None:
    """``--policy FILE`` without ``--controller`` runs the network; a missing file is one
    line and exit status 2, and nothing is written."""
    import json

    from equilibrist.cli.main import main

    path = tmp_path / "net.pt"
    torch.save(_mlp(4, torch.nn.Tanh, seed=2).state_dict(), path)
    runs = []
    for args in (["--policy", str(path)], ["--controller", "policy", "--policy", str(path)], []):
        assert main(["simulate", "cartpole", *args, "--duration", "0.2", "--json"]) == 0
        runs.append(json.loads(capsys.readouterr().out))
    assert runs[0] == runs[1] != runs[2]  # the network's run, not the default LQG's
    assert main(["export", "cartpole", "--policy", str(tmp_path / "none.zip"),
                 "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no such file" in err[0]
    assert not (tmp_path / "out").exists()
