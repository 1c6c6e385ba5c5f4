"""The main job: a tour of the catalogue (what ``equilibrist demo`` runs).

For each system with an input: its default controller (digital LQG at the rig's rate) on a
realistic run of the nonlinear plant (noise, saturation, a reference step, a push) and the
ideal loop beside it; for the gyroscope, which has no input, a steady and a nutating
precession. Each system gets plots, an animation and a section of the report's
``index.html``; the rigs of ``ROA_SYSTEMS`` their LQR's region of attraction, the cart-pole
a Monte-Carlo fan. The scenarios are part of each rig's definition
(``SystemSpec.scenario``). One system's tour is in :mod:`equilibrist.apps.tour_systems`;
this module runs the whole tour and writes the report.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable, Collection, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, TypedDict

from equilibrist.apps.tour_common import (
    SEED,
    SUMMARY_HEADER,
    Outcome,
    _label,
    _say,
    _slug,
)
from equilibrist.apps.tour_systems import (
    tour_controlled,
    tour_gyroscope,
)
from equilibrist.atomic import check_output, make_folder, write_text
from equilibrist.viz.output import VizError
from equilibrist.viz.report import write_index

if TYPE_CHECKING:
    from concurrent.futures import ProcessPoolExecutor

    from equilibrist.numeric.system import System

# -- the whole tour ------------------------------------------------------------


def tour_one(
    system: System,
    folder: Path,
    *,
    size: tuple[int, int] = (400, 300),
    fps: float = 15.0,
    max_frames: int = 150,
    extras: Sequence[str] = ("cartpole",),
    progress: bool = False,
    at: Mapping[str, float] | None = None,
) -> Outcome:
    """The tour of one system: :func:`tour_controlled` (designed at *at*, the states of
    another operating point, when given), or :func:`tour_gyroscope` for a system without
    input."""
    if system.n_inputs:
        return tour_controlled(system, folder, size=size, fps=fps, max_frames=max_frames,
                               extras=system.name in extras, progress=progress, at=at)
    if at:
        raise VizError(f"{system.key} has no input: there is no design to make at another "
                       "operating point")
    return tour_gyroscope(system, folder, size=size, fps=fps, max_frames=max_frames,
                          progress=progress)


class _TourOptions(TypedDict):
    """The options of :func:`tour_one` that the tour gives every system."""

    size: tuple[int, int]
    fps: float
    max_frames: int
    extras: tuple[str, ...]
    at: dict[str, float] | None


def _tour_in_worker(system: System, folder: str, options: _TourOptions) -> Outcome:
    """:func:`tour_one` in a worker process (the system the user named, pickled as its
    definition's content; *options* those of :func:`tour_one`, the operating point ``at``
    among them)."""
    return tour_one(system, Path(folder), progress=False, **options)


def run_tour(
    systems: Sequence[System],
    folder: str | Path,
    *,
    size: tuple[int, int] = (400, 300),
    fps: float = 15.0,
    max_frames: int = 150,
    extras: Sequence[str] = ("cartpole",),
    jobs: int = 1,
    progress: bool = False,
    log: Callable[[str], None] | None = None,
    at: Mapping[str, float] | None = None,
    force: bool = False,
    then: Callable[[Path], object] | None = None,
    then_writes: Sequence[str] = (),
) -> list[Outcome]:
    """Run the demo on *systems* and write the report folder *folder* (``index.html`` and
    one sub-folder per system; an existing folder is replaced only as
    :func:`check_report_folder` allows, whatever it holds with *force*); the outcomes in the
    order of *systems*.

    *extras* names the systems that also get a region of attraction and a Monte-Carlo fan;
    *jobs* systems are toured at once, each in its own process. *at* (``{state: value}``)
    designs at the equilibrium with these states and runs each scenario about it. *then* is
    called with the staged folder before it is put in place (the demo adds its study
    there), and *then_writes* names what it adds at the top of the folder.
    """
    target = Path(folder)
    writes = {"index.html", *(_slug(_label(s)) for s in systems), *then_writes}
    check_report_folder(target, writes=writes, force=force)
    # The report is built in a staging folder beside the target and moved
    # into place whole: a failure or Ctrl-C part-way leaves nothing behind.
    staged = make_folder(target.parent, prefix=f".{target.name}.partial-")
    try:
        outcomes = _tour_into(systems, staged, size=size, fps=fps, max_frames=max_frames,
                              extras=extras, jobs=jobs, progress=progress, log=log, at=at)
        if then is not None:
            then(staged)
        write_manifest(staged)
        _put_in_place(staged, target)
    finally:
        shutil.rmtree(staged, ignore_errors=True)
    return outcomes


# A report folder holds this file, the manifest of what was written: a folder without it
# is the user's, never replaced without force.
REPORT_MARKER = ".equilibrist-report"


def _files(folder: Path) -> list[str]:
    """Every file under *folder* (links as files), as sorted POSIX paths relative to it."""
    out = []
    for root, dirs, names in os.walk(folder):
        here = Path(root)
        out += [(here / n).relative_to(folder).as_posix()
                for n in [*names, *(d for d in dirs if (here / d).is_symlink())]]
    return sorted(n for n in out if n != REPORT_MARKER)


def write_manifest(folder: Path) -> Path:
    """The marker of a report folder: JSON naming its maker and listing every file written."""
    import json

    from equilibrist import __version__

    doc = {"written_by": "equilibrist demo", "version": __version__, "files": _files(folder)}
    return write_text(folder / REPORT_MARKER, json.dumps(doc, indent=1) + "\n")


def report_files(folder: Path) -> set[str] | None:
    """The files the marker of *folder* lists; an empty set for a report of an earlier version
    (a marker without a list, or no marker and an ``index.html`` made by the demo); None for
    a folder equilibrist did not write."""
    import json

    marker = folder / REPORT_MARKER
    if marker.is_file():
        try:
            doc = json.loads(marker.read_text(errors="replace"))
        except (OSError, ValueError):
            doc = None
        listed = doc.get("files") if isinstance(doc, dict) else None
        if isinstance(listed, list) and all(isinstance(n, str) for n in listed):
            return set(listed)
        return set()
    index = folder / "index.html"
    try:
        made = index.is_file() and "Made by 'equilibrist demo'" in index.read_text(errors="replace")
    except OSError:
        made = False
    return set() if made else None


def _some(names: Sequence[str], limit: int = 4) -> str:
    shown = ", ".join(names[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")


def _them(names: Sequence[str]) -> str:
    return "it" if len(names) == 1 else "them"


def check_report_folder(target: Path, *, writes: Collection[str] | None = None,
                        force: bool = False) -> None:
    """Refuse (:class:`VizError`, one line) a report folder whose replacement would lose
    something, unless *force*: a folder equilibrist did not write (no marker) that is not
    empty, files in a report that its marker does not list (the user's), or entries of an
    earlier report that this one does not write (*writes*: the names at the top of the new
    report). Its parent must exist, and a file of its name is never replaced."""
    check_output(target, what="the report folder")
    if target.exists() and not target.is_dir():
        raise VizError(f"the report folder {str(target)!r} is a file: name a folder")
    if force or not target.is_dir():
        return
    present = sorted(p.name for p in target.iterdir() if p.name != REPORT_MARKER)
    listed = report_files(target)
    redo = "give --force to replace it, or name another folder"
    if listed is None:
        if present:
            raise VizError(f"the report folder {str(target)!r} holds {_some(present)}, which "
                           f"equilibrist did not write: replacing it would lose {_them(present)}; "
                           f"{redo}")
        return
    foreign = [n for n in _files(target) if n not in listed] if listed else []
    if foreign:
        raise VizError(f"the report folder {str(target)!r} holds {_some(foreign)} beside the "
                       f"report, which equilibrist did not write: replacing it would lose "
                       f"{_them(foreign)}; {redo}")
    lost = [n for n in present if writes is not None and n not in writes]
    if lost:
        raise VizError(f"the report folder {str(target)!r} holds an earlier report with "
                       f"{_some(lost)}, which this one ({_some(sorted(writes or ()))}) does "
                       f"not write: replacing it would lose {_them(lost)}; {redo}")


def _put_in_place(staged: Path, target: Path) -> None:
    """Replace *target* (an earlier report, or nothing) by *staged*."""
    old = None
    if target.exists():
        old = target.with_name(f".{target.name}.old-{os.getpid()}")
        target.rename(old)
    try:
        staged.rename(target)
    except BaseException:
        if old is not None:
            old.rename(target)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def _tour_into(
    systems: Sequence[System],
    folder: Path,
    *,
    size: tuple[int, int],
    fps: float,
    max_frames: int,
    extras: Sequence[str],
    jobs: int,
    progress: bool,
    log: Callable[[str], None] | None,
    at: Mapping[str, float] | None = None,
) -> list[Outcome]:
    from tqdm.auto import tqdm

    options: _TourOptions = {"size": size, "fps": fps, "max_frames": max_frames,
                             "extras": tuple(extras), "at": dict(at) if at else None}
    bar = tqdm(total=len(systems), desc="demo", unit="system", disable=not progress, leave=False)
    done: dict[int, Outcome] = {}

    def finished(k: int, out: Outcome) -> None:
        done[k] = out
        bar.update()
        _say(log, out.progress_line())

    with bar:
        if jobs <= 1 or len(systems) <= 1:
            for k, system in enumerate(systems):
                bar.set_postfix_str(system.key)
                finished(k, tour_one(system, folder, progress=progress, **options))
        else:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor, as_completed

            # Fresh interpreters (not forks): the core's OpenMP threads and
            # matplotlib's state are not safe to fork.
            from equilibrist.interrupt import quiet_resource_tracker

            context = multiprocessing.get_context("spawn")
            quiet_resource_tracker()  # Ctrl-C stops the workers at once: no leak report after
            pool = ProcessPoolExecutor(max_workers=jobs, mp_context=context)
            try:
                futures = {
                    pool.submit(_tour_in_worker, system, str(folder), options): k
                    for k, system in enumerate(systems)
                }
                for future in as_completed(futures):
                    finished(futures[future], future.result())
            except BaseException:
                # Ctrl-C (or a failure) stops the workers now: waiting for the systems they
                # are compiling would keep the command alive for tens of seconds.
                _stop_workers(pool)
                raise
            pool.shutdown()
    outcomes = [done[k] for k in range(len(systems))]
    write_report(folder, outcomes)
    return outcomes


def _stop_workers(pool: ProcessPoolExecutor) -> None:
    """End a process pool's workers at once, their queued work dropped."""
    workers = list((getattr(pool, "_processes", None) or {}).values())  # the pool's own map
    for proc in workers:
        if proc.is_alive():
            proc.terminate()
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in workers:
        proc.join(timeout=2)


def write_report(folder: Path, outcomes: Sequence[Outcome]) -> Path:
    """The ``index.html`` of a tour."""
    from equilibrist import __version__

    intro = [
        "Each system of the catalogue was given its default controller: a digital LQG (a Kalman "
        "filter that estimates the full state from the rig's noisy sensors, and the LQR gain on "
        "that estimate) running at the rig's control rate, with the actuator's limits. Each run "
        "is simulated on the nonlinear equations of motion, with sensor and process noise, "
        "starts off balance, follows a step of its reference where it has one, and is pushed "
        "halfway through. The gyroscope has no input: it shows a steady and a nutating precession.",
        "In the time responses, solid lines are the true states, dashed lines what the "
        "controller believed (its estimate), grey dots what the sensors read. Angles are in "
        "degrees. 'Settling after push' is the time the balance (the states whose range "
        "decides a fall) takes to come back for good within the larger of the noise it showed "
        "in the second before the push and a tenth of the excursion the push caused. 'Final "
        "error' is where the tracked outputs and the balance end relative to their target "
        "(the reference, else the operating point), averaged over the last second. 'Peak "
        "input' is the largest input applied, as a share of its limit. Every animation is "
        "drawn from the simulated states alone, to scale.",
    ]
    return write_index(
        folder,
        title="equilibrist: a tour of the catalogue",
        intro=intro,
        summary_header=SUMMARY_HEADER,
        summary_rows=[list(o.row) for o in outcomes],
        sections=[o.section for o in outcomes],
        footer=f"Made by 'equilibrist demo' (equilibrist {__version__}); noise seed {SEED}. "
               "Every run is saved beside its plots and can be replotted with 'equilibrist plot' "
               "or re-animated with 'equilibrist animate'.",
    )


__all__ = [
    "REPORT_MARKER",
    "check_report_folder",
    "report_files",
    "run_tour",
    "tour_one",
    "write_manifest",
    "write_report",
]
