"""Reference tests of the acrobot and the pendubot against independent truths.

- Gymnasium's ``AcrobotEnv._dsdt`` ("book" dynamics), the equations the
  catalogue's coordinates and defaults come from: the acrobot's derived
  ``f`` equals it to round-off at random states, torques and parameters;
- a second derivation route written here in numpy: the standard two-link
  manipulator ``M(q) q_ddot + C(q, q_dot) q_dot + G(q) = tau - friction``
  (Spong, Hutchinson and Vidyasagar, "Robot Modeling and Control", the
  two-link planar arm), with the motor at the elbow (acrobot) or at the
  shoulder (pendubot);
- the energy balance ``dE/dt = tau * (actuated joint's rate) - b1 theta1_dot^2
  - b2 theta2_dot^2``, which pins where the motor and each friction act;
- energy conservation along an accurate (DOP853) trajectory of a wide swing,
  without friction and input.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from equilibrist.numeric.lookup import get_system
from equilibrist.numeric.system import System

TWO_LINKS = ("acrobot", "pendubot")
# Which joint the motor drives (SYSTEMS.md): 1 the shoulder, 2 the elbow.
ACTUATED = {"acrobot": 1, "pendubot": 0}


def _draw(name: str, rng: np.random.Generator, *, friction: bool) -> System:
    """*name* with its physical parameters drawn at 0.5 to 2 times Gymnasium's
    defaults (frictions 0.05 to 0.5, or zero)."""
    values = {
        "l1": rng.uniform(0.5, 2.0), "lc1": rng.uniform(0.25, 1.0), "lc2": rng.uniform(0.25, 1.0),
        "m1": rng.uniform(0.5, 2.0), "m2": rng.uniform(0.5, 2.0),
        "I1": rng.uniform(0.5, 2.0), "I2": rng.uniform(0.5, 2.0),
        "b1": rng.uniform(0.05, 0.5) if friction else 0.0,
        "b2": rng.uniform(0.05, 0.5) if friction else 0.0,
        "g": rng.uniform(5.0, 15.0),
    }
    return get_system(name, **{k: float(v) for k, v in values.items()})


def _point(rng: np.random.Generator, limit: float) -> tuple[np.ndarray, float]:
    """Any configuration (angles over the whole turn), rates up to 6 rad/s, a torque within *limit*."""
    x = np.concatenate([rng.uniform(-math.pi, math.pi, 2), rng.uniform(-6.0, 6.0, 2)])
    return x, float(rng.uniform(-limit, limit))


# -- Gymnasium's Acrobot-v1 --------------------------------------------------------


def _gymnasium_acrobot():
    from gymnasium.envs.classic_control.acrobot import AcrobotEnv

    env = AcrobotEnv()
    assert env.book_or_nips == "book"
    return env


def test_acrobot_defaults_are_gymnasiums():
    env = _gymnasium_acrobot()
    p = get_system("acrobot").params
    assert p["l1"] == env.LINK_LENGTH_1 and p["l2"] == env.LINK_LENGTH_2
    assert p["lc1"] == env.LINK_COM_POS_1 and p["lc2"] == env.LINK_COM_POS_2
    assert p["m1"] == env.LINK_MASS_1 and p["m2"] == env.LINK_MASS_2
    assert p["I1"] == env.LINK_MOI and p["I2"] == env.LINK_MOI
    assert p["g"] == 9.8  # Gymnasium's _dsdt hard-codes g = 9.8
    assert p["b1"] == 0.0 and p["b2"] == 0.0


def test_acrobot_equals_gymnasium_book_dynamics_at_defaults():
    env = _gymnasium_acrobot()
    system = get_system("acrobot")
    rng = np.random.default_rng(11)
    for _ in range(200):
        x, tau = _point(rng, 20.0)
        theirs = np.asarray(env._dsdt(np.append(x, tau)), float)
        assert theirs[-1] == 0.0  # the torque's own derivative
        assert system.f(x, [tau]) == pytest.approx(theirs[:4], rel=1e-12, abs=1e-12)


def test_acrobot_equals_gymnasium_book_dynamics_with_other_parameters():
    """Gymnasium reads its parameters from the instance: drawn values (one
    inertia for both links, as its LINK_MOI; its g fixed at 9.8)."""
    env = _gymnasium_acrobot()
    rng = np.random.default_rng(12)
    for _ in range(20):
        l1, lc1, lc2 = rng.uniform(0.5, 2.0), rng.uniform(0.2, 1.0), rng.uniform(0.2, 1.0)
        m1, m2, moi = rng.uniform(0.5, 3.0), rng.uniform(0.5, 3.0), rng.uniform(0.1, 2.0)
        env.LINK_LENGTH_1, env.LINK_COM_POS_1, env.LINK_COM_POS_2 = l1, lc1, lc2
        env.LINK_MASS_1, env.LINK_MASS_2, env.LINK_MOI = m1, m2, moi
        system = get_system("acrobot", l1=l1, lc1=lc1, lc2=lc2, m1=m1, m2=m2, I1=moi, I2=moi)
        for _ in range(10):
            x, tau = _point(rng, 20.0)
            theirs = np.asarray(env._dsdt(np.append(x, tau)), float)[:4]
            assert system.f(x, [tau]) == pytest.approx(theirs, rel=1e-11, abs=1e-11)


def test_link_2_length_enters_the_drawing_only():
    x, u = np.array([2.0, -1.0, 0.7, 1.9]), np.array([3.0])
    for name in TWO_LINKS:
        assert get_system(name, l2=0.3).f(x, u) == pytest.approx(get_system(name).f(x, u), rel=0, abs=0)


# -- the textbook two-link manipulator ------------------------------------------------


def _manipulator_rates(p: dict, x: np.ndarray, tau_joints: np.ndarray) -> np.ndarray:
    """``q_ddot`` of the two-link arm in Spong's form, angles from hanging down.

    ``M = [[d11, d12], [d12, d22]]`` with ``d11 = m1 lc1^2 + m2 (l1^2 + lc2^2
    + 2 l1 lc2 cos q2) + I1 + I2``, ``d12 = m2 (lc2^2 + l1 lc2 cos q2) + I2``,
    ``d22 = m2 lc2^2 + I2``; ``h = -m2 l1 lc2 sin q2``, ``C = [[h q2', h (q1' +
    q2')], [-h q1', 0]]``; with the angles measured from hanging down the
    potential is ``-(m1 lc1 + m2 l1) g cos q1 - m2 lc2 g cos(q1 + q2)``.
    """
    q1, q2, w1, w2 = x
    m1, m2, l1, lc1, lc2 = p["m1"], p["m2"], p["l1"], p["lc1"], p["lc2"]
    I1, I2, g = p["I1"], p["I2"], p["g"]
    d11 = m1 * lc1**2 + m2 * (l1**2 + lc2**2 + 2 * l1 * lc2 * math.cos(q2)) + I1 + I2
    d12 = m2 * (lc2**2 + l1 * lc2 * math.cos(q2)) + I2
    d22 = m2 * lc2**2 + I2
    h = -m2 * l1 * lc2 * math.sin(q2)
    M = np.array([[d11, d12], [d12, d22]])
    C = np.array([[h * w2, h * (w1 + w2)], [-h * w1, 0.0]])
    G = np.array([
        (m1 * lc1 + m2 * l1) * g * math.sin(q1) + m2 * lc2 * g * math.sin(q1 + q2),
        m2 * lc2 * g * math.sin(q1 + q2),
    ])
    friction = np.array([p["b1"] * w1, p["b2"] * w2])
    return np.linalg.solve(M, tau_joints - C @ np.array([w1, w2]) - G - friction)


@pytest.mark.parametrize("name", TWO_LINKS)
def test_two_links_equal_the_textbook_manipulator_with_friction(name):
    rng = np.random.default_rng(21 + ACTUATED[name])
    for _ in range(30):
        system = _draw(name, rng, friction=True)
        for _ in range(5):
            x, tau = _point(rng, float(system.input_limits[1][0]))
            joints = np.zeros(2)
            joints[ACTUATED[name]] = tau
            expected = _manipulator_rates(dict(system.params), x, joints)
            xdot = system.f(x, [tau])
            assert xdot[:2] == pytest.approx(x[2:], rel=0, abs=0)
            assert xdot[2:] == pytest.approx(expected, rel=1e-10, abs=1e-10)


# -- conventions and energy ------------------------------------------------------------


@pytest.mark.parametrize("name", TWO_LINKS)
def test_upright_is_the_operating_point_and_hanging_is_stable(name):
    system = get_system(name)
    eq = system.operating_point()
    assert eq.x == pytest.approx([math.pi, 0.0, 0.0, 0.0], abs=1e-12)
    assert eq.u == pytest.approx([0.0], abs=1e-12)
    # Counter-clockwise from hanging down: link 1 pushed to +theta1 from
    # hanging swings back (restoring), from upright it falls on.
    assert system.f([0.3, 0.0, 0.0, 0.0], [0.0])[2] < 0
    assert system.f([math.pi + 0.1, 0.0, 0.0, 0.0], [0.0])[2] > 0
    upright = np.linalg.eigvals(system.linearize().A).real
    hanging = np.linalg.eigvals(system.linearize(np.zeros(4), np.zeros(1)).A).real
    assert upright.max() > 1.0 and abs(hanging).max() < 1e-9  # a saddle up, a centre down


def test_torque_limits_are_systems_md():
    low, high = get_system("acrobot").input_limits
    assert (low[0], high[0]) == (-20.0, 20.0)
    low, high = get_system("pendubot").input_limits
    assert (low[0], high[0]) == (-10.0, 10.0)


@pytest.mark.parametrize("name", TWO_LINKS)
def test_energy_balance_pins_motor_and_friction(name):
    """``dE/dt`` along ``f`` (central difference of the model's energy) equals
    the motor's power at its own joint less each friction's dissipation."""
    rng = np.random.default_rng(31 + ACTUATED[name])
    for _ in range(20):
        system = _draw(name, rng, friction=True)
        p = system.params
        x, tau = _point(rng, float(system.input_limits[1][0]))
        xdot = system.f(x, [tau])
        h = 1e-6
        dE = (system.energy(x + h * xdot) - system.energy(x - h * xdot)) / (2 * h)
        power = tau * x[2 + ACTUATED[name]] - p["b1"] * x[2] ** 2 - p["b2"] * x[3] ** 2
        assert dE == pytest.approx(power, rel=1e-6, abs=1e-6)


@pytest.mark.parametrize("name", TWO_LINKS)
def test_energy_is_the_mechanical_energy_of_the_links(name):
    """Kinetic plus potential energy written from the geometry (centres of
    mass at ``lc`` along each link, ``y`` up, zero at the shoulder)."""
    rng = np.random.default_rng(41 + ACTUATED[name])
    system = _draw(name, rng, friction=False)
    p = system.params
    for _ in range(10):
        q1, q2, w1, w2 = _point(rng, 1.0)[0]
        c1 = p["lc1"] * np.array([math.sin(q1), -math.cos(q1)])
        elbow = p["l1"] * np.array([math.sin(q1), -math.cos(q1)])
        c2 = elbow + p["lc2"] * np.array([math.sin(q1 + q2), -math.cos(q1 + q2)])
        v1 = w1 * p["lc1"] * np.array([math.cos(q1), math.sin(q1)])
        v2 = (w1 * p["l1"] * np.array([math.cos(q1), math.sin(q1)])
              + (w1 + w2) * p["lc2"] * np.array([math.cos(q1 + q2), math.sin(q1 + q2)]))
        kinetic = (0.5 * p["m1"] * v1 @ v1 + 0.5 * p["I1"] * w1**2
                   + 0.5 * p["m2"] * v2 @ v2 + 0.5 * p["I2"] * (w1 + w2) ** 2)
        potential = p["g"] * (p["m1"] * c1[1] + p["m2"] * c2[1])
        assert system.energy([q1, q2, w1, w2]) == pytest.approx(kinetic + potential, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("name", TWO_LINKS)
def test_energy_conserved_along_a_wide_swing(name):
    system = get_system(name)
    fn, params = system.functions.f, system.p
    buf = np.empty(4)
    u = np.zeros(1)

    def rhs(_t: float, x: np.ndarray) -> np.ndarray:
        fn(x, u, params, buf)
        return buf.copy()

    x0 = np.array([2.0, -1.5, 1.0, 2.5])  # tumbling: both joints turn through large angles
    sol = solve_ivp(rhs, (0.0, 6.0), x0, method="DOP853", rtol=1e-12, atol=1e-12)
    assert sol.success
    assert np.ptp(sol.y[1]) > 2.0
    energies = np.array([system.energy(x) for x in sol.y.T])
    scale = float(np.abs(energies).max())
    assert np.ptp(energies) / scale < 1e-8
