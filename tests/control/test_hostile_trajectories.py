"""Hostile trajectory files and hostile plans: one line, exit 2, nothing read or solved.

A trajectory file (``trajopt --out``) is read by ``simulate``, ``batch`` and ``export``
(``--controller tvlqr --trajectory FILE``) and by ``trajopt --guess FILE``. The files here
are written by hand: a zip of ``.npy`` members, one of them changed, or only a header that
claims an array the file does not hold.
"""

from __future__ import annotations

import io
import json
import signal
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import numpy as np
import pytest
from tests.support.signals import cpu_seconds, signal_while_working
from tests.support.sim import cartpole, state_feedback

from equilibrist import get_system
from equilibrist.cli.main import main
from equilibrist.control import trajopt
from equilibrist.control.trajectory_file import load_trajectory
from equilibrist.control.trajopt import Trajectory, plan
from equilibrist.errors import DesignError
from equilibrist.sim import simulate
from equilibrist.tasks import get_task

ARRAYS = ("times", "states", "inputs", "mid_inputs")


def _one_line(code: int, err: str, *words: str) -> None:
    assert code == 2, err
    assert "Traceback" not in err
    assert len(err.strip().splitlines()) == 1, err
    for word in words:
        assert word in err, err


def _npy(value: object) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asanyarray(value), allow_pickle=False)
    return buf.getvalue()


def _header_only(shape: tuple[int, ...], descr: str = "<f8") -> bytes:
    """An ``.npy`` header that claims an array of *shape*, and no data."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": descr, "fortran_order": False,
                                               "shape": shape})
    return buf.getvalue()


def _parts(plan_file: Path) -> tuple[dict[str, object], dict[str, np.ndarray]]:
    with np.load(plan_file) as data:
        return json.loads(str(data["meta"])), {k: data[k] for k in ARRAYS}


def _write(path: Path, meta: dict[str, object] | str, arrays: dict[str, np.ndarray],
           **raw: bytes) -> Path:
    """A trajectory file of *meta* (a dict, or its JSON text) and *arrays*; *raw* members
    replace theirs byte for byte."""
    text = meta if isinstance(meta, str) else json.dumps(meta)
    members = {"meta": _npy(np.array(text)), **{k: _npy(v) for k, v in arrays.items()}, **raw}
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in members.items():
            zf.writestr(f"{name}.npy", data)
    return path


def _never_read(*args: object, **kwargs: object) -> None:
    raise AssertionError("an array was read before its header was checked")


# -- the size of an array, from its header ------------------------------------------------

def test_a_huge_array_is_refused_from_its_header(tmp_path, cart_plan, monkeypatch) -> None:
    # states claims 100,000,001 x 4 numbers (3.2 GB); the file holds a few kilobytes.
    meta, arrays = _parts(cart_plan)
    bomb = _write(tmp_path / "bomb.npz", meta, arrays, states=_header_only((10**8 + 1, 4)))
    assert bomb.stat().st_size < 20_000
    # No array is read at all (numpy's reader of .npy data, as np.load uses it): the
    # refusal comes from the headers alone.
    monkeypatch.setattr(np.lib.format, "read_array", _never_read)
    with pytest.raises(DesignError) as info:
        load_trajectory(bomb)
    message = str(info.value)
    assert "states" in message and "100000001 x 4" in message and "2,000,000" in message
    assert len(message.splitlines()) == 1


def test_a_huge_guess_is_one_line_on_the_command_line(tmp_path, cart_plan, capsys) -> None:
    meta, arrays = _parts(cart_plan)
    bomb = _write(tmp_path / "bomb.npz", meta, arrays, times=_header_only((10**9,)))
    code = main(["trajopt", "cartpole", "--guess", str(bomb)])
    _one_line(code, capsys.readouterr().err, "times", "1000000000")


# -- the metadata, field by field -----------------------------------------------------------

DROP = object()
META = [
    ("system", DROP), ("system", 7), ("system", "cart\x1b[2Jpole"), ("params", "abc"),
    ("params", {"m_c": "heavy"}), ("cost", None), ("max_defect", []), ("solve_time", "1"),
    ("iterations", "1e400"), ("iterations", -3), ("iterations", 2.5), ("settings", [1]),
    ("state_names", None), ("state_names", DROP), ("input_names", ["F", "F"]),
    ("input_names", ["F\n"]), ("converged", "yes"), ("solver", 7), ("system_digest", 5),
]


def _meta_file(tmp_path: Path, cart_plan: Path, key: str, value: object) -> Path:
    meta, arrays = _parts(cart_plan)
    if value is DROP:
        del meta[key]
        return _write(tmp_path / "t.npz", meta, arrays)
    if value == "1e400":  # JSON's number 1e400 (Python reads it as inf)
        meta[key] = "PLACEHOLDER"
        return _write(tmp_path / "t.npz",
                      json.dumps(meta).replace('"PLACEHOLDER"', "1e400"), arrays)
    meta[key] = value
    return _write(tmp_path / "t.npz", meta, arrays)


@pytest.mark.parametrize(("key", "value"), META, ids=[f"{k}=missing" if v is DROP else f"{k}={v!r}" for k, v in META])
def test_every_metadata_field_is_checked(tmp_path, cart_plan, key, value) -> None:
    path = _meta_file(tmp_path, cart_plan, key, value)
    with pytest.raises(DesignError) as info:
        load_trajectory(path)
    message = str(info.value)
    assert key in message and len(message.splitlines()) == 1, message
    assert "\x1b" not in message  # a name is described, never quoted


@pytest.mark.parametrize("argv", [
    ["simulate", "cartpole", "--controller", "tvlqr", "--duration", "1", "--trajectory"],
    ["batch", "cartpole", "--controller", "tvlqr", "--runs", "2", "--duration", "1",
     "--no-progress", "--trajectory"],
    ["export", "cartpole", "--controller", "tvlqr", "--out", "lib", "--trajectory"],
    ["trajopt", "cartpole", "--knots", "20", "--out", "again.npz", "--guess"],
], ids=["simulate", "batch", "export", "trajopt"])
def test_a_file_that_names_no_system_is_one_line(tmp_path, cart_plan, capsys, monkeypatch,
                                                  argv) -> None:
    monkeypatch.chdir(tmp_path)
    path = _meta_file(tmp_path, cart_plan, "system", DROP)
    code = main([*argv, str(path)])
    _one_line(code, capsys.readouterr().err, "system")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.npz"]


# -- the types of the arrays ----------------------------------------------------------------

def test_complex_and_object_arrays_are_refused(tmp_path, cart_plan) -> None:
    meta, arrays = _parts(cart_plan)
    complex_states = {**arrays, "states": arrays["states"] + 1j}
    path = _write(tmp_path / "c.npz", meta, complex_states)
    with pytest.raises(DesignError, match="states array holds complex numbers"):
        load_trajectory(path)
    path = _write(tmp_path / "o.npz", meta, arrays, inputs=_header_only((61, 1), "|O"))
    with pytest.raises(DesignError, match="inputs array holds Python objects"):
        load_trajectory(path)


# -- the plan's ends, and the overshoot of a run that starts on target -------------------------

def test_the_plan_starts_and_ends_exactly_where_it_was_asked(cart_plan) -> None:
    task = get_task(get_system("cartpole"), "swingup")
    traj = load_trajectory(cart_plan)
    np.testing.assert_array_equal(traj.states[0], np.asarray(task.start, dtype=float))
    np.testing.assert_array_equal(traj.states[-1], np.asarray(task.x_op, dtype=float))
    # A start that is no round number, bit for bit.
    cart = get_system("cartpole")
    start = np.array([0.1 / 3, np.pi / 7, 0.0, 0.0])
    moved = plan(cart, start=start, goal=task.x_op, knots=20, duration=2.0)
    assert moved.states[0].tobytes() == start.tobytes()


def test_a_tracked_swing_up_has_no_overshoot_of_the_cart(cart_plan, capsys) -> None:
    # The cart starts at x = 0, its target: it makes no move whose overshoot is a fraction.
    assert main(["simulate", "cartpole", "--controller", "tvlqr", "--trajectory",
                 str(cart_plan), "--duration", "6", "--json"]) == 0
    metrics = json.loads(capsys.readouterr().out)
    assert metrics["overshoot"]["x"] is None


def test_overshoot_of_a_start_as_good_as_on_target_is_none() -> None:
    sysm = cartpole()
    run = simulate(sysm, state_feedback(sysm, rate=500.0), duration=5.0,
                   x0={"x": 1e-30, "theta": 0.05})
    overshoot = run.metrics()["overshoot"]
    assert np.max(np.abs(run.state("x"))) > 1e-3  # the cart moves, from 1e-30 m off centre
    assert overshoot["x"] is None
    # theta's is the largest excursion past 0 below it, as a fraction of its 0.05 rad start.
    theta = run.state("theta")
    assert overshoot["theta"] == pytest.approx(max(0.0, -theta.min()) / 0.05)


# -- interrupting a plan ------------------------------------------------------------------------

# The command itself, with one line on stderr as IPOPT's solve begins (its marker).
_MARKED = """
import sys
import casadi
solve = casadi.Opti.solve
def marked(self):
    print("solving", file=sys.stderr, flush=True)
    return solve(self)
casadi.Opti.solve = marked
from equilibrist.cli.main import main
sys.argv = ["equilibrist", *sys.argv[1:]]
sys.exit(main())
"""


def _once_solving(proc: subprocess.Popen[bytes]) -> None:
    """Until the command says IPOPT's solve began, then half a second of its CPU more."""
    assert proc.stderr is not None
    line = proc.stderr.readline()
    assert line.strip() == b"solving", line
    began = cpu_seconds(proc.pid)
    while proc.poll() is None and cpu_seconds(proc.pid) < began + 0.5:
        time.sleep(0.02)


@pytest.mark.parametrize(("signum", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)],
                         ids=["SIGINT", "SIGTERM"])
def test_a_signalled_plan_is_interrupted(tmp_path, signum, status) -> None:
    # A minimum-time swing-up of 1000 intervals from a random guess: some 2,000 iterations
    # (minutes) unless stopped.
    argv = ["trajopt", "cartpole", "--knots", "1000", "--duration-max", "8", "--minimize",
            "time", "--guess", "random", "--out", "t.npz"]
    proc = subprocess.Popen([sys.executable, "-c", _MARKED, *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=tmp_path)
    code, _out, err, _took = signal_while_working(proc, signum, _once_solving)
    assert code == status, err.decode()
    assert err.decode().strip() == "equilibrist: interrupted"  # no CasADi warning
    assert list(tmp_path.iterdir()) == []


# -- a guess's duration, and the solve's time -----------------------------------------------------

def _no_plan(*args: object, **kwargs: object) -> None:
    raise AssertionError("the plan was solved")


def test_a_guess_of_a_duration_outside_the_bounds_is_refused(tmp_path, cart_plan, capsys,
                                                              monkeypatch) -> None:
    meta, arrays = _parts(cart_plan)
    tiny = _write(tmp_path / "tiny.npz", meta, {**arrays, "times": arrays["times"] * 1e-12})
    # The Python function: refused before IPOPT (with 5 iterations, an unchecked guess
    # would come back unconverged at once instead).
    cart = get_system("cartpole")
    task = get_task(cart, "swingup")
    with pytest.raises(DesignError, match="duration 4e-12 s is outside"):
        plan(cart, start=task.start, goal=task.x_op, duration_max=8.0, minimize="time",
             guess=load_trajectory(tiny), max_iterations=5)
    backwards = load_trajectory(cart_plan)
    backwards = Trajectory(**{**backwards.__dict__, "times": backwards.times[::-1].copy()})
    with pytest.raises(DesignError, match="strictly increasing"):
        plan(cart, start=task.start, goal=task.x_op, duration=4.0, guess=backwards,
             max_iterations=5)
    # The command line: one line naming the option, and no solve.
    monkeypatch.setattr(trajopt, "plan", _no_plan)
    code = main(["trajopt", "cartpole", "--guess", str(tiny), "--duration-max", "8",
                 "--minimize", "time"])
    _one_line(code, capsys.readouterr().err, "--guess", "--duration-max 8", "[0.4, 8]")


SLOW = ["trajopt", "cartpole", "--knots", "1000", "--duration-max", "8", "--minimize", "time",
        "--guess", "random"]


def test_max_time_stops_the_solve(tmp_path, capsys) -> None:
    out = tmp_path / "t.npz"
    code = main([*SLOW, "--max-time", "1", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 1, err
    assert len(err.splitlines()) == 1 and "--max-time 1 s" in err, err
    assert not out.exists()
    # The Python function: the same problem (built once), its status says why it stopped.
    cart = get_system("cartpole")
    task = get_task(cart, "swingup")
    from equilibrist.tasks import planning_bounds

    traj = plan(cart, start=task.start, goal=task.x_op, knots=1000, duration_max=8.0,
                minimize="time", guess="random", bounds=planning_bounds(task, 0.3), max_time=1.0)
    assert traj.status == "Maximum_WallTime_Exceeded" and not traj.converged  # IPOPT's word


@pytest.mark.parametrize("value", ["0", "-1", "inf", "nan", "abc", "1e7"])
def test_a_bad_max_time_is_one_line(capsys, monkeypatch, value) -> None:
    monkeypatch.setattr(trajopt, "plan", _no_plan)
    code = main(["trajopt", "cartpole", "--max-time", value])
    err = capsys.readouterr().err
    _one_line(code, err, "--max-time")
    assert "unrecognized" not in err


def test_max_time_and_its_default_are_in_the_help(capsys) -> None:
    with pytest.raises(SystemExit):
        main(["trajopt", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--max-time S wall-clock seconds the solve may take (default 120)" in text


# -- every output checked before the solve ---------------------------------------------------------

@pytest.mark.parametrize("outputs", [
    ["--out", "missing/t.npz"],
    ["--out", "folder.npz"],
    ["--out", "t.npz", "--plot", "missing/x.png"],
    ["--out", "t.npz", "--plot", "folder.png"],
    ["--out", "t.npz", "--animate", "folder.gif"],
], ids=["out-missing-folder", "out-is-a-folder", "plot-missing-folder", "plot-is-a-folder",
        "animate-is-a-folder"])
def test_every_output_is_checked_before_the_plan(tmp_path, capsys, monkeypatch, outputs) -> None:
    monkeypatch.chdir(tmp_path)
    for name in ("folder.npz", "folder.png", "folder.gif"):
        (tmp_path / name).mkdir()
    monkeypatch.setattr(trajopt, "plan", _no_plan)
    code = main(["trajopt", "cartpole", *outputs])
    _one_line(code, capsys.readouterr().err, outputs[-1].split("/")[0])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder.gif", "folder.npz",
                                                          "folder.png"]
