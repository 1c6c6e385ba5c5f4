"""The export's sketch built into firmware for a target, with the chip's own toolchain.

The sources are the export's ``hil_arduino/`` folder (the controller, its
interface and the protocol, beside ``hil_arduino.ino``), plus what the
export's ``make hil-host`` adds to them (DAQP's sources for the MPC, read
from the export's Makefile), plus the board (:mod:`equilibrist.pil.boards`).
The sketch is compiled as the Arduino IDE compiles one (``-Os``, as C++ with
the core's header first); the Cortex-M builds keep ``-ffp-contract=off``, as
every build of the project does, so that the chip's arithmetic is the
export's operation for operation.

A firmware is cached by the hash of everything that shapes it (the sources'
text, the flags, the toolchain's version, :data:`REVISION`) in the cache
folder (:func:`~equilibrist.numeric.cache.cache_dir`, ``pil/``), written
into a folder of its own and renamed into place, so that a second build of
the same sources, in this process or another, is a lookup.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from equilibrist.errors import quote_outside
from equilibrist.pil import boards
from equilibrist.pil.targets import DoesNotFit, PILError, Target

#: Bumped when the way a firmware is built changes.
REVISION = 1
SKETCH_FOLDER = "hil_arduino"
SKETCH = "hil_arduino.ino"
HEADER = "pil_arduino.h"
# avr-libc's math.h has C99's INFINITY but not HUGE_VAL, which the exports write.
_AVR_FLAGS = ("-mmcu=atmega328p", "-DF_CPU=16000000UL", "-DHUGE_VAL=__builtin_huge_val()", "-Os",
              "-ffunction-sections", "-fdata-sections")
_CXX_FLAGS = ("-fno-exceptions", "-fno-rtti", "-fno-threadsafe-statics")
_M4F_FLAGS = ("-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16")
_M0_FLAGS = ("-mcpu=cortex-m0", "-mthumb", "-mfloat-abi=soft")
_ARM_COMMON = ("-Os", "-ffp-contract=off", "-ffunction-sections", "-fdata-sections")
#: The stack each Cortex-M firmware reserves at the top of RAM (painted, and measured).
STACK_RESERVE = {"cortex-m4f": 16_384, "cortex-m0": 4_096}


@dataclass(frozen=True)
class Firmware:
    """A built firmware: its image and what the linker says of it.

    ``flash_bytes`` is the image in program memory (code and the data's
    initial values), ``ram_bytes`` the static RAM (initialized and zeroed
    data); ``paint_start`` the first RAM address the start-up paints (the
    simavr harness scans from it).
    """

    target: Target
    folder: Path
    flash_bytes: int
    ram_bytes: int
    paint_start: int

    @property
    def elf(self) -> Path:
        return self.folder / "firmware.elf"

    @property
    def image(self) -> Path:
        """The flat image simavr loads (the AVR), or the ELF QEMU loads."""
        return self.folder / ("firmware.bin" if self.target.name == "uno" else "firmware.elf")


@dataclass(frozen=True)
class Sources:
    """What a firmware is built from: C files by name and defines; and the library's static
    data as the export measured it on this machine (``make size``), where it did."""

    files: dict[str, str]
    defines: tuple[str, ...] = ()
    host_data: int | None = None


def sketch_sources(export_folder: Path) -> Sources:
    """The export's sketch and what its ``make hil-host`` compiles beside it."""
    sketch = export_folder / SKETCH_FOLDER
    if not (sketch / SKETCH).is_file():
        raise PILError(f"{export_folder} holds no {SKETCH_FOLDER}/{SKETCH}: it is not an export")
    files = {p.name: p.read_text() for p in sorted(sketch.iterdir())
             if p.suffix in (".c", ".h", ".ino")}
    defines: list[str] = []
    makefile = (export_folder / "Makefile").read_text()
    for line in makefile.splitlines():
        if line.startswith("HIL_CFLAGS ="):
            defines += [w for w in line.split()[2:] if w.startswith("-D")]
            for inc in (w[2:] for w in line.split()[2:] if w.startswith("-I") and w != "-I."):
                for p in sorted((export_folder / inc).glob("*.h")):
                    files[p.name] = p.read_text()
        if line.startswith("HIL_SRC ="):
            for pattern in re.findall(r"\$\(wildcard ([^)]+)\)", line):
                for p in sorted(export_folder.glob(pattern)):
                    files[p.name] = p.read_text()
    return Sources(files=files, defines=tuple(defines))


def _board(target: Target) -> dict[str, str]:
    if target.name == "uno":
        return {HEADER: boards.ARDUINO_HEADER, "pil_board.c": boards.AVR_BOARD}
    if target.name == "cortex-m4f":
        ld = boards.linker_script(flash_origin=0x0800_0000, flash_bytes=target.flash_bytes,
                                  ram_bytes=target.ram_bytes, stack_bytes=STACK_RESERVE[target.name])
        return {HEADER: boards.ARDUINO_HEADER, "pil_board.c": boards.STM32F4_BOARD, "pil.ld": ld}
    ld = boards.linker_script(flash_origin=0, flash_bytes=target.flash_bytes,
                              ram_bytes=target.ram_bytes, stack_bytes=STACK_RESERVE[target.name])
    return {HEADER: boards.ARDUINO_HEADER, "pil_board.c": boards.NRF51_BOARD, "pil.ld": ld}


def _tools(target: Target) -> tuple[str, str, str, tuple[str, ...], tuple[str, ...]]:
    """C compiler, C++ compiler, size, compile flags, link flags."""
    if target.name == "uno":
        return ("avr-gcc", "avr-g++", "avr-size", _AVR_FLAGS,
                ("-Wl,--gc-sections", "-Wl,--wrap=hil_ctrl_step"))
    arch = _M4F_FLAGS if target.name == "cortex-m4f" else _M0_FLAGS
    return ("arm-none-eabi-gcc", "arm-none-eabi-g++", "arm-none-eabi-size", (*arch, *_ARM_COMMON),
            ("-nostartfiles", "--specs=nano.specs", "--specs=nosys.specs", "-T", "pil.ld",
             "-Wl,--gc-sections", "-Wl,--wrap=hil_ctrl_step"))


@lru_cache(maxsize=8)
def _version(command: str) -> str:
    try:
        done = subprocess.run([command, "--version"], capture_output=True, text=True, timeout=30,
                              check=False)
    except OSError:
        return command
    return (done.stdout.splitlines() or [command])[0]


def cache_folder() -> Path:
    """``pil/`` in the cache folder: the export's sketches, the firmware, the simavr harness."""
    from equilibrist.numeric.cache import cache_dir

    folder = cache_dir() / "pil"
    folder.mkdir(exist_ok=True)
    return folder


def firmware_key(sources: Sources, target: Target) -> str:
    """The hash of everything that shapes the firmware of *sources* for *target*."""
    cc, cxx, _, flags, link = _tools(target)
    h = hashlib.sha256()
    parts = [f"revision {REVISION}", target.name, _version(cc), _version(cxx), *flags, *link,
             *sources.defines]
    for name, text in sorted({**sources.files, **_board(target)}.items()):
        parts += [name, text]
    for part in parts:
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()[:32]


def cached(key: str, target: Target) -> Firmware | None:
    """The firmware of *key* from the cache, or None."""
    folder = cache_folder() / f"{target.name}-{key}"
    try:
        meta = json.loads((folder / "firmware.json").read_text())
        return Firmware(target=target, folder=folder, flash_bytes=int(meta["flash_bytes"]),
                        ram_bytes=int(meta["ram_bytes"]), paint_start=int(meta["paint_start"]))
    except (OSError, ValueError, KeyError, TypeError):
        return None


def build(sources: Sources, target: Target) -> Firmware:
    """The firmware of *sources* for *target*: from the cache, else built with its toolchain."""
    target.check_tools()
    key = firmware_key(sources, target)
    done = cached(key, target)
    if done is not None:
        return done
    root = cache_folder()
    refused = root / f"{target.name}-{key}.does-not-fit"
    if refused.exists():  # a firmware that cannot fit is refused again without a build
        raise DoesNotFit(refused.read_text())
    work = Path(tempfile.mkdtemp(prefix=f".build-{target.name}-", dir=root))
    try:
        for name, text in {**sources.files, **_board(target)}.items():
            (work / name).write_text(text)
        try:
            flash, ram, paint = _compile(work, target, sources.defines)
        except DoesNotFit as exc:
            with tempfile.NamedTemporaryFile("w", dir=root, prefix=".refused-",
                                             delete=False) as f:
                f.write(str(exc))
            os.replace(f.name, refused)
            raise
        (work / "firmware.json").write_text(json.dumps(
            {"flash_bytes": flash, "ram_bytes": ram, "paint_start": paint}))
        final = root / f"{target.name}-{key}"
        try:
            os.rename(work, final)
        except OSError:  # another process built it first
            shutil.rmtree(work, ignore_errors=True)
    finally:
        if work.exists():
            shutil.rmtree(work, ignore_errors=True)
    found = cached(key, target)
    if found is None:
        raise PILError(f"the firmware built for {target.name} is not in the cache folder {root}")
    return found


def _run(command: Sequence[str], cwd: Path, what: str) -> str:
    try:
        done = subprocess.run(list(command), cwd=cwd, capture_output=True, text=True, timeout=600,
                              check=False)
    except OSError as exc:
        raise PILError(f"{what}: {command[0]} could not run ({exc.strerror})") from None
    if done.returncode != 0:
        lines = [ln for ln in (done.stderr or done.stdout).splitlines() if ln.strip()]
        first = next((ln for ln in lines if "error" in ln.lower()), lines[0] if lines else "")
        raise PILError(f"{what} failed: {quote_outside(first.strip())}")
    return done.stdout


def _compile(work: Path, target: Target, defines: tuple[str, ...]) -> tuple[int, int, int]:
    """Compile and link in *work*; flash and RAM bytes, and where the paint starts."""
    cc, cxx, size, flags, link = _tools(target)
    objects = []
    what = f"building the firmware for {target.name}"
    for name in sorted(n for n in os.listdir(work) if n.endswith(".c")):
        obj = name[:-2] + ".o"
        try:
            _run([cc, *flags, "-std=gnu99", *defines, "-I.", "-c", name, "-o", obj], work, what)
        except PILError as exc:
            if "too large" in str(exc):  # an array over the chip's address space
                raise DoesNotFit(str(exc)) from None
            raise
        objects.append(obj)
    _run([cxx, *flags, *_CXX_FLAGS, *defines, "-I.", "-x", "c++", "-include", HEADER,
          "-c", SKETCH, "-o", "sketch.o"], work, what)
    objects.append("sketch.o")
    linked = subprocess.run([cc, *flags, *link, "-o", "firmware.elf", *objects, "-lm"], cwd=work,
                            capture_output=True, text=True, timeout=600, check=False)
    if linked.returncode != 0:
        over = re.findall(r"region `(\w+)' overflowed by (\d+) bytes", linked.stderr)
        if over:
            raise DoesNotFit(_overflow(work, size, objects, over, target))
        _run([cc, *flags, *link, "-o", "firmware.elf", *objects, "-lm"], work, what)
    text, data, bss = (int(v) for v in _run([size, "firmware.elf"], work, what)
                       .splitlines()[1].split()[:3])
    paint = 0
    if target.name == "uno":
        _run(["avr-objcopy", "-O", "binary", "-j", ".text", "-j", ".data", "firmware.elf",
              "firmware.bin"], work, what)
        symbols = _run(["avr-nm", "firmware.elf"], work, what)
        match = re.search(r"^([0-9a-f]+) \w _end$", symbols, re.MULTILINE)
        if match is None:
            raise PILError(f"{what}: the linked firmware has no _end symbol")
        paint = int(match.group(1), 16) & 0xFFFF
    return text + data, data + bss, paint


def _overflow(work: Path, size: str, objects: list[str], over: list[tuple[str, str]],
              target: Target) -> str:
    """The linker's refusal in figures: what the objects need against the chip's memories."""
    totals = _run([size, "-t", *objects], work, "measuring the objects").splitlines()[-1].split()
    text, data, bss = (int(v) for v in totals[:3])
    said = ", ".join(f"region {name} overflowed by {int(n):,} bytes" for name, n in over)
    return (f"the objects need {text + data:,} bytes of flash (of {target.flash_bytes:,}) and "
            f"{data + bss:,} of static RAM (of {target.ram_bytes:,}), before the C library's; "
            f"the linker: {said}")
