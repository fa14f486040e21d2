/* bench_texture: the texture GAN and detail maps on real ground textures (paper 004).
   bin/bench_texture [--minutes M] [--tiling K] [--synth N] [--all] [NAME=MODEL.tnw ...]
   For each texture (grass, cracked soil, pebbles; --all adds sand and snow) it uses the given
   model or trains one for M minutes (default 1: the machine is shared and full training takes
   15), synthesises a texture K times the exemplar (default 6), builds detail maps and measures:
   far-view repetition (normalised autocorrelation at the tiling period after a Gaussian blur of
   sigma = period / 16), high-frequency energy, mean colour, seams on tile borders, a texture-
   statistics distance, and the time to synthesise N x N (default 8192). Prints name: value lines. */
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>

static const char *data_root(void)
{
    const char *r = getenv("TN_SHARED_DATA");
    return r ? r : "../shared/data";
}

static void die(const char *what, tn_status st)
{
    fprintf(stderr, "bench_texture: %s: %s: %s\n", what, tn_status_string(st), tn_last_error());
    exit(1);
}

/* Mean of the channels (luminance-like grey). */
static tn_image grey(const tn_image *a)
{
    tn_image g = {0, 0, 0, NULL};
    size_t i, n = (size_t)a->width * a->height;
    int c, C = a->channels > 3 ? 3 : a->channels;
    if (tn_image_create(&g, a->width, a->height, 1)) die("grey", TN_ERR_OUT_OF_MEMORY);
    for (i = 0; i < n; i++) {
        float s = 0;
        for (c = 0; c < C; c++) s += a->data[i * a->channels + c];
        g.data[i] = s / (float)C;
    }
    return g;
}

/* Normalised autocorrelation of a grey image at lag (dx, dy) over the overlap. */
static double autocorr(const tn_image *g, int dx, int dy)
{
    double ma = 0, mb = 0, sab = 0, saa = 0, sbb = 0, n;
    int x, y, w = g->width - dx, h = g->height - dy;
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++) {
            ma += g->data[(size_t)y * g->width + x];
            mb += g->data[(size_t)(y + dy) * g->width + x + dx];
        }
    n = (double)w * h;
    ma /= n;
    mb /= n;
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++) {
            double a = g->data[(size_t)y * g->width + x] - ma, b = g->data[(size_t)(y + dy) * g->width + x + dx] - mb;
            sab += a * b;
            saa += a * a;
            sbb += b * b;
        }
    return sab / sqrt(saa * sbb + 1e-30);
}

/* Far-view repetition: blur sigma = period / 16, then the peak autocorrelation within +-2 px of
   the tiling period, the larger of the horizontal and vertical peaks. */
static double repetition(const tn_image *img, int px, int py)
{
    tn_image g = grey(img), b = {0, 0, 0, NULL};
    double best = -1;
    int d, e;
    if (tn_image_blur(&b, &g, (float)(px < py ? px : py) / 16.0f)) die("blur", TN_ERR_OUT_OF_MEMORY);
    for (d = -2; d <= 2; d++)
        for (e = -2; e <= 2; e++) {
            double a = autocorr(&b, px + d, e < 0 ? 0 : e), c = autocorr(&b, e < 0 ? 0 : e, py + d);
            if (a > best) best = a;
            if (c > best) best = c;
        }
    tn_image_free(&g);
    tn_image_free(&b);
    return best;
}

/* Mean squared high-pass (image minus Gaussian sigma 1.5), all channels. */
static double hf_energy(const tn_image *img)
{
    tn_image b = {0, 0, 0, NULL};
    size_t i, n = (size_t)img->width * img->height * img->channels;
    double s = 0;
    if (tn_image_blur(&b, img, 1.5f)) die("blur", TN_ERR_OUT_OF_MEMORY);
    for (i = 0; i < n; i++) s += (double)(img->data[i] - b.data[i]) * (img->data[i] - b.data[i]);
    tn_image_free(&b);
    return s / (double)n;
}

static void means(const tn_image *img, double *m)
{
    size_t i, n = (size_t)img->width * img->height;
    int c;
    for (c = 0; c < img->channels; c++) m[c] = 0;
    for (i = 0; i < n; i++)
        for (c = 0; c < img->channels; c++) m[c] += img->data[i * img->channels + c];
    for (c = 0; c < img->channels; c++) m[c] /= (double)n;
}

/* Gradient energy on tile-border columns/rows vs all interior ones, and vs interior ones of the
   same phase of the noise-cell grid (border columns are cell boundaries too). */
static void seam_ratio(const tn_image *g, int tile, int cell, double *vs_all, double *vs_phase)
{
    double eb = 0, ei = 0, ep = 0;
    long nb = 0, ni = 0, np = 0;
    int x, y;
    for (y = 1; y < g->height; y++)
        for (x = 1; x < g->width; x++) {
            double dx = g->data[(size_t)y * g->width + x] - g->data[(size_t)y * g->width + x - 1];
            double dy = g->data[(size_t)y * g->width + x] - g->data[(size_t)(y - 1) * g->width + x];
            if (x % tile == 0) { eb += dx * dx; nb++; }
            else if (x % cell == 0) { ep += dx * dx; np++; ei += dx * dx; ni++; }
            else { ei += dx * dx; ni++; }
            if (y % tile == 0) { eb += dy * dy; nb++; }
            else if (y % cell == 0) { ep += dy * dy; np++; ei += dy * dy; ni++; }
            else { ei += dy * dy; ni++; }
        }
    *vs_all = (eb / (double)(nb ? nb : 1)) / (ei / (double)(ni ? ni : 1) + 1e-30);
    *vs_phase = (eb / (double)(nb ? nb : 1)) / (ep / (double)(np ? np : 1) + 1e-30);
}

/* Gradient energy across pixel boundaries of each phase p of the cell grid (x % cell == p, both
   axes) over the mean of all phases: min and max. 1 and 1 = no grid structure at all. */
static void phase_profile(const tn_image *g, int cell, double *lo, double *hi)
{
    double e[64] = {0}, all = 0;
    long n[64] = {0}, na = 0;
    int x, y, p;
    if (cell > 64) cell = 64;
    for (y = 1; y < g->height; y++)
        for (x = 1; x < g->width; x++) {
            double dx = g->data[(size_t)y * g->width + x] - g->data[(size_t)y * g->width + x - 1];
            double dy = g->data[(size_t)y * g->width + x] - g->data[(size_t)(y - 1) * g->width + x];
            e[x % cell] += dx * dx;
            n[x % cell]++;
            e[y % cell] += dy * dy;
            n[y % cell]++;
            all += dx * dx + dy * dy;
            na += 2;
        }
    *lo = 1e30;
    *hi = 0;
    for (p = 0; p < cell; p++) {
        double r = (e[p] / (double)(n[p] ? n[p] : 1)) / (all / (double)na + 1e-30);
        if (r < *lo) *lo = r;
        if (r > *hi) *hi = r;
    }
}

/* ---- texture-statistics distance: fixed random 5x5 filters (16) at scales 1, 2, 4, ReLU; per
   scale the centred feature covariance and the feature means, relative to the reference's;
   plus the L1 distance of 16-bin colour histograms. ---- */

typedef struct feats { double mean[3][16], cov[3][16][16], hist[8][16]; } feats;

static void features(const tn_image *img, feats *f)
{
    tn_ctx *ctx = tn_ctx_create();
    tn_rng r;
    int s, i, j, C = img->channels > 3 ? 3 : img->channels;
    size_t k, n;
    memset(f, 0, sizeof *f);
    tn_ctx_set_grad(ctx, 0);
    tn_rng_seed(&r, 1234, 5);
    for (s = 0; s < 3; s++) {
        tn_image small = {0, 0, 0, NULL}, rgb = {0, 0, 0, NULL};
        tn_tensor *x, *w, *y;
        size_t hw;
        tn_image_crop(&rgb, img, 0, 0, img->width, img->height);
        if (C != img->channels) { /* keep the colour channels */
            tn_image t = {0, 0, 0, NULL};
            tn_image_create(&t, img->width, img->height, 3);
            for (k = 0; k < (size_t)img->width * img->height; k++)
                for (i = 0; i < 3; i++) t.data[k * 3 + i] = img->data[k * img->channels + i];
            tn_image_free(&rgb);
            rgb = t;
        }
        tn_image_resize(&small, &rgb, img->width >> s, img->height >> s, TN_RESIZE_AREA);
        x = tn_tensor_from_image(ctx, &small);
        w = tn_tensor_4d(ctx, 16, C, 5, 5);
        tn_init_normal(w, &r, 0.0f, 1.0f / sqrtf(25.0f * C));
        y = tn_relu(ctx, tn_conv2d(ctx, x, w, NULL, NULL));
        hw = (size_t)y->shape[2] * y->shape[3];
        for (i = 0; i < 16; i++) {
            double m = 0;
            for (k = 0; k < hw; k++) m += y->data[i * hw + k];
            f->mean[s][i] = m / (double)hw;
        }
        for (i = 0; i < 16; i++)
            for (j = 0; j <= i; j++) {
                double c = 0;
                for (k = 0; k < hw; k++) c += (y->data[i * hw + k] - f->mean[s][i]) * (y->data[j * hw + k] - f->mean[s][j]);
                f->cov[s][i][j] = f->cov[s][j][i] = c / (double)hw;
            }
        tn_image_free(&small);
        tn_image_free(&rgb);
        tn_ctx_reset(ctx);
    }
    n = (size_t)img->width * img->height;
    for (k = 0; k < n; k++)
        for (i = 0; i < C; i++) {
            int b = (int)(img->data[k * img->channels + i] * 16.0f);
            f->hist[i][b < 0 ? 0 : (b > 15 ? 15 : b)] += 1.0 / (double)n;
        }
    tn_ctx_free(ctx);
}

static double distance(const feats *a, const feats *ref)
{
    double d = 0;
    int s, i, j;
    for (s = 0; s < 3; s++) {
        double nc = 0, dc = 0, nm = 0, dm = 0;
        for (i = 0; i < 16; i++) {
            nm += ref->mean[s][i] * ref->mean[s][i];
            dm += (a->mean[s][i] - ref->mean[s][i]) * (a->mean[s][i] - ref->mean[s][i]);
            for (j = 0; j < 16; j++) {
                nc += ref->cov[s][i][j] * ref->cov[s][i][j];
                dc += (a->cov[s][i][j] - ref->cov[s][i][j]) * (a->cov[s][i][j] - ref->cov[s][i][j]);
            }
        }
        d += sqrt(dc / (nc + 1e-30)) + sqrt(dm / (nm + 1e-30));
    }
    for (i = 0; i < 3; i++)
        for (j = 0; j < 16; j++) d += 0.5 * fabs(a->hist[i][j] - ref->hist[i][j]) / 3.0;
    return d / 3.0;
}

static double crop_distance(const tn_image *img, int x, int y, int w, int h, const feats *ref)
{
    tn_image c = {0, 0, 0, NULL};
    feats f;
    if (tn_image_crop(&c, img, x, y, w, h)) die("crop", TN_ERR_INVALID_ARG);
    features(&c, &f);
    tn_image_free(&c);
    return distance(&f, ref);
}

static tn_status null_band(void *user, int y0, const tn_image *band)
{
    (void)y0;
    *(double *)user += band->data[0];
    return TN_OK;
}

static void tile_exemplar(const tn_image *ex, int w, int h, tn_image *out)
{
    int x, y, c;
    if (tn_image_create(out, w, h, ex->channels)) die("tile", TN_ERR_OUT_OF_MEMORY);
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++)
            for (c = 0; c < ex->channels; c++) TN_PIXEL(out, x, y, c) = TN_PIXEL(ex, x % ex->width, y % ex->height, c);
}

static void bench_one(const char *name, const char *file, const char *model_path, double minutes, int tiling, int synth_n, int do_synth_time)
{
    char path[1024];
    tn_image ex = {0, 0, 0, NULL}, synth = {0, 0, 0, NULL}, comp = {0, 0, 0, NULL}, naive = {0, 0, 0, NULL}, g = {0, 0, 0, NULL};
    tn_image ex_half = {0, 0, 0, NULL}, noise = {0, 0, 0, NULL};
    tn_texgan m;
    tn_detail_maps dm;
    tn_status st;
    double t0, mex[8], mc[8], ms[8], dmax = 0, draw = 0, va, vp, sink = 0;
    feats fref;
    int W, H, c, cw, ch;
    snprintf(path, sizeof path, "%s/textures/%s", data_root(), file);
    if ((st = tn_image_load(&ex, path, NULL))) {
        printf("%s: skipped (%s)\n", name, tn_last_error());
        return;
    }
    if (model_path) {
        if ((st = tn_texgan_load(&m, model_path))) die(model_path, st);
        printf("%s.model: %s\n%s.train_minutes: %.2f\n%s.train_iterations: %ld\n", name, model_path, name, m.train_seconds / 60.0, name,
               m.iterations);
    } else {
        tn_texgan_opts o;
        tn_texgan_stats s;
        memset(&o, 0, sizeof o);
        o.train.minutes = minutes;
        o.train.seed = 1;
        if ((st = tn_texgan_train(&m, &ex, &o, &s))) die("train", st);
        printf("%s.model: trained here\n%s.train_minutes: %.2f\n%s.train_iterations: %ld\n%s.seconds_per_iteration: %.4f\n", name, name,
               s.seconds / 60.0, name, s.iterations, name, s.seconds_per_iter);
    }
    W = tiling * ex.width;
    H = tiling * ex.height;
    t0 = tn_time_seconds();
    if ((st = tn_texgan_synthesize(&synth, &m, 1, W, H))) die("synthesize", st);
    printf("%s.synth_size: %d x %d\n%s.synth_seconds: %.2f\n", name, W, H, name, tn_time_seconds() - t0);
    if ((st = tn_detail_maps_from_image(&dm, &synth, &ex, NULL))) die("detail maps", st);
    if ((st = tn_detail_compose(&comp, &dm, W, H))) die("compose", st);
    tile_exemplar(&ex, W, H, &naive);
    {
        double rn = repetition(&naive, ex.width, ex.height), rd = repetition(&comp, ex.width, ex.height), rs = repetition(&synth, ex.width, ex.height);
        printf("%s.repetition_naive: %.4f\n%s.repetition_detail: %.4f\n%s.repetition_raw_gan: %.4f\n%s.repetition_ratio: %.4f (target <= 0.333)\n",
               name, rn, name, rd, name, rs, name, rd / rn);
    }
    {
        double he = hf_energy(&ex), hc = hf_energy(&comp), hs = hf_energy(&synth);
        printf("%s.hf_energy_exemplar: %.7g\n%s.hf_energy_detail: %.7g (%+.2f%%, target within 10%%)\n%s.hf_energy_raw_gan: %.7g (%+.2f%%)\n", name,
               he, name, hc, 100.0 * (hc - he) / he, name, hs, 100.0 * (hs - he) / he);
    }
    means(&ex, mex);
    means(&comp, mc);
    means(&synth, ms);
    for (c = 0; c < ex.channels; c++) {
        if (fabs(mc[c] - mex[c]) > dmax) dmax = fabs(mc[c] - mex[c]);
        if (fabs(ms[c] - mex[c]) > draw) draw = fabs(ms[c] - mex[c]);
    }
    printf("%s.colour_diff_detail: %.5f (x255 = %.3f, target < 1)\n%s.colour_diff_raw_gan: %.5f (x255 = %.3f)\n", name, dmax, dmax * 255,
           name, draw, draw * 255);
    g = grey(&synth);
    seam_ratio(&g, 32 << m.stages, 1 << m.stages, &va, &vp);
    printf("%s.seam_ratio: %.4f (vs same-phase cell borders %.4f; target <= 1.05)\n", name, va, vp);
    {
        double lo, hi;
        phase_profile(&g, (1 << m.stages) * m.scale, &lo, &hi);
        printf("%s.cell_phase_gradient_energy: %.4f .. %.4f (min .. max over the %d pixel phases of the cell grid, / mean)\n", name, lo, hi,
               (1 << m.stages) * m.scale);
    }
    tn_image_free(&g);
    /* likeness: distances to the whole exemplar's statistics, on exemplar-sized windows */
    features(&ex, &fref);
    cw = ex.width / 2;
    ch = ex.height / 2;
    {
        tn_rng r;
        size_t i, n;
        tn_image_crop(&ex_half, &ex, ex.width / 4, ex.height / 4, cw, ch);
        tn_image_create(&noise, cw, ch, ex.channels);
        tn_rng_seed(&r, 9, 9);
        n = (size_t)cw * ch;
        for (i = 0; i < n; i++)
            for (c = 0; c < ex.channels; c++) noise.data[i * ex.channels + c] = (float)mex[c] + 0.3f * (tn_rng_uniform(&r) - 0.5f);
        tn_image_blur(&noise, &noise, 2.0f);
        printf("%s.likeness_real_crop: %.4f\n", name, crop_distance(&ex_half, 0, 0, cw, ch, &fref));
        printf("%s.likeness_raw_gan: %.4f\n", name, crop_distance(&synth, W / 3, H / 3, cw, ch, &fref));
        printf("%s.likeness_detail: %.4f\n", name, crop_distance(&comp, W / 3, H / 3, cw, ch, &fref));
        printf("%s.likeness_blurred_noise: %.4f\n", name, crop_distance(&noise, 0, 0, cw, ch, &fref));
    }
    printf("%s.low_map: %d x %d (memory / %.0f)\n", name, dm.low.width, dm.low.height, (double)W * H / ((double)dm.low.width * dm.low.height));
    if (do_synth_time) {
        t0 = tn_time_seconds();
        if ((st = tn_texgan_synthesize_stream(&m, 1, synth_n, synth_n, 0, null_band, &sink))) die("stream", st);
        printf("synth_%dx%d_seconds: %.2f (threads %d; target < 60)\n", synth_n, synth_n, tn_time_seconds() - t0, tn_get_threads());
    }
    tn_image_free(&ex);
    tn_image_free(&ex_half);
    tn_image_free(&noise);
    tn_image_free(&synth);
    tn_image_free(&comp);
    tn_image_free(&naive);
    tn_detail_maps_free(&dm);
    tn_texgan_free(&m);
}

int main(int argc, char **argv)
{
    static const char *names[5] = {"grass", "soil", "pebbles", "sand", "snow"};
    static const char *files[5] = {"grass_threejs_grasslight.png", "soil_cracked_mud.png", "rock_pebbles_gatys.png", "sand_ripples.png",
                                   "snow_surface.png"};
    const char *models[5] = {NULL, NULL, NULL, NULL, NULL};
    double minutes = 1.0;
    int tiling = 6, synth_n = 8192, count = 3, a, i;
    for (a = 1; a < argc; a++) {
        if (!strcmp(argv[a], "--minutes") && a + 1 < argc) minutes = atof(argv[++a]);
        else if (!strcmp(argv[a], "--tiling") && a + 1 < argc) tiling = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--synth") && a + 1 < argc) synth_n = atoi(argv[++a]);
        else if (!strcmp(argv[a], "--all")) count = 5;
        else if (!strcmp(argv[a], "--only") && a + 1 < argc) {
            const char *o = argv[++a];
            for (i = 0; i < 5; i++)
                if (strcmp(o, names[i])) files[i] = NULL;
            count = 5;
        } else {
            const char *eq = strchr(argv[a], '=');
            for (i = 0; eq && i < 5; i++)
                if ((size_t)(eq - argv[a]) == strlen(names[i]) && !strncmp(argv[a], names[i], strlen(names[i]))) models[i] = eq + 1;
            if (!eq) {
                fprintf(stderr, "usage: bench_texture [--minutes M] [--tiling K] [--synth N] [--all] [--only NAME] [NAME=MODEL.tnw ...]\n");
                return 2;
            }
        }
    }
    if (minutes <= 0 || tiling < 2 || tiling > 16 || synth_n < 64) {
        fprintf(stderr, "bench_texture: bad --minutes/--tiling/--synth\n");
        return 2;
    }
    printf("threads: %d\n", tn_get_threads());
    for (i = 0; i < count; i++)
        if (files[i]) bench_one(names[i], files[i], models[i], minutes, tiling, synth_n, i == 0 || (count == 5 && !files[0]));
    return 0;
}
