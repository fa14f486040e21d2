/* sketch_to_terrain: learn one DEM, then turn a drawn sketch into terrain in its style (paper 000).
   bin/sketch_to_terrain [DEM] [-o PREFIX] [--minutes M] [--size N] [--random N]
   e.g. bin/sketch_to_terrain ../shared/data/dem/alps_montblanc/alps_montblanc_128.png --minutes 3
   (no DEM: a Perlin terrain from 500 to 2500 m). The DEM's centre 128 x 128 window is learnt for
   M minutes (default 0.5; a real model wants about 10). The sketch is the paper's Figure 10: a
   ridge shaped like the letter A inside a circular valley, as polylines with heights in [0, 1]
   (mapped to the example's height range). Writes PREFIX.tnw (the model), PREFIX_terrain.png
   (N x N, default 256, in the DEM's units), PREFIX_preview.png and, for comparison,
   PREFIX_membrane_preview.png: the smooth interpolation of the sketch heights the network
   starts from. --random N adds random ridges and valleys around the sketch (paper 5.2). */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>

static int show_progress(void *user, const char *stage, double f)
{
    (void)user;
    fprintf(stderr, "\r%-14s %3.0f%%", stage, 100.0 * f);
    if (f >= 1.0) fprintf(stderr, "\n");
    return 0; /* non-zero would cancel */
}

/* One polyline from n points (x, y, h) in [0, 1] canvas units. */
static void add_line(tn_contour_set *s, tn_contour_type type, const float *p, int n, int side)
{
    tn_contour *c = &s->items[s->count++];
    int i;
    memset(c, 0, sizeof *c);
    c->type = type;
    c->npoints = n;
    c->points = (float *)malloc((size_t)n * 3 * sizeof(float));
    for (i = 0; i < n; i++) {
        c->points[3 * i] = p[3 * i] * (float)(side - 1);
        c->points[3 * i + 1] = p[3 * i + 1] * (float)(side - 1);
        c->points[3 * i + 2] = p[3 * i + 2];
    }
}

/* The letter A as a ridge (high at the apex) inside a circular valley (low). */
static void a_in_circle(int side, tn_contour_set *s)
{
    static const float left[] = {0.33f, 0.72f, 0.55f, 0.5f, 0.26f, 0.95f};
    static const float right[] = {0.5f, 0.26f, 0.95f, 0.67f, 0.72f, 0.55f};
    static const float bar[] = {0.4f, 0.55f, 0.7f, 0.6f, 0.55f, 0.7f};
    float circle[3 * 65];
    int i;
    for (i = 0; i <= 64; i++) {
        double a = 2 * 3.14159265358979 * i / 64;
        circle[3 * i] = (float)(0.5 + 0.42 * cos(a));
        circle[3 * i + 1] = (float)(0.5 + 0.42 * sin(a));
        circle[3 * i + 2] = 0.1f;
    }
    memset(s, 0, sizeof *s);
    s->width = s->height = side;
    s->items = (tn_contour *)calloc(4, sizeof(tn_contour));
    add_line(s, TN_RIDGE, left, 2, side);
    add_line(s, TN_RIDGE, right, 2, side);
    add_line(s, TN_RIDGE, bar, 2, side);
    add_line(s, TN_VALLEY, circle, 65, side);
}

static tn_status save_preview(const tn_image *dem, const char *prefix, const char *what)
{
    tn_image shade = {0, 0, 0, NULL};
    tn_save_opts so;
    char path[512];
    tn_status st;
    memset(&so, 0, sizeof so);
    so.bit_depth = 8;
    snprintf(path, sizeof path, "%s_%s.png", prefix, what);
    if ((st = tn_render_preview(&shade, dem, NULL))) return st;
    st = tn_image_save(path, &shade, &so);
    tn_image_free(&shade);
    if (!st) printf("wrote %s\n", path);
    return st;
}

int main(int argc, char **argv)
{
    const char *dem_path = NULL, *prefix = "sketch_to_terrain";
    double minutes = 0.5;
    int side = 256, random_nodes = 0, i;
    tn_image dem = {0, 0, 0, NULL}, ex = {0, 0, 0, NULL}, terrain = {0, 0, 0, NULL}, membrane = {0, 0, 0, NULL};
    tn_gnn_opts o;
    tn_gnn model;
    tn_gnn_stats stats;
    tn_gnn_generate_opts go;
    tn_contour_set sketch;
    char path[512];
    tn_status st;
    for (i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "-o") && i + 1 < argc) prefix = argv[++i];
        else if (!strcmp(argv[i], "--minutes") && i + 1 < argc) minutes = atof(argv[++i]);
        else if (!strcmp(argv[i], "--size") && i + 1 < argc) side = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--random") && i + 1 < argc) random_nodes = atoi(argv[++i]);
        else if (argv[i][0] != '-') dem_path = argv[i];
        else {
            fprintf(stderr, "usage: %s [DEM] [-o PREFIX] [--minutes M] [--size N] [--random N]\n", argv[0]);
            return 2;
        }
    }
    if (dem_path) st = tn_image_load(&dem, dem_path, NULL);
    else { /* a Perlin terrain in metres */
        tn_perlin_opts po;
        size_t k;
        memset(&po, 0, sizeof po);
        po.seed = 5;
        po.octaves = 6;
        po.frequency = 2;
        st = tn_noise_perlin(&dem, 128, 128, &po);
        for (k = 0; !st && k < (size_t)dem.width * dem.height; k++) dem.data[k] = 500.0f + 2000.0f * dem.data[k];
    }
    if (!st) {
        int w = dem.width < 128 ? dem.width : 128, h = dem.height < 128 ? dem.height : 128;
        st = tn_image_crop(&ex, &dem, (dem.width - w) / 2, (dem.height - h) / 2, w, h);
    }
    if (st) {
        fprintf(stderr, "sketch_to_terrain: %s\n", tn_last_error());
        return 1;
    }
    tn_set_progress(show_progress, NULL);
    memset(&o, 0, sizeof o); /* zero = defaults */
    o.train.minutes = minutes;
    o.train.seed = 1;
    if ((st = tn_gnn_train(&model, &ex, &o, &stats))) {
        fprintf(stderr, "sketch_to_terrain: training: %s\n", tn_last_error());
        return 1;
    }
    printf("learnt %d x %d: %d parts, %ld iterations in %.1f min\n", ex.width, ex.height, stats.parts, stats.iterations, stats.seconds / 60);
    snprintf(path, sizeof path, "%s.tnw", prefix);
    if ((st = tn_gnn_save(path, &model))) fprintf(stderr, "sketch_to_terrain: %s\n", tn_last_error());

    a_in_circle(side, &sketch);
    memset(&go, 0, sizeof go);
    go.seed = 1;
    go.random_nodes = random_nodes;
    if (!st) st = tn_gnn_generate(&terrain, &model, &sketch, side, side, &go); /* [0, 1] heights: the example's range */
    snprintf(path, sizeof path, "%s_terrain.png", prefix);
    if (!st) st = tn_image_save(path, &terrain, NULL);
    if (!st) st = save_preview(&terrain, prefix, "preview");
    if (!st) { /* the baseline: the sketch heights interpolated smoothly, in the same units */
        tn_contour_set units = sketch;
        int c, j;
        for (c = 0; c < sketch.count; c++)
            for (j = 0; j < sketch.items[c].npoints; j++) {
                float *h = &sketch.items[c].points[3 * j + 2];
                *h = model.lo + (model.hi - model.lo) * *h;
            }
        st = tn_gnn_membrane(&membrane, &units, side, side);
        if (!st) st = save_preview(&membrane, prefix, "membrane_preview");
    }
    if (st) fprintf(stderr, "sketch_to_terrain: %s\n", tn_last_error());
    tn_contour_set_free(&sketch);
    tn_image_free(&terrain);
    tn_image_free(&membrane);
    tn_gnn_free(&model);
    tn_image_free(&ex);
    tn_image_free(&dem);
    return st ? 1 : 0;
}
