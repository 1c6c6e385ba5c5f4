"""Identification speed: the compiled shooting integrator against solve_ivp in the same loop.

Workload (issue 14): the cart-pole, three free parameters (m_p, b_c, b_p),
a 20 s closed-loop log at 200 Hz (4,001 samples) recorded by the simulator
(LQG designed on the default parameters, the plant at m_p = 1.3, b_c = 0.8,
b_p = 0.02, process and sensor noise, a PRBS of 20 N switching every 0.2 s
on the command).

The same least-squares loops (multiple shooting for the start, then the
prediction errors of the model's Kalman filter; scipy ``least_squares``,
central-difference Jacobians) run with the two integrators of the segments
and of the filter's predictions:

* ``compiled``: RK4 at 1 ms with the logged input held, compiled (the C core) over
  the system's generated ``f`` (``equilibrist.ident.kernel``);
* ``solve_ivp``: ``scipy.integrate.solve_ivp`` (RK45, rtol 1e-8, atol 1e-10)
  over each sample interval (the held input jumps at every sample), on the
  same generated ``f`` in plain Python.

Both run the fit with fixed noise levels and the same cap on least-squares
evaluations in each stage, so they do the same iterations; the estimates are
compared to show it is the same work. The compiled integrator's complete fit
(noise re-estimation, statistics) is timed too. The first (compiling) call is
not timed.

Usage: ``python bench/bench_identify.py [--evaluations N] [--json]``.
Goal (issue 14): the compiled loop >= 20x faster than solve_ivp's.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from equilibrist import get_system
from equilibrist.control.design import design
from equilibrist.ident import Log, identify
from equilibrist.sim.controllers import LQG
from equilibrist.sim.noise import Noise
from equilibrist.sim.run import simulate
from equilibrist.sim.signals import PRBS

TRUTH = {"m_p": 1.3, "b_c": 0.8, "b_p": 0.02}
FREE = list(TRUTH)


def record() -> Log:
    nominal = get_system("cartpole")
    d = design(nominal, rate=200.0)
    run = simulate(nominal.with_params(**TRUTH), LQG.from_design(d), duration=20.0,
                   noise=Noise.from_design(d), seed=0, excitation=PRBS(20.0, 0.2, seed=0))
    assert not run.fell
    return Log.from_arrays(nominal, run.time, run.applied,
                           {o: run.measurement(o) for o in run.output_names})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--evaluations", type=int, default=3,
                        help="least-squares evaluations of each stage of the timed loop (default 3)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    cart = get_system("cartpole")
    log = record()
    short = Log.from_arrays(cart, log.time[:200], log.inputs[:200],
                            {o: log.output(o)[:200] for o in log.output_names})
    identify(cart, short, FREE)  # compiles (or loads) the integrator

    t0 = time.perf_counter()
    full = identify(cart, log, FREE)
    t_full = time.perf_counter() - t0

    loop: dict[str, tuple[float, np.ndarray]] = {}
    for backend in ("compiled", "solve_ivp"):
        t0 = time.perf_counter()
        r = identify(cart, log, FREE, backend=backend, reestimate_noise=False,
                     max_nfev=args.evaluations)
        loop[backend] = (time.perf_counter() - t0,
                         np.array([r.estimate(n).value for n in FREE]))
    t_c, est_c = loop["compiled"]
    t_s, est_s = loop["solve_ivp"]
    ratio = t_s / t_c
    out = {
        "workload": "cartpole, free m_p b_c b_p, 20 s log at 200 Hz (4001 samples), "
                    f"{full.method['segments']} shooting segments",
        "full_fit_compiled_s": t_full,
        "full_fit_evaluations": full.method["evaluations"],
        "estimates": {e.name: [e.value, e.std_error] for e in full.estimates},
        "truth": TRUTH,
        "loop_evaluations": args.evaluations,
        "loop_compiled_s": t_c,
        "loop_solve_ivp_s": t_s,
        "speedup": ratio,
        "max_estimate_difference": float(np.max(np.abs(est_c - est_s))),
    }
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"workload: {out['workload']}")
    print(f"  full fit, compiled RK4     {t_full:8.2f} s  ({full.method['evaluations']} "
          "evaluations, noise re-estimated, statistics)")
    for e in full.estimates:
        print(f"    {e.name:4} = {e.value:.5g} +- {e.std_error:.2g}   (truth {TRUTH[e.name]:g})")
    print(f"  same loops, {args.evaluations} evaluations per stage:")
    print(f"    compiled RK4 (C core)    {t_c:8.2f} s")
    print(f"    scipy solve_ivp (RK45)   {t_s:8.2f} s   compiled is {ratio:.0f}x faster (goal >= 20)")
    print(f"  same work: |estimates compiled - solve_ivp| = {out['max_estimate_difference']:.2e}")


if __name__ == "__main__":
    main()
