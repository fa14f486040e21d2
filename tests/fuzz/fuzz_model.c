/* fuzz_model.c - fuzz driver for the .tnw model loaders of every method (@@gnn tn_gnn_load,
   @@singan tn_singan_load, @@texgan tn_texgan_load, @@season tn_kpd_load), at the library's
   default limits. Each input, its CRC-32 repaired so that mutations reach the parsers, is written
   to a scratch file and loaded by all four (a file names its method, so three refuse it from its
   metadata, before its CRC-32 and tensors are read). A model that loads must be usable (gnn: its parts; singan and texgan: a 16 x 16 sample;
   a failure there must say why).
     libFuzzer:  clang -g -O1 -fsanitize=fuzzer,address,undefined -I. fuzz_model.c -lm -pthread
     no libFuzzer: cc -DTN_FUZZ_MAIN -fsanitize=address,undefined -I. fuzz_model.c -lm -pthread
                   ./a.out [files...]   (runs each file as one input; no files: the committed corpus)
   Seeds: tests/fuzz/corpus/fuzz_model (tiny models of each method, tests/fuzz/make_model_seeds.c). */
#define TN_INTERNALS /* private tn__ code: the header's internals block */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include "fuzz_files.h"

#ifdef __cplusplus
extern "C"
#endif
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const char *in = fuzz_path("in.tnw");
    tn_image out = {0, 0, 0, NULL};
    uint8_t *b = (uint8_t *)malloc(size + 1);
    tn_status st;
    int ok;
    tn_set_threads(1); /* one thread: a fuzzing run keeps to one core (the pool's idle workers spin) */
    if (!b) return 0;
    memcpy(b, data, size);
    if (size >= 16) { /* the trailer is the CRC-32 of the rest: repaired, so mutations reach the parsers */
        uint32_t c = tn__crc32(0, b, size - 4);
        b[size - 4] = (uint8_t)c, b[size - 3] = (uint8_t)(c >> 8), b[size - 2] = (uint8_t)(c >> 16), b[size - 1] = (uint8_t)(c >> 24);
    }
    ok = fuzz_write(in, b, size);
    free(b);
    if (!ok) return 0;
    {
        tn_gnn m;
        tn_contour_set parts = {0, 0, 0, NULL};
        if (tn_gnn_load(&m, in) == TN_OK) {
            if (tn_gnn_parts(&parts, &m) != TN_OK || parts.count != m.parts) abort();
            tn_contour_set_free(&parts);
            tn_gnn_free(&m);
        }
    }
    {
        tn_singan m;
        if (tn_singan_load(&m, in) == TN_OK) {
            tn_clear_error();
            if ((st = tn_singan_sample(&out, &m, 0, 0, 16, 16, NULL)) != TN_OK && !tn_last_error()[0]) abort();
            tn_image_free(&out);
            tn_singan_free(&m);
        }
    }
    {
        tn_texgan m;
        if (tn_texgan_load(&m, in) == TN_OK) {
            tn_clear_error();
            if ((st = tn_texgan_synthesize(&out, &m, 1, 16, 16)) != TN_OK && !tn_last_error()[0]) abort();
            tn_image_free(&out);
            tn_texgan_free(&m);
        }
    }
    {
        tn_kpd m;
        if (tn_kpd_load(&m, in) == TN_OK) tn_kpd_free(&m);
    }
    return 0;
}

#define TN_FUZZ_NAME "fuzz_model"
#include "fuzz_replay.h"
