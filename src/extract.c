/* ============================================================================================
   @@extract  ridge and valley networks from a DEM (paper 000, section 4.1); realism report
   Valleys: depression filling (priority-flood + epsilon, so every cell drains), D8 steepest
   descent (diagonals at sqrt 2), flow accumulation; cells draining at least `threshold` cells are
   valley cells. Ridges: the same on the inverted DEM. The masks are then, in the paper's order,
   closed (3x3), Strahler-ordered, thinned (Zhang-Suen + removal of the remaining simple pixels,
   so lines are one pixel wide and 8-connected with the topology kept), traced into polylines
   between junctions and endpoints, filtered (dangling contours under 10 px; contours whose mean
   gradient is in the lowest 1 % of all contours' or exactly 0) and split when long. The polylines
   are 8-connected pixel chains, so tn_contour_parts_make (@@sketch) cuts them into parts directly
   and tn_sketch_preview draws them over the DEM (the paper's Figure 6).
   ============================================================================================ */
#ifndef TN_NO_EXTRACT
#if defined(TN_NO_SKETCH)
#error "terrainnet: @@extract needs @@sketch; define TN_NO_EXTRACT too, or none of them"
#endif

#define TN_FLOW_OUTLET 255   /* direction code of a cell that drains off the map (no lower neighbour) */

/* D8 flow on a DEM. dir: 0..7 = E, SE, S, SW, W, NW, N, NE (x right, y down the rows), or
   TN_FLOW_OUTLET. acc: cells draining through each cell, itself included (>= 1). */
typedef struct tn_flow {
    int width, height;
    uint8_t *dir;
    uint32_t *acc;
} tn_flow;

/* Priority-flood depression filling with epsilon (Barnes et al. 2014): every cell ends at least
   one float step (nextafter) above the cell it was flooded from, so every cell has a strictly
   lower neighbour or lies on the border. Channel 0 is used; the result has one channel.
   NaN/Inf heights fail with TN_ERR_NUMERIC. Caller frees *dst. */
TN_API tn_status tn_fill_depressions(tn_image *dst, const tn_image *dem);
/* D8 directions of a (filled) DEM into flow->dir (allocated here; acc left NULL). A cell drains
   to its steepest strictly lower neighbour (drop / distance, distance 1 or sqrt 2; ties go to
   the first in E, SE, S, ... order). Border cells are outlets: they drain off the map, so no flow
   runs along the edges. Threaded. */
TN_API tn_status tn_flow_directions(tn_flow *flow, const tn_image *filled);
/* Flow accumulation from flow->dir into flow->acc (allocated here), O(n) by walking down from
   cells nobody drains into; threaded by strips of rows (same result for any thread count).
   Fails with TN_ERR_CORRUPT if the directions hold a cycle, point off the map or hold a code
   other than 0-7 and TN_FLOW_OUTLET. */
TN_API tn_status tn_flow_accumulation(tn_flow *flow);
/* All three on dem (invert != 0: on -dem, for ridges). Cells the fill raised (depressions and
   flats) drain instead to the cell the flood reached them from, visiting cells as GRASS
   r.watershed's A* search does (lowest first, equal heights oldest first, S N W E before the
   diagonals), so flow crosses flats and lakes where r.watershed -s puts it; the rest is the D8
   of tn_flow_directions. Caller frees with tn_flow_free. */
TN_API tn_status tn_flow_compute(tn_flow *flow, const tn_image *dem, int invert);
TN_API void      tn_flow_free(tn_flow *flow);

/* Strahler order of the network cells (mask != 0) along the flow directions: sources are 1; a
   cell whose upstream network cells reach their maximum order k at least twice gets k + 1, else
   k. order[] (w*h bytes, caller's) is 0 off the network. The network must be closed downstream
   (a threshold mask on the accumulation is). Returns the highest order in *max_order. Direction
   codes other than 0-7 and TN_FLOW_OUTLET, or ones stepping off the map, fail with TN_ERR_CORRUPT. */
TN_API tn_status tn_strahler_order(uint8_t *order, const tn_flow *flow, const uint8_t *mask, int *max_order);

enum { TN_EXTRACT_BOTH = 0, TN_EXTRACT_VALLEYS = 1, TN_EXTRACT_RIDGES = 2 };

/* Zero means the default everywhere. */
typedef struct tn_extract_opts {
    int threshold;        /* accumulation threshold in cells; 0 = tn_extract_default_threshold() */
    int closing;          /* closing radius in px (3x3 = 1); 0 = 1, < 0 = no closing */
    int min_length;       /* dangling contours shorter than this (px) are dropped; 0 = 10 */
    float drop_fraction;  /* contours whose mean gradient is under this quantile of the contours'
                             mean gradients (or is 0: flat lakes) are dropped; 0 = 0.01, < 0 = keep all */
    int max_length;       /* longer polylines are split into near-equal pieces (px); 0 = 48 */
    float dx, dy;         /* pixel spacing used for gradients; 0 = 1 */
    int which;            /* TN_EXTRACT_BOTH / _VALLEYS / _RIDGES */
} tn_extract_opts;

/* Everything extraction computed; free with tn_extraction_free. Masks are w*h bytes (0/1). */
typedef struct tn_extraction {
    int width, height, threshold;
    tn_flow valley_flow, ridge_flow;        /* on the DEM and on the inverted DEM */
    uint8_t *valley_mask, *ridge_mask;      /* accumulation >= threshold, before closing/thinning */
    uint8_t *valley_order, *ridge_order;    /* Strahler order of the raw network cells */
    int valley_max_order, ridge_max_order;
    tn_contour_set contours;                /* final polylines: valleys first, then ridges */
} tn_extraction;

/* Default accumulation threshold for a w x h DEM: max(8, w*h / 1000) cells, i.e. a valley drains
   at least 0.1 % of the map, so the same terrain gives the same network at any resolution. */
TN_API int       tn_extract_default_threshold(int width, int height);
/* Runs the whole pipeline on channel 0 of dem. opts may be NULL. */
TN_API tn_status tn_extract(tn_extraction *out, const tn_image *dem, const tn_extract_opts *opts);
TN_API void      tn_extraction_free(tn_extraction *ex);

/* Realism of a terrain img against a reference (both channel 0, heights in the same units).
   Histogram distances are earth mover's distances between 256-bin histograms over a common
   range, divided by the reference's mean value (slope) or mean |value| (curvature): 0 for the
   same distribution, about 1 when one is a scaled-down copy. */
typedef struct tn_realism_opts {
    float dx_a, dy_a;     /* pixel spacing of the reference in height units; 0 = 1 (dy 0 = dx) */
    float dx_b, dy_b;     /* of the compared terrain; 0 = the reference's */
    int threshold;        /* valley threshold for density and bifurcation; 0 = default per size */
} tn_realism_opts;

typedef struct tn_realism {
    double slope_distance;        /* slope (|gradient|) histograms, relative EMD */
    double curvature_distance;    /* Laplacian histograms, relative EMD */
    double spectrum_distance;     /* RMS difference of log10 radially averaged power spectra */
    double spectrum_slope_a, spectrum_slope_b; /* log-log slope of each spectrum (terrain: about -2..-4) */
    double drainage_density_a, drainage_density_b; /* valley line length per cell (px / px^2) */
    double bifurcation_ratio_a, bifurcation_ratio_b; /* mean Strahler N_k / N_k+1 (0 if order 1 only) */
    double ssim, psnr;            /* NaN when the sizes differ; psnr +inf for identical inputs */
    double distance;              /* summary: mean of the three distances, the relative density and
                                     bifurcation differences and the relative spectral slope difference */
} tn_realism;

/* Spectra use the centred largest power-of-two square crop (Hann window); both sides >= 16. */
TN_API tn_status tn_realism_compare(tn_realism *out, const tn_image *ref, const tn_image *img,
                                    const tn_realism_opts *opts);
#endif /* TN_NO_EXTRACT */

/* --------------------------------------------------------------------------------------------
   >>extract  (@@extract implementation)
   Filling works on order-preserving integer keys of the float heights (key + 1 = nextafter), so
   the priority queue is a radix heap: priority-flood pops never decrease, which is all a radix
   heap needs, and pushes/pops are O(1) amortised without the cache misses of a binary heap.
   Accumulation and Strahler order walk down from cells with no upstream neighbour, each cell
   once it has heard from all of them (Kahn's order without a queue); accumulation runs one
   strip of rows per thread and then finishes the flow that crossed strips in strip order.
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_EXTRACT

/* Order-preserving map float -> uint32 (-0 and +0 share a key). */
TN__INTERNAL uint32_t tn__fkey(float f)
{
    uint32_t u;
    if (f == 0.0f) f = 0.0f;
    memcpy(&u, &f, 4);
    return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

static float tn__fkey_inv(uint32_t k)
{
    uint32_t u = (k & 0x80000000u) ? (k & 0x7fffffffu) : ~k;
    float f;
    memcpy(&f, &u, 4);
    return f;
}

/* Monotone priority queue of (key, cell): a radix heap with byte digits (Ahuja et al. 1990).
   Bucket [l][v] holds the keys that agree with `last` above byte l and have byte l equal to v
   (above last's); level 0 bucket v holds the single key (last & ~0xff) | v. When level 0 runs
   dry, the lowest non-empty bucket above gives the new `last` (its minimum) and its items move
   down at least one level, so each item moves at most three times. Equal keys pop first in,
   first out (moves keep the order), as in r.watershed's A* search, whose tie order decides
   where flow crosses flats. */
typedef struct tn__rheap_item { uint32_t key, cell; } tn__rheap_item;
typedef struct tn__rheap {
    tn__rheap_item *b[4][256];
    uint32_t n[4][256];
    size_t cap[4][256]; /* bytes */
    uint64_t used[4][4]; /* bit v of level l: bucket [l][v] is not empty */
    uint32_t head[256];  /* next item to pop in each level-0 bucket */
    uint32_t last;
    size_t size;
} tn__rheap;

static int tn__ctz64(uint64_t x)
{
#if defined(__GNUC__) || defined(__clang__)
    return __builtin_ctzll(x);
#else
    int b = 0;
    while (!(x & 1u)) { x >>= 1; b++; }
    return b;
#endif
}

static tn_status tn__rheap_push(tn__rheap *h, uint32_t key, uint32_t cell)
{
    uint32_t x = key ^ h->last;
    int l = x >> 8 ? (x >> 16 ? (x >> 24 ? 3 : 2) : 1) : 0, v = (int)(key >> (8 * l)) & 255;
    tn__rheap_item *it;
    if ((size_t)(h->n[l][v] + 1) * sizeof(tn__rheap_item) > h->cap[l][v]) {
        void *p = h->b[l][v];
        tn_status st = tn__reserve(&p, &h->cap[l][v], (size_t)(h->n[l][v] + 1) * sizeof(tn__rheap_item));
        if (st) return st;
        h->b[l][v] = (tn__rheap_item *)p;
    }
    it = h->b[l][v] + h->n[l][v]++;
    it->key = key;
    it->cell = cell;
    h->used[l][v >> 6] |= (uint64_t)1 << (v & 63);
    h->size++;
    return TN_OK;
}

/* Lowest non-empty bucket of level l, or -1. */
static int tn__rheap_first(const tn__rheap *h, int l)
{
    int q;
    for (q = 0; q < 4; q++)
        if (h->used[l][q]) return q * 64 + tn__ctz64(h->used[l][q]);
    return -1;
}

/* Pops a minimum; the heap must not be empty. */
static tn_status tn__rheap_pop(tn__rheap *h, uint32_t *key, uint32_t *cell)
{
    int v = tn__rheap_first(h, 0);
    if (v < 0) {
        int l = 1, u;
        uint32_t i, m, mn = 0xffffffffu;
        tn__rheap_item *b;
        while ((u = tn__rheap_first(h, l)) < 0) l++;
        b = h->b[l][u];
        m = h->n[l][u];
        for (i = 0; i < m; i++) if (b[i].key < mn) mn = b[i].key;
        h->last = mn;
        h->n[l][u] = 0;
        h->used[l][u >> 6] &= ~((uint64_t)1 << (u & 63));
        h->size -= m;
        for (i = 0; i < m; i++) { /* all land below level l, never in this bucket */
            tn_status st = tn__rheap_push(h, b[i].key, b[i].cell);
            if (st) return st;
        }
        v = tn__rheap_first(h, 0);
    }
    {
        tn__rheap_item *it = h->b[0][v] + h->head[v]++;
        *key = it->key;
        *cell = it->cell;
        if (h->head[v] == h->n[0][v]) {
            h->head[v] = h->n[0][v] = 0;
            h->used[0][v >> 6] &= ~((uint64_t)1 << (v & 63));
        }
        h->size--;
    }
    return TN_OK;
}

/* The cell a pop will return next (for prefetching), or `none` when level 0 is empty. */
static uint32_t tn__rheap_peek(const tn__rheap *h, uint32_t none)
{
    int v = tn__rheap_first(h, 0);
    return v < 0 ? none : h->b[0][v][h->head[v]].cell;
}

static void tn__rheap_free(tn__rheap *h)
{
    int l, v;
    for (l = 0; l < 4; l++)
        for (v = 0; v < 256; v++) TN_FREE(h->b[l][v]);
}

/* Channel 0 of src as a new one-channel image (D8 and the metrics read plain height grids). */
TN__INTERNAL tn_status tn__channel0_image(const tn_image *src, tn_image *dst)
{
    size_t i, n = (size_t)src->width * src->height;
    tn_status st = tn__image_alloc(dst, src->width, src->height, 1);
    if (st) return st;
    for (i = 0; i < n; i++) dst->data[i] = src->data[i * (size_t)src->channels];
    return TN_OK;
}

/* Min-heap of (priority, cell) for the cells of depressions (tn__pheap, in src/internal.h for
   test_fill). */

TN__INTERNAL tn_status tn__pheap_push(tn__pheap *h, uint64_t pri, uint32_t cell)
{
    size_t i;
    tn_status st = tn__reserve((void **)&h->a, &h->cap, (h->n + 1) * sizeof(tn__pheap_item));
    if (st) return st;
    for (i = h->n++; i > 0 && h->a[(i - 1) / 4].pri > pri; i = (i - 1) / 4) h->a[i] = h->a[(i - 1) / 4];
    h->a[i].pri = pri;
    h->a[i].cell = cell;
    return TN_OK;
}

/* The smallest of the children c .. min(c + 4, n) - 1 (c < n), branch-free when all four exist:
   the comparisons are unpredictable. Priorities are unique (they hold a sequence number). */
static size_t tn__pheap_minchild(const tn__pheap_item *a, size_t c, size_t n)
{
    size_t b, k;
    if (c + 4 <= n) {
        size_t b01 = a[c + 1].pri < a[c].pri ? c + 1 : c, b23 = a[c + 3].pri < a[c + 2].pri ? c + 3 : c + 2;
        return a[b23].pri < a[b01].pri ? b23 : b01;
    }
    for (b = c, k = c + 1; k < n; k++) b = a[k].pri < a[b].pri ? k : b;
    return b;
}

/* Replaces the top by `it` (sifted down); returns the old top's cell. */
TN__INTERNAL uint32_t tn__pheap_replace(tn__pheap *h, tn__pheap_item it)
{
    uint32_t top = h->a[0].cell;
    size_t i = 0, c, b;
    while ((c = 4 * i + 1) < h->n && h->a[b = tn__pheap_minchild(h->a, c, h->n)].pri < it.pri) {
        h->a[i] = h->a[b];
        i = b;
    }
    h->a[i] = it;
    return top;
}

/* Pops the top. The last item came from the bottom, so the hole goes down to a leaf along the
   smaller children and the item climbs back from there: fewer comparisons than testing it on
   the way down. */
TN__INTERNAL uint32_t tn__pheap_pop(tn__pheap *h)
{
    uint32_t top = h->a[0].cell;
    tn__pheap_item last = h->a[--h->n];
    size_t i = 0, c, b;
    while ((c = 4 * i + 1) < h->n) {
        b = tn__pheap_minchild(h->a, c, h->n);
        h->a[i] = h->a[b];
        i = b;
    }
    while (i > 0 && h->a[(i - 1) / 4].pri > last.pri) {
        h->a[i] = h->a[(i - 1) / 4];
        i = (i - 1) / 4;
    }
    h->a[i] = last;
    return top;
}

/* Filling runs on a copy of the keys framed by one cell of closed sentinels (TN__FRAME), so no
   neighbour lookup needs a bounds check. */
#define TN__CLOSED 0x80000000u /* in the key word: saves a cache miss per neighbour */
#define TN__FRAME 0xffffffffu

typedef struct tn__fill_state {
    uint32_t *keys;           /* framed: (w + 2) x (h + 2) */
    uint8_t *par;             /* framed, or NULL: direction from each raised cell to the cell that raised it */
    ptrdiff_t off[8];         /* neighbour offsets in the framed grid */
    tn__rheap *q;
    tn__pheap pit;
    uint32_t *trace;          /* stack of slope cells processed out of order (Zhou et al. 2016) */
    size_t ntrace, cap_trace; /* cap in bytes */
    uint32_t seq;
    tn__pheap_item next;      /* the lowest pit cell the last expansion found (when has_next) */
    int has_next;
} tn__fill_state;

/* r.watershed's neighbour order (S, N, W, E, NE, SW, SE, NW): cardinal cells join the queues
   first, so they are the older ones when a flat or depression is crossed. */
static const uint8_t tn__fill_order[8] = {2, 6, 4, 0, 7, 3, 1, 5};

/* Closes the open neighbours of c (filled key k) for a flood at level lvl (k for a cell at its
   own height; the water level inside a depression): lower ones are raised to k + 1 and join the
   pit heap; ones at lvl..k are raised to k + 1 and queue at lvl, behind the cells already there
   (so a flat fills in rings from all its lower edges, oldest first, as in r.watershed's A*
   search); higher ones keep their height and go on the trace stack. Raised cells remember c. */
static tn_status tn__fill_expand(tn__fill_state *f, uint32_t c, uint32_t k, uint32_t lvl)
{
    int o;
    for (o = 0; o < 8; o++) {
        const int d = tn__fill_order[o];
        size_t ni = (size_t)((ptrdiff_t)c + f->off[d]);
        uint32_t v = f->keys[ni];
        tn_status st;
        if (v & TN__CLOSED) continue;
        if (v <= k) {
            f->keys[ni] = (k + 1) | TN__CLOSED;
            if (f->par) f->par[ni] = (uint8_t)((d + 4) & 7);
            if (v < lvl) { /* in a depression: one step above c */
                tn__pheap_item it;
                it.pri = ((uint64_t)v << 32) | f->seq++;
                it.cell = (uint32_t)ni;
                it.pad = 0;
                /* the lowest stays out of the heap: it is often the next pop (the flood runs downhill) */
                if (f->has_next && f->next.pri < it.pri) {
                    if ((st = tn__pheap_push(&f->pit, it.pri, it.cell))) return st;
                } else {
                    if (f->has_next && (st = tn__pheap_push(&f->pit, f->next.pri, f->next.cell))) return st;
                    f->next = it;
                    f->has_next = 1;
                }
            } else if ((st = tn__rheap_push(f->q, lvl, (uint32_t)ni))) return st;
        }
    }
    for (o = 7; o >= 0; o--) { /* reversed, so the trace stack hands them out in the order above */
        const int d = tn__fill_order[o];
        size_t ni = (size_t)((ptrdiff_t)c + f->off[d]);
        uint32_t v = f->keys[ni];
        if (v & TN__CLOSED) continue;
        f->keys[ni] = v | TN__CLOSED;
        if ((f->ntrace + 1) * sizeof(uint32_t) > f->cap_trace) {
            tn_status st = tn__reserve((void **)&f->trace, &f->cap_trace, (f->ntrace + 1) * sizeof(uint32_t));
            if (st) return st;
        }
        f->trace[f->ntrace++] = (uint32_t)ni;
    }
    return TN_OK;
}

/* Fills the framed keys in place by priority-flood + epsilon (Barnes et al. 2014), visiting
   cells in r.watershed's A* order (lowest first, equal heights oldest first), with two speed-ups
   that keep most cells out of the priority queue and its random memory access:
   - slope tracing (Zhou, Sun & Fu 2016): a cell reached from below whose open neighbours are all
     strictly higher keeps its height and is expanded at once, depth first, where its
     neighbourhood is still in cache; only cells with a lower open neighbour wait in the queue;
   - the pit queue of the improved variant, here a heap on the ORIGINAL heights (ties first come,
     first served): a depression fills from its outlet along its deepest path first, like
     r.watershed's least-cost search, so flow follows the depression's thalweg (or, on an
     inverted DEM, a summit's crest) instead of parallel straight lines.
   The main queue is a radix heap of (level, cell): every key pushed is at or above the last one
   popped. When par is given, each raised cell records the cell that raised it: r.watershed's
   flow direction on flats and in depressions, and a strict descent of the filled keys. */
static tn_status tn__fill_keys(uint32_t *keys, uint8_t *par, int w, int h)
{
    tn__fill_state f;
    const size_t W = (size_t)w + 2, n = (size_t)w * h;
    size_t done = 0;
    tn_status st = TN_OK;
    uint32_t flood = 0; /* level of the last main-queue pop: the water level inside a depression */
    int x, y, d;
    memset(&f, 0, sizeof f);
    f.q = (tn__rheap *)tn__calloc(sizeof(tn__rheap));
    if (!f.q) return TN_ERR_OUT_OF_MEMORY;
    f.keys = keys;
    f.par = par;
    for (d = 0; d < 8; d++) f.off[d] = (ptrdiff_t)tn__d8y[d] * (ptrdiff_t)W + tn__d8x[d];
    for (y = 0; y < h && !st; y++)
        for (x = 0; x < w && !st; x += (y == 0 || y == h - 1 || x == w - 1) ? 1 : w - 1) {
            size_t i = (size_t)(y + 1) * W + (size_t)x + 1;
            st = tn__rheap_push(f.q, keys[i], (uint32_t)i);
            keys[i] |= TN__CLOSED;
        }
    while (!st && (f.q->size || f.pit.n || f.has_next)) {
        uint32_t k, c, lvl;
        if (f.has_next) { /* the heap's minimum is either it or the heap's top */
            f.has_next = 0;
            c = f.pit.n && f.pit.a[0].pri < f.next.pri ? tn__pheap_replace(&f.pit, f.next) : f.next.cell;
            lvl = flood;
        } else if (f.pit.n) {
            c = tn__pheap_pop(&f.pit);
            lvl = flood;
        } else if ((st = tn__rheap_pop(f.q, &lvl, &c))) break;
        else flood = lvl;
        k = keys[c] & ~TN__CLOSED; /* above lvl for a raised cell */
        { /* the pops jump around the map: fetch the next cell's rows while this one is processed */
            uint32_t nx = f.has_next ? f.next.cell : f.pit.n ? f.pit.a[0].cell : tn__rheap_peek(f.q, c);
            TN__PREFETCH(keys + nx - W - 1);
            TN__PREFETCH(keys + nx - 1);
            TN__PREFETCH(keys + nx + W - 1);
        }
        if ((st = tn__fill_expand(&f, c, k, lvl))) break;
        while (f.ntrace && !st) {
            const uint32_t t = f.trace[--f.ntrace], kt = keys[t] & ~TN__CLOSED, *p = keys + t;
            /* closed neighbours (and the frame) have the top bit set, so they are never <= kt.
               An open neighbour as low or lower may drain elsewhere at a lower level (and raising
               it here would start a pit cascade above the queue's level): wait in order */
            int lower = p[f.off[0]] <= kt || p[f.off[1]] <= kt || p[f.off[2]] <= kt || p[f.off[3]] <= kt ||
                        p[f.off[4]] <= kt || p[f.off[5]] <= kt || p[f.off[6]] <= kt || p[f.off[7]] <= kt;
            st = lower ? tn__rheap_push(f.q, kt, t) : tn__fill_expand(&f, t, kt, kt);
            done++;
        }
        if (!st && (++done & 0xfffff) < 16) st = tn__progress("fill", (double)done / (double)n);
    }
    tn__rheap_free(f.q);
    TN_FREE(f.q);
    TN_FREE(f.pit.a);
    TN_FREE(f.trace);
    return st;
}

typedef struct tn__keys_job { const tn_image *dem; int invert; uint32_t *k; } tn__keys_job;

static void tn__keys_rows(void *ctx, size_t y0, size_t y1)
{
    const tn__keys_job *j = (const tn__keys_job *)ctx;
    const size_t w = (size_t)j->dem->width, W = w + 2, C = (size_t)j->dem->channels;
    size_t x, y;
    for (y = y0; y < y1; y++) {
        const float *src = j->dem->data + y * w * C;
        uint32_t *row = j->k + (y + 1) * W;
        row[0] = row[w + 1] = TN__FRAME;
        for (x = 0; x < w; x++) row[x + 1] = tn__fkey(j->invert ? -src[x * C] : src[x * C]) >> 1;
    }
}

/* Heights of channel 0 as 31-bit keys (the float key without its last bit, so the top bit is
   free for the closed flag) in a grid framed by TN__FRAME; invert flips the sign (ridges).
   Fails on NaN/Inf. */
static tn_status tn__dem_keys(const tn_image *dem, int invert, const char *what, uint32_t **out)
{
    const int w = dem->width, h = dem->height;
    const size_t W = (size_t)w + 2;
    size_t bytes, x;
    tn__keys_job j;
    tn_status st = tn__size4(W, (size_t)h + 2, 1, sizeof(uint32_t), &bytes);
    if (st) return st;
    if (W * ((size_t)h + 2) > 0xfffffffeu) return tn__fail(TN_ERR_TOO_LARGE, "%s: %d x %d cells exceed the 2^32 cell limit", what, w, h);
    if ((st = tn__dem_finite(dem, what))) return st;
    j.k = (uint32_t *)tn__alloc(bytes);
    if (!j.k) return TN_ERR_OUT_OF_MEMORY;
    j.dem = dem;
    j.invert = invert;
    for (x = 0; x < W; x++) j.k[x] = j.k[(size_t)(h + 1) * W + x] = TN__FRAME;
    tn_parallel_for((size_t)h, tn__row_grain(w), tn__keys_rows, &j);
    *out = j.k;
    return TN_OK;
}

typedef struct tn__heights_job { const uint32_t *keys; const tn_image *dem; int invert; float *out; } tn__heights_job;

/* Filled heights from framed keys: untouched cells keep their exact height; raised cells get the
   float of their key, which is above every float of the key below (so each raise stays strict). */
static void tn__keys_to_heights(void *ctx, size_t y0, size_t y1)
{
    const tn__heights_job *j = (const tn__heights_job *)ctx;
    const size_t w = (size_t)j->dem->width, C = (size_t)j->dem->channels;
    size_t x, y;
    for (y = y0; y < y1; y++) {
        const uint32_t *kr = j->keys + (y + 1) * (w + 2) + 1;
        const float *src = j->dem->data + y * w * C;
        float *o = j->out + y * w;
        for (x = 0; x < w; x++) {
            float v = j->invert ? -src[x * C] : src[x * C];
            uint32_t key = kr[x] & ~TN__CLOSED;
            o[x] = key == (tn__fkey(v) >> 1) ? v : tn__fkey_inv(key << 1);
        }
    }
}

/* Depression-filled channel 0 of dem (negated first when invert) into a new one-channel image.
   With par, also a new framed (w + 2) x (h + 2) grid of the flood's flow directions for the
   raised cells (TN_FLOW_OUTLET elsewhere). */
static tn_status tn__fill_image(const tn_image *dem, int invert, const char *what, tn_image *out, uint8_t **par)
{
    uint32_t *keys = NULL;
    uint8_t *p = NULL;
    tn__heights_job j;
    tn_status st;
    if (!dem || !dem->data || dem->width <= 0 || dem->height <= 0 || dem->channels <= 0)
        return tn__fail(TN_ERR_EMPTY, "%s: the DEM is empty", what);
    if ((st = tn__dem_keys(dem, invert, what, &keys))) return st;
    if (par) {
        const size_t framed = ((size_t)dem->width + 2) * ((size_t)dem->height + 2);
        if (!(p = (uint8_t *)tn__alloc(framed))) {
            TN_FREE(keys);
            return TN_ERR_OUT_OF_MEMORY;
        }
        memset(p, TN_FLOW_OUTLET, framed);
    }
    if ((st = tn__fill_keys(keys, p, dem->width, dem->height)) || (st = tn__image_alloc(out, dem->width, dem->height, 1))) {
        TN_FREE(keys);
        TN_FREE(p);
        return st;
    }
    if (par) *par = p;
    j.keys = keys;
    j.dem = dem;
    j.invert = invert;
    j.out = out->data;
    tn_parallel_for((size_t)dem->height, tn__row_grain(dem->width), tn__keys_to_heights, &j);
    TN_FREE(keys);
    return TN_OK;
}

TN_API tn_status tn_fill_depressions(tn_image *dst, const tn_image *dem)
{
    tn_image out = {0, 0, 0, NULL};
    tn_status st;
    TN_ASSERT(dst);
    if ((st = tn__fill_image(dem, 0, "fill depressions", &out, NULL))) return st;
    *dst = out;
    return TN_OK;
}

typedef struct tn__d8_job { const float *h; const uint8_t *par; uint8_t *dir; int w, hgt; } tn__d8_job;

static void tn__d8_rows(void *ctx, size_t y0, size_t y1)
{
    const tn__d8_job *j = (const tn__d8_job *)ctx;
    const int w = j->w, H = j->hgt;
    int x, y, d;
    for (y = (int)y0; y < (int)y1; y++) {
        uint8_t *dr = j->dir + (size_t)y * w;
        const float *up, *row, *dn, *nb[8];
        if (y == 0 || y == H - 1 || w < 3) { /* the border drains off the map */
            memset(dr, TN_FLOW_OUTLET, (size_t)w);
            continue;
        }
        dr[0] = dr[w - 1] = TN_FLOW_OUTLET;
        /* interior: fixed neighbour offsets and no bounds checks, so the loop vectorises; the
           strict > keeps the first of equal drops in E, SE, S, ... order */
        up = j->h + (size_t)(y - 1) * w;
        row = up + w;
        dn = row + w;
        nb[0] = row + 1; nb[1] = dn + 1; nb[2] = dn; nb[3] = dn - 1;
        nb[4] = row - 1; nb[5] = up - 1; nb[6] = up; nb[7] = up + 1;
        for (x = 1; x < w - 1; x++) {
            double hc = row[x], best = 0.0;
            int bd = TN_FLOW_OUTLET;
            for (d = 0; d < 8; d++) {
                double drop = hc - (double)nb[d][x];
                if (d & 1) drop *= 0.70710678118654752;
                if (drop > best) { best = drop; bd = d; }
            }
            dr[x] = (uint8_t)bd;
        }
        if (j->par) { /* raised cells drain to the cell the flood came from */
            const uint8_t *pr = j->par + (size_t)(y + 1) * (size_t)(w + 2) + 1;
            for (x = 1; x < w - 1; x++)
                if (pr[x] != TN_FLOW_OUTLET) dr[x] = pr[x];
        }
    }
}

/* D8 of a filled DEM; par (framed, or NULL) overrides the directions of raised cells. */
static tn_status tn__flow_dirs(tn_flow *flow, const tn_image *filled, const uint8_t *par)
{
    tn__d8_job j;
    tn_image tmp = {0, 0, 0, NULL};
    tn_status st;
    size_t n;
    TN_ASSERT(flow);
    if ((st = tn__dem_check(filled, 1, "flow directions"))) return st;
    n = (size_t)filled->width * filled->height;
    if (filled->channels != 1) { /* D8 reads a plain height grid */
        if ((st = tn__channel0_image(filled, &tmp))) return st;
        filled = &tmp;
    }
    memset(flow, 0, sizeof *flow);
    flow->dir = (uint8_t *)tn__alloc(n);
    if (!flow->dir) {
        tn_image_free(&tmp);
        return TN_ERR_OUT_OF_MEMORY;
    }
    flow->width = filled->width;
    flow->height = filled->height;
    j.h = filled->data;
    j.par = par;
    j.dir = flow->dir;
    j.w = filled->width;
    j.hgt = filled->height;
    tn_parallel_for((size_t)filled->height, tn__row_grain(filled->width), tn__d8_rows, &j);
    tn_image_free(&tmp);
    return TN_OK;
}

TN_API tn_status tn_flow_directions(tn_flow *flow, const tn_image *filled)
{
    return tn__flow_dirs(flow, filled, NULL);
}

/* Receiver of cell i, or -1 for an outlet. */
static ptrdiff_t tn__receiver(const tn_flow *f, size_t i)
{
    int d = f->dir[i];
    if (d >= 8) return -1;
    return (ptrdiff_t)i + tn__d8y[d] * (ptrdiff_t)f->width + tn__d8x[d];
}

typedef struct tn__indeg_job { const tn_flow *f; const uint8_t *mask; uint8_t *indeg; } tn__indeg_job;

/* In-degree of each cell: neighbours draining into it (only mask cells when mask is given).
   Each cell counts its own upstream neighbours, so rows are independent. */
static void tn__indeg_rows(void *ctx, size_t y0, size_t y1)
{
    const tn__indeg_job *j = (const tn__indeg_job *)ctx;
    const int w = j->f->width, h = j->f->height;
    const uint8_t *dir = j->f->dir, *mask = j->mask;
    int x, y, d;
    for (y = (int)y0; y < (int)y1; y++) {
        uint8_t *out = j->indeg + (size_t)y * w;
        int inner = y > 0 && y < h - 1 && w >= 3;
        for (x = 0; x < w; x++) {
            int c = 0;
            if (inner && x > 0 && x < w - 1) { /* interior: the vectorisable loop below */
                x = w - 2;
                continue;
            }
            for (d = 0; d < 8; d++) {
                int nx = x + tn__d8x[d], ny = y + tn__d8y[d];
                size_t ni;
                if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
                ni = (size_t)ny * w + nx;
                /* neighbour in direction d drains here if its direction is the opposite one */
                if (dir[ni] == (uint8_t)((d + 4) & 7) && (!mask || mask[ni])) c++;
            }
            out[x] = (uint8_t)c;
        }
        if (inner) { /* one term per neighbour: neighbour d drains here if it points back (d + 4) */
            const uint8_t *u = dir + (size_t)(y - 1) * w, *m = u + w, *l = m + w;
            if (!mask) {
                for (x = 1; x < w - 1; x++)
                    out[x] = (uint8_t)((m[x + 1] == 4) + (l[x + 1] == 5) + (l[x] == 6) + (l[x - 1] == 7) +
                                       (m[x - 1] == 0) + (u[x - 1] == 1) + (u[x] == 2) + (u[x + 1] == 3));
            } else {
                const uint8_t *mu = mask + (size_t)(y - 1) * w, *mm = mu + w, *ml = mm + w;
                /* a masked-off neighbour reads as direction 8, which points nowhere (written this
                   way, not as (dir == k) & (mask != 0): gcc 12 -O2 vectorised that into -1 terms) */
                for (x = 1; x < w - 1; x++)
                    out[x] = (uint8_t)(((mm[x + 1] ? m[x + 1] : 8) == 4) + ((ml[x + 1] ? l[x + 1] : 8) == 5) +
                                       ((ml[x] ? l[x] : 8) == 6) + ((ml[x - 1] ? l[x - 1] : 8) == 7) +
                                       ((mm[x - 1] ? m[x - 1] : 8) == 0) + ((mu[x - 1] ? u[x - 1] : 8) == 1) +
                                       ((mu[x] ? u[x] : 8) == 2) + ((mu[x + 1] ? u[x + 1] : 8) == 3));
            }
        }
    }
}

static tn_status tn__indegree(const tn_flow *f, const uint8_t *mask, uint8_t **out)
{
    tn__indeg_job j;
    uint8_t *indeg = (uint8_t *)tn__alloc((size_t)f->width * f->height);
    if (!indeg) return TN_ERR_OUT_OF_MEMORY;
    j.f = f;
    j.mask = mask;
    j.indeg = indeg;
    tn_parallel_for((size_t)f->height, tn__row_grain(f->width), tn__indeg_rows, &j);
    *out = indeg;
    return TN_OK;
}

static tn_status tn__flow_check(const tn_flow *f, const char *what)
{
    if (!f || !f->dir || f->width <= 0 || f->height <= 0)
        return tn__fail(TN_ERR_INVALID_ARG, "%s: no flow directions", what);
    return TN_OK;
}

typedef struct tn__pack_job { const tn_flow *f; const uint8_t *indeg; uint8_t *pk; } tn__pack_job;

/* In-degree and direction in one byte (indeg << 4 | dir, 15 = outlet): the walk below then
   touches two arrays per step instead of three. */
static void tn__pack_rows(void *ctx, size_t y0, size_t y1)
{
    const tn__pack_job *j = (const tn__pack_job *)ctx;
    size_t i, w = (size_t)j->f->width;
    for (i = y0 * w; i < y1 * w; i++) {
        int d = j->f->dir[i];
        j->pk[i] = (uint8_t)(j->indeg[i] << 4 | (d < 8 ? d : 15));
    }
}

/* One strip of rows for the threaded accumulation walk. */
typedef struct tn__acc_job {
    uint8_t *pk;
    uint32_t *acc;
    ptrdiff_t off[16];
    size_t w, rows, nstrips;
    size_t *seen;             /* per strip */
    uint32_t *out_cell, *out_add; /* per strip: 2w slots of flow leaving the strip */
    size_t *nout;
} tn__acc_job;

/* Walks down from cell c carrying a (acc of c, already stored) while each next cell has heard
   from all its upstream cells; cells in [lo, hi) only, flow leaving that range goes to the
   outbox (ocell == NULL: flow off the map, which the caller reports as undrained). Returns the cells finished. */
static size_t tn__acc_walk(const tn__acc_job *j, size_t c, uint32_t a, size_t lo, size_t hi, uint32_t *ocell,
                           uint32_t *oadd, size_t *nout)
{
    size_t seen = 0;
    for (;;) {
        size_t r;
        unsigned v;
        seen++;
        if ((j->pk[c] & 15) == 15) break;
        r = (size_t)((ptrdiff_t)c + j->off[j->pk[c] & 15]);
        if (r < lo || r >= hi) { /* another strip's cell: hand the flow over */
            if (ocell) {
                ocell[*nout] = (uint32_t)r;
                oadd[(*nout)++] = a;
            }
            break;
        }
        a = (j->acc[r] += a);
        v = j->pk[r];
        if ((v >> 4) > 1) {
            j->pk[r] = (uint8_t)(v - 16);
            break;
        }
        j->pk[r] = (uint8_t)(0xf0 | (v & 15));
        c = r;
    }
    return seen;
}

/* Strip ith of nth: every walk that stays inside it. A cell with upstream cells in another strip
   waits (its in-degree never reaches zero here) for the sequential pass over the outboxes. */
static void tn__acc_strip(void *ctx, int ith, int nth)
{
    const tn__acc_job *j = (const tn__acc_job *)ctx;
    size_t s, i;
    for (s = (size_t)ith; s < j->nstrips; s += (size_t)nth) {
        size_t lo = j->rows * s / j->nstrips * j->w, hi = j->rows * (s + 1) / j->nstrips * j->w, seen = 0;
        for (i = lo; i < hi; i++) j->acc[i] = 1;
        j->nout[s] = 0;
        for (i = lo; i < hi; i++)
            if (!(j->pk[i] >> 4)) /* no upstream cells, and not reached by a walk (15) */
                seen += tn__acc_walk(j, i, 1, lo, hi, j->out_cell + 2 * j->w * s, j->out_add + 2 * j->w * s, &j->nout[s]);
        j->seen[s] = seen;
    }
}

static tn_status tn__flow_accumulate(tn_flow *flow);

/* Directions handed in by a caller: every code must be 0-7 or TN_FLOW_OUTLET and lead to a cell
   of the map. The walks would take other codes for outlets, and a step off the left or right
   edge for the neighbouring row. Flows made here (tn_flow_compute) skip this. */
static tn_status tn__flow_codes_check(const tn_flow *f, const char *what)
{
    int x, y;
    tn_status st;
    if ((st = tn__flow_check(f, what))) return st;
    for (y = 0; y < f->height; y++)
        for (x = 0; x < f->width; x++) {
            int d = f->dir[(size_t)y * f->width + x], tx, ty;
            if (d == TN_FLOW_OUTLET) continue;
            if (d >= 8) return tn__fail(TN_ERR_CORRUPT, "%s: direction code %d at (%d, %d)", what, d, x, y);
            tx = x + tn__d8x[d];
            ty = y + tn__d8y[d];
            if (tx < 0 || ty < 0 || tx >= f->width || ty >= f->height)
                return tn__fail(TN_ERR_CORRUPT, "%s: the direction at (%d, %d) points off the map", what, x, y);
        }
    return TN_OK;
}

TN_API tn_status tn_flow_accumulation(tn_flow *flow)
{
    tn_status st = tn__flow_codes_check(flow, "flow accumulation");
    return st ? st : tn__flow_accumulate(flow);
}

static tn_status tn__flow_accumulate(tn_flow *flow)
{
    size_t i, s, n, seen = 0, S;
    uint8_t *pk = NULL;
    tn__acc_job a;
    tn__pack_job j;
    tn_status st;
    int d;
    if ((st = tn__flow_check(flow, "flow accumulation"))) return st;
    n = (size_t)flow->width * flow->height;
    if ((st = tn__indegree(flow, NULL, &pk))) return st;
    j.f = flow;
    j.indeg = pk;
    j.pk = pk; /* row by row in place: each byte is read before it is written */
    tn_parallel_for((size_t)flow->height, tn__row_grain(flow->width), tn__pack_rows, &j);
    memset(&a, 0, sizeof a);
    /* one strip per thread; the sums do not depend on the split, so neither does the result */
    S = (size_t)tn_get_threads();
    if (S > (size_t)flow->height) S = (size_t)flow->height;
    a.pk = pk;
    a.w = (size_t)flow->width;
    a.rows = (size_t)flow->height;
    a.nstrips = S;
    for (d = 0; d < 16; d++) a.off[d] = d < 8 ? tn__d8y[d] * (ptrdiff_t)flow->width + tn__d8x[d] : 0;
    a.acc = (uint32_t *)tn__alloc(n * sizeof(uint32_t));
    a.seen = (size_t *)tn__alloc(2 * S * sizeof(size_t));
    a.out_cell = (uint32_t *)tn__alloc(4 * a.w * S * sizeof(uint32_t));
    if (!a.acc || !a.seen || !a.out_cell) {
        st = TN_ERR_OUT_OF_MEMORY;
        goto done;
    }
    a.nout = a.seen + S;
    a.out_add = a.out_cell + 2 * a.w * S;
    tn_parallel_run(tn__acc_strip, &a);
    for (s = 0; s < S; s++) seen += a.seen[s];
    /* flow that crossed strips, in strip order: add it, and walk on (anywhere) from each cell
       that has now heard from all its upstream cells */
    for (s = 0; s < S; s++)
        for (i = 0; i < a.nout[s]; i++) {
            size_t r = a.out_cell[2 * a.w * s + i];
            unsigned v;
            uint32_t acc_r;
            if (r >= n) continue; /* points off the map: left undrained */
            v = pk[r];
            acc_r = (a.acc[r] += a.out_add[2 * a.w * s + i]);
            if ((v >> 4) > 1) {
                pk[r] = (uint8_t)(v - 16);
                continue;
            }
            pk[r] = (uint8_t)(0xf0 | (v & 15));
            seen += tn__acc_walk(&a, r, acc_r, 0, n, NULL, NULL, NULL);
        }
    if (seen != n) st = tn__fail(TN_ERR_CORRUPT, "flow accumulation: the directions hold a cycle (%zu cells never drained)", n - seen);
done:
    TN_FREE(pk);
    TN_FREE(a.seen);
    TN_FREE(a.out_cell);
    if (st) {
        TN_FREE(a.acc);
        return st;
    }
    TN_FREE(flow->acc);
    flow->acc = a.acc;
    return TN_OK;
}

TN_API void tn_flow_free(tn_flow *flow)
{
    if (!flow) return;
    TN_FREE(flow->dir);
    TN_FREE(flow->acc);
    memset(flow, 0, sizeof *flow);
}

TN_API tn_status tn_flow_compute(tn_flow *flow, const tn_image *dem, int invert)
{
    tn_image filled = {0, 0, 0, NULL};
    uint8_t *par = NULL;
    tn_status st;
    TN_ASSERT(flow);
    memset(flow, 0, sizeof *flow);
    if ((st = tn__fill_image(dem, invert, "flow", &filled, &par))) return st;
    st = tn__flow_dirs(flow, &filled, par);
    tn_image_free(&filled);
    TN_FREE(par);
    if (!st) st = tn__flow_accumulate(flow); /* own directions: valid codes */
    if (st) tn_flow_free(flow);
    return st;
}

static tn_status tn__strahler(const tn_flow *flow, const uint8_t *mask, uint8_t *order, int *max_order);

TN_API tn_status tn_strahler_order(uint8_t *order, const tn_flow *flow, const uint8_t *mask, int *max_order)
{
    tn_status st = tn__flow_codes_check(flow, "strahler order");
    return st ? st : tn__strahler(flow, mask, order, max_order);
}

static tn_status tn__strahler(const tn_flow *flow, const uint8_t *mask, uint8_t *order, int *max_order)
{
    size_t i, n, masked = 0, seen = 0;
    uint8_t *indeg = NULL, *cnt;
    int top = 0;
    tn_status st;
    if ((st = tn__flow_check(flow, "strahler order"))) return st;
    TN_ASSERT(mask && order);
    n = (size_t)flow->width * flow->height;
    if ((st = tn__indegree(flow, mask, &indeg))) return st;
    cnt = (uint8_t *)tn__calloc(n); /* how many upstream cells reached order[] so far */
    if (!cnt) {
        TN_FREE(indeg);
        return TN_ERR_OUT_OF_MEMORY;
    }
    memset(order, 0, n);
    for (i = 0; i < n; i++) {
        size_t c = i;
        masked += mask[i] != 0;
        if (!mask[i] || indeg[i]) continue;
        for (;;) {
            ptrdiff_t r;
            int o = order[c] == 0 ? 1 : (cnt[c] >= 2 ? order[c] + 1 : order[c]);
            seen++;
            if (o > 255) o = 255;
            order[c] = (uint8_t)o;
            if (o > top) top = o;
            r = tn__receiver(flow, c);
            if (r < 0 || !mask[r]) break;
            if (o > order[r]) { order[r] = (uint8_t)o; cnt[r] = 1; }
            else if (o == order[r] && cnt[r] < 255) cnt[r]++;
            if (--indeg[r]) break;
            indeg[r] = 0x80;
            c = (size_t)r;
        }
    }
    TN_FREE(indeg);
    TN_FREE(cnt);
    if (max_order) *max_order = top;
    /* cells on a cycle never run out of upstream cells, so the walk never reaches them */
    if (seen != masked) return tn__fail(TN_ERR_CORRUPT, "strahler order: the directions hold a cycle (%zu network cells never reached)", masked - seen);
    return TN_OK;
}

/* ---- morphology and thinning ---------------------------------------------------------------- */

/* Square dilation (grow != 0) or erosion of radius r, separable; outside the map counts as set
   for erosion and as clear for dilation, so borders neither erode nor grow. */
static tn_status tn__morph(uint8_t *m, int w, int h, int r, int grow)
{
    size_t n = (size_t)w * h;
    uint8_t *t = (uint8_t *)tn__alloc(n);
    int x, y, k;
    if (!t) return TN_ERR_OUT_OF_MEMORY;
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++) {
            int v = grow ? 0 : 1;
            for (k = -r; k <= r; k++) {
                int xx = x + k, s;
                if (xx < 0 || xx >= w) continue;
                s = m[(size_t)y * w + xx] != 0;
                if (grow ? s : !s) { v = grow; break; }
            }
            t[(size_t)y * w + x] = (uint8_t)v;
        }
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++) {
            int v = grow ? 0 : 1;
            for (k = -r; k <= r; k++) {
                int yy = y + k, s;
                if (yy < 0 || yy >= h) continue;
                s = t[(size_t)yy * w + x];
                if (grow ? s : !s) { v = grow; break; }
            }
            m[(size_t)y * w + x] = (uint8_t)v;
        }
    TN_FREE(t);
    return TN_OK;
}




/* ---- contour graph ------------------------------------------------------------------------ */

/* Polylines are built with tn__pts / tn__pts_push and stored with tn__cset_add; skeletons are
   traced by tn__trace_skeleton (>>sketch). */







/* ---- extraction pipeline ------------------------------------------------------------------ */

/* q-quantile of v[0..n) exactly, by a two-pass radix select on order-preserving keys. */
static float tn__quantile(const float *v, size_t n, double q)
{
    size_t *hist, i, k, acc = 0;
    uint32_t hi = 0, lo = 0;
    int pass;
    if (!n) return 0.0f;
    hist = (size_t *)tn__calloc(65536 * sizeof(size_t));
    if (!hist) return 0.0f;
    k = (size_t)(q * (double)(n - 1));
    for (pass = 0; pass < 2; pass++) {
        uint32_t b;
        memset(hist, 0, 65536 * sizeof(size_t));
        for (i = 0; i < n; i++) {
            uint32_t key = tn__fkey(v[i]);
            if (pass == 0) hist[key >> 16]++;
            else if ((key >> 16) == hi) hist[key & 0xffffu]++;
        }
        for (b = 0; b < 65536; b++) {
            if (acc + hist[b] > k) break;
            acc += hist[b];
        }
        if (pass == 0) hi = b;
        else lo = b;
    }
    TN_FREE(hist);
    return tn__fkey_inv((hi << 16) | lo);
}

TN_API int tn_extract_default_threshold(int width, int height)
{
    double t = (double)width * (double)height / 1000.0;
    return t < 8.0 ? 8 : (int)(t + 0.5);
}

TN_API void tn_extraction_free(tn_extraction *ex)
{
    if (!ex) return;
    tn_flow_free(&ex->valley_flow);
    tn_flow_free(&ex->ridge_flow);
    TN_FREE(ex->valley_mask);
    TN_FREE(ex->ridge_mask);
    TN_FREE(ex->valley_order);
    TN_FREE(ex->ridge_order);
    tn_contour_set_free(&ex->contours);
    memset(ex, 0, sizeof *ex);
}

/* Removes dangling lines shorter than min_len pixels (keeping the junction they hang on) until
   none is left; returns through *st. */
static tn_status tn__prune_spurs(uint8_t *skel, int w, int h, int min_len)
{
    int round;
    for (round = 0; round < 8; round++) {
        tn__trace t;
        size_t l, removed = 0;
        tn_status st = tn__trace_skeleton(skel, w, h, &t);
        if (st) return st;
        for (l = 0; l < t.nlines; l++) {
            size_t a = t.starts[l], b = t.starts[l + 1], k;
            size_t c0 = t.cells[a], c1 = t.cells[b - 1];
            int d0 = tn__skel_degree(skel, w, h, (int)(c0 % (size_t)w), (int)(c0 / (size_t)w));
            int d1 = tn__skel_degree(skel, w, h, (int)(c1 % (size_t)w), (int)(c1 / (size_t)w));
            if ((int)(b - a) >= min_len) continue;
            if (c0 == c1 && b - a > 1) continue; /* a closed loop: not dangling */
            if (d0 > 1 && d1 > 1) continue;      /* junction to junction: keeps the network connected */
            for (k = a; k < b; k++) {
                size_t c = t.cells[k];
                if ((k == a && d0 > 2) || (k == b - 1 && d1 > 2)) continue;
                if (skel[c]) { skel[c] = 0; removed++; }
            }
        }
        tn__trace_free(&t);
        if (!removed) break;
    }
    return TN_OK;
}

/* Network of one type: mask, Strahler order, closing, thinning, tracing, filtering, splitting. */
static tn_status tn__extract_type(const tn_image *dem, const tn_image *grad, const tn_extract_opts *o,
                                  int ridge, tn_extraction *ex, size_t *cap)
{
    const int w = dem->width, h = dem->height;
    const size_t n = (size_t)w * h;
    tn_flow *flow = ridge ? &ex->ridge_flow : &ex->valley_flow;
    uint8_t *mask, *order, *skel = NULL, *ord2 = NULL;
    tn__trace t;
    tn__pts pl = {NULL, 0, 0};
    tn_status st;
    size_t i, l;
    int pass, top = 0;
    float grad_floor = 0.0f;
    if ((st = tn_flow_compute(flow, dem, ridge))) return st;
    if ((st = tn__progress(ridge ? "ridges" : "valleys", 0.3))) return st;
    mask = (uint8_t *)tn__alloc(n);
    order = (uint8_t *)tn__alloc(n);
    if (ridge) { ex->ridge_mask = mask; ex->ridge_order = order; }
    else { ex->valley_mask = mask; ex->valley_order = order; }
    if (!mask || !order) return TN_ERR_OUT_OF_MEMORY;
    for (i = 0; i < n; i++) mask[i] = flow->acc[i] >= (uint32_t)ex->threshold;
    if ((st = tn__strahler(flow, mask, order, &top))) return st; /* own flow: valid codes */
    if (ridge) ex->ridge_max_order = top;
    else ex->valley_max_order = top;
    skel = (uint8_t *)tn__alloc(n);
    ord2 = (uint8_t *)tn__alloc(n);
    if (!skel || !ord2) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    memcpy(skel, mask, n);
    memcpy(ord2, order, n);
    if (o->closing > 0) {
        if ((st = tn__morph(skel, w, h, o->closing, 1)) || (st = tn__morph(skel, w, h, o->closing, 0))) goto done;
        /* cells the closing added take the highest order next to them */
        for (pass = 0; pass <= o->closing; pass++)
            for (i = 0; i < n; i++)
                if (skel[i] && !ord2[i]) {
                    int k, x = (int)(i % (size_t)w), y = (int)(i / (size_t)w), best = 0;
                    for (k = 0; k < 8; k++) {
                        int xx = x + tn__d8x[k], yy = y + tn__d8y[k];
                        if (xx >= 0 && yy >= 0 && xx < w && yy < h && ord2[(size_t)yy * w + xx] > best)
                            best = ord2[(size_t)yy * w + xx];
                    }
                    ord2[i] = (uint8_t)best;
                }
    }
    if ((st = tn_skeletonize(skel, w, h))) goto done;
    if ((st = tn__progress(ridge ? "ridges" : "valleys", 0.7))) goto done;
    if ((st = tn__prune_spurs(skel, w, h, o->min_length))) goto done;
    if ((st = tn__trace_skeleton(skel, w, h, &t))) goto done;
    if (o->drop_fraction > 0 && t.nlines) { /* the floor: this quantile of the contours' mean gradients */
        float *means = (float *)tn__alloc(t.nlines * sizeof(float));
        size_t m = 0;
        if (!means) { st = TN_ERR_OUT_OF_MEMORY; tn__trace_free(&t); goto done; }
        for (l = 0; l < t.nlines; l++) {
            size_t a = t.starts[l], b = t.starts[l + 1], k;
            double g = 0.0;
            if ((int)(b - a) < o->min_length) continue;
            for (k = a; k < b; k++) g += grad->data[t.cells[k]];
            means[m++] = (float)(g / (double)(b - a));
        }
        grad_floor = m ? tn__quantile(means, m, o->drop_fraction) : 0.0f;
        TN_FREE(means);
    }
    for (l = 0; l < t.nlines && !st; l++) {
        size_t a = t.starts[l], b = t.starts[l + 1], k;
        int counts[256], npts = (int)(b - a), best = 0, bestc = 0, pieces, j;
        double gsum = 0.0;
        float gmean;
        if (npts < o->min_length) continue; /* what pruning left short: isolated bits */
        memset(counts, 0, sizeof counts);
        for (k = a; k < b; k++) {
            counts[ord2[t.cells[k]]]++;
            gsum += grad->data[t.cells[k]];
        }
        for (j = 1; j < 256; j++) /* the most common order; ties to the higher */
            if (counts[j] && counts[j] >= bestc) { best = j; bestc = counts[j]; }
        gmean = (float)(gsum / (double)npts);
        /* lowest drop_fraction of the contours, and dead flat ones (lakes, plains) */
        if (o->drop_fraction > 0 && (gmean < grad_floor || gmean <= 0.0f)) continue;
        pl.n = 0;
        for (k = a; k < b && !st; k++) {
            size_t c = t.cells[k];
            st = tn__pts_push(&pl, (float)(c % (size_t)w), (float)(c / (size_t)w), dem->data[c * (size_t)dem->channels]);
        }
        if (st) break;
        pieces = (npts - 1 + o->max_length - 2) / (o->max_length - 1);
        if (pieces < 1) pieces = 1;
        for (j = 0; j < pieces && !st; j++) { /* near-equal pieces sharing their end points */
            int s = (int)((long)j * (npts - 1) / pieces), e = (int)((long)(j + 1) * (npts - 1) / pieces);
            st = tn__cset_add(&ex->contours, cap, ridge ? TN_RIDGE : TN_VALLEY, best, gmean, pl.p + (size_t)s * 3, e - s + 1);
        }
    }
    tn__trace_free(&t);
done:
    TN_FREE(pl.p);
    TN_FREE(skel);
    TN_FREE(ord2);
    return st;
}

/* The zero rules of tn_extract_opts for a width x height DEM: the size's default threshold,
   closing radius 1, min_length 10, max_length 48, drop_fraction 0.01. A zero spacing is left
   to tn_image_gradient, whose own rule makes it 1. */
static void tn__extract_opts_defaults(tn_extract_opts *o, int width, int height)
{
    if (o->threshold == 0) o->threshold = tn_extract_default_threshold(width, height);
    if (o->closing == 0) o->closing = 1;
    if (o->min_length == 0) o->min_length = 10;
    if (o->max_length == 0) o->max_length = 48;
    if (o->drop_fraction == 0.0f) o->drop_fraction = 0.01f;
}

TN_API tn_status tn_extract(tn_extraction *out, const tn_image *dem, const tn_extract_opts *opts)
{
    tn_extract_opts o;
    tn_extraction ex;
    tn_image grad = {0, 0, 0, NULL}, gx = {0, 0, 0, NULL}, gy = {0, 0, 0, NULL};
    tn_status st;
    size_t i, n, cap = 0;
    TN_ASSERT(out);
    if ((st = tn__dem_check(dem, 1, "extract"))) return st;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    if (o.threshold < 0 || o.min_length < 0 || o.max_length < 0 || o.which < 0 || o.which > 2 ||
        !(o.drop_fraction < 1.0f) || !(o.dx >= 0.0f) || !(o.dy >= 0.0f))
        return tn__fail(TN_ERR_INVALID_ARG, "extract: negative threshold/lengths, drop_fraction >= 1 or a bad spacing");
    tn__extract_opts_defaults(&o, dem->width, dem->height);
    if (o.closing > 16) return tn__fail(TN_ERR_INVALID_ARG, "extract: closing radius %d is over 16", o.closing);
    if (o.max_length < 2) return tn__fail(TN_ERR_INVALID_ARG, "extract: max_length must be at least 2");
    memset(&ex, 0, sizeof ex);
    ex.width = dem->width;
    ex.height = dem->height;
    ex.threshold = o.threshold;
    ex.contours.width = dem->width;
    ex.contours.height = dem->height;
    n = (size_t)dem->width * dem->height;
    /* gradient magnitude: mean per contour and the floor of the lowest drop_fraction */
    if ((st = tn_image_gradient(&gx, &gy, dem, o.dx, o.dy))) return st;
    for (i = 0; i < n; i++) gx.data[i] = sqrtf(gx.data[i] * gx.data[i] + gy.data[i] * gy.data[i]);
    grad = gx;
    tn_image_free(&gy);
    if (o.which != TN_EXTRACT_RIDGES) st = tn__extract_type(dem, &grad, &o, 0, &ex, &cap);
    if (!st && o.which != TN_EXTRACT_VALLEYS) st = tn__extract_type(dem, &grad, &o, 1, &ex, &cap);
    tn_image_free(&grad);
    if (!st) st = tn__progress("extract", 1.0);
    if (st) {
        tn_extraction_free(&ex);
        return st;
    }
    *out = ex;
    return TN_OK;
}

/* ---- realism report ----------------------------------------------------------------------- */

/* In-place radix-2 complex FFT of n (a power of two) interleaved doubles, stride 1. */
static void tn__fft(double *re, double *im, int n)
{
    int i, j, len;
    for (i = 1, j = 0; i < n; i++) { /* bit reversal */
        int bit = n >> 1;
        for (; j & bit; bit >>= 1) j ^= bit;
        j ^= bit;
        if (i < j) {
            double t = re[i]; re[i] = re[j]; re[j] = t;
            t = im[i]; im[i] = im[j]; im[j] = t;
        }
    }
    for (len = 2; len <= n; len <<= 1) {
        double ang = -6.283185307179586 / len, wr = cos(ang), wi = sin(ang);
        for (i = 0; i < n; i += len) {
            double cr = 1.0, ci = 0.0;
            for (j = 0; j < len / 2; j++) {
                int a = i + j, b = i + j + len / 2;
                double xr = re[b] * cr - im[b] * ci, xi = re[b] * ci + im[b] * cr, t;
                re[b] = re[a] - xr; im[b] = im[a] - xi;
                re[a] += xr; im[a] += xi;
                t = cr * wr - ci * wi;
                ci = cr * wi + ci * wr;
                cr = t;
            }
        }
    }
}

#define TN__SPEC_BINS 24

/* Radially averaged power spectral density of the centred largest power-of-two square crop
   (mean removed, Hann window): bins[k] = mean |F|^2 / sum(w^2) over frequencies in log-spaced
   band k of [1/64 .. 0.5] cycles/px... scaled to the crop: band edges f_lo * (0.5/f_lo)^(k/K)
   with f_lo = 2 / S. Empty bands are 0. */
static tn_status tn__radial_spectrum(const tn_image *img, double f_lo, double *bins, int *size)
{
    int S = 16, x, y, k;
    double *re, *im, *win, mean = 0.0, wsum = 0.0, cnt[TN__SPEC_BINS];
    size_t bytes;
    tn_status st;
    while (S * 2 <= img->width && S * 2 <= img->height && S < 4096) S *= 2;
    if (img->width < 16 || img->height < 16)
        return tn__fail(TN_ERR_INVALID_ARG, "realism: terrain of %d x %d is under 16 x 16", img->width, img->height);
    *size = S;
    if (f_lo <= 0) f_lo = 2.0 / S;
    if ((st = tn__size4((size_t)S, (size_t)S, 2, sizeof(double), &bytes))) return st;
    re = (double *)tn__alloc(bytes);
    win = (double *)tn__alloc((size_t)S * sizeof(double));
    if (!re || !win) {
        TN_FREE(re);
        TN_FREE(win);
        return TN_ERR_OUT_OF_MEMORY;
    }
    im = re + (size_t)S * S;
    {
        int x0 = (img->width - S) / 2, y0 = (img->height - S) / 2;
        for (y = 0; y < S; y++)
            for (x = 0; x < S; x++) {
                double v = TN_PIXEL(img, x0 + x, y0 + y, 0);
                re[(size_t)y * S + x] = v;
                mean += v;
            }
    }
    mean /= (double)S * S;
    for (x = 0; x < S; x++) win[x] = 0.5 - 0.5 * cos(6.283185307179586 * (x + 0.5) / S);
    for (y = 0; y < S; y++)
        for (x = 0; x < S; x++) {
            double w2 = win[x] * win[y];
            re[(size_t)y * S + x] = (re[(size_t)y * S + x] - mean) * w2;
            im[(size_t)y * S + x] = 0.0;
            wsum += w2 * w2;
        }
    for (y = 0; y < S; y++) tn__fft(re + (size_t)y * S, im + (size_t)y * S, S);
    { /* columns through a scratch row */
        double *cr = (double *)tn__alloc((size_t)S * 2 * sizeof(double)), *ci;
        if (!cr) {
            TN_FREE(re);
            TN_FREE(win);
            return TN_ERR_OUT_OF_MEMORY;
        }
        ci = cr + S;
        for (x = 0; x < S; x++) {
            for (y = 0; y < S; y++) { cr[y] = re[(size_t)y * S + x]; ci[y] = im[(size_t)y * S + x]; }
            tn__fft(cr, ci, S);
            for (y = 0; y < S; y++) { re[(size_t)y * S + x] = cr[y]; im[(size_t)y * S + x] = ci[y]; }
        }
        TN_FREE(cr);
    }
    for (k = 0; k < TN__SPEC_BINS; k++) bins[k] = cnt[k] = 0.0;
    for (y = 0; y < S; y++)
        for (x = 0; x < S; x++) {
            int fx = x <= S / 2 ? x : x - S, fy = y <= S / 2 ? y : y - S;
            double f = sqrt((double)fx * fx + (double)fy * fy) / S, p;
            if (f < f_lo || f > 0.5) continue;
            k = (int)(log(f / f_lo) / log(0.5 / f_lo) * TN__SPEC_BINS);
            if (k >= TN__SPEC_BINS) k = TN__SPEC_BINS - 1;
            p = re[(size_t)y * S + x] * re[(size_t)y * S + x] + im[(size_t)y * S + x] * im[(size_t)y * S + x];
            bins[k] += p / wsum;
            cnt[k] += 1.0;
        }
    for (k = 0; k < TN__SPEC_BINS; k++) bins[k] = cnt[k] > 0 ? bins[k] / cnt[k] : 0.0;
    TN_FREE(re);
    TN_FREE(win);
    return TN_OK;
}

/* Least-squares slope of log10(bins) against log10(band centre frequency). */
static double tn__spectrum_slope(const double *bins, double f_lo)
{
    double sx = 0, sy = 0, sxx = 0, sxy = 0, m = 0;
    int k;
    for (k = 0; k < TN__SPEC_BINS; k++) {
        double f = f_lo * pow(0.5 / f_lo, (k + 0.5) / TN__SPEC_BINS), lx, ly;
        if (bins[k] <= 0) continue;
        lx = log10(f);
        ly = log10(bins[k]);
        sx += lx; sy += ly; sxx += lx * lx; sxy += lx * ly; m += 1;
    }
    if (m < 2 || m * sxx - sx * sx <= 0) return 0.0;
    return (m * sxy - sx * sy) / (m * sxx - sx * sx);
}

/* Relative earth mover's distance between the distributions of a[0..na) and b[0..nb) on 256
   bins over [lo, hi], divided by `scale` (the reference's mean magnitude). */
static double tn__hist_emd(const float *a, size_t na, const float *b, size_t nb, float lo, float hi, double scale)
{
    double ha[256], hb[256], ca = 0, cb = 0, emd = 0, bw = (double)(hi - lo) / 256.0;
    size_t i;
    int k;
    if (!(hi > lo) || !(scale > 0)) return 0.0;
    memset(ha, 0, sizeof ha);
    memset(hb, 0, sizeof hb);
    for (i = 0; i < na; i++) { k = (int)((a[i] - lo) / (hi - lo) * 256.0f); ha[k < 0 ? 0 : k > 255 ? 255 : k] += 1.0 / (double)na; }
    for (i = 0; i < nb; i++) { k = (int)((b[i] - lo) / (hi - lo) * 256.0f); hb[k < 0 ? 0 : k > 255 ? 255 : k] += 1.0 / (double)nb; }
    for (k = 0; k < 256; k++) {
        ca += ha[k];
        cb += hb[k];
        emd += fabs(ca - cb) * bw;
    }
    return emd / scale;
}

/* Slope magnitude (field 0) and 5-point Laplacian (field 1) of channel 0, interior cells only. */
static tn_status tn__slope_curv(const tn_image *dem, float dx, float dy, float **slope, float **curv, size_t *count)
{
    const int w = dem->width, h = dem->height;
    size_t n = (size_t)(w - 2) * (h - 2), i = 0;
    float *s, *c, ix, iy;
    int x, y;
    ix = 1.0f / dx;
    iy = 1.0f / dy;
    s = (float *)tn__alloc(n * sizeof(float));
    c = (float *)tn__alloc(n * sizeof(float));
    if (!s || !c) {
        TN_FREE(s);
        TN_FREE(c);
        return TN_ERR_OUT_OF_MEMORY;
    }
    for (y = 1; y < h - 1; y++)
        for (x = 1; x < w - 1; x++) {
            float z = TN_PIXEL(dem, x, y, 0), zl = TN_PIXEL(dem, x - 1, y, 0), zr = TN_PIXEL(dem, x + 1, y, 0);
            float zu = TN_PIXEL(dem, x, y - 1, 0), zd = TN_PIXEL(dem, x, y + 1, 0);
            float gx = tn__grad_x(dem, x, y) * ix, gy = tn__grad_y(dem, x, y) * iy; /* interior: (zr - zl) / 2 */
            s[i] = sqrtf(gx * gx + gy * gy);
            c[i] = (zr + zl - 2.0f * z) * ix * ix + (zd + zu - 2.0f * z) * iy * iy;
            i++;
        }
    *slope = s;
    *curv = c;
    *count = n;
    return TN_OK;
}

/* Drainage density (valley line length per cell) and mean bifurcation ratio of one DEM. */
static tn_status tn__drainage(const tn_image *dem, int threshold, double *density, double *rb)
{
    tn_extract_opts o;
    tn_extraction ex;
    tn_status st;
    double len = 0, nk[256];
    size_t i, n;
    int k, j, m = 0;
    memset(&o, 0, sizeof o);
    o.threshold = threshold;
    o.which = TN_EXTRACT_VALLEYS;
    if ((st = tn_extract(&ex, dem, &o))) return st;
    for (i = 0; i < (size_t)ex.contours.count; i++) {
        const tn_contour *c = &ex.contours.items[i];
        for (j = 1; j < c->npoints; j++)
            len += hypot(c->points[j * 3] - c->points[j * 3 - 3], c->points[j * 3 + 1] - c->points[j * 3 - 2]);
    }
    *density = len / ((double)dem->width * dem->height);
    /* streams of order k: network cells of order k whose receiver is off the network or of another order */
    memset(nk, 0, sizeof nk);
    n = (size_t)dem->width * dem->height;
    for (i = 0; i < n; i++) {
        ptrdiff_t r;
        if (!ex.valley_order[i]) continue;
        r = tn__receiver(&ex.valley_flow, i);
        if (r < 0 || ex.valley_order[r] != ex.valley_order[i]) nk[ex.valley_order[i]] += 1;
    }
    *rb = 0;
    for (k = 1; k < ex.valley_max_order && k < 255; k++)
        if (nk[k + 1] > 0) { *rb += nk[k] / nk[k + 1]; m++; }
    if (m) *rb /= m;
    tn_extraction_free(&ex);
    return TN_OK;
}

/* The zero rules of tn_realism_opts: the compared terrain's spacing is the reference's (dy_b
   only when dx_b is 0 too), then each dx 0 = 1 and each dy 0 = its dx (square pixels).
   threshold stays 0: tn_extract picks the default for each map's own size. */
static void tn__realism_opts_defaults(tn_realism_opts *o)
{
    if (o->dx_b == 0) {
        o->dx_b = o->dx_a;
        if (o->dy_b == 0) o->dy_b = o->dy_a;
    }
    if (o->dx_a == 0) o->dx_a = 1.0f;
    if (o->dy_a == 0) o->dy_a = o->dx_a;
    if (o->dx_b == 0) o->dx_b = 1.0f;
    if (o->dy_b == 0) o->dy_b = o->dx_b;
}

/* The morphology part of the realism report: slope and curvature histogram distances and the
   radially averaged spectra (distance and log-log slopes). Also the style scores (>>style).
   o has its defaults applied (positive spacings). */
static tn_status tn__realism_shape(const tn_image *ref, const tn_image *img, const tn_realism_opts *o, tn_realism *r)
{
    float *sa = NULL, *ca = NULL, *sb = NULL, *cb = NULL;
    size_t na = 0, nb = 0, i;
    double spa[TN__SPEC_BINS], spb[TN__SPEC_BINS], f_lo, mean_s = 0, mean_c = 0, d2 = 0, dm = 0;
    float hi_s = 0, hi_c = 0;
    int Sa, Sb, k, s0 = 16;
    tn_status st;
    if ((st = tn__slope_curv(ref, o->dx_a, o->dy_a, &sa, &ca, &na)) || (st = tn__slope_curv(img, o->dx_b, o->dy_b, &sb, &cb, &nb)))
        goto done;
    for (i = 0; i < na; i++) {
        mean_s += sa[i];
        mean_c += fabsf(ca[i]);
        if (sa[i] > hi_s) hi_s = sa[i];
        if (fabsf(ca[i]) > hi_c) hi_c = fabsf(ca[i]);
    }
    for (i = 0; i < nb; i++) {
        if (sb[i] > hi_s) hi_s = sb[i];
        if (fabsf(cb[i]) > hi_c) hi_c = fabsf(cb[i]);
    }
    mean_s /= (double)na;
    mean_c /= (double)na;
    r->slope_distance = tn__hist_emd(sa, na, sb, nb, 0.0f, hi_s, mean_s);
    r->curvature_distance = tn__hist_emd(ca, na, cb, nb, -hi_c, hi_c, mean_c);
    /* spectra on common bands: from 2 cycles across the smaller crop to Nyquist */
    while (s0 * 2 <= ref->width && s0 * 2 <= ref->height && s0 * 2 <= img->width && s0 * 2 <= img->height && s0 < 4096) s0 *= 2;
    f_lo = 2.0 / s0;
    if ((st = tn__radial_spectrum(ref, f_lo, spa, &Sa)) || (st = tn__radial_spectrum(img, f_lo, spb, &Sb))) goto done;
    for (k = 0; k < TN__SPEC_BINS; k++)
        if (spa[k] > 0 && spb[k] > 0) {
            double d = log10(spa[k]) - log10(spb[k]);
            d2 += d * d;
            dm += 1;
        }
    r->spectrum_distance = dm > 0 ? sqrt(d2 / dm) : 0.0;
    r->spectrum_slope_a = tn__spectrum_slope(spa, f_lo);
    r->spectrum_slope_b = tn__spectrum_slope(spb, f_lo);
done:
    TN_FREE(sa);
    TN_FREE(ca);
    TN_FREE(sb);
    TN_FREE(cb);
    return st;
}

TN_API tn_status tn_realism_compare(tn_realism *out, const tn_image *ref, const tn_image *img, const tn_realism_opts *opts)
{
    tn_realism_opts o;
    tn_realism r;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__dem_check(ref, 1, "realism (reference)")) || (st = tn__dem_check(img, 1, "realism (terrain)"))) return st;
    if (ref->width < 16 || ref->height < 16 || img->width < 16 || img->height < 16)
        return tn__fail(TN_ERR_INVALID_ARG, "realism: both terrains must be at least 16 x 16");
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    if (!(o.dx_a >= 0 && o.dy_a >= 0 && o.dx_b >= 0 && o.dy_b >= 0) || o.threshold < 0 ||
        !(o.dx_a <= FLT_MAX && o.dy_a <= FLT_MAX && o.dx_b <= FLT_MAX && o.dy_b <= FLT_MAX))
        return tn__fail(TN_ERR_INVALID_ARG, "realism: spacing must be finite and >= 0, threshold >= 0");
    tn__realism_opts_defaults(&o);
    memset(&r, 0, sizeof r);
    if ((st = tn__realism_shape(ref, img, &o, &r))) return st;
    if ((st = tn__progress("realism", 0.6))) return st;
    if ((st = tn__drainage(ref, o.threshold, &r.drainage_density_a, &r.bifurcation_ratio_a)) ||
        (st = tn__drainage(img, o.threshold, &r.drainage_density_b, &r.bifurcation_ratio_b)))
        return st;
    if (ref->width == img->width && ref->height == img->height && ref->width >= 11 && ref->height >= 11) {
        tn_image a1 = *ref, b1 = *img;
        tn_image ta = {0, 0, 0, NULL}, tb = {0, 0, 0, NULL};
        tn_metrics m;
        if (ref->channels != 1 || img->channels != 1) { /* compare channel 0 only */
            if ((st = tn__channel0_image(ref, &ta)) || (st = tn__channel0_image(img, &tb))) {
                tn_image_free(&ta);
                return st;
            }
            a1 = ta;
            b1 = tb;
        }
        st = tn_compare(&m, &a1, &b1, 0.0);
        tn_image_free(&ta);
        tn_image_free(&tb);
        if (st) return st;
        r.ssim = m.ssim;
        r.psnr = m.psnr;
    } else {
        r.ssim = r.psnr = NAN;
    }
    {
        double s = r.slope_distance + r.curvature_distance + r.spectrum_distance;
        double da = r.drainage_density_a, ba = r.bifurcation_ratio_a, pa = r.spectrum_slope_a;
        s += da > 0 ? fabs(r.drainage_density_b - da) / da : 0.0;
        s += ba > 0 ? fabs(r.bifurcation_ratio_b - ba) / ba : 0.0;
        s += pa != 0 ? fabs(r.spectrum_slope_b - pa) / fabs(pa) : 0.0;
        r.distance = s / 6.0;
    }
    st = tn__progress("realism", 1.0);
    if (!st) *out = r;
    return st;
}
#endif /* TN_NO_EXTRACT */

