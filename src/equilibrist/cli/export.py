"""``equilibrist export``: the digital controller as a tested C99 library."""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING

from equilibrist import numbers
from equilibrist.cli import common

if TYPE_CHECKING:
    from pathlib import Path

    from equilibrist.export.vectors import RecordedStart
    from equilibrist.export.writer import ExportReport
    from equilibrist.numeric.system import System

PRECISIONS = ("double", "float", "float64", "float32")
#: Other names of the precisions: float32 is float, float64 is double.
PRECISION_NAMES = {"float32": "float", "float64": "double"}

_EPILOG = """\
Writes into --out (default ./<system>_<controller>): <name>.h and <name>.c
(the library), example_desktop.c, example_arduino/ (a sketch), test vectors
<name>_vectors.h with the test program test_<name>.c, a Makefile ('make'
builds everything with -std=c99 -Wall -Wextra -Werror -pedantic, 'make
check' runs the test program, 'make size' prints the library's code, static
data and stack in bytes) and README.txt (with those figures as measured at
export, also in --json as "footprint").

--precision float (float32) is single-precision arithmetic: the LQR/LQG
library and the MPC (DAQP built with -DDAQP_SINGLE_PRECISION, 'make check'
within 1e-4 of the input range of the double controller's commands).

The test vectors are a recorded closed-loop run of the simulation's own
controller on the nonlinear plant, with noise (--duration seconds, --seed).

--controller swingup or mpc: written by their own exporters when installed;
a controller that does not apply to the system, or that has no C exporter,
is refused in one line. --at STATE=VALUE designs at another equilibrium.

--rate defaults to the system's control rate (the rate of its rig's digital
controller, from the system's spec). Weights are diagonals, comma-separated,
as for 'equilibrist design'.
"""


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = common.command(
        sub, "export",
        help="export the digital controller as a tested C99 library",
        description="Design the digital LQG (or LQR) controller of a system and write it as a "
        "self-contained C99 library with examples, test vectors, a test program and a Makefile.",
        epilog=_EPILOG)
    common.add_system(p)
    p.add_argument("--rate", metavar="HZ", default=None,
                   help="sample rate [Hz] (default: the system's control rate)")
    p.add_argument("--precision", choices=PRECISIONS, default="double",
                   help="arithmetic of the C code: double (float64) or float (float32); "
                        "default double")
    p.add_argument("--force", action="store_true",
                   help="write into a folder that holds files equilibrist did not write, "
                        "replacing those of the export's names")
    p.add_argument("--out", metavar="DIR", default=None,
                   help="output folder (default ./<system>_<controller>)")
    common.add_design_options(p)
    common.add_controller(p, "export", default=None,
                          help="the controller to export (default lqg; policy with --policy)")
    p.add_argument("--duration", metavar="S", default=None,
                   help="length of the recorded test-vector run [s]")
    p.add_argument("--seed", type=_seed, default=0, help="noise seed of the test-vector run")
    p.add_argument("--x0", metavar="NAME=VALUE,...", default=None,
                   help="start of the test-vector run (states not named at the operating point; "
                   "default: a quarter of each coordinate's design scale off, less if that falls)")
    common.add_set(p)
    common.add_params(p)
    common.add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from equilibrist.errors import ExportError
    from equilibrist.export.folder import check_folder, check_rate
    from equilibrist.native.c_text import c_identifier

    # Everything that can be checked without designing is checked first.
    rate = None if args.rate is None else check_rate(common.parse_number(args.rate, "--rate"))
    duration = None
    if args.duration is not None:
        duration = common.parse_number(args.duration, "--duration")
        if not (math.isfinite(duration) and duration > 0):
            raise ExportError(f"--duration must be a positive number of seconds, got {duration:g}")
    from equilibrist.controllers import kinds

    # --policy FILE alone exports the trained network (--controller policy).
    args.controller = args.controller or ("policy" if getattr(args, "policy", None) else "lqg")
    record = kinds.get(args.controller, "export")
    if record.open_loop:
        raise ExportError(f"--controller {args.controller} is the open loop: there is no "
                          "controller to export")
    _check_options(args)
    out = Path(args.out) if args.out else Path(f"{c_identifier(args.system)}_{args.controller}")
    check_folder(out, force=args.force)
    from equilibrist.export.vectors import RecordedStart, recorded_start

    start = RecordedStart(None if args.x0 is None else {
        k: common.parse_number(v, f"--x0 {k}")
        for k, v in common.parse_assignments([t for t in args.x0.split(",") if t.strip()] or [args.x0],
                                             "--x0").items()})
    with recorded_start(start):
        return _export(args, out, rate, duration, start)


def _export(args: argparse.Namespace, out: Path, rate: float | None, duration: float | None,
            start: RecordedStart) -> int:
    from equilibrist.errors import ExportError
    from equilibrist.export.folder import check_rate

    system = common.load_system(args)
    if system.n_inputs == 0:
        raise ExportError(f"{system.key} has no input: there is no controller to export")
    if rate is None:
        rate = check_rate(system.spec.control_rate)
    from equilibrist.export.vectors import check_duration

    check_duration(duration, rate, "--duration")  # bounded before the recorded run

    from equilibrist.controllers import kinds

    request = kinds.ControllerRequest(
        system=system, rate=rate, design_options=common.design_options(args),
        options=common.controller_options(args, args.controller, "export"))
    done = kinds.get(args.controller, "export").write_export(
        request, out, precision=PRECISION_NAMES.get(args.precision, args.precision),
        duration=duration, seed=args.seed,
        force=args.force)
    return _report(args, done, system, start)


def _check_options(args: argparse.Namespace) -> None:
    """Refuse what the export cannot use: an empty --out, a negative --seed, the options of
    another controller."""
    from equilibrist.errors import ExportError

    if args.out is not None and not args.out.strip():
        raise ExportError(f"--out {args.out!r}: expected the name of the output folder")
    if args.seed < 0:
        raise ExportError(f"--seed {args.seed}: expected a whole number >= 0")
    common.controller_options(args, args.controller, "export")  # another kind's options


def _report(args: argparse.Namespace, done: ExportReport, system: System,
            start: RecordedStart | None = None) -> int:
    used = start.used if start is not None else {}
    if args.json:
        common.print_json({
            "folder": str(done.folder),
            "name": done.name,
            "design_id": done.data.fingerprint,
            "controller": done.data.controller,
            "precision": done.precision,
            "rate": done.data.rate,
            "files": dict(done.files),
            "vector_steps": done.vectors.n_steps,
            "vector_start": used,
            **_budget(done),
        })
        return 0
    print(f"{done.name}: {done.data.controller.upper()} controller of {system.key} at "
          f"{done.data.rate:g} Hz in {done.precision}, design id {done.data.fingerprint}")
    print(f"written to {done.folder}:")
    width = max(len(f) for f in done.files)
    for fname, what in done.files.items():
        print(f"  {fname:<{width}}  {what}")
    footprint = getattr(done, "footprint", None)
    if footprint is not None:
        print(f"make size: code {footprint.code} bytes, data {footprint.data} bytes, "
              f"stack {footprint.stack} bytes")
    iterations = getattr(done, "iterations", None)
    if iterations:
        print(f"DAQP's iterations, worst: {iterations['recorded_run']} over the recorded run, "
              f"{iterations['sampled_states']} over {iterations['samples']} sampled states")
    if used:
        print("test vectors recorded from " + ", ".join(f"{k} = {v:.6g}" for k, v in used.items()))
    print(f"build and check it: make -C {done.folder} check")
    return 0


def _budget(done: ExportReport) -> dict[str, object]:
    """The footprint ``make size`` printed at export (``null`` and ``footprint_note`` when it
    was not measured) and, for the MPC, DAQP's worst iteration counts."""
    footprint = getattr(done, "footprint", None)
    out: dict[str, object] = {
        "footprint": None if footprint is None else footprint.as_dict(),
        "footprint_note": str(getattr(done, "size_note", "")),
    }
    iterations = getattr(done, "iterations", None)
    if iterations:
        out["daqp_iterations"] = dict(iterations)
    return out


def _seed(text: str) -> int:
    """``--seed``: a whole number in decimal digits (an argparse type; a negative one is
    refused with the other checks, before any work)."""
    if not numbers.is_whole(text):
        raise argparse.ArgumentTypeError(f"{text!r}: expected a whole number >= 0")
    return int(text)
