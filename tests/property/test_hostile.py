"""What a hostile but realistic user tries: the promise is one line, exit 2, nothing lost.

Hypothesis draws command lines from every command with odd values, and
crafted result files that claim the right format; whatever it draws, a
command ends with exit 0 or with exactly one line on stderr and exit 2,
never a traceback, and a file that was there stays whole.
"""

from __future__ import annotations

import contextlib
import json
import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from equilibrist.atomic import atomic_path
from equilibrist.cli.main import main
from equilibrist.errors import EquilibristError
from equilibrist.sim.result import FORMAT, SimResult

ODD = ["nan", "inf", "-inf", "1e400", "-1e400", "", " ", "abc", "0", "-0", "-1", "1e-300",
       "1e308", "=", "a=b", ":::", "theta=nan", "x=1e999", "1,2", ",", "0x10", "1_0", "--",
       "theta", "m_p=", "=3", "../../etc/passwd", "ñ", "1e9", "-1e9"]

COMMANDS = {
    "show": ["--latex"],
    "dynamics": ["--state", "--input", "--set"],
    "linearize": ["--at", "--input", "--set", "--outputs"],
    "design": ["--rate", "--q", "--r", "--qn", "--rn", "--outputs", "--set", "--at"],
    "linkage": ["--geometry", "--platform-angle", "--motor-angle"],
}


def _one_line_or_success(code: int, err: str) -> None:
    assert code in (0, 2), err
    assert "Traceback" not in err
    if code == 2:
        assert len(err.strip().splitlines()) == 1, err


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    command=st.sampled_from(sorted(COMMANDS)),
    system=st.sampled_from(["cartpole", "seesaw", "gyroscope", "nothing", "", "cartpole.py", "/dev/null"]),
    picks=st.lists(st.tuples(st.integers(0, 7), st.sampled_from(ODD)), max_size=3),
)
def test_odd_command_lines(capsys, command, system, picks) -> None:
    options = COMMANDS[command]
    argv = [command] if command == "linkage" else [command, system]
    for k, value in picks:
        argv += [options[k % len(options)], value]
    code = main(argv)
    _one_line_or_success(code, capsys.readouterr().err)


# -- crafted result files ------------------------------------------------------

def _valid_arrays(rows: int = 5) -> tuple[dict[str, object], dict[str, np.ndarray]]:
    meta: dict[str, object] = {
        "format": FORMAT, "system": "cartpole",
        "params": {"m_c": 10.0, "m_p": 1.0, "l": 0.5, "I_p": 0.08333, "b_c": 0.0, "b_p": 0.0,
                   "g": 9.8, "x_max": 1.0, "F_min": -200.0, "F_max": 200.0},
        "state_names": ["x", "theta", "x_dot", "theta_dot"], "state_units": ["m", "rad", "m/s", "rad/s"],
        "input_names": ["F"], "input_units": ["N"], "output_names": ["x", "theta"],
        "reference_names": [], "fell": False, "fell_at": None, "fell_state": None,
        "settings": {"rate": 200.0, "controller": {"kind": "lqr"}},
    }
    t = np.arange(rows) * 0.005
    states = np.column_stack([0.01 * t, 0.1 - t, np.zeros(rows), -np.ones(rows)])
    arrays = {
        "time": t, "states": states, "measurements": states[:, :2], "commanded": np.ones((rows, 1)),
        "saturated": np.ones((rows, 1)), "applied": np.ones((rows, 1)), "reference": np.zeros((rows, 0)),
        "x_op": np.zeros(4), "u_op": np.zeros(1), "final_state": states[-1],
    }
    return meta, arrays


def _write(path: Path, meta: object, arrays: dict[str, object]) -> None:
    np.savez(path, meta=np.array(json.dumps(meta)), **arrays)  # type: ignore[arg-type]


def test_a_valid_crafted_file_loads(tmp_path) -> None:
    meta, arrays = _valid_arrays()
    _write(tmp_path / "ok.npz", meta, arrays)
    result = SimResult.load(tmp_path / "ok.npz")
    assert result.n_rows == 5 and result.state_names[1] == "theta"


META_DAMAGE = st.one_of(
    st.tuples(st.just("drop"), st.sampled_from(["system", "params", "state_names", "fell", "settings",
                                                "input_names", "output_names", "format"])),
    st.tuples(st.just("set"), st.sampled_from(["system", "params", "state_names", "fell", "fell_at",
                                               "settings", "state_units", "reference_names"]),
              st.sampled_from([None, 3, "text", [1, 2], {"a": "b"}, True, 1e308, [None]])),
)
ARRAY_DAMAGE = st.one_of(
    st.tuples(st.just("drop"), st.sampled_from(["time", "states", "measurements", "applied", "x_op",
                                                "final_state", "reference"])),
    st.tuples(st.just("value"), st.sampled_from(["time", "states", "commanded", "x_op"]),
              st.sampled_from(["nan", "inf", "strings", "shape", "empty", "reversed"])),
)


def _damage_array(arrays: dict[str, object], name: str, how: str) -> None:
    if name not in arrays or np.asarray(arrays[name]).dtype.kind not in "fiub":
        return
    a = np.array(arrays[name], dtype=float)
    if a.size == 0:
        return
    if how == "nan":
        a.flat[0] = np.nan
    elif how == "inf":
        a.flat[-1] = np.inf
    elif how == "strings":
        arrays[name] = np.array(["a"] * a.size)
        return
    elif how == "shape":
        a = a.reshape(-1)[:-1] if a.size > 1 else np.zeros((2, 2))
    elif how == "empty":
        a = a[:0]
    elif how == "reversed":
        a = a[::-1].copy()
    arrays[name] = a


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(meta_damage=st.lists(META_DAMAGE, max_size=2), array_damage=st.lists(ARRAY_DAMAGE, max_size=2))
def test_crafted_result_files(tmp_path_factory, capsys, meta_damage, array_damage) -> None:
    folder = tmp_path_factory.mktemp("crafted")
    meta, arrays = _valid_arrays()
    for item in meta_damage:
        if item[0] == "drop":
            meta.pop(item[1], None)
        else:
            meta[item[1]] = item[2]
    for item in array_damage:
        if item[0] == "drop":
            arrays.pop(item[1], None)
        else:
            _damage_array(arrays, item[1], item[2])  # type: ignore[arg-type]
    path = folder / "run.npz"
    _write(path, meta, arrays)
    with contextlib.suppress(EquilibristError):
        SimResult.load(path)
    for argv in (["plot", str(path), "--out", str(folder / "p.png")],
                 ["animate", str(path), "--out", str(folder / "a.gif"), "--max-frames", "3"]):
        code = main(argv)
        _one_line_or_success(code, capsys.readouterr().err)


@pytest.mark.parametrize("content", [b"", b"not a zip", b"PK\x03\x04 truncated"])
def test_garbage_result_files(tmp_path, capsys, content) -> None:
    path = tmp_path / "run.npz"
    path.write_bytes(content)
    assert main(["plot", str(path), "--out", str(tmp_path / "p.png")]) == 2
    _one_line_or_success(2, capsys.readouterr().err)


# -- nothing lost ---------------------------------------------------------------

def test_a_failed_write_keeps_the_old_file(tmp_path) -> None:
    target = tmp_path / "run.npz"
    target.write_bytes(b"the user's valid file")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        tmp.write_bytes(b"half")
        raise RuntimeError("disk full")
    assert target.read_bytes() == b"the user's valid file"
    assert sorted(os.listdir(tmp_path)) == ["run.npz"]


def test_a_result_save_that_fails_midway_keeps_the_old_file(tmp_path, monkeypatch) -> None:
    meta, arrays = _valid_arrays()
    _write(tmp_path / "src.npz", meta, arrays)
    result = SimResult.load(tmp_path / "src.npz")
    target = tmp_path / "run.npz"
    target.write_bytes(b"previous run")

    def broken_savez(file, **kwargs):
        Path(file).write_bytes(b"PK partial")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(np, "savez", broken_savez)
    with pytest.raises(OSError, match="space"):
        result.save(target)
    assert target.read_bytes() == b"previous run"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.npz", "src.npz"]


@pytest.mark.parametrize("name", ["", "run.txt", "run"])
def test_result_file_names_that_say_nothing_are_refused(tmp_path, name) -> None:
    meta, arrays = _valid_arrays()
    _write(tmp_path / "src.npz", meta, arrays)
    result = SimResult.load(tmp_path / "src.npz")
    with pytest.raises(EquilibristError, match="expected"):
        result.save(tmp_path / name if name else Path(""))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["src.npz"]


def test_linkage_answers_the_exact_question_where_the_approximation_has_no_pose(capsys) -> None:
    from equilibrist.mechanics.linkage import FourBar, UnreachablePoseError

    bar = FourBar(a=0.05, b=0.03, c=0.06, d=0.04, e=0.08)
    with pytest.raises(UnreachablePoseError):
        bar.approximate_platform_angle(0.25, branch="plus")
    assert main(["linkage", "--geometry", "a=0.05,b=0.03,c=0.06,d=0.04,e=0.08",
                 "--motor-angle", "0.25", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["approximate"]["phi"] is None
    # The exact pose closes the loop: the independent check of the answer.
    assert abs(out["residual"]) < 1e-12
    assert bar.closure_residual(0.25, out["phi"]) == pytest.approx(0.0, abs=1e-12)


def test_a_rate_too_fast_is_named_as_the_reason(capsys) -> None:
    assert main(["design", "cartpole", "--rate", "1e9"]) == 2
    line = capsys.readouterr().err.strip()
    assert "too fast" in line and "1e+09 Hz" in line and "stabilizable" not in line


@pytest.mark.parametrize("value", ["-inf,0,0,0", "-nan,0,0,0", "-Infinity,0,0,0"])
def test_negative_non_finite_values_are_values(capsys, value) -> None:
    assert main(["dynamics", "cartpole", "--state", value]) == 2
    line = capsys.readouterr().err.strip()
    assert "expected one argument" not in line and "finite" in line


def test_export_never_overwrites_the_users_files(tmp_path, capsys) -> None:
    folder = tmp_path / "robot"
    folder.mkdir()
    (folder / "Makefile").write_text("the user's own Makefile")
    assert main(["export", "cartpole", "--out", str(folder)]) == 2
    assert "--force" in capsys.readouterr().err
    assert (folder / "Makefile").read_text() == "the user's own Makefile"
    assert sorted(p.name for p in folder.iterdir()) == ["Makefile"]
    # An earlier export is equilibrist's own: writing again replaces it.
    again = tmp_path / "export"
    assert main(["export", "cartpole", "--out", str(again)]) == 0
    assert main(["export", "cartpole", "--out", str(again)]) == 0
    assert main(["export", "cartpole", "--out", str(folder), "--force"]) == 0
    assert "the user's own" not in (folder / "Makefile").read_text()


def test_a_terminated_demo_leaves_nothing(tmp_path) -> None:
    import signal
    import subprocess
    import sys
    import time

    report = tmp_path / "report"
    proc = subprocess.Popen([sys.executable, "-m", "equilibrist.cli.main", "demo", "cartpole",
                             "--out", str(report), "--jobs", "1"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not any(tmp_path.glob(".report.partial-*/*")):
        time.sleep(0.05)
    assert any(tmp_path.glob(".report.partial-*")), "the demo never started its report"
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode != 0
    assert b"Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == []


# -- Ctrl-C stops a long run, with or without a progress bar --------------------

def _interrupt_after_start(argv: list[str], folder: Path) -> tuple[int, bytes, bytes, float]:
    """Start the command with stdout to a pipe, interrupt it while it works: once its runs
    have begun in the compiled core (its first call of ``call_interruptibly``, past the
    imports and the core's load) and gone on for half a second of its CPU.

    Returns the exit status, stdout, stderr and the seconds from SIGINT to its end.
    """
    import signal

    from tests.support.signals import signal_while_working, start_at_work

    # Where each command's runs enter the core (run.py calls it by its module's name, batch.py
    # by the name it imported).
    core = {"simulate": "equilibrist.sim.run", "batch": "equilibrist.sim.batch"}[argv[0]]
    proc, ready = start_at_work(argv, folder, f"{core}:call_interruptibly")
    return signal_while_working(proc, signal.SIGINT, ready)


@pytest.mark.parametrize("argv", [
    # One long run: 3000 s at 5000 physics steps a sample (3e9 steps: minutes on any core).
    ["simulate", "cartpole", "--duration", "3000", "--physics-step", "1e-6", "--json",
     "--out", "run.npz"],
    ["simulate", "cartpole", "--duration", "3000", "--physics-step", "1e-6", "--no-progress",
     "--out", "run.npz"],
    # Many short runs: 1e9 steps in all.
    ["batch", "cartpole", "--runs", "100000", "--duration", "10", "--json", "--out", "b.csv"],
], ids=["simulate-json-pipe", "simulate-no-progress", "batch-json-pipe"])
def test_ctrl_c_stops_a_long_run_without_a_progress_bar(tmp_path, argv) -> None:
    code, out, err, took = _interrupt_after_start(argv, tmp_path)
    assert code == 130, err
    assert err.decode().strip() == "equilibrist: interrupted"
    assert out == b""
    # Calls of the compiled core last about 0.2 s; a loaded machine stretches them.
    from tests.support.signals import STOPS_WITHIN

    assert took < STOPS_WITHIN, f"took {took:.1f} s to stop"
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_run_made_in_many_calls_equals_the_run_in_one(monkeypatch) -> None:
    from equilibrist import get_system
    from equilibrist.control.design import design
    from equilibrist.control.linear import LinearController
    from equilibrist.sim import run as run_module
    from equilibrist.sim.events import ParameterChange, Pulse
    from equilibrist.sim.noise import Noise

    system = get_system("cartpole")
    d = design(system, outputs=["x", "theta"], rate=200.0)
    ctrl = LinearController.from_design(d, kind="lqg")
    kwargs = dict(duration=2.0, x0={"theta": 0.1}, noise=Noise.from_design(d), seed=7,
                  events=[Pulse(0.5, 20.0, 0.05), ParameterChange(1.0, {"m_p": 1.3})])
    whole = run_module.simulate(system, ctrl, **kwargs)  # one call of the core (400 samples)
    assert whole.n_rows <= run_module._FIRST_CHUNK_STEPS // 5
    monkeypatch.setattr(run_module, "_FIRST_CHUNK_STEPS", 1)
    monkeypatch.setattr(run_module, "CHUNK_SECONDS", 1e-12)  # then one sample a call
    pieces = run_module.simulate(system, ctrl, **kwargs)
    for name in ("states", "estimates", "measurements", "commanded", "applied"):
        np.testing.assert_array_equal(getattr(pieces, name), getattr(whole, name))
    np.testing.assert_array_equal(pieces.final_state, whole.final_state)


# -- work is bounded before it starts -------------------------------------------

def test_an_absurd_physics_step_is_refused_before_any_work(capsys) -> None:
    assert main(["simulate", "cartpole", "--physics-step", "1e-12", "--json"]) == 2
    line = capsys.readouterr().err.strip()
    assert len(line.splitlines()) == 1
    # 5 s at 200 Hz is 1000 samples of 5e-3 s / 1e-12 s = 5e9 steps each.
    assert "5e+12 physics steps" in line and "--max-steps" in line and "hours" in line


def test_max_steps_is_the_bound_it_says(capsys) -> None:
    # 1 s at 200 Hz with the default 1 ms step: 200 samples of 5 steps.
    argv = ["simulate", "cartpole", "--duration", "1", "--noise", "off", "--json"]
    assert main([*argv, "--max-steps", "999"]) == 2
    assert "1e+03 physics steps" in capsys.readouterr().err
    assert main([*argv, "--max-steps", "1000"]) == 0
    capsys.readouterr()
    batch = ["batch", "cartpole", "--runs", "10", "--duration", "1", "--json"]
    assert main([*batch, "--max-steps", "9999"]) == 2
    assert "a batch of 10 runs asks for 1e+04 physics steps" in capsys.readouterr().err
    assert main([*batch, "--max-steps", "1e4"]) == 0
    capsys.readouterr()
    assert main([*argv, "--max-steps", "inf"]) == 0
    capsys.readouterr()
    for bad in ("0", "-5", "nan", "many"):
        assert main([*argv, "--max-steps", bad]) == 2
        _one_line_or_success(2, capsys.readouterr().err)


def test_the_python_api_bounds_work_too() -> None:
    from equilibrist import get_system
    from equilibrist.errors import SimulationError
    from equilibrist.sim import simulate
    from equilibrist.sim.batch import simulate_batch

    system = get_system("cartpole")
    with pytest.raises(SimulationError, match="max_steps="):
        simulate(system, duration=5.0, rate=200.0, physics_step=1e-12)
    with pytest.raises(SimulationError, match="a batch of 1000000 runs"):
        simulate_batch(system, runs=1_000_000, duration=100.0, rate=200.0)
    with pytest.raises(SimulationError, match="max_steps"):
        simulate(system, duration=1.0, rate=200.0, max_steps="lots")  # type: ignore[arg-type]
    assert simulate(system, duration=0.1, rate=200.0, max_steps=100).n_rows == 21


# -- spreads are checked as spreads ----------------------------------------------

@pytest.mark.parametrize("seed", ["0", "1", "2", "3"])
def test_a_spread_that_leaves_the_valid_range_is_refused_whatever_the_draw(capsys, seed) -> None:
    assert main(["batch", "cartpole", "--runs", "4", "--duration", "0.1", "--spread", "m_p=1.5",
                 "--seed", seed]) == 2
    line = capsys.readouterr().err.strip()
    assert "m_p" in line and "-0.5 to 2.5" in line and "(0, inf)" in line and "below 1" in line


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(rel=st.floats(0.0, 3.0), name=st.sampled_from(["m_p", "l", "b_c", "g", "F_max"]))
def test_spreads_fail_or_not_independently_of_the_draw(rel, name) -> None:
    from equilibrist import get_system
    from equilibrist.errors import SimulationError
    from equilibrist.sim.batch_inputs import sample_uniform

    system = get_system("cartpole")
    param = {p.name: p for p in system.spec.all_parameters}[name]
    outcomes = []
    for seed in range(3):
        try:
            _, params = sample_uniform(system, 50, spread={name: rel}, seed=seed)
        except SimulationError as exc:
            outcomes.append(str(exc))
        else:
            outcomes.append("ok")
            assert all(param.check(float(v)) is None for v in params[name])
    assert len(set(outcomes)) == 1
    nominal = system.params[name]
    ends = (nominal * (1 - rel), nominal * (1 + rel))
    assert (outcomes[0] == "ok") == all(param.check(v) is None for v in ends)


# -- files the options promise ----------------------------------------------------

def test_batch_out_csv_writes_the_table_the_help_promises(tmp_path, capsys) -> None:
    import csv

    with pytest.raises(SystemExit):
        main(["batch", "--help"])
    assert "FILE.csv" in capsys.readouterr().out.replace("\n", " ")
    out = tmp_path / "b.csv"
    assert main(["batch", "cartpole", "--runs", "6", "--duration", "1", "--x0", "theta=-0.3:0.3",
                 "--json", "--out", str(out)]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["saved"] == str(out)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.csv"]
    lines = out.read_text().splitlines()
    assert lines[0].startswith("#")
    rows = list(csv.DictReader(lines[1:]))
    assert len(rows) == 6
    assert [int(float(r["run"])) for r in rows] == list(range(6))
    assert sum(float(r["fell"]) == 0 for r in rows) == summary["stayed_up"]
    assert all(-0.3 <= float(r["theta_0"]) <= 0.3 for r in rows)
    assert {"x_0", "m_p", "peak_F", "rms_F", "time_saturated"} <= set(rows[0])


@pytest.mark.parametrize("command", [["simulate", "cartpole"],
                                     ["batch", "cartpole", "--runs", "2"]])
@pytest.mark.parametrize("name", ["", " ", "run.txt", "run"])
def test_a_bad_out_is_refused_before_running(tmp_path, capsys, monkeypatch, command, name) -> None:
    from equilibrist.sim import batch as batch_module
    from equilibrist.sim import run as run_module

    def never(*args, **kwargs):
        raise AssertionError("a run started")

    monkeypatch.setattr(run_module, "_run_compiled", never)
    monkeypatch.setattr(batch_module, "Kernel", never)
    monkeypatch.chdir(tmp_path)
    assert main([*command, "--duration", "0.5", "--out", name]) == 2
    _one_line_or_success(2, capsys.readouterr().err)
    assert list(tmp_path.iterdir()) == []


# -- references the plant can take; the peaks named for what they are --------------

@pytest.mark.parametrize("signal", ["ramp:1e308", "step:1e300", "ramp:-1e308@1", "square:1e305:1"])
def test_a_reference_beyond_any_command_is_refused(capsys, signal) -> None:
    assert main(["simulate", "cartpole", "--controller", "lqr", "--reference", signal,
                 "--json"]) == 2
    line = capsys.readouterr().err.strip()
    assert len(line.splitlines()) == 1 and "reference of x" in line and "finite" in line


def test_a_reference_outside_the_region_still_runs_and_falls(capsys) -> None:
    # The rig would leave its track: the run says so, it is not refused.
    assert main(["simulate", "cartpole", "--controller", "lqr", "--reference", "step:50",
                 "--noise", "off", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["fell"] is True


def test_peak_command_and_peak_input_are_named_for_what_they_are(capsys) -> None:
    # A 5 N actuator against a 0.3 rad start: the command exceeds what acts.
    assert main(["simulate", "cartpole", "--controller", "lqr", "--set", "F_max=5", "F_min=-5",
                 "--x0", "theta=0.3", "--duration", "1", "--noise", "off", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["peak_command"]["F"] > 5.0
    assert out["peak_input"]["F"] == pytest.approx(5.0, abs=1e-12)
    assert out["time_saturated"] > 0


# -- the Python API: every user mistake is an EquilibristError naming the argument --

WRONG = [None, "abc", "", 3, -1, 2.5, float("nan"), float("inf"), True, [], [1, "a"], {},
         {"m_p": "heavy"}, {3: 1.0}, {"theta": "a"}, ("a", "b"), object(), b"bytes",
         np.array(["x"]), [[1, 2], [3]], {"theta": (0, 1)}, {"theta": (0, 1, "many")}]


def _api_calls():
    from equilibrist import get_system
    from equilibrist.control.design import design
    from equilibrist.export.writer import export_c
    from equilibrist.sim import simulate
    from equilibrist.sim.batch import monte_carlo, region_of_attraction, simulate_batch
    from equilibrist.tasks import get_task

    system = get_system("cartpole")
    run = {"duration": 0.05, "rate": 200.0}
    return {
        "design.system": design,
        "design.outputs": lambda v: design(system, outputs=v),
        "design.rate": lambda v: design(system, rate=v),
        "design.q": lambda v: design(system, q=v),
        "design.at": lambda v: design(system, at=v),
        "design.discretization": lambda v: design(system, rate=200.0, discretization=v),
        "simulate.system": lambda v: simulate(v, **run),
        "simulate.controller": lambda v: simulate(system, v, **run),
        "simulate.reference": lambda v: simulate(system, design(system, rate=200.0), reference=v, **run),
        "simulate.x0": lambda v: simulate(system, x0=v, **run),
        "simulate.duration": lambda v: simulate(system, duration=v, rate=200.0),
        "simulate.events": lambda v: simulate(system, events=v, **run),
        "simulate.outputs": lambda v: simulate(system, outputs=v, **run),
        "simulate.region": lambda v: simulate(system, region=v, **run),
        "simulate.noise": lambda v: simulate(system, noise=v, **run),
        "simulate.seed": lambda v: simulate(system, seed=v, **run),
        "simulate.integrator": lambda v: simulate(system, integrator=v, **run),
        "simulate.plant": lambda v: simulate(system, plant=v, **run),
        "simulate.delay": lambda v: simulate(system, delay=v, **run),
        "simulate.excitation": lambda v: simulate(system, excitation=v, **run),
        "simulate.max_steps": lambda v: simulate(system, max_steps=v, **run),
        "simulate_batch.system": lambda v: simulate_batch(v, runs=2, **run),
        "simulate_batch.runs": lambda v: simulate_batch(system, runs=v, **run),
        "simulate_batch.params": lambda v: simulate_batch(system, runs=2, params=v, **run),
        "simulate_batch.x0": lambda v: simulate_batch(system, runs=2, x0=v, **run),
        "simulate_batch.workers": lambda v: simulate_batch(system, runs=2, workers=v, **run),
        "region_of_attraction.grid": lambda v: region_of_attraction(system, None, grid=v, **run),
        "region_of_attraction.samples": lambda v: region_of_attraction(system, None, samples=v,
                                                                       runs=2, **run),
        "monte_carlo.spread": lambda v: monte_carlo(system, None, spread=v, runs=2, **run),
        "monte_carlo.runs": lambda v: monte_carlo(system, None, spread={"m_p": 0.1}, runs=v, **run),
        "export_c.design": lambda v: export_c(v, "never-written"),
        "get_task.system": lambda v: get_task(v, "balance"),
        "get_task.name": lambda v: get_task(system, v),
        "envs.make.system": lambda v: _make_env(system=v),
        "envs.make.rate": lambda v: _make_env(rate=v),
        "envs.make.params": lambda v: _make_env(params=v),
    }


def _make_env(**kwargs):
    import gymnasium as gym

    import equilibrist.envs  # noqa: F401  (registers the ids)

    return gym.make("equilibrist/cartpole-balance-v0", **kwargs)


API_CALLS = _api_calls()


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(entry=st.sampled_from(sorted(API_CALLS)), value=st.sampled_from(WRONG))
def test_wrong_types_through_the_api_are_equilibrist_errors(tmp_path_factory, monkeypatch,
                                                            entry, value) -> None:
    monkeypatch.chdir(tmp_path_factory.mktemp("api"))
    try:
        API_CALLS[entry](value)
    except EquilibristError as exc:
        assert str(exc).strip() and "\n" not in str(exc).strip()
    assert not Path("never-written").exists()


def test_peak_command_and_peak_input_in_runs_and_batches() -> None:
    from equilibrist import get_system
    from equilibrist.control.design import design
    from equilibrist.sim import simulate, simulate_batch
    from equilibrist.sim.controllers import StateFeedback

    cart = get_system("cartpole", F_min=-5.0, F_max=5.0)
    d = design(cart, rate=200)
    ctrl = StateFeedback.from_design(d)
    run = simulate(cart, ctrl, duration=1.0, x0={"theta": 0.2})
    metrics = run.metrics()
    # The command asks for more than the 5 N actuator gives; the input applied is the limit.
    assert metrics["peak_command"]["F"] > 5.0
    assert metrics["peak_input"]["F"] == pytest.approx(5.0)
    batch = simulate_batch(cart, ctrl, duration=1.0, runs=3, x0={"theta": [0.2, 0.2, 0.2]})
    assert np.all(batch.peak_command[:, 0] > 5.0)
    np.testing.assert_allclose(batch.peak_input[:, 0], 5.0)
    np.testing.assert_allclose(batch.peak_command[0], abs(run.commanded).max(axis=0))
