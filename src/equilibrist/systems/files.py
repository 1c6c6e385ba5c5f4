"""Systems from values: a user's Python file, an MJCF or URDF model, a script's function.

A system is a value built from a definition (a spec and a derivation), not an
entry in a process-wide list. The catalogue's modules are definitions that
ship with the package; this module builds the same kind of value from

* a Python file that declares a system exactly as a catalogue module does
  (a :class:`~equilibrist.mechanics.spec.SystemSpec` and a derivation
  decorated with :func:`~equilibrist.systems.registry.register`);
* a model file, MJCF (``.xml``) or URDF (``.urdf``), read through MuJoCo's own
  compiler (:mod:`equilibrist.importers`, the ``models`` extra);
* a spec and a derivation function handed over in a script or a notebook
  (:func:`from_definition`).

The derived-model cache is keyed by the definition's content (the file's
bytes, the function's source), never by where a module lives. A system read
from a file is named by the file's absolute path (:attr:`Entry.key`), so a
saved result or design rebuilds it; a system defined in a script is known by
its spec's name within the process that defined it.
"""

from __future__ import annotations

import hashlib
import importlib.util
import inspect
import marshal
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from equilibrist.errors import DefinitionError, UnknownNameError
from equilibrist.mechanics.definition import DeriveFunction, Entry
from equilibrist.mechanics.spec import SystemSpec
from equilibrist.systems.registry import SPEC_ATTRIBUTE, family_names

if TYPE_CHECKING:
    from equilibrist.mechanics.model import Derivation, SymbolicModel

PYTHON_SUFFIX = ".py"
MODEL_SUFFIXES = (".xml", ".urdf")

# Definitions handed over in this process (by spec key), and files read (by
# content hash): building the same definition twice gives the same entry.
_DEFINED: dict[str, Entry] = {}
_FROM_FILES: dict[tuple[str, str], Entry] = {}


def looks_like_path(name: str) -> bool:
    """Whether a command line's SYSTEM names a file rather than a catalogue entry."""
    return name.lower().endswith((PYTHON_SUFFIX, *MODEL_SUFFIXES)) or "/" in name or os.sep in name


def from_file(path: str | os.PathLike[str]) -> Entry:
    """The definition in the file *path* (``.py``, MJCF ``.xml`` or ``.urdf``)."""
    given = os.fspath(path)
    file = Path(given).expanduser()
    suffix = file.suffix.lower()
    if suffix not in (PYTHON_SUFFIX, *MODEL_SUFFIXES):
        raise UnknownNameError(
            f"system file {given!r}: expected a .py file, an MJCF model (.xml) or a URDF (.urdf)"
        )
    try:
        if file.exists() and not file.is_dir() and not file.is_file():
            # A FIFO, a device or a socket: reading it could block for ever.
            raise UnknownNameError(f"system file {given!r} is not a regular file (a pipe or a "
                                   "device): expected a file")
        data = file.read_bytes()
    except FileNotFoundError:
        raise UnknownNameError(f"system file {given!r} does not exist") from None
    except IsADirectoryError:
        raise UnknownNameError(f"system file {given!r} is a folder, expected a file") from None
    except OSError as exc:
        raise UnknownNameError(f"system file {given!r} cannot be read: {exc.strerror}") from None
    resolved = str(file.resolve())
    digest = hashlib.sha256(data).hexdigest()
    memo = (resolved, digest)
    if memo in _FROM_FILES:
        return _FROM_FILES[memo]
    if suffix == PYTHON_SUFFIX:
        entry = _from_python(data, resolved, digest)
    else:
        from equilibrist.importers import load_model_file

        entry = load_model_file(file, origin=resolved, content=data)
    _FROM_FILES[memo] = entry
    return entry


def _from_python(data: bytes, origin: str, digest: str) -> Entry:
    """Run a user's system file and take the one system it declares.

    The user's code (the module, and later its derivation) runs with its
    ``print`` output sent to stderr: stdout is the command's own (``--json``).
    Whatever it raises, ``sys.exit`` included, becomes one
    :class:`DefinitionError` naming the file and the line; a Ctrl-C still
    interrupts.
    """
    import contextlib
    import functools

    from equilibrist.errors import EquilibristError

    def said(exc: BaseException, when: str) -> str:  # what the user's code raised, in words
        if isinstance(exc, SystemExit):
            return (f"the file called sys.exit({exc.code!r}) {when}: a system file declares SPEC "
                    "and its derivation, it does not exit")
        if isinstance(exc, EquilibristError):  # a refusal of ours (a spec's): it says what is wrong
            return str(exc)
        return f"{type(exc).__name__}: {exc} ({when})"

    module_name = f"equilibrist_user_{digest[:16]}"
    module = sys.modules.get(module_name)
    if module is None:
        loader_spec = importlib.util.spec_from_file_location(module_name, origin)
        if loader_spec is None or loader_spec.loader is None:
            raise DefinitionError(f"{origin}: cannot be loaded as a Python module")
        module = importlib.util.module_from_spec(loader_spec)
        sys.modules[module_name] = module
        try:
            with contextlib.redirect_stdout(sys.stderr):
                loader_spec.loader.exec_module(module)
        except (Exception, SystemExit) as exc:  # the user's own code: one line that says where
            del sys.modules[module_name]
            raise DefinitionError(f"{origin}: {_where(exc, origin)}{said(exc, 'while it was loaded')}") from None
    found = [
        obj for obj in vars(module).values()
        if callable(obj) and isinstance(getattr(obj, SPEC_ATTRIBUTE, None), SystemSpec)
        and getattr(obj, "__module__", None) == module_name
    ]
    if len(found) != 1:
        what = "no derivation decorated with @register(SPEC)" if not found else (
            f"{len(found)} systems ({', '.join(getattr(f, SPEC_ATTRIBUTE).name for f in found)})"
        )
        raise DefinitionError(f"{origin}: expected one system, found {what}")
    user_derive = found[0]
    spec: SystemSpec = getattr(user_derive, SPEC_ATTRIBUTE)
    name = getattr(user_derive, "__name__", "derive")

    @functools.wraps(user_derive)
    def derive(d: Derivation) -> SymbolicModel:
        from equilibrist.mechanics.model import SymbolicModel

        try:
            with contextlib.redirect_stdout(sys.stderr):
                model = user_derive(d)
        except EquilibristError as exc:  # the mechanics layer's own refusal, said as it is
            raise DefinitionError(f"{origin}: {_where(exc, origin)}{exc}") from None
        except (Exception, SystemExit) as exc:
            raise DefinitionError(
                f"{origin}: {_where(exc, origin)}{said(exc, f'in {name}(d)')}, expected {name}(d) "
                "to return the model of d.kane(...), d.lagrange(...) or d.first_order(...)"
            ) from None
        if not isinstance(model, SymbolicModel):
            raise DefinitionError(
                f"{origin}: {name}(d) returned {type(model).__name__}: expected the model that "
                "d.kane(...), d.lagrange(...) or d.first_order(...) returns"
            )
        return model

    return Entry(spec, derive, module_name, content=data, origin=origin)


def _where(exc: BaseException, origin: str) -> str:
    line = exc.lineno if isinstance(exc, SyntaxError) and exc.filename == origin else None
    tb = exc.__traceback__
    while tb is not None:
        if tb.tb_frame.f_code.co_filename == origin:
            line = tb.tb_lineno
        tb = tb.tb_next
    return f"line {line}: " if line is not None else ""


def _function_content(derive: DeriveFunction) -> bytes:
    """What shapes the derivation *derive*: its source, and those of the functions and classes
    of its own module it uses (by name, at any depth), and the values of that module's
    constants it reads; a helper's change is a new definition."""
    seen: set[int] = set()
    parts: list[bytes] = []

    def add(obj: object) -> None:
        if id(obj) in seen:
            return
        seen.add(id(obj))
        try:
            parts.append(inspect.getsource(obj).encode())  # type: ignore[arg-type]
        except (OSError, TypeError):  # defined where no source is kept (an exec'd string)
            code = getattr(obj, "__code__", None)
            if code is None:
                raise DefinitionError(
                    f"the derivation {obj!r} must be a Python function (got {type(obj).__name__})"
                ) from None
            parts.append(marshal.dumps(code))
        module = getattr(obj, "__module__", None)
        scope = getattr(obj, "__globals__", None)
        code = getattr(obj, "__code__", None)
        if scope is None or code is None:
            return
        for name in sorted(_names_used(code)):
            value = scope.get(name)
            if inspect.isfunction(value) or inspect.isclass(value):
                if getattr(value, "__module__", None) == module:
                    add(value)
            elif isinstance(value, int | float | str | bytes | tuple | frozenset) and \
                    not isinstance(value, bool):
                parts.append(f"{name} = {value!r}".encode())

    add(derive)
    return b"\n\0".join(parts)


def _names_used(code: object) -> set[str]:
    """The global names a code object and the code nested in it read."""
    names = set(getattr(code, "co_names", ()))
    for const in getattr(code, "co_consts", ()):
        if inspect.iscode(const):
            names |= _names_used(const)
    return names


def from_definition(spec: SystemSpec, derive: DeriveFunction) -> Entry:
    """The definition of a system handed over as values (a script, a notebook)."""
    if not isinstance(spec, SystemSpec):
        raise DefinitionError(f"spec must be a SystemSpec, got {type(spec).__name__}")
    if not callable(derive):
        raise DefinitionError(f"derive must be a function of the Derivation, got {type(derive).__name__}")
    if spec.name in family_names():
        raise DefinitionError(
            f"the name {spec.name!r} belongs to the catalogue: give your system another name"
        )
    return adopt(spec, derive, _function_content(derive) + repr(spec).encode())


def adopt(spec: SystemSpec, derive: DeriveFunction, content: bytes) -> Entry:
    """The definition of *spec* and *derive* known by *content* in this process: the one
    :func:`from_definition` makes, or one another process handed over by value (a pickled
    :class:`System`), with the content it was known by there (so the same derived model, and
    the same digest, wherever its source can or cannot be read)."""
    previous = _DEFINED.get(spec.key)
    if previous is not None and previous.content == content:
        return previous
    entry = Entry(spec, derive, getattr(derive, "__module__", "__main__") or "__main__",
                  content=content)
    _DEFINED[spec.key] = entry
    return entry


def defined(key: str) -> Entry | None:
    """The definition handed over in this process under *key*, if any."""
    return _DEFINED.get(key)


def is_python_path(name: str) -> bool:
    """Whether *name* would be loaded as a Python system file (and so run)."""
    return looks_like_path(name) and Path(name).suffix.lower() not in MODEL_SUFFIXES


def already_run(path: str, digest: str | None) -> Entry | None:
    """The Python file *path* as this process already ran it, by the user's own naming.

    With *digest*, only the content with that SHA-256; without, the latest
    content read from that path. ``None`` when this process has not run it:
    a reader of data never runs it then (:func:`~equilibrist.numeric.lookup.system_from_key`).
    """
    resolved = str(Path(path).expanduser().resolve())
    found = [entry for (origin, d), entry in _FROM_FILES.items()
             if origin == resolved and (digest is None or d == digest)]
    return found[-1] if found else None


def digest_of(entry: Entry) -> str | None:
    """SHA-256 of what defines *entry*: a file's bytes, a script's definition; ``None`` for the catalogue.

    Saved results record it, so that a reader can check that the system it is
    handed is the one the data came from, wherever its file now lives.
    """
    for (_, digest), known in _FROM_FILES.items():
        if known is entry:
            return digest
    return None if entry.content is None else hashlib.sha256(entry.content).hexdigest()
