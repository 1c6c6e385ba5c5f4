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


#: multiprocessing's resource tracker reports, when the command ends, the semaphores of a
#: process pool whose workers an interrupt stopped at once: it removes them itself, and its
#: message would follow "equilibrist: interrupted" on the terminal.
_TRACKER_QUIET = "ignore::UserWarning:multiprocessing.resource_tracker"


def quiet_resource_tracker() -> None:
    """Start multiprocessing's resource tracker without its leaked-resource warnings (call
    it before making a process pool). The tracker is a separate interpreter, started once
    per process; it reads ``PYTHONWARNINGS``, which is set only for that start."""
    import os
    from multiprocessing import resource_tracker

    if getattr(resource_tracker._resource_tracker, "_pid", None) is not None:
        return  # already running
    before = os.environ.get("PYTHONWARNINGS")
    os.environ["PYTHONWARNINGS"] = _TRACKER_QUIET if not before else f"{before},{_TRACKER_QUIET}"
    try:
        resource_tracker.ensure_running()
    finally:
        if before is None:
            os.environ.pop("PYTHONWARNINGS", None)
        else:
            os.environ["PYTHONWARNINGS"] = before
