"""Stable-Baselines3's SAC, with its default hyperparameters, learns a swing-up: the
cart-pole's, or the acrobot's.

``SAC("MlpPolicy", env)`` on ``equilibrist/<task>-swingup-v1`` at a control rate of
50 Hz (a step of 20 ms: SAC's discount of 0.99 then looks two seconds ahead, about one
swing), from hanging to balanced: the swing-up's reward is the balance's (dm_control's
cart-pole reward in [0, 1] per step; on the acrobot both links must be up), observations
in Bryson units with each hanging angle as its cosine and sine, 750 steps in an episode of
15 s. It is scored with its deterministic policy on fixed starts, beside the same policy
untrained and the project's energy swing-up (``envs.expert(env, "swingup")``) on the same
starts. Each task's whole configuration is its entry in ``CONFIGS`` (``swingup_config``: the
same settings for each rig).

``python examples/rl_sac_swingup.py [cartpole|acrobot]`` runs the full training (300,000
steps: hours on one core), ``--steps 3000`` a short one. Needs
``pip install 'equilibrist[rl]'``.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3 import SAC
from stable_baselines3.common.logger import Logger

import equilibrist.envs  # noqa: F401  (registers the environments)
from equilibrist.envs.expert import expert


def swingup_config(system: str) -> dict[str, Any]:
    """The configuration of SAC on *system*'s swing-up (``<system>-swingup-v1``)."""
    return {
        "env_id": f"equilibrist/{system}-swingup-v1",
        "env_options": {"rate": 50.0},
        "algorithm": "SAC",
        "policy": "MlpPolicy",
        "hyperparameters": {},  # Stable-Baselines3's defaults
        "steps": 300_000,
        "seed": 0,
        "eval_seeds": [100, 101, 102],
        "expert": "swingup",
    }


CONFIGS: dict[str, dict[str, Any]] = {system: swingup_config(system)
                                      for system in ("cartpole", "acrobot")}


def make_env(config: dict[str, Any], **overrides: Any) -> gym.Env:
    return gym.make(config["env_id"], **{**config["env_options"], **overrides})


def make_model(config: dict[str, Any], seed: int) -> SAC:
    torch.set_num_threads(1)  # the same numbers on every run
    model = SAC(config["policy"], make_env(config), seed=seed, device="cpu",
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


def agent(model: SAC) -> Any:
    return lambda obs: model.predict(obs, deterministic=True)[0]


def expert_scores(config: dict[str, Any], seeds: list[int]) -> list[float]:
    """The expert on the same starts; the swing-up measures the rig's sensors."""
    env = make_env(config, observe="outputs")
    return evaluate(expert(env, config["expert"]), config, seeds, observe="outputs")[0]


def main(argv: list[str] | None = None) -> dict[str, Any]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("task", nargs="?", choices=sorted(CONFIGS), default="cartpole")
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument("--seed", type=int, default=None)
    args = parser.parse_args(argv)
    config = CONFIGS[args.task]
    steps = config["steps"] if args.steps is None else args.steps
    seeds = config["eval_seeds"]
    model = make_model(config, config["seed"] if args.seed is None else args.seed)
    before, _ = evaluate(agent(model), config, seeds)
    start = time.perf_counter()
    model.learn(steps)
    seconds = time.perf_counter() - start
    after, lengths = evaluate(agent(model), config, seeds)
    swingup = expert_scores(config, seeds)
    print(f"{config['algorithm']} on {config['env_id']}, {steps} steps in {seconds:.0f} s")
    print(f"  untrained: returns {np.round(before, 1).tolist()}")
    print(f"  trained:   returns {np.round(after, 1).tolist()}, lengths {lengths}")
    print(f"  {config['expert']}:   returns {np.round(swingup, 1).tolist()}")
    return {"before": before, "after": after, "expert": swingup, "lengths": lengths}


if __name__ == "__main__":
    main()
