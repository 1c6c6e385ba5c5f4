"""RealAIGym's robustness families of one controller: equilibrist's scorecard against the
benchmark's own code.

    python bench/bench_robustness.py [--plan PLAN.npz] [--workers 2] [--harness FILE.jsonl ...]

Runs ``equilibrist robustness`` (the compiled batch, ``--workers`` threads) on the DFKI
acrobot of RealAIGym's v2 boards (design C.1, model 1.0; ``Ir``, damping and Coulomb friction
zero, 6 N*m) under the TVLQR that tracks a swing-up plan (``equilibrist trajopt`` of that
plant, made here when ``--plan`` is not given) and prints the time and each family's score.

With ``--harness``, it reads what the benchmark's own code gave for the same controller
(lines of JSON ``{"family", "index", "value", "successes"}``, one per value the benchmark ran:
its benchmarker's ``check_*_robustness`` called value by value on an ``equilibrist.policy``
of the same plan in the benchmark's controller interface) and compares, family by family,
the scores over the values both ran and the share of values whose outcome agrees (for a
noise level: whether more than half its runs succeed).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

RIG = ["--set", "Ir=0", "b1=0", "b2=0", "cf1=0", "cf2=0"]
#: The benchmark's family names for ours.
NAMES = {"model": "model", "velocity_noise": "noise", "torque_noise": "unoise",
         "torque_response": "response", "delay": "delay", "perturbation": "perturbation"}
REPEATED = {"noise", "unoise"}


def _cli(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "equilibrist.cli.main", *argv], check=True,
                          capture_output=True, text=True)


def ours(plan: Path, workers: int) -> tuple[dict, float]:
    """The scorecard's JSON and the command's wall time."""
    start = time.perf_counter()
    done = _cli("robustness", "dfki_double_pendulum", "--controller", "tvlqr", "--trajectory",
                str(plan), *RIG, "--workers", str(workers), "--json")
    return json.loads(done.stdout), time.perf_counter() - start


def harness(paths: list[Path]) -> dict[str, dict]:
    """family -> {index (or (key, index)): successes}"""
    out: dict[str, dict] = defaultdict(dict)
    for path in paths:
        for line in path.read_text().splitlines():
            rec = json.loads(line)
            if rec.get("done"):
                continue
            key = (rec["key"], rec["index"]) if rec["family"] == "model" else rec["index"]
            out[rec["family"]][key] = rec["successes"]
    return out


def compare(card: dict, theirs: dict[str, dict]) -> list[tuple]:
    rows = []
    fams = card["families"]
    for name, short in NAMES.items():
        got = theirs.get(short, {})
        if not got:
            continue
        fam = fams[name]
        if name == "model":
            mine = {(k, i): [v] for k, vals in fam["parameters"].items()
                    for i, v in enumerate(vals)}
        elif name == "perturbation":
            # Independent random draws on both sides: the scores over as many runs.
            n = len(got)
            ours_s = float(np.mean([s[0] for s in fam["successes"][:n]]))
            theirs_s = float(np.mean([s[0] for s in got.values()]))
            rows.append((name, n, ours_s, theirs_s, None))
            continue
        else:
            mine = dict(enumerate(fam["successes"]))
        keys = [k for k in got if k in mine]

        def outcome(s: list[bool], short: str = short) -> bool:
            return bool(np.mean(s) > 0.5) if short in REPEATED else bool(s[0])

        a = [outcome(mine[k]) for k in keys]
        b = [outcome(got[k]) for k in keys]
        agree = float(np.mean([x == y for x, y in zip(a, b, strict=True)]))
        rows.append((name, len(keys), float(np.mean(a)), float(np.mean(b)), agree))
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plan", type=Path)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--harness", type=Path, nargs="*", default=[])
    args = ap.parse_args()
    plan = args.plan
    if plan is None:
        plan = Path(tempfile.mkdtemp()) / "plan.npz"
        _cli("trajopt", "dfki_double_pendulum", *RIG, "--out", str(plan))
    _cli("robustness", "dfki_double_pendulum", "--controller", "tvlqr", "--trajectory",
         str(plan), *RIG, "--families", "torque_response", "--duration", "0.1")  # compiled
    card, wall = ours(plan, args.workers)
    runs = sum(len(s) for f in card["families"].values() for s in f["successes"])
    print(f"equilibrist robustness: {runs} runs of {card['settings']['duration']:g} s in "
          f"{wall:.1f} s of wall time on {args.workers} threads (the families alone: "
          f"{card['elapsed_s']:.1f} s); benchmark score {card['benchmark_score']:.3f}")
    for name, score in card["scores"].items():
        print(f"  {name:<24} {score:.3f}")
    if args.harness:
        print("\nagainst the benchmark's own code (the values both ran):")
        print(f"  {'family':<16} {'values':>6} {'ours':>6} {'theirs':>7} {'diff':>6} {'agree':>6}")
        for name, n, a, b, agree in compare(card, harness(args.harness)):
            agreed = "" if agree is None else f"{agree:6.2f}"
            print(f"  {name:<16} {n:>6} {a:6.3f} {b:7.3f} {a - b:+6.3f} {agreed}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
