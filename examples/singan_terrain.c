/* singan_terrain: SinGAN learns one DEM and makes more terrain like it (issue 15, @@singan).
   bin/singan_terrain [DEM] [-o PREFIX] [--minutes M] [--size N]
   e.g. bin/singan_terrain ../shared/data/dem/alps_montblanc/alps_montblanc_256.png --minutes 4
   (no DEM: a 96 x 96 Perlin terrain from 500 to 1500 m). Trains for M minutes (default 1; the
   library's default is 10), then writes PREFIX.tnw (the model), PREFIX_sample.png (an N x N
   sample, default 2 x the DEM's side, in the DEM's units), PREFIX_tile.png (its top-right
   quarter made alone: the same pixels), PREFIX_refined.png (a blurred copy of the DEM with the
   model's detail added back) and PREFIX_preview.png (hillshaded: DEM | sample | refined). */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int show_progress(void *user, const char *stage, double f)
{
    (void)user;
    fprintf(stderr, "\r%-26s %3.0f%%", stage, 100.0 * f); /* the stage names the scale being trained */
    if (f >= 1.0) fprintf(stderr, "\n");
    return 0;
}

static tn_status save_as(const char *prefix, const char *what, const tn_image *img)
{
    char path[512];
    snprintf(path, sizeof path, "%s_%s.png", prefix, what);
    return tn_image_save(path, img, NULL); /* 16-bit PNG with the height range recorded */
}

int main(int argc, char **argv)
{
    const char *in = NULL, *prefix = "singan";
    double minutes = 1;
    int size = 0, i, same = 1;
    tn_image dem = {0, 0, 0, NULL}, sample = {0, 0, 0, NULL}, tile = {0, 0, 0, NULL}, blur = {0, 0, 0, NULL}, refined = {0, 0, 0, NULL};
    tn_singan model;
    tn_singan_opts o;
    tn_singan_stats st;
    tn_singan_gen_opts g;
    tn_status s;
    char path[512];
    for (i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "-o") && i + 1 < argc) prefix = argv[++i];
        else if (!strcmp(argv[i], "--minutes") && i + 1 < argc) minutes = atof(argv[++i]);
        else if (!strcmp(argv[i], "--size") && i + 1 < argc) size = atoi(argv[++i]);
        else in = argv[i];
    }
    if (in) s = tn_image_load(&dem, in, NULL);
    else {
        tn_perlin_opts po;
        size_t k;
        memset(&po, 0, sizeof po);
        po.seed = 3;
        s = tn_noise_perlin(&dem, 96, 96, &po);
        for (k = 0; !s && k < (size_t)96 * 96; k++) dem.data[k] = 500.0f + 1000.0f * dem.data[k];
    }
    if (s) goto fail;
    if (size <= 0) size = 2 * dem.width;
    tn_set_progress(show_progress, NULL);
    memset(&o, 0, sizeof o);
    o.train.minutes = minutes;
    snprintf(path, sizeof path, "%s.tnw.ckpt", prefix);
    o.train.checkpoint = path; /* rerun with the same arguments after a kill: set o.train.resume = 1 */
    if ((s = tn_singan_train(&model, &dem, &o, &st))) goto fail;
    printf("%d scales, %ld iterations in %.1f min, reconstruction MSE %.4f\n", st.scales, st.iterations, st.seconds / 60, (double)st.loss_rec);
    snprintf(path, sizeof path, "%s.tnw", prefix);
    if ((s = tn_singan_save(path, &model))) goto fail;
    memset(&g, 0, sizeof g);
    g.seed = 42;
    if ((s = tn_singan_sample(&sample, &model, 0, 0, size, size, &g)) || (s = save_as(prefix, "sample", &sample))) goto fail;
    /* a window made alone equals the same pixels of the whole sample */
    if ((s = tn_singan_sample(&tile, &model, size / 2, 0, size / 2, size / 2, &g)) || (s = save_as(prefix, "tile", &tile))) goto fail;
    for (i = 0; i < (size / 2) * (size / 2); i++) same &= tile.data[i] == TN_PIXEL(&sample, size / 2 + i % (size / 2), i / (size / 2), 0);
    printf("tile equals the whole sample's pixels: %s\n", same ? "yes" : "NO");
    if ((s = tn_image_blur(&blur, &dem, 4.0f)) || (s = tn_singan_refine(&refined, &model, &blur, &g)) || (s = save_as(prefix, "refined", &refined)))
        goto fail;
    {
        tn_image pv[3] = {{0, 0, 0, NULL}, {0, 0, 0, NULL}, {0, 0, 0, NULL}}, row = {0, 0, 0, NULL}, small = {0, 0, 0, NULL};
        tn_render_opts ro;
        int k, y, x0 = 0, w = dem.width, h = dem.height;
        float lo, hi;
        memset(&ro, 0, sizeof ro);
        tn_image_range(&lo, &hi, &dem);
        ro.lo = lo; /* one colour ramp for all three */
        ro.hi = hi;
        s = tn_image_resize(&small, &sample, w, h, TN_RESIZE_AREA);
        if (!s) s = tn_render_preview(&pv[0], &dem, &ro);
        if (!s) s = tn_render_preview(&pv[1], &small, &ro);
        if (!s) s = tn_render_preview(&pv[2], &refined, &ro);
        if (!s) s = tn_image_create(&row, 3 * w, h, 3);
        for (k = 0; !s && k < 3; k++, x0 += w)
            for (y = 0; y < h; y++) memcpy(&TN_PIXEL(&row, x0, y, 0), &TN_PIXEL(&pv[k], 0, y, 0), (size_t)w * 3 * sizeof(float));
        if (!s) s = save_as(prefix, "preview", &row);
        for (k = 0; k < 3; k++) tn_image_free(&pv[k]);
        tn_image_free(&row);
        tn_image_free(&small);
        if (s) goto fail;
    }
    printf("wrote %s.tnw, %s_sample.png (%d x %d), %s_tile.png, %s_refined.png, %s_preview.png\n", prefix, prefix, size, size, prefix, prefix, prefix);
    tn_singan_free(&model);
    tn_image_free(&dem);
    tn_image_free(&sample);
    tn_image_free(&tile);
    tn_image_free(&blur);
    tn_image_free(&refined);
    return same ? 0 : 1;
fail:
    fprintf(stderr, "singan_terrain: %s: %s\n", tn_status_string(s), tn_last_error());
    return 1;
}
