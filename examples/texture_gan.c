/* texture_gan: a spatial GAN learns one small texture photo and paints a larger one (paper 004, III).
   bin/texture_gan [EXEMPLAR] [-o PREFIX] [--minutes M] [--iters N] [--crop N] [--scale K]
   e.g. bin/texture_gan ../shared/data/textures/sand_ripples.png --minutes 2
   (no exemplar: a colour-ramped Perlin pattern). The exemplar's centre N x N window (default 128)
   is the training image; training stops after M minutes (default 0.5) or N iterations, whichever
   comes first - a real model wants 10-20 minutes. Writes PREFIX_exemplar.png, PREFIX.tnw (the
   model; tn_texgan_load reads it back), PREFIX_synth.png (K times the exemplar side, default 4,
   colour-corrected to the exemplar's mean), and the detail maps a renderer would use:
   PREFIX_low.png, PREFIX_high.png, PREFIX_detail.txt, with PREFIX_detail_preview.png comparing
   naive tiling of the exemplar (left) to the detail-mapped texture (right). */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int show_progress(void *user, const char *stage, double f)
{
    (void)user;
    fprintf(stderr, "\r%s %3.0f%%", stage, 100.0 * f);
    if (f >= 1.0) fprintf(stderr, "\n");
    return 0; /* non-zero would cancel */
}

/* The exemplar: the file's centre crop, or a Perlin pattern coloured with the terrain ramp. */
static tn_status load_exemplar(const char *path, int crop, tn_image *out)
{
    tn_image img = {0, 0, 0, NULL}, noise = {0, 0, 0, NULL};
    tn_perlin_opts po;
    tn_status st;
    if (!path) {
        memset(&po, 0, sizeof po);
        po.seed = 11;
        po.frequency = 8;
        po.periodic = 1;
        if (!(st = tn_noise_perlin(&noise, crop, crop, &po))) st = tn_image_colour_ramp(out, &noise, 0, 0);
        tn_image_free(&noise);
        return st;
    }
    if ((st = tn_image_load(&img, path, NULL))) return st;
    if (img.width > crop || img.height > crop) {
        int w = img.width < crop ? img.width : crop, h = img.height < crop ? img.height : crop;
        st = tn_image_crop(out, &img, (img.width - w) / 2, (img.height - h) / 2, w, h);
        tn_image_free(&img);
        return st;
    }
    *out = img;
    return TN_OK;
}

int main(int argc, char **argv)
{
    tn_image exemplar = {0, 0, 0, NULL}, synth = {0, 0, 0, NULL}, preview = {0, 0, 0, NULL};
    tn_texgan model;
    tn_texgan_opts o;
    tn_texgan_stats stats;
    tn_detail_maps maps;
    tn_save_opts so;
    const char *in = NULL, *prefix = "texture";
    char path[1024];
    int i, crop = 128, scale = 4;
    tn_status st;
    memset(&model, 0, sizeof model); /* so the cleanup below is safe whatever fails */
    memset(&maps, 0, sizeof maps);
    memset(&o, 0, sizeof o);         /* zero = defaults (tn_texgan_defaults lists them) */
    o.train.minutes = 0.5;
    o.train.seed = 1;
    for (i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "-o") && i + 1 < argc) prefix = argv[++i];
        else if (!strcmp(argv[i], "--minutes") && i + 1 < argc) o.train.minutes = atof(argv[++i]);
        else if (!strcmp(argv[i], "--iters") && i + 1 < argc) o.train.max_iters = atol(argv[++i]);
        else if (!strcmp(argv[i], "--crop") && i + 1 < argc) crop = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--scale") && i + 1 < argc) scale = atoi(argv[++i]);
        else if (argv[i][0] == '-' || in) {
            fprintf(stderr, "usage: texture_gan [EXEMPLAR] [-o PREFIX] [--minutes M] [--iters N] [--crop N >= 64] "
                            "[--scale K >= 1]\n");
            return 2;
        } else in = argv[i];
    }
    if (!(o.train.minutes > 0) || o.train.max_iters < 0 || crop < 64 || scale < 1 || scale > 64) {
        fprintf(stderr, "texture_gan: --minutes must be > 0, --iters >= 0, --crop >= 64 (the training patch), "
                        "--scale 1..64\n");
        return 2;
    }
    memset(&so, 0, sizeof so);
    so.bit_depth = 8;
    if ((st = load_exemplar(in, crop, &exemplar))) goto fail;
    snprintf(path, sizeof path, "%s_exemplar.png", prefix);
    if ((st = tn_image_save(path, &exemplar, &so))) goto fail;

    tn_set_progress(show_progress, NULL);
    if ((st = tn_texgan_train(&model, &exemplar, &o, &stats))) goto fail;
    tn_set_progress(NULL, NULL);
    printf("trained %ld iterations in %.1f s (%.3f s each); last losses D %.3f, G %.3f\n", stats.iterations,
           stats.seconds, stats.seconds_per_iter, (double)stats.loss_d, (double)stats.loss_g);
    snprintf(path, sizeof path, "%s.tnw", prefix);
    if ((st = tn_texgan_save(path, &model))) goto fail;

    /* any size and seed: the generator is fully convolutional and tiles are seamless */
    if ((st = tn_texgan_synthesize(&synth, &model, 7, scale * exemplar.width, scale * exemplar.height)) ||
        (st = tn_texture_colour_correct(&synth, model.mean, model.lo, model.hi)))
        goto fail;
    snprintf(path, sizeof path, "%s_synth.png", prefix);
    if ((st = tn_image_save(path, &synth, &so))) goto fail;

    /* detail maps: a small low-pass map of the synthesis + the exemplar's tiling high frequencies */
    if ((st = tn_detail_maps_from_image(&maps, &synth, &exemplar, NULL)) || (st = tn_detail_maps_save(prefix, &maps)) ||
        (st = tn_detail_preview(&preview, &maps, &exemplar, NULL, 256)))
        goto fail;
    snprintf(path, sizeof path, "%s_detail_preview.png", prefix);
    if ((st = tn_image_save(path, &preview, &so))) goto fail;
    printf("wrote %s_exemplar.png, %s.tnw, %s_synth.png (%d x %d), %s_low.png (%d x %d), %s_high.png, "
           "%s_detail.txt, %s_detail_preview.png\n", prefix, prefix, prefix, synth.width, synth.height, prefix,
           maps.low.width, maps.low.height, prefix, prefix, prefix);
fail:
    if (st) fprintf(stderr, "texture_gan: %s: %s\n", tn_status_string(st), tn_last_error());
    tn_detail_maps_free(&maps);
    tn_texgan_free(&model);
    tn_image_free(&exemplar);
    tn_image_free(&synth);
    tn_image_free(&preview);
    return st ? 1 : 0;
}
