"""``--plot`` and ``--animate`` for commands that produce a simulation result.

A command adds the options with :func:`add_output_options` and, once it has
its result, calls :func:`handle_outputs`. The file names are checked when
the arguments are parsed (a wrong suffix, or an MP4 without ffmpeg, fails
before anything is simulated).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from equilibrist import numbers
from equilibrist.atomic import OutputError, check_output
from equilibrist.viz.output import (
    ANIMATION_FORMATS,
    FIGURE_FORMATS,
    VizError,
    check_suffix,
    ffmpeg_path,
)

if TYPE_CHECKING:
    from equilibrist.numeric.system import System
    from equilibrist.sim.result import SimResult


def _figure_path(text: str) -> Path:
    try:
        return check_output(check_suffix(text, FIGURE_FORMATS, "figure"))
    except (VizError, OutputError) as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _animation_path(text: str) -> Path:
    try:
        path = check_output(check_suffix(text, ANIMATION_FORMATS, "animation"))
    except (VizError, OutputError) as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if path.suffix.lower() == ".mp4" and ffmpeg_path() is None:
        raise argparse.ArgumentTypeError(
            f"{text!r}: MP4 needs ffmpeg, which is not installed on this machine; "
            "use a .gif (needs nothing) or pip install 'equilibrist[video]'"
        )
    return path


def frame_size(text: str) -> tuple[int, int]:
    """``"480x360"`` -> ``(480, 360)`` (an argparse type)."""
    w, sep, h = text.lower().partition("x")
    try:
        size = (int(w), int(h))
    except ValueError:
        size = (0, 0)
    if not sep or size[0] < 48 or size[1] < 36 or size[0] > MAX_SIDE or size[1] > MAX_SIDE:
        raise argparse.ArgumentTypeError(
            f"{text!r}: expected WIDTHxHEIGHT in pixels, from 48x36 to {MAX_SIDE}x{MAX_SIDE}"
        )
    return size


# Bounds of an animation: a frame no larger than a 4K screen's long side,
# a frame rate a player shows, a frame count that fits in memory.
MAX_SIDE = 4096
MAX_FPS = 240.0
MAX_FRAMES = 20_000


def frame_rate(text: str) -> float:
    """Frames per second of simulated time (an argparse type)."""
    value = float(text) if numbers.is_decimal(text) else math.nan
    if not 0 < value <= MAX_FPS:
        raise argparse.ArgumentTypeError(f"{text!r}: expected frames per second in (0, {MAX_FPS:g}]")
    return value


def frame_count(text: str) -> int:
    """A number of frames (an argparse type)."""
    value = int(text) if numbers.is_whole(text) else 0
    if not 1 <= value <= MAX_FRAMES:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a whole number of frames from 1 to {MAX_FRAMES}")
    return value


def add_animation_options(parser: argparse.ArgumentParser) -> None:
    """``--fps``, ``--max-frames`` and ``--size`` of an animation."""
    parser.add_argument("--fps", type=frame_rate, default=20.0, metavar="N",
                        help="frames per second of simulated time (default 20)")
    parser.add_argument("--max-frames", type=frame_count, default=300, metavar="N",
                        help="at most this many frames; a long run plays with fewer per second "
                        "(default 300)")
    parser.add_argument("--size", type=frame_size, default=(480, 360), metavar="WxH",
                        help="frame size in pixels (default 480x360)")


def add_output_options(parser: argparse.ArgumentParser) -> None:
    """Add ``--plot FILE``, ``--animate FILE`` and the animation options."""
    group = parser.add_argument_group("pictures")
    group.add_argument("--plot", type=_figure_path, metavar="FILE",
                       help="plot the run's time response to FILE (.png or .svg)")
    group.add_argument("--animate", type=_animation_path, metavar="FILE",
                       help="animate the run to FILE (.gif; .mp4 where ffmpeg is installed)")
    add_animation_options(group)  # type: ignore[arg-type]


def handle_outputs(args: argparse.Namespace, result: SimResult, *,
                   system: System | None = None) -> list[Path]:
    """Write the pictures that *args* (of :func:`add_output_options`) asks for of *result*;
    each file is named on stderr, so that the command's own output (JSON) stays clean."""
    written: list[Path] = []
    if getattr(args, "plot", None) is None and getattr(args, "animate", None) is None:
        return written
    from equilibrist.viz.runs import as_run

    run = as_run(result, system=system)
    if args.plot is not None:
        from equilibrist.viz.plots_runs import plot_response

        plot_response(run, args.plot)
        written.append(Path(args.plot))
    if args.animate is not None:
        from equilibrist.viz.animation import animate_result

        width, height = args.size
        animate_result(run, args.animate, fps=args.fps, max_frames=args.max_frames, width=width,
                       height=height, progress=sys.stderr.isatty())
        written.append(Path(args.animate))
    for p in written:
        print(f"wrote {p}", file=sys.stderr)
    return written
