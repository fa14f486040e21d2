/* ============================================================================================
   (@@gnn, continued: densify by example)
   ============================================================================================ */
#ifndef TN_NO_GNN

/* Densify by example (issue 30): a drawing of a few strokes leaves most of the map to the
   membrane, smooth slopes between the strokes. tn_gnn_grow fills the space between the user's
   lines with the example's own network, the network the model rebuilds best: the map is cut
   into blocks, and each copies the example's network from a window of the example under one of
   the 8 rotations and mirrors, the best of `candidates` random placements by how well its lines
   lie on the user's lines nearby (ridge on ridge, valley on valley) and continue the blocks
   placed before it across their overlap (image quilting, on the network; the new block starts
   along the overlap's minimum-error boundary). So line spacing, branch angles, segment lengths
   and ridge/valley alternation are the example's. Added lines keep `gap` px from every user line,
   so none crosses one; they are thinned and traced into polylines of 5+ px, and a line that ends
   heading for a user line of its own kind within 3 gaps runs on to it (a spur joins a drawn
   crest, a tributary a drawn valley). Their heights: the membrane of the user's lines, falling away from
   a user ridge and rising away from a user valley as the example's lines do from its main ridges
   and valleys (so a stroke stays the main line around it), plus the example line's own height above
   the mean of the example's lines within 48 px (its local relief; the quilting also matches
   these heights across the overlap). Given the example's heights as well (the model's path), the
   quilt carries them too, each block offset so its heights meet its neighbours', and the added
   lines are the network of those heights on the strokes' ground, with their relief taken, away
   from the strokes, against a mean over 512 px (tn__gnn_quilt_relief: a mountainside keeps its
   tilt) and faded in over 16 px from the drawn ridges (their flanks are the example's), that
   ground eroded by its own drainage in as far as the example's relief runs down its slopes
   (tn__gnn_quilt_erode: its gullies reach the drawn valleys); then, within 2 gaps of a user line
   (released by 4 gaps), kept below a user ridge and above a user valley (the nearest user line)
   by the example's mean local relief / 16 px per px. Ground whose lines stand above their nearest
   drawn ridge, by more than the example's own ground tops its main ridges, sinks as a whole
   (tn__gnn_grow_sink: the drawn ridges stay the high ground). When the lines' membrane then
   holds far more closed basins than the example's own (on an eroded ground, any more), each
   basin drains by a valley over its lowest saddle, and a drawn valley whose low end lies in one goes
   on out of it (tn__gnn_grow_drain; after the sink, which left new basins). Last, the added lines'
   heights are kept within the example's and the strokes' (tn__soft_limit): relief stacked on a
   high stroke's ground rose above the example's top, on a low one below its floor. */
typedef struct tn_gnn_grow_opts {
    uint64_t seed;
    float gap;            /* px between an added line and every user line; 0 = 4 */
    int block;            /* side of the copied blocks (px); 0 = 48 (2/3 of the example's side when that is smaller) */
    int candidates;       /* random placements scored per block; 0 = 48 */
} tn_gnn_grow_opts;
/* *out = the user's polylines (unchanged, first) followed by the added ones. user: on a width x
   height canvas (else TN_ERR_SHAPE), heights in the example's units; example: a network with
   heights (tn_gnn_parts of a model, or an extraction's contours), same pixel size, at least
   16 x 16. Same inputs and seed, same output. opts may be NULL. *added (may be NULL) = the
   number of added polylines. */
TN_API tn_status tn_gnn_grow(tn_contour_set *out, const tn_contour_set *user, const tn_contour_set *example, int width,
                             int height, const tn_gnn_grow_opts *opts, int *added);
#endif /* TN_NO_GNN */

/* --------------------------------------------------------------------------------------------
   >>gnn_grow  (part of @@gnn implementation; goes after >>gnn, whose chamfer distance it uses)
   Densify by example: image quilting of the example's extracted network (and, given them, its
   heights) between the user's lines (issue 30).
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_GNN

/* Position in the example of pixel (i, j) of an S x S window at (ox, oy) under dihedral t. */
static size_t tn__gnn_grow_at(int i, int j, int S, int t, int ox, int oy, int Wx)
{
    int a = i, b = j;
    if (t & 1) a = j, b = i;
    if (t & 2) a = S - 1 - a;
    if (t & 4) b = S - 1 - b;
    return (size_t)(oy + b) * Wx + ox + a;
}

/* The line types (+1 ridge, -1 valley, 0) averaged over the placed pixels of a 5 x 5 box, at the
   placed pixels of the ww x wh window at (x0, y0) of the map (0 elsewhere; placed NULL: all are):
   blurred, two networks correlate where their lines run close and alike, and an empty overlap
   does not. Returns how many placed line pixels the window holds. */
static int tn__gnn_grow_blur(const uint8_t *placed, const int8_t *ptype, int width, int height, int x0, int y0, int ww, int wh, float *out)
{
    int u, v, a, b, n = 0;
    for (v = 0; v < wh; v++)
        for (u = 0; u < ww; u++) {
            int X = x0 + u, Y = y0 + v, k = 0, m = 0;
            out[(size_t)v * ww + u] = 0;
            if (X < 0 || Y < 0 || X >= width || Y >= height || (placed && !placed[(size_t)Y * width + X])) continue;
            for (b = Y - 2; b <= Y + 2; b++)
                for (a = X - 2; a <= X + 2; a++)
                    if (a >= 0 && b >= 0 && a < width && b < height && (!placed || placed[(size_t)b * width + a]))
                        k += ptype[(size_t)b * width + a], m++;
            out[(size_t)v * ww + u] = (float)k / (float)m;
            n += ptype[(size_t)Y * width + X] != 0;
        }
    return n;
}

/* prof (TN__GNN_PROFILE + 1 values at 0, 1, ... px) at distance x >= 0, linear between, held beyond. */
static float tn__gnn_grow_table(const float *prof, float x)
{
    int i;
    if (!(x < TN__GNN_PROFILE)) return prof[TN__GNN_PROFILE];
    i = (int)x;
    return prof[i] + (x - (float)i) * (prof[i + 1] - prof[i]);
}

/* What the ground between the strokes takes from their kind: a drawn stroke is one of the
   example's main lines, so the ground falls away from a user ridge (rises away from a user
   valley) as the example's lines do from its main ridges (valleys): pr[d] (pv[d]) at distance
   d px, 0 .. TN__GNN_PROFILE (tn__gnn_grow_profile). So a stroke stays the main line around it
   rather than one line among the example's; between a ridge and a valley the two are blended
   by distance (the membrane already slopes from one to the other). dr, dv: px to the nearest
   user ridge and valley, FLT_MAX when the drawing has none. */
static float tn__gnn_grow_fall(float dr, float dv, const float *pr, const float *pv)
{
    float fr, fv, wr;
    if (dr == FLT_MAX && dv == FLT_MAX) return 0;
    fr = dr == FLT_MAX ? 0 : tn__gnn_grow_table(pr, dr);
    fv = dv == FLT_MAX ? 0 : tn__gnn_grow_table(pv, dv);
    if (dv == FLT_MAX) return -fr;
    if (dr == FLT_MAX) return fv;
    wr = dv / (dr + dv);
    return fv * (1 - wr) - fr * wr;
}

/* The example's main lines of one kind (the highest Strahler order among its lines of that kind)
   rasterised W x H into *mr (mr->data NULL when it has no line of that kind), and the chamfer
   distance to them (dist) with the nearest one's pixel (near); mask: W x H scratch. */
static tn_status tn__gnn_grow_mains(const tn_contour_set *example, int kind, int W, int H, tn_image *mr, uint8_t *mask, float *dist, int *near)
{
    tn_contour_set mains;
    int c, top = -1, k = 0;
    size_t i;
    tn_status st;
    for (c = 0; c < example->count; c++)
        if ((int)example->items[c].type == kind && example->items[c].order > top) top = example->items[c].order;
    if (top < 0) return TN_OK;
    mains = *example;
    mains.items = (tn_contour *)tn__alloc((size_t)example->count * sizeof(tn_contour));
    if (!mains.items) return TN_ERR_OUT_OF_MEMORY;
    for (c = 0; c < example->count; c++)
        if ((int)example->items[c].type == kind && example->items[c].order == top) mains.items[k++] = example->items[c];
    mains.count = k;
    st = tn_sketch_rasterise(mr, &mains, W, H);
    TN_FREE(mains.items);
    if (st) return st;
    for (i = 0; i < (size_t)W * H; i++) mask[i] = (uint8_t)(mr->data[3 * i + (kind == TN_VALLEY)] > 0);
    tn__gnn_chamfer(mask, W, H, dist, near);
    return TN_OK;
}

/* (distance, value) pairs by distance, then value. */
static int tn__gnn_pair_cmp(const void *a, const void *b)
{
    const float *x = (const float *)a, *y = (const float *)b;
    return x[0] != y[0] ? (x[0] < y[0] ? -1 : 1) : (x[1] > y[1]) - (x[1] < y[1]);
}

/* The example's profile away from its main lines of one kind (those of the highest Strahler
   order among its lines of that kind): prof[d], d = 0 .. TN__GNN_PROFILE, the mean over the
   example's lines of the same kind, at chamfer distance d (rounded) from the nearest main-line
   pixel, of how far they lie below it (ridges) or above it (valleys). Lines of the same kind
   only: the alternation of ridges and valleys is the added lines' own relief (tn__gnn_grow's
   prel), so this is the trend under it, and a dune field's crests, all alike, give almost none.
   Averaged over 13 px, so a dune field's few crests do not take their whole fall within a few
   px, and never below the distance before; distances no pixel reaches hold the last value.
   er: the example's raster (tn_sketch_rasterise); W x H scratch in mask, dist, near. prof is
   untouched when the example has no line of that kind. */
TN__INTERNAL tn_status tn__gnn_grow_profile(const tn_contour_set *example, const tn_image *er, int kind, float *prof, uint8_t *mask,
                                            float *dist, int *near)
{
    const int W = er->width, H = er->height, P = TN__GNN_PROFILE;
    const size_t n = (size_t)W * H;
    tn_image mr = {0, 0, 0, NULL};
    double sum[TN__GNN_PROFILE + 1], cnt[TN__GNN_PROFILE + 1];
    float raw[TN__GNN_PROFILE + 1], last = 0, sign = kind == TN_VALLEY ? 1.0f : -1.0f;
    int d;
    size_t i;
    tn_status st = tn__gnn_grow_mains(example, kind, W, H, &mr, mask, dist, near);
    if (st || !mr.data) return st;
    memset(sum, 0, sizeof sum);
    memset(cnt, 0, sizeof cnt);
    for (i = 0; i < n; i++) {
        if (!(er->data[3 * i + (kind == TN_VALLEY)] > 0) || near[i] < 0 || !(dist[i] < P + 0.5f)) continue;
        d = (int)(dist[i] + 0.5f);
        sum[d] += sign * (er->data[3 * i + 2] - mr.data[3 * (size_t)near[i] + 2]);
        cnt[d]++;
    }
    tn_image_free(&mr);
    for (d = 0; d <= P; d++) {
        if (cnt[d] > 0) last = (float)(sum[d] / cnt[d]);
        raw[d] = last;
    }
    for (d = 0, last = 0; d <= P; d++) {
        int a = d < 6 ? 0 : d - 6, b = d + 6 > P ? P : d + 6, j;
        float s = 0;
        for (j = a; j <= b; j++) s += raw[j];
        last = fmaxf(last, s / (float)(b - a + 1));
        prof[d] = last;
    }
    return TN_OK;
}

/* The example's ground away from its main lines of one kind (for valleys): prof[d], d = 0 ..
   TN__GNN_PROFILE, the mean over every pixel of dem (the example's heights, on its network's
   pixels) at chamfer distance d (rounded) from the nearest main-line pixel of how far it lies
   above (valleys) or below (ridges) that pixel, never falling back with distance. The example's
   other valleys alone (tn__gnn_grow_profile) stop rising where its tributaries join (the Alps:
   279 m from 18 px on), and a drawn valley between two such shoulders read as a trough; its
   ground rises on (the Alps: 294 m at 16 px, 472 m at 24). Every pixel counts, so it is not
   smoothed (the lines' 13 px window lifted its floor to 44 m at 0 px on the Alps). median (may
   be NULL): the same with the median at each distance (tn__gnn_quilt_lift). prof and median are
   untouched when the example has no line of that kind. mask, dist, near: W x H scratch. */
TN__INTERNAL tn_status tn__gnn_grow_ground(const tn_contour_set *example, const tn_image *dem, int kind, float *prof, float *median, uint8_t *mask,
                                           float *dist, int *near)
{
    const int P = TN__GNN_PROFILE;
    const size_t n = (size_t)dem->width * dem->height;
    tn_image mr = {0, 0, 0, NULL};
    double sum[TN__GNN_PROFILE + 1], cnt[TN__GNN_PROFILE + 1];
    float last = 0, sign = kind == TN_VALLEY ? 1.0f : -1.0f, *pairs = NULL; /* (distance, height above) per pixel, for the median */
    int d;
    size_t i, a, b, np = 0;
    tn_status st = tn__gnn_grow_mains(example, kind, dem->width, dem->height, &mr, mask, dist, near);
    if (st || !mr.data) return st;
    tn_image_free(&mr);
    if (median && !(pairs = (float *)tn__alloc(2 * n * sizeof(float)))) return TN_ERR_OUT_OF_MEMORY;
    memset(sum, 0, sizeof sum);
    memset(cnt, 0, sizeof cnt);
    for (i = 0; i < n; i++) {
        float h;
        if (near[i] < 0 || !(dist[i] < P + 0.5f)) continue;
        d = (int)(dist[i] + 0.5f);
        h = sign * (dem->data[i] - dem->data[near[i]]);
        sum[d] += h;
        cnt[d]++;
        if (pairs) pairs[2 * np] = (float)d, pairs[2 * np + 1] = h, np++;
    }
    for (d = 0; d <= P; d++) { /* distances no pixel reaches hold the last value; never falling back */
        if (cnt[d] > 0) last = fmaxf(last, (float)(sum[d] / cnt[d]));
        prof[d] = last;
    }
    if (!pairs) return TN_OK;
    qsort(pairs, np, 2 * sizeof(float), tn__gnn_pair_cmp);
    for (d = 0, a = 0, last = 0; d <= P; d++, a = b) {
        for (b = a; b < np && pairs[2 * b] == (float)d; b++) {}
        if (b > a) last = fmaxf(last, pairs[2 * (a + (b - a) / 2) + 1]);
        median[d] = last;
    }
    TN_FREE(pairs);
    return TN_OK;
}

/* The index of a drawn valley's lower end (its last point when both ends are as high): where it
   drains, the mouth it shares with the valley it joins. */
static int tn__gnn_low_end(const tn_contour *l) { return l->points[3 * (l->npoints - 1) + 2] <= l->points[2] ? l->npoints - 1 : 0; }

#define TN__GNN_WIDEN_MIN 0.6f /* a drawn valley's width factor at its head ... */
#define TN__GNN_WIDEN_MAX 1.6f /* ... and at most, at the mouth of a long network */

/* How wide each drawn valley's ground is, as a factor of the example's (its main valleys' profile,
   tn__gnn_grow_ground): a valley widens downstream as it drains more, so at each point of a user
   valley the factor is sqrt(A / mean A), clamped to TN__GNN_WIDEN_MIN .. MAX, where A is the length
   of drawn valley upstream of it: its own from its higher end, and the whole of every drawn valley
   whose lower end lies within 3 px of it upstream of that point (tributaries of tributaries too).
   The mean over the drawn valleys is the example's width. kv (width x height): the factor on the
   valleys' pixels (each point rounded), 1 elsewhere; into (drawn->count): the valley each drawn
   valley's lower end joins, -1 where none does (and for ridges). */
static tn_status tn__gnn_grow_widths(const tn_contour_set *drawn, int width, int height, float *kv, int *into)
{
    tn_contour_set dense, *user = &dense;
    const int nu = drawn->count;
    double *tot = (double *)tn__calloc((size_t)nu * sizeof(double)), *len = (double *)tn__calloc((size_t)nu * sizeof(double)), sum = 0, npt = 0;
    int *at = (int *)tn__alloc((size_t)nu * sizeof(int)), c, t, j, pass;
    size_t i, n = (size_t)width * height;
    tn_status st = TN_OK;
    for (i = 0; i < n; i++) kv[i] = 1;
    memset(&dense, 0, sizeof dense);
    for (c = 0; c < nu; c++) into[c] = -1;
    if (!tot || !len || !at) st = TN_ERR_OUT_OF_MEMORY;
    if (st || (st = tn_sketch_densify(&dense, drawn))) goto done; /* a factor on every pixel of the lines */
    for (c = 0; c < nu; c++) { /* each valley's length and where its lower end joins another */
        const tn_contour *l = &user->items[c];
        const float *e;
        double best = 9.0;
        if (l->type != TN_VALLEY || l->npoints < 2) continue;
        for (j = 1; j < l->npoints; j++) len[c] += hypot(l->points[3 * j] - l->points[3 * j - 3], l->points[3 * j + 1] - l->points[3 * j - 2]);
        e = l->points + 3 * tn__gnn_low_end(l);
        for (t = 0; t < nu; t++)
            for (j = 0; t != c && user->items[t].type == TN_VALLEY && j < user->items[t].npoints; j++) {
                double dx = e[0] - user->items[t].points[3 * j], dy = e[1] - user->items[t].points[3 * j + 1];
                if (dx * dx + dy * dy < best) best = dx * dx + dy * dy, into[c] = t, at[c] = j;
            }
    }
    for (pass = 0; pass < 4; pass++) /* a tributary brings everything above it: a few levels of branching */
        for (c = 0; c < nu; c++) {
            tot[c] = len[c];
            for (t = 0; t < nu; t++)
                if (into[t] == c) tot[c] += tot[t];
        }
    for (pass = 0; pass < 2 && (!pass || sum > 0); pass++) /* the mean of A, then the factors */
        for (c = 0; c < nu; c++) {
            const tn_contour *l = &user->items[c];
            int down = tn__gnn_low_end(l) > 0; /* from the head, the higher end */
            double s = 0;
            if (l->type != TN_VALLEY || l->npoints < 2) continue;
            for (j = 0; j < l->npoints; j++) {
                int q = down ? j : l->npoints - 1 - j, qp = down ? j - 1 : q + 1, X, Y;
                double A;
                if (j) s += hypot(l->points[3 * q] - l->points[3 * qp], l->points[3 * q + 1] - l->points[3 * qp + 1]);
                A = s;
                for (t = 0; t < nu; t++)
                    if (into[t] == c && (down ? at[t] <= q : at[t] >= q)) A += tot[t];
                if (!pass) {
                    sum += A, npt++;
                    continue;
                }
                X = (int)floorf(l->points[3 * q] + 0.5f), Y = (int)floorf(l->points[3 * q + 1] + 0.5f);
                if (X >= 0 && Y >= 0 && X < width && Y < height)
                    kv[(size_t)Y * width + X] = tn__clampf((float)sqrt(A / (sum / npt)), TN__GNN_WIDEN_MIN, TN__GNN_WIDEN_MAX);
            }
        }
done:
    tn_contour_set_free(&dense);
    TN_FREE(tot);
    TN_FREE(len);
    TN_FREE(at);
    return st;
}

/* v (width x height) replaced by its mean over the box of radius r around each pixel, clipped to
   the map. I: (width + 1) x (height + 1) scratch whose first row and column are zero (tn__calloc'd;
   tn__gnn_integral writes the rest). */
static void tn__gnn_box_mean(float *v, int width, int height, int r, double *I)
{
    int x, y;
    tn__gnn_integral(v, width, height, I);
    for (y = 0; y < height; y++)
        for (x = 0; x < width; x++) {
            double a, s = tn__gnn_box_sum(I, width, height, x, y, r, &a);
            v[(size_t)y * width + x] = (float)(s / a);
        }
}

#define TN__GNN_WIDTH_BLUR 12 /* px: radius of the two box means that smooth the width field */

/* The width factor of the nearest drawn valley pixel (kv at nearv; 1 where there is none) at
   every pixel, smoothed by two box means of TN__GNN_WIDTH_BLUR px into K: the nearest pixel
   jumps from one valley to another on the line halfway between them (and along one valley from
   one factor to the next), and the ground's rise read at it would step there with it. */
TN__INTERNAL tn_status tn__gnn_grow_width_field(const float *kv, const int *nearv, int width, int height, float *K)
{
    size_t p, n = (size_t)width * height;
    double *I = (double *)tn__calloc(((size_t)width + 1) * (height + 1) * sizeof(double));
    if (!I) return TN_ERR_OUT_OF_MEMORY;
    for (p = 0; p < n; p++) K[p] = nearv[p] >= 0 ? kv[nearv[p]] : 1.0f;
    tn__gnn_box_mean(K, width, height, TN__GNN_WIDTH_BLUR, I);
    tn__gnn_box_mean(K, width, height, TN__GNN_WIDTH_BLUR, I);
    TN_FREE(I);
    return TN_OK;
}

/* The minimum-error boundary cut of image quilting, on the blurred line types: in the block's left
   and top overlaps (mg px wide), the path (a column per row, a row per column, steps of at most
   1 px) along which the placed network and the new block's agree best; the new block covers the
   overlap from there on. Pasting only the block's core left every line cut at a 48 px grid, which
   the membrane showed as seams (curvature 2.5x the rest along them). cutc[v + mg] (cutr[u + mg]):
   the first new column (row) of row v (column u); E: (B + mg) x mg scratch. */
static void tn__gnn_grow_cut(const uint8_t *placed, const float *pbl, const float *ebl, int width, int height, int x0, int y0, int B, int mg,
                             int t, int ox, int oy, int Wx, int *cutc, int *cutr, double *E)
{
    const int S = B + 2 * mg, n = B + mg;
    int pass, a, b, k;
    for (pass = 0; pass < 2; pass++) { /* 0: the left seam, 1: the top one */
        int *cut = pass ? cutr : cutc, bb = 0;
        if (pass ? y0 == 0 : x0 == 0) { /* no overlap there: the map's edge */
            for (a = 0; a < n; a++) cut[a] = -mg;
            continue;
        }
        for (a = 0; a < n; a++)        /* along the seam */
            for (b = 0; b < mg; b++) { /* across it, in the overlap */
                int u = pass ? a - mg : b - mg, v = pass ? b - mg : a - mg, X = x0 + u, Y = y0 + v;
                double e = 0, best = a ? DBL_MAX : 0;
                if (X >= 0 && Y >= 0 && X < width && Y < height && placed[(size_t)Y * width + X]) {
                    float d = ebl[tn__gnn_grow_at(u + mg, v + mg, S, t, ox, oy, Wx)] - pbl[(size_t)(v + mg) * S + u + mg];
                    e = (double)d * d;
                }
                for (k = b - 1; a && k <= b + 1; k++)
                    if (k >= 0 && k < mg && E[(size_t)(a - 1) * mg + k] < best) best = E[(size_t)(a - 1) * mg + k];
                E[(size_t)a * mg + b] = e + best;
            }
        for (b = 1; b < mg; b++)
            if (E[(size_t)(n - 1) * mg + b] < E[(size_t)(n - 1) * mg + bb]) bb = b;
        for (a = n - 1; a >= 0; a--) { /* back along the cheapest path */
            int nb = bb;
            cut[a] = bb - mg;
            for (k = bb - 1; a && k <= bb + 1; k++)
                if (k >= 0 && k < mg && E[(size_t)(a - 1) * mg + k] < E[(size_t)(a - 1) * mg + nb]) nb = k;
            bb = nb;
        }
    }
}

#define TN__GNN_RELIEF_RADIUS 48     /* px: local relief is a height less the mean within this radius */
#define TN__GNN_QUILT_CANDIDATES 200 /* placements scored per block when heights are quilted too */
#define TN__GNN_QUILT_FEATHER 6      /* px past the height cut over which a block fades in (the cut keeps as many
                                        before the block's core, or the block steps up at its edge) */
#define TN__GNN_QUILT_MEAN 512       /* px: away from the strokes, the quilted heights lose their mean within this radius */
#define TN__GNN_FLANK 16             /* px across a drawn ridge that take the example's flanks; the quilted relief fades in over them */

/* With the example's heights (dem), the quilt carries them too: block (x0, y0) under placement
   (t, ox, oy) is offset by its mean height difference from the heights already placed (Q, where
   qset) on its overlap, so neighbours meet, and pasted from the path of least height difference
   across the overlap (tn__gnn_grow_cut on heights) but at least TN__GNN_QUILT_FEATHER px before the
   block's core, faded in over TN__GNN_QUILT_FEATHER px past it.
   pq: S x S, cutc, cutr: S, E: S x mg scratch. */
static void tn__gnn_quilt_heights(float *Q, uint8_t *qset, const tn_image *dem, int width, int height, int x0, int y0, int B, int mg,
                                  int t, int ox, int oy, float *pq, int *cutc, int *cutr, double *E)
{
    const int S = B + 2 * mg, Wx = dem->width;
    double so = 0;
    long no = 0;
    float off;
    int u, v;
    for (v = -mg; v < B + mg; v++)
        for (u = -mg; u < B + mg; u++) {
            int X = x0 + u, Y = y0 + v;
            if (X < 0 || Y < 0 || X >= width || Y >= height || !qset[(size_t)Y * width + X]) continue;
            so += Q[(size_t)Y * width + X] - dem->data[tn__gnn_grow_at(u + mg, v + mg, S, t, ox, oy, Wx)], no++;
        }
    off = no ? (float)(so / (double)no) : 0.0f;
    for (v = -mg; v < B + mg; v++) /* the placed heights in the block's frame, less the offset */
        for (u = -mg; u < B + mg; u++) {
            int X = x0 + u, Y = y0 + v;
            int in = X >= 0 && Y >= 0 && X < width && Y < height && qset[(size_t)Y * width + X];
            pq[(size_t)(v + mg) * S + u + mg] = in ? Q[(size_t)Y * width + X] - off : 0.0f;
        }
    tn__gnn_grow_cut(qset, pq, dem->data, width, height, x0, y0, B, mg, t, ox, oy, Wx, cutc, cutr, E);
    for (u = 0; u < S; u++) { /* room to fade in before the core */
        cutc[u] = cutc[u] < -TN__GNN_QUILT_FEATHER ? cutc[u] : -TN__GNN_QUILT_FEATHER;
        cutr[u] = cutr[u] < -TN__GNN_QUILT_FEATHER ? cutr[u] : -TN__GNN_QUILT_FEATHER;
    }
    for (v = -mg; v < B; v++)
        for (u = -mg; u < B; u++) {
            int X = x0 + u, Y = y0 + v;
            size_t p;
            float a = 1, h;
            if (X < 0 || Y < 0 || X >= width || Y >= height) continue;
            p = (size_t)Y * width + X;
            h = dem->data[tn__gnn_grow_at(u + mg, v + mg, S, t, ox, oy, Wx)] + off;
            if (u < 0) a = fminf(a, tn__clampf((float)(u - cutc[v + mg] + 1) / TN__GNN_QUILT_FEATHER, 0, 1));
            if (v < 0) a = fminf(a, tn__clampf((float)(v - cutr[u + mg] + 1) / TN__GNN_QUILT_FEATHER, 0, 1));
            Q[p] = qset[p] ? (1 - a) * Q[p] + a * h : h;
            qset[p] = 1;
        }
}

/* The quilted heights' relief: Q less its mean within TN__GNN_RELIEF_RADIUS px (its local relief,
   as the network's lines have theirs), plus, from TN__GNN_FALL_REACH px of the strokes on (D: px to
   the nearest), where their own fall ends, that mean less the one within TN__GNN_QUILT_MEAN px: so
   a mountainside keeps its tilt toward the main ridges (without it its spurs were hills) but does
   not sink a drawn valley below its ground (a slot along it). The whole fades in over
   TN__GNN_FLANK px from the drawn ridges (Dr: px to the nearest), where the example's flanks lie
   (tn__gnn_grow_flanks): a quilt that knows nothing of the ridge put full-depth gullies and knolls
   a few px from it, and the ridge stood as a thin fin on them. */
static tn_status tn__gnn_quilt_relief(const float *Q, const float *D, const float *Dr, int width, int height, float *prel)
{
    double *qs = (double *)tn__calloc(((size_t)width + 1) * (height + 1) * sizeof(double));
    int x, y;
    if (!qs) return TN_ERR_OUT_OF_MEMORY;
    tn__gnn_integral(Q, width, height, qs);
    for (y = 0; y < height; y++)
        for (x = 0; x < width; x++) {
            size_t p = (size_t)y * width + x;
            double a, A, loc = tn__gnn_box_sum(qs, width, height, x, y, TN__GNN_RELIEF_RADIUS, &a) / a;
            double far = tn__gnn_box_sum(qs, width, height, x, y, TN__GNN_QUILT_MEAN, &A) / A;
            float w = tn__clampf(D[p] / TN__GNN_FALL_REACH, 0, 1), k = tn__clampf(Dr[p] / TN__GNN_FLANK, 0, 1);
            w = w * w * (3 - 2 * w);
            prel[p] = (float)(Q[p] - loc + w * (loc - far)) * k * k * (3 - 2 * k);
        }
    TN_FREE(qs);
    return TN_OK;
}

#define TN__GNN_FALL_FINE 8        /* px: the relief is what two box means of this radius leave ... */
#define TN__GNN_FALL_GROUND 16     /* ... and the fall lines those of two box means of this radius */

/* The fine relief of h (width x height) into fine: h less two box means of TN__GNN_FALL_FINE px
   of it. I: tn__gnn_box_mean's scratch. */
static void tn__gnn_fine_relief(const float *h, int width, int height, double *I, float *fine)
{
    size_t i, n = (size_t)width * height;
    memcpy(fine, h, n * sizeof(float));
    tn__gnn_box_mean(fine, width, height, TN__GNN_FALL_FINE, I);
    tn__gnn_box_mean(fine, width, height, TN__GNN_FALL_FINE, I);
    for (i = 0; i < n; i++) fine[i] = h[i] - fine[i];
}

/* How far the relief of a DEM (one channel) runs down its slopes: the energy of the fine relief's
   gradient across the ground's fall lines over that along them, TN__GNN_FALL_GROUND px from the
   edge left out (1: no preference; a mountainside whose gullies and spurs run down it: 1.3 and
   more; 0 where the ground is flat or the DEM too small). The measure of bench_sketch's
   fall_ratio. */
TN__INTERNAL tn_status tn__gnn_fall_ratio(const tn_image *dem, double *ratio)
{
    const int W = dem->width, H = dem->height, E = TN__GNN_FALL_GROUND;
    size_t n = (size_t)W * H;
    float *fine = (float *)tn__alloc(n * sizeof(float)), *g = (float *)tn__alloc(n * sizeof(float));
    double *I = (double *)tn__calloc(((size_t)W + 1) * (H + 1) * sizeof(double)), across = 0, along = 0;
    int x, y;
    *ratio = 0;
    if (!fine || !g || !I) {
        TN_FREE(fine), TN_FREE(g), TN_FREE(I);
        return TN_ERR_OUT_OF_MEMORY;
    }
    tn__gnn_fine_relief(dem->data, W, H, I, fine);
    memcpy(g, dem->data, n * sizeof(float));
    tn__gnn_box_mean(g, W, H, TN__GNN_FALL_GROUND, I);
    tn__gnn_box_mean(g, W, H, TN__GNN_FALL_GROUND, I);
    for (y = E; y < H - E; y++)
        for (x = E; x < W - E; x++) {
            size_t q = (size_t)y * W + x;
            float dx = 0.5f * (g[q + 1] - g[q - 1]), dy = 0.5f * (g[q + W] - g[q - W]), m = sqrtf(dx * dx + dy * dy);
            float hx = fine[q + 1] - fine[q], hy = fine[q + W] - fine[q], pa, pc;
            if (!(m > 0)) continue;
            pa = (hx * dx + hy * dy) / m, pc = (hx * dy - hy * dx) / m;
            along += (double)pa * pa, across += (double)pc * pc;
        }
    if (along > 0) *ratio = across / along;
    TN_FREE(fine), TN_FREE(g), TN_FREE(I);
    return TN_OK;
}

#define TN__GNN_ERODE_STEPS 5      /* implicit stream-power steps */
#define TN__GNN_ERODE_K 1.0f       /* per step, for a channel draining the example's valley threshold */
#define TN__GNN_ERODE_SPREAD 2.5f  /* px: the Gaussian that spreads the depth (a channel takes its banks) */
#define TN__GNN_ERODE_FADE 8.0f    /* px: fades in from this many px off the drawn ridges to twice as many */
#define TN__GNN_ERODE_PASSES 16    /* passes that keep the steps within the example's steepest */
#define TN__GNN_ERODE_BISECT 12    /* bisections of the share of the fine relief that keeps the mean slope */

/* The drainage of ground T (width x height): a priority flood from the map's border and the
   drawn valleys (ur's valley channel), over the lowest saddle out of every basin. order: the
   pixels, each after the one it drains to (rcv; -1 at an outlet). */
static tn_status tn__gnn_erode_route(const float *T, const tn_image *ur, int width, int height, uint32_t *order, int32_t *rcv)
{
    const size_t n = (size_t)width * height;
    tn__pheap q = {NULL, 0, 0};
    float *F = (float *)tn__alloc(n * sizeof(float)); /* the level the flood reached each pixel at */
    uint8_t *seen = (uint8_t *)tn__calloc(n);
    uint64_t seq = 0;
    size_t i, k = 0;
    tn_status st = F && seen ? TN_OK : TN_ERR_OUT_OF_MEMORY;
    for (i = 0; !st && i < n; i++) {
        int x = (int)(i % (size_t)width), y = (int)(i / (size_t)width);
        if (x > 0 && y > 0 && x < width - 1 && y < height - 1 && !(ur->data[3 * i + 1] > 0)) continue;
        seen[i] = 1, rcv[i] = -1, F[i] = T[i];
        st = tn__pheap_push(&q, (uint64_t)tn__fkey(T[i]) << 32 | seq++, (uint32_t)i);
    }
    while (!st && q.n) {
        uint32_t c = tn__pheap_pop(&q);
        int x = (int)(c % (uint32_t)width), y = (int)(c / (uint32_t)width), d;
        order[k++] = c;
        for (d = 0; d < 8 && !st; d++) {
            int X = x + tn__d8x[d], Y = y + tn__d8y[d];
            size_t p = (size_t)Y * width + X;
            if (X < 0 || Y < 0 || X >= width || Y >= height || seen[p]) continue;
            seen[p] = 1, rcv[p] = (int32_t)c, F[p] = fmaxf(T[p], F[c]);
            st = tn__pheap_push(&q, (uint64_t)tn__fkey(F[p]) << 32 | seq++, (uint32_t)p);
        }
    }
    TN_FREE(q.a);
    TN_FREE(F);
    TN_FREE(seen);
    return st;
}

/* Depth d (width x height) dug into ground T lessened until no 4-neighbour step of T - d is
   steeper than the example's steepest (dem) or than T's own there (a few passes: each lessening
   can steepen a step beside it). */
static void tn__gnn_erode_guard_steps(const float *T, const tn_image *dem, int width, int height, float *d)
{
    float smax = 0;
    int x, y, pass, changed = 1;
    for (y = 0; y < dem->height; y++)
        for (x = 0; x < dem->width; x++) {
            const float *h = dem->data + (size_t)y * dem->width + x;
            if (x + 1 < dem->width) smax = fmaxf(smax, fabsf(h[1] - h[0]));
            if (y + 1 < dem->height) smax = fmaxf(smax, fabsf(h[dem->width] - h[0]));
        }
    for (pass = 0; changed && pass < TN__GNN_ERODE_PASSES; pass++)
        for (changed = 0, y = 0; y < height; y++)
            for (x = 0; x < width; x++) {
                size_t p = (size_t)y * width + x;
                int e;
                for (e = 0; e < 4; e++) {
                    int X = x + (e == 0) - (e == 1), Y = y + (e == 2) - (e == 3);
                    size_t q = (size_t)Y * width + X;
                    float lim, most;
                    if (X < 0 || Y < 0 || X >= width || Y >= height) continue;
                    lim = fmaxf(smax, T[q] - T[p]);
                    most = lim - T[q] + d[q] + T[p]; /* the depth at p that leaves the step from q at lim */
                    if (d[p] > most) d[p] = fmaxf(most, 0), changed = 1;
                }
            }
}

/* The mean gradient length (height per px, central differences, the border left out) of h - s d
   (d NULL: of h alone), width x height. */
static double tn__gnn_mean_slope(const float *h, const float *d, float s, int width, int height)
{
    double sum = 0;
    long m = 0;
    int x, y;
    for (y = 1; y < height - 1; y++)
        for (x = 1; x < width - 1; x++) {
            size_t p = (size_t)y * width + x;
            float gx = h[p + 1] - h[p - 1], gy = h[p + width] - h[p - width];
            if (d) gx -= s * (d[p + 1] - d[p - 1]), gy -= s * (d[p + width] - d[p - width]);
            sum += 0.5 * sqrt((double)gx * gx + (double)gy * gy), m++;
        }
    return m ? sum / (double)m : 0;
}

/* Eroded relief P (width x height) on ground G, its fine part (tn__gnn_fine_relief, as
   tn__gnn_fall_ratio splits a DEM) lessened by the least share
   that keeps the mean slope of G + P at most the example's (dem) or cap, whichever is more (none
   where that is not enough): digging channels steepens their banks, and ground as steep as the
   example's came out steeper than it. The coarser part, a spur's fall down its mountainside,
   stays. The mean slope is convex in the share, so the shares that keep it form an interval up
   to 1, bisected. */
static tn_status tn__gnn_erode_keep_slope(const float *G, float *P, const tn_image *dem, double cap, int width, int height)
{
    const size_t n = (size_t)width * height;
    float *h = (float *)tn__alloc(n * sizeof(float)), *f = (float *)tn__alloc(n * sizeof(float));
    double *I = (double *)tn__calloc(((size_t)width + 1) * (height + 1) * sizeof(double)), lo = 0, hi = 1;
    size_t i;
    int it;
    tn_status st = h && f && I ? TN_OK : TN_ERR_OUT_OF_MEMORY;
    if (st) goto done;
    tn__gnn_fine_relief(P, width, height, I, f);
    for (i = 0; i < n; i++) h[i] = G[i] + P[i];
    cap = fmax(cap, tn__gnn_mean_slope(dem->data, NULL, 0, dem->width, dem->height));
    if (tn__gnn_mean_slope(h, NULL, 0, width, height) <= cap || tn__gnn_mean_slope(h, f, 1, width, height) > cap) goto done;
    for (it = 0; it < TN__GNN_ERODE_BISECT; it++) { /* hi keeps the slope, lo does not */
        double mid = 0.5 * (lo + hi);
        if (tn__gnn_mean_slope(h, f, (float)mid, width, height) <= cap) hi = mid;
        else lo = mid;
    }
    for (i = 0; i < n; i++) P[i] -= (float)hi * f[i];
done:
    TN_FREE(h);
    TN_FREE(f);
    TN_FREE(I);
    return st;
}

/* The grown ground (ground + prel) eroded by its own drainage, so its gullies and spurs run down
   the slopes to the drawn valleys as the example's do (the quilt's relief lies every way). Routed
   by tn__gnn_erode_route, TN__GNN_ERODE_STEPS implicit stream-power steps (Braun & Willett 2013):
   each channel pixel (upstream area A >= Ac / 4, Ac the example's valley threshold; hillslopes and
   divides stay) moves F / (1 + F) of the way to its receiver, F = K (A / Ac)^0.5 / the step's
   length. The depth dug is softly capped at the example lines' mean local relief (uncapped, the
   trunks were cut down to their outlets), spread by a Gaussian of TN__GNN_ERODE_SPREAD px, faded
   in off the drawn ridges (Dr: px to the nearest; their flanks are the example's), scaled by mix,
   kept from steepening any 4-neighbour step past the example's steepest (dem) and from digging
   basins: nothing ends below the pixel it drains to unless it lay there already. prel is lowered
   by it, and its fine part then lessened so the eroded ground is no steeper on the mean than the
   example or than it was (tn__gnn_erode_keep_slope). */
TN__INTERNAL tn_status tn__gnn_quilt_erode(const float *ground, const tn_image *ur, const float *Dr, const tn_image *dem, int Ac, float relief,
                                           float mix, int width, int height, float *prel)
{
    const size_t n = (size_t)width * height;
    tn_image d = {0, 0, 0, NULL};
    float *T, *A;
    uint32_t *order;
    int32_t *rcv;
    size_t i, k;
    int s;
    tn_status st;
    if (!(mix > 0)) return TN_OK;
    T = (float *)tn__alloc(n * sizeof(float)), A = (float *)tn__alloc(n * sizeof(float));
    order = (uint32_t *)tn__alloc(n * sizeof(uint32_t)), rcv = (int32_t *)tn__alloc(n * sizeof(int32_t));
    st = T && A && order && rcv ? TN_OK : TN_ERR_OUT_OF_MEMORY;
    if (!st) st = tn_image_create(&d, width, height, 1);
    for (i = 0; !st && i < n; i++) T[i] = ground[i] + prel[i], A[i] = 1, d.data[i] = T[i];
    if (!st) st = tn__gnn_erode_route(T, ur, width, height, order, rcv);
    if (st) goto done;
    for (k = n; k-- > 0;)
        if (rcv[order[k]] >= 0) A[rcv[order[k]]] += A[order[k]];
    for (s = 0; s < TN__GNN_ERODE_STEPS; s++) /* d holds the eroded heights here */
        for (k = 0; k < n; k++) {
            size_t p = order[k];
            int32_t r = rcv[p];
            float F, hr;
            if (r < 0 || A[p] < 0.25f * (float)Ac || !(d.data[p] > (hr = d.data[r]))) continue;
            F = TN__GNN_ERODE_K * sqrtf(A[p] / (float)Ac);
            if ((size_t)r % (size_t)width != p % (size_t)width && (size_t)r / (size_t)width != p / (size_t)width) F *= 0.70710678f; /* a diagonal step */
            d.data[p] = (d.data[p] + F * hr) / (1 + F);
        }
    for (i = 0; i < n; i++) d.data[i] = relief * tanhf((T[i] - d.data[i]) / relief); /* now the depth */
    if ((st = tn_image_blur(&d, &d, TN__GNN_ERODE_SPREAD))) goto done;
    for (i = 0; i < n; i++) {
        float f = tn__clampf((Dr[i] - TN__GNN_ERODE_FADE) / TN__GNN_ERODE_FADE, 0, 1);
        d.data[i] = fmaxf(d.data[i], 0) * mix * f * f * (3 - 2 * f);
    }
    tn__gnn_erode_guard_steps(T, dem, width, height, d.data);
    for (k = 0; k < n; k++) { /* downstream first: no pixel below its receiver unless it lay there */
        size_t p = order[k];
        int32_t r = rcv[p];
        float h = T[p] - d.data[p];
        if (r >= 0 && h < T[r] - d.data[r]) d.data[p] = T[p] - fmaxf(h, fminf(T[p], T[r] - d.data[r]));
        prel[p] -= d.data[p];
    }
    st = tn__gnn_erode_keep_slope(ground, prel, dem, tn__gnn_mean_slope(T, NULL, 0, width, height), width, height);
done:
    tn_image_free(&d);
    TN_FREE(T);
    TN_FREE(A);
    TN_FREE(order);
    TN_FREE(rcv);
    return st;
}

/* img (one channel) replaced by its maximum within r px (a square) of each pixel. */
static tn_status tn__gnn_grow_max(tn_image *img, int r)
{
    int W = img->width, H = img->height, x, y, k;
    float *t = (float *)tn__alloc((size_t)W * H * sizeof(float));
    if (!t) return TN_ERR_OUT_OF_MEMORY;
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) {
            float v = -FLT_MAX;
            for (k = x - r < 0 ? 0 : x - r; k <= x + r && k < W; k++) v = fmaxf(v, img->data[(size_t)y * W + k]);
            t[(size_t)y * W + x] = v;
        }
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) {
            float v = -FLT_MAX;
            for (k = y - r < 0 ? 0 : y - r; k <= y + r && k < H; k++) v = fmaxf(v, t[(size_t)k * W + x]);
            img->data[(size_t)y * W + x] = v;
        }
    TN_FREE(t);
    return TN_OK;
}

#define TN__GNN_LIFT (TN__GNN_PROFILE / 2) /* px: the lift reads the ground's low-pass, two box means of this radius (its full reach) */
#define TN__GNN_LIFT_SEAM 3 /* px: ... and is itself smoothed by two box means of this radius */

/* How much of the lift pixel p takes (0 where none): those whose nearest drawn valley pixel is no
   open low end and lies within R px, at least dmin px away, in full within R0 px and fading out
   (smoothstep) by R. */
static float tn__gnn_lift_share(const float *Dv, const int *nearv, const uint8_t *end, size_t p, float dmin, float R0, float R)
{
    float w;
    if (nearv[p] < 0 || Dv[p] < dmin || Dv[p] >= R || end[nearv[p]]) return 0;
    w = tn__clampf((R - Dv[p]) / (R - R0), 0, 1);
    return w * w * (3 - 2 * w);
}

/* A drawn valley is the low ground around it. The quilt knows nothing of it: it laid the
   example's deeper valleys beside a drawn one and its ridges across it, and the drawn valley
   stood perched between banks forced up around it (a tube on a causeway). So where the grown
   ground's low-pass (ground, plus prel under two box means of TN__GNN_LIFT px) lies less than the
   example's median rise from its main valleys (floor, at the distance over the width factor K,
   tn__gnn_grow_width_field) above the nearest drawn valley pixel, prel is lifted by that
   shortfall: in full within TN__GNN_PROFILE / 2 px, fading out by TN__GNN_PROFILE. The low-pass
   is lifted, not the ground itself, so the quilt's gullies and spurs stay on the banks (those
   still below the drawn valley's own height rise to it: they closed basins); a lift
   by the shortfall's upper envelope instead (its max over some px) carried the steep shortfall of
   a bank falling the wrong way onto the valley, which then stood in a trench between walls.
   Not past a drawn valley's low end that meets no other drawn valley (into[c] < 0,
   tn__gnn_grow_widths): its outlet stays open. ur: the user's lines rasterised
   (tn_sketch_rasterise); Dv, nearv: the distance to the nearest user valley pixel and that pixel. */
static tn_status tn__gnn_quilt_lift(const tn_contour_set *user, const int *into, const tn_image *ur, const float *ground, const float *Dv,
                                    const int *nearv, const float *K, const float *floor, int width, int height, float *prel)
{
    const float R = TN__GNN_PROFILE, R0 = 0.5f * TN__GNN_PROFILE;
    size_t p, n = (size_t)width * height;
    int c, dx, dy;
    double *I = (double *)tn__calloc(((size_t)width + 1) * (height + 1) * sizeof(double));
    uint8_t *end = (uint8_t *)tn__calloc(n); /* the pixels around the open low ends */
    float *lp = (float *)tn__alloc(n * sizeof(float));
    if (!I || !end || !lp) {
        TN_FREE(I);
        TN_FREE(end);
        TN_FREE(lp);
        return TN_ERR_OUT_OF_MEMORY;
    }
    for (c = 0; c < user->count; c++) {
        const tn_contour *l = &user->items[c];
        const float *e;
        if (l->type != TN_VALLEY || l->npoints < 2 || into[c] >= 0) continue;
        e = l->points + 3 * tn__gnn_low_end(l);
        for (dy = -1; dy <= 1; dy++)
            for (dx = -1; dx <= 1; dx++) {
                int X = (int)(e[0] + 0.5f) + dx, Y = (int)(e[1] + 0.5f) + dy;
                if (X >= 0 && Y >= 0 && X < width && Y < height) end[(size_t)Y * width + X] = 1;
            }
    }
    memcpy(lp, prel, n * sizeof(float));
    tn__gnn_box_mean(lp, width, height, TN__GNN_LIFT, I);
    tn__gnn_box_mean(lp, width, height, TN__GNN_LIFT, I);
    for (p = 0; p < n; p++) {
        float s = tn__gnn_lift_share(Dv, nearv, end, p, 0, R0, R);
        lp[p] = s > 0 ? fmaxf((ur->data[3 * (size_t)nearv[p] + 2] + tn__gnn_grow_table(floor, Dv[p] / K[p]) - (ground[p] + lp[p])) * s, 0) : 0;
    }
    tn__gnn_box_mean(lp, width, height, TN__GNN_LIFT_SEAM, I); /* no step where the nearest valley pixel jumps, or at an open end */
    tn__gnn_box_mean(lp, width, height, TN__GNN_LIFT_SEAM, I);
    for (p = 0; p < n; p++) prel[p] += lp[p];
    for (p = 0; p < n; p++) { /* and the gullies left on the banks not below the drawn valley (they closed basins) */
        float s = tn__gnn_lift_share(Dv, nearv, end, p, 1, R0, R);
        lp[p] = s > 0 ? fmaxf((ur->data[3 * (size_t)nearv[p] + 2] - (ground[p] + prel[p])) * s, 0) : 0;
    }
    tn__gnn_box_mean(lp, width, height, TN__GNN_LIFT_SEAM, I);
    for (p = 0; p < n; p++) prel[p] += lp[p];
    TN_FREE(I);
    TN_FREE(end);
    TN_FREE(lp);
    return TN_OK;
}

/* The network of the grown ground: the quilted relief (prel) on the strokes' ground (ground: the
   membrane and the fall from the strokes), extracted as the example was (its threshold, from its
   Wx x Hx), so the lines lie where that terrain has its ridges and valleys (the quilted network's
   own lines meet the heights only inside each block). ptype = its lines (1 ridge, -1 valley, 0). */
static tn_status tn__gnn_quilt_network(const float *prel, const float *ground, int width, int height, int Wx, int Hx, int8_t *ptype)
{
    tn_image T = {0, 0, 0, NULL}, xr = {0, 0, 0, NULL};
    tn_extraction xe;
    tn_extract_opts eo;
    size_t i, n = (size_t)width * height;
    tn_status st = tn_image_create(&T, width, height, 1);
    if (st) return st;
    for (i = 0; i < n; i++) T.data[i] = ground[i] + prel[i];
    memset(&eo, 0, sizeof eo);
    eo.threshold = tn_extract_default_threshold(Wx, Hx);
    if (!(st = tn_extract(&xe, &T, &eo))) {
        if (!(st = tn_sketch_rasterise(&xr, &xe.contours, width, height)))
            for (i = 0; i < n; i++) ptype[i] = (int8_t)(xr.data[3 * i] > 0 ? 1 : xr.data[3 * i + 1] > 0 ? -1 : 0);
        tn_extraction_free(&xe);
    }
    tn_image_free(&xr);
    tn_image_free(&T);
    return st;
}

/* Whether a stroke is drawn on pixel p of ur (the strokes rasterised: ridge, valley, height). */
static int tn__gnn_on_stroke(const tn_image *ur, size_t p) { return ur->data[3 * p] > 0 || ur->data[3 * p + 1] > 0; }

/* The pixel of ur under point q (x, y, height) of a line, clamped into the map. */
static size_t tn__gnn_pixel_of(const tn_image *ur, const float *q)
{
    int x = (int)tn__clampf(q[0] + 0.5f, 0, (float)(ur->width - 1)), y = (int)tn__clampf(q[1] + 0.5f, 0, (float)(ur->height - 1));
    return (size_t)y * (size_t)ur->width + (size_t)x;
}

/* A straight run from the line's last point on to user pixel q of the ur raster (width px a row),
   its heights linear to the user line's there; it ends on the first user pixel it meets, at that
   pixel's height (the later line wins a pixel, and a user pixel keeps its height). */
static tn_status tn__gnn_grow_run_on(tn__pts *b, size_t q, const tn_image *ur, int width)
{
    float x = b->p[3 * (b->n - 1)], y = b->p[3 * (b->n - 1) + 1], h = b->p[3 * (b->n - 1) + 2];
    float qx = (float)(q % (size_t)width), qy = (float)(q / (size_t)width), hs = ur->data[3 * q + 2];
    int s, steps = (int)ceilf(fmaxf(fabsf(qx - x), fabsf(qy - y)));
    tn_status st = TN_OK;
    for (s = 1; !st && s <= steps; s++) {
        float f = (float)s / (float)steps, px = floorf(x + f * (qx - x) + 0.5f), py = floorf(y + f * (qy - y) + 0.5f);
        size_t p = (size_t)py * (size_t)width + (size_t)px;
        if (tn__gnn_on_stroke(ur, p)) return tn__pts_push(b, px, py, ur->data[3 * p + 2]);
        st = tn__pts_push(b, px, py, h + f * (hs - h));
    }
    return st;
}

/* An added line whose last point heads for a user line of its own kind within `reach` px runs on
   to it, as the example's network joins its lines: a spur up to a drawn crest, a tributary down
   to a drawn valley, rather than stopping at the gap (the drawn line then stood alone in a bare
   band). Its heights run linearly to the user line's there. b: the line's points (x, y, h). */
static tn_status tn__gnn_grow_join(tn__pts *b, int ridge, const tn_image *ur, const float *D, const int *near, int width, float reach)
{
    int n = b->n;
    size_t p, back, q;
    if (n < 5) return TN_OK;
    p = (size_t)b->p[3 * (n - 1) + 1] * (size_t)width + (size_t)b->p[3 * (n - 1)];
    back = (size_t)b->p[3 * (n - 5) + 1] * (size_t)width + (size_t)b->p[3 * (n - 5)];
    if (near[p] < 0 || !(D[p] < reach) || !(D[p] < D[back] - 1.5f)) return TN_OK; /* near, and heading for it */
    q = (size_t)near[p];
    if ((ur->data[3 * q] > 0) != ridge) return TN_OK;
    return tn__gnn_grow_run_on(b, q, ur, width);
}

static void tn__gnn_pts_reverse(tn__pts *b)
{
    int i, j, k;
    for (i = 0, j = b->n - 1; i < j; i++, j--)
        for (k = 0; k < 3; k++) {
            float t = b->p[3 * i + k];
            b->p[3 * i + k] = b->p[3 * j + k];
            b->p[3 * j + k] = t;
        }
}

/* Pits of the membrane, lowest first (ties by position). */
typedef struct tn__gnn_pit { float z; uint32_t cell; } tn__gnn_pit;

static int tn__gnn_pit_cmp(const void *a, const void *b)
{
    const tn__gnn_pit *p = (const tn__gnn_pit *)a, *q = (const tn__gnn_pit *)b;
    if (p->z != q->z) return p->z < q->z ? -1 : 1;
    return p->cell < q->cell ? -1 : p->cell > q->cell;
}

/* The share of a map's pixels that its depression filling raises by more than thr. */
static tn_status tn__gnn_pit_share(const tn_image *z, float thr, tn_image *filled, double *share)
{
    size_t i, n = (size_t)z->width * z->height, k = 0;
    tn_status st = tn_fill_depressions(filled, z);
    if (st) return st;
    for (i = 0; i < n; i++) k += filled->data[i] - z->data[i] > thr;
    *share = (double)k / (double)n;
    return TN_OK;
}

/* A drawn valley's low end in a closed basin of the membrane z (f: z filled; thr: the depth that
   counts) goes on as the example's valleys do, to lower ground: from the end, each step to the
   lowest of the pixels within 45 degrees of the stroke's last segment (a fixed heading: one that
   turns toward each step can run along the map's edge), falling by `step` per px from the end's
   height, until ground lies below it outside a basin, or the map's edge. (The flood's own path
   from such a pit runs back beside the drawn valley.) A user valley as low takes it (the path
   runs on to it); any other user line, met once the path is `gap` px off its end, leaves it out
   (*ok = 0). pts: the path (x, y, h), without the end; *cut: the most it cuts below the ground. */
static tn_status tn__gnn_drain_end(tn__pts *pts, const tn_contour *l, const tn_image *z, const tn_image *f, const tn_image *ur, const float *D,
                                   const int *unear, float gap, float step, float thr, float *cut, int *ok)
{
    const int W = z->width, H = z->height, n = l->npoints;
    const float *p = l->points, *e, *b;
    float hx, hy, len, L, ex, ey;
    int x, y, m;
    size_t k;
    tn_status st = TN_OK;
    if (tn__gnn_low_end(l) > 0) e = p + 3 * (n - 1), b = p + 3 * (n - 2);
    else e = p, b = p + 3;
    hx = e[0] - b[0], hy = e[1] - b[1], len = sqrtf(hx * hx + hy * hy);
    if (!(len > 0)) return TN_OK;
    hx /= len, hy /= len;
    ex = e[0], ey = e[1], L = e[2];
    x = (int)floorf(ex + 0.5f), y = (int)floorf(ey + 0.5f);
    if (x < 0 || y < 0 || x >= W || y >= H) return TN_OK;
    k = (size_t)y * W + x;
    if (!(f->data[k] - z->data[k] > thr)) return TN_OK;
    for (m = 0; !st && m < W + H; m++) {
        int d, best = -1, qx, qy;
        size_t q;
        float sx, sy, s, bz = 0;
        for (d = 0; d < 8; d++) {
            float dx = (float)tn__d8x[d], dy = (float)tn__d8y[d];
            qx = x + tn__d8x[d], qy = y + tn__d8y[d];
            if ((dx * hx + dy * hy) / sqrtf(dx * dx + dy * dy) < 0.7f) continue;
            if (qx < 0 || qy < 0 || qx >= W || qy >= H) return TN_OK; /* the map's edge */
            if (best < 0 || z->data[(size_t)qy * W + qx] < bz) best = d, bz = z->data[(size_t)qy * W + qx];
        }
        if (best < 0) return TN_OK;
        sx = (float)tn__d8x[best], sy = (float)tn__d8y[best], s = sqrtf(sx * sx + sy * sy);
        x += tn__d8x[best], y += tn__d8y[best];
        q = (size_t)y * W + x;
        L -= step * s;
        if (D[q] < gap && (x - ex) * (x - ex) + (y - ey) * (y - ey) > (gap + 1) * (gap + 1)) {
            size_t u = (size_t)unear[q];
            if (pts->n && ur->data[3 * u + 1] > 0 && ur->data[3 * u + 2] <= L) return tn__gnn_grow_run_on(pts, u, ur, W);
            *ok = 0;
            return TN_OK;
        }
        if (z->data[q] <= L && !(f->data[q] - z->data[q] > thr)) return tn__pts_push(pts, (float)x, (float)y, z->data[q]);
        *cut = fmaxf(*cut, z->data[q] - L);
        st = tn__pts_push(pts, (float)x, (float)y, L);
    }
    return st;
}

#define TN__GNN_DRAIN_CUT 0.25f /* of the example's range: the deepest a basin's path may cut (deeper, a straight gorge the example does not have) */

/* A drain path kept: its pixels marked in on (W px a row), appended to set as a valley. */
static tn_status tn__gnn_drain_add(tn_contour_set *set, size_t *cap, uint8_t *on, int W, const tn__pts *pts, int *drained)
{
    int m;
    for (m = 0; m < pts->n; m++) on[(size_t)pts->p[3 * m + 1] * W + (size_t)pts->p[3 * m]] = 1;
    (*drained)++;
    return tn__cset_add(set, cap, TN_VALLEY, 0, 0.0f, pts->p, pts->n);
}

/* Densified lines drain as the example's do. Blocks of the example's network, each with its own
   line heights, leave the valleys of neighbouring blocks unconnected: the membrane of the grown
   sketch then holds closed basins that the example's own network does not have, and the terrain
   looks like separate cones rather than ridges between valleys.
   When the grown membrane has more than (2 - erode) times the example's share of basins (its
   DEM's, given dem, else its network's membrane's; erode: how far the ground was eroded,
   tn__gnn_quilt_erode, whose gullies' lines the membrane spans with lakes), each basin's lowest
   point gets a valley down its outlet path (the flood's path over the lowest saddle, tn_flow_compute)
   to lower ground, falling by relief / 64 per px, and added ridges give way 2 px around it. Carving
   alone steepens the ground past the example's, so the basin's added valleys first rise halfway
   to its brim and the path starts there; a path that would cut deeper than TN__GNN_DRAIN_CUT of
   the example's range is left out (a crack across a smooth flank). A drawn valley's low end in a
   basin goes on out of it first, however deep (tn__gnn_drain_end); a basin's lowest point on a
   user line is otherwise left alone. A
   path that comes within `gap` of a user valley as low as itself runs on to it; one that meets
   any other user line is left out: a basin the user drew closed stays closed. Appends the valleys
   to set (nuser user lines first) and counts them in *drained. */
static tn_status tn__gnn_grow_drain(tn_contour_set *set, size_t *cap, int nuser, const tn_contour_set *example, const tn_image *dem,
                                    const tn_image *ur, const float *D, const int *unear, float gap, float relief, float erode, int *drained)
{
    const int W = set->width, H = set->height;
    const size_t n = (size_t)W * H;
    tn_image z = {0, 0, 0, NULL}, f = {0, 0, 0, NULL}, ze = {0, 0, 0, NULL}, fe = {0, 0, 0, NULL};
    tn_flow flow;
    tn_contour_set out;
    tn__gnn_pit *pit = NULL;
    tn__pts pts = {NULL, 0, 0};
    uint8_t *on = NULL;
    float *dc = NULL, thr, lo = FLT_MAX, hi = -FLT_MAX, step = relief / 64;
    int *near = NULL, c;
    size_t i, np = 0, ocap = 0;
    double share, share_ex;
    tn_status st;
    memset(&flow, 0, sizeof flow);
    memset(&out, 0, sizeof out);
    *drained = 0;
    if ((st = tn_gnn_membrane(&ze, example, example->width, example->height))) return st;
    for (i = 0; i < (size_t)ze.width * ze.height; i++) lo = fminf(lo, ze.data[i]), hi = fmaxf(hi, ze.data[i]);
    thr = 0.01f * (hi - lo);
    if (dem) { /* the example's own ground: its network's membrane holds basins between lines the DEM drains */
        float dlo, dhi;
        tn_image_range(&dlo, &dhi, dem);
        st = tn__gnn_pit_share(dem, 0.01f * (dhi - dlo), &fe, &share_ex);
    } else
        st = tn__gnn_pit_share(&ze, thr, &fe, &share_ex);
    if (st || (st = tn_gnn_membrane(&z, set, W, H)) || (st = tn__gnn_pit_share(&z, thr, &f, &share))) goto done;
    if (!(share > (2 - erode) * share_ex)) goto done;
    if ((st = tn_flow_compute(&flow, &z, 0))) goto done;
    pit = (tn__gnn_pit *)tn__alloc(n * sizeof(tn__gnn_pit));
    on = (uint8_t *)tn__calloc(n);
    if (!pit || !on) {
        st = TN_ERR_OUT_OF_MEMORY;
        goto done;
    }
    for (i = 0; i < n; i++) { /* a basin's lowest points: no lower neighbour, well below the filled level */
        int x = (int)(i % (size_t)W), y = (int)(i / (size_t)W), k, low = 0;
        if (!(f.data[i] - z.data[i] > thr)) continue;
        for (k = 0; k < 8 && !low; k++) {
            int qx = x + tn__d8x[k], qy = y + tn__d8y[k];
            low = qx >= 0 && qy >= 0 && qx < W && qy < H && z.data[(size_t)qy * W + qx] < z.data[i];
        }
        if (!low) pit[np].z = z.data[i], pit[np++].cell = (uint32_t)i;
    }
    qsort(pit, np, sizeof *pit, tn__gnn_pit_cmp);
    for (c = nuser; c < set->count; c++) { /* the added valleys in a basin rise halfway to its brim */
        tn_contour *l = &set->items[c];
        int a;
        for (a = 0; l->type == TN_VALLEY && a < l->npoints; a++) {
            size_t q = (size_t)l->points[3 * a + 1] * W + (size_t)l->points[3 * a];
            if (f.data[q] - z.data[q] > thr && !(ur->data[3 * q] > 0 || ur->data[3 * q + 1] > 0)) /* a join's end keeps the user's height */
                l->points[3 * a + 2] += 0.5f * (f.data[q] - z.data[q]);
        }
    }
    for (c = 0; c < nuser && !st; c++) { /* the drawn valleys' low ends go on out of their basins */
        const tn_contour *l = &set->items[c];
        float cut = 0;
        int ok = 1;
        if (l->type != TN_VALLEY || l->npoints < 2) continue;
        pts.n = 0;
        st = tn__gnn_drain_end(&pts, l, &z, &f, ur, D, unear, gap, step, thr, &cut, &ok);
        if (st || !ok || pts.n < 5 || !(cut > thr)) continue;
        if ((st = tn__gnn_drain_add(set, cap, on, W, &pts, drained))) goto done;
    }
    for (i = 0; i < np && !st; i++) {
        size_t k = pit[i].cell;
        float L = pit[i].z + 0.5f * (f.data[k] - pit[i].z), cut = 0;
        int ok = 1, m;
        if (on[k] || D[k] < gap) continue;
        pts.n = 0;
        st = tn__pts_push(&pts, (float)(k % (size_t)W), (float)(k / (size_t)W), L);
        for (m = 0; !st && m < W + H + (int)(n / 8) && flow.dir[k] != TN_FLOW_OUTLET; m++) {
            size_t q = (size_t)((ptrdiff_t)k + (ptrdiff_t)tn__d8y[flow.dir[k]] * W + tn__d8x[flow.dir[k]]);
            float zq = z.data[q];
            L -= step;
            if (D[q] < gap) { /* a user valley as low takes the flow (the path runs on to it); other user lines close the basin */
                size_t u = (size_t)unear[q];
                if (ur->data[3 * u + 1] > 0 && ur->data[3 * u + 2] <= L) st = tn__gnn_grow_run_on(&pts, u, ur, W);
                else ok = 0;
                break;
            }
            if (on[q] || zq <= L) { /* an earlier path, or lower ground: the end */
                if (!on[q] && f.data[q] - zq > thr) { /* lower, but still in the basin: follow it down */
                    L = fminf(L, zq + 0.5f * (f.data[q] - zq));
                    k = q;
                    st = tn__pts_push(&pts, (float)(q % (size_t)W), (float)(q / (size_t)W), L);
                    continue;
                }
                if (!on[q]) st = tn__pts_push(&pts, (float)(q % (size_t)W), (float)(q / (size_t)W), zq);
                break;
            }
            cut = fmaxf(cut, zq - L);
            k = q;
            st = tn__pts_push(&pts, (float)(q % (size_t)W), (float)(q / (size_t)W), L);
        }
        if (st || !ok || pts.n < 5 || !(cut > thr) || cut > TN__GNN_DRAIN_CUT * 100 * thr) continue;
        if ((st = tn__gnn_drain_add(set, cap, on, W, &pts, drained))) goto done;
    }
    if (st || !*drained) goto done;
    /* added ridges give way around the new valleys */
    dc = (float *)tn__alloc(n * sizeof(float));
    near = (int *)tn__alloc(n * sizeof(int));
    if (!dc || !near) {
        st = TN_ERR_OUT_OF_MEMORY;
        goto done;
    }
    tn__gnn_chamfer(on, W, H, dc, near);
    out.width = W;
    out.height = H;
    for (c = 0; c < set->count && !st; c++) {
        const tn_contour *l = &set->items[c];
        int a = 0, b;
        if (c < nuser || l->type != TN_RIDGE) {
            st = tn__cset_add(&out, &ocap, l->type, l->order, l->mean_gradient, l->points, l->npoints);
            continue;
        }
        while (a < l->npoints && !st) { /* the runs of points 2 px or more from every new valley */
            while (a < l->npoints && dc[(size_t)l->points[3 * a + 1] * W + (size_t)l->points[3 * a]] < 2) a++;
            for (b = a; b < l->npoints && !(dc[(size_t)l->points[3 * b + 1] * W + (size_t)l->points[3 * b]] < 2); b++) {}
            if (b - a >= 5) st = tn__cset_add(&out, &ocap, l->type, l->order, l->mean_gradient, l->points + 3 * a, b - a);
            a = b;
        }
    }
    if (!st) {
        tn_contour_set_free(set);
        *set = out;
        *cap = ocap;
        memset(&out, 0, sizeof out);
    }
done:
    tn_image_free(&z);
    tn_image_free(&f);
    tn_image_free(&ze);
    tn_image_free(&fe);
    tn_flow_free(&flow);
    tn_contour_set_free(&out);
    TN_FREE(pit);
    TN_FREE(on);
    TN_FREE(dc);
    TN_FREE(near);
    TN_FREE(pts.p);
    return st;
}

#define TN__GNN_SINK_REACH 24     /* px: the largest sink asked within this many px (a square's half side) ... */
#define TN__GNN_SINK_SPREAD 12.0f /* ... smoothed by a Gaussian of this many px ... */
#define TN__GNN_SINK_FADE 16.0f   /* ... fades in over this many px from half the drawn ridges' flanks (TN__GNN_FLANK / 2) */

#define TN__GNN_ROOM_RADIUS 16 /* px around a main ridge over which the example's ground may top it */

/* How far the example's own ground tops its main ridges (tn__gnn_grow_mains): at every main-ridge
   pixel, how far the highest ground within TN__GNN_ROOM_RADIUS px (farther than 4 px from the
   mains) rises above it, 0 where none does; the mean over them (0 without ridges). The ground:
   dem where given, else the example's lines (er, tn_sketch_rasterise). A canyon's or a fjord's
   main ridges stand over their ground (a few m), a dune field's ride on ground half its range
   above them: the drawn ridges are sunk under only as far as the example's own stand. Over 48 px
   a massif near the Alps example's main ridges gave them a third of the range (docs/gnn.md). */
static tn_status tn__gnn_grow_room(const tn_contour_set *example, const tn_image *er, const tn_image *dem, float *room)
{
    tn_image mr = {0, 0, 0, NULL};
    int W = er->width, H = er->height, x, y, u, v, R = TN__GNN_ROOM_RADIUS, *near = (int *)tn__alloc((size_t)W * H * sizeof(int));
    uint8_t *mask = (uint8_t *)tn__alloc((size_t)W * H);
    float *dist = (float *)tn__alloc((size_t)W * H * sizeof(float));
    double sum = 0;
    long n = 0;
    tn_status st = near && mask && dist ? TN_OK : TN_ERR_OUT_OF_MEMORY;
    *room = 0;
    if (!st) st = tn__gnn_grow_mains(example, TN_RIDGE, W, H, &mr, mask, dist, near);
    TN_FREE(near);
    TN_FREE(mask);
    if (st || !mr.data) {
        TN_FREE(dist);
        return st;
    }
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) {
            size_t p = (size_t)y * W + x;
            float h0, hi;
            if (!(mr.data[3 * p] > 0)) continue;
            h0 = hi = dem ? dem->data[p] : er->data[3 * p + 2];
            for (v = y - R < 0 ? -y : -R; v <= R && y + v < H; v++)
                for (u = x - R < 0 ? -x : -R; u <= R && x + u < W; u++) {
                    size_t q = (size_t)(y + v) * W + (size_t)(x + u);
                    if (u * u + v * v > R * R || dist[q] <= 4 || (!dem && !(er->data[3 * q] > 0 || er->data[3 * q + 1] > 0))) continue;
                    hi = fmaxf(hi, dem ? dem->data[q] : er->data[3 * q + 2]);
                }
            sum += hi - h0, n++;
        }
    tn_image_free(&mr);
    TN_FREE(dist);
    if (n) *room = (float)(sum / (double)n);
    return TN_OK;
}

/* The added lines (set's items from nuser on) sunk under the drawn ridges: a point above its
   nearest drawn ridge (nearr: its pixel in ur, Dr: px to it) by more than room (how far the
   example's own ground tops its main ridges, tn__gnn_grow_room) asks the ground there to sink by
   the excess; the largest ask within TN__GNN_SINK_REACH px, smoothed, sinks the ground as a
   whole, so it keeps its own relief (a point-wise cap left flat tops, a local sink pits), and
   fades in from the drawn ridges, whose flanks rise to them. Only where a drawn ridge is nearer
   than every drawn valley (Dv: px to the nearest), fading out toward the valleys: across a valley
   the ground is the other slope's, and a whole map sunk under one low ridge left the drawn
   valleys standing above it. Points on user pixels stay. Quilted high ground stood above a drawn
   ring or crest tens of px away, and the drawing no longer shaped the map (docs/gnn.md, stop 67). */
static tn_status tn__gnn_grow_sink(tn_contour_set *set, int nuser, const tn_image *ur, const int *nearr, const float *Dr, const float *Dv, float room)
{
    tn_image ask = {0, 0, 0, NULL};
    int W = ur->width, H = ur->height, c, j, pass;
    tn_status st;
    if ((st = tn_image_create(&ask, W, H, 1))) return st;
    for (pass = 0; pass < 2 && !st; pass++) {
        if (pass && ((st = tn__gnn_grow_max(&ask, TN__GNN_SINK_REACH)) || (st = tn_image_blur(&ask, &ask, TN__GNN_SINK_SPREAD)))) break;
        for (c = nuser; c < set->count; c++)
            for (j = 0; j < set->items[c].npoints; j++) {
                float *q = set->items[c].points + 3 * j, k, v;
                size_t p = tn__gnn_pixel_of(ur, q);
                if (tn__gnn_on_stroke(ur, p) || nearr[p] < 0 || Dv[p] <= Dr[p]) continue;
                if (!pass) ask.data[p] = fmaxf(ask.data[p], q[2] - ur->data[3 * (size_t)nearr[p] + 2] - room);
                else {
                    k = tn__clampf((Dr[p] - 0.5f * TN__GNN_FLANK) / TN__GNN_SINK_FADE, 0, 1);
                    v = tn__clampf((Dv[p] - Dr[p]) / TN__GNN_SINK_FADE, 0, 1);
                    q[2] -= ask.data[p] * k * k * (3 - 2 * k) * v * v * (3 - 2 * v);
                }
            }
    }
    tn_image_free(&ask);
    return st;
}

/* tn_gnn_grow, and *relief (may be NULL) = the example lines' mean local relief (example units),
   from which generation takes the least slope from a stroke to its banks; with dem, ground (width
   x height, may be NULL) = the grown ground the added lines are traced from (tn__gnn_ground_band). */
TN__INTERNAL tn_status tn__gnn_grow(const tn_contour_set *user, const tn_contour_set *example, const tn_image *dem, int width, int height,
                                    const tn_gnn_grow_opts *opts, tn_contour_set *out, int *added, float *relief_out, float *ground_out)
{
    tn_gnn_grow_opts o;
    tn_image ur = {0, 0, 0, NULL}, er = {0, 0, 0, NULL}, mem = {0, 0, 0, NULL};
    tn_contour_set set;
    tn__pts pts = {NULL, 0, 0};
    size_t n = (size_t)width * height, nx, i, cap = 0, nl = 0;
    int Wx, Hx, B, mg, S, bx, by, type, *near = NULL, c;
    int8_t *etype = NULL, *ptype = NULL;
    uint8_t *umask = NULL, *placed = NULL, *mask = NULL, *emask = NULL;
    float *D = NULL, *Dr = NULL, *Dv = NULL, *erel = NULL, *prel = NULL, *ebl = NULL, *pbl = NULL, near_slope = 0, relief = 0, room = 0, erode = 0;
    float pr[TN__GNN_PROFILE + 1], pv[TN__GNN_PROFILE + 1], pf[TN__GNN_PROFILE + 1], *kv = NULL, *K = NULL, elo = FLT_MAX, ehi = -FLT_MAX, band; /* the example's and strokes' heights; 10 % of the example's */
    int *nearv = NULL, *nearr = NULL, *into = NULL; /* into: the valley each user valley's lower end joins (tn__gnn_grow_widths) */
    int *cutc = NULL, *cutr = NULL;
    double *sum = NULL, *cnt = NULL, *cutE = NULL, rel_sum = 0;
    float *Q = NULL, *pq = NULL; /* with the example's heights: the quilted heights, a block's scratch */
    uint8_t *qset = NULL;
    tn_rng rng;
    tn_status st;
    TN_ASSERT(out);
    if (dem && (dem->width != example->width || dem->height != example->height)) dem = NULL;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    if (added) *added = 0;
    if (!user || user->count <= 0) return tn__fail(TN_ERR_EMPTY, "gnn grow: the sketch is empty");
    if ((st = tn__cset_check(user, "gnn grow"))) return st;
    if ((st = tn__cset_check(example, "gnn grow (example)"))) return st;
    if (user->width != width || user->height != height)
        return tn__fail(TN_ERR_SHAPE, "gnn grow: the sketch's canvas %d x %d is not the map's %d x %d", user->width, user->height, width, height);
    if (example->count <= 0 || example->width < 16 || example->height < 16)
        return tn__fail(TN_ERR_EMPTY, "gnn grow: the example network is empty or under 16 x 16");
    if (!(o.gap >= 0 && o.gap <= 1e4f) || o.block < 0 || o.candidates < 0 || o.candidates > 100000)
        return tn__fail(TN_ERR_INVALID_ARG, "gnn grow: bad option (gap %g, block %d, candidates %d)", (double)o.gap, o.block, o.candidates);
    if (o.gap == 0) o.gap = 4;
    if (!o.block) o.block = 48;
    if (!o.candidates) o.candidates = dem ? TN__GNN_QUILT_CANDIDATES : 48;
    if (dem) tn_image_range(&elo, &ehi, dem);
    else tn__cset_height_range(example, &elo, &ehi);
    band = 0.1f * (ehi - elo);
    tn__cset_height_range(user, &elo, &ehi); /* a drawing beyond the example's heights widens them (the band stays) */
    Wx = example->width;
    Hx = example->height;
    B = o.block;
    if (B + B / 2 > (Wx < Hx ? Wx : Hx)) B = (Wx < Hx ? Wx : Hx) * 2 / 3;
    mg = B / 4;
    S = B + 2 * mg;
    nx = (size_t)Wx * Hx;
    memset(&set, 0, sizeof set);
    set.width = width;
    set.height = height;
    if ((st = tn_sketch_rasterise(&ur, user, width, height)) || (st = tn_sketch_rasterise(&er, example, Wx, Hx)) ||
        (st = tn_gnn_membrane(&mem, user, width, height)))
        goto done;
    umask = (uint8_t *)tn__alloc(n);
    placed = (uint8_t *)tn__calloc(n);
    mask = (uint8_t *)tn__alloc(n);
    ptype = (int8_t *)tn__calloc(n);
    prel = (float *)tn__calloc(n * sizeof(float));
    D = (float *)tn__alloc(n * sizeof(float));
    near = (int *)tn__alloc(n * sizeof(int));
    nearv = (int *)tn__alloc(n * sizeof(int));
    nearr = (int *)tn__alloc(n * sizeof(int));
    kv = (float *)tn__alloc(n * sizeof(float));
    K = (float *)tn__alloc(n * sizeof(float));
    into = (int *)tn__alloc((size_t)user->count * sizeof(int));
    Dr = (float *)tn__alloc(n * sizeof(float));
    Dv = (float *)tn__alloc(n * sizeof(float));
    etype = (int8_t *)tn__alloc(nx);
    emask = (uint8_t *)tn__alloc(nx);
    erel = (float *)tn__alloc(nx * sizeof(float));
    sum = (double *)tn__calloc((nx + (size_t)Hx + (size_t)Wx + 2) * sizeof(double));
    cnt = (double *)tn__calloc((nx + (size_t)Hx + (size_t)Wx + 2) * sizeof(double));
    ebl = (float *)tn__alloc(nx * sizeof(float));
    pbl = (float *)tn__alloc((size_t)S * S * sizeof(float));
    cutc = (int *)tn__alloc((size_t)S * sizeof(int));
    cutr = (int *)tn__alloc((size_t)S * sizeof(int));
    cutE = (double *)tn__alloc((size_t)S * mg * sizeof(double));
    if (dem) {
        Q = (float *)tn__alloc(n * sizeof(float));
        qset = (uint8_t *)tn__calloc(n);
        pq = (float *)tn__alloc((size_t)S * S * sizeof(float));
    }
    if (!umask || !placed || !mask || !ptype || !prel || !D || !Dr || !Dv || !near || !etype || !emask || !erel || !sum || !cnt || !ebl || !pbl ||
        !cutc || !cutr || !cutE || !nearv || !nearr || !kv || !K || !into || (dem && (!Q || !qset || !pq))) {
        st = TN_ERR_OUT_OF_MEMORY;
        goto done;
    }
    for (type = 0; type < 2; type++) { /* the distance to the nearest user ridge, then valley (FLT_MAX: none) */
        for (i = 0; i < n; i++) umask[i] = (uint8_t)(ur.data[3 * i + (size_t)type] > 0);
        tn__gnn_chamfer(umask, width, height, type ? Dv : Dr, type ? nearv : nearr);
    }
    if ((st = tn__gnn_grow_widths(user, width, height, kv, into)) || (st = tn__gnn_grow_width_field(kv, nearv, width, height, K))) goto done;
    for (i = 0; i < n; i++) umask[i] = (uint8_t)(ur.data[3 * i] > 0 || ur.data[3 * i + 1] > 0);
    tn__gnn_chamfer(umask, width, height, D, near);
    /* the example: line types, each line pixel's height above the mean of the lines within R px
       (integral images of (Wx + 1) x (Hx + 1)) */
    {
        int x, y, R = TN__GNN_RELIEF_RADIUS, W1 = Wx + 1;
        size_t nline = 0;
        for (i = 0; i < nx; i++) {
            etype[i] = (int8_t)(er.data[3 * i] > 0 ? 1 : er.data[3 * i + 1] > 0 ? -1 : 0);
            emask[i] = (uint8_t)(etype[i] != 0);
        }
        for (y = 0; y < Hx; y++)
            for (x = 0; x < Wx; x++) {
                size_t q = (size_t)(y + 1) * W1 + x + 1, p = (size_t)y * Wx + x;
                sum[q] = (emask[p] ? er.data[3 * p + 2] : 0.0) + sum[q - 1] + sum[q - W1] - sum[q - W1 - 1];
                cnt[q] = (double)emask[p] + cnt[q - 1] + cnt[q - W1] - cnt[q - W1 - 1];
            }
        for (y = 0; y < Hx; y++)
            for (x = 0; x < Wx; x++) {
                size_t p = (size_t)y * Wx + x;
                double area, s = tn__gnn_box_sum(sum, Wx, Hx, x, y, R, &area), k = tn__gnn_box_sum(cnt, Wx, Hx, x, y, R, &area);
                erel[p] = emask[p] && k > 0 ? (float)(er.data[3 * p + 2] - s / k) : 0.0f;
                if (emask[p]) rel_sum += fabsf(erel[p]), nline++;
            }
        if (!nline) {
            st = tn__fail(TN_ERR_EMPTY, "gnn grow: the example network covers no pixel");
            goto done;
        }
        relief = (float)(rel_sum / (double)nline) + 1e-6f;
        near_slope = relief / 16; /* a third of the relief over the radius it is measured on (docs/gnn.md) */
    }
    { /* the ground's fall from the strokes: the example's own from its main lines (without lines of a kind:
         TN__GNN_FALL x relief over TN__GNN_FALL_REACH px) */
        float *edist = (float *)tn__alloc(nx * sizeof(float));
        int *enear = (int *)tn__alloc(nx * sizeof(int)), d;
        for (d = 0; d <= TN__GNN_PROFILE; d++) pr[d] = pv[d] = pf[d] = TN__GNN_FALL * relief * fminf((float)d / TN__GNN_FALL_REACH, 1.0f);
        if (!edist || !enear) st = TN_ERR_OUT_OF_MEMORY;
        if (!st) st = tn__gnn_grow_profile(example, &er, TN_RIDGE, pr, emask, edist, enear);
        if (!st && dem) st = tn__gnn_grow_ground(example, dem, TN_VALLEY, pv, pf, emask, edist, enear);
        else if (!st) st = tn__gnn_grow_profile(example, &er, TN_VALLEY, pv, emask, edist, enear);
        TN_FREE(edist);
        TN_FREE(enear);
        if (st) goto done;
    }
    (void)tn__gnn_grow_blur(NULL, etype, Wx, Hx, 0, 0, Wx, Hx, ebl);
    /* quilting: blocks in raster order, each the best of the candidates */
    tn_rng_seed(&rng, o.seed, 0x67726f77ULL);
    for (by = 0; by * B < height; by++)
        for (bx = 0; bx * B < width; bx++) {
            int x0 = bx * B, y0 = by * B, bt = 0, box = 0, boy = 0, u, v;
            double best = -DBL_MAX;
            int nl = tn__gnn_grow_blur(placed, ptype, width, height, x0 - mg, y0 - mg, S, S, pbl);
            for (c = 0; c < o.candidates; c++) {
                int t = (int)(tn_rng_u32(&rng) % 8u), ox = (int)(tn_rng_u32(&rng) % (uint32_t)(Wx - S + 1)),
                    oy = (int)(tn_rng_u32(&rng) % (uint32_t)(Hx - S + 1));
                double score = 0, sxy = 0, sxx = 0, syy = 0, dh = 0, dh2 = 0;
                long ndh = 0;
                for (v = -mg; v < B + mg; v++)
                    for (u = -mg; u < B + mg; u++) {
                        int X = x0 + u, Y = y0 + v, e;
                        size_t p, q;
                        if (X < 0 || Y < 0 || X >= width || Y >= height) continue;
                        p = (size_t)Y * width + X;
                        q = tn__gnn_grow_at(u + mg, v + mg, S, t, ox, oy, Wx);
                        e = etype[q];
                        if (D[p] <= o.gap && near[p] >= 0) { /* lie on the user's lines: same type near them */
                            int ut = ur.data[3 * (size_t)near[p]] > 0 ? 1 : -1;
                            score += e * ut;
                        }
                        if (placed[p]) { /* continue the earlier blocks: their lines, and heights where lines meet */
                            float a = ebl[q], b = pbl[(size_t)(v + mg) * S + u + mg];
                            sxy += a * b, sxx += a * a, syy += b * b;
                            if (e && e == ptype[p]) score -= fabsf(erel[q] - prel[p]) / relief;
                        }
                        if (Q && qset[p]) { /* and their heights, up to the offset that will make them meet */
                            double d = Q[p] - dem->data[q];
                            dh += d, dh2 += d * d, ndh++;
                        }
                    }
                if (sxx > 0 && syy > 0) score += nl * sxy / sqrt(sxx * syy);
                if (ndh) score -= nl * (dh2 / ndh - (dh / ndh) * (dh / ndh)) / ((double)relief * relief);
                if (score > best) best = score, bt = t, box = ox, boy = oy;
            }
            tn__gnn_grow_cut(placed, pbl, ebl, width, height, x0, y0, B, mg, bt, box, boy, Wx, cutc, cutr, cutE);
            for (v = -mg; v < B; v++)
                for (u = -mg; u < B; u++) {
                    int X = x0 + u, Y = y0 + v;
                    size_t p, q;
                    if (X < 0 || Y < 0 || X >= width || Y >= height || (u < 0 && u < cutc[v + mg]) || (v < 0 && v < cutr[u + mg])) continue;
                    p = (size_t)Y * width + X;
                    q = tn__gnn_grow_at(u + mg, v + mg, S, bt, box, boy, Wx);
                    placed[p] = 1;
                    ptype[p] = etype[q];
                    prel[p] = erel[q];
                }
            if (Q) tn__gnn_quilt_heights(Q, qset, dem, width, height, x0, y0, B, mg, bt, box, boy, pq, cutc, cutr, cutE);
        }
    if (dem) { /* the erosion, in as far as the example's own relief runs down its slopes */
        double fr;
        if ((st = tn__gnn_fall_ratio(dem, &fr))) goto done;
        erode = tn__clampf((float)(fr - 1) / 0.25f, 0, 1);
    }
    for (i = 0; i < n; i++) /* the strokes' ground: their membrane, and the fall from them */
        mem.data[i] += tn__gnn_grow_fall(Dr[i], nearv[i] >= 0 ? Dv[i] / K[i] : Dv[i], pr, pv);
    if (Q && ((st = tn__gnn_quilt_relief(Q, D, Dr, width, height, prel)) ||
              (st = tn__gnn_quilt_erode(mem.data, &ur, Dr, dem, tn_extract_default_threshold(Wx, Hx), relief, erode, width, height, prel)) ||
              (st = tn__gnn_quilt_lift(user, into, &ur, mem.data, Dv, nearv, K, pf, width, height, prel)) ||
              (st = tn__gnn_quilt_network(prel, mem.data, width, height, Wx, Hx, ptype))))
        goto done;
    if (Q && ground_out)
        for (i = 0; i < n; i++) ground_out[i] = mem.data[i] + prel[i];
    /* the user's lines first, then each type's added pixels away from them, thinned and traced */
    for (c = 0; c < user->count; c++) {
        const tn_contour *u = &user->items[c];
        if ((st = tn__cset_add(&set, &cap, u->type, u->order, u->mean_gradient, u->points, u->npoints))) goto done;
    }
    for (type = 0; type < 2; type++) {
        int want = type == TN_RIDGE ? 1 : -1, x, y, k;
        tn__trace t;
        size_t l;
        for (i = 0; i < n; i++) mask[i] = (uint8_t)(ptype[i] == want && D[i] >= o.gap);
        if ((st = tn_skeletonize(mask, width, height))) goto done;
        if (type == TN_RIDGE) /* the valleys give way where a block's seam put them next to a ridge */
            for (y = 0; y < height; y++)
                for (x = 0; x < width; x++) {
                    size_t p = (size_t)y * width + x;
                    if (!mask[p]) ptype[p] = (int8_t)(ptype[p] == 1 ? 0 : ptype[p]);
                    else
                        for (k = 0; k < 8; k++) {
                            int qx = x + tn__d8x[k], qy = y + tn__d8y[k];
                            if (qx >= 0 && qy >= 0 && qx < width && qy < height && ptype[(size_t)qy * width + qx] == -1)
                                ptype[(size_t)qy * width + qx] = 0;
                        }
                }
        if ((st = tn__trace_skeleton(mask, width, height, &t))) goto done;
        for (l = 0; !st && l < t.nlines; l++) {
            if (t.starts[l + 1] - t.starts[l] < 5) continue;
            pts.n = 0;
            for (k = 0; !st && (size_t)k < t.starts[l + 1] - t.starts[l]; k++) {
                size_t p = t.cells[t.starts[l] + (size_t)k];
                float h = mem.data[p] + prel[p], d = D[p];
                if (near[p] >= 0 && d < 4 * o.gap) { /* below a user ridge, above a user valley, released from 2 to 4 gaps */
                    float hs = ur.data[3 * (size_t)near[p] + 2], b, w = tn__clampf((d - 2 * o.gap) / (2 * o.gap), 0.0f, 1.0f);
                    b = ur.data[3 * (size_t)near[p]] > 0 ? fminf(h, hs - near_slope * d) : fmaxf(h, hs + near_slope * d);
                    h = w * h + (1 - w) * b;
                }
                st = tn__pts_push(&pts, (float)(p % (size_t)width), (float)(p / (size_t)width), h);
            }
            if (!st) st = tn__gnn_grow_join(&pts, type == TN_RIDGE, &ur, D, near, width, 3 * o.gap);
            tn__gnn_pts_reverse(&pts);
            if (!st) st = tn__gnn_grow_join(&pts, type == TN_RIDGE, &ur, D, near, width, 3 * o.gap);
            if (!st) st = tn__cset_add(&set, &cap, (tn_contour_type)type, 0, 0.0f, pts.p, pts.n);
            nl++;
        }
        tn__trace_free(&t);
        if (st) goto done;
    }
    if ((st = tn__gnn_grow_room(example, &er, dem, &room)) ||
        (st = tn__gnn_grow_sink(&set, user->count, &ur, nearr, Dr, Dv, room)))
        goto done;
    if ((st = tn__gnn_grow_drain(&set, &cap, user->count, example, dem, &ur, D, near, o.gap, relief, erode, &c))) goto done;
    nl = (size_t)(set.count - user->count);
    for (c = user->count; c < set.count; c++) /* within the example's heights, but where a line runs onto a user pixel */
        for (i = 0; i < (size_t)set.items[c].npoints; i++) {
            float *q = set.items[c].points + 3 * i;
            if (!tn__gnn_on_stroke(&ur, tn__gnn_pixel_of(&ur, q))) q[2] = tn__soft_limit(q[2], elo, ehi, band);
        }
done:
    tn_image_free(&ur);
    tn_image_free(&er);
    tn_image_free(&mem);
    TN_FREE(umask);
    TN_FREE(placed);
    TN_FREE(mask);
    TN_FREE(ptype);
    TN_FREE(prel);
    TN_FREE(D);
    TN_FREE(Dr);
    TN_FREE(Dv);
    TN_FREE(near);
    TN_FREE(nearv);
    TN_FREE(nearr);
    TN_FREE(kv);
    TN_FREE(K);
    TN_FREE(into);
    TN_FREE(etype);
    TN_FREE(emask);
    TN_FREE(erel);
    TN_FREE(sum);
    TN_FREE(cnt);
    TN_FREE(ebl);
    TN_FREE(pbl);
    TN_FREE(cutc);
    TN_FREE(cutr);
    TN_FREE(cutE);
    TN_FREE(Q);
    TN_FREE(qset);
    TN_FREE(pq);
    TN_FREE(pts.p);
    if (st) {
        tn_contour_set_free(&set);
        return st;
    }
    *out = set;
    if (added) *added = (int)nl;
    if (relief_out) *relief_out = relief;
    return TN_OK;
}

#define TN__GNN_FLANK_SPAN 6 /* points either side over which a line's normal is taken: a pixel chain's
                                staircase turns a shorter chord by up to 45 degrees, and 8 px across
                                that moves a strip's row along its line by 6 px */

/* Unit normal (nx, ny) at point i of n points (stride 2 floats at xy, or 3 with stride 3). */
static void tn__gnn_normal(const float *p, int stride, int n, int i, float *nx, float *ny)
{
    const int S = TN__GNN_FLANK_SPAN;
    int a = i - S < 0 ? 0 : i - S, b = i + S >= n ? n - 1 : i + S;
    float dx = p[stride * b] - p[stride * a], dy = p[stride * b + 1] - p[stride * a + 1], l = sqrtf(dx * dx + dy * dy);
    *nx = l > 0 ? -dy / l : 0;
    *ny = l > 0 ? dx / l : 0;
}

#define TN__GNN_CREST_HALF 8   /* px: an example line shorter than 2 x 8 + 1 px has no peak to give */
#define TN__GNN_CREST_CHUNK 32 /* px of relief copied at once from one example line */
#define TN__GNN_CREST_POOL 64  /* px: less of the example's main lines are not copied (one short
                                  line, copied again and again, drew a comb of spurs at its own
                                  period along a drawn ridge) */
#define TN__GNN_CREST_WIDE 256 /* px: lower orders join a pool shorter than this (8 chunks): a pool
                                  of two or three lines gave every drawn ridge the same few chunks */
#define TN__GNN_CREST_BLEND 8  /* px over which two copies cross-fade */
#define TN__GNN_CREST_FADE 16  /* px over which the relief fades in from another stroke */
#define TN__GNN_CREST_BEND 8.0f /* px: the sigma of the smooth path a main line's bends are taken against */

/* Heights along a polyline of n points (x, y, h) every px of its length into h (at most
   floor(length) + 1 values), and their places into xy (may be NULL); returns how many. */
static int tn__gnn_crest_sample(const float *p, int n, float *h, float *xy)
{
    int j, m = 0;
    float carry = 0;
    for (j = 1; j < n; j++) {
        float dx = p[3 * j] - p[3 * j - 3], dy = p[3 * j + 1] - p[3 * j - 2], sl = sqrtf(dx * dx + dy * dy), t;
        for (t = carry; t < sl; t += 1, m++) {
            h[m] = p[3 * j - 1] + (p[3 * j + 2] - p[3 * j - 1]) * t / sl;
            if (xy) xy[2 * m] = p[3 * j - 3] + dx * t / sl, xy[2 * m + 1] = p[3 * j - 2] + dy * t / sl;
        }
        carry = t - sl;
    }
    return m;
}

/* h[0..n) (backwards with rev) less its least-squares line into out: what lies above and below
   the trend, the trend being the sketch's. */
static void tn__gnn_crest_detrend(const float *h, int n, int rev, float *out)
{
    double xm = 0.5 * (n - 1), ym = 0, sxy = 0, sxx = 0, b;
    int i;
    for (i = 0; i < n; i++) out[i] = h[rev ? n - 1 - i : i], ym += out[i];
    ym /= n;
    for (i = 0; i < n; i++) sxy += (i - xm) * (out[i] - ym), sxx += (i - xm) * (i - xm);
    b = sxx > 0 ? sxy / sxx : 0;
    for (i = 0; i < n; i++) out[i] = (float)(out[i] - ym - b * (i - xm));
}

/* The RMS of h[0..n) less its least-squares line over windows of min(n, TN__GNN_CREST_CHUNK) px
   every TN__GNN_CREST_HALF px (what tn__gnn_crest_synth copies) into *s2, the windows' count into
   *nw; out: scratch of TN__GNN_CREST_CHUNK. */
static void tn__gnn_crest_rms(const float *h, int n, double *s2, int *nw, float *out)
{
    int w = n < TN__GNN_CREST_CHUNK ? n : TN__GNN_CREST_CHUNK, a, i;
    for (a = 0; a + w <= n; a += TN__GNN_CREST_HALF) {
        tn__gnn_crest_detrend(h + a, w, 0, out);
        for (i = 0; i < w; i++) *s2 += (double)out[i] * out[i] / w;
        ++*nw;
    }
}

/* The example's heights along its main lines of one kind (the highest Strahler order among
   them; parts that continue one another, an end beside the next one's start, are one line),
   sampled every px: the pool tn__gnn_grow_crest copies from. When those add up to less than
   TN__GNN_CREST_WIDE px the next orders down join, a whole order at a time, until the pool holds
   that much: a few short lines, copied again and again, drew a comb of spurs at their period. A
   lower order's lines are scaled by sc[k] = min(1, sqrt(the top order's relief / theirs)) (the
   RMS of tn__gnn_crest_rms): their relief meets the top order's halfway (geometric mean), so
   they vary the pool without raising its relief much (the Sahara's second order has 2.5 x its
   main ridges' relief: the two orders unscaled made its summit's heights miss by 15.8 %; the
   full ratio left its spectrum at 1.53 x). *pool (tn__alloc'd, NULL when empty, and when all
   orders together add up to less than TN__GNN_CREST_POOL px) holds *runs runs of at least
   2 x TN__GNN_CREST_HALF + 1 px, run k from offset off[k] (TN__GNN_CREST_MAX_RUNS at most) to
   off[k + 1], to be multiplied by sc[k]; grp[k] (grp may be NULL): its order; *xy (may be NULL;
   tn__alloc'd) their places. */
#define TN__GNN_CREST_MAX_RUNS 256
static tn_status tn__gnn_crest_pool(const tn_contour_set *example, int kind, float **pool, float **xy, int *off, float *sc, int *grp, int *runs)
{
    int c, top = -1, low = 0, ord, n = 0, np = 0, total = 0, nw, k0;
    float *pts = NULL, *h = NULL, *at = NULL, scr[TN__GNN_CREST_CHUNK];
    double s2, rel, rel_top = 0;
    tn_status st = TN_OK;
    *pool = NULL;
    *runs = 0;
    off[0] = 0;
    for (c = 0; c < example->count; c++)
        if ((int)example->items[c].type == kind) {
            if (example->items[c].order > top) top = example->items[c].order;
            total += example->items[c].npoints;
        }
    if (top < 0 || total == 0) return TN_OK;
    for (c = 0; c < example->count; c++)
        if ((int)example->items[c].type == kind && example->items[c].order < low) low = example->items[c].order;
    pts = (float *)tn__alloc((size_t)total * 3 * sizeof(float));
    h = (float *)tn__alloc((size_t)total * 2 * sizeof(float)); /* a chain's length is under 1.5 px a point */
    if (xy && !(at = (float *)tn__alloc((size_t)total * 4 * sizeof(float)))) st = TN_ERR_OUT_OF_MEMORY;
    if (!pts || !h) st = TN_ERR_OUT_OF_MEMORY;
    for (ord = top; !st && ord >= low && (ord == top || n < TN__GNN_CREST_WIDE); ord--) {
        k0 = *runs;
        np = 0;
        for (c = 0; c <= example->count; c++) {
            const tn_contour *l = c < example->count ? &example->items[c] : NULL;
            int main_line = l && (int)l->type == kind && l->order == ord, m;
            if (main_line && np > 0 && fabsf(l->points[0] - pts[3 * np - 3]) <= 1.5f && fabsf(l->points[1] - pts[3 * np - 2]) <= 1.5f) {
                memcpy(pts + 3 * np, l->points, (size_t)l->npoints * 3 * sizeof(float)); /* the chain goes on */
                np += l->npoints;
                continue;
            }
            m = np > 1 ? tn__gnn_crest_sample(pts, np, h + n, at ? at + 2 * n : NULL) : 0; /* the chain so far ends here */
            if (m > 2 * TN__GNN_CREST_HALF && *runs < TN__GNN_CREST_MAX_RUNS) {
                if (grp) grp[*runs] = ord;
                n += m;
                off[++*runs] = n;
            }
            np = 0;
            if (main_line) {
                memcpy(pts, l->points, (size_t)l->npoints * 3 * sizeof(float));
                np = l->npoints;
            }
        }
        for (c = k0, s2 = 0, nw = 0; c < *runs; c++) tn__gnn_crest_rms(h + off[c], off[c + 1] - off[c], &s2, &nw, scr);
        rel = nw ? sqrt(s2 / nw) : 0;
        for (c = k0; c < *runs; c++) sc[c] = ord < top && rel > 0 ? (float)fmin(1.0, sqrt(rel_top / rel)) : 1.0f;
        if (ord == top) rel_top = rel;
        if (!(rel_top > 0)) break; /* no main line of 2 x TN__GNN_CREST_HALF + 1 px (or a flat one): nothing to size the others by */
    }
    TN_FREE(pts);
    if (st || n < TN__GNN_CREST_POOL) {
        TN_FREE(h);
        TN_FREE(at);
        *runs = 0;
        return st;
    }
    *pool = h;
    if (xy) *xy = at;
    return TN_OK;
}

/* How far each px of the pool's lines (xy: their places, runs as in tn__gnn_crest_pool) lies
   beside its own path smoothed by a Gaussian of TN__GNN_CREST_BEND px (signed, along that path's
   normal) into bend: the line's small bends, which the user's smooth stroke has not. */
static void tn__gnn_crest_bends(const float *xy, const int *off, int runs, float *bend)
{
    const float sg = TN__GNN_CREST_BEND;
    const int reach = (int)(3 * sg);
    int k, i, j;
    for (k = 0; k < runs; k++)
        for (i = off[k]; i < off[k + 1]; i++) {
            double sx = 0, sy = 0, sw = 0, tx = 0, ty = 0, l;
            for (j = i - reach; j <= i + reach; j++) {
                double w, dw;
                if (j < off[k] || j >= off[k + 1]) continue;
                w = exp(-0.5 * (j - i) * (j - i) / (sg * sg));
                dw = w * (j - i); /* the smoothed path's tangent */
                sx += w * xy[2 * j], sy += w * xy[2 * j + 1], sw += w;
                tx += dw * (xy[2 * j] - xy[2 * i]), ty += dw * (xy[2 * j + 1] - xy[2 * i + 1]);
            }
            l = sqrt(tx * tx + ty * ty);
            bend[i] = l > 0 ? (float)(((xy[2 * i] - sx / sw) * -ty + (xy[2 * i + 1] - sy / sw) * tx) / l) : 0.0f;
        }
}

/* Relief along a line of m px into g (m x R, zeroed by the caller): chunks of TN__GNN_CREST_CHUNK
   px from random places of pool (R values a px: a strip across the example's line, or its heights
   alone), forwards or backwards (the sides of a strip swap), each row less its straight trend along
   the chunk (tn__gnn_crest_detrend), laid end to end and cross-faded at equal power over
   TN__GNN_CREST_BLEND px. w2 (m), col (2 x TN__GNN_CREST_CHUNK): scratch. */
static void tn__gnn_crest_synth(const float *pool, int R, const int *off, const float *sc, int runs, int m, tn_rng *rng, float *g, float *w2, float *col)
{
    const int C = TN__GNN_CREST_CHUNK, Bl = TN__GNN_CREST_BLEND;
    int at, i, r;
    memset(w2, 0, (size_t)m * sizeof(float));
    for (at = 0; at < m;) {
        uint32_t pick = tn_rng_below(rng, (uint32_t)off[runs]), rev = tn_rng_below(rng, 2);
        int k = 0, len_k, from;
        while (off[k + 1] <= (int)pick) k++;
        len_k = off[k + 1] - off[k] < C ? off[k + 1] - off[k] : C;
        from = (int)pick + len_k > off[k + 1] ? off[k + 1] - len_k : (int)pick;
        for (r = 0; r < R; r++) {
            for (i = 0; i < len_k; i++) col[C + i] = sc[k] * pool[(size_t)(from + i) * R + r];
            tn__gnn_crest_detrend(col + C, len_k, (int)rev, col);
            for (i = 0; i < len_k && at + i < m; i++) {
                float e = fminf(1.0f, fminf((float)(i + 1), (float)(len_k - i)) / (Bl + 1)); /* ramps at both ends */
                g[(size_t)(at + i) * R + (rev ? R - 1 - r : r)] += e * col[i];
                if (r == 0) w2[at + i] += e * e;
            }
        }
        at += len_k > Bl + 1 ? len_k - Bl : 1;
    }
    for (i = 0; i < m; i++)
        for (r = 0; r < R; r++) g[(size_t)i * R + r] = w2[i] > 0 ? g[(size_t)i * R + r] / sqrtf(w2[i]) : 0;
}

/* How much of the relief point j of the user's line c takes: none within 1.5 px of another of the
   first nuser lines, all from TN__GNN_CREST_FADE px on (a smoothstep), so strokes that meet keep
   one height. */
static float tn__gnn_crest_fade(const tn_contour_set *set, int nuser, int c, int j)
{
    const float *p = set->items[c].points + 3 * j;
    float dmin = FLT_MAX, f;
    int o, q;
    for (o = 0; o < nuser && o < set->count; o++)
        for (q = 0; o != c && q < set->items[o].npoints; q++) {
            float dx = set->items[o].points[3 * q] - p[0], dy = set->items[o].points[3 * q + 1] - p[1];
            dmin = fminf(dmin, dx * dx + dy * dy);
        }
    f = fminf(1.0f, fmaxf(0.0f, sqrtf(dmin) - 1.5f) / TN__GNN_CREST_FADE);
    return f * f * (3 - 2 * f);
}

/* g (a line's relief from tn__gnn_crest_synth) at s px along a line of len px; a closed line's
   closing stretch mixes in the relief past its end, so it closes on itself. */
static float tn__gnn_crest_at(const float *g, float s, float len, int closed)
{
    int a = (int)s, b;
    float r = g[a] + (s - (float)a) * (g[a + 1] - g[a]), t, e, r2;
    if (!closed || s >= TN__GNN_CREST_BLEND) return r;
    t = s / TN__GNN_CREST_BLEND, e = len + s, b = (int)e;
    r2 = g[b] + (e - (float)b) * (g[b + 1] - g[b]);
    return (t * r + (1 - t) * r2) / sqrtf(t * t + (1 - t) * (1 - t));
}

/* A drawn line of `kind` takes the example's along-line relief: the peaks and saddles of its main
   ridges (the floor's rises and falls along its main valleys), copied in chunks of
   TN__GNN_CREST_CHUNK px from random places of its main lines (tn__gnn_crest_pool), forwards or
   backwards, less each chunk's own straight trend, cross-faded at equal power over
   TN__GNN_CREST_BLEND px, and added to the asked heights. The sketch gives the trend along a
   stroke; a smooth one made a levee. Its path takes the main lines' bends the same way
   (tn__gnn_crest_bends), moved along its normal by at most TN__GNN_CREST_BEND_MAX px: a drawn
   curve kept its pen's smoothness and read as a thin line through the ground. Both fade in over
   TN__GNN_CREST_FADE px from every other stroke, so strokes that meet keep one place and height;
   a closed line closes on itself.
   set: lines drawn pixel by pixel (tn_sketch_densify), heights in the example's units; its first
   nuser lines are the user's. */
TN__INTERNAL tn_status tn__gnn_grow_crest(tn_contour_set *set, int nuser, const tn_contour_set *example, int kind, uint64_t seed)
{
    int off[TN__GNN_CREST_MAX_RUNS + 1], runs, c, j;
    float sc[TN__GNN_CREST_MAX_RUNS], one[TN__GNN_CREST_MAX_RUNS];
    float *pool = NULL, *xy = NULL, *bend = NULL, *g = NULL, *gb = NULL, *w2 = NULL, col[2 * TN__GNN_CREST_CHUNK];
    tn_rng rng, rngb;
    tn_status st = tn__gnn_crest_pool(example, kind, &pool, &xy, off, sc, NULL, &runs);
    if (st || !pool) return st;
    if (!(bend = (float *)tn__alloc((size_t)off[runs] * sizeof(float)))) st = TN_ERR_OUT_OF_MEMORY;
    if (!st) tn__gnn_crest_bends(xy, off, runs, bend);
    for (c = 0; c < runs; c++) one[c] = 1;
    tn_rng_seed(&rng, seed, 0x6372657374ULL + (uint64_t)kind);
    tn_rng_seed(&rngb, seed, 0x62656e64ULL + (uint64_t)kind);
    for (c = 0; !st && c < nuser && c < set->count; c++) {
        tn_contour *l = &set->items[c];
        float *p = l->points, len = 0, *s, *nrm;
        int n = l->npoints, closed, m;
        if ((int)l->type != kind || n < 2) continue;
        closed = n > 2 && fabsf(p[0] - p[3 * n - 3]) <= 1.5f && fabsf(p[1] - p[3 * n - 2]) <= 1.5f;
        s = (float *)tn__alloc((size_t)n * 3 * sizeof(float));
        if (!s) {
            st = TN_ERR_OUT_OF_MEMORY;
            break;
        }
        nrm = s + n;
        for (j = 0; j < n; j++) {
            if (j) len += sqrtf((p[3 * j] - p[3 * j - 3]) * (p[3 * j] - p[3 * j - 3]) + (p[3 * j + 1] - p[3 * j - 2]) * (p[3 * j + 1] - p[3 * j - 2]));
            s[j] = len;
            tn__gnn_normal(p, 3, n, j, &nrm[2 * j], &nrm[2 * j + 1]);
        }
        m = (int)len + TN__GNN_CREST_CHUNK + 2;
        g = (float *)tn__calloc((size_t)m * sizeof(float));
        gb = (float *)tn__calloc((size_t)m * sizeof(float));
        w2 = (float *)tn__alloc((size_t)m * sizeof(float));
        if (!g || !gb || !w2) st = TN_ERR_OUT_OF_MEMORY;
        if (!st) {
            tn__gnn_crest_synth(pool, 1, off, sc, runs, m, &rng, g, w2, col);
            tn__gnn_crest_synth(bend, 1, off, one, runs, m, &rngb, gb, w2, col);
        }
        for (j = 0; !st && j < n; j++) {
            float f = tn__gnn_crest_fade(set, nuser, c, j), b = f * tn__gnn_crest_at(gb, s[j], len, closed);
            p[3 * j + 2] += f * tn__gnn_crest_at(g, s[j], len, closed);
            b = TN__GNN_CREST_BEND_MAX * (float)tanh((double)b / TN__GNN_CREST_BEND_MAX); /* in double: tanhf differs between libms (the wasm's) */
            p[3 * j] += b * nrm[2 * j], p[3 * j + 1] += b * nrm[2 * j + 1];
        }
        TN_FREE(s);
        TN_FREE(g);
        TN_FREE(gb);
        TN_FREE(w2);
    }
    TN_FREE(pool);
    TN_FREE(xy);
    TN_FREE(bend);
    return st;
}

/* The flanks of the drawn ridges by example: field (W x H, the example's units, zero elsewhere)
   gets, within TN__GNN_FLANK px of a drawn ridge, what the example's main ridges have on their
   flanks: strips across them (heights at -16 .. 16 px along their normals, every px of their
   length), each offset's row less its straight trend along the chunk, copied in chunks along the
   drawn ridge as tn__gnn_grow_crest copies the crest, and read bilinearly at each pixel's place
   along and across the stroke (from its nearest stroke point). Nothing on the stroke (the crest has its own), full from 4 to 8 px, gone
   by 16 px; faded near other strokes as the crest is. dem: the example's heights. */
TN__INTERNAL tn_status tn__gnn_grow_flanks(const tn_contour_set *set, int nuser, const tn_contour_set *example, const tn_image *dem, uint64_t seed,
                                           float *field)
{
    const int T = TN__GNN_FLANK, R = 2 * TN__GNN_FLANK + 1;
    const int W = set->width, H = set->height;
    const size_t np = (size_t)W * H;
    int off[TN__GNN_CREST_MAX_RUNS + 1], grp[TN__GNN_CREST_MAX_RUNS], runs, c, j, i, k, r, npts = 0;
    float sc[TN__GNN_CREST_MAX_RUNS];
    float *pool = NULL, *xy = NULL, *strip = NULL, *row = NULL, **g = NULL, *dist = NULL, *fade = NULL, *sarc = NULL, *nrm = NULL, col[2 * TN__GNN_CREST_CHUNK];
    int *near = NULL, *ptc = NULL, *ptj = NULL, *idx = NULL;
    uint8_t *mask = NULL;
    double rel_top = 0;
    tn_rng rng;
    tn_status st;
    memset(field, 0, np * sizeof(float));
    if ((st = tn__gnn_crest_pool(example, TN_RIDGE, &pool, &xy, off, sc, grp, &runs)) || !pool) return st;
    for (c = 0; c < nuser && c < set->count; c++)
        if (set->items[c].type == TN_RIDGE) npts += set->items[c].npoints;
    strip = (float *)tn__alloc((size_t)off[runs] * R * sizeof(float));
    row = (float *)tn__alloc((size_t)off[runs] * sizeof(float));
    g = (float **)tn__calloc((size_t)(nuser > 0 ? nuser : 1) * sizeof(float *));
    dist = (float *)tn__alloc(np * sizeof(float));
    near = (int *)tn__alloc(np * sizeof(int));
    idx = (int *)tn__alloc(np * sizeof(int));
    mask = (uint8_t *)tn__calloc(np);
    ptc = (int *)tn__alloc((size_t)(npts + 1) * sizeof(int));
    ptj = (int *)tn__alloc((size_t)(npts + 1) * sizeof(int));
    fade = (float *)tn__alloc((size_t)(npts + 1) * sizeof(float));
    sarc = (float *)tn__alloc((size_t)(npts + 1) * sizeof(float));
    nrm = (float *)tn__alloc((size_t)(npts + 1) * 2 * sizeof(float));
    if (!strip || !row || !g || !dist || !near || !idx || !mask || !ptc || !ptj || !fade || !sarc || !nrm) {
        st = TN_ERR_OUT_OF_MEMORY;
        goto done;
    }
    for (k = 0; k < runs; k++) /* the strips across the example's main ridges */
        for (i = off[k]; i < off[k + 1]; i++) {
            float nx, ny;
            tn__gnn_normal(xy + 2 * (size_t)off[k], 2, off[k + 1] - off[k], i - off[k], &nx, &ny);
            for (r = 0; r < R; r++) strip[(size_t)i * R + r] = tn__sample_bilinear(dem, xy[2 * i] + (float)(r - T) * nx, xy[2 * i + 1] + (float)(r - T) * ny, 0);
        }
    for (k = 0; grp[runs - 1] != grp[0] && k < runs;) {
        /* lower orders joined the pool: their flanks meet the top order's halfway by the flanks'
           own relief (rows 4-8 px across, where the field is laid whole), as their crests do by
           the crests' (the Sahara's lower dune ridges have the rougher crests, not flanks) */
        double s2 = 0, rel;
        int k1 = k, nw = 0;
        while (k1 < runs && grp[k1] == grp[k]) k1++;
        for (j = k; j < k1; j++)
            for (r = 0; r < R; r++) {
                if (abs(r - T) < 4 || abs(r - T) > 8) continue;
                for (i = off[j]; i < off[j + 1]; i++) row[i - off[j]] = strip[(size_t)i * R + r];
                tn__gnn_crest_rms(row, off[j + 1] - off[j], &s2, &nw, col);
            }
        rel = nw ? sqrt(s2 / nw) : 0;
        for (j = k; j < k1; j++) sc[j] = k > 0 && rel > 0 ? (float)fmin(1.0, sqrt(rel_top / rel)) : 1.0f;
        if (k == 0) rel_top = rel;
        k = k1;
    }
    tn_rng_seed(&rng, seed, 0x666c616e6bULL);
    for (i = 0; i < (int)np; i++) idx[i] = -1;
    for (c = 0, k = 0; c < nuser && c < set->count; c++) {
        const tn_contour *l = &set->items[c];
        const float *p = l->points;
        float len = 0, *w2;
        int m, n = l->npoints;
        if (l->type != TN_RIDGE || n < 2) continue;
        for (j = 0; j < n; j++, k++) {
            int X = (int)floorf(p[3 * j] + 0.5f), Y = (int)floorf(p[3 * j + 1] + 0.5f);
            if (j) len += sqrtf((p[3 * j] - p[3 * j - 3]) * (p[3 * j] - p[3 * j - 3]) + (p[3 * j + 1] - p[3 * j - 2]) * (p[3 * j + 1] - p[3 * j - 2]));
            ptc[k] = c, ptj[k] = j, sarc[k] = len;
            tn__gnn_normal(p, 3, n, j, &nrm[2 * k], &nrm[2 * k + 1]);
            fade[k] = tn__gnn_crest_fade(set, nuser, c, j);
            if (X >= 0 && Y >= 0 && X < W && Y < H) {
                mask[(size_t)Y * W + X] = 1;
                idx[(size_t)Y * W + X] = k;
            }
        }
        m = (int)len + TN__GNN_CREST_CHUNK + 2;
        g[c] = (float *)tn__calloc((size_t)m * R * sizeof(float));
        w2 = (float *)tn__alloc((size_t)m * sizeof(float));
        if (g[c] && w2) tn__gnn_crest_synth(strip, R, off, sc, runs, m, &rng, g[c], w2, col);
        TN_FREE(w2);
        if (!g[c]) {
            st = TN_ERR_OUT_OF_MEMORY;
            goto done;
        }
    }
    tn__gnn_chamfer(mask, W, H, dist, near);
    for (i = 0; i < (int)np; i++) {
        float d = dist[i], t, s, a, b, fs, ft, *gr;
        int q = near[i] >= 0 ? idx[near[i]] : -1, si;
        if (q < 0 || !(d < (float)T)) continue;
        { /* across and along the line from its nearest point: the nearest pixel of a chain alone
             steps the along place by a px here and there, a streak across the flank each time */
            float ex = (float)(i % W) - set->items[ptc[q]].points[3 * ptj[q]], ey = (float)(i / W) - set->items[ptc[q]].points[3 * ptj[q] + 1];
            t = ex * nrm[2 * q] + ey * nrm[2 * q + 1];
            s = sarc[q] + ex * nrm[2 * q + 1] - ey * nrm[2 * q];
        }
        t = tn__clampf(t + (float)T, 0, (float)(R - 1) - 1e-3f);
        s = tn__clampf(s, 0, sarc[q] + (float)T);
        r = (int)t, si = (int)s, ft = t - (float)r, fs = s - (float)si;
        gr = g[ptc[q]] + (size_t)si * R + r;
        a = tn__clampf(d / 4, 0, 1);
        b = tn__clampf((d - 8) / 8, 0, 1);
        field[i] = a * a * (3 - 2 * a) * (1 - b * b * (3 - 2 * b)) * fade[q] *
                   ((1 - fs) * ((1 - ft) * gr[0] + ft * gr[1]) + fs * ((1 - ft) * gr[R] + ft * gr[R + 1]));
    }
done:
    for (c = 0; g && c < nuser; c++) TN_FREE(g[c]);
    TN_FREE(g);
    TN_FREE(pool);
    TN_FREE(xy);
    TN_FREE(strip);
    TN_FREE(row);
    TN_FREE(dist);
    TN_FREE(near);
    TN_FREE(idx);
    TN_FREE(mask);
    TN_FREE(ptc);
    TN_FREE(ptj);
    TN_FREE(fade);
    TN_FREE(sarc);
    TN_FREE(nrm);
    return st;
}

TN_API tn_status tn_gnn_grow(tn_contour_set *out, const tn_contour_set *user, const tn_contour_set *example, int width,
                             int height, const tn_gnn_grow_opts *opts, int *added)
{
    return tn__gnn_grow(user, example, NULL, width, height, opts, out, added, NULL, NULL);
}
#endif /* TN_NO_GNN */
