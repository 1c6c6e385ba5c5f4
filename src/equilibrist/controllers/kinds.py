"""Controller kinds as records: the one registry every consumer reads.

A *kind* is what ``--controller NAME`` names: LQR, LQG, the swing-up, the
MPC, the time-varying LQR, the open loop, and any kind a user adds. Each is
one :class:`ControllerKind` record (name, label, one-line help, typed
options, where it applies, how it is built, how it exports), and each
record lives in one module:

* the project's own kinds are the modules of the package
  :mod:`equilibrist.controllers` (one file each, found by listing the
  package: there is no list to edit);
* an installed package adds kinds through the entry-point group
  ``equilibrist.controllers`` (``name = "module:KIND"``), so a kind written
  in a folder of one's own works in every process that has it on its path
  (the batch's and the study's workers, the playground). Such a module is
  imported with its printing sent to stderr; a failure to load it, or of its
  kind's own ``build``, ``applies`` or ``export``, is a :data:`KindError` of
  one line naming it, its text quoted (:func:`~equilibrist.errors.quote_outside`).

The command line's ``--controller`` choices and help, each kind's own
flags (``--horizon``, ``--balance``, ``--trajectory``...), ``design``,
``export``, studies (a controller is a study dimension like any other) and
the playground's picker are all read from here; see ``docs/controllers.md``
for the recipe of a new kind.

Importing this module and listing the kinds imports no numerics: a kind's
module keeps its heavy imports inside ``build``.
"""

from __future__ import annotations

import dataclasses
import importlib
import pkgutil
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, TypeVar

from equilibrist.errors import (
    ControllerError,
    EquilibristError,
    outside_prints,
    quote_exception,
    quote_outside,
)

if TYPE_CHECKING:
    from pathlib import Path

    from equilibrist.control.controller import AnyController
    from equilibrist.control.design_record import Design
    from equilibrist.control.linear import LinearController
    from equilibrist.control.nonlinear import NonlinearController
    from equilibrist.control.python_controller import PythonController
    from equilibrist.export.writer import ExportReport
    from equilibrist.numeric.system import System

#: The places a kind can appear (:attr:`ControllerKind.surfaces`).
SURFACES = frozenset({"simulate", "design", "export", "study", "playground"})
#: The package whose modules are the project's own kinds.
PACKAGE = "equilibrist.controllers"
#: The entry-point group of kinds from other packages.
ENTRY_POINTS = "equilibrist.controllers"


#: An unknown kind, a kind that does not apply, or a bad option of one (one line).
KindError = ControllerError


@dataclass(frozen=True)
class Option:
    """A typed option of a kind: a command-line flag, a playground field, a study value.

    Attributes
    ----------
    flag:
        The command line's flag (``"--horizon"``); its key in
        :attr:`ControllerRequest.options` is the flag without dashes, ``-``
        read as ``_`` (``"horizon"``).
    help:
        One line for the command line's help.
    parse:
        Text -> value; raises ``ValueError`` for a bad text (the message
        then names the flag, the text and :attr:`expected`).
    expected:
        What a good value is, for that message (``"a whole number >= 1"``).
    metavar, choices:
        As argparse's.
    """

    flag: str
    help: str
    parse: Callable[[str], object] = str
    expected: str = "a value"
    metavar: str | None = None
    choices: tuple[str, ...] | None = None

    @property
    def key(self) -> str:
        return self.flag.lstrip("-").replace("-", "_")

    def value(self, text: str) -> object:
        """*text* parsed, or a :class:`KindError` naming the flag and what was expected."""
        if self.choices is not None and text not in self.choices:
            raise KindError(f"{self.flag} {text!r}: expected one of {', '.join(self.choices)}")
        try:
            return self.parse(text)
        except (ValueError, TypeError):
            raise KindError(f"{self.flag} {text!r}: expected {self.expected}") from None


@dataclass(frozen=True, eq=False)
class ControllerRequest:
    """What a kind is asked to build.

    Attributes
    ----------
    system:
        The plant (with its parameters).
    rate:
        Sample rate [Hz] of the run (None: the system's control rate).
    design_options:
        Keyword arguments of :func:`equilibrist.control.design.design`
        (``q``, ``r``, ``qn``, ``rn``, ``outputs``, ``kalman_form``,
        ``discretization``, ``at``).
    tracking:
        Whether the controller should follow a reference.
    options:
        The kind's own options by :attr:`Option.key` (``horizon`` for MPC, ...).
    """

    system: System
    rate: float | None
    design_options: Mapping[str, object] = field(default_factory=dict)
    tracking: bool = False
    options: Mapping[str, Any] = field(default_factory=dict)
    _designs: dict[str, Design] = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def of_design(cls, system: System, design: Design, **fields: Any) -> ControllerRequest:
        """A request whose design is *design*, made elsewhere (the playground's, tuned there;
        a study point's), at its rate: :meth:`design` returns it instead of designing."""
        request = cls(system=system, rate=design.rate, **fields)
        request._designs["d"] = design
        return request

    @property
    def sample_rate(self) -> float:
        """The run's rate, the system's control rate when the request names none."""
        return float(self.rate if self.rate is not None else self.system.spec.control_rate)

    def design(self) -> Design:
        """The discrete LQG design of the request (at its ``at`` operating point), made once."""
        if "d" not in self._designs:
            from equilibrist.control.design import design

            self._designs["d"] = design(self.system, rate=self.sample_rate,
                                        **dict(self.design_options))
        return self._designs["d"]

    @property
    def designed(self) -> Design | None:
        """The design if :meth:`design` was called (None otherwise)."""
        return self._designs.get("d")


def _applies_always(system: System) -> str | None:
    return None


@dataclass(frozen=True, eq=False)
class ControllerKind:
    """One kind of controller.

    Attributes
    ----------
    name:
        What ``--controller`` takes (a lower-case word).
    label:
        How the playground's picker names it (``"LQG (Kalman filter + LQR)"``).
    help:
        One line: what it does (the command line's help lists them).
    build:
        ``build(request)`` -> the controller (a ``LinearController``, a
        ``NonlinearController``, a Python controller) or None for the open
        loop; raises an ``EquilibristError`` of one line when it cannot.
    options:
        Its own options (:class:`Option`).
    applies:
        ``applies(system)`` -> None, or the one-line reason the kind does
        not apply to *system* (asked before anything is designed).
    surfaces:
        Where it is offered: ``simulate`` (and ``batch``), ``design``,
        ``export``, ``study``, ``playground``.
    noise:
        The run's noise with ``--noise on``: ``"design"`` (the design's
        covariances, which its Kalman filter assumes) or ``"spec"`` (the
        system's sensors at the run's rate).
    task:
        A task whose region ends the run (``"swingup"``: a swing-up starts
        hanging, only the track ends it), when the system has that task.
    linear:
        Whether ``design`` shows the whole LQG design for it (LQR, LQG).
    loop:
        The design's linear loop its controller is, as
        :meth:`~equilibrist.control.linear.LinearController.from_design` and the design's
        margins name it: ``"lqr"`` (the gain on the full state) or ``"lqg"`` (the gain on
        the estimate of the Kalman filter of the outputs); None for a controller that is
        not one (the playground then shows the state feedback's margins alone).
    from_any_state:
        Whether it brings the system up by itself from any state, with no plan and no
        clock (the swing-up: its supervisor pumps again after a loss and catches wherever
        the energy is right). In the playground only the track's limits (the swing-up
        task's region) end its run, also when it was not started hanging; and since it
        may catch a whole turn away from the operating point, a switch from it to another
        controller brings the angles within half a turn and starts the filter at its
        estimate. Its controller's state holds the supervisor's mode
        (:data:`equilibrist.control.swingup_law.Z`), which the playground shows.
    planned:
        Whether it tracks a plan of the swing-up task (the time-varying LQR): the
        playground plans one from the hanging start before it builds the kind (so the
        kind needs a system with a hanging position and CasADi), and its region of
        attraction is not a slice of starts about the upright.
    solves_qp:
        Whether its controller solves a QP at each sample (the MPC, built as its
        runtime): the playground times the solves and shows them.
    open_loop:
        Whether it is the open loop (nothing to design or export).
    export:
        ``export(request, out, *, system, precision, duration, seed,
        force)`` -> the export's report; None: the built controller is
        exported as the value it is (:func:`equilibrist.export.writer.export_controller`,
        which chooses the exporter by the value's type).
    check_export:
        ``check_export(request)``: refuses, before anything is built, a request
        the export cannot hold (the MPC's horizon); None: nothing to check.
    order:
        Where it is listed (the project's kinds 10..90, others 100).
    """

    name: str
    label: str
    help: str
    build: Callable[[ControllerRequest], AnyController | None]
    options: tuple[Option, ...] = ()
    applies: Callable[[System], str | None] = _applies_always
    surfaces: frozenset[str] = SURFACES
    noise: str = "spec"
    task: str | None = None
    linear: bool = False
    loop: str | None = None
    from_any_state: bool = False
    planned: bool = False
    solves_qp: bool = False
    open_loop: bool = False
    export: Callable[..., ExportReport] | None = None
    check_export: Callable[[ControllerRequest], None] | None = None
    order: int = 100

    def __post_init__(self) -> None:
        if not re.fullmatch(r"[a-z][a-z0-9_-]*", self.name):
            raise KindError(f"controller kind {self.name!r}: expected a lower-case word "
                            "(letters, digits, '_' and '-')")
        unknown = set(self.surfaces) - SURFACES
        if unknown:
            raise KindError(f"controller kind {self.name!r}: unknown surface(s) "
                            f"{', '.join(sorted(unknown))} (expected {', '.join(sorted(SURFACES))})")
        if self.loop not in (None, "lqr", "lqg"):
            raise KindError(f"controller kind {self.name!r}: loop {self.loop!r} "
                            "(expected 'lqr', 'lqg' or None)")
        if self.noise not in ("design", "spec"):
            raise KindError(f"controller kind {self.name!r}: noise {self.noise!r} "
                            "(expected 'design' or 'spec')")

    def make(self, request: ControllerRequest) -> AnyController | None:
        """The controller for *request*: refused in one line when the kind does not apply."""
        why = self.applies(request.system)
        if why is not None:
            raise KindError(f"--controller {self.name}: {why}")
        known = {o.key for o in self.options}
        extra = sorted(set(request.options) - known)
        if extra:
            raise KindError(f"the {self.name} controller takes no option {', '.join(extra)}")
        return self.build(request)

    def write_export(self, request: ControllerRequest, out: str | Path, **options: Any) -> ExportReport:
        """Export the controller of *request* as C into *out* (see :attr:`export`)."""
        if self.open_loop:
            raise KindError(f"--controller {self.name} is the open loop: there is no controller "
                            "to export")
        if self.check_export is not None:
            self.check_export(request)
        if self.export is not None:  # it builds through make(), which asks applies()
            return self.export(request, out, **options)
        from equilibrist.export.writer import export_controller

        return export_controller(self.make(request), out, system=request.system, **options)


def linear_builder(kind: str) -> Callable[[ControllerRequest], LinearController]:
    """``build`` of an LQR/LQG kind: the request's design as a ``LinearController``, designed
    for the loop delay its ``design_delay`` option names (none by default)."""

    def build(request: ControllerRequest) -> LinearController:
        from equilibrist.control.design_extended import delay_periods, delayed
        from equilibrist.control.linear import LinearController

        made = request.design()
        periods = delay_periods(request.options.get("design_delay", 0), request.sample_rate)
        return LinearController.from_design(delayed(made, periods), kind=kind,
                                            tracking=request.tracking)

    return build


_KINDS: dict[str, ControllerKind] = {}
_LOADED = False


#: Modules of the package that are not kinds: the policy object that steps any kind.
_NOT_KINDS = ("loop_policy",)


def _load() -> None:
    global _LOADED
    if _LOADED:
        return
    _LOADED = True
    package = importlib.import_module(PACKAGE)
    own = __name__.rpartition(".")[2]  # this registry, beside the kinds it lists
    for info in pkgutil.iter_modules(package.__path__):
        if not info.name.startswith("_") and info.name not in (own, *_NOT_KINDS):
            _add_from(importlib.import_module(f"{PACKAGE}.{info.name}"), f"{PACKAGE}.{info.name}")
    from importlib.metadata import entry_points

    for ep in entry_points(group=ENTRY_POINTS):
        where = f"the controller kind '{quote_outside(ep.name, limit=60)}' " \
                f"({quote_outside(ep.value, limit=120)})"
        try:
            # What the module prints is not the command's output (stdout may be its JSON).
            with outside_prints():
                obj = ep.load()
        except KeyboardInterrupt:
            raise
        except BaseException as exc:  # SystemExit too: a broken plugin is named in one line
            raise KindError(f"{where} cannot be loaded: {quote_exception(exc)}") from None
        kind = obj.KIND if hasattr(obj, "KIND") else obj
        _add(_guarded(kind, where) if isinstance(kind, ControllerKind) else kind, ep.value)


class _Guard:
    """A plug-in's callable (its kind's ``build``, ``applies``...): a failure other than an
    ``EquilibristError`` is a :class:`KindError` of one line naming the plug-in, and the
    reason ``applies`` gives is quoted (:func:`~equilibrist.errors.quote_outside`)."""

    def __init__(self, fn: Callable[..., Any], where: str, what: str) -> None:
        self.fn, self.where, self.what = fn, where, what

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        try:
            out = self.fn(*args, **kwargs)
        except (EquilibristError, KeyboardInterrupt):
            raise
        except BaseException as exc:
            raise KindError(f"{self.where} failed in its {self.what}: {quote_exception(exc)}") \
                from None
        return quote_outside(out, limit=300) if self.what == "applies" and out is not None else out


def _guarded(kind: ControllerKind, where: str) -> ControllerKind:
    """*kind* (a plug-in's) with its own code behind a :class:`_Guard` each."""
    own: dict[str, Any] = {
        name: _Guard(fn, where, name) for name in ("build", "applies", "export", "check_export")
        if (fn := getattr(kind, name)) is not None and not isinstance(fn, _Guard)}
    return dataclasses.replace(kind, **own)


def _add_from(module: object, where: str) -> None:
    kind = getattr(module, "KIND", None)
    if kind is None:
        raise KindError(f"{where} defines no KIND (a ControllerKind record)")
    _add(kind, where)


def _add(kind: object, where: str) -> None:
    if not isinstance(kind, ControllerKind):
        raise KindError(f"{where}: expected a ControllerKind record, got {type(kind).__name__}")
    old = _KINDS.get(kind.name)
    if old is not None and old is not kind:
        raise KindError(f"two controller kinds are named {kind.name!r} ({where})")
    _KINDS[kind.name] = kind


def register(kind: ControllerKind) -> ControllerKind:
    """Add *kind* in this process (a script's own kind; a module or an entry point is
    what workers and other processes find)."""
    _load()
    _add(kind, "register()")
    return kind


def unregister(name: str) -> None:
    """Remove the kind *name* added by :func:`register` in this process (a script's or a
    test's own; the modules' and entry points' kinds stay)."""
    _load()
    _KINDS.pop(name, None)


def all_kinds(surface: str | None = None) -> tuple[ControllerKind, ...]:
    """The kinds in their order (those offered on *surface* when given)."""
    _load()
    kinds = sorted(_KINDS.values(), key=lambda k: (k.order, k.name))
    return tuple(k for k in kinds if surface is None or surface in k.surfaces)


def names(surface: str | None = None) -> tuple[str, ...]:
    return tuple(k.name for k in all_kinds(surface))


def get(name: str, surface: str | None = None) -> ControllerKind:
    """The kind *name* (offered on *surface*), or a :class:`KindError` listing the known ones."""
    _load()
    kind = _KINDS.get(name)
    if kind is None or (surface is not None and surface not in kind.surfaces):
        known = ", ".join(names(surface))
        where = f" for {surface}" if surface is not None and kind is not None else ""
        raise KindError(f"controller {name!r} is unknown{where}: expected one of {known}")
    return kind


def options(surface: str | None = None) -> tuple[Option, ...]:
    """Every option of the kinds on *surface*, each flag once (the first kind's record)."""
    seen: dict[str, Option] = {}
    for kind in all_kinds(surface):
        for opt in kind.options:
            seen.setdefault(opt.flag, opt)
    return tuple(seen.values())


def owners(flag: str, surface: str | None = None) -> tuple[str, ...]:
    """The kinds that take *flag*."""
    return tuple(k.name for k in all_kinds(surface) if any(o.flag == flag for o in k.options))


def build(name: str, request: ControllerRequest) -> AnyController | None:
    """The controller of kind *name* for *request*."""
    return get(name).make(request)


__all__ = ["ENTRY_POINTS", "PACKAGE", "SURFACES", "ControllerKind", "ControllerRequest",
           "KindError", "Option", "all_kinds", "build", "get", "linear_builder", "names",
           "options", "owners", "register", "unregister"]


#: A kind's ``build``: request -> its controller (None: the open loop).
_Builder = TypeVar("_Builder", bound="Callable[[ControllerRequest], AnyController | None]")


def register_controller(name: str) -> Callable[[_Builder], _Builder]:
    """Decorator: *builder* (request -> controller) as the kind *name* in this process; a
    kind of its own module (:class:`ControllerKind`) says more."""

    def add(builder: _Builder) -> _Builder:
        register(ControllerKind(name=name, label=name, help=name, build=builder))
        return builder

    return add


def registered_controllers() -> tuple[str, ...]:
    """The names of every controller kind (:func:`names`)."""
    return names()


def build_controller(name: str, request: ControllerRequest
                     ) -> LinearController | NonlinearController | PythonController | None:
    """The controller of kind *name* for *request* (:func:`build`).

    Raises
    ------
    ControllerError
        An unknown name or one that does not apply to the system (one line).
    """
    try:
        kind = get(name)
    except KindError:
            raise ControllerError(f"controller {name!r} is unknown for {request.system.key}: "
                              f"expected one of {', '.join(names())}") from None
    result: LinearController | NonlinearController | PythonController | None = kind.make(request)
    return result
