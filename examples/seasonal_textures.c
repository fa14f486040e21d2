/* seasonal_textures: one DEM through the year under a built-in Koppen climate, with the
   procedural texturer of @@season (no trained network, no data files).
   Usage: seasonal_textures DEM.png LO_M HI_M SPACING_M KOPPEN OUT_SHEET.png
   e.g.   seasonal_textures ../shared/data/dem/alps_montblanc/alps_montblanc_256.png 454 4810 92.7 Cfb year.png
   LO_M and HI_M map the file's 0..1 values to metres (0 0 = the file already holds metres). */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int main(int argc, char **argv)
{
    tn_image dem = {0, 0, 0, NULL}, ins = {0, 0, 0, NULL}, months[12], sheet = {0, 0, 0, NULL};
    tn_insolation_opts io;
    tn_season_opts so;
    tn_climate climate;
    float times[12];
    double lo, hi;
    size_t i, n;
    int m;
    if (argc != 7) {
        fprintf(stderr, "usage: %s DEM.png LO_M HI_M SPACING_M KOPPEN OUT_SHEET.png\n", argv[0]);
        return 2;
    }
    lo = atof(argv[2]);
    hi = atof(argv[3]);
    if (tn_image_load(&dem, argv[1], NULL) || tn_climate_koppen(&climate, argv[5])) {
        fprintf(stderr, "%s\n", tn_last_error());
        return 1;
    }
    n = (size_t)dem.width * dem.height;
    if (lo != hi)
        for (i = 0; i < n; i++) dem.data[i * dem.channels] = (float)(lo + dem.data[i * dem.channels] * (hi - lo));
    /* the year's insolation once (12 channels), then the texturer reads the state of snow and
       vegetation on the 15th of every month */
    memset(&io, 0, sizeof io);
    io.dx = (float)atof(argv[4]);
    if (tn_insolation(&ins, &dem, climate.latitude, &io)) {
        fprintf(stderr, "%s\n", tn_last_error());
        return 1;
    }
    memset(&so, 0, sizeof so);
    so.insolation = io;
    so.shade = 0.5f;
    for (m = 0; m < 12; m++) times[m] = (float)m;
    if (tn_season_texture(months, &dem, &climate, climate.latitude, &ins, times, 12, &so, NULL) ||
        tn_season_sheet(&sheet, months, 12, 4, 256) || tn_image_save(argv[6], &sheet, NULL)) {
        fprintf(stderr, "%s\n", tn_last_error());
        return 1;
    }
    printf("%s: %s, 12 months of %d x %d\n", argv[6], climate.name, dem.width, dem.height);
    for (m = 0; m < 12; m++) tn_image_free(&months[m]);
    tn_image_free(&sheet);
    tn_image_free(&ins);
    tn_image_free(&dem);
    return 0;
}
