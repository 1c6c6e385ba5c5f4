"""MuJoCo's compiler as :func:`equilibrist.importers.tree.read_tree` uses it: loading
MuJoCo, compiling a file (its error as one line), names of compiled elements, and
the checks of the compiled model's values (finite numbers, names usable as
identifiers, inertias that a body can have)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.errors import DefinitionError

if TYPE_CHECKING:
    import mujoco

_IDENTIFIER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def load_mujoco() -> Any:
    try:
        import mujoco
    except ImportError:
        raise DefinitionError(
            "reading MJCF or URDF models needs MuJoCo: pip install 'equilibrist[models]'"
        ) from None
    return mujoco


def compile_model(file: Path, text: bytes | None = None) -> mujoco.MjModel:
    """The compiled model of *file* (or of *text*, what was made of it); MuJoCo's error
    becomes one line."""
    mujoco = load_mujoco()
    try:
        if text is not None:
            return mujoco.MjModel.from_xml_string(text.decode())
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


def _name(model: mujoco.MjModel, obj: mujoco.mjtObj, index: int) -> str:
    mujoco = load_mujoco()
    return mujoco.mj_id2name(model, obj, index) or ""


def _identifier(kind: str, name: str, file: Path) -> None:
    if not _IDENTIFIER.match(name):
        raise DefinitionError(
            f"{file.name}: {kind} {name!r} can not name a state or parameter: "
            "expected letters, digits and underscores, not starting with a digit"
        )


# What each compiled array holds, for a value that is not a finite number.
_FINITE = (
    ("jnt_axis", "joint", "mjOBJ_JOINT", "axis"),
    ("jnt_pos", "joint", "mjOBJ_JOINT", "pos"),
    ("qpos0", None, None, "joint reference (ref)"),
    ("jnt_stiffness", "joint", "mjOBJ_JOINT", "stiffness"),
    ("qpos_spring", None, None, "joint springref"),
    ("dof_damping", "dof", "mjOBJ_JOINT", "damping"),
    ("dof_armature", "dof", "mjOBJ_JOINT", "armature"),
    ("dof_frictionloss", "dof", "mjOBJ_JOINT", "friction (frictionloss)"),
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


def _not_finite(model: mujoco.MjModel, mujoco: Any) -> list[str]:
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
                        ("jnt_stiffness", "stiffness"), ("dof_frictionloss", "friction (frictionloss)")):
        values = np.asarray(getattr(model, field), float)
        for i in np.flatnonzero(values < 0):
            j = int(model.dof_jntid[i]) if field.startswith("dof") else int(i)
            problems.append(f"joint {_name(model, T.mjOBJ_JOINT, j) or j!r} has {what} {values[i]:g}: "
                            "expected >= 0")
    return problems


def _model_name(model: mujoco.MjModel, file: Path) -> str:
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
