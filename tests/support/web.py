"""Helpers for the playground's tests: reading frames from a test client's WebSocket."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any


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
