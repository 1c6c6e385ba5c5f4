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

Usage: ``python bench/bench_playground.py [--sessions 20] [--seconds 20] [--json]``.
"""

from __future__ import annotations

import argparse
import asyncio
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


async def _client(url: str, seconds: float, index: int, out: list[dict]) -> None:
    import websockets

    frames = 0
    stamps: list[tuple[float, float]] = []  # (arrival, simulated time) of each frame
    push_sent: dict[int, float] = {}
    push_latency: list[float] = []
    tune_sent: dict[int, float] = {}
    tune_latency: list[float] = []
    design_ms: list[float] = []
    seq = 1000 * index
    async with websockets.connect(url, max_size=2**22) as ws:
        # The opening frames: hello, system, design.
        while True:
            msg = json.loads(await ws.recv())
            if msg["type"] == "frame":
                break
        await asyncio.sleep(1.0 + 0.05 * index)  # settle, and spread the clients' pushes
        begin = time.perf_counter()
        next_push, next_tune = begin + 0.5, begin + 1.5
        scale = 0.2
        pending_tune: int | None = None
        while True:
            now = time.perf_counter()
            if now - begin > seconds:
                break
            if now >= next_push:
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
            elif msg["type"] == "design" and pending_tune is not None:
                tune_latency.append(got - tune_sent.pop(pending_tune))
                design_ms.append(msg["milliseconds"])
                pending_tune = None
            elif msg["type"] in ("error", "design_error"):
                raise RuntimeError(f"session {index}: {msg['message']}")
    # Rates over the second half of the run: the frames buffered while the client
    # settled are read in a burst at its start and would flatter both.
    half = stamps[len(stamps) // 2 :]
    wall = half[-1][0] - half[0][0] if len(half) > 1 else 0.0
    out.append({
        "frames_per_second": (len(half) - 1) / wall if wall > 0 else 0.0,
        "realtime": (half[-1][1] - half[0][1]) / wall if wall > 0 else 0.0,
        "push_latency": push_latency,
        "tune_latency": tune_latency,
        "design_ms": design_ms,
    })


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sessions", type=int, default=20)
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
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
            tasks = [asyncio.create_task(_client(url, args.seconds, i, results))
                     for i in range(args.sessions)]
            await asyncio.sleep(1.5 + 0.05 * args.sessions)
            cpu0, wall0 = _cpu_seconds(server.pid), time.perf_counter()
            await asyncio.sleep(max(1.0, args.seconds - 2.0))
            cpu = (_cpu_seconds(server.pid) - cpu0) / (time.perf_counter() - wall0)
            await asyncio.gather(*tasks)
            return cpu

        cpu = asyncio.run(run_all())
    finally:
        server.send_signal(signal.SIGINT)
        server.wait(timeout=30)
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
    return 0


if __name__ == "__main__":
    sys.exit(main())
