/* ============================================================================================
   @@noise  procedural maps (paper 002, section 2.1)
   Perlin fBm (improved gradient noise, seeded permutation, octaves summed with frequency x
   lacunarity and amplitude x gain per octave, as Algorithm 2) and explicit noise (Algorithm 1:
   uniform random matrices at several scales, upscaled, Gaussian-smoothed, averaged). Outputs are
   one-channel images normalised to [0, 1]; the same seed gives the same map everywhere, for any
   thread count.
   ============================================================================================ */
#ifndef TN_NO_NOISE

typedef struct tn_perlin_opts {
    uint64_t seed;
    int octaves;          /* 0 = 8 */
    float frequency;      /* lattice cells across the width at octave 0; 0 = 4 */
    float lacunarity;     /* frequency factor per octave; 0 = 2 */
    float gain;           /* amplitude factor per octave; 0 = 0.5 */
    int periodic;         /* 1: tiles seamlessly (cell counts rounded to integers per octave) */
} tn_perlin_opts;
/* Fills *out (allocated here, width x height x 1) with Perlin fBm. opts may be NULL. Negative or
   NaN fields, or frequency x lacunarity^(octaves - 1) over 1e9, fail with TN_ERR_INVALID_ARG. */
TN_API tn_status tn_noise_perlin(tn_image *out, int width, int height, const tn_perlin_opts *opts);

typedef struct tn_explicit_opts {
    uint64_t seed;
    int layers;           /* random matrices; layer i (1..layers) is max(1, size / 2^i) square; 0 = 5 */
    const float *sigmas;  /* Gaussian smoothing passes in output pixels; NULL = {size / 64, size / 32} */
    int nsigmas;
} tn_explicit_opts;
/* Explicit multi-scale noise (Algorithm 1). opts may be NULL. */
TN_API tn_status tn_noise_explicit(tn_image *out, int width, int height, const tn_explicit_opts *opts);

/* Steers a noise map with a drawn map (Figure 5 of paper 002): out = weight * drawn +
   (1 - weight) * noise, with drawn (channel 0) resampled to the noise size and normalised to
   [0, 1]; weight in [0, 1]. */
TN_API tn_status tn_noise_blend(tn_image *out, const tn_image *noise, const tn_image *drawn, float weight);
#endif /* TN_NO_NOISE */

/* --------------------------------------------------------------------------------------------
   >>noise  (@@noise implementation)
   Improved Perlin noise (Perlin 2002): quintic fade, a seeded permutation of 0..255, 8 gradient
   directions. Rows are independent, so the map is computed row-parallel and is identical for any
   thread count.
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_NOISE

typedef struct tn__perlin_job {
    uint8_t perm[512];
    int width, height, octaves, periodic; /* the whole map's size: lattice coordinates depend on it */
    int x0, y0, w;                        /* the window computed: columns x0 .. x0 + w - 1, rows from y0 */
    float freq, lacunarity, gain;
    /* per octave and column (the same for every row): hashed x lattice corners, offset, fade */
    int *hx0, *hx1;
    float *fx, *ux;
    float *out;
} tn__perlin_job;

/* The 8 gradient directions of improved noise in 2-D: axes and diagonals. */
static const float tn__perlin_gx[8] = {1, -1, 1, -1, 1, -1, 0, 0};
static const float tn__perlin_gy[8] = {1, 1, -1, -1, 0, 0, 1, -1};

static float tn__fade(float t) { return t * t * t * (t * (t * 6.0f - 15.0f) + 10.0f); }

/* Lattice cells across `size` pixels at octave o, rounded to whole cells in periodic mode. */
static float tn__perlin_cells(const tn__perlin_job *j, float cells)
{
    if (!j->periodic) return cells;
    cells = (float)floor(cells + 0.5f);
    return cells < 1 ? 1 : cells;
}

/* Lattice coordinate of pixel i at octave o: integer cell (wrapped) and fraction. */
static void tn__perlin_coord(const tn__perlin_job *j, int i, int size, float cells, float offset, int *c0, int *c1, float *f)
{
    int period = j->periodic ? (int)cells : 256;
    float s = ((float)i + 0.5f) * cells / (float)size + offset;
    int ic = (int)floor(s);
    *f = s - (float)ic;
    *c0 = ((ic % period) + period) % period & 255;
    *c1 = (((ic + 1) % period) + period) % period & 255;
}

static void tn__perlin_rows(void *ctx, size_t yb, size_t ye)
{
    const tn__perlin_job *j = (const tn__perlin_job *)ctx;
    const uint8_t *p = j->perm;
    size_t y;
    int x, o;
    for (y = yb; y < ye; y++) {
        float *row = j->out + y * (size_t)j->w, freq = j->freq, amp = 1.0f;
        for (x = 0; x < j->w; x++) row[x] = 0.0f;
        for (o = 0; o < j->octaves; o++) {
            const int *hx0 = j->hx0 + (size_t)o * j->w, *hx1 = j->hx1 + (size_t)o * j->w;
            const float *fxs = j->fx + (size_t)o * j->w, *uxs = j->ux + (size_t)o * j->w;
            float cells_y = tn__perlin_cells(j, freq * (float)j->height / (float)j->width), fy, v;
            int y0, y1;
            tn__perlin_coord(j, j->y0 + (int)y, j->height, cells_y, (float)(o * 37), &y0, &y1, &fy);
            v = tn__fade(fy);
            for (x = 0; x < j->w; x++) {
                int h00 = p[hx0[x] + y0] & 7, h10 = p[hx1[x] + y0] & 7, h01 = p[hx0[x] + y1] & 7, h11 = p[hx1[x] + y1] & 7;
                float fx = fxs[x], u = uxs[x];
                float a = tn__perlin_gx[h00] * fx + tn__perlin_gy[h00] * fy;
                float b = tn__perlin_gx[h10] * (fx - 1) + tn__perlin_gy[h10] * fy;
                float c = tn__perlin_gx[h01] * fx + tn__perlin_gy[h01] * (fy - 1);
                float d = tn__perlin_gx[h11] * (fx - 1) + tn__perlin_gy[h11] * (fy - 1);
                float top = a + u * (b - a), bot = c + u * (d - c);
                row[x] += amp * (top + v * (bot - top));
            }
            freq *= j->lacunarity;
            amp *= j->gain;
        }
    }
}

/* Rescales a one-channel image to [0, 1] (a constant image becomes 0.5). */
static void tn__normalise01(tn_image *img)
{
    float lo, hi;
    size_t i, n = (size_t)img->width * img->height * img->channels;
    tn_image_range(&lo, &hi, img);
    for (i = 0; i < n; i++) img->data[i] = hi > lo ? (img->data[i] - lo) / (hi - lo) : 0.5f;
}

/* The zero rules of tn_perlin_opts: 8 octaves from 4 cells, lacunarity 2, gain 0.5. */
static void tn__perlin_opts_defaults(tn_perlin_opts *o)
{
    if (o->octaves == 0) o->octaves = 8;
    if (o->frequency == 0) o->frequency = 4.0f;
    if (o->lacunarity == 0) o->lacunarity = 2.0f;
    if (o->gain == 0) o->gain = 0.5f;
}

/* Checks opts and resolves its zero rules into *o. */
static tn_status tn__perlin_resolve(const tn_perlin_opts *opts, tn_perlin_opts *o)
{
    memset(o, 0, sizeof *o);
    if (opts) *o = *opts;
    if (o->octaves < 0 || !(o->frequency >= 0.0f) || !(o->lacunarity >= 0.0f) || !(o->gain >= 0.0f)) /* also NaN */
        return tn__fail(TN_ERR_INVALID_ARG, "perlin: negative or NaN octaves, frequency, lacunarity or gain");
    tn__perlin_opts_defaults(o);
    if (o->octaves > 24 || o->frequency > 1e6f || o->lacunarity > 16.0f || o->gain > 4.0f)
        return tn__fail(TN_ERR_INVALID_ARG, "perlin: octaves <= 24, frequency <= 1e6, lacunarity <= 16, gain <= 4");
    /* the finest octave's lattice coordinates must fit an int (they are floored to cells) */
    if ((double)o->frequency * pow((double)o->lacunarity, o->octaves - 1) > 1e9)
        return tn__fail(TN_ERR_INVALID_ARG, "perlin: frequency x lacunarity^(octaves - 1) exceeds 1e9 cells");
    return TN_OK;
}

/* Raw (unnormalised) fBm of the w x h window at (x0, y0) of a width x height map into out
   (w * h floats), o resolved. Every pixel is a function of its global position and the map's
   size only, so any window equals the same pixels of the whole map, bit for bit. */
static tn_status tn__perlin_window(const tn_perlin_opts *o, int width, int height, int x0, int y0, int w, int h, float *out)
{
    tn__perlin_job *j;
    tn_rng rng;
    int i;
    j = (tn__perlin_job *)tn__alloc(sizeof *j);
    if (!j) return TN_ERR_OUT_OF_MEMORY;
    for (i = 0; i < 256; i++) j->perm[i] = (uint8_t)i;
    tn_rng_seed(&rng, o->seed, 0x5e71u);
    for (i = 255; i > 0; i--) { /* Fisher-Yates */
        int k = (int)tn_rng_below(&rng, (uint32_t)i + 1);
        uint8_t t = j->perm[i];
        j->perm[i] = j->perm[k];
        j->perm[k] = t;
    }
    for (i = 0; i < 256; i++) j->perm[256 + i] = j->perm[i];
    j->width = width;
    j->height = height;
    j->x0 = x0;
    j->y0 = y0;
    j->w = w;
    j->octaves = o->octaves;
    j->periodic = o->periodic != 0;
    j->freq = o->frequency;
    j->lacunarity = o->lacunarity;
    j->gain = o->gain;
    j->out = out;
    j->hx0 = (int *)tn__alloc(2 * (size_t)o->octaves * (size_t)w * (sizeof(int) + sizeof(float)));
    if (!j->hx0) {
        TN_FREE(j);
        return TN_ERR_OUT_OF_MEMORY;
    }
    j->hx1 = j->hx0 + (size_t)o->octaves * w;
    j->fx = (float *)(j->hx1 + (size_t)o->octaves * w);
    j->ux = j->fx + (size_t)o->octaves * w;
    {
        float freq = o->frequency;
        int oc, x;
        for (oc = 0; oc < o->octaves; oc++, freq *= o->lacunarity) {
            float cells_x = tn__perlin_cells(j, freq);
            for (x = 0; x < w; x++) {
                size_t k = (size_t)oc * w + x;
                int c0, c1;
                tn__perlin_coord(j, x0 + x, width, cells_x, (float)(oc * 59), &c0, &c1, &j->fx[k]);
                j->hx0[k] = j->perm[c0];
                j->hx1[k] = j->perm[c1];
                j->ux[k] = tn__fade(j->fx[k]);
            }
        }
    }
    tn_parallel_for((size_t)h, 4, tn__perlin_rows, j);
    TN_FREE(j->hx0);
    TN_FREE(j);
    return TN_OK;
}

TN_API tn_status tn_noise_perlin(tn_image *out, int width, int height, const tn_perlin_opts *opts)
{
    tn_perlin_opts o;
    tn_image img = {0, 0, 0, NULL};
    tn_status st;
    if ((st = tn__perlin_resolve(opts, &o))) return st;
    if ((st = tn_image_create(&img, width, height, 1))) return st;
    if ((st = tn__perlin_window(&o, width, height, 0, 0, width, height, img.data))) {
        tn_image_free(&img);
        return st;
    }
    tn__normalise01(&img);
    *out = img;
    return TN_OK;
}

/* The zero rules of tn_explicit_opts for a width x height map: 5 layers; no sigmas means
   {size / 64, size / 32} with size the longer side, written to sigmas[2] (the caller's storage). */
static void tn__explicit_opts_defaults(tn_explicit_opts *o, int width, int height, float sigmas[2])
{
    int size = width > height ? width : height;
    if (o->layers == 0) o->layers = 5;
    if (!o->sigmas || o->nsigmas == 0) {
        sigmas[0] = (float)size / 64.0f;
        sigmas[1] = (float)size / 32.0f;
        o->sigmas = sigmas;
        o->nsigmas = 2;
    }
}

TN_API tn_status tn_noise_explicit(tn_image *out, int width, int height, const tn_explicit_opts *opts)
{
    tn_explicit_opts o;
    tn_image acc = {0, 0, 0, NULL}, small = {0, 0, 0, NULL}, big = {0, 0, 0, NULL};
    tn_rng rng;
    tn_status st;
    float sigmas[2];
    int layer, k;
    size_t i, n;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    /* checked as given: the defaults would hide a negative sigma count */
    if (o.layers < 0 || o.nsigmas < 0) return tn__fail(TN_ERR_INVALID_ARG, "explicit noise: negative layers or sigma count");
    if (o.layers > 30) return tn__fail(TN_ERR_INVALID_ARG, "explicit noise: at most 30 layers");
    for (k = 0; o.sigmas && k < o.nsigmas; k++) /* a NaN sigma would be skipped silently */
        if (!(o.sigmas[k] >= 0.0f && o.sigmas[k] <= FLT_MAX))
            return tn__fail(TN_ERR_INVALID_ARG, "explicit noise: sigma %d is %g", k, (double)o.sigmas[k]);
    tn__explicit_opts_defaults(&o, width, height, sigmas);
    if ((st = tn_image_create(&acc, width, height, 1))) return st;
    n = (size_t)width * height;
    tn_rng_seed(&rng, o.seed, 0xe7u);
    for (layer = 1; layer <= o.layers && !st; layer++) {
        int sw = width >> layer, sh = height >> layer;
        if (sw < 1) sw = 1;
        if (sh < 1) sh = 1;
        if ((st = tn_image_create(&small, sw, sh, 1))) break;
        for (i = 0; i < (size_t)sw * sh; i++) small.data[i] = tn_rng_uniform(&rng);
        st = tn_image_resize(&big, &small, width, height, TN_RESIZE_NEAREST);
        tn_image_free(&small);
        for (k = 0; k < o.nsigmas && !st; k++)
            if (o.sigmas[k] > 0) st = tn_image_blur(&big, &big, o.sigmas[k]);
        if (!st)
            for (i = 0; i < n; i++) acc.data[i] += big.data[i] / (float)o.layers;
        tn_image_free(&big);
    }
    if (st) {
        tn_image_free(&acc);
        return st;
    }
    tn__normalise01(&acc);
    *out = acc;
    return TN_OK;
}

TN_API tn_status tn_noise_blend(tn_image *out, const tn_image *noise, const tn_image *drawn, float weight)
{
    tn_image d = {0, 0, 0, NULL}, r = {0, 0, 0, NULL};
    tn_status st;
    size_t i, n;
    if (!noise || !noise->data || !drawn || !drawn->data || noise->channels != 1)
        return tn__fail(TN_ERR_INVALID_ARG, "noise blend: needs a one-channel noise map and a drawn map");
    if (!(weight >= 0.0f && weight <= 1.0f)) return tn__fail(TN_ERR_INVALID_ARG, "noise blend: weight must be in [0, 1]");
    if ((st = tn_image_create(&d, drawn->width, drawn->height, 1))) return st;
    for (i = 0; i < (size_t)drawn->width * drawn->height; i++) d.data[i] = drawn->data[i * drawn->channels];
    if (tn_image_range(NULL, NULL, &d)) {
        tn_image_free(&d);
        return tn__fail(TN_ERR_NUMERIC, "noise blend: the drawn map holds NaN/Inf");
    }
    tn__normalise01(&d);
    st = tn_image_resize(&r, &d, noise->width, noise->height, TN_RESIZE_BILINEAR);
    tn_image_free(&d);
    if (st) return st;
    n = (size_t)noise->width * noise->height;
    for (i = 0; i < n; i++) r.data[i] = weight * r.data[i] + (1.0f - weight) * noise->data[i];
    *out = r;
    return TN_OK;
}
#endif /* TN_NO_NOISE */

