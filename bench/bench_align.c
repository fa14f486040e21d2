/* bench_align: sketch-part alignment (paper 000, section 5.3) of 200 sketch parts against 2000
   DEM contour parts, 1 and 2 threads, plus the random-sketch and contour-part stages that feed it.
   Parts are cut from random sketches (8-connected pixel chains, like extracted contours).
   No peer implementation exists; the target is "well under a second".
   Prints `align_200x2000_t<N>: X ms` (median), `align_200x2000: X ms` (best thread count),
   `sketch_random_1024: X ms` and `contour_parts: X ms`. */
#include "terrainnet.h"
#include <string.h>
#include <stdio.h>
#include <stdlib.h>

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* Parts of a random sketch, at least `want` of them (the count is then cut to want). */
static int make_parts(uint64_t seed, int want, tn_contour_set *parts, double *ms_random, double *ms_parts)
{
    tn_contour_set s = {0, 0, 0, NULL};
    tn_sketch_random_opts o;
    double t0;
    int i;
    memset(&o, 0, sizeof o);
    o.seed = seed;
    o.nodes = 1024;
    t0 = tn_time_seconds();
    if (tn_sketch_random(&s, NULL, 1024, 1024, &o)) return 0;
    if (ms_random) *ms_random = (tn_time_seconds() - t0) * 1e3;
    t0 = tn_time_seconds();
    if (tn_contour_parts_make(parts, &s, seed)) return 0;
    if (ms_parts) *ms_parts = (tn_time_seconds() - t0) * 1e3;
    tn_contour_set_free(&s);
    if (parts->count < want) return 0;
    for (i = want; i < parts->count; i++) tn_free(parts->items[i].points);
    parts->count = want;
    return 1;
}

int main(void)
{
    enum { RUNS = 7 };
    tn_contour_set dem = {0, 0, 0, NULL}, sk = {0, 0, 0, NULL};
    tn_align_opts o;
    double ms[RUNS], best = 1e30, ms_random = 0, ms_parts = 0;
    int match[200], t, r;
    if (!make_parts(1, 2000, &dem, &ms_random, &ms_parts) || !make_parts(2, 200, &sk, NULL, NULL)) {
        fprintf(stderr, "bench_align: setup failed: %s\n", tn_last_error());
        return 1;
    }
    printf("sketch_random_1024: %.1f ms (1024 nodes, 1024 x 1024 canvas)\n", ms_random);
    printf("contour_parts: %.2f ms\n", ms_parts);
    memset(&o, 0, sizeof o);
    o.seed = 5;
    for (t = 1; t <= 2; t++) {
        tn_set_threads(t);
        for (r = 0; r < RUNS; r++) {
            double t0 = tn_time_seconds();
            if (tn_sketch_align(match, &sk, &dem, &o)) { fprintf(stderr, "%s\n", tn_last_error()); return 1; }
            ms[r] = (tn_time_seconds() - t0) * 1e3;
        }
        qsort(ms, RUNS, sizeof ms[0], cmp_double);
        printf("align_200x2000_t%d: %.2f ms (min %.2f max %.2f, runs %d)\n", t, ms[RUNS / 2], ms[0], ms[RUNS - 1], RUNS);
        if (ms[RUNS / 2] < best) best = ms[RUNS / 2];
    }
    printf("align_200x2000: %.2f ms\n", best);
    tn_contour_set_free(&dem);
    tn_contour_set_free(&sk);
    return 0;
}
