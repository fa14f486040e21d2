/* extract_ridges: the ridge and valley network of a DEM as a sketch (paper 000, section 4.1).
   bin/extract_ridges [DEM] [-o PREFIX] [--threshold CELLS]   (no DEM: a 256 x 256 Perlin terrain)
   e.g. bin/extract_ridges ../shared/data/dem/alps_montblanc/alps_montblanc_256.png -o montblanc
   Valleys are cells that drain at least CELLS cells (default 0.1 % of the map), ridges the same
   on the upside-down DEM; both are thinned to one-pixel polylines. Writes PREFIX.tns (the
   network as editable sketch text, read back by tn_sketch_load) and PREFIX_preview.png (ridges
   yellow, valleys blue over a hillshade). */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int main(int argc, char **argv)
{
    tn_image dem = {0, 0, 0, NULL}, preview = {0, 0, 0, NULL};
    tn_extraction ex;
    tn_extract_opts eo;
    tn_perlin_opts po;
    tn_save_opts so;
    const char *in = NULL, *prefix = "ridges";
    char path[1024];
    int i, ridges = 0, valleys = 0;
    long points = 0;
    tn_status st;
    memset(&ex, 0, sizeof ex); /* so the cleanup below is safe whatever fails */
    memset(&eo, 0, sizeof eo); /* zero = defaults: threshold per size, closing 1, min length 10, ... */
    for (i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "-o") && i + 1 < argc) prefix = argv[++i];
        else if (!strcmp(argv[i], "--threshold") && i + 1 < argc) eo.threshold = atoi(argv[++i]);
        else if (argv[i][0] == '-' || in) {
            fprintf(stderr, "usage: extract_ridges [DEM] [-o PREFIX] [--threshold CELLS]\n");
            return 2;
        } else in = argv[i];
    }
    memset(&po, 0, sizeof po);
    po.seed = 3;
    st = in ? tn_image_load(&dem, in, NULL) : tn_noise_perlin(&dem, 256, 256, &po);
    if (st || (st = tn_extract(&ex, &dem, &eo))) goto fail;

    for (i = 0; i < ex.contours.count; i++) {
        if (ex.contours.items[i].type == TN_RIDGE) ridges++;
        else valleys++;
        points += ex.contours.items[i].npoints;
    }
    printf("%s: %d x %d, threshold %d cells\n", in ? in : "Perlin terrain", ex.width, ex.height, ex.threshold);
    printf("%d ridges (Strahler order up to %d), %d valleys (up to %d), %ld points\n", ridges, ex.ridge_max_order,
           valleys, ex.valley_max_order, points);

    snprintf(path, sizeof path, "%s.tns", prefix);
    if ((st = tn_sketch_save(path, &ex.contours))) goto fail;
    memset(&so, 0, sizeof so);
    so.bit_depth = 8;
    snprintf(path, sizeof path, "%s_preview.png", prefix);
    if ((st = tn_sketch_preview(&preview, &ex.contours, &dem, dem.width, dem.height)) ||
        (st = tn_image_save(path, &preview, &so)))
        goto fail;
    printf("wrote %s.tns, %s_preview.png\n", prefix, prefix);
fail:
    if (st) fprintf(stderr, "extract_ridges: %s: %s\n", tn_status_string(st), tn_last_error());
    tn_extraction_free(&ex);
    tn_image_free(&preview);
    tn_image_free(&dem);
    return st ? 1 : 0;
}
