"""Building and checking a study's axes: the numbers, counts and values given for each
varied quantity (a parameter, the rate, a Bryson scale, a noise, the controller...) and the
ranges of the initial states; used by :mod:`equilibrist.study.spec`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.errors import nearest, quote_outside
from equilibrist.study.choice import check_choice
from equilibrist.study.record import (
    MAX_POINTS,
    MAX_ROA_STATES,
    SPECIAL,
    Axis,
    AxisValue,
)

if TYPE_CHECKING:
    from equilibrist.numeric.system import System

# -- building and checking ---------------------------------------------------------------


def _number(value: object, what: str, problems: list[str]) -> float | None:
    if isinstance(value, bool):
        problems.append(f"{what}: {value!r} is not a number")
        return None
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        problems.append(f"{what}: {value!r} is not a number")
        return None
    if not math.isfinite(v):
        problems.append(f"{what}: {value!r} is not a finite number")
        return None
    return v


def _whole(value: object, what: str, problems: list[str], *, minimum: int = 1) -> int | None:
    if isinstance(value, bool):
        problems.append(f"{what}: expected a whole number >= {minimum}, got {value!r}")
        return None
    try:
        v = int(str(value).strip()) if not isinstance(value, int) else value
    except ValueError:
        problems.append(f"{what}: expected a whole number >= {minimum}, got {value!r}")
        return None
    if v < minimum:
        problems.append(f"{what}: expected a whole number >= {minimum}, got {v}")
        return None
    return v


def _low_high(parts: Sequence[object], what: str, shown: str, problems: list[str], *,
              counted: bool) -> tuple[float, float, int | None] | None:
    """``LOW``, ``HIGH`` (and ``N`` when *counted*) of a range's *parts*, or None after
    saying what is wrong (a reversed range among it)."""
    before = len(problems)
    lo = _number(parts[0], f"{what} LOW", problems)
    hi = _number(parts[1], f"{what} HIGH", problems)
    n = _whole(parts[2], f"{what} N", problems) if counted else None
    if len(problems) > before or lo is None or hi is None:
        return None
    if lo > hi:
        problems.append(f"{shown}: reversed range, LOW {lo:g} is above HIGH {hi:g}")
        return None
    return lo, hi, n


def _parse_values(name: str, value: object, sampled: bool, problems: list[str]
                  ) -> tuple[tuple[object, ...], float | None, float | None, bool] | None:
    """``(values, low, high, log)`` of an axis from its text, list or table."""
    what = f"--vary {name}"
    if isinstance(value, Mapping):  # TOML {low = .., high = .., n = .., log = ..}
        unknown = sorted(set(value) - {"low", "high", "n", "log"})
        if unknown:
            problems.append(f"{what}: unknown key(s) {', '.join(unknown)} (expected low, high, n, log)")
            return None
        pieces = [value.get("low"), value.get("high")]
        if "n" in value:
            pieces.append(value["n"])
        if value.get("log"):
            pieces.append("log")
        text = ":".join("" if p is None else str(p) for p in pieces)
        return _parse_values(name, text, sampled, problems)
    if isinstance(value, (list, tuple)):
        if not value:
            problems.append(f"{what}: the list of values is empty")
            return None
        return tuple(value), None, None, False
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return (value,), None, None, False
    text = str(value).strip()
    if not text:
        problems.append(f"{what}: no values (expected LOW:HIGH:N, V1,V2,... or V)")
        return None
    if ":" not in text:
        items = [t.strip() for t in text.split(",")]
        if not all(items):
            problems.append(f"{what}={text}: expected comma-separated values")
            return None
        return tuple(items), None, None, False
    parts = [t.strip() for t in text.split(":")]
    log = False
    if parts and parts[-1].lower() == "log":
        log = True
        parts = parts[:-1]
    form = "LOW:HIGH[:log]" if sampled else "LOW:HIGH:N[:log]"
    if len(parts) != (2 if sampled else 3):
        extra = (" (a random sample draws its own points: give the range only)"
                 if sampled and len(parts) == 3 else "")
        problems.append(f"{what}={text}: expected {form}{extra}")
        return None
    bounds = _low_high(parts, what, f"{what}={text}", problems, counted=not sampled)
    if bounds is None:
        return None
    lo, hi, count = bounds
    if lo == hi:
        problems.append(f"{what}={text}: empty range, LOW equals HIGH (give one value as {name}={lo:g})")
        return None
    if log and lo <= 0:
        problems.append(f"{what}={text}: a log range needs LOW > 0")
        return None
    if sampled:
        return (), lo, hi, log
    assert count is not None
    if count > MAX_POINTS:  # refused before the grid is allocated
        problems.append(f"{what}={text}: N = {count} values, at most {MAX_POINTS} per study")
        return None
    grid = np.geomspace(lo, hi, count) if log else np.linspace(lo, hi, count)
    return tuple(float(v) for v in grid), lo, hi, log


def _axis(system: System, name: str, value: object, sampled: bool,
          problems: list[str]) -> Axis | None:
    spec = system.spec
    params = {p.name: p for p in spec.all_parameters}
    if name in params:
        kind = "parameter"
    elif name in SPECIAL:
        kind = name
    elif name.startswith(("q.", "r.")):
        kind = name[0]
        target = name[2:]
        names = system.state_names if kind == "q" else system.input_names
        if target not in names:
            what = "state" if kind == "q" else "input"
            problems.append(f"--vary {name}: {system.key} has no {what} {target!r} "
                            f"({nearest(target, names)})")
            return None
    else:
        choices = [*spec.parameter_names, *SPECIAL, *(f"q.{s}" for s in system.state_names),
                   *(f"r.{i}" for i in system.input_names)]
        problems.append(f"--vary: unknown quantity {name!r} of {system.key} ({nearest(name, choices)})")
        return None
    if kind == "controller":
        return _controller_axis(system, value, problems)
    parsed = _parse_values(name, value, sampled, problems)
    if parsed is None:
        return None
    raw, low, high, log = parsed
    before = len(problems)
    values: list[AxisValue] = []
    if kind == "delay":
        for v in raw:
            text = str(v).strip().lower()
            if text not in ("0", "1", "true", "false", "0.0", "1.0"):
                problems.append(f"--vary delay: {v!r} is not 0 or 1")
                continue
            values.append(text in ("1", "true", "1.0"))
        if low is not None:
            problems.append("--vary delay: expected a list of 0 and 1")
    else:
        numbers = [_number(v, f"--vary {name}", problems) for v in raw]
        checked = [v for v in numbers if v is not None]
        values = list(checked)  # every value: one that is not a number is a problem (below)
        if low is not None and high is not None:
            checked += [low, high]
        for v in sorted(set(checked)):
            problem = None
            if kind == "parameter":
                problem = params[name].check(v)
                if problem:
                    problem = f"--vary {name}: {problem}"
            elif kind == "rate" and not v > 0:
                problem = f"--vary rate: {v:g} Hz is not a positive sample rate"
            elif kind in ("q", "r") and not v > 0:
                problem = f"--vary {name}: a Bryson scale must be > 0, got {v:g}"
            elif kind == "noise" and not v >= 0:
                problem = f"--vary noise: a noise scale must be >= 0, got {v:g}"
            if problem:
                problems.append(problem)
                break
    if len(problems) > before:
        return None
    if len(set(values)) != len(values):
        problems.append(f"--vary {name}: a value is given twice")
        return None
    return Axis(name, kind, tuple(values), low, high, log)


def _controller_axis(system: System, value: object, problems: list[str]) -> Axis | None:
    """The controllers' axis: a list of ``KIND`` or ``KIND:VALUE`` (:mod:`equilibrist.study.choice`;
    a value's ``:`` is not a range's), no two named alike in the table."""
    if isinstance(value, str):
        raw: list[object] = [t.strip() for t in value.split(",")]
    elif isinstance(value, (list, tuple)):
        raw = list(value)
    else:
        raw = [value]
    if not raw or not all(str(v).strip() for v in raw):
        problems.append(f"--vary controller={value}: expected a list of controllers "
                        "(lqr,lqg,policy:FILE)")
        return None
    before = len(problems)
    choices = [check_choice(system, v, "--vary controller", problems) for v in raw]
    if len(problems) > before:
        return None
    found = [c for c in choices if c is not None]
    labels = [c.label for c in found]
    for label in sorted({la for la in labels if labels.count(la) > 1}):
        same = [c.text for c in found if c.label == label]
        problems.append(f"--vary controller: '{quote_outside(label)}' is given twice"
                        + ("" if len(set(same)) == 1 else " (two files of one name: the table "
                           "names a file by its name, so give them different names)"))
    if len(problems) > before:
        return None
    return Axis("controller", "controller", tuple(c.text for c in found))


def _ranges(system: System, given: Mapping[str, object], option: str, problems: list[str], *,
            counted: bool) -> dict[str, tuple[float, ...]]:
    out: dict[str, tuple[float, ...]] = {}
    form = "LOW:HIGH:N" if counted else "LOW:HIGH"
    for name, value in given.items():
        if name not in system.state_names:
            problems.append(f"{option}: {system.key} has no state {name!r} "
                            f"({nearest(name, system.state_names)})")
            continue
        if isinstance(value, (list, tuple)):
            parts: list[object] = list(value)
        elif isinstance(value, (int, float)) and not isinstance(value, bool) and not counted:
            parts = [value, value]
        else:
            parts = [t.strip() for t in str(value).split(":")]
            if len(parts) == 1 and not counted:
                parts = parts * 2
        if len(parts) != (3 if counted else 2):
            problems.append(f"{option} {name}={value}: expected {form}")
            continue
        bounds = _low_high(parts, f"{option} {name}", f"{option} {name}={value}", problems,
                           counted=counted)
        if bounds is not None:
            lo, hi, n = bounds
            out[name] = (lo, hi, n) if n is not None else (lo, hi)
    if counted and out:
        cells = math.prod(int(v[2]) for v in out.values())
        if cells > MAX_ROA_STATES:
            grid = " x ".join(str(int(v[2])) for v in out.values())
            problems.append(f"{option}: a grid of {grid} = {cells} initial states per point; at "
                            f"most {MAX_ROA_STATES} (each is a run of every point)")
    return out
