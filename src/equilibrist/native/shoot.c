/* The identification's multiple-shooting integrator (equilibrist.ident), appended to the
 * simulation core's body: its steps are the core's (eq_step_free of the table's integrator
 * number `integrator`, without noise), so the identification predicts with the arithmetic
 * that the simulation and the environments integrate with.
 *
 * t (n_rows) sample times; u (n_rows, m) the logged input, held from t[k] to t[k + 1];
 * integrator: a number of the table (EQ_INT_*), rtol and atol its tolerances (an adaptive
 * one's); bounds (n_seg + 1) int64 sample indices b_0 = 0 < ... < b_S = n_rows - 1: segment s
 * starts from xs[s] at t[b_s] and runs to t[b_{s+1}]; n_sub (n_rows - 1) int64 steps per
 * sample interval. A state that stops being finite stays so (the residuals say it); a step
 * that fails makes it NaN.
 */

/* n_sub[k] steps over sample interval k from x (in place) with u[k] held. */
static void eq_shoot_interval(int64_t integrator, double *x, const double *t, const double *u,
                              const int64_t *n_sub, int64_t k, const double *p,
                              const eq_step_ctx *c)
{
    const int64_t steps = n_sub[k];
    const double h = (t[k + 1] - t[k]) / (double)steps;
    int64_t step;
    int i;
    eq_step_begin(integrator, h, c);
    for (step = 0; step < steps; step++) {
        if (!eq_step_free(integrator, x, u + k * EQ_M, p, h, c)) {
            for (i = 0; i < EQ_N; i++) x[i] = NAN;
            return;
        }
    }
}

/* A context for eq_step_free over `work` (EQ_STEP_ROWS rows of EQ_N), with tolerances. */
static eq_step_ctx eq_shoot_ctx(double *work, double rtol, double atol)
{
    eq_step_ctx c;
    c.work = work;
    c.width = EQ_N;
    c.rtol = rtol;
    c.atol = atol;
    c.op = NULL;
    c.lin = NULL;
    return c;
}

/* Every segment for each of K cases: P (K, n_p) parameter vectors, XS (K, n_seg, n) the
 * segments' initial states; writes yhat (K, n_rows, ny) the predicted measured states and
 * xend (K, n_seg, n) each segment's end state. */
EQ_EXPORT void eq_shoot_many(int64_t integrator, double rtol, double atol, const double *P, int64_t K, int64_t n_p,
                             const double *XS, const int64_t *bounds, int64_t n_seg,
                             const double *t, int64_t n_rows, const double *u,
                             const int64_t *n_sub, const int64_t *c_idx, int64_t ny,
                             double *yhat, double *xend)
{
    double x[EQ_N], work[EQ_STEP_ROWS * EQ_N];
    const eq_step_ctx ctx = eq_shoot_ctx(work, rtol, atol);
    int64_t c, s, k, j, i;
    for (c = 0; c < K; c++) {
        const double *p = P + c * n_p;
        double *yc = yhat + c * n_rows * ny;
        double *xe = xend + c * n_seg * EQ_N;
        int64_t last;
        for (s = 0; s < n_seg; s++) {
            for (i = 0; i < EQ_N; i++) x[i] = XS[(c * n_seg + s) * EQ_N + i];
            for (k = bounds[s]; k < bounds[s + 1]; k++) {
                for (j = 0; j < ny; j++) yc[k * ny + j] = x[c_idx[j]];
                eq_shoot_interval(integrator, x, t, u, n_sub, k, p, &ctx);
            }
            for (i = 0; i < EQ_N; i++) xe[s * EQ_N + i] = x[i];
        }
        last = bounds[n_seg];
        for (j = 0; j < ny; j++) yc[last * ny + j] = xe[(n_seg - 1) * EQ_N + c_idx[j]];
    }
}

/* One-step prediction errors of a Kalman filter with a fixed gain (n, ny): the state is
 * predicted with the model (the integrator's steps, the logged input held) and corrected by
 * gain times the error; e[k] is the measurement y[k] minus off minus its prediction. */
EQ_EXPORT void eq_innovations(int64_t integrator, double rtol, double atol, const double *p, const double *x0,
                              const double *t, int64_t n_rows, const double *u,
                              const int64_t *n_sub, const int64_t *c_idx, int64_t ny,
                              const double *gain, const double *y, const double *off, double *e)
{
    double x[EQ_N], work[EQ_STEP_ROWS * EQ_N];
    const eq_step_ctx ctx = eq_shoot_ctx(work, rtol, atol);
    int64_t k, j, i;
    for (i = 0; i < EQ_N; i++) x[i] = x0[i];
    for (k = 0; k < n_rows; k++) {
        for (j = 0; j < ny; j++) e[k * ny + j] = y[k * ny + j] - off[j] - x[c_idx[j]];
        for (i = 0; i < EQ_N; i++) {
            double v = 0.0;
            for (j = 0; j < ny; j++) v += gain[i * ny + j] * e[k * ny + j];
            x[i] += v;
        }
        if (k + 1 < n_rows) eq_shoot_interval(integrator, x, t, u, n_sub, k, p, &ctx);
    }
}
