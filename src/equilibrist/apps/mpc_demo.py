"""The demo's constrained MPC: where it keeps the cart-pole on its track and the clipped LQR does not.

Both controllers measure the full state and share the design; the LQR's command is clipped
at the input limits, the MPC's respects them by construction. :func:`track_case` starts the
cart at the centre at 2 m/s (the clipped LQR runs off the track, the MPC brakes in time);
:func:`regions` is a grid of starts each controller keeps up and on the track. The tour puts
both into the cart-pole's section; ``bench/bench_mpc.py`` saves the same figure as
``docs/images/mpc_roa.png``.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.viz.report import Image

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from equilibrist.control.linear import LinearController
    from equilibrist.control.mpc import MPC
    from equilibrist.numeric.system import System
    from equilibrist.sim.result import SimResult

#: Sample rate [Hz] and horizon [samples] of the demonstration.
RATE, HORIZON = 50.0, 40
#: The MPC's soft bounds: the track 5 cm inside its end, the pole's fall angle.
TRACK = {"x": (-0.95, 0.95), "theta": (-1.2, 1.2)}
#: Where a run counts as fallen (off the 1 m track, or the pole past 1.2 rad).
REGION = {"x": (-1.0, 1.0), "theta": (-1.2, 1.2)}
#: The start of :func:`track_case`.
CASE = {"x": 0.0, "x_dot": 2.0, "theta": 0.0}
#: Length of each run [s].
DURATION = 4.0


def controllers(system: System) -> tuple[LinearController, MPC]:
    """The clipped LQR and the MPC (a value: ``.runtime()`` runs it) of the demonstration."""
    from equilibrist.control.design import design
    from equilibrist.control.linear import LinearController
    from equilibrist.control.mpc import mpc

    d = design(system, rate=RATE)
    lqr = LinearController.from_design(d, kind="lqr")
    return lqr, mpc(system, design=d, horizon=HORIZON, estimator="state", constraints=TRACK)


def track_case(system: System) -> dict[str, SimResult]:
    """The two runs from :data:`CASE`, labelled for a comparison plot."""
    from equilibrist.sim.run import simulate

    lqr, ctrl = controllers(system)
    runs = {}
    for label, c in (("clipped LQR", lqr), (f"MPC, N = {HORIZON}", ctrl.runtime())):
        runs[label] = simulate(system, c, duration=DURATION, x0=dict(CASE), region=REGION)
    return runs


def regions(system: System, grid: int = 9) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """``speeds, angles, kept``: which starts (cart at the centre, ``grid`` cart speeds
    in +-3 m/s by ``grid`` pole angles in +-0.6 rad) each controller keeps up and on
    the track; ``kept[label]`` is a ``(angles, speeds)`` array of booleans."""
    from equilibrist.sim.run import simulate

    lqr, ctrl = controllers(system)
    speeds = np.linspace(-3.0, 3.0, grid)
    angles = np.linspace(-0.6, 0.6, grid)
    kept = {"clipped LQR": np.zeros((grid, grid), dtype=bool),
            f"MPC, N = {HORIZON}": np.zeros((grid, grid), dtype=bool)}
    for i, th in enumerate(angles):
        for j, v in enumerate(speeds):
            x0 = {"x": 0.0, "x_dot": float(v), "theta": float(th)}
            for label, c in (("clipped LQR", lqr), (f"MPC, N = {HORIZON}", ctrl.runtime())):
                kept[label][i, j] = not simulate(system, c, duration=DURATION, x0=x0,
                                                 region=REGION).fell
    return speeds, angles, kept


def plot_regions(system: System, speeds: np.ndarray, angles: np.ndarray,
                 kept: dict[str, np.ndarray], path: str | Path) -> Figure:
    """Both regions of attraction side by side."""
    from equilibrist.viz.plots_maps import plot_regions_side_by_side

    vv, aa = np.meshgrid(speeds, angles)
    units = dict(zip(system.state_names, system.state_units, strict=True))
    return plot_regions_side_by_side(
        {label: (vv.ravel(), aa.ravel(), ok.ravel()) for label, ok in kept.items()}, path,
        x_name="x_dot", y_name="theta", x_unit=units["x_dot"], y_unit=units["theta"],
        title=f"{system.spec.title} at {RATE:g} Hz, cart at the centre of a 2 m track: "
              "green starts stay up and on it")


def mpc_images(system: System, folder: Path, slug: str, *, grid: int = 9) -> list[Image]:
    """The report's MPC figures for the cart-pole: the track case and both regions."""
    from equilibrist.viz.plots_runs import plot_comparison

    runs = track_case(system)
    (l_label, l_run), (m_label, m_run) = runs.items()

    def outcome(run: SimResult) -> str:
        if run.fell:
            return f"left the region at t = {run.fell_at:.2f} s ({run.fell_state})"
        return f"stayed up, the cart within {np.max(np.abs(run.states[:, 0])):.2f} m"

    plot_comparison(runs, folder / "mpc_track.png", states=["x", "theta"],
                    title=f"{system.spec.title}, cart at 2 m/s towards the end of its track: "
                          f"{l_label} and {m_label}")
    speeds, angles, kept = regions(system, grid)
    plot_regions(system, speeds, angles, kept, folder / "mpc_regions.png")
    counts = ", ".join(f"{label} {int(ok.sum())}" for label, ok in kept.items())
    return [
        Image(f"{slug}/mpc_track.png",
              f"Constrained MPC (horizon {HORIZON} at {RATE:g} Hz, track bound {TRACK['x'][1]} m, "
              f"input limits hard) against the clipped LQR, both on the full state, the cart "
              f"starting at the centre at 2 m/s: the clipped LQR {outcome(l_run)}; the MPC "
              f"{outcome(m_run)}.", wide=True),
        Image(f"{slug}/mpc_regions.png",
              f"Regions of attraction of the same two controllers over {grid * grid} starts "
              f"(cart at the centre; initial cart speed by pole angle); starts kept up and on "
              f"the track: {counts}.", wide=True),
    ]


__all__ = ["CASE", "DURATION", "HORIZON", "RATE", "REGION", "TRACK", "controllers", "mpc_images",
           "plot_regions", "regions", "track_case"]
