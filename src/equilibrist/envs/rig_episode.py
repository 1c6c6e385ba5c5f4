"""An environment's episode through a rig's effects: the loop ``simulate`` runs around a
controller written in Python, one sample a step, the agent's action in the controller's
place (used by :mod:`equilibrist.envs.env` and :mod:`equilibrist.envs.vector` when the
option ``rig`` is given)."""

from __future__ import annotations

import numpy as np

from equilibrist.envs.core import Core
from equilibrist.sim import integrators


def _hold(t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The agent's place in a run's settings: its actions come through :meth:`RigEpisode.step`."""
    raise AssertionError("an episode's actions come from its steps")


class RigEpisode:
    """One copy's episode through a rig: the loop ``simulate`` runs around a controller
    written in Python (``equilibrist.sim.run``: the core's ``eq_rig_measure_one``, its
    advance with the rig's generalized forces, ``eq_rig_actuate_one``), one sample a step,
    the agent's action in the controller's place. An episode started at *x0* with the
    parameters *p* and the noise seed *noise_seed* and ``simulate(system, controller, x0=x0,
    seed=noise_seed, noise=core.noise, rig=core.rig, region=core.task.region, ...)`` whose
    controller returns the same actions step the same numbers: states, measurements and the
    torques that acted.

    The reward is the task's (its Python form, :func:`~equilibrist.tasks.python_reward`,
    the source the core translates) on the state at the end of the period and the torque
    that acted during it.
    """

    def __init__(self, core: Core, x0: np.ndarray, p: np.ndarray, noise_seed: int) -> None:
        from equilibrist.sim import setup as sim_setup
        from equilibrist.sim.kernel import Kernel
        from equilibrist.sim.noise import generator_state, seed_sequence
        from equilibrist.sim.steps import SetupSteps
        from equilibrist.tasks import python_reward, task_kind

        system = core.system
        if core.rnd_idx.size:
            names = system.spec.parameter_names
            system = system.with_params(**{names[i]: float(p[i]) for i in core.rnd_idx})
        outputs = tuple(system.state_names[int(i)] for i in core.c_idx)
        setup = sim_setup.build(
            system, _hold, duration=core.n_samples / core.rate, rate=core.rate,
            physics_step=core.physics_step, integrator=core.integrator, rtol=integrators.RTOL,
            atol=integrators.ATOL, plant="nonlinear", x0=x0, delay=False, noise=core.noise,
            reference=None, events=(), outputs=outputs, region=core.task.region, rig=core.rig)
        seq = seed_sequence(noise_seed)
        self.plant = SetupSteps(setup, Kernel(system, setup.nonlinear), generator_state(seq), seq)
        self.core, self.system, self.setup = core, system, setup
        self.x, self.y = self.plant.x, self.plant.y
        self.k = 0
        n, m = system.n_states, system.n_inputs
        base = len(system.spec.parameter_names) - 2 * m
        limits = self.plant.p_sets[0, base:]
        self._low, self._high = limits[0::2][:m], limits[1::2][:m]
        self.acted = np.zeros(m)
        self._reward = python_reward(task_kind(core.task.name), system)
        self._p = np.array(system.p, dtype=float)
        energy = system.functions.energy
        self._eref = np.array([energy(core.op[:n], self._p),
                               energy(np.asarray(core.task.start, dtype=float), self._p)])
        self._iscale = 1.0 / core.sc
        self.plant.measure(0)

    def observation(self) -> np.ndarray:
        """What the agent observes now: the measurement through the rig, or the state."""
        return self.x.copy() if self.core.observe == "state" else self.y.copy()

    def step(self, u: np.ndarray) -> tuple[float, int]:
        """One period with the input *u* (within its limits) commanded: the reward and the
        status (0 running, 1 fell, 2 out of time)."""
        k = self.k
        self.acted = self.plant.actuate(k, u, self._low, self._high)
        fell = self.plant.advance(k)
        self.k = k + 1
        self.plant.measure(self.k)
        core = self.core
        reward = float(self._reward(self.x, self.acted, self._p, core.op, self._iscale,
                                    core.hang, self._eref, 1.0 / core.rate, core.alive_bonus))
        return reward, 1 if fell else (2 if self.k >= core.n_samples else 0)


__all__ = ["RigEpisode"]
