"""Ball rolling on a rotating beam.

Description
    A beam turns about a fixed pivot under a motor torque; a solid ball rolls
    on it without slipping. The ball's centre sits at height ``d`` above the
    line through the pivot along the beam. The model is exact: the ball's
    spin follows from the rolling condition (not assumed), so ``d = 0`` is
    the seed's section without offset done without its approximation.
    Derived by Lagrange's method from the bodies and forces below.

States
    ``theta`` beam angle from +x [rad], counter-clockwise positive; ``R``
    ball position along the beam from the pivot [m]; and their rates. A beam
    tilted counter-clockwise (``theta > 0``) lets the ball roll towards
    ``-R``.

Inputs
    ``tau`` torque on the beam [N m], counter-clockwise.

Parameters
    ======  ========  ==========  ==========================================
    name    default   unit        meaning
    ======  ========  ==========  ==========================================
    m       0.064     kg          ball mass (solid sphere)
    r       0.0125    m           ball radius
    I       0.005     kg m^2      beam inertia about the pivot
    d       0         m           height of the ball centre above the pivot line
    b       0.005     N s/m       rolling friction along the beam
    g       9.81      m/s^2       gravity
    R_d     0         m           ball position of the operating point
    tau_min -0.5      N m         torque lower limit
    tau_max 0.5       N m         torque upper limit
    ======  ========  ==========  ==========================================

    Geometry: ball centre at ``(R cos(theta) - d sin(theta), R sin(theta) +
    d cos(theta))``, contact point a radius below it, towards the beam. Rolling
    without slipping gives the ball's absolute spin ``theta_dot - R_dot / r``
    (counter-clockwise). The beam's centre of mass is on the pivot. The
    rolling friction is a force ``-b R_dot`` on the ball's centre along the
    beam, with its reaction ``+b R_dot`` on the beam along the same line, so
    the pair dissipates ``b R_dot^2`` and exerts no net torque on ``theta``.

Operating point
    Level beam, ball at rest at ``R = R_d``, held by the torque that balances
    the ball's weight (solved for; ``tau = m g R_d`` whatever ``d``, since
    ``d sin(theta)`` vanishes on a level beam). Default outputs ``[R,
    theta]`` (ball position sensor, beam encoder).

Energy
    Kinetic (beam, ball translation and spin) plus potential energy of the
    ball; it changes at the rate ``tau theta_dot - b R_dot^2``.

Source
    seeds/002, "Ball rolling on a rotated linear slide", with and without
    offset. Seed slips, found by derivation:

    - the section without offset approximates the spin by ``R_dot / r``
      (dropping ``theta_dot``), which makes its mass matrix diagonal; the
      exact spin ``theta_dot - R_dot / r`` couples ``theta_ddot`` and
      ``R_ddot`` through ``(d + 2/5 r)``;
    - its input column ``[0, 1, m R^2 + I, 0, 0]`` means ``1 / (m R^2 + I)``;
      its ``m`` is called the mass "of the pendulum part" (it is the ball's);
    - in the section with offset one intermediate line has ``2/3`` for ``2/5``;
    - its linearization for ``R_d != 0`` carries spurious terms ``H21``,
      ``H41`` and an extra ``tau`` column: they differentiate the ``1/det``
      factor, which multiplies the accelerations, zero at the equilibrium. The
      right linearization is the ``R_d = 0`` form with ``R_d^2`` added to the
      beam's effective inertia ``I/m + d^2 + 2/5 r^2`` wherever it occurs
      (in ``det`` and in the ``R_ddot`` row). The ``R_d = 0`` form is right;
    - its large-``I`` limits write ``-25/49 g`` and ``-25/49 b/m`` (and later
      ``-g``, ``-b/m``) where the limit is ``-5/7 g`` and ``-5/7 b/m``.
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
    positive,
)
from equilibrist.systems.registry import register

if TYPE_CHECKING:  # sympy is imported only when the model is derived
    from equilibrist.mechanics.model import Derivation, SymbolicModel

SPEC = SystemSpec(
    name="ball_beam",
    title="Ball and beam",
    description="A solid ball rolling on a beam that a motor turns about a central pivot.",
    coordinates=("theta", "R"),
    units={"theta": "rad", "R": "m"},
    parameters=(
        positive("m", 0.064, "kg", "ball mass (solid sphere)",
                 note="desktop rig: 25 mm steel ball, 7850 kg/m^3"),
        positive("r", 0.0125, "m", "ball radius", note="desktop rig: 25 mm steel ball"),
        positive("I", 0.005, "kg*m^2", "beam inertia about the pivot",
                 note="desktop rig: 0.2 kg, 50 cm aluminium channel (m L^2/12 = 0.0042) "
                      "plus its hub"),
        Parameter("d", 0.0, "m", "height of the ball centre above the pivot line along the beam",
                  note="SYSTEMS.md: default 0 (the seed's section without offset)"),
        friction("b", 0.005, "N*s/m", "rolling friction along the beam",
                    note="estimate for a steel ball in an aluminium channel"),
        positive("g", 9.81, "m/s^2", "gravitational acceleration", note="standard gravity"),
        Parameter("R_d", 0.0, "m", "ball position of the operating point",
                  note="SYSTEMS.md: default 0 (ball at the pivot)"),
    ),
    inputs=(Input("tau", "N*m", "torque on the beam, counter-clockwise", -0.5, 0.5),),
    outputs=("R", "theta"),
    operating_point=OperatingPoint(state={"theta": 0.0, "R": "R_d"}, free=("tau",)),
    source='seeds/002 "Ball rolling on a rotated linear slide" (with and without offset)',
    seed_slips=(
        "the section without offset approximates the spin by R_dot / r; the exact spin is "
        "theta_dot - R_dot / r",
        "the input column [0, 1, m R^2 + I, 0, 0] means 1 / (m R^2 + I)",
        "one intermediate line of the offset section has 2/3 for 2/5",
        "the R_d != 0 linearization carries spurious H21, H41 terms and an extra tau column "
        "(derivatives of 1/det, which multiplies zero accelerations at the equilibrium)",
        "the large-I limits write -25/49 g, -25/49 b/m (and -g, -b/m) for -5/7 g, -5/7 b/m",
    ),
    notes=(
        "the rolling friction acts between the ball's centre and the beam: no net torque "
        "on theta, dissipation b R_dot^2",
    ),
    region={"theta": (-0.5, 0.5), "R": (-0.25, 0.25)},  # the ball leaves a 50 cm beam
    # The ball may stray 5 cm and the beam tilt 0.1 rad; torque corrections of 0.2 N m.
    design_scales={
        "theta": 0.1, "R": 0.05, "theta_dot": 0.5, "R_dot": 0.2, "tau": 0.2,
    },
    # Beam encoder 1.5 mrad; resistive-wire or camera ball position about 1 mm.
    sensor_noise={"R": 1e-3, "theta": 1.5e-3},
    # Motor torque ripple on the beam; surface roughness under the ball.
    process_noise={"theta_dot": 0.1, "R_dot": 0.05},
    drawing="equilibrist.viz.scenes_planar:BallBeamScene",
    scenario=Scenario(duration=8.0, start={"R": -0.05}, push=0.2, push_duration=0.1,
        step={"R": 0.05}, step_at=1.0,
        push_name="a torque kick of 0.2 N m on the beam for 0.1 s"),
    position=7,
)


@register(SPEC)
def derive(d: Derivation) -> SymbolicModel:
    import sympy as sp
    from sympy.physics import mechanics as me

    from equilibrist.systems._ball import rolling_ball

    theta, R = d.q
    thetad, Rd = d.qd
    p, tau = d.p, d.u["tau"]
    m, r, g = p["m"], p["r"], p["g"]
    N, O = d.N, d.O
    rolling = rolling_ball(N, O, theta, thetad, R, m=m, r=r, offset=p["d"], name="ball_beam")
    B, ball, centre, beam_point = rolling.beam_frame, rolling.ball, rolling.centre, rolling.beam_point

    beam = me.RigidBody("beam", O, B, sp.Integer(0), (me.inertia(B, 0, 0, p["I"]), O))
    potential = m * g * centre.pos_from(O).dot(N.y)
    kinetic = beam.kinetic_energy(N) + ball.kinetic_energy(N)
    friction = -p["b"] * Rd * B.x
    loads = [
        (centre, friction),
        (beam_point, -friction),
        (B, tau * N.z),
    ]
    return d.lagrange(kinetic - potential, loads=loads, energy=kinetic + potential)
