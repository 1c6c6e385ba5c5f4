"""One Gymnasium environment of one system and task.

See :mod:`equilibrist.envs` for the contract (spaces, step, reward,
seeding); this module is its single-copy implementation.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from equilibrist.control.checks import given_text, real_array
from equilibrist.envs.core import (
    FINITE,
    OPTION_DEFAULTS,
    Core,
    EnvError,
    as_actions,
    build_core,
)
from equilibrist.envs.rig_episode import RigEpisode
from equilibrist.errors import DimensionError, nearest
from equilibrist.sim.noise import generator_state
from equilibrist.sim.steps import EnvSteps

if TYPE_CHECKING:
    from matplotlib.figure import Figure
    from matplotlib.image import AxesImage

    from equilibrist.viz.frames import FrameRenderer

_F64 = np.dtype(np.float64)
# Backends of matplotlib that draw to files only.
_FILE_BACKENDS = frozenset({"agg", "pdf", "ps", "svg", "pgf", "cairo", "template"})


def display_problem() -> str | None:
    """Why no window can be opened here, or None when one can."""
    if sys.platform.startswith("linux") and not (
        os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    ):
        return "this machine has no display (DISPLAY and WAYLAND_DISPLAY are not set)"
    backend = os.environ.get("MPLBACKEND", "").lower()
    if backend in _FILE_BACKENDS:
        return f"matplotlib's backend is {backend!r} (MPLBACKEND), which draws to files only"
    return None


def drawing_problem(core: Core) -> str | None:
    """Why *core*'s system can not be drawn, or None when it can."""
    from equilibrist.errors import UnknownNameError
    from equilibrist.viz.scenes import scene_for

    try:
        scene_for(core.system)
    except UnknownNameError as exc:
        return str(exc)
    return None


def _spaces(core: Core) -> tuple[spaces.Box, spaces.Box]:
    m = core.system.n_inputs
    dtype = core.dtype.type
    if core.action_units == "physical":
        lo, hi = core.limits
        action = spaces.Box(lo.astype(dtype), hi.astype(dtype), (m,), dtype)
    else:
        action = spaces.Box(-1.0, 1.0, (m,), dtype)
    # Half the largest number of the type: any finite value, and sample() does not overflow.
    bound = FINITE if dtype is np.float64 else float(np.finfo(dtype).max) / 2
    observation = spaces.Box(-bound, bound, (len(core.agent_observation_names),), dtype)
    return action, observation


def open_core(system: object, task: str, options: Mapping[str, Any], render_mode: str | None,
              modes: tuple[str, ...], what: str, *, lanes: bool = False) -> tuple[Core, list[str]]:
    """The core of an environment's options, and the render modes it offers.

    The single and the vector environment both start here. *modes* are the
    render modes the kind of environment *what* has; of those, a system
    without a drawing offers none, and ``"human"`` only where a window can
    open. Every option is checked (unknown ones too, with their nearest
    names) and reported in one :class:`EnvError`.
    """
    if render_mode is not None and render_mode not in modes:
        raise EnvError(
            f"render_mode={render_mode!r}: {what} renders {' or '.join(map(repr, modes))}"
        )
    unknown = [k for k in options if k not in OPTION_DEFAULTS]
    if unknown:
        known = tuple(OPTION_DEFAULTS)
        raise EnvError("; ".join(
            f"unknown option {k!r} ({nearest(k, known)})" for k in unknown
        ))
    core = build_core(system, task, **{**OPTION_DEFAULTS, **options}, lanes=lanes)
    no_drawing = drawing_problem(core)
    no_window = display_problem() if "human" in modes else None
    if render_mode is not None and no_drawing is not None:
        raise EnvError(f"render_mode={render_mode!r}: {no_drawing}")
    if render_mode == "human" and no_window is not None:
        raise EnvError(
            f"render_mode='human' opens a window, but {no_window}: use render_mode='rgb_array'"
        )
    offered = [] if no_drawing else [m for m in modes if m != "human" or no_window is None]
    return core, offered


class Renderer:
    """Frames of an environment: the animations' drawing of the state and input."""

    def __init__(self, core: Core, mode: str) -> None:
        self.core = core
        self.mode = mode
        self._frames: FrameRenderer | None = None
        self._window: tuple[Figure, AxesImage] | None = None

    def _extent_states(self) -> np.ndarray:
        core = self.core
        rows = [core.task.start, core.task.x_op]
        for i in range(core.system.n_states):
            for bound in core.region[:, i]:
                if np.isfinite(bound):
                    row = np.array(core.task.x_op, dtype=float)
                    row[i] = bound
                    rows.append(row)
        return np.array(rows, dtype=float)

    def frame(self, x: np.ndarray, u: np.ndarray | None, t: float) -> np.ndarray:
        if self._frames is None:
            from equilibrist.viz.frames import FrameRenderer

            self._frames = FrameRenderer(self.core.system, states=self._extent_states())
        return self._frames.frame(x, u, t=t)

    def show(self, x: np.ndarray, u: np.ndarray | None, t: float) -> None:
        import matplotlib.pyplot as plt

        image = self.frame(x, u, t)
        if self._window is None or not plt.fignum_exists(self._window[0].number):
            fig, ax = plt.subplots()
            ax.set_axis_off()
            fig.subplots_adjust(0, 0, 1, 1)
            self._window = (fig, ax.imshow(image))
            plt.show(block=False)
        else:
            self._window[1].set_data(image)
        plt.pause(self.core.period)

    def close(self) -> None:
        if self._window is not None:
            import matplotlib.pyplot as plt

            plt.close(self._window[0])
            self._window = None
        self._frames = None


class EquilibristEnv(gym.Env[np.ndarray, np.ndarray]):
    """A system and a task as a Gymnasium environment (see :mod:`equilibrist.envs`).

    Parameters
    ----------
    system : str or System
        A catalogue name, the path of a model file (``"robot.xml"``) or a
        bound :class:`~equilibrist.numeric.system.System`.
    task : {"balance", "swingup"}
    render_mode : {"rgb_array", "human"}, optional

    Other Parameters
    ----------------
    params : mapping, optional
        Parameter values (``{"m_p": 2.0}``).
    rate : float, optional
        Control rate [Hz]: one step is one period (default: the task's).
    physics_step : float, optional
        The integrator's step [s]; must divide the period (default: at most 1 ms, or the
        period for an adaptive integrator).
    integrator : str
        A name of :mod:`equilibrist.sim.integrators`' table (default ``"rk4"``; the vector
        environment steps eight copies at once with RK4 only, one at a time otherwise).
    observe : {"outputs", "state"}
        The rig's measured outputs with their sensor noise, or the state.
    noise : bool
        The rig's process and sensor noise (off: a deterministic plant).
    randomize : mapping, optional
        ``{parameter: relative spread}``: each reset draws the parameter
        uniformly within ``value * (1 +- spread)``.
    action_units : {"normalized", "physical"}
        Actions in ``[-1, 1]`` mapped onto the input limits, or the input
        itself bounded by its limits.
    alive_bonus : float
        Balance reward per second inside the region.
    version : {0, 1}
        The task's version: 1 is the learnable form (:mod:`equilibrist.envs.learnable`),
        what the ``-v1`` ids pass.
    dtype : numpy.float32 or numpy.float64, optional
        The spaces' and observations' type (default float64, float32 from version 1).
    at : mapping, optional
        ``{state: value}``: the balance task about the equilibrium with these
        states (its other components solved, as ``design(at=...)``): the
        start, the reward's cost and the region move there, and
        :func:`~equilibrist.envs.expert` designs there. Default: the
        canonical operating point.
    rig : Rig or mapping, optional
        A rig's effects between the plant and the agent
        (:class:`~equilibrist.sim.rig.Rig`, or its options as a mapping:
        ``{"torque_response": 0.5, "measurement_delay": 2}``): each episode
        steps the loop ``simulate`` runs with that rig
        (:class:`~equilibrist.envs.rig_episode.RigEpisode`), and ``simulate(...,
        rig=rig, seed=info["noise_seed"])`` of the same actions is the same
        numbers.

    The options (:data:`~equilibrist.envs.core.OPTION_DEFAULTS`) are the
    vector environment's too; an unknown one is an :class:`EnvError`.
    """

    metadata: dict[str, Any] = {"render_modes": ["rgb_array", "human"], "render_fps": 50}  # noqa: RUF012

    def __init__(
        self,
        system: object = None,
        task: str = "balance",
        *,
        render_mode: str | None = None,
        **options: object,
    ) -> None:
        core, modes = open_core(system, task, options, render_mode, ("rgb_array", "human"),
                                "an environment")
        self.core = core
        self.render_mode = render_mode
        self.metadata = {"render_modes": modes, "render_fps": core.rate}
        self.action_space, self.observation_space = _spaces(core)
        # One row of the compiled step's arrays: this environment is copy 0.
        self._fs, self._us = core.rows(1)
        self._ci = core.settings()
        self._cf = core.cf
        self._steps = EnvSteps(core.kernel, self._fs, self._us, self._cf, self._ci, core.n_obs)
        n, m = core.system.n_states, core.system.n_inputs
        self._x = self._fs[0, :n]  # views of the row
        self._p = self._fs[0, n:n + core.n_params]
        self._u = np.zeros(m)
        self._ready = False
        self._ashape = (m,)
        self._n = n
        self._renderer = Renderer(core, render_mode) if render_mode is not None else None
        self._step_fn: object = None
        self._learnable = core.learnable
        #: The episode through the rig (a rig's environment steps it instead of the core).
        self._episode: RigEpisode | None = None

    # -- the episode --------------------------------------------------------------
    @property
    def state(self) -> np.ndarray:
        """The plant's true state now (a copy)."""
        return self._x.copy()

    @property
    def params(self) -> dict[str, float]:
        """The parameters of this episode (randomized ones drawn at reset)."""
        names = self.core.system.spec.parameter_names
        return dict(zip(names, self._p.tolist(), strict=True))

    @property
    def time(self) -> float:
        """Seconds since the episode began."""
        return float(self._us[0, 4]) / self.core.rate

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode.

        The env's generator (``np_random``, seeded by *seed*) draws, in this
        order: the initial state from the task's distribution, the
        randomized parameters, and the episode's noise seed (an integer,
        returned as ``info["noise_seed"]``: ``simulate(..., seed=...)`` of
        it draws the same noise). ``options={"state": x0}`` starts at *x0*
        instead of a drawn state (the draws are made all the same).
        """
        super().reset(seed=seed)
        core = self.core
        x0, p, noise_seed = core.draw_episode(self.np_random)
        for key in options or {}:
            if key != "state":
                raise EnvError(f"reset options: unknown option {key!r} (expected 'state')")
        if options and "state" in options:
            given, held = real_array(options["state"])
            if given is None or given.size != self._n or not np.all(np.isfinite(given)):
                raise DimensionError(
                    f"reset options: state must be {self._n} finite real numbers "
                    f"({', '.join(core.system.state_names)}), got {given_text(options['state'])}"
                    + (f", which holds {held}" if given is None else "")
                )
            x0 = given.reshape(-1)
        self._x[:] = x0
        self._p[:] = p
        self._us[0, :4] = generator_state(np.random.SeedSequence(noise_seed))
        self._u[:] = core.task.u_op
        if core.rig is not None:
            self._episode = RigEpisode(core, self._x.copy(), p, noise_seed)
            self._us[0, 4] = 0
            obs = self._episode.observation()
        else:
            obs = self._steps.begin_one()
        if self._learnable is not None:
            obs = self._learnable.observe(obs)
        elif core.dtype is not _F64:
            obs = obs.astype(core.dtype)
        self._ready = True
        info: dict[str, object] = {"state": self._x.copy(), "noise_seed": noise_seed}
        if core.randomize:
            names = core.system.spec.parameter_names
            info["params"] = {names[i]: float(self._p[i]) for i in core.rnd_idx}
        if self.render_mode == "human":
            self.render()
        return obs, info

    def step(self, action: object) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """One control period with *action* held; see :mod:`equilibrist.envs`."""
        if not self._ready:
            raise EnvError("call reset() before step()")
        a = as_actions(action, self._ashape, self.core, "action")
        if self._episode is not None:
            return self._rig_step(a)
        steps = self._steps
        steps.a[0] = a
        reward, status = steps.step_one()
        if status == 3:
            raise EnvError(f"action {a.tolist()} is not a finite number")
        learn = self._learnable
        if learn is not None:
            obs = learn.observe(steps.obs[0])
            u = self.core.physical_input(a)
            reward = float(learn.reward(self._x[None, :], u[None, :])[0])
        elif self.core.dtype is _F64:
            obs = steps.obs[0].copy()
        else:
            obs = steps.obs[0].astype(self.core.dtype)
        if self._renderer is not None:
            self._u = self.core.physical_input(a)
            if self.render_mode == "human":
                self.render()
        return obs, reward, status == 1, status == 2, {}

    def _rig_step(self, a: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """:meth:`step` through the rig: the episode's sample with the action's input."""
        episode = self._episode
        assert episode is not None
        if not np.all(np.isfinite(a)):
            raise EnvError(f"action {a.tolist()} is not a finite number")
        u = self.core.physical_input(a)
        reward, status = episode.step(u)
        self._x[:] = episode.x
        self._us[0, 4] = episode.k
        self._u = episode.acted.copy()
        obs = episode.observation()
        learn = self._learnable
        if learn is not None:
            reward = float(learn.reward(self._x[None, :], self._u[None, :])[0])
            obs = learn.observe(obs)
        elif self.core.dtype is not _F64:
            obs = obs.astype(self.core.dtype)
        if self.render_mode == "human":
            self.render()
        return obs, reward, status == 1, status == 2, {}

    # -- pictures -------------------------------------------------------------------
    def render(self) -> np.ndarray | None:
        """The current state drawn as the animations draw it (``rgb_array``), or shown."""
        if self._renderer is None:
            raise EnvError(
                "render() needs a render_mode: make the environment with render_mode='rgb_array' "
                "or 'human'"
            )
        if self.render_mode == "rgb_array":
            return self._renderer.frame(self._x, self._u, self.time)
        self._renderer.show(self._x, self._u, self.time)
        return None

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
        super().close()


__all__ = ["EquilibristEnv", "display_problem"]
