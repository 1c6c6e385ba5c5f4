"""Balancing robot on a control moment gyroscope.

Description
    A body standing on a ground contact line along its forward axis can roll
    sideways. It carries two identical flywheels, each spinning at a constant
    rate ``Omega`` (held by its own motor) about its spin axis, mounted in
    gimbals that tilt together. Tilting the gimbals turns the flywheels'
    angular momentum and the gyroscopic reaction rights the body. The body
    is held in yaw and pitch by the ground, so the yaw torques of the two
    gimbals add and do no work. Derived by Lagrange's method from the bodies
    below (seed 002's rotation ``q = Rx(theta) Ry(phi) Rz(psi)``).

States
    ``theta`` body roll about its forward x axis from upright [rad];
    ``phi`` gimbal angle about the body's y axis [rad]; and their rates. The
    frames are the seed's: body ``Rx(theta)`` from the ground frame, gimbal
    ``Ry(phi)`` from the body, flywheel ``Rz(psi)`` from the gimbal with
    ``psi_dot = Omega``; heights are measured along the body's z axis,
    gravity along the ground's ``-z``. These signs give the seed's
    linearization.

Inputs
    ``tau`` total torque on the two gimbals about the body's y axis [N m]
    (positive turns ``phi`` positive); the body receives the reaction.

Parameters
    =========  =========  ==========  =====================================
    name       default    unit        meaning
    =========  =========  ==========  =====================================
    I_xy       1.63e-4    kg m^2      flywheel inertia about a transverse axis
    I_z        3.2e-4     kg m^2      flywheel inertia about its spin axis
    m_body     1.0        kg          body mass
    h_body     0.1        m           height of the body's centre of mass
    m_wheel    0.4        kg          mass of one flywheel
    h_wheel    0.15       m           height of the flywheels' centres
    I_body     0          kg m^2      body inertia about its centre of mass (roll)
    Omega      314        rad/s       flywheel spin rate (3000 rpm)
    B_w        1e-4       N m s/rad   gimbal friction
    g          9.81       m/s^2       gravity
    tau_min    -0.3       N m         gimbal torque lower limit
    tau_max    0.3        N m         gimbal torque upper limit
    =========  =========  ==========  =====================================

    With ``I_b = 2 m_wheel h_wheel^2 + m_body h_body^2 + I_body`` and
    ``p = g (2 m_wheel h_wheel + m_body h_body)`` the equations are the
    seed's::

        (2 I_xy cos^2 phi + 2 I_z sin^2 phi + I_b) theta_ddot
            = -2 (I_z - I_xy) theta_dot phi_dot sin(2 phi)
              - 2 I_z Omega phi_dot cos(phi) + p sin(theta)
        2 I_xy phi_ddot = (I_z - I_xy) theta_dot^2 sin(2 phi)
              + 2 I_z Omega theta_dot cos(phi) - B_w phi_dot + tau

    The gimbal frames' own inertia is neglected, as in the seed.

Operating point
    Upright, gimbal at 0, at rest, ``tau = 0``. Default outputs ``[phi,
    theta]`` (gimbal encoder, body IMU). The linearization there is the
    seed's, reordered to ``[theta, phi, theta_dot, phi_dot]``.

Energy
    The flywheel motors hold ``Omega`` against the gyroscopic torques and do
    work, so the total energy ``T + V`` is not conserved even without
    friction and input. The model's ``energy`` is the Jacobi integral
    ``h = T2 - T0 + V`` (``T2`` the part of the kinetic energy quadratic in
    ``theta_dot, phi_dot``, ``T0`` the part free of them, i.e. the spin
    energy ``I_z Omega^2``), conserved without friction and input; it
    changes at the rate ``phi_dot (tau - B_w phi_dot)``. The total energy is
    kept in the symbolic model's ``extras["total_energy"]``.

Source
    seeds/002, "Control moment gyroscope". Seed slips, found by derivation
    (none changes its final equations or linearization):

    - it writes ``psi`` where ``psi_dot`` is meant in the linearization lines,
      and ``I_h`` for ``I_b``;
    - several derivative lines of the linearization are mislabeled (``d/d
      theta`` for ``d/d theta_dot``, ``d/d theta_dot`` and ``d/d phi_dot``
      for ``d/d phi``), one line of ``d phi_ddot / d theta_dot`` omits the
      factor ``1 / (2 I_xy)``, and ``d phi_ddot / d phi`` drops a
      ``theta_dot`` from ``-2 I_z Omega theta_dot sin(phi)`` (all vanish or
      are fixed at the upright point, so its matrix is right);
    - its ``I_b`` leaves out the body's own inertia about its centre of mass
      (kept here as ``I_body``, default 0).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from equilibrist.mechanics.spec import (
    Input,
    OperatingPoint,
    Parameter,
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
    name="cmg_robot",
    title="Balancing robot on a control moment gyroscope",
    description=(
        "A body rolling sideways, righted by the gyroscopic torque of two gimballed flywheels."
    ),
    coordinates=("theta", "phi"),
    units={"theta": "rad", "phi": "rad"},
    parameters=(
        positive("I_xy", 1.63e-4, "kg*m^2", "flywheel inertia about a transverse axis",
                 note="desktop rig: brass disc, 80 mm diameter, 10 mm thick, 0.4 kg "
                      "(m r^2/4 + m h^2/12)"),
        positive("I_z", 3.2e-4, "kg*m^2", "flywheel inertia about its spin axis",
                 note="desktop rig: the same disc (m r^2/2)"),
        positive("m_body", 1.0, "kg", "body mass",
                 note="desktop rig: frame, battery and electronics"),
        positive("h_body", 0.1, "m", "height of the body's centre of mass above the ground line",
                 note="desktop rig estimate"),
        positive("m_wheel", 0.4, "kg", "mass of one flywheel", note="desktop rig: the brass disc"),
        positive("h_wheel", 0.15, "m", "height of the flywheels' centres above the ground line",
                 note="desktop rig estimate"),
        nonnegative("I_body", 0.0, "kg*m^2", "body inertia about its centre of mass (roll axis)",
                    note="SYSTEMS.md: default 0, as the seed"),
        Parameter("Omega", 314.0, "rad/s", "flywheel spin rate (each, about its z axis)",
                  note="desktop rig: 3000 rpm"),
        friction("B_w", 1e-4, "N*m*s/rad", "gimbal friction",
                    note="estimate for ball-bearing gimbals with a servo gearbox backdriven"),
        positive("g", 9.81, "m/s^2", "gravitational acceleration", note="standard gravity"),
    ),
    inputs=(Input("tau", "N*m", "total torque on the two gimbals", -0.3, 0.3),),
    outputs=("phi", "theta"),
    operating_point=OperatingPoint(state={}, inputs={"tau": 0.0}),
    source='seeds/002 "Control moment gyroscope"',
    seed_slips=(
        "psi written for psi_dot in the linearization lines; I_h for I_b",
        "mislabeled derivative lines in the linearization; one line of d phi_ddot / d theta_dot "
        "omits 1 / (2 I_xy); d phi_ddot / d phi drops a theta_dot (its matrix is right)",
        "I_b leaves out the body's own inertia (I_body, default 0)",
    ),
    notes=(
        "energy is the Jacobi integral T2 - T0 + V: the flywheel motors do work",
        "the gimbal frames' inertia is neglected, as in the seed",
    ),
    # The body hits the ground long before 90 degrees; past |phi| = pi/2 the
    # gyroscopic torque reverses and the gimbal cannot right the body.
    region={"theta": (-0.5, 0.5), "phi": (-1.4, 1.4)},
    symbols_latex={"Omega": r"\Omega", "B_w": "B_w", "I_xy": "I_{xy}"},
    # The body may lean 0.05 rad, the gimbal swing 0.5 rad; 0.1 N m of gimbal torque.
    design_scales={
        "theta": 0.05, "phi": 0.5, "theta_dot": 0.5, "phi_dot": 5.0, "tau": 0.1,
    },
    # Gimbal encoder 1.5 mrad; body roll from an IMU about 2 mrad.
    sensor_noise={"phi": 1.5e-3, "theta": 2e-3},
    # Flywheel imbalance shakes the body; servo torque ripple on the gimbal.
    process_noise={"theta_dot": 0.2, "phi_dot": 2.0},
    drawing="equilibrist.viz.scenes_3d:CmgRobotScene",
    scenario=Scenario(duration=8.0, start={"theta": 0.03}, push=0.15, push_duration=0.1,
        push_name="a kick of 0.15 N m on the gimbals for 0.1 s"),
    position=10,
)


@register(SPEC)
def derive(d: Derivation) -> SymbolicModel:
    import sympy as sp
    from sympy.physics import mechanics as me

    theta, phi = d.q
    thetad, phid = d.qd
    p, tau = d.p, d.u["tau"]
    g = p["g"]
    N, O = d.N, d.O
    body = N.orientnew("B", "Axis", (theta, N.x))
    body.set_ang_vel(N, thetad * N.x)
    gimbal = body.orientnew("G", "Axis", (phi, body.y))
    gimbal.set_ang_vel(body, phid * body.y)
    # The flywheel turns at the prescribed Omega about the gimbal's z axis.
    # It is symmetric about that axis, so its inertia is written in the gimbal
    # frame and its orientation angle never enters the model.
    wheel = gimbal.orientnew("W", "Axis", (sp.Symbol("psi"), gimbal.z))
    wheel.set_ang_vel(gimbal, p["Omega"] * gimbal.z)

    body_centre = O.locatenew("Cb", p["h_body"] * body.z)
    body_centre.v2pt_theory(O, N, body)
    # Both flywheels sit on the roll axis' normal at h_wheel; their offset
    # along the roll axis changes neither the kinetic nor the potential energy.
    wheel_centre = O.locatenew("Cw", p["h_wheel"] * body.z)
    wheel_centre.v2pt_theory(O, N, body)

    frame_body = me.RigidBody(
        "body", body_centre, body, p["m_body"], (me.inertia(body, p["I_body"], 0, 0), body_centre)
    )
    wheel_inertia = me.inertia(gimbal, p["I_xy"], p["I_xy"], p["I_z"])
    wheels = [
        me.RigidBody(f"wheel{k}", wheel_centre, wheel, p["m_wheel"], (wheel_inertia, wheel_centre))
        for k in (1, 2)
    ]
    bodies = [frame_body, *wheels]
    kinetic = sum((b.kinetic_energy(N) for b in bodies), sp.Integer(0))
    heights = [(p["m_body"], body_centre), (p["m_wheel"], wheel_centre), (p["m_wheel"], wheel_centre)]
    potential = sum((m * g * c.pos_from(O).dot(N.z) for m, c in heights), sp.Integer(0))
    lagrangian = kinetic - potential

    gimbal_torque = (tau - p["B_w"] * phid) * body.y
    loads = [
        # The gimbal drive and its friction act between gimbals and body; the
        # reaction on the body is about its y axis, which the ground holds.
        (gimbal, gimbal_torque),
        (body, -gimbal_torque),
    ]
    # Jacobi integral sum(q_dot dL/dq_dot) - L = T2 - T0 + V (L has no explicit time).
    jacobi = sum(
        (qd * lagrangian.diff(qd) for qd in (thetad, phid)), sp.Integer(0)
    ) - lagrangian
    jacobi = sp.simplify(sp.expand(jacobi))
    return d.lagrange(
        lagrangian,
        loads=loads,
        energy=jacobi,
        extras={"total_energy": kinetic + potential},
    )
