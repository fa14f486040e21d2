/* Tests for @@extract's depression filling: the pit heap's order, the same bytes for 1 and 2
   threads, and drainage (every interior cell reaches the border along D8 pointers through
   strictly lower filled heights, with no cycles and no sinks) on a synthetic DEM full of
   depressions and flats and on real DEM crops (skipped when ../shared/data is absent). */
#define TN_INTERNALS /* private tn__ code: the header's internals block */
#include "terrainnet.h"
#include "tn_test.h"

/* The 4-ary pit heap (pops and replacements of the top) against a linear scan. */
TN_TEST(test_pheap_order)
{
    enum { N = 3000 };
    static uint64_t live[N];
    tn__pheap h = {NULL, 0, 0};
    tn_rng r;
    size_t nlive = 0, i, step;
    uint32_t seq = 0;
    int bad = 0;
    tn_rng_seed(&r, 7, 1);
    for (step = 0; step < 30000; step++) {
        uint32_t op = tn_rng_u32(&r) % 3;
        /* few distinct heights, so ties (broken by the sequence number) are common */
        uint64_t pri = ((uint64_t)(tn_rng_u32(&r) % 64) << 32) | seq++;
        size_t m = 0;
        if (op == 0 || nlive == 0) {
            if (nlive == N) continue;
            if (tn__pheap_push(&h, pri, (uint32_t)pri) != TN_OK) bad++;
            live[nlive++] = pri;
            continue;
        }
        for (i = 1; i < nlive; i++) if (live[i] < live[m]) m = i;
        if (op == 1) {
            bad += tn__pheap_pop(&h) != (uint32_t)live[m];
            live[m] = live[--nlive];
        } else {
            tn__pheap_item it;
            it.pri = pri;
            it.cell = (uint32_t)pri;
            it.pad = 0;
            bad += tn__pheap_replace(&h, it) != (uint32_t)live[m];
            live[m] = pri;
        }
        bad += h.n != nlive;
    }
    TN_CHECK(bad == 0);
    TN_CHECK(seq > 20000);
    tn_free(h.a);
}

/* Every interior cell drains: its D8 pointer leads to a strictly lower filled cell and, followed
   from any cell, reaches the border within w * h steps. Returns the number of failing cells. */
static size_t drain_failures(const tn_image *filled, const tn_image *dem, const tn_flow *f)
{
    const int w = f->width, h = f->height;
    size_t n = (size_t)w * h, i, bad = 0;
    uint8_t *done = (uint8_t *)calloc(n, 1); /* 1: known to reach the border */
    uint32_t *path = (uint32_t *)malloc(n * sizeof(uint32_t));
    if (!done || !path) {
        free(done);
        free(path);
        return n;
    }
    for (i = 0; i < n; i++) {
        int x = (int)(i % (size_t)w), y = (int)(i / (size_t)w);
        int border = x == 0 || y == 0 || x == w - 1 || y == h - 1;
        if (filled->data[i] < dem->data[i]) bad++;
        if (border != (f->dir[i] == TN_FLOW_OUTLET)) bad++; /* a sink inside, or flow along the edge */
        if (!border && f->dir[i] < 8) {
            size_t r = (size_t)(y + tn__d8y[f->dir[i]]) * w + (size_t)(x + tn__d8x[f->dir[i]]);
            if (!(filled->data[r] < filled->data[i])) bad++;
        }
    }
    for (i = 0; i < n && !bad; i++) { /* follow the pointers; a path longer than n is a cycle */
        size_t c = i, len = 0, k;
        while (!done[c] && f->dir[c] < 8 && len < n) {
            path[len++] = (uint32_t)c;
            c = (size_t)((ptrdiff_t)c + tn__d8y[f->dir[c]] * (ptrdiff_t)w + tn__d8x[f->dir[c]]);
        }
        if (len >= n) {
            bad++;
            break;
        }
        for (k = 0; k < len; k++) done[path[k]] = 1;
        done[c] = 1;
    }
    free(done);
    free(path);
    return bad;
}

/* Fill + D8 with 1 and 2 threads: same bytes, and everything drains. */
static void check_fill(const char *name, const tn_image *dem)
{
    tn_image f1 = {0, 0, 0, NULL}, f2 = {0, 0, 0, NULL};
    tn_flow a, b;
    size_t n = (size_t)dem->width * dem->height, raised = 0, i, bad;
    int t = tn_get_threads();
    tn_set_threads(1);
    TN_CHECK(tn_fill_depressions(&f1, dem) == TN_OK);
    TN_CHECK(tn_flow_directions(&a, &f1) == TN_OK);
    tn_set_threads(2);
    TN_CHECK(tn_fill_depressions(&f2, dem) == TN_OK);
    TN_CHECK(tn_flow_directions(&b, &f2) == TN_OK);
    tn_set_threads(t);
    if (!f1.data || !f2.data || !a.dir || !b.dir) return;
    TN_CHECK(memcmp(f1.data, f2.data, n * sizeof(float)) == 0);
    TN_CHECK(memcmp(a.dir, b.dir, n) == 0);
    for (i = 0; i < n; i++) raised += f1.data[i] > dem->data[i];
    bad = drain_failures(&f1, dem, &a);
    printf("%s: %d x %d, %zu cells raised, %zu failing\n", name, dem->width, dem->height, raised, bad);
    TN_CHECK(raised > n / 50); /* the DEM has depressions and flats to fill */
    TN_CHECK(bad == 0);
    tn_image_free(&f1);
    tn_image_free(&f2);
    tn_flow_free(&a);
    tn_flow_free(&b);
}

/* Perlin noise quantised to 12 levels (wide flats and flat-bottomed pits), with square pits
   and a closed basin carved in. */
TN_TEST(test_fill_synthetic_pits_and_flats)
{
    tn_image dem = {0, 0, 0, NULL};
    tn_perlin_opts po;
    int x, y;
    memset(&po, 0, sizeof po);
    po.octaves = 5;
    po.frequency = 5.0f;
    TN_CHECK(tn_noise_perlin(&dem, 257, 203, &po) == TN_OK);
    if (!dem.data) return;
    for (y = 0; y < dem.height; y++)
        for (x = 0; x < dem.width; x++) {
            float *v = &dem.data[(size_t)y * dem.width + x];
            *v = floorf(*v * 12.0f);
            if (x % 37 > 30 && y % 29 > 24) *v -= 3.0f;                 /* square pits */
            if (abs(x - 128) < 20 && abs(y - 100) < 20) *v = -2.0f;      /* a flat basin */
            if (abs(x - 128) == 20 && abs(y - 100) <= 20) *v = 20.0f;   /* walled on two sides */
        }
    check_fill("synthetic", &dem);
    tn_image_free(&dem);
}

/* Real DEMs: an 8-bit canyon (many flats) and a 16-bit alpine crop, and their inversions (ridges). */
TN_TEST(test_fill_real_crops)
{
    const char *names[2] = {"dem/grandcanyon_hoppe8bit/grandcanyon_hoppe8bit_256.png", "dem/alps_n47e009/alps_n47e009_256.png"};
    int k, any = 0;
    for (k = 0; k < 2; k++) {
        const char *p = tn_test_data(names[k]);
        tn_image dem = {0, 0, 0, NULL}, one = {0, 0, 0, NULL};
        size_t i, n;
        if (!p || tn_image_load(&dem, p, NULL) != TN_OK) continue;
        any = 1;
        TN_CHECK(tn__channel0_image(&dem, &one) == TN_OK);
        n = (size_t)one.width * one.height;
        for (i = 0; i < n; i++) one.data[i] *= 1000.0f;
        check_fill(names[k], &one);
        for (i = 0; i < n; i++) one.data[i] = -one.data[i];
        check_fill("  inverted", &one);
        tn_image_free(&one);
        tn_image_free(&dem);
    }
    if (!any) TN_SKIP("no ../shared/data");
}

/* The NaN check runs over rows in parallel but names the first bad pixel in raster order. */
TN_TEST(test_first_nan_is_reported)
{
    tn_image dem = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_flow f;
    int t = tn_get_threads();
    TN_CHECK(tn_image_create(&dem, 2048, 64, 1) == TN_OK);
    if (!dem.data) return;
    dem.data[(size_t)50 * 2048 + 3] = NAN;
    dem.data[(size_t)9 * 2048 + 1500] = INFINITY;
    dem.data[(size_t)9 * 2048 + 2000] = NAN;
    tn_set_threads(2);
    TN_CHECK(tn_fill_depressions(&out, &dem) == TN_ERR_NUMERIC);
    TN_CHECK(strstr(tn_last_error(), "(1500, 9)") != NULL);
    TN_CHECK(tn_flow_directions(&f, &dem) == TN_ERR_NUMERIC);
    TN_CHECK(strstr(tn_last_error(), "(1500, 9)") != NULL);
    tn_set_threads(t);
    tn_image_free(&dem);
}

int main(void)
{
    TN_RUN(test_pheap_order);
    TN_RUN(test_fill_synthetic_pits_and_flats);
    TN_RUN(test_fill_real_crops);
    TN_RUN(test_first_nan_is_reported);
    return tn_test_summary("test_fill");
}
