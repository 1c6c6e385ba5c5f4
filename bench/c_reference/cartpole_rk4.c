/*
 * Hand-written reference for bench/bench_sim.py: the cart-pole of seed 001
 * (equations typed in from the textbook, independent of equilibrist's
 * derivation) under state feedback u = -K x applied with zero-order hold at
 * the control rate, integrated with fixed-step RK4.
 *
 * Build:  gcc -O2 -fopenmp -o cartpole_rk4 cartpole_rk4.c -lm
 * Run:    cartpole_rk4 K1 K2 K3 K4 THETA0 DURATION DT REPEATS BATCH_RUNS THETA_SPAN
 *
 * Prints one JSON object: the best wall time of one recorded run (the state
 * and input of every step kept, as a simulator must), the final state of
 * that run, and the wall time of BATCH_RUNS runs (initial angles evenly
 * spread over [-THETA_SPAN, THETA_SPAN], outcome only) on all OpenMP threads.
 */
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#ifdef _OPENMP
#include <omp.h>
#endif

/* seed 001 table: m_c, m_p, l (pivot to centre of mass), I_p, g; no friction */
static const double MC = 10.0, MP = 1.0, L = 0.5, IP = 0.08333, G = 9.8;
static const double F_MAX = 200.0;

static void f(const double *x, double u, double *dx) {
    double s = sin(x[1]), c = cos(x[1]);
    /* M q'' = F with M = [[mc+mp, mp l c], [mp l c, Ip + mp l^2]] */
    double m11 = MC + MP, m12 = MP * L * c, m22 = IP + MP * L * L;
    double f1 = u + MP * L * s * x[3] * x[3];
    double f2 = MP * G * L * s;
    double det = m11 * m22 - m12 * m12;
    dx[0] = x[2];
    dx[1] = x[3];
    dx[2] = (m22 * f1 - m12 * f2) / det;
    dx[3] = (m11 * f2 - m12 * f1) / det;
}

static void rk4(double *x, double u, double h) {
    double k1[4], k2[4], k3[4], k4[4], xt[4];
    int i;
    f(x, u, k1);
    for (i = 0; i < 4; i++) xt[i] = x[i] + 0.5 * h * k1[i];
    f(xt, u, k2);
    for (i = 0; i < 4; i++) xt[i] = x[i] + 0.5 * h * k2[i];
    f(xt, u, k3);
    for (i = 0; i < 4; i++) xt[i] = x[i] + h * k3[i];
    f(xt, u, k4);
    for (i = 0; i < 4; i++) x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
}

/* One run; returns 1 if the pole passed horizontal. rec (steps+1 rows of 5) may be NULL. */
static int run(const double *K, double theta0, long steps, double h, double *x, double *rec) {
    long k;
    int i;
    x[0] = 0.0; x[1] = theta0; x[2] = 0.0; x[3] = 0.0;
    for (k = 0; k <= steps; k++) {
        double u = -(K[0] * x[0] + K[1] * x[1] + K[2] * x[2] + K[3] * x[3]);
        if (u > F_MAX) u = F_MAX;
        if (u < -F_MAX) u = -F_MAX;
        if (rec) {
            for (i = 0; i < 4; i++) rec[5 * k + i] = x[i];
            rec[5 * k + 4] = u;
        }
        if (k == steps) break;
        rk4(x, u, h);
        if (!(fabs(x[1]) < 1.5707963267948966)) return 1;
    }
    return 0;
}

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

int main(int argc, char **argv) {
    if (argc != 11) {
        fprintf(stderr, "usage: %s K1 K2 K3 K4 THETA0 DURATION DT REPEATS BATCH_RUNS THETA_SPAN\n", argv[0]);
        return 2;
    }
    double K[4];
    int i;
    for (i = 0; i < 4; i++) K[i] = atof(argv[1 + i]);
    double theta0 = atof(argv[5]), duration = atof(argv[6]), h = atof(argv[7]);
    int repeats = atoi(argv[8]);
    long batch = atol(argv[9]);
    double span = atof(argv[10]);
    long steps = lround(duration / h);
    double *rec = malloc(sizeof(double) * 5 * (steps + 1));
    double x[4], best = 1e30;
    int r;
    for (r = 0; r < repeats; r++) {
        double t0 = now();
        run(K, theta0, steps, h, x, rec);
        double dt = now() - t0;
        if (dt < best) best = dt;
    }
    double t0 = now();
    long fell = 0, b;
#pragma omp parallel for reduction(+ : fell) schedule(static)
    for (b = 0; b < batch; b++) {
        double xb[4];
        double th = batch > 1 ? -span + 2.0 * span * b / (batch - 1) : 0.0;
        fell += run(K, th, steps, h, xb, NULL);
    }
    double batch_s = now() - t0;
    int threads = 1;
#ifdef _OPENMP
    threads = omp_get_max_threads();
#endif
    printf("{\"single_s\": %.9g, \"steps\": %ld, \"final\": [%.17g, %.17g, %.17g, %.17g], "
           "\"batch_s\": %.9g, \"batch_runs\": %ld, \"batch_fell\": %ld, \"threads\": %d}\n",
           best, steps, x[0], x[1], x[2], x[3], batch_s, batch, fell, threads);
    free(rec);
    return 0;
}
