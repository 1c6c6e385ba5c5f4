"""Acrobot: two links in a vertical plane, actuated at the elbow only.

Description
    Link 1 turns freely about a fixed shoulder; link 2 turns about the far
    end of link 1, driven by a motor at that elbow. The shoulder has no
    motor: the acrobot balances upright (or swings up) by bending its elbow
    alone, as a gymnast on a high bar. Derived by Lagrange's method, in the
    coordinates of Gymnasium's ``Acrobot-v1``.

States
    ``theta1`` angle of link 1 from hanging straight down [rad],
    counter-clockwise; ``theta2`` angle of link 2 relative to link 1 [rad],
    counter-clockwise; their rates.

Inputs
    ``tau`` motor torque at the elbow [N m], counter-clockwise on link 2;
    link 1 receives ``-tau``.

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

    The defaults are Gymnasium ``Acrobot-v1``'s (``LINK_MOI`` for both
    inertias, which Gymnasium's "book" dynamics takes about each link's
    centre of mass). ``tau`` is limited to +-20 N m: Gymnasium's +-1 N m
    leaves the upright acrobot a region of attraction of about 0.01 rad
    (the default design's ideal loop, started off upright on ``theta1``
    alone, recovers from 0.005 rad and falls from 0.01 rad), too small to
    balance with any sensor noise; it stays available through
    ``--set tau_min=-1 --set tau_max=1``.

Sensors and rate
    An encoder of 4096 counts per turn on each joint: a quantization step of
    ``2 pi / 4096 = 1.53 mrad``, taken as uniform noise of standard
    deviation ``step / sqrt(12) = 0.44 mrad``. The controller runs at 200 Hz
    (Gymnasium's 5 Hz steps are far too slow to balance upright).

Operating point
    Both links upright (``theta1 = pi``, ``theta2 = 0``), at rest,
    ``tau = 0``. Default outputs ``[theta1, theta2]`` (the two encoders).
    A swing-up starts hanging, ``theta1 = theta2 = 0``.

Source
    Not in the seeds. Coordinates and defaults of Gymnasium ``Acrobot-v1``,
    whose "book" equations of motion (Sutton and Barto; Spong 1995) the
    derived model reproduces to round-off when ``b1 = b2 = 0``.
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


#: The acrobot's swing-up gains, in the rig's own scales (``control/swingup_scales.py``'s
#: ``plant_scales``, docs/swingup.md): k_D and k_P as shares of the bounds of Xin and Kaneda's
#: conditions (``k_d_bound``, ``k_p_bound``: the catalogue acrobot's former k_D = 30, k_P = 60),
#: the damping ratio ``zeta`` of the elbow's loop, and the pump from rest: a quarter of the
#: motor's room (``kick``) until the energy has risen by a hundredth of the lift
#: (``kick_energy``). One tuning for the catalogue's acrobot and DFKI's, whatever their size.
SWINGUP_GAINS: dict[str, float] = {
    "k_energy": 1.0, "k_d_bound": 1.0, "k_p_bound": 0.42, "zeta": 0.35,
    "kick": 0.25, "kick_energy": 0.01, "release_factor": 20.0,
}

SPEC = SystemSpec(
    name="acrobot",
    title="Acrobot (two links, elbow actuated)",
    description="Two links on a fixed shoulder balanced upright by a motor at the elbow alone.",
    coordinates=("theta1", "theta2"),
    units={"theta1": "rad", "theta2": "rad"},
    parameters=_two_link.parameters(),
    inputs=(Input("tau", "N*m", "motor torque at the elbow, counter-clockwise on link 2", -20.0, 20.0),),
    outputs=("theta1", "theta2"),
    operating_point=OperatingPoint(state=dict(_two_link.UPRIGHT), inputs={"tau": 0.0}),
    source="not in the seeds; Gymnasium Acrobot-v1 (its book dynamics)",
    notes=(
        "Gymnasium Acrobot-v1's coordinates: theta1 from hanging down, theta2 relative to link 1",
        "tau limited to +-20 N m; Gymnasium's +-1 N m leaves a region of attraction of about 0.01 rad",
    ),
    region=dict(_two_link.REGION),
    # Bryson: each angle may stray 0.1 rad and turn at 1 rad/s. The torque
    # scale (1.0 N m, a small share of the 20 N m limit) keeps the gains low
    # enough that sensor noise does not drive the motor into saturation.
    design_scales={
        "theta1": 0.1, "theta2": 0.1, "theta1_dot": 1.0, "theta2_dot": 1.0, "tau": 1.0,
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
    swingup=SwingUp("acrobot", SWINGUP_GAINS),
    drawing="equilibrist.viz.scenes_planar:AcrobotScene",
    position=11,
)


@register(SPEC)
def derive(d: Derivation) -> SymbolicModel:
    links = _two_link.two_links(d)
    loads = _two_link.joint_loads(d, links, elbow=d.u["tau"])
    return d.lagrange(links.kinetic - links.potential, loads=loads,
                      energy=links.kinetic + links.potential)
