"""Validated run settings turned into the compiled core's packed arrays.

Shared by single runs and batches, so both hand the core exactly the same
numbers. Every problem with the settings is collected and raised once, as
one :class:`~equilibrist.errors.SimulationError`.

:func:`build` is here, with the settings it remembers between runs; its steps
are in :mod:`equilibrist.sim.setup_steps`, the checks of single settings in
:mod:`equilibrist.sim.setup_checks`, the bounds of a job's work in
:mod:`equilibrist.sim.budget`, and :class:`Setup` in
:mod:`equilibrist.sim.setup_data`.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence

import numpy as np

from equilibrist.control.linear import LinearController
from equilibrist.control.nonlinear import NonlinearController
from equilibrist.errors import SimulationError
from equilibrist.numeric.system import System
from equilibrist.sim import events as ev
from equilibrist.sim import setup_steps as steps
from equilibrist.sim.budget import (
    DEFAULT_MAX_STEPS,
    check_max_steps,
    check_memory,
)
from equilibrist.sim.controllers import LQG, StateFeedback
from equilibrist.sim.noise import Noise
from equilibrist.sim.rig import Rig
from equilibrist.sim.rig import check as check_rig
from equilibrist.sim.setup_checks import (
    _check_regular,
    _has_operating_point,
    _initial_state,
    _names,
    check_system,
    positive,
)
from equilibrist.sim.setup_data import Setup

# Settings of compiled runs validated and packed before, keyed by everything but the
# initial state (immutable values only: the system, a compiled controller, the noise,
# by identity; the other settings by value). A run asked again with another initial
# state only checks and replaces that state.
# key -> (controller, noise, setup)
_BUILT: dict[tuple[Hashable, ...], tuple[object, object, Setup]] = {}
_BUILT_MAX = 8
_IMMUTABLE_CONTROLLERS = (StateFeedback, LQG, LinearController, NonlinearController)


def _scalar(value: object) -> bool:
    return value is None or isinstance(value, bool | int | float | str)


def _built_key(system: System, controller: object,
               settings: dict[str, object]) -> tuple[Hashable, ...] | None:
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
    rig: Rig | None = None,
) -> Setup:
    """Validate the settings of a run (collecting every problem) and pack them.

    *max_steps* bounds the physics steps of the run, or of *runs* of them
    (a batch on *threads* threads); None sets no bound. Settings met before
    (the same system, compiled controller and noise, the same numbers; any
    initial state) are not validated and packed again: only the initial
    state is.
    """
    settings: dict[str, object] = dict(duration=duration, rate=rate, physics_step=physics_step,
                    integrator=integrator, rtol=rtol, atol=atol, plant=plant, x0=x0,
                    delay=delay, noise=noise, reference=reference, events=events,
                    outputs=outputs, region=region, excitation=excitation,
                    max_steps=max_steps, runs=runs, threads=threads, rig=rig)
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
    events, outputs, region, integrator, plant = steps.check_arguments(
        events, outputs, region, delay, integrator, plant)
    problems: list[str] = []
    n, m = system.n_states, system.n_inputs
    names = system.state_names
    x_op, u_op, resolved = steps.resolve_controller(system, controller, problems)
    ctrl = resolved.controller
    compiled = resolved.compiled
    open_loop = isinstance(ctrl, LinearController) and ctrl.kind == "none"
    designed = compiled and not open_loop

    dur = positive(duration, "duration [s]", problems)
    # A controller may declare the rate it was written for.
    run_rate = steps.sample_rate(rate, ctrl.rate, problems)
    tol_r, tol_a = steps.solver(integrator, plant, rtol, atol, problems)
    h, n_sub, n_samples = steps.timing(run_rate, dur, physics_step, integrator, runs=runs,
                                       bound=bound, threads=threads, problems=problems)
    x_init = steps.initial(system, x0, x_op, u_op, designed, problems)
    outs = steps.measured(system, ctrl, outputs, designed=designed, compiled=compiled,
                          problems=problems)
    c_idx = np.array([names.index(o) for o in outs], dtype=np.int64)
    ny = len(outs)
    track = steps.tracking(system, ctrl, reference, x_op, designed=designed, compiled=compiled,
                           open_loop=open_loop, problems=problems)
    evs = tuple(events)
    end_time = None if (n_samples is None or run_rate is None) else n_samples / run_rate
    placed = steps.events(system, evs, h, end_time, problems)
    region_spec, reg = steps.region_of(system, region, x_op, designed, problems)
    lw, lv = steps.noise_roots(noise, n, h, outs, problems)
    the_rig = check_rig(rig)
    if the_rig is not None:
        problems += the_rig.problems(system, run_rate)

    if problems or h is None or n_sub is None or n_samples is None or run_rate is None or dur is None:
        raise SimulationError("; ".join(problems) if problems else "invalid simulation settings")

    cp, z0, estimates = steps.controller_numbers(ctrl)
    n_rows = n_samples + 1
    check_memory(n_rows * (2 * n + ny + 4 * m + 2 * max(len(track.tracked), len(track.ctrl_tracked))
                           + 2) * 8.0,
                 f"a run of {n_rows} samples", None)
    times, ref, uff, excite = steps.signals(resolved, excitation, track, x_op=x_op, u_op=u_op,
                                            region_spec=region_spec, n_samples=n_samples,
                                            run_rate=run_rate)

    setup = Setup(
        system=system, controller=ctrl, compiled=compiled, estimates=estimates,
        description=resolved.description, cp=cp, z0=z0, rate=run_rate,
        h=h, n_sub=n_sub, n_samples=n_samples, integrator=integrator, rtol=float(tol_r or rtol),
        atol=float(tol_a or atol), plant=plant, delay=bool(delay), x0=x_init, x_op=x_op,
        u_op=u_op, outputs=outs, c_idx=c_idx, tracked=track.tracked,
        r_op=np.array(track.r_op, dtype=float),
        times=times, ref=ref, uff=uff, op=np.concatenate([x_op, u_op]), lv=np.ascontiguousarray(lv), lw=np.ascontiguousarray(lw), noise=noise,
        events=evs, change_steps=np.array(placed.change_steps, dtype=np.int64),
        change_values=tuple(placed.change_values),
        kicks=np.array(placed.kicks, dtype=np.int64).reshape(-1, 2),
        kick_value=np.array(placed.kick_value, dtype=float),
        pulses=np.array(placed.pulses, dtype=np.int64).reshape(-1, 3),
        pulse_value=np.array(placed.pulse_value, dtype=float), region=reg, region_spec=region_spec,
        duration=float(dur), reference=track.ref_signal, excitation=excite, rig=the_rig,
    )
    if key is not None and setup.compiled:
        if len(_BUILT) >= _BUILT_MAX:
            _BUILT.pop(next(iter(_BUILT)))
        _BUILT[key] = (controller, noise, setup)
    return setup


__all__ = [
    "build",
]
