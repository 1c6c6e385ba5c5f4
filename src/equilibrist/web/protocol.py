"""The playground's message protocol: what a client may send, checked field by field.

Every message from the browser is one JSON object in one text frame of at
most :data:`MAX_MESSAGE_BYTES` bytes. :func:`parse` turns the frame into a
:class:`Message` or raises :class:`ProtocolError` with one line saying what
was wrong and what was expected; the server answers such a message with an
``error`` frame and goes on. Nothing here touches a file or evaluates text:
names are looked up in the :class:`Limits` the session offers, numbers must
be finite and within the stated ranges, unknown fields are refused.

The protocol is documented for people in ``docs/playground.md``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TypedDict

from equilibrist.errors import EquilibristError

#: Largest text frame accepted from a client, in bytes.
MAX_MESSAGE_BYTES = 16 * 1024


def controllers() -> tuple[str, ...]:
    """The controllers a client may pick, in the picker's order: the registry's kinds offered
    on the playground (:mod:`equilibrist.controllers.kinds`), the default (LQG) first and the
    open loop, named ``off``, last. A session refuses those that do not apply to its system
    (:attr:`Limits.unavailable`)."""
    from equilibrist.controllers import kinds

    offered = kinds.all_kinds("playground")
    names = [k.name for k in offered if not k.open_loop]
    names.sort(key=lambda n: n != DEFAULT)
    return (*names, OFF) if any(k.open_loop for k in offered) else tuple(names)


#: What the picker calls the open loop.
OFF = "off"
#: The controller a session starts with, first in the picker.
DEFAULT = "lqg"


def kind_name(controller: str) -> str:
    """The registry's name of a picked controller (``off`` is the open loop, ``none``)."""
    if controller == OFF:
        from equilibrist.controllers import kinds

        return next(k.name for k in kinds.all_kinds("playground") if k.open_loop)
    return controller


#: The controllers of :func:`controllers` when the server started.
CONTROLLERS = controllers()

# Ranges of the session-independent settings.
RATE_RANGE = (5.0, 2000.0)  # control rate [Hz]
NOISE_RANGE = (0.0, 20.0)  # sensor noise, in multiples of the rig's
LIMIT_RANGE = (0.05, 4.0)  # actuator limits, in multiples of the rig's
PUSH_RANGE = (-3.0, 3.0)  # push, in multiples of the input's full scale
PUSH_DURATION_RANGE = (0.005, 1.0)  # [s]
KICK_RANGE = (-1.0, 1.0)  # [rad] (or the main state's unit)
SEQ_RANGE = (0, 2**53)

# The fields each message type takes (besides "type" and "seq"), and which are required.
FIELDS: dict[str, tuple[frozenset[str], frozenset[str]]] = {
    "select": (frozenset({"system"}), frozenset({"system"})),
    "tune": (frozenset({"controller", "rate", "noise", "limit", "scales", "params", "rig"}),
             frozenset()),
    "push": (frozenset({"size", "duration"}), frozenset({"size"})),
    "kick": (frozenset({"angle"}), frozenset({"angle"})),
    "reset": (frozenset({"kick"}), frozenset()),
    "hang": (frozenset(), frozenset()),
    "pause": (frozenset({"paused"}), frozenset({"paused"})),
    "full": (frozenset(), frozenset()),
    "seen": (frozenset({"frame"}), frozenset({"frame"})),
    "roa": (frozenset(), frozenset()),
}


class ProtocolError(EquilibristError, ValueError):
    """A client message that does not follow the protocol."""


@dataclass(frozen=True)
class Limits:
    """What the session in its current state accepts: the systems offered, the ranges
    ``(low, high)`` of the Bryson *scales* and the tunable *params*, the controllers that
    do not apply with the reason a ``tune`` asking for one is refused with, and why ``hang``
    is refused (None: it is not).
    """

    systems: tuple[str, ...]
    scales: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    params: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    unavailable: Mapping[str, str] = field(default_factory=dict)
    hanging: str | None = None


class MessageFields(TypedDict, total=False):
    """The checked fields of a client message (each type has its own, see :data:`FIELDS`)."""

    system: str
    controller: str
    rate: float
    noise: float
    limit: float
    scales: dict[str, float]
    params: dict[str, float]
    rig: dict[str, float]
    size: float
    duration: float
    angle: float
    kick: float
    paused: bool
    frame: int


@dataclass(frozen=True)
class Message:
    """A checked client message: its ``type``, its fields, its sequence number."""

    type: str
    fields: MessageFields
    seq: int | None = None


def _reject_constant(name: str) -> float:
    raise ProtocolError(f"{name} is not a number of JSON: numbers must be finite")


def _number(value: object, what: str, low: float, high: float) -> float:
    # bool is an int in Python, but true is not a number in the protocol.
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ProtocolError(f"{what} must be a number, got {_short(value)}")
    v = float(value)
    if not math.isfinite(v):
        raise ProtocolError(f"{what} must be a finite number, got {_short(value)}")
    if not low <= v <= high:
        raise ProtocolError(f"{what} = {v:g} is out of range: expected {low:g} to {high:g}")
    return v


def _short(value: object) -> str:
    text = json.dumps(value) if isinstance(value, str | int | float | bool | None) else type(value).__name__
    return text if len(text) <= 40 else text[:37] + "..."


def _named_numbers(
    value: object, what: str, ranges: Mapping[str, tuple[float, float]]
) -> dict[str, float]:
    if not isinstance(value, dict):
        raise ProtocolError(f"{what} must be an object of name: number, got {_short(value)}")
    if not value:
        raise ProtocolError(f"{what} is empty: expected at least one of {', '.join(ranges)}")
    out: dict[str, float] = {}
    for name, raw in value.items():
        if name not in ranges:
            known = ", ".join(ranges) or "none"
            raise ProtocolError(f"{what} has no entry {_short(name)}: expected one of {known}")
        low, high = ranges[name]
        out[name] = _number(raw, f"{what}.{name}", low, high)
    return out


def parse(text: str | bytes, limits: Limits) -> Message:
    """The :class:`Message` in the text frame *text*, checked against *limits*."""
    if isinstance(text, bytes):
        raise ProtocolError("binary frames are not part of the protocol: send JSON text")
    if len(text) > MAX_MESSAGE_BYTES or len(text.encode("utf-8", "replace")) > MAX_MESSAGE_BYTES:
        raise ProtocolError(
            f"message of {len(text.encode('utf-8', 'replace'))} bytes is too long: "
            f"the limit is {MAX_MESSAGE_BYTES} bytes"
        )
    try:
        data = json.loads(text, parse_constant=_reject_constant)
    except ProtocolError:
        raise
    except (ValueError, RecursionError) as exc:
        raise ProtocolError(f"message is not valid JSON: {str(exc)[:80]}") from None
    if not isinstance(data, dict):
        raise ProtocolError(f"message must be a JSON object, got {type(data).__name__}")
    kind = data.get("type")
    if not isinstance(kind, str) or kind not in FIELDS:
        raise ProtocolError(
            f"message type {_short(kind)} is unknown: expected one of {', '.join(FIELDS)}"
        )
    allowed, required = FIELDS[kind]
    unknown = sorted(k for k in data if k not in allowed and k not in ("type", "seq"))
    if unknown:
        raise ProtocolError(
            f"{kind} message has unknown field(s) {', '.join(_short(k) for k in unknown)}: "
            f"expected {', '.join(sorted(allowed)) or 'none'} (and seq)"
        )
    missing = sorted(required - set(data))
    if missing:
        raise ProtocolError(f"{kind} message lacks {', '.join(missing)}")
    seq: int | None = None
    if "seq" in data:
        seq = _counter(data["seq"], "seq")
    fields = _FIELD_CHECKS[kind](data, limits)
    return Message(kind, fields, seq)


def _select(data: dict[str, object], limits: Limits) -> MessageFields:
    name = data["system"]
    if not isinstance(name, str) or name not in limits.systems:
        raise ProtocolError(
            f"system {_short(name)} is not offered: expected one of {', '.join(limits.systems)}"
        )
    return {"system": name}


def _tune(data: dict[str, object], limits: Limits) -> MessageFields:
    out: MessageFields = {}
    if len(data) - ("seq" in data) <= 1:
        raise ProtocolError(
            "tune message changes nothing: give controller, rate, noise, limit, scales, params "
            "or rig"
        )
    if "controller" in data:
        c = data["controller"]
        known = controllers()
        if not isinstance(c, str) or c not in known:
            raise ProtocolError(
                f"controller {_short(c)} is unknown: expected one of {', '.join(known)}"
            )
        if c in limits.unavailable:
            raise ProtocolError(f"controller {c!r} does not apply: {limits.unavailable[c]}")
        out["controller"] = c
    if "rate" in data:
        out["rate"] = _number(data["rate"], "rate", *RATE_RANGE)
    if "noise" in data:
        out["noise"] = _number(data["noise"], "noise", *NOISE_RANGE)
    if "limit" in data:
        out["limit"] = _number(data["limit"], "limit", *LIMIT_RANGE)
    if "scales" in data:
        out["scales"] = _named_numbers(data["scales"], "scales", limits.scales)
    if "params" in data:
        out["params"] = _named_numbers(data["params"], "params", limits.params)
    if "rig" in data:
        out["rig"] = _rig(data["rig"])
    return out


#: The rig's effects a session takes and the numbers each may be: whole numbers of samples
#: (the delays in samples) or finite numbers (the others) within these ranges.
RIG_RANGES: dict[str, tuple[float, float]] = {
    "torque_response": (0.01, 2.0), "torque_time_constant": (1e-4, 10.0),
    "measurement_delay": (0, 100), "measurement_delay_time": (0.0, 1.0),
    "actuation_delay": (0, 100), "actuation_delay_time": (0.0, 1.0),
    "torque_noise": (0.0, 1e3), "velocity_noise": (0.0, 1e3), "encoder_step": (0.0, 1.0),
    "velocity_filter": (0.0, 1e4),
}
_WHOLE = frozenset({"measurement_delay", "actuation_delay"})


def _rig(raw: object) -> dict[str, float]:
    """The ``rig`` field: an object of the rig's effects (an empty one: none)."""
    if not isinstance(raw, dict):
        raise ProtocolError(f"rig must be an object of the rig's effects, got {_short(raw)}")
    out: dict[str, float] = {}
    for name, value in raw.items():
        if name not in RIG_RANGES:
            raise ProtocolError(f"rig has no effect {_short(name)}: expected one of "
                                f"{', '.join(RIG_RANGES)} (random pushes: the page's push)")
        low, high = RIG_RANGES[name]
        number = _number(value, f"rig.{name}", low, high)
        if name in _WHOLE:
            if number != int(number):
                raise ProtocolError(f"rig.{name} must be a whole number of samples, got "
                                    f"{_short(value)}")
            out[name] = int(number)
        else:
            out[name] = number
    return out


def _push(data: dict[str, object], limits: Limits) -> MessageFields:
    out: MessageFields = {"size": _number(data["size"], "size", *PUSH_RANGE)}
    if "duration" in data:
        out["duration"] = _number(data["duration"], "duration", *PUSH_DURATION_RANGE)
    return out


def _kick(data: dict[str, object], limits: Limits) -> MessageFields:
    return {"angle": _number(data["angle"], "angle", *KICK_RANGE)}


def _reset(data: dict[str, object], limits: Limits) -> MessageFields:
    if "kick" in data:
        return {"kick": _number(data["kick"], "kick", *KICK_RANGE)}
    return {}


def _hang(data: dict[str, object], limits: Limits) -> MessageFields:
    if limits.hanging is not None:
        raise ProtocolError(f"hang is refused: {limits.hanging}")
    return {}


def _pause(data: dict[str, object], limits: Limits) -> MessageFields:
    value = data["paused"]
    if not isinstance(value, bool):
        raise ProtocolError(f"paused must be true or false, got {_short(value)}")
    return {"paused": value}


def _nothing(data: dict[str, object], limits: Limits) -> MessageFields:
    return {}


def _seen(data: dict[str, object], limits: Limits) -> MessageFields:
    return {"frame": _counter(data["frame"], "frame")}


def _counter(raw: object, what: str) -> int:
    if isinstance(raw, bool) or not isinstance(raw, int) or not SEQ_RANGE[0] <= raw <= SEQ_RANGE[1]:
        raise ProtocolError(f"{what} must be an integer from 0 to 2^53, got {_short(raw)}")
    return raw


_FIELD_CHECKS = {
    "select": _select,
    "tune": _tune,
    "push": _push,
    "kick": _kick,
    "reset": _reset,
    "hang": _hang,
    "pause": _pause,
    "full": _nothing,
    "seen": _seen,
    "roa": _nothing,
}

__all__ = ["CONTROLLERS", "DEFAULT", "FIELDS", "MAX_MESSAGE_BYTES", "OFF", "Limits", "Message", "ProtocolError", "controllers", "kind_name", "parse"]
