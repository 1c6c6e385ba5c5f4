"""The scenes of the planar systems: the seesaw, the carts with their poles, the
wheeled and reaction-wheel pendulums, the balls on beams, the acrobot and the
pendubot."""

from __future__ import annotations

import math

import numpy as np

from equilibrist.viz.drawing import (
    COLORS,
    Scene,
    Shape,
    _fill,
    _line,
    _pts,
    _spokes,
    _ticks,
    _torque,
    arc_arrow,
    arrow,
    bar,
    circle,
    disc_radius,
    lean,
    rect,
)


class SeesawScene(Scene):
    """Beam on a central pivot, end masses, thrust arrow scaled to the force."""

    caption = "beam angle θ counter-clockwise from level; arrow: motor thrust F"

    def shapes(self, x: np.ndarray, u: np.ndarray | None, trail: np.ndarray | None = None) -> list[Shape]:
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


class CartpoleScene(_CartMixin, Scene):
    """Cart on a track with a pole; the pole is a uniform rod of length 2 l."""

    caption = "cart position x to the right; pole angle θ clockwise from up; arrow: force F"

    def shapes(self, x: np.ndarray, u: np.ndarray | None, trail: np.ndarray | None = None) -> list[Shape]:
        l = self.params["l"]
        size = 2 * l
        out, pivot = self._cart(self.q(x, "x"), size, self.input_fraction(u))
        tip = pivot + size * lean(self.q(x, "theta"))
        out.append(_fill("pole", bar(pivot, tip, 0.05 * size), COLORS["link"], z=4))
        out.append(_fill("pivot", circle(pivot, 0.03 * size, 20), COLORS["pivot"], z=6))
        return out

    def reach(self, states: np.ndarray) -> tuple[float, float, float, float]:
        return self._swing(states, 2 * self.params["l"], 2 * self.params["l"])


class DoubleCartpoleScene(_CartMixin, Scene):
    """Cart with two links of full lengths l1, l2 at absolute angles."""

    caption = "cart position x; link angles θ1, θ2 clockwise from up; arrow: force F"

    def shapes(self, x: np.ndarray, u: np.ndarray | None, trail: np.ndarray | None = None) -> list[Shape]:
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

    def reach(self, states: np.ndarray) -> tuple[float, float, float, float]:
        size = self.params["l1"] + self.params["l2"]
        return self._swing(states, size, size)  # both links stretched out: l1 + l2


class WheeledPendulumScene(Scene):
    """Body on one wheel rolling on the floor; the spoke shows the rolling."""

    caption = "wheel angle φ (red spoke) and body angle θ clockwise; arrow: motor torque τ"

    def shapes(self, x: np.ndarray, u: np.ndarray | None, trail: np.ndarray | None = None) -> list[Shape]:
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

    def reach(self, states: np.ndarray) -> tuple[float, float, float, float]:
        p = self.params
        R, L = p["R"], p["L"]
        xs = R * states[:, self._index["phi"]]
        arm = 2 * L + 0.5 * max(0.9 * R, 0.3 * L)  # the body's length and half its width
        side = max(arm, 1.35 * R + 0.18 * R)  # or the torque arrow around the wheel
        return (float(xs.min()) - side, float(xs.max()) + side, 0.0, R + arm)


class ReactionWheelScene(Scene):
    """Pendulum on a base pivot with its flywheel at the tip."""

    caption = "wheel angle φ (red spoke) and arm angle θ clockwise from up; arrow: torque τ"

    def shapes(self, x: np.ndarray, u: np.ndarray | None, trail: np.ndarray | None = None) -> list[Shape]:
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

    def reach(self, states: np.ndarray) -> tuple[float, float, float, float]:
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

    def shapes(self, x: np.ndarray, u: np.ndarray | None, trail: np.ndarray | None = None) -> list[Shape]:
        p = self.params
        r = p.get("r", self.nominal_radius)
        d = p.get("d", 0.0)
        # The bound System, typed object in Scene (as the other scenes read its spec).
        region = self.system.spec.region.get("R", (-0.25, 0.25))  # type: ignore[attr-defined]
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


class TwoLinkScene(Scene):
    """Two links hanging from a fixed shoulder (the acrobot and the
    pendubot): angles from hanging down, counter-clockwise, ``theta2``
    relative to link 1; the motor's torque is a curved arrow at the joint
    it drives (counter-clockwise when positive)."""

    caption = "θ1 from hanging down, counter-clockwise; θ2 relative to link 1; arrow: torque τ"
    #: The joint the motor drives.
    motor_at = "shoulder"

    def shapes(self, x: np.ndarray, u: np.ndarray | None, trail: np.ndarray | None = None) -> list[Shape]:
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

    def reach(self, states: np.ndarray) -> tuple[float, float, float, float]:
        r = self.params["l1"] + self.params["l2"]
        return (-r, r, -r, r)  # the whole circle the links sweep


class AcrobotScene(TwoLinkScene):
    """The acrobot: the motor at the elbow."""

    motor_at = "elbow"
