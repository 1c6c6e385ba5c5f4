"""The drawings of the rotary pendulum, the acrobot and the pendubot follow
SYSTEMS.md's signs: found by colour in rendered frames, each part sits
where the state puts it."""

from __future__ import annotations

import math

import numpy as np

from equilibrist.numeric.lookup import get_system
from equilibrist.viz.drawing import COLORS
from equilibrist.viz.frames import FrameRenderer
from equilibrist.viz.scenes import scene_for


def _mask(frame: np.ndarray, color: str, tol: int = 6) -> np.ndarray:
    rgb = np.array([int(color[i : i + 2], 16) for i in (1, 3, 5)])
    return np.all(np.abs(frame.astype(int) - rgb) <= tol, axis=2)


def _centroid(frame: np.ndarray, color: str) -> np.ndarray:
    rows, cols = np.nonzero(_mask(frame, color))
    assert len(rows) > 0, f"no pixel of colour {color}"
    return np.array([cols.mean(), rows.mean()])


def _renderer(name: str, **settings) -> FrameRenderer:
    """A square view of the whole circle the two links sweep."""
    system = get_system(name, **settings)
    r = system.params["l1"] + system.params["l2"]
    return FrameRenderer(system, extent=(-r, r, -r, r), width=240, height=240)


def test_two_links_hang_down_at_zero_and_turn_counter_clockwise():
    for name in ("acrobot", "pendubot"):
        r = _renderer(name)
        shoulder = r.to_pixels(np.zeros((1, 2)))[0]
        hanging = r.frame(np.zeros(4))
        assert _centroid(hanging, COLORS["link"])[1] > shoulder[1]  # below (rows grow down)
        # theta1 = pi/2, counter-clockwise from down: link 1 points to the right.
        right = r.frame(np.array([math.pi / 2, 0.0, 0.0, 0.0]))
        link1 = _centroid(right, COLORS["link"])
        assert link1[0] > shoulder[0] and abs(link1[1] - shoulder[1]) < 3
        # theta2 = pi/2 more, relative to link 1: link 2 points up from the elbow.
        bent = r.frame(np.array([math.pi / 2, math.pi / 2, 0.0, 0.0]))
        elbow = r.to_pixels(np.array([[r.system.params["l1"], 0.0]]))[0]
        link2 = _centroid(bent, COLORS["link2"])
        assert link2[1] < elbow[1] and abs(link2[0] - elbow[0]) < 3


def test_torque_arrow_sits_at_the_driven_joint():
    x = np.array([math.pi / 2, 0.0, 0.0, 0.0])  # elbow to the right of the shoulder
    for name, joint in (("acrobot", "elbow"), ("pendubot", "shoulder")):
        r = _renderer(name)
        limit = float(r.system.input_limits[1][0])
        # The input gauge below the picture shares the arrow's colour; only
        # pixels near one of the joints count.
        frame = r.frame(x, np.array([0.8 * limit]))
        mask = _mask(frame, COLORS["input"])
        shoulder = r.to_pixels(np.zeros((1, 2)))[0]
        elbow = r.to_pixels(np.array([[r.system.params["l1"], 0.0]]))[0]
        at = elbow if joint == "elbow" else shoulder
        other = shoulder if joint == "elbow" else elbow
        rows, cols = np.nonzero(mask)
        near = np.hypot(cols - at[0], rows - at[1]) < 0.3 * abs(elbow[0] - shoulder[0])
        far = np.hypot(cols - other[0], rows - other[1]) < 0.3 * abs(elbow[0] - shoulder[0])
        assert near.sum() > 10 and far.sum() == 0, name


def test_furuta_arm_turns_with_phi_and_pendulum_leans_with_theta():
    system = get_system("furuta")
    scene = scene_for(system)

    # In the projection, the arm at phi and at phi + pi point opposite ways.
    def arm_tip(phi: float) -> np.ndarray:
        shapes = {s.key: s for s in scene.shapes(np.array([phi, 0.0, 0.0, 0.0]), None)}
        return shapes["arm"].points.mean(axis=0)

    hub = {s.key: s for s in scene.shapes(np.zeros(4), None)}["hub"].points.mean(axis=0)
    a, b = arm_tip(0.3) - hub, arm_tip(0.3 + math.pi) - hub
    assert a @ b < 0

    # theta > 0 leans the pendulum's tip the way the joint moves as phi
    # grows: the tip at theta = 0.5 is displaced like the joint at phi + d.
    def tip(phi: float, theta: float) -> np.ndarray:
        shapes = {s.key: s for s in scene.shapes(np.array([phi, theta, 0.0, 0.0]), None)}
        return shapes["pendulum"].points.mean(axis=0)

    def joint(phi: float) -> np.ndarray:
        return {s.key: s for s in scene.shapes(np.array([phi, 0.0, 0.0, 0.0]), None)}[
            "joint"].points.mean(axis=0)

    lean = tip(0.0, 0.5) - tip(0.0, 0.0)
    ahead = joint(0.01) - joint(0.0)
    assert lean @ ahead > 0.5 * np.linalg.norm(lean) * np.linalg.norm(ahead)
