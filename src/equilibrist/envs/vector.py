"""Many copies of one environment, stepped together in the compiled core.

:class:`EquilibristVectorEnv` is what ``gymnasium.make_vec(id, num_envs=N,
vectorization_mode="vector_entry_point")`` builds. One call of the core
steps every copy (``numba.prange`` over blocks of copies, on every core);
Python does the same fixed amount of work whatever the number of copies.

Autoreset follows Gymnasium 1.x's default (next step): the step that ends
a copy's episode returns its last observation with ``terminated`` or
``truncated`` set; the copy's next step ignores its action, resets it and
returns its first observation with reward 0.

Seeding: ``reset(seed=s)`` gives copy ``i`` the ``i``-th four words of
``numpy.random.SeedSequence(s).generate_state(4 * num_envs, uint64)`` as
the state of its own xoshiro256** generator (a list of seeds gives copy
``i`` the first four words of ``SeedSequence(seeds[i])``). That generator
draws, at every reset of the copy, its initial state and its randomized
parameters, then the noise of its episode. ``reset()`` without a seed
continues every copy's stream.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from equilibrist.envs._core import EnvError, build_core
from equilibrist.envs.env import Renderer, _spaces, drawing_problem
from equilibrist.errors import DimensionError

# Fewer copies than this step on one thread: starting a parallel region
# (waking the other threads and waiting for them) costs more than it saves.
PARALLEL_MIN = 256


def _chunks() -> int:
    import numba

    return int(numba.get_num_threads())


class EquilibristVectorEnv(VectorEnv[np.ndarray, np.ndarray, np.ndarray]):
    """*num_envs* copies of one system and task (options as :class:`~equilibrist.envs.EquilibristEnv`).

    The copies share the system, the task and the options; each has its own
    generator, so its starts, randomized parameters and noise are its own.
    """

    metadata: dict[str, Any] = {  # noqa: RUF012 - Gymnasium's class attribute
        "render_modes": ["rgb_array"], "render_fps": 50, "autoreset_mode": AutoresetMode.NEXT_STEP,
    }

    def __init__(
        self,
        num_envs: int = 1,
        system: object = None,
        task: str = "balance",
        *,
        params: Mapping[str, object] | None = None,
        rate: float | None = None,
        physics_step: float | None = None,
        observe: str = "outputs",
        noise: bool = True,
        randomize: Mapping[str, object] | None = None,
        action_units: str = "normalized",
        alive_bonus: float = 1.0,
        render_mode: str | None = None,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer) or num_envs < 1:
            raise EnvError(f"num_envs must be a whole number >= 1, got {num_envs!r}")
        if render_mode not in (None, "rgb_array"):
            raise EnvError(f"render_mode={render_mode!r}: a vector environment renders 'rgb_array' only")
        core = build_core(
            system, task, params=params, rate=rate, physics_step=physics_step, observe=observe,
            noise=noise, randomize=randomize, action_units=action_units, alive_bonus=alive_bonus,
        )
        no_drawing = drawing_problem(core)
        if render_mode is not None and no_drawing is not None:
            raise EnvError(f"render_mode={render_mode!r}: {no_drawing}")
        self.core = core
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": core.rate,
                         "render_modes": [] if no_drawing else ["rgb_array"]}
        self.single_action_space, self.single_observation_space = _spaces(core)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        N, m = self.num_envs, core.system.n_inputs
        self._xs = np.tile(np.asarray(core.task.start, dtype=float), (N, 1))
        self._ps = np.tile(core.p_nom, (N, 1))
        self._rngs = np.zeros((N, 4), dtype=np.uint64)
        self._ks = np.zeros(N, dtype=np.int64)
        self._erefs = np.zeros((N, 2))
        self._auto = np.zeros(N, dtype=np.bool_)
        self._obs = np.zeros((N, core.n_obs))
        self._actions = np.zeros((N, m))
        self._seeded = False
        self._ready = False
        ei = core.with_chunks(_chunks())
        self._ei = ei
        self._start = np.ascontiguousarray(core.task.start, dtype=float)
        self._spread = np.ascontiguousarray(core.task.spread, dtype=float)
        parallel = self.num_envs >= PARALLEL_MIN and int(ei[5]) > 1
        self._step_fn = core.kernel.env_step_many if parallel else core.kernel.env_step_serial
        self._step_consts = (ei, core.ef, core.c_idx, core.lv, core.lw, core.region, core.op,
                             core.sc, core.hang, self._start, self._spread, core.p_nom,
                             core.rnd_idx, core.rnd_spread)
        self._ashape = (N, m)
        self._renderer = Renderer(core, "rgb_array") if render_mode is not None else None

    # -- state of the copies ---------------------------------------------------------
    @property
    def states(self) -> np.ndarray:
        """The true states of the copies now, ``(num_envs, n_states)`` (a copy)."""
        return self._xs.copy()

    @property
    def parameters(self) -> np.ndarray:
        """Each copy's parameter vector, ``(num_envs, n_params)`` (a copy)."""
        return self._ps.copy()

    def _seed(self, seed: int | Sequence[int] | None) -> None:
        N = self.num_envs
        if seed is None:
            words = np.random.SeedSequence().generate_state(4 * N, np.uint64).reshape(N, 4)
        elif isinstance(seed, int | np.integer) and not isinstance(seed, bool):
            if seed < 0:
                raise EnvError(f"seed {seed!r} must be a non-negative integer")
            words = np.random.SeedSequence(int(seed)).generate_state(4 * N, np.uint64).reshape(N, 4)
        else:
            seeds = list(seed)  # type: ignore[arg-type]
            if len(seeds) != N or not all(
                isinstance(s, int | np.integer) and not isinstance(s, bool) and s >= 0 for s in seeds
            ):
                raise EnvError(
                    f"seed: expected one non-negative integer, or a list of {N} of them, got {seed!r}"
                )
            words = np.array(
                [np.random.SeedSequence(int(s)).generate_state(4, np.uint64) for s in seeds]
            )
        words[~words.any(axis=1), 0] = np.uint64(1)  # xoshiro's one forbidden state
        self._rngs[:] = words
        self._seeded = True

    def reset(
        self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset every copy (see the module's notes on seeding)."""
        if options:
            raise EnvError(f"reset options: none are taken, got {sorted(options)}")
        if seed is not None or not self._seeded:
            first = seed if isinstance(seed, int | np.integer) or seed is None else None
            self._np_random, self._np_random_seed = seeding.np_random(
                None if first is None else int(first)
            )
            self._seed(seed)
        core = self.core
        mask = np.ones(self.num_envs, dtype=np.bool_)
        obs = np.empty((self.num_envs, core.n_obs))
        core.kernel.env_reset_many(mask, self._xs, self._ps, self._rngs, self._ks, self._erefs, obs,
                                   self._ei, core.c_idx, core.lv, self._start, self._spread,
                                   core.p_nom, core.rnd_idx, core.rnd_spread, core.op)
        self._auto[:] = False
        self._ready = True
        return obs, {"state": self._xs.copy()}

    def step(
        self, actions: object
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """One control period of every copy (next-step autoreset)."""
        if not self._ready:
            raise EnvError("call reset() before step()")
        a = np.asarray(actions, dtype=np.float64)
        if a.shape != self._ashape:
            if a.size != self._ashape[0] * self._ashape[1]:
                raise DimensionError(
                    f"actions have shape {a.shape}, expected {self._ashape} (num_envs, inputs)"
                )
            a = a.reshape(self._ashape)
        if not np.isfinite(a).all():
            raise EnvError("an action is not a finite number")
        N = self.num_envs
        obs = np.empty((N, self.core.n_obs))
        rewards = np.empty(N)
        terminated = np.empty(N, dtype=np.bool_)
        truncated = np.empty(N, dtype=np.bool_)
        if self._renderer is not None:
            self._actions = a.copy()
        self._step_fn(a, self._xs, self._ps, self._rngs, self._ks, self._erefs, self._auto, obs,
                      rewards, terminated, truncated, *self._step_consts)
        return obs, rewards, terminated, truncated, {}

    def render(self) -> tuple[np.ndarray, ...] | None:
        """Every copy's picture (``rgb_array``), as the single environment draws it."""
        if self._renderer is None:
            raise EnvError("render() needs render_mode='rgb_array'")
        core = self.core
        return tuple(
            self._renderer.frame(self._xs[i], core.physical_input(self._actions[i]),
                                 float(self._ks[i]) / core.rate)
            for i in range(self.num_envs)
        )

    def close_extras(self, **kwargs: Any) -> None:
        if self._renderer is not None:
            self._renderer.close()


__all__ = ["EquilibristVectorEnv"]
