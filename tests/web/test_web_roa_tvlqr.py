"""The playground's region of attraction asked for while the time-varying LQR tracks its
plan: an error in the page's own terms (what the view shows, which controller to pick),
and the session goes on. Through the in-process client, as ``test_web_tvlqr.py``."""

from __future__ import annotations

import json

import pytest
from tests.support.web import LocalClient, next_frame, opening, receive_until

from equilibrist.web.app import create_app


@pytest.fixture(scope="module")
def client():
    with LocalClient(create_app(seed=7)) as c:
        yield c


def _answer(ws, seq):
    """The error frame of message *seq*, or a region of attraction that failed."""
    return receive_until(ws, lambda m: (m["type"] == "error" and m.get("seq") == seq)
                         or (m["type"] == "roa" and m["status"] == "failed"), limit=20000)


def test_the_region_of_attraction_of_a_planned_swing_up_is_an_error_the_page_can_act_on(
        client) -> None:
    with client.websocket_connect("/ws") as ws:
        first = opening(ws)["system"]
        labels = {o["name"]: o["label"] for o in first["controller_options"]}
        ws.send_text(json.dumps({"type": "tune", "controller": "tvlqr", "seq": 5}))
        ready = receive_until(ws, lambda m: m["type"] == "plan" and m["status"] != "planning",
                              limit=20000)
        assert ready["status"] == "ready", ready
        ws.send_text(json.dumps({"type": "roa", "seq": 6}))
        answer = _answer(ws, 6)
        assert answer["type"] == "error", answer
        message = answer["message"]
        # The page's words: its button, the picker's labels; no command line.
        assert "Region of attraction" in message
        assert labels["tvlqr"] in message and labels["lqr"] in message
        assert "--" not in message and "equilibrist" not in message
        # The session goes on: the plan is tracked, and the controller named draws the view.
        assert next_frame(ws)["controller"] == "tvlqr"
        ws.send_text(json.dumps({"type": "tune", "controller": "lqr", "seq": 7}))
        receive_until(ws, lambda m: m["type"] == "design" and m["controller"] == "lqr")
        ws.send_text(json.dumps({"type": "roa", "seq": 8}))
        computing = receive_until(ws, lambda m: m["type"] in ("roa", "error"))
        assert computing["type"] == "roa" and computing["status"] == "computing", computing
