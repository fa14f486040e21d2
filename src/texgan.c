/* ============================================================================================
   @@texgan  single-texture spatial GAN, huge textures and detail maps (paper 004, section III)
   A PSGAN-style spatial GAN learns one exemplar (RGB, or RGB + normal map = 6 channels, any
   count up to TN_TEXGAN_MAX_CHANNELS). The generator is fully convolutional: a noise tensor z
   of cells (local dims uniform in [0, 1], optional per-image global dims and periodic sin
   dims) goes through `stages` x (bilinear upsample x2 + [1 2 1]/4 blur, 5x5 valid conv, +
   per-pixel noise scaled per channel, leaky ReLU, pixel norm; tanh last), so there is no
   transposed-conv checkerboard, little cell-grid structure and no zero padding: a window of z
   cells [a, a + T + 8) gives exactly the output pixels [a 2^S, a 2^S + T 2^S + 8). Tiles with 4
   cells of overlap on each side therefore equal a one-pass synthesis, and any tile of any seed can be made alone
   (a cell's z and a stage pixel's noise are hashes of the seed and their global position).
   The first design (nearest upsampling, no stage noise: 4 cells of context instead of 6) is
   kept for its model files (and plain bilinear, `smooth` 1, for the intermediate ones). The discriminator is fully convolutional too (stride-2 5x5 convs,
   a per-location score map), spectral-normalised, hinge loss, Adam, alternating D and G steps
   on random n x n patches; the G loss adds a feature-statistics term (means and covariances of
   fixed random filters at 3 scales vs the exemplar's) that keeps small exemplars from
   collapsing to a flat colour; an exponential moving average of G is what the model keeps. Detail maps (paper: Gaussian split): low map = Gaussian
   low-pass of the colour-corrected synthesis downsampled by f; high map = exemplar minus its
   Gaussian blur, cross-faded with itself shifted by half a side so it tiles seamlessly
   (energy-preserving weights), stored as value / 2 + 0.5; a renderer adds upsampled low + 2 (high - 0.5)
   tiled `tiling` times.
   ============================================================================================ */
#ifndef TN_NO_TEXGAN
#if defined(TN_NO_ENGINE) || defined(TN_NO_NOISE)
#error "terrainnet: @@texgan needs the tensor engine, @@noise; define TN_NO_TEXGAN too, or none of them"
#endif

#define TN_TEXGAN_MAX_CHANNELS 8

/* Zero = default (see tn_texgan_defaults for the values and why). */
typedef struct tn_texgan_opts {
    int noise_local;        /* local noise dims per cell; 0 = 16 */
    int noise_global;       /* dims constant over one image (PSGAN global); 0 = none */
    int noise_periodic;     /* sin channels with fixed random wave vectors, random phase per image; 0 = none */
    int stages;             /* upsample+conv stages: one noise cell = 2^stages pixels; 0 = 4 */
    int gen_width;          /* channels of the first generator stage, halving per stage (min 16); 0 = 64 */
    int disc_width;         /* channels of the first discriminator layer, doubling per layer; 0 = 32 */
    int disc_layers;        /* stride-2 discriminator layers before the score conv; 0 = 3 */
    int patch;              /* training patch side n in pixels; 0 = 64 */
    int scale;              /* learn the exemplar downscaled by this factor and upsample the output
                               (bilinear): features `scale` times larger for the same cost; 0 = 1 */
    int batch;              /* patches per step; 0 = 4 */
    int augment;            /* 1: real patches randomly flipped/transposed (8x the data of a small
                               exemplar; only for textures without a light direction) */
    int nearest;            /* 1: nearest x2 upsampling and no per-pixel stage noise (the first
                               design: a visible 2^stages cell grid); 0 = smooth + stage noise */
    float feat_weight;      /* weight of the feature-statistics term in the G loss (random-filter
                               means and covariances at 3 scales vs the exemplar's); 0 = 1, < 0 = off */
    float lr;               /* Adam rate for G and D; 0 = 2e-4 (betas 0.5, 0.999) */
    float ema;              /* EMA decay of the kept generator; 0 = 0.995 */
    tn_train_opts train;    /* budget (minutes 0 = 15), checkpoints, resume (the file's
                               architecture and settings win), seed */
} tn_texgan_opts;

/* A trained generator (the EMA weights) plus what synthesis needs. Free with tn_texgan_free. */
typedef struct tn_texgan {
    int channels, noise_local, noise_global, noise_periodic, stages, gen_width;
    int scale;                             /* output pixels per generator pixel (1 = none) */
    int smooth;                            /* upsampling: 2 = bilinear x2 + [1 2 1]/4 blur, 1 = bilinear,
                                              0 = nearest (first models) */
    int stage_noise;                       /* 1: per-pixel noise added at every stage */
    float lo, hi;                          /* value range the tanh output maps to */
    float mean[TN_TEXGAN_MAX_CHANNELS];    /* the exemplar's mean per channel */
    long iterations;                       /* training iterations done */
    double train_seconds;                  /* training wall-clock seconds */
    tn_params *weights;                    /* "texgan.config", "texgan.waves", "g.w<i>", "g.b<i>" */
} tn_texgan;

/* What a training run did. */
typedef struct tn_texgan_stats {
    long iterations;          /* total, including resumed ones */
    long resumed_from;        /* iteration the run resumed at (0 = fresh) */
    double seconds;           /* total training seconds, including resumed time */
    double seconds_per_iter;  /* this run's average */
    float loss_d, loss_g;     /* averages over the last 50 iterations */
    int checkpoints;          /* checkpoints written by this run */
} tn_texgan_stats;

/* Fills *o with the defaults (what zero fields mean). */
TN_API void tn_texgan_defaults(tn_texgan_opts *o);
/* Trains on the exemplar (values in any finite range; 1..TN_TEXGAN_MAX_CHANNELS channels, at
   least patch x patch). Reports progress as "texgan-train". With opts->checkpoint it saves the
   full training state atomically every checkpoint interval and at the end; with resume it
   continues from that file, and the continuation is bit-identical to an uninterrupted run.
   *model is allocated here (free with tn_texgan_free). stats may be NULL. */
TN_API tn_status tn_texgan_train(tn_texgan *model, const tn_image *exemplar, const tn_texgan_opts *opts,
                                 tn_texgan_stats *stats);
TN_API void tn_texgan_free(tn_texgan *model);
/* Model files are .tnw: a config tensor (architecture, value range, exemplar mean) + EMA weights. */
TN_API tn_status tn_texgan_save(const char *path, const tn_texgan *model);
TN_API tn_status tn_texgan_load(tn_texgan *model, const char *path);

/* Synthesises the w x h window at pixel (x0, y0) of the infinite texture of `seed` (x0, y0 >= 0)
   in one generator pass. *out is allocated here. */
TN_API tn_status tn_texgan_synthesize_window(tn_image *out, const tn_texgan *model, uint64_t seed, int x0, int y0, int w,
                                             int h);
/* Called with consecutive row bands of a tiled synthesis: rows [y0, y0 + band->height). */
typedef tn_status (*tn_band_fn)(void *user, int y0, const tn_image *band);
/* Tiled synthesis of a width x height texture: z split into tiles of tile_cells cells (0 = 32)
   with 4 cells of overlap (2 for nearest models), each tile run alone and cropped; bands of one tile row are handed to
   fn in order. Memory is bounded by one band. Identical to tn_texgan_synthesize_window at (0, 0). */
TN_API tn_status tn_texgan_synthesize_stream(const tn_texgan *model, uint64_t seed, int width, int height,
                                             int tile_cells, tn_band_fn fn, void *user);
/* Whole image in memory (tiled internally). */
TN_API tn_status tn_texgan_synthesize(tn_image *out, const tn_texgan *model, uint64_t seed, int width, int height);
/* Streams a synthesis to disk band by band (PFM or 8-bit PPM/PGM by extension; other formats are
   built in memory and saved whole). Channels beyond 3 go to "<stem>.ch3-5<ext>" and so on.
   shift (channels floats, may be NULL) is added before writing (colour correction), results
   clipped to the model's range. Files appear atomically. */
TN_API tn_status tn_texgan_synthesize_file(const char *path, const tn_texgan *model, uint64_t seed, int width,
                                           int height, const float *shift);

/* Colour correction: adds a per-channel shift so that the mean of the result, clipped to
   [lo, hi], equals target_mean (found by bisection, so clipping does not spoil it). In place. */
TN_API tn_status tn_texture_colour_correct(tn_image *img, const float *target_mean, float lo, float hi);
/* The per-channel shift the same correction would apply (for streamed outputs). */
TN_API tn_status tn_texture_colour_shift(float *shift, const tn_image *img, const float *target_mean, float lo,
                                         float hi);

/* Detail maps for a renderer. */
typedef struct tn_detail_maps {
    tn_image low;            /* low-pass synthesis, (W / factor) x (H / factor) (rounded up) */
    tn_image high;           /* exemplar high frequencies as value / 2 + 0.5, exemplar size */
    int width, height;       /* size of the full texture the maps stand for */
    float tiling_x, tiling_y;/* repetitions of the high map across the texture (= width / exemplar width) */
    int factor;              /* low-map downsampling factor */
    float sigma;             /* Gaussian split sigma in full-resolution pixels */
    float lo, hi;            /* value range (composition clips to it) */
} tn_detail_maps;

typedef struct tn_detail_opts {
    int factor;              /* low-map downsampling 1..4096; 0 = 10 (memory / 100) */
    float sigma;             /* split sigma in pixels; 0 = factor / 2 */
    int no_colour_correct;   /* 1: keep the synthesis' own mean colour */
    float lo, hi;            /* value range; both 0 = [0, 1] */
} tn_detail_opts;

/* Detail maps from a synthesis in memory. The low map is an f x f area average followed by a
   Gaussian of the remaining width (sqrt(sigma^2 - f^2/12) / f low-map pixels): the same
   low-pass the streaming version applies. */
TN_API tn_status tn_detail_maps_from_image(tn_detail_maps *maps, const tn_image *synth, const tn_image *exemplar,
                                           const tn_detail_opts *opts);
/* Same, synthesising width x height with the model band by band (memory: one band + the maps). */
TN_API tn_status tn_detail_maps_from_model(tn_detail_maps *maps, const tn_texgan *model, uint64_t seed, int width,
                                           int height, const tn_image *exemplar, const tn_detail_opts *opts);
TN_API void tn_detail_maps_free(tn_detail_maps *maps);
/* One texel as a shader computes it, (u, v) in [0, 1) across the texture: bilinear low map
   (texel centres, clamped) + 2 (bilinear high map, repeated tiling times - 0.5), clipped.
   out gets channels floats. */
TN_API void tn_detail_texel(float *out, const tn_detail_maps *maps, float u, float v);
/* The whole composed texture at width x height (0, 0 = the maps' size). */
TN_API tn_status tn_detail_compose(tn_image *out, const tn_detail_maps *maps, int width, int height);
/* PREFIX_low.png, PREFIX_high.png (8-bit) and PREFIX_detail.txt (size, tiling, factor, sigma,
   range) as a sidecar, since the tiling factor must travel with the maps. */
TN_API tn_status tn_detail_maps_save(const char *prefix, const tn_detail_maps *maps);
TN_API tn_status tn_detail_maps_load(tn_detail_maps *maps, const char *prefix);
/* Side-by-side preview (2 x 2 panels of `panel` pixels, 0 = 384): top far view of the whole
   texture, bottom a near crop at full resolution; left naive tiling of the exemplar, right
   the detail-mapped texture; all shaded by the hillshade of dem (NULL = a Perlin terrain). */
TN_API tn_status tn_detail_preview(tn_image *out, const tn_detail_maps *maps, const tn_image *exemplar,
                                   const tn_image *dem, int panel);
#endif /* TN_NO_TEXGAN */

/* --------------------------------------------------------------------------------------------
   >>texgan  (@@texgan implementation)
   Defaults (measured on the shared 2-core Zen 4, see README "Texture GAN"): 4 stages of
   64-32-16 channels from 16 local noise dims, discriminator 32-64-128 + score conv, 64 px
   patches, batch 4, smooth upsampling + stage noise, feature-statistics weight 1. Why: a cell
   is 16 px, so the generator sees 4 cells (~64 px) each side, enough for grass blades at 512 px
   (larger features such as pebbles and crack cells: 5 stages), and the discriminator's ~60 px
   field covers a patch; wider nets cost time per iteration roughly quadratically, and 15 minutes
   bought only 630-1900 iterations at this size (on a loaded machine, README). The GAN output only feeds the low-frequency map, whose content is
   at scales >= 5 px, so a small generator is enough; the exemplar supplies the fine detail.
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_TEXGAN

#define TN__TG_CONFIG 40
#define TN__TG_STATE 24
#define TN__TG_MAX_STAGES 6
#define TN__TG_MAX_DLAYERS 5

TN_API void tn_texgan_defaults(tn_texgan_opts *o)
{
    TN_ASSERT(o);
    if (o->noise_local <= 0) o->noise_local = 16;
    if (o->noise_global < 0) o->noise_global = 0;
    if (o->noise_periodic < 0) o->noise_periodic = 0;
    if (o->stages <= 0) o->stages = 4;
    if (o->gen_width <= 0) o->gen_width = 64;
    if (o->disc_width <= 0) o->disc_width = 32;
    if (o->disc_layers <= 0) o->disc_layers = 3;
    if (o->patch <= 0) o->patch = 64;
    if (o->batch <= 0) o->batch = 4;
    if (o->lr <= 0) o->lr = 2e-4f;
    if (o->ema <= 0) o->ema = 0.995f;
    if (o->feat_weight == 0) o->feat_weight = 1.0f;
    tn_train_defaults(&o->train, 15.0);
}

TN__INTERNAL int tn__tg_zdim(const tn_texgan *m) { return m->noise_local + m->noise_global + m->noise_periodic; }

/* Output channels of generator stage i. */
static int tn__tg_gen_out(const tn_texgan *m, int i)
{
    int w = m->gen_width >> i;
    if (i == m->stages - 1) return m->channels;
    return w < 16 ? 16 : w;
}

/* Kernel of one stage on the nearest-upsampled map: the 5x5 conv, convolved with the smoothing
   the upsampling adds to nearest: none (K = 5), [1 2 1]/4 = bilinear (K = 7), or [1 4 6 4 1]/16
   = bilinear then a [1 2 1]/4 blur (K = 9). A valid stage turns n pixels into 2n - (K - 1). */
static int tn__tg_k(const tn_texgan *m) { return 5 + 2 * m->smooth; }

/* Output pixels of a generator run on `cells` cells. */
TN__INTERNAL int tn__tg_out_size(const tn_texgan *m, int cells)
{
    int r = cells, i;
    for (i = 0; i < m->stages; i++) r = 2 * r - (tn__tg_k(m) - 1);
    return r;
}

/* Cells needed so the output covers `pixels`: n cells give 2^S (n - K + 1) + K - 1 pixels. */
static int tn__tg_cells_for(const tn_texgan *m, int pixels)
{
    int p = 1 << m->stages, k1 = tn__tg_k(m) - 1, need = pixels - k1;
    return need <= 0 ? k1 : (need + p - 1) / p + k1;
}

/* ---- model parameters ---- */

static tn_status tn__tg_check_arch(const tn_texgan *m)
{
    if (m->channels < 1 || m->channels > TN_TEXGAN_MAX_CHANNELS) return tn__fail(TN_ERR_INVALID_ARG, "texgan: %d channels (1..%d)", m->channels, TN_TEXGAN_MAX_CHANNELS);
    if (m->stages < 1 || m->stages > TN__TG_MAX_STAGES) return tn__fail(TN_ERR_INVALID_ARG, "texgan: %d stages (1..%d)", m->stages, TN__TG_MAX_STAGES);
    if (m->noise_local < 1 || m->noise_local > 256 || m->noise_global < 0 || m->noise_global > 256 || m->noise_periodic < 0 ||
        m->noise_periodic > 64)
        return tn__fail(TN_ERR_INVALID_ARG, "texgan: noise dims %d/%d/%d out of range", m->noise_local, m->noise_global, m->noise_periodic);
    if (m->scale < 1 || m->scale > 16) return tn__fail(TN_ERR_INVALID_ARG, "texgan: scale %d (1..16)", m->scale);
    if (m->smooth < 0 || m->smooth > 2 || (m->stage_noise != 0 && m->stage_noise != 1))
        return tn__fail(TN_ERR_INVALID_ARG, "texgan: bad upsampling/noise flags");
    if (m->gen_width < 1 || m->gen_width > 2048) return tn__fail(TN_ERR_INVALID_ARG, "texgan: generator width %d (1..2048)", m->gen_width);
    if (!(m->lo < m->hi) || m->lo != m->lo || m->hi - m->lo > 1e30f) return tn__fail(TN_ERR_INVALID_ARG, "texgan: bad value range");
    return TN_OK;
}

static void tn__tg_write_config(const tn_texgan *m, int disc_width, int disc_layers, float *c)
{
    int i;
    memset(c, 0, TN__TG_CONFIG * sizeof(float));
    c[0] = 1.0f; /* config version */
    c[1] = (float)m->channels;
    c[2] = (float)m->noise_local;
    c[3] = (float)m->noise_global;
    c[4] = (float)m->noise_periodic;
    c[5] = (float)m->stages;
    c[6] = (float)m->gen_width;
    c[7] = m->lo;
    c[8] = m->hi;
    c[9] = (float)(m->iterations & 0xffffff);
    c[10] = (float)(m->iterations >> 24);
    c[11] = 0.0f; /* was the training seconds: provenance is in the metadata (train_seconds), so the
                     tensors, and a digest of them, are the same on every run with the same seed */
    c[12] = (float)disc_width;
    c[13] = (float)disc_layers;
    c[14] = (float)m->scale;
    c[15] = (float)m->smooth; /* zero in the first models: nearest, no stage noise */
    c[24] = (float)m->stage_noise;
    for (i = 0; i < TN_TEXGAN_MAX_CHANNELS; i++) c[16 + i] = m->mean[i];
}

/* Is a config field a whole number in [0, max]? Checked before any cast: converting a float
   outside the target type's range (1e20 to int or long) is undefined behaviour. */
static int tn__tg_whole(float v, float max) { return v >= 0.0f && v <= max && v == floorf(v); }

/* Reads the architecture back; validates every field before anything is allocated from it. */
static tn_status tn__tg_read_config(tn_texgan *m, int *disc_width, int *disc_layers, const float *c, const char *name)
{
    int i;
    for (i = 0; i < TN__TG_CONFIG; i++)
        if (c[i] != c[i] || c[i] > 1e30f || c[i] < -1e30f) return tn__fail(TN_ERR_CORRUPT, "%s: the texgan config holds NaN/Inf", name);
    if (c[0] != 1.0f) return tn__fail(TN_ERR_FORMAT, "%s: texgan config version %g is not supported", name, (double)c[0]);
    for (i = 1; i <= 6; i++)
        if (!tn__tg_whole(c[i], 4096.0f)) return tn__fail(TN_ERR_CORRUPT, "%s: bad texgan config field %d", name, i);
    /* iterations = c[9] + c[10] * 2^24, kept under 2^31 so it fits any long */
    if (!tn__tg_whole(c[9], 16777215.0f) || !tn__tg_whole(c[10], 127.0f) || !(c[11] >= 0.0f))
        return tn__fail(TN_ERR_CORRUPT, "%s: bad texgan iteration count or training time", name);
    if (!tn__tg_whole(c[12], 4096.0f) || !tn__tg_whole(c[13], 4096.0f) || !tn__tg_whole(c[15], 16.0f) ||
        !tn__tg_whole(c[24], 16.0f))
        return tn__fail(TN_ERR_CORRUPT, "%s: bad texgan flags or discriminator size", name);
    m->channels = (int)c[1];
    m->noise_local = (int)c[2];
    m->noise_global = (int)c[3];
    m->noise_periodic = (int)c[4];
    m->stages = (int)c[5];
    m->gen_width = (int)c[6];
    m->lo = c[7];
    m->hi = c[8];
    m->iterations = (long)c[9] + ((long)c[10] << 24);
    m->train_seconds = c[11];
    if (!tn__tg_whole(c[14], 16.0f)) return tn__fail(TN_ERR_CORRUPT, "%s: bad texgan scale", name);
    m->scale = c[14] > 0 ? (int)c[14] : 1;
    m->smooth = (int)c[15];
    m->stage_noise = (int)c[24];
    for (i = 0; i < TN_TEXGAN_MAX_CHANNELS; i++) m->mean[i] = c[16 + i];
    if (disc_width) *disc_width = (int)c[12];
    if (disc_layers) *disc_layers = (int)c[13];
    if (tn__tg_check_arch(m)) return tn__fail_context(TN_ERR_CORRUPT, name);
    return TN_OK;
}

/* Adds the generator tensors ("<prefix>w<i>", "<prefix>b<i>", then the stage-noise strengths
   "<prefix>n<i>" when the model has them) to p. */
static tn_status tn__tg_add_gen(tn_params *p, const tn_texgan *m, const char *prefix, int learned)
{
    int i, cin = tn__tg_zdim(m);
    char name[40];
    for (i = 0; i < m->stages; i++) {
        int cout = tn__tg_gen_out(m, i), ws[4], bs;
        ws[0] = cout; ws[1] = cin; ws[2] = 5; ws[3] = 5;
        bs = cout;
        snprintf(name, sizeof name, "%sw%d", prefix, i);
        if (!(learned ? tn_params_add(p, name, 4, ws) : tn_params_add_buffer(p, name, 4, ws))) return TN_ERR_OUT_OF_MEMORY;
        snprintf(name, sizeof name, "%sb%d", prefix, i);
        if (!(learned ? tn_params_add(p, name, 1, &bs) : tn_params_add_buffer(p, name, 1, &bs))) return TN_ERR_OUT_OF_MEMORY;
        cin = cout;
    }
    for (i = 0; i < m->stages && m->stage_noise; i++) {
        int bs = tn__tg_gen_out(m, i);
        snprintf(name, sizeof name, "%sn%d", prefix, i);
        if (!(learned ? tn_params_add(p, name, 1, &bs) : tn_params_add_buffer(p, name, 1, &bs))) return TN_ERR_OUT_OF_MEMORY;
    }
    return TN_OK;
}

/* Whether a model file holds the generator its config names, shape for shape, checked on the
   file's own tensors before the model is allocated: a config naming a wide, deep generator over
   a few small tensors would otherwise allocate its size first. */
static tn_status tn__tg_file_matches(const tn_texgan *m, const tn_params *f, const char *name)
{
    int i, cin = tn__tg_zdim(m);
    char tname[40];
    for (i = 0; i < m->stages; i++) {
        int cout = tn__tg_gen_out(m, i);
        const tn_tensor *w, *b, *n;
        snprintf(tname, sizeof tname, "g.w%d", i);
        w = tn_params_find(f, tname);
        snprintf(tname, sizeof tname, "g.b%d", i);
        b = tn_params_find(f, tname);
        snprintf(tname, sizeof tname, "g.n%d", i);
        n = tn_params_find(f, tname);
        if (!w || w->ndim != 4 || w->shape[0] != cout || w->shape[1] != cin || w->shape[2] != 5 || w->shape[3] != 5 || !b || b->ndim != 1 ||
            b->shape[0] != cout || (m->stage_noise && (!n || n->ndim != 1 || n->shape[0] != cout)))
            return tn__fail(TN_ERR_CORRUPT, "%s: the texgan config names a generator whose stage %d is %d x %d x 5 x 5; the file's tensors differ", name, i,
                            cout, cin);
        cin = cout;
    }
    return TN_OK;
}

/* The model's params: config, wave vectors (periodic dims, at least one row), EMA generator. */
static tn_status tn__tg_model_params(tn_texgan *m)
{
    int nc = TN__TG_CONFIG, ws[2];
    ws[0] = m->noise_periodic > 0 ? m->noise_periodic : 1;
    ws[1] = 2;
    m->weights = tn_params_create();
    if (!m->weights) return tn__fail(TN_ERR_OUT_OF_MEMORY, "texgan: out of memory");
    if (!tn_params_add_buffer(m->weights, "texgan.config", 1, &nc) || !tn_params_add_buffer(m->weights, "texgan.waves", 2, ws) ||
        tn__tg_add_gen(m->weights, m, "g.", 0)) {
        tn_params_free(m->weights);
        m->weights = NULL;
        return tn__fail(TN_ERR_OUT_OF_MEMORY, "texgan: out of memory");
    }
    return TN_OK;
}

TN_API void tn_texgan_free(tn_texgan *model)
{
    if (!model) return;
    tn_params_free(model->weights);
    memset(model, 0, sizeof *model);
}

TN_API tn_status tn_texgan_save(const char *path, const tn_texgan *model)
{
    tn_tensor *cfg;
    if (!model || !model->weights) return tn__fail(TN_ERR_INVALID_ARG, "texgan save: no model");
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "texgan save: empty path");
    cfg = tn_params_find(model->weights, "texgan.config");
    tn__tg_write_config(model, (int)cfg->data[12], (int)cfg->data[13], cfg->data);
    return tn_params_save(path, model->weights);
}

#define TN__TG_FORMAT 1

TN_API tn_status tn_texgan_load(tn_texgan *model, const char *path)
{
    tn_params *f = NULL;
    tn_texgan m;
    tn_tensor *cfg;
    tn_status st;
    TN_ASSERT(model);
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "texgan load: empty path");
    if ((st = tn__model_open(&f, path, "texgan", TN__TG_FORMAT, "texgan.config"))) return st;
    memset(&m, 0, sizeof m);
    if (!(cfg = tn_params_find(f, "texgan.config")) || cfg->numel != TN__TG_CONFIG)
        st = tn__fail(TN_ERR_FORMAT, "%s: not a texgan model (no texgan.config)", path);
    if (!st) st = tn__tg_read_config(&m, NULL, NULL, cfg->data, path);
    if (!st && m.train_seconds == 0 && tn_params_meta(f, "train_seconds")) { /* models since the config's field is 0 */
        double v;
        const char *t = tn_params_meta(f, "train_seconds");
        if (tn__io_number(t, strlen(t), &v) && v >= 0 && v <= 1e15) m.train_seconds = v;
    }
    if (!st) st = tn__tg_file_matches(&m, f, path);
    if (!st) st = tn__tg_model_params(&m);
    if (!st) st = tn__params_assign(m.weights, f, path);
    tn_params_free(f);
    if (st) {
        tn_params_free(m.weights);
        return st;
    }
    *model = m;
    return TN_OK;
}

/* ---- noise ---- */

/* Fills batch item `item` of z (N x Cz x s x s) for the cell window starting at (cx0, cy0):
   local dims hash (seed, cell), so a cell's noise never depends on the window; global dims and
   the periodic phases come from the image seed. */
TN__INTERNAL void tn__tg_noise(const tn_texgan *m, const float *waves, tn_tensor *z, int item, uint64_t seed, long cx0, long cy0)
{
    int cz = tn__tg_zdim(m), sh = z->shape[2], sw = z->shape[3], x, y, c;
    size_t plane = (size_t)sh * sw;
    float *zi = z->data + (size_t)item * cz * plane;
    float glob[256], phase[64];
    tn_rng r;
    tn_rng_seed(&r, tn__splitmix64(seed), 0x676c6f62ULL);
    for (c = 0; c < m->noise_global; c++) glob[c] = tn_rng_uniform(&r);
    for (c = 0; c < m->noise_periodic; c++) phase[c] = tn_rng_uniform(&r);
    for (y = 0; y < sh; y++)
        for (x = 0; x < sw; x++) {
            uint64_t cell = ((uint64_t)(uint32_t)(cy0 + y) << 32) | (uint32_t)(cx0 + x);
            size_t at = (size_t)y * sw + x;
            tn_rng_seed(&r, tn__splitmix64(seed ^ tn__splitmix64(cell)), 0x6c6f63ULL);
            for (c = 0; c < m->noise_local; c++) zi[(size_t)c * plane + at] = tn_rng_uniform(&r);
            for (c = 0; c < m->noise_global; c++) zi[(size_t)(m->noise_local + c) * plane + at] = glob[c];
            for (c = 0; c < m->noise_periodic; c++) {
                double t = waves[2 * c] * (double)(cx0 + x) + waves[2 * c + 1] * (double)(cy0 + y) + phase[c];
                zi[(size_t)(m->noise_local + m->noise_global + c) * plane + at] = (float)(0.5 + 0.5 * sin(6.283185307179586 * t));
            }
        }
}

/* Per-pixel noise of stage i at global stage coordinates (gx, gy): a hash of (seed, stage,
   pixel), uniform with unit variance. Stage i of a window that starts at cell (cx, cy) starts at
   stage pixel (cx, cy) << (i + 1) (the generator is shift-equivariant), so every tile and
   every window sees the same noise at the same place. */
static uint64_t tn__tg_stage_seed(uint64_t seed, int stage) { return tn__splitmix64(seed ^ (0x73746167ULL + 0x9E3779B97F4A7C15ULL * (uint64_t)(stage + 1))); }

static float tn__tg_pixel_noise(uint64_t sseed, long gx, long gy)
{
    uint64_t v = tn__splitmix64(sseed ^ (((uint64_t)(uint32_t)gy << 32) | (uint32_t)gx));
    return ((float)(v >> 40) * (1.0f / 16777216.0f) - 0.5f) * 3.4641016f;
}

/* h x w noise plane of stage i for the window at cell (cx0, cy0). */
TN__INTERNAL void tn__tg_noise_plane(float *dst, uint64_t seed, int stage, long cx0, long cy0, int h, int w)
{
    uint64_t ss = tn__tg_stage_seed(seed, stage);
    long gx0 = cx0 << (stage + 1), gy0 = cy0 << (stage + 1);
    int x, y;
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++) dst[(size_t)y * w + x] = tn__tg_pixel_noise(ss, gx0 + x, gy0 + y);
}

/* ---- networks ---- */

/* Pixel norm (ProGAN): x / sqrt(mean over channels of x^2 + eps). Per location, so it keeps the
   generator local (tiling stays exact) and behaves the same in training and synthesis. */
TN__INTERNAL tn_tensor *tn__tg_pixel_norm(tn_ctx *ctx, tn_tensor *x)
{
    tn_tensor *r = tn_pow_abs(ctx, tn_scale_shift(ctx, tn_mean_axis(ctx, tn_square(ctx, x), 1), 1.0f, 1e-8f), 0.5f);
    return tn_div(ctx, x, r);
}

/* e = the stage's K x K kernel on the nearest-upsampled map, per axis: the 5 taps of w
   convolved with the upsampling's smoothing filter. Weight of w tap k in e tap a: */
static float tn__tg_tent(const tn_texgan *m, int a, int k)
{
    static const float f[3][5] = {{1.0f}, {0.25f, 0.5f, 0.25f}, {0.0625f, 0.25f, 0.375f, 0.25f, 0.0625f}};
    int d = a - k;
    return d >= 0 && d <= 2 * m->smooth ? f[m->smooth][d] : 0.0f;
}

/* conv_valid(upsample_nearest_x2(x), e) computed as one stride-2 transposed conv with a
   (K+1) x (K+1) kernel v (v[t] = e[K-1-t] + e[K-t] per axis, taps outside 0..K-1 dropped; pad
   K-1): the same function without the upsampled copy (2.7x faster forward + backward than the
   literal form). v = w M with a fixed 25 x (K+1)^2 matrix, so the gradient reaches the 5x5
   weights the model keeps. */
static tn_tensor *tn__tg_up_conv(tn_ctx *ctx, const tn_texgan *m, tn_tensor *x, tn_tensor *w, tn_tensor *b)
{
    int K = tn__tg_k(m), V = K + 1, cout = w->shape[0], cin = w->shape[1], sh[2], s4[4], perm[4] = {1, 0, 2, 3}, t, k, j;
    float A[5][10];
    tn_tensor *fold = tn_tensor_2d(ctx, 25, V * V), *v;
    tn_conv_opts co;
    if (!fold) return NULL;
    for (k = 0; k < 5; k++)
        for (t = 0; t < V; t++) {
            A[k][t] = 0.0f;
            if (K - 1 - t >= 0) A[k][t] += tn__tg_tent(m, K - 1 - t, k);
            if (K - t < K) A[k][t] += tn__tg_tent(m, K - t, k);
        }
    for (k = 0; k < 25; k++)
        for (j = 0; j < V * V; j++) fold->data[k * V * V + j] = A[k / 5][j / V] * A[k % 5][j % V];
    sh[0] = cout * cin;
    sh[1] = 25;
    s4[0] = cout; s4[1] = cin; s4[2] = V; s4[3] = V;
    v = tn_permute(ctx, tn_reshape(ctx, tn_matmul(ctx, tn_reshape(ctx, w, 2, sh), fold, 0, 0), 4, s4), perm);
    memset(&co, 0, sizeof co);
    co.stride = 2;
    co.pad = K - 1;
    return tn_conv_transpose2d(ctx, x, v, b, &co);
}

static tn_tensor *tn__tg_param(tn_params *p, const char *prefix, char kind, int i)
{
    char name[40];
    snprintf(name, sizeof name, "%s%c%d", prefix, kind, i);
    return tn_params_find(p, name);
}

/* The training graph of the generator on z (N items, item n with image seed seeds[n], the
   window starting at cell (cx0, cy0)). */
TN__INTERNAL tn_tensor *tn__tg_generate(tn_ctx *ctx, const tn_texgan *m, tn_params *p, const char *prefix, tn_tensor *z,
                                  const uint64_t *seeds, long cx0, long cy0)
{
    tn_tensor *x = z;
    int i, n;
    for (i = 0; i < m->stages && x; i++) {
        x = tn__tg_up_conv(ctx, m, x, tn__tg_param(p, prefix, 'w', i), tn__tg_param(p, prefix, 'b', i));
        if (x && m->stage_noise) {
            int N = x->shape[0], h = x->shape[2], w = x->shape[3], s4[4];
            tn_tensor *nz = tn_tensor_4d(ctx, N, 1, h, w);
            if (!nz) return NULL;
            for (n = 0; n < N; n++) tn__tg_noise_plane(nz->data + (size_t)n * h * w, seeds[n], i, cx0, cy0, h, w);
            s4[0] = 1; s4[1] = x->shape[1]; s4[2] = 1; s4[3] = 1;
            x = tn_add(ctx, x, tn_mul(ctx, nz, tn_reshape(ctx, tn__tg_param(p, prefix, 'n', i), 4, s4)));
        }
        x = i < m->stages - 1 ? tn__tg_pixel_norm(ctx, tn_leaky_relu(ctx, x, 0.2f)) : tn_tanh(ctx, x);
    }
    return x;
}

/* ---- training ---- */

/* tn__tg_train, the training state: in src/internal.h (test_texgan checks the feature term) */

/* ---- feature statistics (the anti-collapse term) ----
   A GAN on a small exemplar can collapse to a flat colour: the discriminator separates it
   perfectly and its gradient stops pointing anywhere useful. The generator therefore also
   matches, on its fake batch, the means and centred covariances of TN__TG_FEATS fixed random
   5x5 filters (ReLU) at scales 1, 2, 4 to the exemplar's: a flat output has zero covariance,
   so this term pulls it back towards the exemplar's variety whatever the discriminator does. */
/* TN__TG_FEATS (32): in src/internal.h */
#define TN__TG_FSCALES 3

TN__INTERNAL void tn__tg_make_filters(tn__tg_train *s)
{
    tn_rng r;
    size_t k, n = (size_t)TN__TG_FEATS * s->m.channels * 25;
    float sd = 1.0f / sqrtf((float)(s->m.channels * 25));
    tn_rng_seed(&r, 0x66656174ULL, 0x73746174ULL); /* fixed: no state for checkpoints */
    for (k = 0; k < n; k++) s->filt[k] = sd * tn_rng_normal(&r);
}

/* Features (F x P, P = pixels over the batch) of x at pyramid level l. */
static tn_tensor *tn__tg_feats(tn_ctx *ctx, tn__tg_train *s, tn_tensor *x, int l)
{
    int i, perm[4] = {1, 0, 2, 3}, sh[2];
    tn_tensor *w = tn_tensor_4d(ctx, TN__TG_FEATS, s->m.channels, 5, 5), *f;
    if (!w || !x) return NULL;
    memcpy(w->data, s->filt, w->numel * sizeof(float));
    for (i = 0; i < l; i++) x = tn_avg_pool2d(ctx, x, 2, 2);
    if (!x || x->shape[2] < 5 || x->shape[3] < 5) return NULL; /* too small for this level */
    f = tn_permute(ctx, tn_relu(ctx, tn_conv2d(ctx, x, w, NULL, NULL)), perm);
    if (!f) return NULL;
    sh[0] = TN__TG_FEATS;
    sh[1] = (int)(f->numel / TN__TG_FEATS);
    return tn_reshape(ctx, f, 2, sh);
}

/* Reference statistics of the whole exemplar (planar, 1 x C x H x W in [-1, 1]), accumulated over
   256 px crops so memory stays small: per level F means, then the F x F covariance. */
TN__INTERNAL tn_status tn__tg_feat_ref(tn__tg_train *s, tn_ctx *ctx, const float *ex, int W, int H)
{
    const int F = TN__TG_FEATS, per = F + F * F, C = s->m.channels;
    double *acc = (double *)tn__calloc((size_t)TN__TG_FSCALES * per * sizeof(double)), cnt[TN__TG_FSCALES] = {0};
    int l, x0, y0, i, j, c, y;
    if (!acc) return TN_ERR_OUT_OF_MEMORY;
    tn_ctx_set_grad(ctx, 0);
    for (y0 = 0; y0 < H; y0 += 256)
        for (x0 = 0; x0 < W; x0 += 256) {
            int cw = W - x0 < 256 ? W - x0 : 256, ch = H - y0 < 256 ? H - y0 : 256;
            tn_tensor *x;
            tn_ctx_reset(ctx);
            x = tn_tensor_4d(ctx, 1, C, ch, cw);
            if (!x) break;
            for (c = 0; c < C; c++)
                for (y = 0; y < ch; y++) memcpy(x->data + ((size_t)c * ch + y) * cw, ex + ((size_t)c * H + y0 + y) * W + x0, (size_t)cw * sizeof(float));
            for (l = 0; l < TN__TG_FSCALES; l++) {
                tn_tensor *f;
                int P;
                if (!(f = tn__tg_feats(ctx, s, x, l))) continue;
                P = f->shape[1];
                for (i = 0; i < F; i++) {
                    const float *a = f->data + (size_t)i * P;
                    int k;
                    for (k = 0; k < P; k++) acc[l * per + i] += a[k];
                    for (j = 0; j <= i; j++) {
                        const float *b = f->data + (size_t)j * P;
                        double d = 0;
                        for (k = 0; k < P; k++) d += (double)a[k] * b[k];
                        acc[l * per + F + i * F + j] += d;
                    }
                }
                cnt[l] += P;
            }
        }
    tn_ctx_set_grad(ctx, 1);
    if (tn_ctx_status(ctx)) {
        TN_FREE(acc);
        return tn_ctx_status(ctx);
    }
    for (l = 0; l < TN__TG_FSCALES; l++) {
        double *m = acc + l * per, *cv = m + F, n = cnt[l] > 0 ? cnt[l] : 1;
        for (i = 0; i < F; i++) m[i] /= n;
        for (i = 0; i < F; i++)
            for (j = 0; j <= i; j++) cv[i * F + j] = cv[j * F + i] = cv[i * F + j] / n - m[i] * m[j];
    }
    s->ref = acc;
    return TN_OK;
}

/* Sum over levels of |mean - ref|^2 / |ref mean|^2 + |cov - ref|^2 / |ref cov|^2. */
TN__INTERNAL tn_tensor *tn__tg_feat_loss(tn_ctx *ctx, tn__tg_train *s, tn_tensor *x)
{
    const int F = TN__TG_FEATS, per = F + F * F;
    tn_tensor *loss = NULL;
    int l, k, sh[2];
    for (l = 0; l < TN__TG_FSCALES; l++) {
        tn_tensor *f = tn__tg_feats(ctx, s, x, l), *mu, *cov, *rm, *rc, *t;
        const double *ref = s->ref + l * per;
        double nm = 1e-8, nc = 1e-8;
        if (!f || f->shape[1] < 2) return loss;
        mu = tn_mean_axis(ctx, f, 1);
        cov = tn_scale_shift(ctx, tn_matmul(ctx, tn_sub(ctx, f, mu), tn_sub(ctx, f, mu), 0, 1), 1.0f / (float)f->shape[1], 0.0f);
        sh[0] = F;
        sh[1] = 1;
        rm = tn_tensor_new(ctx, 2, sh);
        rc = tn_tensor_2d(ctx, F, F);
        if (!rm || !rc) return NULL;
        for (k = 0; k < F; k++) nm += ref[k] * ref[k], rm->data[k] = (float)ref[k];
        for (k = 0; k < F * F; k++) nc += ref[F + k] * ref[F + k], rc->data[k] = (float)ref[F + k];
        t = tn_add(ctx, tn_scale_shift(ctx, tn_sum(ctx, tn_square(ctx, tn_sub(ctx, mu, rm))), (float)(1.0 / nm), 0.0f),
                   tn_scale_shift(ctx, tn_sum(ctx, tn_square(ctx, tn_sub(ctx, cov, rc))), (float)(1.0 / nc), 0.0f));
        loss = loss ? tn_add(ctx, loss, t) : t;
    }
    return loss;
}

static void tn__tg_train_free(tn__tg_train *s)
{
    TN_FREE(s->filt);
    TN_FREE(s->ref);
    tn_optim_free(s->og);
    tn_optim_free(s->od);
    tn_params_free(s->g);
    tn_params_free(s->d);
    tn_texgan_free(&s->m);
}

/* Builds nets and optimisers for s->m's architecture, initialised from s->rng. */
static tn_status tn__tg_build(tn__tg_train *s)
{
    tn_optim_opts oo;
    int i;
    if (tn__tg_model_params(&s->m)) return TN_ERR_OUT_OF_MEMORY;
    s->g = tn_params_create();
    s->d = tn_params_create();
    if (!s->g || !s->d || tn__tg_add_gen(s->g, &s->m, "g.", 1))
        return tn__fail(TN_ERR_OUT_OF_MEMORY, "texgan: out of memory building the networks");
    for (i = 0; i < tn_params_count(s->g); i++) {
        tn_tensor *t = tn_params_get(s->g, i);
        if (t->ndim == 4) tn_init_kaiming(t, &s->rng, i == 2 * (s->m.stages - 1) ? 0.5f : 1.41f);
        else if (t->name[2] == 'n') tn_init_normal(t, &s->rng, 0.1f, 0.0f); /* stage noise on from the start */
        memcpy(tn_params_get(s->m.weights, i + 2)->data, t->data, t->numel * sizeof(float));
    }
    if (tn_patch_disc_add(s->d, "d.", s->m.channels, s->disc_width, s->disc_layers, 5, &s->rng, &s->disc))
        return tn__fail(TN_ERR_OUT_OF_MEMORY, "texgan: out of memory building the discriminator");
    { /* periodic wave vectors: random directions, periods of 2 to 16 cells */
        tn_tensor *w = tn_params_find(s->m.weights, "texgan.waves");
        for (i = 0; i < s->m.noise_periodic; i++) {
            double ang = 6.283185307179586 * tn_rng_uniform(&s->rng), f = 1.0 / (2.0 + 14.0 * tn_rng_uniform(&s->rng));
            w->data[2 * i] = (float)(f * cos(ang));
            w->data[2 * i + 1] = (float)(f * sin(ang));
        }
    }
    memset(&oo, 0, sizeof oo);
    oo.lr = s->lr;
    oo.beta1 = 0.5f;
    oo.beta2 = 0.999f;
    s->og = tn_optim_create(s->g, &oo);
    s->od = tn_optim_create(s->d, &oo);
    if (!s->og || !s->od) return tn__fail(TN_ERR_OUT_OF_MEMORY, "texgan: out of memory for the optimisers");
    return TN_OK;
}

/* The settings a checkpoint keeps beside the architecture (its config tensor), with the range
   each must lie in when read back. */
static const char *const tn__tg_settings[6] = {"patch", "batch", "lr", "ema", "augment", "feat_weight"};
static const double tn__tg_settings_lo[6] = {8, 1, 1e-30, 1e-30, -1e9, 0}, tn__tg_settings_hi[6] = {4096, 1024, 0.999999, 0.999999, 1e9, 1e6};

static tn_status tn__tg_put_settings(tn__tg_train *s)
{
    const double v[6] = {(double)s->patch, (double)s->batch, s->lr, s->ema, (double)s->augment, s->feat_weight};
    tn_status st = TN_OK;
    int i;
    for (i = 0; i < 6 && !st; i++) st = tn_train_set_meta_number(s->run, tn__tg_settings[i], v[i]);
    return st;
}

static tn_status tn__tg_get_settings(tn__tg_train *s)
{
    double v[6];
    tn_status st = TN_OK;
    int i;
    for (i = 0; i < 6 && !st; i++) st = tn_train_meta_number(s->run, tn__tg_settings[i], tn__tg_settings_lo[i], tn__tg_settings_hi[i], &v[i]);
    if (!st && (v[0] != floor(v[0]) || v[1] != floor(v[1])))
        st = tn__fail(TN_ERR_CORRUPT, "texgan: the checkpoint's patch and batch must be whole numbers");
    if (st) return st;
    s->patch = (int)v[0];
    s->batch = (int)v[1];
    s->lr = (float)v[2];
    s->ema = (float)v[3];
    s->augment = v[4] != 0.0;
    s->feat_weight = (float)v[5];
    return TN_OK;
}

static void tn__tg_put_u64_meta(tn_params *ck, const char *key, uint64_t state, uint64_t inc)
{
    char hex[40];
    tn__hex64(hex, state);
    hex[16] = ':';
    tn__hex64(hex + 17, inc);
    tn_params_set_meta(ck, key, hex);
}

static uint64_t tn__tg_get_u64(const float *f)
{
    uint64_t v = 0;
    int i;
    for (i = 0; i < 4; i++) v |= (uint64_t)((uint32_t)f[i] & 0xffffu) << (16 * i);
    return v;
}

/* Checkpoints written before @@train held a "train.state" vector (counters as 24-bit halves, the
   RNG in 16-bit quarters, the settings) and the config unprefixed: rewritten in memory into the
   current layout, every field range-checked before its cast. */
static tn_status tn__tg_upgrade_legacy(tn_params *ck, const char *name)
{
    const tn_tensor *ts = tn_params_find(ck, "train.state"), *cfg = tn_params_find(ck, "texgan.config");
    const float *st;
    tn_tensor *c;
    char buf[40];
    int i;
    if (tn_params_meta(ck, "iteration")) return TN_OK;
    if (!ts || ts->numel != TN__TG_STATE || !cfg || cfg->numel != TN__TG_CONFIG)
        return tn__fail(TN_ERR_FORMAT, "%s: not a texgan checkpoint", name);
    st = ts->data;
    for (i = 0; i < 19; i++)
        if (st[i] != st[i] || st[i] < 0 || st[i] > 1e12f) return tn__fail(TN_ERR_CORRUPT, "%s: bad training state", name);
    for (i = 0; i < 3; i++)
        if (!tn__tg_whole(st[i ? 9 + 2 * i : 0], 16777215.0f) || !tn__tg_whole(st[i ? 10 + 2 * i : 1], 127.0f))
            return tn__fail(TN_ERR_CORRUPT, "%s: bad training state counters", name);
    for (i = 3; i < 11; i++)
        if (!tn__tg_whole(st[i], 65535.0f)) return tn__fail(TN_ERR_CORRUPT, "%s: bad training state RNG", name);
    tn__meta_put_num(ck, "iteration", (double)st[0] + 16777216.0 * st[1]);
    tn__meta_put_num(ck, "microseconds", floor((double)st[2] * 1e6));
    tn__meta_put_num(ck, "step.g", (double)st[11] + 16777216.0 * st[12]);
    tn__meta_put_num(ck, "step.d", (double)st[13] + 16777216.0 * st[14]);
    tn__tg_put_u64_meta(ck, "rng.main", tn__tg_get_u64(st + 3), tn__tg_get_u64(st + 7) | 1u);
    for (i = 0; i < 6; i++) {
        const double v = i == 5 ? st[20] : st[15 + i];
        char key[40];
        tn__io_format_number(buf, sizeof buf, v, i >= 2);
        snprintf(key, sizeof key, "config.%s", tn__tg_settings[i]);
        tn_params_set_meta(ck, key, buf);
    }
    if (!(c = tn_params_add_buffer(ck, "ema.texgan.config", 1, cfg->shape))) return TN_ERR_OUT_OF_MEMORY;
    memcpy(c->data, cfg->data, cfg->numel * sizeof(float));
    return TN_OK;
}

/* Registers the whole training state with the run. */
static tn_status tn__tg_register(tn__tg_train *s)
{
    tn_status st = tn_train_add_params(s->run, "ema.", s->m.weights);
    if (!st) st = tn_train_add_net(s->run, "g", s->g, s->og);
    if (!st) st = tn_train_add_net(s->run, "d", s->d, s->od);
    if (!st) st = tn_train_add_rng(s->run, "main", &s->rng);
    return st;
}

/* Whether a checkpoint holds the discriminator its config names (tn_patch_disc_add's layers),
   checked before it is allocated: a width of 1024 over 5 layers took 5.3 GB and 22 s to fail. */
static tn_status tn__tg_disc_matches(const tn__tg_train *s, const tn_params *ck, const char *path)
{
    int l, ws[4];
    char name[40];
    ws[1] = s->m.channels;
    ws[2] = ws[3] = 5;
    for (l = 0; l <= s->disc_layers; l++) {
        ws[0] = l == s->disc_layers ? 1 : s->disc_width << l;
        if (!tn__params_has(ck, tn__param_name(name, sizeof name, "d.", "w", l), 4, ws))
            return tn__fail(TN_ERR_CORRUPT, "%s: the texgan config names a discriminator %d wide with %d layers; the checkpoint's differs", path,
                            s->disc_width, s->disc_layers);
        ws[1] = ws[0];
    }
    return TN_OK;
}

/* Resumes from the run's checkpoint: the architecture and settings come from the file. */
static tn_status tn__tg_resume(tn__tg_train *s, const tn_image *ex, const char *path)
{
    tn_params *ck = NULL;
    tn_tensor *cfg;
    tn_status st = tn_train_open_checkpoint(s->run, &ck);
    if (!st) st = tn__tg_upgrade_legacy(ck, path);
    if (!st && (!(cfg = tn_params_find(ck, "ema.texgan.config")) || cfg->numel != TN__TG_CONFIG))
        st = tn__fail(TN_ERR_FORMAT, "%s: not a texgan checkpoint", path);
    if (!st) st = tn__tg_read_config(&s->m, &s->disc_width, &s->disc_layers, cfg->data, path);
    if (!st && (s->disc_width < 1 || s->disc_width > 1024 || s->disc_layers < 1 || s->disc_layers > TN__TG_MAX_DLAYERS))
        st = tn__fail(TN_ERR_CORRUPT, "%s: bad discriminator size", path);
    if (!st && s->m.channels != ex->channels)
        st = tn__fail(TN_ERR_SHAPE, "%s: checkpoint has %d channels, the exemplar %d", path, s->m.channels, ex->channels);
    if (!st) st = tn__tg_file_matches(&s->m, ck, path); /* the training generator's tensors, before the config sizes anything */
    if (!st) st = tn__tg_disc_matches(s, ck, path);
    if (!st) st = tn__tg_get_settings(s);
    if (!st) st = tn__tg_build(s);
    if (!st) st = tn__tg_register(s);
    if (!st) st = tn_train_restore(s->run);
    if (!st) st = tn__tg_put_settings(s);
    return st;
}

/* Random real patches (batch x C x n x n, in [-1, 1]) from the planar normalised exemplar. */
static void tn__tg_real_batch(tn__tg_train *s, const float *ex, int W, int H, tn_tensor *real)
{
    int n = s->patch, C = s->m.channels, b, c, y, x;
    for (b = 0; b < s->batch; b++) {
        int x0 = (int)tn_rng_below(&s->rng, (uint32_t)(W - n + 1)), y0 = (int)tn_rng_below(&s->rng, (uint32_t)(H - n + 1));
        int t = s->augment ? (int)tn_rng_below(&s->rng, 8) : 0; /* bit 0 flip x, bit 1 flip y, bit 2 transpose */
        for (c = 0; c < C; c++)
            for (y = 0; y < n; y++) {
                float *dst = real->data + (((size_t)b * C + c) * n + y) * n;
                if (!t) {
                    memcpy(dst, ex + ((size_t)c * H + y0 + y) * W + x0, (size_t)n * sizeof(float));
                    continue;
                }
                for (x = 0; x < n; x++) {
                    int u = t & 1 ? n - 1 - x : x, v = t & 2 ? n - 1 - y : y;
                    if (t & 4) { int k = u; u = v; v = k; }
                    dst[x] = ex[((size_t)c * H + y0 + v) * W + x0 + u];
                }
            }
    }
}

/* Generator output for a fresh noise batch, cropped to n x n at a random offset (so no phase of
   the 2^stages cell grid is favoured). */
static tn_tensor *tn__tg_fake_batch(tn_ctx *ctx, tn__tg_train *s)
{
    int cells = tn__tg_cells_for(&s->m, s->patch), r = tn__tg_out_size(&s->m, cells), b, ox, oy;
    tn_tensor *z = tn_tensor_4d(ctx, s->batch, tn__tg_zdim(&s->m), cells, cells), *x;
    const float *waves = tn_params_find(s->m.weights, "texgan.waves")->data;
    uint64_t seeds[1024];
    if (!z) return NULL;
    for (b = 0; b < s->batch; b++) {
        seeds[b] = ((uint64_t)tn_rng_u32(&s->rng) << 32) | tn_rng_u32(&s->rng);
        tn__tg_noise(&s->m, waves, z, b, seeds[b], 0, 0);
    }
    ox = (int)tn_rng_below(&s->rng, (uint32_t)(r - s->patch + 1));
    oy = (int)tn_rng_below(&s->rng, (uint32_t)(r - s->patch + 1));
    x = tn__tg_generate(ctx, &s->m, s->g, "g.", z, seeds, 0, 0);
    return tn_slice(ctx, tn_slice(ctx, x, 2, oy, s->patch), 3, ox, s->patch);
}

/* One D step and one G step; the losses go to *ld, *lg. */
static tn_status tn__tg_step(tn__tg_train *s, tn_ctx *ctx, const float *ex, int W, int H, float *ld, float *lg)
{
    tn_tensor *real, *fake, *loss;
    tn_status st;
    long it = tn_train_iteration(s->run);
    tn_ctx_reset(ctx);
    tn_ctx_set_grad(ctx, 0); /* D step: the fake batch is a constant */
    fake = tn__tg_fake_batch(ctx, s);
    tn_ctx_set_grad(ctx, 1);
    real = tn_tensor_4d(ctx, s->batch, s->m.channels, s->patch, s->patch);
    if (!fake || !real) return tn_ctx_status(ctx);
    tn__tg_real_batch(s, ex, W, H, real);
    tn_patch_disc_begin(ctx, &s->disc);
    loss = tn_hinge_d_loss(ctx, tn_patch_disc_score(ctx, &s->disc, real), tn_patch_disc_score(ctx, &s->disc, fake));
    tn_params_zero_grad(s->d);
    if ((st = tn_backward(ctx, loss))) return st;
    tn_optim_step(s->od);
    *ld = loss->data[0];

    tn_ctx_reset(ctx);
    fake = tn__tg_fake_batch(ctx, s);
    tn_patch_disc_begin(ctx, &s->disc);
    loss = tn_hinge_g_loss(ctx, tn_patch_disc_score(ctx, &s->disc, fake));
    if (s->feat_weight > 0 && s->ref && loss) {
        tn_tensor *fl = tn__tg_feat_loss(ctx, s, fake);
        if (fl) loss = tn_add(ctx, loss, tn_scale_shift(ctx, fl, s->feat_weight, 0.0f));
    }
    if (!loss) return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : tn__fail(TN_ERR_OUT_OF_MEMORY, "texgan: out of memory");
    tn_params_zero_grad(s->g);
    if ((st = tn_backward(ctx, loss))) return st;
    tn_optim_step(s->og);
    *lg = loss->data[0];
    if (*ld != *ld || *lg != *lg || *ld > 1e6f || *lg > 1e6f || *lg < -1e6f)
        return tn__fail(TN_ERR_NUMERIC, "texgan: training diverged at iteration %ld (D loss %g, G loss %g)", it, (double)*ld, (double)*lg);
    tn_ema_update(s->m.weights, s->g, s->ema, it);
    return TN_OK;
}

/* Checks an exemplar and returns its value range and per-channel mean. */
static tn_status tn__tg_check_exemplar(const tn_image *ex, float *lo, float *hi, float *mean)
{
    size_t n, i;
    int c;
    double sum[TN_TEXGAN_MAX_CHANNELS];
    if (!ex || !ex->data || ex->width <= 0 || ex->height <= 0) return tn__fail(TN_ERR_EMPTY, "texgan: the exemplar is empty");
    if (ex->channels < 1 || ex->channels > TN_TEXGAN_MAX_CHANNELS)
        return tn__fail(TN_ERR_SHAPE, "texgan: the exemplar has %d channels (1..%d)", ex->channels, TN_TEXGAN_MAX_CHANNELS);
    if (tn_image_range(lo, hi, ex)) return tn__fail(TN_ERR_NUMERIC, "texgan: the exemplar holds NaN/Inf");
    if (*lo > 0.0f) *lo = 0.0f;
    if (*hi < 1.0f) *hi = 1.0f;
    n = (size_t)ex->width * ex->height;
    for (c = 0; c < ex->channels; c++) sum[c] = 0;
    for (i = 0; i < n; i++)
        for (c = 0; c < ex->channels; c++) sum[c] += ex->data[i * ex->channels + c];
    for (c = 0; c < TN_TEXGAN_MAX_CHANNELS; c++) mean[c] = c < ex->channels ? (float)(sum[c] / (double)n) : 0.0f;
    return TN_OK;
}

/* Fresh training state from the options. */
static tn_status tn__tg_fresh(tn__tg_train *s, const tn_image *ex, const tn_texgan_opts *o, float lo, float hi, const float *mean)
{
    tn_status st;
    s->m.channels = ex->channels;
    s->m.noise_local = o->noise_local;
    s->m.noise_global = o->noise_global;
    s->m.noise_periodic = o->noise_periodic;
    s->m.stages = o->stages;
    s->m.gen_width = o->gen_width;
    s->m.scale = o->scale > 0 ? o->scale : 1;
    s->m.smooth = o->nearest ? 0 : 2;
    s->m.stage_noise = !o->nearest;
    s->m.lo = lo;
    s->m.hi = hi;
    memcpy(s->m.mean, mean, TN_TEXGAN_MAX_CHANNELS * sizeof(float));
    if ((st = tn__tg_check_arch(&s->m))) return st;
    if (s->disc_width > 1024 || s->disc_layers > TN__TG_MAX_DLAYERS)
        return tn__fail(TN_ERR_INVALID_ARG, "texgan: discriminator of %d layers from %d channels is too large", s->disc_layers, s->disc_width);
    if (s->patch < 8 || s->patch > 4096 || s->batch > 1024) return tn__fail(TN_ERR_INVALID_ARG, "texgan: patch %d / batch %d out of range", s->patch, s->batch);
    if ((st = tn__tg_build(s))) return st;
    tn__tg_write_config(&s->m, s->disc_width, s->disc_layers, tn_params_find(s->m.weights, "texgan.config")->data); /* checkpoints carry it */
    if ((st = tn__tg_register(s))) return st;
    return tn__tg_put_settings(s);
}

TN_API tn_status tn_texgan_train(tn_texgan *model, const tn_image *ex, const tn_texgan_opts *opts_in, tn_texgan_stats *stats)
{
    tn_texgan_opts o;
    tn__tg_train s;
    tn_image small = {0, 0, 0, NULL};
    const tn_image *ex0 = ex;
    tn_ctx *ctx = NULL;
    float *exn = NULL, lo = 0, hi = 1, mean[TN_TEXGAN_MAX_CHANNELS], ldh[50], lgh[50];
    int nh = 0, c;
    size_t i, npx;
    tn_status st;
    TN_ASSERT(model);
    memset(&o, 0, sizeof o);
    if (opts_in) o = *opts_in;
    tn_texgan_defaults(&o);
    if ((st = tn__tg_check_exemplar(ex, &lo, &hi, mean))) return st;
    memset(&s, 0, sizeof s);
    if ((st = tn_train_create(&s.run, "texgan", "texgan-train", &o.train))) return st;
    tn_rng_seed(&s.rng, o.train.seed, 0x7467616eULL);
    s.disc_width = o.disc_width;
    s.disc_layers = o.disc_layers;
    s.patch = o.patch;
    s.batch = o.batch;
    s.augment = o.augment != 0;
    s.lr = o.lr;
    s.ema = o.ema < 1.0f ? o.ema : 0.999f;
    s.feat_weight = o.feat_weight > 0 ? o.feat_weight : 0.0f;
    st = o.train.resume ? tn__tg_resume(&s, ex, o.train.checkpoint) : tn__tg_fresh(&s, ex, &o, lo, hi, mean);
    if (!st && s.m.scale > 1) { /* the generator learns the downscaled exemplar */
        int sw = (ex->width + s.m.scale / 2) / s.m.scale, sh = (ex->height + s.m.scale / 2) / s.m.scale;
        if (sw < 1 || sh < 1) st = tn__fail(TN_ERR_INVALID_ARG, "texgan: the exemplar is too small for scale %d", s.m.scale);
        else st = tn_image_resize(&small, ex, sw, sh, TN_RESIZE_AREA);
        if (!st) ex = &small;
    }
    if (!st && (ex->width < s.patch || ex->height < s.patch))
        st = tn__fail(TN_ERR_INVALID_ARG, "texgan: the exemplar (%d x %d at scale 1/%d) is smaller than the %d px patch", ex->width, ex->height,
                      s.m.scale, s.patch);
    if (!st && !(ctx = tn_ctx_create())) st = tn__fail(TN_ERR_OUT_OF_MEMORY, "texgan: out of memory");
    npx = (size_t)ex->width * ex->height;
    if (!st && !(exn = (float *)tn__alloc(npx * (size_t)ex->channels * sizeof(float)))) st = TN_ERR_OUT_OF_MEMORY;
    if (!st && s.feat_weight > 0 && !(s.filt = (float *)tn__alloc((size_t)TN__TG_FEATS * ex->channels * 25 * sizeof(float))))
        st = TN_ERR_OUT_OF_MEMORY;
    if (!st) { /* planar, scaled to the generator's tanh range */
        for (c = 0; c < ex->channels; c++)
            for (i = 0; i < npx; i++) exn[(size_t)c * npx + i] = 2.0f * (ex->data[i * ex->channels + c] - s.m.lo) / (s.m.hi - s.m.lo) - 1.0f;
        if (s.filt) {
            tn__tg_make_filters(&s);
            st = tn__tg_feat_ref(&s, ctx, exn, ex->width, ex->height);
        }
    }
    while (!st && tn_train_next(s.run)) {
        float ld = 0, lg = 0;
        tn_status e = tn__tg_step(&s, ctx, exn, ex->width, ex->height, &ld, &lg);
        if (e) {
            tn_train_fail(s.run, e);
            break;
        }
        ldh[nh % 50] = ld;
        lgh[nh % 50] = lg;
        nh++;
    }
    if (!st) st = tn_train_finish(s.run);
    if (stats) {
        int k, m = nh < 50 ? nh : 50;
        long it = tn_train_iteration(s.run), it0 = tn_train_start_iteration(s.run);
        memset(stats, 0, sizeof *stats);
        stats->iterations = it;
        stats->resumed_from = o.train.resume ? it0 : 0;
        stats->seconds = tn_train_seconds(s.run);
        stats->seconds_per_iter = it > it0 ? (tn_train_seconds(s.run) - tn_train_start_seconds(s.run)) / (double)(it - it0) : 0.0;
        for (k = 0; k < m; k++) {
            stats->loss_d += ldh[k] / (float)m;
            stats->loss_g += lgh[k] / (float)m;
        }
        stats->checkpoints = tn_train_checkpoints(s.run);
    }
    TN_FREE(exn);
    tn_ctx_free(ctx);
    tn_image_free(&small);
    if (!st) {
        s.m.iterations = tn_train_iteration(s.run);
        s.m.train_seconds = tn_train_seconds(s.run);
        tn__tg_write_config(&s.m, s.disc_width, s.disc_layers, tn_params_find(s.m.weights, "texgan.config")->data);
        st = tn__train_stamp(s.m.weights, "texgan", TN__TG_FORMAT, s.run, tn_image_digest(ex0), ex0->width, ex0->height, ex0->channels);
    }
    if (!st) {
        *model = s.m;
        memset(&s.m, 0, sizeof s.m); /* handed over */
    }
    tn_train_free(s.run);
    tn__tg_train_free(&s);
    return st;
}

/* ---- synthesis ---- */

static tn_status tn__tg_check_model(const tn_texgan *m)
{
    if (!m || !m->weights) return tn__fail(TN_ERR_INVALID_ARG, "texgan: no model");
    return tn__tg_check_arch(m);
}

/* Inference form of the generator, same function as tn__tg_generate with fewer operations:
   a valid K x K conv e of a nearest-x2-upsampled map is, per output parity (py, px), a T x T
   valid conv of the map itself (T = (K + 1) / 2; e tap k lands on tap (k + parity) / 2), so all
   four phases run as one conv with 4 x Cout filters (no upsampled copy; for the 5x5 nearest
   stage 2.8x fewer multiply-adds), followed by an interleave with the bias and stage noise and a
   fused leaky ReLU + pixel norm (tanh last). */
static tn_tensor *tn__tg_phase_weights(tn_ctx *ctx, const tn_texgan *m, const tn_tensor *w)
{
    int K = tn__tg_k(m), T = (K + 1) / 2, cout = w->shape[0], cin = w->shape[1], py, px, co, ci, k, a, b;
    float tmp[9][5], e[9][9];
    tn_tensor *p = tn_tensor_4d(ctx, 4 * cout, cin, T, T);
    if (!p) return NULL;
    for (co = 0; co < cout; co++)
        for (ci = 0; ci < cin; ci++) {
            const float *src = w->data + ((size_t)co * cin + ci) * 25;
            for (a = 0; a < K; a++) /* e = tent w tent^T, separably */
                for (b = 0; b < 5; b++)
                    for (tmp[a][b] = 0.0f, k = 0; k < 5; k++) tmp[a][b] += tn__tg_tent(m, a, k) * src[k * 5 + b];
            for (a = 0; a < K; a++)
                for (b = 0; b < K; b++)
                    for (e[a][b] = 0.0f, k = 0; k < 5; k++) e[a][b] += tmp[a][k] * tn__tg_tent(m, b, k);
            for (py = 0; py < 2; py++)
                for (px = 0; px < 2; px++) {
                    float *dst = p->data + (((size_t)(py * 2 + px) * cout + co) * cin + ci) * T * T;
                    for (a = 0; a < K; a++)
                        for (b = 0; b < K; b++) dst[((a + py) / 2) * T + (b + px) / 2] += e[a][b];
                }
        }
    return p;
}

TN__INTERNAL tn_tensor *tn__tg_generate_fast(tn_ctx *ctx, const tn_texgan *m, tn_tensor *z, uint64_t seed, long cx0, long cy0)
{
    tn_tensor *x = z;
    int i;
    for (i = 0; i < m->stages && x; i++) {
        tn_tensor *w = tn__tg_param(m->weights, "g.", 'w', i), *b = tn__tg_param(m->weights, "g.", 'b', i), *y4, *o, *nz = NULL;
        const float *ns = m->stage_noise ? tn__tg_param(m->weights, "g.", 'n', i)->data : NULL;
        int cout = w->shape[0], h, wd, c, yy, xx;
        size_t plane, oplane;
        y4 = tn_conv2d(ctx, x, tn__tg_phase_weights(ctx, m, w), NULL, NULL);
        if (!y4) return NULL;
        h = y4->shape[2];
        wd = y4->shape[3];
        o = tn_tensor_4d(ctx, 1, cout, 2 * h, 2 * wd);
        if (ns) nz = tn_tensor_2d(ctx, 2 * h, 2 * wd);
        if (!o || (ns && !nz)) return NULL;
        if (nz) tn__tg_noise_plane(nz->data, seed, i, cx0, cy0, 2 * h, 2 * wd);
        plane = (size_t)h * wd;
        oplane = (size_t)4 * plane;
        for (c = 0; c < cout; c++)
            for (yy = 0; yy < 2 * h; yy++) {
                const float *r0 = y4->data + ((size_t)((yy & 1) * 2) * cout + c) * plane + (size_t)(yy >> 1) * wd;
                const float *r1 = r0 + (size_t)cout * plane;
                float *d = o->data + (size_t)c * oplane + (size_t)yy * 2 * wd, bc = b->data[c];
                for (xx = 0; xx < wd; xx++) {
                    d[2 * xx] = r0[xx] + bc;
                    d[2 * xx + 1] = r1[xx] + bc;
                }
                if (nz) {
                    const float *nr = nz->data + (size_t)yy * 2 * wd;
                    float sc = ns[c];
                    for (xx = 0; xx < 2 * wd; xx++) d[xx] += sc * nr[xx];
                }
            }
        if (i == m->stages - 1) {
            size_t k;
            for (k = 0; k < o->numel; k++) o->data[k] = 1.0f - 2.0f / (expf(2.0f * o->data[k]) + 1.0f); /* tanh; glibc's tanhf was 12 % of synthesis */
        } else {
            size_t k;
            for (k = 0; k < oplane; k++) {
                double ss = 0;
                float r;
                for (c = 0; c < cout; c++) {
                    float *v = o->data + (size_t)c * oplane + k;
                    if (*v < 0) *v *= 0.2f;
                    ss += (double)*v * *v;
                }
                r = 1.0f / sqrtf((float)(ss / cout) + 1e-8f);
                for (c = 0; c < cout; c++) o->data[(size_t)c * oplane + k] *= r;
            }
        }
        x = o;
    }
    return x;
}

/* Runs the generator on the cells covering the window and copies the window into out (which
   is w x h x channels, written at column offset ox of a row stride of stride_w pixels). */
static tn_status tn__tg_window_native(tn_ctx *ctx, const tn_texgan *m, uint64_t seed, int x0, int y0, int w, int h, float *out,
                                      int stride_w)
{
    int p = 1 << m->stages, cx0 = x0 / p, cy0 = y0 / p, dx = x0 - cx0 * p, dy = y0 - cy0 * p;
    int sw = tn__tg_cells_for(m, dx + w), sh = tn__tg_cells_for(m, dy + h), C = m->channels, x, y, c;
    tn_tensor *z, *g;
    size_t plane;
    float scale = 0.5f * (m->hi - m->lo);
    tn_ctx_reset(ctx);
    tn_ctx_set_grad(ctx, 0);
    z = tn_tensor_4d(ctx, 1, tn__tg_zdim(m), sh, sw);
    if (!z) return tn_ctx_status(ctx);
    tn__tg_noise(m, tn_params_find(m->weights, "texgan.waves")->data, z, 0, seed, cx0, cy0);
    g = tn__tg_generate_fast(ctx, m, z, seed, cx0, cy0);
    if (!g) return tn_ctx_status(ctx);
    plane = (size_t)g->shape[2] * g->shape[3];
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++)
            for (c = 0; c < C; c++)
                out[((size_t)y * stride_w + x) * C + c] =
                    m->lo + (g->data[(size_t)c * plane + (size_t)(dy + y) * g->shape[3] + dx + x] + 1.0f) * scale;
    return TN_OK;
}

/* Low-resolution source position of output pixel X at scale s (texel centres aligned), from
   global coordinates only, so every tile samples the same way; clamped at the texture origin. */
static void tn__tg_src(int X, int s, int *i0, int *i1, float *f)
{
    float t = ((float)X + 0.5f) / (float)s - 0.5f, fl = floorf(t);
    *i0 = (int)fl;
    *f = t - fl;
    *i1 = *i0 + 1;
    if (*i0 < 0) { *i0 = 0; *i1 = 0; *f = 0.0f; }
}

/* A window of the output texture: the generator's own pixels, or (scale > 1) the low-resolution
   window with a one-pixel margin, bilinearly upsampled. */
static tn_status tn__tg_window(tn_ctx *ctx, const tn_texgan *m, uint64_t seed, int x0, int y0, int w, int h, float *out, int stride_w)
{
    int s = m->scale, lx0, ly0, lx1, ly1, lw, lh, x, y, c, C = m->channels, a0, a1, b0, b1;
    float fa, fb, *low;
    tn_status st;
    if (s <= 1) return tn__tg_window_native(ctx, m, seed, x0, y0, w, h, out, stride_w);
    tn__tg_src(x0, s, &lx0, &a1, &fa);
    tn__tg_src(y0, s, &ly0, &b1, &fb);
    tn__tg_src(x0 + w - 1, s, &a0, &lx1, &fa);
    tn__tg_src(y0 + h - 1, s, &b0, &ly1, &fb);
    lw = lx1 - lx0 + 1;
    lh = ly1 - ly0 + 1;
    low = (float *)tn__alloc((size_t)lw * lh * C * sizeof(float));
    if (!low) return TN_ERR_OUT_OF_MEMORY;
    st = tn__tg_window_native(ctx, m, seed, lx0, ly0, lw, lh, low, lw);
    for (y = 0; !st && y < h; y++) {
        tn__tg_src(y0 + y, s, &b0, &b1, &fb);
        for (x = 0; x < w; x++) {
            const float *p00, *p01, *p10, *p11;
            tn__tg_src(x0 + x, s, &a0, &a1, &fa);
            p00 = low + ((size_t)(b0 - ly0) * lw + (a0 - lx0)) * C;
            p01 = low + ((size_t)(b0 - ly0) * lw + (a1 - lx0)) * C;
            p10 = low + ((size_t)(b1 - ly0) * lw + (a0 - lx0)) * C;
            p11 = low + ((size_t)(b1 - ly0) * lw + (a1 - lx0)) * C;
            for (c = 0; c < C; c++) {
                float top = p00[c] + (p01[c] - p00[c]) * fa, bot = p10[c] + (p11[c] - p10[c]) * fa;
                out[((size_t)y * stride_w + x) * C + c] = top + (bot - top) * fb;
            }
        }
    }
    TN_FREE(low);
    return st;
}

static tn_status tn__tg_check_size(int w, int h)
{
    if (w <= 0 || h <= 0) return tn__fail(TN_ERR_INVALID_ARG, "texgan: output size %d x %d is not positive", w, h);
    if (w > (1 << 24) || h > (1 << 24)) return tn__fail(TN_ERR_TOO_LARGE, "texgan: output size %d x %d is too large", w, h);
    return TN_OK;
}

TN_API tn_status tn_texgan_synthesize_window(tn_image *out, const tn_texgan *model, uint64_t seed, int x0, int y0, int w, int h)
{
    tn_image img = {0, 0, 0, NULL};
    tn_ctx *ctx;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__tg_check_model(model)) || (st = tn__tg_check_size(w, h))) return st;
    if (x0 < 0 || y0 < 0) return tn__fail(TN_ERR_INVALID_ARG, "texgan: window origin %d, %d is negative", x0, y0);
    if ((st = tn_image_create(&img, w, h, model->channels))) return st;
    if (!(ctx = tn_ctx_create())) {
        tn_image_free(&img);
        return tn__fail(TN_ERR_OUT_OF_MEMORY, "texgan: out of memory");
    }
    st = tn__tg_window(ctx, model, seed, x0, y0, w, h, img.data, w);
    tn_ctx_free(ctx);
    if (st) tn_image_free(&img);
    else *out = img;
    return st;
}

/* One band of tiles: threads take tiles i = ith, ith + nth, ... (each tile is computed alone,
   so the result does not depend on the split); every thread has its own arena. */
typedef struct tn__tg_band_job {
    const tn_texgan *m;
    uint64_t seed;
    int y0, bh, width, tile_px, ntiles;
    tn_image *band;
    tn_ctx **ctx;
    tn_status st[64];
} tn__tg_band_job;

static void tn__tg_band_task(void *arg, int ith, int nth)
{
    tn__tg_band_job *j = (tn__tg_band_job *)arg;
    int i;
    if (ith >= 64) return;
    j->st[ith] = TN_OK;
    for (i = ith; i < j->ntiles && !j->st[ith]; i += nth) {
        int x0 = i * j->tile_px, w = j->width - x0 < j->tile_px ? j->width - x0 : j->tile_px;
        j->st[ith] = tn__tg_window(j->ctx[ith], j->m, j->seed, x0, j->y0, w, j->bh, j->band->data + (size_t)x0 * j->m->channels,
                                   j->width);
    }
}

TN_API tn_status tn_texgan_synthesize_stream(const tn_texgan *model, uint64_t seed, int width, int height, int tile_cells,
                                             tn_band_fn fn, void *user)
{
    tn__tg_band_job job;
    tn_image band = {0, 0, 0, NULL};
    tn_ctx *ctxs[64];
    int nth = tn_get_threads(), t, y0, tile_px;
    tn_status st;
    TN_ASSERT(fn);
    if ((st = tn__tg_check_model(model)) || (st = tn__tg_check_size(width, height))) return st;
    if (tile_cells <= 0) tile_cells = 32;
    if (tile_cells > 4096) return tn__fail(TN_ERR_INVALID_ARG, "texgan: tile of %d cells is too large", tile_cells);
    tile_px = tile_cells << model->stages;
    if (nth > 64) nth = 64;
    memset(ctxs, 0, sizeof ctxs);
    for (t = 0; t < nth; t++)
        if (!(ctxs[t] = tn_ctx_create())) st = tn__fail(TN_ERR_OUT_OF_MEMORY, "texgan: out of memory");
    if (!st) st = tn_image_create(&band, width, height < tile_px ? height : tile_px, model->channels);
    memset(&job, 0, sizeof job);
    job.m = model;
    job.seed = seed;
    job.width = width;
    job.tile_px = tile_px;
    job.ntiles = (width + tile_px - 1) / tile_px;
    job.band = &band;
    job.ctx = ctxs;
    for (y0 = 0; !st && y0 < height; y0 += tile_px) {
        job.y0 = y0;
        job.bh = height - y0 < tile_px ? height - y0 : tile_px;
        band.height = job.bh;
        for (t = 0; t < 64; t++) job.st[t] = TN_OK;
        if (nth > 1) tn_parallel_run(tn__tg_band_task, &job);
        else tn__tg_band_task(&job, 0, 1);
        for (t = 0; t < 64 && !st; t++) st = job.st[t];
        if (!st) st = fn(user, y0, &band);
        if (!st) st = tn__progress("texgan-synth", (double)(y0 + job.bh) / height);
    }
    tn_image_free(&band);
    for (t = 0; t < nth; t++) tn_ctx_free(ctxs[t]);
    return st;
}

TN__INTERNAL tn_status tn__tg_collect_band(void *user, int y0, const tn_image *band)
{
    tn_image *img = (tn_image *)user;
    memcpy(img->data + (size_t)y0 * img->width * img->channels, band->data,
           (size_t)band->width * band->height * band->channels * sizeof(float));
    return TN_OK;
}

TN_API tn_status tn_texgan_synthesize(tn_image *out, const tn_texgan *model, uint64_t seed, int width, int height)
{
    tn_image img = {0, 0, 0, NULL};
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__tg_check_model(model)) || (st = tn__tg_check_size(width, height))) return st;
    if ((st = tn_image_create(&img, width, height, model->channels))) return st;
    st = tn_texgan_synthesize_stream(model, seed, width, height, 0, tn__tg_collect_band, &img);
    if (st) tn_image_free(&img);
    else *out = img;
    return st;
}

/* ---- streaming files ---- */

/* Each channel group's file goes through its target's temporary as every other save does
   (tn__io_temp_open), so a killed synthesis leaves at most "PATH.tmp", which the next save of
   PATH replaces. */
typedef struct tn__tg_writer {
    tn__io_temp t[TN_TEXGAN_MAX_CHANNELS];
    int open[TN_TEXGAN_MAX_CHANNELS];
    char *final[TN_TEXGAN_MAX_CHANNELS];
    long hdr[TN_TEXGAN_MAX_CHANNELS];
    int groups, pfm, width, height, channels;
    const float *shift;
    float lo, hi;
    uint8_t *row;
} tn__tg_writer;

/* "<stem>.ch3-5<ext>" for channel group g > 0. */
static char *tn__tg_group_path(const char *path, int g, int channels)
{
    const char *dot = strrchr(path, '.'), *slash = strrchr(path, '/');
    size_t stem = dot && (!slash || dot > slash) ? (size_t)(dot - path) : strlen(path), cap = strlen(path) + 32;
    char *s = (char *)tn__alloc(cap);
    int last = 3 * g + 2 < channels - 1 ? 3 * g + 2 : channels - 1;
    if (!s) return NULL;
    if (g == 0) snprintf(s, cap, "%s", path);
    else snprintf(s, cap, "%.*s.ch%d-%d%s", (int)stem, path, 3 * g, last, path + stem);
    return s;
}

static int tn__tg_group_channels(int g, int channels) { return channels - 3 * g >= 3 ? 3 : channels - 3 * g; }

static tn_status tn__tg_writer_band(void *user, int y0, const tn_image *band)
{
    tn__tg_writer *w = (tn__tg_writer *)user;
    int g, y, x, k;
    for (g = 0; g < w->groups; g++) {
        int n = tn__tg_group_channels(g, w->channels), fc = n == 1 ? 1 : 3;
        size_t rowbytes = (size_t)w->width * fc * (w->pfm ? 4 : 1);
        for (y = 0; y < band->height; y++) {
            const float *src = band->data + (size_t)y * band->width * band->channels;
            long off = w->hdr[g] + (long)rowbytes * (w->pfm ? (long)(w->height - 1 - (y0 + y)) : (long)(y0 + y));
            for (x = 0; x < w->width; x++)
                for (k = 0; k < fc; k++) {
                    int c = 3 * g + k;
                    float v = k < n ? src[(size_t)x * band->channels + c] + (w->shift ? w->shift[c] : 0.0f) : w->lo;
                    v = tn__clampf(v, w->lo, w->hi);
                    if (w->pfm) tn__io_put_f32le(w->row + 4 * ((size_t)x * fc + k), v);
                    else w->row[(size_t)x * fc + k] = (uint8_t)tn__io_code(v, w->lo, 255.0 / ((double)w->hi - w->lo), 255u);
                }
            if (fseek(w->t[g].f, off, SEEK_SET) != 0 || fwrite(w->row, 1, rowbytes, w->t[g].f) != rowbytes)
                return tn__fail(TN_ERR_IO, "%s: write failed (disk full?)", w->final[g]);
        }
    }
    return TN_OK;
}

static void tn__tg_writer_close(tn__tg_writer *w, tn_status *st)
{
    int g, r;
    for (g = 0; g < w->groups; g++) {
        if (w->open[g] && *st) tn__io_temp_discard(&w->t[g]);
        else if (w->open[g] && (r = tn__io_temp_finish(&w->t[g], 1)) != 1) /* -1: rare, a race of two saves */
            *st = r ? tn__fail(TN_ERR_IO, "%s: another save of it took its temporary file; run again", w->final[g]) : TN_ERR_IO;
        TN_FREE(w->final[g]);
    }
    TN_FREE(w->row);
}

/* Whole image in memory, then saved per channel group (formats that cannot stream). */
static tn_status tn__tg_save_whole(const tn_texgan *m, uint64_t seed, int width, int height, const float *shift, const char *path)
{
    tn_image img = {0, 0, 0, NULL}, part = {0, 0, 0, NULL};
    tn_save_opts so;
    tn_status st = tn_texgan_synthesize(&img, m, seed, width, height);
    size_t i, n = (size_t)width * height;
    int g, c, groups = (m->channels + 2) / 3;
    memset(&so, 0, sizeof so);
    so.bit_depth = 8;
    so.has_range = 1;
    so.range_lo = m->lo;
    so.range_hi = m->hi;
    if (!st && m->lo == 0.0f && m->hi == 1.0f) so.has_range = 0;
    for (i = 0; !st && i < n * (size_t)m->channels; i++)
        img.data[i] = tn__clampf(img.data[i] + (shift ? shift[i % (size_t)m->channels] : 0.0f), m->lo, m->hi);
    for (g = 0; !st && g < groups; g++) {
        int k = tn__tg_group_channels(g, m->channels);
        char *p = tn__tg_group_path(path, g, m->channels);
        if (!p) { st = TN_ERR_OUT_OF_MEMORY; break; }
        st = tn_image_create(&part, width, height, k);
        for (i = 0; !st && i < n; i++)
            for (c = 0; c < k; c++) part.data[i * k + c] = img.data[i * m->channels + 3 * g + c];
        if (!st) st = tn_image_save(p, &part, &so);
        tn_image_free(&part);
        TN_FREE(p);
    }
    tn_image_free(&img);
    return st;
}

TN_API tn_status tn_texgan_synthesize_file(const char *path, const tn_texgan *model, uint64_t seed, int width, int height,
                                           const float *shift)
{
    tn__tg_writer w;
    const char *ext;
    tn_status st;
    int g;
    if ((st = tn__tg_check_model(model)) || (st = tn__tg_check_size(width, height))) return st;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "texgan: empty output path");
    ext = strrchr(path, '.');
    memset(&w, 0, sizeof w);
    if (ext && (!strcmp(ext, ".pfm") || !strcmp(ext, ".PFM"))) w.pfm = 1;
    else if (!(ext && (!strcmp(ext, ".ppm") || !strcmp(ext, ".pgm") || !strcmp(ext, ".pnm"))))
        return tn__tg_save_whole(model, seed, width, height, shift, path);
    w.groups = (model->channels + 2) / 3;
    w.width = width;
    w.height = height;
    w.channels = model->channels;
    w.shift = shift;
    w.lo = model->lo;
    w.hi = model->hi;
    if (!(w.row = (uint8_t *)tn__alloc((size_t)width * 3 * 4))) return TN_ERR_OUT_OF_MEMORY;
    for (g = 0; !st && g < w.groups; g++) {
        int fc = tn__tg_group_channels(g, model->channels) == 1 ? 1 : 3;
        FILE *f;
        if (!(w.final[g] = tn__tg_group_path(path, g, model->channels))) { st = TN_ERR_OUT_OF_MEMORY; break; }
        if ((st = tn__io_temp_open(&w.t[g], w.final[g], 0))) break;
        w.open[g] = 1;
        f = w.t[g].f;
        if (w.pfm) w.hdr[g] = fprintf(f, "P%c\n%d %d\n-1.0\n", fc == 3 ? 'F' : 'f', width, height);
        else w.hdr[g] = fprintf(f, "P%d\n%d %d\n255\n", fc == 3 ? 6 : 5, width, height);
        if (w.hdr[g] <= 0) st = tn__fail(TN_ERR_IO, "%s: write failed", w.final[g]);
    }
    if (!st) st = tn_texgan_synthesize_stream(model, seed, width, height, 0, tn__tg_writer_band, &w);
    tn__tg_writer_close(&w, &st);
    return st;
}

/* ---- colour correction ---- */

static double tn__cc_mean(const tn_image *img, int c, float s, float lo, float hi, int *clipped)
{
    size_t n = (size_t)img->width * img->height, i;
    double sum = 0;
    int cl = 0;
    for (i = 0; i < n; i++) {
        float v = img->data[i * img->channels + c] + s;
        if (v < lo || v > hi) cl = 1;
        sum += tn__clampf(v, lo, hi);
    }
    if (clipped) *clipped = cl;
    return sum / (double)n;
}

TN_API tn_status tn_texture_colour_shift(float *shift, const tn_image *img, const float *target, float lo, float hi)
{
    int c, it;
    if (!img || !img->data || img->width <= 0 || img->height <= 0 || img->channels <= 0) return tn__fail(TN_ERR_EMPTY, "colour correction: empty image");
    if (!(lo < hi) || !(lo >= -FLT_MAX && hi <= FLT_MAX))
        return tn__fail(TN_ERR_INVALID_ARG, "colour correction: range %g..%g is empty or not finite", (double)lo, (double)hi);
    if (tn_image_range(NULL, NULL, img)) return tn__fail(TN_ERR_NUMERIC, "colour correction: the image holds NaN/Inf");
    for (c = 0; c < img->channels; c++) {
        float t = target[c], a, b, s;
        int clipped;
        if (t != t) return tn__fail(TN_ERR_NUMERIC, "colour correction: target mean is NaN");
        t = tn__clampf(t, lo, hi);
        s = (float)(t - tn__cc_mean(img, c, 0.0f, -FLT_MAX, FLT_MAX, NULL)); /* unclipped mean */
        tn__cc_mean(img, c, s, lo, hi, &clipped);
        if (clipped) { /* the clipped mean is monotone in the shift: bisect */
            a = lo - hi;
            b = hi - lo;
            for (it = 0; it < 48; it++) {
                float mid = 0.5f * (a + b);
                if (tn__cc_mean(img, c, mid, lo, hi, NULL) < t) a = mid;
                else b = mid;
            }
            s = 0.5f * (a + b);
        }
        shift[c] = s;
    }
    return TN_OK;
}

TN_API tn_status tn_texture_colour_correct(tn_image *img, const float *target, float lo, float hi)
{
    float shift[64];
    size_t n, i;
    tn_status st;
    if (img && img->channels > 64) return tn__fail(TN_ERR_SHAPE, "colour correction: %d channels (at most 64)", img->channels);
    if ((st = tn_texture_colour_shift(shift, img, target, lo, hi))) return st;
    n = (size_t)img->width * img->height * img->channels;
    for (i = 0; i < n; i++) img->data[i] = tn__clampf(img->data[i] + shift[i % (size_t)img->channels], lo, hi);
    return TN_OK;
}

/* ---- detail maps ---- */

typedef struct tn__dm_acc {
    double *sum;
    int wl, hl, f, width, height, channels;
} tn__dm_acc;

static tn_status tn__dm_acc_band(void *user, int y0, const tn_image *band)
{
    tn__dm_acc *a = (tn__dm_acc *)user;
    int x, y, c;
    for (y = 0; y < band->height; y++) {
        double *row = a->sum + (size_t)((y0 + y) / a->f) * a->wl * a->channels;
        const float *src = band->data + (size_t)y * band->width * band->channels;
        for (x = 0; x < band->width; x++)
            for (c = 0; c < a->channels; c++) row[(size_t)(x / a->f) * a->channels + c] += src[(size_t)x * a->channels + c];
    }
    return TN_OK;
}

static void tn__dm_defaults(const tn_detail_opts *in, tn_detail_opts *o)
{
    memset(o, 0, sizeof *o);
    if (in) *o = *in;
    if (o->factor == 0) o->factor = 10; /* negative and NaN values stay, for tn__dm_begin to refuse */
    if (o->sigma == 0 && o->factor > 0) o->sigma = 0.5f * (float)o->factor;
    if (o->lo == 0 && o->hi == 0) o->hi = 1.0f;
}

static tn_status tn__dm_begin(tn__dm_acc *a, const tn_detail_opts *o, int width, int height, int channels, const tn_image *ex)
{
    size_t n;
    tn_status st;
    memset(a, 0, sizeof *a);
    if (!ex || !ex->data || ex->width <= 0 || ex->height <= 0) return tn__fail(TN_ERR_EMPTY, "detail maps: the exemplar is empty");
    if (ex->channels != channels) return tn__fail(TN_ERR_SHAPE, "detail maps: the exemplar has %d channels, the synthesis %d", ex->channels, channels);
    if (tn_image_range(NULL, NULL, ex)) return tn__fail(TN_ERR_NUMERIC, "detail maps: the exemplar holds NaN/Inf");
    if (o->factor < 1 || o->factor > 4096 || !(o->sigma > 0 && o->sigma < 1e4f) || !(o->lo < o->hi) || !(o->lo >= -FLT_MAX && o->hi <= FLT_MAX))
        return tn__fail(TN_ERR_INVALID_ARG, "detail maps: factor %d must be 1..4096, sigma %g in (0, 1e4), range %g..%g finite and not empty",
                        o->factor, (double)o->sigma, (double)o->lo, (double)o->hi);
    if (width <= 0 || height <= 0) return tn__fail(TN_ERR_EMPTY, "detail maps: the synthesis is empty");
    a->f = o->factor;
    a->width = width;
    a->height = height;
    a->channels = channels;
    a->wl = (width + a->f - 1) / a->f;
    a->hl = (height + a->f - 1) / a->f;
    if ((st = tn__size4((size_t)a->wl, (size_t)a->hl, (size_t)channels, sizeof(double), &n))) return st;
    a->sum = (double *)tn__calloc(n);
    return a->sum ? TN_OK : TN_ERR_OUT_OF_MEMORY;
}

/* Makes high frequencies h periodic along x (axis 0) or y (axis 1), written to out: out = sin(t) h
   + |cos(t)| h shifted by half the side, t = pi (i + 0.5) / side. At the borders the shifted copy
   (continuous across the wrap) takes over, at the centre h (where the copy's own seam lies);
   sin^2 + cos^2 = 1 keeps the energy of uncorrelated detail. Exemplars are rarely seamless, and
   the high map is tiled, so without this its edge shows as a line every exemplar width. */
TN__INTERNAL void tn__dm_seamless(const tn_image *h, float *out, int axis)
{
    int w = h->width, ht = h->height, ch = h->channels, side = axis ? ht : w, x, y, c;
    double wrap = 0, inner = 0;
    /* an exemplar that already tiles along this axis (steps across the wrap no larger than
       twice the mean step between neighbours) keeps its detail untouched */
    for (y = 0; y < ht; y++)
        for (x = 0; x < w; x++)
            for (c = 0; c < ch; c++) {
                int nx = axis ? x : (x + 1) % w, ny = axis ? (y + 1) % ht : y, last = axis ? y == ht - 1 : x == w - 1;
                double d = h->data[((size_t)ny * w + nx) * ch + c] - h->data[((size_t)y * w + x) * ch + c];
                if (last) wrap += d * d;
                else inner += d * d;
            }
    if (side < 2 || wrap / (double)(axis ? w : ht) <= 2.0 * inner / ((double)(side - 1) * (axis ? w : ht))) {
        memcpy(out, h->data, (size_t)w * ht * ch * sizeof(float));
        return;
    }
    for (y = 0; y < ht; y++)
        for (x = 0; x < w; x++) {
            int i = axis ? y : x;
            double t = 3.14159265358979 * (i + 0.5) / side;
            int sx = axis ? x : (x + w / 2) % w, sy = axis ? (y + ht / 2) % ht : y;
            const float *a = h->data + ((size_t)y * w + x) * ch, *b = h->data + ((size_t)sy * w + sx) * ch;
            float *o = out + ((size_t)y * w + x) * ch;
            for (c = 0; c < ch; c++) o[c] = (float)(sin(t) * a[c] + fabs(cos(t)) * b[c]);
        }
}

/* Low map from the block sums (area average, then the remaining Gaussian, colour correction),
   high map from the exemplar. */
static tn_status tn__dm_finish(tn__dm_acc *a, const tn_detail_opts *o, const tn_image *ex, tn_detail_maps *maps)
{
    tn_detail_maps m;
    tn_image blur = {0, 0, 0, NULL};
    int x, y, c;
    size_t i, n;
    float rest = o->sigma * o->sigma - (float)(a->f * a->f) / 12.0f, mean[64];
    tn_status st;
    memset(&m, 0, sizeof m);
    if (a->channels > 64) return tn__fail(TN_ERR_SHAPE, "detail maps: at most 64 channels");
    st = tn_image_create(&m.low, a->wl, a->hl, a->channels);
    for (y = 0; !st && y < a->hl; y++)
        for (x = 0; x < a->wl; x++) {
            int bw = (x + 1) * a->f <= a->width ? a->f : a->width - x * a->f, bh = (y + 1) * a->f <= a->height ? a->f : a->height - y * a->f;
            for (c = 0; c < a->channels; c++) {
                size_t k = ((size_t)y * a->wl + x) * a->channels + c;
                m.low.data[k] = (float)(a->sum[k] / ((double)bw * bh));
            }
        }
    if (!st && rest > 0 && sqrtf(rest) / (float)a->f > 0.05f) st = tn_image_blur(&m.low, &m.low, sqrtf(rest) / (float)a->f);
    if (!st && !o->no_colour_correct) {
        n = (size_t)ex->width * ex->height;
        for (c = 0; c < a->channels; c++) {
            double s = 0;
            for (i = 0; i < n; i++) s += ex->data[i * a->channels + c];
            mean[c] = (float)(s / (double)n);
        }
        st = tn_texture_colour_correct(&m.low, mean, o->lo, o->hi);
    }
    if (!st) st = tn_image_blur(&blur, ex, o->sigma);
    if (!st) st = tn_image_create(&m.high, ex->width, ex->height, ex->channels);
    if (!st) {
        n = (size_t)ex->width * ex->height * ex->channels;
        for (i = 0; i < n; i++) blur.data[i] = ex->data[i] - blur.data[i];
        tn__dm_seamless(&blur, m.high.data, 0);
        tn__dm_seamless(&m.high, blur.data, 1);
        for (i = 0; i < n; i++) m.high.data[i] = 0.5f * blur.data[i] + 0.5f;
    }
    tn_image_free(&blur);
    if (st) {
        tn_detail_maps_free(&m);
        return st;
    }
    m.width = a->width;
    m.height = a->height;
    m.tiling_x = (float)a->width / (float)ex->width;
    m.tiling_y = (float)a->height / (float)ex->height;
    m.factor = a->f;
    m.sigma = o->sigma;
    m.lo = o->lo;
    m.hi = o->hi;
    *maps = m;
    return TN_OK;
}

TN_API tn_status tn_detail_maps_from_image(tn_detail_maps *maps, const tn_image *synth, const tn_image *ex, const tn_detail_opts *opts)
{
    tn_detail_opts o;
    tn__dm_acc a;
    tn_status st;
    TN_ASSERT(maps);
    tn__dm_defaults(opts, &o);
    if (!synth || !synth->data) return tn__fail(TN_ERR_EMPTY, "detail maps: the synthesis is empty");
    if (tn_image_range(NULL, NULL, synth)) return tn__fail(TN_ERR_NUMERIC, "detail maps: the synthesis holds NaN/Inf");
    if ((st = tn__dm_begin(&a, &o, synth->width, synth->height, synth->channels, ex))) return st;
    st = tn__dm_acc_band(&a, 0, synth);
    if (!st) st = tn__dm_finish(&a, &o, ex, maps);
    TN_FREE(a.sum);
    return st;
}

TN_API tn_status tn_detail_maps_from_model(tn_detail_maps *maps, const tn_texgan *model, uint64_t seed, int width, int height,
                                           const tn_image *ex, const tn_detail_opts *opts)
{
    tn_detail_opts o;
    tn__dm_acc a;
    tn_status st;
    TN_ASSERT(maps);
    tn__dm_defaults(opts, &o);
    if ((st = tn__tg_check_model(model)) || (st = tn__tg_check_size(width, height))) return st;
    if (!opts || (opts->lo == 0 && opts->hi == 0)) {
        o.lo = model->lo;
        o.hi = model->hi;
    }
    if ((st = tn__dm_begin(&a, &o, width, height, model->channels, ex))) return st;
    st = tn_texgan_synthesize_stream(model, seed, width, height, 0, tn__dm_acc_band, &a);
    if (!st) st = tn__dm_finish(&a, &o, ex, maps);
    TN_FREE(a.sum);
    return st;
}

TN_API void tn_detail_maps_free(tn_detail_maps *maps)
{
    if (!maps) return;
    tn_image_free(&maps->low);
    tn_image_free(&maps->high);
    memset(maps, 0, sizeof *maps);
}

/* Bilinear tap along one axis, as GPU samplers do: texel centres at i + 0.5; clamp or repeat. */
static void tn__dm_axis(float t, int n, int wrap, int *i0, int *i1, float *w1)
{
    float x = t - 0.5f, fl = floorf(x);
    int a = (int)fl;
    *w1 = x - fl;
    if (wrap) {
        a %= n;
        if (a < 0) a += n;
        *i0 = a;
        *i1 = a + 1 == n ? 0 : a + 1;
    } else {
        *i0 = tn__clampi(a, 0, n - 1);
        *i1 = tn__clampi(a + 1, 0, n - 1);
    }
}

static float tn__dm_bilerp(const tn_image *im, int x0, int x1, float fx, int y0, int y1, float fy, int c)
{
    float a = TN_PIXEL(im, x0, y0, c), b = TN_PIXEL(im, x1, y0, c), d = TN_PIXEL(im, x0, y1, c), e = TN_PIXEL(im, x1, y1, c);
    float top = a + (b - a) * fx, bot = d + (e - d) * fx;
    return top + (bot - top) * fy;
}

/* Texture-space coordinate u in [0, 1) -> low-map and high-map sample positions (in texels). */
static float tn__dm_low_t(const tn_detail_maps *m, float u, int axis)
{
    return u * (axis ? (float)m->height : (float)m->width) / (float)m->factor;
}
static float tn__dm_high_t(const tn_detail_maps *m, float u, int axis)
{
    return u * (axis ? m->tiling_y * (float)m->high.height : m->tiling_x * (float)m->high.width);
}

TN_API void tn_detail_texel(float *out, const tn_detail_maps *m, float u, float v)
{
    int lx0, lx1, ly0, ly1, hx0, hx1, hy0, hy1, c;
    float lfx, lfy, hfx, hfy;
    tn__dm_axis(tn__dm_low_t(m, u, 0), m->low.width, 0, &lx0, &lx1, &lfx);
    tn__dm_axis(tn__dm_low_t(m, v, 1), m->low.height, 0, &ly0, &ly1, &lfy);
    tn__dm_axis(tn__dm_high_t(m, u, 0), m->high.width, 1, &hx0, &hx1, &hfx);
    tn__dm_axis(tn__dm_high_t(m, v, 1), m->high.height, 1, &hy0, &hy1, &hfy);
    for (c = 0; c < m->low.channels; c++) {
        float lo = tn__dm_bilerp(&m->low, lx0, lx1, lfx, ly0, ly1, lfy, c);
        float hi = tn__dm_bilerp(&m->high, hx0, hx1, hfx, hy0, hy1, hfy, c);
        out[c] = tn__clampf(lo + 2.0f * (hi - 0.5f), m->lo, m->hi);
    }
}

/* The whole-image composer: taps per column and per row computed once, then every row blends
   its two low rows and two high rows (the same arithmetic as tn_detail_texel). */
typedef struct tn__dm_job {
    const tn_detail_maps *m;
    tn_image *out;
    int *tx;     /* per column: lx0, lx1, hx0, hx1 */
    float *fx;   /* per column: lfx, hfx */
} tn__dm_job;

static void tn__dm_rows(void *arg, size_t y0, size_t y1)
{
    tn__dm_job *j = (tn__dm_job *)arg;
    const tn_detail_maps *m = j->m;
    size_t y;
    int x, c, C = m->low.channels;
    for (y = y0; y < y1; y++) {
        int ly0, ly1, hy0, hy1;
        float lfy, hfy, v = ((float)y + 0.5f) / (float)j->out->height;
        float *dst = j->out->data + y * (size_t)j->out->width * C;
        tn__dm_axis(tn__dm_low_t(m, v, 1), m->low.height, 0, &ly0, &ly1, &lfy);
        tn__dm_axis(tn__dm_high_t(m, v, 1), m->high.height, 1, &hy0, &hy1, &hfy);
        for (x = 0; x < j->out->width; x++) {
            const int *t = j->tx + 4 * (size_t)x;
            const float *f = j->fx + 2 * (size_t)x;
            for (c = 0; c < C; c++) {
                float lo = tn__dm_bilerp(&m->low, t[0], t[1], f[0], ly0, ly1, lfy, c);
                float hi = tn__dm_bilerp(&m->high, t[2], t[3], f[1], hy0, hy1, hfy, c);
                dst[(size_t)x * C + c] = tn__clampf(lo + 2.0f * (hi - 0.5f), m->lo, m->hi);
            }
        }
    }
}

static tn_status tn__dm_check(const tn_detail_maps *m)
{
    if (!m || !m->low.data || !m->high.data || m->factor <= 0 || m->width <= 0 || m->height <= 0 || !(m->tiling_x > 0) || !(m->tiling_y > 0))
        return tn__fail(TN_ERR_EMPTY, "detail maps: empty or incomplete maps");
    if (m->low.channels != m->high.channels) return tn__fail(TN_ERR_SHAPE, "detail maps: low and high maps differ in channels");
    return TN_OK;
}

TN_API tn_status tn_detail_compose(tn_image *out, const tn_detail_maps *m, int width, int height)
{
    tn_image img = {0, 0, 0, NULL};
    tn__dm_job j;
    tn_status st;
    int x;
    TN_ASSERT(out);
    if ((st = tn__dm_check(m))) return st;
    if (width == 0 && height == 0) {
        width = m->width;
        height = m->height;
    }
    if ((st = tn_image_create(&img, width, height, m->low.channels))) return st;
    j.m = m;
    j.out = &img;
    j.tx = (int *)tn__alloc((size_t)width * 4 * sizeof(int));
    j.fx = (float *)tn__alloc((size_t)width * 2 * sizeof(float));
    if (!j.tx || !j.fx) {
        TN_FREE(j.tx);
        TN_FREE(j.fx);
        tn_image_free(&img);
        return TN_ERR_OUT_OF_MEMORY;
    }
    for (x = 0; x < width; x++) {
        float u = ((float)x + 0.5f) / (float)width;
        tn__dm_axis(tn__dm_low_t(m, u, 0), m->low.width, 0, &j.tx[4 * x], &j.tx[4 * x + 1], &j.fx[2 * x]);
        tn__dm_axis(tn__dm_high_t(m, u, 0), m->high.width, 1, &j.tx[4 * x + 2], &j.tx[4 * x + 3], &j.fx[2 * x + 1]);
    }
    tn_parallel_for((size_t)height, 16, tn__dm_rows, &j);
    TN_FREE(j.tx);
    TN_FREE(j.fx);
    *out = img;
    return TN_OK;
}

/* ---- detail map files ---- */

static char *tn__dm_path(const char *prefix, const char *suffix)
{
    size_t cap = strlen(prefix) + strlen(suffix) + 1;
    char *s = (char *)tn__alloc(cap);
    if (s) snprintf(s, cap, "%s%s", prefix, suffix);
    return s;
}

/* Saves an image of any channel count as PNGs of up to 3 channels (see tn__tg_group_path). */
static tn_status tn__dm_save_groups(const tn_image *img, const char *path, int bits, float lo, float hi)
{
    tn_image part = {0, 0, 0, NULL};
    tn_save_opts so;
    size_t i, n = (size_t)img->width * img->height;
    int g, c, groups = img->channels <= 4 ? 1 : (img->channels + 2) / 3;
    tn_status st = TN_OK;
    memset(&so, 0, sizeof so);
    so.bit_depth = bits;
    if (lo != 0.0f || hi != 1.0f) {
        so.has_range = 1;
        so.range_lo = lo;
        so.range_hi = hi;
    }
    if (groups == 1) return tn_image_save(path, img, &so);
    for (g = 0; !st && g < groups; g++) {
        int k = tn__tg_group_channels(g, img->channels);
        char *p = tn__tg_group_path(path, g, img->channels);
        if (!p) return TN_ERR_OUT_OF_MEMORY;
        st = tn_image_create(&part, img->width, img->height, k);
        for (i = 0; !st && i < n; i++)
            for (c = 0; c < k; c++) part.data[i * k + c] = img->data[i * img->channels + 3 * g + c];
        if (!st) st = tn_image_save(p, &part, &so);
        tn_image_free(&part);
        TN_FREE(p);
    }
    return st;
}

static tn_status tn__dm_load_groups(tn_image *img, const char *path, int channels)
{
    tn_image part = {0, 0, 0, NULL}, all = {0, 0, 0, NULL};
    int g, c, groups = channels <= 4 ? 1 : (channels + 2) / 3;
    size_t i, n = 0;
    tn_status st = TN_OK;
    if (groups == 1) {
        if ((st = tn_image_load(img, path, NULL))) return st;
        if (img->channels != channels) {
            tn_image_free(img);
            return tn__fail(TN_ERR_SHAPE, "%s: %d channels, the sidecar says %d", path, img->channels, channels);
        }
        return TN_OK;
    }
    for (g = 0; !st && g < groups; g++) {
        int k = tn__tg_group_channels(g, channels);
        char *p = tn__tg_group_path(path, g, channels);
        if (!p) { st = TN_ERR_OUT_OF_MEMORY; break; }
        st = tn_image_load(&part, p, NULL);
        if (!st && g == 0) st = tn_image_create(&all, part.width, part.height, channels);
        if (!st && (part.width != all.width || part.height != all.height || part.channels != k))
            st = tn__fail(TN_ERR_SHAPE, "%s: size or channels differ from the first group", p);
        n = (size_t)all.width * all.height;
        for (i = 0; !st && i < n; i++)
            for (c = 0; c < k; c++) all.data[i * channels + 3 * g + c] = part.data[i * k + c];
        tn_image_free(&part);
        TN_FREE(p);
    }
    if (st) tn_image_free(&all);
    else *img = all;
    return st;
}

TN_API tn_status tn_detail_maps_save(const char *prefix, const tn_detail_maps *m)
{
    char *lp, *hp, *tp, txt[512];
    int len;
    tn_status st;
    if ((st = tn__dm_check(m))) return st;
    if (!prefix || !prefix[0]) return tn__fail(TN_ERR_INVALID_ARG, "detail maps: empty prefix");
    lp = tn__dm_path(prefix, "_low.png");
    hp = tn__dm_path(prefix, "_high.png");
    tp = tn__dm_path(prefix, "_detail.txt");
    if (!lp || !hp || !tp) st = TN_ERR_OUT_OF_MEMORY;
    if (!st) st = tn__dm_save_groups(&m->low, lp, 16, m->lo, m->hi);
    if (!st) st = tn__dm_save_groups(&m->high, hp, 8, 0.5f - 0.5f * (m->hi - m->lo), 0.5f + 0.5f * (m->hi - m->lo));
    if (!st) {
        char v[5][40]; /* floats as shortest round-trip text with '.', whatever the C locale */
        const float f[5] = {m->tiling_x, m->tiling_y, m->sigma, m->lo, m->hi};
        for (len = 0; len < 5; len++) tn__io_format_number(v[len], sizeof v[len], (double)f[len], 1);
        len = snprintf(txt, sizeof txt, "terrainnet detail maps 1\nsize %d %d\nchannels %d\ntiling %s %s\nfactor %d\nsigma %s\nrange %s %s\n",
                       m->width, m->height, m->low.channels, v[0], v[1], m->factor, v[2], v[3], v[4]);
        st = tn__io_write_atomic(tp, (const uint8_t *)txt, (size_t)len);
    }
    TN_FREE(lp);
    TN_FREE(hp);
    TN_FREE(tp);
    return st;
}

TN_API tn_status tn_detail_maps_load(tn_detail_maps *maps, const char *prefix)
{
    tn_detail_maps m;
    uint8_t *buf = NULL;
    size_t n = 0;
    char *lp, *hp, *tp;
    int ch = 0;
    tn_status st = TN_OK;
    TN_ASSERT(maps);
    if (!prefix || !prefix[0]) return tn__fail(TN_ERR_INVALID_ARG, "detail maps: empty prefix");
    memset(&m, 0, sizeof m);
    lp = tn__dm_path(prefix, "_low.png");
    hp = tn__dm_path(prefix, "_high.png");
    tp = tn__dm_path(prefix, "_detail.txt");
    if (!lp || !hp || !tp) st = TN_ERR_OUT_OF_MEMORY;
    if (!st) st = tn__io_read_file(tp, &buf, &n);
    if (!st) {
        /* locale-free tokens (sscanf's %lf follows LC_NUMERIC, and its %d overflows undefined);
           every number is range-checked before it is converted */
        static const char *const words[] = {"terrainnet", "detail", "maps", "1", "size", "", "", "channels", "",
                                            "tiling", "", "", "factor", "", "sigma", "", "range", "", ""};
        double v[19];
        size_t i = 0, tb = 0, tl = 0;
        int k, ok = 1;
        for (k = 0; ok && k < 19; k++) {
            ok = tn__io_token(buf, n, &i, &tb, &tl);
            if (ok && words[k][0]) ok = tn__io_token_is((const char *)buf + tb, tl, words[k]);
            else if (ok) ok = tn__io_number((const char *)buf + tb, tl, &v[k]);
        }
        if (!ok || !(v[5] >= 1 && v[5] <= INT_MAX && v[5] == floor(v[5])) || !(v[6] >= 1 && v[6] <= INT_MAX && v[6] == floor(v[6])) ||
            !(v[8] >= 1 && v[8] <= 64 && v[8] == floor(v[8])) || !(v[10] > 0 && v[10] < 1e7) || !(v[11] > 0 && v[11] < 1e7) ||
            !(v[13] >= 1 && v[13] <= INT_MAX && v[13] == floor(v[13])) || !(v[15] >= 0 && v[15] <= FLT_MAX) ||
            !(fabs(v[17]) <= FLT_MAX && fabs(v[18]) <= FLT_MAX && v[17] < v[18]))
            st = tn__fail(TN_ERR_CORRUPT, "%s: not a valid detail-map sidecar", tp);
        else {
            m.width = (int)v[5];
            m.height = (int)v[6];
            ch = (int)v[8];
            m.tiling_x = (float)v[10];
            m.tiling_y = (float)v[11];
            m.factor = (int)v[13];
            m.sigma = (float)v[15];
            m.lo = (float)v[17];
            m.hi = (float)v[18];
        }
    }
    if (!st) st = tn__dm_load_groups(&m.low, lp, ch);
    if (!st) st = tn__dm_load_groups(&m.high, hp, ch);
    TN_FREE(buf);
    TN_FREE(lp);
    TN_FREE(hp);
    TN_FREE(tp);
    if (st) {
        tn_detail_maps_free(&m);
        return st;
    }
    *maps = m;
    return TN_OK;
}

/* ---- preview: naive tiling vs detail mapping, far and near, over a hillshaded terrain ---- */

static void tn__dm_put(tn_image *out, int ox, int oy, int x, int y, const float *rgb, int channels, float shade)
{
    int c;
    for (c = 0; c < 3; c++) TN_PIXEL(out, ox + x, oy + y, c) = tn__clampf(rgb[channels >= 3 ? c : 0], 0.0f, 1.0f) * shade;
}

TN_API tn_status tn_detail_preview(tn_image *out, const tn_detail_maps *m, const tn_image *ex, const tn_image *dem, int panel)
{
    tn_image shade = {0, 0, 0, NULL}, terrain = {0, 0, 0, NULL}, exs = {0, 0, 0, NULL}, his = {0, 0, 0, NULL}, img = {0, 0, 0, NULL};
    int P = panel > 0 ? panel : 384, gap = 8, C, x, y, c, sw, sh, nx0, ny0;
    float px[TN_TEXGAN_MAX_CHANNELS * 8], q[TN_TEXGAN_MAX_CHANNELS * 8];
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__dm_check(m))) return st;
    if (!ex || !ex->data || ex->channels != m->low.channels) return tn__fail(TN_ERR_SHAPE, "preview: the exemplar does not match the maps");
    if (P < 16 || P > 4096) return tn__fail(TN_ERR_INVALID_ARG, "preview: panel size %d (16..4096)", P);
    C = m->low.channels;
    if (C > TN_TEXGAN_MAX_CHANNELS * 8) return tn__fail(TN_ERR_SHAPE, "preview: too many channels");
    if (dem) st = tn_image_hillshade(&shade, dem, NULL);
    else {
        tn_perlin_opts po;
        memset(&po, 0, sizeof po);
        po.seed = 7;
        po.octaves = 6;
        st = tn_noise_perlin(&terrain, 256, 256, &po);
        if (!st) st = tn_image_hillshade(&shade, &terrain, NULL);
    }
    /* far view: what mip-mapping leaves, i.e. both maps box-filtered to the panel's texel size */
    sw = (int)((float)ex->width * (float)P / (float)m->width + 0.5f);
    sh = (int)((float)ex->height * (float)P / (float)m->height + 0.5f);
    if (sw < 1) sw = 1;
    if (sh < 1) sh = 1;
    if (!st) st = tn_image_resize(&exs, ex, sw, sh, TN_RESIZE_AREA);
    if (!st) st = tn_image_resize(&his, &m->high, sw, sh, TN_RESIZE_AREA);
    if (!st) st = tn_image_create(&img, 2 * P + gap, 2 * P + gap, 3);
    if (st) goto done;
    for (x = 0; x < img.width * img.height * 3; x++) img.data[x] = 1.0f;
    nx0 = m->width / 2 - P / 2;
    ny0 = m->height / 2 - P / 2;
    if (nx0 < 0) nx0 = 0;
    if (ny0 < 0) ny0 = 0;
    for (y = 0; y < P; y++)
        for (x = 0; x < P; x++) {
            float u = ((float)x + 0.5f) / (float)P, v = ((float)y + 0.5f) / (float)P, f, s;
            int a0, a1, b0, b1, l0, l1, k0, k1;
            float fa, fb, fl, fk;
            /* far */
            tn__dm_axis(u * (float)shade.width, shade.width, 0, &a0, &a1, &fa);
            tn__dm_axis(v * (float)shade.height, shade.height, 0, &b0, &b1, &fb);
            s = 0.3f + 0.7f * tn__dm_bilerp(&shade, a0, a1, fa, b0, b1, fb, 0);
            tn__dm_axis(u * m->tiling_x * (float)sw, sw, 1, &a0, &a1, &fa);
            tn__dm_axis(v * m->tiling_y * (float)sh, sh, 1, &b0, &b1, &fb);
            tn__dm_axis(tn__dm_low_t(m, u, 0), m->low.width, 0, &l0, &l1, &fl);
            tn__dm_axis(tn__dm_low_t(m, v, 1), m->low.height, 0, &k0, &k1, &fk);
            for (c = 0; c < C; c++) {
                px[c] = tn__dm_bilerp(&exs, a0, a1, fa, b0, b1, fb, c);
                f = tn__dm_bilerp(&his, a0, a1, fa, b0, b1, fb, c);
                q[c] = tn__dm_bilerp(&m->low, l0, l1, fl, k0, k1, fk, c) + 2.0f * (f - 0.5f);
            }
            tn__dm_put(&img, 0, 0, x, y, px, C, s);
            tn__dm_put(&img, P + gap, 0, x, y, q, C, s);
            /* near: full resolution crop at the centre */
            {
                int tx = (nx0 + x) % m->width, ty = (ny0 + y) % m->height;
                float tu = ((float)tx + 0.5f) / (float)m->width, tv = ((float)ty + 0.5f) / (float)m->height;
                tn__dm_axis(tu * (float)shade.width, shade.width, 0, &a0, &a1, &fa);
                tn__dm_axis(tv * (float)shade.height, shade.height, 0, &b0, &b1, &fb);
                s = 0.3f + 0.7f * tn__dm_bilerp(&shade, a0, a1, fa, b0, b1, fb, 0);
                for (c = 0; c < C; c++) px[c] = TN_PIXEL(ex, tx % ex->width, ty % ex->height, c);
                tn_detail_texel(q, m, tu, tv);
                tn__dm_put(&img, 0, P + gap, x, y, px, C, s);
                tn__dm_put(&img, P + gap, P + gap, x, y, q, C, s);
            }
        }
    *out = img;
    img.data = NULL;
done:
    tn_image_free(&img);
    tn_image_free(&shade);
    tn_image_free(&terrain);
    tn_image_free(&exs);
    tn_image_free(&his);
    return st;
}
#endif /* TN_NO_TEXGAN */

