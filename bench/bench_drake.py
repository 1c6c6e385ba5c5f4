"""The acrobot's swing-up planned by equilibrist and by Drake, side by side in one run.

    bash bench/peers_drake.sh                 # Drake in its own environment, once
    .venv/bin/python bench/bench_drake.py [--drake bench/_peers/drake/bin/python]

Drake: the Underactuated Robotics notebook's problem (``AcrobotPlant``,
``DirectCollocation`` with 21 knots, steps of 0.05 to 0.2 s, |tau| <= 8 N*m,
cost 10 u^2 + the duration), solved by SNOPT (Drake's wheel brings it),
from the notebook's straight-line guess and from 20 seeded random guesses
(angles uniform in [-pi, pi], rates in [-5, 5] rad/s at the knots).
equilibrist: the same acrobot (Drake's parameters), the same transcription
size (Hermite-Simpson, 20 intervals), |tau| <= 8 N*m, least effort in a
fixed 6 s and with a free duration up to 4 s, from its straight guess and 20
seeded random guesses, solved by IPOPT. The two solvers alternate, seed by
seed, so a busy machine slows both alike. CPU seconds of the solve only.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

from equilibrist import get_system
from equilibrist.control.trajopt import plan
from equilibrist.tasks import get_task

HERE = Path(__file__).resolve().parent
DRAKE = {"m1": 1.0, "m2": 1.0, "l1": 1.0, "l2": 2.0, "lc1": 0.5, "lc2": 1.0, "I1": 0.083,
         "I2": 0.33, "b1": 0.1, "b2": 0.1, "g": 9.81, "tau_min": -8.0, "tau_max": 8.0}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drake", default=str(HERE / "_peers" / "drake" / "bin" / "python"),
                    help="a Python with pydrake (bench/peers_drake.sh makes one)")
    ap.add_argument("--seeds", type=int, default=20)
    args = ap.parse_args()
    if not Path(args.drake).exists():
        print(f"no Drake at {args.drake}: run bash bench/peers_drake.sh first", file=sys.stderr)
        return 2
    peer = subprocess.Popen([args.drake, str(HERE / "_drake_acrobot.py")], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)

    def drake(word: str) -> dict[str, object]:
        assert peer.stdin is not None and peer.stdout is not None
        peer.stdin.write(word + "\n")
        peer.stdin.flush()
        return json.loads(peer.stdout.readline())

    system = get_system("acrobot", **DRAKE)
    task = get_task(system, "swingup")
    forms: dict[str, dict[str, float]] = {"fixed 6 s": {"duration": 6.0},
                                          "free, up to 4 s": {"duration_max": 4.0}}
    drake("straight")  # the first solve loads Drake's libraries: not counted
    for kw in forms.values():  # each form's problem is built once, as Drake's program is
        plan(system, start=task.start, goal=task.x_op, knots=20, **kw)
    print(f"load average of the machine: {os.getloadavg()[0]:.1f} (2 cores)")
    results: dict[str, list[tuple[bool, float]]] = {"drake": [], **{k: [] for k in forms}}
    straight = {"drake": drake("straight")}
    for name, kw in forms.items():
        t = plan(system, start=task.start, goal=task.x_op, knots=20, **kw)
        straight[name] = {"converged": t.converged, "cpu": t.solve_time}
    for seed in range(args.seeds):
        d = drake(str(seed))
        results["drake"].append((bool(d["converged"]), float(d["cpu"])))  # type: ignore[arg-type]
        for name, kw in forms.items():
            t = plan(system, start=task.start, goal=task.x_op, knots=20, guess="random",
                     seed=seed, **kw)
            results[name].append((t.converged, t.solve_time))
    peer.stdin.close()  # type: ignore[union-attr]
    peer.wait(timeout=30)
    for name, runs in results.items():
        ok = [c for c, _ in runs if c]
        times = [t for _, t in runs]
        who = "Drake (SNOPT)" if name == "drake" else f"equilibrist (IPOPT), {name}"
        s = straight[name]
        good = [t for c, t in runs if c]
        print(f"{who:<38} random guesses converged {len(ok):>2}/{len(runs)}, median solve "
              f"{statistics.median(times):.3f} s CPU (worst {max(times):.3f} s; median of the "
              f"converged {statistics.median(good) if good else float('nan'):.3f} s); straight "
              f"guess: {'converged' if s['converged'] else 'not converged'} in "
              f"{float(s['cpu']):.3f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
