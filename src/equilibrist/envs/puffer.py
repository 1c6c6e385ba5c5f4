"""PufferLib's native environment over the native vector one: many copies, one call.

:class:`EquilibristPufferEnv` is a ``pufferlib.PufferEnv`` whose agents are the
copies of an id's vector environment (:class:`EquilibristVectorEnv`): PufferLib's
``vector.make`` takes it natively (one process, every copy in one call of the
compiled core) or spreads several of them over its ``Serial`` and
``Multiprocessing`` workers, each writing into the buffers PufferLib shares::

    import pufferlib.vector
    from equilibrist.envs.puffer import EquilibristPufferEnv

    envs = pufferlib.vector.make(EquilibristPufferEnv, env_args=["equilibrist/cartpole-balance-v1"],
                                 env_kwargs={"num_envs": 256})
    obs, infos = envs.reset(seed=0)
    obs, rewards, terminals, truncations, infos = envs.step(actions)

PufferLib's native environments restart an agent in the step that ends its
episode: that step's observation is the copy's first of the next episode (the
copy restarted from its own generator, as the vector environment's next step
would restart it), with the ending step's reward and flags. Seeds: ``reset(seed=s)``
gives copy ``i`` the seed ``s + i``. Observations, rewards and flags are copied into
PufferLib's buffers (its rewards are float32).

PufferLib is not an extra of equilibrist: its ``pufferlib-core`` wheel pins the
PyTorch its CUDA extension was built with, which would replace the ``rl`` extra's.
Its ``vector`` and ``emulation`` modules are plain Python and work beside any
PyTorch: ``pip install --no-deps pufferlib-core`` (docs/envs.md).
"""

from __future__ import annotations

import importlib.util
from typing import Any

import numpy as np

from equilibrist.envs.core import EnvError
from equilibrist.errors import EquilibristError


class MissingPufferError(EquilibristError, ImportError):
    """PufferLib is not installed."""


if importlib.util.find_spec("pufferlib") is None:
    raise MissingPufferError(
        "equilibrist's PufferLib environment needs PufferLib's vector interface: "
        "pip install --no-deps pufferlib-core (docs/envs.md says why --no-deps)"
    )

import gymnasium as gym  # noqa: E402
import pufferlib  # noqa: E402

from equilibrist.envs.vector import EquilibristVectorEnv  # noqa: E402


class EquilibristPufferEnv(pufferlib.PufferEnv):  # type: ignore[misc]
    """*num_envs* copies of the environment *env_id* (with *options*) as a native
    ``PufferEnv`` of as many agents (see the module); *buf* and *seed* are what
    PufferLib's vector backends pass."""

    def __init__(self, env_id: str, num_envs: int = 8, *, buf: dict[str, Any] | None = None,
                 seed: int | None = None, **options: Any) -> None:
        venv = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                            **options)
        if not isinstance(venv, EquilibristVectorEnv):
            raise EnvError(f"{env_id} is not an equilibrist environment")
        self.venv = venv
        self.single_observation_space = venv.single_observation_space
        self.single_action_space = venv.single_action_space
        self.num_agents = venv.num_envs
        self.render_mode = None
        self._seed = seed
        super().__init__(buf)

    def reset(self, seed: int | None = None) -> tuple[np.ndarray, list[dict[str, Any]]]:
        first = self._seed if seed is None else seed
        self._seed = None  # the constructor's seed seeds the first reset only
        obs, _ = self.venv.reset(
            seed=None if first is None else [int(first) + i for i in range(self.num_agents)])
        self.observations[:] = obs
        self.rewards[:] = 0.0
        self.terminals[:] = False
        self.truncations[:] = False
        return self.observations, []

    def step(self, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                   list[dict[str, Any]]]:
        obs, rewards, terminated, truncated, _ = self.venv.step(actions)
        done = terminated | truncated
        if done.any():
            obs, _ = self.venv.restart(done)
        self.observations[:] = obs
        self.rewards[:] = rewards
        self.terminals[:] = terminated
        self.truncations[:] = truncated
        return self.observations, self.rewards, self.terminals, self.truncations, []

    def close(self) -> None:
        self.venv.close()
