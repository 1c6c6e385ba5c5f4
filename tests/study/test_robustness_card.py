"""The robustness scorecard: RealAIGym's lists, criterion and scores (worked by hand from
the benchmark's definitions), and each family's runs against the same run made alone."""

from __future__ import annotations

import math

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.controllers import kinds
from equilibrist.sim.rig import Rig
from equilibrist.sim.run import simulate
from equilibrist.study import robustness as rb

RATE = 100.0
START = [math.pi + 0.1, -0.1, 0.0, 0.0]


@pytest.fixture(scope="module")
def loop():
    system = get_system("acrobot")
    request = kinds.ControllerRequest(system=system, rate=RATE, design_options={},
                                      tracking=False, options={})
    return system, kinds.get("lqr", "simulate").make(request)


def test_the_benchmarks_lists_and_scores():
    # get_par_list(2.0, 0.75, 1.25, 21): 1.5 .. 2.5 in steps of 0.05; of 0: all zeros.
    np.testing.assert_allclose(rb.relative_values(2.0), 1.5 + 0.05 * np.arange(21))
    assert not rb.relative_values(0.0).any() and len(rb.relative_values(0.0, 20)) == 21
    # A noise family scores the share of levels where more than half the runs succeed;
    # the others the share of successes.
    assert rb._score([[True, True, False], [False, True, False], [True] * 3], True) == 2 / 3
    assert rb._score([[True], [False], [True], [True]], False) == 0.75


def test_success_is_the_benchmarks_final_state_check():
    system = get_system("acrobot")
    goal = np.array([math.pi, 0.0, 0.0, 0.0])
    finals = np.array([
        [math.pi + 4 * math.pi + 0.3, 0.2 - 2 * math.pi, 0.9, -0.9],  # turns do not count
        [math.pi + 0.36, 0.0, 0.0, 0.0],  # theta1 0.36 off
        [math.pi, 0.0, 0.0, 1.01],  # a rate 1.01 off
        [math.pi - 0.34, -0.34, -0.99, 0.99],
    ])
    assert rb.success(system, finals, goal).tolist() == [True, False, False, True]


def test_each_family_is_its_runs_made_alone(loop):
    system, ctrl = loop
    card = rb.robustness(system, ctrl, x0=START, rate=RATE, duration=2.0, repetitions=2,
                         perturbation_runs=3, seed=4, workers=2,
                         families=("torque_response", "delay", "model", "torque_noise"))
    goal = np.array([math.pi, 0, 0, 0])

    def alone(**kw):
        res = simulate(system, ctrl, duration=2.0, rate=RATE, physics_step=1 / RATE, x0=START,
                       region={}, **kw)
        return bool(rb.success(system, res.final_state, goal)[0])

    fam = card.families["torque_response"]
    for i in (0, 9, 20):
        assert fam.successes[i] == [alone(rig=Rig(torque_response=fam.values[i]))]
    fam = card.families["delay"]
    assert [int(v * RATE) for v in fam.values][:3] == [0, 0, 0]  # 2 ms steps at 10 ms periods
    assert fam.successes[-1] == [alone(rig=Rig(measurement_delay=4))]
    model = card.families["model"]
    assert set(model.curves) == {"l1", "l2", "lc1", "lc2", "m1", "m2", "I1", "I2"}
    i2 = model.curves["I2"]
    assert len(i2) == 21 and i2[10] == alone()  # the nominal value is the plain run
    assert card.families["torque_noise"].successes[0] == [alone()] * 2  # sigma 0
    assert set(card.scores) == {"torque_response", "delay", "model", "torque_noise"}
    assert 0.0 <= card.benchmark_score <= 1.0
