/* test_texgan.c - @@texgan: spatial GAN training, checkpoints, tiled synthesis, detail maps. */
#define TN_INTERNALS /* private tn__ code: the header's internals block */
#include "terrainnet.h"
#include "tn_test.h"

static void tiny_opts(tn_texgan_opts *o)
{
    tn_test_tiny_texgan_opts(o);
    o->lr = 1e-3f;
}

static float m_mean(const tn_image *im, int c)
{
    double s = 0;
    int x, y;
    for (y = 0; y < im->height; y++)
        for (x = 0; x < im->width; x++) s += TN_PIXEL(im, x, y, c);
    return (float)(s / ((double)im->width * im->height));
}

static double max_abs_diff(const tn_image *a, const tn_image *b)
{
    size_t i, n = (size_t)a->width * a->height * a->channels;
    double d = 0;
    if (a->width != b->width || a->height != b->height || a->channels != b->channels) return 1e30;
    for (i = 0; i < n; i++)
        if (fabs((double)a->data[i] - b->data[i]) > d) d = fabs((double)a->data[i] - b->data[i]);
    return d;
}

TN_TEST(training_steps_stay_finite_and_move_the_generator)
{
    tn_image ex = tn_test_exemplar(40, 36, 3, 1);
    tn_texgan m;
    tn_texgan_opts o;
    tn_texgan_stats s;
    tn_tensor *w;
    size_t k;
    int finite = 1;
    tiny_opts(&o);
    o.train.max_iters = 8;
    TN_CHECK(tn_texgan_train(&m, &ex, &o, &s) == TN_OK);
    TN_CHECK(s.iterations == 8 && m.iterations == 8);
    TN_CHECK(s.loss_d == s.loss_d && s.loss_g == s.loss_g);
    TN_CHECK(s.loss_d >= 0 && s.loss_d < 4); /* hinge D loss starts near 2 */
    TN_CHECK(s.seconds_per_iter > 0);
    w = tn_params_find(m.weights, "g.w0");
    TN_CHECK(w != NULL);
    for (k = 0; w && k < w->numel; k++) finite &= w->data[k] == w->data[k];
    TN_CHECK(finite);
    TN_CHECK_NEAR(m.mean[0], 0.4, 0.15);
    tn_texgan_free(&m);
    tn_image_free(&ex);
}

TN_TEST(checkpoint_resume_continues_identically)
{
    const char *ck1 = "build/test/texgan_a.ckpt", *ck2 = "build/test/texgan_b.ckpt";
    tn_image ex = tn_test_exemplar(40, 36, 3, 2);
    tn_texgan full, part, resumed;
    tn_texgan_opts o;
    tn_texgan_stats s;
    tiny_opts(&o);
    o.augment = 1; /* flipped/transposed real patches: the flag is part of the saved state */
    o.train.checkpoint = ck1;
    o.train.max_iters = 6;
    TN_CHECK(tn_texgan_train(&full, &ex, &o, NULL) == TN_OK);
    o.train.checkpoint = ck2;
    o.train.max_iters = 3; /* "killed" after 3 iterations: the checkpoint holds them */
    TN_CHECK(tn_texgan_train(&part, &ex, &o, NULL) == TN_OK);
    o.train.max_iters = 6;
    o.train.resume = 1;
    o.train.seed = 999; /* ignored on resume: the state comes from the file */
    TN_CHECK(tn_texgan_train(&resumed, &ex, &o, &s) == TN_OK);
    TN_CHECK(s.resumed_from == 3 && s.iterations == 6);
    TN_CHECK(tn_test_same_params(full.weights, resumed.weights, 1));
    TN_CHECK(!tn_test_same_params(full.weights, part.weights, 1));
    /* a checkpoint of another channel count is refused */
    {
        tn_image grey = tn_test_exemplar(40, 36, 1, 2);
        tn_texgan bad;
        TN_CHECK(tn_texgan_train(&bad, &grey, &o, NULL) == TN_ERR_SHAPE);
        tn_image_free(&grey);
    }
    tn_texgan_free(&full);
    tn_texgan_free(&part);
    tn_texgan_free(&resumed);
    tn_image_free(&ex);
}

static tn_status trained_tiny_scaled(tn_texgan *m, int channels, int periodic, int scale)
{
    tn_image ex = tn_test_exemplar(40, 36, channels, 3);
    tn_texgan_opts o;
    tn_status st;
    tiny_opts(&o);
    o.noise_global = 2;
    o.noise_periodic = periodic;
    o.scale = scale;
    o.train.max_iters = 2;
    st = tn_texgan_train(m, &ex, &o, NULL);
    tn_image_free(&ex);
    return st;
}

static tn_status trained_tiny(tn_texgan *m, int channels, int periodic) { return trained_tiny_scaled(m, channels, periodic, 1); }

TN_TEST(tiled_synthesis_equals_one_pass)
{
    tn_texgan m;
    tn_image one = {0, 0, 0, NULL}, tiled = {0, 0, 0, NULL}, win = {0, 0, 0, NULL}, crop = {0, 0, 0, NULL};
    int tiles;
    TN_CHECK(trained_tiny(&m, 3, 2) == TN_OK);
    TN_CHECK(tn_texgan_synthesize_window(&one, &m, 42, 0, 0, 61, 45) == TN_OK);
    for (tiles = 1; tiles <= 5; tiles += 2) { /* tiles of 4, 12, 20 px with 4 cells of overlap */
        tn_image_free(&tiled);
        TN_CHECK(tn_image_create(&tiled, 61, 45, 3) == TN_OK);
        TN_CHECK(tn_texgan_synthesize_stream(&m, 42, 61, 45, tiles, tn__tg_collect_band, &tiled) == TN_OK);
        TN_CHECK(max_abs_diff(&one, &tiled) <= 1e-6);
    }
    /* any window of the infinite texture is the same pixels */
    TN_CHECK(tn_texgan_synthesize_window(&win, &m, 42, 13, 7, 30, 21) == TN_OK);
    TN_CHECK(tn_image_crop(&crop, &one, 13, 7, 30, 21) == TN_OK);
    TN_CHECK(max_abs_diff(&win, &crop) <= 1e-6);
    /* another seed differs; the output stays inside the exemplar range */
    tn_image_free(&win);
    TN_CHECK(tn_texgan_synthesize_window(&win, &m, 43, 0, 0, 61, 45) == TN_OK);
    TN_CHECK(max_abs_diff(&win, &one) > 1e-3);
    {
        float lo, hi;
        tn_image_range(&lo, &hi, &one);
        TN_CHECK(lo >= m.lo && hi <= m.hi);
    }
    tn_image_free(&one);
    tn_image_free(&tiled);
    tn_image_free(&win);
    tn_image_free(&crop);
    tn_texgan_free(&m);
}

/* scale 2: the generator learns the half-size exemplar; output is its bilinear upsampling,
   sampled from global coordinates, so tiles and windows still agree exactly */
TN_TEST(scaled_model_tiles_exactly)
{
    tn_texgan m, l;
    tn_image one = {0, 0, 0, NULL}, tiled = {0, 0, 0, NULL}, win = {0, 0, 0, NULL}, crop = {0, 0, 0, NULL};
    TN_CHECK(trained_tiny_scaled(&m, 3, 0, 2) == TN_OK);
    TN_CHECK(m.scale == 2);
    TN_CHECK(tn_texgan_save("build/test/texgan_s2.tnw", &m) == TN_OK && tn_texgan_load(&l, "build/test/texgan_s2.tnw") == TN_OK);
    TN_CHECK(l.scale == 2);
    TN_CHECK(tn_texgan_synthesize_window(&one, &l, 5, 0, 0, 57, 41) == TN_OK);
    TN_CHECK(tn_image_create(&tiled, 57, 41, 3) == TN_OK);
    TN_CHECK(tn_texgan_synthesize_stream(&l, 5, 57, 41, 1, tn__tg_collect_band, &tiled) == TN_OK);
    TN_CHECK(max_abs_diff(&one, &tiled) <= 1e-6);
    TN_CHECK(tn_texgan_synthesize_window(&win, &l, 5, 9, 6, 31, 20) == TN_OK);
    TN_CHECK(tn_image_crop(&crop, &one, 9, 6, 31, 20) == TN_OK);
    TN_CHECK(max_abs_diff(&win, &crop) <= 1e-6);
    /* upsampled: neighbouring pixels inside one low pixel pair differ less than across the image */
    TN_CHECK(fabs(TN_PIXEL(&one, 20, 20, 0) - TN_PIXEL(&one, 21, 20, 0)) < 0.5);
    tn_image_free(&one);
    tn_image_free(&tiled);
    tn_image_free(&win);
    tn_image_free(&crop);
    tn_texgan_free(&m);
    tn_texgan_free(&l);
}

TN_TEST(fast_generator_matches_the_training_graph)
{
    tn_texgan m;
    tn_ctx *c = tn_ctx_create();
    tn_tensor *z, *a, *b;
    size_t k;
    double d = 0;
    uint64_t seed = 9;
    TN_CHECK(trained_tiny(&m, 3, 0) == TN_OK);
    tn_ctx_set_grad(c, 0);
    z = tn_tensor_4d(c, 1, tn__tg_zdim(&m), 10, 9);
    tn__tg_noise(&m, tn_params_find(m.weights, "texgan.waves")->data, z, 0, seed, 3, 4);
    a = tn__tg_generate(c, &m, m.weights, "g.", z, &seed, 3, 4);
    b = tn__tg_generate_fast(c, &m, z, seed, 3, 4);
    TN_CHECK(m.smooth == 2 && m.stage_noise == 1);
    TN_CHECK(a && b && tn_tensor_same_shape(a, b));
    TN_CHECK(a && a->shape[2] == tn__tg_out_size(&m, 10) && a->shape[3] == tn__tg_out_size(&m, 9));
    for (k = 0; a && b && k < a->numel; k++)
        if (fabs((double)a->data[k] - b->data[k]) > d) d = fabs((double)a->data[k] - b->data[k]);
    TN_CHECK(d < 1e-5);
    { /* and the literal definition: bilinear x2 upsampling (its valid part: the outermost rows and
         columns need pixels outside the window), a valid [1 2 1]/4 blur, a valid 5x5 conv, bias,
         stage noise */
        tn_tensor *x = z, *nz, *blur;
        int i, ci, ky, kx;
        char name[16];
        for (i = 0; i < m.stages; i++) {
            int h = x->shape[2], w = x->shape[3], C = x->shape[1];
            static const float t3[3] = {0.25f, 0.5f, 0.25f};
            x = tn_upsample_bilinear(c, x, 2 * h, 2 * w);
            x = tn_slice(c, tn_slice(c, x, 2, 1, 2 * h - 2), 3, 1, 2 * w - 2);
            blur = tn_tensor_4d(c, C, C, 3, 3);
            for (ci = 0; ci < C; ci++)
                for (ky = 0; ky < 3; ky++)
                    for (kx = 0; kx < 3; kx++) blur->data[((size_t)ci * C + ci) * 9 + ky * 3 + kx] = t3[ky] * t3[kx];
            x = tn_conv2d(c, x, blur, NULL, NULL);
            snprintf(name, sizeof name, "g.w%d", i);
            x = tn_conv2d(c, x, tn_params_find(m.weights, name), NULL, NULL);
            snprintf(name, sizeof name, "g.b%d", i);
            x = tn_add(c, x, tn_reshape(c, tn_params_find(m.weights, name), 4, (int[]){1, x->shape[1], 1, 1}));
            nz = tn_tensor_4d(c, 1, 1, x->shape[2], x->shape[3]);
            tn__tg_noise_plane(nz->data, seed, i, 3, 4, x->shape[2], x->shape[3]);
            snprintf(name, sizeof name, "g.n%d", i);
            x = tn_add(c, x, tn_mul(c, nz, tn_reshape(c, tn_params_find(m.weights, name), 4, (int[]){1, x->shape[1], 1, 1})));
            x = i < m.stages - 1 ? tn__tg_pixel_norm(c, tn_leaky_relu(c, x, 0.2f)) : tn_tanh(c, x);
        }
        d = 0;
        for (k = 0; a && x && k < a->numel; k++)
            if (fabs((double)a->data[k] - x->data[k]) > d) d = fabs((double)a->data[k] - x->data[k]);
        TN_CHECK(x && tn_tensor_same_shape(a, x) && d < 1e-5);
    }
    tn_ctx_free(c);
    tn_texgan_free(&m);
}

/* the first design (nearest upsampling, no stage noise) still trains, tiles exactly and runs
   the same in its fast form: its model files stay usable */
TN_TEST(nearest_design_still_tiles_exactly)
{
    tn_image ex = tn_test_exemplar(40, 36, 3, 3), one = {0, 0, 0, NULL}, tiled = {0, 0, 0, NULL};
    tn_texgan m;
    tn_texgan_opts o;
    tn_ctx *c = tn_ctx_create();
    tn_tensor *z, *a, *b;
    uint64_t seed = 4;
    size_t k;
    double d = 0;
    tiny_opts(&o);
    o.nearest = 1;
    o.train.max_iters = 2;
    TN_CHECK(tn_texgan_train(&m, &ex, &o, NULL) == TN_OK);
    TN_CHECK(m.smooth == 0 && m.stage_noise == 0 && tn_params_find(m.weights, "g.n0") == NULL);
    TN_CHECK(tn_texgan_synthesize_window(&one, &m, 7, 0, 0, 50, 33) == TN_OK);
    TN_CHECK(tn_image_create(&tiled, 50, 33, 3) == TN_OK);
    TN_CHECK(tn_texgan_synthesize_stream(&m, 7, 50, 33, 1, tn__tg_collect_band, &tiled) == TN_OK);
    TN_CHECK(max_abs_diff(&one, &tiled) <= 1e-6);
    tn_ctx_set_grad(c, 0);
    z = tn_tensor_4d(c, 1, tn__tg_zdim(&m), 6, 7);
    tn__tg_noise(&m, tn_params_find(m.weights, "texgan.waves")->data, z, 0, seed, 1, 2);
    a = tn__tg_generate(c, &m, m.weights, "g.", z, &seed, 1, 2);
    b = tn__tg_generate_fast(c, &m, z, seed, 1, 2);
    TN_CHECK(a && b && tn_tensor_same_shape(a, b) && a->shape[2] == 2 * (2 * 6 - 4) - 4);
    for (k = 0; a && b && k < a->numel; k++)
        if (fabs((double)a->data[k] - b->data[k]) > d) d = fabs((double)a->data[k] - b->data[k]);
    TN_CHECK(d < 1e-5);
    tn_ctx_free(c);
    tn_image_free(&one);
    tn_image_free(&tiled);
    tn_image_free(&ex);
    tn_texgan_free(&m);
}

/* the anti-collapse term: real crops of the exemplar score far lower than a flat colour */
TN_TEST(feature_statistics_separate_real_from_flat)
{
    tn_image ex = tn_test_exemplar(64, 64, 3, 6);
    tn__tg_train s;
    tn_ctx *c = tn_ctx_create();
    tn_tensor *real, *flat, *lr, *lf;
    float *pl = (float *)malloc(64 * 64 * 3 * sizeof(float));
    int b, ch, y, x;
    memset(&s, 0, sizeof s);
    s.m.channels = 3;
    s.filt = (float *)malloc(TN__TG_FEATS * 3 * 25 * sizeof(float));
    for (ch = 0; ch < 3; ch++)
        for (y = 0; y < 64; y++)
            for (x = 0; x < 64; x++) pl[(ch * 64 + y) * 64 + x] = 2.0f * TN_PIXEL(&ex, x, y, ch) - 1.0f;
    tn__tg_make_filters(&s);
    TN_CHECK(tn__tg_feat_ref(&s, c, pl, 64, 64) == TN_OK);
    tn_ctx_reset(c);
    tn_ctx_set_grad(c, 0);
    real = tn_tensor_4d(c, 2, 3, 32, 32);
    flat = tn_tensor_4d(c, 2, 3, 32, 32);
    for (b = 0; b < 2; b++)
        for (ch = 0; ch < 3; ch++)
            for (y = 0; y < 32; y++)
                for (x = 0; x < 32; x++) {
                    real->data[((b * 3 + ch) * 32 + y) * 32 + x] = pl[(ch * 64 + y + 32 * b) * 64 + x + 16];
                    flat->data[((b * 3 + ch) * 32 + y) * 32 + x] = 2.0f * m_mean(&ex, ch) - 1.0f;
                }
    lr = tn__tg_feat_loss(c, &s, real);
    lf = tn__tg_feat_loss(c, &s, flat);
    TN_CHECK(lr && lf);
    if (lr && lf) {
        TN_CHECK(lf->data[0] > 1.0f); /* zero covariance on 2 levels: at least 1 each */
        TN_CHECK(lr->data[0] < 0.25f * lf->data[0]);
    }
    free(pl);
    free(s.filt);
    free(s.ref);
    tn_ctx_free(c);
    tn_image_free(&ex);
}

TN_TEST(deterministic_for_1_and_2_threads)
{
    tn_image ex = tn_test_exemplar(40, 36, 3, 4), s1 = {0, 0, 0, NULL}, s2 = {0, 0, 0, NULL};
    tn_texgan a, b;
    tn_texgan_opts o;
    tiny_opts(&o);
    o.train.max_iters = 3;
    tn_set_threads(1);
    TN_CHECK(tn_texgan_train(&a, &ex, &o, NULL) == TN_OK);
    TN_CHECK(tn_texgan_synthesize(&s1, &a, 7, 70, 50) == TN_OK);
    tn_set_threads(2);
    TN_CHECK(tn_texgan_train(&b, &ex, &o, NULL) == TN_OK);
    TN_CHECK(tn_texgan_synthesize(&s2, &b, 7, 70, 50) == TN_OK);
    TN_CHECK(tn_test_same_params(a.weights, b.weights, 1));
    TN_CHECK(max_abs_diff(&s1, &s2) == 0.0);
    { /* issue 33 item 9: every tensor, the config included, is the same (values_digest); the
         training seconds are metadata */
        int i;
        TN_CHECK(tn_params_count(a.weights) == tn_params_count(b.weights));
        for (i = 0; i < tn_params_count(a.weights) && i < tn_params_count(b.weights); i++) {
            const tn_tensor *ta = tn_params_get(a.weights, i), *tb = tn_params_get(b.weights, i);
            TN_CHECK(ta->numel == tb->numel && !memcmp(ta->data, tb->data, ta->numel * sizeof(float)));
        }
        TN_CHECK(tn_params_find(a.weights, "texgan.config")->data[11] == 0.0f);
        TN_CHECK(tn_params_meta(a.weights, "train_seconds") != NULL && a.train_seconds > 0);
    }
    tn_set_threads(0);
    tn_image_free(&s1);
    tn_image_free(&s2);
    tn_texgan_free(&a);
    tn_texgan_free(&b);
    tn_image_free(&ex);
}

TN_TEST(model_file_round_trip_and_streamed_files)
{
    const char *path = "build/test/texgan.tnw";
    tn_texgan m, l;
    tn_image mem = {0, 0, 0, NULL}, pfm = {0, 0, 0, NULL}, ppm = {0, 0, 0, NULL}, extra = {0, 0, 0, NULL};
    float shift[6] = {0.1f, -0.05f, 0, 0, 0, 0};
    size_t i;
    double d = 0;
    TN_CHECK(trained_tiny(&m, 6, 1) == TN_OK); /* RGB + normal map */
    TN_CHECK(tn_texgan_save(path, &m) == TN_OK);
    TN_CHECK(tn_texgan_load(&l, path) == TN_OK);
    TN_CHECK(m.train_seconds > 0 && fabs(l.train_seconds - m.train_seconds) < 0.01); /* from the metadata */
    TN_CHECK(l.channels == 6 && l.stages == 2 && l.noise_periodic == 1 && l.iterations == 2);
    TN_CHECK(tn_test_same_params(m.weights, l.weights, 0));
    TN_CHECK(tn_texgan_synthesize(&mem, &l, 3, 37, 29) == TN_OK);
    TN_CHECK(tn_texgan_synthesize_file("build/test/texgan_out.pfm", &l, 3, 37, 29, shift) == TN_OK);
    TN_CHECK(tn_image_load(&pfm, "build/test/texgan_out.pfm", NULL) == TN_OK);
    TN_CHECK(tn_image_load(&extra, "build/test/texgan_out.ch3-5.pfm", NULL) == TN_OK);
    TN_CHECK(pfm.width == 37 && pfm.height == 29 && pfm.channels == 3 && extra.channels == 3);
    for (i = 0; pfm.data && extra.data && i < (size_t)37 * 29; i++) {
        int c;
        for (c = 0; c < 3; c++) {
            float want = tn__clampf(mem.data[i * 6 + c] + shift[c], l.lo, l.hi);
            if (fabs((double)pfm.data[i * 3 + c] - want) > d) d = fabs((double)pfm.data[i * 3 + c] - want);
            if (fabs((double)extra.data[i * 3 + c] - mem.data[i * 6 + 3 + c]) > d) d = fabs((double)extra.data[i * 3 + c] - mem.data[i * 6 + 3 + c]);
        }
    }
    TN_CHECK(d == 0.0);
    TN_CHECK(tn_texgan_synthesize_file("build/test/texgan_out.ppm", &l, 3, 37, 29, NULL) == TN_OK);
    TN_CHECK(tn_image_load(&ppm, "build/test/texgan_out.ppm", NULL) == TN_OK);
    TN_CHECK(ppm.width == 37 && ppm.channels == 3 && fabs(ppm.data[5] - mem.data[(5 / 3) * 6 + 5 % 3]) <= 0.5 / 255 + 1e-6);
    tn_image_free(&mem);
    tn_image_free(&pfm);
    tn_image_free(&ppm);
    tn_image_free(&extra);
    tn_texgan_free(&m);
    tn_texgan_free(&l);
}

TN_TEST(colour_correction_hits_the_target_mean)
{
    tn_image a = tn_test_exemplar(30, 20, 3, 5), b = {0, 0, 0, NULL};
    float target[3] = {0.8f, 0.1f, 0.45f}, shift[3];
    size_t i, n = 600;
    int c;
    TN_CHECK(tn_image_copy(&b, &a) == TN_OK);
    TN_CHECK(tn_texture_colour_correct(&a, target, 0.0f, 1.0f) == TN_OK);
    for (c = 0; c < 3; c++) {
        double s = 0;
        float lo = 1, hi = 0;
        for (i = 0; i < n; i++) {
            s += a.data[i * 3 + c];
            if (a.data[i * 3 + c] < lo) lo = a.data[i * 3 + c];
            if (a.data[i * 3 + c] > hi) hi = a.data[i * 3 + c];
        }
        TN_CHECK_NEAR(s / n, target[c], 2e-6); /* exact despite the clipping channels 0 and 1 need */
        TN_CHECK(lo >= 0.0f && hi <= 1.0f);
    }
    /* no clipping: a pure shift by the mean difference */
    TN_CHECK(tn_texture_colour_shift(shift, &b, target, -10.0f, 10.0f) == TN_OK);
    {
        double s = 0;
        for (i = 0; i < n; i++) s += b.data[i * 3 + 2];
        TN_CHECK_NEAR(shift[2], target[2] - s / n, 1e-6);
    }
    b.data[7] = NAN;
    TN_CHECK(tn_texture_colour_correct(&b, target, 0.0f, 1.0f) == TN_ERR_NUMERIC);
    tn_image_free(&a);
    tn_image_free(&b);
}

TN_TEST(detail_texel_equals_whole_image_composer)
{
    tn_image ex = tn_test_exemplar(24, 20, 3, 6), synth = tn_test_exemplar(97, 61, 3, 7), comp = {0, 0, 0, NULL};
    tn_detail_maps m, l;
    tn_detail_opts o;
    int x, y, c, sizes[3][2] = {{97, 61}, {50, 33}, {130, 70}}, k, bad = 0;
    float t[3];
    memset(&o, 0, sizeof o);
    o.factor = 4;
    TN_CHECK(tn_detail_maps_from_image(&m, &synth, &ex, &o) == TN_OK);
    TN_CHECK(m.low.width == 25 && m.low.height == 16 && m.high.width == 24);
    TN_CHECK_NEAR(m.tiling_x, 97.0 / 24, 1e-6);
    for (k = 0; k < 3; k++) {
        tn_image_free(&comp);
        TN_CHECK(tn_detail_compose(&comp, &m, sizes[k][0], sizes[k][1]) == TN_OK);
        for (y = 0; y < comp.height; y++)
            for (x = 0; x < comp.width; x++) {
                tn_detail_texel(t, &m, ((float)x + 0.5f) / (float)comp.width, ((float)y + 0.5f) / (float)comp.height);
                for (c = 0; c < 3; c++) bad += t[c] != TN_PIXEL(&comp, x, y, c);
            }
    }
    TN_CHECK(bad == 0);
    /* the low map carries the exemplar's mean colour; the high map is centred on 0.5 */
    {
        double sl = 0, sh = 0, se = 0;
        size_t i;
        for (i = 0; i < (size_t)25 * 16; i++) sl += m.low.data[i * 3];
        for (i = 0; i < (size_t)24 * 20; i++) {
            sh += m.high.data[i * 3];
            se += ex.data[i * 3];
        }
        TN_CHECK_NEAR(sl / 400, se / 480, 1e-5);
        TN_CHECK_NEAR(sh / 480, 0.5, 0.01);
    }
    /* save / load keeps the tiling factor (sidecar) and the maps up to 8/16-bit quantisation */
    TN_CHECK(tn_detail_maps_save("build/test/texgan_dm", &m) == TN_OK);
    TN_CHECK(tn_detail_maps_load(&l, "build/test/texgan_dm") == TN_OK);
    TN_CHECK(l.factor == 4 && l.width == 97 && fabs(l.tiling_y - m.tiling_y) < 1e-6);
    TN_CHECK(max_abs_diff(&l.low, &m.low) < 1.0 / 65535 && max_abs_diff(&l.high, &m.high) < 0.51 / 255);
    tn_detail_maps_free(&l);
    tn_image_free(&comp);
    TN_CHECK(tn_detail_preview(&comp, &m, &ex, NULL, 32) == TN_OK);
    TN_CHECK(comp.width == 72 && comp.channels == 3);
    tn_image_free(&comp);
    tn_detail_maps_free(&m);
    tn_image_free(&ex);
    tn_image_free(&synth);
}

/* Mean squared step across the wrap (last column -> first) over the mean squared step between
   interior neighbours, channel 0 of a high map stored as value / 2 + 0.5 (or raw values). */
static double wrap_step_ratio(const tn_image *h)
{
    double wrap = 0, inner = 0;
    int x, y;
    for (y = 0; y < h->height; y++) {
        double d = TN_PIXEL(h, 0, y, 0) - TN_PIXEL(h, h->width - 1, y, 0);
        wrap += d * d;
        for (x = 0; x + 1 < h->width; x++) {
            d = TN_PIXEL(h, x + 1, y, 0) - TN_PIXEL(h, x, y, 0);
            inner += d * d;
        }
    }
    return (wrap / h->height) / (inner / ((double)h->height * (h->width - 1)));
}

/* Stripes of period 11 on a 48-px exemplar do not wrap: its plain high-pass jumps at the edge;
   the stored high map must not; the blend keeps the energy of uncorrelated detail. */
TN_TEST(high_map_tiles_seamlessly)
{
    tn_image ex = {0, 0, 0, NULL}, blur = {0, 0, 0, NULL}, synth = tn_test_exemplar(64, 64, 1, 3), t = {0, 0, 0, NULL};
    tn_detail_maps m;
    tn_detail_opts o;
    double e_raw = 0, e_map = 0;
    size_t i, n = 48 * 40;
    int x, y;
    tn_image_create(&ex, 48, 40, 1);
    for (y = 0; y < 40; y++)
        for (x = 0; x < 48; x++) ex.data[y * 48 + x] = 0.5f + 0.3f * sinf(6.2831853f * (float)x / 11.0f) * cosf(6.2831853f * (float)y / 13.0f);
    memset(&o, 0, sizeof o);
    o.factor = 4;
    TN_CHECK(tn_detail_maps_from_image(&m, &synth, &ex, &o) == TN_OK);
    TN_CHECK(tn_image_blur(&blur, &ex, m.sigma) == TN_OK);
    for (i = 0; i < n; i++) blur.data[i] = ex.data[i] - blur.data[i];
    TN_CHECK(wrap_step_ratio(&blur) > 3.0);      /* the test can fail: the plain high-pass does not tile */
    TN_CHECK(wrap_step_ratio(&m.high) < 1.5);
    TN_CHECK(tn_image_create(&t, 40, 48, 1) == TN_OK); /* the same across the top/bottom wrap */
    for (y = 0; y < 40; y++)
        for (x = 0; x < 48; x++) t.data[x * 40 + y] = m.high.data[y * 48 + x];
    TN_CHECK(wrap_step_ratio(&t) < 1.5);
    /* energy kept on uncorrelated detail: white noise (128 x 128, so the estimate is tight) with
       a jump at the wrap, blended along x; columns 0 and 64 (which takes column 0's copy) aside */
    {
        tn_rng r;
        float *o = (float *)malloc((size_t)128 * 128 * sizeof(float));
        tn_image_free(&ex);
        tn_image_create(&ex, 128, 128, 1);
        tn_rng_seed(&r, 21, 0);
        for (i = 0; i < (size_t)128 * 128; i++) ex.data[i] = tn_rng_uniform(&r) - 0.5f + (i % 128 == 0 ? 3.0f : 0.0f);
        TN_CHECK(o != NULL);
        if (o) {
            tn__dm_seamless(&ex, o, 0);
            for (i = 0; i < (size_t)128 * 128; i++)
                if (i % 128 != 0 && i % 128 != 64) {
                    e_raw += (double)ex.data[i] * ex.data[i];
                    e_map += (double)o[i] * o[i];
                }
            TN_CHECK(fabs(e_map / e_raw - 1.0) < 0.05);
            TN_CHECK(memcmp(o, ex.data, (size_t)128 * 128 * sizeof(float)) != 0); /* the blend ran */
            for (i = 0; i < (size_t)128 * 128; i++) ex.data[i] = o[i];
            TN_CHECK(wrap_step_ratio(&ex) < 1.5);
            /* detail that already tiles (white noise without the jump) is left as it is */
            for (i = 0; i < (size_t)128 * 128; i++) ex.data[i] = tn_rng_uniform(&r) - 0.5f;
            tn__dm_seamless(&ex, o, 0);
            TN_CHECK(memcmp(o, ex.data, (size_t)128 * 128 * sizeof(float)) == 0);
        }
        free(o);
    }
    tn_detail_maps_free(&m);
    tn_image_free(&ex);
    tn_image_free(&blur);
    tn_image_free(&synth);
    tn_image_free(&t);
}

TN_TEST(detail_maps_from_model_match_the_image_path)
{
    tn_texgan m;
    tn_image ex = tn_test_exemplar(40, 36, 3, 3), synth = {0, 0, 0, NULL};
    tn_detail_maps a, b;
    TN_CHECK(trained_tiny(&m, 3, 0) == TN_OK);
    TN_CHECK(tn_texgan_synthesize(&synth, &m, 11, 90, 70) == TN_OK);
    TN_CHECK(tn_detail_maps_from_image(&a, &synth, &ex, NULL) == TN_OK);
    TN_CHECK(tn_detail_maps_from_model(&b, &m, 11, 90, 70, &ex, NULL) == TN_OK);
    TN_CHECK(max_abs_diff(&a.low, &b.low) < 1e-6 && max_abs_diff(&a.high, &b.high) == 0.0);
    TN_CHECK(a.low.width == 9 && a.low.height == 7 && a.factor == 10);
    tn_detail_maps_free(&a);
    tn_detail_maps_free(&b);
    tn_image_free(&synth);
    tn_image_free(&ex);
    tn_texgan_free(&m);
}

TN_TEST(bad_inputs_fail_cleanly)
{
    tn_image ex = tn_test_exemplar(40, 36, 3, 8), empty = {0, 0, 0, NULL}, out = {0, 0, 0, NULL}, small = tn_test_exemplar(10, 10, 3, 1);
    tn_image wide = tn_test_exemplar(20, 20, 9, 1);
    tn_texgan m, l;
    tn_texgan_opts o;
    tn_detail_maps dm;
    uint8_t *buf = NULL;
    size_t n = 0;
    FILE *f;
    tiny_opts(&o);
    o.train.max_iters = 1;
    TN_CHECK(tn_texgan_train(&m, &empty, &o, NULL) == TN_ERR_EMPTY);
    TN_CHECK(tn_texgan_train(&m, &small, &o, NULL) == TN_ERR_INVALID_ARG); /* smaller than the patch */
    TN_CHECK(tn_texgan_train(&m, &wide, &o, NULL) == TN_ERR_SHAPE);
    ex.data[17] = NAN;
    TN_CHECK(tn_texgan_train(&m, &ex, &o, NULL) == TN_ERR_NUMERIC);
    ex.data[17] = 0.5f;
    o.stages = 9;
    TN_CHECK(tn_texgan_train(&m, &ex, &o, NULL) == TN_ERR_INVALID_ARG);
    o.stages = 2;
    o.train.resume = 1;
    o.train.checkpoint = "build/test/no_such_texgan.ckpt";
    TN_CHECK(tn_texgan_train(&m, &ex, &o, NULL) == TN_ERR_IO);
    o.train.resume = 0;
    o.train.checkpoint = NULL;
    TN_CHECK(tn_texgan_train(&m, &ex, &o, NULL) == TN_OK);
    TN_CHECK(tn_texgan_synthesize(&out, &m, 1, 0, 10) == TN_ERR_INVALID_ARG);
    TN_CHECK(tn_texgan_synthesize_window(&out, &m, 1, -1, 0, 10, 10) == TN_ERR_INVALID_ARG);
    TN_CHECK(tn_texgan_synthesize(&out, &m, 1, 1 << 25, 10) == TN_ERR_TOO_LARGE);
    /* model files: corrupt byte, truncated, another .tnw, missing */
    TN_CHECK(tn_texgan_save("build/test/texgan_bad.tnw", &m) == TN_OK);
    TN_CHECK(tn__io_read_file("build/test/texgan_bad.tnw", &buf, &n) == TN_OK);
    buf[n / 2] ^= 0x40;
    f = fopen("build/test/texgan_bad.tnw", "wb");
    fwrite(buf, 1, n, f);
    fclose(f);
    TN_CHECK(tn_texgan_load(&l, "build/test/texgan_bad.tnw") == TN_ERR_CORRUPT);
    f = fopen("build/test/texgan_bad.tnw", "wb");
    fwrite(buf, 1, 40, f);
    fclose(f);
    TN_CHECK(tn_texgan_load(&l, "build/test/texgan_bad.tnw") != TN_OK);
    tn_free(buf);
    {
        tn_params *p = tn_params_create();
        int two = 2;
        tn_params_add(p, "x", 1, &two);
        tn_params_save("build/test/texgan_other.tnw", p);
        tn_params_free(p);
        TN_CHECK(tn_texgan_load(&l, "build/test/texgan_other.tnw") == TN_ERR_FORMAT);
    }
    TN_CHECK(tn_texgan_load(&l, "build/test/no_such_model.tnw") == TN_ERR_IO);
    /* detail maps */
    TN_CHECK(tn_detail_maps_from_image(&dm, &ex, &wide, NULL) == TN_ERR_SHAPE);
    TN_CHECK(tn_detail_maps_from_image(&dm, &empty, &ex, NULL) == TN_ERR_EMPTY);
    ex.data[3] = INFINITY;
    TN_CHECK(tn_detail_maps_from_image(&dm, &ex, &small, NULL) == TN_ERR_NUMERIC);
    TN_CHECK(tn_detail_maps_load(&dm, "build/test/no_such_prefix") == TN_ERR_IO);
    tn_texgan_free(&m);
    tn_image_free(&ex);
    tn_image_free(&small);
    tn_image_free(&wide);
}

int main(void)
{
    TN_RUN(training_steps_stay_finite_and_move_the_generator);
    TN_RUN(checkpoint_resume_continues_identically);
    TN_RUN(tiled_synthesis_equals_one_pass);
    TN_RUN(nearest_design_still_tiles_exactly);
    TN_RUN(feature_statistics_separate_real_from_flat);
    TN_RUN(scaled_model_tiles_exactly);
    TN_RUN(fast_generator_matches_the_training_graph);
    TN_RUN(deterministic_for_1_and_2_threads);
    TN_RUN(model_file_round_trip_and_streamed_files);
    TN_RUN(colour_correction_hits_the_target_mean);
    TN_RUN(detail_texel_equals_whole_image_composer);
    TN_RUN(detail_maps_from_model_match_the_image_path);
    TN_RUN(high_map_tiles_seamlessly);
    TN_RUN(bad_inputs_fail_cleanly);
    return tn_test_summary("test_texgan");
}
