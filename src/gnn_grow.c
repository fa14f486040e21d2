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
   a user ridge and rising away from a user valley by twice the example's mean local relief over
   48 px (so a stroke stays the main line around it), plus the example line's own height above
   the mean of the example's lines within 48 px (its local relief; the quilting also matches
   these heights across the overlap),
   then, within 2 gaps of a user line (released by 4 gaps), kept below a user ridge and above a
   user valley (the nearest user line) by the example's mean local relief / 16 px per px. */
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
   Densify by example: image quilting of the example's extracted network between the user's
   lines (issue 30).
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

/* What the ground between the strokes takes from their kind: it falls away from a user ridge and
   rises away from a user valley, by `relief` x TN__GNN_FALL over TN__GNN_FALL_REACH px, so a stroke
   stays the main line around it rather than one line among the example's; between a ridge and a
   valley the two cancel (the membrane already slopes from one to the other). dr, dv: px to the
   nearest user ridge and valley, FLT_MAX when the drawing has none. */
static float tn__gnn_grow_fall(float dr, float dv, float relief)
{
    const float R = TN__GNN_FALL_REACH;
    float fr = dr < R ? dr / R : 1, fv = dv < R ? dv / R : 1, wr;
    if (dr == FLT_MAX && dv == FLT_MAX) return 0;
    if (dv == FLT_MAX) return -TN__GNN_FALL * relief * fr;
    if (dr == FLT_MAX) return TN__GNN_FALL * relief * fv;
    wr = dv / (dr + dv);
    return TN__GNN_FALL * relief * (fv * (1 - wr) - fr * wr);
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

/* An added line whose last point heads for a user line of its own kind within `reach` px runs on
   to it, as the example's network joins its lines: a spur up to a drawn crest, a tributary down
   to a drawn valley, rather than stopping at the gap (the drawn line then stood alone in a bare
   band). Its heights run linearly to the user line's there. b: the line's points (x, y, h). */
static tn_status tn__gnn_grow_join(tn__pts *b, int ridge, const tn_image *ur, const float *D, const int *near, int width, float reach)
{
    int n = b->n, s, steps;
    size_t p, back, q;
    float x, y, h, qx, qy, hs;
    tn_status st = TN_OK;
    if (n < 5) return TN_OK;
    x = b->p[3 * (n - 1)], y = b->p[3 * (n - 1) + 1], h = b->p[3 * (n - 1) + 2];
    p = (size_t)y * (size_t)width + (size_t)x;
    back = (size_t)b->p[3 * (n - 5) + 1] * (size_t)width + (size_t)b->p[3 * (n - 5)];
    if (near[p] < 0 || !(D[p] < reach) || !(D[p] < D[back] - 1.5f)) return TN_OK; /* near, and heading for it */
    q = (size_t)near[p];
    if ((ur->data[3 * q] > 0) != ridge) return TN_OK;
    qx = (float)(q % (size_t)width), qy = (float)(q / (size_t)width), hs = ur->data[3 * q + 2];
    steps = (int)ceilf(fmaxf(fabsf(qx - x), fabsf(qy - y)));
    for (s = 1; !st && s <= steps; s++) {
        float f = (float)s / (float)steps;
        st = tn__pts_push(b, floorf(x + f * (qx - x) + 0.5f), floorf(y + f * (qy - y) + 0.5f), h + f * (hs - h));
    }
    return st;
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

/* tn_gnn_grow, and *relief (may be NULL) = the example lines' mean local relief (example units),
   from which generation takes the least slope from a stroke to its banks. */
static tn_status tn__gnn_grow(const tn_contour_set *user, const tn_contour_set *example, int width, int height,
                              const tn_gnn_grow_opts *opts, tn_contour_set *out, int *added, float *relief_out)
{
    tn_gnn_grow_opts o;
    tn_image ur = {0, 0, 0, NULL}, er = {0, 0, 0, NULL}, mem = {0, 0, 0, NULL};
    tn_contour_set set;
    tn__pts pts = {NULL, 0, 0};
    size_t n = (size_t)width * height, nx, i, cap = 0, nl = 0;
    int Wx, Hx, B, mg, S, bx, by, type, *near = NULL, c;
    int8_t *etype = NULL, *ptype = NULL;
    uint8_t *umask = NULL, *placed = NULL, *mask = NULL, *emask = NULL;
    float *D = NULL, *Dr = NULL, *Dv = NULL, *erel = NULL, *prel = NULL, *ebl = NULL, *pbl = NULL, near_slope = 0, relief = 0;
    int *cutc = NULL, *cutr = NULL;
    double *sum = NULL, *cnt = NULL, *cutE = NULL, rel_sum = 0;
    tn_rng rng;
    tn_status st;
    TN_ASSERT(out);
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
    if (!o.candidates) o.candidates = 48;
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
    if (!umask || !placed || !mask || !ptype || !prel || !D || !Dr || !Dv || !near || !etype || !emask || !erel || !sum || !cnt || !ebl || !pbl ||
        !cutc || !cutr || !cutE) {
        st = TN_ERR_OUT_OF_MEMORY;
        goto done;
    }
    for (type = 0; type < 2; type++) { /* the distance to the nearest user ridge, then valley (FLT_MAX: none) */
        for (i = 0; i < n; i++) umask[i] = (uint8_t)(ur.data[3 * i + (size_t)type] > 0);
        tn__gnn_chamfer(umask, width, height, type ? Dv : Dr, near);
    }
    for (i = 0; i < n; i++) umask[i] = (uint8_t)(ur.data[3 * i] > 0 || ur.data[3 * i + 1] > 0);
    tn__gnn_chamfer(umask, width, height, D, near);
    /* the example: line types, each line pixel's height above the mean of the lines within R px
       (integral images of (Wx + 1) x (Hx + 1)) */
    {
        int x, y, R = 48, W1 = Wx + 1;
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
                int x0 = x - R < 0 ? 0 : x - R, y0 = y - R < 0 ? 0 : y - R, x1 = x + R + 1 > Wx ? Wx : x + R + 1, y1 = y + R + 1 > Hx ? Hx : y + R + 1;
                double s = sum[(size_t)y1 * W1 + x1] - sum[(size_t)y0 * W1 + x1] - sum[(size_t)y1 * W1 + x0] + sum[(size_t)y0 * W1 + x0];
                double k = cnt[(size_t)y1 * W1 + x1] - cnt[(size_t)y0 * W1 + x1] - cnt[(size_t)y1 * W1 + x0] + cnt[(size_t)y0 * W1 + x0];
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
                double score = 0, sxy = 0, sxx = 0, syy = 0;
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
                    }
                if (sxx > 0 && syy > 0) score += nl * sxy / sqrt(sxx * syy);
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
        }
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
                float h = mem.data[p] + tn__gnn_grow_fall(Dr[p], Dv[p], relief) + prel[p], d = D[p];
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

TN_API tn_status tn_gnn_grow(tn_contour_set *out, const tn_contour_set *user, const tn_contour_set *example, int width,
                             int height, const tn_gnn_grow_opts *opts, int *added)
{
    return tn__gnn_grow(user, example, width, height, opts, out, added, NULL);
}
#endif /* TN_NO_GNN */
