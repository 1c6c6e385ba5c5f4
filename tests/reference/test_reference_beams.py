"""Reference tests of the seesaw, the ball and beam (torque and servo) and the CMG robot.

The truths are independent of the code under test: the seeds' formulas where
SYSTEMS.md says they are right (typed here from the seeds, with the listed
slips corrected), hand derivations written out below, a second derivation
route (the exact ball-and-beam equation reduced by hand to the servo model),
conservation of the Jacobi integral along an accurate trajectory, and the
power balance of friction and input.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp

from equilibrist.numeric.lookup import get_system
from equilibrist.numeric.system import System

RNG_SEEDS = range(8)


def _random(rng: np.random.Generator, ranges: dict[str, tuple[float, float]]) -> dict[str, float]:
    return {k: float(rng.uniform(lo, hi)) for k, (lo, hi) in ranges.items()}


def _energy_rate(system: System, x: np.ndarray, u: np.ndarray) -> float:
    """d/dt of the model's energy along f: sympy's gradient of the energy, dotted with f.

    A finite difference would lose the digits this needs: the CMG robot's
    energy holds a large constant spin term.
    """
    model = system.symbolic
    grad = sp.Matrix([model.energy]).jacobian(sp.Matrix(model.states))
    gradient = sp.lambdify((model.states, model.params), list(grad), "math")
    return float(np.asarray(gradient(x, system.p)) @ system.f(x, u))


# --------------------------------------------------------------------------
# seesaw (seeds/000)

SEESAW_RANGES = {
    "L": (0.2, 1.5),
    "m_b": (0.05, 1.0),
    "m1": (0.0, 0.5),
    "m2": (0.0, 0.5),
    "b": (0.0, 0.05),
    "mu_c": (0.0, 0.05),
    "eps": (0.01, 0.5),
    "g": (1.0, 20.0),
}


def _seesaw_constants(p: dict[str, float]) -> tuple[float, float, float, float]:
    """Seed 000's alpha, beta, gamma, delta, with beta's N corrected (SYSTEMS.md)."""
    L = p["L"]
    inertia = p["m_b"] * L**2 / 12 + (p["m1"] + p["m2"]) * L**2 / 4
    normal = (p["m_b"] + p["m1"] + p["m2"]) * p["g"]
    alpha = p["b"] / inertia
    beta = p["mu_c"] * normal * L / (2 * inertia)
    gamma = (p["m1"] - p["m2"]) * p["g"] * L / (2 * inertia)
    delta = L / (2 * inertia)
    return alpha, beta, gamma, delta


@pytest.mark.parametrize("seed", RNG_SEEDS)
def test_seesaw_matches_seed_form(seed: int) -> None:
    rng = np.random.default_rng(seed)
    params = _random(rng, SEESAW_RANGES)
    system = get_system("seesaw", **params)
    alpha, beta, gamma, delta = _seesaw_constants(params)
    for _ in range(5):
        theta, theta_dot = rng.uniform(-1.5, 1.5), rng.uniform(-2.0, 2.0)
        force = rng.uniform(0.0, 5.0)
        xdot = system.f([theta, theta_dot], [force])
        expected = (
            -alpha * theta_dot
            - beta * math.tanh(theta_dot / params["eps"])
            + gamma * math.cos(theta)
            + delta * force
        )
        assert xdot[0] == pytest.approx(theta_dot, rel=1e-12)
        assert xdot[1] == pytest.approx(expected, rel=1e-10, abs=1e-12)


@pytest.mark.parametrize("theta_e", [-0.4, 0.0, 0.3, 1.0])
def test_seesaw_equilibrium_thrust(theta_e: float) -> None:
    params = {"m1": 0.05, "m2": 0.2, "b": 0.01, "mu_c": 0.01}
    system = get_system("seesaw", **params)
    _, _, gamma, delta = _seesaw_constants({**{p.name: p.default for p in system.spec.parameters},
                                            **params})
    eq = system.equilibrium(state={"theta": theta_e}, free=("F",))
    force = eq.input("F")
    assert eq.residual < 1e-10
    # Seed 000 corrected: cos(theta_e) = -delta F_e / gamma.
    assert math.cos(theta_e) == pytest.approx(-delta * force / gamma, rel=1e-10)
    # The seed's printed acos(delta F_e / gamma) has the wrong sign: F_e > 0 here.
    assert force > 0
    # Seed 000's Jacobians at the equilibrium (x2e = 0, sech^2(0) = 1).
    alpha, beta, _, _ = _seesaw_constants(dict(system.params))
    lm = system.linearize(eq.x, eq.u)
    A_seed = [[0.0, 1.0], [-gamma * math.sin(theta_e), -alpha - beta / system.params["eps"]]]
    np.testing.assert_allclose(lm.A, A_seed, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(lm.B, [[0.0], [delta]], rtol=1e-12)


def test_seesaw_canonical_point_is_level_with_weight_difference_thrust() -> None:
    system = get_system("seesaw")
    eq = system.operating_point()
    p = system.params
    assert eq.state("theta") == 0.0
    assert eq.input("F") == pytest.approx((p["m2"] - p["m1"]) * p["g"], rel=1e-12)
    low, high = system.input_limits
    assert low[0] == 0.0  # a propeller does not reverse
    assert low[0] <= eq.input("F") <= high[0]


def test_seesaw_signs() -> None:
    # Positive theta raises the right end: with only m2, the potential energy
    # grows by m2 g L/2 sin(theta).
    system = get_system("seesaw", m1=0.0, m2=0.3)
    p = system.params
    lift = system.energy([0.2, 0.0]) - system.energy([0.0, 0.0])
    assert lift == pytest.approx(p["m2"] * p["g"] * p["L"] / 2 * math.sin(0.2), rel=1e-12)
    f_e = system.operating_point().input("F")
    # More thrust than the balance raises the right end; none lets it fall.
    assert system.f([0.0, 0.0], [f_e + 0.5])[1] > 0
    assert system.f([0.0, 0.0], [0.0])[1] < 0
    # Both frictions oppose the motion.
    assert system.f([0.0, 1.0], [f_e])[1] < 0
    assert system.f([0.0, -1.0], [f_e])[1] > 0


# --------------------------------------------------------------------------
# ball and beam (seeds/002, "Ball rolling on a rotated linear slide")

BALL_RANGES = {
    "m": (0.02, 0.5),
    "r": (0.005, 0.04),
    "I": (0.001, 0.05),
    "d": (-0.03, 0.05),
    "b": (0.0, 0.1),
    "g": (1.0, 20.0),
}
# Seed order [R, R_dot, theta, theta_dot] -> model order [theta, R, theta_dot, R_dot].
SEED_TO_MODEL = [1, 3, 0, 2]


def _to_model_order(A_seed: np.ndarray, B_seed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = len(SEED_TO_MODEL)
    P = np.zeros((n, n))
    for i_seed, i_model in enumerate(SEED_TO_MODEL):
        P[i_model, i_seed] = 1.0
    return P @ A_seed @ P.T, P @ B_seed


def _offset_section_linearization(p: dict[str, float], R_d: float) -> tuple[np.ndarray, np.ndarray]:
    """The seed's offset-section linearization, ``R_d = 0`` form, in seed order.

    For ``R_d != 0`` the correct form (hand derivation: the mass matrix only
    multiplies accelerations, zero at the equilibrium, and the forcing's
    ``tau/m - g R`` vanishes there) is the same with ``R_d^2`` added to the
    effective inertia ``J``; the seed's extra H21, H41 terms are spurious.
    """
    m, r, inertia, d, b, g = (p[k] for k in ("m", "r", "I", "d", "b", "g"))
    k = d + 2 / 5 * r
    J = R_d**2 + d**2 + inertia / m + 2 / 5 * r**2
    det = k**2 - 7 / 5 * J
    A = np.zeros((4, 4))
    A[0, 1] = A[2, 3] = 1.0
    A[1] = [g * k / det, b / m * J / det, g * (J - k * d) / det, 0.0]
    A[3] = [7 / 5 * g / det, b / m * k / det, g * (k - 7 / 5 * d) / det, 0.0]
    B = -1 / (m * det) * np.array([[0.0], [k], [0.0], [7 / 5]])
    return A, B


@pytest.mark.parametrize("seed", RNG_SEEDS)
def test_ball_beam_matches_seed_offset_equations(seed: int) -> None:
    # The offset section's 2x2 system (right in the seed), solved at random points.
    rng = np.random.default_rng(seed)
    p = _random(rng, BALL_RANGES)
    system = get_system("ball_beam", **p)
    m, r, inertia, d, b, g = (p[k] for k in ("m", "r", "I", "d", "b", "g"))
    for _ in range(5):
        theta, R, theta_dot, R_dot = rng.uniform(-0.6, 0.6, 4)
        tau = rng.uniform(-1.0, 1.0)
        k = d + 2 / 5 * r
        lhs = np.array([[k, -(R**2 + d**2 + inertia / m + 2 / 5 * r**2)], [-7 / 5, k]])
        rhs = np.array([
            2 * R * R_dot * theta_dot + g * R * math.cos(theta) - g * d * math.sin(theta) - tau / m,
            -R * theta_dot**2 + b / m * R_dot + g * math.sin(theta),
        ])
        R_ddot, theta_ddot = np.linalg.solve(lhs, rhs)
        xdot = system.f([theta, R, theta_dot, R_dot], [tau])
        np.testing.assert_allclose(xdot, [theta_dot, R_dot, theta_ddot, R_ddot], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("d", [0.0, 0.02, -0.01])
@pytest.mark.parametrize("R_d", [0.0, 0.12, -0.2])
def test_ball_beam_equilibrium_torque(d: float, R_d: float) -> None:
    system = get_system("ball_beam", d=d, R_d=R_d, m=0.1, g=9.8)
    eq = system.operating_point()
    assert eq.residual < 1e-10
    assert eq.state("R") == R_d and eq.state("theta") == 0.0
    # Hand derivation: on a level beam the ball rests with its contact point
    # straight below its centre, at distance R_d from the pivot along the
    # beam, whatever d; the beam carries the weight m g there: tau = m g R_d.
    assert eq.input("tau") == pytest.approx(0.1 * 9.8 * R_d, rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("seed", RNG_SEEDS)
def test_ball_beam_seed_linearization_R_d_zero(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    p = _random(rng, BALL_RANGES)
    system = get_system("ball_beam", **p)
    lm = system.linearize()
    A, B = _to_model_order(*_offset_section_linearization(p, 0.0))
    np.testing.assert_allclose(lm.A, A, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(lm.B, B, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("seed", RNG_SEEDS)
def test_ball_beam_linearization_R_d_nonzero_has_no_spurious_terms(seed: int) -> None:
    rng = np.random.default_rng(200 + seed)
    p = _random(rng, BALL_RANGES)
    R_d = float(rng.uniform(0.05, 0.3))
    lm = get_system("ball_beam", R_d=R_d, **p).linearize()
    A, B = _to_model_order(*_offset_section_linearization(p, R_d))
    np.testing.assert_allclose(lm.A, A, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(lm.B, B, rtol=1e-9, atol=1e-12)
    # The seed's H21 = (14/5) g (d + 2/5 r) R_d^2 / det, added to A21 and divided
    # by det again, is not zero: the model must not carry it.
    m, r, inertia, d, g = (p[k] for k in ("m", "r", "I", "d", "g"))
    det = (d + 2 / 5 * r) ** 2 - 7 / 5 * (R_d**2 + d**2 + inertia / m + 2 / 5 * r**2)
    h21 = 14 / 5 * g * (d + 2 / 5 * r) * R_d**2 / det
    seed_a21 = (h21 + g * (d + 2 / 5 * r)) / det
    if abs(h21) > 1e-6:
        assert lm.A[3, 1] != pytest.approx(seed_a21, rel=1e-6)


@pytest.mark.parametrize("R_d", [0.0, 0.1, -0.15])
def test_ball_beam_without_offset_section_in_the_small_ball_limit(R_d: float) -> None:
    # The seed's section without offset takes the spin as R_dot / r, which
    # drops the 2/5 r coupling; for a vanishing radius the exact model must
    # agree with that section's linearization at R_d.
    m, inertia, b, g = 0.08, 0.01, 0.03, 9.81
    lm = get_system("ball_beam", m=m, r=1e-9, I=inertia, b=b, g=g, d=0.0, R_d=R_d).linearize()
    assert lm.u0[0] == pytest.approx(m * g * R_d, abs=1e-15)  # the seed's u_d = m g R
    A_seed = np.array([
        [0, 1, 0, 0],
        [0, 0, -m * g / (m * R_d**2 + inertia), 0],
        [0, 0, 0, 1],
        [-5 / 7 * g, 0, 0, -5 / 7 * b / m],
    ])
    B_seed = np.array([[0], [1 / (m * R_d**2 + inertia)], [0], [0]])
    # Seed order [theta, theta_dot, R, R_dot] -> model order [theta, R, theta_dot, R_dot].
    order = [0, 2, 1, 3]
    # The exact model's spin coupling leaves entries of order 20 r.
    np.testing.assert_allclose(lm.A, A_seed[np.ix_(order, order)], rtol=1e-7, atol=1e-6)
    np.testing.assert_allclose(lm.B, B_seed[order], rtol=1e-7, atol=1e-6)


def test_ball_beam_large_inertia_limit_is_five_sevenths() -> None:
    # The seed's large-I reductions print -25/49 g and -25/49 b/m; the limit
    # of its own (right) R_d = 0 form is -5/7 g, -5/7 b/m: a very heavy beam.
    g, m, b = 9.81, 0.064, 0.02
    lm = get_system("ball_beam", I=1e7, m=m, b=b, g=g, d=0.01).linearize()
    i_th, i_rd = 0, 3
    assert lm.A[i_rd, i_th] == pytest.approx(-5 / 7 * g, rel=1e-6)
    assert lm.A[i_rd, i_rd] == pytest.approx(-5 / 7 * b / m, rel=1e-6)


def test_ball_beam_signs() -> None:
    system = get_system("ball_beam")
    p = system.params
    # A beam tilted counter-clockwise lets a ball at rest roll towards -R,
    # whether it is at the pivot or out on the beam (no torque, or the holding one).
    assert system.f([0.1, 0.0, 0.0, 0.0], [0.0])[3] < 0
    tau_hold = p["m"] * p["g"] * 0.1 * math.cos(0.1)
    assert system.f([0.1, 0.1, 0.0, 0.0], [tau_hold])[3] < 0
    # A counter-clockwise torque turns the beam counter-clockwise.
    assert system.f([0.0, 0.0, 0.0, 0.0], [0.1])[2] > 0
    # Counter-clockwise tilt lifts a ball at R > 0 by R sin(theta).
    rise = system.energy([0.2, 0.1, 0.0, 0.0]) - system.energy([0.0, 0.1, 0.0, 0.0])
    assert rise == pytest.approx(p["m"] * p["g"] * 0.1 * math.sin(0.2), rel=1e-12)
    # Friction opposes the ball's motion relative to the beam.
    assert system.f([0.0, 0.0, 0.0, 0.5], [0.0])[3] < 0


# --------------------------------------------------------------------------
# ball and beam on a servo (seeds/002, reduced three-state model)


@pytest.mark.parametrize("seed", RNG_SEEDS)
def test_servo_matches_seed_formula(seed: int) -> None:
    rng = np.random.default_rng(300 + seed)
    p = {"m": rng.uniform(0.02, 0.5), "b": rng.uniform(0.0, 0.1), "g": rng.uniform(1.0, 20.0)}
    system = get_system("ball_beam_servo", **p)
    for _ in range(5):
        theta, R, R_dot = rng.uniform(-0.6, 0.6, 3)
        omega = rng.uniform(-3.0, 3.0)
        xdot = system.f([theta, R, R_dot], [omega])
        R_ddot = 5 / 7 * (R * omega**2 - p["g"] * math.sin(theta) - p["b"] / p["m"] * R_dot)
        np.testing.assert_allclose(xdot, [omega, R_dot, R_ddot], rtol=1e-10, atol=1e-13)


@pytest.mark.parametrize("seed", RNG_SEEDS)
def test_servo_is_the_exact_ball_equation_with_constant_rate(seed: int) -> None:
    # Second route: the exact ball-and-beam model's R row, M_R . q_ddot = F_R,
    # with theta_ddot = 0 and d = 0, gives R_ddot = F_R / M_RR. F is recovered
    # from the exact model as M q_ddot.
    rng = np.random.default_rng(400 + seed)
    p = {"m": rng.uniform(0.02, 0.5), "b": rng.uniform(0.0, 0.1), "g": rng.uniform(1.0, 20.0)}
    exact = get_system("ball_beam", r=rng.uniform(0.005, 0.04), I=rng.uniform(0.001, 0.05),
                       d=0.0, **p)
    servo = get_system("ball_beam_servo", **p)
    for _ in range(5):
        theta, R, R_dot = rng.uniform(-0.6, 0.6, 3)
        omega = rng.uniform(-3.0, 3.0)
        x = np.array([theta, R, omega, R_dot])
        xdot = exact.f(x, [rng.uniform(-1.0, 1.0)])
        mass = np.empty((2, 2))
        exact.functions.mass_matrix(x, exact.p, mass)
        forcing = mass @ xdot[2:]
        assert servo.f([theta, R, R_dot], [omega])[2] == pytest.approx(
            forcing[1] / mass[1, 1], rel=1e-9, abs=1e-12
        )


def test_servo_linearization_matches_seed() -> None:
    g, m, b = 9.81, 0.05, 0.02
    lm = get_system("ball_beam_servo", g=g, m=m, b=b, R_d=0.1).linearize()
    A_seed = np.array([[0, 0, 0], [0, 0, 1], [-5 / 7 * g, 0, -5 / 7 * b / m]])
    np.testing.assert_allclose(lm.x0, [0.0, 0.1, 0.0])
    np.testing.assert_allclose(lm.A, A_seed, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(lm.B, [[1.0], [0.0], [0.0]], atol=1e-14)
    assert lm.state_names == ("theta", "R", "R_dot")
    assert lm.state_units == ("rad", "m", "m/s")


def test_servo_signs() -> None:
    servo = get_system("ball_beam_servo")
    assert servo.f([0.0, 0.0, 0.0], [0.5])[0] > 0  # omega turns the beam counter-clockwise
    assert servo.f([0.1, 0.0, 0.0], [0.0])[2] < 0  # counter-clockwise tilt: ball towards -R
    assert servo.functions.N_Q == 0  # a first-order model, no mass matrix


# --------------------------------------------------------------------------
# CMG robot (seeds/002, "Control moment gyroscope")

CMG_RANGES = {
    "I_xy": (5e-5, 1e-3),
    "I_z": (1e-4, 2e-3),
    "m_body": (0.3, 3.0),
    "h_body": (0.03, 0.3),
    "m_wheel": (0.1, 1.0),
    "h_wheel": (0.05, 0.3),
    "I_body": (0.0, 0.02),
    "Omega": (-600.0, 600.0),
    "B_w": (0.0, 1e-2),
    "g": (1.0, 20.0),
}


def _cmg_inertia_and_load(p: dict[str, float]) -> tuple[float, float]:
    """SYSTEMS.md's I_b and p."""
    I_b = 2 * p["m_wheel"] * p["h_wheel"] ** 2 + p["m_body"] * p["h_body"] ** 2 + p["I_body"]
    load = p["g"] * (2 * p["m_wheel"] * p["h_wheel"] + p["m_body"] * p["h_body"])
    return I_b, load


@pytest.mark.parametrize("seed", RNG_SEEDS)
def test_cmg_seed_linearization(seed: int) -> None:
    rng = np.random.default_rng(500 + seed)
    p = _random(rng, CMG_RANGES)
    if seed == 0:
        p["I_body"] = 0.0  # the seed's I_b exactly
    lm = get_system("cmg_robot", **p).linearize()
    I_b, load = _cmg_inertia_and_load(p)
    I_xy, I_z, Omega = p["I_xy"], p["I_z"], p["Omega"]
    # Seed order [theta, theta_dot, phi, phi_dot].
    A_seed = np.array([
        [0, 1, 0, 0],
        [load / (2 * I_xy + I_b), 0, 0, -2 * I_z * Omega / (2 * I_xy + I_b)],
        [0, 0, 0, 1],
        [0, I_z * Omega / I_xy, 0, -p["B_w"] / (2 * I_xy)],
    ])
    B_seed = np.array([[0], [0], [0], [1 / (2 * I_xy)]])
    order = [0, 2, 1, 3]  # -> [theta, phi, theta_dot, phi_dot]
    np.testing.assert_allclose(lm.A, A_seed[np.ix_(order, order)], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(lm.B, B_seed[order], rtol=1e-12)
    assert lm.state_names == ("theta", "phi", "theta_dot", "phi_dot")


def _cmg_hand_energies(p: dict[str, float], x: np.ndarray) -> tuple[float, float]:
    """(Jacobi integral, total energy) from the seed's Lagrangian, by hand.

    T = I_xy (th_d^2 cos^2 phi + phi_d^2) + I_z (th_d sin phi + Omega)^2 + I_b th_d^2 / 2,
    V = p cos(theta); T2 - T0 + V drops the linear term and flips the spin energy.
    """
    theta, phi, th_d, ph_d = x
    I_b, load = _cmg_inertia_and_load(p)
    I_xy, I_z, Omega = p["I_xy"], p["I_z"], p["Omega"]
    t2 = I_xy * (th_d**2 * math.cos(phi) ** 2 + ph_d**2) + I_z * th_d**2 * math.sin(phi) ** 2
    t2 += I_b * th_d**2 / 2
    t1 = 2 * I_z * Omega * th_d * math.sin(phi)
    t0 = I_z * Omega**2
    v = load * math.cos(theta)
    return t2 - t0 + v, t2 + t1 + t0 + v


@pytest.mark.parametrize("seed", RNG_SEEDS)
def test_cmg_energy_is_the_jacobi_integral(seed: int) -> None:
    rng = np.random.default_rng(600 + seed)
    p = _random(rng, CMG_RANGES)
    system = get_system("cmg_robot", **p)
    for _ in range(5):
        x = rng.uniform(-1.0, 1.0, 4)
        jacobi, _ = _cmg_hand_energies(p, x)
        assert system.energy(x) == pytest.approx(jacobi, rel=1e-10, abs=1e-12)


def test_cmg_jacobi_integral_conserved_along_trajectory() -> None:
    system = get_system("cmg_robot", B_w=0.0)
    params = dict(system.params)
    fn, pv = system.functions.f, system.p
    u = np.zeros(1)
    buf = np.empty(4)

    def rhs(_t: float, x: np.ndarray) -> np.ndarray:
        fn(x, u, pv, buf)
        return buf.copy()

    x0 = np.array([0.05, 0.3, -0.2, 1.5])
    sol = solve_ivp(rhs, (0.0, 0.6), x0, method="DOP853", rtol=1e-10, atol=1e-12)
    assert sol.success
    # The body swings through a large motion (the gyroscope fights the fall).
    assert np.ptp(sol.y[1]) > 0.3
    jacobi = np.array([system.energy(x) for x in sol.y.T])
    total = np.array([_cmg_hand_energies(params, x)[1] for x in sol.y.T])
    scale = abs(jacobi[0])
    assert np.ptp(jacobi) / scale < 1e-8
    # The total energy is not conserved: the flywheel motors do work.
    assert np.ptp(total) / scale > 1e-4


def test_cmg_signs() -> None:
    system = get_system("cmg_robot")
    # Upright is the top of the potential: a leaning body falls further.
    assert system.energy([0.3, 0.0, 0.0, 0.0]) < system.energy([0.0, 0.0, 0.0, 0.0])
    assert system.f([0.1, 0.0, 0.0, 0.0], [0.0])[2] > 0
    # A positive gimbal torque turns the gimbal positive.
    assert system.f([0.0, 0.0, 0.0, 0.0], [0.1])[3] > 0
    # Gimbal friction opposes the gimbal's motion (no spin coupling at theta_dot = 0, phi = 0
    # comes into phi_ddot).
    assert system.f([0.0, 0.0, 0.0, 1.0], [0.0])[3] < 0


# --------------------------------------------------------------------------
# power balance with friction (action and reaction signs)


@pytest.mark.parametrize("seed", RNG_SEEDS)
def test_energy_rate_equals_friction_and_input_power(seed: int) -> None:
    rng = np.random.default_rng(700 + seed)

    seesaw_p = _random(rng, SEESAW_RANGES)
    seesaw = get_system("seesaw", **seesaw_p)
    ball_p = _random(rng, BALL_RANGES)
    ball = get_system("ball_beam", **ball_p)
    cmg_p = _random(rng, CMG_RANGES)
    cmg = get_system("cmg_robot", **cmg_p)

    for _ in range(5):
        theta, theta_dot = rng.uniform(-1.0, 1.0, 2)
        force = rng.uniform(0.0, 4.0)
        half = seesaw_p["L"] / 2
        normal = (seesaw_p["m_b"] + seesaw_p["m1"] + seesaw_p["m2"]) * seesaw_p["g"]
        torque = (
            half * force
            - seesaw_p["b"] * theta_dot
            - seesaw_p["mu_c"] * normal * half * math.tanh(theta_dot / seesaw_p["eps"])
        )
        x = np.array([theta, theta_dot])
        assert _energy_rate(seesaw, x, np.array([force])) == pytest.approx(
            theta_dot * torque, rel=1e-6, abs=1e-9
        )

        x = rng.uniform(-0.5, 0.5, 4)
        tau = rng.uniform(-1.0, 1.0)
        expected = tau * x[2] - ball_p["b"] * x[3] ** 2
        assert _energy_rate(ball, x, np.array([tau])) == pytest.approx(expected, rel=1e-6, abs=1e-9)

        x = rng.uniform(-0.8, 0.8, 4) * np.array([1, 1, 2, 5])
        tau = rng.uniform(-0.3, 0.3)
        expected = x[3] * (tau - cmg_p["B_w"] * x[3])
        assert _energy_rate(cmg, x, np.array([tau])) == pytest.approx(expected, rel=1e-6, abs=1e-8)
