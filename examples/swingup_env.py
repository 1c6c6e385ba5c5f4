"""Solve the cart-pole's swing-up environment with equilibrist's own swing-up controller.

The controller kind ``swingup`` (energy pumping, then the LQR catching the
pole near upright: :mod:`equilibrist.control.swingup`), made the
environment's expert by :func:`equilibrist.envs.expert.expert` (any kind of
the registry can be: ``lqg`` for the balance task, a kind of one's own),
sees only what an agent sees,
the environment's observations (the cart's position and the pole's angle,
with the rig's sensor noise), and acts through ``step`` in the input's own
units. The episode's return is the swing-up reward documented in
:mod:`equilibrist.envs`: 0 per second hanging still, 1 balanced upright.
"""

from __future__ import annotations

import math

import gymnasium as gym

import equilibrist.envs  # noqa: F401  (registers the environments)
from equilibrist.control.swingup_law import MODE_BALANCE, Z
from equilibrist.envs.expert import expert

ENV_ID = "equilibrist/cartpole-swingup-v0"


def main() -> None:
    env = gym.make(ENV_ID)
    core = env.unwrapped.core  # type: ignore[attr-defined]
    policy = expert(env, "swingup")  # refused if it read other signals than the env observes
    print(f"{ENV_ID}: {core.rate:g} Hz, {core.task.duration:g} s, observing "
          f"{', '.join(core.observation_names)} with sensor noise")
    for seed in range(3):
        obs, info = env.reset(seed=seed)
        policy.reset()
        total, caught_at, k = 0.0, None, 0
        terminated = truncated = False
        while not (terminated or truncated):
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            total += float(reward)
            if caught_at is None and policy.runtime.z[Z["mode"]] == MODE_BALANCE:
                caught_at = k / core.rate
            k += 1
        x = env.unwrapped.state  # type: ignore[attr-defined]
        theta = x[core.system.state_index("theta")]
        print(f"  seed {seed}: start theta {info['state'][1]:.3f} rad, caught at "
              f"{'never' if caught_at is None else f'{caught_at:.2f} s'}, final theta "
              f"{theta:+.4f} rad, x {x[0]:+.3f} m, return {total:.2f} of {core.task.duration:g}"
              f"{'  (left the track)' if terminated else ''}")
        if terminated or caught_at is None or abs(math.remainder(theta, 2 * math.pi)) > 0.05:
            raise SystemExit("the swing-up did not end balanced")
    env.close()


if __name__ == "__main__":
    main()
