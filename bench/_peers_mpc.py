"""The MPC part of bench/bench_peers.py: equilibrist's MPC beside DAQP on the textbook QP.

The problem: the cart-pole at 200 Hz, horizon 30, ``|F| <= 20 N`` (the rig's
limit is 200 N), the default design's Bryson weights, the Riccati solution
``S`` as the terminal cost. The states: a closed loop of 300 samples (1.5 s)
from a push (the pole at 0.14 rad), run by equilibrist's MPC; the limit is
active in about half of them.

* equilibrist: ``mpc(system, design=d, horizon=30, estimator="state",
  constraints={})``, the input limit only (the same QP as the textbook's); its
  default (``constraints`` omitted) adds the track's and the pole's soft bounds,
  a larger QP (90 variables, 240 rows), timed alongside.
* DAQP on the textbook condensed QP: the moves ``U`` as the variables,
  ``min 1/2 U'HU + (F dx0)'U`` with ``H = 2 (G'QG + R)``, ``F = 2 G'Q Phi``
  (the stacked predictions ``X = Phi dx0 + G U``, ``Q`` block diagonal with ``S``
  last) and the limits as simple bounds; its Python ``Model`` (set up once, then
  ``update(f=F dx0)`` and ``solve()`` per sample, warm-started) and its C
  sources (those shipped in equilibrist, the same release 0.11) compiled with
  ``gcc -O2`` and timed in a C loop (``setup_daqp`` once, then per sample ``f``,
  ``daqp_update_ldp`` and ``daqp_solve``).
* equilibrist's exported C (``library_files``: DAQP's sources and the driver),
  compiled with the same flags, ``mpc_setup`` once, then ``mpc_step`` per sample.

Each pass replays the 300 states in order from a cold start (DAQP's working
set emptied, or holding only the slacks' bounds in equilibrist's default MPC), the contenders alternating pass by pass. Times are per call
(``perf_counter`` in Python, ``CLOCK_MONOTONIC`` in C); a call during which
the process was preempted (its involuntary context switches, from
``getrusage``, changed) is counted, and the worst of the others reported
beside the worst of all; a virtual machine's stolen time is not seen so, so
the code's own worst is also given: the worst over the states of each
state's best call over the passes (every pass replays the same states from
the same working sets). Every first input must agree with the textbook
QP's to 1e-10 N.
"""

from __future__ import annotations

import resource
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np

from equilibrist import get_system
from equilibrist.control.design import design
from equilibrist.control.mpc import MPC, mpc
from equilibrist.control.mpc_runtime import MPCRuntime
from equilibrist.native.daqp_library import DAQP_SOURCES
from equilibrist.native.mpc_library import library_files
from equilibrist.sim.run import simulate

HORIZON, RATE, LIMIT, PUSH = 30, 200.0, 20.0, {"theta": 0.14}
BUILD = Path(__file__).resolve().parent / "_build" / "peers_mpc"
CFLAGS = ["-O2", "-std=c99"]

_HARNESS = """#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include <sys/resource.h>
#include "states.h"
{include}
static long now(void) {{ struct timespec t; clock_gettime(CLOCK_MONOTONIC, &t);
                         return t.tv_sec * 1000000000L + t.tv_nsec; }}
static long switches(void) {{ struct rusage r; getrusage(RUSAGE_SELF, &r); return r.ru_nivcsw; }}
static long T[NSTATES]; static int S[NSTATES]; static double U[NSTATES];
{globals}
int main(int argc, char **argv)
{{
    int passes = argc > 1 ? atoi(argv[1]) : 1, p, i;
    long t0, t1, c;
    double u[1];
    {setup}
    for (p = 0; p < passes; ++p) {{
        {reset}
        for (i = 0; i < NSTATES; ++i) {{
            c = switches();
            t0 = now();
            {step}
            t1 = now();
            T[i] = t1 - t0; S[i] = switches() != c; U[i] = u[0];
        }}
        for (i = 0; i < NSTATES; ++i) printf("%ld %d %.17g\\n", T[i], S[i], U[i]);
    }}
    return 0;
}}
"""

_OURS = {
    "include": '#include "mpc.h"', "globals": "",
    "setup": "if (mpc_setup() != 0) return 1;",
    "reset": "mpc_setup();  /* the cold working set: the run starts cold */",
    "step": "mpc_step(STATES[i], u);",
}
_DAQP = {
    "include": '#include "api.h"\n#include "textbook.h"',
    "globals": "static c_float f[NZ], SOL[NZ], LAM[NZ]; static int SENSE[NZ];\n"
               "static DAQPProblem qp; static DAQPWorkspace work; static DAQPResult res;",
    "setup": "qp.n = NZ; qp.m = NZ; qp.ms = NZ; qp.H = TB_H; qp.f = f; qp.A = NULL;\n"
             "    qp.bupper = TB_BU; qp.blower = TB_BL; qp.sense = SENSE;\n"
             "    allocate_daqp_settings(&work);\n"
             "    if (setup_daqp(&qp, &work, NULL) < 0) return 1;\n"
             "    res.x = SOL; res.lam = LAM;",
    "reset": "for (i = 0; i < NZ; ++i) SENSE[i] = 0;\n"
             "        daqp_update_ldp(DAQP_UPDATE_sense, &work, &qp);",
    "step": "{ int j, q; for (j = 0; j < NZ; ++j) { c_float s = 0.0;\n"
            "                for (q = 0; q < NX; ++q) s += TB_F[j * NX + q] * (STATES[i][q] - X_OP[q]);\n"
            "                f[j] = s; }\n"
            "              daqp_update_ldp(DAQP_UPDATE_v, &work, &qp); daqp_solve(&res, &work);\n"
            "              u[0] = SOL[0] + U_OP0; }",
}


def problem() -> dict[str, Any]:
    """The controllers, the textbook QP and the closed loop's states."""
    system = get_system("cartpole", F_min=-LIMIT, F_max=LIMIT)
    d = design(system, rate=RATE)
    ctrl = mpc(system, design=d, horizon=HORIZON, estimator="state", constraints={})
    soft = mpc(system, design=d, horizon=HORIZON, estimator="state")
    states: list[np.ndarray] = []

    class Recorder(MPCRuntime):
        def output(self, t: float, y: np.ndarray, r: np.ndarray) -> np.ndarray:
            states.append(np.array(y, dtype=float) - self.ctrl.x_op)  # the full state measured
            return super().output(t, y, r)

    simulate(system, Recorder(ctrl), duration=300 / RATE, x0=PUSH, region={})
    X = ctrl.x_op + np.array(states[:300])
    return {"system": system, "ctrl": ctrl, "soft": soft, "states": X, "textbook": textbook(ctrl)}


def textbook(ctrl: MPC) -> dict[str, np.ndarray]:
    """The condensed QP of the textbook: ``H``, ``F`` (``f = F dx0``) and the moves' bounds."""
    d, N = ctrl.design, ctrl.problem.horizon
    A, B = np.asarray(d.discrete.A), np.asarray(d.discrete.B)
    n, m = B.shape
    Phi = np.zeros(((N + 1) * n, n))
    G = np.zeros(((N + 1) * n, N * m))
    Phi[:n] = np.eye(n)
    for k in range(N):
        Phi[(k + 1) * n:(k + 2) * n] = A @ Phi[k * n:(k + 1) * n]
        G[(k + 1) * n:(k + 2) * n] = A @ G[k * n:(k + 1) * n]
        G[(k + 1) * n:(k + 2) * n, k * m:(k + 1) * m] += B
    Qb = np.kron(np.eye(N + 1), np.asarray(d.Q))
    Qb[N * n:, N * n:] = np.asarray(d.S)
    H = 2.0 * (G.T @ Qb @ G + np.kron(np.eye(N), np.asarray(d.R)))
    return {"H": 0.5 * (H + H.T), "F": 2.0 * G.T @ Qb @ Phi,
            "bu": np.tile(ctrl.problem.u_hi, N), "bl": np.tile(ctrl.problem.u_lo, N)}


def _switches() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_nivcsw


def python_passes(p: dict[str, Any], passes: int) -> dict[str, dict[str, Any]]:
    """Per-call times [s] of the Python calls, the contenders alternating pass by pass."""
    import daqp

    X, tb = p["states"], p["textbook"]
    out: dict[str, dict[str, Any]] = {k: {"t": [], "pre": [], "u": None, "it": None}
                                      for k in ("ours", "soft", "daqp")}
    clock = time.perf_counter

    def ours(key: str, ctrl: MPC) -> None:
        rt = MPCRuntime(ctrl)
        xop, uop = ctrl.x_op, ctrl.u_op
        t, pre, us, its = [], [], [], []
        for x in X:
            dx = x - xop
            c = _switches()
            t0 = clock()
            du = rt.solve(dx)
            t1 = clock()
            t.append(t1 - t0)
            pre.append(_switches() != c)
            us.append(float(uop[0] + du[0]))
            its.append(rt.last_iterations)
        _keep(out[key], t, pre, us, its)

    def peer() -> None:
        mdl = daqp.Model()
        xop, uop = p["ctrl"].x_op, p["ctrl"].u_op
        mdl.setup(tb["H"], tb["F"] @ (X[0] - xop), np.zeros((0, tb["H"].shape[0])), tb["bu"],
                  tb["bl"], np.zeros(tb["bu"].size, dtype=np.intc))
        F = tb["F"]
        t, pre, us, its = [], [], [], []
        for x in X:
            dx = x - xop
            c = _switches()
            t0 = clock()
            mdl.update(f=F @ dx)
            sol, _, _, info = mdl.solve()
            u = sol[0]
            t1 = clock()
            t.append(t1 - t0)
            pre.append(_switches() != c)
            us.append(float(uop[0] + u))
            its.append(info["iterations"])
        _keep(out["daqp"], t, pre, us, its)

    for k in range(passes):
        order = [lambda: ours("ours", p["ctrl"]), peer, lambda: ours("soft", p["soft"])]
        for run in order if k % 2 == 0 else order[::-1]:
            run()
    return out


def _keep(rec: dict[str, Any], t: list[float], pre: list[bool], us: list[float],
          its: list[int]) -> None:
    rec["t"].append(t)
    rec["pre"].append(pre)
    if rec["u"] is None:
        rec["u"], rec["it"] = np.array(us), np.array(its)


def _arr(name: str, values: np.ndarray) -> str:
    flat = ", ".join(repr(float(v)) for v in np.asarray(values, dtype=float).reshape(-1))
    return f"static c_float {name}[{max(1, np.size(values))}] = {{{flat}}};"


def build_c(p: dict[str, Any], compiler: list[str]) -> dict[str, Path]:
    """The three C programs (ours with the input limit only, ours by default, DAQP's)."""
    X, tb, ctrl = p["states"], p["textbook"], p["ctrl"]
    states = (f"#define NSTATES {len(X)}\nstatic const double STATES[NSTATES][{X.shape[1]}] = {{"
              + ", ".join("{" + ", ".join(repr(float(v)) for v in x) + "}" for x in X) + "};\n")
    exes: dict[str, Path] = {}
    for key, c in (("ours", ctrl), ("soft", p["soft"]), ("daqp", None)):
        folder = BUILD / key
        files = library_files(c) if c is not None else {
            f"daqp/{q.relative_to(DAQP_SOURCES).as_posix()}": q.read_text()
            for q in DAQP_SOURCES.rglob("*") if q.is_file() and q.suffix in (".c", ".h")}
        if c is None:
            files["textbook.h"] = "\n".join([
                '#include "types.h"', f"#define NZ {tb['bu'].size}", f"#define NX {X.shape[1]}",
                f"#define U_OP0 {float(ctrl.u_op[0])!r}", _arr("TB_H", tb["H"]),
                _arr("TB_F", tb["F"]), _arr("TB_BU", tb["bu"]), _arr("TB_BL", tb["bl"]),
                _arr("X_OP", ctrl.x_op), ""])
        files["states.h"] = states
        files["bench.c"] = _HARNESS.format(**(_DAQP if c is None else _OURS))
        for rel, text in files.items():
            (folder / rel).parent.mkdir(parents=True, exist_ok=True)
            (folder / rel).write_text(text)
        sources = [folder / "bench.c", *sorted((folder / "daqp" / "src").glob("*.c"))]
        if c is not None:
            sources.append(folder / "mpc.c")
        exe = folder / "bench"
        subprocess.run([*compiler, *CFLAGS, f"-I{folder / 'daqp' / 'include'}", f"-I{folder}",
                        *map(str, sources), "-o", str(exe), "-lm"], check=True,
                       capture_output=True, text=True)
        exes[key] = exe
    return exes


def c_passes(exes: dict[str, Path], passes: int, chunk: int = 10) -> dict[str, dict[str, Any]]:
    """Per-call times [s] of the C loops, *chunk* passes per program run, alternating."""
    out: dict[str, dict[str, Any]] = {k: {"t": [], "pre": [], "u": None, "it": None} for k in exes}
    done = 0
    while done < passes:
        k = min(chunk, passes - done)
        for key, exe in exes.items():
            run = subprocess.run([str(exe), str(k)], check=True, capture_output=True, text=True)
            rows = np.array([line.split() for line in run.stdout.split("\n") if line],
                            dtype=float).reshape(k, -1, 3)
            for r in rows:
                out[key]["t"].append(list(r[:, 0] * 1e-9))
                out[key]["pre"].append(list(r[:, 1] > 0))
            if out[key]["u"] is None:
                out[key]["u"] = rows[0, :, 2]
        done += k
    return out


def stats(rec: dict[str, Any], active: np.ndarray) -> dict[str, float]:
    """Median (all states, active states), p99, worst, worst not preempted, and the code's
    worst: the worst state's best call over the passes (what the state costs when nothing
    else runs) [us]."""
    t = 1e6 * np.asarray(rec["t"])
    pre = np.asarray(rec["pre"], dtype=bool)
    quiet = t[~pre] if (~pre).any() else t
    best = t.min(axis=0)
    return {"median": float(np.median(t)), "median_active": float(np.median(t[:, active])),
            "p99": float(np.percentile(t, 99)), "worst": float(t.max()),
            "worst_quiet": float(quiet.max()), "preempted": int(pre.sum()),
            "worst_best": float(best.max()), "worst_state": int(best.argmax()),
            "first_state": float(np.median(t[:, 0]))}
