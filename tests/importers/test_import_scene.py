"""The generic drawing of a model file: its points are MuJoCo's, its view the plane of motion."""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest

from equilibrist.numeric.lookup import get_system
from equilibrist.viz.frames import FrameRenderer, draw_state
from equilibrist.viz.generic import GenericScene
from equilibrist.viz.scenes import scene_for

ROOT = Path(__file__).resolve().parents[2]
FILES = [ROOT / "examples" / "furuta.xml", ROOT / "examples" / "pendubot.urdf",
         ROOT / "tests" / "models" / "cartpole.xml", ROOT / "tests" / "models" / "arm.urdf"]


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_recorded_points_are_mujocos_centres_of_mass_and_anchors(path: Path) -> None:
    system = get_system(str(path))
    scene = scene_for(system)
    assert isinstance(scene, GenericScene)
    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    names = [model.jnt(j).name for j in range(model.njnt)]
    rng = np.random.default_rng(2)
    for _ in range(5):
        n = len(system.spec.coordinates)
        x = np.concatenate([rng.uniform(-1.5, 1.5, n), np.zeros(n)])
        for k, c in enumerate(system.spec.coordinates):
            data.qpos[model.jnt_qposadr[names.index(c)]] = x[k]
        mujoco.mj_kinematics(model, data)
        points = scene.positions(x)
        for k, name in enumerate(scene.point_names):
            if name.endswith("_com"):
                body = model.body(name[: -len("_com")]).id
                assert np.allclose(points[k], data.xipos[body], atol=1e-12)
            elif name in names:
                assert np.allclose(points[k], data.xanchor[names.index(name)], atol=1e-12)


def test_view_is_the_plane_of_motion() -> None:
    # The pendubot swings in xz; the cart-pole too.
    for path in (ROOT / "examples" / "pendubot.urdf", ROOT / "tests" / "models" / "cartpole.xml"):
        assert scene_for(get_system(str(path))).plane == "xz"  # type: ignore[attr-defined]


def test_frames_and_pictures_of_a_model(tmp_path: Path) -> None:
    system = get_system(str(ROOT / "examples" / "furuta.xml"))
    states = np.array([[0.0, 0.0, 0, 0], [0.4, 0.3, 0, 0], [-0.4, -0.2, 0, 0]])
    renderer = FrameRenderer(system, states=states, width=320, height=240)
    frames = [renderer.frame(x, np.array([0.02])) for x in states]
    assert frames[0].shape == (240, 320, 3)
    assert not np.array_equal(frames[0], frames[1])  # the links move
    out = draw_state(system, states[1], tmp_path / "furuta.png", u=np.array([0.02]))
    assert out.stat().st_size > 1000
