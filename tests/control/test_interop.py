"""python-control wires a design's plant and compensator by their names.

Independent truths: the loop python-control assembles from the named signals
alone has the regulator's and the estimator's poles (separation principle) and
settles the tracked output at its reference (the reference gain's definition);
the loop broken at the plant input, built by python-control's ``interconnect``
from the same two systems (not :func:`loop_at_input`'s own assembly), has the
margins the design reports, computed by python-control.
"""

from __future__ import annotations

import functools
import warnings

import control as ct
import numpy as np
import pytest

from equilibrist.control.design import design
from equilibrist.control.design_record import Design
from equilibrist.control.interop import loop_at_input, to_statespace
from equilibrist.errors import DesignError
from equilibrist.numeric.lookup import get_system

RATES = [None, 200.0]
IDS = ["continuous", "200Hz"]


@functools.cache
def _design(rate: float | None) -> Design:
    return design(get_system("cartpole"), rate=rate)


def _sorted(values: np.ndarray) -> np.ndarray:
    v = np.asarray(values, dtype=complex)
    return v[np.lexsort((np.round(v.imag, 7), np.round(v.real, 7)))]


@pytest.mark.parametrize("rate", RATES, ids=IDS)
def test_plant_and_compensator_share_timebase_and_names(rate: float | None) -> None:
    d = _design(rate)
    plant, comp = to_statespace(d), to_statespace(d.compensator)
    expected_dt = 0 if rate is None else 1 / rate
    assert plant.dt == expected_dt and comp.dt == expected_dt
    assert plant.name == "cartpole"
    assert plant.input_labels == ["F"]
    assert plant.output_labels == ["x", "theta"]
    assert comp.input_labels == ["x", "theta", "r_x"]
    assert comp.output_labels == ["F"]
    assert comp.state_labels == ["xhat_x", "xhat_theta", "xhat_x_dot", "xhat_theta_dot"]


@pytest.mark.parametrize("rate", RATES, ids=IDS)
def test_interconnect_closes_the_loop_by_name(rate: float | None) -> None:
    d = _design(rate)
    plant, comp = to_statespace(d), to_statespace(d.compensator)
    loop = ct.interconnect([plant, comp], inplist=["r_x"], outlist=["x", "theta"])
    expected = _sorted(np.concatenate([d.poles, d.estimator_poles]))
    np.testing.assert_allclose(_sorted(loop.poles()), expected, rtol=1e-6, atol=1e-8)
    # The reference gain puts the cart where it is asked, and the pendulum upright.
    np.testing.assert_allclose(np.ravel(loop.dcgain()), [1.0, 0.0], atol=1e-9)
    # Feedback with the references at zero: the same poles.
    closed = ct.feedback(plant, comp[:, plant.output_labels], sign=1)
    np.testing.assert_allclose(_sorted(closed.poles()), expected, rtol=1e-6, atol=1e-8)


@pytest.mark.parametrize("rate", RATES, ids=IDS)
def test_margins_of_the_loop_wired_by_name_are_the_reported(rate: float | None) -> None:
    d = _design(rate)
    plant, comp = to_statespace(d), to_statespace(d.compensator)
    # Broken at the plant input: F into the plant, the command it brings back out, in
    # negative feedback (L returns minus the command); the compensator's inputs are picked by
    # the plant's output names.
    loop = -(comp[:, plant.output_labels] * plant)
    mg = d.margins
    assert mg is not None
    nearer_gain = mg.gain_lower if abs(np.log(mg.gain_lower)) < abs(np.log(mg.gain_upper)) \
        else mg.gain_upper
    with warnings.catch_warnings():
        # Sampled loops: python-control falls back to an interpolated response, and says so.
        warnings.simplefilter("ignore", UserWarning)
        gm, pm, sm, _, wgc, _ = ct.stability_margins(loop)
    rel = 1e-6 if rate is None else 1e-3  # its coarse interpolation in discrete time
    assert gm == pytest.approx(nearer_gain, rel=rel)
    assert pm == pytest.approx(mg.phase_margin, rel=rel)
    assert wgc == pytest.approx(mg.gain_crossover, rel=rel)
    if rate is None:  # the |1 + L| minimum of the interpolation is not reliable
        assert sm == pytest.approx(mg.return_difference, rel=rel)
    # And loop_at_input is that loop.
    points = 1j * np.array([0.5, 3.0, 20.0]) if rate is None else np.exp(
        1j * np.array([0.5, 3.0, 20.0]) / rate)
    np.testing.assert_allclose(loop_at_input(d)(points), loop(points), rtol=1e-8)


def test_to_statespace_refuses_what_it_cannot_convert() -> None:
    with pytest.raises(DesignError, match="LinearModel, a Compensator or a Design, got str"):
        to_statespace("cartpole")  # type: ignore[arg-type]


@functools.cache
def _delayed(periods: int) -> tuple[Design, Design]:
    """The double cart-pole at 100 Hz: a design without a delay and one for *periods*."""
    system = get_system("double_cartpole")
    return design(system, rate=100.0), design(system, rate=100.0, delay=periods)


def _dense_margins(loop: ct.StateSpace | ct.TransferFunction) -> tuple[float, ...]:
    """python-control's margins of the loop's response on a grid up to the Nyquist frequency
    (its default's interpolation is coarse for sampled loops; on the grid it refines each
    crossover)."""
    w = np.logspace(-2, np.log10(np.pi / loop.dt), 2_000)[:-1]
    gm, pm, sm, _, wgc, _ = ct.stability_margins(ct.frd(loop, w))
    return gm, pm, sm, wgc


@pytest.mark.parametrize("kind", ["lqr", "lqg"])
def test_a_delayed_designs_loop_is_the_loop_that_runs(kind: str) -> None:
    """The loop broken at the plant's input of a design for two periods, built here from
    python-control alone: the continuous plant sampled by ``c2d``, two samples of delay
    (``z^-2``), and the controller that runs (``LinearController.from_design``, its record
    of the commands fed its own command). ``loop_at_input``, the design's margins, its
    ``--json`` and its closed-loop poles are that loop's."""
    from equilibrist.control.linear import LinearController

    d0, d = _delayed(2)
    dt = 1.0 / 100.0
    C = np.eye(d.plant.n_states) if kind == "lqr" else d.plant.C  # what the controller reads
    plant = ct.c2d(ct.ss(d.plant.A, d.plant.B, C, np.zeros((C.shape[0], 1))), dt, "zoh")
    late = ct.tf([1.0], [1.0, 0.0, 0.0], dt)
    c = LinearController.from_design(d, kind=kind)
    own = ct.ss(c.Ac + c.Bu @ c.Cc, c.By + c.Bu @ c.Dy, c.Cc, c.Dy, dt)  # fed its own command
    truth = -(own * plant * late)
    gm, pm, sm, wgc = _dense_margins(truth)
    assert 10.0 < pm < 40.0  # the loop two periods late has a small margin (not 51 degrees)
    ours = _dense_margins(loop_at_input(d, controller=kind))
    np.testing.assert_allclose(ours, (gm, pm, sm, wgc), rtol=1e-6)
    reported = d.margins_of(kind)
    assert reported is not None
    nearer = min(reported.gain_lower, reported.gain_upper, key=lambda g: abs(np.log(g)))
    assert nearer == pytest.approx(gm, rel=1e-4)
    assert reported.phase_margin == pytest.approx(pm, abs=1e-3)
    assert reported.return_difference == pytest.approx(sm, rel=1e-4)
    as_json = d.to_dict(controller=kind)["margins"]
    assert isinstance(as_json, dict) and as_json["phase_margin_deg"] == pytest.approx(pm, abs=1e-3)
    # The closed loop (python-control's feedback, the controller's sign its own) has the
    # poles the design reports: the state feedback's, and the estimator's for the LQG, the
    # controller's record of the commands (LQR) adding poles at z = 0.
    poles = ct.feedback(plant * late, own, sign=1).poles()
    expected = np.concatenate([d.poles, d.estimator_poles if kind == "lqg" else np.zeros(2)])
    slow = np.abs(poles) > 1e-2  # a repeated pole at 0 splits by ~1e-4 in a computed eig
    np.testing.assert_allclose(_sorted(poles[slow]),
                               _sorted(expected[np.abs(expected) > 1e-2]), atol=1e-7)
    assert np.count_nonzero(~slow) == np.count_nonzero(np.abs(expected) <= 1e-2)
    # Those poles at 0 are exact: the undelayed design's and the delay's samples.
    np.testing.assert_allclose(_sorted(d.poles[np.abs(d.poles) > 0]), _sorted(d0.poles),
                               atol=1e-7)
