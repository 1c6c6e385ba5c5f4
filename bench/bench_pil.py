"""Processor in the loop: every kind on the Cortex-M4F, the cart-pole's LQG and swing-up on
the Uno, and the wall time of a warm ``equilibrist pil``.

    .venv/bin/python bench/bench_pil.py [--duration 2] [--steps 1000]

1. Every controller kind of the cart-pole (LQR, LQG, swing-up, MPC, the time-varying LQR
   tracking a planned swing-up) in lockstep on ``cortex-m4f``, in float32 where its export
   has it (LQR, LQG, MPC: the FPU's arithmetic) and in double otherwise: instructions per
   step and the largest difference from ``simulate``'s commands, beside the command's peak.
2. The cart-pole's LQG at 200 Hz and its swing-up on the ``uno``: cycles, flash, RAM, stack.
3. ``equilibrist pil cartpole --controller lqg --target T --duration D`` with D giving
   ``--steps`` lockstep steps, from a warm cache (run once before): the command's wall time
   (design, the firmware from the cache, the emulator's start, the lockstep, simulate beside
   it). Goal: under 10 s on 2 cores.

Every figure comes from ``pil --json``; nothing here is timed by the test suite.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CLI = [sys.executable, "-c", "import sys; from equilibrist.cli.main import main; sys.exit(main())"]


def pil(*args: str) -> dict[str, object]:
    done = subprocess.run([*CLI, "pil", "cartpole", *args, "--json"], capture_output=True,
                          text=True, check=False)
    if done.returncode not in (0, 1):
        raise SystemExit(f"pil {' '.join(args)}: {done.stderr.strip()}")
    figures: dict[str, object] = json.loads(done.stdout)
    return figures


def plan(folder: Path) -> str:
    """The planned swing-up the time-varying LQR tracks (as the tests' fixture plans it)."""
    from equilibrist.control.trajopt import plan as optimize
    from equilibrist.numeric.lookup import get_system
    from equilibrist.tasks import get_task

    cart = get_system("cartpole")
    task = get_task(cart, "swingup")
    traj = optimize(cart, start=task.start, goal=task.x_op, knots=60, duration=4.0,
                    bounds={"x": (-0.9, 0.9)})
    return str(traj.save(folder / "up.npz"))


def row(kind: str, f: dict[str, object]) -> str:
    cycles = f["cycles_per_step"]
    assert isinstance(cycles, dict)
    peak = f.get("peak_command") or {}
    top = max(abs(float(v)) for v in peak.values()) if isinstance(peak, dict) and peak else 0.0
    dev = f["max_deviation"]
    rel = f"{float(dev) / top:.1e}" if isinstance(dev, float) and top else "-"
    return (f"| {kind} | {f['precision']} | {cycles['median']:,.0f} | {cycles['max']:,} | "
            f"{f['max_rate']:,.0f} | {dev:.2e} | {rel} | {f['flash_bytes']:,} | "
            f"{f['ram_bytes']:,} | {f['stack_bytes']:,} | {'yes' if f['fits'] else 'no'} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", default="2", help="seconds of each kind's lockstep")
    parser.add_argument("--steps", type=int, default=1000, help="steps of the timed run")
    args = parser.parse_args()
    head = ("| kind | precision | median | max | max rate [Hz] | max deviation | relative | "
            "flash | RAM | stack | fits |\n|---|---|---|---|---|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        trajectory = plan(Path(tmp))
        print(f"## cortex-m4f, {args.duration} s of lockstep from theta = 0.1 (the swing-up and "
              "the time-varying LQR from hanging)\n\n" + head)
        for kind, extra in (("lqr", ["--precision", "float", "--x0", "theta=0.1"]),
                            ("lqg", ["--precision", "float", "--x0", "theta=0.1"]),
                            ("mpc", ["--precision", "float", "--x0", "theta=0.1"]),
                            ("lqg", ["--x0", "theta=0.1"]),
                            ("swingup", []),
                            ("tvlqr", ["--trajectory", trajectory])):
            f = pil("--controller", kind, "--target", "cortex-m4f", "--duration", args.duration,
                    *extra)
            print(row(kind, f), flush=True)
    print("\n## uno (double is float32 there)\n\n" + head)
    for kind, extra in (("lqg", ["--x0", "theta=0.1"]), ("swingup", [])):
        f = pil("--controller", kind, "--target", "uno", "--duration", args.duration, *extra)
        print(row(kind, f), flush=True)
        print(f"|  | {f['report']} | | | | | | | | | |", flush=True)
    mpc = subprocess.run([*CLI, "pil", "cartpole", "--controller", "mpc", "--target", "uno"],
                         capture_output=True, text=True, check=False)
    print(f"\nMPC on the uno: exit {mpc.returncode}: {mpc.stderr.strip()}")
    print(f"\n## warm cache: {args.steps} lockstep steps of the LQG at 200 Hz\n")
    print("| target | wall [s] | steps | load average before |\n|---|---|---|---|")
    duration = f"{(args.steps - 1) / 200:g}"
    for target in ("uno", "cortex-m4f"):
        pil("--controller", "lqg", "--target", target, "--duration", "0.05")  # warm the cache
        load = os.getloadavg()[0]
        t0 = time.perf_counter()
        f = pil("--controller", "lqg", "--target", target, "--duration", duration,
                "--x0", "theta=0.1")
        wall = time.perf_counter() - t0
        print(f"| {target} | {wall:.2f} | {f['steps']} | {load:.1f} |", flush=True)


if __name__ == "__main__":
    main()
