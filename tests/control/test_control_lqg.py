"""Reference gain, LQG compensator and python-control interop.

Independent truths: the closed loop of plant and compensator simulated (or
assembled by python-control's ``interconnect`` from the named signals)
settles the tracked output at the reference; its poles are the union of the
regulator's and the estimator's (separation principle).
"""

from __future__ import annotations

import functools

import control
import numpy as np
import pytest
import scipy.linalg

from equilibrist.control import (
    design,
    discrete_reference_gain,
    from_statespace,
    lqg_compensator,
    lqr,
    reference_gain,
    to_statespace,
)
from equilibrist.errors import DesignError, DimensionError
from equilibrist.numeric.lookup import get_system

CASES = [(None, "current"), (100.0, "current"), (100.0, "predictor")]


@functools.cache
def _design(rate: float | None, form: str, outputs: tuple[str, ...] | None = None):
    return design(get_system("cartpole"), rate=rate, kalman_form=form, outputs=outputs)


def _sorted(values: np.ndarray) -> np.ndarray:
    v = np.asarray(values, dtype=complex)
    return v[np.lexsort((np.round(v.imag, 9), np.round(v.real, 9)))]


def _closed_loop(d, comp) -> tuple[np.ndarray, np.ndarray]:
    """Plant + compensator with u fed back: state [x, xhat], input r."""
    plant = d.model
    m, p = plant.n_inputs, plant.n_outputs
    Bu, By, Br = comp.B[:, :m], comp.B[:, m : m + p], comp.B[:, m + p :]
    Du, Dy, Dr = comp.D[:, :m], comp.D[:, m : m + p], comp.D[:, m + p :]
    assert np.all(Du == 0)
    # u = C_c xhat + Dy y + Dr r, with y = C x (D = 0).
    u_x, u_xh, u_r = Dy @ plant.C, comp.C, Dr
    A = np.block(
        [
            [plant.A + plant.B @ u_x, plant.B @ u_xh],
            [By @ plant.C + Bu @ u_x, comp.A + Bu @ u_xh],
        ]
    )
    B = np.vstack([plant.B @ u_r, Br + Bu @ u_r])
    return A, B


@pytest.mark.parametrize(("rate", "form"), CASES)
def test_closed_loop_poles_are_regulator_and_estimator_poles(rate: float | None, form: str) -> None:
    d = _design(rate, form)
    A, _ = _closed_loop(d, d.compensator)
    expected = np.concatenate([d.poles, d.estimator_poles])
    np.testing.assert_allclose(
        _sorted(np.linalg.eigvals(A)), _sorted(expected), rtol=1e-6, atol=1e-8
    )


@pytest.mark.parametrize(("rate", "form"), CASES)
def test_tracked_output_settles_at_the_reference(rate: float | None, form: str) -> None:
    d = _design(rate, form)
    assert d.tracked == ("x",)
    A, B = _closed_loop(d, d.compensator)
    r = np.array([0.3])
    if rate is None:
        steps = int(30 / 0.01)
        F = scipy.linalg.expm(A * 0.01)
        G = np.linalg.solve(A, (F - np.eye(len(A))) @ B)
    else:
        steps = int(30 * rate)
        F, G = A, B
    z = np.zeros(len(A))
    for _ in range(steps):
        z = F @ z + G @ r
    x = z[:4]
    assert x[0] == pytest.approx(0.3, abs=1e-9)
    np.testing.assert_allclose(x[1:], 0.0, atol=1e-9)
    np.testing.assert_allclose(z[4:], x, atol=1e-9)  # the estimate agrees


def test_reference_gain_formulas() -> None:
    d = _design(None, "current")
    A, B, C = d.plant.A, d.plant.B, d.plant.C
    Kc = reference_gain(A, B, C[:1], d.K)
    dc = C[:1] @ np.linalg.solve(A - B @ d.K, B)
    assert Kc[0, 0] == pytest.approx(-1 / dc[0, 0])
    np.testing.assert_allclose(d.Kc, Kc)
    dd = _design(100.0, "current")
    F, G = dd.discrete.A, dd.discrete.B
    Kcd = discrete_reference_gain(F, G, C[:1], dd.K)
    dcd = C[:1] @ np.linalg.solve(np.eye(4) - (F - G @ dd.K), G)
    assert Kcd[0, 0] == pytest.approx(1 / dcd[0, 0])


def test_reference_gain_with_several_inputs() -> None:
    rng = np.random.default_rng(4)
    A = rng.normal(size=(4, 4))
    B = rng.normal(size=(4, 2))
    K, _, _ = lqr(A, B, np.eye(4), np.eye(2))
    Cr = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
    Kc = reference_gain(A, B, Cr, K)
    x_ss = -np.linalg.solve(A - B @ K, B @ Kc @ np.array([0.2, -0.7]))
    np.testing.assert_allclose(Cr @ x_ss, [0.2, -0.7], atol=1e-12)


def test_zero_dc_gain_is_named_not_infinite() -> None:
    d = _design(None, "current", ("theta", "x"))
    assert d.Kc is None
    assert d.tracked == ("theta",)
    assert "tracked output theta has zero DC gain from F" in d.kc_note
    with pytest.raises(DesignError, match="tracked output theta has zero DC gain"):
        reference_gain(
            d.plant.A, d.plant.B, d.plant.C[:1], d.K, tracked_names=["theta"], input_names=["F"]
        )
    # Without a reference gain the compensator has no r input.
    assert d.compensator.input_names == ("u_F", "y_theta", "y_x")
    with pytest.raises(DimensionError, match="one tracked output per input"):
        reference_gain(d.plant.A, d.plant.B, d.plant.C, d.K)


def test_from_statespace_round_trip() -> None:
    d = _design(100.0, "current")
    back = from_statespace(
        to_statespace(d.discrete), x0=d.plant.x0, u0=d.plant.u0, system="cartpole"
    )
    np.testing.assert_array_equal(back.A, d.discrete.A)
    np.testing.assert_array_equal(back.B, d.discrete.B)
    assert back.state_names == d.discrete.state_names
    assert back.output_names == d.discrete.output_names
    assert back.dt == d.dt
    cont = from_statespace(to_statespace(d.plant))
    assert cont.dt is None
    with pytest.raises(DesignError, match="dt=True"):
        from_statespace(control.ss([[0.0]], [[1.0]], [[1.0]], [[0.0]], True))


def test_current_form_compensator_equals_filter_then_feedback() -> None:
    d = _design(100.0, "current")
    comp, kf = d.compensator, d.kalman_filter
    rng = np.random.default_rng(2)
    xpred = rng.normal(size=4) * 0.01
    y = rng.normal(size=2) * 0.01
    r = np.array([0.1])
    u = comp.output(xpred, np.zeros(1), y, r)
    xhat = xpred + d.Kf @ (y - kf.H @ xpred)
    np.testing.assert_allclose(u, -d.K @ xhat + d.Kc @ r, rtol=1e-12)
    nxt = comp.A @ xpred + comp.B @ np.concatenate([u, y, r])
    np.testing.assert_allclose(nxt, kf.F @ xhat + kf.B @ u, rtol=1e-12, atol=1e-15)


def test_compensator_validation() -> None:
    d = _design(None, "current")
    with pytest.raises(DimensionError, match="Kf has shape"):
        lqg_compensator(d.plant, d.K, d.Kf.T)
    with pytest.raises(DesignError, match="continuous plant has no Kalman form 'predictor'"):
        lqg_compensator(d.plant, d.K, d.Kf, form="predictor")
