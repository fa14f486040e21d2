/* render_terrain: load any heightmap (or make a procedural one) and write a hillshaded preview
   and a 3D view.   bin/render_terrain [DEM] [-o PREFIX]   (no DEM: Perlin fBm terrain) */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <string.h>

int main(int argc, char **argv)
{
    tn_image dem = {0, 0, 0, NULL}, preview = {0, 0, 0, NULL}, view = {0, 0, 0, NULL};
    const char *in = NULL, *prefix = "terrain";
    char path[1024];
    tn_status st;
    int i;
    for (i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "-o") && i + 1 < argc) prefix = argv[++i];
        else in = argv[i];
    }
    st = in ? tn_image_load(&dem, in, NULL) : tn_noise_perlin(&dem, 512, 512, NULL);
    if (st) {
        fprintf(stderr, "render_terrain: %s: %s\n", tn_status_string(st), tn_last_error());
        return 1;
    }
    if ((st = tn_render_preview(&preview, &dem, NULL)) || (st = tn_render_view(&view, &dem, NULL))) {
        fprintf(stderr, "render_terrain: %s\n", tn_last_error());
        tn_image_free(&dem);
        return 1;
    }
    snprintf(path, sizeof path, "%s_preview.png", prefix);
    st = tn_image_save(path, &preview, NULL);
    snprintf(path, sizeof path, "%s_view.png", prefix);
    if (!st) st = tn_image_save(path, &view, NULL);
    if (st) fprintf(stderr, "render_terrain: %s\n", tn_last_error());
    else printf("wrote %s_preview.png and %s_view.png\n", prefix, prefix);
    tn_image_free(&dem);
    tn_image_free(&preview);
    tn_image_free(&view);
    return st ? 1 : 0;
}
