"""Files written whole or not at all.

Every file equilibrist writes goes through :func:`atomic_path`: the writer
fills a temporary file beside the target, and only a complete file replaces
it (``os.replace`` is atomic on one file system). A failure part-way, a full
disk or Ctrl-C leaves the previous file as it was and no partial file behind.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path to write instead of *path*; it replaces *path* on success.

    The temporary file keeps *path*'s suffix (writers that choose a format
    by suffix, such as matplotlib, see the right one) and lives in the same
    folder, which is created if missing.

    Examples
    --------
    >>> with atomic_path("run.npz") as tmp:  # doctest: +SKIP
    ...     np.savez(tmp, x=x)
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=target.suffix)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        if not tmp.exists() or tmp.stat().st_size == 0:
            raise OSError(f"nothing was written to {target}")
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


def write_bytes(path: str | os.PathLike[str], data: bytes) -> Path:
    """Write *data* to *path* atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def write_text(path: str | os.PathLike[str], text: str) -> Path:
    """Write *text* (UTF-8) to *path* atomically."""
    return write_bytes(path, text.encode())
