"""The bounds of the work a run or a batch may ask for: its physics steps and its
memory, checked before anything is allocated or run."""

from __future__ import annotations

import math
import os

import numpy as np

from equilibrist.errors import SimulationError

# Fraction of the available memory a run or batch may take.
MEMORY_FRACTION = 0.5
# The most physics steps a run (or a batch, over all its runs) may take
# unless asked for more (``max_steps=``, the commands' ``--max-steps``): some minutes of
# work on a fast machine, hours on a slow one. A mistyped physics step
# (1e-12 s) asks for a million times more and is refused before anything runs.
DEFAULT_MAX_STEPS = 10_000_000_000
# A generous speed of the compiled core per core [physics steps per second]:
# the time a refused request would take is stated as at least this long.
FAST_STEPS_PER_SECOND = 1e8


def _fmt_seconds(s: float) -> str:
    for unit, size in (("years", 365.25 * 86400), ("days", 86400), ("hours", 3600), ("minutes", 60)):
        if s >= 2 * size:
            return f"{s / size:.3g} {unit}"
    return f"{s:.3g} s"


#: What a refused run or batch is told to do (``{steps}``: the steps it asks for, rounded
#: up): the options of ``simulate`` and ``batch``, and the keyword of their functions.
ADVICE = ("use a larger physics step, a shorter duration or fewer runs, or ask for it anyway "
          "with --max-steps {steps} (max_steps={steps} in Python)")


def check_steps(steps: float, what: str, max_steps: float | None, threads: int = 1, *,
                advice: str = ADVICE) -> str | None:
    """The problem with a run or batch of *steps* physics steps, if more than *max_steps*,
    ending with *advice* (a command without ``--max-steps`` names its own options).

    ``max_steps=None`` (or infinite) sets no bound.
    """
    if max_steps is None or steps <= max_steps:
        return None
    at_least = steps / (FAST_STEPS_PER_SECOND * max(1, threads))
    return (
        f"{what} asks for {steps:.3g} physics steps, more than the {max_steps:.3g} allowed "
        f"(it would take at least {_fmt_seconds(at_least)} at "
        f"{FAST_STEPS_PER_SECOND / 1e6:.0f} M steps/s per core): "
        + advice.format(steps=_enough(steps))
    )


def _enough(n: float) -> str:
    """*n* in three significant digits, rounded up: a bound of that many steps allows it."""
    text = f"{n:.3g}"
    if float(text) < n:
        unit = 10.0 ** (math.floor(math.log10(n)) - 2)
        text = f"{(math.floor(n / unit) + 1) * unit:.3g}"
    return text


def check_max_steps(value: object) -> float | None:
    """*value* as a bound on physics steps (None or inf: no bound)."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise SimulationError(f"max_steps = {value!r}: expected a number of physics steps >= 1 "
                              "(or None for no bound)")
    v = float(value)
    if math.isnan(v) or v < 1:
        raise SimulationError(f"max_steps = {value!r}: expected a number of physics steps >= 1 "
                              "(or None for no bound)")
    return None if math.isinf(v) else v


def available_memory() -> int:
    """Bytes of memory available now (``MemAvailable``; 4 GiB if unknown)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:  # pragma: no cover - not Linux
        pass
    try:  # pragma: no cover - not Linux
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover
        return 4 << 30


def _fmt_bytes(n: float) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"  # pragma: no cover


def check_memory(n_bytes: float, what: str, limit: float | None) -> None:
    """Refuse (before allocating) a job that needs more than *limit* bytes."""
    if limit is None and n_bytes < 64 << 20:
        return  # small enough anywhere; spares reading /proc on every run
    cap = MEMORY_FRACTION * available_memory() if limit is None else float(limit)
    if n_bytes > cap:
        raise SimulationError(
            f"{what} needs {_fmt_bytes(n_bytes)} of memory, more than the "
            f"{_fmt_bytes(cap)} allowed (half the available memory): "
            "shorten it, lower the rate, or run fewer at once"
        )
