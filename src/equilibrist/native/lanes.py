"""Eight copies at once: the vector environment's physics in GCC's vector types.

A vector environment steps thousands of copies of one rig through the same
arithmetic. Its core (:func:`equilibrist.sim.simcore.load_core` with
``lanes=True``) steps them :data:`LANES` at a time: the rig's dynamics ``f``
and the RK4 stages run on ``eqv`` values, eight doubles side by side, which
the compiler maps to one AVX-512 register, two AVX2 or four SSE2 ones
(``target_clones``: the machine's best, chosen when the library loads).
The lanes step RK4 only (``env.c``'s ``eqv_rk4``): the integrators' table
(:mod:`equilibrist.sim.integrators`) says so (``lanes``), and a vector
environment with another integrator steps its copies one at a time.

The bits are those of one copy at a time, on every CPU: each lane performs the
same IEEE operations in the same order as the scalar code (GCC's vector
operators are element-wise; no contraction, ``-ffp-contract=off``), so a lane
is the scalar translation of ``f`` with its doubles widened. This module
makes that widened function from the scalar C that :mod:`~equilibrist.native.pyc`
writes, and refuses (returns None: the copies then run one at a time, as
before) any ``f`` that is not straight-line arithmetic with the project's
``eq_sin``/``eq_cos``: a branch, a loop or another call would not be the
same in lanes.

``eqv_sin``/``eqv_cos`` run fdlibm's kernel on all eight lanes when every
lane is in its first range (``|x| < pi/4``, the balancing rigs' angles) and
``eq_sin``/``eq_cos`` lane by lane otherwise; their kernels are those of
:func:`equilibrist.numeric.libm.c_source`, operation for operation (a test
compares the bits over every range).
"""

from __future__ import annotations

import re

from equilibrist.native import pyc
from equilibrist.numeric.libm import kernel_c

#: Copies stepped at once (eight doubles: one AVX-512 register).
LANES = 8

_HEAD = re.compile(r"^static inline void (\w+)\((.*)\)$")
_CALL = re.compile(r"\b([A-Za-z_]\w*)\s*\(")
_ALLOWED_CALLS = {"eqv_sin", "eqv_cos", "INT64_C"}

#: What the lanes are compiled for (GCC's vector operations on eight doubles are one
#: instruction each there; for an older target GCC splits its comparisons lane by lane).
#: Everything between EQ_LANES_PUSH and EQ_LANES_POP is: the code below, and env.c's block.
TARGET = "arch=x86-64-v4"
_PUSH_POP = (
    f'#define EQ_LANES_PUSH _Pragma("GCC push_options") _Pragma("GCC target(\\"{TARGET}\\")")\n'
    '#define EQ_LANES_POP _Pragma("GCC pop_options")\n'
)

#: The lanes' types, their libm kernels and their sine and cosine (after libm's C, which
#: defines the EQ_* constants and eq_sin/eq_cos).
PRELUDE = f"""
#define EQ_LANES {LANES}
/* Whether this CPU runs the lanes (AVX-512, x86-64-v4), asked once. */
static int eq_lanes_usable(void)
{{
    static int usable = -1;
    if (usable < 0) {{
        __builtin_cpu_init();
        usable = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq") &&
                 __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512bw");
    }}
    return usable;
}}
EQ_LANES_PUSH
typedef double eqv __attribute__((vector_size({LANES * 8})));
typedef int64_t eqvi __attribute__((vector_size({LANES * 8})));
#define EQ_INLINE static inline __attribute__((always_inline))

/* libm's eq_ksin(x, 0.0, 0) and eq_kcos(x, y), lane by lane. */
EQ_INLINE eqv eqv_ksin0(eqv x)
{{
{kernel_c("sin_poly", "eqv")}
    return {kernel_c("sin_small")};
}}

EQ_INLINE eqv eqv_kcos(eqv x, eqv y)
{{
{kernel_c("cos", "eqv")}
}}

EQ_INLINE eqv eqv_ksin(eqv x, eqv y)
{{
{kernel_c("sin_poly", "eqv")}
    return {kernel_c("sin_tail")};
}}

EQ_INLINE eqv eqv_pick(eqvi m, eqv a, eqv b) {{ return (eqv)(((eqvi)a & m) | ((eqvi)b & ~m)); }}

EQ_INLINE int eqv_any(eqvi m)
{{
    int64_t any = 0;
    int l;
    for (l = 0; l < EQ_LANES; l++) any |= m[l];
    return any != 0;
}}

EQ_INLINE eqv eqv_abs(eqv x) {{ return (eqv)((eqvi)x & INT64_C(0x7fffffffffffffff)); }}

/* libm's eq_rem_pio2 on every lane, its first step (and its one correction): 0 when a lane
 * would take its second or third step (|x| near a multiple of pi/2) or is too large, and
 * then eq_sin/eq_cos run lane by lane. */
EQ_INLINE int eqv_rem_pio2(eqv x, eqv *y0, eqv *y1, eqvi *q)
{{
    eqv fn = x * EQ_INVPIO2 + EQ_TOINT - EQ_TOINT;
    eqv r = x - fn * EQ_PIO2_1;
    eqv w = fn * EQ_PIO2_1T;
    const eqvi low = r - w < -EQ_PIO4, high = r - w > EQ_PIO4;
    eqvi cancel;
    if (eqv_any(low | high)) {{
        const eqv down = fn - 1.0, up = fn + 1.0;
        fn = eqv_pick(low, down, eqv_pick(high, up, fn));
        r = eqv_pick(low | high, x - fn * EQ_PIO2_1, r);
        w = eqv_pick(low | high, fn * EQ_PIO2_1T, w);
    }}
    *y0 = r - w;
    cancel = eqv_abs(*y0) < eqv_abs(x) * EQ_TWO_M16;
    if (eqv_any(cancel)) return 0;
    *y1 = (r - *y0) - w;
    *q = __builtin_convertvector(fn, eqvi) & 3;
    return 1;
}}

/* eq_sin and eq_cos of every lane, together (they share the reduction and its kernels):
 * the first range's kernels, else the reduction's, picked lane by lane (all exact); lane
 * by lane through eq_sin/eq_cos where a lane is not finite, beyond 1e6, or near a multiple
 * of pi/2. */
EQ_INLINE void eqv_sincos(eqv x, eqv *sin_out, eqv *cos_out)
{{
    const eqv zero = {{0.0}}, one = zero + 1.0;
    const eqv a = eqv_abs(x);
    const eqvi first = a < EQ_PIO4_HI;
    eqv y0, y1, s, c, k;
    eqvi q;
    int l;
    if (!eqv_any(~first)) {{
        *sin_out = eqv_pick(a < EQ_SIN_TINY, x, eqv_ksin0(x));
        *cos_out = eqv_pick(a < EQ_COS_TINY, one, eqv_kcos(x, zero));
        return;
    }}
    if (!eqv_any(~(a < 1e6)) && eqv_rem_pio2(x, &y0, &y1, &q)) {{
        s = eqv_ksin(y0, y1);
        c = eqv_kcos(y0, y1);
        k = eqv_pick((q & 1) != 0, c, s);
        k = eqv_pick(q >= 2, -k, k);
        *sin_out = eqv_pick(first, eqv_pick(a < EQ_SIN_TINY, x, eqv_ksin0(x)), k);
        k = eqv_pick((q & 1) != 0, s, c);
        k = eqv_pick((q == 1) | (q == 2), -k, k);
        *cos_out = eqv_pick(first, eqv_pick(a < EQ_COS_TINY, one, eqv_kcos(x, zero)), k);
        return;
    }}
    for (l = 0; l < EQ_LANES; l++) {{
        s[l] = eq_sin(x[l]);
        c[l] = eq_cos(x[l]);
    }}
    *sin_out = s;
    *cos_out = c;
}}

EQ_INLINE eqv eqv_sin(eqv x)
{{
    eqv s, c;
    eqv_sincos(x, &s, &c);
    return s;
}}

EQ_INLINE eqv eqv_cos(eqv x)
{{
    eqv s, c;
    eqv_sincos(x, &s, &c);
    return c;
}}
"""


def widen(function: pyc.Function) -> str | None:
    """The lane version ``<name>_lanes`` of a translated ``void`` function of double arrays
    whose body is straight-line arithmetic with ``eq_sin``/``eq_cos``; None otherwise."""
    lines = function.source.strip().split("\n")
    head = _HEAD.match(lines[0])
    if head is None or lines[1] != "{" or lines[-1] != "}":
        return None
    params = head.group(2).replace("double *", "eqv *")
    body = []
    for line in lines[2:-1]:
        text = re.sub(r"^(\s*)double (v_\w+) = 0;$", r"\1eqv \2 = {0.0};", line)
        text = re.sub(r"^(\s*)const double ", r"\1const eqv ", text)
        text = text.replace("eq_sin(", "eqv_sin(").replace("eq_cos(", "eqv_cos(")
        rest = text.replace("(double)INT64_C(", "INT64_C(")  # integer literals stay scalars
        if "double" in rest or re.search(r"\b(if|for|while|return|switch|goto)\b", rest):
            return None
        if any(name not in _ALLOWED_CALLS for name in _CALL.findall(rest)):
            return None
        body.append(text)
    return "\n".join([f"EQ_INLINE void {head.group(1)}_lanes({params})", "{", *_shared(body),
                      "}"])


def _shared(body: list[str]) -> list[str]:
    """*body* with the sine and the cosine of one variable computed together
    (``eqv_sincos``), where the variable is assigned once, before both."""
    out = list(body)
    for name in sorted(set(re.findall(r"eqv_sin\((v_\w+)\)", "\n".join(body)))):
        uses = [i for i, line in enumerate(out)
                if f"eqv_sin({name})" in line or f"eqv_cos({name})" in line]
        sets = [i for i, line in enumerate(out) if re.match(rf"\s*{name} = ", line)]
        if not any(f"eqv_cos({name})" in out[i] for i in uses) or len(sets) != 1 \
                or sets[0] > uses[0]:
            continue
        s, c = f"_sin_{name}", f"_cos_{name}"
        for i in uses:
            out[i] = out[i].replace(f"eqv_sin({name})", s).replace(f"eqv_cos({name})", c)
        out.insert(uses[0], f"    eqv {s}, {c};\n    eqv_sincos({name}, &{s}, &{c});")
    return out


def source(f: pyc.Function) -> str:
    """The lanes' section of a core whose dynamics are *f* (its ``EQ_F_LANES``), or an
    empty text when *f* cannot be widened (the copies then run one at a time)."""
    lanes = widen(f)
    if lanes is None:
        return ""
    return ("#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)\n"
            + _PUSH_POP + PRELUDE + "\n" + lanes + "\nEQ_LANES_POP\n"
            f"#define EQ_F_LANES(x, u, p, out) {f.name}_lanes(x, EQ_N, u, EQ_M, p, EQ_NP, out, EQ_N)\n"
            "#endif\n")


__all__ = ["LANES", "PRELUDE", "source", "widen"]
