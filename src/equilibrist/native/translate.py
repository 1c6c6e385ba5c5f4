"""The translator of one function (see :mod:`equilibrist.native.pyc`, whose rules it follows).

:class:`Translator` infers the type of every local (an integer unless a
float is ever stored in it), then writes each statement and expression as
C, fully parenthesized in Python's evaluation order.
"""

from __future__ import annotations

import ast

from equilibrist.native.expressions import Expressions, _ctype
from equilibrist.native.pyc import (
    ARRAYS,
    SCALARS,
    Function,
    Module,
    TranslationError,
    _literal,
    _unify,
    c_int,
)


class Translator(Expressions):
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
        self.pre: list[str] = []

    # -- errors ------------------------------------------------------------------------------
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

    def safe_type(self, node: ast.expr) -> str | None:
        try:
            return self.expr(node)[1]
        except TranslationError:
            return None

    # -- expressions -------------------------------------------------------------------------
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
            body = self.block(s.body, depth + 1)
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
        body = self.block(s.body, depth + 1)
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



