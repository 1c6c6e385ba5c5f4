"""One controller contract, consumed unchanged by the simulator, batches and the C export.

A controller is one of three kinds of value:

:class:`LinearController`
    One discrete state-space form in deviation coordinates about the
    operating point (``dy = y - y_op``, ``dr = r - r_op``,
    ``du = u_applied - u_op``)::

        u  = u_op + Cc z + Dy dy + Dr dr          then saturated (and delayed)
        z+ = Ac z + By dy + Br dr + Bu du          du: the input that acted

    with, for the record, the state estimate ``x_hat = x_op + Ez z + Ey dy``.
    LQR (:meth:`LinearController.state_feedback`), both discrete LQG forms
    (:meth:`LinearController.lqg`), a design (:meth:`LinearController.from_design`)
    and the open loop (:meth:`LinearController.open_loop`) are constructors
    of it. The compiled simulation core runs it through the source
    :data:`LINEAR_SOURCE` (one generic loop), the C export writes the same
    loop once in C plus the matrices, and :meth:`LinearController.output`
    and :meth:`LinearController.update` run that very source in Python.

:class:`NonlinearController`
    Python source translated to C into the system's simulation core
    (as the system's own ``f`` is), defining::

        def output(t, z, y, r, params, u_out): ...            # u_out[:] = command
        def update(t, z, y, r, u_applied, params, z_out): ...  # z_out[:] = next z
        def estimate(t, z, y, r, params, x_out): ...           # only with has_estimate

    ``t`` the sample time [s], ``z`` the controller state (length
    ``n_z``), ``y`` the measured outputs, ``r`` the references (absolute
    units, all 1-D float64 arrays), ``params`` the controller's parameter
    vector. The functions use ``math`` and ``numpy`` only, allocate nothing
    and return nothing; any helper function in the source is compiled too.
    The linear library functions ``linear_output``, ``linear_update`` and
    ``linear_estimate`` (same signatures, *params* a
    :meth:`LinearController.packed` vector) are in scope, so a nonlinear
    controller embeds a linear one by carrying its packed vector inside its
    own parameters (``params[a:b]``) and its state inside its own
    (``z[c:d]``). :func:`supervisor_source` builds the switching logic with
    hysteresis that hands over between two such controllers.

:class:`PythonController`
    A protocol for controllers written in Python: ``reset()``,
    ``output(t, y, r) -> u`` and ``update(t, y, r, u_applied)``, plus the
    attributes ``rate``, ``outputs`` and ``estimate`` (None when there is
    nothing to say). :class:`PythonControllerBase` gives those defaults.
    The simulator calls them once per sample; batches of them run in
    worker processes (the controller must pickle). An object with the old
    ``step(t, y, r)`` method, or a function ``(t, y, r) -> u``, runs
    through :class:`StepAdapter`.

The command line's ``--controller`` choices are a registry of builders
(:func:`register_controller`, :func:`build_controller`): ``lqr``, ``lqg``
and ``none`` are registered here; a module that registers ``swingup`` or
``mpc`` adds them everywhere at once.
"""

from __future__ import annotations

import ast
import hashlib
import math
import types
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import numpy as np

from equilibrist.errors import ControllerError, DesignError, DimensionError

if TYPE_CHECKING:
    from equilibrist.control.design import Design


# -- the packed linear controller: one layout, read by the core, Python and C -------------------
#: Header slots of a packed :class:`LinearController` (name -> index): the sizes, then
#: the offset of each block in the vector.
LINEAR_HEADER: tuple[str, ...] = (
    "nz", "ny", "nr", "m", "n",
    "Ac", "By", "Br", "Bu", "Cc", "Dy", "Dr", "Ez", "Ey", "u_op", "y_op", "r_op", "x_op",
)
#: The blocks of a packed controller after the header, with their shapes in sizes.
LINEAR_BLOCKS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("Ac", ("nz", "nz")), ("By", ("nz", "ny")), ("Br", ("nz", "nr")), ("Bu", ("nz", "m")),
    ("Cc", ("m", "nz")), ("Dy", ("m", "ny")), ("Dr", ("m", "nr")),
    ("Ez", ("n", "nz")), ("Ey", ("n", "ny")),
    ("u_op", ("m",)), ("y_op", ("ny",)), ("r_op", ("nr",)), ("x_op", ("n",)),
)


def linear_constants() -> dict[str, int]:
    """``{"_LIN_NZ": 0, ..., "_LIN_X_OP": 17}``: the header slots as source constants."""
    return {f"_LIN_{name.upper()}": i for i, name in enumerate(LINEAR_HEADER)}


def linear_sizes(p: np.ndarray) -> dict[str, int] | None:
    """The sizes ``nz, ny, nr, m, n`` in the header of the packed vector *p* (None if it has none)."""
    if p.shape[0] < len(LINEAR_HEADER):
        return None
    return {key: int(p[LINEAR_HEADER.index(key)]) for key in ("nz", "ny", "nr", "m", "n")}


def linear_layout_source(sizes: Mapping[str, int] | None = None) -> str:
    """Source of ``linear_layout(p)``: the sizes and block offsets :data:`LINEAR_SOURCE` reads.

    It returns the :data:`LINEAR_HEADER` slots in order. Without *sizes*
    they are read from the header of *p* at every call (any packed
    controller); with *sizes* (``nz, ny, nr, m, n``) the function returns
    them, and the offsets they imply, as literals, so that the compiled
    loops of the linear library have fixed trip counts and constant
    indices (the C compiler unrolls them). Such a source serves only
    vectors of exactly those sizes; the sums and their order are the same
    either way, so the results are too, bit for bit.
    """
    head = 'def linear_layout(p):\n    """Sizes and offsets of the packed controller *p*."""\n'
    if sizes is None:
        items = [f"int(p[_LIN_{name.upper()}])" for name in LINEAR_HEADER]
        return head + "    return (" + ", ".join(items) + ")\n"
    values = {key: int(sizes[key]) for key in ("nz", "ny", "nr", "m", "n")}
    offset = len(LINEAR_HEADER)
    for name, dims in LINEAR_BLOCKS:
        values[name] = offset
        offset += math.prod(values[d] for d in dims)
    return head + "    return (" + ", ".join(str(values[name]) for name in LINEAR_HEADER) + ")\n"


#: The most multiply-adds a linear controller may have for :func:`linear_unrolled_source`
#: to write its sums out term by term (larger ones run the loops of :data:`LINEAR_SOURCE`).
UNROLL_LIMIT = 1024

# Per function: the output (its offset block, its row count) and the terms of each row,
# ``(matrix, input)`` in the order of the sums of LINEAR_SOURCE (z, then y, r, u).
_UNROLLED: tuple[tuple[str, str, str, str, tuple[tuple[str, str], ...]], ...] = (
    ("linear_output", "t, z, y, r, p, u_out", "u_out", "m",
     (("Cc", "z"), ("Dy", "y"), ("Dr", "r"))),
    ("linear_update", "t, z, y, r, u_applied, p, z_out", "z_out", "nz",
     (("Ac", "z"), ("By", "y"), ("Br", "r"), ("Bu", "u"))),
    ("linear_estimate", "t, z, y, r, p, x_out", "x_out", "n",
     (("Ez", "z"), ("Ey", "y"))),
)
_UNROLLED_BASE = {"u_out": "u_op", "z_out": None, "x_out": "x_op"}
_INPUTS = {"z": ("nz", None, "z"), "y": ("ny", "y_op", "y"), "r": ("nr", "r_op", "r"),
           "u": ("m", "u_op", "u_applied")}


def linear_pattern(p: np.ndarray) -> bytes | None:
    """What :func:`linear_unrolled_source` specializes to in the packed vector *p*.

    The sizes, then one byte per matrix coefficient (every block from ``Ac``
    to ``Ey``, in order): 0 for an exact zero, 1 for an exact one, 2 for any
    other number. None for a vector without a header, or one too large to
    be written out term by term (:data:`UNROLL_LIMIT`).
    """
    sizes = linear_sizes(p)
    if sizes is None:
        return None
    start = int(p[LINEAR_HEADER.index("Ac")])
    end = int(p[LINEAR_HEADER.index("u_op")])
    if end - start > UNROLL_LIMIT:
        return None
    block = p[start:end]
    codes = np.where(block == 0.0, 0, np.where(block == 1.0, 1, 2)).astype(np.uint8)
    head = np.array([sizes[k] for k in ("nz", "ny", "nr", "m", "n")], dtype=np.int64)
    return head.tobytes() + codes.tobytes()


def linear_unrolled_source(pattern: bytes) -> str:
    """The linear library (``linear_layout``, ``linear_output``, ``linear_update``,
    ``linear_estimate``) written out for the vectors of one :func:`linear_pattern`.

    Each sum is written term by term with the offsets as literals, each
    input deviation (``y[j] - y_op[j]``...) is computed once, and every
    result is stored after all are computed. Terms whose coefficient is an
    exact zero are left out and an exact one multiplies nothing: with
    finite inputs that gives the very bits of :data:`LINEAR_SOURCE`'s sums
    (the sum starts at ``+0.0`` and is never ``-0.0``, so adding ``+-0.0``
    changes nothing, and ``1.0 * d`` is ``d``). Where an input that such a
    term would multiply is not finite (``0 * inf`` is NaN), the function
    takes the full sums instead, so the results are the same in every case.
    The source serves only vectors of that pattern (their sizes, and
    zeros and ones where the pattern has them).
    """
    head = np.frombuffer(pattern[:40], dtype=np.int64)
    sizes = dict(zip(("nz", "ny", "nr", "m", "n"), (int(v) for v in head), strict=True))
    codes = pattern[40:]
    offsets = dict(sizes)
    offset = len(LINEAR_HEADER)
    for name, dims in LINEAR_BLOCKS:
        offsets[name] = offset
        offset += math.prod(sizes[d] for d in dims)
    base = offsets["Ac"]
    lines = [linear_layout_source(sizes)]

    def deviation(kind: str, j: int) -> str:
        _size, op, arg = _INPUTS[kind]
        return f"{arg}[{j}]" if op is None else f"{arg}[{j}] - p[{offsets[op] + j}]"

    def sums(rows: int, terms: tuple[tuple[str, str], ...], skip: bool, indent: str) -> list[str]:
        out = []
        for i in range(rows):
            expr = None
            for matrix, kind in terms:
                width = sizes[_INPUTS[kind][0]]
                for j in range(width):
                    at = offsets[matrix] + i * width + j
                    code = codes[at - base]
                    if skip and code == 0:
                        continue
                    term = f"d_{kind}{j}" if skip and code == 1 else f"p[{at}] * d_{kind}{j}"
                    expr = f"0.0 + {term}" if expr is None else f"v{i} + {term}"
                    out.append(f"{indent}v{i} = {expr}")
            if expr is None:
                out.append(f"{indent}v{i} = 0.0")
        return out

    for name, args, result, rows_key, terms in _UNROLLED:
        rows = sizes[rows_key]
        used = [(kind, j) for _m, kind in terms for j in range(sizes[_INPUTS[kind][0]])]
        lines.append(f"\n\ndef {name}({args}):")
        lines.append('    """The linear library\'s sums, written out for one pattern of vectors."""')
        lines += [f"    d_{kind}{j} = {deviation(kind, j)}" for kind, j in used]
        # Inputs that multiply an exact zero somewhere: their finiteness decides the path.
        zeroed = sorted({(kind, j) for matrix, kind in terms
                         for i in range(rows) for j in range(sizes[_INPUTS[kind][0]])
                         if codes[offsets[matrix] + i * sizes[_INPUTS[kind][0]] + j - base] == 0})
        op = _UNROLLED_BASE[result]
        stores = [f"{result}[{i}] = " + (f"p[{offsets[op] + i}] + v{i}" if op else f"v{i}")
                  for i in range(rows)]
        if zeroed:
            finite = " + ".join(f"0.0 * d_{kind}{j}" for kind, j in zeroed)
            lines.append(f"    if {finite} == 0.0:")
            lines += sums(rows, terms, True, "        ")
            lines += [f"        {s}" for s in stores]
            lines.append("    else:")
            lines += sums(rows, terms, False, "        ")
            lines += [f"        {s}" for s in stores]
        else:
            lines += sums(rows, terms, False, "    ")
            lines += [f"    {s}" for s in stores]
        if not used and not rows:
            lines.append("    pass")
    return "\n".join(lines) + "\n"


#: The compiled linear controller: plain Python translated to C into every
#: simulation core, and that :class:`LinearController` runs as is in Python.
#: Every sum runs in one fixed order (z, then y, then r, then u), the order the
#: exported C code repeats. It reads its sizes and block offsets through
#: ``linear_layout`` (:func:`linear_layout_source`), defined beside it: from the
#: vector's header in Python and in a nonlinear controller's core, as literals
#: in the core of one linear controller.
LINEAR_SOURCE = '''
def linear_output(t, z, y, r, p, u_out):
    """u = u_op + Cc z + Dy (y - y_op) + Dr (r - r_op) (absolute u, not saturated)."""
    (nz, ny, nr, m, n, o_ac, o_by, o_br, o_bu, o_cc, o_dy, o_dr, o_ez, o_ey,
     o_u0, o_y0, o_r0, o_x0) = linear_layout(p)
    for i in range(m):
        v = 0.0
        for j in range(nz):
            v += p[o_cc + i * nz + j] * z[j]
        for j in range(ny):
            v += p[o_dy + i * ny + j] * (y[j] - p[o_y0 + j])
        for j in range(nr):
            v += p[o_dr + i * nr + j] * (r[j] - p[o_r0 + j])
        u_out[i] = p[o_u0 + i] + v


def linear_update(t, z, y, r, u_applied, p, z_out):
    """z_out = Ac z + By (y - y_op) + Br (r - r_op) + Bu (u_applied - u_op)."""
    (nz, ny, nr, m, n, o_ac, o_by, o_br, o_bu, o_cc, o_dy, o_dr, o_ez, o_ey,
     o_u0, o_y0, o_r0, o_x0) = linear_layout(p)
    for i in range(nz):
        v = 0.0
        for j in range(nz):
            v += p[o_ac + i * nz + j] * z[j]
        for j in range(ny):
            v += p[o_by + i * ny + j] * (y[j] - p[o_y0 + j])
        for j in range(nr):
            v += p[o_br + i * nr + j] * (r[j] - p[o_r0 + j])
        for j in range(m):
            v += p[o_bu + i * m + j] * (u_applied[j] - p[o_u0 + j])
        z_out[i] = v


def linear_estimate(t, z, y, r, p, x_out):
    """x_out = x_op + Ez z + Ey (y - y_op): the state estimate behind the command."""
    (nz, ny, nr, m, n, o_ac, o_by, o_br, o_bu, o_cc, o_dy, o_dr, o_ez, o_ey,
     o_u0, o_y0, o_r0, o_x0) = linear_layout(p)
    for i in range(n):
        v = 0.0
        for j in range(nz):
            v += p[o_ez + i * nz + j] * z[j]
        for j in range(ny):
            v += p[o_ey + i * ny + j] * (y[j] - p[o_y0 + j])
        x_out[i] = p[o_x0 + i] + v
'''

#: Names the linear library defines (a nonlinear controller's source may call them).
LINEAR_FUNCTIONS = ("linear_output", "linear_update", "linear_estimate")

_PY_LINEAR: dict[str, Any] = {}


def _python_linear() -> dict[str, Any]:
    """:data:`LINEAR_SOURCE` executed as plain Python (the reference the core is checked on)."""
    if not _PY_LINEAR:
        namespace: dict[str, Any] = {"math": math, "np": np, **linear_constants()}
        exec(compile(linear_layout_source() + LINEAR_SOURCE, "<equilibrist linear controller>",
                     "exec"), namespace)
        _PY_LINEAR.update({name: namespace[name] for name in LINEAR_FUNCTIONS})
    return _PY_LINEAR


def _frozen(value: object, shape: tuple[int, ...], what: str) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DimensionError(f"{what} is not an array of numbers") from exc
    if arr.size == 0 and math.prod(shape) == 0:
        arr = arr.reshape(shape)
    elif arr.shape != shape:
        if arr.size == math.prod(shape) and arr.ndim <= 1 and len(shape) == 2 and 1 in shape:
            arr = arr.reshape(shape)
        else:
            raise DimensionError(f"{what} has shape {arr.shape}, expected {shape}")
    if not np.all(np.isfinite(arr)):
        raise DimensionError(f"{what} has a value that is not a finite number")
    arr.setflags(write=False)
    return arr


def _shaped(value: object, shape: tuple[int, int]) -> np.ndarray:
    """*value* as a float array, reshaped to *shape* when it has that many elements."""
    arr = np.asarray(value, dtype=float)
    return arr.reshape(shape) if arr.size == shape[0] * shape[1] else arr


def _optional(value: object | None) -> np.ndarray | None:
    return None if value is None else np.asarray(value, dtype=float)


def _limits(value: object | None, m: int, fill: float, what: str) -> np.ndarray:
    if value is None:
        arr = np.full(m, fill)
    else:
        arr = np.array(value, dtype=float).reshape(-1)
        if arr.shape != (m,):
            raise DimensionError(f"{what} has {arr.size} values, expected {m}")
        if np.any(np.isnan(arr)):
            raise DimensionError(f"{what} has a value that is not a number")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class LinearController:
    """A digital linear controller in one state-space form (see the module docstring).

    Sizes: ``n`` plant states, ``m`` inputs, ``ny`` measured outputs, ``nr``
    references, ``nz`` controller states. All matrices are read-only
    float64 arrays; vectors are 1-D.

    Attributes
    ----------
    Ac, By, Br, Bu, Cc, Dy, Dr:
        The form's matrices.
    Ez, Ey:
        The estimate ``x_hat = x_op + Ez z + Ey dy`` (zero-sized when
        ``has_estimate`` is False).
    x_op, u_op, y_op, r_op:
        Operating point of the plant's states and inputs, and the measured
        and tracked outputs there.
    z0:
        The controller state at the start of a run.
    state_map:
        ``(nz, n)``: the controller state that belongs to an estimate
        ``x`` of the plant's state is ``state_map @ (x - x_op)`` (to start
        the controller at a given estimate).
    rate:
        Sample rate [Hz] the controller was made for; None for a gain that
        is applied at whatever rate the run uses.
    state_names, input_names, output_names, tracked_names:
        The plant's states and inputs, the measured outputs (``y``, states
        of the plant) and the tracked outputs (``r``).
    u_min, u_max:
        Input limits the command is saturated to (the plant's actuator
        limits apply in the simulation; these are what the exported code uses).
    kind, form:
        ``"lqr"``, ``"lqg"``, ``"none"`` or a builder's name; the Kalman form
        (``"current"``, ``"predictor"``) or ``""``.
    has_estimate:
        Whether ``Ez``, ``Ey`` give a state estimate.
    design:
        The design it came from, if any (not compared, not printed).
    """

    Ac: np.ndarray
    By: np.ndarray
    Br: np.ndarray
    Bu: np.ndarray
    Cc: np.ndarray
    Dy: np.ndarray
    Dr: np.ndarray
    Ez: np.ndarray
    Ey: np.ndarray
    x_op: np.ndarray
    u_op: np.ndarray
    y_op: np.ndarray
    r_op: np.ndarray
    z0: np.ndarray
    state_map: np.ndarray
    rate: float | None
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    tracked_names: tuple[str, ...] = ()
    u_min: np.ndarray | None = None
    u_max: np.ndarray | None = None
    kind: str = "linear"
    form: str = ""
    has_estimate: bool = True
    design: Any = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        n, m = len(self.state_names), len(self.input_names)
        ny, nr = len(self.output_names), len(self.tracked_names)
        nz = int(np.size(self.z0))
        sizes = {"n": n, "m": m, "ny": ny, "nr": nr, "nz": nz}
        for name, dims in LINEAR_BLOCKS:
            shape = tuple(sizes[d] for d in dims)
            if name in ("Ez", "Ey") and not self.has_estimate:
                shape = (0, shape[1])
            object.__setattr__(self, name, _frozen(getattr(self, name), shape, name))
        object.__setattr__(self, "z0", _frozen(self.z0, (nz,), "z0"))
        object.__setattr__(self, "state_map", _frozen(self.state_map, (nz, n), "state_map"))
        for label in ("state_names", "input_names", "output_names", "tracked_names"):
            object.__setattr__(self, label, tuple(getattr(self, label)))
        object.__setattr__(self, "u_min", _limits(self.u_min, m, -math.inf, "u_min"))
        object.__setattr__(self, "u_max", _limits(self.u_max, m, math.inf, "u_max"))
        if self.rate is not None and not (math.isfinite(self.rate) and self.rate > 0):
            raise DesignError(f"the controller's rate must be a positive number of Hz, got {self.rate!r}")
        missing = [o for o in (*self.output_names, *self.tracked_names) if o not in self.state_names]
        if missing:
            raise DesignError(
                f"measured or tracked output(s) {', '.join(missing)} are not states "
                f"({', '.join(self.state_names)})"
            )

    def __getstate__(self) -> dict[str, Any]:
        # The design stays behind when the controller goes to another process.
        state = {**self.__dict__, "design": None}
        state.pop("_packed", None)
        return state

    # -- sizes -------------------------------------------------------------------------------
    @property
    def n_states(self) -> int:
        """Plant states ``n``."""
        return len(self.state_names)

    @property
    def n_inputs(self) -> int:
        return len(self.input_names)

    @property
    def n_outputs(self) -> int:
        """Measured outputs ``ny``."""
        return len(self.output_names)

    @property
    def n_references(self) -> int:
        return len(self.tracked_names)

    @property
    def n_z(self) -> int:
        """Controller states ``nz``."""
        return int(self.z0.size)

    @property
    def outputs(self) -> tuple[str, ...]:
        """The measured states, in the order of ``y`` (what the simulator measures)."""
        return self.output_names

    @property
    def tracked(self) -> tuple[str, ...]:
        return self.tracked_names

    @property
    def output_index(self) -> tuple[int, ...]:
        return tuple(self.state_names.index(o) for o in self.output_names)

    @property
    def tracked_index(self) -> tuple[int, ...]:
        return tuple(self.state_names.index(o) for o in self.tracked_names)

    # -- the numbers the compiled core and the C code read -------------------------------------
    def packed(self) -> np.ndarray:
        """The controller as one float vector: :data:`LINEAR_HEADER`, then :data:`LINEAR_BLOCKS`.

        This is the parameter vector of the compiled ``linear_*`` functions
        (a new array each call).
        """
        return self._packed.copy()

    @cached_property
    def _packed(self) -> np.ndarray:
        # Without an estimate the estimate has no rows (linear_estimate writes nothing).
        sizes = {"n": int(self.Ez.shape[0]), "m": self.n_inputs, "ny": self.n_outputs,
                 "nr": self.n_references, "nz": self.n_z}
        header = np.zeros(len(LINEAR_HEADER))
        for key in ("nz", "ny", "nr", "m", "n"):
            header[LINEAR_HEADER.index(key)] = sizes[key]
        parts = [header]
        offset = header.size
        for name, _dims in LINEAR_BLOCKS:
            block = np.asarray(getattr(self, name), dtype=float).reshape(-1)
            header[LINEAR_HEADER.index(name)] = offset
            parts.append(block)
            offset += block.size
        return np.concatenate(parts)

    # -- the controller in Python (the very source the core compiles) ---------------------------
    def output(self, z: object, y: object, r: object = ()) -> np.ndarray:
        """The command ``u`` (absolute, before saturation) for state *z*, measurements *y*, references *r*."""
        u = np.zeros(self.n_inputs)
        _python_linear()["linear_output"](0.0, *self._vectors(z, y, r), self.packed(), u)
        return u

    def update(self, z: object, y: object, r: object, u_applied: object) -> np.ndarray:
        """The next controller state after *u_applied* (absolute) acted."""
        zn = np.zeros(self.n_z)
        ua = np.asarray(u_applied, dtype=float).reshape(self.n_inputs)
        _python_linear()["linear_update"](0.0, *self._vectors(z, y, r), ua, self.packed(), zn)
        return zn

    def estimate(self, z: object, y: object) -> np.ndarray | None:
        """The absolute state estimate behind the command (None without an estimate)."""
        if not self.has_estimate:
            return None
        x = np.zeros(self.n_states)
        zv, yv, rv = self._vectors(z, y, ())
        _python_linear()["linear_estimate"](0.0, zv, yv, rv, self.packed(), x)
        return x

    def _vectors(self, z: object, y: object, r: object) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        zv = np.asarray(z, dtype=float).reshape(self.n_z)
        yv = np.asarray(y, dtype=float).reshape(self.n_outputs)
        rv = np.asarray(r, dtype=float).reshape(-1)
        if rv.size != self.n_references:
            rv = np.resize(rv, self.n_references) if rv.size else np.array(self.r_op)
        return zv, yv, rv

    def runtime(self, state_names: Sequence[str] | None = None) -> LinearRuntime:
        """This controller as a :class:`PythonController` (for checks of the compiled core)."""
        return LinearRuntime(self)

    def start_at(self, x_estimate: object) -> LinearController:
        """The same controller started from the absolute state estimate *x_estimate*."""
        dx = np.asarray(x_estimate, dtype=float).reshape(self.n_states) - self.x_op
        return _replace(self, z0=self.state_map @ dx)

    def describe(self) -> dict[str, object]:
        """The controller as JSON-able data (recorded with every result)."""
        out: dict[str, object] = {"kind": self.kind, "rate": self.rate,
                                  "outputs": list(self.output_names),
                                  "tracked": list(self.tracked_names)}
        if self.form:
            out["form"] = self.form
        for name, _dims in LINEAR_BLOCKS[:7]:
            out[name] = np.asarray(getattr(self, name)).tolist()
        return out

    @property
    def fingerprint(self) -> str:
        """12 hex digits identifying the controller's numbers and names."""
        h = hashlib.sha256(self.packed().tobytes())
        for names in (self.state_names, self.input_names, self.output_names, self.tracked_names):
            h.update(",".join(names).encode() + b";")
        return h.hexdigest()[:12]

    # -- constructors --------------------------------------------------------------------------
    @classmethod
    def state_feedback(
        cls,
        K: object,
        *,
        x_op: object,
        u_op: object,
        state_names: Sequence[str] | None = None,
        input_names: Sequence[str] | None = None,
        Kc: object | None = None,
        tracked: Sequence[str] = (),
        rate: float | None = None,
        u_min: object | None = None,
        u_max: object | None = None,
        design: Any = None,
    ) -> LinearController:
        """LQR: ``u = u_op - K (x - x_op) + Kc (r - r_op)`` on the measured full state.

        No controller state (``nz = 0``): ``Dy = -K``, ``Dr = Kc``; the
        estimate is the measured state (``Ey = I``).
        """
        xo = np.array(x_op, dtype=float).reshape(-1)
        uo = np.array(u_op, dtype=float).reshape(-1)
        n, m = xo.size, uo.size
        states = tuple(state_names) if state_names is not None else tuple(f"x{i}" for i in range(n))
        inputs = tuple(input_names) if input_names is not None else tuple(f"u{i}" for i in range(m))
        Km = _frozen(_shaped(K, (m, n)), (m, n), "K")
        tracked = tuple(tracked)
        if Kc is None:
            if tracked:
                raise DesignError("tracked outputs given without a reference gain Kc")
            Kcm = np.zeros((m, 0))
        else:
            if not tracked:
                raise DesignError("a reference gain Kc needs the names of the tracked outputs")
            Kcm = _frozen(_shaped(Kc, (m, len(tracked))), (m, len(tracked)), "Kc")
        r_op = xo[[states.index(t) for t in tracked if t in states]]
        return cls(
            Ac=np.zeros((0, 0)), By=np.zeros((0, n)), Br=np.zeros((0, len(tracked))),
            Bu=np.zeros((0, m)), Cc=np.zeros((m, 0)), Dy=-Km, Dr=Kcm,
            Ez=np.zeros((n, 0)), Ey=np.eye(n), x_op=xo, u_op=uo, y_op=xo, r_op=r_op,
            z0=np.zeros(0), state_map=np.zeros((0, n)), rate=rate, state_names=states,
            input_names=inputs, output_names=states, tracked_names=tracked,
            u_min=_optional(u_min), u_max=_optional(u_max), kind="lqr", design=design,
        )

    @classmethod
    def lqg(
        cls,
        K: object,
        *,
        Ad: object,
        Bd: object,
        Kf: object,
        outputs: Sequence[str],
        x_op: object,
        u_op: object,
        rate: float,
        form: str = "current",
        state_names: Sequence[str] | None = None,
        input_names: Sequence[str] | None = None,
        Kc: object | None = None,
        tracked: Sequence[str] = (),
        x_hat0: object | None = None,
        u_min: object | None = None,
        u_max: object | None = None,
        design: Any = None,
    ) -> LinearController:
        """Discrete LQG: Kalman filter on the measured states *outputs*, feedback on its estimate.

        The controller state is the predicted deviation ``xhat_{k|k-1}``.
        ``form="current"`` (``Kf = M``): ``xhat = z + M (dy - C z)``,
        ``u = u_op - K xhat + Kc dr``, ``z+ = Ad xhat + Bd du``.
        ``form="predictor"`` (``Kf = L``): ``u = u_op - K z + Kc dr``,
        ``z+ = Ad z + Bd du + L (dy - C z)``. The matrices come from
        :func:`equilibrist.control.lqg.lqg_compensator` (inputs ``[u; y; r]``).
        *x_hat0* is the starting estimate as a deviation (default zero).
        """
        from equilibrist.control import fixed
        from equilibrist.control.lqg import lqg_compensator
        from equilibrist.numeric.linear import LinearModel

        xo = np.array(x_op, dtype=float).reshape(-1)
        uo = np.array(u_op, dtype=float).reshape(-1)
        n, m = xo.size, uo.size
        states = tuple(state_names) if state_names is not None else tuple(f"x{i}" for i in range(n))
        inputs = tuple(input_names) if input_names is not None else tuple(f"u{i}" for i in range(m))
        outs = tuple(outputs)
        bad = [o for o in outs if o not in states]
        if bad:
            raise DesignError(f"measured output(s) {', '.join(bad)} are not states ({', '.join(states)})")
        C = np.zeros((len(outs), n))
        for row, o in enumerate(outs):
            C[row, states.index(o)] = 1.0
        if form not in ("current", "predictor"):
            raise DesignError(f"Kalman filter form {form!r}: expected 'current' or 'predictor'")
        plant = LinearModel(
            A=_frozen(Ad, (n, n), "Ad"), B=_frozen(_shaped(Bd, (n, m)), (n, m), "Bd"),
            C=C, D=np.zeros((len(outs), m)), state_names=states, input_names=inputs,
            output_names=outs, x0=xo, u0=uo, dt=1.0 / float(rate),
        )
        Km = _shaped(K, (m, n))
        Kfm = _shaped(Kf, (n, len(outs)))
        tracked = tuple(tracked)
        if Kc is not None and not tracked:
            raise DesignError("a reference gain Kc needs the names of the tracked outputs")
        comp = lqg_compensator(plant, Km, Kfm, Kc, tracked=tracked, form=form)
        p, nr = len(outs), len(comp.tracked_names)
        Kf_arr = np.asarray(Kfm, dtype=float)
        if form == "current":
            Ez, Ey = np.eye(n) - fixed.matmul(Kf_arr, C), Kf_arr
        else:
            Ez, Ey = np.eye(n), np.zeros((n, p))
        z0 = np.zeros(n) if x_hat0 is None else np.asarray(x_hat0, dtype=float).reshape(n)
        return cls(
            Ac=comp.A, Bu=comp.B[:, :m], By=comp.B[:, m : m + p], Br=comp.B[:, m + p : m + p + nr],
            Cc=comp.C, Dy=comp.D[:, m : m + p], Dr=comp.D[:, m + p : m + p + nr],
            Ez=Ez, Ey=Ey, x_op=xo, u_op=uo, y_op=fixed.matvec(C, xo), r_op=comp.r0, z0=z0,
            state_map=np.eye(n), rate=float(rate), state_names=states, input_names=inputs,
            output_names=outs, tracked_names=comp.tracked_names, u_min=_optional(u_min),
            u_max=_optional(u_max), kind="lqg", form=form, design=design,
        )

    @classmethod
    def open_loop(cls, *, x_op: object, u_op: object, state_names: Sequence[str],
                  input_names: Sequence[str], outputs: Sequence[str] = ()) -> LinearController:
        """No feedback: ``u = u_op`` (the simulator adds an open-loop signal on top)."""
        xo = np.array(x_op, dtype=float).reshape(-1)
        uo = np.array(u_op, dtype=float).reshape(-1)
        n, m, ny = xo.size, uo.size, len(outputs)
        states = tuple(state_names)
        y_op = xo[[states.index(o) for o in outputs]] if ny else np.zeros(0)
        return cls(
            Ac=np.zeros((0, 0)), By=np.zeros((0, ny)), Br=np.zeros((0, 0)), Bu=np.zeros((0, m)),
            Cc=np.zeros((m, 0)), Dy=np.zeros((m, ny)), Dr=np.zeros((m, 0)),
            Ez=np.zeros((0, 0)), Ey=np.zeros((0, ny)), x_op=xo, u_op=uo, y_op=y_op,
            r_op=np.zeros(0), z0=np.zeros(0), state_map=np.zeros((0, n)), rate=None,
            state_names=states, input_names=tuple(input_names), output_names=tuple(outputs),
            kind="none", has_estimate=False,
        )

    @classmethod
    def from_design(cls, design: Design, *, kind: str = "lqg", tracking: bool = False,
                    u_min: object | None = None, u_max: object | None = None) -> LinearController:
        """The ``"lqr"`` or ``"lqg"`` controller of a discrete :class:`~equilibrist.control.design.Design`.

        Its discrete gain (``lqr`` with a continuous design applies the
        continuous gain at whatever rate the run has); for ``lqg`` the
        discrete Kalman filter in the design's form. *tracking* adds the
        reference gain (an error naming why when the design has none).
        The input limits default to the design's parameters
        (``<input>_min``, ``<input>_max``).
        """
        if kind not in ("lqr", "lqg"):
            raise ControllerError(f"controller kind {kind!r}: expected 'lqr' or 'lqg'")
        plant = design.plant
        params = dict(design.params)
        if u_min is None:
            u_min = [float(params.get(f"{i}_min", -math.inf)) for i in plant.input_names]
        if u_max is None:
            u_max = [float(params.get(f"{i}_max", math.inf)) for i in plant.input_names]
        kc = None
        tracked: tuple[str, ...] = ()
        if tracking:
            if design.Kc is None:
                raise ControllerError(
                    f"reference tracking needs K_c: {design.kc_note or 'the design has no reference gain'}"
                )
            kc, tracked = np.asarray(design.Kc, dtype=float), tuple(design.tracked)
        if kind == "lqr":
            return cls.state_feedback(
                design.K, x_op=plant.x0, u_op=plant.u0, state_names=plant.state_names,
                input_names=plant.input_names, Kc=kc, tracked=tracked, rate=design.rate,
                u_min=u_min, u_max=u_max, design=design,
            )
        if design.discrete is None or design.rate is None:
            raise ControllerError(
                "an LQG controller needs a design with a sample rate (its discrete Kalman "
                "filter): design(system, rate=...)"
            )
        return cls.lqg(
            design.K, Ad=design.discrete.A, Bd=design.discrete.B, Kf=design.Kf,
            outputs=plant.output_names, x_op=plant.x0, u_op=plant.u0, rate=float(design.rate),
            form=design.kalman_form, state_names=plant.state_names,
            input_names=plant.input_names, Kc=kc, tracked=tracked, u_min=u_min, u_max=u_max,
            design=design,
        )


def _replace(ctrl: LinearController, **changes: Any) -> LinearController:
    from dataclasses import replace

    return replace(ctrl, **changes)


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
    settings: Mapping[str, Any] = field(default_factory=dict)

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

    def python_functions(self) -> dict[str, Callable[..., Any]]:
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
                                 "eq_log": libm.eq_log, "eq_exp": libm.eq_exp}
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


#: The argument types of the contract's functions in the C translation (``t`` a float,
#: the rest 1-D float arrays), by role.
CONTRACT_TYPES = {
    "output": ("f", "F1", "F1", "F1", "F1", "F1"),
    "update": ("f", "F1", "F1", "F1", "F1", "F1", "F1"),
    "estimate": ("f", "F1", "F1", "F1", "F1", "F1"),
}
_TRANSLATED: dict[str, None] = {}


def translate_controller(source: str, roles: Mapping[str, str], *, prefix: str = "ctrl_",
                         library: str | None = None) -> tuple[Any, dict[str, Any]]:
    """A controller's functions translated to C (:mod:`equilibrist.native.pyc`).

    *roles* maps each role of the contract (``output``, ``update``,
    ``estimate``) to the function of *source* that plays it; the C names
    start with *prefix*. The linear library (``linear_output``...) is in
    scope, unless *library* gives other functions (``""``: none). Returns the
    translated module (its :meth:`~equilibrist.native.pyc.Module.c_source`)
    and the translated function of each role. Raises
    :class:`~equilibrist.native.pyc.TranslationError`.
    """
    from equilibrist.native.pyc import Module

    mod = Module(source, constants=linear_constants(), prefix=prefix,
                 library=linear_layout_source() + LINEAR_SOURCE if library is None else library)
    return mod, {role: mod.function(name, CONTRACT_TYPES[role]) for role, name in roles.items()}


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
        between the two regions is the hysteresis.

    The linear controller's own state runs (its filter keeps estimating)
    in both modes, so it takes over with a current estimate.
    """
    return f'''
def output(t, z, y, r, params, u_out):
    a0, l0 = 1, 1 + int(params[0])
    nza = int(z.shape[0]) - 1 - int(params[l0 + _LIN_NZ])
    mode = z[0]
    if mode == 0.0 and ({catch}):
        mode = 1.0
    elif mode == 1.0 and ({leave}):
        mode = 0.0
    if mode == 1.0:
        linear_output(t, z[1 + nza:], y, r, params[l0:], u_out)
    else:
        first_output(t, z[1:1 + nza], y, r, params[a0:l0], u_out)


def update(t, z, y, r, u_applied, params, z_out):
    a0, l0 = 1, 1 + int(params[0])
    nza = int(z.shape[0]) - 1 - int(params[l0 + _LIN_NZ])
    mode = z[0]
    if mode == 0.0 and ({catch}):
        mode = 1.0
    elif mode == 1.0 and ({leave}):
        mode = 0.0
    z_out[0] = mode
    first_update(t, z[1:1 + nza], y, r, u_applied, params[a0:l0], z_out[1:1 + nza])
    linear_update(t, z[1 + nza:], y, r, u_applied, params[l0:], z_out[1 + nza:])
'''


# -- controllers written in Python ----------------------------------------------------------
@runtime_checkable
class PythonController(Protocol):
    """A controller written in Python, called once per sample by the simulator.

    Attributes
    ----------
    rate:
        The sample rate [Hz] it was written for, or None (the run's rate).
    outputs:
        The states it measures, in the order of ``y``, or None (the run's
        ``outputs``, else the system's default outputs).
    estimate:
        Its absolute state estimate after the last :meth:`output`, or None.
    """

    rate: float | None
    outputs: tuple[str, ...] | None
    estimate: np.ndarray | None

    def reset(self) -> None:
        """Start again (called before every run)."""

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        """The command (absolute inputs) at sample time *t* from measurements *y* and references *r*."""
        ...

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        """Advance the controller's state: *u_applied* is what acted (saturated, delayed)."""


class PythonControllerBase:
    """Defaults of the :class:`PythonController` protocol: subclass and write ``output``.

    ``rate``, ``outputs`` and ``estimate`` are None; ``reset`` and
    ``update`` do nothing.
    """

    rate: float | None = None
    outputs: tuple[str, ...] | None = None
    estimate: np.ndarray | None = None

    def reset(self) -> None:
        """Nothing to reset."""

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        """No state to advance."""


class StepAdapter(PythonControllerBase):
    """The older step interface as a :class:`PythonController` (kept for existing code).

    Wraps an object with ``step(t, y, r) -> u`` (and, optionally, the old
    ``reset()``, ``applied(u)``, ``estimate``, ``rate`` and ``outputs``
    attributes) or a plain function ``(t, y, r) -> u``. This adapter is the
    only place those optional attributes are looked up.
    """

    def __init__(self, target: Any) -> None:
        self.target = target
        is_function = not (hasattr(target, "step") and callable(target.step))
        self._step: Callable[..., Any] = target if is_function else target.step
        self._reset = None if is_function else getattr(target, "reset", None)
        self._applied = None if is_function else getattr(target, "applied", None)
        self.rate = None if is_function else getattr(target, "rate", None)
        declared = None if is_function else getattr(target, "outputs", None)
        self.outputs = None if declared is None else tuple(declared)
        self._has_estimate = (not is_function) and hasattr(target, "estimate")
        self.estimate = None

    def reset(self) -> None:
        if callable(self._reset):
            self._reset()
        self.estimate = None

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        u = self._step(t, y, r)
        est = getattr(self.target, "estimate", None) if self._has_estimate else None
        self.estimate = None if est is None else np.asarray(est, dtype=float)
        return np.asarray(u, dtype=float)

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        if callable(self._applied):
            self._applied(u_applied)


class LinearRuntime(PythonControllerBase):
    """A :class:`LinearController` run in Python, sample by sample (the core's reference)."""

    def __init__(self, ctrl: LinearController) -> None:
        self.c = ctrl
        self.rate = ctrl.rate
        self.outputs = ctrl.output_names
        self.reset()

    def reset(self) -> None:
        self.z = np.array(self.c.z0)
        self.estimate = None

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        self.estimate = self.c.estimate(self.z, y)
        return self.c.output(self.z, y, r)

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        self.z = self.c.update(self.z, y, r, u_applied)

    # The older step interface (``step`` then ``applied``), for code written against it.
    def step(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        """:meth:`output`, remembering *t*, *y*, *r* for :meth:`applied`."""
        self._last = (t, np.array(y, dtype=float), np.array(r, dtype=float))
        return self.output(t, y, r)

    def applied(self, u: np.ndarray) -> None:
        """:meth:`update` with the arguments of the last :meth:`step`."""
        t, y, r = self._last
        self.update(t, y, r, u)


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


AnyController = LinearController | NonlinearController | PythonController


@runtime_checkable
class DescribedController(Protocol):
    """A controller that describes itself (the linear, nonlinear and MPC controllers)."""

    def describe(self) -> dict[str, object]:
        """Its kind and settings, for ``design`` and reports (JSON-ready)."""
        ...


def describe_controller(ctrl: AnyController, kind: str) -> dict[str, object]:
    """``ctrl.describe()``, or ``{"kind": kind}`` for a controller that does not describe itself."""
    if isinstance(ctrl, DescribedController):
        return ctrl.describe()
    return {"kind": kind}


def measured_outputs(ctrl: AnyController | None) -> tuple[str, ...] | None:
    """The states *ctrl* measures, in the order of its ``y`` (None: the run's outputs)."""
    if ctrl is None:
        return None
    if isinstance(ctrl, LinearController | NonlinearController):
        return ctrl.output_names
    return ctrl.outputs


def python_controller_name(py: PythonController) -> str:
    """The class (or function) name of the controller the user wrote (through the adapter)."""
    target = py.target if isinstance(py, StepAdapter) else py
    if isinstance(target, types.FunctionType | types.MethodType | types.BuiltinFunctionType):
        return target.__name__
    return type(target).__name__


def as_python_controller(obj: object) -> PythonController:
    """*obj* as a :class:`PythonController`: itself, or through :class:`StepAdapter`."""
    if all(callable(getattr(obj, name, None)) for name in ("reset", "output", "update")) and all(
        hasattr(obj, a) for a in ("rate", "outputs", "estimate")
    ):
        return obj  # type: ignore[return-value]
    if (hasattr(obj, "step") and callable(obj.step)) or callable(obj):
        return StepAdapter(obj)
    raise ControllerError(
        f"{type(obj).__name__} is not a controller: expected a LinearController, a "
        "NonlinearController, a PythonController (reset, output, update), an object with "
        "step(t, y, r), or a function (t, y, r) -> u"
    )


# -- the registry of controller kinds lives in equilibrist.control.kinds ---------------------
#: The project's own kinds, in the command line's order (the registry lists every kind:
#: :func:`equilibrist.control.kinds.names`).
CONTROLLER_KINDS = ("lqr", "lqg", "swingup", "mpc", "tvlqr", "none")


def __getattr__(name: str) -> Any:
    if name == "ControllerRequest":  # moved to equilibrist.control.kinds
        from equilibrist.control.kinds import ControllerRequest

        return ControllerRequest
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def register_controller(name: str) -> Callable[[Callable[[Any], Any]], Callable[[Any], Any]]:
    """Decorator: *builder* (request -> controller) as the kind *name* in this process; a
    kind of its own module (:class:`equilibrist.control.kinds.ControllerKind`) says more."""

    def add(builder: Callable[[Any], Any]) -> Callable[[Any], Any]:
        from equilibrist.control.kinds import ControllerKind, register

        register(ControllerKind(name=name, label=name, help=name, build=builder))
        return builder

    return add


def registered_controllers() -> tuple[str, ...]:
    """The names of every controller kind (:func:`equilibrist.control.kinds.names`)."""
    from equilibrist.control.kinds import names

    return names()


def build_controller(name: str, request: Any) -> LinearController | NonlinearController | PythonController | None:
    """The controller of kind *name* for *request* (:func:`equilibrist.control.kinds.build`).

    Raises
    ------
    ControllerError
        An unknown name or one that does not apply to the system (one line).
    """
    from equilibrist.control.kinds import KindError, get

    try:
        kind = get(name)
    except KindError:
        from equilibrist.control.kinds import names

        raise ControllerError(f"controller {name!r} is unknown for {request.system.key}: "
                              f"expected one of {', '.join(names())}") from None
    result: LinearController | NonlinearController | PythonController | None = kind.make(request)
    return result


__all__ = [
    "CONTRACT_TYPES",
    "CONTROLLER_KINDS",
    "LINEAR_BLOCKS",
    "LINEAR_HEADER",
    "LINEAR_SOURCE",
    "AnyController",
    "ControllerError",
    "LinearController",
    "LinearRuntime",
    "NonlinearController",
    "NonlinearRuntime",
    "PythonController",
    "PythonControllerBase",
    "StepAdapter",
    "as_python_controller",
    "build_controller",
    "check_source",
    "contract_namespace",
    "linear_constants",
    "linear_layout_source",
    "linear_sizes",
    "register_controller",
    "registered_controllers",
    "supervisor_source",
    "translate_controller",
]
