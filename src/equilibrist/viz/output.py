"""Files out of the viz layer: figures as PNG or SVG, the viz error, ffmpeg."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import TYPE_CHECKING

from equilibrist.atomic import atomic_path
from equilibrist.errors import EquilibristError

if TYPE_CHECKING:  # matplotlib is imported when a figure is made
    from matplotlib.figure import Figure

#: Suffixes a figure can be saved as.
FIGURE_FORMATS = (".png", ".svg")
#: Suffixes an animation can be saved as.
ANIMATION_FORMATS = (".gif", ".mp4")


class VizError(EquilibristError, ValueError):
    """A plot or animation that can not be made as asked (a format that is
    not supported, ffmpeg missing for an MP4, nothing to show)."""


def check_suffix(path: str | Path, allowed: tuple[str, ...], what: str) -> Path:
    """*path* as a Path, refused unless its suffix is one of *allowed*."""
    p = Path(path)
    if p.suffix.lower() not in allowed:
        raise VizError(
            f"{what} {str(p)!r}: unsupported format {p.suffix or '(no suffix)'!r}; "
            f"use one of {', '.join(allowed)}"
        )
    return p


def save_figure(figure: Figure, path: str | Path, *, dpi: float | None = None) -> Path:
    """Save a matplotlib *figure* as PNG or SVG (by suffix) into an existing folder."""
    p = check_suffix(path, FIGURE_FORMATS, "figure")
    # Reproducible files: no date in an SVG, no software version in a PNG.
    metadata: dict[str, None] = {"Date": None} if p.suffix.lower() == ".svg" else {"Software": None}
    with atomic_path(p) as tmp:
        figure.savefig(tmp, dpi=dpi or figure.dpi, facecolor="white",
                       format=p.suffix.lower()[1:], metadata=metadata)
    return p


def ffmpeg_path() -> str | None:
    """The ffmpeg executable, or None when there is none.

    Looks at matplotlib's ``animation.ffmpeg_path`` setting when it names a
    file, then on ``PATH``, then for the ffmpeg that the ``imageio-ffmpeg``
    package ships (installed with equilibrist's ``video`` extra).
    """
    try:
        import matplotlib

        configured = str(matplotlib.rcParams.get("animation.ffmpeg_path", "ffmpeg"))
    except ImportError:  # pragma: no cover - matplotlib is a dependency
        configured = "ffmpeg"
    return shutil.which(configured) or shutil.which("ffmpeg") or bundled_ffmpeg()


def bundled_ffmpeg() -> str | None:
    """The ffmpeg binary of the ``imageio-ffmpeg`` package, if it is installed."""
    try:
        import imageio_ffmpeg
    except ImportError:
        return None
    try:
        return str(imageio_ffmpeg.get_ffmpeg_exe())
    except RuntimeError:  # the package is there but its binary is not
        return None
