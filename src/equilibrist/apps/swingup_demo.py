"""The demo's swing-up: one seeded swing-up from hanging, animated, for each rig that has one
(its default design's swing-up controller, from the task ``swingup``'s start, with noise)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from equilibrist.control.swingup import SwingUpController
    from equilibrist.numeric.system import System
    from equilibrist.sim.result import SimResult

SEED = 7


#: Length of the run [s] (at most; the task's own when shorter).
SECONDS = 8.0


def energy_run(system: System, *,
               duration: float | None = None) -> tuple[SimResult, SwingUpController]:
    """The demo's energy-shaping swing-up of *system*: its default design's swing-up from the
    task ``swingup``'s seeded hanging start, with the design's noise (the SimResult and the
    controller)."""
    from equilibrist.control.design import design
    from equilibrist.control.swingup import swingup
    from equilibrist.sim.noise import Noise
    from equilibrist.sim.run import simulate
    from equilibrist.tasks import get_task

    task = get_task(system, "swingup")
    d = design(system, rate=task.rate)
    x0 = task.draw_initial(np.random.default_rng(SEED))
    ctrl = swingup(system, design=d)
    run = simulate(system, ctrl, duration=duration or min(task.duration, SECONDS), x0=x0,
                   region=task.region, noise=Noise.from_design(d), seed=SEED)
    return run, ctrl


def swingup_animation(system: System, folder: Path, *, width: int, height: int, fps: float,
                      max_frames: int | None = None, progress: bool = False,
                      duration: float | None = None) -> tuple[Path, str, SimResult]:
    """Animate :func:`energy_run` into ``folder/swingup.gif``: the file, a one-line caption
    and the run."""
    from equilibrist.viz.animation import animate_result

    run, ctrl = energy_run(system, duration=duration)
    path = animate_result(run, folder / "swingup.gif", width=width, height=height, fps=fps,
                          max_frames=max_frames, progress=progress)
    law = ctrl.settings.get("law", "")
    if run.fell:
        caption = f"Swing-up ({law} law): left its track at {run.fell_at:.2f} s."
    else:
        caption = (f"Swing-up from hanging ({law} law, energy pumping then the LQR catch), "
                   "with sensor noise; drawn to scale.")
    return path, caption, run
