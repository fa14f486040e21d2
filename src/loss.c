/* ============================================================================================
   @@loss  losses (each returns a one-element tensor)
   ============================================================================================ */
#ifndef TN_NO_ENGINE
TN_API tn_tensor *tn_mse_loss(tn_ctx *ctx, tn_tensor *pred, tn_tensor *target);
TN_API tn_tensor *tn_l1_loss(tn_ctx *ctx, tn_tensor *pred, tn_tensor *target);
/* mean of softplus(x) - x * t: binary cross-entropy on logits, stable for any x. */
TN_API tn_tensor *tn_bce_logits_loss(tn_ctx *ctx, tn_tensor *logits, tn_tensor *target);
/* Hinge GAN: discriminator mean(relu(1 - real)) + mean(relu(1 + fake)); generator -mean(fake). */
TN_API tn_tensor *tn_hinge_d_loss(tn_ctx *ctx, tn_tensor *real_scores, tn_tensor *fake_scores);
TN_API tn_tensor *tn_hinge_g_loss(tn_ctx *ctx, tn_tensor *fake_scores);
/* Non-saturating GAN: discriminator mean(softplus(-real)) + mean(softplus(fake)); generator
   mean(softplus(-fake)). */
TN_API tn_tensor *tn_nonsat_d_loss(tn_ctx *ctx, tn_tensor *real_scores, tn_tensor *fake_scores);
TN_API tn_tensor *tn_nonsat_g_loss(tn_ctx *ctx, tn_tensor *fake_scores);
/* Gram matrices of N x C x H x W features: N x C x C... returned as (N*C) x C, scaled by `scale`
   (e.g. 1 / (C*H*W)). */
TN_API tn_tensor *tn_gram(tn_ctx *ctx, tn_tensor *x, float scale);
/* Total variation sum over pixels of (dx^2 + dy^2)^(beta/2) (beta 2: the plain squared TV). */
TN_API tn_tensor *tn_tv_loss(tn_ctx *ctx, tn_tensor *x, float beta);
/* 1 - SSIM (Gaussian 11 x 11, sigma 1.5, valid region), differentiable; data range R. */
TN_API tn_tensor *tn_ssim_loss(tn_ctx *ctx, tn_tensor *x, tn_tensor *y, float data_range);
/* Gradient-difference loss: mean | |dx(a)| - |dx(b)| | + mean | |dy(a)| - |dy(b)| |. */
TN_API tn_tensor *tn_gdl_loss(tn_ctx *ctx, tn_tensor *a, tn_tensor *b);
#endif /* TN_NO_ENGINE */

/* --------------------------------------------------------------------------------------------
   >>loss  (@@loss implementation) - mostly compositions of the ops above, so their gradients
   come for free and are checked by the same finite-difference tests.
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_ENGINE

TN_API tn_tensor *tn_mse_loss(tn_ctx *ctx, tn_tensor *pred, tn_tensor *target)
{
    return tn_mean(ctx, tn_square(ctx, tn_sub(ctx, pred, target)));
}

TN_API tn_tensor *tn_l1_loss(tn_ctx *ctx, tn_tensor *pred, tn_tensor *target)
{
    return tn_mean(ctx, tn_abs(ctx, tn_sub(ctx, pred, target)));
}

TN_API tn_tensor *tn_bce_logits_loss(tn_ctx *ctx, tn_tensor *logits, tn_tensor *target)
{
    return tn_mean(ctx, tn_sub(ctx, tn_softplus(ctx, logits), tn_mul(ctx, logits, target)));
}

TN_API tn_tensor *tn_hinge_d_loss(tn_ctx *ctx, tn_tensor *real_scores, tn_tensor *fake_scores)
{
    tn_tensor *r = tn_mean(ctx, tn_relu(ctx, tn_scale_shift(ctx, real_scores, -1.0f, 1.0f)));
    tn_tensor *f = tn_mean(ctx, tn_relu(ctx, tn_scale_shift(ctx, fake_scores, 1.0f, 1.0f)));
    return tn_add(ctx, r, f);
}

TN_API tn_tensor *tn_hinge_g_loss(tn_ctx *ctx, tn_tensor *fake_scores)
{
    return tn_scale_shift(ctx, tn_mean(ctx, fake_scores), -1.0f, 0.0f);
}

TN_API tn_tensor *tn_nonsat_d_loss(tn_ctx *ctx, tn_tensor *real_scores, tn_tensor *fake_scores)
{
    tn_tensor *r = tn_mean(ctx, tn_softplus(ctx, tn_scale_shift(ctx, real_scores, -1.0f, 0.0f)));
    return tn_add(ctx, r, tn_mean(ctx, tn_softplus(ctx, fake_scores)));
}

TN_API tn_tensor *tn_nonsat_g_loss(tn_ctx *ctx, tn_tensor *fake_scores)
{
    return tn_mean(ctx, tn_softplus(ctx, tn_scale_shift(ctx, fake_scores, -1.0f, 0.0f)));
}

static void tn__gram_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    int N = x->shape[0], C = x->shape[1], n, i, j;
    int hw = x->shape[2] * x->shape[3];
    float *gs = tn__ctx_floats(ctx, (size_t)C * C, 0);
    if (!gs || !tn__grad(ctx, x)) return;
    for (n = 0; n < N; n++) {
        const float *g = out->grad + (size_t)n * C * C;
        for (i = 0; i < C; i++) /* dG + dG^T, scaled */
            for (j = 0; j < C; j++) gs[i * C + j] = (g[i * C + j] + g[j * C + i]) * out->fp[0];
        tn_sgemm(0, 0, C, hw, C, 1.0f, gs, C, x->data + (size_t)n * C * hw, hw, 1.0f, x->grad + (size_t)n * C * hw, hw);
    }
}

TN_API tn_tensor *tn_gram(tn_ctx *ctx, tn_tensor *x, float scale)
{
    int shape[2], N, C, hw, n;
    tn_tensor *o;
    if (!x) return NULL;
    TN_ASSERT(x->ndim == 4);
    N = x->shape[0];
    C = x->shape[1];
    hw = x->shape[2] * x->shape[3];
    shape[0] = N * C;
    shape[1] = C;
    o = tn__op(ctx, 2, shape, tn__gram_backward, x, NULL, NULL);
    if (!o) return NULL;
    o->fp[0] = scale;
    for (n = 0; n < N; n++) {
        const float *f = x->data + (size_t)n * C * hw;
        tn_sgemm(0, 1, C, C, hw, scale, f, hw, f, hw, 0.0f, o->data + (size_t)n * C * C, C);
    }
    return o;
}

/* Forward differences along x and y, both cropped to (H-1) x (W-1). */
static void tn__diffs(tn_ctx *ctx, tn_tensor *x, tn_tensor **dx, tn_tensor **dy)
{
    int H = x->shape[2], W = x->shape[3];
    tn_tensor *top = tn_slice(ctx, x, 2, 0, H - 1), *bot = tn_slice(ctx, x, 2, 1, H - 1);
    tn_tensor *left = tn_slice(ctx, x, 3, 0, W - 1), *right = tn_slice(ctx, x, 3, 1, W - 1);
    *dx = tn_slice(ctx, tn_sub(ctx, right, left), 2, 0, H - 1);
    *dy = tn_slice(ctx, tn_sub(ctx, bot, top), 3, 0, W - 1);
}

TN_API tn_tensor *tn_tv_loss(tn_ctx *ctx, tn_tensor *x, float beta)
{
    tn_tensor *dx, *dy, *s;
    if (!x) return NULL;
    TN_ASSERT(x->ndim == 4 && x->shape[2] >= 2 && x->shape[3] >= 2);
    tn__diffs(ctx, x, &dx, &dy);
    s = tn_add(ctx, tn_square(ctx, dx), tn_square(ctx, dy));
    return tn_sum(ctx, beta == 2.0f ? s : tn_pow_abs(ctx, s, 0.5f * beta));
}

TN_API tn_tensor *tn_gdl_loss(tn_ctx *ctx, tn_tensor *a, tn_tensor *b)
{
    tn_tensor *ax, *ay, *bx, *by;
    if (!a || !b) return NULL;
    TN_ASSERT(a->ndim == 4 && a->shape[2] >= 2 && a->shape[3] >= 2);
    tn__diffs(ctx, a, &ax, &ay);
    tn__diffs(ctx, b, &bx, &by);
    return tn_add(ctx, tn_l1_loss(ctx, tn_abs(ctx, ax), tn_abs(ctx, bx)), tn_l1_loss(ctx, tn_abs(ctx, ay), tn_abs(ctx, by)));
}

/* Separable 11-tap Gaussian (sigma 1.5, like skimage), valid region, on every plane. */
static tn_tensor *tn__ssim_blur(tn_ctx *ctx, tn_tensor *x, tn_tensor *kh, tn_tensor *kv)
{
    int shape[4];
    tn_tensor *p;
    shape[0] = x->shape[0] * x->shape[1];
    shape[1] = 1;
    shape[2] = x->shape[2];
    shape[3] = x->shape[3];
    p = tn_reshape(ctx, x, 4, shape);
    return tn_conv2d(ctx, tn_conv2d(ctx, p, kh, NULL, NULL), kv, NULL, NULL);
}

TN_API tn_tensor *tn_ssim_loss(tn_ctx *ctx, tn_tensor *x, tn_tensor *y, float data_range)
{
    tn_tensor *kh, *kv, *mx, *my, *sxx, *syy, *sxy, *num, *den, *vx, *vy, *cxy, *mxy, *m2;
    float c1 = (0.01f * data_range) * (0.01f * data_range), c2 = (0.03f * data_range) * (0.03f * data_range);
    double g[11], s = 0;
    int i;
    if (!x || !y) return NULL;
    TN_ASSERT(tn_tensor_same_shape(x, y) && x->ndim == 4 && x->shape[2] >= 11 && x->shape[3] >= 11);
    kh = tn_tensor_4d(ctx, 1, 1, 1, 11);
    kv = tn_tensor_4d(ctx, 1, 1, 11, 1);
    if (!kh || !kv) return NULL;
    for (i = 0; i < 11; i++) s += g[i] = exp(-0.5 * (i - 5) * (i - 5) / 2.25);
    for (i = 0; i < 11; i++) kh->data[i] = kv->data[i] = (float)(g[i] / s);
    mx = tn__ssim_blur(ctx, x, kh, kv);
    my = tn__ssim_blur(ctx, y, kh, kv);
    sxx = tn__ssim_blur(ctx, tn_square(ctx, x), kh, kv);
    syy = tn__ssim_blur(ctx, tn_square(ctx, y), kh, kv);
    sxy = tn__ssim_blur(ctx, tn_mul(ctx, x, y), kh, kv);
    mxy = tn_mul(ctx, mx, my);
    vx = tn_sub(ctx, sxx, tn_square(ctx, mx));
    vy = tn_sub(ctx, syy, tn_square(ctx, my));
    cxy = tn_sub(ctx, sxy, mxy);
    num = tn_mul(ctx, tn_scale_shift(ctx, mxy, 2.0f, c1), tn_scale_shift(ctx, cxy, 2.0f, c2));
    m2 = tn_add(ctx, tn_square(ctx, mx), tn_square(ctx, my));
    den = tn_mul(ctx, tn_scale_shift(ctx, m2, 1.0f, c1), tn_scale_shift(ctx, tn_add(ctx, vx, vy), 1.0f, c2));
    return tn_scale_shift(ctx, tn_mean(ctx, tn_div(ctx, num, den)), -1.0f, 1.0f);
}

/* ---- 1-D optimal transport: the histogram losses of style transfer and SinGAN ---- */

/* Order-preserving map of a float to an unsigned key (negative floats reversed). */
static uint32_t tn__float_key(float f)
{
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

/* idx = the permutation that sorts v ascending: stable LSD radix sort, 3 passes of 11 bits
   (float keys are exact, so ties keep index order and the result is deterministic).
   scratch holds 3 * n uint32. */
TN__INTERNAL_SHARED void tn__argsort_f32(const float *v, size_t n, uint32_t *idx, uint32_t *scratch)
{
    uint32_t *key = scratch, *k2 = scratch + n, *i2 = scratch + 2 * n, *ia = idx, *t;
    size_t cnt[2048], i;
    int pass;
    for (i = 0; i < n; i++) {
        key[i] = tn__float_key(v[i]);
        ia[i] = (uint32_t)i;
    }
    for (pass = 0; pass < 3; pass++) {
        int sh = pass * 11;
        size_t sum = 0;
        memset(cnt, 0, sizeof cnt);
        for (i = 0; i < n; i++) cnt[(key[i] >> sh) & 2047]++;
        for (i = 0; i < 2048; i++) {
            size_t c = cnt[i];
            cnt[i] = sum;
            sum += c;
        }
        for (i = 0; i < n; i++) {
            size_t d = cnt[(key[i] >> sh) & 2047]++;
            k2[d] = key[i];
            i2[d] = ia[i];
        }
        t = key; key = k2; k2 = t;
        t = ia; ia = i2; i2 = t;
    }
    if (ia != idx) memcpy(idx, ia, n * sizeof *idx);
}

/* Element i of a sorted row of length nt read as a row of length n (quantile resampling). */
TN__SHARED float tn__quantile_at(const float *sorted, size_t nt, size_t i, size_t n)
{
    size_t j = (size_t)(((double)i + 0.5) * (double)nt / (double)n);
    return sorted[j < nt ? j : nt - 1];
}

/* res = each of the n values of x less the quantile of the sorted t (nt values) at its rank: the
   gradient of half the squared 1-D Wasserstein-2 distance between the two histograms (the sliced
   Wasserstein texture loss). idx: 4 n uint32 of scratch; its first n hold the sorting permutation
   on return. Returns the sum of res^2. */
TN__SHARED double tn__ot_residuals(const float *x, size_t n, const float *t, size_t nt, uint32_t *idx, float *res)
{
    double s = 0;
    size_t i;
    tn__argsort_f32(x, n, idx, idx + n);
    for (i = 0; i < n; i++) {
        float d = x[idx[i]] - tn__quantile_at(t, nt, i, n);
        res[idx[i]] = d;
        s += (double)d * d;
    }
    return s;
}
#endif /* TN_NO_ENGINE */


