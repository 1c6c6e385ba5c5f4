"""Systems found and bound: by catalogue name or file (:func:`get_system`), by the key
a saved result or design records (:func:`system_from_key`, :func:`system_for_data`),
in a worker process (:func:`rebuild_system`), with their parameter values checked.

:class:`~equilibrist.numeric.system.System` imports this module, so the two
functions here that need the class at run time import it when called.
"""

from __future__ import annotations

import os
import types
from collections.abc import Mapping
from typing import TYPE_CHECKING

from equilibrist.errors import (
    CodeInDataError,
    DefinitionError,
    ParameterError,
    UnknownNameError,
    nearest,
)
from equilibrist.mechanics.definition import Entry
from equilibrist.mechanics.spec import SystemSpec
from equilibrist.numeric import cache
from equilibrist.systems import registry

if TYPE_CHECKING:
    from equilibrist.numeric.system import System


def _validated(spec: SystemSpec, values: Mapping[str, object]) -> dict[str, float]:
    """Check names and ranges of *values*; collect every problem, raise once."""
    by_name = {p.name: p for p in spec.all_parameters}
    problems: list[str] = []
    out: dict[str, float] = {}
    for name, raw in values.items():
        if name not in by_name:
            problems.append(f"unknown parameter {name!r} of {spec.key}: {nearest(name, list(by_name))}")
            continue
        try:
            v = float(raw)  # type: ignore[arg-type]
        except OverflowError:
            problems.append(f"parameter {name} = {raw!r} is too large for double precision")
            continue
        except (TypeError, ValueError):
            problems.append(f"parameter {name} = {raw!r} is not a number")
            continue
        problem = by_name[name].check(v)
        if problem:
            problems.append(problem)
        else:
            out[name] = v
    if problems:
        unknown_only = all(p.startswith("unknown parameter") for p in problems)
        cls = UnknownNameError if unknown_only else ParameterError
        raise cls("; ".join(problems))
    return out


def _check_limits_order(spec: SystemSpec, params: Mapping[str, float]) -> None:
    for i in spec.inputs:
        lo, hi = params[f"{i.name}_min"], params[f"{i.name}_max"]
        if not lo < hi:
            raise ParameterError(
                f"input limits of {i.name}: {i.name}_min = {lo:g} must be below {i.name}_max = {hi:g}"
            )


def get_system(name: str, **settings: object) -> System:
    """The system *name* with parameters from *settings*.

    *name* is a catalogue name or the path of a system file: a Python file
    that declares a system as a catalogue module does, an MJCF model
    (``.xml``) or a URDF (``.urdf``). *settings* holds parameter values and,
    for a family, its variant option
    (``get_system("gyroscope", euler="xyz", m=2.0)``).
    """
    from equilibrist.systems import files

    if not isinstance(name, (str, os.PathLike)):
        raise UnknownNameError(
            f"system: expected a system name or the path of a system file, got {type(name).__name__}"
        )
    name = os.fspath(name)
    if files.looks_like_path(name):
        return _bind(files.from_file(name), settings)
    option = registry.variant_option(name)
    registry.lookup_family(name)
    variant = None
    settings = dict(settings)
    if option is not None and option in settings:
        variant = str(settings.pop(option))
    return _bind(registry.lookup(name, variant), settings)


def _bind(entry: Entry, settings: Mapping[str, object]) -> System:
    from equilibrist.numeric.system import System

    defaults = {p.name: float(p.default) for p in entry.spec.all_parameters}
    values = _validated(entry.spec, settings)
    defaults.update(values)
    _check_limits_order(entry.spec, defaults)
    return System(entry.spec, cache.load(entry), types.MappingProxyType(defaults))


def system_from_key(key: str, params: Mapping[str, float] | None = None, *,
                    digest: str | None = None, source: str = "the data") -> System:
    """The system a saved result or a design names by *key*, with *params* bound.

    The inverse of :attr:`System.key` plus :attr:`System.params`, for what a
    file records. Data never chooses code: a key that is a Python system file
    is taken only as this process already ran it, because the user named it
    (:func:`get_system`, a command's ``SYSTEM`` or ``--system``); otherwise the
    call is refused (:class:`~equilibrist.errors.CodeInDataError`) and the file
    is not run. A catalogue key or a model file (MJCF, URDF: data read by
    MuJoCo's compiler) is built as usual. *digest*, when the data records one,
    must be the definition's (:attr:`System.digest`); *source* names the data
    in messages.
    """
    from equilibrist.systems import files

    if not isinstance(key, str) or not key:
        raise UnknownNameError(f"{source} names no system (found {key!r})")
    entry = files.defined(key)
    if entry is None and files.is_python_path(key):
        entry = files.already_run(key, digest)
        if entry is None:
            raise CodeInDataError(
                f"{source} names the Python system file {key}: a data file never runs code; "
                "name the system yourself if you trust that file (--system FILE.py on the "
                "command line, system=get_system(FILE.py) in Python)"
            )
    if entry is not None:
        system = _bind(entry, dict(params or {}))
    elif files.looks_like_path(key):
        system = get_system(key, **dict(params or {}))
    else:
        name, variant = key, None
        if "[" in key and key.endswith("]"):
            name, _, rest = key.partition("[")
            variant = rest[:-1].partition("=")[2]
        settings: dict[str, object] = dict(params or {})
        option = registry.variant_option(name)
        if option is not None and variant is not None:
            settings[option] = variant
        system = get_system(name, **settings)
    _check_same(system, key, digest, source, named=False)
    return system


def system_for_data(key: str, params: Mapping[str, float] | None = None, *,
                    digest: str | None = None, system: System | None = None,
                    source: str = "the data") -> System:
    """The system of a saved result: *system* if the user named one, else :func:`system_from_key`.

    A system the user names must be the one the data came from: the same
    definition by content (*digest*, recorded by the data) or, for data that
    records none, the same key; a mismatch is refused in one line.
    """
    from equilibrist.numeric.system import System

    if system is None:
        return system_from_key(key, params, digest=digest, source=source)
    if not isinstance(system, System):
        raise UnknownNameError(f"system: expected a System (equilibrist.get_system(name)), "
                               f"got {type(system).__name__}")
    _check_same(system, key, digest, source, named=True)
    return _bind(system.compiled.entry, dict(params or {}))


def rebuild_system(key: str, params: Mapping[str, float], digest: str | None) -> System:
    """The system of *key* in a worker process of this run (a batch, a tour, a study).

    *key* comes from a :class:`System` the user named in the process that
    started the work, never from a file, so a Python file is run here as it
    was there; *digest* makes sure it is still the same file.
    """
    from equilibrist.systems import files

    entry = files.defined(key)
    system = _bind(entry, dict(params)) if entry is not None else (
        get_system(key, **dict(params)) if files.looks_like_path(key) else system_from_key(key, params))
    _check_same(system, key, digest, f"the system {key}", named=False)
    return system


def portable(system: System) -> tuple[object, ...]:
    """What *system* pickles as (:meth:`System.__reduce__`): its definition's content and its
    parameter values, so another process (a batch's worker, a Dask worker, a later session
    reading a pickle) rebuilds the same system.

    A catalogue system travels as its key, a model or system file as its path and the digest
    of its bytes (checked there), a system defined in a script or a notebook
    (:meth:`System.from_definition`) as its spec, its derivation's code by value (cloudpickle:
    the function and the helpers of its module it calls) and the content its cache key and
    digest come from.
    """
    from equilibrist.systems import files

    entry = system.compiled.entry
    params = dict(system.params)
    if entry.content is not None and entry.origin is None and files.defined(entry.spec.key) is entry:
        import cloudpickle

        return ("definition", entry.spec, cloudpickle.dumps(entry.derive), entry.content, params)
    return ("key", system.key, system.digest, params)


def unpickle_system(kind: str, *args: object) -> System:
    """The system :func:`portable` describes, rebuilt in this process."""
    import pickle

    from equilibrist.systems import files

    if kind == "definition":
        spec, blob, content, params = args
        assert isinstance(spec, SystemSpec) and isinstance(blob, bytes)
        assert isinstance(content, bytes) and isinstance(params, dict)
        return _bind(files.adopt(spec, pickle.loads(blob), content), params)
    key, digest, params = args
    assert isinstance(key, str) and isinstance(params, dict)
    assert digest is None or isinstance(digest, str)
    return rebuild_system(key, params, digest)


def _check_same(system: System, key: str, digest: str | None, source: str, *, named: bool) -> None:
    """Refuse *system* for data recorded from another definition.

    With a recorded *digest*, the definitions' contents must agree. Data that
    records none (files of earlier versions) is matched by its key: the same
    catalogue entry, or a file of the same name wherever it now lives.
    """
    if digest is not None:
        if system.digest != digest:
            raise DefinitionError(
                f"{system.key} is not the system {source} came from: its content differs "
                f"(sha256 {str(system.digest)[:12]}..., the data recorded {digest[:12]}...)"
            )
        return
    if not named or key in (system.key, system.spec.key):
        return
    if os.path.basename(key) != os.path.basename(system.key):
        raise DefinitionError(f"{system.key} is not the system {source} came from ({key})")
