"""The constrained MPC as C code: OSQP's own code generation plus a fixed driver.

:func:`export_mpc` writes into a folder:

``osqp/``
    OSQP's embedded C code for this very QP (``osqp`` 1.x ``codegen``,
    vectors mode: the matrices are fixed, the bounds change every sample),
    with its workspace (``workspace.c``: every matrix and vector of the
    solver as static data; no dynamic memory).
``<name>.h``, ``<name>.c``
    ``int <name>_step(const double x[n], double u[m])``: the MPC at the
    full state ``x``: the bounds at ``dx = x - x_op`` (``l - E dx``,
    ``u - E dx``), ``osqp_update_data_vec``, ``osqp_solve``, then
    ``u = u_op + clip(-K dx + v_0)``. Returns OSQP's status (1: solved).

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
    within ``tolerance`` of the Python controller's
    (:class:`PythonReference`: the same filter, and the same QP with the
    same OSQP settings through OSQP's Python interface; the embedded code
    neither polishes nor adapts its step size, so neither does the
    reference), and the filter's state after each update equal to the
    Python filter's to round-off (``Z_TOLERANCE`` relative).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from equilibrist.errors import ExportError
from equilibrist.export._check import ControllerExport, Described, Steps
from equilibrist.export.writer import register_exporter

if TYPE_CHECKING:
    from equilibrist.control.mpc import MPC, MPCRuntime
    from equilibrist.numeric.system import System


def _array(name: str, values: np.ndarray) -> str:
    flat = ", ".join(repr(float(v)) for v in np.asarray(values, dtype=float).reshape(-1))
    size = max(1, int(np.size(values)))
    return f"static const OSQPFloat {name}[{size}] = {{{flat or '0.0'}}};"


def _finite(values: np.ndarray, big: float = 1e30) -> np.ndarray:
    return np.clip(np.asarray(values, dtype=float), -big, big)


#: OSQP's settings of the exported solver (embedded code: no polishing, no rho adaptation).
SETTINGS = {"eps_abs": 1e-6, "eps_rel": 1e-6, "polishing": False, "adaptive_rho": False,
            "max_iter": 4000, "verbose": False, "warm_starting": True}


class PythonReference:
    """The exported controller's computation through OSQP's Python interface (same settings).

    ``step(y)`` is the command at the measurement *y* (the full state when
    ``estimator="state"``), ``update(y, u_applied)`` advances the filter
    (:class:`~equilibrist.control.mpc.KalmanFront`, the simulated
    controller's own), ``front.z`` its state.
    """

    def __init__(self, ctrl: MPC) -> None:
        import osqp

        from equilibrist.control.mpc import KalmanFront

        self.ctrl = ctrl
        H, q, A, lo, hi, E = ctrl.problem.matrices()
        self.lo, self.hi, self.E = _finite(lo), _finite(hi), E
        self.solver = osqp.OSQP()
        self.solver.setup(H, q, A, self.lo, self.hi, **SETTINGS)
        self.front = KalmanFront(ctrl)

    def solve(self, dx: np.ndarray) -> np.ndarray:
        """The command at the state deviation *dx*."""
        from equilibrist.control.mpc import PRIMAL_TOL

        prob = self.ctrl.problem
        l, u = prob.bounds(dx, self.lo, self.hi, self.E)
        self.solver.update(l=l, u=u)
        res = self.solver.solve()
        v0 = (prob.horizon + 1) * prob.n
        du = -prob.K @ dx
        if str(res.info.status) == "solved" or float(res.info.prim_res) <= PRIMAL_TOL:
            du = du + np.asarray(res.x)[v0:v0 + prob.m]
        return self.ctrl.u_op + np.clip(du, prob.u_lo, prob.u_hi)

    def step(self, y: np.ndarray) -> np.ndarray:
        """The command at the measurement *y* (the filter's estimate, or the state)."""
        return self.solve(self.front.estimate(y))

    def update(self, y: np.ndarray, u_applied: np.ndarray) -> None:
        self.front.update(y, u_applied)


def record(ctrl: MPC, *, x0: Mapping[str, float] | None = None, duration: float = 1.0,
           seed: int = 0) -> dict[str, np.ndarray]:
    """Recorded vectors: a closed-loop run of the simulated MPC with the design's sensor noise.

    ``y`` (measurements), ``u_applied``, and the reference's commands ``u``
    and filter states ``z`` (after each update) on them.
    """
    from equilibrist.control.mpc import MPCRuntime
    from equilibrist.numeric.system import system_from_key
    from equilibrist.sim.noise import Noise
    from equilibrist.sim.run import simulate

    design = ctrl.design
    system = system_from_key(design.system_key, dict(design.params))
    run = simulate(system, MPCRuntime(ctrl), duration=duration, x0=dict(x0 or {"theta": 0.5}),
                   region={}, noise=Noise.from_design(design), seed=seed)
    ys, applied = np.array(run.measurements), np.array(run.applied)
    ref = PythonReference(ctrl)
    us, zs = [], []
    for y, ua in zip(ys, applied, strict=True):
        us.append(ref.step(y))
        ref.update(y, ua)
        zs.append(ref.front.z.copy())
    return {"y": ys, "u_applied": applied, "u": np.array(us), "z": np.array(zs)}


#: Round-off bound of the filter's state in ``make check`` (relative to ``1 + |z|``).
Z_TOLERANCE = 1e-12


def export_mpc(ctrl: MPC, folder: str | Path, *, name: str = "mpc",
               x0: dict[str, float] | None = None, duration: float = 1.0,
               tolerance: float = 1e-3, seed: int = 0) -> Path:
    """Write the MPC's C code, recorded vectors and ``make check`` into *folder*.

    *x0* starts the recorded run (default: the pole at 0.5 rad, which
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
              duration: float = 1.0, tolerance: float = 1e-3, seed: int = 0) -> dict[str, str]:
    """Every file of the MPC's export, relative path -> text (OSQP's generated code under
    ``osqp/``, the library, the recorded vectors, the test program and the Makefile)."""
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
                "with sensor noise; commands of the same QP through OSQP's Python interface.",
        what="the C MPC against the Python controller on recorded measurements.",
        sources=("$(wildcard osqp/src/*.c)", "osqp/workspace.c"),
        include=("osqp", "osqp/inc/public", "osqp/inc/private"),
        cflags="-O2 -std=c99 -ffp-contract=off",
    )
    return {**files, **checks}


def library_files(ctrl: MPC, *, name: str = "mpc") -> dict[str, str]:
    """The library alone, relative path -> text: OSQP's generated code under ``osqp/``,
    ``<name>.h`` and ``<name>.c``."""
    import tempfile

    import osqp

    from equilibrist.export.linear_c import LINEAR_C

    if not name.isidentifier():
        raise ExportError(f"the library's name must be a C identifier, got {name!r}")
    kalman = ctrl.estimator == "kalman"
    prob = ctrl.problem
    H, q, A, lo, hi, E = prob.matrices()
    solver = osqp.OSQP()
    solver.setup(H, q, A, _finite(lo), _finite(hi), **SETTINGS)
    generated: dict[str, str] = {}
    with tempfile.TemporaryDirectory(prefix="equilibrist-osqp-") as tmp:
        solver.codegen(str(Path(tmp) / "osqp"), parameters="vectors", force_rewrite=True)
        for path in sorted(Path(tmp).rglob("*")):
            if path.is_file():
                generated[path.relative_to(tmp).as_posix()] = path.read_text()
    from equilibrist.control.mpc import PRIMAL_TOL

    n, m, ny = prob.n, prob.m, len(ctrl.output_names)
    nc = int(E.shape[0])
    ns = prob.n_soft
    _, Fs = prob.soft_predictions
    r_lo, r_hi = prob.soft_rows()
    v0 = (prob.horizon + 1) * n
    up = name.upper()
    lines = [
        f"/* {name}: constrained MPC (horizon {prob.horizon}) solved by OSQP's generated code,",
        f" * generated by equilibrist. Sample rate {ctrl.rate:g} Hz. Input: "
        f"{', '.join(ctrl.input_names)}.",
        f" * State: {', '.join(ctrl.state_names)}."
        + (f" Measured: {', '.join(ctrl.output_names)} (Kalman filter, {ctrl.form} form). */"
           if kalman else " */"),
        f"#ifndef {up}_H", f"#define {up}_H", f"#define {up}_NX {n}", f"#define {up}_NU {m}",
        f"#define {up}_RATE_HZ {ctrl.rate!r}", "",
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
        f'/* {name}.c: generated by equilibrist (the QP of equilibrist.control.mpc). */',
        "#include <stddef.h>", '#include "osqp.h"', '#include "workspace.h"', f'#include "{name}.h"',
        "", f"#define NC {nc}", f"#define NX {n}", f"#define NU {m}", f"#define V0 {v0}", "",
        _array("E", E), _array("L0", _finite(lo)), _array("U0", _finite(hi)),
        _array("K", prob.K), _array("X_OP", ctrl.x_op), _array("U_OP", ctrl.u_op),
        _array("U_LO", prob.u_lo), _array("U_HI", prob.u_hi), "",
        f"#define NS {ns}", f"#define NH {prob.horizon}", f"#define R_LO {r_lo}",
        f"#define R_HI {r_hi}", f"#define PRIMAL_TOL {PRIMAL_TOL!r}",
        _array("FS", Fs), _array("S_LO", prob.soft_lo), _array("S_HI", prob.soft_hi),
        "static const int S_IDX[" + str(max(1, ns)) + "] = {"
        + (", ".join(str(i) for i in prob.soft_index) or "0") + "};",
        "static OSQPFloat l_now[NC];", "static OSQPFloat u_now[NC];", "",
        "static int solve_at(const OSQPFloat dx[NX], double u[NU])",
        "{",
        "    int i, j, use;",
        "    for (i = 0; i < NC; ++i) {",
        "        OSQPFloat s = 0.0;",
        "        for (j = 0; j < NX; ++j) s += E[i * NX + j] * dx[j];",
        "        l_now[i] = L0[i] - s;",
        "        u_now[i] = U0[i] - s;",
        "    }",
        "    /* A soft bound the state already violates: widened to the LQR's own trajectory. */",
        "    for (j = 0; j < NS; ++j) {",
        "        OSQPFloat c = dx[S_IDX[j]];",
        "        int k;",
        "        if (c <= S_HI[j] && c >= S_LO[j]) continue;",
        "        for (k = 0; k < NH; ++k) {",
        "            int row = k * NS + j, q;",
        "            OSQPFloat xs = 0.0;",
        "            for (q = 0; q < NX; ++q) xs += FS[row * NX + q] * dx[q];",
        "            if (xs < l_now[R_LO + row]) l_now[R_LO + row] = xs;",
        "            if (xs > u_now[R_HI + row]) u_now[R_HI + row] = xs;",
        "        }",
        "    }",
        "    osqp_update_data_vec(&solver, OSQP_NULL, l_now, u_now);",
        "    osqp_solve(&solver);",
        "    /* Not solved and its plan not feasible to PRIMAL_TOL: the LQR (clipped). */",
        "    use = solver.info->status_val == OSQP_SOLVED || solver.info->prim_res <= PRIMAL_TOL;",
        "    for (i = 0; i < NU; ++i) {",
        "        OSQPFloat du = use ? solver.solution->x[V0 + i] : 0.0;",
        "        for (j = 0; j < NX; ++j) du -= K[i * NX + j] * dx[j];",
        "        if (du < U_LO[i]) du = U_LO[i];",
        "        if (du > U_HI[i]) du = U_HI[i];",
        "        u[i] = U_OP[i] + du;",
        "    }",
        "    return (int)solver.info->status_val;",
        "}", "",
        f"int {name}_step(const double x[NX], double u[NU])",
        "{",
        "    OSQPFloat dx[NX];",
        "    int i;",
        "    for (i = 0; i < NX; ++i) dx[i] = x[i] - X_OP[i];",
        "    return solve_at(dx, u);",
        "}", "",
    ]
    if kalman:
        form = PythonReference(ctrl).front.linear_form()
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
            "{", "    OSQPFloat dx[NX];", "    int i;",
            "    eq_linear_estimate(&FILTER, f->z, y, dx);",
            "    for (i = 0; i < NX; ++i) x[i] = X_OP[i] + dx[i];", "}", "",
            f"int {name}_output(const {name}_filter *f, const double y[NY], double u[NU])",
            "{", "    OSQPFloat dx[NX];",
            "    eq_linear_estimate(&FILTER, f->z, y, dx);",
            "    return solve_at(dx, u);", "}", "",
            f"void {name}_update({name}_filter *f, const double y[NY], const double u_applied[NU])",
            "{", "    OSQPFloat z[NX];", "    int i;",
            "    eq_linear_update(&FILTER, f->z, y, NULL, u_applied, z);",
            "    for (i = 0; i < NX; ++i) f->z[i] = z[i];", "}", "",
        ]
    source = "\n".join(body)
    return {**generated, f"{name}.h": header, f"{name}.c": source}


def footprint(folder: str | Path, *, name: str = "mpc") -> dict[str, int]:
    """Bytes of code (text), initialized data and zeroed data of the library alone
    (OSQP's sources, its workspace and the driver; without the test and its vectors),
    measured with the C compiler and ``size`` on the object files."""
    import subprocess
    import tempfile

    from equilibrist.export.native import compiler

    src = Path(folder)
    files = [*sorted((src / "osqp" / "src").glob("*.c")), src / "osqp" / "workspace.c",
             src / f"{name}.c"]
    total = {"text": 0, "data": 0, "bss": 0}
    with tempfile.TemporaryDirectory() as tmp:
        for i, f in enumerate(files):
            obj = Path(tmp) / f"{i}.o"
            subprocess.run([*compiler(), "-O2", "-std=c99", f"-I{src / 'osqp'}",
                            f"-I{src / 'osqp' / 'inc' / 'public'}",
                            f"-I{src / 'osqp' / 'inc' / 'private'}", f"-I{src}", "-c", str(f),
                            "-o", str(obj)], check=True, capture_output=True)
            out = subprocess.run(["size", str(obj)], check=True, capture_output=True, text=True)
            text, data, bss = (int(v) for v in out.stdout.splitlines()[1].split()[:3])
            total["text"] += text
            total["data"] += data
            total["bss"] += bss
    return total


class CompiledMPC:
    """The exported C MPC compiled into a shared library and called through ctypes.

    A :class:`~equilibrist.control.controller.PythonController` (``reset``,
    ``output``, ``update``) on the controller's measured outputs, so the
    code that runs on the robot closes the loop in the simulation. Each
    instance compiles its own copy (OSQP's workspace is static data).
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
        sources = [*sorted((folder / "osqp" / "src").glob("*.c")), folder / "osqp" / "workspace.c",
                   folder / f"{name}.c"]
        lib = folder / f"lib{name}.so"
        inc = [f"-I{folder / d}" for d in ("osqp", "osqp/inc/public", "osqp/inc/private", ".")]
        proc = subprocess.run([*compiler(), "-O2", "-std=c99", "-ffp-contract=off", "-fPIC",
                               "-shared", *inc, *map(str, sources), "-o", str(lib), "-lm"],
                              capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            raise ExportError("the exported MPC does not compile: "
                              + " | ".join((proc.stderr or proc.stdout).strip().splitlines()[:6]))
        self._lib: Any = ctypes.CDLL(str(lib))
        dp = ctypes.POINTER(ctypes.c_double)
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
    """``equilibrist export SYSTEM --controller mpc``: OSQP's generated solver, driver, ``make check``.

    The controller exported is the one simulated: with the Kalman filter in
    front when the design's measured outputs are not the full state.
    """
    import hashlib

    from equilibrist.export.writer import (
        EXPORT_MARKER,
        check_folder,
        generator_version,
        write_files,
    )

    if precision != "double":
        raise ExportError(f"the MPC is exported in double precision only, not {precision!r}")
    ctrl = built.ctrl
    folder = check_folder(out, force=force)
    texts = mpc_files(ctrl, duration=duration or 1.0, seed=seed)
    texts[EXPORT_MARKER] = f"written by {generator_version()}\n"
    write_files(folder, texts)
    digest = hashlib.sha256(np.asarray(ctrl.problem.K).tobytes()
                            + (b"" if ctrl.Kf is None else np.asarray(ctrl.Kf).tobytes())
                            ).hexdigest()[:12]
    kalman = ctrl.estimator == "kalman"
    files = {"osqp/": "OSQP's generated solver and workspace",
             "mpc.h": "the interface" + (" (Kalman filter in front)" if kalman else ""),
             "mpc.c": ("the Kalman filter and " if kalman else "")
             + "the step: bounds at the state, OSQP, the move",
             "mpc_vectors.h": "recorded measurements and the Python controller's commands",
             "test_mpc.c": "test program", "Makefile": "make check"}
    steps = round((duration or 1.0) * ctrl.rate) + 1
    return MPCExport(folder=folder, name="mpc", files=files, precision="double",
                     data=Described(digest, "mpc", ctrl.rate), vectors=Steps(steps))


__all__ = ["SETTINGS", "Z_TOLERANCE", "CompiledMPC", "MPCExport", "PythonReference", "export_files", "export_mpc",
           "footprint", "mpc_files", "record"]
