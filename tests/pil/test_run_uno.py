"""Processor in the loop on the Uno: the export's sketch compiled by avr-gcc, run by simavr.

Independent truths: ``simulate`` of the same controller in Python (the Uno's ``double`` has
32 bits: the commands agree within float32), simavr's own cycle counter beside the
firmware's count of its Timer1, the ELF's section headers beside the linker's ``size``.
"""

from __future__ import annotations

import pytest
from pil_runs import figures_are_the_chips, pil, same_commands


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["lqr", "lqg", "swingup"])
def test_the_uno_runs_the_sketch_within_float32_and_counts_its_cycles(kind: str) -> None:
    run = pil(kind, "uno")
    same_commands(run, 1e-4)  # float32: the Uno's double
    figures_are_the_chips(run, 16_000_000, 32_768, 2_048)
    assert run.figures()["cycles_exact"] is True and run.fits
    # The firmware's count of its Timer1 against simavr's own cycle counter, step by step:
    # the two windows differ by the marks' own instructions (a few cycles).
    for step in run.steps:
        assert step.emulator_count is not None
        assert abs(step.count - step.emulator_count) <= 8
