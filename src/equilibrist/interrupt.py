"""An interrupt that stays requested until the work stops.

Python turns a signal into an exception at the next bytecode of the main
thread. When that bytecode belongs to a finalizer (a ``__del__``, such as
the compiler's objects being collected while the simulation core loads),
the exception is printed as "ignored" and lost, and the command would run
on. So the command line's handlers of Ctrl-C and SIGTERM also record the
request here, and :func:`equilibrist.sim.run.call_interruptibly` (every
call of the compiled core from the main thread) raises it before and while
it waits: a signal that lands anywhere still stops the run. The command
line's ``sys.unraisablehook`` also keeps Python from printing such a
recorded interrupt as "Exception ignored" with a traceback, so the command
ends with its one line, "equilibrist: interrupted".
"""

from __future__ import annotations

import threading

_requested = threading.Event()


def request() -> None:
    """Record an interrupt (called from a signal handler)."""
    _requested.set()


def requested() -> bool:
    """Whether an interrupt was recorded and not yet raised or cleared."""
    return _requested.is_set()


def raise_if_requested() -> None:
    """Raise ``KeyboardInterrupt`` for a recorded interrupt (it stays recorded)."""
    if _requested.is_set():
        raise KeyboardInterrupt


def clear() -> None:
    """Forget a recorded interrupt (a new command starts)."""
    _requested.clear()


__all__ = ["clear", "raise_if_requested", "request", "requested"]
