"""Equations of motion of a kinematic tree, derived by Lagrange's equations in matrices.

Each body's pose follows MuJoCo's forward kinematics: the frame is placed
in its parent's by the body's constant position and orientation, then each
of its joints acts in turn, a hinge as a rotation by ``q - ref`` about its
axis through its anchor, a slide as a translation by ``q - ref`` along its
axis. The centre of mass and the full inertia tensor (the principal moments
rotated by the inertial frame) sit in the final frame.

The kinematics are written in the world frame: each body's rotation matrix
is the product of constant matrices (numbers from the file) and joint
rotations, expanded after every product, so that positions, angular
velocities and the inertia tensor in the world are short polynomials in
the sines and cosines of the joint angles. (Chaining sympy frames by
constant rotations instead nests the direction cosines and makes even a
two-joint tree take minutes to derive.) Lagrange's equations are then
written out from them (:func:`_lagrange_of_tree`), in plain matrices and
plain symbols rather than through sympy.physics' vectors and Kane's method,
which took most of a first run's seconds (importing sympy.physics alone, a
quarter of a second, for its units): the mass matrix from each body's
centre-of-mass and angular-velocity Jacobians and its inertia in the world, the Coriolis and
centrifugal terms from the mass matrix's derivatives, gravity from its
potential; joint damping, Coulomb friction (:mod:`equilibrist.mechanics.friction`),
springs and motors are each joint's generalized
force (the torque on the child body and its reaction on the parent, summed,
work only through the joint's own rate); armature on the diagonal.

Numbers from the file enter as sympy Floats holding the exact binary value,
so the derived ``f`` agrees with MuJoCo's to round-off.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from equilibrist.importers.tree import Tree
from equilibrist.mechanics.friction import coulomb_friction

if TYPE_CHECKING:
    import sympy as sp

    from equilibrist.mechanics.model import Derivation, SymbolicModel


def _float(value: float) -> sp.Expr:
    import sympy as sp

    if value == 0:
        return sp.Integer(0)
    if value == 1:
        return sp.Integer(1)
    if value == -1:
        return sp.Integer(-1)
    return sp.Float(value, 17)


def _matrix(values: np.ndarray) -> sp.Matrix:
    import sympy as sp

    return sp.Matrix(3, 3, [_float(float(v)) for v in np.asarray(values, float).reshape(-1)])


def _column(values: tuple[float, ...] | np.ndarray) -> sp.Matrix:
    import sympy as sp

    return sp.Matrix([_float(float(v)) for v in values])


def _quat_matrix(quat: tuple[float, ...]) -> np.ndarray:
    w, x, y, z = (float(v) for v in np.asarray(quat, float) / np.linalg.norm(quat))
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _expand(m: sp.Matrix) -> sp.Matrix:
    import sympy as sp

    return m.applyfunc(sp.expand)


def _rotation(axis: tuple[float, float, float], angle: sp.Expr) -> sp.Matrix:
    """Rotation by *angle* about the unit *axis* (Rodrigues): numbers times cos, sin and 1."""
    import sympy as sp

    a = np.asarray(axis, float)
    c, s = sp.cos(angle), sp.sin(angle)
    outer = np.outer(a, a)
    cross = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return _matrix(outer) + c * _matrix(np.eye(3) - outer) + s * _matrix(cross)


def derive_tree(tree: Tree, d: Derivation) -> SymbolicModel:
    """The symbolic model of *tree* in the derivation context *d*."""
    import sympy as sp

    qs, qds = d.coordinates()
    rotations: list[sp.Matrix] = []  # world orientation of each body's frame
    origins: list[sp.Matrix] = []  # world position of each body's frame origin
    spins: list[sp.Matrix] = []  # world angular velocity of each body
    joint_axes: dict[int, sp.Matrix] = {}  # world axis of each joint
    positions: dict[str, sp.Matrix] = {"world": sp.zeros(3, 1)}
    links: list[tuple[str, str]] = []
    inertias: list[tuple[sp.Expr, sp.Matrix, sp.Matrix, sp.Matrix]] = []
    potential = sp.Integer(0)  # the joints' springs
    gravity = sp.Integer(0)  # the gravity's potential
    armature: dict[str, sp.Expr] = {}
    g = d.p["g"]
    g_dir = np.asarray(tree.gravity, float)
    norm = float(np.linalg.norm(g_dir))
    g_vec = _column(g_dir / norm if norm > 0 else np.array([0.0, 0.0, -1.0]))
    for body in tree.bodies:
        if body.parent < 0:
            rot, origin, spin = sp.eye(3), sp.zeros(3, 1), sp.zeros(3, 1)
            parent_point = "world"
        else:
            rot, origin, spin = rotations[body.parent], origins[body.parent], spins[body.parent]
            parent_point = f"{tree.bodies[body.parent].name}_com"
        origin = _expand(origin + rot * _column(body.pos))
        rot = _expand(rot * _matrix(_quat_matrix(body.quat)))
        for n, j in enumerate(body.joints):
            joint = tree.joints[j]
            q = qs[j] - _float(joint.ref)
            axis = _expand(rot * _column(joint.axis))
            joint_axes[j] = axis
            anchor = _expand(origin + rot * _column(joint.pos))
            if joint.kind == "hinge":
                rot = _expand(rot * _rotation(joint.axis, q))
                origin = _expand(anchor - rot * _column(joint.pos))
                spin = spin + qds[j] * axis
            else:
                # The anchor stays where the slide starts (on the parent), as
                # MuJoCo's xanchor: the link drawn from it shows the extension.
                origin = _expand(origin + q * axis)
            positions[joint.name] = anchor
            links.append((parent_point if n == 0 else tree.joints[body.joints[n - 1]].name, joint.name))
            if joint.armature:
                armature[joint.name] = _float(joint.armature)
        rotations.append(rot)
        origins.append(origin)
        spins.append(spin)
        com = _expand(origin + rot * _column(body.com))
        positions[f"{body.name}_com"] = com
        links.append((tree.joints[body.joints[-1]].name if body.joints else parent_point, f"{body.name}_com"))
        mass = d.p[f"{body.name}_mass"]
        scale = mass / _float(body.mass)
        tensor = _expand(rot * _matrix(np.asarray(body.inertia, float)) * rot.T)
        inertias.append((mass, com, spin, scale * tensor))
        gravity -= mass * g * (com.T * g_vec)[0]
    # Joint forces: damping, spring and motors act on the child body and, in
    # reaction, on the parent; summed, they do work only through the joint's
    # relative motion, a rotation (or translation) at q_dot along the axis: each is
    # its joint's generalized force.
    forces = []
    for j, joint in enumerate(tree.joints):
        q = qs[j]
        generalized = -d.p[f"{joint.name}_damping"] * qds[j]
        if joint.friction > 0:
            generalized -= coulomb_friction(qds[j], d.p[f"{joint.name}_friction"], tree.friction_form)
        if joint.stiffness:
            generalized -= _float(joint.stiffness) * (q - _float(joint.spring_ref))
            potential += _float(joint.stiffness) * (q - _float(joint.spring_ref)) ** 2 / 2
        for k, a in enumerate(tree.actuators):
            if a.joint == j:
                # The input is the motor's generalized force itself (gear
                # times MuJoCo's ctrl): the spec names it input_names[k].
                generalized += d.u[d.spec.input_names[k]]
        forces.append(generalized)
    mass_matrix, forcing, kinetic = _lagrange_of_tree(d, qs, qds, inertias, armature, gravity, forces)
    return d.from_mass_matrix(
        "Lagrange (tree)",
        mass_matrix,
        forcing,
        energy=kinetic + potential + gravity,
        points=positions,
        links=links,
        jacobian_form="mass",
    )


def _lagrange_of_tree(d: Derivation, qs: list[sp.Symbol], qds: list[sp.Symbol],
                      inertias: list[tuple[sp.Expr, sp.Matrix, sp.Matrix, sp.Matrix]],
                      armature: dict[str, sp.Expr], gravity: sp.Expr,
                      forces: list[sp.Expr]) -> tuple[sp.Matrix, sp.Matrix, sp.Expr]:
    """``M``, ``F`` and the kinetic energy of a tree in the coordinates *qs* and rates *qds*
    (plain symbols): Lagrange's equations written out. ``M = sum m Jv^T Jv + Jw^T I Jw`` over the bodies (``Jv`` the centre of
    mass's Jacobian, ``Jw`` the angular velocity's, ``I`` the inertia in the world) plus
    the armatures; ``F = Q - dV/dq - h`` with the joints' generalized forces ``Q``, the
    gravity's potential ``V`` and ``h_i = sum_jk (dM_ij/dq_k - dM_jk/dq_i / 2) qd_j qd_k``."""
    import sympy as sp

    n = len(qs)
    mass = sp.zeros(n, n)
    def jacobian(v: sp.Matrix, by: list[sp.Symbol]) -> sp.Matrix:
        # Element by element: sympy's Matrix.jacobian and Matrix.diff take tens of times as long.
        return sp.Matrix(len(v), len(by), [e.diff(b) for e in v for b in by])

    for m, com, spin, tensor in inertias:
        jv = jacobian(com, qs)
        jw = jacobian(spin, qds)
        mass += m * (jv.T * jv) + jw.T * tensor * jw
    for name, value in armature.items():
        k = d.spec.coordinates.index(name)
        mass[k, k] += value
    mass = mass.applyfunc(sp.expand)
    rates = sp.Matrix(qds)
    dmass = [mass.applyfunc(lambda e, qk=qk: e.diff(qk)) for qk in qs]
    bias = sp.zeros(n, 1)
    for i in range(n):
        bias[i] = sum(((dmass[k][i, :] * rates)[0] * qds[k] for k in range(n)), sp.Integer(0)) \
            - (rates.T * dmass[i] * rates)[0] / 2
    forcing = sp.Matrix([forces[i] - sp.diff(gravity, qs[i]) - bias[i] for i in range(n)])
    kinetic = (rates.T * mass * rates)[0] / 2
    return mass, forcing, kinetic
