"""Signalling a command while it works, for the tests of Ctrl-C and SIGTERM."""

from __future__ import annotations

import os
import select
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

#: Seconds from the signal to the command's end that count as "at once". Every signalled
#: command here has minutes of work left (or is held for good), so a bound far below that
#: tells a command that stops from one that runs on without guessing the machine's speed;
#: a loaded machine takes a few seconds to deliver the signal and unwind.
STOPS_WITHIN = 15.0


def cpu_seconds(pid: int) -> float:
    """User and system CPU time a process has used so far (from /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def start(argv: list[str], folder: Path) -> subprocess.Popen[bytes]:
    """``equilibrist ARGV`` in *folder*, stdout and stderr to pipes."""
    return subprocess.Popen([sys.executable, "-m", "equilibrist.cli.main", *argv],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=folder)


#: What a held command prints on stdout when it reaches the function it is held in.
HELD = b"held in "

# ``equilibrist ARGV`` (after the three words MODULE FUNCTION CALLS) with MODULE.FUNCTION
# replaced by one that lets its first CALLS calls through, then says so on stdout and waits
# for good: the command is stopped at a known point of its work, whatever the machine's
# speed. The command's own signal handlers are those it sets itself (main() with no
# arguments, as the console script runs it).
_HOLD = """\
import importlib, sys, time
module, name, calls = sys.argv[1], sys.argv[2], int(sys.argv[3])
del sys.argv[1:4]
owner = importlib.import_module(module)
original = getattr(owner, name)

def held(*args, **kwargs):
    global calls
    if calls > 0:
        calls -= 1
        return original(*args, **kwargs)
    print(f"held in {module}.{name}", flush=True)
    while True:
        time.sleep(3600)

setattr(owner, name, held)
from equilibrist.cli.main import main
sys.exit(main())
"""


def start_held(argv: list[str], folder: Path, at: str, *, after: int = 0) -> subprocess.Popen[bytes]:
    """``equilibrist ARGV`` in *folder* as :func:`start`, held for good where it calls *at*
    (``"module:function"``, looked up in the module when called) once *after* calls have
    run through: it prints :data:`HELD` and the name on stdout there (:func:`when_held`)."""
    module, _, name = at.partition(":")
    return subprocess.Popen([sys.executable, "-c", _HOLD, module, name, str(after), *argv],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=folder)


def when_held(proc: subprocess.Popen[bytes]) -> None:
    """Wait until a command of :func:`start_held` is held (its line on stdout); fails with
    its stderr if it ends first."""
    assert proc.stdout is not None
    for line in proc.stdout:
        if line.startswith(HELD):
            return
    raise AssertionError("the command ended before it was held: "
                         + (proc.stderr.read() if proc.stderr else b"").decode())


#: What a command of :func:`start_at_work` writes on its marks' pipe when its work begins.
AT_WORK = b"at work in "

# ``equilibrist ARGV`` (after the four words MODULE FUNCTION CALLS FD) with MODULE.FUNCTION
# replaced by one that, at its call CALLS + 1, writes a line on the pipe FD (neither stdout
# nor stderr, which the tests read whole), then lets that call and every other one through:
# the command runs unchanged, and the test knows when its work has begun, whatever the
# machine's speed.
_MARK = """\
import importlib, os, sys
module, name, calls, fd = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
del sys.argv[1:5]
owner = importlib.import_module(module)
original = getattr(owner, name)

def marked(*args, **kwargs):
    global calls
    if calls == 0:
        os.write(fd, f"at work in {module}.{name}\\n".encode())
        os.close(fd)
    calls -= 1
    return original(*args, **kwargs)

setattr(owner, name, marked)
from equilibrist.cli.main import main
sys.exit(main())
"""


def start_at_work(argv: list[str], folder: Path, at: str, *, after: int = 0,
                  cpu: float = 0.5) -> tuple[subprocess.Popen[bytes],
                                             Callable[[subprocess.Popen[bytes]], None]]:
    """``equilibrist ARGV`` in *folder* as :func:`start`, and the wait until it works: it has
    called *at* (``"module:function"``, looked up in the module when called; its call
    *after* + 1 counts) and used *cpu* seconds of CPU since. The command runs unchanged: the
    signal of :func:`signal_while_working` after this wait reaches the work itself, not the
    imports or the set-up before it, on any machine."""
    module, _, name = at.partition(":")
    marks, mark = os.pipe()
    try:
        proc = subprocess.Popen([sys.executable, "-c", _MARK, module, name, str(after), str(mark),
                                 *argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                cwd=folder, pass_fds=(mark,))
    except BaseException:
        os.close(marks)
        raise
    finally:
        os.close(mark)

    def ready(proc: subprocess.Popen[bytes]) -> None:
        # Its line, or the end of the pipe (the command ended), within the deadline of
        # after_cpu: a command that never calls *at* fails here, not after its minutes.
        with os.fdopen(marks, "rb") as pipe:
            called, _, _ = select.select([pipe], [], [], 120)
            line = pipe.readline() if called else b""
        if not called:
            raise AssertionError(f"the command did not call {at} within 120 s")
        if not line.startswith(AT_WORK):  # the pipe's end: the command ended
            raise AssertionError(f"the command ended before it called {at}: "
                                 + proc.communicate(timeout=60)[1].decode())
        after_cpu(cpu_seconds(proc.pid) + cpu)(proc)

    return proc, ready


def after_cpu(seconds: float) -> Callable[[subprocess.Popen[bytes]], None]:
    """Wait until the process has used *seconds* of CPU (it is working, past its start)."""

    def wait(proc: subprocess.Popen[bytes]) -> None:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if cpu_seconds(proc.pid) >= seconds:
                return
            time.sleep(0.05)

    return wait


def signal_while_working(proc: subprocess.Popen[bytes], signum: int,
                         ready: Callable[[subprocess.Popen[bytes]], None]) -> tuple[int, bytes, bytes, float]:
    """Send *signum* once *ready* returns with the process still running.

    Returns its exit status, stdout, stderr and the seconds from the signal
    to its end; the process is killed if anything fails on the way.
    """
    try:
        ready(proc)
        assert proc.poll() is None, "the command ended before it could be signalled: " + (
            proc.communicate()[1].decode())
        sent = time.monotonic()
        proc.send_signal(signum)
        out, err = proc.communicate(timeout=60)
        return proc.returncode, out, err, time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()  # reaps it and closes its pipes
