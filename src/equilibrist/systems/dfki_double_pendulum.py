"""DFKI's double pendulum (RealAIGym's rig), design C.1: an acrobot or a pendubot.

Description
    The double pendulum of DFKI's Underactuated Lab, the rig of the RealAIGym benchmark:
    two links on a fixed shoulder, each joint with a geared motor (a 6:1 quasi-direct
    drive), one of which is switched off. ``robot = acrobot`` (the default) drives the
    elbow alone, ``robot = pendubot`` the shoulder alone
    (``get_system("dfki_double_pendulum", robot="pendubot")``, ``--set robot=pendubot``).
    Parameterized as the rig is identified (inertias about the joints, the rotors' inertia
    behind the gear, viscous damping of either sign, smooth Coulomb friction), with the
    identified values of design C.1, model 1.0; any identified parameter file of the rig
    (its ``model_parameters.yml``) binds as it is
    (:func:`equilibrist.systems.dfki_parameters.read_model_parameters`).

States
    ``theta1`` angle of link 1 from hanging straight down [rad], counter-clockwise (the
    rig's ``q1``); ``theta2`` angle of link 2 relative to link 1 [rad] (the rig's ``q2``);
    their rates. The rig's state ``[q1, q2, q1_dot, q2_dot]`` is this state, in order, and
    these are the catalogue ``acrobot``'s coordinates.

Inputs
    ``tau`` motor torque [N m]: the acrobot's at the elbow, counter-clockwise on link 2
    (the rig's ``u2``, its ``u1`` zero); the pendubot's at the shoulder, counter-clockwise
    on link 1 (the rig's ``u1``, its ``u2`` zero).

Parameters
    ======  ===============  ==========  ============================================
    name    default          unit        meaning
    ======  ===============  ==========  ============================================
    m1      0.5235           kg          link 1 mass (with the elbow's motor)
    m2      0.6256           kg          link 2 mass
    l1      0.2              m           link 1 length (shoulder to elbow)
    l2      0.3              m           link 2 length (drawing and height only)
    r1      0.2              m           shoulder to link 1 centre of mass
    r2      0.2557           m           elbow to link 2 centre of mass
    I1      0.03189          kg m^2      link 1 inertia about the shoulder
    I2      0.05087          kg m^2      link 2 inertia about the elbow
    Ir      0 (6.287e-05)    kg m^2      each motor's rotor inertia, before its gear
    gr      6                1           each motor's gear ratio
    b1      0 (0.001)        N m s/rad   shoulder viscous friction, either sign
    b2      0 (0.001)        N m s/rad   elbow viscous friction, either sign
    cf1     0 (0.16)         N m         shoulder Coulomb friction, cf1 atan(100 q1_dot),
                                         either sign
    cf2     0 (0.12)         N m         elbow Coulomb friction, cf2 atan(100 q2_dot),
                                         either sign
    g       9.81             m/s^2       gravity
    ======  ===============  ==========  ============================================

    ``tau`` is limited to +-6 N m, the torque limit of RealAIGym's v2 boards (the
    motors' own is 10 N m: ``--set tau_max=10``). ``Ir``, ``b`` and ``cf`` default to zero,
    as the boards' simulation sets them (the identified values in parentheses: ``--set
    Ir=6.287e-05 --set b1=0.001 --set b2=0.001 --set cf1=0.16 --set cf2=0.12``, or the
    model's parameter file): with them the default LQR at +-6 N m loses the rig from a
    0.01 rad tilt, as a linear design that does not know the friction must. The smooth Coulomb law acts as a viscous ``100 cf`` in a linearization at
    rest. Inertias about the joints below ``m r^2`` (no rigid body, as identifications may
    give) are taken as they are: the equations need only ``M`` definite.

Equations
    Lagrange's, in plain symbols: the kinetic energy of link 1 about the shoulder
    (``I1``), of link 2 (``I2`` about the elbow, its centre of mass ``r2`` beyond it) and
    of the two rotors behind their gears (the shoulder's turning at ``gr q1_dot``, the
    elbow's, carried by link 1, at ``q1_dot - gr q2_dot``: the ``gr^2 Ir + Ir`` and
    ``-gr Ir`` terms of the rig's mass matrix); the potential of the two centres of mass;
    each joint's friction ``b q_dot + cf atan(100 q_dot)`` against its relative rate (the
    rig's plant's smooth Coulomb law, which tends to ``cf pi / 2``).

Sensors and rate
    Both joints' encoders: 14 bits on each motor's rotor behind the 6:1 gear, a step of
    ``2 pi / (6 * 2^14) = 64 urad``, taken as uniform noise of standard deviation
    ``step / sqrt(12) = 18 urad`` (the boards' simulation has none). The controller runs
    at 500 Hz, the rig's and the benchmark's rate.

Operating point
    Both links upright (``theta1 = pi``, ``theta2 = 0``), at rest, ``tau = 0``. A
    swing-up starts hanging at rest, ``theta1 = theta2 = 0``.

Source
    Not in the seeds. DFKI RIC Underactuated Lab, ``double_pendulum`` (RealAIGym), design
    C.1, model 1.0 identified parameters and its plant's equations, which the derived
    model reproduces to round-off (``bench/bench_realaigym.py --plant``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from equilibrist.mechanics.friction import coulomb_friction
from equilibrist.mechanics.spec import (
    Input,
    OperatingPoint,
    Parameter,
    SwingUp,
    SystemSpec,
    nonnegative,
    positive,
)
from equilibrist.systems.acrobot import SWINGUP_GAINS as ACROBOT_GAINS
from equilibrist.systems.pendubot import SWINGUP_GAINS as PENDUBOT_GAINS
from equilibrist.systems.registry import register

if TYPE_CHECKING:  # sympy is imported only when the model is derived

    from equilibrist.mechanics.model import Derivation, SymbolicModel

_ID = "design C.1, model 1.0 (model_parameters.yml)"

#: The identified values of design C.1, model 1.0, by the file's names.
MODEL_1_0: dict[str, float] = {
    "m1": 0.5234602302310271, "m2": 0.6255677234174437, "l1": 0.2, "l2": 0.3,
    "r1": 0.2, "r2": 0.25569305436052964, "I1": 0.031887199591513114,
    "I2": 0.05086984812807257, "Ir": 6.287203962819607e-05, "gr": 6.0,
    "b1": 0.001, "b2": 0.001, "cf1": 0.16, "cf2": 0.12, "g": 9.81,
}

#: The catalogue's defaults: model 1.0 with the rotors and the frictions at zero, as
#: RealAIGym's v2 boards simulate the rig (the identified values: ``MODEL_1_0``).
DEFAULTS: dict[str, float] = {**MODEL_1_0, "Ir": 0.0, "b1": 0.0, "b2": 0.0, "cf1": 0.0,
                              "cf2": 0.0}

#: The torque limit of the actuated joint on RealAIGym's v2 boards [N*m] (the file's
#: ``tl1``, ``tl2`` are the motors' 10 N*m).
TORQUE_LIMIT = 6.0

#: The control rate of the rig and the benchmark (a 2 ms step) [Hz].
RATE = 500.0

# The motors' 14-bit encoders on the rotor, behind the 6:1 gear: 6 * 2**14 counts per turn
# of a joint, taken as uniform noise of std step / sqrt(12).
_ENCODER = 2.0 * math.pi / (6 * 2**14) / math.sqrt(12.0)


def _damping(name: str, joint: str) -> Parameter:
    # Identified damping may come out negative (the benchmark varies it through zero): any
    # finite value is taken; it is a friction of the energy contract (zero: conserved).
    return Parameter(name, DEFAULTS[name], "N*m*s/rad",
                     f"{joint} viscous friction (torque -{name} q_dot on the joint), either sign",
                     note=_ID, dissipative=True)


def _coulomb(name: str, joint: str, rate: str) -> Parameter:
    # Either sign too: the benchmark's robustness runs vary it through zero.
    return Parameter(name, DEFAULTS[name], "N*m",
                     f"{joint} Coulomb friction, {name} atan(100 {rate}), either sign",
                     note=_ID, dissipative=True, coulomb=True)


def parameters() -> tuple[Parameter, ...]:
    """The rig's parameters with the identified values of design C.1, model 1.0."""
    v = DEFAULTS
    return (
        positive("m1", v["m1"], "kg", "link 1 mass (with the elbow's motor)", note=_ID),
        positive("m2", v["m2"], "kg", "link 2 mass", note=_ID),
        positive("l1", v["l1"], "m", "link 1 length (shoulder to elbow)", note=_ID),
        positive("l2", v["l2"], "m", "link 2 length (drawing and the benchmark's height only)",
                 note=_ID),
        nonnegative("r1", v["r1"], "m", "shoulder to link 1 centre of mass", note=_ID),
        nonnegative("r2", v["r2"], "m", "elbow to link 2 centre of mass", note=_ID),
        positive("I1", v["I1"], "kg*m^2", "link 1 inertia about the shoulder", note=_ID),
        positive("I2", v["I2"], "kg*m^2", "link 2 inertia about the elbow", note=_ID),
        nonnegative("Ir", v["Ir"], "kg*m^2", "each motor's rotor inertia (before its gear)",
                    note=f"{_ID}: {MODEL_1_0['Ir']:g}; 0 on the v2 boards"),
        positive("gr", v["gr"], "1", "each motor's gear ratio", note=_ID),
        _damping("b1", "shoulder"),
        _damping("b2", "elbow"),
        _coulomb("cf1", "shoulder", "q1_dot"),
        _coulomb("cf2", "elbow", "q2_dot"),
        positive("g", v["g"], "m/s^2", "gravitational acceleration", note=_ID),
    )


#: Both links upright: link 1 turned half a turn from hanging, link 2 in line.
UPRIGHT: dict[str, float | str] = {"theta1": math.pi}

#: A fall: link 1 more than a quarter turn from upright, or the elbow bent more.
REGION = {"theta1": (math.pi / 2, 3 * math.pi / 2), "theta2": (-math.pi / 2, math.pi / 2)}


def _derive(d: Derivation, *, shoulder: bool) -> SymbolicModel:
    """The rig's equations with the motor at the shoulder (*shoulder*) or at the elbow."""
    import sympy as sp

    (q1, q2), (w1, w2) = d.coordinates()
    p = d.p
    # Link 2's centre of mass moves at l1 w1 (across link 1) plus r2 (w1 + w2) (across
    # link 2): its kinetic energy about the elbow is I2 (w1 + w2)^2 / 2 plus the cross term
    # and the elbow's own motion.
    w12 = w1 + w2
    kinetic = (p["I1"] * w1**2 / 2 + p["I2"] * w12**2 / 2 + p["m2"] * p["l1"] ** 2 * w1**2 / 2
               + p["m2"] * p["l1"] * p["r2"] * sp.cos(q2) * w1 * w12
               + p["Ir"] * (p["gr"] * w1) ** 2 / 2 + p["Ir"] * (w1 - p["gr"] * w2) ** 2 / 2)
    potential = -p["g"] * (p["m1"] * p["r1"] * sp.cos(q1)
                           + p["m2"] * (p["l1"] * sp.cos(q1) + p["r2"] * sp.cos(q1 + q2)))
    tau = d.u["tau"]
    forces = [-p["b1"] * w1 - coulomb_friction(w1, p["cf1"]) + (tau if shoulder else 0),
              -p["b2"] * w2 - coulomb_friction(w2, p["cf2"]) + (0 if shoulder else tau)]
    q, w = [q1, q2], [w1, w2]
    mass = sp.Matrix(2, 2, lambda i, j: sp.diff(kinetic, w[i], w[j]))
    momentum = sp.Matrix([sp.diff(kinetic, wi) for wi in w])
    # Lagrange: M q_ddot = Q - dV/dq + dT/dq - (d/dq (dT/dq_dot)) q_dot.
    forcing = sp.Matrix([
        forces[i] - sp.diff(potential, q[i]) + sp.diff(kinetic, q[i])
        - sum((sp.diff(momentum[i], q[j]) * w[j] for j in range(2)), sp.Integer(0))
        for i in range(2)])
    elbow = sp.Matrix([p["l1"] * sp.sin(q1), -p["l1"] * sp.cos(q1), 0])
    tip = elbow + sp.Matrix([p["l2"] * sp.sin(q1 + q2), -p["l2"] * sp.cos(q1 + q2), 0])
    return d.from_mass_matrix(
        "Lagrange", mass, forcing, energy=kinetic + potential,
        points={"shoulder": sp.zeros(3, 1), "elbow": elbow, "tip": tip},
        links=[("shoulder", "elbow"), ("elbow", "tip")])


def _spec(robot: str, joint: str, link: str, drawing: str,
          gains: dict[str, float]) -> SystemSpec:
    """The spec of one variant: the motor at *joint*, turning *link*."""
    return SystemSpec(
        name="dfki_double_pendulum",
        variant=("robot", robot),
        title=f"DFKI double pendulum, {robot} (RealAIGym, design C.1)",
        description=f"DFKI's identified double-pendulum rig with the motor at the {joint} alone.",
        coordinates=("theta1", "theta2"),
        units={"theta1": "rad", "theta2": "rad"},
        parameters=parameters(),
        inputs=(Input("tau", "N*m", f"motor torque at the {joint}, counter-clockwise on {link}",
                      -TORQUE_LIMIT, TORQUE_LIMIT),),
        outputs=("theta1", "theta2"),
        operating_point=OperatingPoint(state=dict(UPRIGHT), inputs={"tau": 0.0}),
        source="not in the seeds; DFKI double_pendulum (RealAIGym), design C.1, model 1.0",
        notes=(
            "the rig's coordinates: theta1 = q1 from hanging down, theta2 = q2 relative to link 1",
            "parameters as the rig identifies them: inertias about the joints, Ir behind the gear",
            "tau limited to +-6 N m, RealAIGym's v2 boards' limit",
        ),
        region=dict(REGION),
        # Bryson: each angle may stray 0.1 rad and turn at 1 rad/s; the torque scale is a
        # small share of the 6 N m limit.
        design_scales={"theta1": 0.1, "theta2": 0.1, "theta1_dot": 1.0, "theta2_dot": 1.0,
                       "tau": 0.5},
        sensor_noise={"theta1": _ENCODER, "theta2": _ENCODER},
        # Random torques of some 0.01 N m sqrt(s) (the gears' cogging, cable drag): the
        # rates wander by about 0.01 rad/s in a second.
        process_noise={"theta1_dot": 0.01, "theta2_dot": 0.01},
        control_rate=RATE,
        hanging={"theta1": 0.0, "theta2": 0.0},
        swingup=SwingUp(robot, dict(gains)),
        drawing=f"equilibrist.viz.scenes_planar:{drawing}",
        position=13,
    )


# The acrobot's LQR at +-6 N m catches from a thin ellipse (232 N m per radian of link 1): the
# supervisor catches at 50 times its saturation level, where the saturating LQR still holds.
SPEC_ACROBOT = _spec("acrobot", "elbow", "link 2", "AcrobotScene",
                     {**ACROBOT_GAINS, "catch_fraction": 50.0})
SPEC_PENDUBOT = _spec("pendubot", "shoulder", "link 1", "TwoLinkScene", PENDUBOT_GAINS)


@register(SPEC_ACROBOT, default=True)
def derive_acrobot(d: Derivation) -> SymbolicModel:
    return _derive(d, shoulder=False)


@register(SPEC_PENDUBOT)
def derive_pendubot(d: Derivation) -> SymbolicModel:
    return _derive(d, shoulder=True)
