"""Regenerate the README's pictures from the demo's cart-pole run.

    .venv/bin/equilibrist demo cartpole --out /tmp/demo
    .venv/bin/python docs/images/make_images.py /tmp/demo

writes ``cartpole_frame.png`` (one frame of the animation, just after the
push) and ``cartpole_response.png`` (the run's time response) here.
``roa.png`` is ``equilibrist roa cartpole --controller lqr --samples 6000
--physics-step 0.005 --plot docs/images/roa.png``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from equilibrist.sim import SimResult
from equilibrist.viz.frames import FrameRenderer
from equilibrist.viz.plots_runs import plot_response
from equilibrist.viz.runs import as_run


def main(demo: Path) -> None:
    here = Path(__file__).parent
    run = as_run(SimResult.load(demo / "cartpole" / "run.npz"))
    push = next(t for t, label in run.events if label.startswith("push"))
    k = int(np.searchsorted(run.t, push + 0.2))
    frame = FrameRenderer(run.system, states=run.x, inputs=run.u, width=400, height=300)
    label = next(label for t, label in run.events if t == push)
    frame.draw(run.x[k], run.u[k], command=run.u_command[k], t=float(run.t[k]), note=label)
    frame.save(here / "cartpole_frame.png")
    plot_response(run, here / "cartpole_response.png", dpi=72,
                  title="Inverted pendulum on a cart: digital LQG at 200 Hz, noisy sensors, a push at 6 s")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
