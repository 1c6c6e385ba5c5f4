"""Heavy symmetric top: a spinning wheel on a fixed point of its axis.

Description
    A wheel, symmetric about its spin axis, turns about a fixed point on
    that axis (the pin of a desktop gyroscope's frame); its centre of mass is
    at distance ``R`` from the point, and gravity pulls it down. Nothing
    drives it (no input) and nothing dissipates: energy and two momenta are
    conserved. One family with two parameterizations of the same physical
    system, chosen by ``euler``; both are derived by Lagrange's method from
    a rigid body in sympy.physics.mechanics, as seed 002 does by hand.

    ``euler = "zxz"`` (default)
        Body orientation ``Rz(phi) Rx(theta) Rz(psi)`` from the room frame
        (z up): ``phi`` precession about the vertical, ``theta`` nutation
        (tilt of the axis from vertical-up), ``psi`` spin about the axis.
        Singular where ``sin(theta) = 0`` (the axis vertical, where
        precession and spin turn about the same line), so the upright top
        cannot be described: it has no canonical operating point.
    ``euler = "xyz"``
        Body orientation ``Rx(theta) Ry(phi) Rz(psi)``: ``theta`` tilt
        about the room's x axis, ``phi`` tilt about the once-rotated y
        axis, ``psi`` spin about the axis. Singular where ``cos(phi) = 0``
        (the axis horizontal along the room's x axis); regular upright.

States
    zxz: ``[phi, theta, psi, phi_dot, theta_dot, psi_dot]``;
    xyz: ``[theta, phi, psi, theta_dot, phi_dot, psi_dot]``; all angles in
    rad. The wheel's axis points along ``(sin(phi) sin(theta),
    -cos(phi) sin(theta), cos(theta))`` (zxz) or ``(sin(phi),
    -cos(phi) sin(theta), cos(phi) cos(theta))`` (xyz) in the room frame.
    "Spin" means the Euler rate ``psi_dot``, not the total spin
    ``omega_3`` (``phi_dot cos(theta) + psi_dot`` in zxz).

Inputs
    None.

Outputs
    The three angles (the orientation, as a motion-capture rig, or an IMU
    on the frame with an encoder on the spin axis, reads it).

Parameters
    ======  =========  ========  =================================================
    name    default    unit      meaning
    ======  =========  ========  =================================================
    m       0.1        kg        wheel mass
    R       0.04       m         fixed point to the wheel's centre of mass
    I_t     1.6e-5     kg m^2    wheel inertia about a transverse axis through
                                 its centre of mass
    I_s     3.125e-5   kg m^2    wheel inertia about its spin axis
    g       9.81       m/s^2     gravity
    ======  =========  ========  =================================================

    The seed gives no numbers. The defaults are a toy desktop gyroscope: a
    brass disc rotor 50 mm across and 6 mm thick (about 0.1 kg; the frame's
    mass is neglected), its centre 40 mm from the pin; ``I_s = m r^2 / 2``
    and ``I_t = m r^2 / 4 + m t^2 / 12`` of a uniform disc. The sleeping top
    (upright, spinning) is then stable above ``psi_dot = 2 sqrt((I_t + m
    R^2) m g R) / I_s``, about 168 rad/s (1600 rpm): a toy spun by its
    string (several thousand rpm) stands.

    In the seed's notation ``I_xy = I_t + m R^2`` (transverse inertia about
    the fixed point), ``I_z = I_s``, ``p = m g R`` and ``I_c = I_z - I_xy``.

Conserved quantities (``System.conserved``)
    zxz: ``p_phi`` and ``p_psi``, the momenta conjugate to ``phi`` and
    ``psi`` (``d L / d phi_dot``, ``d L / d psi_dot``); ``p_phi`` is the
    vertical angular momentum about the fixed point and ``p_psi = I_s
    omega_3`` the axial one (the seed's ``p_psi`` is ``omega_3``, i.e.
    divided by ``I_z``). xyz: ``p_psi`` (the same axial momentum) and
    ``L_vertical``, the angular momentum about the fixed point projected on
    the room's vertical (xyz has no coordinate about the vertical, so it
    is not a conjugate momentum there). ``System.energy`` is ``T + V`` with
    ``V = m g R`` times the height of the axis' tip.

Operating point
    xyz: upright at rest (all zero), an unstable equilibrium without spin;
    with spin ``psi_dot`` it is still an equilibrium. zxz: none (upright is
    its singularity); linearizing it needs an explicit point.

Region
    "Fallen" means the wheel's centre of mass below the height of the fixed
    point (axis below horizontal): zxz ``|theta| < pi/2``; xyz ``|theta| <
    pi/2`` and ``|phi| < pi/2``, which for angles in their principal range
    is exactly ``cos(theta) cos(phi) > 0``.

Source
    seeds/002 ("Gyroscope zxz", "Gyroscope xyz"). Derivations agree with
    the seed's Lagrangians, its nutation equations (zxz ``theta_ddot``, xyz
    ``phi_ddot``), the steady-precession relation
    ``I_c phi_dot^2 cos(theta) + I_z psi_dot phi_dot = p`` and, in both
    sections, the line before the last ``psi_ddot``. Seed slips:

    * zxz, the last printed ``psi_ddot`` line,
      ``(-I_c theta_dot phi_dot cos^2 theta + I_xy theta_dot phi_dot cos theta
      + I_z psi_dot theta_dot) / (I_xy sin theta)``, is wrong; the line
      before it simplifies to ``((I_xy - I_c cos^2 theta) theta_dot phi_dot
      - I_z psi_dot theta_dot cos theta) / (I_xy sin theta)``, which the
      derivation gives.
    * xyz, the last printed ``psi_ddot`` line, ``(I_z theta_dot phi_dot
      sin^2 phi - I_xy theta_dot phi_dot sin phi + I_z psi_dot phi_dot +
      p sin theta) / (I_xy cos phi)``, is wrong; the line before it gives
      ``((I_c sin^2 phi - I_xy) theta_dot phi_dot + I_z psi_dot phi_dot
      sin phi - p sin theta sin phi) / (I_xy cos phi)``, as derived.
    * Both sections write the inertia about the fixed point as
      ``diag(I_xy + m R^2, I_xy + m R^2, I_z)`` and then use ``I_xy`` alone
      in the Lagrangian; the Lagrangian is right if ``I_xy`` is read as the
      inertia about the fixed point, ``I_t + m R^2`` (SYSTEMS.md).
    * xyz's centre-of-mass product writes ``sin(phi/2)`` in the outer
      quaternion where ``sin(theta/2)`` is meant (OCR); its result is right.

Helpers for steady precession and for converting initial conditions
between the two parameterizations are in :mod:`equilibrist.systems._gyro_tools`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from equilibrist.mechanics.spec import OperatingPoint, SystemSpec, positive
from equilibrist.systems.registry import register

if TYPE_CHECKING:  # sympy is imported only when the model is derived
    from sympy.physics import mechanics as me

    from equilibrist.mechanics.model import Derivation, SymbolicModel

_TOY = "toy desktop gyroscope: brass disc rotor 50 mm across, 6 mm thick"

_PARAMETERS = (
    positive("m", 0.1, "kg", "wheel mass", note=_TOY + " (brass, about 0.1 kg)"),
    positive("R", 0.04, "m", "fixed point to the wheel's centre of mass", note=_TOY + ", 40 mm pin"),
    positive(
        "I_t", 1.6e-5, "kg*m^2", "wheel inertia about a transverse axis through its centre of mass",
        note="uniform disc m r^2/4 + m t^2/12 with r = 25 mm, t = 6 mm",
    ),
    positive(
        "I_s", 3.125e-5, "kg*m^2", "wheel inertia about its spin axis",
        note="uniform disc m r^2/2 with r = 25 mm",
    ),
    positive("g", 9.81, "m/s^2", "gravitational acceleration", note="standard gravity"),
)

_SOURCE = "seeds/002 gyroscope zxz, gyroscope xyz"

_COMMON_SLIPS = (
    "the seed writes the inertia about the fixed point as diag(I_xy + m R^2, I_xy + m R^2, I_z) "
    "and then uses I_xy alone in the Lagrangian: I_xy is I_t + m R^2",
)

SPEC_ZXZ = SystemSpec(
    name="gyroscope",
    title="Heavy symmetric top (zxz Euler angles)",
    description="A spinning wheel on a fixed point of its axis, in precession, nutation and spin.",
    coordinates=("phi", "theta", "psi"),
    units={"phi": "rad", "theta": "rad", "psi": "rad"},
    parameters=_PARAMETERS,
    inputs=(),
    # The orientation, as a motion-capture or IMU-plus-encoder rig reads it.
    outputs=("phi", "theta", "psi"),
    operating_point=None,
    source=_SOURCE,
    seed_slips=(
        "zxz: the last printed psi_ddot line is wrong; the line before it is right: "
        "psi_ddot = ((I_xy - I_c cos^2 theta) theta_dot phi_dot - I_z psi_dot theta_dot cos theta)"
        " / (I_xy sin theta)",
        *_COMMON_SLIPS,
    ),
    notes=(
        "q = Rz(phi) Rx(theta) Rz(psi): precession, nutation (tilt from vertical-up), spin",
        "spin is the Euler rate psi_dot, not the total spin phi_dot cos(theta) + psi_dot",
        "p_psi is the true conjugate momentum I_s (phi_dot cos theta + psi_dot); "
        "the seed's p_psi is that divided by I_z",
        "no canonical operating point: upright (theta = 0) is this parameterization's singularity",
    ),
    variant=("euler", "zxz"),
    region={"theta": (-math.pi / 2, math.pi / 2)},
    singularity=(
        "zxz Euler angles are singular where sin(theta) = 0 (axis vertical: precession and spin "
        "turn about the same line); use euler='xyz' near the upright"
    ),
    drawing="equilibrist.viz.scenes_3d:GyroscopeScene",
    position=9,
)

SPEC_XYZ = SystemSpec(
    name="gyroscope",
    title="Heavy symmetric top (xyz Euler angles)",
    description="A spinning wheel on a fixed point of its axis, tilted about x and y, spinning about z.",
    coordinates=("theta", "phi", "psi"),
    units={"theta": "rad", "phi": "rad", "psi": "rad"},
    parameters=_PARAMETERS,
    inputs=(),
    outputs=("theta", "phi", "psi"),
    operating_point=OperatingPoint(state={}, inputs={}),
    source=_SOURCE,
    seed_slips=(
        "xyz: the last printed psi_ddot line is wrong; the line before it is right: "
        "psi_ddot = ((I_c sin^2 phi - I_xy) theta_dot phi_dot + I_z psi_dot phi_dot sin phi "
        "- p sin theta sin phi) / (I_xy cos phi)",
        *_COMMON_SLIPS,
        "xyz centre-of-mass product: sin(phi/2) written where sin(theta/2) is meant (OCR)",
    ),
    notes=(
        "q = Rx(theta) Ry(phi) Rz(psi): tilt about x, tilt about the rotated y, spin",
        "spin is the Euler rate psi_dot, not the total spin theta_dot sin(phi) + psi_dot",
        "L_vertical is the angular momentum about the fixed point along the room's vertical",
    ),
    variant=("euler", "xyz"),
    region={"theta": (-math.pi / 2, math.pi / 2), "phi": (-math.pi / 2, math.pi / 2)},
    singularity=(
        "xyz Euler angles are singular where cos(phi) = 0 (axis horizontal along the room's x "
        "axis: theta and psi turn about the same line); use euler='zxz' there"
    ),
    drawing="equilibrist.viz.scenes_3d:GyroscopeScene",
    position=9,
)


def _wheel(d: Derivation, body_frame: me.ReferenceFrame) -> tuple[me.RigidBody, me.Point]:
    """The wheel in *body_frame* (whose z axis is the spin axis), centre at R along it."""
    from sympy.physics import mechanics as me

    p = d.p
    G = d.O.locatenew("G", p["R"] * body_frame.z)
    G.v2pt_theory(d.O, d.N, body_frame)
    # Transverse I_t and axial I_s about the centre of mass; the m R^2 of
    # the seed's I_xy comes from G's velocity, not from this tensor.
    inertia = me.inertia(body_frame, p["I_t"], p["I_t"], p["I_s"])
    wheel = me.RigidBody("wheel", G, body_frame, p["m"], (inertia, G))
    return wheel, G


def _finish(d: Derivation, body_frame: me.ReferenceFrame, conserved: dict[str, str]) -> SymbolicModel:
    import sympy as sp

    wheel, G = _wheel(d, body_frame)
    p = d.p
    # sin^2 psi + cos^2 psi left unsimplified would carry psi through M
    # and f, although the symmetric wheel's energy does not depend on it.
    kinetic = sp.trigsimp(sp.expand(wheel.kinetic_energy(d.N)))
    potential = p["m"] * p["g"] * G.pos_from(d.O).dot(d.N.z)
    lagrangian = kinetic - potential
    quantities: dict[str, sp.Expr] = {}
    for name, what in conserved.items():
        if what == "vertical":
            quantities[name] = wheel.angular_momentum(d.O, d.N).dot(d.N.z)
        else:
            quantities[name] = sp.diff(lagrangian, d.rate(what))
    return d.lagrange(
        lagrangian,
        energy=kinetic + potential,
        conserved={
            k: sp.collect(sp.expand(sp.expand_trig(sp.trigsimp(v))), d.qd)
            for k, v in quantities.items()
        },
    )


@register(SPEC_ZXZ, default=True)
def derive_zxz(d: Derivation) -> SymbolicModel:
    phi, theta, psi = d.q
    # Intrinsic z, x, z: the matrix is Rz(phi) Rx(theta) Rz(psi).
    B = d.N.orientnew("B", "Body", (phi, theta, psi), "ZXZ")
    return _finish(d, B, {"p_phi": "phi", "p_psi": "psi"})


@register(SPEC_XYZ)
def derive_xyz(d: Derivation) -> SymbolicModel:
    theta, phi, psi = d.q
    B = d.N.orientnew("B", "Body", (theta, phi, psi), "XYZ")
    return _finish(d, B, {"p_psi": "psi", "L_vertical": "vertical"})
