"""The project's own ``sin``, ``cos``, ``log``, ``exp``, ``atan`` and ``tanh``: the same bits
on every CPU.

The C library's ``sin``, ``cos``, ``log``, ``atan``, ``tanh``... are chosen at load time by
the CPU's features and round differently for a few inputs in ten thousand
(docs/reproducibility.md). The functions here are fdlibm's kernels (Sun
Microsystems, 1993, as kept in musl: ``__sin``, ``__cos``, ``__rem_pio2``'s
Cody-Waite reduction in three steps of 118 bits of pi/2, ``log``, ``s_atan.c``,
``s_tanh.c`` over ``s_expm1.c``) written with plain IEEE double operations in
an order the code fixes, so Python and the C core give the same bits on every
CPU. Their accuracy against mpmath is in docs/reproducibility.md; beyond
``|x| < 2**20 * pi / 2`` the reduction stays deterministic but loses accuracy
(fdlibm's Payne-Hanek path is not ported: no angle of a balancing rig comes near).

The section below the marker is copied verbatim into every generated
numeric module (:mod:`equilibrist.numeric.codegen`), so the generated
``f`` calls these functions under the names ``eq_sin`` and ``eq_cos`` as
plain Python (the ``atan`` and ``tanh`` sections only into a module that
calls ``eq_atan`` or ``eq_tanh``, so a model without them keeps its text); the C core (:mod:`equilibrist.native`) translates ``f`` with
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

#: The copied sections: the body, in every generated module; each other one only in a module
#: that calls its function (``eq_atan``, ``eq_tanh``), so that a model without them keeps its text.
SECTIONS = ("body", "atan", "tanh")

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


# ---8<--- libm atan: copied into a generated module that calls eq_atan

# fdlibm's arctangent (s_atan.c, as in musl src/math/atan.c). Its tests of the high word
# are comparisons with the doubles whose low word is zero (exact: no bit access needed).
EQ_ATANHI0 = 4.63647609000806093515e-01  # atan(0.5) hi
EQ_ATANHI1 = 7.85398163397448278999e-01  # atan(1.0) hi
EQ_ATANHI2 = 9.82793723247329054082e-01  # atan(1.5) hi
EQ_ATANHI3 = 1.57079632679489655800e00  # atan(inf) hi
EQ_ATANLO0 = 2.26987774529616870924e-17
EQ_ATANLO1 = 3.06161699786838301793e-17
EQ_ATANLO2 = 1.39033110312309984516e-17
EQ_ATANLO3 = 6.12323399573676603587e-17
EQ_AT0 = 3.33333333333329318027e-01
EQ_AT1 = -1.99999999998764832476e-01
EQ_AT2 = 1.42857142725034663711e-01
EQ_AT3 = -1.11111104054623557880e-01
EQ_AT4 = 9.09088713343650656196e-02
EQ_AT5 = -7.69187620504482999495e-02
EQ_AT6 = 6.66107313738753120669e-02
EQ_AT7 = -5.83357013379057348645e-02
EQ_AT8 = 4.97687799461593236017e-02
EQ_AT9 = -3.65315727442169155270e-02
EQ_AT10 = 1.62858201153657823623e-02
EQ_ATAN_HUGE = 7.378697629483821e19  # 2**66 (high word 0x44100000)
EQ_ATAN_TINY = 7.450580596923828e-09  # 2**-27 (0x3e400000)
EQ_ATAN_7_16 = 0.4375  # 0x3fdc0000
EQ_ATAN_11_16 = 0.6875  # 0x3fe60000
EQ_ATAN_19_16 = 1.1875  # 0x3ff30000
EQ_ATAN_39_16 = 2.4375  # 0x40038000


def eq_katan(x: float) -> float:
    """fdlibm's ``s1 + s2``: atan(x) = x - x (s1 + s2) for |x| <= 7/16."""
    z = x * x
    w = z * z
    s1 = z * (EQ_AT0 + w * (EQ_AT2 + w * (EQ_AT4 + w * (EQ_AT6 + w * (EQ_AT8 + w * EQ_AT10)))))
    s2 = w * (EQ_AT1 + w * (EQ_AT3 + w * (EQ_AT5 + w * (EQ_AT7 + w * EQ_AT9))))
    return s1 + s2


def eq_atan(x: float) -> float:
    """atan(x), the same bits on every CPU (fdlibm's, within 1 ulp)."""
    a = abs(x)
    if not (a < EQ_ATAN_HUGE):  # |x| >= 2**66, or nan
        if math.isnan(a):
            return x
        return -EQ_ATANHI3 if x < 0.0 else EQ_ATANHI3
    if a < EQ_ATAN_7_16:
        if a < EQ_ATAN_TINY:
            return x
        return x - x * eq_katan(x)
    if a < EQ_ATAN_19_16:
        if a < EQ_ATAN_11_16:
            hi = EQ_ATANHI0
            lo = EQ_ATANLO0
            r = (2.0 * a - 1.0) / (2.0 + a)
        else:
            hi = EQ_ATANHI1
            lo = EQ_ATANLO1
            r = (a - 1.0) / (a + 1.0)
    elif a < EQ_ATAN_39_16:
        hi = EQ_ATANHI2
        lo = EQ_ATANLO2
        r = (a - 1.5) / (1.0 + 1.5 * a)
    else:
        hi = EQ_ATANHI3
        lo = EQ_ATANLO3
        r = -1.0 / a
    z = hi - (r * eq_katan(r) - lo - r)
    return -z if x < 0.0 else z


# ---8<--- end of libm atan


# ---8<--- libm tanh: copied into a generated module that calls eq_tanh

# fdlibm's tanh (s_tanh.c) over fdlibm's expm1 (s_expm1.c), as Sun wrote them (and glibc
# keeps them); ``math.ldexp`` (exact) scales by 2**k where fdlibm adds k to the exponent.
EQ_TANH_BIG = 22.0  # 0x40360000
EQ_TWO_M55 = 2.7755575615628914e-17  # 0x3c800000
EQ_EXPM1_HALF_LN2 = 0.3465735912322998  # |x| > 0.5 ln2: high word above 0x3fd62e42
EQ_EXPM1_3HALF_LN2 = 1.0397205352783203  # 0x3ff0a2b2: about 1.5 ln2
EQ_EXPM1_TINY = 5.551115123125783e-17  # 2**-54 (0x3c900000)
EQ_EXPM1_INVLN2 = 1.44269504088896338700e00
EQ_Q1 = -3.33333333333331316428e-02
EQ_Q2 = 1.58730158725481460165e-03
EQ_Q3 = -7.93650757867487942473e-05
EQ_Q4 = 4.00821782732936239552e-06
EQ_Q5 = -2.01099218183624371326e-07


def eq_expm1(x: float) -> float:
    """e**x - 1 for finite ``|x| < 56 ln2`` (fdlibm's expm1; the range tanh calls it in)."""
    a = abs(x)
    if a >= EQ_EXPM1_HALF_LN2:
        if a < EQ_EXPM1_3HALF_LN2:
            if x > 0.0:
                hi = x - EQ_LN2_HI
                lo = EQ_LN2_LO
                k = 1
            else:
                hi = x + EQ_LN2_HI
                lo = -EQ_LN2_LO
                k = -1
        else:
            k = int(EQ_EXPM1_INVLN2 * x + (0.5 if x > 0.0 else -0.5))  # C's (int): toward zero
            t = float(k)
            hi = x - t * EQ_LN2_HI  # exact
            lo = t * EQ_LN2_LO
        r = hi - lo
        c = (hi - r) - lo
    elif a < EQ_EXPM1_TINY:
        return x
    else:
        k = 0
        r = x
        c = 0.0
    hfx = 0.5 * r
    hxs = r * hfx
    r1 = 1.0 + hxs * (EQ_Q1 + hxs * (EQ_Q2 + hxs * (EQ_Q3 + hxs * (EQ_Q4 + hxs * EQ_Q5))))
    t = 3.0 - r1 * hfx
    e = hxs * ((r1 - t) / (6.0 - r * t))
    if k == 0:
        return r - (r * e - hxs)
    e = r * (e - c) - c
    e = e - hxs
    if k == -1:
        return 0.5 * (r - e) - 0.5
    if k == 1:
        if r < -0.25:
            return -2.0 * (e - (r + 0.5))
        return 1.0 + 2.0 * (r - e)
    if k <= -2 or k > 56:
        return math.ldexp(1.0 - (e - r), k) - 1.0
    if k < 20:
        return math.ldexp((1.0 - math.ldexp(1.0, -k)) - (e - r), k)
    return math.ldexp((r - (e + math.ldexp(1.0, -k))) + 1.0, k)


def eq_tanh(x: float) -> float:
    """tanh(x), the same bits on every CPU (fdlibm's)."""
    a = abs(x)
    if a < EQ_TANH_BIG:
        if a < EQ_TWO_M55:
            return x
        if a >= 1.0:
            t = eq_expm1(2.0 * a)
            z = 1.0 - 2.0 / (t + 2.0)
        else:
            t = eq_expm1(-2.0 * a)
            z = -t / (t + 2.0)
    elif math.isnan(a):
        return x
    else:
        z = 1.0
    return -z if x < 0.0 else z


# ---8<--- end of libm tanh


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


def source(section: str = "body") -> str:
    """A section above, as copied into a generated module: ``"body"`` (``sin``, ``cos``,
    ``log``: every module), ``"atan"`` or ``"tanh"`` (a module that calls ``eq_atan`` or
    ``eq_tanh``, after the body)."""
    if section not in SECTIONS:
        raise ValueError(f"no libm section {section!r}: expected one of {', '.join(SECTIONS)}")
    text = Path(__file__).read_text()
    start = text.index(f"\n{_MARKER if section == 'body' else '# ---8<--- libm ' + section}")
    start = text.index("\n", start + 1) + 1
    end = text.index(f"\n# ---8<--- end of libm {section}")
    return text[start:end].strip() + "\n"


sin = eq_sin
cos = eq_cos
log = eq_log
atan = eq_atan
tanh = eq_tanh


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


def c_source(prefix: str = "", *, log: bool = False, exp: bool = False, atan: bool = False,
             tanh: bool = False) -> str:
    """The same functions in C99, operation for operation (``static``; needs ``<math.h>``
    for ``fabs`` and ``frexp``, both exact).

    Compiled with ``-ffp-contract=off`` (no fused multiply-add; GCC's default in
    ISO C mode, not clang's) and without ``-ffast-math``, they give the bits of
    the Python version. *prefix* goes before each function's name;
    ``eq_log`` only with *log*, ``eq_exp`` with *exp*, ``eq_atan`` with *atan*, ``eq_tanh``
    with *tanh* (an unused static function is a warning).
    """
    body = _c_kernels(prefix) + _c_rem_pio2(prefix) + _c_sin_cos(prefix)
    head = ("/* sin, cos, log of equilibrist.numeric.libm (fdlibm's kernels, as in musl): the\n"
            " * simulation's bits on every CPU. Compile with -ffp-contract=off, never -ffast-math. */\n")
    return (head + _c_constants() + "\n" + body + (_c_log(prefix) if log else "")
            + (EXP_C.format(p=prefix) if exp else "") + (ATAN_C.format(p=prefix) if atan else "")
            + (TANH_C.format(p=prefix) if tanh else ""))


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


# The arctangent and tanh sections above, operation for operation.
ATAN_C = """
static double {p}eq_katan(double x)
{{
    double z = x * x;
    double w = z * z;
    double s1 = z * (EQ_AT0 + w * (EQ_AT2 + w * (EQ_AT4 + w * (EQ_AT6 + w * (EQ_AT8 + w * EQ_AT10)))));
    double s2 = w * (EQ_AT1 + w * (EQ_AT3 + w * (EQ_AT5 + w * (EQ_AT7 + w * EQ_AT9))));
    return s1 + s2;
}}

static double {p}eq_atan(double x)
{{
    double a = fabs(x);
    double hi, lo, r, z;
    if (!(a < EQ_ATAN_HUGE)) {{
        if (a != a) {{
            return x;
        }}
        return x < 0.0 ? -EQ_ATANHI3 : EQ_ATANHI3;
    }}
    if (a < EQ_ATAN_7_16) {{
        if (a < EQ_ATAN_TINY) {{
            return x;
        }}
        return x - x * {p}eq_katan(x);
    }}
    if (a < EQ_ATAN_19_16) {{
        if (a < EQ_ATAN_11_16) {{
            hi = EQ_ATANHI0;
            lo = EQ_ATANLO0;
            r = (2.0 * a - 1.0) / (2.0 + a);
        }} else {{
            hi = EQ_ATANHI1;
            lo = EQ_ATANLO1;
            r = (a - 1.0) / (a + 1.0);
        }}
    }} else if (a < EQ_ATAN_39_16) {{
        hi = EQ_ATANHI2;
        lo = EQ_ATANLO2;
        r = (a - 1.5) / (1.0 + 1.5 * a);
    }} else {{
        hi = EQ_ATANHI3;
        lo = EQ_ATANLO3;
        r = -1.0 / a;
    }}
    z = hi - (r * {p}eq_katan(r) - lo - r);
    return x < 0.0 ? -z : z;
}}
"""

TANH_C = """
static double {p}eq_expm1(double x)
{{
    double a = fabs(x);
    double hi, lo, r, c, t, hfx, hxs, r1, e;
    int k;
    if (a >= EQ_EXPM1_HALF_LN2) {{
        if (a < EQ_EXPM1_3HALF_LN2) {{
            if (x > 0.0) {{
                hi = x - EQ_LN2_HI;
                lo = EQ_LN2_LO;
                k = 1;
            }} else {{
                hi = x + EQ_LN2_HI;
                lo = -EQ_LN2_LO;
                k = -1;
            }}
        }} else {{
            k = (int)(EQ_EXPM1_INVLN2 * x + (x > 0.0 ? 0.5 : -0.5));
            t = (double)k;
            hi = x - t * EQ_LN2_HI;
            lo = t * EQ_LN2_LO;
        }}
        r = hi - lo;
        c = (hi - r) - lo;
    }} else if (a < EQ_EXPM1_TINY) {{
        return x;
    }} else {{
        k = 0;
        r = x;
        c = 0.0;
    }}
    hfx = 0.5 * r;
    hxs = r * hfx;
    r1 = 1.0 + hxs * (EQ_Q1 + hxs * (EQ_Q2 + hxs * (EQ_Q3 + hxs * (EQ_Q4 + hxs * EQ_Q5))));
    t = 3.0 - r1 * hfx;
    e = hxs * ((r1 - t) / (6.0 - r * t));
    if (k == 0) {{
        return r - (r * e - hxs);
    }}
    e = r * (e - c) - c;
    e = e - hxs;
    if (k == -1) {{
        return 0.5 * (r - e) - 0.5;
    }}
    if (k == 1) {{
        if (r < -0.25) {{
            return -2.0 * (e - (r + 0.5));
        }}
        return 1.0 + 2.0 * (r - e);
    }}
    if (k <= -2 || k > 56) {{
        return ldexp(1.0 - (e - r), k) - 1.0;
    }}
    if (k < 20) {{
        return ldexp((1.0 - ldexp(1.0, -k)) - (e - r), k);
    }}
    return ldexp((r - (e + ldexp(1.0, -k))) + 1.0, k);
}}

static double {p}eq_tanh(double x)
{{
    double a = fabs(x);
    double t, z;
    if (a < EQ_TANH_BIG) {{
        if (a < EQ_TWO_M55) {{
            return x;
        }}
        if (a >= 1.0) {{
            t = {p}eq_expm1(2.0 * a);
            z = 1.0 - 2.0 / (t + 2.0);
        }} else {{
            t = {p}eq_expm1(-2.0 * a);
            z = -t / (t + 2.0);
        }}
    }} else if (a != a) {{
        return x;
    }} else {{
        z = 1.0;
    }}
    return x < 0.0 ? -z : z;
}}
"""
