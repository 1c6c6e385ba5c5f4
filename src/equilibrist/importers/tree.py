"""The kinematic tree of a model file, read through MuJoCo's compiler, as plain data.

:func:`read_tree` hands the file to ``mujoco.MjModel.from_xml_path`` (which
reads MJCF and URDF, applies defaults classes, the angle unit, euler
sequences, ``fullinertia``, inertia inferred from geoms, and merges fixed
joints), checks that the compiled model holds only what equilibrist models,
and copies what the derivation needs into frozen dataclasses of floats.
Anything that the compiled model has and equilibrist does not model is
refused with one line naming the element; nothing is silently dropped.

MuJoCo's compiler and the checks of the compiled model's values are in
:mod:`equilibrist.importers.mujoco_compiler`, the search for the operating point in
:mod:`equilibrist.importers.equilibrium`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.errors import DefinitionError
from equilibrist.importers.equilibrium import (
    _authority,
    _holds,
    _linearization,
    _nearest_equilibrium,
)
from equilibrist.importers.mujoco_compiler import (
    _check_inertia,
    _identifier,
    _model_name,
    _name,
    _not_finite,
    compile_model,
    load_mujoco,
)

if TYPE_CHECKING:
    import mujoco

Vector3 = tuple[float, float, float]
Matrix3 = tuple[Vector3, Vector3, Vector3]

# Below this, a value read from the file counts as zero (MuJoCo's mjMINVAL).
TINY = 1e-15


@dataclass(frozen=True)
class JointData:
    """One hinge or slide joint of the compiled model."""

    name: str
    kind: str  # "hinge" or "slide"
    pos: Vector3  # anchor in the body frame
    axis: Vector3  # unit axis in the body frame (after the joints before it)
    ref: float  # the configuration at which the joint reads zero displacement (qpos0)
    stiffness: float
    spring_ref: float
    damping: float
    armature: float
    limited: bool
    # Coulomb friction (MJCF frictionloss, a URDF's <dynamics friction>), N*m or N.
    friction: float = 0.0
    # The joint's range where it has one (a URDF's revolute and prismatic limits).
    range: tuple[float, float] | None = None


@dataclass(frozen=True)
class BodyData:
    """One moving body: its place in the tree, its joints and its inertia."""

    name: str  # the parameter prefix (``<name>_mass``)
    label: str  # how messages and notes name it
    parent: int  # index into the bodies, -1 for a body on the world (or on a fixed body)
    pos: Vector3  # frame origin in the parent's frame
    quat: tuple[float, float, float, float]  # frame orientation in the parent's frame (w, x, y, z)
    joints: tuple[int, ...]  # indices into the joints, in order
    mass: float
    com: Vector3  # centre of mass in the body frame
    inertia: Matrix3  # about the centre of mass, in the body frame


@dataclass(frozen=True)
class ActuatorData:
    """A motor: generalized force ``gain * u`` on one joint, ``u`` within limits."""

    name: str
    joint: int
    gain: float
    low: float
    high: float


@dataclass(frozen=True)
class Tree:
    """Everything the derivation and the spec take from a model file."""

    model_name: str
    bodies: tuple[BodyData, ...]
    joints: tuple[JointData, ...]
    actuators: tuple[ActuatorData, ...]
    gravity: Vector3
    # Measured joints (names) and the standard deviation of each one's noise
    # (None where the file gives none).
    sensors: tuple[tuple[str, float | None], ...]
    # The operating point: joint positions and velocities, actuator controls,
    # and the keyframe's name (None: the zero configuration).
    key_name: str | None
    key_qpos: tuple[float, ...]
    key_qvel: tuple[float, ...]
    key_ctrl: tuple[float, ...]
    # Hinge joints whose axis is vertical at the operating point (gravity
    # does no work along them): they can not fall.
    vertical_hinges: tuple[str, ...]
    # Whether the operating point holds (qacc = 0) with the keyframe's controls.
    key_is_equilibrium: bool
    # How far the operating point was moved from the file's pose to the
    # nearest equilibrium: (joint, new - old) of each joint that moved.
    key_moved: tuple[tuple[str, float], ...]
    # The acceleration of each joint (in joint order) when every motor pushes
    # with half its range at the operating point, each motor's share counted
    # whatever its sign: the model's scale of process noise (docs/models.md).
    authority: tuple[float, ...]
    # ``(A, B)`` of the motion at the operating point (positions then rates in joint
    # order; each motor's physical force or torque): the scale of the default process
    # noise (docs/models.md).
    linear: tuple[tuple[tuple[float, ...], ...], tuple[tuple[float, ...], ...]]
    notes: tuple[str, ...]
    # The smooth sign of the joints' Coulomb friction (equilibrist.mechanics.friction):
    # "tanh" for MJCF's frictionloss, which MuJoCo bounds by its value; "atan" for a URDF's
    # friction, the form of the rigs' identified models.
    friction_form: str = "tanh"


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = (float(v) for v in q / np.linalg.norm(q))
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _vec(v: np.ndarray) -> Vector3:
    return (float(v[0]), float(v[1]), float(v[2]))


def read_tree(
    file: Path,
    *,
    joint_order: tuple[str, ...] | None = None,
    actuators: tuple[ActuatorData, ...] | None = None,
    text: bytes | None = None,
    stand_ins: tuple[tuple[str, float], ...] = (),
    friction_form: str = "tanh",
    rotor_inertias: tuple[tuple[str, float], ...] = (),
) -> Tree:
    """Compile *file* and read its tree.

    *joint_order* reorders the joints (a URDF's document order; MJCF's is
    the compiler's own). *actuators* replaces the compiled model's (a
    URDF's transmissions, which MuJoCo's URDF reader ignores); their
    ``joint`` indices refer to the order of the compiled model's joints.
    *text* is compiled instead of the file (a URDF made into what MuJoCo
    reads); *stand_ins* names bodies given more inertia than they have (kg m^2
    about each axis, taken away again); *friction_form* is the smooth sign of
    the joints' Coulomb friction; *rotor_inertias* adds reflected inertia to joints'
    armature (a URDF's Drake rotor inertia through its gear).
    """
    mujoco = load_mujoco()
    model = compile_model(file, text)
    problems = _unmodelled(model)
    problems.extend(_not_finite(model, mujoco))
    if problems:
        raise DefinitionError(f"{file.name}: " + "; ".join(problems))
    compiled_names = _joint_names(model, file)
    order = _joint_order(model, file, compiled_names, joint_order)
    position = {j: k for k, j in enumerate(order)}
    joints = _joints(model, order, compiled_names)
    extra = dict(rotor_inertias)
    joints = [replace(j, armature=j.armature + extra[j.name]) if j.name in extra else j for j in joints]
    bodies = _moving_bodies(model, file, position, dict(stand_ins))
    if actuators is None:
        actuators = _motors(model, file, position)
    sensors, ignored = _sensors(model, compiled_names)

    # -- the operating point ---------------------------------------------------------------
    data = mujoco.MjData(model)
    key_name, qpos, qvel, ctrl = _keyframe(model)
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    moved: list[tuple[str, float]] = []
    key_is_equilibrium = _holds(model, data, qpos, qvel, ctrl)
    if not key_is_equilibrium:
        qpos, ctrl, moved = _nearest_equilibrium(model, data, qpos, qvel, ctrl, actuators, order, compiled_names)
        key_is_equilibrium = _holds(model, data, qpos, qvel, ctrl)
    data.qpos[:], data.qvel[:] = qpos, qvel
    mujoco.mj_kinematics(model, data)
    gravity = np.asarray(model.opt.gravity, float)
    qpos_by_joint = tuple(float(qpos[int(model.jnt_qposadr[j])]) for j in order)
    qvel_by_joint = tuple(float(qvel[int(model.jnt_dofadr[j])]) for j in order)

    notes = ["contacts and joint limits (range) are not modelled: the model is the free motion "
             "of the kinematic tree"]
    limited = [f"{j.name} [{j.range[0]:.6g}, {j.range[1]:.6g}]" for j in joints if j.range is not None]
    if limited:
        notes.append(f"joints with a range that is not enforced: {', '.join(limited)}")
    if ignored:
        notes.append(f"sensors other than jointpos are not used: {', '.join(ignored)}")
    return Tree(
        model_name=_model_name(model, file),
        bodies=tuple(bodies),
        joints=tuple(joints),
        actuators=actuators,
        gravity=_vec(gravity),
        sensors=tuple(sensors),
        key_name=key_name,
        key_qpos=qpos_by_joint,
        key_qvel=qvel_by_joint,
        key_ctrl=tuple(float(c) for c in ctrl) if len(ctrl) == len(actuators) else tuple(0.0 for _ in actuators),
        vertical_hinges=_vertical_hinges(model, data, gravity, compiled_names),
        key_is_equilibrium=key_is_equilibrium,
        key_moved=tuple(moved),
        authority=_authority(model, data, qpos, actuators, order),
        linear=_linearization(model, data, qpos, qvel, ctrl, actuators, order),
        notes=tuple(notes),
        friction_form=friction_form,
    )


def _unmodelled(model: mujoco.MjModel) -> list[str]:
    """What the compiled model holds that equilibrist does not model, one line each."""
    mujoco = load_mujoco()
    T = mujoco.mjtObj
    problems: list[str] = []

    def refuse(what: str) -> None:
        problems.append(what)

    for i in range(model.ntendon):
        refuse(f"tendon {_name(model, T.mjOBJ_TENDON, i) or i!r} is not modelled")
    for i in range(model.neq):
        refuse(f"equality constraint {_name(model, T.mjOBJ_EQUALITY, i) or i!r} is not modelled")
    if model.nflex:
        refuse("flex (deformable) elements are not modelled")
    if model.nplugin:
        refuse("plugins are not modelled")
    if float(model.opt.density) != 0 or float(model.opt.viscosity) != 0 or np.any(model.opt.wind != 0):
        refuse("fluid forces (option density, viscosity or wind) are not modelled")
    if np.any(model.body_gravcomp[1:] != 0):
        body = int(np.flatnonzero(model.body_gravcomp[1:])[0]) + 1
        refuse(f"body {_name(model, T.mjOBJ_BODY, body)!r} has gravcomp, which is not modelled")
    flags = int(model.opt.disableflags)
    D = mujoco.mjtDisableBit
    for bit, what in ((D.mjDSBL_GRAVITY, "gravity"), (D.mjDSBL_DAMPER, "joint damping"),
                      (D.mjDSBL_SPRING, "joint springs"), (D.mjDSBL_ACTUATION, "actuation")):
        if flags & int(bit):
            refuse(f"option flag disables {what}: remove the flag (equilibrist models it)")
    for j in range(model.njnt):
        jname = _name(model, T.mjOBJ_JOINT, j) or f"joint{j}"
        kind = int(model.jnt_type[j])
        if kind == int(mujoco.mjtJoint.mjJNT_FREE):
            refuse(f"free joint {jname!r} is not modelled (only hinge and slide joints)")
        elif kind == int(mujoco.mjtJoint.mjJNT_BALL):
            refuse(f"ball joint {jname!r} is not modelled (only hinge and slide joints)")
        else:
            dof = int(model.jnt_dofadr[j])
            if np.any(model.dof_dampingpoly[dof] != 0):
                refuse(f"joint {jname!r} has nonlinear damping (dampingpoly), which is not modelled")
            if np.any(model.jnt_stiffnesspoly[j] != 0):
                refuse(f"joint {jname!r} has nonlinear stiffness (stiffnesspoly), which is not modelled")
    return problems


def _joint_names(model: mujoco.MjModel, file: Path) -> list[str]:
    """The names of the compiled model's joints, in its order; each must be an identifier."""
    T = load_mujoco().mjtObj
    where = file.name
    compiled_names = []
    for j in range(model.njnt):
        jname = _name(model, T.mjOBJ_JOINT, j)
        if not jname:
            owner = _name(model, T.mjOBJ_BODY, int(model.jnt_bodyid[j])) or f"number {model.jnt_bodyid[j]}"
            raise DefinitionError(
                f"{where}: a joint of body {owner!r} has no name: states are named by their joints"
            )
        _identifier("joint", jname, file)
        compiled_names.append(jname)
    return compiled_names


def _joint_order(model: mujoco.MjModel, file: Path, compiled_names: list[str],
                 joint_order: tuple[str, ...] | None) -> list[int]:
    """The compiled model's joints (indices) in *joint_order*, or in the compiler's order."""
    where = file.name
    order = list(range(model.njnt))
    if joint_order is not None:
        # The file's document order; MuJoCo expands a URDF planar joint into
        # <name>_TX, <name>_TY, <name>_RZ, which keep its place, in order.
        def rank(j: int) -> int:
            name = compiled_names[j]
            if name in joint_order:
                return joint_order.index(name)
            owners = [k for k, n in enumerate(joint_order) if name.startswith(n + "_")]
            if not owners:
                raise DefinitionError(f"{where}: joint {name!r} of the compiled model is not in the file")
            return max(owners, key=lambda k: len(joint_order[k]))

        order = sorted(range(model.njnt), key=rank)
    return order


def _joints(model: mujoco.MjModel, order: list[int], compiled_names: list[str]) -> list[JointData]:
    """The hinge and slide joints, in *order*."""
    mujoco = load_mujoco()
    joints = []
    for j in order:
        dof, adr = int(model.jnt_dofadr[j]), int(model.jnt_qposadr[j])
        joints.append(JointData(
            name=compiled_names[j],
            kind="hinge" if int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE) else "slide",
            pos=_vec(model.jnt_pos[j]),
            axis=_vec(model.jnt_axis[j] / np.linalg.norm(model.jnt_axis[j])),
            ref=float(model.qpos0[adr]),
            stiffness=float(model.jnt_stiffness[j]),
            spring_ref=float(model.qpos_spring[adr]),
            damping=float(model.dof_damping[dof]),
            armature=float(model.dof_armature[dof]),
            limited=bool(model.jnt_limited[j]),
            friction=float(model.dof_frictionloss[dof]),
            range=(float(model.jnt_range[j, 0]), float(model.jnt_range[j, 1])) if model.jnt_limited[j] else None,
        ))
    return joints


def _moving_bodies(model: mujoco.MjModel, file: Path, position: dict[int, int],
                   stand_ins: dict[str, float]) -> list[BodyData]:
    """Every body that moves (welded to a body with a joint), parents first; *position*
    maps a compiled joint's index to its place in the joints; *stand_ins*, the inertia
    (kg m^2 about each axis) a body was lent for MuJoCo, taken away."""
    mujoco = load_mujoco()
    T = mujoco.mjtObj
    where = file.name
    index: dict[int, int] = {}
    bodies: list[BodyData] = []
    for b in range(1, model.nbody):
        if int(model.body_weldid[b]) == 0:
            continue  # fixed to the world: it does not move
        label = _name(model, T.mjOBJ_BODY, b)
        name = label or f"body{b}"
        _identifier("body", name, file)
        mass = float(model.body_mass[b])
        if not mass > TINY:
            raise DefinitionError(
                f"{where}: body {name!r} has mass {mass:g}: every moving body needs a mass > 0 "
                "(an <inertial> element, or geoms to infer it from)"
            )
        rot = _quat_matrix(np.asarray(model.body_iquat[b], float))
        principal = np.asarray(model.body_inertia[b], float)
        _check_inertia(where, name, principal)
        full = rot @ np.diag(principal) @ rot.T
        full = (full + full.T) / 2 - stand_ins.get(label, 0.0) * np.eye(3)
        parent = int(model.body_parentid[b])
        pos, quat = _vec(model.body_pos[b]), tuple(float(v) for v in model.body_quat[b])
        if parent not in index and parent != 0:
            # On a body fixed to the world: its frame is constant, so this
            # body's frame is placed in the world's directly.
            rest = mujoco.MjData(model)
            mujoco.mj_kinematics(model, rest)
            p_rot = np.asarray(rest.xmat[parent], float).reshape(3, 3)
            pos = _vec(np.asarray(rest.xpos[parent], float) + p_rot @ np.asarray(model.body_pos[b], float))
            composed = np.zeros(4)
            mujoco.mju_mulQuat(composed, np.asarray(rest.xquat[parent], float),
                               np.asarray(model.body_quat[b], float))
            quat = tuple(float(v) for v in composed)
        first = int(model.body_jntadr[b])
        own = tuple(position[j] for j in range(first, first + int(model.body_jntnum[b]))) if first >= 0 else ()
        bodies.append(BodyData(
            name=name,
            label=label or f"number {b}",
            parent=index.get(parent, -1),
            pos=pos,
            quat=quat,  # type: ignore[arg-type]
            joints=own,
            mass=mass,
            com=_vec(model.body_ipos[b]),
            inertia=tuple(_vec(r) for r in full),  # type: ignore[arg-type]
        ))
        index[b] = len(bodies) - 1
    return bodies


def _sensors(model: mujoco.MjModel,
             compiled_names: list[str]) -> tuple[list[tuple[str, float | None]], list[str]]:
    """The measured joints with their noise (None: the file gives none), and the names of
    the sensors that are not joint positions (not used)."""
    mujoco = load_mujoco()
    T = mujoco.mjtObj
    sensors: list[tuple[str, float | None]] = []
    ignored: list[str] = []
    for s in range(model.nsensor):
        sname = _name(model, T.mjOBJ_SENSOR, s) or f"sensor {s}"
        if int(model.sensor_type[s]) == int(mujoco.mjtSensor.mjSENS_JOINTPOS):
            j = int(model.sensor_objid[s])
            noise = float(model.sensor_noise[s])
            sensors.append((compiled_names[j], noise if noise > 0 else None))
        else:
            ignored.append(sname)
    return sensors, ignored


def _keyframe(model: mujoco.MjModel) -> tuple[str | None, np.ndarray, np.ndarray, np.ndarray]:
    """The operating point the file gives: the keyframe named ``balance``, else the first,
    else the zero configuration (name None); its ``qpos``, ``qvel`` and ``ctrl``."""
    T = load_mujoco().mjtObj
    key_name: str | None = None
    if model.nkey:
        k = 0
        for i in range(model.nkey):
            if _name(model, T.mjOBJ_KEY, i) == "balance":
                k = i
                break
        key_name = _name(model, T.mjOBJ_KEY, k) or f"keyframe {k}"
        qpos = np.asarray(model.key_qpos[k], float).copy()
        qvel = np.asarray(model.key_qvel[k], float).copy()
        ctrl = np.asarray(model.key_ctrl[k], float).copy()
    else:
        qpos = np.zeros(model.nq)
        qvel = np.zeros(model.nv)
        ctrl = np.zeros(model.nu)
    return key_name, qpos, qvel, ctrl


def _vertical_hinges(model: mujoco.MjModel, data: mujoco.MjData, gravity: np.ndarray,
                     compiled_names: list[str]) -> tuple[str, ...]:
    """The hinges whose axis is vertical in *data*'s pose (gravity does no work along them)."""
    mujoco = load_mujoco()
    vertical: list[str] = []
    g_norm = float(np.linalg.norm(gravity))
    for j in range(model.njnt):
        if int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE) and g_norm > 0:
            axis = np.asarray(data.xaxis[j], float)
            if abs(abs(float(axis @ gravity)) / g_norm - 1.0) < 1e-9:
                vertical.append(compiled_names[j])
    return tuple(vertical)


def _motors(model: mujoco.MjModel, file: Path,
            position: dict[int, int]) -> tuple[ActuatorData, ...]:
    """The compiled model's actuators, each a motor on one joint."""
    mujoco = load_mujoco()
    T = mujoco.mjtObj
    where = file.name
    out = []
    per_joint: dict[int, int] = {}
    for a in range(model.nu):
        name = _name(model, T.mjOBJ_ACTUATOR, a)
        if not name:
            raise DefinitionError(f"{where}: actuator number {a} has no name: inputs are named by their actuators")
        _identifier("actuator", name, file)
        if int(model.actuator_trntype[a]) != int(mujoco.mjtTrn.mjTRN_JOINT):
            raise DefinitionError(
                f"{where}: actuator {name!r} does not act on a joint (tendon, site or body "
                "transmissions are not modelled)"
            )
        if (int(model.actuator_dyntype[a]) != int(mujoco.mjtDyn.mjDYN_NONE)
                or int(model.actuator_gaintype[a]) != int(mujoco.mjtGain.mjGAIN_FIXED)
                or int(model.actuator_biastype[a]) != int(mujoco.mjtBias.mjBIAS_NONE)):
            raise DefinitionError(
                f"{where}: actuator {name!r} is not a motor (position, velocity, damper or "
                "activation dynamics are not modelled): use <motor>"
            )
        if float(model.actuator_damping[a]) != 0 or float(model.actuator_armature[a]) != 0:
            raise DefinitionError(f"{where}: actuator {name!r} has damping or armature, which is not modelled")
        if np.any(np.asarray(model.actuator_delay[a]) != 0):
            raise DefinitionError(f"{where}: actuator {name!r} has a delay, which is not modelled")
        j = int(model.actuator_trnid[a, 0])
        gain = float(model.actuator_gainprm[a, 0]) * float(model.actuator_gear[a, 0])
        if gain == 0:
            raise DefinitionError(f"{where}: actuator {name!r} has zero gear or gain")
        if not bool(model.actuator_ctrllimited[a]):
            raise DefinitionError(
                f"{where}: actuator {name!r} has no ctrlrange: give its limits "
                "(ctrlrange=\"low high\"), the saturation that simulation applies"
            )
        low, high = (float(v) for v in model.actuator_ctrlrange[a])
        unit_gain = float(model.actuator_gainprm[a, 0])
        if bool(model.actuator_forcelimited[a]):
            flo, fhi = sorted(float(v) / unit_gain for v in model.actuator_forcerange[a])
            low, high = max(low, flo), min(high, fhi)
        if bool(model.jnt_actfrclimited[j]):
            if per_joint.get(j) is not None or sum(
                int(model.actuator_trnid[b, 0]) == j for b in range(model.nu)
            ) > 1:
                raise DefinitionError(
                    f"{where}: joint {_name(model, T.mjOBJ_JOINT, j)!r} limits the total force of several "
                    "actuators (actuatorfrcrange), which is not modelled"
                )
            flo, fhi = sorted(float(v) / gain for v in model.jnt_actfrcrange[j])
            low, high = max(low, flo), min(high, fhi)
        if not low < high:
            raise DefinitionError(f"{where}: actuator {name!r} has an empty range of controls [{low:g}, {high:g}]")
        per_joint[j] = a
        out.append(ActuatorData(name=name, joint=position[j], gain=gain, low=low, high=high))
    return tuple(out)


__all__ = [
    "TINY",
    "ActuatorData",
    "BodyData",
    "JointData",
    "Matrix3",
    "Tree",
    "Vector3",
    "read_tree",
]
