"""Hostile command lines of identify, sweep and export: one line, exit 2, nothing lost.

And a command that is signalled ends as a shell expects: 130 after Ctrl-C,
143 after SIGTERM, with its one line and nothing half-written.
"""

from __future__ import annotations

import signal

import pytest
from tests.support.signals import after_cpu, signal_while_working, start

# -- signals ---------------------------------------------------------------------------

SIGNALLED = {
    # show: about 2 s of CPU (the imports and the symbolic printing); signalled after 0.8 s.
    "show": (["show", "double_cartpole", "--latex"], 0.8),
    # sweep: 400 points of 2000 runs each, minutes of work.
    "sweep": (["sweep", "cartpole", "--vary", "m_p=0.2:2:400", "--runs", "2000",
               "--no-progress", "--out", "s.parquet"], 4.0),
    # export: a 40 s recorded run of the MPC, many seconds of solves.
    "export": (["export", "cartpole", "--controller", "mpc", "--duration", "40", "--out", "lib"],
               4.0),
}


@pytest.mark.parametrize("command", sorted(SIGNALLED))
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signalled_command_exits_130_or_143(tmp_path, command, signum) -> None:
    argv, cpu = SIGNALLED[command]
    code, _, err, took = signal_while_working(start(argv, tmp_path), signum, after_cpu(cpu))
    assert code == (143 if signum == signal.SIGTERM else 130), err.decode()
    assert "Traceback" not in err.decode()
    assert err.decode().strip().splitlines()[-1].startswith("equilibrist: interrupted")
    assert took < 10.0, f"took {took:.1f} s to stop"
    assert sorted(p.name for p in tmp_path.iterdir()) == []
