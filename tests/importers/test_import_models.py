"""Model files (MJCF, URDF) against MuJoCo itself, the catalogue, and conservation laws.

The independent truth is MuJoCo: the same file, compiled by MuJoCo and run
through ``mj_forward`` with constraints off (contacts and limits are not
modelled), gives ``qacc``; the derived ``f(x, u)`` must agree to round-off.
An input is the physical generalized force on its joint: MuJoCo's ctrl is
that force over the motor's gear. URDF transmissions, which MuJoCo ignores,
are applied to MuJoCo as that generalized force (``qfrc_applied``), the
actuator's effort times ``mechanicalReduction``.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import pytest
from scipy.integrate import solve_ivp
from tests.support.jacobians import central_differences

from equilibrist.numeric.lookup import get_system
from equilibrist.numeric.system import System

ROOT = Path(__file__).resolve().parents[2]
MODELS = ROOT / "tests" / "models"
SHIPPED = [ROOT / "examples" / "furuta.xml", ROOT / "examples" / "pendubot.urdf"]
TEST_MODELS = [MODELS / "cartpole.xml", MODELS / "spatial.xml", MODELS / "slides.xml", MODELS / "arm.urdf",
               MODELS / "planar.urdf"]
ALL = SHIPPED + TEST_MODELS


def _reductions(path: Path) -> dict[str, tuple[str, float]]:
    """URDF actuator name -> (joint, reduction), read straight from the file."""
    import xml.etree.ElementTree as ET

    out = {}
    for t in ET.parse(path).getroot().findall("transmission"):
        joint = t.find("joint")
        actuator = t.find("actuator")
        assert joint is not None and actuator is not None
        red = actuator.find("mechanicalReduction")
        out[actuator.get("name", "")] = (joint.get("name", ""), float(red.text if red is not None and red.text else 1))
    return out


class MuJoCoTruth:
    """MuJoCo's forward dynamics of a model file, in the derived system's state order."""

    def __init__(self, path: Path, system: System) -> None:
        self.model = mujoco.MjModel.from_xml_path(str(path))
        self.model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
        self.data = mujoco.MjData(self.model)
        names = [self.model.jnt(j).name for j in range(self.model.njnt)]
        joints = [names.index(c) for c in system.spec.coordinates]
        self.qpos = [int(self.model.jnt_qposadr[j]) for j in joints]
        self.dof = [int(self.model.jnt_dofadr[j]) for j in joints]
        self.system = system
        self.urdf = path.suffix == ".urdf"
        self.reductions = _reductions(path) if self.urdf else {}
        self.joint_dof = dict(zip(system.spec.coordinates, self.dof, strict=True))
        # The inputs are the motors' forces: MuJoCo's ctrl is the force over
        # the gain (gear times the gain parameter).
        self.gain = np.array([float(self.model.actuator_gear[a, 0]) * float(self.model.actuator_gainprm[a, 0])
                              for a in range(self.model.nu)])

    def qacc(self, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        n = len(self.qpos)
        self.data.qpos[self.qpos] = x[:n]
        self.data.qvel[self.dof] = x[n:]
        self.data.qfrc_applied[:] = 0.0
        if self.urdf:
            for name, value in zip(self.system.input_names, u, strict=True):
                joint, _reduction = self.reductions[name]
                self.data.qfrc_applied[self.joint_dof[joint]] += value
        elif self.model.nu:
            self.data.ctrl[:] = u / self.gain
        mujoco.mj_forward(self.model, self.data)
        return np.array(self.data.qacc[self.dof])


def _random_params(system: System, rng: np.random.Generator) -> System:
    """Masses and damping drawn around the file's values (the parameters of an import)."""
    values = {}
    for p in system.spec.parameters:
        if p.name.endswith("_mass"):
            values[p.name] = p.default * float(rng.uniform(0.5, 2.0))
        elif p.name.endswith("_damping"):
            values[p.name] = float(rng.uniform(0.0, 0.3))
        elif p.name == "g":
            values[p.name] = float(rng.uniform(5.0, 12.0))
    return system.with_params(**values)


def _set_mujoco_params(truth: MuJoCoTruth, system: System, reference: System) -> None:
    """The same parameter values in MuJoCo's model (mass and inertia scaled, damping, gravity)."""
    m = truth.model
    for b in range(1, m.nbody):
        name = m.body(b).name
        key = f"{name}_mass"
        if key in system.params:
            scale = system.params[key] / reference.params[key]
            m.body_mass[b] *= scale
            m.body_inertia[b] *= scale
    for c, dof in truth.joint_dof.items():
        m.dof_damping[dof] = system.params[f"{c}_damping"]
    g = np.asarray(m.opt.gravity, float)
    if np.linalg.norm(g) > 0:
        m.opt.gravity[:] = g / np.linalg.norm(g) * system.params["g"]


@pytest.mark.parametrize("path", ALL, ids=lambda p: p.name)
def test_f_equals_mujoco_forward_dynamics(path: Path) -> None:
    rng = np.random.default_rng(abs(hash(path.name)) % 2**32)
    base = get_system(str(path))
    assert base.n_states == 2 * len(base.spec.coordinates)
    for trial in range(3):
        system = base if trial == 0 else _random_params(base, rng)
        truth = MuJoCoTruth(path, system)
        _set_mujoco_params(truth, system, base)
        low, high = system.input_limits
        for _ in range(8):
            n = len(system.spec.coordinates)
            x = np.concatenate([rng.uniform(-1.5, 1.5, n), rng.uniform(-3.0, 3.0, n)])
            u = rng.uniform(low, high) if system.n_inputs else np.zeros(0)
            expected = truth.qacc(x, u)
            got = system.f(x, u)
            assert np.allclose(got[:n], x[n:], rtol=0, atol=0)
            scale = max(1.0, float(np.abs(expected).max()))
            assert np.abs(got[n:] - expected).max() <= 1e-9 * scale, (path.name, x, u, got[n:], expected)


@pytest.mark.parametrize("path", ALL, ids=lambda p: p.name)
def test_jacobians_equal_central_differences_of_f(path: Path) -> None:
    # Trees of up to three joints form df/dx from M and F (codegen's mass form), larger
    # ones from f's own derivative: both against central differences of f (which the test
    # above holds to MuJoCo's forward dynamics).
    rng = np.random.default_rng(abs(hash(path.name)) % 2**32 + 1)
    system = get_system(str(path))
    m = system.n_inputs
    for _ in range(4):
        k = len(system.spec.coordinates)
        x = np.concatenate([rng.uniform(-1.5, 1.5, k), rng.uniform(-3.0, 3.0, k)])
        low, high = system.input_limits
        u = rng.uniform(low, high) if m else np.zeros(0)
        A, B = system.jacobians(x, u)
        A_fd, B_fd = central_differences(system, x, u)
        assert np.allclose(A, A_fd, rtol=1e-5, atol=1e-6 * (1.0 + np.abs(A_fd).max()))
        if m:
            assert np.allclose(B, B_fd, rtol=1e-5, atol=1e-6 * (1.0 + np.abs(B_fd).max()))


@pytest.mark.parametrize("path", ALL, ids=lambda p: p.name)
def test_energy_is_conserved_without_damping_and_input(path: Path) -> None:
    base = get_system(str(path))
    free = base.with_params(**{p.name: 0.0 for p in base.spec.parameters if p.name.endswith("_damping")})
    rng = np.random.default_rng(7)
    n = len(free.spec.coordinates)
    x0 = np.concatenate([rng.uniform(-1.0, 1.0, n), rng.uniform(-2.0, 2.0, n)])
    fns, p = free.functions, free.p
    u = np.zeros(free.n_inputs)

    def rhs(_t: float, x: np.ndarray) -> np.ndarray:
        out = np.empty(free.n_states)
        fns.f(x, u, p, out)
        return out

    sol = solve_ivp(rhs, (0.0, 2.0), x0, method="DOP853", rtol=1e-11, atol=1e-12, dense_output=False)
    assert sol.success
    energies = np.array([free.energy(x) for x in sol.y.T])
    # The energy's scale: its kinetic and potential parts move by this much.
    swing = max(float(np.ptp([free.energy(np.concatenate([x[:n], 0 * x[n:]])) for x in sol.y.T])), 1e-6)
    assert np.abs(energies - energies[0]).max() <= 1e-7 * (swing + abs(energies[0]))
    # Damping dissipates: with it, the energy falls.
    damped = base.with_params(**{p.name: 0.2 for p in base.spec.parameters if p.name.endswith("_damping")})
    dfns, dp = damped.functions, damped.p

    def damped_rhs(_t: float, x: np.ndarray) -> np.ndarray:
        out = np.empty(damped.n_states)
        dfns.f(x, u, dp, out)
        return out

    end = solve_ivp(damped_rhs, (0.0, 2.0), x0, method="DOP853", rtol=1e-10, atol=1e-12).y[:, -1]
    assert damped.energy(end) < damped.energy(x0)


def test_cartpole_model_gives_the_catalogue_cartpole() -> None:
    rng = np.random.default_rng(3)
    imported = get_system(str(MODELS / "cartpole.xml"))
    for _ in range(5):
        b_c, b_p = rng.uniform(0.0, 0.5, 2)
        m_c, m_p = rng.uniform(5.0, 15.0), rng.uniform(0.5, 2.0)
        mine = imported.with_params(x_damping=b_c, theta_damping=b_p, cart_mass=m_c, pole_mass=m_p)
        # The file's pole inertia scales with its mass: I_p = 0.08333 m_p.
        theirs = get_system("cartpole", b_c=b_c, b_p=b_p, m_c=m_c, m_p=m_p, I_p=0.08333 * m_p)
        for _ in range(6):
            x = np.concatenate([rng.uniform(-1, 1, 1), rng.uniform(-1.5, 1.5, 1), rng.uniform(-3, 3, 2)])
            u = rng.uniform(-50, 50, 1)
            # Same conventions: x to the right, theta leaning the pole towards +x.
            assert np.allclose(mine.f(x, u), theirs.f(x, u), rtol=1e-12, atol=1e-12)


def test_furuta_model_gives_the_catalogue_furuta() -> None:
    rng = np.random.default_rng(4)
    imported = get_system(str(ROOT / "examples" / "furuta.xml"))
    catalogue = get_system("furuta")
    for _ in range(20):
        x = np.concatenate([rng.uniform(-2, 2, 2), rng.uniform(-5, 5, 2)])
        u = rng.uniform(-0.05, 0.05, 1)
        a, b = imported.f(x, u), catalogue.f(x, u)
        # The file's pendulum keeps 2e-15 kg m^2 about its own axis (MuJoCo's
        # least), the catalogue's slender rod none: 1e-10 of its inertia.
        assert np.abs(a - b).max() <= 1e-9 * np.abs(b).max()
    assert imported.output_names == catalogue.output_names == ("phi", "theta")
    assert imported.spec.sensor_noise["theta"] == pytest.approx(catalogue.spec.sensor_noise["theta"], rel=1e-3)


def test_pendubot_urdf_gives_the_catalogue_pendubot() -> None:
    rng = np.random.default_rng(5)
    # A URDF has no gravity: MuJoCo's default 9.81; the catalogue's is Gymnasium's 9.8.
    imported = get_system(str(ROOT / "examples" / "pendubot.urdf"), g=9.8)
    catalogue = get_system("pendubot")
    for _ in range(20):
        x = np.concatenate([rng.uniform(-2, 2, 2), rng.uniform(-5, 5, 2)])
        u = rng.uniform(-10, 10, 1)
        # The file is drawn upright: the catalogue's theta1 is shoulder + pi.
        xc = x.copy()
        xc[0] += np.pi
        assert np.allclose(imported.f(x, u), catalogue.f(xc, u), rtol=1e-12, atol=1e-12)
    assert imported.input_limits[1][0] == catalogue.input_limits[1][0] == 10.0


def test_mjcf_frictionloss_and_armature_are_mujocos(tmp_path: Path) -> None:
    # MuJoCo's frictionloss is dry friction bounded by its value (a constraint, here at
    # speeds where it saturates), armature a rotor inertia on the joint's diagonal: the
    # derived model's tanh(100 v) law and its mass matrix give MuJoCo's accelerations.
    path = tmp_path / "rotor.xml"
    path.write_text("""<mujoco model="rotor">
  <worldbody>
    <body name="l1">
      <joint name="a" axis="0 1 0" frictionloss="0.3" armature="0.05" damping="0.02"/>
      <inertial pos="0 0 0.5" mass="1" diaginertia="0.1 0.1 0.01"/>
      <body name="l2" pos="0 0 1">
        <joint name="b" axis="0 1 0" frictionloss="0.07" armature="0.2"/>
        <inertial pos="0 0 0.4" mass="0.5" diaginertia="0.03 0.03 0.002"/>
      </body>
    </body>
  </worldbody>
  <actuator><motor name="m" joint="a" ctrlrange="-2 2"/></actuator>
</mujoco>""")
    system = get_system(str(path))
    assert {p.name: p.default for p in system.spec.parameters if p.dissipative} == {
        "a_damping": 0.02, "b_damping": 0.0, "a_friction": 0.3, "b_friction": 0.07}
    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(3)
    for _ in range(10):
        q = rng.uniform(-2, 2, 2)
        v = rng.choice([-1.0, 1.0], 2) * rng.uniform(0.5, 3.0, 2)
        u = rng.uniform(-2, 2, 1)
        data.qpos[:], data.qvel[:], data.ctrl[:] = q, v, u
        mujoco.mj_forward(model, data)
        assert np.allclose(data.qfrc_constraint, -np.array([0.3, 0.07]) * np.sign(v), rtol=1e-9, atol=0)
        got = system.f(np.concatenate([q, v]), u)[2:]
        assert np.abs(got - data.qacc).max() <= 1e-9 * max(1.0, np.abs(data.qacc).max())
