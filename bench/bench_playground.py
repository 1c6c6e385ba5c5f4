"""Load of the playground: concurrent sessions on loopback, each at its frame rate in real time.

``equilibrist play`` is started as a user starts it (its own process, a free
loopback port). N clients (the ``websockets`` library, one asyncio task each,
in this process) open a session each on the cart-pole and, for D seconds:

* count the frames they receive (goal: >= 30 per second each);
* compare the simulated time of their frames with the wall clock (goal: the
  simulation in real time, ratio 1.00);
* push every 2 s and time the push to the first frame that shows it acting
  (``push_seq`` echoed, the push's input nonzero);
* one of them retunes a Bryson scale every 3 s (a student moving a slider
  while the others watch); the tune is timed to its ``design`` frame, and
  the design's own duration read from it (goal: < 100 ms).

The server's CPU is read from ``/proc`` (user + system time of its process
over the measured window) in percent of one core.

``--swingup K`` and ``--mpc K`` add K sessions each running those
controllers beside the N sessions: a swing-up session starts hanging and
hangs again every 6 s (its catch time, from the hang to the supervisor's
hand-over, is read from the frames, in simulated seconds); an MPC session
is pushed as the others and reports the solve times the page shows. Their
frame rates and real-time ratios are reported apart from the N sessions'.

``--costs`` measures in this process, without a server, what one sample
costs under each controller (the session's whole sample: sensors,
controller, actuator, the plant's RK4 steps, the recording), the swing-up
also with its functions compiled to C (the peer of the plain-Python
runtime the playground runs), and the redesign time of each controller
(the design, plus the swing-up's or the MPC's construction with DAQP's
setup).

Usage: ``python bench/bench_playground.py [--sessions 20] [--seconds 20] [--swingup 1] [--mpc 1]
[--costs] [--json]``.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import os
import signal
import statistics
import subprocess
import sys
import time


def _cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as fh:
        fields = fh.read().rsplit(")", 1)[1].split()
    ticks = os.sysconf("SC_CLK_TCK")
    return (int(fields[11]) + int(fields[12])) / ticks  # utime + stime


async def _client(url: str, seconds: float, index: int, out: list[dict], kind: str = "lqg") -> None:
    import websockets

    frames = 0
    stamps: list[tuple[float, float]] = []  # (arrival, simulated time) of each frame
    push_sent: dict[int, float] = {}
    push_latency: list[float] = []
    tune_sent: dict[int, float] = {}
    tune_latency: list[float] = []
    design_ms: list[float] = []
    seq = 1000 * index
    warnings: list[str] = []
    catches: list[float] = []  # simulated seconds from a hang to the hand-over
    solve: dict | None = None
    hung: bool = False
    async with websockets.connect(url, max_size=2**22) as ws:
        # The opening frames: hello, system, design.
        while True:
            msg = json.loads(await ws.recv())
            if msg["type"] == "frame":
                break
        if kind != "lqg":
            await ws.send(json.dumps({"type": "tune", "controller": kind}))
            while json.loads(await ws.recv())["type"] != "design":
                pass
        await asyncio.sleep(1.0 + 0.05 * index)  # settle, and spread the clients' pushes
        begin = time.perf_counter()
        next_push, next_tune = begin + 0.5, begin + 1.5
        next_hang = begin if kind == "swingup" else float("inf")
        scale = 0.2
        pending_tune: int | None = None
        while True:
            now = time.perf_counter()
            if now - begin > seconds:
                break
            if now >= next_hang:
                await ws.send(json.dumps({"type": "hang"}))
                hung = False
                next_hang += 6.0
            if now >= next_push and kind != "swingup":
                seq += 1
                push_sent[seq] = time.perf_counter()
                await ws.send(json.dumps({"type": "push", "size": 0.3, "seq": seq}))
                next_push += 2.0
            if index == 0 and now >= next_tune and pending_tune is None:
                seq += 1
                scale = 0.1 if scale == 0.2 else 0.2
                tune_sent[seq] = time.perf_counter()
                pending_tune = seq
                await ws.send(json.dumps({"type": "tune", "scales": {"theta": scale}, "seq": seq}))
                next_tune += 3.0
            try:
                raw = await asyncio.wait_for(ws.recv(), timeout=1.0)
            except TimeoutError:
                continue
            got = time.perf_counter()
            msg = json.loads(raw)
            if msg["type"] == "frame":
                frames += 1
                stamps.append((got, msg["t"]))
                s = msg.get("push_seq")
                if s in push_sent and msg["push"] != 0:
                    push_latency.append(got - push_sent.pop(s))
                if msg.get("hanging"):
                    hung = True
                elif hung and msg.get("mode") == "balancing":
                    catches.append(msg["mode_since"])
                    hung = False
                if msg.get("solve"):
                    solve = msg["solve"]
            elif msg["type"] == "design" and pending_tune is not None:
                tune_latency.append(got - tune_sent.pop(pending_tune))
                design_ms.append(msg["milliseconds"])
                pending_tune = None
            elif msg["type"] == "warning":
                warnings.append(msg["message"])
            elif msg["type"] in ("error", "design_error"):
                raise RuntimeError(f"session {index}: {msg['message']}")
    # Rates over the second half of the run: the frames buffered while the client
    # settled are read in a burst at its start and would flatter both.
    half = stamps[len(stamps) // 2 :]
    wall = half[-1][0] - half[0][0] if len(half) > 1 else 0.0
    out.append({
        "frames_per_second": (len(half) - 1) / wall if wall > 0 else 0.0,
        # Simulated time advanced (a hang or a reset starts it again at 0) over wall time.
        "realtime": sum(max(0.0, b[1] - a[1]) for a, b in itertools.pairwise(half)) / wall
        if wall > 0 else 0.0,
        "push_latency": push_latency,
        "tune_latency": tune_latency,
        "design_ms": design_ms,
        "kind": kind,
        "warnings": warnings,
        "catches": catches,
        "solve": solve,
    })


def costs(seconds: float = 10.0) -> dict:
    """Per-sample cost of each controller in a session, and redesign times (in this process)."""
    import numpy as np

    from equilibrist.control.swingup import SwingUpRuntime
    from equilibrist.web.session import Session
    from equilibrist.web.session_design import Catalogue, redesign

    cat = Catalogue.default()
    out: dict = {"per_sample_us": {}, "redesign_ms": {}}
    for kind in ("lqg", "lqr", "swingup", "mpc"):
        session = Session(cat, "cartpole", seed=1)
        if kind != "lqg":
            settings = session.settings.changed({"controller": kind})
            system = session.prepare(settings)
            session.install(settings, system, *redesign(system, settings))
        if kind == "swingup":
            session.reset(hang=True)
        clock = 0.0
        session.advance_to(clock)
        samples, spent = 0, 0.0
        for frame in range(int(seconds * 40)):
            if kind != "swingup" and frame % 80 == 40:
                session.push_value = 0.5 * 200.0  # the page's push button: half the full scale
                session.push_left = 20
            clock += 0.025
            t0 = time.perf_counter()
            samples += session.advance_to(clock)
            spent += time.perf_counter() - t0
        out["per_sample_us"][kind] = 1e6 * spent / max(samples, 1)
        if kind == "swingup":
            out["swingup_caught_at_s"] = session.mode_since if session.mode == "balancing" else None
        if kind == "mpc":
            out["mpc_solve"] = session.loop.runner.solve_stats() if session.loop.runner else None
        # Redesigns: a Bryson scale moved back and forth.
        times, parts = [], []
        for i in range(12):
            settings = session.settings.changed({"scales": {"theta": 0.1 if i % 2 else 0.2}})
            system = session.prepare(settings)
            t0 = time.perf_counter()
            d, sec, err, runner, built = redesign(system, settings)
            times.append(1e3 * (time.perf_counter() - t0))
            parts.append((1e3 * sec, 1e3 * built))
            assert err is None, err
            session.install(settings, system, d, sec, err, runner, built)
        out["redesign_ms"][kind] = {
            "median": statistics.median(times), "max": max(times),
            "design_median": statistics.median(p[0] for p in parts),
            "controller_median": statistics.median(p[1] for p in parts),
            "controller_max": max(p[1] for p in parts)}
    # The peer of the swing-up's plain-Python runtime: the same functions compiled to C.
    session = Session(cat, "cartpole", seed=1)
    settings = session.settings.changed({"controller": "swingup"})
    system = session.prepare(settings)
    d, *_ = redesign(system, settings)
    from equilibrist.control.swingup import swingup

    ctrl = swingup(system, design=d)
    y, r = np.array([0.0, 3.1]), np.zeros(0)
    for label, rt in (("python", ctrl.runtime()), ("compiled", SwingUpRuntime(ctrl))):
        t0 = time.perf_counter()
        u = rt.output(0.0, y, r)
        rt.update(0.0, y, r, u)
        first = time.perf_counter() - t0
        n = 20000
        t0 = time.perf_counter()
        for _ in range(n):
            u = rt.output(0.0, y, r)
            rt.update(0.0, y, r, u)
        out[f"swingup_controller_{label}_us"] = 1e6 * (time.perf_counter() - t0) / n
        out[f"swingup_controller_{label}_first_call_s"] = first
    out["load_average"] = os.getloadavg()[0]
    return out


def print_costs(c: dict) -> None:
    print(f"cart-pole at 200 Hz, one session in this process (load average {c['load_average']:.2f})")
    print("  per sample (sensors, controller, actuator, plant RK4 5 x 1 ms, record):")
    lqg = c["per_sample_us"]["lqg"]
    for kind, us in c["per_sample_us"].items():
        print(f"    {kind:8s} {us:8.1f} us  ({us / lqg:.2f} x LQG; {us * 200 / 1e4:.2f} % of a core "
              "in real time)")
    print(f"  swing-up controller alone: plain Python {c['swingup_controller_python_us']:.1f} us a sample "
          f"(first call {c['swingup_controller_python_first_call_s'] * 1e3:.1f} ms), compiled C "
          f"{c['swingup_controller_compiled_us']:.1f} us "
          f"(first call, compiling: {c['swingup_controller_compiled_first_call_s']:.2f} s)")
    if c.get("swingup_caught_at_s") is not None:
        print(f"  swing-up from hanging caught at t = {c['swingup_caught_at_s']:.2f} s (simulated)")
    if c.get("mpc_solve"):
        s = c["mpc_solve"]
        print(f"  MPC sample's solve over the last {s['samples']} samples: median {s['median_ms']:.3f} ms, "
              f"worst {s['worst_ms']:.3f} ms (pushed every 2 s)")
    print("  redesign on a moved Bryson scale (design + controller):")
    for kind, r in c["redesign_ms"].items():
        print(f"    {kind:8s} median {r['median']:6.1f} ms, max {r['max']:6.1f} ms; of which the "
              f"swing-up's or MPC's construction median {r['controller_median']:5.1f} ms, "
              f"max {r['controller_max']:5.1f} ms")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sessions", type=int, default=20)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--swingup", type=int, default=0, help="extra sessions running the swing-up")
    ap.add_argument("--mpc", type=int, default=0, help="extra sessions running the MPC")
    ap.add_argument("--costs", action="store_true", help="per-sample and redesign costs (no server)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    if args.costs:
        c = costs()
        if args.json:
            print(json.dumps(c, indent=2))
        else:
            print_costs(c)
        return 0
    server = subprocess.Popen(
        [sys.executable, "-m", "equilibrist.cli.main", "play", "--no-browser", "--port", "0"],
        stdout=subprocess.PIPE, text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))
    try:
        line = server.stdout.readline() if server.stdout else ""
        if not line.startswith("equilibrist playground at "):
            raise SystemExit(f"the server did not start: {line!r}")
        url = line.split()[3].replace("http://", "ws://") + "ws"
        results: list[dict] = []

        async def run_all() -> float:
            kinds = ["lqg"] * args.sessions + ["swingup"] * args.swingup + ["mpc"] * args.mpc
            tasks = [asyncio.create_task(_client(url, args.seconds, i, results, k))
                     for i, k in enumerate(kinds)]
            await asyncio.sleep(1.5 + 0.05 * len(kinds))
            cpu0, wall0 = _cpu_seconds(server.pid), time.perf_counter()
            await asyncio.sleep(max(1.0, args.seconds - 2.0))
            cpu = (_cpu_seconds(server.pid) - cpu0) / (time.perf_counter() - wall0)
            await asyncio.gather(*tasks)
            return cpu

        cpu = asyncio.run(run_all())
    finally:
        server.send_signal(signal.SIGINT)
        server.wait(timeout=30)
    extra = [r for r in results if r["kind"] != "lqg"]
    results = [r for r in results if r["kind"] == "lqg"]
    fps = [r["frames_per_second"] for r in results]
    rt = [r["realtime"] for r in results]
    pushes = sorted(x * 1e3 for r in results for x in r["push_latency"])
    tunes = sorted(x * 1e3 for r in results for x in r["tune_latency"])
    designs = sorted(x for r in results for x in r["design_ms"])

    def pct(values: list[float], q: float) -> float:
        return values[min(len(values) - 1, int(q * len(values)))] if values else float("nan")

    summary = {
        "sessions": args.sessions,
        "seconds": args.seconds,
        "frames_per_second_min": min(fps),
        "frames_per_second_median": statistics.median(fps),
        "realtime_min": min(rt),
        "realtime_max": max(rt),
        "push_to_frame_ms_median": pct(pushes, 0.5),
        "push_to_frame_ms_p95": pct(pushes, 0.95),
        "pushes": len(pushes),
        "tune_to_design_ms_median": pct(tunes, 0.5),
        "tune_to_design_ms_p95": pct(tunes, 0.95),
        "design_ms_median": pct(designs, 0.5),
        "design_ms_p95": pct(designs, 0.95),
        "tunes": len(tunes),
        "server_cpu_percent_of_one_core": 100 * cpu,
        # What one session costs the server, whatever share of the machine it got:
        # CPU per second of simulated real time and per frame sent.
        "server_cpu_ms_per_session_second": 1e3 * cpu / args.sessions / statistics.median(rt),
        "server_cpu_ms_per_frame": 1e3 * cpu / args.sessions / statistics.median(fps),
        "cores": os.cpu_count(),
        "load_average": os.getloadavg()[0],
        "extra": [{"kind": r["kind"], "frames_per_second": r["frames_per_second"],
                   "realtime": r["realtime"], "catches_s": r["catches"], "solve": r["solve"],
                   "warnings": len(r["warnings"])} for r in extra],
    }
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(f"{args.sessions} sessions for {args.seconds:g} s on loopback ({os.cpu_count()} cores, "
              f"load average {summary['load_average']:.2f})")
        print(f"  frames per second per session: min {summary['frames_per_second_min']:.1f}, "
              f"median {summary['frames_per_second_median']:.1f} (goal >= 30)")
        print(f"  simulated time / wall time:    {summary['realtime_min']:.3f} to "
              f"{summary['realtime_max']:.3f} (goal 1.000)")
        print(f"  push to first frame showing it: median {summary['push_to_frame_ms_median']:.0f} ms, "
              f"95th percentile {summary['push_to_frame_ms_p95']:.0f} ms ({len(pushes)} pushes)")
        print(f"  tune to new design frame:      median {summary['tune_to_design_ms_median']:.0f} ms, "
              f"95th percentile {summary['tune_to_design_ms_p95']:.0f} ms ({len(tunes)} tunes); "
              f"the design itself median {summary['design_ms_median']:.0f} ms, "
              f"95th percentile {summary['design_ms_p95']:.0f} ms")
        print(f"  server CPU: {summary['server_cpu_percent_of_one_core']:.0f} % of one core; "
              f"{summary['server_cpu_ms_per_session_second']:.1f} ms per session per simulated "
              f"second ({summary['server_cpu_ms_per_frame']:.2f} ms per frame sent, its samples "
              "included)")
        for r in summary["extra"]:
            line = (f"  + a {r['kind']} session: {r['frames_per_second']:.1f} frames per second, "
                    f"simulated / wall time {r['realtime']:.3f}, {r['warnings']} lag warnings")
            if r["kind"] == "swingup":
                line += f"; caught {len(r['catches_s'])} times, at t = " + ", ".join(
                    f"{c:.2f}" for c in r["catches_s"]) + " s after each hang"
            if r["solve"]:
                line += (f"; solve median {r['solve']['median_ms']:.3f} ms, worst "
                         f"{r['solve']['worst_ms']:.3f} ms")
            print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
