/* Tests of @@noise: range, determinism (seed and thread count), periodic tiling, octave
   structure, explicit noise, drawn-map blending and bad arguments. */
#include "terrainnet.h"
#include "tn_test.h"

static double mean_abs_step(const tn_image *img, int dx, int dy)
{
    double s = 0;
    int x, y, n = 0;
    for (y = 0; y + dy < img->height; y++)
        for (x = 0; x + dx < img->width; x++, n++) s += fabs(TN_PIXEL(img, x + dx, y + dy, 0) - TN_PIXEL(img, x, y, 0));
    return s / n;
}

TN_TEST(perlin_range_seed_and_threads)
{
    tn_image a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL}, c = {0, 0, 0, NULL};
    tn_perlin_opts o;
    float lo, hi;
    memset(&o, 0, sizeof o);
    o.seed = 42;
    tn_set_threads(1);
    TN_CHECK(tn_noise_perlin(&a, 300, 200, &o) == TN_OK);
    tn_set_threads(2);
    TN_CHECK(tn_noise_perlin(&b, 300, 200, &o) == TN_OK);
    tn_set_threads(0);
    TN_CHECK(memcmp(a.data, b.data, 300 * 200 * sizeof(float)) == 0);
    tn_image_range(&lo, &hi, &a);
    TN_CHECK(lo == 0.0f && hi == 1.0f);
    o.seed = 43;
    TN_CHECK(tn_noise_perlin(&c, 300, 200, &o) == TN_OK);
    TN_CHECK(memcmp(a.data, c.data, 300 * 200 * sizeof(float)) != 0);
    tn_image_free(&a);
    tn_image_free(&b);
    tn_image_free(&c);
}

/* A periodic map continues across its right and bottom edges as smoothly as inside. */
TN_TEST(perlin_periodic_tiles_seamlessly)
{
    tn_image a = {0, 0, 0, NULL};
    tn_perlin_opts o;
    double inner, seam_x = 0, seam_y = 0;
    int y, x;
    memset(&o, 0, sizeof o);
    o.periodic = 1;
    o.octaves = 5;
    o.frequency = 3;
    TN_CHECK(tn_noise_perlin(&a, 256, 128, &o) == TN_OK);
    inner = mean_abs_step(&a, 1, 0);
    for (y = 0; y < 128; y++) seam_x += fabs(TN_PIXEL(&a, 0, y, 0) - TN_PIXEL(&a, 255, y, 0));
    for (x = 0; x < 256; x++) seam_y += fabs(TN_PIXEL(&a, x, 0, 0) - TN_PIXEL(&a, x, 127, 0));
    TN_CHECK(seam_x / 128 < 3 * inner);
    TN_CHECK(seam_y / 256 < 3 * mean_abs_step(&a, 0, 1));
    tn_image_free(&a);
    o.periodic = 0;
    TN_CHECK(tn_noise_perlin(&a, 256, 128, &o) == TN_OK);
    seam_x = 0;
    for (y = 0; y < 128; y++) seam_x += fabs(TN_PIXEL(&a, 0, y, 0) - TN_PIXEL(&a, 255, y, 0));
    TN_CHECK(seam_x / 128 > 3 * mean_abs_step(&a, 1, 0)); /* an ordinary map does not wrap */
    tn_image_free(&a);
}

/* More octaves add fine detail: neighbouring pixels differ more. */
TN_TEST(perlin_octaves_add_detail)
{
    tn_image a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_perlin_opts o;
    memset(&o, 0, sizeof o);
    o.octaves = 1;
    TN_CHECK(tn_noise_perlin(&a, 256, 256, &o) == TN_OK);
    o.octaves = 8;
    TN_CHECK(tn_noise_perlin(&b, 256, 256, &o) == TN_OK);
    TN_CHECK(mean_abs_step(&b, 1, 0) > 1.5 * mean_abs_step(&a, 1, 0));
    tn_image_free(&a);
    tn_image_free(&b);
    o.octaves = 99;
    TN_CHECK(tn_noise_perlin(&a, 16, 16, &o) == TN_ERR_INVALID_ARG);
    TN_CHECK(tn_noise_perlin(&a, 0, 16, NULL) == TN_ERR_INVALID_ARG);
}

TN_TEST(explicit_noise_is_smooth_and_deterministic)
{
    tn_image a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_explicit_opts o;
    float lo, hi;
    memset(&o, 0, sizeof o);
    o.seed = 3;
    TN_CHECK(tn_noise_explicit(&a, 128, 128, &o) == TN_OK);
    TN_CHECK(tn_noise_explicit(&b, 128, 128, &o) == TN_OK);
    TN_CHECK(memcmp(a.data, b.data, 128 * 128 * sizeof(float)) == 0);
    tn_image_range(&lo, &hi, &a);
    TN_CHECK(lo == 0.0f && hi == 1.0f);
    TN_CHECK(mean_abs_step(&a, 1, 0) < 0.02); /* smoothed, unlike raw uniform noise (~0.33) */
    tn_image_free(&a);
    tn_image_free(&b);
}

TN_TEST(blend_follows_the_drawn_map)
{
    tn_image noise = {0, 0, 0, NULL}, drawn = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    int x, y;
    double left = 0, right = 0;
    TN_CHECK(tn_noise_perlin(&noise, 64, 64, NULL) == TN_OK);
    TN_CHECK(tn_image_create(&drawn, 16, 16, 1) == TN_OK);
    for (y = 0; y < 16; y++)
        for (x = 8; x < 16; x++) TN_PIXEL(&drawn, x, y, 0) = 255.0f; /* a raised right half */
    TN_CHECK(tn_noise_blend(&out, &noise, &drawn, 0.7f) == TN_OK);
    for (y = 0; y < 64; y++)
        for (x = 0; x < 24; x++) {
            left += TN_PIXEL(&out, x, y, 0);
            right += TN_PIXEL(&out, 63 - x, y, 0);
        }
    TN_CHECK(right > left + 0.5 * 64 * 24);
    TN_CHECK(tn_noise_blend(&out, &noise, &drawn, 1.5f) == TN_ERR_INVALID_ARG);
    tn_image_free(&noise);
    tn_image_free(&drawn);
    tn_image_free(&out);
}

int main(void)
{
    TN_RUN(perlin_range_seed_and_threads);
    TN_RUN(perlin_periodic_tiles_seamlessly);
    TN_RUN(perlin_octaves_add_detail);
    TN_RUN(explicit_noise_is_smooth_and_deterministic);
    TN_RUN(blend_follows_the_drawn_map);
    return tn_test_summary("test_noise");
}
