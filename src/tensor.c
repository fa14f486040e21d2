/* ============================================================================================
   @@tensor  tensors, arenas and the autograd tape
   A tn_tensor is float32 with up to 4 dimensions (NCHW for images, N x D for graph features).
   Every tensor lives in a tn_ctx, a bump arena: parameters in a context that lives as long as the
   model, per-step temporaries in one that is reset each step (after the first steps a training
   loop does no malloc at all). Operations whose inputs require gradients record themselves on the
   context's tape; tn_backward(ctx, loss) replays the tape in reverse, accumulating gradients
   (+=) into every tensor that requires them: parameters, and inputs that asked (style transfer).
   Misuse by the programmer (mismatched shapes) trips TN_ASSERT. Running out of memory marks the
   context as failed: the op returns NULL, later ops given NULL return NULL, and tn_backward /
   tn_ctx_status report TN_ERR_OUT_OF_MEMORY.
   ============================================================================================ */
#ifndef TN_NO_ENGINE

#define TN_MAX_DIMS 4

typedef struct tn_ctx tn_ctx;
typedef struct tn_tensor tn_tensor;
typedef void (*tn_backward_fn)(tn_ctx *ctx, tn_tensor *out);

struct tn_tensor {
    int ndim;
    int shape[TN_MAX_DIMS];   /* unused trailing entries are 1 */
    size_t numel;
    float *data;
    float *grad;              /* NULL until a gradient flows here (parameters: allocated up front) */
    int requires_grad;
    /* the tape record: how this tensor was made */
    tn_backward_fn backward;
    tn_tensor *src[4];
    int ip[12];               /* op integer parameters */
    float fp[4];              /* op float parameters */
    void *aux;                /* op scratch kept for the backward pass (in the same context) */
    char name[40];            /* parameters: the name saved in .tnw files */
};

/* Creates an empty arena context. Caller frees with tn_ctx_free. NULL if out of memory. */
TN_API tn_ctx *tn_ctx_create(void);
TN_API void tn_ctx_free(tn_ctx *ctx);
/* Forgets every tensor made since creation (or the last reset), keeping the memory. */
TN_API void tn_ctx_reset(tn_ctx *ctx);
/* TN_OK, or the first failure inside the context (out of memory). */
TN_API tn_status tn_ctx_status(const tn_ctx *ctx);
/* Bytes handed out since the last reset. */
TN_API size_t tn_ctx_used(const tn_ctx *ctx);
/* Turns tape recording off (inference) or on (default). */
TN_API void tn_ctx_set_grad(tn_ctx *ctx, int enabled);
/* Scratch memory from the arena (64-byte aligned, uninitialised); NULL on failure. */
TN_API void *tn_ctx_alloc(tn_ctx *ctx, size_t bytes);

/* New zero-filled tensor of the given shape (1 to 4 dims, every size >= 1). NULL on failure. */
TN_API tn_tensor *tn_tensor_new(tn_ctx *ctx, int ndim, const int *shape);
TN_API tn_tensor *tn_tensor_1d(tn_ctx *ctx, int n);
TN_API tn_tensor *tn_tensor_2d(tn_ctx *ctx, int rows, int cols);
TN_API tn_tensor *tn_tensor_4d(tn_ctx *ctx, int n, int c, int h, int w);
/* Makes t a leaf that collects a gradient (allocates t->grad, zeroed). Returns t. */
TN_API tn_tensor *tn_tensor_requires_grad(tn_ctx *ctx, tn_tensor *t);
TN_API void tn_tensor_fill(tn_tensor *t, float v);
/* 1 if a and b have the same dims. */
TN_API int tn_tensor_same_shape(const tn_tensor *a, const tn_tensor *b);
/* Views an image (one batch item, H x W x C interleaved) as a new 1 x C x H x W tensor (copy). */
TN_API tn_tensor *tn_tensor_from_image(tn_ctx *ctx, const tn_image *img);
/* Copies batch item `n` of an N x C x H x W tensor into a new image. Caller frees *img. */
TN_API tn_status tn_tensor_to_image(tn_image *img, const tn_tensor *t, int n);

/* Runs the tape backwards from `loss` (a one-element tensor, gradient 1). Gradients accumulate:
   zero parameter gradients between steps (tn_params_zero_grad). */
TN_API tn_status tn_backward(tn_ctx *ctx, tn_tensor *loss);
#endif /* TN_NO_ENGINE */

/* --------------------------------------------------------------------------------------------
   >>tensor  (@@tensor implementation)
   The arena is a list of blocks; a reset keeps them, and when a step needed more than one block
   the reset merges them into one, so the next identical step fits without calling malloc.
   The tape is an array of tensor pointers in creation order, stored in the arena as well.
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_ENGINE

typedef struct tn__block {
    struct tn__block *next;
    size_t size, used;
    unsigned char *base; /* 64-byte aligned start inside the allocation */
} tn__block;

struct tn_ctx {
    tn__block *blocks;      /* current block first */
    size_t total_used, peak;
    tn_tensor **tape;
    size_t tape_len, tape_cap;
    int grad_enabled;
    tn_status status;
};

#define TN__BLOCK_MIN ((size_t)1 << 20)

static tn__block *tn__block_new(size_t size)
{
    unsigned char *raw;
    tn__block *b;
    if (size > TN_MAX_ALLOC) return NULL;
    raw = (unsigned char *)TN_MALLOC(sizeof(tn__block) + size + 64);
    if (!raw) return NULL;
    b = (tn__block *)raw;
    b->next = NULL;
    b->size = size;
    b->used = 0;
    b->base = raw + sizeof(tn__block);
    b->base += (64 - ((uintptr_t)b->base & 63)) & 63;
    return b;
}

TN_API tn_ctx *tn_ctx_create(void)
{
    tn_ctx *c = (tn_ctx *)TN_MALLOC(sizeof(tn_ctx));
    if (!c) return NULL;
    memset(c, 0, sizeof *c);
    c->grad_enabled = 1;
    return c;
}

TN_API void tn_ctx_free(tn_ctx *ctx)
{
    tn__block *b, *n;
    if (!ctx) return;
    for (b = ctx->blocks; b; b = n) {
        n = b->next;
        TN_FREE(b);
    }
    TN_FREE(ctx->tape);
    TN_FREE(ctx);
}

TN_API void tn_ctx_reset(tn_ctx *ctx)
{
    tn__block *b, *n;
    if (ctx->blocks && ctx->blocks->next) { /* merge into one block big enough for the peak */
        size_t want = ctx->peak + ctx->peak / 8 + 4096;
        for (b = ctx->blocks; b; b = n) {
            n = b->next;
            TN_FREE(b);
        }
        ctx->blocks = tn__block_new(want < TN__BLOCK_MIN ? TN__BLOCK_MIN : want);
    }
    if (ctx->blocks) ctx->blocks->used = 0;
    ctx->total_used = 0;
    ctx->tape_len = 0;
    ctx->status = TN_OK;
}

TN_API tn_status tn_ctx_status(const tn_ctx *ctx) { return ctx->status; }
TN_API size_t tn_ctx_used(const tn_ctx *ctx) { return ctx->total_used; }
TN_API void tn_ctx_set_grad(tn_ctx *ctx, int enabled) { ctx->grad_enabled = enabled != 0; }

TN_API void *tn_ctx_alloc(tn_ctx *ctx, size_t bytes)
{
    tn__block *b = ctx->blocks;
    void *p;
    bytes = (bytes + 63) & ~(size_t)63;
    if (!b || b->size - b->used < bytes) {
        size_t sz = bytes > TN__BLOCK_MIN ? bytes : TN__BLOCK_MIN;
        if (b && sz < b->size * 2 && b->size * 2 <= TN_MAX_ALLOC) sz = b->size * 2;
        b = tn__block_new(sz);
        if (!b) {
            if (!ctx->status) ctx->status = tn__fail(TN_ERR_OUT_OF_MEMORY, "tensor arena: cannot allocate %zu bytes", sz);
            return NULL;
        }
        b->next = ctx->blocks;
        ctx->blocks = b;
    }
    p = b->base + b->used;
    b->used += bytes;
    ctx->total_used += bytes;
    if (ctx->total_used > ctx->peak) ctx->peak = ctx->total_used;
    return p;
}

static float *tn__ctx_floats(tn_ctx *ctx, size_t n, int zero)
{
    float *p = (float *)tn_ctx_alloc(ctx, n * sizeof(float));
    if (p && zero) memset(p, 0, n * sizeof(float));
    return p;
}

/* A tensor in the arena; its data is zeroed only when `zero` (ops that write every element skip it). */
static tn_tensor *tn__tensor_make(tn_ctx *ctx, int ndim, const int *shape, int zero)
{
    tn_tensor *t;
    size_t n = 1;
    int i;
    TN_ASSERT(ndim >= 1 && ndim <= TN_MAX_DIMS);
    for (i = 0; i < ndim; i++) {
        TN_ASSERT(shape[i] >= 1);
        if (!tn__mul_size(n, (size_t)shape[i], &n) || n > TN_MAX_ALLOC / sizeof(float)) {
            if (!ctx->status) ctx->status = tn__fail(TN_ERR_TOO_LARGE, "tensor of %d dims is too large", ndim);
            return NULL;
        }
    }
    t = (tn_tensor *)tn_ctx_alloc(ctx, sizeof(tn_tensor));
    if (!t) return NULL;
    memset(t, 0, sizeof *t);
    t->ndim = ndim;
    for (i = 0; i < TN_MAX_DIMS; i++) t->shape[i] = i < ndim ? shape[i] : 1;
    t->numel = n;
    t->data = tn__ctx_floats(ctx, n, zero);
    return t->data ? t : NULL;
}

TN_API tn_tensor *tn_tensor_new(tn_ctx *ctx, int ndim, const int *shape) { return tn__tensor_make(ctx, ndim, shape, 1); }

TN_API tn_tensor *tn_tensor_1d(tn_ctx *ctx, int n) { return tn_tensor_new(ctx, 1, &n); }
TN_API tn_tensor *tn_tensor_2d(tn_ctx *ctx, int rows, int cols)
{
    int s[2];
    s[0] = rows; s[1] = cols;
    return tn_tensor_new(ctx, 2, s);
}
TN_API tn_tensor *tn_tensor_4d(tn_ctx *ctx, int n, int c, int h, int w)
{
    int s[4];
    s[0] = n; s[1] = c; s[2] = h; s[3] = w;
    return tn_tensor_new(ctx, 4, s);
}

TN_API tn_tensor *tn_tensor_requires_grad(tn_ctx *ctx, tn_tensor *t)
{
    if (!t) return NULL;
    if (!t->grad) t->grad = tn__ctx_floats(ctx, t->numel, 1);
    t->requires_grad = 1;
    return t->grad ? t : NULL;
}

TN_API void tn_tensor_fill(tn_tensor *t, float v)
{
    size_t i;
    for (i = 0; i < t->numel; i++) t->data[i] = v;
}

TN_API int tn_tensor_same_shape(const tn_tensor *a, const tn_tensor *b)
{
    int i;
    if (a->ndim != b->ndim) return 0;
    for (i = 0; i < a->ndim; i++)
        if (a->shape[i] != b->shape[i]) return 0;
    return 1;
}

TN_API tn_tensor *tn_tensor_from_image(tn_ctx *ctx, const tn_image *img)
{
    tn_tensor *t = tn_tensor_4d(ctx, 1, img->channels, img->height, img->width);
    size_t i, hw = (size_t)img->width * img->height;
    int c;
    if (!t) return NULL;
    for (c = 0; c < img->channels; c++)
        for (i = 0; i < hw; i++) t->data[(size_t)c * hw + i] = img->data[i * img->channels + c];
    return t;
}

TN_API tn_status tn_tensor_to_image(tn_image *img, const tn_tensor *t, int n)
{
    tn_image out = {0, 0, 0, NULL};
    size_t i, hw;
    int c;
    tn_status st;
    if (!t || t->ndim != 4 || n < 0 || n >= t->shape[0])
        return tn__fail(TN_ERR_INVALID_ARG, "tensor_to_image needs an N x C x H x W tensor and a valid batch index");
    if ((st = tn_image_create(&out, t->shape[3], t->shape[2], t->shape[1]))) return st;
    hw = (size_t)t->shape[2] * t->shape[3];
    for (c = 0; c < t->shape[1]; c++)
        for (i = 0; i < hw; i++)
            out.data[i * out.channels + c] = t->data[((size_t)n * t->shape[1] + c) * hw + i];
    *img = out;
    return TN_OK;
}

/* The gradient buffer of t, allocated (zeroed) on first use. */
static float *tn__grad(tn_ctx *ctx, tn_tensor *t)
{
    if (!t->grad) t->grad = tn__ctx_floats(ctx, t->numel, 1);
    return t->grad;
}

/* Creates an op's output (zeroed when `zero`) and, when any source needs a gradient, records it
   on the tape. */
static tn_tensor *tn__op_make(tn_ctx *ctx, int ndim, const int *shape, tn_backward_fn bw, tn_tensor *s0, tn_tensor *s1,
                              tn_tensor *s2, int zero)
{
    tn_tensor *t = tn__tensor_make(ctx, ndim, shape, zero);
    int need;
    if (!t) return NULL;
    need = ctx->grad_enabled && ((s0 && s0->requires_grad) || (s1 && s1->requires_grad) || (s2 && s2->requires_grad));
    t->src[0] = s0;
    t->src[1] = s1;
    t->src[2] = s2;
    if (need) {
        if (ctx->tape_len == ctx->tape_cap) {
            size_t cap = ctx->tape_cap ? ctx->tape_cap * 2 : 256;
            tn_tensor **nt = (tn_tensor **)TN_REALLOC(ctx->tape, cap * sizeof(tn_tensor *));
            if (!nt) {
                if (!ctx->status) ctx->status = tn__fail(TN_ERR_OUT_OF_MEMORY, "autograd tape: out of memory");
                return NULL;
            }
            ctx->tape = nt;
            ctx->tape_cap = cap;
        }
        ctx->tape[ctx->tape_len++] = t;
        t->requires_grad = 1;
        t->backward = bw;
    }
    return t;
}

static tn_tensor *tn__op(tn_ctx *ctx, int ndim, const int *shape, tn_backward_fn bw, tn_tensor *s0, tn_tensor *s1,
                         tn_tensor *s2)
{
    return tn__op_make(ctx, ndim, shape, bw, s0, s1, s2, 1);
}

/* Same shape as a. */
static tn_tensor *tn__op_like(tn_ctx *ctx, const tn_tensor *a, tn_backward_fn bw, tn_tensor *s0, tn_tensor *s1)
{
    return tn__op(ctx, a->ndim, a->shape, bw, s0, s1, NULL);
}

TN_API tn_status tn_backward(tn_ctx *ctx, tn_tensor *loss)
{
    size_t i;
    if (!loss) return ctx->status ? ctx->status : tn__fail(TN_ERR_INVALID_ARG, "backward: loss is NULL");
    if (ctx->status) return ctx->status;
    if (loss->numel != 1) return tn__fail(TN_ERR_SHAPE, "backward: the loss must have one element, not %zu", loss->numel);
    if (!loss->requires_grad) return tn__fail(TN_ERR_INVALID_ARG, "backward: the loss does not depend on anything that requires a gradient");
    if (!tn__grad(ctx, loss)) return ctx->status;
    loss->grad[0] += 1.0f;
    for (i = ctx->tape_len; i-- > 0;) {
        tn_tensor *t = ctx->tape[i];
        if (t->grad && t->backward) t->backward(ctx, t);
        if (ctx->status) return ctx->status;
    }
    return TN_OK;
}
#endif /* TN_NO_ENGINE */

