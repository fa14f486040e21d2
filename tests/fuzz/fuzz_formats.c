/* fuzz_formats.c - fuzz target for the @@io loaders (and, on success, the writers).
   Byte 0 picks the format: byte0 % 7 -> 0 = AUTO (magic/extension detection), 1..6 = PNG, PNM,
   PFM, HGT, ASC, R16 forced; bit 0 of byte0 / 7 passes bytes 1 and 2 as the .r16 width/height.
   The rest of the input is the file. A successful load is re-encoded in a format picked by
   byte0 / 14 and decoded again.
     libFuzzer:  clang -g -O1 -fsanitize=fuzzer,address,undefined -I. fuzz_formats.c -lm -pthread
     no libFuzzer: cc -DTN_FUZZ_MAIN -fsanitize=address,undefined -I. fuzz_formats.c -lm -pthread
                   ./a.out files...   (runs each file as one input) */
#ifdef TN_TEST_TU /* scratch build: the library plus the sections not yet in terrainnet.h */
#include TN_TEST_TU
#else
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#endif
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef __cplusplus
extern "C"
#endif
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    tn_load_opts o;
    tn_image img = {0, 0, 0, NULL}, back = {0, 0, 0, NULL};
    tn_image_info info;
    uint8_t *enc = NULL;
    size_t n = 0;
    tn_set_threads(1); /* one thread: a fuzzing run keeps to one core (the pool's idle workers spin) */
    if (size < 1) return 0;
    memset(&o, 0, sizeof o);
    o.format = (tn_format)(data[0] % 7);
    if (((data[0] / 7) & 1) && size >= 3) {
        o.raw_width = data[1];
        o.raw_height = data[2];
    }
    if (tn_image_load_memory(&img, data + 1, size - 1, NULL, &o, &info) != TN_OK) return 0;
    if ((size_t)img.width * img.height * img.channels <= ((size_t)1 << 20) &&
        tn_image_save_memory(&enc, &n, &img, (tn_format)(1 + (data[0] / 14) % 6), NULL) == TN_OK) {
        memset(&o, 0, sizeof o);
        o.format = (tn_format)(1 + (data[0] / 14) % 6);
        if (o.format == TN_FORMAT_R16) { o.raw_width = img.width; o.raw_height = img.height; }
        if (tn_image_load_memory(&back, enc, n, NULL, &o, NULL) == TN_OK) tn_image_free(&back);
        tn_free(enc);
    }
    tn_image_free(&img);
    return 0;
}

#define TN_FUZZ_NAME "fuzz_formats"
#include "fuzz_replay.h"
