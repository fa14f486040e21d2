/* fuzz_world.c - fuzz driver for world SPEC files (@@world tn_world_parse), at the library's
   default limits. The input is the SPEC text; model paths in it start at the working directory
   (the seeds name the committed models of tests/fuzz/corpus/fuzz_model, so run from the
   repository root). A SPEC that parses must give a tile grid that covers its raster. (Computing
   pixels is left out: a few hundred runs a second instead of thousands.) A gnn row's setup
   prepares GNN generation over the whole world (tn_gnn_gain: the sketch densified by example,
   membranes over the whole map), tens of seconds an input under the sanitizers once a world
   passes about 200 x 200 (docs/robustness.md). So SPECs with a gnn row over a world of more
   than FUZZ_GNN_MAX_PX pixels are skipped (fuzz_gnn_world_px); smaller ones run the whole setup,
   and the row's text is parsed the same way at any size.
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

#define FUZZ_GNN_MAX_PX (128.0 * 128.0)

/* The pixels of the SPEC's world when it has a gnn row (0 without one, or when the world line
   does not read as two numbers): lines, '#' comments and words as tn_world_parse splits them,
   the numbers by strtod (tn_world_parse refuses what strtod does not read, so a SPEC this
   misreads fails before any row is set up). text is modified. */
static double fuzz_gnn_world_px(char *text)
{
    char *line = text;
    double px = 0;
    int gnn = 0;
    while (line) {
        char *next = strchr(line, '\n'), *hash, *word[4], *end;
        int nw = 0;
        if (next) *next++ = 0;
        if ((hash = strchr(line, '#')) != NULL) *hash = 0;
        while (*line && nw < 4) {
            while (*line == ' ' || *line == '\t' || *line == '\r') *line++ = 0;
            if (!*line) break;
            word[nw++] = line;
            while (*line && *line != ' ' && *line != '\t' && *line != '\r') line++;
        }
        if (nw >= 1 && !strcmp(word[0], "gnn")) gnn = 1;
        if (nw == 3 && !strcmp(word[0], "world")) {
            double w = strtod(word[1], &end), h = *end ? 0 : strtod(word[2], &end);
            px = *end ? 0 : w * h;
        }
        line = next;
    }
    return gnn ? px : 0;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char *text = (char *)malloc(size + 1);
    tn_world w;
    tn_set_threads(1); /* one thread: a fuzzing run keeps to one core (the pool's idle workers spin) */
    if (!text) return 0;
    memcpy(text, data, size);
    text[size] = 0;
    if (fuzz_gnn_world_px(text) > FUZZ_GNN_MAX_PX) {
        free(text);
        return 0;
    }
    memcpy(text, data, size); /* fuzz_gnn_world_px cut it into words */
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
