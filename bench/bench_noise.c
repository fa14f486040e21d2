/* bench_noise: Perlin fBm (8 octaves) and explicit noise on a 2048 x 2048 map, 1 and 2 threads.
   Compare with ../shared/peers/run_perlin.sh (stb_perlin_fbm_noise3, libnoise) in the same run.
   Prints `noise_perlin_fbm8_2048_t<N>: X ms` (median) and `..._msamples_t<N>: X Msamples/s`. */
#include "terrainnet.h"
#include <string.h>
#include <stdio.h>
#include <stdlib.h>

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

int main(void)
{
    enum { RUNS = 7, N = 2048 };
    double ms[RUNS];
    int t, r;
    for (t = 1; t <= 2; t++) {
        tn_perlin_opts po;
        tn_set_threads(t);
        memset(&po, 0, sizeof po);
        po.octaves = 8;
        for (r = 0; r < RUNS; r++) {
            tn_image img = {0, 0, 0, NULL};
            double t0 = tn_time_seconds();
            if (tn_noise_perlin(&img, N, N, &po)) { fprintf(stderr, "%s\n", tn_last_error()); return 1; }
            ms[r] = (tn_time_seconds() - t0) * 1e3;
            tn_image_free(&img);
        }
        qsort(ms, RUNS, sizeof ms[0], cmp_double);
        printf("noise_perlin_fbm8_%d_t%d: %.1f ms (min %.1f max %.1f, runs %d)\n", N, t, ms[RUNS / 2], ms[0], ms[RUNS - 1], RUNS);
        printf("noise_perlin_fbm8_%d_msamples_t%d: %.1f Msamples/s\n", N, t, (double)N * N / (ms[RUNS / 2] * 1e3));
        for (r = 0; r < 3; r++) {
            tn_image img = {0, 0, 0, NULL};
            double t0 = tn_time_seconds();
            if (tn_noise_explicit(&img, N, N, NULL)) { fprintf(stderr, "%s\n", tn_last_error()); return 1; }
            ms[r] = (tn_time_seconds() - t0) * 1e3;
            tn_image_free(&img);
        }
        qsort(ms, 3, sizeof ms[0], cmp_double);
        printf("noise_explicit_%d_t%d: %.1f ms (min %.1f max %.1f, runs 3)\n", N, t, ms[1], ms[0], ms[2]);
        fflush(stdout);
    }
    return 0;
}
