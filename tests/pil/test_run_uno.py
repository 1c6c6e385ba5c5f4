"""Processor in the loop on the Uno: the export's sketch compiled by avr-gcc, run by simavr.

Independent truths: ``simulate`` of the same controller in Python (the Uno's ``double`` has
32 bits: the commands agree within float32), simavr's own cycle counter beside the
firmware's count of its Timer1, the ELF's section headers beside the linker's ``size``.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import pytest
from pil_runs import figures_are_the_chips, pil, same_commands

from equilibrist.pil import run as pil_run
from equilibrist.pil.emulator import Emulation, emulate
from equilibrist.pil.firmware import Firmware
from equilibrist.pil.run import PILRun


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["lqr", "lqg", "swingup"])
def test_the_uno_runs_the_sketch_within_float32_and_counts_its_cycles(kind: str) -> None:
    run = pil(kind, "uno")
    same_commands(run, 1e-4)  # float32: the Uno's double
    figures_are_the_chips(run, 16_000_000, 32_768, 2_048)
    assert run.figures()["cycles_exact"] is True and run.fits
    # The firmware's count of its Timer1 against simavr's own cycle counter, step by step:
    # the two windows differ by the marks' own instructions (6 cycles), and by Timer1's
    # overflow interrupt (about 40) in the rare step where it falls between a mark and a
    # reading of the timer.
    for step in run.steps:
        assert step.emulator_count is not None
        assert abs(step.count - step.emulator_count) <= 64


@pytest.mark.slow
def test_a_chip_that_stops_answering_ends_the_run_as_hil_says(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The emulator stopped (SIGSTOP) after the third step, as a hung board: the lockstep ends
    on hil's fault, with the samples so far."""
    run = _interrupted(monkeypatch, signal.SIGSTOP, timeout=2.0)
    assert run.fault is not None and "did not answer within 2 s" in run.fault
    # The third step measured; its answer may or may not have left before the stop.
    assert 2 <= run.result.n_rows < 11 and len(run.steps) >= 3


def _interrupted(monkeypatch: pytest.MonkeyPatch, sig: signal.Signals, *,
                 timeout: float) -> PILRun:
    """The Uno's LQR, with *sig* sent to its emulator once the firmware measured three steps."""

    @contextmanager
    def signalled(firmware: Firmware) -> Iterator[Emulation]:
        with emulate(firmware) as emulation:
            def send() -> None:
                while len(emulation.steps) < 3 and emulation.process.poll() is None:
                    time.sleep(0.001)
                os.kill(emulation.process.pid, sig)

            sender = threading.Thread(target=send, daemon=True)
            sender.start()
            try:
                yield emulation
            finally:
                sender.join(5)
                os.kill(emulation.process.pid, signal.SIGCONT)

    monkeypatch.setattr(pil_run, "emulate", signalled)
    return pil("lqr", "uno", timeout=timeout)


@pytest.mark.slow
def test_a_chip_that_resets_mid_run_ends_the_run_as_hil_says(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The chip reset (simavr's harness on SIGUSR1, as a brown-out) after the third step: it
    starts again and says so, and the lockstep ends on hil's fault."""
    run = _interrupted(monkeypatch, signal.SIGUSR1, timeout=20.0)
    assert run.fault is not None and "reset during the run" in run.fault
    assert 2 <= run.result.n_rows < 11
