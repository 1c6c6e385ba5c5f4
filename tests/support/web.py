"""Helpers for the playground's tests: a test client that addresses the playground as a
browser on this machine does, and reading frames from its WebSocket."""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable
from typing import Any
from urllib.parse import urljoin

with warnings.catch_warnings():
    # Starlette asks for its httpx fork; the httpx the project installs works the same.
    warnings.simplefilter("ignore")
    from starlette.testclient import TestClient

#: Where the test client says it is (a loopback name and port the playground answers to).
BASE = "http://127.0.0.1:8050"


class LocalClient(TestClient):
    """Starlette's test client with the address of a local page: the playground refuses its
    default name (``testserver``) as it refuses any name that is not this machine's."""

    def __init__(self, app: Any, **kwargs: Any) -> None:
        kwargs.setdefault("base_url", BASE)
        super().__init__(app, **kwargs)

    def websocket_connect(self, url: str, *args: Any, **kwargs: Any) -> Any:
        base = str(self.base_url).replace("http://", "ws://", 1)
        return super().websocket_connect(urljoin(base, url), *args, **kwargs)


def receive_until(ws: Any, predicate: Callable[[dict[str, Any]], bool],
                  limit: int = 3000) -> dict[str, Any]:
    """Frames until *predicate* holds for one (returned); fails after *limit* frames."""
    for _ in range(limit):
        msg = json.loads(ws.receive_text())
        if predicate(msg):
            return msg
    raise AssertionError("the expected frame never came")


def next_frame(ws: Any) -> dict[str, Any]:
    """The next ``frame`` message."""
    return receive_until(ws, lambda m: m["type"] == "frame")


def opening(ws: Any) -> dict[str, dict[str, Any]]:
    """The hello, system and design frames that open a session, by type."""
    seen: dict[str, dict[str, Any]] = {}
    while len(seen) < 3:
        msg = json.loads(ws.receive_text())
        if msg["type"] in ("hello", "system", "design"):
            seen[msg["type"]] = msg
    return seen
