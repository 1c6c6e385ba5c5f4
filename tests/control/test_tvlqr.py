"""Time-varying LQR: a planned swing-up tracked on the nonlinear plant, handed over to the balancing LQR."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.cli.main import main
from equilibrist.control.trajectory_file import load_trajectory
from equilibrist.control.tvlqr import LAYOUT
from equilibrist.controllers.kinds import ControllerRequest, build_controller
from equilibrist.sim.run import simulate
from support.export import make_check


def _controller(system, path: Path, catch: str = "on"):
    return build_controller("tvlqr", ControllerRequest(
        system=system, rate=200.0, options={"trajectory": str(path), "catch": catch}))


def test_the_gains_hand_over_to_the_balancing_lqr(cart_plan: Path) -> None:
    cart = get_system("cartpole")
    ctrl = _controller(cart, cart_plan)
    gains, k_end = LAYOUT.read(ctrl.params, "gains"), LAYOUT.read(ctrl.params, "K_end")
    assert gains.shape == (800, cart.n_inputs, cart.n_states)
    # The last sample is linearized at the operating point and the recursion starts from the
    # balancing LQR's Riccati solution: its gain is the balancing gain.
    np.testing.assert_allclose(gains[-1], k_end, rtol=1e-6, atol=1e-9)
    assert not np.allclose(gains[0], k_end, rtol=0.1)  # along the swing the gains differ


def test_the_plan_is_tracked_and_balanced_without_noise(cart_plan: Path) -> None:
    cart = get_system("cartpole")
    traj = load_trajectory(cart_plan)
    # Tracked to the plan's end (no early catch): the plan takes the state to the top.
    run = simulate(cart, _controller(cart, cart_plan, catch="off"), duration=6.0,
                   x0=traj.states[0], region={"x": (-1.0, 1.0)})
    assert not run.fell
    # While the plan runs, the state follows it closely (the plan's own knots are the truth).
    k = np.searchsorted(run.time, traj.times[:-1])
    err = np.abs(run.states[k] - traj.states[:-1])
    assert np.max(err[:, 1]) < 0.05, np.max(err[:, 1])
    assert np.max(np.abs(run.states[:, 0])) < 1.0
    np.testing.assert_allclose(run.final_state, np.zeros(4), atol=1e-3)


def test_the_balancing_lqr_takes_over_inside_its_catch_region(cart_plan: Path) -> None:
    """With ``--catch on`` (the default) the balancing LQR's law acts from the first sample
    inside its catch region, before the plan ends; with ``off`` the plan is tracked."""
    from equilibrist.control.design import design

    cart = get_system("cartpole")
    traj = load_trajectory(cart_plan)
    d = design(cart, rate=200.0)  # the balancing design, on its own
    K, S = np.asarray(d.K), np.asarray(d.S)
    room = min(cart.input_limits[1][0], -cart.input_limits[0][0])  # u_op = 0
    ctrl = _controller(cart, cart_plan)
    level = ctrl.settings["catch_level"]
    # The level: the largest ellipse dx' S dx <= level on which |K dx| stays within the
    # limit, checked on 20,000 points of its surface (not by the formula that made it).
    w = np.random.default_rng(1).normal(size=(20_000, 4))
    L = np.linalg.cholesky(np.linalg.inv(S))
    dx = (w / np.linalg.norm(w, axis=1, keepdims=True)) @ L.T * math.sqrt(level)
    peak = np.max(np.abs(dx @ K[0]))
    assert 0.97 * room < peak <= room * (1 + 1e-9), (peak, room)

    for catch in ("on", "off"):
        run = simulate(cart, _controller(cart, cart_plan, catch=catch), duration=6.0,
                       x0=traj.states[0], region={"x": (-1.0, 1.0)})
        assert not run.fell
        y = run.measurements
        v = np.einsum("ki,ij,kj->k", y, S, y)
        first = int(np.argmax(v <= level))
        assert first > 0 and run.time[first] < traj.duration - 0.5  # inside well before the end
        balancing = -(y @ K[0])  # inside the catch region it stays within the limit
        u = run.commanded[:, 0]
        plan_end = int(np.searchsorted(run.time, traj.duration - 1e-9))
        if catch == "on":
            assert not np.allclose(u[:first], balancing[:first], atol=1e-6)
            np.testing.assert_allclose(u[first:], balancing[first:], rtol=1e-9, atol=1e-9)
        else:
            assert np.max(np.abs(u[first:plan_end] - balancing[first:plan_end])) > 0.1
            np.testing.assert_allclose(u[plan_end:], balancing[plan_end:], rtol=1e-9, atol=1e-9)


@pytest.mark.slow
def test_the_command_line_tracks_a_plan_with_noise_and_refuses_what_does_not_fit(
        cart_plan: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "cartpole", "--controller", "tvlqr", "--trajectory", str(cart_plan),
                 "--duration", "6", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["stayed_up"] is True  # started where the plan starts: hanging
    assert abs(out["final_error"]["theta"]) < 0.02
    assert main(["batch", "cartpole", "--controller", "tvlqr", "--trajectory", str(cart_plan),
                 "--runs", "16", "--x0", "theta=3.09:3.19", "--duration", "6", "--json"]) == 0
    batch = json.loads(capsys.readouterr().out)
    assert batch["fraction_up"] == 1.0
    for argv, words in ((["--controller", "tvlqr"], "--trajectory"),
                        (["--controller", "lqr", "--trajectory", str(cart_plan)], "tvlqr"),
                        (["--controller", "tvlqr", "--trajectory", str(tmp_path / "none.npz")],
                         "no trajectory file")):
        assert main(["simulate", "cartpole", *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert words in err and len(err.splitlines()) == 1, err
    assert main(["simulate", "furuta", "--controller", "tvlqr", "--trajectory", str(cart_plan)]) == 2
    assert "not of furuta" in capsys.readouterr().err


def test_the_export_replays_a_tracked_swing_up_to_the_bit(
        cart_plan: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The TVLQR exports as any NonlinearController: its source translated to C, vectors
    recorded from where the plan starts (hanging), make check exact."""

    out = tmp_path / "tv"
    assert main(["export", "cartpole", "--controller", "tvlqr", "--trajectory", str(cart_plan),
                 "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["controller"] == "tvlqr"
    assert report["vector_start"]["theta"] == pytest.approx(math.pi, abs=1e-9)
    assert " 0 mismatches" in make_check(out)
    # The export needs its plan as simulate does.
    assert main(["export", "cartpole", "--controller", "tvlqr", "--out", str(tmp_path / "x")]) == 2
    assert "--trajectory" in capsys.readouterr().err


def test_the_gains_are_the_same_bits_under_another_blas_kernel(cart_plan: Path) -> None:
    """The recursion runs in control.fixed's order: another BLAS kernel (what another CPU
    would select) changes no bit of the controller made from the same plan file."""
    from tests.support.blas import tvlqr_params_digests

    digests = tvlqr_params_digests({"trajectory": str(cart_plan)}, rate=200.0)
    assert digests[0] == digests[1]
