"""Animations of a run, from arrays or from a simulation result.

Frames are rendered by :class:`~equilibrist.viz.frames.FrameRenderer` (the
drawing reads states only) and written as an animated GIF by Pillow (pure
Python, always available) or as an MP4 by ffmpeg when ffmpeg is installed.
The animation plays in real time: frame ``k`` shows the latest sample at or
before ``t0 + k * dt``; a long run gets fewer frames per second rather than
more frames than *max_frames*.
"""

from __future__ import annotations

import base64
import math
import subprocess
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.atomic import atomic_path
from equilibrist.viz.output import ANIMATION_FORMATS, VizError, check_suffix, ffmpeg_path

if TYPE_CHECKING:
    from equilibrist.numeric.system import System
    from equilibrist.sim.result import SimResult
    from equilibrist.viz.runs import Run

#: Default frame rate and cap on the number of frames.
DEFAULT_FPS = 20.0
DEFAULT_MAX_FRAMES = 200
#: Seconds of simulated time an event's label stays on the animation.
EVENT_HOLD = 0.5


def frame_times(t: np.ndarray, *, fps: float = DEFAULT_FPS, max_frames: int = DEFAULT_MAX_FRAMES) -> np.ndarray:
    """Times of the frames of an animation of samples at times *t*.

    Parameters
    ----------
    t : numpy.ndarray
        Sample times, increasing.
    fps : float
        Wanted frames per second of simulated time.
    max_frames : int
        At most this many frames (the frame rate drops to fit).

    Returns
    -------
    numpy.ndarray
        Evenly spaced frame times from ``t[0]`` to ``t[-1]``.
    """
    t = np.asarray(t, float)
    if t.ndim != 1 or len(t) == 0:
        raise VizError("an animation needs at least one sample time")
    if fps <= 0 or not math.isfinite(fps):
        raise VizError(f"frames per second must be a positive number, got {fps}")
    if max_frames < 1:
        raise VizError(f"max_frames must be at least 1, got {max_frames}")
    duration = float(t[-1] - t[0])
    n = min(int(max_frames), math.floor(duration * fps + 1e-9) + 1)
    return np.linspace(t[0], t[-1], max(n, 1))


def _sample_index(t: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Index of the latest sample at or before each of *times*."""
    idx = np.searchsorted(t, times + 1e-12 * max(1.0, abs(float(t[-1]))), side="right") - 1
    return np.clip(idx, 0, len(t) - 1)


def render_frames(
    system: System,
    t: np.ndarray,
    states: np.ndarray,
    *,
    inputs: np.ndarray | None = None,
    commands: np.ndarray | None = None,
    fps: float = DEFAULT_FPS,
    max_frames: int = DEFAULT_MAX_FRAMES,
    width: int = 480,
    height: int = 360,
    title: str | None = None,
    speed: float = 1.0,
    events: Sequence[tuple[float, str]] = (),
    progress: bool = False,
) -> tuple[list[np.ndarray], np.ndarray]:
    """Render the frames of an animation.

    Parameters
    ----------
    system : equilibrist.numeric.system.System
        The bound system whose run is shown.
    t : numpy.ndarray
        ``(n_steps,)`` sample times.
    states : numpy.ndarray
        ``(n_steps, n_states)`` states (time-major).
    inputs : numpy.ndarray, optional
        ``(n_steps, n_inputs)`` inputs applied (after saturation).
    commands : numpy.ndarray, optional
        ``(n_steps, n_inputs)`` inputs asked for (before saturation).
    fps, max_frames : float, int
        See :func:`frame_times`.
    width, height : int
        Frame size in pixels.
    title : str, optional
        Title line of the frames.
    speed : float
        Playback speed relative to real time (0.25: slow motion, shown
        beside the time stamp); *fps* is frames per second of playback.
    events : sequence of (float, str)
        Instants to announce (``(4.0, "push +120")``): each label shows in
        red for :data:`EVENT_HOLD` seconds of simulated time from its instant.
    progress : bool
        Show a progress bar.

    Returns
    -------
    frames : list of numpy.ndarray
        ``(height, width, 3)`` ``uint8`` pictures.
    times : numpy.ndarray
        The time of each frame.
    """
    from equilibrist.viz.frames import FrameRenderer

    t = np.asarray(t, float)
    states = np.atleast_2d(np.asarray(states, float))
    n_states = len(system.state_names)
    if states.shape != (len(t), n_states):
        raise VizError(
            f"states of {system.key} have shape {states.shape}, expected ({len(t)}, {n_states}) "
            "(time-major, one row per sample time)"
        )
    for what, arr in (("inputs", inputs), ("commands", commands)):
        if arr is not None and np.shape(arr) != (len(t), len(system.input_names)):
            raise VizError(
                f"{what} of {system.key} have shape {np.shape(arr)}, expected "
                f"({len(t)}, {len(system.input_names)})"
            )
    if not (speed > 0 and math.isfinite(speed)):
        raise VizError(f"playback speed must be a positive number, got {speed}")
    times = frame_times(t, fps=fps / speed, max_frames=max_frames)
    index = _sample_index(t, times)
    renderer = FrameRenderer(system, states=states[index], inputs=None if inputs is None else inputs[index],
                             width=width, height=height, title=title)
    # The trace of a scene that draws one follows the samples, thinned to a few thousand.
    thin = max(1, len(t) // 3000)
    frames = []
    bar = _progress_bar()(total=len(times), desc=f"animating {system.key}", unit="frame", disable=not progress,
               leave=False)
    with bar:
        for k, i in enumerate(index):
            u = None if inputs is None else inputs[i]
            c = None if commands is None else commands[i]
            trail = np.vstack([states[: i + 1 : thin], states[i : i + 1]])
            now = float(times[k])
            note = "  ".join(label for at, label in events if at <= now + 1e-9 < at + EVENT_HOLD)
            frames.append(renderer.frame(states[i], u, command=c, t=now, trail=trail, speed=speed,
                                         note=note))
            bar.update()
    return frames, times


def _progress_bar() -> Any:
    """tqdm's class: its notebook bar in a Jupyter kernel that can draw it (ipywidgets), its
    text bar elsewhere (``tqdm.auto`` alone warns "IProgress not found" in a kernel without
    ipywidgets)."""
    import importlib.util

    if importlib.util.find_spec("ipywidgets") is None:
        from tqdm import tqdm

        return tqdm
    from tqdm.auto import tqdm as auto

    return auto


def write_gif(frames: Sequence[np.ndarray], path: str | Path, *, frame_seconds: float) -> Path:
    """Write *frames* as a looping animated GIF (Pillow).

    Parameters
    ----------
    frames : sequence of numpy.ndarray
        ``(height, width, 3)`` ``uint8`` pictures, all the same size.
    path : str or pathlib.Path
        Output file.
    frame_seconds : float
        Display time of each frame.
    """
    from PIL import Image

    if not frames:
        raise VizError("no frames to write")
    p = Path(path)
    # One palette for the whole animation, from a few frames spread over it:
    # colours stay steady from frame to frame, and it is ten times faster
    # than a palette per frame.
    pick = np.unique(np.linspace(0, len(frames) - 1, min(len(frames), 8)).round().astype(int))
    palette = Image.fromarray(np.vstack([frames[k] for k in pick])).quantize(
        colors=255, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE)
    images = [Image.fromarray(f).quantize(palette=palette, dither=Image.Dither.NONE) for f in frames]
    ms = max(20, round(frame_seconds * 1000 / 10) * 10)  # GIF delays are in 10 ms steps
    with atomic_path(p) as tmp:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:], duration=ms,
                       loop=0, optimize=False, disposal=1)
    return p


def write_mp4(frames: Sequence[np.ndarray], path: str | Path, *, fps: float) -> Path:
    """Write *frames* as an H.264 MP4 through ffmpeg.

    Raises
    ------
    VizError
        When there is no ffmpeg (install equilibrist's ``video`` extra,
        ``pip install 'equilibrist[video]'``, or the system's ffmpeg, or
        write a ``.gif``).
    """
    exe = ffmpeg_path()
    if exe is None:
        raise VizError(
            f"cannot write {str(path)!r}: MP4 needs ffmpeg, which is not installed on this "
            "machine (pip install 'equilibrist[video]', or the system's ffmpeg, or ask for "
            "a .gif, which needs nothing)"
        )
    if not frames:
        raise VizError("no frames to write")
    p = Path(path)
    h, w = frames[0].shape[:2]
    cmd = [
        exe, "-y", "-loglevel", "error", "-f", "rawvideo", "-pix_fmt", "rgb24",
        "-s", f"{w}x{h}", "-r", f"{fps:.6g}", "-i", "-",
        # yuv420p (what players expect) needs even sizes: pad by one pixel if odd.
        "-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-pix_fmt", "yuv420p", "-vcodec", "libx264",
    ]
    data = b"".join(np.ascontiguousarray(f, dtype=np.uint8).tobytes() for f in frames)
    with atomic_path(p) as tmp:
        done = subprocess.run([*cmd, "-f", "mp4", str(tmp)], input=data, capture_output=True, check=False)
        if done.returncode != 0:
            raise VizError(f"ffmpeg failed writing {str(p)!r}: {done.stderr.decode(errors='replace').strip()}")
    return p


def animate(
    system: System,
    t: np.ndarray,
    states: np.ndarray,
    path: str | Path,
    *,
    inputs: np.ndarray | None = None,
    commands: np.ndarray | None = None,
    fps: float = DEFAULT_FPS,
    max_frames: int = DEFAULT_MAX_FRAMES,
    width: int = 480,
    height: int = 360,
    title: str | None = None,
    speed: float = 1.0,
    events: Sequence[tuple[float, str]] = (),
    progress: bool = False,
) -> Path:
    """Animate a run of *system* from arrays to a GIF or MP4 (by suffix).

    Parameters are those of :func:`render_frames`, plus *path*: the output
    file, ``.gif`` or ``.mp4``.

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    VizError
        For another suffix, or an MP4 without ffmpeg (checked before any
        frame is rendered).
    """
    p = check_suffix(path, ANIMATION_FORMATS, "animation")
    if p.suffix.lower() == ".mp4" and ffmpeg_path() is None:
        write_mp4([], p, fps=fps)  # raises the message that says what to do
    frames, times = render_frames(system, t, states, inputs=inputs, commands=commands, fps=fps,
                                  max_frames=max_frames, width=width, height=height, title=title,
                                  speed=speed, events=events, progress=progress)
    # Seconds of playback per frame.
    step = float(times[1] - times[0]) / speed if len(times) > 1 else 1.0 / fps
    if p.suffix.lower() == ".mp4":
        return write_mp4(frames, p, fps=1.0 / step)
    return write_gif(frames, p, frame_seconds=step)


def animate_result(result: SimResult | Run, path: str | Path, *, system: System | None = None,
                   estimates: bool = False, **options: Any) -> Path:
    """Animate a simulation result to a GIF or MP4.

    Parameters
    ----------
    result : equilibrist.sim.SimResult
        The run (its true states, inputs before and after saturation).
    path : str or pathlib.Path
        Output file, ``.gif`` or ``.mp4``.
    system : equilibrist.numeric.system.System, optional
        The system simulated (default: rebuilt from the result's system
        name and parameters).
    estimates : bool
        Draw the estimated states instead of the true ones.
    **options
        Passed to :func:`animate` (``fps``, ``max_frames``, ``width``,
        ``height``, ``title``, ``speed``, ``progress``).
    """
    from equilibrist.viz.runs import as_run

    run = as_run(result, system=system)
    states = run.estimate if estimates else run.x
    if states is None:
        raise VizError("this result holds no estimated states to animate")
    options.setdefault("events", run.events)
    return animate(run.system, run.t, states, path, inputs=run.u, commands=run.u_command,
                   **options)


@dataclass(frozen=True)
class InlineAnimation:
    """An animation held in memory to show in a notebook: an MP4 played by an HTML5 video
    element, or an animated GIF where ffmpeg is missing.

    Attributes
    ----------
    data : bytes
        The file's bytes.
    mime : str
        ``"video/mp4"`` or ``"image/gif"``.
    """

    data: bytes
    mime: str

    def __repr__(self) -> str:
        return f"InlineAnimation({self.mime}, {len(self.data)} bytes)"

    def _repr_html_(self) -> str:
        source = f"data:{self.mime};base64,{base64.b64encode(self.data).decode('ascii')}"
        if self.mime == "video/mp4":
            return f"<video controls autoplay loop muted playsinline src='{source}'></video>"
        return f"<img src='{source}' alt='animation'/>"

    def save(self, path: str | Path) -> Path:
        """Write the animation to *path* (its suffix must match: ``.mp4`` or ``.gif``)."""
        suffix = ".mp4" if self.mime == "video/mp4" else ".gif"
        p = check_suffix(path, (suffix,), "animation")
        with atomic_path(p) as tmp:
            Path(tmp).write_bytes(self.data)
        return p


def animate_inline(result: SimResult | Run, *, system: System | None = None,
                   estimates: bool = False, progress: bool = True,
                   **options: Any) -> InlineAnimation:
    """Animate a simulation result for a notebook: an MP4 (HTML5 video) with ffmpeg, else a GIF.

    Parameters are those of :func:`animate_result` without *path*; the progress bar is
    on by default (a notebook's widget bar in Jupyter).
    """
    import tempfile

    suffix = ".mp4" if ffmpeg_path() is not None else ".gif"
    with tempfile.TemporaryDirectory() as folder:
        path = animate_result(result, Path(folder) / f"animation{suffix}", system=system,
                              estimates=estimates, progress=progress, **options)
        data = path.read_bytes()
    return InlineAnimation(data, "video/mp4" if suffix == ".mp4" else "image/gif")
