"""One playground session: a system running in real time under a live-tuned controller.

A :class:`Session` holds the plant's state, the controller in force and the
settings the page tuned. The server calls :meth:`Session.advance_to` with
the wall-clock time before each frame; the session runs every controller
sample due by then, and :meth:`Session.frame` describes the latest state for
the page (the shapes that changed, the new chart samples, the margin to a fall).

A sample is the rig as the simulator runs it (``docs/playground.md``, "What the page does"):
sensors with the rig's noise times the ``noise`` setting, the controller, the actuator's
saturation, a push beyond the limits, one control period of the plant on the compiled core
(:class:`~equilibrist.sim.steps.PlantSteps`, whose noise is drawn as ``simulate`` draws it:
with the controller off and the same seed, a session's run is ``simulate``'s bit for bit),
and the region's check. With a rig's effects (the ``rig`` setting), the sensors and the
actuator go through them as ``simulate``'s do, in the same plant steps. Every change of a
setting redesigns outside the simulation's thread; a design that fails leaves the controller in force running, while a changed
physical parameter acts on the plant at once.
"""

from __future__ import annotations

import math
import secrets
import time
import types
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.control import fixed
from equilibrist.sim import integrators
from equilibrist.web.protocol import DEFAULT, Limits, Message, controllers
from equilibrist.web.runners import Runner, from_any_state, hanging_refusal, unavailable
from equilibrist.web.session_design import (
    Catalogue,
    SessionError,
    Settings,
    describe_design,
    kind_facts,
    label,
    make_design,
    tuned_system,
)
from equilibrist.web.session_loop import _Loop, _Record
from equilibrist.web.session_plan import _SessionPlan
from equilibrist.web.session_roa import _SessionRoa

if TYPE_CHECKING:
    from equilibrist.control.design_record import Design
    from equilibrist.mechanics.spec import Parameter
    from equilibrist.numeric.system import System
    from equilibrist.sim.steps import PlantSteps
    from equilibrist.viz.drawing import Scene

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


#: Share of the wall time a batch of samples may take before the page is told the loop lags.
LAG_SHARE = 0.8
#: Seconds between two lag warnings of one session.
LAG_WARN_EVERY = 5.0


class Session(_SessionPlan, _SessionRoa):
    """One browser tab's running system: the *catalogue*'s *system* first, its noise seeded
    by *seed* (fresh entropy when None)."""

    def __init__(self, catalogue: Catalogue, system: str, *, seed: int | None = None) -> None:
        self.catalogue = catalogue
        self.token = secrets.token_urlsafe(18)
        self.rng = np.random.default_rng(seed)
        # The core's generator: the sensors' and the plant's noise, drawn as simulate draws
        # them (same seed, same inputs: the same run).
        from equilibrist.sim.noise import generator_state, seed_sequence

        self.core_rng = generator_state(seed_sequence(seed))
        self.plant: PlantSteps | None = None  # the core's plant steps, rebuilt after any change
        self.plant_x: np.ndarray | None = None  # the state array the plant's steps are bound to
        self.paused = False
        self.busy = False  # True while another thread rebuilds the session
        self.frame_no = 0  # frames made
        self.run = 0  # runs started (each reset, hang or new system starts one)
        self.seen: int | None = None  # the last frame the page said it drew
        self.pending_design = 0  # id of the latest design asked for
        self.messages: list[dict[str, object]] = []  # frames to send besides the next frame
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
        settings = Settings(DEFAULT, float(spec.control_rate), 1.0, 1.0,
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
        self.roa_clear()
        self.plan_clear()
        self.messages.append(self.describe())
        self.messages.append(self.design_message)
        self.reset(kick=0.5 * float(spec.design_scales.get(system.state_names[self.angle_index], 0.1)))
        # The core was built (or loaded) above, in the thread that builds the session, not
        # at the first sample on the server's event loop; the plant's steps bind to it now.
        self.plant = self._plant_steps()
        self.plant_x = self.x

    @staticmethod
    def _param_specs(base: System) -> list[Parameter]:
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
        """The region in force: the swing-up task's (the track only) while a controller that
        brings the system up from any state runs (the swing-up: its record's
        :attr:`~equilibrist.controllers.kinds.ControllerKind.from_any_state`) or the run
        started hanging, the system's (the balance's) otherwise."""
        from equilibrist.tasks import get_task

        system = self.system
        anywhere = from_any_state(self.settings.controller)
        if (anywhere or self.hanging) and self.hang_refusal is None:
            region = dict(get_task(system, "swingup").region)
        else:
            region = dict(system.spec.region)
        self.region_idx = np.array([system.state_index(s) for s in region], dtype=np.int64)
        self.region_lo = np.array([region[s][0] for s in region], dtype=float)
        self.region_hi = np.array([region[s][1] for s in region], dtype=float)

    def _apply_rate(self) -> None:
        from equilibrist.sim.setup_steps import default_substeps

        rate = self.settings.rate
        self.period = 1.0 / rate
        self.n_sub = default_substeps(self.period, integrators.DEFAULT)
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
        self.hang_start = self.x.copy() if hang else None
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
        self.fell: dict[str, float | str] | None = None
        self.push_value = 0.0
        self.push_left = 0
        self.push_seq: int | None = None
        self.pushes = 0
        self.record = _Record(self.record.capacity, self.record.n, self.record.m, self.record.ny)
        self.chart_t: list[float] = []
        self.chart_x: list[list[float]] = []
        self.chart_xhat: list[list[float]] = []
        self.chart_u: list[list[float]] = []
        self.sent_shapes: dict[str, tuple[object, ...]] = {}
        self._anchor(None)

    # -- description ----------------------------------------------------------------------
    def describe(self) -> dict[str, object]:
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
                 "reason": self.unavailable.get(c), **kind_facts(c)} for c in controllers()],
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
            settings = self.settings.changed(f)
            rig = settings.rig_effects()
            if rig is not None:
                problems = rig.problems(self.system, settings.rate)
                if problems:
                    raise SessionError("; ".join(problems))
            return settings
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
                                settings.scales, settings.params, settings.rig)
            rate_changed = False
        self.system = system
        self.settings = settings
        self.p = np.array(system.p, dtype=float)
        self.plant = None
        low, high = system.input_limits
        self.u_low, self.u_high = np.asarray(low, float), np.asarray(high, float)
        if d is not None:
            # Leaving a swing-up (a controller that brings the system up from any state).
            leaving_swingup = (from_any_state(previous_kind)
                               and not from_any_state(settings.controller))
            if leaving_swingup:
                # The swing-up may have caught the pendulum a turn away from the operating point.
                self._wrap_angles()
            self.loop = _Loop(d, system, previous=self.loop, runner=runner, x_estimate=self.xhat)
            if leaving_swingup:
                # The filter ran on a linear model far from where the pendulum was: start it
                # at the swing-up's own estimate.
                self.loop.filter.start_at(self.xhat)
            self.design_message = describe_design(d, settings.controller, seconds, runner,
                                                  controller_seconds)
            self.messages.append(self.design_message)
            self.mode = None if runner is None else runner.mode
            self.mode_since = self.t
            self.plan_installed(runner)
        self._apply_region()
        self.roa_clear()  # the slice shown was another loop's
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
        if self.paused or self.fell is not None or self.plan_holding:
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
        began = time.perf_counter()
        for _ in range(max(0, due)):
            self._sample()
            self.k_since += 1
            if self.fell is not None:
                break
        spent = time.perf_counter() - began
        # A swing-up or an MPC: the page is told when the samples cost more than their time.
        if self.loop.runner is not None and (
                (due >= 4 and spent > LAG_SHARE * due * self.period) or skipped):
            self._warn_lag(spent / max(due, 1), skipped)
        return max(0, due)

    def _warn_lag(self, per_sample: float, skipped: bool) -> None:
        now = time.monotonic()
        if now - self.last_lag_warning < LAG_WARN_EVERY:
            return
        self.last_lag_warning = now
        runner = self.loop.runner
        what = runner.busy if runner is not None else "the controller"
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

    def _plant_steps(self) -> PlantSteps:
        """The core's plant for the settings in force: the sensor noise of ``simulate``
        (the rig's standard deviations times the ``noise`` setting) and its process
        noise (the spec's, white over the period, held over each physics step); through the
        rig's effects when the settings have some."""
        from equilibrist.sim.noise import Noise, square_root

        system, loop = self.system, self.loop
        noise = Noise.from_spec(system, outputs=loop.outputs, rate=self.settings.rate)
        lw = fixed.matmul(noise.process_gain, noise.process_root) / math.sqrt(self.h)
        lw = lw[:, np.any(lw != 0.0, axis=0)]
        lv = np.zeros((0, 0))
        if self.settings.noise > 0 and np.any(self.sigma_y > 0):
            lv = square_root(noise.measurement_covariance, "the sensor noise") * self.settings.noise
        rig = self.settings.rig_effects()
        return self.kernel.plant(x=self.x, p=self.p, rate=self.settings.rate, n_sub=self.n_sub,
                                 lw=lw, outputs=loop.out_idx, lv=lv, rng=self.core_rng,
                                 integrator=integrators.DEFAULT, rig=rig,
                                 op=None if rig is None else np.concatenate([loop.x_op, loop.u_op]))

    def _sample(self) -> None:
        loop, x = self.loop, self.x
        if self.plant is None or self.plant_x is not x:
            self.plant = self._plant_steps()
            self.plant_x = x
        y = self.plant.measure(self.k)
        # The filter runs whichever controller is in charge, so that switching is bumpless.
        u_filter = loop.filter.output(y)
        linear = loop.linear(self.settings.controller)
        runner = loop.runner if loop.runner is not None and \
            loop.runner.kind == self.settings.controller else None
        y_r = y
        if linear is loop.filter:
            u_cmd = u_filter
        elif linear is not None:
            u_cmd = linear.output(y[linear.pick] if linear.reads_sensors else x[linear.idx])
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
        if linear is not None and linear is not loop.filter:
            xhat = linear.estimate() if linear.reads_sensors else x.copy()
        elif runner is not None and runner.estimate is not None:
            xhat = runner.estimate
        else:
            xhat = loop.filter.estimate()
        loop.filter.update(u_sat)
        if linear is not None and linear is not loop.filter and linear.ctrl.n_z:
            linear.update(u_sat)
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
        u_app = self.plant.actuate(self.k, u_sat, u_app)  # what acts (through a rig's effects)
        self.record.add(self.t, x, xhat, y, u_cmd, u_sat, u_app)
        if self.k % self.chart_every == 0:
            self.chart_t.append(self.t)
            self.chart_x.append(x.tolist())
            self.chart_xhat.append(np.asarray(xhat).tolist())
            self.chart_u.append(u_app.tolist())
        self.y, self.xhat, self.u_cmd, self.u_sat, self.u_app = y, xhat, u_cmd, u_sat, u_app
        self.plant.advance(self.k)
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


__all__ = [
    "Session",
]
