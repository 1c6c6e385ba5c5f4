"""The constrained MPC as C code: DAQP's own C sources plus a generated driver.

:func:`export_mpc` writes into a folder:

``daqp/``
    DAQP's C sources (``src/``, ``include/``, its MIT ``LICENSE``), the
    same release (0.11.0) as the ``daqp`` Python package that solves the
    simulated controller's QP, shipped with equilibrist.
``<name>.h``, ``<name>.c``
    The QP's data as constants (the condensed Hessian, linear cost and
    constraint rows of :attr:`~equilibrist.control.mpc.MPCProblem.condensed`,
    the LQR's predictions ``Fu``, ``Fs``, the gain, the limits) and::

        int <name>_setup(void);
        int <name>_step(const double x[n], double u[m]);

    ``<name>_setup`` sets DAQP's workspace up (once: it factorizes the
    Hessian and allocates the workspace with ``malloc``; afterwards it only
    empties the working set) and returns 0, or DAQP's negative setup flag.
    ``<name>_step`` (which calls ``<name>_setup`` itself the first time) is
    the MPC at the full state ``x``, computed as the simulated controller
    computes it (:meth:`~equilibrist.control.mpc.MPCRuntime.solve`): the
    bounds at ``dx = x - x_op``; the LQR's move exactly when the LQR's
    trajectory meets every constraint (returns 0); else DAQP from the last
    sample's working set (returns DAQP's exit flag: 1 or 2 solved; a
    negative flag means no solution, and the clipped LQR's move is applied
    and the working set emptied). ``u = u_op + clip(-K dx + v_0)``.

    With the Kalman filter in front (``estimator="kalman"``, the default
    when the measured outputs are not the full state) also::

        void <name>_init(<name>_filter *f);
        int  <name>_output(const <name>_filter *f, const double y[p], double u[m]);
        void <name>_update(<name>_filter *f, const double y[p], const double u_applied[m]);
        void <name>_estimate(const <name>_filter *f, const double y[p], double x[n]);

    the design's discrete filter (``current`` or ``predictor`` form, as the
    simulated controller runs it) as generated constants of the linear
    controller form and its fixed, separately tested C code
    (:data:`equilibrist.export.linear_c.LINEAR_C`: ``eq_linear_estimate``,
    ``eq_linear_update``); ``<name>_output`` solves the QP at the filter's
    estimate. ``y`` are the measured outputs (absolute), ``u_applied`` the
    input that acted.
``<name>_vectors.h``, ``test_<name>.c``, ``Makefile``
    ``make check`` replays a recorded noisy closed-loop run (measurements
    and applied inputs) through the C controller and requires each command
    within ``tolerance`` of the simulated controller's (the same QP, solved
    by the same DAQP through its Python interface) and the filter's state
    after each update equal to the Python filter's to round-off
    (``Z_TOLERANCE`` relative).

Math functions: the driver calls none; DAQP calls ``sqrt``, ``fabs`` and
``fmax`` from the C library's ``libm`` (linked with ``-lm``).
Memory: :func:`footprint` measures the code and static data with ``size``
and the heap that ``<name>_setup`` allocates by wrapping ``malloc``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.errors import ExportError
from equilibrist.export._check import ControllerExport, Described, Steps
from equilibrist.export.writer import register_exporter

if TYPE_CHECKING:
    from equilibrist.control.mpc import MPC, MPCRuntime
    from equilibrist.hil.firmware import Adapter
    from equilibrist.numeric.system import System

#: DAQP's C sources, shipped with the package.
DAQP_SOURCES = Path(__file__).with_name("daqp")


def _array(name: str, values: np.ndarray, *, const: bool = True) -> str:
    flat = ", ".join(repr(float(v)) for v in np.asarray(values, dtype=float).reshape(-1))
    size = max(1, int(np.size(values)))
    return f"static {'const ' if const else ''}c_float {name}[{size}] = {{{flat or '0.0'}}};"


def _daqp_files() -> dict[str, str]:
    """DAQP's sources, relative path under ``daqp/`` -> text."""
    return {f"daqp/{p.relative_to(DAQP_SOURCES).as_posix()}": p.read_text()
            for p in sorted(DAQP_SOURCES.rglob("*")) if p.is_file() and p.suffix in (".c", ".h", "")}


def _daqp_c_files(folder: Path) -> list[Path]:
    return sorted((folder / "daqp" / "src").glob("*.c"))


#: How far the default recorded run's first LQR move reaches beyond the input limit.
OVERDRIVE = 1.5


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
    from equilibrist.export.vectors import START_FRACTION

    scales = system.spec.design_scales
    coordinates = system.spec.coordinates
    names = ctrl.state_names
    dx = np.array([START_FRACTION * float(scales[k]) if k in coordinates and scales.get(k) else 0.0
                   for k in names])
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
    commands ``u`` and filter states ``z`` (after each update) on them.
    """
    from equilibrist.control.mpc import MPCRuntime
    from equilibrist.numeric.system import system_from_key
    from equilibrist.sim.noise import Noise
    from equilibrist.sim.run import simulate

    design = ctrl.design
    system = system_from_key(design.system_key, dict(design.params))
    start = default_start(ctrl, system) if x0 is None else dict(x0)
    run = simulate(system, MPCRuntime(ctrl), duration=duration, x0=start,
                   region={}, noise=Noise.from_design(design), seed=seed)
    ys, applied = np.array(run.measurements), np.array(run.applied)
    ref = MPCRuntime(ctrl)
    us, zs = [], []
    no_r = np.zeros(0)
    for k, (y, ua) in enumerate(zip(ys, applied, strict=True)):
        us.append(ref.output(k / ctrl.rate, y, no_r))
        ref.update(k / ctrl.rate, y, no_r, ua)
        zs.append(ref.front.z.copy())
    return {"y": ys, "u_applied": applied, "u": np.array(us), "z": np.array(zs)}


#: Round-off bound of the filter's state in ``make check`` (relative to ``1 + |z|``): the C
#: filter takes its products in another order than numpy; the reaction-wheel pendulum's
#: fast wheel reaches 1.1e-12 over a second.
Z_TOLERANCE = 1e-10
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
               tolerance: float = 1e-6, seed: int = 0) -> Path:
    """Write the MPC's C code, recorded vectors and ``make check`` into *folder*.

    *x0* starts the recorded run (default :func:`default_start`, which
    drives the input into its limits), *seed* its sensor noise;
    *tolerance* bounds the difference of each command to the Python
    controller's [input units].
    """
    from equilibrist.export.writer import write_files

    out = Path(folder)
    write_files(out, mpc_files(ctrl, name=name, x0=x0, duration=duration, tolerance=tolerance,
                               seed=seed))
    return out


def mpc_files(ctrl: MPC, *, name: str = "mpc", x0: dict[str, float] | None = None,
              duration: float = 1.0, tolerance: float = 1e-6, seed: int = 0) -> dict[str, str]:
    """Every file of the MPC's export, relative path -> text (DAQP's sources under ``daqp/``,
    the library, the recorded vectors, the test program and the Makefile)."""
    from equilibrist.export._check import check_files

    kalman = ctrl.estimator == "kalman"
    files = library_files(ctrl, name=name)
    vectors = record(ctrl, x0=x0, duration=duration, seed=seed)
    n, m = ctrl.problem.n, ctrl.problem.m
    if kalman:
        program = f"""    {name}_filter f;
    int k, i, bad = 0, bad_z = 0;
    double worst = 0.0, worst_z = 0.0;
    {name}_init(&f);
    for (k = 0; k < N_VECTORS; ++k) {{
        double u[{m}];
        {name}_output(&f, vec_y[k], u);
        for (i = 0; i < {m}; ++i) {{
            double d = fabs(u[i] - vec_u[k][i]);
            if (d > worst) worst = d;
            if (d > TOLERANCE) ++bad;
        }}
        {name}_update(&f, vec_y[k], vec_u_applied[k]);
        for (i = 0; i < {n}; ++i) {{
            double d = fabs(f.z[i] - vec_z[k][i]) / (1.0 + fabs(vec_z[k][i]));
            if (d > worst_z) worst_z = d;
            if (d > Z_TOLERANCE) ++bad_z;
        }}
    }}
    printf("%d samples, worst difference %.3g, %d beyond %.3g; "
           "filter state: worst %.3g, %d beyond %.3g\\n",
           N_VECTORS, worst, bad, TOLERANCE, worst_z, bad_z, Z_TOLERANCE);
    return bad != 0 || bad_z != 0;"""
        arrays = {"y": vectors["y"], "u_applied": vectors["u_applied"], "u": vectors["u"],
                  "z": vectors["z"]}
        defines: dict[str, object] = {"TOLERANCE": tolerance, "Z_TOLERANCE": Z_TOLERANCE}
    else:
        program = f"""    int k, i, bad = 0;
    double worst = 0.0;
    for (k = 0; k < N_VECTORS; ++k) {{
        double u[{m}];
        {name}_step(vec_y[k], u);
        for (i = 0; i < {m}; ++i) {{
            double d = fabs(u[i] - vec_u[k][i]);
            if (d > worst) worst = d;
            if (d > TOLERANCE) ++bad;
        }}
    }}
    printf("%d samples, worst difference %.3g, %d beyond %.3g\\n", N_VECTORS, worst, bad, TOLERANCE);
    return bad != 0;"""
        arrays = {"y": vectors["y"], "u": vectors["u"]}
        defines = {"TOLERANCE": tolerance}
    checks = check_files(
        name, arrays, program=program, defines=defines,
        comment=f"Recorded by equilibrist: {len(vectors['y'])} samples of the MPC in closed loop "
                "with sensor noise; commands of the simulated controller (DAQP's Python interface).",
        what="the C MPC against the Python controller on recorded measurements.",
        sources=("$(wildcard daqp/src/*.c)",),
        include=("daqp/include",),
        cflags="-O2 -std=c99 -ffp-contract=off",
    )
    return {**files, **checks}


def library_files(ctrl: MPC, *, name: str = "mpc") -> dict[str, str]:
    """The library alone, relative path -> text: DAQP's sources under ``daqp/``,
    ``<name>.h`` and ``<name>.c``."""
    from equilibrist.control.mpc import EPS, INF, ITER_LIMIT, KalmanFront
    from equilibrist.export.linear_c import LINEAR_C

    if not name.isidentifier():
        raise ExportError(f"the library's name must be a C identifier, got {name!r}")
    kalman = ctrl.estimator == "kalman"
    prob = ctrl.problem
    H, f, A = prob.condensed
    Fu, Fs = prob.soft_predictions
    n, m, ny, N, ns = prob.n, prob.m, len(ctrl.output_names), prob.horizon, prob.n_soft
    nz, na = prob.n_variables, int(A.shape[0])
    up = name.upper()
    lines = [
        f"/* {name}: constrained MPC (horizon {N}) solved by DAQP,",
        f" * generated by equilibrist. Sample rate {ctrl.rate:g} Hz. Input: "
        f"{', '.join(ctrl.input_names)}.",
        f" * State: {', '.join(ctrl.state_names)}."
        + (f" Measured: {', '.join(ctrl.output_names)} (Kalman filter, {ctrl.form} form). */"
           if kalman else " */"),
        f"#ifndef {up}_H", f"#define {up}_H", f"#define {up}_NX {n}", f"#define {up}_NU {m}",
        f"#define {up}_RATE_HZ {ctrl.rate!r}", "",
        "/* Sets DAQP's workspace up (once; later calls empty its working set). 0: ready. */",
        f"int {name}_setup(void);",
        "/* The MPC at the full state x: 0 (the LQR's move, exact), DAQP's exit flag (1, 2:",
        " * solved; negative: not solved, the clipped LQR's move). */",
        f"int {name}_step(const double x[{n}], double u[{m}]);",
    ]
    if kalman:
        lines += [
            f"#define {up}_NY {ny}", "",
            f"typedef struct {{ double z[{n}]; }} {name}_filter;", "",
            f"void {name}_init({name}_filter *f);",
            f"int {name}_output(const {name}_filter *f, const double y[{ny}], double u[{m}]);",
            f"void {name}_update({name}_filter *f, const double y[{ny}], const double u_applied[{m}]);",
            f"void {name}_estimate(const {name}_filter *f, const double y[{ny}], double x[{n}]);",
        ]
    header = "\n".join([*lines, "#endif", ""])
    body = [
        f"/* {name}.c: generated by equilibrist (the QP of equilibrist.control.mpc). */",
        "#include <stddef.h>", '#include "api.h"', '#include "utils.h"', f'#include "{name}.h"', "",
        f"#define NX {n}", f"#define NU {m}", f"#define NH {N}", f"#define NS {ns}",
        f"#define NV {N * m}", f"#define NSL {N * ns}", f"#define NZ {nz}", f"#define NM {nz + na}",
        f"#define BIG {INF!r}", f"#define ITER_LIMIT {ITER_LIMIT}", f"#define PRIMAL_TOL {EPS!r}",
        "",
        "/* The condensed QP (variables: the corrections v, then the slacks s). */",
        _array("QP_H", H, const=False), _array("QP_F", f, const=False),
        _array("QP_A", A, const=False),
        "/* The LQR's own trajectory: moves FU dx, constrained states FS dx. */",
        _array("FU", Fu), _array("FS", Fs),
        _array("K", prob.K), _array("X_OP", ctrl.x_op), _array("U_OP", ctrl.u_op),
        _array("U_LO", prob.u_lo), _array("U_HI", prob.u_hi),
        _array("S_LO", prob.soft_lo), _array("S_HI", prob.soft_hi),
        "static const int S_IDX[" + str(max(1, ns)) + "] = {"
        + (", ".join(str(i) for i in prob.soft_index) or "0") + "};",
        "static c_float BU[NM], BL[NM], SOL[NZ], LAM[NM];",
        "static int COLD[NM];  /* an empty working set */",
        "static DAQPProblem QP;", "static DAQPWorkspace WORK;", "static int READY = 0;", "",
        "/* The bounds at dx (MPCProblem.qp_bounds): the variables' own, then the rows'. */",
        "static void bounds_at(const c_float dx[NX])",
        "{",
        "    int i, j, k;",
        "    for (i = 0; i < NV; ++i) { BU[i] = BIG; BL[i] = -BIG; }",
        "    for (i = NV; i < NZ; ++i) { BU[i] = BIG; BL[i] = 0.0; }",
        "    for (i = 0; i < NV; ++i) {",
        "        c_float us = 0.0;",
        "        for (j = 0; j < NX; ++j) us += FU[i * NX + j] * dx[j];",
        "        BU[NZ + i] = U_HI[i % NU] - us;",
        "        BL[NZ + i] = U_LO[i % NU] - us;",
        "    }",
        "    for (j = 0; j < NS; ++j) {",
        "        /* A soft bound the state already violates: widened to the LQR's trajectory. */",
        "        c_float c = dx[S_IDX[j]];",
        "        int out = c > S_HI[j] || c < S_LO[j];",
        "        for (k = 0; k < NH; ++k) {",
        "            int row = k * NS + j, q;",
        "            c_float xs = 0.0, lo = S_LO[j], hi = S_HI[j];",
        "            for (q = 0; q < NX; ++q) xs += FS[row * NX + q] * dx[q];",
        "            if (out && xs < lo) lo = xs;",
        "            if (out && xs > hi) hi = xs;",
        "            BU[NZ + NV + row] = BIG;",
        "            BL[NZ + NV + row] = lo - xs;",
        "            BU[NZ + NV + NSL + row] = hi - xs;",
        "            BL[NZ + NV + NSL + row] = -BIG;",
        "        }",
        "    }",
        "}", "",
        f"int {name}_setup(void)",
        "{",
        "    c_float zero[NX] = {0.0};",
        "    int flag;",
        "    if (READY) {",
        "        QP.sense = COLD;",
        "        daqp_update_ldp(DAQP_UPDATE_sense, &WORK, &QP);",
        "        return 0;",
        "    }",
        "    bounds_at(zero);",
        "    QP.n = NZ; QP.m = NM; QP.ms = NZ;",
        "    QP.H = QP_H; QP.f = QP_F; QP.A = QP_A; QP.bupper = BU; QP.blower = BL;",
        "    QP.sense = COLD; QP.break_points = NULL; QP.nh = 0; QP.problem_type = 0;",
        "    allocate_daqp_settings(&WORK);",
        "    WORK.settings->iter_limit = ITER_LIMIT;",
        "    WORK.settings->primal_tol = PRIMAL_TOL;",
        "    flag = setup_daqp(&QP, &WORK, NULL);",
        "    if (flag < 0) return flag;",
        "    READY = 1;",
        "    return 0;",
        "}", "",
        "static int solve_at(const c_float dx[NX], double u[NU])",
        "{",
        "    int i, j, feasible = 1, ok;",
        "    c_float du[NU];",
        "    DAQPResult res;",
        "    if (!READY && " + name + "_setup() != 0) return -100;",
        "    bounds_at(dx);",
        "    for (i = 0; i < NU; ++i) {",
        "        du[i] = 0.0;",
        "        for (j = 0; j < NX; ++j) du[i] -= K[i * NX + j] * dx[j];",
        "    }",
        "    for (i = NZ; i < NM; ++i) if (BL[i] > 0.0 || BU[i] < 0.0) { feasible = 0; break; }",
        "    if (feasible) {",
        "        /* The LQR's trajectory meets every constraint: it is the QP's minimizer. */",
        "        for (i = 0; i < NU; ++i) u[i] = U_OP[i] + du[i];",
        "        return 0;",
        "    }",
        "    /* Only the bounds change: DAQP starts from the last sample's working set. */",
        "    daqp_update_ldp(DAQP_UPDATE_d, &WORK, &QP);",
        "    res.x = SOL; res.lam = LAM;",
        "    daqp_solve(&res, &WORK);",
        "    ok = res.exitflag > 0;",
        "    for (i = 0; i < NU; ++i) ok = ok && SOL[i] - SOL[i] == 0.0;  /* finite */",
        "    if (!ok) {",
        "        /* No solution: the LQR inside the hard limits, and a cold start next time. */",
        "        QP.sense = COLD;",
        "        daqp_update_ldp(DAQP_UPDATE_sense, &WORK, &QP);",
        "    }",
        "    for (i = 0; i < NU; ++i) {",
        "        c_float d = ok ? du[i] + SOL[i] : du[i];",
        "        if (d < U_LO[i]) d = U_LO[i];",
        "        if (d > U_HI[i]) d = U_HI[i];",
        "        u[i] = U_OP[i] + d;",
        "    }",
        "    return res.exitflag;",
        "}", "",
        f"int {name}_step(const double x[NX], double u[NU])",
        "{",
        "    c_float dx[NX];",
        "    int i;",
        "    for (i = 0; i < NX; ++i) dx[i] = x[i] - X_OP[i];",
        "    return solve_at(dx, u);",
        "}", "",
    ]
    if kalman:
        form = KalmanFront(ctrl).linear_form()
        body += [
            "#define EQ_REAL double", LINEAR_C,
            f"#define NY {ny}",
            _array("F_AC", form["Ac"]), _array("F_BY", form["By"]), _array("F_BU", form["Bu"]),
            _array("F_EZ", form["Ez"]), _array("F_EY", form["Ey"]), _array("Y_OP", form["y_op"]),
            "",
            "/* The Kalman filter in front: dx = Ez z + Ey dy, z+ = Ac z + By dy + Bu du. */",
            "static const eq_linear_form FILTER = {NX, NY, 0, NU, NX, F_AC, F_BY, NULL, F_BU,",
            "                                      NULL, NULL, NULL, F_EZ, F_EY, U_OP, Y_OP, NULL};",
            "",
            f"void {name}_init({name}_filter *f)",
            "{", "    int i;", "    for (i = 0; i < NX; ++i) f->z[i] = 0.0;", "}", "",
            f"void {name}_estimate(const {name}_filter *f, const double y[NY], double x[NX])",
            "{", "    c_float dx[NX];", "    int i;",
            "    eq_linear_estimate(&FILTER, f->z, y, dx);",
            "    for (i = 0; i < NX; ++i) x[i] = X_OP[i] + dx[i];", "}", "",
            f"int {name}_output(const {name}_filter *f, const double y[NY], double u[NU])",
            "{", "    c_float dx[NX];",
            "    eq_linear_estimate(&FILTER, f->z, y, dx);",
            "    return solve_at(dx, u);", "}", "",
            f"void {name}_update({name}_filter *f, const double y[NY], const double u_applied[NU])",
            "{", "    c_float z[NX];", "    int i;",
            "    eq_linear_update(&FILTER, f->z, y, NULL, u_applied, z);",
            "    for (i = 0; i < NX; ++i) f->z[i] = z[i];", "}", "",
        ]
    source = "\n".join(body)
    return {**_daqp_files(), f"{name}.h": header, f"{name}.c": source}


#: A program that sets the exported MPC up once, counting what it allocates.
_HEAP_PROGRAM = """#include <stdio.h>
#include <stdlib.h>
#include "{name}.h"
static size_t total = 0;
void *__real_malloc(size_t n);
void *__real_calloc(size_t k, size_t n);
void *__wrap_malloc(size_t n) {{ total += n; return __real_malloc(n); }}
void *__wrap_calloc(size_t k, size_t n) {{ total += k * n; return __real_calloc(k, n); }}
int main(void) {{
    double x[{n}] = {{0.0}}, u[{m}];
    if ({name}_setup() != 0) return 1;
    {name}_step(x, u);
    printf("%lu\\n", (unsigned long)total);
    return 0;
}}
"""


def footprint(folder: str | Path, *, name: str = "mpc", n: int = 4, m: int = 1) -> dict[str, int]:
    """Bytes of the library alone (DAQP's sources and the driver; without the test and its
    vectors): code (``text``), initialized and zeroed static data (``data``, ``bss``), measured
    with the C compiler and ``size`` on the object files, and ``heap``: what
    ``<name>_setup`` allocates (DAQP's workspace), counted by a program linked with
    ``malloc`` and ``calloc`` wrapped. *n*, *m*: the controller's states and inputs."""
    import subprocess
    import tempfile

    from equilibrist.export.native import compiler

    src = Path(folder)
    files = [*_daqp_c_files(src), src / f"{name}.c"]
    inc = [f"-I{src / 'daqp' / 'include'}", f"-I{src}"]
    total = {"text": 0, "data": 0, "bss": 0}
    with tempfile.TemporaryDirectory() as tmp:
        for i, f in enumerate(files):
            obj = Path(tmp) / f"{i}.o"
            subprocess.run([*compiler(), "-O2", "-std=c99", "-ffp-contract=off", *inc, "-c", str(f),
                            "-o", str(obj)],
                           check=True, capture_output=True)
            out = subprocess.run(["size", str(obj)], check=True, capture_output=True, text=True)
            text, data, bss = (int(v) for v in out.stdout.splitlines()[1].split()[:3])
            total["text"] += text
            total["data"] += data
            total["bss"] += bss
        prog = Path(tmp) / "heap.c"
        prog.write_text(_HEAP_PROGRAM.format(name=name, n=n, m=m))
        exe = Path(tmp) / "heap"
        subprocess.run([*compiler(), "-O2", "-std=c99", "-ffp-contract=off", *inc, str(prog),
                        *map(str, files),
                        "-Wl,--wrap=malloc,--wrap=calloc", "-o", str(exe), "-lm"],
                       check=True, capture_output=True)
        run = subprocess.run([str(exe)], check=True, capture_output=True, text=True)
        total["heap"] = int(run.stdout.strip())
    return total


class CompiledMPC:
    """The exported C MPC compiled into a shared library and called through ctypes.

    A :class:`~equilibrist.control.controller.PythonController` (``reset``,
    ``output``, ``update``) on the controller's measured outputs, so the
    code that runs on the robot closes the loop in the simulation. Each
    instance compiles its own copy (the driver's workspace is static data).
    """

    def __init__(self, ctrl: MPC, *, name: str = "mpc") -> None:
        import ctypes
        import subprocess
        import tempfile

        from equilibrist.export.native import compiler

        self.ctrl = ctrl
        self.rate: float | None = ctrl.rate
        self.outputs: tuple[str, ...] | None = ctrl.output_names
        self.estimate: np.ndarray | None = None
        self._kalman = ctrl.estimator == "kalman"
        self._dir = tempfile.TemporaryDirectory(prefix="equilibrist-mpc-")
        folder = Path(self._dir.name)
        for rel, text in library_files(ctrl, name=name).items():
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            (folder / rel).write_text(text)
        sources = [*_daqp_c_files(folder), folder / f"{name}.c"]
        lib = folder / f"lib{name}.so"
        inc = [f"-I{folder / 'daqp' / 'include'}", f"-I{folder}"]
        proc = subprocess.run([*compiler(), "-O2", "-std=c99", "-ffp-contract=off", "-fPIC",
                               "-shared", *inc, *map(str, sources), "-o", str(lib), "-lm"],
                              capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            raise ExportError("the exported MPC does not compile: "
                              + " | ".join((proc.stderr or proc.stdout).strip().splitlines()[:6]))
        self._lib: Any = ctypes.CDLL(str(lib))
        dp = ctypes.POINTER(ctypes.c_double)
        self._setup = self._lib[f"{name}_setup"]
        self._setup.argtypes, self._setup.restype = [], ctypes.c_int
        self._step = self._lib[f"{name}_step"]
        self._step.argtypes, self._step.restype = [dp, dp], ctypes.c_int
        if self._kalman:
            for fn, count, res in (("init", 1, None), ("output", 3, ctypes.c_int),
                                   ("update", 3, None), ("estimate", 3, None)):
                f = self._lib[f"{name}_{fn}"]
                f.argtypes, f.restype = [dp] * count, res
                setattr(self, f"_{fn}", f)
        self._z = np.zeros(ctrl.problem.n)
        self.reset()

    def _call(self, fn: str, *args: np.ndarray) -> Any:
        return getattr(self, f"_{fn}")(*(self._ptr(a) for a in args))

    @staticmethod
    def _ptr(a: np.ndarray) -> Any:
        import ctypes

        return a.ctypes.data_as(ctypes.POINTER(ctypes.c_double))

    @property
    def z(self) -> np.ndarray:
        """The C filter's state (a copy)."""
        return self._z.copy()

    def reset(self) -> None:
        flag = int(self._setup())
        if flag != 0:
            raise ExportError(f"the exported MPC's DAQP setup failed (flag {flag})")
        if self._kalman:
            self._call("init", self._z)
        self.estimate = None

    def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
        yv = np.ascontiguousarray(y, dtype=np.float64)
        u = np.zeros(self.ctrl.problem.m)
        if self._kalman:
            x = np.zeros(self.ctrl.problem.n)
            self._call("estimate", self._z, yv, x)
            self._call("output", self._z, yv, u)
            self.estimate = x
        else:
            self._step(self._ptr(yv), self._ptr(u))
            self.estimate = yv.copy()
        return u

    def update(self, t: float, y: np.ndarray, r: np.ndarray, u_applied: np.ndarray) -> None:
        if self._kalman:
            yv = np.ascontiguousarray(y, dtype=np.float64)
            ua = np.ascontiguousarray(u_applied, dtype=np.float64)
            self._call("update", self._z, yv, ua)

    def close(self) -> None:
        self._dir.cleanup()


#: What :func:`export_files` returns (kept under its former name).
MPCExport = ControllerExport


@register_exporter("mpc")
def export_files(built: MPCRuntime, out: str | Path, *, system: System, precision: str = "double",
                 duration: float | None = None, seed: int = 0, force: bool = False) -> MPCExport:
    """``equilibrist export SYSTEM --controller mpc``: DAQP's sources, the driver, ``make check``.

    The controller exported is the one simulated: with the Kalman filter in
    front when the design's measured outputs are not the full state.
    """
    from equilibrist.export.writer import (
        EXPORT_MARKER,
        check_folder,
        generator_version,
        write_files,
    )
    from equilibrist.hil.firmware import WHAT, with_hil

    if precision != "double":
        raise ExportError(f"the MPC is exported in double precision only, not {precision!r}")
    from equilibrist.export.vectors import check_duration

    ctrl = built.ctrl
    check_duration(duration, ctrl.rate)
    folder = check_folder(out, force=force)
    texts = with_hil(mpc_files(ctrl, duration=duration or 1.0, seed=seed),
                     hil_adapter(built, system), sketch_copies=("mpc.h", "mpc.c"))
    texts[EXPORT_MARKER] = f"written by {generator_version()}\n"
    write_files(folder, texts)
    digest = design_id(built)
    kalman = ctrl.estimator == "kalman"
    files = {"daqp/": "DAQP's C sources (the QP solver, MIT licence)",
             "mpc.h": "the interface" + (" (Kalman filter in front)" if kalman else ""),
             "mpc.c": ("the Kalman filter and " if kalman else "")
             + "the QP's data and the step: bounds at the state, DAQP, the move",
             "mpc_vectors.h": "recorded measurements and the Python controller's commands",
             "test_mpc.c": "test program", "Makefile": "make check, make hil-host",
             **{rel: what for rel, what in WHAT.items()}}
    steps = round((duration or 1.0) * ctrl.rate) + 1
    return MPCExport(folder=folder, name="mpc", files=files, precision="double",
                     data=Described(digest, "mpc", ctrl.rate), vectors=Steps(steps))


def hil_adapter(built: MPCRuntime, system: System) -> Adapter:
    """The MPC (with its filter, if any) behind the hardware-in-the-loop interface."""
    from equilibrist.hil.firmware import Adapter

    ctrl = built.ctrl
    n, m = int(ctrl.problem.n), int(ctrl.problem.m)
    names = system.input_names
    u_min = tuple(float(system.params[f"{i}_min"]) for i in names)
    u_max = tuple(float(system.params[f"{i}_max"]) for i in names)
    outputs = built.outputs or system.state_names
    if ctrl.estimator == "kalman":
        step = """    mpc_estimate(&hil_f, y, est);
    (void)mpc_output(&hil_f, y, u);
    hil_saturate(u, applied);
    mpc_update(&hil_f, y, applied);"""
        init, globals_ = "    (void)mpc_setup();\n    mpc_init(&hil_f);", "static mpc_filter hil_f;"
    else:
        step = f"""    int i;
    (void)mpc_step(y, u);
    for (i = 0; i < {n}; ++i) est[i] = y[i];"""
        init, globals_ = "    (void)mpc_setup();", ""
    return Adapter(controller_id=design_id(built), n=n, m=m, p=len(outputs), references=0,
                   estimate=n, rate=float(ctrl.rate), u_min=u_min, u_max=u_max,
                   includes=("mpc.h",), sources=("$(wildcard daqp/src/*.c)", "mpc.c"),
                   globals=globals_, init=init, step=step,
                   cflags="-std=c99 -O2 -ffp-contract=off -Idaqp/include -I.")


def design_id(built: MPCRuntime) -> str:
    """12 hex digits naming the exported MPC: its gains and its filter's."""
    import hashlib

    ctrl = built.ctrl
    return hashlib.sha256(np.asarray(ctrl.problem.K).tobytes()
                          + (b"" if ctrl.Kf is None else np.asarray(ctrl.Kf).tobytes())
                          ).hexdigest()[:12]


__all__ = ["DAQP_SOURCES", "OVERDRIVE", "Z_TOLERANCE", "CompiledMPC", "MPCExport", "default_start",
           "export_files", "export_mpc",
           "footprint", "mpc_files", "record"]
