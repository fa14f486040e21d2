/* Tests for @@extract: depression filling, D8, accumulation, Strahler order, skeletonisation,
   contour tracing, contour parts, the preview and the realism report, on hand-built DEMs with
   known answers and on the real DEMs in ../shared/data (skipped when absent). */
#define TN_INTERNALS /* private tn__ code: the header's internals block */
#include "terrainnet.h"
#include "tn_test.h"

static tn_image make_dem(int w, int h, float (*f)(int x, int y))
{
    tn_image im = {0, 0, 0, NULL};
    int x, y;
    if (tn_image_create(&im, w, h, 1)) return im;
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++) im.data[(size_t)y * w + x] = f(x, y);
    return im;
}

/* V-shaped valley along x = 16, falling towards y = 0. */
static float v_valley(int x, int y) { return 2.0f * (float)abs(x - 16) + 0.5f * (float)y; }
/* Ridge along x = 16, falling towards y = 0. */
static float ridge_line(int x, int y) { return 100.0f - 2.0f * (float)abs(x - 16) + 0.5f * (float)y; }
/* Cone centred at (16, 16). */
static float cone(int x, int y) { return 100.0f - sqrtf((float)((x - 16) * (x - 16) + (y - 16) * (y - 16))); }
/* A tilted plane with a 3 x 3 pit of depth 5 at (10, 10). */
static float pit(int x, int y) { return 0.3f * (float)x + 0.2f * (float)y - ((abs(x - 10) <= 1 && abs(y - 10) <= 1) ? 5.0f : 0.0f); }

/* Sum of accumulation at the outlets must be every cell: each drains exactly once. */
static size_t outlet_sum(const tn_flow *f)
{
    size_t i, s = 0, n = (size_t)f->width * f->height;
    for (i = 0; i < n; i++) if (f->dir[i] == TN_FLOW_OUTLET) s += f->acc[i];
    return s;
}

/* Priority-flood (with its queue tricks) against the plain definition: the filled surface is the
   lowest one >= the DEM from which every cell reaches the border without climbing, computed by
   relaxation (Planchon-Darboux without epsilon). They agree up to the epsilon steps. */
TN_TEST(test_fill_matches_relaxation)
{
    enum { W = 48, H = 40 };
    tn_image dem = {0, 0, 0, NULL}, filled = {0, 0, 0, NULL};
    float ref[W * H];
    tn_rng rng;
    int x, y, d, changed = 1, raised = 0, seed;
    double worst = 0;
    for (seed = 1; seed <= 3; seed++) {
        tn_rng_seed(&rng, (uint64_t)seed, 3);
        TN_CHECK(tn_image_create(&dem, W, H, 1) == TN_OK);
        for (y = 0; y < H; y++) /* bumpy noise with many pits and some exact flats */
            for (x = 0; x < W; x++) {
                float v = 10.0f * tn_rng_uniform(&rng) + 0.2f * (float)x;
                dem.data[y * W + x] = seed == 3 ? floorf(v) : v;
            }
        for (y = 0; y < H; y++)
            for (x = 0; x < W; x++)
                ref[y * W + x] = (x == 0 || y == 0 || x == W - 1 || y == H - 1) ? dem.data[y * W + x] : 1e30f;
        changed = 1;
        while (changed) {
            changed = 0;
            for (y = 1; y < H - 1; y++)
                for (x = 1; x < W - 1; x++) {
                    float m = 1e30f, v;
                    for (d = 0; d < 8; d++) m = fminf(m, ref[(y + tn__d8y[d]) * W + x + tn__d8x[d]]);
                    v = fmaxf(dem.data[y * W + x], m);
                    if (v < ref[y * W + x]) { ref[y * W + x] = v; changed = 1; }
                }
        }
        TN_CHECK(tn_fill_depressions(&filled, &dem) == TN_OK);
        for (y = 0; y < H; y++)
            for (x = 0; x < W; x++) {
                double e = fabs((double)filled.data[y * W + x] - ref[y * W + x]);
                if (e > worst) worst = e;
                raised += ref[y * W + x] > dem.data[y * W + x];
            }
        tn_image_free(&filled);
        tn_image_free(&dem);
    }
    TN_CHECK(raised > 100); /* the test has depressions to fill */
    TN_CHECK(worst < 1e-3);
}

TN_TEST(test_v_valley)
{
    tn_image dem = make_dem(33, 40, v_valley);
    tn_flow f;
    tn_extract_opts o;
    tn_extraction ex;
    int y, i, j, on_line = 0, off_line = 0;
    TN_CHECK(tn_flow_compute(&f, &dem, 0) == TN_OK);
    TN_CHECK(outlet_sum(&f) == (size_t)33 * 40);
    /* the valley floor drains north, and collects the whole interior */
    for (y = 1; y < 39; y++) TN_CHECK(f.dir[(size_t)y * 33 + 16] == 6);
    TN_CHECK(f.acc[(size_t)1 * 33 + 16] > 31u * 38u / 2u);
    tn_flow_free(&f);
    memset(&o, 0, sizeof o);
    o.threshold = 40;
    o.which = TN_EXTRACT_VALLEYS;
    TN_CHECK(tn_extract(&ex, &dem, &o) == TN_OK);
    TN_CHECK(ex.contours.count >= 1);
    for (i = 0; i < ex.contours.count; i++) {
        TN_CHECK(ex.contours.items[i].type == TN_VALLEY);
        for (j = 0; j < ex.contours.items[i].npoints; j++) {
            float *p = ex.contours.items[i].points + j * 3;
            if (p[0] == 16.0f) on_line++; else off_line++;
            TN_CHECK_NEAR(p[2], v_valley((int)p[0], (int)p[1]), 1e-4);
        }
    }
    TN_CHECK(on_line >= 25);
    TN_CHECK(off_line == 0);
    tn_extraction_free(&ex);
    tn_image_free(&dem);
}

TN_TEST(test_ridge_line)
{
    tn_image dem = make_dem(33, 40, ridge_line);
    tn_extract_opts o;
    tn_extraction ex;
    int i, j, on_line = 0, off_line = 0;
    memset(&o, 0, sizeof o);
    o.threshold = 30;
    o.which = TN_EXTRACT_RIDGES;
    TN_CHECK(tn_extract(&ex, &dem, &o) == TN_OK);
    TN_CHECK(ex.contours.count >= 1);
    for (i = 0; i < ex.contours.count; i++) {
        TN_CHECK(ex.contours.items[i].type == TN_RIDGE);
        for (j = 0; j < ex.contours.items[i].npoints; j++) {
            if (ex.contours.items[i].points[j * 3] == 16.0f) on_line++; else off_line++;
        }
    }
    TN_CHECK(on_line >= 25);
    TN_CHECK(off_line == 0);
    tn_extraction_free(&ex);
    tn_image_free(&dem);
}

TN_TEST(test_cone)
{
    tn_image dem = make_dem(33, 33, cone);
    tn_flow f;
    int x, y, bad = 0;
    uint32_t mx = 0;
    TN_CHECK(tn_flow_compute(&f, &dem, 0) == TN_OK);
    for (y = 0; y < 33; y++)
        for (x = 0; x < 33; x++) {
            int d = f.dir[(size_t)y * 33 + x];
            if (x == 16 && y == 16) continue;
            if (x == 0 || y == 0 || x == 32 || y == 32) { /* the border drains off the map */
                TN_CHECK(d == TN_FLOW_OUTLET);
                continue;
            }
            /* every cell drains away from the summit */
            if ((x - 16) * tn__d8x[d] + (y - 16) * tn__d8y[d] <= 0) bad++;
            if (f.acc[(size_t)y * 33 + x] > mx) mx = f.acc[(size_t)y * 33 + x];
        }
    TN_CHECK(bad == 0);
    TN_CHECK(mx < 33u * 33u / 8u); /* flow diverges: no cell collects a large share */
    TN_CHECK(outlet_sum(&f) == (size_t)33 * 33);
    tn_flow_free(&f);
    tn_image_free(&dem);
}

TN_TEST(test_pit_is_filled)
{
    tn_image dem = make_dem(24, 20, pit), filled = {0, 0, 0, NULL};
    tn_flow f;
    int x, y, d, stuck = 0;
    TN_CHECK(tn_fill_depressions(&filled, &dem) == TN_OK);
    TN_CHECK(filled.data[10 * 24 + 10] > dem.data[10 * 24 + 10] + 4.0f); /* raised to the spill level */
    for (y = 0; y < 20; y++)
        for (x = 0; x < 24; x++) {
            int lower = 0;
            TN_CHECK(filled.data[y * 24 + x] >= dem.data[y * 24 + x]);
            if (x == 0 || y == 0 || x == 23 || y == 19) continue;
            for (d = 0; d < 8; d++)
                if (filled.data[(y + tn__d8y[d]) * 24 + x + tn__d8x[d]] < filled.data[y * 24 + x]) lower = 1;
            if (!lower) stuck++;
        }
    TN_CHECK(stuck == 0);
    /* outside the pit nothing changes */
    TN_CHECK(filled.data[3 * 24 + 20] == dem.data[3 * 24 + 20]);
    TN_CHECK(tn_flow_compute(&f, &dem, 0) == TN_OK);
    TN_CHECK(outlet_sum(&f) == (size_t)24 * 20);
    TN_CHECK(f.dir[10 * 24 + 10] != TN_FLOW_OUTLET);
    tn_flow_free(&f);
    tn_image_free(&filled);
    tn_image_free(&dem);
}

/* A flat plateau (height 1 inside a border ring at 0) fills in rings from all its edges at once,
   so every cell drains straight to its nearest edge: no path collects more than a short line.
   (Filling the flat from the first edge cell reached would drain most of it to that cell.) */
static float plateau(int x, int y) { return x == 0 || y == 0 || x == 63 || y == 63 ? 0.0f : 1.0f; }

TN_TEST(test_flat_drains_to_all_edges)
{
    tn_image dem = make_dem(64, 64, plateau), noise = {0, 0, 0, NULL};
    tn_perlin_opts po;
    tn_flow f, g;
    size_t i, mx = 0;
    int t;
    TN_CHECK(tn_flow_compute(&f, &dem, 0) == TN_OK);
    TN_CHECK(outlet_sum(&f) == (size_t)64 * 64);
    for (i = 0; i < (size_t)64 * 64; i++) if (f.dir[i] != TN_FLOW_OUTLET && f.acc[i] > mx) mx = f.acc[i];
    printf("plateau: largest inner accumulation %zu cells\n", mx);
    TN_CHECK(mx <= 64);
    tn_flow_free(&f);
    /* accumulation is threaded by strips: 1 and 2 threads give the same grids */
    memset(&po, 0, sizeof po);
    po.octaves = 6;
    po.frequency = 6.0f;
    TN_CHECK(tn_noise_perlin(&noise, 301, 203, &po) == TN_OK);
    t = tn_get_threads();
    tn_set_threads(1);
    TN_CHECK(tn_flow_compute(&f, &noise, 0) == TN_OK);
    tn_set_threads(2);
    TN_CHECK(tn_flow_compute(&g, &noise, 0) == TN_OK);
    tn_set_threads(t);
    TN_CHECK(outlet_sum(&g) == (size_t)301 * 203);
    TN_CHECK(memcmp(f.acc, g.acc, (size_t)301 * 203 * sizeof(uint32_t)) == 0);
    TN_CHECK(memcmp(f.dir, g.dir, (size_t)301 * 203) == 0);
    tn_flow_free(&f);
    tn_flow_free(&g);
    tn_image_free(&noise);
    tn_image_free(&dem);
}

/* A lake (flat at 5 inside a rim at 10) with one outlet cell at 0 in the middle of the west
   edge. The flood visits it as r.watershed's A* search does (equal heights oldest first, S N W E
   before the diagonals), and raised cells drain to the cell the flood came from, so the lake
   drains along the outlet's row with diagonal feeders on both sides, symmetrically. */
static float lake(int x, int y) { return x == 0 && y == 7 ? 0.0f : (x == 0 || y == 0 || x == 14 || y == 14) ? 10.0f : 5.0f; }

TN_TEST(test_lake_drains_like_rwatershed)
{
    tn_image dem = make_dem(15, 15, lake), noise = {0, 0, 0, NULL}, filled = {0, 0, 0, NULL};
    tn_perlin_opts po;
    tn_flow f;
    size_t i, n, bad = 0;
    int x;
    TN_CHECK(tn_flow_compute(&f, &dem, 0) == TN_OK);
    TN_CHECK(f.acc[7 * 15] == 13 * 13 + 1);
    for (x = 1; x < 14; x++) TN_CHECK(f.dir[7 * 15 + x] == 4);                /* W along the row */
    for (x = 2; x < 14; x++) TN_CHECK(f.dir[6 * 15 + x] == 3 && f.dir[8 * 15 + x] == 5); /* SW / NW feeders */
    TN_CHECK(f.acc[6 * 15 + 13] == f.acc[8 * 15 + 13]);
    tn_flow_free(&f);
    /* on a noisy DEM with pits, every flow step still descends the filled surface strictly */
    memset(&po, 0, sizeof po);
    po.octaves = 5;
    po.frequency = 8.0f;
    TN_CHECK(tn_noise_perlin(&noise, 157, 131, &po) == TN_OK);
    n = (size_t)157 * 131;
    for (i = 0; i < n; i++) noise.data[i] = floorf(noise.data[i] * 20.0f); /* terraces: many flats */
    TN_CHECK(tn_fill_depressions(&filled, &noise) == TN_OK);
    TN_CHECK(tn_flow_compute(&f, &noise, 0) == TN_OK);
    TN_CHECK(outlet_sum(&f) == n);
    for (i = 0; i < n; i++) {
        int d = f.dir[i];
        if (d == TN_FLOW_OUTLET) continue;
        if (!(filled.data[i + (ptrdiff_t)tn__d8y[d] * 157 + tn__d8x[d]] < filled.data[i])) bad++;
    }
    TN_CHECK(bad == 0);
    tn_flow_free(&f);
    tn_image_free(&filled);
    tn_image_free(&noise);
    tn_image_free(&dem);
}

/* A hand-made network: two sources (order 1) meet at a junction (order 2), a third source joins
   the stem lower down (stays 2), on a 7 x 8 grid draining to (3, 7). */
TN_TEST(test_strahler_y)
{
    enum { W = 7, H = 8 };
    tn_flow f;
    uint8_t dir[W * H], mask[W * H], order[W * H];
    int top = 0, i;
    memset(&f, 0, sizeof f);
    f.width = W;
    f.height = H;
    f.dir = dir;
    memset(dir, TN_FLOW_OUTLET, sizeof dir);
    memset(mask, 0, sizeof mask);
#define AT(x, y) ((y) * W + (x))
    /* left arm (1,0)->(2,1)->(3,2), right arm (5,0)->(4,1)->(3,2): SE = 1, SW = 3, S = 2 */
    dir[AT(1, 0)] = 1; dir[AT(2, 1)] = 1;
    dir[AT(5, 0)] = 3; dir[AT(4, 1)] = 3;
    for (i = 2; i < 7; i++) dir[AT(3, i)] = 2; /* stem down to (3, 7), an outlet */
    dir[AT(6, 3)] = 3; dir[AT(5, 4)] = 3;      /* third source joins the stem at (4, 5) -> (3, 6)? */
    dir[AT(4, 5)] = 3;
    mask[AT(1, 0)] = mask[AT(2, 1)] = mask[AT(5, 0)] = mask[AT(4, 1)] = 1;
    for (i = 2; i < 8; i++) mask[AT(3, i)] = 1;
    mask[AT(6, 3)] = mask[AT(5, 4)] = mask[AT(4, 5)] = 1;
    TN_CHECK(tn_strahler_order(order, &f, mask, &top) == TN_OK);
    TN_CHECK(order[AT(1, 0)] == 1 && order[AT(2, 1)] == 1 && order[AT(4, 1)] == 1);
    TN_CHECK(order[AT(3, 2)] == 2);
    TN_CHECK(order[AT(4, 5)] == 1);
    TN_CHECK(order[AT(3, 6)] == 2 && order[AT(3, 7)] == 2);
    TN_CHECK(order[AT(0, 0)] == 0);
    TN_CHECK(top == 2);
    /* a second order-2 branch joining makes the outlet order 3 */
    dir[AT(6, 3)] = TN_FLOW_OUTLET;
    mask[AT(6, 3)] = 0;
    dir[AT(6, 4)] = 3; dir[AT(6, 5)] = 4; /* (6,4) -> (5,5)? no: keep simple, second source into (5,4) */
    dir[AT(6, 4)] = 4;
    mask[AT(6, 4)] = 1;
    dir[AT(6, 3)] = 3; mask[AT(6, 3)] = 1; /* (6,3) -> (5,4) and (6,4) -> (5,4): two order-1 meet */
    TN_CHECK(tn_strahler_order(order, &f, mask, &top) == TN_OK);
    TN_CHECK(order[AT(5, 4)] == 2);
    TN_CHECK(order[AT(3, 6)] == 3);
    TN_CHECK(top == 3);
#undef AT
}

/* Pixel p of a skeleton is simple (removable without changing topology) and not an endpoint. */
static int removable(const uint8_t *m, int w, int h, int x, int y)
{
    int p[8], k, b = 0;
    tn__nbrs(m, w, h, x, y, p);
    for (k = 0; k < 8; k++) b += p[k];
    return b >= 2 && tn__yokoi8(p) == 1;
}

static int components8(const uint8_t *m, int w, int h)
{
    int *stack = (int *)malloc(sizeof(int) * w * h), comps = 0, i;
    uint8_t *seen = (uint8_t *)calloc((size_t)w * h, 1);
    for (i = 0; i < w * h; i++) {
        int sp = 0;
        if (!m[i] || seen[i]) continue;
        comps++;
        seen[i] = 1;
        stack[sp++] = i;
        while (sp) {
            int c = stack[--sp], d;
            for (d = 0; d < 8; d++) {
                int x = c % w + tn__d8x[d], y = c / w + tn__d8y[d];
                if (x < 0 || y < 0 || x >= w || y >= h || !m[y * w + x] || seen[y * w + x]) continue;
                seen[y * w + x] = 1;
                stack[sp++] = y * w + x;
            }
        }
    }
    free(stack);
    free(seen);
    return comps;
}

TN_TEST(test_skeleton)
{
    enum { W = 48, H = 40 };
    uint8_t m[W * H];
    int x, y, blocks = 0, rem = 0, count = 0;
    memset(m, 0, sizeof m);
    for (y = 5; y < 10; y++) for (x = 3; x < 44; x++) m[y * W + x] = 1;   /* 5 px thick bar */
    for (y = 10; y < 36; y++) for (x = 20; x < 24; x++) m[y * W + x] = 1; /* 4 px thick leg: a T */
    for (y = 28; y < 31; y++) for (x = 30; x < 45; x++) m[y * W + x] = 1; /* separate bar */
    for (x = 0; x < 12; x++) m[(20 + x) * W + 5 + x] = m[(20 + x) * W + 6 + x] = 1; /* thick diagonal */
    TN_CHECK(components8(m, W, H) == 3);
    TN_CHECK(tn_skeletonize(m, W, H) == TN_OK);
    TN_CHECK(components8(m, W, H) == 3);
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) {
            if (!m[y * W + x]) continue;
            count++;
            if (removable(m, W, H, x, y)) rem++;
            if (x + 1 < W && y + 1 < H && m[y * W + x + 1] && m[(y + 1) * W + x] && m[(y + 1) * W + x + 1]) blocks++;
        }
    TN_CHECK(blocks == 0);
    TN_CHECK(rem == 0);
    TN_CHECK(count > 60); /* the lines are still there: ~40 + 25 + 14 + 12 pixels */
}

static const char *data_dem(const char *region, const char *suffix)
{
    static char rel[256];
    snprintf(rel, sizeof rel, "dem/%s/%s_%s.png", region, region, suffix);
    return tn_test_data(rel);
}

/* Loads a shared DEM in metres (the PNGs hold [0, 1] of the MANIFEST's range). */
static int load_metres(const char *region, const char *suffix, float lo, float hi, tn_image *im)
{
    const char *p = data_dem(region, suffix);
    size_t i;
    if (!p || tn_image_load(im, p, NULL) != TN_OK) return 0;
    for (i = 0; i < (size_t)im->width * im->height; i++) im->data[i] = lo + im->data[i] * (hi - lo);
    return 1;
}

static int sets_equal(const tn_contour_set *a, const tn_contour_set *b)
{
    int i;
    if (a->count != b->count || a->width != b->width || a->height != b->height) return 0;
    for (i = 0; i < a->count; i++) {
        const tn_contour *p = &a->items[i], *q = &b->items[i];
        if (p->type != q->type || p->order != q->order || p->npoints != q->npoints || p->mean_gradient != q->mean_gradient ||
            memcmp(p->points, q->points, (size_t)p->npoints * 3 * sizeof(float)))
            return 0;
    }
    return 1;
}

TN_TEST(test_real_dem_pipeline)
{
    tn_image dem = {0, 0, 0, NULL}, prev = {0, 0, 0, NULL};
    tn_extraction ex, ex2;
    tn_contour_set parts, parts2, parts3;
    int i, j, bad_len = 0, bad_adj = 0, valleys = 0, ridges = 0, short_dangling = 0, maxo = 0, x, y, skel_px = 0;
    if (!load_metres("alps_montblanc", "256", 454.0f, 4810.0f, &dem)) TN_SKIP("no ../shared/data");
    tn_set_threads(1);
    TN_CHECK(tn_extract(&ex, &dem, NULL) == TN_OK);
    tn_set_threads(2);
    TN_CHECK(tn_extract(&ex2, &dem, NULL) == TN_OK);
    TN_CHECK(sets_equal(&ex.contours, &ex2.contours)); /* same bytes for 1 and 2 threads */
    TN_CHECK(ex.threshold == tn_extract_default_threshold(256, 256));
    TN_CHECK(ex.valley_max_order >= 3 && ex.valley_max_order <= 7);
    for (i = 0; i < ex.contours.count; i++) {
        const tn_contour *c = &ex.contours.items[i];
        if (c->type == TN_VALLEY) valleys++; else ridges++;
        if (c->order > maxo) maxo = c->order;
        TN_CHECK(c->npoints >= 2 && c->npoints <= 48);
        TN_CHECK(c->order >= 1);
        for (j = 1; j < c->npoints; j++) /* polylines of 8-adjacent pixels */
            if (fabsf(c->points[j * 3] - c->points[j * 3 - 3]) > 1 || fabsf(c->points[j * 3 + 1] - c->points[j * 3 - 2]) > 1) bad_adj++;
    }
    (void)short_dangling;
    TN_CHECK(bad_adj == 0);
    TN_CHECK(valleys > 20 && ridges > 20);
    TN_CHECK(maxo >= 3);
    /* the valley mask holds the raw network: cells with accumulation >= threshold */
    for (y = 0; y < 256; y++)
        for (x = 0; x < 256; x++) {
            size_t k = (size_t)y * 256 + x;
            TN_CHECK(ex.valley_mask[k] == (ex.valley_flow.acc[k] >= (uint32_t)ex.threshold));
            skel_px += ex.valley_mask[k];
        }
    TN_CHECK(skel_px > 500);
    /* parts: the contours are pixel chains, so they cut directly into 5-10 adjacent pixels,
       deterministic per seed */
    TN_CHECK(tn_contour_parts_make(&parts, &ex.contours, 7) == TN_OK);
    TN_CHECK(tn_contour_parts_make(&parts2, &ex.contours, 7) == TN_OK);
    TN_CHECK(tn_contour_parts_make(&parts3, &ex.contours, 8) == TN_OK);
    TN_CHECK(parts.count > 100);
    TN_CHECK(sets_equal(&parts, &parts2));
    TN_CHECK(!sets_equal(&parts, &parts3));
    for (i = 0; i < parts.count; i++) {
        const tn_contour *c = &parts.items[i];
        if (c->npoints < 5 || c->npoints > 10) bad_len++;
        for (j = 1; j < c->npoints; j++) {
            float dx = fabsf(c->points[j * 3] - c->points[j * 3 - 3]), dy = fabsf(c->points[j * 3 + 1] - c->points[j * 3 - 2]);
            if (dx > 1 || dy > 1 || (dx == 0 && dy == 0)) bad_adj++;
        }
    }
    TN_CHECK(bad_len == 0);
    TN_CHECK(bad_adj == 0);
    TN_CHECK(tn_sketch_preview(&prev, &ex.contours, &dem, 256, 256) == TN_OK);
    TN_CHECK(prev.channels == 3 && prev.width == 256);
    { /* a valley pixel is painted blue, a ridge pixel yellow */
        const float *pv = NULL, *pr = NULL;
        for (i = 0; i < ex.contours.count && (!pv || !pr); i++) {
            const tn_contour *c = &ex.contours.items[i];
            const float *p = c->points + 3 * (c->npoints / 2);
            if (c->type == TN_VALLEY && !pv) pv = p;
            if (c->type == TN_RIDGE && !pr) pr = p;
        }
        TN_CHECK(pv && pr);
        if (pv && pr) {
            TN_CHECK(TN_PIXEL(&prev, (int)pv[0], (int)pv[1], 2) > 0.9f && TN_PIXEL(&prev, (int)pv[0], (int)pv[1], 0) < 0.3f);
            TN_CHECK(TN_PIXEL(&prev, (int)pr[0], (int)pr[1], 0) > 0.9f && TN_PIXEL(&prev, (int)pr[1 - 1], (int)pr[1], 2) < 0.3f);
        }
    }
    tn_image_free(&prev);
    tn_contour_set_free(&parts);
    tn_contour_set_free(&parts2);
    tn_contour_set_free(&parts3);
    tn_extraction_free(&ex);
    tn_extraction_free(&ex2);
    tn_image_free(&dem);
}

TN_TEST(test_parts_sparse_sketch)
{
    /* a sketch given by sparse vertices is densified first: a 30 px straight stroke */
    float pts[6] = {2, 5, 0.8f, 31, 5, 0.5f};
    tn_contour c;
    tn_contour_set s, dense, parts;
    int i, total = 0;
    c.type = TN_RIDGE;
    c.order = 1;
    c.npoints = 2;
    c.mean_gradient = 0;
    c.points = pts;
    s.width = 40;
    s.height = 12;
    s.count = 1;
    s.items = &c;
    /* the two vertices are 29 px apart: without densifying there is no adjacent run to cut */
    TN_CHECK(tn_contour_parts_make(&parts, &s, 1) == TN_OK && parts.count == 0);
    tn_contour_set_free(&parts);
    TN_CHECK(tn_sketch_densify(&dense, &s) == TN_OK && dense.count == 1 && dense.items[0].npoints == 30);
    TN_CHECK(tn_contour_parts_make(&parts, &dense, 1) == TN_OK);
    for (i = 0; i < parts.count; i++) {
        TN_CHECK(parts.items[i].npoints >= 5 && parts.items[i].npoints <= 10);
        TN_CHECK(parts.items[i].type == TN_RIDGE);
        total += parts.items[i].npoints;
    }
    TN_CHECK(total == 30); /* a short tail joins the last part: every pixel is used */
    TN_CHECK(parts.count >= 3 && parts.count <= 6);
    TN_CHECK_NEAR(parts.items[0].points[2], 0.8, 1e-5);
    tn_contour_set_free(&parts);
    tn_contour_set_free(&dense);
}

TN_TEST(test_bad_input)
{
    tn_image dem = make_dem(16, 16, cone), empty = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_extraction ex;
    tn_flow f;
    tn_contour_set none, parts;
    tn_realism r;
    tn_extract_opts o;
    dem.data[5 * 16 + 7] = NAN;
    TN_CHECK(tn_extract(&ex, &dem, NULL) == TN_ERR_NUMERIC);
    TN_CHECK(strstr(tn_last_error(), "NaN") != NULL);
    TN_CHECK(tn_flow_compute(&f, &dem, 0) == TN_ERR_NUMERIC);
    TN_CHECK(tn_fill_depressions(&out, &dem) == TN_ERR_NUMERIC);
    dem.data[5 * 16 + 7] = INFINITY;
    TN_CHECK(tn_extract(&ex, &dem, NULL) == TN_ERR_NUMERIC);
    TN_CHECK(tn_extract(&ex, &empty, NULL) == TN_ERR_EMPTY);
    TN_CHECK(tn_realism_compare(&r, &empty, &empty, NULL) == TN_ERR_EMPTY);
    /* no polylines on a canvas: an empty set of parts (documented); no canvas at all: an error */
    memset(&none, 0, sizeof none);
    TN_CHECK(tn_contour_parts_make(&parts, &none, 1) == TN_ERR_INVALID_ARG);
    none.width = none.height = 16;
    TN_CHECK(tn_contour_parts_make(&parts, &none, 1) == TN_OK && parts.count == 0 && parts.width == 16);
    tn_contour_set_free(&parts);
    dem.data[5 * 16 + 7] = 1.0f;
    memset(&o, 0, sizeof o);
    o.threshold = -3;
    TN_CHECK(tn_extract(&ex, &dem, &o) == TN_ERR_INVALID_ARG);
    { /* a direction grid with a cycle is reported, not looped on */
        uint8_t dir[4] = {0, 4, TN_FLOW_OUTLET, TN_FLOW_OUTLET}; /* (0,0) -> (1,0) -> (0,0) */
        memset(&f, 0, sizeof f);
        f.width = 2;
        f.height = 2;
        f.dir = dir;
        TN_CHECK(tn_flow_accumulation(&f) == TN_ERR_CORRUPT);
        TN_CHECK(f.acc == NULL);
    }
    tn_image_free(&dem);
}

TN_TEST(test_realism)
{
    tn_image alps = {0, 0, 0, NULL}, mb = {0, 0, 0, NULL}, sahara = {0, 0, 0, NULL};
    tn_realism same, near_, far_;
    tn_realism_opts o;
    if (!load_metres("alps_n47e009", "256", 388.0f, 2937.0f, &alps) || !load_metres("alps_montblanc", "256", 454.0f, 4810.0f, &mb) ||
        !load_metres("sahara_erg_oriental", "256", 189.0f, 475.0f, &sahara)) {
        tn_image_free(&alps);
        tn_image_free(&mb);
        TN_SKIP("no ../shared/data");
    }
    memset(&o, 0, sizeof o);
    o.dx_a = 62.6f; o.dy_a = 92.6f;
    TN_CHECK(tn_realism_compare(&same, &alps, &alps, &o) == TN_OK);
    TN_CHECK(same.slope_distance == 0 && same.curvature_distance == 0 && same.spectrum_distance == 0 && same.distance == 0);
    TN_CHECK(same.ssim > 0.999999 && same.psnr > 1e30);
    TN_CHECK(same.drainage_density_a == same.drainage_density_b && same.drainage_density_a > 0.01);
    TN_CHECK(same.bifurcation_ratio_a > 2.0 && same.bifurcation_ratio_a < 8.0);
    TN_CHECK(same.spectrum_slope_a < -2.0 && same.spectrum_slope_a > -5.0); /* terrain-like red spectrum */
    o.dx_b = o.dy_b = 92.7f;
    TN_CHECK(tn_realism_compare(&near_, &alps, &mb, &o) == TN_OK);
    o.dx_b = o.dy_b = 92.6f;
    TN_CHECK(tn_realism_compare(&far_, &alps, &sahara, &o) == TN_OK);
    /* two Alpine regions are closer than the Alps and the Sahara dunes */
    TN_CHECK(near_.distance < far_.distance);
    TN_CHECK(near_.slope_distance < far_.slope_distance);
    TN_CHECK(near_.curvature_distance < far_.curvature_distance);
    TN_CHECK(near_.spectrum_distance < far_.spectrum_distance);
    printf("realism alps_n47e009 vs alps_montblanc: %.3f; vs sahara_erg_oriental: %.3f\n", near_.distance, far_.distance);
    tn_image_free(&alps);
    tn_image_free(&mb);
    tn_image_free(&sahara);
}

int main(void)
{
    TN_RUN(test_fill_matches_relaxation);
    TN_RUN(test_v_valley);
    TN_RUN(test_ridge_line);
    TN_RUN(test_cone);
    TN_RUN(test_pit_is_filled);
    TN_RUN(test_flat_drains_to_all_edges);
    TN_RUN(test_lake_drains_like_rwatershed);
    TN_RUN(test_strahler_y);
    TN_RUN(test_skeleton);
    TN_RUN(test_parts_sparse_sketch);
    TN_RUN(test_bad_input);
    TN_RUN(test_real_dem_pipeline);
    TN_RUN(test_realism);
    return tn_test_summary("test_extract");
}
