"""What a URDF says that MuJoCo's URDF reader does not keep.

MuJoCo compiles a URDF's links and joints into the kinematic tree, but it
ignores ``<transmission>`` elements (the actuators) and orders the joints
by the tree rather than by the file. This module reads those few things
with :mod:`xml.etree`: the document order of the moving joints, the
transmissions (one joint, one actuator, a mechanical reduction; ROS 1's
legacy layout, with ``<mechanicalReduction>`` beside the ``<actuator>`` and
no hardware interface, and the current one), each joint's effort limit, and
the checks that MuJoCo's reader does not make (a link without ``<inertial>``,
a link that is the child of two joints). The file is first made into the
URDF MuJoCo's reader takes (:mod:`equilibrist.importers.urdf_clean`: the
``world`` link, namespaces, tool-specific elements, geometry, inertias).

An actuated joint without an effort limit (Drake's examples write none) is
an input without limits, as Drake treats it: its saturation is
:data:`UNLIMITED`, far beyond any force such a model asks for, and a note
says so.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from equilibrist.errors import DefinitionError
from equilibrist.importers.urdf_clean import clean_urdf

# Transmission types that pass the actuator's effort straight to one joint.
_SIMPLE = ("SimpleTransmission",)
# Hardware interfaces that command an effort (a force or torque).
_EFFORT = ("EffortJointInterface",)
_MOVING = ("revolute", "continuous", "prismatic")
# The saturation of an input whose joint has no effort limit [N*m or N].
UNLIMITED = 1e9


@dataclass(frozen=True)
class Transmission:
    """One actuator driving one joint: force ``reduction * u``, ``|u| <= limit``."""

    actuator: str
    joint: str
    reduction: float
    low: float
    high: float
    limited: bool = True


@dataclass(frozen=True)
class UrdfFacts:
    joint_order: tuple[str, ...]  # joints that are not fixed, in document order
    transmissions: tuple[Transmission, ...]
    text: bytes  # the URDF as MuJoCo's reader is given it
    notes: tuple[str, ...]  # what was made of the file, and the inputs without limits
    stand_ins: tuple[tuple[str, float], ...]  # see CleanUrdf.stand_ins
    rotor_inertias: tuple[tuple[str, float], ...]  # see CleanUrdf.rotor_inertias


def _text(element: ET.Element | None) -> str:
    return "" if element is None or element.text is None else element.text.strip()


def _tail(kind: str) -> str:
    return re.split(r"[/:]", kind.strip())[-1]


def read_urdf(file: Path, data: bytes) -> UrdfFacts:
    """The facts of the URDF *data* (the content of *file*)."""
    where = file.name
    clean = clean_urdf(file, data)
    root = clean.root
    links = {link.get("name", ""): link for link in root.findall("link")}
    joints = {j.get("name", ""): j for j in root.findall("joint")}
    # Links, children and loops.
    parent_of: dict[str, str] = {}
    for j in root.findall("joint"):
        name = j.get("name", "")
        child = j.find("child")
        parent = j.find("parent")
        if child is None or parent is None:
            raise DefinitionError(f"{where}: joint {name!r} needs a <parent> and a <child> link")
        c, p = child.get("link", ""), parent.get("link", "")
        for link in (c, p):
            if link not in links:
                raise DefinitionError(f"{where}: joint {name!r} names an unknown link {link!r}")
        if c in parent_of:
            raise DefinitionError(
                f"{where}: link {c!r} is the child of two joints ({parent_of[c]!r} and {name!r}): "
                "a joint loop, which a kinematic tree can not hold"
            )
        parent_of[c] = name
    for link in links:
        seen = {link}
        at = link
        while at in parent_of:
            parent_link = joints[parent_of[at]].find("parent")
            assert parent_link is not None
            at = parent_link.get("link", "")
            if at in seen:
                raise DefinitionError(f"{where}: the joints form a loop through link {link!r}")
            seen.add(at)
    for link_name, element in links.items():
        if (link_name in parent_of and joints[parent_of[link_name]].get("type") in _MOVING
                and element.find("inertial") is None):
            raise DefinitionError(
                f"{where}: link {link_name!r} has no <inertial>: a moving link needs its mass and inertia"
            )
    order = tuple(j.get("name", "") for j in root.findall("joint") if j.get("type") != "fixed")
    transmissions = []
    driven: dict[str, str] = {}
    for t in root.findall("transmission"):
        tname = t.get("name", "")
        kind = _text(t.find("type")) or t.get("type", "")
        if _tail(kind) not in _SIMPLE:
            raise DefinitionError(
                f"{where}: transmission {tname!r} of type {kind!r} is not modelled "
                "(expected transmission_interface/SimpleTransmission)"
            )
        tj = t.findall("joint")
        ta = t.findall("actuator")
        if len(tj) != 1 or len(ta) != 1:
            raise DefinitionError(f"{where}: transmission {tname!r} must have one <joint> and one <actuator>")
        jname = tj[0].get("name", "")
        if jname not in joints:
            raise DefinitionError(f"{where}: transmission {tname!r} drives an unknown joint {jname!r}")
        if joints[jname].get("type") not in _MOVING:
            raise DefinitionError(
                f"{where}: transmission {tname!r} drives joint {jname!r} of type "
                f"{joints[jname].get('type')!r}, expected revolute, continuous or prismatic"
            )
        if jname in driven:
            raise DefinitionError(
                f"{where}: joint {jname!r} is driven by two transmissions ({driven[jname]!r} and {tname!r})"
            )
        driven[jname] = tname
        interfaces = [_text(h) for h in tj[0].findall("hardwareInterface")]
        interfaces += [_text(h) for h in ta[0].findall("hardwareInterface")]
        if interfaces and not all(_tail(h) in _EFFORT for h in interfaces):
            raise DefinitionError(
                f"{where}: transmission {tname!r} uses {', '.join(interfaces)}: only effort "
                "(EffortJointInterface) actuators are modelled"
            )
        aname = ta[0].get("name", "")
        reduction_text = _text(ta[0].find("mechanicalReduction")) or _text(t.find("mechanicalReduction")) or "1"
        try:
            reduction = float(reduction_text)
        except ValueError:
            raise DefinitionError(
                f"{where}: transmission {tname!r}: mechanicalReduction {reduction_text!r} is not a number"
            ) from None
        if not math.isfinite(reduction) or reduction == 0:
            raise DefinitionError(f"{where}: transmission {tname!r}: mechanicalReduction must be a nonzero number")
        limit = joints[jname].find("limit")
        effort_text = None if limit is None else limit.get("effort")
        if effort_text is None:
            transmissions.append(Transmission(aname, jname, reduction, -UNLIMITED, UNLIMITED, limited=False))
            continue
        try:
            effort = float(effort_text)
        except ValueError:
            raise DefinitionError(f"{where}: joint {jname!r}: effort {effort_text!r} is not a number") from None
        if not (math.isfinite(effort) and effort > 0):
            raise DefinitionError(f"{where}: joint {jname!r}: effort limit {effort_text} must be > 0")
        bound = effort / abs(reduction)
        transmissions.append(Transmission(aname, jname, reduction, -bound, bound))
    if not root.findall("transmission"):
        transmissions = _effort_motors(where, root)
    notes = list(clean.notes)
    free = [t for t in transmissions if not t.limited]
    if free:
        notes.append(
            "joints without an effort limit, their actuators' inputs without limits (saturation at "
            f"{UNLIMITED:g}): " + ", ".join(f"{t.joint} ({t.actuator})" for t in free)
        )
    return UrdfFacts(joint_order=order, transmissions=tuple(transmissions), text=clean.text,
                     notes=tuple(notes), stand_ins=clean.stand_ins, rotor_inertias=clean.rotor_inertias)


def _effort_motors(where: str, root: ET.Element) -> list[Transmission]:
    """A URDF without ``<transmission>``: a motor on each moving joint whose
    ``<limit effort>`` is above zero, limited by that effort (what pybullet's
    joint motors apply); a joint without an effort limit is passive.

    The motor is named by its joint; the system names its input
    ``<joint>_force`` or ``<joint>_torque`` (docs/models.md).
    """
    out = []
    for j in root.findall("joint"):
        if j.get("type") not in _MOVING or j.get("type") == "planar":
            continue
        limit = j.find("limit")
        text = None if limit is None else limit.get("effort")
        if text is None:
            continue
        try:
            effort = float(text)
        except ValueError:
            raise DefinitionError(f"{where}: joint {j.get('name')!r}: effort {text!r} is not a number") from None
        if not math.isfinite(effort) or effort < 0:
            raise DefinitionError(f"{where}: joint {j.get('name')!r}: effort limit {text} must be >= 0")
        if effort > 0:
            name = j.get("name", "")
            out.append(Transmission(name, name, 1.0, -effort, effort))
    return out
