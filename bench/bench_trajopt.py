"""Trajectory optimization: the acrobot's swing-up from 20 seeded random guesses, and the cart-pole's plan time.

    .venv/bin/python bench/bench_trajopt.py

Two acrobots: SYSTEMS.md's parameters with |tau| <= 20 N*m, and the
Underactuated Robotics notebook's (Drake's AcrobotParams: m1 = m2 = 1 kg,
l1 = 1 m, l2 = 2 m, lc1 = 0.5 m, lc2 = 1 m, I1 = 0.083, I2 = 0.33 kg*m^2,
b1 = b2 = 0.1, g = 9.81) with |tau| <= 8 N*m, at the notebook's
transcription size (21 knots, N = 20 intervals; Drake's DirectCollocation is
the same Hermite-Simpson form) and at N = 60; in a fixed 6 s (the notebook
frees the time between its knots' bounds). The number converged and the
median CPU time of a solve. Drake itself is not
installed here; its figures (11/20, median 0.32 s, failing from the
straight guess) come from the issue that asked for this and are not
re-measured.
"""

from __future__ import annotations

import os
import statistics
import time

from equilibrist import get_system
from equilibrist.control.trajopt import plan
from equilibrist.tasks import get_task

DRAKE = {"m1": 1.0, "m2": 1.0, "l1": 1.0, "l2": 2.0, "lc1": 0.5, "lc2": 1.0, "I1": 0.083,
         "I2": 0.33, "b1": 0.1, "b2": 0.1, "g": 9.81, "tau_min": -8.0, "tau_max": 8.0}


def acrobot(label: str, params: dict[str, float], knots: int, duration: float) -> None:
    system = get_system("acrobot", **params)
    task = get_task(system, "swingup")
    ok, times, iters = 0, [], []
    for seed in range(20):
        traj = plan(system, start=task.start, goal=task.x_op, knots=knots, duration=duration,
                    guess="random", seed=seed)
        ok += traj.converged
        times.append(traj.solve_time)
        iters.append(traj.iterations)
    straight = plan(system, start=task.start, goal=task.x_op, knots=knots, duration=duration)
    print(f"acrobot ({label}), N = {knots}, {duration:g} s: converged from {ok}/20 random guesses "
          f"(goal 20/20); median solve {statistics.median(times):.3f} s CPU, worst "
          f"{max(times):.3f} s; median {statistics.median(iters):.0f} iterations; straight guess: "
          f"{'converged' if straight.converged else 'not converged'} in {straight.solve_time:.3f} s")


def main() -> None:
    print(f"load average of the machine: {os.getloadavg()[0]:.1f} (2 cores)")
    acrobot("SYSTEMS.md, |tau| <= 20", {}, 60, 4.0)
    acrobot("Drake's parameters, |tau| <= 8", DRAKE, 20, 6.0)
    acrobot("Drake's parameters, |tau| <= 8", DRAKE, 60, 6.0)
    cart = get_system("cartpole")
    task = get_task(cart, "swingup")
    plan(cart, start=task.start, goal=task.x_op, knots=60, duration=4.0, bounds=dict(task.region))
    t0 = time.process_time()
    traj = plan(cart, start=task.start, goal=task.x_op, knots=60, duration=4.0,
                bounds=dict(task.region))
    whole = time.process_time() - t0
    print(f"cart-pole swing-up on its track, warm: {whole:.3f} s CPU for the whole plan "
          f"(goal < 2 s), of which IPOPT {traj.solve_time:.3f} s")
    print(f"load average of the machine after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
