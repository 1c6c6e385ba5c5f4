"""The time-varying LQR on measured outputs (``--balance lqg``): a Kalman filter along the plan,
the design's after it; its gains against plain numpy, its export, studies that track a plan."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.cli.main import main
from equilibrist.control.trajectory_file import load_trajectory
from equilibrist.control.tvlqr import LAYOUT_LQG, SOURCE, kalman_along
from equilibrist.controllers.kinds import ControllerRequest, build
from equilibrist.sim.noise import Noise
from equilibrist.sim.run import simulate
from support.export import make_check

RATE = 200.0


def _request(path: Path, balance: str | None = "lqg", form: str = "current") -> ControllerRequest:
    options = {"trajectory": str(path)} | ({"balance": balance} if balance else {})
    return ControllerRequest(system=get_system("cartpole"), rate=RATE, options=options,
                             design_options={"kalman_form": form})


def _tables(params: np.ndarray) -> dict[str, np.ndarray]:
    """The parameter vector of ``balance="lqg"`` cut into its tables (the source's layout)."""
    out = {name: LAYOUT_LQG.read(params, name) for name, _dims in LAYOUT_LQG.blocks}
    out["index"] = out.pop("sel")
    return out


def _expm(a: np.ndarray) -> np.ndarray:
    """``exp(a)`` by its Taylor series: plain numpy, exact to round-off for the small ``a T``
    of one sample (norm well under 1)."""
    assert np.abs(a).sum(axis=1).max() < 0.5
    term, total = np.eye(a.shape[0]), np.eye(a.shape[0])
    for k in range(1, 20):
        term = term @ a / k
        total = total + term
    return total


def _upright(x: np.ndarray) -> bool:
    """Balanced: the pole within 0.05 rad of upright (modulo a turn), slow, the cart near 0."""
    theta = math.remainder(float(x[1]), 2 * math.pi)
    return abs(theta) < 0.05 and abs(x[0]) < 0.1 and abs(x[2]) < 0.2 and abs(x[3]) < 0.3


@pytest.mark.parametrize("form", ["current", "predictor"])
def test_noisy_swing_ups_end_balanced_on_the_estimate_of_the_measured_outputs(
        cart_plan: Path, form: str) -> None:
    cart = get_system("cartpole")
    traj = load_trajectory(cart_plan)
    ctrl = build("tvlqr", _request(cart_plan, form=form))
    assert ctrl.output_names == ("x", "theta") and ctrl.has_estimate
    assert ctrl.settings["balance"] == "lqg" and ctrl.settings["kalman_form"] == form
    noise = Noise.from_spec(cart, outputs=ctrl.output_names, rate=RATE)
    rng = np.random.default_rng(5)
    for seed in range(4):
        # From where the plan starts and from starts spread around it (the estimate starts
        # at the plan's start: the filter finds the rest).
        dx = np.zeros(4) if seed == 0 else rng.uniform(-1, 1, 4) * [0.02, 0.05, 0.1, 0.1]
        run = simulate(cart, ctrl, duration=6.0, x0=traj.states[0] + dx, noise=noise, seed=seed,
                       region={"x": (-1.0, 1.0)})
        assert not run.fell and _upright(run.final_state), (seed, run.final_state)
        assert run.estimates is not None
        error = np.abs(run.estimates - run.states)
        after = run.time >= traj.duration
        # After the plan the estimate is as good as the sensors allow (1.5 mm, 1.5 mrad).
        assert np.all(error[after].max(axis=0) < [0.01, 0.01, 0.06, 0.06]), error[after].max(0)
        early = (run.time >= 0.05) & (run.time < 1.0)  # and soon along the plan too
        assert np.all(error[early].max(axis=0) < [0.01, 0.02, 0.15, 0.15]), error[early].max(0)


def test_the_filter_along_the_plan_is_the_one_plain_numpy_computes(cart_plan: Path) -> None:
    request = _request(cart_plan)
    cart, ctrl, d = request.system, build("tvlqr", request), request.design()
    tab = _tables(ctrl.params)
    steps, n = tab["gains"].shape[0], cart.n_states
    index = tab["index"].astype(int)
    C = np.eye(n)[index]
    np.testing.assert_array_equal(index, [0, 1])  # x and theta
    dt = 1.0 / RATE
    W = d.G @ d.QN @ d.G.T
    P = d.P + np.diag(1.0 / np.diag(d.Q))
    for k in range(steps):
        A, B = cart.jacobians(tab["xs"][k], tab["us"][k])
        E = _expm(np.block([[A, B], [np.zeros((1, n + 1))]]) * dt)
        np.testing.assert_allclose(tab["A"][k], E[:n, :n], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(tab["B"][k], E[:n, n:], rtol=1e-9, atol=1e-12)
        M = P @ C.T @ np.linalg.inv(C @ P @ C.T + d.Rd)
        np.testing.assert_allclose(tab["F"][k], M, rtol=1e-6, atol=1e-9, err_msg=str(k))
        V = _expm(np.block([[-A, W], [np.zeros((n, n)), A.T]]) * dt)
        F = V[n:, n:].T
        Qd = F @ V[:n, n:]
        P = F @ (P - M @ C @ P) @ F.T + Qd
    # After the plan: the design's stationary filter and balancing gain, as the LQG has them.
    np.testing.assert_array_equal(tab["Kf"], d.Kf)
    np.testing.assert_array_equal(tab["Ad"], d.discrete.A)
    np.testing.assert_array_equal(tab["K_end"], d.K)
    # The recursion held at the operating point converges to that stationary filter, in
    # either form (the predictor's gain L = Ad M).
    A0 = np.asarray(d.plant.A)
    for form in ("current", "predictor"):
        df = _request(cart_plan, form=form).design()
        still = [(A0, df.discrete.A, df.discrete.B)] * 800
        gains, covariances = kalman_along(still, C, df, dt, np.diag(1.0 / np.diag(df.Q)))
        np.testing.assert_allclose(gains[-1], df.Kf, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(covariances[-1], df.P, rtol=1e-6, atol=1e-12)


def test_the_default_balance_is_the_full_state_law_unchanged(cart_plan: Path) -> None:
    plain = build("tvlqr", _request(cart_plan, balance=None))
    lqr = build("tvlqr", _request(cart_plan, balance="lqr"))
    assert plain.source == lqr.source == SOURCE and not lqr.has_estimate
    np.testing.assert_array_equal(plain.params, lqr.params)
    # Its one state is the catch's latch (0 tracking, 1 balancing).
    assert lqr.output_names == get_system("cartpole").state_names and lqr.n_z == 1


@pytest.mark.slow
def test_the_command_line_and_the_export_replay_the_estimating_controller_to_the_bit(
        cart_plan: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["--controller", "tvlqr", "--trajectory", str(cart_plan), "--balance", "lqg"]
    assert main(["simulate", "cartpole", *args, "--duration", "6", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["stayed_up"] is True and abs(out["final_error"]["theta"]) < 0.02
    assert out["estimation_error_rms"]["theta"] < 0.01
    assert main(["batch", "cartpole", *args, "--runs", "16", "--x0", "theta=3.09:3.19",
                 "--duration", "6", "--json"]) == 0
    batch = json.loads(capsys.readouterr().out)
    assert batch["fraction_up"] == 1.0 and batch["fraction_balanced"] == 1.0
    # The compiled core's commands are the plain-Python runtime's (the reference the export's
    # vectors hold), over the plan and the hand-over.
    cart = get_system("cartpole")
    ctrl = build("tvlqr", _request(cart_plan))
    run = simulate(cart, ctrl, duration=5.0, x0=load_trajectory(cart_plan).states[0], seed=3,
                   noise=Noise.from_spec(cart, outputs=ctrl.output_names, rate=RATE), region={})
    runtime = ctrl.runtime()
    runtime.reset()
    for i, t in enumerate(run.time):
        u = runtime.output(float(t), run.measurements[i].copy(), np.zeros(0))
        np.testing.assert_allclose(u, run.commanded[i], rtol=1e-12, atol=1e-9, err_msg=str(t))
        runtime.update(float(t), run.measurements[i].copy(), np.zeros(0), run.applied[i].copy())
    # The export: the source in C, the tables as constants, vectors of a noisy run past the
    # plan's end (4 s), make check exact.
    folder = tmp_path / "tv"
    assert main(["export", "cartpole", *args, "--duration", "5", "--out", str(folder),
                 "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["controller"] == "tvlqr"
    header = (folder / "tvlqr.h").read_text()
    assert "tvlqr_estimate" in header
    assert "1001 samples, 0 mismatches" in make_check(folder)


def test_a_bad_balance_is_one_line_exit_2(cart_plan: Path, capsys: pytest.CaptureFixture[str]
                                          ) -> None:
    for argv, words in ((["--controller", "tvlqr", "--trajectory", str(cart_plan), "--balance",
                          "foo"], "--balance"),
                        (["--controller", "lqr", "--balance", "lqg"], "--balance")):
        assert main(["simulate", "cartpole", *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert words in err and len(err.splitlines()) == 1, err


def test_a_study_tracks_a_plan_on_measured_outputs(cart_plan: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    from equilibrist.study import StudyError, make_study, read_study

    shutil.copy(cart_plan, tmp_path / "up.npz")
    (tmp_path / "study.toml").write_text(
        'system = "cartpole"\nruns = 3\nduration = 6\nseed = 2\ncontroller = "tvlqr"\n'
        'metrics = "basic"\n[vary]\nm_p = [0.95, 1.05]\n[x0]\ntheta = "3.09:3.19"\n'
        '[controller_options]\ntrajectory = "up.npz"\nbalance = "lqg"\n')
    out = tmp_path / "s.parquet"
    assert main(["sweep", "--study", str(tmp_path / "study.toml"), "--out", str(out),
                 "--no-progress", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["points"] == 2 and summary["failed_points"] == 0
    table, study = read_study(out)
    # The plan file is read beside the study file and recorded as an absolute path.
    assert study.controller_options == {"trajectory": str(tmp_path / "up.npz"), "balance": "lqg"}
    rows = table.to_pylist()
    assert [r["status"] for r in rows] == ["ok", "ok"]
    # Started hanging (the other states where the plan starts), judged on the cart's track.
    assert all(r["fraction_up"] == 1.0 and r["fraction_balanced"] == 1.0 for r in rows), rows
    assert all(2.0 < r["time_to_balance_p50"] < 5.0 for r in rows), rows
    # The same study from the command line: the kinds' own flags reach the study.
    flags = tmp_path / "f.parquet"
    assert main(["sweep", "cartpole", "--vary", "m_p=0.95,1.05", "--runs", "3", "--duration",
                 "6", "--seed", "2", "--controller", "tvlqr", "--metrics", "basic", "--x0",
                 "theta=3.09:3.19", "--trajectory", str(tmp_path / "up.npz"), "--balance",
                 "lqg", "--out", str(flags), "--no-progress", "--json"]) == 0
    capsys.readouterr()
    again, study2 = read_study(flags)
    assert study2.controller_options == study.controller_options
    assert [r["fraction_balanced"] for r in again.to_pylist()] == \
        [r["fraction_balanced"] for r in rows]
    # Beside --study, a kind's flag is refused like every other option of the study.
    assert main(["sweep", "--study", str(tmp_path / "study.toml"), "--out", str(out),
                 "--balance", "lqg"]) == 2
    assert "drop --balance" in capsys.readouterr().err
    # Options that no controller of the study takes, or bad values, are named at once.
    with pytest.raises(StudyError) as err:
        make_study("cartpole", controller="lqr", controller_options={"balance": "lqg"})
    assert "controller_options balance" in str(err.value)
    with pytest.raises(StudyError) as err:
        make_study("cartpole", controller="tvlqr", controller_options={"balance": "foo"})
    assert "--balance 'foo'" in str(err.value)
    with pytest.raises(StudyError) as err:
        make_study("cartpole", controller="tvlqr",
                   controller_options={"trajectory": str(tmp_path / "none.npz")})
    assert "controller_options trajectory: no file" in str(err.value)


@pytest.mark.slow
def test_the_filter_tables_are_the_same_bits_under_another_blas_kernel(cart_plan: Path) -> None:
    """The covariance recursion runs in control.fixed's order, as the Riccati recursion does:
    another BLAS kernel (what another CPU would select) changes no bit of the parameters."""
    from tests.support.blas import tvlqr_params_digests

    digests = tvlqr_params_digests({"trajectory": str(cart_plan), "balance": "lqg"}, rate=RATE)
    assert digests[0] == digests[1]
