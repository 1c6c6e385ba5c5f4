"""The report's robustness page: RealAIGym's families of the acrobot's balancing LQR.

The catalogue acrobot's LQR at 500 Hz from 0.1 rad off upright, scored as RealAIGym's
robustness benchmark scores a controller (:mod:`equilibrist.study.robustness`): each
parameter at 0.75 to 1.25 of its value, velocity and torque noise, the motor's response,
the measurement's delay and random pushes of the elbow, 932 runs of 10 s on the compiled
batch.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

from equilibrist.viz.report import Image

if TYPE_CHECKING:
    from equilibrist.numeric.system import System

#: The benchmark's control rate [Hz].
RATE = 500.0
#: The runs' start: link 1 0.1 rad past upright, link 2 bent back as much.
START = {"theta1": math.pi + 0.1, "theta2": -0.1}


def robustness_images(system: System, folder: Path, slug: str) -> list[Image]:
    """The scorecard of *system*'s LQR, drawn into ``folder/robustness.png``."""
    from equilibrist.control.design import design
    from equilibrist.control.linear import LinearController
    from equilibrist.study.robustness import robustness
    from equilibrist.viz.plots_robustness import plot_robustness

    lqr = LinearController.from_design(design(system, rate=RATE), kind="lqr")
    card = robustness(system, lqr, x0=START, rate=RATE)
    plot_robustness(card.describe(), folder / "robustness.png")
    scores = ", ".join(f"{name.replace('_', ' ')} {score:.2f}"
                       for name, score in card.scores.items())
    return [Image(f"{slug}/robustness.png",
                  f"RealAIGym's robustness families of the LQR at {RATE:g} Hz, from 0.1 rad "
                  f"off upright, each run 10 s, a success when it ends within 0.35 rad and 1 "
                  f"rad/s of upright (equilibrist robustness): benchmark score "
                  f"{card.benchmark_score:.2f} ({scores}); {card.elapsed:.0f} s for the "
                  "families' runs on the compiled batch.", wide=True)]


__all__ = ["RATE", "START", "robustness_images"]
