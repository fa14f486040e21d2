/* sketch_to_parts: a user's sketch made ready for synthesis (paper 000, sections 4.1 and 5.2).
   bin/sketch_to_parts [SKETCH] [-o PREFIX] [--seed S]
   SKETCH is a .tns file or a drawn image (red strokes = ridges, blue = valleys, bright = high);
   without one, a sketch is drawn here (a bent red ridge and a blue valley on a 256 x 256 canvas,
   saved as PREFIX_drawn.png).
   The polylines are densified to 8-connected pixel chains and cut into contour parts of 5-10
   points (what sketch-to-DEM alignment matches); the rest of the canvas is filled with random
   ridges and valleys (minimum spanning trees of random nodes and of their Voronoi vertices)
   that never cross the user's lines. Writes PREFIX_parts.tns, PREFIX_full.tns (sketch + random
   lines) and PREFIX_preview.png: left the full sketch (the user's lines white, random ridges
   yellow, random valleys blue), right the user's contour parts, one colour per part. */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A stroke of the drawn sketch: a disc of radius 2 at every step from (x0, y0) to (x1, y1),
   colour rgb with brightness rising from v0 to v1 (brightness = height). */
static void stroke(tn_image *img, float x0, float y0, float x1, float y1, const float rgb[3], float v0, float v1)
{
    int k, steps = 200, dx, dy, c;
    for (k = 0; k <= steps; k++) {
        float t = (float)k / (float)steps, x = x0 + t * (x1 - x0), y = y0 + t * (y1 - y0), v = v0 + t * (v1 - v0);
        for (dy = -2; dy <= 2; dy++)
            for (dx = -2; dx <= 2; dx++) {
                int px = (int)(x + 0.5f) + dx, py = (int)(y + 0.5f) + dy;
                if (dx * dx + dy * dy > 4 || px < 0 || py < 0 || px >= img->width || py >= img->height) continue;
                for (c = 0; c < 3; c++) TN_PIXEL(img, px, py, c) = rgb[c] * v;
            }
    }
}

/* The built-in sketch: a ridge bending through the upper half, a valley below it; the drawing
   is saved as `png` too, to edit in any paint program and pass back. */
static tn_status draw_sketch(const char *png, tn_contour_set *out)
{
    static const float red[3] = {1, 0, 0}, blue[3] = {0, 0, 1};
    tn_image img = {0, 0, 0, NULL};
    tn_status st;
    size_t k;
    if ((st = tn_image_create(&img, 256, 256, 3))) return st;
    for (k = 0; k < (size_t)256 * 256 * 3; k++) img.data[k] = 1.0f; /* white paper */
    stroke(&img, 30, 120, 100, 60, red, 0.6f, 1.0f);
    stroke(&img, 100, 60, 200, 80, red, 1.0f, 0.7f);
    stroke(&img, 20, 200, 230, 170, blue, 0.3f, 0.2f);
    if (!(st = tn_image_save(png, &img, NULL))) st = tn_sketch_from_image(out, &img);
    tn_image_free(&img);
    return st;
}

/* Draws every point of a set as a dot of `size` pixels into pv at x offset x_off, coordinates
   scaled by `scale`: in `colour`, or with colour NULL one colour per polyline, cycling. */
static void dots(tn_image *pv, const tn_contour_set *set, int x_off, int scale, int size, const float *colour)
{
    static const float cycle[6][3] = {{1, 0.2f, 0.2f}, {0.2f, 0.8f, 0.2f}, {0.3f, 0.4f, 1},
                                      {1, 0.8f, 0.1f}, {0.8f, 0.3f, 1}, {0.1f, 0.9f, 0.9f}};
    int i, j, c, dx, dy;
    for (i = 0; i < set->count; i++) {
        const tn_contour *p = &set->items[i];
        const float *rgb = colour ? colour : cycle[i % 6];
        for (j = 0; j < p->npoints; j++)
            for (dy = 0; dy < size; dy++)
                for (dx = 0; dx < size; dx++) {
                    int x = x_off + (int)(p->points[3 * j] * (float)scale) + dx - (size - scale) / 2;
                    int y = (int)(p->points[3 * j + 1] * (float)scale) + dy - (size - scale) / 2;
                    if (x < x_off || y < 0 || x >= pv->width || y >= pv->height) continue;
                    for (c = 0; c < 3; c++) TN_PIXEL(pv, x, y, c) = rgb[c];
                }
    }
}

int main(int argc, char **argv)
{
    tn_contour_set sketch = {0, 0, 0, NULL}, dense = {0, 0, 0, NULL}, parts = {0, 0, 0, NULL}, full = {0, 0, 0, NULL};
    tn_image left = {0, 0, 0, NULL}, pv = {0, 0, 0, NULL};
    tn_sketch_random_opts ro;
    tn_save_opts so;
    const char *in = NULL, *prefix = "sketch";
    char path[1024];
    uint64_t seed = 1;
    static const float white[3] = {1, 1, 1};
    int i, x, y, c, side, scale;
    tn_status st;
    for (i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "-o") && i + 1 < argc) prefix = argv[++i];
        else if (!strcmp(argv[i], "--seed") && i + 1 < argc) seed = (uint64_t)strtoull(argv[++i], NULL, 10);
        else if (argv[i][0] == '-' || in) {
            fprintf(stderr, "usage: sketch_to_parts [SKETCH.tns | DRAWN.png] [-o PREFIX] [--seed S]\n");
            return 2;
        } else in = argv[i];
    }
    snprintf(path, sizeof path, "%s_drawn.png", prefix);
    if ((st = in ? tn_sketch_load(&sketch, in) : draw_sketch(path, &sketch))) goto fail;
    printf("sketch: %d polylines on a %d x %d canvas\n", sketch.count, sketch.width, sketch.height);

    /* parts need consecutive points to be 8-adjacent: a hand-written .tns may have long jumps */
    if ((st = tn_sketch_densify(&dense, &sketch)) || (st = tn_contour_parts_make(&parts, &dense, seed))) goto fail;
    memset(&ro, 0, sizeof ro); /* nodes 0 = one per 1024 canvas pixels */
    ro.seed = seed;
    if ((st = tn_sketch_random(&full, &dense, dense.width, dense.height, &ro))) goto fail;
    printf("%d contour parts; with random lines the canvas holds %d polylines\n", parts.count, full.count);

    snprintf(path, sizeof path, "%s_parts.tns", prefix);
    if ((st = tn_sketch_save(path, &parts))) goto fail;
    snprintf(path, sizeof path, "%s_full.tns", prefix);
    if ((st = tn_sketch_save(path, &full))) goto fail;

    /* preview: two panels of side 512 (or the canvas, when larger) */
    side = full.width > full.height ? full.width : full.height;
    scale = side < 512 ? 512 / side : 1;
    if ((st = tn_sketch_preview(&left, &full, NULL, full.width * scale, full.height * scale)) ||
        (st = tn_image_create(&pv, 2 * left.width + 8, left.height, 3)))
        goto fail;
    for (y = 0; y < pv.height; y++)
        for (x = 0; x < pv.width; x++)
            for (c = 0; c < 3; c++)
                TN_PIXEL(&pv, x, y, c) = x < left.width ? TN_PIXEL(&left, x, y, c) : x < left.width + 8 ? 1.0f : 0.15f;
    dots(&pv, &dense, 0, scale, scale + 2, white); /* the user's own lines, over the random ones */
    dots(&pv, &parts, left.width + 8, scale, scale + 1, NULL);
    memset(&so, 0, sizeof so);
    so.bit_depth = 8;
    snprintf(path, sizeof path, "%s_preview.png", prefix);
    if ((st = tn_image_save(path, &pv, &so))) goto fail;
    printf("wrote %s%s%s_parts.tns, %s_full.tns, %s_preview.png\n", in ? "" : prefix, in ? "" : "_drawn.png, ", prefix,
           prefix, prefix);
fail:
    if (st) fprintf(stderr, "sketch_to_parts: %s: %s\n", tn_status_string(st), tn_last_error());
    tn_contour_set_free(&sketch);
    tn_contour_set_free(&dense);
    tn_contour_set_free(&parts);
    tn_contour_set_free(&full);
    tn_image_free(&left);
    tn_image_free(&pv);
    return st ? 1 : 0;
}
