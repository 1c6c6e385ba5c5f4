"""A system's definition as a value: its spec and its derivation (:class:`Entry`), what the
catalogue's registry lists, a model file's importer returns and a script's system is made of."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

from equilibrist.mechanics.spec import SystemSpec

if TYPE_CHECKING:  # sympy is imported only when a model is derived
    from equilibrist.mechanics.model import Derivation, SymbolicModel

DeriveFunction = Callable[["Derivation"], "SymbolicModel"]


@dataclass(frozen=True)
class Entry:
    """A system's definition: its spec and its derivation, as a value.

    ``content`` is everything that shapes the derived model beyond the shared
    mechanics layer (a user's file, a script's function); ``None`` for a
    catalogue module, whose source is read from ``module``. ``origin`` is the
    path of a user's file (the system's key, so that a saved result can
    rebuild it), ``None`` otherwise.
    """

    spec: SystemSpec
    derive: DeriveFunction
    module: str
    content: bytes | None = None
    origin: str | None = None

    @property
    def key(self) -> str:
        """What names this system in results and designs: the file, or the spec key."""
        return self.origin if self.origin is not None else self.spec.key
