/* bench_data.h - the shared DEMs for the benches that read ../shared/data (TN_DATA overrides):
   the metre mapping and pixel spacing of a region (dem_index.csv), a region's PNG in metres, and
   where a crop lies in its full DEM. Included after terrainnet.h by one bench each. */
#ifndef BENCH_DATA_H
#define BENCH_DATA_H
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static const char *data_dir(void)
{
    const char *d = getenv("TN_DATA");
    return d && d[0] ? d : "../shared/data";
}

/* dx_m, dy_m, h_at_0 and h_at_65535 of <region>_full.png from dem_index.csv. */
static int height_mapping(const char *region, double *dxy, double *h0, double *h1)
{
    char path[512], line[1024], want[256];
    FILE *f;
    snprintf(path, sizeof path, "%s/dem_index.csv", data_dir());
    snprintf(want, sizeof want, "dem/%s/%s_full.png,", region, region);
    if (!(f = fopen(path, "r"))) return 0;
    while (fgets(line, sizeof line, f)) {
        char *p = line;
        int col;
        if (strncmp(line, want, strlen(want)) != 0) continue;
        for (col = 0; col < 5 && p; col++) p = strchr(p, ',') ? strchr(p, ',') + 1 : NULL;
        if (!p || sscanf(p, "%lf,%lf", dxy, dxy + 1) != 2) dxy[0] = dxy[1] = 0; /* none recorded: the hillshade's own */
        for (col = 0; col < 2 && p; col++) p = strchr(p, ',') ? strchr(p, ',') + 1 : NULL;
        if (p && sscanf(p, "%lf,%lf", h0, h1) == 2) {
            fclose(f);
            return 1;
        }
    }
    fclose(f);
    return 0;
}

static int load_metres(const char *region, const char *suffix, double h0, double h1, tn_image *img)
{
    char path[512];
    size_t i;
    snprintf(path, sizeof path, "%s/dem/%s/%s_%s.png", data_dir(), region, region, suffix);
    if (tn_image_load(img, path, NULL)) return 0;
    for (i = 0; i < (size_t)img->width * img->height * img->channels; i++) img->data[i] = (float)(h0 + img->data[i] * (h1 - h0));
    return 1;
}

/* Where crop lies in full (exact match), or -1. */
static int locate(const tn_image *full, const tn_image *crop, int *cx, int *cy)
{
    int x, y, u, v;
    for (y = 0; y + crop->height <= full->height; y++)
        for (x = 0; x + crop->width <= full->width; x++) {
            int ok = 1;
            for (v = 0; v < crop->height && ok; v++)
                for (u = 0; u < crop->width && ok; u++) ok = TN_PIXEL(full, x + u, y + v, 0) == TN_PIXEL(crop, u, v, 0);
            if (ok) {
                *cx = x;
                *cy = y;
                return 1;
            }
        }
    return 0;
}

#endif
