"""The playground's swing-up and MPC: the protocol's new values and refusals, a swing-up from
hanging and an MPC under a push through the server's test client, retunes, downloads."""

from __future__ import annotations

import io
import json
import math
import shutil
import subprocess
import time
import zipfile

import numpy as np
import pytest
from tests.support import cc_cache
from tests.support.web import LocalClient, opening, receive_until

from equilibrist.web.app import create_app
from equilibrist.web.protocol import CONTROLLERS, Limits, ProtocolError, parse
from equilibrist.web.session import Session
from equilibrist.web.session_design import Catalogue, redesign

NO_HANG = "seesaw has no hanging position"
LIMITS = Limits(("cartpole", "seesaw"), {"theta": (0.002, 20.0)}, {},
                unavailable={"swingup": NO_HANG}, hanging=NO_HANG)
OPEN = Limits(("cartpole",), {"theta": (0.002, 20.0)}, {})


@pytest.fixture(scope="module")
def app():
    return create_app(seed=11)


@pytest.fixture(scope="module")
def client(app):
    with LocalClient(app) as c:
        yield c


def wrapped(angle):
    return (angle + math.pi) % (2 * math.pi) - math.pi


# -- the protocol alone --------------------------------------------------------------------------


def test_parse_offers_the_new_controllers_and_hang():
    assert CONTROLLERS == ("lqg", "lqr", "swingup", "mpc", "tvlqr", "off")
    for c in ("swingup", "mpc", "tvlqr"):
        assert parse(json.dumps({"type": "tune", "controller": c}), OPEN).fields == {"controller": c}
    assert parse('{"type": "hang", "seq": 3}', OPEN).type == "hang"


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ('{"type": "tune", "controller": "swingup"}', "does not apply: seesaw has no hanging"),
        ('{"type": "tune", "controller": "swing-up"}', "unknown"),
        ('{"type": "tune", "controller": "MPC"}', "unknown"),
        ('{"type": "hang"}', "hang is refused: seesaw has no hanging"),
        ('{"type": "hang", "angle": 3.1}', "unknown field"),
    ],
)
def test_parse_refuses_what_does_not_apply(text, says):
    with pytest.raises(ProtocolError, match=says):
        parse(text, LIMITS)
    # MPC applies to that system: not refused.
    assert parse('{"type": "tune", "controller": "mpc"}', LIMITS).fields == {"controller": "mpc"}


# -- the server ---------------------------------------------------------------------------------


def test_picker_disables_what_does_not_apply_and_a_refusal_keeps_the_session(client):
    with client.websocket_connect("/ws") as ws:
        first = opening(ws)["system"]
        options = {o["name"]: o for o in first["controller_options"]}
        assert [o["name"] for o in first["controller_options"]] == list(CONTROLLERS)
        assert options["swingup"]["available"] and options["mpc"]["available"]
        assert first["hang"] == {"available": True, "reason": None}
        ws.send_text(json.dumps({"type": "select", "system": "seesaw"}))
        seesaw = receive_until(ws, lambda m: m["type"] == "system" and m["name"] == "seesaw")
        options = {o["name"]: o for o in seesaw["controller_options"]}
        assert not options["swingup"]["available"]
        assert "no hanging position" in options["swingup"]["reason"]
        assert options["mpc"]["available"]
        assert not seesaw["hang"]["available"]
        ws.send_text(json.dumps({"type": "tune", "controller": "swingup", "seq": 21}))
        err = receive_until(ws, lambda m: m["type"] == "error")
        assert "does not apply" in err["message"] and "seesaw" in err["message"]
        ws.send_text(json.dumps({"type": "hang", "seq": 22}))
        err = receive_until(ws, lambda m: m["type"] == "error")
        assert "hang is refused" in err["message"]
        # The session goes on with its controller (0.3 s of its time later).
        t0 = receive_until(ws, lambda m: m["type"] == "frame")["t"]
        frame = receive_until(ws, lambda m: m["type"] == "frame" and (m["fell"] or m["t"] > t0 + 0.3))
        assert frame["controller"] == "lqg" and frame["fell"] is None


def test_swingup_from_hanging_comes_up_and_balances(client):
    """Hanging at rest (theta = pi), the swing-up pumps, hands over and balances upright.

    The judge is the state itself: the pole within 0.1 rad of upright and its rate
    small, the cart on its 1 m track all along; the mode goes from pumping to balancing.
    """
    with client.websocket_connect("/ws") as ws:
        sysm = opening(ws)["system"]
        i_th, i_x = sysm["states"].index("theta"), sysm["states"].index("x")
        i_thd = sysm["states"].index("theta_dot")
        ws.send_text(json.dumps({"type": "tune", "controller": "swingup"}))
        d = receive_until(ws, lambda m: m["type"] == "design")
        assert d["controller"] == "swingup" and d["controller_info"]["kind"] == "swingup"
        ws.send_text(json.dumps({"type": "hang", "seq": 8}))
        receive_until(ws, lambda m: m["type"] == "ack" and m["seq"] == 8)
        # Every frame after the ack is of the hanging run; its first sample is the start.
        start = receive_until(ws, lambda m: m["type"] == "frame" and len(m["samples"]["t"]) > 0)
        assert start["hanging"] and start["samples"]["t"][0] == 0.0
        assert abs(abs(start["samples"]["x"][0][i_th]) - math.pi) < 0.06
        modes, xs, t_up = [], [], None
        while True:
            f = receive_until(ws, lambda m: m["type"] == "frame")
            assert f["fell"] is None, f["fell"]
            if f["mode"]:
                modes.append(f["mode"])
            xs.append(f["x"])
            if f["mode"] == "balancing" and abs(wrapped(f["x"][i_th])) < 0.1 and abs(f["x"][i_thd]) < 0.5:
                t_up = f["t"]
                break
            assert f["t"] < 8.0, "not up after 8 s of simulated time"
        assert modes[0] == "pumping" and modes[-1] == "balancing"
        assert 0.5 < t_up < 8.0
        # It stays up.
        f = receive_until(ws, lambda m: m["type"] == "frame" and m["t"] > t_up + 1.0)
        assert f["mode"] == "balancing" and abs(wrapped(f["x"][i_th])) < 0.1
        assert max(abs(x[i_x]) for x in xs) < 1.0
        # Back to LQG: the angle is taken within half a turn of upright and it keeps balancing.
        ws.send_text(json.dumps({"type": "tune", "controller": "lqg"}))
        receive_until(ws, lambda m: m["type"] == "design")
        t0 = receive_until(ws, lambda m: m["type"] == "frame" and m["controller"] == "lqg")["t"]
        f = receive_until(ws, lambda m: m["type"] == "frame" and (m["fell"] or m["t"] > t0 + 0.5))
        assert f["fell"] is None and abs(f["x"][i_th]) < 0.2


def test_swingup_chosen_upright_just_balances_and_survives_a_retune(client):
    with client.websocket_connect("/ws") as ws:
        sysm = opening(ws)["system"]
        i_th = sysm["states"].index("theta")
        ws.send_text(json.dumps({"type": "tune", "controller": "swingup"}))
        receive_until(ws, lambda m: m["type"] == "design")
        f = receive_until(ws, lambda m: m["type"] == "frame" and m["mode"] is not None)
        assert f["mode"] == "balancing"
        ws.send_text(json.dumps({"type": "tune", "scales": {"theta": 0.05}}))
        d = receive_until(ws, lambda m: m["type"] == "design")
        assert d["controller"] == "swingup"
        t0 = receive_until(ws, lambda m: m["type"] == "frame")["t"]
        receive_until(ws, lambda m: m["type"] == "frame" and (m["fell"] or m["t"] > t0 + 0.5))
        frames = [receive_until(ws, lambda m: m["type"] == "frame") for _ in range(20)]
        assert all(fr["mode"] == "balancing" and fr["fell"] is None for fr in frames)
        assert all(abs(fr["x"][i_th]) < 0.2 for fr in frames)
        # A new rate and a new actuator limit redesign the swing-up too.
        ws.send_text(json.dumps({"type": "tune", "rate": 100, "limit": 0.8}))
        d = receive_until(ws, lambda m: m["type"] == "design")
        assert d["controller"] == "swingup" and d["rate"] == 100.0
        assert d["controller_info"]["c_in"] > 0
        t0 = receive_until(ws, lambda m: m["type"] == "frame")["t"]
        f = receive_until(ws, lambda m: m["type"] == "frame" and (m["fell"] or m["t"] > t0 + 0.5))
        assert f["mode"] == "balancing" and f["fell"] is None
        assert f["u_limits"][1][0] == pytest.approx(0.8 * sysm["input_limits"][0][1])


def test_mpc_holds_a_push_within_its_limits(client):
    """Under MPC a push of half the full scale is rejected, every command within the hard limits."""
    with client.websocket_connect("/ws") as ws:
        sysm = opening(ws)["system"]
        i_th = sysm["states"].index("theta")
        ws.send_text(json.dumps({"type": "tune", "controller": "mpc"}))
        d = receive_until(ws, lambda m: m["type"] == "design")
        info = d["controller_info"]
        assert d["controller"] == "mpc" and info["kind"] == "mpc" and info["horizon"] >= 1
        assert d["controller_milliseconds"] > 0
        ws.send_text(json.dumps({"type": "push", "size": 0.5, "seq": 40}))
        receive_until(ws, lambda m: m["type"] == "ack" and m["seq"] == 40)
        lo, hi = sysm["input_limits"][0]
        frames = [receive_until(ws, lambda m: m["type"] == "frame")]
        while frames[-1]["t"] < frames[0]["t"] + 3.0:  # 3 s of simulated time after the push
            f = receive_until(ws, lambda m: m["type"] == "frame")
            assert f["fell"] is None and f["controller"] == "mpc"
            frames.append(f)
        # Every frame after the ack is stamped with the push (taken: it acts for 0.1 s).
        assert all(f["push_seq"] == 40 and f["pushes"] == 1 for f in frames)
        for f in frames:
            assert lo - 1e-9 <= f["u_cmd"][0] <= hi + 1e-9
        assert abs(frames[-1]["x"][i_th]) < 0.1
        solve = frames[-1]["solve"]
        assert 0 < solve["median_ms"] <= solve["worst_ms"] and solve["samples"] > 0


def test_downloads_of_the_swingup_and_the_mpc(client, tmp_path, tmp_path_factory):
    with client.websocket_connect("/ws") as ws:
        token = opening(ws)["system"]["token"]
        ws.send_text(json.dumps({"type": "tune", "controller": "swingup"}))
        receive_until(ws, lambda m: m["type"] == "design")
        got = client.get(f"/download/{token}/controller.zip")
        assert got.status_code == 200, got.text
        assert "swingup" in got.headers["content-disposition"]
        zipfile.ZipFile(io.BytesIO(got.content)).extractall(tmp_path)
        folder = tmp_path / "cartpole_swingup"
        assert {"swingup.c", "swingup.h", "Makefile"} <= {p.name for p in folder.iterdir()}
        # The exported law, compiled, gives the Python controller's commands (its own check).
        make = shutil.which("make")
        assert make is not None, "make is missing"
        done = subprocess.run([make, "-s", "-C", str(folder), "check"], check=False,
                              capture_output=True, text=True,
                              timeout=120)
        assert done.returncode == 0, done.stdout + done.stderr
        ws.send_text(json.dumps({"type": "tune", "controller": "mpc"}))
        receive_until(ws, lambda m: m["type"] == "design")
        # The export's measurement (make size) compiles DAQP's sources once a run too.
        with cc_cache.cached_measure(cc_cache.folder(tmp_path_factory)):
            got = client.get(f"/download/{token}/controller.zip")
        assert got.status_code == 200, got.text
        names = zipfile.ZipFile(io.BytesIO(got.content)).namelist()
        assert "cartpole_mpc/mpc.c" in names and any(n.startswith("cartpole_mpc/daqp/src/") for n in names)
        zipfile.ZipFile(io.BytesIO(got.content)).extractall(tmp_path)
        # DAQP's sources and the driver, compiled, replay the Python MPC's recorded commands
        # (DAQP's unchanged sources compile once a run: support.cc_cache).
        done = subprocess.run([make, "-s", "-C", str(tmp_path / "cartpole_mpc"), "check"], check=False,
                              capture_output=True, text=True, timeout=300,
                              env=cc_cache.environment(cc_cache.folder(tmp_path_factory)))
        assert done.returncode == 0, done.stdout + done.stderr


def test_a_failed_mpc_design_keeps_the_mpc(client):
    with client.websocket_connect("/ws") as ws:
        opening(ws)
        ws.send_text(json.dumps({"type": "select", "system": "cmg_robot"}))
        receive_until(ws, lambda m: m["type"] == "design")
        ws.send_text(json.dumps({"type": "tune", "controller": "mpc"}))
        receive_until(ws, lambda m: m["type"] == "design" and m["controller"] == "mpc")
        ws.send_text(json.dumps({"type": "tune", "rate": 5}))
        err = receive_until(ws, lambda m: m["type"] in ("design_error", "design"))
        assert err["type"] == "design_error" and err["controller"] == "mpc"
        t0 = receive_until(ws, lambda m: m["type"] == "frame")["t"]
        f = receive_until(ws, lambda m: m["type"] == "frame" and (m["fell"] or m["t"] > t0 + 0.5))
        assert f["controller"] == "mpc" and f["fell"] is None and f["solve"] is not None


def test_a_loop_that_cannot_keep_up_says_so():
    """A controller slower than the sample period: a warning frame, not a silent slowdown."""
    session = Session(Catalogue.default(), "cartpole", seed=3)
    settings = session.settings.changed({"controller": "mpc"})
    system = session.prepare(settings)
    session.install(settings, system, *redesign(system, settings))
    runner = session.loop.runner
    assert runner is not None and runner.kind == "mpc"
    fast = runner.output

    def slow(t, y):
        time.sleep(1.5 * session.period)
        return fast(t, y)

    runner.output = slow  # type: ignore[method-assign]
    session.take_messages()
    clock = 100.0
    session.advance_to(clock)
    for _ in range(4):
        clock += 0.05
        session.advance_to(clock)
    warns = [m for m in session.take_messages() if m["type"] == "warning"]
    assert len(warns) == 1  # one warning, not one per frame
    assert "cannot keep real time" in warns[0]["message"]
    assert np.isfinite(session.x).all()
