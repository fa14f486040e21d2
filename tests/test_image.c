/* test_image.c - @@image operations: crop, pad, resize, blur, gradient, slope, normals,
   hillshade, colour ramp.
   Build (repo): cc -std=c99 -O2 -I.. -I. test_image.c <tu with TERRAINNET_IMPLEMENTATION> -lm -pthread */
#include "terrainnet.h"
#include "tn_test.h"
#include <limits.h>

static uint32_t ti_hash(uint32_t h) /* lowbias32, the same as tests/refs/make_image_refs.py */
{
    h ^= h >> 16;
    h *= 0x7feb352du;
    h ^= h >> 15;
    h *= 0x846ca68bu;
    h ^= h >> 16;
    return h;
}

/* noise(x, y, c, seed) / 2^24 of make_image_refs.py */
static float ti_noise(int x, int y, int c, int s)
{
    uint32_t i = (uint32_t)(((long long)x + 7919LL * y + 104729LL * c + 1000003LL * s) & 0xFFFFFFFF);
    return (float)((double)(ti_hash(i) >> 8) / 16777216.0);
}

static int ti_noise_image(tn_image *img, int w, int h, int ch, int seed)
{
    int x, y, c;
    if (tn_image_create(img, w, h, ch)) return 0;
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++)
            for (c = 0; c < ch; c++) TN_PIXEL(img, x, y, c) = ti_noise(x, y, c, seed);
    return 1;
}

static int ti_same_bits(const tn_image *a, const tn_image *b)
{
    return a->width == b->width && a->height == b->height && a->channels == b->channels &&
           memcmp(a->data, b->data, (size_t)a->width * a->height * a->channels * sizeof(float)) == 0;
}

/* ---- crop / pad ---- */

TN_TEST(crop_copies_window_and_checks_bounds)
{
    tn_image a = {0, 0, 0, NULL}, c = {0, 0, 0, NULL}, keep;
    int x, y;
    TN_CHECK(ti_noise_image(&a, 9, 7, 2, 1));
    TN_CHECK(tn_image_crop(&c, &a, 2, 3, 5, 4) == TN_OK);
    TN_CHECK(c.width == 5 && c.height == 4 && c.channels == 2);
    for (y = 0; y < 4; y++)
        for (x = 0; x < 5; x++) TN_CHECK(TN_PIXEL(&c, x, y, 1) == TN_PIXEL(&a, x + 2, y + 3, 1));
    keep = c;
    TN_CHECK(tn_image_crop(&c, &a, 5, 0, 5, 1) == TN_ERR_INVALID_ARG); /* one column too wide */
    TN_CHECK(tn_image_crop(&c, &a, -1, 0, 2, 2) == TN_ERR_INVALID_ARG);
    TN_CHECK(tn_image_crop(&c, &a, 0, 0, 0, 2) == TN_ERR_INVALID_ARG);
    TN_CHECK(c.data == keep.data && c.width == 5);
    tn_image_free(&c);
    tn_image_free(&a);
}

TN_TEST(pad_modes_match_numpy)
{
    /* np.pad([[1,2,3],[4,5,6]], ((1,3),(5,4)), mode) */
    static const float reflect_row0[12] = {5, 4, 5, 6, 5, 4, 5, 6, 5, 4, 5, 6};
    static const float reflect_row1[12] = {2, 1, 2, 3, 2, 1, 2, 3, 2, 1, 2, 3};
    static const float edge_row0[12] = {1, 1, 1, 1, 1, 1, 2, 3, 3, 3, 3, 3};
    static const float edge_row5[12] = {4, 4, 4, 4, 4, 4, 5, 6, 6, 6, 6, 6};
    tn_image a = {0, 0, 0, NULL}, p = {0, 0, 0, NULL};
    int x, y;
    TN_CHECK(tn_image_create(&a, 3, 2, 1) == TN_OK);
    for (x = 0; x < 6; x++) a.data[x] = (float)(x + 1);
    TN_CHECK(tn_image_pad(&p, &a, 5, 1, 4, 3, TN_PAD_REFLECT) == TN_OK);
    TN_CHECK(p.width == 12 && p.height == 6);
    for (y = 0; y < 6; y++)
        for (x = 0; x < 12; x++) TN_CHECK(TN_PIXEL(&p, x, y, 0) == (y % 2 ? reflect_row1[x] : reflect_row0[x]));
    tn_image_free(&p);
    TN_CHECK(tn_image_pad(&p, &a, 5, 1, 4, 3, TN_PAD_EDGE) == TN_OK);
    for (x = 0; x < 12; x++) TN_CHECK(TN_PIXEL(&p, x, 0, 0) == edge_row0[x] && TN_PIXEL(&p, x, 5, 0) == edge_row5[x]);
    tn_image_free(&p);
    TN_CHECK(tn_image_pad(&p, &a, 1, 0, 0, 1, TN_PAD_ZERO) == TN_OK);
    TN_CHECK(p.width == 4 && p.height == 3 && TN_PIXEL(&p, 0, 0, 0) == 0.0f && TN_PIXEL(&p, 1, 0, 0) == 1.0f &&
             TN_PIXEL(&p, 3, 1, 0) == 6.0f && TN_PIXEL(&p, 2, 2, 0) == 0.0f);
    tn_image_free(&p);
    TN_CHECK(tn_image_pad(&p, &a, -1, 0, 0, 0, TN_PAD_ZERO) == TN_ERR_INVALID_ARG);
    TN_CHECK(tn_image_pad(&p, &a, 0, 0, 0, 0, (tn_pad_mode)7) == TN_ERR_INVALID_ARG);
    TN_CHECK(tn_image_pad(&p, &a, INT_MAX, 0, 0, 0, TN_PAD_ZERO) == TN_ERR_TOO_LARGE);
    TN_CHECK(p.data == NULL);
    tn_image_free(&a);
}

/* ---- resize ---- */

TN_TEST(resize_identity_and_nearest)
{
    tn_image a = {0, 0, 0, NULL}, r = {0, 0, 0, NULL};
    int f, x, y;
    TN_CHECK(ti_noise_image(&a, 13, 11, 3, 2));
    for (f = TN_RESIZE_BILINEAR; f <= TN_RESIZE_NEAREST; f++) { /* same size: exact copy */
        TN_CHECK(tn_image_resize(&r, &a, 13, 11, (tn_resize_filter)f) == TN_OK);
        TN_CHECK(ti_same_bits(&a, &r));
        tn_image_free(&r);
    }
    TN_CHECK(tn_image_resize(&r, &a, 26, 33, TN_RESIZE_NEAREST) == TN_OK);
    for (y = 0; y < 33; y++)
        for (x = 0; x < 26; x++) TN_CHECK(TN_PIXEL(&r, x, y, 2) == TN_PIXEL(&a, x / 2, y / 3, 2));
    tn_image_free(&r);
    TN_CHECK(tn_image_resize(&r, &a, 0, 5, TN_RESIZE_AREA) == TN_ERR_INVALID_ARG);
    TN_CHECK(tn_image_resize(&r, &a, 5, 5, (tn_resize_filter)9) == TN_ERR_INVALID_ARG);
    TN_CHECK(r.data == NULL);
    tn_image_free(&a);
}

TN_TEST(resize_linear_ramps_and_area)
{
    tn_image a = {0, 0, 0, NULL}, r = {0, 0, 0, NULL};
    int x, y;
    TN_CHECK(tn_image_create(&a, 20, 6, 1) == TN_OK);
    for (y = 0; y < 6; y++)
        for (x = 0; x < 20; x++) TN_PIXEL(&a, x, y, 0) = (float)x;
    /* pixel-centre alignment: output o samples source (o + 0.5) * 20 / 7 - 0.5 */
    TN_CHECK(tn_image_resize(&r, &a, 7, 4, TN_RESIZE_BILINEAR) == TN_OK);
    for (x = 0; x < 7; x++) {
        double s = (x + 0.5) * 20.0 / 7.0 - 0.5;
        TN_CHECK_NEAR(TN_PIXEL(&r, x, 2, 0), s, 1e-5);
    }
    tn_image_free(&r);
    TN_CHECK(tn_image_resize(&r, &a, 53, 6, TN_RESIZE_BICUBIC) == TN_OK); /* Keys reproduces lines */
    for (x = 0; x < 53; x++) {
        double s = (x + 0.5) * 20.0 / 53.0 - 0.5;
        if (s >= 1.0 && s <= 17.0) TN_CHECK_NEAR(TN_PIXEL(&r, x, 3, 0), s, 1e-4);
    }
    tn_image_free(&r);
    TN_CHECK(tn_image_resize(&r, &a, 10, 3, TN_RESIZE_AREA) == TN_OK); /* 2x2 means */
    for (x = 0; x < 10; x++) TN_CHECK_NEAR(TN_PIXEL(&r, x, 1, 0), 2 * x + 0.5, 1e-5);
    tn_image_free(&r);
    tn_image_free(&a);
    TN_CHECK(tn_image_create(&a, 3, 1, 1) == TN_OK); /* 3 -> 2: 1.5-pixel windows */
    a.data[0] = 1, a.data[1] = 10, a.data[2] = 100;
    TN_CHECK(tn_image_resize(&r, &a, 2, 1, TN_RESIZE_AREA) == TN_OK);
    TN_CHECK_NEAR(r.data[0], (1 + 0.5 * 10) / 1.5, 1e-5);
    TN_CHECK_NEAR(r.data[1], (0.5 * 10 + 100) / 1.5, 1e-5);
    tn_image_free(&r);
    tn_image_free(&a);
}

/* ---- blur ---- */

/* Made by make_image_refs.py (scipy 1.10.1): scipy.ndimage.gaussian_filter(img, sigma=(s, s, 0),
   mode='reflect') on float64, img = noise(x, y, c, 7) / 2^24; samples (x, y, c, value). */
static const struct {
    int w, h, ch;
    float sigma;
    double s[7][4];
} ti_blur_refs[] = {
    {37, 29, 2, 0.7f, {{0, 0, 0, 0.585247276}, {36, 0, 0, 0.605821445}, {0, 28, 0, 0.470598783}, {36, 28, 0, 0.279816529}, {18, 14, 0, 0.562754611}, {1, 9, 0, 0.514807649}, {35, 2, 1, 0.640181619}}},
    {37, 29, 2, 2.0f, {{0, 0, 0, 0.542977919}, {36, 0, 0, 0.578683654}, {0, 28, 0, 0.485064407}, {36, 28, 0, 0.394005483}, {18, 14, 0, 0.505328579}, {1, 9, 0, 0.544466879}, {35, 2, 1, 0.540895785}}},
    {37, 29, 2, 8.0f, {{0, 0, 0, 0.513241076}, {36, 0, 0, 0.533959362}, {0, 28, 0, 0.499967908}, {36, 28, 0, 0.482266357}, {18, 14, 0, 0.513717604}, {1, 9, 0, 0.509423117}, {35, 2, 1, 0.492060292}}},
    {100, 90, 3, 8.0f, {{0, 0, 0, 0.513222789}, {99, 0, 0, 0.461495446}, {0, 89, 2, 0.515451075}, {99, 89, 2, 0.526095721}, {50, 45, 2, 0.502629721}, {1, 30, 1, 0.486443591}, {98, 2, 1, 0.465013020}}},
    {5, 4, 1, 3.0f, {{0, 0, 0, 0.531140356}, {4, 0, 0, 0.552546418}, {0, 3, 0, 0.519107220}, {4, 3, 0, 0.543339827}, {2, 2, 0, 0.534436631}, {1, 1, 0, 0.531915218}, {3, 2, 0, 0.541629980}}},
    {6, 5, 1, 50.0f, {{0, 0, 0, 0.507157116}, {5, 0, 0, 0.507157115}, {0, 4, 0, 0.507156951}, {5, 4, 0, 0.507156951}, {3, 2, 0, 0.507156907}, {1, 1, 0, 0.507157375}, {4, 2, 0, 0.507157139}}},
};

TN_TEST(blur_matches_scipy)
{
    size_t i;
    int k;
    for (i = 0; i < sizeof ti_blur_refs / sizeof ti_blur_refs[0]; i++) {
        tn_image a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
        TN_CHECK(ti_noise_image(&a, ti_blur_refs[i].w, ti_blur_refs[i].h, ti_blur_refs[i].ch, 7));
        TN_CHECK(tn_image_blur(&b, &a, ti_blur_refs[i].sigma) == TN_OK);
        for (k = 0; k < 7; k++) {
            const double *s = ti_blur_refs[i].s[k];
            TN_CHECK_NEAR(TN_PIXEL(&b, (int)s[0], (int)s[1], (int)s[2]), s[3], 2e-6);
        }
        tn_image_free(&a);
        tn_image_free(&b);
    }
}

/* Independent double reference: direct sums over scipy's truncated kernel with the periodic
   half-sample reflection, x pass then y pass. */
static int ti_reflect(long long i, int n)
{
    long long p = 2LL * n, m = ((i % p) + p) % p;
    return (int)(m >= n ? p - 1 - m : m);
}

static void ti_blur_reference(const tn_image *a, double sigma, double *out)
{
    int W = a->width, H = a->height, C = a->channels, r = (int)(4.0 * sigma + 0.5), x, y, c, k;
    double *g = (double *)malloc((2 * (size_t)r + 1) * sizeof(double)), sum = 0;
    double *t = (double *)malloc((size_t)W * H * C * sizeof(double));
    for (k = -r; k <= r; k++) sum += g[k + r] = exp(-0.5 / (sigma * sigma) * k * k);
    for (k = 0; k <= 2 * r; k++) g[k] /= sum;
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++)
            for (c = 0; c < C; c++) {
                double acc = 0;
                for (k = -r; k <= r; k++) acc += g[k + r] * TN_PIXEL(a, ti_reflect(x + k, W), y, c);
                t[((size_t)y * W + x) * C + c] = acc;
            }
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++)
            for (c = 0; c < C; c++) {
                double acc = 0;
                for (k = -r; k <= r; k++) acc += g[k + r] * t[((size_t)ti_reflect(y + k, H) * W + x) * C + c];
                out[((size_t)y * W + x) * C + c] = acc;
            }
    free(g);
    free(t);
}

TN_TEST(blur_matches_direct_sum_everywhere)
{
    static const float sigmas[] = {0.1f, 0.7f, 2.5f, 8.0f, 17.0f, 30.0f, 300.0f};
    tn_image a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    double *ref = (double *)malloc(53 * 41 * 3 * sizeof(double)), worst;
    size_t i, k;
    TN_CHECK(ti_noise_image(&a, 53, 41, 3, 11));
    for (k = 0; k < sizeof sigmas / sizeof sigmas[0]; k++) {
        ti_blur_reference(&a, sigmas[k], ref);
        TN_CHECK(tn_image_blur(&b, &a, sigmas[k]) == TN_OK);
        worst = 0;
        for (i = 0; i < 53 * 41 * 3; i++)
            if (fabs(b.data[i] - ref[i]) > worst) worst = fabs(b.data[i] - ref[i]);
        /* sigma 300 >= 4 x size uses the flat folded kernel (error ~1e-5 of the image range) */
        TN_CHECK_NEAR(worst, 0.0, sigmas[k] > 100 ? 1e-4 : 2e-6);
        tn_image_free(&b);
    }
    free(ref);
    tn_image_free(&a);
}

TN_TEST(blur_in_place_and_thread_count_bit_identical)
{
    static const float sigmas[] = {1.3f, 8.0f};
    tn_image a = {0, 0, 0, NULL}, b1 = {0, 0, 0, NULL}, b2 = {0, 0, 0, NULL}, c = {0, 0, 0, NULL};
    int saved = tn_get_threads();
    size_t k;
    TN_CHECK(ti_noise_image(&a, 301, 203, 3, 5)); /* row length 903: a partial column block */
    for (k = 0; k < 2; k++) {
        tn_set_threads(1);
        TN_CHECK(tn_image_blur(&b1, &a, sigmas[k]) == TN_OK);
        tn_set_threads(2);
        TN_CHECK(tn_image_blur(&b2, &a, sigmas[k]) == TN_OK);
        TN_CHECK(ti_same_bits(&b1, &b2));
        tn_image_free(&b2);
        tn_set_threads(3);
        TN_CHECK(tn_image_copy(&c, &a) == TN_OK);
        TN_CHECK(tn_image_blur(&c, &c, sigmas[k]) == TN_OK);
        TN_CHECK(ti_same_bits(&b1, &c));
        tn_image_free(&c);
        tn_image_free(&b1);
    }
    tn_set_threads(saved);
    tn_image_free(&a);
}

TN_TEST(blur_edge_cases)
{
    tn_image a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL}, keep;
    size_t i;
    TN_CHECK(ti_noise_image(&a, 7, 1, 1, 3));
    TN_CHECK(tn_image_blur(&b, &a, 0.0f) == TN_OK); /* sigma 0 copies */
    TN_CHECK(ti_same_bits(&a, &b));
    keep = b;
    TN_CHECK(tn_image_blur(&b, &a, -1.0f) == TN_ERR_INVALID_ARG);
    TN_CHECK(tn_image_blur(&b, &a, (float)NAN) == TN_ERR_INVALID_ARG);
    TN_CHECK(b.data == keep.data);
    tn_image_free(&b);
    for (i = 0; i < 7; i++) a.data[i] = 0.25f; /* constant stays constant, 1-row image */
    TN_CHECK(tn_image_blur(&b, &a, 5.0f) == TN_OK);
    for (i = 0; i < 7; i++) TN_CHECK_NEAR(b.data[i], 0.25, 1e-6);
    tn_image_free(&b);
    tn_image_free(&a);
    TN_CHECK(tn_image_blur(&b, &a, 1.0f) == TN_ERR_INVALID_ARG); /* freed: NULL data */
}

/* ---- terrain ---- */

static int ti_plane(tn_image *img, int w, int h, float ax, float ay)
{
    int x, y;
    if (tn_image_create(img, w, h, 1)) return 0;
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++) TN_PIXEL(img, x, y, 0) = ax * x + ay * y;
    return 1;
}

/* A smooth hill stored in 8 bits, about a step per pixel: the step is found, and dequantizing stays within half a step
   of the stored heights while coming back nearer the hill, without the steps' curvature. */
TN_TEST(height_step_and_dequantize_undo_8_bit_terraces)
{
    const int W = 64, H = 48;
    const float step = 100.0f / 255.0f;
    tn_image hill = {0, 0, 0, NULL}, q = {0, 0, 0, NULL}, d = {0, 0, 0, NULL}, keep;
    double eq = 0, ed = 0, lq = 0, ld = 0;
    int x, y;
    TN_CHECK(tn_image_create(&hill, W, H, 1) == TN_OK);
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) TN_PIXEL(&hill, x, y, 0) = 50.0f + 20.0f * sinf(0.021f * x) * cosf(0.027f * y) + 0.05f * x;
    TN_CHECK(tn_image_copy(&q, &hill) == TN_OK);
    for (x = 0; x < W * H; x++) q.data[x] = step * floorf(q.data[x] / step + 0.5f);
    TN_CHECK_NEAR(tn_image_height_step(&q, 0), step, 1e-4f);
    TN_CHECK_NEAR(tn_image_height_step(&q, 1), step, 1e-4f); /* coarse: about a step per pixel */
    TN_CHECK(tn_image_height_step(&hill, 0) == 0.0f); /* heights stored as floats */
    { /* a rough 16-bit DEM in metres: fine steps, many of them per pixel, on heights where float32 rounds */
        tn_image fine = {0, 0, 0, NULL};
        const float f = 4000.0f / 65535.0f;
        TN_CHECK(tn_image_copy(&fine, &hill) == TN_OK);
        for (y = 0; y < H; y++)
            for (x = 0; x < W; x++) { /* rough, with a Laplacian of metres per pixel */
                float *v = &TN_PIXEL(&fine, x, y, 0);
                *v = 600.0f + f * floorf(((*v - 30.0f) * 10.0f + 3.0f * sinf(1.3f * x) * sinf(1.1f * y)) / f + 0.5f);
            }
        TN_CHECK_NEAR(tn_image_height_step(&fine, 0), f, 1e-3f * f);
        TN_CHECK(tn_image_height_step(&fine, 1) == 0.0f); /* fine against its curvature */
        tn_image_free(&fine);
    }
    TN_CHECK(tn_image_dequantize(&d, &q, step) == TN_OK);
    TN_CHECK(d.width == W && d.height == H && d.channels == 1);
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) {
            float e = TN_PIXEL(&d, x, y, 0) - TN_PIXEL(&q, x, y, 0);
            TN_CHECK(fabsf(e) <= 0.5f * step * 1.0001f);
            eq += pow(TN_PIXEL(&q, x, y, 0) - TN_PIXEL(&hill, x, y, 0), 2);
            ed += pow(TN_PIXEL(&d, x, y, 0) - TN_PIXEL(&hill, x, y, 0), 2);
            if (x > 0 && y > 0 && x < W - 1 && y < H - 1) {
                lq += fabsf(TN_PIXEL(&q, x - 1, y, 0) + TN_PIXEL(&q, x + 1, y, 0) + TN_PIXEL(&q, x, y - 1, 0) + TN_PIXEL(&q, x, y + 1, 0) - 4 * TN_PIXEL(&q, x, y, 0));
                ld += fabsf(TN_PIXEL(&d, x - 1, y, 0) + TN_PIXEL(&d, x + 1, y, 0) + TN_PIXEL(&d, x, y - 1, 0) + TN_PIXEL(&d, x, y + 1, 0) - 4 * TN_PIXEL(&d, x, y, 0));
            }
        }
    printf("# dequantize: RMS error %.4f -> %.4f m, mean |Laplacian| %.4f -> %.4f\n", sqrt(eq / (W * H)), sqrt(ed / (W * H)), lq / ((W - 2) * (H - 2)),
           ld / ((W - 2) * (H - 2)));
    TN_CHECK(ed < 0.5 * eq);
    TN_CHECK(ld < 0.25 * lq);
    keep = d;
    TN_CHECK(tn_image_dequantize(&d, &q, NAN) == TN_ERR_INVALID_ARG && d.data == keep.data);
    TN_CHECK(tn_image_dequantize(&q, &q, 0) == TN_OK && fabsf(tn_image_height_step(&q, 0) - step) < 1e-4f); /* step 0 copies; in place */
    tn_set_threads(1);
    TN_CHECK(tn_image_dequantize(&q, &q, step) == TN_OK && ti_same_bits(&q, &d)); /* in place, and on one thread */
    tn_set_threads(0);
    tn_image_free(&hill);
    tn_image_free(&q);
    tn_image_free(&d);
}

TN_TEST(gradient_slope_normals_of_a_plane)
{
    tn_image d = {0, 0, 0, NULL}, gx = {0, 0, 0, NULL}, gy = {0, 0, 0, NULL}, s = {0, 0, 0, NULL}, n = {0, 0, 0, NULL};
    double len = sqrt(4.0 / 0.25 + 9.0 / 4.0 + 1.0);
    int x, y;
    TN_CHECK(ti_plane(&d, 9, 6, 2.0f, 3.0f));
    TN_CHECK(tn_image_gradient(&gx, &gy, &d, 0.5f, 2.0f) == TN_OK);
    TN_CHECK(tn_image_slope(&s, &d, 0.0f, 0.0f) == TN_OK);
    TN_CHECK(tn_image_normals(&n, &d, 0.5f, 2.0f, 1.0f) == TN_OK);
    TN_CHECK(n.channels == 3);
    for (y = 0; y < 6; y++)
        for (x = 0; x < 9; x++) { /* borders too: one-sided differences are exact on a plane */
            TN_CHECK_NEAR(TN_PIXEL(&gx, x, y, 0), 4.0, 1e-5);
            TN_CHECK_NEAR(TN_PIXEL(&gy, x, y, 0), 1.5, 1e-5);
            TN_CHECK_NEAR(TN_PIXEL(&s, x, y, 0), atan(sqrt(13.0)) * 180.0 / 3.14159265358979, 1e-4);
            TN_CHECK_NEAR(TN_PIXEL(&n, x, y, 0), -4.0 / len, 1e-5);  /* rises east: normal tilts west */
            TN_CHECK_NEAR(TN_PIXEL(&n, x, y, 1), 1.5 / len, 1e-5);   /* rises south: tilts north */
            TN_CHECK_NEAR(TN_PIXEL(&n, x, y, 2), 1.0 / len, 1e-5);
        }
    tn_image_free(&gx);
    tn_image_free(&gy);
    TN_CHECK(tn_image_gradient(NULL, &gy, &d, 1.0f, 1.0f) == TN_OK); /* either output may be NULL */
    tn_image_free(&gy);
    tn_image_free(&s);
    tn_image_free(&n);
    tn_image_free(&d);
    TN_CHECK(tn_image_slope(&s, &d, 1.0f, 1.0f) == TN_ERR_INVALID_ARG);
}

TN_TEST(hillshade_lighting_and_auto_scale)
{
    tn_image d = {0, 0, 0, NULL}, e = {0, 0, 0, NULL}, w = {0, 0, 0, NULL}, h1 = {0, 0, 0, NULL}, h2 = {0, 0, 0, NULL}, flat = {0, 0, 0, NULL};
    tn_hillshade_opts o;
    size_t i;
    int x, y;
    memset(&o, 0, sizeof o);
    o.dx = o.dy = 1.0f;
    TN_CHECK(ti_plane(&d, 8, 8, 0.0f, 0.0f));
    TN_CHECK(tn_image_hillshade(&flat, &d, &o) == TN_OK); /* flat: sin(45 deg) */
    for (i = 0; i < 64; i++) TN_CHECK_NEAR(flat.data[i], sqrt(0.5), 1e-6);
    tn_image_free(&d);
    TN_CHECK(ti_plane(&e, 8, 8, 1.0f, 0.0f)); /* rises east: faces the north-west light */
    TN_CHECK(ti_plane(&w, 8, 8, -1.0f, 0.0f));
    TN_CHECK(tn_image_hillshade(&h1, &e, &o) == TN_OK);
    TN_CHECK(tn_image_hillshade(&h2, &w, &o) == TN_OK);
    TN_CHECK_NEAR(h1.data[27], (0.5 + sqrt(0.5)) / sqrt(2.0), 1e-5); /* n.L by hand */
    TN_CHECK(h1.data[27] > flat.data[27] && h2.data[27] < flat.data[27]);
    tn_image_free(&h1);
    tn_image_free(&h2);
    tn_image_free(&e);
    tn_image_free(&w);
    /* auto spacing: heights in metres or in [0, 1] give the same picture */
    TN_CHECK(ti_noise_image(&d, 40, 30, 1, 9));
    TN_CHECK(tn_image_create(&e, 40, 30, 1) == TN_OK);
    for (y = 0; y < 30; y++)
        for (x = 0; x < 40; x++) TN_PIXEL(&e, x, y, 0) = 1500.0f + 2000.0f * TN_PIXEL(&d, x, y, 0);
    TN_CHECK(tn_image_hillshade(&h1, &d, NULL) == TN_OK);
    TN_CHECK(tn_image_hillshade(&h2, &e, NULL) == TN_OK);
    for (i = 0; i < 1200; i++) {
        TN_CHECK_NEAR(h1.data[i], h2.data[i], 1e-4);
        TN_CHECK(h1.data[i] >= 0.0f && h1.data[i] <= 1.0f);
    }
    o.dx = -1.0f;
    TN_CHECK(tn_image_hillshade(&h2, &e, &o) == TN_ERR_INVALID_ARG);
    tn_image_free(&h1);
    tn_image_free(&h2);
    tn_image_free(&d);
    tn_image_free(&e);
    tn_image_free(&flat);
}

TN_TEST(colour_ramp_runs_from_water_to_snow)
{
    tn_image d = {0, 0, 0, NULL}, c = {0, 0, 0, NULL}, c2 = {0, 0, 0, NULL};
    int x;
    TN_CHECK(tn_image_create(&d, 101, 1, 1) == TN_OK);
    for (x = 0; x < 101; x++) d.data[x] = 100.0f + 10.0f * x;
    TN_CHECK(tn_image_colour_ramp(&c, &d, 100.0f, 1100.0f) == TN_OK);
    TN_CHECK(c.channels == 3);
    TN_CHECK(c.data[2] > c.data[0] && c.data[2] > c.data[1]);           /* lowest: blue */
    TN_CHECK(c.data[3 * 25 + 1] > c.data[3 * 25 + 0] && c.data[3 * 25 + 1] > c.data[3 * 25 + 2]); /* green */
    TN_CHECK(c.data[3 * 100] > 0.95f && c.data[3 * 100 + 1] > 0.95f && c.data[3 * 100 + 2] > 0.95f); /* snow */
    for (x = 0; x < 3 * 101; x++) TN_CHECK(c.data[x] >= 0.0f && c.data[x] <= 1.0f);
    TN_CHECK(tn_image_colour_ramp(&c2, &d, 0.0f, 0.0f) == TN_OK); /* lo == hi: the DEM's own range */
    TN_CHECK(ti_same_bits(&c, &c2));
    tn_image_free(&c);
    tn_image_free(&c2);
    d.data[5] = (float)NAN;
    TN_CHECK(tn_image_colour_ramp(&c, &d, 100.0f, 1100.0f) == TN_OK); /* NaN: deepest colour */
    TN_CHECK(c.data[15] >= 0.0f && c.data[15] <= 1.0f);
    tn_image_free(&c);
    tn_image_free(&d);
}

int main(void)
{
    (void)tn_test_data;
    TN_RUN(crop_copies_window_and_checks_bounds);
    TN_RUN(pad_modes_match_numpy);
    TN_RUN(resize_identity_and_nearest);
    TN_RUN(resize_linear_ramps_and_area);
    TN_RUN(blur_matches_scipy);
    TN_RUN(blur_matches_direct_sum_everywhere);
    TN_RUN(blur_in_place_and_thread_count_bit_identical);
    TN_RUN(blur_edge_cases);
    TN_RUN(height_step_and_dequantize_undo_8_bit_terraces);
    TN_RUN(gradient_slope_normals_of_a_plane);
    TN_RUN(hillshade_lighting_and_auto_scale);
    TN_RUN(colour_ramp_runs_from_water_to_snow);
    return tn_test_summary("test_image");
}
