"""The export's folder: checked before anything is made (no missing parent is created, a
folder of the user's is refused without ``force``), and written all at once through a
staging folder; the version every export records and the rate it is checked for."""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from collections.abc import Mapping
from pathlib import Path

from equilibrist.errors import ExportError


def generator_version() -> str:
    """``"equilibrist <version>"``, written into every export."""
    from equilibrist import __version__

    return f"equilibrist {__version__}"


def check_rate(rate: object) -> float:
    """*rate* as a positive finite number of samples per second, else :class:`ExportError`."""
    try:
        value = float(rate)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise ExportError(f"rate must be a positive number of samples per second (Hz), got {rate!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise ExportError(f"rate must be a positive number of samples per second (Hz), got {value:g}")
    return value


# Every export folder holds this file: a folder without it is the user's.
EXPORT_MARKER = ".made-by-equilibrist"


def check_folder(out: object, *, force: bool = False) -> Path:
    """The output folder, if it can be written (existing, or new in an existing folder: no
    missing parent is created), else :class:`ExportError`.

    An existing folder that holds files and is not an earlier export is the
    user's: it is refused unless *force* (its files of the export's names
    are then replaced, the others left alone).
    """
    try:
        path = Path(os.fspath(out)).expanduser()  # type: ignore[call-overload]  # TypeError caught below
    except TypeError:
        raise ExportError(f"output folder {out!r} is not a path") from None
    path = path.absolute()
    if path.exists():
        if not path.is_dir():
            raise ExportError(f"output folder {path} exists and is not a folder")
        if not os.access(path, os.W_OK | os.X_OK):
            raise ExportError(f"output folder {path} is not writable")
        if not force and not (path / EXPORT_MARKER).exists() and any(path.iterdir()):
            raise ExportError(
                f"output folder {path} holds files that equilibrist did not write: name a new or "
                "empty folder, or add --force to replace the files of the export's names"
            )
        return path
    ancestor = path.parent
    if not ancestor.exists():
        raise ExportError(f"cannot create output folder {path}: the folder {ancestor} does not "
                          "exist (equilibrist creates no missing folder: create it first)")
    if not ancestor.is_dir():
        raise ExportError(f"cannot create output folder {path}: {ancestor} is not a folder")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise ExportError(f"cannot create output folder {path}: {ancestor} is not writable")
    return path


def write_files(folder: Path, files: Mapping[str, str]) -> None:
    """Write *files* (relative path -> text) into *folder* through a staging folder.

    A new folder appears whole (one rename); into an existing folder each
    file is moved into place, replacing an older file of the same name and
    leaving other files alone.
    """
    folder = check_folder(folder, force=True)
    existed = folder.exists()
    if existed:
        stage_root = folder
    else:
        stage_root = folder.parent
        while not stage_root.exists():
            stage_root = stage_root.parent
    try:
        staging = Path(tempfile.mkdtemp(prefix=".equilibrist-export-", dir=stage_root))
    except OSError as exc:
        raise ExportError(f"cannot write the export into {folder}: {exc.strerror or exc}") from None
    try:
        for rel, text in files.items():
            path = staging / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
        if not existed:
            folder.parent.mkdir(parents=True, exist_ok=True)
            os.chmod(staging, 0o777 & ~_umask())
            os.rename(staging, folder)
            return
        for rel in files:
            target = folder / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            os.replace(staging / rel, target)
    except OSError as exc:
        raise ExportError(f"cannot write the export into {folder}: {exc.strerror or exc}") from None
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
