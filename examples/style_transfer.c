/* style_transfer: Perlin noise restyled with the morphology of a real heightmap (paper 002).
   bin/style_transfer SOURCE_DEM [-o PREFIX] [--size N] [--weights vgg19.tnw]
   Writes PREFIX_noise.png, PREFIX.png (16-bit, the source's height units) and PREFIX_preview.png. */
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

int main(int argc, char **argv)
{
    tn_image source = {0, 0, 0, NULL}, noise = {0, 0, 0, NULL}, out = {0, 0, 0, NULL}, preview = {0, 0, 0, NULL};
    tn_perlin_opts po;
    tn_style_opts so;
    tn_params *vgg = NULL;
    const char *src = NULL, *prefix = "styled", *weights = NULL;
    char path[1024];
    int i, size = 256;
    tn_status st;
    for (i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "-o") && i + 1 < argc) prefix = argv[++i];
        else if (!strcmp(argv[i], "--size") && i + 1 < argc) size = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--weights") && i + 1 < argc) weights = argv[++i];
        else src = argv[i];
    }
    if (!src || size < 16) {
        fprintf(stderr, "usage: style_transfer SOURCE_DEM [-o PREFIX] [--size N >= 16] [--weights vgg19.tnw]\n");
        return 2;
    }
    memset(&po, 0, sizeof po);
    po.seed = 7;
    po.frequency = 3;
    memset(&so, 0, sizeof so); /* defaults: built-in net, L-BFGS, pyramid */
    if ((st = tn_image_load(&source, src, NULL)) || (st = tn_noise_perlin(&noise, size, size, &po))) goto fail;
    if (weights && (st = tn_vgg19_load(&vgg, weights))) goto fail;
    so.vgg = vgg;
    tn_set_progress(show_progress, NULL);
    if ((st = tn_style_transfer(&out, &noise, &source, &so))) goto fail;
    snprintf(path, sizeof path, "%s_noise.png", prefix);
    if ((st = tn_image_save(path, &noise, NULL))) goto fail;
    snprintf(path, sizeof path, "%s.png", prefix);
    if ((st = tn_image_save(path, &out, NULL))) goto fail;
    snprintf(path, sizeof path, "%s_preview.png", prefix);
    if ((st = tn_render_preview(&preview, &out, NULL)) || (st = tn_image_save(path, &preview, NULL))) goto fail;
    printf("wrote %s_noise.png, %s.png, %s_preview.png\n", prefix, prefix, prefix);
    st = TN_OK;
fail:
    if (st) fprintf(stderr, "style_transfer: %s: %s\n", tn_status_string(st), tn_last_error());
    tn_image_free(&source);
    tn_image_free(&noise);
    tn_image_free(&out);
    tn_image_free(&preview);
    tn_params_free(vgg);
    return st ? 1 : 0;
}
