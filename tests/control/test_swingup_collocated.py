"""The two-link rigs' swing-up (acrobot and pendubot laws): gains in the plant's own scales,
the pump from rest, the laws' Lyapunov rate, and swing-ups from hanging at rest."""

from __future__ import annotations

import math

import numpy as np
import pytest

from equilibrist import get_system
from equilibrist.control.swingup import swingup
from equilibrist.control.swingup_law import CP, energy, python_namespace
from equilibrist.control.swingup_scales import ACTUATED, plant_scales
from equilibrist.sim.run import simulate

#: The rigs and their laws: the catalogue's and DFKI's (RealAIGym's design C.1), each robot.
RIGS = {
    "acrobot": ("acrobot", {}),
    "pendubot": ("pendubot", {}),
    "dfki-acrobot": ("dfki_double_pendulum", {"robot": "acrobot"}),
    "dfki-pendubot": ("dfki_double_pendulum", {"robot": "pendubot"}),
}


def _rig(key: str) -> object:
    name, kw = RIGS[key]
    return get_system(name, **kw)


def _law(system: object) -> str:
    return str(system.spec.swingup.law)  # type: ignore[attr-defined]


def _book(system: object) -> tuple[float, float, float, float, float]:
    """Xin and Kaneda's constants of a two-link rig, by hand from its parameters: the mass
    matrix ``M11 = a1 + a2 + 2 a3 cos q2``, ``M12 = a2 + a3 cos q2``, ``M22 = a2`` and the
    links' gravity torques ``b1``, ``b2``."""
    p = system.params  # type: ignore[attr-defined]
    g, m1, m2, l1 = p["g"], p["m1"], p["m2"], p["l1"]
    if "r1" in p:  # DFKI's: inertias about the joints, rotors at zero
        a1, a2, a3 = p["I1"] + m2 * l1**2, p["I2"], m2 * l1 * p["r2"]
        b1, b2 = g * (m1 * p["r1"] + m2 * l1), g * m2 * p["r2"]
    else:  # the catalogue's: inertias about the centres of mass
        a1 = p["I1"] + m1 * p["lc1"] ** 2 + m2 * l1**2
        a2, a3 = p["I2"] + m2 * p["lc2"] ** 2, m2 * l1 * p["lc2"]
        b1, b2 = g * (m1 * p["lc1"] + m2 * l1), g * m2 * p["lc2"]
    return a1, a2, a3, b1, b2


@pytest.mark.parametrize("key", list(RIGS))
def test_scales_are_the_books(key: str) -> None:
    """The scales the gains are stated in, against closed forms from the rig's parameters:
    the lift ``2 (b1 + b2)``; Xin and Kaneda's bound on k_D, ``max over q2 of (E_r + Phi)
    det M / M_bb`` with ``Phi = |b1 + b2 e^{i q2}|`` (taken on a 20,000-point grid); the
    acrobot's resting-point bound on k_P, ``2 b1 b2`` (bending a little off hanging)."""
    system = _rig(key)
    law = _law(system)
    ctrl = swingup(system)
    sc = plant_scales(system, ctrl.source, ctrl.params, law)
    a1, a2, a3, b1, b2 = _book(system)
    assert sc.lift == pytest.approx(2 * (b1 + b2), rel=1e-12)
    q2 = np.linspace(-math.pi, math.pi, 20001)
    det = a1 * a2 - (a3 * np.cos(q2)) ** 2
    m_bb = a1 + a2 + 2 * a3 * np.cos(q2) if ACTUATED[law] == 1 else np.full_like(q2, a2)
    phi = np.sqrt(b1**2 + b2**2 + 2 * b1 * b2 * np.cos(q2))
    book = float(np.max((b1 + b2 + phi) * det / m_bb))
    # Our grid is one degree: its maximum lies within the curve's change over half a degree.
    assert sc.damping_bound == pytest.approx(book, rel=2e-4)
    assert sc.damping_bound <= book * (1 + 1e-12)
    if law == "acrobot":
        assert sc.stiffness_bound == pytest.approx(2 * b1 * b2, rel=1e-3)
    else:  # the pendubot has no resting point but hanging and upright to push away
        assert sc.stiffness_bound == 0.0
    limit = float(system.input_limits[1][0])  # type: ignore[attr-defined]
    assert sc.torque == limit


@pytest.mark.parametrize("key", ["pendubot", "dfki-acrobot", "dfki-pendubot"])
def test_energy_is_the_derived_models_and_kept_unforced(key: str) -> None:
    """The law's energy is the derived model's total energy from upright, and the unforced,
    frictionless plant keeps it (RK4 over 2 s from a wide swing: the drift is round-off and
    the integrator's, far below the lift)."""
    system = _rig(key)
    ctrl = swingup(system)
    up = system.operating_point().x  # type: ignore[attr-defined]
    rng = np.random.default_rng(2)
    for _ in range(10):
        x = up + rng.uniform(-3.0, 3.0, 4)
        truth = system.energy(x) - system.energy(up)  # type: ignore[attr-defined]
        assert energy(x, ctrl) == pytest.approx(truth, rel=1e-10, abs=1e-12)
    lift = -energy(np.zeros(4), ctrl)
    res = simulate(system, None, duration=2.0, rate=500.0, x0=[2.0, -1.0, 0.0, 3.0], region={})
    e = np.array([energy(x, ctrl) for x in res.states])
    assert np.ptp(e) < 1e-6 * lift


@pytest.mark.parametrize("key", list(RIGS))
def test_the_law_makes_its_lyapunov_function_fall_at_the_stated_rate(key: str) -> None:
    """Above the pump's energy, the torque gives ``dV/dt = -k_V qa_dot^2`` exactly, for ``V =
    k_E (E - E0)^2 / 2 + k_D qa_dot^2 / 2 + k_P qa~^2 / 2`` (``qa`` the actuated joint,
    ``qa~`` its distance from upright): ``dE/dt`` by central differences of the sympy-derived
    energy along the derived model's ``f(x, tau)``, so the law's inertia matrix, bias and
    gravity terms are checked against an independent derivation."""
    system = _rig(key)
    ctrl = swingup(system)
    a = ACTUATED[_law(system)]
    p = ctrl.params
    ke, kp, kv, kd = (float(p[CP[k]]) for k in ("ke", "kp", "kv", "kd"))
    pump = python_namespace(ctrl.source)["su_pump"]
    up = system.operating_point().x  # type: ignore[attr-defined]
    e_up = system.energy(up)  # type: ignore[attr-defined]
    e_kick = float(p[CP["e_kick"]])
    rng = np.random.default_rng(5)
    checked = 0
    for _ in range(60):
        x = np.array([rng.uniform(-math.pi, math.pi), rng.uniform(-1.2, 1.2),
                      rng.uniform(-3.0, 3.0), rng.uniform(-3.0, 3.0)])
        e = system.energy(x) - e_up  # type: ignore[attr-defined]
        tau = float(pump(x[0], x[1], x[2], x[3], p))
        if e < e_kick or abs(tau) > 1e3:  # the pump's; near the law's singular surface
            continue
        xdot = system.f(x, np.array([tau]))  # type: ignore[attr-defined]
        h = 1e-6
        e_dot = (system.energy(x + h * xdot) - system.energy(x - h * xdot)) / (2 * h)  # type: ignore[attr-defined]
        qa = math.remainder(x[a] - up[a], 2 * math.pi)
        v_dot = ke * e * e_dot + kd * x[2 + a] * xdot[2 + a] + kp * qa * x[2 + a]
        scale = kv * (1.0 + x[2 + a] ** 2)
        assert v_dot == pytest.approx(-kv * x[2 + a] ** 2, abs=1e-5 * scale)
        checked += 1
    assert checked >= 30


@pytest.mark.parametrize("key", list(RIGS))
def test_the_pump_from_rest_only_raises_the_energy(key: str) -> None:
    """Below the pump's energy the motor pushes with the kick's torque along the actuated
    joint's rate: ``dE/dt = tau qa_dot = kick |qa_dot| >= 0`` on the derived model; hanging at
    rest (where the law's own torque is zero) it pushes."""
    system = _rig(key)
    ctrl = swingup(system)
    a = ACTUATED[_law(system)]
    p = ctrl.params
    kick, e_kick = float(p[CP["kick"]]), float(p[CP["e_kick"]])
    assert kick > 0
    pump = python_namespace(ctrl.source)["su_pump"]
    up = system.operating_point().x  # type: ignore[attr-defined]
    lift = system.energy(up) - system.energy(np.zeros(4))  # type: ignore[attr-defined]
    assert float(pump(0.0, 0.0, 0.0, 0.0, p)) == kick
    rng = np.random.default_rng(8)
    for _ in range(40):
        x = rng.normal(scale=0.05, size=4)
        e = system.energy(x) - system.energy(up)  # type: ignore[attr-defined]
        assert e < e_kick  # a small stir off hanging: the pump's
        tau = float(pump(*x, p))
        assert abs(tau) == kick
        xdot = system.f(x, np.array([tau]))  # type: ignore[attr-defined]
        h = 1e-5
        e_dot = (system.energy(x + h * xdot) - system.energy(x - h * xdot)) / (2 * h)  # type: ignore[attr-defined]
        assert e_dot == pytest.approx(kick * abs(x[2 + a]), rel=1e-6, abs=1e-8 * lift)
        assert e_dot >= 0.0


#: From hanging exactly at rest, how long each rig's swing-up may take (RealAIGym's boards
#: give DFKI's rigs 10 s).
FROM_REST = {"acrobot": 15.0, "dfki-acrobot": 10.0, "dfki-pendubot": 10.0}


@pytest.mark.parametrize("key", list(FROM_REST))
def test_swings_up_from_hanging_at_rest_and_is_caught(key: str) -> None:
    """From hanging exactly at rest (where every term of the energy law is zero), the default
    tuning swings the rig up and ends it caught and balanced: the supervisor balancing, both
    links within 0.1 rad of upright and their rates under 0.5 rad/s, judged on the
    simulated plant."""
    from equilibrist.control.swingup import SwingUpRuntime
    from equilibrist.control.swingup_law import MODE_BALANCE, Z

    system = _rig(key)
    ctrl = swingup(system)
    res = simulate(system, ctrl, duration=FROM_REST[key], x0=np.zeros(4), region={})
    end = res.final_state - system.operating_point().x  # type: ignore[attr-defined]
    angles = np.abs(np.remainder(end[:2] + math.pi, 2 * math.pi) - math.pi)
    assert angles.max() < 0.1 and np.abs(end[2:]).max() < 0.5, f"{key} ends at {res.final_state}"
    # The supervisor's mode at the end, replayed from the run's measurements and inputs.
    rt = SwingUpRuntime(ctrl, compiled=False)
    for y, u in zip(res.measurements, res.saturated, strict=True):
        rt.output(0.0, y, np.zeros(0))
        rt.update(0.0, y, np.zeros(0), u)
    assert rt.z[Z["mode"]] == MODE_BALANCE
