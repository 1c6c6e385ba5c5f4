"""The constrained MPC's export: DAQP's C sources and the generated driver
(:func:`~equilibrist.native.mpc_library.library_files`, the library the simulated
:class:`~equilibrist.control.mpc_runtime.MPCRuntime` runs, compiled; its C interface is
in docs/mpc.md), a recorded noisy closed-loop run of the simulated controller as test
vectors, ``make check`` (each command within :func:`command_tolerance` of the simulated
one's, the filter's state within :data:`Z_TOLERANCE`, relative; in single precision
:data:`FLOAT_TOLERANCE` of the widest input range and :data:`Z_TOLERANCE_FLOAT`),
``make size`` and the hardware-in-the-loop files (docs/export.md).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.errors import ExportError
from equilibrist.export.report import ControllerExport, Described, Steps
from equilibrist.native.make_check import check_files
from equilibrist.native.mpc_library import (
    check_program,
    library_files,
    mpc_adapter,
    precision_flags,
)

if TYPE_CHECKING:
    from equilibrist.control.design_record import Design
    from equilibrist.control.mpc import MPC
    from equilibrist.control.mpc_runtime import MPCRuntime
    from equilibrist.native.firmware import Adapter
    from equilibrist.numeric.system import System


#: How far the default recorded run's first LQR move reaches beyond the input limit.
OVERDRIVE = 1.5


def _design_of(ctrl: MPC) -> Design:
    """The design *ctrl* was made from (its system, noise and scales); refused without one."""
    if ctrl.design is None:
        raise ExportError("the MPC carries no design: the export records its run on the "
                          "design's system (build it with mpc(system, design=...))")
    return ctrl.design

def default_start(ctrl: MPC, system: System) -> dict[str, float]:
    """The recorded run's default start: one that asks for more than the input allows.

    The linear exports' start (each coordinate with a design scale displaced
    by :data:`~equilibrist.export.vectors.START_FRACTION` of it), scaled so
    that the LQR's first move asks :data:`OVERDRIVE` times what the nearest
    input limit allows, but keeping each softly bounded state within half
    of its bound. For the cart-pole: the cart at 0.5 m and the pole at
    0.2 rad; with the Kalman filter in front the command reaches its 200 N
    limit (the full-state MPC's own first move stays at 113 N). Every
    system of the catalogue with an input exports and passes ``make check``
    from it.
    """
    from equilibrist.export.vectors import displaced

    names = ctrl.state_names
    dx = displaced(np.zeros(len(names)), names, system)
    prob = ctrl.problem
    du = -ctrl.K @ dx
    room = np.where(du > 0, prob.u_hi, -prob.u_lo) / np.maximum(np.abs(du), 1e-300)
    factor = OVERDRIVE * float(np.min(room)) if np.any(du != 0) else 1.0
    for j, i in enumerate(prob.soft_index):
        if dx[i] != 0.0:
            bound = prob.soft_hi[j] if dx[i] > 0 else -prob.soft_lo[j]
            factor = min(factor, 0.5 * bound / abs(dx[i]))
    x = ctrl.x_op + factor * dx
    return {k: float(v) for k, v in zip(names, x, strict=True)}


def record(ctrl: MPC, *, x0: Mapping[str, float] | None = None, duration: float = 1.0,
           seed: int = 0) -> dict[str, np.ndarray]:
    """Recorded vectors: a closed-loop run of the simulated MPC with the design's sensor noise.

    ``y`` (measurements), ``u_applied``, and a fresh simulated controller's
    commands ``u``, filter states ``z`` (after each update) and DAQP's
    ``iterations`` (0 where the LQR's move was exact) on them.
    """
    from equilibrist.control.mpc_runtime import MPCRuntime
    from equilibrist.numeric.lookup import system_from_key
    from equilibrist.sim.noise import Noise
    from equilibrist.sim.run import simulate

    design = _design_of(ctrl)
    system = system_from_key(design.system_key, dict(design.params))
    start = default_start(ctrl, system) if x0 is None else dict(x0)
    run = simulate(system, MPCRuntime(ctrl), duration=duration, x0=start,
                   region={}, noise=Noise.from_design(design), seed=seed)
    ys, applied = np.array(run.measurements), np.array(run.applied)
    ref = MPCRuntime(ctrl)
    us, zs, its = [], [], []
    no_r = np.zeros(0)
    for k, (y, ua) in enumerate(zip(ys, applied, strict=True)):
        us.append(ref.output(k / ctrl.rate, y, no_r))
        its.append(ref.last_iterations)
        ref.update(k / ctrl.rate, y, no_r, ua)
        zs.append(ref.z)
    return {"y": ys, "u_applied": applied, "u": np.array(us), "z": np.array(zs),
            "iterations": np.array(its)}


#: Bound of the filter's state in ``make check`` (relative to ``1 + |z|``). In double precision
#: the simulated filter is this C code (the tests find 0); the bound leaves room for a
#: compiler on the device that contracts products into fused multiply-adds.
Z_TOLERANCE = 1e-10
#: The same bound in single precision (float's epsilon is 1.2e-7; the filter's state carries
#: its rounding from sample to sample): the reaction-wheel pendulum's fast wheel reaches 3e-4
#: over half a second, the cart-pole 4e-6.
Z_TOLERANCE_FLOAT = 1e-3
#: ``make check`` in single precision: each command within this fraction of the widest input
#: range of the double controller's (the cart-pole: 400 N of range, 0.04 N).
FLOAT_TOLERANCE = 1e-4
#: Entries of the condensed QP's dense matrices (``H`` and ``A``) at most: the library
#: holds them as text, and the controller builds them whole (8 MB of doubles).
MAX_QP_ENTRIES = 1_000_000


def qp_entries(horizon: int, n_inputs: int, n_soft: int) -> int:
    """Entries of ``H`` and ``A`` of the condensed QP of a horizon (see ``MPCProblem.condensed``)."""
    nz = horizon * (n_inputs + n_soft)
    rows = horizon * (n_inputs + 2 * n_soft)
    return nz * nz + rows * nz


def check_horizon(system: System, horizon: int, option: str = "--horizon") -> None:
    """Refuse, before anything is built, a horizon whose QP exceeds :data:`MAX_QP_ENTRIES`."""
    from equilibrist.control.mpc import soft_bounds

    m = system.n_inputs
    ns = len(soft_bounds(system, np.zeros(system.n_states)))
    if qp_entries(horizon, m, ns) <= MAX_QP_ENTRIES:
        return
    longest = math.isqrt(MAX_QP_ENTRIES // qp_entries(1, m, ns))  # the entries grow as N^2
    raise ExportError(f"{option} {horizon}: the MPC's QP would hold {qp_entries(horizon, m, ns):,} "
                      f"matrix entries; at most {MAX_QP_ENTRIES:,}, a horizon of at most "
                      f"{longest} samples for {system.key}")


def export_mpc(ctrl: MPC, folder: str | Path, *, name: str = "mpc",
               x0: dict[str, float] | None = None, duration: float = 1.0,
               tolerance: float | None = None, seed: int = 0, precision: str = "double") -> Path:
    """Write the MPC's C code, recorded vectors and ``make check`` into *folder*.

    *x0* starts the recorded run (default :func:`default_start`, which
    drives the input into its limits), *seed* its sensor noise;
    *tolerance* bounds the difference of each command to the Python
    controller's [input units] (default :func:`command_tolerance` of *precision*, ``"double"``
    or ``"float"``).
    """
    from equilibrist.export.folder import write_files

    out = Path(folder)
    write_files(out, mpc_files(ctrl, name=name, x0=x0, duration=duration, tolerance=tolerance,
                               seed=seed, precision=precision))
    return out


def mpc_files(ctrl: MPC, *, name: str = "mpc", x0: dict[str, float] | None = None,
              duration: float = 1.0, tolerance: float | None = None, seed: int = 0,
              precision: str = "double",
              vectors: Mapping[str, np.ndarray] | None = None) -> dict[str, str]:
    """Every file of the MPC's export, relative path -> text (DAQP's sources under ``daqp/``,
    the library, the recorded vectors, the test program and the Makefile).

    *tolerance* defaults to :func:`command_tolerance` of *precision*; *vectors* (default
    :func:`record`) are the recorded run."""
    kalman = ctrl.estimator == "kalman"
    files = library_files(ctrl, name=name, precision=precision)
    if vectors is None:
        vectors = record(ctrl, x0=x0, duration=duration, seed=seed)
    if tolerance is None:
        tolerance = command_tolerance(ctrl, precision)
    z_tolerance = Z_TOLERANCE if precision == "double" else Z_TOLERANCE_FLOAT
    n, m = ctrl.problem.n, ctrl.problem.m
    program = check_program(name, n=n, m=m, kalman=kalman)
    if kalman:
        arrays = {"y": vectors["y"], "u_applied": vectors["u_applied"], "u": vectors["u"],
                  "z": vectors["z"]}
        defines: dict[str, object] = {"TOLERANCE": tolerance, "Z_TOLERANCE": z_tolerance}
    else:
        arrays = {"y": vectors["y"], "u": vectors["u"]}
        defines = {"TOLERANCE": tolerance}
    checks = check_files(
        name, arrays, program=program, defines=defines,
        comment=f"Recorded by equilibrist: {len(vectors['y'])} samples of the MPC in closed loop "
                "with sensor noise; commands of the simulated controller (DAQP's Python interface).",
        what="the C MPC against the Python controller on recorded measurements.",
        sources=("$(wildcard daqp/src/*.c)",),
        include=("daqp/include",),
        cflags="-O2 -std=c99 -ffp-contract=off" + precision_flags(precision),
        entry=(f"{name}_output", f"{name}_update") if kalman else (f"{name}_step",),
    )
    return {**files, **checks}


def command_tolerance(ctrl: MPC, precision: str = "double") -> float:
    """How far ``make check`` lets each C command be from the simulated (double) controller's:
    1e-6 input units in double; in float :data:`FLOAT_TOLERANCE` of the widest input range."""
    if precision == "double":
        return 1e-6
    span = float(np.max(np.asarray(ctrl.problem.u_hi) - np.asarray(ctrl.problem.u_lo)))
    return FLOAT_TOLERANCE * span


#: The sampled states of :func:`iteration_counts`: how many, their seed, and their box (this
#: many design scales of each state around the operating point: on the cart-pole at N = 30
#: about a third of them need the solver).
SAMPLED_STATES, SAMPLE_SEED, SAMPLE_SPREAD = 200, 0, 2.0


def iteration_counts(ctrl: MPC, recorded: Mapping[str, np.ndarray], *,
                     samples: int = SAMPLED_STATES, seed: int = SAMPLE_SEED) -> dict[str, int]:
    """DAQP's worst iteration counts (the simulated controller's solver, double precision).

    ``recorded_run``: over the recorded run (each sample warm-started from
    the last, as the controller runs); ``sampled_states``: over *samples*
    states drawn uniformly within each state's design scale of the
    operating point, each solved from an empty working set (a cold start);
    ``at_cap``: how many of those ended at the iteration cap.
    """
    from equilibrist.control.mpc_runtime import MPCRuntime
    from equilibrist.native.daqp_library import ITER_LIMIT
    from equilibrist.numeric.lookup import system_from_key

    design = _design_of(ctrl)
    scales = system_from_key(design.system_key, dict(design.params)).spec.design_scales
    span = np.array([float(scales.get(k) or 0.0) for k in ctrl.state_names])
    rng = np.random.default_rng(seed)
    rt = MPCRuntime(ctrl)
    worst_cold, at_cap, constrained = 0, 0, 0
    for _ in range(samples):
        rt.reset()
        rt.solve(SAMPLE_SPREAD * rng.uniform(-1.0, 1.0, span.size) * span)
        worst_cold = max(worst_cold, rt.last_iterations)
        at_cap += rt.last_iterations >= ITER_LIMIT
        constrained += rt.last_status != "unconstrained"
    runs = np.asarray(recorded.get("iterations", np.zeros(1)))
    return {"recorded_run": int(runs.max(initial=0)), "sampled_states": worst_cold,
            "samples": samples, "constrained": constrained, "seed": seed, "at_cap": at_cap,
            "iter_limit": ITER_LIMIT}


def export_files(built: MPCRuntime, out: str | Path, *, system: System, precision: str = "double",
                 duration: float | None = None, seed: int = 0, force: bool = False) -> ControllerExport:
    """``equilibrist export SYSTEM --controller mpc``: DAQP's sources, the driver, ``make check``,
    ``make size`` and README.txt (the footprint, DAQP's worst iteration counts).

    The controller exported is the one simulated: with the Kalman filter in
    front when the design's measured outputs are not the full state.
    *precision* ``"double"`` or ``"float"`` (DAQP in single precision, checked
    against the double controller within :func:`command_tolerance`).
    """
    from equilibrist.export.folder import (
        EXPORT_MARKER,
        check_folder,
        generator_version,
        write_files,
    )
    from equilibrist.native.firmware import WHAT, with_hil
    from equilibrist.native.size import controller_readme, measure

    if precision not in ("double", "float"):
        raise ExportError(f"the MPC is exported in double or float precision, not {precision!r}")
    from equilibrist.export.vectors import check_duration

    ctrl = built.ctrl
    check_duration(duration, ctrl.rate)
    folder = check_folder(out, force=force)
    vectors = record(ctrl, duration=duration or 1.0, seed=seed)
    texts = with_hil(mpc_files(ctrl, duration=duration or 1.0, seed=seed, precision=precision,
                               vectors=vectors),
                     hil_adapter(built, system, precision=precision),
                     sketch_copies=("mpc.h", "mpc.c"))
    footprint, why = measure(texts)
    iterations = iteration_counts(ctrl, vectors)
    digest = design_id(built)
    kalman = ctrl.estimator == "kalman"
    files = {"daqp/": "DAQP's C sources (the QP solver, MIT licence)",
             "mpc.h": "the interface" + (" (Kalman filter in front)" if kalman else ""),
             "mpc.c": ("the Kalman filter and " if kalman else "")
             + "the QP's data and the step: bounds at the state, DAQP, the move",
             "mpc_vectors.h": "recorded measurements and the Python controller's commands",
             "test_mpc.c": "test program", "Makefile": "make check, make size, make hil-host",
             **{rel: what for rel, what in WHAT.items()}}
    texts["README.txt"] = controller_readme(
        f"mpc: the constrained MPC (horizon {ctrl.problem.horizon}) of {system.key}, "
        f"{ctrl.rate:g} Hz, {precision} precision; design id {digest}.\n"
        f"Generated by {generator_version()}."
        + ("\nBuild every source with -DDAQP_SINGLE_PRECISION (the Makefile does)."
           if precision == "float" else ""),
        files, footprint=footprint, why=why,
        heap="none (DAQP's workspace is static: no malloc)",
        notes=_readme_notes(ctrl, precision, iterations))
    texts[EXPORT_MARKER] = f"written by {generator_version()}\n"
    write_files(folder, texts)
    steps = round((duration or 1.0) * ctrl.rate) + 1
    return ControllerExport(folder=folder, name="mpc", files={**files, "README.txt": "this list"},
                     precision=precision, data=Described(digest, "mpc", ctrl.rate),
                     vectors=Steps(steps), footprint=footprint, size_note=why,
                     iterations=iterations)


def _readme_notes(ctrl: MPC, precision: str, iterations: Mapping[str, int]) -> list[str]:
    tol = command_tolerance(ctrl, precision)
    lines = [
        "DAQP's iterations per sample, worst (the simulated controller's solver, double):",
        f"  {iterations['recorded_run']:>5}  over the recorded run (warm-started, as it runs)",
        f"  {iterations['sampled_states']:>5}  over {iterations['samples']} states drawn within "
        f"{SAMPLE_SPREAD:g} design scales (seed {iterations['seed']}; "
        f"{iterations['constrained']} need the solver), each from a cold start",
        f"  cap {iterations['iter_limit']} (reached {iterations['at_cap']} times); mpc_iterations() "
        "returns the last step's count.",
        "",
        f"'make check': every command within {tol:.3g} of the double simulated controller's"
        + (f" ({FLOAT_TOLERANCE:g} of the widest input range, single precision)."
           if precision == "float" else "."),
        "",
    ]
    return lines


def hil_adapter(built: MPCRuntime, system: System, *, precision: str = "double") -> Adapter:
    """The MPC (with its filter, if any) behind the hardware-in-the-loop interface."""
    ctrl = built.ctrl
    names = system.input_names
    return mpc_adapter(
        controller_id=design_id(built), n=int(ctrl.problem.n), m=int(ctrl.problem.m),
        p=len(built.outputs or system.state_names), rate=float(ctrl.rate),
        u_min=tuple(float(system.params[f"{i}_min"]) for i in names),
        u_max=tuple(float(system.params[f"{i}_max"]) for i in names),
        kalman=ctrl.estimator == "kalman", precision=precision)


def design_id(built: MPCRuntime) -> str:
    """12 hex digits naming the exported MPC: its gains and its filter's."""
    import hashlib

    ctrl = built.ctrl
    return hashlib.sha256(np.asarray(ctrl.problem.K).tobytes()
                          + (b"" if ctrl.Kf is None else np.asarray(ctrl.Kf).tobytes())
                          ).hexdigest()[:12]


__all__ = [
    "FLOAT_TOLERANCE",
    "OVERDRIVE",
    "Z_TOLERANCE",
    "Z_TOLERANCE_FLOAT",
    "command_tolerance",
    "default_start",
    "export_files",
    "export_mpc",
    "iteration_counts",
    "mpc_files",
        "record",
]
