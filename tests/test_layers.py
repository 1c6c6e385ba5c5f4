"""The import graph agrees with docs/architecture.md.

The layers themselves are import-linter's contract in pyproject.toml (``make test`` runs
``lint-imports``; the first test here runs the same contract in the suite). The graph is
grimp's, import-linter's engine: every import that runs, those inside functions included,
and none under ``TYPE_CHECKING``. Within a package, modules may import each other in a
cycle of at most three files (a translator and its two halves, say); a longer cycle is a
knot to untie. And no function is longer than :data:`MAX_FUNCTION_LINES` lines.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import grimp
import pytest

import equilibrist

ROOT = Path(equilibrist.__file__).parent
PYPROJECT = Path(__file__).resolve().parent.parent / "pyproject.toml"
MAX_CYCLE = 3
#: The longest a function may be, from its ``def`` line to its last line (its docstring
#: counted, its decorators not).
MAX_FUNCTION_LINES = 120


@pytest.fixture(scope="module")
def graph() -> grimp.ImportGraph:
    return grimp.build_graph("equilibrist", cache_dir=None, exclude_type_checking_imports=True)


def test_the_layer_contract_is_kept() -> None:
    from importlinter.cli import lint_imports

    assert lint_imports(config_filename=str(PYPROJECT), no_cache=True) == 0


def test_the_contract_names_every_package(graph: grimp.ImportGraph) -> None:
    """A new package must take its place in the layers (import-linter ignores the rest)."""
    import tomllib

    layers = tomllib.loads(PYPROJECT.read_text())["tool"]["importlinter"]["contracts"][0]["layers"]
    named = {name.strip() for line in layers for name in line.split("|")}
    top = set(graph.find_children("equilibrist"))
    assert top - named == set()


def _strongly_connected(graph: grimp.ImportGraph) -> list[list[str]]:
    """Tarjan's components of the module graph with more than one module."""
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.find_modules_directly_imported_by(v):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for module in sorted(graph.modules):
        if module not in index:
            visit(module)
    return found


def test_no_import_cycle_is_longer_than_three_files(graph: grimp.ImportGraph) -> None:
    long = [c for c in _strongly_connected(graph) if len(c) > MAX_CYCLE]
    assert not long, "import cycles of more than three files:\n" + "\n".join(map(str, long))


def test_the_cycle_finder_finds_a_planted_cycle() -> None:
    """The check above can fail: four modules importing each other in a ring are found."""
    graph = grimp.build_graph("equilibrist", cache_dir=None, exclude_type_checking_imports=True)
    ring = [f"equilibrist.planted_{k}" for k in range(4)]
    for module in ring:
        graph.add_module(module)
    for a, b in zip(ring, ring[1:] + ring[:1], strict=True):
        graph.add_import(importer=a, imported=b)
    assert sorted(ring) in _strongly_connected(graph)


def test_the_demos_are_applications() -> None:
    for name in ("tour", "mpc_demo", "swingup_demo", "planned_demo"):
        assert (ROOT / "apps" / f"{name}.py").exists()
        assert not (ROOT / "viz" / f"{name}.py").exists()


def _long_functions(limit: int) -> list[tuple[str, str, int, int]]:
    """``(file, name, line, lines)`` of every function (methods and nested functions
    included) of the package longer than *limit* lines."""
    found = []
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                assert node.end_lineno is not None
                lines = node.end_lineno - node.lineno + 1
                if lines > limit:
                    found.append((rel, node.name, node.lineno, lines))
    return found


def test_no_function_is_longer_than_the_limit() -> None:
    """A function longer than :data:`MAX_FUNCTION_LINES` is split into functions named for
    what each handles."""
    long = _long_functions(MAX_FUNCTION_LINES)
    assert not long, f"functions longer than {MAX_FUNCTION_LINES} lines:\n" + "\n".join(
        f"  {file}:{line} {name} ({lines} lines)" for file, name, line, lines in long)


def test_the_length_check_finds_a_long_function() -> None:
    """The check above can fail: it sees functions, methods and nested functions alike."""
    every = {(file, name) for file, name, _, _ in _long_functions(0)}
    assert ("control/design.py", "design") in every  # a function
    assert ("control/lyapunov_rate.py", "vdot_box") in every  # a method (of LyapunovRate)
    assert ("study/plot.py", "cell") in every  # a function inside plot_study
