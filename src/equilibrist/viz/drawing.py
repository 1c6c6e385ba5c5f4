"""What the scenes draw with: the parts' colours, :class:`Shape`, the geometry of
bars, discs, arrows and arcs, the parts several scenes share (a track's ticks, a
wheel's spokes, a torque's arc), and the :class:`Scene` base class."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

# Colours of the parts, fixed so that tests can find a part by its colour.
COLORS: dict[str, str] = {
    "ground": "#9a9a9a",
    "body": "#3b6fb6",  # cart, robot body, pendulum arm, beam
    "link": "#e8871e",  # pole, first link, ball
    "link2": "#2e9e4f",  # second link
    "wheel": "#4a4a4a",
    "mark": "#d1263b",  # spoke, spin mark, tip trace head
    "input": "#9b30c8",  # force, thrust and torque arrows
    "pivot": "#222222",
    "trace": "#56b4e9",
    "ball": "#e8871e",
    "mass": "#6b4c2a",
    "disc": "#8fb3de",
    "text": "#333333",
}


@dataclass(frozen=True)
class Shape:
    """One element of a drawing, keeping its *key* from frame to frame.

    *kind* is ``"fill"`` (closed polygon), ``"line"`` (polyline), ``"hline"`` (a horizontal
    line across the picture at ``points[0, 1]``) or ``"text"`` (*text* at ``points[0]``);
    *points* are ``(n, 2)`` world coordinates, empty to hide the element. *width* is in
    points (a fill's edge, in *edge* colour), *z* the drawing order (higher on top), and
    *bounds* whether the element counts when the picture's extent is chosen.
    """

    key: str
    kind: str
    points: np.ndarray
    color: str
    width: float = 1.5
    z: float = 2.0
    bounds: bool = True
    text: str = ""
    edge: str | None = None


# -- geometry ------------------------------------------------------------------


def _pts(*xy: Sequence[float]) -> np.ndarray:
    return np.array(xy, dtype=float).reshape(-1, 2)


def bar(p0: np.ndarray | Sequence[float], p1: np.ndarray | Sequence[float], width: float) -> np.ndarray:
    """The rectangle of a rod of *width* from *p0* to *p1*."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    d = p1 - p0
    n = np.hypot(*d)
    perp = np.array([-d[1], d[0]]) / n * width / 2 if n > 0 else np.array([width / 2, 0.0])
    return np.array([p0 + perp, p1 + perp, p1 - perp, p0 - perp])


def circle(center: np.ndarray | Sequence[float], radius: float, n: int = 48) -> np.ndarray:
    s = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    return np.column_stack([center[0] + radius * np.cos(s), center[1] + radius * np.sin(s)])


def rect(cx: float, y0: float, width: float, height: float) -> np.ndarray:
    """Axis-aligned rectangle with bottom centre ``(cx, y0)``."""
    return _pts((cx - width / 2, y0), (cx + width / 2, y0),
                (cx + width / 2, y0 + height), (cx - width / 2, y0 + height))


def arrow(start: np.ndarray | Sequence[float], vector: np.ndarray | Sequence[float],
          width: float) -> np.ndarray:
    """A filled arrow polygon from *start* along *vector* (empty when tiny)."""
    start, vector = np.asarray(start, float), np.asarray(vector, float)
    length = float(np.hypot(*vector))
    if length < 1e-3 * width:
        return np.empty((0, 2))
    d = vector / length
    n = np.array([-d[1], d[0]])
    head = min(2.2 * width, 0.6 * length)
    shaft = length - head
    w = width / 2
    tip = start + vector
    return np.array([
        start + n * w, start + d * shaft + n * w, start + d * shaft + n * 2 * w, tip,
        start + d * shaft - n * 2 * w, start + d * shaft - n * w, start - n * w,
    ])


def arc_arrow(center: np.ndarray, radius: float, start: float, span: float, width: float) -> np.ndarray:
    """A curved arrow around *center* from angle *start* over *span* rad
    (counter-clockwise when *span* > 0); empty when the span is tiny."""
    if abs(span) < 0.25:  # too short to read as an arrow (the gauge still shows it)
        return np.empty((0, 2))
    head = min(2.2 * width / radius, 0.5 * abs(span))
    body_end = start + span - math.copysign(head, span)
    s = np.linspace(start, body_end, max(8, int(abs(span) * 12)))
    c = np.asarray(center, float)
    outer = c + np.column_stack([np.cos(s), np.sin(s)]) * (radius + width / 2)
    inner = c + np.column_stack([np.cos(s), np.sin(s)]) * (radius - width / 2)
    e = body_end
    tip_angle = start + span
    head_pts = np.array([
        c + (radius + width) * np.array([math.cos(e), math.sin(e)]),
        c + radius * np.array([math.cos(tip_angle), math.sin(tip_angle)]),
        c + (radius - width) * np.array([math.cos(e), math.sin(e)]),
    ])
    return np.vstack([outer, head_pts, inner[::-1]])


def lean(angle: float) -> np.ndarray:
    """Unit vector of a link at *angle* from vertical-up, clockwise positive."""
    return np.array([math.sin(angle), math.cos(angle)])


def disc_radius(inertia: float, mass: float) -> float:
    """Radius of a uniform disc of *mass* with *inertia* about its axle."""
    return math.sqrt(2.0 * inertia / mass)


def _fill(key: str, points: np.ndarray, color: str, *, z: float = 2.0, edge: str | None = None,
          width: float = 1.0, bounds: bool = True) -> Shape:
    return Shape(key, "fill", np.asarray(points, float), color, width=width, z=z, edge=edge,
                 bounds=bounds)


def _line(key: str, points: np.ndarray, color: str, *, width: float = 1.5, z: float = 3.0,
          bounds: bool = True) -> Shape:
    return Shape(key, "line", np.asarray(points, float), color, width=width, z=z, bounds=bounds)


def _text(key: str, at: Sequence[float], text: str, *, color: str = COLORS["text"]) -> Shape:
    return Shape(key, "text", _pts(at), color, z=6.0, text=text, bounds=False)


def _ticks(size: float) -> np.ndarray:
    """Marks along the track every 10 % of *size* (so that motion shows)."""
    step = _nice(0.25 * size)
    xs = np.arange(-400, 401) * step
    pts = np.full((3 * len(xs), 2), np.nan)
    pts[0::3, 0] = xs
    pts[1::3, 0] = xs
    pts[0::3, 1] = 0.0
    pts[1::3, 1] = -0.03 * size
    return pts


def _nice(v: float) -> float:
    """The largest 1, 2 or 5 times a power of ten not above *v*."""
    e = math.floor(math.log10(v))
    power = 10.0**e
    for m in (5.0, 2.0, 1.0):
        if m * power <= v:
            return m * power
    return power


def _spokes(key: str, center: np.ndarray, radius: float, angle: float) -> list[Shape]:
    """A red spoke at *angle* (clockwise from up) and a grey one across it."""
    d = lean(angle)
    perp = lean(angle + math.pi / 2)
    return [
        _fill(f"{key}_cross", bar(center - perp * radius * 0.9, center + perp * radius * 0.9,
                                  0.08 * radius), COLORS["ground"], z=3.2),
        _fill(f"{key}_spoke", bar(center, center + d * radius * 0.95, 0.16 * radius),
              COLORS["mark"], z=3.4),
    ]


def _torque(key: str, center: np.ndarray, radius: float, frac: float, width: float) -> Shape:
    """A curved arrow around *center*, clockwise for positive *frac*, 3/4 turn at full scale."""
    return _fill(key, arc_arrow(center, radius, math.pi / 2, -1.5 * math.pi * frac, width),
                 COLORS["input"], z=5)


# -- scenes --------------------------------------------------------------------


class Scene:
    """The drawing of one *system* (its parameters give the dimensions, its input limits the
    scale of the input arrows). Subclasses implement :meth:`shapes`; ``trail`` is the
    sequence of states up to the one drawn, for scenes that draw a trace (the gyroscope).
    """

    #: What the picture shows, one line.
    caption = ""
    #: Whether the picture is a 3D projection (no metre scale bar).
    projected = False

    def __init__(self, system: object) -> None:
        self.system = system
        self.params = dict(system.params)  # type: ignore[attr-defined]
        self.state_names: tuple[str, ...] = tuple(system.state_names)  # type: ignore[attr-defined]
        self.input_names: tuple[str, ...] = tuple(system.input_names)  # type: ignore[attr-defined]
        self._index = {n: i for i, n in enumerate(self.state_names)}
        if self.input_names:
            low, high = system.input_limits  # type: ignore[attr-defined]
            self.input_low = np.asarray(low, float)
            self.input_high = np.asarray(high, float)
        else:
            self.input_low = self.input_high = np.zeros(0)

    def q(self, x: np.ndarray, name: str) -> float:
        """The state component *name* of *x*."""
        return float(x[self._index[name]])

    def input_fraction(self, u: np.ndarray | None, i: int = 0) -> float:
        """Input *i* as a fraction of its largest limit in magnitude (signed)."""
        if u is None or len(u) <= i:
            return 0.0
        full = max(abs(self.input_low[i]), abs(self.input_high[i]))
        if not math.isfinite(full) or full <= 0:
            return 0.0
        return float(np.clip(u[i] / full, -1.0, 1.0))

    def shapes(self, x: np.ndarray, u: np.ndarray | None, trail: np.ndarray | None = None) -> list[Shape]:
        """The drawing of state *x* with input *u* (world coordinates)."""
        raise NotImplementedError

    def extent(self, states: np.ndarray, inputs: np.ndarray | None = None) -> tuple[float, float, float, float]:
        """``(xmin, xmax, ymin, ymax)`` that shows every state of *states* (up to 80 evenly
        spaced ones are drawn to find it) with its *inputs*' arrows."""
        states = np.atleast_2d(np.asarray(states, float))
        n = len(states)
        pick = np.unique(np.linspace(0, n - 1, min(n, 80)).round().astype(int))
        pts = []
        reach = self.reach(states)
        if reach is not None:
            pts.append(np.array([[reach[0], reach[2]], [reach[1], reach[3]]]))
        for k in pick:
            u = None if inputs is None or not len(inputs) else np.asarray(inputs)[k]
            for s in self.shapes(states[k], u, states[: k + 1]):
                if s.bounds and s.kind in ("fill", "line") and len(s.points):
                    pts.append(s.points)
        allp = np.vstack(pts)
        lo, hi = allp.min(axis=0), allp.max(axis=0)
        span = max(float((hi - lo).max()), 1e-6)
        pad = 0.06 * span
        return (float(lo[0] - pad), float(hi[0] + pad), float(lo[1] - pad), float(hi[1] + pad))

    def reach(self, states: np.ndarray) -> tuple[float, float, float, float] | None:
        """``(xmin, xmax, ymin, ymax)`` that the view contains whatever the
        swinging parts do between the states sampled by :meth:`extent`
        (None: the sampled states alone size the view).

        A pendulum's view holds the whole upper half of the circle its links
        sweep about their pivot (their full length, upright or leaning to
        horizontal on either side), so a link never leaves the top of the
        frame as it swings.
        """
        return None
