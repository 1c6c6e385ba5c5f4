"""A controller kind as an environment's expert: a policy from observations to actions.

:func:`expert` builds any kind of the registry (:mod:`equilibrist.controllers.kinds`:
``lqg``, ``lqr``, ``swingup``, ``mpc``, one's own) for an environment's
system, rate and sensors, and wraps it as a policy that sees only what an
agent sees (the observations) and answers with the environment's actions
(normalized or physical, as the environment takes them). It is the baseline
an agent is compared with and the teacher of an imitation example::

    env = gymnasium.make("equilibrist/cartpole-swingup-v0")
    policy = expert(env, "swingup")
    obs, info = env.reset(seed=0)
    policy.reset()
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        ...

The controller is stepped as the simulation steps it: the command of the
sample, then the controller's update with the input that acted (the
environment's saturation applied).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.errors import EquilibristError

if TYPE_CHECKING:
    from equilibrist.control.controller import AnyController
    from equilibrist.control.python_controller import PythonController
    from equilibrist.envs.core import Core


class ExpertError(EquilibristError, ValueError):
    """A kind that cannot act in this environment (one line)."""


class Expert:
    """A controller acting through an environment's observations and actions."""

    def __init__(self, core: Core, controller: AnyController, kind: str) -> None:
        from equilibrist.control.controller import as_python_controller, measured_outputs
        from equilibrist.control.linear import LinearController
        from equilibrist.control.nonlinear import NonlinearController

        self.core = core
        self.kind = kind
        self.controller = controller
        if isinstance(controller, LinearController | NonlinearController):
            self.runtime: PythonController = controller.runtime()
        else:
            self.runtime = as_python_controller(controller)
        reads = tuple(measured_outputs(controller) or ())
        if reads != tuple(core.observation_names):
            raise ExpertError(f"the {kind} controller reads {', '.join(reads) or 'nothing'}, the "
                              f"environment observes {', '.join(core.observation_names)}")
        self._r = np.zeros(0)
        self._k = 0

    def reset(self) -> None:
        """Start a new episode (call it with the environment's ``reset``)."""
        self.runtime.reset()
        self._k = 0

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        """The action for *observation* (the environment's units); the controller advances."""
        core = self.core
        y = (np.asarray(observation, dtype=float) if core.learnable is None
             else core.learnable.raw(observation))
        t = self._k / core.rate
        u = np.asarray(self.runtime.output(t, y, self._r), dtype=float)
        lo, hi = core.limits
        applied: np.ndarray = np.minimum(np.maximum(u, lo), hi)
        self.runtime.update(t, y, self._r, applied)
        self._k += 1
        if core.action_units == "physical":
            return applied.astype(core.dtype)
        action: np.ndarray = (2.0 * (applied - lo) / (hi - lo) - 1.0).astype(core.dtype)
        return action


def expert(env: object, kind: str = "lqg", *, options: Mapping[str, object] | None = None,
           design_options: Mapping[str, object] | None = None) -> Expert:
    """The controller *kind* as a policy of *env* (an equilibrist environment, wrapped or not).

    The kind is built for the environment's system at its rate, measuring
    its observations, at the environment's operating point (``design_options`` and
    the kind's own ``options`` as ``simulate`` takes them); refused in one line when it does not apply or
    reads other signals than the environment observes.
    """
    from equilibrist.controllers import kinds

    core = getattr(getattr(env, "unwrapped", env), "core", None)
    if core is None:
        raise ExpertError(f"{type(env).__name__} is not an equilibrist environment")
    observed = tuple(core.observation_names)
    # The Kalman filter measures what the agent observes; the whole state is the LQR's own.
    design: dict[str, object] = ({} if observed == tuple(core.system.state_names)
                                 else {"outputs": observed})
    if core.at:  # the environment's operating point (its option at=)
        design["at"] = dict(core.at)
    design.update(design_options or {})
    request = kinds.ControllerRequest(system=core.system, rate=core.rate, design_options=design,
                                      options=dict(options or {}))
    record = kinds.get(kind)
    if record.open_loop:
        raise ExpertError(f"--controller {kind} is the open loop: it is no expert")
    built = record.make(request)
    if built is None:
        raise ExpertError(f"--controller {kind} builds no controller: it is no expert")
    return Expert(core, built, kind)


__all__ = ["Expert", "ExpertError", "expert"]
