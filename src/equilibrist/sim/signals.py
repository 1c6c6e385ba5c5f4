"""Signals of time: references for tracking, inputs for open-loop runs, excitations.

A signal is a frozen description; :meth:`evaluate` turns it into values at
given times, time-major ``(n_times, width)``. Values are absolute (in the
units of the tracked outputs, or of the inputs). Where a signal has a
"before" or "centre" value left as None, it is the operating point's value
(``base``), so a step of a cart's position from rest starts where the cart is
balanced.

The simulator samples a signal at the controller's instants and holds the
value for the control period (zero-order hold), as firmware reading a
set-point would.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from equilibrist.errors import DimensionError, SimulationError

Value = float | Sequence[float] | np.ndarray


def _vector(value: Value | None, base: np.ndarray, what: str) -> np.ndarray:
    """*value* as a vector of the signal's width (a scalar only for width 1)."""
    if value is None:
        return np.array(base, dtype=float)
    try:
        arr = np.atleast_1d(np.asarray(value, dtype=float)).reshape(-1)
    except (TypeError, ValueError):
        raise SimulationError(f"{what} {value!r} is not a number or a vector of numbers") from None
    if arr.size != base.size:
        raise DimensionError(f"{what} has {arr.size} values, expected {base.size}")
    if not np.all(np.isfinite(arr)):
        raise SimulationError(f"{what} is not finite: {arr.tolist()}")
    return arr


def _finite(value: float, what: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise SimulationError(f"{what} = {value!r} is not a number") from None
    if not math.isfinite(v):
        raise SimulationError(f"{what} = {value!r} is not a finite number")
    return v


@dataclass(frozen=True)
class Constant:
    """``r(t) = value`` (None: the operating point's value)."""

    value: Value | None = None

    def evaluate(self, times: np.ndarray, base: np.ndarray) -> np.ndarray:
        v = _vector(self.value, base, "the constant's value")
        return np.broadcast_to(v, (len(times), v.size)).copy()

    def describe(self) -> dict[str, object]:
        return {"kind": "constant", "value": _plain(self.value)}


@dataclass(frozen=True)
class Step:
    """``initial`` before ``at`` seconds, ``value`` from then on."""

    value: Value
    at: float = 0.0
    initial: Value | None = None

    def evaluate(self, times: np.ndarray, base: np.ndarray) -> np.ndarray:
        at = _finite(self.at, "the step's time")
        before = _vector(self.initial, base, "the step's initial value")
        after = _vector(self.value, base, "the step's value")
        return np.where((np.asarray(times) >= at)[:, None], after, before)

    def describe(self) -> dict[str, object]:
        return {"kind": "step", "value": _plain(self.value), "at": self.at,
                "initial": _plain(self.initial)}


@dataclass(frozen=True)
class Ramp:
    """``initial`` until ``start``, then rising at ``slope`` per second."""

    slope: Value
    start: float = 0.0
    initial: Value | None = None

    def evaluate(self, times: np.ndarray, base: np.ndarray) -> np.ndarray:
        start = _finite(self.start, "the ramp's start")
        v0 = _vector(self.initial, base, "the ramp's initial value")
        slope = _vector(self.slope, base, "the ramp's slope")
        elapsed = np.maximum(np.asarray(times, dtype=float) - start, 0.0)
        out: np.ndarray = v0 + elapsed[:, None] * slope
        return out

    def describe(self) -> dict[str, object]:
        return {"kind": "ramp", "slope": _plain(self.slope), "start": self.start,
                "initial": _plain(self.initial)}


@dataclass(frozen=True)
class Square:
    """``centre + amplitude`` for the first half of each ``period``, ``centre - amplitude`` after.

    Before ``start`` the signal is ``centre``.
    """

    amplitude: Value
    period: float
    centre: Value | None = None
    start: float = 0.0

    def evaluate(self, times: np.ndarray, base: np.ndarray) -> np.ndarray:
        period = _finite(self.period, "the square wave's period")
        if period <= 0:
            raise SimulationError(f"the square wave's period must be positive, got {period:g} s")
        start = _finite(self.start, "the square wave's start")
        centre = _vector(self.centre, base, "the square wave's centre")
        amp = _vector(self.amplitude, base, "the square wave's amplitude")
        t = np.asarray(times, dtype=float) - start
        phase = np.mod(t, period) < period / 2
        sign = np.where(phase, 1.0, -1.0)
        sign = np.where(t < 0, 0.0, sign)
        out: np.ndarray = centre + sign[:, None] * amp
        return out

    def describe(self) -> dict[str, object]:
        return {"kind": "square", "amplitude": _plain(self.amplitude), "period": self.period,
                "centre": _plain(self.centre), "start": self.start}


@dataclass(frozen=True, eq=False)
class Samples:
    """Values given at times, interpolated linearly between them and held beyond both ends."""

    times: np.ndarray
    values: np.ndarray
    source: str = ""

    def __post_init__(self) -> None:
        t = np.asarray(self.times, dtype=float).reshape(-1)
        v = np.asarray(self.values, dtype=float)
        if v.ndim == 1:
            v = v[:, None]
        problems = []
        if t.size == 0:
            problems.append("no samples")
        if v.shape[0] != t.size:
            problems.append(f"{t.size} times but {v.shape[0]} rows of values")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(v))):
            problems.append("a time or value that is not a finite number")
        if t.size > 1 and np.any(np.diff(t) <= 0):
            problems.append("times that do not increase")
        if problems:
            where = f" in {self.source}" if self.source else ""
            raise SimulationError(f"reference samples{where}: " + "; ".join(problems))
        t.setflags(write=False)
        v.setflags(write=False)
        object.__setattr__(self, "times", t)
        object.__setattr__(self, "values", v)

    @classmethod
    def from_file(cls, path: str | Path) -> Samples:
        """Read ``time, value[, value...]`` rows from a CSV file (a header line is
        skipped) or the ``times`` and ``values`` arrays of an ``.npz`` file."""
        p = Path(path)
        if not p.exists():
            raise SimulationError(f"reference file {p} does not exist")
        if p.suffix == ".npz":
            with np.load(p) as data:
                if "times" not in data or "values" not in data:
                    raise SimulationError(f"{p} needs arrays 'times' and 'values'")
                return cls(data["times"], data["values"], source=str(p))
        text = p.read_text(errors="replace")
        # Commas, or else white space, separate the columns.
        delimiter = "," if "," in text else None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # genfromtxt warns about an empty file
                rows = np.genfromtxt(p, delimiter=delimiter, comments="#", dtype=float)
        except ValueError as exc:
            raise SimulationError(f"cannot read reference samples from {p}: {exc}") from None
        rows = np.atleast_2d(rows)
        if rows.size and np.all(np.isnan(rows[0])):
            rows = rows[1:]  # a header line
        if rows.ndim != 2 or rows.shape[0] == 0 or rows.shape[1] < 2:
            raise SimulationError(
                f"{p}: expected rows of 'time, value' (separated by commas or spaces)"
            )
        return cls(rows[:, 0], rows[:, 1:], source=str(p))

    def evaluate(self, times: np.ndarray, base: np.ndarray) -> np.ndarray:
        if self.values.shape[1] != base.size:
            raise DimensionError(
                f"reference samples have {self.values.shape[1]} columns, expected {base.size}"
            )
        t = np.asarray(times, dtype=float)
        return np.column_stack(
            [np.interp(t, self.times, self.values[:, j]) for j in range(base.size)]
        )

    def describe(self) -> dict[str, object]:
        return {"kind": "samples", "source": self.source, "count": int(self.times.size)}


@dataclass(frozen=True, eq=False)
class Function:
    """``r(t) = fn(t)`` for a Python function of time (scalar or vector values)."""

    fn: Callable[[float], Value]

    def evaluate(self, times: np.ndarray, base: np.ndarray) -> np.ndarray:
        out = np.empty((len(times), base.size))
        for i, t in enumerate(np.asarray(times, dtype=float)):
            out[i] = _vector(self.fn(float(t)), base, f"the signal's value at t = {t:g} s")
        return out

    def describe(self) -> dict[str, object]:
        return {"kind": "function", "name": getattr(self.fn, "__name__", repr(self.fn))}


def _amplitude(value: Value, width: int, what: str) -> np.ndarray:
    """An amplitude for every channel: one value for all, or one per channel."""
    arr = np.atleast_1d(np.asarray(value, dtype=float)).reshape(-1)
    if arr.size == 1:
        arr = np.full(width, float(arr[0]))
    if arr.size != width:
        raise DimensionError(f"{what} has {arr.size} values, expected 1 or {width}")
    if not np.all(np.isfinite(arr)):
        raise SimulationError(f"{what} is not finite: {arr.tolist()}")
    return arr


@dataclass(frozen=True)
class Chirp:
    """A linear frequency sweep: ``centre + amplitude sin(2 pi (f0 t + (f1 - f0) t^2 / (2 T)))``.

    The frequency rises linearly from ``f0`` to ``f1`` [Hz] over ``sweep``
    seconds from ``start`` (default: up to the last time asked for), and
    stays at ``f1`` after. The signal starts at zero phase, so it starts
    at ``centre`` without a jump. As an excitation (``centre`` None is
    zero there) it is added to the controller's command.
    """

    amplitude: Value
    f0: float
    f1: float
    sweep: float | None = None
    start: float = 0.0
    centre: Value | None = None

    def evaluate(self, times: np.ndarray, base: np.ndarray) -> np.ndarray:
        f0 = _finite(self.f0, "the chirp's start frequency")
        f1 = _finite(self.f1, "the chirp's end frequency")
        if f0 < 0 or f1 < 0:
            raise SimulationError(f"the chirp's frequencies must be >= 0 Hz, got {f0:g} and {f1:g}")
        start = _finite(self.start, "the chirp's start")
        centre = _vector(self.centre, base, "the chirp's centre")
        amp = _amplitude(self.amplitude, base.size, "the chirp's amplitude")
        t = np.asarray(times, dtype=float) - start
        span = float(t[-1]) if self.sweep is None and t.size else _finite(self.sweep or 0.0, "the sweep")
        if span <= 0:
            span = 1.0
        tc = np.clip(t, 0.0, span)
        phase = f0 * tc + (f1 - f0) * tc**2 / (2.0 * span) + f1 * np.maximum(t - span, 0.0)
        # The project's sine (equilibrist.numeric.libm), not numpy's, whose kernel the CPU
        # selects: the excitation decides the trajectory, so it is the same bits everywhere.
        from equilibrist.numeric.libm import eq_sin

        arg = (2.0 * np.pi * phase).tolist()
        sines = np.fromiter((eq_sin(a) for a in arg), dtype=float, count=len(arg))
        value = np.where(t < 0, 0.0, sines)
        out: np.ndarray = centre + value[:, None] * amp
        return out

    def describe(self) -> dict[str, object]:
        return {"kind": "chirp", "amplitude": _plain(self.amplitude), "f0": self.f0, "f1": self.f1,
                "sweep": self.sweep, "start": self.start, "centre": _plain(self.centre)}


# Feedback taps of the maximal-length shift register x^11 + x^9 + 1 (period 2047).
PRBS_ORDER = 11
PRBS_TAPS = (11, 9)


@dataclass(frozen=True)
class PRBS:
    """A pseudo-random binary sequence: ``centre +- amplitude``, held for ``period`` seconds.

    The bits come from an 11-bit maximal-length shift register
    (``x^11 + x^9 + 1``, period 2047 bits) started from a state given by
    ``seed``, so a seed fixes the sequence. Its spectrum is flat up to
    about ``0.44 / period`` Hz. Before ``start`` the signal is ``centre``.
    """

    amplitude: Value
    period: float
    seed: int = 0
    start: float = 0.0
    centre: Value | None = None

    def bits(self, count: int) -> np.ndarray:
        """The first *count* bits (0 or 1) of the sequence."""
        state = (int(self.seed) * 2654435761 + 1) % (2**PRBS_ORDER - 1) + 1  # never all zero
        out = np.empty(count, dtype=np.int8)
        a, b = PRBS_TAPS
        for i in range(count):
            out[i] = state & 1
            fb = ((state >> (PRBS_ORDER - a)) ^ (state >> (PRBS_ORDER - b))) & 1
            state = (state >> 1) | (fb << (PRBS_ORDER - 1))
        return out

    def evaluate(self, times: np.ndarray, base: np.ndarray) -> np.ndarray:
        period = _finite(self.period, "the PRBS period")
        if period <= 0:
            raise SimulationError(f"the PRBS period must be positive, got {period:g} s")
        start = _finite(self.start, "the PRBS start")
        centre = _vector(self.centre, base, "the PRBS centre")
        amp = _amplitude(self.amplitude, base.size, "the PRBS amplitude")
        t = np.asarray(times, dtype=float) - start
        index = np.floor(np.maximum(t, 0.0) / period + 1e-9).astype(np.int64)
        bits = self.bits(int(index.max()) + 1 if index.size else 0)
        sign = np.where(t < 0, 0.0, 2.0 * bits[index] - 1.0) if index.size else np.zeros(0)
        out: np.ndarray = centre + sign[:, None] * amp
        return out

    def describe(self) -> dict[str, object]:
        return {"kind": "prbs", "amplitude": _plain(self.amplitude), "period": self.period,
                "seed": self.seed, "start": self.start, "centre": _plain(self.centre)}


def parse_excitation(text: str, *, seed: int = 0) -> Chirp | PRBS:
    """Parse the command line's excitation syntax.

    ``chirp:AMPLITUDE:F0:F1[:SWEEP]`` (a sweep from F0 to F1 Hz over SWEEP
    seconds, default the whole run) or ``prbs:AMPLITUDE:PERIOD`` (a
    pseudo-random binary sequence switching at most every PERIOD seconds,
    its bits fixed by *seed*). AMPLITUDE is in the input's unit.
    """
    kind, _, rest = text.partition(":")
    parts = rest.split(":") if rest else []
    try:
        values = [float(v) for v in parts]
        sig: Chirp | PRBS
        if kind == "chirp" and len(parts) in (3, 4):
            sweep = values[3] if len(parts) == 4 else None
            sig = Chirp(values[0], values[1], values[2], sweep=sweep)
        elif kind == "prbs" and len(parts) == 2:
            sig = PRBS(values[0], values[1], seed=seed)
        else:
            raise ValueError
    except ValueError:
        raise SimulationError(
            f"excitation {text!r}: expected chirp:AMPLITUDE:F0:F1[:SWEEP] or prbs:AMPLITUDE:PERIOD"
        ) from None
    if not all(math.isfinite(v) for v in values):
        raise SimulationError(f"excitation {text!r}: the values must be finite numbers")
    if isinstance(sig, Chirp) and (sig.f0 < 0 or sig.f1 < 0 or (sig.sweep is not None and sig.sweep <= 0)):
        raise SimulationError(f"excitation {text!r}: frequencies must be >= 0 Hz and the sweep > 0 s")
    if isinstance(sig, PRBS) and sig.period <= 0:
        raise SimulationError(f"excitation {text!r}: the period must be positive")
    return sig


Signal = Constant | Step | Ramp | Square | Samples | Function | Chirp | PRBS


def as_signal(value: object) -> Signal:
    """A signal from a signal, a Python function of time, or a constant."""
    if isinstance(value, Constant | Step | Ramp | Square | Samples | Function | Chirp | PRBS):
        return value
    if callable(value):
        return Function(value)
    if isinstance(value, str | bytes):
        raise SimulationError(
            f"signal {value!r}: text is not a signal; give a number, a vector, a signal "
            "(Step, Ramp, Square, Samples, Chirp, PRBS), a function of time, or parse the "
            "command line's syntax with parse_signal"
        )
    return Constant(value)  # type: ignore[arg-type]


def parse_signal(text: str) -> Signal:
    """Parse the command line's reference syntax.

    ``step:VALUE[@TIME]``, ``ramp:SLOPE[@START]``, ``square:AMPLITUDE:PERIOD``,
    ``file:PATH`` (CSV of ``time,value``), or a bare number (a step at 0).
    """
    kind, _, rest = text.partition(":")
    try:
        if not rest:
            return Step(float(kind))
        if kind == "step":
            value, _, at = rest.partition("@")
            return Step(float(value), at=float(at) if at else 0.0)
        if kind == "ramp":
            slope, _, start = rest.partition("@")
            return Ramp(float(slope), start=float(start) if start else 0.0)
        if kind == "square":
            amp, _, period = rest.partition(":")
            return Square(float(amp), float(period))
        if kind == "file":
            return Samples.from_file(rest)
    except SimulationError:
        raise  # the file's own problem, said precisely
    except ValueError:
        pass
    raise SimulationError(
        f"reference {text!r}: expected step:VALUE[@TIME], ramp:SLOPE[@START], "
        "square:AMPLITUDE:PERIOD, file:PATH or a number"
    )


def _plain(value: object) -> object:
    if value is None:
        return None
    arr = np.asarray(value, dtype=float)
    return arr.tolist()
