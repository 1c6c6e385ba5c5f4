"""The estimator is one definition, plugged in once: a throwaway estimator in a temporary folder
(a module defining its source through the contract of :data:`equilibrist.control.kalman.
ESTIMATOR_SOURCE`) is what every consumer then runs: the LQG in ``simulate``, the time-varying
LQR's filter, the swing-up's hand-over, the MPC's filter in front and the identification's
prediction errors.

The estimator (``half``): the Kalman filter whose correction applies half its gain. Its
independent check: ``0.5 * g * e`` is ``(0.5 g) e`` to the bit (halving is exact), so each
consumer built with it must run exactly as the same consumer built with the Kalman filter and
its gains halved by hand (in the parameters' layout, or the design's gain), and differently
from the Kalman filter's own.
"""

from __future__ import annotations

import dataclasses
import importlib
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.control import kalman
from equilibrist.control.design import design
from equilibrist.control.linear import LinearController
from equilibrist.sim.noise import Noise
from equilibrist.sim.run import simulate

ESTIMATOR_MODULE = '''
"""An estimator of one's own: the Kalman filter's correction at half its gain."""

from equilibrist.control.kalman import Estimator, gain

SOURCE = """
def kf_wrap(a):
    return a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))


def kf_innovation(l, z, y, sel, ref, wrap):
    j = int(sel[l])
    d = y[l]
    if ref.shape[0] > 0:
        d = d - ref[j]
        if wrap[j] != 0.0:
            d = kf_wrap(d)
    return d - z[j]


def kf_estimate(i, z, y, gain, ny, sel, ref, wrap, current):
    x = z[i]
    if current != 0:
        for l in range(ny):
            x = x + 0.5 * gain[i * ny + l] * kf_innovation(l, z, y, sel, ref, wrap)
    return x


def kf_predict(i, acc, z, y, A, B, gain, n, m, ny, sel, ref, wrap, current, xr, u, ur):
    v = acc
    for j in range(n):
        d = kf_estimate(j, z, y, gain, ny, sel, ref, wrap, current)
        if xr.shape[0] > 0:
            d = d - xr[j]
        v = v + A[i * n + j] * d
    for l in range(m):
        v = v + B[i * m + l] * (u[l] - ur[l])
    if current == 0:
        for l in range(ny):
            v = v + 0.5 * gain[i * ny + l] * kf_innovation(l, z, y, sel, ref, wrap)
    return v
"""


def twice(P, C, Rd):
    return 2.0 * gain(P, C, Rd)


HALF = Estimator("half", SOURCE, gain)
#: The same correction with a gain rule of its own (twice the Kalman gain): the time-varying
#: filter's gains come from the estimator's rule.
TWICE = Estimator("twice", SOURCE, twice)
'''


@pytest.fixture(scope="module")
def plugin(tmp_path_factory: pytest.TempPathFactory):
    folder = tmp_path_factory.mktemp("estimator")
    (folder / "half_estimator.py").write_text(textwrap.dedent(ESTIMATOR_MODULE))
    sys.path.insert(0, str(folder))
    try:
        yield importlib.import_module("half_estimator")
    finally:
        sys.path.remove(str(folder))
        sys.modules.pop("half_estimator", None)


def _same(a, b) -> bool:
    return all(np.array_equal(getattr(a, k), getattr(b, k), equal_nan=True)
               for k in ("states", "estimates", "commanded"))


@pytest.mark.parametrize("form", ["current", "predictor"])
def test_the_lqg_in_simulate_runs_the_plugged_estimator(plugin, form: str) -> None:
    system = get_system("cartpole")
    d = design(system, rate=200.0, outputs=["x", "theta"], kalman_form=form)
    kw = dict(Ad=d.discrete.A, Bd=d.discrete.B, outputs=d.plant.output_names, x_op=d.plant.x0,
              u_op=d.plant.u0, rate=200.0, form=form, state_names=system.state_names)
    with kalman.using_estimator(plugin.HALF):
        half = LinearController.lqg(d.K, Kf=d.Kf, **kw)
    by_hand = LinearController.lqg(d.K, Kf=0.5 * np.asarray(d.Kf), **kw)
    kalman_own = LinearController.lqg(d.K, Kf=d.Kf, **kw)
    assert np.array_equal(half.packed(), by_hand.packed())
    assert not np.array_equal(half.packed(), kalman_own.packed())
    run = {name: simulate(system, c, duration=1.0, x0={"theta": 0.1}, seed=2,
                          noise=Noise.from_design(d))
           for name, c in (("half", half), ("hand", by_hand), ("kalman", kalman_own))}
    assert _same(run["half"], run["hand"]) and not _same(run["half"], run["kalman"])


def test_the_time_varying_lqr_runs_the_plugged_estimator(plugin, cart_plan: Path) -> None:
    from equilibrist.control.tvlqr import LAYOUT_LQG, lqg_source
    from equilibrist.controllers.kinds import ControllerRequest, build

    cart = get_system("cartpole")
    request = ControllerRequest(system=cart, rate=200.0,
                                options={"trajectory": str(cart_plan), "balance": "lqg"})
    with kalman.using_estimator(plugin.HALF):
        half = build("tvlqr", request)
    own = build("tvlqr", request)
    assert half.source == lqg_source(plugin.HALF) != own.source
    assert np.array_equal(half.params, own.params)  # the same gain rule: the same tables
    # The Kalman filter's controller with its filters' gains halved in its layout.
    p = np.array(own.params)
    for block in ("F", "Kf"):
        at = int(p[LAYOUT_LQG.header.index(f"o_{block}")])
        size = LAYOUT_LQG.read(p, block).size
        p[at:at + size] *= 0.5
    by_hand = dataclasses.replace(own, params=p)
    d = request.design()
    run = {name: simulate(cart, c, duration=5.0, x0=c.settings["start"], seed=4,
                          noise=Noise.from_design(d))
           for name, c in (("half", half), ("hand", by_hand), ("kalman", own))}
    assert _same(run["half"], run["hand"]) and not _same(run["half"], run["kalman"])
    # A gain rule of the estimator's own makes the filter's gains along the plan.
    with kalman.using_estimator(plugin.TWICE):
        twice = build("tvlqr", request)
    np.testing.assert_array_equal(LAYOUT_LQG.read(twice.params, "F")[0],
                                  2.0 * LAYOUT_LQG.read(own.params, "F")[0])


def test_the_swing_up_hands_over_to_the_plugged_estimator(plugin) -> None:
    from equilibrist.control.swingup import swingup
    from equilibrist.control.swingup_law import LAYOUT
    from equilibrist.sim.batch import simulate_batch
    from equilibrist.tasks import get_task

    system = get_system("cartpole")
    d = design(system, rate=float(system.spec.control_rate))
    with kalman.using_estimator(plugin.HALF):
        half = swingup(system, design=d, balance="lqg")
    own = swingup(system, design=d, balance="lqg")
    assert "0.5 * gain" in half.source and "0.5 * gain" not in own.source
    p = np.array(own.params)
    at = int(p[LAYOUT.header.index("o_Kf")])
    p[at:at + LAYOUT.read(p, "Kf").size] *= 0.5
    by_hand = dataclasses.replace(own, params=p)
    task = get_task(system, "swingup")
    x0 = task.draw_initials(np.random.default_rng(17), 4)
    runs = {name: simulate_batch(system, c, runs=4, duration=task.duration, x0=x0, seed=17,
                                 noise=Noise.from_design(d), region=task.region)
            for name, c in (("half", half), ("hand", by_hand), ("kalman", own))}
    assert np.array_equal(runs["half"].final_state, runs["hand"].final_state)
    assert not np.array_equal(runs["half"].final_state, runs["kalman"].final_state)


def test_the_mpc_filters_with_the_plugged_estimator(plugin) -> None:
    from equilibrist.control.mpc import mpc

    system = get_system("cartpole")
    d = design(system, rate=100.0, outputs=["x", "theta"])
    ctrl = mpc(system, design=d, horizon=10)
    assert ctrl.Kf is not None
    by_hand = dataclasses.replace(ctrl, Kf=0.5 * np.asarray(ctrl.Kf))
    with kalman.using_estimator(plugin.HALF):
        np.testing.assert_array_equal(ctrl.filter_form().Ey, 0.5 * np.asarray(ctrl.Kf))
        half = ctrl.runtime()  # the library it compiles holds the plugged filter
    runs = {name: simulate(system, r, duration=0.5, x0={"theta": 0.1}, seed=1,
                           noise=Noise.from_design(d))
            for name, r in (("half", half), ("hand", by_hand.runtime()),
                            ("kalman", ctrl.runtime()))}
    assert _same(runs["half"], runs["hand"]) and not _same(runs["half"], runs["kalman"])


def test_identification_predicts_with_the_plugged_estimator(plugin) -> None:
    from equilibrist.ident.prediction import _solve_ivp_filter

    system = get_system("cartpole")
    rng = np.random.default_rng(3)
    t = np.arange(6) * 0.01
    u = rng.normal(size=(6, 1))
    y = rng.normal(scale=0.01, size=(6, 2))
    c_idx = np.array([0, 1])
    gain = rng.uniform(0.1, 0.5, size=(4, 2))
    args = (np.asarray(system.p, dtype=float), np.zeros(4), t, u, np.ones(5, dtype=np.int64),
            c_idx)
    with kalman.using_estimator(plugin.HALF):
        half_filter = _solve_ivp_filter(system)
    e_half, e_hand, e_own = (np.zeros((6, 2)) for _ in range(3))
    half_filter(*args, gain, y, np.zeros(2), e_half)
    _solve_ivp_filter(system)(*args, 0.5 * gain, y, np.zeros(2), e_hand)
    _solve_ivp_filter(system)(*args, gain, y, np.zeros(2), e_own)
    np.testing.assert_array_equal(e_half, e_hand)
    assert not np.array_equal(e_half, e_own)
