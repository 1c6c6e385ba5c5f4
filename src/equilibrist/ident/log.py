"""A rig's log: the time, the inputs and the measured outputs, checked against a system.

A CSV file (``docs/identification.md``, "The log"): a header row, then one row a sample:
``t`` strictly increasing, one column per input (held until the next sample), one per
measured state; a unit given in brackets must be the system's, ``#`` starts a comment. The
columns a simulated run adds (:data:`EXTRA_SUFFIXES`) are recognised and not used; any
other column is an error, so a log of another system is never fitted by mistake.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from equilibrist.errors import EquilibristError
from equilibrist.numeric.system import System

# Suffixes of the columns a simulated run writes beside the log.
EXTRA_SUFFIXES = ("_true", "_hat", "_commanded", "_saturated", "_reference")


class IdentificationError(EquilibristError, ValueError):
    """A log or an identification that cannot be used as asked."""


@dataclass(frozen=True, eq=False)
class Log:
    """A validated log of the system *system* (its key): the inputs in the system's order,
    the measured states in the log's column order."""

    system: str
    time: np.ndarray
    inputs: np.ndarray
    output_names: tuple[str, ...]
    outputs: np.ndarray
    source: str = ""

    @property
    def n_rows(self) -> int:
        return int(self.time.shape[0])

    @property
    def duration(self) -> float:
        return float(self.time[-1] - self.time[0])

    def output(self, name: str) -> np.ndarray:
        return self.outputs[:, self.output_names.index(name)]

    @classmethod
    def from_arrays(cls, system: System, time: object, inputs: object,
                    outputs: dict[str, object], *, source: str = "") -> Log:
        """A log from arrays (checked as a file is)."""
        cols: dict[str, np.ndarray] = {"t": np.asarray(time, dtype=float).reshape(-1)}
        u = np.asarray(inputs, dtype=float).reshape(len(cols["t"]), -1)
        for i, name in enumerate(system.input_names):
            cols[name] = u[:, i] if i < u.shape[1] else np.array([])
        for name, values in outputs.items():
            cols[name] = np.asarray(values, dtype=float).reshape(-1)
        return _checked(system, cols, {}, source or "the log")


def read_log(system: System, path: str | Path) -> Log:
    """Read and check the CSV log at *path* for *system*; every problem is one error."""
    p = Path(path)
    where = str(p)
    if not p.exists():
        raise IdentificationError(f"no log file {where}")
    try:
        text = p.read_text()
    except UnicodeDecodeError:
        raise IdentificationError(f"{where} is not a text (CSV) log") from None
    lines = [(i + 1, ln.strip()) for i, ln in enumerate(text.splitlines())]
    lines = [(i, ln) for i, ln in lines if ln and not ln.startswith("#")]
    if not lines:
        raise IdentificationError(f"{where} is empty: expected a header row (t, inputs, outputs) "
                                  "and rows of numbers")
    header = [h.strip() for h in lines[0][1].split(",")]
    names: list[str] = []
    units: dict[str, str] = {}
    for h in header:
        name, _, rest = h.partition("[")
        name = name.strip()
        if not name:
            raise IdentificationError(f"{where}: the header has an empty column name")
        if rest:
            units[name] = rest.rstrip("]").strip()
        names.append(name)
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise IdentificationError(f"{where}: column {dup[0]!r} appears twice in the header")
    rows = lines[1:]
    data = np.empty((len(rows), len(names)))
    for r, (lineno, ln) in enumerate(rows):
        cells = ln.split(",")
        if len(cells) != len(names):
            raise IdentificationError(
                f"{where} line {lineno}: {len(cells)} values, expected {len(names)} "
                f"(one per column of the header)"
            )
        for c, cell in enumerate(cells):
            try:
                data[r, c] = float(cell)
            except ValueError:
                raise IdentificationError(
                    f"{where} line {lineno}, column {names[c]!r}: {cell.strip()!r} is not a number"
                ) from None
    cols = {n: data[:, i] for i, n in enumerate(names)}
    return _checked(system, cols, units, where)


def _checked(system: System, cols: dict[str, np.ndarray], units: dict[str, str], where: str) -> Log:
    states, inputs = system.state_names, system.input_names
    known = {"t": "s"}
    known.update(zip(states, system.state_units, strict=True))
    known.update(zip(inputs, system.input_units, strict=True))
    extras = {f"{s}{suffix}" for s in states + inputs for suffix in EXTRA_SUFFIXES}
    columns = f"t, the input{'s' if len(inputs) != 1 else ''} {', '.join(inputs)} and measured " \
              f"outputs among {', '.join(states)}"
    for name in cols:
        if name not in known and name not in extras:
            raise IdentificationError(
                f"{where}: column {name!r} is not a state or input of {system.key} "
                f"(expected columns {columns})"
            )
    for name, unit in units.items():
        if name in known and unit != known[name]:
            raise IdentificationError(
                f"{where}: column {name!r} is in [{unit}], expected [{known[name]}] "
                f"(the units of {system.key})"
            )
    if "t" not in cols:
        raise IdentificationError(f"{where} has no time column 't' (expected columns {columns})")
    missing = [i for i in inputs if i not in cols]
    if missing:
        raise IdentificationError(
            f"{where} has no column for the input {missing[0]!r} of {system.key} "
            f"(expected columns {columns})"
        )
    outs = tuple(n for n in cols if n in states)
    if not outs:
        raise IdentificationError(
            f"{where} has no measured output: expected a column named after a state of "
            f"{system.key} ({', '.join(states)})"
        )
    time = cols["t"]
    n_rows = time.shape[0]
    if any(cols[n].shape[0] != n_rows for n in (*inputs, *outs)):
        raise IdentificationError(f"{where}: the columns have different lengths")
    if n_rows < 2:
        raise IdentificationError(
            f"{where} has {'a single row' if n_rows == 1 else 'no rows'} of data: "
            "a fit needs a time series (many rows)"
        )
    for name in ("t", *inputs, *outs):
        bad = np.nonzero(~np.isfinite(cols[name]))[0]
        if bad.size:
            raise IdentificationError(
                f"{where}: column {name!r} has a value that is not a finite number "
                f"({cols[name][bad[0]]} in data row {bad[0] + 1})"
            )
    steps = np.diff(time)
    bad = np.nonzero(steps <= 0)[0]
    if bad.size:
        k = int(bad[0])
        raise IdentificationError(
            f"{where}: the time t does not increase at data row {k + 2} "
            f"(t = {time[k + 1]:g} s after {time[k]:g} s)"
        )
    u = np.column_stack([cols[i] for i in inputs]) if inputs else np.zeros((n_rows, 0))
    y = np.column_stack([cols[o] for o in outs])
    time, u, y = time.copy(), np.ascontiguousarray(u), np.ascontiguousarray(y)
    for a in (time, u, y):
        a.setflags(write=False)
    return Log(system.key, time, u, outs, y, where)


__all__ = ["EXTRA_SUFFIXES", "IdentificationError", "Log", "read_log"]
