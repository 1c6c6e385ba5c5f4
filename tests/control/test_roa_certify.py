"""The certified region of attraction: interval enclosures, the branch-and-bound, the command.

The truths it is held to come from elsewhere: mpmath's 50-digit evaluation of the model's
equations (the enclosures), a dense float sampling of dV/dt (no certified level reaches a
point where V does not decrease), scipy's adaptive integrator on the continuous loop the proof
assumes (V never grows from a start on the certified surface) and the compiled sampled loop
(every start inside is caught).
"""

from __future__ import annotations

import json
import math

import mpmath
import numpy as np
import pytest
import sympy as sp
from scipy.integrate import solve_ivp

from equilibrist.cli.main import main
from equilibrist.control.certify import certify
from equilibrist.control.design import design
from equilibrist.control.lyapunov_rate import CertificateUnavailable
from equilibrist.numeric import interval as iv
from equilibrist.numeric.lookup import get_system
from equilibrist.sim.roa import sample_level


@pytest.fixture(scope="module")
def cart():
    system = get_system("cartpole")
    d = design(system, rate=200.0)
    eq = system.operating_point()
    return system, np.asarray(d.K, float), np.asarray(d.S, float), np.asarray(eq.x, float), \
        np.asarray(eq.u, float)


@pytest.fixture(scope="module")
def cert(cart):
    system, K, S, x_op, u_op = cart
    return certify(system, K, S, x_op=x_op, u_op=u_op, max_boxes=130_000)


def test_enclosures_hold_the_true_values_of_the_equations(cart) -> None:
    """Random boxes of the cart-pole's state and force: the model's equations evaluated at
    points inside each box with 50 digits lie inside the interval enclosure of the box."""
    system, *_ = cart
    m = system.symbolic
    args = [*m.states, *m.inputs, *m.params]
    enclose = iv.lambdify(args, [m.f, m.A])
    exact = sp.lambdify(args, [m.f.tolist(), m.A.tolist()], modules="mpmath")
    rng = np.random.default_rng(3)
    lo = rng.uniform(-2.0, 2.0, size=(200, 5))
    hi = lo + rng.uniform(0.0, 0.5, size=(200, 5))
    boxes = [iv.Interval(lo[:, j], hi[:, j]) for j in range(5)]
    f, A = enclose(*boxes, *[iv.Interval(float(v)) for v in system.p])
    mpmath.mp.dps = 50
    for b in range(0, 200, 7):
        for t in (0.0, 0.37, 1.0):
            point = [mpmath.mpf(float(lo[b, j] + t * (hi[b, j] - lo[b, j]))) for j in range(5)]
            fv, Av = exact(*point, *[mpmath.mpf(float(v)) for v in system.p])
            for i in range(4):
                e = iv.Interval.of(f[i][0])
                assert float(np.broadcast_to(e.lo, (200,))[b]) <= fv[i][0] <= \
                    float(np.broadcast_to(e.hi, (200,))[b])
                for j in range(4):
                    e = iv.Interval.of(A[i][j])
                    assert float(np.broadcast_to(e.lo, (200,))[b]) <= Av[i][j] <= \
                        float(np.broadcast_to(e.hi, (200,))[b])


def test_sine_and_cosine_reach_their_crests_and_rationals_are_enclosed() -> None:
    s = iv.sin(iv.Interval(np.array([1.0, 0.1, -2.0]), np.array([2.0, 0.2, -1.0])))
    assert s.hi[0] == 1.0 and s.lo[2] == -1.0  # pi/2 in [1, 2]; -pi/2 in [-2, -1]
    assert s.lo[1] <= math.sin(0.1) and s.hi[1] >= math.sin(0.2) and s.hi[1] < 0.2
    c = iv.cos(iv.Interval(np.array([3.0]), np.array([3.3])))
    assert c.lo[0] == -1.0  # pi inside
    third = iv.Interval.rational(1, 3)
    assert third.lo < third.hi and float(third.lo) <= 1 / 3 <= float(third.hi)
    assert (iv.Interval(np.array([-1.0]), np.array([2.0])) ** 2).lo[0] == 0.0
    whole = iv.Interval(np.array([1.0])) / iv.Interval(np.array([-1.0]), np.array([1.0]))
    assert whole.lo[0] == -np.inf and whole.hi[0] == np.inf  # a zero divisor proves nothing
    with pytest.raises(iv.UnsupportedError):
        x = sp.Symbol("x")
        iv.lambdify([x], [sp.atan(x)])


def test_the_level_stops_before_any_point_where_v_does_not_decrease(cart, cert) -> None:
    """Dense float sampling of dV/dt on spheres of the level: none inside the certified level
    has dV/dt >= 0, and the certificate reports a real point where it does just outside."""
    system, K, S, x_op, u_op = cart
    assert cert.rho > 10.0 and cert.method.startswith("interval branch-and-bound")
    lo, hi = system.input_limits
    T = np.linalg.inv(np.linalg.cholesky(S).T)
    rng = np.random.default_rng(5)
    for r in np.linspace(0.05, 1.0, 12) * math.sqrt(cert.rho):
        z = rng.normal(size=(500, 4))
        z *= r / np.linalg.norm(z, axis=1)[:, None]
        for dx in z @ T.T:
            u = np.clip(u_op - K @ dx, lo, hi)
            assert 2.0 * dx @ S @ system.f(x_op + dx, u) < 0.0
    if cert.violation is not None:
        dx = np.asarray(cert.violation) - x_op
        assert 2.0 * dx @ S @ system.f(x_op + dx, np.clip(u_op - K @ dx, lo, hi)) >= 0.0
        assert dx @ S @ dx > cert.rho


def test_the_continuous_loop_from_the_certified_surface_never_gains_v(cart, cert) -> None:
    """scipy's adaptive integrator on the loop the proof assumes: from starts on the surface
    V = rho, V only falls and ends near zero."""
    system, K, S, x_op, u_op = cart
    lo, hi = system.input_limits
    starts = sample_level(S, x_op, cert.rho, 12, seed=9)[:6]  # the surface half

    def rhs(_t: float, x: np.ndarray) -> np.ndarray:
        return system.f(x, np.clip(u_op - K @ (x - x_op), lo, hi))

    for x0 in starts:
        sol = solve_ivp(rhs, (0.0, 4.0), x0, rtol=1e-9, atol=1e-9, max_step=0.01)
        dx = sol.y.T - x_op
        V = np.einsum("ij,jk,ik->i", dx, S, dx)
        assert V[0] == pytest.approx(cert.rho, rel=1e-6)
        assert np.all(np.diff(V) < 1e-9 * cert.rho) and V[-1] < 0.01 * cert.rho


def test_tight_input_limits_shrink_the_certified_level(cart, cert) -> None:
    """With the force limited to 2 N, saturation sets in close to the operating point: the
    level must shrink, and still no sampled point inside it has dV/dt >= 0."""
    system, K, S, x_op, u_op = cart
    weak = system.with_params(F_min=-2.0, F_max=2.0)
    small = certify(weak, K, S, x_op=x_op, u_op=u_op, max_boxes=40_000)
    assert small.rho < 0.5 * cert.rho
    T = np.linalg.inv(np.linalg.cholesky(S).T)
    z = np.random.default_rng(1).normal(size=(3000, 4))
    z *= math.sqrt(small.rho) / np.linalg.norm(z, axis=1)[:, None]
    for dx in z @ T.T:
        u = np.clip(u_op - K @ dx, -2.0, 2.0)
        assert 2.0 * dx @ S @ weak.f(x_op + dx, u) < 0.0


def test_a_gain_that_does_not_stabilize_has_no_certificate(cart) -> None:
    system, K, S, x_op, u_op = cart
    with pytest.raises(CertificateUnavailable, match="not negative definite"):
        certify(system, np.zeros_like(K), S, x_op=x_op, u_op=u_op, max_boxes=2000)
    with pytest.raises(CertificateUnavailable, match="full-state"):
        certify(system, K[:, :2], S, x_op=x_op, u_op=u_op)


def test_the_command_certifies_and_checks_the_level_against_the_sampled_loop(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["roa", "cartpole", "--controller", "lqr", "--samples", "600", "--json",
                 "--boxes", "30000", "--falsify", "300"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["certified"] is True and out["counterexamples"] == 0
    assert out["method"] == "interval branch-and-bound on the exact dynamics"
    assert out["rho"] > 0 and out["falsify_runs"] >= 300
    assert 0.0 <= out["coverage"] <= 1.0
    assert "continuous-time" in out["certificate"]["assumes"]
    assert out["certificate"]["limited_by"] in ("region", "decrease", "resolution", "budget")
    # A controller without a Riccati function is estimated, never certified.
    assert main(["roa", "cartpole", "--controller", "swingup", "--samples", "300", "--json",
                 "--duration", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["certified"] is False and out["rho"] is None
    assert "no Riccati function" in out["certificate_note"]


@pytest.mark.parametrize("key", ["cartpole", "furuta"])
def test_every_box_bound_lies_above_the_sampled_values_of_dv_dt(key: str) -> None:
    """The branch-and-bound's enclosure of dV/dt over a box, against dV/dt computed in plain
    floats (the model's own f) at points inside: near the operating point (where the quadratic
    part decides), far out, and across the input's limit (the rotary pendulum saturates at
    |z| of about 2)."""
    from equilibrist.control.lyapunov_rate import LyapunovRate

    system = get_system(key)
    d = design(system, rate=float(system.spec.control_rate))
    eq = system.operating_point()
    x_op, u_op = np.asarray(eq.x, float), np.asarray(eq.u, float)
    K, S = np.atleast_2d(np.asarray(d.K, float)), np.asarray(d.S, float)
    lo_u, hi_u = system.input_limits
    loop = LyapunovRate(system, K, S, x_op, u_op, lo_u, hi_u)
    assert loop.quad
    rng = np.random.default_rng(11)
    for scale in (0.01, 0.3, 3.0):
        centres = rng.normal(size=(60, 4)) * scale
        widths = rng.uniform(0.05, 1.0, size=(60, 4)) * scale
        blo, bhi = centres - widths / 2, centres + widths / 2
        upper = loop.vdot_box(blo, bhi)[0].hi
        for b in range(60):
            z = blo[b] + rng.uniform(size=(40, 4)) * (bhi[b] - blo[b])
            for dx in z @ loop.T.T:
                u = np.clip(u_op - K @ dx, lo_u, hi_u)
                v = 2.0 * dx @ S @ system.f(x_op + dx, u)
                assert v <= upper[b] + 1e-9 * abs(v), (scale, b, v, upper[b])
    # The quadratic part is the linearized loop's: dV/dt(z) / |z|^2 -> z' P z / |z|^2.
    P = np.array([[0.5 * (float(loop.P[i][j].lo) + float(loop.P[i][j].hi)) for j in range(4)]
                  for i in range(4)])
    z = rng.normal(size=(5, 4)) * 1e-5
    for zz in z:
        dx = loop.T @ zz
        v = 2.0 * dx @ S @ system.f(x_op + dx, np.clip(u_op - K @ dx, lo_u, hi_u))
        assert v == pytest.approx(zz @ P @ zz, rel=1e-3)
