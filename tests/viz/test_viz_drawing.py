"""Drawings of every system: they follow the state, to scale, as SYSTEMS.md signs it.

The pixel tests render a frame, find a part by its colour and check where
it is: the cart moves right when x grows, a pole at a positive angle leans
right (clockwise from up), and so on for every system.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from PIL import Image

from equilibrist.errors import UnknownNameError
from equilibrist.numeric.lookup import get_system
from equilibrist.systems import registry
from equilibrist.viz.drawing import COLORS, Scene
from equilibrist.viz.frames import FrameRenderer, draw_state
from equilibrist.viz.output import VizError
from equilibrist.viz.scenes import drawing_class, scene_for

ENTRIES = registry.all_entries()
IDS = [e.spec.key for e in ENTRIES]


def _system(entry):
    spec = entry.spec
    return get_system(spec.name, **({} if spec.variant is None else {spec.variant[0]: spec.variant[1]}))


def rest_state(system) -> np.ndarray:
    """The operating point, or a tilted axis for the zxz gyroscope (it has none)."""
    try:
        return np.array(system.operating_point().x, float)
    except Exception:
        x = np.zeros(system.n_states)
        x[system.state_index("theta")] = 0.5
        return x


def _mask(frame: np.ndarray, color: str, tol: int = 6) -> np.ndarray:
    rgb = np.array([int(color[i : i + 2], 16) for i in (1, 3, 5)])
    return np.all(np.abs(frame.astype(int) - rgb) <= tol, axis=2)


def _centroid(frame: np.ndarray, color: str) -> np.ndarray:
    """``(column, row)`` of the pixels of *color*; fails when there are none."""
    rows, cols = np.nonzero(_mask(frame, color))
    assert len(rows) > 0, f"no pixel of colour {color}"
    return np.array([cols.mean(), rows.mean()])


def _renderer(name: str, extent, **settings):
    return FrameRenderer(get_system(name, **settings), extent=extent, width=240, height=180)


def _state(system, **values) -> np.ndarray:
    x = rest_state(system)
    for k, v in values.items():
        x[system.state_index(k)] = v
    return x


@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_every_system_of_the_catalogue_names_its_drawing(entry):
    cls = drawing_class(entry.spec)
    assert isinstance(cls, type) and issubclass(cls, Scene)
    assert isinstance(scene_for(_system(entry)), cls)


def test_a_drawing_that_cannot_be_imported_is_one_line():
    import dataclasses

    from equilibrist.errors import DefinitionError

    spec = dataclasses.replace(ENTRIES[0].spec, drawing="equilibrist.viz.scenes:NoSuchScene")
    with pytest.raises(DefinitionError, match=r"NoSuchScene.*expected 'module:Class'"):
        drawing_class(spec)


@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_draw_state_writes_png_and_svg_of_the_stated_size(entry, tmp_path):
    system = _system(entry)
    x = rest_state(system)
    u = None if not system.n_inputs else np.asarray(system.input_limits[1]) * 0.5
    png = draw_state(system, x, tmp_path / "a.png", u=u, t=1.25, width=160, height=120)
    with Image.open(png) as im:
        assert im.format == "PNG"
        assert im.size == (160, 120)
    svg = draw_state(system, x, tmp_path / "a.svg", u=u, width=160, height=120)
    text = svg.read_text()
    assert text.lstrip().startswith("<?xml") and "<svg" in text


@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_each_coordinate_moves_the_drawing(entry):
    """Changing any coordinate changes the picture (nothing is left undrawn)."""
    system = _system(entry)
    x0 = rest_state(system)
    coords = [n for n in system.state_names if not n.endswith("_dot")]
    moved = []
    for name in coords:
        x1 = x0.copy()
        x1[system.state_index(name)] += 0.2 if name not in ("x", "R") else 0.05
        moved.append(x1)
    r = FrameRenderer(system, states=np.vstack([x0, *moved]), width=160, height=120)
    base = r.frame(x0)
    for name, x1 in zip(coords, moved, strict=True):
        assert np.any(r.frame(x1) != base), f"{name} does not move the drawing of {system.key}"


@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_rates_alone_do_not_move_the_drawing(entry):
    """A drawing is of the configuration: a rate changes nothing on it."""
    system = _system(entry)
    x0 = rest_state(system)
    r = FrameRenderer(system, states=x0[None], width=160, height=120)
    base = r.frame(x0)
    for name in system.state_names:
        if name.endswith("_dot"):
            x1 = x0.copy()
            x1[system.state_index(name)] = 3.0
            assert np.array_equal(r.frame(x1), base), name


def test_cart_moves_right_when_x_grows():
    r = _renderer("cartpole", (-1.5, 1.5, -0.2, 1.3))
    s = r.system
    cols = [_centroid(r.frame(_state(s, x=v)), COLORS["body"])[0] for v in (-0.5, 0.0, 0.5)]
    assert cols[0] < cols[1] < cols[2]
    # To scale: half a metre is as many pixels as the world-to-pixel map says.
    expected = np.diff(r.to_pixels(np.array([[0.0, 0.0], [0.5, 0.0]]))[:, 0])[0]
    assert cols[2] - cols[1] == pytest.approx(expected, rel=0.05)


@pytest.mark.parametrize("theta", [0.4, -0.4])
def test_pole_leans_the_way_theta_says_clockwise_positive(theta):
    r = _renderer("cartpole", (-1.5, 1.5, -0.2, 1.3))
    frame = r.frame(_state(r.system, theta=theta))
    pole = _centroid(frame, COLORS["link"])
    cart = _centroid(frame, COLORS["body"])
    assert pole[1] < cart[1]  # above the cart (rows grow downwards)
    assert np.sign(pole[0] - cart[0]) == np.sign(theta)
    # The pole's centre is l along the pole from the pivot: its offset
    # matches l sin(theta) (the rod is a uniform 2 l long).
    l = r.system.params["l"]
    offset = r.to_pixels(np.array([[0.0, 0.0], [l * math.sin(theta), 0.0]]))
    assert pole[0] - cart[0] == pytest.approx(offset[1, 0] - offset[0, 0], rel=0.1)


def test_double_cartpole_links_follow_their_absolute_angles():
    r = _renderer("double_cartpole", (-1.0, 1.0, -0.1, 0.8))
    frame = r.frame(_state(r.system, theta1=0.5, theta2=-0.5))
    link1, link2 = _centroid(frame, COLORS["link"]), _centroid(frame, COLORS["link2"])
    cart = _centroid(frame, COLORS["body"])
    assert link1[0] > cart[0]  # link 1 leans right
    # link 2 leans left of its own base (the elbow, right of the cart): its
    # centre is left of the elbow's column.
    elbow_col = r.to_pixels(np.array([[r.system.params["l1"] * math.sin(0.5), 0.0]]))[0, 0]
    assert link2[0] < elbow_col


def test_wheel_rolls_right_and_its_spoke_turns_clockwise():
    r = _renderer("wheeled_pendulum", (-0.3, 0.3, -0.02, 0.25))
    s = r.system
    R = s.params["R"]
    a = r.frame(_state(s, phi=0.0))
    b = r.frame(_state(s, phi=2.0))
    # The axle (the spokes turning over the wheel would bias the wheel's own centroid).
    wheel_a, wheel_b = _centroid(a, COLORS["pivot"]), _centroid(b, COLORS["pivot"])
    moved = r.to_pixels(np.array([[0.0, 0.0], [2.0 * R, 0.0]]))
    assert wheel_b[0] - wheel_a[0] == pytest.approx(moved[1, 0] - moved[0, 0], rel=0.1)
    # Clockwise by 1 rad from up: the spoke points up and to the right.
    c = r.frame(_state(s, phi=1.0, theta=0.0))
    centre = r.to_pixels(np.array([[R * 1.0, R]]))[0]
    spoke = _centroid(c, COLORS["mark"])
    assert spoke[0] > centre[0] and spoke[1] < centre[1]
    # The body leans the way theta says.
    d = r.frame(_state(s, theta=0.5))
    assert _centroid(d, COLORS["body"])[0] > r.to_pixels(np.array([[0.0, R]]))[0, 0]


def test_reaction_wheel_pendulum_leans_clockwise_positive():
    r = _renderer("reaction_wheel_pendulum", (-0.35, 0.35, -0.05, 0.3))
    pivot = r.to_pixels(np.zeros((1, 2)))[0]
    right = _centroid(r.frame(_state(r.system, theta=0.4)), COLORS["wheel"])
    left = _centroid(r.frame(_state(r.system, theta=-0.4)), COLORS["wheel"])
    assert right[0] > pivot[0] > left[0]


def test_seesaw_positive_angle_raises_the_right_end_and_thrust_scales():
    r = _renderer("seesaw", (-0.35, 0.35, -0.12, 0.3))
    frame = r.frame(_state(r.system, theta=0.3), np.array([0.0]))
    beam = _mask(frame, COLORS["body"])
    rows, cols = np.nonzero(beam)
    mid = cols.mean()
    assert rows[cols > mid].mean() < rows[cols < mid].mean()  # right end higher on screen
    small = _mask(r.frame(_state(r.system), np.array([1.0])), COLORS["input"]).sum()
    large = _mask(r.frame(_state(r.system), np.array([4.0])), COLORS["input"]).sum()
    assert 0 < small < large


def test_ball_sits_where_R_says_and_spins_as_it_rolls():
    r = _renderer("ball_beam", (-0.3, 0.3, -0.1, 0.1))
    s = r.system
    pivot = r.to_pixels(np.zeros((1, 2)))[0]
    right = _centroid(r.frame(_state(s, R=0.15)), COLORS["ball"])
    left = _centroid(r.frame(_state(s, R=-0.15)), COLORS["ball"])
    assert right[0] > pivot[0] > left[0]
    # Rolling right on a level beam turns the ball clockwise: the mark,
    # up at R = 0, points right after a quarter turn (R = r pi / 2).
    quarter = s.params["r"] * math.pi / 2
    frame = r.frame(_state(s, R=quarter))
    ball = r.to_pixels(np.array([[quarter, 0.0]]))[0]
    mark = _centroid(frame, COLORS["mark"])
    assert mark[0] > ball[0] + 1
    assert abs(mark[1] - ball[1]) < 2


def test_cmg_robot_rolls_counter_clockwise_seen_from_the_front():
    r = _renderer("cmg_robot", (-0.3, 0.3, -0.02, 0.35))
    contact = r.to_pixels(np.zeros((1, 2)))[0]
    body = _centroid(r.frame(_state(r.system, theta=0.3)), COLORS["body"])
    assert body[0] < contact[0]  # rolled about x (towards the viewer): the top goes left
    body = _centroid(r.frame(_state(r.system, theta=-0.3)), COLORS["body"])
    assert body[0] > contact[0]
    # The gimbal angle opens the flywheels' discs (edge-on at phi = 0).
    flat = _mask(r.frame(_state(r.system, phi=0.0)), COLORS["disc"]).sum()
    open_ = _mask(r.frame(_state(r.system, phi=0.8)), COLORS["disc"]).sum()
    assert open_ > flat + 20


def test_gyroscope_axis_tilts_towards_the_room_direction_its_angles_give():
    # zxz: the axis points along (sin phi sin theta, -cos phi sin theta, cos theta).
    # phi = 0 tilts it towards -y, phi = pi towards +y; in the view, +y is to the right.
    system = get_system("gyroscope")
    r = FrameRenderer(system, width=240, height=180)
    pivot = r.to_pixels(np.zeros((1, 2)))[0]
    minus_y = _centroid(r.frame(_state(system, theta=0.8, phi=0.0)), COLORS["disc"])
    plus_y = _centroid(r.frame(_state(system, theta=0.8, phi=math.pi)), COLORS["disc"])
    assert minus_y[0] < pivot[0] < plus_y[0]
    # The same axis from the xyz variant, at the equivalent angles, is drawn at the same place.
    xyz = get_system("gyroscope", euler="xyz")
    r2 = FrameRenderer(xyz, width=240, height=180)
    x = np.zeros(6)
    x[xyz.state_index("theta")] = 0.8  # Rx(0.8) ez = (0, -sin 0.8, cos 0.8)
    same = _centroid(r2.frame(x), COLORS["disc"])
    assert same == pytest.approx(minus_y, abs=1.5)


def test_input_gauge_grows_with_the_input_and_marks_saturation():
    r = _renderer("cartpole", (-1.5, 1.5, -0.2, 1.3))
    x = _state(r.system)
    small = _mask(r.frame(x, np.array([20.0])), "#9b30c8").sum()
    large = _mask(r.frame(x, np.array([150.0])), "#9b30c8").sum()
    assert 0 < small < large
    saturated = r.frame(x, np.array([200.0]), command=np.array([260.0]))
    assert _mask(saturated, "#d1263b").sum() > 0


def test_time_stamp_changes_the_frame_and_nothing_else_moves():
    r = _renderer("cartpole", (-1.5, 1.5, -0.2, 1.3))
    x = _state(r.system)
    a, b = r.frame(x, t=1.0), r.frame(x, t=2.0)
    rows = np.nonzero(np.any(a != b, axis=(1, 2)))[0]
    assert len(rows) > 0
    assert rows.max() < 0.12 * r.height  # only the top line (the time stamp) differs


def test_unknown_system_and_tiny_frames_are_refused():
    import dataclasses

    class Fake:  # a definition that names no drawing, and no model to draw from
        spec = dataclasses.replace(ENTRIES[0].spec, name="nope", drawing=None)
        name = "nope"

    with pytest.raises(UnknownNameError, match="no drawing for system 'nope'"):
        scene_for(Fake())
    with pytest.raises(VizError, match="too small"):
        FrameRenderer(get_system("cartpole"), width=20, height=10)
