/* bench_gemm: tn_sgemm GFLOP/s, measured like shared/peers/sgemm_bench.c (OpenBLAS) so the two
   compare directly: same shapes, same data, warm-up, then the median of 7 runs, each repeating
   the call until >= 0.2 s. Then the bf16 products (tn_gemm(TN_PRECISION_BF16, ...)) at 1024 and
   on the convolution shape, on the CPU's best bf16 kernel and on every other one it has
   (emulated always), each with its ratio to float32 from the same run.
   Usage: bin/bench_gemm [--threads N] [--quick]   (without --threads: 1 and 2 threads;
          --quick: 1024 only)
   Prints: sgemm_<case>_t<N>: X GFLOP/s (min a max b, runs r)
           gemm_bf16[_<kernel>]_<case>_t<N>: X GFLOP/s (...; kernel, Y x fp32)
   bench/gemm_bf16_vs_torch.sh runs PyTorch's bf16 matmul (the peer) and this in one go. */
#define TN_INTERNALS /* private tn__ code: the header's internals block */
#include "terrainnet.h"
#include <string.h>
#include <stdlib.h>
#include <stdio.h>

#define BENCH_RUNS 7

static int bench_cmp(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static float *bench_alloc(size_t n)
{
    float *p = (float *)malloc(n * sizeof(float) + 64);
    if (!p) {
        fprintf(stderr, "bench_gemm: out of memory\n");
        exit(1);
    }
    return p;
}

/* Median GFLOP/s of C = A B in `prec` (bf16: on kernel `force`, 0 = the best), printed as
   <prefix>_<tag>_t<threads>. */
static double bench(int M, int N, int K, const char *tag, int threads, tn_precision prec, int force, const char *prefix,
                    double fp32_rate)
{
    float *A = bench_alloc((size_t)M * K), *B = bench_alloc((size_t)K * N), *C = bench_alloc((size_t)M * N);
    double g[BENCH_RUNS], flop = 2.0 * M * N * K;
    size_t i;
    int r;
    for (i = 0; i < (size_t)M * K; i++) A[i] = (float)((i * 7) % 13) / 13.f - 0.5f;
    for (i = 0; i < (size_t)K * N; i++) B[i] = (float)((i * 5) % 11) / 11.f - 0.5f;
    memset(C, 0, sizeof(float) * (size_t)M * N);
    tn_set_threads(threads);
    tn__gemm_bf16_force = force;
    tn_gemm(prec, 0, 0, M, N, K, 1.f, A, K, B, N, 0.f, C, N); /* warm-up: pool, scratch, caches */
    for (r = 0; r < BENCH_RUNS; r++) {
        int reps = 0;
        double t0 = tn_time_seconds(), t;
        do {
            tn_gemm(prec, 0, 0, M, N, K, 1.f, A, K, B, N, 0.f, C, N);
            reps++;
            t = tn_time_seconds() - t0;
        } while (t < 0.2);
        g[r] = flop * reps / t / 1e9;
    }
    qsort(g, BENCH_RUNS, sizeof(double), bench_cmp);
    printf("%s_%s_t%d: %.1f GFLOP/s (min %.1f max %.1f, runs %d", prefix, tag, threads, g[BENCH_RUNS / 2], g[0],
           g[BENCH_RUNS - 1], BENCH_RUNS);
    if (prec == TN_PRECISION_BF16) printf("; %s, %.2f x fp32", tn_gemm_bf16_kernel(), g[BENCH_RUNS / 2] / fp32_rate);
    printf(")\n");
    fflush(stdout);
    tn__gemm_bf16_force = 0;
    free(A);
    free(B);
    free(C);
    return g[BENCH_RUNS / 2];
}

/* fp32 then bf16 on each kernel this CPU has, same shape, same run. */
static void bench_bf16(int M, int N, int K, const char *tag, int threads)
{
    unsigned f = tn_cpu_features();
    double fp32 = bench(M, N, K, tag, threads, TN_PRECISION_FP32, 0, "sgemm", 0);
    bench(M, N, K, tag, threads, TN_PRECISION_BF16, 0, "gemm_bf16", fp32);
    if (f & TN_CPU_AMX_BF16) bench(M, N, K, tag, threads, TN_PRECISION_BF16, TN__KERN_AVX512BF16, "gemm_bf16_avx512", fp32);
    if (f & (TN_CPU_AMX_BF16 | TN_CPU_AVX512_BF16)) bench(M, N, K, tag, threads, TN_PRECISION_BF16, TN__KERN_EMU, "gemm_bf16_emulated", fp32);
}

static void bench_all(int threads, int quick)
{
    static const int sq[4] = {256, 512, 1024, 2048};
    char tag[64];
    int i;
    for (i = 0; i < 4 && !quick; i++) {
        if (sq[i] == 1024) continue; /* with bf16 below */
        snprintf(tag, sizeof tag, "%d", sq[i]);
        bench(sq[i], sq[i], sq[i], tag, threads, TN_PRECISION_FP32, 0, "sgemm", 0);
    }
    bench_bf16(1024, 1024, 1024, "1024", threads);
    if (!quick) bench_bf16(64, 16384, 576, "convlike_M64_N16384_K576", threads);
}

int main(int argc, char **argv)
{
    int threads = 0, quick = 0, a;
    for (a = 1; a < argc; a++) {
        if (!strcmp(argv[a], "--threads") && a + 1 < argc && atoi(argv[a + 1]) > 0) threads = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--quick")) quick = 1;
        else {
            fprintf(stderr, "usage: %s [--threads N] [--quick]\n", argv[0]);
            return 2;
        }
    }
    printf("# cpu features 0x%x, bf16 kernel %s\n", tn_cpu_features(), tn_gemm_bf16_kernel());
    if (threads > 0) {
        bench_all(threads, quick);
    } else {
        bench_all(1, quick);
        bench_all(2, quick);
    }
    return 0;
}
