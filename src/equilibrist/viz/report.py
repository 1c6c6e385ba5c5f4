"""The report folder's ``index.html``: one self-contained page, no web access.

:func:`write_index` writes a page with a summary table and one section per
system: what the system is, what happened in plain words, its animation and
plots, the facts of the run, and its equations of motion (pretty text, with
the LaTeX source beside it: the page must open offline, so no MathJax).
Images are linked by relative paths inside the folder.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from equilibrist.atomic import write_text


@dataclass(frozen=True)
class Image:
    """An image of the report (relative to the folder) with its caption."""

    path: str
    caption: str
    wide: bool = False


@dataclass(frozen=True)
class Section:
    """One system's part of the report, under the HTML id *anchor*: the *story* in plain
    words, the *facts* (label, value) of the run, the equations of motion as text and as
    LaTeX source, and *notes* on what went wrong or was chosen on the reader's behalf."""

    anchor: str
    title: str
    subtitle: str = ""
    story: Sequence[str] = ()
    images: Sequence[Image] = ()
    facts: Sequence[tuple[str, str]] = ()
    equations: str = ""
    equations_latex: str = ""
    notes: Sequence[str] = field(default=())


_CSS = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; margin: 0 auto;
       max-width: 1100px; padding: 1.5em; color: #222; line-height: 1.45; }
h1 { margin-bottom: 0.2em; }
h2 { border-bottom: 2px solid #3b6fb6; padding-bottom: 0.2em; margin-top: 2.2em; }
.sub { color: #666; margin-top: 0; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.95em; }
th, td { border: 1px solid #ccc; padding: 0.3em 0.6em; text-align: left; }
th { background: #eef3fa; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
.ok { color: #1d7a38; font-weight: bold; }
.bad { color: #c0182b; font-weight: bold; }
.gallery { display: flex; flex-wrap: wrap; gap: 1em; align-items: flex-start; }
figure { margin: 0; }
figure.wide { flex-basis: 100%; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.85em; color: #555; max-width: 520px; }
figure.wide figcaption { max-width: none; }
pre { background: #f6f8fa; padding: 0.8em; overflow-x: auto; font-size: 0.85em; line-height: 1.2; }
details { margin: 0.6em 0; }
summary { cursor: pointer; color: #3b6fb6; }
.notes { background: #fff7e6; border-left: 4px solid #e8871e; padding: 0.4em 0.8em; }
nav a { margin-right: 0.8em; }
"""


def _e(text: str) -> str:
    return html.escape(str(text), quote=True)


def _status_cell(value: str) -> str:
    low = value.lower()
    if low in ("yes", "stayed up", "ok"):
        return f'<td class="ok">{_e(value)}</td>'
    if low in ("no", "fell"):
        return f'<td class="bad">{_e(value)}</td>'
    return f"<td>{_e(value)}</td>"


def _table(header: Sequence[str], rows: Sequence[Sequence[str]], *, link_first: Sequence[str] = ()) -> str:
    out = ["<table>", "<tr>" + "".join(f"<th>{_e(h)}</th>" for h in header) + "</tr>"]
    for k, row in enumerate(rows):
        cells = []
        for j, c in enumerate(row):
            if j == 0 and k < len(link_first) and link_first[k]:
                cells.append(f'<td><a href="#{_e(link_first[k])}">{_e(c)}</a></td>')
            elif header[j].lower().startswith(("stayed", "status")):
                cells.append(_status_cell(c))
            elif _looks_numeric(c):
                cells.append(f'<td class="num">{_e(c)}</td>')
            else:
                cells.append(f"<td>{_e(c)}</td>")
        out.append("<tr>" + "".join(cells) + "</tr>")
    out.append("</table>")
    return "\n".join(out)


def _looks_numeric(text: str) -> bool:
    head = str(text).strip().split(" ")[0].replace("%", "")
    try:
        float(head)
    except ValueError:
        return False
    return True


def write_index(
    folder: str | Path,
    *,
    title: str,
    intro: Sequence[str],
    summary_header: Sequence[str],
    summary_rows: Sequence[Sequence[str]],
    sections: Sequence[Section],
    footer: str = "",
) -> Path:
    """Write ``index.html`` into *folder* (created if missing; image paths are relative to
    it). The first cell of each summary row links to the section of the same position.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{_e(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{_e(title)}</h1>",
    ]
    parts += [f"<p>{_e(p)}</p>" for p in intro]
    if sections:
        parts.append("<nav>" + "".join(f'<a href="#{_e(s.anchor)}">{_e(s.title)}</a>' for s in sections)
                     + "</nav>")
    if summary_rows:
        anchors = [s.anchor for s in sections][: len(summary_rows)]
        parts.append(_table(summary_header, summary_rows, link_first=anchors))
    for s in sections:
        parts.append(f'<section id="{_e(s.anchor)}">')
        parts.append(f"<h2>{_e(s.title)}</h2>")
        if s.subtitle:
            parts.append(f'<p class="sub">{_e(s.subtitle)}</p>')
        parts += [f"<p>{_e(p)}</p>" for p in s.story]
        if s.notes:
            parts.append('<div class="notes">' + "".join(f"<p>{_e(n)}</p>" for n in s.notes) + "</div>")
        if s.images:
            parts.append('<div class="gallery">')
            for im in s.images:
                cls = ' class="wide"' if im.wide else ""
                parts.append(
                    f'<figure{cls}><img src="{_e(im.path)}" alt="{_e(im.caption)}" loading="lazy">'
                    f"<figcaption>{_e(im.caption)}</figcaption></figure>"
                )
            parts.append("</div>")
        if s.facts:
            parts.append(_table(["quantity", "value"], [list(f) for f in s.facts]))
        if s.equations:
            parts.append("<details open><summary>Equations of motion (derived by the project)"
                         "</summary>")
            parts.append(f"<pre>{_e(s.equations)}</pre>")
            if s.equations_latex:
                parts.append("<details><summary>LaTeX source</summary>"
                             f"<pre>{_e(s.equations_latex)}</pre></details>")
            parts.append("</details>")
        parts.append("</section>")
    if footer:
        parts.append(f'<hr><p class="sub">{_e(footer)}</p>')
    parts.append("</body></html>")
    path = folder / "index.html"
    write_text(path, "\n".join(parts) + "\n")
    return path
