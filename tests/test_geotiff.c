/* test_geotiff.c - TIFF / GeoTIFF in @@io: every GDAL-made fixture of tests/refs/tiff (each
   compression, predictor, strips/tiles, sample type, byte order, BigTIFF, planar layout; made
   by tests/refs/make_tiff_refs.py) read sample-exact against the pattern it holds, with its
   geotransform, CRS kind and spacing in metres; nodata and NaN voids filled; writer round trips
   (float32 exact, int16 rounded, uint8 RGB pictures, the georeference carried over verbatim,
   PixelIsPoint and rotated transforms, BigTIFF) and its refusals; overviews skipped; the real
   SRTM tile as GDAL wrote it equals terrainnet's own .hgt reading. */
#define TN_INTERNALS /* private tn__ code: the header's internals block */
#include "terrainnet.h"
#include "tn_test.h"
#include <float.h>

/* The fixtures' pattern (tests/refs/make_tiff_refs.py, pattern()) as terrainnet loads it. */
static float pattern_value(const char *type, int x, int y, int c)
{
    long long v = ((long long)x * x * 3 + (long long)y * 17 + (long long)c * 101 + (long long)x * y) % 100003;
    if (!strcmp(type, "uint8")) return (float)(v % 256) * (1.0f / 255.0f); /* 8-bit: [0, 1] */
    if (!strcmp(type, "int8")) return (float)(v % 256 - 128);
    if (!strcmp(type, "uint16")) return (float)((v * 37) % 65536);
    if (!strcmp(type, "int16")) return (float)((v * 37) % 65536 - 32768);
    if (!strcmp(type, "uint32")) return (float)(double)((v * 2654435761LL) % 4294967296LL);
    if (!strcmp(type, "int32")) return (float)(double)((v * 2654435761LL) % 4294967296LL - 2147483648LL);
    if (!strcmp(type, "float32")) return (float)(v % 1000) * 0.25f - 100.5f;
    return (float)((double)(v % 1000) * 0.125 - 50.0625);
}

typedef struct fixture {
    char name[96], type[16], nodata[32];
    int bands, model;
    double gt[6], dx, dy;
} fixture;

static int read_fixtures(fixture *f, int max)
{
    size_t n = 0;
    char *text = (char *)tn_test_read_file(tn_test_ref("tiff/fixtures.txt"), &n), *line, *end;
    int k = 0;
    if (!text) return 0;
    for (line = text; *line && k < max; line = end + (*end != 0)) {
        fixture *x = &f[k];
        end = strchr(line, '\n');
        if (!end) end = line + strlen(line);
        *end = 0;
        if (line[0] == '#') { *end = '\n'; continue; }
        if (sscanf(line, "%95s %15s %d %31s %lf %lf %lf %lf %lf %lf %d %lf %lf", x->name, x->type, &x->bands, x->nodata, &x->gt[0],
                   &x->gt[1], &x->gt[2], &x->gt[3], &x->gt[4], &x->gt[5], &x->model, &x->dx, &x->dy) == 13)
            k++;
        if (end < text + n) *end = '\n';
    }
    free(text);
    return k;
}

static const char *ref_tiff(const char *name)
{
    static char buf[256];
    snprintf(buf, sizeof buf, "tiff/%s", name);
    return tn_test_ref(buf);
}

/* Every fixture: exact samples (outside nodata holes), geotransform, CRS kind, spacing. */
TN_TEST(test_gdal_fixtures)
{
    fixture fx[64];
    int nf = read_fixtures(fx, 64), i, seen_big = 0, seen_be = 0;
    TN_CHECK(nf >= 35);
    for (i = 0; i < nf; i++) {
        const fixture *f = &fx[i];
        tn_image img = {0, 0, 0, NULL};
        tn_image_info info;
        size_t bad = 0, holes = 0;
        int x, y, c, k, has_nodata = strcmp(f->nodata, "-") != 0;
        tn_status st = tn_image_load(&img, ref_tiff(f->name), &info);
        if (st) {
            fprintf(stderr, "  %s: %s\n", f->name, tn_last_error());
            TN_CHECK(0);
            continue;
        }
        TN_CHECK(info.format == TN_FORMAT_TIFF && img.width == 37 && img.height == 23 && img.channels == f->bands);
        TN_CHECK(info.file_channels == f->bands);
        for (y = 0; y < img.height; y++)
            for (x = 0; x < img.width; x++)
                for (c = 0; c < img.channels; c++) {
                    /* the nodata fixtures' holes: rows 5-7 x cols 10-13 and the 2x2 corner; rows 10-12 x cols 20-22 */
                    int hole = has_nodata && ((strstr(f->name, "int16") && ((x >= 10 && x < 14 && y >= 5 && y < 8) || (x < 2 && y < 2))) ||
                                              (strstr(f->name, "float32") && x >= 20 && x < 23 && y >= 10 && y < 13));
                    if (hole) { holes++; continue; }
                    bad += TN_PIXEL(&img, x, y, c) != pattern_value(f->type, x, y, c);
                }
        if (bad) fprintf(stderr, "  %s: %zu samples differ\n", f->name, bad);
        TN_CHECK(bad == 0);
        TN_CHECK(info.voids_filled == holes);
        TN_CHECK(info.has_nodata == has_nodata);
        TN_CHECK(info.georef.has_transform == (f->model != 0));
        TN_CHECK(info.georef.model_type == f->model);
        for (k = 0; k < 6; k++) TN_CHECK(info.georef.transform[k] == f->gt[k]);
        TN_CHECK_NEAR(info.georef.dx, f->dx, 1e-9 * (1 + f->dx));
        TN_CHECK_NEAR(info.georef.dy, f->dy, 1e-9 * (1 + f->dy));
        if (f->model) TN_CHECK(info.georef.nkeys >= 8 && info.georef.keys[0] == 1);
        seen_big += strstr(f->name, "bigtiff") != NULL;
        seen_be += strstr(f->name, "_be") != NULL;
        tn_image_free(&img);
    }
    TN_CHECK(seen_big >= 3 && seen_be >= 6);
}

/* Filled voids lie within the range of the known cells around them. */
TN_TEST(test_nodata_filled_smoothly)
{
    tn_image img = {0, 0, 0, NULL};
    tn_image_info info;
    int x, y;
    TN_CHECK(tn_image_load(&img, ref_tiff("int16_nodata_deflate.tif"), &info) == TN_OK);
    if (!img.data) return;
    TN_CHECK(info.voids_filled == 16 && info.has_nodata && info.nodata == -32768.0);
    for (y = 5; y < 8; y++)
        for (x = 10; x < 14; x++) {
            float lo = FLT_MAX, hi = -FLT_MAX;
            int xx, yy;
            for (yy = 4; yy < 9; yy++)
                for (xx = 9; xx < 15; xx++)
                    if (yy == 4 || yy == 8 || xx == 9 || xx == 14) {
                        float v = TN_PIXEL(&img, xx, yy, 0);
                        if (v < lo) lo = v;
                        if (v > hi) hi = v;
                    }
            TN_CHECK(TN_PIXEL(&img, x, y, 0) >= lo && TN_PIXEL(&img, x, y, 0) <= hi);
        }
    tn_image_free(&img);
}

static tn_image ramp(int w, int h, int ch, float scale)
{
    tn_image img = {0, 0, 0, NULL};
    size_t i, n;
    if (tn_image_create(&img, w, h, ch)) return img;
    n = (size_t)w * h * ch;
    for (i = 0; i < n; i++) img.data[i] = scale * (float)sin(0.01 * (double)i) + 0.001f * (float)(i % 7) + (scale < 1.0f ? 0.5f : 100.0f);
    return img;
}

/* Writer -> reader: float32 bit-exact, int16 rounded, uint8 codes; channels 1..4. */
TN_TEST(test_write_round_trips)
{
    static const int bits[3] = {32, 16, 8};
    int b, ch;
    for (b = 0; b < 3; b++)
        for (ch = 1; ch <= 4; ch++) {
            tn_image img = ramp(300, 97, ch, b == 2 ? 0.49f : 2500.0f), back = {0, 0, 0, NULL};
            tn_image_info info;
            tn_save_opts so;
            uint8_t *buf = NULL;
            size_t n = 0, i, count = (size_t)300 * 97 * ch, bad = 0;
            memset(&so, 0, sizeof so);
            so.bit_depth = bits[b];
            TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_TIFF, &so) == TN_OK);
            TN_CHECK(buf && n > 8 && !memcmp(buf, "II*\0", 4));
            TN_CHECK(tn_image_load_memory(&back, buf, n, "rt.tif", NULL, &info) == TN_OK);
            TN_CHECK(back.width == 300 && back.height == 97 && back.channels == ch && info.bit_depth == bits[b]);
            for (i = 0; back.data && i < count; i++) {
                float want = b == 0 ? img.data[i] : b == 1 ? (float)floor(img.data[i] + 0.5) : (float)floor(img.data[i] * 255.0 + 0.5) / 255.0f;
                bad += fabsf(back.data[i] - want) > (b == 2 ? 1e-6f : 0.0f);
            }
            if (bad) fprintf(stderr, "  %d-bit, %d channels: %zu samples differ\n", bits[b], ch, bad);
            TN_CHECK(bad == 0);
            TN_CHECK(!info.georef.has_transform);
            tn_image_free(&back);
            tn_free(buf);
            tn_image_free(&img);
        }
    { /* an 8-bit picture of data beyond [0, 1] is stretched from its own min..max */
        tn_image img = ramp(50, 20, 1, 300.0f), back = {0, 0, 0, NULL};
        tn_save_opts so;
        uint8_t *buf = NULL;
        size_t n = 0;
        float lo = 0, hi = 0;
        memset(&so, 0, sizeof so);
        so.bit_depth = 8;
        TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_TIFF, &so) == TN_OK);
        TN_CHECK(tn_image_load_memory(&back, buf, n, "p.tif", NULL, NULL) == TN_OK);
        tn_image_range(&lo, &hi, &back);
        TN_CHECK(lo == 0.0f && hi == 1.0f);
        tn_image_free(&back);
        tn_image_free(&img);
        tn_free(buf);
    }
}

/* Saving a fixture's image with its info.georef writes the same transform and GeoKeys. */
TN_TEST(test_georef_carried_over)
{
    static const char *const names[] = {"int16_geographic_point.tif", "float32_rotated.tif", "int16_deflate_p2_tiled.tif"};
    size_t i;
    for (i = 0; i < sizeof names / sizeof names[0]; i++) {
        tn_image img = {0, 0, 0, NULL}, back = {0, 0, 0, NULL};
        tn_image_info a, b;
        tn_save_opts so;
        uint8_t *buf = NULL;
        size_t n = 0;
        int k;
        TN_CHECK(tn_image_load(&img, ref_tiff(names[i]), &a) == TN_OK);
        memset(&so, 0, sizeof so);
        so.georef = &a.georef;
        so.bit_depth = i == 0 ? 16 : 32;
        TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_TIFF, &so) == TN_OK);
        TN_CHECK(tn_image_load_memory(&back, buf, n, "geo.tif", NULL, &b) == TN_OK);
        TN_CHECK(b.georef.has_transform && b.georef.model_type == a.georef.model_type);
        TN_CHECK(b.georef.pixel_is_point == a.georef.pixel_is_point);
        for (k = 0; k < 6; k++) TN_CHECK_NEAR(b.georef.transform[k], a.georef.transform[k], 1e-12 * (1 + fabs(a.georef.transform[k])));
        TN_CHECK(b.georef.nkeys == a.georef.nkeys && !memcmp(b.georef.keys, a.georef.keys, (size_t)a.georef.nkeys * 2));
        TN_CHECK(b.georef.ndoubles == a.georef.ndoubles && b.georef.nascii == a.georef.nascii && !strcmp(b.georef.ascii, a.georef.ascii));
        TN_CHECK(b.georef.dx == a.georef.dx && b.georef.dy == a.georef.dy);
        TN_CHECK(back.data && !memcmp(back.data, img.data, (size_t)img.width * img.height * sizeof(float)));
        tn_image_free(&back);
        tn_image_free(&img);
        tn_free(buf);
    }
    TN_CHECK(1);
}

/* Files that would pass 4 GiB become BigTIFF (threshold lowered here to test it). */
TN_TEST(test_bigtiff_written)
{
    tn_image img = ramp(64, 40, 1, 50.0f), back = {0, 0, 0, NULL};
    uint8_t *buf = NULL;
    size_t n = 0;
    tn__tif_classic_max = 1000;
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_TIFF, NULL) == TN_OK);
    tn__tif_classic_max = TN__TIF_CLASSIC_MAX;
    TN_CHECK(buf && buf[2] == 43);
    TN_CHECK(tn_image_load_memory(&back, buf, n, "big.tif", NULL, NULL) == TN_OK);
    TN_CHECK(back.data && !memcmp(back.data, img.data, 64 * 40 * sizeof(float)));
    tn_image_free(&back);
    tn_image_free(&img);
    tn_free(buf);
}

/* Writer refusals: int16 beyond range, bad bit depth or level, malformed georeference. */
TN_TEST(test_write_refusals)
{
    tn_image img = ramp(16, 8, 1, 10.0f);
    tn_save_opts so;
    tn_georef g;
    uint8_t *buf = NULL;
    size_t n = 0;
    memset(&so, 0, sizeof so);
    so.bit_depth = 16;
    img.data[3] = 40000.0f;
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_TIFF, &so) == TN_ERR_INVALID_ARG && !buf);
    img.data[3] = 1.0f;
    so.bit_depth = 12;
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_TIFF, &so) == TN_ERR_INVALID_ARG && !buf);
    so.bit_depth = 0;
    so.compression = 11;
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_TIFF, &so) == TN_ERR_INVALID_ARG && !buf);
    so.compression = 0;
    memset(&g, 0, sizeof g);
    g.has_transform = 1;
    g.transform[1] = 1.0; /* singular: no Y step */
    so.georef = &g;
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_TIFF, &so) == TN_ERR_INVALID_ARG && !buf);
    g.transform[5] = -1.0;
    g.transform[0] = NAN;
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_TIFF, &so) == TN_ERR_INVALID_ARG && !buf);
    g.transform[0] = 0.0;
    g.nkeys = 8; /* a key pointing past the (empty) double parameters */
    g.keys[0] = 1; g.keys[1] = 1; g.keys[3] = 1;
    g.keys[4] = 3077; g.keys[5] = 34736; g.keys[6] = 1; g.keys[7] = 0;
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_TIFF, &so) == TN_ERR_INVALID_ARG && !buf);
    g.nkeys = 0;
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_TIFF, &so) == TN_OK && buf);
    tn_free(buf);
    /* NaN in the image is refused like every other format */
    img.data[0] = NAN;
    buf = NULL;
    TN_CHECK(tn_image_save_memory(&buf, &n, &img, TN_FORMAT_TIFF, NULL) == TN_ERR_NUMERIC && !buf);
    tn_image_free(&img);
}

/* Patches the first IFD entry with tag `tag` of a little-endian classic TIFF: its first inline
   value (SHORT or LONG). Returns 0 when the tag is not there. */
static int patch_tag(uint8_t *b, size_t n, unsigned tag, uint32_t v)
{
    uint32_t ifd = (uint32_t)b[4] | ((uint32_t)b[5] << 8) | ((uint32_t)b[6] << 16) | ((uint32_t)b[7] << 24);
    unsigned cnt, i;
    if ((size_t)ifd + 2 > n) return 0;
    cnt = b[ifd] | (b[ifd + 1] << 8);
    for (i = 0; i < cnt && (size_t)ifd + 2 + 12 * (i + 1) <= n; i++) {
        uint8_t *e = b + ifd + 2 + 12 * i;
        if ((unsigned)(e[0] | (e[1] << 8)) != tag) continue;
        if ((e[2] | (e[3] << 8)) == 3) { e[8] = (uint8_t)v; e[9] = (uint8_t)(v >> 8); }
        else { e[8] = (uint8_t)v; e[9] = (uint8_t)(v >> 8); e[10] = (uint8_t)(v >> 16); e[11] = (uint8_t)(v >> 24); }
        return 1;
    }
    return 0;
}

/* An overview IFD before the main image is skipped: two files glued, the first marked reduced. */
TN_TEST(test_overview_skipped)
{
    tn_image small = ramp(8, 5, 1, 3.0f), big = ramp(40, 30, 1, 7.0f), back = {0, 0, 0, NULL};
    uint8_t *a = NULL, *b = NULL, *glued;
    size_t na = 0, nb = 0;
    uint32_t ifd_b;
    unsigned i, cnt;
    TN_CHECK(tn_image_save_memory(&a, &na, &small, TN_FORMAT_TIFF, NULL) == TN_OK);
    TN_CHECK(tn_image_save_memory(&b, &nb, &big, TN_FORMAT_TIFF, NULL) == TN_OK);
    if (!a || !b) return;
    /* the overview gets NewSubfileType = 1 in place of its PlanarConfiguration entry (284 -> 254) */
    cnt = a[8] | (a[9] << 8);
    for (i = 0; i < cnt; i++) {
        uint8_t *e = a + 8 + 2 + 12 * i;
        if ((e[0] | (e[1] << 8)) == 284) { e[0] = 254; e[1] = 0; e[8] = 1; }
    }
    /* b's offsets all move by na: rebuild it with each offset shifted is complex, so glue a
       in front of b and point a's next-IFD at a copy of b's IFD region... simpler: append a's
       IFD chain link to b placed after a, with b's strip offsets patched */
    glued = (uint8_t *)malloc(na + nb);
    memcpy(glued, a, na);
    memcpy(glued + na, b, nb);
    ifd_b = (uint32_t)(b[4] | (b[5] << 8) | (b[6] << 16) | ((uint32_t)b[7] << 24));
    {
        uint32_t next_at = 8 + 2 + 12 * cnt, target = (uint32_t)na + ifd_b;
        unsigned cb = b[ifd_b] | (b[ifd_b + 1] << 8), k;
        glued[next_at] = (uint8_t)target; glued[next_at + 1] = (uint8_t)(target >> 8);
        glued[next_at + 2] = (uint8_t)(target >> 16); glued[next_at + 3] = (uint8_t)(target >> 24);
        for (k = 0; k < cb; k++) { /* shift every out-of-line offset and the strip offsets of b by na */
            uint8_t *e = glued + na + ifd_b + 2 + 12 * k;
            unsigned tag = e[0] | (e[1] << 8), type = e[2] | (e[3] << 8);
            uint32_t count = (uint32_t)(e[4] | (e[5] << 8) | (e[6] << 16) | ((uint32_t)e[7] << 24));
            uint32_t sz = count * (type == 3 ? 2u : type == 12 ? 8u : type == 2 ? 1u : 4u), v;
            v = (uint32_t)(e[8] | (e[9] << 8) | (e[10] << 16) | ((uint32_t)e[11] << 24));
            if (sz > 4) {
                uint32_t j;
                if (tag == 273) /* StripOffsets values */
                    for (j = 0; j < count; j++) {
                        uint8_t *q = glued + na + v + 4 * j;
                        uint32_t o = (uint32_t)(q[0] | (q[1] << 8) | (q[2] << 16) | ((uint32_t)q[3] << 24)) + (uint32_t)na;
                        q[0] = (uint8_t)o; q[1] = (uint8_t)(o >> 8); q[2] = (uint8_t)(o >> 16); q[3] = (uint8_t)(o >> 24);
                    }
                v += (uint32_t)na;
            } else if (tag == 273) {
                v += (uint32_t)na;
            } else {
                continue;
            }
            e[8] = (uint8_t)v; e[9] = (uint8_t)(v >> 8); e[10] = (uint8_t)(v >> 16); e[11] = (uint8_t)(v >> 24);
        }
    }
    TN_CHECK(tn_image_load_memory(&back, glued, na + nb, "ovr.tif", NULL, NULL) == TN_OK);
    TN_CHECK(back.width == 40 && back.height == 30 && back.data && !memcmp(back.data, big.data, 40 * 30 * sizeof(float)));
    tn_image_free(&back);
    /* the same with the chain pointing back at the overview: a loop, an error */
    {
        uint32_t next_at = 8 + 2 + 12 * cnt;
        glued[next_at] = 8; glued[next_at + 1] = glued[next_at + 2] = glued[next_at + 3] = 0;
        TN_CHECK(tn_image_load_memory(&back, glued, na + nb, "loop.tif", NULL, NULL) == TN_ERR_CORRUPT && !back.data);
        TN_CHECK(strstr(tn_last_error(), "loops") != NULL);
    }
    TN_CHECK(patch_tag(a, na, 254, 1) == 1);
    free(glued);
    tn_free(a);
    tn_free(b);
    tn_image_free(&small);
    tn_image_free(&big);
}

/* The real SRTM tile: GDAL's GeoTIFFs of it read the same as terrainnet's .hgt reader. */
TN_TEST(test_real_srtm)
{
    static const char *const tifs[] = {"geotiff/alps_n47e009_int16_plain.tif", "geotiff/alps_n47e009_int16_lzw_pred2_tiled.tif",
                                       "geotiff/alps_n47e009_int16_packbits_bigendian.tif",
                                       "geotiff/alps_n47e009_float32_deflate_pred3_tiled_nodata.tif",
                                       "geotiff/alps_n47e009_float64_bigtiff_deflate.tif"};
    const char *hgt = tn_test_data("dem/alps_n47e009/original/N47E009.hgt");
    tn_image ref = {0, 0, 0, NULL};
    size_t i;
    if (!hgt) { TN_SKIP("shared data absent"); return; }
    TN_CHECK(tn_image_load(&ref, hgt, NULL) == TN_OK);
    for (i = 0; i < sizeof tifs / sizeof tifs[0]; i++) {
        const char *p = tn_test_data(tifs[i]);
        tn_image img = {0, 0, 0, NULL};
        tn_image_info info;
        if (!p) { TN_SKIP("shared GeoTIFFs absent"); continue; }
        TN_CHECK(tn_image_load(&img, p, &info) == TN_OK);
        TN_CHECK(img.data && ref.data && img.width == ref.width && !memcmp(img.data, ref.data, (size_t)ref.width * ref.height * sizeof(float)));
        TN_CHECK(info.georef.model_type == 2 && info.georef.pixel_is_point);
        TN_CHECK_NEAR(info.georef.transform[0], 9.0 - 0.5 / 1200.0, 1e-12);
        TN_CHECK_NEAR(info.georef.dx, 62.79, 0.05); /* MANIFEST.md: 62.6 x 92.6 m at the crop */
        TN_CHECK_NEAR(info.georef.dy, 92.65, 0.05);
        tn_image_free(&img);
    }
    { /* the file with planted -9999 voids: filled, everything else equal */
        const char *p = tn_test_data("geotiff/alps_n47e009_float32_voids.tif");
        tn_image img = {0, 0, 0, NULL};
        tn_image_info info;
        size_t k, diff = 0;
        if (p && tn_image_load(&img, p, &info) == TN_OK) {
            TN_CHECK(info.voids_filled == 20 * 30 + 25);
            for (k = 0; k < (size_t)ref.width * ref.height; k++) diff += img.data[k] != ref.data[k];
            TN_CHECK(diff > 0 && diff <= 625);
            tn_image_free(&img);
        }
    }
    tn_image_free(&ref);
}

/* Unsupported variants name themselves; a wrong magic falls through to other formats. */
TN_TEST(test_unsupported_variants)
{
    size_t n = 0;
    uint8_t *b = tn_test_read_file(ref_tiff("int16_deflate_strips.tif"), &n);
    tn_image img = {0, 0, 0, NULL};
    if (!b) { TN_CHECK(0); return; }
    TN_CHECK(patch_tag(b, n, 259, 7));
    TN_CHECK(tn_image_load_memory(&img, b, n, "jpeg.tif", NULL, NULL) == TN_ERR_FORMAT && strstr(tn_last_error(), "JPEG"));
    TN_CHECK(patch_tag(b, n, 259, 8) && patch_tag(b, n, 258, 12));
    TN_CHECK(tn_image_load_memory(&img, b, n, "b12.tif", NULL, NULL) == TN_ERR_FORMAT);
    TN_CHECK(patch_tag(b, n, 258, 16) && tn_image_load_memory(&img, b, n, "ok.tif", NULL, NULL) == TN_OK);
    tn_image_free(&img);
    TN_CHECK(strcmp(tn_format_name(TN_FORMAT_TIFF), "tiff") == 0);
    free(b);
}

int main(void)
{
    TN_RUN(test_gdal_fixtures);
    TN_RUN(test_nodata_filled_smoothly);
    TN_RUN(test_write_round_trips);
    TN_RUN(test_georef_carried_over);
    TN_RUN(test_bigtiff_written);
    TN_RUN(test_write_refusals);
    TN_RUN(test_overview_skipped);
    TN_RUN(test_real_srtm);
    TN_RUN(test_unsupported_variants);
    return tn_test_summary("test_geotiff");
}
