"""The firmware running in its chip's emulator, its UART on a pseudo-terminal.

- ``uno``: simavr, through a small harness linked with ``libsimavr``
  (:data:`~equilibrist.pil.simavr_harness.SIMAVR_HARNESS`, built once and cached):
  the ATmega328P at 16 MHz, its USART0 bridged to a pseudo-terminal, its
  cycle counter read at the firmware's marks.
- ``cortex-m4f``, ``cortex-m0``: QEMU (``netduinoplus2``, ``microbit``) with
  its UART on a pseudo-terminal made here (QEMU holds its master end) and ``-icount``, so that the virtual clock is the
  instruction count (the timers the firmware reads count instructions, and
  no answer depends on how busy the host is); the firmware's figures come
  by semihosting on QEMU's standard error.

Each step the firmware measures is a :class:`StepFigure`. The emulator ends
when the host closes the pseudo-terminal (simavr's harness) or when
:class:`Emulation` is left (QEMU is stopped).
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import subprocess
import tempfile
import threading
import time
import tty
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

from equilibrist.errors import quote_outside
from equilibrist.pil.firmware import Firmware, cache_folder
from equilibrist.pil.simavr_harness import SIMAVR_HARNESS
from equilibrist.pil.targets import PILError, Target

#: How long the emulator may take to open its pseudo-terminal [s].
START_TIMEOUT = 20.0
_PTY = re.compile(r"(/dev/pts/\d+)")
_AVR_STEP = re.compile(r"^cycles (\d+) (\d+) (\d+)$")  # the simavr harness's
_ARM_STEP = re.compile(r"^step (\d+) (\d+) (\d+)$")  # the firmware's, by semihosting


@dataclass(frozen=True)
class StepFigure:
    """One measured step: the firmware's count, the emulator's own (simavr's cycle counter,
    None under QEMU), the stack's high-water mark then and the heap's size [bytes]."""

    count: int
    emulator_count: int | None
    stack_bytes: int
    heap_bytes: int = 0


@dataclass
class Emulation:
    """A running emulator: the port to open, the figures so far, what it printed besides."""

    port: str
    process: subprocess.Popen[str]
    steps: list[StepFigure] = field(default_factory=list)
    other: list[str] = field(default_factory=list)


def harness() -> str:
    """The simavr harness's program, built once with the host's compiler and libsimavr."""
    if shutil.which("cc") is None:
        raise PILError("--target uno needs a C compiler for its simavr harness: install gcc "
                       "(Debian: apt-get install gcc)")
    digest = hashlib.sha256(SIMAVR_HARNESS.encode()).hexdigest()[:16]
    program = cache_folder() / f"pil_simavr-{digest}"
    if program.exists():
        return str(program)
    work = Path(tempfile.mkdtemp(prefix=".build-simavr-", dir=cache_folder()))
    try:
        (work / "pil_simavr.c").write_text(SIMAVR_HARNESS)
        done = subprocess.run(["cc", "-O2", "-o", "pil_simavr", "pil_simavr.c", "-lsimavr"],
                              cwd=work, capture_output=True, text=True, check=False, timeout=300)
        if done.returncode != 0:
            why = next((ln for ln in done.stderr.splitlines() if "error" in ln), "")
            raise PILError("--target uno needs simavr's library to build its harness: install "
                           "it (Debian: apt-get install libsimavr-dev)"
                           + (f" ({quote_outside(why.strip())})" if why else ""))
        os.replace(work / "pil_simavr", program)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return str(program)


def command(firmware: Firmware, *, link_fd: int | None = None) -> list[str]:
    """The emulator's command line for *firmware*: QEMU's UART on the pseudo-terminal whose
    master end is the file descriptor *link_fd* (passed to QEMU, which holds it as a serial
    device: the link is open from the start, where QEMU's own ``-serial pty`` looks for a
    program on its end once a second)."""
    name = firmware.target.name
    if name == "uno":
        return [harness(), str(firmware.image), str(firmware.paint_start)]
    if link_fd is None:
        raise PILError(f"--target {name}: QEMU needs the link's file descriptor")
    machine, shift = ("netduinoplus2", 0) if name == "cortex-m4f" else ("microbit", 7)
    return ["qemu-system-arm", "-M", machine, "-nographic", "-monitor", "none",
            "-add-fd", f"fd={link_fd},set=1", "-chardev", "serial,id=link,path=/dev/fdset/1",
            "-serial", "chardev:link", "-semihosting-config", "enable=on,target=native",
            "-icount", f"shift={shift},align=off,sleep=on", "-kernel", str(firmware.image)]


def _read(stream: IO[str], emulation: Emulation, found: list[str], ready: threading.Event,
          target: Target) -> None:
    for raw in stream:
        line = raw.strip()
        avr, arm = _AVR_STEP.match(line), _ARM_STEP.match(line)
        if avr is not None:
            fw, sim, stack = (int(v) for v in avr.groups())
            emulation.steps.append(StepFigure(fw, sim, stack))
            continue
        if arm is not None:
            count, stack, heap = (int(v) for v in arm.groups())
            emulation.steps.append(StepFigure(target.count_of(count), None, stack, heap))
            continue
        pty = _PTY.search(line)
        if pty is not None and not ready.is_set():
            found.append(pty.group(1))
            ready.set()
        elif line:
            emulation.other.append(line)


@contextmanager
def emulate(firmware: Firmware, *, extra: Sequence[str] = ()) -> Iterator[Emulation]:
    """Run *firmware* in its emulator while inside (with *extra* arguments: QEMU's ``-gdb``);
    the emulation's port and figures."""
    link: tuple[int, int] | None = None
    if firmware.target.name != "uno":
        master, slave = os.openpty()
        tty.setraw(slave)
        link = (master, slave)
    argv = [*command(firmware, link_fd=None if link is None else link[0]), *extra]
    try:
        process = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, text=True, bufsize=1,
                                   pass_fds=() if link is None else (link[0],))
    except OSError as exc:
        if link is not None:
            os.close(link[0])
            os.close(link[1])
        raise PILError(f"the emulator {argv[0]} could not start ({exc.strerror})") from None
    emulation = Emulation(port="", process=process)
    found: list[str] = []
    ready = threading.Event()
    if link is not None:
        os.close(link[0])  # QEMU's now
        found.append(os.ttyname(link[1]))
        ready.set()
    assert process.stdout is not None and process.stderr is not None
    readers = [threading.Thread(target=_read, args=(s, emulation, found, ready, firmware.target),
                                daemon=True) for s in (process.stdout, process.stderr)]
    for reader in readers:
        reader.start()
    try:
        deadline = time.monotonic() + START_TIMEOUT
        while not ready.wait(0.05):
            if process.poll() is not None or time.monotonic() > deadline:
                time.sleep(0.1)
                said = "; ".join(emulation.other[-3:])
                raise PILError(f"the emulator {argv[0]} did not open its serial port"
                               + (f": {quote_outside(said)}" if said else ""))
        emulation.port = found[0]
        yield emulation
    finally:
        if process.poll() is None:
            process.terminate()
            try:
                process.wait(5)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        if link is not None:
            os.close(link[1])
        for reader in readers:
            reader.join(5)
        for stream in (process.stdout, process.stderr):
            stream.close()
