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
:mod:`equilibrist.sim.integrators`). :func:`equilibrist.sim.simcore.load_core` compiles it.

A linear controller's core is made for its *pattern*
(:func:`~equilibrist.native.linear_layout.linear_pattern`: sizes, and where
its coefficients are exact zeros and ones), with the linear library
written out term by term; a pattern too large for that gets the library
with literal sizes, and any packed linear controller can run in the
generic core (``key=None``), which reads its sizes from the vector.
"""

from __future__ import annotations

import ctypes
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

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
    pass

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
    ("x_ends", "pf"), ("bal", "pf"), ("nbal", "i"), ("rig_i", "pi"), ("rig_f", "pf"),
    ("rig_s", "pf"), ("gforce", "pf"), ("n_gforce", "i"),
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
/* The generalized forces on the coordinates held over the current physics step (a rig's
 * perturbation, equilibrist.sim.rig), or NULL: set by the core around a period's steps, per
 * thread. f then adds M(q)^-1 tau to the accelerations, the mass matrix solved by Cholesky
 * (eq_gforce_add); without it f is the system's own, the same bits. */
static __thread const double *eq_gf_row = NULL;

static inline void eq_gforce_add(const double *x, const double *p, const double *tau, double *out)
{{
#if EQ_NQ > 0
    double mm[EQ_NQ * EQ_NQ], low[EQ_NQ * EQ_NQ], y[EQ_NQ];
    int i, j, k;
    {mass}((double *)x, EQ_N, (double *)p, EQ_NP, mm, EQ_NQ, EQ_NQ);
    for (i = 0; i < EQ_NQ; i++) {{
        for (j = 0; j <= i; j++) {{
            double s = mm[i * EQ_NQ + j];
            for (k = 0; k < j; k++) s -= low[i * EQ_NQ + k] * low[j * EQ_NQ + k];
            low[i * EQ_NQ + j] = i == j ? sqrt(s) : s / low[j * EQ_NQ + j];
        }}
    }}
    for (i = 0; i < EQ_NQ; i++) {{
        double s = tau[i];
        for (k = 0; k < i; k++) s -= low[i * EQ_NQ + k] * y[k];
        y[i] = s / low[i * EQ_NQ + i];
    }}
    for (i = EQ_NQ - 1; i >= 0; i--) {{
        double s = y[i];
        for (k = i + 1; k < EQ_NQ; k++) s -= low[k * EQ_NQ + i] * y[k];
        y[i] = s / low[i * EQ_NQ + i];
    }}
    for (i = 0; i < EQ_NQ; i++) out[EQ_NQ + i] += y[i];
#else
    (void)x; (void)p; (void)tau; (void)out;
#endif
}}

static inline void eq_f(const double *x, const double *u, const double *p, double *out)
{{
    {f}((double *)x, EQ_N, (double *)u, EQ_M, (double *)p, EQ_NP, out, EQ_N);
    if (eq_gf_row != NULL) eq_gforce_add(x, p, eq_gf_row, out);
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
    mass = dynamics.function("mass_matrix", ("F1", "F1", "F2"))
    rewards = [dynamics.function(k.reward_function, tasks.REWARD_TYPES).name
               for k in tasks.TASK_KINDS] if with_env else []
    ctrl, names = controller_module(key, controller)
    parts = [
        f"/* The simulation core of {system.key}, generated by equilibrist (generator "
        f"{GENERATOR}). Do not edit. */\n",
        "#include <math.h>\n#include <stdint.h>\n#include <stdlib.h>\n#include <string.h>\n",
        '#define EQ_EXPORT __attribute__((visibility("default")))\n',
        f"#define EQ_N {system.n_states}\n#define EQ_M {system.n_inputs}\n"
        f"#define EQ_NP {len(system.p)}\n#define EQ_NQ {int(system.functions.N_Q)}\n",
        _constants({**layout.constants(), **integrators.constants()}),
        struct_source(),
        libm.c_source(log=True, exp=True, atan=True, tanh=True),
        pyc.PRELUDE,
        "\n/* ---- the system's dynamics, from its generated Python module ---- */\n",
        dynamics.c_source(),
        "\n/* ---- the controller, from its Python definition ---- */\n",
        ctrl.c_source(),
        _GLUE.format(f=f.name, energy=energy.name, mass=mass.name, **names),
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
_GENERATOR_MODULES = ("equilibrist.native.pyc", "equilibrist.sim.core_unit", "equilibrist.native.lanes",
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


__all__ = ["FIELDS", "GENERATOR", "RunArgs", "linear_library", "struct_source", "unit_inputs",
           "unit_source"]
