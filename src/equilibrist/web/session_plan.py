"""The playground's planned swing-up; a base of :class:`equilibrist.web.session.Session`.

A kind that tracks a plan (its record is
:attr:`~equilibrist.controllers.kinds.ControllerKind.planned`) is built on a swing-up planned
from the session's hanging start, off the live loop's thread (:class:`PlanJob`), while the
run holds there (``plan`` frame ``planning``); then the run starts at the plan's start
(``ready``) and each frame carries ``ghost``, the drawing's moving shapes at the plan's
state, until the balancing LQR takes over. A plan that fails is an ``error`` frame and a
``plan`` frame ``failed``, the controller off. A retune that leaves the plant as it was
keeps the plan and its time; a changed plant plans again. The behaviour the page shows:
``docs/playground.md``, "Planned swing-up".
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.errors import EquilibristError
from equilibrist.web.runners import PlanRunner, Runner, planned
from equilibrist.web.session_design import Settings, describe_design
from equilibrist.web.session_loop import _Loop
from equilibrist.web.session_output import _SessionOutput, wire_points
from equilibrist.web.session_roa import Superseded, _in_thread

if TYPE_CHECKING:
    from equilibrist.control.design_record import Design
    from equilibrist.control.trajopt import Trajectory
    from equilibrist.numeric.system import System
    from equilibrist.sim.steps import PlantSteps

#: Collocation intervals of the plan.
KNOTS = 60
#: Planned duration [s] of a system without one in ``planned_demo.PLANNED``.
DEFAULT_DURATION = 5.0
#: Plans kept per session (by plant and start).
CACHE = 4
#: What a kept plan is looked up by: the plant's parameters, the start, the duration.
PlanKey = tuple[tuple[tuple[str, float], ...], tuple[float, ...], float]


def plant_key(system: System) -> tuple[tuple[str, float], ...]:
    """What a plan depends on of the plant: its parameters (the input limits among them)."""
    return tuple(sorted((k, float(v)) for k, v in system.params.items()))


@dataclass(eq=False)
class PlanJob:
    """One plan's computation: its inputs copied from the session when it was asked for."""

    id: int
    epoch: int
    kind: str
    system: System
    design: Design
    start: np.ndarray
    goal: np.ndarray
    bounds: dict[str, tuple[float, float]]
    duration: float
    cache: dict[PlanKey, Trajectory]
    alive: Callable[[], bool]

    def check(self) -> None:
        if not self.alive():
            raise Superseded(self.id)

    @property
    def key(self) -> PlanKey:
        return (plant_key(self.system), tuple(np.round(self.start, 12).tolist()), self.duration)

    def run(self) -> tuple[Trajectory, PlanRunner, float]:
        """The trajectory, its tracker and the seconds the plan took (in a worker thread)."""
        from equilibrist.control.trajopt import plan
        from equilibrist.web.runners import build_plan_runner

        self.check()
        began = time.perf_counter()
        traj = self.cache.get(self.key)
        if traj is None:
            traj = plan(self.system, start=self.start, goal=self.goal, knots=KNOTS,
                        duration=self.duration, bounds=self.bounds)
            if not traj.converged:
                raise EquilibristError(
                    f"the swing-up plan did not converge ({traj.iterations} iterations, largest "
                    f"defect {traj.max_defect:.3g}): the input limits may be too tight for a "
                    f"{self.duration:g} s swing-up")
            while len(self.cache) >= CACHE:
                self.cache.pop(next(iter(self.cache)))
            self.cache[self.key] = traj
        seconds = time.perf_counter() - began
        self.check()
        return traj, build_plan_runner(self.kind, self.system, self.design, traj), seconds


#: Held while a plan is made: one at a time, whichever the session (the live loops keep the
#: other core).
_PLAN_LOCK = threading.Lock()


class _SessionPlan(_SessionOutput):
    """The planned swing-up of a :class:`~equilibrist.web.session.Session` (its base)."""

    # What these methods read of the session (set by Session).
    rng: np.random.Generator
    design_message: dict[str, object]
    hang_start: np.ndarray | None
    plant: PlantSteps | None

    plan_epoch = 0  # bumped by every change that makes a plan under way another loop's
    plan_ids = 0
    plan_running: PlanJob | None = None
    plan_shown = False  # a plan frame went out since the last clear
    _plan_cache: dict[PlanKey, Trajectory] | None = None

    def reset(self, kick: float = 0.0, *, hang: bool = False) -> None:  # Session's
        raise NotImplementedError

    def _apply_region(self) -> None:  # Session's
        raise NotImplementedError

    @property
    def plan_holding(self) -> bool:
        """Whether the run holds at the hanging start while its plan is made."""
        job = self.plan_running
        return job is not None and job.epoch == self.plan_epoch

    def plan_clear(self) -> None:
        """Another system, or a loop without the plan: a plan under way or shown is dropped."""
        self.plan_epoch += 1
        self.plan_running = None
        if self.plan_shown:
            self.plan_shown = False
            self.messages.append({"type": "plan", "status": "cleared"})

    def plan_installed(self, runner: Runner | None) -> None:
        """A new loop is in force (a redesign): the plan stays when it tracks the same one."""
        previous = self.plan_running
        if not (isinstance(runner, PlanRunner) and previous is None):
            self.plan_clear()

    def plan_for(self, system: System, settings: Settings) -> Trajectory | None:
        """The trajectory a redesign for *settings* builds the tracker on: the one in force
        when the planned kind stays and the plant is the same (None: plan first)."""
        runner = self.loop.runner
        if (planned(settings.controller) and self.settings.controller == settings.controller
                and isinstance(runner, PlanRunner) and runner.kind == settings.controller
                and plant_key(system) == plant_key(self.system)):
            traj: Trajectory = runner.trajectory
            return traj
        return None

    def plan_job(self) -> PlanJob | None:
        """The plan the kind in force needs (None: none needed, or one is under way). Goes
        to the hanging start and holds there until it comes."""
        from equilibrist.apps.planned_demo import PLANNED as DURATIONS
        from equilibrist.tasks import get_task, planning_bounds

        kind, system = self.settings.controller, self.system
        if not planned(kind) or self.loop.runner is not None or self.plan_holding:
            return None
        start = self.hang_start if self.hanging and self.hang_start is not None else None
        self.reset(hang=True)
        if start is not None:
            self.x = np.array(start, dtype=float)
            self.hang_start = self.x.copy()
            self.plant = None
        task = get_task(system, "swingup")
        if self._plan_cache is None:
            self._plan_cache = {}
        self.plan_ids += 1
        epoch = self.plan_epoch
        job = PlanJob(self.plan_ids, epoch, kind, system, self.loop.design,
                      np.array(self.x, dtype=float), np.array(task.x_op, dtype=float),
                      planning_bounds(task), float(DURATIONS.get(system.name, DEFAULT_DURATION)),
                      self._plan_cache, alive=lambda: self.plan_epoch == epoch)
        self.plan_running = job
        self.plan_shown = True
        self.mode, self.mode_since = "planning", 0.0
        self.messages.append({"type": "plan", "status": "planning", "id": job.id,
                              "controller": kind, "duration": job.duration, "knots": KNOTS,
                              "start": job.start.tolist()})
        return job

    def plan_deliver(self, job: PlanJob, result: tuple[Trajectory, PlanRunner, float] | None,
                     error: str | None) -> bool:
        """Put *job*'s tracker in force and start the run at the plan's start, or say why
        there is none (the controller is then off); False when the job was superseded."""
        if job.epoch != self.plan_epoch:
            return False
        self.plan_running = None
        if result is None:
            s = self.settings
            self.settings = Settings("off", s.rate, s.noise, s.limit, s.scales, s.params, s.rig)
            self.mode = None
            self._apply_region()
            text = f"no plan to track: {error}; the controller is off"
            self.messages.append({"type": "plan", "status": "failed", "id": job.id,
                                  "controller": "off", "message": text})
            self.messages.append({"type": "error", "message": text})
            return True
        traj, runner, seconds = result
        d = self.loop.design
        self.loop = _Loop(d, self.system, previous=self.loop, runner=runner, x_estimate=self.xhat)
        self.reset(hang=True)
        self.x = np.array(job.start, dtype=float)
        self.hang_start = self.x.copy()
        self.plant = None
        self.mode, self.mode_since = runner.mode, 0.0
        self.design_message = describe_design(d, job.kind, 0.0, runner, seconds)
        self.messages.append(self.design_message)
        self.messages.append({
            "type": "plan", "status": "ready", "id": job.id, "controller": job.kind,
            "duration": traj.duration, "knots": traj.knots, "solve_time": traj.solve_time,
            "iterations": traj.iterations, "solver": traj.solver, "cost": traj.cost,
            "peak_input": traj.peak_input, "max_defect": traj.max_defect,
            "seconds": round(seconds, 3), "start": job.start.tolist(),
            "bounds": {k: list(v) for k, v in job.bounds.items()}})
        return True

    # -- the ghost ---------------------------------------------------------------------------
    def ghost(self) -> tuple[list[dict[str, object]], float] | None:
        """The drawing's moving shapes at the plan's state at the plan's time, and that time
        (None when no plan runs)."""
        runner = self.loop.runner
        if not isinstance(runner, PlanRunner) or self.settings.controller != runner.kind:
            return None
        at = runner.plan_state()
        if at is None:
            return None
        keys = runner.ghost_keys
        if keys is None:
            # The shapes the state moves: those that differ between the plan's two ends.
            a = {s.key: np.asarray(s.points, float) for s in self.scene.shapes(runner.xs[0], runner.us[0])}
            b = self.scene.shapes(runner.xs[-1], runner.us[0])
            keys = frozenset(s.key for s in b if s.kind not in ("text", "hline") and (
                s.key not in a or a[s.key].shape != np.shape(s.points)
                or not np.allclose(a[s.key], np.asarray(s.points, float), equal_nan=True)))
            runner.ghost_keys = keys
        out = []
        for s in self.scene.shapes(*at):
            if s.key not in keys:
                continue
            out.append({"key": s.key, "kind": s.kind, "z": s.z, "color": s.color,
                        "width": s.width, "edge": s.edge, "points": wire_points(s.points)})
        return out, runner.tau

    def frame(self) -> dict[str, object]:
        out = super().frame()
        ghost = self.ghost()
        out["plan"] = "planning" if self.plan_holding else (None if ghost is None else "tracking")
        out["ghost"] = None if ghost is None else ghost[0]
        out["plan_t"] = None if ghost is None else round(ghost[1], 4)
        return out


async def compute_plan(session: _SessionPlan, job: PlanJob) -> None:
    """Make *job*'s plan and tracker in a thread of its own and put them in force (or say
    why not); a job superseded meanwhile sends nothing."""
    failed: str | None = None
    result = None
    try:
        result = await _in_thread(job.run, _PLAN_LOCK)
    except Superseded:
        return
    except EquilibristError as exc:
        failed = str(exc)
    except Exception as exc:  # a bug must not take the session down; the page shows it
        failed = f"the plan could not be made: {type(exc).__name__}: {exc}"
    session.plan_deliver(job, result, failed)


__all__ = ["CACHE", "KNOTS", "PlanJob", "compute_plan", "plant_key"]
