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
