"""The exporter of any nonlinear controller: its library
(:mod:`equilibrist.native.nonlinear_library`), recorded test vectors, ``make check`` and
the hardware-in-the-loop files, and of any linear controller
(:meth:`LinearController.as_nonlinear`): the export chooses it by the value's type
(:func:`equilibrist.export.writer.exporter_of`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.errors import ExportError
from equilibrist.export.report import ControllerExport, Described, Steps
from equilibrist.native.c_text import c_identifier
from equilibrist.native.nonlinear_library import (
    check_files,
    design_id,
    hil_adapter,
    nonlinear_files,
)

if TYPE_CHECKING:
    from equilibrist.control.nonlinear import NonlinearController
    from equilibrist.numeric.system import System


def default_start(ctrl: NonlinearController, system: System) -> np.ndarray:
    """The recorded run's start: where the controller's plan starts (a tracked trajectory's
    ``settings["start"]``, as ``simulate`` starts it), else the controller's operating point
    with each coordinate that has a design scale displaced by a quarter of it (as the linear
    exports' runs)."""
    from equilibrist.export.vectors import displaced

    planned = ctrl.settings.get("start") if isinstance(ctrl.settings, Mapping) else None
    if isinstance(planned, Mapping) and set(planned) <= set(ctrl.state_names):
        x = np.array(ctrl.x_op, dtype=float)
        for state, value in planned.items():
            x[ctrl.state_names.index(state)] = float(value)
        return x
    return displaced(ctrl.x_op, ctrl.state_names, system)


def recorded_vectors(ctrl: NonlinearController, system: System, *, duration: float = 4.0,
                     seed: int = 0, x0: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Test vectors: the inputs of a noisy closed-loop run, and the Python runtime's answers.

    *ctrl* runs in the simulation core on *system* with the rig's sensor
    noise, from *x0* (else the command line's ``--x0``, else the controller's own
    :meth:`~equilibrist.control.controller.NonlinearController.record_start`, else
    :func:`default_start`); a controller that tracks references follows a
    step of them half way. Its plain-Python runtime
    (:meth:`NonlinearController.runtime`, the reference) is then fed the
    recorded inputs sample by sample. ``t`` (the times handed to the
    controller), ``y``, ``r`` (with references), ``u_applied``, ``u`` (the
    Python runtime's commands) and ``x`` (its estimates, when it has them),
    one row per sample.
    """
    from equilibrist.export import vectors
    from equilibrist.sim import Step
    from equilibrist.sim.noise import Noise
    from equilibrist.sim.run import simulate

    given = vectors._START.get()
    if x0 is not None:
        start = np.asarray(x0, dtype=float)
    elif given is not None and given.given is not None:
        start = np.array(ctrl.x_op, dtype=float)
        for state, value in given.given.items():
            if state not in ctrl.state_names:
                raise ExportError(f"--x0 {state}: the controller has no state {state!r}")
            start[ctrl.state_names.index(state)] = float(value)
    else:
        own = ctrl.record_start(system, seed)
        start = default_start(ctrl, system) if own is None else own
    if given is not None:
        given.used = {n: float(v) for n, v in zip(ctrl.state_names, start, strict=True)}
    reference = None
    if ctrl.tracked_names:
        scales = system.spec.design_scales
        r0 = np.array([ctrl.x_op[ctrl.state_names.index(n)] for n in ctrl.tracked_names])
        step = np.array([vectors.STEP_FRACTION * float(scales.get(n, 0.0))
                         for n in ctrl.tracked_names])
        reference = Step(value=r0 + step, at=0.5 * duration)
    noise = Noise.from_spec(system, outputs=ctrl.output_names, rate=ctrl.rate)
    res = simulate(system, ctrl, duration=duration, x0=start, region={}, noise=noise, seed=seed,
                   reference=reference)
    k = len(res.time)
    t = np.array(res.time, dtype=float)
    y = np.array(res.measurements, dtype=float).reshape(k, -1)
    r = np.array(res.reference, dtype=float).reshape(k, -1) if ctrl.tracked_names \
        else np.zeros((k, 0))
    applied = np.array(res.applied, dtype=float).reshape(k, -1)
    runtime = ctrl.runtime()
    runtime.reset()
    u = np.zeros((k, len(ctrl.input_names)))
    x = np.zeros((k, len(ctrl.state_names)))
    for i in range(k):
        u[i] = runtime.output(float(t[i]), y[i].copy(), r[i].copy())
        if ctrl.has_estimate and runtime.estimate is not None:
            x[i] = runtime.estimate
        runtime.update(float(t[i]), y[i].copy(), r[i].copy(), applied[i].copy())
    out = {"t": t.reshape(k, 1), "y": y}
    if ctrl.tracked_names:
        out["r"] = r
    out["u_applied"] = applied
    out["u"] = u
    if ctrl.has_estimate:
        out["x"] = x
    return out


def export_files(ctrl: NonlinearController, out: str | Path, *, system: System,
                 precision: str = "double", duration: float | None = None, seed: int = 0,
                 force: bool = False, name: str | None = None) -> ControllerExport:
    """The library, recorded vectors, ``make check`` and the HIL files of *ctrl* in *out*."""
    from equilibrist.export.folder import check_folder, generator_version, write_files
    from equilibrist.export.vectors import check_duration
    from equilibrist.native.firmware import WHAT, with_hil
    from equilibrist.native.size import controller_readme, measure

    if precision != "double":
        raise ExportError(
            f"the {ctrl.name} controller is exported in double precision only (its test is bit "
            f"for bit against the Python controller), not {precision!r}"
        )
    if tuple(system.input_names) != tuple(ctrl.input_names):
        raise ExportError(f"the {ctrl.name} controller drives {', '.join(ctrl.input_names)}, "
                          f"{system.key} has inputs {', '.join(system.input_names)}")
    check_duration(duration, ctrl.rate)
    folder = check_folder(out, force=force)
    lib = name or c_identifier(ctrl.name)
    vec = recorded_vectors(ctrl, system, duration=duration or 4.0, seed=seed)
    files = with_hil({**nonlinear_files(ctrl, name=lib), **check_files(ctrl, lib, vec)},
                     hil_adapter(ctrl, system, name=lib), sketch_copies=(f"{lib}.h", f"{lib}.c"))
    what = {
        f"{lib}.h": "the library's interface", f"{lib}.c": ctrl.title(),
        f"{lib}_vectors.h": "recorded test vectors", f"test_{lib}.c": "test program",
        "Makefile": "make check, make size, make hil-host", **WHAT,
    }
    footprint, why = measure(files)
    files["README.txt"] = controller_readme(
        f"{lib}: {ctrl.title()}, for {system.key}, {ctrl.rate:g} Hz, double "
        f"precision; design id {design_id(ctrl)}.\nGenerated by {generator_version()}.",
        what, footprint=footprint, why=why)
    write_files(folder, files)
    return ControllerExport(folder=folder, name=lib, files={**what, "README.txt": "this list"},
                            precision="double", data=Described(design_id(ctrl), ctrl.name, ctrl.rate),
                            vectors=Steps(len(vec["y"])), footprint=footprint, size_note=why)
