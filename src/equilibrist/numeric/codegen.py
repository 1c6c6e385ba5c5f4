"""Generate plain-Python source for a symbolic model.

The generated module uses only ``math`` and array indexing, so the same
source runs as ordinary Python (microseconds per call, no compilation) and,
translated operation for operation to C (:mod:`equilibrist.native.pyc`), in
the simulation core. Common
subexpressions are eliminated once, across each function's outputs.

Sines and cosines (and ``eq_atan``, ``eq_tanh`` in a module that calls them) are the
project's own, copied into the module from :mod:`equilibrist.numeric.libm`, and an integer
power is printed as the product the C translation computes for ``**``
(:func:`equilibrist.numeric.libm.power_product`; a base that is not a symbol is assigned to a
``pw_`` name first, evaluated once as the C's temporary is): the generated dynamics give the
same bits on every machine, in Python and compiled (docs/reproducibility.md).

Functions in the generated module (``x``, ``u``, ``p`` are 1-D float arrays
in the order of the spec's states, inputs and parameters):

``f(x, u, p, out)``
    ``out[:] = x_dot``.
``jac(x, u, p, A, B)``
    ``A[:, :] = df/dx``, ``B[:, :] = df/du``.
``energy(x, p)``
    The conserved energy (NaN when the model states none).
``conserved(x, p, out)``
    The other conserved quantities, in the order of ``CONSERVED``.
``points(x, p, out)``
    ``out[k, :]`` = position ``(x, y, z)`` of the named point ``POINTS[k]``
    (joint anchors, centres of mass) for a generic drawing; ``LINKS`` holds
    the index pairs joined by a link. Both are empty when the derivation
    records no points.

For a mechanical model, the same physics with scalar arguments, which a
controller's source may copy and call (a controller's locals are scalars:
:mod:`equilibrist.native.pyc`), its parameters read from ``p[o + k]`` (the
model's vector at offset ``o`` of the controller's own):

``scalar_qdd(i, x0, ..., u0, ..., p, o)``
    ``q_ddot[i]`` (``f``'s row ``N_Q + i``).
``scalar_mass(i, j, x0, ..., p, o)``
    ``M[i, j]``.
``scalar_energy(x0, ..., p, o)``
    ``energy``.
"""

from __future__ import annotations

import sympy as sp
from sympy.printing.pycode import PythonCodePrinter

from equilibrist.mechanics.model import SymbolicModel
from equilibrist.numeric import libm

#: Revision of the copied :mod:`equilibrist.numeric.libm` section: the cache of derived
#: models is keyed by this module's source, so a change there must bump it.
LIBM_REVISION = 2


# sympy ships no type information, so its printer is Any to mypy (a subclass of Any is an
# error under --strict).
class _Printer(PythonCodePrinter):  # type: ignore[misc]
    def __init__(self) -> None:
        super().__init__({"fully_qualified_modules": True, "standard": "python3"})
        #: Assignments the statement being printed needs first (a power's base), as lines.
        self.hoisted: list[str] = []
        self._bases = 0
        #: The sections of libm besides the body that the printed text calls.
        self.sections: set[str] = set()

    def _print_Pow(self, expr: sp.Pow, rational: bool = False) -> str:
        # An integer power is the product the C translation writes (libm.power_product),
        # not Python's ``**``, which calls the C library's pow (glibc's rounds x ** 2
        # differently from x * x at a few inputs in ten thousand). 1/x is sympy's.
        k = expr.exp
        if k.is_Integer and k != -1 and 0 < abs(int(k)) <= libm.PRODUCT_POWER_MAX:
            base = self._print(expr.base)
            if not expr.base.is_Atom:  # evaluated once, as the C's temporary is
                name = f"pw_{self._bases}"
                self._bases += 1
                self.hoisted.append(f"    {name} = {base}")
                base = name
            return libm.power_product(base, int(k), lambda v: f"({v} * {v})")
        text: str = super()._print_Pow(expr, rational=rational)
        return text

    def statement(self, target: object, expr: sp.Expr) -> list[str]:
        """``target = expr`` as lines: the hoisted bases its powers need, then itself."""
        self.hoisted = []
        text = self.doprint(expr)
        return [*self.hoisted, f"    {target} = {text}"]

    def _print_sin(self, expr: sp.Expr) -> str:
        return f"eq_sin({self._print(expr.args[0])})"

    def _print_cos(self, expr: sp.Expr) -> str:
        return f"eq_cos({self._print(expr.args[0])})"

    # atan and tanh (a smooth Coulomb friction's) are the project's too: glibc's round
    # differently on its FMA and SSE2 paths (tests/numeric/test_libm.py). Their sections
    # of libm are copied only into a module that calls them (see generate_source).
    def _print_atan(self, expr: sp.Expr) -> str:
        self.sections.add("atan")
        return f"eq_atan({self._print(expr.args[0])})"

    def _print_tanh(self, expr: sp.Expr) -> str:
        self.sections.add("tanh")
        return f"eq_tanh({self._print(expr.args[0])})"


def _safe_names(model: SymbolicModel) -> dict[sp.Symbol, sp.Symbol]:
    """Rename states, inputs and parameters so no name clashes with the code's."""
    subs: dict[sp.Symbol, sp.Symbol] = {}
    for prefix, symbols in (("s_", model.states), ("i_", model.inputs), ("p_", model.params)):
        for s in symbols:
            subs[s] = sp.Symbol(prefix + s.name, real=True)
    return subs


def _body(
    exprs: list[sp.Expr], targets: list[str], subs: dict[sp.Symbol, sp.Symbol], printer: _Printer
) -> list[str]:
    exprs = [sp.sympify(e).xreplace(subs) for e in exprs]
    replacements, reduced = sp.cse(exprs, symbols=sp.numbered_symbols("t_"), order="none")
    lines: list[str] = []
    for sym, val in replacements:
        lines += printer.statement(sym, val)
    for tgt, val in zip(targets, reduced, strict=True):
        lines += printer.statement(tgt, val)
    return lines


def _unpack(model: SymbolicModel, *, with_inputs: bool, used: set[sp.Symbol]) -> list[str]:
    lines = []
    for k, s in enumerate(model.states):
        if s in used:
            lines.append(f"    s_{s.name} = x[{k}]")
    if with_inputs:
        for k, s in enumerate(model.inputs):
            if s in used:
                lines.append(f"    i_{s.name} = u[{k}]")
    for k, s in enumerate(model.params):
        if s in used:
            lines.append(f"    p_{s.name} = p[{k}]")
    return lines


def _free(exprs: list[sp.Expr]) -> set[sp.Symbol]:
    out: set[sp.Symbol] = set()
    for e in exprs:
        out |= sp.sympify(e).free_symbols
    return out


def generate_source(model: SymbolicModel) -> str:
    """The Python source of the numeric functions of *model*."""
    printer = _Printer()
    subs = _safe_names(model)
    n, m = len(model.states), len(model.inputs)
    out = [
        f'"""Generated by equilibrist from the derived model of {model.spec_key}. Do not edit."""',
        "import math",
        "",
        f"N_STATES = {n}",
        f"N_INPUTS = {m}",
        f"N_Q = {model.n_q}",
        f"CONSERVED = {tuple(model.conserved)!r}",
        f"POINTS = {tuple(model.points)!r}",
        f"LINKS = {_link_indices(model)!r}",
        "",
        f"# sin, cos, log of equilibrist.numeric.libm (revision {LIBM_REVISION}): the same bits on",
        "# every CPU, unlike the C library's.",
        libm.source(),
        "",
        "def f(x, u, p, out):",
    ]
    fx = list(model.f)
    out += _unpack(model, with_inputs=True, used=_free(fx))
    out += _body(fx, [f"out[{i}]" for i in range(n)], subs, printer)
    out += ["", "", "def jac(x, u, p, A, B):"]
    out += ["    A[:, :] = 0.0", "    B[:, :] = 0.0"]
    if model.jacobian_form == "mass" and model.M is not None and 0 < model.n_q <= 3:
        out += _jac_from_mass(model, subs, printer)
    else:
        entries: list[sp.Expr] = []
        targets: list[str] = []
        for (i, j), val in _nonzero(model.A):
            entries.append(val)
            targets.append(f"A[{i}, {j}]")
        for (i, j), val in _nonzero(model.B):
            entries.append(val)
            targets.append(f"B[{i}, {j}]")
        out += _unpack(model, with_inputs=True, used=_free(entries))
        out += _body(entries, targets, subs, printer)
    out += ["", "", "def mass_matrix(x, p, out):"]
    nq = model.n_q
    mass = [] if model.M is None else [model.M[i, j] for i in range(nq) for j in range(nq)]
    out += _unpack(model, with_inputs=False, used=_free(mass))
    out += _body(mass, [f"out[{i}, {j}]" for i in range(nq) for j in range(nq)], subs, printer)
    out += ["    return None", "", "", "def energy(x, p):"]
    energy = sp.nan if model.energy is None else model.energy
    out += _unpack(model, with_inputs=False, used=_free([energy]))
    out += _body([energy], ["result"], subs, printer)
    out += ["    return result", "", "", "def conserved(x, p, out):"]
    cons = list(model.conserved.values())
    out += _unpack(model, with_inputs=False, used=_free(cons))
    out += _body(cons, [f"out[{i}]" for i in range(len(cons))], subs, printer)
    out += ["    return None", "", "", "def points(x, p, out):"]
    coords = [v for m in model.points.values() for v in m]
    out += _unpack(model, with_inputs=False, used=_free(coords))
    targets = [f"out[{k}, {j}]" for k in range(len(model.points)) for j in range(3)]
    out += _body(coords, targets, subs, printer)
    out += ["    return None", ""]
    if model.M is not None:
        out += _scalar_functions(model, subs, printer)
    libm_at = out.index("def f(x, u, p, out):") - 1
    for section in (s for s in libm.SECTIONS[1:] if s in printer.sections):
        out[libm_at:libm_at] = [f"# {section} of equilibrist.numeric.libm.", libm.source(section), ""]
        libm_at += 3
    return "\n".join(out)


def _jac_from_mass(model: SymbolicModel, subs: dict[sp.Symbol, sp.Symbol],
                   printer: _Printer) -> list[str]:
    """``jac``'s body from ``M`` and ``F``: ``q_ddot`` first (as ``f`` forms it), then
    ``det M``, the adjugate and the derivatives of ``M`` and ``F`` as values, and each column
    ``M^-1 (dF/dx_j - dM/dx_j q_ddot)`` (``dF/du_k`` for ``B``) written out as arithmetic on
    them: derivatives of ``M`` and ``F``, not of the quotient ``f``, and no symbolic product,
    which for an imported tree cost seconds to form."""
    assert model.M is not None and model.F is not None
    nq = model.n_q
    M, F = model.M, model.F
    qdd = [model.f[nq + i] for i in range(nq)]
    values: list[sp.Expr] = [sp.factor_terms(M.det(method="berkowitz"))]
    names = ["jd"]
    adj = M.adjugate(method="berkowitz")
    for i in range(nq):
        for k in range(nq):
            values.append(adj[i, k])
            names.append(f"ja_{i}_{k}")
    columns: list[tuple[str, list[str]]] = []  # (target format, the rhs of each row)
    for j, s in enumerate(model.states):
        # Element by element: sympy's Matrix.diff takes some 40 times as long here.
        dF, dM = F.applyfunc(lambda e, s=s: e.diff(s)), M.applyfunc(lambda e, s=s: e.diff(s))
        rhs = []
        for r in range(nq):
            terms = []
            if dF[r] != 0:
                values.append(dF[r])
                names.append(f"jf_{r}_{j}")
                terms.append(f"jf_{r}_{j}")
            for c in range(nq):
                if dM[r, c] != 0:
                    values.append(dM[r, c])
                    names.append(f"jm_{r}_{c}_{j}")
                    terms.append(f"- jm_{r}_{c}_{j} * jq_{c}")
            rhs.append(" ".join(terms) if terms else "0.0")
        columns.append((f"A[{{}}, {j}]", rhs))
    for k, s in enumerate(model.inputs):
        dF = F.applyfunc(lambda e, s=s: e.diff(s))
        rhs = []
        for r in range(nq):
            if dF[r] != 0:
                values.append(dF[r])
                names.append(f"jb_{r}_{k}")
                rhs.append(f"jb_{r}_{k}")
            else:
                rhs.append("0.0")
        columns.append((f"B[{{}}, {k}]", rhs))
    lines = _unpack(model, with_inputs=True, used=_free(qdd + values))
    lines += _body(qdd, [f"jq_{i}" for i in range(nq)], subs, printer)
    lines += _body(values, names, subs, printer)
    lines += [f"    A[{i}, {nq + i}] = 1.0" for i in range(nq)]
    for target, rhs in columns:
        if all(r == "0.0" for r in rhs):
            continue
        lines += [f"    jr_{r} = {text}" for r, text in enumerate(rhs)]
        for i in range(nq):
            total = " + ".join(f"ja_{i}_{k} * jr_{k}" for k in range(nq))
            lines.append(f"    {target.format(nq + i)} = ({total}) / jd")
    return lines


def _scalar_functions(model: SymbolicModel, subs: dict[sp.Symbol, sp.Symbol],
                      printer: _Printer) -> list[str]:
    """``scalar_qdd``, ``scalar_mass`` and ``scalar_energy`` (see the module's docstring)."""
    assert model.M is not None
    nq, n = model.n_q, len(model.states)
    xs = [f"x{k}" for k in range(n)]
    us = [f"u{k}" for k in range(len(model.inputs))]
    qdd = [model.f[nq + i] for i in range(nq)]
    mass = [model.M[i, j] for i in range(nq) for j in range(nq)]
    energy = sp.nan if model.energy is None else model.energy
    out: list[str] = []
    for name, args, exprs, tests in (
        ("scalar_qdd", ["i", *xs, *us], qdd, [f"i == {i}" for i in range(nq)]),
        ("scalar_mass", ["i", "j", *xs], mass,
         [f"i == {i} and j == {j}" for i in range(nq) for j in range(nq)]),
        ("scalar_energy", xs, [energy], ["True"]),
    ):
        out += ["", f"def {name}({', '.join([*args, 'p', 'o'])}):"]
        used = _free(exprs)
        out += [f"    s_{s.name} = x{k}" for k, s in enumerate(model.states) if s in used]
        out += [f"    i_{s.name} = u{k}" for k, s in enumerate(model.inputs) if s in used]
        out += [f"    p_{s.name} = p[o + {k}]" for k, s in enumerate(model.params) if s in used]
        values = [f"r{k}" for k in range(len(exprs))]
        out += _body(exprs, values, subs, printer)
        for test, value in zip(tests[:-1], values[:-1], strict=True):
            out += [f"    if {test}:", f"        return {value}"]
        out += [f"    return {values[-1]}"]
    out.append("")
    return out


def _link_indices(model: SymbolicModel) -> tuple[tuple[int, int], ...]:
    names = list(model.points)
    return tuple((names.index(a), names.index(b)) for a, b in model.links)


def _nonzero(mat: sp.Matrix) -> list[tuple[tuple[int, int], sp.Expr]]:
    rows, cols = mat.shape
    return [((i, j), mat[i, j]) for i in range(rows) for j in range(cols) if mat[i, j] != 0]
