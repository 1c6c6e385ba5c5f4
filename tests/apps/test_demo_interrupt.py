"""Ctrl-C during the demo's first compile stops it at once, its worker processes with it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from tests.support.signals import STOPS_WITHIN, signal_while_working

from equilibrist.native import build


def _children(pid: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                found.append(int(entry.name))
    return found


def _name(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/comm").read_text().strip()
    except OSError:
        return ""


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_ctrl_c_while_the_workers_compile_ends_the_demo_and_its_workers(tmp_path: Path) -> None:
    env = {**os.environ, "EQUILIBRIST_CACHE": str(tmp_path / "cache")}  # nothing compiled yet
    proc = subprocess.Popen([sys.executable, "-m", "equilibrist.cli.main", "demo", "--out",
                             str(tmp_path / "report")], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=tmp_path, env=env)
    workers: list[int] = []
    # The compiler the workers run, as /proc names its process (15 characters at most).
    compiler = Path(build.compiler()[0]).name[:15]

    def compiling(p: subprocess.Popen[bytes]) -> None:
        # Both workers started and one of them running the C compiler on a core.
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and p.poll() is None:
            workers[:] = [c for c in _children(p.pid) if _alive(c)]
            if len(workers) >= 2 and any(_name(c) == compiler for w in workers
                                         for c in _children(w)):
                return
            time.sleep(0.05)

    code, _, err, took = signal_while_working(proc, signal.SIGINT, compiling)
    assert code == 130, err.decode()
    assert err.decode().strip().splitlines()[-1] == "equilibrist: interrupted"
    assert took < STOPS_WITHIN, f"took {took:.1f} s to stop"
    assert workers, "the demo started no worker processes"
    time.sleep(0.5)
    assert not [w for w in workers if _alive(w)], "worker processes outlived the demo"
    assert not (tmp_path / "report").exists()
