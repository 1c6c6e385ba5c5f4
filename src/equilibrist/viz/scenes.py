"""Drawings of every system of the catalogue from a state vector.

A :class:`Scene` turns one state ``x`` (and the input ``u`` when it has one)
into a list of :class:`Shape` objects in world coordinates (metres; the
gyroscope's in a 3D projection of metres), drawn to scale from the system's
parameters. It reads the state and the parameters only: it never calls the
dynamics. The sign conventions are those of ``SYSTEMS.md``: angles from
vertical-up are clockwise positive, so a positive angle leans a link towards
+x (to the right of the picture); the seesaw's and the ball-and-beam's
angles are counter-clockwise from +x.

Where a dimension is not a parameter (a cart's size, a beam's length), it is
chosen in proportion to one that is and the choice is written beside it.
A wheel's radius comes from its inertia as a uniform disc,
``r = sqrt(2 I / m)``.

:func:`scene_for` returns the scene of a bound
:class:`~equilibrist.numeric.system.System`: the class its definition names
(``SystemSpec.drawing``, imported when a picture is made), or a drawing of
its kinematic tree.

The scenes are in :mod:`equilibrist.viz.scenes_planar` and
:mod:`equilibrist.viz.scenes_3d`, what they draw with (:class:`Shape`,
:class:`Scene`, the geometry) in :mod:`equilibrist.viz.drawing`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import cast

from equilibrist.errors import DefinitionError, UnknownNameError
from equilibrist.mechanics.spec import SystemSpec
from equilibrist.viz.drawing import (
    Scene,
)


def drawing_class(spec: SystemSpec) -> Callable[[object], Scene] | None:
    """The class a system's definition names to draw it (``SystemSpec.drawing``,
    ``"module:Class"``), imported now; None when the definition names none.

    Raises
    ------
    DefinitionError
        When the named module or class does not exist.
    """
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
    """The scene that draws *system* (a bound ``System``).

    A catalogue system has its hand-drawn scene; any other system whose
    derivation records its points (every MJCF or URDF model) is drawn from
    its kinematic tree (:class:`~equilibrist.viz.generic.GenericScene`).

    Raises
    ------
    UnknownNameError
        When no drawing exists for the system (a system added to the
        catalogue without one).
    """
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
