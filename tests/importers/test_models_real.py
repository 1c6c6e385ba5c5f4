"""Model files as people bring them: Gymnasium's, dm_control's and pybullet's habits.

Each defect met with a real file has a small model of its own here
(tests/models/) so that the suite depends on nothing but MuJoCo and
Gymnasium. The truths are MuJoCo's own: ``mj_forward`` on the same file
says whether a point is an equilibrium and what a control does.
"""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import mujoco
import numpy as np
import pytest

from equilibrist.cli.main import main
from equilibrist.numeric.lookup import get_system

ROOT = Path(__file__).resolve().parents[2]
MODELS = ROOT / "tests" / "models"
LEANING = MODELS / "leaning_cartpole.xml"
ACROBOT = MODELS / "acrobot_named.xml"


def _gymnasium_asset(name: str) -> Path:
    gymnasium = pytest.importorskip("gymnasium")
    path = Path(gymnasium.__file__).parent / "envs" / "mujoco" / "assets" / name
    if not path.exists():
        pytest.skip(f"this Gymnasium does not ship {name}")
    return path


def _mujoco_qacc(path: Path, system, x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """MuJoCo's qacc at the state *x* with the physical inputs *u* (ctrl = u / gear)."""
    model = mujoco.MjModel.from_xml_path(str(path))
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    data = mujoco.MjData(model)
    names = [model.jnt(j).name for j in range(model.njnt)]
    joints = [names.index(c) for c in system.spec.coordinates]
    n = len(joints)
    data.qpos[[int(model.jnt_qposadr[j]) for j in joints]] = x[:n]
    data.qvel[[int(model.jnt_dofadr[j]) for j in joints]] = x[n:]
    gains = model.actuator_gear[:, 0] * model.actuator_gainprm[:, 0]
    data.ctrl[:] = u / gains
    mujoco.mj_forward(model, data)
    return np.array(data.qacc)


# -- 1. the nearest equilibrium ------------------------------------------------------------

def test_operating_point_is_the_equilibrium_nearest_the_keyframe() -> None:
    system = get_system(str(LEANING))
    eq = system.operating_point()
    # The keyframe says 3.14159, the pole leans 1 mm in 0.6 m and gravity 1e-5 m/s^2
    # sideways: the centre of mass stands straight against gravity, and the point
    # moved that far from the keyframe, no further.
    moved = eq.state("hinge") - 3.14159
    expected = np.arctan2(0.001, 0.6) + (np.pi - 3.14159) - np.arctan2(1e-5, 9.81)
    assert moved == pytest.approx(expected, abs=1e-9)
    assert eq.state("slider") == 0.0
    # MuJoCo agrees it is an equilibrium, with the holding force against the
    # 1e-5 sideways gravity.
    qacc = _mujoco_qacc(LEANING, system, eq.x, eq.u)
    assert np.abs(qacc).max() < 1e-9
    assert eq.input("slide") != 0.0
    assert any("moved to the nearest equilibrium (hinge +0.00167 rad)" in n for n in system.spec.notes)


def test_linearize_says_how_far_the_point_moved(capsys) -> None:
    assert main(["linearize", str(LEANING)]) == 0
    out = capsys.readouterr().out
    assert "(an equilibrium)" in out
    assert "the keyframe 'up' moved to the nearest equilibrium" in out


def test_no_equilibrium_names_the_point_not_a_canonical_one(capsys, tmp_path: Path) -> None:
    # A keyframe with the pole 1 rad from upright: no equilibrium within reach, and the
    # cart alone can not hold it; the message names the keyframe's point.
    far = tmp_path / "far.xml"
    far.write_text(LEANING.read_text().replace('qpos="0 3.14159"', 'qpos="0 1"'))
    assert main(["linearize", str(far)]) == 2
    err = capsys.readouterr().err
    assert "at its operating point (hinge = 1)" in err, err
    assert "canonical" not in err and len(err.strip().splitlines()) == 1
    assert main(["linearize", str(LEANING), "--at", "hinge=2.5"]) == 2
    err = capsys.readouterr().err
    assert "hinge = 2.5" in err and "canonical" not in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("name", ["inverted_pendulum.xml", "inverted_double_pendulum.xml"])
def test_gymnasium_models_balance_where_mujoco_says(name: str) -> None:
    path = _gymnasium_asset(name)
    system = get_system(str(path))
    eq = system.operating_point()
    assert np.abs(_mujoco_qacc(path, system, eq.x, eq.u)).max() < 1e-9
    assert np.abs(eq.x).max() < 0.01  # near the file's pose
    assert system.linearize().residual < 1e-9


# -- 2. inputs in physical units ---------------------------------------------------------

def test_input_is_the_force_gear_times_ctrl(capsys) -> None:
    system = get_system(str(LEANING))
    assert system.input_units == ("N",)
    low, high = system.input_limits
    assert (low[0], high[0]) == (-300.0, 300.0)  # gear 100 times ctrlrange +-3
    rng = np.random.default_rng(2)
    for _ in range(5):
        x = np.concatenate([rng.uniform(-1, 1, 2), rng.uniform(-2, 2, 2)])
        u = rng.uniform(-300, 300, 1)
        assert np.allclose(system.f(x, u)[2:], _mujoco_qacc(LEANING, system, x, u), rtol=0, atol=1e-9)
    assert main(["show", str(LEANING)]) == 0
    out = capsys.readouterr().out
    assert "inputs: slide [N]" in out
    assert "100 * its ctrl (limits [-300, 300] N, ctrlrange [-3, 3])" in out


# -- 3. an actuator named like its joint ---------------------------------------------------

def test_actuator_named_like_its_joint_is_accepted() -> None:
    system = get_system(str(ACROBOT))
    assert system.input_names == ("elbow_torque",)
    assert system.input_units == ("N*m",)
    assert tuple(v[0] for v in system.input_limits) == (-2.0, 2.0)
    rng = np.random.default_rng(3)
    for _ in range(5):
        x = np.concatenate([rng.uniform(-1, 1, 2), rng.uniform(-2, 2, 2)])
        u = rng.uniform(-2, 2, 1)
        assert np.allclose(system.f(x, u)[2:], _mujoco_qacc(ACROBOT, system, x, u), rtol=0, atol=1e-9)


# -- 4. a parameter file read through another path ------------------------------------------

def test_parameter_file_of_the_same_model_through_a_relative_path(tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    from equilibrist.ident.params import read_params

    model = tmp_path / "cartpole.xml"
    model.write_bytes((MODELS / "cartpole.xml").read_bytes())
    params = tmp_path / "params.json"
    params.write_text(json.dumps({"format": "equilibrist-params-1", "system": str(model.resolve()),
                                  "params": {"pole_mass": 1.5}}))
    monkeypatch.chdir(tmp_path)
    assert read_params("params.json", system="cartpole.xml") == {"pole_mass": 1.5}
    assert read_params("params.json", system="./cartpole.xml") == {"pole_mass": 1.5}
    other = tmp_path / "other.xml"
    other.write_bytes(LEANING.read_bytes())
    from equilibrist.ident.log import IdentificationError

    with pytest.raises(IdentificationError, match="holds parameters of"):
        read_params("params.json", system="other.xml")


# -- 7. the drawing's plane ---------------------------------------------------------------------

def test_a_rig_drawn_with_y_up_is_drawn_in_its_plane() -> None:
    from equilibrist.viz.generic import GenericScene

    scene = GenericScene(get_system(str(ROOT / "examples" / "my_cartpole.py")))
    assert scene.plane == "xy"
    assert GenericScene(get_system(str(MODELS / "cartpole.xml"))).plane == "xz"


# -- 8. legibility --------------------------------------------------------------------------------

def test_long_names_stay_apart_and_print_as_written(capsys, tmp_path: Path) -> None:
    model = tmp_path / "long.urdf"
    model.write_text("""<?xml version="1.0"?>
<robot name="long">
  <link name="base"/>
  <link name="cart"><inertial><mass value="1"/>
    <inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="pole"><inertial><origin xyz="0 0 0.5"/><mass value="0.1"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="slider_to_cart" type="prismatic"><parent link="base"/><child link="cart"/>
    <axis xyz="1 0 0"/><limit effort="100" lower="-1" upper="1" velocity="5"/></joint>
  <joint name="cart_to_pole" type="continuous"><parent link="cart"/><child link="pole"/>
    <axis xyz="0 1 0"/></joint>
</robot>
""")
    assert main(["show", str(model)]) == 0
    out = capsys.readouterr().out
    # A URDF without transmissions: the joint with an effort limit has the motor.
    assert "inputs: slider_to_cart_force [N]" in out
    # Each column header stands apart from the next.
    assert "slider_to_cart  " in out and "slider_to_cartcart_to_pole" not in out
    # Names print as written, not as nested subscripts.
    assert "cart_to_pole" in out.split("A =")[0] and "pole_mass" in out


def test_every_problem_is_listed(tmp_path: Path, capsys) -> None:
    model = tmp_path / "many.xml"
    model.write_text("""<mujoco model="many">
  <worldbody>
    <body name="a"><joint name="ja" axis="0 1 0"/>
      <inertial pos="0 0 0.5" mass="1" diaginertia="0.1 0.1 0.01"/>
      <body name="b" pos="0 0 1"><joint name="jb" type="ball"/>
        <inertial pos="0 0 0.5" mass="1" diaginertia="0.1 0.1 0.01"/></body></body>
  </worldbody>
  <tendon><fixed name="t"><joint joint="ja" coef="1"/></fixed></tendon>
  <equality><joint name="e" joint1="ja"/></equality>
</mujoco>""")
    assert main(["show", str(model)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert "tendon 't'" in err and "equality constraint 'e'" in err and "ball joint 'jb'" in err
    assert "more problem" not in err


# -- hostile files ----------------------------------------------------------------------------------

_PENDULUM = """<mujoco model="hostile">
  {option}
  <worldbody>
    <body name="link">
      <joint name="a" axis="{axis}" damping="{damping}"/>
      <inertial pos="0 0 0.5" mass="{mass}" diaginertia="{inertia}"/>
    </body>
  </worldbody>
  <actuator><motor name="m" joint="a" ctrlrange="{ctrl}"/></actuator>
  <keyframe><key name="k" qpos="{key}"/></keyframe>
</mujoco>
"""
_GOOD = {"option": "", "axis": "0 1 0", "damping": "0.1", "mass": "1", "inertia": "0.1 0.1 0.01",
         "ctrl": "-1 1", "key": "0"}
HOSTILE = {
    "nan_axis": ({"axis": "0 nan 0"}, "axis='0 nan 0' is not a finite number"),
    "nan_mass": ({"mass": "nan"}, "mass='nan' is not a finite number"),
    "nan_inertia": ({"inertia": "0.1 NaN 0.01"}, "diaginertia='0.1 NaN 0.01' is not a finite number"),
    "nan_ctrlrange": ({"ctrl": "-1 nan"}, "ctrlrange='-1 nan' is not a finite number"),
    "nan_keyframe": ({"key": "nan"}, "qpos='nan' is not a finite number"),
    "inf_mass": ({"mass": "inf"}, "mass='inf' is not a finite number"),
    "nan_gravity": ({"option": '<option gravity="0 0 nan"/>'}, "gravity='0 0 nan' is not a finite number"),
    "negative_damping": ({"damping": "-0.5"}, "joint 'a' has damping -0.5: expected >= 0"),
}


@pytest.mark.parametrize("case", list(HOSTILE), ids=list(HOSTILE))
@pytest.mark.parametrize("command", ["show", "linearize"])
def test_hostile_values_are_one_line(case: str, command: str, tmp_path: Path, capsys,
                                     monkeypatch: pytest.MonkeyPatch) -> None:
    values, expected = HOSTILE[case]
    model = tmp_path / "hostile.xml"
    model.write_text(_PENDULUM.format(**{**_GOOD, **values}))
    monkeypatch.chdir(tmp_path)
    assert main([command, str(model)]) == 2
    captured = capsys.readouterr()
    assert expected in captured.err, captured.err
    assert len(captured.err.strip().splitlines()) == 1
    assert "Traceback" not in captured.err and captured.out == ""
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_hostile_values_refused_by_the_environment_too(tmp_path: Path) -> None:
    from equilibrist.errors import DefinitionError

    model = tmp_path / "hostile.xml"
    model.write_text(_PENDULUM.format(**{**_GOOD, "axis": "0 nan 0"}))
    with pytest.raises(DefinitionError, match="not a finite number"):
        get_system(str(model))


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_an_include_that_is_a_fifo_is_refused(tmp_path: Path, capsys) -> None:
    fifo = tmp_path / "part.xml"
    os.mkfifo(fifo)
    assert stat.S_ISFIFO(fifo.stat().st_mode)
    model = tmp_path / "main.xml"
    model.write_text('<mujoco model="m"><include file="part.xml"/></mujoco>')
    assert main(["show", str(model)]) == 2
    err = capsys.readouterr().err
    assert "<include file='part.xml'> is not a regular file" in err


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
@pytest.mark.parametrize("name", ["model.xml", "robot.urdf", "rig.py"])
def test_a_system_path_that_is_a_fifo_is_refused_at_once(tmp_path: Path, capsys, name: str) -> None:
    fifo = tmp_path / name
    os.mkfifo(fifo)
    assert main(["show", str(fifo)]) == 2  # reading it would block: nobody writes to it
    err = capsys.readouterr().err.strip()
    assert "is not a regular file" in err and len(err.splitlines()) == 1


def test_matrix_columns_stay_apart_with_long_names() -> None:
    import numpy as np

    from equilibrist.cli.common import format_matrix

    names = ("cart_to_pole_angle_rate", "slide_position_in_metres")
    text = format_matrix(np.array([[1.5e-3, -2.25e4]]), ("row",), names)
    head, row = text.splitlines()
    assert all(n in head.split() for n in names)  # every name a word of its own
    assert row.split()[1:] == ["0.0015", "-22500"]


def test_a_long_chain_is_refused_before_deriving(tmp_path: Path, capsys) -> None:
    body, close = "", ""
    for k in range(50):
        pos = "0 0 0" if k == 0 else "0 0 0.5"
        body += (f'<body name="l{k}" pos="{pos}"><joint name="j{k}" axis="0 1 0"/>'
                 '<inertial pos="0 0 0.25" mass="1" diaginertia="0.02 0.02 0.001"/>')
        close += "</body>"
    model = tmp_path / "chain.xml"
    model.write_text(f'<mujoco model="chain"><worldbody>{body}{close}</worldbody></mujoco>')
    assert main(["show", str(model)]) == 2
    err = capsys.readouterr().err
    assert "50 joints" in err and "at most 4 joints" in err
