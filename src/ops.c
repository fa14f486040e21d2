/* ============================================================================================
   @@ops  differentiable operations
   Every op takes the context its output lives in, returns a new tensor (NULL if an input is
   NULL or memory ran out) and records its backward pass when an input requires a gradient.
   Shapes follow PyTorch: images N x C x H x W, conv weights Cout x Cin x KH x KW, transposed
   conv weights Cin x Cout x KH x KW, linear weights out x in.
   ============================================================================================ */
#ifndef TN_NO_ENGINE

/* Elementwise with NumPy broadcasting (shapes aligned at the right, size-1 dims stretch). */
TN_API tn_tensor *tn_add(tn_ctx *ctx, tn_tensor *a, tn_tensor *b);
TN_API tn_tensor *tn_sub(tn_ctx *ctx, tn_tensor *a, tn_tensor *b);
TN_API tn_tensor *tn_mul(tn_ctx *ctx, tn_tensor *a, tn_tensor *b);
TN_API tn_tensor *tn_div(tn_ctx *ctx, tn_tensor *a, tn_tensor *b);
/* a * scale + shift */
TN_API tn_tensor *tn_scale_shift(tn_ctx *ctx, tn_tensor *a, float scale, float shift);
/* Unary functions */
TN_API tn_tensor *tn_relu(tn_ctx *ctx, tn_tensor *a);
TN_API tn_tensor *tn_leaky_relu(tn_ctx *ctx, tn_tensor *a, float slope);
TN_API tn_tensor *tn_elu(tn_ctx *ctx, tn_tensor *a, float alpha);
TN_API tn_tensor *tn_tanh(tn_ctx *ctx, tn_tensor *a);
TN_API tn_tensor *tn_sigmoid(tn_ctx *ctx, tn_tensor *a);
TN_API tn_tensor *tn_softplus(tn_ctx *ctx, tn_tensor *a);
TN_API tn_tensor *tn_abs(tn_ctx *ctx, tn_tensor *a);
TN_API tn_tensor *tn_square(tn_ctx *ctx, tn_tensor *a);
/* |a|^p elementwise (p > 0; gradient 0 at a == 0 for p <= 1) */
TN_API tn_tensor *tn_pow_abs(tn_ctx *ctx, tn_tensor *a, float p);

/* Matrix product of 2-D tensors: op(a) x op(b), op = transpose when the flag is set. */
TN_API tn_tensor *tn_matmul(tn_ctx *ctx, tn_tensor *a, tn_tensor *b, int trans_a, int trans_b);
/* x (N x in) times W^T (W: out x in) plus bias (out; may be NULL). */
TN_API tn_tensor *tn_linear(tn_ctx *ctx, tn_tensor *x, tn_tensor *w, tn_tensor *bias);

/* Reductions: over everything (a one-element tensor) or over one axis (kept as size 1). */
TN_API tn_tensor *tn_sum(tn_ctx *ctx, tn_tensor *a);
TN_API tn_tensor *tn_mean(tn_ctx *ctx, tn_tensor *a);
TN_API tn_tensor *tn_sum_axis(tn_ctx *ctx, tn_tensor *a, int axis);
TN_API tn_tensor *tn_mean_axis(tn_ctx *ctx, tn_tensor *a, int axis);

/* Shape ops (they copy). */
TN_API tn_tensor *tn_reshape(tn_ctx *ctx, tn_tensor *a, int ndim, const int *shape);
/* out dim i = a dim perm[i] */
TN_API tn_tensor *tn_permute(tn_ctx *ctx, tn_tensor *a, const int *perm);
/* Concatenation / slicing along any axis (axis 1 = channels for images). */
TN_API tn_tensor *tn_concat(tn_ctx *ctx, tn_tensor *a, tn_tensor *b, int axis);
TN_API tn_tensor *tn_slice(tn_ctx *ctx, tn_tensor *a, int axis, int start, int len);

typedef enum tn_padding { TN_PADDING_ZERO = 0, TN_PADDING_REFLECT } tn_padding;
typedef struct tn_conv_opts {
    int stride;      /* 0 = 1 */
    int pad;         /* zero = no padding; same on all sides */
    int dilation;    /* 0 = 1 */
    tn_padding padding;
    int output_padding; /* transposed conv only: extra rows/cols at the bottom/right */
} tn_conv_opts;
/* 2-D convolution (cross-correlation) via im2col + SGEMM. bias may be NULL; opts NULL = stride 1,
   no padding. */
TN_API tn_tensor *tn_conv2d(tn_ctx *ctx, tn_tensor *x, tn_tensor *w, tn_tensor *bias, const tn_conv_opts *opts);
/* Transposed convolution (the gradient of conv2d with respect to its input), w: Cin x Cout x KH x KW.
   Output size (H - 1) * stride - 2 * pad + dilation * (KH - 1) + output_padding + 1. */
TN_API tn_tensor *tn_conv_transpose2d(tn_ctx *ctx, tn_tensor *x, tn_tensor *w, tn_tensor *bias, const tn_conv_opts *opts);
/* Pooling with a square window k and stride s (no padding; partial windows dropped). */
TN_API tn_tensor *tn_avg_pool2d(tn_ctx *ctx, tn_tensor *x, int k, int s);
TN_API tn_tensor *tn_max_pool2d(tn_ctx *ctx, tn_tensor *x, int k, int s);
/* Upsampling: nearest by an integer factor; bilinear to any size (align_corners = false). */
TN_API tn_tensor *tn_upsample_nearest(tn_ctx *ctx, tn_tensor *x, int factor);
TN_API tn_tensor *tn_upsample_bilinear(tn_ctx *ctx, tn_tensor *x, int out_h, int out_w);

/* Normalisation. batch norm: statistics over N, H, W per channel; in training it updates the
   running mean/var (momentum 0.1) in place, in eval it uses them. gamma/beta (C) may be NULL. */
TN_API tn_tensor *tn_batch_norm(tn_ctx *ctx, tn_tensor *x, tn_tensor *gamma, tn_tensor *beta, tn_tensor *running_mean,
                                tn_tensor *running_var, int training, float eps);
/* Instance norm: statistics over H, W per (n, c); gamma/beta (C) may be NULL. */
TN_API tn_tensor *tn_instance_norm(tn_ctx *ctx, tn_tensor *x, tn_tensor *gamma, tn_tensor *beta, float eps);
/* SPADE: parameter-free instance norm of x, then x_norm * (1 + gamma) + beta with per-pixel
   gamma/beta tensors shaped like x (made by convolutions of a conditioning map). */
TN_API tn_tensor *tn_spade_norm(tn_ctx *ctx, tn_tensor *x, tn_tensor *gamma, tn_tensor *beta, float eps);
/* Spectral normalisation: w / sigma(w), w viewed as rows = shape[0]. u (rows) is the persistent
   power-iteration vector, updated in place (`iters` steps, 1 is usual during training). */
TN_API tn_tensor *tn_spectral_norm(tn_ctx *ctx, tn_tensor *w, tn_tensor *u, int iters);

/* Graph ops on row-major N x D features. idx / seg hold row numbers. */
TN_API tn_tensor *tn_gather_rows(tn_ctx *ctx, tn_tensor *x, const int *idx, int n);
/* out[seg[i]] += x[i] for i < rows(x); out has nseg rows (segment sum). */
TN_API tn_tensor *tn_scatter_add_rows(tn_ctx *ctx, tn_tensor *x, const int *seg, int nseg);
/* Softmax of scores (E x H: E entries, H heads) within each segment (seg[e] in [0, nseg)). */
TN_API tn_tensor *tn_segment_softmax(tn_ctx *ctx, tn_tensor *scores, const int *seg, int nseg);
/* softmax((logits + Gumbel noise) / tau) over the last axis of an N x K tensor. */
TN_API tn_tensor *tn_gumbel_softmax(tn_ctx *ctx, tn_tensor *logits, float tau, tn_rng *rng);
/* Inverted dropout with probability p when training; identity otherwise. */
TN_API tn_tensor *tn_dropout(tn_ctx *ctx, tn_tensor *x, float p, int training, tn_rng *rng);
#endif /* TN_NO_ENGINE */

/* --------------------------------------------------------------------------------------------
   >>ops  (@@ops implementation)
   Broadcasting binary ops walk 4-D index space with per-operand strides (0 on stretched dims);
   the backward pass runs the same walk and sums into the stretched operand. Large elementwise
   loops run on the pool; a split never changes any element's value.
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_ENGINE

#define TN__PAR_GRAIN 16384

/* Shape of a padded to 4 dims on the left (NumPy alignment). */
static void tn__shape4(const tn_tensor *a, int *s)
{
    int i, off = 4 - a->ndim;
    for (i = 0; i < 4; i++) s[i] = i < off ? 1 : a->shape[i - off];
}

/* Contiguous strides of a 4-D shape, with 0 where the dim is 1 and the output's is not. */
static void tn__bstrides(const int *s, const int *os, size_t *st)
{
    size_t acc = 1;
    int i;
    for (i = 3; i >= 0; i--) {
        st[i] = (s[i] == 1 && os[i] != 1) ? 0 : acc;
        acc *= (size_t)s[i];
    }
}

/* Output shape of broadcasting a with b; asserts they are compatible. */
static int tn__broadcast_shape(const tn_tensor *a, const tn_tensor *b, int *os)
{
    int sa[4], sb[4], i, nd = a->ndim > b->ndim ? a->ndim : b->ndim;
    tn__shape4(a, sa);
    tn__shape4(b, sb);
    for (i = 0; i < 4; i++) {
        TN_ASSERT(sa[i] == sb[i] || sa[i] == 1 || sb[i] == 1);
        os[i] = sa[i] > sb[i] ? sa[i] : sb[i];
    }
    return nd;
}

enum { TN__BIN_ADD, TN__BIN_SUB, TN__BIN_MUL, TN__BIN_DIV };

typedef struct tn__bin_job {
    const float *a, *b;
    float *o;
    int os[4];
    size_t sa[4], sb[4];
    int op;
} tn__bin_job;

/* o = a op b over n contiguous floats (op: add, sub or mul), in SIMD; the same bytes as the
   scalar loop, one rounding per element. */
static void tn__bin_row_contig(int op, const float *a, const float *b, float *o, size_t n)
{
    size_t x = 0;
    for (; x + TN__VF_N <= n; x += TN__VF_N) {
        tn__vf va = tn__vf_load(a + x), vb = tn__vf_load(b + x);
        tn__vf_store(o + x, op == TN__BIN_ADD ? tn__vf_add(va, vb) : op == TN__BIN_SUB ? tn__vf_sub(va, vb) : tn__vf_mul(va, vb));
    }
    for (; x < n; x++) o[x] = op == TN__BIN_ADD ? a[x] + b[x] : op == TN__BIN_SUB ? a[x] - b[x] : a[x] * b[x];
}

/* d += s * g (s = +1 or -1), or d += g * m with m (contiguous), over n floats, in SIMD; the
   same bytes as the scalar loop (a product, then a sum: no fused multiply-add). */
static void tn__bin_grad_contig(float *d, const float *g, const float *m, float s, size_t n)
{
    size_t x = 0;
    for (; x + TN__VF_N <= n; x += TN__VF_N) {
        tn__vf vg = tn__vf_load(g + x), vd = tn__vf_load(d + x);
        tn__vf_store(d + x, m ? tn__vf_add(vd, tn__vf_mul(vg, tn__vf_load(m + x))) : s > 0 ? tn__vf_add(vd, vg) : tn__vf_sub(vd, vg));
    }
    for (; x < n; x++) d[x] += m ? g[x] * m[x] : s > 0 ? g[x] : -g[x];
}

/* Forward over output rows [b, e) of the flattened (n, c, h) index. */
static void tn__bin_rows(void *ctx, size_t rb, size_t re)
{
    const tn__bin_job *j = (const tn__bin_job *)ctx;
    size_t r;
    int W = j->os[3];
    for (r = rb; r < re; r++) {
        size_t n = r / ((size_t)j->os[1] * j->os[2]), c = (r / j->os[2]) % j->os[1], h = r % j->os[2];
        const float *pa = j->a + n * j->sa[0] + c * j->sa[1] + h * j->sa[2];
        const float *pb = j->b + n * j->sb[0] + c * j->sb[1] + h * j->sb[2];
        float *po = j->o + r * (size_t)W;
        size_t ia = j->sa[3], ib = j->sb[3];
        int x;
        if (ia == 1 && ib == 1 && j->op != TN__BIN_DIV) {
            tn__bin_row_contig(j->op, pa, pb, po, (size_t)W);
            continue;
        }
        switch (j->op) {
        case TN__BIN_ADD: for (x = 0; x < W; x++) po[x] = pa[x * ia] + pb[x * ib]; break;
        case TN__BIN_SUB: for (x = 0; x < W; x++) po[x] = pa[x * ia] - pb[x * ib]; break;
        case TN__BIN_MUL: for (x = 0; x < W; x++) po[x] = pa[x * ia] * pb[x * ib]; break;
        default: for (x = 0; x < W; x++) po[x] = pa[x * ia] / pb[x * ib]; break;
        }
    }
}

typedef struct tn__bin_grad_job {
    const float *go, *a, *b;
    float *g;                  /* the gradient of operand `which` */
    int os[4], op, which;
    size_t sa[4], sb[4], sd[4]; /* sd: the strides of operand `which` */
} tn__bin_grad_job;

/* d out / d operand times the output gradient, added over output rows [rb, re). */
static void tn__bin_grad_rows(void *vj, size_t rb, size_t re)
{
    const tn__bin_grad_job *j = (const tn__bin_grad_job *)vj;
    size_t r, x, W = (size_t)j->os[3], ia = j->sa[3], ib = j->sb[3], id = j->sd[3];
    for (r = rb; r < re; r++) {
        size_t n = r / ((size_t)j->os[1] * j->os[2]), c = (r / j->os[2]) % j->os[1], h = r % j->os[2];
        const float *pg = j->go + r * W;
        const float *pa = j->a + n * j->sa[0] + c * j->sa[1] + h * j->sa[2];
        const float *pb = j->b + n * j->sb[0] + c * j->sb[1] + h * j->sb[2];
        float *pd = j->g + n * j->sd[0] + c * j->sd[1] + h * j->sd[2];
#define TN__BIN_GRAD(expr) \
    do { \
        if (id == 1) for (x = 0; x < W; x++) pd[x] += (expr); \
        else for (x = 0; x < W; x++) pd[x * id] += (expr); \
    } while (0)
        if (id == 1 && j->op != TN__BIN_DIV && (j->op != TN__BIN_MUL || (j->which ? ia : ib) == 1)) {
            tn__bin_grad_contig(pd, pg, j->op != TN__BIN_MUL ? NULL : j->which ? pa : pb, j->op == TN__BIN_SUB && j->which ? -1.0f : 1.0f, W);
            continue;
        }
        switch (j->op * 2 + j->which) {
        case TN__BIN_ADD * 2: case TN__BIN_ADD * 2 + 1: case TN__BIN_SUB * 2: TN__BIN_GRAD(pg[x]); break;
        case TN__BIN_SUB * 2 + 1: TN__BIN_GRAD(-pg[x]); break;
        case TN__BIN_MUL * 2: TN__BIN_GRAD(pg[x] * pb[x * ib]); break;
        case TN__BIN_MUL * 2 + 1: TN__BIN_GRAD(pg[x] * pa[x * ia]); break;
        case TN__BIN_DIV * 2: TN__BIN_GRAD(pg[x] / pb[x * ib]); break;
        default: TN__BIN_GRAD(-pg[x] * pa[x * ia] / (pb[x * ib] * pb[x * ib])); break;
        }
#undef TN__BIN_GRAD
    }
}

/* Gradient of a binary op for one operand (which = 0: a, 1: b), summed over stretched dims.
   An operand of the output's shape takes disjoint rows, in parallel; one stretched over rows
   sums them serially, in a fixed order (determinism). */
static void tn__bin_backward_one(const tn_tensor *out, int which)
{
    tn_tensor *a = out->src[0], *b = out->src[1];
    tn__bin_grad_job j;
    int sa4[4], sb4[4], i, full = 1;
    size_t rows;
    tn__shape4(out, j.os);
    tn__shape4(a, sa4);
    tn__shape4(b, sb4);
    tn__bstrides(sa4, j.os, j.sa);
    tn__bstrides(sb4, j.os, j.sb);
    for (i = 0; i < 4; i++) {
        j.sd[i] = which ? j.sb[i] : j.sa[i];
        full &= (which ? sb4[i] : sa4[i]) == j.os[i];
    }
    j.go = out->grad;
    j.a = a->data;
    j.b = b->data;
    j.g = which ? b->grad : a->grad;
    j.op = out->ip[0];
    j.which = which;
    rows = (size_t)j.os[0] * j.os[1] * j.os[2];
    if (full) tn_parallel_for(rows, 1 + TN__PAR_GRAIN / (size_t)j.os[3], tn__bin_grad_rows, &j);
    else tn__bin_grad_rows(&j, 0, rows);
}

static void tn__bin_backward(tn_ctx *ctx, tn_tensor *out)
{
    if (out->src[0]->requires_grad && tn__grad(ctx, out->src[0])) tn__bin_backward_one(out, 0);
    if (out->src[1]->requires_grad && tn__grad(ctx, out->src[1])) tn__bin_backward_one(out, 1);
}

static tn_tensor *tn__binary(tn_ctx *ctx, tn_tensor *a, tn_tensor *b, int op)
{
    int os[4], sa4[4], sb4[4], nd, shape[4], i;
    tn_tensor *o;
    tn__bin_job j;
    if (!a || !b) return NULL;
    nd = tn__broadcast_shape(a, b, os);
    for (i = 0; i < nd; i++) shape[i] = os[4 - nd + i];
    o = tn__op(ctx, nd, shape, tn__bin_backward, a, b, NULL);
    if (!o) return NULL;
    o->ip[0] = op;
    tn__shape4(a, sa4);
    tn__shape4(b, sb4);
    j.a = a->data;
    j.b = b->data;
    j.o = o->data;
    memcpy(j.os, os, sizeof os);
    tn__bstrides(sa4, os, j.sa);
    tn__bstrides(sb4, os, j.sb);
    j.op = op;
    tn_parallel_for((size_t)os[0] * os[1] * os[2], 1 + TN__PAR_GRAIN / (size_t)os[3], tn__bin_rows, &j);
    return o;
}

TN_API tn_tensor *tn_add(tn_ctx *ctx, tn_tensor *a, tn_tensor *b) { return tn__binary(ctx, a, b, TN__BIN_ADD); }
TN_API tn_tensor *tn_sub(tn_ctx *ctx, tn_tensor *a, tn_tensor *b) { return tn__binary(ctx, a, b, TN__BIN_SUB); }
TN_API tn_tensor *tn_mul(tn_ctx *ctx, tn_tensor *a, tn_tensor *b) { return tn__binary(ctx, a, b, TN__BIN_MUL); }
TN_API tn_tensor *tn_div(tn_ctx *ctx, tn_tensor *a, tn_tensor *b) { return tn__binary(ctx, a, b, TN__BIN_DIV); }

/* ---- unary elementwise ---- */

enum { TN__UN_SCALE, TN__UN_RELU, TN__UN_LEAKY, TN__UN_ELU, TN__UN_TANH, TN__UN_SIGMOID, TN__UN_SOFTPLUS,
       TN__UN_ABS, TN__UN_SQUARE, TN__UN_POWABS };

typedef struct tn__un_job { const float *x; float *y; int op; float p0, p1; } tn__un_job;

static float tn__unary_f(int op, float x, float p0, float p1)
{
    switch (op) {
    case TN__UN_SCALE: return x * p0 + p1;
    case TN__UN_RELU: return x > 0 ? x : 0.0f;
    case TN__UN_LEAKY: return x > 0 ? x : x * p0;
    case TN__UN_ELU: return x > 0 ? x : p0 * (expf(x) - 1.0f);
    case TN__UN_TANH: return tanhf(x);
    case TN__UN_SIGMOID: return x >= 0 ? 1.0f / (1.0f + expf(-x)) : expf(x) / (1.0f + expf(x));
    case TN__UN_SOFTPLUS: return x > 20.0f ? x : log1pf(expf(x));
    case TN__UN_ABS: return fabsf(x);
    case TN__UN_SQUARE: return x * x;
    default: return powf(fabsf(x), p0);
    }
}

/* dy/dx given x and y = f(x). */
static float tn__unary_df(int op, float x, float y, float p0)
{
    switch (op) {
    case TN__UN_SCALE: return p0;
    case TN__UN_RELU: return x > 0 ? 1.0f : 0.0f;
    case TN__UN_LEAKY: return x > 0 ? 1.0f : p0;
    case TN__UN_ELU: return x > 0 ? 1.0f : y + p0;
    case TN__UN_TANH: return 1.0f - y * y;
    case TN__UN_SIGMOID: return y * (1.0f - y);
    case TN__UN_SOFTPLUS: return x >= 0 ? 1.0f / (1.0f + expf(-x)) : expf(x) / (1.0f + expf(x));
    case TN__UN_ABS: return x > 0 ? 1.0f : (x < 0 ? -1.0f : 0.0f);
    case TN__UN_SQUARE: return 2.0f * x;
    default: return x == 0.0f ? 0.0f : p0 * y / x;
    }
}

static void tn__unary_range(void *ctx, size_t b, size_t e)
{
    const tn__un_job *j = (const tn__un_job *)ctx;
    size_t i;
    if (j->op == TN__UN_RELU) {
        for (i = b; i < e; i++) j->y[i] = j->x[i] > 0 ? j->x[i] : 0.0f;
        return;
    }
    for (i = b; i < e; i++) j->y[i] = tn__unary_f(j->op, j->x[i], j->p0, j->p1);
}

static void tn__unary_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *a = out->src[0];
    float *g = tn__grad(ctx, a);
    size_t i;
    if (!g) return;
    for (i = 0; i < a->numel; i++)
        g[i] += out->grad[i] * tn__unary_df(out->ip[0], a->data[i], out->data[i], out->fp[0]);
}

static tn_tensor *tn__unary(tn_ctx *ctx, tn_tensor *a, int op, float p0, float p1)
{
    tn_tensor *o;
    tn__un_job j;
    if (!a) return NULL;
    o = tn__op_like(ctx, a, tn__unary_backward, a, NULL);
    if (!o) return NULL;
    o->ip[0] = op;
    o->fp[0] = p0;
    o->fp[1] = p1;
    j.x = a->data;
    j.y = o->data;
    j.op = op;
    j.p0 = p0;
    j.p1 = p1;
    tn_parallel_for(a->numel, TN__PAR_GRAIN, tn__unary_range, &j);
    return o;
}

TN_API tn_tensor *tn_scale_shift(tn_ctx *ctx, tn_tensor *a, float scale, float shift) { return tn__unary(ctx, a, TN__UN_SCALE, scale, shift); }
TN_API tn_tensor *tn_relu(tn_ctx *ctx, tn_tensor *a) { return tn__unary(ctx, a, TN__UN_RELU, 0, 0); }
TN_API tn_tensor *tn_leaky_relu(tn_ctx *ctx, tn_tensor *a, float slope) { return tn__unary(ctx, a, TN__UN_LEAKY, slope, 0); }
TN_API tn_tensor *tn_elu(tn_ctx *ctx, tn_tensor *a, float alpha) { return tn__unary(ctx, a, TN__UN_ELU, alpha, 0); }
TN_API tn_tensor *tn_tanh(tn_ctx *ctx, tn_tensor *a) { return tn__unary(ctx, a, TN__UN_TANH, 0, 0); }
TN_API tn_tensor *tn_sigmoid(tn_ctx *ctx, tn_tensor *a) { return tn__unary(ctx, a, TN__UN_SIGMOID, 0, 0); }
TN_API tn_tensor *tn_softplus(tn_ctx *ctx, tn_tensor *a) { return tn__unary(ctx, a, TN__UN_SOFTPLUS, 0, 0); }
TN_API tn_tensor *tn_abs(tn_ctx *ctx, tn_tensor *a) { return tn__unary(ctx, a, TN__UN_ABS, 0, 0); }
TN_API tn_tensor *tn_square(tn_ctx *ctx, tn_tensor *a) { return tn__unary(ctx, a, TN__UN_SQUARE, 0, 0); }
TN_API tn_tensor *tn_pow_abs(tn_ctx *ctx, tn_tensor *a, float p) { return tn__unary(ctx, a, TN__UN_POWABS, p, 0); }

/* ---- matmul / linear ---- */

static void tn__matmul_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *a = out->src[0], *b = out->src[1];
    int ta = out->ip[0], tb = out->ip[1];
    int M = out->shape[0], N = out->shape[1], K = ta ? a->shape[0] : a->shape[1];
    /* C = op(A) op(B): dA = dC op(B)^T (stored transposed when ta), dB likewise */
    if (a->requires_grad && tn__grad(ctx, a)) {
        if (!ta) tn_gemm(TN_PRECISION_AUTO, 0, !tb, M, K, N, 1.0f, out->grad, N, b->data, b->shape[1], 1.0f, a->grad, a->shape[1]);
        else tn_gemm(TN_PRECISION_AUTO, tb, 1, K, M, N, 1.0f, b->data, b->shape[1], out->grad, N, 1.0f, a->grad, a->shape[1]);
    }
    if (b->requires_grad && tn__grad(ctx, b)) {
        if (!tb) tn_gemm(TN_PRECISION_AUTO, !ta, 0, K, N, M, 1.0f, a->data, a->shape[1], out->grad, N, 1.0f, b->grad, b->shape[1]);
        else tn_gemm(TN_PRECISION_AUTO, 1, ta, N, K, M, 1.0f, out->grad, N, a->data, a->shape[1], 1.0f, b->grad, b->shape[1]);
    }
}

TN_API tn_tensor *tn_matmul(tn_ctx *ctx, tn_tensor *a, tn_tensor *b, int trans_a, int trans_b)
{
    int M, K, K2, N, shape[2];
    tn_tensor *o;
    if (!a || !b) return NULL;
    TN_ASSERT(a->ndim == 2 && b->ndim == 2);
    M = trans_a ? a->shape[1] : a->shape[0];
    K = trans_a ? a->shape[0] : a->shape[1];
    K2 = trans_b ? b->shape[1] : b->shape[0];
    N = trans_b ? b->shape[0] : b->shape[1];
    TN_ASSERT(K == K2);
    (void)K2;
    shape[0] = M;
    shape[1] = N;
    o = tn__op(ctx, 2, shape, tn__matmul_backward, a, b, NULL);
    if (!o) return NULL;
    o->ip[0] = trans_a != 0;
    o->ip[1] = trans_b != 0;
    tn_gemm(TN_PRECISION_AUTO, trans_a, trans_b, M, N, K, 1.0f, a->data, a->shape[1], b->data, b->shape[1], 0.0f, o->data, N);
    return o;
}

TN_API tn_tensor *tn_linear(tn_ctx *ctx, tn_tensor *x, tn_tensor *w, tn_tensor *bias)
{
    tn_tensor *y = tn_matmul(ctx, x, w, 0, 1);
    return bias ? tn_add(ctx, y, bias) : y;
}

/* ---- reductions ---- */

static void tn__sum_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *a = out->src[0];
    float *g = tn__grad(ctx, a), v;
    size_t i;
    if (!g) return;
    v = out->grad[0] * out->fp[0];
    for (i = 0; i < a->numel; i++) g[i] += v;
}

/* Deterministic sum: fixed-size chunks summed in double, then the chunks in order. */
static double tn__sum_floats(const float *x, size_t n)
{
    double total = 0.0;
    size_t i = 0;
    while (i < n) {
        size_t e = i + 4096 < n ? i + 4096 : n;
        float acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};
        double part = 0.0;
        for (; i + 8 <= e; i += 8) {
            int k;
            for (k = 0; k < 8; k++) acc[k] += x[i + k];
        }
        for (; i < e; i++) part += x[i];
        part += ((double)acc[0] + acc[1]) + ((double)acc[2] + acc[3]) + ((double)acc[4] + acc[5]) + ((double)acc[6] + acc[7]);
        total += part;
    }
    return total;
}

static tn_tensor *tn__reduce_all(tn_ctx *ctx, tn_tensor *a, float factor)
{
    int one = 1;
    tn_tensor *o;
    if (!a) return NULL;
    o = tn__op(ctx, 1, &one, tn__sum_backward, a, NULL, NULL);
    if (!o) return NULL;
    o->fp[0] = factor;
    o->data[0] = (float)(tn__sum_floats(a->data, a->numel) * factor);
    return o;
}

TN_API tn_tensor *tn_sum(tn_ctx *ctx, tn_tensor *a) { return tn__reduce_all(ctx, a, 1.0f); }
TN_API tn_tensor *tn_mean(tn_ctx *ctx, tn_tensor *a) { return a ? tn__reduce_all(ctx, a, 1.0f / (float)a->numel) : NULL; }

/* outer x len x inner view of a tensor around one axis */
static void tn__axis_split(const tn_tensor *a, int axis, size_t *outer, size_t *len, size_t *inner)
{
    int i;
    *outer = *inner = 1;
    for (i = 0; i < axis; i++) *outer *= (size_t)a->shape[i];
    *len = (size_t)a->shape[axis];
    for (i = axis + 1; i < a->ndim; i++) *inner *= (size_t)a->shape[i];
}

static void tn__sum_axis_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *a = out->src[0];
    float *g = tn__grad(ctx, a);
    size_t o, l, i, outer, len, inner;
    if (!g) return;
    tn__axis_split(a, out->ip[0], &outer, &len, &inner);
    for (o = 0; o < outer; o++)
        for (l = 0; l < len; l++)
            for (i = 0; i < inner; i++) g[(o * len + l) * inner + i] += out->grad[o * inner + i] * out->fp[0];
}

static tn_tensor *tn__reduce_axis(tn_ctx *ctx, tn_tensor *a, int axis, int mean)
{
    int shape[4], k;
    size_t o, l, i, outer, len, inner;
    tn_tensor *r;
    if (!a) return NULL;
    TN_ASSERT(axis >= 0 && axis < a->ndim);
    for (k = 0; k < a->ndim; k++) shape[k] = k == axis ? 1 : a->shape[k];
    r = tn__op(ctx, a->ndim, shape, tn__sum_axis_backward, a, NULL, NULL);
    if (!r) return NULL;
    tn__axis_split(a, axis, &outer, &len, &inner);
    r->ip[0] = axis;
    r->fp[0] = mean ? 1.0f / (float)len : 1.0f;
    for (o = 0; o < outer; o++)
        for (l = 0; l < len; l++)
            for (i = 0; i < inner; i++) r->data[o * inner + i] += a->data[(o * len + l) * inner + i];
    if (mean)
        for (i = 0; i < r->numel; i++) r->data[i] *= r->fp[0];
    return r;
}

TN_API tn_tensor *tn_sum_axis(tn_ctx *ctx, tn_tensor *a, int axis) { return tn__reduce_axis(ctx, a, axis, 0); }
TN_API tn_tensor *tn_mean_axis(tn_ctx *ctx, tn_tensor *a, int axis) { return tn__reduce_axis(ctx, a, axis, 1); }

/* ---- shape ops ---- */

static void tn__copy_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *a = out->src[0];
    float *g = tn__grad(ctx, a);
    size_t i;
    if (!g) return;
    for (i = 0; i < a->numel; i++) g[i] += out->grad[i];
}

TN_API tn_tensor *tn_reshape(tn_ctx *ctx, tn_tensor *a, int ndim, const int *shape)
{
    tn_tensor *o;
    if (!a) return NULL;
    o = tn__op(ctx, ndim, shape, tn__copy_backward, a, NULL, NULL);
    if (!o) return NULL;
    TN_ASSERT(o->numel == a->numel);
    memcpy(o->data, a->data, a->numel * sizeof(float));
    return o;
}

/* Offset in a (contiguous) of output index idx under permutation perm. */
static void tn__permute_walk(const tn_tensor *a, const int *perm, const tn_tensor *o, const float *src, float *dst, int backward)
{
    size_t astr[4], ostride[4], idx[4];
    int i;
    size_t k, acc = 1;
    for (i = 3; i >= 0; i--) {
        astr[i] = acc;
        acc *= (size_t)a->shape[i];
    }
    for (i = 0; i < 4; i++) ostride[i] = i < a->ndim ? astr[perm[i]] : 0;
    for (k = 0; k < o->numel; k++) {
        size_t rem = k, off = 0;
        for (i = 3; i >= 0; i--) {
            idx[i] = rem % (size_t)o->shape[i];
            rem /= (size_t)o->shape[i];
            off += idx[i] * ostride[i];
        }
        if (backward) dst[off] += src[k];
        else dst[k] = src[off];
    }
}

static void tn__permute_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *a = out->src[0];
    if (!tn__grad(ctx, a)) return;
    tn__permute_walk(a, out->ip, out, out->grad, a->grad, 1);
}

TN_API tn_tensor *tn_permute(tn_ctx *ctx, tn_tensor *a, const int *perm)
{
    int shape[4], i;
    tn_tensor *o;
    if (!a) return NULL;
    for (i = 0; i < a->ndim; i++) {
        TN_ASSERT(perm[i] >= 0 && perm[i] < a->ndim);
        shape[i] = a->shape[perm[i]];
    }
    o = tn__op(ctx, a->ndim, shape, tn__permute_backward, a, NULL, NULL);
    if (!o) return NULL;
    for (i = 0; i < 4; i++) o->ip[i] = i < a->ndim ? perm[i] : i;
    tn__permute_walk(a, o->ip, o, a->data, o->data, 0);
    return o;
}

static void tn__concat_backward(tn_ctx *ctx, tn_tensor *out)
{
    size_t o, outer, la, lb, inner, i;
    tn_tensor *a = out->src[0], *b = out->src[1];
    tn__axis_split(a, out->ip[0], &outer, &la, &inner);
    lb = (size_t)b->shape[out->ip[0]];
    for (o = 0; o < outer; o++) {
        const float *g = out->grad + o * (la + lb) * inner;
        if (a->requires_grad && tn__grad(ctx, a))
            for (i = 0; i < la * inner; i++) a->grad[o * la * inner + i] += g[i];
        if (b->requires_grad && tn__grad(ctx, b))
            for (i = 0; i < lb * inner; i++) b->grad[o * lb * inner + i] += g[la * inner + i];
    }
}

TN_API tn_tensor *tn_concat(tn_ctx *ctx, tn_tensor *a, tn_tensor *b, int axis)
{
    int shape[4], i;
    size_t o, outer, la, lb, inner;
    tn_tensor *r;
    if (!a || !b) return NULL;
    TN_ASSERT(a->ndim == b->ndim && axis >= 0 && axis < a->ndim);
    for (i = 0; i < a->ndim; i++) {
        TN_ASSERT(i == axis || a->shape[i] == b->shape[i]);
        shape[i] = i == axis ? a->shape[i] + b->shape[i] : a->shape[i];
    }
    r = tn__op(ctx, a->ndim, shape, tn__concat_backward, a, b, NULL);
    if (!r) return NULL;
    r->ip[0] = axis;
    tn__axis_split(a, axis, &outer, &la, &inner);
    lb = (size_t)b->shape[axis];
    for (o = 0; o < outer; o++) {
        memcpy(r->data + o * (la + lb) * inner, a->data + o * la * inner, la * inner * sizeof(float));
        memcpy(r->data + (o * (la + lb) + la) * inner, b->data + o * lb * inner, lb * inner * sizeof(float));
    }
    return r;
}

static void tn__slice_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *a = out->src[0];
    size_t o, outer, len, inner, i, n = (size_t)out->ip[2];
    if (!tn__grad(ctx, a)) return;
    tn__axis_split(a, out->ip[0], &outer, &len, &inner);
    for (o = 0; o < outer; o++)
        for (i = 0; i < n * inner; i++) a->grad[(o * len + (size_t)out->ip[1]) * inner + i] += out->grad[o * n * inner + i];
}

TN_API tn_tensor *tn_slice(tn_ctx *ctx, tn_tensor *a, int axis, int start, int len)
{
    int shape[4], i;
    size_t o, outer, alen, inner;
    tn_tensor *r;
    if (!a) return NULL;
    TN_ASSERT(axis >= 0 && axis < a->ndim && start >= 0 && len >= 1 && start + len <= a->shape[axis]);
    for (i = 0; i < a->ndim; i++) shape[i] = i == axis ? len : a->shape[i];
    r = tn__op(ctx, a->ndim, shape, tn__slice_backward, a, NULL, NULL);
    if (!r) return NULL;
    r->ip[0] = axis;
    r->ip[1] = start;
    r->ip[2] = len;
    tn__axis_split(a, axis, &outer, &alen, &inner);
    for (o = 0; o < outer; o++)
        memcpy(r->data + o * (size_t)len * inner, a->data + (o * alen + (size_t)start) * inner, (size_t)len * inner * sizeof(float));
    return r;
}

/* ---- convolution ----
   im2col lays the receptive field of every output pixel out as a column:
   col[(ci * KH + ky) * KW + kx][oy * OW + ox] = x[ci][oy * s - p + ky * d][ox * s - p + kx * d]
   so the convolution is a GEMM, W (M x C*KH*KW) times col. The output rows are cut into row groups
   whose number depends on the geometry only (never on the thread count); a thread takes whole
   groups and runs im2col + GEMM on L2-sized sub-bands of each, so the threads never meet. The
   weight gradient is summed per group, then over the groups in a fixed order: 1 and 2 threads
   give the same bits. The input gradient is itself a convolution (stride 1, zero padding: with
   the flipped, transposed kernel), otherwise col2im of W^T dY in two phases (even groups, then
   odd ones) whose groups never write the same input rows. */

typedef struct tn__conv_geom {
    int C, H, W, KH, KW, OH, OW, stride, pad, dil, reflect;
} tn__conv_geom;

/* Source index along one axis for output position o and kernel tap k; -1 = zero padding. */
static int tn__conv_src(int o, int k, int stride, int pad, int dil, int size, int reflect)
{
    int i = o * stride - pad + k * dil;
    if (i >= 0 && i < size) return i;
    if (!reflect) return -1;
    if (size == 1) return 0;
    while (i < 0 || i >= size) i = i < 0 ? -i : 2 * (size - 1) - i;
    return i;
}

/* Output columns [*lo, *hi) whose tap kx reads inside the row without padding: ix = ox*s + x0. */
static void tn__conv_inner(const tn__conv_geom *g, int kx, int *lo, int *hi)
{
    int x0 = kx * g->dil - g->pad, s = g->stride;
    *lo = x0 < 0 ? (-x0 + s - 1) / s : 0;
    *hi = g->W - 1 - x0 < 0 ? 0 : (g->W - 1 - x0) / s + 1;
    if (*hi > g->OW) *hi = g->OW;
    if (*lo > *hi) *lo = *hi;
}

/* d[0 .. ox1-ox0) = input row xr as tap kx sees it at output columns [ox0, ox1) (xr NULL: a
   padding row); [lo, hi) is the tap's inner range (tn__conv_inner). */
static void tn__conv_span(const tn__conv_geom *g, const float *xr, int kx, int lo, int hi, int ox0, int ox1, float *d)
{
    int ox, a = lo > ox0 ? lo : ox0, b = hi < ox1 ? hi : ox1, x0 = kx * g->dil - g->pad;
    d -= ox0; /* d[ox] from here on */
    if (!xr) {
        memset(d + ox0, 0, (size_t)(ox1 - ox0) * sizeof(float));
        return;
    }
    if (a > ox1) a = ox1;
    if (b < a) b = a;
    for (ox = ox0; ox < a; ox++) { /* left edge */
        int ix = g->reflect ? tn__conv_src(ox, kx, g->stride, g->pad, g->dil, g->W, 1) : -1;
        d[ox] = ix < 0 ? 0.0f : xr[ix];
    }
    if (g->stride == 1) memcpy(d + a, xr + x0 + a, (size_t)(b - a) * sizeof(float));
    else
        for (ox = a; ox < b; ox++) d[ox] = xr[ox * g->stride + x0];
    for (ox = b; ox < ox1; ox++) { /* right edge */
        int ix = g->reflect ? tn__conv_src(ox, kx, g->stride, g->pad, g->dil, g->W, 1) : -1;
        d[ox] = ix < 0 ? 0.0f : xr[ix];
    }
}

/* col = im2col(x) for output rows [oy0, oy1) of one image (col row r holds (oy1 - oy0) * OW). */
static void tn__im2col_band(const tn__conv_geom *g, const float *x, float *col, int oy0, int oy1)
{
    size_t band = (size_t)(oy1 - oy0) * g->OW;
    int ci, ky, kx, oy, lo, hi;
    for (ci = 0; ci < g->C; ci++)
        for (ky = 0; ky < g->KH; ky++)
            for (kx = 0; kx < g->KW; kx++, col += band) {
                tn__conv_inner(g, kx, &lo, &hi);
                for (oy = oy0; oy < oy1; oy++) {
                    int iy = tn__conv_src(oy, ky, g->stride, g->pad, g->dil, g->H, g->reflect);
                    const float *xr = iy < 0 ? NULL : x + ((size_t)ci * g->H + iy) * g->W;
                    tn__conv_span(g, xr, kx, lo, hi, 0, g->OW, col + (size_t)(oy - oy0) * g->OW);
                }
            }
}

/* im2col packed straight into the GEMM's B panels (tn__gemm_pack_fn): column j of the band is
   output pixel oy0 * OW + j of image x; row C*KH*KW, if asked for, is ones (times the bias). */
#define TN__CONV_KW_TAB 16
typedef struct tn__conv_pack {
    const tn__conv_geom *g;
    const float *x;
    int oy0;
    int lo[TN__CONV_KW_TAB], hi[TN__CONV_KW_TAB]; /* tn__conv_inner of each kx (if KW fits) */
} tn__conv_pack;

static void tn__conv_pack_init(tn__conv_pack *p, const tn__conv_geom *g, const float *x, int oy0)
{
    int kx;
    p->g = g;
    p->x = x;
    p->oy0 = oy0;
    for (kx = 0; kx < g->KW && kx < TN__CONV_KW_TAB; kx++) tn__conv_inner(g, kx, &p->lo[kx], &p->hi[kx]);
}

static void tn__conv_pack_b(void *ctx, int k0, int kc, int j0, int nc, float *pb)
{
    const tn__conv_pack *p = (const tn__conv_pack *)ctx;
    const tn__conv_geom *g = p->g;
    size_t panel = tn__gemm_b_stride(kc);
    int k, t, kx = (k0 % g->KW) - 1, ky = (k0 / g->KW) % g->KH, ci = k0 / (g->KW * g->KH);
    for (k = 0; k < kc; k++) { /* row by row: each source row is read sequentially */
        int lo, hi, x0, j = 0;
        if (k0 + k == g->C * g->KH * g->KW) { /* the bias row: ones */
            float *d = pb + (size_t)k * TN__GEMM_NR;
            for (j = 0; j < nc; j += TN__GEMM_NR, d += panel)
                for (t = 0; t < TN__GEMM_NR; t++) d[t] = j + t < nc ? 1.0f : 0.0f;
            continue;
        }
        if (++kx == g->KW && (kx = 0, ++ky == g->KH)) { /* next tap (ci, ky, kx) */
            ky = 0;
            ci++;
        }
        x0 = kx * g->dil - g->pad;
        if (kx < TN__CONV_KW_TAB) {
            lo = p->lo[kx];
            hi = p->hi[kx];
        } else {
            tn__conv_inner(g, kx, &lo, &hi);
        }
        while (j < nc) { /* one output row at a time, in pieces that stay inside one panel */
            int pix = j0 + j, oy = p->oy0 + pix / g->OW, ox = pix % g->OW, end = j + g->OW - ox;
            int iy = tn__conv_src(oy, ky, g->stride, g->pad, g->dil, g->H, g->reflect);
            const float *xr = iy < 0 ? NULL : p->x + ((size_t)ci * g->H + iy) * g->W;
            if (end > nc) end = nc;
            while (j < end) {
                int n = TN__GEMM_NR - j % TN__GEMM_NR;
                float *d = pb + (size_t)(j / TN__GEMM_NR) * panel + (size_t)k * TN__GEMM_NR + j % TN__GEMM_NR;
                if (n > end - j) n = end - j;
                if (xr && g->stride == 1 && n == TN__GEMM_NR && ox >= lo && ox + n <= hi)
                    memcpy(d, xr + x0 + ox, TN__GEMM_NR * sizeof(float)); /* inlined */
                else
                    tn__conv_span(g, xr, kx, lo, hi, ox, ox + n, d);
                j += n;
                ox += n;
            }
        }
        if (nc % TN__GEMM_NR) /* columns past nc are zero, as in tn__gemm_pack_b */
            for (t = nc % TN__GEMM_NR; t < TN__GEMM_NR; t++)
                pb[(size_t)(nc / TN__GEMM_NR) * panel + (size_t)k * TN__GEMM_NR + t] = 0.0f;
    }
}

/* dx += col2im(col) for output rows [oy0, oy1) of one image: the adjoint of tn__im2col_band, each
   element's additions in a fixed order. */
static void tn__col2im_band(const tn__conv_geom *g, const float *col, float *dx, int oy0, int oy1)
{
    size_t band = (size_t)(oy1 - oy0) * g->OW;
    int ci, ky, kx, oy, ox, lo, hi;
    for (ci = 0; ci < g->C; ci++)
        for (ky = 0; ky < g->KH; ky++)
            for (kx = 0; kx < g->KW; kx++, col += band) {
                int x0 = kx * g->dil - g->pad;
                tn__conv_inner(g, kx, &lo, &hi);
                for (oy = oy0; oy < oy1; oy++) {
                    int iy = tn__conv_src(oy, ky, g->stride, g->pad, g->dil, g->H, g->reflect);
                    const float *d = col + (size_t)(oy - oy0) * g->OW;
                    float *xr = dx + ((size_t)ci * g->H + (iy < 0 ? 0 : iy)) * g->W;
                    if (iy < 0) continue;
                    for (ox = 0; ox < lo; ox++) {
                        int ix = tn__conv_src(ox, kx, g->stride, g->pad, g->dil, g->W, g->reflect);
                        if (ix >= 0) xr[ix] += d[ox];
                    }
                    if (g->stride == 1)
                        for (ox = lo; ox < hi; ox++) xr[ox + x0] += d[ox];
                    else
                        for (ox = lo; ox < hi; ox++) xr[ox * g->stride + x0] += d[ox];
                    for (ox = hi; ox < g->OW; ox++) {
                        int ix = tn__conv_src(ox, kx, g->stride, g->pad, g->dil, g->W, g->reflect);
                        if (ix >= 0) xr[ix] += d[ox];
                    }
                }
            }
}

static int tn__conv_is_1x1(const tn__conv_geom *g)
{
    return g->KH == 1 && g->KW == 1 && g->stride == 1 && g->pad == 0;
}

/* Row groups: at most 16 and about 256 output pixels or more each; their M x K weight-gradient
   partials stay under 16 MiB. A function of the geometry only, so results never depend on it. */
static int tn__conv_groups(const tn__conv_geom *g, int M)
{
    size_t k = (size_t)g->C * g->KH * g->KW, groups = (size_t)g->OH * g->OW / 256;
    if (groups > 16) groups = 16;
    if (groups > (size_t)g->OH) groups = (size_t)g->OH;
    if (groups * M * k > ((size_t)1 << 22)) groups = ((size_t)1 << 22) / (M * k);
    return groups < 1 ? 1 : (int)groups;
}

/* Output rows per sub-band: about 64K floats (256 KiB) of columns, so im2col's output is still in
   L2 when the GEMM packs it. */
#ifndef TN__CONV_SUB_FLOATS
#define TN__CONV_SUB_FLOATS (1 << 16)
#endif
static int tn__conv_sub_rows(const tn__conv_geom *g)
{
    size_t per_row = (size_t)g->C * g->KH * g->KW * g->OW, rows = (size_t)TN__CONV_SUB_FLOATS / (per_row ? per_row : 1);
    if (rows < 1) rows = 1;
    if (rows > (size_t)g->OH) rows = (size_t)g->OH;
    return (int)rows;
}

/* One convolution pass over row groups; which pass the task function decides. */
typedef struct tn__conv_job {
    tn__conv_geom g;
    int N, M, K, groups, sub, phase; /* col2im: groups of this parity; dw: partials transposed */
    int mparts;                      /* forward: output channels split this many ways */
    int kd, dw_direct;               /* dw: K (+ 1 with the bias gradient); sums straight into dw */
    const float *x, *w, *bias, *dy;  /* x: N x C x H x W, w: M x K, dy: N x M x OH x OW */
    float *y, *dx, *dw;              /* y like dy, dx like x; dw: groups partials of M x K */
    float beta;                      /* forward: y = beta * y + conv */
    const float *wb;                 /* forward: w with the bias appended to each row (or w) */
    float *scratch;                  /* per thread: scratch_floats for columns / packing */
    size_t scratch_floats;
    int next;                        /* next unclaimed item (atomic) */
} tn__conv_job;

static void tn__conv_group_rows(const tn__conv_job *j, int gi, int *r0, int *r1)
{
    *r0 = (int)((long long)j->g.OH * gi / j->groups);
    *r1 = (int)((long long)j->g.OH * (gi + 1) / j->groups);
}

/* The next item for thread ith of nth, -1 when none is left. With atomics a free thread takes
   the next one (an item's result does not depend on which thread computes it, and a thread the
   OS preempts then holds up only its current item); otherwise a fixed contiguous share. */
#if !defined(TN_NO_THREADS) && (defined(__GNUC__) || defined(__clang__))
#define TN__CONV_DYNAMIC 1
#endif
static int tn__conv_claim(const tn__conv_job *j, int items, int ith, int nth, int *cursor)
{
#ifdef TN__CONV_DYNAMIC
    int it = __atomic_fetch_add((int *)&j->next, 1, __ATOMIC_RELAXED);
    (void)ith;
    (void)nth;
    (void)cursor;
    return it < items ? it : -1;
#else
    int b = (int)((long long)items * ith / nth), e = (int)((long long)items * (ith + 1) / nth);
    (void)j;
    if (*cursor < b) *cursor = b;
    return *cursor < e ? (*cursor)++ : -1;
#endif
}

/* Products up to this size go through tn_sgemm's unpacked loops (on an im2col buffer of at most
   this many floats); decided on the whole M, so every split computes them the same way. */
#define TN__CONV_TINY TN__GEMM_SMALL
#ifndef TN__CONV_FWD_PIX
#define TN__CONV_FWD_PIX 2048
#endif

/* Items are (image, group, channel part): y rows = W im2col(x rows) (+ bias), with im2col packed
   straight into the GEMM panels. Each output element's sum is the same for any split. */
static void tn__conv_fwd_task(void *ctx, int ith, int nth)
{
    const tn__conv_job *j = (const tn__conv_job *)ctx;
    const tn__conv_geom *g = &j->g;
    size_t ohw = (size_t)g->OH * g->OW, chw = (size_t)g->C * g->H * g->W;
    float *buf = j->scratch + (size_t)ith * j->scratch_floats, *col = buf + j->scratch_floats - TN__CONV_TINY;
    int parts = j->groups * j->mparts, mtiles = (j->M + TN__GEMM_MR - 1) / TN__GEMM_MR, it, cur = -1, r0, r1, oy, m;
    while ((it = tn__conv_claim(j, j->N * parts, ith, nth, &cur)) >= 0) {
        int mp = it % j->mparts, m0 = mtiles * mp / j->mparts * TN__GEMM_MR, m1 = mtiles * (mp + 1) / j->mparts * TN__GEMM_MR;
        const float *xn = j->x + (size_t)(it / parts) * chw, *wm;
        float *yn = j->y + (size_t)(it / parts) * j->M * ohw;
        if (m1 > j->M) m1 = j->M;
        if (m0 >= m1) continue;
        wm = j->w + (size_t)m0 * j->K;
        tn__conv_group_rows(j, it % parts / j->mparts, &r0, &r1);
        for (oy = r0; oy < r1; oy += j->sub) {
            int oy1 = oy + j->sub < r1 ? oy + j->sub : r1, band = (oy1 - oy) * g->OW;
            float *yb = yn + (size_t)m0 * ohw + (size_t)oy * g->OW;
            if ((double)j->M * band * j->K <= TN__CONV_TINY) {
                tn__im2col_band(g, xn, col, oy, oy1);
                tn_gemm(TN_PRECISION_AUTO, 0, 0, m1 - m0, band, j->K, 1.0f, wm, j->K, col, band, j->beta, yb, (int)ohw);
            } else { /* the bias is folded in as weight column K against a row of ones */
                tn__conv_pack pk;
                int kb = j->K + (j->bias != NULL);
                tn__conv_pack_init(&pk, g, xn, oy);
                tn__sgemm_gen_b(m1 - m0, band, kb, j->wb + (size_t)m0 * kb, kb, tn__conv_pack_b, &pk, j->beta, yb, (int)ohw, buf);
                continue;
            }
            if (j->bias)
                for (m = m0; m < m1; m++) {
                    float *p = yb + (size_t)(m - m0) * ohw, bm = j->bias[m];
                    int i;
                    for (i = 0; i < band; i++) p[i] += bm;
                }
        }
    }
}

/* Items are groups: partial[group] = sum over images and sub-bands of dy rows x im2col(x rows)^T. */
static void tn__conv_dw_task(void *ctx, int ith, int nth)
{
    const tn__conv_job *j = (const tn__conv_job *)ctx;
    const tn__conv_geom *g = &j->g;
    size_t ohw = (size_t)g->OH * g->OW, chw = (size_t)g->C * g->H * g->W;
    float *col = j->scratch + (size_t)ith * j->scratch_floats;
    int gi, cur = -1, r0, r1, oy, n;
    while ((gi = tn__conv_claim(j, j->groups, ith, nth, &cur)) >= 0) {
        float *part = j->dw + (size_t)gi * j->M * j->kd, beta = j->dw_direct ? 1.0f : 0.0f;
        tn__conv_group_rows(j, gi, &r0, &r1);
        for (n = 0; n < j->N; n++)
            for (oy = r0; oy < r1; oy += j->sub) {
                int oy1 = oy + j->sub < r1 ? oy + j->sub : r1, band = (oy1 - oy) * g->OW;
                const float *xn = j->x + (size_t)n * chw, *dyb = j->dy + (size_t)n * j->M * ohw + (size_t)oy * g->OW;
                const float *cb = col;
                int ldc = band;
                if (tn__conv_is_1x1(g)) {
                    cb = xn + (size_t)oy * g->OW;
                    ldc = (int)ohw;
                } else {
                    int i;
                    tn__im2col_band(g, xn, col, oy, oy1);
                    if (j->kd > j->K) /* a row of ones: the bias gradient comes out as column K */
                        for (i = 0; i < band; i++) col[(size_t)j->K * band + i] = 1.0f;
                }
                if (j->phase) /* transposed partial: kd x M = col dy^T */
                    tn_gemm(TN_PRECISION_AUTO, 0, 1, j->kd, j->M, band, 1.0f, cb, ldc, dyb, (int)ohw, beta, part, j->M);
                else
                    tn_gemm(TN_PRECISION_AUTO, 0, 1, j->M, j->kd, band, 1.0f, dyb, (int)ohw, cb, ldc, beta, part, j->kd);
                beta = 1.0f; /* the first product of a group initialises its partial */
            }
    }
}

/* Items are (image, group of parity `phase`) pairs: dx += col2im(W^T dy rows). */
static void tn__conv_dx_task(void *ctx, int ith, int nth)
{
    const tn__conv_job *j = (const tn__conv_job *)ctx;
    const tn__conv_geom *g = &j->g;
    size_t ohw = (size_t)g->OH * g->OW, chw = (size_t)g->C * g->H * g->W;
    float *col = j->scratch + (size_t)ith * j->scratch_floats;
    int per = (j->groups - j->phase + 1) / 2, it, cur = -1, r0, r1, oy;
    while ((it = tn__conv_claim(j, j->N * per, ith, nth, &cur)) >= 0) {
        int n = it / per;
        tn__conv_group_rows(j, 2 * (it % per) + j->phase, &r0, &r1);
        for (oy = r0; oy < r1; oy += j->sub) {
            int oy1 = oy + j->sub < r1 ? oy + j->sub : r1, band = (oy1 - oy) * g->OW;
            tn_gemm(TN_PRECISION_AUTO, 1, 0, j->K, band, j->M, 1.0f, j->w, j->K, j->dy + (size_t)n * j->M * ohw + (size_t)oy * g->OW,
                     (int)ohw, 0.0f, col, band);
            tn__col2im_band(g, col, j->dx + (size_t)n * chw, oy, oy1);
        }
    }
}

/* Sets up a job's split and `floats` of scratch per thread; 0 when the arena is out of memory. */
static int tn__conv_job_init(tn_ctx *ctx, tn__conv_job *j, const tn__conv_geom *g, int N, int M, int groups, size_t floats)
{
    memset(j, 0, sizeof *j);
    j->g = *g;
    j->N = N;
    j->M = M;
    j->K = g->C * g->KH * g->KW;
    j->groups = groups;
    j->sub = tn__conv_sub_rows(g);
    j->mparts = 1;
    j->scratch_floats = (floats + 15) / 16 * 16; /* 64-byte aligned per thread */
    j->scratch = tn__ctx_floats(ctx, (size_t)tn_get_threads() * j->scratch_floats, 0);
    return j->scratch != NULL;
}

/* Column buffer of one sub-band (im2col for the weight gradient, W^T dy for col2im). */
static size_t tn__conv_col_floats(const tn__conv_geom *g)
{
    return (size_t)g->C * g->KH * g->KW * tn__conv_sub_rows(g) * g->OW;
}

/* Runs fn over the pool, or inline when there is a single item (the GEMMs then use the pool). */
static void tn__conv_run(tn_task_fn fn, tn__conv_job *j, int items)
{
    j->next = 0;
    if (items <= 1 || tn_get_threads() <= 1) fn(j, 0, 1);
    else tn_parallel_run(fn, j);
}

#ifdef TN__BF16_HW
/* The forward on AMX tiles without im2col (tn__amx_conv in >>gemm_bf16): the input converted once
   to padded rows of bf16 channel pairs (a ninth of im2col's writes, half their bytes), the
   weights to A tiles per tap. Stride 1 only; up to TN__CONV_AMX_TAPS taps. */
#define TN__CONV_AMX_TAPS 64
typedef struct tn__conv_amx_job {
    const tn__conv_geom *g;
    const float *x;
    int N, Hp, Wp, chunks;         /* chunks: of 32 positions per image */
    const int *colmap;             /* padded column -> input column, -1: zero */
    tn__amx_conv c;                /* image 0's; xp and y step by image */
    int off[TN__CONV_AMX_TAPS];
} tn__conv_amx_job;

/* A row of bf16 values or pair words of padded width: x row r0 (and r1 for pairs) through colmap,
   the inside [pad, pad + W) converted 16 or 32 at a time; zeros from Wp to Wr. */
static void tn__conv_amx_pad_row(const tn__conv_geom *g, const int *colmap, int Wp, int Wr, const float *r0, const float *r1,
                                 uint32_t *words, uint16_t *halves)
{
    int ix;
    if (words) tn__bf16_pair_words(r0, r1, words + g->pad, g->W);
    else tn__bf16_halves(r0, halves + g->pad, g->W);
    for (ix = 0; ix < Wp; ix++) { /* the padding columns */
        int sx = colmap[ix];
        uint32_t v;
        if (ix == g->pad) {
            ix += g->W - 1; /* the inside is done */
            continue;
        }
        v = sx < 0 ? 0u : tn__bf16_bits(r0[sx]) >> 16 | (r1 ? tn__bf16_bits(r1[sx]) & 0xffff0000u : 0u);
        if (words) words[ix] = v;
        else halves[ix] = (uint16_t)v;
    }
    if (words) memset(words + Wp, 0, (size_t)(Wr - Wp) * sizeof(uint32_t));
    else memset(halves + Wp, 0, (size_t)(Wr - Wp) * sizeof(uint16_t));
}

/* Padded column -> input column (-1: zero) for the AMX convolutions' rows; NULL out of memory. */
static const int *tn__conv_amx_colmap(tn_ctx *ctx, const tn__conv_geom *g, int Wp)
{
    int h, *colmap = (int *)tn_ctx_alloc(ctx, (size_t)Wp * sizeof(int));
    if (colmap)
        for (h = 0; h < Wp; h++) colmap[h] = tn__conv_src(h, 0, 1, g->pad, 1, g->W, g->reflect);
    return colmap;
}

/* The AMX convolutions' two passes (bf16 copies, then tiles) on the pool, or inline when small. */
static void tn__conv_amx_run(tn_task_fn prep, tn_task_fn task, void *job, double work)
{
    if (tn_get_threads() <= 1 || work < TN__GEMM_PAR_MIN) {
        prep(job, 0, 1);
        task(job, 0, 1);
    } else {
        tn_parallel_run(prep, job);
        tn_parallel_run(task, job);
    }
}

/* Padded rows [N*Hp*ith/nth, ...): each one's channel-pair rows. */
static void tn__conv_amx_prep_task(void *ctx, int ith, int nth)
{
    const tn__conv_amx_job *j = (const tn__conv_amx_job *)ctx;
    const tn__conv_geom *g = j->g;
    int total = j->N * j->Hp, b = (int)((long long)total * ith / nth), e = (int)((long long)total * (ith + 1) / nth), it, p;
    size_t hw = (size_t)g->H * g->W;
    for (it = b; it < e; it++) {
        int n = it / j->Hp, iy = tn__conv_src(it % j->Hp, 0, 1, g->pad, 1, g->H, g->reflect);
        uint32_t *d = (uint32_t *)j->c.xp + (size_t)it * j->c.prow * j->c.Wr;
        for (p = 0; p < j->c.prow; p++, d += j->c.Wr) {
            const float *r0 = j->x + ((size_t)n * g->C + 2 * p) * hw + (size_t)iy * g->W;
            if (iy < 0 || 2 * p >= g->C) memset(d, 0, (size_t)j->c.Wr * sizeof(uint32_t));
            else tn__conv_amx_pad_row(g, j->colmap, j->Wp, j->c.Wr, r0, 2 * p + 1 < g->C ? r0 + hw : NULL, d, NULL);
        }
    }
}

/* Chunks [N*chunks*ith/nth, ...), image by image. */
static void tn__conv_amx_task(void *ctx, int ith, int nth)
{
    const tn__conv_amx_job *j = (const tn__conv_amx_job *)ctx;
    long long total = (long long)j->N * j->chunks, b = total * ith / nth, e = total * (ith + 1) / nth;
    while (b < e) {
        int n = (int)(b / j->chunks), c0 = (int)(b % j->chunks), c1 = e - (long long)n * j->chunks < j->chunks ? (int)(e - (long long)n * j->chunks) : j->chunks;
        tn__amx_conv c = j->c;
        c.rows += (size_t)ith * 32 * ((c.OW + 31) / 32 * 32);
        c.xp += (size_t)n * j->Hp * c.prow * c.Wr;
        c.y += (size_t)n * c.M * c.OH * c.OW;
        tn__amx_conv_rows(&c, c0, c1);
        b += c1 - c0;
    }
}

/* Padded row length (elements) for tiles of 32 positions: past the last chunk's reads, and an odd
   number of 64-byte lines (`line` elements), so a tile's 16 rows fall in 16 different L1 sets. */
static int tn__conv_amx_row(const tn__conv_geom *g, int Wp, int line)
{
    int w = (g->OW + 31) / 32 * 32 + g->dil * (g->KW - 1);
    if (w < Wp) w = Wp;
    w = (w + line - 1) / line;
    return (w | 1) * line;
}

/* A tile product costs the same whatever its channel count, so with one channel 3 x 3 taps cost
   nine products for 1/32 of their work. Up to 32 channels x taps the taps become channels instead:
   *v is a 1 x 1 convolution of the OH x OW im2col of x (channel c * KH * KW + t: w's own layout),
   one product per chunk. NULL when out of memory. */
static const float *tn__conv_amx_taps_as_channels(tn_ctx *ctx, const tn__conv_geom *g, int N, const float *x, tn__conv_geom *v)
{
    size_t per = (size_t)g->C * g->KH * g->KW * g->OH * g->OW;
    float *xv = tn__ctx_floats(ctx, (size_t)N * per, 0);
    int n;
    if (!xv) return NULL;
    for (n = 0; n < N; n++) tn__im2col_band(g, x + (size_t)n * g->C * g->H * g->W, xv + (size_t)n * per, 0, g->OH);
    memset(v, 0, sizeof *v);
    v->C = g->C * g->KH * g->KW;
    v->H = v->OH = g->OH;
    v->W = v->OW = g->OW;
    v->KH = v->KW = v->stride = v->dil = 1;
    return xv;
}

/* Whether the taps go as channels: up to 32 of them, and an im2col of at most 2^26 floats (256
   MiB; beyond, the 32-channel steps, which need no copy larger than the input). */
static int tn__conv_amx_taps_fit(const tn__conv_geom *g, int N)
{
    size_t ntaps = (size_t)g->KH * g->KW;
    return ntaps > 1 && g->C * ntaps <= 32 && (size_t)N * g->C * ntaps * g->OH * g->OW <= ((size_t)1 << 26);
}

/* 1 done, 0 out of memory, -1 not for this geometry or CPU (the caller goes on with im2col). */
static int tn__conv_forward_amx(tn_ctx *ctx, const tn__conv_geom *g, int N, int M, const float *x, const float *w,
                                const float *bias, float *y, float beta)
{
    tn__conv_amx_job j;
    int ntaps = g->KH * g->KW, mtiles = (M + 15) / 16, t, s, mt, r, h;
    size_t wa_halves, xp_words;
    uint16_t *wa;
    if (tn__gemm_kern(TN_PRECISION_AUTO) != TN__KERN_AMX || g->stride != 1 || ntaps > TN__CONV_AMX_TAPS) return -1;
    if (tn__conv_amx_taps_fit(g, N)) { /* few channels: see tn__conv_amx_taps_as_channels */
        tn__conv_geom v;
        const float *xv = tn__conv_amx_taps_as_channels(ctx, g, N, x, &v);
        return xv ? tn__conv_forward_amx(ctx, &v, N, M, xv, w, bias, y, beta) : 0;
    }
    memset(&j, 0, sizeof j);
    j.g = g;
    j.x = x;
    j.N = N;
    j.Hp = g->H + 2 * g->pad;
    j.Wp = g->W + 2 * g->pad;
    j.c.ksteps = (g->C + 31) / 32;
    j.c.kpairs = j.c.ksteps == 1 ? (g->C + 1) / 2 : 16; /* later steps: channels padded with zeros */
    j.c.prow = j.c.ksteps == 1 ? j.c.kpairs : 16 * j.c.ksteps;
    j.c.Wr = tn__conv_amx_row(g, j.Wp, 16);
    j.chunks = g->OH * ((g->OW + 31) / 32);
    j.c.ntaps = ntaps;
    j.c.M = M;
    j.c.OW = g->OW;
    j.c.OH = g->OH;
    j.c.y = y;
    j.c.bias = bias;
    j.c.beta = beta;
    j.c.off = j.off;
    for (t = 0; t < ntaps; t++) j.off[t] = (t / g->KW) * g->dil * j.c.prow * j.c.Wr + (t % g->KW) * g->dil;
    wa_halves = (size_t)mtiles * ntaps * j.c.ksteps * 512;
    xp_words = (size_t)N * j.Hp * j.c.prow * j.c.Wr;
    wa = (uint16_t *)tn_ctx_alloc(ctx, wa_halves * sizeof(uint16_t));
    j.c.xp = (const uint32_t *)tn_ctx_alloc(ctx, xp_words * sizeof(uint32_t));
    j.colmap = tn__conv_amx_colmap(ctx, g, j.Wp);
    j.c.rows = tn__ctx_floats(ctx, (size_t)tn_get_threads() * 32 * ((g->OW + 31) / 32 * 32), 0);
    if (!wa || !j.c.xp || !j.colmap || !j.c.rows) return 0;
    for (mt = 0; mt < mtiles; mt++) /* tile (mt, t, s): rows m = 16 mt + r, columns c = 32 s + h */
        for (t = 0; t < ntaps; t++)
            for (s = 0; s < j.c.ksteps; s++) {
                uint16_t *tile = wa + (((size_t)mt * ntaps + t) * j.c.ksteps + s) * 512;
                for (r = 0; r < 16; r++)
                    for (h = 0; h < 32; h++) {
                        int m = mt * 16 + r, c = s * 32 + h;
                        tile[r * 32 + h] = m < M && c < g->C ? (uint16_t)(tn__bf16_bits(w[((size_t)m * g->C + c) * ntaps + t]) >> 16) : 0;
                    }
            }
    j.c.wa = wa;
    tn__conv_amx_run(tn__conv_amx_prep_task, tn__conv_amx_task, &j, (double)N * M * g->OH * g->OW * ntaps * g->C);
    return 1;
}
#endif

/* y = beta * y + conv(x, w) (+ bias): x N x g.C x H x W, w M x K, y N x M x OH x OW. */
static int tn__conv_forward(tn_ctx *ctx, const tn__conv_geom *g, int N, int M, const float *x, const float *w,
                            const float *bias, float *y, float beta)
{
    tn__conv_job j;
    int items, nth = tn_get_threads(), mtiles = (M + TN__GEMM_MR - 1) / TN__GEMM_MR;
#ifdef TN__BF16_HW
    int direct = tn__conv_forward_amx(ctx, g, N, M, x, w, bias, y, beta);
    if (direct >= 0) return direct;
#endif
    if (!tn__conv_job_init(ctx, &j, g, N, M, tn__conv_groups(g, M), tn__sgemm_gen_b_floats(M) + TN__CONV_TINY))
        return 0;
    j.sub = (int)(TN__CONV_FWD_PIX / (size_t)g->OW); /* pixels per GEMM */
    if (j.sub < 1) j.sub = 1;
    items = N * j.groups;
    if (items < 2 * nth) { /* few groups (small images): also split the output channels */
        j.mparts = (2 * nth + items - 1) / items;
        if (j.mparts > mtiles) j.mparts = mtiles;
    }
    j.x = x;
    j.w = j.wb = w;
    j.bias = bias;
    j.y = y;
    j.beta = beta;
    if (bias) { /* M x (K + 1): [w | bias] */
        float *wb = tn__ctx_floats(ctx, (size_t)M * (j.K + 1), 0);
        int m;
        if (!wb) return 0;
        for (m = 0; m < M; m++) {
            memcpy(wb + (size_t)m * (j.K + 1), w + (size_t)m * j.K, (size_t)j.K * sizeof(float));
            wb[(size_t)m * (j.K + 1) + j.K] = bias[m];
        }
        j.wb = wb;
    }
    tn__conv_run(tn__conv_fwd_task, &j, items * j.mparts);
    return 1;
}

/* Adds bias[c] to every pixel of channel c; its gradient is the per-channel sum. */
static void tn__bias_add(float *y, const float *bias, int N, int C, size_t hw)
{
    int n, c;
    size_t i;
    for (n = 0; n < N; n++)
        for (c = 0; c < C; c++) {
            float *p = y + ((size_t)n * C + c) * hw, b = bias[c];
            for (i = 0; i < hw; i++) p[i] += b;
        }
}

typedef struct tn__bias_job { float *gb; const float *gy; int N, C; size_t hw; } tn__bias_job;

static void tn__bias_grad_channels(void *ctx, size_t cb, size_t ce)
{
    const tn__bias_job *j = (const tn__bias_job *)ctx;
    size_t c;
    int n;
    for (c = cb; c < ce; c++)
        for (n = 0; n < j->N; n++) j->gb[c] += (float)tn__sum_floats(j->gy + ((size_t)n * j->C + c) * j->hw, j->hw);
}

static void tn__bias_grad(float *gb, const float *gy, int N, int C, size_t hw)
{
    tn__bias_job j;
    j.gb = gb;
    j.gy = gy;
    j.N = N;
    j.C = C;
    j.hw = hw;
    tn_parallel_for((size_t)C, hw * N >= 16384 ? 1 : (size_t)C, tn__bias_grad_channels, &j);
}

typedef struct tn__conv_sum_job {
    float *dw, *db;
    const float *parts;
    size_t n;
    int groups, M, K, kd, transposed;
} tn__conv_sum_job;

/* Element i = (m, k) of the M x kd weight(+bias) gradient += the groups' partials, in group order. */
static void tn__conv_sum_parts(void *ctx, size_t b, size_t e)
{
    const tn__conv_sum_job *s = (const tn__conv_sum_job *)ctx;
    size_t i;
    int k;
    for (i = b; i < e; i++) {
        size_t m = i / (size_t)s->kd, c = i % (size_t)s->kd, at = s->transposed ? c * s->M + m : i;
        float acc = s->parts[at];
        for (k = 1; k < s->groups; k++) acc += s->parts[(size_t)k * s->n + at];
        if (c < (size_t)s->K) s->dw[m * s->K + c] += acc;
        else s->db[m] += acc;
    }
}

/* Whether the weight gradient is better computed transposed (col dy^T): the micro-kernel pads
   rows to MR and columns to NR, so take the form with less padding (a lone bias column would
   cost a whole NR panel), then the one whose packing has fewer element-by-element leftovers. */
static int tn__conv_dw_transposed(int M, int K)
{
    long long mr = TN__GEMM_MR, nr = TN__GEMM_NR;
    long long plain = (M + mr - 1) / mr * mr * ((K + nr - 1) / nr * nr), trans = (K + mr - 1) / mr * mr * ((M + nr - 1) / nr * nr);
    if (plain != trans) return trans < plain;
    return K % TN__GEMM_MR + M % TN__GEMM_NR < M % TN__GEMM_MR + K % TN__GEMM_NR;
}

#ifdef TN__BF16_HW
/* The weight gradient on AMX tiles without im2col (tn__amx_dw in >>gemm_bf16); stride 1. */
typedef struct tn__conv_amxdw_job {
    const tn__conv_geom *g;
    const float *x, *dy;
    int Wp;
    const int *colmap;    /* padded column -> input column, -1: zero */
    uint16_t *tmp;        /* per thread: 16 rows of Wq halves */
    float *acc;           /* per item: a 32 x 32 block of sums */
    int band;             /* output rows per band */
    tn__amx_dw d;
    int off[TN__CONV_AMX_TAPS];
} tn__conv_amxdw_job;

/* Items N * (Hp + OH * mp / 16): a padded row of the input (cp channel rows of bf16), or 16
   output channels of one output row of dy transposed to pair words (zeros past OW and M). */
static void tn__conv_amxdw_prep_task(void *ctx, int ith, int nth)
{
    const tn__conv_amxdw_job *j = (const tn__conv_amxdw_job *)ctx;
    const tn__conv_geom *g = j->g;
    const tn__amx_dw *d = &j->d;
    int mb16 = d->mp / 16, per = d->Hp + g->OH * mb16, total = d->N * per;
    int b = (int)((long long)total * ith / nth), e = (int)((long long)total * (ith + 1) / nth), it, c, i, k, half = d->Wq / 2;
    size_t hw = (size_t)g->H * g->W;
    uint16_t *tmp = j->tmp + (size_t)ith * 16 * d->Wq;
    for (it = b; it < e; it++) {
        int n = it / per, item = it % per;
        if (item < d->Hp) { /* padded input row `item` */
            int iy = tn__conv_src(item, 0, 1, g->pad, 1, g->H, g->reflect);
            uint16_t *row = (uint16_t *)d->xh + ((size_t)n * d->Hp + item) * d->cp * d->Wr;
            for (c = 0; c < d->cp; c++, row += d->Wr) {
                if (iy < 0 || c >= g->C) memset(row, 0, (size_t)d->Wr * sizeof(uint16_t));
                else tn__conv_amx_pad_row(g, j->colmap, j->Wp, d->Wr, j->x + ((size_t)n * g->C + c) * hw + (size_t)iy * g->W, NULL, NULL, row);
            }
            continue;
        }
        item -= d->Hp;
        { /* output row oy, output channels [m0, m0 + 16) */
            int oy = item / mb16, m0 = item % mb16 * 16;
            uint32_t *out = (uint32_t *)d->dyt + (((size_t)n * g->OH + oy) * half) * d->mp + m0, word;
            for (i = 0; i < 16; i++) {
                uint16_t *t = tmp + (size_t)i * d->Wq;
                int m = m0 + i;
                if (m < d->M) {
                    tn__bf16_halves(j->dy + (((size_t)n * d->M + m) * g->OH + oy) * g->OW, t, g->OW);
                    memset(t + g->OW, 0, (size_t)(d->Wq - g->OW) * sizeof(uint16_t));
                } else {
                    memset(t, 0, (size_t)d->Wq * sizeof(uint16_t));
                }
            }
            if (tn__cpu_flags & TN_CPU_AVX512F) /* half is a multiple of 16 */
                for (k = 0; k < half; k += 16) tn__transpose16_words(tmp + 2 * k, d->Wq / 2, out + (size_t)k * d->mp, d->mp);
            else
                for (k = 0; k < half; k++, out += d->mp) /* a 16-word row per position pair */
                    for (i = 0; i < 16; i++) {
                        memcpy(&word, tmp + (size_t)i * d->Wq + 2 * k, sizeof word);
                        out[i] = word;
                    }
        }
    }
}

/* Items [items*ith/nth, ...), band by band; then each one's block added to dw. */
static void tn__conv_amxdw_task(void *ctx, int ith, int nth)
{
    const tn__conv_amxdw_job *j = (const tn__conv_amxdw_job *)ctx;
    const tn__amx_dw *d = &j->d;
    int items = d->ntaps * ((d->cp + 31) / 32) * ((d->mp + 31) / 32), b = (int)((long long)items * ith / nth);
    int e = (int)((long long)items * (ith + 1) / nth), it, n, oy, r, c;
    if (b >= e) return;
    memset(j->acc + (size_t)b * 1024, 0, (size_t)(e - b) * 1024 * sizeof(float));
    for (n = 0; n < d->N; n++)
        for (oy = 0; oy < d->OH; oy += j->band)
            for (it = b; it < e; it++) tn__amx_dw_item(d, it, n, oy, oy + j->band < d->OH ? oy + j->band : d->OH, j->acc + (size_t)it * 1024);
    for (it = b; it < e; it++) {
        int cpairs = (d->cp + 31) / 32, mpairs = (d->mp + 31) / 32, t = it / (cpairs * mpairs);
        int cb = it / mpairs % cpairs * 32, mb = it % mpairs * 32;
        const float *blk = j->acc + (size_t)it * 1024; /* blk[r][c] = dW[mb + c][cb + r][t] */
        for (r = 0; r < 32 && cb + r < d->C; r++)
            for (c = 0; c < 32 && mb + c < d->M; c++) d->dw[((size_t)(mb + c) * d->C + cb + r) * d->ntaps + t] += blk[r * 32 + c];
    }
}

/* dw += the weight gradient, db += dy's channel sums (float32); 1 done, 0 out of memory, -1 not
   for this geometry or CPU. */
static int tn__conv_weight_grad_amx(tn_ctx *ctx, const tn__conv_geom *g, int N, int M, const float *x, const float *dy,
                                    float *dw, float *db)
{
    tn__conv_amxdw_job j;
    int ntaps = g->KH * g->KW, t;
    size_t xh_halves, dyt_words;
    if (tn__gemm_kern(TN_PRECISION_AUTO) != TN__KERN_AMX || g->stride != 1 || ntaps > TN__CONV_AMX_TAPS) return -1;
    if (tn__conv_amx_taps_fit(g, N)) { /* as in tn__conv_forward_amx: dW's layout is the same */
        tn__conv_geom v;
        const float *xv = tn__conv_amx_taps_as_channels(ctx, g, N, x, &v);
        return xv ? tn__conv_weight_grad_amx(ctx, &v, N, M, xv, dy, dw, db) : 0;
    }
    memset(&j, 0, sizeof j);
    j.g = g;
    j.x = x;
    j.dy = dy;
    j.Wp = g->W + 2 * g->pad;
    j.d.Hp = g->H + 2 * g->pad;
    j.d.Wq = (g->OW + 31) / 32 * 32;
    j.d.Wr = tn__conv_amx_row(g, j.Wp, 32);
    j.d.N = N;
    j.d.ntaps = ntaps;
    j.d.C = g->C;
    j.d.M = M;
    j.d.OH = g->OH;
    j.d.cp = (g->C + 15) / 16 * 16;
    j.d.mp = (M + 15) / 16 * 16;
    for (t = 0; t < ntaps; t++) j.off[t] = (t / g->KW) * g->dil * j.d.cp * j.d.Wr + (t % g->KW) * g->dil;
    j.d.off = j.off;
    j.d.dw = dw;
    xh_halves = (size_t)N * j.d.Hp * j.d.cp * j.d.Wr;
    dyt_words = (size_t)N * g->OH * (j.d.Wq / 2) * j.d.mp;
    j.d.xh = (const uint16_t *)tn_ctx_alloc(ctx, xh_halves * sizeof(uint16_t));
    j.d.dyt = (const uint32_t *)tn_ctx_alloc(ctx, dyt_words * sizeof(uint32_t));
    j.tmp = (uint16_t *)tn_ctx_alloc(ctx, (size_t)tn_get_threads() * 16 * j.d.Wq * sizeof(uint16_t));
    j.colmap = tn__conv_amx_colmap(ctx, g, j.Wp);
    j.acc = tn__ctx_floats(ctx, (size_t)ntaps * ((j.d.cp + 31) / 32) * ((j.d.mp + 31) / 32) * 1024, 0);
    if (!j.d.xh || !j.d.dyt || !j.tmp || !j.colmap || !j.acc) return 0;
    /* a band's input and dy rows: about 1 MiB, half of L2 */
    j.band = (int)(((size_t)1 << 20) / ((size_t)j.d.cp * j.d.Wr * 2 + (size_t)j.d.Wq / 2 * j.d.mp * 4));
    if (j.band < 1) j.band = 1;
    tn__conv_amx_run(tn__conv_amxdw_prep_task, tn__conv_amxdw_task, &j, (double)N * M * g->OH * g->OW * ntaps * g->C);
    if (db) tn__bias_grad(db, dy, N, M, (size_t)g->OH * g->OW);
    return 1;
}
#endif

/* dw (M x K) += sum over images of dy (M x OH*OW) x im2col(x)^T, and db (M, if not NULL) += the
   sums of dy's channels, taken in the same pass over dy (1x1: separately). */
static int tn__conv_weight_grad(tn_ctx *ctx, const tn__conv_geom *g, int N, int M, const float *x, const float *dy,
                                float *dw, float *db)
{
    tn__conv_job j;
    tn__conv_sum_job s;
    int fuse = db && !tn__conv_is_1x1(g);
#ifdef TN__BF16_HW
    int direct = tn__conv_weight_grad_amx(ctx, g, N, M, x, dy, dw, db);
    if (direct >= 0) return direct;
#endif
    if (db && !fuse) tn__bias_grad(db, dy, N, M, (size_t)g->OH * g->OW);
    if (!tn__conv_job_init(ctx, &j, g, N, M, tn__conv_groups(g, M), tn__conv_col_floats(g) + (size_t)g->OH * g->OW))
        return 0;
    j.x = x;
    j.dy = dy;
    j.kd = j.K + fuse;
    j.phase = tn__conv_dw_transposed(M, j.kd); /* here: the partials are kd x M */
    j.dw_direct = j.groups == 1 && !j.phase && !fuse;
    j.dw = j.dw_direct ? dw : tn__ctx_floats(ctx, (size_t)j.groups * M * j.kd, 0);
    if (!j.dw) return 0;
    tn__conv_run(tn__conv_dw_task, &j, j.groups);
    if (j.dw_direct) return 1;
    s.dw = dw;
    s.db = db;
    s.parts = j.dw;
    s.n = (size_t)M * j.kd;
    s.groups = j.groups;
    s.M = M;
    s.K = j.K;
    s.kd = j.kd;
    s.transposed = j.phase;
    tn_parallel_for(s.n, 16384, tn__conv_sum_parts, &s);
    return 1;
}

/* Hull [*lo, *hi] of the input rows that output rows [r0, r1) read; *lo > *hi when none. */
static void tn__conv_row_hull(const tn__conv_geom *g, int r0, int r1, int *lo, int *hi)
{
    int oy, ky;
    *lo = g->H;
    *hi = -1;
    for (oy = r0; oy < r1; oy++)
        for (ky = 0; ky < g->KH; ky++) {
            int iy = tn__conv_src(oy, ky, g->stride, g->pad, g->dil, g->H, g->reflect);
            if (iy < 0) continue;
            if (iy < *lo) *lo = iy;
            if (iy > *hi) *hi = iy;
        }
}

/* Most groups (<= `groups`) for which groups g and g + 2 read disjoint input rows, so each col2im
   phase (even or odd groups) can run in parallel without two threads adding into one element. */
static int tn__conv_col2im_groups(const tn__conv_geom *g, int groups)
{
    for (; groups > 2; groups--) {
        int k, ok = 1, lo0, hi0, lo2, hi2;
        for (k = 0; ok && k + 2 < groups; k++) {
            tn__conv_row_hull(g, (int)((long long)g->OH * k / groups), (int)((long long)g->OH * (k + 1) / groups), &lo0, &hi0);
            tn__conv_row_hull(g, (int)((long long)g->OH * (k + 2) / groups), (int)((long long)g->OH * (k + 3) / groups), &lo2, &hi2);
            ok = lo0 > hi0 || lo2 > hi2 || hi0 < lo2 || hi2 < lo0;
        }
        if (ok) break;
    }
    return groups;
}

/* dx = beta * dx + conv^T(dy, w): the input gradient of y = conv(x, w) (x N x g.C x H x W). */
static int tn__conv_input_grad(tn_ctx *ctx, const tn__conv_geom *g, int N, int M, const float *dy, const float *w,
                               float *dx, float beta)
{
    tn__conv_job j;
    int pad2 = (g->KH - 1) * g->dil - g->pad;
    /* (few channels: col2im costs less than a convolution of few output channels, but not on AMX) */
    if (g->stride == 1 && !g->reflect && g->KH == g->KW && pad2 >= 0 && (g->C >= 8 || tn__gemm_kern(TN_PRECISION_AUTO) == TN__KERN_AMX) &&
        g->OH + 2 * pad2 - g->dil * (g->KH - 1) == g->H && g->OW + 2 * pad2 - g->dil * (g->KW - 1) == g->W) {
        /* dx = conv(dy, w'), w'[c][m][ky][kx] = w[m][c][KH-1-ky][KW-1-kx], padding dil*(K-1) - pad */
        tn__conv_geom f;
        size_t kk = (size_t)g->KH * g->KW, c, m, t;
        float *wf = tn__ctx_floats(ctx, (size_t)g->C * M * kk, 0);
        if (!wf) return 0;
        for (c = 0; c < (size_t)g->C; c++)
            for (m = 0; m < (size_t)M; m++)
                for (t = 0; t < kk; t++) wf[(c * M + m) * kk + t] = w[(m * g->C + c) * kk + kk - 1 - t];
        f = *g;
        f.C = M; f.H = g->OH; f.W = g->OW; f.OH = g->H; f.OW = g->W; f.pad = pad2;
        return tn__conv_forward(ctx, &f, N, g->C, dy, wf, NULL, dx, beta);
    }
    if (beta == 0.0f) memset(dx, 0, (size_t)N * g->C * g->H * g->W * sizeof(float));
    if (!tn__conv_job_init(ctx, &j, g, N, M, tn__conv_col2im_groups(g, tn__conv_groups(g, M)), tn__conv_col_floats(g)))
        return 0;
    j.w = w;
    j.dy = dy;
    j.dx = dx;
    for (j.phase = 0; j.phase < 2 && j.phase < j.groups; j.phase++)
        tn__conv_run(tn__conv_dx_task, &j, N * ((j.groups - j.phase + 1) / 2));
    return 1;
}

static void tn__conv_geom_read(tn__conv_geom *g, const tn_tensor *t)
{
    g->C = t->ip[0]; g->H = t->ip[1]; g->W = t->ip[2]; g->KH = t->ip[3]; g->KW = t->ip[4];
    g->OH = t->ip[5]; g->OW = t->ip[6]; g->stride = t->ip[7]; g->pad = t->ip[8]; g->dil = t->ip[9];
    g->reflect = t->ip[10];
}

static void tn__conv_geom_write(const tn__conv_geom *g, tn_tensor *t)
{
    t->ip[0] = g->C; t->ip[1] = g->H; t->ip[2] = g->W; t->ip[3] = g->KH; t->ip[4] = g->KW;
    t->ip[5] = g->OH; t->ip[6] = g->OW; t->ip[7] = g->stride; t->ip[8] = g->pad; t->ip[9] = g->dil;
    t->ip[10] = g->reflect;
}

static void tn__conv2d_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0], *w = out->src[1], *b = out->src[2];
    tn__conv_geom g;
    int N = x->shape[0], Cout = w->shape[0];
    float *db = b && b->requires_grad ? tn__grad(ctx, b) : NULL;
    tn__conv_geom_read(&g, out);
    if (b && b->requires_grad && !db) return;
    if (w->requires_grad) { /* the bias gradient rides along */
        if (!tn__grad(ctx, w) || !tn__conv_weight_grad(ctx, &g, N, Cout, x->data, out->grad, w->grad, db)) return;
    } else if (db) {
        tn__bias_grad(db, out->grad, N, Cout, (size_t)g.OH * g.OW);
    }
    if (x->requires_grad && tn__grad(ctx, x)) tn__conv_input_grad(ctx, &g, N, Cout, out->grad, w->data, x->grad, 1.0f);
}

/* The zero rules of tn_conv_opts: stride and dilation 1 (also for negative values). */
static void tn__conv_opts_defaults(tn_conv_opts *o)
{
    if (o->stride <= 0) o->stride = 1;
    if (o->dilation <= 0) o->dilation = 1;
}

TN_API tn_tensor *tn_conv2d(tn_ctx *ctx, tn_tensor *x, tn_tensor *w, tn_tensor *bias, const tn_conv_opts *opts)
{
    tn__conv_geom g;
    tn_conv_opts co;
    tn_tensor *o;
    int shape[4];
    if (!x || !w) return NULL;
    TN_ASSERT(x->ndim == 4 && w->ndim == 4 && w->shape[1] == x->shape[1]);
    memset(&co, 0, sizeof co);
    if (opts) co = *opts;
    tn__conv_opts_defaults(&co);
    g.C = x->shape[1]; g.H = x->shape[2]; g.W = x->shape[3];
    g.KH = w->shape[2]; g.KW = w->shape[3];
    g.stride = co.stride;
    g.pad = co.pad;
    g.dil = co.dilation;
    g.reflect = co.padding == TN_PADDING_REFLECT;
    TN_ASSERT(!g.reflect || (g.pad < g.H && g.pad < g.W));
    g.OH = (g.H + 2 * g.pad - g.dil * (g.KH - 1) - 1) / g.stride + 1;
    g.OW = (g.W + 2 * g.pad - g.dil * (g.KW - 1) - 1) / g.stride + 1;
    TN_ASSERT(g.OH >= 1 && g.OW >= 1);
    TN_ASSERT(!bias || (int)bias->numel == w->shape[0]);
    shape[0] = x->shape[0]; shape[1] = w->shape[0]; shape[2] = g.OH; shape[3] = g.OW;
    o = tn__op_make(ctx, 4, shape, tn__conv2d_backward, x, w, bias, 0); /* every element is written */
    if (!o) return NULL;
    tn__conv_geom_write(&g, o);
    if (!tn__conv_forward(ctx, &g, shape[0], shape[1], x->data, w->data, bias ? bias->data : NULL, o->data, 0.0f))
        return NULL;
    return o;
}

/* Transposed convolution: y = conv^T(x, w) for the conv whose input is y (g.C = Cout, g.H/W = y
   size, g.OH/OW = x size), so its forward is that conv's input gradient, and its backward is that
   conv's forward (dx) and weight gradient (dw). */
static void tn__convt_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0], *w = out->src[1], *b = out->src[2];
    tn__conv_geom g;
    int N = x->shape[0], Cin = x->shape[1];
    tn__conv_geom_read(&g, out);
    if (b && b->requires_grad && tn__grad(ctx, b)) tn__bias_grad(b->grad, out->grad, N, g.C, (size_t)g.H * g.W);
    if (x->requires_grad && tn__grad(ctx, x) && !tn__conv_forward(ctx, &g, N, Cin, out->grad, w->data, NULL, x->grad, 1.0f))
        return;
    if (w->requires_grad && tn__grad(ctx, w)) tn__conv_weight_grad(ctx, &g, N, Cin, out->grad, x->data, w->grad, NULL);
}

TN_API tn_tensor *tn_conv_transpose2d(tn_ctx *ctx, tn_tensor *x, tn_tensor *w, tn_tensor *bias, const tn_conv_opts *opts)
{
    tn__conv_geom g;
    tn_conv_opts co;
    tn_tensor *o;
    int op, shape[4];
    if (!x || !w) return NULL;
    TN_ASSERT(x->ndim == 4 && w->ndim == 4 && w->shape[0] == x->shape[1]);
    memset(&co, 0, sizeof co);
    if (opts) co = *opts;
    tn__conv_opts_defaults(&co);
    g.C = w->shape[1];
    g.KH = w->shape[2]; g.KW = w->shape[3];
    g.stride = co.stride;
    g.pad = co.pad;
    g.dil = co.dilation;
    g.reflect = 0;
    op = co.output_padding;
    g.OH = x->shape[2]; g.OW = x->shape[3];
    g.H = (g.OH - 1) * g.stride - 2 * g.pad + g.dil * (g.KH - 1) + op + 1;
    g.W = (g.OW - 1) * g.stride - 2 * g.pad + g.dil * (g.KW - 1) + op + 1;
    TN_ASSERT(g.H >= 1 && g.W >= 1);
    TN_ASSERT(!bias || (int)bias->numel == g.C);
    shape[0] = x->shape[0]; shape[1] = g.C; shape[2] = g.H; shape[3] = g.W;
    o = tn__op_make(ctx, 4, shape, tn__convt_backward, x, w, bias, 0); /* input_grad with beta 0 writes all */
    if (!o) return NULL;
    tn__conv_geom_write(&g, o);
    if (!tn__conv_input_grad(ctx, &g, shape[0], x->shape[1], x->data, w->data, o->data, 0.0f)) return NULL;
    if (bias) tn__bias_add(o->data, bias->data, shape[0], g.C, (size_t)g.H * g.W);
    return o;
}

/* ---- pooling and upsampling ---- */

static void tn__pool_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    int k = out->ip[0], s = out->ip[1], is_max = out->ip[2];
    int H = x->shape[2], W = x->shape[3], OH = out->shape[2], OW = out->shape[3];
    size_t nc, NC = (size_t)x->shape[0] * x->shape[1];
    const int *arg = (const int *)out->aux;
    if (!tn__grad(ctx, x)) return;
    for (nc = 0; nc < NC; nc++) {
        int oy, ox, dy, dx;
        float *gx = x->grad + nc * H * W;
        const float *go = out->grad + nc * OH * OW;
        for (oy = 0; oy < OH; oy++)
            for (ox = 0; ox < OW; ox++) {
                size_t oi = (size_t)oy * OW + ox;
                if (is_max) gx[arg[nc * OH * OW + oi]] += go[oi];
                else
                    for (dy = 0; dy < k; dy++)
                        for (dx = 0; dx < k; dx++) gx[(size_t)(oy * s + dy) * W + ox * s + dx] += go[oi] / (float)(k * k);
            }
    }
}

static tn_tensor *tn__pool2d(tn_ctx *ctx, tn_tensor *x, int k, int s, int is_max)
{
    int shape[4], H, W, OH, OW;
    size_t nc, NC;
    tn_tensor *o;
    int *arg = NULL;
    if (!x) return NULL;
    TN_ASSERT(x->ndim == 4 && k >= 1 && s >= 1 && x->shape[2] >= k && x->shape[3] >= k);
    H = x->shape[2]; W = x->shape[3];
    OH = (H - k) / s + 1; OW = (W - k) / s + 1;
    shape[0] = x->shape[0]; shape[1] = x->shape[1]; shape[2] = OH; shape[3] = OW;
    o = tn__op(ctx, 4, shape, tn__pool_backward, x, NULL, NULL);
    if (!o) return NULL;
    o->ip[0] = k; o->ip[1] = s; o->ip[2] = is_max;
    NC = (size_t)x->shape[0] * x->shape[1];
    if (is_max) {
        arg = (int *)tn_ctx_alloc(ctx, o->numel * sizeof(int));
        if (!arg) return NULL;
        o->aux = arg;
    }
    for (nc = 0; nc < NC; nc++) {
        int oy, ox, dy, dx;
        const float *xi = x->data + nc * H * W;
        for (oy = 0; oy < OH; oy++)
            for (ox = 0; ox < OW; ox++) {
                float acc = is_max ? -FLT_MAX : 0.0f;
                int best = 0;
                for (dy = 0; dy < k; dy++)
                    for (dx = 0; dx < k; dx++) {
                        int idx = (oy * s + dy) * W + ox * s + dx;
                        float v = xi[idx];
                        if (!is_max) acc += v;
                        else if (v > acc) { acc = v; best = idx; }
                    }
                o->data[nc * OH * OW + (size_t)oy * OW + ox] = is_max ? acc : acc / (float)(k * k);
                if (is_max) arg[nc * OH * OW + (size_t)oy * OW + ox] = best;
            }
    }
    return o;
}

TN_API tn_tensor *tn_avg_pool2d(tn_ctx *ctx, tn_tensor *x, int k, int s) { return tn__pool2d(ctx, x, k, s, 0); }
TN_API tn_tensor *tn_max_pool2d(tn_ctx *ctx, tn_tensor *x, int k, int s) { return tn__pool2d(ctx, x, k, s, 1); }

/* Bilinear source coordinate (align_corners = false), clamped like PyTorch. */
static void tn__bilinear_src(int o, int in, int out, int *i0, int *i1, float *f)
{
    float s = ((float)o + 0.5f) * (float)in / (float)out - 0.5f;
    if (s < 0) s = 0;
    *i0 = (int)s;
    if (*i0 > in - 1) *i0 = in - 1;
    *i1 = *i0 + 1 < in ? *i0 + 1 : *i0;
    *f = s - (float)*i0;
}

static void tn__upsample_walk(const tn_tensor *x, const tn_tensor *o, const float *src, float *dst, int backward)
{
    int H = x->shape[2], W = x->shape[3], OH = o->shape[2], OW = o->shape[3], mode = o->ip[0];
    size_t nc, NC = (size_t)x->shape[0] * x->shape[1];
    for (nc = 0; nc < NC; nc++) {
        int oy, ox;
        const float *s_in = backward ? NULL : src + nc * H * W;
        float *d_in = backward ? dst + nc * H * W : NULL;
        for (oy = 0; oy < OH; oy++) {
            int y0, y1;
            float fy;
            if (mode == 0) { y0 = y1 = oy * H / OH; fy = 0; }
            else tn__bilinear_src(oy, H, OH, &y0, &y1, &fy);
            for (ox = 0; ox < OW; ox++) {
                int x0, x1;
                float fx;
                size_t oi = nc * OH * OW + (size_t)oy * OW + ox;
                if (mode == 0) { x0 = x1 = ox * W / OW; fx = 0; }
                else tn__bilinear_src(ox, W, OW, &x0, &x1, &fx);
                if (backward) {
                    float g = src[oi];
                    d_in[y0 * W + x0] += g * (1 - fy) * (1 - fx);
                    d_in[y0 * W + x1] += g * (1 - fy) * fx;
                    d_in[y1 * W + x0] += g * fy * (1 - fx);
                    d_in[y1 * W + x1] += g * fy * fx;
                } else {
                    float a = s_in[y0 * W + x0] + fx * (s_in[y0 * W + x1] - s_in[y0 * W + x0]);
                    float b = s_in[y1 * W + x0] + fx * (s_in[y1 * W + x1] - s_in[y1 * W + x0]);
                    dst[oi] = a + fy * (b - a);
                }
            }
        }
    }
}

static void tn__upsample_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    if (!tn__grad(ctx, x)) return;
    tn__upsample_walk(x, out, out->grad, x->grad, 1);
}

static tn_tensor *tn__upsample(tn_ctx *ctx, tn_tensor *x, int oh, int ow, int mode)
{
    int shape[4];
    tn_tensor *o;
    if (!x) return NULL;
    TN_ASSERT(x->ndim == 4 && oh >= 1 && ow >= 1);
    shape[0] = x->shape[0]; shape[1] = x->shape[1]; shape[2] = oh; shape[3] = ow;
    o = tn__op(ctx, 4, shape, tn__upsample_backward, x, NULL, NULL);
    if (!o) return NULL;
    o->ip[0] = mode;
    tn__upsample_walk(x, o, x->data, o->data, 0);
    return o;
}

TN_API tn_tensor *tn_upsample_nearest(tn_ctx *ctx, tn_tensor *x, int factor)
{
    TN_ASSERT(factor >= 1);
    return x ? tn__upsample(ctx, x, x->shape[2] * factor, x->shape[3] * factor, 0) : NULL;
}

TN_API tn_tensor *tn_upsample_bilinear(tn_ctx *ctx, tn_tensor *x, int out_h, int out_w)
{
    return tn__upsample(ctx, x, out_h, out_w, 1);
}

/* ---- normalisation ----
   One kernel serves batch and instance norm: a "set" is the group of elements sharing a mean
   (a channel across the batch, or one (n, c) plane). aux keeps mean and 1/std per set. */

typedef struct tn__norm_info { int per_instance; int nset; float eps; } tn__norm_info;

static int tn__norm_set(const tn_tensor *x, int per_instance, int n, int c)
{
    return per_instance ? n * x->shape[1] + c : c;
}

static void tn__norm_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0], *gamma = out->src[1], *beta = out->src[2];
    int N = x->shape[0], C = x->shape[1], per_inst = out->ip[0], training = out->ip[1], n, c, s;
    int nset = per_inst ? N * C : C;
    size_t hw = (size_t)x->shape[2] * x->shape[3], i;
    const float *mean = (const float *)out->aux, *istd = mean + nset;
    double *sg = (double *)tn_ctx_alloc(ctx, 2 * (size_t)nset * sizeof(double)), *sgx;
    if (!sg) return;
    sgx = sg + nset;
    memset(sg, 0, 2 * (size_t)nset * sizeof(double));
    /* sums of dy*gamma and dy*gamma*xhat per set, and the affine gradients */
    for (n = 0; n < N; n++)
        for (c = 0; c < C; c++) {
            const float *xp = x->data + ((size_t)n * C + c) * hw, *gp = out->grad + ((size_t)n * C + c) * hw;
            float gm = gamma ? gamma->data[c] : 1.0f;
            double a = 0, b = 0;
            s = tn__norm_set(x, per_inst, n, c);
            for (i = 0; i < hw; i++) {
                double xh = ((double)xp[i] - mean[s]) * istd[s];
                a += gp[i];
                b += gp[i] * xh;
            }
            if (gamma && gamma->requires_grad && tn__grad(ctx, gamma)) gamma->grad[c] += (float)b;
            if (beta && beta->requires_grad && tn__grad(ctx, beta)) beta->grad[c] += (float)a;
            sg[s] += a * gm;
            sgx[s] += b * gm;
        }
    if (!x->requires_grad || !tn__grad(ctx, x)) return;
    for (n = 0; n < N; n++)
        for (c = 0; c < C; c++) {
            const float *xp = x->data + ((size_t)n * C + c) * hw, *gp = out->grad + ((size_t)n * C + c) * hw;
            float *dx = x->grad + ((size_t)n * C + c) * hw;
            float gm = gamma ? gamma->data[c] : 1.0f;
            double m = per_inst ? (double)hw : (double)hw * N;
            s = tn__norm_set(x, per_inst, n, c);
            for (i = 0; i < hw; i++) {
                if (!training) dx[i] += gp[i] * gm * istd[s];
                else {
                    double xh = ((double)xp[i] - mean[s]) * istd[s];
                    dx[i] += (float)(istd[s] / m * (m * gp[i] * gm - sg[s] - xh * sgx[s]));
                }
            }
        }
}

static tn_tensor *tn__norm(tn_ctx *ctx, tn_tensor *x, tn_tensor *gamma, tn_tensor *beta, int per_inst, int training,
                           tn_tensor *rmean, tn_tensor *rvar, float eps)
{
    int N, C, n, c, s, nset;
    size_t hw, i;
    tn_tensor *o;
    float *mean, *istd;
    if (!x) return NULL;
    TN_ASSERT(x->ndim == 4);
    N = x->shape[0];
    C = x->shape[1];
    hw = (size_t)x->shape[2] * x->shape[3];
    nset = per_inst ? N * C : C;
    TN_ASSERT(!gamma || (int)gamma->numel == C);
    TN_ASSERT(!beta || (int)beta->numel == C);
    o = tn__op(ctx, 4, x->shape, tn__norm_backward, x, gamma, beta);
    if (!o) return NULL;
    o->ip[0] = per_inst;
    o->ip[1] = training;
    mean = tn__ctx_floats(ctx, 2 * (size_t)nset, 1);
    if (!mean) return NULL;
    istd = mean + nset;
    o->aux = mean;
    if (training) {
        double *s1 = (double *)tn_ctx_alloc(ctx, 2 * (size_t)nset * sizeof(double)), *s2;
        if (!s1) return NULL;
        s2 = s1 + nset;
        memset(s1, 0, 2 * (size_t)nset * sizeof(double));
        for (n = 0; n < N; n++)
            for (c = 0; c < C; c++) {
                const float *xp = x->data + ((size_t)n * C + c) * hw;
                s = tn__norm_set(x, per_inst, n, c);
                for (i = 0; i < hw; i++) s1[s] += xp[i];
            }
        for (s = 0; s < nset; s++) s1[s] /= (double)hw * (per_inst ? 1 : N);
        for (n = 0; n < N; n++)
            for (c = 0; c < C; c++) {
                const float *xp = x->data + ((size_t)n * C + c) * hw;
                s = tn__norm_set(x, per_inst, n, c);
                for (i = 0; i < hw; i++) s2[s] += ((double)xp[i] - s1[s]) * ((double)xp[i] - s1[s]);
            }
        for (s = 0; s < nset; s++) {
            double m = (double)hw * (per_inst ? 1 : N), var = s2[s] / m;
            mean[s] = (float)s1[s];
            istd[s] = (float)(1.0 / sqrt(var + eps));
            if (!per_inst && rmean && rvar) { /* PyTorch: running var uses the unbiased variance */
                rmean->data[s] = 0.9f * rmean->data[s] + 0.1f * (float)s1[s];
                rvar->data[s] = 0.9f * rvar->data[s] + 0.1f * (float)(m > 1 ? s2[s] / (m - 1) : var);
            }
        }
    } else {
        TN_ASSERT(rmean && rvar);
        for (s = 0; s < nset; s++) {
            mean[s] = rmean->data[s];
            istd[s] = 1.0f / sqrtf(rvar->data[s] + eps);
        }
    }
    for (n = 0; n < N; n++)
        for (c = 0; c < C; c++) {
            const float *xp = x->data + ((size_t)n * C + c) * hw;
            float *yp = o->data + ((size_t)n * C + c) * hw;
            float g = gamma ? gamma->data[c] : 1.0f, b = beta ? beta->data[c] : 0.0f;
            s = tn__norm_set(x, per_inst, n, c);
            for (i = 0; i < hw; i++) yp[i] = (xp[i] - mean[s]) * istd[s] * g + b;
        }
    return o;
}

TN_API tn_tensor *tn_batch_norm(tn_ctx *ctx, tn_tensor *x, tn_tensor *gamma, tn_tensor *beta, tn_tensor *running_mean,
                                tn_tensor *running_var, int training, float eps)
{
    return tn__norm(ctx, x, gamma, beta, 0, training, running_mean, running_var, eps);
}

TN_API tn_tensor *tn_instance_norm(tn_ctx *ctx, tn_tensor *x, tn_tensor *gamma, tn_tensor *beta, float eps)
{
    return tn__norm(ctx, x, gamma, beta, 1, 1, NULL, NULL, eps);
}

TN_API tn_tensor *tn_spade_norm(tn_ctx *ctx, tn_tensor *x, tn_tensor *gamma, tn_tensor *beta, float eps)
{
    tn_tensor *xn = tn_instance_norm(ctx, x, NULL, NULL, eps);
    return tn_add(ctx, tn_mul(ctx, xn, tn_scale_shift(ctx, gamma, 1.0f, 1.0f)), beta);
}

/* ---- spectral norm ---- */

static void tn__spectral_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *w = out->src[0];
    int rows = w->shape[0], cols = (int)(w->numel / (size_t)rows), r, c;
    const float *u = (const float *)out->aux, *v = u + rows;
    float sigma = out->fp[0];
    double dot = 0;
    size_t i;
    if (!tn__grad(ctx, w)) return;
    for (i = 0; i < w->numel; i++) dot += (double)out->grad[i] * out->data[i];
    for (r = 0; r < rows; r++)
        for (c = 0; c < cols; c++) {
            size_t k = (size_t)r * cols + c;
            w->grad[k] += (float)((out->grad[k] - dot * u[r] * v[c]) / sigma);
        }
}

static float tn__normalize(float *x, int n)
{
    double s = 0;
    int i;
    for (i = 0; i < n; i++) s += (double)x[i] * x[i];
    s = sqrt(s) + 1e-12;
    for (i = 0; i < n; i++) x[i] = (float)(x[i] / s);
    return (float)s;
}

TN_API tn_tensor *tn_spectral_norm(tn_ctx *ctx, tn_tensor *w, tn_tensor *u, int iters)
{
    int rows, cols, it, r;
    float *uv, *v, sigma;
    tn_tensor *o;
    size_t i;
    if (!w || !u) return NULL;
    rows = w->shape[0];
    cols = (int)(w->numel / (size_t)rows);
    TN_ASSERT((int)u->numel == rows);
    o = tn__op(ctx, w->ndim, w->shape, tn__spectral_backward, w, NULL, NULL);
    uv = tn__ctx_floats(ctx, (size_t)rows + cols, 0);
    if (!o || !uv) return NULL;
    v = uv + rows;
    if (tn__normalize(u->data, rows) < 1e-6f) { /* a zero vector: restart from a fixed one */
        for (r = 0; r < rows; r++) u->data[r] = 1.0f;
        tn__normalize(u->data, rows);
    }
    for (it = 0; it < (iters < 1 ? 1 : iters); it++) {
        tn_sgemm(1, 0, cols, 1, rows, 1.0f, w->data, cols, u->data, 1, 0.0f, v, 1); /* v = W^T u */
        tn__normalize(v, cols);
        tn_sgemm(0, 0, rows, 1, cols, 1.0f, w->data, cols, v, 1, 0.0f, u->data, 1); /* u = W v */
        tn__normalize(u->data, rows);
    }
    memcpy(uv, u->data, (size_t)rows * sizeof(float));
    {
        double s = 0; /* sigma = u^T W v */
        for (r = 0; r < rows; r++) {
            double d = 0;
            int c;
            for (c = 0; c < cols; c++) d += (double)w->data[(size_t)r * cols + c] * v[c];
            s += d * uv[r];
        }
        sigma = (float)(fabs(s) > 1e-12 ? s : 1e-12);
    }
    o->aux = uv;
    o->fp[0] = sigma;
    for (i = 0; i < w->numel; i++) o->data[i] = w->data[i] / sigma;
    return o;
}

/* ---- graph ops ---- */

static void tn__gather_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    const int *idx = (const int *)out->aux;
    int i, n = out->shape[0];
    size_t d = out->numel / (size_t)n, k;
    if (!tn__grad(ctx, x)) return;
    for (i = 0; i < n; i++)
        for (k = 0; k < d; k++) x->grad[(size_t)idx[i] * d + k] += out->grad[(size_t)i * d + k];
}

static int *tn__copy_index(tn_ctx *ctx, const int *idx, int n)
{
    int *p = (int *)tn_ctx_alloc(ctx, (size_t)n * sizeof(int));
    if (p) memcpy(p, idx, (size_t)n * sizeof(int));
    return p;
}

TN_API tn_tensor *tn_gather_rows(tn_ctx *ctx, tn_tensor *x, const int *idx, int n)
{
    int shape[4], i;
    size_t d;
    tn_tensor *o;
    if (!x) return NULL;
    TN_ASSERT(n >= 1);
    memcpy(shape, x->shape, sizeof shape);
    shape[0] = n;
    d = x->numel / (size_t)x->shape[0];
    o = tn__op(ctx, x->ndim, shape, tn__gather_backward, x, NULL, NULL);
    if (!o || !(o->aux = tn__copy_index(ctx, idx, n))) return NULL;
    for (i = 0; i < n; i++) {
        TN_ASSERT(idx[i] >= 0 && idx[i] < x->shape[0]);
        memcpy(o->data + (size_t)i * d, x->data + (size_t)idx[i] * d, d * sizeof(float));
    }
    return o;
}

static void tn__scatter_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    const int *seg = (const int *)out->aux;
    int i, n = x->shape[0];
    size_t d = x->numel / (size_t)n, k;
    if (!tn__grad(ctx, x)) return;
    for (i = 0; i < n; i++)
        for (k = 0; k < d; k++) x->grad[(size_t)i * d + k] += out->grad[(size_t)seg[i] * d + k];
}

TN_API tn_tensor *tn_scatter_add_rows(tn_ctx *ctx, tn_tensor *x, const int *seg, int nseg)
{
    int shape[4], i, n;
    size_t d, k;
    tn_tensor *o;
    if (!x) return NULL;
    TN_ASSERT(nseg >= 1);
    n = x->shape[0];
    memcpy(shape, x->shape, sizeof shape);
    shape[0] = nseg;
    d = x->numel / (size_t)n;
    o = tn__op(ctx, x->ndim, shape, tn__scatter_backward, x, NULL, NULL);
    if (!o || !(o->aux = tn__copy_index(ctx, seg, n))) return NULL;
    for (i = 0; i < n; i++) {
        TN_ASSERT(seg[i] >= 0 && seg[i] < nseg);
        for (k = 0; k < d; k++) o->data[(size_t)seg[i] * d + k] += x->data[(size_t)i * d + k];
    }
    return o;
}

static void tn__segsoftmax_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    const int *seg = (const int *)out->aux;
    int E = x->shape[0], H = (int)(x->numel / (size_t)E), nseg = out->ip[0], e, h;
    double *dot = (double *)tn_ctx_alloc(ctx, (size_t)nseg * H * sizeof(double));
    if (!dot || !tn__grad(ctx, x)) return;
    memset(dot, 0, (size_t)nseg * H * sizeof(double));
    for (e = 0; e < E; e++)
        for (h = 0; h < H; h++) dot[(size_t)seg[e] * H + h] += (double)out->grad[(size_t)e * H + h] * out->data[(size_t)e * H + h];
    for (e = 0; e < E; e++)
        for (h = 0; h < H; h++) {
            size_t k = (size_t)e * H + h;
            x->grad[k] += (float)(out->data[k] * (out->grad[k] - dot[(size_t)seg[e] * H + h]));
        }
}

TN_API tn_tensor *tn_segment_softmax(tn_ctx *ctx, tn_tensor *scores, const int *seg, int nseg)
{
    int E, H, e, h;
    float *mx;
    double *sum;
    tn_tensor *o;
    if (!scores) return NULL;
    E = scores->shape[0];
    H = (int)(scores->numel / (size_t)E);
    o = tn__op(ctx, scores->ndim, scores->shape, tn__segsoftmax_backward, scores, NULL, NULL);
    if (!o || !(o->aux = tn__copy_index(ctx, seg, E))) return NULL;
    o->ip[0] = nseg;
    mx = tn__ctx_floats(ctx, (size_t)nseg * H, 0);
    sum = (double *)tn_ctx_alloc(ctx, (size_t)nseg * H * sizeof(double));
    if (!mx || !sum) return NULL;
    for (e = 0; e < nseg * H; e++) { mx[e] = -FLT_MAX; sum[e] = 0; }
    for (e = 0; e < E; e++) {
        TN_ASSERT(seg[e] >= 0 && seg[e] < nseg);
        for (h = 0; h < H; h++) {
            float v = scores->data[(size_t)e * H + h];
            if (v > mx[(size_t)seg[e] * H + h]) mx[(size_t)seg[e] * H + h] = v;
        }
    }
    for (e = 0; e < E; e++)
        for (h = 0; h < H; h++) {
            size_t k = (size_t)e * H + h, s = (size_t)seg[e] * H + h;
            o->data[k] = expf(scores->data[k] - mx[s]);
            sum[s] += o->data[k];
        }
    for (e = 0; e < E; e++)
        for (h = 0; h < H; h++) o->data[(size_t)e * H + h] = (float)(o->data[(size_t)e * H + h] / sum[(size_t)seg[e] * H + h]);
    return o;
}

static void tn__row_softmax_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    int N = x->shape[0], K = (int)(x->numel / (size_t)N), n, k;
    float inv_tau = out->fp[0];
    if (!tn__grad(ctx, x)) return;
    for (n = 0; n < N; n++) {
        const float *y = out->data + (size_t)n * K, *g = out->grad + (size_t)n * K;
        double dot = 0;
        for (k = 0; k < K; k++) dot += (double)g[k] * y[k];
        for (k = 0; k < K; k++) x->grad[(size_t)n * K + k] += (float)(y[k] * (g[k] - dot) * inv_tau);
    }
}

TN_API tn_tensor *tn_gumbel_softmax(tn_ctx *ctx, tn_tensor *logits, float tau, tn_rng *rng)
{
    int N, K, n, k;
    tn_tensor *o;
    if (!logits) return NULL;
    TN_ASSERT(tau > 0);
    N = logits->shape[0];
    K = (int)(logits->numel / (size_t)N);
    o = tn__op(ctx, logits->ndim, logits->shape, tn__row_softmax_backward, logits, NULL, NULL);
    if (!o) return NULL;
    o->fp[0] = 1.0f / tau;
    for (n = 0; n < N; n++) {
        float *y = o->data + (size_t)n * K, mx = -FLT_MAX;
        double s = 0;
        for (k = 0; k < K; k++) {
            float u = rng ? tn_rng_uniform(rng) : 0.5f;
            float g = -logf(-logf(u * 0.999998f + 1e-6f));
            y[k] = (logits->data[(size_t)n * K + k] + (rng ? g : 0.0f)) / tau;
            if (y[k] > mx) mx = y[k];
        }
        for (k = 0; k < K; k++) { y[k] = expf(y[k] - mx); s += y[k]; }
        for (k = 0; k < K; k++) y[k] = (float)(y[k] / s);
    }
    return o;
}

static void tn__mask_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    const float *m = (const float *)out->aux;
    size_t i;
    if (!tn__grad(ctx, x)) return;
    for (i = 0; i < x->numel; i++) x->grad[i] += out->grad[i] * m[i];
}

TN_API tn_tensor *tn_dropout(tn_ctx *ctx, tn_tensor *x, float p, int training, tn_rng *rng)
{
    tn_tensor *o;
    float *m, keep;
    size_t i;
    if (!x) return NULL;
    if (!training || p <= 0.0f) return x;
    TN_ASSERT(p < 1.0f && rng);
    o = tn__op(ctx, x->ndim, x->shape, tn__mask_backward, x, NULL, NULL);
    m = tn__ctx_floats(ctx, x->numel, 0);
    if (!o || !m) return NULL;
    keep = 1.0f / (1.0f - p);
    for (i = 0; i < x->numel; i++) {
        m[i] = tn_rng_uniform(rng) < p ? 0.0f : keep;
        o->data[i] = x->data[i] * m[i];
    }
    o->aux = m;
    return o;
}
#endif /* TN_NO_ENGINE */

