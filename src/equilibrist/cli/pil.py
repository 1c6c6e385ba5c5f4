"""``equilibrist pil``: the exported controller on an emulated microcontroller, in lockstep.

The controller (``simulate``'s and ``export``'s options) is exported, its
hardware-in-the-loop sketch built for the target with the chip's toolchain
(cached), and run in the chip's emulator, whose UART is the link; the loop
closes in lockstep against the simulated plant, and ``simulate`` runs beside
it. Exit status 2 for a firmware that cannot be built or does not fit the
chip, 1 for a run that ended on a fault (no answer, a reset, a step over its
period: the run so far is saved).
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from equilibrist.cli import common
from equilibrist.errors import ExportError, UsageError

if TYPE_CHECKING:
    from equilibrist.pil.run import PILRun

_EPILOG = """\
Targets: uno (ATmega328P at 16 MHz: avr-gcc and simavr; cycles exact; double
is 32 bits), cortex-m4f (STM32F405 at 168 MHz with a single-precision FPU:
arm-none-eabi-gcc and QEMU netduinoplus2), cortex-m0 (nRF51822 at 16 MHz:
QEMU microbit). On QEMU the figures are instructions, counted by the
emulator (-icount), at one cycle each. --precision float builds the export
in float32 (the FPU's arithmetic on cortex-m4f); the Uno's double is float32
whatever is asked. The report: cycles per step (median and worst) against
the period's budget, flash, static RAM, the stack's high-water mark (painted),
the largest rate that fits, and the largest difference between the chip's
commands and simulate's (max_deviation, in the input's units). A firmware
that does not fit the chip is refused in one line with its figures. Built
firmware is cached by content. Reference: docs/pil.md.
"""


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from equilibrist.cli.simulate import add_run_options
    from equilibrist.pil.targets import TARGETS
    from equilibrist.viz.cli_hooks import add_output_options

    p = common.command(
        sub, "pil",
        help="processor in the loop: the exported controller on an emulated microcontroller",
        description="Build the exported controller into firmware for a microcontroller, run it "
        "in the chip's emulator and close the loop in lockstep with the simulated plant.",
        epilog=_EPILOG)
    p.add_argument("--target", required=True, choices=tuple(TARGETS),
                   help="the microcontroller: " + ", ".join(TARGETS))
    p.add_argument("--precision", choices=("double", "float", "float64", "float32"),
                   default="double", help="the export's arithmetic (default double; the Uno's "
                   "double is 32 bits)")
    p.add_argument("--timeout", default="5", metavar="S",
                   help="how long to wait for the firmware's answer (default 5 s)")
    add_run_options(p)
    add_output_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from equilibrist.cli.simulate import build_run, check_out, parse_x0, run_metrics, start_of
    from equilibrist.controllers import kinds
    from equilibrist.pil.run import check_fits, firmware_for, run_pil
    from equilibrist.pil.targets import get

    check_out(args, "the run")
    timeout = common.parse_number(args.timeout, "--timeout")
    if not 0 < timeout <= 60:
        raise UsageError(f"--timeout {args.timeout}: expected seconds in (0, 60]")
    target = get(args.target)
    target.check_tools()
    # --policy FILE alone runs the trained network, as simulate does.
    kind = kinds.get(args.controller or ("policy" if getattr(args, "policy", None) else "lqg"))
    if kind.open_loop:
        raise UsageError(f"--controller {kind.name} is the open loop: there is no controller "
                         "on a chip")
    precision = {"float32": "float", "float64": "double"}.get(args.precision, args.precision)
    system, options = build_run(args)
    controller = options.pop("controller")
    label = kind.label.split(" (")[0]
    try:
        firmware = firmware_for(controller, system=system, target=target, precision=precision,
                                label=label)
    except ExportError as exc:
        raise UsageError(f"--controller {kind.name}: {exc}") from None
    check_fits(firmware, f"{label} ({kind.name})")
    x0 = start_of({"controller": controller}, parse_x0(args.x0))
    done = run_pil(system, controller, firmware, label=label, precision=precision,
                   options=options, x0=x0, timeout=timeout)
    result = done.result
    figures = done.figures()
    saved = result.save(args.out) if args.out is not None and result.n_rows else None
    if result.n_rows:
        from equilibrist.viz.cli_hooks import handle_outputs

        handle_outputs(args, result, system=system)
    if args.json:
        summary = {**run_metrics(result), **done.hil.summary(), **figures,
                   "fault": done.fault, "report": done.headline()}
        if saved is not None:
            summary["saved"] = str(saved)
        common.print_json(summary)
    else:
        _print_report(done, system.key, saved)
    if done.fault is not None:
        kept = (f"; the run so far is in {saved}" if saved else
                "; the run ended before its first sample, nothing was saved" if not result.n_rows
                else "")
        print(f"equilibrist: {done.fault}{kept}", file=sys.stderr)
        return 1
    return 0


def _print_report(done: PILRun, key: str, saved: object) -> None:
    f = done.figures()
    t = done.target
    result = done.result
    print(f"{key} on {t.name} ({t.chip}), lockstep: "
          + ("ended before its first sample" if not result.n_rows else
             f"fell at {result.fell_at:g} s" if result.fell else "stayed up"))
    print(done.headline() + f" ({t.counted})")
    cycles = f["cycles_per_step"]
    assert isinstance(cycles, dict)
    print(f"cycles per step: median {cycles['median']:,.0f}, max {cycles['max']:,}; "
          f"largest rate that fits {f['max_rate']:,.0f} Hz" if cycles["max"] else "no step measured")
    stack = f["stack_bytes"]
    print(f"flash {f['flash_bytes']:,} of {t.flash_bytes:,} bytes; static RAM {f['ram_bytes']:,} "
          f"+ stack {stack if stack is not None else '?'} of {t.ram_bytes:,} bytes; "
          f"fits: {'yes' if f['fits'] else 'no'}")
    dev = f["max_deviation"]
    arithmetic = "float32" if t.double_bits == 32 or done.precision == "float" else "float64"
    print(f"largest difference from simulate's commands: {dev:.3g} ({arithmetic} on the chip)"
          if isinstance(dev, float) else "no command to compare with simulate's")
    if saved is not None:
        print(f"saved {saved}")
