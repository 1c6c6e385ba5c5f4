"""Reaction-wheel inverted pendulum.

Description
    A pendulum on a pivot at its base carries a flywheel on its own axle,
    driven by a motor fixed to the pendulum. Spinning the wheel up or down
    pushes back on the pendulum, which is balanced upright by that reaction
    torque alone. Derived by Lagrange's method, as seed 002 does.

States
    ``phi`` absolute wheel angle [rad], clockwise positive (measured from
    vertical-up in the room, not relative to the pendulum: the motor's
    encoder reads ``phi - theta``); ``theta`` pendulum angle from vertical-up
    [rad], clockwise positive; their rates.

Inputs
    ``tau`` motor torque on the wheel from the pendulum [N m], clockwise;
    the pendulum receives ``-tau``.

Parameters
    ======  =========  ==========  ==================================================
    name    default    unit        meaning
    ======  =========  ==========  ==================================================
    m       0.2        kg          pendulum mass (without the wheel)
    m_w     0.15       kg          wheel mass
    L       0.1        m           pivot to pendulum centre of mass
    L_w     0.2        m           pivot to wheel centre
    I       6.7e-4     kg m^2      pendulum inertia about its centre of mass
    I_w     2.7e-4     kg m^2      wheel inertia about its axle
    b_a     1e-4       N m s/rad   pivot friction (torque -b_a theta_dot on the pendulum)
    b_m     5e-5       N m s/rad   motor friction (torque -b_m (phi_dot - theta_dot)
                                   on the wheel, the opposite on the pendulum)
    g       9.81       m/s^2       gravity
    ======  =========  ==========  ==================================================

    The seed gives no numbers; the defaults are a desktop rig: a 20 cm arm
    with a 12 cm brass-rimmed flywheel on a brushless gimbal motor.

Operating point
    Upright, wheel at rest, ``tau = 0``. Default outputs ``[phi, theta]``:
    the wheel's angle must be measured, since with ``theta`` alone it is
    unobservable.

Source
    seeds/002 ("Reaction wheel on inverted pendulum"). With ``phi``
    absolute, the mass matrix is constant,
    ``diag(I_w, I + m_w L_w^2 + m L^2)``, and the seed's equations and
    linearization are right; only OCR damage garbles them (a missing
    ``0 0 0 1`` row entry, ``phi_dot`` for ``theta_dot`` in state vectors).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from equilibrist.mechanics.spec import (
    Input,
    OperatingPoint,
    Scenario,
    SwingUp,
    SystemSpec,
    friction,
    nonnegative,
    positive,
)
from equilibrist.systems.registry import register

if TYPE_CHECKING:  # sympy is imported only when the model is derived
    from equilibrist.mechanics.model import Derivation, SymbolicModel

_RIG = "desktop reaction-wheel rig"

SPEC = SystemSpec(
    name="reaction_wheel_pendulum",
    title="Reaction-wheel inverted pendulum",
    description="A pendulum on a base pivot balanced by the reaction torque of a flywheel.",
    coordinates=("phi", "theta"),
    units={"phi": "rad", "theta": "rad"},
    parameters=(
        positive("m", 0.2, "kg", "pendulum mass", note=_RIG + ": 20 cm aluminium arm with motor"),
        positive("m_w", 0.15, "kg", "wheel mass", note=_RIG + ": 12 cm brass-rimmed flywheel"),
        positive("L", 0.1, "m", "pivot to pendulum centre of mass", note=_RIG + ": mid-arm"),
        positive("L_w", 0.2, "m", "pivot to wheel centre", note=_RIG + ": wheel at the arm's tip"),
        nonnegative(
            "I", 6.7e-4, "kg*m^2", "pendulum inertia about its centre of mass",
            note="thin rod m (2 L)^2 / 12 with the defaults",
        ),
        nonnegative(
            "I_w", 2.7e-4, "kg*m^2", "wheel inertia about its axle",
            note="disc m_w r^2 / 2 with r = 6 cm",
        ),
        friction(
            "b_a", 1e-4, "N*m*s/rad", "pivot viscous friction",
            note="ballpark of a ball-bearing pivot; the seed gives none",
        ),
        friction(
            "b_m", 5e-5, "N*m*s/rad", "motor viscous friction (between wheel and pendulum)",
            note="ballpark of a brushless gimbal motor; the seed gives none",
        ),
        positive("g", 9.81, "m/s^2", "gravitational acceleration", note="standard gravity"),
    ),
    inputs=(
        Input("tau", "N*m", "motor torque on the wheel from the pendulum, clockwise", -0.2, 0.2),
    ),
    outputs=("phi", "theta"),
    operating_point=OperatingPoint(state={}, inputs={"tau": 0.0}),
    source="seeds/002 reaction wheel on inverted pendulum",
    notes=(
        "seed 002's equations and linearization are right; OCR drops an entry of "
        "its A matrix's second row and writes phi_dot for theta_dot in state vectors",
        "phi is the absolute wheel angle; the motor's encoder measures phi - theta",
    ),
    region={"theta": (-math.pi / 2, math.pi / 2)},
    # The wheel angle matters little (50 rad), its speed must stay well below
    # the motor's 300 rad/s; the pendulum may lean 0.1 rad; 0.1 N m is half
    # the motor's peak torque.
    design_scales={
        "phi": 50.0, "theta": 0.1, "phi_dot": 100.0, "theta_dot": 1.0, "tau": 0.1,
    },
    # 12-bit magnetic encoder on the motor (1.5 mrad steps); 2048-line
    # quadrature encoder on the pivot (0.77 mrad steps).
    sensor_noise={"phi": 1.5e-3, "theta": 7.7e-4},
    process_noise={"phi_dot": 0.5, "theta_dot": 0.1},
    hanging={"theta": math.pi},
    swingup=SwingUp("wheel", {"k_energy": 0.5, "a_max": 0.2, "catch_fraction": 10.0,
                              "accel": 40.0},
                    free=("phi",)),
    drawing="equilibrist.viz.scenes_planar:ReactionWheelScene",
    scenario=Scenario(duration=8.0, start={"theta": 0.08}, push=0.1,
        push_duration=0.1,
        push_name="a torque kick of 0.1 N m for 0.1 s"),
    position=5,
)


@register(SPEC)
def derive(d: Derivation) -> SymbolicModel:
    from sympy.physics import mechanics as me

    from equilibrist.mechanics.model import kinetic_energy
    phi, theta = d.q
    phid, thetad = d.qd
    p, tau = d.p, d.u["tau"]
    N, O = d.N, d.O
    # Rotating by -angle about N.z makes both angles clockwise; the wheel's
    # frame is oriented from N, so phi is its absolute angle.
    P = N.orientnew("P", "Axis", (-theta, N.z))
    W = N.orientnew("W", "Axis", (-phi, N.z))
    G = O.locatenew("G", p["L"] * P.y)
    Wc = O.locatenew("Wc", p["L_w"] * P.y)
    for point in (G, Wc):
        point.set_vel(N, point.pos_from(O).dt(N))
    pendulum = me.RigidBody("pendulum", G, P, p["m"], (me.inertia(P, 0, 0, p["I"]), G))
    wheel = me.RigidBody("wheel", Wc, W, p["m_w"], (me.inertia(W, 0, 0, p["I_w"]), Wc))
    kinetic = kinetic_energy(N, pendulum, wheel)
    potential = p["g"] * (p["m"] * G.pos_from(O).dot(N.y) + p["m_w"] * Wc.pos_from(O).dot(N.y))
    # Clockwise torques; the motor and its friction act between wheel and
    # pendulum (action and reaction). A clockwise torque c is the vector -c N.z.
    motor_friction = -p["b_m"] * (phid - thetad)
    on_wheel = tau + motor_friction
    on_pendulum = -tau - motor_friction - p["b_a"] * thetad
    loads = [(W, -on_wheel * N.z), (P, -on_pendulum * N.z)]
    return d.lagrange(kinetic - potential, loads=loads, energy=kinetic + potential)
