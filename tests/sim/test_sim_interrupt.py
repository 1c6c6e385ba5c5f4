"""Ctrl-C (and SIGTERM) stop a long run or batch at once, whatever the size of its runs.

The compiled core reads a stop flag at every sample and runs in a helper
thread while the main thread, which receives the signals, waits; so a
single run of minutes, or a batch whose every run takes minutes, stops
within a fraction of a second, prints its one line and writes nothing.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
from tests.support.signals import STOPS_WITHIN, signal_while_working, start_at_work

from equilibrist.numeric.lookup import get_system
from equilibrist.sim import simulate, simulate_batch

# Each single run takes minutes on any machine: 2000 s of the cart-pole with a 1 us physics
# step is 2e9 RK4 steps (more than a minute even on a fast core), as are the batch's runs.
# "At once" is then a bound far below that (STOPS_WITHIN), not a guess of this machine's speed.
SIMULATE = ["simulate", "cartpole", "--duration", "2000", "--physics-step", "1e-6",
            "--no-progress", "--noise", "off", "--out", "run.npz"]
BATCH = ["batch", "cartpole", "--runs", "4", "--duration", "20000", "--physics-step", "1e-5",
         "--no-progress", "--noise", "off", "--max-steps", "1e11", "--out", "batch.npz"]


@pytest.fixture(scope="module")
def warm(tmp_path_factory: pytest.TempPathFactory) -> None:
    """The cores of both commands compiled (and cached on disk) before any is interrupted:
    each command run short in this process (the same cores as the long runs', which are
    keyed by what they compile, not by the run's length)."""
    from equilibrist.cli.main import main

    folder = tmp_path_factory.mktemp("warm")
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(folder)
        for argv in (SIMULATE, BATCH):
            short = [a if a not in ("2000", "20000") else "0.01" for a in argv]
            assert main(short) == 0


#: Where each command's runs enter the core (run.py calls it by its module's name, batch.py
#: by the name it imported).
CORE = {"simulate": "equilibrist.sim.run", "batch": "equilibrist.sim.batch"}


@pytest.mark.parametrize("argv", [SIMULATE, BATCH], ids=["simulate", "batch"])
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_stops_a_long_run_at_once(warm, tmp_path, argv, signum) -> None:
    # Started and working in the core: its runs begun there (its first call of
    # call_interruptibly, past the imports and the cached core's load) and half a second of
    # its CPU since, so the signal lands inside the compiled loop.
    proc, ready = start_at_work(argv, tmp_path, f"{CORE[argv[0]]}:call_interruptibly")
    code, out, err, took = signal_while_working(proc, signum, ready)
    assert code == (143 if signum == signal.SIGTERM else 130), err.decode()
    assert err.decode().strip() == "equilibrist: interrupted"
    assert out == b""
    assert sorted(p.name for p in tmp_path.iterdir()) == []
    assert took < STOPS_WITHIN, f"took {took:.2f} s to stop"


def test_the_stop_flag_ends_the_core_from_another_thread() -> None:
    # The core releases the GIL and reads the flag at every sample: set from this thread
    # while a helper runs a run of 2e8 steps, it ends that run where it is.
    from equilibrist.sim import layout
    from equilibrist.sim import setup as _setup
    from equilibrist.sim.kernel import Kernel

    system = get_system("cartpole")
    setup = _setup.build(system, None, duration=2000.0, rate=100.0, physics_step=1e-5,
                         integrator="rk4", rtol=1e-8, atol=1e-10, plant="nonlinear",
                         x0={"theta": 0.0}, delay=False, noise=None, reference=None, events=(),
                         outputs=None, region={})
    kernel = Kernel(system)
    p_sets = setup.p_sets(np.array(system.p))
    status = np.zeros(len(layout.STATUS), dtype=np.int64)
    stop = np.zeros(1, dtype=np.int64)
    arrays = dict(
        iopts=setup.iopts(), fopts=setup.fopts, x=setup.x0.copy(), z=setup.z0.copy(),
        u_prev=np.zeros(1), rng=np.zeros(4, dtype=np.uint64), op=setup.op, c_idx=setup.c_idx,
        cp=setup.cp, ref=setup.ref, uff=setup.uff, lv=setup.lv, lw=setup.lw, p_sets=p_sets,
        p_switch=setup.p_switch, lin_s=setup.linear_blocks(p_sets), region=setup.region,
        kicks=setup.kicks, kick_value=setup.kick_value, pulses=setup.pulses,
        pulse_value=setup.pulse_value, rec_cols=setup.rec_cols, acc_cols=setup.acc_cols,
        rec=np.empty((setup.n_rows, setup.record_width)), acc=np.zeros(setup.acc_len),
        status=status, fell_x=np.zeros(4), stop=stop,
    )
    core = kernel.core(setup.cp)
    core.run_one(k_start=0, k_end=2, **arrays)  # compiled, and two samples made
    helper = threading.Thread(target=lambda: core.run_one(k_start=2, k_end=setup.n_rows,
                                                          **arrays))
    helper.start()
    while status[layout.STATUS["rows"]] < 20:  # the helper is in the loop
        time.sleep(0.01)
    stop[0] = 1
    helper.join(30)
    assert not helper.is_alive()
    rows = int(status[layout.STATUS["rows"]])
    assert 20 <= rows < setup.n_rows and not status[layout.STATUS["fell"]]


def test_a_keyboard_interrupt_while_waiting_stops_the_core(monkeypatch) -> None:
    # The waiting thread's poll raises KeyboardInterrupt as Ctrl-C would: the core stops
    # within a sample and the interrupt goes on to the caller.
    system = get_system("cartpole")
    calls = []

    def interrupt() -> None:
        calls.append(time.monotonic())
        if len(calls) == 3:
            raise KeyboardInterrupt

    from equilibrist.sim import run as run_module

    real = run_module.call_interruptibly

    def with_poll(work, stop, poll=None):  # type: ignore[no-untyped-def]
        return real(work, stop, interrupt)

    monkeypatch.setattr(run_module, "call_interruptibly", with_poll)
    began = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        simulate(system, None, duration=2000.0, rate=100.0, physics_step=1e-6,
                 x0={"theta": 0.0}, region={})
    assert time.monotonic() - began < 60  # the run alone would take minutes
    from equilibrist.sim import batch as batch_module

    monkeypatch.setattr(batch_module, "call_interruptibly", with_poll)
    calls.clear()
    began = time.monotonic()
    with pytest.raises(KeyboardInterrupt):
        simulate_batch(system, None, runs=2, duration=20000.0, rate=100.0, physics_step=1e-5,
                       region={}, max_steps=None)
    assert time.monotonic() - began < 60


PYTHON_BATCH = '''
import multiprocessing
import sys

import numpy as np

from equilibrist.control.python_controller import PythonControllerBase
from equilibrist.numeric.lookup import get_system
from equilibrist.sim import simulate_batch


class Still(PythonControllerBase):
    rate = 100.0
    outputs = ("x", "theta", "x_dot", "theta_dot")
    running = False

    def output(self, t, y, r):
        if not Still.running:  # once a process: its run has begun
            Still.running = True
            print("running in", multiprocessing.current_process().name, flush=True)
        return np.zeros(1)


if __name__ == "__main__":
    print("started", flush=True)
    try:
        simulate_batch(get_system("cartpole"), Still(), runs=2, duration=1e5, workers=2,
                       region={}, max_steps=None)
    except KeyboardInterrupt:
        print("interrupted", flush=True)
        sys.exit(130)
'''


def test_a_signal_stops_a_batch_of_python_controllers_in_worker_processes(tmp_path) -> None:
    # The runs are in worker processes, which the signal (sent to this process alone,
    # as `kill` does) does not reach: they are ended, not waited for.
    script = tmp_path / "python_batch.py"
    script.write_text(PYTHON_BATCH)
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=tmp_path)

    def ready(proc: subprocess.Popen[bytes]) -> None:
        # Both workers spawned and running their runs (each says so at its first sample).
        assert proc.stdout is not None
        assert proc.stdout.readline() == b"started\n"
        running = {proc.stdout.readline() for _ in range(2)}
        assert running == {b"running in SpawnPoolWorker-1\n", b"running in SpawnPoolWorker-2\n"}, running

    code, out, err, took = signal_while_working(proc, signal.SIGINT, ready)
    assert code == 130, err.decode()
    assert out == b"interrupted\n"
    assert took < STOPS_WITHIN, f"took {took:.2f} s to stop"


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_an_interrupt_a_finalizer_swallowed_still_stops_the_core() -> None:
    """A signal whose KeyboardInterrupt lands in a __del__ is printed as ignored and lost;
    the command line's handler also records it, and the core's call raises it: the run
    of 2e8 steps ends at once instead of running on."""
    import signal as signals

    from equilibrist import interrupt
    from equilibrist.cli.main import _terminated

    class Finalized:
        def __del__(self) -> None:
            _terminated(signals.SIGTERM, None)  # what a signal arriving here does

    system = get_system("cartpole")
    try:
        Finalized()  # collected at once: its KeyboardInterrupt is swallowed
        assert interrupt.requested()
        start = time.monotonic()
        with pytest.raises(KeyboardInterrupt):
            simulate(system, None, duration=2000.0, rate=100.0, physics_step=1e-6)
        assert time.monotonic() - start < STOPS_WITHIN
    finally:
        interrupt.clear()


def test_the_command_line_prints_nothing_for_an_interrupt_a_finalizer_swallowed(
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The command line's unraisable hook drops a recorded interrupt that landed in a
    finalizer (Python would print "Exception ignored" and a traceback before the
    command's own "equilibrist: interrupted"); anything else still reaches the hook
    before it."""
    import signal as signals

    from equilibrist import interrupt
    from equilibrist.cli.main import _quiet_interrupts, _terminated

    seen: list[type[BaseException]] = []
    hook = _quiet_interrupts(lambda unraisable: seen.append(unraisable.exc_type))

    class Finalized:
        def __init__(self, fail: BaseException | None = None) -> None:
            self.fail = fail

        def __del__(self) -> None:
            if self.fail is None:
                _terminated(signals.SIGTERM, None)  # what a signal arriving here does
            raise self.fail

    previous = sys.unraisablehook
    sys.unraisablehook = hook
    try:
        Finalized()
        assert interrupt.requested()
        Finalized(ValueError("a finalizer's own failure"))
    finally:
        sys.unraisablehook = previous
        interrupt.clear()
    assert seen == [ValueError]
    assert capsys.readouterr().err == ""
