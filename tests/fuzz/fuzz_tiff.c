/* fuzz_tiff.c - fuzz driver for the TIFF / GeoTIFF reader and writer (@@io).
   Every input is loaded as a TIFF (format forced, so detection does not stand in the way); a
   successful load is written back as a GeoTIFF carrying the georeference it was read with (the
   writer re-checks the GeoKey directory), which must load again with the same pixels and
   transform. The same bytes also go through the bare LZW and PackBits decoders, whose output
   is capped at 64 KiB.
     libFuzzer:  clang -g -O1 -fsanitize=fuzzer,address,undefined -I. fuzz_tiff.c -lm -pthread
     no libFuzzer: cc -DTN_FUZZ_MAIN -fsanitize=address,undefined -I. fuzz_tiff.c -lm -pthread
                   ./a.out files...   (runs each file as one input)
   Seeds: tests/fuzz/seeds/tiff_* (small GDAL-made files of tests/refs/tiff). */
#define TN_INTERNALS /* private tn__ code: the header's internals block */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef __cplusplus
extern "C"
#endif
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static uint8_t out[65536];
    static size_t tab[4096];
    static uint16_t lens[4096];
    tn_load_opts o;
    tn_image img = {0, 0, 0, NULL}, back = {0, 0, 0, NULL};
    tn_image_info info, info2;
    size_t len = 0;
    tn_set_threads(1); /* one thread: a fuzzing run keeps to one core (the pool's idle workers spin) */
    (void)tn__tif_lzw("fuzz", data, size, out, sizeof out, &len, tab, lens);
    if (len > sizeof out) abort();
    (void)tn__tif_packbits("fuzz", data, size, out, sizeof out, &len);
    if (len > sizeof out) abort();
    memset(&o, 0, sizeof o);
    o.format = TN_FORMAT_TIFF;
    if (tn_image_load_memory(&img, data, size, "fuzz.tif", &o, &info) != TN_OK) return 0;
    if ((size_t)img.width * img.height * img.channels <= ((size_t)1 << 20)) {
        tn_save_opts so;
        uint8_t *enc = NULL;
        size_t n = 0;
        memset(&so, 0, sizeof so);
        so.georef = &info.georef;
        so.compression = 1; /* the fastest deflate: the round trip is about the TIFF layer (fuzz_png runs every level) */
        if (tn_image_save_memory(&enc, &n, &img, TN_FORMAT_TIFF, &so) == TN_OK) {
            if (tn_image_load_memory(&back, enc, n, "fuzz2.tif", &o, &info2) != TN_OK) abort(); /* our own file must load */
            if (back.width != img.width || back.height != img.height || back.channels != img.channels ||
                memcmp(back.data, img.data, (size_t)img.width * img.height * img.channels * sizeof(float)) != 0)
                abort();
            /* a georeference without a transform is not written (the doc of tn_save_opts.georef) */
            if (info2.georef.has_transform != info.georef.has_transform ||
                (info.georef.has_transform && info2.georef.nkeys != info.georef.nkeys))
                abort();
            tn_image_free(&back);
            tn_free(enc);
        }
    }
    tn_image_free(&img);
    return 0;
}

#define TN_FUZZ_NAME "fuzz_tiff"
#include "fuzz_replay.h"
