"""The study's table on disk: Parquet parts written atomically, then one file.

Each finished chunk of points is written to ``<out>.parts/chunk-NNNNNN.parquet`` through a
temporary file and a rename; ``<out>.parts/study.json`` holds the study's description and
the chunk size (what ``--resume`` checks). When every chunk is there, the parts are
concatenated in point order into ``<out>`` and the folder is removed. The file's metadata
holds ``equilibrist.format``, ``equilibrist.study`` (canonical JSON) and
``equilibrist.versions``; nothing that depends on the run (times, hosts, workers) is
written, so the file is the same bytes however it was made.
"""

from __future__ import annotations

import contextlib
import json
import os
import platform
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

from equilibrist.atomic import create_file
from equilibrist.study.compute import metric_names
from equilibrist.study.record import FORMAT, Study, StudyError

if TYPE_CHECKING:
    import pyarrow as pa

_MANIFEST = "study.json"
_PART = re.compile(r"chunk-\d{6,}\.parquet")


def require_pyarrow() -> Any:  # the pyarrow module (untyped)
    try:
        import pyarrow
        import pyarrow.parquet
    except ImportError:
        raise StudyError("study tables need pyarrow: pip install 'equilibrist[cluster]'") from None
    return pyarrow


def versions() -> dict[str, str]:
    """The versions that shape the numbers (recorded in the file)."""
    import numpy
    import scipy

    from equilibrist import __version__
    from equilibrist.native.build import compiler_identity

    pa = require_pyarrow()
    return {"equilibrist": __version__, "python": platform.python_version(),
            "numpy": numpy.__version__, "scipy": scipy.__version__,
            "cc": compiler_identity(), "pyarrow": pa.__version__}


def schema(study: Study) -> pa.Schema:
    """The table's columns and types (the same for every chunk)."""
    pa = require_pyarrow()
    from equilibrist.numeric.lookup import get_system

    inputs = get_system(study.system, **study.settings).input_names
    fields = [pa.field("point", pa.int64(), nullable=False)]
    for a in study.axes:
        typ = pa.string() if a.kind == "controller" else pa.bool_() if a.kind == "delay" else pa.float64()
        fields.append(pa.field(a.name, typ, nullable=False))
    fields += [pa.field("status", pa.string(), nullable=False), pa.field("error", pa.string()),
               pa.field("runs", pa.int64(), nullable=False),
               pa.field("stayed_up", pa.int64(), nullable=False)]
    fields += [pa.field(name, pa.float64(), nullable=False) for name in metric_names(inputs)]
    fields.append(pa.field("steps", pa.int64(), nullable=False))
    meta = {"equilibrist.format": FORMAT, "equilibrist.study": study.to_json(),
            "equilibrist.versions": json.dumps(versions(), sort_keys=True)}
    return pa.schema(fields, metadata=meta)


def rows_to_table(rows: list[dict[str, object]], sch: pa.Schema) -> pa.Table:
    pa = require_pyarrow()
    columns = {f.name: [r[f.name] for r in rows] for f in sch}
    return pa.Table.from_pydict(columns, schema=sch)


def _atomic_parquet(table: pa.Table, path: Path) -> None:
    import pyarrow.parquet as pq

    fd, tmp = create_file(path.parent, prefix=f".{path.name}.", suffix=".tmp")  # umask's mode
    os.close(fd)
    try:
        pq.write_table(table, tmp, compression="zstd")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def parts_dir(out: Path) -> Path:
    return out.with_name(out.name + ".parts")


class Store:
    """The parts folder of one study being written to *out*."""

    def __init__(self, study: Study, out: Path, chunk_size: int) -> None:
        self.study = study
        self.out = out
        self.chunk_size = chunk_size
        self.dir = parts_dir(out)
        self.schema = schema(study)

    @property
    def n_chunks(self) -> int:
        return -(-self.study.n_points // self.chunk_size)

    def part(self, chunk: int) -> Path:
        return self.dir / f"chunk-{chunk:06d}.parquet"

    def open(self, *, resume: bool) -> list[int]:
        """Create (or, resuming, check) the parts folder; the chunks still to compute."""
        manifest = {"study": self.study.to_dict(), "chunk_size": self.chunk_size}
        if self.dir.exists():
            if not self.dir.is_dir() or not (self.dir / _MANIFEST).is_file():
                raise StudyError(f"{self.dir} is in the way and is not the parts folder of a "
                                 "study: move it away (or name another --out)")
            if not resume:
                raise StudyError(f"{self.dir} holds an unfinished study: add --resume to "
                                 "continue it, or remove that folder to start again")
            try:
                found = json.loads((self.dir / _MANIFEST).read_text())
            except (OSError, ValueError):
                found = None
            if not isinstance(found, dict) or not isinstance(found.get("study"), dict):
                raise StudyError(f"{self.dir / _MANIFEST} is damaged (expected the JSON object "
                                 "'equilibrist sweep' writes): remove the folder to start again")
            if found.get("study") != manifest["study"]:
                raise StudyError(f"{self.dir} belongs to another study: --resume continues "
                                 "the same study only (remove the folder to start this one)")
            if found.get("chunk_size") != self.chunk_size:
                raise StudyError(f"{self.dir} was written with --chunk-size "
                                 f"{found.get('chunk_size')!r}: resume with the same chunk size")
            return [c for c in range(self.n_chunks) if not self._complete(c)]
        self.dir.mkdir(parents=True)
        text = json.dumps(manifest, sort_keys=True, indent=1)
        fd, tmp = create_file(self.dir, prefix=".study.", suffix=".tmp")  # the umask's mode
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, self.dir / _MANIFEST)
        return list(range(self.n_chunks))

    def _complete(self, chunk: int) -> bool:
        """Whether the part of *chunk* is there; a file of its name that is not a part of
        this study (another study's, or not Parquet) is refused: it is not ours to delete."""
        import pyarrow.parquet as pq

        path = self.part(chunk)
        if not path.exists():
            return False
        first = chunk * self.chunk_size
        expected = min(self.chunk_size, self.study.n_points - first)
        try:
            found = pq.read_schema(path)
            same = (found.remove_metadata().equals(self.schema.remove_metadata())
                    and (found.metadata or {}).get(b"equilibrist.study")
                    == self.schema.metadata[b"equilibrist.study"])
            points = pq.read_table(path, columns=["point"]).column("point").to_pylist() if same else []
        except Exception:  # any unreadable file is refused below
            same, points = False, []
        if not same or points != list(range(first, first + expected)):
            raise StudyError(f"{path} is not a part of this study (not written by this "
                             "'equilibrist sweep'): move it out of the parts folder, then resume")
        return True

    def write(self, chunk: int, rows: list[dict[str, object]]) -> None:
        _atomic_parquet(rows_to_table(rows, self.schema), self.part(chunk))

    def assemble(self) -> Path:
        """Concatenate the parts into the final file and remove the parts folder."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        tables = [pq.read_table(self.part(c), schema=self.schema) for c in range(self.n_chunks)]
        table = pa.concat_tables(tables) if tables else self.schema.empty_table()
        points = table.column("point").to_pylist()
        if points != list(range(self.study.n_points)):
            raise StudyError(f"{self.dir}: the parts do not cover the study's points: remove it")
        _atomic_parquet(table.replace_schema_metadata(self.schema.metadata), self.out)
        self.remove()
        return self.out

    def remove(self) -> None:
        """Remove the parts folder's own files (the manifest, the parts, their temporary
        files), and the folder when nothing the user put there is left in it."""
        if not self.dir.is_dir():
            return
        for path in self.dir.iterdir():
            name = path.name
            ours = (name == _MANIFEST or _PART.fullmatch(name) is not None
                    or (name.startswith((".study.", ".chunk-")) and name.endswith(".tmp")))
            if ours and path.is_file() and not path.is_symlink():
                path.unlink(missing_ok=True)
        with contextlib.suppress(OSError):  # not empty: the user's files stay, with their folder
            self.dir.rmdir()


def check_out(out: Path, *, force: bool = False, resume: bool = False) -> None:
    """Refuse to replace a file at *out* that is not a study table (the user's), unless
    *force*; with *resume* anything but a table is refused, even with *force*."""
    if not out.exists() and not out.is_symlink():
        return
    if out.is_dir():
        raise StudyError(f"--out {out} is a folder: name the table's file")
    if _is_study_table(out) or (force and not resume):
        return
    if resume:
        raise StudyError(f"--out {out} exists and is not a study table written by 'equilibrist "
                         "sweep': there is nothing to resume from it (name the study's table)")
    raise StudyError(f"--out {out} exists and is not a study table written by 'equilibrist "
                     "sweep': name a new file, or add --force to replace it")


def _is_study_table(path: Path) -> bool:
    import pyarrow.parquet as pq

    try:
        meta = pq.read_schema(path).metadata or {}
    except Exception:  # whatever it is, it is not a table
        return False
    return bool(meta.get(b"equilibrist.format", b"") == FORMAT.encode())


def read_study(path: str | Path) -> tuple[pa.Table, Study]:
    """A study file's table and its study description."""
    pa = require_pyarrow()
    import pyarrow.parquet as pq

    p = Path(path)
    if not p.exists():
        raise StudyError(f"no study file {str(p)!r}")
    try:
        table = pq.read_table(p)
    except (OSError, pa.ArrowException) as exc:
        raise StudyError(f"{p} is not a study table: {exc}") from None
    meta = table.schema.metadata or {}
    if meta.get(b"equilibrist.format", b"").decode() != FORMAT:
        raise StudyError(f"{p} is not a study table written by 'equilibrist sweep'")
    return table, Study.from_json(meta[b"equilibrist.study"].decode())
