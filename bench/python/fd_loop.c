/*
 * The Rust loop the Python overheads are measured against: rbss_forward_dynamics of the 6-UPS
 * called from C on the states python_overhead.py writes (states.bin: k rows of x, xdot, u),
 * the median over 21 passes of the time per call. Built and run by python_overhead.py; with a
 * third argument `cpu`, the thread's CPU time instead of the wall clock (a loaded machine).
 */
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

#include "rbss.h"

static clockid_t clock_id = CLOCK_MONOTONIC;

static double now(void) {
    struct timespec t;
    clock_gettime(clock_id, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

static int cmp(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

int main(int argc, char **argv) {
    if (argc != 3 && argc != 4) return 2;
    if (argc == 4) clock_id = CLOCK_THREAD_CPUTIME_ID;
    size_t k = (size_t)atol(argv[2]);
    rbss_robot *h = rbss_new();
    size_t n = rbss_size(h, RBSS_COORDINATES), m = rbss_size(h, RBSS_CONSTRAINTS);
    size_t a = rbss_size(h, RBSS_ACTUATED), row = 2 * n + a;
    double *s = malloc(k * row * sizeof *s), *xddot = malloc(n * sizeof *xddot);
    double *lambda = malloc(m * sizeof *lambda), t[21];
    FILE *f = fopen(argv[1], "rb");
    if (!f || fread(s, sizeof *s, k * row, f) != k * row) return 1;
    fclose(f);
    for (int p = 0; p < 21; p++) {
        double t0 = now();
        for (size_t i = 0; i < k; i++) {
            const double *r = s + i * row;
            if (rbss_forward_dynamics(h, r, r + n, r + 2 * n, xddot, lambda)) return 1;
        }
        t[p] = (now() - t0) / k;
    }
    qsort(t, 21, sizeof *t, cmp);
    printf("%.1f\n", t[10] * 1e9);
    rbss_free(h);
    return 0;
}
