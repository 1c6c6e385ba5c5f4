"""``equilibrist export``: bad input ends with one clear line and exit status 2, writing nothing."""

from __future__ import annotations

import pytest

from equilibrist.cli.main import main


def _fails(capsys, *argv: str) -> str:
    assert main(list(argv)) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert "Traceback" not in captured.err and captured.out == ""
    return lines[0]


def test_unwritable_output_folder(capsys, tmp_path) -> None:
    blocker = tmp_path / "a_file"
    blocker.write_text("a file, not a folder")
    line = _fails(capsys, "export", "cartpole", "--out", str(blocker / "out"))
    assert "folder" in line and str(blocker) in line
    line = _fails(capsys, "export", "cartpole", "--out", str(blocker))
    assert "is not a folder" in line
    assert blocker.read_text() == "a file, not a folder"


@pytest.mark.parametrize("rate", ["0", "-100", "nan", "inf", "fast"])
def test_rate_that_is_not_positive(capsys, tmp_path, rate) -> None:
    out = tmp_path / "out"
    line = _fails(capsys, "export", "cartpole", "--rate", rate, "--out", str(out))
    assert "rate" in line
    assert not out.exists()


def test_system_without_input(capsys, tmp_path) -> None:
    out = tmp_path / "out"
    line = _fails(capsys, "export", "gyroscope", "--out", str(out))
    assert "has no input" in line
    assert not out.exists()


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["--controller", "pid"], "invalid choice"),
        (["--precision", "half"], "invalid choice"),
        (["--q", "1,2"], "q"),
        (["--set", "m_c=-1"], "m_c"),
        (["--duration", "0"], "duration"),
    ],
)
def test_other_bad_options(capsys, tmp_path, argv, expected) -> None:
    out = tmp_path / "out"
    line = _fails(capsys, "export", "cartpole", "--out", str(out), *argv)
    assert expected in line
    assert not out.exists()


def test_unknown_system(capsys, tmp_path) -> None:
    line = _fails(capsys, "export", "cartpol", "--out", str(tmp_path / "out"))
    assert "cartpole" in line
