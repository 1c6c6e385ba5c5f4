"""Batches equal the same runs done one by one; regions of attraction; Monte Carlo."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from equilibrist.errors import SimulationError
from equilibrist.sim import (
    ParameterChange,
    Pulse,
    monte_carlo,
    region_of_attraction,
    simulate,
    simulate_batch,
)
from equilibrist.sim.batch_inputs import child_seed, sample_uniform
from equilibrist.sim.batch_result import BatchResult
from support.sim import cartpole, lqg, state_feedback
from support.sim import cartpole_noise as _noise


def test_batch_equals_runs_one_by_one():
    sysm = cartpole()
    ctrl = lqg(sysm, rate=200.0, qd_scale=1e-4, rd_scale=1e-5)
    noise = _noise(sysm, 200.0)
    thetas = np.array([-0.2, 0.05, 0.1, 1.4, 0.3])
    masses = np.array([1.0, 1.5, 0.8, 1.0, 2.0])
    events = [Pulse(0.3, 20.0, 0.05), ParameterChange(0.6, {"l": 0.6})]
    batch = simulate_batch(sysm, ctrl, runs=5, duration=1.5, x0={"theta": thetas},
                           params={"m_p": masses}, seed=9, noise=noise, events=events,
                           record=True)
    assert batch.fell.tolist() == [False, False, False, True, False]
    for i in range(5):
        single = simulate(sysm.with_params(m_p=masses[i]), ctrl, duration=1.5,
                          x0={"theta": thetas[i]}, seed=batch.seed(i), noise=noise,
                          events=events)
        kept = batch.run(i)
        np.testing.assert_array_equal(kept.states, single.states)
        np.testing.assert_array_equal(kept.estimates, single.estimates)
        np.testing.assert_array_equal(kept.measurements, single.measurements)
        np.testing.assert_array_equal(batch.final_state[i], single.final_state)
        assert kept.fell == single.fell == batch.fell[i]
        assert kept.fell_at == single.fell_at
        if single.fell:
            assert batch.fell_at[i] == single.fell_at
        m = single.metrics()
        assert batch.peak_input[i, 0] == m["peak_input"]["F"]
        assert batch.rms_input[i, 0] == pytest.approx(m["rms_input"]["F"], rel=1e-12)
        assert batch.time_saturated[i] == pytest.approx(m["time_saturated"], abs=1e-12)
        for j, name in enumerate(sysm.state_names):
            assert batch.peak_deviation[i, j] == m["peak_deviation"][name]
            assert batch.estimation_error_rms[i, j] == pytest.approx(
                m["estimation_error_rms"][name], rel=1e-10, abs=1e-300)


def test_batch_without_trajectories_matches_with_and_workers_do_not_matter():
    sysm = cartpole()
    ctrl = state_feedback(sysm, rate=500.0)
    x0 = {"theta": np.linspace(-0.5, 0.5, 16)}
    kept = simulate_batch(sysm, ctrl, runs=16, duration=1.0, x0=x0, record=True)
    lean = simulate_batch(sysm, ctrl, runs=16, duration=1.0, x0=x0, workers=1)
    assert lean.trajectories is None
    np.testing.assert_array_equal(kept.final_state, lean.final_state)
    np.testing.assert_array_equal(kept.fell, lean.fell)
    with pytest.raises(SimulationError, match="record=True"):
        lean.run(0)
    assert lean.summary()["runs"] == 16
    assert lean.steps_per_second > 0


def test_batch_refuses_what_does_not_fit_before_allocating():
    sysm = cartpole()
    ctrl = state_feedback(sysm, rate=1000.0)
    with pytest.raises(SimulationError, match=r"needs 1\.\d TiB of memory"):
        simulate_batch(sysm, ctrl, runs=100_000, duration=100.0, record=True)
    with pytest.raises(SimulationError, match="MiB"):
        simulate_batch(sysm, ctrl, runs=10, duration=1.0, record=True, max_memory=1000)


def test_batch_result_saves_and_loads(tmp_path):
    sysm = cartpole()
    ctrl = state_feedback(sysm, rate=200.0)
    batch = simulate_batch(sysm, ctrl, runs=4, duration=0.5, x0={"theta": [0.1, 0.2, 0.3, 2.0]},
                           seed=3)
    back = BatchResult.load(batch.save(tmp_path / "b.npz"))
    for name in ("x0", "params", "fell", "fell_at", "final_state", "peak_input"):
        np.testing.assert_array_equal(getattr(back, name), getattr(batch, name))
    assert back.fell_states() == [None, None, None, "theta"]
    assert back.summary()["stayed_up"] == 3


def test_region_of_attraction_grid_marks_caught_and_fallen():
    sysm = cartpole()
    ctrl = state_feedback(sysm, rate=500.0)
    roa = region_of_attraction(sysm, ctrl, grid={"theta": (-1.2, 1.2, 13)}, duration=3.0)
    caught = dict(zip(np.round(roa.points[:, 0], 6), roa.caught, strict=True))
    assert caught[0.0] and caught[0.2] and caught[-0.2]
    assert not caught[1.2] and not caught[-1.2]
    # Symmetric plant, symmetric controller: a symmetric region.
    np.testing.assert_array_equal(roa.caught, roa.caught[::-1])


def test_region_of_attraction_samples_are_seeded():
    sysm = cartpole()
    ctrl = state_feedback(sysm, rate=500.0)
    a = region_of_attraction(sysm, ctrl, samples={"theta": (-1, 1)}, runs=8, seed=1,
                             duration=0.5)
    b = region_of_attraction(sysm, ctrl, samples={"theta": (-1, 1)}, runs=8, seed=1,
                             duration=0.5)
    np.testing.assert_array_equal(a.points, b.points)
    assert np.all(np.abs(a.points) <= 1)


def test_monte_carlo_reports_fraction_up():
    sysm = cartpole()
    ctrl = state_feedback(sysm, rate=500.0)
    mc = monte_carlo(sysm, ctrl, spread={"m_p": 0.5, "l": 0.3}, runs=20, seed=2,
                     x0={"theta": 0.1}, duration=2.0)
    mp = mc.batch.param("m_p")
    assert np.all((mp >= 0.5) & (mp <= 1.5)) and mp.std() > 0
    assert mc.fraction_up == 1.0
    fragile = monte_carlo(sysm, ctrl, spread={"m_p": 0.5}, runs=10, seed=2,
                          x0={"theta": 1.0}, duration=2.0)
    assert fragile.fraction_up < 1.0


def test_sampling_is_uniform_within_spread_and_validated():
    sysm = cartpole()
    x0s, params = sample_uniform(sysm, 1000, ranges={"theta": (-0.3, 0.3)},
                                 spread={"m_c": 0.1}, seed=4)
    assert x0s[:, 1].min() >= -0.3 and x0s[:, 1].max() <= 0.3
    assert abs(x0s[:, 1].mean()) < 0.03
    assert params["m_c"].min() >= 9.0 and params["m_c"].max() <= 11.0
    with pytest.raises(SimulationError, match="m_p"):
        simulate_batch(sysm, None, runs=2, duration=0.1, rate=100.0,
                       params={"m_p": [1.0, -1.0]})
    assert child_seed(np.random.SeedSequence(1), 3).spawn_key == (3,)


def test_batch_of_a_python_controller_equals_the_compiled_batch():
    sysm = cartpole()
    ctrl = state_feedback(sysm, rate=200.0)
    x0 = {"theta": np.array([0.1, -0.2, 1.5])}
    compiled = simulate_batch(sysm, ctrl, runs=3, duration=1.0, x0=x0, record=True)
    python = simulate_batch(sysm, ctrl.runtime(sysm.state_names), runs=3, duration=1.0,
                            x0=x0, record=True)
    np.testing.assert_array_equal(python.fell, compiled.fell)
    np.testing.assert_allclose(python.final_state, compiled.final_state, atol=1e-12)
    np.testing.assert_allclose(python.run(1).applied, compiled.run(1).applied, atol=1e-10)


@settings(max_examples=15, deadline=None)
@given(
    thetas=st.lists(st.floats(-1.6, 1.6), min_size=1, max_size=6),
    spread=st.floats(0.0, 0.9),
    seed=st.integers(0, 2**32),
)
def test_property_batch_runs_equal_single_runs(thetas, spread, seed):
    sysm = cartpole()
    ctrl = lqg(sysm, rate=100.0, qd_scale=1e-4, rd_scale=1e-5)
    noise = _noise(sysm, 100.0)
    runs = len(thetas)
    masses = 1.0 + spread * np.linspace(-1, 1, runs)
    batch = simulate_batch(sysm, ctrl, runs=runs, duration=0.5, x0={"theta": thetas},
                           params={"m_p": masses}, seed=seed, noise=noise)
    i = runs - 1
    single = simulate(sysm.with_params(m_p=masses[i]), ctrl, duration=0.5,
                      x0={"theta": thetas[i]}, seed=batch.seed(i), noise=noise)
    np.testing.assert_array_equal(batch.final_state[i], single.final_state)
    assert batch.fell[i] == single.fell


def test_a_batchs_workers_change_no_other_runs_thread_count() -> None:
    """``workers=1`` is that batch's: the thread count in force for the parallel entries
    (the vector environments', the next batches') is what it was."""
    from equilibrist.numeric.lookup import get_system
    from equilibrist.sim.batch import simulate_batch
    from equilibrist.sim.kernel import set_workers, thread_count

    before = thread_count()
    try:
        set_workers(2)
        simulate_batch(get_system("cartpole"), None, runs=2, duration=0.05, rate=200.0,
                       workers=1)
        assert thread_count() == min(2, os.cpu_count() or 1)
    finally:
        set_workers(before)
