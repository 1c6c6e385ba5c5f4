"""Rig effects in the environments: an episode through a rig is ``simulate``'s run with that
rig and seed, to the bit, in the single and the vector environment."""

from __future__ import annotations

import numpy as np
import pytest

from equilibrist.envs.core import EnvError
from equilibrist.envs.env import EquilibristEnv
from equilibrist.envs.vector import EquilibristVectorEnv
from equilibrist.sim.rig import Rig
from equilibrist.sim.run import simulate

#: Every effect of the rig at once: the torque's response and noise, both delays, encoders
#: with differenced and filtered velocities, velocity noise, and pushes on both joints.
RIG = Rig(torque_response=0.6, measurement_delay=2, actuation_delay=1, torque_noise=0.3,
          velocity_noise=0.02, encoder_step=1e-3, velocity_filter=20.0, perturbations=2,
          perturbation_gap=0.5, perturbation_amplitude=(0.5, 2.0))


def _policy(y: np.ndarray) -> np.ndarray:
    """A feedback of what the agent measured (so the actions depend on the rig's effects)."""
    return np.array([25.0 * y[1] + 2.0 * y[0]])


def _episode(env: EquilibristEnv, seed: int, steps: int
             ) -> tuple[dict[str, object], list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    """An episode of *steps* periods at most under :func:`_policy`: the reset's info, the
    observations, the true states and the actions."""
    obs, info = env.reset(seed=seed)
    ys, xs, us = [obs], [env.state], []
    for _ in range(steps):
        u = _policy(ys[-1])
        obs, _reward, terminated, truncated, _ = env.step(u)
        us.append(u)
        ys.append(obs)
        xs.append(env.state)
        if terminated or truncated:
            break
    return info, ys, xs, us


def test_an_episode_through_a_rig_is_simulates_run_to_the_bit() -> None:
    """The same start, actions, noise seed and rig: ``simulate`` with a Python controller
    returning the agent's actions gives the same states, measurements and acting torques."""
    env = EquilibristEnv("cartpole", "balance", rig=RIG, action_units="physical")
    core = env.core
    info, ys, xs, us = _episode(env, 4, 400)
    assert len(us) > 100
    acted: list[np.ndarray] = []
    commands = iter([*us, *([np.zeros(1)] * core.n_samples)])

    def controller(t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        return next(commands)

    res = simulate(core.system, controller, duration=core.task.duration, rate=core.rate,
                   x0=info["state"], noise=core.noise, seed=info["noise_seed"], rig=RIG,
                   region=core.task.region, outputs=list(core.observation_names))
    n = len(res.states)
    assert np.array_equal(res.states, np.array(xs[:n]))
    assert np.array_equal(res.measurements, np.array(ys[:n]))
    if res.fell:  # the run stops where the state left the region: the episode's last state
        assert len(xs) == n + 1 and np.array_equal(res.fell_x, xs[-1])
    else:
        assert len(xs) == n
    # The rig did act: the measurements are not the state's, the torque not the command.
    assert not np.array_equal(res.measurements[:n, 1], res.states[:n, 1])
    assert not np.array_equal(res.applied[:n - 1, 0], np.array(us)[:, 0])
    # And the environment saw the torque that acted.
    env2 = EquilibristEnv("cartpole", "balance", rig=RIG, action_units="physical")
    env2.reset(seed=4)
    for u in us[:5]:
        env2.step(u)
        acted.append(env2._u.copy())
    assert np.array_equal(np.array(acted)[:, 0], res.applied[:5, 0])


def test_the_vector_environments_copies_are_the_single_environments() -> None:
    """Copy i of the vector environment reset with seed s is the single environment reset with
    s + i, to the bit, across an episode's end and its next-step restart."""
    venv = EquilibristVectorEnv(2, "cartpole", "balance", rig=RIG, action_units="physical",
                                observe="state")
    singles = [EquilibristEnv("cartpole", "balance", rig=RIG, action_units="physical",
                              observe="state") for _ in range(2)]
    obs, info = venv.reset(seed=10)
    got = [s.reset(seed=10 + i) for i, s in enumerate(singles)]
    for i in range(2):
        assert np.array_equal(obs[i], got[i][0])
        assert info["noise_seed"][i] == got[i][1]["noise_seed"]
    kick = np.array([[60.0], [-60.0]])  # pushes that topple both copies within the run
    for k in range(600):
        actions = kick if k < 100 else np.zeros((2, 1))
        obs, rewards, terminated, truncated, _ = venv.step(actions)
        for i, single in enumerate(singles):
            if single._episode is None:
                continue
            o, r, term, trunc, _ = single.step(actions[i])
            assert np.array_equal(obs[i], o) and rewards[i] == r
            assert (terminated[i], truncated[i]) == (term, trunc)
            if term or trunc:
                single._episode = None  # the vector copy restarts at its next step
    assert all(s._episode is None for s in singles), "both copies fell"


def test_the_rig_option_is_checked() -> None:
    with pytest.raises(EnvError, match="unknown effect 'torque_lag'") as info:
        EquilibristEnv("cartpole", "balance", rig={"torque_lag": 0.5})
    assert "\n" not in str(info.value)
    with pytest.raises(EnvError, match="rig measurement_delay = -1"):
        EquilibristEnv("cartpole", "balance", rig={"measurement_delay": -1})
    with pytest.raises(EnvError, match=r"expected an equilibrist\.sim\.rig\.Rig"):
        EquilibristEnv("cartpole", "balance", rig=3)
    env = EquilibristEnv("cartpole", "balance", rig={"torque_response": 0.5})
    assert env.core.rig == Rig(torque_response=0.5)
    assert env.core.describe()["rig"] == {"torque_response": 0.5}
    assert EquilibristEnv("cartpole", "balance", rig=Rig()).core.rig is None  # adds nothing
