"""What every file of the C export is written with: the test vectors' type
(:class:`Vectors`), C literals of numbers, vectors and matrices, the C names of a
controller, and comment and string helpers."""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import PurePath
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.errors import ExportError

if TYPE_CHECKING:
    from equilibrist.native.linear_c import ControllerData

_INDENT = "    "
_FLOAT_MAX = float(np.finfo(np.float32).max)
#: The arithmetic a library may be written in.
PRECISIONS = ("double", "float")


def check_precision(precision: str) -> str:
    """Return *precision* if it is ``"double"`` or ``"float"``, else raise :class:`ExportError`."""
    if precision not in PRECISIONS:
        raise ExportError(
            f"precision {precision!r} is unknown: expected one of {', '.join(PRECISIONS)}"
        )
    return precision


@dataclass(frozen=True)
class Vectors:
    """A recorded closed-loop run as test vectors: measurements in, inputs out.

    Attributes
    ----------
    y:
        ``(n_steps, p)`` measurements in absolute units, as given to ``step``.
    r:
        ``(n_steps, nr)`` references (tracked outputs), absolute.
    u:
        ``(n_steps, m)`` saturated commands the reference controller returned.
    x_init:
        Initial estimate of the state, absolute (``init_at``'s argument).
    tolerance:
        Per input, the largest accepted ``|u_C - u|``.
    """

    y: np.ndarray
    r: np.ndarray
    u: np.ndarray
    x_init: np.ndarray
    tolerance: np.ndarray

    @property
    def n_steps(self) -> int:
        return int(self.u.shape[0])

    def __repr__(self) -> str:  # the arrays are long: say what they are
        return (f"Vectors(n_steps={self.n_steps}, measurements={self.y.shape[1]}, "
                f"references={self.r.shape[1]}, inputs={self.u.shape[1]})")


# -- numbers ------------------------------------------------------------------------------
def literal(value: float, precision: str) -> str:
    """A C literal that reads back as exactly *value* rounded to *precision*.

    Doubles use Python's shortest round-trip form; floats the shortest form
    of the value rounded to single precision, with the ``f`` suffix.
    """
    v = float(value)
    if not math.isfinite(v):
        raise ExportError(f"cannot write {v} as a C constant")
    if precision == "float":
        if abs(v) > _FLOAT_MAX:
            raise ExportError(f"{v:g} is beyond the range of single precision")
        text = str(np.float32(v))
    else:
        text = repr(v)
    if "." not in text and "e" not in text:
        text += ".0"
    return text + ("f" if precision == "float" else "")


def _vector(values: Sequence[float] | np.ndarray, precision: str) -> str:
    return "{" + ", ".join(literal(v, precision) for v in np.asarray(values).reshape(-1)) + "}"


def _matrix(mat: np.ndarray, precision: str, indent: str = _INDENT) -> str:
    rows = [indent + _vector(row, precision) for row in np.atleast_2d(mat)]
    return "{\n" + ",\n".join(rows) + "\n}"


# -- names --------------------------------------------------------------------------------
def c_identifier(text: str) -> str:
    """*text* made into a lower-case C identifier (``gyroscope[euler=xyz]`` -> ``gyroscope_euler_xyz``).

    A system file's key (its path) gives the file's own name
    (``/home/me/robots/furuta.xml`` -> ``furuta``).
    """
    from equilibrist.systems.files import looks_like_path

    if looks_like_path(text):
        text = PurePath(text).stem
    ident = re.sub(r"[^0-9A-Za-z]+", "_", text).strip("_").lower()
    if not ident:
        ident = "controller"
    if ident[0].isdigit():
        ident = "c_" + ident
    return ident


@dataclass(frozen=True)
class _Names:
    lower: str
    upper: str

    def __call__(self, suffix: str) -> str:
        return f"{self.lower}_{suffix}"

    def macro(self, suffix: str) -> str:
        return f"{self.upper}_{suffix}"


def _names(data: ControllerData) -> _Names:
    return _Names(data.name, data.name.upper())


def _unit(unit: str) -> str:
    return f"[{unit}]" if unit else "[-]"


def _comment_lines(lines: Sequence[str]) -> str:
    out = ["/*"]
    for line in lines:
        out.append((" * " + line).rstrip())
    out.append(" */")
    return "\n".join(out)


def _fmt_matrix_text(mat: np.ndarray) -> list[str]:
    mat = np.atleast_2d(np.asarray(mat, dtype=float))
    if mat.shape[0] == mat.shape[1] and np.count_nonzero(mat - np.diag(np.diag(mat))) == 0:
        return ["diag(" + ", ".join(f"{v:.6g}" for v in np.diag(mat)) + ")"]
    return ["[" + ", ".join(f"{v:.6g}" for v in row) + "]" for row in mat]


def _settings_string(data: ControllerData, precision: str) -> str:
    items = dict(data.settings)
    items["precision"] = precision
    return "; ".join(f"{k}={v}" for k, v in items.items())


def _c_string(text: str) -> str:
    escaped = text.replace("\\", "\\\\").replace('"', '\\"')
    return '"' + "".join(c if 32 <= ord(c) < 127 else "?" for c in escaped) + '"'


def _index_macros(nm: _Names, prefix: str, names: Sequence[str]) -> list[str]:
    macros = [nm.macro(f"{prefix}_{n.upper()}") for n in names]
    if len(set(macros)) != len(macros):  # names that differ only in case: skip them
        return []
    return [f"#define {m} {i}" for i, m in enumerate(macros)]
