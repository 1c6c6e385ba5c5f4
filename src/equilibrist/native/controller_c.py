"""A controller's source translated to C with the linear library in scope: the argument
types of the controller contract's functions (:data:`CONTRACT_TYPES`) and
:func:`translate_controller`, read by the simulation core, the compiled Python runtime
and the exports, so that each writes the same C for the same source.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

from equilibrist.native.linear_layout import LINEAR_SOURCE, linear_constants, linear_layout_source

if TYPE_CHECKING:
    from equilibrist.native.pyc import Function, Module

#: The argument types of the contract's functions in the C translation (``t`` a float,
#: the rest 1-D float arrays), by role.
CONTRACT_TYPES = {
    "output": ("f", "F1", "F1", "F1", "F1", "F1"),
    "update": ("f", "F1", "F1", "F1", "F1", "F1", "F1"),
    "estimate": ("f", "F1", "F1", "F1", "F1", "F1"),
}


def translate_controller(source: str, roles: Mapping[str, str], *, prefix: str = "ctrl_",
                         library: str | None = None) -> tuple[Module, dict[str, Function]]:
    """A controller's functions translated to C (:mod:`equilibrist.native.pyc`).

    *roles* maps each role of the contract (``output``, ``update``,
    ``estimate``) to the function of *source* that plays it; the C names
    start with *prefix*. The linear library (``linear_output``...) is in
    scope, unless *library* gives other functions (``""``: none). Returns the
    translated module (its :meth:`~equilibrist.native.pyc.Module.c_source`)
    and the translated function of each role. Raises
    :class:`~equilibrist.native.pyc.TranslationError`.
    """
    from equilibrist.native.pyc import Module

    mod = Module(source, constants=linear_constants(), prefix=prefix,
                 library=linear_layout_source() + LINEAR_SOURCE if library is None else library)
    return mod, {role: mod.function(name, CONTRACT_TYPES[role]) for role, name in roles.items()}


__all__ = ["CONTRACT_TYPES", "translate_controller"]
