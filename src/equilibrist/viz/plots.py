"""Plots of runs and designs: time responses, comparisons, Monte-Carlo fans,
regions of attraction and pole maps.

Every function returns a :class:`matplotlib.figure.Figure` (made without
pyplot, so nothing global changes) and, given *path*, saves it as PNG or
SVG by the suffix. Axes are named with their units; angles are shown in
degrees (``degrees=False`` keeps radians). Runs are read through
:func:`~equilibrist.viz.runs.as_run`, so a simulation result or a
:class:`~equilibrist.viz.runs.Run` made from arrays both work.

The plots of runs over time are in :mod:`equilibrist.viz.plots_runs`, the maps
(regions of attraction, poles) in :mod:`equilibrist.viz.plots_maps`, what they
share (line styles, units, figures) in :mod:`equilibrist.viz.plot_common`.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.viz.output import VizError
from equilibrist.viz.plot_common import (
    _figure,
    _finish,
    _wrap,
    axis_label,
    display_unit,
)
from equilibrist.viz.plots_maps import (
    plot_region_of_attraction,
)
from equilibrist.viz.plots_runs import plot_fan

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from equilibrist.numeric.system import System


def plot_batch(batch: object, path: str | Path | None = None, *, degrees: bool = True,
               title: str | None = None, dpi: float = 100.0,
               system: System | None = None) -> Figure:
    """The picture of a batch of runs (``equilibrist.sim.BatchResult``; a result that holds
    one in ``.batch`` is unwrapped).

    With the runs' trajectories (a batch run with ``record=True``): the
    Monte-Carlo fan (:func:`plot_fan`). Without them (a saved batch): the
    outcome of each run over what varied between runs, initial states first,
    then parameters; two varied quantities give a region-of-attraction map
    (:func:`plot_region_of_attraction`), one gives the peak input against
    it, none the peak input of each run.
    """
    from equilibrist.numeric.lookup import system_for_data
    from equilibrist.sim.batch import MonteCarloResult, RegionOfAttraction
    from equilibrist.sim.batch_result import BatchResult

    if isinstance(batch, MonteCarloResult | RegionOfAttraction):
        batch = batch.batch
    if not isinstance(batch, BatchResult):
        raise VizError(f"cannot plot a {type(batch).__name__} as a batch: expected a BatchResult "
                       "(equilibrist.sim.simulate_batch, BatchResult.load)")
    if batch.trajectories is not None:
        return plot_fan([batch.run(i) for i in range(batch.runs)], path, degrees=degrees,
                        title=title, dpi=dpi)
    system = system_for_data(batch.system, None, digest=batch.system_digest, system=system,
                             source="the batch")
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


__all__ = [
    "plot_batch",
]
