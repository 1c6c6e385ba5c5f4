"""Plots over a plane: regions of attraction (alone and side by side) and pole maps."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.viz.output import VizError
from equilibrist.viz.plot_common import (
    _figure,
    _finish,
    _legend,
    _title,
    _wrap,
    axis_label,
    display_unit,
)

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
    from numpy.typing import ArrayLike

    from equilibrist.control.design_record import Design
    from equilibrist.sim.roa_report import RoaReport


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
) -> Figure:
    """Map of the initial conditions (*x_values*, *y_values* of the states *x_name*,
    *y_name*) from which the controller recovers (*stayed_up*): cells when the points form a
    full grid, else a scatter of points.
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
) -> Figure:
    """Regions of attraction of several controllers over the same starts, side by side:
    *maps* holds each controller's map by label, as :func:`plot_region_of_attraction` takes
    it; each panel is titled with its label and how many starts it kept."""
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


def _region_axes(fig: Figure, ax: Axes, x_values: Sequence[float] | np.ndarray,
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


def _z_plane(ax: Axes, xlim: tuple[float, float], ylim: tuple[float, float]) -> None:
    s = np.linspace(0, 2 * math.pi, 2000)
    ax.plot(np.cos(s), np.sin(s), color="#999999", lw=0.8, label="unit circle (stability limit)")
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("real part of z")
    ax.set_ylabel("imaginary part of z")


def plot_poles(
    source: Design | Mapping[str, ArrayLike],
    path: str | Path | None = None,
    *,
    discrete: bool | None = None,
    title: str | None = None,
    width: float = 5.5,
    height: float = 4.5,
    dpi: float = 100.0,
) -> Figure:
    """Pole map: a design's open-loop, state-feedback and estimator poles, or a mapping of
    label to poles; *discrete* draws the z-plane with the unit circle (a design says it
    itself) rather than the s-plane."""
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


def plot_roa_slice(report: RoaReport, path: str | Path | None = None, *,
                   title: str | None = None) -> Figure:
    """The slice of an ``equilibrist roa`` analysis (:class:`~equilibrist.sim.roa_report.RoaReport`):
    each run caught or not, the level of ``dx' S dx`` no run falsifies (dashed) and the
    certified one (solid), cut by the slice (the other states at the operating point)."""
    system, est, x_op = report.system, report.est, report.x_op
    fig = _figure(6.4, 5.2, 110.0)
    ax = fig.add_subplot()
    pts, ok = est.points, est.caught
    ax.scatter(pts[ok, 0], pts[ok, 1], s=3, color="#2a9d8f", label="caught")
    ax.scatter(pts[~ok, 0], pts[~ok, 1], s=3, color="#e76f51", label="not caught")
    i, j = (system.state_index(s) for s in est.states)
    for level, style, label in (
            (report.figures["rho_sampled"], "--", "dx' S dx = rho_sampled (estimate)"),
            (report.rho_certified, "-", "dx' S dx = rho (certified)")):
        if report.S is None or level is None or not math.isfinite(level):
            continue
        sub = np.asarray(report.S, dtype=float)[np.ix_([i, j], [i, j])]
        w, v = np.linalg.eigh(sub)
        t = np.linspace(0.0, 2.0 * np.pi, 400)
        ring = v @ (np.vstack([np.cos(t), np.sin(t)]) * np.sqrt(level / w)[:, None])
        ax.plot(x_op[i] + ring[0], x_op[j] + ring[1], style, color="black", lw=1.2, label=label)
    ax.set_xlim(*est.bounds[0])
    ax.set_ylim(*est.bounds[1])
    ax.set_xlabel(axis_label(est.states[0], system.state_units[i]))
    ax.set_ylabel(axis_label(est.states[1], system.state_units[j]))
    _title(fig, title or f"{system.key}: region of attraction, slice ({est.samples} runs)")
    ax.legend(loc="upper right", fontsize=8, markerscale=3)
    return _finish(fig, path)
