/* Tests of @@tensor, @@ops, @@loss and @@optim: finite-difference gradient checks for every op
   and loss, toy problems that must be learned, .tnw files, determinism across thread counts. */
#ifndef TN_TEST_TU
#include "terrainnet.h"
#else
#include TN_TEST_TU
#endif
#include "tn_test.h"

/* ---- gradient checking ---- */

typedef tn_tensor *(*build_fn)(tn_ctx *ctx, tn_tensor **in, const void *user);

/* loss = sum(f(in) * R) with a fixed random R, so every output element matters. */
static float gc_loss(tn_ctx *ctx, build_fn f, tn_tensor **in, const void *user, int backward)
{
    tn_tensor *out, *r, *loss;
    tn_rng rng;
    float v;
    tn_ctx_reset(ctx);
    out = f(ctx, in, user);
    if (!out) return (float)NAN;
    r = tn_tensor_new(ctx, out->ndim, out->shape);
    tn_rng_seed(&rng, 99, 1);
    tn_init_uniform(r, &rng, -1.0f, 1.0f);
    loss = tn_sum(ctx, tn_mul(ctx, out, r));
    v = loss->data[0];
    if (backward && tn_backward(ctx, loss) != TN_OK) return (float)NAN;
    return v;
}

/* Compares analytic and central-difference gradients on up to 24 elements of every input.
   Returns the worst scaled error. */
static double gradcheck(build_fn f, tn_tensor **in, int nin, const void *user, float h)
{
    tn_ctx *ctx = tn_ctx_create();
    double worst = 0;
    int i, k;
    tn_rng rng;
    tn_rng_seed(&rng, 5, 5);
    for (i = 0; i < nin; i++)
        if (in[i]->grad) memset(in[i]->grad, 0, in[i]->numel * sizeof(float));
    if (gc_loss(ctx, f, in, user, 1) != gc_loss(ctx, f, in, user, 0)) { /* deterministic forward */
        tn_ctx_free(ctx);
        return 1e9;
    }
    for (i = 0; i < nin; i++) {
        float *ana;
        if (!in[i]->grad) continue;
        ana = (float *)malloc(in[i]->numel * sizeof(float));
        memcpy(ana, in[i]->grad, in[i]->numel * sizeof(float));
        for (k = 0; k < 24 && k < (int)in[i]->numel; k++) {
            size_t e = in[i]->numel <= 24 ? (size_t)k : tn_rng_below(&rng, (uint32_t)in[i]->numel);
            float old = in[i]->data[e], lp, lm;
            double num, err;
            in[i]->data[e] = old + h;
            lp = gc_loss(ctx, f, in, user, 0);
            in[i]->data[e] = old - h;
            lm = gc_loss(ctx, f, in, user, 0);
            in[i]->data[e] = old;
            num = ((double)lp - lm) / (2.0 * h);
            err = fabs(num - ana[e]) / (1e-1 + fabs(num) + fabs(ana[e]));
            if (err > worst) worst = err;
            if (err > 0.02) fprintf(stderr, "  input %d elem %zu: analytic %.6g numeric %.6g\n", i, e, ana[e], num);
        }
        free(ana);
    }
    tn_ctx_free(ctx);
    return worst;
}

static tn_ctx *g_in; /* inputs live here */

static tn_tensor *input(int ndim, int a, int b, int c, int d, float lo, float hi, int seed)
{
    int shape[4];
    tn_tensor *t;
    tn_rng rng;
    shape[0] = a; shape[1] = b; shape[2] = c; shape[3] = d;
    t = tn_tensor_requires_grad(g_in, tn_tensor_new(g_in, ndim, shape));
    tn_rng_seed(&rng, (uint64_t)seed, 3);
    tn_init_uniform(t, &rng, lo, hi);
    return t;
}

/* Values bounded away from 0 (for relu/abs kinks and division). */
static tn_tensor *input_away0(int ndim, int a, int b, int c, int d, int seed)
{
    tn_tensor *t = input(ndim, a, b, c, d, 0.2f, 1.0f, seed);
    size_t i;
    for (i = 0; i < t->numel; i += 2) t->data[i] = -t->data[i];
    return t;
}

#define GC(name, f, nin, user, h) TN_CHECK_NEAR(gradcheck(f, in, nin, user, h), 0.0, 0.02)

static tn_tensor *b_add(tn_ctx *c, tn_tensor **in, const void *u) { (void)u; return tn_add(c, in[0], in[1]); }
static tn_tensor *b_sub(tn_ctx *c, tn_tensor **in, const void *u) { (void)u; return tn_sub(c, in[0], in[1]); }
static tn_tensor *b_mul(tn_ctx *c, tn_tensor **in, const void *u) { (void)u; return tn_mul(c, in[0], in[1]); }
static tn_tensor *b_div(tn_ctx *c, tn_tensor **in, const void *u) { (void)u; return tn_div(c, in[0], in[1]); }

TN_TEST(grad_elementwise_broadcast)
{
    tn_tensor *in[2];
    in[0] = input(4, 2, 3, 4, 5, -1, 1, 1);
    in[1] = input(4, 1, 3, 1, 1, -1, 1, 2);          /* per-channel */
    GC(add, b_add, 2, NULL, 1e-2f);
    GC(sub, b_sub, 2, NULL, 1e-2f);
    GC(mul, b_mul, 2, NULL, 1e-2f);
    in[1] = input(2, 4, 5, 1, 1, -1, 1, 3);          /* trailing dims */
    GC(mul2, b_mul, 2, NULL, 1e-2f);
    in[1] = input_away0(4, 2, 1, 4, 1, 4);            /* mixed stretch */
    GC(div, b_div, 2, NULL, 1e-3f);
    in[0] = input(1, 1, 1, 1, 1, -1, 1, 5);           /* scalar op tensor */
    in[1] = input(3, 2, 3, 4, 1, -1, 1, 6);
    GC(add_scalar, b_add, 2, NULL, 1e-2f);
}

static tn_tensor *b_unary(tn_ctx *c, tn_tensor **in, const void *u)
{
    switch (*(const int *)u) {
    case 0: return tn_relu(c, in[0]);
    case 1: return tn_leaky_relu(c, in[0], 0.2f);
    case 2: return tn_elu(c, in[0], 1.0f);
    case 3: return tn_tanh(c, in[0]);
    case 4: return tn_sigmoid(c, in[0]);
    case 5: return tn_softplus(c, in[0]);
    case 6: return tn_abs(c, in[0]);
    case 7: return tn_square(c, in[0]);
    case 8: return tn_pow_abs(c, in[0], 1.25f);
    default: return tn_scale_shift(c, in[0], -2.5f, 0.5f);
    }
}

TN_TEST(grad_unary)
{
    tn_tensor *in[1];
    int k;
    in[0] = input_away0(2, 6, 7, 1, 1, 7);
    for (k = 0; k < 10; k++) {
        double e = gradcheck(b_unary, in, 1, &k, 1e-2f);
        if (e > 0.02) fprintf(stderr, "  unary op %d\n", k);
        TN_CHECK(e <= 0.02);
    }
}

static tn_tensor *b_matmul(tn_ctx *c, tn_tensor **in, const void *u)
{
    const int *t = (const int *)u;
    return tn_matmul(c, in[0], in[1], t[0], t[1]);
}
static tn_tensor *b_linear(tn_ctx *c, tn_tensor **in, const void *u) { (void)u; return tn_linear(c, in[0], in[1], in[2]); }

TN_TEST(grad_matmul_linear)
{
    tn_tensor *in[3];
    int t[2], ta, tb;
    for (ta = 0; ta < 2; ta++)
        for (tb = 0; tb < 2; tb++) {
            t[0] = ta;
            t[1] = tb;
            in[0] = ta ? input(2, 5, 3, 1, 1, -1, 1, 8) : input(2, 3, 5, 1, 1, -1, 1, 8);
            in[1] = tb ? input(2, 4, 5, 1, 1, -1, 1, 9) : input(2, 5, 4, 1, 1, -1, 1, 9);
            GC(matmul, b_matmul, 2, t, 1e-2f);
        }
    in[0] = input(2, 6, 5, 1, 1, -1, 1, 10);
    in[1] = input(2, 3, 5, 1, 1, -1, 1, 11);
    in[2] = input(1, 3, 1, 1, 1, -1, 1, 12);
    GC(linear, b_linear, 3, NULL, 1e-2f);
}

static tn_tensor *b_reduce(tn_ctx *c, tn_tensor **in, const void *u)
{
    int k = *(const int *)u;
    if (k == 0) return tn_sum(c, in[0]);
    if (k == 1) return tn_mean(c, in[0]);
    if (k == 2) return tn_sum_axis(c, in[0], 1);
    return tn_mean_axis(c, in[0], 2);
}

static tn_tensor *b_shape(tn_ctx *c, tn_tensor **in, const void *u)
{
    int k = *(const int *)u, shape[2], perm[4];
    switch (k) {
    case 0: shape[0] = 6; shape[1] = 20; return tn_reshape(c, in[0], 2, shape);
    case 1: perm[0] = 0; perm[1] = 2; perm[2] = 3; perm[3] = 1; return tn_permute(c, in[0], perm);
    case 2: return tn_concat(c, in[0], in[1], 1);
    case 3: return tn_slice(c, in[0], 3, 1, 3);
    default: return tn_concat(c, in[0], in[1], 3);
    }
}

TN_TEST(grad_reduce_and_shape)
{
    tn_tensor *in[2];
    int k;
    in[0] = input(4, 2, 3, 4, 5, -1, 1, 13);
    for (k = 0; k < 4; k++) GC(reduce, b_reduce, 1, &k, 1e-2f);
    for (k = 0; k < 4; k++) {
        in[1] = input(4, 2, 2, 4, 5, -1, 1, 14);
        GC(shape, b_shape, k == 2 ? 2 : 1, &k, 1e-2f);
    }
    in[1] = input(4, 2, 3, 4, 2, -1, 1, 15);
    k = 4;
    GC(concat_w, b_shape, 2, &k, 1e-2f);
}

static tn_tensor *b_conv(tn_ctx *c, tn_tensor **in, const void *u)
{
    return tn_conv2d(c, in[0], in[1], in[2], (const tn_conv_opts *)u);
}
static tn_tensor *b_convt(tn_ctx *c, tn_tensor **in, const void *u)
{
    return tn_conv_transpose2d(c, in[0], in[1], in[2], (const tn_conv_opts *)u);
}

TN_TEST(grad_conv2d_variants)
{
    tn_tensor *in[3];
    tn_conv_opts o;
    int variant;
    for (variant = 0; variant < 6; variant++) {
        int k = variant == 4 ? 1 : 3;
        memset(&o, 0, sizeof o);
        if (variant == 1) { o.pad = 1; }
        if (variant == 2) { o.pad = 2; o.stride = 2; o.dilation = 2; }
        if (variant == 3) { o.pad = 2; o.padding = TN_PADDING_REFLECT; }
        if (variant == 5) { o.pad = 1; o.stride = 2; o.padding = TN_PADDING_REFLECT; }
        in[0] = input(4, 2, 3, 7, 6, -1, 1, 20 + variant);
        in[1] = input(4, 4, 3, k, k, -1, 1, 30 + variant);
        in[2] = input(1, 4, 1, 1, 1, -1, 1, 40 + variant);
        if (gradcheck(b_conv, in, 3, &o, 1e-2f) > 0.02) {
            fprintf(stderr, "  conv variant %d\n", variant);
            TN_CHECK(0);
        }
    }
    for (variant = 0; variant < 3; variant++) {
        memset(&o, 0, sizeof o);
        o.stride = variant + 1;
        o.pad = variant;
        o.output_padding = variant == 2 ? 1 : 0;
        in[0] = input(4, 2, 3, 4, 5, -1, 1, 50 + variant);
        in[1] = input(4, 3, 2, 5, 5, -1, 1, 60 + variant);
        in[2] = input(1, 2, 1, 1, 1, -1, 1, 70 + variant);
        if (gradcheck(b_convt, in, 3, &o, 1e-2f) > 0.02) {
            fprintf(stderr, "  conv transpose variant %d\n", variant);
            TN_CHECK(0);
        }
    }
}

/* A direct (7-loop) convolution to check the im2col path's values, not only its gradients. */
TN_TEST(conv2d_matches_direct_loops)
{
    tn_ctx *c = tn_ctx_create();
    tn_rng rng;
    tn_tensor *x = tn_tensor_4d(c, 2, 3, 9, 8), *w = tn_tensor_4d(c, 5, 3, 3, 3), *y;
    tn_conv_opts o;
    int n, co, oy, ox, ci, ky, kx;
    double worst = 0;
    tn_rng_seed(&rng, 1, 1);
    tn_init_uniform(x, &rng, -1, 1);
    tn_init_uniform(w, &rng, -1, 1);
    memset(&o, 0, sizeof o);
    o.pad = 1;
    o.stride = 2;
    y = tn_conv2d(c, x, w, NULL, &o);
    TN_CHECK(y->shape[2] == 5 && y->shape[3] == 4);
    for (n = 0; n < 2; n++)
        for (co = 0; co < 5; co++)
            for (oy = 0; oy < 5; oy++)
                for (ox = 0; ox < 4; ox++) {
                    double s = 0;
                    for (ci = 0; ci < 3; ci++)
                        for (ky = 0; ky < 3; ky++)
                            for (kx = 0; kx < 3; kx++) {
                                int iy = oy * 2 - 1 + ky, ix = ox * 2 - 1 + kx;
                                if (iy < 0 || ix < 0 || iy >= 9 || ix >= 8) continue;
                                s += x->data[((n * 3 + ci) * 9 + iy) * 8 + ix] * w->data[((co * 3 + ci) * 3 + ky) * 3 + kx];
                            }
                    s -= y->data[((n * 5 + co) * 5 + oy) * 4 + ox];
                    if (fabs(s) > worst) worst = fabs(s);
                }
    TN_CHECK(worst < 1e-4);
    tn_ctx_free(c);
}

static tn_tensor *b_pool(tn_ctx *c, tn_tensor **in, const void *u)
{
    switch (*(const int *)u) {
    case 0: return tn_avg_pool2d(c, in[0], 2, 2);
    case 1: return tn_max_pool2d(c, in[0], 3, 2);
    case 2: return tn_upsample_nearest(c, in[0], 2);
    default: return tn_upsample_bilinear(c, in[0], 11, 7);
    }
}

TN_TEST(grad_pool_upsample)
{
    tn_tensor *in[1];
    int k;
    in[0] = input(4, 2, 2, 6, 5, -1, 1, 80);
    for (k = 0; k < 4; k++) GC(pool, b_pool, 1, &k, 1e-3f);
}

static tn_tensor *b_norm(tn_ctx *c, tn_tensor **in, const void *u)
{
    int k = *(const int *)u;
    if (k == 0) return tn_batch_norm(c, in[0], in[1], in[2], NULL, NULL, 1, 1e-5f);
    if (k == 1) return tn_instance_norm(c, in[0], in[1], in[2], 1e-5f);
    return tn_spade_norm(c, in[0], in[3], in[4], 1e-5f);
}

TN_TEST(grad_norms)
{
    tn_tensor *in[5];
    int k;
    in[0] = input(4, 3, 2, 4, 3, -1, 2, 90);
    in[1] = input(1, 2, 1, 1, 1, 0.5f, 1.5f, 91);
    in[2] = input(1, 2, 1, 1, 1, -1, 1, 92);
    in[3] = input(4, 3, 2, 4, 3, -1, 1, 93);
    in[4] = input(4, 3, 2, 4, 3, -1, 1, 94);
    for (k = 0; k < 3; k++) GC(norm, b_norm, 5, &k, 1e-2f);
}

TN_TEST(batch_norm_eval_uses_running_stats)
{
    tn_ctx *c = tn_ctx_create();
    tn_tensor *x = tn_tensor_4d(c, 4, 1, 2, 2), *rm = tn_tensor_1d(c, 1), *rv = tn_tensor_1d(c, 1), *y;
    size_t i;
    for (i = 0; i < x->numel; i++) x->data[i] = (float)i;
    rv->data[0] = 1.0f;
    y = tn_batch_norm(c, x, NULL, NULL, rm, rv, 1, 1e-5f);
    TN_CHECK_NEAR(y->data[0], -7.5 / sqrt(21.25 + 1e-5), 1e-4); /* biased variance of 0..15 = 21.25 */
    TN_CHECK_NEAR(rm->data[0], 0.1 * 7.5, 1e-5);
    TN_CHECK_NEAR(rv->data[0], 0.9 + 0.1 * 21.25 * 16 / 15, 1e-4);
    y = tn_batch_norm(c, x, NULL, NULL, rm, rv, 0, 1e-5f);
    TN_CHECK_NEAR(y->data[3], (3 - 0.75) / sqrt(rv->data[0] + 1e-5), 1e-4);
    tn_ctx_free(c);
}

static tn_tensor *b_spectral(tn_ctx *c, tn_tensor **in, const void *u)
{
    tn_tensor *uvec = (tn_tensor *)u;
    tn_rng r;
    size_t i;
    tn_rng_seed(&r, 3, 3); /* fixed u so every evaluation is the same function */
    for (i = 0; i < uvec->numel; i++) uvec->data[i] = tn_rng_uniform(&r) + 0.1f;
    return tn_spectral_norm(c, in[0], uvec, 30);
}

TN_TEST(grad_spectral_norm)
{
    tn_tensor *in[1], *u;
    tn_ctx *c = tn_ctx_create();
    double s;
    in[0] = input(4, 4, 2, 3, 3, -1, 1, 95);
    u = tn_tensor_1d(g_in, 4);
    GC(spectral, b_spectral, 1, u, 1e-3f);
    /* the normalised matrix has spectral norm 1: check with a few power iterations of our own */
    {
        tn_tensor *wn = b_spectral(c, in, u);
        float v[18], w4[4];
        int it, r, k;
        for (k = 0; k < 18; k++) v[k] = 1.0f;
        for (it = 0; it < 100; it++) {
            for (r = 0; r < 4; r++) { w4[r] = 0; for (k = 0; k < 18; k++) w4[r] += wn->data[r * 18 + k] * v[k]; }
            s = 0;
            for (k = 0; k < 18; k++) { v[k] = 0; for (r = 0; r < 4; r++) v[k] += wn->data[r * 18 + k] * w4[r]; s += v[k] * v[k]; }
            s = sqrt(s);
            for (k = 0; k < 18; k++) v[k] = (float)(v[k] / s);
        }
        TN_CHECK_NEAR(sqrt(s), 1.0, 1e-3);
    }
    tn_ctx_free(c);
}

static const int g_idx[7] = {2, 0, 4, 4, 1, 3, 0};
static tn_tensor *b_graph(tn_ctx *c, tn_tensor **in, const void *u)
{
    int k = *(const int *)u;
    if (k == 0) return tn_gather_rows(c, in[0], g_idx, 7);
    if (k == 1) return tn_scatter_add_rows(c, in[1], g_idx, 5);
    if (k == 2) return tn_segment_softmax(c, in[1], g_idx, 5);
    {
        tn_rng r;
        tn_rng_seed(&r, 4, 4);
        return tn_gumbel_softmax(c, in[1], 0.7f, &r);
    }
}

TN_TEST(grad_graph_ops)
{
    tn_tensor *in[2];
    int k;
    in[0] = input(2, 5, 3, 1, 1, -1, 1, 96);
    in[1] = input(2, 7, 3, 1, 1, -1, 1, 97);
    for (k = 0; k < 4; k++) GC(graph, b_graph, 2, &k, 1e-2f);
}

TN_TEST(segment_softmax_sums_to_one)
{
    tn_ctx *c = tn_ctx_create();
    tn_tensor *s = tn_tensor_2d(c, 7, 2), *y;
    double sum[5][2];
    int e, h;
    for (e = 0; e < 14; e++) s->data[e] = (float)((e * 7) % 5) - 2.0f;
    y = tn_segment_softmax(c, s, g_idx, 5);
    memset(sum, 0, sizeof sum);
    for (e = 0; e < 7; e++)
        for (h = 0; h < 2; h++) sum[g_idx[e]][h] += y->data[e * 2 + h];
    for (e = 0; e < 5; e++)
        for (h = 0; h < 2; h++) TN_CHECK_NEAR(sum[e][h], 1.0, 1e-5);
    tn_ctx_free(c);
}

static tn_tensor *b_loss(tn_ctx *c, tn_tensor **in, const void *u)
{
    switch (*(const int *)u) {
    case 0: return tn_mse_loss(c, in[0], in[1]);
    case 1: return tn_l1_loss(c, in[0], in[1]);
    case 2: return tn_bce_logits_loss(c, in[0], in[2]);
    case 3: return tn_hinge_d_loss(c, in[0], in[1]);
    case 4: return tn_hinge_g_loss(c, in[0]);
    case 5: return tn_gram(c, in[0], 0.1f);
    case 6: return tn_tv_loss(c, in[0], 2.5f);
    case 7: return tn_gdl_loss(c, in[0], in[1]);
    case 8: return tn_ssim_loss(c, in[3], in[4], 1.0f);
    default: {
        tn_rng r;
        tn_rng_seed(&r, 2, 2);
        return tn_dropout(c, in[0], 0.3f, 1, &r);
    }
    }
}

TN_TEST(grad_losses)
{
    tn_tensor *in[5];
    int k;
    in[0] = input(4, 2, 2, 5, 4, -1, 1, 100);
    in[1] = input(4, 2, 2, 5, 4, -1, 1, 101);
    in[2] = input(4, 2, 2, 5, 4, 0, 1, 102);
    in[3] = input(4, 1, 2, 13, 12, 0, 1, 103);
    in[4] = input(4, 1, 2, 13, 12, 0, 1, 104);
    for (k = 0; k < 10; k++) {
        double e = gradcheck(b_loss, in, 5, &k, k == 8 ? 2e-3f : 1e-3f);
        if (e > 0.02) fprintf(stderr, "  loss %d\n", k);
        TN_CHECK(e <= 0.02);
    }
}

TN_TEST(ssim_loss_is_zero_for_identical)
{
    tn_ctx *c = tn_ctx_create();
    tn_tensor *x = tn_tensor_4d(c, 1, 1, 16, 16), *l;
    size_t i;
    for (i = 0; i < x->numel; i++) x->data[i] = (float)sin((double)i * 0.3);
    l = tn_ssim_loss(c, x, x, 2.0f);
    TN_CHECK_NEAR(l->data[0], 0.0, 1e-5);
    tn_ctx_free(c);
}

/* ---- learning ---- */

/* A 2-16-1 MLP learns XOR-like quadrants with Adam. */
TN_TEST(mlp_overfits_toy_task)
{
    tn_params *p = tn_params_create();
    int s1[2] = {16, 2}, s2[2] = {1, 16}, b1s = 16, b2s = 1, step, i;
    tn_tensor *w1 = tn_params_add(p, "w1", 2, s1), *b1 = tn_params_add(p, "b1", 1, &b1s);
    tn_tensor *w2 = tn_params_add(p, "w2", 2, s2), *b2 = tn_params_add(p, "b2", 1, &b2s);
    tn_ctx *c = tn_ctx_create();
    tn_optim_opts oo;
    tn_optim *opt;
    tn_rng rng;
    float first = 0, last = 0;
    size_t used_after_warmup = 0;
    tn_rng_seed(&rng, 7, 7);
    tn_init_kaiming(w1, &rng, 1.0f);
    tn_init_kaiming(w2, &rng, 1.0f);
    memset(&oo, 0, sizeof oo);
    oo.lr = 0.02f;
    opt = tn_optim_create(p, &oo);
    for (step = 0; step < 400; step++) {
        tn_tensor *x, *t, *loss;
        tn_ctx_reset(c);
        x = tn_tensor_2d(c, 32, 2);
        t = tn_tensor_2d(c, 32, 1);
        for (i = 0; i < 32; i++) {
            float a = tn_rng_uniform(&rng) * 2 - 1, b = tn_rng_uniform(&rng) * 2 - 1;
            x->data[2 * i] = a;
            x->data[2 * i + 1] = b;
            t->data[i] = (a * b > 0) ? 1.0f : 0.0f;
        }
        loss = tn_bce_logits_loss(c, tn_linear(c, tn_tanh(c, tn_linear(c, x, w1, b1)), w2, b2), t);
        tn_params_zero_grad(p);
        TN_CHECK(tn_backward(c, loss) == TN_OK);
        tn_optim_step(opt);
        if (step == 0) first = loss->data[0];
        last = loss->data[0];
        if (step == 10) used_after_warmup = tn_ctx_used(c);
        if (step > 10) TN_CHECK(tn_ctx_used(c) == used_after_warmup);
    }
    TN_CHECK(first > 0.6f);
    TN_CHECK(last < 0.25f);
    tn_optim_free(opt);
    tn_params_free(p);
    tn_ctx_free(c);
}

/* A small CNN learns to reproduce a fixed 3x3 edge filter from random images. */
TN_TEST(cnn_overfits_toy_task)
{
    tn_params *p = tn_params_create();
    int s1[4] = {8, 1, 3, 3}, s2[4] = {1, 8, 1, 1}, nb = 8, one = 1, step;
    tn_tensor *w1 = tn_params_add(p, "conv1.w", 4, s1), *b1 = tn_params_add(p, "conv1.b", 1, &nb);
    tn_tensor *w2 = tn_params_add(p, "conv2.w", 4, s2), *b2 = tn_params_add(p, "conv2.b", 1, &one);
    tn_ctx *c = tn_ctx_create();
    tn_optim_opts oo;
    tn_optim *opt;
    tn_rng rng;
    tn_conv_opts co;
    float first = 0, last = 0;
    static const float edge[9] = {1, 0, -1, 2, 0, -2, 1, 0, -1};
    tn_rng_seed(&rng, 8, 8);
    tn_init_kaiming(w1, &rng, 1.0f);
    tn_init_kaiming(w2, &rng, 1.0f);
    memset(&oo, 0, sizeof oo);
    oo.lr = 0.01f;
    opt = tn_optim_create(p, &oo);
    memset(&co, 0, sizeof co);
    co.pad = 1;
    for (step = 0; step < 300; step++) {
        tn_tensor *x, *k, *t, *y, *loss;
        tn_ctx_reset(c);
        x = tn_tensor_4d(c, 4, 1, 12, 12);
        k = tn_tensor_4d(c, 1, 1, 3, 3);
        memcpy(k->data, edge, sizeof edge);
        tn_init_uniform(x, &rng, -1, 1);
        t = tn_conv2d(c, x, k, NULL, &co);
        y = tn_conv2d(c, tn_leaky_relu(c, tn_conv2d(c, x, w1, b1, &co), 0.1f), w2, b2, NULL);
        loss = tn_mse_loss(c, y, t);
        tn_params_zero_grad(p);
        TN_CHECK(tn_backward(c, loss) == TN_OK);
        tn_optim_step(opt);
        if (step == 0) first = loss->data[0];
        last = loss->data[0];
    }
    TN_CHECK(last < 0.02f * first);
    tn_optim_free(opt);
    tn_params_free(p);
    tn_ctx_free(c);
}

TN_TEST(sgd_momentum_with_decay)
{
    tn_params *p = tn_params_create();
    int one = 1;
    tn_tensor *x = tn_params_add(p, "x", 1, &one);
    tn_optim_opts oo;
    tn_optim *opt;
    int i;
    memset(&oo, 0, sizeof oo);
    oo.kind = TN_OPTIM_SGD;
    oo.lr = 0.1f;
    oo.momentum = 0.5f;
    oo.lr_decay = 0.5f;
    oo.decay_every = 10;
    opt = tn_optim_create(p, &oo);
    x->data[0] = 3.0f;
    for (i = 0; i < 60; i++) {
        x->grad[0] = 2.0f * (x->data[0] - 1.0f); /* d/dx (x-1)^2 */
        tn_optim_step(opt);
    }
    TN_CHECK_NEAR(x->data[0], 1.0, 1e-3);
    TN_CHECK_NEAR(tn_optim_lr(opt), 0.1 * pow(0.5, 6), 1e-7);
    tn_optim_free(opt);
    tn_params_free(p);
}

static float rosenbrock(void *u, const float *x, float *g)
{
    (void)u;
    g[0] = -2.0f * (1 - x[0]) - 400.0f * x[0] * (x[1] - x[0] * x[0]);
    g[1] = 200.0f * (x[1] - x[0] * x[0]);
    return (1 - x[0]) * (1 - x[0]) + 100.0f * (x[1] - x[0] * x[0]) * (x[1] - x[0] * x[0]);
}

TN_TEST(lbfgs_solves_rosenbrock)
{
    float x[2] = {-1.2f, 1.0f}, f = 0;
    tn_lbfgs_opts o;
    memset(&o, 0, sizeof o);
    o.max_iter = 200;
    TN_CHECK(tn_lbfgs(x, 2, rosenbrock, NULL, &o, &f) == TN_OK);
    TN_CHECK_NEAR(x[0], 1.0, 1e-2);
    TN_CHECK_NEAR(x[1], 1.0, 2e-2);
    TN_CHECK(f < 1e-4f);
}

TN_TEST(gradient_clipping)
{
    tn_params *p = tn_params_create();
    int two = 2;
    tn_tensor *x = tn_params_add(p, "x", 1, &two);
    x->grad[0] = 3;
    x->grad[1] = 4;
    TN_CHECK_NEAR(tn_params_clip_grad(p, 1.0f), 5.0, 1e-5);
    TN_CHECK_NEAR(x->grad[0], 0.6, 1e-4);
    TN_CHECK_NEAR(x->grad[1], 0.8, 1e-4);
    tn_params_free(p);
}

/* The documented Lipschitz control: spectral-normalised discriminator + hinge loss. A tiny GAN
   must move its samples onto a 2-D Gaussian and stay stable (no NaN, bounded losses). */
TN_TEST(gan_with_spectral_norm_and_hinge_trains_stably)
{
    tn_params *gp = tn_params_create(), *dp = tn_params_create();
    int g1[2] = {16, 4}, g2[2] = {2, 16}, d1[2] = {32, 2}, d2[2] = {1, 32}, n16 = 16, n2 = 2, n32 = 32, n1 = 1;
    tn_tensor *gw1 = tn_params_add(gp, "g.w1", 2, g1), *gb1 = tn_params_add(gp, "g.b1", 1, &n16);
    tn_tensor *gw2 = tn_params_add(gp, "g.w2", 2, g2), *gb2 = tn_params_add(gp, "g.b2", 1, &n2);
    tn_tensor *dw1 = tn_params_add(dp, "d.w1", 2, d1), *db1 = tn_params_add(dp, "d.b1", 1, &n32);
    tn_tensor *dw2 = tn_params_add(dp, "d.w2", 2, d2), *db2 = tn_params_add(dp, "d.b2", 1, &n1);
    tn_tensor *du1 = tn_params_add_buffer(dp, "d.u1", 1, &n32), *du2 = tn_params_add_buffer(dp, "d.u2", 1, &n1);
    tn_optim_opts oo;
    tn_optim *og, *od;
    tn_ctx *c = tn_ctx_create();
    tn_rng rng;
    int step, i, bad = 0;
    double mx = 0, my = 0, worst_d = 0;
    tn_rng_seed(&rng, 21, 1);
    tn_init_kaiming(gw1, &rng, 1.0f);
    tn_init_kaiming(gw2, &rng, 1.0f);
    tn_init_kaiming(dw1, &rng, 1.0f);
    tn_init_kaiming(dw2, &rng, 1.0f);
    tn_tensor_fill(du1, 1.0f);
    tn_tensor_fill(du2, 1.0f);
    memset(&oo, 0, sizeof oo);
    oo.lr = 2e-3f;
    oo.beta1 = 0.5f;
    oo.beta2 = 0.9f;
    og = tn_optim_create(gp, &oo);
    od = tn_optim_create(dp, &oo);
    for (step = 0; step < 800; step++) {
        tn_tensor *z, *real, *fake, *ld, *lg;
        tn_tensor *w1n, *w2n;
        /* discriminator step */
        tn_ctx_reset(c);
        z = tn_tensor_2d(c, 64, 4);
        real = tn_tensor_2d(c, 64, 2);
        tn_init_normal(z, &rng, 0, 1);
        for (i = 0; i < 64; i++) {
            real->data[2 * i] = 2.0f + 0.3f * tn_rng_normal(&rng);
            real->data[2 * i + 1] = -1.0f + 0.3f * tn_rng_normal(&rng);
        }
        fake = tn_linear(c, tn_leaky_relu(c, tn_linear(c, z, gw1, gb1), 0.2f), gw2, gb2);
        w1n = tn_spectral_norm(c, dw1, du1, 1);
        w2n = tn_spectral_norm(c, dw2, du2, 1);
        ld = tn_hinge_d_loss(c, tn_linear(c, tn_leaky_relu(c, tn_linear(c, real, w1n, db1), 0.2f), w2n, db2),
                             tn_linear(c, tn_leaky_relu(c, tn_linear(c, fake, w1n, db1), 0.2f), w2n, db2));
        tn_params_zero_grad(dp);
        tn_params_zero_grad(gp);
        if (tn_backward(c, ld) != TN_OK || ld->data[0] != ld->data[0]) bad++;
        tn_optim_step(od);
        if (step > 100 && ld->data[0] > worst_d) worst_d = ld->data[0];
        /* generator step */
        tn_ctx_reset(c);
        z = tn_tensor_2d(c, 64, 4);
        tn_init_normal(z, &rng, 0, 1);
        fake = tn_linear(c, tn_leaky_relu(c, tn_linear(c, z, gw1, gb1), 0.2f), gw2, gb2);
        w1n = tn_spectral_norm(c, dw1, du1, 1);
        w2n = tn_spectral_norm(c, dw2, du2, 1);
        lg = tn_hinge_g_loss(c, tn_linear(c, tn_leaky_relu(c, tn_linear(c, fake, w1n, db1), 0.2f), w2n, db2));
        tn_params_zero_grad(gp);
        if (tn_backward(c, lg) != TN_OK || lg->data[0] != lg->data[0]) bad++;
        tn_optim_step(og);
        if (step >= 700)
            for (i = 0; i < 64; i++) {
                mx += fake->data[2 * i] / (100.0 * 64);
                my += fake->data[2 * i + 1] / (100.0 * 64);
            }
    }
    TN_CHECK(bad == 0);
    TN_CHECK(worst_d < 2.5); /* hinge D loss starts at ~2 and must not blow up */
    TN_CHECK_NEAR(mx, 2.0, 0.3);
    TN_CHECK_NEAR(my, -1.0, 0.3);
    tn_optim_free(og);
    tn_optim_free(od);
    tn_params_free(gp);
    tn_params_free(dp);
    tn_ctx_free(c);
}

/* ---- .tnw files ---- */

static tn_params *make_model(float seed)
{
    tn_params *p = tn_params_create();
    int s[4] = {3, 2, 2, 2}, nb = 3;
    tn_tensor *w = tn_params_add(p, "conv.weight", 4, s), *b = tn_params_add(p, "conv.bias", 1, &nb);
    tn_tensor *rm = tn_params_add_buffer(p, "bn.running_mean", 1, &nb);
    size_t i;
    for (i = 0; i < w->numel; i++) w->data[i] = seed + (float)i * 0.5f;
    for (i = 0; i < 3; i++) b->data[i] = rm->data[i] = seed - (float)i;
    return p;
}

TN_TEST(tnw_round_trip_and_errors)
{
    const char *path = "build/test/model.tnw";
    tn_params *a = make_model(1.0f), *b = make_model(0.0f), *c;
    uint8_t *buf = NULL;
    size_t n = 0, i;
    FILE *f;
    int s2[4] = {3, 2, 3, 2}, nb = 3;
    TN_CHECK(tn_params_save(path, a) == TN_OK);
    TN_CHECK(tn_params_load(b, path) == TN_OK);
    for (i = 0; i < 24; i++) TN_CHECK(tn_params_find(b, "conv.weight")->data[i] == 1.0f + (float)i * 0.5f);
    TN_CHECK(tn_params_find(b, "bn.running_mean")->data[2] == -1.0f);
    /* read the bytes back and damage them */
    f = fopen(path, "rb");
    TN_CHECK(f != NULL);
    if (!f) return;
    fseek(f, 0, SEEK_END);
    n = (size_t)ftell(f);
    fseek(f, 0, SEEK_SET);
    buf = (uint8_t *)malloc(n);
    TN_CHECK(fread(buf, 1, n, f) == n);
    fclose(f);
    TN_CHECK(n == 12 + (2 + 11 + 2 + 16 + 96) + (2 + 9 + 2 + 4 + 12) + (2 + 15 + 2 + 4 + 12) + 4);
    buf[40] ^= 1;
    TN_CHECK(tn_params_load_memory(b, buf, n, "x.tnw") == TN_ERR_CORRUPT);
    TN_CHECK(strstr(tn_last_error(), "CRC") != NULL);
    buf[40] ^= 1;
    for (i = 0; i < n; i += 7) TN_CHECK(tn_params_load_memory(b, buf, i, "x.tnw") != TN_OK); /* truncations */
    memcpy(buf, "XXXX", 4);
    TN_CHECK(tn_params_load_memory(b, buf, n, "x.tnw") == TN_ERR_FORMAT);
    /* shape mismatch names the tensor; nothing is changed */
    c = tn_params_create();
    tn_params_add(c, "conv.weight", 4, s2);
    tn_params_add(c, "conv.bias", 1, &nb);
    tn_params_add_buffer(c, "bn.running_mean", 1, &nb);
    TN_CHECK(tn_params_load(c, path) == TN_ERR_SHAPE);
    TN_CHECK(strstr(tn_last_error(), "conv.weight") != NULL);
    TN_CHECK(tn_params_find(c, "conv.bias")->data[0] == 0.0f);
    TN_CHECK(tn_params_load(c, "build/test/does_not_exist.tnw") == TN_ERR_IO);
    free(buf);
    tn_params_free(a);
    tn_params_free(b);
    tn_params_free(c);
}

/* ---- determinism ---- */

static void conv_net_grads(int threads, float *out, size_t n)
{
    tn_ctx *c = tn_ctx_create();
    tn_rng rng;
    tn_tensor *x, *w, *y, *loss;
    tn_conv_opts co;
    tn_set_threads(threads);
    tn_rng_seed(&rng, 11, 1);
    x = tn_tensor_requires_grad(c, tn_tensor_4d(c, 2, 16, 40, 36));
    w = tn_tensor_requires_grad(c, tn_tensor_4d(c, 24, 16, 3, 3));
    tn_init_uniform(x, &rng, -1, 1);
    tn_init_uniform(w, &rng, -1, 1);
    memset(&co, 0, sizeof co);
    co.pad = 1;
    y = tn_conv2d(c, x, w, NULL, &co);
    loss = tn_mean(c, tn_square(c, tn_relu(c, tn_batch_norm(c, y, NULL, NULL, NULL, NULL, 1, 1e-5f))));
    tn_backward(c, loss);
    memcpy(out, w->grad, n * sizeof(float));
    memcpy(out + n, x->grad, n * sizeof(float));
    out[2 * n] = loss->data[0];
    tn_ctx_free(c);
    tn_set_threads(0);
}

TN_TEST(bit_identical_for_1_and_2_threads)
{
    size_t n = 24 * 16 * 9;
    float *a = (float *)malloc((2 * n + 1) * sizeof(float)), *b = (float *)malloc((2 * n + 1) * sizeof(float));
    conv_net_grads(1, a, n);
    conv_net_grads(2, b, n);
    TN_CHECK(memcmp(a, b, (2 * n + 1) * sizeof(float)) == 0);
    free(a);
    free(b);
}

TN_TEST(arena_reuses_memory_after_reset)
{
    tn_ctx *c = tn_ctx_create();
    int i;
    size_t first = 0;
    for (i = 0; i < 5; i++) {
        tn_ctx_reset(c);
        TN_CHECK(tn_tensor_4d(c, 1, 64, 128, 128) != NULL); /* 4 MiB: needs more than one block */
        TN_CHECK(tn_tensor_4d(c, 1, 64, 128, 128) != NULL);
        if (i == 0) first = tn_ctx_used(c);
        TN_CHECK(tn_ctx_used(c) == first);
    }
    TN_CHECK(tn_ctx_status(c) == TN_OK);
    tn_ctx_free(c);
}

int main(void)
{
    g_in = tn_ctx_create();
    TN_RUN(grad_elementwise_broadcast);
    TN_RUN(grad_unary);
    TN_RUN(grad_matmul_linear);
    TN_RUN(grad_reduce_and_shape);
    TN_RUN(grad_conv2d_variants);
    TN_RUN(conv2d_matches_direct_loops);
    TN_RUN(grad_pool_upsample);
    TN_RUN(grad_norms);
    TN_RUN(batch_norm_eval_uses_running_stats);
    TN_RUN(grad_spectral_norm);
    TN_RUN(grad_graph_ops);
    TN_RUN(segment_softmax_sums_to_one);
    TN_RUN(grad_losses);
    TN_RUN(ssim_loss_is_zero_for_identical);
    TN_RUN(mlp_overfits_toy_task);
    TN_RUN(cnn_overfits_toy_task);
    TN_RUN(sgd_momentum_with_decay);
    TN_RUN(lbfgs_solves_rosenbrock);
    TN_RUN(gradient_clipping);
    TN_RUN(gan_with_spectral_norm_and_hinge_trains_stably);
    TN_RUN(tnw_round_trip_and_errors);
    TN_RUN(bit_identical_for_1_and_2_threads);
    TN_RUN(arena_reuses_memory_after_reset);
    tn_ctx_free(g_in);
    return tn_test_summary("test_tensor");
}
