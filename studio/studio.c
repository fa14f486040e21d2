/* terrainnet studio: the C side of the page, compiled to WebAssembly with emscripten (`make studio`).
   It runs inside a Web Worker (worker.js), so generation does not freeze the page. Files move
   through emscripten's in-memory file system: the page writes a model, a sketch or a drawing to
   /in/..., calls one of these functions, and reads what they wrote to /out/... back to download.
   Every function returns 0 (TN_OK) or a tn_status; studio_error() gives the message.

   Generation is the library's default sketch path, nothing of our own: tn_gnn_generate with a
   zeroed tn_gnn_generate_opts (the seed aside), as `terrainnet gnn-generate ... --finetune 0`. */
#define TERRAINNET_IMPLEMENTATION
#include "../terrainnet.h"
#include <stdio.h>
#include <string.h>
#include <float.h>
#ifdef __EMSCRIPTEN__
#include <emscripten.h>
/* the worker posts {progress: fraction, stage} to the page */
EM_JS(void, studio_js_progress, (const char *stage, double fraction), {
    if (typeof studioProgress === 'function') studioProgress(UTF8ToString(stage), fraction);
})
#define STUDIO_API EMSCRIPTEN_KEEPALIVE
#else
static void studio_js_progress(const char *stage, double fraction) { (void)stage; (void)fraction; }
#define STUDIO_API
#endif

static tn_gnn g_model;
static int g_have_model;
static tn_image g_terrain = {0, 0, 0, NULL};
static tn_image g_shade = {0, 0, 0, NULL};
static unsigned char *g_rgba;
static char g_error[2048];
static double g_seconds, g_lo, g_hi;

static int studio_fail(tn_status st, const char *what)
{
    snprintf(g_error, sizeof g_error, "%s: %s (%s)", what, tn_last_error(), tn_status_string(st));
    return (int)st;
}

static int studio_progress(void *user, const char *stage, double fraction)
{
    (void)user;
    studio_js_progress(stage, fraction);
    return 0;
}

STUDIO_API const char *studio_error(void) { return g_error; }
STUDIO_API float *studio_terrain(void) { return g_terrain.data; }
STUDIO_API int studio_width(void) { return g_terrain.width; }
STUDIO_API int studio_height(void) { return g_terrain.height; }
STUDIO_API double studio_seconds(void) { return g_seconds; }
STUDIO_API double studio_lo(void) { return g_lo; }
STUDIO_API double studio_hi(void) { return g_hi; }

/* A .tnw from gnn-train (a bundled style or the user's own). */
STUDIO_API int studio_load_model(const char *path)
{
    tn_gnn m;
    tn_status st = tn_gnn_load(&m, path);
    if (st) return studio_fail(st, path);
    if (g_have_model) tn_gnn_free(&g_model);
    g_model = m;
    g_have_model = 1;
    return 0;
}

/* A sketch file (.tns text or a drawn image: red ridges, blue valleys) rewritten as .tns text,
   which the page draws and edits. */
STUDIO_API int studio_sketch_to_tns(const char *in_path, const char *out_path)
{
    tn_contour_set sk;
    tn_status st;
    memset(&sk, 0, sizeof sk);
    if ((st = tn_sketch_load(&sk, in_path))) return studio_fail(st, in_path);
    st = tn_sketch_save(out_path, &sk);
    tn_contour_set_free(&sk);
    return st ? studio_fail(st, out_path) : 0;
}

static void studio_range(void)
{
    size_t i, n = (size_t)g_terrain.width * g_terrain.height;
    g_lo = g_hi = n ? g_terrain.data[0] : 0;
    for (i = 1; i < n; i++) {
        if (g_terrain.data[i] < g_lo) g_lo = g_terrain.data[i];
        if (g_terrain.data[i] > g_hi) g_hi = g_terrain.data[i];
    }
}

/* Terrain of width x height from the sketch file in the loaded model's style: the library's
   default sketch path. */
STUDIO_API int studio_generate(const char *sketch_path, int width, int height, double seed)
{
    tn_contour_set sk;
    tn_gnn_generate_opts o;
    tn_image out = {0, 0, 0, NULL};
    tn_status st;
    double t0;
    if (!g_have_model) {
        snprintf(g_error, sizeof g_error, "no style loaded");
        return (int)TN_ERR_INVALID_ARG;
    }
    memset(&sk, 0, sizeof sk);
    if ((st = tn_sketch_load(&sk, sketch_path))) return studio_fail(st, "sketch");
    memset(&o, 0, sizeof o); /* zero = the defaults */
    o.seed = (uint64_t)seed;
    tn_set_progress(studio_progress, NULL);
    t0 = tn_time_seconds();
    st = tn_gnn_generate(&out, &g_model, &sk, width, height, &o);
    g_seconds = tn_time_seconds() - t0;
    tn_set_progress(NULL, NULL);
    tn_contour_set_free(&sk);
    if (st) return studio_fail(st, "generate");
    tn_image_free(&g_terrain);
    g_terrain = out;
    studio_range();
    return 0;
}

/* Forgets the terrain (after a warm-up run: the page then has nothing to export). */
STUDIO_API void studio_clear(void)
{
    tn_image_free(&g_terrain);
    g_lo = g_hi = 0;
}

/* Keeps channel 0, the height, of a DEM loaded with more (grey + alpha, RGB). */
static void studio_channel0(tn_image *img)
{
    size_t i, n = (size_t)img->width * img->height;
    if (img->channels == 1) return;
    for (i = 0; i < n; i++) img->data[i] = img->data[i * img->channels];
    img->channels = 1;
}

/* Replaces the terrain by a DEM file (to view or export one). */
STUDIO_API int studio_load_terrain(const char *path)
{
    tn_image img = {0, 0, 0, NULL};
    tn_status st = tn_image_load(&img, path, NULL);
    if (st) return studio_fail(st, path);
    studio_channel0(&img);
    tn_image_free(&g_terrain);
    g_terrain = img;
    studio_range();
    return 0;
}

/* Hillshaded colour preview of the terrain as width * height RGBA bytes (valid until the next
   call); the light's relief is normalised (tn_hillshade_opts dx 0), so any style reads well. */
STUDIO_API unsigned char *studio_hillshade(void)
{
    tn_render_opts ro;
    size_t i, n;
    tn_status st;
    memset(&ro, 0, sizeof ro);
    tn_image_free(&g_shade);
    if ((st = tn_render_preview(&g_shade, &g_terrain, &ro))) {
        studio_fail(st, "hillshade");
        return NULL;
    }
    n = (size_t)g_shade.width * g_shade.height;
    free(g_rgba);
    if (!(g_rgba = (unsigned char *)malloc(4 * n))) return NULL;
    for (i = 0; i < n; i++) {
        int c;
        for (c = 0; c < 3; c++) {
            float v = g_shade.data[3 * i + c];
            g_rgba[4 * i + c] = (unsigned char)(v <= 0 ? 0 : v >= 1 ? 255 : v * 255.0f + 0.5f);
        }
        g_rgba[4 * i + 3] = 255;
    }
    return g_rgba;
}

/* Writes the terrain with the library's own writers: kind 0 = 16-bit PNG (records the metre
   range), 1 = GeoTIFF (float32), 2 = .glb mesh draped with the hillshade, 3 = Unity RAW
   (2^n + 1 square, 16-bit little-endian; the range goes to studio_lo/hi for the terrain's height).
   dx: metres per pixel of the mesh (the style's example; <= 0 = 1). */
STUDIO_API int studio_export(const char *path, int kind, float dx)
{
    tn_status st;
    if (!g_terrain.data) {
        snprintf(g_error, sizeof g_error, "nothing to export: generate first");
        return (int)TN_ERR_INVALID_ARG;
    }
    if (kind == 0 || kind == 1) {
        tn_save_opts so;
        memset(&so, 0, sizeof so);
        so.bit_depth = kind == 0 ? 16 : 32;
        so.format = kind == 0 ? TN_FORMAT_PNG : TN_FORMAT_TIFF;
        st = tn_image_save(path, &g_terrain, &so);
    } else if (kind == 2) {
        tn_mesh_opts mo;
        tn_render_opts ro;
        tn_image tex = {0, 0, 0, NULL};
        memset(&mo, 0, sizeof mo);
        memset(&ro, 0, sizeof ro);
        mo.dx = dx > 0 ? dx : 1;
        mo.step = g_terrain.width > 1024 || g_terrain.height > 1024 ? 2 : 1;
        if (!(st = tn_render_preview(&tex, &g_terrain, &ro))) {
            mo.texture = &tex;
            st = tn_export_glb(path, &g_terrain, &mo);
        }
        tn_image_free(&tex);
    } else {
        float lo = 0, hi = 0;
        st = tn_export_unity_raw(path, &g_terrain, 0, &lo, &hi);
        g_lo = lo;
        g_hi = hi;
    }
    return st ? studio_fail(st, path) : 0;
}

/* The side x side window of highest relief (max - min on an 8 px grid), as gnn-train picks it
   (examples/cli/terrainnet.c's highest_relief_window: the CLI's, not the library's, so not callable). */
static void studio_relief_window(const tn_image *dem, int side, int *x0, int *y0)
{
    int x, y, u, v;
    float best = -1;
    *x0 = *y0 = 0;
    for (y = 0; y + side <= dem->height; y += 8)
        for (x = 0; x + side <= dem->width; x += 8) {
            float a = FLT_MAX, b = -FLT_MAX;
            for (v = 0; v < side; v += 2)
                for (u = 0; u < side; u += 2) {
                    float h = dem->data[(size_t)(y + v) * dem->width + x + u];
                    a = h < a ? h : a;
                    b = h > b ? h : b;
                }
            if (b - a > best) best = b - a, *x0 = x, *y0 = y;
        }
}

/* Learns a style in the page (issue 35, optional): gnn-train's recipe on a DEM file (channel 0;
   [lo, hi] gives metres to a file that records no range, lo >= hi = as loaded), the 128 px
   window of highest relief, up to 4 holdout windows, `minutes` of one thread. The model becomes
   the loaded style and is written to model_path (.tnw) for download. */
STUDIO_API int studio_train(const char *dem_path, double lo, double hi, double minutes, const char *model_path)
{
    tn_image dem = {0, 0, 0, NULL}, win = {0, 0, 0, NULL}, hold[4];
    tn_image_info info;
    tn_gnn_opts o;
    tn_gnn m;
    tn_gnn_stats stats;
    tn_status st;
    int side, x, y, nhold = 0, i;
    if ((st = tn_image_load(&dem, dem_path, &info))) return studio_fail(st, dem_path);
    studio_channel0(&dem);
    if (!info.has_range && hi > lo) {
        size_t k, n = (size_t)dem.width * dem.height;
        for (k = 0; k < n; k++) dem.data[k] = (float)(lo + dem.data[k] * (hi - lo));
    }
    side = dem.width < 128 || dem.height < 128 ? (dem.width < dem.height ? dem.width : dem.height) : 128;
    studio_relief_window(&dem, side, &x, &y);
    st = tn_image_crop(&win, &dem, x, y, side, side);
    if (!st) nhold = tn_gnn_holdout_windows(hold, &dem, x, y, side, side, 4);
    tn_image_free(&dem);
    if (st) return studio_fail(st, "crop");
    memset(&o, 0, sizeof o);
    o.train.minutes = minutes;
    o.holdout = nhold ? hold : NULL;
    o.holdout_count = nhold;
    tn_set_progress(studio_progress, NULL);
    st = tn_gnn_train(&m, &win, &o, &stats);
    tn_set_progress(NULL, NULL);
    tn_image_free(&win);
    for (i = 0; i < nhold; i++) tn_image_free(&hold[i]);
    if (st) return studio_fail(st, "train");
    if ((st = tn_gnn_save(model_path, &m))) {
        tn_gnn_free(&m);
        return studio_fail(st, model_path);
    }
    if (g_have_model) tn_gnn_free(&g_model);
    g_model = m;
    g_have_model = 1;
    g_seconds = stats.seconds;
    snprintf(g_error, sizeof g_error, "%ld iterations in %.0f s on the %d x %d window at (%d, %d), %d holdout windows%s", stats.iterations,
             stats.seconds, side, side, x, y, nhold, info.has_range || hi > lo ? "" : "; heights in the file's 0..1 codes (no range)");
    return 0;
}

/* The self-test's comparison: max |terrain - reference| / the reference's height range, and
   whether every value is bit-identical (*identical). -1 on error. */
STUDIO_API double studio_compare(const char *reference_path, int *identical)
{
    tn_image ref = {0, 0, 0, NULL};
    size_t i, n, same = 0;
    double lo, hi, worst = 0;
    tn_status st = tn_image_load(&ref, reference_path, NULL);
    *identical = 0;
    if (st) return studio_fail(st, reference_path), -1;
    if (ref.width != g_terrain.width || ref.height != g_terrain.height || ref.channels != 1) {
        snprintf(g_error, sizeof g_error, "%s: %d x %d x %d, the terrain is %d x %d", reference_path, ref.width, ref.height,
                 ref.channels, g_terrain.width, g_terrain.height);
        tn_image_free(&ref);
        return -1;
    }
    n = (size_t)ref.width * ref.height;
    lo = hi = ref.data[0];
    for (i = 0; i < n; i++) {
        double d = fabs((double)g_terrain.data[i] - ref.data[i]);
        if (ref.data[i] < lo) lo = ref.data[i];
        if (ref.data[i] > hi) hi = ref.data[i];
        if (d > worst) worst = d;
        same += memcmp(&g_terrain.data[i], &ref.data[i], sizeof(float)) == 0;
    }
    tn_image_free(&ref);
    *identical = same == n;
    return hi > lo ? worst / (hi - lo) : worst;
}

#ifndef __EMSCRIPTEN__
/* Native build of the same entry points (for checking them): studio MODEL SKETCH OUT [W H SEED] */
int main(int argc, char **argv)
{
    int w = argc > 5 ? atoi(argv[4]) : 256, h = argc > 5 ? atoi(argv[5]) : 256;
    if (argc < 4) {
        fprintf(stderr, "usage: studio MODEL.tnw SKETCH OUT.pfm [W H [SEED]]\n");
        return 2;
    }
    if (studio_load_model(argv[1]) || studio_generate(argv[2], w, h, argc > 6 ? atof(argv[6]) : 1) ||
        tn_image_save(argv[3], &g_terrain, NULL)) {
        fprintf(stderr, "studio: %s\n", g_error);
        return 1;
    }
    printf("seconds: %.3f\nheight_range: %g %g\n", g_seconds, g_lo, g_hi);
    return 0;
}
#endif
