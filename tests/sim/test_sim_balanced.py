"""'Ends balanced and stays': the batch's balanced_since, fraction_balanced and time to balance
(equilibrist.tasks.balance_box), checked against the recorded trajectories read by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from equilibrist.control.design import design
from equilibrist.control.linear import LinearController
from equilibrist.control.swingup import swingup
from equilibrist.numeric.lookup import get_system
from equilibrist.sim import Noise, simulate_batch
from equilibrist.tasks import BALANCED_ANGLE, BALANCED_RATE, balance_box


def _by_hand(states: np.ndarray, x_op: np.ndarray, rate: float, angles: list[int],
             rates: list[int]) -> float:
    """The time from which every angle is within 0.1 rad (modulo a turn) and every rate within
    0.5 rad/s to the end, NaN if the last sample is outside: a plain loop, math.remainder."""
    since = math.nan
    for k, x in enumerate(states):
        ok = all(abs(math.remainder(x[i] - x_op[i], 2 * math.pi)) <= BALANCED_ANGLE
                 for i in angles) and all(abs(x[i] - x_op[i]) <= BALANCED_RATE for i in rates)
        if not ok:
            since = math.nan
        elif math.isnan(since):
            since = k / rate
    return since


def test_the_box_is_the_fall_regions_angles_and_their_rates() -> None:
    box = balance_box(get_system("cartpole"))
    assert np.all(np.isinf(box[[0, 2], :2]))  # the cart is free
    assert box[1].tolist() == [-0.1, 0.1, 2 * math.pi] and box[3].tolist() == [-0.5, 0.5, 0.0]
    acro = balance_box(get_system("acrobot"))
    assert np.all(acro[:2, 1] == 0.1) and np.all(acro[2:, 1] == 0.5)


def test_a_swing_up_batch_reports_who_ends_balanced_and_since_when() -> None:
    system = get_system("cartpole")
    ctrl = swingup(system)
    starts = np.zeros((6, 4))
    starts[:, 1] = np.pi + np.linspace(-0.05, 0.05, 6)
    batch = simulate_batch(system, ctrl, runs=6, x0=starts, duration=6.0, seed=3, record=True,
                           noise=Noise.from_spec(system, outputs=ctrl.output_names,
                                                 rate=ctrl.rate),
                           region={"x": (-1.0, 1.0)})
    setup = batch._setup
    x_op = setup.x_op
    n = system.n_states
    for i in range(6):
        rows = int(batch.rows[i])
        want = _by_hand(batch.trajectories[i, :rows, :n], x_op, setup.rate, [1], [3])
        got = float(batch.balanced_since[i])
        assert (math.isnan(want) and math.isnan(got)) or want == pytest.approx(got, abs=1e-12), i
    # They swing up (the cart-pole's law brings it up in about 2 s) and stay.
    assert batch.fraction_balanced == 1.0 and 0.5 < batch.time_to_balance(0.5) < 5.0
    summary = batch.summary()
    assert summary["fraction_balanced"] == 1.0 and summary["balanced"] == 6
    assert summary["time_to_balance_median"] == pytest.approx(batch.time_to_balance(0.5))
    assert "modulo a turn" in summary["balanced_criterion"]["theta"]


def test_a_run_too_short_to_catch_does_not_count_and_files_keep_it(tmp_path) -> None:
    system = get_system("cartpole")
    starts = np.zeros((3, 4))
    starts[:, 1] = np.pi  # hanging: 1 s is too short to come up
    batch = simulate_batch(system, swingup(system), runs=3, x0=starts, duration=1.0, seed=1,
                           region={"x": (-1.0, 1.0)})
    assert batch.fraction_up == 1.0 and batch.fraction_balanced == 0.0
    assert batch.time_to_balance(0.5) is None
    back = type(batch).load(batch.save(tmp_path / "b.npz"))
    np.testing.assert_array_equal(back.balanced_since, batch.balanced_since)


def test_python_controllers_count_as_the_core_does() -> None:
    """The Python path (a controller written in Python) keeps the same accumulator."""
    system = get_system("cartpole")
    d = design(system, rate=200.0)
    lin = LinearController.from_design(d, kind="lqr")
    starts = np.array([[0.0, 0.05, 0.0, 0.0], [0.0, 0.2, 0.0, 0.6], [0.0, -0.12, 0.0, 0.0]])
    core = simulate_batch(system, lin, runs=3, x0=starts, duration=2.0, seed=2)
    python = simulate_batch(system, lin.runtime(), runs=3, x0=starts, duration=2.0, seed=2,
                            workers=1)
    np.testing.assert_array_equal(core.balanced_since, python.balanced_since)
    assert np.all(np.isfinite(core.balanced_since)) and core.balanced_since.max() > 0.0
