"""One playground session: a system running in real time under a live-tuned controller.

A :class:`Session` holds the plant's state, the controller in force and the
settings the page tuned. The server calls :meth:`Session.advance_to` with
the wall-clock time before each frame; the session runs every controller
sample due by then (measure with noise, control, saturate, integrate the
nonlinear plant on the system's compiled core, check the region), and
:meth:`Session.frame` describes the latest state for the page: the drawing's
shapes (only those that changed since the last frame), the new samples for
the strip charts, the margin to a fall.

How a sample runs (the rig as the simulator runs it, :mod:`equilibrist.sim.run`):

1. the sensors read the design's outputs with the rig's sensor noise times
   the ``noise`` setting;
2. the controller: ``"lqg"`` the design's discrete Kalman filter and LQR
   gain, ``"lqr"`` the gain on the true state (both as the one controller
   contract, :class:`~equilibrist.control.controller.LinearController`,
   run in numpy); ``"off"`` holds the operating point's input;
3. the actuator saturates the command at the input limits (the ``limit``
   setting scales the rig's limits);
4. a push adds to the first input for its duration, beyond the limits (as
   ``--push`` of ``equilibrist simulate``);
5. the plant advances one control period in RK4 steps of at most 1 ms on the
   compiled core, as ``simulate`` advances it around a Python controller
   (:class:`~equilibrist.native.steps.PlantSteps`): the process noise the
   spec gives on the state rates is white noise of ``simulate``'s model
   (:meth:`~equilibrist.sim.noise.Noise.from_spec`), held over each physics
   step, and the sensors' noise is drawn from the same generator: with the
   controller off and the same seed, a session's run is ``simulate``'s, bit
   for bit;
6. a state outside the system's region ends the run ("fell"); the page
   offers Reset.

Every change of a setting redesigns (:func:`equilibrist.control.design.design`
on the tuned system) outside the simulation's thread; a design that fails
leaves the controller in force running and is reported as a message. A
change of a physical parameter acts on the plant at once, also when the
design for it fails (the rig changed; its controller did not).

The Bryson scales, physical parameters and rate are the design's; the
LQR weights are ``Q = diag(1 / scale^2)``, ``R = diag(1 / scale^2)``; the
measurement noise the Kalman filter assumes follows the ``noise`` setting
(with a floor of 5 % of the rig's, so that the filter stays well posed when
the sensors are made perfect).
"""

from __future__ import annotations

import io
import math
import secrets
import time
import types
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.errors import DesignError, EquilibristError
from equilibrist.web.protocol import Limits, Message, controllers, kind_name
from equilibrist.web.runners import Runner, build_runner, hanging_refusal, runner_kinds, unavailable

if TYPE_CHECKING:
    from equilibrist.control.controller import LinearController
    from equilibrist.control.design import Design
    from equilibrist.numeric.system import System
    from equilibrist.sim.result import SimResult
    from equilibrist.viz.scenes import Scene

#: Longest catch-up after a stall [s]: beyond it the simulation skips ahead.
MAX_CATCH_UP = 0.25
#: Seconds of the last run kept for the downloads.
RECORD_SECONDS = 120.0
#: Chart samples per second sent to the page (at most).
CHART_RATE = 100.0
#: Default push, in multiples of the first input's full scale, and its duration.
PUSH_SIZE = 0.5
PUSH_DURATION = 0.1
#: Physical parameters offered as sliders (the first of the spec's, with a positive default).
MAX_PARAM_SLIDERS = 6
#: Range of a physical parameter's slider, as factors of its default.
PARAM_FACTOR = 4.0
#: Range of a Bryson scale's slider, as factors of its default.
SCALE_FACTOR = 100.0
#: Floor of the measurement noise the Kalman filter assumes, as a fraction of the rig's.
NOISE_FLOOR = 0.05
#: Digits of the drawing's coordinates sent to the page.
DIGITS = 5
#: Frames a page that reports what it has drawn may be behind before frames are held back.
MAX_UNSEEN = 12
#: Chart samples kept for a page that is behind (the oldest are dropped).
MAX_CHART_SAMPLES = 2000
#: Share of the wall time a batch of samples may take before the page is told the loop lags.
LAG_SHARE = 0.8
#: Seconds between two lag warnings of one session.
LAG_WARN_EVERY = 5.0


def label(controller: str) -> str:
    """The picker's label of a controller: its kind's (:mod:`equilibrist.control.kinds`)."""
    from equilibrist.control import kinds

    return kinds.get(kind_name(controller)).label


class SessionError(EquilibristError, ValueError):
    """A request the session cannot carry out (download with the controller off, ...)."""


# -- catalogue -------------------------------------------------------------------


@dataclass
class Catalogue:
    """The systems a server offers, each built once and shared by the sessions.

    *names* are catalogue names or a user's model file given on the command
    line; the page can only pick among them.
    """

    names: tuple[str, ...]
    _systems: dict[str, System] = field(default_factory=dict, repr=False)

    @classmethod
    def default(cls, extra: Sequence[str] = ()) -> Catalogue:
        """Every system of the catalogue with an input, an operating point and a drawing, plus *extra*."""
        from equilibrist.systems import registry
        from equilibrist.viz.scenes import SCENES

        names: list[str] = []
        for entry in registry.all_entries():
            spec = entry.spec
            drawn = spec.name in SCENES
            if drawn and spec.inputs and spec.operating_point is not None and spec.name not in names:
                names.append(spec.name)
        for e in extra:
            if e not in names:
                names.insert(0, e)
        return cls(tuple(names))

    def system(self, name: str) -> System:
        """The system *name* with its default parameters (built on first use)."""
        if name not in self.names:
            raise SessionError(f"system {name!r} is not offered: expected one of {', '.join(self.names)}")
        if name not in self._systems:
            from equilibrist.numeric.system import get_system

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
    """What the page tuned (a value: each change makes a new one)."""

    controller: str
    rate: float
    noise: float
    limit: float
    scales: Mapping[str, float]
    params: Mapping[str, float]

    def changed(self, fields: Mapping[str, Any]) -> Settings:
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
        )

    def to_dict(self) -> dict[str, Any]:
        return {"controller": self.controller, "rate": self.rate, "noise": self.noise,
                "limit": self.limit, "scales": dict(self.scales), "params": dict(self.params)}


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
                    runner: Runner | None = None, controller_seconds: float = 0.0) -> dict[str, Any]:
    """The ``design`` frame: gains, poles, margins (JSON-ready).

    *seconds* is the time of the LQG design, *controller_seconds* the time
    of building the swing-up or the MPC (*runner*) on it.
    """
    full = d.to_dict()
    return {
        "type": "design",
        "controller": controller,
        "rate": d.rate,
        "states": full["states"],
        "inputs": full["inputs"],
        "outputs": full["outputs"],
        "K": full["K"],
        "Kf": full["Kf"],
        "poles": full["poles"],
        "estimator_poles": full["estimator_poles"],
        "open_loop_poles": full["open_loop_poles"],
        "pole_table": full["pole_table"],
        "margins": full["margins"],
        "notes": full["notes"],
        "x0": full["x0"],
        "u0": full["u0"],
        "milliseconds": round((seconds + controller_seconds) * 1e3, 2),
        "design_milliseconds": round(seconds * 1e3, 2),
        "controller_milliseconds": round(controller_seconds * 1e3, 2),
        "controller_info": None if runner is None else runner.describe(),
    }


# -- the running loop ----------------------------------------------------------------


class _Linear:
    """One :class:`~equilibrist.control.controller.LinearController` run sample by sample.

    The contract's form in deviation coordinates (``dy = y - y_op``, no
    reference: ``dr = 0``)::

        u = u_op + Cc z + Dy dy,   x_hat = x_op + Ez z + Ey dy,
        z+ = Ac z + By dy + Bu (u_applied - u_op)

    in plain numpy: a few small products per sample.
    """

    def __init__(self, ctrl: LinearController, system: System) -> None:
        self.ctrl = ctrl
        self.idx = np.array([system.state_index(o) for o in ctrl.output_names], dtype=np.int64)
        self.z = np.array(ctrl.z0, dtype=float)
        self._dy = np.zeros(len(ctrl.output_names))

    def start_at(self, x_estimate: np.ndarray) -> None:
        self.z = self.ctrl.state_map @ (np.asarray(x_estimate, dtype=float) - self.ctrl.x_op)

    def output(self, y: np.ndarray) -> np.ndarray:
        c = self.ctrl
        self._dy = y - c.y_op
        u: np.ndarray = c.u_op + c.Cc @ self.z + c.Dy @ self._dy
        return u

    def estimate(self) -> np.ndarray:
        c = self.ctrl
        x: np.ndarray = c.x_op + c.Ez @ self.z + c.Ey @ self._dy
        return x

    def update(self, u_applied: np.ndarray) -> None:
        c = self.ctrl
        self.z = c.Ac @ self.z + c.By @ self._dy + c.Bu @ (u_applied - c.u_op)


class _Loop:
    """The controllers of one design: LQG (in charge, or its filter running alongside for
    the estimate and a bumpless switch) and LQR on the true state."""

    def __init__(self, d: Design, system: System, previous: _Loop | None = None,
                 runner: Runner | None = None, x_estimate: np.ndarray | None = None) -> None:
        from equilibrist.control.controller import LinearController

        self.design = d
        self.x_op = np.array(d.plant.x0, dtype=float)
        self.u_op = np.array(d.plant.u0, dtype=float)
        self.outputs = tuple(d.plant.output_names)
        self.out_idx = np.array([system.state_index(o) for o in self.outputs], dtype=np.int64)
        self.lqg = _Linear(LinearController.from_design(d, kind="lqg"), system)
        self.lqr = _Linear(LinearController.from_design(d, kind="lqr"), system)
        if previous is not None:
            # The new filter goes on from the previous one's estimate.
            self.lqg.start_at(previous.lqg.estimate())
        # The swing-up or the MPC, when one is in charge: it goes on from the previous
        # one of its kind (a retune), or starts at the estimate in force (a switch).
        self.runner = runner
        self.runner_pick: np.ndarray | None = None
        self.runner_sigma = np.zeros(0)
        if runner is not None:
            prev = previous.runner if previous is not None else None
            if prev is not None and prev.kind == runner.kind:
                runner.adopt(prev)
            elif x_estimate is not None:
                runner.start_at(x_estimate)
            if all(o in self.outputs for o in runner.outputs):
                # The runner reads the same noisy measurement as the filter.
                self.runner_pick = np.array([self.outputs.index(o) for o in runner.outputs],
                                            dtype=np.int64)
            else:
                noise = system.spec.sensor_noise
                self.runner_sigma = np.array([float(noise.get(o, 0.0)) for o in runner.outputs])

    def reset(self) -> None:
        self.lqg.z = np.array(self.lqg.ctrl.z0, dtype=float)
        self.lqr.z = np.array(self.lqr.ctrl.z0, dtype=float)
        if self.runner is not None:
            self.runner.reset()


@dataclass
class _Record:
    """The samples of the last run (since a reset, a rate change or a new system)."""

    capacity: int
    n: int
    m: int
    ny: int
    rows: int = 0
    start: int = 0

    def __post_init__(self) -> None:
        self.time = np.empty(self.capacity)
        self.states = np.empty((self.capacity, self.n))
        self.estimates = np.empty((self.capacity, self.n))
        self.measurements = np.empty((self.capacity, self.ny))
        self.commanded = np.empty((self.capacity, self.m))
        self.saturated = np.empty((self.capacity, self.m))
        self.applied = np.empty((self.capacity, self.m))

    def add(self, t: float, x: np.ndarray, xhat: np.ndarray, y: np.ndarray, u_cmd: np.ndarray,
            u_sat: np.ndarray, u_app: np.ndarray) -> None:
        i = (self.start + self.rows) % self.capacity
        if self.rows == self.capacity:
            self.start = (self.start + 1) % self.capacity
        else:
            self.rows += 1
        self.time[i] = t
        self.states[i] = x
        self.estimates[i] = xhat
        self.measurements[i] = y
        self.commanded[i] = u_cmd
        self.saturated[i] = u_sat
        self.applied[i] = u_app

    def ordered(self, arr: np.ndarray) -> np.ndarray:
        idx = (self.start + np.arange(self.rows)) % self.capacity
        return arr[idx]


class Session:
    """One browser tab's running system (see the module docstring).

    Parameters
    ----------
    catalogue:
        The systems offered.
    system:
        The name of the first system.
    seed:
        Seed of the noise (fresh entropy when None).
    """

    def __init__(self, catalogue: Catalogue, system: str, *, seed: int | None = None) -> None:
        self.catalogue = catalogue
        self.token = secrets.token_urlsafe(18)
        self.rng = np.random.default_rng(seed)
        # The core's generator: the sensors' and the plant's noise, drawn as simulate draws
        # them (same seed, same inputs: the same run).
        from equilibrist.sim.noise import generator_state, seed_sequence

        self.core_rng = generator_state(seed_sequence(seed))
        self.plant: Any = None  # the core's plant steps, rebuilt after any change
        self.paused = False
        self.busy = False  # True while another thread rebuilds the session
        self.frame_no = 0  # frames made
        self.run = 0  # runs started (each reset, hang or new system starts one)
        self.seen: int | None = None  # the last frame the page said it drew
        self.pending_design = 0  # id of the latest design asked for
        self.messages: list[dict[str, Any]] = []  # frames to send besides the next frame
        self.load(system)

    # -- setup --------------------------------------------------------------------------
    def load(self, name: str) -> None:
        """Start *name* with its default settings and design (raises on a failed design)."""
        from equilibrist.sim.kernel import load_kernel
        from equilibrist.viz.scenes import scene_for

        base = self.catalogue.check(name)
        spec = base.spec
        scales = {n: float(spec.design_scales.get(n, 1.0)) for n in (*base.state_names, *base.input_names)}
        params = {p.name: float(base.params[p.name]) for p in self._param_specs(base)}
        settings = Settings("lqg", float(spec.control_rate), 1.0, 1.0,
                            types.MappingProxyType(scales), types.MappingProxyType(params))
        system = tuned_system(base, settings)
        began = time.perf_counter()
        d = make_design(system, settings)
        seconds = time.perf_counter() - began
        self.name = name
        self.base = base
        self.system = system
        self.settings = settings
        self.kernel = load_kernel(system)
        self.scene: Scene = scene_for(system)
        self.loop = _Loop(d, system)
        self.unavailable = unavailable(base)
        self.hang_refusal = hanging_refusal(base)
        self.limits = self._limits()
        self.state_names = system.state_names
        coords = [s for s in system.state_names if not s.endswith("_dot")] or list(system.state_names)
        self.angle_index = system.state_index(next((c for c in coords if c.startswith("theta")), coords[0]))
        self.hanging = False
        self.last_lag_warning = -math.inf
        self._apply_region()
        self._apply_rate()
        self.design_message = describe_design(d, settings.controller, seconds)
        self.messages.append(self.describe())
        self.messages.append(self.design_message)
        self.reset(kick=0.5 * float(spec.design_scales.get(system.state_names[self.angle_index], 0.1)))
        # The core was built (or loaded) above, in the thread that builds the session, not
        # at the first sample on the server's event loop; the plant's steps bind to it now.
        self.plant = self._plant_steps()

    @staticmethod
    def _param_specs(base: System) -> list[Any]:
        picked = [p for p in base.spec.parameters if float(base.params[p.name]) > 0
                  and p.name not in ("g",)]
        return picked[:MAX_PARAM_SLIDERS]

    def _limits(self) -> Limits:
        base = self.base
        scales = {}
        for n in (*base.state_names, *base.input_names):
            d = float(base.spec.design_scales.get(n, 1.0))
            scales[n] = (d / SCALE_FACTOR, d * SCALE_FACTOR)
        params = {}
        for p in self._param_specs(base):
            d = float(base.params[p.name])
            low, high = d / PARAM_FACTOR, d * PARAM_FACTOR
            # Within the parameter's own valid range (open bounds nudged inside).
            low = max(low, p.low if not p.low_open else math.nextafter(p.low, math.inf))
            high = min(high, p.high if not p.high_open else math.nextafter(p.high, -math.inf))
            params[p.name] = (low, high)
        return Limits(self.catalogue.names, types.MappingProxyType(scales),
                      types.MappingProxyType(params),
                      unavailable=types.MappingProxyType(dict(self.unavailable)),
                      hanging=self.hang_refusal)

    def _apply_region(self) -> None:
        """The region in force: the swing-up task's (the track only) while a swing-up runs
        or the run started hanging, the system's (the balance's) otherwise."""
        from equilibrist.tasks import get_task

        system = self.system
        if (self.settings.controller == "swingup" or self.hanging) and self.hang_refusal is None:
            region = dict(get_task(system, "swingup").region)
        else:
            region = dict(system.spec.region)
        self.region_idx = np.array([system.state_index(s) for s in region], dtype=np.int64)
        self.region_lo = np.array([region[s][0] for s in region], dtype=float)
        self.region_hi = np.array([region[s][1] for s in region], dtype=float)

    def _apply_rate(self) -> None:
        rate = self.settings.rate
        self.period = 1.0 / rate
        self.n_sub = max(1, math.ceil(self.period / 1e-3 - 1e-9))
        self.h = self.period / self.n_sub
        self.p = np.array(self.system.p, dtype=float)
        low, high = self.system.input_limits
        self.u_low, self.u_high = np.asarray(low, float), np.asarray(high, float)
        self.chart_every = max(1, round(rate / CHART_RATE))
        n, m = self.system.n_states, self.system.n_inputs
        ny = len(self.loop.outputs)
        self.record = _Record(int(RECORD_SECONDS * rate) + 1, n, m, ny)
        self.sigma_y = np.array([float(self.system.spec.sensor_noise.get(o, 0.0))
                                 for o in self.loop.outputs])
        self.plant = None
        self._anchor(None)

    def _anchor(self, now: float | None) -> None:
        """Tie simulated time to the wall clock afresh (after a pause, a reset, a new rate)."""
        self.wall0: float | None = now
        self.k_since = 0

    def reset(self, kick: float = 0.0, *, hang: bool = False) -> None:
        """Back to the operating point, the main angle offset by *kick*; or, with *hang*,
        to the hanging position (the swing-up task's start, drawn with its small offsets)."""
        if hang:
            from equilibrist.tasks import get_task

            self.x = np.array(get_task(self.system, "swingup").draw_initial(self.rng), dtype=float)
        else:
            self.x = self.loop.x_op.copy()
            self.x[self.angle_index] += kick
        if hang != self.hanging:
            self.hanging = hang
            self._apply_region()
        self.run += 1
        self.mode: str | None = None
        self.mode_since = 0.0
        self.t = 0.0
        self.k = 0
        self.loop.reset()
        self.xhat = self.loop.x_op.copy()
        self.u_cmd = self.loop.u_op.copy()
        self.u_sat = np.clip(self.u_cmd, self.u_low, self.u_high)
        self.u_app = self.u_sat.copy()
        self.y = self.x[self.loop.out_idx].copy()
        self.plant = None
        self.fell: dict[str, Any] | None = None
        self.push_value = 0.0
        self.push_left = 0
        self.push_seq: int | None = None
        self.pushes = 0
        self.record = _Record(self.record.capacity, self.record.n, self.record.m, self.record.ny)
        self.chart_t: list[float] = []
        self.chart_x: list[list[float]] = []
        self.chart_xhat: list[list[float]] = []
        self.chart_u: list[list[float]] = []
        self.sent_shapes: dict[str, tuple[Any, ...]] = {}
        self._anchor(None)

    # -- description ----------------------------------------------------------------------
    def describe(self) -> dict[str, Any]:
        """The ``system`` frame: names, units, slider ranges, the view."""
        system, base, spec = self.system, self.base, self.system.spec
        op = self.loop.x_op
        view = self.scene.extent(np.atleast_2d(op), np.atleast_2d(self.loop.u_op))
        params = []
        for p in self._param_specs(base):
            low, high = self.limits.params[p.name]
            params.append({"name": p.name, "unit": p.unit, "meaning": p.meaning,
                           "default": float(base.params[p.name]), "low": low, "high": high})
        scales = []
        for n in (*base.state_names, *base.input_names):
            low, high = self.limits.scales[n]
            unit = spec.state_unit(n) if n in base.state_names else base.input_units[base.input_index(n)]
            scales.append({"name": n, "unit": unit, "default": float(spec.design_scales.get(n, 1.0)),
                           "low": low, "high": high, "kind": "state" if n in base.state_names else "input"})
        u_low, u_high = base.input_limits
        return {
            "type": "system",
            "name": self.name,
            "key": system.key,
            "title": spec.title,
            "caption": self.scene.caption,
            "systems": list(self.catalogue.names),
            "states": list(system.state_names),
            "state_units": list(system.state_units),
            "inputs": list(system.input_names),
            "input_units": list(system.input_units),
            "input_limits": [[float(a), float(b)] for a, b in zip(u_low, u_high, strict=True)],
            "outputs": list(self.loop.outputs),
            "region": {k: [float(v[0]), float(v[1])] for k, v in spec.region.items()},
            "x_op": op.tolist(),
            "u_op": self.loop.u_op.tolist(),
            "main_state": system.state_names[self.angle_index],
            "view": list(view),
            "controllers": list(controllers()),
            "controller_options": [
                {"name": c, "label": label(c), "available": c not in self.unavailable,
                 "reason": self.unavailable.get(c)} for c in controllers()],
            "hang": {"available": self.hang_refusal is None, "reason": self.hang_refusal},
            "settings": self.settings.to_dict(),
            "scales": scales,
            "params": params,
            "push": {"size": PUSH_SIZE, "duration": PUSH_DURATION},
            "token": self.token,
        }

    # -- messages ---------------------------------------------------------------------------
    def handle(self, message: Message) -> Settings | None:
        """Apply *message*; returns the settings to design for when it asks for a redesign."""
        f = message.fields
        if message.type == "select":
            self.load(f["system"])
        elif message.type == "push":
            if self.fell is None:
                low, high = self.base.input_limits
                full = float(max(abs(low[0]), abs(high[0]))) * self.settings.limit
                self.push_value = f["size"] * full
                duration = f.get("duration", PUSH_DURATION)
                self.push_left = max(1, round(duration * self.settings.rate))
                self.push_seq = message.seq
                self.pushes += 1
        elif message.type == "kick":
            if self.fell is None:
                self.x[self.angle_index] += f["angle"]
        elif message.type == "reset":
            self.reset(kick=f.get("kick", 0.0))
        elif message.type == "hang":
            self.reset(hang=True)
        elif message.type == "pause":
            self.paused = f["paused"]
            self._anchor(None)
        elif message.type == "seen":
            frame = int(f["frame"])
            if frame > self.frame_no:
                raise SessionError(f"seen frame {frame} has not been sent: expected a frame "
                                   f"number from 0 to {self.frame_no}, the last frame sent")
            self.seen = frame
        elif message.type == "full":
            self.sent_shapes = {}
            self.messages.append(self.describe())
            self.messages.append(self.design_message)
        elif message.type == "tune":
            return self.settings.changed(f)
        return None

    def prepare(self, settings: Settings) -> System:
        """The plant for *settings* (raises on parameters that do not go together)."""
        return tuned_system(self.base, settings)

    def install(self, settings: Settings, system: System, d: Design | None,
                seconds: float, error: str | None, runner: Runner | None = None,
                controller_seconds: float = 0.0) -> None:
        """Take *settings* into force: the plant always, the controller when *d* is a design
        (with *runner*, the swing-up or MPC built on it, when one is asked for)."""
        rate_changed = settings.rate != self.settings.rate
        previous_kind = self.settings.controller
        if d is None:
            # The previous controller stays, with its own rate.
            settings = Settings(self.settings.controller if error else settings.controller,
                                self.settings.rate, settings.noise, settings.limit,
                                settings.scales, settings.params)
            rate_changed = False
        self.system = system
        self.settings = settings
        self.p = np.array(system.p, dtype=float)
        self.plant = None
        low, high = system.input_limits
        self.u_low, self.u_high = np.asarray(low, float), np.asarray(high, float)
        if d is not None:
            leaving_swingup = previous_kind == "swingup" and settings.controller != "swingup"
            if leaving_swingup:
                # The swing-up may have caught the pendulum a turn away from the operating point.
                self._wrap_angles()
            self.loop = _Loop(d, system, previous=self.loop, runner=runner, x_estimate=self.xhat)
            if leaving_swingup:
                # The filter ran on a linear model far from where the pendulum was: start it
                # at the swing-up's own estimate.
                self.loop.lqg.start_at(self.xhat)
            self.design_message = describe_design(d, settings.controller, seconds, runner,
                                                  controller_seconds)
            self.messages.append(self.design_message)
            self.mode = None if runner is None else runner.mode
            self.mode_since = self.t
        self._apply_region()
        if rate_changed:
            self._apply_rate()  # a new rate starts a new recording
        if error:
            self.messages.append({"type": "design_error", "message": error,
                                  "controller": self.settings.controller,
                                  "settings": self.settings.to_dict()})

    def _wrap_angles(self) -> None:
        """Each angle (a coordinate in rad) and its estimate within half a turn of the operating point."""
        system = self.system
        x_op = self.loop.x_op
        for i in range(len(system.spec.coordinates)):
            if system.state_units[i] == "rad":
                turns = round((self.x[i] - x_op[i]) / (2 * math.pi))
                if turns:
                    self.x[i] -= 2 * math.pi * turns
                    self.xhat = np.array(self.xhat, dtype=float)
                    self.xhat[i] -= 2 * math.pi * turns

    # -- simulation ---------------------------------------------------------------------------
    def advance_to(self, now: float) -> int:
        """Run the samples due by wall-clock time *now* [s]; returns how many ran."""
        if self.paused or self.fell is not None:
            self._anchor(None)
            return 0
        if self.wall0 is None:
            self._anchor(now)
            return 0
        assert self.wall0 is not None
        due = int((now - self.wall0) * self.settings.rate) - self.k_since
        limit = int(MAX_CATCH_UP * self.settings.rate)
        skipped = due > limit
        if skipped:  # stalled (a slow machine, a debugger): skip ahead
            self.wall0 += (due - limit) / self.settings.rate
            due = limit
        if self.loop.runner is None:
            for _ in range(max(0, due)):
                self._sample()
                self.k_since += 1
                if self.fell is not None:
                    break
            return max(0, due)
        # A swing-up or an MPC: the page is told when the samples cost more than their time.
        began = time.perf_counter()
        for _ in range(max(0, due)):
            self._sample()
            self.k_since += 1
            if self.fell is not None:
                break
        spent = time.perf_counter() - began
        if (due >= 4 and spent > LAG_SHARE * due * self.period) or skipped:
            self._warn_lag(spent / max(due, 1), skipped)
        return max(0, due)

    def _warn_lag(self, per_sample: float, skipped: bool) -> None:
        now = time.monotonic()
        if now - self.last_lag_warning < LAG_WARN_EVERY:
            return
        self.last_lag_warning = now
        runner = self.loop.runner
        what = "the MPC's solves" if runner is not None and runner.kind == "mpc" else "the controller"
        stats = runner.solve_stats() if runner is not None else None
        worst = f" (worst solve {stats['worst_ms']:.2f} ms)" if stats else ""
        self.messages.append({
            "type": "warning",
            "message": (f"the loop cannot keep real time: {what} and the plant take "
                        f"{per_sample * 1e3:.2f} ms a sample{worst} against a period of "
                        f"{self.period * 1e3:.2f} ms"
                        + ("; the simulation skipped ahead" if skipped else "")
                        + ": lower the control rate"),
        })

    def _plant_steps(self) -> Any:
        """The core's plant for the settings in force: the sensor noise of ``simulate``
        (the rig's standard deviations times the ``noise`` setting) and its process
        noise (the spec's, white over the period, held over each physics step)."""
        from equilibrist.sim.noise import Noise, square_root

        system, loop = self.system, self.loop
        noise = Noise.from_spec(system, outputs=loop.outputs, rate=self.settings.rate)
        from equilibrist.control import fixed

        lw = fixed.matmul(noise.process_gain, noise.process_root) / math.sqrt(self.h)
        lw = lw[:, np.any(lw != 0.0, axis=0)]
        lv = np.zeros((0, 0))
        if self.settings.noise > 0 and np.any(self.sigma_y > 0):
            lv = square_root(noise.measurement_covariance, "the sensor noise") * self.settings.noise
        return self.kernel.plant(x=self.x, p=self.p, rate=self.settings.rate, n_sub=self.n_sub,
                                 lw=lw, outputs=loop.out_idx, lv=lv, rng=self.core_rng)

    def _sample(self) -> None:
        loop, x = self.loop, self.x
        if self.plant is None or self.plant.x is not x:
            self.plant = self._plant_steps()
        y = self.plant.measure()
        kind = self.settings.controller
        # The filter runs whichever controller is in charge, so that switching is bumpless.
        u_lqg = loop.lqg.output(y)
        runner = loop.runner if loop.runner is not None and loop.runner.kind == kind else None
        y_r = y
        if kind == "lqg":
            u_cmd = u_lqg
        elif kind == "lqr":
            u_cmd = loop.lqr.output(x[loop.lqr.idx])
        elif runner is not None:
            if loop.runner_pick is not None:
                y_r = y[loop.runner_pick]
            else:
                y_r = x[runner.idx]
                if self.settings.noise > 0 and loop.runner_sigma.size:
                    y_r = y_r + (self.settings.noise * loop.runner_sigma
                                 * self.rng.standard_normal(loop.runner_sigma.size))
            u_cmd = runner.output(self.t, y_r)
        else:
            u_cmd = loop.u_op
        u_sat = np.minimum(np.maximum(u_cmd, self.u_low), self.u_high)
        if kind == "lqr":
            xhat = x.copy()
        elif runner is not None and runner.estimate is not None:
            xhat = runner.estimate
        else:
            xhat = loop.lqg.estimate()
        loop.lqg.update(u_sat)
        if runner is not None:
            runner.update(self.t, y_r, u_sat)
            if runner.mode != self.mode:
                self.mode, self.mode_since = runner.mode, self.t
                if self.hanging and self.mode == "balancing":
                    # Caught: from now on the run is a balance like any other.
                    self.hanging = False
                    self._apply_region()
        u_app = u_sat.copy()
        if self.push_left > 0:
            u_app[0] += self.push_value
            self.push_left -= 1
            if self.push_left == 0:
                self.push_value = 0.0
        self.record.add(self.t, x, xhat, y, u_cmd, u_sat, u_app)
        if self.k % self.chart_every == 0:
            self.chart_t.append(self.t)
            self.chart_x.append(x.tolist())
            self.chart_xhat.append(np.asarray(xhat).tolist())
            self.chart_u.append(u_app.tolist())
        self.y, self.xhat, self.u_cmd, self.u_sat, self.u_app = y, xhat, u_cmd, u_sat, u_app
        self.plant.advance(self.k, u_app)
        self.k += 1
        self.t += self.period
        if not np.all(np.isfinite(x)):
            self.fell = {"at": self.t, "state": "not finite"}
            return
        if self.region_idx.size:
            v = x[self.region_idx]
            out = np.nonzero((v <= self.region_lo) | (v >= self.region_hi))[0]
            if out.size:
                self.fell = {"at": self.t, "state": self.state_names[int(self.region_idx[out[0]])]}

    # -- output ---------------------------------------------------------------------------------
    def margin(self) -> dict[str, Any] | None:
        """How far the state is from leaving its region: ``1`` at the centre, ``0`` at the edge."""
        if not self.region_idx.size:
            return None
        v = self.x[self.region_idx]
        half = (self.region_hi - self.region_lo) / 2
        centre = (self.region_hi + self.region_lo) / 2
        frac = 1.0 - np.abs(v - centre) / half
        i = int(np.argmin(frac))
        return {"fraction": float(np.clip(frac[i], 0.0, 1.0)) if np.isfinite(frac[i]) else 0.0,
                "state": self.state_names[int(self.region_idx[i])]}

    def behind(self) -> bool:
        """Whether the page is too far behind to be sent another frame now.

        A page that reports the frames it drew (``seen``) gets frames no
        faster than it draws them; the chart samples wait for the next frame
        it gets. A client that never reports gets every frame.
        """
        if self.seen is None or self.frame_no - self.seen <= MAX_UNSEEN:
            return False
        if len(self.chart_t) > MAX_CHART_SAMPLES:
            cut = len(self.chart_t) - MAX_CHART_SAMPLES
            del self.chart_t[:cut], self.chart_x[:cut], self.chart_xhat[:cut], self.chart_u[:cut]
        return True

    def frame(self) -> dict[str, Any]:
        """The ``frame`` message for the page (and clears the chart samples sent)."""
        shapes = []
        for s in self.scene.shapes(self.x, self.u_app):
            raw = np.asarray(s.points, float)
            sig = (s.kind, s.color, s.z, s.text, s.edge, s.width, raw.tobytes())
            if self.sent_shapes.get(s.key) == sig:
                continue  # unchanged since the last frame: the page keeps it
            self.sent_shapes[s.key] = sig
            pts = np.round(raw, DIGITS)
            # NaN (a break in a polyline) goes out as null.
            flat = [None if math.isnan(v) else v for v in pts.reshape(-1).tolist()]
            shapes.append({"key": s.key, "kind": s.kind, "points": flat, "color": s.color,
                           "width": s.width, "z": s.z, "text": s.text, "edge": s.edge,
                           "bounds": s.bounds})
        self.frame_no += 1
        out = {
            "type": "frame",
            "n": self.frame_no,
            "run": self.run,
            "t": round(self.t, 6),
            "x": self.x.tolist(),
            "xhat": self.xhat.tolist(),
            "u": self.u_app.tolist(),
            "u_cmd": np.asarray(self.u_cmd).tolist(),
            "u_limits": [self.u_low.tolist(), self.u_high.tolist()],
            "push": self.push_value,
            "pushes": self.pushes,
            "push_seq": self.push_seq,
            "paused": self.paused,
            "fell": self.fell,
            "margin": self.margin(),
            "controller": self.settings.controller,
            "mode": self.mode,
            "mode_since": round(self.mode_since, 4),
            "hanging": self.hanging,
            "solve": self.loop.runner.solve_stats() if self.loop.runner is not None else None,
            "shapes": shapes,
            "samples": {"t": self.chart_t, "x": self.chart_x, "xhat": self.chart_xhat,
                        "u": self.chart_u},
        }
        self.chart_t, self.chart_x, self.chart_xhat, self.chart_u = [], [], [], []
        return out

    def take_messages(self) -> list[dict[str, Any]]:
        out, self.messages = self.messages, []
        return out

    # -- downloads ----------------------------------------------------------------------------
    def last_run(self) -> SimResult:
        """The samples since the last reset, rate change or new system, as a result."""
        from equilibrist.sim.result import SimResult

        rec = self.record
        if rec.rows == 0:
            raise SessionError("nothing has run yet: let the system run a moment first")
        system = self.system
        m = system.n_inputs
        return SimResult(
            system=system.key,
            system_digest=system.digest,
            params=dict(system.params),
            state_names=system.state_names,
            state_units=system.state_units,
            input_names=system.input_names,
            input_units=system.input_units,
            output_names=self.loop.outputs,
            reference_names=(),
            time=rec.ordered(rec.time),
            states=rec.ordered(rec.states),
            estimates=rec.ordered(rec.estimates),
            measurements=rec.ordered(rec.measurements),
            commanded=rec.ordered(rec.commanded),
            saturated=rec.ordered(rec.saturated),
            applied=rec.ordered(rec.applied),
            reference=np.zeros((rec.rows, 0)),
            x_op=self.loop.x_op,
            u_op=self.loop.u_op,
            fell=self.fell is not None,
            fell_at=None if self.fell is None else float(self.fell["at"]),
            fell_state=None if self.fell is None else str(self.fell["state"]),
            fell_x=None if self.fell is None else self.x.copy(),
            final_state=self.x.copy(),
            settings={"source": "playground", "rate": self.settings.rate,
                      "controller": {"kind": self.settings.controller},
                      "playground": self.settings.to_dict(), "inputs": m},
        )

    def run_file(self, kind: str, result: SimResult | None = None) -> bytes:
        """The last run (or *result*, the copy :meth:`last_run` made) as ``"csv"`` or ``"npz"`` bytes.

        The server takes the copy on its event loop, where the samples are
        added, and writes it in another thread: read from there, the record
        could gain a row between its time and its states.
        """
        import tempfile
        from pathlib import Path

        if result is None:
            result = self.last_run()
        with tempfile.TemporaryDirectory(prefix="equilibrist-play-") as tmp:
            path = Path(tmp) / f"run.{kind}"
            written = result.to_csv(path) if kind == "csv" else result.save(path)
            return written.read_bytes()

    def export_zip(self) -> bytes:
        """The C export of the controller in force, as a zip archive."""
        from equilibrist.export.vectors import record
        from equilibrist.export.writer import _describe, controller_data, generator_version, render

        kind = self.settings.controller
        if kind == "off":
            raise SessionError("the controller is off: pick LQG, LQR, swing-up or MPC to export it")
        if self.loop.runner is not None:
            return self._export_runner(self.loop.runner)
        d, system = self.loop.design, self.system
        data = controller_data(d, controller=kind)
        vectors = record(d, system, controller=kind, precision="double")
        title, table = _describe(system, data)
        files = render(data, vectors, precision="double", version=generator_version(),
                       title=title, param_table=table)
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
            for rel, (text, _what) in files.items():
                zf.writestr(f"{data.name}/{rel}", text)
        return buf.getvalue()

    def _export_runner(self, runner: Runner) -> bytes:
        """The swing-up's or the MPC's C export (``equilibrist export --controller ...``), zipped."""
        import tempfile
        from pathlib import Path

        from equilibrist.web.runners import export_folder

        top = f"{self.system.name}_{runner.kind}"
        with tempfile.TemporaryDirectory(prefix="equilibrist-play-") as tmp:
            folder = Path(tmp) / top
            export_folder(runner, self.system, str(folder))
            return _zip_folder(folder, top)


def _zip_folder(folder: Any, top: str) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for path in sorted(folder.rglob("*")):
            if path.is_file():
                zf.write(path, f"{top}/{path.relative_to(folder).as_posix()}")
    return buf.getvalue()


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


def redesign(system: System, settings: Settings) -> tuple[Design | None, float, str | None,
                                                         Runner | None, float]:
    """Design for *settings*, and build the swing-up or MPC on the design when it is asked for.

    Returns ``(design or None, design seconds, error or None, runner or None,
    controller seconds)``; a controller that cannot be built is an error
    like a failed design (the previous controller keeps running).
    """
    d, seconds, error = design_for(system, settings)
    if d is None or settings.controller not in runner_kinds():
        return d, seconds, error, None, 0.0
    began = time.perf_counter()
    try:
        runner = build_runner(settings.controller, system, d)
    except EquilibristError as exc:
        return None, seconds, str(exc), None, time.perf_counter() - began
    except (ArithmeticError, np.linalg.LinAlgError, ValueError) as exc:
        return None, seconds, f"the {settings.controller} controller failed: {exc}", None, \
            time.perf_counter() - began
    return d, seconds, None, runner, time.perf_counter() - began


__all__ = ["Catalogue", "Session", "SessionError", "Settings", "design_for", "make_design",
           "redesign", "tuned_system"]
