/* fuzz_sketch.c - fuzz target for the .tns sketch reader (@@sketch). Parses the input; on success
   the set must format and parse back to identical bits, and densify, cutting into parts and
   aligning the parts with themselves must not fail on anything but size/emptiness.
     libFuzzer:  clang -g -O1 -fsanitize=fuzzer,address,undefined -I. fuzz_sketch.c -lm -pthread
     no libFuzzer: cc -DTN_FUZZ_MAIN -fsanitize=address,undefined -I. fuzz_sketch.c -lm -pthread
                   ./a.out files...   (runs each file as one input) */
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
    tn_contour_set s = {0, 0, 0, NULL}, t = {0, 0, 0, NULL}, d = {0, 0, 0, NULL}, p = {0, 0, 0, NULL};
    char *text = NULL;
    size_t n = 0;
    int i, *match;
    tn_set_threads(1); /* one thread: a fuzzing run keeps to one core (the pool's idle workers spin) */
    if (tn_sketch_parse(&s, (const char *)data, size, "fuzz") != TN_OK) return 0;
    if (tn_sketch_format(&text, &n, &s) != TN_OK || tn_sketch_parse(&t, text, n, "again") != TN_OK || t.count != s.count) abort();
    for (i = 0; i < s.count; i++)
        if (t.items[i].npoints != s.items[i].npoints ||
            memcmp(t.items[i].points, s.items[i].points, (size_t)s.items[i].npoints * 3 * sizeof(float)))
            abort();
    /* the pixel-chain stages only on small canvases (a chain can be as long as the canvas) */
    if (s.width <= 512 && s.height <= 512 && tn_sketch_densify(&d, &s) == TN_OK && tn_contour_parts_make(&p, &d, 1) == TN_OK &&
        p.count > 0 && p.count <= 4096 && (match = (int *)malloc((size_t)p.count * sizeof(int)))) {
        /* parts can draw more than their set (each starts a polyline; the graph walk may repeat
           junctions), so near the strokes' limit they may pass it */
        tn_status st = tn_sketch_align(match, &p, &p, NULL);
        if (st != TN_OK && st != TN_ERR_TOO_LARGE) abort();
        for (i = 0; !st && i < p.count; i++)
            if (match[i] < 0 || match[i] >= p.count) abort();
        free(match);
    }
    tn_free(text);
    tn_contour_set_free(&s);
    tn_contour_set_free(&t);
    tn_contour_set_free(&d);
    tn_contour_set_free(&p);
    return 0;
}

#define TN_FUZZ_NAME "fuzz_sketch"
#include "fuzz_replay.h"
