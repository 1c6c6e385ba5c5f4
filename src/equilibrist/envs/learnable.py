"""The learnable form of a task (the ``-v1`` ids): scaled observations, a bounded reward.

The ``-v0`` environments give the rig's signals in their own units and a reward
that is the task's quadratic cost; a trainer with its default settings (a
policy network of unit-scale inputs, a value function of unit-scale returns)
learns little from them. The ``-v1`` form keeps the same plant, step, start,
fall and seeding, and changes what an agent sees and earns:

Observation
    Each observed signal as its deviation from the operating point in units
    of its Bryson scale (the scales of the default design, so that 1 is the
    deviation the design tolerates): ``(y - y_op) / scale``. In the swing-up,
    each coordinate that hangs is observed as ``cos(q - q_op), sin(q - q_op)``
    instead (an angle that winds up has no bounded scaled form). float32 by
    default (``dtype=numpy.float64`` on request). The map is
    :func:`equilibrist.controllers.network.observation_map`, which a trained
    policy run as a controller reads too.
Reward
    dm_control's cart-pole reward, read on every rig through its definition:
    ``upright * centered * small_control * small_velocity`` in ``[0, 1]`` per
    step, so that the maximum return is the number of steps of an episode:

    * ``upright``: the product over the posture coordinates (those that hang,
      and those whose leaving the region is a fall) of ``(1 + cos(q - q_op)) / 2``
      for a coordinate that hangs, else the Gaussian tolerance of its deviation
      (1 at the operating point, 0.1 at the region's bound). A product, not
      dm_control's mean over poles: a relative angle (the acrobot's elbow) is at
      its operating value hanging too, and a mean paid half the reward for
      hanging still;
    * ``centered``: ``(1 + t) / 2`` with ``t`` the mean Gaussian tolerance of the
      other coordinates' scaled deviations (0.1 at two Bryson scales);
    * ``small_control``: ``(4 + t) / 5`` with ``t = 1 - a^2`` (0 beyond), ``a``
      the input's deviation from its operating value in units of half its range;
    * ``small_velocity``: ``(1 + t) / 2`` with ``t`` the smallest Gaussian
      tolerance of the posture coordinates' scaled rates (0.1 at five scales).

    The tolerances are dm_control's ``rewards.tolerance`` (Gaussian sigmoid,
    ``bounds=(0, 0)``; quadratic for the input). The reward is read at the
    state reached and the input applied, as ``-v0``'s.

Rate
    The rig's control rate, divided by the smallest whole number that lets the
    trainers' default discount (0.99: a horizon of about 100 steps) span
    :data:`HORIZON_TIME_CONSTANTS` time constants of the slowest unstable mode
    of the linearization at the operating point (:func:`learnable_rate`; at
    least :data:`LOWEST_RATE`). A rig that falls slowly (the acrobot, 1.9 /s)
    is otherwise decided beyond what its agent's discount sees: at 200 Hz
    PPO's defaults never balance it, at a quarter of that they do.
    Gymnasium's MuJoCo balance tasks run at 20-25 Hz for the same reason.

This module holds that form as a value (:class:`Learnable`) that the single
and the vector environment both apply to the core's raw observations and
states; the core's step, its bits and ``-v0`` are untouched.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from equilibrist.controllers.network import observation_map
from equilibrist.numeric.system import System
from equilibrist.tasks import Task

#: The tolerances' value at their margin (dm_control's default).
VALUE_AT_MARGIN = 0.1
#: The margins, in Bryson scales: the other coordinates' deviation, the posture's rates.
CENTERED_MARGIN = 2.0
VELOCITY_MARGIN = 5.0
_GAUSS = math.sqrt(-2.0 * math.log(VALUE_AT_MARGIN))
#: The steps the trainers' default discount looks ahead: ``1 / (1 - 0.99)``.
HORIZON_STEPS = 100.0
#: The time constants of the slowest unstable mode that horizon spans at least.
HORIZON_TIME_CONSTANTS = 1.5
#: The lowest rate a task is slowed to [Hz] (Gymnasium's InvertedDoublePendulum's).
LOWEST_RATE = 20.0


def learnable_rate(system: System, task: Task) -> float:
    """The ``-v1`` form's control rate of *task* on *system* [Hz]: the task's rate divided
    by the smallest whole number ``n`` for which ``HORIZON_STEPS`` periods last at least
    ``HORIZON_TIME_CONSTANTS / s``, with ``s`` the slowest growth rate [1/s] among the
    unstable eigenvalues of the linearization at the task's operating point (those that
    grow more than e-fold in an episode; the task's rate where none does), no lower than
    ``LOWEST_RATE``."""
    a, _b = system.jacobians(task.x_op, task.u_op)
    # A mode that grows less than e-fold in an episode decides nothing within it.
    growth = [float(e.real) for e in np.linalg.eigvals(a) if e.real * task.duration > 1.0]
    if not growth:
        return task.rate
    n = math.ceil(task.rate * HORIZON_TIME_CONSTANTS / (HORIZON_STEPS * min(growth)) - 1e-9)
    n = max(1, min(n, math.floor(task.rate / LOWEST_RATE)))
    return task.rate / n


def gaussian_tolerance(d: np.ndarray) -> np.ndarray:
    """dm_control's Gaussian tolerance with ``bounds=(0, 0)`` of *d* (in margins)."""
    scaled = d * _GAUSS
    out: np.ndarray = np.exp(-0.5 * scaled * scaled)
    return out


def quadratic_tolerance(d: np.ndarray) -> np.ndarray:
    """dm_control's quadratic tolerance with ``value_at_margin=0`` of *d* (in margins)."""
    out: np.ndarray = np.maximum(0.0, 1.0 - d * d)
    return out


@dataclass(frozen=True, eq=False)
class Learnable:
    """The ``-v1`` observation and reward of one system and task (see the module).

    Attributes
    ----------
    dtype:
        The observations' (and spaces') floating type.
    names:
        What each observation component is (``theta`` scaled, ``cos(theta)``...).
    """

    dtype: np.dtype[np.floating]
    names: tuple[str, ...]
    # The observation: raw component i scaled as (y - offset) * gain, or, where trig,
    # its cos and sin about the offset.
    obs_offset: np.ndarray
    obs_gain: np.ndarray
    obs_trig: np.ndarray
    # The reward: index arrays into the state and the operating point.
    x_op: np.ndarray
    u_op: np.ndarray
    u_half: np.ndarray
    hang: np.ndarray
    posture: np.ndarray
    posture_margin: np.ndarray
    rates: np.ndarray
    rate_gain: np.ndarray
    others: np.ndarray
    other_gain: np.ndarray

    @property
    def n_obs(self) -> int:
        return len(self.names)

    def observe(self, raw: np.ndarray) -> np.ndarray:
        """The scaled observations of raw ones (``(n_obs,)`` or ``(copies, n_obs)``)."""
        d = raw - self.obs_offset
        if not self.obs_trig.any():
            out: np.ndarray = (d * self.obs_gain).astype(self.dtype)
            return out
        parts = []
        for i in range(raw.shape[-1]):
            if self.obs_trig[i]:
                parts += [np.cos(d[..., i]), np.sin(d[..., i])]
            else:
                parts.append(d[..., i] * self.obs_gain[i])
        return np.stack(parts, axis=-1).astype(self.dtype)

    def raw(self, observation: np.ndarray) -> np.ndarray:
        """The signals in their own units of one scaled *observation* (an angle observed as
        its cosine and sine comes back within a half turn of the operating point)."""
        o = np.asarray(observation, dtype=float)
        out = np.empty(self.obs_offset.shape[0])
        j = 0
        for i in range(out.shape[0]):
            if self.obs_trig[i]:
                out[i] = self.obs_offset[i] + math.atan2(o[j + 1], o[j])
                j += 2
            else:
                out[i] = self.obs_offset[i] + o[j] / self.obs_gain[i]
                j += 1
        return out

    def reward(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The reward at states *x* reached with inputs *u* applied (rows are copies)."""
        d = x - self.x_op
        upright = gaussian_tolerance(d[:, self.posture] / self.posture_margin)
        if self.hang.size:
            upright[:, self.hang] = 0.5 * (1.0 + np.cos(d[:, self.posture[self.hang]]))
        r = upright.prod(axis=1)
        if self.others.size:
            r = r * 0.5 * (1.0 + gaussian_tolerance(
                d[:, self.others] * self.other_gain).mean(axis=1))
        a = (u - self.u_op) / self.u_half
        r = r * (4.0 + quadratic_tolerance(a).mean(axis=1)) / 5.0
        if self.rates.size:
            r = r * 0.5 * (1.0 + gaussian_tolerance(
                x[:, self.rates] * self.rate_gain).min(axis=1))
        out: np.ndarray = r
        return out


def learnable(system: System, task: Task, observed: tuple[str, ...],
              dtype: np.dtype[np.floating]) -> Learnable:
    """The ``-v1`` form of *task* on *system*, observing the states *observed*."""
    names = system.state_names
    scales = np.asarray(task.state_scales, dtype=float)
    x_op = np.asarray(task.x_op, dtype=float)
    hanging = tuple(system.spec.hanging or {})
    seen = observation_map(system, task, observed)
    coords = tuple(system.spec.coordinates)
    posture = [c for c in coords if c in system.spec.region or c in hanging]
    region = system.spec.region
    margins = []
    for c in posture:
        k = names.index(c)
        lo, hi = region.get(c, (-math.inf, math.inf))
        margins.append(min(abs(x_op[k] - lo), abs(hi - x_op[k]), math.pi))
    rate_names = [f"{c}_dot" for c in posture if f"{c}_dot" in names]
    others = [names.index(c) for c in coords if c not in posture]
    lo_u, hi_u = system.input_limits
    return Learnable(
        dtype=np.dtype(dtype), names=seen.names, obs_offset=seen.offset, obs_gain=seen.gain,
        obs_trig=seen.trig,
        x_op=x_op, u_op=np.asarray(task.u_op, dtype=float),
        u_half=0.5 * (np.asarray(hi_u, dtype=float) - np.asarray(lo_u, dtype=float)),
        hang=np.array([i for i, c in enumerate(posture) if c in hanging], dtype=np.int64),
        posture=np.array([names.index(c) for c in posture], dtype=np.int64),
        posture_margin=np.array(margins, dtype=float),
        rates=np.array([names.index(r) for r in rate_names], dtype=np.int64),
        rate_gain=np.array([1.0 / (VELOCITY_MARGIN * scales[names.index(r)])
                            for r in rate_names], dtype=float),
        others=np.array(others, dtype=np.int64),
        other_gain=1.0 / (CENTERED_MARGIN * scales[others]) if others else np.zeros(0),
    )


__all__ = ["Learnable", "gaussian_tolerance", "learnable", "learnable_rate",
           "quadratic_tolerance"]
