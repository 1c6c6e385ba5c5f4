"""Stable-Baselines3's vector environment over the native one: many copies, one call.

:func:`sb3_vec_env` makes an :class:`EquilibristVectorEnv` of an id and wraps
it as Stable-Baselines3's ``VecEnv``, so that PPO, SAC and the rest step every
copy in one call of the compiled core instead of one Python environment after
another (``DummyVecEnv``)::

    from stable_baselines3 import PPO
    from equilibrist.envs.sb3 import sb3_vec_env

    env = sb3_vec_env("equilibrist/cartpole-balance-v1", num_envs=8, seed=0)
    model = PPO("MlpPolicy", env).learn(100_000)

Stable-Baselines3 resets a copy in the step that ends its episode: that step
returns the copy's first observation of the next episode, and its info the
last one (``terminal_observation``) and whether the time ran out
(``TimeLimit.truncated``); the copy is restarted from its own generator, as
the native environment's next step would restart it, so that its episodes are
the native environment's. ``seed(s)`` (Stable-Baselines3's) gives copy ``i``
the seed ``s + i`` at the next reset. Wrap it in ``VecMonitor`` for the
episodes' returns in the logs.

Needs the ``rl`` extra (``pip install 'equilibrist[rl]'``).
"""

from __future__ import annotations

import importlib.util
from collections.abc import Sequence
from typing import Any

import numpy as np

from equilibrist.envs.core import EnvError
from equilibrist.errors import EquilibristError


class MissingRLError(EquilibristError, ImportError):
    """Stable-Baselines3 (the ``rl`` extra) is not installed."""


if importlib.util.find_spec("stable_baselines3") is None:
    raise MissingRLError(
        "equilibrist's trainers' adapters need Stable-Baselines3 and PyTorch: "
        "pip install 'equilibrist[rl]'"
    )

import gymnasium as gym  # noqa: E402
from stable_baselines3.common.vec_env.base_vec_env import (  # noqa: E402
    VecEnv,
    VecEnvIndices,
    VecEnvStepReturn,
)

from equilibrist.envs.vector import EquilibristVectorEnv  # noqa: E402


class EquilibristSB3VecEnv(VecEnv):
    """An :class:`EquilibristVectorEnv` as Stable-Baselines3's ``VecEnv`` (see the module)."""

    def __init__(self, venv: EquilibristVectorEnv) -> None:
        if not isinstance(venv, EquilibristVectorEnv):
            raise EnvError(f"expected an EquilibristVectorEnv, got {type(venv).__name__}")
        self.venv = venv
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self._actions: np.ndarray | None = None
        self._started = False

    def reset(self) -> np.ndarray:
        seeds = self._seeds
        seed = None if all(s is None for s in seeds) else [int(s or 0) for s in seeds]
        obs, info = self.venv.reset(seed=seed)
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = [{"state": info["state"][i]} for i in range(self.num_envs)]
        self._started = True
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        if self._actions is None or not self._started:
            raise EnvError("call reset() before step()")
        obs, rewards, terminated, truncated, _ = self.venv.step(self._actions)
        done = terminated | truncated
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if done.any():
            for i in np.flatnonzero(done).tolist():
                infos[i]["terminal_observation"] = obs[i]
                infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            obs, info = self.venv.restart(done)
            for i in np.flatnonzero(done).tolist():
                self.reset_infos[i] = {"state": info["state"][i]}
        return obs, rewards.astype(np.float32), done, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The vector environment's attribute, once per copy asked for (they share it)."""
        return [getattr(self.venv, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> list[Any]:
        method = getattr(self.venv, method_name)
        return [method(*method_args, **method_kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper],
                       indices: VecEnvIndices = None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        frames = self.venv.render()
        return list(frames) if frames is not None else [None] * self.num_envs


def sb3_vec_env(env_id: str, num_envs: int = 8, *, seed: int | None = None,
                **options: Any) -> EquilibristSB3VecEnv:
    """*num_envs* copies of the environment *env_id* (with *options*) as a ``VecEnv``;
    *seed* seeds copy ``i`` with ``seed + i`` at the first reset."""
    venv = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        **options)
    if not isinstance(venv, EquilibristVectorEnv):
        raise EnvError(f"{env_id} is not an equilibrist environment")
    out = EquilibristSB3VecEnv(venv)
    if seed is not None:
        out.seed(seed)
    return out


__all__ = ["EquilibristSB3VecEnv", "MissingRLError", "sb3_vec_env"]
