"""The margins a design reports are those of the loop as implemented, broken at the plant input.

For an LQG design that loop is the compensator (its Kalman filter fed its own command,
``u = -K xhat``) in series with the plant, continuous or in its discrete form at the design's
rate; the state feedback's alone, ``K (sI - A)^-1 B``, is ``lqr_margins``. Independent truth:
python-control's ``stability_margins`` of the loop built here by hand from the design's
matrices (``A, B, C, K, Kf`` and the discretization, sampled here with scipy), on its exact
polynomials for a continuous loop and on a dense frequency response for a sampled one (its
polynomial method fails on the cart's poles at ``z = 1``).
"""

from __future__ import annotations

import functools
import json
import warnings

import control as ct
import numpy as np
import pytest
import scipy.linalg

from equilibrist.cli.main import main
from equilibrist.control import Design, Margins, design, loop_at_input
from equilibrist.control.linear import LinearController
from equilibrist.errors import DesignError
from equilibrist.numeric.lookup import get_system

# (rate, Kalman form, discretization): continuous, the cart-pole's 200 Hz default, and the
# other forms of the compensator.
CASES = [
    (None, "current", "zoh"),
    (200.0, "current", "zoh"),
    (100.0, "predictor", "zoh"),
    (50.0, "current", "euler"),
]
IDS = ["continuous", "200Hz-current", "100Hz-predictor", "50Hz-euler"]


@functools.cache
def _design(rate: float | None, form: str = "current", method: str = "zoh") -> Design:
    return design(get_system("cartpole"), rate=rate, kalman_form=form, discretization=method)


def _sampled(d: Design) -> tuple[np.ndarray, np.ndarray]:
    """The plant's ``Ad, Bd`` sampled by hand (ZOH by the matrix exponential, or Euler)."""
    A, B = d.plant.A, d.plant.B
    n, m = B.shape
    dt = 1.0 / float(d.rate)  # type: ignore[arg-type]
    if d.discretization == "euler":
        return np.eye(n) + A * dt, B * dt
    E = scipy.linalg.expm(np.block([[A, B], [np.zeros((m, n + m))]]) * dt)
    return E[:n, :n], E[:n, n:]


def _hand_loop(d: Design) -> ct.StateSpace:
    """``L = C(s) P(s)`` in negative feedback, the controller written out from the equations.

    Continuous: ``xhat' = A xhat + B u + Kf (y - C xhat)``, ``u = -K xhat``. Discrete
    ``"current"``: ``xhat = xpred + M (y - C xpred)``, ``u = -K xhat``,
    ``xpred+ = Ad xhat + Bd u``. ``"predictor"``: ``u = -K xhat``,
    ``xhat+ = Ad xhat + Bd u + L (y - C xhat)``. The controller block maps ``y`` to ``-u``.
    """
    A, B, C = d.plant.A, d.plant.B, d.plant.C
    K, G = d.K, d.Kf
    n = A.shape[0]
    if d.rate is None:
        return ct.ss(A - B @ K - G @ C, G, K, 0) * ct.ss(A, B, C, 0)
    dt = 1.0 / d.rate
    Ad, Bd = _sampled(d)
    F = Ad - Bd @ K
    if d.kalman_form == "current":
        correct = np.eye(n) - G @ C
        controller = ct.ss(F @ correct, F @ G, K @ correct, K @ G, dt)
    else:
        controller = ct.ss(F - G @ C, G, K, 0, dt)
    return controller * ct.ss(Ad, Bd, C, 0, dt)


def _hand_state_feedback(d: Design) -> ct.StateSpace:
    if d.rate is None:
        return ct.ss(d.plant.A, d.plant.B, d.K, 0)
    Ad, Bd = _sampled(d)
    return ct.ss(Ad, Bd, d.K, 0, 1.0 / d.rate)


def _truth(loop: ct.StateSpace) -> dict[str, float]:
    """python-control's margins of *loop*, as :class:`Margins` names them."""
    if loop.isctime():
        gm, pm, sm, wpc, wgc, _ = ct.stability_margins(loop, returnall=True)
    else:
        # Its exact response on a dense grid below the Nyquist frequency.
        w = np.logspace(-2, np.log10(np.pi / loop.dt), 5000)[:-1]
        gm, pm, sm, wpc, wgc, _ = ct.stability_margins(ct.frd(loop, w), returnall=True)
    lower = [(g, x) for g, x in zip(gm, wpc, strict=True) if g < 1]
    upper = [(g, x) for g, x in zip(gm, wpc, strict=True) if g >= 1]
    i = int(np.argmin(np.abs(pm)))
    return {
        "gain_lower": max(lower)[0] if lower else 0.0,
        "lower_crossover": max(lower)[1] if lower else np.nan,
        "gain_upper": min(upper)[0] if upper else np.inf,
        "upper_crossover": min(upper)[1] if upper else np.nan,
        "phase_margin": float(pm[i]),
        "gain_crossover": float(wgc[i]),
        "return_difference": float(np.min(sm)) if len(sm) else np.inf,
    }


def _assert_margins(mg: Margins, truth: dict[str, float], rel: float = 1e-6) -> None:
    for key, value in truth.items():
        assert getattr(mg, key) == pytest.approx(value, rel=rel, nan_ok=True), key


# What python-control measures on the hand-built loop of the cart-pole's default LQG (the
# figures the report printed before were the state feedback's: 63.05 deg, x0.397).
MEASURED = {
    None: {"phase_margin": 33.076, "gain_crossover": 7.7131, "gain_lower": 0.55672,
           "lower_crossover": 2.5705, "gain_upper": 3.8746, "return_difference": 0.55751},
    200.0: {"phase_margin": 33.056, "gain_crossover": 7.7107, "gain_lower": 0.55689,
            "lower_crossover": 2.5704, "gain_upper": 3.8647, "return_difference": 0.55718},
}


@pytest.mark.parametrize("rate", [None, 200.0], ids=["continuous", "200Hz"])
def test_cartpole_lqg_margins_are_its_loop_with_the_kalman_filter(rate: float | None) -> None:
    d = _design(rate)
    truth = _truth(_hand_loop(d))
    for key, value in MEASURED[rate].items():
        assert truth[key] == pytest.approx(value, rel=2e-4), key
    _assert_margins(d.margins, truth)
    # Half the state feedback's phase margin, and less room to reduce the gain.
    assert d.lqr_margins.phase_margin > 60.0
    assert d.margins.phase_margin < d.lqr_margins.phase_margin - 25.0
    assert d.margins.gain_lower > d.lqr_margins.gain_lower + 0.1


@pytest.mark.parametrize(("rate", "form", "method"), CASES, ids=IDS)
def test_margins_match_the_hand_built_loop(rate: float | None, form: str, method: str) -> None:
    d = _design(rate, form, method)
    _assert_margins(d.margins, _truth(_hand_loop(d)))
    assert d.margins_of("lqg") is d.margins


@pytest.mark.parametrize(("rate", "form", "method"), CASES, ids=IDS)
def test_lqr_margins_are_the_state_feedback(rate: float | None, form: str, method: str) -> None:
    d = _design(rate, form, method)
    truth = _truth(_hand_state_feedback(d))
    if rate is not None:
        # The dense grid stops short of Nyquist, where a sampled loop's upper margin is.
        for key in ("gain_upper", "upper_crossover", "return_difference"):
            truth.pop(key)
        assert d.lqr_margins.upper_crossover == pytest.approx(np.pi * rate)
    else:
        # |1 + L| tends to its infimum 1 (Kalman's inequality) at infinity: no minimum to find.
        assert truth.pop("return_difference") == np.inf
        assert d.lqr_margins.return_difference == pytest.approx(1.0, abs=1e-6)
    _assert_margins(d.lqr_margins, truth)
    assert d.margins_of("lqr") is d.lqr_margins


@pytest.mark.parametrize(("rate", "form", "method"), CASES, ids=IDS)
def test_loop_at_input_is_the_hand_built_loop(rate: float | None, form: str, method: str) -> None:
    d = _design(rate, form, method)
    loop, hand = loop_at_input(d), _hand_loop(d)
    assert isinstance(loop, ct.StateSpace)
    assert loop.dt == (0 if rate is None else pytest.approx(1.0 / rate))
    assert loop.input_labels == ["F"] and loop.output_labels == ["F_return"]
    assert loop.nstates == 8
    w = np.logspace(-2, np.log10(0.9 * np.pi * rate if rate else 1e3), 40)
    points = 1j * w if rate is None else np.exp(1j * w / rate)
    np.testing.assert_allclose(loop(points), hand(points), rtol=1e-8)
    # And the state feedback.
    lqr, hand_lqr = loop_at_input(d, controller="lqr"), _hand_state_feedback(d)
    np.testing.assert_allclose(lqr(points), hand_lqr(points), rtol=1e-8)


@pytest.mark.parametrize(("rate", "form", "method"), CASES[1:], ids=IDS[1:])
def test_loop_at_input_is_what_the_simulator_runs(rate: float, form: str, method: str) -> None:
    """The controller the simulator and the C export run (``LinearController``'s ``Ac, Bu, By,
    Cc, Dy``; its LQG is always discrete), fed its own command, in series with the sampled
    plant: the same loop."""
    d = _design(rate, form, method)
    c = LinearController.from_design(d, kind="lqg")
    dt = 1.0 / rate
    runs = ct.ss(c.Ac + c.Bu @ c.Cc, c.By + c.Bu @ c.Dy, -c.Cc, -c.Dy, dt)
    Ad, Bd = _sampled(d)
    loop = runs * ct.ss(Ad, Bd, d.plant.C, 0, dt)
    points = np.exp(1j * np.logspace(-2, np.log10(0.9 * np.pi / dt), 40) * dt)
    np.testing.assert_allclose(loop_at_input(d)(points), loop(points), rtol=1e-8)


@pytest.mark.parametrize(("rate", "form", "method"), CASES, ids=IDS)
def test_python_control_margins_of_loop_at_input_are_the_reported(
    rate: float | None, form: str, method: str
) -> None:
    d = _design(rate, form, method)
    mg, loop = d.margins, loop_at_input(d)
    with warnings.catch_warnings():
        # Sampled loops: python-control falls back to an interpolated response, and says so.
        warnings.simplefilter("ignore", UserWarning)
        gm, pm, sm, wpc, wgc, _ = ct.stability_margins(loop)
    nearer = (mg.gain_lower, mg.lower_crossover) if abs(np.log(mg.gain_lower)) < abs(
        np.log(mg.gain_upper)) else (mg.gain_upper, mg.upper_crossover)
    rel = 1e-6 if rate is None else 1e-3  # its coarse interpolation in discrete time
    assert gm == pytest.approx(nearer[0], rel=rel)
    assert wpc == pytest.approx(nearer[1], rel=rel)
    assert pm == pytest.approx(mg.phase_margin, rel=rel)
    assert wgc == pytest.approx(mg.gain_crossover, rel=rel)
    if rate is None:
        assert sm == pytest.approx(mg.return_difference, rel=rel)
    else:
        # On a dense grid, to rounding (the docstring's recipe).
        _assert_margins(mg, _truth(loop))


@pytest.mark.parametrize("rate", [None, 200.0], ids=["continuous", "200Hz"])
def test_gain_margins_bound_the_stable_gains_of_the_lqg_loop(rate: float | None) -> None:
    """Independent truth: the closed-loop poles of the hand-built loop with its gain scaled."""
    d = _design(rate)
    hand = _hand_loop(d)
    mg = d.margins

    def stable(k: float) -> bool:
        poles = ct.feedback(k * hand).poles()
        return bool(np.all(np.abs(poles) < 1) if rate else np.all(poles.real < 0))

    assert stable(1.0)
    assert stable(mg.gain_lower * 1.001) and not stable(mg.gain_lower * 0.999)
    assert stable(mg.gain_upper * 0.999) and not stable(mg.gain_upper * 1.001)


def test_loop_at_input_refuses_another_controller() -> None:
    with pytest.raises(DesignError, match="mpc"):
        loop_at_input(_design(None), controller="mpc")
    with pytest.raises(DesignError, match="swingup"):
        _design(None).margins_of("swingup")


def _cli_json(capsys: pytest.CaptureFixture[str], *args: str) -> dict:
    assert main(["design", "cartpole", *args, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("rate", [None, 200.0], ids=["continuous", "200Hz"])
def test_design_json_margins_and_lqr_margins(capsys: pytest.CaptureFixture[str],
                                             rate: float | None) -> None:
    args = () if rate is None else ("--rate", f"{rate:g}")
    data = _cli_json(capsys, *args)
    truth = _truth(_hand_loop(_design(rate)))
    lqr_truth = _truth(_hand_state_feedback(_design(rate)))
    assert data["margins"]["phase_margin_deg"] == pytest.approx(truth["phase_margin"], rel=1e-6)
    assert data["margins"]["gain_crossover"] == pytest.approx(truth["gain_crossover"], rel=1e-6)
    assert data["margins"]["gain_lower"] == pytest.approx(truth["gain_lower"], rel=1e-6)
    assert data["margins"]["gain_upper"] == pytest.approx(truth["gain_upper"], rel=1e-6)
    assert data["lqr_margins"]["phase_margin_deg"] == pytest.approx(
        lqr_truth["phase_margin"], rel=1e-6)
    assert data["lqr_margins"]["gain_lower"] == pytest.approx(lqr_truth["gain_lower"], rel=1e-6)
    # An LQR's loop as implemented is the state feedback.
    lqr = _cli_json(capsys, *args, "--controller", "lqr")
    assert lqr["margins"] == lqr["lqr_margins"] == data["lqr_margins"]


def test_design_text_names_the_two_loops(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["design", "cartpole"]) == 0
    text = capsys.readouterr().out
    implemented = text.index("loop broken at the input, as implemented (LQG")
    alone = text.index("state feedback alone (LQR loop K (sI - A)^-1 B")
    assert implemented < text.index("phase margin: 33.08 deg at 7.713 rad/s") < alone
    assert alone < text.index("phase margin: 63.05 deg at 11.31 rad/s")
    assert "x0.5567" in text[implemented:alone]
    assert main(["design", "cartpole", "--controller", "lqr"]) == 0
    text = capsys.readouterr().out
    assert "as implemented (LQR: u = -K x" in text
    assert "phase margin: 63.05 deg" in text and "33.08" not in text
    assert "state feedback alone" not in text
