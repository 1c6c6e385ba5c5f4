"""The playground's ASGI application (Starlette): the page (``GET /``), its files
(``/static``, uPlot vendored), one session per socket (``WS /ws``, the protocol of
``docs/playground.md``), and the downloads (``GET /download/{token}/{kind}``: the C export
of the controller in force, the last run as CSV or NPZ; no client value names a file).

Safety (``docs/playground.md``, "Safety"): a request's ``Host`` and a socket's ``Origin``
must name this server (:class:`HostCheck`, against DNS rebinding), at most
``max_sessions`` sessions and :data:`MESSAGE_RATE` messages a second per session, every
message checked by :mod:`equilibrist.web.protocol`, a session freed when its socket closes.
"""

from __future__ import annotations

import asyncio
import ipaddress
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from equilibrist.errors import EquilibristError
from equilibrist.web.protocol import ProtocolError, parse
from equilibrist.web.session import Session
from equilibrist.web.session_design import Catalogue, redesign
from equilibrist.web.session_plan import compute_plan
from equilibrist.web.session_roa import compute_roa

if TYPE_CHECKING:
    from collections.abc import Awaitable, Callable

    from starlette.applications import Starlette
    from starlette.requests import Request
    from starlette.responses import Response
    from starlette.types import ASGIApp, Receive, Scope, Send
    from starlette.websockets import WebSocket

#: Frames per second streamed to each page.
FPS = 40.0
#: Messages per second a session may send (sustained), and its burst.
MESSAGE_RATE = 40.0
MESSAGE_BURST = 80.0
#: Sessions served at once (default of :func:`create_app`).
MAX_SESSIONS = 32

STATIC = Path(__file__).parent / "static"
DOWNLOADS = {
    "controller.zip": "application/zip",
    "run.csv": "text/csv",
    "run.npz": "application/octet-stream",
}
_HEADERS = {
    "X-Content-Type-Options": "nosniff",
    "Content-Security-Policy": "default-src 'self'; connect-src 'self' ws: wss:; img-src 'self' data:; "
                               "style-src 'self' 'unsafe-inline'; frame-ancestors 'none'",
    "Cache-Control": "no-store",
}


@dataclass
class _State:
    catalogue: Catalogue
    first: str
    max_sessions: int
    seed: int | None
    sessions: dict[str, Session] = field(default_factory=dict)


class _Bucket:
    """Token bucket of the message rate."""

    def __init__(self, rate: float, burst: float) -> None:
        self.rate, self.burst, self.tokens, self.last = rate, burst, burst, time.monotonic()
        self.warned = 0.0

    def take(self) -> bool:
        now = time.monotonic()
        self.tokens = min(self.burst, self.tokens + (now - self.last) * self.rate)
        self.last = now
        if self.tokens >= 1.0:
            self.tokens -= 1.0
            return True
        return False


#: The names of this machine a playground always answers to.
LOOPBACK_NAMES = ("127.0.0.1", "localhost", "[::1]")
#: Addresses that bind every interface.
WILDCARDS = ("0.0.0.0", "::", "[::]", "")


def _host_name(host: str) -> str:
    """*host* as a ``Host`` header names it: lower case, an IPv6 address in brackets."""
    name = host.strip().lower()
    if ":" in name and not name.startswith("["):
        name = f"[{name}]"
    return name


def _split_host(value: str) -> tuple[str, int | None] | None:
    """``(name, port or None)`` of a ``Host`` value (``name``, ``name:port``, ``[v6]:port``);
    None when it is not of that form."""
    value = value.strip().lower()
    if value.startswith("["):
        end = value.find("]")
        if end < 0:
            return None
        name, rest = value[:end + 1], value[end + 1:]
    else:
        name, colon, tail = value.partition(":")
        rest = colon + tail
    if not name:
        return None
    if not rest:
        return name, None
    digits = rest[1:]
    if rest[0] != ":" or not digits.isascii() or not digits.isdigit() or len(digits) > 5:
        return None
    return name, int(digits)


def _is_address(name: str) -> bool:
    try:
        ipaddress.ip_address(name[1:-1] if name.startswith("[") else name)
    except ValueError:
        return False
    return True


@dataclass(frozen=True)
class HostCheck:
    """The ``Host`` and ``Origin`` a request to the playground may carry: the loopback
    names and the address it was bound to, with the port it serves (``port`` None: any
    port, for an app served by another runner). A server bound to every interface also
    answers to any IP address with its port: a page reaching it by address has no name that
    DNS could turn to this machine.
    """

    names: frozenset[str]
    port: int | None = None
    any_address: bool = False

    @classmethod
    def serving(cls, host: str = "127.0.0.1", port: int | None = None) -> HostCheck:
        """The check of a server bound to *host*:*port*."""
        names = set(LOOPBACK_NAMES)
        wildcard = host.strip() in WILDCARDS
        if not wildcard:
            names.add(_host_name(host))
        return cls(frozenset(names), port, wildcard)

    def expected(self) -> str:
        port = "" if self.port is None else f":{self.port}"
        names = [f"{n}{port}" for n in sorted(self.names)]
        if self.any_address:
            names.append(f"an address of this machine{port}")
        return ", ".join(names[:-1]) + f" or {names[-1]}" if len(names) > 1 else names[0]

    def accepts(self, value: str) -> bool:
        """Whether the ``Host`` value *value* names this server."""
        parts = _split_host(value)
        if parts is None:
            return False
        name, port = parts
        if self.port is not None and port != self.port and not (port is None and self.port == 80):
            return False
        return name in self.names or (self.any_address and _is_address(name))

    def host_refusal(self, value: str | None) -> str | None:
        """Why a request with ``Host`` *value* is refused (None: it is not)."""
        if value is None:
            return f"the request has no Host header: expected {self.expected()}"
        if not self.accepts(value):
            return f"Host {value[:80]!r} is not this playground's address: expected {self.expected()}"
        return None

    def origin_refusal(self, value: str | None) -> str | None:
        """Why a socket opened with ``Origin`` *value* is refused (None: it is not). No
        ``Origin`` is accepted: browsers always send one, so that is a program, not a page."""
        if value is None:
            return None
        scheme, sep, rest = value.strip().lower().partition("://")
        if scheme != "http" or not sep or "/" in rest or not self.accepts(rest):
            return (f"Origin {value[:80]!r} is not this playground's page: expected "
                    f"http:// and {self.expected()}")
        return None


class _Guard:
    """ASGI middleware: refuses a request whose ``Host`` (or a socket whose ``Origin``)
    is not one of the :class:`HostCheck`'s, before any route sees it."""

    def __init__(self, app: ASGIApp, check: HostCheck) -> None:
        self.app, self.check = app, check

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        kind = scope["type"]
        if kind not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        headers: dict[str, str] = {}
        for key, value in scope.get("headers", ()):
            headers.setdefault(key.decode("latin-1").lower(), value.decode("latin-1"))
        why = self.check.host_refusal(headers.get("host"))
        status = 400
        if why is None and kind == "websocket":
            why, status = self.check.origin_refusal(headers.get("origin")), 403
        if why is None:
            await self.app(scope, receive, send)
            return
        if kind == "websocket":
            # Closed before it is accepted: the handshake is answered with a 403, no session starts.
            await send({"type": "websocket.close", "code": 1008, "reason": why[:120]})
            return
        from starlette.responses import PlainTextResponse

        await PlainTextResponse(f"equilibrist playground: {why}\n", status_code=status,
                                headers=_HEADERS)(scope, receive, send)


def create_app(
    catalogue: Catalogue | None = None,
    *,
    system: str | None = None,
    max_sessions: int = MAX_SESSIONS,
    seed: int | None = None,
    host: str = "127.0.0.1",
    port: int | None = None,
) -> Starlette:
    """The playground application (a Starlette app) offering *catalogue* (default: the
    catalogue's systems with an input), a new page starting with *system* (default: the
    cart-pole when offered, else the first). One session beyond *max_sessions* gets an error
    frame and is closed; *seed* seeds the first session's noise (each later one the next).
    Requests must name *host* (and *port*, None: any) in their ``Host`` (:class:`HostCheck`).
    """
    from equilibrist.web import require

    require()
    from starlette.applications import Starlette
    from starlette.middleware import Middleware
    from starlette.responses import FileResponse, Response
    from starlette.routing import Mount, Route, WebSocketRoute
    from starlette.staticfiles import StaticFiles

    cat = catalogue if catalogue is not None else Catalogue.default()
    first = system or ("cartpole" if "cartpole" in cat.names else cat.names[0])
    # The first system, its design and its compiled core are built before serving,
    # so that the first page does not wait for them.
    Session(cat, first, seed=0)
    state = _State(cat, first, int(max_sessions), seed)

    async def index(request: Request) -> Response:
        return FileResponse(STATIC / "index.html", headers=_HEADERS)

    download = _download_handler(state)
    socket = _socket_handler(state)

    async def favicon(request: Request) -> Response:
        return Response(status_code=204, headers=_HEADERS)

    routes = [
        Route("/", index),
        Route("/favicon.ico", favicon),
        Route("/download/{token}/{kind}", download),
        WebSocketRoute("/ws", socket),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ]
    check = HostCheck.serving(host, port)
    app = Starlette(routes=routes, middleware=[Middleware(_Guard, check=check)])
    app.state.playground = state
    return app


def _download_handler(state: _State) -> Callable[[Request], Awaitable[Response]]:
    """The handler of ``/download/{token}/{kind}``: a session's controller as C, or its run."""
    from starlette.responses import JSONResponse, Response

    async def download(request: Request) -> Response:
        token = request.path_params["token"]
        kind = request.path_params["kind"]
        session = state.sessions.get(token)
        if session is None or kind not in DOWNLOADS:
            return JSONResponse({"error": "no such download"}, status_code=404, headers=_HEADERS)
        try:
            if kind == "controller.zip":
                body = await asyncio.to_thread(session.export_zip)
                name = f"{session.system.name}_{session.settings.controller}_c.zip"
            else:
                ext = kind.split(".")[1]
                # The copy of the record here, on the loop that adds to it; the file in a thread.
                body = await asyncio.to_thread(session.run_file, ext, session.last_run())
                name = f"{session.system.name}_run.{ext}"
        except EquilibristError as exc:
            return JSONResponse({"error": str(exc)}, status_code=409, headers=_HEADERS)
        except Exception as exc:  # a bug must not take the server down; the page shows it
            return JSONResponse({"error": f"{kind} could not be made: {type(exc).__name__}"},
                                status_code=500, headers=_HEADERS)
        headers = dict(_HEADERS)
        headers["Content-Disposition"] = f'attachment; filename="{name}"'
        return Response(body, media_type=DOWNLOADS[kind], headers=headers)

    return download


def _socket_handler(state: _State) -> Callable[[WebSocket], Awaitable[None]]:
    """The handler of ``/ws``: one session per socket, its frames streamed, its messages
    received, freed when the socket closes."""
    from starlette.websockets import WebSocketDisconnect

    async def socket(ws: WebSocket) -> None:
        # (Its Host and Origin were checked by the guard, before it got here.)
        await ws.accept()
        if len(state.sessions) >= state.max_sessions:
            await _send(ws, {"type": "error", "message":
                             f"the playground serves {state.max_sessions} sessions at once: "
                             "close another tab and reload"})
            await ws.close(code=1013)
            return
        seed = None if state.seed is None else state.seed + len(state.sessions)
        try:
            session = await asyncio.to_thread(Session, state.catalogue, state.first, seed=seed)
        except EquilibristError as exc:
            await _send(ws, {"type": "error", "message": str(exc)})
            await ws.close(code=1011)
            return
        state.sessions[session.token] = session
        streamer: asyncio.Task[None] | None = None
        try:
            await _send(ws, {"type": "hello", "token": session.token, "fps": FPS,
                             "message_rate": MESSAGE_RATE})
            streamer = asyncio.create_task(_stream(ws, session))
            await _receive(ws, session)
        except WebSocketDisconnect:
            pass
        finally:
            # A closed socket frees its session (and its stream) at once; a region of
            # attraction under way for it stops at its next check.
            state.sessions.pop(session.token, None)
            session.roa_clear()
            session.plan_clear()
            if streamer is not None:
                streamer.cancel()
                # Waited for, not awaited: its end (cancelled, or a closed socket) is no error
                # here, while a cancellation of this handler itself still goes through.
                await asyncio.wait({streamer})
                if not streamer.cancelled():
                    streamer.exception()

    return socket


async def _send(ws: WebSocket, message: dict[str, object]) -> None:
    from starlette.websockets import WebSocketDisconnect

    try:
        text = json.dumps(message, separators=(",", ":"), allow_nan=False, default=_plain)
    except ValueError:  # a number that is not finite (a state that diverged): null in JSON
        text = json.dumps(_clean(message), separators=(",", ":"), allow_nan=False, default=_plain)
    try:
        await ws.send_text(text)
    except RuntimeError:  # the socket closed meanwhile (starlette says so with a RuntimeError)
        raise WebSocketDisconnect(1006) from None


def _plain(obj: object) -> object:
    import numpy as np

    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(type(obj).__name__)


def _clean(obj: object) -> object:
    """Non-finite floats as None (JSON has no NaN)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_clean(v) for v in obj]
    return obj


async def _stream(ws: WebSocket, session: Session) -> None:
    """Advance the session to the wall clock and send a frame, FPS times a second."""
    loop = asyncio.get_running_loop()
    period = 1.0 / FPS
    deadline = loop.time()
    while True:
        if session.busy:
            await asyncio.sleep(period)
            continue
        session.advance_to(loop.time())
        for message in session.take_messages():
            await _send(ws, message)
        if not session.behind():
            await _send(ws, session.frame())
        deadline += period
        now = loop.time()
        if deadline < now - period:  # fell behind: do not burst to catch up
            deadline = now
        await asyncio.sleep(max(0.0, deadline - now))


async def _receive(ws: WebSocket, session: Session) -> None:
    """Take the session's messages until its socket closes: a reader takes each as it
    arrives (the rate limit counts them there), a worker acts on them one at a time, in
    order. The socket's close ends both at once, also while the worker waits for a redesign
    (that thread runs out and its result is dropped)."""
    from starlette.websockets import WebSocketDisconnect

    inbox: asyncio.Queue[str | bytes] = asyncio.Queue()
    reader = asyncio.create_task(_read(ws, inbox))
    worker = asyncio.create_task(_work(ws, session, inbox))
    try:
        await asyncio.wait({reader, worker}, return_when=asyncio.FIRST_COMPLETED)
    finally:
        reader.cancel()
        worker.cancel()
        results = await asyncio.gather(reader, worker, return_exceptions=True)
    for result in results:
        if isinstance(result, BaseException) and not isinstance(
                result, WebSocketDisconnect | asyncio.CancelledError):
            raise result


async def _read(ws: WebSocket, inbox: asyncio.Queue[str | bytes]) -> None:
    """Queue the socket's messages for the worker, within the message rate."""
    from starlette.websockets import WebSocketDisconnect

    bucket = _Bucket(MESSAGE_RATE, MESSAGE_BURST)
    while True:
        raw = await ws.receive()
        if raw["type"] == "websocket.disconnect":
            raise WebSocketDisconnect(raw.get("code", 1000))
        text = raw.get("text")
        payload: str | bytes = text if text is not None else (raw.get("bytes") or b"")
        if not bucket.take():
            now = time.monotonic()
            if now - bucket.warned > 1.0:
                bucket.warned = now
                await _send(ws, {"type": "error", "message":
                                 f"too many messages: at most {MESSAGE_RATE:g} a second; "
                                 "messages are dropped until the rate falls"})
            continue
        inbox.put_nowait(payload)


async def _work(ws: WebSocket, session: Session, inbox: asyncio.Queue[str | bytes]) -> None:
    """Check and carry out the queued messages, one at a time, each against the limits in
    force when its turn comes (a ``select`` changes them). A region of attraction and the
    plan a tracking kind needs are computed aside: the messages after them do not wait."""
    designing = 0
    jobs: set[asyncio.Task[None]] = set()
    try:
        while True:
            payload = await inbox.get()
            try:
                message = parse(payload, session.limits)
            except ProtocolError as exc:
                await _send(ws, {"type": "error", "message": str(exc)})
                continue
            try:
                settings = None
                if message.type == "select":
                    # Building a system and its design takes a moment: off the event loop,
                    # with the stream holding its frames meanwhile.
                    session.busy = True
                    try:
                        await asyncio.to_thread(session.load, message.fields["system"])
                    finally:
                        session.busy = False
                elif message.type == "roa":
                    job = session.roa_job()
                    if job is not None:
                        task = asyncio.create_task(compute_roa(session, job))
                        jobs.add(task)
                        task.add_done_callback(jobs.discard)
                else:
                    settings = session.handle(message)
                if settings is not None:
                    system = session.prepare(settings)
            except EquilibristError as exc:
                await _send(ws, {"type": "error", "message": str(exc), "seq": message.seq})
                continue
            if message.seq is not None:
                await _send(ws, {"type": "ack", "seq": message.seq, "of": message.type})
            if settings is None:
                continue
            designing += 1
            ticket = designing
            session.pending_design = ticket
            plan = session.plan_for(system, settings)
            d, seconds, error, runner, built = await asyncio.to_thread(redesign, system, settings,
                                                                        plan)
            if session.pending_design != ticket or session.base.spec is not system.spec:
                continue  # a later change, or another system, superseded this one
            session.install(settings, system, d, seconds, error, runner, built)
            planning = session.plan_job()  # a kind that tracks a plan, without one yet
            if planning is not None:
                task = asyncio.create_task(compute_plan(session, planning))
                jobs.add(task)
                task.add_done_callback(jobs.discard)
    finally:
        for task in jobs:
            task.cancel()


__all__ = ["FPS", "LOOPBACK_NAMES", "MAX_SESSIONS", "HostCheck", "create_app"]
