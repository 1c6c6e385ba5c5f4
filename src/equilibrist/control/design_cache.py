"""Designs kept on disk: a run that needs a design made before neither redoes it nor imports
scipy (the key hashes the system, the arguments and the sources the numbers come from); used by
:mod:`equilibrist.control.design`.
"""

from __future__ import annotations

import types
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

from equilibrist.control.design_record import Design

if TYPE_CHECKING:
    from pathlib import Path

    from equilibrist.numeric.system import System


# -- designs kept on disk: a run that needs one made before neither redoes it nor imports scipy
#: The sources a design's numbers come from (a change to any makes new keys).
_DESIGN_SOURCES = ("design", "design_record", "weights", "design_cache", "analysis",
                   "discretize", "kalman", "lqg", "reference", "riccati", "checks")
_SOURCES_DIGEST: list[str] = []


def _sources_digest() -> str:
    if not _SOURCES_DIGEST:
        import hashlib
        import importlib.metadata
        from pathlib import Path

        h = hashlib.sha256()
        here = Path(__file__).parent
        for name in _DESIGN_SOURCES:
            h.update((here / f"{name}.py").read_bytes())
        h.update((here.parent / "numeric" / "linear.py").read_bytes())
        for dist in ("numpy", "scipy"):
            h.update(importlib.metadata.version(dist).encode())
        _SOURCES_DIGEST.append(h.hexdigest())
    return _SOURCES_DIGEST[0]


def _cache_key(system: System, args: tuple[object, ...]) -> str | None:
    """The file name of a design of *system* with *args* (None when they do not pickle:
    an argument the design will refuse anyway)."""
    import hashlib
    import os
    import pickle

    from equilibrist.numeric.system import System as _System

    if not isinstance(system, _System):
        return None
    try:
        norm = tuple(sorted(a.items()) if isinstance(a, Mapping) else a for a in args)
        blob = pickle.dumps((system.key, system.compiled.module_path.name, system.digest,
                             system.spec, tuple(sorted(system.params.items())), norm),
                            protocol=4)
    except Exception:  # an argument that does not pickle: no cache for it
        return None
    h = hashlib.sha256(blob)
    h.update(_sources_digest().encode())
    # The BLAS kernel OpenBLAS is told to use changes the design's last bits.
    h.update(os.environ.get("OPENBLAS_CORETYPE", "").encode())
    return h.hexdigest()[:24]


def _design_folder() -> Path:
    from equilibrist.numeric.cache import cache_dir

    folder = cache_dir() / "designs"
    folder.mkdir(exist_ok=True)
    return folder


def _kept_on_disk(make: Callable[..., Design]) -> Callable[..., Design]:
    """*make* (``design``), its results kept on disk under the hash of its arguments."""
    import functools
    import inspect

    signature = inspect.signature(make)

    @functools.wraps(make)
    def design(system: System, **options: object) -> Design:
        try:
            bound = signature.bind(system, **options)
        except TypeError:
            return make(system, **options)  # as Python would refuse it
        bound.apply_defaults()
        args = tuple(v for k, v in bound.arguments.items() if k != "system")
        key = _cache_key(system, args)
        if key is not None:
            known = _cached(key, system)
            if known is not None:
                return known
        made = make(system, **options)
        if key is not None:
            _keep(key, made)
        return made

    return design


def read_only(values: dict[str, float]) -> types.MappingProxyType[str, float]:
    """A read-only view of *values* (how a pickled design's parameters come back)."""
    return types.MappingProxyType(values)


def _register_pickling() -> None:
    import copyreg

    copyreg.pickle(types.MappingProxyType, lambda m: (read_only, (dict(m),)))


# A design's parameters are a read-only mapping: pickled as a dict whichever way the design
# came (made here or read from the cache folder), so a controller holding one goes to a
# batch's worker processes.
_register_pickling()


def _cached(key: str, system: System) -> Design | None:
    import pickle

    path = _design_folder() / f"{key}.pkl"
    try:
        with path.open("rb") as fh:
            known = pickle.load(fh)  # our own cache folder, only we can write it
    except Exception:  # missing or damaged: designed again
        return None
    if not isinstance(known, Design) or known.system_key != system.key:
        return None
    return known


def _keep(key: str, made: Design) -> None:
    import os
    import pickle
    import tempfile

    _register_pickling()
    folder = _design_folder()
    try:
        blob = pickle.dumps(made, protocol=pickle.HIGHEST_PROTOCOL)
    except Exception:  # something in it does not pickle: simply not kept
        return
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=f"{key}.")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(blob)
        os.replace(tmp, folder / f"{key}.pkl")
    except BaseException:
        os.unlink(tmp)
        raise
