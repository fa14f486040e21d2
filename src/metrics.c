/* ============================================================================================
   @@metrics  image comparison
   ============================================================================================ */

typedef struct tn_metrics {
    double ssim;  /* mean SSIM, 11x11 Gaussian window sigma 1.5, K1 0.01, K2 0.03 (channels averaged) */
    double psnr;  /* dB, 20 log10(range / rmse); +inf for identical images */
    double rmse, mae;
} tn_metrics;

/* Compares img against the reference; both must have the same size and channels.
   data_range <= 0 means max(ref) - min(ref). Matches scikit-image structural_similarity(
   gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=R), including its
   cropping of the 5-pixel border. Images smaller than 11 x 11 fail with TN_ERR_INVALID_ARG. */
TN_API tn_status tn_compare(tn_metrics *out, const tn_image *ref, const tn_image *img, double data_range);
/* SSIM only (same definition). */
TN_API tn_status tn_ssim(double *ssim, const tn_image *ref, const tn_image *img, double data_range);

/* --------------------------------------------------------------------------------------------
   >>metrics  (@@metrics implementation)
   SSIM as scikit-image structural_similarity(gaussian_weights=True, sigma=1.5,
   use_sample_covariance=False, data_range=R) computes it (Wang et al. 2004): 11-tap Gaussian
   (scipy kernel, truncate 3.5), K1 0.01, K2 0.03, mean over the map cropped by 5 pixels, channels
   averaged. With radius 5 and a crop of 5 every surviving output reads only pixels inside the
   image, so skimage's 'reflect' border never matters and only the 'valid' region is computed.
   Per output row: vertical 11-tap sums of x, y, x^2, y^2, xy in double straight from the float
   rows, then horizontal 11-tap sums and the SSIM formula, all in double (metre-scale heights with
   small variances lose nothing; skimage on float32 input does). Threads take bands of rows; row
   sums are added in row order afterwards, so the result is the same for any thread count.
   Uses the tn__vd SIMD layer from >>imageops.
   -------------------------------------------------------------------------------------------- */

#define TN__SSIM_R 5               /* int(3.5 * 1.5 + 0.5) */
#define TN__SSIM_TAPS (2 * TN__SSIM_R + 1)

typedef struct tn__ssim_job {
    const float *a, *b;            /* reference, image */
    int W, H, C;
    double g[TN__SSIM_TAPS];
    double c1, c2;
    double *scratch;               /* nslots * scratch_doubles */
    size_t nslots, scratch_doubles;
    double *rowsum;                /* [(H - 10) * C] SSIM sums per valid row and channel */
} tn__ssim_job;

/* Vertical pass: the 5 weighted moments of rows y0 .. y0+10 for every sample of the row. */
static void tn__ssim_vertical(const tn__ssim_job *j, size_t y0, double *m)
{
    const size_t L = (size_t)j->W * j->C;
    double *mx = m, *my = m + L, *mxx = m + 2 * L, *myy = m + 3 * L, *mxy = m + 4 * L;
    const float *pa = j->a + y0 * L, *pb = j->b + y0 * L;
    size_t i;
    int k;
    for (i = 0; i + TN__VD_N <= L; i += TN__VD_N) {
        tn__vd sx = tn__vd_set1(0.0), sy = sx, sxx = sx, syy = sx, sxy = sx;
        for (k = 0; k < TN__SSIM_TAPS; k++) {
            tn__vd x = tn__vd_loadf(pa + (size_t)k * L + i), y = tn__vd_loadf(pb + (size_t)k * L + i);
            tn__vd gk = tn__vd_set1(j->g[k]), gx = tn__vd_mul(gk, x), gy = tn__vd_mul(gk, y);
            sx = tn__vd_add(sx, gx);
            sy = tn__vd_add(sy, gy);
            sxx = tn__vd_madd(gx, x, sxx);
            syy = tn__vd_madd(gy, y, syy);
            sxy = tn__vd_madd(gx, y, sxy);
        }
        tn__vd_store(mx + i, sx);
        tn__vd_store(my + i, sy);
        tn__vd_store(mxx + i, sxx);
        tn__vd_store(myy + i, syy);
        tn__vd_store(mxy + i, sxy);
    }
    for (; i < L; i++) {
        double sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0;
        for (k = 0; k < TN__SSIM_TAPS; k++) {
            double x = pa[(size_t)k * L + i], y = pb[(size_t)k * L + i], gx = j->g[k] * x, gy = j->g[k] * y;
            sx += gx;
            sy += gy;
            sxx += gx * x;
            syy += gy * y;
            sxy += gx * y;
        }
        mx[i] = sx, my[i] = sy, mxx[i] = sxx, myy[i] = syy, mxy[i] = sxy;
    }
}

/* SSIM of one sample from its five local moments (skimage's formula, population covariance). */
static double tn__ssim_formula(double ux, double uy, double uxx, double uyy, double uxy, double c1, double c2)
{
    double vx = uxx - ux * ux, vy = uyy - uy * uy, vxy = uxy - ux * uy;
    return ((2.0 * ux * uy + c1) * (2.0 * vxy + c2)) / ((ux * ux + uy * uy + c1) * (vx + vy + c2));
}

/* Horizontal pass and the SSIM map of one valid row into s[0 .. (W-10)*C). */
static void tn__ssim_horizontal(const tn__ssim_job *j, const double *m, double *s)
{
    const size_t C = (size_t)j->C, L = (size_t)j->W * C, n = ((size_t)j->W - 2 * TN__SSIM_R) * C;
    const tn__vd two = tn__vd_set1(2.0), c1 = tn__vd_set1(j->c1), c2 = tn__vd_set1(j->c2);
    size_t i;
    int k, q;
    for (i = 0; i + TN__VD_N <= n; i += TN__VD_N) {
        tn__vd u[5], vx, vy, vxy, num, den;
        for (q = 0; q < 5; q++) {
            const double *p = m + (size_t)q * L + i, *c = p + TN__SSIM_R * C; /* symmetric taps */
            tn__vd acc = tn__vd_mul(tn__vd_set1(j->g[TN__SSIM_R]), tn__vd_load(c));
            for (k = 1; k <= TN__SSIM_R; k++)
                acc = tn__vd_madd(tn__vd_set1(j->g[TN__SSIM_R + k]),
                                  tn__vd_add(tn__vd_load(c - (size_t)k * C), tn__vd_load(c + (size_t)k * C)), acc);
            u[q] = acc;
        }
        vx = tn__vd_sub(u[2], tn__vd_mul(u[0], u[0]));
        vy = tn__vd_sub(u[3], tn__vd_mul(u[1], u[1]));
        vxy = tn__vd_sub(u[4], tn__vd_mul(u[0], u[1]));
        num = tn__vd_mul(tn__vd_add(tn__vd_mul(two, tn__vd_mul(u[0], u[1])), c1), tn__vd_add(tn__vd_mul(two, vxy), c2));
        den = tn__vd_mul(tn__vd_add(tn__vd_add(tn__vd_mul(u[0], u[0]), tn__vd_mul(u[1], u[1])), c1),
                         tn__vd_add(tn__vd_add(vx, vy), c2));
        tn__vd_store(s + i, tn__vd_div(num, den));
    }
    for (; i < n; i++) {
        double u[5];
        for (q = 0; q < 5; q++) {
            const double *p = m + (size_t)q * L + i;
            double acc = j->g[0] * p[0];
            for (k = 1; k < TN__SSIM_TAPS; k++) acc += j->g[k] * p[(size_t)k * C];
            u[q] = acc;
        }
        s[i] = tn__ssim_formula(u[0], u[1], u[2], u[3], u[4], j->c1, j->c2);
    }
}

static void tn__ssim_rows(void *ctx, size_t sb, size_t se)
{
    const tn__ssim_job *j = (const tn__ssim_job *)ctx;
    const size_t C = (size_t)j->C, L = (size_t)j->W * C, wv = (size_t)j->W - 2 * TN__SSIM_R;
    const size_t hv = (size_t)j->H - 2 * TN__SSIM_R;
    size_t s, y, x, c;
    for (s = sb; s < se; s++) {
        double *m = j->scratch + s * j->scratch_doubles, *srow = m + 5 * L;
        size_t y0 = tn__slot_begin(s, j->nslots, hv), y1 = tn__slot_begin(s + 1, j->nslots, hv);
        for (y = y0; y < y1; y++) {
            double *sum = j->rowsum + y * C, part[4];
            tn__ssim_vertical(j, y, m);
            tn__ssim_horizontal(j, m, srow);
            for (c = 0; c < C; c++) sum[c] = 0.0;
            if (C == 1) { /* four chains: the adds are latency-bound otherwise */
                part[0] = part[1] = part[2] = part[3] = 0.0;
                for (x = 0; x + 4 <= wv; x += 4)
                    part[0] += srow[x], part[1] += srow[x + 1], part[2] += srow[x + 2], part[3] += srow[x + 3];
                for (; x < wv; x++) part[0] += srow[x];
                sum[0] = (part[0] + part[1]) + (part[2] + part[3]);
            } else {
                for (x = 0; x < wv; x++)
                    for (c = 0; c < C; c++) sum[c] += srow[x * C + c];
            }
        }
    }
}

/* Checks the pair and picks the data range (<= 0: the reference's max - min). NaN/Inf samples
   are caught afterwards: every sample reaches the SSIM sum, so they turn it into NaN. */
static tn_status tn__metrics_prepare(const tn_image *ref, const tn_image *img, double *data_range, const char *what)
{
    tn_status st;
    float lo, hi;
    if ((st = tn__image_check(ref, what)) != TN_OK || (st = tn__image_check(img, what)) != TN_OK) return st;
    if (ref->width != img->width || ref->height != img->height || ref->channels != img->channels)
        return tn__fail(TN_ERR_SHAPE, "%s: reference is %d x %d x %d but the image is %d x %d x %d", what,
                        ref->width, ref->height, ref->channels, img->width, img->height, img->channels);
    if (ref->width < TN__SSIM_TAPS || ref->height < TN__SSIM_TAPS)
        return tn__fail(TN_ERR_INVALID_ARG, "%s: images of %d x %d are smaller than the 11 x 11 SSIM window", what,
                        ref->width, ref->height);
    if (*data_range != *data_range || *data_range > DBL_MAX)
        return tn__fail(TN_ERR_INVALID_ARG, "%s: data_range is not finite", what);
    if (*data_range <= 0.0) {
        if (tn_image_range(&lo, &hi, ref) != 0)
            return tn__fail(TN_ERR_NUMERIC, "%s: the reference has NaN/Inf samples", what);
        *data_range = (double)hi - (double)lo;
        if (*data_range <= 0.0)
            return tn__fail(TN_ERR_INVALID_ARG, "%s: the reference is constant; pass data_range", what);
    }
    return TN_OK;
}

static tn_status tn__ssim_compute(const tn_image *ref, const tn_image *img, double data_range, double *out)
{
    tn__ssim_job job;
    size_t hv, wv, bytes = 0, y, c, C;
    double total = 0.0, sigma = 1.5, gsum = 0.0;
    tn_status st;
    int k;
    memset(&job, 0, sizeof job);
    job.a = ref->data;
    job.b = img->data;
    job.W = ref->width;
    job.H = ref->height;
    job.C = ref->channels;
    C = (size_t)job.C;
    hv = (size_t)job.H - 2 * TN__SSIM_R;
    wv = (size_t)job.W - 2 * TN__SSIM_R;
    for (k = 0; k < TN__SSIM_TAPS; k++)
        gsum += job.g[k] = exp(-0.5 / (sigma * sigma) * (double)((k - TN__SSIM_R) * (k - TN__SSIM_R)));
    for (k = 0; k < TN__SSIM_TAPS; k++) job.g[k] /= gsum;
    job.c1 = (0.01 * data_range) * (0.01 * data_range);
    job.c2 = (0.03 * data_range) * (0.03 * data_range);
    job.nslots = tn__slot_count();
    job.scratch_doubles = 6 * (size_t)job.W * C;
    if ((st = tn__size4(job.nslots, job.scratch_doubles, sizeof(double), 1, &bytes)) != TN_OK) return st;
    job.scratch = (double *)tn__alloc(bytes);
    job.rowsum = (double *)tn__alloc(hv * C * sizeof(double));
    if (!job.scratch || !job.rowsum) {
        TN_FREE(job.scratch);
        TN_FREE(job.rowsum);
        return TN_ERR_OUT_OF_MEMORY;
    }
    tn_parallel_for(job.nslots, 1, tn__ssim_rows, &job);
    for (c = 0; c < C; c++) { /* mean per channel, then over channels, like skimage */
        double s = 0.0;
        for (y = 0; y < hv; y++) s += job.rowsum[y * C + c];
        total += s / ((double)hv * (double)wv);
    }
    TN_FREE(job.scratch);
    TN_FREE(job.rowsum);
    if (!(total >= -DBL_MAX && total <= DBL_MAX))
        return tn__fail(TN_ERR_NUMERIC, "ssim: NaN/Inf samples in the images (or a data range too small)");
    *out = total / (double)C;
    return TN_OK;
}

TN_API tn_status tn_ssim(double *ssim, const tn_image *ref, const tn_image *img, double data_range)
{
    double v;
    tn_status st;
    TN_ASSERT(ssim);
    if ((st = tn__metrics_prepare(ref, img, &data_range, "ssim")) != TN_OK) return st;
    if ((st = tn__ssim_compute(ref, img, data_range, &v)) != TN_OK) return st;
    *ssim = v;
    return TN_OK;
}

typedef struct tn__error_job {
    const float *a, *b;
    size_t L;          /* samples per row */
    double *sq, *ab;   /* per-row sums of squared and absolute differences */
} tn__error_job;

static void tn__error_rows(void *ctx, size_t b, size_t e)
{
    const tn__error_job *j = (const tn__error_job *)ctx;
    size_t y, i;
    for (y = b; y < e; y++) {
        const float *pa = j->a + y * j->L, *pb = j->b + y * j->L;
        double sq = 0.0, ab = 0.0;
        for (i = 0; i < j->L; i++) {
            double d = (double)pb[i] - (double)pa[i];
            sq += d * d;
            ab += fabs(d);
        }
        j->sq[y] = sq;
        j->ab[y] = ab;
    }
}

TN_API tn_status tn_compare(tn_metrics *out, const tn_image *ref, const tn_image *img, double data_range)
{
    tn_metrics m;
    tn__error_job job;
    double sq = 0.0, ab = 0.0, n;
    size_t y, H;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__metrics_prepare(ref, img, &data_range, "compare")) != TN_OK) return st;
    memset(&m, 0, sizeof m);
    if ((st = tn__ssim_compute(ref, img, data_range, &m.ssim)) != TN_OK) return st;
    H = (size_t)ref->height;
    job.a = ref->data;
    job.b = img->data;
    job.L = (size_t)ref->width * ref->channels;
    job.sq = (double *)tn__alloc(2 * H * sizeof(double));
    if (!job.sq) return TN_ERR_OUT_OF_MEMORY;
    job.ab = job.sq + H;
    tn_parallel_for(H, 16, tn__error_rows, &job);
    for (y = 0; y < H; y++) sq += job.sq[y], ab += job.ab[y];
    TN_FREE(job.sq);
    if (!(sq <= DBL_MAX)) return tn__fail(TN_ERR_NUMERIC, "compare: the squared error overflows");
    n = (double)job.L * (double)H;
    m.rmse = sqrt(sq / n);
    m.mae = ab / n;
    m.psnr = sq > 0.0 ? 10.0 * log10(data_range * data_range / (sq / n)) : HUGE_VAL;
    *out = m;
    return TN_OK;
}

