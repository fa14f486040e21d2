/* test_style: terrain style transfer (@@style) - loss decrease, finite-difference gradients of the
   style terms, determinism across thread counts, bad input, VGG-19 .tnw loading and the VGG path. */
#define TN_INTERNALS /* private tn__ code: the header's internals block */
#include "terrainnet.h"
#include "tn_test.h"

/* A style source with ridges (a rotated sine) plus a little noise, w x h. */
static void make_style(tn_image *img, int w, int h)
{
    tn_rng rng;
    int x, y;
    tn_rng_seed(&rng, 3, 0);
    tn_image_create(img, w, h, 1);
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++)
            img->data[(size_t)y * w + x] = 1000.0f + 300.0f * fabsf(sinf(0.35f * x + 0.2f * y)) + 20.0f * tn_rng_uniform(&rng);
}

static void make_content(tn_image *img, int w, int h)
{
    tn_perlin_opts po;
    memset(&po, 0, sizeof po);
    po.seed = 5;
    po.octaves = 4;
    tn_noise_perlin(img, w, h, &po);
}

/* A single-level setup like tn__style_level_run's, for direct loss/gradient checks. */
static int level_setup(tn__style_cfg *c, tn__style_level *L, const tn_style_opts *o, tn_image *content, tn_image *style)
{
    double a, b;
    const float *crop;
    int level = c->level; /* setup clears the config */
    if (tn__style_setup(c, o)) return 0;
    c->level = level;
    tn__style_normalise(content, 0, &a, &b);
    tn__style_normalise(style, 0, &a, &b);
    tn__style_level_init(L, c, content->width, content->height);
    crop = style->data;
    if (tn__style_targets(L, &crop, 1, c->o.seed)) return 0;
    if ((L->wh > 0 || L->wdep > 0 || L->wrel > 0) && tn__style_hist_targets(L, style->data, style->width, style->height)) return 0;
    if (L->wc > 0 && tn__style_content_target(L, content->data)) return 0;
    return 1;
}

TN_TEST(test_argsort)
{
    float v[1000];
    uint32_t idx[1000], scratch[3000];
    tn_rng rng;
    int i, ok = 1;
    tn_rng_seed(&rng, 9, 0);
    for (i = 0; i < 1000; i++) v[i] = tn_rng_normal(&rng) * (i % 7 == 0 ? 1e-3f : 100.0f);
    v[10] = v[20]; /* a tie keeps index order */
    tn__argsort_f32(v, 1000, idx, scratch);
    for (i = 1; i < 1000; i++) ok &= v[idx[i - 1]] <= v[idx[i]];
    TN_CHECK(ok);
}

TN_TEST(test_loss_decreases)
{
    tn_image content = {0, 0, 0, NULL}, style = {0, 0, 0, NULL};
    tn_style_opts o;
    tn__style_cfg *c = (tn__style_cfg *)calloc(1, sizeof *c);
    tn__style_level L;
    float *x, *g, f0, f1;
    size_t n = 64 * 64;
    memset(&o, 0, sizeof o);
    o.iters = 15;
    make_content(&content, 64, 64);
    make_style(&style, 64, 64);
    TN_CHECK(level_setup(c, &L, &o, &content, &style));
    x = (float *)malloc(n * sizeof(float));
    g = (float *)malloc(n * sizeof(float));
    memcpy(x, content.data, n * sizeof(float));
    f0 = tn__style_eval(&L, x, g);
    c->work_total = 1;
    TN_CHECK(tn__style_optimise(&L, x, c) == TN_OK);
    f1 = tn__style_eval(&L, x, g);
    TN_CHECK(f0 == f0 && f1 == f1);
    TN_CHECK(f1 < 0.5f * f0);
    /* Adam and SGD lower it too */
    memcpy(x, content.data, n * sizeof(float));
    c->o.optimizer = TN_STYLE_ADAM;
    c->o.iters = 30;
    c->o.lr = 0.02f;
    TN_CHECK(tn__style_optimise(&L, x, c) == TN_OK);
    TN_CHECK(tn__style_eval(&L, x, g) < f0);
    memcpy(x, content.data, n * sizeof(float));
    c->o.optimizer = TN_STYLE_SGD;
    c->o.lr = 0.5f;
    TN_CHECK(tn__style_optimise(&L, x, c) == TN_OK);
    TN_CHECK(tn__style_eval(&L, x, g) < f0);
    free(x);
    free(g);
    tn__style_level_free(&L);
    tn_params_free(c->net.own);
    free(c);
    tn_image_free(&content);
    tn_image_free(&style);
}

/* Central differences of the style loss (Gram + sliced Wasserstein, no content, no histograms,
   no TV) against the backward pass on a 16 x 16 map: along random directions (ReLU and sorting
   kinks average out) and per pixel with a looser bound. */
static int style_gradient_ok(float hist_weight)
{
    tn_image content = {0, 0, 0, NULL}, style = {0, 0, 0, NULL};
    tn_style_opts o;
    tn__style_cfg *c = (tn__style_cfg *)calloc(1, sizeof *c);
    tn__style_level L;
    float x[256], g[256], gd[256], v[256], xv[256];
    const float eps = 1e-3f;
    int k, r, bad = 0;
    tn_rng rng;
    memset(&o, 0, sizeof o);
    o.content_weight = -1;
    o.hist_weight = hist_weight;
    make_content(&content, 16, 16);
    make_style(&style, 16, 16);
    if (!level_setup(c, &L, &o, &content, &style)) return 0;
    memcpy(x, content.data, sizeof x);
    tn__style_eval(&L, x, g);
    tn_rng_seed(&rng, 21, 0);
    for (r = 0; r < 4; r++) {
        double gv = 0, fd;
        for (k = 0; k < 256; k++) {
            v[k] = tn_rng_normal(&rng);
            gv += (double)g[k] * v[k];
        }
        for (k = 0; k < 256; k++) xv[k] = x[k] + 0.1f * eps * v[k];
        fd = tn__style_eval(&L, xv, gd);
        for (k = 0; k < 256; k++) xv[k] = x[k] - 0.1f * eps * v[k];
        fd = (fd - tn__style_eval(&L, xv, gd)) / (0.2 * eps);
        if (fabs(fd - gv) > 0.02 * fabs(gv) + 1e-4) {
            fprintf(stderr, "direction %d: finite difference %g, backward %g\n", r, fd, gv);
            bad++;
        }
    }
    for (k = 0; k < 256; k += 17) {
        float xp = x[k], fp, fm, fd;
        x[k] = xp + eps;
        fp = tn__style_eval(&L, x, gd);
        x[k] = xp - eps;
        fm = tn__style_eval(&L, x, gd);
        x[k] = xp;
        fd = (fp - fm) / (2 * eps);
        if (fabsf(fd - g[k]) > 0.1f * fabsf(g[k]) + 1e-4f) {
            fprintf(stderr, "pixel %d: finite difference %g, backward %g\n", k, fd, g[k]);
            bad++;
        }
    }
    tn__style_level_free(&L);
    tn_params_free(c->net.own);
    free(c);
    tn_image_free(&content);
    tn_image_free(&style);
    return bad == 0;
}

TN_TEST(test_style_gradient)
{
    TN_CHECK(style_gradient_ok(-1)); /* Gram + sliced Wasserstein */
    TN_CHECK(style_gradient_ok(1));  /* plus the height and slope histogram terms */
}

TN_TEST(test_transfer_threads_and_units)
{
    tn_image content = {0, 0, 0, NULL}, style = {0, 0, 0, NULL}, a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_style_opts o;
    tn_style_scores before, after;
    float lo, hi;
    memset(&o, 0, sizeof o);
    o.iters = 8;
    make_content(&content, 96, 80);
    make_style(&style, 120, 120);
    tn_set_threads(1);
    TN_CHECK(tn_style_transfer(&a, &content, &style, &o) == TN_OK);
    tn_set_threads(2);
    TN_CHECK(tn_style_transfer(&b, &content, &style, &o) == TN_OK);
    tn_set_threads(0);
    TN_CHECK(a.width == 96 && a.height == 80 && a.channels == 1);
    TN_CHECK(b.data && a.data && memcmp(a.data, b.data, (size_t)96 * 80 * sizeof(float)) == 0);
    /* heights come back in the style's units (about 1000..1320 m), not [0, 1] */
    TN_CHECK(tn_image_range(&lo, &hi, &a) == 0);
    TN_CHECK(lo > 850 && hi < 1500 && hi - lo > 100);
    /* and the morphology moved towards the source */
    TN_CHECK(tn_style_compare(&before, &content, &style) == TN_OK);
    TN_CHECK(tn_style_compare(&after, &a, &style) == TN_OK);
    TN_CHECK(after.slope_hist_dist < before.slope_hist_dist);
    tn_image_free(&a);
    tn_image_free(&b);
    tn_image_free(&content);
    tn_image_free(&style);
}

/* Mean depression depth (filled - height) of a map, heights standardised first. */
static double mean_depression(const tn_image *m)
{
    tn_image a = {0, 0, 0, NULL}, f = {0, 0, 0, NULL};
    double off, sc, s = 0;
    size_t i, n = (size_t)m->width * m->height;
    tn_image_copy(&a, m);
    tn__style_normalise(&a, 0, &off, &sc);
    if (tn_fill_depressions(&f, &a)) return -1;
    for (i = 0; i < n; i++) s += f.data[i] - a.data[i];
    tn_image_free(&a);
    tn_image_free(&f);
    return s / (double)n;
}

TN_TEST(test_drainage_terms)
{
    /* a source of parallel V-valleys on a tilt (no closed basins); a Perlin content map has many */
    tn_image content = {0, 0, 0, NULL}, style = {0, 0, 0, NULL}, off = {0, 0, 0, NULL}, on = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn__style_cfg *c = (tn__style_cfg *)calloc(1, sizeof *c);
    tn__style_level L;
    tn_style_opts o;
    int x, y;
    double d0, d1;
    TN_CHECK(c != NULL);
    tn_image_create(&style, 64, 64, 1);
    for (y = 0; y < 64; y++)
        for (x = 0; x < 64; x++) style.data[y * 64 + x] = 2.0f * y + 8.0f * fabsf(sinf(0.3f * x));
    make_content(&content, 64, 64);
    /* source targets: cells draining much area (valley floors) lie below their surroundings,
       cells draining only themselves (ridges) above */
    memset(&o, 0, sizeof o);
    o.drain_weight = 1;
    o.valley_weight = 1;
    c->level = 1;
    TN_CHECK(level_setup(c, &L, &o, &content, &style));
    TN_CHECK(L.dsorted != NULL && L.wrel > 0);
    TN_CHECK(L.relief_t[0] > 0 && L.relief_t[8] < 0);
    TN_CHECK(L.dsorted[L.dn - 1] < 1e-3f); /* the source has no depressions */
    tn__style_level_free(&L);
    tn_params_free(c->net.own);
    /* the basin term fills the content's depressions; same bytes for 1 and 2 threads */
    tn_image_free(&content);
    make_content(&content, 64, 64);
    for (y = 0; y < 64; y++)
        for (x = 0; x < 64; x++) style.data[y * 64 + x] = 2.0f * y + 8.0f * fabsf(sinf(0.3f * x));
    memset(&o, 0, sizeof o);
    o.iters = 40;
    o.levels = 2;
    o.drain_weight = o.valley_weight = -1; /* the default would switch them on for this source */
    TN_CHECK(tn_style_transfer(&off, &content, &style, &o) == TN_OK);
    o.drain_weight = 10;
    o.valley_weight = 1;
    tn_set_threads(1);
    TN_CHECK(tn_style_transfer(&on, &content, &style, &o) == TN_OK);
    tn_set_threads(2);
    TN_CHECK(tn_style_transfer(&b, &content, &style, &o) == TN_OK);
    tn_set_threads(0);
    TN_CHECK(on.data && b.data && memcmp(on.data, b.data, (size_t)64 * 64 * sizeof(float)) == 0);
    d0 = mean_depression(&off);
    tn_image_free(&on);
    o.valley_weight = -1; /* the basin term alone */
    TN_CHECK(tn_style_transfer(&on, &content, &style, &o) == TN_OK);
    d1 = mean_depression(&on);
    TN_CHECK(d0 > 0 && d1 >= 0 && d1 < 0.5 * d0);
    tn_image_free(&content);
    tn_image_free(&style);
    tn_image_free(&off);
    tn_image_free(&on);
    tn_image_free(&b);
    free(c);
}

TN_TEST(test_drain_band_drains_straight_off)
{
    /* a slope falling south with a slight west-east tilt: D8 runs every column straight down,
       so the column next to each side edge would carry a whole column's water along it */
    enum { W = 24, H = 20 };
    tn_image dem = {0, 0, 0, NULL};
    tn_flow f, g;
    uint8_t bin[W * H];
    int x, y, ok_dirs = 1, ok_inner = 1;
    memset(&f, 0, sizeof f);
    memset(&g, 0, sizeof g);
    tn_image_create(&dem, W, H, 1);
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) dem.data[y * W + x] = 100.0f - y + 0.01f * x;
    TN_CHECK(tn_flow_directions(&f, &dem) == TN_OK && tn_flow_directions(&g, &dem) == TN_OK);
    TN_CHECK(f.dir[5 * W + 1] == 2); /* south, along the edge */
    tn__style_band_outflow(&f);
    TN_CHECK(tn_flow_accumulation(&f) == TN_OK);
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) {
            int l = x, r = W - 1 - x, t = y, b = H - 1 - y, m = l < r ? l : r, v = t < b ? t : b, d = f.dir[y * W + x];
            if (m >= 2 && v >= 2) ok_inner &= d == g.dir[y * W + x];
            else if (!m || !v) ok_dirs &= d == TN_FLOW_OUTLET;
            else ok_dirs &= d == (m <= v ? (l <= r ? 4 : 0) : (t <= b ? 6 : 2));
        }
    TN_CHECK(ok_dirs && ok_inner);
    TN_CHECK(f.acc[(H - 3) * W + 1] == 1 && f.acc[(H - 3) * W + W - 2] == 1); /* nothing runs along the side edges */
    TN_CHECK(f.acc[(H - 3) * W + 2] == H - 4);                               /* the first inner column still collects */
    /* drainage bins: the band has the edge bin; the first inner column drains H - 4 cells (bin 4) */
    TN_CHECK(tn__style_drain_bins(dem.data, dem.data, W, H, bin) == TN_OK);
    TN_CHECK(bin[(H - 3) * W + 1] == TN__STYLE_ABINS && bin[(H - 3) * W] == TN__STYLE_ABINS && bin[(H - 3) * W + 2] == 4);
    tn_flow_free(&f);
    tn_flow_free(&g);
    tn_image_free(&dem);
}

TN_TEST(test_auto_drainage)
{
    /* valleys on a tilt drain off the map: fluvial, terms on; an egg-crate of closed basins
       (dunes, craters): off; the user's own weights are kept */
    tn__style_cfg *c = (tn__style_cfg *)calloc(1, sizeof *c);
    tn_image v = {0, 0, 0, NULL}, e = {0, 0, 0, NULL};
    int x, y;
    TN_CHECK(c != NULL);
    tn_image_create(&v, 64, 64, 1);
    tn_image_create(&e, 64, 64, 1);
    for (y = 0; y < 64; y++)
        for (x = 0; x < 64; x++) {
            v.data[y * 64 + x] = 2.0f * y + 8.0f * fabsf(sinf(0.3f * x));
            e.data[y * 64 + x] = sinf(0.4f * x) * sinf(0.4f * y);
        }
    TN_CHECK(tn__style_auto_drainage(c, &v) == TN_OK && c->o.drain_weight == 10 && c->o.valley_weight == 1);
    memset(c, 0, sizeof *c);
    TN_CHECK(tn__style_auto_drainage(c, &e) == TN_OK && c->o.drain_weight < 0 && c->o.valley_weight < 0);
    memset(c, 0, sizeof *c);
    c->o.drain_weight = 3;
    TN_CHECK(tn__style_auto_drainage(c, &e) == TN_OK && c->o.drain_weight == 3 && c->o.valley_weight < 0);
    tn_image_free(&v);
    tn_image_free(&e);
    free(c);
}

TN_TEST(test_tiles_and_progress)
{
    /* a 2-level pyramid whose fine level is split into 4 tiles of 48 */
    tn_image content = {0, 0, 0, NULL}, style = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_style_opts o;
    memset(&o, 0, sizeof o);
    o.iters = 3;
    o.levels = 2;
    o.tile = 48;
    make_content(&content, 80, 80);
    make_style(&style, 80, 80);
    TN_CHECK(tn_style_transfer(&out, &content, &style, &o) == TN_OK);
    TN_CHECK(out.width == 80 && tn_image_range(NULL, NULL, &out) == 0);
    tn_image_free(&out);
    tn_image_free(&content);
    tn_image_free(&style);
}

typedef struct progress_log { double last, max; int backwards, other_stage; } progress_log;

static int log_progress(void *user, const char *stage, double f)
{
    progress_log *p = (progress_log *)user;
    p->other_stage += strcmp(stage, "style") != 0;
    p->backwards += f < p->last;
    p->last = f;
    p->max = f > p->max ? f : p->max;
    return 0;
}

TN_TEST(test_margin_progress)
{
    /* drainage terms on: the coarse level runs on a canvas grown by a mirrored margin, and the
       progress total counts that canvas, so progress runs monotonically to exactly 1; the
       floods inside (and before) the evaluations do not show as a stage of their own */
    tn_image content = {0, 0, 0, NULL}, style = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_style_opts o;
    progress_log p = {0, 0, 0, 0};
    int x, y, k;
    memset(&o, 0, sizeof o);
    o.iters = 3;
    o.levels = 2;
    o.drain_weight = 10;
    o.valley_weight = 1;
    make_content(&content, 96, 96);
    tn_image_create(&style, 96, 96, 1);
    for (y = 0; y < 96; y++)
        for (x = 0; x < 96; x++) style.data[y * 96 + x] = 2.0f * y + 8.0f * fabsf(sinf(0.3f * x));
    for (k = 0; k < 2; k++) {
        memset(&p, 0, sizeof p);
        o.optimizer = k ? TN_STYLE_SGD : TN_STYLE_LBFGS;
        tn_set_progress(log_progress, &p);
        TN_CHECK(tn_style_transfer(&out, &content, &style, &o) == TN_OK);
        tn_set_progress(NULL, NULL);
        TN_CHECK(out.width == 96 && out.height == 96 && tn_image_range(NULL, NULL, &out) == 0);
        TN_CHECK_NEAR(p.last, 1.0, 1e-9);
        TN_CHECK(p.max <= 1.0 + 1e-9 && p.backwards == 0 && p.other_stage == 0);
        tn_image_free(&out);
    }
    tn_image_free(&content);
    tn_image_free(&style);
}

static int cancel_at_half(void *user, const char *stage, double f)
{
    (void)stage;
    *(double *)user = f;
    return f > 0.5;
}

TN_TEST(test_cancel)
{
    tn_image content = {0, 0, 0, NULL}, style = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_style_opts o;
    double last = -1;
    memset(&o, 0, sizeof o);
    o.iters = 6;
    o.optimizer = TN_STYLE_ADAM;
    make_content(&content, 64, 64);
    make_style(&style, 64, 64);
    tn_set_progress(cancel_at_half, &last);
    TN_CHECK(tn_style_transfer(&out, &content, &style, &o) == TN_ERR_CANCELLED);
    tn_set_progress(NULL, NULL);
    TN_CHECK(last > 0.5 && last <= 1.0);
    TN_CHECK(out.data == NULL);
    tn_image_free(&content);
    tn_image_free(&style);
}

TN_TEST(test_bad_input)
{
    tn_image content = {0, 0, 0, NULL}, style = {0, 0, 0, NULL}, out = {0, 0, 0, NULL}, tiny = {0, 0, 0, NULL};
    int x;
    tn_style_opts o;
    tn_style_scores sc;
    make_content(&content, 32, 32);
    make_style(&style, 32, 32);
    content.data[100] = NAN;
    TN_CHECK(tn_style_transfer(&out, &content, &style, NULL) == TN_ERR_NUMERIC);
    TN_CHECK(strstr(tn_last_error(), "content") != NULL);
    content.data[100] = 0.5f;
    style.data[7] = INFINITY;
    TN_CHECK(tn_style_transfer(&out, &content, &style, NULL) == TN_ERR_NUMERIC);
    style.data[7] = 1000.0f;
    tn_image_create(&tiny, 8, 8, 1);
    TN_CHECK(tn_style_transfer(&out, &tiny, &style, NULL) == TN_ERR_INVALID_ARG);
    memset(&o, 0, sizeof o);
    o.optimizer = (tn_style_optimizer)7;
    TN_CHECK(tn_style_transfer(&out, &content, &style, &o) == TN_ERR_INVALID_ARG);
    o.optimizer = TN_STYLE_SGD;
    o.lr = -1;
    TN_CHECK(tn_style_transfer(&out, &content, &style, &o) == TN_ERR_INVALID_ARG);
    o.optimizer = TN_STYLE_ADAM;
    o.lr = INFINITY; /* not "out of memory" from the optimiser */
    TN_CHECK(tn_style_transfer(&out, &content, &style, &o) == TN_ERR_INVALID_ARG && strstr(tn_last_error(), "learning rate"));
    o.lr = 0;
    o.valley_weight = NAN;
    TN_CHECK(tn_style_transfer(&out, &content, &style, &o) == TN_ERR_INVALID_ARG && strstr(tn_last_error(), "weights"));
    TN_CHECK(out.data == NULL);
    { /* tiles too small for the map: more than fit per side, refused before any work */
        tn_image wide = {0, 0, 0, NULL};
        memset(&o, 0, sizeof o);
        o.tile = 32;
        o.iters = 1;
        o.levels = 1;
        tn_image_create(&wide, 2100, 16, 1);
        TN_CHECK(tn_style_transfer(&out, &wide, &style, &o) == TN_ERR_INVALID_ARG && strstr(tn_last_error(), "too small"));
        /* more tiles than deep-layer positions per tile (36 tiles of 32 x 32, 16 positions at
           layer 4): each still adds one sorted sample, nothing is read before the pool */
        tn_image_free(&wide);
        tn_image_create(&wide, 1000, 32, 1);
        for (x = 0; x < 1000 * 32; x++) wide.data[x] = (float)sin(0.05 * x) + 0.001f * (float)(x % 97);
        TN_CHECK(tn_style_transfer(&out, &wide, &style, &o) == TN_OK && tn_image_range(NULL, NULL, &out) == 0);
        tn_image_free(&out);
        tn_image_free(&wide);
    }
    /* scores: a map compared with itself */
    TN_CHECK(tn_style_compare(&sc, &style, &style) == TN_OK);
    TN_CHECK_NEAR(sc.ssim, 1.0, 1e-6);
    TN_CHECK_NEAR(sc.slope_hist_dist, 0.0, 1e-9);
    TN_CHECK_NEAR(sc.spectrum_dist, 0.0, 1e-6);
    TN_CHECK(tn_style_compare(&sc, &tiny, &style) == TN_ERR_INVALID_ARG);
    tn_image_free(&tiny);
    tn_image_free(&content);
    tn_image_free(&style);
}

/* The content map's gain follows the source's roughness: Perlin sources of gain 0.5 and 0.85
   (another seed) get back a gain near their own, and the map is exactly that Perlin map. */
TN_TEST(test_content_noise_matches_roughness)
{
    static const float gains[2] = {0.5f, 0.85f};
    tn_image src = {0, 0, 0, NULL}, out = {0, 0, 0, NULL}, ref = {0, 0, 0, NULL};
    tn_perlin_opts po;
    float g = 0.0f;
    int t;
    for (t = 0; t < 2; t++) {
        memset(&po, 0, sizeof po);
        po.seed = 99;
        po.gain = gains[t];
        TN_CHECK(tn_noise_perlin(&src, 128, 128, &po) == TN_OK);
        po.seed = 3;
        TN_CHECK(tn_style_content_noise(&out, 128, 128, &src, &po, &g) == TN_OK);
        TN_CHECK(fabsf(g - gains[t]) <= 0.101f);
        po.gain = g;
        TN_CHECK(tn_noise_perlin(&ref, 128, 128, &po) == TN_OK);
        TN_CHECK(out.data && ref.data && memcmp(out.data, ref.data, 128 * 128 * sizeof(float)) == 0);
        tn_image_free(&src);
        tn_image_free(&out);
        tn_image_free(&ref);
    }
    TN_CHECK(tn_style_content_noise(&out, 128, 128, NULL, NULL, &g) == TN_ERR_INVALID_ARG);
    TN_CHECK(out.data == NULL);
}

TN_TEST(test_vgg_loader_and_path)
{
    const char *path = "build/test/vgg19_random.tnw", *bad = "build/test/vgg19_bad.tnw";
    tn_params *p = NULL, *q = NULL, *wrong;
    tn_image content = {0, 0, 0, NULL}, style = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_style_opts o;
    tn_rng rng;
    int i, shape[4] = {64, 1, 3, 3};
    TN_CHECK(tn_vgg19_create(&p) == TN_OK);
    TN_CHECK(tn_params_count(p) == 32 && tn_params_numel(p) == 0); /* all buffers: no gradients */
    tn_rng_seed(&rng, 11, 0);
    for (i = 0; i < tn_params_count(p); i++) {
        tn_tensor *t = tn_params_get(p, i);
        if (t->ndim == 4) tn_init_kaiming(t, &rng, 1.41421356f);
        else tn_init_uniform(t, &rng, -0.05f, 0.05f);
    }
    TN_CHECK(tn_params_find(p, "conv5_4.weight") && tn_params_find(p, "conv5_4.weight")->shape[1] == 512);
    TN_CHECK(tn_params_save(path, p) == TN_OK);
    TN_CHECK(tn_vgg19_load(&q, path) == TN_OK);
    TN_CHECK(q && memcmp(tn_params_find(q, "conv3_2.weight")->data, tn_params_find(p, "conv3_2.weight")->data,
                         tn_params_find(p, "conv3_2.weight")->numel * sizeof(float)) == 0);
    /* wrong shape: conv1_1 with one input channel */
    wrong = tn_params_create();
    for (i = 0; i < tn_params_count(p); i++) {
        tn_tensor *t = tn_params_get(p, i);
        if (!strcmp(t->name, "conv1_1.weight")) tn_params_add_buffer(wrong, t->name, 4, shape);
        else tn_params_add_buffer(wrong, t->name, t->ndim, t->shape);
    }
    TN_CHECK(tn_params_save(bad, wrong) == TN_OK);
    {
        tn_params *r = NULL;
        TN_CHECK(tn_vgg19_load(&r, bad) == TN_ERR_SHAPE);
        TN_CHECK(strstr(tn_last_error(), "conv1_1.weight") != NULL);
        TN_CHECK(r == NULL);
        TN_CHECK(tn_vgg19_load(&r, "build/test/no_such_vgg.tnw") == TN_ERR_IO);
    }
    tn_params_free(wrong);
    /* wrong count: a file with only the built-in layout's first tensor */
    wrong = tn_params_create();
    tn_params_add_buffer(wrong, "conv1_1.weight", 4, tn_params_find(p, "conv1_1.weight")->shape);
    TN_CHECK(tn_params_save(bad, wrong) == TN_OK);
    {
        tn_params *r = NULL;
        TN_CHECK(tn_vgg19_load(&r, bad) == TN_ERR_SHAPE);
    }
    tn_params_free(wrong);
    /* the full VGG path on a small map */
    make_content(&content, 32, 32);
    make_style(&style, 40, 40);
    memset(&o, 0, sizeof o);
    o.vgg = q;
    o.iters = 3;
    o.levels = 1;
    TN_CHECK(tn_style_transfer(&out, &content, &style, &o) == TN_OK);
    TN_CHECK(out.width == 32 && out.height == 32 && tn_image_range(NULL, NULL, &out) == 0);
    /* a params set that is not VGG-19 is refused with a clear message */
    o.vgg = p;
    tn_image_free(&out);
    wrong = tn_params_create();
    tn_params_add_buffer(wrong, "conv1_1.weight", 4, shape);
    o.vgg = wrong;
    TN_CHECK(tn_style_transfer(&out, &content, &style, &o) == TN_ERR_SHAPE);
    tn_params_free(wrong);
    tn_image_free(&content);
    tn_image_free(&style);
    tn_params_free(p);
    tn_params_free(q);
    remove(path);
    remove(bad);
}

/* Mean power of the rows of m (Hann window, mean removed) at wavelength lam px (direct DFT). */
static double row_power(const tn_image *m, double lam)
{
    int x, y, w = m->width;
    double p = 0;
    for (y = 0; y < m->height; y++) {
        const float *r = m->data + (size_t)y * w;
        double mean = 0, re = 0, im = 0;
        for (x = 0; x < w; x++) mean += r[x];
        mean /= w;
        for (x = 0; x < w; x++) {
            double hw = 0.5 - 0.5 * cos(6.283185307 * x / (w - 1)), v = (r[x] - mean) * hw;
            re += v * cos(6.283185307 * x / lam);
            im += v * sin(6.283185307 * x / lam);
        }
        p += re * re + im * im;
    }
    return p / m->height;
}

/* Mean row power over wavelengths lam0..lam1 px (steps of 0.25). */
static double band_power(const tn_image *m, double lam0, double lam1)
{
    double lam, p = 0;
    int n = 0;
    for (lam = lam0; lam <= lam1 + 1e-9; lam += 0.25, n++) p += row_power(m, lam);
    return p / n;
}

TN_TEST(test_large_map_keeps_source_scale)
{
    /* A 64 px source of ridges 8 px apart (along x) styles a 3x larger map: the map must gain
       power at 8 px, the source's wavelength in its own pixels. The control run gives the
       source upsampled to the map's size, as the transfer did before: its ridges are 24 px
       apart, and so are the map's. Fails if the source is upsampled again. */
    tn_image content = {0, 0, 0, NULL}, src = {0, 0, 0, NULL}, up = {0, 0, 0, NULL}, a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_style_opts o;
    tn_style_scores sa, sb;
    tn_rng rng;
    double a8, a24, b8, b24;
    int x, y;
    tn_rng_seed(&rng, 11, 0);
    tn_image_create(&src, 64, 64, 1);
    for (y = 0; y < 64; y++)
        for (x = 0; x < 64; x++) src.data[y * 64 + x] = 100.0f * sinf(6.2831853f * x / 8.0f) + 5.0f * tn_rng_uniform(&rng);
    make_content(&content, 192, 192);
    memset(&o, 0, sizeof o);
    o.iters = 12;
    o.levels = 1;
    o.drain_weight = o.valley_weight = -1;
    TN_CHECK(tn_style_transfer(&a, &content, &src, &o) == TN_OK);
    TN_CHECK(tn_image_resize(&up, &src, 192, 192, TN_RESIZE_BICUBIC) == TN_OK);
    TN_CHECK(tn_style_transfer(&b, &content, &up, &o) == TN_OK);
    a8 = band_power(&a, 7, 9);
    a24 = band_power(&a, 21, 27);
    b8 = band_power(&b, 7, 9);
    b24 = band_power(&b, 21, 27);
    printf("  row power at 8 / 24 px: native source %.3g / %.3g, upsampled source %.3g / %.3g\n", a8, a24, b8, b24);
    TN_CHECK(a8 > b8);                     /* the source's ridges at their own pixel size */
    TN_CHECK(a8 / a24 > 4.0 * (b8 / b24)); /* and relatively less power at the upsampled wavelength */
    TN_CHECK(tn_style_compare(&sa, &a, &src) == TN_OK);
    TN_CHECK(tn_style_compare(&sb, &b, &src) == TN_OK);
    printf("  slope dist to the source: native %.3f, upsampled %.3f\n", sa.slope_hist_dist, sb.slope_hist_dist);
    TN_CHECK(sa.slope_hist_dist < sb.slope_hist_dist);
    tn_image_free(&a);
    tn_image_free(&b);
    tn_image_free(&up);
    tn_image_free(&src);
    tn_image_free(&content);
}

int main(void)
{
    TN_RUN(test_argsort);
    TN_RUN(test_content_noise_matches_roughness);
    TN_RUN(test_loss_decreases);
    TN_RUN(test_style_gradient);
    TN_RUN(test_transfer_threads_and_units);
    TN_RUN(test_drainage_terms);
    TN_RUN(test_drain_band_drains_straight_off);
    TN_RUN(test_auto_drainage);
    TN_RUN(test_tiles_and_progress);
    TN_RUN(test_large_map_keeps_source_scale);
    TN_RUN(test_margin_progress);
    TN_RUN(test_cancel);
    TN_RUN(test_bad_input);
    TN_RUN(test_vgg_loader_and_path);
    return tn_test_summary("test_style");
}
