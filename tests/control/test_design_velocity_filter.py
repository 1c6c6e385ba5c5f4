"""A Kalman filter designed for the rig's velocity filter (``design(..., velocity_filter=HZ)``):
the extended model against the rig's filter run on its own, the filter's covariance against
scipy's Riccati solver on matrices built here, and the loop as it runs (the plant, the rig's
low-pass of each measured rate, the controller) built from python-control alone."""

from __future__ import annotations

import functools
import math

import control as ct
import numpy as np
import pytest
import scipy.linalg
import scipy.optimize

from equilibrist.control.design import design, kind_design
from equilibrist.control.design_extended import velocity_filtered
from equilibrist.control.linear import LinearController
from equilibrist.errors import ControllerError, DesignError
from equilibrist.numeric.lookup import get_system

#: The DFKI acrobot at 500 Hz measuring its rates too, read through a 20 Hz low-pass.
SYSTEM, RATE, CUTOFF = "dfki_double_pendulum", 500.0, 20.0
OUTPUTS = ("theta1", "theta2", "theta1_dot", "theta2_dot")
RN = (1e-12, 1e-12, 1e-7, 1e-7)


@functools.cache
def _designs(form: str = "current"):
    system = get_system(SYSTEM)
    options = {"rate": RATE, "outputs": OUTPUTS, "rn": RN, "kalman_form": form}
    return design(system, **options), design(system, velocity_filter=CUTOFF, **options)


def _gain() -> float:
    return 1.0 - math.exp(-2.0 * math.pi * CUTOFF / RATE)


def test_the_extended_model_reads_the_rates_as_the_rig_filters_them() -> None:
    """The rig's filter (sim/rig.py, core.c's eq_rig_measure), run here on the rates of a
    trajectory of the sampled plant, gives the readings the extended model measures."""
    d0, d = _designs()
    A, B = d0.discrete.A, d0.discrete.B
    rng = np.random.default_rng(1)
    a = _gain()
    x = rng.normal(size=4) * 0.1
    xi = np.concatenate([x, x[2:]])  # the rig's filter starts at its first reading
    filt = np.zeros(2)
    for k in range(200):
        v = x[2:]
        filt = v.copy() if k == 0 else filt + a * (v - filt)
        np.testing.assert_allclose(d.discrete.C @ xi, np.concatenate([x[:2], filt]),
                                   rtol=1e-11, atol=1e-14)
        u = rng.normal(size=1)
        x = A @ x + B @ u
        xi = d.discrete.A @ xi + d.discrete.B @ u
    assert d.velocity_filter == CUTOFF and d.filtered == ("theta1_dot", "theta2_dot")
    assert d.model_state_names[4:] == ("theta1_dot_filtered", "theta2_dot_filtered")


@pytest.mark.parametrize("form", ["current", "predictor"])
def test_the_kalman_filter_of_the_extended_model_against_scipy(form: str) -> None:
    d0, d = _designs(form)
    A, B, a = d0.discrete.A, d0.discrete.B, _gain()
    Cv = np.eye(4)[2:]
    A_ext = np.block([[A, np.zeros((4, 2))], [a * Cv @ A, (1 - a) * np.eye(2)]])
    C_ext = np.block([[np.eye(4)[:2], np.zeros((2, 2))], [np.zeros((2, 4)), np.eye(2)]])
    np.testing.assert_allclose(d.discrete.A, A_ext, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(d.discrete.B, np.vstack([B, a * Cv @ B]), rtol=1e-14)
    np.testing.assert_array_equal(d.discrete.C, C_ext)
    Qd = scipy.linalg.block_diag(d0.Qd, np.zeros((2, 2)))
    P = scipy.linalg.solve_discrete_are(A_ext.T, C_ext.T, Qd, d0.Rd)
    np.testing.assert_allclose(d.P, P, rtol=1e-6, atol=1e-9 * np.abs(P).max())
    M = P @ C_ext.T @ np.linalg.inv(C_ext @ P @ C_ext.T + d0.Rd)
    gain = M if form == "current" else A_ext @ M
    np.testing.assert_allclose(d.Kf, gain, rtol=1e-5, atol=1e-8 * np.abs(gain).max())
    # The state feedback is the plant's: the filter's states change nothing the plant does.
    np.testing.assert_array_equal(d.K[:, :4], d0.K)
    assert not d.K[:, 4:].any()
    np.testing.assert_allclose(np.sort(np.abs(d.poles)),
                               np.sort(np.abs(np.linalg.eigvals(A_ext - d.discrete.B @ d.K))),
                               atol=1e-9)


def test_the_loop_with_the_rigs_filter_is_the_loop_that_runs() -> None:
    """python-control's loop: the sampled plant, a z / (z - (1 - a)) low-pass on each
    measured rate (the rig's filter), and the LQG that runs; its margins are the design's,
    and its closed loop's poles the state feedback's (with the filter's) and the
    estimator's."""
    _, d = _designs()
    dt = 1.0 / RATE
    a = _gain()
    plant = ct.c2d(ct.ss(d.plant.A, d.plant.B, np.eye(4), np.zeros((4, 1))), dt, "zoh")
    low = ct.ss(ct.tf([a, 0.0], [1.0, -(1.0 - a)], dt))
    one = ct.ss([], [], [], [[1.0]], dt)
    read = ct.append(one, one, low, low)  # positions as they are, rates low-passed
    c = LinearController.from_design(d, kind="lqg")
    own = ct.ss(c.Ac + c.Bu @ c.Cc, c.By + c.Bu @ c.Dy, c.Cc, c.Dy, dt)
    seen = read * plant
    w = np.logspace(-2, np.log10(np.pi / dt), 2_000)[:-1]
    _, pm, sm, _, wgc, _ = ct.stability_margins(ct.frd(-(own * seen), w))
    reported = d.margins
    assert reported is not None
    assert reported.phase_margin == pytest.approx(pm, abs=1e-3)
    assert reported.gain_crossover == pytest.approx(wgc, rel=1e-4)
    assert reported.return_difference == pytest.approx(sm, rel=1e-4)
    poles = ct.feedback(seen, own, sign=1).poles()
    expected = np.concatenate([d.poles, d.estimator_poles])
    rows, cols = scipy.optimize.linear_sum_assignment(
        np.abs(poles[:, None] - expected[None, :]))  # each pole matched with one reported
    assert len(rows) == len(expected) == len(poles)
    assert np.abs(poles[rows] - expected[cols]).max() < 1e-6


def test_no_filter_is_the_design_without_one_to_the_bit() -> None:
    system = get_system(SYSTEM)
    options = {"rate": RATE, "outputs": OUTPUTS, "rn": RN}
    plain, zero = design(system, **options), design(system, velocity_filter=0.0, **options)
    for name in ("K", "S", "Kf", "P", "Kc", "Qd"):
        assert np.array_equal(getattr(plain, name), getattr(zero, name)), name
    assert kind_design(plain, system, {}) is plain and plain.velocity_filter == 0.0


def test_bad_filters_are_named() -> None:
    system = get_system(SYSTEM)
    with pytest.raises(DesignError, match=r"no measured output of .* is a joint's rate"):
        design(system, rate=RATE, velocity_filter=20.0)  # the spec measures positions only
    with pytest.raises(DesignError, match="needs a discrete design"):
        design(system, outputs=OUTPUTS, rn=RN, velocity_filter=20.0)
    for bad in (-1.0, True, math.inf, "20"):
        with pytest.raises(DesignError, match="velocity_filter"):
            design(system, rate=RATE, outputs=OUTPUTS, rn=RN, velocity_filter=bad)
    with pytest.raises(DesignError, match="together are not designed yet"):
        design(system, rate=RATE, outputs=OUTPUTS, rn=RN, velocity_filter=20.0, delay=1)
    _, d = _designs()
    with pytest.raises(DesignError, match="already extended"):
        velocity_filtered(d, 20.0, ("theta1_dot",))
    with pytest.raises(ControllerError, match="an LQR reads the rates as measured"):
        LinearController.from_design(d, kind="lqr")
