"""The specification ships with the project: docs/systems/ is generated from each definition and current."""

from __future__ import annotations

from pathlib import Path

import pytest

from equilibrist import pages
from equilibrist.cli.main import main
from equilibrist.systems import registry

DOCS = Path(__file__).resolve().parent.parent / "docs" / "systems"


def test_docs_systems_is_what_the_definitions_generate() -> None:
    expected = pages.pages()
    found = {p.name: p.read_text() for p in DOCS.glob("*.md")}
    stale = sorted(n for n in expected if found.get(n) != expected[n])
    extra = sorted(set(found) - set(expected))
    assert not stale and not extra, (
        f"docs/systems is out of date (pages {stale}, no longer generated {extra}): run "
        "'equilibrist systems --markdown --out docs/systems'")


def test_every_catalogue_system_has_a_page_with_its_facts() -> None:
    texts = pages.pages()
    for name in registry.family_names():
        variants = registry.variants(name) if registry.variant_option(name) else (None,)
        for v in variants:
            spec = registry.lookup(name, v).spec
            text = texts[pages.page_name(spec)]
            assert f"`{spec.key}`" in texts[pages.INDEX]
            for p in spec.parameters:
                assert f"| `{p.name}` | {p.default:g} | {p.unit or '-'} | {p.range_text} |" in text
            for i in spec.inputs:
                assert f"| `{i.name}` | {i.unit} |" in text
            for s in spec.state_names:
                assert f"| `{s}` |" in text


def test_the_command_line_prints_and_writes_the_pages(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["systems", "--markdown"]) == 0
    printed = capsys.readouterr().out
    assert printed.startswith(pages.pages()[pages.INDEX])
    assert "# Inverted pendulum on a cart (`cartpole`)" in printed
    assert main(["systems", "--markdown", "--out", str(tmp_path / "pages")]) == 0
    assert (tmp_path / "pages" / "cartpole.md").read_text() == pages.pages()["cartpole.md"]
    capsys.readouterr()
    for argv in (["systems", "--out", str(tmp_path)], ["systems", "--markdown", "--json"]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "Traceback" not in err
