"""Hardware in the loop over a pseudo-terminal: round trips per second in lockstep, and realtime at 200 Hz.

The device is the export's own C as a host program (``make hil-host``);
``equilibrist hil`` talks to it over a pseudo-terminal, two ways: the device's
own (``hil_host --pty``: the host opens the path it prints, two processes, as
with a board on a USB cable, where no third program relays the bytes), and
two pseudo-terminals joined by ``socat`` where it is installed (else by a
relay thread in this process), a third process on the way.

    .venv/bin/python bench/bench_hil.py [--duration 10] [--busy 4]

``--busy N`` keeps N busy programs (a Python loop each) running through the
runs: the realtime figures on a loaded machine, where the simulator's and the
device's real-time scheduling (``scheduling`` in the JSON) is what keeps the
samples on time.

Goals (docs/hil.md): lockstep >= 2,000 round trips per second on the
cart-pole's LQG, equal to ``simulate``; realtime at 200 Hz for 10 s with no
late answer on an idle machine and a p99 round trip under 1 ms.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager, suppress
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
from _busy import busy  # noqa: E402

from equilibrist.native.firmware import RT_PRIORITY  # noqa: E402

CLI = [sys.executable, "-m", "equilibrist.cli.main"]


def realtime(tid: int) -> None:
    """Give the relay the real-time priority the two ends take (``hil``, ``hil_host``), where
    the system grants it: the joined pair then measures the link, not the relay's wake-ups."""
    with suppress(OSError):
        os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(RT_PRIORITY))


@contextmanager
def linked_ptys():
    """Two pseudo-terminal paths joined as by a cable (socat, else a relay thread)."""
    socat = shutil.which("socat")
    if socat is None:
        from support.hil import pty_link

        with pty_link() as link:
            realtime(link.relay.native_id)
            yield link.paths, "relay thread"
        return
    proc = subprocess.Popen([socat, "-d", "-d", "pty,raw,echo=0", "pty,raw,echo=0"],
                            stderr=subprocess.PIPE, text=True)
    realtime(proc.pid)
    paths: list[str] = []
    while len(paths) < 2:
        line = proc.stderr.readline()
        m = re.search(r"PTY is (\S+)", line)
        if m:
            paths.append(m.group(1))
    try:
        yield paths, "socat"
    finally:
        proc.terminate()
        proc.wait()


@contextmanager
def device_pty(host_program: Path):
    """The device on a pseudo-terminal of its own (``hil_host --pty``): the path it prints."""
    device = subprocess.Popen([str(host_program), "--pty"], stdout=subprocess.PIPE, text=True)
    try:
        assert device.stdout is not None
        yield device.stdout.readline().strip()
    finally:
        device.terminate()
        device.wait()
        if device.stdout is not None:
            device.stdout.close()


def run_hil(host_program: Path, link: str, *argv: str) -> tuple[dict, float, str]:
    def command(port: str) -> tuple[subprocess.CompletedProcess[str], float]:
        t0 = time.perf_counter()
        done = subprocess.run([*CLI, "hil", "cartpole", "--port", port, "--json", *argv],
                              capture_output=True, text=True, check=False)
        return done, time.perf_counter() - t0

    if link == "device":
        how = "the device's own pseudo-terminal (hil_host --pty)"
        with device_pty(host_program) as port:
            done, wall = command(port)
    else:
        with linked_ptys() as (paths, joined):
            how = f"two pseudo-terminals joined by {joined}"
            device = subprocess.Popen([str(host_program), paths[0]])
            try:
                done, wall = command(paths[1])
            finally:
                device.terminate()
                device.wait()
    if done.returncode != 0:
        sys.exit(f"hil failed: {done.stderr.strip()}")
    return json.loads(done.stdout), wall, how


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--busy", type=int, default=0, help="busy programs running alongside")
    args = ap.parse_args()
    with busy(args.busy):
        measure(args)


def measure(args: argparse.Namespace) -> None:
    print(f"load average of the machine: {os.getloadavg()[0]:.1f} (2 cores), "
          f"{args.busy} busy programs alongside")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "cart_lqg"
        subprocess.run([*CLI, "export", "cartpole", "--out", str(folder), "--duration", "0.5"],
                       check=True, capture_output=True)
        subprocess.run(["make", "-s", "-C", str(folder), "hil-host"], check=True)
        host = folder / "hil_host"
        duration = f"{args.duration:g}"
        for link in ("device", "socat"):
            fig, wall, how = run_hil(host, link, "--duration", duration, "--x0", "theta=0.1")
            rt = fig["round_trip_ms"]
            # Round trips per second: the samples over the loop's own time, from the first step
            # to the last answer (the process start and the design are not the link's).
            steps = fig["steps"]
            print(f"link: {how}")
            print(f"lockstep  {steps} samples of the cart-pole's LQG: "
                  f"{fig['round_trips_per_s']:.0f} round trips/s, simulation included (goal >= "
                  f"2000); round trip p50 {rt['p50']:.3f} ms, p99 {rt['p99']:.3f} ms, max "
                  f"{rt['max']:.3f} ms; whole command {wall:.1f} s")
            fig, wall, how = run_hil(host, link, "--mode", "realtime", "--duration", duration,
                                     "--x0", "theta=0.1")
            rt = fig["round_trip_ms"]
            print(f"realtime  200 Hz for {duration} s: late {fig['late']}, lost {fig['lost']} of "
                  f"{fig['steps']} (goal 0 late); round trip p50 {rt['p50']:.3f} ms, p99 "
                  f"{rt['p99']:.3f} ms (goal < 1), max {rt['max']:.3f} ms; device step p50 "
                  f"{fig['device_step_us']['p50']:.0f} us; sent after its time p99 "
                  f"{fig['send_delay_ms']['p99']:.3f} ms, max {fig['send_delay_ms']['max']:.3f} ms; "
                  f"scheduling {fig['scheduling']}")
    print(f"load average of the machine after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
