"""Processor in the loop: short locksteps of the firmware in its emulator, against ``simulate``.

The independent truths: ``simulate`` of the same controller in Python (the chip's commands
equal it within the chip's precision: float64 on the Cortex-M4F with the export in double,
float32 on the Uno whose ``double`` has 32 bits), simavr's own cycle counter beside the
firmware's count of its Timer1, the ELF's section headers read here beside the linker's
``size``, and the chips' published clocks and memories.
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from equilibrist.cli.main import build_parser
from equilibrist.cli.simulate import build_run, parse_x0, start_of
from equilibrist.pil.run import PILRun, check_fits, firmware_for, run_pil
from equilibrist.pil.targets import get
from support import require

#: A few samples at the cart-pole's 200 Hz: enough to run every branch a step takes.
DURATION = "0.05"


def _pil(kind: str, target: str, *extra: str) -> PILRun:
    for tool, _ in get(target).tools:
        require(tool)
    args = build_parser("pil").parse_args(
        ["pil", "cartpole", "--controller", kind, "--target", target, "--duration", DURATION,
         "--x0", "theta=0.1", *extra])
    system, options = build_run(args)
    controller = options.pop("controller")
    precision = "float" if "float" in extra else "double"
    firmware = firmware_for(controller, system=system, target=get(target), precision=precision,
                            label=kind)
    check_fits(firmware, kind)
    x0 = start_of({"controller": controller}, parse_x0(args.x0))
    return run_pil(system, controller, firmware, label=kind, precision=precision,
                   options=options, x0=x0, timeout=20)


def _elf_sections(path: Path) -> tuple[int, int]:
    """Flash and RAM of a 32-bit little-endian ELF from its section headers: the allocated
    sections with contents in flash (code, constants, the data's initial values), the
    writable ones in RAM (initialized and zeroed data)."""
    raw = path.read_bytes()
    assert raw[:4] == b"\x7fELF" and raw[4] == 1 and raw[5] == 1
    shoff, = struct.unpack_from("<I", raw, 0x20)
    shentsize, shnum = struct.unpack_from("<HH", raw, 0x2E)
    flash = ram = 0
    for k in range(shnum):
        _, kind, flags, _, _, size = struct.unpack_from("<IIIIII", raw, shoff + k * shentsize)
        alloc, write = flags & 0x2, flags & 0x1
        if alloc and kind != 8:  # SHT_NOBITS: no bytes in the image
            flash += size
        if alloc and write:
            ram += size
    return flash, ram


def _same_commands(run: PILRun, precision: float) -> None:
    assert run.hil.fault is None
    rows = run.simulated.n_rows
    assert run.result.n_rows == rows == round(float(DURATION) * 200) + 1
    scale = float(np.max(np.abs(run.simulated.commanded)))
    assert scale > 0
    deviation = run.max_deviation
    assert deviation is not None and deviation <= precision * scale


def _figures_are_the_chips(run: PILRun, clock_hz: int, flash: int, ram: int) -> None:
    f = run.figures()
    assert f["clock_hz"] == clock_hz and f["budget_cycles"] == clock_hz // 200
    elf_flash, elf_ram = _elf_sections(run.firmware.elf)
    assert (f["flash_bytes"], f["ram_bytes"]) == (elf_flash, elf_ram)
    counts = run.counts
    assert counts.size == run.result.n_rows and np.all(counts > 0)
    stack = f["stack_bytes"]
    assert isinstance(stack, int) and stack > 0 and elf_ram + stack <= ram
    assert elf_flash <= flash
    assert f["max_rate"] == float(clock_hz // int(counts.max()))


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["lqr", "lqg", "swingup"])
def test_the_uno_runs_the_sketch_within_float32_and_counts_its_cycles(kind: str) -> None:
    run = _pil(kind, "uno")
    _same_commands(run, 1e-4)  # float32: the Uno's double
    _figures_are_the_chips(run, 16_000_000, 32_768, 2_048)
    assert run.figures()["cycles_exact"] is True and run.fits
    # The firmware's count of its Timer1 against simavr's own cycle counter, step by step:
    # the two windows differ by the marks' own instructions (a few cycles).
    for step in run.steps:
        assert step.emulator_count is not None
        assert abs(step.count - step.emulator_count) <= 8


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["lqr", "lqg", "swingup", "mpc", "tvlqr"])
def test_every_kind_runs_on_the_cortex_m4f_as_simulate(kind: str, tmp_path: Path) -> None:
    extra: tuple[str, ...] = ()
    if kind == "tvlqr":
        extra = ("--trajectory", _upright_plan(tmp_path))
    run = _pil(kind, "cortex-m4f", *extra)
    _same_commands(run, 1e-9)  # double in the export, float64 on the link
    _figures_are_the_chips(run, 168_000_000, 1_048_576, 131_072)
    assert run.figures()["cycles_exact"] is False and run.fits


@pytest.mark.slow
def test_the_float_export_on_the_fpu_is_float32_close() -> None:
    run = _pil("lqg", "cortex-m4f", "--precision", "float")
    _same_commands(run, 1e-4)
    # Not the bits of double: the chip ran single precision.
    assert run.max_deviation is not None and run.max_deviation > 0


def _upright_plan(folder: Path) -> str:
    """A plan that holds the cart-pole upright for a second, saved as ``trajopt --out`` does."""
    from equilibrist.control.trajopt import Trajectory
    from equilibrist.numeric.lookup import get_system

    cart = get_system("cartpole")
    op = cart.operating_point()
    knots = 10
    plan = Trajectory(
        system=cart.key, params=dict(cart.params), state_names=tuple(cart.spec.state_names),
        input_names=tuple(cart.spec.input_names), times=np.linspace(0.0, 1.0, knots + 1),
        states=np.tile(op.x, (knots + 1, 1)), inputs=np.tile(op.u, (knots + 1, 1)),
        mid_inputs=np.tile(op.u, (knots, 1)), converged=True, cost=0.0, max_defect=0.0,
        solve_time=0.0, iterations=0, solver="held")
    return str(plan.save(folder / "upright.npz"))
