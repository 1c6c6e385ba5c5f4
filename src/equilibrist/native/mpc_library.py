"""The MPC's C library: DAQP's shipped C sources and the generated driver (the QP's data as
constants, ``<name>_setup``, ``<name>_step``, ``<name>_move`` and the Kalman filter in front).
One definition for two consumers: the simulated MPC (:class:`MPCRuntime
<equilibrist.control.mpc.MPCRuntime>` compiles and calls it) and the export
(:mod:`equilibrist.export.mpc_c` writes it with its test program), so the controller that
ships is the one simulated.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import numpy as np

from equilibrist.errors import ExportError
from equilibrist.native import daqp_library
from equilibrist.native.daqp_library import DAQP_SOURCES, EPS, INF, ITER_LIMIT
from equilibrist.native.firmware import Adapter


class MPCProblem(Protocol):
    """The MPC's condensed QP as the library reads it
    (:class:`~equilibrist.control.mpc_problem.MPCProblem` has these)."""

    @property
    def n(self) -> int: ...
    @property
    def m(self) -> int: ...
    @property
    def horizon(self) -> int: ...
    @property
    def n_soft(self) -> int: ...
    @property
    def n_variables(self) -> int: ...
    @property
    def condensed(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
    @property
    def soft_predictions(self) -> tuple[np.ndarray, np.ndarray]: ...
    @property
    def K(self) -> np.ndarray: ...
    @property
    def u_lo(self) -> np.ndarray: ...
    @property
    def u_hi(self) -> np.ndarray: ...
    @property
    def soft_lo(self) -> np.ndarray: ...
    @property
    def soft_hi(self) -> np.ndarray: ...
    @property
    def soft_index(self) -> tuple[int, ...]: ...


class Packed(Protocol):
    """A linear controller as its packed vector (:mod:`equilibrist.native.linear_layout`)."""

    def packed(self) -> np.ndarray: ...


class MPC(Protocol):
    """The MPC as the library reads it (:class:`~equilibrist.control.mpc.MPC` has these):
    its QP, operating point, names and the Kalman filter in front."""

    @property
    def problem(self) -> MPCProblem: ...
    @property
    def x_op(self) -> np.ndarray: ...
    @property
    def u_op(self) -> np.ndarray: ...
    @property
    def rate(self) -> float: ...
    @property
    def state_names(self) -> tuple[str, ...]: ...
    @property
    def input_names(self) -> tuple[str, ...]: ...
    @property
    def output_names(self) -> tuple[str, ...]: ...
    @property
    def estimator(self) -> str: ...
    @property
    def form(self) -> str: ...
    def filter_form(self) -> Packed: ...


#: DAQP's sense of a constraint active at its lower bound (DAQP_ACTIVE + DAQP_LOWER): a cold
#: start's working set holds the slacks' bounds ``s >= 0`` (the LQR's plan has zero slack,
#: and a start from an empty set spent an iteration on each of them: 91 iterations instead
#: of 31 on the cart-pole at N = 30 after a push).
COLD_SLACK = 3


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


#: The arithmetic of the exported MPC (``--precision``): name -> C type. ``float`` builds DAQP
#: with ``-DDAQP_SINGLE_PRECISION`` (its ``c_float`` is then ``float``).
PRECISION_TYPES = {"double": "double", "float": "float"}
#: DAQP's tolerances in single precision (its defaults are for double): the primal tolerance
#: of the constraints, and the zero, pivot and progress levels relative to float's epsilon.
FLOAT_SETTINGS = {"primal_tol": 1e-4, "dual_tol": 1e-6, "zero_tol": 1e-6, "pivot_tol": 1e-4,
                  "progress_tol": 1e-7, "sing_tol": 1e-6, "refactor_tol": 1e-5}


def ldp_form(ctrl: MPC) -> dict[str, np.ndarray]:
    """The MPC's QP as DAQP's least-distance problem, formed once here instead of on the device.

    With ``H = R'R`` (Cholesky, ``R`` upper triangular) and ``w = H^-1 f``
    the QP ``min z'Hz/2 + f'z`` over ``lo <= z``, ``bl <= A z <= bu`` is
    ``min |u|^2/2`` over ``u = R z + R^-T f``: the rows ``M = s A R^-1``
    (each scaled by ``s`` to unit length, as DAQP scales them) bound
    ``s (b + A w)``, a simple bound ``lo_i`` of ``z_i`` (the slacks: their
    rows of ``R^-1`` are diagonal) bounds ``u_i`` by ``(lo_i + w_i) / R^-1_ii``,
    and ``z = R^-1 u - w``. ``M`` is what DAQP's setup would compute and
    hold in RAM; here it is a constant (flash), and the device keeps only
    DAQP's factor of the working set and a few vectors.
    """
    prob = ctrl.problem
    H, f, A = (np.asarray(a, dtype=float) for a in prob.condensed)
    nz, nv = prob.n_variables, prob.horizon * prob.m
    rinv = np.linalg.inv(np.linalg.cholesky(H).T)
    w = np.linalg.solve(H, f)
    rows = A @ rinv
    norms = np.linalg.norm(rows, axis=1)
    scale = np.where(norms > 0.0, 1.0 / np.where(norms > 0.0, norms, 1.0), 1.0)
    lo = np.where(np.arange(nz) < nv, -INF, 0.0)  # the corrections are free, the slacks >= 0
    bounded = lo > -INF
    off = np.abs(rinv[bounded]) * (1.0 - np.eye(nz)[bounded])
    if off.size and off.max() > 1e-12 * np.abs(rinv).max():
        raise ExportError("the MPC's Hessian couples a slack with another variable: "
                          "its least-distance form is not the one the export writes")
    diag = np.diag(rinv)
    ldp_lo = np.where(bounded, (lo + w) / diag, -INF)
    return {"M": rows * scale[:, None], "scale": scale, "aw": A @ w,
            "ldp_lo": ldp_lo, "ldp_hi": np.full(nz, INF),
            "rinv_top": rinv[: prob.m], "w_top": w[: prob.m]}


#: Where the install built no DAQP library (:mod:`equilibrist.native.daqp_library`): DAQP's
#: files the MPC's least-distance problem runs, built at ``-O1`` in the simulated MPC's
#: build (``-O2`` saved nothing measurable per sample, 7.5 against 7.3 us, and cost 1.1 s more
#: CPU to compile on a first run); the others (equality elimination, branch and bound,
#: hierarchies, proximal iterations, AVI, presolve) are linked but never entered, and built at
#: ``-O0``. The arithmetic's bits do not depend on the level (IEEE operations, no contraction):
#: ``make check`` of the export, built at ``-O2``, finds the simulated MPC's bits.
DAQP_HOT = frozenset({"api", "auxiliary", "daqp", "factorization", "utils"})


def daqp_objects() -> list[Path]:
    """DAQP's object files, compiled once per cache folder (:func:`equilibrist.native.build.objects`)."""
    from equilibrist.native import build

    return build.objects([(p, "-O1" if p.stem in DAQP_HOT else "-O0")
                          for p in daqp_library.c_sources()],
                         "daqp", DAQP_SOURCES / "include")


def compiled_library(ctrl: MPC, *, shortcut: bool = True, iter_limit: int | None = None) -> Path:
    """The MPC's library (:func:`library_files`, symbols ``mpc_*``) compiled as a shared
    library on this machine, cached by content (:mod:`equilibrist.native.build`), once per
    controller (double precision). It links the DAQP library the install built
    (:func:`~equilibrist.native.daqp_library.installed`), else DAQP's objects, compiled once
    per cache folder (:func:`daqp_objects`)."""
    from equilibrist.native import build

    files = library_files(ctrl, shortcut=shortcut, iter_limit=iter_limit)
    unit = files["mpc.c"].replace('#include "mpc.h"', files["mpc.h"])
    installed = daqp_library.installed()
    if installed is not None:
        # The library's sources name the driver too: another DAQP, another driver.
        unit = f"/* DAQP: the installed library, built from {daqp_library.digest()} */\n{unit}"
    link = [installed] if installed is not None else daqp_objects()
    _, path = build.load(unit, "mpc", link=link, openmp=False,
                         flags=[f"-I{DAQP_SOURCES / 'include'}", "-fvisibility=default"])
    return path


def library_files(ctrl: MPC, *, name: str = "mpc", precision: str = "double",
                  shortcut: bool = True, iter_limit: int | None = None) -> dict[str, str]:
    """The library alone, relative path -> text: DAQP's sources under ``daqp/``,
    ``<name>.h`` and ``<name>.c`` (*precision* ``"double"`` or ``"float"``: ``c_float``, built
    with ``-DDAQP_SINGLE_PRECISION`` for ``"float"``). *shortcut*: the LQR's move without a
    solve where its trajectory meets every constraint (the MPC's own; ``False`` solves every
    QP, as ``MPCRuntime(exact_unconstrained=False)``). *iter_limit*: DAQP's cap on its
    iterations (default :data:`~equilibrist.native.daqp_library.ITER_LIMIT`)."""
    if not name.isidentifier():
        raise ExportError(f"the library's name must be a C identifier, got {name!r}")
    if precision not in PRECISION_TYPES:
        raise ExportError(f"the MPC's precision is double or float, not {precision!r}")
    body = [
        *_source_preamble(name, precision),
        *_qp_constants(ctrl, iter_limit),
        *_workspace_c(ctrl.problem),
        *_bounds_c(),
        *_setup_c(name, precision),
        *_solve_c(name, shortcut),
        *_step_c(name),
    ]
    if ctrl.estimator == "kalman":
        body += _filter_c(ctrl, name)
    source = "\n".join(body)
    return {**_daqp_files(), f"{name}.h": _header(ctrl, name, precision),
            f"{name}.c": source}


def _header(ctrl: MPC, name: str, precision: str) -> str:
    """``<name>.h``: the sizes, the real type and the functions' prototypes (the filter's
    too when a Kalman filter runs in front)."""
    prob = ctrl.problem
    n, m, ny, N = prob.n, prob.m, len(ctrl.output_names), prob.horizon
    kalman = ctrl.estimator == "kalman"
    up = name.upper()
    lines = [
        f"/* {name}: constrained MPC (horizon {N}) solved by DAQP in {precision} precision,",
        f" * generated by equilibrist. Sample rate {ctrl.rate:g} Hz. Input: "
        f"{', '.join(ctrl.input_names)}.",
        f" * State: {', '.join(ctrl.state_names)}."
        + (f" Measured: {', '.join(ctrl.output_names)} (Kalman filter, {ctrl.form} form)."
           if kalman else ""),
        " * No dynamic memory. Build every source (DAQP's too) with -DDAQP_SINGLE_PRECISION. */"
        if precision == "float"
        else " * No dynamic memory: DAQP's workspace is static. */",
        f"#ifndef {up}_H", f"#define {up}_H", f"#define {up}_NX {n}", f"#define {up}_NU {m}",
        f"#define {up}_RATE_HZ {ctrl.rate!r}", "",
        "/* The controller's arithmetic (the arguments stay double). */",
        f"typedef {PRECISION_TYPES[precision]} {name}_real;", "",
        "/* Sets DAQP's workspace up (once; later calls reset its working set to a cold start's:",
        " * the slacks' bounds only). 0: ready. */",
        f"int {name}_setup(void);",
        "/* The MPC at the full state x: 0 (the LQR's move, exact), DAQP's exit flag (1, 2:",
        " * solved; negative: not solved, the clipped LQR's move). */",
        f"int {name}_step(const double x[{n}], double u[{m}]);",
        "/* The same from the deviation dx = x - x_op: the move du, u = u_op + du. */",
        f"int {name}_move(const double dx[{n}], double du[{m}]);",
        "/* DAQP's iterations in the last step (0: the LQR's move, no solve). */",
        f"int {name}_iterations(void);",
    ]
    if kalman:
        lines += [
            f"#define {up}_NY {ny}", "",
            f"typedef struct {{ {name}_real z[{n}]; }} {name}_filter;", "",
            f"void {name}_init({name}_filter *f);",
            f"int {name}_output(const {name}_filter *f, const double y[{ny}], double u[{m}]);",
            f"void {name}_update({name}_filter *f, const double y[{ny}], const double u_applied[{m}]);",
            f"void {name}_estimate(const {name}_filter *f, const double y[{ny}], double x[{n}]);",
        ]
    return "\n".join([*lines, "#endif", ""])


def _source_preamble(name: str, precision: str) -> list[str]:
    """``<name>.c``'s first lines: the check of DAQP's precision and the includes."""
    guard = ("#ifndef DAQP_SINGLE_PRECISION\n#error \"build with -DDAQP_SINGLE_PRECISION "
             "(this controller is single precision)\"\n#endif" if precision == "float" else
             "#ifdef DAQP_SINGLE_PRECISION\n#error \"this controller is double precision: build "
             "without -DDAQP_SINGLE_PRECISION\"\n#endif")
    return [
        f"/* {name}.c: generated by equilibrist (the QP of equilibrist.control.mpc). */",
        guard,
        "#include <stddef.h>", '#include "api.h"', '#include "daqp.h"', '#include "utils.h"',
        f'#include "{name}.h"', "",
    ]


def _qp_constants(ctrl: MPC, iter_limit: int | None) -> list[str]:
    """The sizes, the QP's least-distance form, the LQR's trajectory, the gain, the operating
    point and the limits, as C constants."""
    prob = ctrl.problem
    Fu, Fs = prob.soft_predictions
    n, m, N, ns = prob.n, prob.m, prob.horizon, prob.n_soft
    nz, na = prob.n_variables, int(prob.condensed[2].shape[0])
    ldp = ldp_form(ctrl)
    return [
        f"#define NX {n}", f"#define NU {m}", f"#define NH {N}", f"#define NS {ns}",
        f"#define NV {N * m}", f"#define NSL {N * ns}", f"#define NZ {nz}", f"#define NM {nz + na}",
        f"#define BIG {INF!r}", f"#define ITER_LIMIT {ITER_LIMIT if iter_limit is None else int(iter_limit)}", "",
        "/* The condensed QP as DAQP's least-distance problem (min |u|^2/2, computed by",
        " * equilibrist.native.mpc_library.ldp_form): its rows M (unit length), their",
        " * scales SC and offsets AW (row i bounds SC_i (b_i + AW_i)), the simple bounds of u,",
        " * and the first move's correction v_0 = RINV_TOP u - W_TOP. */",
        _array("LDP_M", ldp["M"]), _array("SC", ldp["scale"]), _array("AW", ldp["aw"]),
        _array("LDP_LO", ldp["ldp_lo"]), _array("LDP_HI", ldp["ldp_hi"]),
        _array("RINV_TOP", ldp["rinv_top"]), _array("W_TOP", ldp["w_top"]),
        "/* The LQR's own trajectory: moves FU dx, constrained states FS dx. */",
        _array("FU", Fu), _array("FS", Fs),
        _array("K", prob.K), _array("X_OP", ctrl.x_op), _array("U_OP", ctrl.u_op),
        _array("U_LO", prob.u_lo), _array("U_HI", prob.u_hi),
        _array("S_LO", prob.soft_lo), _array("S_HI", prob.soft_hi),
        "static const int S_IDX[" + str(max(1, ns)) + "] = {"
        + (", ".join(str(i) for i in prob.soft_index) or "0") + "};",
    ]


def _workspace_c(prob: MPCProblem) -> list[str]:
    """The QP's bounds and solution, the cold start's working set and DAQP's workspace, all
    static."""
    nz, nv = prob.n_variables, prob.horizon * prob.m
    nm = nz + int(prob.condensed[2].shape[0])
    return [
        "static c_float BU[NM], BL[NM], SOL[NZ], LAM[NM];",
        "/* A cold start's working set: the slacks' bounds s >= 0 active (MPCRuntime's). */",
        "static int COLD[NM] = {" + ", ".join(
            str(COLD_SLACK if nv <= i < nz else 0) for i in range(nm)) + "};",
        "/* DAQP's workspace, static (what allocate_daqp_workspace would allocate for NZ",
        " * variables and no soft constraint; the rows M stay in flash). */",
        "static c_float W_LAM[NZ + 1], W_LAM_STAR[NZ + 1], W_D[NZ + 1], W_XLDL[NZ + 1],",
        "    W_ZLDL[NZ + 1], W_L[(NZ + 1) * (NZ + 2) / 2], W_U[NZ], W_XOLD[NZ],",
        "    W_DUP[NM], W_DLO[NM], W_MU[NM - NZ + 1];",
        "static int W_WS[NZ + 1], W_PROX[NZ], W_SENSE[NM];",
        "static DAQPSettings SETTINGS;",
        "static DAQPProblem QP;", "static DAQPWorkspace WORK;", "static int READY = 0;",
        "static int ITERATIONS = 0;", "",
    ]


def _bounds_c() -> list[str]:
    """``bounds_at``, the QP's bounds at a state, and ``to_ldp``, those bounds as the
    least-distance problem's."""
    return [
        "/* The bounds at dx (MPCProblem.qp_bounds), the rows only (the QP's variables' own",
        " * bounds do not depend on dx). */",
        "static void bounds_at(const c_float dx[NX])",
        "{",
        "    int i, j, k;",
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
        "/* The QP's bounds (BU, BL) as the least-distance problem's. */",
        "static void to_ldp(void)",
        "{",
        "    int i;",
        "    for (i = 0; i < NZ; ++i) { BU[i] = LDP_HI[i]; BL[i] = LDP_LO[i]; }",
        "    for (i = NZ; i < NM; ++i) {",
        "        if (BU[i] < BIG) BU[i] = (BU[i] + AW[i - NZ]) * SC[i - NZ];",
        "        if (BL[i] > -BIG) BL[i] = (BL[i] + AW[i - NZ]) * SC[i - NZ];",
        "    }",
        "}", "",
    ]


def _setup_c(name: str, precision: str) -> list[str]:
    """``<name>_setup``, DAQP's problem, settings and static workspace wired up, and
    ``<name>_iterations``."""
    tolerances = FLOAT_SETTINGS if precision == "float" else {"primal_tol": EPS}
    return [
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
        "    to_ldp();",
        "    QP.n = NZ; QP.m = NM; QP.ms = NZ;",
        "    QP.H = NULL; QP.f = NULL; QP.A = (c_float *)LDP_M;  /* DAQP only reads it */",
        "    QP.bupper = BU; QP.blower = BL;",
        "    QP.sense = COLD; QP.break_points = NULL; QP.nh = 0; QP.problem_type = 0;",
        "    daqp_default_settings(&SETTINGS);",
        "    SETTINGS.iter_limit = ITER_LIMIT;",
        *[f"    SETTINGS.{k} = {v!r};" for k, v in tolerances.items()],
        "    WORK.settings = &SETTINGS;",
        "    WORK.n = NZ; WORK.lam = W_LAM; WORK.lam_star = W_LAM_STAR; WORK.WS = W_WS;",
        "    WORK.D = W_D; WORK.xldl = W_XLDL; WORK.zldl = W_ZLDL; WORK.L = W_L;",
        "    WORK.u = W_U; WORK.x = W_U; WORK.xold = W_XOLD; WORK.prox_mask = W_PROX;",
        "    WORK.n_prox = 0; WORK.state = 0; WORK.soft_slack = 0; WORK.outer_iter = 1;",
        "    WORK.Rinv = NULL; WORK.RinvD = NULL; WORK.v = NULL; WORK.scaling = NULL;",
        "    WORK.M = QP.A; WORK.Mu = W_MU; WORK.dupper = W_DUP; WORK.dlower = W_DLO;",
        "    WORK.sense = W_SENSE;",
        "    WORK.rho_ls = NULL; WORK.rho_us = NULL; WORK.w_ls = NULL; WORK.w_us = NULL;",
        "    WORK.bnb = NULL; WORK.hierarchy = NULL; WORK.avi = NULL; WORK.eq = NULL;",
        "    WORK.timer = NULL;",
        "    reset_daqp_workspace(&WORK);",
        "    flag = daqp_update_ldp(DAQP_UPDATE_sense | DAQP_UPDATE_d, &WORK, &QP);",
        "    if (flag < 0) return flag;",
        "    READY = 1;",
        "    return 0;",
        "}", "",
        f"int {name}_iterations(void)",
        "{",
        "    return ITERATIONS;",
        "}", "",
    ]


def _solve_c(name: str, shortcut: bool) -> list[str]:
    """``solve_at``: the LQR's move where its trajectory meets every constraint (with
    *shortcut*), else DAQP's solve from the last working set, clipped to the input's limits."""
    return [
        "static int solve_at(const c_float dx[NX], c_float du_out[NU])",
        "{",
        "    int i, j, feasible = 1, ok;",
        "    c_float du[NU], v[NU];",
        "    DAQPResult res;",
        "    if (!READY && " + name + "_setup() != 0) return -100;",
        "    ITERATIONS = 0;",
        "    bounds_at(dx);",
        "    for (i = 0; i < NU; ++i) {",
        "        du[i] = 0.0;",
        "        for (j = 0; j < NX; ++j) du[i] -= K[i * NX + j] * dx[j];",
        "    }",
        "    for (i = NZ; i < NM; ++i) if (BL[i] > 0.0 || BU[i] < 0.0) { feasible = 0; break; }"
        if shortcut else "    feasible = 0;  /* every QP solved (no shortcut) */",
        "    if (feasible) {",
        "        /* The LQR's trajectory meets every constraint: it is the QP's minimizer. */",
        "        for (i = 0; i < NU; ++i) du_out[i] = du[i];",
        "        return 0;",
        "    }",
        "    /* Only the bounds change: DAQP starts from the last sample's working set. */",
        "    to_ldp();",
        "    daqp_update_ldp(DAQP_UPDATE_d, &WORK, &QP);",
        "    res.x = SOL; res.lam = LAM;",
        "    daqp_solve(&res, &WORK);",
        "    ITERATIONS = res.iter;",
        "    ok = res.exitflag > 0;",
        "    for (i = 0; i < NU; ++i) {",
        "        v[i] = -W_TOP[i];",
        "        for (j = 0; j < NZ; ++j) v[i] += RINV_TOP[i * NZ + j] * SOL[j];",
        "        ok = ok && v[i] - v[i] == 0.0;  /* finite */",
        "    }",
        "    if (!ok) {",
        "        /* No solution: the LQR inside the hard limits, and a cold start next time. */",
        "        QP.sense = COLD;",
        "        daqp_update_ldp(DAQP_UPDATE_sense, &WORK, &QP);",
        "    }",
        "    for (i = 0; i < NU; ++i) {",
        "        c_float d = ok ? du[i] + v[i] : du[i];",
        "        if (d < U_LO[i]) d = U_LO[i];",
        "        if (d > U_HI[i]) d = U_HI[i];",
        "        du_out[i] = d;",
        "    }",
        "    return res.exitflag;",
        "}", "",
    ]


def _step_c(name: str) -> list[str]:
    """``<name>_step`` (from the full state) and ``<name>_move`` (from the deviation)."""
    return [
        f"int {name}_step(const double x[NX], double u[NU])",
        "{",
        "    c_float dx[NX], du[NU];",
        "    int i, flag;",
        "    for (i = 0; i < NX; ++i) dx[i] = (c_float)x[i] - X_OP[i];",
        "    flag = solve_at(dx, du);",
        "    for (i = 0; i < NU; ++i) u[i] = U_OP[i] + du[i];",
        "    return flag;",
        "}", "",
        f"int {name}_move(const double dx_in[NX], double du_out[NU])",
        "{",
        "    c_float dx[NX], du[NU];",
        "    int i, flag;",
        "    for (i = 0; i < NX; ++i) dx[i] = (c_float)dx_in[i];",
        "    flag = solve_at(dx, du);",
        "    for (i = 0; i < NU; ++i) du_out[i] = du[i];",
        "    return flag;",
        "}", "",
    ]


def _filter_c(ctrl: MPC, name: str) -> list[str]:
    """The Kalman filter in front (:meth:`~equilibrist.control.mpc.MPC.filter_form`, in the
    linear library's C) and
    ``<name>_init``, ``<name>_estimate``, ``<name>_output`` and ``<name>_update``."""
    from equilibrist.native.linear_c import deviation_vector, linear_c

    n, m, ny = ctrl.problem.n, ctrl.problem.m, len(ctrl.output_names)
    packed = deviation_vector(ctrl.filter_form().packed())
    return [
        "#include <stdint.h>",
        linear_c({"nz": n, "ny": ny, "nr": 0, "m": m, "n": n}, "c_float"),
        f"#define NY {ny}", f"#define NF {packed.size}",
        "/* The Kalman filter in front, the LQG's estimator as the linear library reads it:",
        " * dx = Ez z + Ey dy, z+ = Ac z + By dy + Bu du. */",
        _array("FILTER", packed),
        "#define FILTER_P (c_float *)FILTER, NF",
        "",
        f"void {name}_init({name}_filter *f)",
        "{", "    int i;", "    for (i = 0; i < NX; ++i) f->z[i] = 0.0;", "}", "",
        f"void {name}_estimate(const {name}_filter *f, const double y[NY], double x[NX])",
        "{", "    c_float dx[NX], yy[NY];", "    int i;",
        "    for (i = 0; i < NY; ++i) yy[i] = (c_float)y[i];",
        "    eq_linear_estimate(0.0, (c_float *)f->z, NX, yy, NY, NULL, 0, FILTER_P, dx, NX);",
        "    for (i = 0; i < NX; ++i) x[i] = X_OP[i] + dx[i];", "}", "",
        f"int {name}_output(const {name}_filter *f, const double y[NY], double u[NU])",
        "{", "    c_float dx[NX], yy[NY], du[NU];", "    int i, flag;",
        "    for (i = 0; i < NY; ++i) yy[i] = (c_float)y[i];",
        "    eq_linear_estimate(0.0, (c_float *)f->z, NX, yy, NY, NULL, 0, FILTER_P, dx, NX);",
        "    flag = solve_at(dx, du);",
        "    for (i = 0; i < NU; ++i) u[i] = U_OP[i] + du[i];",
        "    return flag;", "}", "",
        f"void {name}_update({name}_filter *f, const double y[NY], const double u_applied[NU])",
        "{", "    c_float z[NX], yy[NY], ua[NU];", "    int i;",
        "    for (i = 0; i < NY; ++i) yy[i] = (c_float)y[i];",
        "    for (i = 0; i < NU; ++i) ua[i] = (c_float)u_applied[i];",
        "    eq_linear_update(0.0, f->z, NX, yy, NY, NULL, 0, ua, NU, FILTER_P, z, NX);",
        "    for (i = 0; i < NX; ++i) f->z[i] = z[i];", "}", "",
    ]


# -- make check and hardware in the loop -----------------------------------------------------
def precision_flags(precision: str) -> str:
    """The compiler flags a *precision* needs beyond the defaults (DAQP's single precision)."""
    return " -DDAQP_SINGLE_PRECISION" if precision == "float" else ""


def check_program(name: str, *, n: int, m: int, kalman: bool) -> str:
    """The body of ``test_<name>.c``'s ``main``: the recorded measurements through the library,
    each command within ``TOLERANCE`` (and, with the filter, its state within
    ``Z_TOLERANCE``, relative) of the recorded one."""
    if kalman:
        return f"""    {name}_filter f;
    int k, i, bad = 0, bad_z = 0, iters = 0;
    double worst = 0.0, worst_z = 0.0;
    {name}_init(&f);
    for (k = 0; k < N_VECTORS; ++k) {{
        double u[{m}];
        {name}_output(&f, vec_y[k], u);
        if ({name}_iterations() > iters) iters = {name}_iterations();
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
           "filter state: worst %.3g, %d beyond %.3g; DAQP iterations: worst %d\\n",
           N_VECTORS, worst, bad, TOLERANCE, worst_z, bad_z, Z_TOLERANCE, iters);
    return bad != 0 || bad_z != 0;"""
    return f"""    int k, i, bad = 0, iters = 0;
    double worst = 0.0;
    for (k = 0; k < N_VECTORS; ++k) {{
        double u[{m}];
        {name}_step(vec_y[k], u);
        if ({name}_iterations() > iters) iters = {name}_iterations();
        for (i = 0; i < {m}; ++i) {{
            double d = fabs(u[i] - vec_u[k][i]);
            if (d > worst) worst = d;
            if (d > TOLERANCE) ++bad;
        }}
    }}
    printf("%d samples, worst difference %.3g, %d beyond %.3g; DAQP iterations: worst %d\\n",
           N_VECTORS, worst, bad, TOLERANCE, iters);
    return bad != 0;"""


def mpc_adapter(*, controller_id: str, n: int, m: int, p: int, rate: float,
                u_min: tuple[float, ...], u_max: tuple[float, ...], kalman: bool,
                precision: str) -> Adapter:
    """The library ``mpc`` (with its filter when *kalman*) behind the hardware-in-the-loop
    interface."""
    if kalman:
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
    return Adapter(controller_id=controller_id, n=n, m=m, p=p, references=0,
                   estimate=n, rate=rate, u_min=u_min, u_max=u_max,
                   includes=("mpc.h",), sources=("$(wildcard daqp/src/*.c)", "mpc.c"),
                   globals=globals_, init=init, step=step,
                   cflags="-std=c99 -O2 -ffp-contract=off -Idaqp/include -I."
                   + precision_flags(precision))
