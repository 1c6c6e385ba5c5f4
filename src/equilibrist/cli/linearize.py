"""``equilibrist linearize``: A, B, C, D at an operating point."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

import numpy as np

from equilibrist.cli import common
from equilibrist.errors import NoEquilibriumError

if TYPE_CHECKING:
    from equilibrist.numeric.linear import LinearModel
    from equilibrist.numeric.system import Equilibrium, System


def add_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "linearize",
        help="linearize at the canonical operating point (or another one)",
        description="Linearize at the canonical operating point. --at and --input override "
        "components of it; components the operating point solves for (e.g. a holding thrust) "
        "stay free unless given.",
    )
    common.add_system(p)
    common.add_set(p)
    p.add_argument("--at", action="append", default=[], metavar="STATE=VALUE",
                   help="fix a state component of the point (repeatable)")
    p.add_argument("--input", action="append", default=[], metavar="NAME=VALUE",
                   help="fix an input of the point (repeatable)")
    common.add_json(p)
    p.set_defaults(func=run)


def point(system: System, at: list[str], inputs: list[str]) -> Equilibrium:
    """The equilibrium named by ``--at``/``--input`` (free components solved)."""
    state = {k: common.parse_number(v, f"--at {k}") for k, v in common.parse_assignments(at, "--at").items()}
    given = {k: common.parse_number(v, f"--input {k}")
             for k, v in common.parse_assignments(inputs, "--input").items()}
    try:
        return system.equilibrium(state=state, inputs=given)
    except NoEquilibriumError as exc:
        if system.n_inputs and not given:
            raise NoEquilibriumError(
                f"{exc}; give --input to linearize at a point that is not an equilibrium"
            ) from None
        raise


def run(args: argparse.Namespace) -> int:
    system = common.load_system(args)
    eq = point(system, args.at, args.input)
    lm = system.linearize(eq.x, eq.u)
    if args.json:
        common.print_json({
            "system": system.key,
            "states": list(lm.state_names),
            "inputs": list(lm.input_names),
            "outputs": list(lm.output_names),
            "params": dict(system.params),
            # Zeros without their sign, as the text prints them.
            "x0": unsigned(lm.x0),
            "u0": unsigned(lm.u0),
            "A": unsigned(lm.A),
            "B": unsigned(lm.B),
            "C": unsigned(lm.C),
            "D": unsigned(lm.D),
            "residual": lm.residual,
            # Always {"re", "im"}, as in 'design --json', whether or not any is complex.
            "poles": [{"re": _real(p.real), "im": _real(p.imag)} for p in lm.poles],
            # What the definition says of itself (a model file: what was made of it, what is ignored).
            "notes": list(system.spec.notes),
        })
        return 0
    print(render(system, lm))
    return 0


def render(system: System, lm: LinearModel) -> str:
    """Readable text of a linearization."""
    lines = [f"{system.key}: linearization at"]
    lines.append("  x0: " + ", ".join(f"{n} = {_real(v):.6g}"
                                      for n, v in zip(lm.state_names, lm.x0, strict=True)))
    if lm.n_inputs:
        lines.append("  u0: " + ", ".join(f"{n} = {_real(v):.6g}"
                                          for n, v in zip(lm.input_names, lm.u0, strict=True)))
    status = "an equilibrium" if lm.residual < 1e-9 else "NOT an equilibrium"
    lines.append(f"  residual |f(x0, u0)| = {lm.residual:.3g} ({status})")
    # Where a model file's operating point came from, when it was moved from the file's pose.
    lines += [f"  {n}" for n in system.spec.notes if n.startswith("operating point:") and "moved" in n]
    lines.append("A =")
    lines.append(_matrix(lm.A, lm.state_names, lm.state_names))
    if lm.n_inputs:
        lines.append("B =")
        lines.append(_matrix(lm.B, lm.state_names, lm.input_names))
    lines.append("C =")
    lines.append(_matrix(lm.C, lm.output_names, lm.state_names))
    poles = lm.poles
    lines.append("open-loop poles: " + ", ".join(_fmt_pole(p) for p in poles))
    unstable = int(np.sum(poles.real > 1e-9))
    lines.append(f"  {unstable} unstable" if unstable else "  none unstable")
    return "\n".join(lines)


def unsigned(values: object) -> np.ndarray:
    """*values* as floats, a negative zero (``-0.0``, which prints as ``-0``) made ``0.0``:
    a linearization's exact zeros carry the sign of the products they came from, which
    means nothing."""
    out: np.ndarray = np.asarray(values, dtype=float) + 0.0  # -0.0 + 0.0 is 0.0
    return out


def _real(v: float) -> float:
    return float(v) + 0.0  # a negative zero made 0.0, as in unsigned()


def _matrix(mat: np.ndarray, rows: tuple[str, ...], cols: tuple[str, ...]) -> str:
    """A labelled matrix whose columns stay apart however long their names are."""
    return common.format_matrix(unsigned(mat), rows, cols,
                                width=max([11, *(len(c) + 2 for c in cols)]))


def _fmt_pole(p: complex) -> str:
    if abs(p.imag) < 1e-12:
        return f"{_real(p.real):.4g}"
    return f"{_real(p.real):.4g}{_real(p.imag):+.4g}j"
