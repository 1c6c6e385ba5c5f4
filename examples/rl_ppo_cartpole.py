"""Stable-Baselines3's PPO, with its default hyperparameters, learns to balance the cart-pole.

``PPO("MlpPolicy", env)`` on ``equilibrist/cartpole-balance-v1`` (actions in [-1, 1],
observations in Bryson units, dm_control's reward in [0, 1] per step: 2,000 at most in
an episode of 10 s at 200 Hz), then scored with its deterministic policy on fixed starts,
beside the same policy untrained and the LQG controller from ``envs.expert`` on the same
starts (the LQG measures the cart and the pole's angle with the rig's sensor noise; the
agent sees the state). The whole configuration is ``CONFIG``.

Run as it is for the full training (100,000 steps, a few minutes on one core), or
``--steps 4096`` for a short one. Needs ``pip install 'equilibrist[rl]'``.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import PPO
from stable_baselines3.common.logger import Logger

import equilibrist.envs  # noqa: F401  (registers the environments)
from equilibrist.envs.expert import expert

CONFIG: dict[str, Any] = {
    "env_id": "equilibrist/cartpole-balance-v1",
    "env_options": {},
    "algorithm": "PPO",
    "policy": "MlpPolicy",
    "hyperparameters": {},  # Stable-Baselines3's defaults
    "steps": 100_000,
    "seed": 0,
    "eval_seeds": [100, 101, 102],
    "expert": "lqg",
}


def make_env(config: dict[str, Any], **overrides: Any) -> gym.Env:
    return gym.make(config["env_id"], **{**config["env_options"], **overrides})


def make_model(config: dict[str, Any], seed: int) -> PPO:
    torch.set_num_threads(1)  # the same numbers on every run
    model = PPO(config["policy"], make_env(config), seed=seed, device="cpu",
                **config["hyperparameters"])
    # Stable-Baselines3's own logger makes an empty folder in /tmp for every model it trains.
    model.set_logger(Logger(folder=None, output_formats=[]))
    return model


def evaluate(policy: Any, config: dict[str, Any], seeds: list[int], **env_options: Any
             ) -> tuple[list[float], list[int]]:
    """Each start's return and length under *policy* (observation -> action)."""
    env = make_env(config, **env_options)
    returns, lengths = [], []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        if hasattr(policy, "reset"):
            policy.reset()
        total, steps = 0.0, 0
        while True:
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            total += float(reward)
            steps += 1
            if terminated or truncated:
                break
        returns.append(total)
        lengths.append(steps)
    return returns, lengths


def agent(model: PPO) -> Any:
    return lambda obs: model.predict(obs, deterministic=True)[0]


def expert_scores(config: dict[str, Any], seeds: list[int]) -> list[float]:
    """The expert on the same starts; the LQG measures the rig's sensors."""
    env = make_env(config, observe="outputs")
    return evaluate(expert(env, config["expert"]), config, seeds, observe="outputs")[0]


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=CONFIG["steps"])
    parser.add_argument("--seed", type=int, default=CONFIG["seed"])
    args = parser.parse_args(argv)
    seeds = CONFIG["eval_seeds"]
    model = make_model(CONFIG, args.seed)
    before, before_len = evaluate(agent(model), CONFIG, seeds)
    start = time.perf_counter()
    model.learn(args.steps)
    seconds = time.perf_counter() - start
    after, after_len = evaluate(agent(model), CONFIG, seeds)
    lqg = expert_scores(CONFIG, seeds)
    print(f"{CONFIG['algorithm']} on {CONFIG['env_id']}, {args.steps} steps in {seconds:.0f} s")
    print(f"  untrained: returns {np.round(before, 1).tolist()}, lengths {before_len}")
    print(f"  trained:   returns {np.round(after, 1).tolist()}, lengths {after_len}")
    print(f"  {CONFIG['expert']}:       returns {np.round(lqg, 1).tolist()}")
    print(f"  trained / {CONFIG['expert']}: {np.mean(after) / np.mean(lqg):.3f}")
    return {"before": before, "after": after, "expert": lqg, "lengths": after_len}


if __name__ == "__main__":
    main()
