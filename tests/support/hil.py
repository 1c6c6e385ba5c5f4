"""A serial link without hardware: two pseudo-terminals joined by a relay, and a device that misbehaves.

:class:`PtyLink` opens two pseudo-terminal pairs and copies bytes between
their master ends in a thread, so a program that opens one slave path and
another that opens the other talk as over a cable (what ``socat -d -d
pty,raw pty,raw`` does). :meth:`PtyLink.cut` closes the masters: both ends
see their port gone, as when a USB cable is pulled.

:class:`FakeDevice` speaks the protocol from Python on one end, answering
the host's hello with the host's own shapes, and fails as asked.
"""

from __future__ import annotations

import os
import select
import struct
import subprocess
import threading
import time
import tty
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path

from equilibrist.hil import protocol as proto
from equilibrist.native.firmware import VERSION


class PtyLink:
    def __init__(self) -> None:
        self._masters: list[int] = []
        self._slaves: list[int] = []
        self.paths: list[str] = []
        for _ in range(2):
            master, slave = os.openpty()
            tty.setraw(slave)
            self._masters.append(master)
            self._slaves.append(slave)
            self.paths.append(os.ttyname(slave))
        self._stop = threading.Event()
        self.relay = threading.Thread(target=self._relay, daemon=True)
        self.relay.start()

    def _relay(self) -> None:
        a, b = self._masters
        other = {a: b, b: a}
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([a, b], [], [], 0.05)
            except (OSError, ValueError):
                return
            for fd in ready:
                try:
                    data = os.read(fd, 4096)
                except OSError:
                    continue  # no one holds that end yet
                if data:
                    with suppress(OSError):
                        os.write(other[fd], data)

    def cut(self) -> None:
        """Pull the cable: the relay stops and the ports go away."""
        if self._stop.is_set():
            return
        self._stop.set()
        self.relay.join(timeout=2)
        for fd in self._masters + self._slaves:
            with suppress(OSError):
                os.close(fd)

    close = cut


@contextmanager
def pty_link() -> Iterator[PtyLink]:
    link = PtyLink()
    try:
        yield link
    finally:
        link.cut()


@contextmanager
def host_on_link(host: Path) -> Iterator[str]:
    """The exported host program *host* (``hil_host``) as the device on one end of a
    pseudo-terminal link: yields the other end's path (the command's ``--port``), and stops
    the device when done."""
    with pty_link() as link:
        device = subprocess.Popen([str(host), link.paths[0]])
        try:
            yield link.paths[1]
        finally:
            device.terminate()
            device.wait(timeout=5)


class FakeDevice(threading.Thread):
    """A device in Python on *path* that answers *good* steps with a zero command, then *fault*.

    Faults: ``"silent"`` (stops answering), ``"crc"`` (a frame with a bad CRC),
    ``"length"`` (a step answer of the wrong length), ``"reset"`` (restarts: its
    BOOT frame, then it no longer knows the session), ``"cut"`` (the cable is
    pulled: *link* is cut), ``"other"`` (answers the hello as another controller).
    """

    def __init__(self, path: str, *, good: int = 10, fault: str = "silent",
                 link: PtyLink | None = None) -> None:
        super().__init__(daemon=True)
        self.fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
        tty.setraw(self.fd)
        self.good = good
        self.fault = fault
        self.link = link
        self.steps = 0
        self._stop_event = threading.Event()

    def stop(self) -> None:
        self._stop_event.set()
        self.join(timeout=2)
        with suppress(OSError):
            os.close(self.fd)

    def _send(self, kind: int, seq: int, payload: bytes = b"") -> None:
        os.write(self.fd, proto.frame(kind, seq, payload))

    def run(self) -> None:
        reader = proto.FrameReader()
        hello: proto.Hello | None = None
        started = True
        while not self._stop_event.is_set():
            try:
                ready, _, _ = select.select([self.fd], [], [], 0.05)
                if not ready:
                    continue
                data = os.read(self.fd, 4096)
            except OSError:
                return
            for f in reader.feed(data):
                if f.kind == proto.HELLO:
                    hello = proto.Hello.unpack(f.payload)
                    if self.fault == "other":
                        hello = proto.Hello(**{**hello.__dict__, "controller_id": "0123456789ab"})
                    self._send(proto.HELLO_REPLY, f.seq, hello.pack())
                elif f.kind == proto.RESET:
                    self._send(proto.RESET_REPLY, f.seq)
                elif f.kind == proto.STEP and hello is not None:
                    self.steps += 1
                    if not started:
                        self._send(proto.ERROR, f.seq, b"not started: send a hello first")
                        continue
                    if self.steps <= self.good:
                        u = struct.pack("<" + "f" * hello.m, *([0.0] * hello.m))
                        self._send(proto.STEP_REPLY, f.seq, u + struct.pack("<I", 3))
                        continue
                    if self.fault == "silent":
                        continue
                    if self.fault == "crc":
                        bad = bytearray(proto.frame(proto.STEP_REPLY, f.seq, b"\0" * (4 * hello.m + 4)))
                        bad[-1] ^= 0xFF
                        os.write(self.fd, bytes(bad))
                    elif self.fault == "length":
                        self._send(proto.STEP_REPLY, f.seq, b"\0\0\0")
                    elif self.fault == "reset":
                        self._send(proto.BOOT, 0, bytes([VERSION]))
                        started = False
                    elif self.fault == "cut" and self.link is not None:
                        time.sleep(0.05)
                        self.link.cut()
                        return
