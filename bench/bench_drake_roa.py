"""The cart-pole's certified region of attraction beside Drake's RegionOfAttraction.

    bash bench/peers_drake.sh                 # Drake in its own environment, once
    .venv/bin/python bench/bench_drake_roa.py [--drake bench/_peers/drake/bin/python]

The same continuous plant and gain for both: the cart-pole's exact equations
(``get_system("cartpole")``), the LQR of ``design(system, rate=200.0)`` acting
continuously, ``u = sat(u_op - K dx)``, and the same candidate ``V = dx' S dx``
(``S`` of the design), so the two levels ``rho`` are on one scale.

* equilibrist: :func:`equilibrist.control.certify.certify` (interval
  branch-and-bound on the exact equations, with the saturation).
* Drake: ``RegionOfAttraction`` with ``lyapunov_candidate = x' S x`` (one
  S-procedure SOS program: the largest ``rho`` with ``(V - rho) (x'x)^d -
  lambda(x) dV/dt`` a sum of squares). It needs polynomial dynamics and has no
  saturation: it gets the Taylor polynomials of degree 3 and 5 of the closed
  loop ``f(x_op + dx, u_op - K dx)`` about the operating point (sympy, here),
  and the exact trigonometric field, explicit and implicit, to show what it
  does with it (bench/_drake_roa.py runs it in Drake's environment).

Each level is then checked against the true plant (the exact equations with
the saturation): ``dV/dt`` at ``--samples`` points drawn in the level (half
on its surface, ``sim.roa.sample_level``), counting those where ``dV/dt >= 0``;
``--runs`` starts on the level's surface run on the continuous loop
(``scipy.integrate.solve_ivp``, 3 s: lost if ``|theta|`` reaches pi/2 or ``V``
has not come down below 1 % of its start; runs where ``V`` rose above its start
at any solver step are counted apart) and on the sampled loop at 200 Hz
(``sim.roa.outcomes``, 3 s, no noise: lost unless it ends balanced). Along
20,000 rays, the least level where each field (the true plant, each Taylor
polynomial) has ``dV/dt >= 0`` says how large a level of this ``V`` can be.

Each Drake form runs in a process of its own with its address space capped
(``--memory-gb``, 8 GB): the degree-5 problem grew past 20 GB uncapped. A
form Drake refuses, or a process that dies, is shown with Drake's words.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import sympy as sp
from scipy.integrate import solve_ivp

from equilibrist import get_system
from equilibrist.control.certify import certify
from equilibrist.control.design import design
from equilibrist.control.linear import LinearController
from equilibrist.sim.roa import outcomes, sample_level

HERE = Path(__file__).resolve().parent


def taylor_terms(system: Any, K: np.ndarray, x_op: np.ndarray, u_op: np.ndarray,
                 degree: int) -> list[list[list[Any]]]:
    """The closed loop ``f(x_op + y, u_op - K y)`` to *degree* in ``y``: per state, the
    terms ``[coefficient, [exponents]]`` (the saturation left out, as Drake has none)."""
    model = system.symbolic
    n = len(model.states)
    y = sp.symbols(f"y0:{n}")
    t = sp.Symbol("t")
    sub: dict[Any, Any] = {p: float(v) for p, v in zip(model.params, system.p, strict=True)}
    sub.update({s: float(x_op[i]) + t * y[i] for i, s in enumerate(model.states)})
    for k, inp in enumerate(model.inputs):
        sub[inp] = float(u_op[k]) - t * sum(float(K[k, j]) * y[j] for j in range(n))
    out = []
    for expr in model.f:
        series = sp.series(sp.sympify(expr).xreplace(sub), t, 0, degree + 1).removeO()
        poly = sp.Poly(sp.expand(series.subs(t, 1)), *y)
        out.append([[float(c), [int(e) for e in m]] for m, c in poly.terms()
                    if abs(float(c)) > 0.0])
    return out


def exact_text(system: Any, K: np.ndarray, x_op: np.ndarray, u_op: np.ndarray) -> list[str]:
    """The exact closed loop (no saturation) in ``x0..x3`` deviations, as text."""
    model = system.symbolic
    n = len(model.states)
    y = sp.symbols(f"x0:{n}")
    sub: dict[Any, Any] = {p: float(v) for p, v in zip(model.params, system.p, strict=True)}
    sub.update({s: float(x_op[i]) + y[i] for i, s in enumerate(model.states)})
    for k, inp in enumerate(model.inputs):
        sub[inp] = float(u_op[k]) - sum(float(K[k, j]) * y[j] for j in range(n))
    return [sp.sstr(sp.sympify(e).xreplace(sub)) for e in model.f]


def first_rise(S: np.ndarray, vdot: Any, rho_max: float, directions: int = 20_000,
               seed: int = 0) -> float:
    """The least level (on a grid of 400 up to *rho_max*, along sampled directions) holding a
    point where ``vdot(dx) >= 0``: where ``V`` stops decreasing for that field."""
    n = S.shape[0]
    w = np.random.default_rng(seed).normal(size=(directions, n))
    T = np.linalg.inv(np.linalg.cholesky(S).T)
    w = (w / np.linalg.norm(w, axis=1)[:, None]) @ T.T  # w' S w = 1
    for rho in np.linspace(rho_max / 400, rho_max, 400):
        if (vdot(math.sqrt(rho) * w) >= 0.0).any():
            return float(rho)
    return math.inf


def poly_field(terms: list[list[list[Any]]]) -> Any:
    """The polynomial field of :func:`taylor_terms` at the rows of ``dx``."""
    def f(dx: np.ndarray) -> np.ndarray:
        out = np.zeros_like(dx)
        for i, row in enumerate(terms):
            for coef, exps in row:
                out[:, i] += coef * np.prod(dx ** np.asarray(exps, dtype=float), axis=1)
        return out
    return f


def run_drake(python: str, S: np.ndarray, forms: list[dict[str, Any]],
              memory_gb: float) -> list[dict[str, Any]]:
    """Each form in a Drake process of its own (a form that aborts the process, as the
    degree-5 one does, reports its last words and leaves the others be)."""
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for form in forms:
            path = Path(tmp) / "problem.json"
            path.write_text(json.dumps({"S": S.tolist(), "forms": [form],
                                        "memory_gb": memory_gb}))
            t0 = time.perf_counter()
            done = subprocess.run([python, str(HERE / "_drake_roa.py"), str(path)],
                                  capture_output=True, text=True, check=False)
            got = [json.loads(line) for line in done.stdout.splitlines()
                   if line.startswith("{")]
            if got:
                out.append(got[0])
                continue
            last = (done.stderr.strip().splitlines() or ["(nothing on stderr)"])[-1]
            out.append({"name": form["name"], "ok": False, "seconds": time.perf_counter() - t0,
                        "cpu": float("nan"),
                        "error": f"the process ended with {done.returncode}: {last}"})
    return out


class TruePlant:
    """The exact equations with the saturated continuous feedback, vectorised."""

    def __init__(self, system: Any, K: np.ndarray, S: np.ndarray, x_op: np.ndarray,
                 u_op: np.ndarray) -> None:
        model = system.symbolic
        self.f = sp.lambdify([*model.states, *model.inputs, *model.params], list(model.f),
                             "numpy")
        self.p = [float(v) for v in system.p]
        self.K, self.S, self.x_op, self.u_op = K, S, x_op, u_op
        self.lo, self.hi = (np.asarray(v, dtype=float) for v in system.input_limits)
        self.theta = system.state_names.index("theta")

    def u(self, x: np.ndarray) -> np.ndarray:
        raw = self.u_op - (x - self.x_op) @ self.K.T
        clipped: np.ndarray = np.clip(raw, self.lo, self.hi)
        return clipped

    def field(self, x: np.ndarray) -> np.ndarray:
        """``dx/dt`` at the rows of *x*."""
        u = self.u(x)
        cols = self.f(*x.T, *u.T, *self.p)
        return np.column_stack([np.broadcast_to(np.asarray(c, dtype=float), x.shape[:1])
                                for c in cols])

    def vdot(self, x: np.ndarray) -> np.ndarray:
        dx = x - self.x_op
        out: np.ndarray = 2.0 * np.einsum("ij,jk,ik->i", dx, self.S, self.field(x))
        return out

    def run(self, x0: np.ndarray, duration: float) -> tuple[bool, float, float]:
        """Continuous loop from *x0*: (lost, the largest V on the way and V at the end, both
        over V at the start). Lost: ``|theta|`` reached pi/2 or V did not fall below 1 %."""
        def rhs(_t: float, x: np.ndarray) -> np.ndarray:
            out: np.ndarray = self.field(x[None, :])[0]
            return out

        def fell(_t: float, x: np.ndarray) -> float:
            return math.pi / 2 - abs(float(x[self.theta] - self.x_op[self.theta]))

        fell.terminal = True  # type: ignore[attr-defined]
        sol = solve_ivp(rhs, (0.0, duration), x0, method="LSODA", rtol=1e-8, atol=1e-10,
                        events=fell)
        dx = sol.y.T - self.x_op
        v = np.einsum("ij,jk,ik->i", dx, self.S, dx) / float(dx[0] @ self.S @ dx[0])
        return bool(sol.status == 1 or v[-1] > 1e-2), float(v[1:].max()), float(v[-1])


def check(plant: TruePlant, system: Any, ctrl: Any, rho: float, samples: int, runs: int,
          seed: int) -> dict[str, Any]:
    """*rho* against the true plant: sampled ``dV/dt``, continuous and sampled-loop runs."""
    S, x_op = plant.S, plant.x_op
    pts = sample_level(S, x_op, rho, samples, seed=seed)
    vd = plant.vdot(pts)
    bad = vd >= 0.0
    raw = plant.u_op - (pts - x_op) @ plant.K.T
    saturated = np.any((raw < plant.lo) | (raw > plant.hi), axis=1)
    peak_u = math.sqrt(rho * float((plant.K @ np.linalg.solve(S, plant.K.T))[0, 0]))
    surface = sample_level(S, x_op, rho, 2 * runs, seed=seed + 1)[:runs]
    lost_c, rose, worst = [], 0, 0.0
    for x0 in surface:
        lost, peak, end = plant.run(x0, 3.0)
        lost_c.append(lost)
        rose += peak > 1.0 + 1e-9
        worst = max(worst, end)
    caught = outcomes(system, ctrl, surface, {"duration": 3.0, "rate": 200.0, "noise": None},
                      seed)
    first_bad = pts[np.argmax(bad)] if bad.any() else None
    lost_idx = np.flatnonzero(lost_c)
    return {"violations": int(bad.sum()), "samples": samples,
            "first_violation": None if first_bad is None else first_bad.tolist(),
            "first_violation_vdot": None if first_bad is None else float(vd[np.argmax(bad)]),
            "saturated": float(saturated.mean()), "peak_u": peak_u,
            "lost_continuous": int(np.sum(lost_c)), "worst_ratio": worst, "rose": rose,
            "first_lost": surface[lost_idx[0]].tolist() if lost_idx.size else None,
            "lost_sampled": int((~caught).sum()), "runs": runs,
            "first_lost_sampled": (surface[np.flatnonzero(~caught)[0]].tolist()
                                   if (~caught).any() else None)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drake", default=str(HERE / "_peers" / "drake" / "bin" / "python"),
                    help="a Python with pydrake (bench/peers_drake.sh makes one)")
    ap.add_argument("--samples", type=int, default=100_000, help="dV/dt points per level")
    ap.add_argument("--runs", type=int, default=200, help="starts on each level's surface")
    ap.add_argument("--boxes", type=int, default=1_000_000, help="certify's box budget")
    ap.add_argument("--degrees", default="3,5", help="Taylor degrees for Drake")
    ap.add_argument("--solver", default="", help="Drake's SDP solver (clarabel, csdp, scs; "
                    "default: Drake's choice, Clarabel without a MOSEK licence)")
    ap.add_argument("--memory-gb", type=float, default=8.0, help="Drake's address-space cap")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", help="write every figure to this file")
    args = ap.parse_args()
    if not Path(args.drake).exists():
        print(f"no Drake at {args.drake}: run bash bench/peers_drake.sh first", file=sys.stderr)
        return 2
    system = get_system("cartpole")
    eq = system.operating_point()
    x_op, u_op = np.asarray(eq.x, dtype=float), np.asarray(eq.u, dtype=float)
    d = design(system, rate=200.0)
    K, S = np.atleast_2d(np.asarray(d.K, dtype=float)), np.asarray(d.S, dtype=float)
    print(f"load average of the machine: {os.getloadavg()[0]:.1f} (2 cores)")

    forms: list[dict[str, Any]] = []
    for degree in (int(v) for v in args.degrees.split(",")):
        forms.append({"name": f"Taylor degree {degree}", "solver": args.solver,
                      "terms": taylor_terms(system, K, x_op, u_op, degree)})
    text = exact_text(system, K, x_op, u_op)
    forms.append({"name": "exact (sin, cos, rational)", "text": text})
    forms.append({"name": "exact, implicit form", "text": text, "implicit": True})
    drake = run_drake(args.drake, S, forms, args.memory_gb)

    t0, c0 = time.perf_counter(), time.process_time()
    cert = certify(system, K, S, x_op=x_op, u_op=u_op, max_boxes=args.boxes)
    ours_s, ours_cpu = time.perf_counter() - t0, time.process_time() - c0

    plant = TruePlant(system, K, S, x_op, u_op)
    ctrl = LinearController.from_design(d, kind="lqr")
    rows: list[dict[str, Any]] = [{"method": "equilibrist certify (exact, saturated)",
                                   "rho": cert.rho, "seconds": ours_s, "cpu": ours_cpu,
                                   "limited_by": cert.limited_by,
                                   "violation": cert.violation}]
    rows[0]["first_rise"] = first_rise(
        S, lambda dx: plant.vdot(x_op + dx), 1.2 * cert.rho_region, seed=args.seed)
    for got, form in zip(drake, forms, strict=True):
        row: dict[str, Any] = {"method": f"Drake RegionOfAttraction, {got['name']}",
                               "seconds": got["seconds"], "cpu": got["cpu"]}
        if got["ok"]:
            row["rho"] = got["rho"]
        else:
            row["rho"], row["error"] = None, got["error"]
        if "terms" in form:
            model = poly_field(form["terms"])
            row["first_rise"] = first_rise(
                S, lambda dx, m=model: 2.0 * np.einsum("ij,jk,ik->i", dx, S, m(dx)),
                1.2 * cert.rho_region, seed=args.seed)
        rows.append(row)
    for row in rows:
        if row["rho"] is not None:
            row.update(check(plant, system, ctrl, row["rho"], args.samples, args.runs,
                             args.seed))

    print(f"\n{'method':<52} {'level rho':>9} {'wall s':>7} {'CPU s':>7} {'dV/dt >= 0':>15} "
          f"{'lost, continuous':>16} {'lost, 200 Hz':>12}")
    for row in rows:
        if row["rho"] is None:
            why = ("a denominator holds the state: not polynomial"
                   if "should be free of the indeterminates" in row["error"]
                   else row["error"][:60])
            print(f"{row['method']:<52} {'failed':>9} {row['seconds']:>7.2f} {row['cpu']:>7.2f}"
                  f"  ({why})")
            continue
        print(f"{row['method']:<52} {row['rho']:>9.1f} {row['seconds']:>7.2f} {row['cpu']:>7.2f} "
              f"{row['violations']:>4} of {row['samples']:<7} "
              f"{row['lost_continuous']:>6} of {row['runs']:<4} {row['lost_sampled']:>5} of "
              f"{row['runs']:<4}")
    print()
    for row in rows:
        if row["rho"] is None:
            print(f"{row['method']}: {row['error']}")
            if "first_rise" in row:
                print(f"  its polynomial: dV/dt >= 0 first met at level {row['first_rise']:.0f}")
            continue
        print(f"{row['method']}: |u| up to {row['peak_u']:.0f} N on the level (limit 200 N, "
              f"saturated at {row['saturated']:.1%} of the points); continuous loop: V rose above its start in "
              f"{row['rose']} of {row['runs']} runs, V(3 s)/V(0) at most {row['worst_ratio']:.2g}")
        if "first_rise" in row:
            on = "its polynomial" if "Taylor" in row["method"] else "the true plant"
            print(f"  the field it was proven on ({on}): dV/dt >= 0 first met at level "
                  f"{row['first_rise']:.0f} (20,000 rays, 400 levels)")
        if row["first_violation"] is not None:
            print(f"  dV/dt = {row['first_violation_vdot']:.3g} >= 0 at x = "
                  f"{np.round(row['first_violation'], 4).tolist()}")
        if row["first_lost"] is not None:
            print(f"  lost on the continuous loop from x0 = "
                  f"{np.round(row['first_lost'], 4).tolist()}")
        if row["first_lost_sampled"] is not None:
            print(f"  lost at 200 Hz from x0 = {np.round(row['first_lost_sampled'], 4).tolist()}")
    if cert.violation is not None:
        v = np.asarray(cert.violation)
        print(f"certify's nearest point with dV/dt >= 0: level {float((v - x_op) @ S @ (v - x_op)):.1f}"
              f", x = {np.round(v, 4).tolist()}")
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
