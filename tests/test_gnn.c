/* test_gnn.c - @@gnn: the sketch-to-terrain graph network on a small synthetic example (Perlin
   terrain in metres): training lowers the loss, the membrane baseline, save/load, bit-identical
   resume, early stopping on holdouts, same results for 1 and 2 threads, and bad inputs (empty sketch, no part of 5 px, NaN
   DEM, flat DEM, another method's model, a checkpoint as a model, damaged files). */
#define TN_INTERNALS /* private tn__ code: the header's internals block */
#include "terrainnet.h"
#include "tn_test.h"

static int same_image(const tn_image *a, const tn_image *b)
{
    return a->width == b->width && a->height == b->height && a->channels == b->channels &&
           !memcmp(a->data, b->data, (size_t)a->width * a->height * a->channels * sizeof(float));
}

static tn_contour_set own_sketch(const tn_image *dem)
{
    tn_extraction ex;
    tn_contour_set s;
    memset(&s, 0, sizeof s);
    if (tn_extract(&ex, dem, NULL)) return s;
    s = ex.contours;
    memset(&ex.contours, 0, sizeof ex.contours);
    tn_extraction_free(&ex);
    return s;
}

TN_TEST(membrane_interpolates_between_lines)
{
    /* two vertical valley lines at heights 10 and 30: the membrane is the linear ramp between
       them and constant outside (no flux across the border) */
    tn_contour_set s;
    tn_contour c[2];
    float p0[3 * 20], p1[3 * 20];
    tn_image m = {0, 0, 0, NULL};
    int i;
    for (i = 0; i < 20; i++) {
        p0[3 * i] = 4;
        p1[3 * i] = 24;
        p0[3 * i + 1] = p1[3 * i + 1] = (float)i;
        p0[3 * i + 2] = 10;
        p1[3 * i + 2] = 30;
    }
    memset(c, 0, sizeof c);
    c[0].npoints = c[1].npoints = 20;
    c[0].points = p0;
    c[1].points = p1;
    s.width = 32;
    s.height = 20;
    s.count = 2;
    s.items = c;
    TN_CHECK(tn_gnn_membrane(&m, &s, 32, 20) == TN_OK);
    TN_CHECK_NEAR(TN_PIXEL(&m, 14, 10, 0), 20.0f, 1e-3);
    TN_CHECK_NEAR(TN_PIXEL(&m, 9, 3, 0), 15.0f, 1e-3);
    TN_CHECK_NEAR(TN_PIXEL(&m, 0, 0, 0), 10.0f, 1e-3);
    TN_CHECK_NEAR(TN_PIXEL(&m, 31, 19, 0), 30.0f, 1e-3);
    tn_image_free(&m);
    s.count = 0;
    TN_CHECK(tn_gnn_membrane(&m, &s, 32, 20) == TN_ERR_EMPTY);
}

/* max over free pixels of |sum of 4-neighbours in the map of (u_q - u_p)|, and of |u - val| on fixed ones */
static void membrane_residual(const float *u, const float *val, const uint8_t *fixed, int W, int H, double *lap, double *fix)
{
    int x, y;
    *lap = *fix = 0;
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) {
            size_t p = (size_t)y * W + x;
            double s = 0;
            if (fixed[p]) {
                *fix = fmax(*fix, fabs((double)u[p] - val[p]));
                continue;
            }
            if (x > 0) s += (double)u[p - 1] - u[p];
            if (x < W - 1) s += (double)u[p + 1] - u[p];
            if (y > 0) s += (double)u[p - W] - u[p];
            if (y < H - 1) s += (double)u[p + W] - u[p];
            *lap = fmax(*lap, fabs(s));
        }
}

TN_TEST(membrane_solver_is_the_laplace_solution)
{
    /* the multigrid-preconditioned solver on random problems of odd sizes (several levels, a
       ring of thin ones, one fixed pixel): the discrete Laplace equation holds on free pixels to
       1e-5 of the range (the solver stops at a Jacobi-scaled residual of 1e-7; a plain float
       rounding of the answer is ~1e-7), fixed pixels keep their values exactly, and on a small map
       the answer equals Gauss-Seidel run to convergence */
    static const int size[][2] = {{203, 141}, {67, 67}, {1, 300}, {3, 257}, {129, 2}, {7, 5}, {24, 17}};
    tn_rng r;
    int k;
    tn_rng_seed(&r, 11, 0);
    for (k = 0; k < (int)(sizeof size / sizeof size[0]); k++) {
        int W = size[k][0], H = size[k][1], x, y, it, nf = 0;
        size_t n = (size_t)W * H, i;
        float *val = (float *)calloc(n, sizeof(float)), *u = (float *)malloc(n * sizeof(float));
        uint8_t *fixed = (uint8_t *)calloc(n, 1);
        double lap, fix;
        for (i = 0; i < n; i++)
            if (tn_rng_uniform(&r) < (k == 0 ? 0.002f : 0.02f)) fixed[i] = 1, val[i] = 100 + 1000 * tn_rng_uniform(&r), nf++;
        for (x = 0; k == 0 && x < W / 2; x++) fixed[(size_t)(H / 3) * W + x] = 1, val[(size_t)(H / 3) * W + x] = 100 + 4.0f * (float)x; /* a line */
        if (!nf) fixed[n / 2] = 1, val[n / 2] = 500;
        TN_CHECK(tn__gnn_membrane_solve(val, fixed, W, H, u) == TN_OK);
        membrane_residual(u, val, fixed, W, H, &lap, &fix);
        printf("  membrane %d x %d: max |Laplacian| %.2e of the range\n", W, H, lap / 1000);
        TN_CHECK(fix == 0 && lap < 1e-5 * 1000);
        if (W >= 5 && H >= 5 && W * H <= 24 * 17) { /* Gauss-Seidel in double to convergence */
            double *g = (double *)calloc(n, sizeof(double));
            for (i = 0; i < n; i++) g[i] = fixed[i] ? val[i] : 500;
            for (it = 0; it < 20000; it++)
                for (y = 0; y < H; y++)
                    for (x = 0; x < W; x++) {
                        size_t p = (size_t)y * W + x;
                        double s = 0;
                        int c = 0;
                        if (fixed[p]) continue;
                        if (x > 0) s += g[p - 1], c++;
                        if (x < W - 1) s += g[p + 1], c++;
                        if (y > 0) s += g[p - W], c++;
                        if (y < H - 1) s += g[p + W], c++;
                        g[p] = s / c;
                    }
            for (i = 0; i < n; i++) TN_CHECK_NEAR(u[i], g[i], 1e-5 * 1000);
            free(g);
        }
        /* one fixed pixel: the constant */
        memset(fixed, 0, n);
        fixed[n - 1] = 1;
        val[n - 1] = 321;
        TN_CHECK(tn__gnn_membrane_solve(val, fixed, W, H, u) == TN_OK);
        for (i = 0; i < n; i++) TN_CHECK(u[i] == 321.0f);
        free(val);
        free(u);
        free(fixed);
    }
}

TN_TEST(training_lowers_the_loss_and_generates_metres)
{
    tn_image dem = tn_test_dem(40, 3), out0 = {0, 0, 0, NULL}, out = {0, 0, 0, NULL}, mem = {0, 0, 0, NULL};
    tn_gnn_opts o;
    tn_gnn m0, m;
    tn_gnn_stats s0, s;
    tn_contour_set sk = own_sketch(&dem);
    tn_metrics a0, a, b;
    /* the loss, on the example's own network alone (the sparse levels have other losses) */
    tn_test_tiny_gnn_opts(&o, 1);
    o.sparse_levels = -1;
    TN_CHECK(tn_gnn_train(&m0, &dem, &o, &s0) == TN_OK);
    tn_gnn_free(&m0);
    tn_test_tiny_gnn_opts(&o, 80);
    o.sparse_levels = -1;
    o.lr = 5e-3f;
    TN_CHECK(tn_gnn_train(&m, &dem, &o, &s) == TN_OK);
    TN_CHECK(s.levels == 1 && isfinite(s.loss) && s.loss < 0.8f * s0.loss); /* s.loss: mean of the last 50 steps */
    tn_gnn_free(&m);
    /* the default run: its reconstruction improves on the first step's and on the membrane
       (without the embedding phase, which 60 steps are too few for; its own test below) */
    tn_test_tiny_gnn_opts(&o, 1);
    TN_CHECK(tn_gnn_train(&m0, &dem, &o, &s0) == TN_OK);
    tn_test_tiny_gnn_opts(&o, 60);
    o.lr = 5e-3f;
    o.embed_phase = -1;
    TN_CHECK(tn_gnn_train(&m, &dem, &o, &s) == TN_OK);
    TN_CHECK(s.iterations == 60 && s.parts >= 5 && s.edges > 0 && s.levels >= 2);
    TN_CHECK(strcmp(tn_params_meta(m.weights, "method"), "gnn") == 0);
    TN_CHECK(m.parts == s.parts && m.width == 40 && m.height == 40);
    TN_CHECK(tn_gnn_generate(&out0, &m0, &sk, 40, 40, NULL) == TN_OK);
    TN_CHECK(tn_gnn_generate(&out, &m, &sk, 40, 40, NULL) == TN_OK);
    TN_CHECK(out.width == 40 && out.height == 40 && out.channels == 1);
    TN_CHECK(tn_gnn_membrane(&mem, &sk, 40, 40) == TN_OK);
    TN_CHECK(tn_compare(&a0, &dem, &out0, 0) == TN_OK && tn_compare(&a, &dem, &out, 0) == TN_OK && tn_compare(&b, &dem, &mem, 0) == TN_OK);
    TN_CHECK(a.ssim > 0.5 && a.rmse < 200.0); /* metres, not normalised units */
    TN_CHECK(a.rmse < a0.rmse && a.rmse < b.rmse);
    tn_image_free(&out0);
    tn_image_free(&out);
    tn_image_free(&mem);
    tn_contour_set_free(&sk);
    tn_gnn_free(&m0);
    tn_gnn_free(&m);
    tn_image_free(&dem);
}

/* Trains a model with o and generates the sketch at the DEM's size into *out (freed first). */
static int train_and_generate(const tn_image *dem, const tn_gnn_opts *o, const tn_contour_set *sk, tn_image *out)
{
    tn_gnn m;
    int ok;
    tn_image_free(out);
    if (tn_gnn_train(&m, dem, o, NULL) != TN_OK) return 0;
    ok = tn_gnn_generate(out, &m, sk, dem->width, dem->height, NULL) == TN_OK;
    tn_gnn_free(&m);
    return ok;
}

/* Share of the pixels 1-4 px from a sketch point (not on a line) that lie below the nearest
   point's height if it is a ridge's, above if a valley's: what 6.1's sketch term asks for. */
static double beside_share(const tn_contour_set *sk, const tn_image *img)
{
    tn_image r = {0, 0, 0, NULL};
    long ok = 0, n = 0;
    int x, y, c, j;
    if (tn_sketch_rasterise(&r, sk, img->width, img->height)) return -1;
    for (y = 0; y < img->height; y++)
        for (x = 0; x < img->width; x++) {
            const float *px = r.data + 3 * ((size_t)y * img->width + x);
            float bd = 1e30f, bh = 0, bs = 0;
            if (px[0] > 0 || px[1] > 0) continue;
            for (c = 0; c < sk->count; c++)
                for (j = 0; j < sk->items[c].npoints; j++) {
                    const float *p = sk->items[c].points + 3 * j;
                    float d = (p[0] - (float)x) * (p[0] - (float)x) + (p[1] - (float)y) * (p[1] - (float)y);
                    if (d < bd) {
                        bd = d;
                        bh = p[2];
                        bs = sk->items[c].type == TN_RIDGE ? 1.0f : -1.0f;
                    }
                }
            if (bd < 0.49f || bd > 16.0f) continue;
            n++;
            ok += bs * (bh - TN_PIXEL(img, x, y, 0)) > 0;
        }
    tn_image_free(&r);
    return n ? (double)ok / (double)n : -1;
}

TN_TEST(shape_losses)
{
    /* 6.1's smooth, sketch and further terms: a heavy smoothness weight gives a smoother
       reconstruction than none; the sketch term puts more of the pixels beside the example's
       lines on their side of the line's height (what it asks; the across-line ordering of the
       line pixels themselves, which it does not constrain, can fall); each term changes the
       model; negative weights are refused */
    tn_image dem = tn_test_dem(40, 5), a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_gnn_opts o;
    tn_gnn m;
    tn_contour_set sk = own_sketch(&dem);
    double sh0 = 0, sh1 = 0;
    int x, y;
    float g0 = 0, g1 = 0;
    tn_test_tiny_gnn_opts(&o, 40);
    o.lr = 5e-3f;
    o.smooth_weight = -1; /* each term alone */
    TN_CHECK(train_and_generate(&dem, &o, &sk, &a));
    o.smooth_weight = 50;
    TN_CHECK(train_and_generate(&dem, &o, &sk, &b));
    for (y = 0; y < 40 && a.data && b.data; y++)
        for (x = 0; x + 1 < 40; x++) {
            g0 += fabsf(TN_PIXEL(&a, x + 1, y, 0) - TN_PIXEL(&a, x, y, 0));
            g1 += fabsf(TN_PIXEL(&b, x + 1, y, 0) - TN_PIXEL(&b, x, y, 0));
        }
    TN_CHECK(g1 < g0);
    o.smooth_weight = -1;
    o.sketch_weight = 20;
    TN_CHECK(train_and_generate(&dem, &o, &sk, &b));
    sh0 = beside_share(&sk, &a);
    sh1 = beside_share(&sk, &b);
    TN_CHECK(sh0 > 0 && sh1 > sh0);
    o.sketch_weight = 0;
    o.further_weight = 5;
    TN_CHECK(train_and_generate(&dem, &o, &sk, &b));
    TN_CHECK(b.data && a.data && !same_image(&a, &b));
    o.further_weight = -1;
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_ERR_INVALID_ARG);
    tn_image_free(&a);
    tn_image_free(&b);
    tn_contour_set_free(&sk);
    tn_image_free(&dem);
}

TN_TEST(save_load_round_trip)
{
    const char *path = tn_test_tmp_path("gnn", "model.tnw");
    tn_image dem = tn_test_dem(40, 4), a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_gnn_opts o;
    tn_gnn m, l;
    tn_gnn_generate_opts go;
    tn_contour_set sk = own_sketch(&dem), p1, p2;
    tn_test_tiny_gnn_opts(&o, 5);
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_OK);
    TN_CHECK(tn_gnn_save(path, &m) == TN_OK);
    TN_CHECK(tn_gnn_load(&l, path) == TN_OK);
    TN_CHECK(tn_test_same_params(m.weights, l.weights, 0));
    TN_CHECK(l.iterations == 5 && l.parts == m.parts && l.mean == m.mean && l.std == m.std && l.k == m.k && l.membrane == 1);
    memset(&go, 0, sizeof go);
    go.seed = 3;
    go.finetune = 2;
    TN_CHECK(tn_gnn_generate(&a, &m, &sk, 40, 40, &go) == TN_OK);
    TN_CHECK(tn_gnn_generate(&b, &l, &sk, 40, 40, &go) == TN_OK);
    TN_CHECK(same_image(&a, &b));
    TN_CHECK(tn_gnn_parts(&p1, &l) == TN_OK && tn_gnn_parts(&p2, &m) == TN_OK);
    TN_CHECK(p1.count == m.parts && p1.count == p2.count && p1.items[0].npoints == p2.items[0].npoints);
    tn_contour_set_free(&p1);
    tn_contour_set_free(&p2);
    tn_image_free(&a);
    tn_image_free(&b);
    tn_contour_set_free(&sk);
    tn_gnn_free(&m);
    tn_gnn_free(&l);
    tn_image_free(&dem);
}

TN_TEST(part_overhang)
{
    /* a part without an embedding tells a pixel how far it lies beyond the part's end, not
       where along the part (a random cut) it projects */
    const char *path = tn_test_tmp_path("gnn", "overhang.tnw");
    tn__gnn_parts P;
    tn_contour_set line;
    tn_contour c;
    float pts[30], d2;
    int i, j;
    tn_image dem = tn_test_dem(40, 4), other = tn_test_dem(40, 5), a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_gnn_opts o;
    tn_gnn m;
    tn_tensor *cfg;
    tn_contour_set own = own_sketch(&dem), foreign = own_sketch(&other);
    for (i = 0; i < 10; i++) { /* (10, 10) .. (19, 10) */
        pts[3 * i] = 10.0f + (float)i;
        pts[3 * i + 1] = 10.0f;
        pts[3 * i + 2] = 5.0f;
    }
    memset(&c, 0, sizeof c);
    c.type = TN_RIDGE;
    c.npoints = 10;
    c.points = pts;
    line.count = 1;
    line.items = &c;
    TN_CHECK(tn__gnn_parts_make(&line, 0.0f, 1.0f, &P) == TN_OK);
    j = tn__gnn_project(&P, 0, 25.0f, 13.0f, &d2);
    TN_CHECK(j == 9 && fabsf(tn__gnn_overhang(&P, 0, 1.0f, 25.0f, 13.0f) - 6.0f / TN__GNN_DIST) < 1e-6f);
    TN_CHECK(fabsf(tn__gnn_overhang(&P, 0, -1.0f, 4.0f, 7.0f) - 6.0f / TN__GNN_DIST) < 1e-6f);
    TN_CHECK(tn__gnn_overhang(&P, 0, 2.0f * 5.0f / 9.0f - 1.0f, 15.0f, 4.0f) == 0.0f); /* beside the part */
    TN_CHECK(tn__gnn_overhang(&P, 0, 1.0f, 19.0f, 2.0f) == 0.0f);                    /* beside its end */
    tn__gnn_parts_free(&P);
    /* the model records the choice; it changes what a sketch of other terrain gives and leaves
       the example's own network (every part with an embedding) as it was */
    tn_test_tiny_gnn_opts(&o, 20);
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_OK);
    cfg = tn_params_find(m.weights, "gnn.config");
    TN_CHECK(cfg && cfg->data[17] == 1.0f);
    TN_CHECK(tn_gnn_generate(&a, &m, &own, 40, 40, NULL) == TN_OK);
    cfg->data[17] = 0.0f; /* a model written before the overhang: the index on every part */
    TN_CHECK(tn_gnn_generate(&b, &m, &own, 40, 40, NULL) == TN_OK);
    TN_CHECK(same_image(&a, &b));
    tn_image_free(&a);
    tn_image_free(&b);
    TN_CHECK(tn_gnn_generate(&a, &m, &foreign, 40, 40, NULL) == TN_OK);
    cfg->data[17] = 1.0f;
    TN_CHECK(tn_gnn_generate(&b, &m, &foreign, 40, 40, NULL) == TN_OK);
    TN_CHECK(!same_image(&a, &b));
    tn_image_free(&a);
    cfg->data[17] = 2.0f; /* damaged */
    TN_CHECK(tn_gnn_generate(&a, &m, &own, 40, 40, NULL) == TN_ERR_CORRUPT && !a.data);
    TN_CHECK(tn_gnn_save(path, &m) == TN_ERR_CORRUPT);
    tn_gnn_free(&m);
    o.part_index = -1;
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_OK);
    TN_CHECK(tn_params_find(m.weights, "gnn.config")->data[17] == 0.0f);
    tn_gnn_free(&m);
    tn_image_free(&a);
    tn_image_free(&b);
    tn_contour_set_free(&own);
    tn_contour_set_free(&foreign);
    tn_image_free(&dem);
    tn_image_free(&other);
}

TN_TEST(embedding_phase)
{
    /* the last quarter of the budget moves only the example's embeddings: every other tensor
       equals a run stopped where the phase starts, the embeddings do not, and the example's
       own network is reconstructed closer than by that run */
    tn_image dem = tn_test_dem(40, 4), a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_contour_set sk = own_sketch(&dem);
    tn_gnn_opts o;
    tn_gnn with, stop;
    tn_gnn_stats st;
    tn_metrics ma, mb;
    int i, emb_differs = 0, others_same = 1;
    tn_test_tiny_gnn_opts(&o, 40);
    o.lr = 5e-3f;
    TN_CHECK(tn_gnn_train(&with, &dem, &o, &st) == TN_OK);
    TN_CHECK(st.embed_phase_from == 30);
    tn_test_tiny_gnn_opts(&o, 30);
    o.lr = 5e-3f;
    o.embed_phase = -1;
    TN_CHECK(tn_gnn_train(&stop, &dem, &o, &st) == TN_OK);
    TN_CHECK(st.embed_phase_from == -1);
    TN_CHECK(tn_params_count(with.weights) == tn_params_count(stop.weights));
    for (i = 0; i < tn_params_count(with.weights); i++) {
        const tn_tensor *x = tn_params_get(with.weights, i), *y = tn_params_get(stop.weights, i);
        int same = x->numel == y->numel && !memcmp(x->data, y->data, x->numel * sizeof(float));
        if (!strcmp(x->name, "gnn.emb")) emb_differs = !same;
        else if (x->requires_grad && !same) others_same = 0;
    }
    TN_CHECK(emb_differs && others_same);
    TN_CHECK(tn_gnn_generate(&a, &with, &sk, 40, 40, NULL) == TN_OK && tn_gnn_generate(&b, &stop, &sk, 40, 40, NULL) == TN_OK);
    TN_CHECK(tn_compare(&ma, &dem, &a, 0) == TN_OK && tn_compare(&mb, &dem, &b, 0) == TN_OK);
    TN_CHECK(ma.rmse < mb.rmse);
    /* a share of 1 or more (no training before the phase) or NaN is refused */
    o.embed_phase = 1.0f;
    TN_CHECK(tn_gnn_train(&with, &dem, &o, NULL) == TN_ERR_INVALID_ARG);
    o.embed_phase = NAN;
    TN_CHECK(tn_gnn_train(&with, &dem, &o, NULL) == TN_ERR_INVALID_ARG);
    tn_image_free(&a);
    tn_image_free(&b);
    tn_contour_set_free(&sk);
    tn_gnn_free(&with);
    tn_gnn_free(&stop);
    tn_image_free(&dem);
}

TN_TEST(resume_is_bit_identical)
{
    const char *ck = tn_test_tmp_path("gnn", "run.ckpt");
    tn_image dem = tn_test_dem(40, 5);
    tn_gnn_opts o;
    tn_gnn full, part, res;
    tn_gnn_stats st;
    tn_test_tiny_gnn_opts(&o, 8);
    TN_CHECK(tn_gnn_train(&full, &dem, &o, NULL) == TN_OK);
    tn_test_tiny_gnn_opts(&o, 3);
    o.train.checkpoint = ck;
    TN_CHECK(tn_gnn_train(&part, &dem, &o, NULL) == TN_OK);
    tn_test_tiny_gnn_opts(&o, 8);
    o.train.checkpoint = ck;
    o.train.resume = 1;
    o.train.seed = 999; /* the checkpoint's seed wins */
    o.hidden = 24;      /* and its architecture */
    TN_CHECK(tn_gnn_train(&res, &dem, &o, &st) == TN_OK);
    TN_CHECK(st.resumed_from == 3 && st.iterations == 8);
    TN_CHECK(res.hidden == 16);
    TN_CHECK(tn_test_same_params(full.weights, res.weights, 0));
    tn_gnn_free(&res);
    /* a checkpoint is not a model; another example cannot resume it */
    TN_CHECK(tn_gnn_load(&res, ck) == TN_ERR_FORMAT);
    tn_gnn_free(&part);
    tn_gnn_free(&full);
    {
        tn_image other = tn_test_dem(40, 6);
        TN_CHECK(tn_gnn_train(&res, &other, &o, NULL) != TN_OK);
        tn_image_free(&other);
    }
    tn_image_free(&dem);
}

TN_TEST(same_results_for_1_and_2_threads)
{
    tn_image dem = tn_test_dem(40, 8), a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_gnn_opts o;
    tn_gnn m1, m2;
    tn_gnn_generate_opts go;
    tn_contour_set sk = own_sketch(&dem);
    int before = tn_get_threads();
    tn_test_tiny_gnn_opts(&o, 4);
    memset(&go, 0, sizeof go);
    go.finetune = 2;
    go.order_weight = 1;
    tn_set_threads(1);
    TN_CHECK(tn_gnn_train(&m1, &dem, &o, NULL) == TN_OK);
    TN_CHECK(tn_gnn_generate(&a, &m1, &sk, 48, 40, &go) == TN_OK);
    tn_set_threads(2);
    TN_CHECK(tn_gnn_train(&m2, &dem, &o, NULL) == TN_OK);
    TN_CHECK(tn_gnn_generate(&b, &m2, &sk, 48, 40, &go) == TN_OK);
    tn_set_threads(before);
    TN_CHECK(tn_test_same_params(m1.weights, m2.weights, 0));
    TN_CHECK(a.width == 48 && same_image(&a, &b));
    tn_image_free(&a);
    tn_image_free(&b);
    tn_contour_set_free(&sk);
    tn_gnn_free(&m1);
    tn_gnn_free(&m2);
    tn_image_free(&dem);
}

TN_TEST(bad_inputs_fail_cleanly)
{
    const char *path = tn_test_tmp_path("gnn", "bad.tnw");
    tn_image dem = tn_test_dem(40, 9), flat = {0, 0, 0, NULL}, empty = {0, 0, 0, NULL}, small = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_gnn_opts o;
    tn_gnn m, l;
    tn_contour_set sk, none;
    tn_contour c;
    float pts[9] = {5, 5, 1200, 6, 5, 1210, 7, 5, 1220};
    uint8_t *buf = NULL;
    size_t n = 0;
    FILE *f;
    tn_test_tiny_gnn_opts(&o, 2);
    /* DEMs */
    TN_CHECK(tn_gnn_train(&m, &empty, &o, NULL) == TN_ERR_EMPTY);
    tn_image_create(&small, 10, 10, 1);
    TN_CHECK(tn_gnn_train(&m, &small, &o, NULL) == TN_ERR_INVALID_ARG);
    tn_image_create(&flat, 40, 40, 1);
    TN_CHECK(tn_gnn_train(&m, &flat, &o, NULL) == TN_ERR_EMPTY && strstr(tn_last_error(), "flat"));
    o.extract.threshold = 1000000; /* no cell drains that much: no ridge or valley */
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_ERR_EMPTY && strstr(tn_last_error(), "extract"));
    o.extract.threshold = 0;
    dem.data[77] = NAN;
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_ERR_NUMERIC && strstr(tn_last_error(), "NaN"));
    dem.data[77] = 1500.0f;
    o.hidden = 1000;
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_ERR_INVALID_ARG);
    TN_CHECK(strcmp(tn_last_error(), "gnn: option hidden = 1000, allowed 1 .. 256") == 0);
    /* one message per rule: each names its option and range */
    tn_test_tiny_gnn_opts(&o, 2);
    o.lr = -0.001f; /* zero is the default; a negative rate is an error, not the default */
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_ERR_INVALID_ARG);
    TN_CHECK(strcmp(tn_last_error(), "gnn: option lr = -0.001, allowed (0, 10)") == 0);
    tn_test_tiny_gnn_opts(&o, 2);
    o.ssim_weight = NAN;
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_ERR_INVALID_ARG);
    TN_CHECK(strcmp(tn_last_error(), "gnn: option ssim_weight = nan, allowed finite") == 0);
    tn_test_tiny_gnn_opts(&o, 2);
    o.holdout_count = 2; /* and no holdout */
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_ERR_INVALID_ARG);
    TN_CHECK(strstr(tn_last_error(), "holdout_count = 2") != NULL);
    tn_test_tiny_gnn_opts(&o, 2);
    o.train.resume = 1;
    o.train.checkpoint = "build/test/no_such_gnn.ckpt";
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_ERR_IO);
    tn_test_tiny_gnn_opts(&o, 2);
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_OK);
    /* sketches */
    memset(&none, 0, sizeof none);
    none.width = none.height = 40;
    TN_CHECK(tn_gnn_generate(&out, &m, &none, 40, 40, NULL) == TN_ERR_EMPTY);
    memset(&c, 0, sizeof c);
    c.type = TN_RIDGE;
    c.npoints = 3;
    c.points = pts;
    sk.width = sk.height = 40;
    sk.count = 1;
    sk.items = &c;
    TN_CHECK(tn_gnn_generate(&out, &m, &sk, 40, 40, NULL) == TN_ERR_EMPTY && strstr(tn_last_error(), "5 px"));
    pts[4] = NAN;
    TN_CHECK(tn_gnn_generate(&out, &m, &sk, 40, 40, NULL) == TN_ERR_NUMERIC);
    pts[4] = 5;
    TN_CHECK(tn_gnn_generate(&out, &m, &sk, 8, 40, NULL) == TN_ERR_INVALID_ARG);
    {
        tn_gnn_generate_opts go;
        memset(&go, 0, sizeof go);
        go.random_nodes = 9000;
        TN_CHECK(tn_gnn_generate(&out, &m, &sk, 40, 40, &go) == TN_ERR_INVALID_ARG);
        TN_CHECK(strcmp(tn_last_error(), "gnn generate: option random_nodes = 9000, allowed 0 .. 8192") == 0);
        go.random_nodes = 0;
        go.grow = 2;
        TN_CHECK(tn_gnn_generate(&out, &m, &sk, 40, 40, &go) == TN_ERR_INVALID_ARG);
        go.grow = 0;
        go.order_weight = NAN;
        TN_CHECK(tn_gnn_generate(&out, &m, &sk, 40, 40, &go) == TN_ERR_INVALID_ARG);
        TN_CHECK(strcmp(tn_last_error(), "gnn generate: option order_weight = nan, allowed <= 1e+06") == 0);
    }
    TN_CHECK(out.data == NULL);
    /* model files: another method's model, another .tnw, a damaged byte, a damaged config */
    {
        tn_params *p = tn_params_create();
        int two = 2;
        tn_params_add(p, "g.w0", 1, &two);
        tn_model_stamp(p, "texgan", 1, NULL);
        tn_params_save(path, p);
        tn_params_free(p);
        TN_CHECK(tn_gnn_load(&l, path) == TN_ERR_FORMAT && strstr(tn_last_error(), "texgan"));
        p = tn_params_create();
        tn_params_add(p, "x", 1, &two);
        tn_params_save(path, p);
        tn_params_free(p);
        TN_CHECK(tn_gnn_load(&l, path) == TN_ERR_FORMAT);
    }
    TN_CHECK(tn_gnn_save(path, &m) == TN_OK);
    TN_CHECK(tn__io_read_file(path, &buf, &n) == TN_OK);
    buf[n / 2] ^= 0x40;
    f = fopen(path, "wb");
    fwrite(buf, 1, n, f);
    fclose(f);
    TN_CHECK(tn_gnn_load(&l, path) == TN_ERR_CORRUPT);
    tn_free(buf);
    tn_params_find(m.weights, "gnn.config")->data[3] = 1000.0f; /* k */
    TN_CHECK(tn_gnn_save(path, &m) == TN_ERR_CORRUPT);           /* refused before writing */
    TN_CHECK(tn_gnn_generate(&out, &m, &sk, 40, 40, NULL) == TN_ERR_CORRUPT);
    TN_CHECK(tn_params_save(path, m.weights) == TN_OK);
    TN_CHECK(tn_gnn_load(&l, path) == TN_ERR_CORRUPT);
    tn_params_find(m.weights, "gnn.config")->data[3] = 6.0f;
    tn_params_find(m.weights, "gnn.part_info")->data[1] = 1e6f; /* a part's point count */
    TN_CHECK(tn_params_save(path, m.weights) == TN_OK);
    TN_CHECK(tn_gnn_load(&l, path) == TN_ERR_CORRUPT);
    TN_CHECK(tn_gnn_load(&l, "build/test/no_such_model.tnw") == TN_ERR_IO);
    tn_gnn_free(&m);
    tn_image_free(&dem);
    tn_image_free(&flat);
    tn_image_free(&small);
}

/* A 3-step model of radius 6 px and a random sketch of w x h (ridges from `nodes` nodes). */
static int radius6_model_and_sketch(const tn_image *dem, uint64_t seed, int nodes, int w, int h, tn_gnn *m, tn_contour_set *sk)
{
    tn_gnn_opts o;
    tn_sketch_random_opts ro;
    tn_test_tiny_gnn_opts(&o, 3);
    o.radius = 6;
    memset(&ro, 0, sizeof ro);
    ro.seed = seed;
    ro.nodes = nodes;
    return tn_gnn_train(m, dem, &o, NULL) == TN_OK && tn_sketch_random(sk, NULL, w, h, &ro) == TN_OK;
}

/* win equals the pixels of whole at (x0, y0). */
static int window_matches(const tn_image *win, const tn_image *whole, int x0, int y0)
{
    int x, y;
    if (!win->data || !whole->data) return 0;
    for (y = 0; y < win->height; y++)
        for (x = 0; x < win->width; x++)
            if (TN_PIXEL(win, x, y, 0) != TN_PIXEL(whole, x0 + x, y0 + y, 0)) return 0;
    return 1;
}

TN_TEST(window_equals_whole_map)
{
    /* seamless tiles: a window computed alone equals the same pixels of the whole map, on a map
       larger than one membrane block (260 x 200, so the blocked membrane blends), with a random
       sketch; also the bounded-influence membrane is continuous and matches the plain solve on
       a map of one block */
    tn_image dem = tn_test_dem(40, 12), whole = {0, 0, 0, NULL}, win = {0, 0, 0, NULL}, win2 = {0, 0, 0, NULL};
    tn_gnn m;
    tn_gnn_generate_opts go;
    tn_contour_set sk;
    int before = tn_get_threads();
    TN_CHECK(radius6_model_and_sketch(&dem, 3, 40, 260, 200, &m, &sk));
    TN_CHECK(m.radius == 6.0f);
    memset(&go, 0, sizeof go);
    go.seed = 5;
    TN_CHECK(tn_gnn_generate(&whole, &m, &sk, 260, 200, &go) == TN_OK);
    TN_CHECK(tn_gnn_generate_window(&win, &m, &sk, 260, 200, 150, 70, 90, 50, &go) == TN_OK);
    TN_CHECK(win.width == 90 && win.height == 50);
    TN_CHECK(window_matches(&win, &whole, 150, 70));
    tn_set_threads(1 + (before == 1));
    TN_CHECK(tn_gnn_generate_window(&win2, &m, &sk, 260, 200, 150, 70, 90, 50, &go) == TN_OK);
    tn_set_threads(before);
    TN_CHECK(same_image(&win, &win2));
    TN_CHECK(tn_gnn_generate_window(&win2, &m, &sk, 260, 200, 200, 70, 90, 50, &go) == TN_ERR_INVALID_ARG);
    tn_image_free(&whole);
    tn_image_free(&win);
    tn_image_free(&win2);
    tn_contour_set_free(&sk);
    tn_gnn_free(&m);
    tn_image_free(&dem);
}

TN_TEST(finetune_in_windows)
{
    /* a map over 256^2 fine-tunes window by window: it lifts the ridges above (valleys below)
       the land beside them, gives the same bits on 1 and 2 threads, and a window of the map
       still equals the whole map's pixels */
    tn_image dem = tn_test_dem(40, 12), a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL}, c = {0, 0, 0, NULL};
    tn_gnn m;
    tn_gnn_generate_opts go;
    tn_contour_set sk;
    double s0 = 0, s1 = 0;
    int before = tn_get_threads();
    TN_CHECK(radius6_model_and_sketch(&dem, 4, 30, 300, 270, &m, &sk));
    memset(&go, 0, sizeof go);
    go.seed = 5;
    go.gain = 1;
    TN_CHECK(tn_gnn_generate(&a, &m, &sk, 300, 270, &go) == TN_OK);
    go.finetune = 6;
    go.finetune_lr = 0.05f;
    TN_CHECK(tn_gnn_generate(&b, &m, &sk, 300, 270, &go) == TN_OK);
    TN_CHECK(tn_gnn_ordering(&s0, &sk, &a, 0, NULL) == TN_OK && tn_gnn_ordering(&s1, &sk, &b, 0, NULL) == TN_OK);
    printf("  ordering without / with the fine-tune: %.3f / %.3f\n", s0, s1);
    TN_CHECK(s1 > s0 + 0.02);
    tn_set_threads(1 + (before == 1));
    TN_CHECK(tn_gnn_generate_window(&c, &m, &sk, 300, 270, 180, 150, 100, 80, &go) == TN_OK);
    tn_set_threads(before);
    TN_CHECK(c.width == 100 && c.height == 80 && window_matches(&c, &b, 180, 150));
    tn_image_free(&a);
    tn_image_free(&b);
    tn_image_free(&c);
    tn_contour_set_free(&sk);
    tn_gnn_free(&m);
    tn_image_free(&dem);
}

TN_TEST(residual_gain)
{
    /* the gain validated on the sketch: 1 for the example's own network (the reconstruction),
       in [0, 1] otherwise; a fixed gain blends the membrane and the network's output linearly;
       the validated gain gives the same output as that gain set by hand */
    tn_image dem = tn_test_dem(48, 13), full = {0, 0, 0, NULL}, none = {0, 0, 0, NULL}, half = {0, 0, 0, NULL}, autog = {0, 0, 0, NULL},
             fixg = {0, 0, 0, NULL}, mem = {0, 0, 0, NULL};
    tn_gnn_opts o;
    tn_gnn m;
    tn_gnn_generate_opts go;
    tn_contour_set own = own_sketch(&dem);
    float g = -1, ga = -1;
    size_t i, n = (size_t)48 * 48;
    int lin = 1;
    tn_test_tiny_gnn_opts(&o, 20);
    TN_CHECK(own.count >= 8); /* enough lines for the test (fewer keep gain 1) */
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_OK);
    memset(&go, 0, sizeof go);
    go.seed = 3;
    TN_CHECK(tn_gnn_gain(&g, &m, &own, 48, 48, &go) == TN_OK);
    TN_CHECK(g == 1.0f);
    go.embeddings = TN_GNN_EMBED_NONE;
    TN_CHECK(tn_gnn_gain(&ga, &m, &own, 48, 48, &go) == TN_OK);
    TN_CHECK(ga >= 0.0f && ga <= 1.0f);
    {
        tn_contour_set few = own;
        float gf = -1;
        few.count = 4; /* a few strokes: not tested */
        TN_CHECK(tn_gnn_gain(&gf, &m, &few, 48, 48, &go) == TN_OK && gf == 1.0f);
    }
    TN_CHECK(tn_gnn_generate(&autog, &m, &own, 48, 48, &go) == TN_OK);
    go.gain = ga > 0 ? ga : -1.0f;
    TN_CHECK(tn_gnn_generate(&fixg, &m, &own, 48, 48, &go) == TN_OK);
    TN_CHECK(autog.data && fixg.data && same_image(&autog, &fixg));
    go.gain = 1.0f;
    TN_CHECK(tn_gnn_generate(&full, &m, &own, 48, 48, &go) == TN_OK);
    go.gain = -1.0f;
    TN_CHECK(tn_gnn_generate(&none, &m, &own, 48, 48, &go) == TN_OK);
    go.gain = 0.5f;
    TN_CHECK(tn_gnn_generate(&half, &m, &own, 48, 48, &go) == TN_OK);
    TN_CHECK(tn_gnn_membrane(&mem, &own, 48, 48) == TN_OK);
    for (i = 0; i < n && full.data && none.data && half.data && mem.data; i++) {
        lin &= fabsf(none.data[i] - mem.data[i]) <= 1e-3f * (1.0f + fabsf(mem.data[i]));
        lin &= fabsf(half.data[i] - 0.5f * (full.data[i] + none.data[i])) <= 1e-3f * (1.0f + fabsf(full.data[i]));
    }
    TN_CHECK(lin);
    go.gain = NAN;
    TN_CHECK(tn_gnn_generate(&fixg, &m, &own, 48, 48, &go) == TN_ERR_INVALID_ARG);
    tn_image_free(&full);
    tn_image_free(&none);
    tn_image_free(&half);
    tn_image_free(&autog);
    tn_image_free(&fixg);
    tn_image_free(&mem);
    tn_contour_set_free(&own);
    tn_gnn_free(&m);
    tn_image_free(&dem);
}

TN_TEST(ordering_share)
{
    /* a horizontal ridge on a tent-shaped terrain obeys the ordering everywhere; on the inverted
       terrain nowhere; a valley on the inverted one everywhere */
    tn_contour_set s;
    tn_contour c;
    float pts[3 * 2] = {2, 10, 1, 37, 10, 1};
    tn_image t = {0, 0, 0, NULL};
    double share = -1;
    int n = 0, x, y;
    memset(&c, 0, sizeof c);
    c.type = TN_RIDGE;
    c.npoints = 2;
    c.points = pts;
    s.width = s.height = 40;
    s.count = 1;
    s.items = &c;
    TN_CHECK(tn_image_create(&t, 40, 40, 1) == TN_OK);
    for (y = 0; y < 40; y++)
        for (x = 0; x < 40; x++) TN_PIXEL(&t, x, y, 0) = 100.0f - (float)abs(y - 10);
    TN_CHECK(tn_gnn_ordering(&share, &s, &t, 0, &n) == TN_OK && n >= 30 && share == 1.0);
    for (y = 0; y < 40; y++)
        for (x = 0; x < 40; x++) TN_PIXEL(&t, x, y, 0) = -TN_PIXEL(&t, x, y, 0);
    TN_CHECK(tn_gnn_ordering(&share, &s, &t, 0, &n) == TN_OK && share == 0.0);
    c.type = TN_VALLEY;
    TN_CHECK(tn_gnn_ordering(&share, &s, &t, 2, &n) == TN_OK && share == 1.0);
    TN_CHECK(tn_gnn_ordering(&share, &s, &t, -1, &n) == TN_ERR_INVALID_ARG);
    s.count = 0;
    TN_CHECK(tn_gnn_ordering(&share, &s, &t, 0, &n) == TN_ERR_EMPTY);
    tn_image_free(&t);
}

/* the learned tensors of a (or its "early.*" copies, if early) are the same bits as b's (the
   embeddings left out if no_emb) */
static int same_learned(const tn_gnn *a, int early, const tn_gnn *b, int no_emb)
{
    int i, n = 0;
    for (i = 0; i < tn_params_count(b->weights); i++) {
        const tn_tensor *y = tn_params_get(b->weights, i), *x;
        char name[64];
        if (!y->requires_grad || (no_emb && !strcmp(y->name, "gnn.emb"))) continue;
        snprintf(name, sizeof name, "%s%s", early ? "early." : "", y->name);
        if (!(x = tn_params_find(a->weights, name)) || x->numel != y->numel || memcmp(x->data, y->data, x->numel * sizeof(float))) return 0;
        n++;
    }
    return n > 0;
}

static void holdout_opts(tn_gnn_opts *o, long iters, tn_image *hold)
{
    tn_test_tiny_gnn_opts(o, iters);
    o->lr = 5e-3f;
    o->embed_phase = -1;
    o->holdout = hold;
    o->holdout_count = 2;
    o->holdout_every = 2;
}

/* the model of a run without holdouts stopped at iteration iters (settings of holdout_opts) */
static int stopped_run(const tn_image *dem, long iters, tn_gnn *out)
{
    tn_gnn_opts o;
    holdout_opts(&o, iters, NULL);
    o.holdout_count = 0;
    return tn_gnn_train(out, dem, &o, NULL) == TN_OK;
}

/* Heights stored in coarse steps (32 over the range: on 40 px of this relief, as coarse as 8
   bits on the 8-bit DEMs): the example and the holdouts train without them (option dequantize,
   on by default where they are coarse), and the holdouts' checks run on them. */
static void in_steps(tn_image *img, int levels)
{
    float lo, hi, step;
    size_t k;
    tn_image_range(&lo, &hi, img);
    step = (hi - lo) / (float)levels;
    for (k = 0; k < (size_t)img->width * img->height; k++) img->data[k] = lo + step * floorf((img->data[k] - lo) / step + 0.5f);
}

TN_TEST(an_example_in_coarse_steps_is_trained_without_them)
{
    tn_image dem = tn_test_dem(40, 4), hold[2];
    tn_gnn_opts o;
    tn_gnn a, b;
    tn_gnn_stats st;
    hold[0] = tn_test_dem(40, 8);
    hold[1] = tn_test_dem(40, 9);
    in_steps(&dem, 32);
    in_steps(&hold[0], 32);
    in_steps(&hold[1], 32);
    holdout_opts(&o, 4, hold);
    TN_CHECK(tn_gnn_train(&a, &dem, &o, &st) == TN_OK);
    TN_CHECK(st.dequantized > 0 && st.holdout_checks == 2);
    TN_CHECK(o.holdout == hold); /* the caller's options and holdouts are left as they were */
    o.dequantize = -1;
    TN_CHECK(tn_gnn_train(&b, &dem, &o, &st) == TN_OK);
    TN_CHECK(st.dequantized == 0.0f);
    TN_CHECK(!same_learned(&a, 0, &b, 0));
    tn_gnn_free(&b);
    o.dequantize = 2;
    TN_CHECK(tn_gnn_train(&b, &dem, &o, &st) == TN_ERR_INVALID_ARG);
    tn_gnn_free(&a);
    tn_image_free(&dem);
    tn_image_free(&hold[0]);
    tn_image_free(&hold[1]);
}

TN_TEST(holdout_early_stopping)
{
    /* checks every 2 iterations on two other terrains. The model keeps the fully trained
       network (checks change nothing in training) and, as its early network, the best check's,
       bit for bit a run stopped there: other terrain's sketches run on it, the example's own
       network on the trained one; through save/load and a resume too */
    const char *ck = tn_test_tmp_path("gnn", "hold.ckpt"), *mp = tn_test_tmp_path("gnn", "hold.tnw");
    tn_image dem = tn_test_dem(40, 4), hold[2], bad = {0, 0, 0, NULL}, a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_contour_set own = own_sketch(&dem), other;
    tn_gnn_opts o;
    tn_gnn m, full, stop, res, ld;
    tn_gnn_stats st, st2;
    tn_gnn_generate_opts g1;
    hold[0] = tn_test_dem(40, 8);
    hold[1] = tn_test_dem(40, 9);
    other = own_sketch(&hold[1]);
    holdout_opts(&o, 12, hold);
    TN_CHECK(tn_gnn_train(&m, &dem, &o, &st) == TN_OK);
    TN_CHECK(st.holdout_checks == 6); /* 2, 4, ..., 10 and the end */
    TN_CHECK(st.holdout_ssim > -1 && st.holdout_ssim <= 1 && st.holdout_ssim >= st.holdout_last_ssim);
    TN_CHECK(st.holdout_iteration >= 2 && st.holdout_iteration < 12 && st.holdout_iteration % 2 == 0); /* this seed: not the last */
    holdout_opts(&o, 12, NULL);
    o.holdout_count = 0;
    TN_CHECK(tn_gnn_train(&full, &dem, &o, &st2) == TN_OK && st2.holdout_iteration == -1);
    TN_CHECK(same_learned(&m, 0, &full, 0) && !tn_params_find(full.weights, "early.gnn.emb"));
    TN_CHECK(stopped_run(&dem, st.holdout_iteration, &stop));
    TN_CHECK(same_learned(&m, 1, &stop, 0));
    memset(&g1, 0, sizeof g1);
    g1.gain = 1.0f; /* the networks alone: m's gain test also has a scale from the holdouts */
    TN_CHECK(tn_gnn_generate(&a, &m, &other, 40, 40, &g1) == TN_OK && tn_gnn_generate(&b, &stop, &other, 40, 40, &g1) == TN_OK);
    TN_CHECK(same_image(&a, &b));
    tn_image_free(&a);
    tn_image_free(&b);
    TN_CHECK(tn_gnn_generate(&a, &m, &own, 40, 40, NULL) == TN_OK && tn_gnn_generate(&b, &full, &own, 40, 40, NULL) == TN_OK);
    TN_CHECK(same_image(&a, &b));
    tn_image_free(&b);
    TN_CHECK(tn_gnn_save(mp, &m) == TN_OK && tn_gnn_load(&ld, mp) == TN_OK);
    TN_CHECK(same_learned(&ld, 1, &stop, 0) && same_learned(&ld, 0, &full, 0));
    TN_CHECK(tn_gnn_generate(&b, &ld, &own, 40, 40, NULL) == TN_OK && same_image(&a, &b));
    tn_image_free(&a);
    tn_image_free(&b);
    /* stopped at 6 and resumed to 12: the same model and checks */
    holdout_opts(&o, 6, hold);
    o.train.checkpoint = ck;
    TN_CHECK(tn_gnn_train(&res, &dem, &o, NULL) == TN_OK);
    tn_gnn_free(&res);
    o.train.max_iters = 12;
    o.train.resume = 1;
    TN_CHECK(tn_gnn_train(&res, &dem, &o, &st2) == TN_OK);
    TN_CHECK(st2.holdout_iteration == st.holdout_iteration && st2.holdout_checks == st.holdout_checks);
    TN_CHECK(same_learned(&res, 0, &full, 0) && same_learned(&res, 1, &stop, 0));
    tn_gnn_free(&res);
    /* the default embedding phase with an early network: the second half (from 6), checks at 2, 4
       and 6; it trains the network on (it serves only the example's own network now) */
    holdout_opts(&o, 12, hold);
    o.embed_phase = 0;
    TN_CHECK(tn_gnn_train(&res, &dem, &o, &st2) == TN_OK && st2.embed_phase_from == 6 && st2.holdout_checks == 3);
    TN_CHECK(st2.holdout_iteration >= 2 && st2.holdout_iteration <= 6 && tn_params_find(res.weights, "early.gnn.emb"));
    tn_gnn_free(&stop);
    TN_CHECK(stopped_run(&dem, 6, &stop));
    TN_CHECK(!same_learned(&res, 0, &stop, 1));
    tn_gnn_free(&res);
    /* phase_network = -1: the last quarter (from 9), checks at 2, 4, 6, 8 and 9; only the
       embeddings move in it */
    holdout_opts(&o, 12, hold);
    o.embed_phase = 0;
    o.phase_network = -1;
    TN_CHECK(tn_gnn_train(&res, &dem, &o, &st2) == TN_OK && st2.embed_phase_from == 9 && st2.holdout_checks == 5);
    tn_gnn_free(&stop);
    TN_CHECK(stopped_run(&dem, 9, &stop));
    TN_CHECK(same_learned(&res, 0, &stop, 1) && !same_learned(&res, 0, &stop, 0));
    tn_gnn_free(&res);
    /* holdouts without a network (flat): no check, no early network, so the phase (half, as
       holdouts were given) moves only the embeddings */
    {
        tn_image flat[2];
        int i;
        for (i = 0; i < 2; i++) {
            size_t q;
            TN_CHECK(tn_image_create(&flat[i], 40, 40, 1) == TN_OK);
            for (q = 0; q < 40 * 40; q++) flat[i].data[q] = 100.0f;
        }
        holdout_opts(&o, 12, flat);
        o.embed_phase = 0;
        TN_CHECK(tn_gnn_train(&res, &dem, &o, &st2) == TN_OK && st2.embed_phase_from == 6 && st2.holdout_checks == 0);
        TN_CHECK(st2.holdout_iteration == -1 && !tn_params_find(res.weights, "early.gnn.emb"));
        tn_gnn_free(&stop);
        TN_CHECK(stopped_run(&dem, 6, &stop));
        TN_CHECK(same_learned(&res, 0, &stop, 1) && !same_learned(&res, 0, &stop, 0));
        tn_gnn_free(&res);
        tn_image_free(&flat[0]);
        tn_image_free(&flat[1]);
    }
    /* bad holdouts */
    tn_test_tiny_gnn_opts(&o, 2);
    o.holdout_count = 1;
    TN_CHECK(tn_gnn_train(&res, &dem, &o, NULL) == TN_ERR_INVALID_ARG); /* none given */
    TN_CHECK(tn_image_create(&bad, 40, 40, 1) == TN_OK);
    memcpy(bad.data, hold[0].data, 40 * 40 * sizeof(float));
    bad.data[77] = NAN;
    o.holdout = &bad;
    TN_CHECK(tn_gnn_train(&res, &dem, &o, NULL) == TN_ERR_NUMERIC);
    tn_image_free(&bad);
    TN_CHECK(tn_image_create(&bad, 40, 40, 3) == TN_OK);
    TN_CHECK(tn_gnn_train(&res, &dem, &o, NULL) == TN_ERR_INVALID_ARG); /* three channels */
    tn_image_free(&bad);
    tn_gnn_free(&m);
    tn_gnn_free(&full);
    tn_gnn_free(&stop);
    tn_gnn_free(&ld);
    tn_contour_set_free(&own);
    tn_contour_set_free(&other);
    tn_image_free(&hold[0]);
    tn_image_free(&hold[1]);
    tn_image_free(&dem);
}

/* the stages a progress hook sees; cancels at the first report of stage `cancel_at` */
typedef struct stage_log {
    char seen[8][16];
    int n, calls;
    const char *cancel_at;
} stage_log;

static int log_stage(void *user, const char *stage, double fraction)
{
    stage_log *l = (stage_log *)user;
    int i;
    (void)fraction;
    l->calls++;
    for (i = 0; i < l->n && strcmp(l->seen[i], stage); i++) {}
    if (i == l->n && l->n < 8) snprintf(l->seen[l->n++], sizeof l->seen[0], "%s", stage);
    return l->cancel_at && !strcmp(stage, l->cancel_at);
}

TN_TEST(training_reports_its_preparation_as_one_stage)
{
    /* the dozen extractions before training (example, holdouts, sparse levels) report as
       gnn-prepare, not as fill / valleys / ridges / extract each; a cancel there stops the run,
       and the next operation reports its own stages again */
    tn_image dem = tn_test_dem(40, 4), hold[2];
    tn_extraction ex;
    tn_gnn_opts o;
    tn_gnn m;
    stage_log l;
    hold[0] = tn_test_dem(40, 8);
    hold[1] = tn_test_dem(40, 9);
    holdout_opts(&o, 4, hold);
    memset(&l, 0, sizeof l);
    tn_set_progress(log_stage, &l);
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_OK);
    tn_gnn_free(&m);
    TN_CHECK(l.n == 2 && !strcmp(l.seen[0], "gnn-prepare") && !strcmp(l.seen[1], "gnn-train"));
    memset(&l, 0, sizeof l);
    l.cancel_at = "gnn-prepare";
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_ERR_CANCELLED && strstr(tn_last_error(), "gnn-prepare") && l.calls == 1);
    memset(&l, 0, sizeof l);
    TN_CHECK(tn_extract(&ex, &dem, NULL) == TN_OK);
    tn_extraction_free(&ex);
    TN_CHECK(l.n >= 2 && !strcmp(l.seen[l.n - 1], "extract"));
    tn_set_progress(NULL, NULL);
    tn_image_free(&dem);
    tn_image_free(&hold[0]);
    tn_image_free(&hold[1]);
}

/* Mean SSIM over the holdouts' networks at the default threshold and 4 x it (those of 8 lines or
   more, as the gain's calibration takes them), generated with m's scale set to `scale`. */
static double holdout_mean_ssim(tn_gnn *m, const tn_image *hold, int n, float scale)
{
    double sum = 0;
    int i, d, k = 0;
    tn_params_find(m->weights, "gain.scale")->data[0] = scale;
    for (i = 0; i < n; i++)
        for (d = 0; d < 2; d++) {
            tn_extract_opts eo;
            tn_extraction ex;
            tn_image out = {0, 0, 0, NULL};
            tn_metrics mt;
            memset(&eo, 0, sizeof eo);
            eo.threshold = tn_extract_default_threshold(hold[i].width, hold[i].height) * (d ? 4 : 1);
            if (tn_extract(&ex, &hold[i], &eo)) return -2;
            if (ex.contours.count >= 8 && !tn_gnn_generate(&out, m, &ex.contours, hold[i].width, hold[i].height, NULL) &&
                !tn_compare(&mt, &hold[i], &out, 0)) {
                sum += mt.ssim;
                k++;
            }
            tn_image_free(&out);
            tn_extraction_free(&ex);
        }
    return k ? sum / k : -2;
}

TN_TEST(gain_scale_from_holdouts)
{
    /* training with holdouts calibrates the gain test's scale on them: a multiple of 0.05 in
       0 .. 2 whose mean SSIM over the holdouts' sketches is at least that of 0 (the membrane),
       1 (the raw test) and 2; the gain is min(1, scale x the raw estimate); the scale travels in
       the model file, and a file with a scale out of range is refused */
    const char *mp = tn_test_tmp_path("gnn", "scale.tnw");
    tn_image dem = tn_test_dem(48, 13), hold[2];
    tn_gnn_opts o;
    tn_gnn m, ld, plain;
    tn_gnn_stats st;
    tn_contour_set sk;
    float s, g1 = -1, gh = -1;
    double best, s0, s1;
    hold[0] = tn_test_dem(48, 21);
    hold[1] = tn_test_dem(48, 22);
    sk = own_sketch(&hold[0]);
    TN_CHECK(sk.count >= 8);
    tn_test_tiny_gnn_opts(&o, 20);
    o.holdout = hold;
    o.holdout_count = 2;
    o.holdout_every = 4;
    TN_CHECK(tn_gnn_train(&m, &dem, &o, &st) == TN_OK && tn_params_find(m.weights, "gain.scale"));
    s = tn_params_find(m.weights, "gain.scale")->data[0];
    TN_CHECK(st.gain_scale == s && s >= 0 && s <= 2 && fabsf(s * 20 - floorf(s * 20 + 0.5f)) < 1e-4f);
    best = holdout_mean_ssim(&m, hold, 2, s);
    TN_CHECK(best > -1);
    s0 = holdout_mean_ssim(&m, hold, 2, 0.0f);
    s1 = holdout_mean_ssim(&m, hold, 2, 1.0f);
    TN_CHECK(best >= s0 - 1e-4 && best >= s1 - 1e-4 && best >= holdout_mean_ssim(&m, hold, 2, 2.0f) - 1e-4);
    TN_CHECK(s0 != s1); /* the scale reaches the generation */
    tn_params_find(m.weights, "gain.scale")->data[0] = 1.0f;
    TN_CHECK(tn_gnn_gain(&g1, &m, &sk, 48, 48, NULL) == TN_OK && g1 >= 0 && g1 <= 1);
    tn_params_find(m.weights, "gain.scale")->data[0] = 0.5f;
    TN_CHECK(tn_gnn_gain(&gh, &m, &sk, 48, 48, NULL) == TN_OK);
    TN_CHECK(g1 < 1 ? fabsf(gh - 0.5f * g1) < 1e-6f : gh >= 0.5f);
    tn_params_find(m.weights, "gain.scale")->data[0] = s;
    TN_CHECK(tn_gnn_save(mp, &m) == TN_OK && tn_gnn_load(&ld, mp) == TN_OK);
    TN_CHECK(tn_params_find(ld.weights, "gain.scale") && tn_params_find(ld.weights, "gain.scale")->data[0] == s);
    tn_gnn_free(&ld);
    tn_params_find(m.weights, "gain.scale")->data[0] = 3.0f;
    TN_CHECK(tn_params_save(mp, m.weights) == TN_OK && tn_gnn_load(&ld, mp) == TN_ERR_CORRUPT);
    /* without holdouts: no scale (1) */
    o.holdout = NULL;
    o.holdout_count = 0;
    TN_CHECK(tn_gnn_train(&plain, &dem, &o, &st) == TN_OK && !tn_params_find(plain.weights, "gain.scale") && st.gain_scale == 1.0f);
    remove(mp);
    tn_gnn_free(&plain);
    tn_gnn_free(&m);
    tn_contour_set_free(&sk);
    tn_image_free(&hold[0]);
    tn_image_free(&hold[1]);
    tn_image_free(&dem);
}

TN_TEST(holdout_windows)
{
    /* two windows away, spread (4 of the 11 that fit), else adjacent; NaN windows left out */
    tn_image dem = tn_test_dem(200, 3), out[6], small = tn_test_dem(100, 3);
    int n, u, v, same = 1;
    n = tn_gnn_holdout_windows(out, &dem, 80, 55, 40, 40, 4); /* 200 x 200: ring 2 at x 0 and 160, y 135 (not -25) */
    TN_CHECK(n == 4);
    for (v = 0; v < 40; v++)
        for (u = 0; u < 40; u++) same &= TN_PIXEL(&out[0], u, v, 0) == TN_PIXEL(&dem, 0 + u, 15 + v, 0);
    TN_CHECK(same && out[0].width == 40 && out[0].height == 40 && out[0].channels == 1);
    while (n > 0) tn_image_free(&out[--n]);
    TN_CHECK(tn_gnn_holdout_windows(out, &small, 30, 30, 40, 40, 4) == 0); /* no window fits */
    n = tn_gnn_holdout_windows(out, &small, 0, 0, 40, 40, 4);              /* the adjacent three */
    TN_CHECK(n == 3);
    while (n > 0) tn_image_free(&out[--n]);
    TN_PIXEL(&small, 45, 5, 0) = NAN; /* inside the window at (40, 0) */
    n = tn_gnn_holdout_windows(out, &small, 0, 0, 40, 40, 4);
    TN_CHECK(n == 2);
    while (n > 0) tn_image_free(&out[--n]);
    TN_CHECK(tn_gnn_holdout_windows(out, &small, 0, 0, 40, 40, 0) == 0);
    tn_image_free(&dem);
    tn_image_free(&small);
}

/* A ridge across a width x height canvas at y = h/3 and a valley at y = 2h/3 (heights in metres,
   rising along them), the few strokes of a drawing. */
static tn_contour_set two_strokes(int w, int h, float *rp, float *vp)
{
    tn_contour_set s;
    static tn_contour c[2];
    int i;
    for (i = 0; i < 10; i++) {
        rp[3 * i] = vp[3 * i] = 5.0f + (float)i * (float)(w - 10) / 9.0f;
        rp[3 * i + 1] = (float)h / 3 + 6.0f * sinf((float)i);
        vp[3 * i + 1] = 2.0f * (float)h / 3;
        rp[3 * i + 2] = 1700.0f + 10.0f * (float)i;
        vp[3 * i + 2] = 1200.0f + 5.0f * (float)i;
    }
    memset(c, 0, sizeof c);
    c[0].type = TN_RIDGE;
    c[1].type = TN_VALLEY;
    c[0].npoints = c[1].npoints = 10;
    c[0].points = rp;
    c[1].points = vp;
    memset(&s, 0, sizeof s);
    s.width = w;
    s.height = h;
    s.count = 2;
    s.items = c;
    return s;
}

TN_TEST(membrane_blocks_leave_no_seams)
{
    /* a map over 192 px is the blend of 128 px blocks' membranes: the slope must not jump where
       one block's weight starts to fall (its centre, x = 64 + 128k), which a hillshade shows as a
       line across the map. A jump is a spike in the second difference along x: there it stays
       within 2x of the columns 3 px to either side (mean over the rows above the strokes; 50x
       and 3.7x with a linear blend, 1.0 and 0.9 with the smoothstep) */
    float rp[30], vp[30];
    tn_contour_set user = two_strokes(320, 320, rp, vp);
    tn_image m = {0, 0, 0, NULL};
    double col[318];
    int x, y, k;
    TN_CHECK(tn_gnn_membrane(&m, &user, 320, 320) == TN_OK);
    for (x = 0; x < 318; x++) { /* col[x]: the second difference centred on x + 1 */
        col[x] = 0;
        for (y = 0; y < 80; y++) { /* the strokes run at y ~ 107 and 213 */
            const float *a = m.data + (size_t)y * 320 + x;
            col[x] += fabs((double)a[2] - 2.0 * a[1] + a[0]) / 80;
        }
    }
    for (k = 0; k < 2; k++) {
        int c = 64 + 128 * k; /* the centre falls between pixels c - 1 and c */
        double spike = fmax(col[c - 2], col[c - 1]) / fmax(col[c - 5], col[c + 2]);
        printf("  block centre x = %d: second difference %.2fx its neighbours'\n", c, spike);
        TN_CHECK(spike < 2);
    }
    tn_image_free(&m);
}

TN_TEST(membrane_far_blocks_stay_bounded)
{
    /* blocks far from every stroke grow their domain until it holds one; past 256 x 256 px it is
       solved on a coarser grid (so a sparse drawing on a large map stays fast). The far field must
       still be the membrane's: within the strokes' heights, within 1 % of the range of the plain
       solve of the whole map, and without a jump where blocks meet */
    float rp[30], vp[30], *val, *plain;
    uint8_t *fixed;
    tn_contour_set user = two_strokes(120, 200, rp, vp);
    tn_image m = {0, 0, 0, NULL}, r = {0, 0, 0, NULL};
    const int W = 1400, H = 200;
    double worst = 0, jump = 0;
    int x, y, i;
    user.width = W; /* the strokes keep to the map's left 120 px */
    TN_CHECK(tn_gnn_membrane(&m, &user, W, H) == TN_OK && tn_sketch_rasterise(&r, &user, W, H) == TN_OK);
    val = (float *)malloc((size_t)W * H * sizeof(float));
    plain = (float *)malloc((size_t)W * H * sizeof(float));
    fixed = (uint8_t *)malloc((size_t)W * H);
    for (i = 0; i < W * H; i++) {
        fixed[i] = (uint8_t)(r.data[3 * i] > 0 || r.data[3 * i + 1] > 0);
        val[i] = r.data[3 * i + 2];
    }
    TN_CHECK(tn__gnn_membrane_solve(val, fixed, W, H, plain) == TN_OK);
    for (y = 0; y < H; y++)
        for (x = 400; x < W; x++) {
            float v = m.data[(size_t)y * W + x];
            TN_CHECK(v >= 1200 - 1e-2f && v <= 1790 + 1e-2f);
            worst = fmax(worst, fabs((double)v - plain[(size_t)y * W + x]));
            if (x > 400) jump = fmax(jump, fabs((double)v - m.data[(size_t)y * W + x - 1]));
        }
    printf("  far field (x >= 400 of 1400 px): %.2f m from the plain solve at worst, steps of %.3f m at most (range 590 m)\n", worst, jump);
    TN_CHECK(worst <= 0.01 * 590 && jump <= 0.5);
    free(val);
    free(plain);
    free(fixed);
    tn_image_free(&m);
    tn_image_free(&r);
}

TN_TEST(grow_by_example)
{
    /* densify by example: the user's lines come first and unchanged; added lines are 8-connected
       chains of 5+ px that keep the gap from every user pixel (so none crosses one) except where
       one end runs on to a user line of its own type (a join, ending on that line), of both
       types; same seed same lines, another seed other lines; bad inputs fail */
    tn_image dem = tn_test_dem(64, 21), ur = {0, 0, 0, NULL};
    tn_contour_set ex = own_sketch(&dem), user, g1, g2, g3, bad;
    tn_gnn_grow_opts go;
    float rp[30], vp[30];
    int added = 0, added2 = 0, i, j, types[2] = {0, 0}, x, y, joins = 0;
    size_t q;
    TN_CHECK(ex.count > 0);
    user = two_strokes(120, 90, rp, vp);
    memset(&go, 0, sizeof go);
    go.seed = 3;
    TN_CHECK(tn_gnn_grow(&g1, &user, &ex, 120, 90, &go, &added) == TN_OK);
    TN_CHECK(added > 4 && g1.count == 2 + added);
    for (i = 0; i < 2; i++)
        TN_CHECK(g1.items[i].type == user.items[i].type && g1.items[i].npoints == 10 &&
                 !memcmp(g1.items[i].points, user.items[i].points, 30 * sizeof(float)));
    TN_CHECK(tn_sketch_rasterise(&ur, &user, 120, 90) == TN_OK);
    for (i = 2; i < g1.count; i++) {
        const tn_contour *c = &g1.items[i];
        int first_far = -1, last_far = -1, nfar = 0, ends_on[2] = {0, 0};
        types[c->type == TN_RIDGE]++;
        TN_CHECK(c->npoints >= 5);
        for (j = 0; j < c->npoints; j++) {
            float px = c->points[3 * j], py = c->points[3 * j + 1], d2 = 1e30f;
            int kind = 0; /* the nearest user pixel's: 1 ridge, -1 valley */
            TN_CHECK(isfinite(c->points[3 * j + 2]));
            if (j) TN_CHECK(fabsf(px - c->points[3 * j - 3]) <= 1 && fabsf(py - c->points[3 * j - 2]) <= 1);
            for (y = 0; y < 90; y++)
                for (x = 0; x < 120; x++) {
                    float e;
                    q = (size_t)y * 120 + x;
                    e = (px - x) * (px - x) + (py - y) * (py - y);
                    if ((ur.data[3 * q] > 0 || ur.data[3 * q + 1] > 0) && e < d2) d2 = e, kind = ur.data[3 * q] > 0 ? 1 : -1;
                }
            if (d2 >= 4.0f * 4.0f * 0.99f) { /* chamfer >= 4 px: Euclidean >= 4 / 1.082 would do; the default gap holds */
                if (first_far < 0) first_far = j;
                last_far = j;
                nfar++;
            } else
                TN_CHECK(kind == (c->type == TN_RIDGE ? 1 : -1)); /* only a join comes closer, to its own kind */
            if (d2 == 0) ends_on[j > 0] += j == 0 || j == c->npoints - 1;
        }
        TN_CHECK(first_far >= 0);
        if (first_far > 0) { /* a join runs from the gap to the user line */
            TN_CHECK(ends_on[0]);
            joins++;
        }
        if (last_far < c->npoints - 1) {
            TN_CHECK(ends_on[1]);
            joins++;
        }
        TN_CHECK(nfar == last_far - first_far + 1); /* and only at the ends */
    }
    TN_CHECK(types[0] > 0 && types[1] > 0 && joins > 0);
    TN_CHECK(tn_gnn_grow(&g2, &user, &ex, 120, 90, &go, &added2) == TN_OK && added2 == added);
    for (i = 0; i < g1.count; i++)
        TN_CHECK(g2.items[i].npoints == g1.items[i].npoints && !memcmp(g2.items[i].points, g1.items[i].points, (size_t)g1.items[i].npoints * 3 * sizeof(float)));
    go.seed = 4;
    TN_CHECK(tn_gnn_grow(&g3, &user, &ex, 120, 90, &go, NULL) == TN_OK);
    {
        int differ = g3.count != g1.count;
        for (i = 2; !differ && i < g1.count; i++)
            differ = g3.items[i].npoints != g1.items[i].npoints || memcmp(g3.items[i].points, g1.items[i].points, (size_t)g1.items[i].npoints * 3 * sizeof(float));
        TN_CHECK(differ);
    }
    tn_contour_set_free(&g3);
    /* bad inputs */
    TN_CHECK(tn_gnn_grow(&g3, &user, &ex, 100, 90, &go, NULL) == TN_ERR_SHAPE);
    bad = user;
    bad.count = 0;
    TN_CHECK(tn_gnn_grow(&g3, &bad, &ex, 120, 90, &go, NULL) == TN_ERR_EMPTY);
    bad = ex;
    bad.width = bad.height = 8;
    TN_CHECK(tn_gnn_grow(&g3, &user, &bad, 120, 90, &go, NULL) != TN_OK);
    go.gap = -1;
    TN_CHECK(tn_gnn_grow(&g3, &user, &ex, 120, 90, &go, NULL) == TN_ERR_INVALID_ARG);
    go.gap = 0;
    rp[4] = NAN;
    TN_CHECK(tn_gnn_grow(&g3, &user, &ex, 120, 90, &go, NULL) == TN_ERR_NUMERIC);
    tn_contour_set_free(&g1);
    tn_contour_set_free(&g2);
    tn_contour_set_free(&ex);
    tn_image_free(&ur);
    tn_image_free(&dem);
}

/* The share of the pixels of a membrane that depression filling raises by more than 1 % of
   `range`. */
static double basin_share(const tn_image *m, double range)
{
    tn_image f = {0, 0, 0, NULL};
    size_t i, n = (size_t)m->width * m->height, k = 0;
    if (tn_fill_depressions(&f, m) != TN_OK) return 1;
    for (i = 0; i < n; i++) k += f.data[i] - m->data[i] > 0.01 * range;
    tn_image_free(&f);
    return (double)k / (double)n;
}

TN_TEST(grown_sketch_drains)
{
    /* blocks of the example's network leave neighbouring blocks' valleys unconnected: the grown
       sketch's membrane held closed basins over 10 % of a map whose example network has about
       1 % (Alps); now each basin drains over its lowest saddle. A ring the user drew stays a
       closed basin: no added valley cuts a user ridge */
    tn_image full = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL}, m = {0, 0, 0, NULL}, me = {0, 0, 0, NULL};
    tn_contour_set ex, user, g;
    float rp[30], vp[30], ring[3 * 41];
    double range, share, share_ex;
    tn_contour c;
    int i;
    TN_CHECK(tn_image_load(&full, "examples/data/alps_n47e009_256.png", NULL) == TN_OK);
    TN_CHECK(tn_image_crop(&dem, &full, 64, 64, 128, 128) == TN_OK);
    ex = own_sketch(&dem);
    TN_CHECK(tn_gnn_membrane(&me, &ex, 128, 128) == TN_OK);
    {
        float lo = 1e30f, hi = -1e30f;
        for (i = 0; i < 128 * 128; i++) lo = fminf(lo, me.data[i]), hi = fmaxf(hi, me.data[i]);
        range = hi - lo;
    }
    share_ex = basin_share(&me, range);
    user = two_strokes(256, 256, rp, vp);
    TN_CHECK(tn_gnn_grow(&g, &user, &ex, 256, 256, NULL, NULL) == TN_OK);
    TN_CHECK(tn_gnn_membrane(&m, &g, 256, 256) == TN_OK);
    share = basin_share(&m, range);
    printf("  closed basins: %.1f %% of the grown membrane, %.1f %% of the example network's\n", 100 * share, 100 * share_ex);
    TN_CHECK(share < 2 * share_ex + 0.01);
    tn_image_free(&m);
    tn_contour_set_free(&g);
    /* a drawn ring of ridge: its inside stays lower than the ring all round */
    for (i = 0; i <= 40; i++) {
        ring[3 * i] = 128 + 60 * cosf(6.2831853f * (float)i / 40);
        ring[3 * i + 1] = 128 + 60 * sinf(6.2831853f * (float)i / 40);
        ring[3 * i + 2] = 3000.0f; /* above the example's 431-2908 m */
    }
    memset(&c, 0, sizeof c);
    c.type = TN_RIDGE;
    c.points = ring;
    c.npoints = 41;
    user.items = &c;
    user.count = 1;
    TN_CHECK(tn_gnn_grow(&g, &user, &ex, 256, 256, NULL, NULL) == TN_OK);
    TN_CHECK(tn_gnn_membrane(&m, &g, 256, 256) == TN_OK);
    {
        tn_image f = {0, 0, 0, NULL};
        TN_CHECK(tn_fill_depressions(&f, &m) == TN_OK);
        TN_CHECK(f.data[(size_t)128 * 256 + 128] > m.data[(size_t)128 * 256 + 128] + 100); /* the inside is still a basin */
        tn_image_free(&f);
    }
    tn_image_free(&m);
    tn_image_free(&me);
    tn_contour_set_free(&g);
    tn_contour_set_free(&ex);
    tn_image_free(&dem);
    tn_image_free(&full);
}

TN_TEST(drawn_valley_end_drains)
{
    /* a drawn valley that ends inside the map ended in a lake: the ground beyond its low end rises
       as the example's rises from its valleys, and the flood's path out of that basin ran back
       beside the drawn valley, so it was left out. Now the valley goes on from its end to lower
       ground. Inside a drawn ring it stays closed */
    tn_image full = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL}, m = {0, 0, 0, NULL}, f = {0, 0, 0, NULL};
    tn_contour_set ex, user, g;
    float vp[3 * 9], ring[3 * 41];
    tn_contour c[2];
    size_t end = (size_t)160 * 256 + 176;
    int i;
    TN_CHECK(tn_image_load(&full, "examples/data/alps_n47e009_256.png", NULL) == TN_OK);
    TN_CHECK(tn_image_crop(&dem, &full, 64, 64, 128, 128) == TN_OK);
    ex = own_sketch(&dem);
    for (i = 0; i < 9; i++) { /* west to east, 1500 m down to 800 m, ending 80 px from the east edge */
        vp[3 * i] = 80.0f + 12.0f * (float)i;
        vp[3 * i + 1] = 128.0f + 4.0f * (float)i;
        vp[3 * i + 2] = 1500.0f - 87.5f * (float)i;
    }
    memset(c, 0, sizeof c);
    c[0].type = TN_VALLEY;
    c[0].points = vp;
    c[0].npoints = 9;
    memset(&user, 0, sizeof user);
    user.width = user.height = 256;
    user.items = c;
    user.count = 1;
    TN_CHECK(tn_gnn_grow(&g, &user, &ex, 256, 256, NULL, NULL) == TN_OK);
    TN_CHECK(tn_gnn_membrane(&m, &g, 256, 256) == TN_OK);
    TN_CHECK(tn_fill_depressions(&f, &m) == TN_OK);
    printf("  the drawn valley's end: %.0f m below its basin's brim (%.0f m)\n", (double)(f.data[end] - m.data[end]), (double)m.data[end]);
    TN_CHECK(f.data[end] - m.data[end] < 25); /* 1 % of the example's range */
    tn_image_free(&m);
    tn_image_free(&f);
    tn_contour_set_free(&g);
    for (i = 0; i <= 40; i++) { /* the same valley inside a ring of ridge: it stays a basin */
        ring[3 * i] = 128 + 100 * cosf(6.2831853f * (float)i / 40);
        ring[3 * i + 1] = 128 + 100 * sinf(6.2831853f * (float)i / 40);
        ring[3 * i + 2] = 3000.0f;
    }
    c[1].type = TN_RIDGE;
    c[1].points = ring;
    c[1].npoints = 41;
    user.count = 2;
    TN_CHECK(tn_gnn_grow(&g, &user, &ex, 256, 256, NULL, NULL) == TN_OK);
    TN_CHECK(tn_gnn_membrane(&m, &g, 256, 256) == TN_OK);
    TN_CHECK(tn_fill_depressions(&f, &m) == TN_OK);
    TN_CHECK(f.data[end] - m.data[end] > 100);
    tn_image_free(&m);
    tn_image_free(&f);
    tn_contour_set_free(&g);
    tn_contour_set_free(&ex);
    tn_image_free(&dem);
    tn_image_free(&full);
}

TN_TEST(drawn_valley_is_the_low_ground)
{
    /* the quilt laid the example's deeper valleys beside a drawn one; it stood perched between
       banks forced up around it. With the example's DEM, the grown ground within 24 px of a drawn
       valley (a line at y = 2/3 of the map, 1200..1245 m) keeps above it */
    tn_image full = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL}, m = {0, 0, 0, NULL};
    tn_contour_set ex, user, g;
    float rp[30], vp[30];
    long below = 0, all = 0;
    int x, y;
    TN_CHECK(tn_image_load(&full, "examples/data/alps_n47e009_256.png", NULL) == TN_OK);
    TN_CHECK(tn_image_crop(&dem, &full, 64, 64, 128, 128) == TN_OK);
    ex = own_sketch(&dem);
    user = two_strokes(256, 256, rp, vp);
    TN_CHECK(tn__gnn_grow(&user, &ex, &dem, 256, 256, NULL, &g, NULL, NULL, NULL) == TN_OK);
    TN_CHECK(tn_gnn_membrane(&m, &g, 256, 256) == TN_OK);
    for (y = 0; y < 256; y++)
        for (x = 16; x < 240; x++) {
            float d = fabsf((float)y - 256.0f * 2 / 3), hv = 1200.0f + 45.0f * ((float)x - 5) / 246;
            if (d < 4 || d > 24) continue;
            all++;
            below += m.data[(size_t)y * 256 + x] < hv - 17.8f; /* 1 % of the range under it */
        }
    printf("  ground within 4..24 px of the drawn valley below it: %.1f %%\n", 100.0 * (double)below / (double)all);
    TN_CHECK(below < all / 50);
    tn_image_free(&m);
    tn_contour_set_free(&g);
    tn_contour_set_free(&ex);
    tn_image_free(&dem);
    tn_image_free(&full);
}

TN_TEST(drawn_valley_is_no_trench)
{
    /* the lift that keeps a drawn valley the low ground was the shortfall's maximum over 6 px: where
       the quilted ground fell away from the valley, that carried the banks' large shortfall onto the
       valley itself, and the grown ground stood 255 m above the drawn valley of two_strokes (1200..1245
       m; the example's range 1780 m), rising 388 m within 4 px and 597 m by 16 px. The network then
       kept the drawn heights: a trench between walls. Now the ground's low-pass is lifted: -21 m on
       the valley, 117 m at 4 px, 355 m at 16 px */
    tn_image full = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL};
    tn_contour_set ex, user, g;
    float rp[30], vp[30], *ground = (float *)calloc(256 * 256, sizeof(float));
    double on = 0, at4 = 0, at16 = 0;
    int x, n = 0;
    const int y = 171; /* the valley's row, 2/3 of the map */
    TN_CHECK(ground != NULL);
    TN_CHECK(tn_image_load(&full, "examples/data/alps_n47e009_256.png", NULL) == TN_OK);
    TN_CHECK(tn_image_crop(&dem, &full, 64, 64, 128, 128) == TN_OK);
    ex = own_sketch(&dem);
    user = two_strokes(256, 256, rp, vp);
    TN_CHECK(tn__gnn_grow(&user, &ex, &dem, 256, 256, NULL, &g, NULL, NULL, ground) == TN_OK);
    for (x = 16; x < 240; x++, n++) {
        float hv = 1200.0f + 45.0f * ((float)x - 5) / 246;
        on += ground[(size_t)y * 256 + x] - hv;
        at4 += 0.5 * (ground[(size_t)(y - 4) * 256 + x] + ground[(size_t)(y + 4) * 256 + x]) - hv;
        at16 += 0.5 * (ground[(size_t)(y - 16) * 256 + x] + ground[(size_t)(y + 16) * 256 + x]) - hv;
    }
    on /= n, at4 /= n, at16 /= n;
    printf("  the grown ground on the drawn valley: %.1f m above it; 4 px across %.1f m, 16 px %.1f m\n", on, at4, at16);
    TN_CHECK(fabs(on) < 35.6);    /* 2 % of the example's range */
    TN_CHECK(at4 < 0.5 * at16);   /* a V, not a trench's walls */
    free(ground);
    tn_contour_set_free(&g);
    tn_contour_set_free(&ex);
    tn_image_free(&dem);
    tn_image_free(&full);
}

/* The largest height difference between 4-neighbours of a one-channel W x H field; *over (may
   be NULL): how many exceed `than`. */
static float largest_step(const float *h, int W, int H, float than, int *over)
{
    float m = 0, d;
    int x, y, k;
    if (over) *over = 0;
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++)
            for (k = 0; k < 2; k++) {
                if (k ? y + 1 >= H : x + 1 >= W) continue;
                d = fabsf(h[(size_t)(y + k) * W + x + 1 - k] - h[(size_t)y * W + x]);
                m = fmaxf(m, d);
                if (over) *over += d > than;
            }
    return m;
}

TN_TEST(quilted_ground_has_no_seam_cliffs)
{
    /* a quilted block whose height cut ran at the edge of its core had no room to fade in: on the
       Alps style's example (the heights alps.tnw holds) and the fork drawing, the grown ground
       stepped by 288 m between two pixels (1.6 x the example's steepest step; 408 m in
       gnn-generate's own run), 110 pairs of pixels steeper than any of the example's, and the
       lines traced there followed such steps. Now 258 m and 41 */
    tn_gnn m;
    tn_image dem = {0, 0, 0, NULL};
    tn_contour_set ex, user, g;
    const tn_tensor *e;
    float *ground = (float *)calloc(256 * 256, sizeof(float)), lo, hi, se, sg;
    int c, j, over = 0;
    memset(&m, 0, sizeof m);
    memset(&user, 0, sizeof user);
    memset(&ex, 0, sizeof ex);
    TN_CHECK(ground != NULL && tn_gnn_load(&m, "examples/data/styles/alps.tnw") == TN_OK);
    TN_CHECK(tn_sketch_load(&user, "bench/drawings/sketch_fork.tns") == TN_OK && user.width == 256 && user.height == 256);
    TN_CHECK((e = tn_params_find(m.weights, "detail.example")) != NULL);
    if (ground && e && user.count > 0) {
        dem.width = e->shape[1], dem.height = e->shape[0], dem.channels = 1, dem.data = e->data;
        tn_image_range(&lo, &hi, &dem);
        for (c = 0; c < user.count; c++) /* the drawing's heights 0..1 are the example's range */
            for (j = 0; j < user.items[c].npoints; j++) user.items[c].points[3 * j + 2] = lo + (hi - lo) * user.items[c].points[3 * j + 2];
        ex = own_sketch(&dem);
        TN_CHECK(tn__gnn_grow(&user, &ex, &dem, 256, 256, NULL, &g, NULL, NULL, ground) == TN_OK);
        se = largest_step(dem.data, dem.width, dem.height, 0, NULL);
        sg = largest_step(ground, 256, 256, se, &over);
        printf("  steepest step between two pixels: the grown ground %.0f m (%d steeper than the example's), the example %.0f m\n", (double)sg,
               over, (double)se);
        TN_CHECK(sg <= 1.6f * se && over <= 80); /* before: 288 m, 110 pairs */
        tn_contour_set_free(&g);
    }
    free(ground);
    tn_contour_set_free(&ex);
    tn_contour_set_free(&user);
    tn_gnn_free(&m);
}

TN_TEST(grown_basins_against_the_example_ground)
{
    /* whether the grown lines drain is judged against the example's own ground when the model
       holds it: an 8-bit example's network held as many closed basins as its grown sketch (16 %
       of the map), its DEM almost none, and nothing drained. Here the Alps network's heights
       get a saw of +-150 m along every line (basins between the lines), its DEM none */
    tn_image full = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL}, m = {0, 0, 0, NULL}, me = {0, 0, 0, NULL};
    tn_contour_set ex, user, g;
    float rp[30], vp[30];
    double range, share[2], share_ex;
    int i, j, with;
    TN_CHECK(tn_image_load(&full, "examples/data/alps_n47e009_256.png", NULL) == TN_OK);
    TN_CHECK(tn_image_crop(&dem, &full, 64, 64, 128, 128) == TN_OK);
    ex = own_sketch(&dem);
    for (i = 0; i < ex.count; i++)
        for (j = 0; j < ex.items[i].npoints; j++) ex.items[i].points[3 * j + 2] += (j / 6) % 2 ? 150.0f : -150.0f;
    TN_CHECK(tn_gnn_membrane(&me, &ex, 128, 128) == TN_OK);
    range = 1779; /* the example's heights, 475..2254 m */
    share_ex = basin_share(&me, range);
    user = two_strokes(256, 256, rp, vp);
    for (with = 0; with < 2; with++) {
        TN_CHECK(tn__gnn_grow(&user, &ex, with ? &dem : NULL, 256, 256, NULL, &g, NULL, NULL, NULL) == TN_OK);
        TN_CHECK(tn_gnn_membrane(&m, &g, 256, 256) == TN_OK);
        share[with] = basin_share(&m, range);
        tn_image_free(&m);
        tn_contour_set_free(&g);
    }
    printf("  closed basins: the sawn network %.1f %%, grown without / with its DEM %.1f / %.1f %%\n", 100 * share_ex, 100 * share[0],
           100 * share[1]);
    TN_CHECK(share[1] < 0.5 * share[0]);
    tn_image_free(&me);
    tn_contour_set_free(&ex);
    tn_image_free(&dem);
    tn_image_free(&full);
}

/* A 128 px example of 15 horizontal lines 8 px apart around y = 64: lines of kind `main` at 0,
   +-16, +-32, +-48 px (order 3 at 0, else 1), the other kind between; heights h0 + slope |dy|,
   the other kind's 10 slope more (lower between ridges, higher between valleys). pts holds
   15 x 6 floats. */
static void tn_test_stripes(tn_contour_set *ex, tn_contour *items, float (*pts)[6], int main, float h0, float slope)
{
    int k = 0, dy;
    memset(items, 0, 15 * sizeof *items);
    for (dy = -56; dy <= 56; dy += 8) {
        int on = dy % 16 == 0;
        float h = h0 + slope * (float)abs(dy) + (on ? 0.0f : 10.0f * slope);
        pts[k][0] = 0, pts[k][1] = (float)(64 + dy), pts[k][2] = h;
        pts[k][3] = 127, pts[k][4] = (float)(64 + dy), pts[k][5] = h;
        items[k].type = on ? main : (main == TN_RIDGE ? TN_VALLEY : TN_RIDGE);
        items[k].order = dy == 0 ? 3 : 1;
        items[k].points = pts[k];
        items[k].npoints = 2;
        k++;
    }
    memset(ex, 0, sizeof *ex);
    ex->width = ex->height = 128;
    ex->items = items;
    ex->count = k;
}

TN_TEST(grow_fall_follows_the_example)
{
    /* the ground falls from a drawn ridge as the example's ridges do from its main ridge: an
       example of parallel ridges whose heights fall 10 m per px from the main one (order 3) gives
       that trend, smoothed over 13 px and never falling back; its valleys, all of one order and
       all alike, give none; a kind the example lacks leaves the profile as it was */
    float pts[15][6], prof[TN__GNN_PROFILE + 1], pv[TN__GNN_PROFILE + 1];
    tn_contour items[15];
    tn_contour_set ex;
    tn_image er = {0, 0, 0, NULL};
    uint8_t mask[128 * 128];
    float dist[128 * 128];
    int near[128 * 128], i;
    tn_test_stripes(&ex, items, pts, TN_RIDGE, 1000.0f, -10.0f);
    TN_CHECK(tn_sketch_rasterise(&er, &ex, 128, 128) == TN_OK);
    TN_CHECK(tn__gnn_grow_profile(&ex, &er, TN_RIDGE, prof, mask, dist, near) == TN_OK);
    TN_CHECK(tn__gnn_grow_profile(&ex, &er, TN_VALLEY, pv, mask, dist, near) == TN_OK);
    printf("  ridge profile at 0 / 10 / 22 / 40 px: %.1f / %.1f / %.1f / %.1f m; valleys' largest %.1f m\n", (double)prof[0], (double)prof[10],
           (double)prof[22], (double)prof[40], (double)pv[TN__GNN_PROFILE]);
    TN_CHECK(prof[0] == 0 && fabsf(prof[22] - 160) < 1 && fabsf(prof[40] - 320) < 1);
    for (i = 1; i <= TN__GNN_PROFILE; i++) TN_CHECK(prof[i] >= prof[i - 1] && pv[i] < 1);
    for (i = 0; i < ex.count; i++) items[i].type = TN_RIDGE; /* no valleys now */
    tn_image_free(&er);
    TN_CHECK(tn_sketch_rasterise(&er, &ex, 128, 128) == TN_OK);
    for (i = 0; i <= TN__GNN_PROFILE; i++) pv[i] = -1;
    TN_CHECK(tn__gnn_grow_profile(&ex, &er, TN_VALLEY, pv, mask, dist, near) == TN_OK);
    for (i = 0; i <= TN__GNN_PROFILE; i++) TN_CHECK(pv[i] == -1);
    tn_image_free(&er);
}

/* std of h[a..b) less its running mean over 17 values */
static double crest_relief_of(const float *pts, int a, int b)
{
    double s1 = 0, s2 = 0;
    int i, k, n = 0;
    for (i = a; i < b; i++, n++) {
        double m = 0;
        for (k = i - 8; k <= i + 8; k++) m += pts[3 * k + 2];
        m = pts[3 * i + 2] - m / 17;
        s1 += m, s2 += m * m;
    }
    return sqrt(s2 / n - (s1 / n) * (s1 / n));
}

/* An example of two ridge orders along x, cut into 8 px parts: a main ridge (order 2, its first
   top_len px) at y 64 swinging 40 m and a lower order (128 px) at y 20 swinging 400 m, both with a
   24 px period; with top_lines 2 or 3, one or two more main ridges of 128 px at y 80 and 96
   (ep[2], ep[3]), after the lower order's parts. */
static void two_ridge_orders(float ep[4][128 * 3], tn_contour *items, int top_len, int top_lines, tn_contour_set *ex)
{
    int i, k = 0, x;
    for (x = 0; x < 128; x++) {
        ep[0][3 * x] = (float)x, ep[0][3 * x + 1] = 64, ep[0][3 * x + 2] = 1000 + 40 * sinf(6.2831853f * x / 24);
        ep[1][3 * x] = (float)x, ep[1][3 * x + 1] = 20, ep[1][3 * x + 2] = 1000 + 400 * sinf(6.2831853f * x / 24);
        for (i = 2; i < 4; i++) ep[i][3 * x] = (float)x, ep[i][3 * x + 1] = (float)(48 + 16 * i), ep[i][3 * x + 2] = ep[0][3 * x + 2];
    }
    for (i = 0; i < top_lines + 1; i++)
        for (x = 0; x < (i == 0 ? top_len : 128); x += 8, k++) {
            memset(&items[k], 0, sizeof items[k]);
            items[k].type = TN_RIDGE;
            items[k].order = i == 1 ? 1 : 2;
            items[k].npoints = 8;
            items[k].points = ep[i] + 3 * x;
        }
    memset(ex, 0, sizeof *ex);
    ex->width = ex->height = 128, ex->items = items, ex->count = k;
}

/* A drawn sketch on a 256 canvas: a straight ridge at 500 m along y = 100 (x 20..220) and a valley
   that runs down from its middle (user[0], user[1]; up: their 201 points each). */
static tn_contour_set ridge_with_valley_drawn(float up[2][201 * 3], tn_contour user[2])
{
    tn_contour_set sk;
    int x;
    for (x = 0; x <= 200; x++) {
        up[0][3 * x] = (float)(20 + x), up[0][3 * x + 1] = 100, up[0][3 * x + 2] = 500;
        up[1][3 * x] = 120, up[1][3 * x + 1] = (float)(101 + x / 2), up[1][3 * x + 2] = 500;
    }
    memset(user, 0, 2 * sizeof *user);
    user[0].type = TN_RIDGE, user[1].type = TN_VALLEY;
    user[0].npoints = user[1].npoints = 201;
    user[0].points = up[0], user[1].points = up[1];
    memset(&sk, 0, sizeof sk);
    sk.width = sk.height = 256, sk.items = user, sk.count = 2;
    return sk;
}

TN_TEST(grow_crest_copies_the_example_relief)
{
    /* a drawn ridge of constant height takes the along-line relief of the example's main ridges
       (three chains of 8 px parts whose heights swing 40 m with a 24 px period: over
       TN__GNN_CREST_WIDE px), not that of its lower-order ridge (400 m); a drawn valley keeps its
       heights, and so does the ridge where the valley starts beside it; the seed decides */
    float ep[4][128 * 3], up[2][201 * 3], before[201 * 3], first[201 * 3];
    tn_contour items[64], user[2];
    tn_contour_set ex, sk;
    double want, got;
    int x, seed;
    two_ridge_orders(ep, items, 128, 3, &ex);
    want = crest_relief_of(ep[0], 8, 120);
    sk = ridge_with_valley_drawn(up, user);
    memcpy(before, up[0], sizeof before);
    for (seed = 1; seed <= 2; seed++) {
        if (seed == 2) memcpy(up[0], before, sizeof before);
        TN_CHECK(tn__gnn_grow_crest(&sk, 2, &ex, TN_RIDGE, (uint64_t)seed) == TN_OK);
        got = crest_relief_of(up[0], 20, 80);
        printf("  seed %d: drawn ridge's relief %.1f m, the example main ridge's %.1f m\n", seed, got, want);
        TN_CHECK(got > 0.6 * want && got < 1.4 * want);
        TN_CHECK(fabsf(up[0][3 * 100 + 2] - 500) < 1e-3f);
        for (x = 0; x <= 200; x++) TN_CHECK(fabsf(up[0][3 * x + 2] - 500) < 60 && up[1][3 * x + 2] == 500);
        if (seed == 1) memcpy(first, up[0], sizeof first);
    }
    TN_CHECK(memcmp(first, up[0], sizeof first) != 0);
    memcpy(up[0], before, sizeof before);
    TN_CHECK(tn__gnn_grow_crest(&sk, 2, &ex, TN_RIDGE, 1) == TN_OK);
    TN_CHECK(memcmp(first, up[0], sizeof first) == 0);
}

TN_TEST(grow_crest_widens_a_short_pool)
{
    /* an example whose main ridge is one line of 24 or 128 px (under TN__GNN_CREST_WIDE: copied
       again and again it is a comb) takes its next order down too (128 px), scaled to meet the
       main ridge's relief halfway: a swing of 40 m and one of 400 m give a drawn ridge the relief
       of about sqrt(40 x 400) m, well under the lower order's own; with no main line long enough
       to size it by (one 8 px part), the drawn ridge keeps its heights */
    static const int top_len[2] = {24, 128};
    float ep[4][128 * 3], up[201 * 3], before[201 * 3];
    tn_contour items[64], user;
    tn_contour_set ex, sk;
    double want_top, want_low, got;
    int x, seed, t;
    for (x = 0; x <= 200; x++) up[3 * x] = (float)(20 + x), up[3 * x + 1] = 100, up[3 * x + 2] = 500;
    memcpy(before, up, sizeof before);
    memset(&user, 0, sizeof user);
    user.type = TN_RIDGE, user.npoints = 201, user.points = up;
    memset(&sk, 0, sizeof sk);
    sk.width = sk.height = 256, sk.items = &user, sk.count = 1;
    for (t = 0; t < 2; t++) {
        two_ridge_orders(ep, items, top_len[t], 1, &ex);
        want_top = crest_relief_of(ep[0], 8, 120);
        want_low = crest_relief_of(ep[1], 8, 120);
        for (seed = 1; seed <= 2; seed++) {
            memcpy(up, before, sizeof before);
            TN_CHECK(tn__gnn_grow_crest(&sk, 1, &ex, TN_RIDGE, (uint64_t)seed) == TN_OK);
            got = crest_relief_of(up, 20, 180);
            printf("  main ridge %d px, seed %d: drawn ridge's relief %.1f m; main ridge %.1f m, next order %.1f m, their geometric mean %.1f m\n", top_len[t],
                   seed, got, want_top, want_low, sqrt(want_top * want_low));
            TN_CHECK(got > 0.6 * sqrt(want_top * want_low) && got < 1.4 * sqrt(want_top * want_low) && got < 0.5 * want_low);
        }
    }
    two_ridge_orders(ep, items, 24, 1, &ex);
    ex.count = 1 + 16; /* the main ridge's first part alone: 8 px */
    memmove(items + 1, items + 3, 16 * sizeof items[0]);
    memcpy(up, before, sizeof before);
    TN_CHECK(tn__gnn_grow_crest(&sk, 1, &ex, TN_RIDGE, 1) == TN_OK);
    TN_CHECK(memcmp(up, before, sizeof before) == 0);
}

TN_TEST(grow_crest_takes_the_example_bends)
{
    /* a straight drawn ridge takes the bends of the example's main ridges (three of 128 px that
       swing across by amp px with a 24 px period), never more than TN__GNN_CREST_BEND_MAX px off
       its place; where a drawn valley starts beside it, it stays put; a straight example leaves
       it straight */
    static const float amp[3] = {0, 1, 4};
    float ep[3][128 * 3], up[2][201 * 3];
    tn_contour items[48], user[2];
    tn_contour_set ex, sk;
    int a, i, x, k;
    for (a = 0; a < 3; a++) {
        double s2 = 0, mx = 0;
        int n = 0;
        for (i = 0, k = 0; i < 3; i++) {
            for (x = 0; x < 128; x++)
                ep[i][3 * x] = (float)x, ep[i][3 * x + 1] = (float)(40 + 24 * i) + amp[a] * sinf(6.2831853f * x / 24), ep[i][3 * x + 2] = 1000;
            for (x = 0; x < 128; x += 8, k++) {
                memset(&items[k], 0, sizeof items[k]);
                items[k].type = TN_RIDGE, items[k].order = 2, items[k].npoints = 8, items[k].points = ep[i] + 3 * x;
            }
        }
        memset(&ex, 0, sizeof ex);
        ex.width = ex.height = 128, ex.items = items, ex.count = k;
        sk = ridge_with_valley_drawn(up, user);
        TN_CHECK(tn__gnn_grow_crest(&sk, 2, &ex, TN_RIDGE, 1) == TN_OK);
        for (x = 0; x <= 200; x++) {
            double d = up[0][3 * x + 1] - 100.0;
            TN_CHECK(fabsf(up[0][3 * x] - (float)(20 + x)) < 1e-4f);
            mx = fmax(mx, fabs(d));
            if (abs(x - 100) > 24) s2 += d * d, n++;
        }
        printf("  example bends %.0f px: the drawn ridge moves %.2f px RMS away from the valley, at most %.2f px, %.3f px where the valley starts\n", (double)amp[a],
               sqrt(s2 / n), mx, fabs(up[0][3 * 100 + 1] - 100.0));
        TN_CHECK(mx <= TN__GNN_CREST_BEND_MAX + 1e-4);
        TN_CHECK(fabs(up[0][3 * 100 + 1] - 100.0) < 0.05);
        if (a == 0) TN_CHECK(mx < 1e-3);
        if (a == 1) TN_CHECK(sqrt(s2 / n) > 0.3 && sqrt(s2 / n) < 1.0);
        if (a == 2) TN_CHECK(sqrt(s2 / n) > 0.8);
    }
}


/* A 128 px example whose one ridge runs along y = 64, falling 15 m per px, with gullies and spurs
   swinging 40 m with a 20 px period on its flanks; its ridge line as 16 pieces of order 2 (ep:
   128 points, items: 16). */
static tn_status gullied_ridge_example(tn_image *dem, float *ep, tn_contour *items, tn_contour_set *ex)
{
    int x, y, k = 0;
    tn_status st = tn_image_create(dem, 128, 128, 1);
    if (st) return st;
    for (y = 0; y < 128; y++)
        for (x = 0; x < 128; x++) {
            float dy = fabsf((float)(y - 64));
            dem->data[y * 128 + x] = 1000 - 15 * dy + 40 * sinf(6.2831853f * x / 20) * fminf(1.0f, dy / 4);
        }
    for (x = 0; x < 128; x++) ep[3 * x] = (float)x, ep[3 * x + 1] = 64, ep[3 * x + 2] = 1000;
    memset(items, 0, 16 * sizeof *items);
    for (x = 0; x < 128; x += 8, k++) {
        items[k].type = TN_RIDGE;
        items[k].order = 2;
        items[k].npoints = 8;
        items[k].points = ep + 3 * x;
    }
    memset(ex, 0, sizeof *ex);
    ex->width = ex->height = 128, ex->items = items, ex->count = k;
    return TN_OK;
}

TN_TEST(grow_flanks_copy_the_example_flanks)
{
    /* the flanks of a drawn ridge take the example's: its main ridge (8 px parts along y = 64) has
       gullies and spurs swinging 40 m with a 20 px period on its flanks; 6 px across a drawn
       straight ridge the field swings as much, nothing is added on the stroke or 16 px or more
       away from it, and the same seed gives the same field */
    tn_image dem = {0, 0, 0, NULL};
    float ep[128 * 3], up[201 * 3], fl[6 * 17 * 3], *field = (float *)malloc(256 * 256 * sizeof(float)),
          *again = (float *)malloc(256 * 256 * sizeof(float));
    tn_contour items[16], user;
    tn_contour_set ex, sk;
    double want, got;
    int x, y;
    TN_CHECK(field && again && gullied_ridge_example(&dem, ep, items, &ex) == TN_OK);
    for (x = 0; x < 96; x++) fl[3 * x + 2] = dem.data[70 * 128 + 16 + x]; /* the example's flank, 6 px across */
    want = crest_relief_of(fl, 8, 88);
    for (x = 0; x <= 200; x++) up[3 * x] = (float)(28 + x), up[3 * x + 1] = 128, up[3 * x + 2] = 500;
    memset(&user, 0, sizeof user);
    user.type = TN_RIDGE, user.npoints = 201, user.points = up;
    memset(&sk, 0, sizeof sk);
    sk.width = sk.height = 256, sk.items = &user, sk.count = 1;
    TN_CHECK(tn__gnn_grow_flanks(&sk, 1, &ex, &dem, 1, field) == TN_OK);
    TN_CHECK(tn__gnn_grow_flanks(&sk, 1, &ex, &dem, 1, again) == TN_OK);
    TN_CHECK(memcmp(field, again, 256 * 256 * sizeof(float)) == 0);
    for (x = 40; x < 220; x++) TN_CHECK(field[128 * 256 + x] == 0 && field[(128 + 17) * 256 + x] == 0 && field[(128 - 17) * 256 + x] == 0);
    for (y = 0; y < 2; y++) {
        float row[140 * 3];
        for (x = 0; x < 140; x++) row[3 * x + 2] = field[(128 + (y ? 6 : -6)) * 256 + 60 + x];
        got = crest_relief_of(row, 8, 132);
        printf("  flank %s: %.1f m, the example's %.1f m\n", y ? "below" : "above", got, want);
        TN_CHECK(got > 0.6 * want && got < 1.4 * want);
    }
    tn_image_free(&dem);
    free(field);
    free(again);
}

TN_TEST(grow_without_block_grid)
{
    /* the quilted blocks (48 px) must not show: line pixels are as dense at every phase of the
       block grid, rows and columns (no block is chosen for an empty overlap); the example is the
       network of the bundled Alps DEM's central 128 px */
    tn_image full = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL}, r = {0, 0, 0, NULL};
    tn_contour_set ex, user, g;
    float rp[30], vp[30];
    double bin[12], lo = 1e30, hi = 0;
    int x, y, k;
    memset(bin, 0, sizeof bin);
    TN_CHECK(tn_image_load(&full, "examples/data/alps_n47e009_256.png", NULL) == TN_OK);
    TN_CHECK(tn_image_crop(&dem, &full, 64, 64, 128, 128) == TN_OK);
    ex = own_sketch(&dem);
    user = two_strokes(480, 480, rp, vp);
    TN_CHECK(tn_gnn_grow(&g, &user, &ex, 480, 480, NULL, NULL) == TN_OK);
    TN_CHECK(tn_sketch_rasterise(&r, &g, 480, 480) == TN_OK);
    for (y = 0; y < 480; y++)
        for (x = 0; x < 480; x++) {
            size_t i = (size_t)y * 480 + x;
            int l = r.data[3 * i] > 0 || r.data[3 * i + 1] > 0;
            bin[(y % 48) / 8] += l;
            bin[6 + (x % 48) / 8] += l;
        }
    for (k = 0; k < 12; k++) lo = fmin(lo, bin[k]), hi = fmax(hi, bin[k]);
    TN_CHECK(hi > 0 && lo / hi >= 0.75); /* 0.67 when the overlap score liked empty overlaps; 0.83 pasting cores, 0.79 cut */
    /* nor as seams: the grown sketch's membrane is no more curved along the block borders (the
       pixels either side of x or y = 48k) than elsewhere; 2.1-2.3x when each block's core was
       pasted whole, cutting the lines at the border */
    {
        tn_image m = {0, 0, 0, NULL};
        double s[2][2] = {{0, 0}, {0, 0}}, n[2][2] = {{0, 0}, {0, 0}};
        TN_CHECK(tn_gnn_membrane(&m, &g, 480, 480) == TN_OK);
        for (y = 1; y < 479; y++)
            for (x = 1; x < 479; x++) {
                const float *a = m.data + (size_t)y * 480 + x;
                double L = fabs(4.0 * a[0] - a[-1] - a[1] - a[-480] - a[480]);
                int sx = x % 48 == 0 || x % 48 == 47, sy = y % 48 == 0 || y % 48 == 47;
                s[0][sx] += L, n[0][sx]++;
                s[1][sy] += L, n[1][sy]++;
            }
        for (k = 0; k < 2; k++) {
            double ratio = (s[k][1] / n[k][1]) / (s[k][0] / n[k][0]);
            printf("  seam curvature ratio (%s): %.2f\n", k ? "rows" : "columns", ratio);
            TN_CHECK(ratio < 1.3);
        }
        tn_image_free(&m);
    }
    tn_contour_set_free(&g);
    tn_contour_set_free(&ex);
    tn_image_free(&r);
    tn_image_free(&dem);
    tn_image_free(&full);
}

TN_TEST(grown_strokes_stay_main_lines)
{
    /* a drawing of one kind of stroke: the ground grown around it falls away from a lone ridge
       and rises away from a lone valley, so the stroke stays the main line: the added lines
       beyond 48 px lie, on average, more than a third of the example lines' height spread below
       the ridge (above the valley); the membrane plus the example's own relief put them level
       with it. Example: the bundled Alps DEM's central 128 px */
    tn_image full = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL};
    tn_contour_set ex, user, g;
    tn_contour c;
    float pts[3 * 20];
    double m = 0, m2 = 0, n = 0, sd;
    int i, j, kind;
    TN_CHECK(tn_image_load(&full, "examples/data/alps_n47e009_256.png", NULL) == TN_OK);
    TN_CHECK(tn_image_crop(&dem, &full, 64, 64, 128, 128) == TN_OK);
    ex = own_sketch(&dem);
    for (i = 0; i < ex.count; i++)
        for (j = 0; j < ex.items[i].npoints; j++) {
            double h = ex.items[i].points[3 * j + 2];
            m += h, m2 += h * h, n += 1;
        }
    TN_CHECK(n > 0);
    m /= n;
    sd = sqrt(fmax(m2 / n - m * m, 0));
    for (kind = 0; kind < 2; kind++) {
        double far = 0, nf = 0, H = kind ? m - sd : m + sd;
        for (i = 0; i < 20; i++) {
            pts[3 * i] = 10.0f + 11.0f * (float)i;
            pts[3 * i + 1] = 120.0f + 8.0f * sinf(0.5f * (float)i);
            pts[3 * i + 2] = (float)H;
        }
        memset(&c, 0, sizeof c);
        c.type = kind ? TN_VALLEY : TN_RIDGE;
        c.npoints = 20;
        c.points = pts;
        memset(&user, 0, sizeof user);
        user.width = user.height = 240;
        user.count = 1;
        user.items = &c;
        TN_CHECK(tn_gnn_grow(&g, &user, &ex, 240, 240, NULL, NULL) == TN_OK);
        for (i = 1; i < g.count; i++)
            for (j = 0; j < g.items[i].npoints; j++) {
                float y = g.items[i].points[3 * j + 1];
                if (fabsf(y - 120) < 58) continue; /* 48 px beyond the stroke's 8 px swing and more */
                far += g.items[i].points[3 * j + 2], nf += 1;
            }
        TN_CHECK(nf > 100);
        far /= nf;
        printf("# lone %s at %.0f: added lines beyond 48 px at %.0f (spread %.0f)\n", kind ? "valley" : "ridge", H, far, sd);
        TN_CHECK(kind ? far > H + sd / 3 : far < H - sd / 3);
        tn_contour_set_free(&g);
    }
    tn_contour_set_free(&ex);
    tn_image_free(&dem);
    tn_image_free(&full);
}

/* The mean height range (max - min) along the ridge lines of 24+ points of g from index `from`. */
static double ridge_range(const tn_contour_set *g, int from)
{
    double r = 0;
    int i, j, nl = 0;
    for (i = from; i < g->count; i++) {
        const tn_contour *c = &g->items[i];
        float lo = 1e30f, hi = -1e30f;
        if (c->type != TN_RIDGE || c->npoints < 24) continue;
        for (j = 0; j < c->npoints; j++) lo = fminf(lo, c->points[3 * j + 2]), hi = fmaxf(hi, c->points[3 * j + 2]);
        r += hi - lo, nl++;
    }
    return nl ? r / nl : 0;
}

TN_TEST(grown_spurs_keep_the_example_tilt)
{
    /* with the example's heights, the added lines take theirs from the quilted example, away
       from the strokes less its mean over 512 px, so a spur keeps falling down its mountainside:
       along the added ridge lines the height range comes near the example's own ridge lines';
       the network's heights against a 48 px mean of its lines (no heights given) flatten each
       spur into a hill. Example: the bundled Alps DEM's central 128 px, one drawn ridge; means
       over four seeds (one seed's ratio runs from 0.98 to 1.31); the erosion's slope limit
       lessens the fine relief the spurs' range includes */
    tn_image full = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL};
    tn_contour_set ex, user, g;
    tn_contour c;
    tn_gnn_grow_opts go;
    float pts[3 * 20];
    double range[2], want;
    int i, with;
    TN_CHECK(tn_image_load(&full, "examples/data/alps_n47e009_256.png", NULL) == TN_OK);
    TN_CHECK(tn_image_crop(&dem, &full, 64, 64, 128, 128) == TN_OK);
    ex = own_sketch(&dem);
    want = ridge_range(&ex, 0);
    for (i = 0; i < 20; i++) {
        pts[3 * i] = 10.0f + 11.0f * (float)i;
        pts[3 * i + 1] = 120.0f + 8.0f * sinf(0.5f * (float)i);
        pts[3 * i + 2] = 1800;
    }
    memset(&c, 0, sizeof c);
    c.type = TN_RIDGE, c.npoints = 20, c.points = pts;
    memset(&user, 0, sizeof user);
    user.width = user.height = 240, user.count = 1, user.items = &c;
    memset(&go, 0, sizeof go);
    range[0] = range[1] = 0;
    for (go.seed = 0; go.seed < 4; go.seed++)
        for (with = 0; with < 2; with++) {
            TN_CHECK(tn__gnn_grow(&user, &ex, with ? &dem : NULL, 240, 240, &go, &g, NULL, NULL, NULL) == TN_OK);
            range[with] += ridge_range(&g, 1) / 4;
            tn_contour_set_free(&g);
        }
    printf("  added ridge lines' height range, seeds 0-3: %.0f m (without the example's heights %.0f m; the example's lines %.0f m)\n", range[1],
           range[0], want);
    TN_CHECK(range[1] > 0.7 * want && range[1] > 1.1 * range[0]);
    tn_contour_set_free(&ex);
    tn_image_free(&dem);
    tn_image_free(&full);
}

TN_TEST(grown_lines_keep_the_example_heights)
{
    /* the added lines are the quilted relief on the strokes' ground: on a ridge drawn at the
       example's top and a valley at its floor, that relief ran past both; now it stays within
       the example's range, give or take 10 % of it (tn__soft_limit; strokes beyond it would
       widen it). Example: the bundled Alps DEM's central 128 px */
    tn_image full = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL};
    tn_contour_set ex, user, g;
    tn_contour c[2];
    float rp[3 * 20], vp[3 * 20], lo, hi, glo = 1e30f, ghi = -1e30f, band;
    int i, j;
    TN_CHECK(tn_image_load(&full, "examples/data/alps_n47e009_256.png", NULL) == TN_OK);
    TN_CHECK(tn_image_crop(&dem, &full, 64, 64, 128, 128) == TN_OK);
    tn_image_range(&lo, &hi, &dem);
    band = 0.1f * (hi - lo);
    ex = own_sketch(&dem);
    for (i = 0; i < 20; i++) {
        rp[3 * i] = vp[3 * i] = 10.0f + 11.0f * (float)i;
        rp[3 * i + 1] = 70.0f + 6.0f * sinf(0.5f * (float)i), rp[3 * i + 2] = hi;
        vp[3 * i + 1] = 170.0f, vp[3 * i + 2] = lo;
    }
    memset(c, 0, sizeof c);
    c[0].type = TN_RIDGE, c[0].npoints = 20, c[0].points = rp;
    c[1].type = TN_VALLEY, c[1].npoints = 20, c[1].points = vp;
    memset(&user, 0, sizeof user);
    user.width = user.height = 240, user.count = 2, user.items = c;
    TN_CHECK(tn__gnn_grow(&user, &ex, &dem, 240, 240, NULL, &g, NULL, NULL, NULL) == TN_OK);
    for (i = 2; i < g.count; i++)
        for (j = 0; j < g.items[i].npoints; j++) glo = fminf(glo, g.items[i].points[3 * j + 2]), ghi = fmaxf(ghi, g.items[i].points[3 * j + 2]);
    printf("  added lines' heights %.0f..%.0f m; the example's %.0f..%.0f m (+-10 %%: %.0f..%.0f)\n", (double)glo, (double)ghi, (double)lo,
           (double)hi, (double)(lo - band), (double)(hi + band));
    TN_CHECK(g.count > 10);
    TN_CHECK(glo >= lo - band - 1e-3f * (hi - lo) && ghi <= hi + band + 1e-3f * (hi - lo));
    tn_contour_set_free(&g);
    tn_contour_set_free(&ex);
    tn_image_free(&dem);
    tn_image_free(&full);
}

/* tn__gnn_grow of one drawn ridge (n points at pts) on a 240 x 240 canvas, over ex with its heights dem. */
static tn_status grow_one_ridge(tn_contour_set *g, const tn_contour_set *ex, const tn_image *dem, float *pts, int n)
{
    tn_contour c;
    tn_contour_set user;
    memset(&c, 0, sizeof c);
    c.type = TN_RIDGE, c.npoints = n, c.points = pts;
    memset(&user, 0, sizeof user);
    user.width = user.height = 240, user.count = 1, user.items = &c;
    return tn__gnn_grow(&user, ex, dem, 240, 240, NULL, g, NULL, NULL, NULL);
}

TN_TEST(grown_ground_sinks_under_a_drawn_ring)
{
    /* a ring drawn at the middle of the example's heights: the quilted ground (the example's
       high massifs) stood above it tens of px away, inside and out, and the drawing no longer
       shaped the map; now it sinks as a whole to within the room the example's own main ridges
       leave over them (tn__gnn_grow_sink, tn__gnn_grow_room) and keeps its own relief. Example:
       the bundled Alps DEM's central 128 px */
    tn_image full = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL};
    tn_contour_set ex, g;
    float pts[3 * 49], lo, hi, top;
    double s = 0, s2 = 0, sd, worst = -1e30;
    long cnt = 0, above = 0;
    int i, j;
    TN_CHECK(tn_image_load(&full, "examples/data/alps_n47e009_256.png", NULL) == TN_OK);
    TN_CHECK(tn_image_crop(&dem, &full, 64, 64, 128, 128) == TN_OK);
    tn_image_range(&lo, &hi, &dem);
    top = lo + 0.5f * (hi - lo);
    ex = own_sketch(&dem);
    for (i = 0; i < 49; i++) /* closed: the last point is the first */
        pts[3 * i] = 120.0f + 80.0f * cosf(6.2831853f * (float)i / 48), pts[3 * i + 1] = 120.0f + 80.0f * sinf(6.2831853f * (float)i / 48), pts[3 * i + 2] = top;
    TN_CHECK(grow_one_ridge(&g, &ex, &dem, pts, 49) == TN_OK);
    for (i = 1; i < g.count; i++)
        for (j = 0; j < g.items[i].npoints; j++) {
            const float *p = g.items[i].points + 3 * j;
            if (fabs(hypot(p[0] - 120.0, p[1] - 120.0) - 80.0) < 24) continue; /* the ring's flanks */
            s += p[2], s2 += (double)p[2] * p[2], cnt++;
            above += p[2] > top;
            if (p[2] - top > worst) worst = p[2] - top;
        }
    sd = cnt > 1 ? sqrt(fmax(s2 / cnt - (s / cnt) * (s / cnt), 0)) : 0;
    printf("  added lines 24+ px from the ring at %.0f m: %.1f %% above it, at most %+.0f m; their sd %.0f m (the example's range %.0f m; %ld points)\n",
           (double)top, 100.0 * (double)above / (double)(cnt ? cnt : 1), worst, sd, (double)(hi - lo), cnt);
    TN_CHECK(cnt > 500);
    TN_CHECK(above < cnt * 15 / 100 && worst < 0.15 * (hi - lo)); /* before: 41.2 %, 693 m (39 %); the example's own ridges are topped by some */
    TN_CHECK(sd > 0.08 * (hi - lo)); /* sunk, not flattened */
    tn_contour_set_free(&g);
    tn_contour_set_free(&ex);
    tn_image_free(&dem);
    tn_image_free(&full);
}

TN_TEST(grown_ridge_flanks_are_its_own)
{
    /* with the example's heights, the quilted relief fades in over 16 px from a drawn ridge: the
       added lines 4-8 px from it lie near their mean height at that distance (the ridge's fall),
       where those from 24 px on scatter with the quilt's full relief; a quilt that knew nothing
       of the ridge put full-depth gullies a few px from it (a thin fin). Example: the bundled Alps
       DEM's central 128 px, one drawn ridge */
    tn_image full = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL};
    tn_contour_set ex, g;
    float pts[3 * 20];
    double s[2] = {0, 0}, s2[2] = {0, 0}, sd[2];
    long cnt[2] = {0, 0};
    int i, j, b;
    TN_CHECK(tn_image_load(&full, "examples/data/alps_n47e009_256.png", NULL) == TN_OK);
    TN_CHECK(tn_image_crop(&dem, &full, 64, 64, 128, 128) == TN_OK);
    ex = own_sketch(&dem);
    for (i = 0; i < 20; i++) pts[3 * i] = 10.0f + 11.0f * (float)i, pts[3 * i + 1] = 120.0f, pts[3 * i + 2] = 1800;
    TN_CHECK(grow_one_ridge(&g, &ex, &dem, pts, 20) == TN_OK);
    for (i = 1; i < g.count; i++)
        for (j = 0; j < g.items[i].npoints; j++) {
            const float *p = g.items[i].points + 3 * j;
            double d = fabs(p[1] - 120.0);
            if (p[0] < 24 || p[0] > 205) continue; /* beside the stroke, not past its ends */
            b = d >= 4 && d < 8 ? 0 : d >= 24 && d < 48 ? 1 : -1;
            if (b < 0) continue;
            s[b] += p[2], s2[b] += (double)p[2] * p[2], cnt[b]++;
        }
    for (b = 0; b < 2; b++) sd[b] = cnt[b] > 1 ? sqrt(fmax(s2[b] / cnt[b] - (s[b] / cnt[b]) * (s[b] / cnt[b]), 0)) : 0;
    printf("  added lines' heights: 4-8 px from the ridge sd %.0f m (%ld points), 24-48 px sd %.0f m (%ld points)\n", sd[0], cnt[0], sd[1], cnt[1]);
    TN_CHECK(cnt[0] > 20 && cnt[1] > 100);
    TN_CHECK(sd[0] < 0.15 * sd[1]);
    tn_contour_set_free(&g);
    tn_contour_set_free(&ex);
    tn_image_free(&dem);
    tn_image_free(&full);
}

/* Mean |terrain - asked height| over the strokes' pixels, and the share of their points that keep
   ridges above and valleys below the land 4 px across (tn_gnn_ordering). */
/* Bilinear height of img at (x, y) (inside the map). */
static double height_at(const tn_image *img, double x, double y)
{
    int x0 = (int)x, y0 = (int)y, x1 = x0 + 1 < img->width ? x0 + 1 : x0, y1 = y0 + 1 < img->height ? y0 + 1 : y0;
    double fx = x - x0, fy = y - y0;
    return (1 - fy) * ((1 - fx) * TN_PIXEL(img, x0, y0, 0) + fx * TN_PIXEL(img, x1, y0, 0)) + fy * ((1 - fx) * TN_PIXEL(img, x0, y1, 0) + fx * TN_PIXEL(img, x1, y1, 0));
}

TN_TEST(grow_flanks_without_streaks)
{
    /* a slanted drawn ridge is a staircase of pixels: its flanks must take the example's smooth
       gullies (a 20 px period, as in grow_flanks_copy_the_example_flanks), not a comb of streaks
       where the nearest stroke pixel steps or the normal of a short chord turns; 6 px across,
       along the line, the field's second difference stays small against its own relief (a 20 px
       sine: 0.10) */
    tn_image dem = {0, 0, 0, NULL}, fi = {256, 256, 1, NULL};
    float ep[128 * 3], up[2 * 3];
    tn_contour items[16], user;
    tn_contour_set ex, sk, dense;
    double s1 = 0, s2 = 0, c2 = 0, h[161], ux = 200 / sqrt(200.0 * 200 + 60 * 60), uy = 60 / sqrt(200.0 * 200 + 60 * 60), ratio;
    int k = 0, side;
    TN_CHECK(gullied_ridge_example(&dem, ep, items, &ex) == TN_OK);
    TN_CHECK((fi.data = (float *)malloc(256 * 256 * sizeof(float))) != NULL);
    up[0] = 28, up[1] = 90, up[2] = 500, up[3] = 228, up[4] = 150, up[5] = 500;
    memset(&user, 0, sizeof user);
    user.type = TN_RIDGE, user.npoints = 2, user.points = up;
    memset(&sk, 0, sizeof sk);
    sk.width = sk.height = 256, sk.items = &user, sk.count = 1;
    TN_CHECK(tn_sketch_densify(&dense, &sk) == TN_OK);
    TN_CHECK(tn__gnn_grow_flanks(&dense, 1, &ex, &dem, 1, fi.data) == TN_OK);
    for (side = -1; side <= 1; side += 2) {
        for (k = 0; k < 161; k++) { /* every px along the line, 6 px across it */
            double s = 20 + k;
            h[k] = height_at(&fi, 28 + s * ux - side * 6 * uy, 90 + s * uy + side * 6 * ux);
        }
        for (k = 8; k < 153; k++) {
            double m = 0, d2 = h[k + 1] - 2 * h[k] + h[k - 1];
            int j;
            for (j = k - 8; j <= k + 8; j++) m += h[j];
            m = h[k] - m / 17;
            s1 += m * m, s2 += 1, c2 += d2 * d2;
        }
    }
    ratio = sqrt(c2 / s1);
    printf("  second difference over relief, 6 px across: %.3f (relief %.1f m)\n", ratio, sqrt(s1 / s2));
    TN_CHECK(sqrt(s1 / s2) > 10 && ratio < 0.3);
    tn_contour_set_free(&dense);
    tn_image_free(&dem);
    free(fi.data);
}

/* Cross profiles of a straight ridge from (x0, y0) to (x1, y1), 12 px from its ends: top, the
   share of its points higher than the terrain 1..3 px across on both sides; spike, the mean
   drop 1 px across over a third of the drop 3 px across (1: straight flanks; 2 or more: a wall
   of a pixel on its ground). */
static void ridge_shape(const tn_image *t, double x0, double y0, double x1, double y1, double *top, double *spike)
{
    double len = hypot(x1 - x0, y1 - y0), nx = -(y1 - y0) / len, ny = (x1 - x0) / len, d1 = 0, d3 = 0, s;
    int n = 0, good = 0, o;
    for (s = 12; s <= len - 12; s += 1) {
        double x = x0 + (x1 - x0) * s / len, y = y0 + (y1 - y0) * s / len, h0 = height_at(t, x, y), hi = -HUGE_VAL;
        for (o = 2; o <= 6; o++) hi = fmax(hi, fmax(height_at(t, x + nx * o * 0.5, y + ny * o * 0.5), height_at(t, x - nx * o * 0.5, y - ny * o * 0.5)));
        good += h0 >= hi;
        d1 += h0 - 0.5 * (height_at(t, x + nx, y + ny) + height_at(t, x - nx, y - ny));
        d3 += h0 - 0.5 * (height_at(t, x + 3 * nx, y + 3 * ny) + height_at(t, x - 3 * nx, y - 3 * ny));
        n++;
    }
    *top = n ? (double)good / n : 0;
    *spike = d3 > 0 ? 3 * d1 / d3 : HUGE_VAL;
}

/* A lone ridge drawn across a 160 x 120 map, at 80 % of the range (*lo..*hi) of a tiny model's
   example, grown, generated without (t[0]) and with (t[1]) the fine detail. */
static void lone_ridge_with_and_without_detail(tn_image t[2], float *lo, float *hi)
{
    tn_image dem = tn_test_dem(64, 22);
    tn_gnn m;
    tn_gnn_opts o;
    tn_gnn_generate_opts go;
    tn_contour c;
    tn_contour_set sk;
    float pts[6] = {12, 20, 0, 148, 100, 0};
    int k;
    tn_image_range(lo, hi, &dem);
    pts[2] = pts[5] = *lo + 0.8f * (*hi - *lo);
    tn_test_tiny_gnn_opts(&o, 3);
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_OK);
    memset(&c, 0, sizeof c);
    c.type = TN_RIDGE;
    c.npoints = 2;
    c.points = pts;
    memset(&sk, 0, sizeof sk);
    sk.width = 160;
    sk.height = 120;
    sk.count = 1;
    sk.items = &c;
    memset(&go, 0, sizeof go);
    go.seed = 1;
    go.grow = 1;
    go.map_scale = -1;
    for (k = 0; k < 2; k++) {
        go.detail = k ? 0 : -1;
        TN_CHECK(tn_gnn_generate(&t[k], &m, &sk, 160, 120, &go) == TN_OK);
    }
    tn_gnn_free(&m);
    tn_image_free(&dem);
}

TN_TEST(drawn_ridge_is_a_crest)
{
    /* a lone ridge drawn across the map, grown: in map view a crest, not a thin line or a groove.
       Across it the stroke is the highest ground within 3 px and its flanks fall from it without
       the network's wall of a pixel on its ground; through the fine detail it keeps a top */
    tn_image t[2] = {{0, 0, 0, NULL}, {0, 0, 0, NULL}};
    float dlo = 0, dhi = 0;
    int k;
    lone_ridge_with_and_without_detail(t, &dlo, &dhi);
    for (k = 0; k < 2; k++) {
        double top = 0, spike = 0;
        if (!t[k].data) continue;
        ridge_shape(&t[k], 12, 20, 148, 100, &top, &spike);
        printf("  drawn ridge %s the detail: highest within 3 px at %.1f %% of its points, spike %.2f\n", k ? "with" : "without", 100 * top, spike);
        if (k) TN_CHECK(top >= 0.4 && spike >= 0.45); /* the detail's low-pass left a flat band: 20.9 %, 0.30 */
        else TN_CHECK(top >= 0.95 && spike <= 1.0);   /* the network's wall: 1.13 */
    }
    tn_image_free(&t[0]);
    tn_image_free(&t[1]);
}

/* A tiny model of dem, and on it one straight ridge drawn across a 160 x 120 map (pts: x, y and
   height of its two ends, example units), grown, seed 1, no map-scale level; detail as
   tn_gnn_generate_opts.detail. The model, sketch (c, sk) and options stay for windows. */
static void one_drawn_ridge(const tn_image *dem, float *pts, int detail, tn_gnn *m, tn_contour *c, tn_contour_set *sk, tn_gnn_generate_opts *go,
                            tn_image *t)
{
    tn_gnn_opts o;
    tn_test_tiny_gnn_opts(&o, 3);
    TN_CHECK(tn_gnn_train(m, dem, &o, NULL) == TN_OK);
    memset(c, 0, sizeof *c);
    c->type = TN_RIDGE, c->npoints = 2, c->points = pts;
    memset(sk, 0, sizeof *sk);
    sk->width = 160, sk->height = 120, sk->count = 1, sk->items = c;
    memset(go, 0, sizeof *go);
    go->seed = 1, go->grow = 1, go->detail = detail, go->map_scale = -1, go->heights = TN_GNN_HEIGHTS_EXAMPLE;
    TN_CHECK(tn_gnn_generate(t, m, sk, 160, 120, go) == TN_OK);
}

TN_TEST(bent_ridge_is_followed_where_drawn)
{
    /* the example's main ridges wander (2 px across, 20 px period); a straight ridge drawn
       across the map takes those bends, so its crest leaves the line as drawn, yet the line as
       drawn stays above the ground 4 px across it: the notch raises it there, up to the moved
       crest, where the bends left it lower (95 %; without that notch 90 %), and a window equals
       the whole map. Example: ridges every 32 px, 300 m high */
    tn_image dem, t = {0, 0, 0, NULL}, win = {0, 0, 0, NULL};
    tn_gnn m;
    tn_gnn_generate_opts go;
    tn_contour c;
    tn_contour_set sk;
    float pts[6] = {10, 60, 900, 150, 60, 900};
    double share = 0, off = 0;
    int x, y, n = 0, moved = 0;
    TN_CHECK(tn_image_create(&dem, 96, 96, 1) == TN_OK);
    for (y = 0; y < 96; y++)
        for (x = 0; x < 96; x++) {
            double w = fmod(y + 2.0 * sin(6.2831853 * x / 20) + 64, 32.0); /* 0 .. 32 across a ridge spacing */
            dem.data[y * 96 + x] = (float)(600 + 300 * (1 - fabs(w - 16) / 16) + 20 * sin(0.7 * x + 0.3 * y));
        }
    one_drawn_ridge(&dem, pts, -1, &m, &c, &sk, &go, &t);
    if (t.data) {
        for (x = 20; x <= 140; x++, n++) { /* where the crest lies across the line, within 3 px */
            int best = 0, d;
            for (d = -3; d <= 3; d++)
                if (t.data[(60 + d) * 160 + x] > t.data[(60 + best) * 160 + x]) best = d;
            off += abs(best), moved += best != 0;
        }
        TN_CHECK(tn_gnn_ordering(&share, &sk, &t, 4, NULL) == TN_OK);
        printf("  bent drawn ridge: crest off the line at %d of %d columns (%.2f px on average), followed at %.1f %% of its points\n", moved, n,
               off / n, 100 * share);
        TN_CHECK(moved > n / 4);
        TN_CHECK(share >= 0.93);
        TN_CHECK(tn_gnn_generate_window(&win, &m, &sk, 160, 120, 50, 40, 70, 50, &go) == TN_OK); /* the notch reads the line as drawn tile by tile */
        TN_CHECK(win.data && window_matches(&win, &t, 50, 40));
    }
    tn_image_free(&win);
    tn_image_free(&t);
    tn_image_free(&dem);
    tn_gnn_free(&m);
}

TN_TEST(drawn_ridge_stays_above_cratered_detail)
{
    /* an example of low ridges pitted with craters whose rims stand far above a ridge's flank:
       the fine detail brings such rims to the drawn ridge's banks, where they topped it (followed
       at 77 % of its points with the notch before the detail alone, 100 % without the detail).
       The notch runs again after the detail (96 %); a window equals the whole map. Example:
       ridges every 32 px, 60 m high, craters every 12 px whose rims rise 400 m */
    tn_image dem, t = {0, 0, 0, NULL}, win = {0, 0, 0, NULL};
    tn_gnn m;
    tn_gnn_generate_opts go;
    tn_contour c;
    tn_contour_set sk;
    float pts[6] = {10, 60, 760, 150, 60, 760};
    double share = 0;
    int x, y, i, j;
    TN_CHECK(tn_image_create(&dem, 96, 96, 1) == TN_OK);
    for (y = 0; y < 96; y++)
        for (x = 0; x < 96; x++) {
            double w = fmod(y + 64.0, 32.0), h = 600 + 60 * (1 - fabs(w - 16) / 16);
            for (j = 0; j < 8; j++)
                for (i = 0; i < 8; i++) { /* a crater: a bowl within a rim of radius 3 px */
                    double cx = 6 + 12 * i + 3 * sin(1.7 * j + 0.9 * i), cy = 6 + 12 * j + 3 * cos(1.3 * i + 0.7 * j);
                    double r = hypot(x - cx, y - cy);
                    h += 400 * exp(-(r - 3) * (r - 3)) - 300 * exp(-r * r / 3);
                }
            dem.data[y * 96 + x] = (float)h;
        }
    one_drawn_ridge(&dem, pts, 0, &m, &c, &sk, &go, &t); /* the detail by default */
    if (t.data) {
        TN_CHECK(tn_gnn_ordering(&share, &sk, &t, 4, NULL) == TN_OK);
        printf("  drawn ridge through cratered detail: followed at %.1f %% of its points\n", 100 * share);
        TN_CHECK(share >= 0.93);
        TN_CHECK(tn_gnn_generate_window(&win, &m, &sk, 160, 120, 50, 40, 70, 50, &go) == TN_OK); /* the notch after the detail, tile by tile */
        TN_CHECK(win.data && window_matches(&win, &t, 50, 40));
    }
    tn_image_free(&win);
    tn_image_free(&t);
    tn_image_free(&dem);
    tn_gnn_free(&m);
}

TN_TEST(example_fall_ratio_reads_the_lie_of_gullies)
{
    /* a slope falling along y with gullies running down it (relief across the fall lines) reads
       well above 1; the same relief turned to run across the slope (terraces) well below 1; a flat
       map reads 0. Erosion follows the first kind only */
    tn_image a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    double ra = 0, rb = 0, rf = 1;
    int x, y;
    TN_CHECK(tn_image_create(&a, 128, 128, 1) == TN_OK && tn_image_create(&b, 128, 128, 1) == TN_OK);
    for (y = 0; a.data && b.data && y < 128; y++)
        for (x = 0; x < 128; x++) {
            a.data[y * 128 + x] = 2.0f * (float)y + 5.0f * sinf(6.2831853f * (float)x / 10);
            b.data[y * 128 + x] = 2.0f * (float)y + 5.0f * sinf(6.2831853f * (float)y / 10);
        }
    TN_CHECK(tn__gnn_fall_ratio(&a, &ra) == TN_OK && tn__gnn_fall_ratio(&b, &rb) == TN_OK);
    for (x = 0; b.data && x < 128 * 128; x++) b.data[x] = 7;
    TN_CHECK(tn__gnn_fall_ratio(&b, &rf) == TN_OK);
    printf("  fall ratio: gullies %.2f, terraces %.2f, flat %.2f\n", ra, rb, rf);
    TN_CHECK(ra > 4 && rb < 0.25 && rf == 0);
    tn_image_free(&a);
    tn_image_free(&b);
}

TN_TEST(grown_ground_erodes_down_its_slopes)
{
    /* ground falling 2 a px to a drawn valley along the bottom row, with waves every way on it:
       eroded by its own drainage, its relief runs more down the slope (the fall ratio rises, and
       what was dug runs down it: gullies, not pits), nothing is raised, no depth passes the cap,
       no basin is dug, and no step grows past the example's steepest or its own; mix 0, or
       ground on a drawn ridge's flank, stays as it was */
    const int W = 96, H = 96;
    tn_image ur = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL}, t0 = {0, 0, 0, NULL}, t1 = {0, 0, 0, NULL};
    float *ground = (float *)malloc(sizeof(float) * W * H), *prel = (float *)malloc(sizeof(float) * W * H), *p0 = (float *)malloc(sizeof(float) * W * H);
    float *Dr = (float *)malloc(sizeof(float) * W * H), deepest = 0, worst = 0;
    double r0 = 0, r1 = 0, rd = 0, b0, b1;
    int x, y, i, k, raised = 0;
    TN_CHECK(ground && prel && p0 && Dr);
    TN_CHECK(tn_image_create(&ur, W, H, 3) == TN_OK && tn_image_create(&dem, 32, 32, 1) == TN_OK);
    TN_CHECK(tn_image_create(&t0, W, H, 1) == TN_OK && tn_image_create(&t1, W, H, 1) == TN_OK);
    if (!ground || !prel || !p0 || !Dr || !ur.data || !dem.data || !t0.data || !t1.data) goto done;
    for (i = 0; i < 32 * 32; i++) dem.data[i] = 5.0f * (float)(i % 32); /* steepest step 5 */
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) {
            i = y * W + x;
            ground[i] = 2.0f * (float)(H - 1 - y);
            for (p0[i] = 0, k = 0; k < 12; k++) { /* waves every way: relief with no lie */
                float a = 2.3999632f * (float)k, f = 6.2831853f / (9.0f + 1.3f * (float)k);
                p0[i] += 2.0f * sinf(f * (cosf(a) * (float)x + sinf(a) * (float)y) + (float)k);
            }
            ur.data[3 * i + 1] = y == H - 1 ? 1.0f : 0.0f;
            Dr[i] = 1e9f;
            t0.data[i] = ground[i] + p0[i];
        }
    memcpy(prel, p0, sizeof(float) * W * H);
    TN_CHECK(tn__gnn_quilt_erode(ground, &ur, Dr, &dem, 16, 6.0f, 0.0f, W, H, prel) == TN_OK);
    TN_CHECK(!memcmp(prel, p0, sizeof(float) * W * H));
    for (i = 0; i < W * H; i++) Dr[i] = 4;
    TN_CHECK(tn__gnn_quilt_erode(ground, &ur, Dr, &dem, 16, 6.0f, 1.0f, W, H, prel) == TN_OK);
    TN_CHECK(!memcmp(prel, p0, sizeof(float) * W * H));
    for (i = 0; i < W * H; i++) Dr[i] = 1e9f;
    TN_CHECK(tn__gnn_quilt_erode(ground, &ur, Dr, &dem, 16, 6.0f, 1.0f, W, H, prel) == TN_OK);
    for (i = 0; i < W * H; i++) t1.data[i] = ground[i] + prel[i];
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) {
            i = y * W + x;
            raised += prel[i] > p0[i];
            deepest = fmaxf(deepest, p0[i] - prel[i]);
            if (x + 1 < W) worst = fmaxf(worst, fabsf(t1.data[i + 1] - t1.data[i]) - fmaxf(5, fabsf(t0.data[i + 1] - t0.data[i])));
            if (y + 1 < H) worst = fmaxf(worst, fabsf(t1.data[i + W] - t1.data[i]) - fmaxf(5, fabsf(t0.data[i + W] - t0.data[i])));
        }
    TN_CHECK(tn__gnn_fall_ratio(&t0, &r0) == TN_OK && tn__gnn_fall_ratio(&t1, &r1) == TN_OK);
    for (i = 0; i < W * H; i++) t1.data[i] = ground[i] + prel[i] - p0[i]; /* what the erosion dug, on the slope */
    TN_CHECK(tn__gnn_fall_ratio(&t1, &rd) == TN_OK);
    for (i = 0; i < W * H; i++) t1.data[i] = ground[i] + prel[i];
    b0 = basin_share(&t0, 50), b1 = basin_share(&t1, 50); /* deeper than 0.5 */
    printf("  fall ratio %.2f -> %.2f (what was dug: %.2f); deepest cut %.2f (cap 6); basins %.2f -> %.2f %%; steps past the limit by %.3f\n", r0, r1, rd,
           (double)deepest, 100 * b0, 100 * b1, (double)worst);
    TN_CHECK(r1 > 1.1 * r0 && rd > 1.5);
    TN_CHECK(!raised && deepest > 1 && deepest <= 6);
    TN_CHECK(b1 <= b0 + 0.002);
    TN_CHECK(worst <= 0.01f);
done:
    free(ground), free(prel), free(p0), free(Dr);
    tn_image_free(&ur), tn_image_free(&dem), tn_image_free(&t0), tn_image_free(&t1);
}

/* The mean gradient length of a one-channel image, central differences, the border left out. */
static double mean_gradient(const tn_image *a)
{
    double s = 0;
    int x, y, W = a->width;
    for (y = 1; y < a->height - 1; y++)
        for (x = 1; x < W - 1; x++) {
            const float *h = a->data + (size_t)y * W + x;
            s += 0.5 * hypot((double)(h[1] - h[-1]), (double)(h[W] - h[-W]));
        }
    return s / ((double)(W - 2) * (a->height - 2));
}

TN_TEST(eroded_ground_keeps_the_example_steepness)
{
    /* the ground of grown_ground_erodes_down_its_slopes (2 a px, waves every way, a drawn valley
       along the bottom row) with an example far gentler on the mean (0.5 a px, one cliff of 20 so
       the steps may grow): the erosion steepens the ground, and its relief is scaled back until
       the mean slope is the ground's own again, its arrangement kept (the fall ratio still rises);
       with a steep example (5 a px) the eroded ground keeps the steepness it dug */
    const int W = 96, H = 96;
    tn_image ur = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL}, t0 = {0, 0, 0, NULL}, t1 = {0, 0, 0, NULL};
    float *ground = (float *)malloc(sizeof(float) * W * H), *prel = (float *)malloc(sizeof(float) * W * H), *p0 = (float *)malloc(sizeof(float) * W * H);
    float *Dr = (float *)malloc(sizeof(float) * W * H);
    double s0 = 0, s_gentle = 0, s_steep = 0, ex = 0, r0 = 0, r1 = 0;
    int x, y, i, k, pass;
    TN_CHECK(ground && prel && p0 && Dr);
    TN_CHECK(tn_image_create(&ur, W, H, 3) == TN_OK && tn_image_create(&dem, 32, 32, 1) == TN_OK);
    TN_CHECK(tn_image_create(&t0, W, H, 1) == TN_OK && tn_image_create(&t1, W, H, 1) == TN_OK);
    if (!ground || !prel || !p0 || !Dr || !ur.data || !dem.data || !t0.data || !t1.data) goto done;
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) {
            i = y * W + x;
            ground[i] = 2.0f * (float)(H - 1 - y);
            for (p0[i] = 0, k = 0; k < 12; k++) {
                float a = 2.3999632f * (float)k, f = 6.2831853f / (9.0f + 1.3f * (float)k);
                p0[i] += 2.0f * sinf(f * (cosf(a) * (float)x + sinf(a) * (float)y) + (float)k);
            }
            ur.data[3 * i + 1] = y == H - 1 ? 1.0f : 0.0f;
            Dr[i] = 1e9f;
            t0.data[i] = ground[i] + p0[i];
        }
    s0 = mean_gradient(&t0);
    for (pass = 0; pass < 2; pass++) { /* 0: the gentle example, 1: the steep one */
        for (i = 0; i < 32 * 32; i++) dem.data[i] = pass ? 5.0f * (float)(i % 32) : 0.5f * (float)(i % 32) + (i % 32 >= 16 ? 20.0f : 0.0f);
        if (!pass) ex = mean_gradient(&dem);
        memcpy(prel, p0, sizeof(float) * W * H);
        TN_CHECK(tn__gnn_quilt_erode(ground, &ur, Dr, &dem, 16, 6.0f, 1.0f, W, H, prel) == TN_OK);
        for (i = 0; i < W * H; i++) t1.data[i] = ground[i] + prel[i];
        if (pass) s_steep = mean_gradient(&t1);
        else {
            s_gentle = mean_gradient(&t1);
            TN_CHECK(tn__gnn_fall_ratio(&t0, &r0) == TN_OK && tn__gnn_fall_ratio(&t1, &r1) == TN_OK);
        }
    }
    printf("  mean slope %.3f; eroded: %.3f under a gentle example (its own %.3f), %.3f under a steep one; fall ratio %.2f -> %.2f\n", s0, s_gentle,
           ex, s_steep, r0, r1);
    TN_CHECK(ex < s0);
    TN_CHECK(s_steep > 1.02 * s0);
    TN_CHECK(s_gentle <= 1.002 * s0 && s_gentle > 0.98 * s0);
    TN_CHECK(r1 > 1.1 * r0);
done:
    free(ground), free(prel), free(p0), free(Dr);
    tn_image_free(&ur), tn_image_free(&dem), tn_image_free(&t0), tn_image_free(&t1);
}

TN_TEST(width_field_is_smooth)
{
    /* two drawn valleys of width factors 0.6 and 1.6, 80 px apart: the factor read at each
       pixel's nearest valley pixel jumps by 1.0 on the bisector between them (a 150 m cliff in
       the grown ground on the Alps); the smoothed field moves by at most 0.05 a px there, and
       keeps each valley's own factor beside it within 0.1 */
    const int W = 120, H = 40;
    float kv[120 * 40], K[120 * 40], step = 0;
    int nearv[120 * 40], x, y;
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) {
            kv[y * W + x] = x == 20 ? 0.6f : x == 100 ? 1.6f : 1.0f;
            nearv[y * W + x] = y * W + (x <= 60 ? 20 : 100); /* the valleys run down x = 20 and x = 100 */
        }
    TN_CHECK(fabsf(kv[nearv[20 * W + 59]] - kv[nearv[20 * W + 61]]) > 0.99f);
    TN_CHECK(tn__gnn_grow_width_field(kv, nearv, W, H, K) == TN_OK);
    for (y = 0; y < H; y++)
        for (x = 1; x < W; x++) step = fmaxf(step, fabsf(K[y * W + x] - K[y * W + x - 1]));
    printf("  largest step of the width field: %.3f a px\n", (double)step);
    TN_CHECK(step <= 0.05f);
    TN_CHECK(fabsf(K[20 * W + 20] - 0.6f) <= 0.1f && fabsf(K[20 * W + 100] - 1.6f) <= 0.1f);
}

TN_TEST(bundled_style_window_equals_whole_map)
{
    /* the Alps style on the fork drawing, grown, with the fine detail and the grown ground's
       band: windows equal the whole map, one of the two starting its detail tile at an odd x (the
       detail's coherence sweeps colour the pixels by their x + y in the map, not in the tile) */
    tn_gnn m;
    tn_contour_set sk;
    tn_gnn_generate_opts go;
    tn_image whole = {0, 0, 0, NULL}, win = {0, 0, 0, NULL};
    int x;
    memset(&m, 0, sizeof m);
    memset(&sk, 0, sizeof sk);
    memset(&go, 0, sizeof go);
    go.seed = 1;
    TN_CHECK(tn_gnn_load(&m, "examples/data/styles/alps.tnw") == TN_OK && tn_sketch_load(&sk, "bench/drawings/sketch_fork.tns") == TN_OK);
    TN_CHECK(tn_gnn_generate(&whole, &m, &sk, 256, 256, &go) == TN_OK);
    for (x = 100; whole.data && x <= 101; x++) {
        TN_CHECK(tn_gnn_generate_window(&win, &m, &sk, 256, 256, x, 60, 90, 70, &go) == TN_OK);
        TN_CHECK(window_matches(&win, &whole, x, 60));
        tn_image_free(&win);
    }
    tn_image_free(&whole);
    tn_contour_set_free(&sk);
    tn_gnn_free(&m);
}

TN_TEST(bundled_styles_hold_their_example_without_steps)
{
    /* gnn-train learns and stores an 8-bit example without its height steps; the quilt, the
       levels and the fine detail draw on the stored heights, so a bundled style trained before
       that carried the steps' speckle into every drawing (the Grand Canyon's: mean |Laplacian|
       1.27 against the example's 0.72 without its steps) */
    static const char *name[5] = {"alps", "dunes", "grandcanyon", "himalaya", "moon"};
    char path[64];
    int i;
    for (i = 0; i < 5; i++) {
        tn_gnn m;
        const tn_tensor *e;
        memset(&m, 0, sizeof m);
        snprintf(path, sizeof path, "examples/data/styles/%s.tnw", name[i]);
        TN_CHECK(tn_gnn_load(&m, path) == TN_OK);
        TN_CHECK((e = tn_params_find(m.weights, "detail.example")) != NULL);
        if (e) {
            tn_image ex;
            ex.width = e->shape[1], ex.height = e->shape[0], ex.channels = 1, ex.data = e->data;
            printf("  %s: coarse height step %g\n", name[i], (double)tn_image_height_step(&ex, 1));
            TN_CHECK(tn_image_height_step(&ex, 1) == 0);
        }
        tn_gnn_free(&m);
    }
}

TN_TEST(detail_digs_no_groove_beside_a_drawn_ridge)
{
    /* the fine detail adds the example's texture to a drawn ridge, not a cross profile of its
       own: its change, averaged along the ridge at each distance across it, stays near its
       change on the ridge. Pinning only the change on the ridge, faded over 12 px, left the
       detail's raised band 0-3 px wide and dug a groove along its foot 4-8 px out (an
       embankment in map view). The notch after the detail raises the ridge where the detail's
       banks top it (here by 1.3 m on average; 3-8 px out the change is as without it): 1.2 %
       of the range, where 9.3 m passed 1 % without that notch */
    tn_image t[2] = {{0, 0, 0, NULL}, {0, 0, 0, NULL}};
    float dlo = 0, dhi = 0;
    double len = hypot(136.0, 80.0), nx = -80 / len, ny = 136 / len, ch[11], dev = 0, s;
    int k, o1, n = 0;
    lone_ridge_with_and_without_detail(t, &dlo, &dhi);
    if (t[0].data && t[1].data) {
        for (o1 = 0; o1 <= 10; o1++) ch[o1] = 0;
        for (s = 12; s <= len - 12; s += 1, n++) /* the detail's change 0..10 px across, both sides */
            for (o1 = 0; o1 <= 10; o1++)
                for (k = -1; k <= 1; k += 2) {
                    double x = 12 + 136 * s / len + k * nx * o1, y = 20 + 80 * s / len + k * ny * o1;
                    ch[o1] += 0.5 * (height_at(&t[1], x, y) - height_at(&t[0], x, y));
                }
        printf("  the detail's mean change 0..10 px across a drawn ridge, m:");
        for (o1 = 0; o1 <= 10; o1++) printf(" %.1f", ch[o1] / n);
        for (o1 = 3; o1 <= 8; o1++) dev = fmax(dev, fabs(ch[o1] - ch[0]) / n);
        printf("\n  largest 3-8 px across, against its change on the ridge: %.1f m (range %.0f m)\n", dev, (double)(dhi - dlo));
        TN_CHECK(dev < 0.012 * (dhi - dlo));
    }
    tn_image_free(&t[0]);
    tn_image_free(&t[1]);
}

TN_TEST(drawn_valley_widens_downstream)
{
    /* a drawn valley is a valley of the example's, not a trough of one width: its ground rises as
       the example's does from its main valley, over a distance that grows with the drawn valley
       upstream (narrow at its head, broad at its mouth). An example whose valleys rise 10 m per
       px from the main one (order 3); a valley drawn down the map: the added lines 10-20 px from
       it rise above it more near its head than near its mouth */
    float pts[15][6], up[6] = {128, 8, 1000, 128, 248, 500};
    tn_contour items[15], drawn;
    tn_contour_set ex, user, out;
    double rise[2] = {0, 0}, cnt[2] = {0, 0};
    int c, j, k = 0;
    tn_test_stripes(&ex, items, pts, TN_VALLEY, 100.0f, 10.0f);
    memset(&drawn, 0, sizeof drawn);
    drawn.type = TN_VALLEY;
    drawn.points = up;
    drawn.npoints = 2;
    memset(&user, 0, sizeof user);
    user.width = user.height = 256;
    user.items = &drawn;
    user.count = 1;
    TN_CHECK(tn_gnn_grow(&out, &user, &ex, 256, 256, NULL, NULL) == TN_OK);
    for (c = 1; c < out.count; c++)
        for (j = 0; j < out.items[c].npoints; j++) {
            const float *q = out.items[c].points + 3 * j;
            float d = fabsf(q[0] - 128);
            int part = q[1] < 90 ? 0 : q[1] > 170 ? 1 : -1;
            if (part < 0 || d < 10 || d > 20) continue;
            rise[part] += q[2] - (1000 + (500 - 1000) * (q[1] - 8) / 240), cnt[part]++;
        }
    for (k = 0; k < 2; k++) rise[k] = cnt[k] > 0 ? rise[k] / cnt[k] : 0;
    printf("  added lines 10-20 px from a drawn valley: %.1f m above it near its head, %.1f m near its mouth\n", rise[0], rise[1]);
    TN_CHECK(cnt[0] > 0 && cnt[1] > 0 && rise[1] > 0 && rise[0] > 1.4 * rise[1]);
    tn_contour_set_free(&out);
}

static void stroke_fit(const tn_contour_set *sk, const tn_image *t, double *err, double *follow)
{
    tn_image r = {0, 0, 0, NULL};
    size_t k, nk = 0;
    *err = 0;
    if (tn_sketch_rasterise(&r, sk, t->width, t->height) == TN_OK)
        for (k = 0; k < (size_t)t->width * t->height; k++)
            if (r.data[3 * k] > 0 || r.data[3 * k + 1] > 0) *err += fabs(t->data[k] - r.data[3 * k + 2]), nk++;
    *err = nk ? *err / (double)nk : 1e30;
    if (tn_gnn_ordering(follow, sk, t, 4, NULL) != TN_OK) *follow = 0;
    tn_image_free(&r);
}

/* Median |img - its Gaussian of 2 px| within 4 px of the sketch's valley pixels. */
static double floor_detail(const tn_contour_set *sk, const tn_image *img)
{
    tn_image r = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    double *v = (double *)malloc((size_t)img->width * img->height * sizeof(double)), med = -1;
    size_t k, n = 0;
    int x, y, dx, dy;
    if (v && tn_sketch_rasterise(&r, sk, img->width, img->height) == TN_OK && tn_image_blur(&b, img, 2.0f) == TN_OK) {
        for (y = 0; y < img->height; y++)
            for (x = 0; x < img->width; x++) {
                int near_valley = 0;
                for (dy = -4; dy <= 4 && !near_valley; dy++)
                    for (dx = -4; dx <= 4 && !near_valley; dx++)
                        if (x + dx >= 0 && y + dy >= 0 && x + dx < img->width && y + dy < img->height)
                            near_valley = r.data[3 * ((size_t)(y + dy) * img->width + x + dx) + 1] > 0;
                k = (size_t)y * img->width + x;
                if (near_valley) v[n++] = fabs(img->data[k] - b.data[k]);
            }
        for (k = 1; k < n; k++) { /* insertion sort: a few thousand values */
            double t = v[k];
            size_t j = k;
            while (j > 0 && v[j - 1] > t) v[j] = v[j - 1], j--;
            v[j] = t;
        }
        if (n) med = v[n / 2];
    }
    free(v);
    tn_image_free(&r);
    tn_image_free(&b);
    return med;
}

TN_TEST(map_scale_level)
{
    /* a drawing over three times the example's side gets the map-scale level: the large scales
       from the drawing generated twice smaller, the detail faded on the drawn valley's floor as on
       the example's main valleys. Windows still equal the whole map, the strokes still hold
       (the issue's bounds: heights within 10 % of the range, 90 % followed), the output is not
       the one-level one, and a drawing within twice the example does not get the level */
    tn_image dem = tn_test_dem(64, 22), a = {0, 0, 0, NULL}, one = {0, 0, 0, NULL}, win = {0, 0, 0, NULL}, want = {0, 0, 0, NULL};
    tn_gnn m;
    tn_gnn_opts o;
    tn_gnn_generate_opts go;
    tn_gnn_plan plan;
    tn_contour_set user;
    float rp[30], vp[30], lo = 0, hi = 0;
    double err = 0, follow = 0, fa, fo;
    tn_image_range(&lo, &hi, &dem);
    tn_test_tiny_gnn_opts(&o, 3);
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_OK);
    user = two_strokes(240, 180, rp, vp);
    memset(&go, 0, sizeof go);
    go.seed = 2;
    TN_CHECK(tn_gnn_plan_of(&plan, &m, &user, 240, 180, &go) == TN_OK && plan.map_scale == 2);
    TN_CHECK(plan.floor_detail >= 0 && plan.floor_detail <= 1);
    printf("  map scale %d, floor detail %.2f\n", plan.map_scale, (double)plan.floor_detail);
    TN_CHECK(tn_gnn_generate(&a, &m, &user, 240, 180, &go) == TN_OK);
    TN_CHECK(tn_gnn_generate_window(&win, &m, &user, 240, 180, 150, 100, 60, 50, &go) == TN_OK);
    TN_CHECK(tn_image_crop(&want, &a, 150, 100, 60, 50) == TN_OK && same_image(&win, &want));
    tn_image_free(&win);
    tn_image_free(&want);
    TN_CHECK(tn_gnn_generate_window(&win, &m, &user, 240, 180, 0, 0, 37, 180, &go) == TN_OK); /* at the map's edge */
    TN_CHECK(tn_image_crop(&want, &a, 0, 0, 37, 180) == TN_OK && same_image(&win, &want));
    { /* one prepared generation: its windows are the same pixels */
        tn_gnn_prepared *P = NULL;
        TN_CHECK(tn_gnn_prepare(&P, &m, &user, 240, 180, &go) == TN_OK);
        { /* its plan is tn_gnn_plan_of's */
            const tn_gnn_plan *pp = tn_gnn_prepared_plan(P);
            TN_CHECK(pp->map_scale == plan.map_scale && pp->floor_detail == plan.floor_detail && pp->grown_lines == plan.grown_lines &&
                     pp->gain == plan.gain && pp->user_lines == plan.user_lines && !strcmp(pp->gain_why, plan.gain_why));
        }
        tn_image_free(&win);
        tn_image_free(&want);
        TN_CHECK(tn_gnn_prepared_window(&win, P, 100, 20, 90, 70) == TN_OK);
        TN_CHECK(tn_image_crop(&want, &a, 100, 20, 90, 70) == TN_OK && same_image(&win, &want));
        TN_CHECK(tn_gnn_prepared_window(&one, P, 200, 0, 41, 10) == TN_ERR_INVALID_ARG && strstr(tn_last_error(), "not inside"));
        tn_gnn_prepared_free(P);
        tn_gnn_prepared_free(NULL);
    }
    stroke_fit(&user, &a, &err, &follow);
    printf("  strokes: %.1f m from their heights (range %.0f m), %.1f %% followed\n", err, (double)(hi - lo), 100 * follow);
    TN_CHECK(err <= 0.1 * (hi - lo) && follow >= 0.9);
    go.map_scale = -1;
    TN_CHECK(tn_gnn_generate(&one, &m, &user, 240, 180, &go) == TN_OK && !same_image(&a, &one));
    fa = floor_detail(&user, &a), fo = floor_detail(&user, &one);
    printf("  detail on the valley's floor: %.2f m, one level %.2f m\n", fa, fo);
    if (plan.floor_detail < 0.9f) TN_CHECK(fa >= 0 && fa < fo);
    go.map_scale = 0;
    { /* the same strokes 100 px long on the same map: grown, within twice the example */
        int k;
        for (k = 0; k < 10; k++) rp[3 * k] = vp[3 * k] = 70.0f + 100.0f * (float)k / 9.0f;
        TN_CHECK(tn_gnn_plan_of(&plan, &m, &user, 240, 180, &go) == TN_OK);
        TN_CHECK(plan.grown_lines > 0 && plan.map_scale == 1 && strstr(plan.map_scale_why, "at most"));
        user = two_strokes(240, 180, rp, vp);
    }
    go.map_scale = 12; /* 20 x 15 for the large scales: refused */
    TN_CHECK(tn_gnn_generate(&one, &m, &user, 240, 180, &go) == TN_ERR_INVALID_ARG && strstr(tn_last_error(), "map scale 12"));
    go.map_scale = 65;
    TN_CHECK(tn_gnn_generate(&one, &m, &user, 240, 180, &go) == TN_ERR_INVALID_ARG);
    tn_image_free(&a);
    tn_image_free(&one);
    tn_image_free(&win);
    tn_image_free(&want);
    tn_gnn_free(&m);
    tn_image_free(&dem);
}

TN_TEST(drawing_off_the_example_level_is_seen_at_it)
{
    /* the network learnt the example's heights: given a drawing's ground above them it pulled
       the land beside the strokes down toward them, and the notch then dug a drawn valley below
       its asked height to keep it lowest. It now sees a ground that lies outside the example's
       levels moved to the nearest one, so a drawing wholly above the example raised by 20 % of
       the range more is the same terrain 20 % higher, to float rounding (7 m off in 1000 m
       without). Without the fine detail: its choice of patch can turn float rounding into
       another patch */
    tn_image dem = tn_test_dem(64, 22), a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_gnn m;
    tn_gnn_opts o;
    tn_gnn_generate_opts go;
    tn_contour_set user;
    float rp[30], vp[30], lo = 0, hi = 0;
    double dmax = 0;
    size_t q;
    int i, k;
    tn_image_range(&lo, &hi, &dem);
    tn_test_tiny_gnn_opts(&o, 3);
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_OK);
    memset(&go, 0, sizeof go);
    go.seed = 2;
    go.map_scale = -1;
    go.detail = -1;
    for (k = 0; k < 2; k++) {
        float shift = (k ? 1.2f : 1.0f) * (hi - lo);
        user = two_strokes(240, 180, rp, vp);
        for (i = 0; i < 10; i++) rp[3 * i + 2] += shift, vp[3 * i + 2] += shift;
        TN_CHECK(tn_gnn_generate(k ? &b : &a, &m, &user, 240, 180, &go) == TN_OK);
    }
    for (q = 0; a.data && b.data && q < (size_t)240 * 180; q++) dmax = fmax(dmax, fabs(b.data[q] - a.data[q] - 0.2 * (hi - lo)));
    printf("  raised by 20 %% of the range: at most %.3f m off 20 %% higher (range %.0f m)\n", dmax, (double)(hi - lo));
    TN_CHECK(a.data && b.data && dmax < 1e-3 * (hi - lo));
    tn_image_free(&a);
    tn_image_free(&b);
    tn_gnn_free(&m);
    tn_image_free(&dem);
}

TN_TEST(grown_generation)
{
    /* gnn generation of a drawing of two strokes: grown by default (the plan says how much and
       why the gain is what it is), not with grow = -1; the strokes' pixels keep their heights
       in the grown membrane; the same bytes on 1 and 2 threads */
    tn_image dem = tn_test_dem(64, 22), a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL}, mem = {0, 0, 0, NULL}, ur = {0, 0, 0, NULL};
    tn_gnn m;
    tn_gnn_opts o;
    tn_gnn_generate_opts go;
    tn_gnn_plan plan;
    tn_contour_set user, ex, grown;
    float rp[30], vp[30];
    int before = tn_get_threads();
    size_t q, n = 0;
    double err = 0;
    float dlo = 0, dhi = 0;
    tn_image_range(&dlo, &dhi, &dem);
    tn_test_tiny_gnn_opts(&o, 3);
    TN_CHECK(tn_gnn_train(&m, &dem, &o, NULL) == TN_OK);
    user = two_strokes(240, 180, rp, vp);
    memset(&go, 0, sizeof go);
    go.seed = 2;
    TN_CHECK(tn_gnn_plan_of(&plan, &m, &user, 240, 180, &go) == TN_OK);
    TN_CHECK(plan.grown_lines > 0 && plan.user_lines == 2 && plan.gain_why && strstr(plan.gain_why, "fewer than 8") && plan.gain == 1.0f);
    TN_CHECK(plan.user_density > 0 && plan.user_density < plan.example_density / 6);
    TN_CHECK(plan.detail == 1 && plan.detail_why && strstr(plan.detail_why, "fine detail"));
    TN_CHECK(plan.map_scale == 2 && strstr(plan.map_scale_why, "twice")); /* strokes 230 px long, the example 64 */
    go.map_scale = -1; /* the one-level generation from here on (map_scale_level tests the other) */
    go.grow = -1;
    TN_CHECK(tn_gnn_plan_of(&plan, &m, &user, 240, 180, &go) == TN_OK && plan.grown_lines == 0);
    TN_CHECK(plan.detail == 0 && strstr(plan.detail_why, "not grown"));
    go.grow = 0;
    go.detail = -1;
    TN_CHECK(tn_gnn_plan_of(&plan, &m, &user, 240, 180, &go) == TN_OK && plan.detail == 0);
    go.detail = 0;
    go.gain = -1;
    TN_CHECK(tn_gnn_plan_of(&plan, &m, &user, 240, 180, &go) == TN_OK && plan.gain == 0 && strstr(plan.gain_why, "membrane"));
    go.gain = 0;
    TN_CHECK(tn_gnn_generate(&a, &m, &user, 240, 180, &go) == TN_OK);
    tn_set_threads(1 + (before == 1));
    TN_CHECK(tn_gnn_generate(&b, &m, &user, 240, 180, &go) == TN_OK);
    tn_set_threads(before);
    TN_CHECK(same_image(&a, &b));
    /* with the fine detail by example (the default here), a window still equals the whole map */
    {
        tn_image win = {0, 0, 0, NULL}, want = {0, 0, 0, NULL}, plain = {0, 0, 0, NULL};
        tn_tensor *e = tn_params_find(m.weights, "detail.example");
        TN_CHECK(e && e->numel == (size_t)64 * 64 && e->data[0] == dem.data[0]);
        TN_CHECK(tn_gnn_generate_window(&win, &m, &user, 240, 180, 150, 100, 60, 50, &go) == TN_OK);
        TN_CHECK(tn_image_crop(&want, &a, 150, 100, 60, 50) == TN_OK && same_image(&win, &want));
        go.detail = -1;
        TN_CHECK(tn_gnn_generate(&plain, &m, &user, 240, 180, &go) == TN_OK && !same_image(&a, &plain));
        { /* the strokes keep their heights through the detail too (pinned again after it) */
            tn_image r = {0, 0, 0, NULL};
            double ea = 0, ep = 0;
            size_t k, nk = 0;
            TN_CHECK(tn_sketch_rasterise(&r, &user, 240, 180) == TN_OK);
            for (k = 0; r.data && k < (size_t)240 * 180; k++)
                if (r.data[3 * k] > 0 || r.data[3 * k + 1] > 0)
                    ea += fabs(a.data[k] - r.data[3 * k + 2]), ep += fabs(plain.data[k] - r.data[3 * k + 2]), nk++;
            printf("  strokes' height error with / without the detail: %.2f / %.2f m (example range %.0f m)\n", ea / (double)nk, ep / (double)nk, (double)(dhi - dlo));
            TN_CHECK(nk > 0 && ea <= ep + 0.02 * (dhi - dlo) * (double)nk);
            tn_image_free(&r);
        }
        { /* a valley drawn across a steep hillside (at the height the slope has there) is still the
             lowest ground 4 px across it: the notch cuts it in (44.6 % without it) */
            float hp[3][6];
            tn_contour hc[3];
            tn_contour_set hill = user;
            tn_image hi = {0, 0, 0, NULL};
            double share = 0;
            int k, j;
            for (k = 0; k < 3; k++) {
                for (j = 0; j < 2; j++) {
                    hp[k][3 * j] = k == 2 ? 60.0f + 120.0f * (float)j : 4.0f + 232.0f * (float)j;
                    hp[k][3 * j + 1] = k == 0 ? 70.0f : k == 1 ? 110.0f : 90.0f;
                    hp[k][3 * j + 2] = k == 0 ? 3000.0f : k == 1 ? 0.0f : 1500.0f;
                }
                memset(&hc[k], 0, sizeof hc[k]);
                hc[k].type = k == 0 ? TN_RIDGE : TN_VALLEY;
                hc[k].npoints = 2;
                hc[k].points = hp[k];
            }
            hill.count = 3;
            hill.items = hc;
            go.grow = 1; /* long strokes: denser than auto grows on this small example */
            TN_CHECK(tn_gnn_generate(&hi, &m, &hill, 240, 180, &go) == TN_OK);
            go.grow = 0;
            hill.count = 1;
            hill.items = &hc[2];
            TN_CHECK(tn_gnn_ordering(&share, &hill, &hi, 4, NULL) == TN_OK);
            printf("  a valley across a hillside: %.1f %% of its points below both sides 4 px across\n", 100 * share);
            TN_CHECK(share >= 0.95);
            { /* a lone ridge or valley on open ground keeps its height: the grown ground's fall
                 already gives it banks, so the notch cuts nothing (-21 m, 2 % of the range, when
                 it asked for more than that fall) */
                int s2;
                for (s2 = 0; s2 < 2; s2++) {
                    tn_contour_set one = user;
                    tn_image r = {0, 0, 0, NULL}, o1 = {0, 0, 0, NULL};
                    double e = 0, sh = 0;
                    size_t k2, nk = 0;
                    one.count = 1;
                    one.items = user.items + s2;
                    go.grow = 1;
                    TN_CHECK(tn_gnn_generate(&o1, &m, &one, 240, 180, &go) == TN_OK);
                    go.grow = 0;
                    TN_CHECK(tn_sketch_rasterise(&r, &one, 240, 180) == TN_OK);
                    for (k2 = 0; r.data && k2 < (size_t)240 * 180; k2++)
                        if (r.data[3 * k2] > 0 || r.data[3 * k2 + 1] > 0) e += o1.data[k2] - r.data[3 * k2 + 2], nk++;
                    TN_CHECK(tn_gnn_ordering(&sh, &one, &o1, 4, NULL) == TN_OK);
                    printf("  lone %s: bias %.1f m, follow %.1f %%\n", s2 ? "valley" : "ridge", e / (double)(nk ? nk : 1), 100 * sh);
                    TN_CHECK(nk > 0 && fabs(e / (double)nk) <= 0.01 * (dhi - dlo) && sh >= 0.95);
                    tn_image_free(&r);
                    tn_image_free(&o1);
                }
            }
            tn_image_free(&hi);
        }
        /* a model without the example's heights (trained before them): auto skips, 1 fails */
        if (e) strcpy(e->name, "detail.other");
        go.detail = 0;
        TN_CHECK(tn_gnn_plan_of(&plan, &m, &user, 240, 180, &go) == TN_OK && plan.detail == 0 && strstr(plan.detail_why, "no example"));
        go.detail = 1;
        TN_CHECK(tn_gnn_plan_of(&plan, &m, &user, 240, 180, &go) == TN_ERR_INVALID_ARG && strstr(tn_last_error(), "no example"));
        if (e) strcpy(e->name, "detail.example");
        go.detail = 0;
        tn_image_free(&win);
        tn_image_free(&want);
        tn_image_free(&plain);
    }
    /* the grown sketch's membrane holds every stroke pixel at its asked height */
    TN_CHECK(tn_gnn_parts(&ex, &m) == TN_OK);
    TN_CHECK(tn_gnn_grow(&grown, &user, &ex, 240, 180, NULL, NULL) == TN_OK);
    TN_CHECK(tn_gnn_membrane(&mem, &grown, 240, 180) == TN_OK && tn_sketch_rasterise(&ur, &user, 240, 180) == TN_OK);
    for (q = 0; q < (size_t)240 * 180; q++)
        if (ur.data[3 * q] > 0 || ur.data[3 * q + 1] > 0) err += fabs(mem.data[q] - ur.data[3 * q + 2]), n++;
    TN_CHECK(n > 100 && err / n < 1e-3);
    tn_image_free(&a);
    tn_image_free(&b);
    tn_image_free(&mem);
    tn_image_free(&ur);
    tn_contour_set_free(&ex);
    tn_contour_set_free(&grown);
    tn_gnn_free(&m);
    tn_image_free(&dem);
}

int main(void)
{
    TN_RUN(membrane_interpolates_between_lines);
    TN_RUN(membrane_solver_is_the_laplace_solution);
    TN_RUN(membrane_blocks_leave_no_seams);
    TN_RUN(membrane_far_blocks_stay_bounded);
    TN_RUN(training_lowers_the_loss_and_generates_metres);
    TN_RUN(shape_losses);
    TN_RUN(save_load_round_trip);
    TN_RUN(part_overhang);
    TN_RUN(embedding_phase);
    TN_RUN(resume_is_bit_identical);
    TN_RUN(holdout_early_stopping);
    TN_RUN(an_example_in_coarse_steps_is_trained_without_them);
    TN_RUN(training_reports_its_preparation_as_one_stage);
    TN_RUN(holdout_windows);
    TN_RUN(gain_scale_from_holdouts);
    TN_RUN(same_results_for_1_and_2_threads);
    TN_RUN(bad_inputs_fail_cleanly);
    TN_RUN(window_equals_whole_map);
    TN_RUN(finetune_in_windows);
    TN_RUN(residual_gain);
    TN_RUN(ordering_share);
    TN_RUN(grow_by_example);
    TN_RUN(grow_without_block_grid);
    TN_RUN(grown_sketch_drains);
    TN_RUN(drawn_valley_end_drains);
    TN_RUN(drawn_valley_is_the_low_ground);
    TN_RUN(drawn_valley_is_no_trench);
    TN_RUN(quilted_ground_has_no_seam_cliffs);
    TN_RUN(grown_basins_against_the_example_ground);
    TN_RUN(grow_fall_follows_the_example);
    TN_RUN(grow_crest_copies_the_example_relief);
    TN_RUN(grow_crest_widens_a_short_pool);
    TN_RUN(grow_crest_takes_the_example_bends);
    TN_RUN(grow_flanks_copy_the_example_flanks);
    TN_RUN(grow_flanks_without_streaks);
    TN_RUN(grown_strokes_stay_main_lines);
    TN_RUN(grown_spurs_keep_the_example_tilt);
    TN_RUN(grown_lines_keep_the_example_heights);
    TN_RUN(grown_ground_sinks_under_a_drawn_ring);
    TN_RUN(grown_ridge_flanks_are_its_own);
    TN_RUN(drawing_off_the_example_level_is_seen_at_it);
    TN_RUN(grown_generation);
    TN_RUN(drawn_ridge_is_a_crest);
    TN_RUN(bent_ridge_is_followed_where_drawn);
    TN_RUN(width_field_is_smooth);
    TN_RUN(example_fall_ratio_reads_the_lie_of_gullies);
    TN_RUN(grown_ground_erodes_down_its_slopes);
    TN_RUN(eroded_ground_keeps_the_example_steepness);
    TN_RUN(bundled_style_window_equals_whole_map);
    TN_RUN(bundled_styles_hold_their_example_without_steps);
    TN_RUN(detail_digs_no_groove_beside_a_drawn_ridge);
    TN_RUN(drawn_ridge_stays_above_cratered_detail);
    TN_RUN(drawn_valley_widens_downstream);
    TN_RUN(map_scale_level);
    return tn_test_summary("test_gnn");
}
