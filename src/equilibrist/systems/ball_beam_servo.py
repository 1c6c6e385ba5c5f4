"""Ball and beam driven by a position-controlled servo.

Description
    The seed's reduced ball-and-beam: a servo (through the four-bar linkage
    of the ball-balancing platform) commands the beam's angle, so the beam
    follows its command kinematically and its inertia drops out. The input is
    the beam's angular rate. Derived, not typed: the ball's Lagrange equation
    along the beam is formed from the same geometry as ``ball_beam`` (solid
    ball rolling without slipping, spin from the rolling condition, rolling
    friction ``-b R_dot``) with ``theta`` a prescribed function of time, then
    ``theta_dot = omega``, ``theta_ddot = 0`` and ``d = 0`` are substituted.
    The result is the seed's form::

        theta_dot = omega
        R_ddot    = 5/7 (R omega^2 - g sin(theta) - (b/m) R_dot)

    The ball's radius cancels. The exact equation has a further term
    ``5/7 (d + 2/5 r) theta_ddot``: dropping it makes the model exact only
    while ``omega`` is constant (between changes of the command); a servo
    that changes its rate adds an unmodelled ball acceleration ``2/7 r
    d(omega)/dt`` (with ``d = 0``).

States
    ``theta`` beam angle from +x [rad], counter-clockwise positive; ``R``
    ball position along the beam [m]; ``R_dot`` [m/s]. There is no
    ``theta_dot`` state: it is the input. No mass matrix (a first-order
    model).

Inputs
    ``omega`` beam angular rate [rad/s], counter-clockwise.

Parameters
    =========  ========  ==========  ======================================
    name       default   unit        meaning
    =========  ========  ==========  ======================================
    m          0.064     kg          ball mass (solid sphere)
    b          0.005     N s/m       rolling friction along the beam
    g          9.81      m/s^2       gravity
    R_d        0         m           ball position of the operating point
    omega_min  -3        rad/s       beam rate lower limit
    omega_max  3         rad/s       beam rate upper limit
    =========  ========  ==========  ======================================

Operating point
    ``[theta, R, R_dot] = [0, R_d, 0]`` with ``omega = 0``. Default outputs
    ``[R, theta]``.

Energy
    None: the servo does whatever work the prescribed motion needs.

Source
    seeds/002, "Ball rolling on a rotated linear slide" (the reduced
    three-state models at the end of both sections). Seed slips, found by
    derivation: the offset section's large-``I`` reductions write
    ``-25/49 g`` and ``-25/49 b/m`` and its last form ``-g`` and ``-b/m``;
    the reduced model's coefficients are ``-5/7 g`` and ``-5/7 b/m`` (as the
    section without offset has them).
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
    name="ball_beam_servo",
    title="Ball and beam on a servo",
    description=(
        "A ball rolling on a beam whose angle a servo commands; the input is the beam's rate."
    ),
    # theta and R are the mechanical coordinates of the derivation; the state
    # is [theta, R, R_dot] because theta_dot is the input, not a state.
    coordinates=("theta", "R"),
    states=("theta", "R", "R_dot"),
    units={"theta": "rad", "R": "m"},
    parameters=(
        positive("m", 0.064, "kg", "ball mass (solid sphere)",
                 note="desktop rig: 25 mm steel ball, 7850 kg/m^3"),
        friction("b", 0.005, "N*s/m", "rolling friction along the beam",
                    note="estimate for a steel ball in an aluminium channel"),
        positive("g", 9.81, "m/s^2", "gravitational acceleration", note="standard gravity"),
        Parameter("R_d", 0.0, "m", "ball position of the operating point",
                  note="SYSTEMS.md: default 0 (ball at the pivot)"),
    ),
    inputs=(Input("omega", "rad/s", "beam angular rate, counter-clockwise", -3.0, 3.0),),
    outputs=("R", "theta"),
    operating_point=OperatingPoint(state={"theta": 0.0, "R": "R_d", "R_dot": 0.0},
                                   inputs={"omega": 0.0}),
    source='seeds/002 "Ball rolling on a rotated linear slide" (reduced three-state models)',
    seed_slips=(
        "the offset section's large-I reductions write -25/49 g, -25/49 b/m (and later "
        "-g, -b/m) for -5/7 g, -5/7 b/m",
    ),
    notes=(
        "drops the 5/7 (d + 2/5 r) theta_ddot term: exact only while omega is constant",
        "omega limits: a hobby servo (about 6 rad/s) through a linkage of ratio about 1/2",
    ),
    region={"theta": (-0.5, 0.5), "R": (-0.2, 0.2)},  # the ball leaves a 40 cm beam
    # The ball may stray 5 cm, the beam tilt 0.1 rad; rate commands of 1 rad/s.
    design_scales={"theta": 0.1, "R": 0.05, "R_dot": 0.2, "omega": 1.0},
    # Servo angle known to about 2 mrad; ball position sensor about 1 mm.
    sensor_noise={"R": 1e-3, "theta": 2e-3},
    # Surface roughness and the neglected theta_ddot push on the ball.
    process_noise={"R_dot": 0.05},
    drawing="equilibrist.viz.scenes_planar:BallBeamScene",
    scenario=Scenario(duration=8.0, start={"R": -0.05}, push=2.0, push_duration=0.1,
        step={"R": 0.05}, step_at=1.0,
        push_name="a jolt of 2 rad/s on the beam's rate for 0.1 s",
        note="The jolt acts on the servo's rate, which this model takes "
        "as exact: the design gives the beam angle almost no process "
        "noise (only a floor), so the Kalman filter trusts its "
        "prediction over the encoder and its estimate of theta (dashed) "
        "takes seconds to rejoin the truth; the ball recovers as "
        "slowly."),
    position=8,
)


@register(SPEC)
def derive(d: Derivation) -> SymbolicModel:
    import sympy as sp
    from sympy.physics import mechanics as me

    from equilibrist.systems._ball import rolling_ball

    theta, R = d.q
    thetad, Rd = d.qd
    t = d.t
    p, omega = d.p, d.u["omega"]
    m, g = p["m"], p["g"]
    # The ball's radius and offset enter the exact equation and are set or
    # cancel below; they are not parameters of the reduced model.
    r, offset = sp.symbols("r d_offset", positive=True)
    N, O = d.N, d.O
    rolling = rolling_ball(N, O, theta, thetad, R, m=m, r=r, offset=offset, name="ball_beam_servo")
    B, ball, centre, beam_point = rolling.beam_frame, rolling.ball, rolling.centre, rolling.beam_point
    lagrangian = ball.kinetic_energy(N) - m * g * centre.pos_from(O).dot(N.y)
    friction = -p["b"] * Rd * B.x
    # theta is not a coordinate here: it is prescribed, so only R has an equation.
    lm = me.LagrangesMethod(
        lagrangian, [R], forcelist=[(centre, friction), (beam_point, -friction)], frame=N
    )
    (eom,) = lm.form_lagranges_equations()
    servo = {thetad.diff(t): 0, thetad: omega, offset: 0}
    eom = d.plain(me.msubs(eom, servo))
    R_ddot = sp.Symbol("R_ddot", real=True)
    (accel,) = sp.solve(eom, R_ddot)
    accel = sp.factor_terms(sp.simplify(accel))
    if r in accel.free_symbols:
        raise RuntimeError("ball_beam_servo: the ball's radius did not cancel")
    rate = sp.Symbol("R_dot", real=True)
    return d.first_order(sp.Matrix([omega, rate, accel]), method="Lagrange (theta prescribed)")
