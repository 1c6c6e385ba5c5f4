"""Seesaw balanced by a drone motor.

Description
    A uniform beam of length ``L`` turns on a central pivot; point masses
    ``m1`` and ``m2`` sit at its left and right ends. A drone motor fixed at
    the right end pushes perpendicular to the beam and holds it level against
    the heavier right end. The pivot has viscous and (tanh-smoothed) Coulomb
    friction. Derived by Kane's method from the bodies and forces below.

States
    ``theta`` beam angle from horizontal [rad], counter-clockwise positive
    (positive raises the right end, where ``m2`` and the motor are), and
    ``theta_dot`` [rad/s].

Inputs
    ``F`` motor thrust [N], perpendicular to the beam, positive when it raises
    the right end: torque ``+L/2 F`` about the pivot at any angle. A propeller
    does not reverse, so ``F_min = 0``; a level balance then needs
    ``m2 >= m1`` (``F_e = (m2 - m1) g``), which the defaults respect. The
    spec cannot enforce that inequality between two parameters: a choice
    ``m1 > m2`` is a valid model whose level point needs a negative thrust.

Parameters
    ======  ========  ==========  ==========================================
    name    default   unit        meaning
    ======  ========  ==========  ==========================================
    L       0.5       m           beam length (pivot at its centre)
    m_b     0.1       kg          beam mass (uniform; inertia m_b L^2 / 12)
    m1      0.05      kg          point mass at the left end
    m2      0.1       kg          point mass at the right end (with motor)
    b       1e-3      N m s/rad   pivot viscous friction
    mu_c    0.005     1           pivot Coulomb friction coefficient
    eps     0.05      rad/s       rate scale of the tanh smoothing of sgn
    g       9.81      m/s^2       gravity
    F_min   0         N           thrust lower limit (propeller)
    F_max   4         N           thrust upper limit
    ======  ========  ==========  ==========================================

    Equations (from the derivation; seed 000 writes the same with ``N``
    replaced by ``g``)::

        I theta_ddot = -b theta_dot - mu_c N L/2 tanh(theta_dot / eps)
                       + (m1 - m2) g L/2 cos(theta) + L/2 F
        I = m_b L^2 / 12 + (m1 + m2) L^2 / 4,   N = (m_b + m1 + m2) g

    The pivot load ``N`` ignores the thrust's share (the seed's
    approximation, kept).

Operating point
    Level beam at rest, ``theta = 0``, with the thrust that holds it solved
    for (``F_e = (m2 - m1) g`` without friction at rest). Default output
    ``[theta]`` (an encoder or IMU on the beam).

Energy
    Kinetic plus potential energy of the beam and the two masses; it changes
    at the rate ``theta_dot (L/2 F - b theta_dot - mu_c N L/2 tanh(theta_dot/eps))``.

Source
    seeds/000 (the whole document). Seed slips, found by derivation:

    - it places the motor at ``x = +L/2`` in one sentence and at ``x = -L/2``
      (the left end) in the next, yet keeps the torque ``+L/2 F``; here the
      motor is at the right end and the torque sign is kept;
    - it approximates the pivot's normal load ``N`` by ``g`` (a load per unit
      mass), so its ``beta = mu_c g L / (2 I)``; here ``N = (m_b + m1 + m2) g``
      and ``beta = mu_c N L / (2 I)``;
    - its equilibrium ``x1 = acos(delta F_e / )`` lost ``gamma`` and a sign:
      ``gamma cos(theta_e) + delta F_e = 0`` gives
      ``cos(theta_e) = -delta F_e / gamma``.
"""

from __future__ import annotations

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

SPEC = SystemSpec(
    name="seesaw",
    title="Seesaw balanced by a drone motor",
    description=(
        "A beam on a central pivot with masses at both ends, held level by a "
        "motor's thrust at its right end."
    ),
    coordinates=("theta",),
    units={"theta": "rad"},
    parameters=(
        positive("L", 0.5, "m", "beam length, pivot at its centre",
                 note="desktop rig: a 50 cm aluminium bar"),
        positive("m_b", 0.1, "kg", "beam mass (uniform bar)",
                 note="desktop rig: 50 cm of 20x3 mm aluminium flat bar"),
        nonnegative("m1", 0.05, "kg", "point mass at the left end",
                    note="desktop rig: counterweight; m1 <= m2 so that F_min = 0 can hold the beam level"),
        nonnegative("m2", 0.1, "kg", "point mass at the right end, motor and propeller included",
                    note="desktop rig: 2204-class motor, 5-inch propeller and mount"),
        friction("b", 1e-3, "N*m*s/rad", "pivot viscous friction",
                    note="estimate for a ball-bearing pivot"),
        friction("mu_c", 0.005, "1", "pivot Coulomb friction coefficient",
                    note="typical rolling-bearing friction coefficient 0.001-0.005"),
        positive("eps", 0.05, "rad/s", "rate scale of the tanh smoothing of sgn(theta_dot)",
                 note="seed 000 asks for a small positive constant; 0.05 rad/s keeps the "
                      "linearized Coulomb damping mu_c N L / (2 I eps) moderate"),
        positive("g", 9.81, "m/s^2", "gravitational acceleration", note="standard gravity"),
    ),
    inputs=(Input("F", "N", "motor thrust perpendicular to the beam, raising the right end",
                  0.0, 4.0),),
    outputs=("theta",),
    operating_point=OperatingPoint(state={"theta": 0.0}, free=("F",)),
    source="seeds/000",
    seed_slips=(
        "the motor is placed at x = +L/2 and then at x = -L/2 with the same torque +L/2 F; "
        "kept: right end, torque +L/2 F",
        "the pivot's normal load N is approximated by g; here N = (m_b + m1 + m2) g",
        "the equilibrium x1 = acos(delta F_e / ) lost gamma and the sign: "
        "cos(theta_e) = -delta F_e / gamma",
    ),
    notes=(
        "the pivot load N ignores the thrust's share (the seed's approximation)",
        "a level balance with F_min = 0 needs m2 >= m1",
    ),
    region={"theta": (-0.6, 0.6)},  # the beam rests on end stops at about 35 degrees
    symbols_latex={"mu_c": r"\mu_c", "eps": r"\epsilon", "m_b": "m_b"},
    # The beam may droop 0.1 rad and swing at 1 rad/s; thrust corrections of 1 N
    # (a quarter of the motor's range).
    design_scales={"theta": 0.1, "theta_dot": 1.0, "F": 1.0},
    # 4096-count encoder on the pivot: 1.5 mrad quantization.
    sensor_noise={"theta": 1.5e-3},
    # Propeller wash and thrust ripple: about 0.5 rad/s^2 of angular acceleration.
    process_noise={"theta_dot": 0.5},
    drawing="equilibrist.viz.scenes_planar:SeesawScene",
    scenario=Scenario(duration=8.0, start={"theta": -0.15}, push=-2.0, push_duration=0.15,
        step={"theta": 0.1}, step_at=1.5,
        push_name="a downward tap of 2 N on the motor end for 0.15 s"),
    position=1,
)


@register(SPEC)
def derive(d: Derivation) -> SymbolicModel:
    import sympy as sp
    from sympy.physics import mechanics as me

    (theta,) = d.q
    (thetad,) = d.qd
    p, F = d.p, d.u["F"]
    N, O = d.N, d.O
    half = p["L"] / 2
    B = N.orientnew("B", "Axis", (theta, N.z))  # counter-clockwise positive
    B.set_ang_vel(N, thetad * N.z)
    left = O.locatenew("P1", -half * B.x)
    right = O.locatenew("P2", half * B.x)
    left.v2pt_theory(O, N, B)
    right.v2pt_theory(O, N, B)
    beam = me.RigidBody("beam", O, B, p["m_b"], (me.inertia(B, 0, 0, p["m_b"] * p["L"] ** 2 / 12), O))
    mass1 = me.Particle("mass1", left, p["m1"])
    mass2 = me.Particle("mass2", right, p["m2"])
    g = p["g"]
    normal_load = (p["m_b"] + p["m1"] + p["m2"]) * g
    friction = -p["b"] * thetad - p["mu_c"] * normal_load * half * sp.tanh(thetad / p["eps"])
    loads = [
        (O, -p["m_b"] * g * N.y),
        (left, -p["m1"] * g * N.y),
        (right, -p["m2"] * g * N.y + F * B.y),  # thrust rotates with the beam
        # The pivot's reaction on the (fixed) ground does no work.
        (B, friction * N.z),
    ]
    potential = sum(
        (m * g * pt.pos_from(O).dot(N.y) for m, pt in ((p["m1"], left), (p["m2"], right))),
        sp.Integer(0),
    )
    energy = beam.kinetic_energy(N) + mass1.kinetic_energy(N) + mass2.kinetic_energy(N) + potential
    return d.kane(bodies=[beam, mass1, mass2], loads=loads, energy=energy)
