"""The playground through a rig's effects: the ``rig`` field of ``tune``, checked; a session
with a rig is ``simulate``'s run with that rig and seed, to the bit."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from tests.support.web import LocalClient, opening, receive_until

from equilibrist.sim.rig import Rig
from equilibrist.web.app import create_app
from equilibrist.web.protocol import Limits, ProtocolError, parse
from equilibrist.web.session_design import Catalogue

LIMITS = Limits(systems=("cartpole",), scales={"theta": (1e-4, 10.0)}, params={})
EFFECTS = {"torque_response": 0.6, "measurement_delay": 2, "actuation_delay": 1,
           "torque_noise": 0.3, "velocity_noise": 0.02, "encoder_step": 1e-3,
           "velocity_filter": 20.0}


@pytest.mark.parametrize(("text", "expected"), [
    ('{"type": "tune", "rig": 3}', "rig must be an object"),
    ('{"type": "tune", "rig": {"perturbations": 2}}', "rig has no effect \"perturbations\""),
    ('{"type": "tune", "rig": {"torque_lag": 2}}', "rig has no effect \"torque_lag\""),
    ('{"type": "tune", "rig": {"measurement_delay": 1.5}}', "whole number of samples"),
    ('{"type": "tune", "rig": {"torque_noise": -1}}', "out of range"),
    ('{"type": "tune", "rig": {"velocity_noise": "a lot"}}', "rig.velocity_noise"),
])
def test_a_bad_rig_is_one_line(text: str, expected: str) -> None:
    with pytest.raises(ProtocolError, match=expected) as info:
        parse(text, LIMITS)
    assert "\n" not in str(info.value)


def test_the_rig_field_is_taken() -> None:
    fields = parse(json.dumps({"type": "tune", "rig": EFFECTS}), LIMITS).fields
    assert fields == {"rig": EFFECTS}
    assert isinstance(fields["rig"]["measurement_delay"], int)
    assert parse('{"type": "tune", "rig": {}}', LIMITS).fields == {"rig": {}}  # off


def test_a_session_through_a_rig_is_simulate_to_the_bit() -> None:
    """The playground's LQG through a rig is simulate's with the same rig, design, seed and
    noise: states, measurements (through the encoders, delay, velocity noise and filter) and
    commands, to the bit."""
    from equilibrist.control.linear import LinearController
    from equilibrist.sim import simulate
    from equilibrist.sim.noise import Noise
    from equilibrist.web.session import Session

    session = Session(Catalogue.default(), "cartpole", seed=5)
    settings = session.handle(parse(json.dumps({"type": "tune", "rig": EFFECTS}), session.limits))
    assert settings is not None
    session.settings = dataclasses.replace(settings, controller="lqg")
    session.plant = None
    x0 = session.x.copy()
    x0[1] += 0.05
    session.x[:] = x0
    states, measured, commands, acted = [], [], [], []
    for _ in range(300):
        states.append(session.x.copy())
        session._sample()
        measured.append(session.y.copy())
        commands.append(session.u_cmd.copy())
        acted.append(session.u_app.copy())
    rate = session.settings.rate
    ctrl = LinearController.from_design(session.loop.design, kind="lqg")
    noise = Noise.from_spec(session.system, outputs=ctrl.output_names, rate=rate)
    res = simulate(session.system, ctrl, duration=299 / rate, rate=rate, physics_step=session.h,
                   x0=x0, noise=noise, seed=5, region={}, rig=Rig(**EFFECTS))
    assert res.states.shape[0] == 300
    np.testing.assert_array_equal(np.array(states), res.states)
    np.testing.assert_array_equal(np.array(measured), res.measurements)
    np.testing.assert_array_equal(np.array(commands), res.commanded)
    np.testing.assert_array_equal(np.array(acted), res.applied)
    # The rig acted: the torque is not the command, the velocity not the state's.
    assert not np.array_equal(res.applied, res.saturated)
    assert not res.fell


def test_a_rig_is_tuned_through_the_protocol() -> None:
    """Over the websocket: a ``tune`` with a rig is taken (the settings say so), one the rig
    refuses at the session's rate is one error line, and the session goes on."""
    with LocalClient(create_app(seed=3)) as client, client.websocket_connect("/ws") as ws:
        opening(ws)
        ws.send_text(json.dumps({"type": "tune", "rig": {"measurement_delay_time": 0.0013},
                                 "seq": 5}))
        err = receive_until(ws, lambda m: m["type"] in ("error", "ack"))
        assert err["type"] == "error" and err["seq"] == 5, err
        assert "whole number of periods" in err["message"]
        assert len(err["message"].splitlines()) == 1
        ws.send_text(json.dumps({"type": "tune", "rig": EFFECTS, "seq": 6}))
        receive_until(ws, lambda m: m["type"] == "design")
        ws.send_text(json.dumps({"type": "full"}))
        system = receive_until(ws, lambda m: m["type"] == "system")
        assert system["settings"]["rig"] == EFFECTS
        frame = receive_until(ws, lambda m: m["type"] == "frame")
        assert frame["t"] >= 0
