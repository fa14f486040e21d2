/* bench_gemm: tn_sgemm GFLOP/s, measured like shared/peers/sgemm_bench.c (OpenBLAS) so the two
   compare directly: same shapes, same data, warm-up, then the median of 7 runs, each repeating
   the call until >= 0.2 s.
   Usage: bin/bench_gemm [--threads N]   (without --threads: 1 and 2 threads)
   Prints: sgemm_<case>_t<N>: X GFLOP/s (min a max b, runs r) */
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

static void bench(int M, int N, int K, const char *tag, int threads)
{
    float *A = bench_alloc((size_t)M * K), *B = bench_alloc((size_t)K * N), *C = bench_alloc((size_t)M * N);
    double g[BENCH_RUNS], flop = 2.0 * M * N * K;
    size_t i;
    int r;
    for (i = 0; i < (size_t)M * K; i++) A[i] = (float)((i * 7) % 13) / 13.f - 0.5f;
    for (i = 0; i < (size_t)K * N; i++) B[i] = (float)((i * 5) % 11) / 11.f - 0.5f;
    memset(C, 0, sizeof(float) * (size_t)M * N);
    tn_set_threads(threads);
    tn_sgemm(0, 0, M, N, K, 1.f, A, K, B, N, 0.f, C, N); /* warm-up: pool, scratch, caches */
    for (r = 0; r < BENCH_RUNS; r++) {
        int reps = 0;
        double t0 = tn_time_seconds(), t;
        do {
            tn_sgemm(0, 0, M, N, K, 1.f, A, K, B, N, 0.f, C, N);
            reps++;
            t = tn_time_seconds() - t0;
        } while (t < 0.2);
        g[r] = flop * reps / t / 1e9;
    }
    qsort(g, BENCH_RUNS, sizeof(double), bench_cmp);
    printf("sgemm_%s_t%d: %.1f GFLOP/s (min %.1f max %.1f, runs %d)\n", tag, threads, g[BENCH_RUNS / 2], g[0],
           g[BENCH_RUNS - 1], BENCH_RUNS);
    fflush(stdout);
    free(A);
    free(B);
    free(C);
}

static void bench_all(int threads)
{
    static const int sq[4] = {256, 512, 1024, 2048};
    char tag[64];
    int i;
    for (i = 0; i < 4; i++) {
        snprintf(tag, sizeof tag, "%d", sq[i]);
        bench(sq[i], sq[i], sq[i], tag, threads);
    }
    bench(64, 16384, 576, "convlike_M64_N16384_K576", threads);
}

int main(int argc, char **argv)
{
    int threads = 0;
    if (argc == 3 && strcmp(argv[1], "--threads") == 0) threads = atoi(argv[2]);
    if (argc != 1 && threads <= 0) {
        fprintf(stderr, "usage: %s [--threads N]\n", argv[0]);
        return 2;
    }
    if (threads > 0) {
        bench_all(threads);
    } else {
        bench_all(1);
        bench_all(2);
    }
    return 0;
}
