"""Load and evaluation speed of the derived models.

For every system of the catalogue, in fresh processes:

* cold load: derivation with sympy + code generation (empty cache);
* warm load: ``import equilibrist`` + ``get_system`` + one ``f`` call, from the cache;
* one evaluation of ``f`` and of the Jacobians with the generated code,
  against sympy's ``lambdify`` of the same symbolic expressions (the peer a
  sympy user would reach for), in microseconds per call.

Run: ``.venv/bin/python bench/bench_load.py`` (about a minute).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import timeit

import numpy as np

CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
from equilibrist.numeric.lookup import get_system
name, variant = sys.argv[1], sys.argv[2]
settings = {} if variant == "-" else {"euler": variant}
s = get_system(name, **settings)
import numpy as np
x = np.zeros(s.n_states); x[0] = 0.3
if name == "gyroscope":
    x[:3] = 0.5
s.functions.f(x, np.zeros(s.n_inputs), s.p, np.empty(s.n_states))
print(json.dumps({"seconds": time.perf_counter() - t0}))
"""


def _child(name: str, variant: str, cache: str) -> float:
    env = dict(os.environ, EQUILIBRIST_CACHE=cache)
    out = subprocess.run([sys.executable, "-c", CHILD, name, variant], env=env,
                         capture_output=True, text=True, check=True).stdout
    return json.loads(out)["seconds"]


def _eval_speed(name: str, variant: str) -> tuple[float, float, float, float]:
    import sympy as sp

    from equilibrist.numeric.lookup import get_system

    settings = {} if variant == "-" else {"euler": variant}
    s = get_system(name, **settings)
    model = s.symbolic
    x = np.full(s.n_states, 0.3)
    u = np.full(s.n_inputs, 0.1)
    out = np.empty(s.n_states)
    A = np.empty((s.n_states, s.n_states))
    B = np.empty((s.n_states, s.n_inputs))
    fn, jac, p = s.functions.f, s.functions.jac, s.p
    n = 2000
    t_f = min(timeit.repeat(lambda: fn(x, u, p, out), number=n, repeat=5)) / n
    t_j = min(timeit.repeat(lambda: jac(x, u, p, A, B), number=n, repeat=5)) / n
    args = (*model.states, *model.inputs, *model.params)
    lf = sp.lambdify(args, model.f, "numpy")
    lj = sp.lambdify(args, sp.Matrix.hstack(model.A, model.B), "numpy")
    vals = (*x, *u, *p)
    m = 200
    l_f = min(timeit.repeat(lambda: lf(*vals), number=m, repeat=5)) / m
    l_j = min(timeit.repeat(lambda: lj(*vals), number=m, repeat=5)) / m
    return t_f, t_j, l_f, l_j


def main() -> None:
    from equilibrist.systems import registry

    rows = []
    for entry in registry.all_entries():
        name = entry.spec.name
        variant = "-" if entry.spec.variant is None else entry.spec.variant[1]
        with tempfile.TemporaryDirectory() as tmp:
            cold = _child(name, variant, tmp)
            warm = min(_child(name, variant, tmp) for _ in range(3))
        t_f, t_j, l_f, l_j = _eval_speed(name, variant)
        rows.append((entry.spec.key, cold, warm, t_f * 1e6, t_j * 1e6, l_f / t_f, l_j / t_j))
    head = f"{'system':28s} {'cold s':>7s} {'warm s':>7s} {'f us':>7s} {'jac us':>7s} {'lambdify/f':>11s} {'lambdify/jac':>13s}"
    print(head)
    for r in rows:
        print(f"{r[0]:28s} {r[1]:7.2f} {r[2]:7.3f} {r[3]:7.2f} {r[4]:7.2f} {r[5]:11.1f} {r[6]:13.1f}")


if __name__ == "__main__":
    main()
