"""Swing-up: the pumped energy against the derived model, its monotone rise, the catch."""

from __future__ import annotations

import math

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.control.nonlinear import NonlinearController
from equilibrist.control.swingup import (
    SwingUpRuntime,
    SwingUpTuning,
    catch_level,
    swingup,
    swingup_laws,
    tracking_gains,
)
from equilibrist.control.swingup_law import CP, MODE_BALANCE, Z, energy
from equilibrist.controllers.kinds import ControllerRequest, build_controller
from equilibrist.errors import ControllerError
from equilibrist.sim.run import simulate
from equilibrist.tasks import get_task

PENDULUMS = ("cartpole", "reaction_wheel_pendulum", "furuta")


def _pendulum_part(name: str, x: np.ndarray) -> np.ndarray:
    """The state with the drive at rest, so the derived total energy is the pendulum's."""
    x = np.array(x, dtype=float)
    if name != "acrobot":
        x[2] = 0.0
    return x


@pytest.mark.parametrize("name", [*PENDULUMS, "acrobot"])
def test_energy_is_the_derived_models(name: str) -> None:
    """The law's energy equals the derived model's (sympy) energy, measured from upright."""
    system = get_system(name)
    ctrl = swingup(system)
    up = system.operating_point().x
    rng = np.random.default_rng(3)
    for _ in range(20):
        x = up + rng.uniform(-3.0, 3.0, 4)
        xp = _pendulum_part(name, x)
        truth = system.energy(xp) - system.energy(_pendulum_part(name, up))
        assert energy(xp, ctrl) == pytest.approx(truth, rel=1e-10, abs=1e-12)
    hanging = get_task(system, "swingup").start
    # Hanging at rest is the lowest energy: minus the lift from hanging to upright.
    assert energy(hanging, ctrl) < 0


def test_alpha_beta_gains_are_kalatas() -> None:
    """Kalata's steady-state gains satisfy the alpha-beta filter's Riccati relation."""
    for lam in (0.01, 0.3, 5.0):
        a, b = tracking_gains(1.0, lam, 1.0)
        # beta^2 / (1 - alpha) = lambda^2 (Kalata 1984, eq. 18).
        assert b * b / (1.0 - a) == pytest.approx(lam * lam, rel=1e-9)


def test_catch_level_is_where_the_lqr_saturates() -> None:
    """On the ellipse dx' S dx = c_sat the largest LQR command is exactly the room to the limit."""
    rng = np.random.default_rng(0)
    K = rng.normal(size=(1, 4))
    L = rng.normal(size=(4, 4))
    S = L @ L.T + 4 * np.eye(4)
    c = catch_level(K, S, np.array([2.0]))
    # The maximizer of K dx on the ellipse: dx = sqrt(c) S^-1 K' / sqrt(K S^-1 K').
    g = np.linalg.solve(S, K[0])
    dx = math.sqrt(c) * g / math.sqrt(K[0] @ g)
    assert dx @ S @ dx == pytest.approx(c)
    assert float(K[0] @ dx) == pytest.approx(2.0)


@pytest.mark.parametrize("name", PENDULUMS)
def test_pumping_energy_rises_monotonically(name: str) -> None:
    """Pure pumping (no centering, no catch, no noise): E never falls until it reaches E0.

    In continuous time ``dE/dt = -c k_E (E - E0) |theta_dot cos theta| >= 0``
    (minus the pendulum joint's small friction); a sample-and-hold command
    can lose at most what one sample of a sign change costs, far below
    1e-3 of the lift ``-E(hanging)``.
    """
    system = get_system(name)
    base = swingup(system).settings["tuning"]
    tune = SwingUpTuning(k_energy=base["k_energy"], a_max=base["a_max"], catch_fraction=0.0,
                         accel=base["accel"])
    ctrl = swingup(system, tuning=tune)
    task = get_task(system, "swingup")
    res = simulate(system, ctrl, duration=6.0, x0=task.draw_initial(np.random.default_rng(1)),
                   region={})
    E = np.array([energy(x, ctrl) for x in res.states])
    lift = -E[0]
    reached = int(np.argmax(-1e-3 * lift <= E)) if np.any(-1e-3 * lift <= E) else len(E)
    assert reached > 10, "the pendulum must take some swings"
    assert reached < len(E), f"{name}: the energy never reached the upright's"
    steps = np.diff(E[: reached + 1])
    assert steps.min() >= -1e-3 * lift, f"{name}: energy fell by {-steps.min():.3g} J in a sample"
    # And it does rise: from hanging to within 0.1 % of the top.
    assert E[reached] - E[0] > 0.99 * lift


@pytest.mark.parametrize("name", ["cartpole", "reaction_wheel_pendulum"])
def test_swings_up_and_stays_with_noise(name: str) -> None:
    """From seeded hanging starts, with sensor noise, it is caught and balanced, on the track."""
    from equilibrist.sim.noise import Noise

    system = get_system(name)
    ctrl = swingup(system)
    task = get_task(system, "swingup")
    noise = Noise.from_design(_design(system))
    rng = np.random.default_rng(11)
    for seed in range(3):
        res = simulate(system, ctrl, duration=8.0, x0=task.draw_initial(rng), region=task.region,
                       noise=noise, seed=seed)
        assert not res.fell, f"{name} seed {seed}: left its track ({res.fell_state})"
        end = res.final_state - system.operating_point().x
        theta = system.state_index("theta")
        assert abs(math.remainder(end[theta], 2 * math.pi)) < 0.05
        assert abs(end[theta + 2]) < 0.5


def _design(system: object) -> object:
    from equilibrist.control.design import design

    return design(system, rate=system.spec.control_rate)  # type: ignore[attr-defined]


def test_compiled_and_python_agree() -> None:
    """The source compiled into the core and run as plain Python give the same run."""
    system = get_system("cartpole")
    ctrl = swingup(system)
    x0 = get_task(system, "swingup").draw_initial(np.random.default_rng(4))
    a = simulate(system, ctrl, duration=3.0, x0=x0, region={})
    b = simulate(system, SwingUpRuntime(ctrl, compiled=False), duration=3.0, x0=x0, region={})
    np.testing.assert_allclose(a.states, b.states, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.commanded, b.commanded, rtol=0, atol=1e-9)


def test_supervisor_hysteresis() -> None:
    """Catch below c_in, stay up to c_out, hand back above it."""
    system = get_system("cartpole")
    ctrl = swingup(system)
    fns = ctrl.python_functions()
    p = ctrl.params
    S = p[CP["S"]:CP["S"] + 16].reshape(4, 4)
    v = np.array([0.0, 1.0, 0.0, 0.0])
    unit = float(v @ S @ v)

    def mode_after(z: np.ndarray, level: float) -> float:
        y = np.array([0.0, math.sqrt(level / unit)])
        zn = np.zeros_like(z)
        fns["update"](0.0, z, y, np.zeros(0), np.zeros(1), p, zn)
        return float(zn[Z["mode"]])

    z = np.zeros(Z["end"])
    c_in, c_out = ctrl.settings["c_in"], ctrl.settings["c_out"]
    assert mode_after(z, 0.5 * c_in) == MODE_BALANCE
    assert mode_after(z, 1.5 * c_in) != MODE_BALANCE
    z[Z["init"]] = 1.0
    z[Z["mode"]] = MODE_BALANCE
    for level, expected in ((0.9 * c_out, True), (1.1 * c_out, False)):
        # A held estimate at the level (rates zero): the predicted state is the measurement.
        z[Z["xhat"] + 1] = math.sqrt(level / unit)
        z[Z["xhat"] + 3] = 0.0
        z[Z["ref"]:Z["ref"] + 4] = system.operating_point().x
        assert (mode_after(z, level) == MODE_BALANCE) is expected


def test_registered_and_refused_where_it_does_not_apply() -> None:
    ctrl = build_controller("swingup", ControllerRequest(system=get_system("cartpole"), rate=None))
    assert isinstance(ctrl, NonlinearController)
    with pytest.raises(ControllerError, match="ball_beam has no swing-up") as info:
        build_controller("swingup", ControllerRequest(system=get_system("ball_beam"), rate=None))
    assert "\n" not in str(info.value)
    assert swingup_laws() == {"cartpole": "cart", "reaction_wheel_pendulum": "wheel",
                              "furuta": "rotary", "acrobot": "acrobot", "pendubot": "pendubot",
                              "dfki_double_pendulum[robot=acrobot]": "acrobot",
                              "dfki_double_pendulum[robot=pendubot]": "pendubot"}


def test_demo_animates_a_swing_up(tmp_path: object) -> None:
    from pathlib import Path

    from PIL import Image

    from equilibrist.apps.swingup_demo import swingup_animation

    path, caption, _run = swingup_animation(get_system("cartpole"), Path(str(tmp_path)), width=160,
                                      height=120, fps=5, max_frames=6, duration=4.0)
    with Image.open(path) as gif:
        assert gif.size == (160, 120) and gif.n_frames >= 2
    assert "Swing-up from hanging" in caption


def test_acrobot_swings_up_in_most_noisy_starts() -> None:
    """Over 200 seeded noisy hanging starts, most acrobots end upright and still after 15 s.

    Judged on the simulated plant's final state (both links within 0.1 rad
    of upright, rates under 0.5 rad/s), not on the supervisor's mode.
    """
    from equilibrist.sim.batch import simulate_batch
    from equilibrist.sim.noise import Noise

    system = get_system("acrobot")
    task = get_task(system, "swingup")
    d = _design(system)
    ctrl = swingup(system, design=d)
    runs = 200
    x0 = task.draw_initials(np.random.default_rng(7), runs)
    b = simulate_batch(system, ctrl, runs=runs, duration=task.duration, x0=x0, seed=7,
                       noise=Noise.from_design(d), region=task.region)
    end = np.asarray(b.final_state) - system.operating_point().x
    angles = np.abs(np.remainder(end[:, :2] + math.pi, 2 * math.pi) - math.pi)
    up = (angles.max(axis=1) < 0.1) & (np.abs(end[:, 2:]).max(axis=1) < 0.5)
    assert up.mean() >= 0.5, f"only {100 * up.mean():.1f} % of {runs} starts end upright"


def test_acrobot_law_makes_its_lyapunov_function_fall_at_the_stated_rate() -> None:
    """On the derived model, the acrobot's torque gives dV/dt = -k_V theta2_dot^2 exactly.

    ``V = k_E (E - E0)^2 / 2 + k_D theta2_dot^2 / 2 + k_P theta2^2 / 2``
    (Xin and Kaneda); ``dE/dt`` is taken by central differences of the
    sympy-derived energy along the derived model's ``f(x, tau)``, so the
    law's inertia matrix, velocity and gravity terms are checked against an
    independent derivation.
    """
    from equilibrist.control.swingup_law import python_namespace

    system = get_system("acrobot")
    ctrl = swingup(system)
    p = ctrl.params
    ke, kp, kv, kd = (float(p[CP[k]]) for k in ("ke", "kp", "kv", "kd"))
    pump = python_namespace(ctrl.source)["su_pump"]
    e_up = system.energy(system.operating_point().x)
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(40):
        x = np.array([rng.uniform(-math.pi, math.pi), rng.uniform(-1.2, 1.2),
                      rng.uniform(-3.0, 3.0), rng.uniform(-3.0, 3.0)])
        tau = float(pump(x[0], x[1], x[2], x[3], p))
        if abs(tau) > 1e3:  # near the law's singular surface: not a fair finite difference
            continue
        xdot = system.f(x, np.array([tau]))
        h = 1e-6
        e_dot = (system.energy(x + h * xdot) - system.energy(x - h * xdot)) / (2 * h)
        v_dot = (ke * (system.energy(x) - e_up) * e_dot + kd * x[3] * xdot[3]
                 + kp * x[1] * x[3])
        assert v_dot == pytest.approx(-kv * x[3] ** 2, rel=1e-5, abs=1e-5)
        checked += 1
    assert checked >= 30


@pytest.mark.parametrize("form", ["current", "predictor"])
def test_lqg_balance_is_the_designs_lqg(form: str) -> None:
    """Balancing with ``balance="lqg"``, the supervisor's filter and command are the contract's
    LQG (LinearController.from_design) fed the same measurements, to round-off."""
    from equilibrist.control.design import design
    from equilibrist.control.linear import LinearController

    system = get_system("cartpole")
    d = design(system, rate=system.spec.control_rate, kalman_form=form)
    ctrl = swingup(system, design=d, balance="lqg")
    assert ctrl.settings["balance"] == "lqg" and ctrl.settings["kalman_form"] == form
    lqg = LinearController.from_design(d, kind="lqg")
    fns, p = ctrl.python_functions(), ctrl.params
    x_op = system.operating_point().x
    z = np.zeros(Z["end"])
    z[Z["init"]] = z[Z["mode"]] = 1.0
    z[Z["ref"]:Z["ref"] + 4] = x_op
    z[Z["xhat"]:Z["xhat"] + 4] = x_op
    zl = np.zeros(lqg.n_z)
    rng = np.random.default_rng(5)
    for _ in range(60):
        y = x_op[:2] + rng.normal(scale=[0.01, 0.005])
        u = np.zeros(1)
        fns["output"](0.0, z, y, np.zeros(0), p, u)
        np.testing.assert_allclose(u, lqg.output(zl, y), rtol=0, atol=1e-9)
        x = np.zeros(4)
        fns["estimate"](0.0, z, y, np.zeros(0), p, x)
        np.testing.assert_allclose(x - x_op, lqg.estimate(zl, y), rtol=0, atol=1e-12)
        zn = np.zeros_like(z)
        fns["update"](0.0, z, y, np.zeros(0), u, p, zn)
        zl = lqg.update(zl, y, np.zeros(0), u)
        z = zn
        assert z[Z["mode"]] == MODE_BALANCE
        np.testing.assert_allclose(z[Z["kz"]:Z["kz"] + 4], zl, rtol=0, atol=1e-12)


def _upright(system: object, final: np.ndarray) -> np.ndarray:
    """Which final states are upright and balanced: the pendulum within 0.05 rad and its rate
    under 1 rad/s (the sensor noise moves it by some tenths); the acrobot's two links within
    0.1 rad and their rates under 0.5 rad/s (its goal's judge)."""
    end = np.asarray(final) - system.operating_point().x  # type: ignore[attr-defined]
    wrapped = np.abs(np.remainder(end[:, :2] + math.pi, 2 * math.pi) - math.pi)
    if system.name == "acrobot":  # type: ignore[attr-defined]
        return (wrapped.max(axis=1) < 0.1) & (np.abs(end[:, 2:]).max(axis=1) < 0.5)
    return (wrapped[:, 1] < 0.05) & (np.abs(end[:, 3]) < 1.0)


@pytest.mark.parametrize("name", [*PENDULUMS, "acrobot"])
def test_lqg_hand_over_catches_from_the_same_starts(name: str) -> None:
    """From the same seeded noisy hanging starts, the LQG hand-over ends upright and still:
    the pendulums in every start of 40 (as with the LQR), the acrobot in at least half of 100
    (its goal)."""
    from equilibrist.sim.batch import simulate_batch
    from equilibrist.sim.noise import Noise

    system = get_system(name)
    task = get_task(system, "swingup")
    d = _design(system)
    runs = 100 if name == "acrobot" else 40
    x0 = task.draw_initials(np.random.default_rng(17), runs)
    up = {}
    for balance in ("lqr", "lqg"):
        b = simulate_batch(system, swingup(system, design=d, balance=balance), runs=runs,  # type: ignore[arg-type]
                           duration=task.duration, x0=x0, seed=17, noise=Noise.from_design(d),
                           region=task.region)
        up[balance] = _upright(system, b.final_state)
    if name == "acrobot":
        assert up["lqg"].mean() >= 0.5, f"LQG hand-over: {100 * up['lqg'].mean():.0f} % upright"
    else:
        assert up["lqr"].all()
        assert up["lqg"].all(), f"{name}: starts {np.flatnonzero(~up['lqg'])} not caught by the LQG"


def test_balance_option_is_checked() -> None:
    with pytest.raises(ControllerError, match="balance 'pid'") as info:
        swingup(get_system("cartpole"), balance="pid")
    assert "\n" not in str(info.value)
    ctrl = build_controller("swingup", ControllerRequest(system=get_system("furuta"), rate=None,
                                                         options={"balance": "lqg"}))
    assert isinstance(ctrl, NonlinearController) and ctrl.settings["balance"] == "lqg"


def test_the_law_is_written_for_any_number_of_states_and_outputs() -> None:
    """The supervisor, the tracker, the catch and the LQG hand-over read their sizes from the
    layout: a rig of three coordinates (six states, a stand-in pumping term) translates to C,
    and balancing it commands ``u_op - K dx``, on the filter's estimate with the LQG."""
    from equilibrist.control.kalman import estimator
    from equilibrist.control.nonlinear import CATCH_SOURCE, check_source, contract_namespace
    from equilibrist.control.swingup_law import (
        CP_SLOTS,
        LAW_SOURCE,
        LAYOUT,
        layout_constants,
        z_layout,
    )

    n, nq = 6, 3
    head = "\n".join(f"{k} = {v}" for k, v in layout_constants(n, nq).items())
    law = ("\n\ndef su_law(z, y, p):\n    return 0.0\n\n\n"
           "def su_energy(x0, x1, x2, x3, x4, x5, p):\n    return 0.0\n")
    source = head + "\n" + estimator().source + CATCH_SOURCE + LAW_SOURCE + law
    check_source(source, has_estimate=True)
    rng = np.random.default_rng(5)
    K, S = rng.normal(size=n), np.eye(n)
    gain = rng.uniform(0.0, 0.3, size=(n, nq))
    slots = dict.fromkeys(CP_SLOTS, 0.0) | {
        "T": 0.01, "alpha": 0.5, "beta": 0.1, "u_min": -100.0, "u_max": 100.0, "u_op": 0.5,
        "c_in": 10.0, "c_out": 40.0, "current": 1.0, "n": n, "nq": nq, "np": 0}
    blocks = {"x_op": np.zeros(n), "K": K, "S": S, "wrap": np.zeros(n), "free": np.zeros(n),
              "Ad": np.eye(n), "Bd": np.zeros(n), "Kf": gain, "sel": np.arange(nq, dtype=float),
              "phys": np.zeros(0)}
    ns = contract_namespace()
    exec(compile(source, "<six states>", "exec"), ns)
    zl = z_layout(n)
    y = rng.normal(scale=0.05, size=nq)
    z = np.zeros(zl["end"])
    z[zl["init"]] = z[zl["mode"]] = MODE_BALANCE
    z[zl["xhat"]:zl["xhat"] + n] = rng.normal(scale=0.05, size=n)
    z[zl["kz"]:zl["kz"] + n] = rng.normal(scale=0.05, size=n)
    for lqg in (0.0, 1.0):
        p = LAYOUT.pack(slots | {"lqg": lqg}, blocks)
        u, x = np.zeros(1), np.zeros(n)
        ns["output"](0.0, z, y, np.zeros(0), p, u)
        ns["estimate"](0.0, z, y, np.zeros(0), p, x)
        if lqg:
            kz = z[zl["kz"]:zl["kz"] + n]
            dx = kz + gain @ (y - kz[:nq])
        else:
            dx = x  # the tracker's estimate, about a zero reference
        np.testing.assert_allclose(x, dx, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(u[0], 0.5 - K @ dx, rtol=1e-12, atol=1e-12)
        zn = np.zeros(zl["end"])
        ns["update"](0.0, z, y, np.zeros(0), np.array([0.5]), p, zn)
        assert zn[zl["mode"]] == MODE_BALANCE


def test_the_kinds_offer_the_balances_the_controllers_take() -> None:
    from equilibrist.control.nonlinear import BALANCES
    from equilibrist.controllers.kinds import get

    for kind in ("swingup", "tvlqr"):
        (option,) = [o for o in get(kind).options if o.flag == "--balance"]
        assert option.choices == BALANCES
