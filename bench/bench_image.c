/* bench_image.c - Gaussian blur and SSIM timings against the peers in /work/shared/peers
   (gaussian_blur.py: scipy sigma 8 on 4096x4096x3 HWC; ssim_bench.py: skimage 1024x1024).
   Prints `name_t<N>: median ms (min a max b, runs r)` for N = 1 and 2 threads.
   Build: cc -std=c99 -O2 -march=native -I.. bench_image.c <tu with TERRAINNET_IMPLEMENTATION> -lm -pthread */
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int bi_cmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static void bi_report(const char *name, int threads, double *ms, int runs, const char *extra)
{
    qsort(ms, (size_t)runs, sizeof *ms, bi_cmp);
    printf("%s_t%d: %.1f ms (min %.1f max %.1f, runs %d)%s\n", name, threads, ms[runs / 2], ms[0], ms[runs - 1], runs,
           extra);
    fflush(stdout);
}

static void bi_fill_uniform(tn_image *img, uint64_t seed)
{
    tn_rng r;
    size_t i, n = (size_t)img->width * img->height * img->channels;
    tn_rng_seed(&r, seed, 1);
    for (i = 0; i < n; i++) img->data[i] = tn_rng_uniform(&r);
}

int main(int argc, char **argv)
{
    int runs = argc > 1 ? atoi(argv[1]) : 7, t, k;
    double ms[64];
    tn_image big = {0, 0, 0, NULL}, out = {0, 0, 0, NULL}, a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_rng r;
    size_t i;
    if (runs < 1 || runs > 64) runs = 7;
    if (tn_image_create(&big, 4096, 4096, 3) || tn_image_create(&a, 1024, 1024, 1) || tn_image_create(&b, 1024, 1024, 1)) {
        fprintf(stderr, "%s\n", tn_last_error());
        return 1;
    }
    bi_fill_uniform(&big, 1);
    /* like ssim_bench.py: b = clip(a + 0.1 N(0, 1), 0, 1) */
    bi_fill_uniform(&a, 2);
    tn_rng_seed(&r, 3, 1);
    for (i = 0; i < (size_t)1024 * 1024; i++) {
        float v = a.data[i] + 0.1f * tn_rng_normal(&r);
        b.data[i] = v < 0.0f ? 0.0f : (v > 1.0f ? 1.0f : v);
    }
    for (t = 1; t <= 2; t++) {
        double s = 0.0;
        char extra[64];
        tn_set_threads(t);
        /* the API as called: a fresh *dst every time (allocation and page faults included) */
        for (k = -1; k < runs; k++) {
            double t0 = tn_time_seconds();
            if (tn_image_blur(&out, &big, 8.0f)) return 1;
            if (k >= 0) ms[k] = 1e3 * (tn_time_seconds() - t0);
            tn_image_free(&out);
        }
        bi_report("blur_sigma8_4096x4096x3", t, ms, runs, "");
        /* in place on a warm buffer, the closest match to scipy's output= call */
        if (tn_image_copy(&out, &big)) return 1;
        for (k = -1; k < runs; k++) {
            double t0 = tn_time_seconds();
            if (tn_image_blur(&out, &out, 8.0f)) return 1;
            if (k >= 0) ms[k] = 1e3 * (tn_time_seconds() - t0);
        }
        tn_image_free(&out);
        bi_report("blur_sigma8_4096x4096x3_inplace", t, ms, runs, "");
        for (k = -1; k < runs; k++) {
            double t0 = tn_time_seconds();
            if (tn_ssim(&s, &a, &b, 1.0)) return 1;
            if (k >= 0) ms[k] = 1e3 * (tn_time_seconds() - t0);
        }
        snprintf(extra, sizeof extra, " [ssim=%.6f]", s);
        bi_report("ssim_1024", t, ms, runs, extra);
    }
    tn_image_free(&big);
    tn_image_free(&a);
    tn_image_free(&b);
    return 0;
}
