"""The playground's server through Starlette's test client: the protocol, hostile messages,
live redesigns against python-control, pushes and falls against the physics, downloads."""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest
from starlette.websockets import WebSocketDisconnect
from tests.support.web import LocalClient, next_frame, opening, receive_until

from equilibrist.web.app import HostCheck, create_app
from equilibrist.web.protocol import MAX_MESSAGE_BYTES, Limits, ProtocolError, parse
from equilibrist.web.session_design import Catalogue

LIMITS = Limits(("cartpole", "seesaw"), {"theta": (0.002, 20.0)}, {"m_p": (0.25, 4.0)})


@pytest.fixture(scope="module")
def app():
    return create_app(seed=7)


@pytest.fixture(scope="module")
def client(app):
    with LocalClient(app) as c:
        yield c


# -- the protocol alone --------------------------------------------------------------------


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("{not json", "not valid JSON"),
        ("[1, 2]", "must be a JSON object"),
        ('{"type": "push", "size": NaN}', "not a number of JSON"),
        ('{"type": "push", "size": Infinity}', "not a number of JSON"),
        ('{"type": "push", "size": 1e999}', "finite"),
        ('{"type": "push", "size": 1e300}', "out of range"),
        ('{"type": "push", "size": "1"}', "must be a number"),
        ('{"type": "push", "size": true}', "must be a number"),
        ('{"type": "push"}', "lacks size"),
        ('{"type": "push", "size": 0.5, "force": 3}', "unknown field"),
        ('{"type": "explode"}', "unknown"),
        ('{"size": 1}', "unknown"),
        ('{"type": "select", "system": "/etc/passwd"}', "not offered"),
        ('{"type": "select", "system": "__import__(\'os\')"}', "not offered"),
        ('{"type": "tune"}', "changes nothing"),
        ('{"type": "tune", "controller": "pid"}', "unknown"),
        ('{"type": "tune", "rate": 0}', "out of range"),
        ('{"type": "tune", "rate": -200}', "out of range"),
        ('{"type": "tune", "scales": {"theta": 0}}', "out of range"),
        ('{"type": "tune", "scales": {"__class__": 1}}', "no entry"),
        ('{"type": "tune", "scales": [1, 2]}', "must be an object"),
        ('{"type": "tune", "params": {"m_p": 1e6}}', "out of range"),
        ('{"type": "tune", "params": {"g": 9.8}}', "no entry"),
        ('{"type": "pause", "paused": 1}', "true or false"),
        ('{"type": "reset", "kick": 7}', "out of range"),
        ('{"type": "push", "size": 1, "seq": -1}', "seq"),
        ('{"type": "push", "size": 1, "seq": 1.5}', "seq"),
        ('{"type": "seen", "frame": -3}', "frame must be an integer"),
        ('{"type": "roa", "grid": 64}', "unknown field"),
        ("[" * 8000 + "]" * 8000, "not valid JSON"),
    ],
)
def test_parse_refuses_with_a_reason(text, says):
    with pytest.raises(ProtocolError, match=says):
        parse(text, LIMITS)


def test_parse_size_limit_and_binary():
    big = json.dumps({"type": "push", "size": 1, "pad": "x" * MAX_MESSAGE_BYTES})
    with pytest.raises(ProtocolError, match="too long"):
        parse(big, LIMITS)
    with pytest.raises(ProtocolError, match="binary"):
        parse(b'{"type": "push", "size": 1}', LIMITS)


def test_parse_accepts_the_documented_messages():
    m = parse('{"type": "tune", "scales": {"theta": 0.1}, "params": {"m_p": 2}, "rate": 100, '
              '"controller": "lqr", "noise": 0, "limit": 0.5, "seq": 4}', LIMITS)
    assert m.type == "tune" and m.seq == 4
    assert m.fields == {"scales": {"theta": 0.1}, "params": {"m_p": 2.0}, "rate": 100.0,
                        "controller": "lqr", "noise": 0.0, "limit": 0.5}
    assert parse('{"type": "push", "size": -1, "duration": 0.2}', LIMITS).fields == {
        "size": -1.0, "duration": 0.2}
    assert parse('{"type": "select", "system": "seesaw"}', LIMITS).fields == {"system": "seesaw"}
    assert parse('{"type": "seen", "frame": 12}', LIMITS).fields == {"frame": 12}
    assert parse('{"type": "roa", "seq": 3}', LIMITS).fields == {}


# -- the server --------------------------------------------------------------------------------


def test_page_and_files_ship_with_the_package(client):
    page = client.get("/")
    assert page.status_code == 200
    assert "equilibrist playground" in page.text
    # Every script and style the page loads is served by the package (no CDN).
    for ref in ("/static/vendor/uPlot.iife.min.js", "/static/vendor/uPlot.min.css",
                "/static/app.js", "/static/style.css"):
        assert ref in page.text
        assert client.get(ref).status_code == 200
    assert "http" not in page.text.replace("http-equiv", "")
    assert "MIT" in client.get("/static/vendor/uPlot.LICENSE").text


def test_hostile_messages_get_error_frames_and_the_session_goes_on(client):
    hostile = [
        "{not json", '{"type": "push", "size": NaN}', '{"type": "push", "size": 1e999}',
        '{"type": "tune", "rate": 1e308}', '{"type": "push", "size": 0.5, "evil": 1}',
        '{"type": "select", "system": "../../etc/passwd"}', "x" * (1024 * 1024),
        json.dumps({"type": "tune", "scales": {"theta": -1}}),
    ]
    with client.websocket_connect("/ws") as ws:
        opening(ws)
        for text in hostile:
            ws.send_text(text)
            err = receive_until(ws, lambda m: m["type"] == "error")
            assert err["message"]
        ws.send_bytes(b"\x00\x01binary")
        assert "binary" in receive_until(ws, lambda m: m["type"] == "error")["message"]
        # Still alive: a valid message is acknowledged and frames keep coming.
        ws.send_text(json.dumps({"type": "push", "size": 0.5, "seq": 99}))
        ack = receive_until(ws, lambda m: m["type"] == "ack")
        assert ack["seq"] == 99
        t1 = next_frame(ws)["t"]
        assert receive_until(ws, lambda m: m["type"] == "frame" and m["t"] > t1 + 0.2)


def test_a_seen_frame_from_the_future_gets_an_error_frame_and_the_session_goes_on(client):
    with client.websocket_connect("/ws") as ws:
        opening(ws)
        n = next_frame(ws)["n"]
        ws.send_text(json.dumps({"type": "seen", "frame": n + 10**9, "seq": 31}))
        ws.send_text(json.dumps({"type": "kick", "angle": 0.0, "seq": 32}))
        got = receive_until(ws, lambda m: m["type"] in ("error", "ack"))
        assert got["type"] == "error" and got["seq"] == 31, got
        assert "seen frame" in got["message"] and "has not been sent" in got["message"]
        assert len(got["message"].splitlines()) == 1
        assert receive_until(ws, lambda m: m["type"] == "ack")["seq"] == 32
        # The bad report changed nothing: frames keep coming, numbered on, not held back.
        frames = [next_frame(ws) for _ in range(20)]
        assert [f["n"] for f in frames] == list(range(frames[0]["n"], frames[0]["n"] + 20))
        # A frame that was sent is a good report.
        ws.send_text(json.dumps({"type": "seen", "frame": frames[-1]["n"], "seq": 33}))
        assert receive_until(ws, lambda m: m["type"] in ("error", "ack"))["type"] == "ack"


def _roa_until(ws, status, frames):
    """The next ``roa`` frame of *status* (a tuple), the live frames before it kept in *frames*
    as (wall time, frame)."""
    import time

    def done(m):
        if m["type"] == "frame":
            frames.append((time.monotonic(), m))
        return m["type"] == "roa" and m["status"] in status

    return receive_until(ws, done, limit=100_000)


def test_region_of_attraction_is_computed_aside_and_a_bad_request_is_one_error(client,
                                                                             monkeypatch):
    """``roa``: a bad message is one error line and the session goes on; a good one is
    computed off the live loop (its frames keep coming), the slice is ``roa``'s default one
    (theta, theta_dot over the region), the LQG's level certified (with a small budget: the
    level is smaller, the protocol the same); a change of controller clears it, and a result
    the change superseded is never sent."""
    import time

    from equilibrist.web import session_roa as _session_roa

    monkeypatch.setattr(_session_roa, "MAX_BOXES", 4000)

    from equilibrist import get_system
    from equilibrist.sim.roa import default_bounds

    with client.websocket_connect("/ws") as ws:
        opening(ws)
        ws.send_text(json.dumps({"type": "roa", "grid": 64, "seq": 50}))
        err = receive_until(ws, lambda m: m["type"] in ("error", "ack", "roa"))
        assert err["type"] == "error" and "unknown field" in err["message"], err
        assert len(err["message"].splitlines()) == 1
        ws.send_text(json.dumps({"type": "roa", "seq": 51}))
        assert receive_until(ws, lambda m: m["type"] in ("error", "ack"))["seq"] == 51
        frames: list = []
        computing = _roa_until(ws, ("computing",), frames)
        began = time.monotonic()
        got = _roa_until(ws, ("slice", "failed"), frames)
        assert got["status"] == "slice", got
        assert got["id"] == computing["id"] and got["controller"] == "lqg"
        assert got["states"] == ["theta", "theta_dot"] and got["units"] == ["rad", "rad/s"]
        system = get_system("cartpole")
        x_op = np.asarray(system.operating_point().x, dtype=float)
        expected = default_bounds(system, ("theta", "theta_dot"), x_op)
        assert got["bounds"] == [list(expected["theta"]), list(expected["theta_dot"])]
        points = np.array(got["points"]).reshape(-1, 2)
        caught = np.array([c == "1" for c in got["caught"]])
        assert set(got["caught"]) == {"0", "1"} and len(points) == len(caught) == got["samples"]
        assert got["samples"] <= 1500
        # Caught near the operating point; not far out, leaning and falling the same way.
        scaled = (points - x_op[got["index"]]) / np.ptp(np.array(got["bounds"]), axis=1)
        dist = np.hypot(scaled[:, 0], scaled[:, 1])
        away = (scaled[:, 0] * scaled[:, 1] > 0) & (dist > 0.5)
        assert caught[dist < 0.05].all() and away.any() and not caught[away].any()
        assert got["certificate"] == "computing"
        cert = _roa_until(ws, ("certificate", "failed"), frames)
        assert cert["status"] == "certificate" and cert["id"] == got["id"], cert
        c = cert["certificate"]
        S2 = np.array(c["S"])
        assert S2.shape == (2, 2) and np.allclose(S2, S2.T) and np.all(np.linalg.eigvalsh(S2) > 0)
        assert c["rho"] > 0 and c["counterexamples"] == 0 and c["certified"]
        # The live loop went on meanwhile, in real time.
        wall = time.monotonic() - began
        live = [f for t, f in frames if t >= began]
        assert len(live) >= 0.25 * 40 * wall, (len(live), wall)
        assert live[-1]["t"] - live[0]["t"] >= 0.5 * (wall - 1.0), wall
        # Asked again with nothing changed: the same answer at once.
        ws.send_text(json.dumps({"type": "roa"}))
        again = _roa_until(ws, ("slice",), frames)
        assert again["id"] == got["id"] and again["points"] == got["points"]
        # Another controller clears it; a request superseded by a change is dropped.
        ws.send_text(json.dumps({"type": "tune", "controller": "swingup"}))
        _roa_until(ws, ("cleared",), frames)
        ws.send_text(json.dumps({"type": "roa"}))
        stale = _roa_until(ws, ("computing",), frames)
        ws.send_text(json.dumps({"type": "tune", "noise": 2.0}))
        _roa_until(ws, ("cleared",), frames)
        ws.send_text(json.dumps({"type": "roa"}))
        fresh = _roa_until(ws, ("computing",), frames)
        assert fresh["id"] > stale["id"]
        done = _roa_until(ws, ("slice", "failed"), frames)
        assert done["status"] == "slice" and done["id"] == fresh["id"], done
        assert done["controller"] == "swingup" and done["certificate"] is None
        # The open loop has no region to show: one error line, the session goes on.
        ws.send_text(json.dumps({"type": "tune", "controller": "off"}))
        receive_until(ws, lambda m: m["type"] == "design")
        ws.send_text(json.dumps({"type": "roa", "seq": 52}))
        refused = receive_until(ws, lambda m: m["type"] in ("error", "ack"))
        assert refused["type"] == "error" and refused["seq"] == 52
        assert "controller is off" in refused["message"]
        t1 = next_frame(ws)["t"]
        assert receive_until(ws, lambda m: m["type"] == "frame" and m["t"] > t1 + 0.2)


def test_a_flood_is_cut_and_other_sessions_do_not_notice(client, app):
    with client.websocket_connect("/ws") as calm, client.websocket_connect("/ws") as flood:
        opening(calm)
        opening(flood)
        for _ in range(400):
            flood.send_text('{"type": "kick", "angle": 0.0}')
        refused = receive_until(flood, lambda m: m["type"] == "error" and "too many" in m["message"])
        assert refused
        # The calm session still streams and still redesigns.
        t_before = next_frame(calm)["t"]
        calm.send_text(json.dumps({"type": "tune", "scales": {"theta": 0.1}}))
        assert receive_until(calm, lambda m: m["type"] == "design")
        assert next_frame(calm)["t"] > t_before
        assert len(app.state.playground.sessions) == 2
    # Disconnecting frees the sessions (the test client's socket waits for its handler to end).
    assert app.state.playground.sessions == {}


def test_session_cap_and_foreign_origin():
    app = create_app(max_sessions=1, port=8050)
    with LocalClient(app) as c:
        with c.websocket_connect("/ws") as first:
            opening(first)
            with c.websocket_connect("/ws") as second:
                msg = json.loads(second.receive_text())
                assert msg["type"] == "error" and "1 sessions at once" in msg["message"]
                with pytest.raises(WebSocketDisconnect):
                    second.receive_text()
            assert next_frame(first)
        with pytest.raises(WebSocketDisconnect), \
                c.websocket_connect("/ws", headers={"origin": "http://evil.example"}) as ws:
            ws.receive_text()
        # The port is part of the address: the same name on another port is another site.
        assert c.get("/", headers={"host": "127.0.0.1:8051"}).status_code == 400
        with pytest.raises(WebSocketDisconnect), \
                c.websocket_connect("/ws", headers={"origin": "http://127.0.0.1:8051"}) as ws:
            ws.receive_text()
        assert app.state.playground.sessions == {}


@pytest.mark.parametrize("host", ["attacker.example:8050", "attacker.example", "127.0.0.1.nip.io:8050",
                                  "localhost.attacker.example:8050", "evil", "127.0.0.1:80x",
                                  "[::1", "", "127.0.0.1:8050@attacker.example"])
def test_a_foreign_host_gets_no_page_and_no_session(client, app, host):
    """DNS rebinding: a page served from a name that resolves to this machine sends that name
    as its Host (and as the socket's Origin): no page, no file, no download, no session."""
    for path in ("/", "/static/app.js", "/favicon.ico", "/download/x/run.csv"):
        got = client.get(path, headers={"host": host})
        assert got.status_code == 400, (path, got.status_code)
        assert "not this playground's address" in got.text and "127.0.0.1" in got.text
        assert len(got.text.splitlines()) == 1 and "Traceback" not in got.text
    with pytest.raises(WebSocketDisconnect) as refused, \
            client.websocket_connect("/ws", headers={"host": host, "origin": f"http://{host}"}) as ws:
        ws.receive_text()
    assert refused.value.code == 1008
    assert app.state.playground.sessions == {}


@pytest.mark.parametrize("origin", ["http://attacker.example:8050", "null", "https://127.0.0.1:8050",
                                    "http://127.0.0.1:8050/path", "file://", "http://localhost.evil"])
def test_a_foreign_origin_gets_no_session(client, app, origin):
    with pytest.raises(WebSocketDisconnect) as refused, \
            client.websocket_connect("/ws", headers={"origin": origin}) as ws:
        ws.receive_text()
    assert refused.value.code == 1008
    assert app.state.playground.sessions == {}


@pytest.mark.parametrize("host", ["127.0.0.1:8050", "localhost:8050", "LOCALHOST:8050", "[::1]:8050"])
def test_the_loopback_names_get_the_page_and_a_session(client, host):
    assert client.get("/", headers={"host": host}).status_code == 200
    origin = f"http://{host.lower()}"
    with client.websocket_connect("/ws", headers={"host": host, "origin": origin}) as ws:
        assert opening(ws)["hello"]["token"]
    # A client that sends no Origin is a program, not a page (browsers always send one).
    with client.websocket_connect("/ws", headers={"host": host}) as ws:
        assert opening(ws)["hello"]["token"]


def test_the_accepted_hosts_are_the_loopback_names_and_the_bound_address():
    local = HostCheck.serving("127.0.0.1", 8050)
    for ok in ("127.0.0.1:8050", "localhost:8050", "[::1]:8050"):
        assert local.host_refusal(ok) is None and local.origin_refusal(f"http://{ok}") is None
    for bad in ("127.0.0.1:8051", "127.0.0.1", "attacker.example:8050", "10.0.0.2:8050",
                "[::1]:80", "localhost:08050x"):
        assert local.host_refusal(bad), bad
        assert local.origin_refusal(f"http://{bad}"), bad
    assert "no Host header" in local.host_refusal(None)
    assert local.origin_refusal(None) is None
    # --host names another address: it is accepted besides the loopback names.
    lan = HostCheck.serving("192.168.1.5", 9000)
    assert lan.host_refusal("192.168.1.5:9000") is None and lan.host_refusal("localhost:9000") is None
    assert lan.host_refusal("192.168.1.6:9000")
    named = HostCheck.serving("Box.Lan", 9000)
    assert named.host_refusal("box.lan:9000") is None and named.host_refusal("other.lan:9000")
    v6 = HostCheck.serving("fe80::1", 9000)
    assert v6.host_refusal("[fe80::1]:9000") is None
    # Every interface: any address of the machine (an address is no name DNS can turn), no name.
    wild = HostCheck.serving("0.0.0.0", 9000)
    assert wild.host_refusal("192.168.1.5:9000") is None and wild.host_refusal("[fe80::2]:9000") is None
    assert wild.host_refusal("attacker.example:9000") and wild.host_refusal("192.168.1.5:9001")
    assert wild.host_refusal("0.0.0.0:9000") is None  # the address the command prints
    # Port 80: a browser leaves it out.
    assert HostCheck.serving("127.0.0.1", 80).host_refusal("localhost") is None


def _python_control_gain(design_msg, system_name, scales, rate):
    """The LQR gain of the same weights from python-control (an independent solver)."""
    import control

    from equilibrist import get_system

    system = get_system(system_name)
    lin = system.linearize()
    sys_d = control.sample_system(control.ss(lin.A, lin.B, np.eye(lin.A.shape[0]), 0), 1 / rate)
    Q = np.diag([1 / scales[s] ** 2 for s in system.state_names])
    R = np.diag([1 / scales[i] ** 2 for i in system.input_names])
    K, _, _ = control.dlqr(sys_d.A, sys_d.B, Q, R)
    return np.asarray(K)


def test_weights_redesign_live_and_match_python_control(client):
    with client.websocket_connect("/ws") as ws:
        first = opening(ws)
        sys_msg, d0 = first["system"], first["design"]
        scales = dict(sys_msg["settings"]["scales"])
        K0 = np.array(d0["K"])
        np.testing.assert_allclose(K0, _python_control_gain(d0, "cartpole", scales, 200.0), rtol=1e-6)
        scales["theta"] = 0.02
        ws.send_text(json.dumps({"type": "tune", "scales": {"theta": 0.02}}))
        d1 = receive_until(ws, lambda m: m["type"] == "design")
        K1 = np.array(d1["K"])
        np.testing.assert_allclose(K1, _python_control_gain(d1, "cartpole", scales, 200.0), rtol=1e-6)
        assert abs(K1[0, 1]) > 2 * abs(K0[0, 1])  # a tighter angle: a stiffer angle gain
        assert d1["poles"] != d0["poles"]
        # The closed-loop poles are the eigenvalues of Ad - Bd K (discrete, |z| < 1).
        assert all(math.hypot(p["re"], p["im"]) < 1 for p in d1["poles"])


def test_a_failed_design_keeps_the_previous_controller(client):
    with client.websocket_connect("/ws") as ws:
        opening(ws)
        ws.send_text(json.dumps({"type": "select", "system": "cmg_robot"}))
        d0 = receive_until(ws, lambda m: m["type"] == "design")
        ws.send_text(json.dumps({"type": "tune", "rate": 5}))
        err = receive_until(ws, lambda m: m["type"] in ("design_error", "design"))
        assert err["type"] == "design_error"
        assert "too slow" in err["message"]
        assert err["settings"]["rate"] == 200.0
        # Still balancing with the 200 Hz controller, a second of simulated time later.
        t_err = next_frame(ws)["t"]
        frame = receive_until(ws, lambda m: m["type"] == "frame" and (m["fell"] is not None
                                                                      or m["t"] > t_err + 1.0))
        assert frame["fell"] is None and frame["controller"] == "lqg"
        ws.send_text(json.dumps({"type": "tune", "scales": {"theta": 0.04}}))
        d1 = receive_until(ws, lambda m: m["type"] == "design")
        assert d1["rate"] == 200.0 and d1["K"] != d0["K"]


def test_push_moves_the_cart_by_the_impulse(client):
    """A push of F for T seconds changes the cart's speed by F T / m, the cart's mass plus
    the part of the pole's that a push moves at once,
    m = m_c + m_p - (m_p l cos(theta))^2 / (I_p + m_p l^2).

    The controller is off (the loop would fight the push), the run starts at
    rest upright without sensor noise, so the push alone acts. The change is
    read in the controller samples the frames carry (the simulation's own
    time and input), from the sample before the push to the first one after
    it: how the frames fell on the wall clock does not matter.
    """
    with client.websocket_connect("/ws") as ws:
        first = opening(ws)
        sysm = first["system"]
        i_xdot = sysm["states"].index("x_dot")
        ws.send_text(json.dumps({"type": "tune", "noise": 0, "controller": "off"}))
        receive_until(ws, lambda m: m["type"] == "design")
        ws.send_text(json.dumps({"type": "reset", "seq": 4}))
        receive_until(ws, lambda m: m["type"] == "ack" and m["seq"] == 4)
        # Every frame after the reset's ack is of the new run: wait for one with samples.
        samples = {"t": [], "x": [], "u": []}

        def collect(m):
            if m["type"] == "frame":
                for key, values in samples.items():
                    values.extend(m["samples"][key])
            return m

        collect(receive_until(ws, lambda m: m["type"] == "frame" and len(m["samples"]["t"]) > 0))
        ws.send_text(json.dumps({"type": "push", "size": 1.0, "duration": 0.05, "seq": 5}))

        def pushed_and_over():
            u = [row[0] for row in samples["u"]]
            on = [k for k, v in enumerate(u) if v != u[0]]
            return bool(on) and any(v == u[0] for v in u[on[-1]:])

        t_sent = samples["t"][-1]
        while not pushed_and_over():
            collect(next_frame(ws))
            assert samples["t"][-1] < t_sent + 1.0, "the push did not act within 1 s of simulated time"
        u = [row[0] for row in samples["u"]]
        on = [k for k, v in enumerate(u) if v != u[0]]
        start, end = on[0], on[-1] + 1
        full = max(abs(v) for v in sysm["input_limits"][0])
        assert all(u[k] - u[0] == pytest.approx(full) for k in on)  # the push, all of it
        assert on == list(range(start, end)) and start > 0
        period = 1.0 / first["design"]["rate"]
        t = samples["t"]
        # The samples around the push are consecutive (the charts take every other one at 200 Hz).
        assert np.all(np.diff(t[start - 1:end + 1]) < 2.5 * period)
        m_c, m_p, l, i_p = 10.0, 1.0, 0.5, 0.08333  # the cart-pole's defaults
        # The pole leans a little by the time the push comes (the controller is off and
        # the process noise acts): the mass a push moves at once is that of the lean.
        lean = math.cos(samples["x"][start - 1][sysm["states"].index("theta")])
        m = m_c + m_p - (m_p * l * lean) ** 2 / (i_p + m_p * l**2)
        expected = full * 0.05 / m
        gained = samples["x"][end][i_xdot] - samples["x"][start - 1][i_xdot]
        # The process noise on the cart's rate acts during the push too (a random walk
        # of sigma per root second): four of its standard deviations, plus 2 % for the
        # pole tilting a little during the push.
        from equilibrist import get_system

        sigma = float(get_system("cartpole").spec.process_noise["x_dot"])
        walk = sigma * math.sqrt(t[end] - t[start - 1])
        assert abs(gained - expected) <= 0.02 * expected + 4 * walk


def test_controller_off_falls_and_reset_recovers(client):
    with client.websocket_connect("/ws") as ws:
        opening(ws)
        ws.send_text(json.dumps({"type": "tune", "controller": "off"}))
        receive_until(ws, lambda m: m["type"] == "design")
        ws.send_text(json.dumps({"type": "kick", "angle": 0.05}))
        fell = receive_until(ws, lambda m: m["type"] == "frame" and m["fell"] is not None, limit=600)
        assert fell["fell"]["state"] == "theta"
        ws.send_text(json.dumps({"type": "tune", "controller": "lqg"}))
        receive_until(ws, lambda m: m["type"] == "design")
        ws.send_text(json.dumps({"type": "reset", "kick": 0.1}))
        frame = receive_until(ws, lambda m: m["type"] == "frame" and m["fell"] is None)
        assert abs(frame["x"][1] - 0.1) < 0.05


def test_every_system_runs_and_draws(client):
    with client.websocket_connect("/ws") as ws:
        sys_msg = opening(ws)["system"]
        for name in sys_msg["systems"]:
            ws.send_text(json.dumps({"type": "select", "system": name}))
            desc = receive_until(ws, lambda m, n=name: m["type"] == "system" and m["name"] == n)
            frame = receive_until(ws, lambda m: m["type"] == "frame" and m["shapes"])
            assert {s["kind"] for s in frame["shapes"]} <= {"fill", "line", "hline", "text"}
            assert len(frame["x"]) == len(desc["states"])
            # Still up after 0.3 s of its own time.
            later = receive_until(ws, lambda m: m["type"] == "frame"
                                  and (m["fell"] is not None or m["t"] >= 0.3))
            assert later["fell"] is None, name


def test_downloads(client, app, tmp_path):
    from equilibrist.sim.result import SimResult

    with client.websocket_connect("/ws") as ws:
        token = opening(ws)["system"]["token"]
        ran = receive_until(ws, lambda m: m["type"] == "frame" and (m["t"] >= 0.2 or m["fell"]))
        assert ran["fell"] is None, ran["fell"]  # 40 samples run
        csv = client.get(f"/download/{token}/run.csv")
        assert csv.status_code == 200
        (tmp_path / "run.csv").write_bytes(csv.content)
        cols = SimResult.read_csv(tmp_path / "run.csv")
        assert cols["time"].size > 20 and np.all(np.diff(cols["time"]) > 0)
        np.testing.assert_allclose(np.diff(cols["time"]), 1 / 200.0, rtol=1e-6)
        npz = client.get(f"/download/{token}/run.npz")
        (tmp_path / "run.npz").write_bytes(npz.content)
        run = SimResult.load(tmp_path / "run.npz")
        assert run.system == "cartpole" and run.n_rows >= cols["time"].size
        archive = client.get(f"/download/{token}/controller.zip")
        assert archive.status_code == 200, archive.text
        names = zipfile.ZipFile(io.BytesIO(archive.content)).namelist()
        assert any(n.endswith(".h") for n in names) and any(n.endswith("Makefile") for n in names)
        ws.send_text(json.dumps({"type": "tune", "controller": "off"}))
        receive_until(ws, lambda m: m["type"] == "design")
        off = client.get(f"/download/{token}/controller.zip")
        assert off.status_code == 409 and "controller is off" in off.json()["error"]
    assert client.get(f"/download/{token}/run.csv").status_code == 404  # session gone
    assert client.get("/download/nosuch/run.csv").status_code == 404
    assert client.get("/download/x/..%2F..%2Fetc%2Fpasswd").status_code == 404


def test_a_run_is_copied_where_its_samples_are_added(client, monkeypatch):
    """The download's copy of the record is taken on the server's loop, which adds the
    samples; taken in the writing thread, a sample added between the record's time and its
    states made them disagree (a 500, 'run.csv could not be made: ValueError')."""
    import threading

    from equilibrist.web.session import Session

    threads: dict[str, set[int]] = {"advance": set(), "copy": set()}
    advance, last_run = Session.advance_to, Session.last_run

    def advancing(self, now):
        threads["advance"].add(threading.get_ident())
        return advance(self, now)

    def copying(self):
        threads["copy"].add(threading.get_ident())
        return last_run(self)

    monkeypatch.setattr(Session, "advance_to", advancing)
    monkeypatch.setattr(Session, "last_run", copying)
    with client.websocket_connect("/ws") as ws:
        token = opening(ws)["system"]["token"]
        receive_until(ws, lambda m: m["type"] == "frame" and m["t"] > 0)
        for kind in ("run.csv", "run.npz"):
            assert client.get(f"/download/{token}/{kind}").status_code == 200
    assert threads["copy"] and threads["copy"] == threads["advance"], threads


def test_user_model_path_is_offered_as_given():
    path = str(Path(__file__).parents[2] / "examples" / "my_cartpole.py")
    cat = Catalogue.default([path])
    assert cat.names[0] == path and "cartpole" in cat.names
    assert len(set(cat.names)) == len(cat.names)
    assert Catalogue.default(["cartpole"]).names.count("cartpole") == 1


# -- the command -------------------------------------------------------------------------------


def _start(*args):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "equilibrist.cli.main", "play", "--no-browser",
                             "--port", "0", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    line = proc.stdout.readline()
    return proc, line


def test_play_command_serves_and_stops_cleanly():
    import httpx

    proc, line = _start()
    try:
        assert line.startswith("equilibrist playground at http://127.0.0.1:"), line
        url = line.split()[3]
        assert httpx.get(url, timeout=10).status_code == 200
        # The same server under a name that is not this machine's: refused.
        foreign = httpx.get(url, headers={"host": "attacker.example:" + url.split(":")[2].rstrip("/")},
                            timeout=10)
        assert foreign.status_code == 400 and "not this playground's address" in foreign.text
    finally:
        proc.send_signal(signal.SIGINT)
        _out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130
    assert err.splitlines() == ["equilibrist: interrupted"], err


def test_a_script_plays_its_own_system(tmp_path):
    """A system defined in a script (System.from_definition, known only to that process) is
    offered by the playground the script serves, with the script's parameter values, and a
    page plays it: its design comes and its state moves."""
    import asyncio

    import websockets

    example = Path(__file__).parents[2] / "examples" / "my_cartpole.py"
    script = tmp_path / "play_mine.py"
    script.write_text(textwrap.dedent(f"""
        import dataclasses
        from equilibrist.numeric.system import System
        from equilibrist.web import play

        namespace = {{"__name__": "definition"}}
        exec(open({str(example)!r}).read(), namespace)
        spec = dataclasses.replace(namespace["SPEC"], name="scripted_cartpole")
        mine = System.from_definition(spec, namespace["derive"], m_c=10.0, m_p=0.7, l=0.5,
                                      I_p=0.06, b_c=0.1, b_p=0.0, g=9.8)
        play(mine, port=0, browser=False)
    """))
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    line = proc.stdout.readline()

    async def a_page() -> tuple[dict, list[float], list[float]]:
        url = line.split()[3]
        async with websockets.connect(url.replace("http://", "ws://") + "ws") as ws:
            hello = None
            states = []
            while len(states) < 20:
                msg = json.loads(await ws.recv())
                assert msg["type"] != "error", msg
                if msg["type"] == "system":
                    hello = msg
                if msg["type"] == "frame":
                    states.append(msg)
            return hello, states[0], states[-1]

    try:
        assert line.startswith("equilibrist playground at http://127.0.0.1:"), (line, proc.stderr)
        hello, first, last = asyncio.run(a_page())
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=60)
    assert hello["key"] == "scripted_cartpole" and hello["systems"] == ["scripted_cartpole"]
    params = {p["name"]: p["default"] for p in hello["params"]}
    assert params["m_p"] == 0.7 and params["I_p"] == 0.06
    assert first["t"] < last["t"]


def test_ctrl_c_while_redesigning_ends_with_one_line_and_frees_the_port():
    """Ctrl-C while a session's redesigns are under way (dozens queued): the command's one
    line, exit 130, no traceback of the cancelled designs, and the port free again."""
    import asyncio

    import websockets

    from equilibrist.web.server import bind

    proc, line = _start()
    url = line.split()[3]
    port = int(url.rstrip("/").rsplit(":", 1)[1])

    async def redesign_then_interrupt() -> None:
        async with websockets.connect(url.replace("http://", "ws://") + "ws") as ws:
            while json.loads(await ws.recv())["type"] != "design":
                pass  # the opening's design
            # Within the burst of 80; without seq, so that no acknowledgement is due: the
            # server has nothing to send them but designs.
            for i in range(70):
                await ws.send(json.dumps({"type": "tune", "controller": ("mpc", "swingup")[i % 2],
                                          "rate": 100 + i}))
            # The first redesign is done (its ack and design came), the others are queued.
            while (msg := json.loads(await ws.recv()))["type"] != "design":
                assert msg["type"] != "error", msg
            proc.send_signal(signal.SIGINT)
            with contextlib.suppress(websockets.ConnectionClosed):
                while True:
                    await ws.recv()

    try:
        asyncio.run(redesign_then_interrupt())
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        _out, err = proc.communicate(timeout=120)
    assert err.splitlines() == ["equilibrist: interrupted"], err
    assert proc.returncode == 130
    bind("127.0.0.1", port).close()  # as the next `equilibrist play --port PORT` would


def test_a_port_that_cannot_be_had_is_one_line_before_the_warm_up(monkeypatch, capsys):
    """In use, out of range, not a number: one line, exit 2, before the app is made (the app's
    warm-up, which can take a while, is never reached)."""
    import socket

    import equilibrist.web.app
    from equilibrist.cli.main import main

    def no_warm_up(*args, **kwargs):
        raise AssertionError("the app was made before the port was refused")

    monkeypatch.setattr(equilibrist.web.app, "create_app", no_warm_up)
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        busy = taken.getsockname()[1]
        for port, says in ((str(busy), f"port {busy} on 127.0.0.1 is in use"),
                           ("70000", "out of range: expected 0 to 65535"),
                           ("-1", "out of range: expected 0 to 65535"),
                           ("http", "is not a port number")):
            assert main(["play", "--no-browser", "--port", port]) == 2
            err = capsys.readouterr().err
            assert err.splitlines() == [err.strip()] and says in err, err
    assert main(["play", "--no-browser", "--host", "192.0.2.1", "--port", "0"]) == 2
    assert "not an address of this machine" in capsys.readouterr().err


def test_a_privileged_port_without_the_right_is_one_line_at_once():
    """Port 1 for a user who may not bind it (root without CAP_NET_BIND_SERVICE here)."""
    cmd = [sys.executable, "-m", "equilibrist.cli.main", "play", "--no-browser", "--port", "1"]
    if os.geteuid() == 0:
        setpriv = shutil.which("setpriv")
        assert setpriv, "setpriv (util-linux) is needed to drop root's right to bind port 1"
        cmd = [setpriv, "--bounding-set", "-net_bind_service", "--inh-caps", "-net_bind_service", *cmd]
    done = subprocess.run(cmd, check=False, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stdout + done.stderr
    assert done.stderr.splitlines() == [
        "equilibrist: error: port 1 on 127.0.0.1 is privileged and this user may not bind it: "
        "pick one from 1024 to 65535 with --port (or 0 for any free one)"], done.stderr
    assert done.stdout == ""


def test_play_command_warns_off_loopback_and_refuses_bad_input():
    proc, line = _start("--host", "0.0.0.0")
    try:
        assert "http://0.0.0.0:" in line
    finally:
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    assert "warning" in err and "no login" in err
    bad = subprocess.run([sys.executable, "-m", "equilibrist.cli.main", "play", "gyroscope",
                          "--no-browser"], check=False, capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "no input" in bad.stderr and "Traceback" not in bad.stderr
    assert Path(__file__).exists()


def test_session_runs_the_controller_contract_as_its_reference_does():
    """The session's numpy loop against the contract's own (numba-source) output and update."""
    from equilibrist.control.linear import LinearController
    from equilibrist.web.session import Session
    from equilibrist.web.session_loop import _Linear

    session = Session(Catalogue.default(), "cartpole", seed=3)
    design = session.loop.design
    ctrl = LinearController.from_design(design, kind="lqg")
    fast = _Linear(ctrl, session.system)
    rng = np.random.default_rng(0)
    z = np.array(ctrl.z0)
    for _ in range(50):
        y = ctrl.y_op + rng.normal(scale=0.05, size=len(ctrl.output_names))
        u = fast.output(y)
        np.testing.assert_allclose(u, ctrl.output(z, y), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(fast.estimate(), ctrl.estimate(z, y), rtol=1e-12, atol=1e-12)
        u_applied = np.clip(u, -50, 50)
        fast.update(u_applied)
        z = ctrl.update(z, y, (), u_applied)
        np.testing.assert_allclose(fast.z, z, rtol=1e-12, atol=1e-12)


def test_a_page_that_lags_is_not_flooded(tmp_path):
    """A page that reports the frames it drew gets no more than a dozen ahead of it
    (over a real socket: the test client hands frames over one at a time).

    How far the simulation ran while the page drew nothing is read in the
    server's own record (the run's download), not on the wall clock.
    """
    import asyncio

    import httpx
    import websockets

    from equilibrist.sim.result import SimResult

    async def recorded_until(http: httpx.AsyncClient, url: str) -> float:
        got = await http.get(url)
        assert got.status_code == 200, got.text
        (tmp_path / "run.csv").write_bytes(got.content)
        return float(SimResult.read_csv(tmp_path / "run.csv")["time"][-1])

    async def check(base: str) -> None:
        async with websockets.connect(base.replace("http://", "ws://") + "ws") as ws, \
                httpx.AsyncClient(timeout=60) as http:
            token = ""
            while (msg := json.loads(await ws.recv()))["type"] != "frame":
                token = msg.get("token", token)
            n0 = msg["n"]
            await ws.send(json.dumps({"type": "seen", "frame": n0}))
            # Twelve frames it has not drawn, and one more, come; then frames wait.
            numbers = []
            while not numbers or numbers[-1] < n0 + 13:
                if (msg := json.loads(await ws.recv()))["type"] == "frame":
                    numbers.append(msg["n"])
                    last = msg
            # The simulation runs on: until the server recorded 1 s (40 frames' time) more.
            while await recorded_until(http, f"{base}download/{token}/run.csv") < last["t"] + 1.0:
                await asyncio.sleep(0.1)
            # Whatever the server sent before this acknowledgement came before it: no frame more.
            await ws.send(json.dumps({"type": "kick", "angle": 0.0, "seq": 77}))
            while (msg := json.loads(await ws.recv()))["type"] != "ack":
                if msg["type"] == "frame":
                    numbers.append(msg["n"])
            assert max(numbers) <= n0 + 13 and len(numbers) < 30, numbers
            # Once it catches up, frames flow again, with the samples it missed.
            await ws.send(json.dumps({"type": "seen", "frame": max(numbers)}))
            while (msg := json.loads(await ws.recv()))["type"] != "frame":
                pass
            assert msg["n"] == max(numbers) + 1
            t = msg["samples"]["t"]
            assert t[0] <= last["t"] + 0.02 and t[-1] >= last["t"] + 0.99, (last["t"], t[:2], t[-2:])
            assert np.all(np.diff(t) > 0)

    proc, line = _start()
    try:
        asyncio.run(check(line.split()[3]))
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=60)


def test_no_browser_is_started_without_a_display(monkeypatch) -> None:
    """Without a display only a console browser could start, and it would take the terminal."""
    import webbrowser

    from equilibrist.web import server as play

    opened: list[str] = []

    class Recorder:
        def open(self, url: str) -> None:
            opened.append(url)

    class Started:
        started = True

    monkeypatch.setattr(webbrowser, "get", lambda *a: Recorder())
    monkeypatch.setattr(play.sys, "platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    play._open_browser("http://127.0.0.1:1/", Started())
    assert opened == []
    monkeypatch.setenv("DISPLAY", ":0")
    play._open_browser("http://127.0.0.1:1/", Started())
    assert opened == ["http://127.0.0.1:1/"]


def test_a_session_balancing_with_its_lqg_is_simulate_to_the_bit():
    """The playground's LQG is simulate's: the same design, seed and noise give the same
    states, measurements, estimates and commands, to the bit (the controller's sums in the
    core's order, not numpy's products)."""
    import dataclasses

    from equilibrist.control.linear import LinearController
    from equilibrist.sim import simulate
    from equilibrist.sim.noise import Noise
    from equilibrist.web.session import Session

    session = Session(Catalogue.default(), "cartpole", seed=5)
    session.settings = dataclasses.replace(session.settings, controller="lqg")
    session.plant = None
    x0 = session.x.copy()
    x0[1] += 0.05  # off the operating point: the loop has work to do
    session.x[:] = x0
    states, measured, estimates, commands = [], [], [], []
    for _ in range(300):
        states.append(session.x.copy())
        session._sample()
        measured.append(session.y.copy())
        estimates.append(np.array(session.xhat))
        commands.append(session.u_cmd.copy())
    rate = session.settings.rate
    ctrl = LinearController.from_design(session.loop.design, kind="lqg")
    noise = Noise.from_spec(session.system, outputs=ctrl.output_names, rate=rate)
    res = simulate(session.system, ctrl, duration=299 / rate, rate=rate,
                   physics_step=session.h, x0=x0, noise=noise, seed=5, region={})
    assert res.states.shape[0] == 300
    np.testing.assert_array_equal(np.array(states), res.states)
    np.testing.assert_array_equal(np.array(measured), res.measurements)
    np.testing.assert_array_equal(np.array(commands), res.commanded)
    np.testing.assert_array_equal(np.array(estimates), res.estimates)
    assert abs(res.states[-1, 1]) < 0.5 * abs(x0[1]) and not res.fell  # it balances


def test_the_playground_is_simulate_in_real_time():
    """A session's plant and sensors are simulate's: with the controller off and the same
    seed, its states and measurements are those of ``simulate`` with the spec's noise,
    to the bit (the core's generator, sensor noise at each sample, process noise held
    over each physics step)."""
    import dataclasses

    from equilibrist.sim import simulate
    from equilibrist.sim.noise import Noise
    from equilibrist.web.session import Session

    session = Session(Catalogue.default(), "cartpole", seed=11)
    session.settings = dataclasses.replace(session.settings, controller="off")
    session.plant = None
    x0 = session.x.copy()
    states, measured = [], []
    for _ in range(200):
        states.append(session.x.copy())
        session._sample()
        measured.append(session.y.copy())
    rate = session.settings.rate
    noise = Noise.from_spec(session.system, outputs=session.loop.outputs, rate=rate)
    res = simulate(session.system, None, duration=199 / rate, rate=rate,
                   physics_step=session.h, x0=x0, noise=noise, seed=11,
                   outputs=session.loop.outputs, region={})
    assert res.states.shape[0] == 200
    np.testing.assert_array_equal(np.array(states), res.states)
    np.testing.assert_array_equal(np.array(measured), res.measurements)
    # And the noise is there: the run is not the noise-free one.
    quiet = simulate(session.system, None, duration=199 / rate, rate=rate,
                     physics_step=session.h, x0=x0, outputs=session.loop.outputs, region={})
    assert not np.array_equal(quiet.states, res.states)
