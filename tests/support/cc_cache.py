"""A C compiler front for tests that compile the same vendored sources over and over.

Used as ``CC="python tests/support/cc_cache.py"``: each translation unit
under a ``daqp/src`` folder (DAQP's sources, copied unchanged into every MPC
export) is compiled once per key into an object file, which later
compilations and links reuse; every other file, and every link, goes to the
real compiler with the same arguments. The key is the flags (but the include
folders' paths), the source and every header it includes (``-MM``), so a
changed source or header compiles anew. GCC compiles each source of one
command line separately, so a link of the cached objects is the same
program as the one command line the exported Makefile runs.

Environment: ``EQUILIBRIST_TEST_CC_CACHE`` (the cache folder),
``EQUILIBRIST_TEST_REAL_CC`` (the compiler, default ``cc``).
"""

from __future__ import annotations

import hashlib
import os
import shlex
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the front itself runs without pytest, once a compile
    import pytest

CACHED = "daqp/src/"
#: Options of a link only (every other option is a compile flag of each source).
LINK_ONLY = ("-shared", "-l", "-Wl,", "-L")


def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The cache of a test run: shared by the xdist workers of the run, gone with its temp."""
    base = tmp_path_factory.getbasetemp()
    return (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "daqp-objects"


def environment(cache: Path) -> dict[str, str]:
    """``os.environ`` with ``CC`` this front, caching in *cache*, for a subprocess (``make``)."""
    return {**os.environ, "CC": f"{shlex.quote(sys.executable)} {shlex.quote(__file__)}",
            "EQUILIBRIST_TEST_REAL_CC": os.environ.get("CC", ""),
            "EQUILIBRIST_TEST_CC_CACHE": str(cache)}


@contextmanager
def cached_cc(cache: Path) -> Iterator[None]:
    """``CC`` this front within the block (for the in-process compiles of the MPC export).

    Not around a command that builds a simulation core: the core's builder remembers the
    compiler it found first (:func:`cached_measure` is for an export command)."""
    names = ("CC", "EQUILIBRIST_TEST_REAL_CC", "EQUILIBRIST_TEST_CC_CACHE")
    saved = {k: os.environ.get(k) for k in names}
    os.environ.update({k: environment(cache)[k] for k in names})
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _cacheable(arg: str) -> bool:
    return arg.endswith(".c") and CACHED in Path(arg).as_posix()


def _split(args: list[str]) -> tuple[list[str], list[str], str | None, bool]:
    """Compile flags (``-I`` with their paths), sources, the output and whether ``-c``."""
    flags, sources, out, compile_only = [], [], None, False
    k = 0
    while k < len(args):
        a = args[k]
        if a == "-o":
            out = args[k + 1]
            k += 2
            continue
        if a == "-c":
            compile_only = True
        elif a.endswith(".c"):
            sources.append(a)
        elif not a.startswith(LINK_ONLY):
            flags.append(a)
        k += 1
    return flags, sources, out, compile_only


def _object(real: list[str], flags: list[str], source: str, cache: Path) -> Path:
    deps = subprocess.run([*real, *flags, "-MM", source], check=True, capture_output=True,
                          text=True).stdout.replace("\\\n", " ").split(":", 1)[1].split()
    digest = hashlib.sha256()
    digest.update(repr([f for f in flags if not f.startswith("-I")]).encode())
    for dep in deps:
        digest.update(Path(dep).name.encode() + b"\0" + Path(dep).read_bytes() + b"\0")
    obj = cache / f"{digest.hexdigest()}.o"
    if not obj.exists():
        cache.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(suffix=".o", dir=cache)
        os.close(fd)
        subprocess.run([*real, *flags, "-c", source, "-o", tmp], check=True)
        os.replace(tmp, obj)  # another worker may have written the same bytes meanwhile
    return obj


def main(args: list[str]) -> int:
    real = shlex.split(os.environ.get("EQUILIBRIST_TEST_REAL_CC", "") or "cc")
    cache = Path(os.environ["EQUILIBRIST_TEST_CC_CACHE"])
    flags, sources, out, compile_only = _split(args)
    if any(a in ("-E", "-S", "-M", "-MM") for a in args) or not any(map(_cacheable, sources)):
        return subprocess.run([*real, *args], check=False).returncode
    try:
        objects = {s: _object(real, flags, s, cache) for s in sources if _cacheable(s)}
    except subprocess.CalledProcessError:
        return subprocess.run([*real, *args], check=False).returncode  # the compiler's own message
    if compile_only:
        if len(sources) != 1 or out is None:
            return subprocess.run([*real, *args], check=False).returncode
        Path(out).write_bytes(objects[sources[0]].read_bytes())
        return 0
    return subprocess.run([*real, *[str(objects[a]) if a in objects else a for a in args]],
                          check=False).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))


@contextmanager
def cached_measure(cache: Path) -> Iterator[None]:
    """An export's measurement at export (``make size`` of its files, in
    :func:`equilibrist.native.size.measure`) through this front within the block, and
    nothing else: the commands' other compiles (the cores) keep the real compiler."""
    from equilibrist.native import size as _size

    original = _size.measure

    def measure(files: object) -> object:
        with cached_cc(cache):
            return original(files)  # type: ignore[arg-type]

    _size.measure = measure  # type: ignore[assignment]
    try:
        yield
    finally:
        _size.measure = original
