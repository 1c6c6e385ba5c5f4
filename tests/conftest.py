"""Shared fixtures: the registry's specs, and a headless matplotlib; the order of the run."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")
# One BLAS thread a process (set before numpy loads OpenBLAS here, and inherited by the
# workers and every command a test starts): the suite already keeps both cores busy with
# its two workers, and OpenBLAS's own threads on top of them wait on each other. A fit's
# Cholesky of 700 unknowns took 4 times as long with 2 threads as with 1 on a loaded
# 2-core machine; identification's tests 90 s against 58 s on 2 workers. The recorded
# digests stay those recorded under OpenBLAS's default threads (tests/control/test_bits_designs.py,
# tests/sim/test_sim_bits.py, tests/sim/test_bits_cpu.py pass either way).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

#: The modules that take longest (seconds of CPU, a few to fifty each), longest first.
#: They run first, each whole on one worker, so that neither worker is left with a long
#: module at the end while the other waits, and no module-scoped fixture (an export's
#: build, the playground's server and browser) is set up on both workers. The order is
#: each module's time alone, one process, at a load of 2 to 4 (2026-12-08): the first
#: nineteen 48 to 12 s (the tutorials' kernels, the playground's server with Chromium, the
#: examples and the docs site among them: left out, they ran last), the next four 4 to 9 s,
#: the rest as measured before.
LONGEST_FIRST = (
    "test_ident_coverage.py", "test_tutorials.py", "test_web_protocol.py", "test_web_browser.py",
    "test_bits_cpu.py", "test_web_controllers.py", "test_viz_systems.py", "test_viz_results.py",
    "test_run.py", "test_web_tvlqr.py", "test_tvlqr_lqg.py", "test_hostile_cli.py",
    "test_hil.py", "test_examples.py", "test_mpc_export.py", "test_hostile_trajectories.py",
    "test_export_size.py", "test_hostile.py", "test_docs_site.py", "test_run_mpc.py",
    "test_roa_certify.py", "test_swingup.py", "test_tvlqr.py",
    "test_sim_systems.py", "test_sim_batch.py", "test_models_real.py", "test_user_systems.py",
    "test_import_cli.py", "test_study_cluster.py", "test_export_sim.py", "test_packaged_models.py",
    "test_study.py", "test_mpc.py", "test_sim_controllers.py", "test_swingup_export.py",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Whole modules reordered, longest first (each module's tests keep their order)."""
    rank = {name: k for k, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable


@pytest.hookimpl(tryfirst=True)
def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> object | None:
    """Under ``-n`` with the default distribution: whole modules to a worker (``loadfile``)
    in the order of the collection above, instead of chunks of tests."""
    if config.getvalue("dist") != "load":
        return None  # a distribution asked for on the command line is kept
    from xdist.scheduler import LoadFileScheduling

    config.option.loadscopereorder = False  # keep the order above, not by count of tests
    return LoadFileScheduling(config, log)


@pytest.fixture(scope="session", autouse=True)
def _sb3_logs_in_the_run(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """Stable-Baselines3's default logger makes a folder for every model trained (in /tmp, or
    ``SB3_LOGDIR``): the run's temporary folder here, gone with the run's others."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("SB3_LOGDIR", str(tmp_path_factory.mktemp("sb3")))
        yield


@pytest.fixture(scope="session")
def cart_plan(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The cart-pole's swing-up planned by trajopt (4 s, 60 intervals, within 0.9 m of the
    track's centre: a margin for the tracking error), saved as a trajectory file: the plan
    the time-varying LQR's tests track (made once per worker)."""
    from equilibrist import get_system
    from equilibrist.control.trajopt import plan
    from equilibrist.tasks import get_task

    cart = get_system("cartpole")
    task = get_task(cart, "swingup")
    traj = plan(cart, start=task.start, goal=task.x_op, knots=60, duration=4.0,
                bounds={"x": (-0.9, 0.9)})
    assert traj.converged
    return traj.save(tmp_path_factory.mktemp("plan") / "up.npz")
