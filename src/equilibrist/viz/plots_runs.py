"""Plots of runs over time: one run's response, runs compared, and the Monte-Carlo
fan of many runs."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.viz.output import VizError
from equilibrist.viz.plot_common import (
    APPLIED,
    COMMAND,
    ESTIMATE,
    EVENT,
    LIMIT,
    MEASURED,
    OPERATING,
    REFERENCE,
    TRUE,
    _figure,
    _finish,
    _legend,
    _state_pairs,
    _title,
    axis_label,
    display_unit,
)
from equilibrist.viz.runs import Run, as_run

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from equilibrist.numeric.system import System
    from equilibrist.sim.result import SimResult


def _operating_point(run: Run) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The run's operating point, else the system's canonical one (None: it has none)."""
    if run.x_op is not None:
        return run.x_op, run.u_op
    from equilibrist.errors import EquilibristError

    try:
        eq = run.system.operating_point()
    except EquilibristError:  # no canonical point (the zxz gyroscope)
        return None, None
    return np.asarray(eq.x, float), np.asarray(eq.u, float)


def _saturated(run: Run) -> np.ndarray | None:
    if run.u is None or run.u_command is None:
        return None
    saturated: np.ndarray = ~np.isclose(run.u, run.u_command, rtol=1e-6, atol=1e-9)
    return saturated


def _events(ax: Axes, run: Run) -> None:
    for when, what in run.events:
        ax.axvline(when, **EVENT)
        ax.annotate(what, (when, 1.0), xycoords=("data", "axes fraction"), xytext=(2, -2),
                    textcoords="offset points", va="top", fontsize="x-small", color=EVENT["color"])


def plot_response(
    # SimResult | Run; Any while equilibrist.cli.plot passes its SimResult | BatchResult.
    result: Any,
    path: str | Path | None = None,
    *,
    states: Sequence[str] | None = None,
    rates: bool = True,
    degrees: bool = True,
    title: str | None = None,
    width: float = 9.0,
    row_height: float = 1.7,
    dpi: float = 100.0,
    system: System | None = None,
) -> Figure:
    """Time response of one run: states, estimates vs truth, inputs.

    Each coordinate has a row (its rate beside it, with *rates*): the true state, the
    estimate (dashed), the measurements (grey dots) when the state is
    measured, the reference (dash-dot) when it is tracked, and the operating
    point (dotted). Each input has a row: the input applied, the command
    before saturation (dotted), the limits (red dashed) and the samples in
    saturation (shaded). Marked events (a push) are vertical lines.

    *states* picks the coordinates shown (default: all). *system* is the simulated system
    (default: rebuilt from the result's key, which never runs a Python system file: name
    such a system here). The conventions of every plot are in :mod:`equilibrist.viz.plots`.
    """
    run = as_run(result, system=system)
    pairs = _state_pairs(run.state_names)
    if states is not None:
        for s in states:
            run._index(s)
        pairs = [p for p in pairs if p[0] in states]
    show_rates = rates and any(r for _, r in pairs)
    n_in = len(run.input_names) if run.u is not None else 0
    rows = len(pairs) + n_in
    fig = _figure(width, max(2.0, row_height * rows + 0.6), dpi)
    grid = fig.add_gridspec(rows, 2 if show_rates else 1)
    x_op, u_op = _operating_point(run)
    measured = {n: i for i, n in enumerate(run.output_names)}
    tracked = {n: i for i, n in enumerate(run.reference_names)}
    axes: list[Axes] = []
    for row, (coord, rate) in enumerate(pairs):
        for col, name in enumerate((coord, rate) if show_rates else (coord,)):
            if name is None:
                continue
            ax = fig.add_subplot(grid[row, col], sharex=axes[0] if axes else None)
            axes.append(ax)
            i = run.state_names.index(name)
            k, unit = display_unit(run.state_units[i], degrees=degrees)
            if x_op is not None:
                ax.axhline(k * x_op[i], **OPERATING, label="operating point")
            if name in measured and run.y is not None:
                ax.plot(run.t, k * run.y[:, measured[name]], **MEASURED, label="measured")
            ax.plot(run.t, k * run.x[:, i], **TRUE, label="true")
            if run.estimate is not None:
                ax.plot(run.t, k * run.estimate[:, i], **ESTIMATE, label="estimate")
            if name in tracked and run.reference is not None:
                ax.plot(run.t, k * run.reference[:, tracked[name]], **REFERENCE, label="reference")
            _events(ax, run)
            ax.set_ylabel(axis_label(name, unit))
            ax.grid(alpha=0.3)
    sat = _saturated(run)
    for j in range(n_in):
        ax = fig.add_subplot(grid[len(pairs) + j, :], sharex=axes[0] if axes else None)
        axes.append(ax)
        unit = run.input_units[j]
        low, high = run.system.input_limits
        if run.u_command is not None:
            ax.plot(run.t, run.u_command[:, j], **COMMAND, label="command")
        ax.plot(run.t, run.u[:, j], **APPLIED, label="applied")  # type: ignore[index]
        _limit_lines(ax, low[j], high[j])
        if u_op is not None and len(u_op):
            ax.axhline(u_op[j], **OPERATING)
        if sat is not None and sat[:, j].any():
            ax.fill_between(run.t, 0, 1, where=sat[:, j], transform=ax.get_xaxis_transform(),
                            color=LIMIT["color"], alpha=0.12, lw=0, label="saturated")
        _events(ax, run)
        ax.set_ylabel(axis_label(run.input_names[j], unit))
        ax.grid(alpha=0.3)
    # Every panel keeps its time tick labels (panels are read one at a time);
    # the axis title goes under the bottom row only.
    for a in axes:
        a.tick_params(labelbottom=True)
        spec = a.get_subplotspec()
        if spec is not None and spec.is_last_row():
            a.set_xlabel("time [s]")
    _legend(fig, axes)
    _title(fig, title if title is not None else _run_title(run))
    return _finish(fig, path)


def _run_title(run: Run) -> str:
    name = run.system.spec.title or run.key
    bits = [name]
    if run.label:
        bits.append(run.label)
    if run.fell is not None:
        bits.append("FELL" if run.fell else "stayed up")
    return " - ".join(bits)


def plot_comparison(
    # Results or Runs; Any while equilibrist.cli.plot passes its SimResult | BatchResult.
    results: Sequence[Any] | Mapping[str, Any],
    path: str | Path | None = None,
    *,
    states: Sequence[str] | None = None,
    inputs: bool = True,
    degrees: bool = True,
    title: str | None = None,
    width: float = 8.0,
    row_height: float = 1.7,
    dpi: float = 100.0,
    system: System | None = None,
) -> Figure:
    """Several runs of the same system overlaid, one colour per run (a mapping's keys are
    the legend labels, else each run's own label): the coordinates, or *states*, and with
    *inputs* the inputs applied and their limits. *system* as for :func:`plot_response`.
    """
    items = results.items() if isinstance(results, Mapping) else [(None, r) for r in results]
    runs = [as_run(r, label=lab, system=system) for lab, r in items]
    if not runs:
        raise VizError("nothing to compare: no runs given")
    first = runs[0]
    for r in runs[1:]:
        if r.state_names != first.state_names:
            raise VizError(f"cannot compare runs of {first.key} and {r.key}: their states differ")
    names, n_in, fig, axes = _rows(runs, states, inputs=inputs, width=width,
                                   row_height=row_height, dpi=dpi)
    colors = _colors(len(runs))
    for k, run in enumerate(runs):
        label = run.label or f"run {k + 1}"
        for ax, name in zip(axes, names, strict=False):
            i = run.state_names.index(name)
            f, _ = display_unit(run.state_units[i], degrees=degrees)
            ax.plot(run.t, f * run.x[:, i], color=colors[k], lw=1.4, label=label)
        for j in range(n_in):
            axes[len(names) + j].plot(run.t, run.u[:, j], color=colors[k], lw=1.2, label=label)  # type: ignore[index]
    for ax, name in zip(axes, names, strict=False):
        i = first.state_names.index(name)
        ax.set_ylabel(axis_label(name, display_unit(first.state_units[i], degrees=degrees)[1]))
    low, high = first.system.input_limits if n_in else (np.zeros(0), np.zeros(0))
    for j in range(n_in):
        ax = axes[len(names) + j]
        _limit_lines(ax, low[j], high[j])
        ax.set_ylabel(axis_label(first.input_names[j], first.input_units[j]))
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    _legend(fig, list(axes))
    _title(fig, title or f"{first.system.spec.title or first.key}: comparison")
    return _finish(fig, path)


def _rows(runs: Sequence[Run], states: Sequence[str] | None, *, inputs: bool, width: float,
          row_height: float, dpi: float) -> tuple[list[str], int, Figure, np.ndarray]:
    """The states shown (default: the coordinates, checked), the inputs shown (only when
    every run has them), and a figure with a row for each."""
    first = runs[0]
    names = list(states) if states is not None else [c for c, _ in _state_pairs(first.state_names)]
    for s in names:
        first._index(s)
    n_in = len(first.input_names) if inputs and all(r.u is not None for r in runs) else 0
    rows = len(names) + n_in
    fig = _figure(width, max(2.0, row_height * rows + 0.6), dpi)
    return names, n_in, fig, fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]


def _limit_lines(ax: Axes, low: float, high: float, *, label_each: bool = False) -> None:
    for v in (low, high):
        if math.isfinite(v):
            ax.axhline(v, **LIMIT, label="limits" if label_each or v == low else None)


def _colors(n: int) -> list[str]:
    base = ["#1f5fa8", "#e8871e", "#2e9e4f", "#d1263b", "#9b30c8", "#6b4c2a", "#e377c2",
            "#555555", "#17becf", "#bcbd22"]
    return [base[k % len(base)] for k in range(n)]


def plot_fan(
    results: Iterable[SimResult | Run],
    path: str | Path | None = None,
    *,
    states: Sequence[str] | None = None,
    inputs: bool = True,
    degrees: bool = True,
    title: str | None = None,
    max_traces: int = 40,
    width: float = 8.0,
    row_height: float = 1.7,
    dpi: float = 100.0,
) -> Figure:
    """Monte-Carlo fan: the spread of many runs over time.

    For each state shown (default: the coordinates), the median, the 25-75 % and 5-95 % bands
    over the runs at each time, and up to *max_traces* individual runs as thin lines
    (runs that fell in red). Runs sampled at other times are interpolated
    onto the first run's times (a run that ended early counts until it
    ended). With *inputs*, the inputs' fan too.
    """
    runs = [as_run(r) for r in results]
    if not runs:
        raise VizError("a fan plot needs at least one run")
    first = runs[0]
    names, n_in, fig, axes = _rows(runs, states, inputs=inputs, width=width,
                                   row_height=row_height, dpi=dpi)
    t = first.t

    def stack(get: Callable[[Run], np.ndarray], col: int) -> np.ndarray:
        out = np.full((len(runs), len(t)), np.nan)
        for k, r in enumerate(runs):
            v = get(r)[:, col]
            inside = t <= r.t[-1] + 1e-12
            out[k, inside] = np.interp(t[inside], r.t, v)
        return out

    def applied(r: Run) -> np.ndarray:
        assert r.u is not None  # inputs are shown only when every run has them
        return r.u

    series = []
    for name in names:
        i = first.state_names.index(name)
        f, unit = display_unit(first.state_units[i], degrees=degrees)
        series.append((name, unit, f * stack(lambda r: r.x, i)))
    for j in range(n_in):
        series.append((first.input_names[j], first.input_units[j], stack(applied, j)))
    fell = [bool(r.fell) for r in runs]
    pick = np.unique(np.linspace(0, len(runs) - 1, min(len(runs), max_traces)).round().astype(int))
    for ax, (name, unit, data) in zip(axes, series, strict=True):
        for k in pick:
            ax.plot(t, data[k], color="#d1263b" if fell[k] else "#777777", lw=0.5, alpha=0.5,
                    label="a run that fell" if fell[k] else "single runs")
        with np.errstate(all="ignore"):
            import warnings

            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                q = np.nanpercentile(data, [5, 25, 50, 75, 95], axis=0)
        ax.fill_between(t, q[0], q[4], color="#1f5fa8", alpha=0.18, lw=0, label="5-95 %")
        ax.fill_between(t, q[1], q[3], color="#1f5fa8", alpha=0.35, lw=0, label="25-75 %")
        ax.plot(t, q[2], color="#1f5fa8", lw=1.6, label="median")
        ax.set_ylabel(axis_label(name, unit))
        ax.grid(alpha=0.3)
    if n_in:
        low, high = first.system.input_limits
        for j in range(n_in):
            _limit_lines(axes[len(names) + j], low[j], high[j], label_each=True)
    axes[-1].set_xlabel("time [s]")
    _legend(fig, list(axes))
    n_fell = sum(fell)
    _title(fig, title or f"{first.system.spec.title or first.key}: {len(runs)} runs, "
                f"{n_fell} fell")
    return _finish(fig, path)
