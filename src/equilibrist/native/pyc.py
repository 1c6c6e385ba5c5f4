"""Python to C: the numeric subset the compiled core runs, translated operation for operation.

The generated dynamics (:mod:`equilibrist.numeric.codegen`) and the
controllers' sources are plain Python over floats, integers and 1-D or 2-D
arrays: the one definition that runs in Python as the reference. This module
turns such a function into a C99 function that performs the same IEEE
operations in the same order, with fixed typing rules (docs/core.md lists them
and the subset; a run in the C core gives the same bits on every machine).
What it does not know it refuses with :class:`TranslationError`, naming
the construct and its line, instead of guessing.

Arrays are pointers; a 2-D array ``a`` has its row length in a companion
argument ``a_n1`` (and every array its length ``a_n0``), so ``a[i, j]`` is
``a[i * a_n1 + j]`` and ``a.shape[k]`` is ``a_nk``.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from equilibrist.errors import EquilibristError


class TranslationError(EquilibristError, ValueError):
    """A source uses a construct the C translation does not support."""


#: Types: scalars ``"f"`` (double), ``"i"`` (int64), and arrays ``"F1"``, ``"F2"``
#: (double, 1-D or 2-D), ``"I1"``, ``"I2"`` (int64).
SCALARS = ("f", "i")
ARRAYS = ("F1", "F2", "I1", "I2")

# math (or numpy) functions of one or two floats that are the C library's function of the
# same name.
_MATH = {
    "sqrt": "sqrt", "exp": "exp", "log": "log", "sin": "sin", "cos": "cos", "tan": "tan",
    "asin": "asin", "acos": "acos", "atan": "atan", "atan2": "atan2", "sinh": "sinh",
    "cosh": "cosh", "tanh": "tanh", "floor": "floor", "ceil": "ceil", "fabs": "fabs",
    "hypot": "hypot", "copysign": "copysign", "expm1": "expm1", "log1p": "log1p",
    "log10": "log10", "fmod": "fmod", "pow": "pow", "arctan2": "atan2", "arcsin": "asin",
    "arccos": "acos", "arctan": "atan", "trunc": "trunc",
}
_MATH_BOOL = {"isfinite": "isfinite", "isnan": "isnan", "isinf": "isinf"}
_MATH_CONST = {"pi": "3.141592653589793", "e": "2.718281828459045", "inf": "INFINITY",
               "nan": "NAN", "tau": "6.283185307179586"}
_LIBM = ("eq_sin", "eq_cos", "eq_log", "eq_exp", "eq_atan", "eq_tanh")

#: C helpers the translated functions call (written once into every unit by :func:`prelude`).
PRELUDE = r"""
static inline double eq_maxf(double a, double b) { return b > a ? b : a; }
static inline double eq_minf(double a, double b) { return b < a ? b : a; }
static inline int64_t eq_maxi(int64_t a, int64_t b) { return b > a ? b : a; }
static inline int64_t eq_mini(int64_t a, int64_t b) { return b < a ? b : a; }
static inline int64_t eq_floordivi(int64_t a, int64_t b)
{
    int64_t q = a / b;
    if ((a % b != 0) && ((a < 0) != (b < 0))) q -= 1;
    return q;
}
static inline int64_t eq_modi(int64_t a, int64_t b)
{
    int64_t r = a % b;
    if (r != 0 && ((r < 0) != (b < 0))) r += b;
    return r;
}
static inline double eq_modf(double a, double b)
{
    double r = fmod(a, b);
    if (r != 0.0) {
        if ((b < 0.0) != (r < 0.0)) r += b;
    } else {
        r = copysign(0.0, b);
    }
    return r;
}
static inline double eq_floordivf(double a, double b)
{
    double mod = fmod(a, b);
    double div = (a - mod) / b;
    double fl;
    if (mod != 0.0) {
        if ((b < 0.0) != (mod < 0.0)) div -= 1.0;
    }
    if (div != 0.0) {
        fl = floor(div);
        if (div - fl > 0.5) fl += 1.0;
    } else {
        fl = copysign(0.0, a / b);
    }
    return fl;
}
"""


def c_float(value: float) -> str:
    """A C literal of the double *value* (exact: ``repr`` round-trips)."""
    if math.isnan(value):
        return "NAN"
    if math.isinf(value):
        return "INFINITY" if value > 0 else "(-INFINITY)"
    text = repr(float(value))
    if "e" not in text and "." not in text:
        text += ".0"
    return f"({text})" if text.startswith("-") else text


def c_int(value: int) -> str:
    if not -(2**63) <= value < 2**63:
        raise TranslationError(f"integer {value} does not fit 64 bits")
    if value == -(2**63):
        return "INT64_MIN"
    return f"INT64_C({value})" if value >= 0 else f"(-INT64_C({-value}))"


@dataclass
class Function:
    """One translated function: its C name, argument types and C source."""

    name: str
    args: tuple[tuple[str, str], ...]
    returns: str | None
    source: str


@dataclass
class Module:
    """A Python source whose functions are translated on demand, monomorphized by types.

    *constants* are module-level names with literal values (``N_STATES``,
    the layout's slots...). *aliases* map a Python name to another (the
    kernel's ``controller_output = linear_output``...).
    """

    source: str
    constants: Mapping[str, int | float] = field(default_factory=dict)
    prefix: str = "py_"
    #: Source of functions in scope beside the source's own (its line numbers are its own).
    library: str = ""
    defs: dict[str, ast.FunctionDef] = field(default_factory=dict)
    done: dict[tuple[str, tuple[str, ...]], Function] = field(default_factory=dict)
    order: list[Function] = field(default_factory=list)
    busy: set[tuple[str, tuple[str, ...]]] = field(default_factory=set)

    def __post_init__(self) -> None:
        try:
            tree = ast.parse(self.source)
            lib = ast.parse(self.library)
        except SyntaxError as exc:
            raise TranslationError(f"line {exc.lineno}: {exc.msg}") from None
        consts = dict(self.constants)
        for node in [*lib.body, *tree.body]:
            if isinstance(node, ast.FunctionDef):
                self.defs[node.name] = node
            elif (isinstance(node, ast.Assign) and len(node.targets) == 1
                  and isinstance(node.targets[0], ast.Name)):
                value = _literal(node.value, consts)
                if value is not None:
                    consts[node.targets[0].id] = value
        self.constants = consts

    def function(self, name: str, types: tuple[str, ...]) -> Function:
        """The C translation of function *name* for arguments of *types*."""
        key = (name, types)
        known = self.done.get(key)
        if known is not None:
            return known
        fdef = self.defs.get(name)
        if fdef is None:
            raise TranslationError(f"no function {name!r} in the source")
        if key in self.busy:
            raise TranslationError(f"{name} calls itself: recursion is not supported")
        cname = self.prefix + name + ("" if not self._overloaded(name, types)
                                      else "_" + "".join(t.lower() for t in types))
        self.busy.add(key)
        try:
            from equilibrist.native.translate import Translator

            fn = Translator(self, fdef, types, cname).run()
        finally:
            self.busy.discard(key)
        self.done[key] = fn
        self.order.append(fn)
        return fn

    def _overloaded(self, name: str, types: tuple[str, ...]) -> bool:
        return any(n == name and t != types for n, t in self.done)

    def c_source(self) -> str:
        """Every translated function, callees first (``static``)."""
        return "\n".join(fn.source for fn in self.order)


def _literal(node: ast.expr, consts: Mapping[str, int | float]) -> int | float | None:
    """The value of a module-level numeric literal (a constant, a negated one, a name of one)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) \
            and not isinstance(node.value, bool):
        return node.value
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        inner = _literal(node.operand, consts)
        return None if inner is None else -inner
    if isinstance(node, ast.Name) and node.id in consts:
        return consts[node.id]
    return None


def _unify(a: str, b: str) -> str:
    return "i" if a == b == "i" else "f"


__all__ = ["ARRAYS", "PRELUDE", "SCALARS", "Function", "Module", "TranslationError", "c_float",
           "c_int"]
