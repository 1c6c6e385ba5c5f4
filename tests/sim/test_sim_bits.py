"""The compiled core gives the same numbers, to the bit, as the release it was measured in.

Every optimization of the simulation core (the linear controller's code
specialized to its sizes and zeros, the recording and accumulating only of
what is asked, the noise-free integrator step) promises results identical
to the bit to those of the generic loop. The digests below were taken from
that generic loop (before those optimizations), then taken again when the
dynamics' sine and cosine and the generator's logarithm became the
project's own (equilibrist.numeric.libm, fdlibm's kernels) instead of the C
library's, which glibc picks by the CPU's features: a few results in ten
thousand moved by one ulp, and every closed loop amplifies that. They are
now the same on every x86-64 CPU (tests/sim/test_bits_cpu.py runs them under
another feature set). The runs that design their controller were taken again
when the designs moved from LAPACK (whose BLAS kernel the CPU selects) to
the fixed order of equilibrist.control.fixed: they are the same under
another BLAS kernel too (see docs/reproducibility.md). This file says
which arrays differ. Independent truths of the simulation are tested elsewhere
(test_sim_systems, test_sim_linear, test_sim_noise); this file pins the
numbers, LQR and LQG, single runs and batches, with noise, events,
delay, references, both integrators and the linear plant.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from equilibrist.control.design import design
from equilibrist.control.linear import LinearController
from equilibrist.numeric.lookup import get_system
from equilibrist.sim import (
    Impulse,
    Kick,
    Noise,
    ParameterChange,
    Pulse,
    StateFeedback,
    simulate,
    simulate_batch,
)
from equilibrist.sim.signals import Step

RESULT_ARRAYS = ("states", "estimates", "measurements", "commanded", "saturated", "applied",
                 "final_state")
BATCH_ARRAYS = ("fell", "fell_at", "fell_code", "fell_x", "final_state", "peak_input",
                "peak_command", "rms_input", "time_saturated", "peak_deviation",
                "estimation_error_rms", "rows", "trajectories")


def digest(array: object) -> str:
    if array is None:
        return "none"
    a = np.ascontiguousarray(array)
    return hashlib.sha256(str(a.dtype).encode() + str(a.shape).encode() + a.tobytes()).hexdigest()[:16]


def digests(result: object, names: tuple[str, ...]) -> dict[str, str]:
    return {name: digest(getattr(result, name)) for name in names}


#: The benchmark's continuous LQR gain (Q = diag(10, 10, 1, 1), R = 0.1) as numbers: scipy's
#: continuous Riccati solver runs LAPACK, whose last bits depend on the BLAS kernel the CPU
#: selects, and this file pins the core's bits, not LAPACK's (the gain itself is checked
#: against scipy below, to 1e-12).
BENCH_K = np.array([[-9.999999999999618, -303.9634076212058, -20.256689881153306,
                     -77.35929432136862]])


def _cartpole_lqr_continuous():
    system = get_system("cartpole")
    lm = system.linearize()
    return system, StateFeedback(K=BENCH_K, x_op=lm.x0, u_op=lm.u0)


def test_the_pinned_gain_is_the_continuous_lqr_of_the_benchmark() -> None:
    import scipy.linalg as sl

    lm = get_system("cartpole").linearize()
    q, r = np.diag([10.0, 10.0, 1.0, 1.0]), np.array([[0.1]])
    k = np.linalg.solve(r, lm.B.T @ sl.solve_continuous_are(lm.A, lm.B, q, r))
    np.testing.assert_allclose(k, BENCH_K, rtol=1e-12, atol=0)


def scenario(name: str) -> object:
    """The run or batch called *name* (each a few thousand samples)."""
    if name == "lqr-1khz":  # the benchmark's workload, 2 s
        system, lqr = _cartpole_lqr_continuous()
        return simulate(system, lqr, duration=2.0, rate=1000.0, physics_step=1e-3,
                        x0=[0.0, 0.2, 0.0, 0.0])
    if name == "lqr-saturating-delay":
        system = get_system("cartpole")
        ctrl = LinearController.from_design(design(system, rate=200.0), kind="lqr")
        return simulate(system, ctrl, duration=2.0, x0={"theta": 0.5}, delay=True,
                        events=[Kick(0.3, "theta_dot", 0.4)])
    if name == "lqg-noise-events":
        system = get_system("cartpole")
        d = design(system, rate=200.0)
        ctrl = LinearController.from_design(d, kind="lqg")
        return simulate(system, ctrl, duration=2.0, x0={"theta": 0.2}, noise=Noise.from_design(d),
                        seed=3, events=[Pulse(0.7, 20.0, 0.05), Impulse(1.1, 2.0),
                                        ParameterChange(1.5, {"m_p": 1.3})])
    if name == "lqg-predictor-tracking":
        system = get_system("cartpole")
        d = design(system, rate=100.0, outputs=["x", "theta"], kalman_form="predictor")
        ctrl = LinearController.from_design(d, kind="lqg", tracking=True)
        return simulate(system, ctrl, duration=3.0, x0={"theta": 0.1}, noise=Noise.from_design(d),
                        seed=5, reference=Step(0.5, at=0.5))
    if name == "lqg-reaction-wheel":
        system = get_system("reaction_wheel_pendulum")
        d = design(system, rate=250.0)
        ctrl = LinearController.from_design(d, kind="lqg")
        return simulate(system, ctrl, duration=2.0, noise=Noise.from_design(d), seed=11,
                        x0={system.state_names[0]: 0.1})
    if name == "lqr-adaptive":
        system = get_system("cartpole")
        ctrl = LinearController.from_design(design(system, rate=100.0), kind="lqr")
        return simulate(system, ctrl, duration=1.0, x0={"theta": 0.3}, integrator="adaptive")
    if name == "lqg-linear-plant":
        system = get_system("cartpole")
        d = design(system, rate=200.0)
        return simulate(system, LinearController.from_design(d, kind="lqg"), duration=1.0,
                        x0={"theta": 0.2}, plant="linear", noise=Noise.from_design(d), seed=2)
    if name == "lqr-negative-zeros":  # -0.0 in the state must stay what it was
        system, lqr = _cartpole_lqr_continuous()
        return simulate(system, lqr, duration=0.5, rate=1000.0, physics_step=1e-3,
                        x0=[-0.0, 0.2, -0.0, -0.0])
    if name == "open-loop-at-rest-negative-zeros":  # the equilibrium: every derivative is +-0
        system = get_system("cartpole")
        return simulate(system, None, duration=0.5, rate=100.0, x0=[-0.0, -0.0, -0.0, -0.0])
    if name == "open-loop-falls":
        system = get_system("cartpole")
        return simulate(system, None, duration=3.0, rate=100.0, x0={"theta": 0.05},
                        events=[Kick(0.2, "x_dot", 0.1)])
    if name == "batch-lqg-recorded":
        system = get_system("cartpole")
        d = design(system, rate=200.0)
        ctrl = LinearController.from_design(d, kind="lqg")
        return simulate_batch(system, ctrl, runs=6, duration=1.5,
                              x0={"theta": np.linspace(-0.4, 0.4, 6)},
                              params={"m_p": np.linspace(0.8, 1.4, 6)},
                              noise=Noise.from_design(d), seed=21, record=True, workers=2)
    if name == "batch-lqr-outcomes":
        system, lqr = _cartpole_lqr_continuous()
        return simulate_batch(system, lqr, runs=40, duration=2.0, rate=1000.0, physics_step=1e-3,
                              x0={"theta": np.linspace(-1.2, 1.2, 40)}, workers=2)
    if name == "batch-lqr-noise":
        system = get_system("cartpole")
        d = design(system, rate=200.0)
        ctrl = LinearController.from_design(d, kind="lqr")
        return simulate_batch(system, ctrl, runs=10, duration=1.0,
                              x0={"theta": np.linspace(-0.3, 0.3, 10)},
                              noise=Noise.from_design(d), seed=4, workers=2)
    raise KeyError(name)


# Taken from the generic loop with the project's sin, cos and log (see the module docstring).
EXPECTED: dict[str, dict[str, str]] = {
    "lqr-1khz": {
        "states": "913a9d916268e3e8",
        "estimates": "913a9d916268e3e8",
        "measurements": "913a9d916268e3e8",
        "commanded": "793d16178eff646e",
        "saturated": "793d16178eff646e",
        "applied": "793d16178eff646e",
        "final_state": "f740b843071196ab",
    },
    "lqr-saturating-delay": {
        "states": "e68aea3478499f41",
        "estimates": "e68aea3478499f41",
        "measurements": "e68aea3478499f41",
        "commanded": "2d88783efd247349",
        "saturated": "c60653b48d9bcc5a",
        "applied": "8021a8341e9b9c08",
        "final_state": "5dbefa2af34e20c4",
    },
    "lqg-noise-events": {
        "states": "345abac6cbfc6b77",
        "estimates": "768a7d79c9fb0609",
        "measurements": "9b71f60d690576fe",
        "commanded": "da7011df240f09d1",
        "saturated": "2068d5d3212b916d",
        "applied": "2068d5d3212b916d",
        "final_state": "22672a414a48dd02",
    },
    "lqg-predictor-tracking": {
        "states": "11b725e7dc5ae106",
        "estimates": "030ea5397c69c772",
        "measurements": "a2b56036f8145bb0",
        "commanded": "c42977d3a2e14b66",
        "saturated": "c42977d3a2e14b66",
        "applied": "c42977d3a2e14b66",
        "final_state": "23b7b01ccedd5324",
    },
    "lqg-reaction-wheel": {
        "states": "8334a0d69299cab6",
        "estimates": "f9b286a107ae3792",
        "measurements": "357972bcc8e9fe42",
        "commanded": "b7d12d28e9ee2862",
        "saturated": "b7d12d28e9ee2862",
        "applied": "b7d12d28e9ee2862",
        "final_state": "fb2f25cb7a129597",
    },
    "lqr-adaptive": {
        "states": "f7c614ad4aca1262",
        "estimates": "f7c614ad4aca1262",
        "measurements": "f7c614ad4aca1262",
        "commanded": "5ac5be7ad1c5dcf6",
        "saturated": "5ac5be7ad1c5dcf6",
        "applied": "5ac5be7ad1c5dcf6",
        "final_state": "3b00aa8c4e78e5f8",
    },
    "lqg-linear-plant": {
        "states": "32273c8b40784fd9",
        "estimates": "efe54cad05577aef",
        "measurements": "c2d42df0a0c1e154",
        "commanded": "2211c3342627660d",
        "saturated": "c93012c2f5ae9486",
        "applied": "c93012c2f5ae9486",
        "final_state": "774f252c82e67987",
    },
    "open-loop-falls": {
        "states": "c0fbf4a75b69801c",
        "estimates": "none",
        "measurements": "f6550416f2541630",
        "commanded": "e8d0eccf220d1c5b",
        "saturated": "e8d0eccf220d1c5b",
        "applied": "e8d0eccf220d1c5b",
        "final_state": "9c79de5eed724f2b",
    },
    "batch-lqg-recorded": {
        "fell": "b08263a01bb3ed88",
        "fell_at": "4effff3f5b15c210",
        "fell_code": "0ea920c2bde894e9",
        "fell_x": "657a8232a19d90d1",
        "final_state": "0cdaf4373d961baf",
        "peak_input": "b738999a17a181bc",
        "peak_command": "a437d9c2cc27ae5f",
        "rms_input": "127f7cb674c173af",
        "time_saturated": "03fa368ccefcd3a3",
        "peak_deviation": "3b92dfbe9ab1c8ca",
        "estimation_error_rms": "7a0551cb9c65b043",
        "rows": "e64f3662ef173cb9",
        "trajectories": "e8893dfe7a9f2ac0",
    },
    "batch-lqr-outcomes": {
        "fell": "195550dc41841fae",
        "fell_at": "efb273493f6be537",
        "fell_code": "8efc4cf56b84254f",
        "fell_x": "93f11518219a0ffa",
        "final_state": "beb204a155cf4201",
        "peak_input": "e2ba7d07bddcbf2f",
        "peak_command": "60ef787d18721112",
        "rms_input": "b64a80af5f60024f",
        "time_saturated": "becca3894bde74ed",
        "peak_deviation": "f5d188175f5e8db2",
        "estimation_error_rms": "8e041ffa2c4e882f",
        "rows": "d2885874b0fefb03",
        "trajectories": "none",
    },
    "batch-lqr-noise": {
        "fell": "dc12ad490f541138",
        "fell_at": "f66ecb3ae6a5ed0b",
        "fell_code": "c37fc27f4eb48f66",
        "fell_x": "33245eb5fa89eeec",
        "final_state": "4ad37ce1a54c3247",
        "peak_input": "c67bb8777b2c8045",
        "peak_command": "c67bb8777b2c8045",
        "rms_input": "b2a0e908f4a22e70",
        "time_saturated": "13e862f160a6c463",
        "peak_deviation": "eff0bb67b836a72d",
        "estimation_error_rms": "44687470dbab4adf",
        "rows": "e8fdc33cd961d431",
        "trajectories": "none",
    },
    "lqr-negative-zeros": {
        "states": "0a756ab88d46f648",
        "estimates": "f1883c68db0bd880",
        "measurements": "0a756ab88d46f648",
        "commanded": "ebb9eec6b2c6adb3",
        "saturated": "ebb9eec6b2c6adb3",
        "applied": "ebb9eec6b2c6adb3",
        "final_state": "42332a2788a4e531",
    },
    "open-loop-at-rest-negative-zeros": {
        "states": "730af0d5193d591a",
        "estimates": "none",
        "measurements": "a5a9aaaed5a82bd4",
        "commanded": "b3054cd4ec281cca",
        "saturated": "b3054cd4ec281cca",
        "applied": "b3054cd4ec281cca",
        "final_state": "291d224189edb466",
    },
}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_the_core_gives_the_recorded_numbers(name: str) -> None:
    result = scenario(name)
    names = BATCH_ARRAYS if name.startswith("batch") else RESULT_ARRAYS
    got = digests(result, names)
    differ = [k for k in names if got[k] != EXPECTED[name][k]]
    assert not differ, f"{name}: {', '.join(differ)} differ from the recorded numbers"


def test_every_scenario_is_pinned() -> None:
    assert set(EXPECTED) == {
        "lqr-1khz", "lqr-saturating-delay", "lqg-noise-events", "lqg-predictor-tracking",
        "lqg-reaction-wheel", "lqr-adaptive", "lqg-linear-plant", "open-loop-falls",
        "batch-lqg-recorded", "batch-lqr-outcomes", "batch-lqr-noise", "lqr-negative-zeros",
        "open-loop-at-rest-negative-zeros",
    }
