"""``equilibrist hil``: the exported controller on a device, closed over a serial link.

The simulator plays the plant, the device (a board flashed with the export's
``hil_arduino`` sketch, or ``./hil_host PORT`` built by ``make hil-host``)
runs the controller. The run takes ``simulate``'s options; the JSON adds the
link's figures. Exit status 2 for a start that is refused (no device, another
controller), 1 for a run that ended on a fault (the run so far is saved).
"""

from __future__ import annotations

import argparse
import sys

from equilibrist.cli import common
from equilibrist.errors import ExportError, UsageError

_EPILOG = """\
--mode lockstep (default): the simulator waits for each answer; the run equals
'equilibrist simulate' of the same controller to the payload's rounding.
--mode realtime: the plant advances on the wall clock at the controller's
rate; an answer not back before the next sample is late and the previous
input is held. --payload float64 where the device has doubles (a host
program does; an 8-bit board does not). The device's controller must be the
one these options design: the hello compares the shapes, the rate and the
design id ('equilibrist export' with the same options, then flash or
'make hil-host'). --out run.csv writes the log 'equilibrist identify' reads;
--excite adds simulate's identification experiment to the device's command.
The protocol, the wiring and the loop back to identification: docs/hil.md.
"""


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from equilibrist.cli.simulate import add_run_options
    from equilibrist.viz.cli_hooks import add_output_options

    p = sub.add_parser(
        "hil",
        help="hardware in the loop: the exported controller on a device over a serial link",
        description="Close the loop between the simulated plant and the exported controller "
        "running on a device (or ./hil_host) over a serial link.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--port", required=True, metavar="PATH",
                   help="the device's serial port (/dev/ttyACM0, or a pseudo-terminal /dev/pts/N)")
    p.add_argument("--mode", choices=("lockstep", "realtime"), default="lockstep",
                   help="wait for every answer (default), or run on the wall clock")
    p.add_argument("--payload", choices=("float32", "float64"), default="float32",
                   help="the reals on the link (default float32)")
    p.add_argument("--timeout", default="1", metavar="S",
                   help="how long to wait for an answer before the run ends on a fault (default 1 s)")
    p.add_argument("--baud", default="115200", metavar="N", help="the link's baud rate (default 115200)")
    p.add_argument("--excite", metavar="SIGNAL", help="add an identification experiment to the "
                   "device's command: chirp:AMP:F0:F1[:SWEEP] or prbs:AMP:PERIOD (as simulate's)")
    add_run_options(p)
    common.add_rig_options(p)
    add_output_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from equilibrist.cli.simulate import (
        build_run,
        check_out,
        controller_name,
        parse_excitation,
        parse_x0,
        run_metrics,
        start_of,
    )
    from equilibrist.control.controller import measured_outputs
    from equilibrist.controllers import kinds
    from equilibrist.export.writer import design_id
    from equilibrist.hil.link import SerialLink
    from equilibrist.hil.protocol import Hello
    from equilibrist.hil.run import DeviceController, run_hil

    check_out(args, "the run")
    timeout = common.parse_number(args.timeout, "--timeout")
    if not 0 < timeout <= 60:
        raise UsageError(f"--timeout {args.timeout}: expected seconds in (0, 60]")
    try:
        baud = int(args.baud)
    except ValueError:
        raise UsageError(f"--baud {args.baud!r}: expected a whole number of bits per second") from None
    if not 50 <= baud <= 20_000_000:
        raise UsageError(f"--baud {baud}: expected 50 to 20000000 bits per second")
    system, options = build_run(args)
    kind = kinds.get(controller_name(args, system))  # --policy FILE alone: the network
    if kind.open_loop:
        raise UsageError(f"--controller {kind.name} is the open loop: there is no controller "
                         "on a device")
    simulated = options.pop("controller")
    try:
        controller_id = design_id(simulated)
    except ExportError as exc:
        raise UsageError(f"--controller {kind.name}: {exc}") from None
    outputs = measured_outputs(simulated) or tuple(system.spec.outputs)
    nr = 0 if options.get("reference") is None else len(getattr(simulated, "tracked_names", ()))
    host = Hello(real_size=8 if args.payload == "float64" else 4, n=system.n_states,
                 m=system.n_inputs, p=len(outputs), references=nr, estimate=0,
                 rate=float(options["rate"]), controller_id=controller_id)
    options["outputs"] = None
    with SerialLink(args.port, baudrate=baud) as link:
        device = DeviceController(link, host, outputs=tuple(outputs),
                                  u_op=system.operating_point().u, mode=args.mode, timeout=timeout,
                                  excitation=parse_excitation(args))
        device.connect()
        x0 = start_of({"controller": simulated}, parse_x0(args.x0))  # a plan starts the run
        done = run_hil(system, device, x0=x0, **options)
    result = done.result
    summary = {**run_metrics(result), **done.summary()}
    # A fault before the first answer leaves no run: nothing to save or draw.
    saved = result.save(args.out) if args.out is not None and result.n_rows else None
    if result.n_rows:
        from equilibrist.viz.cli_hooks import handle_outputs

        handle_outputs(args, result, system=system)
    if args.json:
        if saved is not None:
            summary["saved"] = str(saved)
        common.print_json(summary)
    else:
        link_figures = done.stats.summary()
        rt = link_figures["round_trip_ms"]
        print(f"{system.key} with the device on {args.port} ({args.mode}): "
              + ("ended before its first sample" if not result.n_rows else
                 "fell at " + f"{result.fell_at:g} s" if result.fell else "stayed up"))
        if rt["p50"] is not None:
            print(f"round trip p50 {rt['p50']:.3f} ms, p99 {rt['p99']:.3f} ms, max {rt['max']:.3f} ms; "
                  f"late {link_figures['late']}, lost {link_figures['lost']}")
        if saved is not None:
            print(f"saved {saved}")
    if done.fault is not None:
        kept = (f"; the run so far is in {saved}" if saved else
                "; the run ended before its first sample, nothing was saved" if not result.n_rows
                else "")
        print(f"equilibrist: {done.fault}{kept}", file=sys.stderr)
        return 1
    return 0
