"""A user's own system: a Python file or a definition handed over in a script.

The truth for the worked example is the catalogue's cart-pole, derived in
another file: with the same parameters both must give the same ``f``.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.cli.main import main
from equilibrist.errors import DefinitionError, EquilibristError, UnknownNameError
from equilibrist.numeric import cache
from equilibrist.numeric.lookup import system_from_key
from equilibrist.numeric.system import System
from equilibrist.systems import files

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "my_cartpole.py"
CATALOGUE_VALUES = {"m_c": 10.0, "m_p": 1.0, "l": 0.5, "I_p": 0.08333, "b_c": 0.3, "b_p": 0.02, "g": 9.8}


def _fails(capsys, *argv: str) -> str:
    assert main(list(argv)) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert "Traceback" not in captured.err
    return lines[0]


def test_user_file_gives_the_catalogue_dynamics() -> None:
    mine = get_system(str(EXAMPLE), **CATALOGUE_VALUES)
    catalogue = get_system("cartpole", **CATALOGUE_VALUES)
    rng = np.random.default_rng(7)
    for _ in range(50):
        x = rng.uniform(-2, 2, 4)
        u = rng.uniform(-50, 50, 1)
        np.testing.assert_allclose(mine.f(x, u), catalogue.f(x, u), rtol=1e-12, atol=1e-12)
    assert mine.key == str(EXAMPLE)
    assert mine.name == "my_cartpole"


def test_file_key_rebuilds_the_system() -> None:
    mine = get_system(str(EXAMPLE), m_p=0.2)
    again = system_from_key(mine.key, mine.params)
    assert again.params["m_p"] == 0.2
    x, u = [0.0, 0.1, 0.0, 0.0], [1.0]
    np.testing.assert_array_equal(again.f(x, u), mine.f(x, u))


def test_cache_is_keyed_by_content_not_place(tmp_path: Path) -> None:
    a = tmp_path / "a" / "rig.py"
    b = tmp_path / "b" / "rig.py"
    for path in (a, b):
        path.parent.mkdir()
        shutil.copy(EXAMPLE, path)
    key_a = cache.model_key(files.from_file(a))
    key_b = cache.model_key(files.from_file(b))
    assert key_a == key_b
    changed = tmp_path / "c.py"
    changed.write_text(EXAMPLE.read_text().replace('"m_c", 2.0', '"m_c", 2.5'))
    assert cache.model_key(files.from_file(changed)) != key_a
    assert get_system(str(changed)).params["m_c"] == 2.5


def _definition() -> tuple[object, object]:
    namespace: dict[str, object] = {}
    exec(compile(EXAMPLE.read_text(), str(EXAMPLE), "exec"), namespace)  # the user's file, as a script
    return namespace["SPEC"], namespace["derive"]


def test_from_definition_in_a_script() -> None:
    spec, derive = _definition()
    spec = dataclasses.replace(spec, name="script_cartpole")
    system = System.from_definition(spec, derive, m_c=10.0, m_p=1.0, l=0.5, I_p=0.08333,
                                    b_c=0.3, b_p=0.02, g=9.8)
    catalogue = get_system("cartpole", **CATALOGUE_VALUES)
    x, u = [0.3, -0.4, 0.1, 0.2], [5.0]
    np.testing.assert_allclose(system.f(x, u), catalogue.f(x, u), rtol=1e-12)
    # Known in this process by its name, so results and designs rebuild it.
    again = system_from_key("script_cartpole", system.params)
    np.testing.assert_array_equal(again.f(x, u), system.f(x, u))


def test_from_definition_refuses_a_catalogue_name_and_bad_values() -> None:
    spec, derive = _definition()
    with pytest.raises(DefinitionError, match="belongs to the catalogue"):
        System.from_definition(dataclasses.replace(spec, name="cartpole"), derive)
    with pytest.raises(DefinitionError, match="SystemSpec"):
        System.from_definition("cartpole", derive)  # type: ignore[arg-type]
    with pytest.raises(DefinitionError, match="function"):
        System.from_definition(dataclasses.replace(spec, name="x_rig"), 3)  # type: ignore[arg-type]


def test_api_names_wrong_types() -> None:
    with pytest.raises(UnknownNameError, match="system"):
        get_system(None)  # type: ignore[arg-type]
    with pytest.raises(EquilibristError, match="m_p"):
        get_system("cartpole", m_p=10**400)
    with pytest.raises(EquilibristError, match="m_p"):
        get_system("cartpole", m_p="heavy")


@pytest.mark.parametrize(
    ("content", "name", "expected"),
    [
        (None, "missing.py", "does not exist"),
        ("x = (", "broken.py", "SyntaxError"),
        ("raise RuntimeError('boom')", "raises.py", "line 1: RuntimeError: boom"),
        ("A = 1", "empty.py", "expected one system"),
        ("<mujoco/>", "model.txt", "expected a .py file"),
    ],
)
def test_bad_system_files_are_one_line(capsys, tmp_path: Path, content, name, expected) -> None:
    path = tmp_path / name
    if content is not None:
        path.write_text(content)
    line = _fails(capsys, "linearize", str(path))
    assert expected in line


def test_two_systems_in_one_file(capsys, tmp_path: Path) -> None:
    text = EXAMPLE.read_text().split("if __name__")[0] + (
        "\nimport dataclasses\n"
        "OTHER = dataclasses.replace(SPEC, name='other')\n\n\n"
        "@register(OTHER)\ndef derive_other(d):\n    return derive(d)\n"
    )
    path = tmp_path / "two.py"
    path.write_text(text)
    line = _fails(capsys, "linearize", str(path))
    assert "expected one system, found 2 systems" in line


def test_user_file_through_design_simulate_export(tmp_path: Path, capsys) -> None:
    assert main(["design", str(EXAMPLE), "--rate", "200", "--json"]) == 0
    design = json.loads(capsys.readouterr().out)
    assert design["system"] == str(EXAMPLE)
    run = tmp_path / "run.npz"
    assert main(["simulate", str(EXAMPLE), "--x0", "theta=0.1", "--push", "2:3",
                 "--duration", "4", "--out", str(run), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["stayed_up"] is True
    assert abs(summary["final_error"]["theta"]) < 0.02
    assert main(["plot", str(run), "--out", str(tmp_path / "run.png")]) == 0
    assert (tmp_path / "run.png").stat().st_size > 1000
    out = tmp_path / "c"
    assert main(["export", str(EXAMPLE), "--rate", "200", "--out", str(out)]) == 0
    capsys.readouterr()
    proc = subprocess.run(["make", "-C", str(out), "check"], capture_output=True, text=True,
                          timeout=300, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr


@pytest.mark.slow
def test_user_file_through_the_demo(tmp_path: Path, capsys) -> None:
    report = tmp_path / "report"
    assert main(["demo", str(EXAMPLE), "--out", str(report), "--jobs", "1"]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("my_cartpole"))
    assert row.rstrip().endswith("yes"), row
    index = (report / "index.html").read_text()
    assert "My cart-pole" in index or "my_cartpole" in index
