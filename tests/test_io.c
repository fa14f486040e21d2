/* Tests of @@io (everything but the PNG codec internals): round trips of every format at 8/16 bit
   and 1/3 channels with the range record, the real SRTM tile and 16-bit PNGs, void filling,
   corrupt/truncated/garbage inputs, absurd sizes, atomic saving, .r16 size inference. */
/* Allocations are counted to check that absurd sizes fail before allocating. */
#include <stdlib.h>
static size_t tn_io_test_allocs;
static void *tn_io_test_malloc(size_t n) { tn_io_test_allocs++; return malloc(n); }
static void *tn_io_test_realloc(void *p, size_t n) { tn_io_test_allocs++; return realloc(p, n); }
#define TN_MALLOC(sz) tn_io_test_malloc(sz)
#define TN_REALLOC(p, sz) tn_io_test_realloc(p, sz)
#define TN_FREE(p) free(p)
#ifdef TN_TEST_TU /* scratch build: the library plus the sections not yet in terrainnet.h */
#include TN_TEST_TU
#else
/* Its own implementation (private tn__ code), with only @@core ... @@metrics compiled in. */
#define TN_NO_ENGINE
#define TN_NO_NOISE
#define TN_NO_SKETCH
#define TN_NO_EXTRACT
#define TN_NO_STYLE
#define TN_NO_TEXGAN
#define TN_NO_SINGAN
#define TN_NO_GNN
#define TN_NO_SEASON
#define TN_NO_RENDER
#define TN_NO_EXPORT
#define TN_NO_WORLD
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#endif
#include "tn_test.h"

/* ---- helpers ---- */

static const char *tmp_path(const char *leaf) { return tn_test_tmp_path("io", leaf); }

/* A smooth deterministic pattern in [lo, hi], reaching both ends. */
static void fill_pattern(tn_image *img, float lo, float hi)
{
    size_t i, n = (size_t)img->width * img->height * img->channels;
    for (i = 0; i < n; i++) img->data[i] = lo + (hi - lo) * (float)((i * 7919u) % 1001u) / 1000.0f;
    if (n >= 2) { img->data[0] = lo; img->data[n - 1] = hi; }
}

static double max_abs_diff(const tn_image *a, const tn_image *b)
{
    size_t i, n = (size_t)a->width * a->height * a->channels;
    double m = 0;
    for (i = 0; i < n; i++)
        if (fabs((double)a->data[i] - b->data[i]) > m) m = fabs((double)a->data[i] - b->data[i]);
    return m;
}

static int file_bytes(const char *path, char *buf, size_t cap)
{
    FILE *f = fopen(path, "rb");
    int n;
    if (!f) return -1;
    n = (int)fread(buf, 1, cap, f);
    fclose(f);
    return n;
}

static void write_file(const char *path, const void *d, size_t n)
{
    FILE *f = fopen(path, "wb");
    if (!f) return;
    fwrite(d, 1, n, f);
    fclose(f);
}

static tn_status load_text(const char *text, const char *name, tn_image *img, tn_image_info *info)
{
    return tn_image_load_memory(img, text, strlen(text), name, NULL, info);
}

/* Saves img in format f with opts, loads it back, checks shape and error bound. */
static void roundtrip(tn_format f, int w, int h, int ch, int bits, float lo, float hi, const tn_save_opts *extra,
                      int expect_range)
{
    tn_image img = {0, 0, 0, NULL}, back = {0, 0, 0, NULL};
    tn_image_info info;
    tn_save_opts o;
    uint8_t *buf = NULL;
    size_t n = 0;
    unsigned maxc = bits == 16 ? 65535u : 255u;
    double span;
    if (extra) o = *extra;
    else memset(&o, 0, sizeof o);
    o.bit_depth = bits;
    TN_CHECK(tn_image_create(&img, w, h, ch) == TN_OK);
    fill_pattern(&img, lo, hi);
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, f, &o) == TN_OK);
    TN_CHECK(tn_image_load_memory(&back, buf, n, NULL, NULL, &info) == TN_OK);
    TN_CHECK(back.width == w && back.height == h && back.channels == ch);
    TN_CHECK(info.format == f);
    TN_CHECK(info.file_channels == ch);
    TN_CHECK(info.has_range == expect_range);
    if (f == TN_FORMAT_PNM || f == TN_FORMAT_PNG) TN_CHECK(info.bit_depth == bits);
    span = expect_range ? info.range_hi - info.range_lo : 1.0;
    if (expect_range && !o.has_range) { /* mapped from the data's own min..max */
        TN_CHECK_NEAR(info.range_lo, lo, 1e-9 * (fabs(lo) + 1));
        TN_CHECK_NEAR(info.range_hi, hi, 1e-9 * (fabs(hi) + 1));
    }
    if (o.has_range) {
        TN_CHECK(info.range_lo == o.range_lo && info.range_hi == o.range_hi);
    }
    if (back.data) TN_CHECK(max_abs_diff(&img, &back) <= 0.5 * fabs(span) / maxc * 1.001 + 1e-6 * (fabs(hi) + 1));
    tn_free(buf);
    tn_image_free(&img);
    tn_image_free(&back);
}

/* ---- tests ---- */

TN_TEST(format_names)
{
    TN_CHECK(strcmp(tn_format_name(TN_FORMAT_PNG), "png") == 0);
    TN_CHECK(strcmp(tn_format_name(TN_FORMAT_PNM), "pnm") == 0);
    TN_CHECK(strcmp(tn_format_name(TN_FORMAT_PFM), "pfm") == 0);
    TN_CHECK(strcmp(tn_format_name(TN_FORMAT_HGT), "hgt") == 0);
    TN_CHECK(strcmp(tn_format_name(TN_FORMAT_ASC), "asc") == 0);
    TN_CHECK(strcmp(tn_format_name(TN_FORMAT_R16), "r16") == 0);
    TN_CHECK(strcmp(tn_format_name((tn_format)99), "unknown") == 0);
    tn_free(NULL);
}

TN_TEST(pnm_roundtrip_8_16_bit_1_3_channels)
{
    tn_save_opts o;
    int bits, ch;
    for (bits = 8; bits <= 16; bits += 8)
        for (ch = 1; ch <= 3; ch += 2) {
            roundtrip(TN_FORMAT_PNM, 37, 23, ch, bits, 0.0f, 1.0f, NULL, 0);        /* [0,1]: no record */
            roundtrip(TN_FORMAT_PNM, 37, 23, ch, bits, 388.0f, 2937.0f, NULL, 1);   /* metres: min..max */
            roundtrip(TN_FORMAT_PNM, 5, 4, ch, bits, -6011.0f, 5623.5f, NULL, 1);   /* negative heights */
        }
    memset(&o, 0, sizeof o);
    o.has_range = 1;
    o.range_lo = -100.0;
    o.range_hi = 5000.0;
    roundtrip(TN_FORMAT_PNM, 16, 9, 1, 16, 0.0f, 4000.0f, &o, 1);
    roundtrip(TN_FORMAT_PNM, 16, 9, 3, 8, 0.0f, 4000.0f, &o, 1);
}

TN_TEST(pnm_header_text_and_files)
{
    tn_image img = {0, 0, 0, NULL}, back = {0, 0, 0, NULL};
    tn_image_info info;
    tn_save_opts o;
    char text[256];
    const char *path = tmp_path("a.pgm");
    int n;
    TN_CHECK(tn_image_create(&img, 4, 3, 1) == TN_OK);
    fill_pattern(&img, 388.0f, 2937.0f);
    TN_CHECK(tn_image_save(path, &img, NULL) == TN_OK);
    n = file_bytes(path, text, sizeof text - 1);
    TN_CHECK(n > 0);
    if (n > 0) {
        text[n] = 0;
        TN_CHECK(strncmp(text, "P5\n# terrainnet.range 388 2937\n4 3\n65535\n", 41) == 0);
        TN_CHECK(n == 41 + 4 * 3 * 2);
    }
    TN_CHECK(tn_image_load(&back, path, &info) == TN_OK);
    TN_CHECK(info.format == TN_FORMAT_PNM && info.has_range == 1 && info.range_lo == 388.0 && info.range_hi == 2937.0);
    TN_CHECK(back.data && max_abs_diff(&img, &back) < 0.03);
    tn_image_free(&back);
    /* [0,1] data, 8-bit PPM: no range comment */
    tn_image_free(&img);
    TN_CHECK(tn_image_create(&img, 2, 2, 3) == TN_OK);
    fill_pattern(&img, 0.0f, 1.0f);
    memset(&o, 0, sizeof o);
    path = tmp_path("b.ppm");
    TN_CHECK(tn_image_save(path, &img, &o) == TN_OK);
    n = file_bytes(path, text, sizeof text - 1);
    TN_CHECK(n == 11 + 12);
    if (n > 0) TN_CHECK(memcmp(text, "P6\n2 2\n255\n", 11) == 0);
    remove(path);
    remove(tmp_path("a.pgm"));
    tn_image_free(&img);
}

TN_TEST(pnm_ascii_with_comments_everywhere)
{
    tn_image img = {0, 0, 0, NULL};
    tn_image_info info;
    const char *p2 = "P2 # grey\n# a comment\n3 # width\n2\n# terrainnet.range 100 1100\n1000\n"
                     "0 500 1000\n# comment inside the data\n250 750\n100\n";
    const char *p3 = "P3\n2 1\n255\n255 0 0  0 128 255\n";
    TN_CHECK(load_text(p2, "x.pgm", &img, &info) == TN_OK);
    TN_CHECK(img.width == 3 && img.height == 2 && img.channels == 1);
    TN_CHECK(info.bit_depth == 10 && info.has_range == 1);
    if (img.data) {
        TN_CHECK_NEAR(img.data[0], 100.0, 1e-4);
        TN_CHECK_NEAR(img.data[1], 600.0, 1e-4);
        TN_CHECK_NEAR(img.data[2], 1100.0, 1e-4);
        TN_CHECK_NEAR(img.data[5], 200.0, 1e-4);
    }
    tn_image_free(&img);
    TN_CHECK(load_text(p3, NULL, &img, &info) == TN_OK);
    TN_CHECK(img.channels == 3 && info.file_channels == 3 && info.bit_depth == 8 && info.has_range == 0);
    if (img.data) {
        TN_CHECK(img.data[0] == 1.0f && img.data[1] == 0.0f);
        TN_CHECK_NEAR(img.data[4], 128.0 / 255.0, 1e-7);
    }
    tn_image_free(&img);
    /* sample above maxval, missing sample, PBM */
    TN_CHECK(load_text("P2 2 1 10 3 11", NULL, &img, NULL) == TN_ERR_CORRUPT);
    TN_CHECK(load_text("P2 2 1 10 3 ", NULL, &img, NULL) == TN_ERR_CORRUPT);
    TN_CHECK(load_text("P2 2 1 10 3 x", NULL, &img, NULL) == TN_ERR_CORRUPT);
    TN_CHECK(load_text("P1 2 1 0 1", NULL, &img, NULL) == TN_ERR_FORMAT);
    TN_CHECK(load_text("P5 2 1 70000 ", NULL, &img, NULL) == TN_ERR_FORMAT);
    TN_CHECK(load_text("P5 0 1 255 ", NULL, &img, NULL) == TN_ERR_CORRUPT);
    TN_CHECK(img.data == NULL);
}

TN_TEST(pnm_16bit_is_big_endian)
{
    static const unsigned char p5[] = {'P', '5', '\n', '2', ' ', '1', '\n', '6', '5', '5', '3', '5', '\n', 0x01, 0x02, 0xff, 0xfe};
    tn_image img = {0, 0, 0, NULL};
    tn_image_info info;
    TN_CHECK(tn_image_load_memory(&img, p5, sizeof p5, NULL, NULL, &info) == TN_OK);
    TN_CHECK(info.bit_depth == 16);
    if (img.data) {
        TN_CHECK_NEAR(img.data[0], 258.0 / 65535.0, 1e-7);
        TN_CHECK_NEAR(img.data[1], 65534.0 / 65535.0, 1e-7);
    }
    tn_image_free(&img);
}

TN_TEST(pfm_roundtrip_and_orientation)
{
    /* big-endian (positive scale) grey 2x2: file rows bottom to top */
    static const unsigned char be[] = {'P', 'f', '\n', '2', ' ', '2', '\n', '1', '.', '0', '\n',
                                       0x3f, 0x80, 0, 0, 0x40, 0, 0, 0,     /* bottom row: 1 2 */
                                       0x40, 0x40, 0, 0, 0xc0, 0x80, 0, 0}; /* top row: 3 -4 */
    unsigned char nanpfm[sizeof be];
    tn_image img = {0, 0, 0, NULL}, back = {0, 0, 0, NULL};
    tn_image_info info;
    uint8_t *buf = NULL;
    size_t n = 0;
    int ch;
    TN_CHECK(tn_image_load_memory(&img, be, sizeof be, NULL, NULL, &info) == TN_OK);
    TN_CHECK(info.format == TN_FORMAT_PFM && info.bit_depth == 32 && info.file_channels == 1);
    if (img.data) {
        TN_CHECK(img.data[0] == 3.0f && img.data[1] == -4.0f && img.data[2] == 1.0f && img.data[3] == 2.0f);
    }
    tn_image_free(&img);
    memcpy(nanpfm, be, sizeof be);
    nanpfm[11] = 0x7f; nanpfm[12] = 0xc0; /* NaN */
    TN_CHECK(tn_image_load_memory(&img, nanpfm, sizeof nanpfm, "n.pfm", NULL, NULL) == TN_ERR_NUMERIC);
    TN_CHECK(strstr(tn_last_error(), "n.pfm") != NULL);
    TN_CHECK(img.data == NULL);
    for (ch = 1; ch <= 3; ch += 2) { /* bit exact, little endian as written */
        TN_CHECK(tn_image_create(&img, 13, 7, ch) == TN_OK);
        fill_pattern(&img, -1234.5f, 8848.25f);
        img.data[5] = 1e-30f;
        TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_PFM, NULL) == TN_OK);
        TN_CHECK(n > 4 && buf[0] == 'P' && buf[1] == (ch == 3 ? 'F' : 'f'));
        TN_CHECK(tn_image_load_memory(&back, buf, n, NULL, NULL, &info) == TN_OK);
        TN_CHECK(back.channels == ch && back.data && max_abs_diff(&img, &back) == 0.0);
        tn_free(buf);
        tn_image_free(&img);
        tn_image_free(&back);
    }
}

/* A synthetic 1201x1201 .hgt buffer: a tilted plane (metres), big-endian. */
static uint8_t *make_hgt(void)
{
    uint8_t *b = (uint8_t *)malloc((size_t)1201 * 1201 * 2);
    int x, y;
    if (!b) return NULL;
    for (y = 0; y < 1201; y++)
        for (x = 0; x < 1201; x++) {
            int v = 100 + 2 * x + 3 * y;
            b[2 * ((size_t)y * 1201 + x)] = (uint8_t)(v >> 8);
            b[2 * ((size_t)y * 1201 + x) + 1] = (uint8_t)v;
        }
    return b;
}

static void set_void(uint8_t *b, int x, int y)
{
    b[2 * ((size_t)y * 1201 + x)] = 0x80;
    b[2 * ((size_t)y * 1201 + x) + 1] = 0x00;
}

/* A 3601 x 3601 (1 arc-second) .hgt of voids but two 5 x 5 patches on row 1800, at 0 m (x 600)
   and 1000 m (x 3000): 12,967,151 void cells, more than the relaxation's budget covers, so the
   pyramid fills them. Between the patches the fill must be a smooth rise: within the patches'
   heights and without a crease (the onion fill with 16 relaxation passes left one where the two
   fronts met, and took seconds where this takes a fraction) */
TN_TEST(hgt_huge_voids_fill_smoothly)
{
    const int N = 3601;
    uint8_t *b = (uint8_t *)malloc((size_t)N * N * 2);
    tn_image img = {0, 0, 0, NULL};
    tn_image_info info;
    size_t i;
    int x, y, k;
    double crease = 0, lo = 1e9, hi = -1e9;
    if (!b) TN_SKIP("no memory");
    for (i = 0; i < (size_t)N * N; i++) b[2 * i] = 0x80, b[2 * i + 1] = 0x00;
    for (k = 0; k < 2; k++)
        for (y = 1798; y <= 1802; y++)
            for (x = (k ? 2998 : 598); x <= (k ? 3002 : 602); x++) {
                size_t c = (size_t)y * N + x;
                b[2 * c] = (uint8_t)((k ? 1000 : 0) >> 8), b[2 * c + 1] = (uint8_t)(k ? 1000 : 0);
            }
    TN_CHECK(tn_image_load_memory(&img, b, (size_t)N * N * 2, "N01E001.hgt", NULL, &info) == TN_OK);
    TN_CHECK(info.voids_filled == (size_t)N * N - 50);
    for (x = 610; img.data && x <= 2990; x++) {
        const float *r = img.data + (size_t)1800 * N;
        lo = fmin(lo, r[x]), hi = fmax(hi, r[x]);
        crease = fmax(crease, fabs((double)r[x - 1] - 2.0 * r[x] + r[x + 1]));
    }
    fprintf(stderr, "  huge voids: row between the patches %.1f .. %.1f m, largest second difference %.3f m\n", lo, hi, crease);
    TN_CHECK(lo >= 0 && hi <= 1000 && hi - lo > 500 && crease < 1.0);
    tn_image_free(&img);
    free(b);
}

TN_TEST(hgt_roundtrip_voids_and_errors)
{
    uint8_t *b = make_hgt(), *out = NULL;
    tn_image img = {0, 0, 0, NULL}, small = {0, 0, 0, NULL};
    tn_image_info info;
    size_t n = (size_t)1201 * 1201 * 2, on = 0, i;
    int x, y;
    double worst = 0;
    if (!b) TN_SKIP("no memory");
    TN_CHECK(tn_image_load_memory(&img, b, n, "N00E000.hgt", NULL, &info) == TN_OK);
    TN_CHECK(img.width == 1201 && img.height == 1201 && info.format == TN_FORMAT_HGT && info.voids_filled == 0);
    if (img.data) {
        TN_CHECK(img.data[0] == 100.0f && img.data[1] == 102.0f && img.data[1201] == 103.0f);
        img.data[0] = 40000.0f;  /* clamps to 32767 */
        img.data[1] = -40000.0f; /* clamps to -32767, not the void marker */
        img.data[2] = 103.6f;    /* rounds */
        TN_CHECK(tn_image_save_memory(&out, &on, &img, TN_FORMAT_HGT, NULL) == TN_OK);
        TN_CHECK(on == n);
        if (out) {
            TN_CHECK(out[0] == 0x7f && out[1] == 0xff && out[2] == 0x80 && out[3] == 0x01);
            TN_CHECK(out[4] == 0 && out[5] == 104);
            TN_CHECK(memcmp(out + 6, b + 6, n - 6) == 0);
        }
        tn_free(out);
    }
    tn_image_free(&img);
    /* voids: a 30x20 hole and scattered single cells in the plane */
    for (y = 500; y < 520; y++)
        for (x = 600; x < 630; x++) set_void(b, x, y);
    set_void(b, 0, 0);
    set_void(b, 1200, 1200);
    set_void(b, 77, 1000);
    TN_CHECK(tn_image_load_memory(&img, b, n, "N00E000.HGT", NULL, &info) == TN_OK);
    TN_CHECK(info.voids_filled == 30 * 20 + 3);
    if (img.data) {
        for (y = 500; y < 520; y++)
            for (x = 600; x < 630; x++) {
                double d = fabs(img.data[(size_t)y * 1201 + x] - (100.0 + 2 * x + 3 * y));
                if (d > worst) worst = d;
            }
        /* a plane is harmonic: the fill must stay close to it (the hole spans 97 m of relief) */
        TN_CHECK(worst < 1.0);
        TN_CHECK_NEAR(img.data[(size_t)1000 * 1201 + 77], 100.0 + 2 * 77 + 3 * 1000, 1e-3);
        TN_CHECK(fabs(img.data[0] - 100.0) < 6.0);
        for (i = 0; i < n / 2; i++) TN_CHECK(img.data[i] >= 100.0f && img.data[i] <= 6100.0f);
    }
    fprintf(stderr, "  hgt hole fill: worst error %.3f m on a plane\n", worst);
    tn_image_free(&img);
    /* all void -> empty */
    memset(b, 0, n);
    for (i = 0; i < n; i += 2) b[i] = 0x80;
    TN_CHECK(tn_image_load_memory(&img, b, n, "v.hgt", NULL, &info) == TN_ERR_EMPTY);
    TN_CHECK(img.data == NULL);
    /* wrong sizes */
    TN_CHECK(tn_image_load_memory(&img, b, n - 1, "t.hgt", NULL, &info) == TN_ERR_CORRUPT);
    TN_CHECK(strstr(tn_last_error(), "t.hgt") != NULL);
    TN_CHECK(tn_image_load_memory(&img, b, 0, "t.hgt", NULL, &info) == TN_ERR_CORRUPT);
    /* only 1201/3601 squares can be written */
    TN_CHECK(tn_image_create(&small, 100, 100, 1) == TN_OK);
    TN_CHECK(tn_image_save_memory(&out, &on, &small, TN_FORMAT_HGT, NULL) == TN_ERR_SHAPE);
    TN_CHECK(out == NULL);
    tn_image_free(&small);
    free(b);
}

TN_TEST(hgt_real_srtm_tile)
{
    const char *path = tn_test_data("dem/alps_n47e009/original/N47E009.hgt");
    tn_image img = {0, 0, 0, NULL};
    tn_image_info info;
    float lo, hi;
    if (!path) TN_SKIP("shared data not found");
    TN_CHECK(tn_image_load(&img, path, &info) == TN_OK);
    TN_CHECK(img.width == 1201 && img.height == 1201 && img.channels == 1);
    TN_CHECK(info.format == TN_FORMAT_HGT && info.voids_filled == 0 && info.bit_depth == 16);
    if (img.data) {
        TN_CHECK(tn_image_range(&lo, &hi, &img) == 0);
        TN_CHECK(lo == 388.0f && hi == 2937.0f); /* MANIFEST.md: 388 .. 2937 m */
    }
    tn_image_free(&img);
}

TN_TEST(png_real_16bit_matches_hgt)
{
    const char *p = tn_test_data("dem/alps_n47e009/alps_n47e009_full.png");
    char png[1024];
    const char *h;
    tn_image a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_image_info info;
    double worst = 0;
    int x, y;
#ifdef TN_TEST_PNG_SHIM
    TN_SKIP("PNG codec not integrated (shim build)");
#endif
    if (!p) TN_SKIP("shared data not found");
    snprintf(png, sizeof png, "%s", p);
    h = tn_test_data("dem/alps_n47e009/original/N47E009.hgt");
    if (!h) TN_SKIP("shared data not found");
    TN_CHECK(tn_image_load(&a, png, &info) == TN_OK);
    TN_CHECK(info.format == TN_FORMAT_PNG && info.bit_depth == 16 && info.has_range == 0);
    TN_CHECK(a.width == 1024 && a.height == 1024 && a.channels == 1);
    TN_CHECK(tn_image_load(&b, h, NULL) == TN_OK);
    if (a.data && b.data && a.width == 1024) { /* MANIFEST: rows/cols 177-1200 of the tile, 0 -> 388 m, 65535 -> 2937 m */
        for (y = 0; y < 1024; y++)
            for (x = 0; x < 1024; x++) {
                double m = 388.0 + a.data[(size_t)y * 1024 + x] * (2937.0 - 388.0);
                double d = fabs(m - b.data[(size_t)(y + 177) * 1201 + (x + 177)]);
                if (d > worst) worst = d;
            }
        TN_CHECK(worst < 0.03); /* half a 16-bit step is 0.019 m */
    }
    tn_image_free(&a);
    tn_image_free(&b);
    p = tn_test_data("dem/grandcanyon_hoppe8bit/grandcanyon_hoppe8bit_256.png");
    if (p) {
        float lo, hi;
        TN_CHECK(tn_image_load(&a, p, &info) == TN_OK);
        TN_CHECK(a.width == 256 && a.height == 256);
        if (a.data) {
            tn_image_range(&lo, &hi, &a);
            TN_CHECK_NEAR(lo * 255.0, 39.0, 1e-3); /* MANIFEST: grey 39 .. 172 */
            TN_CHECK_NEAR(hi * 255.0, 172.0, 1e-3);
        }
        tn_image_free(&a);
    }
}

TN_TEST(png_roundtrip_8_16_bit_1_3_channels)
{
    tn_save_opts o;
    int bits, ch;
    for (bits = 8; bits <= 16; bits += 8)
        for (ch = 1; ch <= 3; ch += 2) {
            roundtrip(TN_FORMAT_PNG, 31, 17, ch, bits, 0.0f, 1.0f, NULL, 0);
            /* the PNG codec applies "terrainnet.range" to grey images only */
            if (ch == 1) roundtrip(TN_FORMAT_PNG, 31, 17, ch, bits, 388.0f, 2937.0f, NULL, 1);
        }
    memset(&o, 0, sizeof o);
    o.has_range = 1;
    o.range_lo = 0.0;
    o.range_hi = 9000.0;
    o.compression = 9;
    roundtrip(TN_FORMAT_PNG, 64, 64, 1, 16, 10.0f, 8848.0f, &o, 1);
}

TN_TEST(asc_roundtrip_and_header)
{
    tn_image img = {0, 0, 0, NULL}, back = {0, 0, 0, NULL};
    tn_image_info info;
    tn_save_opts o;
    uint8_t *buf = NULL;
    size_t n = 0;
    const char *text = "NCOLS 4\nnRows 3\nXLLCENTER 1000.5\nyllcorner -20\nCellSize 2\nnodata_value -9999\n"
                       "1 2 3 4\n5 -9999 7 8\n9 10 11 12\n";
    TN_CHECK(tn_image_create(&img, 9, 5, 1) == TN_OK);
    fill_pattern(&img, -432.1f, 4810.7f);
    img.data[3] = 0.1f;
    img.data[4] = 1e-7f;
    memset(&o, 0, sizeof o);
    o.cellsize = 30.0;
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_ASC, &o) == TN_OK);
    TN_CHECK(tn_image_load_memory(&back, buf, n, NULL, NULL, &info) == TN_OK);
    TN_CHECK(info.format == TN_FORMAT_ASC && info.cellsize == 30.0 && info.x_origin == 0.0 && info.voids_filled == 0);
    TN_CHECK(back.width == 9 && back.height == 5 && back.data && max_abs_diff(&img, &back) == 0.0); /* exact text */
    tn_free(buf);
    tn_image_free(&back);
    tn_image_free(&img);
    TN_CHECK(load_text(text, NULL, &img, &info) == TN_OK);
    TN_CHECK(info.cellsize == 2.0 && info.x_origin == 999.5 && info.y_origin == -20.0 && info.voids_filled == 1);
    if (img.data) {
        TN_CHECK(img.data[0] == 1.0f && img.data[11] == 12.0f);
        TN_CHECK(img.data[5] > 2.0f && img.data[5] < 10.0f); /* filled between its neighbours */
    }
    tn_image_free(&img);
    /* errors */
    TN_CHECK(load_text("ncols 2\nnrows 2\n1 2 3", "t.asc", &img, NULL) == TN_ERR_CORRUPT);
    TN_CHECK(strstr(tn_last_error(), "t.asc") != NULL);
    TN_CHECK(load_text("ncols 2\nnrows 1\n1 2 3", NULL, &img, NULL) == TN_ERR_CORRUPT);
    TN_CHECK(load_text("ncols 2\nnrows 1\n1 abc", NULL, &img, NULL) == TN_ERR_CORRUPT);
    TN_CHECK(load_text("nrows 1\n1 2", NULL, &img, NULL) == TN_ERR_CORRUPT);
    TN_CHECK(load_text("ncols 2.5\nnrows 1\n1 2", NULL, &img, NULL) == TN_ERR_CORRUPT);
    TN_CHECK(load_text("ncols 2\nnrows 1\nbogus 3\n1 2", NULL, &img, NULL) == TN_ERR_FORMAT);
    TN_CHECK(load_text("ncols 2\nnrows 1\nNODATA_value 5\n5 5", NULL, &img, NULL) == TN_ERR_EMPTY);
    TN_CHECK(load_text("ncols 2\nnrows 1\n1 nan", NULL, &img, &info) == TN_OK && info.voids_filled == 1);
    tn_image_free(&img);
    TN_CHECK(load_text("ncols 2\nnrows 1\n1 1e300", NULL, &img, &info) == TN_ERR_CORRUPT);
    TN_CHECK(img.data == NULL);
}

TN_TEST(r16_roundtrip_and_size_inference)
{
    tn_image img = {0, 0, 0, NULL}, back = {0, 0, 0, NULL};
    tn_image_info info;
    tn_load_opts lo;
    uint8_t *buf = NULL, raw[2 * 6];
    size_t n = 0;
    float mn, mx;
    memset(&lo, 0, sizeof lo);
    TN_CHECK(tn_image_create(&img, 20, 20, 1) == TN_OK);
    fill_pattern(&img, 0.0f, 1.0f);
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_R16, NULL) == TN_OK);
    TN_CHECK(n == 800);
    lo.format = TN_FORMAT_R16;
    TN_CHECK(tn_image_load_memory(&back, buf, n, NULL, &lo, &info) == TN_OK); /* 20x20 inferred */
    TN_CHECK(back.width == 20 && back.height == 20 && info.bit_depth == 16);
    TN_CHECK(back.data && max_abs_diff(&img, &back) <= 0.5 / 65535 + 1e-7);
    tn_image_free(&back);
    tn_free(buf);
    /* metres: mapped from min..max, which .r16 cannot record */
    fill_pattern(&img, 388.0f, 2937.0f);
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_R16, NULL) == TN_OK);
    TN_CHECK(tn_image_load_memory(&back, buf, n, "x.r16", NULL, &info) == TN_OK);
    TN_CHECK(info.has_range == 0 && back.data);
    if (back.data) {
        tn_image_range(&mn, &mx, &back);
        TN_CHECK(mn == 0.0f && mx == 1.0f);
    }
    tn_image_free(&back);
    tn_free(buf);
    tn_image_free(&img);
    /* non-square without dims, with dims, mismatching dims */
    memset(raw, 0, sizeof raw);
    raw[0] = 0xff; raw[1] = 0xff; raw[2] = 0x01; raw[3] = 0x00; /* 65535, 1: little endian */
    TN_CHECK(tn_image_load_memory(&back, raw, sizeof raw, "x.r16", NULL, NULL) == TN_ERR_SHAPE);
    TN_CHECK(strstr(tn_last_error(), "x.r16") != NULL);
    lo.format = TN_FORMAT_AUTO;
    lo.raw_width = 3;
    lo.raw_height = 2;
    TN_CHECK(tn_image_load_memory(&back, raw, sizeof raw, "x.raw", &lo, &info) == TN_OK);
    TN_CHECK(back.width == 3 && back.height == 2 && info.format == TN_FORMAT_R16);
    if (back.data) TN_CHECK(back.data[0] == 1.0f && back.data[1] == 1.0f / 65535.0f);
    tn_image_free(&back);
    lo.raw_width = 2;
    TN_CHECK(tn_image_load_memory(&back, raw, sizeof raw, "x.raw", &lo, &info) == TN_ERR_SHAPE);
    lo.raw_height = 0;
    TN_CHECK(tn_image_load_memory(&back, raw, sizeof raw, "x.raw", &lo, &info) == TN_ERR_INVALID_ARG);
    TN_CHECK(tn_image_load_memory(&back, raw, 5, "x.r16", NULL, NULL) == TN_ERR_SHAPE);
    TN_CHECK(tn_image_load_memory(&back, raw, 0, "x.r16", NULL, NULL) == TN_ERR_EMPTY);
    TN_CHECK(back.data == NULL);
}

TN_TEST(format_detection)
{
    tn_image img = {0, 0, 0, NULL};
    tn_image_info info;
    const char *pgm = "P2 1 1 255 7";
    TN_CHECK(load_text(pgm, "misnamed.hgt", &img, &info) == TN_OK && info.format == TN_FORMAT_PNM); /* magic wins */
    tn_image_free(&img);
    TN_CHECK(load_text("  ncols 1 nrows 1 5", NULL, &img, &info) == TN_OK && info.format == TN_FORMAT_ASC);
    tn_image_free(&img);
    TN_CHECK(load_text("nrows 1 ncols 1 5", NULL, &img, &info) == TN_OK && info.format == TN_FORMAT_ASC);
    tn_image_free(&img);
    TN_CHECK(load_text("\x01\x02", "a.R16", &img, &info) == TN_OK && info.format == TN_FORMAT_R16);
    tn_image_free(&img);
    TN_CHECK(load_text("\x01\x02", "dir.v1/noext", &img, &info) == TN_ERR_FORMAT);
    TN_CHECK(strstr(tn_last_error(), "dir.v1/noext") != NULL);
    TN_CHECK(tn_image_load(&img, "/nonexistent/dir/x.png", &info) == TN_ERR_IO);
    TN_CHECK(strstr(tn_last_error(), "/nonexistent/dir/x.png") != NULL);
    TN_CHECK(tn_image_load(&img, "/tmp", &info) == TN_ERR_IO || tn_image_load(&img, "/tmp", &info) == TN_ERR_FORMAT);
    TN_CHECK(img.data == NULL);
}

/* Every strict prefix of a valid encoding must fail (text formats: every prefix that drops at
   least the start of the last value). */
static void check_truncations(const uint8_t *buf, size_t n, const char *name, tn_format f, int text)
{
    size_t cut, limit = n, bad = 0;
    tn_load_opts o;
    tn_image img = {0, 0, 0, NULL};
    memset(&o, 0, sizeof o);
    o.format = f;
    if (text) { /* start of the last token */
        while (limit > 0 && (buf[limit - 1] == ' ' || buf[limit - 1] == '\n')) limit--;
        while (limit > 0 && buf[limit - 1] != ' ' && buf[limit - 1] != '\n') limit--;
    }
    for (cut = 0; cut < limit; cut++) {
        tn_status st = tn_image_load_memory(&img, buf, cut, name, &o, NULL);
        if (st == TN_OK) { bad++; tn_image_free(&img); }
    }
    if (bad) fprintf(stderr, "  %s: %zu truncations loaded\n", name, bad);
    TN_CHECK(bad == 0);
    TN_CHECK(tn_image_load_memory(&img, buf, n, name, &o, NULL) == TN_OK);
    tn_image_free(&img);
}

TN_TEST(truncated_inputs_fail)
{
    tn_image img = {0, 0, 0, NULL};
    tn_save_opts so;
    uint8_t *buf = NULL;
    size_t n = 0;
    static const tn_format fmts[] = {TN_FORMAT_PNM, TN_FORMAT_PFM, TN_FORMAT_ASC, TN_FORMAT_PNG};
    int k, bits;
    TN_CHECK(tn_image_create(&img, 11, 7, 1) == TN_OK);
    fill_pattern(&img, 100.0f, 900.0f);
    memset(&so, 0, sizeof so);
    for (k = 0; k < 4; k++)
        for (bits = 8; bits <= 16; bits += 8) {
            so.bit_depth = bits;
            if (tn_image_save_memory(&buf, &n, &img, fmts[k], &so) != TN_OK) { TN_CHECK(0); continue; }
            check_truncations(buf, n, tn_format_name(fmts[k]), fmts[k], fmts[k] == TN_FORMAT_ASC);
            tn_free(buf);
        }
    check_truncations((const uint8_t *)"P2 3 1 9 1 2 3", 14, "p2", TN_FORMAT_AUTO, 1);
    check_truncations((const uint8_t *)"P3 1 1 9 1 2 3", 14, "p3", TN_FORMAT_AUTO, 1);
    tn_image_free(&img);
}

TN_TEST(absurd_sizes_fail_without_allocating)
{
    static const char *const cases[] = {
        "P5 100000000 100000000 255", "P5 100000000 100000000 255\n\x01\x02", "P2 100000 100000 255 1 2 3",
        "P6 99999999999999999999 1 255 ", "PF\n100000000 100000000\n-1.0\n", "Pf 2147483647 2147483647 1 ",
        "ncols 100000000\nnrows 100000000\n1 2 3", "ncols 1e12 nrows 1e12 1"};
    tn_image img = {0, 0, 0, NULL};
    tn_load_opts o;
    size_t k, before;
    for (k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        tn_status st;
        before = tn_io_test_allocs;
        st = load_text(cases[k], "big", &img, NULL);
        if (st != TN_ERR_TOO_LARGE) fprintf(stderr, "  case %zu: %s (%s)\n", k, tn_status_string(st), tn_last_error());
        TN_CHECK(st == TN_ERR_TOO_LARGE);
        TN_CHECK(tn_io_test_allocs == before);
    }
    memset(&o, 0, sizeof o);
    o.format = TN_FORMAT_R16;
    o.raw_width = 2000000000;
    o.raw_height = 2000000000;
    before = tn_io_test_allocs;
    TN_CHECK(tn_image_load_memory(&img, "ab", 2, NULL, &o, NULL) == TN_ERR_TOO_LARGE);
    TN_CHECK(tn_io_test_allocs == before);
    /* big header, tiny data: truncation is reported before allocating */
    before = tn_io_test_allocs;
    TN_CHECK(load_text("P5 10000 10000 255\n\x01", NULL, &img, NULL) == TN_ERR_CORRUPT);
    TN_CHECK(load_text("ncols 10000\nnrows 10000\n1 2", NULL, &img, NULL) == TN_ERR_CORRUPT);
    TN_CHECK(tn_io_test_allocs == before);
    TN_CHECK(img.data == NULL);
}

TN_TEST(garbage_never_crashes)
{
    tn_rng r;
    uint8_t buf[512], *enc = NULL;
    size_t n = 0, i, k, ok = 0;
    tn_image img = {0, 0, 0, NULL};
    tn_load_opts o;
    int f;
    tn_rng_seed(&r, 42, 7);
    memset(&o, 0, sizeof o);
    for (k = 0; k < 3000; k++) { /* random bytes with forced formats, sometimes behind a valid magic */
        size_t len = tn_rng_below(&r, sizeof buf);
        for (i = 0; i < len; i++) buf[i] = (uint8_t)tn_rng_u32(&r);
        if (len > 3 && k % 3 == 0) { buf[0] = 'P'; buf[1] = "2356Ff"[k % 6]; buf[2] = ' '; }
        o.format = (tn_format)(k % 7);
        if (tn_image_load_memory(&img, buf, len, NULL, &o, NULL) == TN_OK) { ok++; tn_image_free(&img); }
    }
    /* mutated valid files */
    TN_CHECK(tn_image_create(&img, 9, 9, 1) == TN_OK);
    fill_pattern(&img, 0.0f, 1.0f);
    for (f = TN_FORMAT_PNG; f <= TN_FORMAT_ASC; f++) {
        if (f == TN_FORMAT_HGT) continue;
        if (tn_image_save_memory(&enc, &n, &img, (tn_format)f, NULL) != TN_OK) { TN_CHECK(0); continue; }
        for (k = 0; k < 500; k++) {
            tn_image t = {0, 0, 0, NULL};
            uint8_t *m = (uint8_t *)malloc(n);
            if (!m) break;
            memcpy(m, enc, n);
            for (i = 0; i < 1 + k % 4; i++) m[tn_rng_below(&r, (uint32_t)n)] = (uint8_t)tn_rng_u32(&r);
            if (tn_image_load_memory(&t, m, n, NULL, NULL, NULL) == TN_OK) tn_image_free(&t);
            free(m);
        }
        tn_free(enc);
    }
    tn_image_free(&img);
    TN_CHECK(1); /* reaching here under ASan/UBSan is the test */
    (void)ok;
}

TN_TEST(save_never_clobbers_on_failure)
{
    const char *path = tmp_path("keep.pgm");
    static const char old[] = "P2 1 1 255 42\n";
    char got[64];
    tn_image img = {0, 0, 0, NULL};
    tn_save_opts o;
    int n;
    write_file(path, old, sizeof old - 1);
    TN_CHECK(tn_image_create(&img, 3, 3, 1) == TN_OK);
    img.data[4] = NAN;
    TN_CHECK(tn_image_save(path, &img, NULL) == TN_ERR_NUMERIC);
    TN_CHECK(strstr(tn_last_error(), path) != NULL);
    n = file_bytes(path, got, sizeof got);
    TN_CHECK(n == (int)sizeof old - 1 && memcmp(got, old, sizeof old - 1) == 0);
    img.data[4] = INFINITY;
    TN_CHECK(tn_image_save(path, &img, NULL) == TN_ERR_NUMERIC);
    img.data[4] = 0.5f;
    memset(&o, 0, sizeof o);
    o.bit_depth = 12;
    TN_CHECK(tn_image_save(path, &img, &o) == TN_ERR_INVALID_ARG);
    o.bit_depth = 0;
    o.has_range = 1; /* empty range */
    TN_CHECK(tn_image_save(path, &img, &o) == TN_ERR_INVALID_ARG);
    o.has_range = 0;
    o.format = TN_FORMAT_HGT; /* wrong shape for .hgt */
    TN_CHECK(tn_image_save(path, &img, &o) == TN_ERR_SHAPE);
    n = file_bytes(path, got, sizeof got);
    TN_CHECK(n == (int)sizeof old - 1 && memcmp(got, old, sizeof old - 1) == 0);
    TN_CHECK(tn_image_save(tmp_path("x.unknown"), &img, NULL) == TN_ERR_FORMAT);
    TN_CHECK(tn_image_save("/nonexistent/dir/x.pgm", &img, NULL) == TN_ERR_IO);
    /* a successful save replaces it */
    TN_CHECK(tn_image_save(path, &img, NULL) == TN_OK);
    n = file_bytes(path, got, sizeof got);
    TN_CHECK(n > 2 && memcmp(got, "P5", 2) == 0);
    remove(path);
    tn_image_free(&img);
}

TN_TEST(save_rejects_bad_channels)
{
    tn_image img = {0, 0, 0, NULL};
    uint8_t *buf = NULL;
    size_t n = 0;
    TN_CHECK(tn_image_create(&img, 4, 4, 2) == TN_OK);
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_PNM, NULL) == TN_ERR_SHAPE);
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_PFM, NULL) == TN_ERR_SHAPE);
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_ASC, NULL) == TN_ERR_SHAPE);
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_R16, NULL) == TN_ERR_SHAPE);
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_AUTO, NULL) == TN_ERR_INVALID_ARG);
    TN_CHECK(buf == NULL && n == 0);
    tn_image_free(&img);
}

int main(void)
{
    TN_RUN(format_names);
    TN_RUN(pnm_roundtrip_8_16_bit_1_3_channels);
    TN_RUN(pnm_header_text_and_files);
    TN_RUN(pnm_ascii_with_comments_everywhere);
    TN_RUN(pnm_16bit_is_big_endian);
    TN_RUN(pfm_roundtrip_and_orientation);
    TN_RUN(hgt_roundtrip_voids_and_errors);
    TN_RUN(hgt_huge_voids_fill_smoothly);
    TN_RUN(hgt_real_srtm_tile);
    TN_RUN(png_real_16bit_matches_hgt);
    TN_RUN(png_roundtrip_8_16_bit_1_3_channels);
    TN_RUN(asc_roundtrip_and_header);
    TN_RUN(r16_roundtrip_and_size_inference);
    TN_RUN(format_detection);
    TN_RUN(truncated_inputs_fail);
    TN_RUN(absurd_sizes_fail_without_allocating);
    TN_RUN(garbage_never_crashes);
    TN_RUN(save_never_clobbers_on_failure);
    TN_RUN(save_rejects_bad_channels);
    return tn_test_summary("test_io");
}
