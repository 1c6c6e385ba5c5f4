"""The documentation site builds from a fresh clone with MkDocs, warnings as errors, and holds
what a newcomer is sent to: the tutorials, the guides and the API reference from the
docstrings."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_the_site_builds_strictly_with_the_tutorials_and_the_reference(tmp_path: Path) -> None:
    site = tmp_path / "site"
    mkdocs = Path(sys.executable).with_name("mkdocs")
    done = subprocess.run(
        [str(mkdocs), "build", "--strict", "--site-dir", str(site)],
        cwd=ROOT, capture_output=True, text=True, check=False,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    assert done.returncode == 0, done.stderr[-3000:]
    # The reference is made from the docstrings: the design's own words are on its page.
    design_page = (site / "api" / "design" / "index.html").read_text()
    assert "Design LQR, Kalman filter and reference gain" in design_page
    interop_page = (site / "api" / "interop" / "index.html").read_text()
    assert "closed_compensator" in interop_page and "loop_at_input" in interop_page
    # The docstrings' Sphinx roles read as code (docs/hooks.py), not as ":func:".
    assert ":func:<code>" not in interop_page and ":class:<code>" not in design_page
    # Each tutorial is a page with its code.
    for notebook in sorted((ROOT / "docs" / "tutorials").glob("*.ipynb")):
        page = (site / "tutorials" / notebook.stem / "index.html").read_text()
        assert "Running this notebook" in page and "get_system" in page
    # The README's link to the site's first page and the home page's links resolve.
    home = (site / "index.html").read_text()
    for href in re.findall(r'href="([^"#:]+/)"', home):
        assert (site / href / "index.html").exists() or (site / href).exists(), href


def test_the_readme_names_the_command_that_builds_the_site() -> None:
    assert "make docs" in (ROOT / "README.md").read_text()
    assert "docs:" in (ROOT / "Makefile").read_text()


def test_the_readmes_python_example_runs_as_pasted(tmp_path: Path) -> None:
    """Ten lines that design, simulate, plot and export: the files they promise are written,
    and the picture is a PNG."""
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    assert len(blocks) == 1
    assert len([line for line in blocks[0].splitlines() if line.strip()]) <= 11
    done = subprocess.run([sys.executable, "-c", blocks[0]], cwd=tmp_path, capture_output=True,
                          text=True, check=False, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert (tmp_path / "response.png").read_bytes().startswith(b"\x89PNG\r\n\x1a\n")
    exported = {p.suffix for p in (tmp_path / "cartpole_lqg").iterdir()}
    assert {".c", ".h"} <= exported
