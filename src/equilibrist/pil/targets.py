"""The chips processor-in-the-loop runs on: their clocks, memories, toolchains and emulators."""

from __future__ import annotations

import shutil
from dataclasses import dataclass

from equilibrist.errors import EquilibristError


class PILError(EquilibristError, ValueError):
    """A target that cannot be used here, or a firmware that cannot be built (exit status 2)."""


class DoesNotFit(PILError):
    """The controller's firmware does not fit the chip's memory (exit status 2)."""


@dataclass(frozen=True)
class Target:
    """A microcontroller, its toolchain and the emulator that runs its firmware.

    Attributes
    ----------
    name:
        What ``--target`` takes.
    chip:
        The chip and board, for the report.
    clock_hz:
        The chip's clock: the period's budget is ``clock_hz / rate`` cycles.
    flash_bytes, ram_bytes:
        The chip's program memory and RAM: a firmware fits when its image does.
    double_bits:
        The size of C's ``double`` on the chip (32 on the AVR).
    cycles_exact:
        True where the emulator counts the chip's cycles (simavr); False where it
        counts instructions and one cycle per instruction is assumed (QEMU).
    counted:
        What a step's figure counts, in words, for the report.
    tools:
        The commands the build and the run need, with the Debian package of each.
    ticks_per_count:
        How many ticks of the timer the firmware reads make one counted cycle or
        instruction (the nRF51's 16 MHz timer under ``-icount shift=7``: 2.048).
    """

    name: str
    chip: str
    clock_hz: int
    flash_bytes: int
    ram_bytes: int
    double_bits: int
    cycles_exact: bool
    counted: str
    tools: tuple[tuple[str, str], ...]
    ticks_per_count: float = 1.0

    def count_of(self, ticks: int) -> int:
        """The instructions (or cycles) that *ticks* of the firmware's timer are.

        At 2.048 ticks an instruction, the difference of two floored readings over n
        instructions lies in (2.048 n - 1, 2.048 n + 1], an interval that holds one whole n
        only (it is narrower than 2.048)."""
        if self.ticks_per_count == 1.0:
            return ticks
        return int((ticks + 1) // self.ticks_per_count)

    @property
    def payload_bytes(self) -> int:
        """The size of the link's reals: float64 where the chip has 64-bit doubles."""
        return 8 if self.double_bits == 64 else 4

    def check_tools(self) -> None:
        """Raise :class:`PILError` naming every missing command and its Debian package."""
        missing = [(cmd, pkg) for cmd, pkg in self.tools if shutil.which(cmd) is None]
        if missing:
            names = ", ".join(cmd for cmd, _ in missing)
            packages = " ".join(dict.fromkeys(pkg for _, pkg in missing))
            raise PILError(f"--target {self.name} needs {names}, not found on this machine: "
                           f"install them (Debian: apt-get install {packages})")


_ARM = (("arm-none-eabi-gcc", "gcc-arm-none-eabi"), ("arm-none-eabi-g++", "gcc-arm-none-eabi"),
        ("arm-none-eabi-size", "binutils-arm-none-eabi"),
        ("qemu-system-arm", "qemu-system-arm"))

TARGETS: dict[str, Target] = {
    "uno": Target(
        name="uno", chip="ATmega328P at 16 MHz (Arduino Uno), in simavr", clock_hz=16_000_000,
        flash_bytes=32_768, ram_bytes=2_048, double_bits=32, cycles_exact=True,
        counted="cycles, counted by simavr",
        tools=(("avr-gcc", "gcc-avr"), ("avr-g++", "gcc-avr"), ("avr-size", "binutils-avr"),
               ("avr-objcopy", "binutils-avr"), ("cc", "gcc"))),
    "cortex-m4f": Target(
        name="cortex-m4f",
        chip="STM32F405 Cortex-M4F at 168 MHz (QEMU netduinoplus2, -icount shift=0)",
        clock_hz=168_000_000, flash_bytes=1_048_576, ram_bytes=131_072, double_bits=64,
        cycles_exact=False,
        counted="instructions, counted by QEMU (one cycle per instruction assumed)",
        tools=_ARM),
    "cortex-m0": Target(
        name="cortex-m0", chip="nRF51822 Cortex-M0 at 16 MHz (QEMU microbit, -icount shift=7)",
        clock_hz=16_000_000, flash_bytes=262_144, ram_bytes=16_384, double_bits=64,
        cycles_exact=False,
        counted="instructions, counted by QEMU (one cycle per instruction assumed)",
        tools=_ARM, ticks_per_count=2.048),
}


def get(name: str) -> Target:
    """The target called *name*, else :class:`PILError` listing them."""
    try:
        return TARGETS[name]
    except KeyError:
        raise PILError(f"--target {name!r}: expected one of {', '.join(TARGETS)}") from None
