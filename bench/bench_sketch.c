/* bench_sketch: a drawing of a few strokes becomes terrain (paper 000's user path, issue 30).
   For one region and a trained gnn model of its 128 crop (gnn-train), each drawing of
   examples/data (sketch_valley, sketch_summit, sketch_ring, sketch_cross: heights 0..1 over the
   example's range) is generated at 256 x 256 six ways:
   - membrane: the Laplace interpolation of the strokes' heights (no network);
   - today: the network on the strokes alone (--grow off), the gain as tested;
   - random48: the strokes with 48 random nodes' ridges and valleys (paper 5.2, --random 48);
   - new: the default for a drawing of few strokes: densified by example (tn_gnn_grow), then the
     example's fine detail (tn_fine_detail) when the model holds its example;
   - grown_membrane: the membrane of the densified sketch (gain -1), what the network adds to;
   - grown_nodetail: new without the fine detail (--detail none).
   Figures per drawing and way (`name: value unit` lines):
   - follow: the share of stroke points above (ridge) or below (valley) both terrain pixels 4 px
     across the stroke (tn_gnn_ordering, distance 4);
   - height_error: mean |terrain - asked height| over the strokes' pixels, % of the example's range;
     height_bias: the mean of terrain - asked height there (< 0: strokes deeper than asked);
   - slope, curvature, spectrum: tn_realism_compare distances of the output to the example (the
     128 crop, metres, its pixel spacing; nothing resized), each divided by the mean distance of
     three real 256 crops of the same DEM (the corners of <region>_full.png farthest from the
     example) to the example: <= 1.5 is the target; where the example is stored in
     coarse height steps (tn_image_height_step: 8-bit), _smooth: the same three against the
     example and the real crops without their steps (tn_image_dequantize), as gnn-train learns it;
   - heights: the output's height range against the example's (the model's), and the share of
     the map more than 10 % of that range outside it (ground the example has nowhere);
   - basins: the share of the map in closed basins deeper than 1 % of the example's range (water
     could not leave them), beside the real crops' (real_crop_K lines);
   - peaks: summits per 10^4 px, points of the terrain (rounded to the DEM's height step, as the
     real crops are stored: height_step) blurred by a Gaussian of 1.5 px that are the highest
     within 4 px (a 9 x 9 window), 4 px from the map's edge; x real: over the real crops' mean
     (real_peaks; the example's 128 px beside it); an egg-crate of cones between the strokes has
     several times the real crops' count;
   - lines, blobness: the arrangement of the relief (issue 30: cones of one size against long
     crests), ARR_EDGE px from the map's edge. lines: on a Gaussian of LINE_SIGMA px, the LINE_TOP
     share of the pixels with the largest Hessian eigenvalue (valleys; the smallest, negated:
     ridges), 8-connected, and the share of them in lines whose bounding box has a diagonal of
     LINE_LONG px or more; blobness: on a Gaussian of BLOB_SIGMA px, over the BLOB_TOP share of the
     pixels most curved across, the mean of |the other eigenvalue| over |that one| (0: crests and
     valleys, 1: cones and pits); x real: over the real crops' mean (real_lines, with the example's
     128 px beside it). Smooth ground scores long lines and low blobness too (the membrane, today's
     output): these read the arrangement beside the three distances, not alone;
   - fall_ratio: whether the relief runs down the slopes (gullies and spurs down a mountainside, not
     knolls): the relief finer than two box means of 8 px, the energy of its gradient across
     the fall lines of the ground (two box means of 16 px) over that along them (1: no
     preference), 16 px from the edge; x real: over the real crops' mean (real_lines);
   - crest_dominance, floor_dominance: whether the drawing shapes the map around its lines: at
     every px of the drawn ridges (valleys), 12 px from their ends and 48 px from the map's edge,
     over the ground 6-48 px from it (ground within 4 px of a line of the kind left out): the
     share lower than the line (higher for a valley), and over: how far the highest (lowest)
     pixel of that ground tops the line (lies below it), mean over the points, % of the
     example's range; real_crest_dominance, real_floor_dominance: the same on the three real
     crops' main lines (tn_extract's highest Strahler order). Quilted high ground standing over
     a drawn ring tens of px away passes follow (4 px) but reads here;
   - crest_relief, floor_relief: the along-line relief of the drawn ridges (valleys): the std of
     the terrain along them (every px of their length) minus its running mean over 17 px, against
     the same on the example's main ridges (valleys: the highest Strahler order of tn_extract's
     lines of the 128 crop; example_crest_relief, example_floor_relief lines); crest_flank_relief,
     floor_flank_relief: the same 6 px across the lines on both sides (gullies and spurs);
   - crest_top, crest_seam, crest_spike (floor_* for the drawn valleys, heights negated): the
     cross profiles of the drawn lines (every px of their length, 12 px from their ends and from
     every other stroke, bilinear every 0.5 px along the normal): top, the share of points that
     are the highest within 1..3 px across; seam, the share with higher ground on both sides
     within 6 px (a groove along a ridge); spike, the mean profile's drop 1 px across over a third
     of its drop 3 px across (1: straight flanks, > 1: a wall of a pixel on its ground, a thin line
     in map view, < 1: a rounded top); example_crest_top ... lines: the same on the example's main
     lines (no clearance: its network is dense; its lines are extracted, not drawn, so within a
     px of the crest: read its top as a floor, its spike as the target);
   - crest_profile_left, crest_profile_right, crest_shoulder (drawn ridges against the example's
     main ridges, tn_extract's highest Strahler order): the mean cross profile of the drawn ridges
     on each side apart (left and right of the drawing direction: on the ring, its inside and
     outside; the example's sides pooled), every px of their length (12 px from their ends and
     from every other stroke, 12 px from the map's edge), the drop below the line d = 1 .. 12 px
     across over the drop at 12 px; shoulder: the drop from 6 to 12 px over the drop from 0 to 6
     px (1: a straight flank; the Alps' main ridges 0.70; less: a face of a few px on flatter
     ground, an embankment; a groove at its foot lowers it further);
   - hatch: the comb of short streaks across a drawn line (issue 30: "no hatching with the 5-10
     px part period"): along paths 2, 3, 4, 5 and 6 px off the drawn lines on both sides (the line
     averaged over 7 points, so a pixel chain's staircase does not shake its normal; every px of
     its length, bilinear), windows of 32 px (12 px from the line's ends and from every other
     stroke, 8 px inside the map), linear trend removed, Hann weighted: the RMS of their power in
     periods of 3.2 to 6.4 px (DFT bins 5-10), m, where a streak of a px or two across a flank
     lands, and that band's share of all their power; against the same on the example's main lines
     (example_hatch: its ridges and valleys of the two highest Strahler orders of tn_extract,
     chained end to end, no clearance) and on the three real crops' (real_hatch);
   - floor_profile (drawn valleys against the example's main valleys, tn_extract's highest
     Strahler order): at every px of the drawn valleys (12 px from their ends and from every other
     stroke; the example's main valleys without clearance; both 16 px from the map's edge), the
     depth below the banks d px across, r(d) = the mean height d px either side along the normal
     less the height on the line; printed as the mean r at 1, 2, 4, 8 px over the mean r at 16 px
     (a V rises on: the Alps example 0.04 0.12 0.27 0.52; a trough is full by 8 px: 0.94);
     floor_profile_distance: the mean over 1, 2, 4, 8 px of |drawn - example| of those ratios
     (_real: against the mean ratios of the real crops' own main valleys, a larger sample);
     floor_width_cv, floor_depth_cv: std / mean over the points of the half-depth width (the
     first d with r(d) >= r(16) / 2) and of the depth r(16); floor_junctions: tributaries per 100
     px of the lines: tn_extract run on the output itself (the example's threshold, 16 cells),
     its valleys with one end within 3 px of a drawn valley and the other more than 9 px from all
     of them; example_floor_* and real_floor_* lines: the same on the example and on the real
     crops (the mean of their normalised figures); floor_depth: the mean r at 16 px, m, against
     the example's main valleys and the real crops' (a drawn valley cut deeper than the example's
     main valleys is a trench);
   - seconds: generation time (gain test included); membrane_seconds and membrane_1024_seconds:
     tn_gnn_membrane alone at 256 and 1024 px.
   With big=N, each drawing also at N x N (its canvas scaled) the new way, with the map-scale level
   (map_scale: its factor, 1 = none) and without it (one_level): seconds, follow, height_error, and
   floor_detail: the median |terrain - its Gaussian of 2 px| within 4 px of the drawn valleys over
   the median elsewhere (the example's own: the plan's floor_detail); for N >= 512, _windows: the
   three distances of 9 windows of 256 px of the big map (a 3 x 3 grid over its middle 3/4) to
   the example, their mean, against the real crops' mean.
   Usage: bench_sketch REGION MODEL.tnw [threads] [finetune=N] [pictures=DIR] [drawings=a,b,...] [from=DIR] [big=N] [seed=S]
   from the repository root; seed= the generation's seed (default 1); drawings= names the drawings, read from DIR/sketch_<name>.tns (from=,
   default examples/data); pictures=DIR writes DIR/sketch_<region>_<drawing>.png: example (its
   128 px at their own size) | drawing | today | grown_nodetail | new, hillshaded on the example's
   range. */
#define TN_INTERNALS /* tn__gnn_fall_ratio */
#include "terrainnet.h"
#include "bench_data.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>

static tn_realism_opts ropts;

static void distances(const tn_image *ex, const tn_image *img, double *d)
{
    tn_realism r;
    d[0] = d[1] = d[2] = NAN;
    if (tn_realism_compare(&r, ex, img, &ropts)) return;
    d[0] = r.slope_distance;
    d[1] = r.curvature_distance;
    d[2] = r.spectrum_distance;
}

#define PEAK_SIGMA 1.5f /* px: the Gaussian a peak is found on */
#define PEAK_R 4         /* px: a peak is the highest point within this many px (a 9 x 9 window) */

/* The DEM's height step (the smallest gap between two of its heights) and one of its heights:
   peaks counts a terrain on that grid, as the real crops are stored. On an 8-bit DEM a flat
   mesa top is one grey level, and a continuous terrain's sub-level ripples there would count
   as summits (docs/gnn.md, "Summits on an 8-bit DEM"). */
static double g_step, g_base;

static int cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return (x > y) - (x < y);
}

/* g_step and g_base from the DEM's heights. */
static void height_step(const tn_image *dem)
{
    size_t i, n = (size_t)dem->width * dem->height;
    float *v = (float *)malloc(n * sizeof(float));
    double tiny;
    g_step = 0, g_base = 0;
    if (!v || !n) {
        free(v);
        return;
    }
    memcpy(v, dem->data, n * sizeof(float));
    qsort(v, n, sizeof(float), cmp_float);
    tiny = 1e-6 * ((double)v[n - 1] - v[0]);
    for (i = 1; i < n; i++) {
        double gap = (double)v[i] - v[i - 1];
        if (gap > tiny && (g_step == 0 || gap < g_step)) g_step = gap;
    }
    g_base = v[0];
    free(v);
}

/* Summits per 10^4 px: points of img (on the DEM's height grid) blurred by PEAK_SIGMA that are the
   highest within PEAK_R px (ties count once, the first in raster order), PEAK_R px from the map's edge. */
static double peaks(const tn_image *img)
{
    tn_image b = {0, 0, 0, NULL}, g = {0, 0, 0, NULL};
    int x, y, u, v, W = img->width, H = img->height, n = 0;
    size_t i;
    if (W <= 2 * PEAK_R || H <= 2 * PEAK_R || tn_image_copy(&g, img)) return NAN;
    if (g_step > 0)
        for (i = 0; i < (size_t)W * H; i++) g.data[i] = (float)(g_base + g_step * floor((g.data[i] - g_base) / g_step + 0.5));
    if (tn_image_blur(&b, &g, PEAK_SIGMA)) {
        tn_image_free(&g);
        return NAN;
    }
    tn_image_free(&g);
    for (y = PEAK_R; y < H - PEAK_R; y++)
        for (x = PEAK_R; x < W - PEAK_R; x++) {
            float h = b.data[(size_t)y * W + x];
            int top = 1;
            for (v = -PEAK_R; top && v <= PEAK_R; v++)
                for (u = -PEAK_R; u <= PEAK_R; u++) {
                    float q = b.data[(size_t)(y + v) * W + x + u];
                    if (q > h || (q == h && (v < 0 || (v == 0 && u < 0)))) {
                        top = 0;
                        break;
                    }
                }
            n += top;
        }
    tn_image_free(&b);
    return 1e4 * n / ((double)(W - 2 * PEAK_R) * (H - 2 * PEAK_R));
}

#define LINE_SIGMA 1.5f /* px: the Gaussian the lines' curvature is read on ... */
#define LINE_TOP 0.15    /* ... the sharpest share of the pixels that are line pixels ... */
#define LINE_LONG 32     /* ... and a long line's bounding-box diagonal (px) */
#define BLOB_SIGMA 3.0f  /* px: the Gaussian the blobness is read on ... */
#define BLOB_TOP 0.25    /* ... over this share of the pixels, the most curved */
#define ARR_EDGE 16      /* px from the map's edge left out of both */

/* The Hessian's eigenvalues at p of g (W wide), e1 >= e2. */
static void hessian(const float *g, int W, size_t p, float *e1, float *e2)
{
    float xx = g[p + 1] - 2 * g[p] + g[p - 1], yy = g[p + W] - 2 * g[p] + g[p - W];
    float xy = 0.25f * (g[p + W + 1] - g[p + W - 1] - g[p - W + 1] + g[p - W - 1]);
    float tr = 0.5f * (xx + yy), d = sqrtf(0.25f * (xx - yy) * (xx - yy) + xy * xy);
    *e1 = tr + d, *e2 = tr - d;
}

/* The value at share q of v's n values (sorts v). */
static float quantile(float *v, size_t n, double q)
{
    qsort(v, n, sizeof(float), cmp_float);
    return v[(size_t)(q * (double)(n - 1))];
}

/* Whether valleys and ridges run on as lines: img blurred by LINE_SIGMA; its valley pixels are the
   LINE_TOP share with the largest Hessian eigenvalue (ridges: the smallest, negated), 8-connected
   into lines; share[0] (valleys), share[1] (ridges) = the share of them in lines whose bounding box
   has a diagonal of LINE_LONG px or more. ARR_EDGE px from the edge left out. */
static void long_lines(const tn_image *img, double *share)
{
    tn_image b = {0, 0, 0, NULL};
    int W = img->width, H = img->height, kind, x, y;
    size_t n = (size_t)W * H, m = 0, i;
    float *e = (float *)malloc(n * sizeof(float)), *v = (float *)malloc(n * sizeof(float));
    int *stack = (int *)malloc(n * sizeof(int));
    unsigned char *seen = (unsigned char *)malloc(n);
    share[0] = share[1] = NAN;
    if (!e || !v || !stack || !seen || W <= 2 * ARR_EDGE + 2 || H <= 2 * ARR_EDGE + 2 || tn_image_blur(&b, img, LINE_SIGMA)) goto done;
    for (kind = 0; kind < 2; kind++) {
        long all = 0, longp = 0;
        float thr;
        m = 0;
        for (y = ARR_EDGE; y < H - ARR_EDGE; y++)
            for (x = ARR_EDGE; x < W - ARR_EDGE; x++) {
                float e1, e2;
                i = (size_t)y * W + x;
                hessian(b.data, W, i, &e1, &e2);
                v[m++] = e[i] = kind ? -e2 : e1;
            }
        thr = quantile(v, m, 1 - LINE_TOP);
        memset(seen, 0, n);
        for (y = ARR_EDGE; y < H - ARR_EDGE; y++)
            for (x = ARR_EDGE; x < W - ARR_EDGE; x++) {
                int sp = 0, x0 = x, x1 = x, y0 = y, y1 = y, cnt = 0;
                i = (size_t)y * W + x;
                if (seen[i] || !(e[i] >= thr && e[i] > 0)) continue;
                seen[i] = 1, stack[sp++] = (int)i;
                while (sp) {
                    int q = stack[--sp], qx = q % W, qy = q / W, dx, dy;
                    cnt++;
                    x0 = qx < x0 ? qx : x0, x1 = qx > x1 ? qx : x1, y0 = qy < y0 ? qy : y0, y1 = qy > y1 ? qy : y1;
                    for (dy = -1; dy <= 1; dy++)
                        for (dx = -1; dx <= 1; dx++) {
                            int X = qx + dx, Y = qy + dy;
                            size_t r = (size_t)Y * W + X;
                            if (X < ARR_EDGE || Y < ARR_EDGE || X >= W - ARR_EDGE || Y >= H - ARR_EDGE || seen[r] || !(e[r] >= thr && e[r] > 0)) continue;
                            seen[r] = 1, stack[sp++] = (int)r;
                        }
                }
                all += cnt;
                if ((double)(x1 - x0 + 1) * (x1 - x0 + 1) + (double)(y1 - y0 + 1) * (y1 - y0 + 1) >= (double)LINE_LONG * LINE_LONG) longp += cnt;
            }
        share[kind] = all ? (double)longp / all : NAN;
    }
done:
    tn_image_free(&b);
    free(e), free(v), free(stack), free(seen);
}

/* Whether the relief runs down the slopes (tn__gnn_fall_ratio, which the grown ground's erosion
   reads on the example): its part finer than two box means of 8 px, the energy of its gradient
   across the fall lines of the ground (two box means of 16 px) over that along them (1: no
   preference; gullies and spurs down a mountainside: more), 16 px from the edge left out. */
static double fall_ratio(const tn_image *img)
{
    double r = NAN;
    return tn__gnn_fall_ratio(img, &r) ? NAN : r;
}

/* Cones against crests: img blurred by BLOB_SIGMA; over the BLOB_TOP share of the pixels with the
   largest |Hessian eigenvalue| (the more curved direction), the mean of the other eigenvalue's
   magnitude over it (0: a crest or a valley, curved across only; 1: a cone's top or a pit).
   ARR_EDGE px from the edge left out. */
static double blobness(const tn_image *img)
{
    tn_image b = {0, 0, 0, NULL};
    int W = img->width, H = img->height, x, y;
    size_t n = (size_t)W * H, m = 0, k, cnt = 0;
    float *a = (float *)malloc(n * sizeof(float)), *o = (float *)malloc(n * sizeof(float)), *v = (float *)malloc(n * sizeof(float)), thr;
    double sum = 0, r = NAN;
    if (!a || !o || !v || W <= 2 * ARR_EDGE + 2 || H <= 2 * ARR_EDGE + 2 || tn_image_blur(&b, img, BLOB_SIGMA)) goto done;
    for (y = ARR_EDGE; y < H - ARR_EDGE; y++)
        for (x = ARR_EDGE; x < W - ARR_EDGE; x++) {
            float e1, e2;
            hessian(b.data, W, (size_t)y * W + x, &e1, &e2);
            e1 = fabsf(e1), e2 = fabsf(e2);
            a[m] = v[m] = e1 > e2 ? e1 : e2, o[m] = e1 > e2 ? e2 : e1, m++;
        }
    thr = quantile(v, m, 1 - BLOB_TOP);
    for (k = 0; k < m; k++)
        if (a[k] >= thr && a[k] > 0) sum += o[k] / a[k], cnt++;
    if (cnt) r = sum / (double)cnt;
done:
    tn_image_free(&b);
    free(a), free(o), free(v);
    return r;
}

/* The share of img's pixels in closed basins deeper than 1 % of the example's range (lo..hi):
   what depression filling raises by more; almost none on a real mountain crop. */
static double basins(const tn_image *img, float lo, float hi)
{
    tn_image f = {0, 0, 0, NULL};
    size_t i, n = (size_t)img->width * img->height, k = 0;
    if (tn_fill_depressions(&f, img)) return NAN;
    for (i = 0; i < n; i++) k += f.data[i] - img->data[i] > 0.01f * (hi - lo);
    tn_image_free(&f);
    return (double)k / (double)n;
}

/* Panels at their own pixel size (a 128 example stays 128 px), 4 px apart, hillshaded on lo..hi. */
static void save_strip(const char *path, const tn_image *const *img, int n, float lo, float hi, const double *dxy)
{
    tn_render_opts ro;
    tn_image strip = {0, 0, 0, NULL}, pv = {0, 0, 0, NULL};
    int i, y, W = 0, Hm = 0, x0 = 0;
    memset(&ro, 0, sizeof ro);
    ro.lo = lo;
    ro.hi = hi;
    ro.shade.dx = (float)dxy[0];
    ro.shade.dy = (float)dxy[1];
    for (i = 0; i < n; i++) {
        W += img[i]->width + (i ? 4 : 0);
        if (img[i]->height > Hm) Hm = img[i]->height;
    }
    if (tn_image_create(&strip, W, Hm, 3)) return;
    for (i = 0; i < n; i++) {
        int rgb = img[i]->channels == 3;
        if (rgb || !tn_render_preview(&pv, img[i], &ro))
            for (y = 0; y < img[i]->height; y++)
                memcpy(&TN_PIXEL(&strip, x0, y, 0), &TN_PIXEL(rgb ? img[i] : &pv, 0, y, 0), (size_t)img[i]->width * 3 * sizeof(float));
        tn_image_free(&pv);
        x0 += img[i]->width + 4;
    }
    {
        tn_save_opts so;
        memset(&so, 0, sizeof so);
        so.bit_depth = 8;
        if (!tn_image_save(path, &strip, &so)) printf("picture: %s\n", path);
    }
    tn_image_free(&strip);
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

/* Median |t - its Gaussian of 2 px| within 4 px of rast's valley pixels over the median elsewhere
   (-1 without valleys). */
static double floor_detail(const tn_image *t, const tn_image *rast)
{
    tn_image b = {0, 0, 0, NULL};
    size_t n = (size_t)t->width * t->height, nf = 0, ne = 0, k;
    double *fl = (double *)malloc(n * sizeof(double)), *el = (double *)malloc(n * sizeof(double)), r = -1;
    int x, y, dx, dy;
    if (fl && el && !tn_image_blur(&b, t, 2.0f)) {
        for (y = 0; y < t->height; y++)
            for (x = 0; x < t->width; x++) {
                int nv = 0;
                for (dy = -4; dy <= 4 && !nv; dy++)
                    for (dx = -4; dx <= 4 && !nv; dx++)
                        if (x + dx >= 0 && y + dy >= 0 && x + dx < t->width && y + dy < t->height)
                            nv = rast->data[3 * ((size_t)(y + dy) * t->width + x + dx) + 1] > 0;
                k = (size_t)y * t->width + x;
                if (nv) fl[nf++] = fabs(t->data[k] - b.data[k]);
                else el[ne++] = fabs(t->data[k] - b.data[k]);
            }
        qsort(fl, nf, sizeof(double), cmp_double);
        qsort(el, ne, sizeof(double), cmp_double);
        if (nf && ne && el[ne / 2] > 0) r = fl[nf / 2] / el[ne / 2];
    }
    tn_image_free(&b);
    free(fl);
    free(el);
    return r;
}

#define RELIEF_HALF 8 /* px: the running mean along a line spans 2 x 8 + 1 px */
#define RELIEF_SPAN 6 /* points either side of a line's step over which its flanks' normal is taken */
#define FLANK 6       /* px: a line's flanks are measured this far across it */

/* Bilinear height of img at (x, y), clamped to the map. */
static double height_at(const tn_image *img, double x, double y)
{
    int x0, y0, x1, y1;
    double fx, fy;
    x = x < 0 ? 0 : x > img->width - 1 ? img->width - 1 : x;
    y = y < 0 ? 0 : y > img->height - 1 ? img->height - 1 : y;
    x0 = (int)x, y0 = (int)y;
    x1 = x0 + 1 < img->width ? x0 + 1 : x0, y1 = y0 + 1 < img->height ? y0 + 1 : y0;
    fx = x - x0, fy = y - y0;
    return (1 - fy) * ((1 - fx) * img->data[(size_t)y0 * img->width + x0] + fx * img->data[(size_t)y0 * img->width + x1]) +
           fy * ((1 - fx) * img->data[(size_t)y1 * img->width + x0] + fx * img->data[(size_t)y1 * img->width + x1]);
}

/* Along-line relief: the std of img along set's lines of one kind (sampled every px of their
   length; with off > 0, on both sides of them, off px across: their flanks) minus its running
   mean over 2 x RELIEF_HALF + 1 px along the same path; with mains, only the lines of the highest
   Strahler order of that kind. NAN without such lines. The flanks are read along the normal over
   RELIEF_SPAN points either side, as tn__gnn_grow_flanks reads the example's: an extracted line
   is a pixel chain, and the normal of each of its steps swung the path 6 px off across the slope
   at every turn, which inflated the example's flank relief (docs/gnn.md, stop 70). */
static double line_relief(const tn_image *img, const tn_contour_set *set, int kind, int mains, double off)
{
    int c, j, top = -1;
    double s1 = 0, s2 = 0, n = 0;
    for (c = 0; c < set->count; c++)
        if ((int)set->items[c].type == kind && set->items[c].order > top) top = set->items[c].order;
    for (c = 0; c < set->count; c++) {
        const tn_contour *l = &set->items[c];
        double *h, len = 0;
        int m = 0, cap, i, k, side;
        if ((int)l->type != kind || (mains && l->order != top) || l->npoints < 2) continue;
        for (j = 1; j < l->npoints; j++) len += hypot(l->points[3 * j] - l->points[3 * j - 3], l->points[3 * j + 1] - l->points[3 * j - 2]);
        cap = (int)len + 2;
        if (!(h = (double *)malloc((size_t)cap * sizeof(double)))) continue;
        for (side = off > 0 ? -1 : 1; side <= 1; side += 2) {
            m = 0;
            for (j = 1, len = 0; j < l->npoints; j++) { /* a sample every px of the length; len carries the step over */
                double ax = l->points[3 * j - 3], ay = l->points[3 * j - 2], dx = l->points[3 * j] - ax, dy = l->points[3 * j + 1] - ay;
                int ja = j - 1 - RELIEF_SPAN > 0 ? j - 1 - RELIEF_SPAN : 0, jb = j + RELIEF_SPAN < l->npoints - 1 ? j + RELIEF_SPAN : l->npoints - 1;
                double tx = l->points[3 * jb] - l->points[3 * ja], ty = l->points[3 * jb + 1] - l->points[3 * ja + 1], tl = hypot(tx, ty);
                double sl = hypot(dx, dy), t, nx = tl > 0 ? -ty / tl * side * off : 0, ny = tl > 0 ? tx / tl * side * off : 0;
                for (t = len; t < sl && m < cap; t += 1) h[m++] = height_at(img, ax + dx * t / sl + nx, ay + dy * t / sl + ny);
                len = t - sl;
            }
            for (i = RELIEF_HALF; i + RELIEF_HALF < m; i++) { /* whole windows only: a cut one is off-centre on a slope */
                double mean = 0;
                for (k = i - RELIEF_HALF; k <= i + RELIEF_HALF; k++) mean += h[k];
                mean = h[i] - mean / (2 * RELIEF_HALF + 1);
                s1 += mean, s2 += mean * mean, n++;
            }
        }
        free(h);
    }
    return n > 1 ? sqrt(s2 / n - (s1 / n) * (s1 / n)) : NAN;
}

#define ACROSS 8   /* px: the cross profile of a line spans -8 .. +8 px along its normal */
#define CLEAR 12   /* px: profiles only this far from the line's ends and from every other line */

typedef struct cross_shape {
    double top, seam, spike; /* shares (0..1) and the profile's ratio; NAN without profiles */
    int n;
} cross_shape;

/* Whether point j of line c of the densified set d is read, and its unit tangent (over +-2
   points) in *ux, *uy: it lies `edge` px inside the map and, for a drawn line (!mains), CLEAR px
   from its ends and from every other line. */
static int line_point(const tn_image *img, const tn_contour_set *d, int c, int j, int mains, int edge, double *ux, double *uy)
{
    const tn_contour *l = &d->items[c];
    const float *pt = l->points;
    int a = j - 2 > 0 ? j - 2 : 0, b = j + 2 < l->npoints - 1 ? j + 2 : l->npoints - 1, k, m;
    double x = pt[3 * j], y = pt[3 * j + 1], tx = pt[3 * b] - pt[3 * a], ty = pt[3 * b + 1] - pt[3 * a + 1], len = hypot(tx, ty);
    if (!(len > 0) || x < edge || y < edge || x > img->width - 1 - edge || y > img->height - 1 - edge) return 0;
    if (!mains) {
        if (hypot(x - pt[0], y - pt[1]) < CLEAR || hypot(x - pt[3 * l->npoints - 3], y - pt[3 * l->npoints - 2]) < CLEAR) return 0;
        for (k = 0; k < d->count; k++)
            for (m = 0; k != c && m < d->items[k].npoints; m++)
                if (hypot(x - d->items[k].points[3 * m], y - d->items[k].points[3 * m + 1]) < CLEAR) return 0;
    }
    *ux = tx / len;
    *uy = ty / len;
    return 1;
}

/* The cross profiles of set's lines of one kind (heights negated for valleys, so a floor is a
   top), sampled every 0.5 px from -ACROSS to +ACROSS px along the normal of each px of their
   length (tangent over +-2 points of the densified line), CLEAR px from their ends and from every
   other line of the set; with mains, only the lines of the highest Strahler order of that kind
   (and no clearance from other lines: an extracted network is dense). top: the share whose line
   point is the highest of its profile within 1..3 px; seam: the share with higher ground on both
   sides within 6 px (a groove along a drawn ridge); spike: the mean profile's drop 1 px across
   over a third of its drop 3 px across (1: straight flanks; > 1: a wall of a pixel or two on its
   ground, a thin line in map view; < 1: a rounded top). */
static cross_shape cross_profiles(const tn_image *img, const tn_contour_set *set, int kind, int mains)
{
    enum { NS = 4 * ACROSS + 1, MID = 2 * ACROSS };
    tn_contour_set d;
    cross_shape r;
    double d1 = 0, d3 = 0;
    int c, j, o, top = -1, ntop = 0, nseam = 0;
    r.top = r.seam = r.spike = NAN;
    r.n = 0;
    if (tn_sketch_densify(&d, set)) return r;
    for (c = 0; c < d.count; c++)
        if ((int)d.items[c].type == kind && d.items[c].order > top) top = d.items[c].order;
    for (c = 0; c < d.count; c++) {
        const tn_contour *l = &d.items[c];
        const float *pt = l->points;
        if ((int)l->type != kind || (mains && l->order != top)) continue;
        for (j = 0; j < l->npoints; j++) {
            double x = pt[3 * j], y = pt[3 * j + 1], ux, uy;
            double h[NS], sg = kind == TN_RIDGE ? 1 : -1, lo = -HUGE_VAL, side[2] = {-HUGE_VAL, -HUGE_VAL};
            if (!line_point(img, &d, c, j, mains, ACROSS, &ux, &uy)) continue;
            for (o = 0; o < NS; o++) h[o] = sg * height_at(img, x - uy * (o - MID) * 0.5, y + ux * (o - MID) * 0.5);
            for (o = 2; o <= 6; o++) lo = fmax(lo, fmax(h[MID - o], h[MID + o]));
            for (o = 2; o <= 12; o++) side[0] = fmax(side[0], h[MID - o]), side[1] = fmax(side[1], h[MID + o]);
            ntop += h[MID] >= lo;
            nseam += side[0] > h[MID] && side[1] > h[MID];
            d1 += h[MID] - 0.5 * (h[MID - 2] + h[MID + 2]);
            d3 += h[MID] - 0.5 * (h[MID - 6] + h[MID + 6]);
            r.n++;
        }
    }
    tn_contour_set_free(&d);
    if (r.n) {
        r.top = (double)ntop / r.n;
        r.seam = (double)nseam / r.n;
        r.spike = d3 > 0 ? 3 * d1 / d3 : NAN;
    }
    return r;
}

#define DOMINANCE_R 48 /* px: a line's ground is read out to this far around it (a fifth of a 256 map) */

/* Dominance: how far a line stands over (a valley under) the ground around it. At every px of
   set's lines of one kind (with mains, the highest Strahler order of that kind; drawn lines CLEAR
   px from their ends as cross_profiles, not from other lines), DOMINANCE_R px from the map's
   edge, over the ground 6 to DOMINANCE_R px from it, ground within 4 px of any line read left
   out (a summit's other ridges, a valley's own lower course): share, the mean share of that ground
   lower (higher for a valley); over, the mean height of its highest pixel above the line (its
   lowest below a valley), 0 where none is, in the heights' units. A drawn ridge in higher quilted
   ground reads low: the drawing no longer shapes the map there. NAN without any point. */
typedef struct dominance_t {
    double share, over;
} dominance_t;

static dominance_t dominance(const tn_image *img, const tn_contour_set *set, int kind, int mains)
{
    tn_contour_set d;
    uint8_t *near;
    dominance_t r = {NAN, NAN};
    double s = 0, o = 0;
    int c, j, top = -1, n = 0, W = img->width, H = img->height, R = DOMINANCE_R;
    if (tn_sketch_densify(&d, set)) return r;
    if (!(near = (uint8_t *)calloc((size_t)W * H, 1))) {
        tn_contour_set_free(&d);
        return r;
    }
    for (c = 0; c < d.count; c++)
        if ((int)d.items[c].type == kind && d.items[c].order > top) top = d.items[c].order;
    for (c = 0; c < d.count; c++) /* the ground left out: 4 px around every line read */
        for (j = 0; (int)d.items[c].type == kind && (!mains || d.items[c].order == top) && j < d.items[c].npoints; j++) {
            int x = (int)lrint(d.items[c].points[3 * j]), y = (int)lrint(d.items[c].points[3 * j + 1]), u, v;
            for (v = -4; v <= 4; v++)
                for (u = -4; u <= 4; u++)
                    if (u * u + v * v <= 16 && x + u >= 0 && y + v >= 0 && x + u < W && y + v < H) near[(size_t)(y + v) * W + x + u] = 1;
        }
    for (c = 0; c < d.count; c++) {
        const tn_contour *l = &d.items[c];
        if ((int)l->type != kind || (mains && l->order != top)) continue;
        for (j = 0; j < l->npoints; j++) {
            double x = l->points[3 * j], y = l->points[3 * j + 1], sg = kind == TN_RIDGE ? 1 : -1, h0 = sg * height_at(img, x, y), hi = h0;
            int X = (int)lrint(x), Y = (int)lrint(y), u, v, below = 0, all = 0;
            if (X < R || Y < R || X >= W - R || Y >= H - R) continue;
            if (!mains && (hypot(x - l->points[0], y - l->points[1]) < CLEAR ||
                           hypot(x - l->points[3 * l->npoints - 3], y - l->points[3 * l->npoints - 2]) < CLEAR))
                continue;
            for (v = -R; v <= R; v++)
                for (u = -R; u <= R; u++) {
                    size_t p = (size_t)(Y + v) * W + X + u;
                    double h;
                    if (u * u + v * v < 36 || u * u + v * v > R * R || near[p]) continue;
                    h = sg * img->data[p];
                    below += h < h0, all++;
                    if (h > hi) hi = h;
                }
            if (all) s += (double)below / all, o += hi - h0, n++;
        }
    }
    free(near);
    tn_contour_set_free(&d);
    if (n) r.share = s / n, r.over = o / n;
    return r;
}

#define SHOULDER 12 /* px: a drawn ridge's cross profile is read out to this far on each side */

typedef struct crest_sides {
    double drop[2][SHOULDER + 1]; /* mean drop below the line d = 0 .. SHOULDER px to its left [0] and right [1], m */
    int n;
} crest_sides;

/* The mean cross profile of set's ridges on each side apart (drawn ridges: left and right of
   their drawing direction, on a ring its inside and outside; with mains, the example's main
   ridges, both sides of a line pooled into each), every px of their length as cross_profiles,
   SHOULDER px from the map's edge: the drop below the line d px across, d = 0 .. SHOULDER. */
static crest_sides crest_profile(const tn_image *img, const tn_contour_set *set, int mains)
{
    tn_contour_set d;
    crest_sides r;
    int c, j, o, s, top = -1;
    memset(&r, 0, sizeof r);
    if (tn_sketch_densify(&d, set)) return r;
    for (c = 0; c < d.count; c++)
        if (d.items[c].type == TN_RIDGE && d.items[c].order > top) top = d.items[c].order;
    for (c = 0; c < d.count; c++) {
        const tn_contour *l = &d.items[c];
        const float *pt = l->points;
        if (l->type != TN_RIDGE || (mains && l->order != top)) continue;
        for (j = 0; j < l->npoints; j++) {
            double x = pt[3 * j], y = pt[3 * j + 1], ux, uy, h0;
            if (!line_point(img, &d, c, j, mains, SHOULDER, &ux, &uy)) continue;
            h0 = height_at(img, x, y);
            for (s = 0; s < 2; s++)
                for (o = 1; o <= SHOULDER; o++) {
                    double dr = h0 - height_at(img, x + (s ? uy : -uy) * o, y + (s ? -ux : ux) * o);
                    if (mains) r.drop[0][o] += 0.5 * dr, r.drop[1][o] += 0.5 * dr;
                    else r.drop[s][o] += dr;
                }
            r.n++;
        }
    }
    tn_contour_set_free(&d);
    for (s = 0; s < 2 && r.n; s++)
        for (o = 1; o <= SHOULDER; o++) r.drop[s][o] /= r.n;
    return r;
}

/* The shoulder of a side's mean profile: its drop from 6 to 12 px across over its drop from 0 to 6 px. */
static double crest_shoulder(const crest_sides *p, int s) { return (p->drop[s][SHOULDER] - p->drop[s][SHOULDER / 2]) / p->drop[s][SHOULDER / 2]; }

/* who's crest profile and shoulder per side (against ex's shoulder when ex is not NULL). */
static void crest_profile_print(const char *who, const crest_sides *p, const crest_sides *ex)
{
    int s, o;
    for (s = 0; s < 2; s++) {
        printf("%s_crest_profile_%s:", who, s ? "right" : "left");
        for (o = 1; o <= SHOULDER; o++) printf(" %.2f", p->drop[s][o] / p->drop[s][SHOULDER]);
        printf(" (1..12 px, of %.1f m at 12 px; %d points)\n", p->drop[s][SHOULDER], p->n);
    }
    printf("%s_crest_shoulder: %.2f %.2f (left, right", who, crest_shoulder(p, 0), crest_shoulder(p, 1));
    if (ex) printf("; example %.2f)\n", crest_shoulder(ex, 0));
    else printf(")\n");
}

#define HATCH_N 32   /* px: the along-line windows whose spectrum is read (hop HATCH_N / 2) */
#define HATCH_LO 2   /* px across: the flanks are read from HATCH_LO .. HATCH_HI px off the line, both sides */
#define HATCH_HI 6
#define HATCH_PI 3.14159265358979323846
#define HATCH_BIN_LO 5 /* periods of HATCH_N / 5 = 6.4 px ... */
#define HATCH_BIN_HI 10 /* ... to 3.2 px: a streak of a px or two across a flank */

typedef struct hatch_power {
    double band, total; /* along-line power in periods of 3.2 .. 6.4 px (bins HATCH_BIN_LO .. HATCH_BIN_HI of HATCH_N) and in all */
    double ss;          /* the windows' sum of squared Hann weights, for the band's RMS */
    int windows;
} hatch_power;

/* Chains set's segments of one kind and of order >= min_order end to end (an end within 1.5 px of
   another's), as an extracted network splits its lines at every junction: the chained paths of
   the densified points go into out (xy pairs; starts[k] .. starts[k + 1] is path k). */
static int hatch_chain(const tn_contour_set *d, int kind, int min_order, double **out, int **starts)
{
    int c, n = 0, np = 0, total = 0, *used = (int *)calloc((size_t)d->count + 1, sizeof(int));
    for (c = 0; c < d->count; c++) total += d->items[c].npoints;
    *out = (double *)malloc((size_t)(2 * total + 2) * sizeof(double));
    *starts = (int *)malloc((size_t)(d->count + 2) * sizeof(int));
    for (c = 0; c < d->count; c++) {
        const tn_contour *l = &d->items[c];
        int k, j, grew = 1, s0 = n;
        if (used[c] || (int)l->type != kind || l->order < min_order) continue;
        used[c] = 1;
        (*starts)[np++] = n;
        for (j = 0; j < l->npoints; j++) (*out)[2 * n] = l->points[3 * j], (*out)[2 * n + 1] = l->points[3 * j + 1], n++;
        while (grew) { /* append at the tail, then at the head (the path turned round) */
            grew = 0;
            for (k = 0; k < d->count && !grew; k++) {
                const tn_contour *q = &d->items[k];
                int e, m = q->npoints;
                if (used[k] || (int)q->type != kind || q->order < min_order) continue;
                for (e = 0; e < 2 && !grew; e++) {
                    const float *qe = q->points + (e ? 3 * (m - 1) : 0);
                    int r;
                    if (hypot(qe[0] - (*out)[2 * n - 2], qe[1] - (*out)[2 * n - 1]) > 1.5) continue;
                    for (j = 1; j < m; j++) r = e ? m - 1 - j : j, (*out)[2 * n] = q->points[3 * r], (*out)[2 * n + 1] = q->points[3 * r + 1], n++;
                    used[k] = grew = 1;
                }
            }
            if (!grew && s0 >= 0) { /* reverse the path once and grow its other end */
                int i0 = s0, i1 = n - 1;
                for (; i0 < i1; i0++, i1--) {
                    double tx = (*out)[2 * i0], ty = (*out)[2 * i0 + 1];
                    (*out)[2 * i0] = (*out)[2 * i1], (*out)[2 * i0 + 1] = (*out)[2 * i1 + 1], (*out)[2 * i1] = tx, (*out)[2 * i1 + 1] = ty;
                }
                grew = 1;
                s0 = -1;
            }
        }
    }
    (*starts)[np] = n;
    free(used);
    return np;
}

/* The along-line spectrum of the flanks of set's lines: the drawn lines (mains 0), or the
   example's main lines (mains 1: its ridges and valleys of the two highest Strahler orders of
   each kind, chained end to end, no clearance). Each densified path, its points averaged over 7
   (a pixel chain's staircase would shake its normal), is resampled every px of its length; at
   each point HATCH_LO .. HATCH_HI px off it along the normal on both sides, the height
   (bilinear) makes one sequence per offset. Windows of HATCH_N points (all CLEAR px from the
   line's ends and from every other line when drawn, and HATCH_HI + 2 px inside the map), linear
   trend removed, Hann weighted, add their DFT power to p. */
static void hatch_add(hatch_power *p, const tn_image *img, const tn_contour_set *set, int mains)
{
    tn_contour_set d;
    double *pts = NULL;
    int *starts = NULL, npath = 0, c, j, k, kind, top[2] = {-1, -1};
    if (tn_sketch_densify(&d, set)) return;
    for (c = 0; c < d.count; c++) {
        int t = d.items[c].type == TN_VALLEY;
        if (d.items[c].order > top[t]) top[t] = d.items[c].order;
    }
    for (kind = 0; kind < 2; kind++) {
        int tk = kind ? TN_VALLEY : TN_RIDGE;
        if (mains) npath = hatch_chain(&d, tk, top[kind] - 1, &pts, &starts);
        else { /* each drawn line its own path */
            int total = 0;
            for (c = 0; c < d.count; c++) total += d.items[c].npoints;
            pts = (double *)malloc((size_t)(2 * total + 2) * sizeof(double));
            starts = (int *)malloc((size_t)(d.count + 2) * sizeof(int));
            for (c = 0, npath = 0, total = 0; c < d.count; c++) {
                if ((int)d.items[c].type != tk) continue;
                starts[npath++] = total;
                for (j = 0; j < d.items[c].npoints; j++) pts[2 * total] = d.items[c].points[3 * j], pts[2 * total + 1] = d.items[c].points[3 * j + 1], total++;
            }
            starts[npath] = total;
        }
        for (c = 0; c < npath; c++) {
            const double *lp = pts + 2 * starts[c];
            int n = starts[c + 1] - starts[c], m = 0, i, side, off, cap;
            double *sx, *sy, *px, *py, *nx, *ny, len = 0;
            char *ok;
            if (n < HATCH_N) continue;
            sx = (double *)malloc((size_t)n * 2 * sizeof(double)), sy = sx + n;
            for (j = 0; j < n; j++) { /* the chain averaged over 7 points */
                int a = j - 3 > 0 ? j - 3 : 0, b = j + 3 < n - 1 ? j + 3 : n - 1;
                sx[j] = sy[j] = 0;
                for (k = a; k <= b; k++) sx[j] += lp[2 * k], sy[j] += lp[2 * k + 1];
                sx[j] /= b - a + 1, sy[j] /= b - a + 1;
            }
            for (j = 1; j < n; j++) len += hypot(sx[j] - sx[j - 1], sy[j] - sy[j - 1]);
            cap = (int)len + 2;
            px = (double *)malloc((size_t)cap * 4 * sizeof(double)), py = px + cap, nx = py + cap, ny = nx + cap;
            ok = (char *)malloc((size_t)cap);
            for (j = 1, len = 0; j < n; j++) { /* a point every px of the length, the normal of its segment */
                double ax = sx[j - 1], ay = sy[j - 1], dx = sx[j] - ax, dy = sy[j] - ay, sl = hypot(dx, dy), t;
                if (!(sl > 0)) continue;
                for (t = len; t < sl && m < cap; t += 1) px[m] = ax + dx * t / sl, py[m] = ay + dy * t / sl, nx[m] = -dy / sl, ny[m] = dx / sl, m++;
                len = t - sl;
            }
            for (i = 0; i < m; i++) {
                int near = px[i] < HATCH_HI + 2 || py[i] < HATCH_HI + 2 || px[i] > img->width - 3 - HATCH_HI || py[i] > img->height - 3 - HATCH_HI;
                if (!mains) {
                    near |= i < CLEAR || i >= m - CLEAR;
                    for (k = 0; k < d.count && !near; k++) {
                        int q;
                        const double *own = lp;
                        if (d.items[k].npoints == n && d.items[k].points[0] == own[0] && d.items[k].points[1] == own[1]) continue; /* the line itself */
                        for (q = 0; q < d.items[k].npoints && !near; q++) near = hypot(px[i] - d.items[k].points[3 * q], py[i] - d.items[k].points[3 * q + 1]) < CLEAR;
                    }
                }
                ok[i] = !near;
            }
            for (i = 0; i + HATCH_N <= m; i += HATCH_N / 2) {
                int good = 1;
                for (j = i; j < i + HATCH_N && good; j++) good = ok[j];
                if (!good) continue;
                for (side = -1; side <= 1; side += 2)
                    for (off = HATCH_LO; off <= HATCH_HI; off++) {
                        double h[HATCH_N], mt = 0, mh = 0, sth = 0, stt = 0, slope;
                        int f;
                        for (j = 0; j < HATCH_N; j++) {
                            h[j] = height_at(img, px[i + j] + side * off * nx[i + j], py[i + j] + side * off * ny[i + j]);
                            mt += j, mh += h[j];
                        }
                        mt /= HATCH_N, mh /= HATCH_N;
                        for (j = 0; j < HATCH_N; j++) sth += (j - mt) * (h[j] - mh), stt += (j - mt) * (j - mt);
                        slope = sth / stt;
                        for (j = 0; j < HATCH_N; j++) {
                            double w = 0.5 - 0.5 * cos(2 * HATCH_PI * (j + 0.5) / HATCH_N);
                            h[j] = (h[j] - mh - slope * (j - mt)) * w;
                            p->ss += w * w;
                        }
                        for (f = 1; f <= HATCH_N / 2; f++) {
                            double re = 0, im = 0, pw;
                            for (j = 0; j < HATCH_N; j++) {
                                re += h[j] * cos(2 * HATCH_PI * f * j / HATCH_N);
                                im -= h[j] * sin(2 * HATCH_PI * f * j / HATCH_N);
                            }
                            pw = (re * re + im * im) * (f < HATCH_N / 2 ? 2 : 1) / HATCH_N;
                            p->total += pw;
                            if (f >= HATCH_BIN_LO && f <= HATCH_BIN_HI) p->band += pw;
                        }
                        p->windows++;
                    }
            }
            free(sx), free(px), free(ok);
        }
        free(pts), free(starts);
        pts = NULL, starts = NULL;
    }
    tn_contour_set_free(&d);
}

/* The share of the flanks' along-line power in periods of 3.2 .. 6.4 px, and that band's RMS. */
static double hatch_share(const hatch_power *p) { return p->total > 0 ? p->band / p->total : NAN; }
static double hatch_rms(const hatch_power *p) { return p->ss > 0 ? sqrt(p->band / p->ss) : NAN; }

#define DEEP 16   /* px: a valley's cross profile is read out to its banks this far across */
#define JOIN 3    /* px: an extracted valley ends on a line within this */

typedef struct valley_shape {
    double rise[5];          /* mean depth below the banks 1, 2, 4, 8, 16 px across, m */
    double width_cv, depth_cv; /* along the lines: std / mean of the half-depth width and of the depth 16 px across */
    double junctions;        /* tributaries ending on the lines, per 100 px of their length */
    int n;                   /* profiles read; 0: none */
} valley_shape;

static const int valley_at[5] = {1, 2, 4, 8, 16};

/* The valley figures of set's valleys (drawn valleys; with mains, the example's main valleys, the
   highest Strahler order, no clearance): at each px of their length (CLEAR px from their ends and
   from every other line of the set when drawn), the depth below the banks d px across, r(d) = the
   mean of the heights d px either side along the normal less the height on the line, for d = 0.5
   .. DEEP px every 0.5 px; rise[] the means of r at 1, 2, 4, 8, 16 px; width: the first d at which
   r reaches half of r(DEEP) (points with r(DEEP) > 0); depth: r(DEEP). Junctions: the valleys of
   tn_extract on img itself (the example's threshold in cells, thr) with one end within JOIN px of
   a line of the set and the other farther than 3 JOIN px from all of them (a tributary, not a piece
   of the line), per 100 px of the lines' length. */
static valley_shape valley_profiles(const tn_image *img, const tn_contour_set *set, int mains, int thr)
{
    enum { NS = 2 * DEEP + 1 };
    tn_contour_set d;
    valley_shape r;
    double s1w = 0, s2w = 0, s1d = 0, s2d = 0, length = 0;
    int c, j, k, m, o, top = -1, nw = 0;
    memset(&r, 0, sizeof r);
    for (k = 0; k < 5; k++) r.rise[k] = NAN;
    r.width_cv = r.depth_cv = r.junctions = NAN;
    if (tn_sketch_densify(&d, set)) return r;
    for (c = 0; c < d.count; c++)
        if (d.items[c].type == TN_VALLEY && d.items[c].order > top) top = d.items[c].order;
    for (k = 0; k < 5; k++) r.rise[k] = 0;
    for (c = 0; c < d.count; c++) {
        const tn_contour *l = &d.items[c];
        const float *pt = l->points;
        if (l->type != TN_VALLEY || (mains && l->order != top)) continue;
        for (j = 1; j < l->npoints; j++) length += hypot(pt[3 * j] - pt[3 * j - 3], pt[3 * j + 1] - pt[3 * j - 2]);
        for (j = 0; j < l->npoints; j++) {
            double x = pt[3 * j], y = pt[3 * j + 1], ux, uy;
            double h0, rr[NS], w = NAN;
            if (!line_point(img, &d, c, j, mains, DEEP, &ux, &uy)) continue;
            h0 = height_at(img, x, y);
            rr[0] = 0;
            for (o = 1; o < NS; o++) {
                double t = 0.5 * o;
                rr[o] = 0.5 * (height_at(img, x - uy * t, y + ux * t) + height_at(img, x + uy * t, y - ux * t)) - h0;
            }
            for (k = 0; k < 5; k++) r.rise[k] += rr[2 * valley_at[k]];
            s1d += rr[NS - 1], s2d += rr[NS - 1] * rr[NS - 1];
            for (o = 1; o < NS && rr[NS - 1] > 0 && w != w; o++)
                if (rr[o] >= 0.5 * rr[NS - 1]) w = 0.5 * (o - 1) + 0.5 * (0.5 * rr[NS - 1] - rr[o - 1]) / (rr[o] - rr[o - 1]);
            if (w == w) s1w += w, s2w += w * w, nw++;
            r.n++;
        }
    }
    if (r.n) {
        for (k = 0; k < 5; k++) r.rise[k] /= r.n;
        s1d /= r.n, s2d /= r.n;
        r.depth_cv = s1d != 0 ? sqrt(fmax(0, s2d - s1d * s1d)) / fabs(s1d) : NAN;
    } else
        for (k = 0; k < 5; k++) r.rise[k] = NAN;
    if (nw > 1) s1w /= nw, s2w /= nw, r.width_cv = sqrt(fmax(0, s2w - s1w * s1w)) / s1w;
    { /* tributaries from the terrain's own network */
        tn_extract_opts eo;
        tn_extraction e;
        int nj = 0;
        memset(&eo, 0, sizeof eo);
        eo.threshold = thr;
        eo.which = TN_EXTRACT_VALLEYS;
        if (length > 0 && !tn_extract(&e, img, &eo)) {
            for (c = 0; c < e.contours.count; c++) {
                const tn_contour *t = &e.contours.items[c];
                double dd[2] = {HUGE_VAL, HUGE_VAL};
                int end;
                if (t->type != TN_VALLEY || t->npoints < 2) continue;
                for (end = 0; end < 2; end++) {
                    const float *q = t->points + (end ? 3 * (t->npoints - 1) : 0);
                    for (k = 0; k < d.count; k++)
                        for (m = 0; d.items[k].type == TN_VALLEY && (!mains || d.items[k].order == top) && m < d.items[k].npoints; m++)
                            dd[end] = fmin(dd[end], hypot(q[0] - d.items[k].points[3 * m], q[1] - d.items[k].points[3 * m + 1]));
                }
                nj += (dd[0] <= JOIN && dd[1] > 3 * JOIN) || (dd[1] <= JOIN && dd[0] > 3 * JOIN);
            }
            tn_extraction_free(&e);
            r.junctions = 100.0 * nj / length;
        }
    }
    tn_contour_set_free(&d);
    return r;
}

/* The profile distance: the mean over 1, 2, 4, 8 px of |a's rise over its rise at DEEP px - b's|. */
static double valley_profile_distance(const valley_shape *a, const valley_shape *b)
{
    double s = 0;
    int k;
    for (k = 0; k < 4; k++) s += fabs(a->rise[k] / a->rise[4] - b->rise[k] / b->rise[4]);
    return s / 4;
}

/* who's valley figures (against ex's when ex is not NULL); crops: v is a mean of that many crops' normalised figures. */
static void valley_print(const char *who, const valley_shape *v, const valley_shape *ex, int crops)
{
    printf("%s_floor_profile: %.2f %.2f %.2f %.2f 1 (1, 2, 4, 8, 16 px; ", who, v->rise[0] / v->rise[4], v->rise[1] / v->rise[4], v->rise[2] / v->rise[4],
           v->rise[3] / v->rise[4]);
    if (crops) printf("the mean of %d crops)\n", crops);
    else printf("of %.1f m at 16 px; %d points)\n", v->rise[4], v->n);
    if (ex) printf("%s_floor_profile_distance: %.3f\n", who, valley_profile_distance(v, ex));
    printf("%s_floor_width_cv: %.2f%s", who, v->width_cv, ex ? "" : "\n");
    if (ex) printf(" (%.2f x example)\n", v->width_cv / ex->width_cv);
    printf("%s_floor_depth_cv: %.2f%s", who, v->depth_cv, ex ? "" : "\n");
    if (ex) printf(" (%.2f x example)\n", v->depth_cv / ex->depth_cv);
    printf("%s_floor_junctions: %.2f per 100 px%s", who, v->junctions, ex ? "" : "\n");
    if (ex) printf(" (%.2f x example)\n", v->junctions / ex->junctions);
}

/* The drawing at N x N the new way, with the map-scale level and without it (big=N). */
static void big_map(const char *name, const tn_gnn *model, const tn_contour_set *sk, const tn_contour_set *asked, int N, const tn_image *ex,
                    const double *real, uint64_t seed)
{
    tn_image rast = {0, 0, 0, NULL};
    int level;
    if (tn_sketch_rasterise(&rast, asked, N, N)) return;
    for (level = 0; level < 2; level++) {
        tn_gnn_generate_opts o;
        tn_gnn_plan plan;
        tn_image t = {0, 0, 0, NULL};
        const char *lv = level ? "one_level" : "map_scale";
        double t0 = tn_time_seconds(), share = 0, err = 0, secs;
        size_t q, nq = 0;
        memset(&o, 0, sizeof o);
        o.seed = seed;
        o.map_scale = level ? -1 : 0;
        if (tn_gnn_plan_of(&plan, model, sk, N, N, &o) || tn_gnn_generate(&t, model, sk, N, N, &o)) {
            printf("%s_%d_%s: failed (%s)\n", name, N, lv, tn_last_error());
            continue;
        }
        secs = tn_time_seconds() - t0;
        tn_gnn_ordering(&share, sk, &t, 4, NULL);
        for (q = 0; q < (size_t)N * N; q++)
            if (rast.data[3 * q] > 0 || rast.data[3 * q + 1] > 0) err += fabs(t.data[q] - rast.data[3 * q + 2]), nq++;
        printf("%s_%d_%s: factor %d (example floor_detail %.2f); seconds %.2f; follow %.1f %%; height_error %.2f %% of range; floor_detail %.2f\n",
               name, N, lv, plan.map_scale, (double)plan.floor_detail, secs, 100 * share, 100 * err / (nq ? nq : 1) / (model->hi - model->lo),
               floor_detail(&t, &rast));
        if (N >= 512) { /* 9 windows of 256 px inside the map's middle 3/4, as the real crops are measured */
            double m[3] = {0, 0, 0}, dist[3];
            int i, j, nw = 0, span = N * 3 / 4 - 256;
            for (j = 0; j < 3; j++)
                for (i = 0; i < 3; i++) {
                    tn_image c = {0, 0, 0, NULL};
                    if (tn_image_crop(&c, &t, N / 8 + i * span / 2, N / 8 + j * span / 2, 256, 256)) continue;
                    distances(ex, &c, dist);
                    m[0] += dist[0], m[1] += dist[1], m[2] += dist[2], nw++;
                    tn_image_free(&c);
                }
            for (i = 0; i < 3 && nw; i++) m[i] /= nw;
            printf("%s_%d_%s_windows: slope %.4f (%.2f x real) curvature %.4f (%.2f x real) spectrum %.4f (%.2f x real)\n", name, N, lv, m[0],
                   m[0] / real[0], m[1], m[1] / real[1], m[2], m[2] / real[2]);
        }
        fflush(stdout);
        tn_image_free(&t);
    }
    tn_image_free(&rast);
}

int main(int argc, char **argv)
{
    static const char *all[16] = {"valley", "summit", "ring", "cross"};
    static char names[512];
    static const char *way[] = {"membrane", "today", "random48", "new", "grown_membrane", "grown_nodetail"};
    const char *region, *model_path, *pictures = NULL, *from = "examples/data";
    double dxy[2], h0, h1, real[3] = {0, 0, 0}, real_s[3] = {0, 0, 0}, real_peaks = 0, pk, real_lines[2] = {0, 0}, real_blob = 0, real_fall = 0, ln[2], bl, fr, ex_relief[4] = {NAN, NAN, NAN, NAN};
    static const char *relief_name[] = {"crest", "floor", "crest_flank", "floor_flank"}, *shape_name[] = {"crest", "floor"};
    tn_image full = {0, 0, 0, NULL}, ex = {0, 0, 0, NULL}, ex_s = {0, 0, 0, NULL};
    float coarse;
    tn_gnn model;
    dominance_t real_dom[2] = {{0, 0}, {0, 0}};
    int ndom[2] = {0, 0};
    valley_shape ex_valley, real_valley;
    double real_deep = 0; /* the real crops' mean floor depth at 16 px, m */
    hatch_power ex_hatch, real_hatch;
    crest_sides ex_crest;
    uint64_t seed = 1;
    int ex_thr, threads = 1, finetune = 0, ndrawings = 4, a, d, w, ex_x = 0, ex_y = 0, nreal = 0, k, big = 0;
    if (argc < 3) {
        fprintf(stderr, "usage: bench_sketch REGION MODEL.tnw [threads] [finetune=N] [pictures=DIR] [drawings=a,b] [from=DIR] [big=N] [seed=S]\n");
        return 2;
    }
    region = argv[1];
    model_path = argv[2];
    for (a = 3; a < argc; a++) {
        if (!strncmp(argv[a], "finetune=", 9)) finetune = atoi(argv[a] + 9);
        else if (!strncmp(argv[a], "pictures=", 9)) pictures = argv[a] + 9;
        else if (!strncmp(argv[a], "drawings=", 9)) { /* names, comma-separated */
            char *t;
            strncpy(names, argv[a] + 9, sizeof names - 1);
            for (ndrawings = 0, t = strtok(names, ","); t && ndrawings < 16; t = strtok(NULL, ",")) all[ndrawings++] = t;
        } else if (!strncmp(argv[a], "from=", 5))
            from = argv[a] + 5;
        else if (!strncmp(argv[a], "big=", 4)) big = atoi(argv[a] + 4);
        else if (!strncmp(argv[a], "seed=", 5)) seed = strtoull(argv[a] + 5, NULL, 10);
        else threads = atoi(argv[a]);
    }
    tn_set_threads(threads);
    ex_thr = tn_extract_default_threshold(128, 128);
    memset(&real_valley, 0, sizeof real_valley);
    memset(&ex_hatch, 0, sizeof ex_hatch);
    memset(&real_hatch, 0, sizeof real_hatch);
    if (!height_mapping(region, dxy, &h0, &h1) || !load_metres(region, "full", h0, h1, &full) || !load_metres(region, "128", h0, h1, &ex) ||
        !locate(&full, &ex, &ex_x, &ex_y)) {
        fprintf(stderr, "bench_sketch: %s: data not found under %s\n", region, data_dir());
        return 1;
    }
    if (dxy[0] <= 0) dxy[0] = dxy[1] = 1; /* no spacing recorded: 1 per pixel */
    height_step(&full);
    if (tn_gnn_load(&model, model_path)) {
        fprintf(stderr, "bench_sketch: %s: %s\n", model_path, tn_last_error());
        return 1;
    }
    memset(&ropts, 0, sizeof ropts);
    ropts.dx_a = (float)dxy[0];
    ropts.dy_a = (float)dxy[1];
    printf("region: %s\nexample: 128 x 128 at (%d, %d), %.6g .. %.6g m\nmodel: %s (%ld iterations)\nthreads: %d\nfinetune: %d\n", region, ex_x, ex_y,
           (double)model.lo, (double)model.hi, model_path, model.iterations, threads, finetune);
    printf("height_step: %.6g m (the DEM's smallest gap between heights; peaks counts a terrain on that grid)\n", g_step);
    coarse = tn_image_height_step(&ex, 1);
    if (coarse > 0) { /* judged without the steps too, as the model was trained (docs/gnn.md) */
        tn_image_dequantize(&ex_s, &ex, coarse);
        printf("coarse_step: %.6g m (the example is stored in steps coarse against its curvature: gnn-train learns it without them; "
               "the _smooth lines compare with the example and the real crops without them)\n", (double)coarse);
    }
    /* the three real 256 crops of the DEM's corners farthest from the example */
    {
        int cx[4] = {0, full.width - 256, 0, full.width - 256}, cy[4] = {0, 0, full.height - 256, full.height - 256}, used[4] = {0, 0, 0, 0};
        for (k = 0; k < 3; k++) {
            int best = -1, i;
            double bd = -1;
            for (i = 0; i < 4; i++) {
                double dd = hypot(cx[i] + 128 - (ex_x + 64), cy[i] + 128 - (ex_y + 64));
                if (!used[i] && dd > bd) bd = dd, best = i;
            }
            used[best] = 1;
            {
                tn_image c = {0, 0, 0, NULL};
                double dist[3];
                if (tn_image_crop(&c, &full, cx[best], cy[best], 256, 256)) continue;
                distances(&ex, &c, dist);
                { /* the crop's own main valleys, a larger sample of the DEM's valleys than the example's 128 px */
                    tn_extract_opts eo;
                    tn_extraction e;
                    memset(&eo, 0, sizeof eo);
                    eo.threshold = ex_thr;
                    if (!tn_extract(&e, &c, &eo)) {
                        valley_shape v = valley_profiles(&c, &e.contours, 1, ex_thr);
                        hatch_add(&real_hatch, &c, &e.contours, 1);
                        {
                            int kd;
                            for (kd = 0; kd < 2; kd++) {
                                dominance_t dm = dominance(&c, &e.contours, kd ? TN_VALLEY : TN_RIDGE, 1);
                                if (dm.share == dm.share) real_dom[kd].share += dm.share, real_dom[kd].over += dm.over, ndom[kd]++;
                            }
                        }
                        int q;
                        if (v.n) {
                            for (q = 0; q < 5; q++) real_valley.rise[q] += v.rise[q] / v.rise[4];
                            real_deep += v.rise[4];
                            real_valley.width_cv += v.width_cv, real_valley.depth_cv += v.depth_cv, real_valley.junctions += v.junctions;
                            real_valley.n++;
                        }
                        tn_extraction_free(&e);
                    }
                }
                pk = peaks(&c);
                real_peaks += pk;
                long_lines(&c, ln);
                bl = blobness(&c);
                fr = fall_ratio(&c);
                real_lines[0] += ln[0], real_lines[1] += ln[1], real_blob += bl, real_fall += fr;
                printf("real_crop_%d_lines: valleys %.2f ridges %.2f; blobness %.3f; fall_ratio %.3f\n", k, ln[0], ln[1], bl, fr);
                printf("real_crop_%d: (%d, %d) slope %.4f curvature %.4f spectrum %.4f basins %.1f %% peaks %.1f per 10^4 px\n", k, cx[best], cy[best], dist[0],
                       dist[1], dist[2], 100 * basins(&c, model.lo, model.hi), pk);
                real[0] += dist[0], real[1] += dist[1], real[2] += dist[2], nreal++;
                if (coarse > 0) {
                    tn_image cs = {0, 0, 0, NULL};
                    tn_image_dequantize(&cs, &c, coarse);
                    distances(&ex_s, &cs, dist);
                    real_s[0] += dist[0], real_s[1] += dist[1], real_s[2] += dist[2];
                    tn_image_free(&cs);
                }
                tn_image_free(&c);
            }
        }
        for (k = 0; k < 3; k++) real[k] /= nreal;
        real_peaks /= nreal;
        printf("real_peaks: %.1f per 10^4 px (the real crops' mean; the example's 128 px: %.1f)\n", real_peaks, peaks(&ex));
        real_lines[0] /= nreal, real_lines[1] /= nreal, real_blob /= nreal, real_fall /= nreal;
        long_lines(&ex, ln);
        printf("real_lines: valleys %.2f ridges %.2f; blobness %.3f; fall_ratio %.3f (the real crops' mean; the example's 128 px: %.2f %.2f; %.3f; %.3f)\n",
               real_lines[0], real_lines[1], real_blob, real_fall, ln[0], ln[1], blobness(&ex), fall_ratio(&ex));
        if (real_valley.n) { /* the mean over the crops of their normalised profiles and figures */
            for (k = 0; k < 5; k++) real_valley.rise[k] /= real_valley.n;
            real_valley.width_cv /= real_valley.n, real_valley.depth_cv /= real_valley.n, real_valley.junctions /= real_valley.n;
            valley_print("real", &real_valley, NULL, real_valley.n);
            real_deep /= real_valley.n;
            printf("real_floor_depth: %.1f m at 16 px (the mean of %d crops' main valleys)\n", real_deep, real_valley.n);
        }
        printf("real_mean: slope %.4f curvature %.4f spectrum %.4f\n", real[0], real[1], real[2]);
        for (k = 0; k < 2; k++) {
            if (ndom[k]) real_dom[k].share /= ndom[k], real_dom[k].over /= ndom[k];
            else real_dom[k].share = real_dom[k].over = NAN;
            printf("real_%s_dominance: %.1f %%; over %.2f %% of range (the crops' main %s: the share of the ground 6-%d px around them %s, and how far "
                   "its %s pixel %s them)\n",
                   shape_name[k], 100 * real_dom[k].share, 100 * real_dom[k].over / (model.hi - model.lo), k ? "valleys" : "ridges", DOMINANCE_R,
                   k ? "above a valley" : "below a ridge", k ? "lowest" : "highest", k ? "lies below" : "tops");
        }
        if (coarse > 0) {
            for (k = 0; k < 3; k++) real_s[k] /= nreal;
            printf("real_mean_smooth: slope %.4f curvature %.4f spectrum %.4f (all without their height steps)\n", real_s[0], real_s[1], real_s[2]);
        }
        printf("real_hatch: %.2f m in periods of 3.2-6.4 px along the main lines' flanks (%.1f %% of the power; %d windows)\n",
               hatch_rms(&real_hatch), 100 * hatch_share(&real_hatch), real_hatch.windows);
    }
    { /* the example's own along-line relief and cross profiles on its main ridges and valleys (tn_extract) */
        tn_extraction e;
        cross_shape cs[2];
        cs[0].n = cs[1].n = 0;
        ex_valley.n = 0;
        ex_crest.n = 0;
        if (!tn_extract(&e, &ex, NULL)) {
            for (k = 0; k < 4; k++) ex_relief[k] = line_relief(&ex, &e.contours, k & 1 ? TN_VALLEY : TN_RIDGE, 1, k < 2 ? 0 : FLANK);
            for (k = 0; k < 2; k++) cs[k] = cross_profiles(&ex, &e.contours, k ? TN_VALLEY : TN_RIDGE, 1);
            ex_valley = valley_profiles(&ex, &e.contours, 1, ex_thr);
            hatch_add(&ex_hatch, &ex, &e.contours, 1);
            ex_crest = crest_profile(&ex, &e.contours, 1);
            tn_extraction_free(&e);
        }
        for (k = 0; k < 4; k++) printf("example_%s_relief: %.2f m (main %s)\n", relief_name[k], ex_relief[k], k & 1 ? "valleys" : "ridges");
        if (ex_valley.n) valley_print("example", &ex_valley, NULL, 0);
        if (ex_crest.n) crest_profile_print("example", &ex_crest, NULL);
        printf("example_hatch: %.2f m in periods of 3.2-6.4 px along the main lines' flanks (%.1f %% of the power; %d windows)\n",
               hatch_rms(&ex_hatch), 100 * hatch_share(&ex_hatch), ex_hatch.windows);
        for (k = 0; k < 2; k++)
            if (cs[k].n)
                printf("example_%s_top: %.1f %%; %s_seam: %.1f %%; %s_spike: %.2f (main %s, %d points)\n", shape_name[k], 100 * cs[k].top, shape_name[k],
                       100 * cs[k].seam, shape_name[k], cs[k].spike, k ? "valleys" : "ridges", cs[k].n);
    }
    for (d = 0; d < ndrawings; d++) {
        char path[512];
        tn_contour_set sk, asked;
        tn_image out[6], rast = {0, 0, 0, NULL}, drawing = {0, 0, 0, NULL};
        snprintf(path, sizeof path, "%s/sketch_%s.tns", from, all[d]);
        if (tn_sketch_load(&sk, path)) {
            fprintf(stderr, "bench_sketch: %s\n", tn_last_error());
            continue;
        }
        asked = sk; /* heights 0..1 -> the example's range, for the height error */
        asked.items = (tn_contour *)calloc((size_t)sk.count, sizeof(tn_contour));
        for (k = 0; k < sk.count; k++) {
            int j;
            asked.items[k] = sk.items[k];
            asked.items[k].points = (float *)malloc((size_t)sk.items[k].npoints * 3 * sizeof(float));
            for (j = 0; j < sk.items[k].npoints; j++) {
                asked.items[k].points[3 * j] = sk.items[k].points[3 * j];
                asked.items[k].points[3 * j + 1] = sk.items[k].points[3 * j + 1];
                asked.items[k].points[3 * j + 2] = model.lo + (model.hi - model.lo) * sk.items[k].points[3 * j + 2];
            }
        }
        tn_sketch_rasterise(&rast, &asked, 256, 256);
        for (w = 0; w < 6; w++) {
            tn_gnn_generate_opts o;
            tn_gnn_plan plan;
            double t0 = tn_time_seconds(), share = 0, err = 0, bias = 0, dist[3], secs;
            size_t q, nq = 0;
            int cnt = 0;
            tn_status st;
            memset(&out[w], 0, sizeof out[w]);
            memset(&o, 0, sizeof o);
            memset(&plan, 0, sizeof plan);
            o.seed = seed;
            o.finetune = w == 0 ? 0 : finetune;
            o.grow = w >= 3 ? 0 : -1;
            o.detail = w >= 4 ? -1 : 0;
            o.random_nodes = w == 2 ? 48 : 0;
            if (w == 0) st = tn_gnn_membrane(&out[w], &asked, 256, 256);
            else {
                st = tn_gnn_plan_of(&plan, &model, &sk, 256, 256, &o);
                if (!st) {
                    o.gain = w == 4 || plan.gain <= 0 ? -1.0f : plan.gain;
                    st = tn_gnn_generate(&out[w], &model, &sk, 256, 256, &o);
                }
            }
            secs = tn_time_seconds() - t0;
            if (st) {
                printf("%s_%s: failed (%s)\n", all[d], way[w], tn_last_error());
                continue;
            }
            tn_gnn_ordering(&share, &sk, &out[w], 4, &cnt);
            for (q = 0; q < (size_t)256 * 256; q++)
                if (rast.data[3 * q] > 0 || rast.data[3 * q + 1] > 0) err += fabs(out[w].data[q] - rast.data[3 * q + 2]), bias += out[w].data[q] - rast.data[3 * q + 2], nq++;
            distances(&ex, &out[w], dist);
            printf("%s_%s_follow: %.1f %%\n", all[d], way[w], 100 * share);
            printf("%s_%s_height_error: %.2f %% of range\n", all[d], way[w], 100 * err / (nq ? nq : 1) / (model.hi - model.lo));
            printf("%s_%s_height_bias: %+.2f %% of range\n", all[d], way[w], 100 * bias / (nq ? nq : 1) / (model.hi - model.lo));
            printf("%s_%s_slope: %.4f (%.2f x real)\n", all[d], way[w], dist[0], dist[0] / real[0]);
            printf("%s_%s_curvature: %.4f (%.2f x real)\n", all[d], way[w], dist[1], dist[1] / real[1]);
            printf("%s_%s_spectrum: %.4f (%.2f x real)\n", all[d], way[w], dist[2], dist[2] / real[2]);
            if (coarse > 0) {
                distances(&ex_s, &out[w], dist);
                printf("%s_%s_smooth: slope %.4f (%.2f x real) curvature %.4f (%.2f x real) spectrum %.4f (%.2f x real)\n", all[d], way[w], dist[0],
                       dist[0] / real_s[0], dist[1], dist[1] / real_s[1], dist[2], dist[2] / real_s[2]);
            }
            printf("%s_%s_basins: %.1f %% of the map\n", all[d], way[w], 100 * basins(&out[w], model.lo, model.hi));
            {
                float lo, hi, band = 0.1f * (model.hi - model.lo);
                size_t beyond = 0;
                tn_image_range(&lo, &hi, &out[w]);
                for (q = 0; q < (size_t)256 * 256; q++) beyond += out[w].data[q] < model.lo - band || out[w].data[q] > model.hi + band;
                printf("%s_%s_heights: %.0f..%.0f m (the example's %.0f..%.0f m; %.1f %% of the map beyond it by more than 10 %% of its range)\n", all[d],
                       way[w], (double)lo, (double)hi, (double)model.lo, (double)model.hi, 100.0 * (double)beyond / (256.0 * 256.0));
            }
            pk = peaks(&out[w]);
            printf("%s_%s_peaks: %.1f per 10^4 px (%.2f x real)\n", all[d], way[w], pk, pk / real_peaks);
            long_lines(&out[w], ln);
            bl = blobness(&out[w]);
            printf("%s_%s_lines: valleys %.2f ridges %.2f (%.2f %.2f x real); blobness %.3f (%.2f x real)\n", all[d], way[w], ln[0], ln[1],
                   ln[0] / real_lines[0], ln[1] / real_lines[1], bl, bl / real_blob);
            fr = fall_ratio(&out[w]);
            printf("%s_%s_fall_ratio: %.3f (%.2f x real)\n", all[d], way[w], fr, fr / real_fall);
            for (k = 0; k < 4; k++) {
                double r = line_relief(&out[w], &asked, k & 1 ? TN_VALLEY : TN_RIDGE, 0, k < 2 ? 0 : FLANK);
                if (r == r) printf("%s_%s_%s_relief: %.2f m (%.2f x example)\n", all[d], way[w], relief_name[k], r, r / ex_relief[k]);
            }
            for (k = 0; k < 2; k++) {
                dominance_t dm = dominance(&out[w], &asked, k ? TN_VALLEY : TN_RIDGE, 0);
                if (dm.share == dm.share)
                    printf("%s_%s_%s_dominance: %.1f %% (real %.1f %%); over %.2f %% of range (real %.2f %%)\n", all[d], way[w], shape_name[k], 100 * dm.share,
                           100 * real_dom[k].share, 100 * dm.over / (model.hi - model.lo), 100 * real_dom[k].over / (model.hi - model.lo));
            }
            for (k = 0; k < 2; k++) {
                cross_shape cs = cross_profiles(&out[w], &asked, k ? TN_VALLEY : TN_RIDGE, 0);
                if (cs.n)
                    printf("%s_%s_%s_top: %.1f %%\n%s_%s_%s_seam: %.1f %%\n%s_%s_%s_spike: %.2f\n", all[d], way[w], shape_name[k], 100 * cs.top, all[d], way[w],
                           shape_name[k], 100 * cs.seam, all[d], way[w], shape_name[k], cs.spike);
            }
            {
                hatch_power hp;
                memset(&hp, 0, sizeof hp);
                hatch_add(&hp, &out[w], &asked, 0);
                if (hp.windows)
                    printf("%s_%s_hatch: %.2f m (%.2f x example, %.2f x real; %.1f %% of the power)\n", all[d], way[w], hatch_rms(&hp),
                           hatch_rms(&hp) / hatch_rms(&ex_hatch), hatch_rms(&hp) / hatch_rms(&real_hatch), 100 * hatch_share(&hp));
            }
            {
                valley_shape vs = valley_profiles(&out[w], &asked, 0, ex_thr);
                crest_sides cp = crest_profile(&out[w], &asked, 0);
                char who[64];
                snprintf(who, sizeof who, "%s_%s", all[d], way[w]);
                if (cp.n) crest_profile_print(who, &cp, ex_crest.n ? &ex_crest : NULL);
                if (vs.n) valley_print(who, &vs, ex_valley.n ? &ex_valley : NULL, 0);
                if (vs.n && real_valley.n) printf("%s_floor_profile_distance_real: %.3f\n", who, valley_profile_distance(&vs, &real_valley));
                if (vs.n && ex_valley.n && real_valley.n)
                    printf("%s_floor_depth: %.1f m at 16 px (%.2f x example, %.2f x real)\n", who, vs.rise[4], vs.rise[4] / ex_valley.rise[4], vs.rise[4] / real_deep);
            }
            if (w) printf("%s_%s_gain: %.3f; grown_lines: %d; detail: %d; seconds: %.2f\n", all[d], way[w], (double)plan.gain, plan.grown_lines, plan.detail, secs);
            else { /* the membrane alone, at 256 and 1024 px (its blocks of 128 + 64 px) */
                tn_image big = {0, 0, 0, NULL};
                double t1 = tn_time_seconds();
                printf("%s_membrane_seconds: %.4f s\n", all[d], secs);
                if (!tn_gnn_membrane(&big, &asked, 1024, 1024)) printf("%s_membrane_1024_seconds: %.3f s\n", all[d], tn_time_seconds() - t1);
                tn_image_free(&big);
            }
            fflush(stdout);
        }
        if (pictures && out[1].data && out[3].data && !tn_sketch_preview(&drawing, &asked, NULL, 256, 256)) {
            const tn_image *panel[5];
            panel[0] = &ex;
            panel[1] = &drawing;
            panel[2] = &out[1];
            panel[3] = &out[5];
            panel[4] = &out[3];
            snprintf(path, sizeof path, "%s/sketch_%s_%s.png", pictures, region, all[d]);
            save_strip(path, panel, out[5].data ? 5 : 4, model.lo, model.hi, dxy);
        }
        if (big >= 16) big_map(all[d], &model, &sk, &asked, big, &ex, real, seed);
        for (w = 0; w < 6; w++) tn_image_free(&out[w]);
        tn_image_free(&rast);
        tn_image_free(&drawing);
        tn_contour_set_free(&asked);
        tn_contour_set_free(&sk);
    }
    tn_gnn_free(&model);
    tn_image_free(&full);
    tn_image_free(&ex);
    tn_image_free(&ex_s);
    return 0;
}
