"""The project's own ``sin``, ``cos`` and ``log``: the same bits on every CPU.

The C library's ``sin``, ``cos``, ``log`` (and ``exp``, ``pow``, ``atan2``,
``tan``) are chosen at load time by the CPU's features: glibc on x86-64
picks ``__sin_fma`` on a CPU with FMA and AVX2, ``__sin_avx`` or
``__sin_sse2`` elsewhere (and ``GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA``
picks another on the same CPU). Those variants round differently for a few
inputs in ten thousand, so a trajectory that calls them is not the same to
the bit on two machines. The functions here are written with plain IEEE
double operations (``+ - * /``, comparisons, the exact ``math.frexp``), in
an order the code fixes, so Python and the C core (which contracts nothing
without ``fastmath``) give the same bits on every CPU.

They are the kernels of fdlibm (Sun Microsystems, 1993), as kept in musl:
``__sin``, ``__cos`` and ``__rem_pio2``'s Cody-Waite reduction (three
steps, 118 bits of pi/2), and ``log``. Within 1 ulp of the exact value
(checked against mpmath in tests/sim/test_bits_cpu.py) for every finite
argument of ``sin`` and ``cos`` with ``|x| < 2**20 * pi / 2`` (about
1.6e6 rad); beyond that the reduction is still deterministic but loses
accuracy (fdlibm's Payne-Hanek path is not ported: no angle of a
balancing rig comes near).

The section below the marker is copied verbatim into every generated
numeric module (:mod:`equilibrist.numeric.codegen`), so the generated
``f`` calls these functions under the names ``eq_sin`` and ``eq_cos`` as
plain Python; the C core (:mod:`equilibrist.native`) translates ``f`` with
the calls kept and links :func:`c_source`, the same functions in C. Edit
the section only together with ``REVISION`` in
:mod:`equilibrist.numeric.codegen` and :func:`c_source`: the cache of
derived models is keyed by both modules' sources.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

#: The functions of the copied section, in the order they must be compiled.
FUNCTIONS = ("eq_ksin", "eq_kcos", "eq_rem_pio2", "eq_sin", "eq_cos", "eq_log")

_MARKER = "# ---8<--- libm body"

# ---8<--- libm body: everything below is copied into each generated module

# fdlibm's kernels (musl src/math/__sin.c, __cos.c, __rem_pio2.c, sin.c, cos.c, log.c).
EQ_S1 = -1.66666666666666324348e-01
EQ_S2 = 8.33333333332248946124e-03
EQ_S3 = -1.98412698298579493134e-04
EQ_S4 = 2.75573137070700676789e-06
EQ_S5 = -2.50507602534068634195e-08
EQ_S6 = 1.58969099521155010221e-10
EQ_C1 = 4.16666666666666019037e-02
EQ_C2 = -1.38888888888741095749e-03
EQ_C3 = 2.48015872894767294178e-05
EQ_C4 = -2.75573143513906633035e-07
EQ_C5 = 2.08757232129817482790e-09
EQ_C6 = -1.13596475577881948265e-11
EQ_TOINT = 6755399441055744.0  # 1.5 * 2**52
EQ_INVPIO2 = 6.36619772367581382433e-01
EQ_PIO2_1 = 1.57079632673412561417e00
EQ_PIO2_1T = 6.07710050650619224932e-11
EQ_PIO2_2 = 6.07710050630396597660e-11
EQ_PIO2_2T = 2.02226624879595063154e-21
EQ_PIO2_3 = 2.02226624871116645580e-21
EQ_PIO2_3T = 8.47842766036889956997e-32
EQ_TWO_M16 = 1.52587890625e-05
EQ_TWO_M49 = 1.7763568394002505e-15
EQ_TWO_52 = 4503599627370496.0
EQ_PIO4 = 0.7853981633974483  # 0x1.921fb54442d18p-1
EQ_PIO4_HI = 0.7853984832763672  # high word 0x3fe921fc: |x| < this is fdlibm's |x| ~<= pi/4
EQ_SIN_TINY = 1.4901161193847656e-08  # 2**-26
EQ_COS_TINY = 1.0536709282860102e-08  # high word 0x3e46a09e: 2**-27 * sqrt(2)
EQ_LN2_HI = 6.93147180369123816490e-01
EQ_LN2_LO = 1.90821492927058770002e-10
EQ_LG1 = 6.666666666666735130e-01
EQ_LG2 = 3.999999999940941908e-01
EQ_LG3 = 2.857142874366239149e-01
EQ_LG4 = 2.222219843214978396e-01
EQ_LG5 = 1.818357216161805012e-01
EQ_LG6 = 1.531383769920937332e-01
EQ_LG7 = 1.479819860511658591e-01
EQ_SQRT2_HALF_HI = 0.7071065902709961  # high word 0x3fe6a09e: fdlibm's split of the mantissa


def eq_ksin(x: float, y: float, iy: int) -> float:
    """sin(x + y) for |x + y| <= pi/4 (y the tail of x; iy 0 when y is zero)."""
    z = x * x
    w = z * z
    r = EQ_S2 + z * (EQ_S3 + z * EQ_S4) + z * w * (EQ_S5 + z * EQ_S6)
    v = z * x
    if iy == 0:
        return x + v * (EQ_S1 + z * r)
    return x - ((z * (0.5 * y - v * r) - y) - v * EQ_S1)


def eq_kcos(x: float, y: float) -> float:
    """cos(x + y) for |x + y| <= pi/4."""
    z = x * x
    w = z * z
    r = z * (EQ_C1 + z * (EQ_C2 + z * EQ_C3)) + w * w * (EQ_C4 + z * (EQ_C5 + z * EQ_C6))
    hz = 0.5 * z
    w = 1.0 - hz
    return w + (((1.0 - w) - hz) + (z * r - x * y))


def eq_rem_pio2(x: float) -> tuple[int, float, float]:
    """``(q, y0, y1)`` with ``x = n pi/2 + y0 + y1``, ``|y0 + y1| <= pi/4``, ``q = n mod 4`` (x finite)."""
    fn = x * EQ_INVPIO2 + EQ_TOINT - EQ_TOINT
    r = x - fn * EQ_PIO2_1
    w = fn * EQ_PIO2_1T
    if r - w < -EQ_PIO4:
        fn = fn - 1.0
        r = x - fn * EQ_PIO2_1
        w = fn * EQ_PIO2_1T
    elif r - w > EQ_PIO4:
        fn = fn + 1.0
        r = x - fn * EQ_PIO2_1
        w = fn * EQ_PIO2_1T
    y0 = r - w
    # fdlibm compares exponents (16 and 49 bits lost); these tests take the
    # extra steps whenever it does (and a little more often), no bit access.
    ax = abs(x)
    if abs(y0) < ax * EQ_TWO_M16:  # cancellation: a second step, good to 118 bits
        t = r
        w = fn * EQ_PIO2_2
        r = t - w
        w = fn * EQ_PIO2_2T - ((t - r) - w)
        y0 = r - w
        if abs(y0) < ax * EQ_TWO_M49:  # a third, good to 151 bits
            t = r
            w = fn * EQ_PIO2_3
            r = t - w
            w = fn * EQ_PIO2_3T - ((t - r) - w)
            y0 = r - w
    y1 = (r - y0) - w
    if abs(fn) < EQ_TWO_52:
        return int(fn) & 3, y0, y1
    return 0, y0, y1  # |x| > 7e15: deterministic, not accurate


def eq_sin(x: float) -> float:
    """sin(x), the same bits on every CPU."""
    a = abs(x)
    if a < EQ_PIO4_HI:
        if a < EQ_SIN_TINY:
            return x
        return eq_ksin(x, 0.0, 0)
    if not (a < math.inf):  # inf or nan
        return x - x
    q, y0, y1 = eq_rem_pio2(x)
    if q == 0:
        return eq_ksin(y0, y1, 1)
    if q == 1:
        return eq_kcos(y0, y1)
    if q == 2:
        return -eq_ksin(y0, y1, 1)
    return -eq_kcos(y0, y1)


def eq_cos(x: float) -> float:
    """cos(x), the same bits on every CPU."""
    a = abs(x)
    if a < EQ_PIO4_HI:
        if a < EQ_COS_TINY:
            return 1.0
        return eq_kcos(x, 0.0)
    if not (a < math.inf):
        return x - x
    q, y0, y1 = eq_rem_pio2(x)
    if q == 0:
        return eq_kcos(y0, y1)
    if q == 1:
        return -eq_ksin(y0, y1, 1)
    if q == 2:
        return -eq_kcos(y0, y1)
    return eq_ksin(y0, y1, 1)


def eq_log(x: float) -> float:
    """The natural logarithm, the same bits on every CPU."""
    if not (x > 0.0):
        if x == 0.0:
            return -math.inf
        return math.nan  # negative or nan
    if x == math.inf:
        return x
    m, k = math.frexp(x)  # x = m 2**k, 0.5 <= m < 1 (exact, subnormals too)
    if m < EQ_SQRT2_HALF_HI:
        m = m * 2.0
        k = k - 1
    f = m - 1.0
    hfsq = 0.5 * f * f
    s = f / (2.0 + f)
    z = s * s
    w = z * z
    t1 = w * (EQ_LG2 + w * (EQ_LG4 + w * EQ_LG6))
    t2 = z * (EQ_LG1 + w * (EQ_LG3 + w * (EQ_LG5 + w * EQ_LG7)))
    r = t2 + t1
    dk = float(k)
    return s * (hfsq + r) + dk * EQ_LN2_LO - hfsq + f + dk * EQ_LN2_HI


# ---8<--- end of libm body


# fdlibm's exp (musl src/math/exp.c), for the C core's own use (the adaptive integrator's
# step-size control): not copied into generated modules.
EXP_P1 = 1.66666666666666019037e-01
EXP_P2 = -2.77777777770155933842e-03
EXP_P3 = 6.61375632143793436117e-05
EXP_P4 = -1.65339022054652515390e-06
EXP_P5 = 4.13813679705723846039e-08
EXP_INVLN2 = 1.44269504088896338700e00
EXP_HUGE = 709.782712893383973096
EXP_TINY = -745.13321910194110842
EXP_HALF_LN2 = 0.34657359027997264  # fdlibm's |x| > 0.5 ln2 (high word 0x3fd62e42)
EXP_TWO_M28 = 3.725290298461914e-09


def eq_exp(x: float) -> float:
    """e**x, the same bits on every CPU (within 1 ulp: fdlibm's exp)."""
    if math.isnan(x):
        return x
    if x > EXP_HUGE:
        return math.inf
    if x < EXP_TINY:
        return 0.0
    a = abs(x)
    if a > EXP_HALF_LN2:
        k = int(EXP_INVLN2 * x + (0.5 if x >= 0.0 else -0.5))  # C's (int): toward zero
        hi = x - k * EQ_LN2_HI  # exact: EQ_LN2_HI has 32 trailing zero bits
        lo = k * EQ_LN2_LO
        r = hi - lo
    elif a > EXP_TWO_M28:
        k, hi, lo, r = 0, x, 0.0, x
    else:
        return 1.0 + x
    xx = r * r
    c = r - xx * (EXP_P1 + xx * (EXP_P2 + xx * (EXP_P3 + xx * (EXP_P4 + xx * EXP_P5))))
    y = 1.0 + (r * c / (2.0 - c) - lo + hi)
    return y if k == 0 else math.ldexp(y, k)


EXP_C = """
static double {p}eq_exp(double x)
{{
    double a, hi, lo, r, xx, c, y;
    int k;
    if (x != x) {{
        return x;
    }}
    if (x > EXP_HUGE) {{
        return HUGE_VAL;
    }}
    if (x < EXP_TINY) {{
        return 0.0;
    }}
    a = fabs(x);
    if (a > EXP_HALF_LN2) {{
        k = (int)(EXP_INVLN2 * x + (x >= 0.0 ? 0.5 : -0.5));
        hi = x - k * EQ_LN2_HI;
        lo = k * EQ_LN2_LO;
        r = hi - lo;
    }} else if (a > EXP_TWO_M28) {{
        k = 0;
        hi = x;
        lo = 0.0;
        r = x;
    }} else {{
        return 1.0 + x;
    }}
    xx = r * r;
    c = r - xx * (EXP_P1 + xx * (EXP_P2 + xx * (EXP_P3 + xx * (EXP_P4 + xx * EXP_P5))));
    y = 1.0 + (r * c / (2.0 - c) - lo + hi);
    return k == 0 ? y : ldexp(y, k);
}}
"""


def source() -> str:
    """The section above, as copied into each generated module."""
    text = Path(__file__).read_text()
    start = text.index("\n" + _MARKER)
    start = text.index("\n", start + 1) + 1
    end = text.index("\n# ---8<--- end of libm body")
    return text[start:end].strip() + "\n"


sin = eq_sin
cos = eq_cos
log = eq_log


#: The largest ``|k|`` of a power ``x ** k`` (``k`` an integer literal) written as a product of
#: ``x``: a larger one, or any other exponent, is the C library's ``pow``.
PRODUCT_POWER_MAX = 64


def power_product(base: str, exponent: int, square: Callable[[str], str]) -> str:
    """The text of ``base ** exponent`` as the product both forms of a source compute: the
    C translation (:mod:`equilibrist.native.expressions`) and the generated Python
    (:mod:`equilibrist.numeric.codegen`) write it from here, so they evaluate the same IEEE
    operations in the same order (CPython's ``x ** 2`` calls the C library's ``pow``, which
    glibc 2.36 rounds differently from ``x * x`` at a few inputs in ten thousand).

    Repeated squaring, ``r = 1; while e: (if e & 1: r *= v); e >>= 1; v *= v`` with the first
    factor taken as it is (no ``1.0 *``), for ``0 < |exponent| <= PRODUCT_POWER_MAX``; a
    negative exponent is ``1.0 / `` the product. *square* of a factor's text gives the text
    of its square (a temporary's name, or the parenthesized product itself). ``x ** 2`` is
    ``(x * x)`` then, ``x ** 3`` ``(x * (x * x))``, ``x ** 4`` ``((x * x) * (x * x))``.
    """
    if not 0 < abs(exponent) <= PRODUCT_POWER_MAX:
        raise ValueError(f"not a power written as a product: {exponent}")
    result: str | None = None
    factor = base
    e = abs(exponent)
    while e:
        if e & 1:
            result = factor if result is None else f"({result} * {factor})"
        e >>= 1
        if e:
            factor = square(factor)
    assert result is not None
    return f"(1.0 / {result})" if exponent < 0 else result


def _c_constants() -> str:
    g = globals()
    names = [n for n in g if n.startswith(("EQ_", "EXP_")) and isinstance(g[n], float)]
    return "\n".join(f"#define {n} ({float(g[n])!r})" for n in names)


# fdlibm's kernels in C, for the scalar functions below and the vector environment's lanes
# (equilibrist.native.lanes), which run the same operations on eight doubles at a time.
_KERNELS_C = {
    # __kernel_sin's polynomial (x, y: the reduced argument's head and tail) ...
    "sin_poly": """    {t} z = x * x;
    {t} w = z * z;
    {t} r = EQ_S2 + z * (EQ_S3 + z * EQ_S4) + z * w * (EQ_S5 + z * EQ_S6);
    {t} v = z * x;""",
    # ... its value with no tail (iy == 0), and with one:
    "sin_small": "x + v * (EQ_S1 + z * r)",
    "sin_tail": "x - ((z * (0.5 * y - v * r) - y) - v * EQ_S1)",
    # __kernel_cos, whole:
    "cos": """    {t} z = x * x;
    {t} w = z * z;
    {t} r = z * (EQ_C1 + z * (EQ_C2 + z * EQ_C3)) + w * w * (EQ_C4 + z * (EQ_C5 + z * EQ_C6));
    {t} hz = 0.5 * z;
    w = 1.0 - hz;
    return w + (((1.0 - w) - hz) + (z * r - x * y));""",
}


def kernel_c(part: str, type_name: str = "double") -> str:
    """A part of fdlibm's sine or cosine kernel in C (:data:`_KERNELS_C`), its variables of
    the C type *type_name* (``double``, or a GCC vector of doubles)."""
    return _KERNELS_C[part].format(t=type_name)


def c_source(prefix: str = "", *, log: bool = False, exp: bool = False) -> str:
    """The same functions in C99, operation for operation (``static``; needs ``<math.h>``
    for ``fabs`` and ``frexp``, both exact).

    Compiled with ``-ffp-contract=off`` (no fused multiply-add; GCC's default in
    ISO C mode, not clang's) and without ``-ffast-math``, they give the bits of
    the Python version. *prefix* goes before each function's name;
    ``eq_log`` only with *log* (an unused static function is a warning).
    """
    body = _c_kernels(prefix) + _c_rem_pio2(prefix) + _c_sin_cos(prefix)
    head = ("/* sin, cos, log of equilibrist.numeric.libm (fdlibm's kernels, as in musl): the\n"
            " * simulation's bits on every CPU. Compile with -ffp-contract=off, never -ffast-math. */\n")
    return (head + _c_constants() + "\n" + body + (_c_log(prefix) if log else "")
            + (EXP_C.format(p=prefix) if exp else ""))


def _c_kernels(p: str) -> str:
    """fdlibm's sine and cosine kernels in C, ``{p}eq_ksin`` and ``{p}eq_kcos`` (*p*: the
    prefix of the names)."""
    return f"""
static double {p}eq_ksin(double x, double y, int iy)
{{
{kernel_c("sin_poly", "double")}
    if (iy == 0) {{
        return {kernel_c("sin_small")};
    }}
    return {kernel_c("sin_tail")};
}}

static double {p}eq_kcos(double x, double y)
{{
{kernel_c("cos", "double")}
}}
"""


def _c_rem_pio2(p: str) -> str:
    """``{p}eq_rem_pio2``: the argument reduced by a multiple of pi/2 (into *y*), and
    the multiple's last two bits."""
    return f"""
static int {p}eq_rem_pio2(double x, double *y)
{{
    double fn = x * EQ_INVPIO2 + EQ_TOINT - EQ_TOINT;
    double r = x - fn * EQ_PIO2_1;
    double w = fn * EQ_PIO2_1T;
    double ax, t, y0;
    if (r - w < -EQ_PIO4) {{
        fn = fn - 1.0;
        r = x - fn * EQ_PIO2_1;
        w = fn * EQ_PIO2_1T;
    }} else if (r - w > EQ_PIO4) {{
        fn = fn + 1.0;
        r = x - fn * EQ_PIO2_1;
        w = fn * EQ_PIO2_1T;
    }}
    y0 = r - w;
    ax = fabs(x);
    if (fabs(y0) < ax * EQ_TWO_M16) {{
        t = r;
        w = fn * EQ_PIO2_2;
        r = t - w;
        w = fn * EQ_PIO2_2T - ((t - r) - w);
        y0 = r - w;
        if (fabs(y0) < ax * EQ_TWO_M49) {{
            t = r;
            w = fn * EQ_PIO2_3;
            r = t - w;
            w = fn * EQ_PIO2_3T - ((t - r) - w);
            y0 = r - w;
        }}
    }}
    y[0] = y0;
    y[1] = (r - y0) - w;
    if (fabs(fn) < EQ_TWO_52) {{
        return (int)((unsigned long long)(long long)fn & 3u);
    }}
    return 0;
}}
"""


def _c_sin_cos(p: str) -> str:
    """``{p}eq_sin`` and ``{p}eq_cos``: the reduction, then the kernel its quadrant calls."""
    return f"""
static double {p}eq_sin(double x)
{{
    double a = fabs(x);
    double y[2];
    int q;
    if (a < EQ_PIO4_HI) {{
        if (a < EQ_SIN_TINY) {{
            return x;
        }}
        return {p}eq_ksin(x, 0.0, 0);
    }}
    if (!(a < HUGE_VAL)) {{
        return x - x;
    }}
    q = {p}eq_rem_pio2(x, y);
    if (q == 0) {{
        return {p}eq_ksin(y[0], y[1], 1);
    }}
    if (q == 1) {{
        return {p}eq_kcos(y[0], y[1]);
    }}
    if (q == 2) {{
        return -{p}eq_ksin(y[0], y[1], 1);
    }}
    return -{p}eq_kcos(y[0], y[1]);
}}

static double {p}eq_cos(double x)
{{
    double a = fabs(x);
    double y[2];
    int q;
    if (a < EQ_PIO4_HI) {{
        if (a < EQ_COS_TINY) {{
            return 1.0;
        }}
        return {p}eq_kcos(x, 0.0);
    }}
    if (!(a < HUGE_VAL)) {{
        return x - x;
    }}
    q = {p}eq_rem_pio2(x, y);
    if (q == 0) {{
        return {p}eq_kcos(y[0], y[1]);
    }}
    if (q == 1) {{
        return -{p}eq_ksin(y[0], y[1], 1);
    }}
    if (q == 2) {{
        return -{p}eq_kcos(y[0], y[1]);
    }}
    return {p}eq_ksin(y[0], y[1], 1);
}}
"""


def _c_log(p: str) -> str:
    """``{p}eq_log``: fdlibm's logarithm."""
    return f"""
static double {p}eq_log(double x)
{{
    double m, f, hfsq, s, z, w, t1, t2, r, dk;
    int k;
    if (!(x > 0.0)) {{
        return x == 0.0 ? -HUGE_VAL : NAN;
    }}
    if (x == HUGE_VAL) {{
        return x;
    }}
    m = frexp(x, &k);
    if (m < EQ_SQRT2_HALF_HI) {{
        m = m * 2.0;
        k = k - 1;
    }}
    f = m - 1.0;
    hfsq = 0.5 * f * f;
    s = f / (2.0 + f);
    z = s * s;
    w = z * z;
    t1 = w * (EQ_LG2 + w * (EQ_LG4 + w * EQ_LG6));
    t2 = z * (EQ_LG1 + w * (EQ_LG3 + w * (EQ_LG5 + w * EQ_LG7)));
    r = t2 + t1;
    dk = (double)k;
    return s * (hfsq + r) + dk * EQ_LN2_LO - hfsq + f + dk * EQ_LN2_HI;
}}
"""
