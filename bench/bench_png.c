/* bench_png.c - PNG decode/encode speed on a 16-bit DEM and an 8-bit RGB texture.
   Prints `png_decode_<what>: X MB/s` and `png_encode_<what>: X MB/s` (MB = 1e6 bytes of raw
   decoded pixel data, i.e. width * height * channels * bit_depth / 8) and the encoded size
   relative to the input file. Built with -DTN_BENCH_ZLIB -lz it also compresses the very same
   filtered rows with zlib at level 6 and prints both sizes. */
#define TN_INTERNALS /* private tn__ code: the header's internals block */
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#ifdef TN_BENCH_ZLIB
#include <zlib.h>
#endif

static uint8_t *bench_read(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    long len;
    uint8_t *b;
    *n = 0;
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    len = ftell(f);
    fseek(f, 0, SEEK_SET);
    b = (uint8_t *)malloc(len > 0 ? (size_t)len : 1);
    if (b && len > 0 && fread(b, 1, (size_t)len, f) != (size_t)len) { free(b); b = NULL; }
    fclose(f);
    *n = (size_t)len;
    return b;
}

/* Concatenated IDAT payload of a PNG (our own encoder's output). */
static size_t bench_idat(const uint8_t *png, size_t n, uint8_t *out)
{
    size_t pos = 8, o = 0;
    while (pos + 12 <= n) {
        uint32_t len = tn__png_be32(png + pos);
        if (!memcmp(png + pos + 4, "IDAT", 4)) { memcpy(out + o, png + pos + 8, len); o += len; }
        pos += 12 + (size_t)len;
    }
    return o;
}

static void bench_file(const char *rel, const char *what)
{
    char path[1024];
    const char *root = getenv("TN_SHARED_DATA");
    size_t n = 0, raw, out_n = 0;
    uint8_t *buf, *out = NULL;
    tn_image img = {0, 0, 0, NULL};
    tn_image_info info;
    double t0, t, best;
    int reps, level;
    snprintf(path, sizeof path, "%s/%s", root ? root : "../shared/data", rel);
    buf = bench_read(path, &n);
    if (!buf) { printf("png_bench_%s: skipped (%s not found)\n", what, path); return; }
    if (tn__png_decode(buf, n, path, &img, &info) != TN_OK) { printf("png_bench_%s: %s\n", what, tn_last_error()); free(buf); return; }
    raw = (size_t)img.width * img.height * info.file_channels * (size_t)info.bit_depth / 8;
    /* decode: best single run over >= 1 s (robust against other load on the machine) */
    for (reps = 0, best = 1e30, t0 = tn_time_seconds(); tn_time_seconds() - t0 < 1.0 || reps < 3; reps++) {
        tn_image tmp = {0, 0, 0, NULL};
        t = tn_time_seconds();
        tn__png_decode(buf, n, path, &tmp, NULL);
        t = tn_time_seconds() - t;
        if (t < best) best = t;
        tn_image_free(&tmp);
    }
    printf("png_decode_%s: %.1f MB/s  (%dx%dx%d, %d-bit, best of %d: %.2f ms)\n", what, raw / best / 1e6, img.width,
           img.height, info.file_channels, info.bit_depth, reps, best * 1e3);
    /* encode at levels 1, 6 (default), 9 */
    for (level = 1; level <= 9; level += level == 1 ? 5 : 3) {
        for (reps = 0, best = 1e30, t0 = tn_time_seconds(); tn_time_seconds() - t0 < 1.0 || reps < 2; reps++) {
            tn_free(out);
            t = tn_time_seconds();
            tn__png_encode(&img, info.bit_depth, 0.0, 1.0, 0, level, &out, &out_n);
            t = tn_time_seconds() - t;
            if (t < best) best = t;
        }
        printf("png_encode_%s%s: %.1f MB/s  (level %d, best of %d: %.2f ms, %zu bytes = %.3f x the input file)\n", what,
               level == 6 ? "" : level == 1 ? "_level1" : "_level9", raw / best / 1e6, level, reps, best * 1e3, out_n,
               (double)out_n / (double)n);
#ifdef TN_BENCH_ZLIB
        if (level == 6) { /* same filtered rows through zlib level 6 */
            uint8_t *z = (uint8_t *)malloc(out_n), *rows = NULL, *mine = NULL;
            size_t zn = bench_idat(out, out_n, z), rn = 0, mn = 0;
            uLongf zl;
            uint8_t *zb;
            double tz;
            tn_zlib_inflate(&rows, &rn, z, zn, 0);
            zl = compressBound(rn);
            zb = (uint8_t *)malloc(zl);
            tz = tn_time_seconds();
            compress2(zb, &zl, rows, rn, 6);
            tz = tn_time_seconds() - tz;
            tn_zlib_deflate(&mine, &mn, rows, rn, 6);
            printf("png_zlib_compare_%s: same filtered rows, ours level 6 %zu bytes, zlib level 6 %lu bytes (ours/zlib = %.3f; zlib %.1f MB/s)\n",
                   what, mn, (unsigned long)zl, (double)mn / (double)zl, rn / tz / 1e6);
            free(zb);
            free(z);
            tn_free(rows);
            tn_free(mine);
        }
#else
        (void)bench_idat;
#endif
    }
    tn_free(out);
    tn_image_free(&img);
    free(buf);
}

int main(void)
{
    bench_file("dem/alps_n47e009/alps_n47e009_full.png", "dem16");
    bench_file("textures/grass_threejs_grasslight.png", "rgb8");
    return 0;
}
