"""``equilibrist plot``: pictures of saved results.

One result file (``equilibrist simulate --out run.npz``) gives its time
response; several give a comparison; a saved batch (``equilibrist batch
--out batch.npz``) gives the map of which runs stayed up over what varied
between them.
"""

from __future__ import annotations

import argparse
import zipfile
from pathlib import Path
from typing import TYPE_CHECKING

from equilibrist.cli import common
from equilibrist.errors import UsageError
from equilibrist.viz import plots_runs

if TYPE_CHECKING:
    from equilibrist.sim import BatchResult, SimResult

_EPILOG = """\
The picture is written beside the first file with the suffix .png unless
--out names another file (.png or .svg). Angles are shown in degrees
(--radians keeps radians). --states picks the coordinates shown.

A result of your own Python system file is plotted with --system FILE.py:
a data file never runs the Python file it names (docs/models.md).
"""


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = common.command(
        sub, "plot",
        help="plot saved results: a time response, a comparison, a batch's outcomes",
        description="Plot saved simulation results: one file gives its time response "
        "(states, estimates, measurements, reference, inputs with their limits); several "
        "files give a comparison; a saved batch gives the outcome of each run.",
        epilog=_EPILOG)
    p.add_argument("files", nargs="+", metavar="RESULT_FILE",
                   help="a result saved by 'equilibrist simulate --out' or 'batch --out'")
    p.add_argument("--out", "-o", metavar="FILE", help="the picture (.png or .svg)")
    p.add_argument("--states", metavar="NAME,...", help="coordinates to show (default: all)")
    p.add_argument("--labels", metavar="TEXT,...", help="legend labels of a comparison")
    p.add_argument("--radians", action="store_true", help="show angles in radians")
    common.add_system_option(p)
    add_study_options(p)
    p.set_defaults(func=run)


def add_study_options(p: argparse.ArgumentParser) -> None:
    """Options of a study table's picture (``equilibrist sweep --out study.parquet``)."""
    g = p.add_argument_group("study tables (.parquet)")
    g.add_argument("--metric", default="fraction_up", metavar="NAME",
                   help="the metric shown (default fraction_up; settling_p90, cost_mean, ...)")
    g.add_argument("--x", metavar="NAME", help="varied quantity along x (default: the first)")
    g.add_argument("--y", metavar="NAME",
                   help="varied quantity along y: a heat map (default: the second, if any)")
    g.add_argument("--agg", default="mean", choices=("mean", "median", "min", "max"),
                   help="how the other varied quantities are combined (default mean)")
    g.add_argument("--where", action="extend", nargs="+", default=[], metavar="NAME=VALUE",
                   help="fix another varied quantity at one of its values")


def plot_study_file(args: argparse.Namespace) -> int:
    """The picture of a study table (one file, ``.parquet``)."""
    from equilibrist.study.plot import plot_study
    from equilibrist.study.store import read_study
    from equilibrist.viz.output import FIGURE_FORMATS, VizError, check_suffix

    if len(args.files) > 1:
        raise VizError("plot one study table at a time")
    first = Path(args.files[0])
    out = check_suffix(args.out, FIGURE_FORMATS, "--out") if args.out else first.with_suffix(".png")
    table, study = read_study(first)
    # --x alone draws a line over x; neither draws the first two quantities' heat map.
    written = plot_study(table, study, out, metric=args.metric, x=args.x, y=args.y, agg=args.agg,
                         where=common.parse_assignments(args.where, "--where"))
    print(f"wrote {written}")
    return 0


def load_result(path: str | Path) -> SimResult | BatchResult:
    """A saved run (``SimResult``) or batch (``BatchResult``), whichever the file holds."""
    from equilibrist.sim import BatchResult, SimResult
    from equilibrist.sim.result import read_npz
    from equilibrist.viz.output import VizError

    p = Path(path)
    if not p.exists():
        raise VizError(f"no result file {str(p)!r}")
    try:
        meta, _ = read_npz(p)
        fmt = str(meta.get("format", "")) if isinstance(meta, dict) else ""
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        fmt = ""
    if fmt.startswith("equilibrist-batch"):
        return BatchResult.load(p)
    if fmt.startswith("equilibrist-simresult"):
        return SimResult.load(p)
    raise VizError(
        f"{str(p)!r} is not a saved result: expected a file written by "
        "'equilibrist simulate --out FILE.npz' or 'equilibrist batch --out FILE.npz'"
    )


def run(args: argparse.Namespace) -> int:
    from equilibrist.sim import BatchResult
    from equilibrist.viz import plots
    from equilibrist.viz.output import FIGURE_FORMATS, VizError, check_suffix

    if any(Path(f).suffix == ".parquet" for f in args.files):
        return plot_study_file(args)
    first = Path(args.files[0])
    out = check_suffix(args.out, FIGURE_FORMATS, "--out") if args.out else first.with_suffix(".png")
    states = common.parse_names(args.states, "--states")
    labels = common.parse_names(args.labels, "--labels")
    degrees = not args.radians
    results = [load_result(f) for f in args.files]
    system = common.named_system(args.system)
    batches = [r for r in results if isinstance(r, BatchResult)]
    if batches:
        if len(results) > 1:
            raise VizError("plot one batch at a time (a batch file cannot be compared with others)")
        plots.plot_batch(results[0], out, degrees=degrees, system=system)
    elif len(results) == 1:
        plots_runs.plot_response(results[0], out, states=states, degrees=degrees, system=system)
    else:
        names = labels or [Path(f).stem for f in args.files]
        if len(names) != len(results):
            raise UsageError(f"--labels gives {len(names)} labels for {len(results)} files")
        if len(set(names)) != len(names):
            raise UsageError("the comparison needs distinct labels: give --labels")
        plots_runs.plot_comparison(dict(zip(names, results, strict=True)), out, states=states,
                              degrees=degrees, system=system)
    print(f"wrote {out}")
    return 0
