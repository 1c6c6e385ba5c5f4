"""Train a linear policy for the cart-pole with the cross-entropy method, and
compare it with the LQR on the same starts.

The vector environment steps every copy in the compiled core: each
generation evaluates its whole population, each policy on the same few
starts, in one batch. The policy is ``a = clip(W z)`` with ``z`` the state's
deviation from upright divided by its Bryson scale (the task's cost is
``|z|^2 + |du / scale|^2``) and ``a`` the normalized force in ``[-1, 1]``.
The cross-entropy method (Rubinstein 1999) keeps a Gaussian over ``W``,
samples a population, and refits the Gaussian to the best fifth.

Both policies are then scored on one set of fresh starts by the task's
integrated cost; the LQR (from the same Bryson weights, at the same rate)
is the optimum for the linearized plant, so the ratio says how close a
dozen generations of black-box search come to it.

Run as it is (a short setting: ten generations), or longer with
``--generations 40 --population 64``.
"""

from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np

import equilibrist.envs  # noqa: F401  (registers the environments)
from equilibrist.control.design import design

ENV_ID = "equilibrist/cartpole-balance-v0"
RATE = 50.0  # Hz: one step is 20 ms (20 RK4 steps of 1 ms)


def make(num_envs: int) -> gym.vector.VectorEnv:
    return gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        rate=RATE, observe="state", noise=False)


def evaluate(env: gym.vector.VectorEnv, gains: np.ndarray, seed: int) -> tuple[np.ndarray, ...]:
    """One episode per copy; copy ``i`` runs the policy ``gains[i]``.

    Returns each copy's return, integrated cost and whether it fell.
    """
    core = env.unwrapped.core  # type: ignore[attr-defined]
    task = core.task
    scales = task.state_scales
    n = env.num_envs
    obs, _ = env.reset(seed=seed)
    returns = np.zeros(n)
    cost = np.zeros(n)
    fell = np.zeros(n, dtype=bool)
    live = np.ones(n, dtype=bool)
    while live.any():
        z = (obs - task.x_op) / scales
        actions = np.clip(np.einsum("ij,ij->i", gains, z), -1.0, 1.0)[:, None]
        u = core.physical_input(actions)
        obs, rewards, terminated, truncated, _ = env.step(actions)
        # The observation is the state reached (noise off, the state observed).
        returns[live] += rewards[live]
        cost[live] += core.period * task.cost(obs[live], u[live])
        fell |= live & terminated
        live &= ~(terminated | truncated)
    return returns, cost, fell


def lqr_gain(env: gym.vector.VectorEnv) -> np.ndarray:
    """The discrete LQR at the env's rate, in the policy's coordinates."""
    core = env.unwrapped.core  # type: ignore[attr-defined]
    K = design(core.system, rate=core.rate).K  # u - u_op = -K (x - x_op)
    lo, hi = core.limits
    half = (hi - lo) / 2
    # a = (u - mid) / half with u_op at the middle of the limits (0 N).
    return (-K[0] * core.task.state_scales) / half[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--generations", type=int, default=10)
    parser.add_argument("--population", type=int, default=40)
    parser.add_argument("--starts", type=int, default=5, help="starts per policy and generation")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    rng = np.random.default_rng(args.seed)
    pop, starts = args.population, args.starts
    env = make(pop * starts)
    n_params = env.single_observation_space.shape[0]
    mean = np.zeros(n_params)
    std = np.full(n_params, 0.5)
    elite = max(2, pop // 5)
    print(f"cross-entropy search on {ENV_ID} at {RATE:g} Hz: {pop} policies x {starts} starts "
          f"= {pop * starts} copies per generation")
    for gen in range(args.generations):
        candidates = mean + std * rng.standard_normal((pop, n_params))
        gains = np.repeat(candidates, starts, axis=0)
        returns, _, fell = evaluate(env, gains, seed=args.seed * 1000 + gen)
        score = returns.reshape(pop, starts).mean(axis=1)
        best = candidates[np.argsort(score)[-elite:]]
        mean, std = best.mean(axis=0), best.std(axis=0) + 0.01
        print(f"  generation {gen + 1:2d}: best mean return {score.max():7.3f} s, "
              f"falls {int(fell.sum()):4d} of {fell.size}")

    # Both policies on the same fresh starts.
    trials = 64
    test = make(trials)
    k_lqr = lqr_gain(test)
    _, cost_cem, fell_cem = evaluate(test, np.tile(mean, (trials, 1)), seed=12345)
    _, cost_lqr, fell_lqr = evaluate(test, np.tile(k_lqr, (trials, 1)), seed=12345)
    print()
    print(f"{'policy':8s} {'gain W (on x/scale, theta/scale, rates)':44s} {'falls':>6s} {'cost':>9s}")
    print(f"{'CEM':8s} {np.array2string(mean, precision=3):44s} {int(fell_cem.sum()):6d} "
          f"{cost_cem.mean():9.4f}")
    print(f"{'LQR':8s} {np.array2string(k_lqr, precision=3):44s} {int(fell_lqr.sum()):6d} "
          f"{cost_lqr.mean():9.4f}")
    print(f"\nthe trained policy's cost is {cost_cem.mean() / cost_lqr.mean():.3f} x the LQR's "
          f"on the same {trials} starts (integrated task cost over the 10 s episode)")
    if fell_lqr.any() or fell_cem.any():
        raise SystemExit("a policy fell from the task's starts: train longer")
    if cost_cem.mean() > 1.5 * cost_lqr.mean():
        raise SystemExit("the search stopped far from the LQR's cost: train longer")


if __name__ == "__main__":
    main()
