"""The playground's systems, settings and designs: the catalogue offered, the settings a page
tunes, the tuned system and its design (and the swing-up or MPC built on it); used by :mod:`equilibrist.web.session`.
"""

from __future__ import annotations

import time
import types
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.errors import DesignError, EquilibristError
from equilibrist.web.protocol import MessageFields, kind_name
from equilibrist.web.runners import Runner, build_plan_runner, build_runner, planned, runner_kinds

if TYPE_CHECKING:
    from equilibrist.control.design_record import Design
    from equilibrist.control.trajopt import Trajectory
    from equilibrist.numeric.system import System
    from equilibrist.sim.rig import Rig


#: Floor of the measurement noise the Kalman filter assumes, as a fraction of the rig's.
NOISE_FLOOR = 0.05


def label(controller: str) -> str:
    """The picker's label of a controller: its kind's (:mod:`equilibrist.controllers.kinds`)."""
    from equilibrist.controllers import kinds

    return kinds.get(kind_name(controller)).label


def kind_facts(controller: str) -> dict[str, object]:
    """What the page reads of a controller's kind record, to show it as it is (the mode's
    note, the design's line, the margins' heading, the Hang button's hint) without asking
    its name: ``short_label`` (the label before its parenthesis, the status line's word),
    and the record's ``loop``, ``linear``, ``from_any_state``, ``planned``, ``solves_qp``
    and ``open_loop`` (:class:`~equilibrist.controllers.kinds.ControllerKind`)."""
    from equilibrist.controllers import kinds

    kind = kinds.get(kind_name(controller))
    return {"short_label": kind.label.split(" (", 1)[0].strip() or kind.label,
            "loop": kind.loop, "linear": kind.linear, "from_any_state": kind.from_any_state,
            "planned": kind.planned, "solves_qp": kind.solves_qp, "open_loop": kind.open_loop}


class SessionError(EquilibristError, ValueError):
    """A request the session cannot carry out (download with the controller off, ...)."""


# -- catalogue -------------------------------------------------------------------


@dataclass
class Catalogue:
    """The systems a server offers (catalogue names or a user's model file; the page can only
    pick among them), each built once and shared by the sessions. :meth:`of` offers systems
    given as values (a script's own), which the server's process knows."""

    names: tuple[str, ...]
    _systems: dict[str, System] = field(default_factory=dict, repr=False)

    @classmethod
    def default(cls, extra: Sequence[str] = ()) -> Catalogue:
        """Every system of the catalogue with an input, an operating point and a drawing, plus *extra*."""
        from equilibrist.systems import registry
        names: list[str] = []
        for entry in registry.all_entries():
            spec = entry.spec
            drawn = spec.drawing is not None
            if drawn and spec.inputs and spec.operating_point is not None and spec.name not in names:
                names.append(spec.name)
        for e in extra:
            if e not in names:
                names.insert(0, e)
        return cls(tuple(names))

    @classmethod
    def of(cls, systems: Sequence[System]) -> Catalogue:
        """The systems given, offered by their keys in their order, with their parameter values."""
        if not systems:
            raise SessionError("no system to offer: expected at least one")
        offered = {s.key: s for s in systems}
        if len(offered) != len(systems):
            raise SessionError("a system is given twice: expected each once")
        return cls(tuple(offered), dict(offered))

    def system(self, name: str) -> System:
        """The system *name* with its default parameters (built on first use)."""
        if name not in self.names:
            raise SessionError(f"system {name!r} is not offered: expected one of {', '.join(self.names)}")
        if name not in self._systems:
            from equilibrist.numeric.lookup import get_system

            self._systems[name] = get_system(name)
        return self._systems[name]

    def check(self, name: str) -> System:
        """The system *name*, refused when it cannot be played (no input, operating point or drawing)."""
        system = self.system(name)
        if not system.n_inputs:
            raise SessionError(f"{system.key} has no input: there is nothing to control in the playground")
        if system.spec.operating_point is None:
            raise SessionError(f"{system.key} has no operating point to balance at")
        from equilibrist.viz.scenes import scene_for

        scene_for(system)  # one clear line when the system has no drawing
        return system


# -- settings and designs -------------------------------------------------------------


@dataclass(frozen=True)
class Settings:
    """What the page tuned (a value: each change makes a new one). *rig*: the rig's effects
    between the plant and the controller, by :class:`~equilibrist.sim.rig.Rig`'s option names
    (empty: none)."""

    controller: str
    rate: float
    noise: float
    limit: float
    scales: Mapping[str, float]
    params: Mapping[str, float]
    rig: Mapping[str, float] = field(default_factory=lambda: types.MappingProxyType({}))

    def changed(self, fields: MessageFields) -> Settings:
        scales = dict(self.scales)
        scales.update(fields.get("scales", {}))
        params = dict(self.params)
        params.update(fields.get("params", {}))
        return Settings(
            controller=fields.get("controller", self.controller),
            rate=float(fields.get("rate", self.rate)),
            noise=float(fields.get("noise", self.noise)),
            limit=float(fields.get("limit", self.limit)),
            scales=types.MappingProxyType(scales),
            params=types.MappingProxyType(params),
            rig=types.MappingProxyType(dict(fields["rig"])) if "rig" in fields else self.rig,
        )

    def to_dict(self) -> dict[str, object]:
        return {"controller": self.controller, "rate": self.rate, "noise": self.noise,
                "limit": self.limit, "scales": dict(self.scales), "params": dict(self.params),
                "rig": dict(self.rig)}

    def rig_effects(self) -> Rig | None:
        """The rig of these settings, or None (no effect)."""
        from equilibrist.sim.rig import Rig

        rig = Rig(**self.rig)  # type: ignore[arg-type]
        return None if rig.off else rig


def tuned_system(base: System, settings: Settings) -> System:
    """*base* with the tuned physical parameters and the scaled input limits."""
    values: dict[str, float] = dict(settings.params)
    for name in base.input_names:
        values[f"{name}_min"] = settings.limit * float(base.params[f"{name}_min"])
        values[f"{name}_max"] = settings.limit * float(base.params[f"{name}_max"])
    return base.with_params(**values)


def make_design(system: System, settings: Settings) -> Design:
    """The discrete LQG design of the tuned *system* (raises an ``EquilibristError``)."""
    from equilibrist.control.design import design

    states, inputs = system.state_names, system.input_names
    q = [1.0 / settings.scales[s] ** 2 for s in states]
    r = [1.0 / settings.scales[i] ** 2 for i in inputs]
    spec = system.spec
    outputs = tuple(system.output_names or states)
    sigma = [float(spec.sensor_noise.get(o, 0.0)) for o in outputs]
    if all(s > 0 for s in sigma):
        level = max(settings.noise, NOISE_FLOOR)
        rn: object = [(level * s) ** 2 / settings.rate for s in sigma]
    else:
        rn = None  # the design names the missing sensor noise
    return design(system, q=q, r=r, rn=rn, outputs=outputs, rate=settings.rate)


def describe_design(d: Design, controller: str, seconds: float,
                    runner: Runner | None = None,
                    controller_seconds: float = 0.0) -> dict[str, object]:
    """The ``design`` frame: gains, poles, margins (JSON-ready), with the times of the
    design (*seconds*) and of building the *runner* on it (*controller_seconds*).
    ``margins`` are those of the loop the kind record names (``margins_loop``: ``"lqg"``, the
    Kalman filter in the loop, or ``"lqr"``); ``lqr_margins`` always the state feedback's.
    """
    from equilibrist.controllers import kinds

    loop = kinds.get(kind_name(controller)).loop or "lqr"
    full = d.to_dict(controller=loop)
    return {
        "type": "design",
        "controller": controller,
        "rate": d.rate,
        **{k: full[k] for k in ("states", "inputs", "outputs", "K", "Kf", "poles",
                                "estimator_poles", "open_loop_poles", "pole_table", "margins")},
        "margins_loop": loop,
        **{k: full[k] for k in ("lqr_margins", "notes", "x0", "u0")},
        "milliseconds": round((seconds + controller_seconds) * 1e3, 2),
        "design_milliseconds": round(seconds * 1e3, 2),
        "controller_milliseconds": round(controller_seconds * 1e3, 2),
        "controller_info": None if runner is None else runner.describe(),
    }


def design_for(system: System, settings: Settings) -> tuple[Design | None, float, str | None]:
    """Design for *settings* on *system*: ``(design or None, seconds, error or None)``."""
    began = time.perf_counter()
    try:
        d = make_design(system, settings)
    except EquilibristError as exc:
        return None, time.perf_counter() - began, str(exc)
    except (ArithmeticError, np.linalg.LinAlgError, ValueError) as exc:
        return None, time.perf_counter() - began, f"the design failed: {exc}"
    seconds = time.perf_counter() - began
    unstable = [p for p in np.asarray(d.poles, complex) if not abs(p) < 1.0]
    if unstable:
        return None, seconds, DesignError(
            f"the design's closed loop is not stable (pole at |z| = {abs(unstable[0]):.4g})").args[0]
    return d, seconds, None


def redesign(system: System, settings: Settings, plan: Trajectory | None = None
             ) -> tuple[Design | None, float, str | None, Runner | None, float]:
    """Design for *settings*, and build the kind's runner on the design when it asks for one:
    ``(design or None, design seconds, error or None, runner or None, controller seconds)``.
    A controller that cannot be built is an error like a failed design. A kind that tracks
    a plan is built on *plan* (the session's, still valid for *system*); without one, no
    runner: the session plans first (:mod:`equilibrist.web.session_plan`).
    """
    d, seconds, error = design_for(system, settings)
    if d is None or settings.controller not in runner_kinds():
        return d, seconds, error, None, 0.0
    plans = planned(settings.controller)
    if plans and plan is None:
        return d, seconds, error, None, 0.0
    began = time.perf_counter()
    try:
        if plans and plan is not None:
            runner: Runner = build_plan_runner(settings.controller, system, d, plan)
        else:
            runner = build_runner(settings.controller, system, d)
    except EquilibristError as exc:
        return None, seconds, str(exc), None, time.perf_counter() - began
    except (ArithmeticError, np.linalg.LinAlgError, ValueError) as exc:
        return None, seconds, f"the {settings.controller} controller failed: {exc}", None, \
            time.perf_counter() - began
    return d, seconds, None, runner, time.perf_counter() - began
