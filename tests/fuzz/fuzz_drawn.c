/* fuzz_drawn.c - fuzz driver for drawn sketches (@@sketch tn_sketch_from_image), at the library's
   default limits: the input is an image file in any format the loaders read (PNG, PPM, ...); an
   RGB(A) image up to 512 x 512 is traced into polylines, which must format as .tns and parse back
   to the same points, and cut into parts.
     libFuzzer:  clang -g -O1 -fsanitize=fuzzer,address,undefined -I. fuzz_drawn.c -lm -pthread
     no libFuzzer: cc -DTN_FUZZ_MAIN -fsanitize=address,undefined -I. fuzz_drawn.c -lm -pthread
                   ./a.out [files...]   (runs each file as one input; no files: the committed corpus)
   Seeds: tests/fuzz/corpus/fuzz_drawn (small drawings: red ridges, blue valleys). */
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
    tn_image img = {0, 0, 0, NULL};
    tn_contour_set s = {0, 0, 0, NULL}, t = {0, 0, 0, NULL}, p = {0, 0, 0, NULL};
    char *text = NULL;
    size_t n = 0;
    int i;
    tn_set_threads(1); /* one thread: a fuzzing run keeps to one core (the pool's idle workers spin) */
    if (tn_image_load_memory(&img, data, size, "fuzz.png", NULL, NULL) != TN_OK) return 0;
    if (img.width <= 512 && img.height <= 512 && tn_sketch_from_image(&s, &img) == TN_OK) {
        if (s.width != img.width || s.height != img.height || s.count < 1) abort();
        if (tn_sketch_format(&text, &n, &s) != TN_OK || tn_sketch_parse(&t, text, n, "again") != TN_OK || t.count != s.count) abort();
        for (i = 0; i < s.count; i++)
            if (t.items[i].npoints != s.items[i].npoints ||
                memcmp(t.items[i].points, s.items[i].points, (size_t)s.items[i].npoints * 3 * sizeof(float)))
                abort();
        (void)tn_contour_parts_make(&p, &s, 1);
    }
    tn_free(text);
    tn_contour_set_free(&s);
    tn_contour_set_free(&t);
    tn_contour_set_free(&p);
    tn_image_free(&img);
    return 0;
}

#define TN_FUZZ_NAME "fuzz_drawn"
#include "fuzz_replay.h"
