"""The serial link to the device (pyserial; a pseudo-terminal works as a port)."""

from __future__ import annotations

import contextlib
import os
import stat
import time
from typing import Any

from equilibrist.errors import quote_outside
from equilibrist.hil.protocol import Frame, FrameReader, HILError, ProtocolError, frame


def require_pyserial() -> Any:
    try:
        import serial
    except ImportError:  # pragma: no cover - the extra is part of the dev install
        raise HILError("hardware in the loop needs pyserial: pip install 'equilibrist[hil]'") from None
    return serial


class DeviceGone(HILError):
    """The port closed under the link: the device was unplugged or its program ended."""


class SerialLink:
    """Frames over a serial port: sent whole, received with a deadline.

    The port is opened exclusively, in raw mode; :meth:`close` releases it
    (the link is a context manager).
    """

    def __init__(self, port: str, *, baudrate: int = 115200) -> None:
        serial = require_pyserial()
        if not isinstance(port, str) or not port.strip():
            raise HILError(f"--port {port!r}: expected the path of a serial device (/dev/ttyACM0)")
        try:
            mode = os.stat(port).st_mode
        except FileNotFoundError:
            raise HILError(f"--port {port}: no such device") from None
        except OSError as exc:
            raise HILError(f"--port {port}: {exc.strerror}") from None
        if not stat.S_ISCHR(mode):
            raise HILError(f"--port {port}: not a serial device (expected a character device "
                           "such as /dev/ttyACM0 or a pseudo-terminal /dev/pts/N)")
        self.port = port
        try:
            self._serial = serial.Serial(port, baudrate=baudrate, timeout=0, write_timeout=2.0,
                                         exclusive=True)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise HILError(f"--port {port}: cannot be opened ({_reason(exc)})") from None
        self._reader = FrameReader()
        self._pending: list[Frame] = []
        self.bytes_in = 0
        self.bytes_out = 0

    def __enter__(self) -> SerialLink:
        return self

    def __exit__(self, *_exc: object) -> None:
        self.close()

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self._serial.close()

    def send(self, kind: int, seq: int, payload: bytes = b"") -> None:
        data = frame(kind, seq, payload)
        serial = require_pyserial()
        try:
            self._serial.write(data)
        except (serial.SerialException, OSError) as exc:
            raise DeviceGone(f"the device disappeared: writing to {self.port} failed "
                             f"({_reason(exc)})") from None
        self.bytes_out += len(data)

    def drain(self) -> None:
        """Forget whatever the device sent before now."""
        self._pending.clear()
        self._reader = FrameReader()
        with contextlib.suppress(Exception):
            self._serial.reset_input_buffer()

    def receive(self, deadline: float) -> Frame | None:
        """The next frame, or None when *deadline* (``time.perf_counter``) passes first.

        A frame with a bad CRC or length raises :class:`ProtocolError`.
        """
        serial = require_pyserial()
        while not self._pending:
            remaining = deadline - time.perf_counter()
            if remaining <= 0:
                return None
            self._serial.timeout = remaining
            try:
                waiting = self._serial.in_waiting
                data = self._serial.read(waiting or 1)
            except (serial.SerialException, OSError) as exc:
                raise DeviceGone(f"the device disappeared: the port {self.port} closed "
                                 f"({_reason(exc)})") from None
            if data:
                self.bytes_in += len(data)
                try:
                    self._pending += self._reader.feed(data)
                except ProtocolError:
                    self._reader = FrameReader()
                    raise
        return self._pending.pop(0)


def _reason(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return quote_outside(text.splitlines()[0])
