"""LQR / LQE gains against python-control, a published example and the cost identity."""

from __future__ import annotations

import functools

import control
import numpy as np
import pytest
import scipy.integrate
import scipy.linalg
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from equilibrist.control import (
    controllability,
    design,
    discretize,
    dlqe,
    dlqr,
    loop_margins,
    lqe,
    lqr,
    observability,
)
from equilibrist.errors import DesignError, DimensionError
from equilibrist.numeric.lookup import get_system
from equilibrist.systems import registry


def _actuated() -> list[tuple[str, dict[str, str]]]:
    out = []
    for entry in registry.all_entries():
        if entry.spec.inputs:
            variant = (
                {} if entry.spec.variant is None else {entry.spec.variant[0]: entry.spec.variant[1]}
            )
            out.append((entry.spec.name, variant))
    return out


ACTUATED = _actuated()
IDS = [name + "".join(f"[{v}]" for v in variant.values()) for name, variant in ACTUATED]


@functools.cache
def _system(name: str, variant: tuple[tuple[str, str], ...] = ()):
    return get_system(name, **dict(variant))


def _sorted(values: np.ndarray) -> np.ndarray:
    v = np.asarray(values, dtype=complex)
    return v[np.lexsort((v.imag, v.real))]


def test_the_catalogue_has_actuated_systems() -> None:
    assert ("cartpole", {}) in ACTUATED


@pytest.mark.parametrize(("name", "variant"), ACTUATED, ids=IDS)
def test_gains_equal_python_control(name: str, variant: dict[str, str]) -> None:
    system = _system(name, tuple(variant.items()))
    d = design(system)  # default weights: Bryson's rule and the spec's noise
    A, B, C = d.plant.A, d.plant.B, d.plant.C

    K, S, E = lqr(A, B, d.Q, d.R)
    Kr, Sr, Er = control.lqr(A, B, d.Q, d.R)
    np.testing.assert_allclose(K, Kr, rtol=1e-8, atol=1e-10 * np.abs(Kr).max())
    np.testing.assert_allclose(S, Sr, rtol=1e-8, atol=1e-10 * np.abs(Sr).max())
    np.testing.assert_allclose(_sorted(E), _sorted(Er), rtol=1e-8)

    L, P, Ee = lqe(A, d.G, C, d.QN, d.RN)
    Lr, Pr, Eer = control.lqe(A, d.G, C, d.QN, d.RN)
    np.testing.assert_allclose(L, Lr, rtol=1e-8, atol=1e-10 * np.abs(Lr).max())
    np.testing.assert_allclose(P, Pr, rtol=1e-8, atol=1e-10 * np.abs(Pr).max())
    np.testing.assert_allclose(_sorted(Ee), _sorted(Eer), rtol=1e-8)

    disc = discretize(d.plant, 0.01)
    Kd, Sd, _ = dlqr(disc.A, disc.B, d.Q, d.R)
    Kdr, Sdr, _ = control.dlqr(disc.A, disc.B, d.Q, d.R)
    np.testing.assert_allclose(Kd, Kdr, rtol=1e-7, atol=1e-9 * np.abs(Kdr).max())
    np.testing.assert_allclose(Sd, Sdr, rtol=1e-7, atol=1e-9 * np.abs(Sdr).max())

    Qd = np.diag(np.diag(d.QN) * 0.01 + 1e-12)
    Rd = d.RN / 0.01
    Ld, Pd, _ = dlqe(disc.A, np.eye(A.shape[0]), C, Qd, Rd)
    Ldr, Pdr, _ = control.dlqe(disc.A, np.eye(A.shape[0]), C, Qd, Rd)
    np.testing.assert_allclose(Ld, Ldr, rtol=1e-7, atol=1e-9 * np.abs(Ldr).max())
    np.testing.assert_allclose(Pd, Pdr, rtol=1e-7, atol=1e-9 * np.abs(Pdr).max())


def test_michigan_inverted_pendulum_lqr() -> None:
    """Control Tutorials for MATLAB (Michigan), inverted pendulum, state-space design.

    Their state is [x, x_dot, phi, phi_dot] with phi the pendulum's deviation
    from upright, positive the other way from our theta; Q = diag(1, 0, 1, 0)
    (C'C with C = [x; phi]), R = 1 gives K = [-1.0000 -1.6567 18.6854 3.4594].
    """
    system = get_system("cartpole", m_c=0.5, m_p=0.2, b_c=0.1, I_p=0.006, l=0.3, g=9.8)
    lm = system.linearize()
    assert lm.state_names == ("x", "theta", "x_dot", "theta_dot")
    # z = T x: z = [x, x_dot, phi, phi_dot] with phi = -theta.
    T = np.array(
        [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0, 0.0],
            [0.0, 0.0, 0.0, -1.0],
        ]
    )
    Q_mich = np.diag([1.0, 0.0, 1.0, 0.0])
    K, _, _ = lqr(lm.A, lm.B, T.T @ Q_mich @ T, 1.0)
    K_mich = K @ np.linalg.inv(T)
    np.testing.assert_allclose(K_mich, [[-1.0000, -1.6567, 18.6854, 3.4594]], atol=6e-5)


@pytest.mark.parametrize("rate", [None, 50.0])
def test_lqr_cost_equals_x0_S_x0(rate: float | None) -> None:
    system = _system("cartpole")
    d = design(system, rate=rate)
    A, B = d.model.A, d.model.B
    x0 = np.array([0.1, -0.05, 0.2, 0.3])
    if rate is None:
        closed = A - B @ d.K
        Q, R, K = d.Q, d.R, d.K

        def rhs(_t: float, z: np.ndarray) -> np.ndarray:
            x = z[:-1]
            u = -K @ x
            return np.concatenate([closed @ x, [x @ Q @ x + u @ R @ u]])

        sol = scipy.integrate.solve_ivp(
            rhs, (0.0, 40.0), np.concatenate([x0, [0.0]]), rtol=1e-11, atol=1e-13, method="DOP853"
        )
        assert np.linalg.norm(sol.y[:-1, -1]) < 1e-10  # settled: the tail adds nothing
        cost = sol.y[-1, -1]
    else:
        x, cost = x0.copy(), 0.0
        for _ in range(4000):
            u = -d.K @ x
            cost += x @ d.Q @ x + u @ d.R @ u
            x = A @ x + B @ u
        assert np.linalg.norm(x) < 1e-12
    assert cost == pytest.approx(x0 @ d.S @ x0, rel=1e-7)


def test_continuous_lqr_return_difference_and_phase_margin() -> None:
    """Kalman's inequality: |1 + K (jwI - A)^-1 B| >= 1, so the phase margin is >= 60 deg."""
    for name, variant in ACTUATED:
        d = design(_system(name, tuple(variant.items())))
        if d.plant.n_inputs != 1:
            continue
        m = loop_margins(d.plant.A, d.plant.B, d.K)
        assert m.return_difference >= 1.0 - 1e-6, name
        assert m.phase_margin >= 60.0 - 1e-6, name


def test_discrete_estimator_gain_is_predictor_form() -> None:
    d = design(_system("cartpole"))
    disc = discretize(d.plant, 0.01)
    W = np.diag([1e-6, 1e-6, 1e-4, 1e-4])
    V = np.diag([1e-4, 1e-4])
    L, P, E = dlqe(disc.A, np.eye(4), disc.C, W, V)
    # P is the a-priori covariance: it solves the filter's Riccati equation.
    M = P @ disc.C.T @ np.linalg.inv(disc.C @ P @ disc.C.T + V)
    np.testing.assert_allclose(L, disc.A @ M, rtol=1e-10)
    riccati = disc.A @ (P - M @ disc.C @ P) @ disc.A.T + W
    np.testing.assert_allclose(riccati, P, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(
        _sorted(E), _sorted(np.linalg.eigvals(disc.A - L @ disc.C)), rtol=1e-9
    )


# -- validation ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def cartpole_matrices() -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[str, ...]]:
    lm = _system("cartpole").linearize()
    return lm.A, lm.B, lm.C, lm.state_names


def test_weights_not_psd_or_pd_are_refused_together(cartpole_matrices) -> None:
    A, B, _, _ = cartpole_matrices
    with pytest.raises(DesignError) as err:
        lqr(A, B, np.diag([-1.0, 1.0, 1.0, 1.0]), 0.0)
    text = str(err.value)
    assert "Q is not positive semidefinite" in text
    assert "R is not positive definite" in text


def test_asymmetric_weight_is_refused(cartpole_matrices) -> None:
    A, B, _, _ = cartpole_matrices
    Q = np.eye(4)
    Q[0, 1] = 0.5
    with pytest.raises(DesignError, match="Q is not symmetric"):
        lqr(A, B, Q, 1.0)


def test_wrong_sizes_are_dimension_errors(cartpole_matrices) -> None:
    A, B, C, _ = cartpole_matrices
    with pytest.raises(DimensionError, match=r"Q has shape \(3, 3\), expected \(4, 4\)"):
        lqr(A, B, np.eye(3), 1.0)
    with pytest.raises(DimensionError, match="R has shape"):
        lqr(A, B, np.eye(4), np.eye(2))
    with pytest.raises(DimensionError, match="RN has shape"):
        lqe(A, np.eye(4), C, np.eye(4), 1.0)


def test_uncontrollable_mode_is_named(cartpole_matrices) -> None:
    A, _, _, names = cartpole_matrices
    # A force that only moves the cart's position cannot reach the pole.
    B = np.array([[1.0], [0.0], [0.0], [0.0]])
    with pytest.raises(DesignError) as err:
        lqr(A, B, np.eye(4), 1.0, state_names=names)
    text = str(err.value)
    assert "not stabilizable" in text
    assert "s = 3.97" in text
    assert "theta" in text


def test_unobservable_mode_is_named(cartpole_matrices) -> None:
    A, _, C, names = cartpole_matrices
    with pytest.raises(DesignError) as err:
        lqe(A, np.eye(4), C[1:], np.eye(4), 1.0, state_names=names, output_names=["theta"])
    text = str(err.value)
    assert "not detectable" in text
    assert "s = 0 (x)" in text


def test_marginal_mode_hidden_from_q_is_refused(cartpole_matrices) -> None:
    A, B, _, names = cartpole_matrices
    with pytest.raises(DesignError, match=r"Q does not weight the marginal mode\(s\) s = 0 \(x\)"):
        lqr(A, B, np.diag([0.0, 1.0, 0.0, 1.0]), 1.0, state_names=names)


def test_pbh_analysis(cartpole_matrices) -> None:
    A, B, C, names = cartpole_matrices
    full = controllability(A, B, state_names=names)
    assert full.rank == 4
    assert full.full
    assert full.stabilizable
    blind = observability(A, C[1:], state_names=names)
    # theta alone sees neither the cart's position nor its velocity.
    assert blind.rank == 2
    assert not blind.stabilizable
    assert [m.eigenvalue for m in blind.modes] == [0j]
    assert blind.modes[0].states == ("x",)
    pushed = controllability(A, np.zeros((4, 1)), state_names=names)
    assert pushed.rank == 0
    assert sorted(round(m.eigenvalue.real, 3) for m in pushed.modes) == [-3.972, 0.0, 3.972]


def test_stable_uncontrollable_mode_is_stabilizable() -> None:
    A = np.diag([1.0, -2.0])
    B = np.array([[1.0], [0.0]])
    info = controllability(A, B)
    assert not info.full
    assert info.stabilizable
    K, _, E = lqr(A, B, np.eye(2), 1.0)
    assert np.all(E.real < 0)
    assert K[0, 1] == pytest.approx(0.0, abs=1e-12)


# -- property: any well-controllable system ---------------------------------------------


@st.composite
def _plants(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    n = draw(st.integers(1, 4))
    m = draw(st.integers(1, 2))
    entries = st.floats(-5, 5, allow_nan=False, allow_infinity=False)
    A = draw(arrays(float, (n, n), elements=entries))
    B = draw(arrays(float, (n, m), elements=entries))
    q = draw(arrays(float, (n,), elements=st.floats(0.1, 10)))
    r = draw(arrays(float, (m,), elements=st.floats(0.1, 10)))
    return A, B, np.diag(q), np.diag(r)


def _pbh_margin(A: np.ndarray, B: np.ndarray) -> float:
    n = A.shape[0]
    return min(
        np.linalg.svd(np.hstack([A - lam * np.eye(n), B]), compute_uv=False)[-1]
        for lam in np.linalg.eigvals(A)
    )


@settings(max_examples=60, deadline=None)
@given(_plants())
def test_lqr_stabilizes_and_solves_the_riccati_equation(plant) -> None:
    A, B, Q, R = plant
    assume(_pbh_margin(A, B) > 0.05)
    _, S, E = lqr(A, B, Q, R)
    assert np.all(E.real < 0)
    residual = A.T @ S + S @ A - S @ B @ np.linalg.solve(R, B.T @ S) + Q
    assert np.abs(residual).max() <= 1e-7 * max(1.0, np.abs(S).max() * (1 + np.abs(A).max()))
    assert np.all(np.linalg.eigvalsh(S) > -1e-9 * np.abs(S).max())
    F = scipy.linalg.expm(A * 0.05)
    G = np.linalg.solve(A, (F - np.eye(len(A))) @ B) if abs(np.linalg.det(A)) > 1e-3 else None
    if G is not None and _pbh_margin(F, G) > 1e-3:
        _, _, Ed = dlqr(F, G, Q, R)
        assert np.all(np.abs(Ed) < 1)


@pytest.mark.parametrize(("name", "variant"), ACTUATED, ids=IDS)
@pytest.mark.parametrize("rate", [None, 50.0, 200.0])
def test_gain_margins_bound_the_stable_gains(
    name: str, variant: dict[str, str], rate: float | None
) -> None:
    """Independent truth: the closed-loop eigenvalues of A - k B K at the margins of the state
    feedback (``lqr_margins``; the LQG loop's, ``margins``, are tests/control/test_control_margins.py's)."""
    d = design(_system(name, tuple(variant.items())), rate=rate)
    if d.plant.n_inputs != 1:
        pytest.skip("margins are for single-input loops")
    A, B = d.model.A, d.model.B
    mg = d.lqr_margins
    assert d.margins_of("lqr") is mg

    def stable(k: float) -> bool:
        ev = np.linalg.eigvals(A - k * B @ d.K)
        return bool(np.all(np.abs(ev) < 1) if rate else np.all(ev.real < 0))

    assert stable(1.0)
    if mg.gain_lower > 0:
        assert stable(mg.gain_lower * 1.001)
        assert not stable(mg.gain_lower * 0.999)
    else:
        assert stable(1e-3)
    if np.isfinite(mg.gain_upper):
        assert stable(mg.gain_upper * 0.999)
        assert not stable(mg.gain_upper * 1.001)
    else:
        assert rate is None  # a sampled loop always has a finite upper margin
        assert stable(1e3)
    if rate is None:
        gm, pm, _, _, wgc, _ = control.stability_margins(control.ss(A, B, d.K, 0))
        assert mg.phase_margin == pytest.approx(pm, rel=1e-6)
        assert mg.gain_crossover == pytest.approx(wgc, rel=1e-6)
        assert gm == pytest.approx(mg.gain_lower if mg.gain_lower > 0 else np.inf, rel=1e-6)
