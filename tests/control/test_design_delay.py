"""A design for a delayed loop (``design(..., delay=N)``, ``delayed``): the extended model and
its gains against a construction of this file's own (python-control's ``dlqr``, scipy's
Riccati solver, the predictor over the delay), and the loop with the delay closed around the
controller that runs."""

from __future__ import annotations

import functools

import control
import numpy as np
import pytest
import scipy.linalg

from equilibrist.control.design import design
from equilibrist.control.design_extended import delay_periods, delayed
from equilibrist.control.linear import LinearController
from equilibrist.errors import DesignError
from equilibrist.numeric.lookup import get_system

#: A rig on which two periods of delay matter: the double cart-pole at 100 Hz (its
#: undelayed LQR's loop with the delay has a pole at |z| = 1.08).
SYSTEM, RATE, N = "double_cartpole", 100.0, 2


@functools.cache
def _designs(form: str = "current"):
    system = get_system(SYSTEM)
    return design(system, rate=RATE, kalman_form=form), design(system, rate=RATE,
                                                                kalman_form=form, delay=N)


def _extended(A: np.ndarray, B: np.ndarray, periods: int) -> tuple[np.ndarray, np.ndarray]:
    """x_{k+1} = A x_k + B u_{k-N} as a model of [x; u_{k-N}; ...; u_{k-1}], built here."""
    n, m = B.shape
    line = np.eye(periods * m, k=m)  # each command one slot older
    A_ext = np.block([[A, B, np.zeros((n, (periods - 1) * m))],
                      [np.zeros((periods * m, n)), line]])
    B_ext = np.vstack([np.zeros((n + (periods - 1) * m, m)), np.eye(m)])
    return A_ext, B_ext


def test_extended_model_and_lqr_gain_against_python_control() -> None:
    d0, d2 = _designs()
    A, B = d0.discrete.A, d0.discrete.B
    n, m = B.shape
    A_ext, B_ext = _extended(A, B, N)
    np.testing.assert_array_equal(d2.discrete.A, A_ext)
    np.testing.assert_array_equal(d2.discrete.B, B_ext)
    np.testing.assert_array_equal(d2.discrete.C, np.hstack([d0.discrete.C, np.zeros((3, N * m))]))
    assert d2.delay == N and d2.model_state_names[n:] == ("F_sent2", "F_sent1")
    Q_ext = scipy.linalg.block_diag(d0.Q, np.zeros((N * m, N * m)))
    K, S, _ = control.dlqr(A_ext, B_ext, Q_ext, d0.R)
    np.testing.assert_allclose(d2.K, K, rtol=1e-7, atol=1e-9 * np.abs(K).max())
    np.testing.assert_allclose(d2.S, S, rtol=1e-7, atol=1e-9 * np.abs(S).max())
    # A second derivation: the optimal gain is the undelayed one on the state predicted over
    # the delay, x_{k+N} = A^N x_k + sum A^{N-1-j} B u_{k-N+j}.
    predict = np.hstack([np.linalg.matrix_power(A, N)]
                        + [np.linalg.matrix_power(A, N - 1 - j) @ B for j in range(N)])
    np.testing.assert_allclose(d2.K, d0.K @ predict, rtol=1e-7, atol=1e-9 * np.abs(K).max())


@pytest.mark.parametrize("form", ["current", "predictor"])
def test_kalman_filter_of_the_extended_model_against_scipy(form: str) -> None:
    d0, d2 = _designs(form)
    A_ext, _ = _extended(d0.discrete.A, d0.discrete.B, N)
    size = A_ext.shape[0]
    C_ext = d2.discrete.C
    Qd_ext = scipy.linalg.block_diag(d0.Qd, np.zeros((size - d0.Qd.shape[0],) * 2))
    np.testing.assert_array_equal(d2.Qd, Qd_ext)
    P = scipy.linalg.solve_discrete_are(A_ext.T, C_ext.T, Qd_ext, d0.Rd)
    scale = np.abs(P).max()
    np.testing.assert_allclose(d2.P, P, rtol=1e-6, atol=1e-9 * scale)
    M = P @ C_ext.T @ np.linalg.inv(C_ext @ P @ C_ext.T + d0.Rd)
    gain = M if form == "current" else A_ext @ M
    np.testing.assert_allclose(d2.Kf, gain, rtol=1e-6, atol=1e-9 * np.abs(gain).max())
    np.testing.assert_allclose(np.sort(np.abs(d2.estimator_poles)),
                               np.sort(np.abs(np.linalg.eigvals(A_ext - A_ext @ M @ C_ext))),
                               atol=1e-9)


def _loop(ctrl: LinearController, A: np.ndarray, B: np.ndarray, *, where: str) -> np.ndarray:
    """The closed loop's matrix: the plant x+ = A x + B v, a line of N samples between the
    controller and the plant (*where*: the commands, or the measurements), and the
    controller's own form z+ = Ac z + By y + Bu u, u = Cc z + Dy y (deviations), told the
    command it sent. States [x; line; z]."""
    n, m = B.shape
    C = np.eye(n)[[ctrl.state_names.index(o) for o in ctrl.output_names]]
    p, nz = C.shape[0], ctrl.n_z
    width = m if where == "commands" else p
    line = N * width
    size = n + line + nz
    # Rows: what each state is next, as a map of [x; line; z] (and u where u enters).
    shift = np.eye(line, k=width)  # slot j takes slot j+1; the last slot takes the new value
    enter = np.vstack([np.zeros((line - width, width)), np.eye(width)])
    oldest = np.hstack([np.eye(width), np.zeros((width, line - width))])
    if where == "commands":
        y = np.hstack([C, np.zeros((p, line)), np.zeros((p, nz))])
    else:
        y = np.hstack([np.zeros((p, n)), oldest, np.zeros((p, nz))])
    u = ctrl.Cc @ np.hstack([np.zeros((nz, n + line)), np.eye(nz)]) + ctrl.Dy @ y
    acts = u if where != "commands" else np.hstack([np.zeros((m, n)), oldest,
                                                    np.zeros((m, nz))])
    x_next = A @ np.hstack([np.eye(n), np.zeros((n, line + nz))]) + B @ acts
    line_state = np.hstack([np.zeros((line, n)), np.eye(line), np.zeros((line, nz))])
    line_next = shift @ line_state + enter @ (u if where == "commands" else
                                             np.hstack([C, np.zeros((p, line + nz))]))
    z_next = ctrl.Ac @ np.hstack([np.zeros((nz, n + line)), np.eye(nz)]) + ctrl.By @ y \
        + ctrl.Bu @ u
    loop = np.vstack([x_next, line_next, z_next])
    assert loop.shape == (size, size)
    return loop


@pytest.mark.parametrize("kind", ["lqr", "lqg"])
@pytest.mark.parametrize("where", ["commands", "measurements"])
def test_the_delayed_loop_is_stable_only_with_the_design_delay(kind: str, where: str) -> None:
    d0, d2 = _designs()
    A, B = d0.discrete.A, d0.discrete.B
    with_delay = LinearController.from_design(d2, kind=kind)
    without = LinearController.from_design(d0, kind=kind)
    radius = np.abs(np.linalg.eigvals(_loop(with_delay, A, B, where=where))).max()
    radius_without = np.abs(np.linalg.eigvals(_loop(without, A, B, where=where))).max()
    assert radius < 0.995
    assert radius_without > 1.0
    # The state feedback's poles are the undelayed design's, and N samples' worth at 0.
    if kind == "lqr":
        poles = np.linalg.eigvals(_loop(with_delay, A, B, where=where))
        slow = np.sort_complex(poles[np.abs(poles) > 1e-2])  # a repeated 0 splits by ~1e-4
        np.testing.assert_allclose(slow, np.sort_complex(d0.poles), atol=1e-7)


def test_delayed_lqr_margins_are_its_implemented_loop() -> None:
    """The delayed LQR's margins are those of its loop as it runs, broken at the plant's
    input: the plant with its delay line, in series with the controller whose record of the
    commands is fed its own command (python-control's margins of that loop, built here)."""
    _, d2 = _designs()
    ctrl = LinearController.from_design(d2, kind="lqr")
    A_ext, B_ext = d2.discrete.A, d2.discrete.B
    n, dt = ctrl.n_states, 1.0 / RATE
    # The loop's states: the plant with its line [x; line], then the controller's record z.
    nz = ctrl.n_z
    Cx = np.eye(A_ext.shape[0])[:n]
    A = np.block([[A_ext, np.zeros((A_ext.shape[0], nz))],
                  [ctrl.Bu @ ctrl.Dy @ Cx, ctrl.Ac + ctrl.Bu @ ctrl.Cc]])
    B = np.vstack([B_ext, np.zeros((nz, 1))])
    C = -np.hstack([ctrl.Dy @ Cx, ctrl.Cc])  # returns -u
    w = np.linspace(1e-3, np.pi / dt, 40_001)[:-1]
    z = np.exp(1j * w * dt)
    L = np.array([(C @ np.linalg.solve(zk * np.eye(A.shape[0]) - A, B))[0, 0] for zk in z])
    margins = d2.lqr_margins
    assert margins is not None
    assert margins.return_difference == pytest.approx(np.abs(1 + L).min(), rel=1e-3)
    cross = np.flatnonzero(np.diff(np.sign(np.abs(L) - 1.0)))
    phase = [180.0 + np.degrees(np.angle(L[i])) for i in cross]
    assert margins.phase_margin == pytest.approx(min(phase, key=abs), abs=0.5)


def test_zero_delay_is_the_design_without_one_to_the_bit() -> None:
    system = get_system(SYSTEM)
    plain, zero = design(system, rate=RATE), design(system, rate=RATE, delay=0)
    for name in ("K", "S", "Kf", "P", "Kc", "Qd"):
        assert np.array_equal(getattr(plain, name), getattr(zero, name)), name
    assert delayed(plain, 0) is plain and plain.delay == 0
    for kind in ("lqr", "lqg"):
        assert (LinearController.from_design(zero, kind=kind).fingerprint
                == LinearController.from_design(plain, kind=kind).fingerprint)


def test_bad_delays_are_named() -> None:
    system = get_system(SYSTEM)
    for bad in (-1, True, 1.5, "2"):
        with pytest.raises(DesignError, match="delay"):
            design(system, rate=RATE, delay=bad)
    with pytest.raises(DesignError, match="needs a discrete design"):
        design(system, delay=1)
    _, d2 = _designs()
    with pytest.raises(DesignError, match="already compensates a delay of 2"):
        delayed(d2, 1)
    assert delay_periods("4ms", 500.0) == 2 and delay_periods("0.02s", 100.0) == 2
    assert delay_periods("3", 100.0) == 3 and delay_periods(0, 100.0) == 0
    with pytest.raises(DesignError, match=r"0\.5 control periods at 100 Hz"):
        delay_periods("5ms", 100.0)
    for bad_text in ("-1", "x", "2 periods"):
        with pytest.raises(DesignError, match="expected a whole number"):
            delay_periods(bad_text, 100.0)


def test_the_designs_own_library_refuses_a_delayed_design_naming_the_export_that_takes_it(
        tmp_path) -> None:
    from equilibrist.errors import ExportError
    from equilibrist.export.writer import export_c

    _, d2 = _designs()
    with pytest.raises(ExportError, match=r"a loop 2 period\(s\) late.*export_controller\("):
        export_c(d2, tmp_path / "late")
    assert not (tmp_path / "late").exists()  # nothing half-written
