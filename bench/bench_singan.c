/* bench_singan.c - SinGAN on heightmaps (@@singan): per DEM of ../shared/data (256 x 256
   examples, 2 threads) it trains a model for a time budget and measures
     - seconds per iteration (all scales, finest scale), next to the PyTorch SinGAN-like step
       (../shared/peers/torch_singan_step.py, run once in the same bench run at 256 px),
     - realism distance (tn_realism_compare) of samples to the example, of another crop of the
       same DEM and of Perlin fBm in the example's range,
     - best SSIM of a 128 px window of a sample against every 128 px crop of the example (copy check),
     - refinement of a blurred copy and of the membrane of the example's own ridges and valleys:
       spectrum distance to the example before / after, SSIM to the input,
     - 4x upscaling of the example downsampled to 64 px: spectrum distance vs bicubic,
     - a 2048 x 2048 sample: time and the child process' peak memory.
   Usage: bench_singan [--minutes M] [--threads N] [--patch P] [--no-peer] [name ...]
   (--patch -1: train whole scales, the work per iteration the PyTorch step does at 256 px)
   (names: mountain canyon dunes moon volcano; default all, M = 10) */
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <sys/resource.h>
#include <unistd.h>

typedef struct demdef { const char *name, *dir; int ox, oy; } demdef; /* another crop of the full DEM, off the example */
static const demdef dems[] = {
    {"mountain", "alps_montblanc", 391, 0},
    {"canyon", "grandcanyon_hoppe8bit", 700, 0},
    {"dunes", "sahara_erg_oriental", 392, 0},
    {"moon", "moon_nearside_lola4ppd", 0, 0},
    {"volcano", "volcano_sthelens_10m", 700, 700},
};

static int load(const char *dir, const char *leaf, tn_image *img)
{
    char path[512];
    const char *root = getenv("TN_DATA");
    snprintf(path, sizeof path, "%s/dem/%s/%s_%s.png", root ? root : "../shared/data", dir, dir, leaf);
    if (tn_image_load(path, img, NULL)) {
        snprintf(path, sizeof path, "/work/shared/data/dem/%s/%s_%s.png", dir, dir, leaf);
        if (tn_image_load(path, img, NULL)) return 0;
    }
    return 1;
}

static double dist(const tn_image *ref, const tn_image *img, int spectrum)
{
    tn_realism r;
    if (tn_realism_compare(ref, img, NULL, &r)) return NAN;
    return spectrum ? r.spectrum_distance : r.distance;
}

static double ssim_of(const tn_image *a, const tn_image *b)
{
    double s = NAN;
    float lo, hi;
    tn_image_range(a, &lo, &hi);
    tn_ssim(a, b, hi - lo, &s);
    return s;
}

/* Best SSIM of a w x w window of s against every w x w crop of ex (stride 4). */
static double best_crop_ssim(const tn_image *ex, const tn_image *win)
{
    double best = -1;
    int x, y, w = win->width;
    for (y = 0; y + w <= ex->height; y += 4)
        for (x = 0; x + w <= ex->width; x += 4) {
            tn_image c = {0, 0, 0, NULL};
            double s;
            tn_image_crop(&c, ex, x, y, w, w);
            s = ssim_of(&c, win);
            if (s > best) best = s;
            tn_image_free(&c);
        }
    return best;
}

static const char *g_argv0;
static int g_patch; /* --patch: 0 = the default (128 px windows), -1 = whole scales */

static void bench_dem(const demdef *d, double minutes, int threads)
{
    tn_image ex = {0, 0, 0, NULL}, full = {0, 0, 0, NULL}, other = {0, 0, 0, NULL}, per = {0, 0, 0, NULL};
    tn_singan m;
    tn_singan_opts o;
    tn_singan_stats st;
    tn_singan_gen_opts g;
    double t0, ds = 0, dc, dp, best = -1;
    float lo, hi;
    int i;
    const char *n = d->name;
    if (!load(d->dir, "256", &ex) || !load(d->dir, "full", &full)) {
        printf("# %s: skipped (no data)\n", n);
        return;
    }
    tn_set_threads(threads);
    memset(&o, 0, sizeof o);
    o.train.minutes = minutes;
    o.train.seed = 1;
    o.patch = g_patch;
    t0 = tn_time_seconds();
    if (tn_singan_train(&ex, &o, &m, &st)) {
        printf("# %s: training failed: %s\n", n, tn_last_error());
        return;
    }
    printf("%s_train_minutes: %.2f min\n", n, (tn_time_seconds() - t0) / 60.0);
    printf("%s_scales: %d scales (trained %d)\n", n, st.scales, st.trained);
    printf("# %s per-scale iterations:", n);
    for (i = 0; i < st.scales; i++) printf(" %ld", st.scale_iters[i]);
    printf("\n%s_iterations: %ld iterations\n", n, st.iterations);
    printf("%s_seconds_per_iteration: %.4f s\n%s_seconds_per_iteration_finest: %.4f s\n", n, st.seconds_per_iter, n, st.seconds_per_iter_finest);
    printf("%s_loss_rec: %.5f (network units^2)\n", n, (double)st.loss_rec);
    /* realism: 3 samples vs another crop vs Perlin in the example's range */
    memset(&g, 0, sizeof g);
    for (i = 0; i < 3; i++) {
        tn_image s = {0, 0, 0, NULL}, w = {0, 0, 0, NULL};
        g.seed = 100 + (uint64_t)i;
        if (tn_singan_sample(&m, 0, 0, 256, 256, &g, &s)) continue;
        ds += dist(&ex, &s, 0) / 3.0;
        if (i == 0) {
            char path[256];
            snprintf(path, sizeof path, "/tmp/bench_singan_%s_sample.png", n);
            tn_image_save(path, &s, NULL);
        }
        tn_image_crop(&w, &s, 64, 64, 128, 128);
        { double b = best_crop_ssim(&ex, &w); if (b > best) best = b; }
        tn_image_free(&w);
        tn_image_free(&s);
    }
    tn_image_crop(&other, &full, d->ox, d->oy, 256, 256);
    dc = dist(&ex, &other, 0);
    {
        tn_perlin_opts po;
        size_t k;
        float plo, phi;
        memset(&po, 0, sizeof po);
        po.seed = 7;
        tn_noise_perlin(&per, 256, 256, &po);
        tn_image_range(&per, &plo, &phi);
        tn_image_range(&ex, &lo, &hi);
        for (k = 0; k < 256 * 256; k++) per.data[k] = lo + (hi - lo) * (per.data[k] - plo) / (phi - plo);
        dp = dist(&ex, &per, 0);
    }
    printf("%s_realism_sample: %.3f distance (mean of 3 seeds)\n%s_realism_other_crop: %.3f distance\n%s_realism_perlin: %.3f distance\n", n, ds, n,
           dc, n, dp);
    printf("%s_realism_sample_over_other_crop: %.2f ratio\n", n, ds / dc);
    printf("%s_best_crop_ssim: %.3f ssim (128 px windows of 3 samples vs every crop of the example, stride 4)\n", n, best);
    { /* refinement of a blurred copy and of the membrane of the example's own network */
        tn_image in[2] = {{0, 0, 0, NULL}, {0, 0, 0, NULL}};
        const char *what[2] = {"blurred", "membrane"};
        tn_extraction exn;
        int k;
        tn_image_blur(&in[0], &ex, 4.0f);
        if (!tn_extract(&ex, NULL, &exn)) {
            tn_gnn_membrane(&exn.contours, 256, 256, &in[1]);
            tn_extraction_free(&exn);
        }
        for (k = 0; k < 2; k++) {
            tn_image r = {0, 0, 0, NULL};
            if (!in[k].data) continue;
            g.seed = 5;
            g.from_scale = 0;
            t0 = tn_time_seconds();
            if (tn_singan_refine(&m, &in[k], &g, &r)) continue;
            printf("%s_refine_%s_spectrum: %.3f -> %.3f distance (input -> refined)\n", n, what[k], dist(&ex, &in[k], 1), dist(&ex, &r, 1));
            printf("%s_refine_%s_ssim_to_input: %.3f ssim (%.2f s)\n", n, what[k], ssim_of(&in[k], &r), tn_time_seconds() - t0);
            if (k == 0) {
                char path[256];
                snprintf(path, sizeof path, "/tmp/bench_singan_%s_refined.png", n);
                tn_image_save(path, &r, NULL);
            }
            tn_image_free(&r);
            tn_image_free(&in[k]);
        }
    }
    { /* 4x upscaling of the example downsampled to 64 px */
        tn_image small = {0, 0, 0, NULL}, up = {0, 0, 0, NULL}, bic = {0, 0, 0, NULL};
        tn_image_resize(&small, &ex, 64, 64, TN_RESIZE_AREA);
        tn_image_resize(&bic, &small, 256, 256, TN_RESIZE_BICUBIC);
        g.from_scale = 0;
        if (!tn_singan_upscale(&m, &small, 4.0f, &g, &up)) {
            printf("%s_upscale4_spectrum: %.3f distance (bicubic %.3f)\n", n, dist(&ex, &up, 1), dist(&ex, &bic, 1));
            printf("%s_upscale4_ssim: %.3f ssim (bicubic %.3f)\n", n, ssim_of(&ex, &up), ssim_of(&ex, &bic));
        }
        tn_image_free(&small);
        tn_image_free(&up);
        tn_image_free(&bic);
    }
    { /* 2048 x 2048 in a fresh process (this program re-run with --sample2048), so its peak
         memory is the sample's alone; a fork without exec would inherit a thread pool whose
         workers do not exist in the child */
        char path[256], cmd[1024];
        snprintf(path, sizeof path, "/tmp/bench_singan_%s_%d.tnw", n, (int)getpid());
        tn_singan_save(&m, path);
        fflush(stdout);
        snprintf(cmd, sizeof cmd, "%s --threads %d --sample2048 %s %s", g_argv0, threads, path, n);
        if (system(cmd)) printf("# %s: the 2048 sample failed\n", n);
        remove(path);
    }
    tn_singan_free(&m);
    tn_image_free(&ex);
    tn_image_free(&full);
    tn_image_free(&other);
    tn_image_free(&per);
}

int main(int argc, char **argv)
{
    double minutes = 10;
    int threads = 2, peer = 1, i, k, any = 0;
    g_argv0 = argv[0];
    for (i = 1; i < argc; i++)
        if (!strcmp(argv[i], "--threads") && i + 1 < argc) threads = atoi(argv[i + 1]);
    if (argc >= 4 && !strcmp(argv[argc - 3], "--sample2048")) { /* child mode: MODEL NAME */
        tn_singan mm;
        tn_singan_gen_opts g;
        tn_image s = {0, 0, 0, NULL};
        struct rusage ru;
        double t;
        tn_set_threads(threads);
        if (tn_singan_load(argv[argc - 2], &mm)) return 1;
        memset(&g, 0, sizeof g);
        t = tn_time_seconds();
        if (tn_singan_sample(&mm, 0, 0, 2048, 2048, &g, &s)) return 1;
        t = tn_time_seconds() - t;
        getrusage(RUSAGE_SELF, &ru);
        printf("%s_sample_2048_seconds: %.2f s\n%s_sample_2048_peak_memory: %.0f MB (whole process; the output alone is 16 MB)\n", argv[argc - 1], t,
               argv[argc - 1], ru.ru_maxrss / 1024.0);
        tn_image_free(&s);
        tn_singan_free(&mm);
        return 0;
    }
    for (i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--minutes") && i + 1 < argc) minutes = atof(argv[++i]);
        else if (!strcmp(argv[i], "--threads") && i + 1 < argc) threads = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--no-peer")) peer = 0;
        else if (!strcmp(argv[i], "--patch") && i + 1 < argc) g_patch = atoi(argv[++i]);
    }
    printf("# bench_singan: %.1f min per DEM, %d threads, patch %d\n", minutes, threads, g_patch);
    fflush(stdout);
    if (peer) { /* the host's 2-core scaling now, then the PyTorch step at the same size */
        if (system("sh /work/shared/peers/probe.sh 2>&1 | sed 's/^/# /'")) printf("# probe failed\n");
        fflush(stdout);
        if (system("/usr/bin/python3 /work/shared/peers/torch_singan_step.py --threads 2 --size 256 --runs 3 2>&1 | sed 's/^/peer: /'"))
            printf("# peer failed\n");
        fflush(stdout);
    }
    for (k = 0; k < (int)(sizeof dems / sizeof dems[0]); k++) {
        int want = 1;
        for (i = 1; i < argc; i++)
            if (argv[i][0] != '-' && !(i > 1 && (!strcmp(argv[i - 1], "--minutes") || !strcmp(argv[i - 1], "--threads") || !strcmp(argv[i - 1], "--patch")))) {
                want = 0;
                any = 1;
                break;
            }
        for (i = 1; any && i < argc; i++)
            if (!strcmp(argv[i], dems[k].name)) want = 1;
        if (want) bench_dem(&dems[k], minutes, threads);
        fflush(stdout);
    }
    return 0;
}
