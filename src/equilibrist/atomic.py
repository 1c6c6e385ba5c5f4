"""Files written whole or not at all, where the user said, with the modes the user's umask gives.

Every file equilibrist writes goes through :func:`atomic_path`: the writer
fills a temporary file beside the target, and only a complete file replaces
it (``os.replace`` is atomic on one file system). A failure part-way, a full
disk or Ctrl-C leaves the previous file as it was and no partial file behind.

Three rules hold for every output (docs/outputs.md):

* A missing folder is never created: :func:`check_output` refuses an output
  whose folder does not exist, in one line naming that folder.
* A file gets the mode ``open()`` gives a new file (``0o666`` less the
  umask), a folder the mode ``mkdir`` gives (``0o777`` less the umask),
  also when it replaces an older one: :func:`create_file` and
  :func:`make_folder` make the temporary ones that way (``tempfile``'s are
  private, ``0o600`` and ``0o700``).
* An error names the path the user gave, never the temporary file's.
"""

from __future__ import annotations

import errno
import os
import secrets
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from equilibrist.errors import EquilibristError


class OutputError(EquilibristError, OSError):
    """An output that is not written where it was asked: its folder is missing, or what is
    there is not equilibrist's to replace."""


def check_output(path: str | os.PathLike[str], *, what: str = "") -> Path:
    """*path* as a Path, refused (:class:`OutputError`) when its folder does not exist or
    is not a folder: equilibrist creates no missing folder (*what*, such as ``"--out"``,
    begins the message)."""
    target = Path(path)
    folder = target.parent
    if folder.is_dir():
        return target
    name = f"{what} {target}" if what else str(target)
    if folder.exists() or folder.is_symlink():
        raise OutputError(f"{name}: {folder} is not a folder")
    raise OutputError(f"{name}: the folder {folder} does not exist (equilibrist creates no "
                      "missing folder: create it first)")


_ATTEMPTS = 100


def create_file(folder: str | os.PathLike[str], *, prefix: str, suffix: str = "") -> tuple[int, Path]:
    """A new empty file in *folder*, open for writing: its descriptor and path.

    As :func:`tempfile.mkstemp` (a fresh name, never an existing file or a link
    followed), but with the mode ``open()`` gives a new file: ``0o666`` less the
    umask, applied by the system."""
    flags = os.O_RDWR | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) \
        | getattr(os, "O_CLOEXEC", 0)
    for _ in range(_ATTEMPTS):
        path = Path(folder) / f"{prefix}{secrets.token_hex(6)}{suffix}"
        try:
            return os.open(path, flags, 0o666), path
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name in {folder}")


def make_folder(parent: str | os.PathLike[str], *, prefix: str) -> Path:
    """A new empty folder in *parent*, with the mode ``mkdir`` gives: ``0o777`` less the
    umask (as :func:`tempfile.mkdtemp` otherwise, whose folder is private)."""
    for _ in range(_ATTEMPTS):
        path = Path(parent) / f"{prefix}{secrets.token_hex(6)}"
        try:
            path.mkdir(mode=0o777)
        except FileExistsError:
            continue
        return path
    raise FileExistsError(f"no free temporary name in {parent}")


def _naming(exc: OSError, target: Path, tmp: Path | None) -> OSError:
    """*exc* naming *target* where it named the temporary file *tmp* (every name, when
    *tmp* is None: the temporary file was being made)."""
    if isinstance(exc, OutputError) or exc.errno is None:
        return exc
    if tmp is not None and str(tmp) not in (exc.filename, exc.filename2):
        return exc
    reason = exc.strerror
    if tmp is None and exc.errno == errno.ENOENT:  # the folder is there (checked before)
        reason = f"the folder {target.parent} takes no new files"
    return OSError(exc.errno, reason, str(target))  # the subclass of the errno


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """A temporary path to write instead of *path*; it replaces *path* on success.

    The temporary file keeps *path*'s suffix (writers that choose a format
    by suffix, such as matplotlib, see the right one) and lives in the same
    folder, which must exist (:func:`check_output`). The file gets the
    umask's mode (:func:`create_file`); an error of the file system names
    *path*.

    Examples
    --------
    >>> with atomic_path("run.npz") as tmp:  # doctest: +SKIP
    ...     np.savez(tmp, x=x)
    """
    target = check_output(path)
    if target.is_dir():
        raise OutputError(f"{target} is a folder: name a file")
    try:
        fd, tmp = create_file(target.parent, prefix=f".{target.name}.", suffix=target.suffix)
    except OSError as exc:
        raise _naming(exc, target, None) from None
    os.close(fd)
    try:
        yield tmp
        if not tmp.exists() or tmp.stat().st_size == 0:
            raise OSError(f"nothing was written to {target}")
        os.replace(tmp, target)
    except OSError as exc:
        renamed = _naming(exc, target, tmp)
        if renamed is exc:
            raise
        raise renamed from None
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
