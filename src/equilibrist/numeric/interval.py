"""Interval arithmetic on numpy arrays, rounded outward: enclosures that hold in real numbers.

An :class:`Interval` is a pair of arrays ``lo <= hi`` (one interval per
element: a batch of boxes is evaluated at once). Every operation returns an
interval that contains every real result for every real operand in its
operands' intervals:

* ``+ - * /`` and ``sqrt`` are IEEE operations, correctly rounded, so moving
  each end one floating-point number outward (``nextafter``) is enough;
* ``sin``, ``cos``, ``exp``, ``tanh`` come from the C library or numpy,
  whose errors are a few units in the last place: each end moves out by
  :data:`LIBM_SLACK` relative (with a floor), far more than those errors;
* a division by an interval that holds zero, an overflow or a NaN gives the
  whole line ``[-inf, inf]``: an enclosure that proves nothing rather than
  a wrong one.

:func:`lambdify` turns sympy expressions into a function of intervals (the
operations above; a rational constant is enclosed, not rounded to the
nearest float); an expression with a function outside them is refused with
:class:`UnsupportedError`. This is what :mod:`equilibrist.control.certify`
proves a region of attraction with.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from types import SimpleNamespace
from typing import Any

import numpy as np

#: Relative outward slack of the library functions' results (their error is a few ulp).
LIBM_SLACK = 1e-14
_TWO_PI = 2.0 * math.pi


class UnsupportedError(ValueError):
    """An expression holds a function that has no enclosure here."""


# One step outward from a correctly rounded result: |x| 2^-52 is at least one ulp of x (an
# exact product), so x - |x| 2^-52 rounds to a float below x's exact value; the smallest
# subnormal covers zero and the subnormals. Cheaper than nextafter, and as sound.
_EPS = 2.0**-52
_TINY = float(np.finfo(float).smallest_subnormal)


def _down(x: np.ndarray | float) -> np.ndarray:
    with np.errstate(invalid="ignore", over="ignore"):
        out: np.ndarray = x - (np.abs(x) * _EPS + _TINY)
    return out


def _up(x: np.ndarray | float) -> np.ndarray:
    with np.errstate(invalid="ignore", over="ignore"):
        out: np.ndarray = x + (np.abs(x) * _EPS + _TINY)
    return out


def _slack(x: np.ndarray) -> np.ndarray:
    out: np.ndarray = LIBM_SLACK * np.maximum(np.abs(x), 1e-300) + 1e-300
    return out


#: An index of the arrays of an interval (numpy's basic and advanced indexing).
Index = int | slice | np.ndarray | tuple[int | slice | np.ndarray, ...]


class Interval:
    """Elementwise intervals ``[lo, hi]`` (arrays of one shape, or scalars)."""

    __slots__ = ("hi", "lo")
    __array_priority__ = 1000  # numpy scalars defer to Interval's operators

    def __init__(self, lo: float | np.ndarray, hi: float | np.ndarray | None = None) -> None:
        lo_a = np.asarray(lo, dtype=float)
        hi_a = lo_a if hi is None else np.asarray(hi, dtype=float)
        bad = np.isnan(lo_a) | np.isnan(hi_a)
        if np.any(bad):
            lo_a = np.where(bad, -np.inf, lo_a)
            hi_a = np.where(bad, np.inf, hi_a)
        self.lo, self.hi = lo_a, hi_a

    # -- construction -------------------------------------------------------------
    @staticmethod
    def of(value: Operand) -> Interval:
        return value if isinstance(value, Interval) else Interval(value)

    @staticmethod
    def rational(p: int, q: int) -> Interval:
        """The real number ``p / q`` enclosed (its nearest float may not be it)."""
        v = np.float64(p) / np.float64(q)
        exact = float(v).as_integer_ratio()
        if exact[0] * q == p * exact[1] and abs(p) < 2**53 and abs(q) < 2**53:
            return Interval(v)
        return Interval(_down(v), _up(v))

    @property
    def mid(self) -> np.ndarray:
        m: np.ndarray = 0.5 * self.lo + 0.5 * self.hi
        return m

    @property
    def width(self) -> np.ndarray:
        w: np.ndarray = self.hi - self.lo
        return w

    def __getitem__(self, key: Index) -> Interval:
        return Interval(self.lo[key], self.hi[key])

    def __repr__(self) -> str:
        return f"Interval({self.lo!r}, {self.hi!r})"

    # -- arithmetic ---------------------------------------------------------------
    def __neg__(self) -> Interval:
        return Interval(-self.hi, -self.lo)

    def __pos__(self) -> Interval:
        return self

    def __add__(self, other: Operand) -> Interval:
        o = Interval.of(other)
        return Interval(_down(self.lo + o.lo), _up(self.hi + o.hi))

    __radd__ = __add__

    def __sub__(self, other: Operand) -> Interval:
        o = Interval.of(other)
        return Interval(_down(self.lo - o.hi), _up(self.hi - o.lo))

    def __rsub__(self, other: Operand) -> Interval:
        return Interval.of(other) - self

    def __mul__(self, other: Operand) -> Interval:
        o = Interval.of(other)
        with np.errstate(invalid="ignore", over="ignore"):
            if o.lo is o.hi and o.lo.ndim == 0:  # times a number
                a, b = self.lo * o.lo, self.hi * o.lo
                return Interval(_down(np.minimum(a, b)), _up(np.maximum(a, b)))
            if self.lo is self.hi and self.lo.ndim == 0:
                return o * self
            p1, p2 = self.lo * o.lo, self.lo * o.hi
            p3, p4 = self.hi * o.lo, self.hi * o.hi
            lo = np.minimum(np.minimum(p1, p2), np.minimum(p3, p4))
            hi = np.maximum(np.maximum(p1, p2), np.maximum(p3, p4))
        return Interval(_down(lo), _up(hi))

    __rmul__ = __mul__

    def reciprocal(self) -> Interval:
        holds_zero = (self.lo <= 0.0) & (self.hi >= 0.0)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            lo = np.where(holds_zero, -np.inf, _down(1.0 / self.hi))
            hi = np.where(holds_zero, np.inf, _up(1.0 / self.lo))
        return Interval(lo, hi)

    def __truediv__(self, other: Operand) -> Interval:
        o = Interval.of(other)
        if not np.any((o.lo <= 0.0) & (o.hi >= 0.0)):
            with np.errstate(invalid="ignore", over="ignore"):
                p1, p2 = self.lo / o.lo, self.lo / o.hi
                p3, p4 = self.hi / o.lo, self.hi / o.hi
                lo = np.minimum(np.minimum(p1, p2), np.minimum(p3, p4))
                hi = np.maximum(np.maximum(p1, p2), np.maximum(p3, p4))
            return Interval(_down(lo), _up(hi))
        return self * o.reciprocal()

    def __rtruediv__(self, other: Operand) -> Interval:
        return Interval.of(other) / self

    def square(self) -> Interval:
        a = np.abs(self.lo)
        b = np.abs(self.hi)
        holds_zero = (self.lo <= 0.0) & (self.hi >= 0.0)
        lo = np.where(holds_zero, 0.0, _down(np.minimum(a, b) ** 2))
        return Interval(lo, _up(np.maximum(a, b) ** 2))

    def __pow__(self, k: Interval | float) -> Interval:
        if isinstance(k, Interval):
            if np.all(k.lo == k.hi) and np.unique(k.lo).size == 1:
                k = float(np.ravel(k.lo)[0])
            else:
                raise UnsupportedError("a power with an interval exponent has no enclosure here")
        if float(k) == 0.5:
            return self.sqrt()
        if float(k) != int(k):
            raise UnsupportedError(f"the power {k} has no enclosure here (integers and 1/2 only)")
        n = int(k)
        if n < 0:
            return (self ** (-n)).reciprocal()
        if n == 0:
            return Interval(np.ones_like(self.lo))
        if n % 2 == 0:
            base = self.square()
            out = base
            for _ in range(n // 2 - 1):
                out = out * base
            return out
        out = self
        for _ in range(n - 1):
            out = out * self
        return out

    def sqrt(self) -> Interval:
        with np.errstate(invalid="ignore"):
            lo = np.where(self.lo <= 0.0, 0.0, _down(np.sqrt(np.maximum(self.lo, 0.0))))
            hi = np.where(self.hi < 0.0, np.nan, _up(np.sqrt(np.maximum(self.hi, 0.0))))
        return Interval(lo, hi)

    def abs(self) -> Interval:
        holds_zero = (self.lo <= 0.0) & (self.hi >= 0.0)
        a, b = np.abs(self.lo), np.abs(self.hi)
        return Interval(np.where(holds_zero, 0.0, np.minimum(a, b)), np.maximum(a, b))

    __abs__ = abs

    def hull(self, other: Interval) -> Interval:
        return Interval(np.minimum(self.lo, other.lo), np.maximum(self.hi, other.hi))

    def intersect(self, other: Interval) -> Interval:
        """Both enclose the same value: their common part (still an enclosure)."""
        return Interval(np.maximum(self.lo, other.lo), np.minimum(self.hi, other.hi))


#: An operand of the interval operations: an interval, or numbers (a scalar or an array,
#: each a point interval).
Operand = Interval | float | np.ndarray


def _periodic(x: Interval, phase: float, fn: Callable[[np.ndarray], np.ndarray]) -> Interval:
    """``fn`` (sin or cos) on intervals: the ends, and 1 or -1 where a crest or a trough lies
    inside (``phase``: where the function has its crest, modulo a turn)."""
    a, b = x.lo, x.hi
    fa, fb = fn(a), fn(b)
    lo, hi = np.minimum(fa, fb), np.maximum(fa, fb)
    lo, hi = lo - _slack(lo), hi + _slack(hi)
    # Widened a little: a crest counted inside that is not only loosens the enclosure.
    pad = 1e-9 * np.maximum(1.0, np.maximum(np.abs(a), np.abs(b)))
    a_, b_ = a - pad, b + pad
    with np.errstate(invalid="ignore"):
        crest = np.floor((b_ - phase) / _TWO_PI) >= np.ceil((a_ - phase) / _TWO_PI)
        trough = (np.floor((b_ - phase - math.pi) / _TWO_PI)
                  >= np.ceil((a_ - phase - math.pi) / _TWO_PI))
    whole = ~(np.isfinite(a) & np.isfinite(b)) | (b - a >= _TWO_PI)
    hi = np.where(crest | whole, 1.0, np.minimum(hi, 1.0))
    lo = np.where(trough | whole, -1.0, np.maximum(lo, -1.0))
    return Interval(lo, hi)


def sin(x: Operand) -> Interval:
    return _periodic(Interval.of(x), 0.5 * math.pi, np.sin)


def cos(x: Operand) -> Interval:
    return _periodic(Interval.of(x), 0.0, np.cos)


def _monotone(x: Operand, fn: Callable[[np.ndarray], np.ndarray]) -> Interval:
    v = Interval.of(x)
    with np.errstate(over="ignore"):
        lo, hi = fn(v.lo), fn(v.hi)
    return Interval(lo - _slack(lo), hi + _slack(hi))


def exp(x: Operand) -> Interval:
    out = _monotone(x, np.exp)
    return Interval(np.maximum(out.lo, 0.0), out.hi)


def tanh(x: Operand) -> Interval:
    out = _monotone(x, np.tanh)
    return Interval(np.maximum(out.lo, -1.0), np.minimum(out.hi, 1.0))


def sqrt(x: Operand) -> Interval:
    return Interval.of(x).sqrt()


def _abs(x: Operand) -> Interval:
    return Interval.of(x).abs()


def _unsupported(name: str) -> Callable[..., Interval]:
    def refuse(*_args: object) -> Interval:
        raise UnsupportedError(f"{name} has no enclosure here")
    return refuse


NAMESPACE: dict[str, object] = {
    "math": SimpleNamespace(sin=sin, cos=cos, exp=exp, tanh=tanh, sqrt=sqrt),
    "sin": sin, "cos": cos, "exp": exp, "tanh": tanh, "sqrt": sqrt, "Abs": _abs, "abs": _abs,
    "_rational": Interval.rational, "Interval": Interval,
}


def lambdify(args: Sequence[Any], exprs: Any) -> Callable[..., Any]:
    """``sympy.lambdify`` onto intervals: the returned function takes :class:`Interval`
    arguments (or floats) and returns the same nesting of intervals as *exprs* (a matrix
    becomes a list of rows)."""
    import sympy as sp
    from sympy.printing.lambdarepr import LambdaPrinter

    def leaves(e: Any) -> list[Any]:
        if isinstance(e, (list, tuple)):
            return [x for item in e for x in leaves(item)]
        if isinstance(e, sp.MatrixBase):
            return list(e)
        return [sp.sympify(e)]

    allowed = {sp.sin, sp.cos, sp.exp, sp.tanh}
    for e in leaves(exprs):
        for fn in e.atoms(sp.Function):
            if fn.func not in allowed:
                raise UnsupportedError(f"{fn.func} has no enclosure here")
        if e.has(sp.Piecewise) or e.has(sp.sign) or e.has(sp.Min) or e.has(sp.Max):
            raise UnsupportedError("a piecewise expression has no enclosure here")

    class _Printer(LambdaPrinter):  # type: ignore[misc]
        def _print_Rational(self, expr: Any) -> str:
            return f"_rational({int(expr.p)}, {int(expr.q)})"

        def _print_Half(self, expr: Any) -> str:
            return "_rational(1, 2)"

        def _print_Pow(self, expr: Any, rational: bool = False) -> str:
            base, e = expr.as_base_exp()
            if e == sp.Rational(1, 2):
                return f"sqrt({self._print(base)})"
            if e.is_Integer:
                return f"({self._print(base)})**{int(e)}"
            raise UnsupportedError(f"the power {e} has no enclosure here")

    # Arguments renamed (a model's symbol need not be a Python name), common parts computed
    # once (sympy's cse), then one Python function: its text is the printer's.
    names = [sp.Symbol(f"_a{i}") for i in range(len(args))]
    swap = dict(zip(args, names, strict=True))
    flat = [e.xreplace(swap) for e in leaves(exprs)]
    reps, reduced = sp.cse(flat, symbols=sp.numbered_symbols("_c"))
    printer = _Printer()
    lines = [f"def _enclose({', '.join(str(a) for a in names)}):"]
    lines += [f"    {sym} = {printer.doprint(e)}" for sym, e in reps]
    flat_text = iter(printer.doprint(e) for e in reduced)

    def shape(e: Any) -> str:
        if isinstance(e, (list, tuple)):
            return "[" + ", ".join(shape(item) for item in e) + "]"
        if isinstance(e, sp.MatrixBase):
            return shape(e.tolist())
        return str(next(flat_text))

    lines.append(f"    return {shape(exprs)}")
    scope: dict[str, Any] = dict(NAMESPACE)
    exec("\n".join(lines), scope)
    enclose: Callable[..., Any] = scope["_enclose"]
    return enclose


__all__ = ["LIBM_SLACK", "NAMESPACE", "Interval", "UnsupportedError", "cos", "exp", "lambdify",
           "sin", "sqrt", "tanh"]
