"""Bad model files: one line on stderr naming what is wrong, exit status 2."""

from __future__ import annotations

from pathlib import Path

import pytest

from equilibrist.cli.main import main


def _mjcf(body: str, extra: str = "", option: str = "") -> str:
    return f"""<mujoco model="bad">{option}
  <worldbody>
{body}
  </worldbody>
{extra}
</mujoco>
"""


_PENDULUM = """    <body name="link">
      <joint name="a" axis="0 1 0"/>
      <inertial pos="0 0 0.5" mass="1" diaginertia="0.1 0.1 0.01"/>
    </body>"""

_URDF_HEAD = """<?xml version="1.0"?>
<robot name="bad">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0 0 0.5"/><mass value="1"/>
    <inertia ixx="0.1" iyy="0.1" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
"""

_URDF_JOINT = """  <joint name="j1" type="continuous"><parent link="base"/><child link="l1"/>
    <axis xyz="0 1 0"/><limit effort="5" velocity="1"/></joint>
"""


def _transmission(joint: str, interface: str = "hardware_interface/EffortJointInterface") -> str:
    return f"""  <transmission name="t"><type>transmission_interface/SimpleTransmission</type>
    <joint name="{joint}"><hardwareInterface>{interface}</hardwareInterface></joint>
    <actuator name="m"><mechanicalReduction>1</mechanicalReduction></actuator></transmission>
"""


CASES = {
    "malformed_xml": ("bad.xml", "<mujoco model='x'><worldbody><body></worldbody></mujoco>", "malformed XML"),
    "malformed_urdf": ("bad.urdf", "<robot name='x'><link name='a'></robot>", "malformed XML"),
    "urdf_in_xml": ("bad.xml", _URDF_HEAD + _URDF_JOINT + "</robot>", "expected an MJCF model"),
    "missing_inertial_urdf": (
        "bad.urdf",
        _URDF_HEAD.replace('<link name="l1"><inertial>', '<link name="l1"><nothing>').replace(
            "</inertial></link>", "</nothing></link>") + _URDF_JOINT + "</robot>",
        "has no <inertial>",
    ),
    "missing_inertial_mjcf": (
        "bad.xml", _mjcf('    <body name="link"><joint name="a"/></body>'), "mass",
    ),
    "zero_mass": (
        "bad.xml", _mjcf(_PENDULUM.replace('mass="1"', 'mass="0"')), "mass",
    ),
    "negative_mass": (
        "bad.xml", _mjcf(_PENDULUM.replace('mass="1"', 'mass="-1"')), "mass",
    ),
    "inertia_not_positive": (
        "bad.xml", _mjcf(_PENDULUM.replace('diaginertia="0.1 0.1 0.01"', 'diaginertia="0.1 -0.1 0.01"')),
        "inertia",
    ),
    "inertia_triangle": (
        "bad.xml", _mjcf(_PENDULUM.replace('diaginertia="0.1 0.1 0.01"', 'diaginertia="0.1 0.1 0.5"')),
        "inertia",
    ),
    "full_inertia_not_positive_definite": (
        "bad.xml", _mjcf(_PENDULUM.replace('diaginertia="0.1 0.1 0.01"',
                                           'fullinertia="0.1 0.1 0.1 0.2 0 0"')),
        "inertia",
    ),
    "ball_joint": ("bad.xml", _mjcf(_PENDULUM.replace('<joint name="a" axis="0 1 0"/>',
                                                      '<joint name="a" type="ball"/>')), "ball joint 'a'"),
    "free_joint": ("bad.xml", _mjcf(_PENDULUM.replace('<joint name="a" axis="0 1 0"/>',
                                                      '<freejoint name="a"/>')), "free joint 'a'"),
    "tendon": (
        "bad.xml",
        _mjcf(_PENDULUM, '<tendon><fixed name="tie"><joint joint="a" coef="1"/></fixed></tendon>'),
        "tendon 'tie'",
    ),
    "equality": (
        "bad.xml",
        _mjcf(_PENDULUM, '<equality><joint name="lock" joint1="a"/></equality>'),
        "equality constraint 'lock'",
    ),
    "position_actuator": (
        "bad.xml",
        _mjcf(_PENDULUM, '<actuator><position name="servo" joint="a" kp="10" ctrlrange="-1 1"/></actuator>'),
        "actuator 'servo' is not a motor",
    ),
    "motor_without_range": (
        "bad.xml",
        _mjcf(_PENDULUM, '<actuator><motor name="m" joint="a" ctrllimited="false"/></actuator>'),
        "actuator 'm' has no ctrlrange",
    ),
    "unknown_actuator_joint": (
        "bad.xml", _mjcf(_PENDULUM, '<actuator><motor name="m" joint="nope" ctrlrange="-1 1"/></actuator>'),
        "nope",
    ),
    "unknown_transmission_joint": (
        "bad.urdf", _URDF_HEAD + _URDF_JOINT + _transmission("nope") + "</robot>", "unknown joint 'nope'",
    ),
    "position_transmission": (
        "bad.urdf",
        _URDF_HEAD + _URDF_JOINT + _transmission("j1", "hardware_interface/PositionJointInterface")
        + "</robot>",
        "only effort",
    ),
    "joint_loop": (
        "bad.urdf",
        _URDF_HEAD + _URDF_JOINT
        + """  <link name="l2"><inertial><mass value="1"/><inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="j2" type="continuous"><parent link="l1"/><child link="l2"/><axis xyz="0 1 0"/></joint>
  <joint name="j3" type="continuous"><parent link="base"/><child link="l2"/><axis xyz="0 1 0"/></joint>
</robot>""",
        "loop",
    ),
    "negative_frictionloss": (
        "bad.xml", _mjcf(_PENDULUM.replace('axis="0 1 0"', 'axis="0 1 0" frictionloss="-0.1"')),
        "joint 'a' has friction (frictionloss) -0.1: expected >= 0",
    ),
    "negative_urdf_friction": (
        "bad.urdf", _URDF_HEAD + _URDF_JOINT.replace("</joint>", '<dynamics friction="-0.2"/></joint>') + "</robot>",
        "joint 'j1' has friction (frictionloss) -0.2: expected >= 0",
    ),
    "entity_declaration": (
        "bad.urdf",
        '<?xml version="1.0"?>\n<!DOCTYPE robot [<!ENTITY m "1">]>\n'
        + _URDF_HEAD.split("\n", 1)[1].replace('<mass value="1"/>', '<mass value="&m;"/>') + _URDF_JOINT
        + "</robot>",
        "entities (<!ENTITY>), which are not expanded",
    ),
    "entity_declaration_mjcf": (
        "bad.xml",
        '<?xml version="1.0"?>\n<!DOCTYPE mujoco [<!ENTITY m "1">]>\n'
        + _mjcf(_PENDULUM.replace('mass="1"', 'mass="&m;"')),
        "entities (<!ENTITY>), which are not expanded",
    ),
    "bad_number_in_a_merged_link": (
        "bad.urdf",
        _URDF_HEAD + _URDF_JOINT
        + '  <link name="tip"><inertial><mass value="0"/><origin xyz="0 0 one"/></inertial></link>\n'
        + '  <joint name="tip_mount" type="fixed"><parent link="l1"/><child link="tip"/></joint>\n</robot>',
        "<origin> xyz='0 0 one': expected 3 numbers separated by spaces",
    ),
    "world_as_child": (
        "bad.urdf",
        _URDF_HEAD + _URDF_JOINT
        + '  <joint name="up" type="fixed"><parent link="l1"/><child link="world"/></joint>\n</robot>',
        "joint 'up' makes the link 'world' a child",
    ),
    "namespaced_root_not_robot": (
        "bad.urdf", '<model xmlns="https://drake.mit.edu" name="x"/>', "expected a <robot> root element",
    ),
    "keyframe_length": (
        "bad.xml", _mjcf(_PENDULUM, '<keyframe><key name="balance" qpos="0 0 0"/></keyframe>'),
        "keyframe 'balance'",
    ),
    "unnamed_joint": ("bad.xml", _mjcf(_PENDULUM.replace(' name="a"', "")), "has no name"),
    "fluid": ("bad.xml", _mjcf(_PENDULUM, option='<option density="1.2"/>'), "fluid"),
    "nothing_moves": ("bad.xml", _mjcf('    <body name="b"><geom size="0.1"/></body>'), "no hinge or slide"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_model_file_is_one_line_and_exit_2(case: str, tmp_path: Path, capsys) -> None:
    name, text, expected = CASES[case]
    path = tmp_path / name
    path.write_text(text)
    assert main(["show", str(path)]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    assert expected in err, err
    assert name in err, err
    assert captured.out == ""
