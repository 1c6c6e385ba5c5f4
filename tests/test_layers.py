"""The applications sit above the libraries: no library module imports an application.

Applications: the demo's tour and demos (``apps``), the commands (``cli``), the
playground (``web``), studies (``study``), the environments (``envs``). Read from the
sources' import statements (deferred imports inside functions included)."""

from __future__ import annotations

import ast
from pathlib import Path

import equilibrist

APPLICATIONS = ("apps", "cli", "web", "study", "envs")
ROOT = Path(equilibrist.__file__).parent


def _imported(path: Path) -> list[tuple[int, str]]:
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module, *(f"{node.module}.{a.name}" for a in node.names)]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        else:
            continue
        out.extend((node.lineno, n) for n in names)
    return out


def test_no_library_imports_an_application() -> None:
    libraries = [p for p in ROOT.iterdir() if p.is_dir() and (p / "__init__.py").exists()
                 and p.name not in APPLICATIONS]
    assert {"control", "sim", "viz", "native", "export", "systems"} <= {p.name for p in libraries}
    wrong = []
    for package in libraries:
        for path in package.rglob("*.py"):
            for line, name in _imported(path):
                parts = name.split(".")
                if len(parts) > 1 and parts[0] == "equilibrist" and parts[1] in APPLICATIONS:
                    wrong.append(f"{path.relative_to(ROOT)}:{line} imports {name}")
    assert not wrong, "\n".join(wrong)


def test_the_demos_are_applications() -> None:
    for name in ("tour", "mpc_demo", "swingup_demo", "planned_demo"):
        assert (ROOT / "apps" / f"{name}.py").exists()
        assert not (ROOT / "viz" / f"{name}.py").exists()
