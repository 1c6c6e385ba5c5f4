"""A trajectory file read back (:func:`load_trajectory`), as :meth:`Trajectory.save
<equilibrist.control.trajopt.Trajectory.save>` writes it: every array's size and type read
from the archive's ``.npy`` headers before any array is unpacked, and every metadata field
checked for its type, so that a hostile or damaged file is one line, never gigabytes or a
traceback. The system it names is looked up, never run.
"""

from __future__ import annotations

import json
import math
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from equilibrist.control.trajopt import FORMAT, Trajectory
from equilibrist.errors import DesignError

#: The most numbers an array of a trajectory file may hold (2,000,000: 16 MB of float64, a
#: 2000-knot plan of up to 999 states), and the most characters of its metadata. Both are
#: read from the file's ``.npy`` headers and checked before any array is read, so that a
#: small compressed file that claims a huge array is refused without unpacking it.
MAX_VALUES = 2_000_000
MAX_META_CHARS = 1_000_000
_ARRAYS = {"times": 1, "states": 2, "inputs": 2, "mid_inputs": 2}  # name: dimensions
_KINDS = {"c": "complex numbers", "O": "Python objects", "U": "text", "S": "bytes",
          "V": "records", "b": "booleans", "M": "dates", "m": "time spans"}


def load_trajectory(path: str | Path) -> Trajectory:
    """A trajectory written by :meth:`Trajectory.save` (its system is named, never run).

    Every array's size and type is checked in the file's ``.npy`` headers before any is
    read (at most :data:`MAX_VALUES` real numbers each, the metadata at most
    :data:`MAX_META_CHARS` characters), then every metadata field's type; anything else
    is a :class:`DesignError` of one line naming the file and what was wrong.
    """
    import zlib

    from equilibrist.errors import quote_exception

    p = Path(path)
    try:
        with zipfile.ZipFile(p) as zf:
            headers = {k: _npy_header(zf, k, p) for k in ("meta", *_ARRAYS)}
            _check_headers(p, headers)
            meta = _metadata(p, _read_member(zf, "meta"))
            arrays = {k: np.asarray(_read_member(zf, k), dtype=float) for k in _ARRAYS}
    except FileNotFoundError:
        raise DesignError(f"no trajectory file {p}") from None
    except IsADirectoryError:
        raise DesignError(f"{p} is a folder, not a trajectory file") from None
    except (OSError, ValueError, KeyError, EOFError, RuntimeError, NotImplementedError,
            zipfile.BadZipFile, zlib.error) as exc:
        if isinstance(exc, DesignError):
            raise
        raise DesignError(f"{p} is not a trajectory file: {quote_exception(exc)}") from None
    times, states, inputs, mids = (arrays[k] for k in _ARRAYS)
    n, m = len(meta["state_names"]), len(meta["input_names"])
    N = times.size - 1
    if (N < 1 or states.shape != (N + 1, n) or inputs.shape != (N + 1, m) or mids.shape != (N, m)
            or not all(np.all(np.isfinite(a)) for a in arrays.values()) or np.any(np.diff(times) <= 0)):
        raise DesignError(f"{p} is not a valid trajectory file: its arrays do not fit together")
    return Trajectory(
        system=meta["system"], params=meta["params"], state_names=meta["state_names"],
        input_names=meta["input_names"], times=times, states=states, inputs=inputs,
        mid_inputs=mids, converged=meta["converged"], cost=meta["cost"],
        max_defect=meta["max_defect"], solve_time=meta["solve_time"],
        iterations=meta["iterations"], solver=meta["solver"], settings=meta["settings"],
        system_digest=meta["system_digest"],
    )


def _npy_header(zf: Any, name: str, p: Path) -> tuple[tuple[int, ...], np.dtype[Any]]:
    """The shape and type of the array *name* of the archive, from its ``.npy`` header only."""
    from numpy.lib import format as npy

    try:
        member = zf.open(f"{name}.npy")
    except KeyError:
        raise DesignError(f"{p} is not a trajectory file: it has no {name} array") from None
    with member as fh:
        version = npy.read_magic(fh)
        if version == (1, 0):
            shape, _fortran, dtype = npy.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, _fortran, dtype = npy.read_array_header_2_0(fh)
        else:
            raise DesignError(f"{p} is not a trajectory file: its {name} array is stored in "
                              f".npy version {version[0]}.{version[1]}, expected 1.0 or 2.0")
    return tuple(shape), dtype


def _check_headers(p: Path, headers: Mapping[str, tuple[tuple[int, ...], np.dtype[Any]]]) -> None:
    """The arrays' sizes and types as their headers state them (nothing is read yet)."""
    shape, dtype = headers["meta"]
    if dtype.kind != "U" or shape != ():
        raise DesignError(f"{p} is not a trajectory file: its meta is not one text")
    if dtype.itemsize // 4 > MAX_META_CHARS:
        raise DesignError(f"{p} is not a trajectory file equilibrist reads: its meta is "
                          f"{dtype.itemsize // 4:,} characters, more than the "
                          f"{MAX_META_CHARS:,} it may hold")
    for name, ndim in _ARRAYS.items():
        shape, dtype = headers[name]
        if dtype.kind not in "fiu":
            kind = _KINDS.get(dtype.kind, f"{dtype.kind!r} values")
            raise DesignError(f"{p} is not a valid trajectory file: its {name} array holds "
                              f"{kind}, expected real numbers")
        if len(shape) != ndim or any(d < 0 for d in shape):
            raise DesignError(f"{p} is not a valid trajectory file: its {name} array has "
                              f"{len(shape)} dimensions, expected {ndim}")
        if math.prod(shape) > MAX_VALUES:
            size = " x ".join(str(d) for d in shape)
            raise DesignError(f"{p} is not a trajectory file equilibrist reads: its {name} "
                              f"array is {size} numbers, more than the {MAX_VALUES:,} an "
                              "array may hold")


def _read_member(zf: Any, name: str) -> np.ndarray:
    from numpy.lib import format as npy

    with zf.open(f"{name}.npy") as fh:
        array: np.ndarray = npy.read_array(fh, allow_pickle=False)
    return array


def _json_kind(value: object) -> str:
    """What a JSON value is, in JSON's words (never the value itself: it is outside text)."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return "a number"
    if isinstance(value, str):
        return "a text"
    return "a list" if isinstance(value, list) else "an object"


def _is_number(value: object) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _is_name(value: object) -> bool:
    return isinstance(value, str) and bool(value) and value.isprintable()


def _metadata(p: Path, stored: np.ndarray) -> dict[str, Any]:
    """The metadata's fields, each checked for its type (:meth:`Trajectory.save` writes them;
    the summary's ``cost`` and the like may be absent, as in a file written by hand)."""

    try:
        meta = json.loads(str(stored))
    except (ValueError, RecursionError):
        raise DesignError(f"{p} is not a trajectory file: its meta is not JSON") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise DesignError(f"{p} is not a trajectory file (written by 'equilibrist trajopt --out')")
    out: dict[str, Any] = {}

    def bad(key: str, expected: str) -> DesignError:
        return DesignError(f"{p} is not a valid trajectory file: its {key} is "
                           f"{_json_kind(meta.get(key))}, expected {expected}")

    for key in ("system", "state_names", "input_names"):
        if key not in meta:
            raise DesignError(f"{p} is not a valid trajectory file: it names no {key}")
    if not _is_name(meta["system"]):
        raise bad("system", "a system's name (printable text)")
    out["system"] = meta["system"]
    for key in ("state_names", "input_names"):
        names = meta[key]
        if (not isinstance(names, list) or not names or not all(_is_name(v) for v in names)
                or len(set(names)) != len(names)):
            raise bad(key, "a list of distinct names (printable texts)")
        out[key] = tuple(names)
    digest = meta.get("system_digest")
    if digest is not None and not _is_name(digest):
        raise bad("system_digest", "a digest (printable text) or null")
    out["system_digest"] = digest
    params = meta.get("params", {})
    if not isinstance(params, dict) or not all(_is_number(v) for v in params.values()):
        raise bad("params", "an object of parameter values (numbers)")
    out["params"] = {k: float(v) for k, v in params.items()}
    settings = meta.get("settings", {})
    if not isinstance(settings, dict):
        raise bad("settings", "an object")
    out["settings"] = settings
    for key in ("cost", "max_defect", "solve_time"):
        value = meta.get(key, math.nan)
        if not _is_number(value):
            raise bad(key, "a number")
        out[key] = float(value)
    iterations = meta.get("iterations", 0)
    if not (isinstance(iterations, int) and not isinstance(iterations, bool)
            and 0 <= iterations <= 10**9):
        raise bad("iterations", "a whole number from 0 to 1000000000")
    out["iterations"] = iterations
    converged = meta.get("converged", False)
    if not isinstance(converged, bool):
        raise bad("converged", "true or false")
    out["converged"] = converged
    solver = meta.get("solver", "")
    if not isinstance(solver, str) or not solver.isprintable():
        raise bad("solver", "a text")
    out["solver"] = solver
    return out
