"""Many copies of one environment, stepped together in the compiled core.

:class:`EquilibristVectorEnv` is what ``gymnasium.make_vec(id, num_envs=N,
vectorization_mode="vector_entry_point")`` builds. One call of the core
steps every copy (OpenMP threads over as many blocks of copies as
threads, or one thread: see ``PROBE_EVERY``); Python does the same fixed
amount of work whatever the number of copies. Every step returns fresh
arrays, as Gymnasium's own vector environments do.

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

With a rig (the option ``rig``), each copy steps the loop ``simulate`` runs
with that rig (:class:`~equilibrist.envs.rig_episode.RigEpisode`), one copy after
the other in Python: copy ``i`` is the single environment reset with
``seed + i`` (or ``seeds[i]``), the same numbers, and its ``noise_seed``
(in the reset's info) is the integer ``simulate(..., seed=...)`` takes.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from equilibrist.envs.core import Core, EnvError, as_actions
from equilibrist.envs.env import Renderer, _spaces, open_core
from equilibrist.envs.rig_episode import RigEpisode
from equilibrist.sim.steps import EnvSteps

# Fewer copies than this step on one thread: starting a parallel region
# (waking the other threads and waiting for them) costs more than it saves.
PARALLEL_MIN = 256
# From PARALLEL_MIN copies up, a step now and then runs the other way (one
# thread or all: a probe), and the faster of the two steps the others: the
# way in use by the moving average of its times per step (weight SMOOTHING
# for the newest, every time counted whole: on a busy machine a parallel
# step is fast most of the time and now and then waits a whole time slice
# for a descheduled thread, and its cost is the mean of both), the other by
# its last probe. A probe is PROBE_STEPS steps, the best of all but
# the first counted (the first wakes threads that went to sleep; one step
# can be slowed by a moment's interruption). On a machine whose other
# cores are taken, the parallel step waits for descheduled threads and can
# run many times slower than one thread. Probes come every PROBE_EVERY
# steps at first; each probe that finds the other way slower doubles the
# interval, up to PROBE_EVERY_MAX steps, and a switch, or the way in use
# growing RESLOWED times slower than at the last probe, starts again from
# PROBE_EVERY. Probes come rarer still when the other way is much slower,
# so that they take at most about 1 / PROBE_SHARE of the time: the next probe
# waits PROBE_SHARE times the whole last probe (every one of its steps, the
# first too: on a busy machine a parallel step that waits for a descheduled
# thread takes a whole time slice, some milliseconds), in steps of the way
# in use, and so does a probe that a slower step calls early. A way taken at
# a probe's word that proves slower in use than the way it left (the probe's
# few steps missed its slow ones) is left, and the next probe waits twice as
# long as after the last such one (up to PROBE_EVERY_MAX), until a way so
# taken holds that long. Of the steps between probes, one in TIME_EVERY is
# timed.
TIME_EVERY = 4
# A probe whose first step takes PROBE_GIVE_UP times a step of the way in use, and at
# least PROBE_GIVE_UP_S seconds, ends there (that step is its time): waking the other
# threads costs microseconds; a step that waits for a descheduled one, a time slice.
PROBE_GIVE_UP = 20.0
PROBE_GIVE_UP_S = 1e-3
PROBE_EVERY = 50
PROBE_EVERY_MAX = 1600
RESLOWED = 1.5
PROBE_STEPS = 3
PROBE_SHARE = 20.0
SMOOTHING = 0.25
_F64 = np.dtype(np.float64)
# Looked up once: a step of few copies takes a few microseconds in all.
_copyto = np.copyto


def _chunks() -> int:
    """Blocks of copies a parallel step runs: the thread count (``set_workers``, else the
    CPU count)."""
    from equilibrist.sim.kernel import thread_count

    return thread_count()


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
        render_mode: str | None = None,
        **options: object,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, int | np.integer) or num_envs < 1:
            raise EnvError(f"num_envs must be a whole number >= 1, got {num_envs!r}")
        # Copies are stepped eight at a time where there are eight (native/lanes.py).
        core, modes = open_core(system, task, options, render_mode, ("rgb_array",),
                                "a vector environment", lanes=num_envs >= 8)
        self.core = core
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        self.metadata = {**type(self).metadata, "render_fps": core.rate, "render_modes": modes}
        self.single_action_space, self.single_observation_space = _spaces(core)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        N, m = self.num_envs, core.system.n_inputs
        # Every copy's row of the compiled step's arrays (see _core.Core.rows).
        self._fs, self._us = core.rows(N)
        self._actions = np.zeros((N, m))
        self._seeded = False
        chunks = _chunks()
        #: Whether steps may run on several threads (from PARALLEL_MIN copies up).
        self.parallel = N >= PARALLEL_MIN and chunks > 1
        self._ci = core.settings(chunks=chunks, autoreset=True)
        self._cf = core.cf
        # The compiled steps bound to the copies' rows: one thread, then parallel.
        self._steps = EnvSteps(core.kernel, self._fs, self._us, self._cf, self._ci, core.n_obs)
        steps = self._steps
        #: The two ways of a step: one thread, all (each returns the count of bad actions).
        self._ways: list[Callable[[], int]] = [lambda: steps.step_many(1),
                                               lambda: steps.step_many(chunks)]
        self._mode = int(self.parallel)
        self._cost = [math.inf, math.inf]  # seconds per step, moving averages
        self._countdown = 0  # steps before the next probe
        self._untimed = 0  # steps before the next timed one
        self._probe_best = math.inf  # the best time of the probe under way
        self._probe_spent = 0.0  # the whole time of the probe under way
        self._probe_wait = PROBE_EVERY  # steps the last probe's cost asks to wait
        self._interval = PROBE_EVERY  # steps between probes, doubled while they confirm the way
        self._at_probe = math.inf  # the way in use's time per step at the last probe
        self._probed_in = False  # whether the way in use was taken at a probe's word
        self._misled = PROBE_EVERY  # steps before probing again after a probe misled us
        self._held = 0  # steps the way taken at a probe's word has held
        self._probe_left = 0  # steps left of the probe under way
        self._step_fn: list[Callable[[], int]] | None = None
        self._ashape = (N, m)
        self._obs_shape = (N, core.n_obs)
        self._flags_shape = (2, N)
        self._renderer = Renderer(core, "rgb_array") if render_mode is not None else None
        self._learnable = core.learnable
        # The copies whose episode ended at the last step (this step restarts them), or None.
        self._due: np.ndarray | None = None
        #: The copies' episodes through the rig (a rig's environment steps them instead).
        self._rig = _RigCopies(core, self._fs, self._us) if core.rig is not None else None

    # -- state of the copies ---------------------------------------------------------
    @property
    def states(self) -> np.ndarray:
        """The true states of the copies now, ``(num_envs, n_states)`` (a copy)."""
        return self.core.state_of(self._fs).copy()

    @property
    def parameters(self) -> np.ndarray:
        """Each copy's parameter vector, ``(num_envs, n_params)`` (a copy)."""
        return self.core.params_of(self._fs).copy()

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
        self._us[:, :4] = words
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
            if self._rig is not None:
                self._rig.seed(seed)
        if self._rig is not None:
            self._step_fn = self._ways
            self._due = None
            obs = self._rig.start(np.ones(self.num_envs, dtype=np.bool_))
            return self._observed(obs), self._rig.info(np.ones(self.num_envs, dtype=np.bool_))
        obs = self._steps.reset_many()
        self._step_fn = self._ways  # set, it also says reset was called
        self._due = None
        return self._observed(obs), self._reset_info(np.ones(self.num_envs, dtype=np.bool_))

    def restart(self, mask: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
        """Start the copies *mask* now (those whose episode ended at the last step), each
        from its own generator as its next step would: every copy's observation (the
        others' as the last step gave them) and the restarted copies' info. A trainer
        that resets in the step that ends an episode (Stable-Baselines3) calls it."""
        if self._step_fn is None:
            raise EnvError("call reset() before restart()")
        rows = np.flatnonzero(mask)
        if self._rig is not None:
            obs = self._rig.start(np.asarray(mask, bool))
        else:
            self._steps.reset_rows(rows)
            obs = self._steps.obs.copy()
        if self._due is not None:
            self._due[rows] = False
            if not self._due.any():
                self._due = None
        if self._rig is not None:
            return self._observed(obs), self._rig.info(np.asarray(mask, bool))
        return self._observed(obs), self._reset_info(np.asarray(mask, bool))

    def _reset_info(self, mask: np.ndarray) -> dict[str, Any]:
        """The info of the copies *mask* that (re)started, with Gymnasium's ``_key`` masks:
        the true start ``state`` and ``noise_seed``, the copy's generator's four words
        after its start was drawn (the stream its episode's noise comes from)."""
        return {"state": self.states, "_state": mask.copy(),
                "noise_seed": self._us[:, :4].copy(), "_noise_seed": mask.copy()}

    def _observed(self, obs: np.ndarray) -> np.ndarray:
        """The observations an agent gets of the core's *obs* (scaled from version 1 on)."""
        if self._learnable is not None:
            return self._learnable.observe(obs)
        if self.core.dtype is not _F64:
            return obs.astype(self.core.dtype)
        return obs

    def step(
        self, actions: object
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """One control period of every copy (next-step autoreset)."""
        step = self._step_fn
        if step is None:
            raise EnvError("call reset() before step()")
        a = as_actions(actions, self._ashape, self.core, "actions")
        if self._rig is not None:
            return self._rig_step(a)
        steps = self._steps
        _copyto(steps.a, a)
        if self.parallel:
            if self._untimed > 0:  # most steps: the way in use, not timed
                self._untimed -= 1
                bad = self._ways[self._mode]()
            else:
                bad = self._timed_step()
        else:
            bad = self._ways[0]()
        if bad:
            raise EnvError("an action is not a finite number (no copy was stepped)")
        if self._renderer is not None:
            self._actions = a.copy()
        # Fresh arrays every step, as Gymnasium's own vector environments return.
        flags = steps.flags.copy()
        # One test a step when no copy ends (a step of 16 copies takes microseconds).
        restarted = self._due
        self._due = flags[0] | flags[1] if flags.any() else None
        info: dict[str, Any] = {} if restarted is None else self._reset_info(restarted)
        learn = self._learnable
        if learn is None:
            obs = steps.obs.copy() if self.core.dtype is _F64 else steps.obs.astype(self.core.dtype)
            return obs, steps.rewards.copy(), flags[0], flags[1], info
        rewards = learn.reward(self.core.state_of(self._fs), self.core.physical_input(a))
        if restarted is not None:
            rewards[restarted] = 0.0
        return learn.observe(steps.obs), rewards, flags[0], flags[1], info

    def _rig_step(self, a: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """:meth:`step` through the rig: every copy's episode a sample, those whose episode
        ended at the last step restarted instead (reward 0, their action ignored)."""
        assert self._rig is not None
        if not np.all(np.isfinite(a)):
            raise EnvError("an action is not a finite number (no copy was stepped)")
        if self._renderer is not None:
            self._actions = a.copy()
        restarted = self._due
        obs, rewards, flags = self._rig.step(a, restarted)
        self._due = flags[0] | flags[1] if flags.any() else None
        info: dict[str, Any] = {} if restarted is None else self._rig.info(restarted)
        learn = self._learnable
        if learn is None:
            return self._observed(obs), rewards, flags[0], flags[1], info
        rewards = learn.reward(self.core.state_of(self._fs), self._rig.acted)
        if restarted is not None:
            rewards[restarted] = 0.0
        return learn.observe(obs), rewards, flags[0], flags[1], info

    def _timed_step(self) -> int:
        """A step on one thread or on all, whichever has been faster lately
        (see ``PROBE_EVERY``); both give the same numbers."""
        cost = self._cost
        mode = self._mode
        if self._probe_left == 0 and self._countdown > 0 and cost[1 - mode] != math.inf:
            # A step of the way in use, timed into its moving average; the
            # next TIME_EVERY - 1 are not (timing costs about a microsecond of
            # Python, 5 % of a step of 256 copies).
            self._countdown -= TIME_EVERY
            self._held += TIME_EVERY
            self._untimed = TIME_EVERY - 1
            start = time.perf_counter()
            bad = self._ways[mode]()
            spent = time.perf_counter() - start
            average = cost[mode]
            average = SMOOTHING * spent + (1.0 - SMOOTHING) * average
            cost[mode] = average
            if average > RESLOWED * self._at_probe or average > cost[1 - mode]:
                self._changed(mode)
            return int(bad)
        # A probe: the other way, for PROBE_STEPS steps, the best of all but the
        # first counted. Also how each way gets its first time, the other way first.
        first = self._probe_left == 0
        if first:
            self._probe_left = PROBE_STEPS
            self._probe_best = math.inf
            self._probe_spent = 0.0
        self._probe_left -= 1
        mode = 1 - mode
        start = time.perf_counter()
        bad = self._ways[mode]()
        spent = time.perf_counter() - start
        self._probe_spent += spent
        if not first:
            self._probe_best = min(self._probe_best, spent)
        elif spent > max(PROBE_GIVE_UP * cost[1 - mode], PROBE_GIVE_UP_S):
            # The other cores are taken (a whole time slice, not a wake-up): the probe
            # ends at its first step, which counts.
            self._probe_best, self._probe_left = spent, 0
        if self._probe_left > 0:
            return int(bad)
        cost[mode] = self._probe_best  # the best of the probe's timed steps
        if math.inf in cost:
            self._mode = mode  # the only way timed so far
            return int(bad)
        before = self._mode
        self._mode = 0 if cost[0] < cost[1] else 1
        if self._mode != before:
            self._probed_in, self._held = True, 0  # on trial
        elif self._probed_in and self._held >= self._misled:
            # The way a probe chose held as long as the last misleading one took to unmask.
            self._probed_in, self._misled = False, PROBE_EVERY
        self._interval = min(2 * self._interval, PROBE_EVERY_MAX) \
            if self._mode == before else PROBE_EVERY
        self._at_probe = cost[self._mode]
        # The probe's whole time, PROBE_SHARE times over, in steps of the way in use.
        self._probe_wait = int(PROBE_SHARE * self._probe_spent / max(cost[self._mode], 1e-12))
        self._countdown = max(self._interval, self._probe_wait)
        return int(bad)

    def _changed(self, mode: int) -> None:
        """The way in use got slower than at the last probe, or than the other way
        was then: switch if the other way was faster, and probe again soon."""
        cost = self._cost
        misled = False
        if cost[mode] > cost[1 - mode]:
            # Taken at a probe's word and found slower in use than the way it left: the
            # probe's few steps missed what this way costs on the whole (on a busy machine,
            # fast steps and, now and then, a whole time slice waiting for a thread).
            misled = self._probed_in
            self._mode = 1 - mode
        self._probed_in = False
        self._at_probe = math.inf
        if misled:
            # Not soon: each time a probe misleads, twice as long before the next.
            self._misled = min(2 * self._misled, PROBE_EVERY_MAX)
            self._interval = self._misled
            self._countdown = max(self._misled, self._probe_wait)
            return
        self._interval = PROBE_EVERY
        # Soon, but not sooner than the last probe's cost allows.
        self._countdown = min(self._countdown, max(PROBE_EVERY, self._probe_wait))

    @property
    def threads_in_use(self) -> int:
        """How many threads the next step runs on (1, or the core's thread count)."""
        return _chunks() if self.parallel and self._mode == 1 else 1

    def render(self) -> tuple[np.ndarray, ...] | None:
        """Every copy's picture (``rgb_array``), as the single environment draws it."""
        if self._renderer is None:
            raise EnvError("render() needs render_mode='rgb_array'")
        core = self.core
        states = core.state_of(self._fs)
        return tuple(
            self._renderer.frame(states[i], core.physical_input(self._actions[i]),
                                 float(self._us[i, 4]) / core.rate)
            for i in range(self.num_envs)
        )

    def close_extras(self, **kwargs: object) -> None:
        if self._renderer is not None:
            self._renderer.close()


class _RigCopies:
    """The copies of a vector environment with a rig: each its own generator and
    :class:`~equilibrist.envs.rig_episode.RigEpisode`, the single environment's, stepped in turn;
    their states, parameters and periods taken written into the copies' rows."""

    def __init__(self, core: Core, fs: np.ndarray, us: np.ndarray) -> None:
        self.core, self._fs, self._us = core, fs, us
        n = len(fs)
        self._generators = [seeding.np_random(None)[0] for _ in range(n)]
        self._episodes: list[RigEpisode | None] = [None] * n
        self._noise_seeds = np.zeros(n, dtype=np.int64)
        self.acted = np.zeros((n, core.system.n_inputs))

    def seed(self, seed: int | Sequence[int] | None) -> None:
        """Copy ``i``'s generator: the single environment's of ``seed + i`` (or ``seed[i]``)."""
        n = len(self._fs)
        if seed is None:
            seeds: list[int | None] = [None] * n
        elif isinstance(seed, int | np.integer):
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = [int(s) for s in seed]
        self._generators = [seeding.np_random(s)[0] for s in seeds]

    def start(self, mask: np.ndarray) -> np.ndarray:
        """Start the copies *mask* from their generators; every copy's observation."""
        core = self.core
        for i in np.flatnonzero(mask):
            x0, p, noise_seed = core.draw_episode(self._generators[i])
            self._episodes[i] = RigEpisode(core, x0, p, noise_seed)
            self._noise_seeds[i] = noise_seed
            core.params_of(self._fs)[i] = p
            self._write(int(i))
        return self._observations()

    def _write(self, i: int) -> None:
        episode = self._episodes[i]
        assert episode is not None
        self.core.state_of(self._fs)[i] = episode.x
        self._us[i, 4] = episode.k
        self.acted[i] = episode.acted

    def _observations(self) -> np.ndarray:
        return np.array([e.observation() for e in self._episodes if e is not None])

    def info(self, mask: np.ndarray) -> dict[str, Any]:
        """The restarted copies' start ``state`` and ``noise_seed``, with Gymnasium's masks."""
        return {"state": self.core.state_of(self._fs).copy(), "_state": mask.copy(),
                "noise_seed": self._noise_seeds.copy(), "_noise_seed": mask.copy()}

    def step(self, a: np.ndarray, restarted: np.ndarray | None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every copy a period with the actions *a* (the copies *restarted* start again):
        the observations, the rewards and the flags (terminated, truncated)."""
        n = len(self._fs)
        rewards = np.zeros(n)
        flags = np.zeros((2, n), dtype=np.bool_)
        again = np.zeros(n, dtype=np.bool_) if restarted is None else restarted
        u = self.core.physical_input(a)
        for i in range(n):
            if again[i]:
                continue
            episode = self._episodes[i]
            assert episode is not None
            rewards[i], status = episode.step(u[i])
            self._write(i)
            if status:
                flags[status - 1, i] = True
        if again.any():
            self.start(again)
        return self._observations(), rewards, flags


__all__ = ["EquilibristVectorEnv"]
