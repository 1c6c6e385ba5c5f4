"""Helpers of the processor-in-the-loop tests (no tests here): a short lockstep through the
command's own composition, and the checks against independent truths."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from equilibrist.cli.main import build_parser
from equilibrist.cli.simulate import build_run, parse_x0, start_of
from equilibrist.pil.run import PILRun, check_fits, firmware_for, run_pil
from equilibrist.pil.targets import get
from support import require

#: A few samples at the cart-pole's 200 Hz: enough to run every branch a step takes.
DURATION = "0.05"


def pil(kind: str, target: str, *extra: str, timeout: float = 20.0) -> PILRun:
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
                   options=options, x0=x0, timeout=timeout)


def elf_sections(path: Path) -> tuple[int, int]:
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


def same_commands(run: PILRun, precision: float) -> None:
    assert run.hil.fault is None
    rows = run.simulated.n_rows
    assert run.result.n_rows == rows == round(float(DURATION) * 200) + 1
    scale = float(np.max(np.abs(run.simulated.commanded)))
    assert scale > 0
    deviation = run.max_deviation
    assert deviation is not None and deviation <= precision * scale


def figures_are_the_chips(run: PILRun, clock_hz: int, flash: int, ram: int) -> None:
    f = run.figures()
    assert f["clock_hz"] == clock_hz and f["budget_cycles"] == clock_hz // 200
    elf_flash, elf_ram = elf_sections(run.firmware.elf)
    assert (f["flash_bytes"], f["ram_bytes"]) == (elf_flash, elf_ram)
    counts = run.counts
    assert counts.size == run.result.n_rows and np.all(counts > 0)
    stack = f["stack_bytes"]
    assert isinstance(stack, int) and stack > 0 and elf_ram + stack <= ram
    assert elf_flash <= flash
    assert f["max_rate"] == float(clock_hz // int(counts.max()))
