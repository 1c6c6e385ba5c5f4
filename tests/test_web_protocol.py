"""The playground's server through Starlette's test client: the protocol, hostile messages,
live redesigns against python-control, pushes and falls against the physics, downloads."""

from __future__ import annotations

import io
import json
import math
import os
import signal
import subprocess
import sys
import time
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest

with warnings.catch_warnings():
    # Starlette asks for its httpx fork; the httpx the project installs works the same.
    warnings.simplefilter("ignore")
    from starlette.testclient import TestClient
from starlette.websockets import WebSocketDisconnect
from tests.support.web import next_frame, opening, receive_until

from equilibrist.web.app import create_app
from equilibrist.web.protocol import MAX_MESSAGE_BYTES, Limits, ProtocolError, parse
from equilibrist.web.session import Catalogue

LIMITS = Limits(("cartpole", "seesaw"), {"theta": (0.002, 20.0)}, {"m_p": (0.25, 4.0)})


@pytest.fixture(scope="module")
def app():
    return create_app(seed=7)


@pytest.fixture(scope="module")
def client(app):
    with TestClient(app) as c:
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
        time.sleep(0.2)
        assert receive_until(ws, lambda m: m["type"] == "frame" and m["t"] > t1)


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
    # Disconnecting frees the sessions.
    for _ in range(50):
        if not app.state.playground.sessions:
            break
        time.sleep(0.05)
    assert app.state.playground.sessions == {}


def test_session_cap_and_foreign_origin():
    app = create_app(max_sessions=1)
    with TestClient(app) as c:
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
        # Still balancing with the 200 Hz controller.
        time.sleep(1.0)
        frame = next_frame(ws)
        assert frame["fell"] is None and frame["controller"] == "lqg"
        ws.send_text(json.dumps({"type": "tune", "scales": {"theta": 0.04}}))
        d1 = receive_until(ws, lambda m: m["type"] == "design")
        assert d1["rate"] == 200.0 and d1["K"] != d0["K"]


def test_push_moves_the_cart_by_the_impulse(client):
    """A push of F for T seconds changes the cart's speed by about F T / (m_c + m_p).

    The controller is off (the loop would fight the push), the run starts at
    rest upright without noise, so the push alone acts.
    """
    with client.websocket_connect("/ws") as ws:
        first = opening(ws)
        sysm = first["system"]
        ws.send_text(json.dumps({"type": "tune", "noise": 0, "controller": "off"}))
        receive_until(ws, lambda m: m["type"] == "design")
        ws.send_text(json.dumps({"type": "reset"}))
        time.sleep(0.3)
        before = next_frame(ws)
        i_xdot = sysm["states"].index("x_dot")
        ws.send_text(json.dumps({"type": "push", "size": 1.0, "duration": 0.05, "seq": 5}))
        after = receive_until(ws, lambda m: m["type"] == "frame" and m["push_seq"] == 5
                              and m["push"] == 0.0)
        full = max(abs(v) for v in sysm["input_limits"][0])
        m_total = 10.0 + 1.0  # the cart-pole's default cart and pole masses
        expected = full * 0.05 / m_total
        gained = after["x"][i_xdot] - before["x"][i_xdot]
        # Frames stream while the test reads them, so "before" may be a frame or
        # two old: the band is wide, but a push that did not act, acted the
        # wrong way or ten times too hard fails it.
        assert 0.3 * expected < gained < 1.5 * expected


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
            time.sleep(0.3)
            assert next_frame(ws)["fell"] is None, name


def test_downloads(client, app, tmp_path):
    from equilibrist.sim.result import SimResult

    with client.websocket_connect("/ws") as ws:
        token = opening(ws)["system"]["token"]
        time.sleep(0.5)
        next_frame(ws)
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


def test_user_model_path_is_offered_as_given():
    path = str(Path(__file__).parents[1] / "examples" / "my_cartpole.py")
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
    finally:
        proc.send_signal(signal.SIGINT)
        _out, err = proc.communicate(timeout=20)
    assert proc.returncode == 0
    assert "Traceback" not in err and "stopped" in err


def test_play_command_warns_off_loopback_and_refuses_bad_input():
    proc, line = _start("--host", "0.0.0.0")
    try:
        assert "http://0.0.0.0:" in line
    finally:
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=20)
    assert "warning" in err and "no login" in err
    bad = subprocess.run([sys.executable, "-m", "equilibrist.cli.main", "play", "gyroscope",
                          "--no-browser"], check=False, capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "no input" in bad.stderr and "Traceback" not in bad.stderr
    assert Path(__file__).exists()


def test_session_runs_the_controller_contract_as_its_reference_does():
    """The session's numpy loop against the contract's own (numba-source) output and update."""
    from equilibrist.control.controller import LinearController
    from equilibrist.web.session import Session, _Linear

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


def test_a_page_that_lags_is_not_flooded():
    """A page that reports the frames it drew gets no more than a dozen ahead of it
    (over a real socket: the test client hands frames over one at a time)."""
    import asyncio

    import websockets

    async def check(url: str) -> None:
        async with websockets.connect(url) as ws:
            while (msg := json.loads(await ws.recv()))["type"] != "frame":
                pass
            n0 = msg["n"]
            await ws.send(json.dumps({"type": "seen", "frame": n0}))
            await asyncio.sleep(1.5)  # the page draws nothing for 60 frames' time
            numbers = []
            try:
                while True:
                    msg = json.loads(await asyncio.wait_for(ws.recv(), 0.5))
                    if msg["type"] == "frame":
                        numbers.append(msg["n"])
            except TimeoutError:
                pass
            assert numbers and max(numbers) <= n0 + 13 and len(numbers) < 30
            # Once it catches up, frames flow again, with the samples it missed.
            await ws.send(json.dumps({"type": "seen", "frame": max(numbers)}))
            while (msg := json.loads(await ws.recv()))["type"] != "frame":
                pass
            assert msg["n"] == max(numbers) + 1
            assert len(msg["samples"]["t"]) > 100  # 2 s of samples at 100 a second

    proc, line = _start()
    try:
        asyncio.run(check(line.split()[3].replace("http://", "ws://") + "ws"))
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=20)
