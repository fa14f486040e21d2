/* ============================================================================================
   (@@gnn, continued: the map-scale level and prepared generation)
   ============================================================================================ */
#ifndef TN_NO_GNN
/* A generation prepared once for many windows (the tiles of one map): the sketch grown, cut into
   parts and rasterised, the gain tested, the fine detail's index and, for a drawing larger than
   its example, the map-scale level's small map: the work tn_gnn_generate_window repeats for each
   window. A window of it equals the same pixels of tn_gnn_generate_window with the same model,
   sketch, size and options, and costs only the network over the window and its halo. The model
   must outlive *out; sketch and opts are not kept. Free with tn_gnn_prepared_free. */
typedef struct tn_gnn_prepared tn_gnn_prepared;
TN_API tn_status tn_gnn_prepare(tn_gnn_prepared **out, const tn_gnn *model, const tn_contour_set *sketch, int width, int height,
                                const tn_gnn_generate_opts *opts);
/* *out = the window (x, y, w, h) of p's map (one channel, the example's units), allocated here.
   p is only read. */
TN_API tn_status tn_gnn_prepared_window(tn_image *out, const tn_gnn_prepared *p, int x, int y, int w, int h);
/* The plan of p's generation (tn_gnn_plan_of's fields), owned by p. */
TN_API const tn_gnn_plan *tn_gnn_prepared_plan(const tn_gnn_prepared *p);
TN_API void tn_gnn_prepared_free(tn_gnn_prepared *p); /* NULL is fine */
#endif /* TN_NO_GNN */

/* --------------------------------------------------------------------------------------------
   >>gnn_scale  (part of @@gnn implementation; goes after >>gnn, whose generation it runs)
   One level of generation over a window; the map-scale level of a drawing larger than its
   example (issue 30); the prepared generation that tn_gnn_generate_window and a world's tiles
   run on; tn_gnn_gain and tn_gnn_plan_of.
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_GNN

/* ---- the map-scale level: a drawing larger than its example ---- */

#define TN__GNN_SCALE_SPAN 2   /* a drawing whose lines span more than this many example sides draws a larger landscape */
#define TN__GNN_SCALE_SIGMA 2  /* px per factor: the Gaussian that parts the small map's scales from this map's detail */
#define TN__GNN_FLOOR_REACH 12 /* px per factor: a drawn valley's floor, across which the detail fades in */
#define TN__GNN_FLOOR_NEAR 4   /* px: the example's floor, within this of its main valleys */

/* The map-scale factor of a grown drawing: its lines' extent on the map (bounding box, longer
   side) over TN__GNN_SCALE_SPAN example sides, rounded (1: none, below 1.5). A DEM's network or a
   dense sketch is not grown and keeps 1: its lines are the example's size already. */
static int tn__gnn_map_factor(const tn__gnn_gen *G, const tn_contour_set *sketch, int width, int height, const tn_gnn_generate_opts *o,
                              const char **why)
{
    float x0 = FLT_MAX, y0 = FLT_MAX, x1 = -FLT_MAX, y1 = -FLT_MAX, side = (float)(G->A.width > G->A.height ? G->A.width : G->A.height), s;
    int c, j;
    if (o->map_scale < 0 || o->map_scale == 1) return *why = "off (--map-scale off)", 1;
    if (!G->grown) return *why = "none: the sketch is not grown (its lines are the example's size)", 1;
    if (o->map_scale >= 2) return *why = "set by --map-scale", o->map_scale;
    for (c = 0; c < sketch->count; c++)
        for (j = 0; j < sketch->items[c].npoints; j++) {
            const float *q = sketch->items[c].points + 3 * (size_t)j;
            x0 = fminf(x0, q[0]), x1 = fmaxf(x1, q[0]), y0 = fminf(y0, q[1]), y1 = fmaxf(y1, q[1]);
        }
    s = fmaxf((x1 - x0) * (float)width / (float)sketch->width, (y1 - y0) * (float)height / (float)sketch->height) / (TN__GNN_SCALE_SPAN * side);
    if (!(s >= 1.5f)) return *why = "none: the drawing spans at most twice the example", 1;
    *why = "the drawing spans more than twice the example, so its lines are larger than the example's: the large scales come "
           "from the drawing generated this many times smaller";
    return s >= TN__GNN_SCALE_MAX ? TN__GNN_SCALE_MAX : (int)(s + 0.5f);
}

/* The share of the example's detail (|heights - their Gaussian of 2 px|, median) within
   TN__GNN_FLOOR_NEAR px of its main valleys (the highest Strahler order) against the whole
   example's, clamped to 0..1: how much smoother its valley floors are than the rest. 1 when the
   model holds no example heights or its network no valley. */
static tn_status tn__gnn_floor_detail(const tn_gnn *model, const tn__gnn_gen *G, float *share)
{
    const tn_tensor *e = tn_params_find(model->weights, "detail.example");
    const int W = G->A.width, H = G->A.height;
    const size_t n = (size_t)W * H;
    tn_contour_set ex, mains;
    tn_image z = {0, 0, 0, NULL}, b = {0, 0, 0, NULL}, r = {0, 0, 0, NULL};
    float *all = NULL, *floor_px = NULL, *d = NULL;
    int *nearest = NULL, c, top = -1, k = 0;
    uint8_t *mask = NULL;
    size_t i, m = 0;
    tn_status st;
    *share = 1;
    if (!e) return TN_OK;
    memset(&ex, 0, sizeof ex);
    if ((st = tn__gnn_stored_parts(model->weights, &G->A, "gnn", &ex))) return st;
    for (c = 0; c < ex.count; c++)
        if (ex.items[c].type == TN_VALLEY && ex.items[c].order > top) top = ex.items[c].order;
    mains = ex;
    mains.items = top < 0 ? NULL : (tn_contour *)tn__alloc((size_t)ex.count * sizeof(tn_contour));
    if (top >= 0 && !mains.items) st = TN_ERR_OUT_OF_MEMORY;
    for (c = 0; !st && top >= 0 && c < ex.count; c++)
        if (ex.items[c].type == TN_VALLEY && ex.items[c].order == top) mains.items[k++] = ex.items[c];
    mains.count = k;
    z.width = W, z.height = H, z.channels = 1, z.data = e->data;
    if (!st && top >= 0 && !(st = tn_sketch_rasterise(&r, &mains, W, H)) && !(st = tn_image_blur(&b, &z, 2.0f))) {
        all = (float *)tn__alloc(n * sizeof(float));
        floor_px = (float *)tn__alloc(n * sizeof(float));
        d = (float *)tn__alloc(n * sizeof(float));
        nearest = (int *)tn__alloc(n * sizeof(int));
        mask = (uint8_t *)tn__alloc(n);
        if (!all || !floor_px || !d || !nearest || !mask) st = TN_ERR_OUT_OF_MEMORY;
    }
    if (!st && mask) {
        for (i = 0; i < n; i++) mask[i] = (uint8_t)(r.data[3 * i + 1] > 0);
        tn__gnn_chamfer(mask, W, H, d, nearest);
        for (i = 0; i < n; i++) {
            all[i] = fabsf(z.data[i] - b.data[i]);
            if (d[i] <= TN__GNN_FLOOR_NEAR) floor_px[m++] = all[i];
        }
        qsort(all, n, sizeof(float), tn__cmp_float);
        qsort(floor_px, m, sizeof(float), tn__cmp_float);
        if (m && all[n / 2] > 0) *share = tn__clampf(floor_px[m / 2] / all[n / 2], 0.0f, 1.0f);
    }
    TN_FREE(mains.items);
    tn_contour_set_free(&ex);
    tn_image_free(&b);
    tn_image_free(&r);
    TN_FREE(all);
    TN_FREE(floor_px);
    TN_FREE(d);
    TN_FREE(nearest);
    TN_FREE(mask);
    return st;
}

/* Window (x, y, w, h) of one level of generation (G's map) into dst, w floats a row; G's
   detail index is built (tn__gnn_prepare). */
static tn_status tn__gnn_level_run(const tn__gnn_gen *G, tn_ctx *ctx, int x, int y, int w, int h, float *dst)
{
    return G->detail ? tn__gnn_gen_detailed(G, ctx, x, y, w, h, dst) : tn__gnn_gen_run(G, G->w, ctx, x, y, w, h, dst, NULL, "gnn-generate");
}

/* What every window of one generation reads (tn_gnn_prepared). */
struct tn_gnn_prepared {
    tn__gnn_gen G;  /* the map's generation */
    int f;          /* the map-scale factor (1: one level) */
    float a0;       /* f > 1: the example's floor detail (tn__gnn_floor_detail) */
    tn__gnn_gen Gc; /* f > 1: the drawing on the map f times smaller, without fine detail */
    float *floor_d; /* f > 1: W x H, px to the nearest drawn valley pixel */
    tn_gnn_plan plan;
};

/* The Gaussian kern (2K + 1 taps) of src (g's layout, g within the W x H map) over r (within g
   grown by K), rows and columns clamped to the map, into out (r's layout); tmp: g.w x r.h. */
static void tn__gnn_gauss_rect(const float *src, tn_rect g, tn_rect r, int W, int H, const float *kern, int K, float *tmp, float *out)
{
    int u, v, k;
    for (v = 0; v < r.h; v++) /* down the columns */
        for (u = 0; u < g.w; u++) {
            double acc = 0;
            for (k = -K; k <= K; k++) {
                int Y = r.y + v + k;
                Y = Y < 0 ? 0 : Y > H - 1 ? H - 1 : Y;
                acc += kern[k + K] * src[(size_t)(Y - g.y) * g.w + u];
            }
            tmp[(size_t)v * g.w + u] = (float)acc;
        }
    for (v = 0; v < r.h; v++) /* along the rows */
        for (u = 0; u < r.w; u++) {
            double acc = 0;
            for (k = -K; k <= K; k++) {
                int X = r.x + u + k;
                X = X < 0 ? 0 : X > W - 1 ? W - 1 : X;
                acc += kern[k + K] * tmp[(size_t)v * g.w + (X - g.x)];
            }
            out[(size_t)v * r.w + u] = (float)acc;
        }
}

/* The map-scale level, window (x, y, w, h) into dst (w floats a row). Large scales: the drawing
   generated on a map f times smaller (without its fine detail), upsampled (Catmull-Rom at pixel
   centres) and low-passed; detail: this map's generation G minus its low-pass, times
   a(d) = a0 + (1 - a0) smoothstep(d / (TN__GNN_FLOOR_REACH f)), d the distance to the nearest
   drawn valley pixel, a0 the example's floor detail (tn__gnn_floor_detail). The low-pass is a
   Gaussian of TN__GNN_SCALE_SIGMA f px, the map's edges clamped. Then the strokes are pinned to
   G's heights again (tn__gnn_pin: the upsampling smooths the small map's) and notched again
   (tn__gnn_incise, asking for 1/f of the fall: the fade takes the valleys' notch with the detail). Each part is computed on
   the window grown by what the next reads, so windows equal the whole map. */
static tn_status tn__gnn_map_scaled(const tn_gnn_prepared *P, tn_ctx *ctx, int x, int y, int w, int h, float *dst)
{
    const tn__gnn_gen *G = &P->G, *Gc = &P->Gc;
    const int f = P->f, W = G->W, H = G->H, Wc = Gc->W, Hc = Gc->H, K = 3 * TN__GNN_SCALE_SIGMA * f;
    const float sigma = (float)(TN__GNN_SCALE_SIGMA * f), reach = (float)(TN__GNN_FLOOR_REACH * f), a0 = P->a0;
    tn_rect win, A, r, g;
    float *F = NULL, *B = NULL, *C = NULL, *lowF = NULL, *lowB = NULL, *M = NULL, *tmp = NULL, *kern = NULL, *corr = NULL, *val = NULL,
          *def = NULL, *res = NULL, sum = 0;
    int cx0, cy0, cx1, cy1, cw, u, v, k;
    size_t i;
    tn_status st;
    win.x = x, win.y = y, win.w = w, win.h = h;
    A = tn_rect_halo(win, TN__GNN_NOTCH + TN__GNN_BANK + 1, W, H); /* what the notch reads */
    r = tn_rect_halo(A, TN__GNN_PIN, W, H);                       /* what the pinning reads */
    g = tn_rect_halo(r, K, W, H);                                 /* what the low-pass reads */
    cx0 = (int)floorf(((float)g.x + 0.5f) / (float)f - 0.5f) - 1, cy0 = (int)floorf(((float)g.y + 0.5f) / (float)f - 0.5f) - 1;
    cx1 = (int)floorf(((float)(g.x + g.w) - 0.5f) / (float)f - 0.5f) + 2, cy1 = (int)floorf(((float)(g.y + g.h) - 0.5f) / (float)f - 0.5f) + 2;
    cx0 = cx0 < 0 ? 0 : cx0, cy0 = cy0 < 0 ? 0 : cy0, cx1 = cx1 > Wc - 1 ? Wc - 1 : cx1, cy1 = cy1 > Hc - 1 ? Hc - 1 : cy1;
    cw = cx1 - cx0 + 1;
    kern = (float *)tn__alloc((size_t)(2 * K + 1) * sizeof(float));
    F = (float *)tn__alloc((size_t)g.w * g.h * sizeof(float));
    B = (float *)tn__alloc((size_t)g.w * g.h * sizeof(float));
    C = (float *)tn__alloc((size_t)cw * (cy1 - cy0 + 1) * sizeof(float));
    lowF = (float *)tn__alloc((size_t)r.w * r.h * sizeof(float));
    lowB = (float *)tn__alloc((size_t)r.w * r.h * sizeof(float));
    M = (float *)tn__alloc((size_t)r.w * r.h * sizeof(float));
    tmp = (float *)tn__alloc((size_t)g.w * r.h * sizeof(float));
    corr = (float *)tn__alloc((size_t)A.w * A.h * sizeof(float));
    val = (float *)tn__alloc((size_t)A.w * A.h * sizeof(float));
    def = (float *)tn__alloc((size_t)A.w * A.h * (G->drawn ? 2 : 1) * sizeof(float)); /* tn__gnn_incise's scratch */
    res = (float *)tn__alloc((size_t)w * h * sizeof(float));
    if (!kern || !F || !B || !C || !lowF || !lowB || !M || !tmp || !corr || !val || !def || !res) {
        st = TN_ERR_OUT_OF_MEMORY;
        goto done;
    }
    for (k = -K; k <= K; k++) sum += kern[k + K] = expf(-0.5f * (float)(k * k) / (sigma * sigma));
    for (k = 0; k <= 2 * K; k++) kern[k] /= sum;
    if ((st = tn__gnn_level_run(G, ctx, g.x, g.y, g.w, g.h, F)) || (st = tn__gnn_level_run(Gc, ctx, cx0, cy0, cw, cy1 - cy0 + 1, C))) goto done;
    for (v = 0; v < g.h; v++) /* the small map upsampled */
        for (u = 0; u < g.w; u++) {
            float kx[4], ky[4], fx = ((float)(g.x + u) + 0.5f) / (float)f - 0.5f, fy = ((float)(g.y + v) + 0.5f) / (float)f - 0.5f;
            int ix = (int)floorf(fx), iy = (int)floorf(fy), j, l;
            double up = 0;
            for (j = 0; j < 4; j++) /* Catmull-Rom: tn_image_resize's bicubic kernel */
                kx[j] = tn__keys_cubic(fx - (float)ix - (float)(j - 1)), ky[j] = tn__keys_cubic(fy - (float)iy - (float)(j - 1));
            for (j = 0; j < 4; j++)
                for (l = 0; l < 4; l++) {
                    int cx = ix - 1 + l, cy = iy - 1 + j;
                    cx = cx < 0 ? 0 : cx > Wc - 1 ? Wc - 1 : cx;
                    cy = cy < 0 ? 0 : cy > Hc - 1 ? Hc - 1 : cy;
                    up += ky[j] * kx[l] * C[(size_t)(cy - cy0) * cw + (cx - cx0)];
                }
            B[(size_t)v * g.w + u] = (float)up;
        }
    tn__gnn_gauss_rect(F, g, r, W, H, kern, K, tmp, lowF);
    tn__gnn_gauss_rect(B, g, r, W, H, kern, K, tmp, lowB);
    for (v = 0; v < r.h; v++)
        for (u = 0; u < r.w; u++) {
            size_t q = (size_t)v * r.w + u, p = (size_t)(r.y + v) * W + (r.x + u);
            float t = fminf(P->floor_d[p] / reach, 1.0f), a = a0 + (1 - a0) * t * t * (3 - 2 * t);
            M[q] = lowB[q] + a * (F[(size_t)(r.y + v - g.y) * g.w + (r.x + u - g.x)] - lowF[q]);
        }
    for (v = 0; v < r.h; v++) /* the pinning reads both on one layout: G's output over r into lowF */
        for (u = 0; u < r.w; u++) lowF[(size_t)v * r.w + u] = F[(size_t)(r.y + v - g.y) * g.w + (r.x + u - g.x)];
    tn__gnn_pin(G, M, lowF, r.x, r.y, r.w, A.x, A.y, A.w, A.h, 0, corr);
    for (v = 0; v < A.h; v++) /* the notch works in the network's units */
        for (u = 0; u < A.w; u++) {
            size_t q = (size_t)v * A.w + u;
            val[q] = (M[(size_t)(A.y + v - r.y) * r.w + (A.x + u - r.x)] - corr[q] - G->A.mean) / G->A.std;
        }
    tn__gnn_incise(G, G->side / (float)f, val, A.x, A.y, A.w, A.h, x, y, w, h, def, res); /* a larger line's banks fall as much over f x the px */
    for (i = 0; i < (size_t)w * h; i++) dst[i] = G->A.mean + G->A.std * res[i];
done:
    TN_FREE(kern);
    TN_FREE(F);
    TN_FREE(B);
    TN_FREE(C);
    TN_FREE(lowF);
    TN_FREE(lowB);
    TN_FREE(M);
    TN_FREE(tmp);
    TN_FREE(corr);
    TN_FREE(val);
    TN_FREE(def);
    TN_FREE(res);
    return st;
}

/* *plan from G, the generation of sketch on a width x height map with options o. */
static tn_status tn__gnn_plan_fill(tn_gnn_plan *plan, const tn_gnn *model, const tn__gnn_gen *G, const tn_contour_set *sketch, int width,
                                   int height, const tn_gnn_generate_opts *o)
{
    memset(plan, 0, sizeof *plan);
    plan->user_lines = sketch->count;
    plan->grown_lines = G->grown;
    plan->user_density = G->user_density;
    plan->example_density = G->example_density;
    plan->gain = G->gain;
    plan->gain_raw = G->gain_raw;
    plan->gain_scale = tn__gnn_gain_scale(G->w);
    if (o->gain > 0) plan->gain_why = "set by --gain";
    else if (o->gain < 0) plan->gain_why = "set to none: the membrane of the sketch alone";
    else if (!G->A.membrane) plan->gain_why = "the model predicts heights directly (no membrane): gain 1";
    else if (isfinite(G->gain_raw))
        plan->gain_why = G->gain <= 0 ? "tested on the sketch: the network's relief did not fit the held-out lines, so the output is the membrane "
                                        "of the lines (smooth between them); --gain 1 forces the relief"
                                      : "tested on the sketch: held-out lines predicted from the rest";
    else if (sketch->count < TN__GNN_GAIN_MIN_LINES)
        plan->gain_why = "untested: fewer than 8 lines in the sketch (a held-out stroke says little about the rest), gain 1";
    else plan->gain_why = "untested (every part the example's own, or nothing left to hold out): gain 1";
    plan->detail = G->detail;
    plan->detail_why = G->detail_why;
    plan->map_scale = tn__gnn_map_factor(G, sketch, width, height, o, &plan->map_scale_why);
    plan->floor_detail = 1;
    return plan->map_scale > 1 ? tn__gnn_floor_detail(model, G, &plan->floor_detail) : TN_OK;
}

/* G's whole-map membrane, solved once for all its windows (their regions overlap by the halo). */
static tn_status tn__gnn_prepare_base(tn__gnn_gen *G)
{
    if (!G->A.membrane) return TN_OK;
    if (!(G->base = (float *)tn__alloc((size_t)G->W * G->H * sizeof(float)))) return tn__oom();
    return tn__gnn_membrane_rect(G->hgt, G->fixed, G->W, G->H, 0, 0, G->W, G->H, G->base);
}

TN_API const tn_gnn_plan *tn_gnn_prepared_plan(const tn_gnn_prepared *p) { return &p->plan; }

TN_API void tn_gnn_prepared_free(tn_gnn_prepared *p)
{
    if (!p) return;
    tn__gnn_gen_free(&p->G);
    tn__gnn_gen_free(&p->Gc);
    TN_FREE(p->floor_d);
    TN_FREE(p);
}

TN_API tn_status tn_gnn_prepare(tn_gnn_prepared **out, const tn_gnn *model, const tn_contour_set *sketch, int width, int height,
                                const tn_gnn_generate_opts *opts)
{
    tn_gnn_prepared *P;
    tn_gnn_generate_opts o;
    tn_status st;
    TN_ASSERT(out);
    *out = NULL;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    if (!(P = (tn_gnn_prepared *)tn__calloc(sizeof *P))) return tn__oom();
    if ((st = tn__gnn_gen_make(model, sketch, width, height, &o, &P->G)) || (P->G.detail && (st = tn__gnn_detail_index(model, &P->G)))) goto done;
    if ((st = tn__gnn_prepare_base(&P->G))) goto done;
    if ((st = tn__gnn_plan_fill(&P->plan, model, &P->G, sketch, width, height, &o))) goto done;
    P->f = P->plan.map_scale;
    P->a0 = P->plan.floor_detail;
    if (P->f > 1) {
        tn_gnn_generate_opts oc = o;
        const int Wc = (width + P->f - 1) / P->f, Hc = (height + P->f - 1) / P->f;
        size_t i, n = (size_t)width * height;
        uint8_t *mask = (uint8_t *)tn__alloc(n);
        int *nearest = (int *)tn__alloc(n * sizeof(int));
        TN_ASSERT(P->G.pin); /* a grown sketch's (tn__gnn_map_factor) */
        oc.detail = -1;      /* below the low-pass */
        if (Wc < 16 || Hc < 16)
            st = tn__fail(TN_ERR_INVALID_ARG, "gnn generate: map scale %d leaves a %d x %d map for the large scales (16 a side at least)", P->f, Wc,
                          Hc);
        else if (!mask || !nearest || !(P->floor_d = (float *)tn__alloc(n * sizeof(float)))) st = TN_ERR_OUT_OF_MEMORY;
        else if (!(st = tn__gnn_gen_make(model, sketch, Wc, Hc, &oc, &P->Gc)) &&
                 !(st = tn__gnn_prepare_base(&P->Gc))) {
            for (i = 0; i < n; i++) mask[i] = (uint8_t)(P->G.pin[i] == 2);
            tn__gnn_chamfer(mask, width, height, P->floor_d, nearest);
        }
        TN_FREE(mask);
        TN_FREE(nearest);
    }
done:
    if (st) tn_gnn_prepared_free(P);
    else *out = P;
    return st;
}

/* TN_OK when the window (x, y, w, h) lies inside the W x H map. */
static tn_status tn__gnn_window_check(int x, int y, int w, int h, int W, int H)
{
    if (w <= 0 || h <= 0 || x < 0 || y < 0 || x > W - w || y > H - h)
        return tn__fail(TN_ERR_INVALID_ARG, "gnn generate: window %d x %d at (%d, %d) is not inside the %d x %d map", w, h, x, y, W, H);
    return TN_OK;
}

TN_API tn_status tn_gnn_prepared_window(tn_image *out, const tn_gnn_prepared *p, int x, int y, int w, int h)
{
    tn_image res = {0, 0, 0, NULL};
    tn_ctx *ctx = NULL;
    tn_status st;
    TN_ASSERT(out && p);
    if ((st = tn__gnn_window_check(x, y, w, h, p->G.W, p->G.H))) return st;
    if ((st = tn_image_create(&res, w, h, 1))) return st;
    if (!(ctx = tn_ctx_create())) st = tn__oom();
    else st = p->f > 1 ? tn__gnn_map_scaled(p, ctx, x, y, w, h, res.data) : tn__gnn_level_run(&p->G, ctx, x, y, w, h, res.data);
    tn_ctx_free(ctx);
    if (st) tn_image_free(&res);
    else *out = res;
    return st;
}

TN_API tn_status tn_gnn_generate_window(tn_image *out, const tn_gnn *model, const tn_contour_set *sketch, int width, int height, int x, int y,
                                        int w, int h, const tn_gnn_generate_opts *opts)
{
    tn_gnn_prepared *P;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__gnn_window_check(x, y, w, h, width, height))) return st; /* before the preparation's cost */
    if ((st = tn_gnn_prepare(&P, model, sketch, width, height, opts))) return st;
    st = tn_gnn_prepared_window(out, P, x, y, w, h);
    tn_gnn_prepared_free(P);
    return st;
}

/* The generation's plan without the fine-tune (which the gain test and the plan never run); *o
   = the options so resolved. */
static tn_status tn__gnn_gen_plan(const tn_gnn *model, const tn_contour_set *sketch, int width, int height, const tn_gnn_generate_opts *opts,
                                  tn_gnn_generate_opts *o, tn__gnn_gen *G)
{
    memset(o, 0, sizeof *o);
    if (opts) *o = *opts;
    o->finetune = 0;
    return tn__gnn_gen_make(model, sketch, width, height, o, G);
}

TN_API tn_status tn_gnn_gain(float *gain, const tn_gnn *model, const tn_contour_set *sketch, int width, int height,
                             const tn_gnn_generate_opts *opts)
{
    tn__gnn_gen G;
    tn_gnn_generate_opts o;
    tn_status st;
    TN_ASSERT(gain);
    if ((st = tn__gnn_gen_plan(model, sketch, width, height, opts, &o, &G))) return st;
    *gain = G.gain;
    tn__gnn_gen_free(&G);
    return TN_OK;
}

TN_API tn_status tn_gnn_plan_of(tn_gnn_plan *plan, const tn_gnn *model, const tn_contour_set *sketch, int width, int height,
                                const tn_gnn_generate_opts *opts)
{
    tn__gnn_gen G;
    tn_gnn_generate_opts o;
    tn_status st;
    TN_ASSERT(plan);
    memset(plan, 0, sizeof *plan);
    if ((st = tn__gnn_gen_plan(model, sketch, width, height, opts, &o, &G))) return st;
    st = tn__gnn_plan_fill(plan, model, &G, sketch, width, height, &o);
    tn__gnn_gen_free(&G);
    return st;
}

TN_API tn_status tn_gnn_generate(tn_image *out, const tn_gnn *model, const tn_contour_set *sketch, int width,
                                 int height, const tn_gnn_generate_opts *opts)
{
    return tn_gnn_generate_window(out, model, sketch, width, height, 0, 0, width, height, opts);
}
#endif /* TN_NO_GNN */
