"""After an interrupt stops a process pool at once, the command's last line is still
"equilibrist: interrupted": multiprocessing's resource tracker cleans up the pool's semaphores
without reporting them (equilibrist.interrupt.quiet_resource_tracker)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import time

CHILD = textwrap.dedent("""
    import multiprocessing, os, sys
    if sys.argv[1] == "quiet":
        from equilibrist.interrupt import quiet_resource_tracker
        quiet_resource_tracker()
    locks = [multiprocessing.get_context("spawn").Lock() for _ in range(3)]
    print("equilibrist: interrupted", file=sys.stderr, flush=True)
    os._exit(130)  # as the command ends after an interrupt: nothing is finalized
""")


def _stderr(mode: str) -> str:
    proc = subprocess.run([sys.executable, "-c", CHILD, mode], capture_output=True, text=True,
                          timeout=60, check=False)
    assert proc.returncode == 130
    time.sleep(0.5)  # the tracker writes when its pipe closes, possibly after the child
    return proc.stderr


def test_the_leak_report_is_what_it_quiets_and_it_is_quiet() -> None:
    assert "leaked semaphore" in _stderr("loud")  # the report exists, so the test can fail
    quiet = _stderr("quiet")
    assert quiet.strip().splitlines() == ["equilibrist: interrupted"], quiet
