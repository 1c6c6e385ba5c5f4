"""The certified region of attraction against what sampling cannot falsify, and its speed.

    .venv/bin/python bench/bench_roa.py [--runs 100000] [--boxes 1000000]

For the cart-pole's LQR at 200 Hz (and the reaction-wheel and rotary
pendulums' for comparison):

1. the certificate (``equilibrist.control.certify``, interval
   branch-and-bound on the exact equations with the input's saturation,
   continuous-time feedback): its level ``rho``, the boxes and the seconds;
2. the largest level that sampling cannot falsify: levels between the
   certified one and the fall region's, bisected, each tried with 2,000 starts
   on its surface in the sampled, saturated loop (3 s per run, caught = ended
   balanced); the goal is the certified level within a factor 2 of it;
3. ``--runs`` starts drawn inside the certified level (half on its surface)
   through the compiled batch: the goal is 0 counterexamples in 10^5;
4. the time of those rollouts (3 s at 200 Hz, one RK4 step per sample and at
   simulate's default 1 ms step), against the goal of 10^5 in under 10 s of
   wall time on 2 cores.

Drake's ``RegionOfAttraction`` is not compared here: it needs a polynomial
plant (a Taylor model of the cart-pole's trigonometry), and its level would
be of that model, not of these equations.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from equilibrist import get_system
from equilibrist.control.certify import certify
from equilibrist.control.design import design
from equilibrist.control.linear import LinearController
from equilibrist.sim.roa import outcomes, sample_level


def _falls(system: object, ctrl: object, S: np.ndarray, x_op: np.ndarray, level: float,
           opts: dict[str, object], seed: int) -> int:
    """How many of 2,000 starts on the surface of *level* the sampled loop loses."""
    starts = sample_level(S, x_op, level, 4000, seed=seed)[:2000]  # the surface half
    return int((~outcomes(system, ctrl, starts, opts, seed)).sum())  # type: ignore[arg-type]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=100_000)
    ap.add_argument("--boxes", type=int, default=1_000_000)
    ap.add_argument("--systems", default="cartpole,reaction_wheel_pendulum,furuta")
    args = ap.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")
    for key in args.systems.split(","):
        system = get_system(key)
        rate = float(system.spec.control_rate)
        d = design(system, rate=rate)
        ctrl = LinearController.from_design(d, kind="lqr")
        eq = system.operating_point()
        x_op, u_op, S = np.asarray(eq.x, float), np.asarray(eq.u, float), np.asarray(d.S, float)
        cert = certify(system, d.K, S, x_op=x_op, u_op=u_op, max_boxes=args.boxes)
        print(f"\n{key} (LQR at {rate:g} Hz): certified rho {cert.rho:.4g} "
              f"(limited by {cert.limited_by}; {cert.boxes} boxes, {cert.seconds:.1f} s; "
              f"the fall region allows {cert.rho_region:.4g})")
        opts = {"duration": 3.0, "rate": rate, "noise": None, "physics_step": 1.0 / rate}

        lo, hi = cert.rho, cert.rho_region
        if _falls(system, ctrl, S, x_op, hi, opts, 1) == 0:
            lo = hi
        else:
            for i in range(12):
                mid = float(np.sqrt(lo * hi))
                ok = _falls(system, ctrl, S, x_op, mid, opts, 2 + i) == 0
                lo, hi = (mid, hi) if ok else (lo, mid)
        print(f"  largest level no sampled start falsifies: {lo:.4g} (2,000 surface starts per "
              f"level); certified / sampled = {cert.rho / lo:.3f} (goal >= 0.5)")
        if key != "cartpole":
            continue
        starts = sample_level(S, x_op, cert.rho, args.runs, seed=11)
        for step, label in ((1.0 / rate, "one RK4 step per sample"), (None, "RK4 at 1 ms")):
            o = dict(opts, physics_step=step) if step else {k: v for k, v in opts.items()
                                                          if k != "physics_step"}
            t0 = time.perf_counter()
            caught = outcomes(system, ctrl, starts, o, 5)
            wall = time.perf_counter() - t0
            print(f"  {args.runs} runs inside the certified level, 3 s at {rate:g} Hz ({label}): "
                  f"{int((~caught).sum())} counterexamples, {wall:.1f} s wall "
                  f"(goal: 0, and 10^5 runs in < 10 s)")


if __name__ == "__main__":
    main()
