"""A controller kind as an environment's expert (equilibrist.envs.expert)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import equilibrist.envs  # noqa: F401  (registers the environments)
from equilibrist.controllers import kinds
from equilibrist.envs.expert import ExpertError, expert
from equilibrist.sim import simulate


def test_an_lqg_expert_steps_the_env_as_simulate_runs_the_same_controller() -> None:
    # Second route to the same trajectory: simulate's compiled closed loop of the same
    # controller from the same start, no noise on either side.
    env = gym.make("equilibrist/cartpole-balance-v0", noise=False, action_units="physical")
    policy = expert(env, "lqg")
    obs, _ = env.reset(seed=4)
    policy.reset()
    core = env.unwrapped.core
    states = [np.array(env.unwrapped.state)]
    for _ in range(200):
        obs, _, terminated, _, _ = env.step(policy(obs))
        assert not terminated
        states.append(np.array(env.unwrapped.state))
    run = simulate(core.system, policy.controller, x0=dict(zip(core.system.state_names,
                                                               states[0], strict=True)),
                   duration=200 / core.rate, rate=core.rate, physics_step=core.physics_step)
    assert np.allclose(np.array(states), run.states[: len(states)], rtol=0, atol=1e-12)
    # It balances: the pole ends within a thousandth of a radian of upright.
    assert abs(states[-1][1]) < 1e-3 < abs(states[0][1])


def test_the_swingup_expert_solves_the_swingup_task_in_normalized_actions() -> None:
    env = gym.make("equilibrist/cartpole-swingup-v0")
    policy = expert(env, "swingup")
    obs, _ = env.reset(seed=0)
    policy.reset()
    terminated = truncated = False
    while not (terminated or truncated):
        action = policy(obs)
        assert np.all(np.abs(action) <= 1.0)  # the env's normalized units
        obs, _, terminated, truncated, _ = env.step(action)
    theta = env.unwrapped.state[1]
    assert not terminated and abs(math.remainder(theta, 2 * math.pi)) < 0.05


def test_an_expert_that_reads_other_signals_is_refused_in_one_line() -> None:
    env = gym.make("equilibrist/cartpole-balance-v0")  # observes x and theta
    with pytest.raises(ExpertError, match="lqr controller reads x, theta, x_dot, theta_dot") as info:
        expert(env, "lqr")
    assert "\n" not in str(info.value)
    with pytest.raises(ExpertError, match="open loop"):
        expert(env, "none")
    with pytest.raises(kinds.KindError, match="'zigzag' is unknown"):
        expert(env, "zigzag")
