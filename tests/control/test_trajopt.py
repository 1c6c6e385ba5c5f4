"""Trajectory optimization: plans checked against the system's own numeric dynamics.

The plan is solved with CasADi's translation of the derived equations; the
truth it is checked against is the system's compiled ``f`` integrated by
scipy's adaptive Runge-Kutta over every interval with the planned input:
each interval must land where the plan says.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from equilibrist import get_system
from equilibrist.cli.main import main
from equilibrist.control.trajectory_file import load_trajectory
from equilibrist.control.trajopt import plan
from equilibrist.errors import DesignError
from equilibrist.tasks import get_task


def _shooting_errors(system, traj) -> np.ndarray:
    """Per interval: where the system's own f carries the plan's start, minus the plan's end."""
    errors = []
    for k in range(traj.knots):
        t0, t1 = traj.times[k], traj.times[k + 1]
        sol = solve_ivp(lambda t, x: system.f(x, traj.input_at(t)), (t0, t1), traj.states[k],
                        rtol=1e-10, atol=1e-12)
        errors.append(sol.y[:, -1] - traj.states[k + 1])
    return np.array(errors)


def test_the_cart_pole_swing_up_keeps_its_track_and_its_limits() -> None:
    cart = get_system("cartpole")
    task = get_task(cart, "swingup")
    traj = plan(cart, start=task.start, goal=task.x_op, knots=80, duration=4.0,
                bounds=dict(task.region))
    assert traj.converged and traj.max_defect < 1e-8
    np.testing.assert_allclose(traj.states[0], task.start, atol=1e-9)
    np.testing.assert_allclose(traj.states[-1], task.x_op, atol=1e-9)
    t = np.linspace(0, traj.duration, 2001)
    x_max = cart.params["x_max"]
    assert np.max(np.abs(traj.states[:, 0])) <= x_max + 1e-9
    assert np.max(np.abs(traj.input_at(t))) <= cart.params["F_max"] + 1e-6
    # Each interval, integrated with the system's own f, lands on the next knot.
    err = _shooting_errors(cart, traj)
    scale = np.array([x_max, np.pi, 5.0, 10.0])
    assert np.max(np.abs(err) / scale) < 2e-3, np.max(np.abs(err) / scale)


@pytest.mark.slow
def test_the_acrobot_converges_from_random_guesses() -> None:
    acro = get_system("acrobot")
    task = get_task(acro, "swingup")
    costs = []
    for seed in range(5):
        traj = plan(acro, start=task.start, goal=task.x_op, knots=60, duration=4.0,
                    guess="random", seed=seed)
        assert traj.converged, seed
        assert traj.peak_input["tau"] <= 20 + 1e-6
        costs.append(traj.cost)
    # A random start may end in another local optimum, never in a worse-than-random one.
    assert min(costs) > 0
    err = _shooting_errors(acro, traj)
    assert np.max(np.abs(err)) < 5e-3, np.max(np.abs(err))


def test_a_problem_built_once_solves_as_a_fresh_one() -> None:
    """The transcription is built once per shape and reused (its start and goal are
    parameters): a reused problem gives the bits of a freshly built one, whatever it solved
    before, and another start is not the last start's answer."""
    from equilibrist.control import trajopt

    cart = get_system("cartpole")
    task = get_task(cart, "swingup")
    kw = {"goal": task.x_op, "knots": 30, "duration": 3.0, "bounds": {"x": (-0.9, 0.9)}}
    other = np.asarray(task.start, dtype=float) + np.array([0.0, 0.3, 0.0, 0.0])
    trajopt._PROBLEMS.clear()
    fresh = plan(cart, start=task.start, guess="random", seed=3, **kw)
    moved = plan(cart, start=other, **kw)  # the same problem, another start and guess
    again = plan(cart, start=task.start, guess="random", seed=3, **kw)
    assert len(trajopt._PROBLEMS) == 1
    assert fresh.converged and moved.converged
    np.testing.assert_allclose(moved.states[0], other, atol=1e-9)
    for name in ("states", "inputs", "mid_inputs"):
        np.testing.assert_array_equal(getattr(again, name), getattr(fresh, name))
    assert again.iterations == fresh.iterations


def test_minimum_time_is_shorter_than_its_bound() -> None:
    cart = get_system("cartpole")
    task = get_task(cart, "swingup")
    traj = plan(cart, start=task.start, goal=task.x_op, knots=50, duration_max=8.0,
                minimize="time", bounds=dict(task.region))
    assert traj.converged
    assert 0.5 < traj.duration < 8.0 - 1e-3
    # With the input at its limit somewhere: a minimum-time plan uses what it has.
    assert traj.peak_input["F"] > 0.99 * cart.params["F_max"]


def test_the_command_line_plans_writes_and_refuses(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "up.npz"
    assert main(["trajopt", "cartpole", "--json", "--out", str(out), "--knots", "40"]) == 0
    summary = json.loads(capsys.readouterr().out)
    for key in ("converged", "duration", "cost", "peak_input", "max_defect", "solve_time",
                "iterations", "solver"):
        assert key in summary
    assert summary["converged"] is True and summary["duration"] == 5.0
    traj = load_trajectory(out)
    assert traj.system == "cartpole" and traj.knots == 40 and traj.converged
    # A plan from that file as the guess converges again, to the same optimum.
    assert main(["trajopt", "cartpole", "--json", "--guess", str(out), "--knots", "40"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["converged"] and abs(again["cost"] - summary["cost"]) <= 1e-6 * summary["cost"]
    # A transfer: the cart moves 0.5 m and stops, upright.
    assert main(["trajopt", "cartpole", "--to", "x=0.5", "--duration", "2", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["converged"] is True
    # An impossible plan is one line and exit status 1, nothing written.
    bad = tmp_path / "bad.npz"
    status = main(["trajopt", "acrobot", "--duration", "0.05", "--knots", "10", "--out", str(bad)])
    err = capsys.readouterr().err.strip()
    assert status == 1 and len(err.splitlines()) == 1 and "did not converge" in err
    assert not bad.exists()
    for argv, words in ((["--knots", "1"], "--knots"), (["--minimize", "time"], "--duration-max"),
                        (["--to", "nope=1"], "unknown state"), (["--out", "x.csv"], ".npz"),
                        (["--from", "x=1"], "--to")):
        assert main(["trajopt", "cartpole", *argv]) == 2
        err = capsys.readouterr().err.strip()
        assert words in err and len(err.splitlines()) == 1, err
    assert main(["trajopt", "seesaw"]) == 2  # no swing-up task
    assert "no swing-up task" in capsys.readouterr().err


def test_a_trajectory_file_never_runs_the_system_it_names(tmp_path: Path) -> None:
    cart = get_system("cartpole")
    task = get_task(cart, "swingup")
    traj = plan(cart, start=task.start, goal=task.x_op, knots=20, duration=4.0,
                bounds=dict(task.region))
    marker = tmp_path / "marker"
    evil = tmp_path / "evil.py"
    evil.write_text(f"open({str(marker)!r}, 'w').write('ran')\n")
    from dataclasses import replace

    path = replace(traj, system=str(evil)).save(tmp_path / "t.npz")
    assert load_trajectory(path).system == str(evil)
    assert not marker.exists()
    with pytest.raises(DesignError, match="not a trajectory file"):
        load_trajectory(tmp_path / "evil.py")


def test_costs_on_the_rates_plan_a_slower_motion_and_a_smoother_input() -> None:
    cart = get_system("cartpole")
    task = get_task(cart, "swingup")
    kw = dict(start=task.start, goal=task.x_op, knots=20, duration=4.0, bounds=dict(task.region))

    def rates_squared(traj) -> float:  # the trapezoid over the knots
        return float(np.trapezoid(np.sum(traj.states[:, 2:] ** 2, axis=1), traj.times))

    plain = plan(cart, **kw)
    slow = plan(cart, state_cost={"x_dot": 1.0, "theta_dot": 1.0}, **kw)
    assert plain.converged and slow.converged
    assert rates_squared(slow) < 0.9 * rates_squared(plain)
    assert slow.settings["state_cost"] == {"x_dot": 1.0, "theta_dot": 1.0}
    assert "state_cost" not in plain.settings
    smooth = plan(cart, input_rate_cost={"F": 0.01}, **kw)
    assert smooth.converged
    assert np.sum(np.diff(smooth.inputs[:, 0]) ** 2) < 0.9 * np.sum(np.diff(plain.inputs[:, 0]) ** 2)
    with pytest.raises(DesignError, match="expected one of cartpole's"):
        plan(cart, state_cost={"speed": 1.0}, **kw)
    with pytest.raises(DesignError, match="expected one of cartpole's"):
        plan(cart, input_rate_cost={"tau": 1.0}, **kw)
    with pytest.raises(DesignError, match="non-negative number"):
        plan(cart, state_cost={"x_dot": -1.0}, **kw)
