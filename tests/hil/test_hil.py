"""Hardware in the loop over a pseudo-terminal: the exported C as a host program, and faults.

The truth for a lockstep run is ``equilibrist simulate`` of the same
controller: the device (the export's own C, built by ``make hil-host``)
must give the same run to the payload's rounding. Faults come from a device
written in Python that misbehaves as asked (tests/support/hil.py).
"""

from __future__ import annotations

import contextlib
import io
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from equilibrist.cli.main import main
from equilibrist.hil import protocol as proto
from equilibrist.native.firmware import RT_PRIORITY
from equilibrist.sim import SimResult
from support import cc_cache, require
from support.hil import FakeDevice, host_on_link, pty_link

CLI = [sys.executable, "-m", "equilibrist.cli.main"]


def _cli(*argv: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    return subprocess.run([*CLI, *argv], capture_output=True, text=True, timeout=timeout, check=False)


# -- the protocol -------------------------------------------------------------------------
def test_crc_is_crc16_xmodem() -> None:
    assert proto.crc16(b"123456789") == 0x31C3  # the catalogue check value of CRC-16/XMODEM
    assert proto.crc16(b"") == 0


def test_frames_survive_noise_splits_and_a_broken_frame() -> None:
    a = proto.frame(proto.STEP, 7, b"\x01\x02\x03")
    b = proto.frame(proto.RESET, 8)
    broken = bytearray(proto.frame(proto.STEP, 9, b"xyz"))
    broken[-2] ^= 0x55
    reader = proto.FrameReader()
    stream = b"\x00\xeb\xffjunk" + a + b
    got = []
    for i in range(0, len(stream), 3):  # fed in small pieces
        got += reader.feed(stream[i : i + 3])
    assert [(f.kind, f.seq, f.payload) for f in got] == [(proto.STEP, 7, b"\x01\x02\x03"),
                                                          (proto.RESET, 8, b"")]
    with pytest.raises(proto.ProtocolError, match="bad CRC"):
        reader.feed(bytes(broken))
    assert [f.seq for f in reader.feed(a)] == [7]  # reading goes on after it


def test_hello_names_what_differs() -> None:
    host = proto.Hello(4, 4, 1, 2, 0, 0, 200.0, "418b195560fb")
    assert host.mismatch(proto.Hello.unpack(host.pack())) is None
    other = proto.Hello(4, 4, 1, 3, 0, 0, 200.0, "418b195560fb")
    assert host.mismatch(other) == "3 measured outputs, expected 2"
    assert "controller '0123'" in str(host.mismatch(proto.Hello(4, 4, 1, 2, 0, 0, 200.0, "0123")))
    assert "float64 payloads" in str(host.mismatch(proto.Hello(8, 4, 1, 2, 0, 0, 200.0, "x")))


# -- lockstep against simulate, for every controller kind -------------------------------------
KINDS = {
    "lqr": ("--duration", "2", "--x0", "theta=0.1"),
    "lqg": ("--duration", "2", "--x0", "theta=0.1", "--push", "1:40"),
    "swingup": ("--duration", "4", "--x0", "theta=3.1"),
    "mpc": ("--duration", "1", "--x0", "x=0.5"),
}


@pytest.fixture(scope="module")
def exports(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    require("cc")
    require("make")
    root = tmp_path_factory.mktemp("hil_exports")
    out = {}
    for kind in KINDS:
        folder = root / kind
        # The export's command in this process (its output, not its process, is tested here);
        # the MPC's DAQP sources compile once a run (support.cc_cache), for its measurement
        # (make size) as for make hil-host.
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()), \
                cc_cache.cached_measure(cc_cache.folder(tmp_path_factory)):
            code = main(["export", "cartpole", "--controller", kind, "--out", str(folder),
                         "--duration", "0.5"])
        assert code == 0, err.getvalue()
        made = subprocess.run(["make", "-s", "-C", str(folder), "hil-host"], capture_output=True, text=True,
                              check=False, env=cc_cache.environment(cc_cache.folder(tmp_path_factory)))
        assert made.returncode == 0, made.stderr
        out[kind] = folder
    return out


def _hil(folder: Path, *argv: str) -> subprocess.CompletedProcess[str]:
    with host_on_link(folder / "hil_host") as port:
        return _cli("hil", "cartpole", "--port", port, *argv)


@pytest.mark.slow
@pytest.mark.parametrize("kind", list(KINDS))
def test_lockstep_equals_simulate(kind: str, exports: dict[str, Path], tmp_path: Path,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    args = KINDS[kind]
    assert main(["simulate", "cartpole", "--controller", kind, "--out", str(tmp_path / "sim.npz"),
                 *args]) == 0
    b = SimResult.load(tmp_path / "sim.npz")
    for payload, tolerance in (("float32", 1e-4), ("float64", 1e-9)):
        capsys.readouterr()
        with host_on_link(exports[kind] / "hil_host") as port:
            status = main(["hil", "cartpole", "--port", port, "--controller", kind,
                           "--payload", payload, "--out", str(tmp_path / "hil.npz"), "--json",
                           *args])
        out = capsys.readouterr()
        assert status == 0, out.err
        figures = json.loads(out.out)
        a = SimResult.load(tmp_path / "hil.npz")
        assert a.states.shape == b.states.shape
        for name in ("states", "applied"):
            x, y = getattr(a, name), getattr(b, name)
            scale = np.max(np.abs(y), axis=0)
            assert np.all(np.abs(x - y) <= tolerance * scale + 1e-300), (
                payload, name, np.max(np.abs(x - y) / scale))
        assert figures["late"] == 0 and figures["lost"] == 0 and figures["fault"] is None
        assert figures["steps"] == b.n_rows
        assert figures["payload"] == payload
        assert figures["round_trip_ms"]["p50"] > 0 and figures["device_step_us"]["max"] is not None
        # The saved run records both sides: the device's answers beside the plant.
        assert a.settings["hil"]["controller_id"] == figures["controller_id"]


@pytest.mark.slow
def test_realtime_at_200_hz_reports_its_figures(exports: dict[str, Path], tmp_path: Path) -> None:
    done = _hil(exports["lqg"], "--mode", "realtime", "--duration", "2", "--x0", "theta=0.05",
                   "--json", "--out", str(tmp_path / "rt.csv"))
    assert done.returncode == 0, done.stderr
    fig = json.loads(done.stdout)
    assert fig["mode"] == "realtime" and fig["steps"] == 401 and fig["fault"] is None
    # Every sample either got its answer in time or was held and counted late.
    assert fig["steps"] >= fig["late"] >= fig["lost"] >= 0
    assert fig["round_trip_ms"]["p99"] >= fig["round_trip_ms"]["p50"] > 0
    # How late the simulator itself sent each sample after its time on the clock.
    assert fig["send_delay_ms"]["max"] >= fig["send_delay_ms"]["p50"] >= 0
    # The scheduling the run had: real-time where the system grants it (CI runs as root).
    import os

    if os.geteuid() == 0:
        assert fig["scheduling"] == "SCHED_FIFO 20"
    else:
        assert fig["scheduling"].startswith(("SCHED_FIFO", "normal ("))
    # The log is the one identify reads.
    from equilibrist import get_system
    from equilibrist.ident.log import read_log

    log = read_log(get_system("cartpole"), tmp_path / "rt.csv")
    assert log.n_rows == 401 and log.output_names == ("x", "theta")


@pytest.mark.slow
def test_the_device_on_a_pseudo_terminal_of_its_own(exports: dict[str, Path], tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    """``hil_host --pty`` opens a pseudo-terminal itself and prints its path: ``hil`` runs over it
    with no relay between, equal to a run over the joined pair, and the device ends by itself
    once the host has gone (``hil``'s command in this process: it closes the port itself)."""
    device = subprocess.Popen([str(exports["lqg"] / "hil_host"), "--pty"], stdout=subprocess.PIPE,
                              text=True)
    try:
        assert device.stdout is not None
        port = device.stdout.readline().strip()
        assert port.startswith("/dev/")
        status = main(["hil", "cartpole", "--port", port, "--duration", "0.5", "--x0",
                       "theta=0.05", "--json", "--out", str(tmp_path / "direct.npz")])
        direct = capsys.readouterr()
        assert status == 0, direct.err
        assert device.wait(timeout=10) == 0  # the host closed the port: the device ends
    finally:
        if device.poll() is None:
            device.kill()
            device.wait()
        assert device.stdout is not None
        device.stdout.close()
    with host_on_link(exports["lqg"] / "hil_host") as joined_port:
        status = main(["hil", "cartpole", "--port", joined_port, "--duration", "0.5", "--x0",
                       "theta=0.05", "--json", "--out", str(tmp_path / "joined.npz")])
    assert status == 0, capsys.readouterr().err
    a, b = SimResult.load(tmp_path / "direct.npz"), SimResult.load(tmp_path / "joined.npz")
    np.testing.assert_array_equal(a.states, b.states)
    assert json.loads(direct.out)["send_delay_ms"]["p50"] is None  # lockstep: no clock


# -- faults: one line, the right status, the run so far saved, the port released ---------------
FAULTS = {
    "silent": "did not answer",
    "crc": "bad CRC",
    "length": "a step answer of 3 bytes",
    "reset": "reset during the run",
    "cut": "disappeared",
}


@pytest.mark.parametrize("fault", list(FAULTS))
def test_a_fault_ends_the_run_in_one_line_and_keeps_it(fault: str, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    import serial

    with pty_link() as link:
        device = FakeDevice(link.paths[0], good=20, fault=fault, link=link)
        device.start()
        try:
            status = main(["hil", "cartpole", "--port", link.paths[1], "--controller", "lqr",
                           "--duration", "2", "--timeout", "0.3", "--out", str(tmp_path / "run.npz")])
        finally:
            device.stop()
        err = capsys.readouterr().err.strip()
        assert status == 1, err
        assert len(err.splitlines()) == 1 and "Traceback" not in err, err
        assert FAULTS[fault] in err and "run.npz" in err
        run = SimResult.load(tmp_path / "run.npz")
        assert run.n_rows == 20  # the samples answered before the fault
        assert not list(tmp_path.glob(".*"))  # written atomically: no temporary left
        if fault != "cut":  # the port is free again at once
            serial.Serial(link.paths[1], exclusive=True).close()


def test_a_start_that_cannot_be_made_is_refused_with_status_2(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    with pty_link() as link:
        device = FakeDevice(link.paths[0], fault="other")
        device.start()
        try:
            status = main(["hil", "cartpole", "--port", link.paths[1], "--controller", "lqr",
                           "--out", str(tmp_path / "run.npz")])
        finally:
            device.stop()
    err = capsys.readouterr().err.strip()
    assert status == 2 and len(err.splitlines()) == 1
    assert "runs another controller" in err and "'0123456789ab'" in err
    assert not (tmp_path / "run.npz").exists()
    fifo = tmp_path / "fifo"
    import os

    os.mkfifo(fifo)
    for port, words in ((str(tmp_path / "nothing"), "no such device"), (str(fifo), "not a serial device")):
        assert main(["hil", "cartpole", "--port", port]) == 2
        err = capsys.readouterr().err.strip()
        assert words in err and len(err.splitlines()) == 1


def test_realtime_priority_is_held_only_inside_and_a_refusal_is_said(monkeypatch: pytest.MonkeyPatch) -> None:
    """The simulator's thread runs under SCHED_FIFO inside a realtime run and gets its own
    scheduling back after; a system that refuses leaves the run at normal priority, said so."""
    import os

    from equilibrist.hil import run as hil_run

    policy = os.sched_getscheduler(0)
    if os.geteuid() == 0:
        with hil_run.realtime_priority() as granted:
            assert granted == f"SCHED_FIFO {RT_PRIORITY}"
            assert os.sched_getscheduler(0) == os.SCHED_FIFO
            assert os.sched_getparam(0).sched_priority == RT_PRIORITY
        assert os.sched_getscheduler(0) == policy

    def refuse(*_: object) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    with hil_run.realtime_priority() as granted:
        assert granted == "normal (the system refused real-time priority: Operation not permitted)"
        assert os.sched_getscheduler(0) == policy
