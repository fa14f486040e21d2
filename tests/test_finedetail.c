/* test_finedetail.c - @@finedetail: a smooth terrain takes an example's fine detail and keeps its
   own coarse shape; on real crops of a DEM the finest band is as rough as the crops' own; a
   window computed on itself grown by the halo equals the whole map's; the
   same bytes on any thread count; bad inputs fail with a message and no output. */
#include "terrainnet.h"
#include "tn_test.h"

/* A rough example: Perlin fBm of 8 octaves from 1000 to 2000 m. */
static tn_image rough_dem(int w, int h, uint64_t seed)
{
    tn_image d = {0, 0, 0, NULL};
    tn_perlin_opts po;
    size_t i;
    memset(&po, 0, sizeof po);
    po.seed = seed;
    po.octaves = 8;
    po.frequency = 4;
    if (tn_noise_perlin(&d, w, h, &po)) return d;
    for (i = 0; i < (size_t)w * h; i++) d.data[i] = 1000.0f + 1000.0f * d.data[i];
    return d;
}

/* Standard deviation of the 4-neighbour Laplacian over the interior. */
static double laplacian_std(const tn_image *a)
{
    double s = 0, s2 = 0;
    int x, y, n = 0;
    for (y = 1; y < a->height - 1; y++)
        for (x = 1; x < a->width - 1; x++) {
            double l = TN_PIXEL(a, x - 1, y, 0) + TN_PIXEL(a, x + 1, y, 0) + TN_PIXEL(a, x, y - 1, 0) + TN_PIXEL(a, x, y + 1, 0) -
                       4.0 * TN_PIXEL(a, x, y, 0);
            s += l, s2 += l * l, n++;
        }
    return sqrt(s2 / n - (s / n) * (s / n));
}

static int same_image(const tn_image *a, const tn_image *b)
{
    return a->width == b->width && a->height == b->height && a->channels == b->channels &&
           !memcmp(a->data, b->data, (size_t)a->width * a->height * a->channels * sizeof(float));
}

TN_TEST(smooth_terrain_takes_the_examples_detail)
{
    tn_image ex = rough_dem(96, 96, 5), raw = rough_dem(160, 120, 9), smooth = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_image lo_in = {0, 0, 0, NULL}, lo_out = {0, 0, 0, NULL};
    double lap_ex, lap_in, lap_out, diff = 0, rel = 0;
    size_t i, n = (size_t)160 * 120;
    TN_CHECK(tn_image_blur(&smooth, &raw, 3.0f) == TN_OK);
    TN_CHECK(tn_fine_detail(&out, &ex, &smooth, NULL) == TN_OK);
    TN_CHECK(out.width == 160 && out.height == 120 && out.channels == 1);
    lap_ex = laplacian_std(&ex), lap_in = laplacian_std(&smooth), lap_out = laplacian_std(&out);
    /* the input has almost none of the example's finest relief; the output has about as much */
    TN_CHECK(lap_in < 0.25 * lap_ex);
    TN_CHECK(lap_out > 0.6 * lap_ex && lap_out < 1.6 * lap_ex);
    /* and the coarse shape stays: the two agree after a blur of 6 px */
    TN_CHECK(tn_image_blur(&lo_in, &smooth, 6.0f) == TN_OK && tn_image_blur(&lo_out, &out, 6.0f) == TN_OK);
    for (i = 0; i < n; i++) diff += fabs(lo_out.data[i] - lo_in.data[i]), rel += fabs(out.data[i] - smooth.data[i]);
    TN_CHECK(diff < 0.35 * rel);
    for (i = 0; i < n; i++) TN_CHECK(isfinite(out.data[i]));
    tn_image_free(&ex);
    tn_image_free(&raw);
    tn_image_free(&smooth);
    tn_image_free(&out);
    tn_image_free(&lo_in);
    tn_image_free(&lo_out);
}

/* Mean |Laplacian| of the finest band (the map minus a Gaussian of 1 px). */
static double fine_laplacian(const tn_image *a)
{
    tn_image b = {0, 0, 0, NULL};
    double m = 0;
    int x, y, k, W = a->width, n = 0;
    if (tn_image_blur(&b, a, 1.0f)) return -1;
    for (y = 2; y < a->height - 2; y++)
        for (x = 2; x < W - 2; x++) {
            size_t i = (size_t)y * W + x, q[5];
            double l = 0;
            q[0] = i, q[1] = i - 1, q[2] = i + 1, q[3] = i - (size_t)W, q[4] = i + (size_t)W;
            for (k = 0; k < 5; k++) l += (k ? 1 : -4) * (a->data[q[k]] - b.data[q[k]]);
            m += fabs(l), n++;
        }
    tn_image_free(&b);
    return m / n;
}

TN_TEST(real_terrain_keeps_its_fine_roughness)
{
    /* detail from the bundled Alps DEM's central 128 px onto its four corner crops: the finest
       band's Laplacian comes out within 25 % of what each crop really has (1.44-1.69 x when each
       pixel took its own match's finest detail, which is white where matches disagree) */
    tn_image full = {0, 0, 0, NULL}, ex = {0, 0, 0, NULL};
    int c;
    TN_CHECK(tn_image_load(&full, "examples/data/alps_n47e009_256.png", NULL) == TN_OK);
    TN_CHECK(tn_image_crop(&ex, &full, 64, 64, 128, 128) == TN_OK);
    for (c = 0; c < 4; c++) {
        tn_image t = {0, 0, 0, NULL}, o = {0, 0, 0, NULL};
        double r;
        TN_CHECK(tn_image_crop(&t, &full, 128 * (c & 1), 128 * (c >> 1), 128, 128) == TN_OK);
        TN_CHECK(tn_fine_detail(&o, &ex, &t, NULL) == TN_OK);
        r = fine_laplacian(&o) / fine_laplacian(&t);
        printf("# corner %d: finest-band Laplacian detailed / real %.2f\n", c, r);
        TN_CHECK(r > 0.75 && r < 1.25);
        tn_image_free(&t);
        tn_image_free(&o);
    }
    tn_image_free(&ex);
    tn_image_free(&full);
}

TN_TEST(window_equals_whole_map_and_threads)
{
    tn_image ex = rough_dem(80, 64, 3), raw = rough_dem(150, 110, 4), t = {0, 0, 0, NULL}, whole = {0, 0, 0, NULL}, whole2 = {0, 0, 0, NULL};
    tn_image part = {0, 0, 0, NULL}, dpart = {0, 0, 0, NULL}, want = {0, 0, 0, NULL}, got = {0, 0, 0, NULL};
    tn_rect r, g;
    int halo = tn_fine_detail_halo(NULL), before = tn_get_threads();
    TN_CHECK(halo > 0);
    TN_CHECK(tn_image_blur(&t, &raw, 2.0f) == TN_OK);
    TN_CHECK(tn_fine_detail(&whole, &ex, &t, NULL) == TN_OK);
    tn_set_threads(1 + (before == 1));
    TN_CHECK(tn_fine_detail(&whole2, &ex, &t, NULL) == TN_OK);
    tn_set_threads(before);
    TN_CHECK(same_image(&whole, &whole2));
    /* an inner window: every side of the grown rectangle is inside the map */
    r.x = 60, r.y = 40, r.w = 30, r.h = 25;
    g = tn_rect_halo(r, halo, 150, 110);
    TN_CHECK(g.x > 0 && g.y > 0 && g.x + g.w < 150 && g.y + g.h < 110);
    TN_CHECK(tn_image_crop(&part, &t, g.x, g.y, g.w, g.h) == TN_OK && tn_fine_detail(&dpart, &ex, &part, NULL) == TN_OK);
    TN_CHECK(tn_image_crop(&got, &dpart, r.x - g.x, r.y - g.y, r.w, r.h) == TN_OK && tn_image_crop(&want, &whole, r.x, r.y, r.w, r.h) == TN_OK);
    TN_CHECK(same_image(&got, &want));
    tn_image_free(&ex), tn_image_free(&raw), tn_image_free(&t), tn_image_free(&whole), tn_image_free(&whole2);
    tn_image_free(&part), tn_image_free(&dpart), tn_image_free(&want), tn_image_free(&got);
}

TN_TEST(bad_inputs_fail_cleanly)
{
    tn_image ex = rough_dem(64, 64, 1), t = rough_dem(40, 40, 2), small = rough_dem(10, 40, 3), rgb = {0, 0, 0, NULL}, empty = {0, 0, 0, NULL};
    tn_image out = {0, 0, 0, NULL};
    tn_fine_detail_opts o;
    TN_CHECK(tn_image_create(&rgb, 40, 40, 3) == TN_OK);
    TN_CHECK(tn_fine_detail(&out, &empty, &t, NULL) == TN_ERR_EMPTY && !out.data);
    TN_CHECK(tn_fine_detail(&out, &ex, &empty, NULL) == TN_ERR_EMPTY && !out.data);
    TN_CHECK(tn_fine_detail(&out, &small, &t, NULL) == TN_ERR_INVALID_ARG && !out.data && strstr(tn_last_error(), "at least"));
    TN_CHECK(tn_fine_detail(&out, &ex, &rgb, NULL) == TN_ERR_INVALID_ARG && !out.data && strstr(tn_last_error(), "one channel"));
    ex.data[5] = NAN;
    TN_CHECK(tn_fine_detail(&out, &ex, &t, NULL) == TN_ERR_NUMERIC && !out.data);
    ex.data[5] = 1500;
    t.data[7] = INFINITY;
    TN_CHECK(tn_fine_detail(&out, &ex, &t, NULL) == TN_ERR_NUMERIC && !out.data);
    t.data[7] = 1500;
    memset(&o, 0, sizeof o);
    o.patch = 4;
    TN_CHECK(tn_fine_detail(&out, &ex, &t, &o) == TN_ERR_INVALID_ARG && !out.data && strstr(tn_last_error(), "patch 4"));
    TN_CHECK(tn_fine_detail_halo(&o) < 0);
    o.patch = 0;
    o.sigma = NAN;
    TN_CHECK(tn_fine_detail(&out, &ex, &t, &o) == TN_ERR_INVALID_ARG && !out.data);
    o.sigma = 0;
    o.probes = 65;
    TN_CHECK(tn_fine_detail(&out, &ex, &t, &o) == TN_ERR_INVALID_ARG && !out.data);
    o.probes = 1;
    o.patch = 3;
    TN_CHECK(tn_fine_detail(&out, &ex, &t, &o) == TN_OK && out.width == 40);
    tn_image_free(&out);
    tn_image_free(&ex), tn_image_free(&t), tn_image_free(&small), tn_image_free(&rgb);
}

int main(void)
{
    (void)tn_test_data;
    TN_RUN(smooth_terrain_takes_the_examples_detail);
    TN_RUN(real_terrain_keeps_its_fine_roughness);
    TN_RUN(window_equals_whole_map_and_threads);
    TN_RUN(bad_inputs_fail_cleanly);
    return tn_test_summary("test_finedetail");
}
