"""One closed-loop run, as a rig runs it.

The nonlinear plant (the system's own ``f``) is integrated between the
controller's samples; the controller runs at its sample rate with
zero-order hold. At each sample ``t_k = k T``:

1. the sensors read the measured outputs, with noise;
2. the controller estimates the state (a Kalman filter for LQG, the
   measured state for state feedback) and computes its command;
3. the actuator saturates the command at the input limits; with
   ``delay=True`` the command acts one sample late (computation delay);
4. the plant runs ``T / h`` physics steps of length ``h`` (RK4, or an
   adaptive Dormand-Prince 5(4) over each step, or the exact solution of
   the linearization with ``plant="linear"``) with the input held, process
   noise held over each step, and the events (pushes, parameter changes)
   that fall on the physics grid;
5. after each physics step the state is checked against the system's
   region; leaving it (or ceasing to be finite) ends the run with
   ``fell = True`` and the time.

Everything the controller does is in deviation coordinates about its
operating point; the result is reported in absolute ones.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any, TypeVar

import numpy as np

from equilibrist import interrupt
from equilibrist.control.linear import LinearController
from equilibrist.control.nonlinear import NonlinearController
from equilibrist.errors import SimulationError
from equilibrist.numeric.system import System
from equilibrist.sim import budget, integrators, layout, setup_data
from equilibrist.sim import setup as _setup
from equilibrist.sim.events import Event
from equilibrist.sim.kernel import Kernel
from equilibrist.sim.noise import Noise, SeedLike, describe_seed, generator_state, seed_sequence
from equilibrist.sim.result import SimResult
from equilibrist.sim.rig import Rig
from equilibrist.sim.steps import SetupSteps

# A run of at most this many physics steps (RK4 or the linear plant) is one
# call of the compiled core in the calling thread: a few milliseconds, too
# short for Ctrl-C to wait for, too short to pay for a thread. A longer run
# is made in the helper thread of `call_interruptibly`, in calls of the core
# that grow to about CHUNK_SECONDS each (the core resumes a run at any
# sample); the core reads a stop flag at every sample, so Ctrl-C stops it
# at once whatever the size of a call.
CHUNK_SECONDS = 0.2
_FIRST_CHUNK_STEPS = 20_000
# How often the waiting thread looks at the run (progress bar, Ctrl-C) [s].
_POLL_SECONDS = 0.05

T = TypeVar("T")


def next_chunk(chunk: int, seconds: float) -> int:
    """The size of the next call of the core after *chunk* units took *seconds*."""
    if seconds <= 0:
        return chunk * 4
    return max(1, min(chunk * 4, int(chunk * CHUNK_SECONDS / seconds)))


def call_interruptibly(work: Callable[[], T], stop: np.ndarray,
                       poll: Callable[[], None] | None = None) -> T:
    """``work()``, a call of the compiled core that reads *stop*, stoppable by Ctrl-C.

    Signals reach Python only in the main thread, and only between bytecodes:
    while the core runs there, Ctrl-C waits for it. So from the main thread
    *work* runs in a helper thread (the core's entries release the GIL) while
    this one waits in short intervals, calling *poll* (a progress bar). A
    KeyboardInterrupt (Ctrl-C; on the command line SIGTERM too) sets
    ``stop[0]``, which the core reads at every sample, waits for the helper
    to return and is raised again. From any other thread, which receives no
    signals, *work* runs right there. An interrupt recorded by the command
    line's handlers (:mod:`equilibrist.interrupt`) is raised here too, so one
    whose exception a finalizer swallowed still stops the run.
    """
    if threading.current_thread() is not threading.main_thread():
        return work()
    # An interrupt whose exception a finalizer swallowed (equilibrist.interrupt).
    interrupt.raise_if_requested()
    value: list[T] = []
    error: list[BaseException] = []

    def target() -> None:
        try:
            value.append(work())
        except BaseException as exc:  # handed to the waiting thread
            error.append(exc)

    helper = threading.Thread(target=target, name="equilibrist-core", daemon=True)
    helper.start()
    try:
        while helper.is_alive():
            helper.join(_POLL_SECONDS)
            interrupt.raise_if_requested()
            if poll is not None:
                poll()
    except BaseException:
        stop[0] = 1
        helper.join()
        raise
    if error:
        raise error[0]
    return value[0]


def fall_reason(code: int, state_names: Sequence[str]) -> str:
    """The name of the state that left its region, or why the run stopped."""
    if code >= 0:
        return state_names[code]
    return {-2: "not finite", -3: "integrator failed"}.get(code, "unknown")


def simulate(
    system: System,
    controller: object = None,
    *,
    duration: float,
    rate: float | None = None,
    physics_step: float | None = None,
    integrator: str = integrators.DEFAULT,
    rtol: float = integrators.RTOL,
    atol: float = integrators.ATOL,
    plant: str = "nonlinear",
    x0: Mapping[str, float] | Sequence[float] | np.ndarray | None = None,
    delay: bool = False,
    noise: Noise | None = None,
    seed: SeedLike = None,
    reference: object = None,
    events: Sequence[Event] = (),
    outputs: Sequence[str] | None = None,
    region: Mapping[str, tuple[float, float]] | None = None,
    progress: bool = False,
    excitation: object = None,
    max_steps: float | None = budget.DEFAULT_MAX_STEPS,
    rig: Rig | None = None,
) -> SimResult:
    """Simulate *system* under *controller* for *duration* seconds.

    Parameters
    ----------
    system : System
        The plant, with its parameters (``get_system(...)``).
    controller : LinearController, NonlinearController, PythonController, OpenLoop, StateFeedback, LQG, or None
        The first two run compiled; a PythonController (or an object with
        the older ``step``, or a function ``(t, y, r)``) is called once
        per sample. None runs open loop at the operating point's input.
        See :mod:`equilibrist.control.controller` and
        :mod:`equilibrist.sim.controllers`.
    duration : float
        Seconds to simulate, rounded up to a whole number of control periods.
    rate : float, optional
        Controller sample rate [Hz]; defaults to the controller's design rate.
    physics_step : float, optional
        Integration step [s]; must divide the control period. Default: the
        period split into steps of at most 1 ms (a fixed-step integrator) or
        the period itself (an adaptive one).
    integrator : str
        A name of :mod:`equilibrist.sim.integrators`' table: ``"rk4"``
        (fixed-step RK4, the default), ``"adaptive"`` (Dormand-Prince 5(4)
        with *rtol*, *atol* inside each physics step), or one registered.
    plant : {"nonlinear", "linear"}
        The system's own dynamics, or its linearization at the operating
        point (propagated exactly, by matrix exponential).
    x0 : mapping or vector, optional
        Initial state (absolute): a full vector, or ``{name: value}``
        overriding components of the operating point.
    delay : bool
        Apply each command one sample late (one-sample computation delay).
    noise : Noise, optional
        Process and sensor noise (``Noise.from_design(design)``); None: none.
    seed : int or SeedSequence, optional
        Seed of the noise (fresh entropy when None; the result records it).
    reference : signal, optional
        Reference of the tracked outputs (absolute); needs a controller with
        ``K_c`` or a Python controller.
    events : sequence of Kick, Pulse, Impulse, ParameterChange
        Things that happen during the run (:mod:`equilibrist.sim.events`).
    outputs : sequence of str, optional
        Measured states for an open loop or a Python controller (default:
        the system's default outputs).
    region : mapping, optional
        ``{state: (low, high)}`` outside which the run has fallen (default:
        the system's; ``{}`` never stops).
    progress : bool
        Show a progress bar on stderr for runs longer than a second.
    excitation : signal, optional
        Added to the controller's command before the actuator's limits
        (:class:`~equilibrist.sim.signals.Chirp`, :class:`~equilibrist.sim.signals.PRBS`):
        an identification experiment. The logged input is what acted.
    max_steps : float or None
        The most physics steps the run may take (default
        :data:`~equilibrist.sim.setup.DEFAULT_MAX_STEPS`); a run that needs
        more is refused before it starts. None: no bound.
    rig : Rig, optional
        A rig's effects between the plant and the controller (torque response,
        delays, noise, encoders, perturbations: :mod:`equilibrist.sim.rig`);
        None: none. Recorded in the result's settings (``"rig"``).

    Returns
    -------
    SimResult
    """
    setup = _setup.build(
        system, controller, duration=duration, rate=rate, physics_step=physics_step,
        integrator=integrator, rtol=rtol, atol=atol, plant=plant, x0=x0, delay=delay,
        noise=noise, reference=reference, events=events, outputs=outputs, region=region,
        excitation=excitation, max_steps=max_steps, rig=rig,
    )
    draws = noise is not None or (setup.rig is not None and setup.rig.draws)
    seq = seed_sequence(seed) if (draws or seed is not None) else None
    rng = generator_state(seq) if seq is not None else np.zeros(4, dtype=np.uint64)
    kernel = Kernel(system, setup.nonlinear)
    if setup.compiled:
        return _run_compiled(setup, kernel, rng, seq, progress)
    return _run_python(setup, kernel, rng, seq, progress)


def _progress_bar(total: int, enabled: bool, unit: str) -> Any:
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit=unit, file=sys.stderr, delay=1.0, leave=False,
                dynamic_ncols=True)


def _run_compiled(setup: setup_data.Setup, kernel: Kernel, rng: np.ndarray,
                  seq: np.random.SeedSequence | None, progress: bool) -> SimResult:
    n = setup.system.n_states
    x = setup.x0.copy()
    p_sets = setup.p_sets(np.array(setup.system.p))
    rec = np.empty((setup.n_rows, setup.record_width))
    status = np.zeros(len(layout.STATUS), dtype=np.int64)
    fell_x = np.zeros(n)
    stop = np.zeros(1, dtype=np.int64)
    core = kernel.core(setup.cp)
    rig_i, rig_f = setup.rig_arrays()
    gforce, pulses = setup.rig_forces(seq)
    # A single run's metrics come from its trajectory: nothing is accumulated.
    arrays: dict[str, Any] = dict(
        iopts=setup.iopts(accumulate=False), fopts=setup.fopts, x=x, z=setup.z0.copy(),
        u_prev=np.zeros(setup.system.n_inputs), rng=rng, op=setup.op, c_idx=setup.c_idx,
        cp=setup.cp, ref=setup.ref, uff=setup.uff, lv=setup.lv, lw=setup.lw, p_sets=p_sets,
        p_switch=setup.p_switch, lin_s=setup.linear_blocks(p_sets), region=setup.region,
        kicks=setup.kicks, kick_value=setup.kick_value, pulses=setup.pulses,
        pulse_value=setup.pulse_value, rec_cols=setup.rec_cols, acc_cols=setup.acc_cols,
        rec=rec, acc=np.zeros(setup.acc_len), status=status, fell_x=fell_x, stop=stop,
        rig_i=rig_i, rig_f=rig_f, rig_s=setup.rig_state(), gforce=gforce,
    )
    total = setup.n_rows
    rows, fell = layout.STATUS["rows"], layout.STATUS["fell"]
    if integrators.get(setup.integrator).fixed_step \
            and setup.n_samples * setup.n_sub <= _FIRST_CHUNK_STEPS:
        core.run_one(k_start=0, k_end=total, **arrays)
        return _result(setup, rec, int(status[rows]), status, fell_x, x, seq,
                       estimates=setup.estimates, pulses=pulses)
    if not kernel.compiled(setup.cp):  # compiled (or loaded) here: Ctrl-C can stop that
        core.run_one(k_start=0, k_end=0, **arrays)

    def pieces() -> None:
        # Calls that grow to about CHUNK_SECONDS: the run resumes at any sample.
        chunk = max(1, _FIRST_CHUNK_STEPS // setup.n_sub)
        k = 0
        while k < total and not stop[0]:
            k_end = min(total, k + chunk)
            t0 = time.perf_counter()
            core.run_one(k_start=k, k_end=k_end, **arrays)
            chunk = next_chunk(k_end - k, time.perf_counter() - t0)
            if status[fell] or status[rows] < k_end:
                break
            k = k_end

    bar = _progress_bar(total, progress, "samples")

    def show() -> None:
        if bar is not None:
            bar.update(int(status[rows]) - bar.n)

    try:
        call_interruptibly(pieces, stop, show)
    finally:
        if bar is not None:
            bar.close()
    return _result(setup, rec, int(status[rows]), status, fell_x, x, seq,
                   estimates=setup.estimates, pulses=pulses)


class StopRun(Exception):
    """Raised by a Python controller's ``output`` or ``update`` to end the run there.

    The result holds the samples before the one being computed (a device in
    the loop that stopped answering; the controller says why itself).
    """


def _run_python(setup: setup_data.Setup, kernel: Kernel, rng: np.ndarray,
                seq: np.random.SeedSequence | None, progress: bool) -> SimResult:
    """A run of a :class:`~equilibrist.control.controller.PythonController`: the core
    measures and advances the plant, the controller is called in between."""
    ctrl = setup.controller
    assert not isinstance(ctrl, LinearController | NonlinearController)  # those run compiled
    sysm = setup.system
    n, m = sysm.n_states, sysm.n_inputs
    ctrl.reset()
    plant = SetupSteps(setup, kernel, rng, seq)
    x, y, p_sets, status, scr = plant.x, plant.y, plant.p_sets, plant.status, plant.scr
    fell_row = layout.SCRATCH["fell_x"]
    rec = np.empty((setup.n_rows, setup.record_width))
    cols = layout.RECORD.slices(**setup.sizes)
    base = len(sysm.spec.parameter_names) - 2 * m
    u_prev = None
    has_estimate = False
    bar = _progress_bar(setup.n_rows, progress, "samples")
    rows = 0
    try:
        for k in range(setup.n_rows):
            plant.measure(k)
            t = float(setup.times[k])
            r = setup.ref[k].copy()
            try:
                raw = ctrl.output(t, y.copy(), r)
            except StopRun:  # the controller ended the run: the samples before this one stay
                break
            u_cmd = np.asarray(raw, dtype=float).reshape(-1)
            if u_cmd.size != m or not np.all(np.isfinite(u_cmd)):
                raise SimulationError(
                    f"the controller returned {np.asarray(raw).tolist()!r} at t = {t:g} s: "
                    f"expected {m} finite input value(s) ({', '.join(sysm.input_names)})"
                )
            ps = int(np.searchsorted(setup.p_switch, k * setup.n_sub, side="right") - 1)
            lo = p_sets[ps, base::2][:m]
            hi = p_sets[ps, base + 1 :: 2][:m]
            u_sat = np.minimum(np.maximum(u_cmd, lo), hi)
            if u_prev is None:
                u_prev = np.minimum(np.maximum(setup.u_op, lo), hi)
            u_app = u_prev if setup.delay else u_sat
            u_prev = u_sat
            acted = plant.actuate(k, u_app, lo, hi)
            try:
                ctrl.update(t, y.copy(), r, u_app.copy())
            except StopRun:
                break
            est = ctrl.estimate
            rec[k, cols["x"]] = x
            if est is not None:
                has_estimate = True
                rec[k, cols["x_hat"]] = np.asarray(est, dtype=float).reshape(n)
            else:
                rec[k, cols["x_hat"]] = np.nan
            rec[k, cols["y"]] = y
            rec[k, cols["u_cmd"]] = u_cmd
            rec[k, cols["u_sat"]] = u_sat
            rec[k, cols["u_app"]] = acted
            rows = k + 1
            if bar is not None and k % 1000 == 0:
                bar.update(k + 1 - bar.n)
            if k == 0:
                outside = _outside(x, setup.region)
                if outside != -1:
                    status[:] = layout.STATUS.pack(np.int64, rows=rows, fell=1,
                                                   fell_code=outside, fell_step=0)
                    scr[fell_row, :n] = x
                    break
            if k >= setup.n_samples:
                break
            if plant.advance(k):
                break
    finally:
        if bar is not None:
            bar.close()
    status[layout.STATUS["rows"]] = rows
    return _result(setup, rec, rows, status, scr[fell_row, :n].copy(), x, seq,
                   estimates=has_estimate, pulses=plant.pulses)


def _outside(x: np.ndarray, region: np.ndarray) -> int:
    if not np.all(np.isfinite(x)):
        return -2
    out = np.nonzero((x <= region[0]) | (x >= region[1]))[0]
    return int(out[0]) if out.size else -1


def _result(setup: setup_data.Setup, rec: np.ndarray, rows: int, status: np.ndarray,
            fell_x: np.ndarray, x_end: np.ndarray, seq: np.random.SeedSequence | None,
            *, estimates: bool, pulses: dict[str, object] | None = None) -> SimResult:
    """The result of a run recorded in *rec* (its first *rows* rows).

    The result's arrays are read-only views of *rec* (which nothing else
    keeps), not copies; a run that ended early is copied, so that it does
    not keep the unused rows alive.
    """
    sysm = setup.system
    cols = layout.RECORD.slices(**setup.sizes)
    st = layout.STATUS
    r = rec[:rows] if 2 * rows > rec.shape[0] else rec[:rows].copy()
    r.flags.writeable = False
    fell = bool(status[st["fell"]])
    settings = setup.describe()
    settings["seed"] = None if seq is None else describe_seed(seq)
    if pulses is not None:
        settings["rig"] = {**setup.rig.describe(), "pulses": pulses} if setup.rig else pulses
    return SimResult(
        system=sysm.key,
        system_digest=sysm.digest,
        params=dict(sysm.params),
        state_names=sysm.state_names,
        state_units=sysm.state_units,
        input_names=sysm.input_names,
        input_units=sysm.input_units,
        output_names=setup.outputs,
        reference_names=setup.tracked,
        time=setup.times[:rows],
        states=r[:, cols["x"]],
        estimates=r[:, cols["x_hat"]] if estimates else None,
        measurements=r[:, cols["y"]],
        commanded=r[:, cols["u_cmd"]],
        saturated=r[:, cols["u_sat"]],
        applied=r[:, cols["u_app"]],
        reference=setup.ref[:rows, : len(setup.tracked)],
        x_op=setup.x_op,
        u_op=setup.u_op,
        fell=fell,
        fell_at=float(status[st["fell_step"]] * setup.h) if fell else None,
        fell_state=fall_reason(int(status[st["fell_code"]]), sysm.state_names) if fell else None,
        fell_x=fell_x.copy() if fell else None,
        final_state=x_end.copy(),
        settings=settings,
    )
