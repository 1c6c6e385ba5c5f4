"""Studies on a real Dask cluster (two worker processes): the same bytes as locally.

These start ``distributed.LocalCluster`` processes and a ``sweep`` process,
so they are marked slow; they still run in CI (two cores are enough).
"""

from __future__ import annotations

import json
import os
import signal

import pytest
from tests.support.signals import signal_while_working, start_held, when_held

from equilibrist.cli.main import main
from equilibrist.study import make_study, run_study

ARGS = ["--vary", "m_p=0.1:0.4:3", "--vary", "rate=100,200", "--runs", "8", "--duration", "1",
        "--x0", "theta=-0.25:0.25", "--spread", "l=0.05", "--seed", "5", "--no-progress"]


def _study():
    return make_study("cartpole", vary=[("m_p", "0.1:0.4:3"), ("rate", "100,200")], runs=8,
                      duration=1.0, x0={"theta": "-0.25:0.25"}, spread={"l": 0.05}, seed=5)


@pytest.fixture(scope="module")
def local_table(tmp_path_factory):
    out = tmp_path_factory.mktemp("local") / "local.parquet"
    assert main(["sweep", "cartpole", *ARGS, "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def cluster():
    import logging

    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0", silence_logs=logging.ERROR) as lc, Client(lc) as client:
        yield client


@pytest.mark.slow
def test_a_local_cluster_started_by_the_command_gives_the_local_bytes(tmp_path, local_table):
    out = tmp_path / "cluster.parquet"
    assert main(["sweep", "cartpole", *ARGS, "--workers", "2", "--chunk-size", "2",
                 "--out", str(out)]) == 0
    assert out.read_bytes() == local_table.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cluster.parquet"]


@pytest.mark.slow
def test_a_worker_killed_mid_study_changes_nothing(tmp_path, local_table, cluster):
    killed: list[str] = []

    async def die():  # a coroutine: run() need not wait for an answer that never comes
        os._exit(1)

    def kill_a_busy_worker(chunk, done):
        if killed:
            return
        busy = [w for w, keys in cluster.processing().items() if keys]
        if busy:
            killed.append(busy[0])
            cluster.run(die, workers=[busy[0]], wait=False)

    out = tmp_path / "survived.parquet"
    done = run_study(_study(), out, client=cluster, chunk_size=1, on_chunk=kill_a_busy_worker)
    assert killed, "no worker was busy after the first chunk"
    assert done.computed_chunks == 6
    assert out.read_bytes() == local_table.read_bytes()


# Twelve chunks (one value of m_p each); the interrupted command is held in its third
# (tests.support.signals.start_held), so the interrupt comes after exactly two chunks are
# written and while it works, whatever the machine's speed: the chunks can be small.
LONG = ["--vary", "m_p=0.1:0.4:12", "--runs", "10", "--duration", "1", "--x0",
        "theta=-0.25:0.25", "--metrics", "basic", "--seed", "9", "--no-progress"]


@pytest.mark.slow
def test_an_interrupted_study_resumes_to_the_same_bytes(tmp_path, capsys):
    whole = tmp_path / "whole.parquet"
    assert main(["sweep", "cartpole", *LONG, "--out", str(whole)]) == 0
    out = tmp_path / "resumed.parquet"
    parts = tmp_path / "resumed.parquet.parts"
    proc = start_held(["sweep", "cartpole", *LONG, "--chunk-size", "1", "--out", str(out)],
                      tmp_path, "equilibrist.study.runner:evaluate_chunk", after=2)
    code, _, err, _ = signal_while_working(proc, signal.SIGINT, when_held)
    assert code == 130, err.decode()
    assert "--resume" in err.decode()
    assert not out.exists()
    done_before = {int(p.stem.split("-")[1]) for p in parts.glob("chunk-*.parquet")}
    assert done_before == {0, 1}
    assert not list(parts.glob(".*.tmp"))
    capsys.readouterr()
    assert main(["sweep", "cartpole", *LONG, "--chunk-size", "1", "--out", str(out),
                 "--resume", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    # Nothing already done is computed again.
    assert summary["resumed_chunks"] == len(done_before)
    assert summary["computed_chunks"] == 12 - len(done_before)
    assert out.read_bytes() == whole.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["resumed.parquet", "whole.parquet"]
