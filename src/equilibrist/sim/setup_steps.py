"""The steps of :func:`equilibrist.sim.setup.build`, in the order it takes them.

Each step validates one group of settings, appends what is wrong with them to
the shared list of problems (so that every problem is reported at once) and
returns the numbers the core needs; :func:`check_arguments` and
:func:`timing` raise at once where going on would only confuse the report.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from equilibrist.control import fixed
from equilibrist.control.linear import LinearController
from equilibrist.control.nonlinear import NonlinearController
from equilibrist.control.python_controller import PythonController
from equilibrist.errors import EquilibristError, SimulationError
from equilibrist.numeric.system import System
from equilibrist.sim import events as ev
from equilibrist.sim import integrators
from equilibrist.sim.budget import check_steps
from equilibrist.sim.controllers import Resolved, as_controller
from equilibrist.sim.noise import Noise, square_root
from equilibrist.sim.setup_checks import (
    _check_reference,
    _check_regular,
    _has_operating_point,
    _initial_state,
    _names,
    operating_point,
    positive,
)
from equilibrist.sim.signals import Signal, as_signal

PLANTS = ("nonlinear", "linear")
# The default physics step: the control period split into steps of at most this.
DEFAULT_MAX_STEP = 1e-3

Controller = LinearController | NonlinearController | PythonController


def check_arguments(
    events: Sequence[ev.Event], outputs: Sequence[str] | None,
    region: Mapping[str, tuple[float, float]] | None, delay: bool, integrator: str, plant: str,
) -> tuple[Sequence[ev.Event], Sequence[str] | None, Mapping[str, tuple[float, float]] | None,
           str, str]:
    """The arguments of the wrong kind, refused together before anything is computed;
    *events*, *outputs*, *region*, *integrator* and *plant* as the next steps read them
    (a region's bounds as floats)."""
    problems: list[str] = []
    if isinstance(events, str | bytes) or not isinstance(events, Sequence | tuple | list):
        problems.append(f"events = {events!r}: expected a list of events (Kick, Pulse, Impulse, "
                        "ParameterChange)")
        events = ()
    if outputs is not None and not _names(outputs):
        problems.append(f"outputs = {outputs!r}: expected a list of state names")
        outputs = None
    if region is not None and not isinstance(region, Mapping):
        problems.append(f"region = {region!r}: expected a mapping {{state: (low, high)}}")
        region = None
    elif region is not None:
        checked: dict[str, tuple[float, float]] = {}
        for name, bounds in region.items():
            try:
                lo_b, hi_b = (float(b) for b in bounds)
            except (TypeError, ValueError):
                problems.append(f"region of {name!r}: expected (low, high), got {bounds!r}")
                continue
            if math.isnan(lo_b) or math.isnan(hi_b):
                problems.append(f"region of {name!r}: low and high must be numbers, got {bounds!r}")
                continue
            checked[str(name) if isinstance(name, str) else repr(name)] = (lo_b, hi_b)
        region = checked
    if not isinstance(delay, bool | np.bool_):
        problems.append(f"delay = {delay!r}: expected True or False")
    if not isinstance(integrator, str):
        problems.append(f"integrator = {integrator!r}: expected one of "
                        f"{', '.join(integrators.names())}")
        integrator = integrators.DEFAULT
    if not isinstance(plant, str):
        problems.append(f"plant = {plant!r}: expected one of {', '.join(PLANTS)}")
        plant = "nonlinear"
    if problems:
        raise SimulationError("; ".join(problems))
    return events, outputs, region, integrator, plant


def resolve_controller(system: System, controller: object,
                       problems: list[str]) -> tuple[np.ndarray, np.ndarray, Resolved]:
    """The operating point (the controller's, else the system's canonical one) and the
    controller as the simulator runs it."""
    n, m = system.n_states, system.n_inputs
    x_op, u_op = operating_point(system, controller)
    if x_op.size != n or u_op.size != m:
        problems.append(
            f"the controller is for {x_op.size} states and {u_op.size} inputs; "
            f"{system.key} has {n} and {m}"
        )
        x_op, u_op = np.zeros(n), np.zeros(m)
    return x_op, u_op, as_controller(controller, system, x_op, u_op)


def sample_rate(rate: float | None, ctrl_rate: float | None, problems: list[str]) -> float | None:
    """The run's sample rate: the one asked, else the one the controller declares it was
    written for (the two must agree)."""
    if rate is None and ctrl_rate is None:
        problems.append("give the controller's sample rate (rate=... in Hz)")
        run_rate = None
    elif rate is None:
        run_rate = float(ctrl_rate)  # type: ignore[arg-type]
    else:
        run_rate = positive(rate, "rate [Hz]", problems)
        if run_rate is not None and ctrl_rate is not None and not math.isclose(
            run_rate, float(ctrl_rate), rel_tol=1e-12
        ):
            problems.append(
                f"the controller was designed for {float(ctrl_rate):g} Hz but the run asks "
                f"{run_rate:g} Hz: design for the run's rate"
            )
    return run_rate


def solver(integrator: str, plant: str, rtol: float, atol: float,
           problems: list[str]) -> tuple[float | None, float | None]:
    """The integrator and plant checked by name; the tolerances (None if not positive)."""
    wrong = integrators.check(integrator)
    if wrong is not None:
        problems.append(wrong)
    if plant not in PLANTS:
        problems.append(f"plant {plant!r}: expected one of {', '.join(PLANTS)}")
    tol_r = positive(rtol, "rtol", problems)
    tol_a = positive(atol, "atol", problems)
    return tol_r, tol_a


def default_substeps(period: float, integrator: str) -> int:
    """The physics steps of a control period when none is asked: steps of at most
    :data:`DEFAULT_MAX_STEP` for a fixed-step integrator, one period for an adaptive one."""
    known = integrator in integrators.names()
    if known and not integrators.get(integrator).fixed_step:
        return 1
    return max(1, math.ceil(period / DEFAULT_MAX_STEP - 1e-9))


def split_period(run_rate: float, physics_step: float | None, integrator: str,
                 problems: list[str], *, option: str = "the physics step"
                 ) -> tuple[float | None, int | None]:
    """The physics step and the steps per control period: the integrator's default split
    (:func:`default_substeps`), or *physics_step*, which must divide the period (else a
    problem naming *option*, and ``(None, None)``)."""
    period = 1.0 / run_rate
    if physics_step is None:
        n_sub = default_substeps(period, integrator)
        return period / n_sub, n_sub
    step = positive(physics_step, f"{option.removeprefix('the ')} [s]", problems)
    if step is None:
        return None, None
    ratio = period / step
    k = round(ratio)
    if k < 1 or abs(ratio - k) > 1e-9 * max(1.0, ratio):
        sug = period / max(1, math.ceil(ratio))
        problems.append(
            f"{option} {step:g} s does not divide the control period {period:g} s "
            f"({run_rate:g} Hz): use the period divided by a whole number, e.g. {sug:.6g} s"
        )
        return None, None
    return period / k, k


def timing(run_rate: float | None, dur: float | None, physics_step: float | None,
           integrator: str, *, runs: int, bound: float | None, threads: int,
           problems: list[str]) -> tuple[float | None, int | None, int | None]:
    """The physics step ``h``, the steps per sample and the samples of the run.

    The physics step must divide the control period. A run (or batch of
    *runs*) of more physics steps than *bound* is refused at once.
    """
    h = n_sub = n_samples = None
    if run_rate is not None:
        h, n_sub = split_period(run_rate, physics_step, integrator, problems)
        if dur is not None:
            exact = dur * run_rate
            if not math.isfinite(exact):
                problems.append(f"duration {dur:g} s at {run_rate:g} Hz is too many samples to count")
            else:
                n_samples = round(exact) if abs(exact - round(exact)) < 1e-9 * max(1.0, exact) else math.ceil(exact)
                n_samples = max(1, int(n_samples))
            if n_sub is not None and n_samples is not None:
                what = "the run" if runs == 1 else f"a batch of {runs} runs"
                too_many = check_steps(float(n_samples) * n_sub * runs, what, bound, threads)
                if too_many:
                    # Alone: the other settings' checks (memory) would only confuse it.
                    raise SimulationError(too_many)
    return h, n_sub, n_samples


def initial(system: System, x0: object, x_op: np.ndarray, u_op: np.ndarray, designed: bool,
            problems: list[str]) -> np.ndarray:
    """The initial state, checked regular; the operating point's inputs within their limits."""
    names = system.state_names
    lo, hi = system.input_limits
    for i, name in enumerate(system.input_names):
        if not lo[i] <= u_op[i] <= hi[i]:
            problems.append(
                f"the operating point needs {name} = {u_op[i]:g}, outside its limits "
                f"[{lo[i]:g}, {hi[i]:g}] ({name}_min, {name}_max)"
            )
    no_x0 = x0 is None or (isinstance(x0, Mapping) and not x0)
    if no_x0 and not designed and not _has_operating_point(system):
        problems.append(
            f"{system.key} has no canonical operating point: give the initial state "
            f"({', '.join(names)})"
        )
    x_init = _initial_state(system, x0, x_op, problems)
    if not problems:
        try:
            _check_regular(system, x_init)
        except EquilibristError as exc:
            problems.append(f"the initial state is not usable: {exc}")
    return x_init


def measured(system: System, ctrl: Controller, outputs: Sequence[str] | None, *, designed: bool,
             compiled: bool, problems: list[str]) -> tuple[str, ...]:
    """The measured outputs: a designed controller's, else those asked, else those a Python
    controller declares, else the system's (all its states without any)."""
    names = system.state_names
    if designed:
        outs = tuple(ctrl.outputs or ())
    else:
        declared = None if compiled else ctrl.outputs
        if outputs is not None:
            outs = tuple(outputs)
        elif declared is not None:
            outs = tuple(declared)
        else:
            outs = tuple(system.spec.outputs) or tuple(names)
    if outputs is not None and tuple(outputs) != outs:
        problems.append(
            f"outputs {list(outputs)} differ from the controller's measured outputs {list(outs)}"
        )
    bad = [o for o in outs if o not in names]
    if bad:
        problems.append(f"unknown outputs {bad}: the outputs are states of {system.key} ({', '.join(names)})")
        outs = tuple(o for o in outs if o in names)
    return outs


@dataclass(frozen=True)
class Tracking:
    """The states a reference is given for (``tracked``, none without a reference) and
    those a compiled controller reads one of (``ctrl_tracked``), with their indices."""

    tracked: tuple[str, ...]
    ctrl_tracked: tuple[str, ...]
    ref_signal: Signal | None
    r_idx: list[int]
    r_op: np.ndarray
    ctrl_r_idx: list[int]


def tracking(system: System, ctrl: Controller, reference: object, x_op: np.ndarray, *,
             designed: bool, compiled: bool, open_loop: bool, problems: list[str]) -> Tracking:
    """The reference signal, and the states it is for."""
    names = system.state_names
    m = system.n_inputs
    tracked: tuple[str, ...] = ()
    if designed and isinstance(ctrl, LinearController | NonlinearController):
        tracked = tuple(ctrl.tracked)
    elif not compiled and reference is not None:
        tracked = tuple((system.spec.outputs or names)[:m])
    ctrl_tracked = tracked if compiled else ()
    ref_signal = None
    if reference is not None:
        if open_loop:
            problems.append("a reference needs a controller that tracks it (an open loop has none)")
        elif compiled and not tracked:
            problems.append(
                "a reference needs a controller with a reference gain K_c "
                "(from_design(design, tracking=True))"
            )
        else:
            ref_signal = as_signal(reference)
    r_idx = [names.index(t) for t in tracked if t in names]
    r_op = x_op[r_idx] if ref_signal is not None else np.zeros(0)
    if ref_signal is None:
        tracked = ()
    # A compiled controller with tracked outputs reads a reference at every
    # sample: without one given, it is held at the operating point.
    ctrl_r_idx = [names.index(t) for t in ctrl_tracked if t in names]
    return Tracking(tracked, ctrl_tracked, ref_signal, r_idx, r_op, ctrl_r_idx)


@dataclass
class Events:
    """The events as the core takes them: parameter changes (from a physics step on),
    kicks of a state, and pulses of an input (from a step until another)."""

    change_steps: list[int] = field(default_factory=list)
    change_values: list[dict[str, float]] = field(default_factory=list)
    kicks: list[tuple[int, int]] = field(default_factory=list)
    kick_value: list[float] = field(default_factory=list)
    pulses: list[tuple[int, int, int]] = field(default_factory=list)
    pulse_value: list[float] = field(default_factory=list)


def events(system: System, evs: tuple[ev.Event, ...], h: float | None, end_time: float | None,
           problems: list[str]) -> Events:
    """The events checked and placed on the physics steps (without a step, only checked)."""
    names = system.state_names
    m = system.n_inputs
    out = Events()
    changes_sorted: list[ev.ParameterChange] = []
    for e in evs:
        if not isinstance(e, ev.Kick | ev.Pulse | ev.Impulse | ev.ParameterChange):
            problems.append(f"{e!r} is not an event (Kick, Pulse, Impulse or ParameterChange)")
            continue
        t = e.time
        if not isinstance(t, int | float) or not math.isfinite(t) or t < 0:
            problems.append(f"{type(e).__name__} at time {t!r}: expected a finite time >= 0 s")
            continue
        if end_time is not None and t > end_time + 1e-12:
            problems.append(f"{type(e).__name__} at {t:g} s is after the end of the run ({end_time:g} s)")
            continue
        if h is None:
            continue
        step = round(t / h)
        if isinstance(e, ev.Kick):
            if e.state not in names:
                from equilibrist.errors import nearest

                problems.append(f"kick of unknown state {e.state!r} ({nearest(e.state, names)})")
            elif not math.isfinite(e.value):
                problems.append(f"kick value {e.value!r} is not finite")
            else:
                out.kicks.append((step, names.index(e.state)))
                out.kick_value.append(float(e.value))
        elif isinstance(e, ev.Pulse | ev.Impulse):
            if m == 0:
                problems.append(f"{system.key} has no input to push through; use a Kick of a rate")
                continue
            iname = e.input if e.input is not None else system.input_names[0]
            if iname not in system.input_names:
                problems.append(f"push on unknown input {iname!r} (inputs: {', '.join(system.input_names)})")
                continue
            if not math.isfinite(e.value):
                problems.append(f"push value {e.value!r} is not finite")
                continue
            if isinstance(e, ev.Pulse):
                if not (math.isfinite(e.duration) and e.duration > 0):
                    problems.append(f"pulse duration must be positive, got {e.duration!r}")
                    continue
                length = max(1, round(e.duration / h))
                value = float(e.value)
            else:
                length = 1
                value = float(e.value) / h
            out.pulses.append((step, step + length, system.input_names.index(iname)))
            out.pulse_value.append(value)
        else:
            changes_sorted.append(e)
    for e in sorted(changes_sorted, key=lambda c: c.time):
        try:
            system.with_params(**e.values)
        except EquilibristError as exc:
            problems.append(f"parameter change at {e.time:g} s: {exc}")
            continue
        if h is not None:
            out.change_steps.append(round(e.time / h))
            out.change_values.append({k: float(v) for k, v in e.values.items()})
    return out


def region_of(system: System, region: Mapping[str, tuple[float, float]] | None, x_op: np.ndarray,
              designed: bool, problems: list[str]) -> tuple[dict[str, tuple[float, float]], np.ndarray]:
    """The region of the balancing task, by name and as the core's ``(2, n)`` bounds.

    A controller made at another operating point (design --at) outside that
    region holds the system there: the system's region moves with it, by the
    distance between the two points.
    """
    n = system.n_states
    names = system.state_names
    region_spec = dict(system.spec.region if region is None else region)
    outside_op = [name for name, (lo_r, hi_r) in region_spec.items()
                  if name in names and not lo_r < x_op[names.index(name)] < hi_r]
    if region is None and designed and outside_op and _has_operating_point(system):
        canonical = system.operating_point().x
        for name in outside_op:
            lo_r, hi_r = region_spec[name]
            shift = float(x_op[names.index(name)] - canonical[names.index(name)])
            region_spec[name] = (float(lo_r) + shift, float(hi_r) + shift)
    reg = np.array([[-np.inf] * n, [np.inf] * n])
    for name, bounds in region_spec.items():
        if name not in names:
            problems.append(f"region of unknown state {name!r}")
            continue
        try:
            lo_b, hi_b = (float(b) for b in bounds)
        except (TypeError, ValueError):
            problems.append(f"region of {name}: expected (low, high), got {bounds!r}")
            continue
        if not lo_b < hi_b:
            problems.append(f"region of {name}: low {lo_b:g} must be below high {hi_b:g}")
            continue
        reg[0, names.index(name)] = lo_b
        reg[1, names.index(name)] = hi_b
    return region_spec, reg


def noise_roots(noise: Noise | None, n: int, h: float | None, outs: tuple[str, ...],
                problems: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """The square roots the core draws the noise with: ``lw`` of the process noise (per
    physics step, its silent channels dropped) and ``lv`` of the measured outputs'."""
    ny = len(outs)
    lw = np.zeros((n, 0))
    lv = np.zeros((0, 0))
    if noise is not None:
        if not isinstance(noise, Noise):
            problems.append(f"noise must be a Noise or None, got {type(noise).__name__}")
        elif noise.process_gain.shape[0] != n:
            problems.append(
                f"the process noise gain has {noise.process_gain.shape[0]} rows, expected {n}"
            )
        else:
            try:
                sq = noise.process_root
                if h is not None:
                    lw = fixed.matmul(noise.process_gain, sq) / math.sqrt(h)
                    # Channels without noise (zero columns) cost deviates for nothing.
                    lw = lw[:, np.any(lw != 0.0, axis=0)]
                r_full = np.zeros((ny, ny))
                pos = {o: i for i, o in enumerate(outs)}
                for a, oa in enumerate(noise.outputs):
                    for b, ob in enumerate(noise.outputs):
                        if oa in pos and ob in pos:
                            r_full[pos[oa], pos[ob]] = noise.measurement_covariance[a, b]
                lv = square_root(r_full, "the measurement noise covariance") if ny else lv
            except SimulationError as exc:
                problems.append(str(exc))
    return lw, lv


def controller_numbers(ctrl: Controller) -> tuple[np.ndarray, np.ndarray, bool]:
    """A compiled controller's packed parameters, its initial state and whether it
    estimates the state (nothing for a Python controller)."""
    if isinstance(ctrl, LinearController):
        cp, z0, estimates = ctrl.packed(), np.array(ctrl.z0, dtype=float), ctrl.has_estimate
    elif isinstance(ctrl, NonlinearController):
        cp, z0, estimates = np.array(ctrl.params), np.array(ctrl.z0, dtype=float), ctrl.has_estimate
    else:
        cp, z0, estimates = np.zeros(0), np.zeros(0), False
    return cp, z0, estimates


def signals(resolved: Resolved, excitation: object, track: Tracking, *, x_op: np.ndarray,
            u_op: np.ndarray, region_spec: Mapping[str, tuple[float, float]], n_samples: int,
            run_rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, Signal | None]:
    """The sample times, the reference at them, the input added to the command (the
    open loop's signal and the excitation) and the excitation as a signal."""
    m = u_op.shape[0]
    compiled = resolved.compiled
    n_rows = n_samples + 1
    times = np.arange(n_samples + 1) / run_rate
    times.flags.writeable = False  # shared by the results' time axes
    ref = np.zeros((n_rows, len(track.tracked)))
    if track.ref_signal is not None:
        ref = np.ascontiguousarray(track.ref_signal.evaluate(times, x_op[track.r_idx]), dtype=float)
        _check_reference(ref, times, track.tracked, x_op[track.r_idx], region_spec)
    elif track.ctrl_tracked:
        ref = np.ascontiguousarray(np.tile(x_op[track.ctrl_r_idx], (n_rows, 1)), dtype=float)
    uff = np.zeros((n_rows, m))
    if resolved.signal is not None:
        uff = np.ascontiguousarray(as_signal(resolved.signal).evaluate(times, u_op) - u_op)
    excite = None
    if excitation is not None:  # on top of the command, before the actuator's limits
        if not compiled:
            raise SimulationError("an excitation is added to the command of a compiled controller "
                                  "(open loop, linear or nonlinear), not of a Python one")
        excite = as_signal(excitation)
        uff = np.ascontiguousarray(uff + excite.evaluate(times, np.zeros(m)))
    if not np.all(np.isfinite(uff)):
        k = int(np.nonzero(~np.all(np.isfinite(uff), axis=1))[0][0])
        raise SimulationError(f"the input added to the command is not finite at t = {times[k]:g} s "
                              f"({uff[k].tolist()}): expected finite values over the run")
    return times, ref, uff, excite
