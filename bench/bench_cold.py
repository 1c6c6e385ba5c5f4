"""Cold and warm starts: what a new user waits for, in CPU seconds of the whole process.

Each row runs a fresh process (``sys.executable``) with empty caches (a new
``EQUILIBRIST_CACHE`` folder; nothing derived, nothing compiled), then the
same command again with the cache it left (warm). CPU seconds are the
child's user + system time (``resource.getrusage(RUSAGE_CHILDREN)``), wall
seconds its elapsed time. Gymnasium's own ``CartPole-v1`` (make, reset, one
step) is measured in the same run as the peer of a first environment.

Goals (issue "One core, compiled in seconds"): cold ``simulate cartpole``
(LQG) <= 2 s CPU, ``--controller swingup`` <= 3 s, ``--controller mpc`` <= 3 s,
an imported MJCF model's first ``simulate`` <= 3 s, a first environment
(make + reset + step) <= 2 s; warm ``simulate cartpole --duration 2 --json``
<= 0.5 s wall; ``equilibrist demo`` of the whole catalogue from empty caches
<= 90 s wall on 2 cores (``--demo``, a few minutes).

Run: ``.venv/bin/python bench/bench_cold.py [--demo] [--json FILE]``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CLI = [sys.executable, "-m", "equilibrist.cli.main"]
MJCF = ROOT / "examples" / "furuta.xml"

ENV_CHILD = """
import gymnasium as gym
{imports}
env = gym.make({env_id!r})
env.reset(seed=0)
env.step(env.action_space.sample())
"""

CASES = [
    ("simulate cartpole (LQG)", [*CLI, "simulate", "cartpole", "--duration", "2", "--json"], 2.0),
    ("simulate cartpole --controller lqr",
     [*CLI, "simulate", "cartpole", "--controller", "lqr", "--duration", "2", "--json"], None),
    ("simulate cartpole --controller swingup",
     [*CLI, "simulate", "cartpole", "--controller", "swingup", "--x0", "theta=3.14", "--json"],
     3.0),
    ("simulate cartpole --controller mpc",
     [*CLI, "simulate", "cartpole", "--controller", "mpc", "--duration", "2", "--json"], 3.0),
    ("simulate examples/furuta.xml (MJCF)",
     [*CLI, "simulate", str(MJCF), "--duration", "2", "--json"], 3.0),
    ("gymnasium.make equilibrist/cartpole-balance-v0 + reset + step",
     [sys.executable, "-c", ENV_CHILD.format(imports="import equilibrist.envs",
                                              env_id="equilibrist/cartpole-balance-v0")], 2.0),
    ("gymnasium.make CartPole-v1 + reset + step (peer)",
     [sys.executable, "-c", ENV_CHILD.format(imports="", env_id="CartPole-v1")], None),
]


def measure(cmd: list[str], cache: str) -> tuple[float, float, int]:
    """CPU and wall seconds of one child process, and its exit status."""
    env = {**os.environ, "EQUILIBRIST_CACHE": cache}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        print(f"  failed ({proc.returncode}): {proc.stderr.strip()[-300:]}", file=sys.stderr)
    return cpu, wall, proc.returncode


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--demo", action="store_true", help="also the whole catalogue's demo (minutes)")
    ap.add_argument("--json", help="write the figures here too")
    args = ap.parse_args()
    rows = []
    print(f"{'command':64s} {'cold CPU':>9s} {'cold wall':>9s} {'warm CPU':>9s} {'warm wall':>9s}  goal")
    for label, cmd, goal in CASES:
        with tempfile.TemporaryDirectory() as cache:
            os.chmod(cache, 0o700)
            cold = measure(cmd, cache)
            warm = measure(cmd, cache)
        met = "" if goal is None else ("met" if cold[0] <= goal else "NOT met") + f" (<= {goal:g} s CPU)"
        print(f"{label:64s} {cold[0]:9.2f} {cold[1]:9.2f} {warm[0]:9.2f} {warm[1]:9.2f}  {met}")
        rows.append({"case": label, "cold_cpu": cold[0], "cold_wall": cold[1], "warm_cpu": warm[0],
                     "warm_wall": warm[1], "goal_cpu": goal, "status": cold[2]})
    if args.demo:
        with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as out:
            os.chmod(cache, 0o700)
            cpu, wall, status = measure([*CLI, "demo", "--out", out], cache)
        print(f"{'demo (whole catalogue, empty caches)':64s} {cpu:9.2f} {wall:9.2f} "
              f"{'':9s} {'':9s}  {'met' if wall <= 90 else 'NOT met'} (<= 90 s wall)")
        rows.append({"case": "demo", "cold_cpu": cpu, "cold_wall": wall, "status": status})
    load = os.getloadavg()[0]
    print(f"load average during the run: {load:.2f} (2 cores)")
    if args.json:
        Path(args.json).write_text(json.dumps({"rows": rows, "load": load}, indent=1))


if __name__ == "__main__":
    main()
