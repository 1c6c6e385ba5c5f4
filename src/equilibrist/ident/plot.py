"""The picture of a fit: each measured output against the fitted model's replay."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from equilibrist.ident.result import Identification


def plot_fit(result: Identification, path: str | Path) -> Path:
    """Plot measured and replayed outputs, and the residuals, to *path* (.png or .svg).

    The replay is the shooting stage's: each segment integrated from its
    estimated initial state with the logged input, at the final parameters.
    """
    from matplotlib.figure import Figure

    from equilibrist.viz.output import FIGURE_FORMATS, check_suffix, save_figure

    p = check_suffix(path, FIGURE_FORMATS, "--plot")
    ny = len(result.output_names)
    fig = Figure(figsize=(10, 2.6 * ny + 0.6), dpi=100, layout="constrained")
    axes = fig.subplots(ny, 2, squeeze=False, width_ratios=(3, 1.2))
    t = result.time
    for j, name in enumerate(result.output_names):
        fit = result.outputs[j]
        ax = axes[j, 0]
        ax.plot(t, result.measured[:, j], ".", ms=2, color="0.55", label="measured")
        ax.plot(t, result.replayed[:, j], "-", lw=1.0, color="C0", label="replayed (fitted model)")
        ax.set_ylabel(f"{name} [{fit.unit}]")
        ax.set_title(f"{name}: NRMSE {fit.nrmse:.3f} ({fit.fit_percent:.1f} % fit)", fontsize=9)
        ax.grid(alpha=0.3)
        if j == 0:
            ax.legend(loc="upper right", fontsize=8)
        res = result.measured[:, j] - result.replayed[:, j]
        axr = axes[j, 1]
        axr.plot(t, res, lw=0.6, color="C3")
        axr.axhline(0.0, color="0.3", lw=0.6)
        band = 2.0 * fit.sensor_std
        axr.fill_between([t[0], t[-1]], -band, band, color="C2", alpha=0.15, label="2 sensor std")
        axr.set_title(f"residual ({'white' if fit.white else 'not white'}, "
                      f"p = {fit.ljung_box_p:.2f})", fontsize=9)
        axr.grid(alpha=0.3)
        if j == 0:
            axr.legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("t [s]")
    axes[-1, 1].set_xlabel("t [s]")
    est = ", ".join(
        f"{e.name} = {e.value:.4g}" + (f" +- {e.std_error:.2g}" if np.isfinite(e.std_error) else "")
        for e in result.estimates
    )
    fig.suptitle(f"{result.system}: {est}\n{result.method['name']}; replayed in "
                 f"{result.method['segments']} segments of {result.method['segment_seconds']:g} s",
                 fontsize=10)
    return save_figure(fig, p)


__all__ = ["plot_fit"]
