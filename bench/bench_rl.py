"""Learning curves of the recipes in examples/: return against environment steps and wall time.

Each run trains one recipe (``examples/rl_ppo_cartpole.py``: Stable-Baselines3's PPO with
its default hyperparameters on ``equilibrist/cartpole-balance-v1``;
``examples/rl_sac_swingup.py``: SAC on ``equilibrist/cartpole-swingup-v1`` at 50 Hz) with
its configuration as it is, for several seeds, one after the other on one thread
(``torch.set_num_threads(1)``). Every ``--every`` steps the deterministic policy is scored
on the recipe's fixed starts (seeds 100, 101, 102; the time spent scoring is not counted
as training time), beside the recipe's expert (the LQG on the sensors, or the energy
swing-up) on the same starts. The curves go to ``--out`` (JSON) and a figure
(``docs/images/rl_<recipe>.png``).

Usage: ``python bench/bench_rl.py ppo [--seeds 0 1 2] [--steps N] [--every N]``
(``sac`` for the swing-up). Goal: PPO balances the cart-pole within 100,000 steps (no
episode ends early, the return >= 0.9 of the LQG's on the same starts), on every seed.
"""

from __future__ import annotations

import argparse
import json
import runpy
import time
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RECIPES = {"ppo": ROOT / "examples" / "rl_ppo_cartpole.py",
           "sac": ROOT / "examples" / "rl_sac_swingup.py"}


def run(recipe: dict[str, Any], seed: int, steps: int, every: int) -> list[dict[str, Any]]:
    config = recipe["CONFIG"]
    model = recipe["make_model"](config, seed)
    seeds = config["eval_seeds"]
    returns, lengths = recipe["evaluate"](recipe["agent"](model), config, seeds)
    curve = [{"steps": 0, "seconds": 0.0, "returns": returns, "lengths": lengths}]
    trained = 0.0
    done = 0
    while done < steps:
        start = time.perf_counter()
        model.learn(every, reset_num_timesteps=False)
        trained += time.perf_counter() - start
        done += every
        returns, lengths = recipe["evaluate"](recipe["agent"](model), config, seeds)
        curve.append({"steps": done, "seconds": trained, "returns": returns,
                      "lengths": lengths})
        print(f"  seed {seed}: {done:>7} steps {trained:7.0f} s  returns "
              f"{np.round(returns, 1).tolist()} lengths {lengths}", flush=True)
    return curve


def plot(result: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4), sharey=True)
    for seed, curve in result["curves"].items():
        steps = [p["steps"] for p in curve]
        seconds = [p["seconds"] for p in curve]
        mean = [float(np.mean(p["returns"])) for p in curve]
        axes[0].plot(steps, mean, marker=".", label=f"seed {seed}")
        axes[1].plot(seconds, mean, marker=".", label=f"seed {seed}")
    for ax in axes:
        ax.axhline(float(np.mean(result["expert"])), color="k", ls="--",
                   label=f"{result['expert_kind']} (same starts)")
        ax.axhline(result["max_return"], color="0.6", ls=":", label="maximum")
        ax.grid(alpha=0.3)
    axes[0].set_xlabel("environment steps")
    axes[1].set_xlabel("training wall time [s] (one thread)")
    axes[0].set_ylabel("return (mean of 3 fixed starts)")
    axes[1].legend(fontsize=8, loc="lower right")
    fig.suptitle(f"{result['algorithm']} (Stable-Baselines3 defaults) on {result['env_id']}",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("recipe", choices=sorted(RECIPES))
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument("--every", type=int, default=10_000)
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    recipe = runpy.run_path(str(RECIPES[args.recipe]))
    config = recipe["CONFIG"]
    steps = args.steps or config["steps"]
    expert = recipe["expert_scores"](config, config["eval_seeds"])
    env = recipe["make_env"](config)
    max_return = float(env.unwrapped.core.n_samples)
    print(f"{config['algorithm']} on {config['env_id']} {config['env_options']}: {steps} steps; "
          f"{config['expert']} returns {np.round(expert, 1).tolist()} (maximum {max_return:g})")
    curves = {str(seed): run(recipe, seed, steps, args.every) for seed in args.seeds}
    result = {"algorithm": config["algorithm"], "env_id": config["env_id"],
              "env_options": config["env_options"], "expert_kind": config["expert"],
              "expert": expert, "max_return": max_return, "curves": curves}
    out = Path(args.out or f"rl_{args.recipe}.json")
    out.write_text(json.dumps(result, indent=1))
    plot(result, ROOT / "docs" / "images" / f"rl_{args.recipe}.png")
    for seed, curve in curves.items():
        last = curve[-1]
        ratio = float(np.mean(last["returns"]) / np.mean(expert))
        full = all(n == max_return for n in last["lengths"])
        print(f"seed {seed}: {ratio:.3f} of the {config['expert']}'s return, "
              f"{'no episode ends early' if full else 'an episode ends early'}")


if __name__ == "__main__":
    main()
