"""The descriptions ``StateFeedback.from_design`` and ``LQG.from_design`` of a design for a
delayed loop run the controller the ``lqr`` and ``lqg`` kinds build
(``LinearController.from_design``): the same bits through a rig two periods late, and the
same record."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from equilibrist.control.design import design
from equilibrist.control.linear import LinearController
from equilibrist.errors import SimulationError
from equilibrist.numeric.lookup import get_system
from equilibrist.sim.controllers import LQG, StateFeedback
from equilibrist.sim.noise import Noise
from equilibrist.sim.rig import Rig
from equilibrist.sim.run import simulate

#: The double cart-pole at 100 Hz: two periods late, its undelayed loop is unstable.
SYSTEM, RATE, N = "double_cartpole", 100.0, 2


@functools.cache
def _design():
    return design(get_system(SYSTEM), rate=RATE, delay=N)


@pytest.mark.parametrize(("kind", "description"), [("lqr", StateFeedback), ("lqg", LQG)])
def test_a_delayed_design_described_runs_the_kinds_controller(kind, description) -> None:
    system, d = get_system(SYSTEM), _design()
    run = functools.partial(simulate, system, duration=2.0, rate=RATE, x0={"theta1": 0.05},
                            rig=Rig(actuation_delay=N), seed=3,
                            noise=Noise.from_design(d) if kind == "lqg" else None)
    described = description.from_design(d)
    by_kind = LinearController.from_design(d, kind=kind)
    ours, theirs = run(described), run(by_kind)
    for signal in ("states", "commanded", "applied", "measurements"):
        np.testing.assert_array_equal(getattr(ours, signal), getattr(theirs, signal))
    if kind == "lqg":
        np.testing.assert_array_equal(ours.estimates, theirs.estimates)
    assert not ours.fell and abs(ours.state("theta1")[-1]) < 0.05  # it balances, two late
    assert described.describe() == by_kind.describe()
    assert ours.settings["controller"] == theirs.settings["controller"]
    # The record of the commands in flight is the controller's state: N commands (LQR), or
    # the filter's N commands beside the plant's states (LQG).
    built = described.linear(system.state_names, system.input_names)
    assert built.n_z == (N if kind == "lqr" else system.n_states + N)
    assert built.fingerprint == by_kind.fingerprint
    py = described.runtime(system.state_names)
    y = np.zeros(len(built.output_names))
    assert np.array_equal(py.output(0.0, y, np.zeros(0)), by_kind.output(by_kind.z0, y))


def test_an_undelayed_design_described_is_as_before() -> None:
    """Without a delay the description builds its own form (the record it always had)."""
    d = design(get_system(SYSTEM), rate=RATE)
    described = StateFeedback.from_design(d).describe()
    assert set(described) == {"kind", "K", "Kc", "tracked", "rate"}
    assert np.array_equal(described["K"], d.K)


def test_a_design_for_the_rigs_velocity_filter_described_runs_the_kinds_controller() -> None:
    system = get_system("dfki_double_pendulum")
    d = design(system, rate=500.0, outputs=("theta1", "theta2", "theta1_dot", "theta2_dot"),
               rn=(1e-12, 1e-12, 1e-7, 1e-7), velocity_filter=20.0)
    run = functools.partial(simulate, system, duration=1.0, rate=500.0, x0={"theta1": 3.1},
                            rig=Rig(velocity_filter=20.0, velocity_noise=0.05), seed=5)
    ours, theirs = run(LQG.from_design(d)), run(LinearController.from_design(d, kind="lqg"))
    np.testing.assert_array_equal(ours.states, theirs.states)
    np.testing.assert_array_equal(ours.estimates, theirs.estimates)
    assert LQG.from_design(d).describe() == LinearController.from_design(d).describe()
    with pytest.raises(SimulationError, match="an LQR reads the rates as measured"):
        run(StateFeedback.from_design(d))
