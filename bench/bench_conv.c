/* bench_conv: conv2d 3x3 (batch 1, with bias) forward and forward+backward (input, weight and
   bias gradients) in milliseconds: padding 1 on the shapes of ../shared/peers/torch_conv2d.py,
   then SinGAN's (valid 3x3 convolutions of 32 channels, 1 channel in and out at the ends) at its
   finest scale of a 256 px example (268 px in, 266 out; _p0 in the names).
   Each in float32, then with bf16 GEMM operands (tn_set_precision(TN_PRECISION_BF16)) in the same
   run, with the float32 time over the bf16 time.
   Usage: bin/bench_conv [--threads N] [--runs R] [--fp32]   (no --threads: 1 and 2; --fp32: no bf16)
   Prints: conv_fwd_<shape>_t<N>: X ms and conv_fwdbwd_<shape>_t<N>: X ms (medians), and
           conv_bf16_fwd_<shape>_t<N>: X ms (...; kernel, fp32/bf16 = Y x) likewise. */
#ifndef TN_BENCH_TU
#include "terrainnet.h"
#else
#include TN_BENCH_TU
#endif
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double run_once(tn_ctx *ctx, tn_tensor *x, tn_tensor *w, tn_tensor *b, int backward, int pad)
{
    tn_conv_opts o;
    tn_tensor *y;
    double t0 = tn_time_seconds();
    memset(&o, 0, sizeof o);
    o.pad = pad;
    tn_ctx_reset(ctx);
    tn_ctx_set_grad(ctx, backward);
    y = tn_conv2d(ctx, x, w, b, &o);
    if (backward) {
        memset(x->grad, 0, x->numel * sizeof(float));
        memset(w->grad, 0, w->numel * sizeof(float));
        memset(b->grad, 0, b->numel * sizeof(float));
        tn_backward(ctx, tn_sum(ctx, y));
    }
    return (tn_time_seconds() - t0) * 1e3;
}

int main(int argc, char **argv)
{
    static const struct { const char *name; int ci, co, hw, pad; } shapes[6] = {
        {"c32to32_3x3_128", 32, 32, 128, 1}, {"c64to64_3x3_256", 64, 64, 256, 1}, {"c3to64_3x3_512", 3, 64, 512, 1},
        {"c32to32_3x3_p0_268", 32, 32, 268, 0}, {"c1to32_3x3_p0_268", 1, 32, 268, 0}, {"c32to1_3x3_p0_268", 32, 1, 268, 0}};
    int threads[2] = {1, 2}, nthreads = 2, runs = 11, nprec = 2, a, s, t, r, bw, pr;
    for (a = 1; a < argc; a++) {
        if (!strcmp(argv[a], "--threads") && a + 1 < argc) { threads[0] = atoi(argv[++a]); nthreads = 1; }
        else if (!strcmp(argv[a], "--runs") && a + 1 < argc) runs = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--fp32")) nprec = 1;
        else { fprintf(stderr, "usage: bench_conv [--threads N] [--runs R] [--fp32]\n"); return 2; }
    }
    if (runs < 1 || runs > 1000 || threads[0] < 1) { fprintf(stderr, "bench_conv: bad arguments\n"); return 2; }
    for (t = 0; t < nthreads; t++) {
        tn_set_threads(threads[t]);
        for (s = 0; s < 6; s++) {
            tn_ctx *pc = tn_ctx_create(), *ctx = tn_ctx_create();
            tn_rng rng;
            tn_tensor *x = tn_tensor_requires_grad(pc, tn_tensor_4d(pc, 1, shapes[s].ci, shapes[s].hw, shapes[s].hw));
            tn_tensor *w = tn_tensor_requires_grad(pc, tn_tensor_4d(pc, shapes[s].co, shapes[s].ci, 3, 3));
            tn_tensor *b = tn_tensor_requires_grad(pc, tn_tensor_1d(pc, shapes[s].co));
            double *ms = (double *)malloc(sizeof(double) * (size_t)runs);
            tn_rng_seed(&rng, 1, 1);
            tn_init_uniform(x, &rng, -1, 1);
            tn_init_kaiming(w, &rng, 1.0f);
            for (bw = 0; bw < 2; bw++) {
                double fp32_ms = 0;
                for (pr = 0; pr < nprec; pr++) {
                    tn_set_precision(pr ? TN_PRECISION_BF16 : TN_PRECISION_FP32);
                    run_once(ctx, x, w, b, bw, shapes[s].pad); /* warm-up: sizes the arena */
                    run_once(ctx, x, w, b, bw, shapes[s].pad);
                    for (r = 0; r < runs; r++) ms[r] = run_once(ctx, x, w, b, bw, shapes[s].pad);
                    qsort(ms, (size_t)runs, sizeof(double), cmp_double);
                    printf("conv_%s%s_%s_t%d: %.3f ms (min %.3f max %.3f, runs %d", pr ? "bf16_" : "", bw ? "fwdbwd" : "fwd",
                           shapes[s].name, threads[t], ms[runs / 2], ms[0], ms[runs - 1], runs);
                    if (pr) printf("; %s, fp32/bf16 = %.2f x", tn_gemm_bf16_kernel(), fp32_ms / ms[runs / 2]);
                    printf(")\n");
                    fflush(stdout);
                    fp32_ms = ms[runs / 2];
                }
                tn_set_precision(TN_PRECISION_AUTO);
            }
            free(ms);
            tn_ctx_free(ctx);
            tn_ctx_free(pc);
        }
    }
    return 0;
}
