/* test_conv_par: conv2d and transposed conv2d forward, input, weight and bias gradients against
   direct loops (kernel 1/3/5, stride 1/2, dilation 2, zero and reflect padding, Cin < 8 and >= 8,
   batch 2, odd sizes; both the flipped-kernel and the col2im input-gradient paths), and bit
   identity of every result between 1 and 2 threads. */
#include "terrainnet.h"
#include "tn_test.h"

typedef struct conv_case {
    int n, cin, cout, h, w, k, stride, pad, dil, reflect, transposed, out_pad;
} conv_case;

/* Source index of output o, tap k along an axis of `size`; -1 = zero padding. */
static int src_index(int o, int k, const conv_case *c, int size)
{
    int i = o * c->stride - c->pad + k * c->dil;
    if (i >= 0 && i < size) return i;
    if (!c->reflect) return -1;
    while (i < 0 || i >= size) i = i < 0 ? -i : 2 * (size - 1) - i;
    return i;
}

typedef struct conv_result { float *y, *dx, *dw, *db; size_t ny, nx, nw, nb; } conv_result;

/* Runs the op with loss = sum(y * r) (so dy = r) on `threads` threads and copies the results. */
static int run_op(const conv_case *cc, int threads, conv_result *res, tn_tensor **r_out, tn_ctx *keep)
{
    tn_ctx *c = tn_ctx_create();
    tn_rng rng;
    tn_conv_opts o;
    tn_tensor *x, *w, *b, *y, *r;
    int wshape0 = cc->transposed ? cc->cin : cc->cout, wshape1 = cc->transposed ? cc->cout : cc->cin;
    tn_set_threads(threads);
    tn_rng_seed(&rng, 5, 3);
    x = tn_tensor_requires_grad(c, tn_tensor_4d(c, cc->n, cc->cin, cc->h, cc->w));
    w = tn_tensor_requires_grad(c, tn_tensor_4d(c, wshape0, wshape1, cc->k, cc->k));
    b = tn_tensor_requires_grad(c, tn_tensor_1d(c, cc->cout));
    tn_init_uniform(x, &rng, -1, 1);
    tn_init_uniform(w, &rng, -1, 1);
    tn_init_uniform(b, &rng, -1, 1);
    memset(&o, 0, sizeof o);
    o.stride = cc->stride;
    o.pad = cc->pad;
    o.dilation = cc->dil;
    o.padding = cc->reflect ? TN_PADDING_REFLECT : TN_PADDING_ZERO;
    o.output_padding = cc->out_pad;
    y = cc->transposed ? tn_conv_transpose2d(c, x, w, b, &o) : tn_conv2d(c, x, w, b, &o);
    if (!y) return 0;
    r = tn_tensor_new(c, 4, y->shape);
    tn_init_uniform(r, &rng, -1, 1);
    if (tn_backward(c, tn_sum(c, tn_mul(c, y, r))) != TN_OK) return 0;
    res->ny = y->numel; res->nx = x->numel; res->nw = w->numel; res->nb = b->numel;
    res->y = (float *)malloc(sizeof(float) * (res->ny + res->nx + res->nw + res->nb));
    res->dx = res->y + res->ny;
    res->dw = res->dx + res->nx;
    res->db = res->dw + res->nw;
    memcpy(res->y, y->data, res->ny * sizeof(float));
    memcpy(res->dx, x->grad, res->nx * sizeof(float));
    memcpy(res->dw, w->grad, res->nw * sizeof(float));
    memcpy(res->db, b->grad, res->nb * sizeof(float));
    if (r_out) { /* copies of x, w, b, r for the reference, in `keep` */
        r_out[0] = tn_tensor_new(keep, 4, x->shape);
        r_out[1] = tn_tensor_new(keep, 4, w->shape);
        r_out[2] = tn_tensor_new(keep, 1, b->shape);
        r_out[3] = tn_tensor_new(keep, 4, r->shape);
        memcpy(r_out[0]->data, x->data, x->numel * sizeof(float));
        memcpy(r_out[1]->data, w->data, w->numel * sizeof(float));
        memcpy(r_out[2]->data, b->data, b->numel * sizeof(float));
        memcpy(r_out[3]->data, r->data, r->numel * sizeof(float));
    }
    tn_ctx_free(c);
    tn_set_threads(0);
    return 1;
}

/* Direct loops in double: a conv with input `big` (C channels, H x W) and output `small`
   (M channels, OH x OW), weight index (m, c) (a transposed conv's Cin x Cout kernel is M x C). For
   conv2d big = x, small = y; for the transposed conv big = y, small = x. Accumulates
   y_small += conv(big) or big += conv^T(small), per `adjoint`. */
static void direct(const conv_case *cc, int C, int H, int W, int M, int OH, int OW, const double *wt,
                   double *big, double *small, int adjoint)
{
    int n, m, c, oy, ox, ky, kx;
    for (n = 0; n < cc->n; n++)
        for (m = 0; m < M; m++)
            for (oy = 0; oy < OH; oy++)
                for (ox = 0; ox < OW; ox++) {
                    double *s = small + (((size_t)n * M + m) * OH + oy) * OW + ox;
                    for (c = 0; c < C; c++)
                        for (ky = 0; ky < cc->k; ky++)
                            for (kx = 0; kx < cc->k; kx++) {
                                int iy = src_index(oy, ky, cc, H), ix = src_index(ox, kx, cc, W);
                                double wv = wt[(((size_t)m * C + c) * cc->k + ky) * cc->k + kx];
                                double *bv;
                                if (iy < 0 || ix < 0) continue;
                                bv = big + (((size_t)n * C + c) * H + iy) * W + ix;
                                if (adjoint) *bv += wv * *s;
                                else *s += wv * *bv;
                            }
                }
}

static double max_diff(const float *a, const double *b, size_t n)
{
    double worst = 0;
    size_t i;
    for (i = 0; i < n; i++)
        if (fabs(a[i] - b[i]) > worst) worst = fabs(a[i] - b[i]);
    return worst;
}

/* Checks one case; returns the worst absolute error against the direct loops, or 1e9 on mismatch
   between thread counts / failure. */
static double check_case(const conv_case *cc)
{
    tn_ctx *keep = tn_ctx_create();
    tn_tensor *in[4];
    conv_result r1, r2;
    double worst = 0, *xd, *yd, *dwd, *dbd, *rd, *wd;
    int OH, OW, n, m, c, oy, ox, ky, kx, t, M, C, H, W;
    size_t i, ny, nx, nw;
    if (!run_op(cc, 1, &r1, in, keep) || !run_op(cc, 2, &r2, NULL, NULL)) return 1e9;
    if (memcmp(r1.y, r2.y, (r1.ny + r1.nx + r1.nw + r1.nb) * sizeof(float)) != 0) {
        fprintf(stderr, "  1 vs 2 threads differ\n");
        worst = 1e9;
    }
    OH = in[3]->shape[2];
    OW = in[3]->shape[3];
    ny = r1.ny; nx = r1.nx; nw = r1.nw;
    xd = (double *)calloc(nx + 2 * ny + 2 * nw + nx, sizeof(double));
    yd = xd + nx; rd = yd + ny; dwd = rd + ny; wd = dwd + nw; dbd = wd + nw;
    (void)dbd;
    for (i = 0; i < nx; i++) xd[i] = in[0]->data[i];
    for (i = 0; i < ny; i++) rd[i] = in[3]->data[i];
    for (i = 0; i < nw; i++) wd[i] = in[1]->data[i];
    if (!cc->transposed) { /* conv: big = x (C = cin), small = y (M = cout) */
        C = cc->cin; H = cc->h; W = cc->w; M = cc->cout;
    } else { /* transposed: big = y (C = cout), small = x (M = cin), weight Cin x Cout = M x C */
        C = cc->cout; H = OH; W = OW; M = cc->cin; OH = cc->h; OW = cc->w;
    }
    {
        double *bigv = (double *)calloc((size_t)cc->n * C * H * W, sizeof(double));
        double *smallv = (double *)calloc((size_t)cc->n * M * OH * OW, sizeof(double));
        double *dbig = (double *)calloc((size_t)cc->n * C * H * W, sizeof(double));
        double *dsmall = (double *)calloc((size_t)cc->n * M * OH * OW, sizeof(double));
        double *gw = (double *)calloc(nw, sizeof(double)), *gb = (double *)calloc((size_t)cc->cout, sizeof(double));
        double *yref, *dxref;
        const double *xref, *dyref;
        if (!cc->transposed) {
            memcpy(bigv, xd, nx * sizeof(double));
            direct(cc, C, H, W, M, OH, OW, wd, bigv, smallv, 0); /* y */
            memcpy(dsmall, rd, ny * sizeof(double));
            direct(cc, C, H, W, M, OH, OW, wd, dbig, dsmall, 1); /* dx */
            yref = smallv; dxref = dbig; xref = bigv; dyref = dsmall;
        } else {
            memcpy(smallv, xd, nx * sizeof(double));
            direct(cc, C, H, W, M, OH, OW, wd, bigv, smallv, 1); /* y = conv^T(x) */
            memcpy(dbig, rd, ny * sizeof(double));
            direct(cc, C, H, W, M, OH, OW, wd, dbig, dsmall, 0); /* dx = conv(dy) */
            yref = bigv; dxref = dsmall; xref = dbig; dyref = smallv;
        }
        /* bias on y and its gradient: the per-channel sum of dy = r */
        for (n = 0; n < cc->n; n++)
            for (c = 0; c < cc->cout; c++)
                for (t = 0; t < (int)(ny / cc->n / cc->cout); t++) {
                    size_t idx = ((size_t)n * cc->cout + c) * (ny / cc->n / cc->cout) + t;
                    yref[idx] += in[2]->data[c];
                    gb[c] += rd[idx];
                }
        /* weight gradient: sum over (small, big) pairs of small * big, index (m, c, ky, kx) */
        for (n = 0; n < cc->n; n++)
            for (m = 0; m < M; m++)
                for (c = 0; c < C; c++)
                    for (ky = 0; ky < cc->k; ky++)
                        for (kx = 0; kx < cc->k; kx++) {
                            double s = 0;
                            for (oy = 0; oy < OH; oy++)
                                for (ox = 0; ox < OW; ox++) {
                                    int iy = src_index(oy, ky, cc, H), ix = src_index(ox, kx, cc, W);
                                    if (iy < 0 || ix < 0) continue;
                                    s += dyref[(((size_t)n * M + m) * OH + oy) * OW + ox] *
                                         xref[(((size_t)n * C + c) * H + iy) * W + ix];
                                }
                            gw[(((size_t)m * C + c) * cc->k + ky) * cc->k + kx] += s;
                        }
        {
            double e[4];
            e[0] = max_diff(r1.y, yref, ny);
            e[1] = max_diff(r1.dx, dxref, nx);
            e[2] = max_diff(r1.dw, gw, nw);
            e[3] = max_diff(r1.db, gb, (size_t)cc->cout);
            for (t = 0; t < 4; t++)
                if (e[t] > worst) worst = e[t];
            if (worst > 1e-3)
                fprintf(stderr, "  errors y %g dx %g dw %g db %g\n", e[0], e[1], e[2], e[3]);
        }
        free(bigv); free(smallv); free(dbig); free(dsmall); free(gw); free(gb);
    }
    free(xd);
    free(r1.y);
    free(r2.y);
    tn_ctx_free(keep);
    return worst;
}

static const conv_case cases[] = {
    /* n cin cout  h   w  k s p d refl tr op */
    {2, 8, 5, 11, 9, 3, 1, 1, 1, 0, 0, 0},   /* flipped-kernel dX */
    {2, 3, 6, 11, 9, 3, 1, 1, 1, 0, 0, 0},   /* Cin < 8: col2im dX */
    {2, 8, 4, 7, 10, 1, 1, 0, 1, 0, 0, 0},   /* 1x1, flipped */
    {1, 3, 4, 7, 10, 1, 1, 0, 1, 0, 0, 0},   /* 1x1, col2im */
    {2, 9, 3, 13, 11, 5, 1, 2, 1, 0, 0, 0},  /* 5x5 */
    {2, 8, 5, 13, 10, 3, 2, 1, 1, 0, 0, 0},  /* stride 2 */
    {1, 8, 4, 12, 13, 3, 1, 2, 2, 0, 0, 0},  /* dilation 2, flipped */
    {2, 8, 4, 11, 12, 3, 1, 1, 1, 1, 0, 0},  /* reflect */
    {2, 3, 4, 15, 13, 5, 2, 2, 1, 1, 0, 0},  /* reflect, stride 2, 5x5 */
    {1, 10, 3, 14, 11, 3, 2, 2, 2, 1, 0, 0}, /* reflect, stride 2, dilation 2 */
    {1, 16, 8, 96, 72, 3, 1, 1, 1, 0, 0, 0}, /* 16 row groups with several sub-bands each */
    {1, 3, 8, 64, 80, 3, 2, 1, 1, 0, 0, 0},  /* many groups, phased col2im with stride 2 */
    {1, 8, 20, 9, 7, 3, 1, 1, 1, 0, 0, 0},   /* one row group: output channels split by threads */
    {1, 2, 3, 4, 5, 1, 1, 0, 1, 0, 0, 0},    /* tiny: unpacked GEMM */
    {2, 4, 3, 5, 6, 3, 2, 1, 1, 0, 1, 1},    /* transposed, stride 2, output padding */
    {1, 6, 9, 9, 7, 3, 1, 1, 1, 0, 1, 0},    /* transposed, stride 1: flipped path */
    {1, 8, 4, 20, 24, 4, 2, 1, 1, 0, 1, 0},  /* transposed 4x4 stride 2, several groups */
};

TN_TEST(conv_matches_direct_loops_and_threads)
{
    size_t i;
    for (i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        double e = check_case(&cases[i]);
        if (!(e < 1e-3)) {
            fprintf(stderr, "  case %d: worst error %g\n", (int)i, e);
            TN_CHECK(0);
        }
    }
}

int main(void)
{
    TN_RUN(conv_matches_direct_loops_and_threads);
    return tn_test_summary("test_conv_par");
}
