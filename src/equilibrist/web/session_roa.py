"""The playground's region of attraction; a base of :class:`equilibrist.web.session.Session`.

The slice of the loop in force, estimated from the real loop as ``equilibrist roa``
estimates it (its default slice, with a budget that answers in a second or two: no noise,
one thread), and for LQR and LQG the certified level of the LQR, which follows in its own
message; computed off the live loop's thread (:class:`RoaJob`), a result superseded by a
change of system, controller or setting dropped.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, TypeVar

import numpy as np

from equilibrist.errors import EquilibristError
from equilibrist.web.protocol import OFF, kind_name
from equilibrist.web.runners import planned
from equilibrist.web.session_design import SessionError, Settings, label
from equilibrist.web.session_loop import _Loop

if TYPE_CHECKING:
    from equilibrist.control.design_record import Design
    from equilibrist.numeric.system import System
    from equilibrist.sim.roa import SliceEstimate

_T = TypeVar("_T")

#: The slice's first grid (``(GRID + 1)^2`` runs), its most runs, and seconds per run.
GRID = 16
MAX_SAMPLES = 1500
DURATION = 3.0
#: The same for a controller that runs in Python (the MPC: tens of milliseconds a run).
SLOW_GRID = 4
SLOW_MAX_SAMPLES = 60
#: Boxes of the certificate's branch-and-bound.
MAX_BOXES = 40_000
#: Digits of the slice's points sent to the page.
DIGITS = 5


class Superseded(Exception):
    """A computation's request was superseded (another system, controller or setting; a
    closed page)."""


@dataclass(eq=False)
class RoaJob:
    """One request's computation: its inputs copied from the session when it was asked for,
    so that the thread that runs it reads nothing the live loop changes."""

    id: int
    epoch: int
    system: System
    design: Design
    controller: str
    rate: float
    x_op: np.ndarray
    u_op: np.ndarray
    states: tuple[str, str]
    bounds: tuple[tuple[float, float], tuple[float, float]]
    alive: Callable[[], bool]
    est: SliceEstimate | None = None
    sent: list[dict[str, object]] = field(default_factory=list)

    @property
    def certifies(self) -> bool:
        """Whether the controller is the design's linear loop (its record's
        :attr:`~equilibrist.controllers.kinds.ControllerKind.loop`, LQR or LQG), whose LQR
        has the design's Riccati function ``S`` to certify."""
        from equilibrist.controllers import kinds

        return kinds.get(kind_name(self.controller)).loop is not None

    def check(self, _note: str = "") -> None:
        """Raises :class:`Superseded` when the request was superseded (also the certificate's
        progress callback: it stops there)."""
        if not self.alive():
            raise Superseded(self.id)

    def _controller(self) -> object:
        from equilibrist.controllers import kinds

        record = kinds.get(kind_name(self.controller))
        request = kinds.ControllerRequest.of_design(self.system, self.design)  # the page's own
        return record.make(request)

    def run_slice(self) -> dict[str, object]:
        """The ``roa`` frame of the slice (runs in a worker thread)."""
        from equilibrist.control.linear import LinearController
        from equilibrist.control.nonlinear import NonlinearController
        from equilibrist.sim.roa import estimate_slice

        self.check()
        began = time.perf_counter()
        ctrl = self._controller()
        compiled = isinstance(ctrl, LinearController | NonlinearController)
        rate = self.rate
        est = estimate_slice(self.system, ctrl, self.states, self.bounds, x_op=self.x_op,
                             grid=GRID if compiled else SLOW_GRID,
                             max_samples=MAX_SAMPLES if compiled else SLOW_MAX_SAMPLES,
                             duration=DURATION, rate=rate, physics_step=1.0 / rate,
                             noise=None, workers=1)
        self.est = est
        system = self.system
        idx = [system.state_index(s) for s in self.states]
        return {
            "type": "roa", "status": "slice", "id": self.id, "system": system.key,
            "controller": self.controller, "label": label(self.controller),
            "states": list(self.states), "index": idx,
            "units": [system.state_units[i] for i in idx],
            "bounds": [list(b) for b in self.bounds],
            "x_op": [float(self.x_op[i]) for i in idx],
            "points": np.round(est.points, DIGITS).reshape(-1).tolist(),
            "caught": "".join("1" if c else "0" for c in est.caught.tolist()),
            "samples": est.samples, "levels": est.levels,
            "fraction_caught": est.fraction_caught, "duration": DURATION, "rate": rate,
            "seconds": round(time.perf_counter() - began, 3),
            "certificate": "computing" if self.certifies else None,
        }

    def run_certificate(self) -> dict[str, object]:
        """The ``roa`` frame of the certificate (runs in a worker thread, after the slice)."""
        from equilibrist.control.certify import certify
        from equilibrist.control.lyapunov_rate import CertificateUnavailable
        from equilibrist.sim.roa import levels_of

        self.check()
        d = self.design
        S = np.asarray(d.S, dtype=float)
        out: dict[str, object] = {"type": "roa", "status": "certificate", "id": self.id,
                                  "certificate": None, "note": None}
        try:
            cert = certify(self.system, d.K, S, x_op=self.x_op, u_op=self.u_op,
                           max_boxes=MAX_BOXES, progress=self.check)
        except CertificateUnavailable as exc:
            out["note"] = str(exc)
            return out
        fell = 0
        if self.est is not None:
            inside = levels_of(S, self.x_op, self.est.x0s) <= cert.rho
            fell = int((inside & ~self.est.caught).sum())
        idx = [self.system.state_index(s) for s in self.states]
        out["certificate"] = {
            "rho": cert.rho, "S": S[np.ix_(idx, idx)].tolist(),
            "center": [float(self.x_op[i]) for i in idx], "method": cert.method,
            "assumes": cert.assumes, "limited_by": cert.limited_by, "boxes": cert.boxes,
            "seconds": round(cert.seconds, 3), "counterexamples": fell, "certified": fell == 0,
        }
        if fell:
            out["note"] = (f"{fell} runs of the slice started inside the proven level fell: the "
                           "sampled loop differs from the continuous one the proof assumes")
        return out


class _SessionRoa:
    """The region-of-attraction requests of a :class:`~equilibrist.web.session.Session`."""

    # What these methods read of the session (set by Session).
    system: System
    settings: Settings
    loop: _Loop
    messages: list[dict[str, object]]

    roa_epoch = 0  # bumped by every change that makes a slice another loop's
    roa_ids = 0  # requests made
    roa_shown = False  # whether the page asked for the view since the last change
    roa_running: RoaJob | None = None
    roa_done: list[dict[str, object]] | None = None  # the frames of the slice in force

    def roa_clear(self) -> None:
        """Another system, controller or setting: a slice shown or under way is dropped."""
        self.roa_epoch += 1
        self.roa_done = None
        if self.roa_shown:
            self.roa_shown = False
            self.messages.append({"type": "roa", "status": "cleared"})

    def roa_job(self) -> RoaJob | None:
        """The computation a ``roa`` message asks for; None when the answer is already here
        (sent again) or under way (the page is told so). Raises :class:`SessionError` when
        there is nothing to estimate (the controller off, or one that tracks a plan)."""
        from equilibrist.sim.roa import default_bounds, default_slice

        kind, system = self.settings.controller, self.system
        if kind == OFF:
            raise SessionError("the controller is off: the open loop catches nothing; pick a "
                               "controller to see its region of attraction")
        if planned(kind):
            # The slice is of starts about the operating point, each run from rest there:
            # a tracker's starts are along its plan, which the slice does not draw.
            raise SessionError(
                "the region of attraction shows the starts near the upright that a balancing "
                f"controller catches; {label(kind)} follows a swing-up plan from hanging "
                f"instead: pick {label('lqr')}, which holds the system up once the plan ends, "
                "and press Region of attraction again")
        states = default_slice(system)
        if states is None:
            raise SessionError(f"{system.key} states no fall region: there is no slice to draw")
        x_op = np.array(self.loop.x_op, dtype=float)
        known = default_bounds(system, states, x_op)
        if any(s not in known for s in states):
            raise SessionError(f"{system.key}: the slice {states[0]}, {states[1]} has no "
                               "default bounds")
        self.roa_shown = True
        if self.roa_done is not None:
            self.messages.extend(self.roa_done)
            return None
        running = self.roa_running
        if running is not None and running.epoch == self.roa_epoch:
            self.messages.append({"type": "roa", "status": "computing", "id": running.id,
                                  "states": list(running.states)})
            return None
        self.roa_ids += 1
        epoch = self.roa_epoch
        job = RoaJob(self.roa_ids, epoch, system, self.loop.design, kind,
                     float(self.settings.rate), x_op,
                     np.array(self.loop.u_op, dtype=float), states,
                     (known[states[0]], known[states[1]]),
                     alive=lambda: self.roa_epoch == epoch)
        self.roa_running = job
        self.messages.append({"type": "roa", "status": "computing", "id": job.id,
                              "states": list(states)})
        return job

    def roa_deliver(self, job: RoaJob, message: dict[str, object], last: bool) -> bool:
        """Queue *job*'s *message* for the page, unless the job was superseded (False)."""
        if job.epoch != self.roa_epoch:
            return False
        self.messages.append(message)
        job.sent.append(message)
        if last:
            self.roa_running = None
            if message["status"] != "failed":
                self.roa_done = list(job.sent)
        return True


#: Held by the computation of a slice, and of a certificate: one of each at a time, whichever
#: the session, so that the live loops keep the other cores (and a slice never waits for a
#: certificate, which takes longer and stops only at its checks).
_SLICE_LOCK = threading.Lock()
_CERTIFICATE_LOCK = threading.Lock()


async def _in_thread(fn: Callable[[], _T], lock: threading.Lock) -> _T:
    """``fn()`` in a thread of its own, after the computations before it that hold *lock*.

    A daemon thread: a computation under way does not hold up the server's
    exit (its page is gone; the job stops at its next check anyway).
    """
    loop = asyncio.get_running_loop()
    future: asyncio.Future[_T] = loop.create_future()

    def settle(outcome: Callable[[], None]) -> None:
        if not future.done():
            outcome()  # the future's set_result or set_exception

    def run() -> None:
        outcome: Callable[[], None]
        with lock:
            try:
                value = fn()
            except Exception as exc:
                outcome = partial(future.set_exception, exc)
            else:
                outcome = partial(future.set_result, value)
        with contextlib.suppress(RuntimeError):  # the server's loop closed meanwhile
            loop.call_soon_threadsafe(settle, outcome)

    threading.Thread(target=run, name="equilibrist-roa", daemon=True).start()
    return await future


async def compute_roa(session: _SessionRoa, job: RoaJob) -> None:
    """Compute *job*'s slice, then its certificate, each in a thread of its own, and
    queue their ``roa`` frames for the stream; a job superseded meanwhile (another system,
    controller or setting, a closed page) stops at its next check and sends nothing."""
    failed: str | None = None
    try:
        message = await _in_thread(job.run_slice, _SLICE_LOCK)
        last = not job.certifies
        if session.roa_deliver(job, message, last) and not last:
            message = await _in_thread(job.run_certificate, _CERTIFICATE_LOCK)
            session.roa_deliver(job, message, True)
    except Superseded:
        pass
    except EquilibristError as exc:
        failed = str(exc)
    except Exception as exc:  # a bug must not take the session down; the page shows it
        failed = f"the region of attraction could not be computed: {type(exc).__name__}: {exc}"
    if failed is not None:
        session.roa_deliver(job, {"type": "roa", "status": "failed", "id": job.id,
                                  "message": failed}, True)


__all__ = ["DURATION", "GRID", "MAX_BOXES", "MAX_SAMPLES", "RoaJob", "Superseded",
           "compute_roa"]
