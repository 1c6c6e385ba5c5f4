"""Running a study: on the local cores, on a local Dask cluster (``workers``), or on a
cluster (``scheduler``); ``docs/studies.md`` says how each divides the cores.

A chunk is one task (:func:`~equilibrist.study.compute.chunk_task`), written to the parts
folder as it arrives. A worker that dies has its tasks run again elsewhere; since every
random draw comes from the study's seed and the point's index, the rows are the same. The
driver builds the compiled core first, so a local cluster's workers never compile.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, Any

from equilibrist.study.compute import chunk_task, evaluate_chunk
from equilibrist.study.record import Study, StudyError
from equilibrist.study.store import Store, check_out, require_pyarrow

if TYPE_CHECKING:  # Dask and tqdm are imported when a study runs
    # A distributed.Client is Any where its methods are called: close() and cancel() are
    # unannotated (untyped calls under --strict).
    from distributed import Client
    from tqdm import tqdm

ChunkCallback = Callable[[int, int], None]


@dataclass(frozen=True)
class StudyRun:
    """What :func:`run_study` did (the table is in ``out``)."""

    out: Path
    points: int
    runs: int
    chunks: int
    computed_chunks: int
    resumed_chunks: int
    failed_points: int
    elapsed: float
    where: str

    def to_dict(self) -> dict[str, object]:
        return {
            "out": str(self.out), "points": self.points, "runs": self.runs,
            "chunks": self.chunks, "computed_chunks": self.computed_chunks,
            "resumed_chunks": self.resumed_chunks, "failed_points": self.failed_points,
            "elapsed": self.elapsed,
            "runs_per_second": (self.runs * self.computed_chunks / max(self.chunks, 1)) / self.elapsed
            if self.elapsed > 0 else None,
            "where": self.where,
        }


def default_chunk_size(study: Study) -> int:
    """Points per chunk: about 20,000 runs per task, and at least 4 tasks per core-ish."""
    by_runs = max(1, 20_000 // study.runs)
    by_tasks = max(1, study.n_points // 16)
    return max(1, min(by_runs, by_tasks))


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def _warm(study: Study) -> None:
    """Compile (or load) the point's core in this process, so workers find it on disk."""
    from dataclasses import replace

    from equilibrist.study.compute import evaluate_point

    evaluate_point(replace(study, runs=1, batch_size=1, roa={}), 0, threads=1)


def run_study(
    study: Study,
    out: str | Path,
    *,
    resume: bool = False,
    workers: int | None = None,
    scheduler: str | None = None,
    threads: int | None = None,
    chunk_size: int | None = None,
    progress: bool = False,
    on_chunk: ChunkCallback | None = None,
    client: Client | None = None,
    force: bool = False,
) -> StudyRun:
    """Run *study* and write its table to *out* (Parquet).

    *resume* continues from ``<out>.parts`` (only the missing chunks are computed).
    *threads* is the threads per batch (default: all cores locally, ``cores // workers``
    on a local cluster, 1 on a cluster); *client* is a Dask client to use instead of
    *scheduler*; *on_chunk(chunk, done)* is called after each chunk is written; *force*
    replaces an *out* that is not a study table (the user's file, refused without it).
    A ``KeyboardInterrupt`` stops at once; the chunks written stay for ``resume=True``.
    """
    require_pyarrow()
    out = Path(out)
    if out.suffix != ".parquet":
        raise StudyError(f"--out {out}: a study table is a .parquet file")
    if workers is not None and scheduler is not None:
        raise StudyError("give --workers (a local cluster) or --scheduler (an existing one), not both")
    if workers is not None and workers < 1:
        raise StudyError(f"--workers {workers}: expected a whole number >= 1")
    if workers is not None and workers > _cores():
        raise StudyError(f"--workers {workers}: this machine has {_cores()} cores, so a local "
                         f"cluster takes at most {_cores()} workers (more would only compete "
                         "for them; use --scheduler for a larger cluster)")
    if scheduler is not None:
        _check_address(scheduler)
    if threads is not None and threads < 1:
        raise StudyError(f"--threads {threads}: expected a whole number >= 1")
    if not out.parent.is_dir():
        raise StudyError(f"--out {out}: the folder {out.parent} does not exist")
    size = chunk_size or default_chunk_size(study)
    if size < 1:
        raise StudyError(f"--chunk-size {size}: expected a whole number >= 1")
    check_out(out, force=force, resume=resume)
    store = Store(study, out, size)
    if resume and not store.dir.exists() and out.exists():
        from equilibrist.study.store import read_study

        _, done = read_study(out)
        if done.to_json() == study.to_json():
            return StudyRun(out, study.n_points, study.total_runs, store.n_chunks, 0,
                            store.n_chunks, _failed(out), 0.0, "already complete")
    fresh = not store.dir.exists()
    todo = store.open(resume=resume)
    began = time.perf_counter()
    bar = _bar(study.n_points, progress)
    if bar is not None:
        done_points = study.n_points - sum(_chunk_points(study, size, c) for c in todo)
        bar.update(done_points)
    written = [store.n_chunks - len(todo)]

    def finished(chunk: int, rows: list[dict[str, object]]) -> None:
        store.write(chunk, rows)
        written[0] += 1
        if bar is not None:
            bar.update(len(rows))
        if on_chunk is not None:
            on_chunk(chunk, written[0])

    try:
        if workers is None and scheduler is None and client is None:
            where = f"local, {threads or _cores()} threads"
            for chunk in todo:
                finished(chunk, evaluate_chunk(study, chunk, size, threads=threads))
        elif client is not None:
            where = "cluster"
            _run_on(client, study, store, todo, threads or 1, finished)
        elif scheduler is not None:
            where = f"cluster at {scheduler}"
            with _connect(scheduler) as cl:
                _run_on(cl, study, store, todo, threads or 1, finished)
        else:
            assert workers is not None
            per = threads or max(1, _cores() // workers)
            where = f"local cluster, {workers} workers x {per} threads"
            if todo:
                _warm(study)
                with _local_cluster(workers) as cl:
                    _run_on(cl, study, store, todo, per, finished)
    except BaseException:
        if fresh and written[0] == 0:
            # Nothing finished: leave nothing behind.
            store.remove()
        raise
    finally:
        if bar is not None:
            bar.close()
    path = store.assemble()
    return StudyRun(path, study.n_points, study.total_runs, store.n_chunks, len(todo),
                    store.n_chunks - len(todo), _failed(path), time.perf_counter() - began, where)


def _check_address(address: str) -> None:
    """Refuse a scheduler address Dask cannot connect to, before any work."""
    _distributed()  # installed, or one line saying how to install it
    from distributed.comm.addressing import parse_address, parse_host_port
    from distributed.comm.registry import get_backend

    try:
        scheme, location = parse_address(address)
        get_backend(scheme)
        if scheme in ("tcp", "tls"):
            host, _ = parse_host_port(location, 8786)
            if not host or any(c.isspace() for c in host):
                raise ValueError(f"no host name in {address!r}")
    except (ValueError, TypeError) as exc:
        raise StudyError(f"--scheduler {address}: not the address of a Dask scheduler, "
                         f"expected tcp://HOST:PORT ({exc})") from None


def _chunk_points(study: Study, size: int, chunk: int) -> int:
    return min(size, study.n_points - chunk * size)


def _failed(path: Path) -> int:
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    status = pq.read_table(path, columns=["status"]).column("status")
    return int(pc.sum(pc.not_equal(status, "ok")).as_py() or 0)


def _bar(total: int, show: bool) -> tqdm | None:
    if not show:
        return None
    from tqdm import tqdm

    return tqdm(total=total, unit="point", desc="study", dynamic_ncols=True, leave=False)


def _distributed() -> ModuleType:
    try:
        import distributed
    except ImportError:
        raise StudyError("--workers and --scheduler need Dask: pip install 'equilibrist[cluster]'") from None
    return distributed


@contextlib.contextmanager
def _local_cluster(workers: int) -> Iterator[Any]:  # the distributed.Client
    import logging

    distributed = _distributed()
    cluster = distributed.LocalCluster(
        n_workers=workers, threads_per_worker=1, processes=True,
        # ":0": its HTTP endpoint on a free port, never clashing with another cluster.
        dashboard_address=":0", silence_logs=logging.ERROR,
    )
    client = distributed.Client(cluster)
    try:
        yield client
    finally:
        # Short timeouts: after Ctrl-C the workers are stopped, not waited for.
        try:
            client.close(timeout=5)
        finally:
            cluster.close(timeout=10)


@contextlib.contextmanager
def _connect(address: str) -> Iterator[Any]:  # the distributed.Client
    distributed = _distributed()
    try:
        client = distributed.Client(address, timeout="20s")
    except (OSError, TimeoutError, ValueError) as exc:
        raise StudyError(f"--scheduler {address}: cannot connect ({exc})") from None
    try:
        yield client
    finally:
        client.close()


def _run_on(client: Any, study: Study, store: Store, todo: list[int], threads: int,
            finished: Callable[[int, list[dict[str, object]]], None]) -> None:
    distributed = _distributed()
    if not todo:
        return
    text = study.to_json()
    tag = study.digest[:16]
    futures = [
        client.submit(chunk_task, text, c, store.chunk_size, threads,
                      key=f"equilibrist-study-{tag}-{store.chunk_size}-{c}", pure=False,
                      retries=2)
        for c in todo
    ]
    chunk_of = {f.key: c for f, c in zip(futures, todo, strict=True)}
    try:
        for future in distributed.as_completed(futures):
            rows = future.result()
            finished(chunk_of[future.key], rows)
            future.release()
    finally:
        client.cancel(futures)
