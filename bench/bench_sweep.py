"""Studies on Dask: scaling from one worker to two, and the cost of the Dask path.

Two measurements, in one run on one machine:

1. Scaling: one study (cart-pole, digital LQG at 200 Hz with noise, 16
   points of m_p x 2,500 runs of 1 s, full metrics) on a
   ``distributed.LocalCluster`` of 1 worker and of 2 workers (one process
   each, one Dask thread and one core thread per worker). Efficiency =
   T(1) / (2 T(2)); goal >= 0.8.
2. Overhead: 10^5 runs (10 points x 10^4 runs, basic metrics, the nominal
   design at every point) through the Dask path on 2 workers, against the
   plain compiled batch (``simulate_batch``, 10^5 runs on 2 threads,
   the same plants, controller, seeds and duration); goal <= 10 %. The
   local study path (no Dask) is timed beside them.

The clusters are started, and every process has loaded the compiled core,
before the clock starts; each figure is the best of ``--repeats``.

Usage: ``python bench/bench_sweep.py [--repeats N] [--json]``.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import tempfile
import time
from pathlib import Path

import numpy as np


def _cluster(workers: int):  # type: ignore[no-untyped-def]
    from distributed import Client, LocalCluster

    lc = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      dashboard_address=":0", silence_logs=logging.ERROR)
    return lc, Client(lc)


def _warm_worker() -> None:
    from equilibrist.study import evaluate_point, make_study

    evaluate_point(make_study("cartpole", vary={"m_p": [0.1]}, runs=2, duration=0.1), 0,
                   threads=1)


def _cpu(client) -> float:  # type: ignore[no-untyped-def]
    """CPU seconds of this process, the workers and the scheduler so far."""
    workers = sum(client.run(time.process_time).values())
    pid, sched = client.run_on_scheduler(_pid_and_cpu)
    # A LocalCluster's scheduler runs in this process: counted once.
    return time.process_time() + workers + (0.0 if pid == os.getpid() else sched)


def _pid_and_cpu() -> tuple[int, float]:
    return os.getpid(), time.process_time()


def _timed_study(study, client, folder: Path, name: str, chunk: int, threads: int | None  # type: ignore[no-untyped-def]
                 ) -> tuple[float, float]:
    from equilibrist.study import run_study

    out = folder / f"{name}.parquet"
    out.unlink(missing_ok=True)
    c0 = _cpu(client)
    t0 = time.perf_counter()
    run_study(study, out, client=client, chunk_size=chunk, threads=threads)
    wall = time.perf_counter() - t0
    return wall, _cpu(client) - c0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    from equilibrist.control.design import design
    from equilibrist.numeric.lookup import get_system
    from equilibrist.sim.batch import simulate_batch
    from equilibrist.sim.batch_inputs import sample_uniform
    from equilibrist.sim.controllers import LQG
    from equilibrist.sim.noise import Noise
    from equilibrist.study import make_study, run_study

    folder = Path(tempfile.mkdtemp(prefix="bench_sweep_"))
    scaling = make_study("cartpole", vary={"m_p": "0.08:0.2:16"}, runs=2500, duration=1.0,
                         x0={"theta": "-0.2:0.2"}, seed=1)
    masses = np.linspace(0.095, 0.105, 10)
    overhead = make_study("cartpole", vary={"m_p": [float(m) for m in masses]}, runs=10_000,
                          duration=1.0, x0={"theta": "-0.2:0.2"}, seed=2, metrics="basic",
                          design_for="nominal")
    # Warm the compiled core in this process (and so on disk for the workers).
    run_study(make_study("cartpole", vary={"m_p": [0.1]}, runs=4, duration=0.1),
              folder / "warm.parquet")

    # The plain batch: the same 10^5 runs as one simulate_batch call.
    plant = get_system("cartpole")
    d = design(plant, rate=200.0)
    ctrl, noise = LQG.from_design(d), Noise.from_design(d)
    x0s = np.concatenate([
        sample_uniform(plant.with_params(m_p=float(m)), 10_000, ranges={"theta": (-0.2, 0.2)},
                       seed=overhead.point_seed(i, 1), x_op=np.asarray(d.plant.x0))[0]
        for i, m in enumerate(masses)])
    m_p = np.repeat(masses, 10_000)

    def plain() -> tuple[float, float]:
        c0, t0 = time.process_time(), time.perf_counter()
        simulate_batch(plant, ctrl, runs=100_000, duration=1.0, rate=200.0, x0=x0s,
                       params={"m_p": m_p}, noise=noise, seed=2, workers=2)
        return time.perf_counter() - t0, time.process_time() - c0

    def local_study() -> tuple[float, float]:
        out = folder / "local.parquet"
        out.unlink(missing_ok=True)
        c0, t0 = time.process_time(), time.perf_counter()
        run_study(overhead, out, chunk_size=1, threads=2)
        return time.perf_counter() - t0, time.process_time() - c0

    plain()
    results: dict[str, list[tuple[float, float]]] = {
        "plain": [], "local": [], "dask2": [], "scale1": [], "scale2": []}
    load_before = os.getloadavg()[0]
    lc1, c1 = _cluster(1)
    lc2, c2 = _cluster(2)
    try:
        for client in (c1, c2):  # every worker loads the core before timing
            client.run(_warm_worker)
        for _ in range(args.repeats):
            results["plain"].append(plain())
            results["local"].append(local_study())
            results["dask2"].append(_timed_study(overhead, c2, folder, "dask2", 1, 1))
            results["scale1"].append(_timed_study(scaling, c1, folder, "s1", 1, 1))
            results["scale2"].append(_timed_study(scaling, c2, folder, "s2", 1, 1))
    finally:
        for c, lc in ((c1, lc1), (c2, lc2)):
            c.close()
            lc.close()
    same = (folder / "s1.parquet").read_bytes() == (folder / "s2.parquet").read_bytes()
    load_after = os.getloadavg()[0]
    best = {k: min(w for w, _ in v) for k, v in results.items()}
    cpu = {k: min(c for _, c in v) for k, v in results.items()}
    runs_scaling = scaling.total_runs
    steps_per_run = 1.0 * 1000  # 1 s at the 1 ms physics step
    out = {
        "scaling_study": f"cartpole LQG 200 Hz with noise, {scaling.n_points} points x "
                         f"{scaling.runs} runs x 1 s, full metrics",
        "one_worker_s": best["scale1"], "two_workers_s": best["scale2"],
        "scaling_efficiency": best["scale1"] / (2 * best["scale2"]),
        "tables_identical": same,
        "per_run_ms_one_worker": 1e3 * best["scale1"] / runs_scaling,
        "per_step_ns_one_worker": 1e9 * best["scale1"] / (runs_scaling * steps_per_run),
        "overhead_study": "10 points x 10^4 runs x 1 s, basic metrics, nominal design",
        "plain_batch_s": best["plain"], "local_study_s": best["local"],
        "dask_2_workers_s": best["dask2"],
        "dask_overhead": best["dask2"] / best["plain"] - 1.0,
        "local_overhead": best["local"] / best["plain"] - 1.0,
        "cpu_s": cpu,
        "dask_overhead_cpu": cpu["dask2"] / cpu["plain"] - 1.0,
        "local_overhead_cpu": cpu["local"] / cpu["plain"] - 1.0,
        "scaling_cpu_ratio": cpu["scale2"] / cpu["scale1"],
        "load_average": [load_before, load_after],
        "runs": results,
    }
    if args.json:
        print(json.dumps(out, indent=2))
        return
    print(f"load average of the machine: {load_before:.1f} before, {load_after:.1f} after "
          f"(2 cores)")
    print(f"scaling: {out['scaling_study']}")
    print(f"  1 worker   {best['scale1']:8.2f} s   {1e3 * best['scale1'] / runs_scaling:.3f} ms/run")
    print(f"  2 workers  {best['scale2']:8.2f} s   efficiency {out['scaling_efficiency']:.2f} "
          f"(goal >= 0.8); tables identical: {same}")
    print(f"  CPU time: {cpu['scale1']:.2f} s on 1 worker, {cpu['scale2']:.2f} s on 2 "
          f"(ratio {out['scaling_cpu_ratio']:.3f})")
    print(f"overhead at 10^5 runs: {out['overhead_study']}")
    print(f"  plain simulate_batch, 2 threads   {best['plain']:8.2f} s")
    print(f"  study, local (no Dask), 2 threads {best['local']:8.2f} s   "
          f"{100 * out['local_overhead']:+.1f} %")
    print(f"  study, Dask, 2 workers x 1 thread {best['dask2']:8.2f} s   "
          f"{100 * out['dask_overhead']:+.1f} % (goal <= 10 %)")
    print(f"  CPU time (all processes): plain {cpu['plain']:.2f} s, local study {cpu['local']:.2f} s "
          f"({100 * out['local_overhead_cpu']:+.1f} %), Dask {cpu['dask2']:.2f} s "
          f"({100 * out['dask_overhead_cpu']:+.1f} %)")


if __name__ == "__main__":
    main()
