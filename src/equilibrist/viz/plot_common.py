"""What the plots share: the line styles, the units angles are shown in, axis labels,
figures made without pyplot (titled, saved), and the rows of a state's plots."""

from __future__ import annotations

import math
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

from equilibrist.viz.output import save_figure

if TYPE_CHECKING:  # matplotlib is imported when a figure is made
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure


class LineStyle(TypedDict, total=False):
    """Keyword arguments of a matplotlib line (``ax.plot(t, y, **TRUE)``)."""

    color: str
    lw: float
    ls: str
    marker: str
    ms: float
    alpha: float


# Line styles shared by the plots.
TRUE: LineStyle = {"color": "#1f5fa8", "lw": 1.5}
ESTIMATE: LineStyle = {"color": "#e8871e", "lw": 1.2, "ls": "--"}
MEASURED: LineStyle = {"color": "#888888", "ls": "none", "marker": ".", "ms": 1.5, "alpha": 0.6}
REFERENCE: LineStyle = {"color": "#111111", "lw": 1.0, "ls": "-."}
APPLIED: LineStyle = {"color": "#2e9e4f", "lw": 1.5}
COMMAND: LineStyle = {"color": "#9b30c8", "lw": 1.0, "ls": ":"}
LIMIT: LineStyle = {"color": "#d1263b", "lw": 1.0, "ls": "--"}
OPERATING: LineStyle = {"color": "#999999", "lw": 0.8, "ls": ":"}
EVENT: LineStyle = {"color": "#d1263b", "lw": 0.8, "ls": "-", "alpha": 0.5}


def display_unit(unit: str, *, degrees: bool = True) -> tuple[float, str]:
    """The factor and unit a quantity in *unit* is shown in.

    Angles (``rad``, ``rad/s``, ``rad/s^2``) become degrees when *degrees*.
    """
    if degrees and (unit == "rad" or unit.startswith("rad/")):
        return 180.0 / math.pi, "deg" + unit[3:]
    return 1.0, unit


def axis_label(name: str, unit: str) -> str:
    """``"theta [deg]"``; a name without unit stays bare."""
    return f"{name} [{unit}]" if unit and unit != "1" else name


def _figure(width: float, height: float, dpi: float = 100.0) -> Figure:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _wrap(fig: Figure, text: str, points: float = 10.0) -> str:
    """*text* broken into lines that fit the figure's width (a long title
    would otherwise run off both sides of a centred suptitle)."""
    chars = max(20, int(fig.get_figwidth() * 72.0 / (0.55 * points)))
    return "\n".join(textwrap.fill(line, chars) for line in text.splitlines() or [""])


def _title(fig: Figure, text: str) -> None:
    fig.suptitle(_wrap(fig, text), fontsize="medium")


def _finish(fig: Figure, path: str | Path | None) -> Figure:
    if path is not None:
        save_figure(fig, path)
    return fig


def _state_pairs(state_names: Sequence[str]) -> list[tuple[str, str | None]]:
    """Coordinates with their rates: ``[("x", "x_dot"), ...]``.

    A rate whose coordinate is not a state (none in the catalogue) gets a
    row of its own.
    """
    pairs: list[tuple[str, str | None]] = []
    used: set[str] = set()
    for name in state_names:
        if name.endswith("_dot") and name[:-4] in state_names:
            continue
        rate = f"{name}_dot" if f"{name}_dot" in state_names else None
        pairs.append((name, rate))
        used.update([name] + ([rate] if rate else []))
    return pairs + [(n, None) for n in state_names if n not in used]


def _legend(fig: Figure, axes: Sequence[Axes]) -> None:
    """One legend for the figure, with each label once."""
    seen: dict[str, Artist] = {}
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab and not lab.startswith("_") and lab not in seen:
                seen[lab] = h
    if seen:
        fig.legend(list(seen.values()), list(seen.keys()), loc="outside lower center",
                   ncols=min(len(seen), 6), fontsize="small", frameon=False)
