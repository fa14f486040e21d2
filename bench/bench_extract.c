/* bench_extract: fill + D8 + accumulation per stage on a 4096 x 4096 DEM, then the whole
   extraction pipeline, 1 and 2 threads; GRASS r.watershed -s on the same DEM in the same run.
   DEM: /tmp/peers_data/dem4096.f32 (../shared/peers/make_dem.c, what d8_grass.sh uses) when it
   exists, else terrainnet's own Perlin fBm x 100 + 0.05 (x + y), written there as raw float32.
   Prints `extract_<stage>_4096_t<N>: X ms` (median of 3 wall), `extract_<stage>_cpu_...` (process CPU
   time, less sensitive to a shared machine) and GRASS as `grass_rwatershed_sfd_4096: X ms`.
   TN_BENCH_GRASS=0 skips GRASS; TN_BENCH_SIZE=N changes the size; TN_BENCH_RUNS=N takes the
   median of N runs (3, at most 15); TN_BENCH_THREADS=T times only T threads; TN_BENCH_PIPELINE=0
   skips the whole-pipeline runs (for quick interleaved comparisons on a shared machine). */
#include "terrainnet.h"
#include <string.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static int die(void)
{
    fprintf(stderr, "bench_extract: %s\n", tn_last_error());
    return 1;
}

int main(void)
{
    enum { MAXRUNS = 15 };
    const char *env = getenv("TN_BENCH_SIZE"), *e_runs = getenv("TN_BENCH_RUNS"), *e_thr = getenv("TN_BENCH_THREADS"),
               *e_pipe = getenv("TN_BENCH_PIPELINE");
    int N = env ? atoi(env) : 4096, t, r, RUNS = e_runs ? atoi(e_runs) : 3, tlo = 1, thi = 2;
    char path[256];
    tn_image dem = {0, 0, 0, NULL};
    FILE *f;
    size_t n;
    if (N < 16 || N > 16384) N = 4096;
    if (RUNS < 1 || RUNS > MAXRUNS) RUNS = 3;
    if (e_thr && atoi(e_thr) >= 1) tlo = thi = atoi(e_thr);
    n = (size_t)N * N;
    snprintf(path, sizeof path, "/tmp/peers_data/dem%d.f32", N);
    if (tn_image_create(&dem, N, N, 1)) return die();
    f = fopen(path, "rb");
    if (f && fread(dem.data, sizeof(float), n, f) == n) {
        printf("# DEM: %s (make_dem.c)\n", path);
    } else {
        tn_perlin_opts po;
        tn_image noise = {0, 0, 0, NULL};
        size_t i;
        memset(&po, 0, sizeof po);
        po.octaves = 8;
        po.frequency = (float)N * 8.0f / 1024.0f;
        if (tn_noise_perlin(&noise, N, N, &po)) return die();
        for (i = 0; i < n; i++) dem.data[i] = 100.0f * noise.data[i] + 0.05f * (float)(i % (size_t)N + i / (size_t)N);
        tn_image_free(&noise);
        if (system("mkdir -p /tmp/peers_data") == 0 && (f = fopen(path, "wb")) != NULL) {
            if (fwrite(dem.data, sizeof(float), n, f) != n) printf("# could not write %s\n", path);
            fclose(f);
        }
        f = NULL;
        printf("# DEM: terrainnet Perlin fBm, written to %s\n", path);
    }
    if (f) fclose(f);
    for (t = tlo; t <= thi; t++) {
        double ms[4][MAXRUNS], cpu[4][MAXRUNS];
        const char *names[4] = {"fill", "d8", "accumulation", "fill_d8_acc"};
        int k;
        tn_set_threads(t);
        for (r = 0; r < RUNS; r++) {
            tn_image filled = {0, 0, 0, NULL};
            tn_flow flow;
            double t0 = tn_time_seconds(), t1, t2, t3;
            clock_t c0 = clock(), c1, c2, c3;
            if (tn_fill_depressions(&filled, &dem)) return die();
            t1 = tn_time_seconds();
            c1 = clock();
            if (tn_flow_directions(&flow, &filled)) return die();
            t2 = tn_time_seconds();
            c2 = clock();
            if (tn_flow_accumulation(&flow)) return die();
            t3 = tn_time_seconds();
            c3 = clock();
            cpu[0][r] = 1e3 * (double)(c1 - c0) / CLOCKS_PER_SEC;
            cpu[1][r] = 1e3 * (double)(c2 - c1) / CLOCKS_PER_SEC;
            cpu[2][r] = 1e3 * (double)(c3 - c2) / CLOCKS_PER_SEC;
            cpu[3][r] = 1e3 * (double)(c3 - c0) / CLOCKS_PER_SEC;
            ms[0][r] = (t1 - t0) * 1e3;
            ms[1][r] = (t2 - t1) * 1e3;
            ms[2][r] = (t3 - t2) * 1e3;
            ms[3][r] = (t3 - t0) * 1e3;
            if (r == 0 && t == tlo) {
                uint32_t mx = 0;
                size_t i;
                for (i = 0; i < n; i++) if (flow.acc[i] > mx) mx = flow.acc[i];
                printf("# accumulation max %u cells\n", mx);
            }
            tn_image_free(&filled);
            tn_flow_free(&flow);
        }
        for (k = 0; k < 4; k++) {
            qsort(ms[k], RUNS, sizeof(double), cmp_double);
            qsort(cpu[k], RUNS, sizeof(double), cmp_double);
            printf("extract_%s_%d_t%d: %.1f ms (min %.1f max %.1f, runs %d)\n", names[k], N, t, ms[k][RUNS / 2], ms[k][0],
                   ms[k][RUNS - 1], RUNS);
            /* process CPU time: a shared machine inflates wall time; at 1 thread CPU ~ an idle core's wall */
            printf("extract_%s_cpu_%d_t%d: %.1f ms (min %.1f, all threads)\n", names[k], N, t, cpu[k][RUNS / 2], cpu[k][0]);
        }
        if (!(e_pipe && e_pipe[0] == '0')) {
            tn_extraction ex;
            double s0 = tn_time_seconds();
            if (tn_extract(&ex, &dem, NULL)) return die();
            printf("extract_full_pipeline_%d_t%d: %.1f ms (valleys + ridges, %d contours, runs 1)\n", N, t,
                   (tn_time_seconds() - s0) * 1e3, ex.contours.count);
            tn_extraction_free(&ex);
        }
        fflush(stdout);
    }
    tn_image_free(&dem);
    env = getenv("TN_BENCH_GRASS");
    if (!(env && env[0] == '0')) {
        char cmd[512];
        fflush(stdout);
        snprintf(cmd, sizeof cmd, "sh bench/grass_watershed.sh %s %d", path, N);
        if (system(cmd) != 0) printf("# GRASS run failed or grass is not installed (see bench/grass_watershed.sh)\n");
    }
    return 0;
}
