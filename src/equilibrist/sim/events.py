"""Things that happen to a run at a given time: pushes and parameter changes.

Every event acts at the start of the physics step nearest its time (the
physics step is the simulation's grid), just after the controller's sample
when the two coincide, so the controller first sees the effect one sample
later, as on a rig.

- :class:`Kick`: an instantaneous change of one state, in that state's unit.
  On a rate (``theta_dot``) it is the impulse divided by the inertia: a
  hammer tap. On a position it teleports the body, which is allowed but
  rarely meant.
- :class:`Pulse`: a force (or torque) of ``value`` in the unit of an input,
  added to that input's channel for ``duration`` seconds: a hand pushing the
  cart. It acts beside the actuator, so the actuator's saturation does not
  limit it, and the controller does not know of it.
- :class:`Impulse`: a pulse of ``value / h`` for one physics step ``h``, so
  that its integral is ``value`` (N s for a force): the limit of a short,
  hard push.
- :class:`ParameterChange`: new values of physical parameters (of the plant;
  the controller keeps the design it has), e.g. a heavier pole from a time on.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

Number = float | int


@dataclass(frozen=True)
class Kick:
    """Add ``value`` (in the state's unit) to the state ``state`` at ``time``."""

    time: float
    state: str
    value: float

    def describe(self) -> dict[str, object]:
        return {"kind": "kick", "time": self.time, "state": self.state, "value": self.value}


@dataclass(frozen=True)
class Pulse:
    """Add ``value`` (the input's unit) to input ``input`` from ``time`` for ``duration`` s.

    ``input`` None means the system's first input.
    """

    time: float
    value: float
    duration: float
    input: str | None = None

    def describe(self) -> dict[str, object]:
        return {"kind": "pulse", "time": self.time, "value": self.value,
                "duration": self.duration, "input": self.input}


@dataclass(frozen=True)
class Impulse:
    """An impulse of ``value`` (input unit times seconds, N s for a force) at ``time``.

    Applied as a pulse of ``value / h`` during one physics step ``h``.
    """

    time: float
    value: float
    input: str | None = None

    def describe(self) -> dict[str, object]:
        return {"kind": "impulse", "time": self.time, "value": self.value, "input": self.input}


@dataclass(frozen=True)
class ParameterChange:
    """From ``time`` on, the plant's parameters ``values`` (name -> value)."""

    time: float
    values: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "values", dict(self.values))

    def __hash__(self) -> int:
        return hash((self.time, tuple(sorted(self.values.items()))))

    def describe(self) -> dict[str, object]:
        return {"kind": "parameter_change", "time": self.time, "values": dict(self.values)}


Event = Kick | Pulse | Impulse | ParameterChange


def describe(events: tuple[Event, ...]) -> list[dict[str, object]]:
    return [e.describe() for e in events]


def from_description(items: list[dict[str, object]]) -> tuple[Event, ...]:
    """The events of :func:`describe`'s output (results loaded from a file)."""
    out: list[Event] = []
    for item in items:
        d = dict(item)
        kind = d.pop("kind")
        if kind == "kick":
            out.append(Kick(float(d["time"]), str(d["state"]), float(d["value"])))  # type: ignore[arg-type]
        elif kind == "pulse":
            out.append(Pulse(float(d["time"]), float(d["value"]), float(d["duration"]),  # type: ignore[arg-type]
                             d.get("input")))  # type: ignore[arg-type]
        elif kind == "impulse":
            out.append(Impulse(float(d["time"]), float(d["value"]), d.get("input")))  # type: ignore[arg-type]
        elif kind == "parameter_change":
            out.append(ParameterChange(float(d["time"]), d["values"]))  # type: ignore[arg-type]
    return tuple(out)


__all__ = ["Event", "Impulse", "Kick", "ParameterChange", "Pulse", "describe", "from_description"]
