"""The playground's ASGI application (Starlette): the page, its files, the socket, the downloads.

Routes:

``GET /``
    The page (``static/index.html``).
``GET /static/...``
    The page's scripts, styles and the vendored uPlot (no CDN).
``WS /ws``
    One session per connection (the protocol: ``docs/playground.md``).
``GET /download/{token}/{kind}``
    ``kind`` one of ``controller.zip`` (the C export of the controller in
    force), ``run.csv``, ``run.npz`` (the last run) of the session whose
    token the ``system`` frame gave; no client value names a file.

Safety: the page's origin only (a socket opened by another site's page is
refused), at most ``max_sessions`` sessions, at most ``MESSAGE_RATE``
messages per second per session (a burst of ``MESSAGE_BURST``; beyond it
messages are dropped with one error frame per second), every message
checked by :mod:`equilibrist.web.protocol`, and a session's resources freed
when its socket closes.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from equilibrist.errors import EquilibristError
from equilibrist.web.protocol import ProtocolError, parse
from equilibrist.web.session import Catalogue, Session, redesign

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


def create_app(
    catalogue: Catalogue | None = None,
    *,
    system: str | None = None,
    max_sessions: int = MAX_SESSIONS,
    seed: int | None = None,
) -> Any:
    """The playground application (a Starlette app).

    Parameters
    ----------
    catalogue:
        The systems offered (default: the catalogue's systems with an input).
    system:
        The system a new page starts with (default: the first offered, or
        the cart-pole when offered).
    max_sessions:
        Sessions served at once; one more gets an error frame and is closed.
    seed:
        Seed of the first session's noise (tests); each later one gets the next.
    """
    from equilibrist.web import require

    require()
    from starlette.applications import Starlette
    from starlette.requests import Request
    from starlette.responses import FileResponse, JSONResponse, Response
    from starlette.routing import Mount, Route, WebSocketRoute
    from starlette.staticfiles import StaticFiles
    from starlette.websockets import WebSocket, WebSocketDisconnect

    cat = catalogue if catalogue is not None else Catalogue.default()
    first = system or ("cartpole" if "cartpole" in cat.names else cat.names[0])
    # The first system, its design and its compiled core are built before serving,
    # so that the first page does not wait for them.
    Session(cat, first, seed=0)
    state = _State(cat, first, int(max_sessions), seed)

    async def index(request: Request) -> Response:
        return FileResponse(STATIC / "index.html", headers=_HEADERS)

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
                body = await asyncio.to_thread(session.run_file, ext)
                name = f"{session.system.name}_run.{ext}"
        except EquilibristError as exc:
            return JSONResponse({"error": str(exc)}, status_code=409, headers=_HEADERS)
        except Exception as exc:  # a bug must not take the server down; the page shows it
            return JSONResponse({"error": f"{kind} could not be made: {type(exc).__name__}"},
                                status_code=500, headers=_HEADERS)
        headers = dict(_HEADERS)
        headers["Content-Disposition"] = f'attachment; filename="{name}"'
        return Response(body, media_type=DOWNLOADS[kind], headers=headers)

    async def socket(ws: WebSocket) -> None:
        origin = ws.headers.get("origin")
        host = ws.headers.get("host", "")
        if origin is not None and origin.split("://", 1)[-1] != host:
            await ws.close(code=1008)
            return
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
            # A closed socket frees its session (and its stream) at once.
            state.sessions.pop(session.token, None)
            if streamer is not None:
                streamer.cancel()
                with contextlib.suppress(asyncio.CancelledError, Exception):
                    await streamer

    async def favicon(request: Request) -> Response:
        return Response(status_code=204, headers=_HEADERS)

    routes = [
        Route("/", index),
        Route("/favicon.ico", favicon),
        Route("/download/{token}/{kind}", download),
        WebSocketRoute("/ws", socket),
        Mount("/static", StaticFiles(directory=STATIC), name="static"),
    ]
    app = Starlette(routes=routes)
    app.state.playground = state
    return app


async def _send(ws: Any, message: dict[str, Any]) -> None:
    from starlette.websockets import WebSocketDisconnect

    try:
        text = json.dumps(message, separators=(",", ":"), allow_nan=False, default=_plain)
    except ValueError:  # a number that is not finite (a state that diverged): null in JSON
        text = json.dumps(_clean(message), separators=(",", ":"), allow_nan=False, default=_plain)
    try:
        await ws.send_text(text)
    except RuntimeError:  # the socket closed meanwhile (starlette says so with a RuntimeError)
        raise WebSocketDisconnect(1006) from None


def _plain(obj: Any) -> Any:
    import numpy as np

    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(type(obj).__name__)


def _clean(obj: Any) -> Any:
    """Non-finite floats as None (JSON has no NaN)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_clean(v) for v in obj]
    return obj


async def _stream(ws: Any, session: Session) -> None:
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


async def _receive(ws: Any, session: Session) -> None:
    from starlette.websockets import WebSocketDisconnect

    bucket = _Bucket(MESSAGE_RATE, MESSAGE_BURST)
    designing = 0
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
        try:
            message = parse(payload, session.limits)
        except ProtocolError as exc:
            await _send(ws, {"type": "error", "message": str(exc)})
            continue
        try:
            if message.type == "select":
                # Building a system and its design takes a moment: off the event loop,
                # with the stream holding its frames meanwhile.
                session.busy = True
                try:
                    await asyncio.to_thread(session.load, message.fields["system"])
                finally:
                    session.busy = False
                settings = None
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
        d, seconds, error, runner, built = await asyncio.to_thread(redesign, system, settings)
        if session.pending_design != ticket or session.base.spec is not system.spec:
            continue  # a later change, or another system, superseded this one
        session.install(settings, system, d, seconds, error, runner, built)


__all__ = ["FPS", "MAX_SESSIONS", "create_app"]
