"""Reading the simulation layer's results into the viz layer's :class:`Run`."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, SupportsFloat

import numpy as np

from equilibrist.viz.output import VizError
from equilibrist.viz.runs import Run

if TYPE_CHECKING:  # the simulation layer is imported only when a result is shown
    from equilibrist.numeric.system import System
    from equilibrist.sim.result import SimResult

# How an event of the simulation's settings is named on a plot.
_EVENT_NAMES = {"kick": "push", "pulse": "push", "impulse": "push",
                "parameter_change": "parameters change"}


def _number(value: object) -> float:
    """*value* of a result's settings as a float (a :class:`VizError` when it is none)."""
    if not isinstance(value, SupportsFloat | str):
        raise VizError(f"the result's settings hold {value!r} where a number belongs")
    return float(value)


def _mapping(value: object, what: str) -> Mapping[str, object]:
    """*value* of a result's settings as the mapping it should be (a :class:`VizError` when not)."""
    if not isinstance(value, Mapping):
        raise VizError(f"the result's settings hold {value!r} as {what}, expected a mapping")
    return value


def _label(settings: Mapping[str, object]) -> str:
    ctrl = dict(_mapping(settings.get("controller") or {}, "the controller"))
    kind = str(ctrl.get("kind", "")).replace("_", " ")
    bits = []
    if kind and kind != "open loop":
        bits.append(kind if kind.isupper() else kind.replace("lqg", "LQG").replace("state feedback", "LQR"))
    rate = settings.get("rate")
    if rate:
        bits.append(f"{_number(rate):g} Hz")
    if settings.get("plant") == "linear":
        bits.append("linear plant")
    return ", ".join(bits)


def run_from_result(result: SimResult, *, system: System | None = None, label: str | None = None) -> Run:
    """The :class:`Run` of a :class:`~equilibrist.sim.SimResult`."""
    from equilibrist.numeric.lookup import system_for_data
    from equilibrist.sim.result import SimResult

    if not isinstance(result, SimResult):
        raise VizError(
            f"cannot show a {type(result).__name__}: it is not a simulation result "
            "(equilibrist.sim.simulate returns one; SimResult.load reads a saved one)"
        )
    # A Python system file named by the result is refused, never run, unless *system* is it.
    system = system_for_data(result.system, result.params, digest=result.system_digest,
                             system=system, source="the result")
    settings = dict(result.settings)
    events = []
    listed = settings.get("events") or ()
    if not isinstance(listed, list | tuple):
        raise VizError(f"the result's settings hold {listed!r} as the events, expected a list")
    for entry in listed:
        e = _mapping(entry, "an event")
        kind = str(e.get("kind", ""))
        what = _EVENT_NAMES.get(kind, kind.replace("_", " "))
        if kind in ("pulse", "impulse") and "value" in e and system.input_names:
            name = str(e.get("input") or system.input_names[0])
            unit = system.input_units[list(system.input_names).index(name)]
            unit = f"{unit}*s" if kind == "impulse" else unit
            what = f"push {_number(e['value']):+g} {unit}"
        elif kind == "kick" and "state" in e:
            unit = system.state_units[list(system.state_names).index(str(e["state"]))]
            what = f"kick {e['state']} {_number(e['value']):+g} {unit}"
        events.append((_number(e["time"]), what))
    if result.fell and result.fell_at is not None:
        events.append((float(result.fell_at), f"fell ({result.fell_state})"))
    has_reference = result.reference.ndim == 2 and result.reference.shape[1] > 0
    reference = result.reference if has_reference else None
    ref_names = tuple(result.reference_names) if has_reference else ()
    n_inputs = len(result.input_names)
    return Run.from_arrays(
        system,
        result.time,
        result.states,
        u=result.applied if n_inputs else np.zeros((len(result.time), 0)),
        u_command=result.commanded if n_inputs else None,
        estimate=result.estimates,
        y=result.measurements if len(result.output_names) else None,
        output_names=tuple(result.output_names) if len(result.output_names) else (),
        reference=reference,
        reference_names=ref_names,
        label=label if label is not None else _label(settings),
        events=events,
        fell=result.fell,
        x_op=result.x_op,
        u_op=result.u_op,
    )
