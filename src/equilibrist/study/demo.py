"""The demo's small study: the cart-pole's pole mass against the sample rate.

Added to a finished demo report (``equilibrist demo``): a 5 x 5 grid of
``m_p`` and ``rate``, 40 noisy LQG runs per point from initial angles within
+-0.5 rad, written as ``study/study.parquet`` with its heat maps, and a
section of ``index.html`` that says how to run it yourself.
"""

from __future__ import annotations

import re
import tempfile
from collections.abc import Callable
from pathlib import Path

from equilibrist.study.plot import plot_study
from equilibrist.study.runner import run_study
from equilibrist.study.spec import make_study

COMMAND = ("equilibrist sweep cartpole --vary m_p=0.05:0.8:5 --vary rate=4:64:5:log "
           "--runs 40 --duration 3 --x0 theta=-0.5:0.5 --out study.parquet")


def add_study_to_report(folder: str | Path, *, log: Callable[[str], None] | None = None) -> Path:
    """Run the demo's study into *folder*/study and add its section to the report's index."""
    from equilibrist.atomic import write_text
    from equilibrist.study.store import read_study
    from equilibrist.viz.report import Image, Section, write_index

    folder = Path(folder)
    sub = folder / "study"
    sub.mkdir(exist_ok=True)
    study = make_study("cartpole", vary=[("m_p", "0.05:0.8:5"), ("rate", "4:64:5:log")],
                       runs=40, duration=3.0, x0={"theta": "-0.5:0.5"})
    out = sub / "study.parquet"
    done = run_study(study, out)
    table, study = read_study(out)
    plot_study(table, study, sub / "fraction_up.png", metric="fraction_up")
    plot_study(table, study, sub / "settling_p90.png", metric="settling_p90")
    if log is not None:
        log(f"study: {done.points} points x {study.runs} runs ({done.elapsed:.1f} s)")
    section = Section(
        anchor="study", title="A small study",
        subtitle="cartpole: pole mass x sample rate, 40 runs per point",
        story=[
            "How slow may the controller sample, and how heavy may the pole be? For each of "
            "25 pairs of pole mass and sample rate the digital LQG controller was designed "
            "anew and run 40 times from initial angles within 0.5 rad, with noise. The "
            "maps show the share of runs that stayed up and the time by which 90 % of them "
            "had settled (blank: more than a tenth never settled or fell).",
            f"The same study from the command line: {COMMAND}; then 'equilibrist plot "
            "study.parquet --metric settling_p90'. See docs/studies.md for studies on a cluster.",
        ],
        images=[Image("study/fraction_up.png", "Share of runs that stayed up"),
                Image("study/settling_p90.png", "90th percentile of the settling time [s]")],
        facts=[("points", str(done.points)), ("runs", str(done.runs)),
               ("table", "study/study.parquet")],
    )
    with tempfile.TemporaryDirectory() as tmp:
        html = write_index(Path(tmp), title="study", intro=[], summary_header=[],
                           summary_rows=[], sections=[section]).read_text()
    found = re.search(r'<section id="study">.*?</section>', html, flags=re.S)
    index = folder / "index.html"
    page = index.read_text()
    if found is not None:
        at = page.rfind("<hr>")
        at = at if at >= 0 else page.rfind("</body>")
        page = page[:at] + found.group(0) + page[at:]
        write_text(index, page)
    return out
