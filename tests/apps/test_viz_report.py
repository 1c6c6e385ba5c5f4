"""The report page and the --plot/--animate options of commands that simulate."""

from __future__ import annotations

import argparse
from html.parser import HTMLParser

import numpy as np
import pytest
from PIL import Image

from equilibrist.numeric.lookup import get_system
from equilibrist.viz import cli_hooks, output
from equilibrist.viz.report import Image as ReportImage
from equilibrist.viz.report import Section, write_index
from equilibrist.viz.runs import Run


class _Collect(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict[str, str | None]]] = []

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))


def test_index_links_every_image_and_works_offline(tmp_path):
    sections = [
        Section(anchor="cartpole", title="Cart <pole>", subtitle="cartpole",
                story=["It stayed up & recovered."],
                images=[ReportImage("cartpole/run.gif", "animation"), ReportImage("cartpole/r.png", "plot")],
                facts=[("peak force", "12 N")], equations="M q'' = F", equations_latex=r"\ddot{x}"),
        Section(anchor="seesaw", title="Seesaw", notes=["the motor saturated"]),
    ]
    page = write_index(tmp_path, title="Tour", intro=["How to read this page."],
                       summary_header=["system", "stayed up", "peak input"],
                       summary_rows=[["cartpole", "yes", "12 N"], ["seesaw", "no", "4 N"]],
                       sections=sections, footer="made by a test")
    text = page.read_text()
    parser = _Collect()
    parser.feed(text)
    srcs = [a["src"] for t, a in parser.tags if t == "img"]
    assert srcs == ["cartpole/run.gif", "cartpole/r.png"]
    hrefs = [a["href"] for t, a in parser.tags if t == "a"]
    assert "#cartpole" in hrefs and "#seesaw" in hrefs
    assert "http://" not in text and "https://" not in text  # nothing fetched from the web
    assert "Cart &lt;pole&gt;" in text and "stayed up &amp; recovered" in text
    assert '<td class="ok">yes</td>' in text and '<td class="bad">no</td>' in text
    assert "\\ddot{x}" in text and "the motor saturated" in text


def _parser() -> argparse.ArgumentParser:
    class Strict(argparse.ArgumentParser):
        def error(self, message):
            raise ValueError(message)

    p = Strict()
    cli_hooks.add_output_options(p)
    return p


def test_output_options_refuse_bad_files_before_anything_runs(monkeypatch):
    p = _parser()
    args = p.parse_args(["--plot", "a.svg", "--animate", "a.gif", "--size", "160x120"])
    assert args.size == (160, 120)
    with pytest.raises(ValueError, match="unsupported format"):
        p.parse_args(["--plot", "a.jpg"])
    with pytest.raises(ValueError, match="WIDTHxHEIGHT"):
        p.parse_args(["--size", "big"])
    monkeypatch.setattr(output.shutil, "which", lambda name: None)
    monkeypatch.setattr(output, "bundled_ffmpeg", lambda: None)
    with pytest.raises(ValueError, match="MP4 needs ffmpeg"):
        p.parse_args(["--animate", "a.mp4"])


def test_handle_outputs_writes_the_plot_and_the_animation(tmp_path, capsys):
    system = get_system("cartpole")
    t = np.linspace(0, 1, 21)
    x = np.zeros((21, 4))
    x[:, 1] = 0.1 * t
    run = Run.from_arrays(system, t, x, u=np.zeros((21, 1)))
    args = _parser().parse_args(["--plot", str(tmp_path / "p.png"), "--animate", str(tmp_path / "a.gif"),
                                 "--size", "96x72", "--fps", "5"])
    written = cli_hooks.handle_outputs(args, run)
    assert [p.name for p in written] == ["p.png", "a.gif"]
    with Image.open(tmp_path / "a.gif") as im:
        assert im.size == (96, 72) and im.n_frames == 6
    assert "wrote" in capsys.readouterr().err
    assert cli_hooks.handle_outputs(_parser().parse_args([]), run) == []
