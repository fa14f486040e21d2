/* fuzz_png.c - fuzz driver for the PNG decoder (tn__png_decode) and zlib inflate.
   libFuzzer:  clang -g -O1 -fsanitize=fuzzer,address,undefined -I. fuzz_png.c -lm -pthread
   without libFuzzer (-DTN_FUZZ_MAIN): runs every file named on the command line once, so crashes
   found elsewhere can be replayed under any compiler/sanitizer (stb style).
   Half of the inputs (chosen by the last byte) get their chunk CRCs repaired first: random bytes
   almost never pass the CRC check, and the decoder behind it deserves the mutations. Every input
   is also fed to the bare zlib inflater, and deflated (level from the first byte) and inflated
   back, which must reproduce it exactly. */
#define TN_INTERNALS /* private tn__ code: the header's internals block */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static void fuzz_fix_crcs(uint8_t *b, size_t n)
{
    size_t pos = 8;
    while (pos + 12 <= n) {
        uint32_t len = tn__png_be32(b + pos);
        if (len > n - pos - 12) break;
        tn__png_put_be32(b + pos + 8 + len, tn__crc32(0, b + pos + 4, (size_t)len + 4));
        pos += 12 + (size_t)len;
    }
}

#ifdef __cplusplus
extern "C"
#endif
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    tn_image img = {0, 0, 0, NULL};
    tn_image_info info;
    uint8_t *copy, *out = NULL;
    size_t out_n = 0;
    tn_set_threads(1); /* one thread: a fuzzing run keeps to one core (the pool's idle workers spin) */
    if (size == 0) return 0;
    copy = (uint8_t *)malloc(size);
    if (!copy) return 0;
    memcpy(copy, data, size);
    if (data[size - 1] & 1) fuzz_fix_crcs(copy, size);
    if (tn__png_decode(copy, size, "fuzz", &img, &info) == TN_OK) {
        /* touch every sample so a short buffer would be caught */
        size_t i, n = (size_t)img.width * img.height * img.channels;
        volatile float sum = 0;
        for (i = 0; i < n; i++) sum += img.data[i];
        (void)sum;
        tn_image_free(&img);
    }
    if (tn_zlib_inflate(&out, &out_n, data, size, (size_t)1 << 24) == TN_OK) tn_free(out);
    out = NULL;
    if (tn_zlib_deflate(&out, &out_n, data, size, data[0] % 10) == TN_OK) {
        uint8_t *back = NULL;
        size_t back_n = 0;
        if (tn_zlib_inflate(&back, &back_n, out, out_n, 0) != TN_OK || back_n != size || memcmp(back, data, size) != 0) {
            fprintf(stderr, "fuzz_png: deflate round trip failed (%zu bytes, level %d): %s\n", size, data[0] % 10, tn_last_error());
            abort();
        }
        tn_free(back);
        tn_free(out);
    }
    free(copy);
    return 0;
}

#define TN_FUZZ_NAME "fuzz_png"
#include "fuzz_replay.h"
