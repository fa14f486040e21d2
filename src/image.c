/* ============================================================================================
   @@image  tn_image and image operations
   ============================================================================================ */

/* A float32 raster, row-major, channels interleaved: pixel (x, y, c) is
   data[((size_t)y * width + x) * channels + c]. Heightmaps have one channel, in metres when the
   source says so (see tn_image_info), otherwise in the file's normalised [0, 1] scale. */
typedef struct tn_image {
    int width, height, channels;
    float *data;
} tn_image;

#define TN_PIXEL(img, x, y, c) \
    ((img)->data[((size_t)(y) * (size_t)(img)->width + (size_t)(x)) * (size_t)(img)->channels + (size_t)(c)])

/* Allocates a zero-filled image; frees nothing that *img held before. Caller frees with
   tn_image_free. Fails with TN_ERR_INVALID_ARG or TN_ERR_TOO_LARGE on bad sizes. */
TN_API tn_status tn_image_create(tn_image *img, int width, int height, int channels);
/* Frees img->data and zeroes the struct. Safe on a zeroed struct. */
TN_API void      tn_image_free(tn_image *img);
/* Deep copy into *dst (allocated here). */
TN_API tn_status tn_image_copy(tn_image *dst, const tn_image *src);
/* Minimum and maximum over all samples; NaNs are ignored. Returns the count of NaN/Inf samples. */
TN_API size_t    tn_image_range(float *lo, float *hi, const tn_image *img);

/* All operations below write a newly allocated *dst (caller frees); dst may not alias src unless
   stated. They fail with TN_ERR_INVALID_ARG on bad parameters and never touch *dst then. */

/* Copies the w x h window at (x, y); the window must lie inside src. */
TN_API tn_status tn_image_crop(tn_image *dst, const tn_image *src, int x, int y, int w, int h);

typedef enum tn_pad_mode { TN_PAD_ZERO = 0, TN_PAD_EDGE, TN_PAD_REFLECT } tn_pad_mode;
/* Adds borders; TN_PAD_REFLECT mirrors without repeating the edge (like numpy 'reflect'). */
TN_API tn_status tn_image_pad(tn_image *dst, const tn_image *src, int left, int top, int right, int bottom,
                              tn_pad_mode mode);

typedef enum tn_resize_filter { TN_RESIZE_BILINEAR = 0, TN_RESIZE_BICUBIC, TN_RESIZE_AREA, TN_RESIZE_NEAREST } tn_resize_filter;
/* Resamples to w x h with pixel centres aligned (align_corners = false). AREA averages the
   covered source area (use it to downsample); BICUBIC uses Keys a = -0.5 and clamps at edges. */
TN_API tn_status tn_image_resize(tn_image *dst, const tn_image *src, int w, int h, tn_resize_filter filter);

/* Separable Gaussian blur of every channel, any sigma > 0 (sigma 0 copies). Borders reflect
   (scipy 'reflect' = half-sample symmetric). dst may equal src (in place). Threaded. */
TN_API tn_status tn_image_blur(tn_image *dst, const tn_image *src, float sigma);

/* Central-difference gradients of channel 0 in height units per metre; dx, dy are the pixel
   spacings in metres (<= 0 means 1). gx points east (+x), gy points south (+y, down the rows).
   Either output may be NULL. */
TN_API tn_status tn_image_gradient(tn_image *gx, tn_image *gy, const tn_image *dem, float dx, float dy);
/* Slope in degrees (0 = flat). */
TN_API tn_status tn_image_slope(tn_image *dst, const tn_image *dem, float dx, float dy);
/* Unit surface normals as 3 channels (x east, y north, z up) in [-1, 1]; z_scale exaggerates. */
TN_API tn_status tn_image_normals(tn_image *dst, const tn_image *dem, float dx, float dy, float z_scale);

typedef struct tn_hillshade_opts {
    float azimuth_deg;   /* light direction, clockwise from north; 0 means the default 315 (north-west) */
    float altitude_deg;  /* sun elevation; 0 means the default 45 */
    float z_factor;      /* vertical exaggeration; 0 means 1 */
    float dx, dy;        /* pixel spacing in metres; 0 means "auto": relief-normalised so any DEM reads well */
} tn_hillshade_opts;
/* Lambertian hillshade in [0, 1], one channel. opts may be NULL for defaults. */
TN_API tn_status tn_image_hillshade(tn_image *dst, const tn_image *dem, const tn_hillshade_opts *opts);
/* The step a DEM's heights are stored in (channel 0): the smallest height difference between
   neighbours when at least 99 % of all such differences are whole multiples of it, else 0 (heights
   stored as floats, or resampled). An 8-bit heightmap gives its range / 255. With coarse_only,
   only a step of at least 0.1 x the DEM's mean |Laplacian| at 1 px, else 0: steps the terrain's
   own curvature does not dwarf (8-bit heightmaps: 1.1-1.7 steps), which the learned methods
   train without (their option dequantize). */
TN_API float     tn_image_height_step(const tn_image *dem, int coarse_only);
/* Removes the terraces of heights stored in coarse steps (channel 0 -> one channel): dst is the
   smoothest surface (least squared Laplacian) within step / 2 of dem everywhere, so rounding it
   to the same steps gives dem back. step <= 0 copies channel 0. Threaded; 200 passes over the
   raster. */
TN_API tn_status tn_image_dequantize(tn_image *dst, const tn_image *dem, float step);
/* Hypsometric terrain colours (water-blue, green lowlands, brown, rock grey, snow white) for
   heights mapped linearly from [lo, hi] (lo == hi: the DEM's own range). RGB in [0, 1]. */
TN_API tn_status tn_image_colour_ramp(tn_image *dst, const tn_image *dem, float lo, float hi);

/* A rectangle of pixels: columns x .. x + w - 1, rows y .. y + h - 1 (a tile of a world). */
typedef struct tn_rect { int x, y, w, h; } tn_rect;
/* "Compute this rectangle with a halo of h": r grown by `halo` pixels on every side and clipped
   to a width x height raster. An operation whose output pixel depends only on inputs at most
   `halo` pixels away (and on where the raster's edges are) gives exactly its whole-raster pixels
   of r when run on the grown rectangle alone and cropped at (r.x - grown.x, r.y - grown.y): each
   edge of the grown rectangle is either the raster's edge, which the whole run sees too, or at
   least `halo` pixels from r. Chains add their halos. (@@world builds every tile this way.) */
TN_API tn_rect tn_rect_halo(tn_rect r, int halo, int width, int height);


/* --------------------------------------------------------------------------------------------
   >>image  (@@image implementation)
   -------------------------------------------------------------------------------------------- */

TN_API tn_status tn_image_create(tn_image *img, int width, int height, int channels)
{
    size_t bytes = 0;
    tn_status st;
    TN_ASSERT(img);
    if (width <= 0 || height <= 0 || channels <= 0)
        return tn__fail(TN_ERR_INVALID_ARG, "image size %d x %d x %d is not positive", width, height, channels);
    st = tn__size4((size_t)width, (size_t)height, (size_t)channels, sizeof(float), &bytes);
    if (st) return st;
    img->data = (float *)tn__calloc(bytes);
    if (!img->data) {
        img->width = img->height = img->channels = 0;
        return TN_ERR_OUT_OF_MEMORY;
    }
    img->width = width;
    img->height = height;
    img->channels = channels;
    return TN_OK;
}

TN_API void tn_image_free(tn_image *img)
{
    if (!img) return;
    TN_FREE(img->data);
    img->data = NULL;
    img->width = img->height = img->channels = 0;
}

TN_API tn_status tn_image_copy(tn_image *dst, const tn_image *src)
{
    tn_status st = tn_image_create(dst, src->width, src->height, src->channels);
    if (st) return st;
    memcpy(dst->data, src->data, (size_t)src->width * src->height * src->channels * sizeof(float));
    return TN_OK;
}

TN_API size_t tn_image_range(float *lo, float *hi, const tn_image *img)
{
    size_t i, n = (size_t)img->width * img->height * img->channels, bad = 0;
    float mn = FLT_MAX, mx = -FLT_MAX;
    for (i = 0; i < n; i++) {
        float v = img->data[i];
        if (v != v || v > FLT_MAX || v < -FLT_MAX) { bad++; continue; }
        if (v < mn) mn = v;
        if (v > mx) mx = v;
    }
    if (mn > mx) mn = mx = 0.0f;
    if (lo) *lo = mn;
    if (hi) *hi = mx;
    return bad;
}

/* --------------------------------------------------------------------------------------------
   >>imageops  (part of @@image implementation)
   crop / pad / resize, Gaussian blur, gradients, slope, normals, hillshade, colour ramp.
   Blur is an exact separable FIR with scipy.ndimage's kernel (radius int(4 sigma + 0.5), weights
   exp(-x^2 / 2 sigma^2) normalised in double) and its 'reflect' border (half-sample symmetric,
   periodic with period 2n, so a kernel longer than the image folds onto at most 2n + 1 taps).
   Pass 1 filters rows (threads take bands of rows); pass 2 filters columns in blocks of 4 SIMD
   vectors, streaming down the rows through a small ring of row copies, so it runs in place and
   its working set stays in L1. Each output sample is made by the same instruction sequence
   whatever the thread split, so results are bit-identical for any thread count.
   The small SIMD layer (tn__vf float, tn__vd double) is shared with >>metrics.
   -------------------------------------------------------------------------------------------- */

#if defined(__AVX512F__)
#define TN__VF_N 16
typedef __m512 tn__vf;
#define tn__vf_load(p) _mm512_loadu_ps(p)
#define tn__vf_store(p, v) _mm512_storeu_ps((p), (v))
#define tn__vf_set1(x) _mm512_set1_ps(x)
#define tn__vf_add(a, b) _mm512_add_ps((a), (b))
#define tn__vf_sub(a, b) _mm512_sub_ps((a), (b))
#define tn__vf_mul(a, b) _mm512_mul_ps((a), (b))
#define tn__vf_madd(a, b, c) _mm512_fmadd_ps((a), (b), (c))
#define TN__VD_N 8
typedef __m512d tn__vd;
#define tn__vd_load(p) _mm512_loadu_pd(p)
#define tn__vd_loadf(p) _mm512_maskz_cvtps_pd((__mmask8)0xFF, _mm256_loadu_ps(p)) /* not cvtps_pd: g++ 12 false warning */
#define tn__vd_store(p, v) _mm512_storeu_pd((p), (v))
#define tn__vd_set1(x) _mm512_set1_pd(x)
#define tn__vd_add(a, b) _mm512_add_pd((a), (b))
#define tn__vd_sub(a, b) _mm512_sub_pd((a), (b))
#define tn__vd_mul(a, b) _mm512_mul_pd((a), (b))
#define tn__vd_div(a, b) _mm512_div_pd((a), (b))
#define tn__vd_madd(a, b, c) _mm512_fmadd_pd((a), (b), (c))
#define TN__PREFETCH(p) _mm_prefetch((const char *)(p), _MM_HINT_T0)
#elif defined(__AVX2__) && defined(__FMA__)
#define TN__VF_N 8
typedef __m256 tn__vf;
#define tn__vf_load(p) _mm256_loadu_ps(p)
#define tn__vf_store(p, v) _mm256_storeu_ps((p), (v))
#define tn__vf_set1(x) _mm256_set1_ps(x)
#define tn__vf_add(a, b) _mm256_add_ps((a), (b))
#define tn__vf_sub(a, b) _mm256_sub_ps((a), (b))
#define tn__vf_mul(a, b) _mm256_mul_ps((a), (b))
#define tn__vf_madd(a, b, c) _mm256_fmadd_ps((a), (b), (c))
#define TN__VD_N 4
typedef __m256d tn__vd;
#define tn__vd_load(p) _mm256_loadu_pd(p)
#define tn__vd_loadf(p) _mm256_cvtps_pd(_mm_loadu_ps(p))
#define tn__vd_store(p, v) _mm256_storeu_pd((p), (v))
#define tn__vd_set1(x) _mm256_set1_pd(x)
#define tn__vd_add(a, b) _mm256_add_pd((a), (b))
#define tn__vd_sub(a, b) _mm256_sub_pd((a), (b))
#define tn__vd_mul(a, b) _mm256_mul_pd((a), (b))
#define tn__vd_div(a, b) _mm256_div_pd((a), (b))
#define tn__vd_madd(a, b, c) _mm256_fmadd_pd((a), (b), (c))
#define TN__PREFETCH(p) _mm_prefetch((const char *)(p), _MM_HINT_T0)
#else /* portable scalar fallback: one lane */
#define TN__VF_N 1
typedef float tn__vf;
#define tn__vf_load(p) (*(p))
#define tn__vf_store(p, v) (*(p) = (v))
#define tn__vf_set1(x) (x)
#define tn__vf_add(a, b) ((a) + (b))
#define tn__vf_sub(a, b) ((a) - (b))
#define tn__vf_mul(a, b) ((a) * (b))
#define tn__vf_madd(a, b, c) ((a) * (b) + (c))
#define TN__VD_N 1
typedef double tn__vd;
#define tn__vd_load(p) (*(p))
#define tn__vd_loadf(p) ((double)*(p))
#define tn__vd_store(p, v) (*(p) = (v))
#define tn__vd_set1(x) (x)
#define tn__vd_add(a, b) ((a) + (b))
#define tn__vd_sub(a, b) ((a) - (b))
#define tn__vd_mul(a, b) ((a) * (b))
#define tn__vd_div(a, b) ((a) / (b))
#define tn__vd_madd(a, b, c) ((a) * (b) + (c))
#define TN__PREFETCH(p) ((void)(p))
#endif

static tn_status tn__image_check(const tn_image *img, const char *what)
{
    if (!img || !img->data || img->width <= 0 || img->height <= 0 || img->channels <= 0)
        return tn__fail(TN_ERR_INVALID_ARG, "%s: image is NULL or empty", what);
    return TN_OK;
}

/* Allocates w x h x c floats without zeroing (callers write every sample). */
static tn_status tn__image_alloc(tn_image *img, int w, int h, int c)
{
    size_t bytes = 0;
    tn_status st;
    if (w <= 0 || h <= 0 || c <= 0)
        return tn__fail(TN_ERR_INVALID_ARG, "image size %d x %d x %d is not positive", w, h, c);
    st = tn__size4((size_t)w, (size_t)h, (size_t)c, sizeof(float), &bytes);
    if (st) return st;
    img->data = (float *)tn__alloc(bytes);
    if (!img->data) return TN_ERR_OUT_OF_MEMORY;
    img->width = w;
    img->height = h;
    img->channels = c;
    return TN_OK;
}

/* Hands a finished result to the caller. When dst is the source its old buffer is freed;
   otherwise *dst is overwritten untouched (it may hold garbage). */
static void tn__image_give(tn_image *dst, const tn_image *src, tn_image *out)
{
    if (dst == src && dst->data != out->data) TN_FREE(dst->data);
    *dst = *out;
}

/* Threads take "slots": slot s of ns owns items [s*n/ns, (s+1)*n/ns) and its own scratch, so a
   tn_parallel_for over slot numbers gives every thread its private buffers. */
static size_t tn__slot_begin(size_t s, size_t ns, size_t n)
{
    return (size_t)((unsigned long long)n * s / ns);
}

static size_t tn__slot_count(void)
{
    int n = tn_get_threads();
    return (size_t)(n < 1 ? 1 : n);
}

/* scipy 'reflect' (half-sample symmetric): ... c b a | a b c | c b a ..., period 2n. */
static int tn__reflect_half(long long i, int n)
{
    long long p = 2LL * n, m = i % p;
    if (m < 0) m += p;
    return (int)(m >= n ? p - 1 - m : m);
}

/* numpy 'reflect' (whole-sample symmetric, edge not repeated): ... c b | a b c | b a ..., period 2n-2. */
TN__SHARED int tn__reflect_whole(long long i, int n)
{
    long long p = 2LL * n - 2, m;
    if (n == 1) return 0;
    m = i % p;
    if (m < 0) m += p;
    return (int)(m >= n ? p - m : m);
}

/* ---- crop / pad ---------------------------------------------------------------------------- */

/* Bilinear sample of channel c at (x, y), clamped to the image. */
TN__SHARED float tn__sample_bilinear(const tn_image *im, float x, float y, int c)
{
    int x0, y0, x1, y1;
    float fx, fy, a, b;
    x = tn__clampf(x, 0.0f, (float)(im->width - 1));
    y = tn__clampf(y, 0.0f, (float)(im->height - 1));
    x0 = (int)x; y0 = (int)y;
    x1 = x0 + 1 < im->width ? x0 + 1 : x0;
    y1 = y0 + 1 < im->height ? y0 + 1 : y0;
    fx = x - (float)x0; fy = y - (float)y0;
    a = TN_PIXEL(im, x0, y0, c) + fx * (TN_PIXEL(im, x1, y0, c) - TN_PIXEL(im, x0, y0, c));
    b = TN_PIXEL(im, x0, y1, c) + fx * (TN_PIXEL(im, x1, y1, c) - TN_PIXEL(im, x0, y1, c));
    return a + fy * (b - a);
}

TN_API tn_status tn_image_crop(tn_image *dst, const tn_image *src, int x, int y, int w, int h)
{
    tn_image out;
    size_t rowf;
    int r;
    tn_status st;
    TN_ASSERT(dst);
    if ((st = tn__image_check(src, "crop")) != TN_OK) return st;
    if (w <= 0 || h <= 0 || x < 0 || y < 0 || x > src->width - w || y > src->height - h)
        return tn__fail(TN_ERR_INVALID_ARG, "crop: window %d x %d at (%d, %d) is not inside the %d x %d image",
                        w, h, x, y, src->width, src->height);
    if ((st = tn__image_alloc(&out, w, h, src->channels)) != TN_OK) return st;
    rowf = (size_t)w * (size_t)src->channels;
    for (r = 0; r < h; r++)
        memcpy(out.data + (size_t)r * rowf, &TN_PIXEL(src, x, y + r, 0), rowf * sizeof(float));
    tn__image_give(dst, src, &out);
    return TN_OK;
}

/* Source index for a padded coordinate, or -1 for a zero sample. */
static int tn__pad_index(long long i, int n, tn_pad_mode mode)
{
    if (i >= 0 && i < n) return (int)i;
    if (mode == TN_PAD_ZERO) return -1;
    if (mode == TN_PAD_EDGE) return i < 0 ? 0 : n - 1;
    return tn__reflect_whole(i, n);
}

TN_API tn_status tn_image_pad(tn_image *dst, const tn_image *src, int left, int top, int right, int bottom,
                              tn_pad_mode mode)
{
    tn_image out;
    long long nw, nh;
    int *colmap, ox, oy, c, C;
    tn_status st;
    TN_ASSERT(dst);
    if ((st = tn__image_check(src, "pad")) != TN_OK) return st;
    if (left < 0 || top < 0 || right < 0 || bottom < 0)
        return tn__fail(TN_ERR_INVALID_ARG, "pad: negative border (%d, %d, %d, %d)", left, top, right, bottom);
    if (mode != TN_PAD_ZERO && mode != TN_PAD_EDGE && mode != TN_PAD_REFLECT)
        return tn__fail(TN_ERR_INVALID_ARG, "pad: unknown mode %d", (int)mode);
    nw = (long long)src->width + left + right;
    nh = (long long)src->height + top + bottom;
    if (nw > INT_MAX || nh > INT_MAX)
        return tn__fail(TN_ERR_TOO_LARGE, "pad: result %lld x %lld is too large", nw, nh);
    colmap = (int *)tn__alloc((size_t)nw * sizeof(int));
    if (!colmap) return TN_ERR_OUT_OF_MEMORY;
    if ((st = tn__image_alloc(&out, (int)nw, (int)nh, src->channels)) != TN_OK) {
        TN_FREE(colmap);
        return st;
    }
    C = src->channels;
    for (ox = 0; ox < (int)nw; ox++) colmap[ox] = tn__pad_index((long long)ox - left, src->width, mode);
    for (oy = 0; oy < (int)nh; oy++) {
        int sy = tn__pad_index((long long)oy - top, src->height, mode);
        float *o = out.data + (size_t)oy * (size_t)nw * (size_t)C;
        for (ox = 0; ox < (int)nw; ox++, o += C) {
            if (sy < 0 || colmap[ox] < 0)
                for (c = 0; c < C; c++) o[c] = 0.0f;
            else
                memcpy(o, &TN_PIXEL(src, colmap[ox], sy, 0), (size_t)C * sizeof(float));
        }
    }
    TN_FREE(colmap);
    tn__image_give(dst, src, &out);
    return TN_OK;
}

/* ---- resize ----------------------------------------------------------------------------------
   Separable: per output coordinate a short list of (source index, weight) taps, applied along x
   (source rows -> temp) and then along y (temp rows -> dst). Pixel i covers [i, i+1), so the
   centre of output pixel o sits at source (o + 0.5) * scale - 0.5. */

typedef struct tn__taps {
    int ntaps;    /* taps per output coordinate (unused ones have weight 0) */
    int *idx;     /* [n_out * ntaps] source indices, always in range */
    float *wt;    /* [n_out * ntaps] */
} tn__taps;

static float tn__keys_cubic(double t) /* Keys (1981) kernel, a = -0.5 */
{
    const double a = -0.5;
    t = fabs(t);
    if (t <= 1.0) return (float)(((a + 2.0) * t - (a + 3.0)) * t * t + 1.0);
    if (t < 2.0) return (float)(((a * t - 5.0 * a) * t + 8.0 * a) * t - 4.0 * a);
    return 0.0f;
}

static tn_status tn__taps_build(tn__taps *tp, int n_in, int n_out, tn_resize_filter filter)
{
    double scale = (double)n_in / (double)n_out;
    size_t cnt = 0;
    int o, k, T;
    tn_status st;
    switch (filter) {
    case TN_RESIZE_NEAREST: T = 1; break;
    case TN_RESIZE_BILINEAR: T = 2; break;
    case TN_RESIZE_BICUBIC: T = 4; break;
    default: T = (int)ceil(scale) + 2; break;
    }
    tp->ntaps = T;
    if ((st = tn__size4((size_t)n_out, (size_t)T, 1, 1, &cnt)) != TN_OK) return st;
    tp->idx = (int *)tn__alloc(cnt * sizeof(int));
    tp->wt = (float *)tn__alloc(cnt * sizeof(float));
    if (!tp->idx || !tp->wt) {
        TN_FREE(tp->idx);
        TN_FREE(tp->wt);
        tp->idx = NULL;
        tp->wt = NULL;
        return TN_ERR_OUT_OF_MEMORY;
    }
    for (o = 0; o < n_out; o++) {
        int *ix = tp->idx + (size_t)o * T;
        float *w = tp->wt + (size_t)o * T;
        double s = (o + 0.5) * scale - 0.5;
        for (k = 0; k < T; k++) ix[k] = 0, w[k] = 0.0f;
        if (filter == TN_RESIZE_NEAREST) {
            ix[0] = tn__clampi((int)floor((o + 0.5) * scale), 0, n_in - 1);
            w[0] = 1.0f;
        } else if (filter == TN_RESIZE_BILINEAR) {
            double i0;
            if (s < 0.0) s = 0.0;
            if (s > n_in - 1) s = n_in - 1;
            i0 = floor(s);
            ix[0] = (int)i0;
            ix[1] = tn__clampi((int)i0 + 1, 0, n_in - 1);
            w[1] = (float)(s - i0);
            w[0] = 1.0f - w[1];
        } else if (filter == TN_RESIZE_BICUBIC) {
            double i0 = floor(s), t = s - i0;
            for (k = 0; k < 4; k++) {
                ix[k] = tn__clampi((int)i0 - 1 + k, 0, n_in - 1);
                w[k] = tn__keys_cubic(t - (k - 1));
            }
        } else { /* area: overlap of [o, o+1) * scale with each source pixel */
            double x0 = o * scale, x1 = (o + 1) * scale;
            int i = (int)floor(x0), n = 0;
            for (; i < n_in && (double)i < x1 && n < T; i++) {
                double ov = (x1 < i + 1.0 ? x1 : i + 1.0) - (x0 > i ? x0 : (double)i);
                if (ov <= 0.0) continue;
                ix[n] = i;
                w[n++] = (float)(ov / (x1 - x0));
            }
            for (k = n; k < T; k++) ix[k] = ix[0];
        }
    }
    return TN_OK;
}

static void tn__taps_free(tn__taps *tp)
{
    TN_FREE(tp->idx);
    TN_FREE(tp->wt);
}

typedef struct tn__resize_job {
    const tn_image *src;
    float *tmp, *out;        /* tmp: src->height rows of out_w pixels */
    int out_w;
    const tn__taps *tx, *ty;
} tn__resize_job;

static void tn__resize_rows_x(void *ctx, size_t b, size_t e)
{
    const tn__resize_job *j = (const tn__resize_job *)ctx;
    int C = j->src->channels, T = j->tx->ntaps, x, k, c;
    size_t y;
    for (y = b; y < e; y++) {
        const float *s = j->src->data + y * (size_t)j->src->width * C;
        float *t = j->tmp + y * (size_t)j->out_w * C;
        for (x = 0; x < j->out_w; x++, t += C) {
            const int *ix = j->tx->idx + (size_t)x * T;
            const float *w = j->tx->wt + (size_t)x * T;
            for (c = 0; c < C; c++) {
                float acc = 0.0f;
                for (k = 0; k < T; k++) acc += w[k] * s[(size_t)ix[k] * C + c];
                t[c] = acc;
            }
        }
    }
}

static void tn__resize_rows_y(void *ctx, size_t b, size_t e)
{
    const tn__resize_job *j = (const tn__resize_job *)ctx;
    size_t L = (size_t)j->out_w * j->src->channels, y, i;
    int T = j->ty->ntaps, k;
    for (y = b; y < e; y++) {
        const int *iy = j->ty->idx + y * T;
        const float *w = j->ty->wt + y * T;
        float *o = j->out + y * L;
        const float *r0 = j->tmp + (size_t)iy[0] * L;
        for (i = 0; i < L; i++) o[i] = w[0] * r0[i];
        for (k = 1; k < T; k++) {
            const float *r = j->tmp + (size_t)iy[k] * L;
            float wk = w[k];
            if (wk == 0.0f) continue;
            for (i = 0; i < L; i++) o[i] += wk * r[i];
        }
    }
}

TN_API tn_status tn_image_resize(tn_image *dst, const tn_image *src, int w, int h, tn_resize_filter filter)
{
    tn_image out, tmp;
    tn__taps tx, ty;
    tn__resize_job job;
    tn_status st;
    TN_ASSERT(dst);
    if ((st = tn__image_check(src, "resize")) != TN_OK) return st;
    if (w <= 0 || h <= 0) return tn__fail(TN_ERR_INVALID_ARG, "resize: target size %d x %d is not positive", w, h);
    if ((int)filter < 0 || filter > TN_RESIZE_NEAREST)
        return tn__fail(TN_ERR_INVALID_ARG, "resize: unknown filter %d", (int)filter);
    memset(&tx, 0, sizeof tx);
    memset(&ty, 0, sizeof ty);
    tmp.data = out.data = NULL;
    /* images first: their size checks refuse absurd targets before w + h taps are built */
    if ((st = tn__image_alloc(&tmp, w, src->height, src->channels)) != TN_OK ||
        (st = tn__image_alloc(&out, w, h, src->channels)) != TN_OK ||
        (st = tn__taps_build(&tx, src->width, w, filter)) != TN_OK ||
        (st = tn__taps_build(&ty, src->height, h, filter)) != TN_OK) {
        tn__taps_free(&tx);
        tn__taps_free(&ty);
        TN_FREE(tmp.data);
        TN_FREE(out.data);
        return st;
    }
    job.src = src;
    job.tmp = tmp.data;
    job.out = out.data;
    job.out_w = w;
    job.tx = &tx;
    job.ty = &ty;
    tn_parallel_for((size_t)src->height, 16, tn__resize_rows_x, &job);
    tn_parallel_for((size_t)h, 16, tn__resize_rows_y, &job);
    tn__taps_free(&tx);
    tn__taps_free(&ty);
    TN_FREE(tmp.data);
    tn__image_give(dst, src, &out);
    return TN_OK;
}

/* ---- Gaussian blur --------------------------------------------------------------------------- */

/* Half kernel w[0..*radius] (w[k] weighs offsets -k and +k) for an axis of n samples, built like
   scipy's _gaussian_kernel1d. When the radius reaches n the reflected signal is periodic (2n), so
   the taps fold onto offsets -n..n; for sigma >= 4n the folded kernel is flat (the truncated
   tails move it by < 1e-4 relative). */
static float *tn__gauss_half_kernel(double sigma, int n, int *radius)
{
    double rd = floor(4.0 * sigma + 0.5), s2 = sigma * sigma;
    float *w;
    int k;
    if (rd < n) {
        int r = (int)rd;
        double *phi = (double *)tn__alloc(((size_t)r + 1) * sizeof(double)), sum;
        w = (float *)tn__alloc(((size_t)r + 1) * sizeof(float));
        if (!phi || !w) {
            TN_FREE(phi);
            TN_FREE(w);
            return NULL;
        }
        sum = phi[0] = 1.0;
        for (k = 1; k <= r; k++) sum += 2.0 * (phi[k] = exp(-0.5 / s2 * (double)k * (double)k));
        for (k = 0; k <= r; k++) w[k] = (float)(phi[k] / sum);
        TN_FREE(phi);
        *radius = r;
        return w;
    }
    w = (float *)tn__alloc(((size_t)n + 1) * sizeof(float));
    if (!w) return NULL;
    *radius = n;
    if (sigma >= 4.0 * n) {
        for (k = 0; k < n; k++) w[k] = (float)(1.0 / (2.0 * n));
        w[n] = (float)(1.0 / (4.0 * n)); /* offsets -n and +n are the same sample: half each */
    } else { /* rd <= 16 n + 1 here */
        long long r = (long long)rd, j, p = 2LL * n;
        double *G = (double *)tn__calloc((size_t)p * sizeof(double)), sum = 0.0;
        if (!G) {
            TN_FREE(w);
            return NULL;
        }
        for (j = -r; j <= r; j++) sum += exp(-0.5 / s2 * (double)j * (double)j);
        for (j = -r; j <= r; j++) G[((j % p) + p) % p] += exp(-0.5 / s2 * (double)j * (double)j) / sum;
        for (k = 0; k < n; k++) w[k] = (float)G[k];
        w[n] = (float)(0.5 * G[n]);
        TN_FREE(G);
    }
    return w;
}

#define TN__BLUR_BLOCK (4 * TN__VF_N) /* floats per column block / per row step: 4 vectors */
#define TN__BLUR_COLS TN__BLUR_BLOCK /* column pass: floats per block (wider spills the ring out of L1) */
#define TN__BLUR_PREFETCH_ROWS 8

typedef struct tn__blur_job {
    float *data;              /* pass 1 reads src, writes data; pass 2 works in place on data */
    const float *src;
    int W, H, C;
    const float *wx, *wy;     /* half kernels */
    int rx, ry;               /* their radii */
    float *scratch;           /* nslots * scratch_floats */
    size_t nslots, scratch_floats;
} tn__blur_job;

/* out[i] = w0 c[i] + sum_k wk (c[i - k*step] + c[i + k*step]) for i in [0, n), n a multiple of
   4 vectors (callers leave room). Folding the symmetric taps halves the multiplies; the row pass
   (step C, unaligned loads that split cache lines) is bound by loads, the column pass by FMAs. */
static void tn__blur_fir(float *out, const float *c, size_t n, const float *w, int r, size_t step)
{
    size_t i;
    int k;
    for (i = 0; i < n; i += TN__BLUR_BLOCK) {
        const float *p = c + i;
        tn__vf w0 = tn__vf_set1(w[0]);
        tn__vf a0 = tn__vf_mul(w0, tn__vf_load(p));
        tn__vf a1 = tn__vf_mul(w0, tn__vf_load(p + TN__VF_N));
        tn__vf a2 = tn__vf_mul(w0, tn__vf_load(p + 2 * TN__VF_N));
        tn__vf a3 = tn__vf_mul(w0, tn__vf_load(p + 3 * TN__VF_N));
        for (k = 1; k <= r; k++) {
            const float *lo = p - (size_t)k * step, *hi = p + (size_t)k * step;
            tn__vf wk = tn__vf_set1(w[k]);
            a0 = tn__vf_madd(wk, tn__vf_add(tn__vf_load(lo), tn__vf_load(hi)), a0);
            a1 = tn__vf_madd(wk, tn__vf_add(tn__vf_load(lo + TN__VF_N), tn__vf_load(hi + TN__VF_N)), a1);
            a2 = tn__vf_madd(wk, tn__vf_add(tn__vf_load(lo + 2 * TN__VF_N), tn__vf_load(hi + 2 * TN__VF_N)), a2);
            a3 = tn__vf_madd(wk, tn__vf_add(tn__vf_load(lo + 3 * TN__VF_N), tn__vf_load(hi + 3 * TN__VF_N)), a3);
        }
        tn__vf_store(out + i, a0);
        tn__vf_store(out + i + TN__VF_N, a1);
        tn__vf_store(out + i + 2 * TN__VF_N, a2);
        tn__vf_store(out + i + 3 * TN__VF_N, a3);
    }
}

/* Row length rounded up to whole 4-vector blocks of tn__blur_fir. */
static size_t tn__blur_row_round(size_t L)
{
    return (L + TN__BLUR_BLOCK - 1) / TN__BLUR_BLOCK * TN__BLUR_BLOCK;
}

/* Pass 1: each row is copied into a reflect-padded buffer, filtered, and written back.
   Scratch per slot: padded row (r*C | row | r*C | zero slack up to the rounded length), output. */
static void tn__blur_rows(void *ctx, size_t sb, size_t se)
{
    const tn__blur_job *j = (const tn__blur_job *)ctx;
    const size_t C = (size_t)j->C, L = (size_t)j->W * C, nr = tn__blur_row_round(L), rc = (size_t)j->rx * C;
    size_t s, y;
    int p;
    for (s = sb; s < se; s++) {
        float *pad = j->scratch + s * j->scratch_floats, *out = pad + nr + 2 * rc;
        size_t y0 = tn__slot_begin(s, j->nslots, (size_t)j->H), y1 = tn__slot_begin(s + 1, j->nslots, (size_t)j->H);
        memset(pad + 2 * rc + L, 0, (nr - L) * sizeof(float)); /* read, results discarded */
        for (y = y0; y < y1; y++) {
            const float *row = j->src + y * L;
            for (p = -j->rx; p < 0; p++)
                memcpy(pad + (size_t)(p + j->rx) * C, row + (size_t)tn__reflect_half(p, j->W) * C, C * sizeof(float));
            memcpy(pad + rc, row, L * sizeof(float));
            for (p = j->W; p < j->W + j->rx; p++)
                memcpy(pad + (size_t)(p + j->rx) * C, row + (size_t)tn__reflect_half(p, j->W) * C, C * sizeof(float));
            tn__blur_fir(out, pad + rc, L, j->wx, j->rx, C);
            memcpy(j->data + y * L, out, L * sizeof(float));
        }
    }
}

/* Pass 2 on one block of columns [c0, c0 + bw): streams virtual rows v = -r .. H-1+r (the
   reflected extension) through a ring of 2r+1 slots stored twice, so the 2r+1 rows under the
   kernel are always contiguous. Rows are copied in before they are overwritten; rows past the
   bottom are reflections of rows still in the ring. */
static void tn__blur_column_block(const tn__blur_job *j, float *ring, float *tmp, size_t c0, size_t bw)
{
    const int r = j->ry, H = j->H;
    const size_t cap = 2 * (size_t)r + 1, L = (size_t)j->W * j->C, B = TN__BLUR_COLS;
    long long v;
    int y;
    for (v = -r; v < (long long)H + r; v++) {
        size_t slot = (size_t)(v + r) % cap;
        float *d = ring + slot * B;
        if (v < H) {
            const float *srow = j->data + (size_t)(v < 0 ? -v - 1 : v) * L + c0;
            size_t q;
            if (v >= 0 && v + TN__BLUR_PREFETCH_ROWS < H) /* rows are a page apart: no HW prefetch */
                for (q = 0; q < bw; q += 16) TN__PREFETCH(srow + TN__BLUR_PREFETCH_ROWS * L + q);
            memcpy(d, srow, bw * sizeof(float));
        } else { /* reflection of virtual row 2H-1-v, still in the ring */
            memcpy(d, ring + ((size_t)(2LL * H - 1 - v + r) % cap) * B, bw * sizeof(float));
        }
        memcpy(d + cap * B, d, bw * sizeof(float));
        if (v < r) continue;
        y = (int)(v - r); /* rows y-r .. y+r are now in slots y % cap .. y % cap + 2r */
        tn__blur_fir(tmp, ring + ((size_t)y % cap + (size_t)r) * B, B, j->wy, r, B);
        memcpy(j->data + (size_t)y * L + c0, tmp, bw * sizeof(float));
    }
}

static void tn__blur_cols(void *ctx, size_t sb, size_t se)
{
    const tn__blur_job *j = (const tn__blur_job *)ctx;
    size_t L = (size_t)j->W * j->C, nblocks = (L + TN__BLUR_COLS - 1) / TN__BLUR_COLS, s, b;
    size_t ringf = 2 * (2 * (size_t)j->ry + 1) * TN__BLUR_COLS;
    for (s = sb; s < se; s++) {
        float *ring = j->scratch + s * j->scratch_floats, *tmp = ring + ringf;
        size_t b0 = tn__slot_begin(s, j->nslots, nblocks), b1 = tn__slot_begin(s + 1, j->nslots, nblocks);
        memset(ring, 0, ringf * sizeof(float)); /* lanes past a partial block stay finite */
        for (b = b0; b < b1; b++) {
            size_t c0 = b * TN__BLUR_COLS, bw = L - c0 < TN__BLUR_COLS ? L - c0 : TN__BLUR_COLS;
            tn__blur_column_block(j, ring, tmp, c0, bw);
        }
    }
}

TN_API tn_status tn_image_blur(tn_image *dst, const tn_image *src, float sigma)
{
    tn_image out;
    tn__blur_job job;
    float *wx = NULL, *wy = NULL;
    size_t rowf, colf, bytes = 0;
    tn_status st;
    TN_ASSERT(dst);
    if ((st = tn__image_check(src, "blur")) != TN_OK) return st;
    if (!(sigma >= 0.0f) || sigma > FLT_MAX) return tn__fail(TN_ERR_INVALID_ARG, "blur: sigma %g is not >= 0 and finite", (double)sigma);
    out = *src;
    if (dst != src) {
        if ((st = tn__image_alloc(&out, src->width, src->height, src->channels)) != TN_OK) return st;
        if (sigma == 0.0f)
            memcpy(out.data, src->data, (size_t)src->width * src->height * src->channels * sizeof(float));
    }
    if (sigma > 0.0f) {
        memset(&job, 0, sizeof job);
        job.W = src->width;
        job.H = src->height;
        job.C = src->channels;
        wx = tn__gauss_half_kernel(sigma, job.W, &job.rx);
        wy = wx ? tn__gauss_half_kernel(sigma, job.H, &job.ry) : NULL;
        job.nslots = tn__slot_count();
        /* per slot: pass 1 padded row + output row, pass 2 doubled ring + one block */
        rowf = 2 * tn__blur_row_round((size_t)job.W * job.C) + 2 * (size_t)job.rx * job.C;
        colf = 2 * (2 * (size_t)job.ry + 1) * TN__BLUR_COLS + TN__BLUR_COLS;
        job.scratch_floats = rowf > colf ? rowf : colf;
        st = !wy ? TN_ERR_OUT_OF_MEMORY : tn__size4(job.nslots, job.scratch_floats, sizeof(float), 1, &bytes);
        job.scratch = st ? NULL : (float *)tn__alloc(bytes);
        if (!job.scratch) {
            if (!st) st = TN_ERR_OUT_OF_MEMORY;
            TN_FREE(wx);
            TN_FREE(wy);
            if (dst != src) TN_FREE(out.data);
            return st;
        }
        job.src = src->data;
        job.data = out.data;
        job.wx = wx;
        job.wy = wy;
        tn_parallel_for(job.nslots, 1, tn__blur_rows, &job);
        tn_parallel_for(job.nslots, 1, tn__blur_cols, &job);
        TN_FREE(job.scratch);
        TN_FREE(wx);
        TN_FREE(wy);
    }
    if (dst != src) tn__image_give(dst, src, &out);
    return TN_OK;
}

/* ---- gradients, slope, normals, hillshade ---------------------------------------------------- */

/* Central differences of channel 0 (one-sided at the borders, like numpy.gradient). */
static float tn__grad_x(const tn_image *d, int x, int y)
{
    int x0 = x > 0 ? x - 1 : x, x1 = x < d->width - 1 ? x + 1 : x;
    if (x1 == x0) return 0.0f;
    return (TN_PIXEL(d, x1, y, 0) - TN_PIXEL(d, x0, y, 0)) / (float)(x1 - x0);
}

static float tn__grad_y(const tn_image *d, int x, int y)
{
    int y0 = y > 0 ? y - 1 : y, y1 = y < d->height - 1 ? y + 1 : y;
    if (y1 == y0) return 0.0f;
    return (TN_PIXEL(d, x, y1, 0) - TN_PIXEL(d, x, y0, 0)) / (float)(y1 - y0);
}

typedef enum tn__terrain_op { TN__OP_GRAD, TN__OP_SLOPE, TN__OP_NORMALS, TN__OP_SHADE, TN__OP_RAMP } tn__terrain_op;

typedef struct tn__terrain_job {
    tn__terrain_op op;
    const tn_image *dem;
    float *out0, *out1;           /* gx/gy, or the single output */
    float ix, iy;                 /* 1 / pixel spacing, times the z factor where one applies */
    float lx, ly, lz;             /* unit vector towards the light (east, north, up) */
    float lo, inv_span;           /* colour ramp mapping */
} tn__terrain_job;

static void tn__colour_at(float t, float *rgb);

/* Horn (1981) 3x3 weighted slope; edge pixels reuse the nearest row/column. */
static void tn__horn(const tn_image *d, int x, int y, float *dzdx, float *dzdy)
{
    int xm = x > 0 ? x - 1 : x, xp = x < d->width - 1 ? x + 1 : x;
    int ym = y > 0 ? y - 1 : y, yp = y < d->height - 1 ? y + 1 : y;
    float a = TN_PIXEL(d, xm, ym, 0), b = TN_PIXEL(d, x, ym, 0), c = TN_PIXEL(d, xp, ym, 0);
    float e = TN_PIXEL(d, xm, y, 0), f = TN_PIXEL(d, xp, y, 0);
    float g = TN_PIXEL(d, xm, yp, 0), h = TN_PIXEL(d, x, yp, 0), i = TN_PIXEL(d, xp, yp, 0);
    float sx = (float)(xp - xm) * 4.0f, sy = (float)(yp - ym) * 4.0f;
    *dzdx = sx > 0.0f ? ((c + 2.0f * f + i) - (a + 2.0f * e + g)) / sx : 0.0f;
    *dzdy = sy > 0.0f ? ((g + 2.0f * h + i) - (a + 2.0f * b + c)) / sy : 0.0f; /* towards +y (south) */
}

static void tn__terrain_rows(void *ctx, size_t b, size_t e)
{
    const tn__terrain_job *j = (const tn__terrain_job *)ctx;
    const tn_image *d = j->dem;
    int x, y;
    for (y = (int)b; y < (int)e; y++) {
        size_t o = (size_t)y * d->width;
        for (x = 0; x < d->width; x++, o++) {
            float gx, gy, n;
            switch (j->op) {
            case TN__OP_GRAD:
                if (j->out0) j->out0[o] = tn__grad_x(d, x, y) * j->ix;
                if (j->out1) j->out1[o] = tn__grad_y(d, x, y) * j->iy;
                break;
            case TN__OP_SLOPE:
                gx = tn__grad_x(d, x, y) * j->ix;
                gy = tn__grad_y(d, x, y) * j->iy;
                j->out0[o] = (float)(atan(sqrt((double)gx * gx + (double)gy * gy)) * (180.0 / 3.14159265358979323846));
                break;
            case TN__OP_NORMALS: /* surface z = h(east, north): n ~ (-dh/deast, -dh/dnorth, 1) */
                gx = tn__grad_x(d, x, y) * j->ix;
                gy = tn__grad_y(d, x, y) * j->iy; /* dh/dsouth = -dh/dnorth */
                if (fabsf(gx) <= 1e18f && fabsf(gy) <= 1e18f) {
                    n = 1.0f / sqrtf(gx * gx + gy * gy + 1.0f);
                    j->out0[3 * o] = -gx * n;
                    j->out0[3 * o + 1] = gy * n;
                    j->out0[3 * o + 2] = n;
                } else { /* near-vertical (huge z_scale): gx * gx would overflow to Inf and give NaN */
                    double dgx = (double)tn__grad_x(d, x, y) * j->ix, dgy = (double)tn__grad_y(d, x, y) * j->iy;
                    double dn = 1.0 / sqrt(dgx * dgx + dgy * dgy + 1.0);
                    j->out0[3 * o] = (float)(-dgx * dn);
                    j->out0[3 * o + 1] = (float)(dgy * dn);
                    j->out0[3 * o + 2] = (float)dn;
                }
                break;
            case TN__OP_SHADE:
                tn__horn(d, x, y, &gx, &gy);
                gx *= j->ix;
                gy *= j->iy;
                n = (-gx * j->lx + gy * j->ly + j->lz) / sqrtf(gx * gx + gy * gy + 1.0f);
                j->out0[o] = n > 0.0f ? (n < 1.0f ? n : 1.0f) : 0.0f; /* NaN -> 0 too */
                break;
            case TN__OP_RAMP: {
                float t = (TN_PIXEL(d, x, y, 0) - j->lo) * j->inv_span;
                tn__colour_at(t, j->out0 + 3 * o);
                break;
            }
            }
        }
    }
}

static size_t tn__row_grain(int width) { return (size_t)(width >= 16384 ? 1 : 16384 / width); }

typedef struct tn__finite_job { const tn_image *dem; uint8_t *bad; } tn__finite_job;

/* bad[y] = 1 where row y of channel 0 holds a NaN/Inf. */
static void tn__finite_rows(void *ctx, size_t y0, size_t y1)
{
    const tn__finite_job *j = (const tn__finite_job *)ctx;
    const size_t w = (size_t)j->dem->width, C = (size_t)j->dem->channels;
    size_t x, y;
    for (y = y0; y < y1; y++) {
        const float *r = j->dem->data + y * w * C;
        int ok = 1;
        for (x = 0; x < w; x++) ok &= r[x * C] >= -FLT_MAX && r[x * C] <= FLT_MAX;
        j->bad[y] = (uint8_t)!ok;
    }
}

/* Fails with TN_ERR_NUMERIC naming the first NaN/Inf of channel 0 in raster order (rows are
   scanned in parallel: a 4096 x 4096 DEM takes a while on one core). */
static tn_status tn__dem_finite(const tn_image *dem, const char *what)
{
    const size_t w = (size_t)dem->width, h = (size_t)dem->height, C = (size_t)dem->channels;
    tn__finite_job j;
    size_t x, y;
    j.dem = dem;
    j.bad = (uint8_t *)tn__alloc(h);
    if (!j.bad) return TN_ERR_OUT_OF_MEMORY;
    tn_parallel_for(h, tn__row_grain(dem->width), tn__finite_rows, &j);
    for (y = 0; y < h && !j.bad[y]; y++) {}
    TN_FREE(j.bad);
    if (y == h) return TN_OK;
    for (x = 0; x + 1 < w && dem->data[(y * w + x) * C] >= -FLT_MAX && dem->data[(y * w + x) * C] <= FLT_MAX; x++) {}
    return tn__fail(TN_ERR_NUMERIC, "%s: NaN/Inf height at pixel (%d, %d)", what, (int)x, (int)y);
}

/* Checks a DEM for extraction and rendering: non-empty, at least min_side pixels a side, channel 0 finite. */
TN__SHARED tn_status tn__dem_check(const tn_image *dem, int min_side, const char *what)
{
    if (!dem || !dem->data || dem->width <= 0 || dem->height <= 0 || dem->channels <= 0)
        return tn__fail(TN_ERR_EMPTY, "%s: the DEM is empty", what);
    if (dem->width < min_side || dem->height < min_side)
        return tn__fail(TN_ERR_INVALID_ARG, "%s: the DEM must be at least %d x %d pixels", what, min_side, min_side);
    return tn__dem_finite(dem, what);
}

/* Pixel spacing: <= 0 means 1; returns 1 / spacing. */
/* 1 / spacing for dx and dy (<= 0 means 1). NaN/Inf, or a spacing so small that its inverse
   (times scale) overflows, would give NaN/Inf or all-zero gradients: refused instead. */
static tn_status tn__inv_spacing(float dx, float dy, float scale, float *ix, float *iy, const char *what)
{
    if (!(fabsf(dx) <= FLT_MAX && fabsf(dy) <= FLT_MAX))
        return tn__fail(TN_ERR_INVALID_ARG, "%s: pixel spacing %g x %g is not finite", what, (double)dx, (double)dy);
    *ix = (float)((dx > 0.0f ? 1.0 / dx : 1.0) * scale);
    *iy = (float)((dy > 0.0f ? 1.0 / dy : 1.0) * scale);
    if (!(fabsf(*ix) <= FLT_MAX && fabsf(*iy) <= FLT_MAX))
        return tn__fail(TN_ERR_INVALID_ARG, "%s: pixel spacing %g x %g is too small", what, (double)dx, (double)dy);
    return TN_OK;
}

TN_API tn_status tn_image_gradient(tn_image *gx, tn_image *gy, const tn_image *dem, float dx, float dy)
{
    tn_image ox, oy;
    tn__terrain_job job;
    tn_status st;
    if ((st = tn__image_check(dem, "gradient")) != TN_OK) return st;
    memset(&job, 0, sizeof job);
    if ((st = tn__inv_spacing(dx, dy, 1.0f, &job.ix, &job.iy, "gradient")) != TN_OK) return st;
    ox.data = oy.data = NULL;
    if ((gx && (st = tn__image_alloc(&ox, dem->width, dem->height, 1)) != TN_OK) ||
        (gy && (st = tn__image_alloc(&oy, dem->width, dem->height, 1)) != TN_OK)) {
        TN_FREE(ox.data);
        return st;
    }
    job.op = TN__OP_GRAD;
    job.dem = dem;
    job.out0 = ox.data;
    job.out1 = oy.data;
    tn_parallel_for((size_t)dem->height, tn__row_grain(dem->width), tn__terrain_rows, &job);
    if (gx) tn__image_give(gx, dem, &ox);
    if (gy) tn__image_give(gy, dem, &oy);
    return TN_OK;
}

/* Runs one per-pixel terrain op into a new `channels`-channel image. */
static tn_status tn__terrain_run(tn_image *dst, const tn_image *dem, tn__terrain_job *job, int channels)
{
    tn_image out;
    tn_status st = tn__image_alloc(&out, dem->width, dem->height, channels);
    if (st) return st;
    job->dem = dem;
    job->out0 = out.data;
    tn_parallel_for((size_t)dem->height, tn__row_grain(dem->width), tn__terrain_rows, job);
    tn__image_give(dst, dem, &out);
    return TN_OK;
}

TN_API tn_status tn_image_slope(tn_image *dst, const tn_image *dem, float dx, float dy)
{
    tn__terrain_job job;
    tn_status st;
    TN_ASSERT(dst);
    if ((st = tn__image_check(dem, "slope")) != TN_OK) return st;
    memset(&job, 0, sizeof job);
    if ((st = tn__inv_spacing(dx, dy, 1.0f, &job.ix, &job.iy, "slope")) != TN_OK) return st;
    job.op = TN__OP_SLOPE;
    return tn__terrain_run(dst, dem, &job, 1);
}

TN_API tn_status tn_image_normals(tn_image *dst, const tn_image *dem, float dx, float dy, float z_scale)
{
    tn__terrain_job job;
    tn_status st;
    TN_ASSERT(dst);
    if ((st = tn__image_check(dem, "normals")) != TN_OK) return st;
    if (z_scale != z_scale || z_scale > FLT_MAX || z_scale < -FLT_MAX)
        return tn__fail(TN_ERR_INVALID_ARG, "normals: z_scale is not finite");
    if (z_scale == 0.0f) z_scale = 1.0f;
    memset(&job, 0, sizeof job);
    if ((st = tn__inv_spacing(dx, dy, z_scale, &job.ix, &job.iy, "normals")) != TN_OK) return st;
    job.op = TN__OP_NORMALS;
    return tn__terrain_run(dst, dem, &job, 3);
}

/* Range of channel 0 ignoring NaN/Inf; lo = hi = 0 when nothing is finite. */
static void tn__channel0_range(const tn_image *img, float *lo, float *hi)
{
    size_t i, n = (size_t)img->width * img->height, C = (size_t)img->channels;
    float mn = FLT_MAX, mx = -FLT_MAX;
    for (i = 0; i < n; i++) {
        float v = img->data[i * C];
        if (!(v >= -FLT_MAX && v <= FLT_MAX)) continue;
        if (v < mn) mn = v;
        if (v > mx) mx = v;
    }
    if (mn > mx) mn = mx = 0.0f;
    *lo = mn;
    *hi = mx;
}

/* "Auto" spacing: the height range spans 10% of the image's longer side, about what mountain
   DEMs have at their true spacing (Alps 4-7%, Fuji 12%, St Helens 16%), so flat plains are
   exaggerated and [0, 1] PNG heights and metre DEMs give the same picture. */
#define TN__SHADE_AUTO_RELIEF 0.1f

/* The zero rules of tn_hillshade_opts: sun at 315 / 45 degrees, z_factor 1, one spacing given
   means square pixels, none means the "auto" spacing from dem's relief. */
static void tn__hillshade_opts_defaults(tn_hillshade_opts *o, const tn_image *dem)
{
    if (o->azimuth_deg == 0.0f) o->azimuth_deg = 315.0f;
    if (o->altitude_deg == 0.0f) o->altitude_deg = 45.0f;
    if (o->z_factor == 0.0f) o->z_factor = 1.0f;
    if (o->dx == 0.0f) o->dx = o->dy;
    if (o->dy == 0.0f) o->dy = o->dx;
    if (o->dx == 0.0f) {
        float lo, hi;
        tn__channel0_range(dem, &lo, &hi);
        o->dx = o->dy = hi > lo ? (hi - lo) / (TN__SHADE_AUTO_RELIEF * (float)(dem->width > dem->height ? dem->width : dem->height)) : 1.0f;
    }
}

TN_API tn_status tn_image_hillshade(tn_image *dst, const tn_image *dem, const tn_hillshade_opts *opts)
{
    tn_hillshade_opts o;
    tn__terrain_job job;
    double az, alt;
    tn_status st;
    TN_ASSERT(dst);
    if ((st = tn__image_check(dem, "hillshade")) != TN_OK) return st;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    /* Inf angles make sin/cos NaN, so everything must be finite */
    if (!(o.dx >= 0.0f && o.dy >= 0.0f && o.dx <= FLT_MAX && o.dy <= FLT_MAX) || !(fabsf(o.z_factor) <= FLT_MAX) ||
        !(fabsf(o.azimuth_deg) <= FLT_MAX) || !(fabsf(o.altitude_deg) <= FLT_MAX))
        return tn__fail(TN_ERR_INVALID_ARG, "hillshade: spacing must be finite and >= 0, angles and z_factor finite");
    tn__hillshade_opts_defaults(&o, dem);
    memset(&job, 0, sizeof job);
    job.op = TN__OP_SHADE;
    job.ix = o.z_factor / o.dx;
    job.iy = o.z_factor / o.dy;
    if (!(fabsf(job.ix) <= FLT_MAX && fabsf(job.iy) <= FLT_MAX)) /* a tiny spacing or a huge z_factor */
        return tn__fail(TN_ERR_INVALID_ARG, "hillshade: z_factor %g over spacing %g x %g overflows", (double)o.z_factor,
                        (double)o.dx, (double)o.dy);
    az = o.azimuth_deg * (3.14159265358979323846 / 180.0);
    alt = o.altitude_deg * (3.14159265358979323846 / 180.0);
    job.lx = (float)(sin(az) * cos(alt));
    job.ly = (float)(cos(az) * cos(alt));
    job.lz = (float)sin(alt);
    return tn__terrain_run(dst, dem, &job, 1);
}

/* ---- colour ramp ---------------------------------------------------------------------------- */

/* Hypsometric stops: deep and shallow water, a sharp shore, green lowlands, tan and brown hills,
   grey rock, snow. t is the height mapped to [0, 1]; NaN gives the deepest colour. */
static void tn__colour_at(float t, float *rgb)
{
    static const float stops[][4] = {
        {0.00f, 0.10f, 0.22f, 0.45f}, {0.10f, 0.30f, 0.55f, 0.75f}, {0.12f, 0.72f, 0.74f, 0.56f},
        {0.14f, 0.30f, 0.55f, 0.27f}, {0.35f, 0.56f, 0.68f, 0.36f}, {0.55f, 0.74f, 0.66f, 0.44f},
        {0.70f, 0.55f, 0.42f, 0.30f}, {0.82f, 0.55f, 0.53f, 0.51f}, {0.92f, 0.85f, 0.85f, 0.86f},
        {1.00f, 1.00f, 1.00f, 1.00f}};
    const int n = (int)(sizeof stops / sizeof stops[0]);
    int i = 1;
    float f;
    if (!(t > 0.0f)) t = 0.0f;
    if (t > 1.0f) t = 1.0f;
    while (i < n - 1 && t > stops[i][0]) i++;
    f = (t - stops[i - 1][0]) / (stops[i][0] - stops[i - 1][0]);
    rgb[0] = stops[i - 1][1] + f * (stops[i][1] - stops[i - 1][1]);
    rgb[1] = stops[i - 1][2] + f * (stops[i][2] - stops[i - 1][2]);
    rgb[2] = stops[i - 1][3] + f * (stops[i][3] - stops[i - 1][3]);
}

TN_API float tn_image_height_step(const tn_image *dem, int coarse_only)
{
    size_t W, H, x, y, n = 0, on = 0, k;
    float *d, s, top = 0;
    double lim;
    if (!dem || !dem->data || dem->width < 2 || dem->height < 2 || dem->channels < 1) return 0;
    W = (size_t)dem->width;
    H = (size_t)dem->height;
    if (!(d = (float *)tn__alloc(2 * W * H * sizeof(float)))) return 0;
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) {
            float h = dem->data[(y * W + x) * dem->channels], e;
            if (fabsf(h) > top) top = fabsf(h);
            if (x + 1 < W && (e = fabsf(dem->data[(y * W + x + 1) * dem->channels] - h)) > 0) d[n++] = e;
            if (y + 1 < H && (e = fabsf(dem->data[((y + 1) * W + x) * dem->channels] - h)) > 0) d[n++] = e;
        }
    if (!n) {
        TN_FREE(d);
        return 0;
    }
    qsort(d, n, sizeof(float), tn__cmp_float);
    s = d[0];
    for (lim = 8; s > 0 && isfinite(s); lim *= 8) { /* float heights round each difference: fit s to the small multiples, then larger */
        double sd = 0, sm = 0;
        for (k = 0; k < n; k++) {
            double m = floor(d[k] / s + 0.5);
            if (m >= 1 && m <= lim) sd += d[k], sm += m;
        }
        s = (float)(sd / sm);
        if (lim > d[n - 1] / s) break;
    }
    for (k = 0; k < n; k++) { /* whole multiples, to a fiftieth of a step and float32's rounding of the heights */
        double m = floor(d[k] / s + 0.5);
        if (fabs(d[k] - m * s) <= 0.02 * s + 4.0 * FLT_EPSILON * top) on++;
    }
    TN_FREE(d);
    if (!(s > 0 && isfinite(s) && (double)on >= 0.99 * (double)n)) return 0;
    if (coarse_only) {
        double sum = 0;
        const float *e = dem->data;
        size_t c = (size_t)dem->channels, r = W * c;
        for (y = 1; y + 1 < H; y++)
            for (x = 1; x + 1 < W; x++) {
                const float *q = e + (y * W + x) * c;
                sum += fabs((double)q[c] + q[-(ptrdiff_t)c] + q[r] + q[-(ptrdiff_t)r] - 4.0 * q[0]);
            }
        if (W < 3 || H < 3 || s < 0.1 * sum / ((double)(W - 2) * (H - 2))) return 0;
    }
    return s;
}

/* Passes of each smoothing in tn_image_dequantize: both had converged at 100 on the 8-bit 256 px
   DEMs (docs/singan.md). */
#define TN__DEQUANT_ITERS 100

/* One pass of tn_image_dequantize over rows [y0, y1): the Laplacian of `h` (lap_only), or one
   projected step of membrane or biharmonic smoothing from `h` into `out`, clamped to [lo, hi].
   Borders replicate the edge. Each pixel reads only the pass's input: any thread count gives the
   same bytes. */
typedef struct tn__dequant_job {
    const float *h, *lap, *lo, *hi;
    float *out;
    int W, H, membrane, lap_only;
} tn__dequant_job;

static void tn__dequant_rows(void *ctx, size_t y0, size_t y1)
{
    const tn__dequant_job *j = (const tn__dequant_job *)ctx;
    const float *h = j->h, *lap = j->lap;
    size_t y, W = (size_t)j->W;
    int x;
    for (y = y0; y < y1; y++)
        for (x = 0; x < j->W; x++) {
            size_t i = y * W + (size_t)x;
            size_t l = x > 0 ? i - 1 : i, r = x + 1 < j->W ? i + 1 : i, u = y > 0 ? i - W : i, d = y + 1 < (size_t)j->H ? i + W : i;
            float v;
            if (j->lap_only) {
                j->out[i] = h[l] + h[r] + h[u] + h[d] - 4.0f * h[i];
                continue;
            }
            if (j->membrane) v = 0.25f * (h[l] + h[r] + h[u] + h[d]);
            else v = h[i] - (lap[l] + lap[r] + lap[u] + lap[d] - 4.0f * lap[i]) * (0.9f / 64.0f); /* 0.9 x the stable step */
            j->out[i] = tn__clampf(v, j->lo[i], j->hi[i]);
        }
}

TN_API tn_status tn_image_dequantize(tn_image *dst, const tn_image *dem, float step)
{
    tn_image out = {0, 0, 0, NULL};
    float *buf, *lo, *hi, *lap, *a, *b;
    size_t N, i;
    int W, H, it;
    tn_status st;
    if ((st = tn__image_check(dem, "dequantize"))) return st;
    if (!isfinite(step)) return tn__fail(TN_ERR_INVALID_ARG, "dequantize: step must be finite");
    W = dem->width;
    H = dem->height;
    N = (size_t)W * H;
    if ((st = tn__image_alloc(&out, W, H, 1))) return st;
    for (i = 0; i < N; i++) out.data[i] = dem->data[i * dem->channels];
    if (step > 0) {
        if (!(buf = (float *)tn__alloc(4 * N * sizeof(float)))) {
            tn_image_free(&out);
            return tn__fail(TN_ERR_OUT_OF_MEMORY, "dequantize: out of memory");
        }
        lo = buf;
        hi = buf + N;
        lap = buf + 2 * N;
        b = buf + 3 * N;
        a = out.data;
        for (i = 0; i < N; i++) {
            lo[i] = a[i] - 0.5f * step;
            hi[i] = a[i] + 0.5f * step;
        }
        /* the membrane first (fast over wide terraces), then the biharmonic removes its kinks */
        for (it = 0; it < 2 * TN__DEQUANT_ITERS; it++) {
            tn__dequant_job job;
            float *t;
            job.lo = lo;
            job.hi = hi;
            job.lap = lap;
            job.W = W;
            job.H = H;
            job.membrane = it < TN__DEQUANT_ITERS;
            if (!job.membrane) {
                job.h = a;
                job.out = lap;
                job.lap_only = 1;
                tn_parallel_for((size_t)H, tn__row_grain(W), tn__dequant_rows, &job);
            }
            job.h = a;
            job.out = b;
            job.lap_only = 0;
            tn_parallel_for((size_t)H, tn__row_grain(W), tn__dequant_rows, &job);
            t = a;
            a = b;
            b = t;
        }
        if (a != out.data) memcpy(out.data, a, N * sizeof(float));
        TN_FREE(buf);
    }
    tn__image_give(dst, dem, &out);
    return TN_OK;
}

TN_API tn_status tn_image_colour_ramp(tn_image *dst, const tn_image *dem, float lo, float hi)
{
    tn__terrain_job job;
    tn_status st;
    TN_ASSERT(dst);
    if ((st = tn__image_check(dem, "colour ramp")) != TN_OK) return st;
    if (lo != lo || hi != hi) return tn__fail(TN_ERR_INVALID_ARG, "colour ramp: lo/hi is NaN");
    if (lo == hi) tn__channel0_range(dem, &lo, &hi);
    memset(&job, 0, sizeof job);
    job.op = TN__OP_RAMP;
    job.lo = lo;
    job.inv_span = hi != lo ? 1.0f / (hi - lo) : 0.0f; /* flat DEM: every pixel gets t = 0 */
    return tn__terrain_run(dst, dem, &job, 3);
}

/* ---- halo rectangles ------------------------------------------------------------------------ */

TN_API tn_rect tn_rect_halo(tn_rect r, int halo, int width, int height)
{
    long long x0 = (long long)r.x - halo, y0 = (long long)r.y - halo;
    long long x1 = (long long)r.x + r.w + halo, y1 = (long long)r.y + r.h + halo;
    tn_rect g;
    if (x0 < 0) x0 = 0;
    if (y0 < 0) y0 = 0;
    if (x1 > width) x1 = width;
    if (y1 > height) y1 = height;
    g.x = (int)x0;
    g.y = (int)y0;
    g.w = x1 > x0 ? (int)(x1 - x0) : 0;
    g.h = y1 > y0 ? (int)(y1 - y0) : 0;
    return g;
}

