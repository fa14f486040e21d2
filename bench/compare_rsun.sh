#!/bin/sh
# Insolation against GRASS GIS r.sun on real DEMs: Pearson correlation of terrainnet's monthly
# direct-beam maps (tn_insolation, outside the atmosphere) with r.sun's beam irradiation (clear
# sky, Linke turbidity 3, 15 min steps, terrain shadows, slope/aspect from r.slope.aspect) on the
# 15th of a winter, an equinox and a summer month; the ratio of the means shows the atmosphere's
# share. Usage: sh bench/compare_rsun.sh [DATA_DIR]   (needs `grass`: apt-get install grass-core)
set -e
cd "$(dirname "$0")/.."
D=${1:-${TN_SHARED_DATA:-../shared/data}}
W=${TMPDIR:-/tmp}/tn_compare_rsun
mkdir -p "$W"
command -v grass > /dev/null || { echo "# grass not installed"; exit 1; }
cat > "$W/tool.c" << 'CEOF'
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
/* prep PNG LO HI OUT.f32 -> "W H"; cmp OUT.f32 W H DX DY LAT PREFIX MONTH... -> figures */
int main(int argc, char **argv) {
    tn_image dem = {0, 0, 0, NULL}, ins = {0, 0, 0, NULL};
    size_t i, n;
    if (argc == 6 && !strcmp(argv[1], "prep")) {
        double lo = atof(argv[3]), hi = atof(argv[4]); FILE *f;
        if (tn_image_load(&dem, argv[2], NULL)) { fprintf(stderr, "%s\n", tn_last_error()); return 1; }
        n = (size_t)dem.width * dem.height;
        for (i = 0; i < n; i++) dem.data[i] = (float)(lo + dem.data[i] * (hi - lo));
        f = fopen(argv[5], "wb"); if (!f || fwrite(dem.data, 4, n, f) != n) return 1; fclose(f);
        printf("%d %d\n", dem.width, dem.height);
        return 0;
    }
    if (argc >= 9 && !strcmp(argv[1], "cmp")) {
        int w = atoi(argv[3]), h = atoi(argv[4]), a, b = 2; tn_insolation_opts o; double t0, sec; FILE *f; float *g;
        tn_image_create(&dem, w, h, 1);
        n = (size_t)w * h;
        f = fopen(argv[2], "rb"); if (!f || fread(dem.data, 4, n, f) != n) return 1; fclose(f);
        memset(&o, 0, sizeof o); o.dx = (float)atof(argv[5]); o.dy = (float)atof(argv[6]);
        t0 = tn_time_seconds();
        if (tn_insolation(&ins, &dem, atof(argv[7]), &o)) { fprintf(stderr, "%s\n", tn_last_error()); return 1; }
        sec = tn_time_seconds() - t0;
        g = (float *)malloc(n * 4);
        for (a = 9; a < argc; a++) {
            int m = atoi(argv[a]); char p[1024]; double sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0, r; size_t k = 0;
            snprintf(p, sizeof p, "%s_%d.f32", argv[8], tn_day_of_year(m, 15));
            f = fopen(p, "rb"); if (!f || fread(g, 4, n, f) != n) { fprintf(stderr, "read %s\n", p); return 1; } fclose(f);
            /* r.sun leaves the outermost ring without slope: compare the interior */
            for (i = 0; i < n; i++) {
                int x = (int)(i % (size_t)w), y = (int)(i / (size_t)w); double u, v;
                if (x < b || y < b || x >= w - b || y >= h - b) continue;
                u = ins.data[i * 12 + m - 1]; v = g[i];
                sx += u; sy += v; sxx += u * u; syy += v * v; sxy += u * v; k++;
            }
            r = (sxy - sx * sy / k) / sqrt((sxx - sx * sx / k) * (syy - sy * sy / k));
            printf("  month %2d: pearson %.4f  mean ours %.0f  r.sun %.0f  W h/m^2/day (ratio %.3f)\n", m, r, sx / k, sy / k, sy / sx);
        }
        printf("  terrainnet year (12 months): %.2f s on %d threads\n", sec, tn_get_threads());
        free(g);
        return 0;
    }
    fprintf(stderr, "usage: tool prep|cmp ...\n");
    return 2;
}
CEOF
cc -O2 -march=native -I"${TN_COMPARE_INC:-.}" "$W/tool.c" -o "$W/tool" -lm -pthread
# region lo hi dx dy lat (MANIFEST.md; latitudes of the regions' centres)
for spec in "alps_montblanc/alps_montblanc_256 454 4810 92.7 92.7 45.8" "himalaya_everest/himalaya_everest_256 2362 8838 92.6 92.6 27.9" \
            "volcano_sthelens_10m/volcano_sthelens_10m_256 902 2539 10 10 46.2"; do
    set -- $spec
    r=$(basename "$1")
    set -- $("$W/tool" prep "$D/dem/$1.png" "$2" "$3" "$W/$r.f32") "$4" "$5" "$6"
    if [ "${TN_RSUN_REUSE:-0}" != 1 ] || [ ! -s "$W/${r}_349.f32" ]; then
        grass --tmp-location EPSG:32632 --exec /usr/bin/python3 bench/rsun_inner.py "$W/$r.f32" "$1" "$2" "$3" "$4" "$5" "$W/$r" 15 74 166 349 \
            > "$W/$r.log" 2>&1 || { echo "$r: GRASS failed (see $W/$r.log)"; continue; }
    fi
    echo "$r ($1 x $2, lat $5): $(grep '^# r.sun' "$W/$r.log" | tr '\n' ' ')"
    "$W/tool" cmp "$W/$r.f32" "$1" "$2" "$3" "$4" "$5" "$W/$r" 1 3 6 12
done
