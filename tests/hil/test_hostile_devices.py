"""A device that says hostile things: its text printed escaped, its NaNs refused, in one line.

The devices are tests/support/hil.py's Python device, each with one frame changed on its
way out: an error frame whose text would retitle and clear a terminal, a command that is
NaN or infinite, a hello whose rate is NaN. The truths are the protocol's rules
(docs/hil.md): a start that cannot be made is exit status 2 and writes nothing, a fault
during the run is exit status 1 and keeps the run so far, each in one line.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path

import pytest

from equilibrist.cli.main import main
from equilibrist.errors import quote_outside
from equilibrist.hil import protocol as proto
from equilibrist.sim import SimResult
from support.hil import FakeDevice, pty_link

# What a hostile device sends as its error text: set the terminal's title, ring, clear the
# screen, go back to the start of the line, and turn the rest of it around.
HOSTILE = b"\x1b]0;PWNED\x07\x1b[2J\rgone \xe2\x80\xaeevil"
RAW = ("\x1b", "\x07", "\r", "\u202e")


class HostileDevice(FakeDevice):
    """The fake device, answering every step with a zero command, except as *change* says:
    ``"refuse hello"`` (an error frame for the hello), ``"refuse step"`` (an error frame for
    the step after *after*), ``"nan"``/``"inf"`` (that command for the steps after *after*),
    ``"nan rate"`` (a hello answer whose rate is NaN)."""

    def __init__(self, path: str, change: str, *, after: int = 0) -> None:
        super().__init__(path, good=10**9, fault="silent")
        self.change = change
        self.after = after

    def _send(self, kind: int, seq: int, payload: bytes = b"") -> None:
        if kind == proto.HELLO_REPLY and self.change == "refuse hello":
            kind, payload = proto.ERROR, HOSTILE
        elif kind == proto.HELLO_REPLY and self.change == "nan rate":
            hello = proto.Hello.unpack(payload)
            payload = proto.Hello(**{**hello.__dict__, "rate": math.nan}).pack()
        elif kind == proto.STEP_REPLY and self.steps > self.after:
            if self.change == "refuse step":
                kind, payload = proto.ERROR, HOSTILE
            elif self.change in ("nan", "inf"):
                value = math.nan if self.change == "nan" else -math.inf
                payload = struct.pack("<f", value) + payload[4:]  # cartpole: one input
        super()._send(kind, seq, payload)


def _run(change: str, out: Path, capsys: pytest.CaptureFixture[str], *,
         after: int = 0) -> tuple[int, str, str]:
    with pty_link() as link:
        device = HostileDevice(link.paths[0], change, after=after)
        device.start()
        try:
            status = main(["hil", "cartpole", "--port", link.paths[1], "--controller", "lqr",
                           "--duration", "1", "--timeout", "0.5", "--out", str(out)])
        finally:
            device.stop()
    got = capsys.readouterr()
    return status, got.out, got.err


def _one_escaped_line(err: str) -> str:
    assert not any(c in err for c in RAW), repr(err)
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    # The device's text is there, each control character as its escape.
    assert "\\x1b]0;PWNED\\x07\\x1b[2J\\rgone \\u202eevil" in err, err
    return err


def test_an_error_frame_for_the_hello_is_printed_escaped(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    status, _, err = _run("refuse hello", tmp_path / "run.npz", capsys)
    assert status == 2
    assert "refused the hello" in _one_escaped_line(err)
    assert not (tmp_path / "run.npz").exists()


def test_an_error_frame_during_the_run_is_printed_escaped(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    status, _, err = _run("refuse step", tmp_path / "run.npz", capsys, after=5)
    assert status == 1
    assert "refused a step" in _one_escaped_line(err)
    assert SimResult.load(tmp_path / "run.npz").n_rows == 5  # the samples answered before


def test_a_nan_command_at_the_first_sample_is_a_fault_and_writes_nothing(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    status, out, err = _run("nan", tmp_path / "run.npz", capsys)
    assert status == 1, err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert "not finite" in err and "nothing was saved" in err
    assert not list(tmp_path.iterdir())  # no run, no temporary
    assert "ended before its first sample" in out


def test_an_infinite_command_later_is_a_fault_that_keeps_the_run_so_far(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    status, _, err = _run("inf", tmp_path / "run.npz", capsys, after=7)
    assert status == 1, err
    assert len(err.strip().splitlines()) == 1 and "not finite ([-inf])" in err, err
    run = SimResult.load(tmp_path / "run.npz")
    assert run.n_rows == 7
    assert all(math.isfinite(v) for v in run.applied.ravel())


def test_a_hello_with_a_nan_rate_is_refused_as_another_rate_is(tmp_path: Path,
                                                              capsys: pytest.CaptureFixture[str]) -> None:
    status, _, err = _run("nan rate", tmp_path / "run.npz", capsys)
    assert status == 2
    assert len(err.strip().splitlines()) == 1, err
    assert "runs another controller: it has a rate of nan Hz" in err
    assert not (tmp_path / "run.npz").exists()


def test_quote_outside_shows_every_control_character_and_bounds_the_length() -> None:
    assert quote_outside("\x1b[2J\x07\r\n\t\x7f\x85\x9b") == "\\x1b[2J\\x07\\r\\n\\t\\x7f\\x85\\x9b"
    # The bidi overrides and isolates, a zero-width joiner, the line separator, a lone surrogate.
    assert quote_outside("a\u202eb\u2066c\u200dd\u2028e\udcff") == \
        "a\\u202eb\\u2066c\\u200dd\\u2028e\\udcff"
    assert quote_outside("Zürich 10 µs — ok \\x1b") == "Zürich 10 µs — ok \\x1b"  # as it is
    assert quote_outside("\x1b" * 10) == quote_outside(quote_outside("\x1b" * 10))
    assert quote_outside("a" * 500, limit=20) == "a" * 20 + "..."
    assert quote_outside("\x1b" * 500, limit=10) == "\\x1b\\x1b..."  # no escape cut in two
    assert quote_outside("a" * 20, limit=20) == "a" * 20


def test_the_error_printer_escapes_what_reached_a_message_raw(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The last line of defence: a message that carries outside text unquoted (here the port's
    path, as given) is still printed with its control characters escaped, in one line."""
    port = str(tmp_path / "x\x1b]0;PWNED\x07y\rz")
    assert main(["hil", "cartpole", "--port", port]) == 2
    err = capsys.readouterr().err
    assert not any(c in err for c in RAW), repr(err)
    assert "x\\x1b]0;PWNED\\x07y\\rz: no such device" in err
    assert main(["hil", "cartpole", "--port", str(tmp_path / "two\nlines")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "two lines: no such device" in err
