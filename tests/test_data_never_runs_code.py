"""A data file never runs code: results, batches, studies and parameter files that name a Python system.

Each crafted file names a Python file whose import writes a marker. Every
reader (the command line's plot, animate, sweep --study and --params, and
the Python API's loaders and pictures) must refuse it in one line, or use
what the file carries, without the marker ever appearing. When the user
names the system (``--system``), it runs, and it must be the same definition
as the data's (its content digest).
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.cli.main import main
from equilibrist.errors import CodeInDataError, EquilibristError
from equilibrist.numeric.lookup import system_from_key
from equilibrist.sim import BatchResult, SimResult
from equilibrist.sim.result import read_npz

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "my_cartpole.py"


def _evil(folder: Path, marker: Path, *, body: str = "") -> Path:
    """A Python file whose import leaves *marker* behind (and that may hold a real system)."""
    path = folder / "evil_system.py"
    path.write_text(f"{body}\nfrom pathlib import Path as _Path\n_Path({str(marker)!r}).write_text('ran')\n")
    return path


def _run(system_key: str, *, digest: str | None = None, params: dict[str, float] | None = None
         ) -> SimResult:
    """A short cart-pole run (made by hand: no simulation needed to read it back)."""
    sysm = get_system("cartpole")
    rows = 5
    t = np.arange(rows) * 0.01
    states = np.zeros((rows, 4))
    states[:, 1] = np.linspace(0.1, 0.05, rows)
    u = np.zeros((rows, 1))
    return SimResult(
        system=system_key, params=dict(sysm.params) if params is None else params,
        state_names=sysm.state_names,
        state_units=sysm.state_units, input_names=sysm.input_names, input_units=sysm.input_units,
        output_names=("x", "theta"), reference_names=(), time=t, states=states, estimates=None,
        measurements=states[:, :2], commanded=u, saturated=u, applied=u,
        reference=np.zeros((rows, 0)), x_op=np.zeros(4), u_op=np.zeros(1), fell=False,
        fell_at=None, fell_state=None, fell_x=None, final_state=states[-1],
        settings={"rate": 100.0, "controller": {"kind": "open_loop"}}, system_digest=digest,
    )


def _batch(system_key: str) -> BatchResult:
    sysm = get_system("cartpole")
    runs, n = 3, 4
    x0 = np.zeros((runs, n))
    x0[:, 1] = [0.1, 0.2, 0.3]
    z = np.zeros((runs, n))
    one = np.zeros((runs, 1))
    return BatchResult(
        system=system_key, state_names=sysm.state_names, input_names=sysm.input_names,
        parameter_names=sysm.spec.parameter_names, x0=x0,
        params=np.tile([sysm.params[p] for p in sysm.spec.parameter_names], (runs, 1)),
        fell=np.array([False, False, True]), fell_at=np.array([np.nan, np.nan, 0.5]),
        fell_code=np.array([-1, -1, 1]), fell_x=z, final_state=z, peak_input=one,
        peak_command=one, rms_input=one, time_saturated=one, peak_deviation=z,
        estimation_error_rms=None, rows=np.full(runs, 5), seeds=(None, None, None),
        settings={"rate": 100.0}, elapsed=0.1, steps=10,
    )


def _one_line_refusal(capsys: pytest.CaptureFixture[str], argv: list[str]) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err
    assert len(err.splitlines()) == 1, err
    return err


@pytest.fixture
def evil(tmp_path: Path) -> tuple[Path, Path]:
    marker = tmp_path / "marker"
    return _evil(tmp_path, marker), marker


def test_plot_and_animate_of_a_crafted_run_never_run_the_file(
        evil: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, marker = evil
    run = _run(str(path)).save(tmp_path / "run.npz")
    other = _run(str(path)).save(tmp_path / "other.npz")
    for argv in (["plot", str(run), "--out", str(tmp_path / "p.png")],
                 ["plot", str(run), str(other), "--out", str(tmp_path / "c.png")],
                 ["animate", str(run), "--out", str(tmp_path / "a.gif")]):
        err = _one_line_refusal(capsys, argv)
        assert "--system" in err and str(path) in err, err
        assert not marker.exists(), f"{argv[0]} ran the file the data named"
    assert not (tmp_path / "p.png").exists() and not (tmp_path / "a.gif").exists()


def test_plot_of_a_crafted_batch_never_runs_the_file(
        evil: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path, marker = evil
    batch = _batch(str(path)).save(tmp_path / "batch.npz")
    err = _one_line_refusal(capsys, ["plot", str(batch), "--out", str(tmp_path / "b.png")])
    assert "never runs code" in err
    assert not marker.exists()


def test_the_python_api_never_runs_a_file_the_data_names(evil: tuple[Path, Path], tmp_path: Path) -> None:
    from equilibrist.viz.animation import animate_result
    from equilibrist.viz.plots import plot_batch
    from equilibrist.viz.plots_runs import plot_comparison, plot_response
    from equilibrist.viz.runs import as_run

    path, marker = evil
    saved = _run(str(path)).save(tmp_path / "run.npz")
    csv = _run(str(path)).to_csv(tmp_path / "run.csv")
    batch = BatchResult.load(_batch(str(path)).save(tmp_path / "batch.npz"))
    for result in (SimResult.load(saved), SimResult.load(csv)):
        assert result.system == str(path)  # loading alone reads the name, nothing more
        for show in (plot_response, lambda r: plot_comparison([r, r]), as_run,
                     lambda r: animate_result(r, tmp_path / "x.gif")):
            with pytest.raises(CodeInDataError, match="never runs code"):
                show(result)
    with pytest.raises(CodeInDataError):
        plot_batch(batch)
    with pytest.raises(CodeInDataError):
        system_from_key(str(path), {})
    # The same in other spellings of a Python file's name.
    with pytest.raises(CodeInDataError):
        system_from_key(str(path.parent / "." / path.name), {})
    assert not marker.exists()


def test_a_study_file_naming_a_python_file_is_refused(
        evil: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from equilibrist.study import load_study_file
    from equilibrist.study.record import StudyError

    path, marker = evil
    study = tmp_path / "study.toml"
    study.write_text(f'system = "{path}"\nruns = 2\n[vary]\nm_p = "0.5:1:2"\n')
    with pytest.raises(StudyError, match="never runs code"):
        load_study_file(study)
    err = _one_line_refusal(capsys, ["sweep", "--study", str(study), "--out",
                                     str(tmp_path / "s.parquet")])
    assert f"equilibrist sweep {path} --study" in err
    assert not marker.exists()
    assert not (tmp_path / "s.parquet").exists()
    # Naming another file than the study's own is refused before it is run.
    other = tmp_path / "other.py"
    other.write_text("raise SystemExit('never imported')\n")
    with pytest.raises(StudyError, match="contents differ"):
        load_study_file(study, system=str(other))
    with pytest.raises(StudyError, match="is a study of cartpole"):
        study.write_text('system = "cartpole"\nruns = 2\n[vary]\nm_p = "0.5:1:2"\n')
        load_study_file(study, system="furuta")


def test_a_parameter_file_naming_a_python_file_is_not_run(
        evil: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from equilibrist.ident.params import read_params

    path, marker = evil
    params = tmp_path / "params.json"
    params.write_text(json.dumps({"system": str(path), "params": {"m_p": 1.0}}))
    with pytest.raises(EquilibristError):
        read_params(params, system="cartpole")
    _one_line_refusal(capsys, ["linearize", "cartpole", "--params", str(params)])
    assert not marker.exists()


def test_a_named_system_must_be_the_one_the_data_came_from(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    marker = tmp_path / "marker"
    rig = _evil(tmp_path, marker, body=EXAMPLE.read_text())  # a real system that leaves a marker
    digest = hashlib.sha256(rig.read_bytes()).hexdigest()
    params = dict(get_system(str(rig)).params)
    assert marker.exists()  # named by the user (here, in Python): it runs
    run = _run(str(tmp_path / "elsewhere" / rig.name), digest=digest, params=params)
    run.save(tmp_path / "run.npz")
    run = tmp_path / "run.npz"
    assert read_npz(run)[0]["system_digest"] == digest

    # Named by the user, wherever it now lives: the picture is drawn.
    assert main(["plot", str(run), "--system", str(rig), "--out", str(tmp_path / "p.png")]) == 0
    assert (tmp_path / "p.png").stat().st_size > 0
    capsys.readouterr()

    # Another content under the same name is refused in one line.
    changed = tmp_path / "changed"
    changed.mkdir()
    shutil.copy(rig, changed / rig.name)
    with (changed / rig.name).open("a") as fh:
        fh.write("\n# changed\n")
    err = _one_line_refusal(capsys, ["plot", str(run), "--system", str(changed / rig.name),
                                     "--out", str(tmp_path / "q.png")])
    assert "is not the system" in err and "content differs" in err
    assert not (tmp_path / "q.png").exists()
    # So is another catalogue system.
    err = _one_line_refusal(capsys, ["animate", str(run), "--system", "furuta",
                                     "--out", str(tmp_path / "a.gif")])
    assert "is not the system" in err


def test_a_file_the_user_ran_in_this_process_is_used_as_run(tmp_path: Path) -> None:
    from equilibrist.viz.runs import as_run

    marker = tmp_path / "marker"
    rig = _evil(tmp_path, marker, body=EXAMPLE.read_text())
    mine = get_system(str(rig))
    assert marker.exists()
    marker.unlink()
    result = _run(mine.key, digest=mine.digest, params=dict(mine.params))
    assert as_run(result).system.digest == mine.digest
    # The file changed on disk since: the data's digest no longer matches what was run,
    # and the new content is not run either.
    rig.write_text(rig.read_text() + "\n# changed\n")
    assert as_run(result).system.digest == mine.digest
    other = _run(mine.key, digest="0" * 64, params=dict(mine.params))
    with pytest.raises(CodeInDataError):
        as_run(other)
    assert not marker.exists()
