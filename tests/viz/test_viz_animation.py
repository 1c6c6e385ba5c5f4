"""Animations of every system: valid GIFs of the stated size and frame count,
frames that differ where the system moves; MP4 only where ffmpeg exists."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from PIL import Image

from equilibrist.numeric.lookup import get_system
from equilibrist.systems import registry
from equilibrist.viz import animation, output
from equilibrist.viz.animation import animate, frame_times, render_frames
from equilibrist.viz.output import VizError

ENTRIES = registry.all_entries()
IDS = [e.spec.key for e in ENTRIES]


def _system(entry):
    spec = entry.spec
    return get_system(spec.name, **({} if spec.variant is None else {spec.variant[0]: spec.variant[1]}))


def moving_run(system, n: int = 41, duration: float = 2.0):
    """A made-up trajectory in which every coordinate moves (not a simulation)."""
    t = np.linspace(0.0, duration, n)
    try:
        x0 = np.array(system.operating_point().x, float)
    except Exception:  # the zxz gyroscope has no canonical point
        x0 = np.zeros(system.n_states)
        x0[system.state_index("theta")] = 0.6
    x = np.tile(x0, (n, 1))
    for name in system.state_names:
        if not name.endswith("_dot"):
            amp = 0.05 if name in ("x", "R") else 0.3
            x[:, system.state_index(name)] += amp * np.sin(2 * math.pi * t / duration)
    u = None
    if system.n_inputs:
        low, high = system.input_limits
        u = np.outer(np.sin(2 * math.pi * t / duration), high) * 0.8 + np.maximum(low, 0) * 0
    return t, x, u


@pytest.mark.parametrize("entry", ENTRIES, ids=IDS)
def test_gif_of_every_system_has_the_stated_size_and_frames(entry, tmp_path):
    system = _system(entry)
    t, x, u = moving_run(system)
    path = animate(system, t, x, tmp_path / "run.gif", inputs=u, fps=3, width=120, height=90)
    with Image.open(path) as im:
        assert im.format == "GIF"
        assert im.size == (120, 90)
        assert im.n_frames == len(frame_times(t, fps=3)) == 7
        frames = []
        for k in range(im.n_frames):
            im.seek(k)
            frames.append(np.asarray(im.convert("RGB")))
    # The system moves: frames differ below the title lines as well.
    body = [f[int(0.15 * 90):] for f in frames]
    assert not np.array_equal(body[0], body[1])
    assert not np.array_equal(body[1], body[2])


def test_frames_differ_only_in_the_time_stamp_when_nothing_moves():
    system = get_system("cartpole")
    t = np.linspace(0.0, 1.0, 11)
    x = np.zeros((11, 4))
    frames, times = render_frames(system, t, x, inputs=np.zeros((11, 1)), fps=5, width=160, height=120)
    assert len(frames) == 6 and times[-1] == pytest.approx(1.0)
    for a, b in itertools.pairwise(frames):
        rows = np.nonzero(np.any(a != b, axis=(1, 2)))[0]
        assert len(rows) and rows.max() < 0.12 * 120


def test_frame_times_are_real_time_and_capped():
    t = np.linspace(0.0, 10.0, 1001)
    assert len(frame_times(t, fps=20, max_frames=1000)) == 201
    capped = frame_times(t, fps=20, max_frames=50)
    assert len(capped) == 50 and capped[0] == 0.0 and capped[-1] == 10.0
    assert len(frame_times(np.array([0.0]))) == 1
    with pytest.raises(VizError):
        frame_times(t, fps=0)


def test_frames_show_the_latest_sample_at_or_before_their_time():
    t = np.array([0.0, 0.3, 0.6, 1.0])
    assert animation._sample_index(t, np.array([0.0, 0.29, 0.3, 0.99, 1.0])).tolist() == [0, 0, 1, 2, 3]


def test_gif_frame_delay_is_real_time(tmp_path):
    system = get_system("cartpole")
    t = np.linspace(0.0, 2.0, 201)
    path = animate(system, t, np.zeros((201, 4)), tmp_path / "a.gif", fps=10, width=96, height=72)
    with Image.open(path) as im:
        assert im.n_frames == 21
        assert im.info["duration"] == 100


def test_mp4_without_ffmpeg_says_so_before_rendering(tmp_path, monkeypatch):
    monkeypatch.setattr(output.shutil, "which", lambda name: None)
    monkeypatch.setattr(output, "bundled_ffmpeg", lambda: None)
    system = get_system("cartpole")
    t = np.linspace(0.0, 1.0, 11)
    with pytest.raises(VizError, match="MP4 needs ffmpeg, which is not installed"):
        animate(system, t, np.zeros((11, 4)), tmp_path / "a.mp4")
    assert not (tmp_path / "a.mp4").exists()


def test_mp4_where_ffmpeg_exists(tmp_path):
    # The dev install brings ffmpeg through imageio-ffmpeg, so this always runs.
    assert output.ffmpeg_path() is not None
    system = get_system("cartpole")
    t = np.linspace(0.0, 1.0, 11)
    path = animate(system, t, np.zeros((11, 4)), tmp_path / "a.mp4", fps=5, width=97, height=73)
    assert path.stat().st_size > 0
    assert path.read_bytes()[4:8] == b"ftyp"


def test_bad_requests_are_refused_with_a_reason(tmp_path):
    system = get_system("cartpole")
    t = np.linspace(0.0, 1.0, 11)
    with pytest.raises(VizError, match=r"unsupported format '\.avi'"):
        animate(system, t, np.zeros((11, 4)), tmp_path / "a.avi")
    with pytest.raises(VizError, match=r"expected \(11, 4\)"):
        animate(system, t, np.zeros((4, 11)), tmp_path / "a.gif")
    with pytest.raises(VizError, match="inputs of cartpole"):
        animate(system, t, np.zeros((11, 4)), tmp_path / "a.gif", inputs=np.zeros((11, 2)))


def test_slow_motion_has_more_frames_and_says_so(tmp_path):
    system = get_system("gyroscope", euler="xyz")
    t = np.linspace(0.0, 1.0, 101)
    x = np.zeros((101, 6))
    x[:, 0] = 0.3 * t
    path = animate(system, t, x, tmp_path / "slow.gif", fps=10, speed=0.5, width=96, height=72)
    with Image.open(path) as im:
        assert im.n_frames == 21  # 2 s of playback at 10 frames per second
        assert im.info["duration"] == 100
    with pytest.raises(VizError, match="speed"):
        animate(system, t, x, tmp_path / "bad.gif", speed=0)
