"""The heavy symmetric top in both parameterizations.

Independent truths used here: conservation of energy and momenta along
accurate trajectories; the kinetic energy and momenta computed by hand from
the quaternion route (``equilibrist.mechanics.rotations``) and the parallel
axis theorem, not from sympy.physics.mechanics; the equations printed in
seed 002 where they are right; the compound pendulum's and the sleeping
top's (Maxwell-Klein) stability limits; scipy's rotations for the axis.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp
from scipy.spatial.transform import Rotation

from equilibrist.errors import SingularConfigurationError, UnknownNameError
from equilibrist.mechanics import rotations
from equilibrist.numeric.lookup import get_system
from equilibrist.systems import _gyro_tools as gt

# A generic motion, away from both singularities: the axis 0.5-1.1 rad from
# vertical (zxz regular) and never horizontal (xyz regular).
X0_ZXZ = np.array([0.3, 0.8, -0.4, 1.5, 2.0, 250.0])


def _systems():
    return get_system("gyroscope"), get_system("gyroscope", euler="xyz")


def _simulate(system, x0, t_end: float, n: int = 400) -> tuple[np.ndarray, np.ndarray]:
    fn, p = system.functions.f, system.p
    u = np.zeros(0)
    buf = np.empty(6)

    def rhs(_t: float, x: np.ndarray) -> np.ndarray:
        fn(x, u, p, buf)
        return buf.copy()

    t_eval = np.linspace(0.0, t_end, n)
    sol = solve_ivp(rhs, (0.0, t_end), x0, method="DOP853", rtol=1e-11, atol=1e-12, t_eval=t_eval)
    assert sol.success, sol.message
    return sol.t, sol.y.T


def _inertias(system) -> tuple[float, float, float]:
    prm = system.params
    I_xy = prm["I_t"] + prm["m"] * prm["R"] ** 2  # transverse, about the fixed point
    return I_xy, prm["I_s"], prm["m"] * prm["g"] * prm["R"]


# -- conservation ----------------------------------------------------------------
@pytest.mark.parametrize("euler", ["zxz", "xyz"])
def test_energy_and_momenta_conserved(euler: str) -> None:
    system = get_system("gyroscope", euler=euler)
    x0 = X0_ZXZ if euler == "zxz" else gt.zxz_to_xyz(X0_ZXZ)
    _, xs = _simulate(system, x0, 2.0)
    # Nutation must actually happen for conservation to mean anything.
    tilt = np.arccos(gt.spin_axis(euler, xs)[:, 2])
    assert np.ptp(tilt) > 1e-3
    energy = np.array([system.energy(x) for x in xs])
    assert np.ptp(energy) / abs(energy[0]) < 1e-8
    names = {"zxz": {"p_phi", "p_psi"}, "xyz": {"p_psi", "L_vertical"}}[euler]
    series = [system.conserved(x) for x in xs]
    assert set(series[0]) == names
    for name in names:
        values = np.array([c[name] for c in series])
        assert np.ptp(values) / abs(values[0]) < 1e-8, name


def _hand_quantities(euler: str, system, x: np.ndarray) -> dict[str, float]:
    """Energy and momenta by the quaternion route and the parallel-axis theorem."""
    I_xy, I_s, p = _inertias(system)
    omega_body = rotations.angular_velocity(euler, x[:3], x[3:], frame="body")
    inertia = np.diag([I_xy, I_xy, I_s])  # about the fixed point, body axes
    R = rotations.rotation_matrix(euler, x[:3])
    momentum = R @ (inertia @ omega_body)  # about the fixed point, room axes
    height = R[2, 2]  # the axis' vertical component
    return {
        "energy": 0.5 * omega_body @ inertia @ omega_body + p * height,
        "p_psi": I_s * omega_body[2],
        "vertical": momentum[2],
    }


@pytest.mark.parametrize("euler", ["zxz", "xyz"])
def test_energy_and_momenta_equal_a_second_route(euler: str) -> None:
    system = get_system("gyroscope", euler=euler, m=0.3, R=0.07, I_t=2e-4, I_s=5e-4)
    rng = np.random.default_rng(17)
    for _ in range(10):
        x = np.concatenate([rng.uniform(-1.2, 1.2, 3), rng.uniform(-20, 20, 3)])
        if euler == "zxz":
            x[1] = rng.uniform(0.3, 2.8)
        hand = _hand_quantities(euler, system, x)
        got = system.conserved(x)
        assert system.energy(x) == pytest.approx(hand["energy"], rel=1e-12)
        assert got["p_psi"] == pytest.approx(hand["p_psi"], rel=1e-12)
        vertical = got["p_phi"] if euler == "zxz" else got["L_vertical"]
        assert vertical == pytest.approx(hand["vertical"], rel=1e-12, abs=1e-15)


# -- the seed's equations ----------------------------------------------------------
def _random_states(rng, n: int = 8) -> list[np.ndarray]:
    out = []
    for _ in range(n):
        x = np.concatenate([rng.uniform(-1.2, 1.2, 3), rng.uniform(-10, 10, 3)])
        x[1] = rng.uniform(0.3, 1.3) * rng.choice([-1, 1])  # regular in both variants
        out.append(x)
    return out


def test_zxz_matches_the_seed_except_its_last_psi_ddot_line() -> None:
    system, _ = _systems()
    I_xy, I_z, p = _inertias(system)
    I_c = I_z - I_xy
    wrong_seen = 0
    for x in _random_states(np.random.default_rng(1)):
        _phi, th, _psi, phd, thd, psd = x
        s, c = math.sin(th), math.cos(th)
        phi_dd, theta_dd, psi_dd = system.f(x)[3:]
        seed_theta = (
            0.5 * phd**2 * math.sin(2 * th)
            + I_z / (2 * I_xy) * (-(phd**2) * math.sin(2 * th) - 2 * psd * phd * s)
            + p * s / I_xy
        )
        seed_phi = (I_z * thd * phd * c - 2 * I_xy * thd * phd * c + I_z * psd * thd) / (I_xy * s)
        # The line before the last: right.
        seed_psi = (
            -I_z * thd * phd * c**2 + 2 * I_xy * thd * phd * c**2 - I_z * psd * thd * c
            + I_xy * thd * phd * s**2
        ) / (I_xy * s)
        # The last printed line: the slip SYSTEMS.md lists.
        seed_psi_last = (-I_c * thd * phd * c**2 + I_xy * thd * phd * c + I_z * psd * thd) / (I_xy * s)
        assert theta_dd == pytest.approx(seed_theta, rel=1e-9)
        assert phi_dd == pytest.approx(seed_phi, rel=1e-9)
        assert psi_dd == pytest.approx(seed_psi, rel=1e-9)
        wrong_seen += not math.isclose(psi_dd, seed_psi_last, rel_tol=1e-3)
    assert wrong_seen == 8


def test_xyz_matches_the_seed_except_its_last_psi_ddot_line() -> None:
    _, system = _systems()
    I_xy, I_z, p = _inertias(system)
    I_c = I_z - I_xy
    wrong_seen = 0
    for x in _random_states(np.random.default_rng(2)):
        th, ph, _psi, thd, phd, psd = x
        s, c = math.sin(ph), math.cos(ph)
        theta_dd, phi_dd, psi_dd = system.f(x)[3:]
        seed_phi = (
            -0.5 * thd**2 * math.sin(2 * ph)
            + I_z / (2 * I_xy) * (thd**2 * math.sin(2 * ph) + 2 * psd * thd * c)
            + p * math.cos(th) * s / I_xy
        )
        # The line before the last, as a matrix product: right.
        matrix = np.array([[1.0, -I_z * s], [-s, I_xy * c**2 + I_z * s**2]])
        vector = np.array([-2 * I_c * thd * phd * s - I_z * psd * phd + p * math.sin(th), -thd * phd])
        seed_theta, seed_psi = matrix @ vector / (I_xy * c)
        # The last printed lines: theta_ddot right, psi_ddot the slip.
        seed_theta_last = (
            -I_z * thd * phd * s + 2 * I_xy * thd * phd * s - I_z * psd * phd + p * math.sin(th)
        ) / (I_xy * c)
        seed_psi_last = (
            I_z * thd * phd * s**2 - I_xy * thd * phd * s + I_z * psd * phd + p * math.sin(th)
        ) / (I_xy * c)
        assert phi_dd == pytest.approx(seed_phi, rel=1e-9)
        assert theta_dd == pytest.approx(seed_theta, rel=1e-9)
        assert theta_dd == pytest.approx(seed_theta_last, rel=1e-9)
        assert psi_dd == pytest.approx(seed_psi, rel=1e-9)
        wrong_seen += not math.isclose(psi_dd, seed_psi_last, rel_tol=1e-3)
    assert wrong_seen == 8


# -- steady precession ------------------------------------------------------------
def test_steady_precession_relation_derived_from_the_model_is_the_seeds() -> None:
    system, _ = _systems()
    relation = gt.steady_precession_relation(system.symbolic)
    theta, phi_dot, psi_dot = sp.symbols("theta phi_dot psi_dot", real=True)
    m, R, I_t, I_s, g = sp.symbols("m R I_t I_s g", real=True)
    I_c, I_z, p = I_s - (I_t + m * R**2), I_s, m * g * R
    seed = I_c * phi_dot**2 * sp.cos(theta) + I_z * psi_dot * phi_dot - p
    assert sp.expand(relation - seed) == 0


@pytest.mark.parametrize(("theta", "psi_dot"), [(0.8, 250.0), (1.3, 400.0), (2.2, 150.0)])
def test_steady_precession_keeps_the_nutation_angle(theta: float, psi_dot: float) -> None:
    system, _ = _systems()
    slow, fast = gt.steady_precession_rates(system, theta, psi_dot)
    assert abs(slow) < abs(fast)
    for rate in (slow, fast):
        x0 = np.array([0.0, theta, 0.0, rate, 0.0, psi_dot])
        assert abs(system.f(x0)[4]) < 1e-9 * (1 + abs(rate) * psi_dot)
        _, xs = _simulate(system, x0, 1.0, n=200)
        assert np.ptp(xs[:, 1]) < 1e-7, f"theta moved by {np.ptp(xs[:, 1]):.3g} at phi_dot = {rate:g}"
        assert np.allclose(xs[:, 3], rate, rtol=1e-7)
    # The test can fail: 2 % off the slow rate, the top nods.
    x_off = np.array([0.0, theta, 0.0, 1.02 * slow, 0.0, psi_dot])
    _, xs = _simulate(system, x_off, 1.0, n=200)
    assert np.ptp(xs[:, 1]) > 1e-5


def test_slow_precession_of_a_fast_top_is_the_textbook_rate() -> None:
    # Gyroscopic approximation: Omega = m g R / (I_s omega_spin) for a fast top.
    system, _ = _systems()
    _, I_s, p = _inertias(system)
    spin = 3000.0
    slow, fast = gt.steady_precession_rates(system, 1.0, spin)
    assert slow == pytest.approx(p / (I_s * spin), rel=1e-3)
    assert abs(fast) > 100 * abs(slow)


def test_no_steady_precession_without_enough_spin() -> None:
    system, _ = _systems()
    # The default wheel has I_c < 0: above horizontal it needs spin to precess.
    with pytest.raises(gt.NoSteadyPrecessionError, match="no real root"):
        gt.steady_precession_rates(system, 0.5, 10.0)
    with pytest.raises(SingularConfigurationError, match="vertical"):
        gt.steady_precession_rates(system, 0.0, 300.0)
    # Below horizontal (hanging) a spinless top precesses as a conical pendulum.
    slow, fast = gt.steady_precession_rates(system, 2.5, 0.0)
    I_xy, I_s, p = _inertias(system)
    expected = math.sqrt(p / ((I_xy - I_s) * -math.cos(2.5)))
    assert sorted([abs(slow), abs(fast)]) == pytest.approx([expected, expected])


# -- the two parameterizations ----------------------------------------------------
def test_spin_axis_matches_scipy() -> None:
    rng = np.random.default_rng(4)
    for euler, seq in (("zxz", "ZXZ"), ("xyz", "XYZ")):
        angles = rng.uniform(-3, 3, (6, 3))
        expected = Rotation.from_euler(seq, angles).as_matrix()[:, :, 2]
        assert np.allclose(gt.spin_axis(euler, angles), expected, atol=1e-14)


def test_conversion_keeps_orientation_and_angular_velocity() -> None:
    rng = np.random.default_rng(9)
    for _ in range(10):
        x = np.concatenate([rng.uniform(-3, 3, 3), rng.uniform(-5, 5, 3)])
        x[1] = rng.uniform(0.2, 1.3)
        y = gt.zxz_to_xyz(x)
        R_zxz = Rotation.from_euler("ZXZ", x[:3]).as_matrix()
        R_xyz = Rotation.from_euler("XYZ", y[:3]).as_matrix()
        assert np.allclose(R_zxz, R_xyz, atol=1e-12)
        w_zxz = rotations.angular_velocity("zxz", x[:3], x[3:])
        w_xyz = rotations.angular_velocity("xyz", y[:3], y[3:])
        assert np.allclose(w_zxz, w_xyz, atol=1e-12)
        back = gt.xyz_to_zxz(y)
        assert np.allclose(Rotation.from_euler("ZXZ", back[:3]).as_matrix(), R_zxz, atol=1e-12)
        assert np.allclose(rotations.angular_velocity("zxz", back[:3], back[3:]), w_zxz, atol=1e-12)


def test_both_parameterizations_move_the_axis_identically() -> None:
    zxz, xyz = _systems()
    y0 = gt.zxz_to_xyz(X0_ZXZ)
    # Same physical state: the same energy and momenta.
    assert xyz.energy(y0) == pytest.approx(zxz.energy(X0_ZXZ), rel=1e-12)
    assert xyz.conserved(y0)["p_psi"] == pytest.approx(zxz.conserved(X0_ZXZ)["p_psi"], rel=1e-12)
    assert xyz.conserved(y0)["L_vertical"] == pytest.approx(zxz.conserved(X0_ZXZ)["p_phi"], rel=1e-12)
    t, xs = _simulate(zxz, X0_ZXZ, 1.5)
    _, ys = _simulate(xyz, y0, 1.5)
    axis_zxz, axis_xyz = gt.spin_axis("zxz", xs), gt.spin_axis("xyz", ys)
    assert np.ptp(axis_zxz[:, 0]) > 0.1  # the axis goes somewhere
    assert np.abs(axis_zxz - axis_xyz).max() < 1e-7
    # The whole body, not only its axis, turns the same way.
    R_zxz = Rotation.from_euler("ZXZ", xs[:, :3]).as_matrix()
    R_xyz = Rotation.from_euler("XYZ", ys[:, :3]).as_matrix()
    assert np.abs(R_zxz - R_xyz).max() < 1e-6
    assert t[-1] == 1.5


# -- singularities, operating point, linearization --------------------------------
def test_zxz_is_singular_at_the_upright() -> None:
    system = get_system("gyroscope")
    with pytest.raises(SingularConfigurationError, match=r"sin\(theta\) = 0"):
        system.f([0.0, 0.0, 0.0, 0.0, 0.0, 100.0])
    with pytest.raises(SingularConfigurationError, match=r"sin\(theta\) = 0"):
        system.f([0.2, math.pi, 0.0, 1.0, 0.0, 0.0])
    assert np.all(np.isfinite(system.f([0.0, 0.1, 0.0, 0.0, 0.0, 100.0])))


def test_xyz_is_singular_with_the_axis_along_x_but_not_upright() -> None:
    system = get_system("gyroscope", euler="xyz")
    with pytest.raises(SingularConfigurationError, match=r"cos\(phi\) = 0"):
        system.f([0.3, math.pi / 2, 0.0, 0.0, 0.0, 10.0])
    assert np.all(system.f(np.zeros(6)) == 0.0)


def test_xyz_upright_linearization_is_a_compound_pendulum() -> None:
    system = get_system("gyroscope", euler="xyz")
    lm = system.linearize()
    assert lm.residual == 0.0
    assert lm.B.shape == (6, 0)
    I_xy, _, p = _inertias(system)
    rate = math.sqrt(p / I_xy)  # inverted compound pendulum about the fixed point
    ev = np.sort_complex(np.linalg.eigvals(lm.A))
    expected = np.sort_complex(np.array([-rate, -rate, 0, 0, rate, rate], dtype=complex))
    assert np.allclose(ev, expected, atol=1e-6 * rate)


@pytest.mark.parametrize(("factor", "stable"), [(1.05, True), (0.95, False)])
def test_sleeping_top_is_stable_above_the_maxwell_klein_spin(factor: float, stable: bool) -> None:
    # Upright spinning top: stable iff I_s^2 omega^2 > 4 (I_t + m R^2) m g R.
    system = get_system("gyroscope", euler="xyz")
    I_xy, I_s, p = _inertias(system)
    spin = factor * 2 * math.sqrt(I_xy * p) / I_s
    x0 = np.array([0, 0, 0, 0, 0, spin], dtype=float)
    # A relative equilibrium: only the cyclic spin angle moves.
    assert np.allclose(system.f(x0), [0, 0, spin, 0, 0, 0], atol=1e-12 * spin)
    lm = system.linearize(x0, None)
    growth = np.linalg.eigvals(lm.A).real.max()
    if stable:
        assert growth < 1e-9 * spin
    else:
        assert growth > 1e-3 * math.sqrt(p / I_xy)


def test_zxz_has_no_canonical_operating_point_but_linearizes_at_a_given_one() -> None:
    system = get_system("gyroscope")
    slow, _ = gt.steady_precession_rates(system, 1.0, 300.0)
    x0 = np.array([0.0, 1.0, 0.0, slow, 0.0, 300.0])
    # Steady precession is a relative equilibrium: only phi and psi move.
    assert np.allclose(system.f(x0), [slow, 0, 300.0, 0, 0, 0], atol=1e-9)
    lm = system.linearize(x0, None)
    assert np.allclose(lm.A[:3, 3:], np.eye(3))
    # phi and psi are cyclic: the dynamics do not depend on them.
    assert np.allclose(lm.A[3:, [0, 2]], 0.0)


def test_region_means_axis_above_horizontal() -> None:
    _, xyz = _systems()
    region = xyz.spec.region
    rng = np.random.default_rng(8)
    for _ in range(200):
        angles = rng.uniform(-math.pi, math.pi, 3)
        angles[1] = rng.uniform(-math.pi / 2, math.pi / 2)  # phi's principal range
        inside = all(lo < angles[i] < hi for i, (lo, hi) in
                     ((0, region["theta"]), (1, region["phi"])))
        assert inside == (gt.spin_axis("xyz", angles)[2] > 0)


def test_steady_precession_refuses_other_systems() -> None:
    with pytest.raises(UnknownNameError, match="gyroscope"):
        gt.steady_precession_rates(get_system("cartpole"), 1.0, 100.0)
