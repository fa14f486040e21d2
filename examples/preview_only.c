/* preview_only: a hillshaded preview of any DEM, from a program that compiles out everything
   but I/O and rendering (the TN_NO_ switches), so it stays small.
   bin/preview_only DEM OUT.png        Build alone: cc -O2 -I. examples/preview_only.c -lm -pthread */
#define TN_NO_ENGINE
#define TN_NO_NOISE
#define TN_NO_FINEDETAIL
#define TN_NO_SKETCH
#define TN_NO_EXTRACT
#define TN_NO_STYLE
#define TN_NO_TEXGAN
#define TN_NO_SINGAN
#define TN_NO_GNN
#define TN_NO_SEASON
#define TN_NO_EXPORT
#define TN_NO_WORLD
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>

int main(int argc, char **argv)
{
    tn_image dem = {0}, shade = {0};
    tn_status st;
    if (argc != 3) {
        fprintf(stderr, "usage: %s DEM OUT.png\n", argv[0]);
        return 2;
    }
    st = tn_image_load(&dem, argv[1], NULL);
    if (!st) st = tn_render_preview(&shade, &dem, NULL);
    if (!st) st = tn_image_save(argv[2], &shade, NULL);
    if (st) fprintf(stderr, "preview_only: %s: %s\n", tn_status_string(st), tn_last_error());
    tn_image_free(&shade);
    tn_image_free(&dem);
    return st ? 1 : 0;
}
