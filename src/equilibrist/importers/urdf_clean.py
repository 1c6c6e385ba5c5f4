"""A URDF as ROS, Drake and Gazebo users write it, made into the URDF MuJoCo's reader takes.

MuJoCo's URDF reader refuses several habits of the field's own files, and
this module takes them away before it reads the file, saying what it did in
notes (the system's ``notes``, ``show --json`` too), never silently:

* the link ``world``: a joint whose parent is ``world`` (defined in the file
  or not, the ROS and Drake convention) is a joint to the world; a fixed one
  places the base. The ``world`` link is replaced by an empty root link
  (MuJoCo's own world body is called ``world``), its inertial ignored;
* Drake's rotor inertia: an actuator's ``<drake:rotor_inertia value>`` through
  its ``<drake:gear_ratio value>`` is the reflected inertia ``Ir * gr**2`` on
  its joint, as Drake's MultibodyPlant adds it (:attr:`CleanUrdf.rotor_inertias`);
* XML namespaces: the root's own (``<robot xmlns="https://drake.mit.edu">``)
  is taken as URDF's; elements and attributes of other namespaces and those
  that are not URDF (``drake_ignore``, ``<gazebo>``, ``<frame>``,
  ``<ros2_control>``, schema attributes) are removed, each named once in a
  note. Nothing in them is read or run;
* ``<visual>`` and ``<collision>``: contacts are not modelled and a link's
  mass is its ``<inertial>`` (URDF's rule, and Drake's), so geometry is not
  given to MuJoCo and a mesh file that is not shipped is no error (named in
  a note);
* inertias that MuJoCo refuses but a tree can have: a link fixed to a moving
  link with no mass or no rotational inertia (a marker, a point mass) is
  merged into its parent here (mass, centre of mass and inertia added by the
  parallel-axis rule); a moving link that is a point mass, or a rod, is given
  to MuJoCo with ``STAND_IN`` kg m^2 per kg added about each axis, which the
  derivation takes away again (:attr:`CleanUrdf.stand_ins`); links welded to
  the world carry nothing that moves, and their inertials are dropped.

A document with entity declarations (``<!ENTITY``) is refused: entities are
not expanded.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from equilibrist.errors import DefinitionError

WORLD = "world"
# Below this a mass (kg) or a principal moment (kg m^2, relative to the largest) is zero.
_ZERO = 1e-12
# What a point mass or a rod is given about each axis, per kg, for MuJoCo [m^2].
STAND_IN = 1e-6

# URDF's elements and their attributes (ROS's urdfdom schema), as (attributes, children).
# Subtrees marked None are passed as they are (materials; MuJoCo's own <mujoco> extension).
_Schema = tuple[frozenset[str], "dict[str, _Schema | None]"]


def _node(attributes: str, children: dict[str, _Schema | None] | None = None) -> _Schema:
    return frozenset(attributes.split()), children or {}


_ORIGIN = _node("xyz rpy")
_HARDWARE: dict[str, _Schema | None] = {"hardwareInterface": _node(""), "mechanicalReduction": _node(""), "role": _node("")}
_SCHEMA: _Schema = _node("name version", {
    "link": _node("name type", {
        "inertial": _node("", {
            "origin": _ORIGIN, "mass": _node("value"),
            "inertia": _node("ixx ixy ixz iyy iyz izz"),
        }),
        "visual": None, "collision": None,
    }),
    "joint": _node("name type", {
        "origin": _ORIGIN, "parent": _node("link"), "child": _node("link"), "axis": _node("xyz"),
        "calibration": _node("rising falling reference_position"),
        "dynamics": _node("damping friction"),
        "limit": _node("lower upper effort velocity"),
        "mimic": _node("joint multiplier offset"),
        "safety_controller": _node("soft_lower_limit soft_upper_limit k_position k_velocity"),
    }),
    "transmission": _node("name type", {
        "type": _node(""), "joint": _node("name", _HARDWARE), "actuator": _node("name", _HARDWARE),
        "mechanicalReduction": _node(""),
    }),
    "material": None,
    "mujoco": None,
})


@dataclass(frozen=True)
class CleanUrdf:
    """The URDF as MuJoCo reads it, what was done to it, and the inertias MuJoCo is lent."""

    root: ET.Element
    text: bytes
    notes: tuple[str, ...]
    # Moving links MuJoCo is given more inertia than they have: (link, kg m^2 added about
    # each axis), to be taken away from the compiled body's inertia.
    stand_ins: tuple[tuple[str, float], ...]
    # Joints with Drake's reflected rotor inertia: (joint, Ir * gr**2 in kg m^2 or kg).
    rotor_inertias: tuple[tuple[str, float], ...] = ()


def parse_urdf(where: str, data: bytes) -> ET.Element:
    """The document's root element; entity declarations and malformed XML refused."""
    # Comments carry nothing; MuJoCo's lenient parser takes a "--" in one.
    stripped = re.sub(rb"<!--.*?-->", b"", data, flags=re.S)
    refuse_entities(where, stripped)
    try:
        return ET.fromstring(stripped)
    except ET.ParseError as exc:
        raise DefinitionError(f"{where}: malformed XML: {exc}") from None


def refuse_entities(where: str, data: bytes) -> None:
    """Refuse a document that declares XML entities (MJCF's too): none is ever expanded."""
    if _declares_entities(data):
        raise DefinitionError(
            f"{where}: the document declares XML entities (<!ENTITY>), which are not expanded: "
            "expected a model file without a DOCTYPE's entities"
        )


class _EntityDeclared(Exception):
    pass


def _declares_entities(data: bytes) -> bool:
    """Whether the document declares an entity: expat's own reading, whatever the encoding,
    stopped at the first declaration (before any use could expand it)."""
    from xml.parsers import expat

    def refuse(*_: object) -> None:
        raise _EntityDeclared

    parser = expat.ParserCreate()
    parser.EntityDeclHandler = refuse
    try:
        parser.Parse(data, True)
    except _EntityDeclared:
        return True
    except expat.ExpatError:
        return False  # malformed: ElementTree says where
    return False


def _split(tag: str) -> tuple[str, str]:
    if tag.startswith("{"):
        namespace, _, local = tag[1:].partition("}")
        return namespace, local
    return "", tag


def _prune(element: ET.Element, schema: _Schema, namespace: str, ignored: dict[str, None]) -> None:
    """Strip *element*'s tags of the root's *namespace*; remove what is not URDF, naming it."""
    attributes, children = schema
    for key in list(element.attrib):
        space, local = _split(key)
        if space or local not in attributes:
            ignored[f"attribute {local!r}" + (f" (namespace {space})" if space else "")] = None
            del element.attrib[key]
    for child in list(element):
        if not isinstance(child.tag, str):  # a processing instruction
            element.remove(child)
            continue
        space, local = _split(child.tag)
        if space not in ("", namespace) or local not in children:
            ignored[f"element <{local}>" + (f" (namespace {space})" if space not in ("", namespace) else "")] = None
            element.remove(child)
            continue
        child.tag = local
        sub = children[local]
        if sub is None:
            for inner in child.iter():
                if isinstance(inner.tag, str):
                    inner.tag = _split(inner.tag)[1]
        else:
            _prune(child, sub, namespace, ignored)


def clean_urdf(file: Path, data: bytes) -> CleanUrdf:
    """The URDF *data* (the content of *file*) made into what MuJoCo's reader takes."""
    where = file.name
    root = parse_urdf(where, data)
    namespace, tag = _split(root.tag)
    if tag != "robot":
        raise DefinitionError(f"{where}: expected a <robot> root element (URDF), found <{root.tag}>")
    root.tag = "robot"
    notes: list[str] = []
    ignored: dict[str, None] = {}
    rotors = _rotor_inertias(where, root)
    if rotors:
        notes.append("rotor inertia through the gear (drake:rotor_inertia * drake:gear_ratio^2) on "
                     + ", ".join(f"{j} {v:g}" for j, v in rotors))
    _prune(root, _SCHEMA, namespace, ignored)
    for key in [k for k in ignored if "drake.mit.edu" in k and k.split()[1] in ("<rotor_inertia>", "<gear_ratio>")]:
        del ignored[key]  # read above
    if namespace:
        notes.append(f"the root's XML namespace {namespace} is read as URDF's")
    if ignored:
        notes.append("not URDF, ignored: " + ", ".join(ignored))
    missing = _drop_geometry(file, root)
    if missing:
        notes.append("mesh files not found, ignored (geometry is not modelled): " + ", ".join(missing))
    _world(where, root, notes)
    try:
        stand_ins = _inertials(root, notes)
    except DefinitionError as exc:
        raise DefinitionError(f"{where}: {exc}") from None
    return CleanUrdf(root=root, text=ET.tostring(root), notes=tuple(notes), stand_ins=stand_ins,
                     rotor_inertias=rotors)


def _rotor_inertias(where: str, root: ET.Element) -> tuple[tuple[str, float], ...]:
    """Drake's reflected rotor inertia of each transmission's joint, ``Ir * gr**2``."""
    out: dict[str, float] = {}
    for t in root:
        if not isinstance(t.tag, str) or _split(t.tag)[1] != "transmission":
            continue
        joint = next((e.get("name", "") for e in t if isinstance(e.tag, str) and _split(e.tag)[1] == "joint"), "")
        values = {"rotor_inertia": 0.0, "gear_ratio": 1.0}
        for element in t.iter():
            space, local = _split(element.tag) if isinstance(element.tag, str) else ("", "")
            if "drake.mit.edu" in space and local in values:
                text = element.get("value", "")
                try:
                    values[local] = float(text)
                except ValueError:
                    raise DefinitionError(
                        f"{where}: transmission {t.get('name', '')!r}: drake:{local} value {text!r} "
                        "is not a number"
                    ) from None
                if not (math.isfinite(values[local]) and values[local] >= 0):
                    raise DefinitionError(
                        f"{where}: transmission {t.get('name', '')!r}: drake:{local} value {text!r}: "
                        "expected a finite number >= 0"
                    )
        reflected = values["rotor_inertia"] * values["gear_ratio"] ** 2
        if joint and reflected > 0:
            out[joint] = out.get(joint, 0.0) + reflected
    return tuple(out.items())


def _drop_geometry(file: Path, root: ET.Element) -> list[str]:
    """Remove every ``<visual>`` and ``<collision>``; the mesh files that are not there."""
    missing: dict[str, None] = {}
    for link in root.findall("link"):
        for kind in ("visual", "collision"):
            for element in link.findall(kind):
                for mesh in element.iter("mesh"):
                    name = mesh.get("filename", "")
                    local = re.sub(r"^(package|file|model)://", "", name)
                    if not any(p.is_file() for p in (file.parent / local, file.parent / Path(local).name)):
                        missing[name] = None
                link.remove(element)
    return list(missing)


def _world(where: str, root: ET.Element, notes: list[str]) -> None:
    """A joint to the link ``world`` is a joint to the world: the link becomes an empty root."""
    joints = root.findall("joint")
    uses = [j for j in joints if (p := j.find("parent")) is not None and p.get("link") == WORLD]
    defined = [link for link in root.findall("link") if link.get("name") == WORLD]
    for j in joints:
        child = j.find("child")
        if child is not None and child.get("link") == WORLD:
            raise DefinitionError(
                f"{where}: joint {j.get('name', '')!r} makes the link 'world' a child: "
                "'world' is the world, which no joint moves"
            )
    if not uses and not defined:
        return
    taken = {link.get("name", "") for link in root.findall("link")}
    name = "world_link"
    while name in taken:
        name += "_"
    for link in defined:
        root.remove(link)
    if uses:
        root.insert(0, ET.Element("link", {"name": name}))
        for j in uses:
            parent = j.find("parent")
            assert parent is not None
            parent.set("link", name)
        welds = [j.get("name", "") for j in uses if j.get("type") == "fixed"]
        notes.append(
            "the link 'world' is the world"
            + (" (its inertial ignored)" if defined else "")
            + (f"; {', '.join(welds)} place{'s' * (len(welds) == 1)} the base in it" if welds else "")
        )


def _rpy(origin: ET.Element | None) -> np.ndarray:
    r, p, y = _numbers(origin, "rpy", 3)
    rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    rotation: np.ndarray = rz @ ry @ rx
    return rotation


def _numbers(element: ET.Element | None, key: str, n: int) -> list[float]:
    """The *n* numbers of *element*'s attribute *key* (zeros where it is not given)."""
    text = None if element is None else element.get(key)
    if not text:
        return [0.0] * n
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != n:
        assert element is not None
        raise DefinitionError(
            f"<{element.tag}> {key}={text!r}: expected "
            + ("a number" if n == 1 else f"{n} numbers separated by spaces")
        )
    return values


def _read_inertial(link: ET.Element) -> tuple[float, np.ndarray, np.ndarray] | None:
    """``(mass, com, inertia about the com)`` in the link's frame, or None without one."""
    inertial = link.find("inertial")
    if inertial is None:
        return None
    mass = _numbers(inertial.find("mass"), "value", 1)[0]
    origin = inertial.find("origin")
    com = np.array(_numbers(origin, "xyz", 3))
    rotation = _rpy(origin)
    tensor = inertial.find("inertia")

    def get(key: str) -> float:
        return _numbers(tensor, key, 1)[0]

    local = np.array([[get("ixx"), get("ixy"), get("ixz")],
                      [get("ixy"), get("iyy"), get("iyz")],
                      [get("ixz"), get("iyz"), get("izz")]])
    return mass, com, rotation @ local @ rotation.T


def _singular(mass: float, inertia: np.ndarray) -> bool:
    """No mass, or no rotational inertia about some axis (a point, a rod)."""
    moments = np.linalg.eigvalsh((inertia + inertia.T) / 2)
    return mass <= _ZERO or float(moments.min()) <= _ZERO * max(float(moments.max()), mass * 1e-6)


def _write(link: ET.Element, mass: float, com: np.ndarray, inertia: np.ndarray) -> None:
    for old in link.findall("inertial"):
        link.remove(old)
    inertial = ET.SubElement(link, "inertial")
    ET.SubElement(inertial, "origin", {"xyz": " ".join(repr(float(v)) for v in com), "rpy": "0 0 0"})
    ET.SubElement(inertial, "mass", {"value": repr(float(mass))})
    keys = (("ixx", 0, 0), ("ixy", 0, 1), ("ixz", 0, 2), ("iyy", 1, 1), ("iyz", 1, 2), ("izz", 2, 2))
    ET.SubElement(inertial, "inertia", {k: repr(float(inertia[i, j])) for k, i, j in keys})


def _inertials(root: ET.Element, notes: list[str]) -> tuple[tuple[str, float], ...]:
    """Merge singular links fixed to a moving link into it; drop the inertials of the links
    welded to the world; stand-ins for moving point masses and rods (see the module's text)."""
    links = {link.get("name", ""): link for link in root.findall("link")}
    parent_joint = {}
    for j in root.findall("joint"):
        child = j.find("child")
        if child is not None:
            parent_joint[child.get("link", "")] = j

    def parent_of(name: str) -> str | None:
        j = parent_joint.get(name)
        p = None if j is None else j.find("parent")
        return None if p is None else p.get("link", "")

    def static(name: str) -> bool:
        seen = set()
        while name in parent_joint and name not in seen:
            seen.add(name)
            if parent_joint[name].get("type") != "fixed":
                return False
            name = parent_of(name) or ""
        return True

    def depth(name: str) -> int:
        k, seen = 0, set()
        while (p := parent_of(name)) is not None and name not in seen:
            seen.add(name)
            name, k = p, k + 1
        return k

    merged: list[str] = []
    for name in sorted(links, key=depth, reverse=True):  # leaves first
        link = links[name]
        if static(name):
            _read_inertial(link)  # its numbers checked all the same
            for old in link.findall("inertial"):
                link.remove(old)
            continue
        read = _read_inertial(link)
        joint = parent_joint[name]
        parent = parent_of(name)
        if read is None or joint.get("type") != "fixed" or parent is None or parent not in links \
                or not _singular(read[0], read[2]) or static(parent):
            continue
        origin = joint.find("origin")
        rotation = _rpy(origin)
        offset = np.array(_numbers(origin, "xyz", 3))
        mass_c, com_c = read[0], offset + rotation @ read[1]
        inertia_c = rotation @ read[2] @ rotation.T
        host = _read_inertial(links[parent]) or (0.0, np.zeros(3), np.zeros((3, 3)))
        mass = host[0] + mass_c
        com = (host[0] * host[1] + mass_c * com_c) / mass if mass > 0 else host[1]
        inertia = np.zeros((3, 3))
        for m, c, tensor in ((host[0], host[1], host[2]), (mass_c, com_c, inertia_c)):
            d = c - com
            inertia += tensor + m * (float(d @ d) * np.eye(3) - np.outer(d, d))
        _write(links[parent], mass, com, inertia)
        link.remove(link.find("inertial"))  # type: ignore[arg-type]
        merged.append(name)
    if merged:
        notes.append("links fixed to a moving link with no mass or no rotational inertia, merged into it: "
                     + ", ".join(merged))
    stand_ins: list[tuple[str, float]] = []
    for name, link in links.items():
        read = _read_inertial(link)
        if read is None or static(name) or read[0] <= _ZERO or not _singular(read[0], read[2]):
            continue
        mass, com, inertia = read
        _write(link, mass, com, inertia + STAND_IN * mass * np.eye(3))
        stand_ins.append((name, STAND_IN * mass))
    if stand_ins:
        notes.append("point masses and rods (no inertia about some axis), derived as they are: "
                     + ", ".join(n for n, _ in stand_ins))
    return tuple(stand_ins)
