/* fuzz_season.c - fuzz driver for the @@season CSV readers, at the library's default limits: the
   input is parsed as a climate (tn_climate_parse) and, written to a scratch directory that holds
   an 8 x 8 DEM "dem.pgm", a picture "frame.ppm", a mask "mask.pgm" and a climate "climate.csv",
   loaded as a season data list (tn_season_data_load), whose paths start at that directory. A
   climate that parses must pass tn_climate_check; a list that loads must hold finite samples.
     libFuzzer:  clang -g -O1 -fsanitize=fuzzer,address,undefined -I. fuzz_season.c -lm -pthread
     no libFuzzer: cc -DTN_FUZZ_MAIN -fsanitize=address,undefined -I. fuzz_season.c -lm -pthread
                   ./a.out [files...]   (runs each file as one input; no files: the committed corpus)
   Seeds: tests/fuzz/corpus/fuzz_season (climates and lists naming the files above). */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include "fuzz_files.h"
#include <math.h>

#ifdef __cplusplus
extern "C"
#endif
int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

/* The files a list may name, written once; SIDE x SIDE pixels (each site's insolation, most of
   an input's time, grows with them). */
#define SIDE 8
static int fixtures(void)
{
    static int made;
    static const char climate[] = "month,t_c,p_mm\n1,-2,60\n2,-1,55\n3,3,70\n4,8,80\n5,13,100\n6,16,120\n7,18,110\n8,17,115\n"
                                  "9,13,120\n10,8,110\n11,3,100\n12,-1,80\nlatitude,46\nelevation,300\n";
    tn_image dem = {0, 0, 0, NULL}, fr = {0, 0, 0, NULL}, mask = {0, 0, 0, NULL};
    int x, y, ok;
    if (made) return made > 0;
    ok = !tn_image_create(&dem, SIDE, SIDE, 1) && !tn_image_create(&fr, SIDE, SIDE, 3) && !tn_image_create(&mask, SIDE, SIDE, 1);
    for (y = 0; ok && y < SIDE; y++)
        for (x = 0; x < SIDE; x++) {
            dem.data[y * SIDE + x] = (float)(0.5 + 0.4 * sin(x * 0.5) * cos(y * 0.4));
            fr.data[3 * (y * SIDE + x)] = fr.data[3 * (y * SIDE + x) + 1] = fr.data[3 * (y * SIDE + x) + 2] = (float)((x + y) / (2.0 * SIDE));
            mask.data[y * SIDE + x] = (float)((x * y) % 5 == 0);
        }
    ok = ok && !tn_image_save(fuzz_path("dem.pgm"), &dem, NULL) && !tn_image_save(fuzz_path("frame.ppm"), &fr, NULL) &&
         !tn_image_save(fuzz_path("mask.pgm"), &mask, NULL) && fuzz_write(fuzz_path("climate.csv"), climate, sizeof climate - 1);
    tn_image_free(&dem);
    tn_image_free(&fr);
    tn_image_free(&mask);
    made = ok ? 1 : -1;
    return ok;
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const char *list = fuzz_path("list.csv");
    tn_climate c;
    tn_season_data d;
    int i;
    size_t k;
    tn_set_threads(1); /* one thread: a fuzzing run keeps to one core (the pool's idle workers spin) */
    if (tn_climate_parse(&c, (const char *)data, size, "fuzz") == TN_OK && tn_climate_check(&c) != TN_OK) abort();
    if (!fixtures() || !fuzz_write(list, data, size)) return 0;
    if (tn_season_data_load(&d, list) == TN_OK) {
        for (i = 0; i < d.count; i++) {
            const tn_image *t = d.samples[i].target;
            if (!t || !t->data || !isfinite(d.samples[i].time)) abort();
            for (k = 0; k < (size_t)t->width * t->height * t->channels; k++)
                if (!isfinite(t->data[k])) abort();
        }
        tn_season_data_free(&d);
    }
    return 0;
}

#define TN_FUZZ_NAME "fuzz_season"
#include "fuzz_replay.h"
