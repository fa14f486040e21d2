/* ============================================================================================
   @@style  terrain style transfer (paper 002, sections 2.2, 3, 4)
   The output map, initialised from the content map, is optimised so that the deep-feature
   statistics of a real heightmap (the style source) appear in it:
       alpha * content + beta * style + gamma * TV   (+ histogram terms with the built-in net).
   The style source is resized to the output size when the output is no larger than it; for a
   larger output it keeps its own pixel size (the output is a larger field of the same
   morphology: each pyramid level matches the source's level of the same pixel size, and the
   automatic pyramid stops where the source's coarsest level would be too small).
   Work runs coarse to fine over an image pyramid (each level x2): the coarse levels lay out
   ridges and valleys, the fine ones add detail; levels larger than `tile` are optimised in
   overlapping tiles, so 2048 x 2048 runs in the memory of a 512 x 512 map.
   Heights: maps are standardised internally; the output is returned in the style source's
   height units (metres when the source has them), with the source's mean and spread.

   Built-in feature network (no weights file): fixed random zero-mean filters (Kaiming normal,
   seeded), reflect padding, ReLU, 2 x 2 average pooling:
       conv 5x5 1->24 | pool | conv 3x3 24->32 | pool | conv 3x3 32->48 | pool | conv 3x3 48->64
   Style = per layer Gram-matrix distance (relative to the source's Gram) plus a sliced
   Wasserstein distance (Heitz et al. 2021: features projected on C fixed random directions,
   sorted, compared with the source's sorted projections); histogram terms match the sorted
   heights and slopes of the source; content = relative squared distance of the third layer.
   Drainage terms (drain_weight, valley_weight; by default on for fluvial sources, i.e. under
   5 % of the source in closed basins deeper than 0.1 % of its height range, off for dunes,
   craters and karst): the depression depths (depression-filled map minus map, @@extract's
   priority flood) are sorted-matched to the source's, so a source without closed basins
   removes them; and every cell's relief (height minus its Gaussian-smoothed surroundings,
   sigma 2 px) is pulled towards the source's mean relief for cells of the same D8 drainage
   area (log2 bins), on all levels but the finest, so valleys are carved where water collects
   and the network connects. The filled map and the drainage bins are recomputed every
   evaluation and held constant in the gradient. Those levels run on a canvas grown by a
   mirrored margin (1/8 of the smaller side) that is cut off afterwards, so the truncated
   drainage at the canvas edge leaves no frame on the map. With the terms on, the automatic
   pyramid goes one level coarser (coarsest side >= 32).

   VGG-19 (tn_vgg19_load): the paper's network. Greyscale is fed as three identical channels in
   [0, 1] with ImageNet normalisation (mean 0.485 0.456 0.406, std 0.229 0.224 0.225), max
   pooling; content conv5_2 (0.5 * sum of squares), style conv1_1 conv2_1 conv3_1 conv4_1
   conv5_1 (sum (G1 - G2)^2 / (4 * 3^2 * (H*W)^2), the published code's normaliser),
   TV sum (dx^2 + dy^2)^1.25; default weights are the published code's (content 2.5e-11,
   style 1e-5, TV 1e-10).
   .tnw tensor names and layout (PyTorch order, float32): conv<g>_<i>.weight  Cout x Cin x 3 x 3
   and conv<g>_<i>.bias  Cout, for the 16 convolutions conv1_1 conv1_2 conv2_1 conv2_2
   conv3_1..conv3_4 conv4_1..conv4_4 conv5_1..conv5_4 (channels 64, 128, 256, 512, 512; conv1_1
   has Cin 3), exactly these 32 tensors. examples/vgg19_to_tnw.py converts a torchvision
   state dict (torchvision.models.vgg19 features.N.weight/bias).
   ============================================================================================ */
#ifndef TN_NO_STYLE
#if defined(TN_NO_ENGINE) || defined(TN_NO_NOISE) || defined(TN_NO_EXTRACT)
#error "terrainnet: @@style needs the tensor engine, @@noise, @@extract; define TN_NO_STYLE too, or none of them"
#endif

typedef enum tn_style_optimizer { TN_STYLE_LBFGS = 0, TN_STYLE_SGD, TN_STYLE_ADAM } tn_style_optimizer;

typedef struct tn_style_opts {
    tn_style_optimizer optimizer; /* L-BFGS (default), SGD with exponential decay, Adam */
    int iters;            /* iterations per pyramid level; 0 = default (L-BFGS 40, Adam 150, SGD 300) */
    int levels;           /* pyramid levels; 0 = auto (coarsest side >= 64, >= 32 with drainage terms; at most 6) */
    int tile;             /* levels wider or taller than this are optimised in tiles; 0 = 512 */
    /* Loss weights; 0 = the network's default, negative = term off. */
    float content_weight; /* alpha */
    float style_weight;   /* beta: Gram term */
    float sw_weight;      /* built-in net: sliced Wasserstein term */
    float hist_weight;    /* built-in net: height and slope histogram terms */
    float drain_weight;   /* built-in net: closed basins (depressions) as deep as the source's; 0 = 10 for fluvial sources, else off */
    float valley_weight;  /* built-in net: valley relief per drainage area as in the source (all but the finest level); 0 = 1 for fluvial sources, else off */
    float tv_weight;      /* gamma */
    float lr;             /* SGD / Adam learning rate; 0 = default (SGD decays x0.96 every iters/20 steps) */
    uint64_t seed;        /* random filters and projections of the built-in net */
    const tn_params *vgg; /* VGG-19 weights from tn_vgg19_load; NULL = the built-in network */
} tn_style_opts;

/* Restyles `content` (any one-channel map, e.g. tn_noise_perlin output; channel 0 is used) with
   the morphology of `style` (a heightmap). *out has the content's size and the style's height
   units. opts may be NULL. Reports progress as stage "style". NaN/Inf in either map fails with
   TN_ERR_NUMERIC; maps smaller than 16 x 16 with TN_ERR_INVALID_ARG. */
TN_API tn_status tn_style_transfer(tn_image *out, const tn_image *content, const tn_image *style, const tn_style_opts *opts);

/* The VGG-19 convolution layout above with zero weights (to fill and save, e.g. for tests). */
TN_API tn_status tn_vgg19_create(tn_params **out);
/* Loads VGG-19 convolution weights from a .tnw file; a wrong tensor name, count or shape fails
   with TN_ERR_SHAPE naming the tensor. Caller frees with tn_params_free. */
TN_API tn_status tn_vgg19_load(tn_params **out, const char *path);

/* How well a map reproduces a source's morphology (paper 002, Table 1, plus two distances).
   Both are normalised to [0, 1]. SSIM compares with the source resized to the map's size; the
   distances are tn_realism_compare's (@@extract) against the source at the pixel scale
   tn_style_transfer matches: resized to the map, or its own size when the map is larger. */
typedef struct tn_style_scores {
    double ssim;            /* SSIM(source, map), Table 1: higher is closer */
    double slope_hist_dist; /* tn_realism slope_distance (relative EMD of slope histograms): lower is closer */
    double spectrum_dist;   /* tn_realism spectrum_distance (RMS log10 spectrum difference): lower is closer */
} tn_style_scores;
TN_API tn_status tn_style_compare(tn_style_scores *out, const tn_image *map, const tn_image *source);

/* A Perlin fBm content map of width x height for `source`: the gain is picked from 0.45, 0.50,
   ..., 0.90 to minimise tn_style_compare's slope-histogram + spectrum distances to the source,
   so the content starts with the source's roughness and the transfer rebuilds its morphology
   (smooth gain-0.5 content against a rough source is what made Table-1 SSIM fall; README).
   opts: seed, octaves, frequency, lacunarity, periodic (its gain is ignored); NULL = defaults.
   *gain_out (may be NULL) gets the gain. Costs ten noise maps and ten comparisons. */
TN_API tn_status tn_style_content_noise(tn_image *out, int width, int height, const tn_image *source,
                                        const tn_perlin_opts *opts, float *gain_out);
#endif /* TN_NO_STYLE */

/* --------------------------------------------------------------------------------------------
   >>style  (@@style implementation)
   One evaluation = reset the level's arena, run the feature net on the current map with the
   tape on, sum the loss terms, backward; the gradient wrt the map drives L-BFGS / SGD / Adam.
   Targets (source Grams, sorted source projections, sorted heights and slopes, content
   features) are computed once per pyramid level and kept outside the arena.
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_STYLE

/* Per-row sorting work, rows split round-robin over threads (each row's result is independent of
   the split). mode 0: sorted copy of each row into out; mode 1: residual of the sorted row
   against the target (written back at the unsorted positions) and the row's squared sum. */
typedef struct tn__rowsort_job {
    const float *x, *target;
    float *out;
    double *rowsum;
    size_t rows, n, nt;
    int mode, failed;
} tn__rowsort_job;

static void tn__rowsort_task(void *ctx, int ith, int nth)
{
    tn__rowsort_job *j = (tn__rowsort_job *)ctx;
    uint32_t *idx = (uint32_t *)TN_MALLOC(4 * j->n * sizeof(uint32_t));
    size_t r, i;
    if (!idx) {
        j->failed = 1;
        return;
    }
    for (r = (size_t)ith; r < j->rows; r += (size_t)nth) {
        const float *x = j->x + r * j->n;
        float *o = j->out + r * j->n;
        if (j->mode == 0) {
            tn__argsort_f32(x, j->n, idx, idx + j->n);
            for (i = 0; i < j->n; i++) o[i] = x[idx[i]];
        } else
            j->rowsum[r] = tn__ot_residuals(x, j->n, j->target + r * j->nt, j->nt, idx, o);
    }
    TN_FREE(idx);
}

static tn_status tn__rowsort_run(tn__rowsort_job *j)
{
    j->failed = 0;
    tn_parallel_run(tn__rowsort_task, j);
    return j->failed ? tn__fail(TN_ERR_OUT_OF_MEMORY, "style: out of memory sorting %zu values", j->n) : TN_OK;
}

static void tn__sorted_match_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    const float *r = (const float *)out->aux;
    float *g = tn__grad(ctx, x), k;
    size_t i;
    if (!g) return;
    k = 2.0f * out->grad[0] * out->fp[0];
    for (i = 0; i < x->numel; i++) g[i] += k * r[i];
}

/* scale * mean((sort(row of x) - target row)^2) over the rows of x (rows x n): the squared 1-D
   Wasserstein-2 distance between each row's values and the sorted target row (length nt). */
static tn_tensor *tn__sorted_match(tn_ctx *ctx, tn_tensor *x, const float *target, size_t nt, float scale)
{
    int one = 1;
    tn__rowsort_job j;
    tn_tensor *o;
    double s = 0;
    size_t r;
    if (!x) return NULL;
    o = tn__op(ctx, 1, &one, tn__sorted_match_backward, x, NULL, NULL);
    if (!o) return NULL;
    memset(&j, 0, sizeof j);
    j.x = x->data;
    j.target = target;
    j.rows = (size_t)x->shape[0];
    j.n = x->numel / j.rows;
    j.nt = nt;
    j.mode = 1;
    j.out = tn__ctx_floats(ctx, x->numel, 0);
    j.rowsum = (double *)tn_ctx_alloc(ctx, j.rows * sizeof(double));
    if (!j.out || !j.rowsum) return NULL;
    if (tn__rowsort_run(&j)) {
        if (!ctx->status) ctx->status = TN_ERR_OUT_OF_MEMORY;
        return NULL;
    }
    for (r = 0; r < j.rows; r++) s += j.rowsum[r];
    o->aux = j.out;
    o->fp[0] = scale / (float)x->numel;
    o->data[0] = (float)(s * scale / (double)x->numel);
    return o;
}

/* ---- feature networks ---- */

static const int tn__sn_ch[4] = {24, 32, 48, 64}, tn__sn_k[4] = {5, 3, 3, 3};
static const int tn__vgg_groups[5] = {2, 2, 4, 4, 4}, tn__vgg_ch[5] = {64, 128, 256, 512, 512};

/* tn__style_net: in src/internal.h, with the pyramid level and the configuration */

static tn_status tn__style_net_builtin(tn__style_net *net, uint64_t seed)
{
    tn_rng rng;
    int l, cin = 1;
    memset(net, 0, sizeof *net);
    if (!(net->own = tn_params_create())) return tn__fail(TN_ERR_OUT_OF_MEMORY, "style: out of memory");
    tn_rng_seed(&rng, seed, 0x57f1e);
    for (l = 0; l < 4; l++) {
        int shape[4], o;
        char name[64];
        size_t k, fan;
        tn_tensor *w;
        shape[0] = tn__sn_ch[l];
        shape[1] = cin;
        shape[2] = shape[3] = tn__sn_k[l];
        sprintf(name, "f%d.weight", l + 1);
        if (!(w = tn_params_add_buffer(net->own, name, 4, shape))) return tn__fail(TN_ERR_OUT_OF_MEMORY, "style: out of memory");
        tn_init_kaiming(w, &rng, 1.41421356f);
        fan = w->numel / (size_t)shape[0];
        for (o = 0; o < shape[0]; o++) { /* zero-mean filters respond to shape, not to height level */
            float *f = w->data + (size_t)o * fan;
            double m = 0;
            for (k = 0; k < fan; k++) m += f[k];
            for (k = 0; k < fan; k++) f[k] -= (float)(m / (double)fan);
        }
        net->w[l] = w;
        cin = shape[0];
    }
    net->nconv = 4;
    return TN_OK;
}

TN_API tn_status tn_vgg19_create(tn_params **out)
{
    tn_params *p = tn_params_create();
    int g, i, cin = 3;
    if (!out) return tn__fail(TN_ERR_INVALID_ARG, "vgg19: out is NULL");
    if (!p) return tn__fail(TN_ERR_OUT_OF_MEMORY, "vgg19: out of memory");
    for (g = 0; g < 5; g++)
        for (i = 0; i < tn__vgg_groups[g]; i++) {
            int ws[4], bs = tn__vgg_ch[g];
            char name[64];
            ws[0] = tn__vgg_ch[g];
            ws[1] = cin;
            ws[2] = ws[3] = 3;
            sprintf(name, "conv%d_%d.weight", g + 1, i + 1);
            if (!tn_params_add_buffer(p, name, 4, ws)) break;
            sprintf(name, "conv%d_%d.bias", g + 1, i + 1);
            if (!tn_params_add_buffer(p, name, 1, &bs)) break;
            cin = ws[0];
        }
    if (tn_params_count(p) != 32) {
        tn_params_free(p);
        return tn__fail(TN_ERR_OUT_OF_MEMORY, "vgg19: out of memory");
    }
    *out = p;
    return TN_OK;
}

TN_API tn_status tn_vgg19_load(tn_params **out, const char *path)
{
    tn_params *p = NULL;
    tn_status st;
    if (!out || !path) return tn__fail(TN_ERR_INVALID_ARG, "vgg19: NULL argument");
    if ((st = tn_vgg19_create(&p))) return st;
    if ((st = tn_params_load(p, path))) {
        tn_params_free(p);
        return st;
    }
    *out = p;
    return TN_OK;
}

static tn_status tn__style_net_vgg(tn__style_net *net, const tn_params *p)
{
    int g, i, k = 0, cin = 3;
    memset(net, 0, sizeof *net);
    net->vgg = 1;
    for (g = 0; g < 5; g++)
        for (i = 0; i < tn__vgg_groups[g]; i++, k++) {
            char name[64];
            tn_tensor *w, *b;
            sprintf(name, "conv%d_%d.weight", g + 1, i + 1);
            w = tn_params_find(p, name);
            sprintf(name, "conv%d_%d.bias", g + 1, i + 1);
            b = tn_params_find(p, name);
            if (!w || !b || w->ndim != 4 || w->shape[0] != tn__vgg_ch[g] || w->shape[1] != cin || w->shape[2] != 3 ||
                w->shape[3] != 3 || (int)b->numel != tn__vgg_ch[g])
                return tn__fail(TN_ERR_SHAPE, "style: the VGG-19 weights lack conv%d_%d or have the wrong shape (use tn_vgg19_load)", g + 1, i + 1);
            net->w[k] = w;
            net->b[k] = b;
            cin = tn__vgg_ch[g];
        }
    net->nconv = k;
    return TN_OK;
}

/* Runs the net on x (1 x 1 x H x W, in the net's input space); fills the style layers and the
   content layer and returns how many style layers there are (0 when out of memory). */
static int tn__style_forward(tn_ctx *ctx, const tn__style_net *net, tn_tensor *x, tn_tensor **style, tn_tensor **content)
{
    tn_conv_opts co;
    tn_tensor *h = x;
    int l;
    memset(&co, 0, sizeof co);
    if (!net->vgg) {
        co.padding = TN_PADDING_REFLECT;
        for (l = 0; l < 4; l++) {
            if (l) h = tn_avg_pool2d(ctx, h, 2, 2);
            co.pad = tn__sn_k[l] / 2;
            h = tn_relu(ctx, tn_conv2d(ctx, h, net->w[l], NULL, &co));
            style[l] = h;
        }
        *content = style[2];
        return h ? 4 : 0;
    } else {
        static const float mean[3] = {0.485f, 0.456f, 0.406f}, sd[3] = {0.229f, 0.224f, 0.225f};
        int g, i, k = 0;
        h = NULL;
        for (i = 0; i < 3; i++) {
            tn_tensor *c = tn_scale_shift(ctx, x, 1.0f / sd[i], -mean[i] / sd[i]);
            h = h ? tn_concat(ctx, h, c, 1) : c;
        }
        co.pad = 1;
        *content = NULL;
        for (g = 0; g < 5 && !*content; g++) {
            if (g) h = tn_max_pool2d(ctx, h, 2, 2);
            for (i = 0; i < tn__vgg_groups[g]; i++, k++) {
                h = tn_relu(ctx, tn_conv2d(ctx, h, net->w[k], net->b[k], &co));
                if (i == 0) style[g] = h;
                if (g == 4 && i == 1) {
                    *content = h;
                    break;
                }
            }
        }
        return *content ? 5 : 0;
    }
}

/* ---- one pyramid level (or one tile of it): targets, loss, gradient ---- */

/* tn__style_level: in src/internal.h (test_style and bench_style run one level) */

TN__INTERNAL void tn__style_level_free(tn__style_level *L)
{
    int l;
    for (l = 0; l < TN__STYLE_MAXL; l++) {
        TN_FREE(L->gram[l]);
        TN_FREE(L->dirs[l]);
        TN_FREE(L->sorted[l]);
    }
    TN_FREE(L->content);
    TN_FREE(L->hsorted);
    TN_FREE(L->ssorted);
    TN_FREE(L->dsorted);
    tn_ctx_free(L->ctx);
    memset(L, 0, sizeof *L);
}

/* Slope magnitude (forward differences) of a 1 x 1 x H x W map, as a 1 x (H-1)(W-1) row. */
static tn_tensor *tn__style_slope(tn_ctx *ctx, tn_tensor *x)
{
    tn_tensor *dx, *dy, *s;
    int shape[2];
    tn__diffs(ctx, x, &dx, &dy);
    s = tn_pow_abs(ctx, tn_scale_shift(ctx, tn_add(ctx, tn_square(ctx, dx), tn_square(ctx, dy)), 1.0f, 1e-6f), 0.5f);
    if (!s) return NULL;
    shape[0] = 1;
    shape[1] = (int)s->numel;
    return tn_reshape(ctx, s, 2, shape);
}

static tn_tensor *tn__style_map_tensor(tn_ctx *ctx, const float *v, int w, int h)
{
    tn_tensor *t = tn_tensor_4d(ctx, 1, 1, h, w);
    if (t) memcpy(t->data, v, (size_t)w * h * sizeof(float));
    return t;
}

static float *tn__style_dup(const float *v, size_t n)
{
    float *p = (float *)tn__alloc(n * sizeof(float));
    if (p) memcpy(p, v, n * sizeof(float));
    return p;
}

static tn_status tn__style_sort_rows(const float *x, size_t rows, size_t n, float *out)
{
    tn__rowsort_job j;
    memset(&j, 0, sizeof j);
    j.x = x;
    j.out = out;
    j.rows = rows;
    j.n = n;
    return tn__rowsort_run(&j);
}

/* Source statistics from `ncrop` source tiles (each L->w x L->h; the optimised tiles may differ
   in size): Grams are averaged; each crop's sorted projections are resampled to n / ncrop
   values (at least 1), pooled and sorted. */
TN__INTERNAL tn_status tn__style_targets(tn__style_level *L, const float *const *crops, int ncrop, uint64_t seed)
{
    tn_ctx *ctx = L->ctx;
    tn_rng rng;
    int c, l;
    tn_status st = TN_OK;
    float *pool[TN__STYLE_MAXL];
    memset(pool, 0, sizeof pool);
    tn_rng_seed(&rng, seed, 0x5d1ec7);
    for (c = 0; c < ncrop && !st; c++) {
        tn_tensor *x, *sf[TN__STYLE_MAXL], *cf;
        tn_ctx_reset(ctx);
        tn_ctx_set_grad(ctx, 0);
        x = tn__style_map_tensor(ctx, crops[c], L->w, L->h);
        L->nstyle = x ? tn__style_forward(ctx, L->net, x, sf, &cf) : 0;
        if (!L->nstyle) {
            st = tn_ctx_status(ctx) ? tn_ctx_status(ctx) : tn__fail(TN_ERR_OUT_OF_MEMORY, "style: out of memory");
            break;
        }
        for (l = 0; l < L->nstyle && !st; l++) {
            int C = sf[l]->shape[1];
            size_t hw = sf[l]->numel / (size_t)C, k, part = hw >= (size_t)ncrop ? hw / (size_t)ncrop : 1, i;
            tn_tensor *g = tn_gram(ctx, sf[l], L->net->vgg ? 1.0f : 1.0f / (float)hw), *D, *F2, *P;
            int shape[2];
            L->ch[l] = C;
            if (!g) { st = TN_ERR_OUT_OF_MEMORY; break; }
            if (!L->gram[l] && !(L->gram[l] = (float *)tn__calloc((size_t)C * C * sizeof(float)))) { st = TN_ERR_OUT_OF_MEMORY; break; }
            for (k = 0; k < (size_t)C * C; k++) L->gram[l][k] += g->data[k] / (float)ncrop;
            if (L->net->vgg || L->wsw <= 0) continue;
            if (!L->dirs[l]) { /* C random unit directions */
                if (!(L->dirs[l] = (float *)tn__alloc((size_t)C * C * sizeof(float)))) { st = TN_ERR_OUT_OF_MEMORY; break; }
                for (i = 0; i < (size_t)C; i++) {
                    double s = 0;
                    for (k = 0; k < (size_t)C; k++) {
                        float v = tn_rng_normal(&rng);
                        L->dirs[l][i * C + k] = v;
                        s += (double)v * v;
                    }
                    for (k = 0; k < (size_t)C; k++) L->dirs[l][i * C + k] /= (float)sqrt(s > 0 ? s : 1);
                }
                L->snt[l] = part * (size_t)ncrop;
                if (!(pool[l] = (float *)tn__alloc((size_t)C * L->snt[l] * sizeof(float)))) { st = TN_ERR_OUT_OF_MEMORY; break; }
            }
            D = tn_tensor_2d(ctx, C, C);
            shape[0] = C;
            shape[1] = (int)hw;
            F2 = tn_reshape(ctx, sf[l], 2, shape);
            if (D) memcpy(D->data, L->dirs[l], (size_t)C * C * sizeof(float));
            P = tn_matmul(ctx, D, F2, 0, 0);
            {
                float *srt = P ? tn__ctx_floats(ctx, P->numel, 0) : NULL;
                if (!srt || (st = tn__style_sort_rows(P->data, (size_t)C, hw, srt))) { st = st ? st : TN_ERR_OUT_OF_MEMORY; break; }
                for (i = 0; i < (size_t)C; i++)
                    for (k = 0; k < part; k++)
                        pool[l][i * L->snt[l] + (size_t)c * part + k] = tn__quantile_at(srt + i * hw, hw, k, part);
            }
        }
    }
    for (l = 0; l < L->nstyle && !st; l++) {
        size_t k, n = (size_t)L->ch[l] * L->ch[l];
        double s = 0;
        for (k = 0; k < n; k++) s += (double)L->gram[l][k] * L->gram[l][k];
        L->gnorm[l] = s > 1e-30 ? s : 1e-30;
        if (!pool[l]) continue;
        if (!(L->sorted[l] = (float *)tn__alloc((size_t)L->ch[l] * L->snt[l] * sizeof(float)))) { st = TN_ERR_OUT_OF_MEMORY; break; }
        if ((st = tn__style_sort_rows(pool[l], (size_t)L->ch[l], L->snt[l], L->sorted[l]))) break;
        s = 0;
        for (k = 0; k < (size_t)L->ch[l] * L->snt[l]; k++) s += (double)L->sorted[l][k] * L->sorted[l][k];
        s /= (double)L->ch[l] * L->snt[l];
        L->svar[l] = s > 1e-30 ? s : 1e-30;
    }
    for (l = 0; l < TN__STYLE_MAXL; l++) TN_FREE(pool[l]);
    tn_ctx_set_grad(ctx, 1);
    return st;
}

/* Depression-filled copy of a w x h map (priority flood, @@extract): water leaves every cell. */
static tn_status tn__style_fill(const float *v, int w, int h, float *filled)
{
    tn_image m, f = {0, 0, 0, NULL};
    tn_status st;
    m.width = w;
    m.height = h;
    m.channels = 1;
    m.data = (float *)v;
    if ((st = tn_fill_depressions(&f, &m))) return st;
    memcpy(filled, f.data, (size_t)w * h * sizeof(float));
    tn_image_free(&f);
    return TN_OK;
}

/* Gaussian kernel of the relief (sigma 2 px, 9 x 9) as a 1 x 1 x 9 x 9 tensor. */
static tn_tensor *tn__style_relief_kernel(tn_ctx *ctx)
{
    tn_tensor *k = tn_tensor_4d(ctx, 1, 1, 9, 9);
    double g[9], s = 0;
    int i, j;
    if (!k) return NULL;
    for (i = 0; i < 9; i++) s += g[i] = exp(-0.125 * (i - 4) * (i - 4));
    for (i = 0; i < 9; i++)
        for (j = 0; j < 9; j++) k->data[i * 9 + j] = (float)(g[i] * g[j] / (s * s));
    return k;
}

/* Relief = height minus its Gaussian-smoothed height (reflect padding): negative in valley bottoms,
   positive on ridges. xs is the map the smoothing reads (x itself, or x with cells held fixed). */
static tn_tensor *tn__style_relief(tn_ctx *ctx, tn_tensor *x, tn_tensor *xs)
{
    tn_conv_opts co;
    memset(&co, 0, sizeof co);
    co.padding = TN_PADDING_REFLECT;
    co.pad = 4;
    return tn_sub(ctx, x, tn_conv2d(ctx, xs, tn__style_relief_kernel(ctx), NULL, &co));
}

#define TN__STYLE_LAKE 255 /* drainage bin of a cell left alone: in a depression */
#define TN__STYLE_BAND 2   /* px: cells this close to the edge drain straight off the map and share
                              one bin (TN__STYLE_ABINS) */

/* Distance of cell (x, y) from the nearest edge of a w x h map. */
static int tn__style_edge_dist(int x, int y, int w, int h)
{
    int a = x < w - 1 - x ? x : w - 1 - x, b = y < h - 1 - y ? y : h - 1 - y;
    return a < b ? a : b;
}

/* Points the cells of a TN__STYLE_BAND-wide border band straight at their nearest edge (the
   border row itself is an outlet). Left to D8, the band collects the flow of everything next
   to it and runs it along the edge, and the relief term then cuts a channel parallel to the
   border. In their own bin, the band's cells are neither carved nor raised into a rim (as
   cells draining only themselves would be), so flow leaves the map at any angle. */
TN__INTERNAL void tn__style_band_outflow(tn_flow *f)
{
    int w = f->width, h = f->height, x, y;
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++) {
            int l = x, r = w - 1 - x, t = y, b = h - 1 - y, m = l < r ? l : r, v = t < b ? t : b;
            uint8_t *d = &f->dir[(size_t)y * w + x];
            if (m >= TN__STYLE_BAND && v >= TN__STYLE_BAND) {
                x = w - TN__STYLE_BAND - 1; /* skip the interior of the row */
                continue;
            }
            if (!m || !v) *d = TN_FLOW_OUTLET;
            else if (m <= v) *d = l <= r ? 4 : 0; /* W or E (tn__d8x order) */
            else *d = t <= b ? 6 : 2;             /* N or S */
        }
}

/* Drainage bin of every cell of a w x h map v: floor(log2(D8 flow accumulation)) on its filled
   copy, capped at TN__STYLE_ABINS - 1; TN__STYLE_LAKE inside depressions (filled > v), where
   the flow crosses flats in straight lines that should not be carved, and near the edge. */
TN__INTERNAL tn_status tn__style_drain_bins(const float *filled, const float *v, int w, int h, uint8_t *bin)
{
    tn_image m;
    tn_flow f;
    size_t i, n = (size_t)w * h;
    tn_status st;
    m.width = w;
    m.height = h;
    m.channels = 1;
    m.data = (float *)filled;
    memset(&f, 0, sizeof f);
    if (!(st = tn_flow_directions(&f, &m))) tn__style_band_outflow(&f);
    if (st || (st = tn__flow_accumulate(&f))) { /* codes valid by construction: no check pass */
        tn_flow_free(&f);
        return st;
    }
    for (i = 0; i < n; i++) {
        uint32_t a = f.acc[i];
        int b = 0;
        while (a > 1 && b < TN__STYLE_ABINS - 1) { a >>= 1; b++; }
        int edge = tn__style_edge_dist((int)(i % (size_t)w), (int)(i / (size_t)w), w, h) < TN__STYLE_BAND;
        bin[i] = filled[i] > v[i] ? TN__STYLE_LAKE : edge ? TN__STYLE_ABINS : (uint8_t)b;
    }
    tn_flow_free(&f);
    return TN_OK;
}

/* The source's mean relief per drainage bin (empty bins take the next lower bin's value) and
   its mean squared relief, from the source level x and its filled copy. */
static tn_status tn__style_relief_targets(tn__style_level *L, tn_tensor *x, const float *filled, int w, int h)
{
    size_t i, n = (size_t)w * h;
    tn_tensor *rt = tn__style_relief(L->ctx, x, x);
    float *r = rt ? rt->data : NULL;
    uint8_t *bin = (uint8_t *)tn__alloc(n);
    double sum[TN__STYLE_ABINS + 1], cnt[TN__STYLE_ABINS + 1], s2 = 0;
    int b;
    tn_status st = r && bin ? TN_OK : TN_ERR_OUT_OF_MEMORY;
    if (!st) st = tn__style_drain_bins(filled, x->data, w, h, bin);
    if (!st) {
        memset(sum, 0, sizeof sum);
        memset(cnt, 0, sizeof cnt);
        for (i = 0; i < n; i++) {
            s2 += (double)r[i] * r[i];
            if (bin[i] == TN__STYLE_LAKE) continue;
            sum[bin[i]] += r[i];
            cnt[bin[i]] += 1;
        }
        for (b = 0; b < TN__STYLE_ABINS; b++) L->relief_t[b] = cnt[b] > 0 ? (float)(sum[b] / cnt[b]) : (b ? L->relief_t[b - 1] : 0.0f);
        L->relief_t[TN__STYLE_ABINS] = cnt[TN__STYLE_ABINS] > 0 ? (float)(sum[TN__STYLE_ABINS] / cnt[TN__STYLE_ABINS]) : 0.0f;
        s2 /= (double)n;
        L->relief2 = s2 > 1e-30 ? s2 : 1e-30;
    }
    TN_FREE(bin);
    return st;
}

/* Sorted heights and slopes of the whole source level (w x h). */
TN__INTERNAL tn_status tn__style_hist_targets(tn__style_level *L, const float *src, int w, int h)
{
    tn_ctx *ctx = L->ctx;
    tn_tensor *x, *s;
    float *f = NULL;
    tn_status st;
    size_t k;
    double m = 0;
    tn_ctx_reset(ctx);
    tn_ctx_set_grad(ctx, 0);
    x = tn__style_map_tensor(ctx, src, w, h);
    s = x ? tn__style_slope(ctx, x) : NULL;
    tn_ctx_set_grad(ctx, 1);
    if (!s) return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : TN_ERR_OUT_OF_MEMORY;
    L->hn = x->numel;
    L->sn = s->numel;
    L->hsorted = (float *)tn__alloc(L->hn * sizeof(float));
    L->ssorted = (float *)tn__alloc(L->sn * sizeof(float));
    if (!L->hsorted || !L->ssorted) return TN_ERR_OUT_OF_MEMORY;
    if ((st = tn__style_sort_rows(x->data, 1, L->hn, L->hsorted)) || (st = tn__style_sort_rows(s->data, 1, L->sn, L->ssorted))) return st;
    for (k = 0; k < L->sn; k++) m += (double)L->ssorted[k] * L->ssorted[k];
    L->s2 = m / (double)L->sn > 1e-30 ? m / (double)L->sn : 1e-30;
    if (L->wdep <= 0 && L->wrel <= 0) return TN_OK;
    L->dn = L->hn;
    if (!(L->dsorted = (float *)tn__alloc(L->dn * sizeof(float))) || !(f = (float *)tn__alloc(L->dn * sizeof(float))))
        return TN_ERR_OUT_OF_MEMORY;
    if (!(st = tn__style_fill(src, w, h, f)) && !(st = tn__style_relief_targets(L, x, f, w, h))) {
        for (k = 0; k < L->dn; k++) f[k] -= src[k]; /* depression depths */
        st = tn__style_sort_rows(f, 1, L->dn, L->dsorted);
    }
    TN_FREE(f);
    return st;
}

/* Content-layer features of the anchor map (w x h). */
TN__INTERNAL tn_status tn__style_content_target(tn__style_level *L, const float *anchor)
{
    tn_ctx *ctx = L->ctx;
    tn_tensor *x, *sf[TN__STYLE_MAXL], *cf = NULL;
    size_t k;
    double s = 0;
    tn_ctx_reset(ctx);
    tn_ctx_set_grad(ctx, 0);
    x = tn__style_map_tensor(ctx, anchor, L->w, L->h);
    if (!x || !tn__style_forward(ctx, L->net, x, sf, &cf)) {
        tn_ctx_set_grad(ctx, 1);
        return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : TN_ERR_OUT_OF_MEMORY;
    }
    tn_ctx_set_grad(ctx, 1);
    TN_FREE(L->content);
    if (!(L->content = tn__style_dup(cf->data, cf->numel))) return TN_ERR_OUT_OF_MEMORY;
    memcpy(L->cshape, cf->shape, sizeof L->cshape);
    for (k = 0; k < cf->numel; k++) s += (double)cf->data[k] * cf->data[k];
    s /= (double)cf->numel;
    L->cnorm = s > 1e-30 ? s : 1e-30;
    return TN_OK;
}

static tn_tensor *tn__style_acc(tn_ctx *ctx, tn_tensor *acc, tn_tensor *term) { return acc ? tn_add(ctx, acc, term) : term; }

/* The total loss of map x (1 x 1 x h x w, recorded on the tape). */
static tn_tensor *tn__style_loss(tn__style_level *L, tn_tensor *x)
{
    tn_ctx *ctx = L->ctx;
    tn_tensor *sf[TN__STYLE_MAXL], *cf = NULL, *loss = NULL, *t;
    int l, ns = tn__style_forward(ctx, L->net, x, sf, &cf);
    double hw0 = (double)L->w * L->h;
    size_t q;
    if (!ns) return NULL;
    if (L->wc > 0) {
        t = tn_tensor_new(ctx, 4, L->cshape);
        if (!t) return NULL;
        memcpy(t->data, L->content, t->numel * sizeof(float));
        t = tn_sum(ctx, tn_square(ctx, tn_sub(ctx, cf, t)));
        loss = tn_scale_shift(ctx, t, L->net->vgg ? 0.5f * L->wc : (float)(L->wc / (L->cnorm * (double)cf->numel)), 0.0f);
    }
    for (l = 0; l < ns; l++) {
        int C = sf[l]->shape[1];
        size_t hw = sf[l]->numel / (size_t)C;
        if (L->wg > 0) {
            tn_tensor *g = tn_gram(ctx, sf[l], L->net->vgg ? 1.0f : 1.0f / (float)hw), *gt = tn_tensor_2d(ctx, C, C);
            double k = L->net->vgg ? L->wg / (4.0 * 9.0 * hw0 * hw0) : L->wg / (L->gnorm[l] * ns);
            if (!gt) return NULL;
            memcpy(gt->data, L->gram[l], (size_t)C * C * sizeof(float));
            loss = tn__style_acc(ctx, loss, tn_scale_shift(ctx, tn_sum(ctx, tn_square(ctx, tn_sub(ctx, g, gt))), (float)k, 0.0f));
        }
        if (L->wsw > 0 && L->sorted[l]) {
            tn_tensor *D = tn_tensor_2d(ctx, C, C), *P;
            int shape[2];
            if (!D) return NULL;
            memcpy(D->data, L->dirs[l], (size_t)C * C * sizeof(float));
            shape[0] = C;
            shape[1] = (int)hw;
            P = tn_matmul(ctx, D, tn_reshape(ctx, sf[l], 2, shape), 0, 0);
            loss = tn__style_acc(ctx, loss, tn__sorted_match(ctx, P, L->sorted[l], L->snt[l], (float)(L->wsw / (L->svar[l] * ns))));
        }
    }
    if (L->dsorted) { /* drainage terms; the filled map and the drainage bins are held constant */
        tn_tensor *f = tn_tensor_new(ctx, 4, x->shape), *rt = tn_tensor_new(ctx, 4, x->shape), *r;
        tn_tensor *fixed = tn_tensor_new(ctx, 4, x->shape), *free_ = tn_tensor_new(ctx, 4, x->shape);
        uint8_t *bin = (uint8_t *)tn_ctx_alloc(ctx, x->numel);
        int shape[2];
        if (!f || !rt || !fixed || !free_ || !bin) return NULL;
        if ((ctx->status = tn__style_fill(x->data, L->w, L->h, f->data)) ||
            (ctx->status = tn__style_drain_bins(f->data, x->data, L->w, L->h, bin)))
            return NULL;
        shape[0] = 1;
        shape[1] = (int)x->numel;
        /* closed basins as deep as the source's: depths filled - x, sorted-matched */
        if (L->wdep > 0)
            loss = tn__style_acc(ctx, loss, tn__sorted_match(ctx, tn_reshape(ctx, tn_sub(ctx, f, x), 2, shape), L->dsorted, L->dn, L->wdep));
        /* valleys as far below their surroundings as the source's with the same drainage area; cells
           left alone (lakes, the edge) are also held fixed in the smoothing, so nothing pushes them */
        if (L->wrel > 0) {
            for (q = 0; q < x->numel; q++) {
                int keep = bin[q] == TN__STYLE_LAKE;
                free_->data[q] = keep ? 0.0f : 1.0f;
                fixed->data[q] = keep ? x->data[q] : 0.0f;
            }
            r = tn__style_relief(ctx, x, tn_add(ctx, tn_mul(ctx, x, free_), fixed));
            if (!r) return NULL;
            for (q = 0; q < x->numel; q++) rt->data[q] = bin[q] == TN__STYLE_LAKE ? r->data[q] : L->relief_t[bin[q]];
            t = tn_sum(ctx, tn_square(ctx, tn_sub(ctx, r, rt)));
            loss = tn__style_acc(ctx, loss, tn_scale_shift(ctx, t, (float)(L->wrel / (L->relief2 * (double)x->numel)), 0.0f));
        }
    }
    if (L->wh > 0 && L->hsorted) {
        int shape[2];
        shape[0] = 1;
        shape[1] = (int)x->numel;
        loss = tn__style_acc(ctx, loss, tn__sorted_match(ctx, tn_reshape(ctx, x, 2, shape), L->hsorted, L->hn, L->wh));
        loss = tn__style_acc(ctx, loss, tn__sorted_match(ctx, tn__style_slope(ctx, x), L->ssorted, L->sn, (float)(L->wh / L->s2)));
    }
    if (L->wtv > 0) {
        t = tn_tv_loss(ctx, x, L->net->vgg ? 2.5f : 2.0f);
        loss = tn__style_acc(ctx, loss, tn_scale_shift(ctx, t, L->net->vgg ? L->wtv : (float)(L->wtv / hw0), 0.0f));
    }
    return loss;
}

/* Loss and gradient at xd (the tn_lbfgs callback). Failures are kept in L->status; NaN is returned. */
TN__INTERNAL float tn__style_eval(void *user, const float *xd, float *grad)
{
    tn__style_level *L = (tn__style_level *)user;
    tn_ctx *ctx = L->ctx;
    size_t n = (size_t)L->w * L->h;
    tn_tensor *x, *loss;
    tn_status st;
    if (L->status) return NAN;
    tn_ctx_reset(ctx);
    x = tn_tensor_requires_grad(ctx, tn__style_map_tensor(ctx, xd, L->w, L->h));
    loss = x ? tn__style_loss(L, x) : NULL;
    if (!loss) {
        L->status = tn_ctx_status(ctx) ? tn_ctx_status(ctx) : tn__fail(TN_ERR_INVALID_ARG, "style: no loss term is switched on");
        return NAN;
    }
    if ((st = tn_backward(ctx, loss))) {
        L->status = st;
        return NAN;
    }
    memcpy(grad, x->grad, n * sizeof(float));
    if (!(loss->data[0] == loss->data[0]) || loss->data[0] > FLT_MAX) {
        L->status = tn__fail(TN_ERR_NUMERIC, "style: the loss diverged (NaN/Inf); lower the learning rate");
        return NAN;
    }
    return loss->data[0];
}

/* ---- optimisation ---- */

/* tn__style_cfg: in src/internal.h */

/* Reports the fraction f of the tile being optimised as progress of the whole transfer. */
static int tn__style_report(tn__style_cfg *c, double f)
{
    c->frac = f;
    if (!c->user_fn) return 0;
    return c->user_fn(c->user_data, "style", c->work_total > 0 ? (c->work_done + f * c->span) / c->work_total : 0.0);
}

/* Installed for the whole transfer: the optimiser's own progress moves "style" on; the priority
   floods of the drainage terms (and their targets) report "fill", which only gets a chance to
   cancel, so the user sees one stage that never goes back. */
static int tn__style_progress_fwd(void *user, const char *stage, double f)
{
    tn__style_cfg *c = (tn__style_cfg *)user;
    return tn__style_report(c, strcmp(stage, "lbfgs") ? c->frac : f);
}

TN__INTERNAL tn_status tn__style_optimise(tn__style_level *L, float *x, tn__style_cfg *c)
{
    size_t n = (size_t)L->w * L->h;
    int it, iters = c->o.iters;
    tn_status st = TN_OK;
    c->span = (double)iters * (double)n;
    c->frac = 0;
    if (c->o.optimizer == TN_STYLE_LBFGS) {
        tn_lbfgs_opts lo;
        float f;
        memset(&lo, 0, sizeof lo);
        lo.max_iter = iters;
        lo.history = 10;
        lo.tol = 1e-9f;
        st = tn_lbfgs(x, n, tn__style_eval, L, &lo, &f);
        if (L->status) st = L->status; /* the real cause, not "objective is NaN" */
        if (st == TN_ERR_CANCELLED) st = tn__fail(TN_ERR_CANCELLED, "style: cancelled by the progress callback");
    } else {
        tn_params *p = tn_params_create();
        tn_optim_opts oo;
        tn_optim *opt = NULL;
        tn_tensor *t = NULL;
        int len = (int)n;
        memset(&oo, 0, sizeof oo);
        oo.kind = c->o.optimizer == TN_STYLE_ADAM ? TN_OPTIM_ADAM : TN_OPTIM_SGD;
        oo.lr = c->o.lr;
        if (c->o.optimizer == TN_STYLE_SGD) { /* the paper's schedule: x0.96 every 1/20 of the run */
            oo.lr_decay = 0.96f;
            oo.decay_every = iters / 20 > 0 ? iters / 20 : 1;
        }
        if (p) t = tn_params_add(p, "map", 1, &len);
        if (t) opt = tn_optim_create(p, &oo);
        if (!opt) st = tn__fail(TN_ERR_OUT_OF_MEMORY, "style: out of memory");
        if (t) memcpy(t->data, x, n * sizeof(float));
        for (it = 0; it < iters && !st; it++) {
            memset(t->grad, 0, n * sizeof(float));
            tn__style_eval(L, t->data, t->grad);
            if ((st = L->status)) break;
            tn_optim_step(opt);
            if (tn__style_report(c, (double)(it + 1) / iters)) st = tn__fail(TN_ERR_CANCELLED, "style: cancelled by the progress callback");
        }
        if (!st) memcpy(x, t->data, n * sizeof(float));
        tn_optim_free(opt);
        tn_params_free(p);
    }
    c->work_done += c->span;
    c->frac = 0; /* the next level's target fills report from here, not one tile ahead */
    return st;
}

/* Copies the w x h window at (x0, y0) of a one-channel map into dst. */
static void tn__style_window(float *dst, const tn_image *m, int x0, int y0, int w, int h)
{
    int y;
    for (y = 0; y < h; y++) memcpy(dst + (size_t)y * w, m->data + (size_t)(y0 + y) * m->width + x0, (size_t)w * sizeof(float));
}

/* Tile origins along one axis: tiles of length t overlapping by ov, the last one flush with the end. */
static int tn__style_tile_pos(int size, int t, int ov, int *pos, int max)
{
    int n = 0, p = 0;
    if (t >= size) {
        pos[0] = 0;
        return 1;
    }
    for (;;) {
        if (p + t >= size) {
            pos[n++] = size - t;
            return n;
        }
        if (n == max - 1) return 0; /* more tiles needed than pos holds */
        pos[n++] = p;
        p += t - ov;
    }
}

/* Blend weight of pixel i of a tile of length t at origin p on an axis of length size. */
static float tn__style_ramp(int i, int t, int p, int size, int ov)
{
    float w = 1.0f;
    if (p > 0 && i < ov) w = (float)(i + 1) / (float)(ov + 1);
    if (p + t < size && t - 1 - i < ov) {
        float v = (float)(t - i) / (float)(ov + 1);
        if (v < w) w = v;
    }
    return w;
}

#define TN__STYLE_MAXTILES 64

/* Tile length along an axis of `size` for tiles of nominal length t overlapping by t / 8: the
   fewest tiles of at most t that cover it, grown by the overlap (1024 -> 2 tiles of 576). */
static int tn__style_tile_len(int size, int t)
{
    int n = (size + t - 1) / t, len = (size + n - 1) / n + (n > 1 ? t / 8 : 0);
    return len < size ? len : size;
}

/* A level optimising w x h maps with the configured net and weights (targets still empty). */
TN__INTERNAL void tn__style_level_init(tn__style_level *L, const tn__style_cfg *c, int w, int h)
{
    memset(L, 0, sizeof *L);
    L->net = &c->net;
    L->w = w;
    L->h = h;
    L->wc = c->o.content_weight;
    L->wg = c->o.style_weight;
    L->wsw = c->o.sw_weight;
    L->wh = c->o.hist_weight;
    L->wtv = c->o.tv_weight;
    L->wdep = c->o.drain_weight;
    L->wrel = c->level > 0 ? c->o.valley_weight : -1.0f; /* the finest level only adds detail */
    L->ctx = tn_ctx_create();
}

/* Optimises one pyramid level: x (init in, result out), anchor = content target (x's size),
   src = source (x's size, or smaller when x carries a margin: its tiles give the targets). */
static tn_status tn__style_level_run(tn__style_cfg *c, const tn_image *src, const tn_image *anchor, tn_image *x)
{
    int W = x->width, H = x->height, T = c->o.tile, SW = src->width, SH = src->height;
    int tw = tn__style_tile_len(W, T), th = tn__style_tile_len(H, T), ov = T / 8;
    int sw = tn__style_tile_len(SW, T), sh = tn__style_tile_len(SH, T);
    int px[TN__STYLE_MAXTILES], py[TN__STYLE_MAXTILES], nx, ny, i, j, k, ncrop;
    float *buf = NULL, *wsum = NULL, *acc = NULL, **crops = NULL;
    size_t tn = (size_t)tw * th, sn = (size_t)sw * sh, n = (size_t)W * H, q;
    tn__style_level L;
    tn_status st = TN_OK;
    nx = tn__style_tile_pos(SW, sw, ov, px, TN__STYLE_MAXTILES); /* the caller checked the counts */
    ny = tn__style_tile_pos(SH, sh, ov, py, TN__STYLE_MAXTILES);
    ncrop = nx * ny;
    tn__style_level_init(&L, c, sw, sh);
    buf = (float *)tn__alloc((tn + sn * (size_t)ncrop) * sizeof(float));
    crops = (float **)tn__alloc((size_t)ncrop * sizeof(float *));
    acc = (float *)tn__calloc(2 * n * sizeof(float));
    if (!L.ctx || !buf || !crops || !acc) {
        st = tn__fail(TN_ERR_OUT_OF_MEMORY, "style: out of memory");
        goto done;
    }
    wsum = acc + n;
    for (j = 0, k = 0; j < ny; j++)
        for (i = 0; i < nx; i++, k++) {
            crops[k] = buf + tn + sn * (size_t)k;
            tn__style_window(crops[k], src, px[i], py[j], sw, sh);
        }
    if ((st = tn__style_targets(&L, (const float *const *)crops, ncrop, c->o.seed))) goto done;
    if (!c->net.vgg && (L.wh > 0 || L.wdep > 0 || L.wrel > 0) && (st = tn__style_hist_targets(&L, src->data, SW, SH))) goto done;
    L.w = tw; /* the targets are statistics: they hold for tiles of x's size too */
    L.h = th;
    nx = tn__style_tile_pos(W, tw, ov, px, TN__STYLE_MAXTILES);
    ny = tn__style_tile_pos(H, th, ov, py, TN__STYLE_MAXTILES);
    for (j = 0; j < ny && !st; j++)
        for (i = 0; i < nx && !st; i++) {
            int y, xx;
            tn__style_window(buf, anchor, px[i], py[j], tw, th);
            if (L.wc > 0 && (st = tn__style_content_target(&L, buf))) break;
            tn__style_window(buf, x, px[i], py[j], tw, th);
            if ((st = tn__style_optimise(&L, buf, c))) break;
            for (y = 0; y < th; y++)
                for (xx = 0; xx < tw; xx++) {
                    float w = tn__style_ramp(xx, tw, px[i], W, ov) * tn__style_ramp(y, th, py[j], H, ov);
                    size_t o = (size_t)(py[j] + y) * W + px[i] + xx;
                    acc[o] += w * buf[(size_t)y * tw + xx];
                    wsum[o] += w;
                }
        }
    if (!st)
        for (q = 0; q < n; q++) x->data[q] = acc[q] / wsum[q];
done:
    tn__style_level_free(&L);
    TN_FREE(buf);
    TN_FREE(crops);
    TN_FREE(acc);
    return st;
}

/* Affine normalisation of a map to the net's input space: standardised (built-in) or [0, 1]
   (VGG). Returns the offset and scale so that v = z * scale + offset. */
TN__INTERNAL void tn__style_normalise(tn_image *m, int unit_range, double *offset, double *scale)
{
    size_t i, n = (size_t)m->width * m->height;
    double a, b;
    if (unit_range) {
        float lo, hi;
        tn_image_range(&lo, &hi, m);
        a = lo;
        b = hi - lo;
    } else {
        double s = 0, s2 = 0;
        for (i = 0; i < n; i++) s += m->data[i];
        a = s / (double)n;
        for (i = 0; i < n; i++) s2 += (m->data[i] - a) * (m->data[i] - a);
        b = sqrt(s2 / (double)n);
    }
    if (!(b > 1e-12)) b = 1;
    for (i = 0; i < n; i++) m->data[i] = (float)((m->data[i] - a) / b);
    *offset = a;
    *scale = b;
}

static tn_status tn__style_resize(tn_image *dst, const tn_image *src, int w, int h)
{
    int down = w <= src->width && h <= src->height;
    return tn_image_resize(dst, src, w, h, down ? TN_RESIZE_AREA : TN_RESIZE_BICUBIC);
}

/* The source at the pixel scale the transfer matches (dst, one channel): resized to the map's
   w x h when the map is no larger than it, kept at its own size when the map is larger on either
   side: an upsampled source has smoothed statistics and the result turns blobby (docs/style.md).
   The map is then a larger field with the source's morphology, each pyramid level matched to
   the source's level of the same pixel size (tn__style_level_run only takes statistics from it). */
static tn_status tn__style_source_scale(tn_image *dst, const tn_image *src, int w, int h)
{
    if (w > src->width || h > src->height) return tn_image_copy(dst, src);
    return tn__style_resize(dst, src, w, h);
}

/* Size of pyramid level k (0 = full size, each level halves), at least 16 x 16. */
static void tn__style_level_size(int W, int H, int k, int *lw, int *lh)
{
    *lw = (int)(W / (double)(1 << k) + 0.5);
    *lh = (int)(H / (double)(1 << k) + 0.5);
    if (*lw < 16) *lw = 16;
    if (*lh < 16) *lh = 16;
}

/* The zero rules of tn_style_opts that follow from the options alone: iterations and learning
   rate per optimiser, tile 512, loss weights per network (VGG-19 or built-in), seed 1. Two
   rules need the maps and are applied in tn_style_transfer: the built-in net's drain_weight
   and valley_weight (tn__style_auto_drainage) and levels (tn__style_auto_levels). */
static void tn__style_opts_defaults(tn_style_opts *o)
{
    int vgg = o->vgg != NULL;
    if (!o->iters) o->iters = o->optimizer == TN_STYLE_LBFGS ? 40 : (o->optimizer == TN_STYLE_ADAM ? 150 : 300);
    if (!o->tile) o->tile = 512;
    if (o->content_weight == 0) o->content_weight = vgg ? 2.5e-11f : 0.1f;
    if (o->style_weight == 0) o->style_weight = vgg ? 1e-5f : 1.0f;
    if (o->sw_weight == 0) o->sw_weight = vgg ? -1.0f : 1.0f;
    if (o->hist_weight == 0) o->hist_weight = vgg ? -1.0f : 1.0f;
    if (vgg && o->drain_weight == 0) o->drain_weight = -1.0f;
    if (vgg && o->valley_weight == 0) o->valley_weight = -1.0f;
    if (o->tv_weight == 0) o->tv_weight = vgg ? 1e-10f : -1.0f;
    if (o->lr == 0) o->lr = o->optimizer == TN_STYLE_SGD ? (vgg ? 150.0f : 0.5f) : (vgg ? 0.01f : 0.02f);
    if (!o->seed) o->seed = 1;
}

/* Checks options whose defaults are applied (a zero never fails here). */
static tn_status tn__style_opts_check(const tn_style_opts *o)
{
    const float w[7] = {o->content_weight, o->style_weight, o->sw_weight, o->hist_weight, o->drain_weight, o->valley_weight, o->tv_weight};
    int i;
    if (o->optimizer != TN_STYLE_LBFGS && o->optimizer != TN_STYLE_SGD && o->optimizer != TN_STYLE_ADAM)
        return tn__fail(TN_ERR_INVALID_ARG, "style: unknown optimizer %d", (int)o->optimizer);
    if (o->iters < 0 || o->iters > 1000000) return tn__fail(TN_ERR_INVALID_ARG, "style: iters must be in 0..1000000");
    if (o->levels < 0 || o->levels > 8) return tn__fail(TN_ERR_INVALID_ARG, "style: levels must be in 0..8");
    if (o->tile < 0 || (o->tile > 0 && o->tile < 32)) return tn__fail(TN_ERR_INVALID_ARG, "style: tile must be 0 or >= 32");
    for (i = 0; i < 7; i++)
        if (!(w[i] >= -FLT_MAX && w[i] <= FLT_MAX)) return tn__fail(TN_ERR_INVALID_ARG, "style: loss weights must be finite");
    if (!(o->lr > 0 && o->lr <= FLT_MAX)) return tn__fail(TN_ERR_INVALID_ARG, "style: the learning rate must be positive and finite");
    return TN_OK;
}

/* Resolves and checks the options, and builds the network. */
TN__INTERNAL tn_status tn__style_setup(tn__style_cfg *c, const tn_style_opts *opts)
{
    tn_status st;
    memset(c, 0, sizeof *c);
    if (opts) c->o = *opts;
    tn__style_opts_defaults(&c->o);
    if ((st = tn__style_opts_check(&c->o))) return st;
    return c->o.vgg ? tn__style_net_vgg(&c->net, c->o.vgg) : tn__style_net_builtin(&c->net, c->o.seed);
}

/* Margin (px per side) of a w x h level: 1/8 of the smaller side, at least 2, on levels with
   the valley term (built-in net, all but the finest level); 0 elsewhere. */
static int tn__style_margin(const tn__style_cfg *c, int level, int w, int h)
{
    int m = (w < h ? w : h) / 8;
    if (level == 0 || !(c->o.valley_weight > 0) || c->net.vgg) return 0;
    return m < 2 ? 2 : m;
}

/* Tile size for a w x h level grown by margin m: a level that fits one tile stays in one. */
static int tn__style_margin_tile(const tn__style_cfg *c, int w, int h, int m)
{
    return w <= c->o.tile && h <= c->o.tile && m ? (w > h ? w : h) + 2 * m : c->o.tile;
}

/* Runs a level, with the valley term on a canvas grown by the mirrored margin and cut back
   afterwards. Drainage is truncated at the map's edge, and the valley term, optimised there,
   leaves a frame (a low edge and a rim a few px in); with the margin, the frame falls outside. */
static tn_status tn__style_level_margin(tn__style_cfg *c, const tn_image *s, tn_image *a, tn_image *x)
{
    tn_image pa = {0, 0, 0, NULL}, px = {0, 0, 0, NULL};
    int w = x->width, h = x->height, m = tn__style_margin(c, c->level, w, h), tile = c->o.tile;
    tn_status st;
    if (!m) return tn__style_level_run(c, s, a, x);
    c->o.tile = tn__style_margin_tile(c, w, h, m);
    if (!(st = tn_image_pad(&pa, a, m, m, m, m, TN_PAD_REFLECT)) && !(st = tn_image_pad(&px, x, m, m, m, m, TN_PAD_REFLECT)) &&
        !(st = tn__style_level_run(c, s, &pa, &px))) {
        tn_image_free(x);
        st = tn_image_crop(x, &px, m, m, w, h);
    }
    c->o.tile = tile;
    tn_image_free(&pa);
    tn_image_free(&px);
    return st;
}

#define TN__STYLE_BASIN_DEPTH 1e-3 /* of the height range: a cell this far under its filled level is in a closed basin */
#define TN__STYLE_BASIN_SHARE 0.05 /* sources with less of their area in closed basins are fluvial */

/* Default drainage terms from the source s (at map size): on (drain 10, valley 1) when under
   5 % of it lies in closed basins deeper than 0.1 % of its range, i.e. water leaves it through
   valleys (mountains, canyons; the shallow flats of 8-bit DEMs do not count); off for dunes,
   craters and karst, whose closed basins the valley term would cut open. */
TN__INTERNAL tn_status tn__style_auto_drainage(tn__style_cfg *c, const tn_image *s)
{
    size_t i, n = (size_t)s->width * s->height, deep = 0;
    float lo, hi, *f;
    tn_status st;
    int fluvial;
    if (c->o.drain_weight != 0 && c->o.valley_weight != 0) return TN_OK;
    if (!(f = (float *)tn__alloc(n * sizeof(float)))) return TN_ERR_OUT_OF_MEMORY;
    tn_image_range(&lo, &hi, s);
    if (!(st = tn__style_fill(s->data, s->width, s->height, f)))
        for (i = 0; i < n; i++) deep += f[i] - s->data[i] > TN__STYLE_BASIN_DEPTH * (hi - lo);
    TN_FREE(f);
    fluvial = (double)deep < TN__STYLE_BASIN_SHARE * (double)n;
    if (c->o.drain_weight == 0) c->o.drain_weight = fluvial ? 10.0f : -1.0f;
    if (c->o.valley_weight == 0) c->o.valley_weight = fluvial ? 1.0f : -1.0f;
    return st;
}

/* Pyramid levels for a W x H map when levels is 0: halve while the coarsest side stays >= 64,
   or >= 32 when the built-in net's drainage terms are on (they carve the valley network from
   one level coarser); at most 6. */
static int tn__style_auto_levels(const tn__style_cfg *c, int W, int H)
{
    int nl, coarsest = !c->net.vgg && (c->o.drain_weight > 0 || c->o.valley_weight > 0) ? 32 : 64;
    if (c->o.levels) return c->o.levels;
    for (nl = 1; nl < 6 && ((W < H ? W : H) >> nl) >= coarsest;) nl++;
    return nl;
}

TN_API tn_status tn_style_transfer(tn_image *out, const tn_image *content, const tn_image *style, const tn_style_opts *opts)
{
    tn__style_cfg *c;
    tn_image cm = {0, 0, 0, NULL}, sm = {0, 0, 0, NULL}, cur = {0, 0, 0, NULL};
    double sa, sb, ca, cb;
    int W, H, nl, k;
    tn_status st;
    size_t i;
    if (!out || !content || !style || !content->data || !style->data || content->channels < 1 || style->channels < 1)
        return tn__fail(TN_ERR_INVALID_ARG, "style: needs a content map and a style map");
    W = content->width;
    H = content->height;
    if (W < 16 || H < 16 || style->width < 16 || style->height < 16)
        return tn__fail(TN_ERR_INVALID_ARG, "style: maps must be at least 16 x 16 (content %d x %d, style %d x %d)", W, H,
                        style->width, style->height);
    if (tn_image_range(NULL, NULL, content)) return tn__fail(TN_ERR_NUMERIC, "style: the content map holds NaN/Inf");
    if (tn_image_range(NULL, NULL, style)) return tn__fail(TN_ERR_NUMERIC, "style: the style map holds NaN/Inf");
    if (!(c = (tn__style_cfg *)tn__alloc(sizeof *c))) return TN_ERR_OUT_OF_MEMORY;
    st = tn__style_setup(c, opts); /* clears c */
    c->user_fn = tn__progress_fn;  /* restored at the end */
    c->user_data = tn__progress_user;
    if (st) goto done;
    tn_set_progress(tn__style_progress_fwd, c);
    if ((st = tn__channel0_image(style, &cur))) goto done;
    st = tn__style_source_scale(&sm, &cur, W, H);
    tn_image_free(&cur);
    if (st || (st = tn__channel0_image(content, &cm))) goto done;
    tn__style_normalise(&sm, c->net.vgg, &sa, &sb);
    tn__style_normalise(&cm, c->net.vgg, &ca, &cb);
    if (!c->net.vgg && (st = tn__style_auto_drainage(c, &sm))) goto done;
    /* a source smaller than the map also bounds the pyramid: its coarsest level must hold statistics */
    nl = tn__style_auto_levels(c, W < sm.width ? W : sm.width, H < sm.height ? H : sm.height);
    for (k = nl - 1; k >= 0; k--) { /* progress total: pixel-iterations over all levels and tiles */
        int lw, lh, tw, th, m, T, nx, ny, p[TN__STYLE_MAXTILES];
        tn__style_level_size(W, H, k, &lw, &lh);
        m = tn__style_margin(c, k, lw, lh);
        T = tn__style_margin_tile(c, lw, lh, m);
        lw += 2 * m;
        lh += 2 * m;
        tw = tn__style_tile_len(lw, T);
        th = tn__style_tile_len(lh, T);
        nx = tn__style_tile_pos(lw, tw, T / 8, p, TN__STYLE_MAXTILES);
        ny = tn__style_tile_pos(lh, th, T / 8, p, TN__STYLE_MAXTILES);
        if (!nx || !ny) {
            st = tn__fail(TN_ERR_INVALID_ARG, "style: tiles of %d px are too small for a %d x %d map (at most %d per side)", c->o.tile, W, H,
                          TN__STYLE_MAXTILES);
            goto done;
        }
        c->work_total += (double)c->o.iters * tw * th * nx * ny;
    }
    for (k = nl - 1; k >= 0 && !st; k--) {
        int lw, lh;
        tn_image s = {0, 0, 0, NULL}, a = {0, 0, 0, NULL}, x = {0, 0, 0, NULL};
        tn__style_level_size(sm.width, sm.height, k, &lw, &lh); /* the source's level k: the same pixel scale as the map's */
        st = tn__style_resize(&s, &sm, lw, lh);
        tn__style_level_size(W, H, k, &lw, &lh);
        if (!st) st = cur.data ? tn_image_resize(&x, &cur, lw, lh, TN_RESIZE_BILINEAR) : tn__style_resize(&x, &cm, lw, lh);
        if (!st) st = tn_image_copy(&a, &x); /* finer levels are anchored to the coarser result */
        c->level = k;
        if (!st) st = tn__style_level_margin(c, &s, &a, &x);
        tn_image_free(&s);
        tn_image_free(&a);
        tn_image_free(&cur);
        cur = x;
    }
    if (!st && c->user_fn && c->user_fn(c->user_data, "style", 1.0)) st = tn__fail(TN_ERR_CANCELLED, "style: cancelled by the progress callback");
    if (!st) {
        for (i = 0; i < (size_t)W * H; i++) cur.data[i] = (float)(cur.data[i] * sb + sa);
        *out = cur;
        cur.data = NULL;
    }
done:
    tn_set_progress(c->user_fn, c->user_data);
    tn_image_free(&cur);
    tn_image_free(&cm);
    tn_image_free(&sm);
    tn_params_free(c->net.own);
    TN_FREE(c);
    (void)ca;
    (void)cb;
    return st;
}

/* ---- morphology scores: Table 1 SSIM, the realism report's slope and spectrum distances ---- */

TN_API tn_status tn_style_compare(tn_style_scores *out, const tn_image *map, const tn_image *source)
{
    tn_image a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL}, t = {0, 0, 0, NULL}, n = {0, 0, 0, NULL};
    tn_status st;
    if (!map || !source || !out || !map->data || !source->data || map->channels < 1 || source->channels < 1)
        return tn__fail(TN_ERR_INVALID_ARG, "style compare: needs a map and a source");
    if (map->width < 16 || map->height < 16 || source->width < 2 || source->height < 2)
        return tn__fail(TN_ERR_INVALID_ARG, "style compare: the map must be at least 16 x 16");
    if (tn_image_range(NULL, NULL, map) || tn_image_range(NULL, NULL, source))
        return tn__fail(TN_ERR_NUMERIC, "style compare: NaN/Inf in the input");
    if (!(st = tn__channel0_image(map, &a)) && !(st = tn__channel0_image(source, &t)) &&
        !(st = tn__style_resize(&b, &t, map->width, map->height))) {
        int native = map->width > t.width || map->height > t.height;
        tn_realism_opts ro;
        tn_realism r;
        tn__normalise01(&a);
        tn__normalise01(&b);
        /* the distances compare with the source at the pixel scale the transfer matches */
        if (native && !(st = tn_image_copy(&n, &t))) tn__normalise01(&n);
        memset(&ro, 0, sizeof ro);
        tn__realism_opts_defaults(&ro);
        memset(&r, 0, sizeof r);
        memset(out, 0, sizeof *out);
        if (!st && !(st = tn_ssim(&out->ssim, &b, &a, 1.0)) && !(st = tn__realism_shape(native ? &n : &b, &a, &ro, &r))) {
            out->slope_hist_dist = r.slope_distance;
            out->spectrum_dist = r.spectrum_distance;
        }
    }
    tn_image_free(&a);
    tn_image_free(&b);
    tn_image_free(&t);
    tn_image_free(&n);
    return st;
}

TN_API tn_status tn_style_content_noise(tn_image *out, int width, int height, const tn_image *source,
                                        const tn_perlin_opts *opts, float *gain_out)
{
    tn_image best = {0, 0, 0, NULL}, cand = {0, 0, 0, NULL};
    tn_perlin_opts po;
    tn_style_scores sc;
    double best_d = 0.0;
    float best_g = 0.5f;
    tn_status st = TN_OK;
    int k;
    if (!out || !source) return tn__fail(TN_ERR_INVALID_ARG, "style content noise: needs an output and a source");
    if (opts) po = *opts;
    else memset(&po, 0, sizeof po);
    for (k = 0; k < 10 && !st; k++) {
        po.gain = 0.45f + 0.05f * (float)k;
        if ((st = tn_noise_perlin(&cand, width, height, &po)) || (st = tn_style_compare(&sc, &cand, source))) break;
        if (!best.data || sc.slope_hist_dist + sc.spectrum_dist < best_d) {
            tn_image_free(&best);
            best = cand;
            cand.data = NULL;
            best_d = sc.slope_hist_dist + sc.spectrum_dist;
            best_g = po.gain;
        }
        tn_image_free(&cand);
    }
    tn_image_free(&cand);
    if (st) {
        tn_image_free(&best);
        return st;
    }
    *out = best;
    if (gain_out) *gain_out = best_g;
    return TN_OK;
}
#endif /* TN_NO_STYLE */

