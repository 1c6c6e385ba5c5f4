"""The simulator runs the controller contract: nonlinear controllers compiled into the core
(single runs and parallel batches), a linear controller embedded in a nonlinear one, the
supervisor hook, and Python controllers in worker processes."""

from __future__ import annotations

import numpy as np
import pytest

from equilibrist.control.design import design
from equilibrist.control.linear import LinearController
from equilibrist.control.nonlinear import NonlinearController, supervisor_source
from equilibrist.control.python_controller import PythonControllerBase
from equilibrist.errors import SimulationError
from equilibrist.numeric.lookup import get_system
from equilibrist.sim import Noise, Pulse, simulate, simulate_batch

# A nonlinear controller that runs an embedded linear controller (its packed
# vector after one leading parameter) and adds a gain times sin(theta): with
# the gain zero it is exactly the linear controller.
EMBED = '''
import math


def output(t, z, y, r, params, u_out):
    linear_output(t, z, y, r, params[1:], u_out)
    u_out[0] += params[0] * math.sin(y[1])


def update(t, z, y, r, u_applied, params, z_out):
    linear_update(t, z, y, r, u_applied, params[1:], z_out)


def estimate(t, z, y, r, params, x_out):
    linear_estimate(t, z, y, r, params[1:], x_out)
'''


@pytest.fixture(scope="module")
def cartpole_lqg():
    system = get_system("cartpole")
    d = design(system, rate=200.0)
    return system, d, LinearController.from_design(d, kind="lqg")


def embedded(lin: LinearController, gain: float) -> NonlinearController:
    return NonlinearController(
        name="embed", source=EMBED, params=np.concatenate([[gain], lin.packed()]), z0=lin.z0,
        rate=lin.rate or 200.0, x_op=lin.x_op, u_op=lin.u_op, state_names=lin.state_names,
        input_names=lin.input_names, output_names=lin.output_names, has_estimate=True,
    )


def test_embedded_linear_controller_runs_exactly_as_the_linear_one(cartpole_lqg):
    system, d, lin = cartpole_lqg
    opts = dict(duration=2.0, x0={"theta": 0.2}, noise=Noise.from_design(d), seed=3,
                events=[Pulse(0.7, 20.0, 0.05)])
    ref = simulate(system, lin, **opts)
    got = simulate(system, embedded(lin, 0.0), **opts)
    assert not ref.fell
    np.testing.assert_array_equal(got.states, ref.states)
    np.testing.assert_array_equal(got.estimates, ref.estimates)
    np.testing.assert_array_equal(got.applied, ref.applied)
    assert got.settings["controller"]["kind"] == "embed"


def test_compiled_nonlinear_controller_equals_its_python_source(cartpole_lqg):
    system, d, lin = cartpole_lqg
    ctrl = embedded(lin, 3.0)
    opts = dict(duration=1.0, x0={"theta": 0.15}, noise=Noise.from_design(d), seed=9, delay=True)
    compiled = simulate(system, ctrl, **opts)
    python = simulate(system, ctrl.runtime(), **opts)
    np.testing.assert_allclose(python.states, compiled.states, rtol=0, atol=1e-12)
    np.testing.assert_allclose(python.applied, compiled.applied, rtol=0, atol=1e-10)
    # the gain changed the command: u - u_linear = 3 sin(theta_measured)
    u_lin = np.array([lin.output(np.zeros(4), y) for y in compiled.measurements[:1]])
    assert compiled.commanded[0, 0] - u_lin[0, 0] == pytest.approx(
        3.0 * np.sin(compiled.measurements[0, 1]), abs=1e-12)


def test_nonlinear_batch_runs_in_parallel_and_equals_single_runs(cartpole_lqg):
    system, d, lin = cartpole_lqg
    ctrl = embedded(lin, 1.0)
    thetas = np.linspace(-0.3, 0.3, 8)
    batch = simulate_batch(system, ctrl, runs=8, duration=1.0, x0={"theta": thetas},
                           noise=Noise.from_design(d), seed=11, workers=2)
    i = 5
    single = simulate(system, ctrl, duration=1.0, x0={"theta": thetas[i]},
                      noise=Noise.from_design(d), seed=batch.seed(i))
    np.testing.assert_array_equal(batch.final_state[i], single.final_state)
    assert batch.estimation_error_rms is not None


def test_supervisor_hands_over_with_hysteresis(cartpole_lqg):
    system, d, _lin = cartpole_lqg
    lqr = LinearController.from_design(d, kind="lqr")
    # First controller: no force at all. Catch inside |theta| < 0.25, leave beyond 0.5.
    first = '''
def first_output(t, z, y, r, params, u_out):
    u_out[0] = 0.0


def first_update(t, z, y, r, u_applied, params, z_out):
    pass
'''
    source = first + supervisor_source(catch="abs(y[1]) < 0.25", leave="abs(y[1]) > 0.5")
    sup = NonlinearController(
        name="supervised", source=source,
        params=np.concatenate([[0.0], lqr.packed()]), z0=np.zeros(1), rate=200.0,
        x_op=lqr.x_op, u_op=lqr.u_op, state_names=lqr.state_names,
        input_names=lqr.input_names, output_names=lqr.output_names,
    )
    inside = simulate(system, sup, duration=1.0, x0={"theta": 0.1})
    pure = simulate(system, lqr, duration=1.0, x0={"theta": 0.1})
    np.testing.assert_array_equal(inside.states, pure.states)  # caught from the first sample
    # Started between the regions: the passive controller holds until the pendulum
    # falls past 0.5 rad... it never enters the catch region, so the force stays zero.
    outside = simulate(system, sup, duration=0.5, x0={"theta": 0.3}, region={})
    assert np.all(outside.commanded == 0.0)
    python = simulate(system, sup.runtime(), duration=0.5, x0={"theta": 0.3}, region={})
    np.testing.assert_array_equal(python.commanded, outside.commanded)


class Proportional(PythonControllerBase):
    """A module-level Python controller (it pickles to worker processes)."""

    rate = 100.0
    outputs = ("x", "theta", "x_dot", "theta_dot")

    def __init__(self, K):
        self.K = np.asarray(K)

    def output(self, t, y, r):
        return -self.K @ y


def test_python_controller_batches_run_in_processes(cartpole_lqg):
    system, _d, _lin = cartpole_lqg
    K = design(system, rate=100.0).K
    x0 = {"theta": np.array([0.05, -0.1, 0.2])}
    here = simulate_batch(system, Proportional(K), runs=3, duration=0.5, x0=x0, workers=1)
    there = simulate_batch(system, Proportional(K), runs=3, duration=0.5, x0=x0, workers=2)
    np.testing.assert_array_equal(there.final_state, here.final_state)
    np.testing.assert_array_equal(there.peak_input, here.peak_input)

    class Local(Proportional):
        pass

    with pytest.raises(SimulationError, match=r"cannot be sent to worker processes.*workers=1"):
        simulate_batch(system, Local(K), runs=2, duration=0.1, workers=2)
