"""Pendubot: two links in a vertical plane, actuated at the shoulder only.

Description
    Link 1 turns about a fixed shoulder driven by a motor; link 2 turns
    freely about the far end of link 1. The elbow has no motor: the pendubot
    balances link 2 upright by moving link 1. Derived by Lagrange's method,
    in the coordinates of Gymnasium's ``Acrobot-v1`` (the same mechanism as
    the acrobot with the motor moved to the other joint).

States
    ``theta1`` angle of link 1 from hanging straight down [rad],
    counter-clockwise; ``theta2`` angle of link 2 relative to link 1 [rad],
    counter-clockwise; their rates.

Inputs
    ``tau`` motor torque at the shoulder [N m], counter-clockwise on link 1.

Parameters
    ======  ========  ==========  ==================================================
    name    default   unit        meaning
    ======  ========  ==========  ==================================================
    l1      1.0       m           link 1 length (shoulder to elbow)
    l2      1.0       m           link 2 length (drawing only)
    lc1     0.5       m           shoulder to link 1 centre of mass
    lc2     0.5       m           elbow to link 2 centre of mass
    m1      1.0       kg          link 1 mass
    m2      1.0       kg          link 2 mass
    I1      1.0       kg m^2      link 1 inertia about its centre of mass
    I2      1.0       kg m^2      link 2 inertia about its centre of mass
    b1      0         N m s/rad   shoulder friction (torque -b1 theta1_dot on link 1)
    b2      0         N m s/rad   elbow friction (torque -b2 theta2_dot on link 2,
                                  the opposite on link 1)
    g       9.8       m/s^2       gravity
    ======  ========  ==========  ==================================================

    The defaults are Gymnasium ``Acrobot-v1``'s, as the acrobot's.
    ``tau`` is limited to +-10 N m.

Sensors and rate
    An encoder of 4096 counts per turn on each joint: a quantization step of
    ``2 pi / 4096 = 1.53 mrad``, taken as uniform noise of standard
    deviation ``step / sqrt(12) = 0.44 mrad``. The controller runs at 200 Hz.

Operating point
    Both links upright (``theta1 = pi``, ``theta2 = 0``), at rest,
    ``tau = 0``. Default outputs ``[theta1, theta2]`` (the two encoders).
    A swing-up starts hanging, ``theta1 = theta2 = 0``: Fantoni, Lozano and
    Spong's energy law on the shoulder's collocated partial feedback
    linearization, its gains in the rig's own scales (docs/swingup.md).

Source
    Not in the seeds. Coordinates and defaults of Gymnasium ``Acrobot-v1``;
    the equations are the standard two-link manipulator's (Spong, Hutchinson
    and Vidyasagar, "Robot Modeling and Control") with the torque at the
    first joint.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from equilibrist.mechanics.spec import Input, OperatingPoint, SwingUp, SystemSpec
from equilibrist.systems import _two_link
from equilibrist.systems.registry import register

if TYPE_CHECKING:  # sympy is imported only when the model is derived
    from equilibrist.mechanics.model import Derivation, SymbolicModel

# 4096-count encoders: the quantization step, uniform noise of std step / sqrt(12).
_ENCODER = 2.0 * math.pi / 4096 / math.sqrt(12.0)
#: The pendubot's swing-up gains, in the rig's own scales (as the acrobot's): k_D at 1.3 times its bound, k_P such that hanging at rest (half a turn
#: from upright) the law's stiffness asks 0.3 of the motor's room (``k_p_torque``), and the
#: pump with the whole room until the energy has risen by 0.3 of the lift.
SWINGUP_GAINS: dict[str, float] = {
    "k_energy": 1.0, "k_d_bound": 1.3, "k_p_torque": 0.3, "zeta": 0.5,
    "kick": 1.0, "kick_energy": 0.3, "release_factor": 20.0,
}

SPEC = SystemSpec(
    name="pendubot",
    title="Pendubot (two links, shoulder actuated)",
    description="Two links on a motor-driven shoulder balancing a free second link upright.",
    coordinates=("theta1", "theta2"),
    units={"theta1": "rad", "theta2": "rad"},
    parameters=_two_link.parameters(),
    inputs=(Input("tau", "N*m", "motor torque at the shoulder, counter-clockwise on link 1", -10.0, 10.0),),
    outputs=("theta1", "theta2"),
    operating_point=OperatingPoint(state=dict(_two_link.UPRIGHT), inputs={"tau": 0.0}),
    source="not in the seeds; Gymnasium Acrobot-v1 coordinates and defaults; Spong's two-link arm",
    notes=(
        "Gymnasium Acrobot-v1's coordinates: theta1 from hanging down, theta2 relative to link 1",
    ),
    region=dict(_two_link.REGION),
    # Bryson: each angle may stray 0.1 rad and turn at 1 rad/s. The torque
    # scale (0.5 N m, a small share of the 10 N m limit) keeps the gains low
    # enough that sensor noise does not drive the motor into saturation.
    design_scales={
        "theta1": 0.1, "theta2": 0.1, "theta1_dot": 1.0, "theta2_dot": 1.0, "tau": 0.5,
    },
    sensor_noise={"theta1": _ENCODER, "theta2": _ENCODER},
    # Random torques of about 0.05 N m sqrt(s) (bearing drag, the motor's
    # cogging): the rates wander by some 0.01 rad/s in a second. The loop
    # rejects such noise slowly (a closed-loop pair near -2 /s stays there
    # however heavily the angles are weighted), so the links wander by a
    # few degrees about upright.
    process_noise={"theta1_dot": 0.01, "theta2_dot": 0.01},
    control_rate=200.0,
    # Both joints are offset at the start of a swing-up.
    hanging={"theta1": 0.0, "theta2": 0.0},
    swingup=SwingUp("pendubot", SWINGUP_GAINS),
    drawing="equilibrist.viz.scenes_planar:TwoLinkScene",
    position=12,
)


@register(SPEC)
def derive(d: Derivation) -> SymbolicModel:
    links = _two_link.two_links(d)
    loads = _two_link.joint_loads(d, links, shoulder=d.u["tau"])
    return d.lagrange(links.kinetic - links.potential, loads=loads,
                      energy=links.kinetic + links.potential)
