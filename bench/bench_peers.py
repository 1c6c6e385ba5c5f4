"""Peers, side by side in one run: the MPC against DAQP, the environments against Gymnasium,
gymnax and EnvPool.

    bash bench/peers_envs.sh                  # the environment peers, once (bench/_peers/envs)
    .venv/bin/python bench/bench_peers.py [--peers bench/_peers/envs/bin/python] [--json]

1. The MPC (bench/_peers_mpc.py has the problem and the harnesses): the
   cart-pole at 200 Hz, horizon 30, |F| <= 20 N, on 300 closed-loop states
   after a push. equilibrist's ``MPCRuntime.solve`` (one Python call) against
   DAQP's Python ``Model`` on the textbook condensed QP of the same problem
   (in this process: DAQP is equilibrist's own solver, the ``mpc`` extra), and
   equilibrist's exported C against DAQP's C sources, both compiled with
   ``gcc -O2`` and timed in a C loop. Per call: the median (over all states and
   over the states where the input limit is active within the horizon), the
   99th percentile, the worst, and the worst of the calls during which the
   process was not preempted. Goals: the exported C's median and p99 within
   1.5x of DAQP's C and its worst within 2x of DAQP's worst; the Python call's
   median within 1.5x of DAQP's Python call.
2. The environments: steps per second of the cart-pole at 0.02 s per step with
   N = 16, 256 and 4096 copies: equilibrist's vector environment as it
   chooses its threads, kept on one thread (twice: two copies of the same
   environment, whose ratio shows the noise of the run) and kept on all, against
   Gymnasium's vector CartPole, gymnax on the CPU (``jit`` of ``vmap(step)``,
   and ``lax.scan`` of it) and EnvPool (in the peers' environment, through
   bench/_peers_envs.py), each contender timed in turn, repeated; the median
   of the repeats. And the first step's latency of each (its make and reset
   apart). Goals: the thread choice loses at most 10 % to one thread; at 4096
   copies the step on all threads wins where the machine has the cores. Beside
   the speeds, each contender's env-steps per CPU second (every thread of its
   process) and its CPU seconds per wall second while it stepped: on a machine
   shared with other programs, how much of the cores each got, apart from
   what its step costs.

The machine's load average is printed before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _busy import busy  # noqa: E402

ENV_ID = "equilibrist/cartpole-balance-v0"
OPTIONS = {"rate": 50.0, "physics_step": 0.02, "noise": False}
SIZES = (16, 256, 4096)
PEERS = ("gymnasium", "gymnax", "gymnax_scan", "envpool")
OURS = ("auto", "one", "one_b", "all")
NAMES = {"auto": "equilibrist (its choice)", "one": "equilibrist, 1 thread",
         "one_b": "  the same, another copy", "all": "equilibrist, all threads", "gymnasium": "Gymnasium vector CartPole",
         "gymnax": "gymnax jit(vmap(step))", "gymnax_scan": "gymnax lax.scan",
         "envpool": "EnvPool"}


def load() -> str:
    return "/".join(f"{v:.1f}" for v in os.getloadavg())


# -- 1. the MPC ------------------------------------------------------------------------------
def mpc_table(passes: int, c_passes: int) -> dict[str, Any]:
    import _peers_mpc as pm

    from equilibrist.native.shared_library import compiler

    p = pm.problem()
    exes = pm.build_c(p, compiler())
    py = pm.python_passes(p, passes)
    c = pm.c_passes(exes, c_passes)
    active = py["ours"]["it"] > 0
    ref = py["daqp"]["u"]
    rows = {}
    for label, rec in (("py ours", py["ours"]), ("py daqp", py["daqp"]), ("py soft", py["soft"]),
                       ("c ours", c["ours"]), ("c daqp", c["daqp"]), ("c soft", c["soft"])):
        rows[label] = {**pm.stats(rec, active), "du": float(np.max(np.abs(rec["u"] - ref)))}
    its = {k: {"median_active": float(np.median(py[k]["it"][active])), "worst": int(py[k]["it"].max())}
           for k in py}
    return {"states": len(p["states"]), "active": int(active.sum()), "passes": passes,
            "c_passes": c_passes, "rows": rows, "iterations": its}


def print_mpc(r: dict[str, Any]) -> None:
    names = {"py ours": "equilibrist MPCRuntime.solve (Python call)",
             "py daqp": "DAQP Model.update+solve (Python call)",
             "py soft": "  equilibrist, default MPC (+ soft track, angle)",
             "c ours": "equilibrist exported C (mpc_step)",
             "c daqp": "DAQP C (daqp_update_ldp+daqp_solve)",
             "c soft": "  equilibrist exported C, default MPC"}
    print(f"MPC: cart-pole 200 Hz, N = 30, |F| <= 20 N; {r['states']} closed-loop states after a "
          f"push, {r['active']} with the limit active; {r['passes']} Python passes, "
          f"{r['c_passes']} C passes, each from a cold start")
    print(f"{'us per call':48s} {'median':>7s} {'active':>7s} {'p99':>7s} {'worst':>8s} "
          f"{'w/o pre':>8s} {'pre':>5s} {'code':>7s} {'cold':>7s} {'|du| vs DAQP':>12s}")
    for k, s in r["rows"].items():
        print(f"{names[k]:48s} {s['median']:7.2f} {s['median_active']:7.2f} {s['p99']:7.2f} "
              f"{s['worst']:8.1f} {s['worst_quiet']:8.1f} {s['preempted']:5d} "
              f"{s['worst_best']:7.1f} {s['first_state']:7.1f} {s['du']:12.1e}")
    print("  active: states with the limit active; w/o pre: worst of the calls not preempted "
          "(pre: how many were); code: the worst state's best call; cold: the first state, "
          "from a cold start (median)")
    it = r["iterations"]
    print(f"DAQP iterations (median on active states / worst): equilibrist {it['ours']['median_active']:.0f}"
          f" / {it['ours']['worst']}, default MPC {it['soft']['median_active']:.0f} / "
          f"{it['soft']['worst']}, textbook QP {it['daqp']['median_active']:.0f} / {it['daqp']['worst']}")
    rows = r["rows"]
    co, cd, po, pd = rows["c ours"], rows["c daqp"], rows["py ours"], rows["py daqp"]
    goals = [("exported C median <= 1.5x DAQP C", co["median"] / cd["median"], 1.5),
             ("exported C median, active states <= 1.5x", co["median_active"] / cd["median_active"], 1.5),
             ("exported C p99 <= 1.5x DAQP C", co["p99"] / cd["p99"], 1.5),
             ("exported C worst <= 2x DAQP C's worst", co["worst"] / cd["worst"], 2.0),
             ("  the same, calls not preempted", co["worst_quiet"] / cd["worst_quiet"], 2.0),
             ("  the same, the code's worst", co["worst_best"] / cd["worst_best"], 2.0),
             ("Python call median <= 1.5x DAQP's", po["median"] / pd["median"], 1.5),
             ("Python call median, active states <= 1.5x", po["median_active"] / pd["median_active"], 1.5)]
    for text, ratio, bound in goals:
        print(f"  {text:44s} {ratio:6.2f}x  {'met' if ratio <= bound else 'NOT met'}")
    r["goals"] = {text.strip(): ratio for text, ratio, _ in goals}


# -- 2. the environments ---------------------------------------------------------------------
class Peer:
    """bench/_peers_envs.py running in the peers' Python."""

    def __init__(self, python: str) -> None:
        self.proc = subprocess.Popen([python, "-W", "ignore", str(HERE / "_peers_envs.py")],
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)

    def ask(self, **kw: Any) -> dict[str, Any]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps(kw) + "\n")
        self.proc.stdin.flush()
        answer: dict[str, Any] = json.loads(self.proc.stdout.readline())
        return answer

    def close(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.close()
        self.proc.wait(timeout=60)


def ours(way: str, n: int) -> tuple[Any, dict[str, float]]:
    """equilibrist's vector env: its own choice of threads, or kept on one or all."""
    import gymnasium as gym

    import equilibrist.envs  # noqa: F401  (registers the environments)
    from equilibrist.envs import vector as vector_module

    t0 = time.perf_counter()
    keep = vector_module.PARALLEL_MIN
    if way in ("one", "one_b"):
        vector_module.PARALLEL_MIN = 10**12
    try:
        env = gym.make_vec(ENV_ID, num_envs=n, vectorization_mode="vector_entry_point", **OPTIONS)
    finally:
        vector_module.PARALLEL_MIN = keep
    env.reset(seed=0)
    if way == "all":
        u = env.unwrapped
        u.parallel, u._mode, u._untimed = True, 1, 10**12  # type: ignore[attr-defined]
    actions = np.zeros((n, 1))
    t1 = time.perf_counter()
    env.step(actions)
    t2 = time.perf_counter()
    return (env, actions), {"ready": t1 - t0, "first": t2 - t1, "steps_per_call": 1}


#: The CPU seconds (every thread of the process) each timing of ``_time_ours`` took, per step.
_CPU: list[float] = []


def _time_ours(made: tuple[Any, Any], seconds: float) -> float:
    env, actions = made
    t0 = time.perf_counter()
    env.step(actions)
    count = max(3, int(seconds / max(time.perf_counter() - t0, 1e-9)))
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(count):
        env.step(actions)
    _CPU.append((time.process_time() - c0) / count)
    return (time.perf_counter() - t0) / count


def _paired(choice: tuple[Any, Any], one: tuple[Any, Any], seconds: float) -> float:
    """Its choice of threads against one thread, step by step: the two environments step in
    turn (the order alternating), so a busy machine's load, which comes and goes, falls on
    both alike; the ratio of their total times over about *seconds* (one thread's / the
    choice's: above 1, the choice is faster)."""
    spent = [0.0, 0.0]
    pair = (choice, one)
    count = max(200, int(seconds / max(_time_ours(one, 0.05), 1e-9)))
    for k in range(count):
        for i in ((0, 1) if k % 2 == 0 else (1, 0)):
            env, actions = pair[i]
            t0 = time.perf_counter()
            env.step(actions)
            spent[i] += time.perf_counter() - t0
    return spent[1] / spent[0]


def _best_step(made: tuple[Any, Any], count: int = 200) -> float:
    env, actions = made
    best = float("inf")
    for _ in range(count):
        t0 = time.perf_counter()
        env.step(actions)
        best = min(best, time.perf_counter() - t0)
    return best


def env_table(python: str | None, seconds: float, repeats: int) -> dict[str, Any]:
    from equilibrist.sim.kernel import thread_count

    peer = Peer(python) if python else None
    versions = peer.ask(cmd="versions") if peer else {}
    usable = [k for k in PEERS if peer and not str(versions.get(
        "gymnax" if k.startswith("gymnax") else k, "missing")).startswith("missing")]
    made: dict[tuple[str, int], Any] = {}
    first: dict[tuple[str, int], dict[str, Any]] = {}
    for n in SIZES:
        for way in OURS:
            made[(way, n)], first[(way, n)] = ours(way, n)
        for k in usable:
            assert peer is not None
            first[(k, n)] = peer.ask(cmd="make", peer=k, n=n)
    times: dict[tuple[str, int], list[float]] = {key: [] for key in first}
    # CPU seconds per step (all the process's threads): how much of the machine each got.
    cpu: dict[tuple[str, int], list[float]] = {key: [] for key in first}
    for rep in range(repeats):
        for n in SIZES:
            order = [*OURS, *usable]
            for k in order if rep % 2 == 0 else order[::-1]:
                if "error" in first[(k, n)]:
                    continue
                if k in OURS:
                    times[(k, n)].append(_time_ours(made[(k, n)], seconds))
                    cpu[(k, n)].append(_CPU[-1])
                else:
                    assert peer is not None
                    a = peer.ask(cmd="time", peer=k, n=n, seconds=seconds)
                    if "error" in a:
                        first[(k, n)] = a
                    else:
                        times[(k, n)].append(float(a["per_step"]))
                        cpu[(k, n)].append(float(a["cpu_per_step"]))
    # The choice against one thread, stepped in turn: the medians above take each way's
    # timings apart in time, which under load differ by tens of per cent between two
    # identical copies.
    paired = {n: _paired(made[("auto", n)], made[("one", n)], 20 * seconds) for n in SIZES}
    chosen = {n: int(made[("auto", n)][0].unwrapped.threads_in_use) for n in SIZES}
    # The best single step of each way: what it costs when the machine leaves it alone.
    best = {f"{k}@{n}": _best_step(made[(k, n)]) for n in SIZES for k in ("one", "all")}
    if peer:
        peer.close()
    rate = {f"{k}@{n}": n / statistics.median(v) for (k, n), v in times.items() if v}
    # Env-steps per CPU second (what a step costs, whatever share of the cores it got) and the
    # share itself (CPU seconds per wall second: 2 is both cores), over all the repeats.
    per_cpu = {f"{k}@{n}": n * len(v) / sum(v) for (k, n), v in cpu.items() if v and sum(v) > 0}
    share = {f"{k}@{n}": sum(cpu[(k, n)]) / sum(v) for (k, n), v in times.items() if v}
    return {"threads": thread_count(), "versions": versions, "usable": usable, "rate": rate,
            "per_cpu": per_cpu, "share": share,
            "best_step": best, "paired": paired,
            "first": {f"{k}@{n}": v for (k, n), v in first.items()}, "chosen": chosen}


def print_envs(r: dict[str, Any]) -> None:
    rate, first = r["rate"], r["first"]
    print(f"\nEnvironments: cart-pole, 0.02 s per step, fixed action; {r['threads']} threads; "
          "million env-steps per second (median of the repeats)")
    print(f"{'':28s}" + "".join(f"{'N = ' + str(n):>12s}" for n in SIZES))
    for k in (*OURS, *PEERS):
        cells = []
        for n in SIZES:
            key = f"{k}@{n}"
            if key in rate:
                extra = f" ({r['chosen'][n]})" if k == "auto" else ""
                cells.append(f"{rate[key] / 1e6:.3f}{extra}")
            else:
                cells.append(str(first.get(key, {}).get("error", "not run"))[:11])
        print(f"{NAMES[k]:28s}" + "".join(f"{c:>12s}" for c in cells))
    print("first step after make + reset, ms (make + reset in brackets); gymnax's first call "
          "compiles; lax.scan's first call runs a whole scan")
    for k in ("auto", *PEERS):
        cells = []
        for n in SIZES:
            f = first.get(f"{k}@{n}", {})
            cells.append(f"{1e3 * f['first']:.2f} ({1e3 * f['ready']:.0f})" if "first" in f
                         else "-")
        print(f"{NAMES[k]:28s}" + "".join(f"{c:>16s}" for c in cells))
    verdict = []
    for n in SIZES:
        auto, one, twin, full = (rate.get(f"{k}@{n}") for k in ("auto", "one", "one_b", "all"))
        if auto and one:
            verdict.append(f"N = {n}: its choice {auto / one:.2f}x one thread"
                           + (f", all threads {full / one:.2f}x" if full else "")
                           + (f" (another one-thread copy {twin / one:.2f}x)" if twin else ""))
    print("threads: " + "; ".join(verdict))
    print("its choice against one thread, stepped in turn (one thread's time / the choice's): "
          + "; ".join(f"N = {n}: {r['paired'][n]:.3f}x" for n in SIZES))
    b = r["best_step"]
    print("best single step of 200, one thread / all threads (ms): " + "; ".join(
        f"N = {n}: {1e3 * b[f'one@{n}']:.3f} / {1e3 * b[f'all@{n}']:.3f} "
        f"({b[f'one@{n}'] / b[f'all@{n}']:.2f}x)" for n in SIZES))
    ahead = []
    for n in SIZES:
        peers = {k: rate[f"{k}@{n}"] for k in PEERS if f"{k}@{n}" in rate}
        if peers and f"auto@{n}" in rate:
            best = max(peers, key=lambda k: peers[k])
            ahead.append(f"N = {n}: {rate[f'auto@{n}'] / peers[best]:.2f}x the fastest peer "
                         f"({NAMES[best]})")
    print("ahead: " + "; ".join(ahead))
    print("million env-steps per CPU second (all the process's threads), and in brackets its "
          "CPU seconds per wall second while stepping (2: both cores)")
    for k in (*OURS, *PEERS):
        cells = [f"{r['per_cpu'][f'{k}@{n}'] / 1e6:.3f} ({r['share'][f'{k}@{n}']:.2f})"
                 if f"{k}@{n}" in r.get("per_cpu", {}) else "-" for n in SIZES]
        print(f"{NAMES[k]:28s}" + "".join(f"{c:>16s}" for c in cells))
    print("peers: " + ", ".join(f"{k} {v}" for k, v in r["versions"].items()))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--peers", default=str(HERE / "_peers" / "envs" / "bin" / "python"),
                    help="a Python with the environment peers (bench/peers_envs.sh makes one)")
    ap.add_argument("--passes", type=int, default=40, help="Python passes over the MPC's states")
    ap.add_argument("--c-passes", type=int, default=200, help="C passes over the MPC's states")
    ap.add_argument("--seconds", type=float, default=0.2, help="per timing of an environment")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--only", choices=("mpc", "envs"), default=None)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--busy", type=int, default=0,
                    help="busy programs running alongside (the loaded machine's case)")
    args = ap.parse_args()
    with busy(args.busy):
        return measure(args)


def measure(args: argparse.Namespace) -> int:
    out: dict[str, Any] = {"load_before": os.getloadavg(), "busy": args.busy}
    if args.busy:
        print(f"{args.busy} busy programs alongside")
    print(f"load average before: {load()} (1/5/15 min), {os.cpu_count()} cores")
    if args.only != "envs":
        out["mpc"] = mpc_table(args.passes, args.c_passes)
        print_mpc(out["mpc"])
    if args.only != "mpc":
        python = args.peers if Path(args.peers).exists() else None
        if python is None:
            print(f"no peers at {args.peers}: run bash bench/peers_envs.sh (equilibrist alone)")
        out["envs"] = env_table(python, args.seconds, args.repeats)
        print_envs(out["envs"])
    out["load_after"] = os.getloadavg()
    print(f"load average after: {load()}")
    if args.json:
        print(json.dumps(out, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
