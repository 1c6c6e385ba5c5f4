"""Inverted pendulum on a wheel.

Description
    A body balances on one wheel that rolls without slipping on a flat floor:
    a two-wheeled self-balancing robot seen from the side (both wheels lumped
    into one). A motor between body and wheel drives the wheel; its reaction
    tilts the body. Derived by Kane's method; the rolling constraint is built
    into the kinematics (wheel centre at ``x_w = R phi``, contact point at
    rest), so the contact force does no work and drops out.

States
    ``phi`` wheel rotation [rad], clockwise positive, so the wheel rolls
    towards +x and its centre is at ``x_w = R phi``; ``theta`` body angle from
    vertical-up [rad], clockwise positive (leaning towards +x); their rates.
    ``phi`` is the wheel's absolute rotation, not the motor's angle
    ``phi - theta``.

Inputs
    ``tau`` motor torque on the wheel from the body [N m], clockwise
    positive; the body receives ``-tau``.

Parameters
    ======  =========  ==========  ==================================================
    name    default    unit        meaning
    ======  =========  ==========  ==================================================
    m       1.0        kg          body mass
    m_w     0.1        kg          wheel mass (both wheels)
    R       0.04       m           wheel radius
    L       0.08       m           wheel axle to body centre of mass
    I       0.0023     kg m^2      body inertia about its centre of mass
    I_w     8e-5       kg m^2      wheel inertia about its axle (both wheels)
    b_r     1e-4       N m s/rad   wheel-floor friction (torque -b_r phi_dot on the wheel)
    b_m     1e-3       N m s/rad   motor friction (torque -b_m (phi_dot - theta_dot)
                                   on the wheel, the opposite on the body)
    g       9.81       m/s^2       gravity
    ======  =========  ==========  ==================================================

    The seed gives no numbers; the defaults are a hobby balancing robot: an
    80 mm wheel pair driven by geared 12 V DC motors under a 1 kg body.

Operating point
    Upright, at rest, ``tau = 0``. Default outputs ``[phi, theta]`` (wheel
    encoder and a tilt estimate from an IMU).

Source
    seeds/002 ("Inverted pendulum on wheel"). The seed keeps only the
    linearization ``G [phi_ddot, theta_ddot] = [[0, 0, -b_m - b_r, b_m],
    [0, m g L, b_m, -b_m]] x + [1, -1] tau`` with the mass matrix ``G`` at
    upright left implicit; the derivation here agrees with it, with
    ``G = [[I_w + (m + m_w) R^2, m R L], [m R L, I + m L^2]]``.
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

_ROBOT = "hobby two-wheeled balancing robot"

SPEC = SystemSpec(
    name="wheeled_pendulum",
    title="Inverted pendulum on a wheel",
    description="A body balancing on a wheel that rolls without slipping (a two-wheeled robot).",
    coordinates=("phi", "theta"),
    units={"phi": "rad", "theta": "rad"},
    parameters=(
        positive("m", 1.0, "kg", "body mass", note=_ROBOT + ": chassis, battery, electronics"),
        positive("m_w", 0.1, "kg", "wheel mass (both wheels)", note=_ROBOT + ": two 50 g wheels"),
        positive("R", 0.04, "m", "wheel radius", note=_ROBOT + ": 80 mm wheels"),
        positive("L", 0.08, "m", "wheel axle to body centre of mass", note=_ROBOT + ", measured"),
        nonnegative(
            "I", 0.0023, "kg*m^2", "body inertia about its centre of mass",
            note="box 0.16 m tall, 0.04 m deep: m (h^2 + d^2) / 12",
        ),
        nonnegative(
            "I_w", 8e-5, "kg*m^2", "wheel inertia about its axle (both wheels)",
            note="uniform discs m_w R^2 / 2 with the defaults",
        ),
        friction(
            "b_r", 1e-4, "N*m*s/rad", "wheel-floor (rolling) friction",
            note="ballpark for rubber tyres on a hard floor; the seed gives none",
        ),
        friction(
            "b_m", 1e-3, "N*m*s/rad", "motor friction between wheel and body",
            note="ballpark for a small geared DC motor; the seed gives none",
        ),
        positive("g", 9.81, "m/s^2", "gravitational acceleration", note="standard gravity"),
    ),
    inputs=(
        Input("tau", "N*m", "motor torque on the wheel from the body, clockwise", -0.6, 0.6),
    ),
    outputs=("phi", "theta"),
    operating_point=OperatingPoint(state={}, inputs={"tau": 0.0}),
    source="seeds/002 inverted pendulum on wheel",
    notes=(
        "seed 002 leaves the mass matrix G at upright implicit; its linearized "
        "forcing and input columns are right (OCR drops m g L from its reduced form)",
        "the two wheels of a balancing robot are lumped into one (m_w, I_w are totals)",
        "the wheel rolls without slipping: the contact force is not modelled",
    ),
    region={"theta": (-math.pi / 2, math.pi / 2)},
    # The robot may drift 0.3 m (7.5 rad of wheel) and lean 0.1 rad; the
    # motors give 0.3 N m without saturating.
    design_scales={
        "phi": 7.5, "theta": 0.1, "phi_dot": 10.0, "theta_dot": 1.0, "tau": 0.3,
    },
    # Wheel encoder of 1320 counts per wheel turn (11-pulse magnetic encoder,
    # 30:1 gearbox, quadrature): 4.8 mrad steps; tilt from an MPU-6050
    # complementary filter: about 2 mrad.
    sensor_noise={"phi": 4.8e-3, "theta": 2e-3},
    process_noise={"phi_dot": 0.5, "theta_dot": 0.1},
    drawing="equilibrist.viz.scenes_planar:WheeledPendulumScene",
    scenario=Scenario(duration=8.0, start={"theta": 0.08}, push=0.12, push_duration=0.1,
        step={"phi": 5.0}, step_at=1.0,
        push_name="a torque kick of 0.12 N m on the wheel for 0.1 s"),
    position=4,
)


@register(SPEC)
def derive(d: Derivation) -> SymbolicModel:
    from sympy.physics import mechanics as me

    from equilibrist.mechanics.model import kinetic_energy
    phi, theta = d.q
    phid, thetad = d.qd
    p, tau = d.p, d.u["tau"]
    N, O = d.N, d.O
    # Rotating by -angle about N.z makes both angles clockwise.
    W = N.orientnew("W", "Axis", (-phi, N.z))
    B = N.orientnew("B", "Axis", (-theta, N.z))
    # Rolling without slipping: the centre advances R per radian of clockwise
    # rotation, so the contact point (centre - R N.y) is at rest.
    Wc = O.locatenew("Wc", p["R"] * phi * N.x + p["R"] * N.y)
    Wc.set_vel(N, p["R"] * phid * N.x)
    G = Wc.locatenew("G", p["L"] * B.y)
    G.set_vel(N, G.pos_from(O).dt(N))
    wheel = me.RigidBody("wheel", Wc, W, p["m_w"], (me.inertia(W, 0, 0, p["I_w"]), Wc))
    body = me.RigidBody("body", G, B, p["m"], (me.inertia(B, 0, 0, p["I"]), G))
    # Clockwise torques on the wheel: motor, floor friction, motor friction;
    # the body gets the reaction of the motor torque and of its friction.
    # A clockwise torque c is the vector -c N.z.
    motor_friction = -p["b_m"] * (phid - thetad)
    on_wheel = tau - p["b_r"] * phid + motor_friction
    on_body = -tau - motor_friction
    loads = [
        (Wc, -p["m_w"] * p["g"] * N.y),
        (G, -p["m"] * p["g"] * N.y),
        (W, -on_wheel * N.z),
        (B, -on_body * N.z),
    ]
    potential = p["g"] * (p["m_w"] * Wc.pos_from(O).dot(N.y) + p["m"] * G.pos_from(O).dot(N.y))
    energy = kinetic_energy(N, wheel, body) + potential
    return d.kane(bodies=[wheel, body], loads=loads, energy=energy)
