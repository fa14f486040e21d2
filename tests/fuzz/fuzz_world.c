/* fuzz_world.c - fuzz driver for world SPEC files (@@world tn_world_parse), at the library's
   default limits. The input is the SPEC text; model paths in it start at the working directory
   (the seeds name the committed models of tests/fuzz/corpus/fuzz_model, so run from the
   repository root). A SPEC that parses must give a tile grid that covers its raster. (Computing
   pixels is left out: a few hundred runs a second instead of thousands.)
     libFuzzer:  clang -g -O1 -fsanitize=fuzzer,address,undefined -I. fuzz_world.c -lm -pthread
     no libFuzzer: cc -DTN_FUZZ_MAIN -fsanitize=address,undefined -I. fuzz_world.c -lm -pthread
                   ./a.out [files...]   (runs each file as one input; no files: the committed corpus)
   Seeds: tests/fuzz/corpus/fuzz_world. */
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
    char *text = (char *)malloc(size + 1);
    tn_world w;
    tn_set_threads(1); /* one thread: a fuzzing run keeps to one core (the pool's idle workers spin) */
    if (!text) return 0;
    memcpy(text, data, size);
    text[size] = 0;
    memset(&w, 0, sizeof w);
    if (tn_world_parse(&w, text, NULL) == TN_OK) {
        tn_rect r = tn_world_tile_rect(&w, w.rows - 1, w.cols - 1);
        if (w.rows < 1 || w.cols < 1 || r.x + r.w != w.out_width || r.y + r.h != w.out_height) abort();
        tn_world_free(&w);
    }
    free(text);
    return 0;
}

#define TN_FUZZ_NAME "fuzz_world"
#include "fuzz_replay.h"
