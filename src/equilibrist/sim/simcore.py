"""The simulation core in C: one unit per system and controller, generated and compiled.

:func:`unit_source` writes the translation unit: the calling convention's
constants (:mod:`equilibrist.sim.layout`), the run's argument struct
(:data:`FIELDS`, from which :func:`struct_source` writes the C struct and
:class:`RunArgs` is the ctypes one), the project's libm
(:mod:`equilibrist.numeric.libm`), the system's dynamics ``f`` and the
controller's functions, both translated from their one Python definition
by :mod:`equilibrist.native.pyc`, and the core's body (``core.c``, the
loops written once in C, with its generator and integrators from
``integrators.c`` and the integrators' dispatch written from their table,
:mod:`equilibrist.sim.integrators`). :func:`load_core` compiles it
(:mod:`equilibrist.native.build`: cached by content, atomic, checked) and
:class:`NativeCore` calls its entries.

A linear controller's core is made for its *pattern*
(:func:`~equilibrist.native.linear_layout.linear_pattern`: sizes, and where
its coefficients are exact zeros and ones), with the linear library
written out term by term; a pattern too large for that gets the library
with literal sizes, and any packed linear controller can run in the
generic core (``key=None``), which reads its sizes from the vector.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist import tasks
from equilibrist.control.nonlinear import NonlinearController, check_source
from equilibrist.native import build, pyc
from equilibrist.native.controller_c import CONTRACT_TYPES, translate_controller
from equilibrist.native.lanes import source as lanes_section
from equilibrist.native.linear_layout import (
    LINEAR_SOURCE,
    linear_layout_source,
    linear_unrolled_source,
)
from equilibrist.numeric import libm
from equilibrist.numeric.system import System
from equilibrist.sim import integrators, layout

#: The core's C sources (core.c, integrators.c, env.c, shoot.c), in the package that writes C.
_C_FOLDER = Path(build.__file__).parent

if TYPE_CHECKING:
    from equilibrist.sim.steps import PlantSteps

#: Bumped when the generated unit changes in a way its source text does not show.
GENERATOR = 1

# The run's arguments: (name, kind). Kinds: "i" an int64 scalar, "pi"/"pf"/"pu" a pointer to
# int64 / double / uint64 data, "vi" a volatile int64 pointer (the stop flag).
FIELDS: tuple[tuple[str, str], ...] = (
    ("k_start", "i"), ("k_end", "i"), ("iopts", "pi"), ("fopts", "pf"), ("x", "pf"),
    ("z", "pf"), ("nz", "i"), ("u_prev", "pf"), ("rng", "pu"), ("op", "pf"), ("c_idx", "pi"),
    ("ny", "i"), ("cp", "pf"), ("ncp", "i"), ("ref", "pf"), ("nr", "i"), ("uff", "pf"),
    ("lv", "pf"), ("nlv", "i"), ("lw", "pf"), ("nw", "i"), ("p_sets", "pf"), ("n_sets", "i"),
    ("p_len", "i"), ("p_switch", "pi"), ("lin_s", "pf"), ("region", "pf"), ("kicks", "pi"),
    ("n_kicks", "i"), ("kick_value", "pf"), ("pulses", "pi"), ("n_pulses", "i"),
    ("pulse_value", "pf"), ("rec_cols", "pi"), ("acc_cols", "pi"), ("rec", "pf"),
    ("rec_w", "i"), ("acc", "pf"), ("status", "pi"), ("fell_x", "pf"), ("stop", "vi"),
    ("n_runs", "i"), ("n_threads", "i"), ("x0s", "pf"), ("rngs", "pu"), ("acc_w", "i"),
    ("x_ends", "pf"), ("bal", "pf"), ("nbal", "i"),
)
_C_TYPES = {"i": "int64_t", "pi": "int64_t *", "pf": "double *", "pu": "uint64_t *",
            "vi": "volatile int64_t *"}
_CTYPES: dict[str, type[ctypes.c_int64 | ctypes.c_void_p]] = {
    "i": ctypes.c_int64, "pi": ctypes.c_void_p, "pf": ctypes.c_void_p, "pu": ctypes.c_void_p,
    "vi": ctypes.c_void_p}


class RunArgs(ctypes.Structure):
    """The C core's ``eq_args`` for ctypes, written from :data:`FIELDS` (as
    :func:`struct_source` writes it for C)."""

    _fields_ = [(name, _CTYPES[kind]) for name, kind in FIELDS]


def struct_source() -> str:
    """The C core's ``eq_args``, written from :data:`FIELDS` (as :class:`RunArgs` is)."""
    lines = ["typedef struct {"]
    lines += [f"    {_C_TYPES[kind]}{'' if kind != 'i' else ' '}{name};".replace("* ", "*")
              for name, kind in FIELDS]
    return "\n".join(lines) + "\n} eq_args;\n"


#: The line of core.c where the unit takes integrators.c (the generator and the built-in
#: integrators) and the integrators' table (the registered ones and the dispatch).
_INTEGRATORS = "/* ---- the generator and the integrators: integrators.c, inserted here ---- */\n"


def _body() -> str:
    here = _C_FOLDER
    core = (here / "core.c").read_text()
    assert _INTEGRATORS in core
    return core.replace(_INTEGRATORS,
                        (here / "integrators.c").read_text() + integrators.c_source(), 1)


_GLUE = """
static inline void eq_f(const double *x, const double *u, const double *p, double *out)
{{
    {f}((double *)x, EQ_N, (double *)u, EQ_M, (double *)p, EQ_NP, out, EQ_N);
}}

static inline double eq_energy(const double *x, const double *p)
{{
    return {energy}((double *)x, EQ_N, (double *)p, EQ_NP);
}}

static inline void eq_ctrl_output(double t, double *z, int64_t nz, const double *y, int64_t ny,
                                  const double *r, int64_t nr, const double *cp, int64_t ncp,
                                  double *u_out)
{{
    {output}(t, z, nz, (double *)y, ny, (double *)r, nr, (double *)cp, ncp, u_out, EQ_M);
}}

static inline void eq_ctrl_update(double t, double *z, int64_t nz, const double *y, int64_t ny,
                                  const double *r, int64_t nr, const double *u_app,
                                  const double *cp, int64_t ncp, double *z_out)
{{
    {update}(t, z, nz, (double *)y, ny, (double *)r, nr, (double *)u_app, EQ_M, (double *)cp,
             ncp, z_out, nz);
}}

static inline void eq_ctrl_estimate(double t, double *z, int64_t nz, const double *y,
                                    int64_t ny, const double *r, int64_t nr, const double *cp,
                                    int64_t ncp, double *x_out)
{{
    {estimate}(t, z, nz, (double *)y, ny, (double *)r, nr, (double *)cp, ncp, x_out, EQ_N);
}}
"""


def _reward_dispatch(names: list[str]) -> str:
    """``eq_task_reward(task, ...)``: the reward function of the task at that index of
    :data:`equilibrist.tasks.TASK_KINDS` (each translated from its source)."""
    args = ("(double *)x, EQ_N, (double *)u, EQ_M, (double *)p, EQ_NP, (double *)op, EQ_N + EQ_M, "
            "(double *)iscale, EQ_N + EQ_M, (int64_t *)hang, nhang, (double *)eref, 2, dt, bonus")
    cases = "".join(f"    case {i}: return {name}({args});\n" for i, name in enumerate(names))
    return ("\nstatic inline double eq_task_reward(int64_t task, const double *x, const double *u,\n"
            "    const double *p, const double *op, const double *iscale, const int64_t *hang,\n"
            "    int64_t nhang, const double *eref, double dt, double bonus)\n{\n"
            f"    switch (task) {{\n{cases}    }}\n    return 0.0;\n}}\n")


def _constants(values: Mapping[str, int]) -> str:
    return "".join(f"#define EQ{name} {value}\n" for name, value in values.items())


def linear_library(key: bytes | tuple[int, ...] | None) -> str:
    """The linear library's Python source for a core made for *key* (a pattern, sizes or
    None: the generic library)."""
    if isinstance(key, bytes):
        return linear_unrolled_source(key)
    fixed = None if key is None else dict(zip(("nz", "ny", "nr", "m", "n"), key, strict=True))
    return linear_layout_source(fixed) + LINEAR_SOURCE


def controller_module(key: bytes | tuple[int, ...] | None = None,
                      controller: NonlinearController | None = None) -> tuple[pyc.Module, dict[str, str]]:
    """The controller's functions translated to C, and the C names of its ``output``,
    ``update`` and ``estimate`` (a linear controller's made for *key*, or *controller*'s
    beside the generic linear library it may call)."""
    if controller is None:
        ctrl, fns = translate_controller(
            linear_library(key), {role: f"linear_{role}" for role in CONTRACT_TYPES}, library="")
    else:
        check_source(controller.source, has_estimate=controller.has_estimate)
        ctrl, fns = translate_controller(controller.source, {
            "output": "output", "update": "update",
            "estimate": "estimate" if controller.has_estimate else "linear_estimate"})
    return ctrl, {role: fn.name for role, fn in fns.items()}


def unit_source(system: System, key: bytes | tuple[int, ...] | None = None,
                controller: NonlinearController | None = None, *, lanes: bool = False) -> str:
    """The C translation unit of *system*'s core with a linear controller made for *key*,
    or with the nonlinear *controller*.

    The system's own core (no *key*, no *controller*: the generic linear library) also
    holds the environments' steps and the identification's shooting; a core made for a
    controller holds the closed loop only (less to compile, about a quarter). With *lanes*
    (the vector environment's), its environment steps copies eight at a time
    (:mod:`equilibrist.native.lanes`), the same bits.
    """
    system.compiled.functions  # noqa: B018  # a damaged generated module is rebuilt first
    with_env = key is None and controller is None
    dynamics = pyc.Module(system.compiled.module_path.read_text(), prefix="sys_",
                          library=tasks.rewards_source() if with_env else "")
    f = dynamics.function("f", ("F1", "F1", "F1", "F1"))
    energy = dynamics.function("energy", ("F1", "F1"))
    rewards = [dynamics.function(k.reward_function, tasks.REWARD_TYPES).name
               for k in tasks.TASK_KINDS] if with_env else []
    ctrl, names = controller_module(key, controller)
    parts = [
        f"/* The simulation core of {system.key}, generated by equilibrist (generator "
        f"{GENERATOR}). Do not edit. */\n",
        "#include <math.h>\n#include <stdint.h>\n#include <stdlib.h>\n#include <string.h>\n",
        '#define EQ_EXPORT __attribute__((visibility("default")))\n',
        f"#define EQ_N {system.n_states}\n#define EQ_M {system.n_inputs}\n"
        f"#define EQ_NP {len(system.p)}\n",
        _constants({**layout.constants(), **integrators.constants()}),
        struct_source(),
        libm.c_source(log=True, exp=True),
        pyc.PRELUDE,
        "\n/* ---- the system's dynamics, from its generated Python module ---- */\n",
        dynamics.c_source(),
        "\n/* ---- the controller, from its Python definition ---- */\n",
        ctrl.c_source(),
        _GLUE.format(f=f.name, energy=energy.name, **names),
        _reward_dispatch(rewards) if with_env else "",
        "/* ---- the generated part ends here; the core's body follows ---- */\n",
        _body(),
    ]
    if with_env:
        if lanes:
            parts.append(lanes_section(f))
        parts += [(_C_FOLDER / "env.c").read_text(),
                  (_C_FOLDER / "shoot.c").read_text()]
    return "".join(parts)


# What the generator reads besides the system's module and the controller: a change in
# any of them makes a new unit (and so a new library name).
_GENERATOR_FILES = ("core.c", "integrators.c", "env.c", "shoot.c")
_GENERATOR_MODULES = ("equilibrist.native.pyc", "equilibrist.sim.simcore", "equilibrist.native.lanes",
                      "equilibrist.numeric.libm", "equilibrist.sim.layout",
                      "equilibrist.sim.integrators",
                      "equilibrist.control.controller", "equilibrist.tasks")
_GENERATOR: list[str] = []


def _generator_digest() -> str:
    if not _GENERATOR:
        import hashlib
        import importlib.util

        h = hashlib.sha256(str(GENERATOR).encode())
        here = _C_FOLDER
        for name in _GENERATOR_FILES:
            h.update((here / name).read_bytes())
        for module in _GENERATOR_MODULES:
            spec = importlib.util.find_spec(module)
            assert spec is not None and spec.origin is not None
            h.update(Path(spec.origin).read_bytes())
        _GENERATOR.append(h.hexdigest())
    return _GENERATOR[0]


def unit_inputs(system: System, key: bytes | tuple[int, ...] | None = None,
                controller: NonlinearController | None = None, *, lanes: bool = False) -> str:
    """A text that determines :func:`unit_source` of the same arguments entirely, cheap to
    make: the digests of the system's generated module and of the generator's sources, and
    what the controller is (its pattern, sizes or source), and the integrators' table."""
    import hashlib

    module = hashlib.sha256(system.compiled.module_path.read_bytes()).hexdigest()
    if controller is not None:
        what = "nonlinear:" + hashlib.sha256(
            (controller.source + repr(controller.has_estimate)).encode()).hexdigest()
    elif isinstance(key, bytes):
        what = "pattern:" + key.hex()
    else:
        what = "sizes:" + repr(key)
    return "\n".join((module, _generator_digest(), what, "lanes" if lanes else "one",
                      integrators.digest()))


def _ptr(a: np.ndarray | None) -> int | None:
    return None if a is None or a.size == 0 else int(a.ctypes.data)


class NativeCore:
    """One compiled core: its entries, called with numpy arrays.

    Arrays that the core writes must be C-contiguous and of the core's
    dtype (float64, int64 or uint64); the others are converted if needed.
    """

    def __init__(self, system: System, key: bytes | tuple[int, ...] | None,
                 controller: NonlinearController | None = None, *, lanes: bool = False) -> None:
        self.system = system
        self.key = key
        #: Copies the vector environment's step runs at once here (native/lanes.py).
        self.lanes = 1
        stem = f"{system.compiled.module_path.stem}_core"
        system.compiled.functions  # noqa: B018  # a damaged generated module is rebuilt first
        self.lib, self.path = build.load(
            lambda: unit_source(system, key, controller, lanes=lanes), stem,
            inputs=unit_inputs(system, key, controller, lanes=lanes))
        lib = self.lib
        args_p = ctypes.POINTER(RunArgs)
        lib.eq_run_one.argtypes = [args_p]
        lib.eq_run_one.restype = ctypes.c_int
        lib.eq_run_many.argtypes = [args_p]
        lib.eq_run_many.restype = ctypes.c_int
        vp, i64 = ctypes.c_void_p, ctypes.c_int64
        lib.eq_measure_one.argtypes = [vp, vp, i64, vp, i64, vp, vp]
        lib.eq_measure_one.restype = None
        lib.eq_scratch_rows.argtypes = []
        lib.eq_scratch_rows.restype = i64
        lib.eq_scratch_width.argtypes = [i64, i64, i64]
        lib.eq_scratch_width.restype = i64
        lib.eq_advance_one.argtypes = [args_p, i64, vp, vp]
        lib.eq_advance_one.restype = ctypes.c_int
        lib.eq_rk4_steps.argtypes = [vp, vp, vp, ctypes.c_double, i64]
        lib.eq_rk4_steps.restype = None
        lib.eq_normals_into.argtypes = [vp, vp, i64]
        lib.eq_normals_into.restype = None
        lib.eq_f_one.argtypes = [vp, vp, vp, vp]
        lib.eq_f_one.restype = None
        if not hasattr(lib, "eq_env_step_many"):
            return  # a core made for one controller: the closed loop only
        lib.eq_env_lanes.argtypes = []
        lib.eq_env_lanes.restype = i64
        self.lanes = int(lib.eq_env_lanes())
        lib.eq_env_step_many.argtypes = [vp, vp, vp, vp, i64, vp, vp, i64, vp, vp, i64]
        lib.eq_env_step_many.restype = i64
        lib.eq_env_step_one.argtypes = [vp, vp, vp, vp, vp, vp, vp]
        lib.eq_env_step_one.restype = ctypes.c_double
        lib.eq_env_begin_one.argtypes = [vp, vp, vp, vp, vp]
        lib.eq_env_begin_one.restype = None
        lib.eq_env_reset_many.argtypes = [vp, vp, vp, i64, i64, vp, vp]
        lib.eq_env_reset_many.restype = None
        f64 = ctypes.c_double
        lib.eq_shoot_many.argtypes = [i64, f64, f64, vp, i64, i64, vp, vp, i64, vp, i64, vp, vp,
                                      vp, i64, vp, vp]
        lib.eq_shoot_many.restype = None
        lib.eq_innovations.argtypes = [i64, f64, f64, vp, vp, vp, i64, vp, vp, vp, i64, vp, vp,
                                       vp, vp]
        lib.eq_innovations.restype = None

    # -- the shared argument struct ------------------------------------------------------------
    @staticmethod
    def _arrays(values: dict[str, Any]) -> tuple[RunArgs, list[np.ndarray]]:
        keep: list[np.ndarray] = []
        args = RunArgs()
        for name, kind in FIELDS:
            if name not in values:
                continue
            v = values[name]
            if kind == "i":
                setattr(args, name, int(v))
                continue
            if v is None:
                continue
            dtype = {"pf": np.float64, "pi": np.int64, "vi": np.int64, "pu": np.uint64}[kind]
            arr = np.asarray(v)
            if arr.dtype != dtype or not arr.flags.c_contiguous:
                arr = np.ascontiguousarray(arr, dtype=dtype)
            keep.append(arr)
            setattr(args, name, _ptr(arr))
        return args, keep

    @staticmethod
    def _out(arr: np.ndarray, dtype: type[np.generic], what: str) -> np.ndarray:
        if arr.dtype != dtype or not arr.flags.c_contiguous or not arr.flags.writeable:
            raise TypeError(f"the core writes {what}: it must be a writable C-contiguous "
                            f"{np.dtype(dtype).name} array")
        return arr

    def _common(self, *, op: np.ndarray, c_idx: np.ndarray, cp: np.ndarray, ref: np.ndarray,
                uff: np.ndarray, lv: np.ndarray, lw: np.ndarray, p_switch: np.ndarray,
                region: np.ndarray, kicks: np.ndarray, kick_value: np.ndarray,
                pulses: np.ndarray, pulse_value: np.ndarray, rec_cols: np.ndarray,
                acc_cols: np.ndarray, iopts: np.ndarray, fopts: np.ndarray,
                bal: np.ndarray | None = None) -> dict[str, object]:
        ref = np.asarray(ref, dtype=float)
        lv = np.asarray(lv, dtype=float)
        lw = np.asarray(lw, dtype=float)
        return dict(
            iopts=iopts, fopts=fopts, op=op, c_idx=c_idx, ny=len(c_idx), cp=cp, ncp=len(cp),
            ref=ref, nr=(ref.shape[1] if ref.ndim == 2 else 0), uff=uff, lv=lv,
            nlv=lv.shape[0], lw=lw, nw=(lw.shape[1] if lw.ndim == 2 else 0),
            p_switch=p_switch, n_sets=len(p_switch), region=region, kicks=kicks,
            n_kicks=len(kicks), kick_value=kick_value, pulses=pulses, n_pulses=len(pulses),
            pulse_value=pulse_value, rec_cols=rec_cols, acc_cols=acc_cols,
            bal=bal, nbal=0 if bal is None else 1,
        )

    def run_one(self, k_start: int, k_end: int, iopts: np.ndarray, fopts: np.ndarray,
                x: np.ndarray, z: np.ndarray, u_prev: np.ndarray, rng: np.ndarray,
                op: np.ndarray, c_idx: np.ndarray, cp: np.ndarray, ref: np.ndarray,
                uff: np.ndarray, lv: np.ndarray, lw: np.ndarray, p_sets: np.ndarray,
                p_switch: np.ndarray, lin_s: np.ndarray, region: np.ndarray,
                kicks: np.ndarray, kick_value: np.ndarray, pulses: np.ndarray,
                pulse_value: np.ndarray, rec_cols: np.ndarray, acc_cols: np.ndarray,
                rec: np.ndarray, acc: np.ndarray, status: np.ndarray, fell_x: np.ndarray,
                stop: np.ndarray) -> None:
        """One closed-loop run, or samples *k_start* .. *k_end* - 1 of one (``eq_run_one``:
        *x*, *z*, *u_prev*, *rng*, *rec*, *acc*, *status*, *fell_x* written in place)."""
        values = self._common(op=op, c_idx=c_idx, cp=cp, ref=ref, uff=uff, lv=lv, lw=lw,
                              p_switch=p_switch, region=region, kicks=kicks,
                              kick_value=kick_value, pulses=pulses, pulse_value=pulse_value,
                              rec_cols=rec_cols, acc_cols=acc_cols, iopts=iopts, fopts=fopts)
        for arr, dtype, what in ((x, np.float64, "x"), (z, np.float64, "z"),
                                 (u_prev, np.float64, "u_prev"), (rng, np.uint64, "rng"),
                                 (rec, np.float64, "rec"), (acc, np.float64, "acc"),
                                 (status, np.int64, "status"), (fell_x, np.float64, "fell_x"),
                                 (stop, np.int64, "stop")):
            self._out(arr, dtype, what)
        p_sets = np.asarray(p_sets, dtype=float)
        values.update(k_start=k_start, k_end=k_end, x=x, z=z, nz=len(z), u_prev=u_prev, rng=rng,
                      p_sets=p_sets, p_len=p_sets.shape[1], lin_s=lin_s, rec=rec,
                      rec_w=rec.shape[1] if rec.ndim == 2 else 0, acc=acc, status=status,
                      fell_x=fell_x, stop=stop)
        args, keep = self._arrays(values)
        if self.lib.eq_run_one(ctypes.byref(args)) != 0:
            raise MemoryError("the simulation core ran out of memory")
        del keep

    def run_many(self, iopts: np.ndarray, fopts: np.ndarray, x0s: np.ndarray,
                 z0: np.ndarray, rngs: np.ndarray, op: np.ndarray, c_idx: np.ndarray,
                 cp: np.ndarray, ref: np.ndarray, uff: np.ndarray, lv: np.ndarray,
                 lw: np.ndarray, p_sets_r: np.ndarray, p_switch: np.ndarray,
                 lin_r: np.ndarray, region: np.ndarray, kicks: np.ndarray,
                 kick_value: np.ndarray, pulses: np.ndarray, pulse_value: np.ndarray,
                 rec_cols: np.ndarray, acc_cols: np.ndarray, recs: np.ndarray,
                 accs: np.ndarray, statuses: np.ndarray, fell_xs: np.ndarray,
                 x_ends: np.ndarray, stop: np.ndarray, threads: int = 1,
                 bal: np.ndarray | None = None) -> None:
        """Independent runs from *x0s*, in parallel on *threads* threads (``eq_run_many``:
        the per-run blocks of *recs*, *accs*, *statuses*, *fell_xs*, *x_ends* written; *bal*
        the balance box whose last exit each run's accumulators keep)."""
        values = self._common(op=op, c_idx=c_idx, cp=cp, ref=ref, uff=uff, lv=lv, lw=lw,
                              p_switch=p_switch, region=region, kicks=kicks,
                              kick_value=kick_value, pulses=pulses, pulse_value=pulse_value,
                              rec_cols=rec_cols, acc_cols=acc_cols, iopts=iopts, fopts=fopts,
                              bal=bal)
        for arr, dtype, what in ((recs, np.float64, "recs"), (accs, np.float64, "accs"),
                                 (statuses, np.int64, "statuses"),
                                 (fell_xs, np.float64, "fell_xs"),
                                 (x_ends, np.float64, "x_ends"), (stop, np.int64, "stop")):
            self._out(arr, dtype, what)
        runs = len(x0s)
        if runs == 0:
            return
        p_sets_r = np.asarray(p_sets_r, dtype=float)
        lin_r = np.asarray(lin_r, dtype=float)
        values.update(n_runs=runs, n_threads=max(1, int(threads)), x0s=x0s, rngs=rngs,
                      z=np.asarray(z0, dtype=float), nz=len(z0), p_sets=p_sets_r,
                      p_len=p_sets_r.shape[2], lin_s=(lin_r if lin_r.size else None),
                      rec=(recs if recs.size else None), rec_w=recs.shape[2], acc=accs,
                      acc_w=accs.shape[1], status=statuses, fell_x=fell_xs, x_ends=x_ends,
                      stop=stop)
        args, keep = self._arrays(values)
        if self.lib.eq_run_many(ctypes.byref(args)) != 0:
            raise MemoryError("the simulation core ran out of memory")
        del keep

    def measurer(self, *, x: np.ndarray, c_idx: np.ndarray, lv: np.ndarray, rng: np.ndarray,
                 y: np.ndarray) -> Callable[[], None]:
        """``measure()``: the sensors of *x* into *y*, with the noise ``lv z`` drawn from
        *rng* (the arrays kept by reference, their addresses taken once)."""
        self._out(x, np.float64, "x")
        self._out(rng, np.uint64, "rng")
        self._out(y, np.float64, "y")
        c_idx = np.ascontiguousarray(c_idx, dtype=np.int64)
        lv = np.ascontiguousarray(lv, dtype=float)
        fn = self.lib.eq_measure_one
        args = (_ptr(x), _ptr(c_idx), len(c_idx), _ptr(lv), lv.shape[0] if lv.ndim == 2 else 0,
                _ptr(rng), _ptr(y))
        held = (x, c_idx, lv, rng, y)

        def measure(_held: tuple[np.ndarray, ...] = held) -> None:  # the arrays live as long as it
            fn(*args)

        return measure

    def scratch(self, p_len: int, ny: int, nw: int) -> np.ndarray:
        width = int(self.lib.eq_scratch_width(p_len, ny, nw))
        return np.zeros((int(self.lib.eq_scratch_rows()), width))

    def advancer(self, *, x: np.ndarray, u_app: np.ndarray, op: np.ndarray,
                 p_sets: np.ndarray, p_switch: np.ndarray, lin_s: np.ndarray | None,
                 region: np.ndarray, kicks: np.ndarray, kick_value: np.ndarray,
                 pulses: np.ndarray, pulse_value: np.ndarray, lw: np.ndarray, rng: np.ndarray,
                 iopts: np.ndarray, fopts: np.ndarray, status: np.ndarray,
                 scr: np.ndarray) -> Callable[[int], bool]:
        """``advance(k)``: the physics steps after sample *k* with the input in *u_app* held
        (True if the state left its region). The arrays are kept by reference and their
        addresses taken once: write the input into *u_app* before each call."""
        for arr, dtype, what in ((x, np.float64, "x"), (u_app, np.float64, "u_app"),
                                 (rng, np.uint64, "rng"), (status, np.int64, "status"),
                                 (scr, np.float64, "the scratch")):
            self._out(arr, dtype, what)
        lw = np.asarray(lw, dtype=float)
        p_sets = np.asarray(p_sets, dtype=float)
        values = dict(iopts=iopts, fopts=fopts, x=x, op=op, lw=lw,
                      nw=(lw.shape[1] if lw.ndim == 2 else 0), p_sets=p_sets,
                      n_sets=p_sets.shape[0], p_len=p_sets.shape[1], p_switch=p_switch,
                      lin_s=lin_s, region=region, kicks=kicks, n_kicks=len(kicks),
                      kick_value=kick_value, pulses=pulses, n_pulses=len(pulses),
                      pulse_value=pulse_value, rng=rng, status=status, ny=0, nz=0)
        args, keep = self._arrays(values)
        fn = self.lib.eq_advance_one
        pargs, u, sc = ctypes.byref(args), _ptr(u_app), _ptr(scr)
        held = (args, keep, u_app, scr)

        def advance(k: int, _held: object = held) -> bool:  # the arrays live as long as it
            return bool(fn(pargs, k, u, sc))

        return advance

    def plant(self, *, x: np.ndarray, p: np.ndarray, rate: float, n_sub: int,
              lw: np.ndarray, outputs: np.ndarray, lv: np.ndarray,
              rng: np.ndarray, integrator: str = integrators.DEFAULT) -> PlantSteps:
        """The plant alone, sample by sample, as ``simulate`` advances it around a controller
        written in Python: see :class:`PlantSteps`."""
        from equilibrist.sim.steps import PlantSteps

        return PlantSteps(self, x=x, p=p, rate=rate, n_sub=n_sub, lw=lw, outputs=outputs, lv=lv,
                          rng=rng, integrator=integrator)

    def rk4_steps(self, x: np.ndarray, u: np.ndarray, p: np.ndarray, h: float,
                  n_steps: int) -> None:
        self._out(x, np.float64, "x")
        u = np.ascontiguousarray(u, dtype=float)
        p = np.ascontiguousarray(p, dtype=float)
        self.lib.eq_rk4_steps(_ptr(x), _ptr(u), _ptr(p), float(h), int(n_steps))

    def normals(self, rng: np.ndarray, out: np.ndarray) -> None:
        self._out(rng, np.uint64, "rng")
        self._out(out, np.float64, "out")
        self.lib.eq_normals_into(_ptr(rng), _ptr(out), len(out))

    def f(self, x: np.ndarray, u: np.ndarray, p: np.ndarray, out: np.ndarray) -> None:
        self._out(out, np.float64, "out")
        x, u, p = (np.ascontiguousarray(a, dtype=float) for a in (x, u, p))
        self.lib.eq_f_one(_ptr(x), _ptr(u), _ptr(p), _ptr(out))


    # -- the identification's integrator (equilibrist.ident.kernel) ---------------------------
    def shoot_many(self, P: np.ndarray, XS: np.ndarray, bounds: np.ndarray, t: np.ndarray,
                   u: np.ndarray, n_sub: np.ndarray, c_idx: np.ndarray, yhat: np.ndarray,
                   xend: np.ndarray, *, integrator: str = integrators.DEFAULT,
                   rtol: float = integrators.RTOL, atol: float = integrators.ATOL) -> None:
        """C-contiguous arrays of the right dtypes (see ``shoot.c``); the steps of
        *integrator* (a name of :mod:`equilibrist.sim.integrators`' table)."""
        if P.shape[0] == 0:
            return
        self.lib.eq_shoot_many(integrators.number(integrator), float(rtol), float(atol),
                               _ptr(P), P.shape[0], P.shape[1], _ptr(XS), _ptr(bounds),
                               len(bounds) - 1, _ptr(t), len(t), _ptr(u), _ptr(n_sub),
                               _ptr(c_idx), len(c_idx), _ptr(yhat), _ptr(xend))

    def innovations(self, p: np.ndarray, x0: np.ndarray, t: np.ndarray, u: np.ndarray,
                    n_sub: np.ndarray, c_idx: np.ndarray, gain: np.ndarray, y: np.ndarray,
                    off: np.ndarray, e: np.ndarray, *, integrator: str = integrators.DEFAULT,
                    rtol: float = integrators.RTOL, atol: float = integrators.ATOL) -> None:
        """C-contiguous arrays of the right dtypes (see ``shoot.c``); the steps of
        *integrator*."""
        self.lib.eq_innovations(integrators.number(integrator), float(rtol), float(atol),
                                _ptr(p), _ptr(x0), _ptr(t), len(t), _ptr(u), _ptr(n_sub),
                                _ptr(c_idx), len(c_idx), _ptr(gain), _ptr(y), _ptr(off),
                                _ptr(e))


_CacheKey = tuple[Path, bytes | tuple[int, ...] | None, str | None, bool, str]
_CORES: dict[_CacheKey, NativeCore] = {}


def _cache_key(system: System, key: bytes | tuple[int, ...] | None,
               controller: NonlinearController | None, lanes: bool) -> _CacheKey:
    """A loaded core's key: a core loaded before an integrator was registered lacks it."""
    source = None if controller is None else controller.source + repr(controller.has_estimate)
    return (system.compiled.module_path, key if controller is None else None, source, lanes,
            integrators.digest())


def loaded(system: System, key: bytes | tuple[int, ...] | None = None,
           controller: NonlinearController | None = None) -> bool:
    """Whether :func:`load_core` of these (without lanes) has been called in this process."""
    return _cache_key(system, key, controller, False) in _CORES


def load_core(system: System, key: bytes | tuple[int, ...] | None = None,
              controller: NonlinearController | None = None, *, lanes: bool = False) -> NativeCore:
    """The compiled core of *system* for a linear controller made for *key*, or for the
    nonlinear *controller* (built once; raises :class:`~equilibrist.native.pyc.TranslationError`
    when the controller's source uses what the C translation does not know). *lanes*: the
    system's own core with its environment stepped in lanes (the vector environment's)."""
    cache_key = _cache_key(system, key, controller, lanes)
    core = _CORES.get(cache_key)
    if core is None:
        try:
            core = NativeCore(system, key, controller, lanes=lanes)
        except build.BuildError:
            if not lanes:
                raise
            # A compiler that does not know x86-64-v4 (GCC before 11): one copy at a time,
            # the same bits (the core says so: lanes == 1).
            core = load_core(system, key, controller)
        _CORES[cache_key] = core
    return core


__all__ = ["FIELDS", "GENERATOR", "NativeCore", "RunArgs", "linear_library", "load_core", "loaded",
           "struct_source", "unit_source"]
