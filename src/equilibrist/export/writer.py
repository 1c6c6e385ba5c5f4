"""Write the C export of a design into a folder, all of it or nothing.

Everything is checked and every file's text made in memory first; then the
files are written into a hidden staging folder beside the target and moved
into place, so a bad input leaves nothing half-written.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from equilibrist.errors import ExportError
from equilibrist.export.data import check_controller, controller_data
from equilibrist.export.folder import EXPORT_MARKER, check_folder, generator_version, write_files
from equilibrist.native import c_programs, c_text, linear_library
from equilibrist.native.c_text import check_precision
from equilibrist.native.linear_c import ControllerData

if TYPE_CHECKING:
    from typing import TypedDict, Unpack

    from equilibrist.control.design_record import Design
    from equilibrist.control.linear import LinearController
    from equilibrist.control.mpc_runtime import MPCRuntime
    from equilibrist.control.nonlinear import NonlinearController
    from equilibrist.native.size import Footprint
    from equilibrist.numeric.system import System

    class _Options(TypedDict, total=False):
        """What an exporter takes besides the controller, the folder and the system."""

        precision: str
        duration: float | None
        seed: int
        force: bool


ARDUINO_FOLDER = "example_arduino"


@dataclass(frozen=True)
class Export:
    """What :func:`export_c` wrote.

    Attributes
    ----------
    folder:
        The output folder.
    files:
        Paths of the files written, relative to *folder*, with what each is.
    data:
        The controller that was exported.
    precision:
        ``"double"`` or ``"float"``.
    vectors:
        The test vectors written.
    """

    folder: Path
    files: Mapping[str, str]
    data: ControllerData
    precision: str
    vectors: c_text.Vectors
    #: What ``make size`` printed at export (None: not measured, see :attr:`size_note`).
    footprint: Footprint | None = None
    size_note: str = ""

    @property
    def name(self) -> str:
        return self.data.name

    @property
    def header(self) -> Path:
        return self.folder / f"{self.data.name}.h"

    @property
    def source(self) -> Path:
        return self.folder / f"{self.data.name}.c"


def render(
    data: ControllerData,
    vectors: c_text.Vectors,
    *,
    precision: str,
    version: str,
    title: str = "",
    param_table: tuple[tuple[str, float, str, str], ...] = (),
) -> dict[str, tuple[str, str]]:
    """Every file of the export: relative path -> (text, what it is)."""
    return render_measured(data, vectors, precision=precision, version=version, title=title,
                           param_table=param_table)[0]


def render_measured(
    data: ControllerData,
    vectors: c_text.Vectors,
    *,
    precision: str,
    version: str,
    title: str = "",
    param_table: tuple[tuple[str, float, str, str], ...] = (),
) -> tuple[dict[str, tuple[str, str]], Footprint | None, str]:
    """:func:`render`, and the footprint ``make size`` printed for it (None and why not)."""
    from equilibrist.native.size import measure, readme_lines

    name = data.name
    head = linear_library.header(data, precision=precision, version=version, title=title,
                         param_table=param_table)
    src = linear_library.source(data, precision=precision, version=version)
    files: dict[str, tuple[str, str]] = {
        f"{name}.h": (head, "the library's header: constants, units, the functions"),
        f"{name}.c": (src, "the library: init, step, estimate, version"),
        "example_desktop.c": (c_programs.desktop_example(data),
                              "desktop example: balances the linear model, or reads stdin with '-'"),
        f"test_{name}.c": (c_programs.test_program(data), "test program: replays the test vectors"),
        f"{name}_vectors.h": (c_programs.vectors_header(data, vectors, version=version),
                              "test vectors: a recorded noisy closed-loop run"),
        "Makefile": (c_programs.makefile(data), "make / make check / make size / make clean"),
        f"{ARDUINO_FOLDER}/{ARDUINO_FOLDER}.ino": (
            c_programs.arduino_sketch(data, precision=precision),
            "Arduino sketch (with its own copy of the library)",
        ),
        f"{ARDUINO_FOLDER}/{name}.h": (head, "copy of the header for the sketch"),
        f"{ARDUINO_FOLDER}/{name}.c": (src, "copy of the library for the sketch"),
    }
    files = _with_hil(files, data)
    footprint, why = measure({rel: text for rel, (text, _) in files.items()})
    listing = {path: what for path, (_, what) in files.items()}
    listing["README.txt"] = "this list"
    files["README.txt"] = (
        c_programs.readme(data, precision=precision, version=version, files=listing,
                      footprint=readme_lines(footprint, why)),
        "this list",
    )
    return files, footprint, why


def _with_hil(files: dict[str, tuple[str, str]], data: ControllerData) -> dict[str, tuple[str, str]]:
    from equilibrist.native.firmware import WHAT, with_hil

    name = data.name
    texts = with_hil({rel: text for rel, (text, _) in files.items()}, c_programs.hil_adapter(data),
                     sketch_copies=(f"{name}.h", f"{name}.c"))
    whats = {rel: what for rel, (_, what) in files.items()}
    return {rel: (text, whats.get(rel) or WHAT.get(rel) or "hardware in the loop: copy for the "
                  "sketch") for rel, text in texts.items()}


class ExportedController(Protocol):
    """What every export reports of the controller it wrote."""

    @property
    def fingerprint(self) -> str: ...
    @property
    def controller(self) -> str: ...
    @property
    def rate(self) -> float: ...


class ExportedVectors(Protocol):
    """What every export reports of its recorded test vectors."""

    @property
    def n_steps(self) -> int: ...


class ExportReport(Protocol):
    """What every exporter returns (:class:`Export` and the other controllers' exports):
    the fields the command line reports."""

    @property
    def folder(self) -> Path: ...
    @property
    def name(self) -> str: ...
    @property
    def files(self) -> Mapping[str, str]: ...
    @property
    def precision(self) -> str: ...
    @property
    def data(self) -> ExportedController: ...
    @property
    def vectors(self) -> ExportedVectors: ...


#: Exporters by the type of the controller value, beyond the project's own
#: (:func:`exporter_of`): a module that defines a controller type of its own adds one with
#: :func:`register_exporter`. ``exporter(controller, out, *, system, precision, duration,
#: seed, force) -> report``.
EXPORTERS: dict[type, Callable[..., ExportReport]] = {}


def register_exporter(kind: type) -> Callable[[Callable[..., ExportReport]], Callable[..., ExportReport]]:
    """Decorator: *exporter* writes the C code of controller values of type *kind* (and of
    its subclasses that have none of their own)."""

    def add(exporter: Callable[..., ExportReport]) -> Callable[..., ExportReport]:
        EXPORTERS[kind] = exporter
        return exporter

    return add


def exporter_of(ctrl: object) -> Callable[..., ExportReport]:
    """The exporter of the controller value *ctrl*, chosen by its type (the most derived one
    that has an exporter): the MPC's library with DAQP, an LQR or LQG
    design's library, any other linear controller or :class:`NonlinearController` (the
    swing-up too) translated from its source. Other values are refused in one line."""
    from equilibrist.control.linear import LinearController
    from equilibrist.control.mpc_runtime import MPCRuntime
    from equilibrist.control.nonlinear import NonlinearController

    def mpc(built: MPCRuntime, out: str | Path, *, system: System,
            **options: Unpack[_Options]) -> ExportReport:
        from equilibrist.export.mpc_c import export_files

        return export_files(built, out, system=system, **options)

    def nonlinear(ctrl: NonlinearController, out: str | Path, *, system: System,
                  **options: Unpack[_Options]) -> ExportReport:
        from equilibrist.export.nonlinear_c import export_files

        return export_files(ctrl, out, system=system, **options)

    known: dict[type, Callable[..., ExportReport]] = {
        MPCRuntime: mpc, NonlinearController: nonlinear,
        LinearController: _export_linear, **EXPORTERS}
    for cls in type(ctrl).__mro__:
        if cls in known:
            return known[cls]
    if ctrl is None:
        raise ExportError("the open loop has no controller to export")
    raise ExportError(f"a {type(ctrl).__name__} has no C export: the export takes a "
                      "LinearController, a NonlinearController or the MPC")


def export_controller(ctrl: object, out: str | os.PathLike[str], *, system: System,
                      precision: str = "double", duration: float | None = None, seed: int = 0,
                      force: bool = False) -> ExportReport:
    """Write the C export of the controller value *ctrl*, whatever made it (:func:`exporter_of`).

    A :class:`~equilibrist.control.controller.LinearController` of an LQR or
    LQG design is the design's library (:func:`export_c`); any other linear
    controller, a hand-built one included, and any
    :class:`~equilibrist.control.controller.NonlinearController` (a kind of
    one's own, the time-varying LQR...) is its source translated to C
    (:mod:`equilibrist.export.nonlinear_c`), tested bit for bit against the
    Python controller; the MPC has a library of its own (DAQP and its driver).
    """
    return exporter_of(ctrl)(ctrl, out, system=system, precision=precision, duration=duration,
                             seed=seed, force=force)


def _export_linear(ctrl: LinearController, out: str | os.PathLike[str], *, system: System,
                   **options: Unpack[_Options]) -> ExportReport:
    """A controller its discrete design made (an LQR, an LQG): the design's library (its
    matrices, the Kalman form, the recorded run); any other linear controller: the linear
    library on its packed vector, through the nonlinear export
    (:meth:`LinearController.as_nonlinear`)."""
    if ctrl.design is not None and made_by_design(ctrl):
        return export_c(ctrl.design, out, controller=ctrl.kind, system=system, **options)
    from equilibrist.export.nonlinear_c import export_files

    return export_files(ctrl.as_nonlinear(), Path(out), system=system, **options)


def _same(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    return a is b if a is None or b is None else bool(np.array_equal(a, b))


def made_by_design(ctrl: LinearController) -> bool:
    """Whether *ctrl* is its discrete design's controller as the design makes it (the same
    numbers, names, limits and start): a controller changed after (started elsewhere, other
    gains or limits) is exported as the value it is."""
    from equilibrist.control.design_record import Design
    from equilibrist.control.linear import LinearController
    from equilibrist.errors import EquilibristError

    design = ctrl.design
    # The design's library holds the matrices of a design on the plant as it is; a design on
    # an extended model (the commands in flight of a delayed loop, the rig's velocity filter)
    # is exported as the value it is.
    if not isinstance(design, Design) or design.discrete is None or not design.rate \
            or design.extended:
        return False
    try:
        made = LinearController.from_design(design, kind=ctrl.kind,
                                            tracking=bool(ctrl.tracked_names))
    except EquilibristError:
        return False
    return (made.fingerprint == ctrl.fingerprint and made.rate == ctrl.rate
            and made.form == ctrl.form and np.array_equal(made.z0, ctrl.z0)
            and _same(made.u_min, ctrl.u_min) and _same(made.u_max, ctrl.u_max))


def design_id(ctrl: object) -> str:
    """The design id the export of the controller value *ctrl* carries (what a device flashed
    with it reports), chosen as :func:`exporter_of` chooses the exporter."""
    from equilibrist.control.linear import LinearController
    from equilibrist.control.mpc_runtime import MPCRuntime
    from equilibrist.control.nonlinear import NonlinearController
    from equilibrist.export.mpc_c import design_id as mpc_id
    from equilibrist.native.nonlinear_library import design_id as nonlinear_id

    def linear(value: LinearController) -> str:
        if value.design is not None and made_by_design(value):  # the design's library
            return controller_data(value.design, controller=value.kind).fingerprint
        return nonlinear_id(value.as_nonlinear())

    ids: dict[type, Callable[[Any], str]] = {
        MPCRuntime: mpc_id, NonlinearController: nonlinear_id, LinearController: linear}
    for cls in type(ctrl).__mro__:
        if cls in ids:
            return ids[cls](ctrl)
    raise ExportError("there is no exported controller for "
                      + ("the open loop" if ctrl is None else f"a {type(ctrl).__name__}"))


def export_c(
    design: Design,
    out: str | os.PathLike[str],
    *,
    controller: str = "lqg",
    precision: str = "double",
    vectors: c_text.Vectors | None = None,
    duration: float | None = None,
    seed: int = 0,
    system: System | None = None,
    force: bool = False,
) -> Export:
    """Write the C99 library of *design*'s digital controller, with examples and tests.

    The folder receives ``<name>.h`` and ``<name>.c`` (the library; ``<name>``
    is ``<system>_<controller>``), ``example_desktop.c``, an Arduino sketch
    in ``example_arduino/``, ``test_<name>.c`` with ``<name>_vectors.h``, a
    ``Makefile`` (``make``, ``make check``) and ``README.txt``.

    Parameters
    ----------
    design:
        A discrete control-layer ``Design``.
    out:
        Output folder; created if missing, files of the same names replaced.
    controller:
        ``"lqg"`` (Kalman filter on the design's outputs) or ``"lqr"`` (full state).
    precision:
        ``"double"`` or ``"float"``: the library's arithmetic.
    vectors:
        Test vectors to ship; default a recorded noisy closed-loop run of
        the simulation's reference controller (:func:`~equilibrist.export.vectors.record`).
    duration, seed:
        Length [s] and noise seed of that run.
    system:
        The bound system the design was made for (default: rebuilt from the
        design's key and parameters), for its descriptions.
    force:
        Write into an existing folder that holds files equilibrist did not
        write (replacing those of the export's names).

    Returns
    -------
    Export

    Raises
    ------
    ExportError
        An unknown controller or precision, a continuous design, a system
        without input, an output folder that cannot be written. Nothing is
        written then.
    """
    check_controller(controller)
    check_precision(precision)
    from equilibrist.control.design_record import Design

    if isinstance(design, Design) and design.extended:
        what = (f"a loop {design.delay} period(s) late" if design.delay
                else f"the rig's {design.velocity_filter:g} Hz velocity filter")
        raise ExportError(
            f"the design is for {what}: its library holds a design of the plant as it is; "
            "export its controller, the linear controller it is: export_controller("
            f"LinearController.from_design(design, kind={controller!r}), out, system=...) "
            "from equilibrist.export.writer (the command line's export does)")
    folder = check_folder(out, force=force)
    data = controller_data(design, controller=controller)
    if system is None:
        system = _system_of(design)
    if vectors is None:
        from equilibrist.export.vectors import record

        vectors = record(design, system, controller=controller, precision=precision,
                         duration=duration, seed=seed)
    version = generator_version()
    title, table = _describe(system, data)
    files, footprint, why = render_measured(data, vectors, precision=precision, version=version,
                                            title=title, param_table=table)
    texts = {rel: text for rel, (text, _) in files.items()}
    texts[EXPORT_MARKER] = f"written by equilibrist {version}\n"
    write_files(folder, texts)
    return Export(
        folder=folder,
        files={rel: what for rel, (_, what) in files.items()},
        data=data,
        precision=precision,
        vectors=vectors,
        footprint=footprint,
        size_note=why,
    )


def _system_of(design: Design) -> System:
    from equilibrist.numeric.lookup import system_from_key

    return system_from_key(str(design.system_key), design.params)


def _describe(system: System | None, data: ControllerData) -> tuple[str, tuple[tuple[str, float, str, str], ...]]:
    if system is None:
        return "", tuple((k, float(v), "", "") for k, v in data.params.items())
    spec = system.spec
    table = []
    for p in spec.all_parameters:
        if p.name in data.params:
            table.append((p.name, float(data.params[p.name]), p.unit, p.meaning))
    return spec.title, tuple(table)

