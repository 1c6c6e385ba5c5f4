"""Compile a generated C unit into a shared library, cached by content, and load it.

The library's name is the hash of everything that shapes it: the unit's source, the
compiler's identity (its command and ``--version``), the flags and this module's
:data:`REVISION`, so an unchanged one is loaded from the cache folder
(:func:`equilibrist.numeric.cache.cache_dir`, ``native/``) in milliseconds. A build is
atomic and done once (a file of its own renamed into place, under a ``flock`` on
``<library>.lock``), checked (a ``.sha256`` beside each library), and uses ``$CC``, ``cc``
or the ``ziglang`` package's compiler, with OpenMP where the compiler has it: docs/core.md,
"Compiled in about a second, cached by content".
"""

from __future__ import annotations

import ctypes
import hashlib
import importlib
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager, suppress
from functools import lru_cache
from pathlib import Path

from equilibrist.errors import EquilibristError

#: Bumped when the way a library is built changes (flags, layout of the folder).
REVISION = 1
#: Flags of every build: optimized, no fused multiply-add and no reassociation (the bits
#: of the Python definitions), position-independent, entries visible by EQ_EXPORT only.
FLAGS = ("-std=gnu99", "-O2", "-ffp-contract=off", "-fno-math-errno", "-fPIC", "-shared",
         "-fvisibility=hidden", "-Wall", "-Wno-unused-function", "-Wno-unused-variable")
_OPENMP = ("-fopenmp",)


class BuildError(EquilibristError, RuntimeError):
    """The C compiler is missing or refused a generated unit."""


@lru_cache(maxsize=1)
def compiler() -> tuple[str, ...]:
    """The C compiler command: ``$CC``, else ``cc``, else ziglang's ``zig cc``."""
    words = shlex.split(os.environ.get("CC", "") or "cc")
    if words and shutil.which(words[0]) is not None:
        return tuple(words)
    try:
        importlib.import_module("ziglang")  # the package that brings `zig cc`, if it loads
    except ImportError:
        raise BuildError(
            f"no C compiler found ({' '.join(words) or 'cc'}): install gcc (Debian: apt-get "
            "install gcc), set CC, or pip install ziglang"
        ) from None
    return (sys.executable, "-m", "ziglang", "cc")


@lru_cache(maxsize=1)
def compiler_identity() -> str:
    """The compiler's command and the first line of its ``--version``."""
    cmd = compiler()
    try:
        out = subprocess.run([*cmd, "--version"], capture_output=True, text=True, timeout=60,
                             check=False).stdout
    except (OSError, subprocess.SubprocessError) as exc:
        raise BuildError(f"the C compiler {' '.join(cmd)} does not run: {exc}") from None
    first = out.strip().splitlines()[0] if out.strip() else "unknown"
    return " ".join(cmd) + " | " + first


def _folder() -> Path:
    from equilibrist.numeric.cache import cache_dir

    path = cache_dir() / "native"
    path.mkdir(parents=True, exist_ok=True)
    return path


def library_key(source: str) -> str:
    """The hash that names the library built from *source* (or from the text that
    determines it)."""
    h = hashlib.sha256()
    for part in (source, compiler_identity(), " ".join(FLAGS), str(REVISION)):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()[:20]


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _compile(source: str, out: Path, extra: Sequence[str] = (), openmp: bool = True) -> None:
    folder = out.parent
    fd, tmp_c = tempfile.mkstemp(prefix=out.stem + ".", suffix=".c", dir=folder)
    tmp_so = Path(tmp_c).with_suffix(".so")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(source)
        errors = ""
        for omp in ((_OPENMP, ()) if openmp else ((),)):
            cmd = [*compiler(), *FLAGS, *omp, tmp_c, *extra, "-o", str(tmp_so), "-lm"]
            proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
            if proc.returncode == 0 and omp and not _loads(tmp_so):
                # Compiled with OpenMP but its runtime is not there to load (zig cc, a
                # clang without libomp): built again without.
                errors = f"{' '.join(cmd)} built a library that does not load"
                continue
            if proc.returncode == 0:
                break
            errors = (proc.stderr or proc.stdout).strip()
            if omp and "openmp" not in errors.lower() and "omp" not in errors.lower():
                break  # an error of the unit, not of OpenMP: no second try
        else:
            proc = None
        if proc is None or proc.returncode != 0:
            lines = errors.splitlines()
            raise BuildError("the generated core does not compile: "
                             + " | ".join(lines[:8]) + f" (unit kept at {tmp_c})")
        digest = _digest(tmp_so)
        sidecar = out.with_suffix(out.suffix + ".sha256")
        tmp_sum = Path(str(tmp_so) + ".sha256")
        tmp_sum.write_text(digest + "\n")
        os.replace(tmp_so, out)
        os.replace(tmp_sum, sidecar)
        keep = out.with_suffix(".c")
        os.replace(tmp_c, keep)  # the unit beside its library, to read
    except BaseException:
        for leftover in (tmp_so, Path(str(tmp_so) + ".sha256")):
            leftover.unlink(missing_ok=True)
        raise


def objects(sources: Sequence[tuple[Path, str]], stem: str, include: Path) -> list[Path]:
    """Object files of a vendored library, compiled once per cache folder (and compiler).

    *sources*: each C file with its optimization flag (``-O2`` where the code runs, ``-O0``
    for what it never enters: the bits of IEEE arithmetic without contraction do not depend
    on it), *include* its headers' folder. The folder ``<stem>_<key>`` of the cache is named
    by the hash of every source and header, the flags and the compiler, built in a folder of
    its own and renamed into place under the build lock, and its files' digests are checked
    on each use (a damaged one is built again). Returns the objects' paths."""
    h = hashlib.sha256()
    headers = sorted(include.glob("*.h"))
    for part in (*(f"{p.name} {opt}\n{p.read_text()}" for p, opt in sources),
                 *(f"{p.name}\n{p.read_text()}" for p in headers),
                 compiler_identity(), " ".join(FLAGS), str(REVISION)):
        h.update(part.encode())
        h.update(b"\0")
    final = _folder() / f"{stem}_{h.hexdigest()[:20]}"
    names = [f"{i:02d}_{p.stem}.o" for i, (p, _) in enumerate(sources)]

    def whole() -> bool:
        sums = final / "objects.sha256"
        if not sums.exists():
            return False
        try:
            want = dict(line.split() for line in sums.read_text().splitlines())
            return all(want.get(n) == _digest(final / n) for n in names)
        except (OSError, ValueError):
            return False

    if not whole():
        with _exclusive(final.with_suffix(".dir")):
            if not whole():
                tmp = Path(tempfile.mkdtemp(prefix=final.name + ".", dir=final.parent))
                try:
                    common = [f for f in FLAGS if f not in ("-O2", "-shared")]

                    def one(item: tuple[tuple[Path, str], str]) -> subprocess.CompletedProcess[str]:
                        (src, opt), name = item
                        return subprocess.run([*compiler(), *common, opt,
                                               f"-I{include}", "-c",
                                               str(src), "-o", str(tmp / name)],
                                              capture_output=True, text=True, check=False)

                    with ThreadPoolExecutor(max_workers=max(1, os.cpu_count() or 1)) as pool:
                        done = list(pool.map(one, zip(sources, names, strict=True)))
                    for proc in done:
                        if proc.returncode != 0:
                            lines = (proc.stderr or proc.stdout).strip().splitlines()
                            raise BuildError(f"{stem} does not compile: " + " | ".join(lines[:8]))
                    (tmp / "objects.sha256").write_text(
                        "".join(f"{n} {_digest(tmp / n)}\n" for n in names))
                    if final.exists():
                        shutil.rmtree(final)  # damaged: replaced whole
                    os.replace(tmp, final)
                except BaseException:
                    shutil.rmtree(tmp, ignore_errors=True)
                    raise
    return [final / n for n in names]


def _loads(path: Path) -> bool:
    """Whether the shared library at *path* loads (its symbols resolve)."""
    try:
        ctypes.CDLL(str(path))
    except OSError:
        return False
    return True


_LOADED: dict[Path, ctypes.CDLL] = {}


def _whole(path: Path, sidecar: Path) -> bool:
    """Whether the library at *path* is there and matches the digest beside it."""
    if not (path.exists() and sidecar.exists()):
        return False
    try:
        return sidecar.read_text().strip() == _digest(path)
    except OSError:
        return False


@contextmanager
def _exclusive(path: Path) -> Iterator[None]:
    """Hold the build lock of the library *path* (none where ``fcntl`` is missing)."""
    try:
        import fcntl
    except ImportError:  # not a POSIX system: the atomic rename alone keeps the library whole
        yield
        return
    with open(path.with_suffix(".lock"), "a") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)


def load(source: str | Callable[[], str], stem: str,
         inputs: str | None = None, *, link: Sequence[Path] = (),
         flags: Sequence[str] = (), openmp: bool = True) -> tuple[ctypes.CDLL, Path]:
    """The library built from *source* (built now if the cache has no whole one).

    *source* may be a function that writes the unit, called only when the library must be
    built; then *inputs* is a text that determines the unit entirely (the hashes of what
    the generator reads), and names the library in its place. *link*: object files
    (:func:`objects`) linked in, *flags*: the unit's own (after :data:`FLAGS`), *openmp*:
    whether to try OpenMP; all three name the library too.
    """
    if inputs is None:
        assert isinstance(source, str)
        inputs = source
    extra = [*flags, *map(str, link)]
    named = inputs if not extra and openmp else chr(0).join([inputs, *extra, str(openmp)])
    path = _folder() / f"{stem}_{library_key(named)}.so"
    lib = _LOADED.get(path)
    if lib is not None:
        return lib, path
    sidecar = path.with_suffix(path.suffix + ".sha256")
    whole = _whole(path, sidecar)

    def text() -> str:
        return source if isinstance(source, str) else source()

    if not whole:
        with _exclusive(path):
            whole = _whole(path, sidecar)  # built by another process while this one waited
            if not whole:
                _compile(text(), path, extra, openmp)
    try:
        lib = ctypes.CDLL(str(path))
    except OSError:
        if not whole:
            raise BuildError(f"the compiled core {path} does not load") from None
        with _exclusive(path):
            _compile(text(), path, extra, openmp)  # matched its digest yet does not load: again
        lib = ctypes.CDLL(str(path))
    _LOADED[path] = lib
    return lib, path


def private(path: Path) -> ctypes.CDLL:
    """A copy of the library *path* loaded on its own: its static data is this copy's alone
    (the loader shares one copy of a path among all its users). The copy's file is removed
    once loaded (where the system allows it)."""
    fd, tmp = tempfile.mkstemp(prefix=path.stem + ".", suffix=".so", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(path.read_bytes())
        return ctypes.CDLL(tmp)
    finally:
        with suppress(OSError):  # a system that keeps a loaded library's file: left there
            os.unlink(tmp)


__all__ = ["FLAGS", "REVISION", "BuildError", "compiler", "compiler_identity", "library_key",
           "load", "objects", "private"]
