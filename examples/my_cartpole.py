"""A cart-pole written from scratch as a user's own system file.

This file is what you write to bring your own rig to equilibrist: a
:class:`~equilibrist.mechanics.spec.SystemSpec` (what the rig is: its
coordinates, parameters with units and ranges, actuators with limits,
sensors, the point it balances at) and a derivation decorated with
``@register(SPEC)`` that builds frames, bodies and loads with
``sympy.physics.mechanics``. No equation of motion is typed in.

Every command then takes the file where it takes a system name::

    equilibrist show examples/my_cartpole.py
    equilibrist design examples/my_cartpole.py --rate 200
    equilibrist simulate examples/my_cartpole.py --x0 theta=0.2 --push 3:40 --plot run.png
    equilibrist export examples/my_cartpole.py --out my_cartpole_lqg
    equilibrist demo examples/my_cartpole.py --out my_report

and so does Python: ``get_system("examples/my_cartpole.py", m_p=0.2)``.
Run this file to see the rig next to the catalogue's cart-pole.
"""

from __future__ import annotations

import math

from equilibrist.mechanics.spec import Input, OperatingPoint, SystemSpec, nonnegative, positive
from equilibrist.systems.registry import register

SPEC = SystemSpec(
    name="my_cartpole",
    title="My cart-pole",
    description="A 2 kg cart on a belt-driven track balancing a 30 cm aluminium pole.",
    coordinates=("x", "theta"),  # cart position; pole angle from upright, clockwise
    units={"x": "m", "theta": "rad"},
    parameters=(
        positive("m_c", 2.0, "kg", "cart mass (weighed)"),
        positive("m_p", 0.12, "kg", "pole mass (weighed)"),
        positive("l", 0.15, "m", "pivot to the pole's centre of mass"),
        nonnegative("I_p", 0.12 * 0.3**2 / 12, "kg*m^2", "pole inertia about its centre of mass (rod)"),
        nonnegative("b_c", 0.5, "N*s/m", "cart viscous friction"),
        nonnegative("b_p", 1e-4, "N*m*s/rad", "pivot viscous friction"),
        positive("g", 9.81, "m/s^2", "gravitational acceleration"),
    ),
    inputs=(Input("F", "N", "belt force on the cart, +x", -15.0, 15.0),),
    outputs=("x", "theta"),  # a motor encoder on the belt, an encoder on the pivot
    operating_point=OperatingPoint(state={}, inputs={"F": 0.0}),
    region={"theta": (-math.pi / 2, math.pi / 2), "x": (-0.4, 0.4)},
    # Bryson's rule: the largest deviations the rig tolerates.
    design_scales={"x": 0.1, "theta": 0.05, "x_dot": 0.5, "theta_dot": 1.0, "F": 5.0},
    sensor_noise={"x": 2e-4, "theta": 1.5e-3},      # 0.2 mm belt steps, 4096-count encoder
    process_noise={"x_dot": 0.05, "theta_dot": 0.05},
    control_rate=200.0,
)


@register(SPEC)
def derive(d):  # type: ignore[no-untyped-def]
    """Kane's method on a particle (the cart) and a rigid body (the pole)."""
    from sympy.physics import mechanics as me

    x, theta = d.q
    x_dot, theta_dot = d.qd
    p, F = d.p, d.u["F"]
    N, O = d.N, d.O
    pole_frame = N.orientnew("pole", "Axis", (-theta, N.z))  # clockwise positive
    pole_frame.set_ang_vel(N, -theta_dot * N.z)
    pivot = O.locatenew("pivot", x * N.x)
    pivot.set_vel(N, x_dot * N.x)
    centre = pivot.locatenew("centre", p["l"] * pole_frame.y)
    centre.set_vel(N, centre.pos_from(O).dt(N))
    cart = me.Particle("cart", pivot, p["m_c"])
    pole = me.RigidBody("pole", centre, pole_frame, p["m_p"],
                        (me.inertia(pole_frame, 0, 0, p["I_p"]), centre))
    loads = [
        (pivot, (F - p["b_c"] * x_dot) * N.x - p["m_c"] * p["g"] * N.y),
        (centre, -p["m_p"] * p["g"] * N.y),
        (pole_frame, p["b_p"] * theta_dot * N.z),  # friction opposes -theta_dot N.z
    ]
    energy = (cart.kinetic_energy(N) + pole.kinetic_energy(N)
              + p["m_p"] * p["g"] * centre.pos_from(O).dot(N.y))
    # Named points and the links between them: what the generic drawing of
    # the demo, the animations and the playground shows of this rig.
    tip = pivot.locatenew("tip", 2 * p["l"] * pole_frame.y)
    points = {"track_left": O.locatenew("left", -0.4 * N.x), "track_right": O.locatenew("right", 0.4 * N.x),
              "cart": pivot, "pole_centre": centre, "pole_tip": tip}
    links = [("track_left", "track_right"), ("cart", "pole_tip")]
    return d.kane(bodies=[cart, pole], loads=loads, energy=energy, points=points, links=links)


if __name__ == "__main__":
    import numpy as np

    from equilibrist import get_system
    from equilibrist.control.design import design

    mine = get_system(__file__)
    same = {"m_c": 10.0, "m_p": 1.0, "l": 0.5, "I_p": 0.08333, "b_c": 0.0, "b_p": 0.0, "g": 9.8}
    catalogue = get_system("cartpole")
    x, u = [0.1, 0.3, -0.2, 0.5], [3.0]
    print("with the catalogue's parameters, f(x, u) of this file and of 'cartpole':")
    print("  mine:     ", np.round(mine.with_params(**same).f(x, u), 12))
    print("  catalogue:", np.round(catalogue.f(x, u), 12))
    d = design(mine, rate=mine.spec.control_rate)
    print(f"\n{mine.spec.title}: open-loop poles {np.round(d.open_loop_poles, 3)}")
    print(f"LQR gain at {mine.spec.control_rate:g} Hz: {np.round(d.K, 3)}")
