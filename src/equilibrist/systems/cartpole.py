"""Inverted pendulum on a cart.

Description
    A cart on a straight horizontal track carries a rigid pole on a revolute
    joint. The cart is pushed by a horizontal force; the pole is balanced
    upright. Derived by Kane's method, as seed 001 does ("road-map" style).

States
    ``x`` cart position [m] (+x to the right), ``theta`` pole angle from
    vertical-up [rad], positive clockwise (the pole leaning towards +x; seed
    001: "angle from n_y to b_y with -n_z sense"), and their rates.

Inputs
    ``F`` horizontal force on the cart [N], +x.

Parameters
    ======  ========  ========  ==========================================
    name    default   unit      meaning
    ======  ========  ========  ==========================================
    m_c     10        kg        cart mass
    m_p     1         kg        pole mass
    l       0.5       m         pivot to pole centre of mass
    I_p     0.08333   kg m^2    pole inertia about its centre of mass
    b_c     0         N s/m     cart viscous friction (force -b_c x_dot)
    b_p     0         N m s     pivot viscous friction (torque -b_p theta_dot)
    g       9.8       m/s^2     gravity
    x_max   1         m         half length of the track (swing-up task)
    ======  ========  ========  ==========================================

Operating point
    Upright at rest, ``F = 0``. Default outputs ``[x, theta]`` (cart and
    pivot encoders).

Source
    seeds/001 (chapter 27, with its parameter table), seeds/002 ("cart-pole").
    Seed 002 writes the pole's full length ``l1`` (centre of mass at ``l1/2``)
    and, by a slip, ``l1`` where the inertia ``I1`` is meant; here ``l`` is
    the pivot-to-centre-of-mass distance and ``I_p`` the inertia.
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

SPEC = SystemSpec(
    name="cartpole",
    title="Inverted pendulum on a cart",
    description="A cart on a horizontal track balancing a pole on a revolute joint.",
    coordinates=("x", "theta"),
    units={"x": "m", "theta": "rad"},
    parameters=(
        positive("m_c", 10.0, "kg", "cart mass", note="seed 001 table"),
        positive("m_p", 1.0, "kg", "pole mass", note="seed 001 table"),
        positive("l", 0.5, "m", "pivot to pole centre of mass", note="seed 001 table"),
        nonnegative("I_p", 0.08333, "kg*m^2", "pole inertia about its centre of mass", note="seed 001 table"),
        friction("b_c", 0.0, "N*s/m", "cart viscous friction"),
        friction("b_p", 0.0, "N*m*s/rad", "pivot viscous friction"),
        positive("g", 9.8, "m/s^2", "gravitational acceleration", note="seed 001 table"),
        positive("x_max", 1.0, "m", "half length of the track (the swing-up task's bound on x)",
                 note="SYSTEMS.md, Tasks"),
    ),
    inputs=(Input("F", "N", "horizontal force on the cart, +x", -200.0, 200.0),),
    outputs=("x", "theta"),
    operating_point=OperatingPoint(state={}, inputs={"F": 0.0}),
    source="seeds/001 chapter 27; seeds/002 cart-pole",
    seed_slips=(
        "seed 002 writes l1 where the pole inertia I1 is meant; the derivation uses I_p",
    ),
    region={"theta": (-math.pi / 2, math.pi / 2)},
    # The cart may wander 0.5 m and the pole 0.2 rad; the push is 20 N.
    design_scales={
        "x": 0.5, "theta": 0.2, "x_dot": 1.0, "theta_dot": 1.0, "F": 20.0,
    },
    # 4096-count encoders: quantization of 1.5 mm and 1.5 mrad.
    sensor_noise={"x": 1.5e-3, "theta": 1.5e-3},
    process_noise={"x_dot": 0.05, "theta_dot": 0.05},
    hanging={"theta": math.pi},
    swingup=SwingUp("cart", {"k_energy": 5.0, "a_max": 6.0, "k_x": 6.0, "k_v": 2.0}),
    drawing="equilibrist.viz.scenes_planar:CartpoleScene",
    scenario=Scenario(duration=12.0, start={"theta": 0.1}, push=120.0, push_duration=0.1,
        step={"x": 0.3}, step_at=1.0,
        push_name="a shove of 120 N on the cart for 0.1 s"),
    position=2,
)


@register(SPEC)
def derive(d: Derivation) -> SymbolicModel:
    from sympy.physics import mechanics as me
    x, theta = d.q
    xd, thetad = d.qd
    p, F = d.p, d.u["F"]
    N, O = d.N, d.O
    B = N.orientnew("B", "Axis", (-theta, N.z))  # clockwise positive
    A = O.locatenew("A", x * N.x)
    A.set_vel(N, xd * N.x)
    P = A.locatenew("P", p["l"] * B.y)
    P.set_vel(N, P.pos_from(O).dt(N))
    B.set_ang_vel(N, -thetad * N.z)
    cart = me.Particle("cart", A, p["m_c"])
    pole = me.RigidBody("pole", P, B, p["m_p"], (me.inertia(B, 0, 0, p["I_p"]), P))
    loads = [
        (A, (F - p["b_c"] * xd) * N.x - p["m_c"] * p["g"] * N.y),
        (P, -p["m_p"] * p["g"] * N.y),
        (B, p["b_p"] * thetad * N.z),  # opposes the pole's rotation -thetad N.z
    ]
    energy = cart.kinetic_energy(N) + pole.kinetic_energy(N) + p["m_p"] * p["g"] * P.pos_from(O).dot(N.y)
    return d.kane(bodies=[cart, pole], loads=loads, energy=energy)
