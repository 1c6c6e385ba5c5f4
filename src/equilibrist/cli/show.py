"""``equilibrist show``: equations of motion and the linearization at the operating point."""

from __future__ import annotations

import argparse

from equilibrist.cli import common
from equilibrist.errors import NoEquilibriumError


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser("show", help="print a system's equations of motion and linearization")
    common.add_system(p)
    common.add_set(p)
    p.add_argument("--latex", action="store_true", help="print the equations as LaTeX")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from equilibrist.cli.linearize import render
    from equilibrist.mechanics.printing import equations_latex, equations_text, matrix_latex

    system = common.load_system(args)
    spec, model = system.spec, system.symbolic
    print(f"{spec.key}: {spec.title}")
    print(f"  {spec.description}")
    print(f"  derived by: {model.method}; source: {spec.source}")
    print(f"  states: {', '.join(f'{s} [{u}]' for s, u in zip(system.state_names, system.state_units, strict=True))}")
    inputs = ", ".join(f"{i.name} [{i.unit}]" for i in spec.inputs) or "(none)"
    print(f"  inputs: {inputs}")
    print()
    if args.latex:
        print(equations_latex(model, spec))
        if model.M is not None:
            print()
            print("M = " + matrix_latex(model, spec, "M"))
            print("F = " + matrix_latex(model, spec, "F"))
    else:
        print(equations_text(model, spec))
    print()
    try:
        lm = system.linearize()
    except NoEquilibriumError as exc:
        print(f"no linearization shown: {exc}")
    else:
        print(render(system, lm))
        if args.latex:
            print()
            print("A = " + common_matrix_latex(lm.A))
            if lm.n_inputs:
                print("B = " + common_matrix_latex(lm.B))
    for title, items in (("seed slips corrected", spec.seed_slips), ("notes", spec.notes)):
        if items:
            print()
            print(f"{title}:")
            for item in items:
                print(f"  - {item}")
    return 0


def common_matrix_latex(mat: object) -> str:
    import sympy as sp

    text: str = sp.latex(sp.Matrix(mat).applyfunc(lambda v: sp.Float(v, 6)))
    return text
