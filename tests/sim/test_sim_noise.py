"""Noise: the core's generator, reproducibility by seed, and the covariances it produces."""

from __future__ import annotations

import math

import numpy as np
import pytest

from equilibrist.sim import Noise, simulate
from equilibrist.sim.kernel import load_kernel
from equilibrist.sim.noise import generator_state
from support.sim import cartpole, lqg
from support.sim import cartpole_noise as _noise

MASK = (1 << 64) - 1


def _xoshiro_normals(state: list[int], count: int) -> list[float]:
    """xoshiro256** and the polar method in plain Python integers: the reference."""
    s = list(state)

    def rotl(v: int, k: int) -> int:
        return ((v << k) | (v >> (64 - k))) & MASK

    def nxt() -> int:
        result = (rotl((s[1] * 5) & MASK, 7) * 9) & MASK
        t = (s[1] << 17) & MASK
        s[2] ^= s[0]
        s[3] ^= s[1]
        s[1] ^= s[2]
        s[0] ^= s[3]
        s[2] ^= t
        s[3] = rotl(s[3], 45)
        return result

    out: list[float] = []
    while len(out) < count:
        v1 = 2.0 * ((nxt() >> 11) + 1) * 2.0**-53 - 1.0
        v2 = 2.0 * ((nxt() >> 11) + 1) * 2.0**-53 - 1.0
        r2 = v1 * v1 + v2 * v2
        if r2 >= 1.0 or r2 == 0.0:
            continue
        scale = math.sqrt(-2.0 * math.log(r2) / r2)
        out += [v1 * scale, v2 * scale]
    return out[:count]


def test_core_generator_matches_reference_implementation():
    kernel = load_kernel(cartpole())
    state = generator_state(np.random.SeedSequence(1234))
    out = np.empty(101)
    kernel.normals(state.copy(), out)
    expected = _xoshiro_normals([int(v) for v in state], 101)
    np.testing.assert_allclose(out, expected, rtol=1e-14, atol=1e-15)


def test_core_generator_is_standard_normal():
    kernel = load_kernel(cartpole())
    out = np.empty(200_000)
    kernel.normals(generator_state(np.random.SeedSequence(7)), out)
    assert abs(out.mean()) < 0.01
    assert abs(out.std() - 1.0) < 0.01
    assert abs(np.mean(out[:-1] * out[1:])) < 0.01  # no lag-one correlation


def test_seeded_runs_are_reproducible_and_seeds_differ():
    sysm = cartpole()
    ctrl = lqg(sysm, rate=200.0)
    noise = _noise(sysm, 200.0)
    a = simulate(sysm, ctrl, duration=1.0, noise=noise, seed=5)
    b = simulate(sysm, ctrl, duration=1.0, noise=noise, seed=5)
    c = simulate(sysm, ctrl, duration=1.0, noise=noise, seed=6)
    for name in ("states", "estimates", "measurements", "commanded", "applied"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(a.states, c.states)
    assert not np.array_equal(a.measurements, c.measurements)
    assert a.settings["seed"] == {"entropy": 5, "spawn_key": []}


def test_unseeded_noisy_run_records_its_seed():
    sysm = cartpole()
    ctrl = lqg(sysm, rate=200.0)
    noise = _noise(sysm, 200.0)
    a = simulate(sysm, ctrl, duration=0.2, noise=noise)
    seq = np.random.SeedSequence(a.settings["seed"]["entropy"])
    b = simulate(sysm, ctrl, duration=0.2, noise=noise, seed=seq)
    np.testing.assert_array_equal(a.states, b.states)


def test_measurement_noise_has_the_given_covariance():
    sysm = cartpole()
    cov = np.array([[4e-6, 1e-6], [1e-6, 1e-6]])
    noise = Noise(np.zeros((4, 0)), np.zeros((0, 0)), cov, ("x", "theta"))
    res = simulate(sysm, None, duration=20.0, rate=1000.0, noise=noise, seed=3)
    err = res.measurements - res.states[:, :2]
    np.testing.assert_array_equal(res.states, 0.0)  # the plant rests at its equilibrium
    sample = np.cov(err.T)
    np.testing.assert_allclose(sample, cov, rtol=0.05, atol=1e-7)


def test_process_noise_increment_has_intensity_times_step():
    sysm = cartpole()
    h = 1e-3
    qn = 0.04
    g = np.zeros((4, 1))
    g[2, 0] = 1.0  # on x_dot
    noise = Noise(g, [[qn]], np.zeros((2, 2)), ("x", "theta"))
    res = simulate(sysm, None, duration=20.0, rate=1000.0, noise=noise, seed=11, region={})
    dv = np.diff(res.state("x_dot"))
    # The cart's speed is a random walk: increments of variance QN h.
    assert dv.var() == pytest.approx(qn * h, rel=0.05)
    assert abs(dv.mean()) < 5 * math.sqrt(qn * h / dv.size)
