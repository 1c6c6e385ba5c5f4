"""The runs of a batch with a Python controller: in worker processes (the settings
pickled to them), or one after the other in this process with ``workers=1``."""

from __future__ import annotations

import multiprocessing
import os
import pickle
import time
from collections.abc import Sequence

import numpy as np

from equilibrist.control.controller import python_controller_name
from equilibrist.control.python_controller import PythonController
from equilibrist.errors import SimulationError
from equilibrist.sim import layout, setup_data
from equilibrist.sim.batch_result import BatchResult, _batch_result
from equilibrist.sim.kernel import Kernel
from equilibrist.sim.noise import describe_seed, generator_state
from equilibrist.sim.result import SimResult
from equilibrist.sim.run import _run_python
from equilibrist.tasks import balance_box, in_box


def _python_batch(setup: setup_data.Setup, x0s: np.ndarray, pmat: np.ndarray,
                  seqs: list[np.random.SeedSequence | None], record: bool,
                  progress: bool, workers: int | None) -> BatchResult:
    """Runs of a Python controller: in worker processes, or here with ``workers=1``."""
    runs = x0s.shape[0]
    count = (os.cpu_count() or 1) if workers is None else max(1, int(workers))
    count = min(count, runs)
    t0 = time.perf_counter()
    if count <= 1:
        parts = [_python_runs(setup, x0s, pmat, seqs, record)]
    else:
        payload = _portable(setup)
        chunks = np.array_split(np.arange(runs), count)
        from equilibrist.interrupt import quiet_resource_tracker

        ctx = multiprocessing.get_context("spawn")
        quiet_resource_tracker()  # an interrupt terminates the pool: no leak report after
        pool = ctx.Pool(count)
        try:
            pending = [pool.apply_async(_python_worker, (payload, x0s[c], pmat[c],
                                                         [seqs[i] for i in c], record))
                       for c in chunks]
            parts = []
            for job in pending:
                while not job.ready():  # short waits: Ctrl-C is seen at once
                    job.wait(0.1)
                parts.append(job.get())
        except BaseException:
            pool.terminate()  # the workers' runs are not waited for
            raise
        else:
            pool.close()
        finally:
            pool.join()
    elapsed = time.perf_counter() - t0
    statuses, accs, fell_xs, x_ends, recs = (np.concatenate(a) for a in zip(*parts, strict=True))
    setup0 = setup_data.Setup(**{**setup.__dict__, "estimates": False})
    seeds = [None if s is None else describe_seed(s) for s in seqs]
    return _batch_result(setup0, x0s, pmat, seeds, statuses, accs, fell_xs, x_ends,
                         recs if record else None, elapsed)


def _portable(setup: setup_data.Setup) -> bytes:
    """*setup* pickled for a worker process (the system as its definition's content and its
    parameters: :meth:`~equilibrist.numeric.system.System.__reduce__`)."""
    try:
        return pickle.dumps(dict(setup.__dict__))
    except (pickle.PicklingError, TypeError, AttributeError) as exc:
        name = (python_controller_name(setup.controller)
                if isinstance(setup.controller, PythonController) else type(setup.controller).__name__)
        raise SimulationError(
            f"the Python controller {name} cannot be sent to worker processes ({exc}): define "
            "it at module level (not in a function, not a lambda), or run the batch in this "
            "process with workers=1"
        ) from exc


def _python_worker(payload: bytes, x0s: np.ndarray, pmat: np.ndarray,
                   seqs: list[np.random.SeedSequence | None], record: bool
                   ) -> tuple[np.ndarray, ...]:
    setup = setup_data.Setup(**pickle.loads(payload))
    return _python_runs(setup, x0s, pmat, seqs, record)


def _python_runs(setup: setup_data.Setup, x0s: np.ndarray, pmat: np.ndarray,
                 seqs: list[np.random.SeedSequence | None], record: bool
                 ) -> tuple[np.ndarray, ...]:
    """Runs of a Python controller one after the other: the batch's per-run arrays."""
    sysm = setup.system
    names = sysm.spec.parameter_names
    runs = x0s.shape[0]
    n = sysm.n_states
    st = layout.STATUS
    statuses = np.zeros((runs, len(st)), dtype=np.int64)
    accs = np.zeros((runs, setup.acc_len))
    acc = layout.ACC.slices(**setup.sizes)
    cols = layout.RECORD.slices(**setup.sizes)
    fell_xs = np.zeros((runs, n))
    x_ends = np.zeros((runs, n))
    recs = np.empty((runs, setup.n_rows if record else 0, setup.record_width))
    box = balance_box(sysm)
    for i in range(runs):
        sysi = sysm.with_params(**dict(zip(names, pmat[i].tolist(), strict=True)))
        s = setup_data.Setup(**{**setup.__dict__, "system": sysi, "x0": x0s[i]})
        seq = seqs[i]
        rng = generator_state(seq) if seq is not None else np.zeros(4, dtype=np.uint64)
        res = _run_python(s, Kernel(sysi), rng, seq, progress=False)
        k = res.n_rows
        statuses[i] = st.pack(np.int64, rows=k, fell=int(res.fell),
                              fell_code=_code(res, sysm.state_names),
                              fell_step=0 if res.fell_at is None else round(res.fell_at / setup.h))
        accs[i, acc["peak_u"]] = np.abs(res.commanded).max(axis=0)
        accs[i, acc["peak_u_app"]] = np.abs(res.applied).max(axis=0)
        accs[i, acc["sum_u2"]] = (res.applied**2).sum(axis=0)
        accs[i, acc["n_sat"]] = np.count_nonzero(np.any(res.saturated != res.commanded, axis=1))
        accs[i, acc["peak_dx"]] = np.abs(res.states - res.x_op).max(axis=0)
        outside = np.nonzero(~in_box(res.states, res.x_op, box))[0]
        accs[i, acc["last_out"]] = float(outside[-1] + 1) if outside.size else 0.0
        if res.fell_x is not None:
            fell_xs[i] = res.fell_x
        x_ends[i] = res.final_state
        if record:
            recs[i, :k, cols["x"]] = res.states
            recs[i, :k, cols["x_hat"]] = np.nan if res.estimates is None else res.estimates
            recs[i, :k, cols["y"]] = res.measurements
            recs[i, :k, cols["u_cmd"]] = res.commanded
            recs[i, :k, cols["u_sat"]] = res.saturated
            recs[i, :k, cols["u_app"]] = res.applied
    return statuses, accs, fell_xs, x_ends, recs


def _code(res: SimResult, names: Sequence[str]) -> int:
    if not res.fell:
        return -1
    if res.fell_state in names:
        return list(names).index(res.fell_state)  # type: ignore[arg-type]
    return {"not finite": -2, "integrator failed": -3}.get(res.fell_state or "", -1)
