"""Double inverted pendulum on a cart.

Description
    A cart on a straight horizontal track carries two rigid links in series:
    link 1 on a revolute joint on the cart, link 2 on a revolute joint at the
    far end of link 1. The cart is pushed by a horizontal force; both links
    are balanced upright. Each link is a rod with its centre of mass at
    mid-length. Derived by Lagrange's method, as seed 002 does.

States
    ``x`` cart position [m] (+x to the right); ``theta1``, ``theta2`` the
    absolute angles of link 1 and link 2 from vertical-up [rad], positive
    clockwise (the link leaning towards +x, as the cart-pole); and their rates.

Inputs
    ``F`` horizontal force on the cart [N], +x.

Parameters
    ======  =========  ==========  ==================================================
    name    default    unit        meaning
    ======  =========  ==========  ==================================================
    m_c     1.0        kg          cart mass
    m1      0.2        kg          link 1 mass
    l1      0.3        m           link 1 full length (centre of mass at l1/2)
    I1      0.0015     kg m^2      link 1 inertia about its centre of mass
    m2      0.1        kg          link 2 mass
    l2      0.3        m           link 2 full length (centre of mass at l2/2)
    I2      0.00075    kg m^2      link 2 inertia about its centre of mass
    b_c     0.2        N s/m       cart viscous friction (force -b_c x_dot)
    b1      5e-4       N m s/rad   joint-1 friction (torque -b1 theta1_dot on link 1)
    b2      5e-4       N m s/rad   joint-2 friction (torque -b2 (theta2_dot -
                                   theta1_dot) on link 2, the opposite on link 1)
    g       9.81       m/s^2       gravity
    ======  =========  ==========  ==================================================

    The seed gives no numbers; the defaults are a desktop rig: a belt-driven
    cart of 1 kg with two 30 cm aluminium rods (``I = m l^2 / 12``).

Operating point
    Both links upright, at rest, ``F = 0``. Default outputs
    ``[x, theta1, theta2]`` (cart encoder and the two joint encoders).

Source
    seeds/002 ("Double inverted pendulum on cart"), where the angles are
    called ``theta`` (link 1) and ``phi`` (link 2). The derivation here
    differs from the seed's printed equations by the seed's slips:

    - its theta equation carries ``(1/7 m1 + m2) g l1 sin(theta)`` where
      ``(1/2 m1 + m2)`` is right (its own potential energy says 1/2);
    - it writes ``l1``, ``l2`` where the inertias ``I1``, ``I2`` are meant
      (in the kinetic energy and in the mass matrix);
    - its x equation has ``1/2 m2 l2 cos(phi) phi_dot`` where ``phi_ddot``
      is meant (the final matrix form has it right);
    - its theta equation misses the reaction of the joint-2 friction on
      link 1: the generalized force of ``theta1`` is
      ``-b1 theta1_dot + b2 (theta2_dot - theta1_dot)``, not ``-b1 theta1_dot``.
      The same omission makes its linearization's friction columns wrong
      (``dH/dtheta_dot = [0, -b1, b2]`` should be ``[0, -b1 - b2, b2]`` and
      ``dH/dphi_dot = [0, 0, -b2]`` should be ``[0, b2, -b2]``).
    The seed has no cart friction; ``b_c`` is an addition.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from equilibrist.mechanics.spec import (
    Input,
    OperatingPoint,
    Scenario,
    SystemSpec,
    friction,
    nonnegative,
    positive,
)
from equilibrist.systems.registry import register

if TYPE_CHECKING:  # sympy is imported only when the model is derived
    from equilibrist.mechanics.model import Derivation, SymbolicModel

_RIG = "desktop rig: 30 cm aluminium bar"

SPEC = SystemSpec(
    name="double_cartpole",
    title="Double inverted pendulum on a cart",
    description="A cart on a horizontal track balancing two links in series.",
    coordinates=("x", "theta1", "theta2"),
    units={"x": "m", "theta1": "rad", "theta2": "rad"},
    parameters=(
        positive("m_c", 1.0, "kg", "cart mass", note="desktop rig: belt-driven cart and carriage"),
        positive("m1", 0.2, "kg", "link 1 mass", note=_RIG + " of 15 x 15 mm with bearing housing"),
        positive("l1", 0.3, "m", "link 1 full length (centre of mass at l1/2)", note=_RIG),
        nonnegative(
            "I1", 0.0015, "kg*m^2", "link 1 inertia about its centre of mass",
            note="thin rod m1 l1^2 / 12 with the defaults",
        ),
        positive("m2", 0.1, "kg", "link 2 mass", note=_RIG + " of 10 x 12 mm"),
        positive("l2", 0.3, "m", "link 2 full length (centre of mass at l2/2)", note=_RIG),
        nonnegative(
            "I2", 0.00075, "kg*m^2", "link 2 inertia about its centre of mass",
            note="thin rod m2 l2^2 / 12 with the defaults",
        ),
        friction(
            "b_c", 0.2, "N*s/m", "cart viscous friction",
            note="ballpark of a linear-bearing carriage on a belt; not from the seed",
        ),
        friction(
            "b1", 5e-4, "N*m*s/rad", "joint-1 viscous friction",
            note="ballpark of a ball-bearing joint with an encoder; the seed gives none",
        ),
        friction(
            "b2", 5e-4, "N*m*s/rad", "joint-2 viscous friction (between the links)",
            note="ballpark of a ball-bearing joint with an encoder; the seed gives none",
        ),
        positive("g", 9.81, "m/s^2", "gravitational acceleration", note="standard gravity"),
    ),
    inputs=(Input("F", "N", "horizontal force on the cart, +x", -20.0, 20.0),),
    outputs=("x", "theta1", "theta2"),
    operating_point=OperatingPoint(state={}, inputs={"F": 0.0}),
    source="seeds/002 double inverted pendulum on cart",
    seed_slips=(
        "seed 002 writes (1/7 m1 + m2) g l1 sin(theta) for (1/2 m1 + m2) g l1 sin(theta)",
        "seed 002 writes l1, l2 where the link inertias I1, I2 are meant",
        "seed 002's x equation has a phi_dot where phi_ddot is meant",
        "seed 002's theta equation (and its linearization) misses the reaction "
        "+b2 (phi_dot - theta_dot) of the joint-2 friction on link 1",
    ),
    notes=(
        "angles are absolute (both from vertical-up); the seed calls theta2 phi",
        "the seed has no cart friction; b_c = 0 recovers its model",
    ),
    region={"theta1": (-math.pi / 2, math.pi / 2), "theta2": (-math.pi / 2, math.pi / 2)},
    # The track allows 0.3 m of wander; each link may lean 0.1 rad; a 12 V
    # belt drive pushes about 10 N without saturating.
    design_scales={
        "x": 0.3, "theta1": 0.1, "theta2": 0.1,
        "x_dot": 1.0, "theta1_dot": 1.0, "theta2_dot": 1.0,
        "F": 10.0,
    },
    # Quadrature encoders: 0.05 mm on the belt; 4096 counts per turn on the
    # joints (1.5 mrad quantization), as the cart-pole.
    sensor_noise={"x": 5e-5, "theta1": 1.5e-3, "theta2": 1.5e-3},
    process_noise={"x_dot": 0.05, "theta1_dot": 0.1, "theta2_dot": 0.1},
    drawing="equilibrist.viz.scenes_planar:DoubleCartpoleScene",
    scenario=Scenario(duration=10.0, start={"theta1": 0.04, "theta2": -0.03}, push=8.0,
        push_duration=0.1, step={"x": 0.15}, step_at=1.0,
        push_name="a shove of 8 N on the cart for 0.1 s"),
    position=3,
)


@register(SPEC)
def derive(d: Derivation) -> SymbolicModel:
    from sympy.physics import mechanics as me

    from equilibrist.mechanics.model import kinetic_energy
    x, theta1, theta2 = d.q
    xd, theta1d, theta2d = d.qd
    p, F = d.p, d.u["F"]
    N, O = d.N, d.O
    # Absolute link frames; rotating by -theta about N.z makes theta clockwise.
    L1 = N.orientnew("L1", "Axis", (-theta1, N.z))
    L2 = N.orientnew("L2", "Axis", (-theta2, N.z))
    C = O.locatenew("C", x * N.x)
    C.set_vel(N, xd * N.x)
    G1 = C.locatenew("G1", p["l1"] / 2 * L1.y)
    J2 = C.locatenew("J2", p["l1"] * L1.y)
    G2 = J2.locatenew("G2", p["l2"] / 2 * L2.y)
    for point in (G1, J2, G2):
        point.set_vel(N, point.pos_from(O).dt(N))
    cart = me.Particle("cart", C, p["m_c"])
    link1 = me.RigidBody("link1", G1, L1, p["m1"], (me.inertia(L1, 0, 0, p["I1"]), G1))
    link2 = me.RigidBody("link2", G2, L2, p["m2"], (me.inertia(L2, 0, 0, p["I2"]), G2))
    kinetic = kinetic_energy(N, cart, link1, link2)
    potential = p["g"] * (p["m1"] * G1.pos_from(O).dot(N.y) + p["m2"] * G2.pos_from(O).dot(N.y))
    # A clockwise torque tau is the vector -tau N.z. Joint-2 friction acts
    # between the links: -b2 (theta2_dot - theta1_dot) clockwise on link 2,
    # the reaction on link 1 (the term seed 002 misses).
    joint2 = -p["b2"] * (theta2d - theta1d)
    loads = [
        (C, (F - p["b_c"] * xd) * N.x),
        (L1, -(-p["b1"] * theta1d - joint2) * N.z),
        (L2, -joint2 * N.z),
    ]
    return d.lagrange(kinetic - potential, loads=loads, energy=kinetic + potential)
