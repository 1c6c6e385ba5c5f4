"""Identification: logs, parameter files, excitations, and fits against known truths.

The truths are independent of the fit: logs are recorded by the project's
own closed-loop simulator on a plant whose parameters are set apart from the
defaults the fit starts from; the shift register's period is the textbook
2^11 - 1; the chirp's frequency is read off its zero crossings.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.cli.main import main
from equilibrist.control.design import design
from equilibrist.errors import SimulationError
from equilibrist.ident import Log, identify, read_log, read_params
from equilibrist.sim.controllers import LQG
from equilibrist.sim.noise import Noise
from equilibrist.sim.result import SimResult
from equilibrist.sim.run import simulate
from equilibrist.sim.signals import PRBS, Chirp, parse_excitation


def _run(sysm, nominal, *, seed, duration, excitation):
    d = design(nominal, rate=nominal.spec.control_rate)
    return simulate(sysm, LQG.from_design(d), duration=duration, noise=Noise.from_design(d),
                    seed=seed, excitation=excitation)


@pytest.fixture(scope="module")
def cart_csv(tmp_path_factory):
    """A 6 s closed-loop log of a cart-pole with a heavier pole, written by the CLI."""
    path = tmp_path_factory.mktemp("ident") / "run.csv"
    assert main(["simulate", "cartpole", "--duration", "6", "--excite", "prbs:20:0.2",
                 "--set", "m_p=1.3", "--seed", "3", "--out", str(path), "--json"]) == 0
    return path


# -- signals ------------------------------------------------------------------------


def test_prbs_is_a_maximal_length_sequence():
    bits = PRBS(1.0, 0.1, seed=5).bits(2 * 2047)
    assert np.array_equal(bits[:2047], bits[2047:])  # period 2^11 - 1 ...
    assert not any(np.array_equal(bits[:100], bits[k:k + 100]) for k in range(1, 2047))  # ... no shorter
    assert int(bits[:2047].sum()) == 1024  # a maximal-length sequence has 2^(n-1) ones
    assert not np.array_equal(bits[:50], PRBS(1.0, 0.1, seed=6).bits(50))  # the seed picks the phase
    t = np.arange(0, 1, 0.01)
    v = PRBS(2.5, 0.1, seed=1).evaluate(t, np.zeros(1))[:, 0]
    assert set(np.round(v, 12)) <= {-2.5, 2.5}
    assert np.all(v[:10] == v[0]) and np.all(v[10:20] == v[10])  # held for a period


def test_chirp_sweeps_its_frequency_linearly():
    t = np.arange(0.0, 10.0, 1e-4)
    v = Chirp(3.0, 1.0, 5.0).evaluate(t, np.zeros(1))[:, 0]
    assert np.max(np.abs(v)) == pytest.approx(3.0, rel=1e-4) and v[0] == 0.0
    up = np.nonzero((v[:-1] < 0) & (v[1:] >= 0))[0]
    freq = 1.0 / np.diff(t[up])
    mid = 0.5 * (t[up][1:] + t[up][:-1])
    np.testing.assert_allclose(freq, 1.0 + 0.4 * mid, rtol=0.02)  # f0 + (f1 - f0) t / T


def test_excitation_is_added_to_the_command_before_saturation():
    cart = get_system("cartpole")
    excite = PRBS(30.0, 0.05, seed=2)
    with_e = _run(cart, cart, seed=1, duration=1.0, excitation=excite)
    d = design(cart, rate=200.0)
    without = simulate(cart, LQG.from_design(d), duration=1.0, noise=Noise.from_design(d), seed=1)
    # Same noise, same start: the first command differs by exactly the signal.
    signal = excite.evaluate(with_e.time, np.zeros(1))[:, 0]
    assert with_e.commanded[0, 0] - without.commanded[0, 0] == pytest.approx(signal[0])
    assert with_e.settings["excitation"]["kind"] == "prbs"
    lo, hi = cart.input_limits
    assert np.all(with_e.applied >= lo[0]) and np.all(with_e.applied <= hi[0])


@pytest.mark.parametrize("text", ["chirp:1:2", "prbs:1", "prbs:1:0", "chirp:a:1:2", "sine:1:2",
                                  "chirp:1:-1:2", "prbs:nan:0.1"])
def test_bad_excitations_are_one_line(text, capsys):
    with pytest.raises(SimulationError, match="excitation"):
        parse_excitation(text)
    assert main(["simulate", "cartpole", "--duration", "0.1", "--excite", text]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "excitation" in err


# -- logs -----------------------------------------------------------------------------


def test_a_simulated_run_is_a_valid_log(cart_csv):
    cart = get_system("cartpole")
    log = read_log(cart, cart_csv)
    run = SimResult.load(cart_csv)  # the same file is also the whole run
    assert log.output_names == ("x", "theta")
    np.testing.assert_array_equal(log.time, run.time)
    np.testing.assert_array_equal(log.inputs[:, 0], run.input("F"))
    np.testing.assert_array_equal(log.output("theta"), run.measurement("theta"))
    header = cart_csv.read_text().splitlines()[2]
    assert header.startswith("t [s],F [N],x [m],theta [rad],")


def _write(path, header, rows):
    path.write_text(header + "\n" + "\n".join(",".join(str(v) for v in r) for r in rows) + "\n")
    return path


GOOD = [(0.0, 1.0, 0.0, 0.01), (0.005, 1.5, 0.0001, 0.012), (0.01, 2.0, 0.0003, 0.013)]


@pytest.mark.parametrize(
    ("header", "rows", "message"),
    [
        ("t,x,theta", [r[:1] + r[2:] for r in GOOD], "no column for the input 'F'"),
        ("t,F", [r[:2] for r in GOOD], "no measured output"),
        ("F,x,theta", [r[1:] for r in GOOD], "no time column 't'"),
        ("t,F,x,theta", [GOOD[0], GOOD[2], GOOD[1]], "does not increase at data row 3"),
        ("t,F,x,theta", [GOOD[0], (0.005, "nan", 0.0, 0.0), GOOD[2]], "column 'F' has a value that is not a finite"),
        ("t,F,x,theta", GOOD[:1], "a single row"),
        ("t,F,x,theta", [], "no rows"),
        ("t,F,x,theta,phi", [(*r, 0.0) for r in GOOD], "column 'phi' is not a state or input of cartpole"),
        ("t,tau,x,theta", GOOD, "column 'tau' is not a state or input of cartpole"),
        ("t,F,x [mm],theta", GOOD, "is in [mm], expected [m]"),
        ("t,F,x,theta", [GOOD[0], (0.005, 1.0, "abc", 0.0)], "'abc' is not a number"),
        ("t,F,x,x", GOOD, "appears twice"),
    ],
)
def test_bad_logs_are_one_line_and_exit_2(tmp_path, capsys, header, rows, message):
    path = _write(tmp_path / "log.csv", header, rows)
    out = tmp_path / "params.json"
    assert main(["identify", "cartpole", str(path), "--free", "m_p", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert message in err
    assert not out.exists()  # nothing half-written


@pytest.mark.parametrize(
    ("free", "message"),
    [("m_q", "unknown parameter 'm_q' of cartpole: did you mean 'm_p'?"),
     ("F_max", "F_max is an input limit"),
     ("m_p,m_p", "m_p is free twice")],
)
def test_bad_free_parameters_are_one_line(cart_csv, capsys, free, message):
    assert main(["identify", "cartpole", str(cart_csv), "--free", free]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err


def test_a_log_of_another_system_is_refused(cart_csv, capsys):
    assert main(["identify", "reaction_wheel_pendulum", str(cart_csv), "--free", "m"]) == 2
    assert "column 'F' is not a state or input of reaction_wheel_pendulum" in capsys.readouterr().err


def test_missing_log_and_bad_outputs(tmp_path, capsys):
    assert main(["identify", "cartpole", str(tmp_path / "none.csv"), "--free", "m_p"]) == 2
    assert "no log file" in capsys.readouterr().err
    assert main(["identify", "cartpole", str(tmp_path / "none.csv"), "--free", "m_p",
                 "--out", "p.txt"]) == 2
    assert ".json" in capsys.readouterr().err
    assert main(["identify", "cartpole", str(tmp_path / "none.csv"), "--free", "m_p",
                 "--plot", "fit.bmp"]) == 2
    assert "unsupported format" in capsys.readouterr().err


# -- the fit --------------------------------------------------------------------------


def test_identify_from_the_command_line_then_design_on_the_result(cart_csv, tmp_path, capsys):
    out = tmp_path / "params.json"
    png = tmp_path / "fit.png"
    assert main(["identify", "cartpole", str(cart_csv), "--free", "m_p", "--json",
                 "--out", str(out), "--plot", str(png)]) == 0
    doc = json.loads(capsys.readouterr().out)
    est = doc["estimates"]["m_p"]
    assert abs(est["value"] - 1.3) < 3 * est["std_error"]
    assert doc["method"]["name"] == "prediction error"
    assert doc["method"]["start"] == "multiple shooting"
    assert set(doc["outputs"]) == {"x", "theta"}
    assert 0 < doc["outputs"]["theta"]["nrmse"] < 0.5
    assert doc["outputs"]["x"]["whiteness"]["test"] == "Ljung-Box"
    assert png.read_bytes()[:4] == b"\x89PNG"
    params = read_params(out, "cartpole")
    assert params["m_p"] == pytest.approx(est["value"])
    assert params["m_c"] == 10.0  # the others as they were
    # design --params is design --set of the same values.
    assert main(["design", "cartpole", "--params", str(out), "--json"]) == 0
    from_file = json.loads(capsys.readouterr().out)
    assert main(["design", "cartpole", "--set", f"m_p={params['m_p']!r}", "--json"]) == 0
    by_hand = json.loads(capsys.readouterr().out)
    assert from_file["K"] == by_hand["K"]
    # --set overrides the file; a file of another system is refused.
    assert main(["simulate", "cartpole", "--params", str(out), "--set", "m_p=2", "--duration",
                 "0.2", "--json"]) == 0
    capsys.readouterr()
    assert main(["export", "seesaw", "--params", str(out), "--out", str(tmp_path / "c")]) == 2
    assert "holds parameters of cartpole, not of seesaw" in capsys.readouterr().err


def test_an_unidentifiable_pair_is_named_not_estimated():
    """In the servo ball and beam the ball's mass and friction enter only as b/m."""
    servo = get_system("ball_beam_servo", b=0.3)
    plant = servo.with_params(m=0.08, b=0.5)
    run = _run(plant, servo, seed=0, duration=3.0, excitation=PRBS(0.5, 0.2, seed=0))
    log = Log.from_arrays(servo, run.time, run.applied,
                          {o: run.measurement(o) for o in run.output_names})
    result = identify(servo, log, ["m", "b"], reestimate_noise=False)
    text = " ".join(result.unidentifiable)
    assert "m and b only appear as m/b" in text or "b and m only appear as b/m" in text
    assert all(not np.isfinite(e.std_error) for e in result.estimates)
    assert "not determined" in result.summary()


def test_compiled_and_solve_ivp_replays_agree():
    """The compiled RK4 segments against scipy's adaptive integrator on the same log."""
    cart = get_system("cartpole")
    d = design(cart, rate=200.0)
    run = simulate(cart.with_params(m_p=1.2), LQG.from_design(d), duration=0.5,
                   excitation=PRBS(10.0, 0.05, seed=2), x0={"theta": 0.05})
    log = Log.from_arrays(cart, run.time, run.applied, {o: run.measurement(o) for o in run.output_names})
    from equilibrist.ident.shooting import _shooter

    bounds = np.array([0, 17, 34, 51, 68, 85, 100], dtype=np.int64)
    xs = run.states[bounds[:-1]][None]
    p = np.array(cart.with_params(m_p=1.2).p)[None]
    n_sub = np.full(100, 5, dtype=np.int64)
    c_idx = np.array([0, 1], dtype=np.int64)
    out = {}
    for backend in ("compiled", "solve_ivp"):
        yhat = np.empty((1, 101, 2))
        xend = np.empty((1, 6, 4))
        _shooter(cart, backend)(p, xs, bounds, log.time, log.inputs, n_sub, c_idx, yhat, xend)
        out[backend] = (yhat, xend)
    np.testing.assert_allclose(out["compiled"][0], out["solve_ivp"][0], atol=1e-8)
    np.testing.assert_allclose(out["compiled"][1], out["solve_ivp"][1], atol=1e-7)
    # Without noise, the replay from the true state is the simulator's run itself
    # (the same RK4 steps of 1 ms with the input held).
    np.testing.assert_allclose(out["compiled"][0][0, :, :], run.states[:, :2], atol=1e-12)
    np.testing.assert_allclose(out["compiled"][1][0, :-1], run.states[bounds[1:-1]], atol=1e-12)


def test_compiled_and_solve_ivp_filters_agree():
    """The Kalman filter's prediction errors (the fit's residuals): compiled RK4
    against scipy's adaptive integrator, and without noise from the true state
    and parameters, zero (the filter predicts the simulator's run exactly)."""
    cart = get_system("cartpole")
    d = design(cart, rate=200.0)
    run = simulate(cart.with_params(m_p=1.2), LQG.from_design(d), duration=0.5,
                   excitation=PRBS(10.0, 0.05, seed=2), x0={"theta": 0.05})
    log = Log.from_arrays(cart, run.time, run.applied, {o: run.measurement(o) for o in run.output_names})
    from equilibrist.ident.prediction import _filter

    p = np.array(cart.with_params(m_p=1.2).p)
    n_sub = np.full(100, 5, dtype=np.int64)
    c_idx = np.array([0, 1], dtype=np.int64)
    gain = np.random.default_rng(0).uniform(0.0, 0.5, (4, 2))
    out = {}
    for backend in ("compiled", "solve_ivp"):
        for x0, y in ((run.states[0], log.outputs), (run.states[0] + 0.01, log.outputs + 0.003)):
            e = np.empty((101, 2))
            _filter(cart, backend)(p, x0.copy(), log.time, log.inputs, n_sub, c_idx, gain, y,
                                   np.array([0.001, 0.0]), e)
            out[backend, float(x0[0])] = e
    for key in [k for k in out if k[0] == "compiled"]:
        np.testing.assert_allclose(out[key], out["solve_ivp", key[1]], atol=1e-8)
    # From the true state and parameters, the errors are zero: the filter predicts
    # the simulator's run exactly (the same RK4 steps of 1 ms with the input held).
    e = np.empty((101, 2))
    _filter(cart, "compiled")(p, run.states[0].copy(), log.time, log.inputs, n_sub, c_idx, gain,
                              log.outputs, np.zeros(2), e)
    np.testing.assert_allclose(e, 0.0, atol=1e-12)
