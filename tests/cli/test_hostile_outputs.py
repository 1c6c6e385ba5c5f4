"""Outputs that are not lost or left behind: a report folder is replaced only when nothing in
it would be lost, files and folders take the modes the umask gives, errors name the path the
user gave, and no missing folder is created."""

from __future__ import annotations

import os
import re
import stat
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from equilibrist.cli.main import main

#: The folders of a full tour's report (one per catalogue system, and the study) as the demo
#: writes them, beside index.html.
FULL_TOUR = ("seesaw", "cartpole", "double_cartpole", "wheeled_pendulum",
             "reaction_wheel_pendulum", "furuta", "ball_beam", "ball_beam_servo",
             "gyroscope_euler_zxz", "cmg_robot", "acrobot", "pendubot", "study")


def _mode(path: Path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def _snapshot(folder: Path) -> dict[str, tuple[int, bytes]]:
    """Every entry under *folder* (hidden ones too) with its mode and content."""
    out = {}
    for path in sorted(folder.rglob("*")):
        rel = path.relative_to(folder).as_posix()
        out[rel] = (path.stat().st_mode, b"" if path.is_dir() else path.read_bytes())
    return out


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


@pytest.fixture(params=[(0o022, 0o644, 0o755), (0o077, 0o600, 0o700)],
                ids=["umask022", "umask077"])
def umask(request: pytest.FixtureRequest) -> Iterator[tuple[int, int]]:
    """The process's umask set for the test (restored after): the modes a new file and a
    new folder must get under it."""
    mask, file_mode, folder_mode = request.param
    before = os.umask(mask)
    try:
        yield file_mode, folder_mode
    finally:
        os.umask(before)


# -- finding: a demo of one system replaced the full tour's report ---------------------


def _full_tour(folder: Path, marker: str) -> None:
    """*folder* laid out as the full tour's report, with the demo's marker file."""
    folder.mkdir()
    for name in FULL_TOUR:
        (folder / name).mkdir()
        (folder / name / "response.png").write_bytes(b"png of " + name.encode())
    (folder / "index.html").write_text("<p>Made by 'equilibrist demo'</p>\n")
    (folder / ".equilibrist-report").write_text(marker)


@pytest.mark.parametrize("marker", ["written by equilibrist demo\n", "manifest"])
def test_a_demo_of_one_system_does_not_replace_the_full_tour(tmp_path, capsys, marker) -> None:
    report = tmp_path / "report"
    if marker == "manifest":  # the manifest this version writes, listing every file
        from equilibrist.apps.tour import write_manifest

        _full_tour(report, "")
        write_manifest(report)
    else:  # the marker an earlier version wrote
        _full_tour(report, marker)
    before = _snapshot(report)
    assert main(["demo", "cartpole", "--out", str(report), "--jobs", "1"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "--force" in line and str(report) in line
    assert "acrobot" in line  # what would be lost is named
    assert _snapshot(report) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report"]  # no staging left


def test_the_report_guard_lets_a_same_report_be_replaced_and_force_any(tmp_path) -> None:
    from equilibrist.apps.tour import check_report_folder, write_manifest
    from equilibrist.viz.output import VizError

    report = tmp_path / "report"
    _full_tour(report, "")
    write_manifest(report)
    everything = {"index.html", *FULL_TOUR}
    check_report_folder(report, writes=everything)  # the same tour again: nothing lost
    with pytest.raises(VizError, match="acrobot"):
        check_report_folder(report, writes={"index.html", "cartpole", "study"})
    check_report_folder(report, writes={"index.html", "cartpole"}, force=True)
    (report / "cartpole" / "notes.txt").write_text("mine\n")  # the user's, in a report
    with pytest.raises(VizError, match=r"cartpole/notes\.txt"):
        check_report_folder(report, writes=everything)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("\\section{}\n")  # no marker: not equilibrist's
    with pytest.raises(VizError, match=r"thesis\.tex.*--force"):
        check_report_folder(mine, writes=everything)
    check_report_folder(mine, writes=everything, force=True)


def test_a_report_is_staged_with_a_manifest_and_the_umask_modes(tmp_path, monkeypatch,
                                                                 umask) -> None:
    from equilibrist.apps import tour
    from equilibrist.numeric.lookup import get_system

    file_mode, folder_mode = umask

    def tour_into(systems, folder, **_options):  # the tour's simulations left out
        (folder / "seesaw").mkdir()
        (folder / "seesaw" / "run.npz").write_bytes(b"run")
        (folder / "index.html").write_text("<p>report</p>\n")
        return []

    monkeypatch.setattr(tour, "_tour_into", tour_into)
    report = tmp_path / "report"
    tour.run_tour([get_system("seesaw")], report)
    assert _mode(report) == folder_mode
    assert _mode(report / "seesaw") == folder_mode
    assert _mode(report / "index.html") == file_mode
    assert _mode(report / ".equilibrist-report") == file_mode
    assert "seesaw/run.npz" in (report / ".equilibrist-report").read_text()
    tour.run_tour([get_system("seesaw")], report)  # its own report again: replaced
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report"]


def test_the_pages_replace_no_file_equilibrist_did_not_generate(tmp_path, capsys) -> None:
    folder = tmp_path / "notes"
    folder.mkdir()
    (folder / "README.md").write_text("# My notes\n")
    assert main(["systems", "--markdown", "--out", str(folder)]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "README.md" in line and "--force" in line
    assert (folder / "README.md").read_text() == "# My notes\n"
    assert list(folder.iterdir()) == [folder / "README.md"]
    assert main(["systems", "--markdown", "--out", str(folder), "--force"]) == 0
    assert (folder / "README.md").read_text().startswith("<!-- Generated")
    assert main(["systems", "--markdown", "--out", str(folder)]) == 0  # its own pages again


# -- finding: every file 0600 and every folder 0700 -------------------------------------


def test_atomic_writes_take_the_umask_mode(tmp_path, umask) -> None:
    from equilibrist.atomic import write_text
    from equilibrist.ident.params import write_params

    file_mode, _ = umask
    assert _mode(write_text(tmp_path / "a.txt", "a\n")) == file_mode
    old = tmp_path / "b.txt"
    old.write_text("old\n")
    old.chmod(0o600)
    assert _mode(write_text(old, "new\n")) == file_mode  # a new file: the umask's mode too
    assert _mode(write_params({"params": {"m_p": 0.2}}, tmp_path / "p.json")) == file_mode


def test_a_run_and_its_plot_take_the_umask_mode(tmp_path, capsys, umask) -> None:
    file_mode, _ = umask
    run, plot = tmp_path / "run.npz", tmp_path / "run.png"
    assert main(["simulate", "cartpole", "--duration", "0.2", "--out", str(run),
                 "--plot", str(plot)]) == 0
    assert _mode(run) == file_mode and _mode(plot) == file_mode


def test_a_study_table_takes_the_umask_mode(tmp_path, umask) -> None:
    pytest.importorskip("pyarrow")
    from equilibrist.study.spec import make_study
    from equilibrist.study.store import _atomic_parquet, rows_to_table, schema

    file_mode, _ = umask
    study = make_study("cartpole", vary=[("m_p", "0.1:0.2:2")], runs=1, duration=0.1)
    out = tmp_path / "s.parquet"
    _atomic_parquet(rows_to_table([], schema(study)), out)
    assert _mode(out) == file_mode


# -- finding: an error named the temporary file ------------------------------------------


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc takes no new files")
def test_an_error_names_the_file_the_user_gave(capsys) -> None:
    from equilibrist.atomic import write_bytes

    with pytest.raises(OSError) as raised:
        write_bytes("/proc/version.npz", b"x")
    assert raised.value.filename == "/proc/version.npz"
    assert main(["simulate", "cartpole", "--duration", "0.2", "--out", "/proc/version.npz"]) == 2
    line = _one_line(capsys.readouterr().err)
    assert "/proc/version.npz" in line and ".version.npz." not in line


# -- finding: missing folders were created -----------------------------------------------


@pytest.mark.parametrize("argv", [
    ["simulate", "cartpole", "--duration", "0.2", "--out", "{nope}/run.npz"],
    ["simulate", "cartpole", "--duration", "0.2", "--plot", "{nope}/run.png"],
    ["simulate", "cartpole", "--duration", "0.2", "--animate", "{nope}/run.gif"],
    ["demo", "cartpole", "--out", "{nope}/report"],
    ["systems", "--markdown", "--out", "{nope}/pages"],
    ["export", "cartpole", "--out", "{nope}/ctl"],
], ids=["simulate-out", "simulate-plot", "simulate-animate", "demo", "systems", "export"])
def test_no_missing_folder_is_created(tmp_path, capsys, argv) -> None:
    nope = tmp_path / "nope"
    assert main([a.format(nope=nope) for a in argv]) == 2
    line = _one_line(capsys.readouterr().err)
    assert str(nope) in line and "does not exist" in line
    assert not nope.exists()
    assert list(tmp_path.iterdir()) == []


def test_the_writer_creates_no_missing_folder(tmp_path) -> None:
    from equilibrist.atomic import OutputError, write_text

    with pytest.raises(OutputError, match=re.escape(f"the folder {tmp_path / 'a' / 'b'} does not exist")):
        write_text(tmp_path / "a" / "b" / "c.txt", "c\n")
    assert list(tmp_path.iterdir()) == []
    assert write_text(tmp_path / "c.txt", "c\n").read_text() == "c\n"  # an existing folder


# -- finding: the progress line's time read as simulated time ----------------------------


def test_the_progress_line_names_simulated_and_wall_time() -> None:
    from equilibrist.apps.tour_common import Outcome
    from equilibrist.viz.report import Section

    done = Outcome(key="cartpole", row=(), section=Section("cartpole", "Cart-pole"),
                   stayed_up=True, seconds=87.0, simulated=10.0)
    line = done.progress_line()
    assert "10 s simulated" in line and "87.0 s of wall time" in line
    fell = Outcome(key="acrobot", row=(), section=Section("acrobot", "Acrobot"),
                   stayed_up=False, seconds=3.25, simulated=8.0)
    assert "FELL" in fell.progress_line() and "8 s simulated" in fell.progress_line()
