"""Names of a package imported from their modules on first use (PEP 562).

A package's ``__init__`` lists where each public name lives; :func:`exports`
returns the module ``__getattr__`` that imports it when first asked, so that
importing the package (or one of its modules) does no more work than the
command needs.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping, MutableMapping


def exports(package: str, where: Mapping[str, str], namespace: MutableMapping[str, object]
            ) -> Callable[[str], object]:
    """The ``__getattr__`` of *package*: name -> the attribute of module ``where[name]``,
    kept in *namespace* (the package's globals) once imported."""

    def __getattr__(name: str) -> object:
        module = where.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        namespace[name] = value
        return value

    return __getattr__
