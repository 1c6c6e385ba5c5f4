"""Readable equations of motion: pretty text and LaTeX with the seeds' symbols.

State symbols are plain names (``theta_dot``) so that generated code and
JSON stay ASCII; for printing they are swapped for display symbols that
sympy renders with accents (``θ̇``, ``θ̈``, ``θ̇₁``).
"""

from __future__ import annotations

import re

import sympy as sp

from equilibrist.mechanics.model import SymbolicModel
from equilibrist.mechanics.spec import SystemSpec


# sympy ships no type information, so Symbol is Any to mypy and subclassing it is an error
# under --strict.
class _Literal(sp.Symbol):  # type: ignore[misc]
    """A symbol printed as its name, underscores and digits as written.

    sympy reads ``_`` in a name as a subscript and ``__`` as a superscript,
    so ``cart_to_pole`` would print as nested subscripts; names that are
    words (a model file's joints and bodies) print literally, with the
    accent of a rate over the name.
    """

    accent: str

    def __new__(cls, name: str, accent: str = "") -> _Literal:
        obj: _Literal = super().__new__(cls, f"{name}\u2063{accent}")
        obj.accent = accent
        obj.shown = name
        return obj

    def _pretty(self, printer: object) -> object:
        from sympy.printing.pretty.stringpict import prettyForm

        mark = {"": "", "dot": "\u0307", "ddot": "\u0308"}[self.accent]
        return prettyForm(self.shown + mark)

    def _latex(self, printer: object) -> str:
        text = "\\mathrm{" + self.shown.replace("_", "\\_") + "}"
        return f"\\{self.accent}{{{text}}}" if self.accent else text


# A name prints as a symbol with a subscript (``m_p``, ``I_body``,
# ``theta1``, ``phi``) when it is a short symbol: a stem of one or two
# letters or a Greek letter's name, then digits or one subscript; anything
# else is a word (``elbow``, ``cart_to_pole``) and prints literally.
_SYMBOL_LIKE = re.compile(r"^([A-Za-z]{1,2}|(?P<greek>[A-Za-z]+))(\d*|_[A-Za-z0-9]+)$")


def literal(name: str) -> bool:
    """Whether *name* prints as written rather than as a symbol with subscripts."""
    from sympy.printing.pretty.pretty_symbology import greek_unicode

    found = _SYMBOL_LIKE.match(name)
    if not found:
        return True
    greek = found.group("greek")
    return greek is not None and greek not in greek_unicode


def _display(name: str, accent: str) -> sp.Symbol:
    if literal(name):
        return _Literal(name, accent)
    base, digits = re.match(r"^(.*?)(\d*)$", name).groups()  # type: ignore[union-attr]
    # theta_1 as theta1: the digits are the subscript (a "_" left on the
    # stem would make sympy read "__1" as a superscript).
    return sp.Symbol(base.rstrip("_") + accent + (f"_{digits}" if digits else ""))


def display_symbols(model: SymbolicModel, spec: SystemSpec) -> dict[sp.Symbol, sp.Symbol]:
    """Substitution of state, rate and acceleration symbols by display symbols."""
    subs: dict[sp.Symbol, sp.Symbol] = {}
    for c in spec.coordinates:
        subs[sp.Symbol(c, real=True)] = _display(c, "")
        subs[sp.Symbol(f"{c}_dot", real=True)] = _display(c, "dot")
        subs[sp.Symbol(f"{c}_ddot", real=True)] = _display(c, "ddot")
        subs[sp.Symbol(f"{c}_ddot")] = _display(c, "ddot")
        # Left-hand sides of a first-order model: the rate of each state.
        subs[sp.Symbol(f"{c}__rate")] = _display(c, "dot")
        subs[sp.Symbol(f"{c}_dot__rate")] = _display(c, "ddot")
    for state in model.states:  # states that are not coordinates or their rates
        if state not in subs:
            subs[state] = _display(state.name, "")
            subs[sp.Symbol(f"{state.name}__rate")] = _display(state.name, "dot")
    for s in (*model.params, *model.inputs):
        if literal(s.name) and s.name not in spec.symbols_latex:
            subs[s] = _Literal(s.name)
    return subs


def _latex_overrides(model: SymbolicModel, spec: SystemSpec) -> dict[sp.Symbol, str]:
    return {s: spec.symbols_latex[s.name] for s in (*model.params, *model.inputs)
            if s.name in spec.symbols_latex}


def _rows(model: SymbolicModel) -> list[tuple[sp.Expr, sp.Expr]]:
    """``(lhs, rhs)`` per equation: ``sum_j M_ij q_ddot_j = F_i`` or ``x_dot_i = f_i``."""
    if model.M is not None and model.F is not None:
        qdd = model.q_ddot_symbols()
        return [
            (sum((model.M[i, j] * qdd[j] for j in range(model.n_q)), sp.Integer(0)), model.F[i])
            for i in range(model.n_q)
        ]
    return [(sp.Symbol(f"{s.name}__rate"), model.f[i]) for i, s in enumerate(model.states)]


def equations_text(model: SymbolicModel, spec: SystemSpec) -> str:
    """The equations of motion as pretty (unicode) text."""
    subs = display_symbols(model, spec)
    header = "M(q) q_ddot = F(q, q_dot, u):" if model.M is not None else "x_dot = f(x, u):"
    lines = [header, ""]
    for lhs, rhs in _rows(model):
        eq = sp.Eq(lhs.xreplace(subs), rhs.xreplace(subs), evaluate=False)
        lines.append(sp.pretty(eq, use_unicode=True, wrap_line=False))
        lines.append("")
    return "\n".join(lines).rstrip()


def equations_latex(model: SymbolicModel, spec: SystemSpec) -> str:
    """The equations of motion as a LaTeX ``aligned`` block."""
    subs = display_symbols(model, spec)
    names = _latex_overrides(model, spec)
    rows = [
        f"{sp.latex(lhs.xreplace(subs), symbol_names=names)} &= "
        f"{sp.latex(rhs.xreplace(subs), symbol_names=names)}"
        for lhs, rhs in _rows(model)
    ]
    return "\\begin{aligned}\n" + " \\\\\n".join(rows) + "\n\\end{aligned}"


def matrix_latex(model: SymbolicModel, spec: SystemSpec, which: str) -> str:
    """LaTeX of ``M``, ``F``, ``f``, ``A`` or ``B``."""
    mat = {"M": model.M, "F": model.F, "f": model.f, "A": model.A, "B": model.B}[which]
    if mat is None:
        raise ValueError(f"model of {spec.key} has no {which}")
    text: str = sp.latex(mat.xreplace(display_symbols(model, spec)),
                         symbol_names=_latex_overrides(model, spec))
    return text
