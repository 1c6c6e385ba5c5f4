"""A figure that draws a :class:`~equilibrist.viz.scenes.Scene` frame by frame.

:class:`FrameRenderer` lays out the picture (the scene to scale with a scale
bar, the time stamp, one gauge per input showing the applied input within
its limits and the command when saturation cut it) and renders a state to
an RGB array or a PNG. The artists are made once and updated for each
frame, so that rendering an animation does not rebuild the figure.

:func:`draw_state` draws a single state to a PNG or SVG file.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict, Unpack

import numpy as np

from equilibrist.viz.drawing import COLORS, Scene, Shape, _nice
from equilibrist.viz.output import VizError, save_figure
from equilibrist.viz.scenes import scene_for

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.lines import Line2D
    from matplotlib.patches import Rectangle
    from matplotlib.text import Text

    from equilibrist.numeric.system import System

# Colour of an input gauge within limits, and when the command saturates.
_GAUGE = "#9b30c8"
_SATURATED = "#d1263b"


class _Gauge(TypedDict):
    """The artists and the scale of one input's gauge."""

    bar: Rectangle
    cmd: Line2D
    value: Text
    lo: float
    hi: float
    unit: str


class _DrawOptions(TypedDict, total=False):
    """The keyword arguments of :meth:`FrameRenderer.draw` after the state and input."""

    command: np.ndarray | None
    t: float | None
    trail: np.ndarray | None
    speed: float
    note: str


class FrameRenderer:
    """Render one system's drawing, one state at a time, *width* x *height* pixels, of the
    world *extent* ``(xmin, xmax, ymin, ymax)`` (default: what the run's *states* and
    *inputs* need).
    """

    def __init__(
        self,
        system: System,
        *,
        extent: tuple[float, float, float, float] | None = None,
        states: np.ndarray | None = None,
        inputs: np.ndarray | None = None,
        width: int = 480,
        height: int = 360,
        title: str | None = None,
    ) -> None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.system = system
        self.scene: Scene = scene_for(system)
        if width < 48 or height < 36:
            raise VizError(f"a frame of {width} x {height} pixels is too small (at least 48 x 36)")
        self.width, self.height = int(width), int(height)
        if extent is None:
            if states is None:
                states = np.atleast_2d(self._rest_state())
            extent = self.scene.extent(np.atleast_2d(states), inputs)
        dpi = 100.0
        # A hair over the exact size: Agg truncates the canvas size to whole pixels.
        self.figure = Figure(figsize=((self.width + 1e-3) / dpi, (self.height + 1e-3) / dpi), dpi=dpi)
        self.canvas = FigureCanvasAgg(self.figure)
        self.font = max(5.0, min(11.0, self.height / 36.0))
        n_in = len(self.scene.input_names)
        # Layout in figure fractions: two text lines on top, the gauges below.
        line = 1.35 * self.font / (72.0 / dpi) / self.height
        gauge_h = 1.6 * line
        gauge_step = gauge_h + 1.3 * line  # the gauge and its tick labels
        bottom = (0.01 + 1.2 * line + gauge_step * n_in) if n_in else 0.01
        top = 1.0 - 2.3 * line
        box = (0.01, bottom, 0.98, top - bottom)
        self.ax = self.figure.add_axes(box)
        self.ax.set_axis_off()
        # Equal scale in x and y: widen the extent to the axes' shape.
        x0, x1, y0, y1 = _fit(extent, box[2] * self.width / (box[3] * self.height))
        self.ax.set_xlim(x0, x1)
        self.ax.set_ylim(y0, y1)
        self.extent = (x0, x1, y0, y1)
        title = title if title is not None else _title(system)
        # The title leaves room for the time stamp (about 0.6 em per character).
        room = 0.72 * self.width / (0.62 * dpi / 72.0 * max(len(title), 1))
        self.figure.text(0.01, 0.995, title, ha="left", va="top", fontsize=min(self.font, room),
                         color=COLORS["text"], weight="bold")
        self.caption_text = self.figure.text(0.01, 0.995 - line, self.scene.caption, ha="left",
                                             va="top", fontsize=self.font * 0.8, color="#666666")
        self.time_text = self.figure.text(0.99, 0.995, "", ha="right", va="top",
                                          fontsize=self.font, family="monospace",
                                          color=COLORS["text"], weight="bold")
        self._line, self._speed_y = line, 0.995 - line
        self.speed_text = self.figure.text(0.99, self._speed_y, "", ha="right", va="top",
                                           fontsize=self.font * 0.8, color="#666666")
        # What is happening now (a push), in red under the captions.
        self.note_text = self.figure.text(0.01, 0.995 - 2.1 * line, "", ha="left", va="top",
                                          fontsize=self.font, color="#d1263b", weight="bold")
        self._artists: dict[str, Artist] = {}
        self._background: object = None  # the Agg canvas's BufferRegion (untyped)
        self._fitted_speed: str | None = None
        self._gauges = [
            self._make_gauge(i, 0.01 + 1.2 * line + gauge_step * (n_in - 1 - i), gauge_h)
            for i in range(n_in)
        ]
        if not self.scene.projected:
            self._scale_bar()

    # -- layout ------------------------------------------------------------------
    def _rest_state(self) -> np.ndarray:
        # All coordinates zero: upright or level for every system (the
        # drawing never solves the dynamics for an operating point).
        return np.zeros(len(self.scene.state_names))

    def _scale_bar(self) -> None:
        x0, x1, y0, y1 = self.extent
        length = _nice(0.2 * (x1 - x0))
        label = f"{length * 100:g} cm" if length < 1 else f"{length:g} m"
        # Bottom right of the world shown, above the ground line.
        xe = x1 - 0.03 * (x1 - x0)
        ys = y0 + 0.04 * (y1 - y0)
        self.ax.plot([xe - length, xe], [ys, ys], color=COLORS["text"], lw=1.5,
                     solid_capstyle="butt", zorder=7)
        self.ax.text(xe - length / 2, ys + 0.015 * (y1 - y0), label, ha="center", va="bottom",
                     fontsize=self.font * 0.85, color=COLORS["text"], zorder=7)

    def _fit_caption(self) -> None:
        """Keep the caption line and the speed note beside it apart: when
        the caption leaves no room for the note, the note moves down a line
        (right-aligned, opposite the event note); a caption wider than the
        frame is shrunk to fit it."""
        # matplotlib's Agg canvas methods are unannotated (untyped calls under --strict).
        renderer = self.canvas.get_renderer()  # type: ignore[no-untyped-call]
        gap = 0.8 * self.font * self.figure.dpi / 72.0  # pixels
        self.caption_text.set_fontsize(self.font * 0.8)
        self.speed_text.set_y(self._speed_y)
        caption = self.caption_text.get_window_extent(renderer)
        room = self.width * 0.99 - caption.x0
        if caption.width > room:
            self.caption_text.set_fontsize(max(3.0, self.font * 0.8 * room / caption.width * 0.98))
            caption = self.caption_text.get_window_extent(renderer)
        if self.speed_text.get_text():
            speed = self.speed_text.get_window_extent(renderer)
            if caption.x1 + gap > speed.x0:
                self.speed_text.set_y(self._speed_y - self._line)

    def _make_gauge(self, i: int, y: float, h: float) -> _Gauge:
        name = self.scene.input_names[i]
        unit = self.system.input_units[i]
        lo, hi = float(self.scene.input_low[i]), float(self.scene.input_high[i])
        if not (math.isfinite(lo) and math.isfinite(hi)):
            lo, hi = -1.0, 1.0
        ax = self.figure.add_axes((0.3, y, 0.42, h))
        span = hi - lo
        ax.set_xlim(lo - 0.02 * span, hi + 0.02 * span)
        ax.set_ylim(0, 1)
        ax.set_yticks([])
        ax.set_xticks([lo, hi])
        ax.tick_params(labelsize=self.font * 0.75, length=2, pad=1)
        for spine in ("top", "right", "left"):
            ax.spines[spine].set_visible(False)
        ax.axvspan(lo, hi, color="#eeeeee", zorder=0)
        ax.axvline(0.0 if lo <= 0 <= hi else lo, color=COLORS["text"], lw=0.8, zorder=3)
        bar = ax.barh([0.5], [0.0], left=[0.0], height=0.8, color=_GAUGE, zorder=2)[0]
        cmd = ax.axvline(0.0, color=_SATURATED, lw=1.5, ls=":", zorder=4, visible=False)
        self.figure.text(0.29, y + h / 2, f"{name} [{unit}]" if unit else name, ha="right",
                         va="center", fontsize=self.font * 0.9, color=COLORS["text"])
        value = self.figure.text(0.73, y + h / 2, "", ha="left", va="center",
                                 fontsize=self.font * 0.9, family="monospace", color=COLORS["text"])
        return {"bar": bar, "cmd": cmd, "value": value, "lo": lo, "hi": hi, "unit": unit}

    # -- drawing -----------------------------------------------------------------
    def _apply(self, shape: Shape) -> None:
        from matplotlib.lines import Line2D
        from matplotlib.patches import Polygon
        from matplotlib.text import Text

        art = self._artists.get(shape.key)
        pts = shape.points
        if art is None:
            if shape.kind == "fill":
                art = Polygon(pts if len(pts) else np.zeros((1, 2)), closed=True, facecolor=shape.color,
                              edgecolor=shape.edge or "none", linewidth=shape.width if shape.edge else 0,
                              zorder=shape.z, antialiased=True)
                self.ax.add_patch(art)
            elif shape.kind == "line":
                art = Line2D([], [], color=shape.color, linewidth=shape.width * self.font / 9,
                             zorder=shape.z, solid_capstyle="round")
                self.ax.add_line(art)
            elif shape.kind == "hline":
                art = self.ax.axhline(float(pts[0, 1]), color=shape.color, lw=shape.width, zorder=shape.z)
            elif shape.kind == "text":
                art = self.ax.text(0.0, 0.0, "", fontsize=self.font * 0.85, color=shape.color,
                                   ha="center", va="center", zorder=shape.z)
            else:
                raise ValueError(f"unknown shape kind {shape.kind!r}")
            self._artists[shape.key] = art
            self._background = None  # a new moving part: take the background again
        # A key keeps its kind from frame to frame, so its artist is of that kind.
        if shape.kind == "fill":
            assert isinstance(art, Polygon)
            if len(pts):
                art.set_xy(pts)
            art.set_visible(bool(len(pts)))
        elif shape.kind == "line":
            assert isinstance(art, Line2D)
            art.set_data(pts[:, 0], pts[:, 1]) if len(pts) else art.set_data([], [])
        elif shape.kind == "hline":
            assert isinstance(art, Line2D)
            art.set_ydata([pts[0, 1], pts[0, 1]])
        elif shape.kind == "text":
            assert isinstance(art, Text)
            art.set_position((float(pts[0, 0]), float(pts[0, 1])))
            art.set_text(shape.text)

    def draw(
        self,
        x: np.ndarray,
        u: np.ndarray | None = None,
        *,
        command: np.ndarray | None = None,
        t: float | None = None,
        trail: np.ndarray | None = None,
        speed: float = 1.0,
        note: str = "",
    ) -> None:
        """Update the figure to state *x* with the input *u* applied; *command* (before
        saturation) is a dotted mark on the gauge where it differs from *u*; *trail* is the
        states up to *x*; *speed*, when not 1, is shown under the time stamp *t*; *note*
        (``"push +120"``) is shown in red."""
        x = np.asarray(x, float)
        uu = None if u is None else np.atleast_1d(np.asarray(u, float))
        for shape in self.scene.shapes(x, uu, trail):
            self._apply(shape)
        self.time_text.set_text("" if t is None else f"t = {t:6.2f} s")
        self.speed_text.set_text("" if math.isclose(speed, 1.0) else
                                 ("slow motion" if speed < 1 else "fast") + f" x{speed:g}")
        if self.speed_text.get_text() != self._fitted_speed:
            # The caption is static (drawn with the background): fit it
            # beside the new speed note and take the background again.
            self._fitted_speed = self.speed_text.get_text()
            self._fit_caption()
            self._background = None
        self.note_text.set_text(note)
        for i, g in enumerate(self._gauges):
            val = 0.0 if uu is None else float(uu[i])
            clipped = min(max(val, g["lo"]), g["hi"])
            g["bar"].set_x(min(0.0, clipped) if g["lo"] <= 0 <= g["hi"] else g["lo"])
            g["bar"].set_width(abs(clipped) if g["lo"] <= 0 <= g["hi"] else clipped - g["lo"])
            saturated = False
            if command is not None:
                c = float(np.atleast_1d(command)[i])
                saturated = not math.isclose(c, val, rel_tol=1e-6, abs_tol=1e-9)
                g["cmd"].set_xdata([min(max(c, g["lo"]), g["hi"])] * 2)
            g["cmd"].set_visible(saturated)
            g["bar"].set_color(_SATURATED if saturated else _GAUGE)
            text = f"{val:+.3g} {g['unit']}".rstrip() if uu is not None else "-"
            g["value"].set_text(text + (" sat." if saturated else ""))

    def _dynamic(self) -> list[Artist]:
        """The artists that change from frame to frame, in drawing order."""
        scene = sorted(self._artists.values(), key=lambda a: a.get_zorder())
        gauges = [a for g in self._gauges for a in (g["bar"], g["cmd"], g["value"])]
        return [*scene, self.time_text, self.speed_text, self.note_text, *gauges]

    def frame(self, x: np.ndarray, u: np.ndarray | None = None,
              **kwargs: Unpack[_DrawOptions]) -> np.ndarray:
        """Draw state *x* (see :meth:`draw`) and return the picture as an
        ``(height, width, 3)`` ``uint8`` array.

        The static parts (titles, scale bar, gauge scales) are drawn once
        and kept as a background; each frame draws the moving parts on it.
        """
        self.draw(x, u, **kwargs)
        if self._background is None:
            for a in self._dynamic():
                a.set_animated(True)
            # matplotlib's Agg canvas methods are unannotated (untyped calls under --strict).
            self.canvas.draw()  # type: ignore[no-untyped-call]
            self._background = self.canvas.copy_from_bbox(self.figure.bbox)  # type: ignore[no-untyped-call]
        self.canvas.restore_region(self._background)  # type: ignore[no-untyped-call]
        for a in self._dynamic():
            self.figure.draw_artist(a)
        rgba = np.asarray(self.canvas.buffer_rgba())  # type: ignore[no-untyped-call]
        return rgba[: self.height, : self.width, :3].copy()

    def save(self, path: str | Path) -> Path:
        """Save the current picture (PNG or SVG by the file's suffix)."""
        for a in self._dynamic():
            a.set_animated(False)
        self._background = None
        return save_figure(self.figure, path)

    def to_pixels(self, points: np.ndarray) -> np.ndarray:
        """World points to ``(column, row)`` pixel coordinates of the frame
        (row 0 at the top), as drawn last."""
        xy = self.ax.transData.transform(np.atleast_2d(points))
        return np.column_stack([xy[:, 0], self.height - xy[:, 1]])


def _fit(extent: tuple[float, float, float, float], aspect: float) -> tuple[float, float, float, float]:
    """*extent* widened (never cut) to a width / height ratio of *aspect*."""
    x0, x1, y0, y1 = extent
    w, h = x1 - x0, y1 - y0
    if w / h < aspect:
        grow = (aspect * h - w) / 2
        return (x0 - grow, x1 + grow, y0, y1)
    grow = (w / aspect - h) / 2
    return (x0, x1, y0 - grow, y1 + grow)


def _title(system: System) -> str:
    return system.spec.title or system.key


def draw_state(
    system: System,
    x: np.ndarray,
    path: str | Path,
    *,
    u: np.ndarray | None = None,
    t: float | None = None,
    width: int = 480,
    height: int = 360,
    extent: tuple[float, float, float, float] | None = None,
) -> Path:
    """Draw one state *x* of *system* (with its input *u*) to a PNG or SVG file; *extent*
    defaults to the drawing of *x* itself."""
    x = np.asarray(x, float)
    renderer = FrameRenderer(system, extent=extent, states=x[None, :],
                             inputs=None if u is None else np.atleast_2d(u), width=width, height=height)
    renderer.draw(x, u, t=t, trail=x[None, :])
    return renderer.save(path)
