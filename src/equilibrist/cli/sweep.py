"""``equilibrist sweep``: a study over parameters and designs, into a Parquet table.

``equilibrist sweep SYSTEM --vary NAME=LOW:HIGH:N ... --runs R --out study.parquet``
or ``equilibrist sweep --study study.toml --out study.parquet``; locally, on
a local Dask cluster (``--workers N``) or on a running one (``--scheduler``).
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from equilibrist.cli import common
from equilibrist.errors import UsageError

if TYPE_CHECKING:
    from equilibrist.study.record import Study

_EPILOG = """\
Varied quantities (--vary, repeatable): any physical parameter of the system
(m_p=0.5:2:16), rate (the controller's sample rate, Hz), q.STATE and r.INPUT
(Bryson scales: the largest acceptable deviation of a state or input, in its
unit; the LQR weight is 1/scale^2), controller (lqr,lqg,mpc,swingup...), noise (scale of the
noise's standard deviations; 0 = none) and delay (0,1: commands one sample
late). Values: LOW:HIGH:N (evenly spaced, both ends), LOW:HIGH:N:log
(geometric), V1,V2,... or V. The grid is every combination; --sample random:N
draws N points instead (then a range is LOW:HIGH). A controller KIND:VALUE
gives VALUE to the kind's first option: controller=lqr,policy:ppo.zip
compares a trained network (--policy FILE) with the LQR, the table naming it
by its file's name; tvlqr:PLAN.npz, mpc:HORIZON likewise.

Each point: the controller designed (for the point's parameters, or the
nominal ones with --design-for nominal: the system with its --set values, a
parameter both set and varied among them; a failed design is a row with
status 'design failed' and the reason, never fatal), --runs runs with initial states
uniform in the --x0 ranges and parameters within (1 +- REL) of the point's
(--spread), and the metrics: fraction_up, settling_p50/p90/max, peak input,
time saturated, the quadratic cost, roa_fraction with --roa STATE=LOW:HIGH:N.

The table (one row per point; the study and the versions in the file's
metadata) is written chunk by chunk: Ctrl-C keeps the finished chunks, and
--resume computes only what is missing. The table is the same bytes however
it was computed: in one go or resumed, locally or on a cluster, on any
number of workers (every seed derives from --seed and the point's index).
--json prints a summary for scripts.
"""


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "sweep",
        help="a study: a grid or sample of parameters and designs, many runs each, to Parquet",
        description="Run a study: for each point of a grid (or random sample) over physical "
        "parameters, design weights, the rate, the controller, noise and delay, design the "
        "controller, run a batch and write one row of metrics to a Parquet table.",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("system", nargs="?", metavar="SYSTEM", help="a system name (or give --study)")
    p.add_argument("--study", metavar="FILE.toml", help="the study described in a TOML file")
    common.add_items(p, "--vary", marker="=", metavar="NAME=VALUES",
                     help="a varied quantity: NAME=LOW:HIGH:N[:log] or NAME=V1,V2,...")
    p.add_argument("--sample", metavar="random:N", help="draw N random points instead of the grid")
    p.add_argument("--runs", metavar="R", help="runs per point (default 100)")
    p.add_argument("--duration", metavar="S", help="seconds per run (default 5)")
    common.add_items(p, "--x0", marker="=", metavar="STATE=LOW:HIGH",
                     help="initial-state range (absolute; uniform)")
    common.add_items(p, "--spread", marker="=", metavar="PARAM=REL",
                     help="relative spread of a parameter around the point's value")
    common.add_items(p, "--roa", marker="=", metavar="STATE=LOW:HIGH:N",
                     help="estimate the region of attraction on this grid of initial states")
    from equilibrist.controllers import kinds

    p.add_argument("--controller", choices=kinds.names("study"),
                   help="when not varied (default lqg): " + ", ".join(kinds.names("study")))
    for opt in kinds.options("study"):  # the kinds' own options (--trajectory, --horizon ...)
        p.add_argument(opt.flag, metavar=opt.metavar, choices=opt.choices, default=None,
                       dest=opt.key, help=f"{opt.help} (to each point whose controller has it)")
    p.add_argument("--rate", metavar="HZ", help="when not varied (default: the rig's control rate)")
    p.add_argument("--noise", metavar="on|off|SCALE", help="when not varied (default on)")
    p.add_argument("--delay", action="store_true", help="commands one sample late (when not varied)")
    p.add_argument("--design-for", choices=("point", "nominal"),
                   help="design for each point's parameters (default) or the nominal ones")
    p.add_argument("--metrics", choices=("full", "basic"),
                   help="full (default) adds settling times and cost; basic is faster")
    p.add_argument("--seed", metavar="S", help="the study's seed (default 0)")
    common.add_set(p)
    p.add_argument("--out", required=True, metavar="FILE.parquet", help="the table")
    p.add_argument("--resume", action="store_true", help="continue an interrupted study")
    p.add_argument("--force", action="store_true",
                   help="replace an --out file that is not a study table (a study table is "
                   "replaced without it)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--workers", metavar="N", help="start a local Dask cluster of N processes")
    where.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="use a running Dask cluster")
    p.add_argument("--threads", metavar="T", help="threads per batch (default: cores / workers)")
    p.add_argument("--chunk-size", metavar="K", help="points per task (default: about 20,000 runs)")
    p.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    common.add_json(p)
    p.set_defaults(func=run)


_STUDY_OPTIONS = ("system", "vary", "sample", "runs", "duration", "x0", "spread", "roa",
                  "controller", "rate", "noise", "delay", "design_for", "metrics", "seed",
                  "settings")


def _count(text: str | None, option: str, minimum: int = 1) -> int | None:
    return None if text is None else common.parse_whole(text, option, minimum)


def _sample(text: str | None) -> int | None:
    if text is None:
        return None
    kind, sep, n = text.partition(":")
    if kind != "random" or not sep:
        raise UsageError(f"--sample {text!r}: expected random:N")
    return _count(n, "--sample random:N")


def build_study(args: argparse.Namespace) -> Study:
    """The :class:`~equilibrist.study.Study` of the command line (or its --study file)."""
    from equilibrist.study import load_study_file, make_study

    if args.study is not None:
        # SYSTEM beside --study names the study's system (a Python file is the user's to run).
        from equilibrist.controllers import kinds

        given = [o for o in _STUDY_OPTIONS if o != "system" and getattr(args, o) not in (None, [], False)]
        given += [o.key for o in kinds.options("study") if getattr(args, o.key, None) is not None]
        if given:
            flags = ", ".join("SYSTEM" if o == "system" else "--" + o.replace("_", "-")
                              .replace("settings", "set") for o in given)
            raise UsageError(f"--study describes the whole study: drop {flags} "
                                    "(or leave out --study)")
        return load_study_file(args.study, system=args.system)
    if args.system is None:
        raise UsageError("give a SYSTEM (with --vary ...) or --study FILE.toml")
    vary = []
    for item in args.vary:
        name, sep, value = item.partition("=")
        if not sep or not name.strip() or not value.strip():
            raise UsageError(f"--vary {item!r}: expected NAME=VALUES")
        vary.append((name.strip(), value.strip()))
    options: dict[str, Any] = {
        "vary": vary,
        "sample": _sample(args.sample),
        "x0": common.parse_assignments(args.x0, "--x0"),
        "spread": common.parse_assignments(args.spread, "--spread"),
        "roa": common.parse_assignments(args.roa, "--roa"),
        "settings": common.system_settings(args.system, args.settings),
        "delay": args.delay,
    }
    from equilibrist.controllers import kinds

    own = {o.key: getattr(args, o.key) for o in kinds.options("study")
           if getattr(args, o.key, None) is not None}
    if own:
        options["controller_options"] = own
    for key, value in (("runs", args.runs), ("duration", args.duration), ("seed", args.seed),
                       ("controller", args.controller), ("rate", args.rate),
                       ("noise", args.noise), ("design_for", args.design_for),
                       ("metrics", args.metrics)):
        if value is not None:
            options[key] = value
    return make_study(args.system, **options)


def run(args: argparse.Namespace) -> int:
    from equilibrist.cli.simulate import show_progress
    from equilibrist.study import run_study
    from equilibrist.study.store import parts_dir, require_pyarrow

    require_pyarrow()
    workers = _count(args.workers, "--workers")
    threads = _count(args.threads, "--threads")
    chunk = _count(args.chunk_size, "--chunk-size")
    study = build_study(args)
    try:
        done = run_study(study, args.out, resume=args.resume, workers=workers,
                         scheduler=args.scheduler, threads=threads, chunk_size=chunk,
                         progress=show_progress(args), force=args.force)
    except KeyboardInterrupt:
        from pathlib import Path

        parts = parts_dir(Path(args.out))
        if parts.exists():
            print(f"equilibrist: interrupted; the finished chunks are in {parts}: run the same "
                  "command with --resume to continue", file=sys.stderr)
        else:
            print("equilibrist: interrupted before any chunk was finished; nothing was written",
                  file=sys.stderr)
        return 130
    summary = done.to_dict()
    summary["study"] = study.to_dict()
    if args.json:
        common.print_json(summary)
        return 0
    rate = summary["runs_per_second"]
    print(f"{study.system}: {done.points} points x {study.runs} runs -> {done.out} "
          f"({done.computed_chunks} of {done.chunks} chunks computed, {done.where}, "
          f"{done.elapsed:.1f} s" + (f", {rate:,.0f} runs/s)" if rate else ")"))
    if done.failed_points:
        print(f"{done.failed_points} point(s) without a result: see the status and error columns")
    return 0
