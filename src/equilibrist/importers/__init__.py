"""Systems from model files: MJCF (``.xml``) and URDF (``.urdf``).

The model file is the only input. MuJoCo's own compiler reads it (MJCF and
URDF alike, with defaults classes, the angle unit, euler sequences,
``fullinertia`` and inertia inferred from geoms, fixed joints merged);
equilibrist takes the compiled kinematic tree (:mod:`.tree`) and derives the
symbolic equations of motion from it by Lagrange's equations written out in
matrices (:mod:`.derive`). A URDF's ``<transmission>`` elements, which MuJoCo
ignores, are read with :mod:`xml.etree` (:mod:`.urdf`).

The system that results is an ordinary :class:`~equilibrist.numeric.system.System`: its
states, inputs, parameters, operating point, outputs and defaults, what is refused with one
line naming the element and what is not modelled are in docs/models.md. A URDF is first made
into what MuJoCo's reader takes (:mod:`.urdf_clean`), saying so in notes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from equilibrist.errors import DefinitionError
from equilibrist.importers.tree import ActuatorData, Tree, read_tree
from equilibrist.mechanics.definition import Entry
from equilibrist.mechanics.spec import (
    Input,
    OperatingPoint,
    Parameter,
    SystemSpec,
    friction,
    nonnegative,
    positive,
)

if TYPE_CHECKING:
    import numpy as np

    from equilibrist.mechanics.model import Derivation, SymbolicModel

# Defaults that make design and simulation work with nothing but the file
# (docs/models.md): Bryson scales of the states, noise and the control rate.
HINGE_SCALE = 0.2  # rad
SLIDE_SCALE = 0.5  # m
RATE_SCALE = 1.0  # rad/s or m/s
# Sensor noise per sample where the file gives none: an encoder's quantization, that of
# 4096 counts a turn for a hinge (2 pi / 4096 / sqrt(12) rad, the catalogue's acrobot's and
# pendubot's), 1e-3 m for a slide.
ENCODER_NOISE = 2 * math.pi / 4096 / math.sqrt(12)  # rad
SLIDE_NOISE = 1e-3  # m
# Process noise on each rate, per sqrt(s) (see _process_noise): the same on every rate, at
# most PROCESS_NOISE, and no more than makes the default LQR's input (its standard
# deviation) INPUT_SHARE of each input's half range.
PROCESS_NOISE = 0.05
INPUT_SHARE = 0.2
CONTROL_RATE = 200.0  # Hz
# A hinge may turn this far from the operating point before a balancing run
# counts as fallen (hinges about the vertical can not fall).
FALL_ANGLE = math.pi / 2

# The symbolic derivation grows steeply with the number of joints (three
# take about a minute, four several): a larger tree is refused up front
# rather than left deriving for hours (docs/models.md).
MAX_COORDINATES = 4

_SOURCES = ("__init__.py", "tree.py", "derive.py", "urdf.py", "urdf_clean.py")


def _importer_source() -> bytes:
    here = Path(__file__).resolve().parent
    return b"".join(name.encode() + (here / name).read_bytes() for name in _SOURCES)


def load_model_file(file: Path, *, origin: str, content: bytes) -> Entry:
    """The definition of the system in the MJCF or URDF *file*.

    Parameters
    ----------
    file : pathlib.Path
        The model file (``.xml`` MJCF or ``.urdf``).
    origin : str
        Its absolute path: the system's key in results and designs.
    content : bytes
        The file's bytes, as read.

    Raises
    ------
    DefinitionError
        A file that can not be read, compiled, or that holds something
        equilibrist does not model; the message is one line naming it.
    """
    suffix = file.suffix.lower()
    if suffix == ".urdf":
        from equilibrist.importers.urdf import read_urdf

        facts = read_urdf(file, content)
        # The numbers MuJoCo will read: a tool's element that is dropped is not checked.
        _check_numbers(file, facts.text)
        tree0 = read_tree(file, joint_order=facts.joint_order, actuators=(), text=facts.text,
                          stand_ins=facts.stand_ins, friction_form="atan", rotor_inertias=facts.rotor_inertias)
        position = {j.name: k for k, j in enumerate(tree0.joints)}
        actuators = []
        for t in facts.transmissions:
            if t.joint not in position:
                raise DefinitionError(
                    f"{file.name}: transmission of {t.actuator!r} drives joint {t.joint!r}, "
                    "which the compiled model does not have"
                )
            actuators.append(ActuatorData(t.actuator, position[t.joint], t.reduction, t.low, t.high))
        tree = read_tree(file, joint_order=facts.joint_order, actuators=tuple(actuators), text=facts.text,
                         stand_ins=facts.stand_ins, friction_form="atan", rotor_inertias=facts.rotor_inertias)
        tree = replace(tree, notes=tree.notes + facts.notes)
        unlimited = tuple(t.actuator for t in facts.transmissions if not t.limited)
        kind = "URDF"
    else:
        _check_numbers(file, content)
        _check_xml(file, content)
        tree = read_tree(file)
        unlimited = ()
        kind = "MJCF"
    spec = build_spec(tree, name=file.name, kind=kind, origin=origin, unlimited=unlimited)

    def derive(d: Derivation) -> SymbolicModel:
        from equilibrist.importers.derive import derive_tree

        return derive_tree(tree, d)

    return Entry(
        spec,
        derive,
        "equilibrist.importers",
        content=content + repr(tree).encode() + _importer_source(),
        origin=origin,
    )


# Attributes that hold names or words, not numbers (a body may be called "nan").
_NAMES = frozenset({
    "name", "model", "class", "childclass", "file", "type", "prefix", "key", "plugin", "instance",
    "link", "parent", "child", "filename", "content_type", "reftype", "objtype", "objname",
    "refname", "target", "meshdir", "texturedir", "assetdir", "cranksite", "slidersite",
    "mesh", "material", "texture", "hfield", "actuator",
})
_NAME_STEMS = ("joint", "body", "site", "tendon", "geom")


def _process_noise(tree: Tree, scales: Sequence[float], ranges: Sequence[float]) -> dict[str, float]:
    """The default process noise of each rate, scaled to what the motors can correct.

    The same on every rate: :data:`PROCESS_NOISE`, or less where the default
    LQR (Bryson's weights: the design *scales* of the states, half of each
    input's range, *ranges*) would spend more than :data:`INPUT_SHARE` of an
    input's half range on it (the stationary standard deviation of its input,
    continuous time, at the operating point). A strong motor keeps 0.05 per
    sqrt(s); dm_control's acrobot under its +-2 N m gets about 0.01, which it
    survives. The design's Kalman filter assumes the same noise, so it is not
    made smaller than that: a filter that assumes too little against its
    sensors' is slow (with 1e-3 rad sensors ``examples/pendubot.urdf`` needed
    0.04 to balance from 0.05 rad; with :data:`ENCODER_NOISE`, 0.015 does).
    """
    names = [f"{j.name}_dot" for j in tree.joints]
    share = _input_share(tree, scales, ranges)
    sigma = PROCESS_NOISE if share is None or share * PROCESS_NOISE <= INPUT_SHARE \
        else float(f"{INPUT_SHARE / share:.2g}")
    return dict.fromkeys(names, sigma)


def _input_share(tree: Tree, scales: Sequence[float], ranges: Sequence[float]) -> float | None:
    """The largest standard deviation of an input, as a share of its half range, that the
    default LQR spends on process noise of unit intensity on every rate (None: no motor,
    or no stabilizing LQR)."""
    import numpy as np

    a, b = (np.array(m, dtype=float) for m in tree.linear)
    if not tree.actuators or b.size == 0:
        return None
    n = a.shape[0] // 2
    half = np.asarray(ranges, dtype=float)
    try:
        with np.errstate(all="ignore"):
            s = _care(a, b, np.diag(1.0 / np.asarray(scales, float) ** 2), np.diag(1.0 / half**2))
            k = np.linalg.solve(np.diag(1.0 / half**2), b.T @ s)
            closed = a - b @ k
            if not np.all(np.linalg.eigvals(closed).real < 0):
                return None
            g = np.vstack([np.zeros((n, n)), np.eye(n)])
            x = _lyapunov(closed, -g @ g.T)
        share = float(np.max(np.sqrt(np.clip(np.diag(k @ x @ k.T), 0.0, None)) / half))
    except (np.linalg.LinAlgError, ValueError):
        return None
    return share if math.isfinite(share) and share > 0 else None


# The two small solves of the process-noise rule with numpy alone: scipy.linalg's import
# (0.2 s) is a tenth of an imported model's first run, and nothing else on that path needs
# it. A rule rounded to two digits needs neither Schur's accuracy nor speed at this size;
# the tests hold both to scipy.linalg's solvers.
def _care(a: np.ndarray, b: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
    """The stabilizing solution of ``A'X + XA - XBR^-1B'X + Q = 0`` from the stable
    invariant subspace of the Hamiltonian matrix (MacFarlane and Potter's method)."""
    import numpy as np

    n = a.shape[0]
    hamiltonian = np.block([[a, -b @ np.linalg.solve(r, b.T)], [-q, -a.T]])
    values, vectors = np.linalg.eig(hamiltonian)
    stable = vectors[:, values.real < 0]
    if stable.shape[1] != n:
        raise np.linalg.LinAlgError("the Hamiltonian matrix has eigenvalues on the imaginary axis")
    x = np.linalg.solve(stable[:n].T, stable[n:].T).T.real
    symmetric: np.ndarray = (x + x.T) / 2
    return symmetric


def _lyapunov(a: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The solution of ``AX + XA' = Q``, by its Kronecker form (a few dozen states at most)."""
    import numpy as np

    n = a.shape[0]
    eye = np.eye(n)
    x = np.linalg.solve(np.kron(eye, a) + np.kron(a, eye), q.reshape(-1, order="F"))
    return x.reshape(n, n, order="F")


def _frictions(tree: Tree) -> list[Parameter]:
    """Each joint's viscous damping, and the Coulomb friction of those that have one."""
    out = []
    for j in tree.joints:
        unit = "N*m*s/rad" if j.kind == "hinge" else "N*s/m"
        out.append(friction(f"{j.name}_damping", j.damping, unit, f"viscous damping of joint {j.name}"))
    for j in tree.joints:
        if j.friction > 0:
            law = "cf * atan(100 v)" if tree.friction_form == "atan" else "cf * tanh(100 v)"
            out.append(friction(
                f"{j.name}_friction", j.friction, "N*m" if j.kind == "hinge" else "N",
                f"Coulomb friction cf of joint {j.name}", note=f"smoothed: {law}", coulomb=True))
    return out


def _region(tree: Tree, kind: str) -> dict[str, tuple[float, float]]:
    """Where a balancing run counts as fallen: each hinge that can fall, the fall angle about
    the operating point; a URDF's joint limits bound it (MJCF's ranges are left as they were)."""
    region = {
        j.name: (tree.key_qpos[k] - FALL_ANGLE, tree.key_qpos[k] + FALL_ANGLE)
        for k, j in enumerate(tree.joints)
        if j.kind == "hinge" and j.name not in tree.vertical_hinges
    }
    if kind == "URDF":
        for k, j in enumerate(tree.joints):
            if j.range is not None and j.range[0] < tree.key_qpos[k] < j.range[1]:
                low, high = region.get(j.name, j.range)
                region[j.name] = (max(low, j.range[0]), min(high, j.range[1]))
    return region


def _unlimited_scale(tree: Tree, k: int, scales: Sequence[float]) -> float:
    """The design scale of actuator *k*, whose input has no limits: the force that gives its
    joint, alone, the acceleration a tilt of every coordinate by its design scale does (at
    the operating point, from MuJoCo's linearization); without one, that which gives it
    1 rad/s^2 or m/s^2. Two significant digits."""
    a, b = tree.linear
    n = len(tree.joints)
    j = tree.actuators[k].joint
    accel = sum(abs(a[n + j][c]) * s for c, s in enumerate(scales)) or RATE_SCALE
    reach = abs(b[n + j][k])
    return float(f"{accel / reach:.2g}") if reach > 0 else 1.0


def _check_numbers(file: Path, content: bytes, depth: int = 0) -> None:
    """Refuse, before MuJoCo reads it, a number that is not finite (``nan``,
    ``inf``) in any attribute, and an ``<include>`` that is not a regular file.

    MuJoCo's compiler accepts NaN with a warning on stderr and a
    ``MUJOCO_LOG.TXT`` in the working folder, and blocks forever on an
    include that is a FIFO.
    """
    import stat
    import xml.etree.ElementTree as ET

    from equilibrist.importers.urdf_clean import refuse_entities

    refuse_entities(file.name, content)  # before anything could expand one
    try:
        root = ET.fromstring(content)
    except ET.ParseError:
        return  # MuJoCo's reader says where
    for element in root.iter():
        for attribute, value in element.attrib.items():
            if attribute in _NAMES or any(attribute.startswith(n) for n in _NAME_STEMS):
                continue
            for token in value.split():
                low = token.lower().lstrip("+-")
                if low in ("nan", "inf", "infinity"):
                    name = element.get("name")
                    which = f"<{element.tag}{f' name={name!r}' if name else ''}>"
                    raise DefinitionError(
                        f"{file.name}: {which} {attribute}={value!r} is not a finite number: "
                        "expected finite values"
                    )
        if element.tag == "include" and element.get("file") and depth < 20:
            included = file.parent / str(element.get("file"))
            try:
                mode = included.stat().st_mode
            except OSError:
                continue  # MuJoCo says it is missing
            if not stat.S_ISREG(mode):
                raise DefinitionError(
                    f"{file.name}: <include file={element.get('file')!r}> is not a regular file: "
                    "expected a model file"
                )
            _check_numbers(included, included.read_bytes(), depth + 1)
    for element in root.iter():
        text = (element.text or "").strip()
        if text and element.tag in ("mechanicalReduction",) and text.lower().lstrip("+-") in ("nan", "inf"):
            raise DefinitionError(f"{file.name}: <{element.tag}> {text} is not a finite number")


def _check_xml(file: Path, content: bytes) -> None:
    """An MJCF file must have a ``<mujoco>`` root (MuJoCo reads a ``<robot>`` as URDF).

    XML that this parser refuses but MuJoCo's more lenient one reads (a
    ``--`` in a comment) is left to MuJoCo.
    """
    import xml.etree.ElementTree as ET

    try:
        root = ET.fromstring(content)
    except ET.ParseError:
        return
    if root.tag != "mujoco":
        raise DefinitionError(
            f"{file.name}: expected an MJCF model (a <mujoco> root element), found <{root.tag}>"
            + (": name a URDF with the .urdf suffix" if root.tag == "robot" else "")
        )


def build_spec(tree: Tree, *, name: str, kind: str, origin: str, unlimited: tuple[str, ...] = ()) -> SystemSpec:
    """The spec of the system of *tree* (a file called *name*); *unlimited* names the
    actuators whose input has no limits (a URDF joint without an effort limit)."""
    joints = tree.joints
    if not joints:
        raise DefinitionError(f"{name}: the model has no hinge or slide joint: nothing moves")
    if len(joints) > MAX_COORDINATES:
        raise DefinitionError(
            f"{name}: {len(joints)} joints: equilibrist derives the equations of motion of at most "
            f"{MAX_COORDINATES} joints symbolically (the derivation grows steeply with each joint); "
            "a larger tree needs a numeric engine such as MuJoCo itself"
        )
    coords = tuple(j.name for j in joints)
    units = {j.name: "rad" if j.kind == "hinge" else "m" for j in joints}
    g_norm = math.sqrt(sum(v * v for v in tree.gravity))
    parameters: list[Parameter] = [
        nonnegative("g", g_norm, "m/s^2", "gravitational acceleration",
                    note=f"the model's gravity, along ({', '.join(f'{v:g}' for v in tree.gravity)})"),
    ]
    for b in tree.bodies:
        parameters.append(positive(
            f"{b.name}_mass", b.mass, "kg", f"mass of body {b.label} (its inertia scales with it)",
            note=f"{b.mass:g} kg in the file",
        ))
    parameters += _frictions(tree)
    inputs = []
    taken = {*coords, *(f"{c}_dot" for c in coords), *(p.name for p in parameters)}
    scales = []
    for a in tree.actuators:
        joint = joints[a.joint]
        unit = "N*m" if joint.kind == "hinge" else "N"
        what = "torque" if joint.kind == "hinge" else "force"
        # The input is the physical torque or force on the joint, gear times
        # MuJoCo's ctrl (a URDF's reduction times the actuator's effort).
        # An actuator named as its joint (MuJoCo's usual convention) names
        # the input <actuator>_torque or <actuator>_force.
        iname = a.name if a.name not in taken else f"{a.name}_{what}"
        low, high = sorted((a.gain * a.low, a.gain * a.high))
        ctrl = "MuJoCo's ctrl" if kind == "MJCF" else "the actuator's effort"
        scale = "" if a.gain == 1 else f"; {ctrl} = {iname} / {a.gain:g}"
        inputs.append(Input(iname, unit, f"{what} of motor {a.name!r} on joint {joint.name}{scale}", low, high))
        if a.gain != 1 or iname != a.name:
            scales.append(f"input {iname} [{unit}] is the {what} of {'motor' if kind == 'MJCF' else 'actuator'} "
                          f"{a.name!r} on joint {joint.name}" + (f", {a.gain:g} * its ctrl" if a.gain != 1 else "")
                          + (f" (limits [{low:g}, {high:g}] {unit}, ctrlrange [{a.low:g}, {a.high:g}])"
                             if a.gain != 1 else ""))
    names = [*coords, *(f"{c}_dot" for c in coords), *(i.name for i in inputs)]
    names += [p.name for p in parameters] + [p.name for i in inputs for p in i.limit_parameters()]
    seen: set[str] = set()
    for n in names:
        if n in seen:
            raise DefinitionError(
                f"{name}: the name {n!r} is used twice among states, inputs and parameters: "
                "rename a joint, body or actuator"
            )
        seen.add(n)
    sensors = tree.sensors or tuple((c, None) for c in coords)
    outputs = tuple(s for s, _ in sensors)
    sensor_noise = {s: noise if noise is not None else ENCODER_NOISE if units[s] == "rad" else SLIDE_NOISE
                    for s, noise in sensors}
    state = {c: v for c, v in zip(coords, tree.key_qpos, strict=True) if v != 0}
    state.update({f"{c}_dot": v for c, v in zip(coords, tree.key_qvel, strict=True) if v != 0})
    free = tuple(i.name for i in inputs)  # solved, from the keyframe's controls, so that the point holds
    operating_point = OperatingPoint(
        state=dict(state),
        inputs={i.name: a.gain * v for i, a, v in zip(inputs, tree.actuators, tree.key_ctrl, strict=True)},
        free=free,
    )
    region = _region(tree, kind)
    design_scales = {j.name: HINGE_SCALE if j.kind == "hinge" else SLIDE_SCALE for j in joints}
    design_scales.update({f"{c}_dot": RATE_SCALE for c in coords})
    design_scales.update({i.name: (i.high - i.low) / 2 for i in inputs})
    for k, (i, a) in enumerate(zip(inputs, tree.actuators, strict=True)):
        if a.name in unlimited:
            design_scales[i.name] = _unlimited_scale(tree, k, [design_scales[c] for c in coords])
            scales.append(f"input {i.name} has no limits: its design scale is {design_scales[i.name]:g} "
                          f"{i.unit}, what gives its joint the acceleration that the design scales' tilt does")
    process_noise = _process_noise(tree, [design_scales[s] for s in (*coords, *(f"{c}_dot" for c in coords))],
                                   [design_scales[i.name] for i in inputs])
    where = f"the keyframe {tree.key_name!r}" if tree.key_name else "the zero configuration"
    if tree.key_moved:
        where += " moved to the nearest equilibrium (" + ", ".join(
            f"{j} {v:+.3g} {units[j]}" for j, v in tree.key_moved) + ")"
    notes = [
        f"imported from the {kind} file {origin} through MuJoCo's compiler; derived by Lagrange's equations of the tree",
        *tree.notes,
        *scales,
        f"operating point: {where}"
        + ("" if tree.key_is_equilibrium or not inputs else " (its inputs solved so that it holds)"),
        "defaults of the import (docs/models.md): design scales 0.2 rad, 0.5 m, 1 /s and half of "
        f"each input's range; sensor noise {ENCODER_NOISE:.2g} rad or {SLIDE_NOISE:g} m where the file "
        "gives none; 200 Hz; process noise "
        + ", ".join(f"{k} {v:g}" for k, v in process_noise.items()) + " per sqrt(s)"
        + ("" if all(v == PROCESS_NOISE for v in process_noise.values())
           else f" (less than {PROCESS_NOISE:g}: the motors can correct no more)"),
    ]
    return SystemSpec(
        name=name,
        title=f"{tree.model_name} ({kind} model)",
        description=(
            f"{kind} model {tree.model_name!r}: {len(joints)} joint{'s' * (len(joints) != 1)}, "
            f"{len(inputs)} motor{'s' * (len(inputs) != 1)}, {len(tree.bodies)} moving "
            f"bod{'ies' if len(tree.bodies) != 1 else 'y'}."
        ),
        coordinates=coords,
        units=units,
        parameters=tuple(parameters),
        inputs=tuple(inputs),
        outputs=outputs,
        operating_point=operating_point,
        source=origin,
        notes=tuple(notes),
        region=region,
        design_scales=design_scales,
        sensor_noise=sensor_noise,
        process_noise=process_noise,
        control_rate=CONTROL_RATE,
    )
