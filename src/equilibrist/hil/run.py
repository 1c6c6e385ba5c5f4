"""A hardware-in-the-loop run: the simulator plays the plant, the device runs the controller.

The device is a :class:`~equilibrist.control.controller.PythonController`
of the simulation (:class:`DeviceController`): at each sample the simulator
measures the plant (with the rig's sensor noise), sends the measurements
over the link, and applies the device's answer (saturated, held, delayed as
:func:`~equilibrist.sim.run.simulate` does). So a lockstep run is
``simulate`` with the device in place of the simulated controller, sample
for sample, and equals it to the payload's rounding.

``lockstep`` waits for every answer. ``realtime`` paces the plant on the
wall clock at the rig's rate: an answer that is not back before the next
sample is late, and the previous input is held. While it runs, the
simulator's thread asks the system for real-time scheduling (``SCHED_FIFO``),
as a rig's control computer would: a wake-up held back by other programs is a
late sample that is the machine's, not the device's. Where the system refuses
(no privilege), the run goes on at normal priority and its summary says so
(``scheduling``).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import partial
from typing import TYPE_CHECKING, Any, NoReturn, TypedDict, TypeVar

import numpy as np

from equilibrist.control.python_controller import PythonControllerBase
from equilibrist.errors import quote_outside
from equilibrist.hil import protocol as proto
from equilibrist.hil.link import DeviceGone, SerialLink
from equilibrist.hil.protocol import Hello, HILError, ProtocolError
from equilibrist.native.firmware import RT_PRIORITY
from equilibrist.sim.run import StopRun
from equilibrist.sim.signals import as_signal

if TYPE_CHECKING:
    from equilibrist.numeric.system import System
    from equilibrist.sim.result import SimResult

_T = TypeVar("_T")

MODES = ("lockstep", "realtime")
#: How long the host waits for the device's hello answer [s].
HELLO_TIMEOUT = 3.0


@contextmanager
def realtime_priority() -> Iterator[str]:
    """Run the calling thread under ``SCHED_FIFO`` while inside; yield what was granted."""
    setter = getattr(os, "sched_setscheduler", None)
    if setter is None:
        yield "normal (this system has no real-time scheduling)"
        return
    before = os.sched_getscheduler(0), os.sched_getparam(0)
    try:
        setter(0, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))
    except OSError as exc:
        yield f"normal (the system refused real-time priority: {exc.strerror})"
        return
    try:
        yield f"SCHED_FIFO {RT_PRIORITY}"
    finally:
        setter(0, before[0], before[1])


class HILRefused(HILError):
    """The device could not be started: no answer, or another controller (exit status 2)."""


class LinkSummary(TypedDict):
    """The link's figures (:meth:`LinkStats.summary`): milliseconds, microseconds, counts."""

    round_trip_ms: dict[str, float | None]
    round_trips_per_s: float | None
    device_step_us: dict[str, float | None]
    send_delay_ms: dict[str, float | None]
    late: int
    lost: int
    steps: int


@dataclass
class LinkStats:
    """What the link did: round trips, the device's own step times, late and lost answers."""

    round_trip_s: list[float] = field(default_factory=list)
    device_step_us: list[int] = field(default_factory=list)
    # Realtime: how long after its time on the clock each sample was sent (the simulator's own
    # lateness, apart from the link's and the device's).
    send_delay_s: list[float] = field(default_factory=list)
    late: int = 0
    lost: int = 0
    steps: int = 0
    started: float | None = None  # time.perf_counter() at the first step
    ended: float | None = None  # ... at the last answer

    def summary(self) -> LinkSummary:
        rt = np.asarray(self.round_trip_s) * 1e3
        us = np.asarray(self.device_step_us, dtype=float)
        sd = np.asarray(self.send_delay_s) * 1e3

        def q(a: np.ndarray, p: float) -> float | None:
            return float(np.percentile(a, p)) if a.size else None

        wall = (self.ended - self.started) if self.started is not None and self.ended is not None else 0.0
        return {
            "round_trip_ms": {"p50": q(rt, 50), "p99": q(rt, 99), "max": q(rt, 100)},
            "round_trips_per_s": self.steps / wall if wall > 0 else None,
            "device_step_us": {"p50": q(us, 50), "max": q(us, 100)},
            "send_delay_ms": {"p50": q(sd, 50), "p99": q(sd, 99), "max": q(sd, 100)},
            "late": self.late, "lost": self.lost, "steps": self.steps,
        }


class DeviceController(PythonControllerBase):
    """The device on the other end of *link* as the simulation's controller.

    :meth:`connect` exchanges the hellos (a mismatch raises
    :class:`HILRefused`); a fault during the run (no answer, garbage, a
    reset, the port gone) is kept in :attr:`fault` and ends the run
    (:class:`~equilibrist.sim.run.StopRun`) with the samples so far.
    """

    def __init__(self, link: SerialLink, host: Hello, *, outputs: tuple[str, ...],
                 u_op: np.ndarray, mode: str = "lockstep", timeout: float = 1.0,
                 excitation: object = None) -> None:
        if mode not in MODES:
            raise HILError(f"--mode {mode!r}: expected one of {', '.join(MODES)}")
        self.link = link
        self.host = host
        self.device: Hello | None = None
        self.mode = mode
        self.timeout = float(timeout)
        self.rate = host.rate
        self.outputs = outputs
        self.estimate: np.ndarray | None = None
        self.stats = LinkStats()
        self.fault: str | None = None
        self._u_op = np.asarray(u_op, dtype=float)
        # An identification experiment: added by the simulator to the device's command, before
        # the actuator's limits (what the log records as the input that acted).
        self._excitation = None if excitation is None else as_signal(excitation)
        self._held = self._u_op.copy()
        self._seq = 0
        self._t0: float | None = None
        self._missing: set[int] = set()
        self._last_answer = 0.0

    # -- start ----------------------------------------------------------------------
    def connect(self) -> Hello:
        """Exchange the hellos; the device's, when it runs the host's controller."""
        self.link.drain()
        self._seq = (self._seq + 1) & 0xFFFF
        self.link.send(proto.HELLO, self._seq, self.host.pack())
        deadline = time.perf_counter() + HELLO_TIMEOUT
        while True:
            try:
                f = self.link.receive(deadline)
            except ProtocolError as exc:
                raise HILRefused(f"the device on {self.link.port} answered the hello with "
                                 f"garbage: {exc}") from None
            except DeviceGone as exc:
                raise HILRefused(str(exc)) from None
            if f is None:
                raise HILRefused(f"no answer from a device on {self.link.port} within "
                                 f"{HELLO_TIMEOUT:g} s: is the exported program running there "
                                 "(./hil_host PORT, or the sketch built with HIL)?")
            if f.kind == proto.HELLO_REPLY and f.seq == self._seq:
                try:
                    device = Hello.unpack(f.payload)
                except ProtocolError as exc:
                    raise HILRefused(f"the device's hello is not one: {exc}") from None
                problem = self.host.mismatch(device)
                if problem is not None:
                    raise HILRefused(f"the device on {self.link.port} runs another controller: "
                                     f"it has {problem}")
                if device.estimate not in (0, self.host.n):
                    raise HILRefused(f"the device sends {device.estimate} estimate values, "
                                     f"expected 0 or {self.host.n}")
                self.device = device
                return device
            if f.kind == proto.ERROR:
                raise HILRefused(f"the device refused the hello: {_text(f.payload)}")
            # a BOOT frame, or an answer to an earlier session: not the hello's answer

    # -- the PythonController protocol ----------------------------------------------------
    def reset(self) -> None:
        if self.device is None:
            self.connect()
        self._request(proto.RESET, b"", proto.RESET_REPLY, time.perf_counter() + self.timeout,
                      when="resetting the controller")
        self.stats = LinkStats()
        self._held = self._u_op.copy()
        self._t0 = None
        self._missing.clear()
        self.estimate = None
        self.fault = None

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        device = self.device
        assert device is not None  # reset() connects first
        now = time.perf_counter()
        period = 1.0 / self.host.rate
        if self.mode == "realtime":
            if self._t0 is None:
                self._t0 = now - t
                self._last_answer = now
            wait = self._t0 + t - now
            if wait > 0:
                time.sleep(wait)
            self.stats.send_delay_s.append(time.perf_counter() - (self._t0 + t))
            deadline = self._t0 + t + period
        else:
            deadline = time.perf_counter() + self.timeout
        refs = np.asarray(r, dtype=float).reshape(-1)[: self.host.references]
        sent = time.perf_counter()
        if self.stats.started is None:
            self.stats.started = sent
        self._seq = (self._seq + 1) & 0xFFFF
        seq = self._seq
        self.stats.steps += 1
        self._guard(lambda: self.link.send(proto.STEP, seq, proto.step_payload(
            np.asarray(y, dtype=float), refs, device.real_size)), t)
        while True:
            f = self._guard(lambda: self.link.receive(deadline), t)
            if f is None:
                if self.mode == "lockstep":
                    self._stop(f"the device did not answer within {self.timeout:g} s "
                               f"(sample at t = {t:.4g} s)")
                self.stats.late += 1
                self._missing.add(seq)
                if time.perf_counter() - self._last_answer > self.timeout:
                    self._stop(f"the device did not answer for {self.timeout:g} s "
                               f"(sample at t = {t:.4g} s)")
                return self._excite(t, self._held)
            if f.kind == proto.STEP_REPLY and f.seq == seq:
                reply = self._guard(partial(proto.parse_step_reply, f.payload, device), t)
                self.stats.ended = time.perf_counter()
                self.stats.round_trip_s.append(self.stats.ended - sent)
                self.stats.device_step_us.append(reply.device_step_us)
                self._last_answer = time.perf_counter()
                self.estimate = reply.estimate
                if not np.all(np.isfinite(reply.u)):
                    self._stop(f"the device answered a command that is not finite "
                               f"({reply.u.tolist()}) at t = {t:.4g} s")
                self._held = reply.u.copy()
                return self._excite(t, reply.u)
            if f.kind == proto.STEP_REPLY and f.seq in self._missing:
                self._missing.discard(f.seq)  # a late answer, come at last: already counted
                self._last_answer = time.perf_counter()
                continue
            self._unexpected(f, t)

    def _excite(self, t: float, u: np.ndarray) -> np.ndarray:
        if self._excitation is None:
            return u.copy()
        excited: np.ndarray = u + self._excitation.evaluate(np.array([t]), np.zeros(u.size))[0]
        return excited

    # -- faults -----------------------------------------------------------------------------
    def finish(self) -> None:
        """Count the answers that never came."""
        self.stats.lost = len(self._missing)

    def _request(self, kind: int, payload: bytes, answer: int, deadline: float, *, when: str) -> None:
        self._seq = (self._seq + 1) & 0xFFFF
        seq = self._seq
        try:
            self.link.send(kind, seq, payload)
            while True:
                f = self.link.receive(deadline)
                if f is None:
                    raise HILRefused(f"no answer from the device {when}")
                if f.kind == answer and f.seq == seq:
                    return
                if f.kind in (proto.ERROR, proto.BOOT):
                    raise HILRefused(f"the device failed {when}: {_what(f)}")
        except (ProtocolError, DeviceGone) as exc:
            raise HILRefused(f"{exc} ({when})") from None

    def _guard(self, call: Callable[[], _T], t: float) -> _T:
        try:
            return call()
        except ProtocolError as exc:
            self._stop(f"the device answered garbage at t = {t:.4g} s: {exc}")
        except DeviceGone as exc:
            self._stop(f"{exc} (at t = {t:.4g} s)")

    def _unexpected(self, f: proto.Frame, t: float) -> None:
        if f.kind == proto.BOOT:
            self._stop(f"the device reset during the run (it sent its start-up frame at "
                       f"t = {t:.4g} s)")
        if f.kind == proto.ERROR:
            text = _text(f.payload)
            if text.startswith("not started"):
                self._stop(f"the device reset during the run (it no longer knew the session at "
                           f"t = {t:.4g} s)")
            self._stop(f"the device refused a step at t = {t:.4g} s: {text}")
        if f.kind == proto.STEP_REPLY:
            return  # an answer to a sample long given up (realtime): ignored
        self._stop(f"the device answered a message of type 0x{f.kind:02x} at t = {t:.4g} s, "
                   "expected a step answer")

    def _stop(self, why: str) -> NoReturn:
        self.fault = why
        raise StopRun(why)


def _text(payload: bytes) -> str:
    """A device's text (an error frame's), as it may be printed: escaped and bounded."""
    return quote_outside(payload.decode("utf-8", "backslashreplace")) or "(no text)"


def _what(f: proto.Frame) -> str:
    return "it restarted" if f.kind == proto.BOOT else _text(f.payload)


@dataclass(frozen=True)
class HILRun:
    """A hardware-in-the-loop run: the simulation's result, the link's figures, a fault if any."""

    result: SimResult
    stats: LinkStats
    mode: str
    port: str
    fault: str | None
    device: Hello
    scheduling: str = "normal"

    def summary(self) -> dict[str, object]:
        return {"mode": self.mode, "port": self.port, "fault": self.fault,
                "scheduling": self.scheduling,
                "controller_id": quote_outside(self.device.controller_id),
                "payload": "float64" if self.device.real_size == 8 else "float32",
                **self.stats.summary()}


def run_hil(system: System, controller: DeviceController, *, x0: Mapping[str, float] | None = None,
            **options: Any) -> HILRun:
    """Simulate *system* with the device behind *controller* closing the loop.

    *options* are :func:`~equilibrist.sim.run.simulate`'s (duration, noise,
    seed, events, ...). The run ends early, with the samples so far, on a
    fault (:attr:`HILRun.fault`).
    """
    from equilibrist.sim.run import simulate

    if controller.device is None:
        controller.connect()
    scheduling = "normal"
    if controller.mode == "realtime":
        with realtime_priority() as scheduling:
            result = simulate(system, controller, x0=x0, **options)
    else:
        result = simulate(system, controller, x0=x0, **options)
    controller.finish()
    settings = dict(result.settings)
    device = controller.device
    assert device is not None
    run = HILRun(result=result, stats=controller.stats, mode=controller.mode,
                 port=controller.link.port, fault=controller.fault, device=device,
                 scheduling=scheduling)
    settings["hil"] = run.summary()
    from dataclasses import replace

    return replace(run, result=replace(result, settings=settings))
