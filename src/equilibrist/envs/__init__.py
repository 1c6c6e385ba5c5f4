"""Every system with an input, and each of its tasks, as a Gymnasium environment.

``import equilibrist.envs`` registers, for every system of the catalogue
that has an input and for each task it offers (:mod:`equilibrist.tasks`):

``equilibrist/<system>-<task>-v0``
    e.g. ``equilibrist/cartpole-balance-v0``, ``equilibrist/cartpole-swingup-v0``;
``equilibrist/balance-v0``, ``equilibrist/swingup-v0``
    the task on a system given by name or file:
    ``gymnasium.make("equilibrist/balance-v0", system="robot.xml")``;
``...-v1``
    each of them as a task to learn (:mod:`equilibrist.envs.learnable`): the
    whole state observed in Bryson units, float32 spaces, dm_control's
    cart-pole reward in ``[0, 1]`` per step. What follows is ``-v0``'s.

``gymnasium.make("equilibrist.envs:equilibrist/cartpole-balance-v0")``
imports this package by itself. Every id has a native vector environment:
``gymnasium.make_vec(id, num_envs=N, vectorization_mode="vector_entry_point")``.

The environment
---------------
Action
    ``Box(-1, 1, (n_inputs,))``, mapped affinely onto each input's limits
    (``-1`` is ``<input>_min``, ``+1`` is ``<input>_max``); out-of-range
    actions saturate at the limits, as the actuator does.
    ``action_units="physical"`` gives a ``Box`` in the input's own units
    bounded by its limits.
Observation
    The rig's measured outputs (the system's sensors) with its sensor
    noise, or the full state with ``observe="state"``; float64, angles as
    they are (never wrapped). The space's bounds are half the largest
    double (about 9e307): every value a state can take is an observation,
    and ``observation_space.sample()`` does not overflow.
Step
    One control period of the task's rate (``rate=`` changes it), the
    plant integrated as :func:`equilibrist.sim.simulate` does it: the
    saturated input held, RK4 physics steps of ``physics_step`` (at most
    1 ms by default), process noise held over each physics step, the
    region checked after each. ``noise=False`` removes the process and the
    sensor noise. With ``observe="state"`` the sensor noise is still drawn
    (and not added), so the run is the same as with the outputs observed.
Reward
    Balance: ``dt * max(0, alive_bonus - c(x, u))`` with ``c`` the task's
    quadratic cost (Bryson's weights of the default design,
    :meth:`equilibrist.tasks.Task.cost`) at the state reached and the input
    applied, ``alive_bonus`` 1 per second: near upright an episode's return
    is the time balanced minus the integrated cost. The floor at zero keeps
    a fall from ever paying: without it a policy that struggles far from
    upright (where the cost is large) would earn less than one that falls
    at once, and a search would learn to fall. Swing-up: ``dt * (U + S) / 2`` with
    ``U`` the mean of ``(1 + cos(q - q_up)) / 2`` over the coordinates
    that hang, and ``S = max(0, 1 - ((E - E_up) / (E_up - E_hang))**2)``
    the energy shaping (``E`` the model's energy, ``E_up`` at the
    operating point, ``E_hang`` hanging at rest): 0 hanging still, ``dt``
    balanced upright, never negative (leaving the track early never pays).
Episode
    Terminated when the state leaves the task's region (a fall; a state
    that stops being finite is replaced by the last finite one);
    truncated at the task's duration.
Options
    ``params={"m_p": 2.0}`` sets parameters; ``randomize={"m_p": 0.2}``
    draws each reset's value uniformly within ``+-20 %`` of it.
Seeding
    Only through ``reset(seed=...)``. The env's ``np_random`` draws the
    initial state, the randomized parameters and an integer noise seed
    (``info["noise_seed"]``): ``simulate(..., seed=info["noise_seed"])``
    with the same actions reproduces the episode, noise included.
Rendering
    ``render_mode="rgb_array"`` returns the picture the animations draw;
    ``"human"`` shows it in a matplotlib window, and where no window can
    open the environment refuses it when made, saying why.
"""

from __future__ import annotations

import importlib.util

from equilibrist.errors import EquilibristError


class MissingExtraError(EquilibristError, ImportError):
    """Gymnasium is not installed."""


if importlib.util.find_spec("gymnasium") is None:
    raise MissingExtraError(
        "equilibrist's environments need Gymnasium: pip install 'equilibrist[envs]'"
    )

from equilibrist.envs.core import EnvError  # noqa: E402
from equilibrist.envs.env import EquilibristEnv  # noqa: E402
from equilibrist.envs.registration import env_ids, register_all  # noqa: E402
from equilibrist.envs.vector import EquilibristVectorEnv  # noqa: E402

register_all()

__all__ = ["EnvError", "EquilibristEnv", "EquilibristVectorEnv", "MissingExtraError", "env_ids"]
