/* tn_test.h - the tiny harness every tests/test_*.c uses.
   TN_TEST(name) { ... TN_CHECK(cond); ... }   and in main: TN_RUN(name); return tn_test_summary("file");
   A test passes when none of its checks fail; TN_SKIP("why") marks it skipped (e.g. no ../shared/data).
   The last line of every test program is "<file>: N passed, N failed, N skipped". */
#ifndef TN_TEST_H
#define TN_TEST_H
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>

static int tn_test_passed, tn_test_failed, tn_test_skipped;
static int tn_test_cur_failed, tn_test_cur_skipped;
static const char *tn_test_cur_name;

#define TN_TEST(name) static void name(void)
#define TN_CHECK(cond)                                                                   \
    do {                                                                                 \
        if (!(cond)) {                                                                   \
            fprintf(stderr, "FAIL %s (%s:%d): %s\n", tn_test_cur_name, __FILE__, __LINE__, #cond); \
            tn_test_cur_failed++;                                                        \
        }                                                                                \
    } while (0)
/* Checks |a - b| <= tol and prints both values when it fails. */
#define TN_CHECK_NEAR(a, b, tol)                                                         \
    do {                                                                                 \
        double tn__a = (double)(a), tn__b = (double)(b);                                 \
        if (!(fabs(tn__a - tn__b) <= (double)(tol))) {                                   \
            fprintf(stderr, "FAIL %s (%s:%d): %s = %.9g, %s = %.9g, tol %g\n", tn_test_cur_name, \
                    __FILE__, __LINE__, #a, tn__a, #b, tn__b, (double)(tol));            \
            tn_test_cur_failed++;                                                        \
        }                                                                                \
    } while (0)
#define TN_SKIP(why)                                                                     \
    do {                                                                                 \
        fprintf(stderr, "skipped %s: %s\n", tn_test_cur_name, why);                      \
        tn_test_cur_skipped = 1;                                                         \
        return;                                                                          \
    } while (0)
#define TN_RUN(name)                                                                     \
    do {                                                                                 \
        tn_test_cur_name = #name;                                                        \
        tn_test_cur_failed = 0;                                                          \
        tn_test_cur_skipped = 0;                                                         \
        name();                                                                          \
        if (tn_test_cur_failed) tn_test_failed++;                                        \
        else if (tn_test_cur_skipped) tn_test_skipped++;                                 \
        else tn_test_passed++;                                                           \
    } while (0)

static const char *tn_test_data(const char *rel);
static const char *tn_test_ref(const char *rel);
static unsigned char *tn_test_read_file(const char *path, size_t *n);
static int tn_test_write_text(const char *path, const char *text);
#ifdef TERRAINNET_H
static tn_image tn_test_exemplar(int w, int h, int channels, uint64_t seed);
#ifndef TN_NO_ENGINE
static int tn_test_same_params(const tn_params *a, const tn_params *b, int skip);
#endif
#ifndef TN_NO_NOISE
static tn_image tn_test_dem(int n, uint64_t seed);
#endif
#ifndef TN_NO_TEXGAN
static void tn_test_tiny_texgan_opts(tn_texgan_opts *o);
#endif
#ifndef TN_NO_GNN
static void tn_test_tiny_gnn_opts(tn_gnn_opts *o, long iters);
#endif
#ifndef TN_NO_SINGAN
static void tn_test_tiny_singan_opts(tn_singan_opts *o, int iters);
#endif
#ifndef TN_NO_SEASON
typedef struct tn_test_kpd_set tn_test_kpd_set;
static int tn_test_kpd_set_make(tn_test_kpd_set *k, int n);
static void tn_test_kpd_set_free(tn_test_kpd_set *k);
static void tn_test_small_kpd_opts(tn_kpd_opts *o, long iters);
#endif
#endif

/* A scratch file path $TMPDIR/tn_test_<tag>_<leaf> (or /tmp); four buffers rotate, so up to
   four paths can be in use at once. */
static const char *tn_test_tmp_path(const char *tag, const char *leaf)
{
    static char buf[4][512];
    static int k;
    const char *dir = getenv("TMPDIR");
    k = (k + 1) & 3;
    snprintf(buf[k], sizeof buf[k], "%s/tn_test_%s_%s", dir && dir[0] ? dir : "/tmp", tag, leaf);
    return buf[k];
}

static int tn_test_summary(const char *file)
{
    (void)tn_test_data; /* not every test file reads shared data or writes scratch files */
    (void)tn_test_tmp_path;
    (void)tn_test_ref;
    (void)tn_test_read_file;
    (void)tn_test_write_text;
#ifdef TERRAINNET_H
    (void)tn_test_exemplar;
#ifndef TN_NO_ENGINE
    (void)tn_test_same_params;
#endif
#ifndef TN_NO_NOISE
    (void)tn_test_dem;
#endif
#ifndef TN_NO_TEXGAN
    (void)tn_test_tiny_texgan_opts;
#endif
#ifndef TN_NO_GNN
    (void)tn_test_tiny_gnn_opts;
#endif
#ifndef TN_NO_SINGAN
    (void)tn_test_tiny_singan_opts;
#endif
#ifndef TN_NO_SEASON
    (void)tn_test_kpd_set_make;
    (void)tn_test_kpd_set_free;
    (void)tn_test_small_kpd_opts;
#endif
#endif
    printf("%s: %d passed, %d failed, %d skipped\n", file, tn_test_passed, tn_test_failed, tn_test_skipped);
    return tn_test_failed ? 1 : 0;
}

/* Path of a reference file kept in the repository (tests/refs/, tests run from the top). */
static const char *tn_test_ref(const char *rel)
{
    static char buf[512];
    snprintf(buf, sizeof buf, "tests/refs/%s", rel);
    return buf;
}

/* Path of a file under ../shared/data (or $TN_SHARED_DATA), or NULL when it is not there. */
static const char *tn_test_data(const char *rel)
{
    static char buf[1024];
    const char *root = getenv("TN_SHARED_DATA");
    FILE *f;
    if (!root) root = "../shared/data";
    snprintf(buf, sizeof buf, "%s/%s", root, rel);
    f = fopen(buf, "rb");
    if (!f) return NULL;
    fclose(f);
    return buf;
}

/* A whole file in a malloc'ed buffer (NUL-terminated, *n bytes), or NULL. */
static unsigned char *tn_test_read_file(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    unsigned char *b = NULL;
    long len;
    *n = 0;
    if (!f) return NULL;
    if (fseek(f, 0, SEEK_END) == 0 && (len = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0 && (b = (unsigned char *)malloc((size_t)len + 1))) {
        *n = fread(b, 1, (size_t)len, f);
        b[*n] = 0;
    }
    fclose(f);
    return b;
}

/* Writes text to path; 1 when it was written whole. */
static int tn_test_write_text(const char *path, const char *text)
{
    FILE *f = fopen(path, "w");
    int ok = f && fputs(text, f) >= 0;
    if (f) ok &= fclose(f) == 0;
    return ok;
}

#ifdef TERRAINNET_H
/* The texture-GAN tests' exemplar: stripes, blobs and noise in [0, 1] (also the recipe of
   tests/refs/texgan_v1_*.tnw, made with w 40, h 36, 3 channels, seed 1). */
static tn_image tn_test_exemplar(int w, int h, int channels, uint64_t seed)
{
    tn_image img = {0, 0, 0, NULL};
    tn_rng r;
    int x, y, c;
    tn_rng_seed(&r, seed, 3);
    if (tn_image_create(&img, w, h, channels)) return img;
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++)
            for (c = 0; c < channels; c++)
                TN_PIXEL(&img, x, y, c) = 0.3f + 0.2f * sinf(0.7f * (float)x + (float)c) * cosf(0.4f * (float)y) + 0.2f * tn_rng_uniform(&r);
    return img;
}

/* An n x n Perlin terrain (4 octaves, 3 cells across) from 1000 to 2000 m: a small DEM with
   ridges and valleys for the learned methods' tests. */
#ifndef TN_NO_NOISE
static tn_image tn_test_dem(int n, uint64_t seed)
{
    tn_image d = {0, 0, 0, NULL};
    tn_perlin_opts po;
    size_t i;
    memset(&po, 0, sizeof po);
    po.seed = seed;
    po.octaves = 4;
    po.frequency = 3;
    if (tn_noise_perlin(&d, n, n, &po)) return d;
    for (i = 0; i < (size_t)d.width * d.height; i++) d.data[i] = 1000.0f + 1000.0f * d.data[i];
    return d;
}
#endif

/* A texture GAN small enough to train in a second under the sanitizers (set train.max_iters). */
#ifndef TN_NO_TEXGAN
static void tn_test_tiny_texgan_opts(tn_texgan_opts *o)
{
    memset(o, 0, sizeof *o);
    o->noise_local = 4;
    o->stages = 2;
    o->gen_width = 16;
    o->disc_width = 8;
    o->disc_layers = 2;
    o->patch = 16;
    o->batch = 2;
    o->train.minutes = 100;
    o->train.seed = 5;
}
#endif

/* A sketch-to-terrain network of a few thousand weights, trained for `iters` iterations. */
#ifndef TN_NO_GNN
static void tn_test_tiny_gnn_opts(tn_gnn_opts *o, long iters)
{
    memset(o, 0, sizeof *o);
    o->hidden = 16;
    o->embed = 8;
    o->k = 6;
    o->random_edges = 300;
    o->train.max_iters = iters;
    o->train.seed = 7;
}
#endif

/* A SinGAN of 3 scales of 12..24 px on tn_test_dem(24, ...), 8 channels, `iters` per scale. */
#ifndef TN_NO_SINGAN
static void tn_test_tiny_singan_opts(tn_singan_opts *o, int iters)
{
    memset(o, 0, sizeof *o);
    o->coarsest = 12;
    o->factor = 0.7f;
    o->channels = 8;
    o->max_channels = 8;
    o->iters = iters;
    o->height_weight = -1; /* off: at these sizes and counts it slows the reconstruction (test_singan's heights test turns it on) */
    o->train.seed = 3;
}
#endif

#ifndef TN_NO_SEASON
/* A small paired set: the procedural texturer's pictures of a Perlin DEM at four months. */
struct tn_test_kpd_set {
    tn_image dem, ins, tex[4], mask;
    tn_climate c;
    tn_season_sample s[4];
};

static int tn_test_kpd_set_make(tn_test_kpd_set *k, int n)
{
    tn_insolation_opts io;
    float times[4] = {0.0f, 3.0f, 6.0f, 9.0f};
    int i;
    size_t p;
    memset(k, 0, sizeof *k);
    k->dem = tn_test_dem(n, 5);
    memset(&io, 0, sizeof io);
    io.dx = 30.0f;
    io.step_minutes = 60.0f;
    io.directions = 8;
    if (!k->dem.data || tn_climate_koppen(&k->c, "Dfb") || tn_insolation(&k->ins, &k->dem, 55.8, &io)) return 0;
    if (tn_season_texture(k->tex, &k->dem, &k->c, 55.8, &k->ins, times, 4, NULL, NULL)) return 0;
    if (tn_image_create(&k->mask, n, n, 1)) return 0;
    for (p = 0; p < (size_t)n * n; p++) k->mask.data[p] = (p % 7) != 0; /* every 7th pixel unusable */
    for (i = 0; i < 4; i++) {
        k->s[i].dem = &k->dem;
        k->s[i].insolation = &k->ins;
        k->s[i].climate = &k->c;
        k->s[i].time = times[i];
        k->s[i].target = &k->tex[i];
        k->s[i].mask = &k->mask;
    }
    return 1;
}

static void tn_test_kpd_set_free(tn_test_kpd_set *k)
{
    int i;
    tn_image_free(&k->dem);
    tn_image_free(&k->ins);
    tn_image_free(&k->mask);
    for (i = 0; i < 4; i++) tn_image_free(&k->tex[i]);
}

static void tn_test_small_kpd_opts(tn_kpd_opts *o, long iters)
{
    memset(o, 0, sizeof *o);
    o->width = 8;
    o->crop = 32;
    o->batch = 2;
    o->train.max_iters = iters;
    o->train.minutes = 5;
    o->train.seed = 3;
}

#endif

/* 1 when two parameter sets hold the same tensors bit for bit (names, sizes, values), from the
   skip-th tensor on (texgan's first tensor is its configuration). */
#ifndef TN_NO_ENGINE
static int tn_test_same_params(const tn_params *a, const tn_params *b, int skip)
{
    int i;
    if (tn_params_count(a) != tn_params_count(b)) return 0;
    for (i = skip; i < tn_params_count(a); i++) {
        const tn_tensor *x = tn_params_get(a, i), *y = tn_params_get(b, i);
        if (x->numel != y->numel || strcmp(x->name, y->name) || memcmp(x->data, y->data, x->numel * sizeof(float))) return 0;
    }
    return 1;
}
#endif
#endif
#endif
