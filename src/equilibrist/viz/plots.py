"""Plots of runs and designs: time responses, comparisons, Monte-Carlo fans,
regions of attraction and pole maps.

Every function returns a :class:`matplotlib.figure.Figure` (made without
pyplot, so nothing global changes) and, given *path*, saves it as PNG or
SVG by the suffix. Axes are named with their units; angles are shown in
degrees (``degrees=False`` keeps radians). Runs are read through
:func:`~equilibrist.viz.runs.as_run`, so a simulation result or a
:class:`~equilibrist.viz.runs.Run` made from arrays both work.
"""

from __future__ import annotations

import math
import textwrap
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.viz.output import VizError, save_figure
from equilibrist.viz.runs import Run, as_run

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from equilibrist.numeric.system import System

# Line styles shared by the plots.
TRUE = {"color": "#1f5fa8", "lw": 1.5}
ESTIMATE = {"color": "#e8871e", "lw": 1.2, "ls": "--"}
MEASURED = {"color": "#888888", "ls": "none", "marker": ".", "ms": 1.5, "alpha": 0.6}
REFERENCE = {"color": "#111111", "lw": 1.0, "ls": "-."}
APPLIED = {"color": "#2e9e4f", "lw": 1.5}
COMMAND = {"color": "#9b30c8", "lw": 1.0, "ls": ":"}
LIMIT = {"color": "#d1263b", "lw": 1.0, "ls": "--"}
OPERATING = {"color": "#999999", "lw": 0.8, "ls": ":"}
EVENT = {"color": "#d1263b", "lw": 0.8, "ls": "-", "alpha": 0.5}


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


def _figure(width: float, height: float, dpi: float = 100.0) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _wrap(fig: Any, text: str, points: float = 10.0) -> str:
    """*text* broken into lines that fit the figure's width (a long title
    would otherwise run off both sides of a centred suptitle)."""
    chars = max(20, int(fig.get_figwidth() * 72.0 / (0.55 * points)))
    return "\n".join(textwrap.fill(line, chars) for line in text.splitlines() or [""])


def _title(fig: Any, text: str) -> None:
    fig.suptitle(_wrap(fig, text), fontsize="medium")


def _finish(fig: Any, path: str | Path | None) -> Any:
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
    return ~np.isclose(run.u, run.u_command, rtol=1e-6, atol=1e-9)


def _events(ax: Any, run: Run) -> None:
    for when, what in run.events:
        ax.axvline(when, **EVENT)
        ax.annotate(what, (when, 1.0), xycoords=("data", "axes fraction"), xytext=(2, -2),
                    textcoords="offset points", va="top", fontsize="x-small", color=EVENT["color"])


def plot_response(
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
) -> Any:
    """Time response of one run: states, estimates vs truth, inputs.

    Each coordinate has a row (its rate beside it): the true state, the
    estimate (dashed), the measurements (grey dots) when the state is
    measured, the reference (dash-dot) when it is tracked, and the operating
    point (dotted). Each input has a row: the input applied, the command
    before saturation (dotted), the limits (red dashed) and the samples in
    saturation (shaded). Marked events (a push) are vertical lines.

    Parameters
    ----------
    result : equilibrist.sim.SimResult or Run
        The run.
    path : str or pathlib.Path, optional
        Save the figure there (``.png`` or ``.svg``).
    states : sequence of str, optional
        Coordinates to show (default: all).
    rates : bool
        Show each coordinate's rate beside it.
    degrees : bool
        Show angles in degrees.
    title : str, optional
        Figure title (default: the system's title and the run's label).
    width, row_height, dpi : float
        Size of the figure in inches (per row) and its resolution.
    system : equilibrist.numeric.system.System, optional
        The simulated system (default: rebuilt from the result's key, which
        never runs a Python system file: name such a system here).

    Returns
    -------
    matplotlib.figure.Figure
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
        for v in (low[j], high[j]):
            if math.isfinite(v):
                ax.axhline(v, **LIMIT, label="limits" if v == low[j] else None)
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


def _legend(fig: Any, axes: Sequence[Any]) -> None:
    """One legend for the figure, with each label once."""
    seen: dict[str, Any] = {}
    for ax in axes:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab and not lab.startswith("_") and lab not in seen:
                seen[lab] = h
    if seen:
        fig.legend(list(seen.values()), list(seen.keys()), loc="outside lower center",
                   ncols=min(len(seen), 6), fontsize="small", frameon=False)


def plot_comparison(
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
) -> Any:
    """Several runs of the same system overlaid, one colour per run.

    For comparisons such as linear vs nonlinear plant, LQR vs LQG, nominal
    vs perturbed parameters.

    Parameters
    ----------
    results : sequence of results or mapping of label to result
        The runs (each a simulation result or a Run); a mapping's keys are
        the legend labels, else each run's own label.
    path : str or pathlib.Path, optional
        Save the figure there.
    states : sequence of str, optional
        States to show (default: the coordinates).
    inputs : bool
        Show the inputs applied (and their limits).
    degrees : bool
        Show angles in degrees.
    title : str, optional
        Figure title.
    width, row_height, dpi : float
        Figure size and resolution.
    system : equilibrist.numeric.system.System, optional
        The simulated system, as for :func:`plot_response`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    items = results.items() if isinstance(results, Mapping) else [(None, r) for r in results]
    runs = [as_run(r, label=lab, system=system) for lab, r in items]
    if not runs:
        raise VizError("nothing to compare: no runs given")
    first = runs[0]
    for r in runs[1:]:
        if r.state_names != first.state_names:
            raise VizError(f"cannot compare runs of {first.key} and {r.key}: their states differ")
    names = list(states) if states is not None else [c for c, _ in _state_pairs(first.state_names)]
    for s in names:
        first._index(s)
    n_in = len(first.input_names) if inputs and all(r.u is not None for r in runs) else 0
    rows = len(names) + n_in
    fig = _figure(width, max(2.0, row_height * rows + 0.6), dpi)
    axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
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
        for v in (low[j], high[j]):
            if math.isfinite(v):
                ax.axhline(v, **LIMIT, label="limits" if v == low[j] else None)
        ax.set_ylabel(axis_label(first.input_names[j], first.input_units[j]))
    for ax in axes:
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    _legend(fig, list(axes))
    _title(fig, title or f"{first.system.spec.title or first.key}: comparison")
    return _finish(fig, path)


def _colors(n: int) -> list[str]:
    base = ["#1f5fa8", "#e8871e", "#2e9e4f", "#d1263b", "#9b30c8", "#6b4c2a", "#e377c2",
            "#555555", "#17becf", "#bcbd22"]
    return [base[k % len(base)] for k in range(n)]


def plot_fan(
    results: Iterable[Any],
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
) -> Any:
    """Monte-Carlo fan: the spread of many runs over time.

    For each state shown, the median, the 25-75 % and 5-95 % bands over the
    runs at each time, and up to *max_traces* individual runs as thin lines
    (runs that fell in red). Runs sampled at other times are interpolated
    onto the first run's times (a run that ended early counts until it
    ended).

    Parameters
    ----------
    results : iterable of results
        The runs of a batch (simulation results or Runs).
    path : str or pathlib.Path, optional
        Save the figure there.
    states : sequence of str, optional
        States to show (default: the coordinates).
    inputs : bool
        Show the inputs' fan too.
    degrees : bool
        Show angles in degrees.
    title : str, optional
        Figure title.
    max_traces : int
        Individual runs drawn at most.
    width, row_height, dpi : float
        Figure size and resolution.

    Returns
    -------
    matplotlib.figure.Figure
    """
    runs = [as_run(r) for r in results]
    if not runs:
        raise VizError("a fan plot needs at least one run")
    first = runs[0]
    names = list(states) if states is not None else [c for c, _ in _state_pairs(first.state_names)]
    for s in names:
        first._index(s)
    n_in = len(first.input_names) if inputs and all(r.u is not None for r in runs) else 0
    rows = len(names) + n_in
    t = first.t
    fig = _figure(width, max(2.0, row_height * rows + 0.6), dpi)
    axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]

    def stack(get: Any) -> np.ndarray:
        out = np.full((len(runs), len(t)), np.nan)
        for k, r in enumerate(runs):
            v = get(r)
            inside = t <= r.t[-1] + 1e-12
            out[k, inside] = np.interp(t[inside], r.t, v)
        return out

    series = []
    for name in names:
        i = first.state_names.index(name)
        f, unit = display_unit(first.state_units[i], degrees=degrees)
        series.append((name, unit, f * stack(lambda r, i=i: r.x[:, i])))
    for j in range(n_in):
        series.append((first.input_names[j], first.input_units[j], stack(lambda r, j=j: r.u[:, j])))
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
            for v in (low[j], high[j]):
                if math.isfinite(v):
                    axes[len(names) + j].axhline(v, **LIMIT, label="limits")
    axes[-1].set_xlabel("time [s]")
    _legend(fig, list(axes))
    n_fell = sum(fell)
    _title(fig, title or f"{first.system.spec.title or first.key}: {len(runs)} runs, "
                f"{n_fell} fell")
    return _finish(fig, path)


def plot_region_of_attraction(
    x_values: Sequence[float] | np.ndarray,
    y_values: Sequence[float] | np.ndarray,
    stayed_up: Sequence[bool] | np.ndarray,
    path: str | Path | None = None,
    *,
    x_name: str,
    y_name: str,
    x_unit: str = "",
    y_unit: str = "",
    degrees: bool = True,
    title: str | None = None,
    width: float = 5.5,
    height: float = 4.5,
    dpi: float = 100.0,
) -> Any:
    """Map of the initial conditions from which the controller recovers.

    Parameters
    ----------
    x_values, y_values : sequence of float
        The two varied initial-condition components of each run.
    stayed_up : sequence of bool
        Whether each run stayed in its region (recovered).
    path : str or pathlib.Path, optional
        Save the figure there.
    x_name, y_name, x_unit, y_unit : str
        Names and units of the two components (the states varied).
    degrees : bool
        Show angles in degrees.
    title : str, optional
        Figure title.
    width, height, dpi : float
        Figure size and resolution.

    Returns
    -------
    matplotlib.figure.Figure

    Notes
    -----
    When the points form a full grid, the map is drawn as cells; otherwise
    as a scatter of points.
    """
    fig = _figure(width, height, dpi)
    _region_axes(fig, fig.add_subplot(), x_values, y_values, stayed_up, x_name=x_name,
                 y_name=y_name, x_unit=x_unit, y_unit=y_unit, degrees=degrees,
                 title=title or "region of attraction")
    return _finish(fig, path)


def plot_regions_side_by_side(
    maps: Mapping[str, tuple[Sequence[float] | np.ndarray, Sequence[float] | np.ndarray,
                             Sequence[bool] | np.ndarray]],
    path: str | Path | None = None,
    *,
    x_name: str,
    y_name: str,
    x_unit: str = "",
    y_unit: str = "",
    degrees: bool = True,
    title: str | None = None,
    width: float = 9.5,
    height: float = 4.3,
    dpi: float = 100.0,
) -> Any:
    """Regions of attraction of several controllers over the same starts, side by side.

    Parameters
    ----------
    maps : mapping of label to (x values, y values, stayed up)
        Each controller's map, as :func:`plot_region_of_attraction` takes it;
        each panel is titled with its label and how many starts it kept.
    path, x_name, y_name, x_unit, y_unit, degrees, title, width, height, dpi
        As for :func:`plot_region_of_attraction`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if not maps:
        raise VizError("regions side by side need at least one map")
    fig = _figure(width, height, dpi)
    axes = np.atleast_1d(fig.subplots(1, len(maps), sharey=True))
    for ax, (label, (xv, yv, ok)) in zip(axes, maps.items(), strict=True):
        kept = int(np.sum(np.asarray(ok, bool)))
        _region_axes(fig, ax, xv, yv, ok, x_name=x_name, y_name=y_name, x_unit=x_unit,
                     y_unit=y_unit, degrees=degrees,
                     title=f"{label}: {kept} of {np.size(ok)} starts kept")
    if title:
        _title(fig, title)
    return _finish(fig, path)


def _region_axes(fig: Any, ax: Any, x_values: Sequence[float] | np.ndarray,
                 y_values: Sequence[float] | np.ndarray, stayed_up: Sequence[bool] | np.ndarray,
                 *, x_name: str, y_name: str, x_unit: str, y_unit: str, degrees: bool,
                 title: str) -> None:
    """One region-of-attraction map on *ax*: cells for a full grid, else points."""
    xv = np.asarray(x_values, float).reshape(-1)
    yv = np.asarray(y_values, float).reshape(-1)
    ok = np.asarray(stayed_up, bool).reshape(-1)
    if not (len(xv) == len(yv) == len(ok)) or len(xv) == 0:
        raise VizError(
            f"a region-of-attraction map needs as many x values ({len(xv)}), y values ({len(yv)}) "
            f"and outcomes ({len(ok)}), at least one"
        )
    fx, ux = display_unit(x_unit, degrees=degrees)
    fy, uy = display_unit(y_unit, degrees=degrees)
    xv, yv = fx * xv, fy * yv
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    cmap = ListedColormap(["#f4a6a6", "#8fd19e"])
    xs, ys = np.unique(xv), np.unique(yv)
    if len(xs) * len(ys) == len(xv) and len(xs) > 1 and len(ys) > 1:
        grid = np.full((len(ys), len(xs)), np.nan)
        grid[np.searchsorted(ys, yv), np.searchsorted(xs, xv)] = ok
        ax.pcolormesh(_edges(xs), _edges(ys), grid, cmap=cmap, vmin=0, vmax=1, shading="flat")
        ax.legend(handles=[Patch(color=cmap(1), label=f"recovered ({ok.sum()})"),
                           Patch(color=cmap(0), label=f"fell ({(~ok).sum()})")],
                  loc="upper right", fontsize="small")
    else:
        ax.scatter(xv[ok], yv[ok], color="#2e9e4f", s=14, marker="o", label=f"recovered ({ok.sum()})")
        ax.scatter(xv[~ok], yv[~ok], color="#d1263b", s=14, marker="x", label=f"fell ({(~ok).sum()})")
        ax.legend(loc="upper right", fontsize="small")
    ax.plot([0], [0], marker="+", color="#111111", ms=10, ls="none")
    ax.set_xlabel(axis_label(f"initial {x_name}", ux))
    ax.set_ylabel(axis_label(f"initial {y_name}", uy))
    ax.set_title(_wrap(fig, title), fontsize="medium")


def _edges(centres: np.ndarray) -> np.ndarray:
    mid = (centres[1:] + centres[:-1]) / 2
    return np.concatenate([[centres[0] - (mid[0] - centres[0])], mid,
                           [centres[-1] + (centres[-1] - mid[-1])]])


def _z_plane(ax: Any, xlim: tuple[float, float], ylim: tuple[float, float]) -> None:
    s = np.linspace(0, 2 * math.pi, 2000)
    ax.plot(np.cos(s), np.sin(s), color="#999999", lw=0.8, label="unit circle (stability limit)")
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("real part of z")
    ax.set_ylabel("imaginary part of z")


def plot_poles(
    source: Any,
    path: str | Path | None = None,
    *,
    discrete: bool | None = None,
    title: str | None = None,
    width: float = 5.5,
    height: float = 4.5,
    dpi: float = 100.0,
) -> Any:
    """Pole map: open loop, state feedback and estimator.

    Parameters
    ----------
    source : equilibrist.control.Design or mapping
        A design (its open-loop, state-feedback and estimator poles), or a
        mapping of label to an array of poles.
    path : str or pathlib.Path, optional
        Save the figure there.
    discrete : bool, optional
        Poles in the z-plane (with the unit circle) rather than the
        s-plane; a design says it itself.
    title : str, optional
        Figure title.
    width, height, dpi : float
        Figure size and resolution.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if isinstance(source, Mapping):
        sets = {str(k): np.atleast_1d(np.asarray(v, complex)) for k, v in source.items()}
        is_discrete = bool(discrete)
        default_title = "poles"
    elif hasattr(source, "poles") and hasattr(source, "estimator_poles"):
        is_discrete = bool(source.is_discrete) if discrete is None else bool(discrete)
        sets = {
            "open loop": np.asarray(source.open_loop_poles, complex),
            "state feedback (LQR)": np.asarray(source.poles, complex),
            "estimator (Kalman)": np.asarray(source.estimator_poles, complex),
        }
        rate = f", sampled at {source.rate:g} Hz" if source.is_discrete else ""
        default_title = f"poles of {source.system_key}{rate}"
    else:
        raise VizError(
            f"plot_poles needs a Design or a mapping of label to poles, got {type(source).__name__}"
        )
    if not any(len(v) for v in sets.values()):
        raise VizError("no poles to plot")
    everything = np.concatenate([v for v in sets.values() if len(v)])
    if is_discrete:
        # The whole unit circle, and a close-up of the poles (at a high
        # sample rate they crowd near z = 1).
        fig = _figure(width * 1.8, height, dpi)
        whole, close = fig.subplots(1, 2)
        reach = max(1.1, float(np.abs(everything).max()) * 1.08)
        _z_plane(whole, (-reach, reach), (-reach, reach))
        lo, hi = everything.real.min(), everything.real.max()
        half = max(float(hi - lo), 2 * float(np.abs(everything.imag).max()), 1e-4) * 0.6
        mid = (lo + hi) / 2
        _z_plane(close, (mid - half, mid + half), (-half, half))
        close.set_title("close-up", fontsize="small")
        panels = [whole, close]
    else:
        fig = _figure(width, height, dpi)
        ax = fig.add_subplot()
        re, im = everything.real, everything.imag
        span = max(float(np.abs(re).max()), float(np.abs(im).max()), 1e-3) * 1.12
        left = min(float(re.min()) * 1.12, -0.1 * span)
        right = max(float(re.max()) * 1.12, 0.1 * span)
        ax.axvspan(0, right, color="#d1263b", alpha=0.06, lw=0)
        ax.axvline(0, color="#999999", lw=0.8)
        ax.set_xlim(left, right)
        top = max(float(np.abs(im).max()) * 1.15, 0.1 * span)
        ax.set_ylim(-top, top)
        ax.set_xlabel("real part [1/s]")
        ax.set_ylabel("imaginary part [rad/s]")
        ax.text(0.99, 0.02, "unstable", transform=ax.transAxes, ha="right", va="bottom",
                fontsize="x-small", color="#d1263b")
        panels = [ax]
    markers = ["x", "o", "D", "s", "^", "v"]
    colors = ["#d1263b", "#1f5fa8", "#e8871e", "#2e9e4f", "#9b30c8", "#555555"]
    for ax in panels:
        ax.axhline(0, color="#999999", lw=0.8)
        for k, (label, poles) in enumerate(sets.items()):
            if not len(poles):
                continue
            filled = markers[k % len(markers)] in "x+"
            ax.plot(poles.real, poles.imag, ls="none", marker=markers[k % len(markers)], ms=7,
                    mec=colors[k % len(colors)], mfc=colors[k % len(colors)] if filled else "none",
                    mew=1.5, label=label)
        ax.grid(alpha=0.3)
    _legend(fig, panels)
    _title(fig, title or default_title)
    return _finish(fig, path)


def plot_batch(batch: Any, path: str | Path | None = None, *, degrees: bool = True,
               title: str | None = None, dpi: float = 100.0, system: System | None = None) -> Any:
    """The picture of a batch of runs (``equilibrist.sim.BatchResult``).

    With the runs' trajectories (a batch run with ``record=True``): the
    Monte-Carlo fan (:func:`plot_fan`). Without them (a saved batch): the
    outcome of each run over what varied between runs, initial states first,
    then parameters; two varied quantities give a region-of-attraction map
    (:func:`plot_region_of_attraction`), one gives the peak input against
    it, none the peak input of each run.

    Parameters
    ----------
    batch : equilibrist.sim.BatchResult or MonteCarloResult or RegionOfAttraction
        The batch (a result that holds one in ``.batch`` is unwrapped).
    path : str or pathlib.Path, optional
        Save the figure there.
    degrees : bool
        Show angles in degrees.
    title : str, optional
        Figure title.
    dpi : float
        Resolution.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from equilibrist.sim.batch import BatchResult, MonteCarloResult, RegionOfAttraction
    from equilibrist.viz._adapt import system_of

    if isinstance(batch, MonteCarloResult | RegionOfAttraction):
        batch = batch.batch
    if not isinstance(batch, BatchResult):
        raise VizError(f"cannot plot a {type(batch).__name__} as a batch: expected a BatchResult "
                       "(equilibrist.sim.simulate_batch, BatchResult.load)")
    if batch.trajectories is not None:
        return plot_fan([batch.run(i) for i in range(batch.runs)], path, degrees=degrees,
                        title=title, dpi=dpi)
    system = system_of(batch.system, digest=batch.system_digest, system=system, source="the batch")
    units = {p.name: p.unit for p in system.spec.all_parameters}
    units.update(zip(system.state_names, system.state_units, strict=True))
    varied: list[tuple[str, np.ndarray]] = []
    for j, n in enumerate(batch.state_names):
        if np.ptp(batch.x0[:, j]) > 0:
            varied.append((n, batch.x0[:, j]))
    for j, n in enumerate(batch.parameter_names):
        if np.ptp(batch.params[:, j]) > 0:
            varied.append((n, batch.params[:, j]))
    ok = ~np.asarray(batch.fell, bool)
    runs = len(ok)
    head = title or (f"{system.spec.title or batch.system}: {int(ok.sum())} of {runs} "
                     "runs stayed up")
    if len(varied) >= 2:
        (xn, xv), (yn, yv) = varied[:2]
        return plot_region_of_attraction(xv, yv, ok, path, x_name=xn, y_name=yn,
                                         x_unit=units.get(xn, ""), y_unit=units.get(yn, ""),
                                         degrees=degrees, title=head, dpi=dpi)
    fig = _figure(5.5, 4.0, dpi)
    ax = fig.add_subplot()
    peak = np.asarray(batch.peak_input, float).reshape(runs, -1)
    if varied:
        xn, xv = varied[0]
        f, unit = display_unit(units.get(xn, ""), degrees=degrees)
        x = f * xv
        ax.set_xlabel(axis_label(f"initial {xn}" if xn in batch.state_names else xn, unit))
    else:
        x = np.arange(runs, dtype=float)
        ax.set_xlabel("run")
    y = peak[:, 0] if peak.shape[1] else np.zeros(runs)
    u_unit = system.input_units[0] if system.n_inputs else ""
    ax.scatter(x[ok], y[ok], color="#2e9e4f", s=14, marker="o", label=f"stayed up ({ok.sum()})")
    ax.scatter(x[~ok], y[~ok], color="#d1263b", s=14, marker="x", label=f"fell ({(~ok).sum()})")
    ax.set_ylabel(axis_label(f"peak {system.input_names[0]}" if system.n_inputs else "peak input",
                             u_unit))
    ax.grid(alpha=0.3)
    ax.legend(fontsize="small")
    ax.set_title(_wrap(fig, head), fontsize="medium")
    return _finish(fig, path)
