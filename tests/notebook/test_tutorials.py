"""The tutorials run top to bottom in a real Jupyter kernel (nbclient), as a student runs
them, and are kept in git without their outputs.

A cell that raises fails its notebook's test; so does anything a cell writes to stderr
(a warning such as tqdm's "IProgress not found" among them).
"""

from __future__ import annotations

from pathlib import Path

import pytest

TUTORIALS = Path(__file__).resolve().parents[2] / "docs" / "tutorials"
NOTEBOOKS = sorted(TUTORIALS.glob("*.ipynb"))


def test_there_are_four_to_six_tutorials_numbered_in_order() -> None:
    assert 4 <= len(NOTEBOOKS) <= 6
    assert [p.name[:3] for p in NOTEBOOKS] == [f"{i:02d}-" for i in range(1, len(NOTEBOOKS) + 1)]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_tutorial_is_stored_without_outputs(path: Path) -> None:
    import nbformat  # here, not at collection: its schema check's imports cost seconds of CPU

    notebook = nbformat.read(path, as_version=4)
    nbformat.validate(notebook)
    for cell in notebook.cells:
        if cell.cell_type == "code":
            assert cell.outputs == [], f"{path.name}: a cell keeps its outputs"
            assert cell.execution_count is None, f"{path.name}: a cell keeps its count"
    # The first thing a student reads says how to start Jupyter from the project's .venv.
    assert ".venv/bin/jupyter lab" in notebook.cells[0].source


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_tutorial_runs_top_to_bottom(path: Path, tmp_path: Path) -> None:
    import nbformat
    from nbclient import NotebookClient

    notebook = nbformat.read(path, as_version=4)
    # A cell's own bound (the longest takes seconds); ipykernel 7 could leave a started
    # kernel silent for good, which is why the notebook extra keeps ipykernel below 7.
    client = NotebookClient(notebook, timeout=300, kernel_name="python3",
                            resources={"metadata": {"path": str(tmp_path)}})
    client.execute()  # raises CellExecutionError naming the cell that failed
    for cell in notebook.cells:
        if cell.cell_type != "code":
            continue
        errors = [o.get("text", "") for o in cell.outputs
                  if o.output_type == "stream" and o.name == "stderr"]
        assert errors == [], f"{path.name}: {cell.source[:60]!r} wrote to stderr: {errors}"
        # A value shows itself (a picture, a table, a video), once: never as its bare text.
        pictures = [o for o in cell.outputs if "image/png" in o.get("data", {})]
        assert len(pictures) <= 1, f"{path.name}: {cell.source[:60]!r} shows a picture twice"
        for output in cell.outputs:
            plain = output.get("data", {}).get("text/plain", "")
            assert not plain.startswith("<Figure size"), f"{path.name}: a figure shown as text"
            assert " object at 0x" not in plain, f"{path.name}: {plain[:80]}"
    rich = [o for c in notebook.cells if c.cell_type == "code" for o in c.outputs
            if {"text/html", "image/png"} & set(o.get("data", {}))]
    assert rich, f"{path.name}: nothing shown but text"
