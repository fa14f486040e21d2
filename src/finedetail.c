/* ============================================================================================
   @@finedetail  detail by example (the fine scales of paper 000's sketch path, section 4.4's role)
   A terrain keeps its coarse shape, a Gaussian low-pass, and takes everything finer from
   patches of an example DEM at the same pixel size, as image analogies with the low-pass as
   the guide: every 7 x 7 patch of the terrain's low-pass is matched to the nearest patch of the
   example's low-pass (under the example's 8 rotations and mirrors, heights relative to the
   patch mean), and the example's detail (itself minus its low-pass) at the matches is added.
   A pixel depends only on the terrain within tn_fine_detail_halo pixels (and on the colour,
   x + y even or odd, its place gives it), so tiles cut at an even x + y equal the whole map,
   and on no thread count.
   ============================================================================================ */
#ifndef TN_NO_FINEDETAIL

typedef struct tn_fine_detail_opts {
    float sigma;   /* px: the terrain keeps what a Gaussian of this sigma keeps, the example gives
                      the rest; 0 = 2 */
    int patch;     /* odd patch side in px, 3..15; 0 = 7 */
    int probes;    /* patch clusters searched per patch, 1..64; 0 = 2 (more: nearer matches, slower) */
} tn_fine_detail_opts;

/* out = terrain's low-pass + the example's finer detail, matched by shape. example and terrain:
   one channel, the same pixel size and height units (metres), each at least patch x patch
   (example: 2 patches); out is allocated here, terrain's size. opts may be NULL. */
TN_API tn_status tn_fine_detail(tn_image *out, const tn_image *example, const tn_image *terrain, const tn_fine_detail_opts *opts);

/* Pixels around a window that tn_fine_detail reads for it: a window computed from the
   terrain grown by this much (tn_rect_halo), cut from the map at an even x + y, equals the whole
   map's pixels there (the coherence sweeps take the pixels of one colour, x + y even or odd, at a
   time). */
TN_API int tn_fine_detail_halo(const tn_fine_detail_opts *opts);
#endif /* TN_NO_FINEDETAIL */

/* --------------------------------------------------------------------------------------------
   >>finedetail  (@@finedetail implementation)
   Patches are keyed by their low-pass heights minus their mean (matching the detailed terrain
   against the detailed example instead, as texture optimisation does, favours the smoothest
   example patches pass after pass). Nearest patches are found in an inverted file:
   k-means clusters of the keys (deterministic start and subsample), each query scans the keys
   of its `probes` nearest clusters exactly, 16 keys a block; a key is the patch sampled every
   second pixel (the low-pass loses nothing by it; 16 values for 7 x 7). Then coherence: each pixel may take
   a 4-neighbour's match shifted by one pixel when that fits its patch better (Jacobi sweeps), so
   neighbouring patches come from one place of the example (a match that no neighbour shares
   counts its distance twice). The detail comes in two bands: down to a Gaussian of 1 px, the
   Gaussian-weighted vote of the patches over the pixel (smooth where neighbouring matches
   disagree, so scaled to the local RMS of the band at the pixels' own matches); finer, the
   example's at the pixel's own match, which a wide vote would average away (the finest band is
   what slope breaks and gullies are made of), read through the 3 x 3 neighbours' matches so
   that it stays the example's texture where they agree and is not white where they do not.
   The detail starts below a Gaussian of sqrt(3) sigma, not sigma: the terrain's low-pass and
   the example's detail are uncorrelated, so their powers add,
   and with filters g and 1 - g^3 (g = the Gaussian's response) that sum stays within -0.04 ..
   +0.01 decades of 1 where 1 - g would dip by 0.3 at the crossover. (The finest band does not
   overlap the voted one so: taken pixel by pixel it is close to white, and the overlap made the
   Laplacian twice the example's.)
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_FINEDETAIL

#define TN__FD_MAX_KEYS 131072 /* the example is subsampled to at most this many patch centres */
#define TN__FD_KMEANS_ITERS 6
#define TN__FD_SWEEPS 4        /* coherence sweeps, red-black */
#define TN__FD_KAPPA 1.0f      /* a match no neighbour shares counts its distance (1 + kappa) times */
#define TN__FD_VOTE_SIGMA 1.0f /* px: the vote's Gaussian weight */
#define TN__FD_FINE_SIGMA 1.0f /* px: detail finer than this comes from each pixel's own match */
#define TN__FD_OWN_SIGMA 0.7f  /* px: the weight of the 3 x 3 neighbours' matches in that (tn__fd_own) */
#define TN__FD_RMS_SIGMA 4.0f  /* px: the window of the voted band's local RMS */
#define TN__FD_BAND 1.7320508f /* the detail band reaches up to a Gaussian of sqrt(3) sigma (below) */
#define TN__FD_LANES 16        /* keys a block (one or two SIMD vectors) */
#define TN__FD_PAD 1e15f       /* the heights of padding keys: never nearest */

typedef struct tn__fd_keys {
    int k;            /* clusters */
    int nblk;         /* key blocks */
    float *blk;       /* nblk x D x LANES: keys minus their mean, grouped by cluster */
    int *where;       /* nblk x LANES: plane index of the key's centre, -1 = padding */
    int *bstart;      /* k + 1: cluster c's blocks are bstart[c] .. bstart[c + 1] - 1 */
    float *cent;      /* ceil(k / LANES) x D x LANES centroids (padding past k) */
} tn__fd_keys;

typedef struct tn__fd {
    int P, r, D, DK, probes, side, plane; /* D = P^2 patch values, DK key values */
    float sigma;
    float *low, *det; /* 8 transforms of the example's low-pass (sigma) and its detail: the band
                         between Gaussians of sqrt(3) sigma and FINE_SIGMA, side x side each */
    float *fine;      /* the finest detail: the example minus a Gaussian of FINE_SIGMA */
    float *lowm;      /* the low-pass's patch means at every valid centre */
    int tw[8], th[8];
    tn__fd_keys keys;
} tn__fd;

static void tn__fd_opts_defaults(tn_fine_detail_opts *o)
{
    if (o->sigma == 0) o->sigma = 2.0f;
    if (o->patch == 0) o->patch = 7;
    if (o->probes == 0) o->probes = 2;
}

static tn_status tn__fd_opts_check(const tn_fine_detail_opts *o)
{
    if (!(o->sigma >= 0.5f && o->sigma <= 32.0f))
        return tn__fail(TN_ERR_INVALID_ARG, "fine detail: sigma %g is not in 0.5 .. 32 px", (double)o->sigma);
    if (o->patch < 3 || o->patch > 15 || !(o->patch & 1))
        return tn__fail(TN_ERR_INVALID_ARG, "fine detail: patch %d is not odd in 3 .. 15", o->patch);
    if (o->probes < 1 || o->probes > 64) return tn__fail(TN_ERR_INVALID_ARG, "fine detail: probes %d is not in 1 .. 64", o->probes);
    return TN_OK;
}

static int tn__fd_blur_radius(float sigma) { return (int)(4.0f * sigma + 0.5f); }

TN_API int tn_fine_detail_halo(const tn_fine_detail_opts *opts)
{
    tn_fine_detail_opts o;
    int b;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    tn__fd_opts_defaults(&o);
    if (tn__fd_opts_check(&o)) return -1;
    b = tn__fd_blur_radius(o.sigma);
    /* the guide's blur, the match's patch, a pixel a sweep, the vote, the RMS window */
    return b + 2 * (o.patch / 2) + TN__FD_SWEEPS + tn__fd_blur_radius(TN__FD_RMS_SIGMA);
}

static void tn__fd_keys_free(tn__fd_keys *K)
{
    TN_FREE(K->blk);
    TN_FREE(K->where);
    TN_FREE(K->bstart);
    TN_FREE(K->cent);
    memset(K, 0, sizeof *K);
}

TN__SHARED void tn__fd_free(tn__fd *d)
{
    tn__fd_keys_free(&d->keys);
    TN_FREE(d->low);
    TN_FREE(d->det);
    TN_FREE(d->fine);
    TN_FREE(d->lowm);
    memset(d, 0, sizeof *d);
}

/* Squared distances of q to the LANES keys of a block (lanes are keys: no reduction to reorder).
   The lanes are the inner loop, so that a compiler vectorises it where tn__vf is one float (the
   WebAssembly build) and the vectors' sums run side by side; each lane's sum is the same. */
static void tn__fd_dist(const float *q, const float *blk, int D, float *out)
{
    tn__vf acc[TN__FD_LANES / TN__VF_N];
    int i, l;
    for (l = 0; l < TN__FD_LANES / TN__VF_N; l++) acc[l] = tn__vf_set1(0.0f);
    for (i = 0; i < D; i++) {
        tn__vf qi = tn__vf_set1(q[i]);
        for (l = 0; l < TN__FD_LANES / TN__VF_N; l++) {
            tn__vf e = tn__vf_sub(qi, tn__vf_load(blk + i * TN__FD_LANES + l * TN__VF_N));
            acc[l] = tn__vf_madd(e, e, acc[l]);
        }
    }
    for (l = 0; l < TN__FD_LANES / TN__VF_N; l++) tn__vf_store(out + l * TN__VF_N, acc[l]);
}

/* The values of src (w x h, rows of `stride`) every `step` px from (x - r, y - r) to (x + r,
   y + r), coordinates clamped, minus their mean (returned). step 1: the patch; step 2: its key
   (the match runs on low-passes, which that sampling keeps: 16 values for 7 x 7). */
static float tn__fd_sample(const float *src, int w, int h, size_t stride, int x, int y, int r, int step, float *out)
{
    int u, v, n = 0;
    float m = 0;
    for (v = -r; v <= r; v += step) {
        int yy = y + v < 0 ? 0 : y + v >= h ? h - 1 : y + v;
        for (u = -r; u <= r; u += step) {
            int xx = x + u < 0 ? 0 : x + u >= w ? w - 1 : x + u;
            out[n] = src[(size_t)yy * stride + xx];
            m += out[n++];
        }
    }
    m /= (float)n;
    for (u = 0; u < n; u++) out[u] -= m;
    return m;
}

/* 1 when plane index `at` is a patch centre (r px inside its transform). */
static int tn__fd_valid(const tn__fd *d, int at)
{
    int t = at / d->plane, y = at % d->plane / d->side, x = at % d->side;
    return at >= 0 && t < 8 && x >= d->r && y >= d->r && x < d->tw[t] - d->r && y < d->th[t] - d->r;
}

/* Squared distance of q (mean removed) to src's patch at `at` (mean m removed). */
static float tn__fd_dist_at(const tn__fd *d, const float *q, const float *src, int at, float m)
{
    const float *p = src + at - d->r * d->side - d->r;
    float s = 0;
    int u, v, n = 0;
    for (v = 0; v < d->P; v++, p += d->side)
        for (u = 0; u < d->P; u++) {
            float e = q[n++] - (p[u] - m);
            s += e * e;
        }
    return s;
}

typedef struct tn__fd_assign_job {
    const float *key, *cent; /* key: n x D rows; cent: blocks */
    int D, k;
    int *label;
} tn__fd_assign_job;

static void tn__fd_assign_task(void *vj, size_t b, size_t e)
{
    const tn__fd_assign_job *j = (const tn__fd_assign_job *)vj;
    float dist[TN__FD_LANES];
    size_t i;
    int c, l;
    for (i = b; i < e; i++) {
        float best = FLT_MAX;
        int bc = 0;
        for (c = 0; c < j->k; c += TN__FD_LANES) {
            tn__fd_dist(j->key + i * j->D, j->cent + (size_t)c * j->D, j->D, dist);
            for (l = 0; l < TN__FD_LANES && c + l < j->k; l++)
                if (dist[l] < best) best = dist[l], bc = c + l;
        }
        j->label[i] = bc;
    }
}

/* Writes centroid c (D floats) into the block layout. */
static void tn__fd_cent_set(float *cent, int D, int c, const float *v)
{
    float *b = cent + (size_t)(c / TN__FD_LANES) * D * TN__FD_LANES + c % TN__FD_LANES;
    int i;
    for (i = 0; i < D; i++) b[i * TN__FD_LANES] = v[i];
}

/* The keys (n rows of D, centres `where`) clustered and laid out in blocks by cluster. */
static tn_status tn__fd_index(const float *key, const int *where, int n, int D, tn__fd_keys *K)
{
    int k = (int)sqrt((double)n), it, c, i, l, q;
    int m, nt, ncb, *label = NULL, *count = NULL, *pos = NULL;
    float *train = NULL, *v = NULL;
    double *sum = NULL;
    tn__fd_assign_job job;
    tn_status st = TN_OK;
    if (k < 1) k = 1;
    if (k > 1024) k = 1024;
    m = n / (k * 64) > 1 ? n / (k * 64) : 1; /* ~64 training keys a cluster */
    nt = (n + m - 1) / m;
    ncb = (k + TN__FD_LANES - 1) / TN__FD_LANES;
    K->k = k;
    K->cent = (float *)tn__alloc((size_t)ncb * D * TN__FD_LANES * sizeof(float));
    K->bstart = (int *)tn__alloc((size_t)(k + 1) * sizeof(int));
    label = (int *)tn__alloc((size_t)n * sizeof(int));
    count = (int *)tn__alloc((size_t)k * sizeof(int));
    pos = (int *)tn__alloc((size_t)k * sizeof(int));
    sum = (double *)tn__alloc((size_t)k * D * sizeof(double));
    train = (float *)tn__alloc((size_t)nt * D * sizeof(float));
    v = (float *)tn__alloc((size_t)D * sizeof(float));
    if (!K->cent || !K->bstart || !label || !count || !pos || !sum || !train || !v) {
        st = tn__oom();
        goto done;
    }
    for (i = 0; i < ncb * D * TN__FD_LANES; i++) K->cent[i] = TN__FD_PAD;
    for (i = 0; i < nt; i++) memcpy(train + (size_t)i * D, key + (size_t)i * m * D, (size_t)D * sizeof(float));
    for (c = 0; c < k; c++) tn__fd_cent_set(K->cent, D, c, train + (size_t)((long long)c * nt / k) * D);
    job.cent = K->cent;
    job.D = D;
    job.k = k;
    job.label = label;
    for (it = 0; it < TN__FD_KMEANS_ITERS; it++) {
        job.key = train;
        tn_parallel_for((size_t)nt, 256, tn__fd_assign_task, &job);
        memset(count, 0, (size_t)k * sizeof(int));
        memset(sum, 0, (size_t)k * D * sizeof(double));
        for (i = 0; i < nt; i++) {
            count[label[i]]++;
            for (q = 0; q < D; q++) sum[(size_t)label[i] * D + q] += train[(size_t)i * D + q];
        }
        for (c = 0; c < k; c++)
            if (count[c]) {
                for (q = 0; q < D; q++) v[q] = (float)(sum[(size_t)c * D + q] / count[c]);
                tn__fd_cent_set(K->cent, D, c, v);
            }
    }
    job.key = key;
    tn_parallel_for((size_t)n, 256, tn__fd_assign_task, &job);
    memset(count, 0, (size_t)k * sizeof(int));
    for (i = 0; i < n; i++) count[label[i]]++;
    K->bstart[0] = 0;
    for (c = 0; c < k; c++) K->bstart[c + 1] = K->bstart[c] + (count[c] + TN__FD_LANES - 1) / TN__FD_LANES, pos[c] = 0;
    K->nblk = K->bstart[k];
    K->blk = (float *)tn__alloc((size_t)K->nblk * D * TN__FD_LANES * sizeof(float));
    K->where = (int *)tn__alloc((size_t)K->nblk * TN__FD_LANES * sizeof(int));
    if (!K->blk || !K->where) {
        st = tn__oom();
        goto done;
    }
    for (i = 0; i < K->nblk * D * TN__FD_LANES; i++) K->blk[i] = TN__FD_PAD;
    for (i = 0; i < K->nblk * TN__FD_LANES; i++) K->where[i] = -1;
    for (i = 0; i < n; i++) {
        int c2 = label[i], slot = K->bstart[c2] * TN__FD_LANES + pos[c2]++;
        float *b = K->blk + (size_t)(slot / TN__FD_LANES) * D * TN__FD_LANES + slot % TN__FD_LANES;
        for (l = 0; l < D; l++) b[l * TN__FD_LANES] = key[(size_t)i * D + l];
        K->where[slot] = where[i];
    }
done:
    TN_FREE(label);
    TN_FREE(count);
    TN_FREE(pos);
    TN_FREE(sum);
    TN_FREE(train);
    TN_FREE(v);
    return st;
}

/* The keys of src's 8 transforms (planes as d->low), every `step` px, and their index. */
static tn_status tn__fd_keys_make(const tn__fd *d, const float *src, int step, tn__fd_keys *K)
{
    float *key = NULL;
    int *where = NULL, t, x, y, n = 0, cap = 0;
    tn_status st;
    for (t = 0; t < 8; t++) cap += ((d->tw[t] - 2 * d->r + step - 1) / step) * ((d->th[t] - 2 * d->r + step - 1) / step);
    key = (float *)tn__alloc((size_t)cap * d->DK * sizeof(float));
    where = (int *)tn__alloc((size_t)cap * sizeof(int));
    if (!key || !where) {
        TN_FREE(key);
        TN_FREE(where);
        return tn__oom();
    }
    for (t = 0; t < 8; t++)
        for (y = d->r; y < d->th[t] - d->r; y += step)
            for (x = d->r; x < d->tw[t] - d->r; x += step) {
                tn__fd_sample(src + (size_t)t * d->plane, d->tw[t], d->th[t], (size_t)d->side, x, y, d->r, 2, key + (size_t)n * d->DK);
                where[n++] = t * d->plane + y * d->side + x;
            }
    st = tn__fd_index(key, where, n, d->DK, K);
    TN_FREE(key);
    TN_FREE(where);
    return st;
}

/* The 8 rotations and mirrors of a w x h image into side x side planes. */
static void tn__fd_transforms(const float *src, int w, int h, int side, float *dst, int *tw, int *th)
{
    int t, x, y;
    for (t = 0; t < 8; t++) {
        int swap = t & 1, W = swap ? h : w, H = swap ? w : h;
        float *pl = dst + (size_t)t * side * side;
        tw[t] = W, th[t] = H;
        for (y = 0; y < H; y++)
            for (x = 0; x < W; x++) {
                int sx = swap ? y : x, sy = swap ? x : y;
                if (t & 2) sx = w - 1 - sx;
                if (t & 4) sy = h - 1 - sy;
                pl[(size_t)y * side + x] = src[(size_t)sy * w + sx];
            }
    }
}

/* Patch means of the planes at every valid centre. */
static void tn__fd_means(const tn__fd *d, const float *src, float *mean)
{
    float q[225];
    int t, x, y;
    for (t = 0; t < 8; t++)
        for (y = d->r; y < d->th[t] - d->r; y++)
            for (x = d->r; x < d->tw[t] - d->r; x++) {
                size_t at = (size_t)t * d->plane + (size_t)y * d->side + x;
                mean[at] = tn__fd_sample(src + (size_t)t * d->plane, d->tw[t], d->th[t], (size_t)d->side, x, y, d->r, 1, q);
            }
}

TN__SHARED tn_status tn__fd_build(const tn_image *example, const tn_fine_detail_opts *opts, tn__fd *d)
{
    tn_fine_detail_opts o;
    tn_image lo = {0, 0, 0, NULL}, mid = {0, 0, 0, NULL};
    size_t bytes, i;
    int w, h, step = 1;
    tn_status st;
    memset(d, 0, sizeof *d);
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    tn__fd_opts_defaults(&o);
    if ((st = tn__fd_opts_check(&o))) return st;
    if ((st = tn__dem_check(example, 2 * o.patch, "fine detail: example"))) return st;
    if (example->channels != 1) return tn__fail(TN_ERR_INVALID_ARG, "fine detail: the example must have one channel (heights)");
    w = example->width, h = example->height;
    d->P = o.patch, d->r = o.patch / 2, d->D = o.patch * o.patch, d->DK = (o.patch / 2 + 1) * (o.patch / 2 + 1);
    d->probes = o.probes, d->sigma = o.sigma;
    d->side = w > h ? w : h;
    if ((st = tn__size4(8, (size_t)d->side, (size_t)d->side, sizeof(float), &bytes))) return st;
    d->plane = d->side * d->side;
    while ((double)8 * ((w - 2 * d->r + step - 1) / step) * ((h - 2 * d->r + step - 1) / step) > TN__FD_MAX_KEYS) step++;
    if (!(d->low = (float *)tn__calloc(bytes)) || !(d->det = (float *)tn__calloc(bytes)) || !(d->fine = (float *)tn__calloc(bytes)) ||
        !(d->lowm = (float *)tn__calloc(bytes))) {
        st = tn__oom();
        goto done;
    }
    if ((st = tn_image_blur(&lo, example, o.sigma)) || (st = tn_image_blur(&mid, example, TN__FD_FINE_SIGMA))) goto done;
    tn__fd_transforms(lo.data, w, h, d->side, d->low, d->tw, d->th);
    tn_image_free(&lo);
    if ((st = tn_image_blur(&lo, example, o.sigma * TN__FD_BAND))) goto done;
    for (i = 0; i < (size_t)w * h; i++) {
        lo.data[i] = mid.data[i] - lo.data[i];
        mid.data[i] = example->data[i] - mid.data[i];
    }
    tn__fd_transforms(lo.data, w, h, d->side, d->det, d->tw, d->th);
    tn__fd_transforms(mid.data, w, h, d->side, d->fine, d->tw, d->th);
    tn__fd_means(d, d->low, d->lowm);
    st = tn__fd_keys_make(d, d->low, step, &d->keys);
done:
    tn_image_free(&lo);
    tn_image_free(&mid);
    if (st) tn__fd_free(d);
    return st;
}

typedef struct tn__fd_job {
    const tn__fd *d;
    const float *img;        /* the terrain's low-pass, w x h */
    int w, h, parity, odd;   /* odd: the image's origin lies at an odd x + y of its map */
    const int *from;         /* sweeps: the matches before the sweep */
    int *match;              /* w x h plane indices */
    float *vote, *own, *band;/* w x h: the voted band, the finest detail at each pixel's own match, the
                                voted band's there */
} tn__fd_job;

/* Nearest key of each pixel's patch: the probes nearest clusters, scanned whole. */
static void tn__fd_match_task(void *vj, size_t b, size_t e)
{
    const tn__fd_job *j = (const tn__fd_job *)vj;
    const tn__fd *d = j->d;
    const tn__fd_keys *K = &d->keys;
    float q[225], cd[64], dist[TN__FD_LANES];
    int cc[64];
    size_t row;
    for (row = b; row < e; row++) {
        int x;
        for (x = 0; x < j->w; x++) {
            int c, p, l, n = 0, best = -1;
            float bd = FLT_MAX;
            tn__fd_sample(j->img, j->w, j->h, (size_t)j->w, x, (int)row, d->r, 2, q);
            for (c = 0; c < K->k; c += TN__FD_LANES) {
                tn__fd_dist(q, K->cent + (size_t)c * d->DK, d->DK, dist);
                for (l = 0; l < TN__FD_LANES && c + l < K->k; l++) {
                    float dc = dist[l];
                    if (K->bstart[c + l + 1] == K->bstart[c + l] || (n == d->probes && dc >= cd[n - 1])) continue;
                    p = n < d->probes ? n++ : n - 1; /* insertion into the sorted list; ties keep the lower index */
                    while (p > 0 && cd[p - 1] > dc) cd[p] = cd[p - 1], cc[p] = cc[p - 1], p--;
                    cd[p] = dc, cc[p] = c + l;
                }
            }
            for (p = 0; p < n; p++) {
                int bk;
                for (bk = K->bstart[cc[p]]; bk < K->bstart[cc[p] + 1]; bk++) {
                    tn__fd_dist(q, K->blk + (size_t)bk * d->DK * TN__FD_LANES, d->DK, dist);
                    for (l = 0; l < TN__FD_LANES; l++)
                        if (dist[l] < bd) bd = dist[l], best = K->where[bk * TN__FD_LANES + l];
                }
            }
            j->match[row * j->w + x] = best;
        }
    }
}

/* One coherence half-sweep over the pixels of one colour (x + y even or odd, in the map's
   coordinates: a window cut at an odd x + y keeps its pixels' colours): each keeps its
   match or takes a 4-neighbour's, shifted by the pixel between them, whichever fits its patch
   best, a match that no neighbour shares counting (1 + kappa) times its distance. Red-black, so
   two neighbours never swap matches back and forth. */
static void tn__fd_sweep_task(void *vj, size_t b, size_t e)
{
    static const int nx[4] = {-1, 1, 0, 0}, ny[4] = {0, 0, -1, 1};
    const tn__fd_job *j = (const tn__fd_job *)vj;
    const tn__fd *d = j->d;
    float q[225];
    size_t row;
    for (row = b; row < e; row++) {
        int x, k;
        for (x = 0; x < j->w; x++) {
            size_t i = row * j->w + x;
            int best = j->from[i], cand[4], shared = 0;
            float bd;
            j->match[i] = best;
            if (((x + (int)row + j->odd) & 1) != j->parity) continue;
            for (k = 0; k < 4; k++) {
                int x2 = x + nx[k], y2 = (int)row + ny[k];
                cand[k] = -1;
                if (x2 < 0 || y2 < 0 || x2 >= j->w || y2 >= j->h) continue;
                cand[k] = j->from[(size_t)y2 * j->w + x2] - nx[k] - ny[k] * d->side;
                if (cand[k] == best) shared = 1;
            }
            tn__fd_sample(j->img, j->w, j->h, (size_t)j->w, x, (int)row, d->r, 1, q);
            bd = tn__fd_dist_at(d, q, d->low, best, d->lowm[best]) * (shared ? 1.0f : 1.0f + TN__FD_KAPPA);
            for (k = 0; k < 4; k++) {
                float dk;
                if (cand[k] == best || !tn__fd_valid(d, cand[k])) continue;
                dk = tn__fd_dist_at(d, q, d->low, cand[k], d->lowm[cand[k]]);
                if (dk < bd) bd = dk, best = cand[k];
            }
            j->match[i] = best;
        }
    }
}

/* The finest detail at pixel (x, y): the example's at its own match, as the 3 x 3 neighbours'
   matches (shifted to the pixel) give it, weighted by wo[squared offset] (a Gaussian of
   TN__FD_OWN_SIGMA). Where the
   matches are coherent all nine agree and this is the own match's detail exactly; where they
   disagree, detail picked pixel by pixel is white, with a Laplacian about 1.5 x the example's. */
static float tn__fd_own(const tn__fd_job *j, const float wo[3], int y, int x)
{
    const tn__fd *d = j->d;
    float s = 0, sw = 0;
    int u, v;
    for (v = -1; v <= 1; v++)
        for (u = -1; u <= 1; u++) {
            int x2 = x - u, y2 = y - v;
            float w = wo[u * u + v * v];
            if (x2 < 0 || y2 < 0 || x2 >= j->w || y2 >= j->h) continue;
            s += w * d->fine[j->match[(size_t)y2 * j->w + x2] + v * d->side + u];
            sw += w;
        }
    return s / sw;
}

/* Each pixel: the Gaussian-weighted mean over the patches that cover it of the example's detail
   there, and the finest detail at its own match. */
static void tn__fd_vote_task(void *vj, size_t b, size_t e)
{
    const tn__fd_job *j = (const tn__fd_job *)vj;
    const tn__fd *d = j->d;
    float wt[16], wo[3];
    size_t row;
    int u, v;
    for (u = 0; u <= d->r; u++) wt[u] = expf(-0.5f * (float)(u * u) / (TN__FD_VOTE_SIGMA * TN__FD_VOTE_SIGMA));
    for (u = 0; u < 3; u++) wo[u] = expf(-0.5f * (float)u / (TN__FD_OWN_SIGMA * TN__FD_OWN_SIGMA));
    for (row = b; row < e; row++) {
        int x;
        for (x = 0; x < j->w; x++) {
            float s = 0, sw = 0;
            for (v = -d->r; v <= d->r; v++) {
                int y2 = (int)row - v;
                if (y2 < 0 || y2 >= j->h) continue;
                for (u = -d->r; u <= d->r; u++) {
                    int x2 = x - u;
                    float w;
                    if (x2 < 0 || x2 >= j->w) continue;
                    w = wt[u < 0 ? -u : u] * wt[v < 0 ? -v : v];
                    s += w * d->det[j->match[(size_t)y2 * j->w + x2] + v * d->side + u];
                    sw += w;
                }
            }
            j->vote[row * j->w + x] = s / sw;
            j->own[row * j->w + x] = tn__fd_own(j, wo, (int)row, x);
            j->band[row * j->w + x] = d->det[j->match[row * j->w + x]];
        }
    }
}

/* out (terrain's size) = terrain's low-pass + detail from d's example; odd: terrain's origin lies
   at an odd x + y of the map it is a window of. */
TN__SHARED tn_status tn__fd_apply(const tn__fd *d, const tn_image *terrain, int odd, tn_image *out)
{
    tn_image guide = {0, 0, 0, NULL}, vote = {0, 0, 0, NULL}, own = {0, 0, 0, NULL}, band = {0, 0, 0, NULL}, v2 = {0, 0, 0, NULL};
    size_t n = (size_t)terrain->width * terrain->height, i;
    int s, *match = NULL, *other = NULL;
    tn__fd_job j;
    tn_status st;
    if ((st = tn__dem_check(terrain, 1, "fine detail: terrain"))) return st;
    if (terrain->channels != 1) return tn__fail(TN_ERR_INVALID_ARG, "fine detail: the terrain must have one channel (heights)");
    if ((st = tn_image_blur(&guide, terrain, d->sigma)) || (st = tn_image_create(&vote, terrain->width, terrain->height, 1)) ||
        (st = tn_image_create(&own, terrain->width, terrain->height, 1)) || (st = tn_image_create(&band, terrain->width, terrain->height, 1)))
        goto done;
    if (!(match = (int *)tn__alloc(n * sizeof(int))) || !(other = (int *)tn__alloc(n * sizeof(int)))) {
        st = tn__oom();
        goto done;
    }
    memset(&j, 0, sizeof j);
    j.d = d;
    j.img = guide.data;
    j.w = terrain->width;
    j.h = terrain->height;
    j.odd = odd & 1;
    j.match = match;
    j.vote = vote.data;
    j.own = own.data;
    j.band = band.data;
    tn_parallel_for((size_t)j.h, 1, tn__fd_match_task, &j);
    for (s = 0; s < TN__FD_SWEEPS; s++) {
        int *t = match;
        j.from = match;
        j.match = other;
        j.parity = s & 1;
        tn_parallel_for((size_t)j.h, 2, tn__fd_sweep_task, &j);
        match = other, other = t;
    }
    j.match = match;
    tn_parallel_for((size_t)j.h, 4, tn__fd_vote_task, &j);
    /* the vote averages disagreeing matches down: its local RMS is brought to that of the band at
       the pixels' own matches (at most 4x) */
    if ((st = tn_image_copy(&v2, &vote))) goto done;
    for (i = 0; i < n; i++) v2.data[i] *= v2.data[i], band.data[i] *= band.data[i];
    if ((st = tn_image_blur(&v2, &v2, TN__FD_RMS_SIGMA)) || (st = tn_image_blur(&band, &band, TN__FD_RMS_SIGMA))) goto done;
    for (i = 0; i < n; i++) {
        float g = v2.data[i] > 0 ? sqrtf(band.data[i] / v2.data[i]) : 1.0f;
        guide.data[i] += vote.data[i] * (g < 4.0f ? g : 4.0f) + own.data[i];
    }
    *out = guide;
    guide.data = NULL;
done:
    tn_image_free(&guide);
    tn_image_free(&vote);
    tn_image_free(&own);
    tn_image_free(&band);
    tn_image_free(&v2);
    TN_FREE(match);
    TN_FREE(other);
    return st;
}

TN_API tn_status tn_fine_detail(tn_image *out, const tn_image *example, const tn_image *terrain, const tn_fine_detail_opts *opts)
{
    tn__fd d;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__dem_check(terrain, 1, "fine detail: terrain"))) return st;
    if (terrain->channels != 1) return tn__fail(TN_ERR_INVALID_ARG, "fine detail: the terrain must have one channel (heights)");
    if ((st = tn__fd_build(example, opts, &d))) return st;
    st = tn__fd_apply(&d, terrain, 0, out);
    tn__fd_free(&d);
    return st;
}
#endif /* TN_NO_FINEDETAIL */
