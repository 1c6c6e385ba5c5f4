"""The hardware-in-the-loop protocol: framed binary messages over a serial link.

Every message is one frame (all integers little-endian)::

    0xEB 0x90 | type u8 | seq u16 | length u16 | payload (length bytes) | crc u16

``crc`` is CRC-16/XMODEM (polynomial 0x1021, initial value 0, no
reflection, no final xor) over ``type``, ``seq``, ``length`` and the payload.
A receiver hunts for the two sync bytes, so a frame broken on the line costs
that frame only. Reals are float32 by default, float64 where both sides
have it (the size is agreed in the hello). ``docs/hil.md`` is the reference;
the C side (:mod:`equilibrist.native.firmware`, which defines the numbers both
sides share) implements the same.
"""

from __future__ import annotations

import binascii
import math
import struct
from dataclasses import dataclass

import numpy as np

from equilibrist.errors import EquilibristError, quote_outside
from equilibrist.native.firmware import ID_BYTES, MAX_PAYLOAD, VERSION

SYNC = b"\xeb\x90"
HEAD = struct.Struct("<BHH")  # type, seq, length
CRC = struct.Struct("<H")

# Host to device.
HELLO, STEP, RESET = 0x01, 0x02, 0x03
# Device to host: the answer to a request is its type | 0x80.
HELLO_REPLY, STEP_REPLY, RESET_REPLY = 0x81, 0x82, 0x83
BOOT = 0x80  # sent by the device when it starts: a device that resets says so
ERROR = 0xFF  # text: what the device could not do

# version u8, real size u8, n u16, m u16, p u16, references u16, estimate u16, rate f64, id
_HELLO = struct.Struct(f"<BBHHHHHd{ID_BYTES}s")


class HILError(EquilibristError, ValueError):
    """A link, a device or a message that cannot be used (said in one line)."""


class ProtocolError(HILError):
    """A frame that is not one: bad CRC, wrong length, an unexpected type."""


def crc16(data: bytes) -> int:
    """CRC-16/XMODEM of *data* (``crc16(b"123456789") == 0x31C3``)."""
    return binascii.crc_hqx(data, 0)


def frame(kind: int, seq: int, payload: bytes = b"") -> bytes:
    """The bytes of one frame."""
    if len(payload) > MAX_PAYLOAD:
        raise ProtocolError(f"a payload of {len(payload)} bytes is over the {MAX_PAYLOAD} allowed")
    body = HEAD.pack(kind, seq & 0xFFFF, len(payload)) + payload
    return SYNC + body + CRC.pack(crc16(body))


@dataclass(frozen=True)
class Frame:
    kind: int
    seq: int
    payload: bytes


class FrameReader:
    """Frames out of a byte stream fed in pieces (sync hunting, CRC checked).

    :meth:`feed` returns the complete frames; a frame whose CRC or length is
    wrong raises :class:`ProtocolError` once, and reading goes on after it.
    """

    def __init__(self) -> None:
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[Frame]:
        self._buf += data
        out: list[Frame] = []
        while True:
            start = self._buf.find(SYNC)
            if start < 0:
                del self._buf[: max(0, len(self._buf) - 1)]  # keep a lone first sync byte
                return out
            del self._buf[:start]
            if len(self._buf) < 2 + HEAD.size:
                return out
            kind, seq, length = HEAD.unpack_from(self._buf, 2)
            if length > MAX_PAYLOAD:
                del self._buf[:2]
                raise ProtocolError(f"a frame says its payload is {length} bytes, over the "
                                    f"{MAX_PAYLOAD} allowed")
            end = 2 + HEAD.size + length + CRC.size
            if len(self._buf) < end:
                return out
            body = bytes(self._buf[2 : end - CRC.size])
            (crc,) = CRC.unpack_from(self._buf, end - CRC.size)
            del self._buf[:end]
            if crc != crc16(body):
                raise ProtocolError(f"a frame of type 0x{kind:02x} has a bad CRC "
                                    f"(0x{crc:04x}, expected 0x{crc16(body):04x})")
            out.append(Frame(kind, seq, body[HEAD.size :]))


@dataclass(frozen=True)
class Hello:
    """What each side states at the start: the protocol, the reals, the shapes, the controller."""

    real_size: int  # 4 (float32) or 8 (float64)
    n: int  # states
    m: int  # inputs
    p: int  # measured outputs
    references: int  # references the controller takes (0: none)
    estimate: int  # estimate values in each answer (0: none)
    rate: float  # samples per second
    controller_id: str  # the exported controller's design id
    version: int = VERSION

    def pack(self) -> bytes:
        ident = self.controller_id.encode("ascii", "replace")[:ID_BYTES]
        return _HELLO.pack(self.version, self.real_size, self.n, self.m, self.p,
                           self.references, self.estimate, self.rate, ident)

    @classmethod
    def unpack(cls, payload: bytes) -> Hello:
        if len(payload) != _HELLO.size:
            raise ProtocolError(f"a hello of {len(payload)} bytes, expected {_HELLO.size}")
        v, size, n, m, p, refs, est, rate, ident = _HELLO.unpack(payload)
        return cls(real_size=size, n=n, m=m, p=p, references=refs, estimate=est, rate=rate,
                   controller_id=ident.rstrip(b"\0").decode("ascii", "replace"), version=v)

    def mismatch(self, device: Hello) -> str | None:
        """What in the *device*'s hello differs from this one (the host's), or None."""
        if device.version != self.version:
            return f"protocol version {device.version}, expected {self.version}"
        if device.real_size != self.real_size:
            return (f"{_real_name(device.real_size)} payloads, expected "
                    f"{_real_name(self.real_size)} (--payload)")
        wanted = (("n", "states"), ("m", "inputs"), ("p", "measured outputs"))
        for field_, what in wanted:
            if getattr(device, field_) != getattr(self, field_):
                return f"{getattr(device, field_)} {what}, expected {getattr(self, field_)}"
        if self.references > device.references:
            return f"{device.references} references, expected at least {self.references}"
        if not math.isfinite(device.rate) or abs(device.rate - self.rate) > 1e-9 * self.rate:
            return f"a rate of {device.rate:g} Hz, expected {self.rate:g} Hz"
        if device.controller_id != self.controller_id:
            return (f"controller '{quote_outside(device.controller_id, limit=40)}', expected "
                    f"{self.controller_id!r} "
                    "(export the same design and flash it again)")
        return None


def _real_name(size: int) -> str:
    return {4: "float32", 8: "float64"}.get(size, f"{size}-byte")


def real_dtype(size: int) -> np.dtype:
    if size not in (4, 8):
        raise ProtocolError(f"reals of {size} bytes: expected 4 (float32) or 8 (float64)")
    return np.dtype("<f4" if size == 4 else "<f8")


def step_payload(y: np.ndarray, r: np.ndarray, real_size: int) -> bytes:
    """The payload of a step request: the measured outputs, then the references."""
    return np.concatenate([y, r]).astype(real_dtype(real_size)).tobytes()


@dataclass(frozen=True)
class StepReply:
    u: np.ndarray
    estimate: np.ndarray | None
    device_step_us: int


def parse_step_reply(payload: bytes, hello: Hello) -> StepReply:
    """A step answer: the inputs, the estimate (if any), the device's step time [us]."""
    dtype = real_dtype(hello.real_size)
    count = hello.m + hello.estimate
    want = count * dtype.itemsize + 4
    if len(payload) != want:
        raise ProtocolError(f"a step answer of {len(payload)} bytes, expected {want} "
                            f"({hello.m} inputs, {hello.estimate} estimates, the step time)")
    values = np.frombuffer(payload, dtype=dtype, count=count).astype(float)
    (us,) = struct.unpack_from("<I", payload, count * dtype.itemsize)
    est = values[hello.m :] if hello.estimate else None
    return StepReply(values[: hello.m].copy(), None if est is None else est.copy(), int(us))
