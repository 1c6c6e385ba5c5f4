"""Validated run settings turned into the compiled core's packed arrays.

Shared by single runs and batches, so both hand the core exactly the same
numbers. Every problem with the settings is collected and raised once, as
one :class:`~equilibrist.errors.SimulationError`.
"""

from __future__ import annotations

import math
import os
import weakref
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from equilibrist.control.controller import LinearController, NonlinearController
from equilibrist.errors import EquilibristError, NoEquilibriumError, SimulationError
from equilibrist.numeric.system import System
from equilibrist.sim import events as ev
from equilibrist.sim import layout
from equilibrist.sim.controllers import LQG, StateFeedback, as_controller
from equilibrist.sim.noise import Noise, square_root
from equilibrist.sim.signals import as_signal

INTEGRATORS = {"rk4": 0, "adaptive": 1}
PLANTS = ("nonlinear", "linear")
# The default physics step: the control period split into steps of at most this.
DEFAULT_MAX_STEP = 1e-3
# Fraction of the available memory a run or batch may take.
MEMORY_FRACTION = 0.5
# The most physics steps a run (or a batch, over all its runs) may take
# unless asked for more (``max_steps=``, ``--max-steps``): some minutes of
# work on a fast machine, hours on a slow one. A mistyped physics step
# (1e-12 s) asks for a million times more and is refused before anything runs.
DEFAULT_MAX_STEPS = 10_000_000_000
# A generous speed of the compiled core per core [physics steps per second]:
# the time a refused request would take is stated as at least this long.
FAST_STEPS_PER_SECOND = 1e8


def _fmt_seconds(s: float) -> str:
    for unit, size in (("years", 365.25 * 86400), ("days", 86400), ("hours", 3600), ("minutes", 60)):
        if s >= 2 * size:
            return f"{s / size:.3g} {unit}"
    return f"{s:.3g} s"


def check_steps(steps: float, what: str, max_steps: float | None, threads: int = 1) -> str | None:
    """The problem with a run or batch of *steps* physics steps, if more than *max_steps*.

    ``max_steps=None`` (or infinite) sets no bound.
    """
    if max_steps is None or steps <= max_steps:
        return None
    at_least = steps / (FAST_STEPS_PER_SECOND * max(1, threads))
    return (
        f"{what} asks for {steps:.3g} physics steps, more than the {max_steps:.3g} allowed "
        f"(it would take at least {_fmt_seconds(at_least)} at "
        f"{FAST_STEPS_PER_SECOND / 1e6:.0f} M steps/s per core): use a larger physics step, a "
        f"shorter duration or fewer runs, or ask for it anyway with --max-steps {steps:.3g} "
        f"(max_steps={steps:.3g} in Python)"
    )


def check_max_steps(value: object) -> float | None:
    """*value* as a bound on physics steps (None or inf: no bound)."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise SimulationError(f"max_steps = {value!r}: expected a number of physics steps >= 1 "
                              "(or None for no bound)")
    v = float(value)
    if math.isnan(v) or v < 1:
        raise SimulationError(f"max_steps = {value!r}: expected a number of physics steps >= 1 "
                              "(or None for no bound)")
    return None if math.isinf(v) else v


def available_memory() -> int:
    """Bytes of memory available now (``MemAvailable``; 4 GiB if unknown)."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:  # pragma: no cover - not Linux
        pass
    try:  # pragma: no cover - not Linux
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover
        return 4 << 30


def _fmt_bytes(n: float) -> str:
    for unit in ("bytes", "KiB", "MiB", "GiB", "TiB"):
        if n < 1024 or unit == "TiB":
            return f"{n:.0f} {unit}" if unit == "bytes" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"  # pragma: no cover


def check_memory(n_bytes: float, what: str, limit: float | None) -> None:
    """Refuse (before allocating) a job that needs more than *limit* bytes."""
    if limit is None and n_bytes < 64 << 20:
        return  # small enough anywhere; spares reading /proc on every run
    cap = MEMORY_FRACTION * available_memory() if limit is None else float(limit)
    if n_bytes > cap:
        raise SimulationError(
            f"{what} needs {_fmt_bytes(n_bytes)} of memory, more than the "
            f"{_fmt_bytes(cap)} allowed (half the available memory): "
            "shorten it, lower the rate, or run fewer at once"
        )


@dataclass(frozen=True, eq=False)
class Setup:
    """Everything a run needs, validated, with the core's packed arrays."""

    system: System
    controller: Any
    compiled: bool
    estimates: bool
    description: dict[str, Any]
    cp: np.ndarray
    z0: np.ndarray
    rate: float
    h: float
    n_sub: int
    n_samples: int
    integrator: str
    rtol: float
    atol: float
    plant: str
    delay: bool
    x0: np.ndarray
    x_op: np.ndarray
    u_op: np.ndarray
    outputs: tuple[str, ...]
    c_idx: np.ndarray
    tracked: tuple[str, ...]
    r_op: np.ndarray
    times: np.ndarray
    ref: np.ndarray
    uff: np.ndarray
    op: np.ndarray
    lv: np.ndarray
    lw: np.ndarray
    noise: Noise | None
    events: tuple[ev.Event, ...]
    change_steps: np.ndarray
    change_values: tuple[dict[str, float], ...]
    kicks: np.ndarray
    kick_value: np.ndarray
    pulses: np.ndarray
    pulse_value: np.ndarray
    region: np.ndarray
    region_spec: dict[str, tuple[float, float]]
    duration: float
    reference: Any
    excitation: Any = None

    @property
    def n_rows(self) -> int:
        return self.n_samples + 1

    @property
    def nonlinear(self) -> NonlinearController | None:
        """The nonlinear controller whose kernel runs this setup, if any."""
        return self.controller if isinstance(self.controller, NonlinearController) else None

    def iopts(self, *, record: bool = True, accumulate: bool = True) -> np.ndarray:
        """The core's integer options: *record* the trajectory, *accumulate* the peaks
        and sums of a batch's outcomes (a single run's come from its trajectory)."""
        return layout.IOPTS.pack(
            np.int64, n_samples=self.n_samples, record=int(record), delay=int(self.delay),
            n_sub=self.n_sub, estimates=int(self.estimates), accumulate=int(accumulate),
            integrator=layout.INTEGRATORS["linear" if self.plant == "linear" else self.integrator],
        )

    @property
    def fopts(self) -> np.ndarray:
        return layout.FOPTS.pack(h=self.h, rtol=self.rtol, atol=self.atol, rate=self.rate)

    @property
    def sizes(self) -> dict[str, int]:
        return {"n": self.x_op.shape[0], "m": self.u_op.shape[0], "ny": len(self.outputs)}

    @property
    def rec_cols(self) -> np.ndarray:
        return layout.RECORD.offsets(n=self.x_op.shape[0], m=self.u_op.shape[0],
                                     ny=len(self.outputs))

    @property
    def acc_cols(self) -> np.ndarray:
        return layout.ACC.offsets(n=self.x_op.shape[0], m=self.u_op.shape[0],
                                  ny=len(self.outputs))

    @property
    def record_width(self) -> int:
        return layout.RECORD.width(**self.sizes)

    @property
    def acc_len(self) -> int:
        return layout.ACC.width(**self.sizes)

    def p_sets(self, base: np.ndarray) -> np.ndarray:
        """The parameter sets of the run from parameter vector(s) *base*: ``(..., n_sets, n_p)``.

        Each change sets its parameters from its time on, on top of the
        parameters before it.
        """
        base = np.asarray(base, dtype=float)
        if not self.change_values:
            return np.ascontiguousarray(base[..., None, :])
        names = self.system.spec.parameter_names
        sets = [base]
        for values in self.change_values:
            nxt = sets[-1].copy()
            for name, v in values.items():
                nxt[..., names.index(name)] = v
            sets.append(nxt)
        return np.ascontiguousarray(np.stack(sets, axis=-2))

    @property
    def p_switch(self) -> np.ndarray:
        return np.concatenate([[0], self.change_steps]).astype(np.int64)

    def linear_blocks(self, p_sets: np.ndarray) -> np.ndarray:
        """``[Phi | E | Gamma | f0]`` per parameter set (``(n_sets, n, 2n+m+1)``), or empty."""
        n, m = self.system.n_states, self.system.n_inputs
        if self.plant != "linear":
            return np.zeros((p_sets.shape[0], 0, 0))
        from scipy.linalg import expm

        names = self.system.spec.parameter_names
        out = np.zeros((p_sets.shape[0], n, 2 * n + m + 1))
        for j, pv in enumerate(p_sets):
            sysj = self.system.with_params(**dict(zip(names, pv.tolist(), strict=True)))
            A, B = sysj.jacobians(self.x_op, self.u_op)
            f0 = sysj.f(self.x_op, self.u_op)
            aug = np.zeros((2 * n, 2 * n))
            aug[:n, :n] = A
            aug[:n, n:] = np.eye(n)
            big = expm(aug * self.h)
            phi, ex = big[:n, :n], big[:n, n:]
            out[j, :, :n] = phi
            out[j, :, n : 2 * n] = ex
            out[j, :, 2 * n : 2 * n + m] = ex @ B
            out[j, :, 2 * n + m] = f0
        return out

    def describe(self) -> dict[str, Any]:
        """The settings as JSON-able data (recorded with every result)."""
        return {
            "system": self.system.key,
            "controller": self.description,
            "duration": self.duration,
            "n_samples": self.n_samples,
            "rate": self.rate,
            "physics_step": self.h,
            "substeps": self.n_sub,
            "integrator": self.integrator,
            "rtol": self.rtol,
            "atol": self.atol,
            "plant": self.plant,
            "delay": self.delay,
            "x0": self.x0.tolist(),
            "outputs": list(self.outputs),
            "noise": None if self.noise is None else self.noise.describe(),
            "reference": None if self.reference is None else self.reference.describe(),
            "tracked": list(self.tracked),
            "events": ev.describe(self.events),
            "region": {k: [lo, hi] for k, (lo, hi) in self.region_spec.items()},
            "excitation": None if self.excitation is None else self.excitation.describe(),
        }


def _positive(value: object, what: str, problems: list[str]) -> float | None:
    try:
        v = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        problems.append(f"{what} {value!r} is not a number")
        return None
    if not math.isfinite(v) or v <= 0:
        problems.append(f"{what} must be a positive number, got {value!r}")
        return None
    return v


def _initial_state(system: System, x0: object, x_op: np.ndarray, problems: list[str]) -> np.ndarray:
    x = x_op.copy()
    if x0 is None:
        return x
    if isinstance(x0, Mapping):
        for name, value in x0.items():
            if name not in system.state_names:
                from equilibrist.errors import nearest

                problems.append(f"initial state: no state {name!r} ({nearest(str(name), system.state_names)})")
                continue
            try:
                v = float(value)
            except (TypeError, ValueError):
                problems.append(f"initial state {name} = {value!r} is not a number")
                continue
            if not math.isfinite(v):
                problems.append(f"initial state {name} = {value} is not a finite number")
                continue
            x[system.state_names.index(name)] = v
        return x
    try:
        arr = np.asarray(x0, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        problems.append(f"initial state {x0!r} is not a vector of numbers")
        return x
    if arr.size != system.n_states:
        problems.append(
            f"initial state has {arr.size} values, expected {system.n_states} "
            f"({', '.join(system.state_names)})"
        )
        return x
    if not np.all(np.isfinite(arr)):
        problems.append(f"initial state {arr.tolist()} has a value that is not a finite number")
        return x
    return arr


# How far a reference may go from the operating point, in units of the
# tracked state's region (its width; 1 in the state's unit where unbounded).
REFERENCE_REACH = 1e12


def _check_reference(ref: np.ndarray, times: np.ndarray, tracked: Sequence[str],
                     r_op: np.ndarray, region_spec: Mapping[str, tuple[float, float]]) -> None:
    """Refuse a reference that is not finite, or so far away its command would overflow.

    A reference may lie outside the system's region (the run then falls,
    as it would on the rig), but not beyond :data:`REFERENCE_REACH` times
    that region's width from the operating point: the command ``K_c r``
    of such a value is no longer a number the plant can take.
    """
    for j, name in enumerate(tracked):
        col = ref[:, j]
        lo, hi = region_spec.get(name, (-math.inf, math.inf))
        width = float(hi) - float(lo)
        scale = width if math.isfinite(width) and width > 0 else 1.0
        reach = REFERENCE_REACH * scale
        bad = ~np.isfinite(col) | (np.abs(col - r_op[j]) > reach)
        if bad.any():
            k = int(np.nonzero(bad)[0][0])
            raise SimulationError(
                f"the reference of {name} is {col[k]:g} at t = {times[k]:g} s: a reference must "
                f"stay finite and within {reach:g} of the operating point {r_op[j]:g} "
                f"({REFERENCE_REACH:g} times the width of {name}'s region)"
            )


def check_system(system: object) -> None:
    """Refuse anything but a :class:`~equilibrist.numeric.system.System` as the plant."""
    if not isinstance(system, System):
        raise SimulationError(
            f"system = {system!r}: expected a System (equilibrist.get_system(name)), "
            f"not {type(system).__name__}"
        )


def _names(value: object) -> bool:
    """Whether *value* is a list (or tuple) of names."""
    return (isinstance(value, Sequence) and not isinstance(value, str | bytes)
            and all(isinstance(v, str) for v in value))


# What is known of a system (it is immutable): whether it has a canonical
# operating point, and initial states checked regular. Solving the point
# and the mass matrix's condition number cost more than a short run.
_KNOWN: weakref.WeakKeyDictionary[System, dict[Any, bool]] = weakref.WeakKeyDictionary()
_KNOWN_MAX = 256


def _known(system: System) -> dict[Any, bool]:
    known = _KNOWN.get(system)
    if known is None or len(known) > _KNOWN_MAX:
        known = _KNOWN[system] = {}
    return known


def _has_operating_point(system: System) -> bool:
    known = _known(system)
    found = known.get("operating point")
    if found is None:
        try:
            system.operating_point()
            found = True
        except NoEquilibriumError:
            found = False
        known["operating point"] = found
    return found


def _check_regular(system: System, x: np.ndarray) -> None:
    """``system.check_regular(x)``, remembered for the states it passed."""
    known = _known(system)
    key = x.tobytes()
    if key not in known:
        system.check_regular(x)
        known[key] = True


def operating_point(system: System, controller: Any) -> tuple[np.ndarray, np.ndarray]:
    """The controller's operating point; the system's canonical one for others.

    A system without a canonical point (the zxz gyroscope) runs open loop
    about zero input, with deviations measured from zero.
    """
    if isinstance(controller, NonlinearController) or (
        isinstance(controller, StateFeedback | LQG | LinearController) and controller.kind != "none"
    ):
        return np.array(controller.x_op), np.array(controller.u_op)
    try:
        eq = system.operating_point()
    except NoEquilibriumError:
        return np.zeros(system.n_states), np.zeros(system.n_inputs)
    return np.array(eq.x), np.array(eq.u)


# Settings of compiled runs validated and packed before, keyed by everything but the
# initial state (immutable values only: the system, a compiled controller, the noise,
# by identity; the other settings by value). A run asked again with another initial
# state only checks and replaces that state.
_BUILT: dict[tuple[Any, ...], tuple[object, object, Setup]] = {}  # key -> (controller, noise, setup)
_BUILT_MAX = 8
_IMMUTABLE_CONTROLLERS = (StateFeedback, LQG, LinearController, NonlinearController)


def _scalar(value: object) -> bool:
    return value is None or isinstance(value, bool | int | float | str)


def _built_key(system: System, controller: object, settings: dict[str, Any]) -> tuple[Any, ...] | None:
    """The key of :data:`_BUILT` for these settings, or None when they are not all immutable."""
    if controller is not None and not isinstance(controller, _IMMUTABLE_CONTROLLERS):
        return None
    noise = settings["noise"]
    if noise is not None and not isinstance(noise, Noise):
        return None
    events = settings["events"]
    if (settings["reference"] is not None or settings["excitation"] is not None
            or settings["region"] is not None
            or not (isinstance(events, tuple | list) and len(events) == 0)):
        return None
    outputs = settings["outputs"]
    if outputs is not None and not (isinstance(outputs, tuple) and _names(outputs)):
        return None
    scalars = tuple((k, v) for k, v in settings.items()
                    if k not in ("noise", "reference", "excitation", "region", "events",
                                 "outputs", "x0"))
    if not all(_scalar(v) for _k, v in scalars):
        return None
    return (id(system), id(controller), id(noise), outputs, scalars)


def _with_x0(known: Setup, system: System, x0: object) -> Setup | None:
    """*known* with initial state *x0*, if *x0* passes the checks :func:`build` makes of it."""
    if x0 is None or (isinstance(x0, Mapping) and not x0):
        designed = known.compiled and not (isinstance(known.controller, LinearController)
                                           and known.controller.kind == "none")
        if not designed and not _has_operating_point(system):
            return None
    problems: list[str] = []
    try:
        x_init = _initial_state(system, x0, known.x_op, problems)
        if problems:
            return None
        _check_regular(system, x_init)
    except Exception:  # any problem: the full validation says what it is
        return None
    fresh = object.__new__(Setup)
    fresh.__dict__.update(known.__dict__)
    fresh.__dict__["x0"] = x_init if x_init is not known.x_op else x_init.copy()
    return fresh


def build(
    system: System,
    controller: object,
    *,
    duration: float,
    rate: float | None,
    physics_step: float | None,
    integrator: str,
    rtol: float,
    atol: float,
    plant: str,
    x0: object,
    delay: bool,
    noise: Noise | None,
    reference: object,
    events: Sequence[ev.Event],
    outputs: Sequence[str] | None,
    region: Mapping[str, tuple[float, float]] | None,
    excitation: object = None,
    max_steps: object = DEFAULT_MAX_STEPS,
    runs: int = 1,
    threads: int = 1,
) -> Setup:
    """Validate the settings of a run (collecting every problem) and pack them.

    *max_steps* bounds the physics steps of the run, or of *runs* of them
    (a batch on *threads* threads); None sets no bound. Settings met before
    (the same system, compiled controller and noise, the same numbers; any
    initial state) are not validated and packed again: only the initial
    state is.
    """
    settings: dict[str, Any] = dict(duration=duration, rate=rate, physics_step=physics_step,
                    integrator=integrator, rtol=rtol, atol=atol, plant=plant, x0=x0,
                    delay=delay, noise=noise, reference=reference, events=events,
                    outputs=outputs, region=region, excitation=excitation,
                    max_steps=max_steps, runs=runs, threads=threads)
    key = _built_key(system, controller, settings) if isinstance(system, System) else None
    if key is not None:
        entry = _BUILT.get(key)
        # The entry keeps its objects alive, so their ids name them.
        if entry is not None and entry[0] is controller and entry[1] is noise \
                and entry[2].system is system:
            fresh = _with_x0(entry[2], system, x0)
            if fresh is not None:
                return fresh
    bound = check_max_steps(max_steps)
    check_system(system)
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
        problems.append(f"integrator = {integrator!r}: expected one of {', '.join(INTEGRATORS)}")
        integrator = "rk4"
    if not isinstance(plant, str):
        problems.append(f"plant = {plant!r}: expected one of {', '.join(PLANTS)}")
        plant = "nonlinear"
    if problems:
        raise SimulationError("; ".join(problems))
    n, m = system.n_states, system.n_inputs
    names = system.state_names
    # Operating point: the controller's, else the system's canonical one.
    x_op, u_op = operating_point(system, controller)
    if x_op.size != n or u_op.size != m:
        problems.append(
            f"the controller is for {x_op.size} states and {u_op.size} inputs; "
            f"{system.key} has {n} and {m}"
        )
        x_op, u_op = np.zeros(n), np.zeros(m)
    resolved = as_controller(controller, system, x_op, u_op)
    ctrl = resolved.controller
    compiled = resolved.compiled
    open_loop = isinstance(ctrl, LinearController) and ctrl.kind == "none"
    designed = compiled and not open_loop

    dur = _positive(duration, "duration [s]", problems)
    # A controller may declare the rate it was written for.
    ctrl_rate = ctrl.rate
    if rate is None and ctrl_rate is None:
        problems.append("give the controller's sample rate (rate=... in Hz)")
        run_rate = None
    elif rate is None:
        run_rate = float(ctrl_rate)  # type: ignore[arg-type]
    else:
        run_rate = _positive(rate, "rate [Hz]", problems)
        if run_rate is not None and ctrl_rate is not None and not math.isclose(
            run_rate, float(ctrl_rate), rel_tol=1e-12
        ):
            problems.append(
                f"the controller was designed for {float(ctrl_rate):g} Hz but the run asks "
                f"{run_rate:g} Hz: design for the run's rate"
            )
    if integrator not in INTEGRATORS:
        problems.append(f"integrator {integrator!r}: expected one of {', '.join(INTEGRATORS)}")
    if plant not in PLANTS:
        problems.append(f"plant {plant!r}: expected one of {', '.join(PLANTS)}")
    tol_r = _positive(rtol, "rtol", problems)
    tol_a = _positive(atol, "atol", problems)

    # Timing: the physics step must divide the control period.
    h = n_sub = n_samples = None
    if run_rate is not None:
        period = 1.0 / run_rate
        if physics_step is None:
            n_sub = 1 if integrator == "adaptive" else max(1, math.ceil(period / DEFAULT_MAX_STEP - 1e-9))
            h = period / n_sub
        else:
            step = _positive(physics_step, "physics step [s]", problems)
            if step is not None:
                ratio = period / step
                k = round(ratio)
                if k < 1 or abs(ratio - k) > 1e-9 * max(1.0, ratio):
                    sug = period / max(1, math.ceil(ratio))
                    problems.append(
                        f"the physics step {step:g} s does not divide the control period "
                        f"{period:g} s ({run_rate:g} Hz): use the period divided by a whole "
                        f"number, e.g. {sug:.6g} s"
                    )
                else:
                    n_sub = k
                    h = period / k
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

    # Initial state, measured outputs.
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
    c_idx = np.array([names.index(o) for o in outs], dtype=np.int64)
    ny = len(outs)

    # Reference and feedforward signals.
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

    # Events.
    evs = tuple(events)
    change_steps: list[int] = []
    change_values: list[dict[str, float]] = []
    kicks: list[tuple[int, int]] = []
    kick_value: list[float] = []
    pulses: list[tuple[int, int, int]] = []
    pulse_value: list[float] = []
    end_time = None if (n_samples is None or run_rate is None) else n_samples / run_rate
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
                kicks.append((step, names.index(e.state)))
                kick_value.append(float(e.value))
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
            pulses.append((step, step + length, system.input_names.index(iname)))
            pulse_value.append(value)
        else:
            changes_sorted.append(e)
    for e in sorted(changes_sorted, key=lambda c: c.time):
        try:
            system.with_params(**e.values)
        except EquilibristError as exc:
            problems.append(f"parameter change at {e.time:g} s: {exc}")
            continue
        if h is not None:
            change_steps.append(round(e.time / h))
            change_values.append({k: float(v) for k, v in e.values.items()})

    # Region of the balancing task. A controller made at another operating
    # point (design --at) outside that region holds the system there: the
    # system's region moves with it, by the distance between the two points.
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

    # Noise.
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
                    lw = noise.process_gain @ sq / math.sqrt(h)
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

    if problems or h is None or n_sub is None or n_samples is None or run_rate is None or dur is None:
        raise SimulationError("; ".join(problems) if problems else "invalid simulation settings")

    # The controller's numbers.
    if isinstance(ctrl, LinearController):
        cp, z0, estimates = ctrl.packed(), np.array(ctrl.z0, dtype=float), ctrl.has_estimate
    elif isinstance(ctrl, NonlinearController):
        cp, z0, estimates = np.array(ctrl.params), np.array(ctrl.z0, dtype=float), ctrl.has_estimate
    else:
        cp, z0, estimates = np.zeros(0), np.zeros(0), False

    n_rows = n_samples + 1
    check_memory(n_rows * (2 * n + ny + 4 * m + 2 * max(len(tracked), len(ctrl_tracked)) + 2) * 8.0,
                 f"a run of {n_rows} samples", None)
    times = np.arange(n_samples + 1) / run_rate
    times.flags.writeable = False  # shared by the results' time axes
    ref = np.zeros((n_rows, len(tracked)))
    if ref_signal is not None:
        ref = np.ascontiguousarray(ref_signal.evaluate(times, x_op[r_idx]), dtype=float)
        _check_reference(ref, times, tracked, x_op[r_idx], region_spec)
    elif ctrl_tracked:
        ref = np.ascontiguousarray(np.tile(x_op[ctrl_r_idx], (n_rows, 1)), dtype=float)
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

    setup = Setup(
        system=system, controller=ctrl, compiled=compiled, estimates=estimates,
        description=resolved.description, cp=cp, z0=z0, rate=run_rate,
        h=h, n_sub=n_sub, n_samples=n_samples, integrator=integrator, rtol=float(tol_r or rtol),
        atol=float(tol_a or atol), plant=plant, delay=bool(delay), x0=x_init, x_op=x_op,
        u_op=u_op, outputs=outs, c_idx=c_idx, tracked=tracked, r_op=np.array(r_op, dtype=float),
        times=times, ref=ref, uff=uff, op=np.concatenate([x_op, u_op]), lv=np.ascontiguousarray(lv), lw=np.ascontiguousarray(lw), noise=noise,
        events=evs, change_steps=np.array(change_steps, dtype=np.int64),
        change_values=tuple(change_values),
        kicks=np.array(kicks, dtype=np.int64).reshape(-1, 2),
        kick_value=np.array(kick_value, dtype=float),
        pulses=np.array(pulses, dtype=np.int64).reshape(-1, 3),
        pulse_value=np.array(pulse_value, dtype=float), region=reg, region_spec=region_spec,
        duration=float(dur), reference=ref_signal, excitation=excite,
    )
    if key is not None and setup.compiled:
        if len(_BUILT) >= _BUILT_MAX:
            _BUILT.pop(next(iter(_BUILT)))
        _BUILT[key] = (controller, noise, setup)
    return setup
