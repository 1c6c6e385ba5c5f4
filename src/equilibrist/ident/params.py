"""Parameter files: what ``identify --out params.json`` writes and ``--params`` reads.

The file is JSON: ``{"format": "equilibrist-params-1", "system": KEY,
"params": {NAME: VALUE, ...}, ...}`` (``identified`` holds the fitted values
with their standard errors, for people). A plain object of parameter values
``{NAME: VALUE, ...}`` is accepted too.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path

from equilibrist.atomic import write_text
from equilibrist.ident.log import IdentificationError

FORMAT = "equilibrist-params-1"


def _family(key: str) -> str:
    return key.partition("[")[0]


def _same_file(a: str, b: str) -> bool:
    """Whether *a* and *b* name the same system file, however each path is written.

    A file system is the same system by its content: the same file reached
    by another path (relative, through a link), or a copy with the same
    bytes, is the same system.
    """
    pa, pb = Path(a), Path(b)
    try:
        if pa.resolve() == pb.resolve():
            return True
        if not (pa.is_file() and pb.is_file()):
            return False
        return pa.read_bytes() == pb.read_bytes()
    except OSError:
        return False


def read_params(path: str | Path, system: str | None = None) -> dict[str, float]:
    """The parameter values in *path*; with *system*, checked to be that system's.

    Returns a plain ``{name: value}`` (names are checked by the system when
    the values are bound).
    """
    p = Path(path)
    if not p.exists():
        raise IdentificationError(f"no parameter file {p}")
    try:
        doc = json.loads(p.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise IdentificationError(f"{p} is not a JSON parameter file: {exc}") from None
    if not isinstance(doc, dict):
        raise IdentificationError(f"{p}: expected a JSON object of parameter values")
    if "params" in doc and isinstance(doc.get("params"), dict):
        key = doc.get("system")
        if system is not None and isinstance(key, str) and _family(key) != _family(system) \
                and key != system and not _same_file(key, system):
            raise IdentificationError(f"{p} holds parameters of {key}, not of {system}")
        values = doc["params"]
    else:
        values = doc
    out: dict[str, float] = {}
    for name, v in values.items():
        try:
            value = float(v) if isinstance(v, int | float) and not isinstance(v, bool) else math.nan
        except OverflowError:  # an integer too large for a double
            value = math.inf
        if not math.isfinite(value):
            shown = repr(v) if len(repr(v)) <= 40 else f"{repr(v)[:20]}... ({len(repr(v))} digits)"
            raise IdentificationError(f"{p}: parameter {name} = {shown} is not a finite number")
        out[str(name)] = value
    return out


def write_params(document: Mapping[str, object], path: str | Path) -> Path:
    """Write *document* (``Identification.params_document()``) atomically."""
    p = Path(path)
    if p.suffix != ".json":
        raise IdentificationError(f"--out {p}: a parameter file is written as .json")
    text = json.dumps(document, indent=2) + "\n"
    write_text(p, text)  # whole or not at all, with the umask's mode
    return p


__all__ = ["FORMAT", "read_params", "write_params"]
