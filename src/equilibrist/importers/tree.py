"""The kinematic tree of a model file, read through MuJoCo's compiler, as plain data.

:func:`read_tree` hands the file to ``mujoco.MjModel.from_xml_path`` (which
reads MJCF and URDF, applies defaults classes, the angle unit, euler
sequences, ``fullinertia``, inertia inferred from geoms, and merges fixed
joints), checks that the compiled model holds only what equilibrist models,
and copies what the derivation needs into frozen dataclasses of floats.
Anything that the compiled model has and equilibrist does not model is
refused with one line naming the element; nothing is silently dropped.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.errors import DefinitionError

if TYPE_CHECKING:
    import mujoco

Vector3 = tuple[float, float, float]
Matrix3 = tuple[Vector3, Vector3, Vector3]

# Below this, a value read from the file counts as zero (MuJoCo's mjMINVAL).
TINY = 1e-15
_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


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
    notes: tuple[str, ...]


def load_mujoco() -> Any:
    try:
        import mujoco
    except ImportError:
        raise DefinitionError(
            "reading MJCF or URDF models needs MuJoCo: pip install 'equilibrist[models]'"
        ) from None
    return mujoco


def compile_model(file: Path) -> mujoco.MjModel:
    """The compiled model of *file*; MuJoCo's error becomes one line."""
    mujoco = load_mujoco()
    try:
        return mujoco.MjModel.from_xml_path(str(file))
    except ValueError as exc:
        message = one_line(str(exc))
    import xml.etree.ElementTree as ET

    try:
        ET.parse(file)
    except ET.ParseError as exc:  # says where, plainly
        raise DefinitionError(f"{file.name}: malformed XML: {exc}") from None
    raise DefinitionError(f"{file.name}: {message}")


def one_line(message: str) -> str:
    """MuJoCo's multi-line compile error as one line: what, and where."""
    lines = [ln.strip() for ln in message.strip().splitlines() if ln.strip()]
    if not lines:
        return "MuJoCo could not read the model"
    what = re.sub(r"^(Error|XML Error|Parse error)\s*:\s*", "", lines[0]).rstrip(".")
    what = what.replace("mjMINVAL", "1e-15 (mjMINVAL)")
    where = ""
    for ln in lines[1:]:
        found = re.search(r"line (\d+)", ln)
        element = re.search(r"Element name '([^']*)'", ln)
        bits = []
        if element and element.group(1) and element.group(1) not in what:
            bits.append(f"element {element.group(1)!r}")
        if found:
            bits.append(f"line {found.group(1)}")
        if bits:
            where = f" ({', '.join(bits)})"
            break
    return f"{what}{where}"


def _name(model: Any, obj: Any, index: int) -> str:
    mujoco = load_mujoco()
    return mujoco.mj_id2name(model, obj, index) or ""


def _identifier(kind: str, name: str, file: Path) -> None:
    if not _IDENTIFIER.match(name):
        raise DefinitionError(
            f"{file.name}: {kind} {name!r} can not name a state or parameter: "
            "expected letters, digits and underscores, not starting with a digit"
        )


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = (float(v) for v in q / np.linalg.norm(q))
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def _vec(v: Any) -> Vector3:
    return (float(v[0]), float(v[1]), float(v[2]))


def read_tree(
    file: Path,
    *,
    joint_order: tuple[str, ...] | None = None,
    actuators: tuple[ActuatorData, ...] | None = None,
) -> Tree:
    """Compile *file* and read its tree.

    *joint_order* reorders the joints (a URDF's document order; MJCF's is
    the compiler's own). *actuators* replaces the compiled model's (a
    URDF's transmissions, which MuJoCo's URDF reader ignores); their
    ``joint`` indices refer to the order of the compiled model's joints.
    """
    mujoco = load_mujoco()
    model = compile_model(file)
    where = file.name
    T = mujoco.mjtObj
    problems: list[str] = []

    def refuse(what: str) -> None:
        problems.append(what)

    # -- elements equilibrist does not model ---------------------------------------
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
            if float(model.dof_frictionloss[dof]) > 0:
                refuse(f"joint {jname!r} has frictionloss (dry friction), which is not modelled")
            if np.any(model.dof_dampingpoly[dof] != 0):
                refuse(f"joint {jname!r} has nonlinear damping (dampingpoly), which is not modelled")
            if np.any(model.jnt_stiffnesspoly[j] != 0):
                refuse(f"joint {jname!r} has nonlinear stiffness (stiffnesspoly), which is not modelled")
    problems.extend(_not_finite(model, mujoco))
    if problems:
        raise DefinitionError(f"{where}: " + "; ".join(problems))

    # -- joints ----------------------------------------------------------------------
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
    position = {j: k for k, j in enumerate(order)}
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
        ))

    # -- bodies: every body that moves (welded to a body with a joint) ------------------
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
        full = (full + full.T) / 2
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

    # -- actuators -----------------------------------------------------------------------
    if actuators is None:
        actuators = _motors(model, file, position)

    # -- sensors ---------------------------------------------------------------------------
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

    # -- the operating point ---------------------------------------------------------------
    key_name: str | None = None
    data = mujoco.MjData(model)
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
    model.opt.disableflags |= int(D.mjDSBL_CONSTRAINT)
    moved: list[tuple[str, float]] = []
    key_is_equilibrium = _holds(model, data, qpos, qvel, ctrl)
    if not key_is_equilibrium:
        qpos, ctrl, moved = _nearest_equilibrium(model, data, qpos, qvel, ctrl, actuators, order, compiled_names)
        key_is_equilibrium = _holds(model, data, qpos, qvel, ctrl)
    data.qpos[:], data.qvel[:] = qpos, qvel
    mujoco.mj_kinematics(model, data)
    gravity = np.asarray(model.opt.gravity, float)
    vertical: list[str] = []
    g_norm = float(np.linalg.norm(gravity))
    for j in range(model.njnt):
        if int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE) and g_norm > 0:
            axis = np.asarray(data.xaxis[j], float)
            if abs(abs(float(axis @ gravity)) / g_norm - 1.0) < 1e-9:
                vertical.append(compiled_names[j])
    qpos_by_joint = tuple(float(qpos[int(model.jnt_qposadr[j])]) for j in order)
    qvel_by_joint = tuple(float(qvel[int(model.jnt_dofadr[j])]) for j in order)

    notes = ["contacts and joint limits (range) are not modelled: the model is the free motion "
             "of the kinematic tree"]
    limited = [j.name for j in joints if j.limited]
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
        vertical_hinges=tuple(vertical),
        key_is_equilibrium=key_is_equilibrium,
        key_moved=tuple(moved),
        authority=_authority(model, data, qpos, actuators, order),
        notes=tuple(notes),
    )


# The nearest equilibrium may lie at most this far from the file's pose, in
# each coordinate that moves (rad or m); farther, the file's pose is kept and
# the operating point is refused where it is used, saying what was found.
MAX_MOVE = 0.1


def _holds(model: Any, data: Any, qpos: np.ndarray, qvel: np.ndarray, ctrl: np.ndarray) -> bool:
    """Whether *qpos*, *qvel* with the controls *ctrl* is an equilibrium (qacc = 0)."""
    mujoco = load_mujoco()
    data.qpos[:], data.qvel[:] = qpos, qvel
    if model.nu:
        data.ctrl[:] = ctrl
    mujoco.mj_forward(model, data)
    return bool(np.all(np.abs(data.qacc) < 1e-9 * (1.0 + np.abs(data.qfrc_bias).max(initial=0.0))))


def _nearest_equilibrium(
    model: Any, data: Any, qpos: np.ndarray, qvel: np.ndarray, ctrl: np.ndarray,
    actuators: tuple[ActuatorData, ...], order: list[int], names: list[str],
) -> tuple[np.ndarray, np.ndarray, list[tuple[str, float]]]:
    """The equilibrium nearest the file's pose, by MuJoCo's inverse dynamics.

    The joints no actuator drives are free; at ``qacc = 0`` the generalized
    force that MuJoCo's ``mj_inverse`` asks for must vanish on them (solved
    from the file's pose, so the solution is the nearest one) and equal the
    motors' force on the driven joints (their controls solved by least
    squares). Returns the pose, the controls (in the actuators' order) and
    the coordinates that moved; a solution farther than :data:`MAX_MOVE`,
    or none, keeps the file's pose and controls.
    """
    from scipy.optimize import least_squares

    mujoco = load_mujoco()
    driven = {order[a.joint] for a in actuators}
    free = [j for j in range(model.njnt) if j not in driven]
    adr = [int(model.jnt_qposadr[j]) for j in free]
    dofs = [int(model.jnt_dofadr[j]) for j in free]

    def inverse(q: np.ndarray) -> np.ndarray:
        data.qpos[:], data.qvel[:] = q, qvel
        data.qacc[:] = 0.0
        mujoco.mj_inverse(model, data)
        return np.array(data.qfrc_inverse, float)

    q = qpos.copy()
    scale = 1.0 + float(np.abs(inverse(q)).max(initial=0.0))
    if free:
        def residual(z: np.ndarray) -> np.ndarray:
            qq = qpos.copy()
            qq[adr] = z
            return inverse(qq)[dofs] / scale

        with np.errstate(all="ignore"):
            z = least_squares(residual, qpos[adr], xtol=1e-15, ftol=1e-15, gtol=1e-15).x
        if not (np.all(np.isfinite(z)) and np.abs(z - qpos[adr]).max() <= MAX_MOVE
                and np.abs(residual(z)).max() <= 1e-12):
            return qpos, ctrl, []
        q[adr] = z
    force = inverse(q)
    new_ctrl = ctrl.copy()
    if actuators:
        gains = np.zeros((model.nv, len(actuators)))
        for k, a in enumerate(actuators):
            gains[int(model.jnt_dofadr[order[a.joint]]), k] = a.gain
        solved = np.linalg.lstsq(gains, force, rcond=None)[0]
        if len(new_ctrl) == len(actuators):
            new_ctrl = solved
    # Moves of round-off size (a joint the solver only grazed) are not reported.
    moved = [(names[j], float(q[a] - qpos[a])) for j, a in zip(free, adr, strict=True)
             if abs(q[a] - qpos[a]) > 1e-12]
    return q, new_ctrl, moved


def _authority(model: Any, data: Any, qpos: np.ndarray, actuators: tuple[ActuatorData, ...],
               order: list[int]) -> tuple[float, ...]:
    """Per joint (in *order*), ``sum_a |M^-1[j, a]| * |gain_a| * (high_a - low_a) / 2``."""
    mujoco = load_mujoco()
    data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, mass)
    inverse = np.linalg.inv(mass)
    reach = np.zeros(model.nv)
    for a in actuators:
        dof = int(model.jnt_dofadr[order[a.joint]])
        reach += np.abs(inverse[:, dof]) * abs(a.gain) * (a.high - a.low) / 2
    return tuple(float(reach[int(model.jnt_dofadr[j])]) for j in order)


# What each compiled array holds, for a value that is not a finite number.
_FINITE = (
    ("jnt_axis", "joint", "mjOBJ_JOINT", "axis"),
    ("jnt_pos", "joint", "mjOBJ_JOINT", "pos"),
    ("qpos0", None, None, "joint reference (ref)"),
    ("jnt_stiffness", "joint", "mjOBJ_JOINT", "stiffness"),
    ("qpos_spring", None, None, "joint springref"),
    ("dof_damping", "dof", "mjOBJ_JOINT", "damping"),
    ("dof_armature", "dof", "mjOBJ_JOINT", "armature"),
    ("body_pos", "body", "mjOBJ_BODY", "pos"),
    ("body_quat", "body", "mjOBJ_BODY", "orientation"),
    ("body_ipos", "body", "mjOBJ_BODY", "centre of mass (inertial pos)"),
    ("body_iquat", "body", "mjOBJ_BODY", "inertial orientation"),
    ("body_mass", "body", "mjOBJ_BODY", "mass"),
    ("body_inertia", "body", "mjOBJ_BODY", "inertia"),
    ("actuator_gear", "actuator", "mjOBJ_ACTUATOR", "gear"),
    ("actuator_gainprm", "actuator", "mjOBJ_ACTUATOR", "gain"),
    ("actuator_ctrlrange", "actuator", "mjOBJ_ACTUATOR", "ctrlrange"),
    ("actuator_forcerange", "actuator", "mjOBJ_ACTUATOR", "forcerange"),
    ("jnt_actfrcrange", "joint", "mjOBJ_JOINT", "actuatorfrcrange"),
    ("key_qpos", "key", "mjOBJ_KEY", "qpos"),
    ("key_qvel", "key", "mjOBJ_KEY", "qvel"),
    ("key_ctrl", "key", "mjOBJ_KEY", "ctrl"),
    ("sensor_noise", "sensor", "mjOBJ_SENSOR", "noise"),
)


def _not_finite(model: Any, mujoco: Any) -> list[str]:
    """Values of the compiled model that are not finite numbers (NaN, inf), and
    damping, stiffness or armature below zero: each one named."""
    problems = []
    T = mujoco.mjtObj
    gravity = np.asarray(model.opt.gravity, float)
    if not np.all(np.isfinite(gravity)):
        problems.append(f"option gravity {' '.join(f'{v:g}' for v in gravity)} is not finite: "
                        "expected three numbers")
    for field, kind, obj, what in _FINITE:
        values = np.asarray(getattr(model, field), float)
        if values.size == 0:
            continue
        rows = values.reshape(values.shape[0], -1)
        for i in np.flatnonzero(~np.all(np.isfinite(rows), axis=1)):
            if kind is None:  # indexed by qpos address
                j = int(np.flatnonzero(np.asarray(model.jnt_qposadr) <= i)[-1])
                label = f"joint {_name(model, T.mjOBJ_JOINT, j) or j!r}"
            elif kind == "dof":
                j = int(model.dof_jntid[i])
                label = f"joint {_name(model, T.mjOBJ_JOINT, j) or j!r}"
            else:
                label = f"{'keyframe' if kind == 'key' else kind} {_name(model, getattr(T, str(obj)), int(i)) or int(i)!r}"
            problems.append(f"{label}: {what} is not a finite number "
                            f"({' '.join(f'{v:g}' for v in rows[i])})")
    for field, what in (("dof_damping", "damping"), ("dof_armature", "armature"),
                        ("jnt_stiffness", "stiffness")):
        values = np.asarray(getattr(model, field), float)
        for i in np.flatnonzero(values < 0):
            j = int(model.dof_jntid[i]) if field.startswith("dof") else int(i)
            problems.append(f"joint {_name(model, T.mjOBJ_JOINT, j) or j!r} has {what} {values[i]:g}: "
                            "expected >= 0")
    return problems


def _model_name(model: Any, file: Path) -> str:
    # The model's name is the first entry of its names buffer.
    raw = bytes(model.names)
    name = raw.split(b"\0", 1)[0].decode(errors="replace")
    return name or file.stem


def _check_inertia(where: str, name: str, principal: np.ndarray) -> None:
    a, b, c = (float(v) for v in principal)
    if min(a, b, c) <= 0:
        raise DefinitionError(
            f"{where}: body {name!r} has an inertia that is not positive definite "
            f"(principal moments {a:g}, {b:g}, {c:g})"
        )
    slack = 1e-9 * (a + b + c)
    if a + b < c - slack or b + c < a - slack or a + c < b - slack:
        raise DefinitionError(
            f"{where}: body {name!r} has principal moments {a:g}, {b:g}, {c:g} that violate "
            "the triangle inequality (each must be at most the sum of the other two)"
        )


def _motors(model: Any, file: Path, position: dict[int, int]) -> tuple[ActuatorData, ...]:
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
