"""The exported C code closes the loop on the nonlinear plant, and matches the simulation.

For each system, the simulation runs twice from the same start with the same
noise: once with its own digital controller (the reference), once with the
compiled C library as a user-written controller. The commands must agree to
1e-12 in double precision and to single-precision tolerance in float, and
both runs must stay up. Then the shipped export, with vectors recorded from
the simulation, must pass its own 'make check'.
"""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

from equilibrist.cli.main import main
from equilibrist.control.design import design
from equilibrist.export.vectors import RELATIVE_TOLERANCE, c_controller, record, scenario
from equilibrist.export.writer import export_c
from equilibrist.numeric.lookup import get_system
from equilibrist.sim import LQG, StateFeedback, simulate
from support import require

pytestmark = pytest.mark.slow

SYSTEMS = ("cartpole", "reaction_wheel_pendulum", "wheeled_pendulum", "ball_beam", "seesaw")
SEED = 11


@pytest.fixture(scope="module")
def runs():
    """Per system and controller: the simulation's run and the C runs in both precisions."""
    out = {}
    cases = [(name, "lqg") for name in SYSTEMS] + [("cartpole", "lqr"), ("seesaw", "lqr")]
    for name, kind in cases:
        system = get_system(name)
        d = design(system, rate=system.spec.control_rate)
        settings = scenario(d, system)
        builtin = (LQG if kind == "lqg" else StateFeedback).from_design(d, tracking=True)
        reference = simulate(system, builtin, seed=SEED, **settings)
        c_runs = {}
        for precision in ("double", "float"):
            ctrl = c_controller(d, controller=kind, precision=precision)
            c_runs[precision] = simulate(system, ctrl, seed=SEED, **settings)
            ctrl.close()
        out[name, kind] = (d, reference, c_runs)
    return out


def _activity(result, u_op):
    return np.max(np.abs(result.saturated - u_op), axis=0)


@pytest.mark.parametrize("name", SYSTEMS)
def test_c_lqg_matches_the_simulated_lqg_in_double(runs, name) -> None:
    d, ref, c_runs = runs[name, "lqg"]
    got = c_runs["double"]
    assert not ref.fell and not got.fell
    assert got.n_rows == ref.n_rows == round(4.0 * d.rate) + 1
    # A noisy run that moved the input (and the reference stepped).
    assert np.max(np.abs(ref.measurements - ref.states[:, [d.state_names.index(o)
                                                          for o in d.output_names]])) > 0
    assert np.ptp(ref.reference) > 0
    err = np.max(np.abs(got.saturated - ref.saturated))
    assert err <= 1e-12 * max(1.0, float(np.max(_activity(ref, d.plant.u0)))), err
    assert np.max(np.abs(got.estimates - ref.estimates)) <= 1e-12 * (1 + np.max(np.abs(ref.estimates)))
    # Stayed up and came back to the reference (the tracked output near it at the end).
    assert ref.stayed_up and got.stayed_up


@pytest.mark.parametrize("name", SYSTEMS)
def test_c_lqg_matches_the_simulated_lqg_in_float(runs, name) -> None:
    d, ref, c_runs = runs[name, "lqg"]
    got = c_runs["float"]
    assert not got.fell and got.stayed_up
    activity = _activity(ref, d.plant.u0)
    err = np.max(np.abs(got.saturated - ref.saturated), axis=0)
    assert np.all(err <= RELATIVE_TOLERANCE["float"] * activity), (err, activity)
    # ... and is really single precision: it does not agree to double precision.
    assert np.max(err) > 1e-9 * np.max(activity)


@pytest.mark.parametrize("name", ["cartpole", "seesaw"])
def test_c_lqr_matches_the_simulated_state_feedback(runs, name) -> None:
    d, ref, c_runs = runs[name, "lqr"]
    assert not ref.fell and not c_runs["double"].fell and not c_runs["float"].fell
    activity = _activity(ref, d.plant.u0)
    assert np.max(np.abs(c_runs["double"].saturated - ref.saturated)) <= 1e-12 * max(1.0, np.max(activity))
    err = np.max(np.abs(c_runs["float"].saturated - ref.saturated), axis=0)
    assert np.all(err <= RELATIVE_TOLERANCE["float"] * activity)


def test_some_run_saturates(runs) -> None:
    """The comparison covers the saturation branch: some reference run hits a limit."""
    hits = 0
    for d, ref, _ in runs.values():
        low, high = get_system(d.system_key).input_limits
        hits += int(np.sum((ref.saturated <= low) | (ref.saturated >= high)))
    assert hits > 0


def test_vectors_are_the_simulated_run(runs) -> None:
    d, ref, _ = runs["ball_beam", "lqg"]
    vec = record(d, get_system("ball_beam"), seed=SEED)
    assert np.array_equal(vec.y, ref.measurements)
    assert np.array_equal(vec.u, ref.saturated)
    assert np.array_equal(vec.r, ref.reference)


@pytest.mark.parametrize(("name", "precision"), [("wheeled_pendulum", "double"),
                                                  ("ball_beam", "float")])
def test_shipped_export_passes_its_own_check(tmp_path, name, precision) -> None:
    system = get_system(name)
    d = design(system, rate=system.spec.control_rate)
    done = export_c(d, tmp_path / "out", precision=precision, system=system)
    proc = subprocess.run([require("make"), "-C", str(done.folder), "check"], capture_output=True,
                          text=True, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"{done.vectors.n_steps} steps match" in proc.stdout


def test_command_line_export(tmp_path, capsys) -> None:
    out = tmp_path / "seesaw_float"
    assert main(["export", "seesaw", "--precision", "float", "--rate", "100", "--duration", "2",
                 "--out", str(out), "--json"]) == 0
    import json

    info = json.loads(capsys.readouterr().out)
    assert info["rate"] == 100.0 and info["precision"] == "float" and info["controller"] == "lqg"
    assert info["vector_steps"] == 201
    proc = subprocess.run([require("make"), "-C", str(out), "check"], capture_output=True, text=True,
                          check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert info["design_id"] in proc.stdout and "rate=100 Hz" in proc.stdout
    assert main(["export", "cartpole", "--controller", "lqr", "--out", str(tmp_path / "c")]) == 0
    text = capsys.readouterr().out
    assert "cartpole_lqr" in text and "200 Hz" in text
