"""Signalling a command while it works, for the tests of Ctrl-C and SIGTERM."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path


def cpu_seconds(pid: int) -> float:
    """User and system CPU time a process has used so far (from /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def start(argv: list[str], folder: Path) -> subprocess.Popen[bytes]:
    """``equilibrist ARGV`` in *folder*, stdout and stderr to pipes."""
    return subprocess.Popen([sys.executable, "-m", "equilibrist.cli.main", *argv],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=folder)


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
