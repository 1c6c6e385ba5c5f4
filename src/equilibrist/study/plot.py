"""Pictures of a study table: a metric over one or two varied quantities.

Two quantities give a heat map (one cell per pair of grid values), one a
line (a random sample: points). The other varied quantities are fixed with
``where`` (``{"controller": "lqr"}``) or aggregated over (``agg``: mean,
median, min or max of the metric over the rows that share the shown
values). Points without a result (a failed design) and non-finite values (a
settling percentile of runs that did not settle, ``inf``) are left blank
and counted in the caption.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.errors import nearest
from equilibrist.study.record import Axis, Study, StudyError

if TYPE_CHECKING:
    import pyarrow as pa
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

AGGREGATIONS: dict[str, Callable[[np.ndarray], float]] = {
    "mean": np.mean, "median": np.median, "min": np.min, "max": np.max}
# More distinct values than this along an axis: a random sample, drawn as points.
_GRID_LIMIT = 60


def _column(table: pa.Table, name: str) -> np.ndarray:
    values = table.column(name).to_pylist()
    if values and isinstance(values[0], str):
        return np.array(values, dtype=object)
    return np.array([math.nan if v is None else v for v in values], dtype=float if not
                    isinstance(values[0] if values else 0.0, bool) else bool)


def _matches(value: float | str | bool, text: str, kind: str) -> bool:
    if kind == "controller":  # the kind's name in any case; a file's name as it is
        name, sep, rest = text.partition(":")
        return str(value) == name.strip().lower() + sep + rest.strip()
    if kind == "delay":
        return bool(value) == (text.lower() in ("1", "true"))
    try:
        return bool(np.isclose(float(value), float(text), rtol=1e-9, atol=0.0))
    except ValueError:
        return False


def _label(value: object) -> str:
    if isinstance(value, (float, np.floating)):
        return f"{float(value):.4g}"
    return str(value)


def plot_study(
    table: pa.Table,
    study: Study,
    path: str | Path,
    *,
    metric: str = "fraction_up",
    x: str | None = None,
    y: str | None = None,
    agg: str = "mean",
    where: Mapping[str, str] | None = None,
    dpi: float = 100.0,
) -> Path:
    """Draw *metric* (a numeric column) over the varied quantities *x* (and *y*), by default
    the study's first two, into *path*; *where* keeps the rows with these values of other
    quantities, *agg* combines the rows that share the shown values."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    from equilibrist.viz.output import save_figure

    axes = {a.name: a for a in study.axes}
    x, y = _picture_axes(table, axes, metric=metric, x=x, y=y, agg=agg, where=where)
    names = list(axes)
    keep = _kept_rows(table, axes, where or {})
    failed = int((~np.array([s == "ok" for s in table.column("status").to_pylist()])).sum())
    values = _column(table, metric).astype(float)
    xs = _column(table, x)
    others = [n for n in names if n not in (x, y) and n not in (where or {})]
    fn = AGGREGATIONS[agg]
    fig, ax = plt.subplots(figsize=(7.0, 5.0), dpi=dpi)
    title = f"{study.system}: {metric}"
    notes = []
    if others:
        notes.append(f"{agg} over {', '.join(others)}")
    if where:
        notes.append(", ".join(f"{k} = {v}" for k, v in where.items()))
    if failed:
        notes.append(f"{failed} point(s) without a result")

    def cell(mask: np.ndarray) -> float:
        v = values[mask & keep]
        v = v[~np.isnan(v)]
        return float(fn(v)) if v.size else math.nan

    if y is None:
        _draw_line(ax, xs, values, keep, cell, x=x, log=axes[x].log, metric=metric)
    else:
        _draw_map(fig, ax, xs, _column(table, y), values, keep, cell, metric=metric, notes=notes)
        ax.set_xlabel(x)
        ax.set_ylabel(y)
    ax.set_title(title + (f"\n({'; '.join(notes)})" if notes else ""), fontsize=10)
    fig.tight_layout()
    out = save_figure(fig, path)
    plt.close(fig)
    return out


def _picture_axes(table: pa.Table, axes: Mapping[str, Axis], *, metric: str, x: str | None,
                  y: str | None, agg: str,
                  where: Mapping[str, str] | None) -> tuple[str, str | None]:
    """The quantities on the picture's x and y axes (default the study's first two), every
    option checked; raises :class:`StudyError` naming every problem."""
    problems = []
    numeric = [f.name for f in table.schema
               if f.name not in axes and str(f.type) in ("double", "int64") and f.name != "point"]
    if metric not in numeric:
        problems.append(f"--metric {metric!r}: not a metric of the table ({nearest(metric, numeric)})")
    if not axes:
        problems.append("the study varies nothing: there is no axis to plot over")
    names = list(axes)
    if x is None and names:
        x = names[0]
        if y is None and len(names) > 1:
            y = names[1]
    for option, name in (("--x", x), ("--y", y)):
        if name is not None and name not in axes:
            problems.append(f"{option} {name!r}: not a varied quantity of the study "
                            f"({nearest(name, names) if names else 'it varies nothing'})")
    if x is not None and x == y:
        problems.append(f"--x and --y are both {x}")
    if agg not in AGGREGATIONS:
        problems.append(f"--agg {agg!r}: expected one of {', '.join(AGGREGATIONS)}")
    for name in where or {}:
        if name not in axes:
            problems.append(f"--where {name!r}: not a varied quantity ({nearest(name, names)})")
        elif name in (x, y):
            problems.append(f"--where {name}: it is on an axis of the picture")
    if problems:
        raise StudyError("; ".join(problems))
    assert x is not None
    return x, y


def _kept_rows(table: pa.Table, axes: Mapping[str, Axis], where: Mapping[str, str]) -> np.ndarray:
    """The rows drawn: those with a result and the values *where* asks for; a value no point
    has is refused."""
    keep = np.array([s == "ok" for s in table.column("status").to_pylist()], dtype=bool)
    for name, text in where.items():
        col = _column(table, name)
        sel = np.array([_matches(v, text, axes[name].kind) for v in col], dtype=bool)
        if not sel.any():
            raise StudyError(f"--where {name}={text}: no point of the study has that value "
                             f"(values: {', '.join(sorted({_label(v) for v in col}))})")
        keep &= sel
    return keep


def _draw_line(ax: Axes, xs: np.ndarray, values: np.ndarray, keep: np.ndarray,
               cell: Callable[[np.ndarray], float], *, x: str, log: bool, metric: str) -> None:
    """The metric over one quantity: a line through the grid's values (the rows that share
    each combined by *cell*), or the points of a random sample."""
    ux = _unique(xs)
    if len(ux) > _GRID_LIMIT:
        ax.plot(xs[keep], values[keep], ".", alpha=0.6)
    else:
        line = [cell(_eq(xs, v)) for v in ux]
        pos = np.arange(len(ux)) if xs.dtype == object else np.asarray(ux, dtype=float)
        ax.plot(pos, line, "o-")
        if xs.dtype == object:
            ax.set_xticks(pos, [_label(v) for v in ux])
        if log:
            ax.set_xscale("log")
            ax.minorticks_off()
            ax.set_xticks(pos, [_label(v) for v in ux])
    ax.set_xlabel(x)
    ax.set_ylabel(metric)
    ax.grid(True, alpha=0.3)


def _draw_map(fig: Figure, ax: Axes, xs: np.ndarray, ys: np.ndarray, values: np.ndarray,
              keep: np.ndarray, cell: Callable[[np.ndarray], float], *, metric: str,
              notes: list[str]) -> None:
    """The metric over two quantities: a heat map of the grid (each cell's rows combined by
    *cell*; a blank cell counted in *notes*), or the points of a random sample, coloured."""
    import matplotlib

    ux, uy = _unique(xs), _unique(ys)
    if len(ux) > _GRID_LIMIT or len(uy) > _GRID_LIMIT:
        sc = ax.scatter(xs[keep], ys[keep], c=values[keep], s=18, cmap="viridis")
        fig.colorbar(sc, ax=ax, label=metric)
        return
    grid = np.array([[cell(_eq(xs, vx) & _eq(ys, vy)) for vx in ux] for vy in uy])
    blank = int((~np.isfinite(grid)).sum())
    shown = np.ma.masked_invalid(grid)
    cmap = matplotlib.colormaps["viridis"].copy()
    cmap.set_bad("lightgray")
    share = "fraction" in metric
    im = ax.imshow(shown, origin="lower", aspect="auto", cmap=cmap,
                   interpolation="nearest", vmin=0.0 if share else None,
                   vmax=1.0 if share else None)
    fig.colorbar(im, ax=ax, label=metric)
    step_x = max(1, len(ux) // 10)
    step_y = max(1, len(uy) // 10)
    ax.set_xticks(range(0, len(ux), step_x), [_label(v) for v in ux[::step_x]])
    ax.set_yticks(range(0, len(uy), step_y), [_label(v) for v in uy[::step_y]])
    if len(ux) * len(uy) <= 100:
        for i in range(len(uy)):
            for j in range(len(ux)):
                if np.isfinite(grid[i, j]):
                    ax.text(j, i, f"{grid[i, j]:.3g}", ha="center", va="center",
                            fontsize=7, color="white")
    if blank:
        notes.append(f"{blank} blank cell(s): no finite value")


def _unique(col: np.ndarray) -> np.ndarray:
    if col.dtype == object:
        return np.array(sorted(set(col.tolist())), dtype=object)
    return np.unique(col)


def _eq(col: np.ndarray, value: object) -> np.ndarray:
    if col.dtype == object:
        return np.array([c == value for c in col], dtype=bool)
    mask: np.ndarray = col == value
    return mask
