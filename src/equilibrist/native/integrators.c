/* The simulation core's generator and built-in integrators: the first part of its body
 * (core.c, which follows it in the unit): xoshiro256** with the polar method's normal
 * deviates, RK4 (with and without noise, and eq_rk4_plain: the noise-free step of
 * eq_run_plain), Dormand-Prince 5(4), and the exact step of the affine model.
 *
 * Each integrator's step of the table (equilibrist.sim.integrators, which writes the
 * dispatch eq_step after this file) takes the state, input, parameters and noise and an
 * eq_step_ctx: its work rows (EQ_<NAME>_<ROW>, named in that table) and what some of
 * them read besides. */

/* What a step may use besides x, u, p and the noise: work, the integrator's rows of
 * `width` doubles (width >= EQ_N); the run's tolerances (the adaptive integrator's); a
 * linear plant's operating point (state then input) and its [Phi | E | Gamma | f0]. */
typedef struct {
    double *work;
    int64_t width;
    double rtol, atol;
    const double *op;
    const double *lin;
} eq_step_ctx;

#define EQ_WORK(c, row) ((c)->work + (int64_t)(row) * (c)->width)

/* Dormand-Prince 5(4) tableau. */
#define EQ_A21 (1.0 / 5.0)
#define EQ_A31 (3.0 / 40.0)
#define EQ_A32 (9.0 / 40.0)
#define EQ_A41 (44.0 / 45.0)
#define EQ_A42 (-56.0 / 15.0)
#define EQ_A43 (32.0 / 9.0)
#define EQ_A51 (19372.0 / 6561.0)
#define EQ_A52 (-25360.0 / 2187.0)
#define EQ_A53 (64448.0 / 6561.0)
#define EQ_A54 (-212.0 / 729.0)
#define EQ_A61 (9017.0 / 3168.0)
#define EQ_A62 (-355.0 / 33.0)
#define EQ_A63 (46732.0 / 5247.0)
#define EQ_A64 (49.0 / 176.0)
#define EQ_A65 (-5103.0 / 18656.0)
#define EQ_B1 (35.0 / 384.0)
#define EQ_B3 (500.0 / 1113.0)
#define EQ_B4 (125.0 / 192.0)
#define EQ_B5 (-2187.0 / 6784.0)
#define EQ_B6 (11.0 / 84.0)
#define EQ_E1 (71.0 / 57600.0)
#define EQ_E3 (-71.0 / 16695.0)
#define EQ_E4 (71.0 / 1920.0)
#define EQ_E5 (-17253.0 / 339200.0)
#define EQ_E6 (22.0 / 525.0)
#define EQ_E7 (-1.0 / 40.0)
#define EQ_DOPRI_MAX_STEPS 100000
#define EQ_TWO_M53 (1.0 / 9007199254740992.0)

/* ---- xoshiro256** and Marsaglia's polar method ---- */
static inline uint64_t eq_rotl(uint64_t v, int k) { return (v << k) | (v >> (64 - k)); }

static inline uint64_t eq_next_u64(uint64_t *s)
{
    uint64_t result = eq_rotl(s[1] * 5u, 7) * 9u;
    uint64_t t = s[1] << 17;
    s[2] ^= s[0];
    s[3] ^= s[1];
    s[1] ^= s[2];
    s[0] ^= s[3];
    s[2] ^= t;
    s[3] = eq_rotl(s[3], 45);
    return result;
}

static inline double eq_uniform(uint64_t *s)
{
    return ((double)(eq_next_u64(s) >> 11) + 1.0) * EQ_TWO_M53;
}

static void eq_normals(uint64_t *s, double *out, int64_t count)
{
    int64_t i = 0;
    while (i < count) {
        double v1 = 2.0 * eq_uniform(s) - 1.0;
        double v2 = 2.0 * eq_uniform(s) - 1.0;
        double r2 = v1 * v1 + v2 * v2;
        double scale;
        if (r2 >= 1.0 || r2 == 0.0) {
            continue;
        }
        scale = sqrt(-2.0 * eq_log(r2) / r2);
        out[i] = v1 * scale;
        if (i + 1 < count) {
            out[i + 1] = v2 * scale;
        }
        i += 2;
    }
}

/* ---- integrators ---- */
static inline void eq_deriv(const double *x, const double *u, const double *p, const double *w,
                            double *out)
{
    int i;
    eq_f(x, u, p, out);
    for (i = 0; i < EQ_N; i++) {
        out[i] += w[i];
    }
}

/* Not flattened: inlining f (its sin and cos) into the four stages saves some 150
 * instructions a step (a batch about 20 % faster) but gives gcc a copy of f per stage and
 * path to compile, and a first run's core took 0.8 s more to build (a cold simulate 2.5 s
 * of CPU against the 2 s it is held to): the cold start is what every user waits for. */
static void
eq_rk4(double *restrict x, const double *restrict u, const double *restrict p,
       const double *restrict w, double h, double *restrict k1, double *restrict k2,
       double *restrict k3, double *restrict k4, double *restrict xt)
{
    int i;
    eq_f(x, u, p, k1);
    for (i = 0; i < EQ_N; i++) xt[i] = x[i] + 0.5 * h * (k1[i] + w[i]);
    eq_f(xt, u, p, k2);
    for (i = 0; i < EQ_N; i++) xt[i] = x[i] + 0.5 * h * (k2[i] + w[i]);
    eq_f(xt, u, p, k3);
    for (i = 0; i < EQ_N; i++) xt[i] = x[i] + h * (k3[i] + w[i]);
    eq_f(xt, u, p, k4);
    for (i = 0; i < EQ_N; i++) {
        x[i] += (h / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i] + 6.0 * w[i]);
    }
}

static void
eq_rk4_free(double *restrict x, const double *restrict u, const double *restrict p, double h,
            double *restrict k1, double *restrict k2, double *restrict k3,
            double *restrict k4, double *restrict xt)
{
    int i;
    eq_f(x, u, p, k1);
    for (i = 0; i < EQ_N; i++) xt[i] = x[i] + 0.5 * h * k1[i];
    eq_f(xt, u, p, k2);
    for (i = 0; i < EQ_N; i++) xt[i] = x[i] + 0.5 * h * k2[i];
    eq_f(xt, u, p, k3);
    for (i = 0; i < EQ_N; i++) xt[i] = x[i] + h * k3[i];
    eq_f(xt, u, p, k4);
    for (i = 0; i < EQ_N; i++) {
        x[i] += (h / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    }
}

/* Whether no component is -0.0 (compared as bits: one test a component). */
static inline int eq_no_negative_zero(const double *x)
{
    uint64_t any = 0;
    int i;
    for (i = 0; i < EQ_N; i++) {
        uint64_t b;
        memcpy(&b, &x[i], sizeof b);
        any |= (uint64_t)(b == UINT64_C(0x8000000000000000));
    }
    return any == 0;
}

static inline void eq_rk4_step(double *x, const double *u, const double *p, const double *w,
                               int64_t nw, double h, double *k1, double *k2, double *k3,
                               double *k4, double *xt)
{
    if (nw == 0 && eq_no_negative_zero(x)) {
        eq_rk4_free(x, u, p, h, k1, k2, k3, k4, xt);
    } else {
        eq_rk4(x, u, p, w, h, k1, k2, k3, k4, xt);
    }
}

/* eq_rk4_step without noise, its stages in local arrays (kept in registers, where the
 * stages read and write them) rather than in the run's scratch. */
static __attribute__((noinline)) void
eq_rk4_plain(double *restrict x, const double *restrict u, const double *restrict p, double h)
{
    double k1[EQ_N], k2[EQ_N], k3[EQ_N], k4[EQ_N], xt[EQ_N], w[EQ_N];
    int i;
    if (eq_no_negative_zero(x)) {
        eq_rk4_free(x, u, p, h, k1, k2, k3, k4, xt);
        return;
    }
    for (i = 0; i < EQ_N; i++) w[i] = 0.0;
    eq_rk4(x, u, p, w, h, k1, k2, k3, k4, xt);
}

/* Integrate over [0, h] with adaptive Dormand-Prince steps; 0 if it gives up. Its work
 * rows: the stages, the trial and the new state, and the step size to try next (set to the
 * period's h by eq_dopri_begin, carried from one call to the next within a period). */
static int eq_dopri(double *x, const double *u, const double *p, const double *w, double h,
                    double rtol, double atol, const eq_step_ctx *c)
{
    const int n = EQ_N;
    double *k1 = EQ_WORK(c, EQ_ADAPTIVE_K1), *k2 = EQ_WORK(c, EQ_ADAPTIVE_K2);
    double *k3 = EQ_WORK(c, EQ_ADAPTIVE_K3), *k4 = EQ_WORK(c, EQ_ADAPTIVE_K4);
    double *k5 = EQ_WORK(c, EQ_ADAPTIVE_K5), *k6 = EQ_WORK(c, EQ_ADAPTIVE_K6);
    double *k7 = EQ_WORK(c, EQ_ADAPTIVE_K7), *yt = EQ_WORK(c, EQ_ADAPTIVE_YT);
    double *yn = EQ_WORK(c, EQ_ADAPTIVE_YN), *hstate = EQ_WORK(c, EQ_ADAPTIVE_H_NEXT);
    double t = 0.0;
    double dt = eq_minf(hstate[0], h);
    long steps = 0;
    int i;
    eq_deriv(x, u, p, w, k1);
    while (t < h) {
        int last = 0;
        double err = 0.0;
        steps += 1;
        if (steps > EQ_DOPRI_MAX_STEPS) return 0;
        if (t + dt >= h * (1.0 - 1e-12)) {
            dt = h - t;
            last = 1;
        }
        for (i = 0; i < n; i++) yt[i] = x[i] + dt * EQ_A21 * k1[i];
        eq_deriv(yt, u, p, w, k2);
        for (i = 0; i < n; i++) yt[i] = x[i] + dt * (EQ_A31 * k1[i] + EQ_A32 * k2[i]);
        eq_deriv(yt, u, p, w, k3);
        for (i = 0; i < n; i++) {
            yt[i] = x[i] + dt * (EQ_A41 * k1[i] + EQ_A42 * k2[i] + EQ_A43 * k3[i]);
        }
        eq_deriv(yt, u, p, w, k4);
        for (i = 0; i < n; i++) {
            yt[i] = x[i] + dt * (EQ_A51 * k1[i] + EQ_A52 * k2[i] + EQ_A53 * k3[i]
                                 + EQ_A54 * k4[i]);
        }
        eq_deriv(yt, u, p, w, k5);
        for (i = 0; i < n; i++) {
            yt[i] = x[i] + dt * (EQ_A61 * k1[i] + EQ_A62 * k2[i] + EQ_A63 * k3[i]
                                 + EQ_A64 * k4[i] + EQ_A65 * k5[i]);
        }
        eq_deriv(yt, u, p, w, k6);
        for (i = 0; i < n; i++) {
            yn[i] = x[i] + dt * (EQ_B1 * k1[i] + EQ_B3 * k3[i] + EQ_B4 * k4[i]
                                 + EQ_B5 * k5[i] + EQ_B6 * k6[i]);
        }
        eq_deriv(yn, u, p, w, k7);
        for (i = 0; i < n; i++) {
            double e = dt * (EQ_E1 * k1[i] + EQ_E3 * k3[i] + EQ_E4 * k4[i] + EQ_E5 * k5[i]
                             + EQ_E6 * k6[i] + EQ_E7 * k7[i]);
            double sc = atol + rtol * eq_maxf(fabs(x[i]), fabs(yn[i]));
            double q = e / sc;
            err += q * q;
        }
        err = sqrt(err / (double)n);
        if (!isfinite(err)) {
            dt *= 0.2;
            if (dt < h * 1e-14) return 0;
            continue;
        }
        if (err <= 1.0) {
            double fac;
            t = last ? h : t + dt;
            for (i = 0; i < n; i++) {
                x[i] = yn[i];
                k1[i] = k7[i];
            }
            fac = err == 0.0 ? 5.0 : eq_minf(5.0, eq_maxf(0.2, 0.9 * eq_exp(-0.2 * eq_log(err))));
            if (!last) hstate[0] = dt * fac;
            dt = dt * fac;
        } else {
            dt *= eq_maxf(0.2, 0.9 * eq_exp(-0.2 * eq_log(err)));
            if (dt < h * 1e-14) return 0;
        }
    }
    return 1;
}

/* Exact step of the affine model dx' = A dx + B du + f0 + w (held u, w); lin is
 * [Phi | E | Gamma | f0], n rows of 2n + m + 1. */
static inline void eq_linear(double *x, const double *u, const double *op, const double *w,
                             const double *lin, double *dx)
{
    const int n = EQ_N, m = EQ_M, cols = 2 * EQ_N + EQ_M + 1;
    int i, j;
    for (i = 0; i < n; i++) dx[i] = x[i] - op[i];
    for (i = 0; i < n; i++) {
        double v = 0.0;
        for (j = 0; j < n; j++) {
            v += lin[i * cols + j] * dx[j] + lin[i * cols + n + j] * (lin[j * cols + 2 * n + m] + w[j]);
        }
        for (j = 0; j < m; j++) {
            v += lin[i * cols + 2 * n + j] * (u[j] - op[n + j]);
        }
        x[i] = op[i] + v;
    }
}

/* ---- the table's steps (equilibrist.sim.integrators: their signatures) ---- */
static inline int eq_rk4_step_ctx(double *x, const double *u, const double *p, const double *w,
                                  int64_t nw, double h, const eq_step_ctx *c)
{
    eq_rk4_step(x, u, p, w, nw, h, EQ_WORK(c, EQ_RK4_K1), EQ_WORK(c, EQ_RK4_K2),
                EQ_WORK(c, EQ_RK4_K3), EQ_WORK(c, EQ_RK4_K4), EQ_WORK(c, EQ_RK4_XT));
    return 1;
}

static inline void eq_rk4_free_ctx(double *x, const double *u, const double *p, double h,
                                   const eq_step_ctx *c)
{
    eq_rk4_free(x, u, p, h, EQ_WORK(c, EQ_RK4_K1), EQ_WORK(c, EQ_RK4_K2),
                EQ_WORK(c, EQ_RK4_K3), EQ_WORK(c, EQ_RK4_K4), EQ_WORK(c, EQ_RK4_XT));
}

static inline int eq_dopri_step(double *x, const double *u, const double *p, const double *w,
                                int64_t nw, double h, const eq_step_ctx *c)
{
    (void)nw;
    return eq_dopri(x, u, p, w, h, c->rtol, c->atol, c);
}

static inline void eq_dopri_begin(double h, const eq_step_ctx *c)
{
    EQ_WORK(c, EQ_ADAPTIVE_H_NEXT)[0] = h;
}

static inline int eq_linear_step(double *x, const double *u, const double *p, const double *w,
                                 int64_t nw, double h, const eq_step_ctx *c)
{
    (void)p;
    (void)nw;
    (void)h;
    eq_linear(x, u, c->op, w, c->lin, EQ_WORK(c, EQ_LINEAR_DX));
    return 1;
}
