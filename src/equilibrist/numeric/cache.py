"""The on-disk cache of derived models.

Deriving equations with sympy takes seconds; loading them must not. For each
definition the cache holds the pickled :class:`SymbolicModel` (with its
symbolic Jacobians) and the generated numeric module. Both are keyed by a
hash of everything that shapes them: the definition's content (a catalogue
module's source, a user's file, a script's function), the whole
mechanics layer, the systems' private helper modules (``systems/_*.py``),
the code-generation source, and the sympy version. Changing the
model's source changes the key, so a stale model is never loaded.

The folder is ``$EQUILIBRIST_CACHE`` or ``~/.cache/equilibrist``. Writes are
atomic (write, then rename), so parallel processes may share it.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import importlib.util
import os
import pickle
import re
import stat
import sys
import tempfile
import types
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING

from equilibrist.errors import EquilibristError
from equilibrist.mechanics.definition import Entry

if TYPE_CHECKING:  # sympy is imported only when a model is derived or unpickled
    from equilibrist.mechanics.model import SymbolicModel

SCHEMA = "3"


class CacheError(EquilibristError, OSError):
    """The cache folder cannot be used (it names the setting that chose it)."""


def cache_dir() -> Path:
    """The cache folder, created if missing; refused if it is unusable or not private.

    The folder holds code that is imported and models that are unpickled, so
    a folder that other users can write to is refused: one of them could
    plant a file that runs as you.
    """
    root = os.environ.get("EQUILIBRIST_CACHE")
    base = Path(root) if root else Path.home() / ".cache" / "equilibrist"
    where = f"the cache folder EQUILIBRIST_CACHE={root}" if root else f"the cache folder {base}"
    hint = "set EQUILIBRIST_CACHE to a folder of your own" if not root else "point it at a folder of your own"
    try:
        base.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise CacheError(f"{where} is not a folder: {hint}") from None
    except OSError as exc:
        raise CacheError(f"{where} cannot be created ({exc.strerror}): {hint}") from None
    if not base.is_dir():
        raise CacheError(f"{where} is not a folder: {hint}")
    info = base.stat()
    if info.st_mode & 0o022:
        raise CacheError(
            f"{where} can be written by other users (mode {stat.S_IMODE(info.st_mode):o}): its files "
            f"are imported and unpickled, so it must be yours alone (chmod go-w), or {hint}"
        )
    if info.st_uid != os.getuid():
        raise CacheError(f"{where} belongs to another user: {hint}")
    if not os.access(base, os.W_OK | os.X_OK):
        raise CacheError(f"{where} is not writable: {hint}")
    return base


def _source_of(module_name: str) -> bytes:
    # find_spec locates the file without importing (and so without sympy).
    spec = importlib.util.find_spec(module_name)
    if spec is None or spec.origin is None:
        raise RuntimeError(f"cannot find the source of {module_name}")
    return Path(spec.origin).read_bytes()


def model_key(entry: Entry, *, with_sympy: bool = True) -> str:
    """Hash of everything the derived model depends on (without *with_sympy*: all but the
    installed sympy's version, the key of a derivation shipped with the package)."""
    h = hashlib.sha256()
    # The definition's own content: a user's file or function as handed
    # over, a catalogue module's source.
    h.update(entry.content if entry.content is not None else _source_of(entry.module))
    h.update(_source_of("equilibrist.numeric.codegen"))
    h.update(_source_of("equilibrist.numeric.libm"))  # copied into every generated module
    # Everything a derivation may lean on: the mechanics layer and the
    # systems' private helper modules (a leading underscore).
    for folder in ("mechanics", "systems"):
        base = Path(__file__).resolve().parent.parent / folder
        for path in sorted(base.glob("*.py")):
            if folder == "mechanics" or path.name.startswith("_"):
                h.update(path.name.encode())
                h.update(path.read_bytes())
    h.update(entry.spec.key.encode())
    if with_sympy:
        h.update(importlib.metadata.version("sympy").encode())
    h.update(SCHEMA.encode())
    return h.hexdigest()[:16]


#: Where the catalogue's derived models ship with the package (written by
#: ``python -m equilibrist.numeric.package``, checked by a test to be what deriving them
#: again gives): a first use of a catalogue system copies its module from here instead of
#: importing sympy and deriving it. A user's system or an imported model is derived.
PACKAGED = Path(__file__).resolve().parent / "derived"


def packaged_path(entry: Entry) -> Path | None:
    """The shipped derivation of a catalogue *entry* (None for a user's system)."""
    if entry.content is not None:
        return None
    return PACKAGED / f"{_stem(entry, model_key(entry, with_sympy=False))}.py.txt"


def _atomic_write(path: Path, data: bytes) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name + ".")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _stem(entry: Entry, key: str) -> str:
    safe = re.sub(r"[^A-Za-z0-9_]+", "_", entry.spec.key).strip("_")[:40] or "system"
    return f"{safe}_{key}"


@dataclass(frozen=True, eq=False)
class CompiledModel:
    """A derived model: the generated numeric module, the symbolic model on demand."""

    entry: Entry
    key: str
    module_path: Path
    pickle_path: Path

    @cached_property
    def functions(self) -> types.ModuleType:
        """The generated module (``f``, ``jac``, ``mass_matrix``, ``energy``, ``conserved``, ``points``)."""
        name = f"equilibrist_generated_{self.module_path.stem}"
        if name in sys.modules:
            return sys.modules[name]
        try:
            module = _import(name, self.module_path)
            _check_module(module, self.entry)
            return module
        except Exception:  # any damage (truncated, emptied, edited) is rebuilt
            sys.modules.pop(name, None)
            _write_module(self.entry, self.module_path, self.pickle_path)
            module = _import(name, self.module_path)
            _check_module(module, self.entry)
            return module

    @cached_property
    def symbolic(self) -> SymbolicModel:
        """The symbolic model (unpickled the first time it is asked for)."""
        from equilibrist.mechanics.model import SymbolicModel

        try:
            with self.pickle_path.open("rb") as fh:
                model = pickle.load(fh)  # our own cache file, in a folder only we can write
        except Exception:  # any damage is rebuilt
            model = None
        if not isinstance(model, SymbolicModel) or model.spec_key != self.entry.spec.key:
            # Derived now; the generated module already in use (perhaps the shipped one)
            # stays as it is.
            model = _build(self.entry, self.module_path, self.pickle_path, module=False)
        return model


# What every generated module defines (see numeric/codegen.py).
_GENERATED = ("N_STATES", "N_INPUTS", "N_Q", "CONSERVED", "f", "jac", "mass_matrix", "energy",
              "conserved")


def _check_module(module: types.ModuleType, entry: Entry) -> None:
    """Raise if *module* is not a complete generated model of *entry*."""
    missing = [n for n in _GENERATED if not hasattr(module, n)]
    if missing:
        raise ImportError(f"generated model lacks {', '.join(missing)}")
    if (len(entry.spec.state_names), len(entry.spec.inputs)) != (module.N_STATES, module.N_INPUTS):
        raise ImportError("generated model has the wrong size")


def _import(name: str, path: Path) -> types.ModuleType:
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise ImportError(f"cannot load {path}")
    module = importlib.util.module_from_spec(spec)
    # In sys.modules while it runs (a module that imports itself by name finds itself).
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


def _build(entry: Entry, module_path: Path, pickle_path: Path, *,
           module: bool = True) -> SymbolicModel:
    """Derive *entry* and write its cache files (the pickle only, without *module*);
    returns the symbolic model."""
    model = derive(entry)
    if model.jacobian_form == "symbolic":
        _ = model.A, model.B  # computed once, stored with the model (the code uses them)
    _atomic_write(pickle_path, pickle.dumps(model, protocol=pickle.HIGHEST_PROTOCOL))
    if module:
        from equilibrist.numeric.codegen import generate_source

        _atomic_write(module_path, generate_source(model).encode())
    return model


def _write_module(entry: Entry, module_path: Path, pickle_path: Path) -> None:
    """The generated module of *entry* into the cache: the shipped derivation of a catalogue
    system (the symbolic model is derived when first asked for), else derived now."""
    shipped = packaged_path(entry)
    if shipped is not None and shipped.is_file():
        _atomic_write(module_path, shipped.read_bytes())
    else:
        _build(entry, module_path, pickle_path)


_MEMO: dict[str, CompiledModel] = {}


def derive(entry: Entry) -> SymbolicModel:
    """Run the derivation of *entry* (slow; bypasses the cache)."""
    from equilibrist.mechanics.model import Derivation

    return entry.derive(Derivation(entry.spec))


def load(entry: Entry) -> CompiledModel:
    """The compiled model of *entry*, derived and cached on first use."""
    key = model_key(entry)
    memo_key = f"{entry.key}:{key}"
    if memo_key in _MEMO:
        return _MEMO[memo_key]
    folder = cache_dir()
    stem = _stem(entry, key)
    module_path = folder / f"{stem}.py"
    pickle_path = folder / f"{stem}.pkl"
    if not module_path.exists():
        _write_module(entry, module_path, pickle_path)
    compiled = CompiledModel(entry, key, module_path, pickle_path)
    _MEMO[memo_key] = compiled
    return compiled
