"""The playground's time-varying LQR: picked on a system with a swing-up, the session holds
the system at its hanging start while the swing-up is planned off the live loop ("planning"),
then tracks the plan, each frame carrying the plan's state at its time as a ghost of the
drawing; a plan that fails is an error frame and the session goes on with the controller
off. The protocol through the in-process client, then the ghost drawn in a real headless
Chromium (never skipped)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import test_web_browser as _shared  # beside this file (tests/web/)
from test_web_browser import wait_for
from tests.support.web import LocalClient, next_frame, opening, receive_until

from equilibrist.errors import DesignError
from equilibrist.web.app import create_app
from equilibrist.web.protocol import Limits, parse


@pytest.fixture(scope="module")
def app():
    return create_app(seed=7)


@pytest.fixture(scope="module")
def client(app):
    with LocalClient(app) as c:
        yield c


def _pick(ws, controller, seq):
    ws.send_text(json.dumps({"type": "tune", "controller": controller, "seq": seq}))


def test_the_kind_is_offered_where_a_swing_up_can_be_planned(client):
    with client.websocket_connect("/ws") as ws:
        first = opening(ws)["system"]
        options = {o["name"]: o for o in first["controller_options"]}
        assert options["tvlqr"]["available"], options["tvlqr"]
        assert options["tvlqr"]["label"].startswith("Time-varying LQR")
        ws.send_text(json.dumps({"type": "select", "system": "seesaw"}))
        seesaw = receive_until(ws, lambda m: m["type"] == "system" and m["name"] == "seesaw")
        options = {o["name"]: o for o in seesaw["controller_options"]}
        assert not options["tvlqr"]["available"]
        assert "no hanging position" in options["tvlqr"]["reason"]
    limits = Limits(("seesaw",), unavailable={"tvlqr": "seesaw has no hanging position"})
    with pytest.raises(ValueError, match="does not apply: seesaw has no hanging"):
        parse('{"type": "tune", "controller": "tvlqr"}', limits)


def test_picking_it_plans_from_hanging_then_tracks_the_plan_drawn_as_a_ghost(client):
    with client.websocket_connect("/ws") as ws:
        opening(ws)
        _pick(ws, "tvlqr", 5)
        planning = receive_until(ws, lambda m: m["type"] == "plan")
        assert planning["status"] == "planning" and planning["controller"] == "tvlqr"
        start = np.array(planning["start"])
        assert abs(start[1] - np.pi) < 0.2  # the cart-pole's pole hangs
        # While the plan is made the system holds at the start, and the frames say so.
        held = receive_until(ws, lambda m: m["type"] == "frame" and m["plan"] == "planning")
        assert held["mode"] == "planning" and held["hanging"] and held["ghost"] is None
        np.testing.assert_allclose(held["x"], start)
        ready = receive_until(ws, lambda m: m["type"] == "plan" and m["status"] != "planning",
                              limit=20000)
        assert ready["status"] == "ready", ready
        assert ready["duration"] == 4.0 and ready["knots"] == 60 and ready["solve_time"] > 0
        assert ready["start"] == planning["start"]
        lo, hi = ready["bounds"]["x"]
        assert -1.0 < lo < hi < 1.0  # within the track, with room to correct
        # The run starts at the plan's start and tracks it; each frame has the ghost.
        frames = [next_frame(ws) for _ in range(12)]
        tracking = [f for f in frames if f["plan"] == "tracking"]
        assert tracking, [f["plan"] for f in frames]
        f0, f1 = tracking[0], tracking[-1]
        assert f0["controller"] == "tvlqr" and f0["mode"] == "tracking"
        assert f0["ghost"] and all(s["points"] for s in f0["ghost"])
        assert abs(f0["plan_t"] - f0["t"]) < 0.05  # the plan's clock is the run's
        moved = [s0["points"] != s1["points"] for s0, s1 in zip(f0["ghost"], f1["ghost"],
                                                                   strict=True)]
        assert f1["plan_t"] > f0["plan_t"] and any(moved)
        # The static parts (the track, the labels) are not in the ghost.
        assert {s["kind"] for s in f0["ghost"]} <= {"fill", "line"}
        # A retune that leaves the plant as it was rebuilds the tracker on the same plan, at
        # the same plan time: no new plan, the run goes on.
        ws.send_text(json.dumps({"type": "tune", "noise": 0.5, "seq": 6}))
        seen = []
        design = receive_until(ws, lambda m: seen.append(m) or m["type"] == "design")
        assert not [m for m in seen if m["type"] == "plan"]
        assert design["controller_info"]["kind"] == "tvlqr"
        assert design["controller_info"]["plan_duration"] == 4.0
        after = next_frame(ws)
        assert after["run"] == f1["run"] and after["t"] > f1["t"]
        assert after["controller"] == "tvlqr" and after["mode"] in ("tracking", "balancing")
        assert after["plan_t"] is None or abs(after["plan_t"] - after["t"]) < 0.05
        # The plan ends upright, caught by the balancing LQR: the ghost is gone.
        up = receive_until(ws, lambda m: m["type"] == "frame" and (m["fell"] or m["t"] > 4.6),
                           limit=20000)
        assert up["fell"] is None and up["mode"] == "balancing" and up["ghost"] is None
        assert abs(np.cos(up["x"][1]) - 1.0) < 0.02 and abs(up["x"][0]) < 1.0


def test_a_plan_that_fails_is_an_error_and_the_session_goes_on(client, monkeypatch):
    from equilibrist.control import trajopt

    def refuse(*args, **kwargs):
        raise DesignError("trajectory optimization needs CasADi with IPOPT (a test)")

    monkeypatch.setattr(trajopt, "plan", refuse)
    with client.websocket_connect("/ws") as ws:
        opening(ws)
        _pick(ws, "tvlqr", 3)
        assert receive_until(ws, lambda m: m["type"] == "plan")["status"] == "planning"
        failed = receive_until(ws, lambda m: m["type"] == "plan" and m["status"] != "planning")
        assert failed["status"] == "failed" and failed["controller"] == "off"
        err = receive_until(ws, lambda m: m["type"] == "error")
        assert "no plan to track" in err["message"] and "CasADi" in err["message"]
        # The session goes on: the open loop, the clock running.
        a = receive_until(ws, lambda m: m["type"] == "frame" and m["plan"] is None)
        b = receive_until(ws, lambda m: m["type"] == "frame" and m["t"] > a["t"])
        assert b["controller"] == "off" and b["ghost"] is None
        _pick(ws, "lqg", 4)
        assert receive_until(ws, lambda m: m["type"] == "design")["controller"] == "lqg"


# -- the page -------------------------------------------------------------------------------


# The playground served as a user starts it, a headless Chromium, the page open in it (the
# fixtures of test_web_browser.py, which never skips).
server = _shared.server
browser = _shared.browser
page = _shared.page


@pytest.mark.slow
def test_the_page_says_planning_then_draws_the_ghost_and_it_moves(page):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    Select(page.find_element(By.ID, "controller")).select_by_value("tvlqr")
    status = page.find_element(By.ID, "plan-status")
    wait_for(lambda: "Planning" in status.text or "Plan:" in status.text, 30, "planning…")
    wait_for(lambda: status.text.startswith("Plan:"), 120, "the plan")
    cv = page.find_element(By.ID, "scene")
    wait_for(lambda: cv.get_attribute("data-ghost"), 30, "the ghost drawn")
    seen = set()
    wait_for(lambda: seen.add(cv.get_attribute("data-ghost-at")) or len(seen) >= 4, 30,
             "the ghost moving")
    first = float(cv.get_attribute("data-plan-t"))
    wait_for(lambda: float(cv.get_attribute("data-plan-t") or 0) > first + 0.3, 30,
             "the plan's clock running")
    # The ghost is drawn over the live system: its dashed outline's colour is on the canvas.
    colours = page.execute_script("""
        const cv = document.getElementById('scene'), ctx = cv.getContext('2d');
        const d = ctx.getImageData(0, 0, cv.width, cv.height).data;
        let n = 0;
        for (let k = 0; k < d.length; k += 4) {
          if (Math.abs(d[k] - 0x5b) < 40 && Math.abs(d[k + 1] - 0x6b) < 40
              && Math.abs(d[k + 2] - 0x8c) < 40 && d[k + 2] > d[k]) n += 1;
        }
        return n;""")
    assert colours > 20, colours
    # The plan ends, the balancing LQR holds it up: no ghost.
    wait_for(lambda: page.execute_script("return window.playground.frame.mode") == "balancing",
             30, "the hand-over to the balancing LQR")
    wait_for(lambda: cv.get_attribute("data-ghost") is None, 10, "the ghost gone")
    assert page.execute_script("return window.playground.frame.fell") is None
