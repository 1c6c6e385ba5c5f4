"""Drawings of every system of the catalogue from a state vector.

A :class:`~equilibrist.viz.drawing.Scene` turns one state ``x`` (and the input ``u``) into
:class:`~equilibrist.viz.drawing.Shape` objects in world coordinates (metres; the
gyroscope's in a 3D projection), drawn to scale from the system's parameters; it never
calls the dynamics. Angles follow ``SYSTEMS.md``: from vertical-up clockwise positive (a
positive angle leans a link towards +x); the seesaw's and the ball-and-beam's
counter-clockwise from +x. A dimension that is not a parameter is chosen in proportion to
one that is, and the choice is written beside it; a wheel's radius comes from its inertia
as a uniform disc, ``r = sqrt(2 I / m)``.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import cast

from equilibrist.errors import DefinitionError, UnknownNameError
from equilibrist.mechanics.spec import SystemSpec
from equilibrist.viz.drawing import Scene


def drawing_class(spec: SystemSpec) -> Callable[[object], Scene] | None:
    """The class a system's definition names to draw it (``SystemSpec.drawing``,
    ``"module:Class"``), imported now; None when it names none."""
    ref = spec.drawing
    if ref is None:
        return None
    module_name, _, attr = ref.partition(":")
    try:
        cls = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError, ValueError) as e:
        raise DefinitionError(
            f"system {spec.key}: its drawing {ref!r} cannot be imported ({e}): "
            "expected 'module:Class' naming a Scene"
        ) from None
    return cast("Callable[[object], Scene]", cls)


def scene_for(system: object) -> Scene:
    """The scene that draws *system* (a bound ``System``): the class its definition names,
    else, when its derivation records its points (every MJCF or URDF model), its kinematic
    tree (:class:`~equilibrist.viz.generic.GenericScene`)."""
    spec = system.spec  # type: ignore[attr-defined]
    cls = drawing_class(spec)
    if cls is not None:
        return cls(system)
    from equilibrist.viz.generic import GenericScene, can_draw

    if can_draw(system):
        return GenericScene(system)
    raise UnknownNameError(
        f"no drawing for system {spec.key!r}: its definition names none (SystemSpec.drawing), "
        "and its derivation records no points to draw it from (model files do)"
    )


__all__ = [
    "drawing_class",
    "scene_for",
]
