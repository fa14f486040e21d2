#!/bin/sh
# Correctness against GRASS GIS: for every full DEM in ../shared/data (heights in metres from
# dem_index.csv), valley masks from terrainnet's accumulation and from `r.watershed -s` at the same
# threshold (terrainnet's default, 0.1 % of the map): F1 where a pixel within one pixel (8-neighbourhood)
# of the other mask counts as a match, and the strict Jaccard index. Highest Strahler order:
# terrainnet's network vs GRASS's `r.stream.extract` streams (same threshold, its own D8 directions,
# d8cut=0); r.stream.order is a GRASS add-on (not in Debian), so GRASS's order is computed by
# terrainnet's Strahler routine on GRASS's stream cells and directions (documented equivalent).
# Usage: sh bench/compare_grass.sh [DATA_DIR]   (needs `grass`: apt-get install grass-core)
# TN_GRASS_REUSE=1 reuses GRASS's outputs from an earlier run (in $TMPDIR/tn_compare_grass) when
# they are there, so only terrainnet's side is recomputed; TN_COMPARE_INC=DIR compiles the tool
# against DIR/terrainnet.h instead of this tree's.
set -e
cd "$(dirname "$0")/.."
D=${1:-${TN_SHARED_DATA:-../shared/data}}
W=${TMPDIR:-/tmp}/tn_compare_grass
mkdir -p "$W"
command -v grass > /dev/null || { echo "# grass not installed"; exit 1; }
[ -f "$D/dem_index.csv" ] || { echo "# no $D/dem_index.csv"; exit 1; }
cat > "$W/tool.c" << 'CEOF'
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
/* prep PNG LO HI OUT.f32 -> prints "W H T"; cmp OUT.f32 W H T PREFIX -> figures */
static void *slurp(const char *p, size_t n) { FILE *f = fopen(p, "rb"); void *b = malloc(n); if (!f || fread(b, 1, n, f) != n) { fprintf(stderr, "read %s\n", p); exit(1); } fclose(f); return b; }
static int near1(const uint8_t *m, int w, int h, int x, int y) { int dx, dy; for (dy = -1; dy <= 1; dy++) for (dx = -1; dx <= 1; dx++) { int xx = x + dx, yy = y + dy; if (xx >= 0 && yy >= 0 && xx < w && yy < h && m[yy * w + xx]) return 1; } return 0; }
int main(int argc, char **argv) {
    tn_image dem = {0, 0, 0, NULL};
    if (argc == 6 && !strcmp(argv[1], "prep")) {
        double lo = atof(argv[3]), hi = atof(argv[4]); size_t i, n; FILE *f;
        if (tn_image_load(&dem, argv[2], NULL)) { fprintf(stderr, "%s\n", tn_last_error()); return 1; }
        n = (size_t)dem.width * dem.height;
        for (i = 0; i < n; i++) dem.data[i] = (float)(lo + dem.data[i] * (hi - lo));
        f = fopen(argv[5], "wb"); if (!f || fwrite(dem.data, 4, n, f) != n) return 1; fclose(f);
        printf("%d %d %d\n", dem.width, dem.height, tn_extract_default_threshold(dem.width, dem.height));
        return 0;
    }
    if (argc == 7 && !strcmp(argv[1], "cmp")) {
        int w = atoi(argv[3]), h = atoi(argv[4]), T = atoi(argv[5]), x, y, top = 0, gtop = 0; size_t n = (size_t)w * h, i;
        char p[1024]; float *gacc; int32_t *gstr, *gdir; uint8_t *gm, *om, *gdir8, *gord, *smask; tn_flow f, gf;
        size_t a = 0, b = 0, both = 0, uni = 0, pa = 0, rb = 0; double P, R;
        tn_image_create(&dem, w, h, 1);
        free(dem.data); dem.data = (float *)slurp(argv[2], n * 4);
        snprintf(p, sizeof p, "%s.acc", argv[6]); gacc = (float *)slurp(p, n * 4);
        snprintf(p, sizeof p, "%s.str", argv[6]); gstr = (int32_t *)slurp(p, n * 4);
        snprintf(p, sizeof p, "%s.dir", argv[6]); gdir = (int32_t *)slurp(p, n * 4);
        if (tn_flow_compute(&f, &dem, 0)) { fprintf(stderr, "%s\n", tn_last_error()); return 1; }
        gm = calloc(n, 1); om = calloc(n, 1); gdir8 = malloc(n); gord = calloc(n, 1); smask = calloc(n, 1);
        for (i = 0; i < n; i++) { om[i] = f.acc[i] >= (uint32_t)T; gm[i] = fabsf(gacc[i]) >= (float)T; }
        for (y = 0; y < h; y++) for (x = 0; x < w; x++) {
            i = (size_t)y * w + x;
            a += om[i]; b += gm[i]; both += om[i] && gm[i]; uni += om[i] || gm[i];
            if (om[i] && near1(gm, w, h, x, y)) pa++;
            if (gm[i] && near1(om, w, h, x, y)) rb++;
        }
        P = a ? (double)pa / a : 0; R = b ? (double)rb / b : 0;
        /* GRASS directions (1 = NE ... 8 = E, counter-clockwise; negative = leaves the region) -> ours */
        for (i = 0; i < n; i++) {
            int g = abs(gdir[i]), d = g >= 1 && g <= 8 ? (8 - g) % 8 : TN_FLOW_OUTLET;
            x = (int)(i % (size_t)w); y = (int)(i / (size_t)w);
            if (d != TN_FLOW_OUTLET) { int nx = x + tn__d8x[d], ny = y + tn__d8y[d]; if (nx < 0 || ny < 0 || nx >= w || ny >= h) d = TN_FLOW_OUTLET; }
            gdir8[i] = (uint8_t)d; smask[i] = gstr[i] > 0;
        }
        memset(&gf, 0, sizeof gf); gf.width = w; gf.height = h; gf.dir = gdir8;
        {
            uint8_t *ord = calloc(n, 1);
            tn_strahler_order(ord, &f, om, &top);
            if (tn_strahler_order(gord, &gf, smask, &gtop)) { fprintf(stderr, "grass strahler: %s\n", tn_last_error()); gtop = -1; }
            free(ord);
        }
        printf("cells_ours %zu cells_grass %zu f1_tol1 %.4f precision %.4f recall %.4f jaccard %.4f strahler_ours %d strahler_grass %d\n",
               a, b, P + R > 0 ? 2 * P * R / (P + R) : 0, P, R, uni ? (double)both / uni : 0, top, gtop);
        return 0;
    }
    fprintf(stderr, "usage: tool prep|cmp ...\n");
    return 2;
}
CEOF
cc -O2 -I"${TN_COMPARE_INC:-.}" "$W/tool.c" -o "$W/tool" -lm -pthread
grep ',full,' "$D/dem_index.csv" | while IFS=, read -r path region kind w h dx dy lo hi mn mx; do
    set -- $("$W/tool" prep "$D/$path" "$lo" "$hi" "$W/$region.f32")
    if [ "${TN_GRASS_REUSE:-0}" != 1 ] || [ ! -s "$W/$region.dir" ]; then
        grass --tmp-location XY --exec /usr/bin/python3 bench/grass_inner.py export "$W/$region.f32" "$1" "$2" "$3" "$W/$region" \
            > "$W/$region.log" 2>&1 || { echo "$region: GRASS failed (see $W/$region.log)"; continue; }
    fi
    echo "$region ($1 x $2, threshold $3): $("$W/tool" cmp "$W/$region.f32" "$1" "$2" "$3" "$W/$region")"
done
