"""Drawings of every system of the catalogue from a state vector.

A :class:`Scene` turns one state ``x`` (and the input ``u`` when it has one)
into a list of :class:`Shape` objects in world coordinates (metres; the
gyroscope's in a 3D projection of metres), drawn to scale from the system's
parameters. It reads the state and the parameters only: it never calls the
dynamics. The sign conventions are those of ``SYSTEMS.md``: angles from
vertical-up are clockwise positive, so a positive angle leans a link towards
+x (to the right of the picture); the seesaw's and the ball-and-beam's
angles are counter-clockwise from +x.

Where a dimension is not a parameter (a cart's size, a beam's length), it is
chosen in proportion to one that is and the choice is written beside it.
A wheel's radius comes from its inertia as a uniform disc,
``r = sqrt(2 I / m)``.

:func:`scene_for` returns the scene of a bound
:class:`~equilibrist.numeric.system.System`; :data:`SCENES` maps each
system name to its scene class.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from equilibrist.errors import UnknownNameError

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
    """One element of a drawing.

    Attributes
    ----------
    key : str
        Stable name of the element (the same element keeps its key from
        frame to frame).
    kind : str
        ``"fill"`` (closed polygon), ``"line"`` (polyline), ``"hline"`` (a
        horizontal line across the picture at ``points[0, 1]``) or
        ``"text"`` (``text`` placed at ``points[0]``).
    points : numpy.ndarray
        ``(n, 2)`` world coordinates; may be empty (the element is hidden).
    color : str
        Face colour of a fill, colour of a line or text.
    width : float
        Line width in points (edge width of a fill).
    z : float
        Drawing order (higher on top).
    bounds : bool
        Whether the element counts when the picture's extent is chosen.
    text : str
        The text of a ``"text"`` element.
    edge : str or None
        Edge colour of a fill (None: no edge).
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


def bar(p0: np.ndarray, p1: np.ndarray, width: float) -> np.ndarray:
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


def rotate(points: np.ndarray, angle: float, about: Sequence[float] = (0.0, 0.0)) -> np.ndarray:
    """Rotate *points* counter-clockwise by *angle* about *about*."""
    c, s = math.cos(angle), math.sin(angle)
    o = np.asarray(about, float)
    p = np.asarray(points, float) - o
    return np.column_stack([c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1]]) + o


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


# -- scenes --------------------------------------------------------------------


class Scene:
    """The drawing of one system.

    Parameters
    ----------
    system : equilibrist.numeric.system.System
        The bound system: its parameters give the drawing's dimensions and
        its input limits the scale of the input arrows.

    Notes
    -----
    Subclasses implement :meth:`shapes`. ``trail`` is the sequence of states
    up to the one drawn, for scenes that draw a trace (the gyroscope).
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
        """``(xmin, xmax, ymin, ymax)`` that shows every state of *states*.

        Parameters
        ----------
        states : numpy.ndarray
            ``(n_steps, n_states)``; up to 80 evenly spaced ones are drawn
            to find the extent.
        inputs : numpy.ndarray, optional
            ``(n_steps, n_inputs)`` matching *states* (the arrows count).
        """
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


class SeesawScene(Scene):
    """Beam on a central pivot, end masses, thrust arrow scaled to the force."""

    caption = "beam angle θ counter-clockwise from level; arrow: motor thrust F"

    def shapes(self, x, u, trail=None):
        p = self.params
        L = p["L"]
        th = self.q(x, "theta")
        e = np.array([math.cos(th), math.sin(th)])
        n = np.array([-math.sin(th), math.cos(th)])
        t = 0.025 * L  # beam thickness: 2.5 % of its length
        h = 0.16 * L  # pivot post height (not a parameter)
        out = [
            Shape("ground", "hline", _pts((0.0, -h)), COLORS["ground"], width=1.0, z=0.5),
            _fill("post", _pts((-0.05 * L, -h), (0.05 * L, -h), (0.0, 0.0)), COLORS["pivot"], z=1),
            _fill("beam", bar(-L / 2 * e, L / 2 * e, t), COLORS["body"], z=2),
        ]
        m_ref = max(p["m1"], p["m2"], 1e-12)
        for key, mass, side in (("m1", p["m1"], -1.0), ("m2", p["m2"], 1.0)):
            if mass <= 0:
                continue
            r = 0.045 * L * (mass / m_ref) ** (1 / 3)  # area grows with mass
            c = side * L / 2 * e * 0.94 + n * (t / 2 + r)
            out.append(_fill(key, circle(c, r), COLORS["mass"], z=3))
        # Propeller: a bar parallel to the beam above the motor at the right end.
        motor = L / 2 * e - n * t / 2
        prop = L / 2 * e + n * 0.09 * L
        out.append(_fill("motor", bar(motor, prop, 0.03 * L), COLORS["pivot"], z=3))
        out.append(_fill("prop", bar(prop - 0.09 * L * e, prop + 0.09 * L * e, 0.012 * L),
                         COLORS["wheel"], z=4))
        frac = self.input_fraction(u)
        # Full-scale thrust is an arrow 40 % of the beam long, perpendicular to it.
        out.append(_fill("thrust", arrow(prop + n * 0.02 * L, n * 0.4 * L * frac, 0.03 * L),
                         COLORS["input"], z=5))
        out.append(_fill("pivot", circle((0.0, 0.0), 0.018 * L), COLORS["pivot"], z=6))
        return out


class _CartMixin:
    """Cart on a track: dimensions in proportion to the pendulum's height."""

    def _cart(self, x_c: float, size: float, frac: float) -> tuple[list[Shape], np.ndarray]:
        w, h, r = 0.4 * size, 0.16 * size, 0.04 * size  # cart width, body height, wheel radius
        body = rect(x_c, r, w, h)
        pivot = np.array([x_c, r + h])
        shapes = [
            Shape("ground", "hline", _pts((0.0, 0.0)), COLORS["ground"], width=1.0, z=0.5),
            _line("ticks", _ticks(size), COLORS["ground"], width=1.0, z=0.6, bounds=False),
            _fill("cart", body, COLORS["body"], z=2),
            _fill("wheel_l", circle((x_c - w / 3, r), r, 24), COLORS["wheel"], z=3),
            _fill("wheel_r", circle((x_c + w / 3, r), r, 24), COLORS["wheel"], z=3),
        ]
        # Full-scale force: an arrow as long as the cart is wide, pushing its side.
        length = 1.0 * w * frac
        side = x_c - w / 2 if length >= 0 else x_c + w / 2
        shapes.append(_fill("force", arrow((side - length, r + h / 2), (length, 0.0), 0.06 * size),
                            COLORS["input"], z=5))
        return shapes, pivot

    def _swing(self, states: np.ndarray, size: float, links: float) -> tuple[float, float, float, float]:
        """The cart's travel, widened by *links* (the full length of the
        links on the cart's pivot) to each side and above the pivot."""
        column: int = self._index["x"]  # type: ignore[attr-defined]
        xs = states[:, column]
        w, h, r = 0.4 * size, 0.16 * size, 0.04 * size
        side = max(links + 0.05 * size, w / 2 + w)  # the force arrow: a cart's width beside it
        return (float(xs.min()) - side, float(xs.max()) + side, 0.0, r + h + links + 0.03 * size)


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
    for m in (5.0, 2.0, 1.0):
        if m * 10**e <= v:
            return m * 10**e
    return 10**e


class CartpoleScene(_CartMixin, Scene):
    """Cart on a track with a pole; the pole is a uniform rod of length 2 l."""

    caption = "cart position x to the right; pole angle θ clockwise from up; arrow: force F"

    def shapes(self, x, u, trail=None):
        l = self.params["l"]
        size = 2 * l
        out, pivot = self._cart(self.q(x, "x"), size, self.input_fraction(u))
        tip = pivot + size * lean(self.q(x, "theta"))
        out.append(_fill("pole", bar(pivot, tip, 0.05 * size), COLORS["link"], z=4))
        out.append(_fill("pivot", circle(pivot, 0.03 * size, 20), COLORS["pivot"], z=6))
        return out

    def reach(self, states):
        return self._swing(states, 2 * self.params["l"], 2 * self.params["l"])


class DoubleCartpoleScene(_CartMixin, Scene):
    """Cart with two links of full lengths l1, l2 at absolute angles."""

    caption = "cart position x; link angles θ1, θ2 clockwise from up; arrow: force F"

    def shapes(self, x, u, trail=None):
        l1, l2 = self.params["l1"], self.params["l2"]
        size = l1 + l2
        out, pivot = self._cart(self.q(x, "x"), size, self.input_fraction(u))
        elbow = pivot + l1 * lean(self.q(x, "theta1"))
        tip = elbow + l2 * lean(self.q(x, "theta2"))
        out.append(_fill("link1", bar(pivot, elbow, 0.04 * size), COLORS["link"], z=4))
        out.append(_fill("link2", bar(elbow, tip, 0.035 * size), COLORS["link2"], z=4.5))
        out.append(_fill("pivot", circle(pivot, 0.025 * size, 20), COLORS["pivot"], z=6))
        out.append(_fill("elbow", circle(elbow, 0.022 * size, 20), COLORS["pivot"], z=6))
        return out

    def reach(self, states):
        size = self.params["l1"] + self.params["l2"]
        return self._swing(states, size, size)  # both links stretched out: l1 + l2


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


class WheeledPendulumScene(Scene):
    """Body on one wheel rolling on the floor; the spoke shows the rolling."""

    caption = "wheel angle φ (red spoke) and body angle θ clockwise; arrow: motor torque τ"

    def shapes(self, x, u, trail=None):
        p = self.params
        R, L = p["R"], p["L"]
        phi, th = self.q(x, "phi"), self.q(x, "theta")
        c = np.array([R * phi, R])
        top = c + 2 * L * lean(th)  # body: uniform block with its centre of mass at L
        size = 2 * L + R
        out = [
            Shape("ground", "hline", _pts((0.0, 0.0)), COLORS["ground"], width=1.0, z=0.5),
            _line("ticks", _ticks(size), COLORS["ground"], width=1.0, z=0.6, bounds=False),
            _fill("body", bar(c, top, max(0.9 * R, 0.3 * L)), COLORS["body"], z=2),
            _fill("wheel", circle(c, R), COLORS["wheel"], z=3),
            *_spokes("wheel", c, R, phi),
            _torque("torque", c, 1.35 * R, self.input_fraction(u), 0.18 * R),
            _fill("axle", circle(c, 0.12 * R, 16), COLORS["pivot"], z=6),
        ]
        return out

    def reach(self, states):
        p = self.params
        R, L = p["R"], p["L"]
        xs = R * states[:, self._index["phi"]]
        arm = 2 * L + 0.5 * max(0.9 * R, 0.3 * L)  # the body's length and half its width
        side = max(arm, 1.35 * R + 0.18 * R)  # or the torque arrow around the wheel
        return (float(xs.min()) - side, float(xs.max()) + side, 0.0, R + arm)


class ReactionWheelScene(Scene):
    """Pendulum on a base pivot with its flywheel at the tip."""

    caption = "wheel angle φ (red spoke) and arm angle θ clockwise from up; arrow: torque τ"

    def shapes(self, x, u, trail=None):
        p = self.params
        Lw = p["L_w"]
        rw = disc_radius(p["I_w"], p["m_w"])
        phi, th = self.q(x, "phi"), self.q(x, "theta")
        c = Lw * lean(th)
        base_h = 0.15 * Lw  # base block (not a parameter)
        out = [
            Shape("ground", "hline", _pts((0.0, -base_h)), COLORS["ground"], width=1.0, z=0.5),
            _fill("base", _pts((-0.12 * Lw, -base_h), (0.12 * Lw, -base_h), (0.0, 0.0)),
                  COLORS["pivot"], z=1),
            _fill("arm", bar((0.0, 0.0), c, 0.1 * Lw), COLORS["body"], z=2),
            _fill("wheel", circle(c, rw), COLORS["wheel"], z=3, edge=COLORS["pivot"]),
            *_spokes("wheel", c, rw, phi),
            _torque("torque", c, 1.25 * rw, self.input_fraction(u), 0.12 * rw),
            _fill("pivot", circle((0.0, 0.0), 0.04 * Lw, 16), COLORS["pivot"], z=6),
            _fill("axle", circle(c, 0.1 * rw, 16), COLORS["pivot"], z=6),
        ]
        return out

    def reach(self, states):
        p = self.params
        arm = p["L_w"] + 1.4 * disc_radius(p["I_w"], p["m_w"])  # the wheel and its torque arrow
        return (-arm, arm, -0.15 * p["L_w"], arm)


class BallBeamScene(Scene):
    """Beam on a pivot with a rolling ball and its spin mark.

    The beam's length is the span of the system's region for ``R`` (the
    ball leaves the beam there); the servo model has no ball radius, so a
    nominal 12.5 mm ball is drawn (its radius cancels from that model).
    """

    caption = "beam angle θ counter-clockwise; ball position R along the beam; red: ball spin"
    nominal_radius = 0.0125

    def shapes(self, x, u, trail=None):
        p = self.params
        r = p.get("r", self.nominal_radius)
        d = p.get("d", 0.0)
        region = self.system.spec.region.get("R", (-0.25, 0.25))
        half = max(abs(region[0]), abs(region[1]))
        th, R = self.q(x, "theta"), self.q(x, "R")
        e = np.array([math.cos(th), math.sin(th)])
        n = np.array([-math.sin(th), math.cos(th)])
        centre = R * e + d * n
        surface = d - r  # the rolling surface, a radius below the ball's centre
        t = 0.04 * half  # beam thickness
        beam = np.array([-half * e + surface * n, half * e + surface * n,
                         half * e + (surface - t) * n, -half * e + (surface - t) * n])
        # Absolute spin angle: its rate is theta_dot - R_dot / r, so it is
        # theta - R / r up to a constant (the mark points up at R = 0, theta = 0).
        spin = math.pi / 2 + th - R / r
        mark = centre + 0.9 * r * np.array([math.cos(spin), math.sin(spin)])
        post = 0.3 * half
        low = surface - t
        out = [
            Shape("ground", "hline", _pts((0.0, -post)), COLORS["ground"], width=1.0, z=0.5),
            _fill("post", _pts((-0.08 * half, -post), (0.08 * half, -post), (0.0, 0.0)),
                  COLORS["pivot"], z=1),
            _fill("beam", beam, COLORS["body"], z=2),
            _fill("stop_l", bar(-half * e + low * n, -half * e + (surface + r) * n, 0.015 * half),
                  COLORS["pivot"], z=2.5),
            _fill("stop_r", bar(half * e + low * n, half * e + (surface + r) * n, 0.015 * half),
                  COLORS["pivot"], z=2.5),
            _fill("ball", circle(centre, r, 32), COLORS["ball"], z=3),
            _fill("spin", bar(centre, mark, 0.25 * r), COLORS["mark"], z=3.5),
            _torque("torque", np.zeros(2), 0.12 * half, -self.input_fraction(u), 0.02 * half),
            _fill("pivot", circle((0.0, 0.0), 0.02 * half, 16), COLORS["pivot"], z=6),
        ]
        return out


class _Projection:
    """Orthographic view of the room (z up) from azimuth *az*, elevation *el*."""

    def __init__(self, az: float = math.radians(-55.0), el: float = math.radians(22.0)) -> None:
        ca, sa, ce, se = math.cos(az), math.sin(az), math.cos(el), math.sin(el)
        self.right = np.array([-sa, ca, 0.0])
        self.up = np.array([-se * ca, -se * sa, ce])

    def __call__(self, p: np.ndarray) -> np.ndarray:
        p = np.atleast_2d(p)
        return np.column_stack([p @ self.right, p @ self.up])


def _rx(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _disc3d(centre: np.ndarray, e1: np.ndarray, e2: np.ndarray, radius: float, n: int = 40) -> np.ndarray:
    s = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    return centre + radius * (np.outer(np.cos(s), e1) + np.outer(np.sin(s), e2))


class GyroscopeScene(Scene):
    """The top's axis, wheel and spin mark in a 3D projection, with the
    trace of the axis' tip."""

    caption = "3D view: the axis, the trace of its tip (blue), the spin mark (red)"
    projected = True

    def orientation(self, x: np.ndarray) -> np.ndarray:
        """The wheel's rotation matrix in the room frame (z up)."""
        euler = self.system.spec.variant[1] if self.system.spec.variant else "zxz"  # type: ignore[attr-defined]
        if euler == "xyz":
            return _rx(self.q(x, "theta")) @ _ry(self.q(x, "phi")) @ _rz(self.q(x, "psi"))
        return _rz(self.q(x, "phi")) @ _rx(self.q(x, "theta")) @ _rz(self.q(x, "psi"))

    def shapes(self, x, u, trail=None):
        p = self.params
        R = p["R"]
        rw = disc_radius(p["I_s"], p["m"])
        proj = _Projection()
        rot = self.orientation(x)
        axis, e1, e2 = rot[:, 2], rot[:, 0], rot[:, 1]
        centre = R * axis
        tip_len = R + 0.6 * rw
        tip = tip_len * axis
        reach = tip_len + rw
        out = [
            # Room axes and a horizontal circle through the fixed point.
            _line("ring", proj(_disc3d(np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]),
                                       reach, 72))[[*list(range(72)), 0]], COLORS["ground"],
                  width=0.8, z=0.5),
            _line("stand", proj(np.array([[0, 0, -reach], [0, 0, 0]])), COLORS["pivot"],
                  width=3.0, z=1),
        ]
        for name, v in (("x", (1.0, 0, 0)), ("y", (0, 1.0, 0)), ("z", (0, 0, 1.0))):
            end = proj(np.array(v) * reach * 1.05)
            out.append(_line(f"axis_{name}", np.vstack([proj(np.zeros(3)), end]), COLORS["ground"],
                             width=0.8, z=0.6))
            out.append(_text(f"label_{name}", end[0] * 1.08, name))
        if trail is not None and len(trail) > 1:
            tr = np.asarray(trail)
            step = max(1, len(tr) // 1500)
            pts = np.array([tip_len * self.orientation(s)[:, 2] for s in tr[::step]] + [tip])
            out.append(_line("trace", proj(pts), COLORS["trace"], width=1.2, z=1.5))
        else:
            out.append(_line("trace", np.empty((0, 2)), COLORS["trace"], width=1.2, z=1.5))
        out += [
            _fill("shaft", bar(proj(-0.15 * R * axis)[0], proj(tip)[0], 0.08 * rw), COLORS["body"], z=2),
            _fill("wheel", proj(_disc3d(centre, e1, e2, rw)), COLORS["disc"], z=3,
                  edge=COLORS["wheel"], width=1.0),
            _fill("spin", bar(proj(centre)[0], proj(centre + 0.95 * rw * e1)[0], 0.12 * rw),
                  COLORS["mark"], z=3.5),
            _fill("tip", circle(proj(tip)[0], 0.08 * rw, 16), COLORS["mark"], z=4),
            _fill("pivot", circle(proj(np.zeros(3))[0], 0.07 * rw, 16), COLORS["pivot"], z=6),
        ]
        return out

    def extent(self, states, inputs=None):
        p = self.params
        reach = p["R"] + 1.6 * disc_radius(p["I_s"], p["m"])
        return (-1.25 * reach, 1.25 * reach, -1.1 * reach, 1.25 * reach)


class CmgRobotScene(Scene):
    """The robot seen from the front (x towards the viewer, y to the right,
    z up): its body rolls by ``theta`` about the contact line (positive turns
    counter-clockwise in this view, the right-hand rule about x); the two
    flywheels tilt in their gimbals by ``phi`` about the body's y axis,
    which from the front opens their discs into ellipses. A dial shows
    ``phi`` itself."""

    caption = "front view (x towards you): roll θ counter-clockwise; dial: gimbal angle φ"

    def shapes(self, x, u, trail=None):
        p = self.params
        th, phi = self.q(x, "theta"), self.q(x, "phi")
        rw = disc_radius(p["I_z"], p["m_wheel"])
        hw, hb = p["h_wheel"], p["h_body"]
        height = max(2 * hb, hw + 1.4 * rw)  # body block: uniform about its centre of mass
        gap = 1.25 * rw  # flywheels side by side, either side of the centre line
        width = 2 * (gap + 1.3 * rw)
        roll = _rx(th)

        def screen(p3: np.ndarray) -> np.ndarray:  # front view: (y, z)
            return np.atleast_2d(p3)[:, 1:3]

        def body_pt(y: float, z: float) -> np.ndarray:
            return screen(roll @ np.array([0.0, y, z]))[0]

        body = np.array([body_pt(-width / 2, 0), body_pt(width / 2, 0),
                         body_pt(width / 2, height), body_pt(-width / 2, height)])
        out = [
            Shape("ground", "hline", _pts((0.0, 0.0)), COLORS["ground"], width=1.0, z=0.5),
            _fill("body", body, COLORS["body"], z=1, edge=COLORS["pivot"]),
        ]
        gimbal = roll @ _ry(phi)
        e1, e2, spin_axis = gimbal[:, 0], gimbal[:, 1], gimbal[:, 2]
        for side, s in (("left", -1.0), ("right", 1.0)):
            c3 = roll @ np.array([0.0, s * gap, hw])
            ring = _disc3d(c3, e1, e2, rw)
            out.append(_fill(f"wheel_{side}", screen(ring), COLORS["disc"], z=3,
                             edge=COLORS["wheel"], width=1.0))
            out.append(_fill(f"axis_{side}", bar(screen(c3 - 0.7 * rw * spin_axis)[0],
                                                 screen(c3 + 0.7 * rw * spin_axis)[0], 0.08 * rw),
                             COLORS["mark"], z=3.5))
            # Gimbal pins on the body's y axis through the flywheel's centre.
            y_axis = roll[:, 1]
            out.append(_fill(f"pins_{side}", bar(screen(c3 - 1.15 * rw * y_axis)[0],
                                                 screen(c3 + 1.15 * rw * y_axis)[0], 0.1 * rw),
                             COLORS["pivot"], z=2.5))
        # Gimbal-angle dial above the robot: the needle turns by phi.
        dial_c = np.array([0.0, height + 2.2 * rw])
        dial_r = 0.9 * rw
        out.append(_line("dial", np.vstack([circle(dial_c, dial_r, 48), circle(dial_c, dial_r, 48)[:1]]),
                         COLORS["ground"], width=1.0, z=2))
        out.append(_fill("needle", bar(dial_c, dial_c + dial_r * lean(phi), 0.12 * rw),
                         COLORS["mark"], z=3))
        out.append(_text("dial_label", dial_c + np.array([3.0 * dial_r, 0.0]), "gimbal φ"))
        out.append(_torque("torque", dial_c, 1.25 * dial_r, self.input_fraction(u), 0.15 * rw))
        out.append(_fill("contact", circle((0.0, 0.0), 0.08 * rw, 16), COLORS["pivot"], z=6))
        return out


class FurutaScene(Scene):
    """The rotary pendulum in a 3D projection (z up): the motor on its
    stand, the arm turning about the vertical, the pendulum swinging in the
    plane across the arm's tip. The pendulum is drawn as the uniform rod of
    length ``2 l_p`` that the default inertia describes; the motor's body
    (not a parameter) is a cylinder of a third of the arm's length."""

    caption = "3D view: arm angle φ counter-clockwise from above; pendulum θ from up; arrow: torque τ"
    projected = True

    def shapes(self, x, u, trail=None):
        p = self.params
        La, lp = p["L_a"], p["l_p"]
        phi, th = self.q(x, "phi"), self.q(x, "theta")
        proj = _Projection()
        arm = np.array([math.cos(phi), math.sin(phi), 0.0])
        across = np.array([-math.sin(phi), math.cos(phi), 0.0])  # where the tip goes as phi grows
        up = np.array([0.0, 0.0, 1.0])
        joint = La * arm
        tip = joint + 2 * lp * (math.cos(th) * up + math.sin(th) * across)
        r_motor = La / 3
        h_motor = 0.9 * La
        ring = _disc3d(np.array([0.0, 0.0, -h_motor]), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]),
                       r_motor, 36)
        lid = _disc3d(np.zeros(3), np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), r_motor, 36)
        # The motor's outline: its bottom and top circles joined at the sides of the view.
        base, top = proj(ring), proj(lid)
        left, right = int(np.argmin(base[:, 0])), int(np.argmax(base[:, 0]))
        body = np.vstack([base[left], base[right], top[right], top[left]])
        frac = self.input_fraction(u)
        # The torque: an arc above the motor, counter-clockwise seen from above
        # when positive, three quarters of a turn at full scale.
        arc = arc_arrow(np.zeros(2), 0.55 * La, phi + math.pi, 1.5 * math.pi * frac, 0.06 * La)
        arc3 = np.column_stack([arc, np.full(len(arc), 0.12 * La)]) if len(arc) else np.empty((0, 3))
        out = [
            _fill("motor", body, COLORS["wheel"], z=1),
            _fill("motor_base", base, COLORS["wheel"], z=0.9),
            _fill("motor_top", top, COLORS["ground"], z=1.1, edge=COLORS["wheel"]),
            _fill("arm", bar(proj(np.zeros(3))[0], proj(joint)[0], 0.09 * La), COLORS["body"], z=2),
            _fill("pendulum", bar(proj(joint)[0], proj(tip)[0], 0.07 * La), COLORS["link"], z=3),
            _fill("torque", proj(arc3) if len(arc3) else np.empty((0, 2)), COLORS["input"], z=5),
            _fill("hub", circle(proj(np.zeros(3))[0], 0.08 * La, 16), COLORS["pivot"], z=6),
            _fill("joint", circle(proj(joint)[0], 0.06 * La, 16), COLORS["pivot"], z=6),
        ]
        return out

    def extent(self, states, inputs=None):
        p = self.params
        reach = p["L_a"] + 2 * p["l_p"]
        return (-1.15 * reach, 1.15 * reach, -1.15 * reach, 1.15 * reach)


class TwoLinkScene(Scene):
    """Two links hanging from a fixed shoulder (the acrobot and the
    pendubot): angles from hanging down, counter-clockwise, ``theta2``
    relative to link 1; the motor's torque is a curved arrow at the joint
    it drives (counter-clockwise when positive)."""

    caption = "θ1 from hanging down, counter-clockwise; θ2 relative to link 1; arrow: torque τ"
    #: The joint the motor drives.
    motor_at = "shoulder"

    def shapes(self, x, u, trail=None):
        p = self.params
        l1, l2 = p["l1"], p["l2"]
        size = l1 + l2
        a1 = self.q(x, "theta1")
        a2 = a1 + self.q(x, "theta2")
        shoulder = np.zeros(2)
        elbow = l1 * np.array([math.sin(a1), -math.cos(a1)])
        tip = elbow + l2 * np.array([math.sin(a2), -math.cos(a2)])
        at = elbow if self.motor_at == "elbow" else shoulder
        frac = self.input_fraction(u)
        out = [
            _fill("mount", _pts((-0.06 * size, 0.05 * size), (0.06 * size, 0.05 * size), (0.0, 0.0)),
                  COLORS["ground"], z=1),
            _fill("link1", bar(shoulder, elbow, 0.05 * size), COLORS["link"], z=3),
            _fill("link2", bar(elbow, tip, 0.045 * size), COLORS["link2"], z=3.5),
            _fill("torque", arc_arrow(at, 0.1 * size, a1 + math.pi / 2, 1.5 * math.pi * frac,
                                      0.02 * size), COLORS["input"], z=5),
            _fill("shoulder", circle(shoulder, 0.025 * size, 20), COLORS["pivot"], z=6),
            _fill("elbow", circle(elbow, 0.022 * size, 20), COLORS["pivot"], z=6),
        ]
        return out

    def reach(self, states):
        r = self.params["l1"] + self.params["l2"]
        return (-r, r, -r, r)  # the whole circle the links sweep


class AcrobotScene(TwoLinkScene):
    """The acrobot: the motor at the elbow."""

    motor_at = "elbow"


SCENES: dict[str, Callable[[object], Scene]] = {
    "seesaw": SeesawScene,
    "cartpole": CartpoleScene,
    "double_cartpole": DoubleCartpoleScene,
    "wheeled_pendulum": WheeledPendulumScene,
    "reaction_wheel_pendulum": ReactionWheelScene,
    "ball_beam": BallBeamScene,
    "ball_beam_servo": BallBeamScene,
    "gyroscope": GyroscopeScene,
    "cmg_robot": CmgRobotScene,
    "furuta": FurutaScene,
    "acrobot": AcrobotScene,
    "pendubot": TwoLinkScene,
}


def scene_for(system: object) -> Scene:
    """The scene that draws *system* (a bound ``System``).

    A catalogue system has its hand-drawn scene; any other system whose
    derivation records its points (every MJCF or URDF model) is drawn from
    its kinematic tree (:class:`~equilibrist.viz.generic.GenericScene`).

    Raises
    ------
    UnknownNameError
        When no drawing exists for the system (a system added to the
        catalogue without one).
    """
    name = system.name  # type: ignore[attr-defined]
    if name in SCENES:
        return SCENES[name](system)
    from equilibrist.viz.generic import GenericScene, can_draw

    if can_draw(system):
        return GenericScene(system)
    raise UnknownNameError(
        f"no drawing for system {name!r}: drawings exist for {', '.join(SCENES)} and for "
        "systems whose derivation records its points (model files do)"
    )
