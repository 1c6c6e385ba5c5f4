"""Drake's RegionOfAttraction on the cart-pole's closed loop, one problem file in, JSON out.

Runs under Drake's own environment (bench/peers_drake.sh):

    bench/_peers/drake/bin/python bench/_drake_roa.py PROBLEM.json

PROBLEM.json (written by bench/bench_drake_roa.py) holds ``S`` (the candidate
``V = x' S x``, in deviations from the operating point at the origin) and
``forms``: each a closed-loop vector field ``dx/dt = f(x)`` given either as
polynomial terms (``terms``: per state a list of ``[coefficient, [exponents]]``)
or as text (``text``: per state an expression in ``x0..x3``, ``sin``, ``cos``,
``**``), and whether to ask for the implicit form (``implicit``). For each
form one JSON line reports the level ``rho`` of ``x' S x`` Drake proves (its
answer is ``V / rho``, so ``rho`` is the candidate over the answer, checked at
several points), the seconds of the call (wall and process CPU) and the
solver, or the exact error Drake raised.
"""

import json
import resource
import sys
import time

import numpy as np
from pydrake.solvers import ClarabelSolver, CsdpSolver, MosekSolver, ScsSolver
from pydrake.symbolic import Expression, Variable, cos, sin
from pydrake.systems.analysis import RegionOfAttraction, RegionOfAttractionOptions
from pydrake.systems.primitives import SymbolicVectorSystem

SOLVERS = {"clarabel": ClarabelSolver, "csdp": CsdpSolver, "scs": ScsSolver,
           "mosek": MosekSolver}


def field(form, x):
    if "terms" in form:
        out = []
        for terms in form["terms"]:
            e = Expression(0.0)
            for coef, exps in terms:
                mono = Expression(float(coef))
                for xi, k in zip(x, exps, strict=True):
                    if k:
                        mono = mono * xi ** int(k)
                e = e + mono
            out.append(e)
        return out
    names = {f"x{i}": xi for i, xi in enumerate(x)}
    names.update({"sin": sin, "cos": cos})
    return [Expression(0.0) + eval(text, {"__builtins__": {}}, names) for text in form["text"]]


def solve(S, form):
    n = S.shape[0]
    x = [Variable(f"x{i}") for i in range(n)]
    f = field(form, x)
    system = SymbolicVectorSystem(state=x, dynamics=f)
    context = system.CreateDefaultContext()
    context.SetContinuousState(np.zeros(n))
    options = RegionOfAttractionOptions()
    xv = np.array(x, dtype=object)
    candidate = xv.dot(S.dot(xv))
    options.lyapunov_candidate = candidate
    options.state_variables = xv
    options.use_implicit_dynamics = bool(form.get("implicit", False))
    solver = SOLVERS.get(form.get("solver", ""))
    if solver is not None:
        options.solver_id = solver.id()
    used = form.get("solver") or "Drake's choice"
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        V = RegionOfAttraction(system, context, options)
    except Exception as err:  # report Drake's own words
        return {"name": form["name"], "ok": False, "solver": used,
                "error": f"{type(err).__name__}: {err}",
                "seconds": time.perf_counter() - t0, "cpu": time.process_time() - c0}
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    rng = np.random.default_rng(0)
    ratios = []
    for p in rng.normal(size=(5, n)):
        env = {xi: float(v) for xi, v in zip(x, p, strict=True)}
        ratios.append(candidate.Evaluate(env) / V.Evaluate(env))
    return {"name": form["name"], "ok": True, "solver": used, "rho": float(np.median(ratios)),
            "rho_spread": float(np.ptp(ratios)), "seconds": seconds, "cpu": cpu,
            "V": str(V)[:200]}


def main():
    with open(sys.argv[1]) as fh:
        problem = json.load(fh)
    # A cap on the address space: the degree-5 problem grew past 20 GB unbounded.
    cap = int(float(problem.get("memory_gb", 8.0)) * 2**30)
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    S = np.asarray(problem["S"], dtype=float)
    # Drake picks the solver (the wheel's MOSEK needs a licence; the free conic solvers
    # come with it): say which were there.
    solvers = [s.__name__ for s in (MosekSolver, ClarabelSolver, CsdpSolver, ScsSolver)
               if s().available() and s().enabled()]
    for form in problem["forms"]:
        out = solve(S, form)
        out["solvers_enabled"] = solvers
        print(json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
