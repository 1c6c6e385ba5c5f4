"""Stable-Baselines3's VecEnv over the native vector environment: its copies live the
native environment's episodes (restarted in the step that ends one, as Stable-Baselines3
expects, instead of the next), PPO trains on it, and without the extra the error names it."""

from __future__ import annotations

import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.vec_env import VecMonitor
from tests.support.imports import import_without

from equilibrist.envs.sb3 import EquilibristSB3VecEnv, sb3_vec_env


def test_copies_live_the_native_environments_episodes() -> None:
    """Copy by copy, the adapter's observations are the native vector environment's with
    the native restarting step left out; the ending step's info holds the last
    observation."""
    import gymnasium as gym

    env_id = "equilibrist/cartpole-balance-v1"
    adapter = sb3_vec_env(env_id, num_envs=3, seed=10)
    native = gym.make_vec(env_id, num_envs=3)
    rng = np.random.default_rng(1)
    actions = rng.uniform(-1, 1, (120, 3, 1)).astype(np.float32)
    actions[:, 1] = 1.0  # copy 1 falls, then again
    a_obs = [adapter.reset()]
    a_infos, a_dones = [], []
    for k in range(120):
        adapter.step_async(actions[k])
        obs, rewards, dones, infos = adapter.step_wait()
        assert rewards.dtype == np.float32
        a_obs.append(obs)
        a_dones.append(dones)
        a_infos.append(infos)
    for i in range(3):
        n_obs, _ = native.reset(seed=[10, 11, 12])
        seen = [n_obs[i]]
        k = 0
        due = False
        while len(seen) < 121:
            # The native copy restarts one step after its end: its action there is ignored.
            act = np.zeros((3, 1), dtype=np.float32)
            if not due:
                act[i] = actions[k, i]
                k += 1
            o, _, term, trunc, _ = native.step(act)
            if due:
                seen[-1] = o[i]  # the adapter shows the next episode's start at once
            else:
                seen.append(o[i])
            due = bool(term[i] or trunc[i])
            if due:
                ended = len(seen) - 1
                np.testing.assert_array_equal(a_infos[ended - 1][i]["terminal_observation"], o[i])
                assert a_dones[ended - 1][i]
                assert a_infos[ended - 1][i]["TimeLimit.truncated"] == bool(trunc[i] and not term[i])
        np.testing.assert_array_equal(np.array(seen[:121]), np.array([x[i] for x in a_obs]))
    assert sum(d[1] for d in a_dones) == 1  # copy 1 fell and restarted


def test_ppo_trains_on_it() -> None:
    env = VecMonitor(sb3_vec_env("equilibrist/cartpole-balance-v1", num_envs=4, seed=0))
    model = PPO("MlpPolicy", env, n_steps=64, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(256)
    assert model.num_timesteps == 256
    assert isinstance(env.venv, EquilibristSB3VecEnv)
    assert env.get_attr("render_mode") == [None] * 4


def test_without_the_extra_the_error_names_it(monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(ImportError, match=r"pip install 'equilibrist\[rl\]'"):
        import_without(monkeypatch, "stable_baselines3", "equilibrist.envs.sb3")
