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

Usage: ``python bench/bench_rl.py ppo [--env ID] [--seeds 0 1 2] [--steps N] [--every N]``
(``--env equilibrist/furuta-balance-v1``: the same recipe on another balance task; ``sac``
for the swing-up, ``--env equilibrist/acrobot-swingup-v1`` for the acrobot's entry of the
recipe); ``python bench/bench_rl.py plot a.json b.json --name ppo_furuta``: one figure of
seeds run apart; ``python bench/bench_rl.py race``: PPO's defaults on Gymnasium's
CartPole-v1 and on ``cartpole-balance-v1`` interleaved in one process (rollout by rollout,
seed after seed), the training wall time until each is solved; ``python bench/bench_rl.py policy-c``: an
exported 2x64 policy's C step time, ``make check`` and ``make size``; ``python
bench/bench_rl.py throughput``: PPO's training steps per second over 16 copies, the adapter
against ``DummyVecEnv``. Goals: PPO balances the cart-pole within 100,000 steps and the
acrobot, Furuta and reaction-wheel pendulums within 300,000 (no episode ends early, the
return >= 0.9 of the LQG's on the same starts), on every seed, and solves the cart-pole
no slower in wall time than CartPole-v1; the exported policy steps in under 20 us and
equals PyTorch's forward pass to 1e-6.
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


def recipe_config(recipe: dict[str, Any], env_id: str | None) -> dict[str, Any]:
    """The recipe's configuration for *env_id*: its own entry in ``CONFIGS`` (one a task),
    else its ``CONFIG`` with the id replaced."""
    if "CONFIGS" in recipe:
        configs: dict[str, dict[str, Any]] = recipe["CONFIGS"]
        return configs[system_of(env_id) if env_id else next(iter(configs))]
    config: dict[str, Any] = recipe["CONFIG"]
    return {**config, "env_id": env_id} if env_id else config


def run(recipe: dict[str, Any], config: dict[str, Any], seed: int, steps: int, every: int,
        save: Any = None) -> list[dict[str, Any]]:
    """One seed's curve; *save* (if given) is called with the curve after each point."""
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
        if save is not None:
            save(curve)
    return curve


def system_of(env_id: str) -> str:
    """``equilibrist/furuta-balance-v1`` -> ``furuta``."""
    return env_id.rsplit("/", maxsplit=1)[-1].split("-", maxsplit=1)[0]


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
    axes[0].xaxis.set_major_formatter(lambda v, _pos: f"{v / 1000:g}k")
    axes[0].set_xlabel("environment steps")
    axes[1].set_xlabel("training wall time [s] (one thread)")
    axes[0].set_ylabel("return (mean of 3 fixed starts)")
    axes[1].legend(fontsize=8, loc="lower right")
    fig.suptitle(f"{result['algorithm']} (Stable-Baselines3 defaults) on {result['env_id']}",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


_TIMER_C = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <time.h>
#include "policy.h"
int main(void) {
    policy_state s;
    double y[4] = {0.1, 0.05, 0.0, 0.0}, u[1], acc = 0.0, best = 1e30;
    int i, r, n = 100000;
    policy_init(&s);
    for (r = 0; r < 7; r++) {
        struct timespec a, b;
        double us;
        clock_gettime(CLOCK_MONOTONIC, &a);
        for (i = 0; i < n; i++) {
            y[0] = 1e-6 * i;
            policy_output(&s, 0.0, y, u);
            policy_update(&s, 0.0, y, u);
            acc += u[0];
        }
        clock_gettime(CLOCK_MONOTONIC, &b);
        us = ((b.tv_sec - a.tv_sec) * 1e9 + (b.tv_nsec - a.tv_nsec)) / n / 1e3;
        if (us < best) best = us;
    }
    printf("%.3f %g\n", best, acc);
    return 0;
}
"""


def policy_step(folder: Path) -> dict[str, float]:
    """An exported 2x64 tanh policy of the cart-pole: its C step (output and update, the
    best of 7 runs of 100,000 at -O2), its agreement with PyTorch's forward pass, and
    ``make size``."""
    import subprocess

    import torch

    from equilibrist import get_system
    from equilibrist.controllers.network import network_controller, read_network

    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Linear(4, 64), torch.nn.Tanh(), torch.nn.Linear(64, 64),
                              torch.nn.Tanh(), torch.nn.Linear(64, 1))
    folder.mkdir(parents=True, exist_ok=True)
    torch.save(net.state_dict(), folder / "net.pt")
    out = folder / "export"
    subprocess.run(["equilibrist", "export", "cartpole", "--policy", str(folder / "net.pt"),
                    "--out", str(out), "--force"], check=True, capture_output=True)
    check = subprocess.run(["make", "-s", "-C", str(out), "check"], check=True, capture_output=True,
                           text=True).stdout.strip().splitlines()[-1]
    size = subprocess.run(["make", "-s", "-C", str(out), "size"], check=True,
                          capture_output=True, text=True).stdout.split()
    (out / "timer.c").write_text(_TIMER_C)
    subprocess.run(["cc", "-std=c99", "-O2", "-ffp-contract=off", "-I", str(out), "-o",
                    str(out / "timer"), str(out / "timer.c"), str(out / "policy.c"), "-lm"],
                   check=True)
    us = float(subprocess.run([str(out / "timer")], check=True, capture_output=True,
                              text=True).stdout.split()[0])
    ctrl = network_controller(get_system("cartpole"), read_network(folder / "net.pt"),
                              rate=200.0)
    runtime = ctrl.runtime()
    xs = np.random.default_rng(0).normal(size=(1000, 4)) * [0.5, 0.2, 1.0, 1.0]
    with torch.no_grad():
        want = net.double()(torch.from_numpy(xs / [0.5, 0.2, 1.0, 1.0])).clamp(-1, 1).numpy()
    got = np.array([runtime.output(0.0, x, np.zeros(0)) for x in xs]) / 200.0
    print(f"exported 2x64 policy: {us:.2f} us a step in C; make check: {check}; "
          f"make size: {' '.join(size)}; |action - torch (float64)| <= "
          f"{np.abs(got - want).max():.1e}")
    return {"us_per_step": us, "max_abs_error": float(np.abs(got - want).max())}


def throughput(algorithm: str = "ppo", copies: int = 16, rollouts: int = 6) -> dict[str, float]:
    """Training steps per second on *copies* copies of a task: the adapter over the native
    vector environment against Stable-Baselines3's ``DummyVecEnv`` of as many single
    environments (``make_vec_env``), the same learner, one thread, the best of three
    interleaved repetitions. PPO on ``cartpole-balance-v1`` (rollouts of 128 steps a copy,
    one epoch, so that stepping weighs as much as it does in a collection-bound training);
    SAC on ``cartpole-swingup-v1`` at 50 Hz with its defaults (one gradient step of a batch
    of 256 after each step of the copies)."""
    import torch
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.base_class import BaseAlgorithm
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.logger import Logger

    from equilibrist.envs.sb3 import sb3_vec_env

    torch.set_num_threads(1)
    if algorithm == "ppo":
        env_id, options, steps = "equilibrist/cartpole-balance-v1", {}, copies * 128 * rollouts

        def learner(env: Any) -> BaseAlgorithm:
            return PPO("MlpPolicy", env, n_steps=128, batch_size=copies * 128, n_epochs=1,
                       seed=0, device="cpu")
    else:
        env_id, options, steps = "equilibrist/cartpole-swingup-v1", {"rate": 50}, copies * 200

        def learner(env: Any) -> BaseAlgorithm:
            return SAC("MlpPolicy", env, seed=0, device="cpu")
    makers = {"adapter": lambda: sb3_vec_env(env_id, num_envs=copies, seed=0, **options),
              "DummyVecEnv": lambda: make_vec_env(env_id, n_envs=copies, seed=0,
                                                  env_kwargs=options)}
    best = dict.fromkeys(makers, 0.0)
    for _ in range(3):
        for name, make in makers.items():
            model = learner(make())
            model.set_logger(Logger(folder=None, output_formats=[]))  # no folder in /tmp
            model.learn(copies * 128)  # warm (and past SAC's first 100 steps without learning)
            start = time.perf_counter()
            model.learn(steps, reset_num_timesteps=False)
            best[name] = max(best[name], steps / (time.perf_counter() - start))
    print(f"{algorithm.upper()} on {copies} copies of {env_id} {options}: adapter "
          f"{best['adapter']:,.0f} steps/s, DummyVecEnv {best['DummyVecEnv']:,.0f} steps/s, "
          f"ratio {best['adapter'] / best['DummyVecEnv']:.2f}")
    return best


#: The race: Gymnasium's CartPole-v1 against the project's balance task, PPO's defaults.
RACE_IDS = ("CartPole-v1", "equilibrist/cartpole-balance-v1")


def _score(model: Any, env: Any) -> tuple[list[float], list[int]]:
    """The deterministic policy's return and length from each of seeds 100-102."""
    returns, lengths = [], []
    for start_seed in (100, 101, 102):
        obs, _ = env.reset(seed=start_seed)
        total, n, done = 0.0, 0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(
                model.predict(obs, deterministic=True)[0])
            total += float(reward)
            n += 1
            done = terminated or truncated
        returns.append(total)
        lengths.append(n)
    return returns, lengths


def race(seeds: list[int], max_steps: int, out: Path) -> dict[str, Any]:
    """PPO's defaults (one thread) on Gymnasium's CartPole-v1 and on ``cartpole-balance-v1``,
    interleaved in one process (a rollout of 2,048 steps and its update on one, then on the
    other, so that both train under the same load), each scored on seeds 100-102 after every
    rollout until solved: CartPole-v1's mean return 500; ours: no episode ends early and the
    return at least 0.9 of the LQG's. The training wall time until each is solved."""
    import gymnasium as gym
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.logger import Logger

    torch.set_num_threads(1)
    recipe = runpy.run_path(str(RECIPES["ppo"]))
    config = recipe["CONFIG"]
    lqg = float(np.mean(recipe["expert_scores"](config, config["eval_seeds"])))
    targets = {"CartPole-v1": {"reference": 500.0, "fraction": 1.0, "length": 500},
               "equilibrist/cartpole-balance-v1": {"reference": lqg, "fraction": 0.9,
                                                   "length": 2000}}
    result: dict[str, Any] = {"targets": targets, "runs": []}
    for seed in seeds:
        runs = {}
        for env_id in RACE_IDS:
            model = PPO("MlpPolicy", gym.make(env_id), seed=seed, device="cpu")
            model.set_logger(Logger(folder=None, output_formats=[]))
            runs[env_id] = {"env_id": env_id, "seed": seed, "points": [], "solved_at": None,
                            "seconds": 0.0, "model": model, "scoring": gym.make(env_id)}
        while any(r["solved_at"] is None and r["model"].num_timesteps < max_steps
                  for r in runs.values()):
            for env_id, r in runs.items():
                model = r["model"]
                if r["solved_at"] is not None or model.num_timesteps >= max_steps:
                    continue
                start = time.perf_counter()
                model.learn(model.n_steps, reset_num_timesteps=False)
                r["seconds"] += time.perf_counter() - start
                returns, lengths = _score(model, r["scoring"])
                target = targets[env_id]
                solved = (min(lengths) == target["length"] and float(np.mean(returns))
                          >= target["fraction"] * target["reference"])
                r["points"].append({"steps": model.num_timesteps, "seconds": r["seconds"],
                                    "returns": returns, "lengths": lengths})
                if solved:
                    r["solved_at"] = model.num_timesteps
        for r in runs.values():
            del r["model"], r["scoring"]
            result["runs"].append(r)
            print(f"  {r['env_id']:<34} seed {seed}: solved at {r['solved_at']} steps, "
                  f"{r['seconds']:.0f} s of training", flush=True)
        out.write_text(json.dumps(result, indent=1))
    return result


def plot_race(result: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.4), sharey=True)
    colors = dict(zip(RACE_IDS, ("C0", "C3"), strict=True))
    for run_ in result["runs"]:
        target = result["targets"][run_["env_id"]]["reference"]
        frac = [float(np.mean(p["returns"])) / target for p in run_["points"]]
        label = run_["env_id"] if run_["seed"] == result["runs"][0]["seed"] else None
        axes[0].plot([p["steps"] for p in run_["points"]], frac, color=colors[run_["env_id"]],
                     label=label, alpha=0.8)
        axes[1].plot([p["seconds"] for p in run_["points"]], frac,
                     color=colors[run_["env_id"]], alpha=0.8)
    for ax in axes:
        ax.axhline(1.0, color="0.6", ls=":")
        ax.grid(alpha=0.3)
    axes[0].xaxis.set_major_formatter(lambda v, _pos: f"{v / 1000:g}k")
    axes[0].set_xlabel("environment steps")
    axes[1].set_xlabel("training wall time [s] (one thread, interleaved)")
    axes[0].set_ylabel("return / reference (500; the LQG's)")
    axes[0].legend(fontsize=8, loc="lower right")
    fig.suptitle("PPO (Stable-Baselines3 defaults) until solved, 3 seeds", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def plot_merged(paths: list[str], name: str) -> None:
    """One figure from the curves of several runs' JSON files (seeds run apart)."""
    results = [json.loads(Path(p).read_text()) for p in paths]
    merged = {**results[0], "curves": {k: v for r in results for k, v in r["curves"].items()}}
    plot(merged, ROOT / "docs" / "images" / f"rl_{name}.png")
    expert = float(np.mean(merged["expert"]))
    for seed, curve in merged["curves"].items():
        ok = [min(p["lengths"]) == merged["max_return"]
              and float(np.mean(p["returns"])) >= 0.9 * expert for p in curve]
        since = next((curve[i]["steps"] for i in range(len(curve)) if all(ok[i:])), None)
        last = curve[-1]
        print(f"seed {seed}: goal met from {since} steps on, at {last['steps']} steps "
              f"{float(np.mean(last['returns'])):.1f} ({float(np.mean(last['returns'])) / expert:.3f}"
              f" of the {merged['expert_kind']}'s), {last['seconds']:.0f} s of training")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("recipe", choices=[*sorted(RECIPES), "policy-c", "throughput", "race",
                                           "plot"])
    parser.add_argument("files", nargs="*", help="plot: the runs' JSON files to draw as one")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--steps", type=int, default=None)
    parser.add_argument("--every", type=int, default=10_000)
    parser.add_argument("--out", default=None)
    parser.add_argument("--env", default=None,
                        help="another task for the recipe (equilibrist/furuta-balance-v1)")
    parser.add_argument("--algorithm", choices=["ppo", "sac"], default="ppo",
                        help="throughput: the learner (PPO on the balance, SAC on the swing-up)")
    parser.add_argument("--name", default="ppo", help="plot: the figure's name (rl_NAME.png)")
    args = parser.parse_args()
    if args.recipe == "throughput":
        throughput(args.algorithm)
        return
    if args.recipe == "race":
        out = Path(args.out or "rl_race.json")
        plot_race(race(args.seeds, args.steps or 150_000, out), ROOT / "docs" / "images"
                  / "rl_race.png")
        return
    if args.recipe == "plot":
        plot_merged(args.files, args.name)
        return
    if args.recipe == "policy-c":
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            policy_step(Path(tmp))
        return
    recipe = runpy.run_path(str(RECIPES[args.recipe]))
    config = recipe_config(recipe, args.env)
    steps = args.steps or config["steps"]
    expert = recipe["expert_scores"](config, config["eval_seeds"])
    env = recipe["make_env"](config)
    max_return = float(env.unwrapped.core.n_samples)
    print(f"{config['algorithm']} on {config['env_id']} {config['env_options']}: {steps} steps; "
          f"{config['expert']} returns {np.round(expert, 1).tolist()} (maximum {max_return:g})")
    name = args.recipe if not args.env else f"{args.recipe}_{system_of(args.env)}"
    curves: dict[str, list[dict[str, Any]]] = {}
    result = {"algorithm": config["algorithm"], "env_id": config["env_id"],
              "env_options": config["env_options"], "expert_kind": config["expert"],
              "expert": expert, "max_return": max_return, "curves": curves}
    out = Path(args.out or f"rl_{name}.json")

    for seed in args.seeds:
        def save(curve: list[dict[str, Any]], key: str = str(seed)) -> None:
            curves[key] = curve
            out.write_text(json.dumps(result, indent=1))

        save(run(recipe, config, seed, steps, args.every, save))
    plot(result, ROOT / "docs" / "images" / f"rl_{name}.png")
    for seed, curve in curves.items():
        last = curve[-1]
        ratio = float(np.mean(last["returns"]) / np.mean(expert))
        full = all(n == max_return for n in last["lengths"])
        print(f"seed {seed}: {ratio:.3f} of the {config['expert']}'s return, "
              f"{'no episode ends early' if full else 'an episode ends early'}")


if __name__ == "__main__":
    main()
