"""Two links in a vertical plane, in Gymnasium ``Acrobot-v1``'s coordinates (shared by two systems).

The acrobot (actuated at the elbow) and the pendubot (actuated at the
shoulder) are the same mechanism with the motor at a different joint: their
parameters and their geometry live here once. (The derivation cache hashes
the systems' helper modules, so a change here re-derives both.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from equilibrist.mechanics.spec import Parameter, friction, nonnegative, positive

_GYM = "Gymnasium Acrobot-v1"


def parameters() -> tuple[Parameter, ...]:
    """The physical parameters of both systems, with Gymnasium's defaults."""
    return (
        positive("l1", 1.0, "m", "link 1 length (shoulder to elbow)", note=_GYM + " LINK_LENGTH_1"),
        positive(
            "l2", 1.0, "m", "link 2 length (drawing only: it does not enter the dynamics)",
            note=_GYM + " LINK_LENGTH_2",
        ),
        nonnegative("lc1", 0.5, "m", "shoulder to link 1 centre of mass", note=_GYM + " LINK_COM_POS_1"),
        nonnegative("lc2", 0.5, "m", "elbow to link 2 centre of mass", note=_GYM + " LINK_COM_POS_2"),
        positive("m1", 1.0, "kg", "link 1 mass", note=_GYM + " LINK_MASS_1"),
        positive("m2", 1.0, "kg", "link 2 mass", note=_GYM + " LINK_MASS_2"),
        nonnegative("I1", 1.0, "kg*m^2", "link 1 inertia about its centre of mass", note=_GYM + " LINK_MOI"),
        nonnegative("I2", 1.0, "kg*m^2", "link 2 inertia about its centre of mass", note=_GYM + " LINK_MOI"),
        friction(
            "b1", 0.0, "N*m*s/rad", "shoulder viscous friction (torque -b1 theta1_dot on link 1)",
            note=_GYM + " has none",
        ),
        friction(
            "b2", 0.0, "N*m*s/rad",
            "elbow viscous friction (torque -b2 theta2_dot on link 2, the opposite on link 1)",
            note=_GYM + " has none",
        ),
        positive("g", 9.8, "m/s^2", "gravitational acceleration", note=_GYM),
    )


#: Both links upright: link 1 turned half a turn from hanging, link 2 in line.
UPRIGHT: dict[str, float | str] = {"theta1": math.pi}

#: A fall: link 1 more than a quarter turn from upright, or the elbow bent
#: more than a quarter turn.
REGION = {"theta1": (math.pi / 2, 3 * math.pi / 2), "theta2": (-math.pi / 2, math.pi / 2)}


@dataclass(frozen=True)
class TwoLinks:
    """The links' frames, the bodies, and the energy of the pair."""

    link1_frame: Any
    link2_frame: Any
    link1: Any
    link2: Any
    kinetic: Any
    potential: Any


def two_links(d: Any) -> TwoLinks:
    """Frames, points and bodies of the two links of *d* (a ``Derivation``).

    ``N.x`` is to the right, ``N.y`` up, ``N.z`` towards the viewer, so a
    rotation about ``N.z`` is counter-clockwise. At ``theta1 = 0`` link 1
    hangs straight down from the shoulder ``O``; ``theta2`` turns link 2
    relative to link 1 about the elbow.
    """
    from sympy.physics import mechanics as me

    from equilibrist.mechanics.model import kinetic_energy

    theta1, theta2 = d.q
    p, N, O = d.p, d.N, d.O
    L1 = N.orientnew("L1", "Axis", (theta1, N.z))
    L2 = L1.orientnew("L2", "Axis", (theta2, L1.z))
    # Each link points along its frame's -y (hanging down at zero angle).
    G1 = O.locatenew("G1", -p["lc1"] * L1.y)
    elbow = O.locatenew("E", -p["l1"] * L1.y)
    G2 = elbow.locatenew("G2", -p["lc2"] * L2.y)
    for point in (G1, elbow, G2):
        point.set_vel(N, point.pos_from(O).dt(N))
    link1 = me.RigidBody("link1", G1, L1, p["m1"], (me.inertia(L1, 0, 0, p["I1"]), G1))
    link2 = me.RigidBody("link2", G2, L2, p["m2"], (me.inertia(L2, 0, 0, p["I2"]), G2))
    kinetic = kinetic_energy(N, link1, link2)
    potential = p["g"] * (p["m1"] * G1.pos_from(O).dot(N.y) + p["m2"] * G2.pos_from(O).dot(N.y))
    return TwoLinks(L1, L2, link1, link2, kinetic, potential)


def joint_loads(d: Any, links: TwoLinks, *, shoulder: Any = 0, elbow: Any = 0) -> list[tuple[Any, Any]]:
    """The torques on the links (counter-clockwise, vectors along ``N.z``).

    *shoulder* is a motor torque on link 1 from the ground, *elbow* one on
    link 2 from link 1 (its reaction acts on link 1). The joints' viscous
    friction acts the same way: ``-b1 theta1_dot`` on link 1 from the
    ground; ``-b2 theta2_dot`` on link 2 from link 1, and its reaction on
    link 1.
    """
    p, N = d.p, d.N
    theta1d, theta2d = d.qd
    at_shoulder = shoulder - p["b1"] * theta1d
    at_elbow = elbow - p["b2"] * theta2d
    return [
        (links.link1_frame, (at_shoulder - at_elbow) * N.z),
        (links.link2_frame, at_elbow * N.z),
    ]
