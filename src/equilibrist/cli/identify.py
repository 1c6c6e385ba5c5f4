"""``equilibrist identify``: the physical parameters of a system, fitted to a rig's log."""

from __future__ import annotations

import argparse
from pathlib import Path

from equilibrist.cli import common
from equilibrist.errors import UsageError

_EPILOG = """\
The log: a CSV file with a header row and one row per sample: the time t [s]
(increasing), one column per input of the system (the input that acted until
the next sample) and one per measured output, named after the state it
measures (units as 'equilibrist systems' lists them; a header may say them
in brackets, 'theta [rad]'). 'equilibrist simulate --out run.csv' writes
this format (with more columns, which are recognised and not used).

The fit: the parameters named by --free (the others at their values, with
--set and --params), and with --offsets a constant offset of each sensor,
on the system's derived model (scipy least_squares), in two stages. The rigs
balance unstable systems in closed loop, so the start is multiple shooting:
segments of --segment seconds (default: as long as the process noise stays
below the sensor noise over one), each from an estimated initial state, with
the logged input held between samples; the continuity defects between
segments are residuals weighted by the process noise. The estimate then
minimizes the one-step prediction errors of the model's Kalman filter, which
stay unbiased where the controller answers the process noise. Noise levels
start from the system's spec (--sensor-noise, --process-noise override them)
and are re-estimated from the residuals.

The answer: each estimate with its standard error, the correlation matrix,
the directions the log cannot tell apart in words, the NRMSE of each output,
a Ljung-Box whiteness test of the Kalman filter's prediction errors.
--plot FILE.png shows measured against replayed outputs; --out params.json
writes the parameters for 'design', 'simulate' and 'export' (--params).
"""


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = common.command(
        sub, "identify",
        help="fit physical parameters of a system to a logged run (grey-box, multiple shooting)",
        description="Fit the chosen physical parameters of a system's derived model to a log "
        "of the rig (time, inputs, measured outputs) by multiple shooting.",
        epilog=_EPILOG)
    common.add_system(p)
    p.add_argument("log", metavar="LOG.csv", help="the log: t, one column per input, one per "
                   "measured output")
    p.add_argument("--free", required=True, metavar="NAME,...",
                   help="the parameters to fit (comma-separated)")
    p.add_argument("--offsets", action="store_true",
                   help="also fit a constant offset of each sensor")
    p.add_argument("--segment", metavar="S",
                   help="length of the shooting segments [s] (default: from the noise levels)")
    p.add_argument("--max-step", metavar="S", default="0.001",
                   help="longest RK4 step [s] (default 0.001)")
    common.add_items(p, "--sensor-noise", marker="=", metavar="OUTPUT=STD",
                     help="sensor standard deviation of an output (start value; default the "
                     "spec's)")
    common.add_items(p, "--process-noise", marker="=", metavar="STATE=SIGMA",
                     help="process noise intensity on a state rate [unit/s/sqrt(Hz)] (start "
                     "value; default the spec's)")
    common.add_set(p)
    common.add_params(p)
    p.add_argument("--plot", metavar="FILE", help="plot measured against replayed outputs "
                   "(.png or .svg)")
    p.add_argument("--out", metavar="FILE.json",
                   help="write the parameters (for --params of design, simulate, export)")
    p.add_argument("--force", action="store_true",
                   help="replace an --out file that is not a parameter file equilibrist wrote")
    common.add_json(p)
    p.set_defaults(func=run)


def _levels(items: list[str], option: str, *, positive: bool = False) -> dict[str, float]:
    raw = common.parse_assignments(items, option)
    out = {}
    for k, v in raw.items():
        value = common.parse_number(v, f"{option} {k}")
        if value < 0 or (positive and value == 0):
            # A sensor without noise would have infinite weight: the fit would never end.
            raise UsageError(f"{option} {k}: expected a value {'>' if positive else '>='} 0, "
                                    f"got {v}")
        out[k] = value
    return out


def _check_out(path: str, force: bool) -> None:
    """Refuse to replace a file that is not a parameter file equilibrist wrote, unless *force*."""
    import json

    from equilibrist.ident.log import IdentificationError
    from equilibrist.ident.params import FORMAT

    target = Path(path)
    if target.is_dir():
        raise IdentificationError(f"--out {path} is a folder: name the parameter file")
    if force or not (target.exists() or target.is_symlink()):
        return
    try:
        doc = json.loads(target.read_text())
    except (OSError, ValueError):
        doc = None
    if not (isinstance(doc, dict) and doc.get("format") == FORMAT):
        raise IdentificationError(f"--out {path} exists and is not a parameter file written by "
                                  "'equilibrist identify': name a new file, or add --force to "
                                  "replace it")


def run(args: argparse.Namespace) -> int:
    from equilibrist.ident import identify, read_log, write_params
    from equilibrist.ident.log import IdentificationError

    # Everything that can be checked before the fit is checked first, so
    # that a mistake costs no time and nothing is half-written.
    free = common.parse_names(args.free, "--free") or ()
    segment = None if args.segment is None else common.parse_positive(args.segment, "--segment")
    max_step = (None if args.max_step is None
                else common.parse_positive(args.max_step, "--max-step"))
    sensor = _levels(args.sensor_noise or [], "--sensor-noise", positive=True)
    process = _levels(args.process_noise or [], "--process-noise")
    if args.out is not None and Path(args.out).suffix != ".json":
        raise IdentificationError(f"--out {args.out}: the parameters are written as .json")
    if args.out is not None:
        _check_out(args.out, args.force)
        common.check_output_path(args.out, "--out")  # its folder exists: none is created
    if args.plot is not None:
        from equilibrist.viz.output import FIGURE_FORMATS, check_suffix

        check_suffix(args.plot, FIGURE_FORMATS, "--plot")
        common.check_output_path(args.plot, "--plot")  # its folder exists: none is created
    system = common.load_system(args)
    log = read_log(system, args.log)
    for name in sensor:
        if name not in log.output_names:
            raise IdentificationError(
                f"--sensor-noise {name}: not a measured output of the log "
                f"({', '.join(log.output_names)})")
    for name in process:
        if name not in system.state_names:
            raise IdentificationError(
                f"--process-noise {name}: not a state of {system.key} "
                f"({', '.join(system.state_names)})")
    result = identify(system, log, free, offsets=args.offsets, segment=segment,
                      max_step=max_step or 1e-3, sensor_noise=sensor, process_noise=process)
    written = []
    if args.plot is not None:
        from equilibrist.ident.plot import plot_fit

        written.append(plot_fit(result, args.plot))
    if args.out is not None:
        _check_out(args.out, args.force)  # again: the fit took a while
        written.append(write_params(result.params_document(), args.out))
    if args.json:
        out = result.to_dict()
        out["written"] = [str(w) for w in written]
        common.print_json(out)
        return 0
    print(result.summary())
    for w in written:
        print(f"wrote {w}")
    return 0
