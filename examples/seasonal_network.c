/* seasonal_network: train paper 003's KPD generator on one site's year of pictures and render a
   smooth year from it, every frame between two months made by interpolating the network's
   gamma/beta (Eq. 1), not by blending pictures.
   Usage: seasonal_network DATA.csv MINUTES OUT_SHEET.png
   e.g.   seasonal_network examples/data/slovenia_season.csv 3 ndvi_year.png
   DATA.csv is a season data file (docs/season.md): Sentinel-2 NDVI of a Slovenian meadow here. */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int main(int argc, char **argv)
{
    tn_season_data data;
    tn_kpd_opts o;
    tn_kpd model;
    tn_image frames[24], sheet = {0, 0, 0, NULL};
    int f, n = 0;
    size_t k;
    if (argc != 4) {
        fprintf(stderr, "usage: %s DATA.csv MINUTES OUT_SHEET.png\n", argv[0]);
        return 2;
    }
    if (tn_season_data_load(&data, argv[1])) { /* reads every picture, computes each site's insolation */
        fprintf(stderr, "%s\n", tn_last_error());
        return 1;
    }
    memset(&o, 0, sizeof o); /* zero = defaults: the paper's conditioning (T12 + P12 + S12) */
    o.lo = data.lo;
    o.hi = data.hi;
    o.train.minutes = atof(argv[2]);
    if (tn_kpd_train(&model, data.samples, data.count, &o, NULL)) {
        fprintf(stderr, "%s\n", tn_last_error());
        return 1;
    }
    for (f = 0; f < 24; f++, n++) { /* twice a month from mid-January, site 0 */
        if (tn_kpd_generate(&frames[f], &model, &data.dems[0], &data.climates[0], &data.insolation[0], 0.5f * (float)f, 0, 0,
                            data.dems[0].width, data.dems[0].height))
            break;
        for (k = 0; k < (size_t)frames[f].width * frames[f].height * frames[f].channels; k++) /* to 0..1 for the picture */
            frames[f].data[k] = (frames[f].data[k] - model.lo) / (model.hi - model.lo);
    }
    if (n < 24 || tn_season_sheet(&sheet, frames, 24, 6, 128) || tn_image_save(argv[3], &sheet, NULL)) {
        fprintf(stderr, "%s\n", tn_last_error());
        return 1;
    }
    printf("%s: 24 frames through the year (%ld training iterations)\n", argv[3], model.iterations);
    for (f = 0; f < n; f++) tn_image_free(&frames[f]);
    tn_image_free(&sheet);
    tn_kpd_free(&model);
    tn_season_data_free(&data);
    return 0;
}
