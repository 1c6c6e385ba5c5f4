"""Equations of motion of a kinematic tree, derived with sympy.physics.mechanics.

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
two-joint tree take minutes to derive.) The bodies, their velocities and
the loads then go to Kane's method: gravity at each centre of mass; joint
damping, springs and motors as a torque about the joint's axis on the
joint's relative rotation (a force along the axis for a slide), which is
the torque on the child body and its reaction on the parent summed;
armature on the diagonal of the mass matrix.

Numbers from the file enter as sympy Floats holding the exact binary value,
so the derived ``f`` agrees with MuJoCo's to round-off.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from equilibrist.importers.tree import Tree

if TYPE_CHECKING:
    import sympy as sp
    from sympy.physics import mechanics as me

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


def _in_world(N: me.ReferenceFrame, v: sp.Matrix) -> me.Vector:
    return v[0] * N.x + v[1] * N.y + v[2] * N.z


def derive_tree(tree: Tree, d: Derivation) -> SymbolicModel:
    """The symbolic model of *tree* in the derivation context *d*."""
    import sympy as sp
    from sympy.physics import mechanics as me

    N, O, t = d.N, d.O, d.t
    rotations: list[sp.Matrix] = []  # world orientation of each body's frame
    origins: list[sp.Matrix] = []  # world position of each body's frame origin
    spins: list[sp.Matrix] = []  # world angular velocity of each body
    joint_axes: dict[int, sp.Matrix] = {}  # world axis of each joint
    positions: dict[str, sp.Matrix] = {"world": sp.zeros(3, 1)}
    links: list[tuple[str, str]] = []
    bodies: list[me.RigidBody] = []
    loads: list[tuple[object, me.Vector]] = []
    potential = sp.Integer(0)
    kinetic = sp.Integer(0)
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
            q = d.q[j] - _float(joint.ref)
            axis = _expand(rot * _column(joint.axis))
            joint_axes[j] = axis
            anchor = _expand(origin + rot * _column(joint.pos))
            if joint.kind == "hinge":
                rot = _expand(rot * _rotation(joint.axis, q))
                origin = _expand(anchor - rot * _column(joint.pos))
                spin = spin + d.qd[j] * axis
            else:
                # The anchor stays where the slide starts (on the parent), as
                # MuJoCo's xanchor: the link drawn from it shows the extension.
                origin = _expand(origin + q * axis)
            positions[joint.name] = anchor
            links.append((parent_point if n == 0 else tree.joints[body.joints[n - 1]].name, joint.name))
            if joint.armature:
                armature[joint.name] = _float(joint.armature)
                kinetic += _float(joint.armature) * d.qd[j] ** 2 / 2
        rotations.append(rot)
        origins.append(origin)
        spins.append(spin)
        com = _expand(origin + rot * _column(body.com))
        positions[f"{body.name}_com"] = com
        links.append((tree.joints[body.joints[-1]].name if body.joints else parent_point, f"{body.name}_com"))
        mass = d.p[f"{body.name}_mass"]
        scale = mass / _float(body.mass)
        tensor = _expand(rot * _matrix(np.asarray(body.inertia, float)) * rot.T)
        point = O.locatenew(f"{body.name}_com", _in_world(N, com))
        point.set_vel(N, _in_world(N, _expand(com.diff(t))))
        frame = me.ReferenceFrame(f"{body.name}_frame")
        frame.set_ang_vel(N, _in_world(N, spin))
        dyadic = sum(
            (scale * tensor[r, c] * (N_axis | M_axis)
             for r, N_axis in enumerate((N.x, N.y, N.z)) for c, M_axis in enumerate((N.x, N.y, N.z))
             if tensor[r, c] != 0),
            me.Dyadic(0),
        )
        bodies.append(me.RigidBody(body.name, point, frame, mass, (dyadic, point)))
        loads.append((point, mass * g * _in_world(N, g_vec)))
        potential -= mass * g * (com.T * g_vec)[0]
    # Joint forces: damping, spring and motors act on the child body and, in
    # reaction, on the parent; summed, they do work only through the joint's
    # relative motion, a rotation (or translation) at q_dot along the axis.
    for j, joint in enumerate(tree.joints):
        q = d.q[j]
        generalized = -d.p[f"{joint.name}_damping"] * d.qd[j]
        if joint.stiffness:
            generalized -= _float(joint.stiffness) * (q - _float(joint.spring_ref))
            potential += _float(joint.stiffness) * (q - _float(joint.spring_ref)) ** 2 / 2
        for k, a in enumerate(tree.actuators):
            if a.joint == j:
                # The input is the motor's generalized force itself (gear
                # times MuJoCo's ctrl): the spec names it input_names[k].
                generalized += d.u[d.spec.input_names[k]]
        axis = _in_world(N, joint_axes[j])
        if joint.kind == "hinge":
            relative = me.ReferenceFrame(f"{joint.name}_relative")
            relative.set_ang_vel(N, d.qd[j] * axis)
            loads.append((relative, generalized * axis))
        else:
            sliding = me.Point(f"{joint.name}_relative")
            sliding.set_vel(N, d.qd[j] * axis)
            loads.append((sliding, generalized * axis))
    kinetic += sum((b.kinetic_energy(N) for b in bodies), sp.Integer(0))
    points = {}
    for name, r in positions.items():
        points[name] = O.locatenew(f"{name}_point", _in_world(N, r))
    return d.kane(
        bodies=bodies,
        loads=loads,
        energy=kinetic + potential,
        armature=armature,
        points=points,
        links=links,
        jacobian_form="mass",
    )
