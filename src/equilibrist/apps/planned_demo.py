"""The demo's planned swing-up: planned by trajectory optimization, tracked by the time-varying LQR.

For the systems of :data:`PLANNED`, from the energy-shaping demo's hanging start (the same
seed): the swing-up planned as ``equilibrist trajopt`` plans it (within the task's state
bounds less their margin), tracked by ``--controller tvlqr`` with the rig's noise, compared
with the energy-shaping run. Writes ``planned_swingup.gif`` and ``planned_swingup.png``
(the plan, dashed, against the tracked run). Needs CasADi
(``pip install 'equilibrist[trajopt]'``); without it the section gets a note instead.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.viz.report import Image

if TYPE_CHECKING:
    from equilibrist.control.nonlinear import NonlinearController
    from equilibrist.control.trajopt import Trajectory
    from equilibrist.numeric.system import System
    from equilibrist.sim.result import SimResult

#: Seed of the hanging start: the energy-shaping demo's (the same start).
SEED = 7
#: The systems shown and the planned duration of each swing-up [s] (as bench/bench_tracking.py).
PLANNED = {"acrobot": 4.0, "cartpole": 4.0, "furuta": 4.0}
#: Collocation intervals of the plan.
KNOTS = 60
#: Length of the tracked run shown [s]: the plan and two seconds of balance (an animation's
#: frames are the demo's dearest part).
RUN_SECONDS = 6.0


@dataclass(frozen=True)
class PlannedRun:
    """The plan, its tracker, the tracked run and the energy-shaping run of the same start."""

    trajectory: Trajectory
    controller: NonlinearController  # the tvlqr
    tracked: SimResult
    energy: SimResult  # of the energy-shaping swing-up
    plan_seconds: float  # wall time of the plan (the solve and its setup)
    balanced_at: float | None  # tracked run: balanced from then to the end [s]
    energy_balanced_at: float | None


def balanced_from(system: System, run: SimResult) -> float | None:
    """The time from which *run* stays balanced to its end (the batch's criterion:
    :func:`equilibrist.tasks.balance_box`), None when it does not end balanced."""
    from equilibrist.tasks import balance_box, in_box

    if run.fell or not run.n_rows:
        return None
    inside = in_box(run.states, np.asarray(run.x_op, dtype=float), balance_box(system))
    if not inside[-1]:
        return None
    out = np.nonzero(~inside)[0]
    return float(run.time[0] if out.size == 0 else run.time[min(out[-1] + 1, run.n_rows - 1)])


def planned_run(system: System, *, duration: float | None = None,
                energy: SimResult | None = None) -> PlannedRun:
    """Plan, track and compare (see the module docstring) with *energy*, the energy-shaping
    demo's run (:func:`equilibrist.apps.swingup_demo.energy_run`, made here when not given);
    raises ``DesignError`` without CasADi or when the plan does not converge."""
    from equilibrist.control.design import design
    from equilibrist.control.trajopt import plan
    from equilibrist.control.tvlqr import tvlqr
    from equilibrist.errors import DesignError
    from equilibrist.sim.noise import Noise
    from equilibrist.sim.run import simulate
    from equilibrist.tasks import get_task, planning_bounds

    task = get_task(system, "swingup")
    x0 = task.draw_initial(np.random.default_rng(SEED))
    seconds = duration or min(task.duration, RUN_SECONDS)
    began = time.perf_counter()
    traj = plan(system, start=x0, goal=task.x_op, knots=KNOTS,
                duration=PLANNED.get(system.name, 4.0), bounds=planning_bounds(task))
    plan_seconds = time.perf_counter() - began
    if not traj.converged:
        raise DesignError(f"the plan of {system.key}'s swing-up did not converge "
                          f"({traj.iterations} iterations)")
    d = design(system, rate=task.rate)
    ctrl = tvlqr(system, traj, rate=float(d.rate or task.rate), Q=d.Q, R=d.R, S_end=d.S, K_end=d.K,
                 x_op=d.plant.x0, u_op=d.plant.u0)
    noise = Noise.from_spec(system, outputs=ctrl.output_names, rate=ctrl.rate)
    tracked = simulate(system, ctrl, duration=seconds, x0=x0, region=task.region, noise=noise,
                       seed=SEED)
    if energy is None:  # the energy-shaping run of the demo beside it (the same start, seed)
        from equilibrist.apps.swingup_demo import energy_run

        energy, _ctrl = energy_run(system, duration=duration)
    return PlannedRun(traj, ctrl, tracked, energy, plan_seconds, balanced_from(system, tracked),
                      balanced_from(system, energy))


def plot_planned(system: System, pr: PlannedRun, path: str | Path) -> Path:
    """The plan (dashed) against the tracked run: each coordinate and each input over time."""
    from equilibrist.control.tvlqr import plan_samples
    from equilibrist.viz.plot_common import (
        LIMIT,
        _figure,
        _finish,
        _title,
        axis_label,
        display_unit,
    )

    run = pr.tracked
    m = system.n_inputs
    t_plan, xs, us = plan_samples(pr.controller)
    coords = [i for i, s in enumerate(system.state_names) if not s.endswith("_dot")]
    rows = len(coords) + m
    fig = _figure(8.0, 1.6 * rows + 0.9)
    axes = fig.subplots(rows, 1, sharex=True, squeeze=False)[:, 0]
    for ax, i in zip(axes, coords, strict=False):
        f, unit = display_unit(system.state_units[i])
        ax.plot(run.time, f * run.states[:, i], color="#1f5fa8", lw=1.5, label="tracked (noisy rig)")
        ax.plot(t_plan, f * xs[:, i], color="#111111", lw=1.2, ls="--", label="plan")
        ax.set_ylabel(axis_label(system.state_names[i], unit))
    low, high = system.input_limits
    for j in range(m):
        ax = axes[len(coords) + j]
        ax.plot(run.time, run.applied[:, j], color="#2e9e4f", lw=1.2, label="input applied")
        ax.plot(t_plan, us[:, j], color="#111111", lw=1.2, ls="--", label="plan")
        for v in (low[j], high[j]):
            ax.axhline(float(v), **LIMIT)
        ax.set_ylabel(axis_label(system.input_names[j], system.input_units[j]))
    axes[-1].set_xlabel("time [s]")
    for ax in axes:
        ax.axvline(pr.trajectory.duration, color="#999999", lw=0.8, ls=":")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize="small", frameon=False)
    _title(fig, f"{system.spec.title}: the planned swing-up (dashed) and the time-varying LQR "
                f"tracking it; the plan ends at the dotted line, the balancing LQR takes over")
    _finish(fig, path)
    return Path(path)


def _when(t: float | None, run: SimResult) -> str:
    if t is not None:
        return f"balanced from {t:.2f} s"
    return f"not balanced at the end of its {round(float(run.time[-1])):d} s run"


def caption(system: System, pr: PlannedRun) -> str:
    """The caption of the two pictures: plan duration, solve time, times to balance."""
    from equilibrist.tasks import get_task

    traj = pr.trajectory
    bounds = (" within 70 % of its track," if "x" in dict(get_task(system, "swingup").region)
              else "")
    return (f"Planned swing-up: {traj.duration:g} s planned by trajectory optimization "
            f"(Hermite-Simpson, {traj.knots} intervals,{bounds} IPOPT solved it in "
            f"{traj.solve_time:.2f} s of CPU, {traj.iterations} iterations, {pr.plan_seconds:.1f} s "
            f"with its setup) and tracked by the time-varying LQR with sensor and process noise: "
            f"{_when(pr.balanced_at, pr.tracked)}; the energy-shaping swing-up from the same "
            f"start: {_when(pr.energy_balanced_at, pr.energy)} (balanced as batch counts it: "
            "every angle within 0.1 rad of upright and its rate under 0.5 rad/s, to the end).")


def planned_images(system: System, folder: Path, slug: str, notes: list[str], *, width: int,
                   height: int, fps: float, max_frames: int | None = None,
                   progress: bool = False, duration: float | None = None,
                   energy: SimResult | None = None) -> list[Image]:
    """The planned swing-up's animation and plot (``folder/planned_swingup.gif`` and
    ``.png``) as the report's images; none, and a line in *notes*, without CasADi or
    when the plan fails."""
    from equilibrist.errors import DesignError
    from equilibrist.viz.animation import animate_result

    if system.name not in PLANNED:
        return []
    try:
        pr = planned_run(system, duration=duration, energy=energy)
    except DesignError as exc:
        notes.append(f"No planned swing-up: {exc}.")
        return []
    animate_result(pr.tracked, folder / "planned_swingup.gif", system=system, width=width,
                   height=height, fps=fps, max_frames=max_frames, progress=progress)
    plot_planned(system, pr, folder / "planned_swingup.png")
    text = caption(system, pr)
    return [Image(f"{slug}/planned_swingup.gif", text),
            Image(f"{slug}/planned_swingup.png", "The plan (dashed) against the tracked run: "
                  "the coordinates and the input over time (limits red dashed).", wide=True)]


__all__ = ["KNOTS", "PLANNED", "SEED", "PlannedRun", "balanced_from", "caption",
           "planned_images", "planned_run", "plot_planned"]
