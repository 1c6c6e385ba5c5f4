"""A processor-in-the-loop run: the firmware in its emulator closes the loop in lockstep.

:func:`sources_for` exports the controller's sketch, :func:`firmware_for`
builds it for the target (both cached); :func:`run_pil` runs the firmware in the emulator and
closes the loop over the emulated UART with :mod:`equilibrist.hil`'s link
and lockstep (:class:`~equilibrist.hil.run.DeviceController`), then runs
``simulate`` with the same controller in Python and compares the commands.
:class:`PILRun` holds the figures a builder decides with (:meth:`PILRun.figures`).
"""

from __future__ import annotations

import hashlib
import math
import os
import tempfile
import time
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.errors import quote_outside
from equilibrist.pil.emulator import START_TIMEOUT, StepFigure, emulate
from equilibrist.pil.firmware import Firmware, Sources, build, sketch_sources
from equilibrist.pil.targets import DoesNotFit, Target

if TYPE_CHECKING:
    from equilibrist.control.controller import AnyController
    from equilibrist.hil.protocol import Hello
    from equilibrist.hil.run import DeviceController, HILRun
    from equilibrist.numeric.system import System
    from equilibrist.sim.result import SimResult

#: Bumped when what :func:`sources_for` keys its lookup on changes.
_INDEX_REVISION = 1


def _code_digest() -> str:
    """The hash of the code that writes a firmware's sources (the export's and the C writers')."""
    import equilibrist.export as export_pkg
    import equilibrist.native as native_pkg
    import equilibrist.pil as pil_pkg

    h = hashlib.sha256()
    for pkg in (export_pkg, native_pkg, pil_pkg):
        root = Path(next(iter(pkg.__path__)))
        for path in sorted(root.rglob("*")):
            if path.suffix in (".py", ".c", ".h") and path.is_file():
                h.update(str(path.relative_to(root)).encode())
                h.update(path.read_bytes())
    return h.hexdigest()


def sources_for(controller: object, *, system: System, precision: str) -> Sources:
    """The export's sketch of *controller*, what every target's firmware is built from.

    Kept in the cache folder by the controller's design id, the precision and
    the code that writes the sources, so that a warm cache does not export
    again (for this target or another)."""
    import json

    from equilibrist import __version__
    from equilibrist.export.writer import design_id, export_controller
    from equilibrist.pil.firmware import cache_folder

    key = hashlib.sha256("\0".join(
        (str(_INDEX_REVISION), __version__, precision, design_id(controller), system.key,
         _code_digest())).encode()).hexdigest()[:32]
    path = cache_folder() / f"sources-{key}.json"
    try:
        kept = json.loads(path.read_text())
        return Sources(files=dict(kept["files"]), defines=tuple(kept["defines"]),
                       host_data=kept["host_data"])
    except (OSError, ValueError, KeyError, TypeError):
        pass
    with tempfile.TemporaryDirectory(prefix="equilibrist-pil-") as tmp:
        folder = Path(tmp) / "export"
        # The export's recorded run is not in the firmware: ten samples of it are enough.
        rate = float(getattr(controller, "rate", 0.0) or system.spec.control_rate)
        report = export_controller(controller, folder, system=system, precision=precision,
                                   duration=10.0 / rate)
        footprint = getattr(report, "footprint", None)
        found = sketch_sources(folder)
    sources = Sources(files=found.files, defines=found.defines,
                      host_data=None if footprint is None else int(footprint.data))
    with tempfile.NamedTemporaryFile("w", dir=path.parent, prefix=".sources-", delete=False) as f:
        json.dump({"files": sources.files, "defines": list(sources.defines),
                   "host_data": sources.host_data}, f)
    os.replace(f.name, path)
    return sources


def firmware_for(controller: object, *, system: System, target: Target, precision: str,
                 label: str) -> Firmware:
    """The firmware of *controller* for *target*: its export's sketch (:func:`sources_for`)
    built with the chip's toolchain (cached by content: a warm cache neither exports nor
    compiles). A firmware that cannot fit the chip raises :class:`DoesNotFit` with the
    figures that decided it."""
    target.check_tools()
    sources = sources_for(controller, system=system, precision=precision)
    try:
        return build(sources, target)
    except DoesNotFit as exc:
        data = ("" if sources.host_data is None or sources.host_data <= target.ram_bytes else
                f"its static data is {sources.host_data:,} bytes in float64 (make size on this "
                f"machine), over the {target.ram_bytes:,} bytes of RAM; ")
        raise DoesNotFit(f"{label} does not fit the {target.name} ({target.chip}): {data}"
                         f"{exc}") from None


def check_fits(firmware: Firmware, label: str) -> None:
    """Raise :class:`DoesNotFit` when the image or its static RAM exceed the chip's."""
    t = firmware.target
    over = []
    if firmware.flash_bytes > t.flash_bytes:
        over.append(f"flash {firmware.flash_bytes:,} bytes of {t.flash_bytes:,}")
    if firmware.ram_bytes > t.ram_bytes:
        over.append(f"static RAM {firmware.ram_bytes:,} bytes of {t.ram_bytes:,}")
    if over:
        raise DoesNotFit(f"{label} does not fit the {t.name} ({t.chip}): {', '.join(over)}")


@dataclass(frozen=True)
class PILRun:
    """A processor-in-the-loop run, its figures, and ``simulate``'s run beside it."""

    hil: HILRun
    target: Target
    firmware: Firmware
    steps: tuple[StepFigure, ...]
    rate: float
    simulated: SimResult
    label: str
    precision: str

    @property
    def result(self) -> SimResult:
        return self.hil.result

    @property
    def budget_cycles(self) -> int:
        """The cycles one period has at the chip's clock."""
        return int(self.target.clock_hz // self.rate)

    @property
    def counts(self) -> np.ndarray:
        return np.array([s.count for s in self.steps], dtype=np.int64)

    @property
    def stack_bytes(self) -> int | None:
        return max((s.stack_bytes for s in self.steps), default=None)

    @property
    def heap_bytes(self) -> int:
        """What the firmware allocated with ``malloc`` (the Cortex-M's heap) [bytes]."""
        return max((s.heap_bytes for s in self.steps), default=0)

    @property
    def max_deviation(self) -> float | None:
        """The largest difference between the device's commands and ``simulate``'s [input units]."""
        rows = min(self.result.n_rows, self.simulated.n_rows)
        if rows == 0:
            return None
        return float(np.max(np.abs(self.result.commanded[:rows] - self.simulated.commanded[:rows])))

    @property
    def overrun(self) -> str | None:
        """The first step that took longer than its period, in one line, or None."""
        counts = self.counts
        late = np.flatnonzero(counts > self.budget_cycles)
        if late.size == 0:
            return None
        k = int(late[0])
        t = float(self.result.time[k]) if k < self.result.n_rows else k / self.rate
        return (f"the controller overran its period at t = {t:.4g} s: {int(counts[k]):,} cycles "
                f"of the {self.budget_cycles:,} a period has at {self.rate:g} Hz "
                f"({late.size} of {counts.size} steps over)")

    @property
    def fault(self) -> str | None:
        return self.hil.fault or self.overrun

    @property
    def fits(self) -> bool:
        t, fw = self.target, self.firmware
        stack = self.stack_bytes or 0
        counts = self.counts
        return bool(counts.size and int(counts.max()) <= self.budget_cycles
                    and fw.flash_bytes <= t.flash_bytes
                    and fw.ram_bytes + self.heap_bytes + stack <= t.ram_bytes)

    def figures(self) -> dict[str, object]:
        """The figures, by the keys ``--json`` writes."""
        counts = self.counts
        worst = int(counts.max()) if counts.size else None
        return {
            "target": self.target.name,
            "clock_hz": self.target.clock_hz,
            "cycles_per_step": {"median": float(np.median(counts)) if counts.size else None,
                                "max": worst},
            "cycles_exact": self.target.cycles_exact,
            "counted": self.target.counted,
            "budget_cycles": self.budget_cycles,
            "budget_fraction": None if worst is None else worst / self.budget_cycles,
            "flash_bytes": self.firmware.flash_bytes,
            "ram_bytes": self.firmware.ram_bytes,
            "stack_bytes": self.stack_bytes,
            "heap_bytes": self.heap_bytes,
            "max_rate": None if not worst else float(math.floor(self.target.clock_hz / worst)),
            "steps": int(counts.size),
            "max_deviation": self.max_deviation,
            "fits": self.fits,
            "precision": self.precision,
            "double_bits": self.target.double_bits,
        }

    def headline(self) -> str:
        """``"LQG at 200 Hz: N cycles of 80,000, P %"``: the worst step against the budget."""
        counts = self.counts
        if not counts.size:
            return f"{self.label} at {self.rate:g} Hz: no step measured"
        worst = int(counts.max())
        return (f"{self.label} at {self.rate:g} Hz: {worst:,} cycles of {self.budget_cycles:,}, "
                f"{100 * worst / self.budget_cycles:.1f} %")


def host_hello(system: System, controller: AnyController, *, target: Target, rate: float,
               tracking: bool) -> tuple[Hello, tuple[str, ...]]:
    """The host's hello for *controller* on *target*, and the outputs the device reads."""
    from equilibrist.control.controller import measured_outputs
    from equilibrist.export.writer import design_id
    from equilibrist.hil.protocol import Hello

    outputs = measured_outputs(controller) or tuple(system.spec.outputs)
    nr = len(getattr(controller, "tracked_names", ())) if tracking else 0
    hello = Hello(real_size=target.payload_bytes, n=system.n_states, m=system.n_inputs,
                  p=len(outputs), references=nr, estimate=0, rate=float(rate),
                  controller_id=design_id(controller))
    return hello, tuple(outputs)


def _connect(device: DeviceController) -> None:
    """The hellos, asked again while the emulator is still starting (on a busy machine it
    may take longer than a device's usual hello time)."""
    from equilibrist.hil.run import HILRefused

    deadline = time.monotonic() + START_TIMEOUT
    while True:
        try:
            device.connect()
            return
        except HILRefused as exc:
            if not str(exc).startswith("no answer") or time.monotonic() > deadline:
                raise


def run_pil(system: System, controller: AnyController, firmware: Firmware, *, label: str,
            precision: str, options: Mapping[str, Any], x0: Mapping[str, float] | None = None,
            timeout: float = 1.0) -> PILRun:
    """Run *firmware* in its emulator against *system* in lockstep, and ``simulate`` beside it.

    *options* are :func:`~equilibrist.sim.run.simulate`'s (without the
    controller). A fault (no answer, a reset, the emulator gone) ends the run
    with the samples so far, as in :func:`~equilibrist.hil.run.run_hil`.
    """
    from equilibrist.hil.link import SerialLink
    from equilibrist.hil.run import DeviceController, run_hil
    from equilibrist.sim.run import simulate

    target = firmware.target
    rate = float(options["rate"])
    hello, outputs = host_hello(system, controller, target=target, rate=rate,
                                tracking=options.get("reference") is not None)
    run_options = {**options, "outputs": None}
    with emulate(firmware) as emulation, SerialLink(emulation.port) as link:
        device = DeviceController(link, hello, outputs=outputs,
                                  u_op=system.operating_point().u, timeout=timeout)
        _connect(device)
        done = run_hil(system, device, x0=x0, **run_options)
    if done.fault is not None and emulation.other:
        # What the emulator said as it ended (simavr's harness: the firmware crashed).
        done = replace(done, fault=f"{done.fault} (the emulator: "
                                  f"{quote_outside(emulation.other[-1])})")
    simulated = simulate(system, controller, x0=x0, **options)
    run = PILRun(hil=done, target=target, firmware=firmware, steps=tuple(emulation.steps),
                 rate=rate, simulated=simulated, label=label, precision=precision)
    settings = dict(done.result.settings)
    settings["pil"] = {**run.figures(), "fault": run.fault}
    return replace(run, hil=replace(done, result=replace(done.result, settings=settings)))

