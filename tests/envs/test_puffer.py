"""PufferLib's native environment over the native vector environment: PufferLib's own
``vector.make`` takes it (natively and through its Serial workers), its agents live the
native environment's episodes (restarted in the step that ends one, as PufferLib's native
environments do, instead of the next), and without PufferLib the error names it."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pufferlib
import pufferlib.vector
import pytest
from tests.support.imports import import_without

from equilibrist.envs.puffer import EquilibristPufferEnv

ENV_ID = "equilibrist/cartpole-balance-v1"


def test_agents_live_the_native_environments_episodes() -> None:
    """Copy by copy, PufferLib's observations, rewards and flags are the native vector
    environment's with its restarting step left out (the ending step shows the next
    episode's start at once), through PufferLib's own ``vector.make``."""
    envs = pufferlib.vector.make(EquilibristPufferEnv, env_args=[ENV_ID],
                                 env_kwargs={"num_envs": 3})
    assert isinstance(envs, EquilibristPufferEnv)  # PufferLib's native path: no workers
    rng = np.random.default_rng(1)
    actions = rng.uniform(-1, 1, (120, 3, 1)).astype(np.float32)
    actions[:, 1] = 1.0  # copy 1 falls, then again
    obs, _ = envs.reset(seed=10)
    p_obs, p_rew, p_done = [obs.copy()], [], []
    for k in range(120):
        obs, rewards, terminals, truncations, _ = envs.step(actions[k])
        assert rewards.dtype == np.float32
        p_obs.append(obs.copy())
        p_rew.append(rewards.copy())
        p_done.append(terminals | truncations)
    native = gym.make_vec(ENV_ID, num_envs=3)
    for i in range(3):
        n_obs, _ = native.reset(seed=[10, 11, 12])
        seen, rewards_seen = [n_obs[i]], []
        k, due = 0, False
        while len(seen) < 121:
            act = np.zeros((3, 1), dtype=np.float32)
            if not due:  # the native copy restarts one step after its end
                act[i] = actions[k, i]
                k += 1
            o, r, term, trunc, _ = native.step(act)
            if due:
                seen[-1] = o[i]
            else:
                seen.append(o[i])
                rewards_seen.append(r[i])
            due = bool(term[i] or trunc[i])
            if due:
                assert p_done[len(seen) - 2][i]
        np.testing.assert_array_equal(np.array(seen), np.array([x[i] for x in p_obs]))
        np.testing.assert_array_equal(np.float32(rewards_seen), [x[i] for x in p_rew])
    assert sum(d[1] for d in p_done) >= 1  # copy 1 fell and restarted
    assert sum(d[0] for d in p_done) == 0


def test_pufferlibs_workers_share_its_buffers() -> None:
    """PufferLib's Serial backend builds two of them over its shared buffers: each
    worker's slice is its own environment's copies, seeded as PufferLib seeds them."""
    envs = pufferlib.vector.make(EquilibristPufferEnv, env_args=[ENV_ID],
                                 env_kwargs={"num_envs": 4}, backend=pufferlib.vector.Serial,
                                 num_envs=2)
    obs, _ = envs.reset(seed=0)
    assert obs.shape == (8, 4)
    alone = EquilibristPufferEnv(ENV_ID, num_envs=4)
    for worker in range(2):
        start, _ = alone.reset(seed=worker)  # PufferLib resets worker i with seed + i
        np.testing.assert_array_equal(obs[4 * worker:4 * worker + 4], start)
    obs, rewards, terminals, truncations, _ = envs.step(np.zeros((8, 1), np.float32))
    assert rewards.shape == terminals.shape == truncations.shape == (8,)
    assert np.all(rewards > 0.9)  # near upright every copy earns nearly the whole step


def test_without_pufferlib_the_error_names_it(monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(ImportError, match=r"pip install --no-deps pufferlib-core"):
        import_without(monkeypatch, "pufferlib", "equilibrist.envs.puffer")
    assert pufferlib.PufferEnv  # the real one stays importable
