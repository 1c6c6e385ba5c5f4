"""DAQP's vendored C sources, and the shared library the install builds from them.

DAQP is a fixed library, not a generated unit: ``pip install`` (``setup.py``)
compiles it once as ``equilibrist/native/_daqp*.so``, as any package with C
sources does, and the MPC's driver links it, so a first MPC compiles only
its own driver. The library carries the digest of the sources it was built
from (``eq_daqp_digest``): a library from other sources, or none (an install
on a machine without a compiler, where the build is optional), leaves the MPC
to compile DAQP's objects into the cache instead
(:func:`equilibrist.native.mpc_library.daqp_objects`).

This module imports nothing but the standard library: ``setup.py`` reads it
by its path, before any dependency is installed.
"""

from __future__ import annotations

import hashlib
import struct
from pathlib import Path

#: DAQP's sources (``src/*.c``), headers (``include/*.h``) and licence.
DAQP_SOURCES = Path(__file__).resolve().parent / "daqp"
#: The module name of the library the install builds (a shared library, not a Python module).
MODULE = "equilibrist.native._daqp"
#: The file that holds the digest, compiled into the library beside DAQP's sources.
DIGEST_SOURCE = Path(__file__).resolve().parent / "daqp_digest.c"
#: The install's flags: as the cache's builds (``native.build.FLAGS``), no contraction and no
#: reassociation, so the bits are the exported C's.
INSTALL_FLAGS = ("-std=gnu99", "-O2", "-ffp-contract=off", "-fno-math-errno", "-g0")
#: DAQP's bound for "no bound".
INF = 1e30
#: DAQP's iteration cap (a bounded solve time). A cold start of the cart-pole's QP at
#: N = 30 takes at most about 75 iterations; a warm one a few (bench/README.md).
ITER_LIMIT = 1000
#: DAQP's primal feasibility tolerance (the constraints of its exact active set hold to it).
EPS = 1e-6


def c_sources() -> list[Path]:
    """DAQP's C files, in a fixed order."""
    return sorted((DAQP_SOURCES / "src").glob("*.c"))


def digest() -> str:
    """The hash of DAQP's sources and headers and of the install's flags."""
    h = hashlib.sha256()
    for p in (*c_sources(), *sorted((DAQP_SOURCES / "include").glob("*.h"))):
        h.update(f"{p.name}\n".encode())
        h.update(p.read_bytes())
        h.update(b"\0")
    h.update(" ".join(INSTALL_FLAGS).encode())
    return h.hexdigest()[:32]


_INSTALLED: list[Path | None] = []


def installed() -> Path | None:
    """The library the install built, where it is there, loads, and was built from these
    sources (:func:`built_from`); else None (the caller compiles DAQP into the cache)."""
    if not _INSTALLED:
        import importlib.util

        try:
            spec = importlib.util.find_spec(MODULE)
        except (ImportError, ValueError):
            spec = None
        origin = None if spec is None or spec.origin is None else Path(spec.origin)
        _INSTALLED.append(origin if origin is not None and built_from(origin) == digest()
                          else None)
    return _INSTALLED[0]


#: What precedes the digest in the library's bytes (``daqp_digest.c``).
MARK = b"equilibrist DAQP sources "


def built_from(path: Path) -> str | None:
    """The digest of the sources the library at *path* was built from, read from its bytes
    (not loaded: a damaged library would bring the process down); None where the file is not
    there, is cut short, or holds none."""
    try:
        data = path.read_bytes()
    except OSError:
        return None
    if data[:4] == b"\x7fELF" and data[4:6] == b"\x02\x01":  # 64-bit little-endian ELF
        # Its section headers come last: a file cut short ends before their end.
        shoff, = struct.unpack_from("<Q", data, 0x28)
        shentsize, shnum = struct.unpack_from("<HH", data, 0x3A)
        if len(data) < shoff + shentsize * shnum:
            return None
    at = data.find(MARK)
    if at < 0:
        return None
    found = data[at + len(MARK): at + len(MARK) + 32]
    return found.decode() if len(found) == 32 and found.isalnum() else None
