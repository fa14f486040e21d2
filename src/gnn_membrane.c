/* ============================================================================================
   (@@gnn, continued: the membrane)
   ============================================================================================ */
#ifndef TN_NO_GNN
/* The membrane baseline: heights fixed on the sketch's rasterised ridge and valley pixels
   (tn_sketch_rasterise), the discrete Laplace equation elsewhere (4 neighbours, no flux across
   the border), in the sketch's height units. *out (one channel) allocated here. */
TN_API tn_status tn_gnn_membrane(tn_image *out, const tn_contour_set *sketch, int width, int height);
#endif /* TN_NO_GNN */

/* --------------------------------------------------------------------------------------------
   >>gnn_membrane  (part of @@gnn implementation; goes after >>gnn, which calls it through
   prototypes, as it does >>gnn_grow)
   Membrane (Laplace) interpolation between a sketch's lines: the baseline the network adds its
   residual to, solved in blocks of bounded influence so that tiles equal the whole map.
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_GNN

/* out = val on fixed pixels; sum over 4-neighbours inside the map of (out_q - out_p) = 0 on the
   others (Neumann border). Conjugate gradients in double, preconditioned by one multigrid
   V-cycle: red-black Gauss-Seidel before and, in the reverse colour order, after (so the
   preconditioner is symmetric), bilinear prolongation P and restriction P^T, and on each coarser
   level the operator its 2 x 2 children's sum to, halved (the aggregation coarse operator, which
   equals P^T A P on a smooth field and keeps the pull of a fixed pixel that no coarse cell
   represents), down to a Cholesky solve on at most 64 cells. ~10 iterations on any size and any
   sketch, where Jacobi preconditioning took hundreds. Stops at the old Jacobi-scaled residual,
   1e-7 of the largest fixed value. Needs at least one fixed pixel (none: 0). Serial: the same
   result everywhere. Grids carry a ring of inactive cells, so no loop tests the border. */
#define TN__GNN_MG_COARSEST 64
#define TN__GNN_MG_LEVELS 40

typedef struct tn__gnn_mlevel {
    int w, h, s;                   /* size and row stride w + 2; cell (x, y) at (y + 1) s + x + 1 */
    float *diag, *idiag, *we, *ws; /* operator: diagonal and its inverse (0: no unknown), weight to the east and south cell */
    double *e, *f;                 /* the correction and its right-hand side */
} tn__gnn_mlevel;

typedef struct tn__gnn_mgrid {
    tn__gnn_mlevel lv[TN__GNN_MG_LEVELS];
    int nl, m;   /* levels; unknowns of the last */
    int *idx;    /* the last level's cell -> unknown, or -1 */
    double *chol; /* its Cholesky factor, m x m */
    double *tmp; /* m values, then the restriction's rows */
} tn__gnn_mgrid;

/* Row i of the operator's off-diagonal part applied to e: the weighted neighbours. */
#define TN__GNN_MG_NBRS(L, e, i) ((L)->we[(i) - 1] * (e)[(i) - 1] + (L)->we[i] * (e)[(i) + 1] + (L)->ws[(i) - (L)->s] * (e)[(i) - (L)->s] + (L)->ws[i] * (e)[(i) + (L)->s])

/* One Gauss-Seidel half sweep over the cells of one colour ((x + y) % 2). */
static void tn__gnn_mg_smooth(tn__gnn_mlevel *L, int colour)
{
    int x, y;
    for (y = 1; y <= L->h; y++)
        for (x = 1 + ((1 + y + colour) & 1); x <= L->w; x += 2) {
            size_t i = (size_t)y * L->s + x;
            L->e[i] = (L->f[i] + TN__GNN_MG_NBRS(L, L->e, i)) * L->idiag[i];
        }
}

/* C->f = P^T (L->f - A L->e). P: cell-centred bilinear, 3/4 of the parent and 1/4 of the next
   one out, or of the parent again at the border (the ring holds that copy, see the prolongation).
   Row by row: a fine row's residual (rr: w + 3 values from index -1, mirrored at the border as P
   copies), gathered along x, then added to its two coarse rows, the ring's folded back at the end. */
static void tn__gnn_mg_restrict(const tn__gnn_mlevel *L, tn__gnn_mlevel *C, double *rr)
{
    int x, y, X, wc = C->w;
    size_t c, nc = (size_t)C->s * (C->h + 2);
    double *t = rr + L->w + 3; /* the row gathered along x: wc values */
    memset(C->f, 0, nc * sizeof(double));
    for (y = 0; y < L->h; y++) {
        const size_t i0 = (size_t)(y + 1) * L->s + 1;
        double *fa = C->f + (size_t)(y / 2 + 1) * C->s + 1, *fb = fa + (y & 1 ? C->s : -C->s);
        for (x = 0; x < L->w; x++) {
            size_t i = i0 + x;
            rr[x + 1] = L->f[i] - L->diag[i] * L->e[i] + TN__GNN_MG_NBRS(L, L->e, i);
        }
        rr[0] = rr[1];
        rr[L->w + 1] = L->w & 1 ? 0 : rr[L->w];
        rr[L->w + 2] = 0;
        for (X = 0; X < wc; X++) t[X] = 0.75 * (rr[2 * X + 1] + rr[2 * X + 2]) + 0.25 * (rr[2 * X] + rr[2 * X + 3]);
        for (X = 0; X < wc; X++) {
            fa[X] += 0.75 * t[X];
            fb[X] += 0.25 * t[X];
        }
    }
    for (X = 1; X <= wc; X++) {
        C->f[C->s + X] += C->f[X];
        C->f[(size_t)C->h * C->s + X] += C->f[(size_t)(C->h + 1) * C->s + X];
    }
    for (c = 0; c < nc; c++) /* the ring and the cells without an unknown: 0, as their e */
        if (!(C->diag[c] > 0)) C->f[c] = 0;
}

/* L->e += P C->e (C->e is 0 where C has no unknown; L's cells without one are set to 0 again by
   the smoothing that follows). */
static void tn__gnn_mg_prolong(tn__gnn_mlevel *L, tn__gnn_mlevel *C)
{
    int x, y, X, Y;
    for (X = 1; X <= C->w; X++) { /* the ring: a copy of the border, rows then columns */
        C->e[X] = C->e[C->s + X];
        C->e[(size_t)(C->h + 1) * C->s + X] = C->e[(size_t)C->h * C->s + X];
    }
    for (Y = 0; Y < C->h + 2; Y++) {
        double *e = C->e + (size_t)Y * C->s;
        e[0] = e[1];
        e[C->w + 1] = e[C->w];
    }
    for (y = 0; y < L->h; y++) {
        const double *ea = C->e + (size_t)(y / 2 + 1) * C->s, *eb = ea + (y & 1 ? C->s : -C->s);
        for (x = 0; x < L->w; x++) {
            size_t i = (size_t)(y + 1) * L->s + x + 1;
            int a = x / 2 + 1, b = a - 1 + 2 * (x & 1);
            L->e[i] += (9 * ea[a] + 3 * (ea[b] + eb[a]) + eb[b]) * (1.0 / 16);
        }
    }
}

/* C's operator from L's: per 2 x 2 aggregate, its children's diagonals less twice the weights
   inside it, and the weights crossing to the next aggregate east and south; halved. */
static void tn__gnn_mg_coarsen(const tn__gnn_mlevel *L, tn__gnn_mlevel *C)
{
    int X, Y;
    for (Y = 1; Y <= C->h; Y++)
        for (X = 1; X <= C->w; X++) {
            size_t I = (size_t)Y * C->s + X, i = (size_t)(2 * Y - 1) * L->s + 2 * X - 1, j = i + L->s; /* children i, i + 1, j, j + 1 */
            double d = (double)L->diag[i] + L->diag[i + 1] + L->diag[j] + L->diag[j + 1] -
                       2.0 * ((double)L->we[i] + L->we[j] + L->ws[i] + L->ws[i + 1]);
            C->diag[I] = (float)(0.5 * d);
            C->idiag[I] = d > 0 ? (float)(2.0 / d) : 0.0f;
            C->we[I] = (float)(0.5 * ((double)L->we[i + 1] + L->we[j + 1]));
            C->ws[I] = (float)(0.5 * ((double)L->ws[j] + L->ws[j + 1]));
        }
}

/* The last level's operator on its m unknowns (idx: cell -> unknown or -1), Cholesky-factored
   into chol (m x m, lower). */
static void tn__gnn_mg_factor(const tn__gnn_mlevel *L, int *idx, double *chol, int *m)
{
    int n = L->s * (L->h + 2), i, j, k, M = 0;
    for (i = 0; i < n; i++) idx[i] = L->diag[i] > 0 ? M++ : -1;
    memset(chol, 0, (size_t)M * M * sizeof(double));
    for (i = 0; i < n; i++) {
        int a = idx[i];
        if (a < 0) continue;
        chol[(size_t)a * M + a] = L->diag[i];
        if (idx[i + 1] >= 0) chol[(size_t)idx[i + 1] * M + a] = -L->we[i];
        if (idx[i + L->s] >= 0) chol[(size_t)idx[i + L->s] * M + a] = -L->ws[i];
    }
    for (j = 0; j < M; j++) { /* the lower triangle holds the matrix, then its factor */
        double d = chol[(size_t)j * M + j];
        for (k = 0; k < j; k++) d -= chol[(size_t)j * M + k] * chol[(size_t)j * M + k];
        d = sqrt(d > 1e-300 ? d : 1e-300);
        chol[(size_t)j * M + j] = d;
        for (i = j + 1; i < M; i++) {
            double s = chol[(size_t)i * M + j];
            for (k = 0; k < j; k++) s -= chol[(size_t)i * M + k] * chol[(size_t)j * M + k];
            chol[(size_t)i * M + j] = s / d;
        }
    }
    *m = M;
}

/* L->e = L's operator^-1 L->f by the factor (tmp: m values). */
static void tn__gnn_mg_direct(tn__gnn_mlevel *L, const int *idx, const double *chol, int m, double *tmp)
{
    int n = L->s * (L->h + 2), i, k;
    for (i = 0; i < n; i++)
        if (idx[i] >= 0) tmp[idx[i]] = L->f[i];
    for (i = 0; i < m; i++) {
        double s = tmp[i];
        for (k = 0; k < i; k++) s -= chol[(size_t)i * m + k] * tmp[k];
        tmp[i] = s / chol[(size_t)i * m + i];
    }
    for (i = m - 1; i >= 0; i--) {
        double s = tmp[i];
        for (k = i + 1; k < m; k++) s -= chol[(size_t)k * m + i] * tmp[k];
        tmp[i] = s / chol[(size_t)i * m + i];
    }
    for (i = 0; i < n; i++) L->e[i] = idx[i] >= 0 ? tmp[idx[i]] : 0.0;
}

/* lv[0].e = one V-cycle applied to lv[0].f, from a zero guess. */
static void tn__gnn_mg_vcycle(tn__gnn_mgrid *G)
{
    tn__gnn_mlevel *lv = G->lv;
    int l, nl = G->nl;
    for (l = 0; l < nl - 1; l++) {
        memset(lv[l].e, 0, (size_t)lv[l].s * (lv[l].h + 2) * sizeof(double));
        tn__gnn_mg_smooth(&lv[l], 0);
        tn__gnn_mg_smooth(&lv[l], 1);
        tn__gnn_mg_restrict(&lv[l], &lv[l + 1], G->tmp + G->m);
    }
    tn__gnn_mg_direct(&lv[nl - 1], G->idx, G->chol, G->m, G->tmp);
    for (l = nl - 2; l >= 0; l--) {
        tn__gnn_mg_prolong(&lv[l], &lv[l + 1]);
        tn__gnn_mg_smooth(&lv[l], 1);
        tn__gnn_mg_smooth(&lv[l], 0);
    }
}

static void tn__gnn_mg_free(tn__gnn_mgrid *G)
{
    TN_FREE(G->lv[0].diag);
    TN_FREE(G->lv[1].e);
    TN_FREE(G->idx);
    TN_FREE(G->chol);
    memset(G, 0, sizeof *G);
}

/* The hierarchy of the W x H problem with these fixed pixels (at least one, not all); level 0's
   e and f are the caller's (padded like the grids). */
static tn_status tn__gnn_mg_make(const uint8_t *fixed, int W, int H, double *e0, double *f0, tn__gnn_mgrid *G)
{
    tn__gnn_mlevel *lv = G->lv;
    size_t cells = 0, coarse = 0, k;
    int l, px, py, nl, m;
    float *pw;
    double *pd;
    memset(G, 0, sizeof *G);
    /* the levels: halved (rounded up) down to at most TN__GNN_MG_COARSEST cells */
    lv[0].w = W;
    lv[0].h = H;
    for (nl = 1; nl < TN__GNN_MG_LEVELS && (size_t)lv[nl - 1].w * lv[nl - 1].h > TN__GNN_MG_COARSEST; nl++) {
        lv[nl].w = (lv[nl - 1].w + 1) / 2;
        lv[nl].h = (lv[nl - 1].h + 1) / 2;
    }
    for (l = 0; l < nl; l++) {
        lv[l].s = lv[l].w + 2;
        cells += (size_t)lv[l].s * (lv[l].h + 2);
        if (l) coarse += (size_t)lv[l].s * (lv[l].h + 2);
    }
    G->nl = nl;
    m = lv[nl - 1].s * (lv[nl - 1].h + 2);
    pw = (float *)tn__calloc(4 * cells * sizeof(float));
    pd = nl > 1 ? (double *)tn__calloc(2 * coarse * sizeof(double)) : NULL;
    G->idx = (int *)tn__alloc((size_t)m * sizeof(int));
    G->chol = (double *)tn__alloc(((size_t)m * m + (size_t)m + 2 * (size_t)W + 4) * sizeof(double));
    lv[0].diag = pw;
    lv[1].e = pd;
    if (!pw || (nl > 1 && !pd) || !G->idx || !G->chol) {
        tn__gnn_mg_free(G);
        return TN_ERR_OUT_OF_MEMORY;
    }
    G->tmp = G->chol + (size_t)m * m;
    for (l = 0; l < nl; l++) {
        size_t c = (size_t)lv[l].s * (lv[l].h + 2);
        lv[l].diag = pw;
        lv[l].idiag = pw + c;
        lv[l].we = pw + 2 * c;
        lv[l].ws = pw + 3 * c;
        pw += 4 * c;
        lv[l].e = l ? pd : e0;
        lv[l].f = l ? pd + c : f0;
        if (l) pd += 2 * c;
    }
    /* level 0: a free pixel's diagonal counts its neighbours in the map, the fixed ones too (their
       values are the right-hand side); the weights join free pixels */
    for (py = 0; py < H; py++)
        for (px = 0; px < W; px++) {
            size_t p = (size_t)py * W + px;
            k = (size_t)(py + 1) * lv[0].s + px + 1;
            if (fixed[p]) continue;
            lv[0].diag[k] = (float)((px > 0) + (px < W - 1) + (py > 0) + (py < H - 1));
            lv[0].idiag[k] = 1.0f / lv[0].diag[k];
            lv[0].we[k] = px < W - 1 && !fixed[p + 1] ? 1.0f : 0.0f;
            lv[0].ws[k] = py < H - 1 && !fixed[p + W] ? 1.0f : 0.0f;
        }
    for (l = 1; l < nl; l++) tn__gnn_mg_coarsen(&lv[l - 1], &lv[l]);
    tn__gnn_mg_factor(&lv[nl - 1], G->idx, G->chol, &G->m);
    return TN_OK;
}

TN__INTERNAL tn_status tn__gnn_membrane_solve(const float *val, const uint8_t *fixed, int W, int H, float *out)
{
    tn__gnn_mgrid G;
    const tn__gnn_mlevel *L = &G.lv[0];
    size_t n = (size_t)W * H, n0 = (size_t)(W + 2) * (H + 2), s = (size_t)W + 2, i, nf = 0;
    double *x, *r, *d, *q, mean = 0, scale = 0, tol, rz, rjac = 0;
    int it, px, py;
    tn_status st;
    for (i = 0; i < n; i++)
        if (fixed[i]) {
            nf++;
            mean += val[i];
            if (fabs((double)val[i]) > scale) scale = fabs((double)val[i]);
        }
    if (nf == 0 || nf == n) { /* nothing holds it, or nothing to solve */
        for (i = 0; i < n; i++) out[i] = fixed[i] ? val[i] : 0.0f;
        return TN_OK;
    }
    mean /= (double)nf;
    /* x, the residual r, the search direction d, and q: A d, then the V-cycle's output */
    if (!(x = (double *)tn__calloc(4 * n0 * sizeof(double)))) return TN_ERR_OUT_OF_MEMORY;
    r = x + n0;
    d = r + n0;
    q = d + n0;
    if ((st = tn__gnn_mg_make(fixed, W, H, q, r, &G))) {
        TN_FREE(x);
        return st;
    }
    /* x0: the mean of the fixed values; r = b - A x on free pixels (the Laplacian of x) */
    for (py = 0; py < H; py++)
        for (px = 0; px < W; px++) x[(py + 1) * s + px + 1] = fixed[(size_t)py * W + px] ? (double)val[(size_t)py * W + px] : mean;
    for (py = 0; py < H; py++)
        for (px = 0; px < W; px++) {
            size_t k = (py + 1) * s + px + 1;
            double v = 0;
            if (!(L->diag[k] > 0)) continue;
            if (px > 0) v += x[k - 1] - x[k];
            if (px < W - 1) v += x[k + 1] - x[k];
            if (py > 0) v += x[k - s] - x[k];
            if (py < H - 1) v += x[k + s] - x[k];
            r[k] = v;
            rjac += v * v * L->idiag[k];
        }
    tol = 1e-7 * (scale > 1e-30 ? scale : 1.0);
    tol = tol * tol * (double)n;
    tn__gnn_mg_vcycle(&G);
    rz = 0;
    for (i = 0; i < n0; i++) {
        d[i] = q[i];
        rz += r[i] * q[i];
    }
    for (it = 0; it < 200 && rjac > tol && rz > 0; it++) {
        double dq = 0, alpha, rz2 = 0, beta;
        for (i = s + 1; i < n0 - s - 1; i++) {
            q[i] = L->diag[i] * d[i] - TN__GNN_MG_NBRS(L, d, i);
            dq += d[i] * q[i];
        }
        if (!(dq > 0)) break;
        alpha = rz / dq;
        rjac = 0;
        for (i = 0; i < n0; i++) {
            x[i] += alpha * d[i];
            r[i] -= alpha * q[i];
            rjac += r[i] * r[i] * L->idiag[i];
        }
        if (rjac <= tol) break;
        tn__gnn_mg_vcycle(&G);
        for (i = 0; i < n0; i++) rz2 += r[i] * q[i];
        beta = rz2 / rz;
        rz = rz2;
        for (i = 0; i < n0; i++) d[i] = q[i] + beta * d[i];
    }
    for (py = 0; py < H; py++)
        for (px = 0; px < W; px++) out[(size_t)py * W + px] = (float)x[(py + 1) * s + px + 1];
    tn__gnn_mg_free(&G);
    TN_FREE(x);
    return TN_OK;
}
#undef TN__GNN_MG_NBRS

/* The membrane with bounded influence, so that a window of a map can be computed alone (tiled
   generation): the map is cut into blocks of B = 128 px; each block's membrane is solved on the
   block grown by a halo of 64 px (clipped to the map; doubled while it holds no sketch pixel), and
   a pixel blends the solutions of the 4 blocks around it by its distance to their centres (a
   smoothstep each way), so the result is continuous and a block keeps only itself and half a
   block around it. A domain of more than TN__GNN_MSOLVE pixels, a block far from every stroke,
   is solved on a grid coarsened by 2, 4, ... (a cell fixed at the mean of its sketch pixels) and
   interpolated: what it keeps holds no sketch pixel and is smooth, and the cost of a block stays
   bounded on any map. Maps whose every block would see the whole map (up to 128 + 64 px a side,
   the training crops) take one plain solve: the global membrane. */
#define TN__GNN_MB 128
#define TN__GNN_MHALO 64
#define TN__GNN_MSOLVE (256 * 256)

typedef struct tn__gnn_mblock {
    int x0, y0, w, h;         /* solved domain */
    int sx, sy, sw, sh;       /* kept: the block and B / 2 around it (what the blend reads) */
    float *sol;               /* sw x sh */
    tn_status st;
} tn__gnn_mblock;

typedef struct tn__gnn_mjob {
    const float *val;
    const uint8_t *fixed;
    int W, H;
    tn__gnn_mblock *b;
} tn__gnn_mjob;

/* Block B's domain (x0, y0, w, h) as a grid of cells of c x c px: v, f (cw x ch) the mean of the
   fixed values in a cell and whether it holds one; cnt: cw x ch scratch. */
static void tn__gnn_mblock_cells(const tn__gnn_mjob *J, const tn__gnn_mblock *B, int c, int cw, float *v, uint8_t *f, int *cnt)
{
    int x, y;
    size_t i, nc = (size_t)cw * ((B->h + c - 1) / c);
    for (i = 0; i < nc; i++) v[i] = 0, cnt[i] = 0;
    for (y = 0; y < B->h; y++)
        for (x = 0; x < B->w; x++) {
            size_t p = (size_t)(B->y0 + y) * J->W + B->x0 + x, q = (size_t)(y / c) * cw + x / c;
            if (J->fixed[p]) v[q] += J->val[p], cnt[q]++;
        }
    for (i = 0; i < nc; i++) {
        f[i] = (uint8_t)(cnt[i] > 0);
        if (cnt[i]) v[i] /= (float)cnt[i];
    }
}

static void tn__gnn_mblock_task(void *vj, size_t b0, size_t b1)
{
    tn__gnn_mjob *J = (tn__gnn_mjob *)vj;
    size_t bi;
    for (bi = b0; bi < b1; bi++) {
        tn__gnn_mblock *B = &J->b[bi];
        int bx = B->x0, by = B->y0, halo = TN__GNN_MHALO, x, y, any = 0, c = 1, cw, ch;
        float *v = NULL, *sol = NULL;
        uint8_t *f = NULL;
        int *cnt = NULL;
        for (;;) { /* the domain: block + halo, grown until it holds a fixed pixel */
            B->x0 = bx - halo > 0 ? bx - halo : 0;
            B->y0 = by - halo > 0 ? by - halo : 0;
            B->w = (bx + TN__GNN_MB + halo < J->W ? bx + TN__GNN_MB + halo : J->W) - B->x0;
            B->h = (by + TN__GNN_MB + halo < J->H ? by + TN__GNN_MB + halo : J->H) - B->y0;
            for (y = 0; y < B->h && !any; y++)
                for (x = 0; x < B->w && !any; x++) any = J->fixed[(size_t)(B->y0 + y) * J->W + B->x0 + x];
            if (any || (B->w == J->W && B->h == J->H)) break;
            halo *= 2;
        }
        B->sx = bx - TN__GNN_MB / 2 > 0 ? bx - TN__GNN_MB / 2 : 0;
        B->sy = by - TN__GNN_MB / 2 > 0 ? by - TN__GNN_MB / 2 : 0;
        B->sw = (bx + TN__GNN_MB + TN__GNN_MB / 2 < J->W ? bx + TN__GNN_MB + TN__GNN_MB / 2 : J->W) - B->sx;
        B->sh = (by + TN__GNN_MB + TN__GNN_MB / 2 < J->H ? by + TN__GNN_MB + TN__GNN_MB / 2 : J->H) - B->sy;
        while ((size_t)((B->w + c - 1) / c) * (size_t)((B->h + c - 1) / c) > TN__GNN_MSOLVE) c *= 2;
        cw = (B->w + c - 1) / c;
        ch = (B->h + c - 1) / c;
        v = (float *)tn__alloc((size_t)cw * ch * sizeof(float));
        f = (uint8_t *)tn__alloc((size_t)cw * ch);
        cnt = (int *)tn__alloc((size_t)cw * ch * sizeof(int));
        sol = (float *)tn__alloc((size_t)cw * ch * sizeof(float));
        B->sol = (float *)tn__alloc((size_t)B->sw * B->sh * sizeof(float));
        if (!v || !f || !cnt || !sol || !B->sol) B->st = TN_ERR_OUT_OF_MEMORY;
        else {
            tn__gnn_mblock_cells(J, B, c, cw, v, f, cnt);
            B->st = tn__gnn_membrane_solve(v, f, cw, ch, sol);
        }
        for (y = 0; !B->st && y < B->sh; y++) /* the kept pixels: the cells' values, bilinear at their centres */
            for (x = 0; x < B->sw; x++) {
                float u = ((float)(B->sx + x - B->x0) + 0.5f) / (float)c - 0.5f, t = ((float)(B->sy + y - B->y0) + 0.5f) / (float)c - 0.5f;
                int i0, j0, i1, j1;
                u = tn__clampf(u, 0.0f, (float)(cw - 1));
                t = tn__clampf(t, 0.0f, (float)(ch - 1));
                i0 = (int)u, j0 = (int)t;
                i1 = i0 + 1 < cw ? i0 + 1 : i0, j1 = j0 + 1 < ch ? j0 + 1 : j0;
                u -= (float)i0, t -= (float)j0;
                B->sol[(size_t)y * B->sw + x] = (1 - t) * ((1 - u) * sol[(size_t)j0 * cw + i0] + u * sol[(size_t)j0 * cw + i1]) +
                                                t * ((1 - u) * sol[(size_t)j1 * cw + i0] + u * sol[(size_t)j1 * cw + i1]);
            }
        TN_FREE(v);
        TN_FREE(f);
        TN_FREE(cnt);
        TN_FREE(sol);
    }
}

/* Block a pixel coordinate blends: blocks *a and *b (clamped to 0 .. n - 1), weight of b in *t,
   a smoothstep of the distance: a linear weight left a kink where it starts, at every block
   centre, which a hillshade shows as a line across the map. */
static void tn__gnn_mblend(int x, int n, int *a, int *b, float *t)
{
    float u = ((float)x + 0.5f) / (float)TN__GNN_MB - 0.5f, fl = floorf(u);
    *a = (int)fl;
    *t = (u - fl) * (u - fl) * (3 - 2 * (u - fl));
    *b = *a + 1;
    if (*a < 0) *a = 0;
    if (*b < 0) *b = 0;
    if (*a > n - 1) *a = n - 1;
    if (*b > n - 1) *b = n - 1;
}

/* out (rw x rh) = the bounded-influence membrane on the rectangle (rx, ry, rw, rh) of the W x H
   map given by val / fixed (W x H). Needs at least one fixed pixel in the map. */
static tn_status tn__gnn_membrane_rect(const float *val, const uint8_t *fixed, int W, int H, int rx, int ry, int rw, int rh, float *out)
{
    int nbx = (W + TN__GNN_MB - 1) / TN__GNN_MB, nby = (H + TN__GNN_MB - 1) / TN__GNN_MB, bxa, bxb, bya, byb, x, y, i, nb;
    float t;
    tn__gnn_mjob J;
    tn_status st = TN_OK;
    if ((nbx - 1) * TN__GNN_MB <= TN__GNN_MHALO && TN__GNN_MB + TN__GNN_MHALO >= W && (nby - 1) * TN__GNN_MB <= TN__GNN_MHALO &&
        TN__GNN_MB + TN__GNN_MHALO >= H) {
        float *all = out;
        if ((rw != W || rh != H) && !(all = (float *)tn__alloc((size_t)W * H * sizeof(float)))) return TN_ERR_OUT_OF_MEMORY;
        st = tn__gnn_membrane_solve(val, fixed, W, H, all);
        if (all != out) {
            for (y = 0; !st && y < rh; y++) memcpy(out + (size_t)y * rw, all + (size_t)(ry + y) * W + rx, (size_t)rw * sizeof(float));
            TN_FREE(all);
        }
        return st;
    }
    tn__gnn_mblend(rx, nbx, &bxa, &i, &t);
    tn__gnn_mblend(rx + rw - 1, nbx, &i, &bxb, &t);
    tn__gnn_mblend(ry, nby, &bya, &i, &t);
    tn__gnn_mblend(ry + rh - 1, nby, &i, &byb, &t);
    nb = (bxb - bxa + 1) * (byb - bya + 1);
    memset(&J, 0, sizeof J);
    J.val = val;
    J.fixed = fixed;
    J.W = W;
    J.H = H;
    if (!(J.b = (tn__gnn_mblock *)tn__calloc((size_t)nb * sizeof(tn__gnn_mblock)))) return TN_ERR_OUT_OF_MEMORY;
    for (i = 0; i < nb; i++) {
        J.b[i].x0 = (bxa + i % (bxb - bxa + 1)) * TN__GNN_MB;
        J.b[i].y0 = (bya + i / (bxb - bxa + 1)) * TN__GNN_MB;
    }
    tn_parallel_for((size_t)nb, 1, tn__gnn_mblock_task, &J);
    for (i = 0; i < nb; i++)
        if (J.b[i].st && !st) st = J.b[i].st;
    for (y = 0; !st && y < rh; y++)
        for (x = 0; x < rw; x++) {
            int gx = rx + x, gy = ry + y, xa, xb, ya, yb, q;
            float tx, ty, v = 0, w[4];
            const tn__gnn_mblock *bl[4];
            tn__gnn_mblend(gx, nbx, &xa, &xb, &tx);
            tn__gnn_mblend(gy, nby, &ya, &yb, &ty);
            bl[0] = &J.b[(ya - bya) * (bxb - bxa + 1) + xa - bxa];
            bl[1] = &J.b[(ya - bya) * (bxb - bxa + 1) + xb - bxa];
            bl[2] = &J.b[(yb - bya) * (bxb - bxa + 1) + xa - bxa];
            bl[3] = &J.b[(yb - bya) * (bxb - bxa + 1) + xb - bxa];
            w[0] = (1 - tx) * (1 - ty);
            w[1] = tx * (1 - ty);
            w[2] = (1 - tx) * ty;
            w[3] = tx * ty;
            for (q = 0; q < 4; q++) v += w[q] * bl[q]->sol[(size_t)(gy - bl[q]->sy) * bl[q]->sw + gx - bl[q]->sx];
            out[(size_t)y * rw + x] = v;
        }
    for (i = 0; i < nb; i++) TN_FREE(J.b[i].sol);
    TN_FREE(J.b);
    return st;
}

/* Rasterised sketch -> pixel type (+1 ridge, -1 valley, 0 none), fixed heights, membrane. */
static tn_status tn__gnn_sketch_pixels(const tn_contour_set *set, int W, int H, float *type, float *height, float *membrane)
{
    tn_image r = {0, 0, 0, NULL};
    uint8_t *fixed;
    size_t i, n = (size_t)W * H, nf = 0;
    tn_status st;
    if ((st = tn_sketch_rasterise(&r, set, W, H))) return st;
    if (!(fixed = (uint8_t *)tn__alloc(n))) {
        tn_image_free(&r);
        return TN_ERR_OUT_OF_MEMORY;
    }
    for (i = 0; i < n; i++) {
        const float *p = r.data + 3 * i;
        fixed[i] = (uint8_t)(p[0] > 0 || p[1] > 0);
        nf += fixed[i];
        if (type) type[i] = p[0] > 0 ? 1.0f : p[1] > 0 ? -1.0f : 0.0f;
        height[i] = fixed[i] ? p[2] : 0.0f;
    }
    if (!nf) st = tn__fail(TN_ERR_EMPTY, "gnn: the sketch covers no pixel of the %d x %d map", W, H);
    if (!st && membrane) st = tn__gnn_membrane_rect(height, fixed, W, H, 0, 0, W, H, membrane);
    TN_FREE(fixed);
    tn_image_free(&r);
    return st;
}

TN_API tn_status tn_gnn_membrane(tn_image *out, const tn_contour_set *sketch, int width, int height)
{
    tn_image m = {0, 0, 0, NULL};
    float *h;
    tn_status st;
    TN_ASSERT(out);
    if (!sketch || sketch->count <= 0) return tn__fail(TN_ERR_EMPTY, "membrane: the sketch is empty");
    if ((st = tn__cset_check(sketch, "membrane"))) return st;
    if ((st = tn_image_create(&m, width, height, 1))) return st;
    if (!(h = (float *)tn__alloc((size_t)width * height * sizeof(float)))) {
        tn_image_free(&m);
        return TN_ERR_OUT_OF_MEMORY;
    }
    st = tn__gnn_sketch_pixels(sketch, width, height, NULL, h, m.data);
    TN_FREE(h);
    if (st) {
        tn_image_free(&m);
        return st;
    }
    *out = m;
    return TN_OK;
}
#endif /* TN_NO_GNN */
