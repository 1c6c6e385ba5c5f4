"""The registry of systems.

A system module declares its :class:`~equilibrist.mechanics.spec.SystemSpec`
and decorates its derivation with :func:`register`; adding a system is adding
one file to this package, or one module of one's own named by an entry point
of the group ``equilibrist.systems`` (``pointcart = my_rigs.pointcart``): it
joins the catalogue as the shipped ones do (names, ids, workers, studies).
Families of parameterizations (the gyroscope's ``euler = zxz | xyz``) register
one spec per variant under one name.
"""

from __future__ import annotations

import importlib
import math
import pkgutil
from collections.abc import Callable

from equilibrist.errors import (
    DefinitionError,
    UnknownNameError,
    outside_prints,
    quote_exception,
    quote_outside,
)
from equilibrist.mechanics.definition import DeriveFunction, Entry
from equilibrist.mechanics.spec import SystemSpec

_FAMILIES: dict[str, dict[str | None, Entry]] = {}
_VARIANT_OPTION: dict[str, str] = {}
_DEFAULT_VARIANT: dict[str, str] = {}
_LOADED = False
# Modules of this package that are machinery, not systems.
_NOT_SYSTEMS = frozenset({"registry", "files", "dfki_parameters"})
#: The entry-point group of systems of one's own (a module declaring one or more systems).
ENTRY_POINTS = "equilibrist.systems"
# Modules named by those entry points: their decorated derivations join the catalogue.
_PLUGIN_MODULES: set[str] = set()


# The attribute by which a decorated derivation carries its spec, so that a
# user's file outside this package declares a system the same way.
SPEC_ATTRIBUTE = "__equilibrist_spec__"


def register(spec: SystemSpec, *, default: bool = False) -> Callable[[DeriveFunction], DeriveFunction]:
    """Declare the decorated function as the derivation of *spec*.

    In a module of this package, or one named by an entry point of the group
    ``equilibrist.systems``, the pair joins the catalogue; anywhere else
    (a user's file, a script) the function only carries its spec, and
    :func:`equilibrist.get_system` builds the system from the file.
    """

    def decorate(fn: DeriveFunction) -> DeriveFunction:
        setattr(fn, SPEC_ATTRIBUTE, spec)
        module = getattr(fn, "__module__", None) or ""
        if module.startswith("equilibrist.systems.") or module in _PLUGIN_MODULES:
            _add(spec, fn, default=default)
        return fn

    return decorate


def _add(spec: SystemSpec, fn: DeriveFunction, *, default: bool = False) -> None:
    family = _FAMILIES.setdefault(spec.name, {})
    value = None if spec.variant is None else spec.variant[1]
    if value in family:
        raise DefinitionError(f"system {spec.key} is registered twice ({family[value].module} and "
                              f"{fn.__module__}): expected one definition per name")
    family[value] = Entry(spec, fn, fn.__module__)
    if spec.variant is not None:
        _VARIANT_OPTION[spec.name] = spec.variant[0]
        if default or spec.name not in _DEFAULT_VARIANT:
            _DEFAULT_VARIANT[spec.name] = spec.variant[1]


def _registered(module: str) -> bool:
    return any(e.module == module for f in _FAMILIES.values() for e in f.values())


def _load_all() -> None:
    global _LOADED
    if _LOADED:
        return
    import equilibrist.systems as pkg

    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda m: m.name):
        if info.name not in _NOT_SYSTEMS and not info.name.startswith("_"):
            importlib.import_module(f"{pkg.__name__}.{info.name}")
    _LOADED = True
    from importlib.metadata import entry_points

    for ep in entry_points(group=ENTRY_POINTS):
        _PLUGIN_MODULES.add(ep.module)
        where = (f"the system module '{quote_outside(ep.module, limit=120)}' "
                 f"(entry point '{quote_outside(ep.name, limit=60)}')")
        try:
            # What the module prints is not the command's output (stdout may be its JSON).
            with outside_prints():
                module = importlib.import_module(ep.module)
        except (DefinitionError, KeyboardInterrupt):
            raise
        except BaseException as exc:  # SystemExit too: a broken plugin is named in one line
            raise DefinitionError(f"{where} cannot be loaded: {quote_exception(exc)}") from None
        if not _registered(ep.module):  # imported before the registry knew it was a plugin
            for fn in list(vars(module).values()):
                spec = getattr(fn, SPEC_ATTRIBUTE, None)
                if isinstance(spec, SystemSpec) and getattr(fn, "__module__", None) == ep.module:
                    _add(spec, fn)
        if not _registered(ep.module):
            raise DefinitionError(f"{where} registers no system: expected a derivation decorated "
                                  "with @register(SPEC)")


def family_names() -> list[str]:
    """Registered system names, in the catalogue's order: by each spec's ``position``, then
    those without one by name."""
    _load_all()

    def place(name: str) -> tuple[float, str]:
        position = next(iter(_FAMILIES[name].values())).spec.position
        return (math.inf if position is None else float(position), name)

    return sorted(_FAMILIES, key=place)


def variant_option(name: str) -> str | None:
    """The option that selects a variant of *name* (``"euler"``), or None."""
    _load_all()
    return _VARIANT_OPTION.get(name)


def variants(name: str) -> tuple[str, ...]:
    _load_all()
    return tuple(v for v in lookup_family(name) if v is not None)


def default_variant(name: str) -> str | None:
    _load_all()
    return _DEFAULT_VARIANT.get(name)


def lookup_family(name: str) -> dict[str | None, Entry]:
    _load_all()
    if name not in _FAMILIES:
        from equilibrist.errors import nearest

        hint = nearest(name, family_names())
        known = "" if hint.startswith("expected") else f" (known systems: {', '.join(family_names())})"
        raise UnknownNameError(f"unknown system {name!r}: {hint}{known}")
    return _FAMILIES[name]


def lookup(name: str, variant: str | None = None) -> Entry:
    """The registry entry of *name* (and *variant* for a family)."""
    family = lookup_family(name)
    option = _VARIANT_OPTION.get(name)
    if option is None:
        if variant is not None:
            raise UnknownNameError(f"system {name} has no variants (got {variant!r})")
        return family[None]
    value = variant if variant is not None else _DEFAULT_VARIANT[name]
    if value not in family:
        choices = ", ".join(v for v in family if v is not None)
        raise UnknownNameError(f"{option} = {value!r} is not a variant of {name}: expected one of {choices}")
    return family[value]


def all_entries() -> list[Entry]:
    """Every registered spec, variants included, in catalogue order."""
    out: list[Entry] = []
    for name in family_names():
        out.extend(_FAMILIES[name].values())
    return out
