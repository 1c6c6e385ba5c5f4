"""Rotary inverted pendulum (Furuta pendulum).

Description
    An arm turns in the horizontal plane about a vertical motor shaft; at its
    tip a pendulum swings freely on a joint whose axis lies along the arm, so
    the pendulum moves in the vertical plane perpendicular to the arm. The
    motor balances the pendulum upright by swinging the arm. The model is
    fully three-dimensional (the pendulum's share of the arm's inertia,
    ``(I_p + m_p l_p^2) sin^2(theta)``, and the centrifugal and Coriolis
    couplings are all kept). Derived by Lagrange's method.

States
    ``phi`` arm angle about the vertical [rad], counter-clockwise seen from
    above; ``theta`` pendulum angle from vertical-up [rad], positive when the
    pendulum's tip leans towards the arm's direction of increasing ``phi``
    (the direction the joint moves when ``phi`` grows); their rates.

Inputs
    ``tau`` motor torque on the arm [N m], in the sense of ``phi``.

Parameters
    ======  ==========  ==========  ==================================================
    name    default     unit        meaning
    ======  ==========  ==========  ==================================================
    m_a     0.095       kg          arm mass
    L_a     0.085       m           motor axis to pendulum joint
    I_a     2.288e-4    kg m^2      arm inertia about the motor axis, hub included
                                    (``m_a L_a^2 / 3`` with the defaults)
    m_p     0.024       kg          pendulum mass
    l_p     0.0645      m           joint to pendulum centre of mass (rod of 0.129 m)
    I_p     3.328e-5    kg m^2      pendulum inertia about its centre of mass,
                                    transverse (``m_p (2 l_p)^2 / 12``; a slender rod:
                                    no inertia about its own axis)
    b_a     5e-4        N m s/rad   arm viscous friction (torque -b_a phi_dot)
    b_p     1e-5        N m s/rad   pendulum joint friction (torque -b_p theta_dot on
                                    the pendulum, the reaction on the arm)
    g       9.81        m/s^2       gravity
    ======  ==========  ==========  ==================================================

    The defaults are a desktop servo rig of the QUBE-Servo 2 class: its
    published arm and pendulum masses and lengths, with the inertias of
    uniform rods (the arm about its end, the pendulum about its centre).
    ``tau`` is limited to +-0.05 N m (a 10 V drive at stall).

Sensors and rate
    Encoders of 2048 counts per turn on both angles: a quantization step of
    ``2 pi / 2048 = 3.07 mrad``, taken as uniform noise of standard deviation
    ``step / sqrt(12) = 0.89 mrad``. The controller runs at 500 Hz, the
    sample rate of the rig's own control software.

Operating point
    Pendulum upright, arm at 0, at rest, ``tau = 0``. Default outputs
    ``[phi, theta]`` (the two encoders). A swing-up starts hanging,
    ``theta = pi``.

Source
    Not in the seeds. The equations agree with the published Furuta-pendulum
    model of Cazzolato and Prime (2011, "On the dynamics of the Furuta
    pendulum", J. Control Sci. Eng., their equations 33-34 for a slender
    pendulum), whose pendulum angle is measured from hanging down:
    their ``theta_1 = phi``, ``theta_2 = pi - theta``.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from equilibrist.mechanics.spec import (
    Input,
    OperatingPoint,
    SwingUp,
    SystemSpec,
    friction,
    nonnegative,
    positive,
)
from equilibrist.systems.registry import register

if TYPE_CHECKING:  # sympy is imported only when the model is derived
    from equilibrist.mechanics.model import Derivation, SymbolicModel

_RIG = "QUBE-Servo 2 class rig"
_M_A, _L_A = 0.095, 0.085
_M_P, _L_P = 0.024, 0.0645
# 2048-count encoders: the quantization step, uniform noise of std step / sqrt(12).
_ENCODER = 2.0 * math.pi / 2048 / math.sqrt(12.0)

SPEC = SystemSpec(
    name="furuta",
    title="Rotary inverted pendulum (Furuta pendulum)",
    description="An arm turning about a vertical motor shaft balances a pendulum at its tip.",
    coordinates=("phi", "theta"),
    units={"phi": "rad", "theta": "rad"},
    parameters=(
        positive("m_a", _M_A, "kg", "arm mass", note=_RIG),
        positive("L_a", _L_A, "m", "motor axis to pendulum joint", note=_RIG),
        positive(
            "I_a", _M_A * _L_A**2 / 3.0, "kg*m^2", "arm inertia about the motor axis, hub included",
            note="uniform rod about its end, m_a L_a^2 / 3, with the defaults",
        ),
        positive("m_p", _M_P, "kg", "pendulum mass", note=_RIG),
        positive(
            "l_p", _L_P, "m", "joint to pendulum centre of mass",
            note=_RIG + ": a rod of 0.129 m, centre of mass at mid-length",
        ),
        nonnegative(
            "I_p", _M_P * (2.0 * _L_P) ** 2 / 12.0, "kg*m^2",
            "pendulum inertia about its centre of mass, transverse (slender rod)",
            note="uniform rod m_p (2 l_p)^2 / 12 with the defaults",
        ),
        friction(
            "b_a", 5e-4, "N*m*s/rad", "arm viscous friction (motor and bearing)",
            note=_RIG + ": ballpark of its motor's viscous loss",
        ),
        friction(
            "b_p", 1e-5, "N*m*s/rad", "pendulum joint viscous friction",
            note=_RIG + ": ballpark of a ball-bearing encoder shaft",
        ),
        positive("g", 9.81, "m/s^2", "gravitational acceleration", note="standard gravity"),
    ),
    inputs=(Input("tau", "N*m", "motor torque on the arm, in the sense of phi", -0.05, 0.05),),
    outputs=("phi", "theta"),
    operating_point=OperatingPoint(state={}, inputs={"tau": 0.0}),
    source="not in the seeds; Cazzolato and Prime (2011), On the dynamics of the Furuta pendulum",
    notes=(
        "the pendulum is a slender rod: I_p about the two axes across it, none about its own axis",
        "Cazzolato and Prime measure the pendulum from hanging down: theta_2 = pi - theta",
        "defaults: a QUBE-Servo 2 class desktop rig (10 V drive, 2048-count encoders, 500 Hz)",
    ),
    region={"theta": (-math.pi / 2, math.pi / 2)},
    # Bryson: the arm may wander half a radian and swing at 5 rad/s; the
    # pendulum may lean 0.1 rad and turn at 2 rad/s; the drive's full
    # 0.05 N m is the torque to spend.
    design_scales={
        "phi": 0.5, "theta": 0.1, "phi_dot": 5.0, "theta_dot": 2.0, "tau": 0.05,
    },
    sensor_noise={"phi": _ENCODER, "theta": _ENCODER},
    # Random torques of some 2e-4 N m sqrt(s) on the arm (the small DC
    # motor's ripple and cogging, over the arm's 4e-4 kg m^2 with the
    # pendulum) and 3e-5 N m sqrt(s) on the pendulum (air, the encoder's cable).
    process_noise={"phi_dot": 0.5, "theta_dot": 0.2},
    # The rig's control software samples its encoders and drive at 500 Hz.
    control_rate=500.0,
    hanging={"theta": math.pi},
    swingup=SwingUp("rotary", {"k_energy": 40.0, "a_max": 0.05, "catch_fraction": 20.0,
                               "accel": 100.0},
                    free=("phi",)),
    drawing="equilibrist.viz.scenes_3d:FurutaScene",
    position=6,
)


@register(SPEC)
def derive(d: Derivation) -> SymbolicModel:
    from sympy.physics import mechanics as me

    from equilibrist.mechanics.model import kinetic_energy
    phi, theta = d.q
    phid, thetad = d.qd
    p, tau = d.p, d.u["tau"]
    N, O = d.N, d.O  # N.z up, the motor axis through O
    # The arm turns about the vertical; it points along A.x, and A.y is the
    # direction its tip moves when phi grows.
    A = N.orientnew("A", "Axis", (phi, N.z))
    # The pendulum turns about the arm's axis; along P.z. A rotation of
    # -theta about A.x tips P.z from A.z towards +A.y for theta > 0.
    P = A.orientnew("P", "Axis", (-theta, A.x))
    J = O.locatenew("J", p["L_a"] * A.x)
    Ga = O.locatenew("Ga", p["L_a"] / 2 * A.x)
    Gp = J.locatenew("Gp", p["l_p"] * P.z)
    for point in (J, Ga, Gp):
        point.set_vel(N, point.pos_from(O).dt(N))
    # The arm is a slender bar along A.x; its inertia is given about the motor
    # axis (I_a about A.z and, as a bar, about A.y; only A.z matters since the
    # arm turns about the vertical alone). sympy moves it to the centre of mass.
    arm = me.RigidBody("arm", Ga, A, p["m_a"], (me.inertia(A, 0, p["I_a"], p["I_a"]), O))
    pendulum = me.RigidBody(
        "pendulum", Gp, P, p["m_p"], (me.inertia(P, p["I_p"], p["I_p"], 0), Gp),
    )
    # The pendulum joint's friction: a torque -b_p theta_dot in the sense of
    # theta (the vector -A.x) on the pendulum, and its reaction on the arm.
    joint = -p["b_p"] * thetad * (-A.x)
    loads = [(A, (tau - p["b_a"] * phid) * N.z - joint), (P, joint)]
    kinetic = kinetic_energy(N, arm, pendulum)
    # The arm stays level: its weight does no work, but it is written down.
    potential = p["g"] * (p["m_a"] * Ga.pos_from(O).dot(N.z) + p["m_p"] * Gp.pos_from(O).dot(N.z))
    return d.lagrange(kinetic - potential, loads=loads, energy=kinetic + potential)
