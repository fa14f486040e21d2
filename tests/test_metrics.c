/* test_metrics.c - @@metrics: SSIM / PSNR / RMSE / MAE against scikit-image and numpy.
   Build (repo): cc -std=c99 -O2 -I.. -I. test_metrics.c <tu with TERRAINNET_IMPLEMENTATION> -lm -pthread */
#include "terrainnet.h"
#include "tn_test.h"

/* Integer recipes shared with tests/refs/make_image_refs.py (see there). */
static uint32_t tm_hash(uint32_t h)
{
    h ^= h >> 16;
    h *= 0x7feb352du;
    h ^= h >> 15;
    h *= 0x846ca68bu;
    h ^= h >> 16;
    return h;
}

static long long tm_noise(long long x, long long y, long long c, long long s)
{
    return (long long)(tm_hash((uint32_t)((x + 7919 * y + 104729 * c + 1000003 * s) & 0xFFFFFFFF)) >> 8);
}

static long long tm_smooth(long long x, long long y, long long c, long long s)
{
    long long gx = x / 8, gy = y / 8, fx = x % 8, fy = y % 8;
    return ((8 - fx) * (8 - fy) * tm_noise(gx, gy, c, s) + fx * (8 - fy) * tm_noise(gx + 1, gy, c, s) +
            (8 - fx) * fy * tm_noise(gx, gy + 1, c, s) + fx * fy * tm_noise(gx + 1, gy + 1, c, s)) >> 6;
}

/* The pair `kind` of make_image_refs.py: values are integers / 2^shift, exact in float32. */
static int tm_make_pair(int kind, int w, int h, int ch, tn_image *a, tn_image *b)
{
    int x, y, c;
    if (tn_image_create(a, w, h, ch) || tn_image_create(b, w, h, ch)) return 0;
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++)
            for (c = 0; c < ch; c++) {
                long long r, n;
                double scale = 1.0 / 16777216.0;
                if (kind == 0) {
                    r = tm_smooth(x, y, c, 1);
                    n = (3 * r + tm_noise(x, y, c, 2)) >> 2;
                } else if (kind == 1) {
                    r = tm_noise(x, y, c, 3);
                    n = tm_smooth(x, y, c, 4);
                } else {
                    long long s5 = tm_smooth(x, y, c, 5) >> 8;
                    r = (1LL << 23) + s5;
                    n = (1LL << 23) + ((s5 * 7 + (tm_noise(x, y, c, 6) >> 8)) >> 3);
                    scale = 1.0 / 1024.0;
                }
                TN_PIXEL(a, x, y, c) = (float)((double)r * scale);
                TN_PIXEL(b, x, y, c) = (float)((double)n * scale);
            }
    return 1;
}

/* Made by make_image_refs.py with numpy 1.24.2, scipy 1.10.1, scikit-image 0.19.3:
   structural_similarity(a, b, gaussian_weights=True, sigma=1.5, use_sample_covariance=False,
   data_range=R[, channel_axis=-1]) on float64 copies, and 10 log10(R^2 / mse).
   data_range 0 = the reference's max - min. */
static const struct {
    int kind, w, h, ch;
    double range, ssim, psnr;
} tm_refs[] = {
    {0, 67, 45, 1, 1.0, 0.511760357885, 21.5684661184},  /* float32 skimage: 0.511760403 */
    {1, 67, 45, 1, 1.0, 0.003793552104, 9.1209124189},   /* float32 skimage: 0.003793561 */
    {0, 40, 33, 3, 1.0, 0.537315990060, 21.3541805459},  /* float32 skimage: 0.537316084 */
    {0, 128, 128, 1, 0.0, 0.563193818912, 21.1722535494}, /* float32 skimage: 0.563193835 */
    {2, 61, 70, 1, 0.0, 0.868677095701, 27.1869482474},  /* float32 skimage: 0.861154411 (float32 loss) */
    {0, 11, 11, 1, 1.0, 0.611000389719, 21.8455746711},  /* float32 skimage: 0.611003935 */
    {1, 32, 19, 2, 0.5, 0.009869198874, 3.2354826230},   /* float32 skimage: 0.009869158 */
};

TN_TEST(ssim_matches_skimage)
{
    size_t i;
    for (i = 0; i < sizeof tm_refs / sizeof tm_refs[0]; i++) {
        tn_image a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
        double s = -1.0;
        tn_metrics m;
        TN_CHECK(tm_make_pair(tm_refs[i].kind, tm_refs[i].w, tm_refs[i].h, tm_refs[i].ch, &a, &b));
        TN_CHECK(tn_ssim(&s, &a, &b, tm_refs[i].range) == TN_OK);
        TN_CHECK_NEAR(s, tm_refs[i].ssim, 1e-7); /* acceptance is 1e-4; double gets ~1e-12 */
        TN_CHECK(tn_compare(&m, &a, &b, tm_refs[i].range) == TN_OK);
        TN_CHECK(m.ssim == s);
        TN_CHECK_NEAR(m.psnr, tm_refs[i].psnr, 1e-7);
        tn_image_free(&a);
        tn_image_free(&b);
    }
}

TN_TEST(compare_errors_and_identity)
{
    tn_image a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_metrics m;
    double s;
    size_t i, n;
    TN_CHECK(tm_make_pair(0, 30, 20, 2, &a, &b));
    n = 30 * 20 * 2;
    for (i = 0; i < n; i++) b.data[i] = a.data[i] + ((i & 1) ? 0.25f : -0.125f); /* float rounding ~6e-8 */
    TN_CHECK(tn_compare(&m, &a, &b, 2.0) == TN_OK);
    TN_CHECK_NEAR(m.mae, (0.25 + 0.125) / 2, 1e-7);
    TN_CHECK_NEAR(m.rmse, sqrt((0.0625 + 0.015625) / 2), 1e-7);
    TN_CHECK_NEAR(m.psnr, 20 * log10(2.0 / m.rmse), 1e-9);
    TN_CHECK(m.ssim < 1.0);
    TN_CHECK(tn_compare(&m, &a, &a, 1.0) == TN_OK);
    TN_CHECK_NEAR(m.ssim, 1.0, 1e-12);
    TN_CHECK(m.rmse == 0.0 && m.mae == 0.0 && m.psnr > 1e300);
    /* SSIM is symmetric in its arguments when the range is given */
    TN_CHECK(tn_ssim(&s, &a, &b, 1.0) == TN_OK);
    TN_CHECK(tn_compare(&m, &b, &a, 1.0) == TN_OK);
    TN_CHECK_NEAR(m.ssim, s, 1e-12);
    tn_image_free(&a);
    tn_image_free(&b);
}

TN_TEST(ssim_same_for_any_thread_count)
{
    tn_image a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    double s1 = 0, s2 = 1, s3 = 2;
    int saved = tn_get_threads();
    TN_CHECK(tm_make_pair(1, 301, 257, 1, &a, &b));
    tn_set_threads(1);
    TN_CHECK(tn_ssim(&s1, &a, &b, 1.0) == TN_OK);
    tn_set_threads(2);
    TN_CHECK(tn_ssim(&s2, &a, &b, 1.0) == TN_OK);
    tn_set_threads(3);
    TN_CHECK(tn_ssim(&s3, &a, &b, 1.0) == TN_OK);
    tn_set_threads(saved);
    TN_CHECK(memcmp(&s1, &s2, sizeof s1) == 0 && memcmp(&s1, &s3, sizeof s1) == 0);
    tn_image_free(&a);
    tn_image_free(&b);
}

TN_TEST(bad_inputs_fail_and_leave_output)
{
    tn_image a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL}, c = {0, 0, 0, NULL}, small = {0, 0, 0, NULL};
    tn_metrics m;
    double s = 42.0;
    m.ssim = 42.0;
    TN_CHECK(tm_make_pair(0, 20, 20, 1, &a, &b));
    TN_CHECK(tn_image_create(&c, 20, 21, 1) == TN_OK);
    TN_CHECK(tn_ssim(&s, &a, &c, 1.0) == TN_ERR_SHAPE);
    TN_CHECK(tn_compare(&m, &a, &c, 1.0) == TN_ERR_SHAPE);
    TN_CHECK(strstr(tn_last_error(), "20 x 21") != NULL);
    TN_CHECK(tn_image_create(&small, 10, 30, 1) == TN_OK);
    TN_CHECK(tn_ssim(&s, &small, &small, 1.0) == TN_ERR_INVALID_ARG);
    TN_CHECK(tn_ssim(&s, NULL, &b, 1.0) == TN_ERR_INVALID_ARG);
    b.data[0] = (float)NAN; /* a corner: only reaches the cropped map through the window edge */
    TN_CHECK(tn_ssim(&s, &a, &b, 1.0) == TN_ERR_NUMERIC);
    TN_CHECK(tn_compare(&m, &a, &b, 1.0) == TN_ERR_NUMERIC);
    b.data[0] = 0.5f;
    a.data[399] = (float)INFINITY;
    TN_CHECK(tn_ssim(&s, &a, &b, 1.0) == TN_ERR_NUMERIC);
    TN_CHECK(tn_ssim(&s, &a, &b, 0.0) == TN_ERR_NUMERIC);
    a.data[399] = 0.5f;
    TN_CHECK(tn_ssim(&s, &c, &c, 0.0) == TN_ERR_INVALID_ARG); /* constant reference, no range */
    TN_CHECK(tn_ssim(&s, &a, &b, (double)NAN) == TN_ERR_INVALID_ARG);
    TN_CHECK(s == 42.0 && m.ssim == 42.0);
    tn_image_free(&a);
    tn_image_free(&b);
    tn_image_free(&c);
    tn_image_free(&small);
}

int main(void)
{
    (void)tn_test_data;
    TN_RUN(ssim_matches_skimage);
    TN_RUN(compare_errors_and_identity);
    TN_RUN(ssim_same_for_any_thread_count);
    TN_RUN(bad_inputs_fail_and_leave_output);
    return tn_test_summary("test_metrics");
}
