"""The export folder: Makefile, test program, desktop example, and all-or-nothing writing.

Each export here ships vectors recorded from the numpy transcription of the
controller on synthetic measurements (the simulation's closed-loop vectors
are covered by test_export_sim.py), so these tests exercise the files.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from equilibrist.control.design import design
from equilibrist.errors import ExportError
from equilibrist.export.data import controller_data
from equilibrist.export.vectors import make_vectors
from equilibrist.export.writer import export_c
from equilibrist.numeric.lookup import get_system
from support import require
from support.export import measurements, reference_run


@pytest.fixture(autouse=True)
def _make() -> None:
    """Every test here builds with make: without it they fail (CI has it)."""
    require("make")


def _reference(data, ys, rs):
    return reference_run(data, ys, rs)[0]


def _vectors(d, controller: str, precision: str, *, n_steps: int = 300, spoil: float = 0.0):
    data = controller_data(d, controller=controller)
    ys, rs = measurements(data, n_steps, seed=5)
    us = _reference(data, ys, rs)
    vec = make_vectors(data, ys, rs, us, data.x0, precision=precision)
    if spoil:
        u = vec.u.copy()
        u[n_steps // 2] += spoil * vec.tolerance
        vec = make_vectors(data, ys, rs, u, data.x0, precision=precision)
    return vec


@pytest.fixture(scope="module")
def wheel_design():
    return design(get_system("reaction_wheel_pendulum"), rate=100)


@pytest.fixture(scope="module")
def built(tmp_path_factory, wheel_design):
    """One export per precision, built with make."""
    out = {}
    for precision in ("double", "float"):
        folder = tmp_path_factory.mktemp(f"export_{precision}") / "out"
        done = export_c(wheel_design, folder, precision=precision,
                        vectors=_vectors(wheel_design, "lqg", precision))
        proc = subprocess.run(["make", "-C", str(folder)], capture_output=True, text=True,
                              check=False)
        assert proc.returncode == 0, proc.stdout + proc.stderr
        out[precision] = done
    return out


@pytest.mark.parametrize("precision", ["double", "float"])
def test_make_check_passes(built, precision) -> None:
    done = built[precision]
    proc = subprocess.run(["make", "-C", str(done.folder), "check"], capture_output=True,
                          text=True, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "300 steps match" in proc.stdout
    assert done.data.fingerprint in proc.stdout
    for rel in done.files:
        assert (done.folder / rel).is_file(), rel
    assert not [p for p in done.folder.iterdir() if p.name.startswith(".equilibrist-export")]


def test_make_check_fails_on_a_wrong_vector(tmp_path, wheel_design) -> None:
    folder = tmp_path / "bad"
    export_c(wheel_design, folder, vectors=_vectors(wheel_design, "lqg", "double", spoil=3.0))
    proc = subprocess.run(["make", "-C", str(folder), "check"], capture_output=True, text=True,
                          check=False)
    assert proc.returncode != 0
    assert "FAIL: 1 of 300" in proc.stdout


def test_make_check_fails_on_another_controller(tmp_path, wheel_design) -> None:
    """Vectors of the predictor form do not pass the current form's code."""
    other = design(get_system("reaction_wheel_pendulum"), rate=100, kalman_form="predictor")
    folder = tmp_path / "other"
    export_c(wheel_design, folder, vectors=_vectors(other, "lqg", "double"))
    proc = subprocess.run(["make", "-C", str(folder), "check"], capture_output=True, text=True,
                          check=False)
    assert proc.returncode != 0


def test_lqr_export_builds_and_checks(tmp_path) -> None:
    d = design(get_system("cartpole"), rate=100)
    folder = tmp_path / "lqr"
    export_c(d, folder, controller="lqr", precision="float", vectors=_vectors(d, "lqr", "float"))
    proc = subprocess.run(["make", "-C", str(folder), "check"], capture_output=True, text=True,
                          check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def _run_example(folder: Path, *args: str, stdin: str | None = None) -> np.ndarray:
    proc = subprocess.run([str(folder / "example_desktop"), *args], input=stdin,
                          capture_output=True, text=True, check=True)
    rows = [line.split() for line in proc.stdout.splitlines() if not line.startswith("#")]
    return np.array(rows, dtype=float)


@pytest.mark.parametrize("precision", ["double", "float"])
def test_desktop_example_balances_the_linear_model(built, precision) -> None:
    data = built[precision].data
    rows = _run_example(built[precision].folder)
    p = data.n_measured
    t, y, u = rows[:, 0], rows[:, 1:1 + p], rows[:, 1 + p:]
    assert t[1] - t[0] == pytest.approx(data.dt)
    assert abs(y[0, 0] - data.y0[0]) == pytest.approx(0.05, rel=1e-6)  # the offset it starts from
    assert np.max(np.abs(y[-1] - data.y0)) < 0.05 * 0.05  # and returns
    assert np.ptp(u) > 0 and np.all(u >= data.u_min) and np.all(u <= data.u_max)


def test_desktop_example_reads_measurements_from_stdin(built, wheel_design) -> None:
    data = built["double"].data
    ys, _ = measurements(data, 50, seed=9)
    text = "\n".join(" ".join(repr(float(v)) for v in row) for row in ys) + "\n"
    got = _run_example(built["double"].folder, "-", stdin=text)
    expected = _reference(data, ys, np.tile(data.r0, (len(ys), 1)))
    assert got.shape == expected.shape
    assert np.allclose(got, expected, rtol=1e-8, atol=1e-12)
    proc = subprocess.run([str(built["double"].folder / "example_desktop"), "-"],
                          input="0.1 zero\n", capture_output=True, text=True, check=False)
    assert proc.returncode == 1 and "numbers per line" in proc.stderr


# -- all or nothing ---------------------------------------------------------------------
def test_an_unwritable_folder_is_refused_and_nothing_written(tmp_path, wheel_design) -> None:
    if os.geteuid() == 0:
        locked = tmp_path / "a_file"
        locked.write_text("not a folder")
        target = locked / "out"  # a path through a file: never writable, even for root
    else:
        locked = tmp_path / "locked"
        locked.mkdir()
        locked.chmod(0o500)
        target = locked / "out"
    vec = _vectors(wheel_design, "lqg", "double", n_steps=10)
    with pytest.raises(ExportError, match="folder"):
        export_c(wheel_design, target, vectors=vec)
    assert not target.exists()


def test_an_existing_folder_keeps_other_files(tmp_path, wheel_design) -> None:
    folder = tmp_path / "mine"
    folder.mkdir()
    (folder / "notes.txt").write_text("keep me")
    vec = _vectors(wheel_design, "lqg", "double", n_steps=10)
    with pytest.raises(ExportError, match="--force"):
        export_c(wheel_design, folder, vectors=vec)
    assert sorted(p.name for p in folder.iterdir()) == ["notes.txt"]
    done = export_c(wheel_design, folder, vectors=vec, force=True)
    assert (folder / "notes.txt").read_text() == "keep me"
    assert done.header.is_file() and done.source.is_file()
    assert sorted(p.name for p in folder.iterdir() if p.name.startswith(".")) == [".made-by-equilibrist"]


def test_bad_options_write_nothing(tmp_path, wheel_design) -> None:
    vec = _vectors(wheel_design, "lqg", "double", n_steps=10)
    for kwargs, match in (
        ({"precision": "half"}, "precision 'half'"),
        ({"controller": "pid"}, "controller 'pid'"),
    ):
        with pytest.raises(ExportError, match=match):
            export_c(wheel_design, tmp_path / "x", vectors=vec, **kwargs)
    with pytest.raises(ExportError, match="sample rate"):
        export_c(design(get_system("cartpole")), tmp_path / "x", vectors=vec)
    assert not (tmp_path / "x").exists()
