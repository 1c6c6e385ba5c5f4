"""The learnable tasks (``-v1``): the same plant as ``-v0`` seen in Bryson units, float32 by
default, and dm_control's cart-pole reward, checked against its formulas written out here;
the vector environment's ``-v1`` is the single one's, copy by copy; ``_key`` masks in the
vector ``info``."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from equilibrist import envs
from equilibrist.envs import EnvError, EquilibristEnv, EquilibristVectorEnv
from equilibrist.envs.expert import expert


def _make(env_id: str, **kwargs: object) -> EquilibristEnv:
    env = gym.make(env_id, **kwargs).unwrapped
    assert isinstance(env, EquilibristEnv)
    return env


def test_every_v0_id_has_its_v1() -> None:
    v0, v1 = envs.env_ids(), envs.env_ids(1)
    assert [i.replace("-v0", "-v1") for i in v0] == list(v1)
    for env_id in v1:
        assert env_id in gym.registry
    assert gym.registry["equilibrist/cartpole-balance-v1"].kwargs["version"] == 1


def test_check_env_and_float32_spaces() -> None:
    env_id = "equilibrist/cartpole-balance-v1"
    env = gym.make(env_id)
    check_env(env.unwrapped, skip_render_check=True)  # the drawing is -v0's
    assert env.observation_space.dtype == np.float32 and env.action_space.dtype == np.float32
    assert (env.action_space.low == -1).all() and (env.action_space.high == 1).all()
    obs, _ = env.reset(seed=0)
    assert obs.dtype == np.float32
    wide = gym.make(env_id, dtype=np.float64)
    assert wide.observation_space.dtype == np.float64 and wide.reset(seed=0)[0].dtype == np.float64
    with pytest.raises(EnvError, match="dtype='int8'"):
        gym.make(env_id, dtype="int8")
    with pytest.raises(EnvError, match="version=2"):
        gym.make("equilibrist/cartpole-balance-v0", version=2)


def _dm_cartpole_reward(x: np.ndarray, force: float) -> float:
    """dm_control's cart-pole reward (suite/cartpole.py, ``_get_reward``), its margins in
    the cart-pole's Bryson scales (x 0.5 m, theta 0.2 rad, rates 1/s) and its control in
    units of half the force's range (200 N)."""

    def gaussian(d: float, margin: float) -> float:
        scale = math.sqrt(-2 * math.log(0.1))
        return math.exp(-0.5 * (d / margin * scale) ** 2)

    upright = (math.cos(x[1]) + 1) / 2  # theta from upright
    centered = (1 + gaussian(x[0], 2 * 0.5)) / 2
    small_control = (4 + max(0.0, 1 - (force / 200.0) ** 2)) / 5
    small_velocity = (1 + gaussian(x[3], 5 * 1.0)) / 2
    return upright * small_control * small_velocity * centered


def test_v1_is_v0_seen_in_bryson_units_with_dm_controls_reward() -> None:
    """Same seed and actions: the v1 observation is the v0 state less the operating point
    over the Bryson scales, and the reward dm_control's formula at that state and force."""
    v0 = _make("equilibrist/cartpole-balance-v0", observe="state")
    v1 = _make("equilibrist/cartpole-balance-v1", dtype=np.float64)
    o0, _ = v0.reset(seed=3)
    o1, _ = v1.reset(seed=3)
    scale = np.array([0.5, 0.2, 1.0, 1.0])  # upright at 0
    np.testing.assert_allclose(o1, o0 / scale, rtol=1e-13, atol=1e-13)
    rewards = []
    for a in (0.05, -0.3, 0.9, 1.7, -0.02):  # 1.7 saturates at the limit: 200 N
        o0, _, t0, _, _ = v0.step(np.array([a]))
        o1, r1, t1, _, _ = v1.step(np.array([a]))
        np.testing.assert_allclose(o1, o0 / scale, rtol=1e-12, atol=1e-12)
        assert r1 == pytest.approx(_dm_cartpole_reward(o0, 200.0 * min(a, 1.0)), rel=1e-12)
        assert t0 == t1
        rewards.append(r1)
    assert 0.0 < min(rewards) < max(rewards) <= 1.0


def test_swingup_observes_the_hanging_angle_by_its_cosine_and_sine() -> None:
    v0 = _make("equilibrist/cartpole-swingup-v0", observe="state")
    v1 = _make("equilibrist/cartpole-swingup-v1")
    assert v1.core.learnable is not None
    assert v1.core.learnable.names == ("x", "cos(theta)", "sin(theta)", "x_dot", "theta_dot")
    o0, _ = v0.reset(seed=1)
    o1, _ = v1.reset(seed=1)
    for _ in range(30):
        o0, *_ = v0.step(np.array([0.4]))
        o1, r1, *_ = v1.step(np.array([0.4]))
    expected = [o0[0] / 0.5, math.cos(o0[1]), math.sin(o0[1]), o0[2], o0[3]]
    np.testing.assert_allclose(o1, expected, rtol=2e-6, atol=2e-6)  # float32
    assert r1 == pytest.approx(_dm_cartpole_reward(o0, 80.0), rel=1e-12)
    # Hanging, the reward is small; the expert's swing-up earns it near 1 at the end.
    assert r1 < 0.1


def test_the_expert_acts_through_the_scaled_observations() -> None:
    env = gym.make("equilibrist/cartpole-balance-v1")
    policy = expert(env, "lqr")
    obs, _ = env.reset(seed=0)
    policy.reset()
    total = 0.0
    for _ in range(400):
        action = policy(obs)
        assert action.dtype == np.float32
        obs, reward, terminated, _, _ = env.step(action)
        total += reward
        assert not terminated
    assert total > 0.97 * 400  # balanced: near the maximum of 1 per step


def test_vector_v1_is_the_single_one_copy_by_copy() -> None:
    """Rewards and observations of every copy are those of a single environment started at
    the copy's start, noise off, through an autoreset (the restarting step pays 0)."""
    vec = gym.make_vec("equilibrist/cartpole-balance-v1", num_envs=3, noise=False)
    assert isinstance(vec, EquilibristVectorEnv)  # make_vec's default for these ids
    obs, info = vec.reset(seed=4)
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (40, 3, 1)).astype(np.float32)
    actions[:, 2] = 1.0  # copy 2 falls, and restarts
    singles = [_make("equilibrist/cartpole-balance-v1", noise=False) for _ in range(3)]
    for i, env in enumerate(singles):
        np.testing.assert_array_equal(env.reset(options={"state": info["state"][i]})[0], obs[i])
    ended = np.zeros(3, dtype=bool)
    for k in range(40):
        o, r, term, trunc, step_info = vec.step(actions[k])
        for i, env in enumerate(singles):
            if ended[i]:
                assert r[i] == 0.0 and step_info["_state"][i] and step_info["_noise_seed"][i]
                env.reset(options={"state": step_info["state"][i]})
                continue
            so, sr, st, _, _ = env.step(actions[k, i])
            np.testing.assert_array_equal(o[i], so)
            assert r[i] == sr and term[i] == st
        ended = term | trunc
    assert r.dtype == np.float64 and o.dtype == np.float32


def test_vector_info_has_gymnasiums_key_masks() -> None:
    vec = gym.make_vec("equilibrist/cartpole-balance-v0", num_envs=2)
    _, info = vec.reset(seed=0)
    assert set(info) == {"state", "_state", "noise_seed", "_noise_seed"}
    assert info["_state"].tolist() == [True, True] and info["noise_seed"].shape == (2, 4)
    actions = np.array([[1.0], [0.0]])
    while True:
        _, _, term, trunc, step_info = vec.step(actions)
        assert step_info == {}
        if term.any() or trunc.any():
            break
    assert term.tolist() == [True, False]
    _, reward, _, _, step_info = vec.step(actions)
    assert step_info["_state"].tolist() == [True, False]
    assert step_info["_noise_seed"].tolist() == [True, False]
    assert reward[0] == 0.0
    np.testing.assert_array_equal(step_info["state"][0], vec.states[0])


def test_gymnasiums_vector_wrappers_take_it() -> None:
    """CleanRL's way: make_vec's default mode, Gymnasium's episode statistics and
    observation normalization around it; the recorded return is the sum of the rewards."""
    vec = gym.make_vec("equilibrist/cartpole-balance-v1", num_envs=2)
    vec = gym.wrappers.vector.RecordEpisodeStatistics(vec)
    vec = gym.wrappers.vector.NormalizeObservation(vec)
    vec.reset(seed=0)
    totals = np.zeros(2)
    actions = np.array([[1.0], [-1.0]], dtype=np.float32)
    while True:
        _, reward, term, trunc, info = vec.step(actions)
        totals += reward
        if (term | trunc).any():
            break
    assert term.any() and not trunc.any()
    np.testing.assert_allclose(info["episode"]["r"][term], totals[term], rtol=1e-12)
    assert info["_episode"].tolist() == term.tolist()


def test_acrobot_swingup_pays_for_both_links_up_not_for_hanging() -> None:
    """On the acrobot the elbow's relative angle is 0 hanging as well as upright: the
    reward multiplies the links' uprightness (both angles hang in the swing-up, each
    scored ``(1 + cos(q - q_op)) / 2``, written out here), so hanging still pays nothing
    and upright, still and unforced pays 1."""
    env = _make("equilibrist/acrobot-swingup-v1")
    learnable = env.core.learnable
    assert learnable is not None

    def reward(theta1: float, theta2: float) -> float:
        # still and unforced: the other factors are 1
        return (1 + math.cos(theta1 - math.pi)) / 2 * (1 + math.cos(theta2)) / 2

    for theta1, theta2 in ((0.0, 0.0), (math.pi, 0.0), (math.pi - 0.3, 0.4), (2.0, -1.0)):
        x = np.array([[theta1, theta2, 0.0, 0.0]])
        got = float(learnable.reward(x, np.zeros((1, 1)))[0])
        assert got == pytest.approx(reward(theta1, theta2), rel=1e-12, abs=1e-15)
    assert float(learnable.reward(np.zeros((1, 4)), np.zeros((1, 1)))[0]) == 0.0


def _slowest_growth(env_id: str) -> float:
    """The slowest unstable mode's growth rate [1/s] at the operating point, from central
    differences of the rig's ``f`` (not its symbolic Jacobian)."""
    core = _make(env_id).core
    system, x0, u0 = core.system, np.asarray(core.task.x_op), np.asarray(core.task.u_op)
    step = 1e-6
    a = np.column_stack([(system.f(x0 + step * e, u0) - system.f(x0 - step * e, u0)) / (2 * step)
                         for e in np.eye(len(x0))])
    return float(min(e.real for e in np.linalg.eigvals(a) if e.real > 0.1))


def test_the_learnable_rate_lets_the_discount_see_the_slowest_fall() -> None:
    """``-v1`` slows a rig whose slowest unstable mode the default discount (100 steps)
    would not see for 1.5 time constants: the acrobot (1.9 /s) from 200 Hz to 100 Hz; the
    cart-pole (4.0 /s), Furuta (12.7 /s) and the reaction wheel keep their rates; ``-v0``
    and an explicit ``rate`` are as they were."""
    growth = _slowest_growth("equilibrist/acrobot-balance-v1")
    assert 1.8 < growth < 2.0
    assert 100 / 200 * growth < 1.5 <= 100 / 100 * growth  # 200 Hz too short, 100 Hz enough
    assert _make("equilibrist/acrobot-balance-v1").core.rate == 100.0
    assert _make("equilibrist/acrobot-balance-v1").core.n_samples == 1000
    assert _make("equilibrist/acrobot-balance-v0").core.rate == 200.0
    assert _make("equilibrist/acrobot-balance-v1", rate=50.0).core.rate == 50.0
    for env_id, rate in (("cartpole", 200.0), ("furuta", 500.0),
                         ("reaction_wheel_pendulum", 200.0)):
        full = f"equilibrist/{env_id}-balance-v1"
        assert 100 / rate * _slowest_growth(full) >= 1.5
        assert _make(full).core.rate == rate
