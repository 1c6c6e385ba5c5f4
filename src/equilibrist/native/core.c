/* The simulation core of equilibrist, in C: written once, compiled per system and controller.
 *
 * equilibrist.sim.simcore writes one translation unit per system and
 * controller: the calling convention's constants (EQ_IO_*, EQ_REC_*... from
 * equilibrist.sim.layout; EQ_INT_* and the integrators' work rows from
 * equilibrist.sim.integrators), the run's argument struct eq_args (from
 * equilibrist.sim.core_unit.FIELDS, which also gives ctypes its RunArgs), the
 * project's libm (equilibrist.numeric.libm), the system's dynamics and the
 * controller translated from their one Python definition
 * (equilibrist.native.pyc), the glue below the marker "the generated part ends
 * here", then this body, with integrators.c and the integrators' dispatch
 * (eq_step...) where its marker says. The unit defines:
 *
 *   EQ_N, EQ_M        states and inputs of the system
 *   eq_f(x, u, p, out)                       out = f(x, u, p)
 *   eq_ctrl_output(t, z, nz, y, ny, r, nr, cp, ncp, u_out)
 *   eq_ctrl_update(t, z, nz, y, ny, r, nr, u_app, cp, ncp, z_out)
 *   eq_ctrl_estimate(t, z, nz, y, ny, r, nr, cp, ncp, x_out)
 *
 * The arithmetic is fixed operation for operation: the same sums in the same
 * order, Python's min and max (eq_minf, eq_maxf), integer powers by repeated
 * squaring (pyc), the project's log for the normal deviates; compiled with
 * -ffp-contract=off and without -ffast-math, so a run gives the same bits on
 * every CPU. The conventions: the state and the input are absolute (not
 * deviations from the operating point); sample k is at t = k / rate, and
 * the n_sub physics steps after it are numbered s = k * n_sub + j; events
 * (kicks, pulses, parameter changes) are given by physics step; a run falls
 * when a state leaves its region (the fell code: the index of the state,
 * -2 when a state is not finite, -3 when the integrator failed); each run
 * draws its noise from its own xoshiro256** state; a run stops between
 * samples (and every 4096 physics steps) when *stop is set.
 */

/* ---- the run's arrays: the struct eq_args, written before this body from
 * equilibrist.sim.core_unit.FIELDS: the sample range, options, state, controller, noise,
 * parameter sets, events, and the outputs. ---- */

/* ---- the generator and the integrators: integrators.c, inserted here ---- */

/* -1 inside; the index of the first state outside its region; -2 if not finite. */
static inline int64_t eq_outside(const double *x, const double *region)
{
    int i;
    /* Strictly between its bounds is finite and inside: one pass for the usual case (NaN
     * fails every comparison); the others are sorted out below, as before. */
    for (i = 0; i < EQ_N; i++) {
        if (!(x[i] > region[i] && x[i] < region[EQ_N + i])) break;
    }
    if (i == EQ_N) return -1;
    for (i = 0; i < EQ_N; i++) {
        if (!isfinite(x[i])) return -2;
    }
    for (i = 0; i < EQ_N; i++) {
        if (x[i] <= region[i] || x[i] >= region[EQ_N + i]) return i;
    }
    return -1;
}

static inline int64_t eq_pset(const int64_t *p_switch, int64_t n_sets, int64_t s)
{
    int64_t j = n_sets - 1;
    while (j > 0 && p_switch[j] > s) j -= 1;
    return j;
}

static inline void eq_switch(const eq_args *a, const double *p_sets, int64_t s, double *pcur)
{
    int64_t j, i;
    for (j = 1; j < a->n_sets; j++) {
        if (a->p_switch[j] == s) {
            for (i = 0; i < a->p_len; i++) pcur[i] = p_sets[j * a->p_len + i];
        }
    }
}

static inline void eq_measure(const double *x, const int64_t *c_idx, int64_t ny,
                              const double *lv, int64_t nlv, uint64_t *rng, double *y,
                              double *zbuf)
{
    int64_t j, k;
    for (j = 0; j < ny; j++) y[j] = x[c_idx[j]];
    if (nlv > 0) {
        eq_normals(rng, zbuf, ny);
        for (j = 0; j < ny; j++) {
            double v = 0.0;
            for (k = 0; k < ny; k++) v += lv[j * ny + k] * zbuf[k];
            y[j] += v;
        }
    }
}

/* floor(v), the same bits, without a call to libm where the value is small: truncation
 * is exact below 2^52, and a truncation above v is one too high (v = -0.0 kept). */
static inline double eq_floor(double v)
{
    double t;
    if (!(fabs(v) < 4503599627370496.0) || v == 0.0) return floor(v);
    t = (double)(int64_t)v;
    return t > v ? t - 1.0 : t;
}

/* ---- a rig's effects (equilibrist.sim.rig; rig_i, rig_f: layout.RIG_I, RIG_F) ---- */

/* Doubles of one run's rig state (layout.rig_state_len): the motors' torques (m), the
 * actuation's ring (m per delayed sample and one), the measurement's ring (ny per delayed
 * sample and one), the encoders' last positions (nq), the filtered velocities (ny). */
static inline int64_t eq_rig_len(const eq_args *a)
{
    if (a->rig_i == NULL) return 0;
    return EQ_M + EQ_M * (a->rig_i[EQ_RI_ACT_DELAY] + 1)
        + a->ny * (a->rig_i[EQ_RI_MEAS_DELAY] + 1) + a->rig_i[EQ_RI_NQ] + a->ny;
}

/* The measurement at sample k through the rig: the encoders (positions quantized to their
 * step, velocities by differencing the quantized positions over a period: 0 at the first
 * sample), the sensors' noise (as eq_measure), the measurement's delay (the reading of
 * sample k - d; sample 0's before that), the velocities' noise, their low-pass filter
 * (y_f += a (y - y_f), starting at the first reading). A velocity is the output of state
 * nq + i for coordinate i. */
static inline void eq_rig_measure(const eq_args *a, int64_t k, const double *x, uint64_t *rng,
                                  double *y, double *zbuf, double *rs)
{
    const int64_t ny = a->ny, m = EQ_M, nq = a->rig_i[EQ_RI_NQ];
    const int64_t da = a->rig_i[EQ_RI_ACT_DELAY], dm = a->rig_i[EQ_RI_MEAS_DELAY];
    const double sigma = a->rig_f[EQ_RF_VEL_SIGMA];
    double *ring = rs + m + m * (da + 1);
    double *enc = ring + ny * (dm + 1), *filt = enc + nq;
    int64_t j, c, nv;
    for (j = 0; j < ny; j++) y[j] = x[a->c_idx[j]];
    if (a->rig_i[EQ_RI_ENCODER] != 0) {
        const double step = a->rig_f[EQ_RF_ENCODER_STEP], rate = a->fopts[EQ_FO_RATE];
        for (j = 0; j < ny; j++) {
            c = a->c_idx[j];
            if (c < nq) {
                y[j] = step * eq_floor(x[c] / step);
            } else if (c < 2 * nq) {
                double now = step * eq_floor(x[c - nq] / step);
                y[j] = k == 0 ? 0.0 : (now - enc[c - nq]) * rate;
            }
        }
        for (c = 0; c < nq; c++) enc[c] = step * eq_floor(x[c] / step);
    }
    if (a->nlv > 0) {
        eq_normals(rng, zbuf, ny);
        for (j = 0; j < ny; j++) {
            double v = 0.0;
            for (c = 0; c < ny; c++) v += a->lv[j * ny + c] * zbuf[c];
            y[j] += v;
        }
    }
    if (dm > 0) {
        double *slot = ring + (k % (dm + 1)) * ny;
        const double *old = ring + ((k >= dm ? k - dm : 0) % (dm + 1)) * ny;
        for (j = 0; j < ny; j++) slot[j] = y[j];
        for (j = 0; j < ny; j++) y[j] = old[j];
    }
    if (sigma > 0.0) {
        nv = 0;
        for (j = 0; j < ny; j++) nv += a->c_idx[j] >= nq && a->c_idx[j] < 2 * nq;
        eq_normals(rng, zbuf, nv);
        nv = 0;
        for (j = 0; j < ny; j++) {
            if (a->c_idx[j] >= nq && a->c_idx[j] < 2 * nq) y[j] += sigma * zbuf[nv++];
        }
    }
    if (a->rig_i[EQ_RI_FILTER] != 0) {
        const double fa = a->rig_f[EQ_RF_FILTER_A];
        for (j = 0; j < ny; j++) {
            if (a->c_idx[j] >= nq && a->c_idx[j] < 2 * nq) {
                filt[j] = k == 0 ? y[j] : filt[j] + fa * (y[j] - filt[j]);
                y[j] = filt[j];
            }
        }
    }
}

/* The torque that acts at sample k through the rig, from the actuator's u_app: the
 * actuation's delay (u_app of sample k - d; the operating point's input, saturated, before),
 * the motor's response (tau = tau_prev + k (tau_des - tau_prev), tau_prev the torque that
 * acted at the sample before, the operating point's input at the first), the torque's
 * noise, then the limits in force (lim: low, high per input). */
static inline void eq_rig_actuate(const eq_args *a, int64_t k, const double *u_app,
                                  double *u_act, const double *lim, uint64_t *rng,
                                  double *zbuf, double *rs)
{
    const int64_t m = EQ_M, da = a->rig_i[EQ_RI_ACT_DELAY];
    const double sigma = a->rig_f[EQ_RF_TORQUE_SIGMA];
    double *mot = rs, *ring = rs + m;
    int64_t i, j;
    if (k == 0) {
        for (i = 0; i < m; i++) {
            mot[i] = eq_minf(eq_maxf(a->op[EQ_N + i], lim[2 * i]), lim[2 * i + 1]);
            for (j = 0; j <= da; j++) ring[j * m + i] = mot[i];
        }
    }
    for (i = 0; i < m; i++) u_act[i] = u_app[i];
    if (da > 0) {
        double *slot = ring + (k % (da + 1)) * m;
        const double *old = ring + ((k + 1) % (da + 1)) * m;
        for (i = 0; i < m; i++) slot[i] = u_act[i];
        for (i = 0; i < m; i++) u_act[i] = old[i];
    }
    if (a->rig_i[EQ_RI_RESPONSE] != 0) {
        const double kr = a->rig_f[EQ_RF_RESPONSE_K];
        for (i = 0; i < m; i++) u_act[i] = mot[i] + kr * (u_act[i] - mot[i]);
    }
    if (sigma > 0.0) {
        eq_normals(rng, zbuf, m);
        for (i = 0; i < m; i++) u_act[i] += sigma * zbuf[i];
    }
    for (i = 0; i < m; i++) {
        u_act[i] = eq_minf(eq_maxf(u_act[i], lim[2 * i]), lim[2 * i + 1]);
        mot[i] = u_act[i];
    }
}

/* The scratch of one run: EQ_SCR_ROWS rows of `width` (layout.SCRATCH's, the last, wk,
 * starting the integrator's work rows). */
#define EQ_SCR_ROWS (EQ_S_WK + EQ_STEP_ROWS)
static int64_t eq_width(int64_t p_len, int64_t ny, int64_t nw, int64_t nz)
{
    int64_t w = EQ_N;
    w = w > EQ_M ? w : EQ_M;
    w = w > p_len ? w : p_len;
    w = w > ny + 2 ? w : ny + 2;
    w = w > nw + 2 ? w : nw + 2;
    w = w > nz ? w : nz;
    return w > 1 ? w : 1;
}

#define EQ_ROW(scr, width, r) ((scr) + (int64_t)(r) * (width))

/* The physics steps between samples k and k + 1; 1 when the run fell or was stopped.
 * plain (a constant where it is inlined): a run with one parameter set, no kicks or
 * pulses, no noise and RK4 (eq_plain), whose steps skip what it has not. */
static inline __attribute__((always_inline)) int
eq_advance_t(const eq_args *a, int64_t k, double *x, const double *u_app, const double *p_sets,
             const double *lin_s, uint64_t *rng, int64_t *status, double *scr, int64_t width,
             volatile int64_t *stop, const int plain)
{
    const int n = EQ_N, m = EQ_M;
    const int64_t nw = a->nw;
    const int64_t n_sub = a->iopts[EQ_IO_N_SUB];
    const int64_t integrator = a->iopts[EQ_IO_INTEGRATOR];
    const double h = a->fopts[EQ_FO_H];
    const int64_t lin_size = (int64_t)EQ_N * (2 * EQ_N + EQ_M + 1);
    double *xprev = EQ_ROW(scr, width, EQ_S_XPREV);
    double *ubuf = EQ_ROW(scr, width, EQ_S_UBUF), *wvec = EQ_ROW(scr, width, EQ_S_WVEC);
    double *zbuf = EQ_ROW(scr, width, EQ_S_ZBUF), *pcur = EQ_ROW(scr, width, EQ_S_PCUR);
    double *fell_x = EQ_ROW(scr, width, EQ_S_FELL_X);
    eq_step_ctx ctx;
    int ok = 1;
    int64_t j, e, i, c;
    ctx.work = EQ_ROW(scr, width, EQ_S_WK);
    ctx.width = width;
    ctx.rtol = a->fopts[EQ_FO_RTOL];
    ctx.atol = a->fopts[EQ_FO_ATOL];
    ctx.op = a->op;
    ctx.lin = NULL;
    eq_step_begin(integrator, h, &ctx);
    for (j = 0; j < n_sub; j++) {
        int64_t s = k * n_sub + j;
        int64_t code;
        if ((j & 4095) == 4095 && *stop != 0) return 1;
        if (plain) {
            for (i = 0; i < n; i++) xprev[i] = x[i];
            eq_rk4_plain(x, u_app, pcur, h);
            goto check;
        }
        eq_switch(a, p_sets, s, pcur);
        for (e = 0; e < a->n_kicks; e++) {
            if (a->kicks[2 * e] == s) x[a->kicks[2 * e + 1]] += a->kick_value[e];
        }
        for (i = 0; i < m; i++) ubuf[i] = u_app[i];
        for (e = 0; e < a->n_pulses; e++) {
            if (a->pulses[3 * e] <= s && s < a->pulses[3 * e + 1]) {
                ubuf[a->pulses[3 * e + 2]] += a->pulse_value[e];
            }
        }
        if (nw > 0) {
            eq_normals(rng, zbuf, nw);
            for (i = 0; i < n; i++) {
                double v = 0.0;
                for (c = 0; c < nw; c++) v += a->lw[i * nw + c] * zbuf[c];
                wvec[i] = v;
            }
        }
        for (i = 0; i < n; i++) xprev[i] = x[i];
        if (lin_s != NULL) ctx.lin = lin_s + eq_pset(a->p_switch, a->n_sets, s) * lin_size;
        ok = eq_step(integrator, x, ubuf, pcur, wvec, nw, h, &ctx);
    check:
        code = eq_outside(x, a->region);
        if (!ok) code = -3;
        if (code != -1) {
            int finite = code >= 0;
            status[EQ_ST_FELL] = 1;
            status[EQ_ST_FELL_CODE] = code;
            status[EQ_ST_FELL_STEP] = s + 1;
            for (i = 0; i < n; i++) fell_x[i] = finite ? x[i] : xprev[i];
            return 1;
        }
    }
    return 0;
}

static int eq_advance(const eq_args *a, int64_t k, double *x, const double *u_app,
                      const double *p_sets, const double *lin_s, uint64_t *rng, int64_t *status,
                      double *scr, int64_t width, volatile int64_t *stop)
{
    return eq_advance_t(a, k, x, u_app, p_sets, lin_s, rng, status, scr, width, stop, 0);
}

/* Whether a run can take eq_advance_t's and eq_run_t's plain path. */
static int eq_plain(const eq_args *a)
{
    return a->n_sets == 1 && a->n_kicks == 0 && a->n_pulses == 0 && a->nw == 0
        && a->nlv == 0 && a->iopts[EQ_IO_INTEGRATOR] == EQ_INT_RK4
        && a->iopts[EQ_IO_RECORD] == 0 && (a->rig_i == NULL || a->rig_i[EQ_RI_ON] == 0)
        && a->gforce == NULL;
}

/* Whether x is in the balance box (equilibrist.tasks.balance_box: per state the deviation's
 * low and high, and its period, 2 pi for an angle taken modulo a turn, else 0). */
static inline int eq_in_box(const double *x, const double *op, const double *box)
{
    int i;
    for (i = 0; i < EQ_N; i++) {
        double d = x[i] - op[i];
        double period = box[3 * i + 2];
        if (period > 0.0) d = d - period * eq_floor(d / period + 0.5);
        if (!(d >= box[3 * i] && d <= box[3 * i + 1])) return 0;
    }
    return 1;
}

/* Samples k_start .. k_end - 1 of one closed-loop run (resumable): at each sample the
 * sensors, the controller's output (and estimate), the saturated and applied input, the
 * record and the accumulators, the controller's update, then the physics steps to the next
 * sample. plain: as in eq_advance_t (the constant of eq_run and eq_run_plain). */
static inline __attribute__((always_inline)) void
eq_run_t(const eq_args *a, int64_t k_start, int64_t k_end, double *x, double *z, double *u_prev,
         uint64_t *rng, const double *p_sets, const double *lin_s, double *rec, double *acc,
         int64_t *status, double *scr, int64_t width, double *rs, const double *gf,
         const int plain)
{
    const int n = EQ_N, m = EQ_M;
    const int64_t n_samples = a->iopts[EQ_IO_N_SAMPLES];
    const int record = !plain && a->iopts[EQ_IO_RECORD] != 0;
    const int accumulate = a->iopts[EQ_IO_ACCUMULATE] != 0;
    const int delay = a->iopts[EQ_IO_DELAY] != 0;
    const int64_t n_sub = a->iopts[EQ_IO_N_SUB];
    const int estimates = a->iopts[EQ_IO_ESTIMATES] != 0 && (record || accumulate);
    const double rate = a->fopts[EQ_FO_RATE];
    const int64_t ny = a->ny, nz = a->nz, nr = a->nr, ncp = a->ncp;
    double *y = EQ_ROW(scr, width, EQ_S_Y), *xhat = EQ_ROW(scr, width, EQ_S_X_HAT);
    double *u_cmd = EQ_ROW(scr, width, EQ_S_U_CMD), *u_sat = EQ_ROW(scr, width, EQ_S_U_SAT);
    double *u_app = EQ_ROW(scr, width, EQ_S_U_APP), *znew = EQ_ROW(scr, width, EQ_S_Z_NEW);
    double *zbuf = EQ_ROW(scr, width, EQ_S_ZBUF), *pcur = EQ_ROW(scr, width, EQ_S_PCUR);
    double *fell_x = EQ_ROW(scr, width, EQ_S_FELL_X);
    const int64_t base = a->p_len - 2 * m;
    const int64_t c_x = a->rec_cols[EQ_REC_X], c_xhat = a->rec_cols[EQ_REC_X_HAT];
    const int64_t c_y = a->rec_cols[EQ_REC_Y], c_cmd = a->rec_cols[EQ_REC_U_CMD];
    const int64_t c_sat = a->rec_cols[EQ_REC_U_SAT], c_app = a->rec_cols[EQ_REC_U_APP];
    const int64_t a_peak = a->acc_cols[EQ_ACC_PEAK_U], a_u2 = a->acc_cols[EQ_ACC_SUM_U2];
    const int64_t a_sat = a->acc_cols[EQ_ACC_N_SAT], a_dx = a->acc_cols[EQ_ACC_PEAK_DX];
    const int64_t a_est = a->acc_cols[EQ_ACC_SUM_EST2];
    const int64_t a_peak_app = a->acc_cols[EQ_ACC_PEAK_U_APP];
    const int64_t a_last_out = a->acc_cols[EQ_ACC_LAST_OUT];
    /* a rig's effects (u_act: the torque that acts; without them, u_app itself) */
    const int rig = !plain && a->rig_i != NULL && a->rig_i[EQ_RI_ON] != 0;
    double *u_act = rig ? EQ_ROW(scr, width, EQ_S_U_ACT) : u_app;
    const int64_t nq = a->rig_i != NULL ? a->rig_i[EQ_RI_NQ] : 0;
    int64_t ps0 = eq_pset(a->p_switch, a->n_sets, k_start * n_sub);
    int64_t k, i, j;
    for (i = 0; i < a->p_len; i++) pcur[i] = p_sets[ps0 * a->p_len + i];
    for (k = k_start; k < k_end; k++) {
        double t;
        const double *r = a->ref + k * nr;
        int saturated = 0;
        if (*a->stop != 0) return;
        if (!plain) eq_switch(a, p_sets, k * n_sub, pcur);
        if (k == 0) {
            for (i = 0; i < m; i++) {
                u_prev[i] = eq_minf(eq_maxf(a->op[n + i], pcur[base + 2 * i]),
                                    pcur[base + 2 * i + 1]);
            }
        }
        if (rig) {
            eq_rig_measure(a, k, x, rng, y, zbuf, rs);
        } else {
            eq_measure(x, a->c_idx, ny, a->lv, plain ? 0 : a->nlv, rng, y, zbuf);
        }
        t = (double)k / rate;
        eq_ctrl_output(t, z, nz, y, ny, r, nr, a->cp, ncp, u_cmd);
        if (estimates) eq_ctrl_estimate(t, z, nz, y, ny, r, nr, a->cp, ncp, xhat);
        for (i = 0; i < m; i++) {
            u_cmd[i] = u_cmd[i] + a->uff[k * m + i];
            u_sat[i] = eq_minf(eq_maxf(u_cmd[i], pcur[base + 2 * i]), pcur[base + 2 * i + 1]);
            if (u_sat[i] != u_cmd[i]) saturated = 1;
            u_app[i] = delay ? u_prev[i] : u_sat[i];
            u_prev[i] = u_sat[i];
        }
        if (rig) eq_rig_actuate(a, k, u_app, u_act, pcur + base, rng, zbuf, rs);
        if (record) {
            double *row = rec + k * a->rec_w;
            for (i = 0; i < n; i++) {
                row[c_x + i] = x[i];
                row[c_xhat + i] = estimates ? xhat[i] : NAN;
            }
            for (j = 0; j < ny; j++) row[c_y + j] = y[j];
            for (i = 0; i < m; i++) {
                row[c_cmd + i] = u_cmd[i];
                row[c_sat + i] = u_sat[i];
                row[c_app + i] = u_act[i];
            }
        }
        if (accumulate) {
            for (i = 0; i < m; i++) {
                acc[a_peak + i] = eq_maxf(acc[a_peak + i], fabs(u_cmd[i]));
                acc[a_peak_app + i] = eq_maxf(acc[a_peak_app + i], fabs(u_act[i]));
                acc[a_u2 + i] += u_act[i] * u_act[i];
            }
            if (saturated) acc[a_sat] += 1.0;
            for (i = 0; i < n; i++) {
                acc[a_dx + i] = eq_maxf(acc[a_dx + i], fabs(x[i] - a->op[i]));
                if (estimates) {
                    double e = xhat[i] - x[i];
                    acc[a_est + i] += e * e;
                }
            }
            if (a->nbal > 0 && !eq_in_box(x, a->op, a->bal)) acc[a_last_out] = (double)(k + 1);
        }
        status[EQ_ST_ROWS] = k + 1;
        if (nz > 0) {
            eq_ctrl_update(t, z, nz, y, ny, r, nr, u_app, a->cp, ncp, znew);
            for (i = 0; i < nz; i++) z[i] = znew[i];
        }
        if (k == 0) {
            int64_t code = eq_outside(x, a->region);
            if (code != -1) {
                status[EQ_ST_FELL] = 1;
                status[EQ_ST_FELL_CODE] = code;
                status[EQ_ST_FELL_STEP] = 0;
                for (i = 0; i < n; i++) fell_x[i] = x[i];
                return;
            }
        }
        if (k >= n_samples) return;
        if (gf != NULL) eq_gf_row = k < a->n_gforce ? gf + k * nq : NULL;
        {
            int ended = eq_advance_t(a, k, x, u_act, p_sets, lin_s, rng, status, scr, width,
                                     a->stop, plain);
            eq_gf_row = NULL;
            if (ended) return;
        }
    }
}

static void eq_run(const eq_args *a, int64_t k_start, int64_t k_end, double *x, double *z,
                   double *u_prev, uint64_t *rng, const double *p_sets, const double *lin_s,
                   double *rec, double *acc, int64_t *status, double *scr, int64_t width,
                   double *rs, const double *gf)
{
    eq_run_t(a, k_start, k_end, x, z, u_prev, rng, p_sets, lin_s, rec, acc, status, scr, width,
             rs, gf, 0);
}

static void eq_run_plain(const eq_args *a, int64_t k_start, int64_t k_end, double *x, double *z,
                         double *u_prev, uint64_t *rng, const double *p_sets,
                         const double *lin_s, double *rec, double *acc, int64_t *status,
                         double *scr, int64_t width, double *rs, const double *gf)
{
    eq_run_t(a, k_start, k_end, x, z, u_prev, rng, p_sets, lin_s, rec, acc, status, scr, width,
             rs, gf, 1);
}

static double *eq_scratch(const eq_args *a, int64_t *width)
{
    *width = eq_width(a->p_len, a->ny, a->nw, a->nz);
    return (double *)calloc((size_t)(EQ_SCR_ROWS * *width), sizeof(double));
}

/* ---- entries (called through ctypes; they release Python's lock) ---- */

/* One run, or samples k_start .. k_end - 1 of one; 0, or -1 when out of memory. */
EQ_EXPORT int eq_run_one(const eq_args *a)
{
    int64_t width, i;
    double *scr = eq_scratch(a, &width);
    if (scr == NULL) return -1;
    (eq_plain(a) ? eq_run_plain : eq_run)(a, a->k_start, a->k_end, a->x, a->z, a->u_prev,
                                          a->rng, a->p_sets, a->lin_s, a->rec, a->acc,
                                          a->status, scr, width, a->rig_s, a->gforce);
    for (i = 0; i < EQ_N; i++) a->fell_x[i] = EQ_ROW(scr, width, EQ_S_FELL_X)[i];
    free(scr);
    return 0;
}

/* Independent runs over the per-run arrays, in parallel: x0s, rngs, p_sets (n_runs stacked
 * sets), lin_s, rec, acc, status, fell_x and x_ends hold one block per run. A run's
 * accumulators and status, written at every sample, are kept in its own memory while it
 * runs and copied back at its end: neighbouring runs' blocks share cache lines, and two
 * threads writing one line at every sample ran the batch at 1.2 times one thread's speed. */
EQ_EXPORT int eq_run_many(const eq_args *a)
{
    const int64_t n_rows = a->iopts[EQ_IO_N_SAMPLES] + 1;
    const int64_t lin_size = a->lin_s == NULL ? 0
        : a->n_sets * (int64_t)EQ_N * (2 * EQ_N + EQ_M + 1);
    const int plain = eq_plain(a);
    int failed = 0;
    int64_t r;
#ifdef _OPENMP
#pragma omp parallel for schedule(dynamic, 1) num_threads((int)a->n_threads) reduction(|:failed)
#endif
    for (r = 0; r < a->n_runs; r++) {
        int64_t width, i;
        double *scr = eq_scratch(a, &width);
        const int64_t nz1 = a->nz > 0 ? a->nz : 1;
        const int64_t rig_len = eq_rig_len(a);
        double *x = (double *)malloc(sizeof(double) * (EQ_N + EQ_M + nz1 + a->acc_w + rig_len));
        uint64_t rng[4];
        int64_t status[4];
        if (scr == NULL || x == NULL) {
            free(scr);
            free(x);
            failed = 1;
            continue;
        }
        {
            double *u_prev = x + EQ_N;
            double *z = u_prev + EQ_M;
            double *acc = z + nz1;
            double *rs = acc + a->acc_w;
            const double *gf = a->gforce == NULL ? NULL
                : a->gforce + r * a->n_gforce * a->rig_i[EQ_RI_NQ];
            for (i = 0; i < EQ_N; i++) x[i] = a->x0s[r * EQ_N + i];
            for (i = 0; i < a->nz; i++) z[i] = a->z[i];
            for (i = 0; i < EQ_M; i++) u_prev[i] = 0.0;
            for (i = 0; i < 4; i++) rng[i] = a->rngs[r * 4 + i];
            for (i = 0; i < a->acc_w; i++) acc[i] = a->acc[r * a->acc_w + i];
            for (i = 0; i < 4; i++) status[i] = a->status[r * 4 + i];
            (plain ? eq_run_plain : eq_run)(
                a, 0, n_rows, x, z, u_prev, rng, a->p_sets + r * a->n_sets * a->p_len,
                a->lin_s == NULL ? NULL : a->lin_s + r * lin_size,
                a->rec == NULL ? NULL : a->rec + r * n_rows * a->rec_w,
                acc, status, scr, width, rs, gf);
            for (i = 0; i < EQ_N; i++) {
                a->x_ends[r * EQ_N + i] = x[i];
                a->fell_x[r * EQ_N + i] = EQ_ROW(scr, width, EQ_S_FELL_X)[i];
            }
            for (i = 0; i < a->acc_w; i++) a->acc[r * a->acc_w + i] = acc[i];
            for (i = 0; i < 4; i++) a->status[r * 4 + i] = status[i];
        }
        free(scr);
        free(x);
    }
    return failed ? -1 : 0;
}

/* Measured outputs of x with noise (the Python-controller path). */
EQ_EXPORT void eq_measure_one(const double *x, const int64_t *c_idx, int64_t ny,
                              const double *lv, int64_t nlv, uint64_t *rng, double *y)
{
    double zbuf[ny + 2];
    eq_measure(x, c_idx, ny, lv, nlv, rng, y, zbuf);
}

/* The rows of advance_one's scratch. */
EQ_EXPORT int64_t eq_scratch_rows(void)
{
    return EQ_SCR_ROWS;
}

/* The width of advance_one's scratch (eq_scratch_rows() rows). */
EQ_EXPORT int64_t eq_scratch_width(int64_t p_len, int64_t ny, int64_t nw)
{
    return eq_width(p_len, ny, nw, 0);
}

/* The physics steps after sample k (the Python-controller path); 1 if it fell. A rig's
 * generalized forces (a->gforce, a->n_gforce rows of a->rig_i's nq) act as in eq_run_t. */
EQ_EXPORT int eq_advance_one(const eq_args *a, int64_t k, const double *u_app, double *scr)
{
    const int64_t width = eq_width(a->p_len, a->ny, a->nw, 0);
    double *pcur = EQ_ROW(scr, width, EQ_S_PCUR);
    int64_t ps = eq_pset(a->p_switch, a->n_sets, k * a->iopts[EQ_IO_N_SUB]);
    int64_t i;
    int ended;
    static volatile int64_t no_stop = 0;
    for (i = 0; i < a->p_len; i++) pcur[i] = a->p_sets[ps * a->p_len + i];
    if (a->gforce != NULL && k < a->n_gforce) eq_gf_row = a->gforce + k * a->rig_i[EQ_RI_NQ];
    ended = eq_advance(a, k, a->x, u_app, a->p_sets, a->lin_s, a->rng, a->status, scr, width,
                       &no_stop);
    eq_gf_row = NULL;
    return ended;
}

/* The measurement at sample k through a rig (the Python-controller path: eq_rig_measure). */
EQ_EXPORT void eq_rig_measure_one(const eq_args *a, int64_t k, const double *x, uint64_t *rng,
                                  double *y, double *rs)
{
    double zbuf[a->ny + 2];
    eq_rig_measure(a, k, x, rng, y, zbuf, rs);
}

/* The torque that acts at sample k through a rig (the Python-controller path:
 * eq_rig_actuate; lim: low, high per input). */
EQ_EXPORT void eq_rig_actuate_one(const eq_args *a, int64_t k, const double *u_app,
                                  double *u_act, const double *lim, uint64_t *rng, double *rs)
{
    double zbuf[EQ_M + 2];
    eq_rig_actuate(a, k, u_app, u_act, lim, rng, zbuf, rs);
}

/* n_steps RK4 steps of length h from x (in place) with u held. */
EQ_EXPORT void eq_rk4_steps(double *x, const double *u, const double *p, double h,
                            int64_t n_steps)
{
    double w[EQ_N], k1[EQ_N], k2[EQ_N], k3[EQ_N], k4[EQ_N], xt[EQ_N];
    int64_t s;
    int i;
    for (i = 0; i < EQ_N; i++) w[i] = 0.0;
    for (s = 0; s < n_steps; s++) eq_rk4(x, u, p, w, h, k1, k2, k3, k4, xt);
}

/* Standard normal deviates from the core's generator (for tests). */
EQ_EXPORT void eq_normals_into(uint64_t *rng, double *out, int64_t count)
{
    eq_normals(rng, out, count);
}

/* The system's derivative (for tests and for Python callers that want the core's bits). */
EQ_EXPORT void eq_f_one(const double *x, const double *u, const double *p, double *out)
{
    eq_f(x, u, p, out);
}
