/* The environments' steps (equilibrist.envs), appended to the simulation core's body.
 *
 * A control period of an environment is, number for number, a sample of
 * `simulate` with a Python controller: zero-order hold of the saturated
 * input, physics steps of the environment's integrator (EQ_CI_INTEGRATOR, a
 * number of equilibrist.sim.integrators' table) with process noise held over each, the region
 * checked after each physics step, the sensors read with noise at the next
 * sample. Every entry takes the same few arrays:
 *
 *   fs (copies, n + n_p + 2) double: per copy [x | p | energy upright, energy hanging]
 *   us (copies, 6) uint64: per copy [xoshiro256** words (4) | periods taken | autoreset due]
 *   cf double and ci int64: the settings written by equilibrist.envs.core; ci's head
 *     holds the sizes and the offsets of cf's blocks and of ci's own index blocks
 *     (slots EQ_CI_*, EQ_CF_*, EQ_US_* from equilibrist.sim.layout).
 *
 * A copy's step status: 0 running, 1 fell (terminated), 2 out of time (truncated).
 * The unit defines eq_energy(x, p) (the system's energy) before this body.
 */

/* Scratch rows of `width` (layout.ENV_SCRATCH's; the last, work, starts the integrator's). */
#define EQ_ENV_SCR (EQ_ES_WORK + EQ_STEP_ROWS)
/* A parallel step gives each block of copies scratch at least this many doubles apart
 * (two cache lines): scratch written by two threads in one line would bounce it. */
#define EQ_ENV_GAP 16

typedef struct {
    int64_t n_sub, n_samples, observe_state, reward, physical, autoreset, ny, nw, nlv, np;
    int64_t nhang, integrator;
    double h, dt, bonus, rtol, atol;
    const double *region; /* 2 x n: lower bounds, upper bounds */
    const double *op;     /* state then input */
    const double *iscale; /* 1 / scales: state then input */
    const int64_t *c_idx;
    const int64_t *hang;
    const double *lv; /* ny x ny */
    const double *lw; /* n x nw */
} eq_env;

static void eq_env_settings(const double *cf, const int64_t *ci, eq_env *S)
{
    S->n_sub = ci[EQ_CI_N_SUB];
    S->n_samples = ci[EQ_CI_N_SAMPLES];
    S->observe_state = ci[EQ_CI_OBSERVE_STATE];
    S->reward = ci[EQ_CI_REWARD];
    S->physical = ci[EQ_CI_PHYSICAL];
    S->autoreset = ci[EQ_CI_AUTORESET];
    S->ny = ci[EQ_CI_NY];
    S->nw = ci[EQ_CI_NW];
    S->nlv = ci[EQ_CI_NLV];
    S->np = ci[EQ_CI_NP];
    S->nhang = ci[EQ_CI_NHANG];
    S->integrator = ci[EQ_CI_INTEGRATOR];
    S->h = cf[EQ_CF_H];
    S->dt = cf[EQ_CF_DT];
    S->bonus = cf[EQ_CF_BONUS];
    S->rtol = cf[EQ_CF_RTOL];
    S->atol = cf[EQ_CF_ATOL];
    S->region = cf + ci[EQ_CI_O_REGION];
    S->op = cf + ci[EQ_CI_O_OP];
    S->iscale = cf + ci[EQ_CI_O_ISCALE];
    S->c_idx = ci + ci[EQ_CI_O_C_IDX];
    S->hang = ci + ci[EQ_CI_O_HANG];
    S->lv = cf + ci[EQ_CI_O_LV];
    S->lw = cf + ci[EQ_CI_O_LW];
}

static int64_t eq_env_width(const int64_t *ci)
{
    int64_t w = EQ_N;
    w = w > EQ_M ? w : EQ_M;
    w = w > ci[EQ_CI_NY] ? w : ci[EQ_CI_NY];
    w = w > ci[EQ_CI_NW] ? w : ci[EQ_CI_NW];
    return w + 2;
}

static inline int64_t eq_env_fs_width(const int64_t *ci) { return EQ_N + ci[EQ_CI_NP] + 2; }

/* orow: the state, or the measured outputs with sensor noise (as eq_measure). The sensor
 * noise is drawn either way, so an environment observing the state follows the same run. */
static void eq_env_observe(const double *x, uint64_t *rng, double *orow, const eq_env *S,
                           double *zbuf)
{
    int64_t i, j, c;
    if (S->nlv > 0) eq_normals(rng, zbuf, S->ny);
    if (S->observe_state != 0) {
        for (i = 0; i < EQ_N; i++) orow[i] = x[i];
        return;
    }
    for (j = 0; j < S->ny; j++) {
        double y = x[S->c_idx[j]];
        if (S->nlv > 0) {
            double v = 0.0;
            for (c = 0; c < S->ny; c++) v += S->lv[j * S->ny + c] * zbuf[c];
            y += v;
        }
        orow[j] = y;
    }
}

/* The saturated input of action a (limits from p, as the core saturates). */
static void eq_env_input(const double *a, const double *p, int64_t np_, int64_t physical,
                         double *u)
{
    const int64_t base = np_ - 2 * EQ_M;
    int i;
    for (i = 0; i < EQ_M; i++) {
        double lo = p[base + 2 * i];
        double hi = p[base + 2 * i + 1];
        double v = physical != 0 ? a[i] : lo + 0.5 * (a[i] + 1.0) * (hi - lo);
        u[i] = eq_minf(eq_maxf(v, lo), hi);
    }
}

/* One control period; the region code at a fall (-2 not finite, -3 the integrator failed:
 * the last state before it kept), else -1. w is zero on entry and stays so without process
 * noise; work: the integrator's rows of `width`. */
static int64_t eq_env_physics(double *x, const double *u, const double *p, uint64_t *rng,
                              const eq_env *S, double *w, double *zbuf, double *xprev,
                              double *work, int64_t width)
{
    int64_t s, i, c;
    eq_step_ctx ctx;
    ctx.work = work;
    ctx.width = width;
    ctx.rtol = S->rtol;
    ctx.atol = S->atol;
    ctx.op = S->op;
    ctx.lin = NULL;
    eq_step_begin(S->integrator, S->h, &ctx);
    for (s = 0; s < S->n_sub; s++) {
        int64_t code;
        if (S->nw > 0) {
            eq_normals(rng, zbuf, S->nw);
            for (i = 0; i < EQ_N; i++) {
                double v = 0.0;
                for (c = 0; c < S->nw; c++) v += S->lw[i * S->nw + c] * zbuf[c];
                w[i] = v;
            }
        }
        for (i = 0; i < EQ_N; i++) xprev[i] = x[i];
        code = eq_step(S->integrator, x, u, p, w, S->nw, S->h, &ctx) ? eq_outside(x, S->region)
                                                                       : -3;
        if (code != -1) {
            if (code < -1) {
                for (i = 0; i < EQ_N; i++) x[i] = xprev[i];
            }
            return code;
        }
    }
    return -1;
}

/* Reward of a period ending in x with u applied: the task's own reward function (its
 * Python source in equilibrist.tasks, translated into this unit: eq_task_reward). eref:
 * the energies at the operating point and at the task's start. */
static double eq_env_reward(const double *x, const double *u, const double *p,
                            const double *eref, const eq_env *S)
{
    return eq_task_reward(S->reward, x, u, p, S->op, S->iscale, S->hang, S->nhang, eref, S->dt,
                          S->bonus);
}

/* Start copy r's episode from the state and parameters in its row: the shaping's reference
 * energies, the step count, the first observation. */
static void eq_env_begin(int64_t r, double *fs, uint64_t *us, double *orow, const double *cf,
                         const int64_t *ci, double *zbuf)
{
    const int64_t np_ = ci[EQ_CI_NP], fw = eq_env_fs_width(ci);
    double *row = fs + r * fw;
    uint64_t *urow = us + r * EQ_US_WIDTH;
    eq_env S;
    row[EQ_N + np_] = eq_energy(cf + ci[EQ_CI_O_OP], row + EQ_N);
    row[EQ_N + np_ + 1] = eq_energy(cf + ci[EQ_CI_O_START], row + EQ_N);
    urow[EQ_US_K] = 0;
    urow[EQ_US_AUTO] = 0;
    eq_env_settings(cf, ci, &S);
    eq_env_observe(row, urow, orow, &S, zbuf);
}

/* Copy r's start from the task's distribution and its randomized parameters, drawn from
 * its own generator. */
static void eq_env_draw(int64_t r, double *fs, uint64_t *us, const double *cf,
                        const int64_t *ci)
{
    const int64_t fw = eq_env_fs_width(ci);
    double *row = fs + r * fw;
    uint64_t *rng = us + r * EQ_US_WIDTH;
    const int64_t o_st = ci[EQ_CI_O_START], o_sp = ci[EQ_CI_O_SPREAD];
    const int64_t o_pn = ci[EQ_CI_O_P_NOM], np_ = ci[EQ_CI_NP];
    const int64_t o_ri = ci[EQ_CI_O_RND_IDX], o_rs = ci[EQ_CI_O_RND_SPREAD];
    int64_t i, j;
    for (i = 0; i < EQ_N; i++) {
        row[i] = cf[o_st + i] + (2.0 * eq_uniform(rng) - 1.0) * cf[o_sp + i];
    }
    for (i = 0; i < np_; i++) row[EQ_N + i] = cf[o_pn + i];
    for (j = 0; j < ci[EQ_CI_NRND]; j++) {
        int64_t q = ci[o_ri + j];
        row[EQ_N + q] = cf[o_pn + q] * (1.0 + (2.0 * eq_uniform(rng) - 1.0) * cf[o_rs + j]);
    }
}

/* The end of copy r's period, its physics done (code: the region's, -1 inside): the step
 * count, the observation, the reward, and *status. */
static double eq_env_finish(double *row, const double *u, uint64_t *urow, double *orow,
                            const eq_env *S, double *zbuf, int64_t code, int *status)
{
    const int64_t k = (int64_t)urow[EQ_US_K] + 1;
    double reward;
    urow[EQ_US_K] = (uint64_t)k;
    eq_env_observe(row, urow, orow, S, zbuf);
    reward = eq_env_reward(row, u, row + EQ_N, row + EQ_N + S->np, S);
    *status = code != -1 ? 1 : (k >= S->n_samples ? 2 : 0);
    if (*status != 0 && S->autoreset != 0) urow[EQ_US_AUTO] = 1;
    return reward;
}

/* One control period of copy r with action a: the reward, and *status. A copy whose
 * episode ended at its previous step (autoreset due) is reset instead: its action is
 * ignored, its reward is 0. scr: EQ_ENV_SCR rows of `width`. */
static double eq_env_step_copy(int64_t r, const double *a, double *fs, uint64_t *us,
                               double *orow, const double *cf, const int64_t *ci,
                               const eq_env *S, double *scr, int64_t width, int *status)
{
    const int64_t fw = eq_env_fs_width(ci);
    double *u = scr + EQ_ES_U * width, *w = scr + EQ_ES_W * width;
    double *zbuf = scr + EQ_ES_ZBUF * width, *xprev = scr + EQ_ES_XPREV * width;
    double *row = fs + r * fw;
    uint64_t *urow = us + r * EQ_US_WIDTH;
    int64_t code;
    if (urow[EQ_US_AUTO] != 0) {
        eq_env_draw(r, fs, us, cf, ci);
        eq_env_begin(r, fs, us, orow, cf, ci, zbuf);
        *status = 0;
        return 0.0;
    }
    eq_env_input(a, row + EQ_N, S->np, S->physical, u);
    code = eq_env_physics(row, u, row + EQ_N, urow, S, w, zbuf, xprev, scr + EQ_ES_WORK * width,
                          width);
    return eq_env_finish(row, u, urow, orow, S, zbuf, code, status);
}

#ifdef EQ_LANES
EQ_LANES_PUSH
/* eq_rk4 on EQ_LANES copies at once, the same operations lane by lane. It also gives
 * eq_rk4_free's bits where the scalar step takes that one (no noise, no -0.0 in the state):
 * adding the zero noise changes only the sign of a zero sum, and a zero sum then added to a
 * state component that is not -0.0 gives the same bits either way. */
EQ_INLINE void eqv_rk4(eqv *x, eqv *u, eqv *p, const eqv *w, double h)
{
    eqv k1[EQ_N], k2[EQ_N], k3[EQ_N], k4[EQ_N], xt[EQ_N];
    int i;
    EQ_F_LANES(x, u, p, k1);
    for (i = 0; i < EQ_N; i++) xt[i] = x[i] + 0.5 * h * (k1[i] + w[i]);
    EQ_F_LANES(xt, u, p, k2);
    for (i = 0; i < EQ_N; i++) xt[i] = x[i] + 0.5 * h * (k2[i] + w[i]);
    EQ_F_LANES(xt, u, p, k3);
    for (i = 0; i < EQ_N; i++) xt[i] = x[i] + h * (k3[i] + w[i]);
    EQ_F_LANES(xt, u, p, k4);
    for (i = 0; i < EQ_N; i++) {
        x[i] += (h / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i] + 6.0 * w[i]);
    }
}

/* One control period of the EQ_LANES copies from r0, their physics in lanes: the same
 * numbers as eq_env_step_copy on each (its noise drawn from each copy's generator, its
 * substeps stopped at its fall). A copy whose autoreset is due is reset, as there. Lanes
 * that do not step (fallen, reset) compute on a stepping lane's numbers, which are
 * dropped: an angle past pi/4 in a fallen copy would send the sines lane by lane. */
static void eq_env_block(int64_t r0, const double *actions, double *fs, uint64_t *us,
                         double *obs, int64_t n_obs, double *rewards, uint8_t *flags,
                         int64_t n_copies, const double *cf, const int64_t *ci, const eq_env *S,
                         double *scr, int64_t width)
{
    const int64_t fw = eq_env_fs_width(ci);
    double *zbuf = scr + EQ_ES_ZBUF * width;
    eqv x[EQ_N], xprev[EQ_N], u[EQ_M], p[EQ_NP], w[EQ_N];
    double uu[EQ_LANES][EQ_M > 0 ? EQ_M : 1], xl[EQ_N];
    const eqv zero = {0.0};
    int64_t code[EQ_LANES];
    eqvi inside;
    int stepping[EQ_LANES], reset[EQ_LANES], l, i, j, c, s, lead = -1;
    for (l = 0; l < EQ_LANES; l++) {
        const int64_t r = r0 + l;
        double *row = fs + r * fw;
        code[l] = -1;
        reset[l] = us[r * EQ_US_WIDTH + EQ_US_AUTO] != 0;
        stepping[l] = !reset[l];
        if (reset[l]) {
            int st;
            rewards[r] = eq_env_step_copy(r, actions + r * EQ_M, fs, us, obs + r * n_obs, cf,
                                          ci, S, scr, width, &st);
            flags[r] = 0;
            flags[n_copies + r] = 0;
            continue;
        }
        if (lead < 0) lead = l;
        eq_env_input(actions + r * EQ_M, row + EQ_N, S->np, S->physical, uu[l]);
        for (i = 0; i < EQ_N; i++) x[i][l] = row[i];
        for (j = 0; j < EQ_NP; j++) p[j][l] = row[EQ_N + j];
        for (j = 0; j < EQ_M; j++) u[j][l] = uu[l][j];
    }
    for (s = 0; s < S->n_sub && lead >= 0; s++) {
        for (l = 0; l < EQ_LANES; l++) {
            if (stepping[l]) continue;
            for (i = 0; i < EQ_N; i++) x[i][l] = x[i][lead];
            for (j = 0; j < EQ_NP; j++) p[j][l] = p[j][lead];
            for (j = 0; j < EQ_M; j++) u[j][l] = u[j][lead];
        }
        for (i = 0; i < EQ_N; i++) w[i] = zero;
        for (l = 0; l < EQ_LANES && S->nw > 0; l++) {
            if (!stepping[l]) continue;
            eq_normals(us + (r0 + l) * EQ_US_WIDTH, zbuf, S->nw);
            for (i = 0; i < EQ_N; i++) {
                double v = 0.0;
                for (c = 0; c < S->nw; c++) v += S->lw[i * S->nw + c] * zbuf[c];
                w[i][l] = v;
            }
        }
        for (i = 0; i < EQ_N; i++) xprev[i] = x[i];
        eqv_rk4(x, u, p, w, S->h);
        lead = -1;
        inside = (x[0] > S->region[0]) & (x[0] < S->region[EQ_N]);
        for (i = 1; i < EQ_N; i++) inside &= (x[i] > S->region[i]) & (x[i] < S->region[EQ_N + i]);
        for (l = 0; l < EQ_LANES; l++) {
            double *row = fs + (r0 + l) * fw;
            int64_t at;
            if (!stepping[l]) continue;
            if (inside[l]) { /* eq_outside's first pass, on every lane at once */
                if (lead < 0) lead = l;
                continue;
            }
            for (i = 0; i < EQ_N; i++) xl[i] = x[i][l];
            at = eq_outside(xl, S->region);
            if (at == -1) {
                if (lead < 0) lead = l;
                continue;
            }
            for (i = 0; i < EQ_N; i++) row[i] = at == -2 ? xprev[i][l] : xl[i];
            code[l] = at;
            stepping[l] = 0;
        }
    }
    for (l = 0; l < EQ_LANES; l++) {
        const int64_t r = r0 + l;
        double *row = fs + r * fw;
        int st;
        if (reset[l]) continue;
        if (stepping[l]) {
            for (i = 0; i < EQ_N; i++) row[i] = x[i][l];
        }
        rewards[r] = eq_env_finish(row, uu[l], us + r * EQ_US_WIDTH, obs + r * n_obs, S, zbuf,
                                   code[l], &st);
        flags[r] = st == 1;
        flags[n_copies + r] = st == 2;
    }
}
EQ_LANES_POP
#endif

/* How many actions are not finite numbers (then no copy is stepped). */
static int64_t eq_env_bad_actions(const double *actions, int64_t count)
{
    int64_t i, bad = 0;
    for (i = 0; i < count; i++) {
        if (!isfinite(actions[i])) bad += 1;
    }
    return bad;
}

static void eq_env_step_range(int64_t lo, int64_t hi, const double *actions, double *fs,
                              uint64_t *us, double *obs, int64_t n_obs, double *rewards,
                              uint8_t *flags, int64_t n_copies, const double *cf,
                              const int64_t *ci, double *scr, int64_t width)
{
    eq_env S;
    int64_t r = lo;
    eq_env_settings(cf, ci, &S);
#ifdef EQ_LANES
    if (S.np == EQ_NP && eq_int_lanes(S.integrator) && eq_lanes_usable()) {
        for (; r + EQ_LANES <= hi; r += EQ_LANES) {
            eq_env_block(r, actions, fs, us, obs, n_obs, rewards, flags, n_copies, cf, ci, &S, scr,
                         width);
        }
    }
#endif
    for (; r < hi; r++) {
        int status;
        rewards[r] = eq_env_step_copy(r, actions + r * EQ_M, fs, us, obs + r * n_obs, cf, ci,
                                      &S, scr, width, &status);
        flags[r] = status == 1;
        flags[n_copies + r] = status == 2;
    }
}

/* One control period of every copy, in `chunks` contiguous blocks of copies run in
 * parallel; Gymnasium's next-step autoreset. flags: (2, copies) bytes, terminated then
 * truncated. Returns the number of actions that are not finite numbers (then nothing is
 * done), or -1 when out of memory. */
EQ_EXPORT int64_t eq_env_step_many(const double *actions, double *fs, uint64_t *us, double *obs,
                                   int64_t n_obs, double *rewards, uint8_t *flags,
                                   int64_t n_copies, const double *cf, const int64_t *ci,
                                   int64_t chunks)
{
    const int64_t width = eq_env_width(ci);
    const int64_t stride = EQ_ENV_SCR * width + EQ_ENV_GAP;
    int64_t bad = eq_env_bad_actions(actions, n_copies * EQ_M), c;
    double *scrs;
    if (bad > 0) return bad;
    if (chunks > n_copies) chunks = n_copies;
    if (chunks < 1) chunks = 1;
    scrs = (double *)calloc((size_t)(chunks * stride), sizeof(double));
    if (scrs == NULL) return -1;
#ifdef _OPENMP
#pragma omp parallel for schedule(static, 1) num_threads((int)chunks) if (chunks > 1)
#endif
    for (c = 0; c < chunks; c++) {
        eq_env_step_range(c * n_copies / chunks, (c + 1) * n_copies / chunks, actions, fs, us,
                          obs, n_obs, rewards, flags, n_copies, cf, ci, scrs + c * stride,
                          width);
    }
    free(scrs);
    return 0;
}

/* How many copies the vector environment's step runs at once on this CPU (1: one at a time)
 * with an integrator that has a lanes step (eq_int_lanes). */
EQ_EXPORT int64_t eq_env_lanes(void)
{
#ifdef EQ_LANES
    if (eq_lanes_usable()) return EQ_LANES;
#endif
    return 1;
}

/* One control period of the single environment in row 0: the reward, and *status (3 when
 * the action is not a finite number: nothing done). */
EQ_EXPORT double eq_env_step_one(const double *a, double *fs, uint64_t *us, double *obs,
                                 const double *cf, const int64_t *ci, int64_t *status)
{
    const int64_t width = eq_env_width(ci);
    double scr[EQ_ENV_SCR * width];
    eq_env S;
    int st, i;
    double reward;
    for (i = 0; i < EQ_M; i++) {
        if (!isfinite(a[i])) {
            *status = 3;
            return 0.0;
        }
    }
    memset(scr, 0, sizeof(scr));
    eq_env_settings(cf, ci, &S);
    reward = eq_env_step_copy(0, a, fs, us, obs, cf, ci, &S, scr, width, &st);
    *status = st;
    return reward;
}

/* Start row 0's episode from the state and parameters written in it (the single
 * environment's reset); obs receives the first observation. */
EQ_EXPORT void eq_env_begin_one(double *fs, uint64_t *us, double *obs, const double *cf,
                                const int64_t *ci)
{
    double zbuf[eq_env_width(ci)];
    memset(zbuf, 0, sizeof(zbuf));
    eq_env_begin(0, fs, us, obs, cf, ci, zbuf);
}

/* Reset every copy: draw each one's start and parameters from its own generator and
 * observe it into its row of obs. */
EQ_EXPORT void eq_env_reset_many(double *fs, uint64_t *us, double *obs, int64_t n_obs,
                                 int64_t n_copies, const double *cf, const int64_t *ci)
{
    double zbuf[eq_env_width(ci)];
    int64_t r;
    memset(zbuf, 0, sizeof(zbuf));
    for (r = 0; r < n_copies; r++) {
        eq_env_draw(r, fs, us, cf, ci);
        eq_env_begin(r, fs, us, obs + r * n_obs, cf, ci, zbuf);
    }
}
