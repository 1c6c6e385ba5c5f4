"""The Gymnasium environments: every id passes Gymnasium's checker, a rollout
is ``simulate`` of the same actions, rewards are the task's cost, and the
vector environment is the single one, copy by copy."""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tests.support.envs import on_fake_clock

import equilibrist.envs.vector as vector_module
from equilibrist import envs, get_system
from equilibrist.envs import EnvError, EquilibristEnv, EquilibristVectorEnv
from equilibrist.errors import EquilibristError, UnknownNameError
from equilibrist.sim.run import simulate
from equilibrist.systems import registry
from equilibrist.tasks import get_task, task_names

CATALOGUE_IDS = [i for i in envs.env_ids() if i.count("-") == 2]


def _make(env_id: str, **kwargs: object) -> EquilibristEnv:
    env = gym.make(env_id, **kwargs).unwrapped
    assert isinstance(env, EquilibristEnv)
    return env


# -- registration --------------------------------------------------------------------


def test_every_system_with_an_input_has_an_id_per_task() -> None:
    expected = set()
    for name in registry.family_names():
        # A family's variants have an id each, named after the variant (dfki_double_pendulum_acrobot).
        variants = registry.variants(name)
        option = registry.variant_option(name)
        for variant in variants or (None,):
            system = get_system(name, **({option: variant} if variant else {}))
            label = f"{name}_{variant}" if variant else name
            for task in task_names(system):
                expected.add(f"equilibrist/{label}-{task}-v0")
    assert expected == set(CATALOGUE_IDS)
    assert "equilibrist/cartpole-swingup-v0" in expected
    assert {"equilibrist/balance-v0", "equilibrist/swingup-v0"} <= set(envs.env_ids())
    for env_id in envs.env_ids():
        assert env_id in gym.registry


def test_make_with_module_prefix() -> None:
    env = gym.make("equilibrist.envs:equilibrist/cartpole-balance-v0")
    obs, _ = env.reset(seed=0)
    assert obs.shape == (2,) and obs.dtype == np.float64
    assert env.observation_space.sample().shape == (2,)  # no overflow warning
    assert env.observation_space.contains(np.array([1e300, -1e300]))
    env.close()


@pytest.mark.slow
@pytest.mark.parametrize("env_id", CATALOGUE_IDS)
def test_check_env_passes_without_warning(env_id: str) -> None:
    # pytest turns every warning into an error (pyproject), Gymnasium's included.
    env = gym.make(env_id)
    check_env(env.unwrapped)
    env.close()


def test_model_file_environments(tmp_path) -> None:
    examples = os.path.join(os.path.dirname(__file__), "..", "..", "examples")
    # An MJCF model, drawn from its kinematic tree.
    env = _make("equilibrist/balance-v0", system=os.path.join(examples, "furuta.xml"))
    check_env(env)
    # A system declared in a Python file that names its points: drawn generically.
    mine = os.path.join(examples, "my_cartpole.py")
    env = _make("equilibrist/balance-v0", system=mine, render_mode="rgb_array")
    assert env.metadata["render_modes"] == ["rgb_array"]
    env.reset(seed=0)
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.std() > 0
    # The same file without its points has no drawing, so no render modes.
    text = Path(mine).read_text().replace(", points=points, links=links", "")
    bare = tmp_path / "bare_cartpole.py"
    bare.write_text(text.replace('name="my_cartpole"', 'name="bare_cartpole"'))
    env = _make("equilibrist/balance-v0", system=str(bare))
    assert env.metadata["render_modes"] == []
    check_env(env)
    with pytest.raises(EnvError, match="no drawing"):
        gym.make("equilibrist/balance-v0", system=str(bare), render_mode="rgb_array")
    with pytest.raises(EnvError, match="give the system"):
        gym.make("equilibrist/balance-v0")


# -- faithful to simulate ------------------------------------------------------------


def _rollout(env: EquilibristEnv, actions: np.ndarray, seed: int):
    obs, info = env.reset(seed=seed)
    observations, states = [obs], [env.state]
    steps = 0
    for a in actions:
        obs, _, terminated, truncated, _ = env.step(a)
        observations.append(obs)
        states.append(env.state)
        steps += 1
        if terminated or truncated:
            break
    return info, np.array(observations), np.array(states), steps, terminated


@pytest.mark.parametrize(("env_id", "kwargs"), [
    ("equilibrist/cartpole-balance-v0", {}),
    ("equilibrist/cartpole-swingup-v0", {"rate": 100.0}),
    ("equilibrist/furuta-balance-v0", {"randomize": {"m_p": 0.3}}),
])
def test_rollout_is_simulate_of_the_same_actions(env_id: str, kwargs: dict) -> None:
    """Noise included: the episode's noise seed given to simulate draws the same noise."""
    env = _make(env_id, **kwargs)
    core = env.core
    rng = np.random.default_rng(7)
    actions = rng.uniform(-0.3, 0.3, (60, core.system.n_inputs))
    info, obs, states, steps, _ = _rollout(env, actions, seed=11)
    applied = [core.physical_input(a) for a in actions[:steps]]
    system = core.system.with_params(**info.get("params", {}))

    def replay(t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        k = min(round(t * core.rate), steps - 1)
        return applied[k]

    result = simulate(
        system, replay, duration=steps / core.rate, rate=core.rate,
        physics_step=core.physics_step, x0=info["state"], noise=core.noise,
        seed=info["noise_seed"], outputs=core.observation_names, region=core.task.region,
    )
    assert result.n_rows == steps + 1
    np.testing.assert_allclose(result.states, states, rtol=0, atol=1e-12)
    np.testing.assert_allclose(result.measurements, obs, rtol=0, atol=1e-12)
    assert not np.allclose(result.measurements, result.states[:, core.c_idx])  # noise is on


def test_fall_ends_the_episode_where_simulate_falls() -> None:
    env = _make("equilibrist/cartpole-balance-v0", noise=False)
    core = env.core
    info, _obs, states, steps, terminated = _rollout(env, np.ones((400, 1)), seed=3)
    assert terminated
    result = simulate(core.system, lambda t, y, r: core.physical_input(np.ones(1)),
                      duration=steps / core.rate, rate=core.rate, x0=info["state"],
                      region=core.task.region)
    assert result.fell
    assert math.isclose(result.fell_at, steps / core.rate, abs_tol=core.period)
    assert core.task.fallen(states[-1]) and not core.task.fallen(states[-2])


def test_truncation_at_the_task_duration() -> None:
    # The reaction wheel's swing-up has no region: only time ends it.
    env = _make("equilibrist/reaction_wheel_pendulum-swingup-v0", rate=50.0, noise=False)
    env.reset(seed=0)
    n = math.ceil(env.core.task.duration * 50.0 - 1e-9)
    for k in range(n):
        _, _, terminated, truncated, _ = env.step(np.array([0.1]))
        assert not terminated
        assert truncated == (k == n - 1)


def test_observing_the_state_follows_the_same_run() -> None:
    a = _make("equilibrist/cartpole-balance-v0", observe="state")
    b = _make("equilibrist/cartpole-balance-v0")
    oa, _ = a.reset(seed=5)
    b.reset(seed=5)
    np.testing.assert_array_equal(oa, a.state)
    for _ in range(20):
        oa, *_ = a.step(np.array([0.05]))
        b.step(np.array([0.05]))
        np.testing.assert_array_equal(oa, b.state)
    assert a.observation_space.shape == (4,)


# -- rewards ---------------------------------------------------------------------------


def test_balance_reward_is_the_task_cost_and_the_alive_bonus() -> None:
    env = _make("equilibrist/cartpole-balance-v0", alive_bonus=2.0)
    task = env.core.task
    env.reset(seed=1)
    for a in (0.02, -0.05, 3.0):  # 3.0 saturates at the limit (a cost over the bonus)
        _, reward, *_ = env.step(np.array([a]))
        u = np.clip(np.array([a]), -1, 1) * 200.0  # F in [-200, 200] N
        expected = env.core.period * max(0.0, 2.0 - task.cost(env.state, u))
        assert reward == pytest.approx(expected, rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("env_id", ["equilibrist/cartpole-balance-v0",
                                    "equilibrist/acrobot-swingup-v0"])
def test_reward_is_the_tasks_own_source_to_the_bit(env_id: str) -> None:
    """The core's reward is the task's reward function (its Python source in
    ``equilibrist.tasks``, translated to C) run as plain Python on the same state, input and
    parameters: the same bits."""
    from equilibrist.tasks import python_reward, task_kind

    env = _make(env_id, noise=False)
    core = env.core
    task = core.task
    reward_py = python_reward(task_kind(task.name), core.system)
    p = np.array(core.system.p, dtype=float)
    eref = np.array([core.system.energy(task.x_op), core.system.energy(task.start)])
    env.reset(seed=4)
    lo, hi = (np.asarray(b, dtype=float) for b in core.system.input_limits)
    for a in (0.3, -0.7, 0.05, 1.0):
        _, reward, *_ = env.step(np.array([a] * core.system.n_inputs))
        u = lo + (np.clip(a, -1.0, 1.0) + 1.0) * 0.5 * (hi - lo)
        want = reward_py(np.array(env.state), u, p, core.op, 1.0 / core.sc, core.hang, eref,
                         core.period, core.alive_bonus)
        assert reward == want


def test_swingup_reward_shapes_energy_and_height() -> None:
    env = _make("equilibrist/cartpole-swingup-v0", noise=False)
    system = env.core.system
    task = env.core.task
    e_up = system.energy(task.x_op)
    e_hang = system.energy(task.start)
    env.reset(seed=2)
    for a in (0.5, -0.5, 0.2):
        _, reward, *_ = env.step(np.array([a]))
        x = env.state
        theta = x[system.state_index("theta")]
        upright = 0.5 * (1 + math.cos(theta - task.x_op[1]))
        shaping = max(0.0, 1 - ((system.energy(x) - e_up) / (e_up - e_hang)) ** 2)
        assert reward == pytest.approx(env.core.period * 0.5 * (upright + shaping), rel=1e-9)
    # Hanging at rest earns nothing; upright at rest earns dt.
    env.reset(options={"state": task.start})
    _, reward, *_ = env.step(np.array([0.0]))
    assert abs(reward) < 1e-6 * env.core.period
    env.reset(options={"state": task.x_op})
    _, reward, *_ = env.step(np.array([0.0]))
    assert reward == pytest.approx(env.core.period, rel=1e-6)


# -- actions, options, errors ----------------------------------------------------------------


def test_physical_actions_are_the_input() -> None:
    env = _make("equilibrist/cartpole-balance-v0", action_units="physical", noise=False)
    lo, hi = env.core.system.input_limits
    np.testing.assert_array_equal(env.action_space.low, lo)
    np.testing.assert_array_equal(env.action_space.high, hi)
    norm = _make("equilibrist/cartpole-balance-v0", noise=False)
    env.reset(seed=4)
    norm.reset(seed=4)
    env.step(np.array([50.0]))
    norm.step(np.array([0.25]))  # 50 N of [-200, 200]
    np.testing.assert_allclose(env.state, norm.state, rtol=0, atol=1e-14)


def test_params_and_randomization() -> None:
    heavy = _make("equilibrist/cartpole-balance-v0", params={"m_p": 2.0})
    assert heavy.params["m_p"] == 2.0
    env = _make("equilibrist/cartpole-balance-v0", randomize={"m_p": 0.2, "l": 0.1})
    nominal = env.core.system.params
    drawn = []
    for seed in range(40):
        _, info = env.reset(seed=seed)
        drawn.append(info["params"]["m_p"] / nominal["m_p"])
        assert abs(info["params"]["l"] / nominal["l"] - 1) <= 0.1
        assert env.params["m_p"] == info["params"]["m_p"]
    assert min(drawn) >= 0.8 and max(drawn) <= 1.2
    assert min(drawn) < 0.9 and max(drawn) > 1.1
    _, again = env.reset(seed=3)
    _, first = env.reset(seed=3)
    assert again["params"] == first["params"]


def test_bad_options_are_reported_together() -> None:
    with pytest.raises(EnvError) as err:
        EquilibristEnv("cartpole", "balance", physics_step=0.003, observe="angles",
                       randomize={"m_q": 0.1, "F_max": 0.1, "l": 2.0})
    text = str(err.value)
    for part in ("physics_step", "observe", "m_q", "F_max", "spread of l"):
        assert part in text
    with pytest.raises(UnknownNameError, match="task"):
        EquilibristEnv("cartpole", "walk")
    with pytest.raises(UnknownNameError, match="swingup"):
        EquilibristEnv("seesaw", "swingup")
    env = EquilibristEnv("cartpole", "balance")
    with pytest.raises(EnvError, match="reset"):
        env.step(np.zeros(1))
    env.reset(seed=0)
    with pytest.raises(EnvError, match="finite"):
        env.step(np.array([np.nan]))
    with pytest.raises(ValueError, match="expected 1"):
        env.step(np.zeros(3))


def test_unknown_options_name_the_nearest() -> None:
    with pytest.raises(EnvError, match=r"unknown option 'physics_stp'.*physics_step"):
        gym.make("equilibrist/cartpole-balance-v0", physics_stp=0.001)
    with pytest.raises(EnvError, match="unknown option 'rates'"):
        gym.make_vec("equilibrist/cartpole-balance-v0", num_envs=2,
                     vectorization_mode="vector_entry_point", rates=100.0)


def test_compiled_slots_agree_with_the_packing() -> None:
    """The compiled core's slot constants are the ones the settings are packed by."""
    from equilibrist.envs import core as _core

    core = _make("equilibrist/cartpole-swingup-v0", randomize={"m_p": 0.1}).core
    unit = core.kernel.path.with_suffix(".c").read_text()
    for prefix, names, first in (("EQ_CI_", _core.CI_SLOTS, 0), ("EQ_CF_", _core.CF_SLOTS, 0),
                                 ("EQ_US_", _core.US_SLOTS, 4)):
        for i, name in enumerate(names):
            assert f"#define {prefix}{name.upper()} {first + i}\n" in unit, name
    ci, cf = core.ci, core.cf
    slot = {name: ci[i] for i, name in enumerate(_core.CI_SLOTS)}
    n = core.system.n_states
    np.testing.assert_array_equal(cf[slot["o_region"]:slot["o_region"] + 2 * n],
                                  core.region.ravel())
    np.testing.assert_array_equal(ci[slot["o_rnd_idx"]:slot["o_rnd_idx"] + 1], core.rnd_idx)
    np.testing.assert_array_equal(cf[slot["o_lw"]:], core.lw.ravel())
    assert len(ci) == slot["o_rnd_idx"] + core.rnd_idx.size
    assert cf[slot["o_rnd_spread"]] == core.rnd_spread[0] == 0.1


# -- rendering ---------------------------------------------------------------------------------


def test_rgb_array_is_the_animation_frame() -> None:
    from equilibrist.viz.frames import FrameRenderer

    env = _make("equilibrist/cartpole-balance-v0", render_mode="rgb_array")
    env.reset(seed=0)
    env.step(np.array([0.3]))
    image = env.render()
    assert image is not None and image.dtype == np.uint8 and image.ndim == 3
    renderer = FrameRenderer(env.core.system, states=env._renderer._extent_states())
    expected = renderer.frame(env.state, env.core.physical_input(np.array([0.3])), t=env.time)
    np.testing.assert_array_equal(image, expected)
    env.close()
    env.close()


def test_human_rendering_without_a_display_says_so(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(EnvError, match="no display"):
        gym.make("equilibrist/cartpole-balance-v0", render_mode="human")


# -- the vector environment ------------------------------------------------------------------------


def _vec(n: int, env_id: str = "equilibrist/cartpole-balance-v0", **kwargs: object
         ) -> EquilibristVectorEnv:
    env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **kwargs)
    assert isinstance(env, EquilibristVectorEnv)
    return env


@pytest.mark.parametrize("env_id", ["equilibrist/cartpole-balance-v0",
                                    "equilibrist/cartpole-swingup-v0"])
def test_vector_copy_is_the_single_env(env_id: str) -> None:
    """Observations and rewards, copy by copy, with randomized parameters."""
    vec = _vec(5, env_id, noise=False, randomize={"m_p": 0.2})
    single = _make(env_id, noise=False)
    obs, info = vec.reset(seed=9)
    x0 = info["state"]
    params = vec.parameters
    rng = np.random.default_rng(0)
    actions = rng.uniform(-0.2, 0.2, (30, 5, 1))
    out = []
    for a in actions:
        out.append(vec.step(a)[:2])
    for i in range(5):
        names = single.core.system.spec.parameter_names
        env = _make(env_id, noise=False, params={"m_p": params[i, names.index("m_p")]})
        o, _ = env.reset(options={"state": x0[i]})
        np.testing.assert_array_equal(o, obs[i])
        for k in range(30):
            o, reward, *_ = env.step(actions[k, i])
            np.testing.assert_allclose(o, out[k][0][i], rtol=0, atol=1e-13)
            assert reward == pytest.approx(out[k][1][i], rel=1e-12, abs=1e-15)
    assert not np.allclose(params[0], params[1])


def test_vector_autoreset_is_next_step() -> None:
    vec = _vec(3, noise=False)
    vec.reset(seed=1)
    push = np.array([[1.0], [0.0], [0.0]])  # only copy 0 is pushed over
    for _ in range(400):
        obs, rewards, terminated, truncated, _ = vec.step(push)
        if terminated[0]:
            break
    assert terminated[0] and not terminated[1:].any() and not truncated.any()
    fallen_obs = obs[0].copy()
    obs, rewards, terminated, truncated, _ = vec.step(push)
    assert rewards[0] == 0.0 and not terminated[0]
    assert abs(obs[0, 1]) < abs(fallen_obs[1])  # a fresh start near upright
    assert vec.states[0, 1] == obs[0, 1]  # noise off: observation is the state
    assert vec.metadata["autoreset_mode"] == gym.vector.AutoresetMode.NEXT_STEP


def test_vector_seeding() -> None:
    vec = _vec(4)
    a, _ = vec.reset(seed=3)
    b, _ = vec.reset(seed=3)
    np.testing.assert_array_equal(a, b)
    assert len({row[1] for row in a}) == 4  # every copy its own start
    c, _ = vec.reset()  # continues the streams
    assert not np.array_equal(a, c)
    d, _ = vec.reset(seed=[5, 6, 7, 8])
    e, _ = vec.reset(seed=[5, 6, 7, 9])
    np.testing.assert_array_equal(d[:3], e[:3])
    assert not np.array_equal(d[3], e[3])


def test_vector_parallel_equals_serial(monkeypatch: pytest.MonkeyPatch) -> None:
    """One thread, all threads, and switching between them every other step: the same numbers."""
    runs = []
    monkeypatch.setattr(vector_module, "PROBE_EVERY", 2)
    monkeypatch.setattr(vector_module, "PROBE_SHARE", 0.0)
    for minimum in (1, 10**9):
        monkeypatch.setattr(vector_module, "PARALLEL_MIN", minimum)
        vec = _vec(64, randomize={"m_c": 0.3})
        vec.reset(seed=2)
        rng = np.random.default_rng(1)
        trace = [vec.step(rng.uniform(-1, 1, (64, 1)))[:4] for _ in range(50)]
        runs.append(trace)
        both = all(math.isfinite(cost) for cost in vec._cost)
        assert both == (minimum == 1)
    for one, two in zip(*runs, strict=True):
        for p, q in zip(one, two, strict=True):
            np.testing.assert_array_equal(p, q)


def test_vector_runs_the_faster_way(monkeypatch: pytest.MonkeyPatch) -> None:
    """The switch between one thread and all, on a fake clock: it settles on the
    faster way, follows a change, and probes a much slower way rarely."""
    cost = {0: 1.0, 1: 0.5}  # seconds per step: one thread, all threads
    runs = {0: 0, 1: 0}

    def seconds(mode: int) -> float:
        runs[mode] += 1
        return cost[mode]

    vec = on_fake_clock(monkeypatch, seconds)
    a = np.zeros((4, 1))
    for _ in range(200):
        vec.step(a)
    assert vec.threads_in_use > 1 and runs[0] < 10
    runs.update({0: 0, 1: 0})
    for _ in range(5000):  # probes that confirm the way come rarer and rarer
        vec.step(a)
    backoff = math.ceil(math.log2(vector_module.PROBE_EVERY_MAX / vector_module.PROBE_EVERY))
    assert 0 < runs[0] <= vector_module.PROBE_STEPS * (backoff + 5000 // vector_module.PROBE_EVERY_MAX + 1)
    cost[1] = 40.0  # the other cores got busy: all threads now 40 times slower
    for _ in range(10):
        vec.step(a)
    assert vec.threads_in_use == 1
    runs.update({0: 0, 1: 0})
    for _ in range(5000):
        vec.step(a)
    assert vec.threads_in_use == 1
    share = runs[1] * cost[1] / (runs[0] * cost[0] + runs[1] * cost[1])
    assert 0 < share < 2 / vector_module.PROBE_SHARE  # still probed, rarely
    cost[1] = 0.5  # quiet again
    for _ in range(3000):
        vec.step(a)
    assert vec.threads_in_use > 1


def test_vector_probe_outlasts_one_interrupted_step(monkeypatch: pytest.MonkeyPatch) -> None:
    """A probe of the parallel way whose first two steps are slow (threads waking,
    then a moment's interruption) still finds it faster: the best timed step counts."""
    last = [0]  # the way of the previous step
    streak = [0]  # parallel steps in a row

    def seconds(mode: int) -> float:
        streak[0] = streak[0] + 1 if mode == 1 and last[0] == 1 else int(mode == 1)
        last[0] = mode
        return 1.0 if mode == 0 else (5.0 if streak[0] <= 2 else 0.5)

    vec = on_fake_clock(monkeypatch, seconds)
    vec._mode = 0  # start on one thread
    a = np.zeros((4, 1))
    for _ in range(400):
        vec.step(a)
    assert vec.threads_in_use > 1


def test_vector_sensor_noise_has_the_rigs_spread() -> None:
    """Observation minus the true output: zero mean, the catalogue's sensor sigma."""
    vec = _vec(400)
    vec.reset(seed=0)
    system = vec.core.system
    errors = []
    for _ in range(10):
        obs, *_ = vec.step(np.zeros((400, 1)))
        errors.append(obs - vec.states[:, vec.core.c_idx])
    err = np.concatenate(errors)
    for j, name in enumerate(vec.core.observation_names):
        sigma = system.spec.sensor_noise[name]
        assert abs(err[:, j].mean()) < 4 * sigma / math.sqrt(err.shape[0])
        assert err[:, j].std() == pytest.approx(sigma, rel=0.05)


def test_vector_render_draws_every_copy() -> None:
    vec = _vec(2, render_mode="rgb_array")
    vec.reset(seed=0)
    vec.step(np.array([[0.5], [-0.5]]))
    frames = vec.render()
    assert frames is not None and len(frames) == 2
    assert frames[0].dtype == np.uint8 and frames[0].shape == frames[1].shape
    assert not np.array_equal(frames[0], frames[1])
    vec.close()


def test_vector_rejects_bad_input() -> None:
    vec = _vec(2)
    with pytest.raises(EnvError, match="reset"):
        vec.step(np.zeros((2, 1)))
    vec.reset(seed=0)
    with pytest.raises(EnvError, match="finite"):
        vec.step(np.array([[0.0], [np.inf]]))
    with pytest.raises(ValueError, match="shape"):
        vec.step(np.zeros((3, 1)))
    # A bad action steps no copy at all.
    before = vec.states
    with pytest.raises(EnvError, match="finite"):
        vec.step(np.array([[0.5], [np.nan]]))
    np.testing.assert_array_equal(vec.states, before)


def test_vector_returns_fresh_arrays() -> None:
    """A step's arrays are its own: the next step does not write into them."""
    vec = _vec(8, noise=False)
    vec.reset(seed=0)
    first = vec.step(np.full((8, 1), 0.3))[:4]
    kept = [a.copy() for a in first]
    vec.step(np.full((8, 1), -0.3))
    for a, b in zip(first, kept, strict=True):
        np.testing.assert_array_equal(a, b)
    assert first[0].flags.c_contiguous and first[0].flags.writeable
    with pytest.raises(EnvError, match="num_envs"):
        EquilibristVectorEnv(0, "cartpole")


def test_task_start_is_used() -> None:
    env = _make("equilibrist/cartpole-swingup-v0", noise=False)
    task = get_task(env.core.system, "swingup")
    for seed in range(5):
        _, info = env.reset(seed=seed)
        assert np.all(np.abs(info["state"] - task.start) <= task.spread + 1e-15)


# -- actions and starts that are not real numbers -------------------------------------------
# What an agent or a user may hand over where numbers belong: one of these, or a
# container of them.
NOT_REAL = st.one_of(
    st.text(max_size=8), st.just({"F": 1.0}), st.builds(object), st.none(), st.booleans(),
    st.complex_numbers(allow_nan=False, allow_infinity=False), st.just(b"1"),
)
NOT_ACTIONS = st.one_of(
    NOT_REAL,
    NOT_REAL.map(lambda v: [v]),
    NOT_REAL.map(lambda v: np.array([v], dtype=object)),
    st.complex_numbers(allow_nan=False, allow_infinity=False).map(lambda c: np.array([c])),
    st.just([[0.1, 0.2], [0.3]]),
)


def _refused(call: Callable[[], object], *words: str) -> str:
    with pytest.raises(EquilibristError) as info:
        call()
    assert isinstance(info.value, ValueError)
    text = str(info.value)
    assert "\n" not in text
    for word in words:
        assert word in text, text
    return text


@pytest.fixture(scope="module")
def stepped() -> tuple[EquilibristEnv, EquilibristVectorEnv]:
    env = EquilibristEnv("cartpole", "balance")
    env.reset(seed=0)
    vec = EquilibristVectorEnv(3, "cartpole", "balance")
    vec.reset(seed=0)
    return env, vec


@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(action=NOT_ACTIONS)
def test_an_action_that_is_not_real_numbers_is_named(stepped, action: object) -> None:
    env, vec = stepped
    before = env.state
    _refused(lambda: env.step(action), "action", "expected 1 real number", "[-1, 1]", "shape (1,)")
    np.testing.assert_array_equal(env.state, before)  # nothing was stepped
    states = vec.states
    batch = action if isinstance(action, np.ndarray | list) else [action] * 3
    _refused(lambda: vec.step(batch), "actions", "expected shape (3, 1)", "real number")
    np.testing.assert_array_equal(vec.states, states)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(state=st.one_of(NOT_REAL, NOT_REAL.filter(lambda v: not isinstance(v, bool))
                       .map(lambda v: [0.0, 0.0, 0.0, v])))
def test_a_start_that_is_not_real_numbers_is_named(stepped, state: object) -> None:
    env, _ = stepped
    _refused(lambda: env.reset(options={"state": state}), "reset options", "state must be 4",
             "x, theta, x_dot, theta_dot")


def test_real_actions_in_any_form_still_step(stepped) -> None:
    env, vec = stepped
    for action in (0.1, [0.1], (0.1,), np.array([0.1], dtype=np.float32), np.array([[0.1]]), [1],
                   np.array([0.1], dtype=object)):
        env.reset(seed=1)
        obs, *_ = env.step(action)
        assert obs.shape == (env.core.n_obs,)
    for actions in ([0.1, 0.2, 0.3], np.zeros((3, 1), dtype=np.float32), [[0], [1], [2]]):
        obs, *_ = vec.step(actions)
        assert obs.shape == (3, vec.core.n_obs)
