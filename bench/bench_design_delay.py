"""What a design for a delayed loop buys and costs: ``equilibrist robustness`` of a balancing
LQR and LQG with and without ``--design-delay``; with ``--velocity-filter``, of an LQG that
measures its rates too, with and without ``--design-velocity-filter``.

    python bench/bench_design_delay.py [--delays 0,5,10,15] [--kinds lqr,lqg] [--workers 2]
    python bench/bench_design_delay.py --velocity-filter [--cutoffs 50,20,10,5]
        [--rate-noise 1e-9,1e-7]

Runs the scorecard (RealAIGym's families, the compiled batch) on the DFKI acrobot of the v2
boards (design C.1, model 1.0; ``Ir``, damping and Coulomb friction zero, 500 Hz, 10 s),
balancing from 0.04 rad off the upright (``--x0 theta1=3.1``: from the operating point a
noiseless run has nothing to correct, and the delay family would be all successes), once per
kind and design delay (in control periods of 2 ms). Prints each family's score, the benchmark
score and the delays (of the delay family's 0-40 ms, measurement late) each design holds,
as a Markdown table.

``--velocity-filter``: the same rig and start, an LQG measuring ``theta1, theta2,
theta1_dot, theta2_dot`` (``--rn 1e-12,1e-12,R,R`` for each rate noise ``R``), its scorecard
with the filtered velocity family's cutoff (``--filter-cutoff``) at each of ``--cutoffs``,
without and with ``--design-velocity-filter`` at that cutoff; each family's score and the
filtered family's successes per noise level.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time

RIG = ["--set", "Ir=0", "b1=0", "b2=0", "cf1=0", "cf2=0"]
FAMILIES = ("model", "velocity_noise", "torque_noise", "torque_response", "delay",
            "perturbation")


def card(kind: str, delay: int, workers: int, *extra: str) -> tuple[dict, float]:
    """The scorecard's JSON for *kind* designed for *delay* periods (and the options *extra*),
    and its wall time."""
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "equilibrist.cli.main", "robustness", "dfki_double_pendulum",
         "--controller", kind, "--design-delay", str(delay), *RIG, "--x0", "theta1=3.1",
         "--workers", str(workers), *extra, "--json"],
        check=True, capture_output=True, text=True)
    return json.loads(done.stdout), time.perf_counter() - start


def filtered(cutoffs: list[float], noises: list[str], workers: int) -> None:
    """The LQG measuring its rates, without and with --design-velocity-filter, per cutoff."""
    head = ["rate noise rn", "rig filter (Hz)", "design filter", *FAMILIES, "benchmark",
            "velocity noise, filtered", "filtered: runs up of 210", "wall (s)"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for rn in noises:
        for cutoff in cutoffs:
            for designed in (False, True):
                extra = ["--outputs", "theta1,theta2,theta1_dot,theta2_dot",
                         "--rn", f"1e-12,1e-12,{rn},{rn}", "--filter-cutoff", f"{cutoff:g}"]
                if designed:
                    extra += ["--design-velocity-filter", f"{cutoff:g}"]
                got, wall = card("lqg", 0, workers, *extra)
                scores = got["scores"]
                runs = sum(sum(s) for s in got["families"]["velocity_noise_filtered"]["successes"])
                row = [rn, f"{cutoff:g}", f"{cutoff:g} Hz" if designed else "none",
                       *(f"{scores[f]:.3f}" for f in FAMILIES),
                       f"{got['benchmark_score']:.3f}",
                       f"{scores['velocity_noise_filtered']:.3f}", str(runs), f"{wall:.1f}"]
                print("| " + " | ".join(row) + " |", flush=True)


def held(family: dict) -> str:
    """The delays (ms) of the family's successful runs, as ranges."""
    ok = [round(v * 1000) for v, s in zip(family["values"], family["successes"], strict=True)
          if all(s)]
    if not ok:
        return "none"
    spans, first, last = [], ok[0], ok[0]
    for v in ok[1:]:
        if v == last + 2:
            last = v
            continue
        spans.append((first, last))
        first = last = v
    spans.append((first, last))
    return ", ".join(f"{a}-{b}" if a != b else f"{a}" for a, b in spans)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--delays", default="0,5,10,15")
    parser.add_argument("--kinds", default="lqr,lqg")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--velocity-filter", action="store_true",
                        help="the LQG measuring its rates, with and without the design filter")
    parser.add_argument("--cutoffs", default="50,20,10,5")
    parser.add_argument("--rate-noise", default="1e-9,1e-7")
    args = parser.parse_args()
    if args.velocity_filter:
        filtered([float(c) for c in args.cutoffs.split(",")], args.rate_noise.split(","),
                 args.workers)
        return
    head = ["kind", "design delay", *FAMILIES, "benchmark", "delays held (ms)",
            "velocity noise, filtered", "wall (s)"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for kind in args.kinds.split(","):
        for delay in (int(d) for d in args.delays.split(",")):
            got, wall = card(kind, delay, args.workers)
            scores = got["scores"]
            row = [kind, f"{delay} ({2 * delay} ms)",
                   *(f"{scores[f]:.3f}" for f in FAMILIES), f"{got['benchmark_score']:.3f}",
                   held(got["families"]["delay"]), f"{scores['velocity_noise_filtered']:.3f}",
                   f"{wall:.1f}"]
            print("| " + " | ".join(row) + " |", flush=True)


if __name__ == "__main__":
    main()
