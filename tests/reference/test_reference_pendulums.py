"""Reference tests of the pendulum family against independent truths.

Covers ``cartpole``, ``double_cartpole``, ``wheeled_pendulum`` and
``reaction_wheel_pendulum``:

- the seed-001 cart-pole state-space matrices, written from the seed text;
- the seeds' nonlinear matrix forms and linearizations, where they are right
  (and their corrected forms where they are not, with the slip named);
- a second derivation route: planar Newton-Euler with the joint and contact
  reactions as unknowns, solved numerically (no sympy, no Lagrangian);
- the energy balance ``dE/dt = input power - friction dissipation``, which
  pins the signs of every friction's action and reaction;
- the sign conventions of SYSTEMS.md.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from equilibrist.numeric.lookup import get_system
from equilibrist.numeric.system import System

PENDULUMS = ("cartpole", "double_cartpole", "wheeled_pendulum", "reaction_wheel_pendulum")
FRICTIONS = {
    "cartpole": ("b_c", "b_p"),
    "double_cartpole": ("b_c", "b1", "b2"),
    "wheeled_pendulum": ("b_r", "b_m"),
    "reaction_wheel_pendulum": ("b_a", "b_m"),
}


# -- random draws ---------------------------------------------------------------


def random_system(name: str, rng: np.random.Generator, *, friction: bool = True) -> System:
    """*name* with every physical parameter drawn around its default.

    Frictions are drawn large enough (0.05 to 0.5 in SI units) that their
    terms stand far above round-off in every comparison, or set to zero.
    """
    base = get_system(name)
    values: dict[str, float] = {}
    for par in base.spec.parameters:
        if par.name in FRICTIONS[name]:
            values[par.name] = float(rng.uniform(0.05, 0.5)) if friction else 0.0
        else:
            values[par.name] = par.default * float(rng.uniform(0.5, 2.0))
    return base.with_params(**values)


def random_point(sys: System, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A state with angles up to 1.3 rad and rates up to 3 /s, and an input within limits."""
    nq = len(sys.spec.coordinates)
    q = rng.uniform(-1.3, 1.3, nq)
    qd = rng.uniform(-3.0, 3.0, nq)
    low, high = sys.input_limits
    return np.concatenate([q, qd]), rng.uniform(low, high)


# -- planar Newton-Euler, the second derivation route -----------------------------
#
# Unknowns z = [q_ddot..., reaction force components...]. An affine scalar in
# z is an array of length n_z + 1 (last entry: the constant); a planar vector
# is a (2, n_z + 1) array. Each body contributes m a = sum F (two rows) and
# I alpha = sum of torques about its centre of mass (one row); the square
# system is solved for z. Angles are clockwise from vertical-up, so a body's
# axis is e = (sin, cos) and d e / dt = theta_dot * n with n = (cos, -sin).


class _NewtonEuler:
    def __init__(self, n_unknowns: int) -> None:
        self.n = n_unknowns
        self.rows: list[np.ndarray] = []

    def z(self, k: int) -> np.ndarray:
        v = np.zeros(self.n + 1)
        v[k] = 1.0
        return v

    def c(self, value: float) -> np.ndarray:
        v = np.zeros(self.n + 1)
        v[-1] = value
        return v

    def vec(self, kx: int, ky: int) -> np.ndarray:
        """The unknown force ``(z[kx], z[ky])``."""
        return np.stack([self.z(kx), self.z(ky)])

    def cvec(self, x: float, y: float) -> np.ndarray:
        return np.stack([self.c(x), self.c(y)])

    def swing(self, k: int, angle: float, rate: float, length: float) -> np.ndarray:
        """Acceleration of a point *length* along a body axis relative to its base.

        ``length * (angle_ddot n - angle_dot^2 e)`` with ``angle_ddot = z[k]``.
        """
        e = np.array([math.sin(angle), math.cos(angle)])
        n = np.array([math.cos(angle), -math.sin(angle)])
        return length * (np.outer(n, self.z(k)) - rate**2 * np.outer(e, self.c(1.0)))

    @staticmethod
    def clockwise_torque(r: np.ndarray, force: np.ndarray) -> np.ndarray:
        """Clockwise moment of *force* applied at offset *r* (numbers) from the centre."""
        # z-moment r_x F_y - r_y F_x; clockwise is its negative.
        return r[1] * force[0] - r[0] * force[1]

    def equal(self, lhs: np.ndarray, rhs: np.ndarray) -> None:
        """Add the rows of ``lhs = rhs`` (scalars or vectors)."""
        diff = np.atleast_2d(lhs - rhs)
        self.rows.extend(diff)

    def solve(self) -> np.ndarray:
        mat = np.array(self.rows)
        assert mat.shape == (self.n, self.n + 1), mat.shape
        return np.linalg.solve(mat[:, :-1], -mat[:, -1])


def _axis(angle: float) -> np.ndarray:
    return np.array([math.sin(angle), math.cos(angle)])


def newton_euler_cartpole(p: dict[str, float], x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``[x_ddot, theta_ddot]``; unknowns ``[x_ddot, theta_ddot, R_x, R_y]``.

    ``R`` is the force on the pole from the cart at the pivot.
    """
    _, th, xd, thd = x
    ne = _NewtonEuler(4)
    X, T, R = ne.z(0), ne.z(1), ne.vec(2, 3)
    a_cart = np.stack([X, ne.c(0.0)])
    a_pole = a_cart + ne.swing(1, th, thd, p["l"])
    ne.equal(p["m_c"] * X, ne.c(u[0] - p["b_c"] * xd) - R[0])
    ne.equal(p["m_p"] * a_pole, R + ne.cvec(0.0, -p["m_p"] * p["g"]))
    torque = ne.clockwise_torque(-p["l"] * _axis(th), R) + ne.c(-p["b_p"] * thd)
    ne.equal(p["I_p"] * T, torque)
    return ne.solve()[:2]


def newton_euler_double_cartpole(
    p: dict[str, float], x: np.ndarray, u: np.ndarray, *, joint2_reaction: bool = True
) -> np.ndarray:
    """``[x_ddot, theta1_ddot, theta2_ddot]``.

    Unknowns ``[x_ddot, theta1_ddot, theta2_ddot, R1, R2]``: ``R1`` on link 1
    from the cart, ``R2`` on link 2 from link 1. Without *joint2_reaction*,
    the joint-2 friction acts on link 2 only (seed 002's slip).
    """
    _, t1, t2, xd, t1d, t2d = x
    h1, h2 = p["l1"] / 2, p["l2"] / 2
    ne = _NewtonEuler(7)
    X, T1, T2 = ne.z(0), ne.z(1), ne.z(2)
    R1, R2 = ne.vec(3, 4), ne.vec(5, 6)
    a_cart = np.stack([X, ne.c(0.0)])
    a_g1 = a_cart + ne.swing(1, t1, t1d, h1)
    a_j2 = a_cart + ne.swing(1, t1, t1d, p["l1"])
    a_g2 = a_j2 + ne.swing(2, t2, t2d, h2)
    joint2 = p["b2"] * (t2d - t1d)  # clockwise friction torque on link 2 is -joint2
    ne.equal(p["m_c"] * X, ne.c(u[0] - p["b_c"] * xd) - R1[0])
    ne.equal(p["m1"] * a_g1, R1 - R2 + ne.cvec(0.0, -p["m1"] * p["g"]))
    torque1 = (
        ne.clockwise_torque(-h1 * _axis(t1), R1)
        + ne.clockwise_torque(h1 * _axis(t1), -R2)
        + ne.c(-p["b1"] * t1d + (joint2 if joint2_reaction else 0.0))
    )
    ne.equal(p["I1"] * T1, torque1)
    ne.equal(p["m2"] * a_g2, R2 + ne.cvec(0.0, -p["m2"] * p["g"]))
    ne.equal(p["I2"] * T2, ne.clockwise_torque(-h2 * _axis(t2), R2) + ne.c(-joint2))
    return ne.solve()[:3]


def newton_euler_reaction_wheel(p: dict[str, float], x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``[phi_ddot, theta_ddot]``.

    Unknowns ``[phi_ddot, theta_ddot, R, S]``: ``R`` on the pendulum from the
    ground pivot, ``S`` on the wheel from the pendulum at the wheel's axle.
    """
    _, th, phd, thd = x
    tau = u[0]
    ne = _NewtonEuler(6)
    P, T = ne.z(0), ne.z(1)
    R, S = ne.vec(2, 3), ne.vec(4, 5)
    a_g = ne.swing(1, th, thd, p["L"])
    a_w = ne.swing(1, th, thd, p["L_w"])
    motor_friction = -p["b_m"] * (phd - thd)  # clockwise, on the wheel
    ne.equal(p["m"] * a_g, R - S + ne.cvec(0.0, -p["m"] * p["g"]))
    torque = (
        ne.clockwise_torque(-p["L"] * _axis(th), R)
        + ne.clockwise_torque((p["L_w"] - p["L"]) * _axis(th), -S)
        + ne.c(-tau - motor_friction - p["b_a"] * thd)
    )
    ne.equal(p["I"] * T, torque)
    ne.equal(p["m_w"] * a_w, S + ne.cvec(0.0, -p["m_w"] * p["g"]))
    ne.equal(p["I_w"] * P, ne.c(tau + motor_friction))
    return ne.solve()[:2]


def newton_euler_wheeled(p: dict[str, float], x: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``[phi_ddot, theta_ddot]``.

    Unknowns ``[phi_ddot, theta_ddot, S, C]``: ``S`` on the body from the
    wheel at the axle, ``C`` on the wheel from the floor at the contact
    point. Rolling without slipping: the centre accelerates by ``R phi_ddot``
    along +x and the contact force is whatever it takes.
    """
    _, th, phd, thd = x
    tau = u[0]
    ne = _NewtonEuler(6)
    P, T = ne.z(0), ne.z(1)
    S, C = ne.vec(2, 3), ne.vec(4, 5)
    a_w = np.stack([p["R"] * P, ne.c(0.0)])
    a_g = a_w + ne.swing(1, th, thd, p["L"])
    motor_friction = -p["b_m"] * (phd - thd)  # clockwise, on the wheel
    ne.equal(p["m_w"] * a_w, C - S + ne.cvec(0.0, -p["m_w"] * p["g"]))
    wheel_torque = ne.clockwise_torque(np.array([0.0, -p["R"]]), C) + ne.c(
        tau - p["b_r"] * phd + motor_friction
    )
    ne.equal(p["I_w"] * P, wheel_torque)
    ne.equal(p["m"] * a_g, S + ne.cvec(0.0, -p["m"] * p["g"]))
    body_torque = ne.clockwise_torque(-p["L"] * _axis(th), S) + ne.c(-tau - motor_friction)
    ne.equal(p["I"] * T, body_torque)
    return ne.solve()[:2]


NEWTON_EULER = {
    "cartpole": newton_euler_cartpole,
    "double_cartpole": newton_euler_double_cartpole,
    "reaction_wheel_pendulum": newton_euler_reaction_wheel,
    "wheeled_pendulum": newton_euler_wheeled,
}


@pytest.mark.parametrize("name", PENDULUMS)
def test_newton_euler_agrees_with_the_model(name: str) -> None:
    rng = np.random.default_rng(20240101)
    for _ in range(25):
        sys = random_system(name, rng)
        x, u = random_point(sys, rng)
        nq = len(sys.spec.coordinates)
        model = sys.f(x, u)
        reference = NEWTON_EULER[name](dict(sys.params), x, u)
        np.testing.assert_array_equal(model[:nq], x[nq:])
        scale = np.max(np.abs(reference))
        np.testing.assert_allclose(model[nq:], reference, rtol=1e-10, atol=1e-10 * scale)


def test_newton_euler_route_sees_the_seed_slip_of_joint2_friction() -> None:
    """The comparison is sharp enough to fail on the seed's missing reaction."""
    rng = np.random.default_rng(7)
    for _ in range(5):
        sys = random_system("double_cartpole", rng)
        x, u = random_point(sys, rng)
        seed_like = newton_euler_double_cartpole(dict(sys.params), x, u, joint2_reaction=False)
        assert np.max(np.abs(sys.f(x, u)[3:] - seed_like)) > 1e-3


# -- seed 001: the cart-pole ------------------------------------------------------


def _seed001_state_space(m_A: float, m_B: float, L: float, I_zz: float, g: float):
    """Seed 001 section 27.10, the linearized state-space form, as printed."""
    d = I_zz * (m_A + m_B) + m_A * m_B * L**2
    A = np.array(
        [
            [0.0, 0.0, 1.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
            [0.0, (-g * L**2 * m_B**2) / d, 0.0, 0.0],
            [0.0, (g * L * m_B * (m_A + m_B)) / d, 0.0, 0.0],
        ]
    )
    B = np.array([[0.0], [0.0], [(I_zz + m_B * L**2) / d], [(-L * m_B) / d]])
    return A, B


def test_cartpole_linearization_is_seed_001_state_space() -> None:
    lin = get_system("cartpole").linearize()
    # The seed-001 table.
    A, B = _seed001_state_space(m_A=10.0, m_B=1.0, L=0.5, I_zz=0.08333, g=9.8)
    assert lin.state_names == ("x", "theta", "x_dot", "theta_dot")
    np.testing.assert_allclose(lin.A, A, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(lin.B, B, rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(lin.x0, np.zeros(4))
    np.testing.assert_array_equal(lin.u0, np.zeros(1))


def test_cartpole_linearization_is_seed_001_at_other_parameters() -> None:
    rng = np.random.default_rng(1)
    for _ in range(5):
        sys = random_system("cartpole", rng, friction=False)
        p = sys.params
        A, B = _seed001_state_space(p["m_c"], p["m_p"], p["l"], p["I_p"], p["g"])
        lin = sys.linearize()
        np.testing.assert_allclose(lin.A, A, rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(lin.B, B, rtol=1e-12, atol=1e-14)


def test_cartpole_is_seed_001_nonlinear_matrix_form() -> None:
    """Seed 001 section 27.10: ``[1, 0] F = M q_ddot + [-m_B L sin th th_dot^2, -m_B g L sin th]``."""
    rng = np.random.default_rng(2)
    for _ in range(20):
        sys = random_system("cartpole", rng, friction=False)
        p = sys.params
        x, u = random_point(sys, rng)
        _, th, _, thd = x
        mA, mB, L, Izz, g = p["m_c"], p["m_p"], p["l"], p["I_p"], p["g"]
        M = np.array(
            [[mA + mB, mB * L * math.cos(th)], [mB * L * math.cos(th), Izz + mB * L**2]]
        )
        rest = np.array([-mB * L * math.sin(th) * thd**2, -mB * g * L * math.sin(th)])
        qdd = np.linalg.solve(M, np.array([u[0], 0.0]) - rest)
        np.testing.assert_allclose(sys.f(x, u)[2:], qdd, rtol=1e-11, atol=1e-11)


def test_cartpole_is_seed_002_form_with_full_length_and_pivot_friction() -> None:
    """Seed 002's cart-pole: full length ``l1`` (centre at ``l1/2``), ``I1`` for its slip ``l1``."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        sys = random_system("cartpole", rng)
        sys = sys.with_params(b_c=0.0)  # seed 002 has no cart friction
        p = sys.params
        m1, mc, l1, I1, b1, g = p["m_p"], p["m_c"], 2 * p["l"], p["I_p"], p["b_p"], p["g"]
        x, u = random_point(sys, rng)
        _, th, _, thd = x
        G = np.array(
            [
                [m1 + mc, 0.5 * m1 * l1 * math.cos(th)],
                [0.5 * m1 * l1 * math.cos(th), 0.25 * m1 * l1**2 + I1],
            ]
        )
        H = np.array(
            [
                u[0] + 0.5 * m1 * l1 * thd**2 * math.sin(th),
                0.5 * m1 * g * l1 * math.sin(th) - b1 * thd,
            ]
        )
        np.testing.assert_allclose(sys.f(x, u)[2:], np.linalg.solve(G, H), rtol=1e-11, atol=1e-11)


# -- seed 002: double cart-pole -----------------------------------------------------


def _seed002_double_G(p: dict[str, float], th: float, ph: float) -> np.ndarray:
    """Seed 002's mass matrix, with ``I1``, ``I2`` where it writes ``l1``, ``l2``."""
    mc, m1, m2, l1, l2, I1, I2 = (p[k] for k in ("m_c", "m1", "m2", "l1", "l2", "I1", "I2"))
    a = (0.5 * m1 + m2) * l1 * math.cos(th)
    b = 0.5 * m2 * l2 * math.cos(ph)
    c = 0.5 * m2 * l1 * l2 * math.cos(ph - th)
    return np.array(
        [
            [mc + m1 + m2, a, b],
            [a, (0.25 * m1 + m2) * l1**2 + I1, c],
            [b, c, 0.25 * m2 * l2**2 + I2],
        ]
    )


def test_double_cartpole_is_seed_002_nonlinear_form_corrected() -> None:
    """Seed 002's combined equations, with its slips corrected.

    Corrections: ``I1, I2`` for ``l1, l2`` in G; the theta row gains the
    joint-2 friction's reaction ``+b2 (phi_dot - theta_dot)``; the x row
    gains the cart friction ``-b_c x_dot`` (not in the seed). The printed
    ``1/7`` is already ``1/2`` in the seed's final matrix form.
    """
    rng = np.random.default_rng(4)
    for _ in range(20):
        sys = random_system("double_cartpole", rng)
        p = dict(sys.params)
        x, u = random_point(sys, rng)
        _, th, ph, xd, thd, phd = x
        m1, m2, l1, l2, g = p["m1"], p["m2"], p["l1"], p["l2"], p["g"]
        b1, b2 = p["b1"], p["b2"]
        H = np.array(
            [
                u[0]
                - p["b_c"] * xd
                + (0.5 * m1 + m2) * l1 * math.sin(th) * thd**2
                + 0.5 * m2 * l2 * math.sin(ph) * phd**2,
                0.5 * m2 * l1 * l2 * math.sin(ph - th) * phd**2
                + (0.5 * m1 + m2) * g * l1 * math.sin(th)
                - b1 * thd
                + b2 * (phd - thd),
                -0.5 * m2 * l1 * l2 * math.sin(ph - th) * thd**2
                + 0.5 * m2 * g * l2 * math.sin(ph)
                - b2 * (phd - thd),
            ]
        )
        qdd = np.linalg.solve(_seed002_double_G(p, th, ph), H)
        np.testing.assert_allclose(sys.f(x, u)[3:], qdd, rtol=1e-10, atol=1e-10)


def _seed002_double_linear(p: dict[str, float], *, corrected: bool) -> tuple[np.ndarray, np.ndarray]:
    """Seed 002's linearization ``G^-1 dH`` in the state order ``[x, th, ph, xd, thd, phd]``.

    As printed, ``dH/dtheta_dot = [0, -b1, b2]`` and ``dH/dphi_dot = [0, 0, -b2]``;
    *corrected* adds the joint-2 reaction on link 1: ``[0, -b1 - b2, b2]`` and
    ``[0, b2, -b2]``. The cart friction column ``[-b_c, 0, 0]`` is ours.
    """
    m1, m2, l1, l2, g, b1, b2 = (p[k] for k in ("m1", "m2", "l1", "l2", "g", "b1", "b2"))
    dH = np.zeros((3, 6))
    dH[1, 1] = (0.5 * m1 + m2) * g * l1
    dH[2, 2] = 0.5 * m2 * g * l2
    dH[0, 3] = -p["b_c"]
    dH[:, 4] = [0.0, -b1 - (b2 if corrected else 0.0), b2]
    dH[:, 5] = [0.0, b2 if corrected else 0.0, -b2]
    G = _seed002_double_G(p, 0.0, 0.0)
    A = np.zeros((6, 6))
    A[:3, 3:] = np.eye(3)
    A[3:] = np.linalg.solve(G, dH)
    B = np.zeros((6, 1))
    B[3:, 0] = np.linalg.solve(G, [1.0, 0.0, 0.0])
    return A, B


def test_double_cartpole_linearization_is_seed_002_corrected() -> None:
    rng = np.random.default_rng(5)
    systems = [get_system("double_cartpole")] + [
        random_system("double_cartpole", rng) for _ in range(4)
    ]
    for sys in systems:
        lin = sys.linearize()
        A, B = _seed002_double_linear(dict(sys.params), corrected=True)
        np.testing.assert_allclose(lin.A, A, rtol=1e-11, atol=1e-12)
        np.testing.assert_allclose(lin.B, B, rtol=1e-11, atol=1e-12)


def test_double_cartpole_seed_002_printed_linearization_holds_only_without_joint2_friction() -> None:
    """The seed's printed friction columns are right exactly when ``b2 = 0``."""
    rng = np.random.default_rng(6)
    sys = random_system("double_cartpole", rng)
    printed, _ = _seed002_double_linear(dict(sys.params), corrected=False)
    assert np.max(np.abs(sys.linearize().A - printed)) > 1e-2
    sys0 = sys.with_params(b2=0.0)
    printed0, _ = _seed002_double_linear(dict(sys0.params), corrected=False)
    np.testing.assert_allclose(sys0.linearize().A, printed0, rtol=1e-11, atol=1e-12)


# -- seed 002: reaction-wheel and wheeled pendulums ------------------------------------


def test_reaction_wheel_linearization_is_seed_002() -> None:
    """Seed 002's ``df/dx`` and ``df/dtau`` at upright, as printed (OCR repaired)."""
    rng = np.random.default_rng(8)
    systems = [get_system("reaction_wheel_pendulum")] + [
        random_system("reaction_wheel_pendulum", rng) for _ in range(4)
    ]
    for sys in systems:
        p = sys.params
        J = p["I"] + p["m_w"] * p["L_w"] ** 2 + p["m"] * p["L"] ** 2
        bm, ba, Iw = p["b_m"], p["b_a"], p["I_w"]
        A = np.array(
            [
                [0.0, 0.0, 1.0, 0.0],
                [0.0, 0.0, 0.0, 1.0],
                [0.0, 0.0, -bm / Iw, bm / Iw],
                [0.0, (p["m"] * p["L"] + p["m_w"] * p["L_w"]) * p["g"] / J, bm / J, (-bm - ba) / J],
            ]
        )
        B = np.array([[0.0], [0.0], [1.0 / Iw], [-1.0 / J]])
        lin = sys.linearize()
        assert lin.state_names == ("phi", "theta", "phi_dot", "theta_dot")
        np.testing.assert_allclose(lin.A, A, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(lin.B, B, rtol=1e-12, atol=1e-12)


def test_reaction_wheel_is_seed_002_nonlinear_form() -> None:
    """The seed's ``phi_ddot`` and ``theta_ddot`` are exact (constant mass matrix)."""
    rng = np.random.default_rng(9)
    for _ in range(20):
        sys = random_system("reaction_wheel_pendulum", rng)
        p = sys.params
        x, u = random_point(sys, rng)
        _, th, phd, thd = x
        tau = u[0]
        J = p["I"] + p["m_w"] * p["L_w"] ** 2 + p["m"] * p["L"] ** 2
        phdd = (-p["b_m"] * (phd - thd) + tau) / p["I_w"]
        thdd = (
            (p["m"] * p["L"] + p["m_w"] * p["L_w"]) * p["g"] * math.sin(th)
            + p["b_m"] * (phd - thd)
            - p["b_a"] * thd
            - tau
        ) / J
        np.testing.assert_allclose(sys.f(x, u)[2:], [phdd, thdd], rtol=1e-11, atol=1e-11)


def test_wheeled_pendulum_linearization_is_seed_002() -> None:
    """``G [phi_ddot, theta_ddot] = [[0, 0, -bm - br, bm], [0, mgL, bm, -bm]] x + [1, -1] tau``.

    The seed leaves ``G`` implicit. Here it is written from the kinetic
    energy at upright: the wheel spins (``I_w``) and carries wheel and body
    along at ``R phi_dot`` (``(m + m_w) R^2``); the body turns about its
    centre (``I``) and its centre moves at ``L theta_dot`` (``m L^2``) in the
    same direction as the wheel's (``m R L`` coupling).
    """
    rng = np.random.default_rng(10)
    systems = [get_system("wheeled_pendulum")] + [
        random_system("wheeled_pendulum", rng) for _ in range(4)
    ]
    for sys in systems:
        p = sys.params
        m, R, L = p["m"], p["R"], p["L"]
        G = np.array(
            [[p["I_w"] + (m + p["m_w"]) * R**2, m * R * L], [m * R * L, p["I"] + m * L**2]]
        )
        bm, br = p["b_m"], p["b_r"]
        seed_F = np.array([[0.0, 0.0, -bm - br, bm], [0.0, m * p["g"] * L, bm, -bm]])
        lin = sys.linearize()
        np.testing.assert_allclose(lin.A[2:], np.linalg.solve(G, seed_F), rtol=1e-11, atol=1e-11)
        np.testing.assert_allclose(lin.B[2:, 0], np.linalg.solve(G, [1.0, -1.0]), rtol=1e-11)
        np.testing.assert_array_equal(lin.A[:2], np.hstack([np.zeros((2, 2)), np.eye(2)]))


# -- energy balance ------------------------------------------------------------------


def _power(name: str, p: dict[str, float], x: np.ndarray, u: np.ndarray) -> tuple[float, float]:
    """``(input power, friction power)`` from the forces' definitions in SYSTEMS.md.

    Each viscous friction between two bodies dissipates ``b * (relative rate)^2``
    only when it acts on both with opposite signs; a missing reaction leaves
    a term that is not a square.
    """
    if name == "cartpole":
        _, _, xd, thd = x
        return u[0] * xd, -p["b_c"] * xd**2 - p["b_p"] * thd**2
    if name == "double_cartpole":
        _, _, _, xd, t1d, t2d = x
        return u[0] * xd, -p["b_c"] * xd**2 - p["b1"] * t1d**2 - p["b2"] * (t2d - t1d) ** 2
    if name == "wheeled_pendulum":
        _, _, phd, thd = x
        # The motor acts between wheel and body: power tau * relative rate.
        return u[0] * (phd - thd), -p["b_r"] * phd**2 - p["b_m"] * (phd - thd) ** 2
    _, _, phd, thd = x
    return u[0] * (phd - thd), -p["b_a"] * thd**2 - p["b_m"] * (phd - thd) ** 2


@pytest.mark.parametrize("name", PENDULUMS)
def test_energy_balance_with_friction_and_input(name: str) -> None:
    base = get_system(name)
    model = base.symbolic
    energy = model.energy
    grad = sp.lambdify([model.states, model.params], [energy.diff(s) for s in model.states])
    rng = np.random.default_rng(11)
    for _ in range(25):
        sys = random_system(name, rng)
        x, u = random_point(sys, rng)
        dE = float(np.dot(grad(x, sys.p), sys.f(x, u)))
        p_in, p_fr = _power(name, dict(sys.params), x, u)
        assert p_fr < 0.0
        assert dE == pytest.approx(p_in + p_fr, rel=1e-10, abs=1e-10 * (abs(p_in) + abs(p_fr)))


@pytest.mark.parametrize("name", PENDULUMS)
def test_energy_is_kinetic_plus_potential_of_the_bodies(name: str) -> None:
    """The model's energy at rest is the potential energy of the centres of mass."""
    sys = get_system(name)
    p = sys.params
    th = 0.4
    if name == "cartpole":
        x, expected = [0.3, th, 0, 0], p["m_p"] * p["g"] * p["l"] * math.cos(th)
    elif name == "double_cartpole":
        t2 = -0.2
        height1 = p["l1"] / 2 * math.cos(th)
        height2 = p["l1"] * math.cos(th) + p["l2"] / 2 * math.cos(t2)
        x = [0.3, th, t2, 0, 0, 0]
        expected = p["g"] * (p["m1"] * height1 + p["m2"] * height2)
    elif name == "wheeled_pendulum":
        x = [2.0, th, 0, 0]
        expected = p["g"] * (p["m_w"] * p["R"] + p["m"] * (p["R"] + p["L"] * math.cos(th)))
    else:
        x = [2.0, th, 0, 0]
        expected = p["g"] * (p["m"] * p["L"] + p["m_w"] * p["L_w"]) * math.cos(th)
    assert sys.energy(x) == pytest.approx(expected, rel=1e-12)


# -- sign conventions ------------------------------------------------------------------


def test_cartpole_signs() -> None:
    sys = get_system("cartpole")
    # Leaning towards +x (theta > 0), released at rest: falls further.
    xdot = sys.f([0, 0.05, 0, 0], [0])
    assert xdot[3] > 0
    # A push to +x accelerates the cart to +x and swings the pole back.
    xdot = sys.f([0, 0, 0, 0], [1.0])
    assert xdot[2] > 0 and xdot[3] < 0
    # Friction opposes motion.
    moving = sys.with_params(b_c=1.0, b_p=1.0)
    assert moving.f([0, 0, 1.0, 0], [0])[2] < 0
    assert moving.f([0, 0, 0, 1.0], [0])[3] < 0


def test_double_cartpole_signs() -> None:
    sys = get_system("double_cartpole")
    p = sys.params
    # Either link leaning towards +x on its own, released at rest, falls further.
    assert sys.f([0, 0.05, 0, 0, 0, 0], [0])[4] > 0
    assert sys.f([0, 0, 0.05, 0, 0, 0], [0])[5] > 0
    # Leaning both links: gravity's generalized forces push both further
    # over, (1/2 m1 + m2) g l1 sin(theta1) and 1/2 m2 g l2 sin(theta2).
    leaning = np.array([0, 0.05, 0.08, 0, 0, 0])
    mass = np.empty((3, 3))
    sys.functions.mass_matrix(leaning, sys.p, mass)
    forces = mass @ sys.f(leaning, [0])[3:]
    expected = [
        0.0,
        (0.5 * p["m1"] + p["m2"]) * p["g"] * p["l1"] * math.sin(0.05),
        0.5 * p["m2"] * p["g"] * p["l2"] * math.sin(0.08),
    ]
    np.testing.assert_allclose(forces, expected, rtol=1e-12, atol=1e-14)
    # Pushing to +x accelerates the cart and swings link 1 back.
    xdot = sys.f([0, 0, 0, 0, 0, 0], [1.0])
    assert xdot[3] > 0 and xdot[4] < 0
    # Joint-2 friction: link 2 turning clockwise relative to link 1 is braked,
    # and link 1 is dragged along (the reaction).
    rel = sys.with_params(b2=0.5, b1=0.0, b_c=0.0)
    still = rel.with_params(b2=0.0)
    state = [0, 0, 0, 0, 0, 1.0]
    gain = rel.f(state, [0]) - still.f(state, [0])
    rel.functions.mass_matrix(np.array(state, dtype=float), rel.p, mass)
    # In generalized forces: +0.5 on theta1, -0.5 on theta2, nothing on x.
    np.testing.assert_allclose(mass @ gain[3:], [0.0, 0.5, -0.5], atol=1e-12)


def test_wheeled_pendulum_signs() -> None:
    sys = get_system("wheeled_pendulum")
    # Positive torque spins the wheel clockwise and the body counter-clockwise.
    xdot = sys.f([0, 0, 0, 0], [0.1])
    assert xdot[2] > 0 and xdot[3] < 0
    # Leaning towards +x, released at rest: falls further.
    assert sys.f([0, 0.05, 0, 0], [0])[3] > 0
    # x_w = R phi: a clockwise-turning wheel carries the axle to +x, the same
    # way a clockwise-leaning body moves its centre, so their kinetic
    # energies add when both rates are positive.
    same = sys.energy([0, 0, 1.0, 1.0])
    opposite = sys.energy([0, 0, 1.0, -1.0])
    p = sys.params
    # The cross term of the kinetic energy is m R L cos(theta) phi_dot theta_dot.
    assert same - opposite == pytest.approx(2 * p["m"] * p["R"] * p["L"], rel=1e-12)
    # Rolling: a pure wheel spin carries everything along at R phi_dot.
    spin = sys.energy([0, 0, 1.0, 0]) - sys.energy([0, 0, 0, 0])
    expected = 0.5 * (p["I_w"] + (p["m"] + p["m_w"]) * p["R"] ** 2)
    assert spin == pytest.approx(expected, rel=1e-12)


def test_reaction_wheel_signs_and_absolute_wheel_angle() -> None:
    sys = get_system("reaction_wheel_pendulum")
    p = sys.params
    xdot = sys.f([0, 0, 0, 0], [0.05])
    assert xdot[2] > 0 and xdot[3] < 0
    assert sys.f([0, 0.05, 0, 0], [0])[3] > 0
    # phi is absolute: a swinging pendulum with a free wheel (no motor
    # torque, no motor friction) leaves the wheel's rate unchanged, and a
    # wheel at absolute rest carries no spin energy.
    free = sys.with_params(b_m=0.0)
    assert free.f([0.3, 0.7, 2.0, -1.5], [0])[2] == 0.0
    swing = sys.energy([0, 0, 0, 1.0]) - sys.energy([0, 0, 0, 0])
    expected = 0.5 * (p["I"] + p["m"] * p["L"] ** 2 + p["m_w"] * p["L_w"] ** 2)
    assert swing == pytest.approx(expected, rel=1e-12)
