"""``equilibrist animate``: an animation of a saved run, drawn from its states."""

from __future__ import annotations

import argparse
from pathlib import Path

from equilibrist.cli import common
from equilibrist.errors import UsageError

_EPILOG = """\
The animation is written beside the result with the suffix .gif unless --out
names another file (.gif, or .mp4 where ffmpeg is installed). It plays in
real time (--speed 0.25 for slow motion); a long run gets fewer frames per
second rather than more than --max-frames. A run of your own Python system
file is animated with --system FILE.py: a data file never runs the Python
file it names.
"""


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    from equilibrist.viz.cli_hooks import add_animation_options

    p = common.command(
        sub, "animate",
        help="animate a saved run (GIF; MP4 where ffmpeg is installed)",
        description="Animate a run saved by 'equilibrist simulate --out', drawn to scale "
        "from its states, with a time stamp and the input applied.",
        epilog=_EPILOG)
    p.add_argument("file", metavar="RESULT_FILE", help="a run saved by 'equilibrist simulate --out'")
    p.add_argument("--out", "-o", metavar="FILE", help="the animation (.gif or .mp4)")
    add_animation_options(p)
    p.add_argument("--speed", default="1", metavar="X",
                   help="playback speed relative to real time (default 1; 0.25 is slow motion)")
    p.add_argument("--estimates", action="store_true",
                   help="draw what the controller believed (its estimates) instead of the truth")
    common.add_system_option(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import sys

    from equilibrist.cli.plot import load_result
    from equilibrist.sim import SimResult
    from equilibrist.viz.animation import animate_result
    from equilibrist.viz.output import ANIMATION_FORMATS, VizError, check_suffix

    src = Path(args.file)
    out = check_suffix(args.out, ANIMATION_FORMATS, "--out") if args.out else src.with_suffix(".gif")
    speed = common.parse_positive(args.speed, "--speed")
    if args.fps <= 0 or args.max_frames < 1:
        raise UsageError("--fps must be positive and --max-frames at least 1")
    result = load_result(src)
    if not isinstance(result, SimResult):
        raise VizError(f"{str(src)!r} is a batch: animate one run (save it with 'equilibrist "
                       "simulate --out'), or plot the batch with 'equilibrist plot'")
    width, height = args.size
    animate_result(result, out, system=common.named_system(args.system), fps=args.fps, max_frames=args.max_frames, width=width,
                   height=height, speed=speed, estimates=args.estimates,
                   progress=sys.stderr.isatty())
    print(f"wrote {out}")
    return 0
