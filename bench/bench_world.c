/* bench_world: a terrainnet world in tiles, in 1 and 2 processes (fork; the same split as
   `terrainnet world --part K/N`, MPI ranks or a job array), and a big world with GDAL reading it.
   Usage: bin/bench_world [BIG_SIDE [DIR]]   (defaults 16384 and build/bench_world)
   Prints `name: value unit` lines:
     world_scale_<side>_p1 / _p2: tiles/s of 512 px Perlin + hillshade tiles, 1 thread per process
     world_big_<side>_*: wall time, tiles/s, peak RSS of a process, tile bytes, gdalinfo -stats time
     world_arith_65536_*: ARITHMETIC from the measured per-process rate, not a measurement.
   Each run's tiles are checked against the 1-process run (manifest digests). */
#define _POSIX_C_SOURCE 200809L /* popen, fork */
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

/* CPU seconds (user + system) of the waited-for children so far. */
static double children_cpu(void)
{
    struct rusage ru;
    getrusage(RUSAGE_CHILDREN, &ru);
    return ru.ru_utime.tv_sec + ru.ru_stime.tv_sec + 1e-6 * (ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
}

/* Runs the world's tiles in `procs` forked processes (one thread each) into dir; seconds, or -1. */
static double run_procs(const tn_world *w, const char *dir, int procs)
{
    double t0 = tn_time_seconds();
    int p, ok = 1, status;
    mkdir(dir, 0777);
    for (p = 0; p < procs; p++) {
        pid_t pid = fork();
        if (pid == 0) {
            tn_world_run_opts ro;
            memset(&ro, 0, sizeof ro);
            ro.part = p;
            ro.parts = procs;
            tn_set_threads(1);
            if (tn_world_write_tiles(dir, w, &ro, NULL)) {
                fprintf(stderr, "part %d: %s\n", p, tn_last_error());
                _exit(1);
            }
            _exit(0);
        }
        if (pid < 0) ok = 0;
    }
    while (wait(&status) > 0)
        if (!WIFEXITED(status) || WEXITSTATUS(status)) ok = 0;
    return ok ? tn_time_seconds() - t0 : -1;
}

/* The manifest's tile lines (after "grid"), for comparing runs. */
static char *tile_digests(const char *dir)
{
    char path[1100], *buf, *p;
    long n;
    FILE *f;
    snprintf(path, sizeof path, "%s/manifest.txt", dir);
    if (!(f = fopen(path, "rb"))) return NULL;
    fseek(f, 0, SEEK_END);
    n = ftell(f);
    fseek(f, 0, SEEK_SET);
    buf = (char *)calloc((size_t)n + 1, 1);
    if (buf && fread(buf, 1, (size_t)n, f) != (size_t)n) buf[0] = 0;
    fclose(f);
    p = buf ? strstr(buf, "\nr0_c0.png") : NULL;
    if (p) memmove(buf, p, strlen(p) + 1);
    return buf;
}

static int clear_dir(const char *dir)
{
    char cmd[1200];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    return system(cmd);
}

int main(int argc, char **argv)
{
    int big = argc > 1 ? atoi(argv[1]) : 16384, p, present;
    const char *root = argc > 2 ? argv[2] : "build/bench_world";
    char spec[512], dir[512], *ref = NULL;
    double rate_big = 0, cpu_tile = 0, t, c0;
    tn_world w;
    tn_world_opts wo;
    struct rusage ru;
    if (big < 1024) big = 1024;
    mkdir("build", 0777);
    mkdir(root, 0777);
    memset(&wo, 0, sizeof wo);
    /* scaling: a 4096 x 4096 world of 64 tiles, 1 and 2 processes */
    snprintf(spec, sizeof spec, "world 4096 4096\nseed 3\nheight 0 4000\ncellsize 30\ntile 512\nperlin frequency=8 octaves=10\nhillshade\n");
    if (tn_world_parse(&w, spec, &wo)) { fprintf(stderr, "%s\n", tn_last_error()); return 1; }
    for (p = 1; p <= 2; p++) {
        char *dig;
        snprintf(dir, sizeof dir, "%s/scale_p%d", root, p);
        clear_dir(dir);
        c0 = children_cpu();
        if ((t = run_procs(&w, dir, p)) < 0 || tn_world_write_index(dir, &w, &present)) { fprintf(stderr, "scale run failed\n"); return 1; }
        printf("world_scale_4096_p%d: %.3f tiles/s (%d tiles of 512 px in %.2f s; %.1f CPU s)\n", p, w.rows * w.cols / t, w.rows * w.cols, t,
               children_cpu() - c0);
        dig = tile_digests(dir);
        if (p == 1) ref = dig;
        else {
            printf("world_scale_4096_p2_tiles_identical_to_p1: %d bool\n", dig && ref && !strcmp(dig, ref));
            free(dig);
        }
    }
    free(ref);
    tn_world_free(&w);
    /* the big world: Perlin heights in 1024 px tiles, 2 processes */
    snprintf(spec, sizeof spec, "world %d %d\nseed 7\nheight 0 4000\ncellsize 30\ntile 1024\nperlin frequency=16 octaves=12\n", big, big);
    if (tn_world_parse(&w, spec, &wo)) { fprintf(stderr, "%s\n", tn_last_error()); return 1; }
    snprintf(dir, sizeof dir, "%s/big_%d", root, big);
    clear_dir(dir);
    c0 = children_cpu();
    if ((t = run_procs(&w, dir, 2)) < 0 || tn_world_write_index(dir, &w, &present)) { fprintf(stderr, "big run failed\n"); return 1; }
    cpu_tile = (children_cpu() - c0) / (w.rows * w.cols);
    getrusage(RUSAGE_CHILDREN, &ru);
    printf("world_big_%d_cpu_seconds_per_tile: %.2f s (user + system of the 2 processes / tiles)\n", big, cpu_tile);
    printf("world_big_%d_seconds_p2: %.1f s (%d tiles of 1024 px)\n", big, t, w.rows * w.cols);
    rate_big = w.rows * w.cols / t;
    printf("world_big_%d_tiles_per_s_p2: %.3f tiles/s\n", big, rate_big);
    printf("world_big_%d_mpixels_per_s_p2: %.2f Mpx/s\n", big, (double)big * big / t / 1e6);
    printf("world_big_%d_peak_rss_per_process: %.1f MiB (largest child, ru_maxrss)\n", big, ru.ru_maxrss / 1024.0);
    {
        char cmd[1400]; /* dir is at most 511 bytes */
        FILE *f;
        snprintf(cmd, sizeof cmd, "du -sk '%s' | cut -f1", dir);
        if ((f = popen(cmd, "r"))) {
            long kb = 0;
            if (fscanf(f, "%ld", &kb) == 1) printf("world_big_%d_disk: %.1f MiB (16-bit PNG tiles)\n", big, kb / 1024.0);
            pclose(f);
        }
        snprintf(cmd, sizeof cmd, "command -v gdalinfo >/dev/null 2>&1 && gdalinfo -stats '%s/world.vrt' > '%s/gdalinfo.txt' 2>&1", dir, dir);
        t = tn_time_seconds();
        if (system(cmd) == 0) {
            char line[256];
            printf("world_big_%d_gdalinfo_stats_seconds: %.1f s\n", big, tn_time_seconds() - t);
            snprintf(cmd, sizeof cmd, "%s/gdalinfo.txt", dir);
            if ((f = fopen(cmd, "r"))) {
                while (fgets(line, sizeof line, f))
                    if (strstr(line, "Size is") || strstr(line, "Minimum=")) printf("world_big_%d_gdalinfo: %s", big, line + strspn(line, " "));
                fclose(f);
            }
        } else {
            printf("world_big_%d_gdalinfo_stats_seconds: skipped (no gdalinfo)\n", big);
        }
    }
    tn_world_free(&w);
    /* arithmetic, not measurement: 65536^2 = 4096 tiles of 1024 px, from the big run's wall rate
       per process (pessimistic on a shared machine) and from its CPU seconds per tile (one
       process per core with the core to itself) */
    {
        double per_proc = rate_big / 2.0, tiles = 64.0 * 64.0;
        int nodes[] = {1, 8, 64, 512}, k;
        printf("world_arith_note: ARITHMETIC from this run (wall: %.3f tiles/s per process; CPU: %.2f s per tile), not measurements\n",
               per_proc, cpu_tile);
        for (k = 0; k < 4; k++) {
            printf("world_arith_65536_hours_wall_rate_%d_nodes_of_2_cores: %.2f h (ARITHMETIC: %.0f tiles / (%.3f tiles/s x 2 x %d))\n",
                   nodes[k], tiles / (per_proc * 2.0 * nodes[k]) / 3600.0, tiles, per_proc, nodes[k]);
            printf("world_arith_65536_hours_cpu_rate_%d_nodes_of_2_cores: %.2f h (ARITHMETIC: %.0f tiles x %.2f s / (2 x %d))\n", nodes[k],
                   tiles * cpu_tile / (2.0 * nodes[k]) / 3600.0, tiles, cpu_tile, nodes[k]);
        }
    }
    return 0;
}
