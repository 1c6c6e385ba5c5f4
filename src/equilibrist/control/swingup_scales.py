"""A two-link rig's own scales, which its energy swing-up's gains are stated in
(docs/swingup.md): the lift from hanging to upright, Xin and Kaneda's bounds on the law's
damping and stiffness gains, and the motor's torque room, each computed from the law's own
generated physics (used by :func:`equilibrist.control.swingup.swingup`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control.swingup_law import CP_SLOTS, python_namespace

if TYPE_CHECKING:
    from equilibrist.numeric.system import System


#: The two-link laws and the joint each drives (0: the shoulder, 1: the elbow).
ACTUATED = {"acrobot": 1, "pendubot": 0}


@dataclass(frozen=True)
class PlantScales:
    """A two-link rig's own scales, which its swing-up's gains are stated in (docs/swingup.md).

    The rig's potential is a first harmonic in the shoulder's angle at every bend ``q2``:
    ``P(q1, q2) = c - R(q2) cos(q1 - phi(q2))``, so the lowest the rig can hang with that
    bend is ``c - R(q2)``, and ``R(0) = b1 + b2``, ``R(pi) = |b1 - b2|`` give the two links'
    gravity torques ``b1`` (link 1's, with link 2's mass at the elbow) and ``b2`` (link 2's).

    Attributes
    ----------
    lift:
        The energy from hanging at rest to upright at rest [J].
    damping_bound:
        ``max over q2 of (E_up - c + R(q2)) det M / M_bb`` [J kg m^2] (``b`` the passive
        joint): above ``k_E`` times it, ``k_D`` keeps the law's denominator from zero at every
        state the energy function allows (Xin and Kaneda's condition on ``k_D``).
    stiffness_bound:
        ``(2 / pi) min(b1, b2)^2`` [J^2]: above ``k_E`` times it, ``k_P`` leaves the closed
        loop no resting point but hanging and upright (Xin and Kaneda's condition on ``k_P``).
    torque:
        The motor's room from its operating torque to its nearer limit [N m].
    """

    lift: float
    damping_bound: float
    stiffness_bound: float
    torque: float


def plant_scales(system: System, source: str, cp: np.ndarray, law: str) -> PlantScales:
    """*system*'s scales (:class:`PlantScales`) for the two-link law *law*, from the law's own
    physics (its generated ``scalar_mass`` and ``scalar_energy`` on the parameters *cp*), in
    plain float arithmetic on fixed grids of 1 degree (the same bits on every CPU)."""
    from equilibrist.control.swingup_law import cp_layout

    ns = python_namespace(source)
    a = ACTUATED[law]
    b = 1 - a
    at = cp_layout(4, 2, int(cp[CP_SLOTS.index("np")]))
    x_op = [float(v) for v in cp[at["x_op"]:at["x_op"] + 4]]
    hang = _hanging(system, np.asarray(x_op))
    mass = ns["scalar_mass"]
    pot = _Potential(ns["scalar_energy"], cp, at["phys"])
    e_up = pot(x_op[0], x_op[1])
    lift = e_up - pot(float(hang[0]), float(hang[1]))
    step = 2.0 * math.pi / 360
    worst = 0.0
    for k in range(360):
        bend = -math.pi + k * step
        m = [[float(mass(i, j, 0.0, bend, 0.0, 0.0, cp, at["phys"])) for j in (0, 1)]
             for i in (0, 1)]
        # The lowest the rig hangs with this bend: c - R of the potential's harmonic in q1.
        c, r, _phase = _harmonic(pot.along([0.0, bend], 0))
        det = m[0][0] * m[1][1] - m[0][1] * m[0][1]
        worst = max(worst, (e_up - c + r) * det / m[b][b])
    # The closed loop's resting points: the actuated joint at qa, the passive one where
    # gravity leaves it still (an extreme of the potential's harmonic in its angle), the motor
    # holding gravity's torque there; the law rests there when kp qa~ = -ke (E - E0) torque.
    stiff = 0.0
    for k in range(1, 360):
        distance = -math.pi + k * step
        if k == 180:  # upright: no distance to hold
            continue
        q = [0.0, 0.0]
        q[a] = x_op[a] + distance
        _c, _r, still = _harmonic(pot.along(q, b))
        for rest in (still, still + math.pi):
            q[b] = rest
            _c, r, phase = _harmonic(pot.along(q, a))
            torque = r * math.sin(q[a] - phase)
            stiff = max(stiff, -(pot(q[0], q[1]) - e_up) * torque / distance)
    lo, hi = (float(v[0]) for v in system.input_limits)
    u_op = float(cp[CP_SLOTS.index("u_op")])
    return PlantScales(lift=lift, damping_bound=worst, stiffness_bound=stiff,
                       torque=min(hi - u_op, u_op - lo))


@dataclass(frozen=True)
class _Potential:
    """The rig's energy at rest at ``(q1, q2)``: its generated ``scalar_energy``."""

    energy: Callable[..., float]
    cp: np.ndarray
    phys: int

    def __call__(self, q1: float, q2: float) -> float:
        return float(self.energy(q1, q2, 0.0, 0.0, self.cp, self.phys))

    def along(self, q: list[float], i: int) -> Callable[[float], float]:
        """The potential as a function of angle *i*, the other held at *q*'s."""
        held = list(q)

        def at(v: float) -> float:
            point = list(held)
            point[i] = v
            return self(point[0], point[1])

        return at


def _harmonic(fn: Callable[[float], float]) -> tuple[float, float, float]:
    """``(c, R, phi)`` of a first harmonic ``fn(v) = c - R cos(v - phi)`` (a two-link rig's
    potential in either angle, the other held), from its values at 0, pi/2 and pi."""
    p0, p1, p2 = fn(0.0), fn(0.5 * math.pi), fn(math.pi)
    c = 0.5 * (p0 + p2)
    return c, math.hypot(0.5 * (p2 - p0), c - p1), math.atan2(c - p1, 0.5 * (p2 - p0))


def _hanging(system: System, x_op: np.ndarray) -> np.ndarray:
    """*system* hanging at rest (``spec.hanging``'s coordinates, the others at *x_op*)."""
    x = np.array(x_op, dtype=float)
    nq = len(system.spec.coordinates)
    x[nq:] = 0.0
    for name, value in (system.spec.hanging or {}).items():
        x[system.spec.coordinates.index(name)] = float(value)
    return x


__all__ = ["ACTUATED", "PlantScales", "plant_scales"]
