"""The scenes drawn in a 3D projection: the gyroscope, the control-moment-gyroscope
robot and the Furuta pendulum (with the projection and the rotations they share)."""

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
    _text,
    _torque,
    arc_arrow,
    bar,
    circle,
    disc_radius,
    lean,
)


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
        rot: np.ndarray
        if euler == "xyz":
            rot = _rx(self.q(x, "theta")) @ _ry(self.q(x, "phi")) @ _rz(self.q(x, "psi"))
        else:
            rot = _rz(self.q(x, "phi")) @ _rx(self.q(x, "theta")) @ _rz(self.q(x, "psi"))
        return rot

    def shapes(self, x: np.ndarray, u: np.ndarray | None, trail: np.ndarray | None = None) -> list[Shape]:
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

    def extent(self, states: np.ndarray, inputs: np.ndarray | None = None) -> tuple[float, float, float, float]:
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

    def shapes(self, x: np.ndarray, u: np.ndarray | None, trail: np.ndarray | None = None) -> list[Shape]:
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
            point: np.ndarray = screen(roll @ np.array([0.0, y, z]))[0]
            return point

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

    def shapes(self, x: np.ndarray, u: np.ndarray | None, trail: np.ndarray | None = None) -> list[Shape]:
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

    def extent(self, states: np.ndarray, inputs: np.ndarray | None = None) -> tuple[float, float, float, float]:
        p = self.params
        reach = p["L_a"] + 2 * p["l_p"]
        return (-1.15 * reach, 1.15 * reach, -1.15 * reach, 1.15 * reach)
