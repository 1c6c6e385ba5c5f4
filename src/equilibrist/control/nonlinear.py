"""Nonlinear controllers compiled into the simulation core: :class:`NonlinearController`
and its Python runtime, the checks of a controller's source (its C translation is
:func:`equilibrist.native.controller_c.translate_controller`), the namespace it runs in
as Python, and the supervisor that switches between two controllers (used by :mod:`equilibrist.control.controller`).
"""

from __future__ import annotations

import ast
import hashlib
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from equilibrist.control.linear import _frozen
from equilibrist.control.python_controller import PythonControllerBase
from equilibrist.errors import ControllerError
from equilibrist.native.controller_c import translate_controller
from equilibrist.native.linear_layout import LINEAR_FUNCTIONS, _python_linear, linear_constants

if TYPE_CHECKING:
    from equilibrist.numeric.system import System

# -- nonlinear controllers, compiled into the simulation core ---------------------------------
#: The functions a nonlinear controller's source defines (estimate only with has_estimate).
NONLINEAR_FUNCTIONS = ("output", "update", "estimate")


@dataclass(frozen=True, eq=False)
class NonlinearController:
    """A controller given as Python source that the C translation knows (see the module docstring).

    Attributes
    ----------
    name:
        A short name (``"swingup"``), recorded with results.
    source:
        Python source defining ``output``, ``update`` (and ``estimate`` when
        *has_estimate*); only ``math`` and ``numpy`` (as ``np``) and the
        linear library (``linear_output`` ...) are in scope.
    params:
        The parameter vector handed to every call (1-D float64).
    z0:
        The controller state at the start of a run (1-D float64, may be empty).
    rate:
        Sample rate [Hz] the controller was made for.
    x_op, u_op:
        The operating point the run's deviations are measured from.
    state_names, input_names, output_names, tracked_names:
        The plant's states and inputs, the measured states (``y``) and the
        tracked outputs (``r``).
    has_estimate:
        Whether the source defines ``estimate``.
    settings:
        JSON-able description of how it was built (recorded with results).
    """

    name: str
    source: str
    params: np.ndarray
    z0: np.ndarray
    rate: float
    x_op: np.ndarray
    u_op: np.ndarray
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    tracked_names: tuple[str, ...] = ()
    has_estimate: bool = False
    settings: Mapping[str, object] = field(default_factory=dict)
    #: Whether the source reads the time ``t`` (a type whose functions never do says so: its C
    #: export's functions then take no time, and a source that reads it is refused).
    reads_time: ClassVar[bool] = True

    def __post_init__(self) -> None:
        n, m = len(self.state_names), len(self.input_names)
        object.__setattr__(self, "params", _frozen(np.asarray(self.params, dtype=float).reshape(-1),
                                                   (int(np.size(self.params)),), "params"))
        object.__setattr__(self, "z0", _frozen(np.asarray(self.z0, dtype=float).reshape(-1),
                                               (int(np.size(self.z0)),), "z0"))
        object.__setattr__(self, "x_op", _frozen(self.x_op, (n,), "x_op"))
        object.__setattr__(self, "u_op", _frozen(self.u_op, (m,), "u_op"))
        for label in ("state_names", "input_names", "output_names", "tracked_names"):
            object.__setattr__(self, label, tuple(getattr(self, label)))
        if not (math.isfinite(self.rate) and self.rate > 0):
            raise ControllerError(f"the controller's rate must be a positive number of Hz, got {self.rate!r}")
        missing = [o for o in (*self.output_names, *self.tracked_names) if o not in self.state_names]
        if missing:
            raise ControllerError(f"measured or tracked output(s) {', '.join(missing)} are not states")
        check_source(self.source, has_estimate=self.has_estimate)
        if not self.reads_time and source_reads_time(self.source):
            raise ControllerError(f"the {self.name} controller's source reads the time t, which "
                                  f"a {type(self).__name__} is not handed")

    def title(self) -> str:
        """What the controller is, in a few words (its C export's header and README)."""
        return f"the {self.name} controller"

    def record_start(self, system: System, seed: int) -> np.ndarray | None:
        """Where the run its C export records starts (absolute state), or None: the export's
        default (:func:`equilibrist.export.nonlinear_c.default_start`)."""
        return None

    @property
    def n_z(self) -> int:
        return int(self.z0.size)

    @property
    def outputs(self) -> tuple[str, ...]:
        return self.output_names

    @property
    def tracked(self) -> tuple[str, ...]:
        return self.tracked_names

    @property
    def kind(self) -> str:
        return self.name

    @property
    def source_hash(self) -> str:
        return hashlib.sha256(self.source.encode()).hexdigest()[:12]

    def python_functions(self) -> dict[str, Callable[..., object]]:
        """The source executed as plain Python (slow; for checks against the compiled core)."""
        namespace = contract_namespace()
        exec(compile(self.source, f"<controller {self.name}>", "exec"), namespace)
        return {k: namespace[k] for k in NONLINEAR_FUNCTIONS if k in namespace}

    def runtime(self, state_names: Sequence[str] | None = None) -> NonlinearRuntime:
        """This controller run in plain Python through the :class:`PythonController` protocol."""
        return NonlinearRuntime(self)

    def describe(self) -> dict[str, object]:
        return {"kind": self.name, "rate": self.rate, "source": self.source_hash,
                "outputs": list(self.output_names), "tracked": list(self.tracked_names),
                "settings": dict(self.settings)}


def contract_namespace() -> dict[str, Any]:
    """What a controller's source sees when it runs as Python: ``math``, ``np``, the linear
    library (``linear_output``...) and its layout's constants, and the project's ``eq_sin``,
    ``eq_cos``, ``eq_log``, ``eq_exp`` (:mod:`equilibrist.numeric.libm`: the same bits on every CPU,
    and in the C the translation writes)."""
    from equilibrist.numeric import libm

    namespace: dict[str, Any] = {"math": math, "np": np, **linear_constants(),
                                 "eq_sin": libm.eq_sin, "eq_cos": libm.eq_cos,
                                 "eq_log": libm.eq_log, "eq_exp": libm.eq_exp,
                                 "eq_atan": libm.eq_atan, "eq_tanh": libm.eq_tanh}
    namespace.update(_python_linear())
    return namespace


def check_source(source: str, *, has_estimate: bool) -> tuple[str, ...]:
    """The top-level function names of a controller's *source*, after checking it.

    Raises :class:`ControllerError` for a syntax error, a missing ``output``
    or ``update`` (or ``estimate`` with *has_estimate*), a top-level name
    that would hide the linear library, or top-level code other than
    functions, imports of ``math``/``numpy`` and constants.
    """
    try:
        tree = ast.parse(source)
    except SyntaxError as exc:
        raise ControllerError(f"the controller's source does not parse: {exc.msg} (line {exc.lineno})") from exc
    names: list[str] = []
    problems: list[str] = []
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            names.append(node.name)
        elif isinstance(node, ast.Import | ast.ImportFrom):
            mods = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
            if any(mod.split(".")[0] not in ("math", "numpy") for mod in mods):
                problems.append(f"line {node.lineno} imports {', '.join(mods)}: only math and numpy")
        elif isinstance(node, ast.Assign | ast.AnnAssign) or (
            isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
        ):
            continue
        else:
            problems.append(f"line {node.lineno}: only functions, imports and constants at top level")
    wanted = ["output", "update"] + (["estimate"] if has_estimate else [])
    problems += [f"no function {w}()" for w in wanted if w not in names]
    clash = [n for n in names if n in LINEAR_FUNCTIONS or n.startswith("_") or n in _RESERVED]
    if clash:
        problems.append(f"function name(s) {', '.join(clash)} are reserved by the simulation core")
    if problems:
        raise ControllerError("the controller's source: " + "; ".join(problems))
    _translate(source, wanted)
    return tuple(names)


def source_reads_time(source: str) -> bool:
    """Whether one of the contract's functions in *source* reads its time argument."""
    for node in ast.parse(source).body:
        if isinstance(node, ast.FunctionDef) and node.name in NONLINEAR_FUNCTIONS and node.args.args:
            t = node.args.args[0].arg
            if any(isinstance(n, ast.Name) and n.id == t for b in node.body for n in ast.walk(b)):
                return True
    return False


_TRANSLATED: dict[str, None] = {}


def _translate(source: str, wanted: Sequence[str]) -> None:
    """Translate the controller's functions to C once, so that what the simulation core
    cannot run is refused here, with its line."""
    key = source + repr(tuple(wanted))
    if key in _TRANSLATED:
        return
    from equilibrist.native.pyc import TranslationError

    try:
        translate_controller(source, {name: name for name in wanted})
    except TranslationError as exc:
        raise ControllerError(f"the controller's source: {exc}") from None
    if len(_TRANSLATED) > 256:
        _TRANSLATED.clear()
    _TRANSLATED[key] = None


# Names of the simulation core's module that a controller's source must not redefine.
_RESERVED = frozenset({
    "f", "run_one", "run_many", "measure_one", "advance_one", "scratch", "rk4_steps", "normals",
    "controller_output", "controller_update", "controller_estimate", "math", "np", "njit",
    "prange",
})


#: What balances after a catch (the swing-up's and the time-varying LQR's ``balance=``): the
#: design's LQR on the full state (or the swing-up's tracker), or on the estimator's estimate
#: of the design's outputs (the LQG).
BALANCES = ("lqr", "lqg")

#: The catch of a balancing controller, written once for every controller that hands over to
#: one (the swing-up, the time-varying LQR in both its forms, :func:`supervisor_source`): the
#: hysteresis of the switch (``catch_switch``), and the catch region of the balance's level
#: set ``V = dx' S dx`` (``catch_level``, ``catch_mode``: entered where ``V < enter``, kept
#: while ``V <= leave``). ``catch_level`` reads the deviation ``dx_i`` from the controller's
#: own ``catch_dev(i, t, z, y, params)`` (its estimate less the balance's operating point).
CATCH_SOURCE = '''
def catch_switch(held, enter, leave):
    """The hysteresis of a hand-over: 1.0 (the balance) or 0.0 next, from whether the balance
    holds now, whether to enter and whether to leave."""
    if held != 0:
        if leave != 0:
            return 0.0
        return 1.0
    if enter != 0:
        return 1.0
    return 0.0


def catch_level(t, z, y, params, S, n):
    """The level V = dx' S dx (S: n x n) of the deviation dx_i = catch_dev(i, t, z, y, params)."""
    v = 0.0
    for i in range(n):
        acc = 0.0
        for j in range(n):
            acc += S[i * n + j] * catch_dev(j, t, z, y, params)
        v += catch_dev(i, t, z, y, params) * acc
    return v


def catch_mode(held, v, enter, leave):
    """The catch region with its hysteresis: the balance takes over where the level v is below
    enter, and keeps the rig while v is at most leave."""
    return catch_switch(held, v < enter, not (v <= leave))
'''


def supervisor_source(*, catch: str, leave: str) -> str:
    """Source of a supervisor that switches between a nonlinear controller and a linear one.

    The hook for switching controllers with hysteresis, in the contract's
    own terms. The returned source defines ``output``/``update`` for a
    :class:`NonlinearController` whose parameters are
    ``[n_a, <a's params>, <linear controller packed>]`` and whose state is
    ``[mode, <a's state>, <linear controller's state>]`` (``mode`` 0: the
    first controller, 1: the linear one). The caller supplies the first
    controller's functions as ``first_output``/``first_update`` (same
    signatures as ``output``/``update``) in the same source, and two
    boolean expressions over ``y`` and ``params`` (code the C translation knows):

    *catch*
        True when the linear controller should take over (entering the
        catch region).
    *leave*
        True when it should hand back (leaving a larger region): the gap
        between the two regions is the hysteresis (:data:`CATCH_SOURCE`'s
        ``catch_switch``, the hand-over of every controller that catches).

    The linear controller's own state runs (its filter keeps estimating)
    in both modes, so it takes over with a current estimate.
    """
    return CATCH_SOURCE + f'''
def output(t, z, y, r, params, u_out):
    a0, l0 = 1, 1 + int(params[0])
    nza = int(z.shape[0]) - 1 - int(params[l0 + _LIN_NZ])
    mode = catch_switch(z[0] == 1.0, ({catch}), ({leave}))
    if mode == 1.0:
        linear_output(t, z[1 + nza:], y, r, params[l0:], u_out)
    else:
        first_output(t, z[1:1 + nza], y, r, params[a0:l0], u_out)


def update(t, z, y, r, u_applied, params, z_out):
    a0, l0 = 1, 1 + int(params[0])
    nza = int(z.shape[0]) - 1 - int(params[l0 + _LIN_NZ])
    mode = catch_switch(z[0] == 1.0, ({catch}), ({leave}))
    z_out[0] = mode
    first_update(t, z[1:1 + nza], y, r, u_applied, params[a0:l0], z_out[1:1 + nza])
    linear_update(t, z[1 + nza:], y, r, u_applied, params[l0:], z_out[1 + nza:])
'''


class NonlinearRuntime(PythonControllerBase):
    """A :class:`NonlinearController`'s source run as plain Python (the core's reference)."""

    def __init__(self, ctrl: NonlinearController) -> None:
        self.c = ctrl
        self.fns = ctrl.python_functions()
        self.rate = ctrl.rate
        self.outputs = ctrl.output_names
        self.reset()

    def reset(self) -> None:
        self.z = np.array(self.c.z0)
        self.estimate = None

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        u = np.zeros(len(self.c.input_names))
        y = np.asarray(y, dtype=float)
        r = np.asarray(r, dtype=float)
        if self.c.has_estimate:
            x = np.zeros(len(self.c.state_names))
            self.fns["estimate"](t, self.z, y, r, self.c.params, x)
            self.estimate = x
        self.fns["output"](t, self.z, y, r, self.c.params, u)
        return u

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        zn = np.zeros(self.c.n_z)
        self.fns["update"](t, self.z, np.asarray(y, dtype=float), np.asarray(r, dtype=float),
                           np.asarray(u_applied, dtype=float), self.c.params, zn)
        self.z = zn
