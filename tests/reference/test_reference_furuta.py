"""Reference tests of the rotary (Furuta) pendulum against independent truths.

- The published model of Cazzolato and Prime (2011, "On the dynamics of the
  Furuta pendulum", J. Control Sci. Eng., article 528341), their equations
  33-34 for a slender pendulum, written here in numpy in their coordinates
  (arm angle ``theta_1``; pendulum angle ``theta_2`` from hanging down) and
  mapped to SYSTEMS.md's by ``theta_1 = phi``, ``theta_2 = pi - theta``;
- the sign conventions of SYSTEMS.md from physics alone (a push of the arm
  leaves the upright pendulum behind; an upright pendulum falls);
- the energy balance ``dE/dt = tau phi_dot - b_a phi_dot^2 - b_p theta_dot^2``;
- the energy written from the geometry, and its conservation along an
  accurate (DOP853) trajectory of a wide swing without friction and input.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from equilibrist.numeric.lookup import get_system
from equilibrist.numeric.system import System


def _draw(rng: np.random.Generator, *, friction: bool) -> System:
    base = get_system("furuta")
    values = {}
    for par in base.spec.parameters:
        if par.name in ("b_a", "b_p"):
            values[par.name] = float(rng.uniform(1e-4, 1e-3)) if friction else 0.0
        else:
            values[par.name] = par.default * float(rng.uniform(0.5, 2.0))
    return base.with_params(**values)


def _point(rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """Any configuration, rates up to 10 rad/s, a torque within the limits."""
    x = np.concatenate([rng.uniform(-math.pi, math.pi, 2), rng.uniform(-10.0, 10.0, 2)])
    return x, float(rng.uniform(-0.05, 0.05))


def _cazzolato_prime(p: dict, t1: float, t2: float, w1: float, w2: float,
                     tau1: float, tau2: float) -> tuple[float, float]:
    """Equations 33-34 of Cazzolato and Prime (2011): slender pendulum
    (no inertia about its own axis), arm and pendulum on principal axes.

    ``J0h`` is the arm's inertia about the motor axis plus the pendulum's
    mass at the arm's tip, ``J2h`` the pendulum's inertia about its joint.
    """
    m2, L1, l2, g = p["m_p"], p["L_a"], p["l_p"], p["g"]
    b1, b2 = p["b_a"], p["b_p"]
    J0h = p["I_a"] + m2 * L1**2
    J2h = p["I_p"] + m2 * l2**2
    k = m2 * L1 * l2
    s, c, s2 = math.sin(t2), math.cos(t2), math.sin(2 * t2)
    den = J0h * J2h + J2h**2 * s**2 - k**2 * c**2
    dd1 = (-J2h * b1 * w1 + k * c * b2 * w2 - J2h**2 * s2 * w1 * w2
           - 0.5 * J2h * k * c * s2 * w1**2 + J2h * k * s * w2**2
           + J2h * tau1 - k * c * tau2 + 0.5 * g * m2 * l2 * k * s2) / den
    dd2 = (k * c * b1 * w1 - b2 * (J0h + J2h * s**2) * w2 + k * J2h * c * s2 * w1 * w2
           - k**2 * s * c * w2**2 - k * c * tau1 + (J0h + J2h * s**2) * tau2
           + 0.5 * (J0h + J2h * s**2) * J2h * s2 * w1**2
           - g * m2 * l2 * (J0h + J2h * s**2) * s) / den
    return dd1, dd2


def test_equals_cazzolato_and_prime():
    rng = np.random.default_rng(3)
    for _ in range(40):
        system = _draw(rng, friction=True)
        p = dict(system.params)
        for _ in range(5):
            x, tau = _point(rng)
            phi, theta, phid, thetad = x
            dd1, dd2 = _cazzolato_prime(p, phi, math.pi - theta, phid, -thetad, tau, 0.0)
            xdot = system.f(x, [tau])
            assert xdot[:2] == pytest.approx(x[2:], rel=0, abs=0)
            assert xdot[2:] == pytest.approx([dd1, -dd2], rel=1e-9, abs=1e-9)


def test_defaults_are_systems_md_rig():
    p = get_system("furuta").params
    assert (p["m_a"], p["L_a"], p["m_p"], p["l_p"]) == (0.095, 0.085, 0.024, 0.0645)
    assert p["I_a"] == pytest.approx(0.095 * 0.085**2 / 3, rel=1e-15)
    assert p["I_p"] == pytest.approx(0.024 * 0.129**2 / 12, rel=1e-15)
    assert (p["b_a"], p["b_p"], p["g"]) == (5e-4, 1e-5, 9.81)
    low, high = get_system("furuta").input_limits
    assert (low[0], high[0]) == (-0.05, 0.05)
    # 2048-count encoders: uniform quantization noise of step / sqrt(12).
    spec = get_system("furuta").spec
    step = 2 * math.pi / 2048
    assert spec.sensor_noise == pytest.approx({"phi": step / math.sqrt(12), "theta": step / math.sqrt(12)})


def test_signs_follow_systems_md():
    system = get_system("furuta")
    # A positive torque turns the arm counter-clockwise (phi grows); its tip,
    # and the pendulum's joint, move in the direction of growing phi, and
    # the pendulum's inertia leaves the upright pendulum's tip behind: it
    # leans against that direction, theta (positive towards growing phi) falls.
    xdot = system.f([0.0, 0.0, 0.0, 0.0], [0.04])
    assert xdot[2] > 0 and xdot[3] < 0
    # Upright is unstable: leaning, the pendulum falls on.
    assert system.f([0.0, 0.2, 0.0, 0.0], [0.0])[3] > 0
    # Hanging (theta = pi), it swings back towards pi.
    assert system.f([0.0, math.pi - 0.2, 0.0, 0.0], [0.0])[3] > 0
    # The arm spinning (either way) flings a leaning pendulum outwards: its
    # centre of mass, l_p sin(theta) beside the arm, moves away from the axis.
    still = system.f([0.0, 0.3, 0.0, 0.0], [0.0])[3]
    for spin in (5.0, -5.0):
        assert system.f([0.0, 0.3, spin, 0.0], [0.0])[3] > still
    eq = system.operating_point()
    assert eq.x == pytest.approx(np.zeros(4), abs=1e-12) and eq.u == pytest.approx([0.0], abs=1e-12)


def test_energy_balance_pins_motor_and_friction():
    rng = np.random.default_rng(5)
    for _ in range(20):
        system = _draw(rng, friction=True)
        p = system.params
        x, tau = _point(rng)
        xdot = system.f(x, [tau])
        h = 1e-7
        dE = (system.energy(x + h * xdot) - system.energy(x - h * xdot)) / (2 * h)
        power = tau * x[2] - p["b_a"] * x[2] ** 2 - p["b_p"] * x[3] ** 2
        assert dE == pytest.approx(power, rel=1e-5, abs=1e-8)


def test_energy_is_the_mechanical_energy_from_the_geometry():
    """The pendulum's centre of mass at ``L_a`` along the arm plus ``l_p``
    along the pendulum, which tips from vertical towards the arm's direction
    of growing ``phi``; the arm turns about the vertical with ``I_a``."""
    rng = np.random.default_rng(6)
    system = _draw(rng, friction=False)
    p = system.params
    for _ in range(10):
        phi, th, wp, wt = _point(rng)[0]
        arm = np.array([math.cos(phi), math.sin(phi), 0.0])
        across = np.array([-math.sin(phi), math.cos(phi), 0.0])
        up = np.array([0.0, 0.0, 1.0])

        def com(dt: float, *, phi=phi, th=th, wp=wp, wt=wt) -> np.ndarray:
            a, t = phi + wp * dt, th + wt * dt
            return (p["L_a"] * np.array([math.cos(a), math.sin(a), 0.0])
                    + p["l_p"] * (math.sin(t) * np.array([-math.sin(a), math.cos(a), 0.0])
                                  + math.cos(t) * np.array([0.0, 0.0, 1.0])))

        r = com(0.0)
        h = 1e-6  # velocity of the centre of mass by a central difference in time
        v = (com(h) - com(-h)) / (2 * h)
        # The pendulum's angular velocity: wp about the vertical plus wt about
        # the arm's axis; a slender rod has inertia I_p across itself only.
        axis = math.sin(th) * across + math.cos(th) * up
        omega = wp * up - wt * arm
        across_axis = omega - (omega @ axis) * axis
        kinetic = (0.5 * p["I_a"] * wp**2 + 0.5 * p["m_p"] * v @ v
                   + 0.5 * p["I_p"] * across_axis @ across_axis)
        potential = p["m_p"] * p["g"] * r[2]
        assert system.energy([phi, th, wp, wt]) == pytest.approx(kinetic + potential, rel=1e-8)


def test_energy_conserved_along_a_wide_swing():
    system = get_system("furuta", b_a=0.0, b_p=0.0)
    fn, params = system.functions.f, system.p
    buf = np.empty(4)
    u = np.zeros(1)

    def rhs(_t: float, x: np.ndarray) -> np.ndarray:
        fn(x, u, params, buf)
        return buf.copy()

    x0 = np.array([0.0, 0.3, 6.0, 0.0])  # a spinning arm, the pendulum falling and whirling
    sol = solve_ivp(rhs, (0.0, 3.0), x0, method="DOP853", rtol=1e-12, atol=1e-12)
    assert sol.success
    assert np.ptp(sol.y[1]) > 2.0 and np.ptp(sol.y[0]) > 2.0
    energies = np.array([system.energy(x) for x in sol.y.T])
    kinetic_scale = 0.5 * float(system.params["I_a"]) * 6.0**2
    assert np.ptp(energies) / max(float(np.abs(energies).max()), kinetic_scale) < 1e-8
