"""URDFs as ROS, Drake and Gazebo users write them, unedited, against a second derivation.

Each file in tests/models was written in one community's habits (see its
comment): a ``world`` weld, Drake's namespace and attributes, Gazebo and
``<frame>`` elements, ROS 1's legacy transmissions, joint friction, point
masses, a massless link, meshes that are not shipped. The truth here is the
dynamics written by hand from the files' link parameters: every rig is planar,
so each body's centre of mass is a sum of rotated constant vectors, and the
equations are the bodies' Newton-Euler equations projected on the joints
(``M = sum m J'J + I w w'``, ``M q_dd = Q - sum m J' Jdot q_d - dV/dq``), not
the importer's Lagrangian of the kinematic tree. (Drake's MultibodyPlant
gives the same to round-off: bench/bench_urdf_drake.py.)
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from equilibrist.cli.main import main
from equilibrist.numeric.lookup import get_system

MODELS = Path(__file__).resolve().parents[1] / "models"
G = 9.81


def _rot(phi: float) -> np.ndarray:
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, -s], [s, c]])


_TURN = np.array([[0.0, -1.0], [1.0, 0.0]])

# A body: mass, inertia about the rotation axis, its rotation's weights on the coordinates,
# its centre of mass as (weights, constant vector) terms rotated by w.q, and the
# coordinates' weights of a translation along the plane's first and second axes.
Body = tuple[float, float, list[float], list[tuple[list[float], list[float]]], list[list[float]]]


def _planar(bodies: list[Body], up: int, forces: Callable[[np.ndarray, np.ndarray], np.ndarray],
            n: int) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """``x -> (M, M^-1 F)`` of planar rigid bodies (the plane's axis *up* points up)."""

    def dynamics(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q, qd = x[:n], x[n:]
        mass = np.zeros((n, n))
        rhs = forces(q, qd).astype(float)
        for m, inertia, spin, terms, slide in bodies:
            jac = np.array(slide, float) if slide else np.zeros((2, n))
            bias = np.zeros(2)
            for w, a in terms:
                w_arr, r = np.array(w, float), _rot(float(np.dot(w, q))) @ np.array(a, float)
                jac = jac + np.outer(_TURN @ r, w_arr)
                bias -= r * float(np.dot(w_arr, qd)) ** 2
            mass += m * jac.T @ jac + inertia * np.outer(spin, spin)
            rhs -= m * jac.T @ bias + m * G * jac[up]
        return mass, np.linalg.solve(mass, rhs)

    return dynamics


def _atan(cf: float, v: float) -> float:  # the benchmark's smooth Coulomb law
    return cf * math.atan(100.0 * v)


def _acrobot() -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    # Plane (z, x) of rotations about +y; links hang along -z; elbow 1 m below the shoulder.
    bodies: list[Body] = [
        (1.0, 0.083, [1, 0], [([1, 0], [-0.5, 0])], []),
        (1.0, 0.33, [1, 1], [([1, 0], [-1.0, 0]), ([1, 1], [-1.0, 0])], []),
    ]
    return _planar(bodies, 0, lambda q, qd: np.array([-0.1 * qd[0], -0.1 * qd[1] + U[0]]), 2)


def _pendulum() -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    # Two point masses on one arm: 0.4 kg at 0.6 m and 0.5 kg at 0.45 m; a rotor of
    # 0.0005 kg m^2 through a 6:1 gear (Drake's reflected inertia, Ir * gr^2).
    bodies: list[Body] = [(0.4, 0.0, [1], [([1], [-0.6, 0])], []), (0.5, 0.0, [1], [([1], [-0.45, 0])], []),
                          (0.0, 0.0005 * 6**2, [1], [], [])]
    return _planar(bodies, 0, lambda q, qd: np.array([-0.1 * qd[0] + U[0]]), 1)


def _cartpole() -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    # Plane (z, x); the cart slides along x, the pole (0.4 m to its centre) stands up.
    bodies: list[Body] = [
        (1.5, 0.0, [0, 0], [], [[0, 0], [1, 0]]),
        (0.25, 0.0134, [0, 1], [([0, 1], [0.4, 0])], [[0, 0], [1, 0]]),
    ]

    def forces(q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return np.array([U[0] - 0.3 * qd[0] - _atan(0.5, qd[0]), -0.002 * qd[1] - _atan(0.01, qd[1])])

    return _planar(bodies, 0, forces, 2)


def _rig() -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    # Plane (y, z) of rotations about +x; the second link's frame is turned over (rpy = -pi
    # about x) at (y, z) = (0, -0.3); the zero-mass weight adds nothing.
    bodies: list[Body] = [
        (0.5934, 0.0531, [1, 0], [([1, 0], [0.0013, -0.2711])], []),
        (0.6307, 0.0251, [1, 1], [([1, 0], [0.0, -0.3]), ([1, 1], list(_rot(-math.pi) @ [0.0009, 0.1672]))], []),
    ]

    def forces(q: np.ndarray, qd: np.ndarray) -> np.ndarray:
        return np.array([U[0] - 0.0812 * qd[0] - _atan(0.0931, qd[0]),
                         U[1] - 0.0012 * qd[1] - _atan(0.0786, qd[1])])

    return _planar(bodies, 1, forces, 2)


U = np.zeros(2)  # the inputs of the hand derivations, set per state
FILES = {
    "drake_acrobot.urdf": _acrobot,
    "drake_pendulum.urdf": _pendulum,
    "ros_cartpole.urdf": _cartpole,
    "rig_double_pendulum.urdf": _rig,
}


@pytest.mark.parametrize("name", sorted(FILES))
def test_dynamics_equal_the_hand_derivation(name: str) -> None:
    system = get_system(str(MODELS / name))
    truth = FILES[name]()
    n = len(system.spec.coordinates)
    rng = np.random.default_rng(47)
    for _ in range(12):
        x = np.concatenate([rng.uniform(-math.pi, math.pi, n), rng.uniform(-3, 3, n)])
        u = rng.uniform(-5, 5, system.n_inputs)
        U[: len(u)] = u
        mass, qdd = truth(x)
        got = system.f(x, u)[n:]
        assert np.abs(got - qdd).max() <= 1e-9 * max(1.0, np.abs(qdd).max()), (name, x, got, qdd)
        ours = np.zeros((n, n))
        system.functions.mass_matrix(x, system.p, ours)
        assert np.abs(ours - mass).max() <= 1e-12 * np.abs(mass).max()


def test_drake_acrobot_is_read_as_drake_writes_it(capsys: pytest.CaptureFixture[str]) -> None:
    path = MODELS / "drake_acrobot.urdf"
    assert main(["linearize", str(path), "--json"]) == 0
    notes = json.loads(capsys.readouterr().out)["notes"]
    assert "the root's XML namespace https://drake.mit.edu is read as URDF's" in notes
    ignored = next(n for n in notes if n.startswith("not URDF, ignored: "))
    # each named once, though the schema attribute and <frame> could repeat
    assert ignored == ("not URDF, ignored: attribute 'schemaLocation' (namespace "
                       "http://www.w3.org/2001/XMLSchema-instance), element <frame>")
    assert "the link 'world' is the world; base_weld places the base in it" in notes
    # The elbow has no effort limit: an input without limits, said in a note.
    system = get_system(str(path))
    assert system.input_names == ("elbow_torque",)
    low, high = system.input_limits
    assert low[0] == -1e9 and high[0] == 1e9
    assert any(n.startswith("joints without an effort limit") and "elbow (elbow)" in n for n in notes)


def test_ros_cartpole_legacy_transmission_friction_and_limits() -> None:
    system = get_system(str(MODELS / "ros_cartpole.urdf"))
    spec = system.spec
    assert system.input_names == ("cart_motor",)
    assert tuple(system.input_limits[1]) == (30.0,)
    frictions = {p.name: p for p in spec.parameters if p.name.endswith("_friction")}
    assert {k: p.default for k, p in frictions.items()} == {"slider_friction": 0.5, "hinge_friction": 0.01}
    assert all(p.dissipative for p in frictions.values())
    assert spec.region["slider"] == (-0.8, 0.8)  # the rail's limits
    assert "joints with a range that is not enforced: slider [-0.8, 0.8]" in spec.notes  # continuous: none
    assert spec.region["hinge"] == (-math.pi / 2, math.pi / 2)  # continuous: the fall angle only
    notes = "\n".join(spec.notes)
    assert "not URDF, ignored: element <gazebo>\n" in notes
    assert "package://cartpole_description/meshes/cart.stl" in notes
    assert "the link 'world' is the world (its inertial ignored); rail_weld places the base in it" in notes
    # Friction takes energy out; with it at zero (and no damping, no input) energy is kept.
    n = 2
    x = np.array([0.1, 0.3, 0.7, -1.1])
    free = system.with_params(slider_friction=0.0, hinge_friction=0.0, slider_damping=0.0, hinge_damping=0.0)
    power = _power(free, x, n)
    assert abs(power) <= 1e-12
    assert _power(system.with_params(slider_damping=0.0, hinge_damping=0.0), x, n) < 0


def _power(system, x: np.ndarray, n: int) -> float:
    """dE/dt along f (central difference along the flow)."""
    h = 1e-6
    xd = system.f(x, np.zeros(system.n_inputs))
    return (system.energy(x + h * xd) - system.energy(x - h * xd)) / (2 * h)


def test_point_masses_and_massless_links_are_merged_and_named() -> None:
    pendulum = get_system(str(MODELS / "drake_pendulum.urdf"))
    notes = pendulum.spec.notes
    assert "not URDF, ignored: attribute 'drake_ignore', element <gazebo>" in notes
    assert "links fixed to a moving link with no mass or no rotational inertia, merged into it: arm_com" in notes
    assert [p.name for p in pendulum.spec.parameters] == ["g", "arm_mass", "theta_damping"]
    assert any(n.startswith("rotor inertia through the gear") and n.endswith("theta 0.018") for n in notes)
    assert pendulum.params["arm_mass"] == pytest.approx(0.9, abs=1e-15)
    rig = get_system(str(MODELS / "rig_double_pendulum.urdf"))
    assert any(n.endswith("merged into it: Weight") for n in rig.spec.notes)
    assert any(n.startswith("mesh files not found, ignored") and "./meshes/Weight.obj" in n for n in rig.spec.notes)
    # revolute limits of +-3.1415926 bound nothing tighter than the fall angle around the hanging pose
    assert rig.spec.region["Joint1"] == pytest.approx((-math.pi / 2, math.pi / 2))


def test_tool_specific_content_is_named_never_read(tmp_path: Path) -> None:
    from equilibrist.importers import load_model_file

    path = tmp_path / "tools.urdf"
    path.write_text("""<?xml version="1.0"?>
<robot name="tools" xmlns:drake="http://drake.mit.edu" xmlns:xacro="http://www.ros.org/wiki/xacro">
  <link name="base"><drake:proximity_properties><drake:mu_static value="inf"/></drake:proximity_properties></link>
  <link name="arm" drake:collision_filter="all">
    <inertial><origin xyz="0 0 -0.5"/><mass value="1"/>
      <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial>
  </link>
  <joint name="theta" type="continuous"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
    <limit effort="2" velocity="1"/></joint>
  <gazebo reference="arm"><plugin name="p" filename="lib.so" period="nan"/></gazebo>
  <gazebo reference="base"><mu1>0.2</mu1></gazebo>
  <ros2_control name="hw" type="system"><hardware><plugin>mock</plugin></hardware></ros2_control>
  <xacro:macro name="m"/>
  <transmission name="t">
    <type>transmission_interface/SimpleTransmission</type>
    <joint name="theta"><hardwareInterface>hardware_interface/EffortJointInterface</hardwareInterface></joint>
    <actuator name="motor"><mechanicalReduction>2</mechanicalReduction></actuator>
  </transmission>
</robot>
""")
    entry = load_model_file(path, origin=str(path), content=path.read_bytes())
    ignored = [n for n in entry.spec.notes if n.startswith("not URDF, ignored: ")]
    assert ignored == ["not URDF, ignored: element <proximity_properties> (namespace http://drake.mit.edu), "
                       "attribute 'collision_filter' (namespace http://drake.mit.edu), element <gazebo>, "
                       "element <ros2_control>, element <macro> (namespace http://www.ros.org/wiki/xacro)"]
    assert entry.spec.input_names == ("motor",)
    # The input is the torque at the joint (2 * the actuator's effort), within the joint's effort limit.
    assert (entry.spec.inputs[0].low, entry.spec.inputs[0].high) == (-2.0, 2.0)


@pytest.mark.parametrize("encoding", ["utf-8", "utf-16"])
def test_entity_declarations_are_refused_in_any_encoding(encoding: str) -> None:
    from equilibrist.errors import DefinitionError
    from equilibrist.importers.urdf_clean import parse_urdf

    doc = (f'<?xml version="1.0" encoding="{encoding}"?>\n'
           '<!DOCTYPE robot [<!ENTITY a "aaaaaaaaaa"><!ENTITY b "&a;&a;&a;&a;">]>\n<robot name="x">&b;</robot>')
    with pytest.raises(DefinitionError, match=r"declares XML entities \(<!ENTITY>\), which are not expanded"):
        parse_urdf("x.urdf", doc.encode(encoding))
