"""Any nonlinear controller as a C99 library, translated from its one Python source.

:func:`nonlinear_files` writes ``<name>.h`` and ``<name>.c`` of a
:class:`~equilibrist.control.controller.Source`: its
``output``, ``update`` (and ``estimate``) translated by
:mod:`equilibrist.native.pyc`, the translation the simulation core compiles
(the same IEEE operations in the same order as the Python source), its
parameter vector and initial state as ``static const`` arrays, and four
functions around them. Compiled without contraction of multiply-adds
(``-ffp-contract=off``), the library gives the Python controller's
commands bit for bit on the same inputs (with the same C library's ``sin``,
``cos``...: the header names the ``<math.h>`` functions it calls).

Every function of the translation, and the helpers it needs (the
prelude's ``eq_modf``..., the project's ``eq_sin``/``eq_cos``/``eq_log``/``eq_exp``
when the source calls them), is ``static``; the only external symbols are
``<name>_init``, ``<name>_output``, ``<name>_update`` and
``<name>_estimate``, so two exported controllers link into one firmware.
No dynamic memory.

The API (``t``: the sample's time, ``k / rate`` in the simulation; ``r``
only for a controller that tracks references; ``estimate`` only for one
that has it)::

    void <name>_init(<name>_state *s);
    void <name>_output(const <name>_state *s, double t, const double y[NY], const double r[NR], double u[NU]);
    void <name>_update(<name>_state *s, double t, const double y[NY], const double r[NR], const double u_applied[NU]);
    void <name>_estimate(const <name>_state *s, double t, const double y[NY], const double r[NR], double x[NX]);

As the Python runtime (:meth:`Source.runtime`) does, ``u``
and ``x`` are zeroed before the controller's function writes them and
``update`` writes into a zeroed state that replaces the old one.

The controller is read through :class:`Source`, the attributes a
:class:`~equilibrist.control.nonlinear.Source` has; its exporter
(recorded vectors, the folder) is :mod:`equilibrist.export.nonlinear_c`.
"""
from __future__ import annotations

import ctypes
import hashlib
import re
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from equilibrist.errors import ExportError
from equilibrist.native import pyc
from equilibrist.native.c_text import c_identifier
from equilibrist.native.controller_c import translate_controller
from equilibrist.native.firmware import Adapter
from equilibrist.native.make_check import check_files as shared_check_files
from equilibrist.native.shared_library import build_shared_library
from equilibrist.numeric import libm

if TYPE_CHECKING:
    from equilibrist.numeric.system import System


class Source(Protocol):
    """What the library is written from: a controller's source, numbers and names
    (:class:`~equilibrist.control.nonlinear.Source` has them)."""

    @property
    def name(self) -> str: ...
    @property
    def source(self) -> str: ...
    @property
    def params(self) -> np.ndarray: ...
    @property
    def z0(self) -> np.ndarray: ...
    @property
    def x_op(self) -> np.ndarray: ...
    @property
    def n_z(self) -> int: ...
    @property
    def rate(self) -> float: ...
    @property
    def state_names(self) -> tuple[str, ...]: ...
    @property
    def input_names(self) -> tuple[str, ...]: ...
    @property
    def output_names(self) -> tuple[str, ...]: ...
    @property
    def tracked_names(self) -> tuple[str, ...]: ...
    @property
    def has_estimate(self) -> bool: ...
    @property
    def reads_time(self) -> bool: ...
    def title(self) -> str: ...


#: The ``<math.h>`` functions a translated library may call (what its header names).
C_MATH = ("acos", "asin", "atan", "atan2", "ceil", "copysign", "cos", "cosh", "exp", "expm1",
          "fabs", "floor", "fmod", "frexp", "hypot", "log", "log10", "log1p", "pow", "sin",
          "sinh", "sqrt", "tan", "tanh", "trunc")


@dataclass(frozen=True)
class Interface:
    """What the exported functions take besides the state, ``y`` and ``u``.

    *time*: a ``double t`` after the state (else the controller is handed
    ``t = 0``: only for a source that does not read it); *references*: a
    ``const double r[NR]`` after ``y`` (else ``r`` is empty).
    """

    time: bool = True
    references: bool = False


def interface_of(ctrl: Source) -> Interface:
    """The export's interface: the time unless *ctrl*'s type never reads it (the swing-up),
    references when *ctrl* tracks some."""
    return Interface(time=ctrl.reads_time, references=bool(ctrl.tracked_names))


def math_functions(c_source: str) -> tuple[str, ...]:
    """The ``<math.h>`` functions *c_source* calls, sorted."""
    return tuple(f for f in C_MATH if re.search(rf"(?<![\w.]){f}\s*\(", c_source))


def _prelude(code: str) -> str:
    """The functions of :data:`pyc.PRELUDE` that *code* calls (all ``static inline``)."""
    blocks = re.split(r"\n(?=static inline )", pyc.PRELUDE.strip("\n"))
    named = {}
    for block in blocks:
        found = re.match(r"static inline [\w ]+?(\w+)\(", block)
        if found is None:
            raise AssertionError(f"a prelude block without a function: {block[:40]!r}")
        named[found.group(1)] = block
    used: set[str] = set()
    text = code
    while True:
        new = {n for n in named if n not in used and re.search(rf"\b{n}\(", text)}
        if not new:
            break
        used |= new
        text += "".join(named[n] for n in new)
    return "".join(block + "\n" for n, block in named.items() if n in used)


@dataclass(frozen=True)
class Translation:
    """A controller's functions in C: the code (helpers first) and the C names of the
    contract's functions."""

    code: str
    names: Mapping[str, str]


def translate(ctrl: Source, prefix: str) -> Translation:
    """*ctrl*'s ``output``, ``update`` (and ``estimate``) in C, every function ``static``
    and named with *prefix*, with the helpers they call."""
    wanted = ("output", "update", "estimate") if ctrl.has_estimate else ("output", "update")
    try:
        mod, fns = translate_controller(ctrl.source, {w: w for w in wanted}, prefix=prefix)
        names = {w: fn.name for w, fn in fns.items()}
    except pyc.TranslationError as exc:
        raise ExportError(f"the {ctrl.name} controller's source: {exc}") from None
    code = mod.c_source()
    parts = []
    if re.search(r"\beq_(sin|cos|log|exp|atan|tanh)\(", code):
        # The project's own sin, cos (and log, exp; exp needs log's constants, so log comes
        # with it): static, the unused ones kept quiet.
        log = re.search(r"\beq_(log|exp)\(", code) is not None
        parts += [libm.c_source(log=log, exp=re.search(r"\beq_exp\(", code) is not None,
                                atan=re.search(r"\beq_atan\(", code) is not None,
                                tanh=re.search(r"\beq_tanh\(", code) is not None),
                  f"\nstatic inline void {prefix}_libm_used(void)\n{{\n"
                  "    (void)eq_sin;\n    (void)eq_cos;\n"
                  + ("    (void)eq_log;\n" if log and not re.search(r"\beq_log\(", code) else "")
                  + "}\n"]
    prelude = _prelude(code)
    if prelude:
        parts += ["\n/* Python's rules for min, max, % and // (equilibrist.native.pyc). */\n",
                  prelude]
    parts += ["\n/* ---- the controller's functions, translated from its Python source ---- */\n",
              code]
    return Translation("".join(parts), names)


def _c_array(values: np.ndarray) -> str:
    """An initializer of *values* (``repr`` digits: exact), at least one element."""
    vals = [repr(float(v)) for v in np.asarray(values, dtype=float).reshape(-1)] or ["0.0"]
    rows = [", ".join(vals[i:i + 4]) for i in range(0, len(vals), 4)]
    return "{\n    " + ",\n    ".join(rows) + "\n}"


def _arg(kind: str, name: str, size: int) -> str:
    return f"{kind} {name}[{size}]" if size > 0 else f"{kind} *{name}"


def library_files(ctrl: Source, *, name: str, interface: Interface,
                  comment: str, prefix: str | None = None) -> dict[str, str]:
    """``{"<name>.h": ..., "<name>.c": ...}`` of *ctrl* with *interface*.

    *comment* opens the header (what the library is); *prefix* names the
    translated functions (default ``<name>_py_``).
    """
    if not name.isidentifier():
        raise ExportError(f"the library's name must be a C identifier, got {name!r}")
    if not interface.references and ctrl.tracked_names:
        raise ExportError(f"the {ctrl.name} controller tracks {', '.join(ctrl.tracked_names)}: "
                          "its library takes references")
    unit = translate(ctrl, prefix if prefix is not None else f"{name}_py_")
    up = name.upper()
    nz, ny, nu = ctrl.n_z, len(ctrl.output_names), len(ctrl.input_names)
    nx, nr, n_p = len(ctrl.state_names), len(ctrl.tracked_names), int(ctrl.params.size)
    needs = math_functions(unit.code)
    t_arg = "double t, " if interface.time else ""
    r_arg = _arg("const double", "r", nr) + ", " if interface.references else ""
    y_arg = _arg("const double", "y", ny) + ", "
    protos = {
        "init": f"void {name}_init({name}_state *s)",
        "output": f"void {name}_output(const {name}_state *s, {t_arg}{y_arg}{r_arg}"
                  f"{_arg('double', 'u', nu)})",
        "update": f"void {name}_update({name}_state *s, {t_arg}{y_arg}{r_arg}"
                  f"{_arg('const double', 'u_applied', nu)})",
    }
    if ctrl.has_estimate:
        protos["estimate"] = (f"void {name}_estimate(const {name}_state *s, {t_arg}{y_arg}{r_arg}"
                              f"{_arg('double', 'x', nx)})")
    guard = up + "_H"
    math_note = (f"Needs {', '.join(needs)} from <math.h> (-lm)." if needs
                 else "Needs nothing from <math.h>.")
    header = "\n".join([
        comment,
        f" * Sample rate {ctrl.rate:g} Hz. Measured: {', '.join(ctrl.output_names) or 'nothing'}."
        + (f" Tracked: {', '.join(ctrl.tracked_names)}." if nr else ""),
        f" * Input: {', '.join(ctrl.input_names)}. {math_note} */",
        f"#ifndef {guard}",
        f"#define {guard}",
        "",
        f"#define {up}_NZ {nz}",
        f"#define {up}_NY {ny}",
        f"#define {up}_NX {nx}",
        f"#define {up}_NU {nu}",
        f"#define {up}_NR {nr}",
        f"#define {up}_RATE_HZ {ctrl.rate!r}",
        "",
        f"typedef struct {{ double z[{max(nz, 1)}]; }} {name}_state;",
        "",
        *(f"{p};" for p in protos.values()),
        "",
        f"#endif /* {guard} */",
        "",
    ])
    t_val = "t" if interface.time else "0.0"
    r_val = ("(double *)r" if interface.references else "NULL") + f", {nr}"
    y_val = f"(double *)y, {ny}"
    params = f"(double *){name}_params, {n_p}"
    calls = {
        "init": ["    int i;", f"    for (i = 0; i < {nz}; ++i) s->z[i] = {name}_z0[i];"],
        "output": ["    int i;", f"    for (i = 0; i < {nu}; ++i) u[i] = 0.0;",
                   f"    {unit.names['output']}({t_val}, (double *)s->z, {nz}, {y_val}, {r_val}, "
                   f"{params}, u, {nu});"],
        "update": [f"    double z_out[{max(nz, 1)}];", "    int i;",
                   f"    for (i = 0; i < {max(nz, 1)}; ++i) z_out[i] = 0.0;",
                   f"    {unit.names['update']}({t_val}, s->z, {nz}, {y_val}, {r_val}, "
                   f"(double *)u_applied, {nu}, {params}, z_out, {nz});",
                   f"    for (i = 0; i < {nz}; ++i) s->z[i] = z_out[i];"],
    }
    if ctrl.has_estimate:
        calls["estimate"] = [
            "    int i;", f"    for (i = 0; i < {nx}; ++i) x[i] = 0.0;",
            f"    {unit.names['estimate']}({t_val}, (double *)s->z, {nz}, {y_val}, {r_val}, "
            f"{params}, x, {nx});"]
    wrappers = "".join(f"\n{protos[fn]}\n{{\n" + "\n".join(calls[fn]) + "\n}\n" for fn in protos)
    source = (
        f"/* {name}.c: generated by equilibrist from the {ctrl.name} controller's Python source\n"
        " * (translated by equilibrist.native.pyc, as the simulation core runs it); do not edit.\n"
        " * Compile with -ffp-contract=off and without -ffast-math: the Python controller's bits. */\n"
        f'#include <math.h>\n#include <stdint.h>\n#include <stdlib.h>\n#include "{name}.h"\n\n'
        f"/* The controller's parameters and its state at the start. */\n"
        f"static const double {name}_params[{max(n_p, 1)}] = {_c_array(ctrl.params)};\n"
        f"static const double {name}_z0[{max(nz, 1)}] = {_c_array(ctrl.z0)};\n"
        f"{unit.code}\n/* ---- the library's interface ---- */\n{wrappers}"
    )
    return {f"{name}.h": header, f"{name}.c": source}


def nonlinear_files(ctrl: Source, *, name: str | None = None) -> dict[str, str]:
    """``{"<name>.h": ..., "<name>.c": ...}`` of any nonlinear controller *ctrl* (default
    name: its own, as a C identifier)."""
    lib = name or c_identifier(ctrl.name)
    return library_files(
        ctrl, name=lib, interface=interface_of(ctrl),
        comment=f"/* {lib}: {ctrl.title()}, generated by equilibrist from its Python source.")


def check_files(ctrl: Source, name: str, vectors: dict[str, np.ndarray],
                interface: Interface | None = None) -> dict[str, str]:
    """``<name>_vectors.h``, ``test_<name>.c`` and a ``Makefile`` whose ``make check`` runs them.

    The test program feeds the recorded times, measurements (references)
    and applied inputs to the library and requires every command (and
    estimate) to equal the recorded one exactly.
    """
    iface = interface or interface_of(ctrl)
    k = len(vectors["y"])
    nu, nx = len(ctrl.input_names), len(ctrl.state_names)
    arrays: dict[str, np.ndarray] = {key: vectors[key] for key in ("t", "y", "r", "u_applied", "u", "x")
              if key in vectors and np.asarray(vectors[key]).size}
    y = "vec_y[k], " if "y" in arrays else "NULL, "
    t = "vec_t[k][0], " if iface.time else ""
    r = ("vec_r[k], " if "r" in arrays else "NULL, ") if iface.references else ""
    est = ""
    if "x" in arrays and ctrl.has_estimate:
        est = f"""        {name}_estimate(&s, {t}{y}{r}x);
        for (i = 0; i < {nx}; ++i) {{
            if (x[i] != vec_x[k][i]) {{
                if (bad < 5) printf("sample %d: estimate %d %.17g, expected %.17g\\n", k, i, x[i], vec_x[k][i]);
                ++bad;
            }}
        }}
"""
    program = f"""    {name}_state s;
    int k, i, bad = 0;
    {name}_init(&s);
    for (k = 0; k < N_VECTORS; ++k) {{
        double u[{max(nu, 1)}], x[{max(nx, 1)}];
        (void)x;
{est}        {name}_output(&s, {t}{y}{r}u);
        for (i = 0; i < {nu}; ++i) {{
            if (u[i] != vec_u[k][i]) {{
                if (bad < 5) printf("sample %d: input %d %.17g, expected %.17g\\n", k, i, u[i], vec_u[k][i]);
                ++bad;
            }}
        }}
        {name}_update(&s, {t}{y}{r}vec_u_applied[k]);
    }}
    printf("%d samples, %d mismatches\\n", N_VECTORS, bad);
    return bad != 0;"""
    return shared_check_files(
        name, arrays,
        comment=f"Recorded by equilibrist: {k} samples of the {ctrl.name} controller under its "
                "Python runtime.",
        program=program, what="the library against the recorded Python commands, exactly.",
        cflags="-std=c99 -Wall -Wextra -Werror -pedantic -O2 -ffp-contract=off",
    )


def design_id(ctrl: Source) -> str:
    """12 hex digits naming an exported controller: its source and its numbers."""
    return hashlib.sha256(ctrl.params.tobytes() + ctrl.source.encode()).hexdigest()[:12]


def hil_adapter(ctrl: Source, system: System, *, name: str,
                interface: Interface | None = None) -> Adapter:
    """The exported controller behind the hardware-in-the-loop interface (its time is the
    sample count since the reset over the rate, as in the simulation)."""
    iface = interface or interface_of(ctrl)
    inputs = system.input_names
    nr = len(ctrl.tracked_names)
    t = "t, " if iface.time else ""
    r = "rr, " if iface.references else ""
    lines = []
    glob = [f"static {name}_state hil_s;", "static unsigned long hil_k;"]
    if iface.references:
        r0 = [float(ctrl.x_op[ctrl.state_names.index(n)]) for n in ctrl.tracked_names]
        glob.append(f"static const double hil_r0[{max(nr, 1)}] = {_c_array(np.array(r0))};")
        lines.append("    const double *rr = r != NULL ? r : hil_r0;")
    lines.append("    double t = (double)hil_k / HIL_RATE;" if iface.time else "")
    if ctrl.has_estimate:
        lines.append(f"    {name}_estimate(&hil_s, {t}y, {r}est);")
    lines += [f"    {name}_output(&hil_s, {t}y, {r}u);", "    hil_saturate(u, applied);",
              f"    {name}_update(&hil_s, {t}y, {r}applied);", "    hil_k += 1;"]
    return Adapter(
        controller_id=design_id(ctrl), n=len(ctrl.state_names), m=len(inputs),
        p=len(ctrl.output_names), references=nr,
        estimate=len(ctrl.state_names) if ctrl.has_estimate else 0, rate=float(ctrl.rate),
        u_min=tuple(float(system.params[f"{i}_min"]) for i in inputs),
        u_max=tuple(float(system.params[f"{i}_max"]) for i in inputs),
        includes=(f"{name}.h",), sources=(f"{name}.c",), globals="\n".join(glob),
        init=f"    {name}_init(&hil_s);\n    hil_k = 0;", step="\n".join(x for x in lines if x),
    )


# -- the exported library in the simulation ---------------------------------------------------
class CompiledNonlinear:
    """An exported controller compiled into a shared library and called through ctypes.

    A :class:`~equilibrist.control.controller.PythonController`
    (``reset``, ``output``, ``update``), so it closes the loop in the
    simulation: the code that runs on the robot. *files* are the library's
    (default :func:`nonlinear_files`), made with *interface*.
    """

    def __init__(self, ctrl: Source, *, name: str | None = None,
                 files: dict[str, str] | None = None, interface: Interface | None = None) -> None:

        lib_name = name or c_identifier(ctrl.name)
        self.ctrl = ctrl
        self.interface = interface or interface_of(ctrl)
        self.rate: float | None = ctrl.rate
        self.outputs: tuple[str, ...] | None = ctrl.output_names
        self.estimate: np.ndarray | None = None
        self._dir = tempfile.TemporaryDirectory(prefix=f"equilibrist-{lib_name}-")
        folder = Path(self._dir.name)
        for fname, text in (files or nonlinear_files(ctrl, name=lib_name)).items():
            (folder / fname).write_text(text)
        lib = build_shared_library([folder / f"{lib_name}.c"], folder / f"lib{lib_name}.so",
                                   include=folder, extra_flags=("-lm",))
        self._lib = ctypes.CDLL(str(lib))
        dp = ctypes.POINTER(ctypes.c_double)
        rest = ([ctypes.c_double] if self.interface.time else []) + [dp] * (
            2 + self.interface.references)

        def function(fn: str) -> Any:
            f = getattr(self._lib, f"{lib_name}_{fn}")
            f.argtypes = [dp] if fn == "init" else [dp, *rest]
            f.restype = None
            return f

        self._init = function("init")
        self._output = function("output")
        self._update = function("update")
        self._estimate = function("estimate") if ctrl.has_estimate else None
        self._z = np.zeros(max(ctrl.n_z, 1))
        self.reset()

    @staticmethod
    def _ptr(a: np.ndarray) -> object:
        return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))

    def _args(self, t: float, y: np.ndarray, r: np.ndarray) -> list[object]:
        args: list[object] = [self._ptr(self._z)]
        if self.interface.time:
            args.append(float(t))
        args.append(self._ptr(np.ascontiguousarray(y, dtype=np.float64)))
        if self.interface.references:
            args.append(self._ptr(np.ascontiguousarray(r, dtype=np.float64)))
        return args

    def reset(self) -> None:
        self._init(self._ptr(self._z))
        self.estimate = None

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        yv = np.ascontiguousarray(y, dtype=np.float64)
        rv = np.ascontiguousarray(r, dtype=np.float64)
        u = np.zeros(len(self.ctrl.input_names))
        if self._estimate is not None:
            x = np.zeros(len(self.ctrl.state_names))
            self._estimate(*self._args(t, yv, rv), self._ptr(x))
            self.estimate = x
        self._output(*self._args(t, yv, rv), self._ptr(u))
        return u

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        yv = np.ascontiguousarray(y, dtype=np.float64)
        rv = np.ascontiguousarray(r, dtype=np.float64)
        ua = np.ascontiguousarray(u_applied, dtype=np.float64)
        self._update(*self._args(t, yv, rv), self._ptr(ua))

    def close(self) -> None:
        self._dir.cleanup()


__all__ = ["C_MATH", "CompiledNonlinear", "Interface", "Source", "Translation", "check_files",
           "design_id", "hil_adapter", "interface_of", "library_files", "math_functions",
           "nonlinear_files", "translate"]
