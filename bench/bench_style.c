/* bench_style: terrain style transfer (paper 002) on real heightmaps, default settings.
   usage: bench_style [PREVIEW_DIR] [--no-1024] [--peer] [--drain | --no-drain] [--fixed-content]
   For a mountain, a canyon and a desert source (../shared/data or $TN_SHARED_DATA): a 512 x 512
   Perlin map (seed 7, 8 octaves, 3 cells; gain matched to the source by tn_style_content_noise,
   or 0.5 with --fixed-content) is restyled; prints the Table 1 protocol (SSIM of the
   source resized to the map size, both normalised to [0, 1]) before/after, the slope-histogram
   and radial power-spectrum distances before/after, and the time. Then the time for 1024 x 1024,
   and the time of one VGG-19 loss+gradient evaluation at 256 x 256 (random weights) for
   comparison with ../shared/peers/torch_style_transfer.py (run in the same process with --peer).
   With PREVIEW_DIR, writes <name>_source_noise_result.png: hillshaded source | noise | result.
   Also prints SSIM(source, the source mirrored left-right / transposed): maps with exactly the
   source's morphology but another layout, the reference for what Table 1's SSIM can reach when
   the layout is not the source's. The drainage terms are at their default (on for fluvial
   sources); --drain forces them on for every source (drain_weight 10, valley_weight 1),
   --no-drain off. Times are wall clock, with the process CPU time beside them. */
#define TN_INTERNALS /* private tn__ code: the header's internals block */
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static const char *data_root(void)
{
    const char *r = getenv("TN_SHARED_DATA");
    return r ? r : "../shared/data";
}

static int save_triptych(const char *dir, const char *name, const tn_image *src, const tn_image *noise, const tn_image *res)
{
    const tn_image *maps[3];
    tn_image cat = {0, 0, 0, NULL}, r = {0, 0, 0, NULL};
    char path[1024];
    int i, x, y, c, W = noise->width, H = noise->height;
    tn_status st;
    maps[1] = noise;
    maps[2] = res;
    if (tn_image_resize(&r, src, W, H, TN_RESIZE_AREA)) return 1;
    maps[0] = &r;
    if (tn_image_create(&cat, 3 * W + 8, H, 3)) return 1;
    for (i = 0; i < 3; i++) {
        tn_image p = {0, 0, 0, NULL};
        if (tn_render_preview(&p, maps[i], NULL)) return 1;
        for (y = 0; y < H; y++)
            for (x = 0; x < W; x++)
                for (c = 0; c < 3; c++) TN_PIXEL(&cat, x + i * (W + 4), y, c) = TN_PIXEL(&p, x, y, c);
        tn_image_free(&p);
    }
    snprintf(path, sizeof path, "%s/%s_source_noise_result.png", dir, name);
    st = tn_image_save(path, &cat, NULL);
    tn_image_free(&cat);
    tn_image_free(&r);
    return st != TN_OK;
}

/* SSIM(source, source mirrored left-right (t = 0) or transposed (t = 1)) at n x n. */
static double ssim_rearranged(const tn_image *src, int n, int t)
{
    tn_image r = {0, 0, 0, NULL}, f = {0, 0, 0, NULL};
    tn_style_scores sc;
    int x, y;
    if (tn_image_resize(&r, src, n, n, TN_RESIZE_AREA) || tn_image_copy(&f, &r)) return -1;
    for (y = 0; y < n; y++)
        for (x = 0; x < n; x++) f.data[y * n + x] = t ? r.data[x * n + y] : r.data[y * n + n - 1 - x];
    if (tn_style_compare(&sc, &f, src)) sc.ssim = -1;
    tn_image_free(&r);
    tn_image_free(&f);
    return sc.ssim;
}

static tn_perlin_opts perlin_opts(void)
{
    tn_perlin_opts po;
    memset(&po, 0, sizeof po);
    po.seed = 7;
    po.octaves = 8;
    po.frequency = 3;
    return po;
}

static int perlin(tn_image *img, int n)
{
    tn_perlin_opts po = perlin_opts();
    return tn_noise_perlin(img, n, n, &po) != TN_OK;
}

/* The content map for a source: gain-0.5 Perlin (--fixed-content) or the gain matched to the
   source's slopes by tn_style_content_noise (default). */
static int content(tn_image *img, int n, const tn_image *src, int fixed, const char *name)
{
    tn_perlin_opts po = perlin_opts();
    float gain = 0.5f;
    tn_image_free(img);
    if (fixed) return perlin(img, n);
    if (tn_style_content_noise(img, n, n, src, &po, &gain)) return 1;
    printf("style_%s_content_gain_%d: %.2f\n", name, n, gain);
    return 0;
}

int main(int argc, char **argv)
{
    static const char *sources[3][2] = {{"mountain", "dem/himalaya_everest/himalaya_everest_full.png"},
                                        {"canyon", "dem/grandcanyon_hoppe8bit/grandcanyon_hoppe8bit_full.png"},
                                        {"desert", "dem/sahara_erg_oriental/sahara_erg_oriental_full.png"}};
    const char *dir = NULL;
    int i, do1024 = 1, peer = 0, ok = 1, ran = 0, fixed = 0;
    tn_style_opts so;
    char path[1024];
    tn_image noise = {0, 0, 0, NULL};
    const tn_style_opts *opts = NULL;
    for (i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--no-1024")) do1024 = 0;
        else if (!strcmp(argv[i], "--peer")) peer = 1;
        else if (!strcmp(argv[i], "--fixed-content")) fixed = 1;
        else if (!strcmp(argv[i], "--drain") || !strcmp(argv[i], "--no-drain")) {
            int on = !strcmp(argv[i], "--drain");
            memset(&so, 0, sizeof so);
            so.drain_weight = on ? 10.0f : -1.0f;
            so.valley_weight = on ? 1.0f : -1.0f;
            opts = &so;
        }
        else dir = argv[i];
    }
    tn_set_threads(2);
    printf("style_threads: %d\n", tn_get_threads());
    printf("style_content: %s\n", fixed ? "Perlin fBm, gain 0.5" : "Perlin fBm, gain matched to each source (tn_style_content_noise)");
    for (i = 0; i < 3; i++) {
        tn_image src = {0, 0, 0, NULL}, res = {0, 0, 0, NULL};
        tn_style_scores a, b;
        double t0, t, cpu;
        clock_t c0;
        snprintf(path, sizeof path, "%s/%s", data_root(), sources[i][1]);
        if (tn_image_load(&src, path, NULL)) {
            printf("style_%s: skipped (%s)\n", sources[i][0], tn_last_error());
            continue;
        }
        if (content(&noise, 512, &src, fixed, sources[i][0])) return 1;
        t0 = tn_time_seconds();
        c0 = clock();
        if (tn_style_transfer(&res, &noise, &src, opts)) {
            fprintf(stderr, "%s\n", tn_last_error());
            return 1;
        }
        t = tn_time_seconds() - t0;
        cpu = (double)(clock() - c0) / CLOCKS_PER_SEC;
        if (tn_style_compare(&a, &noise, &src) || tn_style_compare(&b, &res, &src)) return 1;
        printf("style_%s_source: %s\n", sources[i][0], sources[i][1]);
        printf("style_%s_ssim_noise: %.4f\n", sources[i][0], a.ssim);
        printf("style_%s_ssim_result: %.4f\n", sources[i][0], b.ssim);
        printf("style_%s_slope_hist_dist_noise: %.4f\n", sources[i][0], a.slope_hist_dist);
        printf("style_%s_slope_hist_dist_result: %.4f\n", sources[i][0], b.slope_hist_dist);
        printf("style_%s_spectrum_dist_noise: %.4f\n", sources[i][0], a.spectrum_dist);
        printf("style_%s_spectrum_dist_result: %.4f\n", sources[i][0], b.spectrum_dist);
        printf("style_%s_512_time: %.1f s\n", sources[i][0], t);
        printf("style_%s_512_cpu: %.1f s (process CPU, all threads)\n", sources[i][0], cpu);
        printf("style_%s_ssim_source_mirrored: %.4f\n", sources[i][0], ssim_rearranged(&src, 512, 0));
        printf("style_%s_ssim_source_transposed: %.4f\n", sources[i][0], ssim_rearranged(&src, 512, 1));
        ran++;
        ok &= b.ssim > a.ssim && b.slope_hist_dist < a.slope_hist_dist && b.spectrum_dist < a.spectrum_dist;
        fflush(stdout);
        if (dir && save_triptych(dir, sources[i][0], &src, &noise, &res)) fprintf(stderr, "cannot write the preview in %s\n", dir);
        if (i == 0 && do1024) {
            tn_image n2 = {0, 0, 0, NULL}, r2 = {0, 0, 0, NULL};
            if (content(&n2, 1024, &src, fixed, sources[i][0])) return 1;
            t0 = tn_time_seconds();
            c0 = clock();
            if (tn_style_transfer(&r2, &n2, &src, opts)) {
                fprintf(stderr, "%s\n", tn_last_error());
                return 1;
            }
            printf("style_mountain_1024_time: %.1f s\n", tn_time_seconds() - t0);
            printf("style_mountain_1024_cpu: %.1f s (process CPU, all threads)\n", (double)(clock() - c0) / CLOCKS_PER_SEC);
            if (tn_style_compare(&b, &r2, &src) == TN_OK && tn_style_compare(&a, &n2, &src) == TN_OK)
                printf("style_mountain_1024_ssim: %.4f -> %.4f\n", a.ssim, b.ssim);
            tn_image_free(&n2);
            tn_image_free(&r2);
            fflush(stdout);
        }
        tn_image_free(&src);
        tn_image_free(&res);
    }
    printf("style_all_criteria_met: %s (%d of 3 sources ran)\n", ok && ran == 3 ? "yes" : "no", ran);
    { /* one VGG-19 evaluation (loss + gradient) at 256 x 256, random weights */
        tn_params *p = NULL;
        tn_style_opts o;
        tn__style_cfg *c = (tn__style_cfg *)calloc(1, sizeof *c);
        tn__style_level L;
        tn_image n256 = {0, 0, 0, NULL};
        tn_rng rng;
        float *g;
        const float *crop;
        double t0;
        int k;
        if (tn_vgg19_create(&p) || !c) return 1;
        tn_rng_seed(&rng, 1, 0);
        for (k = 0; k < tn_params_count(p); k++) tn_init_kaiming(tn_params_get(p, k), &rng, 1.41421356f);
        memset(&o, 0, sizeof o);
        o.vgg = p;
        perlin(&n256, 256);
        if (tn__style_setup(c, &o)) return 1;
        tn__style_level_init(&L, c, 256, 256);
        crop = n256.data;
        g = (float *)malloc(256 * 256 * sizeof(float));
        if (tn__style_targets(&L, &crop, 1, 1) || tn__style_content_target(&L, n256.data)) return 1;
        tn__style_eval(&L, n256.data, g);
        t0 = tn_time_seconds();
        for (k = 0; k < 3; k++) tn__style_eval(&L, n256.data, g);
        printf("style_vgg19_eval_256: %.3f s (loss + gradient, mean of 3)\n", (tn_time_seconds() - t0) / 3);
        fflush(stdout);
        free(g);
        tn__style_level_free(&L);
        tn_image_free(&n256);
        free(c);
        tn_params_free(p);
    }
    if (peer) {
        printf("== peer: torch_style_transfer.py (VGG-19, random weights)\n");
        fflush(stdout);
        snprintf(path, sizeof path, "/usr/bin/python3 %s/../peers/torch_style_transfer.py --threads 2 --sizes 256 --runs 3", data_root());
        if (system(path) != 0)
            printf("style_peer: could not run\n");
    }
    tn_image_free(&noise);
    return 0;
}
