"""Python to C: the numeric subset the compiled core runs, translated operation for operation.

The generated dynamics (:mod:`equilibrist.numeric.codegen`) and the
controllers' sources (the linear library of
:mod:`equilibrist.control.controller`, a nonlinear controller's
``output``/``update``/``estimate``) are plain Python over floats, integers
and 1-D or 2-D arrays: the one definition that runs in Python as the
reference. This module turns such a function into a C99 function that
performs the same IEEE operations in the same order, with the typing rules
numba applied to the same source before (so a run in the C core gives the
bits the numba core gave):

- integers are ``int64_t``, floats ``double``; ``/`` is a float division,
  ``//`` and ``%`` follow Python's signs (for floats, CPython's and numba's
  ``fmod``-based rule); ``x ** k`` with an integer literal ``k`` is
  computed by repeated squaring exactly as numba unrolls it, any other
  power with ``pow``;
- ``min`` and ``max`` keep Python's rule for ties and NaN (``max(a, b)`` is
  ``b if b > a else a``); ``int(x)`` truncates; ``abs`` of a float is
  ``fabs``;
- ``math``'s functions are the C library's of the same name, the project's
  ``eq_sin``/``eq_cos``/``eq_log`` are :mod:`equilibrist.numeric.libm`'s C
  versions;
- every intermediate is a C ``double`` expression fully parenthesized in
  Python's evaluation order, compiled with ``-ffp-contract=off`` and
  without ``-ffast-math`` (no fused multiply-add, no reassociation).

What it does not know it refuses with :class:`TranslationError`, naming
the construct and its line, instead of guessing.

Arrays are pointers; a 2-D array ``a`` has its row length in a companion
argument ``a_n1`` (and every array its length ``a_n0``), so ``a[i, j]`` is
``a[i * a_n1 + j]`` and ``a.shape[k]`` is ``a_nk``.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from equilibrist.errors import EquilibristError


class TranslationError(EquilibristError, ValueError):
    """A source uses a construct the C translation does not support."""


#: Types: scalars ``"f"`` (double), ``"i"`` (int64), and arrays ``"F1"``, ``"F2"``
#: (double, 1-D or 2-D), ``"I1"``, ``"I2"`` (int64).
SCALARS = ("f", "i")
ARRAYS = ("F1", "F2", "I1", "I2")

# math (or numpy) functions of one or two floats that are the C library's function of the
# same name: the call numba makes for them too.
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
_LIBM = ("eq_sin", "eq_cos", "eq_log")

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
            fn = _Translator(self, fdef, types, cname).run()
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


class _Translator:
    def __init__(self, module: Module, fdef: ast.FunctionDef, types: tuple[str, ...],
                 cname: str) -> None:
        self.m = module
        self.fdef = fdef
        self.cname = cname
        params = [a.arg for a in fdef.args.args]
        if fdef.args.vararg or fdef.args.kwarg or fdef.args.kwonlyargs or fdef.args.defaults:
            self.fail(fdef, "only plain positional arguments are supported")
        if len(params) != len(types):
            self.fail(fdef, f"{fdef.name} takes {len(params)} arguments, called with {len(types)}")
        self.params = dict(zip(params, types, strict=True))
        self.locals: dict[str, str] = {}
        self.returns: str | None = None
        self.tmp = 0
        self.loop_depth = 0
        self.pre: list[str] = []

    # -- errors ------------------------------------------------------------------------------
    def fail(self, node: ast.AST, what: str) -> None:
        line = getattr(node, "lineno", None)
        where = f"{self.fdef.name}, line {line}" if line else self.fdef.name
        raise TranslationError(f"{where}: {what}")

    # -- names -------------------------------------------------------------------------------
    @staticmethod
    def var(name: str) -> str:
        return "v_" + name

    def type_of_name(self, node: ast.Name) -> str:
        name = node.id
        if name in self.params:
            return self.params[name]
        if name in self.locals:
            return self.locals[name]
        if name in self.m.constants:
            return "i" if isinstance(self.m.constants[name], int) else "f"
        self.fail(node, f"name {name!r} is not defined before it is used")
        raise AssertionError

    # -- typing pass: find every local's type (int unless a float is ever stored) ---------------
    def infer(self) -> None:
        for _ in range(8):
            before = dict(self.locals)
            for stmt in ast.walk(self.fdef):
                if isinstance(stmt, ast.Assign):
                    for target in stmt.targets:
                        self.bind(target, stmt.value)
                elif isinstance(stmt, ast.AugAssign) and isinstance(stmt.target, ast.Name):
                    name = stmt.target.id
                    if name in self.params:
                        continue
                    t = self.safe_type(stmt.value)
                    old = self.locals.get(name)
                    if t is not None and old is not None:
                        new = _unify(old, t)
                        if isinstance(stmt.op, ast.Div):
                            new = "f"
                        self.locals[name] = new
                elif isinstance(stmt, ast.For) and isinstance(stmt.target, ast.Name):
                    self.locals.setdefault(stmt.target.id, "i")
            if self.locals == before:
                return

    def bind(self, target: ast.expr, value: ast.expr) -> None:
        if isinstance(target, ast.Name):
            if target.id in self.params:
                self.fail(target, f"argument {target.id!r} is assigned to (use another name)")
            t = self.safe_type(value)
            if t is None:
                return
            if t not in SCALARS:
                self.fail(target, f"{target.id!r} would be an array: only scalars may be locals")
            old = self.locals.get(target.id)
            self.locals[target.id] = t if old is None else _unify(old, t)
        elif isinstance(target, ast.Tuple):
            types = self.tuple_types(value)
            if types is None:
                return
            if len(types) != len(target.elts):
                self.fail(target, "unpacking a tuple of another length")
            for el, t in zip(target.elts, types, strict=True):
                if not isinstance(el, ast.Name):
                    self.fail(el, "only names may be unpacked into")
                assert isinstance(el, ast.Name)
                if el.id in self.params:
                    self.fail(el, f"argument {el.id!r} is assigned to (use another name)")
                old = self.locals.get(el.id)
                self.locals[el.id] = t if old is None else _unify(old, t)

    def tuple_types(self, value: ast.expr) -> list[str] | None:
        """The element types of a tuple literal or of a call of a function returning one."""
        if isinstance(value, ast.Tuple):
            out = []
            for el in value.elts:
                t = self.safe_type(el)
                if t is None:
                    return None
                out.append(t)
            return out
        if isinstance(value, ast.Call) and isinstance(value.func, ast.Name) \
                and value.func.id in self.m.defs:
            try:
                fn = self.callee(value)[0]
            except TranslationError:
                return None
            if fn.returns is None or not fn.returns.startswith("tuple:"):
                self.fail(value, f"{value.func.id} returns no tuple")
            assert fn.returns is not None
            return fn.returns[6:].split(",")
        self.fail(value, "a tuple is unpacked from something that is not one")
        raise AssertionError

    def callee(self, node: ast.Call) -> tuple[Function, list[str]]:
        """The translated function a call of a function of the source reaches, and the C
        arguments (an array passes its pointer and lengths; a slice ``a[lo:hi]`` of a 1-D
        array passes a pointer into it)."""
        assert isinstance(node.func, ast.Name)
        types: list[str] = []
        codes: list[str] = []
        for a in node.args:
            if isinstance(a, ast.Subscript) and isinstance(a.slice, ast.Slice):
                ptr, length, t = self.slice_arg(a)
                types.append(t)
                codes += [ptr, length]
                continue
            code, t = self.expr(a)
            types.append(t)
            codes.append(code)
            if t in ARRAYS:
                codes += [f"{code}_n{k}" for k in range(int(t[1]))]
        fn = self.m.function(node.func.id, tuple(types))
        return fn, codes

    def slice_arg(self, node: ast.Subscript) -> tuple[str, str, str]:
        if not isinstance(node.value, ast.Name) or self.params.get(node.value.id) not in ("F1", "I1"):
            self.fail(node, "only a 1-D array argument may be sliced")
        assert isinstance(node.value, ast.Name) and isinstance(node.slice, ast.Slice)
        arr = self.var(node.value.id)
        sl = node.slice
        if sl.step is not None:
            self.fail(node, "a slice with a step is not supported")
        lo = "INT64_C(0)"
        if sl.lower is not None:
            lo, tl = self.scalar(sl.lower)
            if tl != "i" or (isinstance(_literal(sl.lower, {}), int) and _literal(sl.lower, {}) < 0):  # type: ignore[operator]
                self.fail(node, "a slice's start must be a non-negative integer")
        hi = f"{arr}_n0"
        if sl.upper is not None:
            hi, th = self.scalar(sl.upper)
            if th != "i" or (isinstance(_literal(sl.upper, {}), int) and _literal(sl.upper, {}) < 0):  # type: ignore[operator]
                self.fail(node, "a slice's end must be a non-negative integer")
            hi = f"eq_mini({hi}, {arr}_n0)"
        length = f"eq_maxi(INT64_C(0), {hi} - eq_mini({lo}, {arr}_n0))"
        return f"({arr} + eq_mini({lo}, {arr}_n0))", length, self.params[node.value.id]

    def safe_type(self, node: ast.expr) -> str | None:
        try:
            return self.expr(node)[1]
        except TranslationError:
            return None

    # -- expressions -------------------------------------------------------------------------
    def expr(self, node: ast.expr) -> tuple[str, str]:
        method: Callable[[ast.expr], tuple[str, str]] | None = getattr(
            self, "e_" + type(node).__name__, None)
        if method is None:
            self.fail(node, f"{type(node).__name__} expressions are not supported")
            raise AssertionError
        return method(node)

    def scalar(self, node: ast.expr) -> tuple[str, str]:
        code, t = self.expr(node)
        if t not in SCALARS:
            what = "nothing (a function without a value)" if t == "void" else "an array"
            self.fail(node, f"{what} where a number is expected")
        return code, t

    def as_float(self, node: ast.expr) -> str:
        code, t = self.scalar(node)
        return code if t == "f" else f"((double){code})"

    def e_Constant(self, node: ast.Constant) -> tuple[str, str]:
        v = node.value
        if isinstance(v, bool):
            return ("1" if v else "0"), "i"
        if isinstance(v, int):
            return c_int(v), "i"
        if isinstance(v, float):
            return c_float(v), "f"
        self.fail(node, f"constant {v!r} is not a number")
        raise AssertionError

    def e_Name(self, node: ast.Name) -> tuple[str, str]:
        t = self.type_of_name(node)
        if node.id in self.params or node.id in self.locals:
            return self.var(node.id), t
        value = self.m.constants[node.id]
        return (c_int(value) if isinstance(value, int) else c_float(value)), t

    def e_UnaryOp(self, node: ast.UnaryOp) -> tuple[str, str]:
        code, t = self.scalar(node.operand)
        if isinstance(node.op, ast.USub):
            return f"(-{code})", t
        if isinstance(node.op, ast.UAdd):
            return code, t
        if isinstance(node.op, ast.Not):
            return f"(!{code})", "i"
        if isinstance(node.op, ast.Invert) and t == "i":
            return f"(~{code})", "i"
        self.fail(node, "unsupported unary operator")
        raise AssertionError

    def e_BinOp(self, node: ast.BinOp) -> tuple[str, str]:
        op = node.op
        if isinstance(op, ast.Pow):
            return self.power(node)
        a, ta = self.scalar(node.left)
        b, tb = self.scalar(node.right)
        t = _unify(ta, tb)
        if isinstance(op, (ast.Add, ast.Sub, ast.Mult)):
            sym = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*"}[type(op)]
            if t == "f":
                a = a if ta == "f" else f"((double){a})"
                b = b if tb == "f" else f"((double){b})"
            return f"({a} {sym} {b})", t
        # The operands as floats, from the codes above: translating them again would write
        # the statements they need (a power's temporaries) twice, the first copy unused.
        fa = a if ta == "f" else f"((double){a})"
        fb = b if tb == "f" else f"((double){b})"
        if isinstance(op, ast.Div):
            return f"({fa} / {fb})", "f"
        if isinstance(op, ast.FloorDiv):
            if t == "i":
                return f"eq_floordivi({a}, {b})", "i"
            return f"eq_floordivf({fa}, {fb})", "f"
        if isinstance(op, ast.Mod):
            if t == "i":
                return f"eq_modi({a}, {b})", "i"
            return f"eq_modf({fa}, {fb})", "f"
        bits = {ast.BitAnd: "&", ast.BitOr: "|", ast.BitXor: "^", ast.LShift: "<<",
                ast.RShift: ">>"}
        if type(op) in bits and t == "i":
            return f"({a} {bits[type(op)]} {b})", "i"
        self.fail(node, f"operator {type(op).__name__} is not supported on these types")
        raise AssertionError

    def power(self, node: ast.BinOp) -> tuple[str, str]:
        base, tb = self.scalar(node.left)
        exponent = _literal(node.right, {})
        if isinstance(node.right, ast.Name) and node.right.id in self.m.constants:
            exponent = self.m.constants[node.right.id]
        if isinstance(exponent, int) and abs(exponent) <= 64:
            # numba's static power: res = 1; while e: (if e & 1: res *= val); e >>= 1; val *= val
            if exponent == 0:
                return ("1.0", "f") if tb == "f" else ("INT64_C(1)", "i")
            name = self.fresh()
            self.pre.append(f"const {_ctype(tb)} {name}_b = {base};")
            res = None
            val = f"{name}_b"
            e = abs(exponent)
            k = 0
            while e:
                if e & 1:
                    res = val if res is None else f"({res} * {val})"
                e >>= 1
                if e:
                    nxt = f"{name}_{k}"
                    self.pre.append(f"const {_ctype(tb)} {nxt} = {val} * {val};")
                    val = nxt
                    k += 1
            assert res is not None
            if exponent < 0:
                if tb == "i":
                    self.fail(node, "an integer to a negative power")
                return f"(1.0 / {res})", "f"
            return res, tb
        return f"pow({base if tb == 'f' else f'((double){base})'}, {self.as_float(node.right)})", "f"

    def fresh(self) -> str:
        self.tmp += 1
        return f"_t{self.tmp}"

    def e_BoolOp(self, node: ast.BoolOp) -> tuple[str, str]:
        sym = " && " if isinstance(node.op, ast.And) else " || "
        parts = [self.scalar(v)[0] for v in node.values]
        return "(" + sym.join(parts) + ")", "i"

    def e_Compare(self, node: ast.Compare) -> tuple[str, str]:
        syms = {ast.Lt: "<", ast.LtE: "<=", ast.Gt: ">", ast.GtE: ">=", ast.Eq: "==",
                ast.NotEq: "!="}
        left_node = node.left
        parts = []
        for op, right_node in zip(node.ops, node.comparators, strict=True):
            if type(op) not in syms:
                self.fail(node, f"comparison {type(op).__name__} is not supported")
            a, ta = self.scalar(left_node)
            b, tb = self.scalar(right_node)
            if ta != tb:
                a = a if ta == "f" else f"((double){a})"
                b = b if tb == "f" else f"((double){b})"
            parts.append(f"({a} {syms[type(op)]} {b})")
            left_node = right_node
        return ("(" + " && ".join(parts) + ")" if len(parts) > 1 else parts[0]), "i"

    def e_IfExp(self, node: ast.IfExp) -> tuple[str, str]:
        c, _ = self.scalar(node.test)
        a, ta = self.scalar(node.body)
        b, tb = self.scalar(node.orelse)
        t = _unify(ta, tb)
        if t == "f":
            a = a if ta == "f" else f"((double){a})"
            b = b if tb == "f" else f"((double){b})"
        return f"({c} ? {a} : {b})", t

    def e_Attribute(self, node: ast.Attribute) -> tuple[str, str]:
        if isinstance(node.value, ast.Name) and node.value.id in ("math", "np", "numpy") \
                and node.attr in _MATH_CONST:
            return _MATH_CONST[node.attr], "f"
        self.fail(node, f"attribute .{node.attr} is not supported")
        raise AssertionError

    def e_Subscript(self, node: ast.Subscript) -> tuple[str, str]:
        # a.shape[k]
        if isinstance(node.value, ast.Attribute) and node.value.attr == "shape" \
                and isinstance(node.value.value, ast.Name):
            arr = node.value.value.id
            k = _literal(node.slice, {})
            t = self.params.get(arr)
            if t not in ARRAYS or not isinstance(k, int) or not 0 <= k < int(t[1]):
                self.fail(node, f"{arr}.shape[{k}] of something that is not such an array")
            return f"{self.var(arr)}_n{k}", "i"
        return self.element(node)

    def element(self, node: ast.Subscript) -> tuple[str, str]:
        if not isinstance(node.value, ast.Name) or self.params.get(node.value.id) not in ARRAYS:
            self.fail(node, "indexing something that is not an array argument")
        assert isinstance(node.value, ast.Name)
        arr = node.value.id
        t = self.params[arr]
        dims = int(t[1])
        idx = list(node.slice.elts) if isinstance(node.slice, ast.Tuple) else [node.slice]
        if any(isinstance(i, ast.Slice) for i in idx):
            self.fail(node, "slices are not supported (index one element at a time)")
        if len(idx) != dims:
            self.fail(node, f"{arr} has {dims} dimension(s), indexed with {len(idx)}")
        v = self.var(arr)
        codes = []
        for k, i in enumerate(idx):
            code, ti = self.scalar(i)
            if ti != "i":
                self.fail(node, "an array index that is not an integer")
            lit = _literal(i, {})
            if isinstance(lit, int) and lit < 0:
                code = f"({v}_n{k} - {-lit})"
            codes.append(code)
        flat = codes[0] if dims == 1 else f"{codes[0]} * {v}_n1 + {codes[1]}"
        return f"{v}[{flat}]", ("f" if t[0] == "F" else "i")

    def e_Call(self, node: ast.Call) -> tuple[str, str]:
        if node.keywords:
            self.fail(node, "keyword arguments are not supported")
        func = node.func
        args = node.args
        if isinstance(func, ast.Attribute) and isinstance(func.value, ast.Name) \
                and func.value.id in ("math", "np", "numpy"):
            name = func.attr
            if name in _MATH_BOOL and len(args) == 1:
                return f"({_MATH_BOOL[name]}({self.as_float(args[0])}) != 0)", "i"
            if name in ("abs", "absolute") and len(args) == 1:
                return self.builtin("abs", node)
            if name in _MATH:
                return f"{_MATH[name]}(" + ", ".join(self.as_float(a) for a in args) + ")", "f"
            self.fail(node, f"{func.value.id}.{name} is not supported")
        if not isinstance(func, ast.Name):
            self.fail(node, "only calls of names and math functions are supported")
        assert isinstance(func, ast.Name)
        name = func.id
        if name in _LIBM:
            return f"{name}(" + ", ".join(self.as_float(a) for a in args) + ")", "f"
        if name in ("abs", "min", "max", "int", "float", "bool", "round"):
            return self.builtin(name, node)
        if name in self.m.defs:
            fn, codes = self.callee(node)
            call = f"{fn.name}(" + ", ".join(codes) + ")"
            if fn.returns is None:
                return call, "void"
            if fn.returns.startswith("tuple:"):
                self.fail(node, f"{name} returns a tuple: unpack it into names")
            return call, fn.returns
        self.fail(node, f"function {name!r} is not known to the C translation")
        raise AssertionError

    def builtin(self, name: str, node: ast.Call) -> tuple[str, str]:
        args = node.args
        if name == "abs" and len(args) == 1:
            code, t = self.scalar(args[0])
            return (f"fabs({code})", "f") if t == "f" else (f"llabs({code})", "i")
        if name in ("min", "max") and len(args) >= 2:
            vals = [self.scalar(a) for a in args]
            t = "i" if all(v[1] == "i" for v in vals) else "f"
            fn = f"eq_{name}{t}"
            acc = vals[0][0] if vals[0][1] == t else f"((double){vals[0][0]})"
            for item, tv in vals[1:]:
                cast = item if tv == t else f"((double){item})"
                acc = f"{fn}({acc}, {cast})"
            return acc, t
        if name == "int" and len(args) == 1:
            code, t = self.scalar(args[0])
            return (code, "i") if t == "i" else (f"((int64_t)({code}))", "i")
        if name == "float" and len(args) == 1:
            return self.as_float(args[0]), "f"
        if name == "bool" and len(args) == 1:
            return f"({self.scalar(args[0])[0]} != 0)", "i"
        self.fail(node, f"{name}() with {len(args)} arguments is not supported")
        raise AssertionError

    # -- statements --------------------------------------------------------------------------
    def run(self) -> Function:
        self.infer()
        self.pre = []
        self.tmp = 0
        body = self.block(self.fdef.body, 1)
        args = []
        for pname, t in self.params.items():
            if t in ARRAYS:
                const = ""
                args.append(f"{const}{_ctype(t[0].lower())} *{self.var(pname)}")
                args += [f"int64_t {self.var(pname)}_n{k}" for k in range(int(t[1]))]
            else:
                args.append(f"{_ctype(t)} {self.var(pname)}")
        decls = [f"    {_ctype(t)} {self.var(n)} = 0;" for n, t in self.locals.items()
                 if n not in self.params]
        if self.returns is not None and self.returns.startswith("tuple:"):
            args += [f"{_ctype(t)} *ret_{k}" for k, t in enumerate(self.returns[6:].split(","))]
            ret = "void"
        else:
            ret = "void" if self.returns is None else _ctype(self.returns)
        # Arguments a function never uses are fine: mark them so -Wunused stays quiet; so are
        # locals it only sets (a tuple's element it ignores), for -Wunused-but-set-variable.
        unused = [f"    (void){a.split()[-1].lstrip('*')};" for a in args]
        unused += [f"    (void){self.var(n)};" for n in self.locals if n not in self.params]
        head = f"static inline {ret} {self.cname}({', '.join(args) or 'void'})"
        source = head + "\n{\n" + "\n".join(decls + unused + body) + "\n}\n"
        return Function(self.cname, tuple(self.params.items()), self.returns, source)

    def block(self, stmts: list[ast.stmt], depth: int) -> list[str]:
        out: list[str] = []
        for s in stmts:
            if isinstance(s, ast.Expr) and isinstance(s.value, ast.Constant) \
                    and isinstance(s.value.value, str):
                continue  # a docstring
            saved = self.pre
            self.pre = []
            lines = self.stmt(s, depth)
            ind = "    " * depth
            out += [ind + p for p in self.pre] + lines
            self.pre = saved
        return out

    def stmt(self, s: ast.stmt, depth: int) -> list[str]:
        ind = "    " * depth
        if isinstance(s, ast.Assign):
            out: list[str] = []
            for target in s.targets:
                out += self.assign(target, s.value, ind)
            return out
        if isinstance(s, ast.AugAssign):
            fake = ast.BinOp(left=_load(s.target), op=s.op, right=s.value)
            ast.copy_location(fake, s)
            return self.assign(s.target, fake, ind)
        if isinstance(s, ast.If):
            test, _ = self.scalar(s.test)
            out = [f"{ind}if ({test}) {{", *self.block(s.body, depth + 1)]
            if s.orelse:
                out += [f"{ind}}} else {{", *self.block(s.orelse, depth + 1)]
            return [*out, f"{ind}}}"]
        if isinstance(s, ast.While):
            if s.orelse:
                self.fail(s, "while ... else is not supported")
            # The test may need statements (a power): evaluate it at the top of each pass.
            saved = self.pre
            self.pre = []
            test, _ = self.scalar(s.test)
            pre = self.pre
            self.pre = saved
            self.loop_depth += 1
            body = self.block(s.body, depth + 1)
            self.loop_depth -= 1
            inner = "    " * (depth + 1)
            return [f"{ind}for (;;) {{", *[inner + p for p in pre],
                    f"{inner}if (!({test})) break;", *body, f"{ind}}}"]
        if isinstance(s, ast.For):
            return self.for_range(s, depth)
        if isinstance(s, ast.Break):
            return [f"{ind}break;"]
        if isinstance(s, ast.Continue):
            return [f"{ind}continue;"]
        if isinstance(s, ast.Pass):
            return []
        if isinstance(s, ast.Return):
            if s.value is None or (isinstance(s.value, ast.Constant) and s.value.value is None):
                if self.returns is not None:
                    self.fail(s, "returns a value on one path and nothing on another")
                return [f"{ind}return;"]
            if isinstance(s.value, ast.Tuple):
                vals = [self.scalar(e) for e in s.value.elts]
                kinds = "tuple:" + ",".join(t for _, t in vals)
                if self.returns is not None and self.returns != kinds:
                    self.fail(s, "returns tuples of different types")
                self.returns = kinds
                return [*(f"{ind}*ret_{k} = {code};" for k, (code, _) in enumerate(vals)),
                        f"{ind}return;"]
            code, t = self.scalar(s.value)
            if self.returns is None:
                self.returns = t
            elif self.returns.startswith("tuple:"):
                self.fail(s, "returns a tuple on one path and a number on another")
            elif self.returns != t:
                self.returns = "f"
                code = code if t == "f" else f"((double){code})"
            return [f"{ind}return {code};"]
        if isinstance(s, ast.Expr) and isinstance(s.value, ast.Call):
            code, _ = self.expr(s.value)
            return [f"{ind}{code};"]
        self.fail(s, f"{type(s).__name__} statements are not supported")
        raise AssertionError

    def assign(self, target: ast.expr, value: ast.expr, ind: str) -> list[str]:
        if isinstance(target, ast.Tuple):
            names = []
            for el in target.elts:
                if not isinstance(el, ast.Name):
                    self.fail(el, "only names may be unpacked into")
                assert isinstance(el, ast.Name)
                names.append(el.id)
            out = []
            temps = []
            if isinstance(value, ast.Tuple):
                if len(value.elts) != len(names):
                    self.fail(target, "unpacking a tuple of another length")
                for v in value.elts:
                    code, t = self.scalar(v)
                    name = self.fresh()
                    temps.append((name, t))
                    out.append(f"{ind}const {_ctype(t)} {name} = {code};")
            elif isinstance(value, ast.Call) and isinstance(value.func, ast.Name) \
                    and value.func.id in self.m.defs:
                fn, codes = self.callee(value)
                if fn.returns is None or not fn.returns.startswith("tuple:"):
                    self.fail(value, f"{value.func.id} returns no tuple")
                assert fn.returns is not None
                kinds = fn.returns[6:].split(",")
                if len(kinds) != len(names):
                    self.fail(target, "unpacking a tuple of another length")
                for t in kinds:
                    name = self.fresh()
                    temps.append((name, t))
                    out.append(f"{ind}{_ctype(t)} {name};")
                out.append(f"{ind}{fn.name}(" + ", ".join([*codes, *(f"&{n}" for n, _ in temps)])
                           + ");")
            else:
                self.fail(value, "a tuple is unpacked from something that is not one")
            for var, (name, t) in zip(names, temps, strict=True):
                cast = name if not (self.locals[var] == "f" and t == "i") else f"((double){name})"
                out.append(f"{ind}{self.var(var)} = {cast};")
            return out
        code, t = self.scalar(value)
        if isinstance(target, ast.Name):
            want = self.locals[target.id]
            if want == "f" and t == "i":
                code = f"((double){code})"
            return [f"{ind}{self.var(target.id)} = {code};"]
        if isinstance(target, ast.Subscript):
            if isinstance(target.slice, ast.Tuple) and all(
                    isinstance(e, ast.Slice) for e in target.slice.elts):
                self.fail(target, "slice assignment is not supported")
            dest, te = self.element(target)
            if te == "f" and t == "i":
                code = f"((double){code})"
            elif te == "i" and t == "f":
                self.fail(target, "a float stored into an integer array")
            return [f"{ind}{dest} = {code};"]
        self.fail(target, "assignment to this target is not supported")
        raise AssertionError

    def for_range(self, s: ast.For, depth: int) -> list[str]:
        ind = "    " * depth
        it = s.iter
        if s.orelse:
            self.fail(s, "for ... else is not supported")
        if not (isinstance(it, ast.Call) and isinstance(it.func, ast.Name)
                and it.func.id == "range" and 1 <= len(it.args) <= 3):
            self.fail(s, "only `for name in range(...)` loops are supported")
        if not isinstance(s.target, ast.Name):
            self.fail(s, "the loop variable must be a name")
        assert isinstance(it, ast.Call) and isinstance(s.target, ast.Name)
        args = [self.scalar(a) for a in it.args]
        if any(t != "i" for _, t in args):
            self.fail(s, "range() of a float")
        start, stop, step = "INT64_C(0)", args[0][0], "INT64_C(1)"
        sign = 1
        if len(args) >= 2:
            start, stop = args[0][0], args[1][0]
        if len(args) == 3:
            lit = _literal(it.args[2], self.m.constants)
            if not isinstance(lit, int) or lit == 0:
                self.fail(s, "range() with a step that is not a non-zero integer literal")
            assert isinstance(lit, int)
            step = c_int(lit)
            sign = 1 if lit > 0 else -1
        var = self.var(s.target.id)
        end = self.fresh()
        cmp = "<" if sign > 0 else ">"
        self.loop_depth += 1
        body = self.block(s.body, depth + 1)
        self.loop_depth -= 1
        return [f"{ind}{{", f"{ind}    const int64_t {end} = {stop};",
                f"{ind}    for (int64_t {end}_i = {start}; {end}_i {cmp} {end}; {end}_i += {step}) {{",
                f"{ind}        {var} = {end}_i;",
                *["    " + line for line in body],
                f"{ind}    }}", f"{ind}}}"]


def _load(target: ast.expr) -> ast.expr:
    import copy

    node = copy.deepcopy(target)
    for sub in ast.walk(node):
        if hasattr(sub, "ctx"):
            sub.ctx = ast.Load()
    return node


def _ctype(t: str) -> str:
    return {"f": "double", "i": "int64_t"}[t]


__all__ = ["ARRAYS", "PRELUDE", "SCALARS", "Function", "Module", "TranslationError", "c_float",
           "c_int"]
