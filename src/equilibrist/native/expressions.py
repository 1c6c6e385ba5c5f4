"""The expressions of the C translation (see :mod:`equilibrist.native.pyc`).

:class:`Expressions` writes one Python expression as C (fully parenthesized
in Python's evaluation order, with the typing rules of :mod:`equilibrist.native.pyc`) and
knows the names in scope; :class:`equilibrist.native.translate.Translator`
adds the statements and the function around them.
"""

from __future__ import annotations

import ast
from collections.abc import Callable

from equilibrist.native.pyc import (
    _LIBM,
    _MATH,
    _MATH_BOOL,
    _MATH_CONST,
    ARRAYS,
    SCALARS,
    Function,
    Module,
    TranslationError,
    _literal,
    _unify,
    c_float,
    c_int,
)
from equilibrist.numeric import libm


class Expressions:
    """The expression half of a function's translation (its names, types and values)."""

    m: Module
    fdef: ast.FunctionDef
    params: dict[str, str]
    locals: dict[str, str]
    returns: str | None
    tmp: int
    pre: list[str]

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
        if isinstance(exponent, int) and abs(exponent) <= libm.PRODUCT_POWER_MAX:
            # A static power: the product libm.power_product writes (repeated squaring),
            # each square a temporary; the generated Python prints the same product.
            if exponent == 0:
                return ("1.0", "f") if tb == "f" else ("INT64_C(1)", "i")
            if exponent < 0 and tb == "i":
                self.fail(node, "an integer to a negative power")
            name = self.fresh()
            self.pre.append(f"const {_ctype(tb)} {name}_b = {base};")
            squares: list[str] = []

            def square(factor: str) -> str:
                squares.append(f"{name}_{len(squares)}")
                self.pre.append(f"const {_ctype(tb)} {squares[-1]} = {factor} * {factor};")
                return squares[-1]

            return libm.power_product(f"{name}_b", exponent, square), ("f" if exponent < 0 else tb)
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

def _ctype(t: str) -> str:
    return {"f": "double", "i": "int64_t"}[t]
