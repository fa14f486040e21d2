/* ============================================================================================
   @@singan  multi-scale single-image GAN on heightmaps (paper 000's detail step, after Shaham et
   al. 2019, SinGAN)
   A pyramid of the example DEM from a coarsest side of about 25 px, each scale `factor` (0.75)
   times the next finer one; per scale a generator of 5 valid 3 x 3 convolutions (conv, batch
   norm, leaky ReLU 0.2; tanh last, times a gain of 5 x the example's detail RMS sigma at that
   scale, or 1.25 x its largest detail where that is more) that adds a residual to the upsampled
   coarser output, fed that output plus noise of amplitude noise_amp x sigma (1 at the coarsest
   scale, smoothed over 1.4 px). Scales train one
   after another, coarse to fine, each against its own spectral-normalised patch discriminator
   with the hinge loss (the engine has no double backward for SinGAN's WGAN-GP) plus 10 x the
   MSE of the reconstruction in units of sigma^2: the fixed noise map at the coarsest scale, and above it the example's
   coarser scale upsampled (teacher forcing) with no noise.
   The discriminator judges a scale's DETAIL (the generator's residual; for the example, the
   scale minus its coarser scale upsampled) in units of sigma, beside the gradient of the base it
   was added to (so detail must fit the slope it lies on: none on a lake). Issue 31 measured why
   (docs/singan.md): the generator's output in network units made every Adam step move the finest
   scales by more than their whole detail (0.005 of the range), the copied coarser tail added
   the coarser detail again, and the reconstruction taught the fine scales to correct the coarse
   scales' errors: ripples of 4-11x the example's detail RMS.
   Adam 5e-4 (0.5, 0.999), reset at every scale; a scale starts from the coarser one's weights
   when the widths match, with the tail at zero (the identity). Scales larger than 64 px train on
   random 64 px windows, each on a window of one of 4 fake bases of the whole scale made when the
   scale starts (the coarser generators are frozen by then). The time budget gives the scales
   equal iteration counts, estimated from each scale's measured speed.
   Everything is defined on the infinite integer grid of each scale: noise is a hash of the seed,
   the scale and the GLOBAL pixel position, upsampling is bilinear between global positions, the
   convolutions are valid and the norms use their running statistics when sampling. So any
   window (x0, y0, w, h) of a sample equals those pixels of any larger window, tiles need no
   seams, and large samples run tile by tile in bounded memory.
   Heights: the network works on [-1, 1] (the example's range); the model stores the mapping and
   every call takes and returns heights in the example's units (metres for metre DEMs).
   ============================================================================================ */
#ifndef TN_NO_SINGAN
#if defined(TN_NO_ENGINE)
#error "terrainnet: @@singan needs the tensor engine; define TN_NO_SINGAN too, or none of them"
#endif

#define TN_SINGAN_MAX_SCALES 16

/* Zero = default (tn_singan_defaults gives the values and the reasons). */
typedef struct tn_singan_opts {
    int coarsest;          /* side (the smaller one) of the coarsest scale in px; 0 = 25 */
    float factor;          /* size ratio of a scale to the next finer one, 0.5..0.9; 0 = 0.75 */
    int channels;          /* generator and discriminator width at the coarsest scale; 0 = 32 */
    int max_channels;      /* the width doubles every 4 scales up to this; 0 = 32 (2 cores) */
    int iters;             /* iterations per scale at most; 0 = 2000, or train.max_iters / scales.
                              The time budget gives every scale the same count (measured: the
                              count the remaining budget allows at each scale's speed) */
    int disc_layers;       /* stride-2 layers of the patch discriminator; 0 = 2 (15 px patches) */
    int patch;             /* scales larger than this train on random patch x patch windows (the
                              networks are fully convolutional); 0 = 64, < 0 = whole scales */
    float lr;              /* Adam rate of G and D; 0 = 5e-4 */
    float rec_weight;      /* weight of the reconstruction MSE; 0 = 10 */
    float noise_amp;       /* noise amplitude / the example's detail RMS at the scale; 0 = 0.5 (0.1:
                              too smooth, 3.6x the curvature distance on Mont Blanc; docs/singan.md) */
    float adv_weight;      /* weight of the adversarial loss (both losses in units of the scale's
                              detail RMS); 0 = 1, < 0 = none (reconstruction only; docs/singan.md) */
    int d_steps;           /* discriminator steps per iteration (SinGAN: 3); 0 = 1 */
    float curv_weight;     /* weight of the curvature loss: the 1-D Wasserstein distance between the
                              Laplacians of a scale's output and of the example's scale, in units of
                              the example's mean square Laplacian; 0 = 10, < 0 = none (without it the
                              finest scales add crumpled detail, no smooth floors or sharp crests) */
    float spec_weight;     /* weight of the spectrum loss at the coarsest scale: the squared log ratio
                              of its power spectrum to the example's where it exceeds it, at periods
                              of 8 px and more (the Sahara's undulation at half the map's period;
                              docs/singan.md); 0 = 1, < 0 = none */
    float height_weight;   /* weight of the heights loss at the coarsest scale (on whole windows:
                              not when coarsest > patch): the 1-D Wasserstein distance between
                              the heights of its output and of the example's coarsest scale, in
                              units of their variance there (without it samples
                              lack the example's rarer massif or range; docs/singan.md); 0 = 4,
                              < 0 = none */
    int dequantize;        /* train on the example without its height steps (tn_image_dequantize):
                              0 = when they are coarse (tn_image_height_step's coarse_only: 8-bit
                              heightmaps, whose steps the finest scales would learn as a grain),
                              1 = whenever it is stored in steps, -1 = never */
    tn_train_opts train;   /* budget (minutes 0 = 10), checkpoints, resume (the checkpoint's
                              architecture wins; the example must be the same), seed */
} tn_singan_opts;

/* A trained model (the generators). Free with tn_singan_free. */
typedef struct tn_singan {
    int scales;              /* pyramid scales (0 = coarsest) */
    int trained;             /* scales trained; finer ones (a run stopped early) pass their input on */
    int width, height;       /* the example's size (the finest scale) */
    float factor;            /* size ratio between consecutive scales */
    float offset, range;     /* example heights = offset + range * network units */
    float amp[TN_SINGAN_MAX_SCALES];  /* noise amplitude per scale (network units) */
    int channels[TN_SINGAN_MAX_SCALES];
    long iterations;         /* training iterations done */
    double train_seconds;
    tn_params *weights;      /* "singan.config", "g<s>.w<l>" / "b<l>" / "n<l>" / "o<l>", buffers "g<s>.m<l>" / "v<l>" */
} tn_singan;

typedef struct tn_singan_stats {
    long iterations;          /* total, including resumed ones */
    long resumed_from;        /* iteration the run resumed at (0 = fresh) */
    double seconds;           /* total training seconds, including resumed time */
    double seconds_per_iter;  /* this run's average over all scales */
    double seconds_per_iter_finest; /* this run's average at the finest scale (0 if it did not get there) */
    int scales, trained;      /* pyramid scales; scales trained */
    long scale_iters[TN_SINGAN_MAX_SCALES]; /* iterations each scale got */
    float loss_d, loss_g, loss_rec; /* last scale trained, averages over its last 50 iterations
                                       (loss_rec: unweighted MSE in network units) */
    float loss_rec_first;     /* loss_rec of the first iteration of that scale in this run (NaN if none) */
    int checkpoints;          /* checkpoints written by this run */
    float dequantized;        /* the height step the example was trained without (option
                                 dequantize); 0 = none */
} tn_singan_stats;

/* Options of sampling, refinement and upscaling (zero = defaults, resolved by tn_singan_gen_defaults). */
typedef struct tn_singan_gen_opts {
    uint64_t seed;         /* noise seed: the same seed gives the same terrain */
    int from_scale;        /* refine: the first scale whose generator runs on the injected map
                              (1..scales-1; 0 = scales - 3); upscale: the scale the input stands
                              for + 1 (1..scales; 0 = the output at the example's pixel size) */
    float noise;           /* multiplier of the trained noise amplitudes; 0 = 1, < 0 = no noise */
    float fine_noise;      /* a further multiplier of the finest generator's noise, wherever it runs (upscaling's
                              levels too); < 0 = none; 0 = 0.7 in a free sample with the gate, 1 (as trained) in
                              laid-out maps, refinement and upscaling. The finest generator passes part of its
                              noise on, and a free sample's gate keeps that grain at the example's detail RMS */
    int tile;              /* generated in tiles of this side (bounded memory, same result); 0 = 256 */
    int layout;            /* sample: 1 = the example itself (or its parts: layout_blocks), rearranged by patch
                              nearest neighbours (GPNN) and bent by a random smooth warp on the grid of scale
                              layout_scale - 1, is that scale's output; the finer scales add SinGAN's detail; the
                              map is then finite (origin (0, 0) only). 0 = the coarsest generator (infinite
                              terrain) */
    int layout_scale;      /* the first scale that runs on the layout, 1..scales-1 (1: the layout replaces the
                              coarsest scale); 0 = 3, at most scales - 1 */
    float layout_noise;    /* GPNN's noise for the layout (tn_gpnn_opts.noise); 0 = 2 */
    int layout_blocks;     /* n > 0: GPNN starts the layout from a quilt of n x n blocks of the example, with
                              GPNN's completeness term so that no part repeats: a new arrangement of the
                              example's parts (tn_gpnn_opts.blocks, alpha 0.005; 2 is what docs/singan.md
                              measured); 0 = from the example itself (its own arrangement, bent and turned) */
    float layout_warp;     /* RMS displacement of the layout's warp, in the sample's px; 0 = 16, < 0 = none */
    float layout_smooth;   /* the warp's Gaussian smoothing, in the sample's px; 0 = 96 */
    int layout_turn;       /* the layout is given one of its mirror images, drawn from the seed: 1 = one of 4
                              (as it is, mirrored in x, in y, or both: a half turn), right for any pixel shape;
                              2 = one of 8, the quarter turns too (square pixels only: a quarter turn swaps
                              the pixel's sides); 0 = 1, < 0 = as the example */
    int gate;              /* sample: 1 = each scale's detail is scaled by the example's own detail over the
                              generator's at the same rank of the coarser scale's slope, at most 1.5 (the
                              example's plains stay smooth, its crests sharp); measured on a reference
                              sample for free samples, on the example for laid-out maps; 0 = 1, < 0 = off */
} tn_singan_gen_opts;

/* Fills *o with the defaults (what zero fields mean). */
TN_API void tn_singan_defaults(tn_singan_opts *o);
/* Resolves the zero fields of generation options (from_scale is resolved per call, by the model, and
   fine_noise per call, by what is generated). */
TN_API void tn_singan_gen_defaults(tn_singan_gen_opts *o);
/* Trains on channel 0 of dem (finite, not constant, its smaller side >= opts->coarsest).
   Reports progress as "singan-train scale S/N". *model is allocated here (free with
   tn_singan_free); stats may be NULL. */
TN_API tn_status tn_singan_train(tn_singan *model, const tn_image *dem, const tn_singan_opts *opts, tn_singan_stats *stats);
TN_API void tn_singan_free(tn_singan *model);
/* .tnw model files stamped with method "singan"; load refuses other methods' files and
   checkpoints with TN_ERR_FORMAT and damaged ones with TN_ERR_CORRUPT. */
TN_API tn_status tn_singan_save(const char *path, const tn_singan *model);
TN_API tn_status tn_singan_load(tn_singan *model, const char *path);

/* The window (x0, y0, w, h) of the infinite random terrain of opts->seed at the example's pixel
   size, in the example's units: any window equals the same pixels of a larger one exactly (a
   whole map and its tiles agree). Heights beyond the example's range are compressed smoothly
   into 10 % of the range on either side (upstream SinGAN clamps to the range). *out (one
   channel) is allocated here. */
TN_API tn_status tn_singan_sample(tn_image *out, const tn_singan *model, int x0, int y0, int w, int h,
                                  const tn_singan_gen_opts *opts);
/* A w x h map prepared once for many windows (the tiles of one world): with opts->layout its
   layout (GPNN and the warp, the part that is not local) is made here, so a laid-out map, finite
   for tn_singan_sample, can be made tile by tile. A window of it equals the same pixels of
   tn_singan_sample(0, 0, w, h) with the same model and options. Laid-out maps up to
   TN_SINGAN_LAYOUT_MAX_PX pixels. The model must outlive *out; opts is copied. Free with
   tn_singan_prepared_free. */
#define TN_SINGAN_LAYOUT_MAX_PX (4096L * 4096L)
typedef struct tn_singan_prepared tn_singan_prepared;
TN_API tn_status tn_singan_prepare(tn_singan_prepared **out, const tn_singan *model, int w, int h, const tn_singan_gen_opts *opts);
/* *out = the window (x0, y0, w, h) of p's map, which it must lie in (one channel, the example's
   units), allocated here. p is only read. */
TN_API tn_status tn_singan_prepared_window(tn_image *out, const tn_singan_prepared *p, int x0, int y0, int w, int h);
TN_API void tn_singan_prepared_free(tn_singan_prepared *p); /* NULL is fine */
/* Adds the example's detail to `in` (a smooth map in the example's units and pixel size, e.g.
   a GNN output or a membrane): `in` resized to scale opts->from_scale replaces the upsampled
   coarser output there and the generators of that scale and the finer ones run. *out has in's
   size. */
TN_API tn_status tn_singan_refine(tn_image *out, const tn_singan *model, const tn_image *in, const tn_singan_gen_opts *opts);
/* Super-resolution by `factor` (1 < factor <= 64): `in` stands for the scale round(log factor /
   log(1/model->factor)) scales coarser than the output; the generators above it add detail
   (beyond the finest scale the finest generator repeats, SinGAN's SR mode). *out is
   round(factor * in's size). */
TN_API tn_status tn_singan_upscale(tn_image *out, const tn_singan *model, const tn_image *in, float factor,
                                   const tn_singan_gen_opts *opts);

/* GPNN baseline (Granot et al. 2022, "Drop the GAN"): generation by patch nearest neighbours,
   no training. A pyramid of the example (factor, down to `coarsest` px); the output's coarsest
   scale is the example's plus Gaussian noise; at every scale each patch of the current image is
   replaced by its nearest patch of the example at that scale (keys: the example's coarser scale
   upsampled on the first pass, the example itself after it; the overlapping patches averaged),
   `iters` passes, then upsampled to the next scale. Exact nearest neighbours where the search is
   small (optionally with GPNN's completeness normalisation: score = distance / (alpha + the
   key's best distance to any query)), PatchMatch (propagation + random search) above it.
   Measured on the shared DEMs (docs/singan.md): GPNN's own noise (0.75) and normalisation give
   back the example itself at the example's size; noise 5 x the std and plain nearest
   neighbours are the defaults. */
typedef struct tn_gpnn_opts {
    uint64_t seed;         /* noise seed */
    int patch;             /* patch side (odd, 3..15); 0 = 7 */
    int coarsest;          /* smaller side of the coarsest scale in px (>= patch); 0 = 25 */
    float factor;          /* size ratio between scales, 0.5..0.9; 0 = 0.75 */
    int iters;             /* passes per scale; 0 = 10 */
    float noise;           /* noise std at the coarsest scale / the example's std there; 0 = 5, < 0 = none */
    float alpha;           /* > 0: GPNN's completeness normalisation, alpha in units of the distance of
                              the example's patches to themselves shifted by 1 px (GPNN: 0.005);
                              0 = none (plain nearest neighbours) */
    int extend;            /* an output larger than the example starts from: 0 = the example's coarsest scale
                              stretched to it (GPNN's retargeting: features grow with the output); 1 = blocks
                              of it at random places (features keep the example's size) */
    int blocks;            /* > 0: the coarsest scale starts from a quilt of blocks of 1 / blocks of the
                              example's smaller side, of the example without its tilt and within one of its
                              mirror images, that continue the blocks beside them but not as the example
                              does (its parts rearranged, at any output size); 0 = as `extend` says */
} tn_gpnn_opts;

/* A w x h terrain like channel 0 of example (finite, not constant, smaller side >= opts->coarsest),
   in its units. *out (one channel) is allocated here. opts may be NULL (defaults). */
TN_API tn_status tn_gpnn_sample(tn_image *out, const tn_image *example, int w, int h, const tn_gpnn_opts *opts);
#endif /* TN_NO_SINGAN */

/* --------------------------------------------------------------------------------------------
   >>singan  (@@singan implementation)
   Layout: sizes and the config tensor; networks (generator, discriminators); the windowed
   generation every caller shares (one level computes its window from the coarser level's
   window grown by the convolutions' 5 px context, or from an injected map); training on
   tn_train runs (one G set and one D set holding every scale, so the run registers two nets; a scale
   switch zeroes both optimisers' moments and steps, so the earlier scales, whose gradients stay
   zero, do not move: a fresh Adam per scale as in SinGAN); model files; sample, refine, upscale.
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_SINGAN

#define TN__SG_FORMAT 5 /* 2: the per-scale output gain (issue 31); 3: the smoothed coarsest
                           noise (its third round); 4: the example's coarsest scale for the
                           layout (its fourth); 5: the whole example for the layout (its
                           seventh). Older models are refused */
/* What each older format lacks, for the message that refuses it. */
static const char *const tn__sg_format_why[TN__SG_FORMAT] = {
    "", "per-scale output gain", "smoothed coarsest noise", "layout: it lacks the example's coarsest scale",
    "layout at any scale: it holds only the example's coarsest scale"};
#define TN__SG_CONFIG (8 + 3 * TN_SINGAN_MAX_SCALES)
#define TN__SG_CONFIG1 (8 + 2 * TN_SINGAN_MAX_SCALES) /* format 1 */
#define TN__SG_SCHED (5 + TN_SINGAN_MAX_SCALES) /* scale, its first iteration, its count, a time, its deadline, iterations per scale */
#define TN__SG_M 5 /* context of 5 valid 3 x 3 convolutions */
/* The coarsest generator's tanh times 2: the example spans -1..1 there, and at a gain of 1 its
   summits and floors sat where tanh saturates, so samples fell short of them (older models
   store 1, and keep it) */
#define TN__SG_GAIN0 2.0f
/* The finer generators' tanh times 5 x the example's detail RMS sigma at the scale, or 1.25 x its
   largest detail where that is more (at most 1): a summit or a crater rim is 6-14 sigma, and a gain
   of 5 sigma cut it off, so a sample's massifs came out flat-topped (docs/singan.md). */
#define TN__SG_GAIN_RMS 5.0f
#define TN__SG_GAIN_PEAK 1.25f
static float tn__sg_gain(float sigma, float peak)
{
    float g = fmaxf(TN__SG_GAIN_RMS * sigma, TN__SG_GAIN_PEAK * peak);
    return g > 1.0f ? 1.0f : g;
}
#define TN__SG_BANK 4 /* fake bases per scale (tn__sg_bank_fill) */
#define TN__SG_BANK_PX (1 << 20) /* scales with more pixels (grown by the context) make each base anew */
#define TN__SG_BANK_TILE 256

TN_API void tn_singan_defaults(tn_singan_opts *o)
{
    TN_ASSERT(o);
    /* SinGAN's recipe: coarsest ~25 px, factor 0.75, 32 channels doubling every 4 scales,
       Adam 5e-4 (0.5, 0.999), reconstruction weight 10; noise 0.5 x the detail RMS (SinGAN: 0.1 x
       the coarser reconstruction's RMSE, measured too smooth here). The width cap is 32:
       at 64 channels the finest scales of a 256 x 256 example cost 4x as much and the default
       10-minute budget on 2 cores leaves too few iterations per scale (docs/singan.md). */
    if (o->coarsest <= 0) o->coarsest = 25;
    if (o->factor == 0) o->factor = 0.75f;
    if (o->channels <= 0) o->channels = 32;
    if (o->max_channels <= 0) o->max_channels = 32;
    if (o->max_channels < o->channels) o->max_channels = o->channels;
    if (o->disc_layers <= 0) o->disc_layers = 2;
    if (o->patch == 0) o->patch = 64;
    if (o->lr == 0) o->lr = 5e-4f;
    if (o->rec_weight == 0) o->rec_weight = 10.0f;
    if (o->noise_amp == 0) o->noise_amp = 0.5f;
    if (o->adv_weight == 0) o->adv_weight = 1.0f;
    if (o->adv_weight < 0) o->adv_weight = 0.0f;
    if (o->d_steps <= 0) o->d_steps = 1;
    if (o->curv_weight == 0) o->curv_weight = 10.0f;
    if (o->curv_weight < 0) o->curv_weight = 0.0f;
    if (o->spec_weight == 0) o->spec_weight = 1.0f;
    if (o->spec_weight < 0) o->spec_weight = 0.0f;
    if (o->height_weight == 0) o->height_weight = 4.0f;
    if (o->height_weight < 0) o->height_weight = 0.0f;
    tn_train_defaults(&o->train, 10.0);
}

/* The rules of tn_singan_opts after tn_singan_defaults, one message each. */
static tn_status tn__sg_validate(const tn_singan_opts *o)
{
    const char *w = "singan";
    tn_status st;
    if ((st = tn__opt_float(w, "factor", o->factor, "[]", 0.5, 0.9)) || (st = tn__opt_int(w, "coarsest", o->coarsest, 4, INT_MAX)) ||
        (st = tn__opt_int(w, "channels", o->channels, 1, 256)) || (st = tn__opt_int(w, "max_channels", o->max_channels, 1, 256)) ||
        (st = tn__opt_int(w, "disc_layers", o->disc_layers, 1, 4)))
        return st;
    if (o->patch > 0 && o->patch < 16)
        return tn__fail(TN_ERR_INVALID_ARG, "singan: option patch = %d, allowed >= 16 (< 0: whole scales)", o->patch);
    if ((st = tn__opt_float(w, "lr", o->lr, "()", 0, 10)) || (st = tn__opt_float(w, "rec_weight", o->rec_weight, "()", -HUGE_VAL, HUGE_VAL)) ||
        (st = tn__opt_float(w, "noise_amp", o->noise_amp, "[]", 0, 100)) || (st = tn__opt_int(w, "iters", o->iters, 0, INT_MAX)) ||
        (st = tn__opt_float(w, "adv_weight", o->adv_weight, "[]", 0, 1e6)) || (st = tn__opt_int(w, "d_steps", o->d_steps, 1, 100)) ||
        (st = tn__opt_float(w, "curv_weight", o->curv_weight, "[]", 0, 1e6)) || (st = tn__opt_float(w, "spec_weight", o->spec_weight, "[]", 0, 1e6)) ||
        (st = tn__opt_float(w, "height_weight", o->height_weight, "[]", 0, 1e6)) || (st = tn__opt_int(w, "dequantize", o->dequantize, -1, 1)))
        return st;
    return TN_OK;
}

TN_API void tn_singan_gen_defaults(tn_singan_gen_opts *o)
{
    TN_ASSERT(o);
    if (o->noise == 0) o->noise = 1.0f;
    if (o->noise < 0) o->noise = 0.0f;
    if (o->tile <= 0) o->tile = 256;
    if (o->layout_noise == 0) o->layout_noise = 2.0f;
    if (o->layout_warp == 0) o->layout_warp = 16.0f;
    if (o->layout_warp < 0) o->layout_warp = 0.0f;
    if (o->layout_smooth == 0) o->layout_smooth = 96.0f;
    if (o->layout_turn == 0) o->layout_turn = 1;
    if (o->layout_turn < 0) o->layout_turn = 0;
    if (o->gate == 0) o->gate = 1;
    if (o->gate < 0) o->gate = 0;
}

/* ---- sizes and config ---- */

typedef struct tn__sg_arch {
    int scales, width, height, trained, disc_layers;
    float factor, offset, range;
    float amp[TN_SINGAN_MAX_SCALES];
    float gain[TN_SINGAN_MAX_SCALES]; /* the generator's tanh times this: tn__sg_gain (TN__SG_GAIN0 at scale 0) */
    int ch[TN_SINGAN_MAX_SCALES];
} tn__sg_arch;

/* Size of scale s of an output whose finest scale (level scales - 1) is n px. */
static int tn__sg_size(int n, float factor, int levels_down)
{
    double v = (double)n * pow((double)factor, (double)levels_down);
    int r = (int)floor(v + 0.5);
    return r < 1 ? 1 : r;
}

static void tn__sg_write_config(const tn__sg_arch *A, float *c)
{
    int s;
    memset(c, 0, TN__SG_CONFIG * sizeof(float));
    c[0] = (float)A->scales;
    c[1] = (float)A->width;
    c[2] = (float)A->height;
    c[3] = A->factor;
    c[4] = A->offset;
    c[5] = A->range;
    c[6] = (float)A->trained;
    c[7] = (float)A->disc_layers;
    for (s = 0; s < A->scales; s++) {
        c[8 + s] = A->amp[s];
        c[8 + TN_SINGAN_MAX_SCALES + s] = (float)A->ch[s];
        c[8 + 2 * TN_SINGAN_MAX_SCALES + s] = A->gain[s];
    }
}

static tn_status tn__sg_read_config(const float *c, tn__sg_arch *A, const char *name)
{
    int s;
    memset(A, 0, sizeof *A);
    if (!(c[0] >= 1 && c[0] <= TN_SINGAN_MAX_SCALES && c[0] == floorf(c[0])) || !(c[1] >= 1 && c[1] <= 1e6f && c[1] == floorf(c[1])) ||
        !(c[2] >= 1 && c[2] <= 1e6f && c[2] == floorf(c[2])) || !(c[3] >= 0.5f && c[3] <= 0.9f) || !isfinite(c[4]) ||
        !(c[5] > 0 && c[5] <= FLT_MAX) || !(c[6] >= 0 && c[6] <= c[0] && c[6] == floorf(c[6])) ||
        !(c[7] >= 1 && c[7] <= TN_DISC_MAX_LAYERS && c[7] == floorf(c[7])))
        return tn__fail(TN_ERR_CORRUPT, "%s: damaged singan configuration", name);
    A->scales = (int)c[0];
    A->width = (int)c[1];
    A->height = (int)c[2];
    A->factor = c[3];
    A->offset = c[4];
    A->range = c[5];
    A->trained = (int)c[6];
    A->disc_layers = (int)c[7];
    for (s = 0; s < A->scales; s++) {
        float a = c[8 + s], w = c[8 + TN_SINGAN_MAX_SCALES + s], g = c[8 + 2 * TN_SINGAN_MAX_SCALES + s];
        if (!(a >= 0 && a <= 100) || !(w >= 1 && w <= 512 && w == floorf(w)) || !(g > 0 && g <= 2))
            return tn__fail(TN_ERR_CORRUPT, "%s: damaged singan configuration (scale %d)", name, s);
        A->amp[s] = a;
        A->gain[s] = g;
        A->ch[s] = (int)w;
    }
    return TN_OK;
}

/* ---- networks ---- */

/* Generator of scale s: "g<s>.w<l>" (Cout x Cin x 3 x 3), "b<l>", batch norm gain "n<l>",
   offset "o<l>", running mean / variance buffers "m<l>" / "v<l>" for l < 4. SinGAN's init
   (conv weights N(0, 0.02), norm gains N(1, 0.02)) except the tail conv, which starts at zero. */
static tn_status tn__sg_gen_add(tn_params *p, int s, int ch, tn_rng *rng)
{
    int l;
    for (l = 0; l < 5; l++) {
        int cin = l == 0 ? 1 : ch, cout = l == 4 ? 1 : ch, ws[4];
        char pre[16];
        tn_tensor *w, *b;
        ws[0] = cout;
        ws[1] = cin;
        ws[2] = ws[3] = 3;
        snprintf(pre, sizeof pre, "g%d.", s);
        if (!(w = tn__param_new(p, pre, "w", l, 4, ws, 1)) || !(b = tn__param_new(p, pre, "b", l, 1, &cout, 1))) return TN_ERR_OUT_OF_MEMORY;
        if (rng) tn_init_normal(w, rng, 0.0f, 0.02f);
        if (l == 4) tn_tensor_fill(w, 0.0f); /* a scale starts as the identity on its input, so a
                                                short run's little-trained scales add no noise */
        if (l < 4) {
            tn_tensor *g, *o, *m, *v;
            if (!(g = tn__param_new(p, pre, "n", l, 1, &cout, 1)) || !(o = tn__param_new(p, pre, "o", l, 1, &cout, 1)) ||
                !(m = tn__param_new(p, pre, "m", l, 1, &cout, 0)) || !(v = tn__param_new(p, pre, "v", l, 1, &cout, 0)))
                return TN_ERR_OUT_OF_MEMORY;
            if (rng) tn_init_normal(g, rng, 1.0f, 0.02f);
            else tn_tensor_fill(g, 1.0f);
            tn_tensor_fill(v, 1.0f);
        }
    }
    return TN_OK;
}

static tn_status tn__sg_model_params(const tn__sg_arch *A, tn_rng *rng, tn_params **out)
{
    tn_params *p = tn_params_create();
    tn_tensor *cfg;
    int n = TN__SG_CONFIG, s;
    tn_status st = TN_OK;
    *out = NULL;
    if (!p) return tn__fail(TN_ERR_OUT_OF_MEMORY, "singan: out of memory");
    int ls[2];
    ls[0] = A->height;
    ls[1] = A->width;
    if (!(cfg = tn_params_add_buffer(p, "singan.config", 1, &n))) st = TN_ERR_OUT_OF_MEMORY;
    else tn__sg_write_config(A, cfg->data);
    /* the example (network units): what a laid-out sample rearranges */
    if (!st && !tn_params_add_buffer(p, "singan.layout", 2, ls)) st = TN_ERR_OUT_OF_MEMORY;
    for (s = 0; s < A->scales && !st; s++) st = tn__sg_gen_add(p, s, A->ch[s], rng);
    if (st) {
        tn_params_free(p);
        return st;
    }
    *out = p;
    return TN_OK;
}

/* 5 valid 3 x 3 convolutions: (h + 10) x (w + 10) in, h x w out. training: batch statistics
   (and running averages updated); else the running statistics, so every pixel depends only on
   its 11 x 11 input neighbourhood. */
static tn_tensor *tn__sg_gen(tn_ctx *ctx, const tn_params *p, int s, float gain, tn_tensor *x, int training)
{
    char pre[16];
    int l;
    snprintf(pre, sizeof pre, "g%d.", s);
    for (l = 0; l < 5 && x; l++) {
        x = tn_conv2d(ctx, x, tn__param_named(p, pre, "w", l), tn__param_named(p, pre, "b", l), NULL);
        if (l < 4) {
            x = tn_batch_norm(ctx, x, tn__param_named(p, pre, "n", l), tn__param_named(p, pre, "o", l), tn__param_named(p, pre, "m", l),
                              tn__param_named(p, pre, "v", l), training, 1e-5f);
            x = tn_leaky_relu(ctx, x, 0.2f);
        } else
            x = tn_tanh(ctx, x);
    }
    return gain != 1.0f ? tn_scale_shift(ctx, x, gain, 0.0f) : x;
}

/* ---- noise ---- */

static uint64_t tn__sg_level_key(uint64_t seed, int level) { return tn__splitmix64(seed ^ (0x73696e67ULL + 0x9E3779B97F4A7C15ULL * (uint64_t)(level + 1))); }
/* The reconstruction's fixed noise map (coarsest scale only): a key no seed's level key equals in practice. */
#define TN__SG_REC_KEY 0x5245434f4e535452ULL

/* Approximately standard normal noise at global pixel (gx, gy): the sum of four 16-bit uniforms
   of one hash, centred and scaled to unit variance (no libm call, same bits everywhere). */
static float tn__sg_noise(uint64_t key, long gx, long gy)
{
    uint64_t v = tn__splitmix64(key ^ (((uint64_t)(uint32_t)gy << 32) | (uint32_t)gx));
    float s = (float)(v & 0xffffu) + (float)((v >> 16) & 0xffffu) + (float)((v >> 32) & 0xffffu) + (float)(v >> 48);
    return (s * (1.0f / 65536.0f) - 2.0f + 2.0f / 65536.0f) * 1.7320508f;
}

/* The coarsest scale's noise: tn__sg_noise filtered by a 9 x 9 binomial kernel (std 1.4 px),
   scaled back to unit variance. From white noise the coarsest generator made pixel-sized bumps
   that the bilinear upsampling drew as axis-aligned straight lines (docs/singan.md). */
#define TN__SG_BLUR0 4
static float tn__sg_noise0(uint64_t key, long gx, long gy)
{
    static const float k[2 * TN__SG_BLUR0 + 1] = {1, 8, 28, 56, 70, 56, 28, 8, 1};
    const float norm = 1.0f / 12870.0f; /* 1 / sum of k^2, once per axis: unit variance */
    float v = 0;
    int a, b;
    for (b = 0; b <= 2 * TN__SG_BLUR0; b++) {
        float r = 0;
        for (a = 0; a <= 2 * TN__SG_BLUR0; a++) r += k[a] * tn__sg_noise(key, gx + a - TN__SG_BLUR0, gy + b - TN__SG_BLUR0);
        v += k[b] * r;
    }
    return v * norm;
}

/* ---- windowed generation ---- */

/* Per scale, the factor on the generator's detail by the slope of the coarser scale upsampled
   (tn__sg_gate_make): piecewise linear through TN__SG_GATE_BINS (slope, factor) points. */
#define TN__SG_GATE_BINS 8
#define TN__SG_GATE_MAX 1.5f
typedef struct tn__sg_gate {
    float slope[TN_SINGAN_MAX_SCALES][TN__SG_GATE_BINS];
    float keep[TN_SINGAN_MAX_SCALES][TN__SG_GATE_BINS];
    int on[TN_SINGAN_MAX_SCALES];
} tn__sg_gate;

typedef struct tn__sg_gen_run {
    const tn__sg_arch *A;
    const tn__sg_gate *gate; /* NULL: the detail as generated */
    const tn_params *g;
    tn_ctx *ctx;
    uint64_t seed;
    int rec;              /* the reconstruction: fixed noise at level 0, none above */
    float noise;          /* multiplier of the amplitudes */
    float fine_noise;     /* and of the finest generator's, on top */
    const float *map;     /* injected map on level map_level's grid (origin 0), or NULL */
    int mw, mh, map_level;
    int mx0, my0, mstride; /* map holds only columns mx0.. and rows my0.. of the mw x mh map, rows
                              mstride apart (0 = mw: the whole map); @@world's refine tiles */
    int map_is_output;    /* 1: the map is that level's output; 0: its upsampled coarser input */
    int limit;            /* 1: the output's heights softly limited to the example's range +- 10 % (tn__soft_limit; upstream SinGAN clamps) */
} tn__sg_gen_run;

static int tn__sg_net(const tn__sg_arch *A, int level) { return level < A->scales ? level : A->scales - 1; }

static tn_status tn__sg_window(const tn__sg_gen_run *r, int level, long x0, long y0, int w, int h, float *out);

/* Coarse pixel index and weight of the bilinear sample at fine global position x. */
static void tn__sg_coord(long x, double f, long *i, float *t)
{
    double c = ((double)x + 0.5) * f - 0.5, fl = floor(c);
    *i = (long)fl;
    *t = (float)(c - fl);
}

/* The base of `level` (the upsampled coarser output, the injected map, or 0) on a window. */
static tn_status tn__sg_base(const tn__sg_gen_run *r, int level, long x0, long y0, int w, int h, float *base)
{
    long cx0, cy0, cx1, cy1, *ix = NULL, *iy = NULL;
    float *tx = NULL, *ty = NULL, *coarse = NULL, tt;
    int x, y, cw, chh;
    size_t n = (size_t)w * h;
    tn_status st = TN_OK;
    if (r->map && level == r->map_level) { /* clamped at the map's border */
        size_t stride = (size_t)(r->mstride ? r->mstride : r->mw);
        for (y = 0; y < h; y++) {
            long yy = y0 + y;
            yy = yy < 0 ? 0 : yy >= r->mh ? r->mh - 1 : yy;
            for (x = 0; x < w; x++) {
                long xx = x0 + x;
                xx = xx < 0 ? 0 : xx >= r->mw ? r->mw - 1 : xx;
                base[(size_t)y * w + x] = r->map[(size_t)(yy - r->my0) * stride + (size_t)(xx - r->mx0)];
            }
        }
        return TN_OK;
    }
    if (level == 0 || (r->map && level < r->map_level)) {
        memset(base, 0, n * sizeof(float));
        return TN_OK;
    }
    tn__sg_coord(x0, r->A->factor, &cx0, &tt);
    tn__sg_coord(x0 + w - 1, r->A->factor, &cx1, &tt);
    tn__sg_coord(y0, r->A->factor, &cy0, &tt);
    tn__sg_coord(y0 + h - 1, r->A->factor, &cy1, &tt);
    cw = (int)(cx1 + 2 - cx0);
    chh = (int)(cy1 + 2 - cy0);
    coarse = (float *)tn__alloc((size_t)cw * chh * sizeof(float));
    ix = (long *)tn__alloc((size_t)(w + h) * sizeof(long));
    tx = (float *)tn__alloc((size_t)(w + h) * sizeof(float));
    if (!coarse || !ix || !tx) {
        st = TN_ERR_OUT_OF_MEMORY;
        goto done;
    }
    iy = ix + w;
    ty = tx + w;
    if ((st = tn__sg_window(r, level - 1, cx0, cy0, cw, chh, coarse))) goto done;
    for (x = 0; x < w; x++) {
        tn__sg_coord(x0 + x, r->A->factor, &ix[x], &tx[x]);
        ix[x] -= cx0;
    }
    for (y = 0; y < h; y++) {
        tn__sg_coord(y0 + y, r->A->factor, &iy[y], &ty[y]);
        iy[y] -= cy0;
    }
    for (y = 0; y < h; y++) {
        const float *c0 = coarse + (size_t)iy[y] * cw, *c1 = c0 + cw;
        float b = ty[y];
        for (x = 0; x < w; x++) {
            float a = tx[x], u = (1 - a) * c0[ix[x]] + a * c0[ix[x] + 1], v = (1 - a) * c1[ix[x]] + a * c1[ix[x] + 1];
            base[(size_t)y * w + x] = (1 - b) * u + b * v;
        }
    }
done:
    TN_FREE(coarse);
    TN_FREE(ix);
    TN_FREE(tx);
    return st;
}

/* Generator input of `level` on the window grown by the context: base + amplitude x noise. */
static void tn__sg_add_noise(const tn__sg_gen_run *r, int level, long x0, long y0, int w, int h, float *x)
{
    float amp = r->rec ? (level == 0 ? 1.0f : 0.0f)
                       : r->A->amp[tn__sg_net(r->A, level)] * r->noise * (level >= r->A->scales - 1 ? r->fine_noise : 1.0f);
    uint64_t key = r->rec ? TN__SG_REC_KEY : tn__sg_level_key(r->seed, level);
    int i, j;
    if (amp == 0) return;
    if (level == 0) { /* smoothed: see tn__sg_noise0 */
        for (j = 0; j < h; j++)
            for (i = 0; i < w; i++) x[(size_t)j * w + i] += amp * tn__sg_noise0(key, x0 + i, y0 + j);
        return;
    }
    for (j = 0; j < h; j++)
        for (i = 0; i < w; i++) x[(size_t)j * w + i] += amp * tn__sg_noise(key, x0 + i, y0 + j);
}

/* The slope at b (central differences; rows `stride` apart). */
static float tn__sg_slope(const float *b, int stride)
{
    float gx = b[1] - b[-1], gy = b[stride] - b[-stride];
    return 0.5f * sqrtf(gx * gx + gy * gy);
}

/* The gate's factor at base pixel b of `level`. */
static float tn__sg_gate_at(const tn__sg_gate *g, int level, const float *b, int stride)
{
    const float *sl = g->slope[level], *k = g->keep[level];
    float v = tn__sg_slope(b, stride);
    int i;
    if (v <= sl[0]) return k[0];
    for (i = 1; i < TN__SG_GATE_BINS; i++)
        if (v < sl[i]) return k[i - 1] + (k[i] - k[i - 1]) * (v - sl[i - 1]) / (sl[i] - sl[i - 1]);
    return k[TN__SG_GATE_BINS - 1];
}

/* Output of `level` on the window (x0, y0, w, h) into out (w * h). */
static tn_status tn__sg_window(const tn__sg_gen_run *r, int level, long x0, long y0, int w, int h, float *out)
{
    const int M = TN__SG_M;
    int ew = w + 2 * M, eh = h + 2 * M, net = tn__sg_net(r->A, level), y;
    float *base;
    tn_tensor *xin, *g;
    tn_status st;
    if (r->map && r->map_is_output && level == r->map_level) return tn__sg_base(r, level, x0, y0, w, h, out);
    if (net >= r->A->trained) { /* an untrained scale passes its input on */
        return tn__sg_base(r, level, x0, y0, w, h, out);
    }
    if (!(base = (float *)tn__alloc((size_t)ew * eh * sizeof(float)))) return TN_ERR_OUT_OF_MEMORY;
    if ((st = tn__sg_base(r, level, x0 - M, y0 - M, ew, eh, base))) {
        TN_FREE(base);
        return st;
    }
    tn_ctx_reset(r->ctx);
    tn_ctx_set_grad(r->ctx, 0);
    xin = tn_tensor_4d(r->ctx, 1, 1, eh, ew);
    if (xin) {
        memcpy(xin->data, base, (size_t)ew * eh * sizeof(float));
        tn__sg_add_noise(r, level, x0 - M, y0 - M, ew, eh, xin->data);
    }
    g = tn__sg_gen(r->ctx, r->g, net, r->A->gain[net], xin, 0);
    if (!g) {
        TN_FREE(base);
        return tn_ctx_status(r->ctx) ? tn_ctx_status(r->ctx) : tn__fail(TN_ERR_OUT_OF_MEMORY, "singan: out of memory");
    }
    for (y = 0; y < h; y++) {
        const float *b = base + (size_t)(y + M) * ew + M, *gg = g->data + (size_t)y * w;
        float *o = out + (size_t)y * w;
        int x;
        if (r->gate && r->gate->on[level])
            for (x = 0; x < w; x++) o[x] = tn__sg_gate_at(r->gate, level, b + x, ew) * gg[x] + b[x];
        else
            for (x = 0; x < w; x++) o[x] = gg[x] + b[x];
    }
    TN_FREE(base);
    return TN_OK;
}

/* The top level's window (x0, y0, w, h) tile by tile into *out, in the example's units. */
static tn_status tn__sg_generate(const tn_singan *m, tn__sg_gen_run *r, int level, long x0, long y0, int w, int h, int tile, tn_image *out)
{
    tn_image img = {0, 0, 0, NULL};
    float *buf = NULL;
    int tx, ty;
    tn_status st;
    long done = 0, total = (long)((w + tile - 1) / tile) * ((h + tile - 1) / tile);
    if ((st = tn_image_create(&img, w, h, 1))) return st;
    if (!(r->ctx = tn_ctx_create()) || !(buf = (float *)tn__alloc((size_t)tile * tile * sizeof(float)))) {
        st = tn__fail(TN_ERR_OUT_OF_MEMORY, "singan: out of memory");
        goto done;
    }
    for (ty = 0; ty < h && !st; ty += tile)
        for (tx = 0; tx < w && !st; tx += tile) {
            int tw = w - tx < tile ? w - tx : tile, th = h - ty < tile ? h - ty : tile, y, x;
            if ((st = tn__sg_window(r, level, x0 + tx, y0 + ty, tw, th, buf))) break;
            for (y = 0; y < th; y++)
                for (x = 0; x < tw; x++) {
                    float v = buf[(size_t)y * tw + x];
                    img.data[(size_t)(ty + y) * w + tx + x] = m->offset + m->range * (r->limit ? tn__soft_limit(v, -1.0f, 1.0f, 0.2f) : v);
                }
            if (total > 1) st = tn__progress("singan-generate", (double)++done / (double)total);
        }
done:
    TN_FREE(buf);
    tn_ctx_free(r->ctx);
    r->ctx = NULL;
    if (st) tn_image_free(&img);
    else *out = img;
    return st;
}

/* ---- training (a tn_train run) ---- */

#define TN__SG_SPEC_BINS 33 /* radii of the spectrum loss at scale 0 (13 on a 26 px scale) */
typedef struct tn__sg_train {
    tn_singan_opts o;
    tn__sg_arch A;
    tn_train *run;
    tn_params *g, *d, *sched;  /* generators (the model's layout), discriminators, schedule */
    tn_optim *og, *od;
    tn_patch_disc disc[TN_SINGAN_MAX_SCALES];
    float sigma[TN_SINGAN_MAX_SCALES]; /* RMS of the example's detail per scale (the scale minus the coarser one upsampled) */
    float gnorm[TN_SINGAN_MAX_SCALES]; /* RMS of the gradient of the example's upsampled coarser scale per scale */
    float *fcond;              /* this iteration's fake base gradient (2 x patch), the discriminator's context */
    float *realbase;           /* the example's coarser scale upsampled to the current scale */
    tn_rng rng;
    tn_image real[TN_SINGAN_MAX_SCALES]; /* the example pyramid in network units */
    float *recbase;            /* the reconstruction's base at the current scale (grown window) */
    float *xrec;               /* the reconstruction's generator input at the current scale */
    float *base, *xin;         /* this iteration's random base and generator input (patch window) */
    float *fake;               /* this iteration's fake patch (for the D step) */
    float *lapq;               /* the example's Laplacian at the current scale, sorted (its quantiles) */
    size_t nlapq;
    double lapms;              /* its mean square */
    float *lapc;               /* the curvature, spectrum and heights losses' gradient on the fake patch */
    float *lapv, *lapr;        /* the fake patch's Laplacian values; the transport's residuals (Laplacians or heights) */
    uint32_t *lapi;            /* the transport's scratch (4 x the patch's pixels) */
    float *hq;                 /* the example's heights at scale 0, sorted (the heights loss's target) */
    size_t nhq;
    double hvar;               /* their variance */
    float *bank;               /* TN__SG_BANK fake bases of the whole scale, grown by the context */
    int bank_w, bank_h;        /* their size; 0 = none (scale 0, or a scale too large to hold) */
    double budget;             /* seconds */
    double spec_real[TN__SG_SPEC_BINS]; /* the example's radial power spectrum at scale 0 (the spectrum loss's target) */
} tn__sg_train;

static void tn__sg_train_free(tn__sg_train *s)
{
    int i;
    tn_train_free(s->run);
    tn_optim_free(s->og);
    tn_optim_free(s->od);
    tn_params_free(s->g);
    tn_params_free(s->d);
    tn_params_free(s->sched);
    for (i = 0; i < TN_SINGAN_MAX_SCALES; i++) tn_image_free(&s->real[i]);
    TN_FREE(s->recbase);
    TN_FREE(s->xrec);
    TN_FREE(s->base);
    TN_FREE(s->xin);
    TN_FREE(s->fake);
    TN_FREE(s->fcond);
    TN_FREE(s->realbase);
    TN_FREE(s->bank);
    TN_FREE(s->lapq);
    TN_FREE(s->lapc);
    TN_FREE(s->lapv);
    TN_FREE(s->lapr);
    TN_FREE(s->lapi);
    TN_FREE(s->hq);
}

/* The training window of scale sc: the whole scale or a patch. */
static void tn__sg_patch_size(const tn__sg_train *s, int sc, int *pw, int *ph)
{
    int P = s->o.patch;
    *pw = P > 0 && s->real[sc].width > P ? P : s->real[sc].width;
    *ph = P > 0 && s->real[sc].height > P ? P : s->real[sc].height;
}

/* Iterations of scale k relative to the finest: equal counts as in SinGAN, but a scale that
   costs less gets up to 4 times as many (they are cheap and lay out the terrain). */
static double tn__sg_cost(const tn__sg_train *s, int sc);
static double tn__sg_weight(const tn__sg_train *s, int k)
{
    double w = tn__sg_cost(s, s->A.scales - 1) / tn__sg_cost(s, k);
    return w < 1 ? 1 : w > 4 ? 4 : w;
}

/* Whether scale sc draws its fake bases from a bank (tn__sg_bank_fill). */
static int tn__sg_banked(const tn__sg_train *s, int sc)
{
    return sc > 0 && (double)(s->real[sc].width + 2 * TN__SG_M) * (s->real[sc].height + 2 * TN__SG_M) <= TN__SG_BANK_PX;
}

/* Relative cost of the forward passes of scales sc - 1 .. 0 that make a w x h base at scale sc. */
static double tn__sg_base_cost(const tn__sg_train *s, int sc, double w, double h)
{
    double c = 0, f = 1;
    int k;
    for (k = sc - 1; k >= 0; k--) {
        f *= s->A.factor;
        c += (w * f < s->real[k].width ? w * f : s->real[k].width) * (h * f < s->real[k].height ? h * f : s->real[k].height) *
             ((double)s->A.ch[k] * s->A.ch[k] + 1);
    }
    return c;
}

/* Relative cost of one iteration at scale sc: G forward + backward on the fake and the
   reconstruction, and, without a bank, the coarser passes that make the random base. */
static double tn__sg_cost(const tn__sg_train *s, int sc)
{
    int pw, ph;
    double pew, peh;
    tn__sg_patch_size(s, sc, &pw, &ph);
    pew = pw + 2.0 * TN__SG_M;
    peh = ph + 2.0 * TN__SG_M;
    return 6.0 * pew * peh * ((double)s->A.ch[sc] * s->A.ch[sc] + 1) + (tn__sg_banked(s, sc) ? 0 : tn__sg_base_cost(s, sc, pew, peh));
}

/* Relative cost of filling scale sc's bank (0 without one). */
static double tn__sg_bank_cost(const tn__sg_train *s, int sc)
{
    return tn__sg_banked(s, sc) ? TN__SG_BANK * tn__sg_base_cost(s, sc, s->real[sc].width + 2.0 * TN__SG_M, s->real[sc].height + 2.0 * TN__SG_M) : 0;
}

static tn__sg_gen_run tn__sg_train_gen(tn__sg_train *s, tn_ctx *ctx, int rec, uint64_t seed)
{
    tn__sg_gen_run r;
    memset(&r, 0, sizeof r);
    r.A = &s->A;
    r.g = s->g;
    r.ctx = ctx;
    r.seed = seed;
    r.rec = rec;
    r.noise = 1.0f;
    r.fine_noise = 1.0f;
    return r;
}

/* The example's scale sc - 1 upsampled to scale sc's grid as generation upsamples (bilinear
   between global positions, clamped at the border), on the window (ox, oy, W, H); zeros at scale 0. */
static void tn__sg_real_base_window(const tn__sg_train *s, int sc, int ox, int oy, int W, int H, float *out)
{
    const tn_image *c = sc > 0 ? &s->real[sc - 1] : NULL;
    int x, y;
    if (!c) {
        memset(out, 0, (size_t)W * H * sizeof(float));
        return;
    }
    for (y = 0; y < H; y++) {
        long iy, y0, y1;
        float ty;
        tn__sg_coord(oy + y, s->A.factor, &iy, &ty);
        y0 = iy < 0 ? 0 : iy >= c->height ? c->height - 1 : iy;
        y1 = iy + 1 < 0 ? 0 : iy + 1 >= c->height ? c->height - 1 : iy + 1;
        for (x = 0; x < W; x++) {
            long ix, x0, x1;
            float tx;
            const float *r0 = c->data + (size_t)y0 * c->width, *r1 = c->data + (size_t)y1 * c->width;
            tn__sg_coord(ox + x, s->A.factor, &ix, &tx);
            x0 = ix < 0 ? 0 : ix >= c->width ? c->width - 1 : ix;
            x1 = ix + 1 < 0 ? 0 : ix + 1 >= c->width ? c->width - 1 : ix + 1;
            out[(size_t)y * W + x] = (1 - ty) * ((1 - tx) * r0[x0] + tx * r0[x1]) + ty * ((1 - tx) * r1[x0] + tx * r1[x1]);
        }
    }
}

static void tn__sg_real_base(const tn__sg_train *s, int sc, float *out)
{
    tn__sg_real_base_window(s, sc, 0, 0, s->real[sc].width, s->real[sc].height, out);
}

/* The 5-point Laplacian at q, rows `stride` floats apart. */
static float tn__sg_lap5(const float *q, int stride) { return q[1] + q[-1] + q[stride] + q[-stride] - 4.0f * q[0]; }

/* The radially binned power spectrum of x (w x h, mean removed, Hann-windowed) into e (bins 1 ..
   TN__SG_SPEC_BINS - 1 of radius round(sqrt((kx s / w)^2 + (ky s / h)^2)), s = (w + h) / 2; bin
   0 unused, an empty bin 0). With g: the gradient of w_loss x the sum over the radii of periods
   of 8 px or more of ln((e + f) / (t + f))^2 where e > t (t: target, f: a hundredth of its mean)
   added into g; returns that loss, or -1 out of memory. Nothing in training sees those periods
   (the generator's field is 11 px, the critic's 15), and the generator drew them too strong
   (the Sahara's undulation at a 128 px period). Only an excess is penalised: the two-sided form,
   which pulled shorter periods up too, drew rows of linear dunes (docs/singan.md). */
static double tn__sg_spec(const float *x, int w, int h, double *e, const double *target, float w_loss, float *g)
{
    size_t n = (size_t)w * h;
    double *cx, *sx, *cy, *sy, *xw, *A, *B, *re, *im, *win, cnt[TN__SG_SPEC_BINS], m = 0, loss = 0, f[TN__SG_SPEC_BINS], lr;
    int *bin, i, j, k, q;
    const double tau = 6.28318530717958647692, sc = 0.5 * (w + h);
    double *buf = (double *)tn__alloc((2 * (size_t)w * w + 2 * (size_t)h * h + 6 * n) * sizeof(double));
    bin = (int *)tn__alloc(n * sizeof(int));
    if (!buf || !bin) {
        TN_FREE(buf);
        TN_FREE(bin);
        return -1;
    }
    cx = buf, sx = cx + (size_t)w * w, cy = sx + (size_t)w * w, sy = cy + (size_t)h * h;
    xw = sy + (size_t)h * h, A = xw + n, B = A + n, re = B + n, im = re + n, win = im + n;
    for (k = 0; k < w; k++)
        for (i = 0; i < w; i++) cx[(size_t)k * w + i] = cos(tau * k * i / w), sx[(size_t)k * w + i] = sin(tau * k * i / w);
    for (k = 0; k < h; k++)
        for (j = 0; j < h; j++) cy[(size_t)k * h + j] = cos(tau * k * j / h), sy[(size_t)k * h + j] = sin(tau * k * j / h);
    for (i = 0; i < (int)n; i++) m += x[i];
    m /= (double)n;
    for (j = 0; j < h; j++)
        for (i = 0; i < w; i++) {
            win[(size_t)j * w + i] = (0.5 - 0.5 * cos(tau * (i + 0.5) / w)) * (0.5 - 0.5 * cos(tau * (j + 0.5) / h));
            xw[(size_t)j * w + i] = win[(size_t)j * w + i] * (x[(size_t)j * w + i] - m);
        }
    /* A = xw Cx^T, B = xw Sx^T; Re = Cy A - Sy B, Im = -(Sy A + Cy B) */
    for (j = 0; j < h; j++)
        for (k = 0; k < w; k++) {
            double a = 0, bb = 0;
            for (i = 0; i < w; i++) a += xw[(size_t)j * w + i] * cx[(size_t)k * w + i], bb += xw[(size_t)j * w + i] * sx[(size_t)k * w + i];
            A[(size_t)j * w + k] = a, B[(size_t)j * w + k] = bb;
        }
    for (q = 0; q < h; q++)
        for (k = 0; k < w; k++) {
            double r = 0, s2 = 0;
            for (j = 0; j < h; j++) {
                double c = cy[(size_t)q * h + j], s1 = sy[(size_t)q * h + j];
                r += c * A[(size_t)j * w + k] - s1 * B[(size_t)j * w + k];
                s2 -= s1 * A[(size_t)j * w + k] + c * B[(size_t)j * w + k];
            }
            re[(size_t)q * w + k] = r, im[(size_t)q * w + k] = s2;
        }
    memset(cnt, 0, sizeof cnt);
    for (k = 0; k < TN__SG_SPEC_BINS; k++) e[k] = 0;
    for (q = 0; q < h; q++)
        for (k = 0; k < w; k++) {
            double fx = (k <= w / 2 ? k : k - w) * sc / w, fy = (q <= h / 2 ? q : q - h) * sc / h;
            int b = (int)floor(sqrt(fx * fx + fy * fy) + 0.5);
            size_t t = (size_t)q * w + k;
            bin[t] = b >= 1 && b < TN__SG_SPEC_BINS ? b : 0;
            if (bin[t]) e[b] += re[t] * re[t] + im[t] * im[t], cnt[b]++;
        }
    for (k = 1; k < TN__SG_SPEC_BINS; k++) e[k] = cnt[k] > 0 ? e[k] / cnt[k] + 1e-12 : 0;
    if (g && target) {
        /* d loss / d xw = Cy^T U Cx - Sy^T U Sx - Sy^T V Cx - Cy^T V Sx, U = f Re, V = f Im */
        int top = (int)(sc / 8); /* radii of periods of 8 px and more */
        double fl = 0; /* the floor: a hundredth of the mean power over those radii */
        for (k = 1; k <= top && k < TN__SG_SPEC_BINS; k++) fl += target[k] / (100.0 * top);
        for (k = 0; k < TN__SG_SPEC_BINS; k++) {
            f[k] = 0;
            if (!cnt[k] || !(target[k] > 0) || k > top) continue;
            lr = log((e[k] + fl) / (target[k] + fl));
            if (lr <= 0) continue; /* an excess only */
            loss += w_loss * lr * lr;
            f[k] = 2.0 * w_loss * lr / (e[k] + fl) * 2.0 / cnt[k];
        }
        for (i = 0; i < (int)n; i++) re[i] *= f[bin[i]], im[i] *= f[bin[i]];
        /* A = U Cx - V Sx, B = -(U Sx + V Cx) (k-space rows, pixel columns): G = Cy^T A + Sy^T B */
        for (q = 0; q < h; q++)
            for (i = 0; i < w; i++) {
                double a = 0, bb = 0;
                for (k = 0; k < w; k++) {
                    double u = re[(size_t)q * w + k], v = im[(size_t)q * w + k], c = cx[(size_t)k * w + i], s1 = sx[(size_t)k * w + i];
                    a += u * c - v * s1;
                    bb -= u * s1 + v * c;
                }
                A[(size_t)q * w + i] = a, B[(size_t)q * w + i] = bb;
            }
        m = 0;
        for (j = 0; j < h; j++)
            for (i = 0; i < w; i++) {
                double gg = 0;
                for (q = 0; q < h; q++) gg += cy[(size_t)q * h + j] * A[(size_t)q * w + i] + sy[(size_t)q * h + j] * B[(size_t)q * w + i];
                xw[(size_t)j * w + i] = gg * win[(size_t)j * w + i];
                m += xw[(size_t)j * w + i];
            }
        m /= (double)n;
        for (i = 0; i < (int)n; i++) g[i] += (float)(xw[i] - m);
    }
    TN_FREE(buf);
    TN_FREE(bin);
    return loss;
}

/* The spectrum loss's target: the mean spectrum of the example's scale 0 over windows of the
   training window's size pw x ph (one: the whole scale, by default). */
static tn_status tn__sg_spec_target(tn__sg_train *s, int pw, int ph)
{
    int W = s->real[0].width, H = s->real[0].height, sx = (W - pw) / 4 > 1 ? (W - pw) / 4 : 1, sy = (H - ph) / 4 > 1 ? (H - ph) / 4 : 1, x0, y0, y, k;
    float *d = (float *)tn__alloc((size_t)pw * ph * sizeof(float));
    double e[TN__SG_SPEC_BINS], n = 0;
    if (!d) return TN_ERR_OUT_OF_MEMORY;
    memset(s->spec_real, 0, sizeof s->spec_real);
    for (y0 = 0; y0 + ph <= H; y0 += sy)
        for (x0 = 0; x0 + pw <= W; x0 += sx) {
            for (y = 0; y < ph; y++) memcpy(d + (size_t)y * pw, s->real[0].data + (size_t)(y0 + y) * W + x0, (size_t)pw * sizeof(float));
            if (tn__sg_spec(d, pw, ph, e, NULL, 0, NULL) < 0) {
                TN_FREE(d);
                return TN_ERR_OUT_OF_MEMORY;
            }
            for (k = 0; k < TN__SG_SPEC_BINS; k++) s->spec_real[k] += e[k];
            n++;
        }
    for (k = 0; k < TN__SG_SPEC_BINS; k++) s->spec_real[k] /= n;
    TN_FREE(d);
    return TN_OK;
}

/* The curvature loss's gradient with respect to the fake output patch out (pw x ph) into s->lapc:
   the patch's Laplacian values are pulled to the example's Laplacian quantiles of the same ranks,
   so the sample gets the example's smooth floors and sharp crests rather than the network's
   Gaussian-like texture. Returns the loss (weighted). */
static double tn__sg_curv_grad(tn__sg_train *s, const float *out, int pw, int ph)
{
    size_t n = 0, r;
    int x, y;
    double loss, gs;
    memset(s->lapc, 0, (size_t)pw * ph * sizeof(float));
    if (!s->nlapq || pw < 3 || ph < 3 || !(s->o.curv_weight > 0)) return 0;
    for (y = 1; y < ph - 1; y++)
        for (x = 1; x < pw - 1; x++) {
            s->lapv[n++] = tn__sg_lap5(out + (size_t)y * pw + x, pw);
        }
    loss = tn__ot_residuals(s->lapv, n, s->lapq, s->nlapq, s->lapi, s->lapr);
    gs = 2.0 * s->o.curv_weight / ((double)n * s->lapms);
    for (r = 0; r < n; r++) { /* in rank order (the permutation the transport leaves in lapi) */
        size_t i = s->lapi[r], xx = 1 + i % (size_t)(pw - 2), yy = 1 + i / (size_t)(pw - 2);
        float g = (float)(gs * s->lapr[i]);
        float *c = s->lapc + yy * (size_t)pw + xx;
        c[0] -= 4.0f * g; /* the Laplacian is its own adjoint */
        c[1] += g;
        c[-1] += g;
        c[pw] += g;
        c[-pw] += g;
    }
    return s->o.curv_weight * loss / ((double)n * s->lapms);
}

/* The heights loss's gradient with respect to the fake output patch out (pw x ph), added to
   s->lapc: its heights are pulled to the example's of the same rank, so that a sample has the
   example's massif or range even where the critic's patches, mostly of lower ground, would let
   it leave it out. Returns the loss (weighted). */
static double tn__sg_height_grad(tn__sg_train *s, const float *out, int pw, int ph)
{
    size_t n = (size_t)pw * ph, i;
    double loss, gs;
    if (!s->nhq || !s->lapr || !(s->o.height_weight > 0)) return 0;
    loss = tn__ot_residuals(out, n, s->hq, s->nhq, s->lapi, s->lapr);
    gs = 2.0 * s->o.height_weight / ((double)n * s->hvar);
    for (i = 0; i < n; i++) s->lapc[i] += (float)(gs * s->lapr[i]);
    return s->o.height_weight * loss / ((double)n * s->hvar);
}

/* Scale sc's bank: TN__SG_BANK fake bases of the whole scale (the coarser generators, frozen
   now, on seeds of the run's seed, the scale and the entry), grown by the context. Each step
   takes its window from one of them instead of running the coarser scales on it anew: those
   passes were 35-40 % of a step at the fine scales (docs/singan.md). */
static tn_status tn__sg_bank_fill(tn__sg_train *s, tn_ctx *ctx, int sc)
{
    const int M = TN__SG_M;
    size_t n;
    int e, tx, ty;
    float *tile = NULL;
    tn_status st = TN_OK;
    TN_FREE(s->bank);
    s->bank_w = s->bank_h = 0;
    if (!tn__sg_banked(s, sc)) return TN_OK;
    s->bank_w = s->real[sc].width + 2 * M;
    s->bank_h = s->real[sc].height + 2 * M;
    n = (size_t)s->bank_w * s->bank_h;
    if (!(s->bank = (float *)tn__alloc(TN__SG_BANK * n * sizeof(float))) ||
        !(tile = (float *)tn__alloc((size_t)TN__SG_BANK_TILE * TN__SG_BANK_TILE * sizeof(float))))
        return TN_ERR_OUT_OF_MEMORY;
    for (e = 0; e < TN__SG_BANK && !st; e++) {
        tn__sg_gen_run r = tn__sg_train_gen(s, ctx, 0, tn__splitmix64(tn_train_seed(s->run) ^ (0x62616e6bULL + 0x9E3779B97F4A7C15ULL * (uint64_t)(sc * TN__SG_BANK + e + 1))));
        /* in tiles, so the coarser scales' activations stay small (a window is the same pixels
           of any larger one) */
        for (ty = 0; ty < s->bank_h && !st; ty += TN__SG_BANK_TILE)
            for (tx = 0; tx < s->bank_w && !st; tx += TN__SG_BANK_TILE) {
                int tw = s->bank_w - tx < TN__SG_BANK_TILE ? s->bank_w - tx : TN__SG_BANK_TILE;
                int th = s->bank_h - ty < TN__SG_BANK_TILE ? s->bank_h - ty : TN__SG_BANK_TILE, y;
                if ((st = tn__sg_base(&r, sc, tx - M, ty - M, tw, th, tile))) break;
                for (y = 0; y < th; y++)
                    memcpy(s->bank + (size_t)e * n + (size_t)(ty + y) * s->bank_w + tx, tile + (size_t)y * tw, (size_t)tw * sizeof(float));
            }
    }
    TN_FREE(tile);
    return st;
}

/* The fake base of a step on the window (ox - M, oy - M, pew, peh) into s->base: from the bank
   entry the step's seed picks, or made anew. */
static tn_status tn__sg_fake_base(tn__sg_train *s, const tn__sg_gen_run *r, int sc, int ox, int oy, int pew, int peh)
{
    const int M = TN__SG_M;
    int y;
    if (!s->bank) return tn__sg_base(r, sc, ox - M, oy - M, pew, peh, s->base);
    for (y = 0; y < peh; y++)
        memcpy(s->base + (size_t)y * pew, s->bank + (size_t)(r->seed % TN__SG_BANK) * s->bank_w * s->bank_h + (size_t)(oy + y) * s->bank_w + ox,
               (size_t)pew * sizeof(float));
    return TN_OK;
}

/* Enters scale sc: progress name, the reconstruction's base and noise amplitude, the starting
   weights (the coarser scale's when the widths match), fresh optimiser state, its deadline.
   resumed: the schedule and weights come from the checkpoint; only derived data is rebuilt. */
static tn_status tn__sg_enter_scale(tn__sg_train *s, tn_ctx *ctx, int sc, int resumed)
{
    float *sch = tn_params_find(s->sched, "singan.sched")->data;
    int W = s->real[sc].width, H = s->real[sc].height, ew = W + 2 * TN__SG_M, eh = H + 2 * TN__SG_M, i, pw, ph;
    tn__sg_gen_run r;
    {
        char stage[48];
        snprintf(stage, sizeof stage, "singan-train scale %d/%d", sc + 1, s->A.scales);
        tn_train_set_stage(s->run, stage);
    }
    s->A.trained = sc; /* the coarser scales are done; the window recursion uses them */
    TN_FREE(s->recbase);
    TN_FREE(s->xrec);
    TN_FREE(s->base);
    TN_FREE(s->xin);
    s->recbase = (float *)tn__alloc((size_t)ew * eh * sizeof(float));
    s->xrec = (float *)tn__alloc((size_t)ew * eh * sizeof(float));
    TN_FREE(s->fake);
    TN_FREE(s->fcond);
    tn__sg_patch_size(s, sc, &pw, &ph);
    s->fcond = (float *)tn__alloc((size_t)2 * pw * ph * sizeof(float));
    s->base = (float *)tn__alloc((size_t)(pw + 2 * TN__SG_M) * (ph + 2 * TN__SG_M) * sizeof(float));
    s->xin = (float *)tn__alloc((size_t)(pw + 2 * TN__SG_M) * (ph + 2 * TN__SG_M) * sizeof(float));
    s->fake = (float *)tn__alloc((size_t)pw * ph * sizeof(float));
    TN_FREE(s->realbase);
    s->realbase = (float *)tn__alloc((size_t)W * H * sizeof(float));
    if (!s->recbase || !s->xrec || !s->base || !s->xin || !s->fake || !s->fcond || !s->realbase) return TN_ERR_OUT_OF_MEMORY;
    tn__sg_real_base(s, sc, s->realbase);
    if (sc == 0 && s->o.spec_weight > 0) { /* the spectrum loss's target */
        tn_status st = tn__sg_spec_target(s, pw, ph);
        if (st) return st;
    }
    TN_FREE(s->hq);
    s->hq = NULL;
    s->nhq = 0;
    s->hvar = 0;
    /* the heights loss's target, on whole windows only (a window of part of the scale need not
       hold the example's heights; scale 0 is whole unless `coarsest` exceeds `patch`) */
    if (sc == 0 && s->o.height_weight > 0 && pw == W && ph == H) {
        size_t k, n = (size_t)W * H;
        double m = 0;
        if (!(s->hq = (float *)tn__alloc(n * sizeof(float)))) return TN_ERR_OUT_OF_MEMORY;
        memcpy(s->hq, s->real[0].data, n * sizeof(float));
        qsort(s->hq, n, sizeof(float), tn__cmp_float);
        for (k = 0; k < n; k++) m += s->hq[k] / (double)n;
        for (k = 0; k < n; k++) s->hvar += ((double)s->hq[k] - m) * ((double)s->hq[k] - m) / (double)n;
        s->hvar += 1e-20;
        s->nhq = n;
    }
    TN_FREE(s->lapq);
    TN_FREE(s->lapc);
    TN_FREE(s->lapv);
    TN_FREE(s->lapr);
    TN_FREE(s->lapi);
    s->nlapq = 0;
    if (W >= 3 && H >= 3) { /* the example's Laplacian quantiles at this scale (the curvature loss's target) */
        const float *e = s->real[sc].data;
        int x, y;
        size_t k = 0;
        s->lapq = (float *)tn__alloc((size_t)(W - 2) * (H - 2) * sizeof(float));
        s->lapc = (float *)tn__alloc((size_t)pw * ph * sizeof(float));
        s->lapv = (float *)tn__alloc((size_t)pw * ph * sizeof(float));
        s->lapr = (float *)tn__alloc((size_t)pw * ph * sizeof(float));
        s->lapi = (uint32_t *)tn__alloc(4 * (size_t)pw * ph * sizeof(uint32_t));
        if (!s->lapq || !s->lapc || !s->lapv || !s->lapr || !s->lapi) return TN_ERR_OUT_OF_MEMORY;
        s->lapms = 0;
        for (y = 1; y < H - 1; y++)
            for (x = 1; x < W - 1; x++) {
                const float *q = e + (size_t)y * W + x;
                s->lapq[k] = tn__sg_lap5(q, W);
                s->lapms += (double)s->lapq[k] * s->lapq[k];
                k++;
            }
        s->nlapq = k;
        s->lapms = s->lapms / (double)k + 1e-20;
        qsort(s->lapq, k, sizeof(float), tn__cmp_float);
    }
    /* the reconstruction's input: the fixed noise map at scale 0; above it the EXAMPLE's coarser
       scale upsampled (teacher forcing), not the coarser generators' reconstruction: that one's
       error (0.1 of the range at the coarse scales, 3x the finest scale's detail) was what the
       fine scales were taught to correct (docs/singan.md) */
    r = tn__sg_train_gen(s, ctx, 1, 0);
    tn__sg_real_base_window(s, sc, -TN__SG_M, -TN__SG_M, ew, eh, s->recbase);
    memcpy(s->xrec, s->recbase, (size_t)ew * eh * sizeof(float));
    tn__sg_add_noise(&r, sc, -TN__SG_M, -TN__SG_M, ew, eh, s->xrec);
    if (!resumed) {
        /* noise_amp x the example's detail RMS at this scale (SinGAN: x the RMSE of the coarser
           reconstruction, which is that detail when the reconstruction is good) */
        s->A.amp[sc] = sc == 0 ? 1.0f : s->o.noise_amp * s->sigma[sc];
        if (sc > 0 && s->A.ch[sc] == s->A.ch[sc - 1]) { /* start from the coarser scale's weights */
            char a[16], b[16];
            int l;
            snprintf(a, sizeof a, "g%d.", sc - 1);
            snprintf(b, sizeof b, "g%d.", sc);
            for (i = 0; i < tn_params_count(s->g); i++) {
                tn_tensor *t = tn_params_get(s->g, i), *u;
                char nm[64];
                if (strncmp(t->name, a, strlen(a)) != 0) continue;
                snprintf(nm, sizeof nm, "%s%s", b, t->name + strlen(a));
                if ((u = tn_params_find(s->g, nm))) memcpy(u->data, t->data, t->numel * sizeof(float));
            }
            /* but the tail at zero: the scale starts as the identity on its input. The coarser
               tail added that scale's detail again (6.5x the finest scale's detail RMS on Mont
               Blanc in 3 minutes: the ripples; docs/singan.md) */
            tn_tensor_fill(tn__param_named(s->g, b, "w", 4), 0.0f);
            tn_tensor_fill(tn__param_named(s->g, b, "b", 4), 0.0f);
            snprintf(a, sizeof a, "d%d.", sc - 1);
            snprintf(b, sizeof b, "d%d.", sc);
            for (l = 0; l < tn_params_count(s->d); l++) {
                tn_tensor *t = tn_params_get(s->d, l), *u;
                char nm[64];
                if (strncmp(t->name, a, strlen(a)) != 0) continue;
                snprintf(nm, sizeof nm, "%s%s", b, t->name + strlen(a));
                if ((u = tn_params_find(s->d, nm))) memcpy(u->data, t->data, t->numel * sizeof(float));
            }
        }
        { /* a fresh Adam: zero moments keep the other scales still (their gradients are zero) */
            tn_optim *os[2];
            int j;
            os[0] = s->og;
            os[1] = s->od;
            for (j = 0; j < 2; j++) {
                for (i = 0; i < os[j]->p->n; i++) {
                    size_t n = os[j]->p->t[i]->numel;
                    if (os[j]->m[i]) memset(os[j]->m[i], 0, n * sizeof(float));
                    if (os[j]->v[i]) memset(os[j]->v[i], 0, n * sizeof(float));
                }
                os[j]->step = 0;
            }
        }
        sch[0] = (float)sc;
        sch[1] = (float)tn_train_iteration(s->run);
        sch[2] = 0; /* this scale's iteration count: set once its speed is measured */
        tn__sg_write_config(&s->A, tn_params_find(s->g, "singan.config")->data);
    }
    return tn__sg_bank_fill(s, ctx, sc);
}

/* A 1 x 1 x h x w tensor holding the window (x0, y0, w, h) of a buffer of width bw. */
static tn_tensor *tn__sg_tensor(tn_ctx *ctx, const float *buf, int bw, int x0, int y0, int w, int h)
{
    tn_tensor *t = tn_tensor_4d(ctx, 1, 1, h, w);
    int y;
    if (t)
        for (y = 0; y < h; y++) memcpy(t->data + (size_t)y * w, buf + (size_t)(y + y0) * bw + x0, (size_t)w * sizeof(float));
    return t;
}

/* Sampling uses the norms' running statistics, and a short run leaves them lagging behind the
   batch statistics of the final weights (momentum 0.1). So when a scale ends its running
   statistics are refreshed by 20 training-mode passes without gradients on random windows of
   the reconstruction's input, every other one with the scale's noise added (the two kinds of
   input of training; no coarser passes needed), from an RNG of their own. */
#define TN__SG_CALIB 20
static tn_status tn__sg_calibrate(tn__sg_train *s, tn_ctx *ctx, int sc)
{
    const int M = TN__SG_M;
    int W = s->real[sc].width, ew = W + 2 * M, pw, ph, pew, peh, k, j;
    tn_rng rng;
    tn__sg_patch_size(s, sc, &pw, &ph);
    pew = pw + 2 * M;
    peh = ph + 2 * M;
    tn_rng_seed(&rng, tn_train_seed(s->run), 0x63616c00ULL + (uint64_t)sc);
    for (k = 0; k < TN__SG_CALIB; k++) {
        int ox = (int)tn_rng_below(&rng, (uint32_t)(W - pw + 1)), oy = (int)tn_rng_below(&rng, (uint32_t)(s->real[sc].height - ph + 1));
        tn_tensor *x;
        tn_ctx_reset(ctx);
        tn_ctx_set_grad(ctx, 0);
        x = tn__sg_tensor(ctx, s->xrec, ew, ox, oy, pew, peh);
        if (x && (k & 1)) {
            tn__sg_gen_run r = tn__sg_train_gen(s, ctx, 0, ((uint64_t)tn_rng_u32(&rng) << 32) | tn_rng_u32(&rng));
            for (j = 0; j < pew * peh; j++) x->data[j] -= sc == 0 ? x->data[j] : 0.0f; /* scale 0: noise only */
            tn__sg_add_noise(&r, sc, ox - M, oy - M, pew, peh, x->data);
        }
        if (!tn__sg_gen(ctx, s->g, sc, s->A.gain[sc], x, 1)) return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : tn__fail(TN_ERR_OUT_OF_MEMORY, "singan: out of memory");
    }
    tn_ctx_set_grad(ctx, 1);
    return TN_OK;
}

/* The discriminator's context: the gradient (central differences, clamped at the buffer's
   border) of the base b (bw x bh) on the window (x0, y0, w, h), x then y, times inv. */
static void tn__sg_cond(const float *b, int bw, int bh, int x0, int y0, int w, int h, float inv, float *out)
{
    int x, y;
    for (y = 0; y < h; y++) {
        int yy = y0 + y, ya = yy > 0 ? yy - 1 : 0, yb = yy + 1 < bh ? yy + 1 : bh - 1;
        for (x = 0; x < w; x++) {
            int xx = x0 + x, xa = xx > 0 ? xx - 1 : 0, xb = xx + 1 < bw ? xx + 1 : bw - 1;
            out[(size_t)y * w + x] = 0.5f * inv * (b[(size_t)yy * bw + xb] - b[(size_t)yy * bw + xa]);
            out[(size_t)w * h + (size_t)y * w + x] = 0.5f * inv * (b[(size_t)yb * bw + xx] - b[(size_t)ya * bw + xx]);
        }
    }
}

/* A step's draw at scale sc, for a pw x ph window: the fake's noise seed and window (ox, oy), the
   real window (rx, ry); then the fake's base and input there (s->base, s->xin, with the margin)
   and the critic's condition (s->fcond). */
static tn_status tn__sg_draw(tn__sg_train *s, tn_ctx *ctx, int sc, int pw, int ph, tn__sg_gen_run *r, int *ox, int *oy, int *rx, int *ry)
{
    const int M = TN__SG_M;
    int W = s->real[sc].width, H = s->real[sc].height, pew = pw + 2 * M, peh = ph + 2 * M;
    uint64_t seed = ((uint64_t)tn_rng_u32(&s->rng) << 32) | tn_rng_u32(&s->rng);
    tn_status st;
    *ox = (int)tn_rng_below(&s->rng, (uint32_t)(W - pw + 1));
    *oy = (int)tn_rng_below(&s->rng, (uint32_t)(H - ph + 1));
    *rx = (int)tn_rng_below(&s->rng, (uint32_t)(W - pw + 1));
    *ry = (int)tn_rng_below(&s->rng, (uint32_t)(H - ph + 1));
    *r = tn__sg_train_gen(s, ctx, 0, seed);
    if ((st = tn__sg_fake_base(s, r, sc, *ox, *oy, pew, peh))) return st;
    memcpy(s->xin, s->base, (size_t)pew * peh * sizeof(float));
    tn__sg_add_noise(r, sc, *ox - M, *oy - M, pew, peh, s->xin);
    tn__sg_cond(s->base, pew, peh, M, M, pw, ph, s->gnorm[sc] > 0 ? 1.0f / s->gnorm[sc] : 0.0f, s->fcond);
    return TN_OK;
}

/* One G step and one D step at scale sc on a random window (the whole scale or a patch): the G
   step first, and the D step on its fake (one generator pass fewer than D first).
   l: D loss, G adversarial loss, reconstruction MSE. */
static tn_status tn__sg_step(tn__sg_train *s, tn_ctx *ctx, int sc, float *l)
{
    const int M = TN__SG_M;
    int W = s->real[sc].width, H = s->real[sc].height, ew = W + 2 * M, pw, ph, pew, peh, ox, oy, rx, ry;
    tn__sg_gen_run r;
    tn_tensor *real, *fake, *rec, *loss, *lg, *lr, *gres;
    int ds;
    tn_status st;
    long it = tn_train_iteration(s->run);
    tn__sg_patch_size(s, sc, &pw, &ph);
    pew = pw + 2 * M;
    peh = ph + 2 * M;
    /* the fake's and the reconstruction's window (ox, oy); the D step's real patch (rx, ry) */
    if ((st = tn__sg_draw(s, ctx, sc, pw, ph, &r, &ox, &oy, &rx, &ry))) return st;
    /* G step: adversarial + reconstruction on the same window */
    tn_ctx_reset(ctx);
    tn_ctx_set_grad(ctx, 1);
    tn_patch_disc_begin(ctx, &s->disc[sc]);
    gres = tn__sg_gen(ctx, s->g, sc, s->A.gain[sc], tn__sg_tensor(ctx, s->xin, pew, 0, 0, pew, peh), 1);
    /* D judges the residual in units of the example's detail RMS sigma beside the base's
       gradient; the reconstruction's MSE is in units of sigma^2 too, so the two terms weigh the
       same at every scale */
    {
        tn_tensor *cond = tn_tensor_4d(ctx, 1, 2, ph, pw);
        if (cond) memcpy(cond->data, s->fcond, (size_t)2 * pw * ph * sizeof(float));
        lg = tn_scale_shift(ctx, tn_hinge_g_loss(ctx, tn_patch_disc_score(ctx, &s->disc[sc], tn_concat(ctx, tn_scale_shift(ctx, gres, 1.0f / s->sigma[sc], 0.0f), cond, 1))),
                            s->o.adv_weight, 0.0f);
    }
    rec = tn_add(ctx, tn__sg_gen(ctx, s->g, sc, s->A.gain[sc], tn__sg_tensor(ctx, s->xrec, ew, ox, oy, pew, peh), 1),
                 tn__sg_tensor(ctx, s->recbase, ew, ox + M, oy + M, pw, ph));
    lr = tn_mse_loss(ctx, rec, tn__sg_tensor(ctx, s->real[sc].data, W, ox, oy, pw, ph));
    loss = tn_add(ctx, lg, tn_scale_shift(ctx, lr, s->o.rec_weight / (s->sigma[sc] * s->sigma[sc]), 0.0f));
    if (gres && ((s->o.curv_weight > 0 && s->nlapq) || (sc == 0 && (s->o.spec_weight > 0 || s->nhq)))) { /* the curvature, spectrum and heights losses, as sum(fake x their gradient) */
        tn_tensor *c = tn_tensor_4d(ctx, 1, 1, ph, pw);
        int y, x;
        for (y = 0; y < ph; y++)
            for (x = 0; x < pw; x++) s->fake[(size_t)y * pw + x] = s->base[(size_t)(y + M) * pew + x + M] + gres->data[(size_t)y * pw + x];
        tn__sg_curv_grad(s, s->fake, pw, ph);
        if (sc == 0) tn__sg_height_grad(s, s->fake, pw, ph);
        if (sc == 0 && s->o.spec_weight > 0) {
            double e[TN__SG_SPEC_BINS];
            if (tn__sg_spec(s->fake, pw, ph, e, s->spec_real, s->o.spec_weight, s->lapc) < 0) return tn__fail(TN_ERR_OUT_OF_MEMORY, "singan: out of memory");
        }
        if (c) memcpy(c->data, s->lapc, (size_t)pw * ph * sizeof(float));
        loss = tn_add(ctx, loss, tn_sum(ctx, tn_mul(ctx, gres, c)));
    }
    if (!loss) return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : tn__fail(TN_ERR_OUT_OF_MEMORY, "singan: out of memory");
    tn_params_zero_grad(s->g);
    if ((st = tn_backward(ctx, loss))) return st;
    tn_optim_step(s->og);
    l[1] = lg->data[0];
    l[2] = lr->data[0];
    memcpy(s->fake, gres->data, (size_t)pw * ph * sizeof(float));
    for (ds = 0; ds < s->o.d_steps; ds++) {
        /* D steps: the first on the G step's fake (a constant), the others on new fakes (new noise
           and windows) of the updated generator, each against a new real window */
        if (ds > 0) {
            if ((st = tn__sg_draw(s, ctx, sc, pw, ph, &r, &ox, &oy, &rx, &ry))) return st;
            tn_ctx_reset(ctx);
            tn_ctx_set_grad(ctx, 0);
            if (!(gres = tn__sg_gen(ctx, s->g, sc, s->A.gain[sc], tn__sg_tensor(ctx, s->xin, pew, 0, 0, pew, peh), 1)))
                return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : tn__fail(TN_ERR_OUT_OF_MEMORY, "singan: out of memory");
            memcpy(s->fake, gres->data, (size_t)pw * ph * sizeof(float));
            tn_ctx_set_grad(ctx, 1);
        }
        tn_ctx_reset(ctx);
        fake = tn_tensor_4d(ctx, 1, 3, ph, pw);
        real = tn_tensor_4d(ctx, 1, 3, ph, pw);
        if (real && fake) { /* the detail in units of its RMS, and the base's gradient */
            int y, x;
            size_t n1 = (size_t)pw * ph;
            for (y = 0; y < ph; y++)
                for (x = 0; x < pw; x++) {
                    size_t k = (size_t)y * pw + x, q = (size_t)(y + ry) * W + x + rx;
                    real->data[k] = (s->real[sc].data[q] - s->realbase[q]) / s->sigma[sc];
                    fake->data[k] = s->fake[k] / s->sigma[sc];
                }
            tn__sg_cond(s->realbase, W, H, rx, ry, pw, ph, s->gnorm[sc] > 0 ? 1.0f / s->gnorm[sc] : 0.0f, real->data + n1);
            memcpy(fake->data + n1, s->fcond, 2 * n1 * sizeof(float));
        }
        tn_patch_disc_begin(ctx, &s->disc[sc]);
        loss = tn_hinge_d_loss(ctx, tn_patch_disc_score(ctx, &s->disc[sc], real), tn_patch_disc_score(ctx, &s->disc[sc], fake));
        if (!loss) return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : tn__fail(TN_ERR_OUT_OF_MEMORY, "singan: out of memory");
        tn_params_zero_grad(s->d);
        if ((st = tn_backward(ctx, loss))) return st;
        tn_optim_step(s->od);
        l[0] = loss->data[0];
    }
    if (!isfinite(l[0]) || !isfinite(l[1]) || !isfinite(l[2]) || fabsf(l[0]) > 1e6f || fabsf(l[1]) > 1e6f)
        return tn__fail(TN_ERR_NUMERIC, "singan: training diverged at iteration %ld, scale %d (D loss %g, G loss %g, reconstruction %g)", it,
                        sc, (double)l[0], (double)l[1], (double)l[2]);
    return TN_OK;
}

/* The example in network units, channel 0; its range. */
static tn_status tn__sg_check_dem(const tn_image *dem, int coarsest, float *lo, float *hi)
{
    size_t i, n;
    if (!dem || !dem->data || dem->width < 1 || dem->height < 1 || dem->channels < 1) return tn__fail(TN_ERR_EMPTY, "singan: empty DEM");
    n = (size_t)dem->width * dem->height;
    *lo = FLT_MAX;
    *hi = -FLT_MAX;
    for (i = 0; i < n; i++) {
        float v = dem->data[i * dem->channels];
        if (!isfinite(v)) return tn__fail(TN_ERR_NUMERIC, "singan: the DEM has NaN/Inf heights (pixel %zu, %zu)", i % dem->width, i / dem->width);
        if (v < *lo) *lo = v;
        if (v > *hi) *hi = v;
    }
    if (dem->width < coarsest || dem->height < coarsest)
        return tn__fail(TN_ERR_INVALID_ARG, "singan: the DEM (%d x %d) is smaller than the coarsest scale (%d px); give a larger DEM or a smaller coarsest side",
                        dem->width, dem->height, coarsest);
    if (!(*hi - *lo > 1e-6f * (fabsf(*lo) + fabsf(*hi))) || !(*hi - *lo > 0))
        return tn__fail(TN_ERR_INVALID_ARG, "singan: the DEM is constant (all heights %g): nothing to learn", (double)*lo);
    return TN_OK;
}

/* The settings a checkpoint keeps (a resumed run continues with the ones it started with). */
#define TN__SG_SETTINGS(X)                                                                                          \
    X("iters", iters, int, 1, 1e9) X("patch", patch, int, -1, 1e9) X("lr", lr, float, 1e-9, 10)                     \
    X("rec_weight", rec_weight, float, -1e6, 1e6) X("noise_amp", noise_amp, float, 0, 100) X("adv_weight", adv_weight, float, 0, 1e6) \
    X("d_steps", d_steps, int, 1, 100)

static tn_status tn__sg_set_meta(tn__sg_train *s, uint64_t digest)
{
    tn_status st = tn_train_set_example(s->run, digest);
#define TN__SG_PUT(key, field, type, lo, hi) \
    if (!st) st = tn_train_set_meta_number(s->run, key, (double)s->o.field);
    TN__SG_SETTINGS(TN__SG_PUT)
#undef TN__SG_PUT
    return st;
}

static tn_status tn__sg_get_meta(tn__sg_train *s, uint64_t digest)
{
    double d = 0;
    tn_status st = tn_train_check_example(s->run, digest);
#define TN__SG_GET(key, field, type, lo, hi) \
    if (!st && !(st = tn_train_meta_number(s->run, key, lo, hi, &d))) s->o.field = (type)d;
    TN__SG_SETTINGS(TN__SG_GET)
#undef TN__SG_GET
    return st;
}
#undef TN__SG_SETTINGS

/* The networks of a run: G (the model's layout), one discriminator per scale, the schedule. */
static tn_status tn__sg_train_nets(tn__sg_train *s)
{
    tn_optim_opts oo;
    int s_, n = TN__SG_SCHED;
    tn_status st;
    if ((st = tn__sg_model_params(&s->A, &s->rng, &s->g))) return st;
    if (!(s->d = tn_params_create()) || !(s->sched = tn_params_create())) return TN_ERR_OUT_OF_MEMORY;
    for (s_ = 0; s_ < s->A.scales; s_++) {
        char pre[16];
        snprintf(pre, sizeof pre, "d%d.", s_);
        if ((st = tn_patch_disc_add(s->d, pre, 3, s->A.ch[s_], s->A.disc_layers, 3, &s->rng, &s->disc[s_]))) return st;
    }
    if (!tn_params_add_buffer(s->sched, "singan.sched", 1, &n)) return TN_ERR_OUT_OF_MEMORY;
    memset(&oo, 0, sizeof oo);
    oo.lr = s->o.lr;
    oo.beta1 = 0.5f;
    oo.beta2 = 0.999f;
    if (!(s->og = tn_optim_create(s->g, &oo)) || !(s->od = tn_optim_create(s->d, &oo))) return TN_ERR_INVALID_ARG;
    return TN_OK;
}

static tn_status tn__sg_file_matches(const tn_params *f, const tn__sg_arch *A, const char *name);

TN_API tn_status tn_singan_train(tn_singan *model, const tn_image *dem, const tn_singan_opts *opts_in, tn_singan_stats *stats)
{
    tn__sg_train s;
    tn_ctx *ctx = NULL;
    tn_image one = {0, 0, 0, NULL};
    const tn_image *d1 = dem;
    float lo = 0, hi = 0, hist[50][3], rec_first = NAN, dq_step = 0;
    float *sch;
    double fin_sec = 0;
    long fin_it = 0;
    int nh = 0, sc = 0, i, done_all = 0;
    size_t n;
    uint64_t digest, seed;
    tn_status st;
    TN_ASSERT(model);
    memset(&s, 0, sizeof s);
    if (opts_in) s.o = *opts_in;
    tn_singan_defaults(&s.o);
    if ((st = tn__sg_validate(&s.o))) return st;
    if ((st = tn__sg_check_dem(dem, s.o.coarsest, &lo, &hi))) return st;
    if (dem->channels > 1) { /* channel 0 only, as every DEM function */
        if ((st = tn_image_create(&one, dem->width, dem->height, 1))) return st;
        for (n = 0; n < (size_t)dem->width * dem->height; n++) one.data[n] = dem->data[n * dem->channels];
        d1 = &one;
    }
    digest = tn_image_digest(d1);
    if ((st = tn__train_without_steps(&one, &d1, s.o.dequantize, &dq_step))) goto done;
    seed = s.o.train.seed;
    if ((st = tn_train_create(&s.run, "singan", "singan-train", &s.o.train))) goto done;
    if (s.o.train.resume) { /* the checkpoint's seed and architecture win */
        tn_params *ck;
        tn_tensor *cfg;
        const char *sd;
        if ((st = tn_train_open_checkpoint(s.run, &ck))) goto done;
        if (!(cfg = tn_params_find(ck, "singan.config")) || cfg->numel != TN__SG_CONFIG) {
            if (cfg && cfg->numel == TN__SG_CONFIG1) {
                st = tn__fail(TN_ERR_FORMAT, "%s: a singan checkpoint of format 1 (before issue 31's output gain): train again", s.o.train.checkpoint);
                goto done;
            }
            st = tn__fail(TN_ERR_FORMAT, "%s: not a singan checkpoint", s.o.train.checkpoint);
            goto done;
        }
        if ((st = tn__sg_read_config(cfg->data, &s.A, s.o.train.checkpoint))) goto done;
        if ((st = tn__sg_file_matches(ck, &s.A, s.o.train.checkpoint))) goto done; /* before the config sizes anything */
        if ((st = tn__sg_get_meta(&s, digest))) goto done;
        if (s.A.width != d1->width || s.A.height != d1->height) {
            st = tn__fail(TN_ERR_SHAPE, "%s: the checkpoint's example is %d x %d, this one %d x %d", s.o.train.checkpoint, s.A.width, s.A.height,
                          d1->width, d1->height);
            goto done;
        }
        sd = tn_params_meta(ck, "seed");
        if (!sd || !tn__parse_hex64(sd, strlen(sd), &seed)) {
            st = tn__fail(TN_ERR_CORRUPT, "%s: the checkpoint names no seed", s.o.train.checkpoint);
            goto done;
        }
    } else {
        int mn = d1->width < d1->height ? d1->width : d1->height;
        s.A.scales = 1 + (int)floor(log((double)mn / s.o.coarsest) / log(1.0 / s.o.factor) + 0.5);
        if (s.A.scales > TN_SINGAN_MAX_SCALES) s.A.scales = TN_SINGAN_MAX_SCALES;
        if (s.A.scales < 1) s.A.scales = 1;
        s.A.width = d1->width;
        s.A.height = d1->height;
        s.A.factor = s.o.factor;
        s.A.offset = 0.5f * (lo + hi);
        s.A.range = 0.5f * (hi - lo);
        s.A.trained = 0;
        s.A.disc_layers = s.o.disc_layers;
        for (i = 0; i < s.A.scales; i++) {
            long c = (long)s.o.channels << (i / 4);
            s.A.ch[i] = (int)(c < s.o.max_channels ? c : s.o.max_channels);
        }
        if (s.o.iters == 0) s.o.iters = s.o.train.max_iters > 0 ? (int)((s.o.train.max_iters + s.A.scales - 1) / s.A.scales) : 2000;
    }
    s.budget = s.o.train.minutes * 60.0;
    for (i = 0; i < s.A.scales; i++) { /* the example pyramid in network units */
        tn_image t = {0, 0, 0, NULL};
        int w = tn__sg_size(s.A.width, s.A.factor, s.A.scales - 1 - i), h = tn__sg_size(s.A.height, s.A.factor, s.A.scales - 1 - i);
        size_t k;
        if (w == s.A.width && h == s.A.height) st = tn_image_copy(&t, d1);
        else st = tn_image_resize(&t, d1, w, h, TN_RESIZE_AREA);
        if (st) goto done;
        for (k = 0; k < (size_t)w * h; k++) t.data[k] = (t.data[k] - s.A.offset) / s.A.range;
        s.real[i] = t;
    }
    tn_rng_seed(&s.rng, seed, 0x73696e67ULL);
    for (i = 0; i < s.A.scales; i++) { /* the detail each scale adds to the coarser one: its RMS */
        size_t k, nn = (size_t)s.real[i].width * s.real[i].height;
        float *b = (float *)tn__alloc(nn * sizeof(float));
        double se = 0, peak = 0;
        if (!b) {
            st = tn__fail(TN_ERR_OUT_OF_MEMORY, "singan: out of memory");
            goto done;
        }
        tn__sg_real_base(&s, i, b);
        for (k = 0; k < nn; k++) {
            double d = (double)s.real[i].data[k] - b[k];
            se += d * d;
            if (fabs(d) > peak) peak = fabs(d);
        }
        s.sigma[i] = (float)sqrt(se / (double)nn + 1e-12);
        if (!s.o.train.resume) s.A.gain[i] = i == 0 ? TN__SG_GAIN0 : tn__sg_gain(s.sigma[i], (float)peak);
        { /* the RMS of the base's gradient (0 at the coarsest scale, whose base is zero) */
            float *gxy = (float *)tn__alloc(2 * nn * sizeof(float));
            double sg = 0;
            if (!gxy) {
                TN_FREE(b);
                st = tn__fail(TN_ERR_OUT_OF_MEMORY, "singan: out of memory");
                goto done;
            }
            tn__sg_cond(b, s.real[i].width, s.real[i].height, 0, 0, s.real[i].width, s.real[i].height, 1.0f, gxy);
            for (k = 0; k < 2 * nn; k++) sg += (double)gxy[k] * gxy[k];
            s.gnorm[i] = (float)sqrt(sg / (double)nn);
            if (!(s.gnorm[i] > 1e-9f)) s.gnorm[i] = 0;
            TN_FREE(gxy);
        }
        TN_FREE(b);
    }
    if ((st = tn__sg_train_nets(&s))) goto done;
    memcpy(tn_params_find(s.g, "singan.layout")->data, s.real[s.A.scales - 1].data, (size_t)s.A.width * s.A.height * sizeof(float));
    if ((st = tn_train_add_net(s.run, "g", s.g, s.og)) || (st = tn_train_add_net(s.run, "d", s.d, s.od)) ||
        (st = tn_train_add_params(s.run, "", s.sched)) || (st = tn_train_add_rng(s.run, "main", &s.rng)))
        goto done;
    if ((st = tn__sg_set_meta(&s, digest))) goto done;
    if (s.o.train.resume && (st = tn_train_restore(s.run))) goto done;
    if (!(ctx = tn_ctx_create())) {
        st = tn__fail(TN_ERR_OUT_OF_MEMORY, "singan: out of memory");
        goto done;
    }
    sch = tn_params_find(s.sched, "singan.sched")->data;
    if (s.o.train.resume) {
        sc = (int)sch[0];
        if (!(sch[0] >= 0 && sch[0] < s.A.scales && (sc == s.A.trained || sc + 1 == s.A.trained))) {
            st = tn__fail(TN_ERR_CORRUPT, "%s: damaged singan schedule", s.o.train.checkpoint);
            goto done;
        }
        st = tn__sg_enter_scale(&s, ctx, sc, 1);
    } else
        st = tn__sg_enter_scale(&s, ctx, 0, 0);
    if (st) goto done;
    while (tn_train_next(s.run)) {
        float l[3];
        long it = tn_train_iteration(s.run);
        tn_status e;
        if (sch[2] == 0 && it - (long)sch[1] == 1) sch[3] = (float)tn_train_seconds(s.run); /* after the warm-up iteration */
        if (sch[2] == 0 && it - (long)sch[1] == 3) {
            /* equal counts (x weights) for this and the finer scales at this speed, after the
               fixed cost of each scale change (~5 iterations: calibration, reconstruction);
               and a deadline at 1.25 x this scale's share, so a slow spell here cannot starve
               the finer scales */
            double per = (tn_train_seconds(s.run) - sch[3]) / 2.0, need = 0, fixed = 0, nit, rem = s.budget - tn_train_seconds(s.run);
            int k;
            for (k = sc; k < s.A.scales; k++) {
                double pk = per * tn__sg_cost(&s, k) / tn__sg_cost(&s, sc);
                need += pk * tn__sg_weight(&s, k);
                fixed += 5.0 * pk + (k > sc ? per * tn__sg_bank_cost(&s, k) / tn__sg_cost(&s, sc) : 0);
            }
            nit = (rem - fixed) / need * tn__sg_weight(&s, sc) + 3;
            sch[2] = (float)(nit < 3 ? 3 : nit > s.o.iters ? s.o.iters : floor(nit));
            sch[4] = (float)(tn_train_seconds(s.run) + 1.25 * (nit - 3) * per);
        }
        if (it - (long)sch[1] >= s.o.iters || (sch[2] > 0 && it - (long)sch[1] >= (long)sch[2]) ||
            (sch[2] > 0 && it - (long)sch[1] > 3 && tn_train_seconds(s.run) > sch[4])) { /* this scale is done */
            sch[5 + sc] = (float)(it - (long)sch[1]);
            if (sc == s.A.scales - 1) {
                done_all = 1;
                break;
            }
            nh = 0;
            rec_first = NAN;
            if ((e = tn__sg_calibrate(&s, ctx, sc)) || (e = tn__sg_enter_scale(&s, ctx, ++sc, 0))) {
                tn_train_fail(s.run, e);
                break;
            }
        }
        if (sc == s.A.scales - 1 && !fin_it) fin_sec = tn_train_seconds(s.run);
        if ((e = tn__sg_step(&s, ctx, sc, l))) {
            tn_train_fail(s.run, e);
            break;
        }
        if (sc == s.A.scales - 1) fin_it++;
        if (nh == 0) rec_first = l[2];
        memcpy(hist[nh % 50], l, sizeof l);
        nh++;
    }
    if (!done_all) sch[5 + sc] = (float)(tn_train_iteration(s.run) - (long)sch[1]);
    else { /* the last scale ended before the budget: the run is done, say 100 % (issue 34) */
        char stage[48];
        snprintf(stage, sizeof stage, "singan-train scale %d/%d", sc + 1, s.A.scales);
        (void)tn__progress(stage, 1.0);
    }
    s.A.trained = sc + 1;
    tn__sg_write_config(&s.A, tn_params_find(s.g, "singan.config")->data);
    st = tn_train_finish(s.run);
    if (!st) st = tn__sg_calibrate(&s, ctx, sc); /* after the final checkpoint: a resumed run calibrates again */
    if (stats) {
        int k, m = nh < 50 ? nh : 50;
        long it = tn_train_iteration(s.run), it0 = tn_train_start_iteration(s.run);
        memset(stats, 0, sizeof *stats);
        stats->iterations = it;
        stats->resumed_from = s.o.train.resume ? it0 : 0;
        stats->seconds = tn_train_seconds(s.run);
        stats->seconds_per_iter = it > it0 ? (tn_train_seconds(s.run) - tn_train_start_seconds(s.run)) / (double)(it - it0) : 0.0;
        stats->seconds_per_iter_finest = fin_it ? (tn_train_seconds(s.run) - fin_sec) / (double)fin_it : 0.0;
        stats->scales = s.A.scales;
        stats->trained = s.A.trained;
        for (k = 0; k < s.A.scales; k++) stats->scale_iters[k] = (long)sch[5 + k];
        for (k = 0; k < m; k++) {
            stats->loss_d += hist[k][0] / (float)m;
            stats->loss_g += hist[k][1] / (float)m;
            stats->loss_rec += hist[k][2] / (float)m;
        }
        stats->loss_rec_first = rec_first;
        stats->checkpoints = tn_train_checkpoints(s.run);
        stats->dequantized = dq_step;
    }
    if (!st) st = tn__train_stamp(s.g, "singan", TN__SG_FORMAT, s.run, digest, d1->width, d1->height, 1);
    if (!st) {
        memset(model, 0, sizeof *model);
        model->scales = s.A.scales;
        model->trained = s.A.trained;
        model->width = s.A.width;
        model->height = s.A.height;
        model->factor = s.A.factor;
        model->offset = s.A.offset;
        model->range = s.A.range;
        memcpy(model->amp, s.A.amp, sizeof model->amp);
        memcpy(model->channels, s.A.ch, sizeof model->channels);
        model->iterations = tn_train_iteration(s.run);
        model->train_seconds = tn_train_seconds(s.run);
        model->weights = s.g;
        s.g = NULL; /* handed over; the optimiser still points at it but is only freed */
    }
done:
    tn_ctx_free(ctx);
    tn_image_free(&one);
    tn__sg_train_free(&s);
    return st;
}

/* ---- model files ---- */

TN_API void tn_singan_free(tn_singan *model)
{
    if (!model) return;
    tn_params_free(model->weights);
    memset(model, 0, sizeof *model);
}

/* The model's fields as an arch (and a check that they match its weights' config). */
static tn_status tn__sg_arch_of(const tn_singan *m, tn__sg_arch *A)
{
    const tn_tensor *cfg;
    if (!m || !m->weights || !(cfg = tn_params_find(m->weights, "singan.config")) || cfg->numel != TN__SG_CONFIG)
        return tn__fail(TN_ERR_INVALID_ARG, "singan: not a trained or loaded model");
    return tn__sg_read_config(cfg->data, A, "singan model");
}

TN_API tn_status tn_singan_save(const char *path, const tn_singan *model)
{
    tn__sg_arch A;
    tn_status st;
    if ((st = tn__sg_arch_of(model, &A))) return st;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "singan save: empty path");
    return tn_params_save(path, model->weights);
}

/* Whether a model file holds the generators its config names, checked on the file's own tensors
   before the model is allocated (each scale's convolutions grow with its width squared). */
static tn_status tn__sg_file_matches(const tn_params *f, const tn__sg_arch *A, const char *name)
{
    int s, l, ws[4];
    char pre[16], tname[40];
    for (s = 0; s < A->scales; s++)
        for (l = 0; l < 5; l++) {
            ws[0] = l == 4 ? 1 : A->ch[s];
            ws[1] = l == 0 ? 1 : A->ch[s];
            ws[2] = ws[3] = 3;
            snprintf(pre, sizeof pre, "g%d.", s);
            if (!tn__params_has(f, tn__param_name(tname, sizeof tname, pre, "w", l), 4, ws))
                return tn__fail(TN_ERR_CORRUPT, "%s: the singan config names %d scales, scale %d of width %d; the file's generator differs", name,
                                A->scales, s, A->ch[s]);
        }
    return TN_OK;
}

TN_API tn_status tn_singan_load(tn_singan *model, const char *path)
{
    tn_params *f = NULL, *w = NULL;
    tn_tensor *cfg = NULL;
    tn__sg_arch A;
    tn_singan m;
    int fmt;
    tn_status st;
    TN_ASSERT(model);
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "singan load: empty path");
    if ((st = tn__model_open(&f, path, "singan", TN__SG_FORMAT, NULL))) return st;
    cfg = tn_params_find(f, "singan.config");
    fmt = cfg && cfg->numel == TN__SG_CONFIG1 ? 1 : tn_params_meta(f, "format") ? atoi(tn_params_meta(f, "format")) : TN__SG_FORMAT;
    if (fmt >= 1 && fmt < TN__SG_FORMAT)
        st = tn__fail(TN_ERR_FORMAT, "%s: a singan model of format %d (before issue 31's %s): train it again", path, fmt, tn__sg_format_why[fmt]);
    else if (!cfg || cfg->numel != TN__SG_CONFIG)
        st = tn__fail(TN_ERR_FORMAT, "%s: not a singan model (no singan.config)", path);
    if (!st) st = tn__sg_read_config(cfg->data, &A, path);
    if (!st) st = tn__sg_file_matches(f, &A, path);
    if (!st) st = tn__sg_model_params(&A, NULL, &w);
    if (!st) st = tn__params_assign(w, f, path);
    if (!st) st = tn__model_check_finite(w, path);
    if (st) {
        tn_params_free(f);
        tn_params_free(w);
        return st;
    }
    memset(&m, 0, sizeof m);
    m.scales = A.scales;
    m.trained = A.trained;
    m.width = A.width;
    m.height = A.height;
    m.factor = A.factor;
    m.offset = A.offset;
    m.range = A.range;
    memcpy(m.amp, A.amp, sizeof m.amp);
    memcpy(m.channels, A.ch, sizeof m.channels);
    tn__model_training(f, path, &m.iterations, &m.train_seconds);
    tn_params_free(f);
    m.weights = w;
    *model = m;
    return TN_OK;
}

/* ---- sampling, refinement, upscaling ---- */

/* tn_singan_gen_opts.fine_noise for a free sample (`sample` 1) or anything else. A free sample's
   gate scales the finest generator's detail to the example's RMS, noise it passed on included. */
#define TN__SG_FINE_NOISE 0.7f
static float tn__sg_fine_noise(const tn_singan_gen_opts *o, int sample)
{
    if (o->fine_noise != 0) return o->fine_noise < 0 ? 0.0f : o->fine_noise;
    return sample && !o->layout && o->gate ? TN__SG_FINE_NOISE : 1.0f;
}

/* Resolves opts into *o and the run *r; sample: 1 for tn_singan_sample and tn_singan_prepare, 0 for
   refinement and upscaling (tn__sg_fine_noise). */
static tn_status tn__sg_gen_prepare(const tn_singan *model, const tn_singan_gen_opts *opts, int sample, tn__sg_arch *A,
                                    tn_singan_gen_opts *o, tn__sg_gen_run *r)
{
    tn_status st;
    memset(o, 0, sizeof *o);
    if (opts) *o = *opts;
    tn_singan_gen_defaults(o);
    if ((st = tn__sg_arch_of(model, A))) return st;
    if (!isfinite(o->noise) || o->noise > 100 || !(o->fine_noise <= 100) || o->tile > 4096 || o->layout < 0 || o->layout > 1 || !(o->layout_noise <= 100) ||
        o->layout_scale < 0 || o->layout_scale > TN_SINGAN_MAX_SCALES || !(o->layout_warp <= 4096) || !(o->layout_smooth > 0 && o->layout_smooth <= 4096) ||
        o->layout_turn > 2 || o->layout_blocks < 0 || o->layout_blocks > 64 || o->gate > 1)
        return tn__fail(TN_ERR_INVALID_ARG, "singan: bad generation option (noise %g <= 100, fine noise %g <= 100, tile %d <= 4096, layout %d 0 or 1, "
                        "layout noise %g <= 100, layout scale %d, layout warp %g <= 4096 px, layout smooth %g in (0, 4096] px, layout turn %d 0..2, "
                        "layout blocks %d in 0..64, gate %d 0 or 1)",
                        (double)o->noise, (double)o->fine_noise, o->tile, o->layout, (double)o->layout_noise, o->layout_scale, (double)o->layout_warp, (double)o->layout_smooth,
                        o->layout_turn, o->layout_blocks, o->gate);
    memset(r, 0, sizeof *r);
    r->A = A;
    r->g = model->weights;
    r->seed = o->seed;
    r->noise = o->noise;
    r->fine_noise = tn__sg_fine_noise(o, sample);
    return TN_OK;
}

/* The displacement d at x of an n px side, faded towards the border (tn__sg_warp). */
static float tn__sg_warp_fade(float d, int x, int n, float amp)
{
    float m = 3 * amp, e = (float)(x < n - 1 - x ? x : n - 1 - x), f = e < m ? e / m : 1;
    d = d > 2.5f * amp ? 2.5f * amp : d < -2.5f * amp ? -2.5f * amp : d;
    d *= f;
    return x + d < 0 ? -(float)x : x + d > n - 1 ? (float)(n - 1 - x) : d;
}

/* Bends map by a random smooth warp: each pixel takes the map at itself plus a displacement of
   Gaussian-blurred noise (sigma `smooth` px), scaled to RMS `amp` px. Towards the border the
   displacement across it fades (within 3 amp, capped at 2.5 amp), so the warp never reaches
   outside: a mirrored read there folded the map into a straight crease along the border. */
TN__INTERNAL tn_status tn__sg_warp(tn_image *map, float amp, float smooth, uint64_t seed)
{
    tn_image d = {0, 0, 0, NULL}, src = {0, 0, 0, NULL};
    size_t n = (size_t)map->width * map->height, i;
    double rms[2] = {0, 0};
    int x, y, c;
    tn_rng rng;
    tn_status st;
    if (amp <= 0) return TN_OK;
    if ((st = tn_image_create(&d, map->width, map->height, 2)) || (st = tn_image_create(&src, map->width, map->height, 1))) goto done;
    tn_rng_seed(&rng, seed, 0x77617270ULL);
    for (i = 0; i < 2 * n; i++) d.data[i] = tn_rng_normal(&rng);
    if ((st = tn_image_blur(&d, &d, smooth))) goto done;
    for (i = 0; i < 2 * n; i++) rms[i & 1] += (double)d.data[i] * d.data[i];
    for (c = 0; c < 2; c++) rms[c] = rms[c] > 0 ? amp / sqrt(rms[c] / (double)n) : 0;
    memcpy(src.data, map->data, n * sizeof(float));
    for (y = 0; y < map->height; y++)
        for (x = 0; x < map->width; x++) {
            const float *v = &TN_PIXEL(&d, x, y, 0);
            float sx = (float)x + tn__sg_warp_fade((float)rms[0] * v[0], x, map->width, amp);
            float sy = (float)y + tn__sg_warp_fade((float)rms[1] * v[1], y, map->height, amp);
            TN_PIXEL(map, x, y, 0) = tn__sample_bilinear(&src, sx, sy, 0);
        }
done:
    tn_image_free(&d);
    tn_image_free(&src);
    return st;
}

/* *map becomes one of its 8 quarter turns and mirror images: bit 0 of orient swaps x and y (its
   width becomes its height), bit 1 mirrors x and bit 2 y of the result. Exact: no resampling. */
static tn_status tn__sg_turn(tn_image *map, int orient)
{
    tn_image out = {0, 0, 0, NULL};
    int sw = orient & 1, w = sw ? map->height : map->width, h = sw ? map->width : map->height, x, y;
    tn_status st = tn_image_create(&out, w, h, 1);
    if (st) return st;
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++) {
            int u = orient & 2 ? w - 1 - x : x, v = orient & 4 ? h - 1 - y : y;
            TN_PIXEL(&out, x, y, 0) = sw ? TN_PIXEL(map, v, u, 0) : TN_PIXEL(map, u, v, 0);
        }
    tn_image_free(map);
    *map = out;
    return TN_OK;
}

/* A value and its pixel: the gate ranks pixels by slope, the layout by height (ties by pixel). */
typedef struct tn__sg_ranked {
    float v;
    int i;
} tn__sg_ranked;

static int tn__sg_cmp_ranked(const void *a, const void *b)
{
    const tn__sg_ranked *x = (const tn__sg_ranked *)a, *y = (const tn__sg_ranked *)b;
    return x->v < y->v ? -1 : x->v > y->v ? 1 : x->i - y->i;
}

/* Ranks the interior pixels of b (W x H) by slope into rk; returns their count. */
static int tn__sg_rank_slopes(const float *b, int W, int H, tn__sg_ranked *rk)
{
    int x, y, n = 0;
    for (y = 1; y + 1 < H; y++)
        for (x = 1; x + 1 < W; x++) {
            rk[n].v = tn__sg_slope(b + (size_t)y * W + x, W);
            rk[n++].i = y * W + x;
        }
    qsort(rk, (size_t)n, sizeof *rk, tn__sg_cmp_ranked);
    return n;
}

/* The mean slope of each of TN__SG_GATE_BINS equal-count bins of rk[0..n), increasing. */
static void tn__sg_bin_slopes(float *slope, const tn__sg_ranked *rk, int n)
{
    int b, i;
    for (b = 0; b < TN__SG_GATE_BINS; b++) {
        int i0 = (int)((long)n * b / TN__SG_GATE_BINS), i1 = (int)((long)n * (b + 1) / TN__SG_GATE_BINS);
        double sv = 0;
        for (i = i0; i < i1; i++) sv += rk[i].v;
        slope[b] = i1 > i0 ? (float)(sv / (i1 - i0)) : 0.0f;
        if (b > 0 && slope[b] <= slope[b - 1]) slope[b] = slope[b - 1] + 1e-9f; /* for the interpolation */
    }
}

/* The RMS of d - base in each of TN__SG_GATE_BINS equal-count bins of the pixels rk[0..n) ranked
   by the base's slope. */
static void tn__sg_bin_rms(float *rms, const float *d, const float *base, const tn__sg_ranked *rk, int n)
{
    int b, i;
    for (b = 0; b < TN__SG_GATE_BINS; b++) {
        int i0 = (int)((long)n * b / TN__SG_GATE_BINS), i1 = (int)((long)n * (b + 1) / TN__SG_GATE_BINS);
        double se = 0;
        for (i = i0; i < i1; i++) {
            double e = d[rk[i].i] - base[rk[i].i];
            se += e * e;
        }
        rms[b] = i1 > i0 ? (float)sqrt(se / (i1 - i0)) : 0.0f;
    }
}

/* A bin's factor: the example's detail RMS qe over the generator's q, over the median bin's
   ratio when `relative`, at most TN__SG_GATE_MAX. */
static void tn__sg_gate_keep(float *keep, const float *qe, const float *q, int relative)
{
    float r[TN__SG_GATE_BINS], rs[TN__SG_GATE_BINS], med = 1.0f;
    int b;
    for (b = 0; b < TN__SG_GATE_BINS; b++) r[b] = q[b] > 0 ? qe[b] / q[b] : 1.0f;
    if (relative) {
        memcpy(rs, r, sizeof r);
        qsort(rs, TN__SG_GATE_BINS, sizeof *rs, tn__cmp_float);
        med = 0.5f * (rs[TN__SG_GATE_BINS / 2 - 1] + rs[TN__SG_GATE_BINS / 2]);
    }
    for (b = 0; b < TN__SG_GATE_BINS; b++) keep[b] = med <= 0 ? 1.0f : r[b] < TN__SG_GATE_MAX * med ? r[b] / med : TN__SG_GATE_MAX;
}

/* Makes *out, scale sc's W x H output, the map s runs the next scale on (held in *sample, the
   previous one freed). */
static void tn__sg_chain_map(tn__sg_gen_run *s, float **sample, float **out, int W, int H, int sc)
{
    TN_FREE(*sample);
    *sample = *out;
    *out = NULL;
    s->map = *sample;
    s->mw = W;
    s->mh = H;
    s->mx0 = s->my0 = s->mstride = 0;
    s->map_level = sc;
    s->map_is_output = 1;
}

/* A laid-out map's gate at the example's level: scale by scale from the layout up, on the map's
   window of (at most) the example's size at the origin, made with the gate so far, each scale's
   factors times the example's detail RMS there (level[sc]) over the map's, by at most
   TN__SG_GATE_MAX either way. The generators add detail by how sharp their input is, and the
   layout, GPNN's rearranged map, is not the example: they add more or less on it. */
static tn_status tn__sg_gate_level(const tn__sg_arch *A, const tn__sg_gen_run *run, tn_ctx *ctx, const double *level, int last, tn__sg_gate *gt)
{
    tn__sg_gen_run s = *run;
    float *base = NULL, *out = NULL, *sample = NULL;
    int sc, lw = tn__sg_size(A->width, A->factor, A->scales - 1 - run->map_level), lh = tn__sg_size(A->height, A->factor, A->scales - 1 - run->map_level);
    tn_status st = TN_OK;
    s.gate = gt;
    s.ctx = ctx;
    for (sc = run->map_level + 1; sc < last && !st && gt->on[sc]; sc++) {
        int W = tn__sg_size(A->width, A->factor, A->scales - 1 - sc), H = tn__sg_size(A->height, A->factor, A->scales - 1 - sc), x, y, b;
        int mw = (int)((long)run->mw * W / lw), mh = (int)((long)run->mh * H / lh); /* the map at scale sc, about */
        double se = 0, f;
        size_t i;
        if (mw < W) W = mw;
        if (mh < H) H = mh;
        if (W < 3 || H < 3) break;
        TN_FREE(base);
        base = (float *)tn__alloc((size_t)W * H * sizeof(float));
        out = (float *)tn__alloc((size_t)W * H * sizeof(float));
        if (!base || !out) {
            st = tn__fail(TN_ERR_OUT_OF_MEMORY, "singan: out of memory");
            break;
        }
        if ((st = tn__sg_base(&s, sc, 0, 0, W, H, base)) || (st = tn__sg_window(&s, sc, 0, 0, W, H, out))) break;
        for (y = 1; y + 1 < H; y++)
            for (x = 1; x + 1 < W; x++) {
                double e = out[(size_t)y * W + x] - base[(size_t)y * W + x];
                se += e * e;
            }
        se = sqrt(se / ((double)(W - 2) * (H - 2)));
        f = se > 0 && level[sc] > 0 ? level[sc] / se : 1.0;
        f = f < 1.0 / TN__SG_GATE_MAX ? 1.0 / TN__SG_GATE_MAX : f > TN__SG_GATE_MAX ? TN__SG_GATE_MAX : f;
        for (b = 0; b < TN__SG_GATE_BINS; b++) gt->keep[sc][b] *= (float)f;
        for (i = 0; i < (size_t)W * H; i++) out[i] = base[i] + (float)f * (out[i] - base[i]);
        tn__sg_chain_map(&s, &sample, &out, W, H, sc);
    }
    TN_FREE(base);
    TN_FREE(out);
    TN_FREE(sample);
    return st;
}

/* The gate (tn_singan_gen_opts.gate) of every trained scale from 1 up: at scale s, in bins of
   equal count by the slope of the coarser scale upsampled (the base), the RMS of the example's
   detail (its scale s less its scale s - 1 upsampled) over the generator's (tn__sg_gate_keep).
   The finest generators, trained for a few hundred iterations, put texture on flat ground where
   the example has none, or too much everywhere (docs/singan.md).
   - A laid-out map (`run` has a layout): the generator runs on the example's own scale s - 1,
     ranked on the example's slopes, relative to the median bin. The map's coarse scales are the
     example's arrangement and heights; measured on a sample bin by bin, the factors rose above 1
     and speckled its plains. Each scale's level is then measured on the map (tn__sg_gate_level).
   - A free sample: the generator's detail is its own on `run`'s window of the example's size at
     the origin, made scale by scale with the gate and ranked on its own slopes, at the
     example's level. A free sample's ground can be rougher than the example's: ranked on the
     example's slopes, its rough ground fell into the steep bins, where a factor above 1
     roughened it further, scale after scale. */
static tn_status tn__sg_gate_make(const tn_singan *m, const tn__sg_arch *A, const tn__sg_gen_run *run, tn__sg_gate *gt)
{
    const tn_tensor *t = tn_params_find(m->weights, "singan.layout");
    tn_image ex, lc = {0, 0, 0, NULL}, ls = {0, 0, 0, NULL};
    tn__sg_gen_run r, s;
    tn__sg_ranked *rk = NULL;
    float *base = NULL, *out = NULL, *sample = NULL;
    int sc, last = A->trained < A->scales ? A->trained : A->scales;
    double level[TN_SINGAN_MAX_SCALES]; /* a laid-out map's: the example's detail RMS per scale */
    tn_status st = TN_OK;
    memset(gt, 0, sizeof *gt);
    memset(level, 0, sizeof level);
    if (!t) return TN_OK;
    ex.width = A->width;
    ex.height = A->height;
    ex.channels = 1;
    ex.data = t->data;
    memset(&r, 0, sizeof r);
    r.A = A;
    r.g = m->weights;
    r.seed = 0x67617465ULL;
    r.noise = 1.0f;
    r.fine_noise = run->fine_noise;
    r.map_is_output = 1;
    s = *run;
    s.gate = gt;
    if (!(r.ctx = s.ctx = tn_ctx_create())) return tn__fail(TN_ERR_OUT_OF_MEMORY, "singan: out of memory");
    for (sc = 1; sc < last && !st; sc++) {
        int W = tn__sg_size(A->width, A->factor, A->scales - 1 - sc), H = tn__sg_size(A->height, A->factor, A->scales - 1 - sc), n, x, y;
        float qe[TN__SG_GATE_BINS], q[TN__SG_GATE_BINS];
        tn_image_free(&lc);
        tn_image_free(&ls);
        TN_FREE(base);
        TN_FREE(out);
        TN_FREE(rk);
        if (W < 3 || H < 3 || (run->map && sc <= run->map_level)) continue; /* a laid-out map's scales below its layout are not made */
        if ((st = tn_image_resize(&lc, &ex, tn__sg_size(A->width, A->factor, A->scales - sc), tn__sg_size(A->height, A->factor, A->scales - sc),
                                  TN_RESIZE_AREA)) ||
            (st = W == A->width && H == A->height ? tn_image_copy(&ls, &ex) : tn_image_resize(&ls, &ex, W, H, TN_RESIZE_AREA)))
            break;
        base = (float *)tn__alloc((size_t)W * H * sizeof(float));
        out = (float *)tn__alloc((size_t)W * H * sizeof(float));
        rk = (tn__sg_ranked *)tn__alloc((size_t)W * H * sizeof(tn__sg_ranked));
        if (!base || !out || !rk) {
            st = tn__fail(TN_ERR_OUT_OF_MEMORY, "singan: out of memory");
            break;
        }
        r.map = lc.data; /* the example's scale s - 1 as the output of s - 1 */
        r.mw = lc.width;
        r.mh = lc.height;
        r.map_level = sc - 1;
        if ((st = tn__sg_base(&r, sc, 0, 0, W, H, base))) break;
        n = tn__sg_rank_slopes(base, W, H, rk);
        tn__sg_bin_rms(qe, ls.data, base, rk, n);
        if (run->map) {
            int b;
            for (b = 0; b < TN__SG_GATE_BINS; b++) level[sc] += (double)qe[b] * qe[b] / TN__SG_GATE_BINS;
            level[sc] = sqrt(level[sc]);
            if ((st = tn__sg_window(&r, sc, 0, 0, W, H, out))) break;
            tn__sg_bin_rms(q, out, base, rk, n);
            tn__sg_gate_keep(gt->keep[sc], qe, q, 1);
            tn__sg_bin_slopes(gt->slope[sc], rk, n);
            gt->on[sc] = n > 0;
            continue;
        }
        if ((st = tn__sg_base(&s, sc, 0, 0, W, H, base)) || (st = tn__sg_window(&s, sc, 0, 0, W, H, out))) break;
        n = tn__sg_rank_slopes(base, W, H, rk);
        tn__sg_bin_rms(q, out, base, rk, n);
        tn__sg_gate_keep(gt->keep[sc], qe, q, 0);
        tn__sg_bin_slopes(gt->slope[sc], rk, n);
        gt->on[sc] = n > 0;
        for (y = 0; y < H; y++) /* the sample's scale sc gated, the next scale's map (its border takes the factor inside) */
            for (x = 0; x < W; x++) {
                int cx = x < 1 ? 1 : x > W - 2 ? W - 2 : x, cy = y < 1 ? 1 : y > H - 2 ? H - 2 : y;
                size_t i = (size_t)y * W + x;
                out[i] = base[i] + tn__sg_gate_at(gt, sc, base + (size_t)cy * W + cx, W) * (out[i] - base[i]);
            }
        tn__sg_chain_map(&s, &sample, &out, W, H, sc);
    }
    if (!st && run->map) st = tn__sg_gate_level(A, run, s.ctx, level, last, gt);
    tn_ctx_free(r.ctx);
    tn_image_free(&lc);
    tn_image_free(&ls);
    TN_FREE(base);
    TN_FREE(out);
    TN_FREE(rk);
    TN_FREE(sample);
    return st;
}

/* Gives map the height distribution of ref, rank for rank (ref's quantile at each pixel's rank,
   linear between ref's sorted values): GPNN's averaging of overlapping patches lowers the
   example's summits and raises its floors. */
static tn_status tn__sg_match_heights(tn_image *map, const tn_image *ref)
{
    size_t n = (size_t)map->width * map->height, m = (size_t)ref->width * ref->height, i;
    tn__sg_ranked *rk = (tn__sg_ranked *)tn__alloc(n * sizeof *rk);
    float *q = (float *)tn__alloc(m * sizeof *q);
    if (!rk || !q) {
        TN_FREE(rk);
        TN_FREE(q);
        return tn__fail(TN_ERR_OUT_OF_MEMORY, "singan: out of memory");
    }
    memcpy(q, ref->data, m * sizeof *q);
    qsort(q, m, sizeof *q, tn__cmp_float);
    for (i = 0; i < n; i++) {
        rk[i].v = map->data[i];
        rk[i].i = (int)i;
    }
    qsort(rk, n, sizeof *rk, tn__sg_cmp_ranked);
    for (i = 0; i < n; i++) {
        double t = n > 1 ? (double)i / (double)(n - 1) * (double)(m - 1) : 0;
        size_t j = (size_t)t;
        float f = (float)(t - (double)j);
        map->data[rk[i].i] = j + 1 < m ? q[j] + f * (q[j + 1] - q[j]) : q[m - 1];
    }
    TN_FREE(rk);
    TN_FREE(q);
    return TN_OK;
}

/* Restores map's detail to ref's in three bands (differences of Gaussians of 0.6, 1.2 and
   2.4 px), band by band where map has less, by at most TN__SG_DETAIL_MAX: GPNN's average of
   overlapping patches and the warp's interpolation smooth the layout, and the finer
   generators, trained on the example's sharp scales, then add less detail than it has. */
#define TN__SG_DETAIL_MAX 3.0
TN__INTERNAL tn_status tn__sg_match_detail(tn_image *map, const tn_image *ref)
{
    static const float sigma[3] = {0.6f, 1.2f, 2.4f};
    tn_image gm[4], gr[4];
    double gain[3];
    size_t n = (size_t)map->width * map->height, m = (size_t)ref->width * ref->height, i;
    int b;
    tn_status st = TN_OK;
    memset(gm, 0, sizeof gm);
    memset(gr, 0, sizeof gr);
    if (!(st = tn_image_copy(&gm[0], map))) st = tn_image_copy(&gr[0], ref);
    for (b = 0; b < 3 && !st; b++)
        if (!(st = tn_image_blur(&gm[b + 1], map, sigma[b]))) st = tn_image_blur(&gr[b + 1], ref, sigma[b]);
    for (b = 0; b < 3 && !st; b++) {
        double em = 0, er = 0;
        for (i = 0; i < n; i++) em += (double)(gm[b].data[i] - gm[b + 1].data[i]) * (gm[b].data[i] - gm[b + 1].data[i]) / (double)n;
        for (i = 0; i < m; i++) er += (double)(gr[b].data[i] - gr[b + 1].data[i]) * (gr[b].data[i] - gr[b + 1].data[i]) / (double)m;
        gain[b] = em <= 0 || er <= em ? 1.0 : er >= TN__SG_DETAIL_MAX * TN__SG_DETAIL_MAX * em ? TN__SG_DETAIL_MAX : sqrt(er / em);
    }
    for (i = 0; i < n && !st; i++) {
        float v = gm[3].data[i];
        for (b = 0; b < 3; b++) v += (float)gain[b] * (gm[b].data[i] - gm[b + 1].data[i]);
        map->data[i] = v;
    }
    for (b = 0; b < 4; b++) {
        tn_image_free(&gm[b]);
        tn_image_free(&gr[b]);
    }
    return st;
}

/* The layout of a w x h sample: the output of scale K - 1 on its grid (*mw x *mh, network units,
   allocated here), made of the example at that scale by GPNN (from SinGAN's coarsest size up),
   given the example's height distribution at that scale, bent by a random smooth warp, given
   the example's detail and heights again (tn__sg_match_detail), then one of its mirror images
   or quarter turns (exact, where a turn by any angle would smooth the layout by resampling
   it). The coarsest generator, 5 layers on noise, made features
   without the example's arrangement (no cone, no massif, no main valleys); the example's own scale
   rearranged by patches keeps them; the warp, the turn and SinGAN's finer scales with their
   noise on top keep samples from being copies (docs/singan.md). */
static tn_status tn__sg_layout(const tn_singan *m, const tn__sg_arch *A, const tn_singan_gen_opts *o, int K, int w, int h, float **map, int *mw,
                               int *mh)
{
    const tn_tensor *t = tn_params_find(m->weights, "singan.layout");
    tn_image ex, exl = {0, 0, 0, NULL}, lay = {0, 0, 0, NULL};
    tn_gpnn_opts go;
    tn_rng rng;
    int orient;
    int down = A->scales - K, ew = tn__sg_size(A->width, A->factor, down), eh = tn__sg_size(A->height, A->factor, down);
    int cw = tn__sg_size(A->width, A->factor, A->scales - 1), ch = tn__sg_size(A->height, A->factor, A->scales - 1);
    float px;
    tn_status st;
    *map = NULL;
    *mw = tn__sg_size(w, A->factor, down);
    *mh = tn__sg_size(h, A->factor, down);
    if (!t || t->ndim != 2 || t->shape[0] != A->height || t->shape[1] != A->width)
        return tn__fail(TN_ERR_INVALID_ARG, "singan sample: the model holds no layout");
    if (ew < 7 || eh < 7 || *mw < 7 || *mh < 7)
        return tn__fail(TN_ERR_INVALID_ARG, "singan sample: a layout needs the example and the map at least 7 px on scale %d's grid "
                        "(%d x %d and %d x %d)", K - 1, ew, eh, *mw, *mh);
    ex.width = A->width;
    ex.height = A->height;
    ex.channels = 1;
    ex.data = t->data;
    if ((st = tn_image_resize(&exl, &ex, ew, eh, TN_RESIZE_AREA))) return st;
    memset(&go, 0, sizeof go);
    go.seed = o->seed;
    go.noise = o->layout_noise;
    go.extend = 1;
    go.blocks = o->layout_blocks > 0 ? o->layout_blocks : 0;
    go.alpha = o->layout_blocks > 0 ? 0.005f : 0; /* without it, blocks' seams drew rows of the same scarp */
    go.coarsest = cw < ch ? cw : ch;
    if (go.coarsest > (ew < eh ? ew : eh)) go.coarsest = ew < eh ? ew : eh;
    tn_rng_seed(&rng, o->seed, 0x7475726eULL);
    orient = o->layout_turn ? (int)(tn_rng_u32(&rng) & (o->layout_turn == 2 ? 7u : 6u)) : 0; /* bit 0, the swap, only at 2 */
    px = (float)*mw / (float)w; /* the layout's px per sample px */
    if ((st = tn_gpnn_sample(&lay, &exl, orient & 1 ? *mh : *mw, orient & 1 ? *mw : *mh, &go)) || (st = tn__sg_match_heights(&lay, &exl)) ||
        (st = tn__sg_warp(&lay, o->layout_warp * px, o->layout_smooth * px, o->seed)) || (st = tn__sg_match_detail(&lay, &exl)) ||
        (st = tn__sg_match_heights(&lay, &exl)) || (st = tn__sg_turn(&lay, orient))) {
        tn_image_free(&exl);
        tn_image_free(&lay);
        return st;
    }
    tn_image_free(&exl);
    *map = lay.data;
    return TN_OK;
}

struct tn_singan_prepared {
    const tn_singan *model;
    tn__sg_arch A;
    tn_singan_gen_opts o;   /* defaults resolved */
    int width, height;      /* the map */
    float *map;             /* the layout: the output of scale level + 1's input grid (NULL: none) */
    int mw, mh, level;
    tn__sg_gate gate;
    tn__sg_gen_run run;     /* what every window runs with (points into this struct) */
};

TN_API void tn_singan_prepared_free(tn_singan_prepared *p)
{
    if (!p) return;
    TN_FREE(p->map);
    TN_FREE(p);
}

TN_API tn_status tn_singan_prepare(tn_singan_prepared **out, const tn_singan *model, int w, int h, const tn_singan_gen_opts *opts)
{
    tn_singan_prepared *p;
    tn__sg_gen_run r;
    tn_status st;
    TN_ASSERT(out && model);
    *out = NULL;
    if (!(p = (tn_singan_prepared *)tn__calloc(sizeof *p))) return tn__oom();
    p->model = model;
    p->width = w;
    p->height = h;
    if ((st = tn__sg_gen_prepare(model, opts, 1, &p->A, &p->o, &r))) goto fail;
    if (w < 1 || h < 1 || w > (1 << 20) || h > (1 << 20) || (p->o.layout && (long)w * h > TN_SINGAN_LAYOUT_MAX_PX)) {
        st = tn__fail(TN_ERR_INVALID_ARG, "singan: map %d x %d (sides 1..2^20; a laid-out map at most %ld pixels)", w, h, TN_SINGAN_LAYOUT_MAX_PX);
        goto fail;
    }
    if (p->o.layout) { /* the layout is the output of scale K - 1 */
        int K = p->o.layout_scale ? p->o.layout_scale : (p->A.scales - 1 < 3 ? p->A.scales - 1 : 3);
        if (K < 1 || K > p->A.scales - 1) {
            st = tn__fail(TN_ERR_INVALID_ARG, "singan sample: layout scale %d outside 1..%d", p->o.layout_scale, p->A.scales - 1);
            goto fail;
        }
        if ((st = tn__sg_layout(model, &p->A, &p->o, K, w, h, &p->map, &p->mw, &p->mh))) goto fail;
        p->level = K - 1;
    }
    r.limit = 1;
    if (p->map) {
        r.map = p->map;
        r.mw = p->mw;
        r.mh = p->mh;
        r.map_level = p->level;
        r.map_is_output = 1;
    }
    if (p->o.gate && (st = tn__sg_gate_make(model, &p->A, &r, &p->gate))) goto fail;
    r.gate = p->o.gate ? &p->gate : NULL;
    p->run = r;
    *out = p;
    return TN_OK;
fail:
    tn_singan_prepared_free(p);
    return st;
}

TN_API tn_status tn_singan_prepared_window(tn_image *out, const tn_singan_prepared *p, int x0, int y0, int w, int h)
{
    tn__sg_gen_run r;
    TN_ASSERT(out && p);
    if (w < 1 || h < 1 || x0 < 0 || y0 < 0 || x0 > p->width - w || y0 > p->height - h)
        return tn__fail(TN_ERR_INVALID_ARG, "singan: window %d x %d at (%d, %d) outside the %d x %d map", w, h, x0, y0, p->width, p->height);
    r = p->run; /* a copy: tn__sg_generate sets its context */
    return tn__sg_generate(p->model, &r, p->A.scales - 1, x0, y0, w, h, p->o.tile, out);
}

TN_API tn_status tn_singan_sample(tn_image *out, const tn_singan *model, int x0, int y0, int w, int h, const tn_singan_gen_opts *opts)
{
    tn__sg_arch A;
    tn_singan_gen_opts o;
    tn__sg_gen_run r;
    tn_singan_prepared *p;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__sg_gen_prepare(model, opts, 1, &A, &o, &r))) return st;
    if (w < 1 || h < 1 || w > (1 << 20) || h > (1 << 20) || x0 < -(1 << 29) || x0 > (1 << 29) || y0 < -(1 << 29) || y0 > (1 << 29))
        return tn__fail(TN_ERR_INVALID_ARG, "singan sample: window %d x %d at (%d, %d) (sizes 1..2^20, origin within +-2^29)", w, h, x0, y0);
    if (!o.layout) {
        tn__sg_gate gate;
        r.limit = 1;
        if (o.gate && (st = tn__sg_gate_make(model, &A, &r, &gate))) return st;
        r.gate = o.gate ? &gate : NULL;
        return tn__sg_generate(model, &r, A.scales - 1, x0, y0, w, h, o.tile, out);
    }
    if (x0 || y0)
        return tn__fail(TN_ERR_INVALID_ARG, "singan sample: a laid-out map is finite: its origin must be (0, 0), not (%d, %d) "
                        "(tn_singan_prepare gives windows of a larger one)", x0, y0);
    if ((st = tn_singan_prepare(&p, model, w, h, opts))) return st;
    st = tn_singan_prepared_window(out, p, 0, 0, w, h);
    tn_singan_prepared_free(p);
    return st;
}

/* in (channel 0, finite) in network units, resized to w x h. */
static tn_status tn__sg_input(const tn_singan *model, const tn_image *in, int w, int h, const char *what, float **out)
{
    tn_image one = {0, 0, 0, NULL}, rs = {0, 0, 0, NULL};
    size_t i;
    tn_status st;
    *out = NULL;
    if (!in || !in->data || in->width < 1 || in->height < 1 || in->channels < 1) return tn__fail(TN_ERR_EMPTY, "singan %s: empty input map", what);
    if ((st = tn_image_create(&one, in->width, in->height, 1))) return st;
    for (i = 0; i < (size_t)in->width * in->height; i++) {
        float v = in->data[i * in->channels];
        if (!isfinite(v)) {
            tn_image_free(&one);
            return tn__fail(TN_ERR_NUMERIC, "singan %s: the input map has NaN/Inf heights", what);
        }
        one.data[i] = (v - model->offset) / model->range;
    }
    if (w == in->width && h == in->height) rs = one;
    else {
        st = tn_image_resize(&rs, &one, w, h, w < in->width && h < in->height ? TN_RESIZE_AREA : TN_RESIZE_BICUBIC);
        tn_image_free(&one);
        if (st) return st;
    }
    *out = rs.data;
    return TN_OK;
}

TN_API tn_status tn_singan_refine(tn_image *out, const tn_singan *model, const tn_image *in, const tn_singan_gen_opts *opts)
{
    tn__sg_arch A;
    tn_singan_gen_opts o;
    tn__sg_gen_run r;
    float *map = NULL;
    int K, mw, mh;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__sg_gen_prepare(model, opts, 0, &A, &o, &r))) return st;
    if (A.scales < 2) return tn__fail(TN_ERR_INVALID_ARG, "singan refine: the model has one scale only");
    K = o.from_scale ? o.from_scale : A.scales - 3;
    if (K < 1) K = 1;
    if (o.from_scale < 0 || K > A.scales - 1)
        return tn__fail(TN_ERR_INVALID_ARG, "singan refine: from_scale %d outside 1..%d", o.from_scale, A.scales - 1);
    if (in && (in->width > (1 << 20) || in->height > (1 << 20))) return tn__fail(TN_ERR_TOO_LARGE, "singan refine: input larger than 2^20");
    mw = in ? tn__sg_size(in->width, A.factor, A.scales - 1 - K) : 1;
    mh = in ? tn__sg_size(in->height, A.factor, A.scales - 1 - K) : 1;
    if ((st = tn__sg_input(model, in, mw, mh, "refine", &map))) return st;
    r.map = map;
    r.mw = mw;
    r.mh = mh;
    r.map_level = K;
    st = tn__sg_generate(model, &r, A.scales - 1, 0, 0, in->width, in->height, o.tile, out);
    TN_FREE(map);
    return st;
}

TN_API tn_status tn_singan_upscale(tn_image *out, const tn_singan *model, const tn_image *in, float factor, const tn_singan_gen_opts *opts)
{
    tn__sg_arch A;
    tn_singan_gen_opts o;
    tn__sg_gen_run r;
    float *map = NULL;
    int m, L, W, H, mw, mh;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__sg_gen_prepare(model, opts, 0, &A, &o, &r))) return st;
    if (!(factor > 1.0f && factor <= 64.0f)) return tn__fail(TN_ERR_INVALID_ARG, "singan upscale: factor %g outside (1, 64]", (double)factor);
    if (!in || !in->data || in->width < 1 || in->height < 1) return tn__fail(TN_ERR_EMPTY, "singan upscale: empty input map");
    W = (int)floor((double)in->width * factor + 0.5);
    H = (int)floor((double)in->height * factor + 0.5);
    if (W > (1 << 20) || H > (1 << 20)) return tn__fail(TN_ERR_TOO_LARGE, "singan upscale: output %d x %d larger than 2^20", W, H);
    m = (int)floor(log((double)factor) / log(1.0 / A.factor) + 0.5);
    if (m < 1) m = 1;
    /* the input's level L (its output is injected), the output level L + m */
    L = o.from_scale ? o.from_scale - 1 : A.scales - 1 - m;
    if (o.from_scale < 0 || o.from_scale > A.scales || L < 0)
        return tn__fail(TN_ERR_INVALID_ARG, "singan upscale: from_scale %d outside 1..%d (or the factor spans more than the %d scales: set from_scale)",
                        o.from_scale, A.scales, A.scales);
    mw = tn__sg_size(W, A.factor, m); /* the input resized to exactly the output's grid m levels down */
    mh = tn__sg_size(H, A.factor, m);
    if ((st = tn__sg_input(model, in, mw, mh, "upscale", &map))) return st;
    r.map = map;
    r.mw = mw;
    r.mh = mh;
    r.map_level = L;
    r.map_is_output = 1;
    st = tn__sg_generate(model, &r, L + m, 0, 0, W, H, o.tile, out);
    TN_FREE(map);
    return st;
}

/* ---- GPNN baseline (patch nearest neighbours, no training) ---- */

/* Patch vectors (P x P, row-major) of every P x P window of a w x h image, window (x, y) at
   index y * (w - P + 1) + x. */
static float *tn__gp_patches(const float *img, int w, int h, int P)
{
    int nx = w - P + 1, ny = h - P + 1, x, y, i;
    float *v = (float *)tn__alloc((size_t)nx * ny * P * P * sizeof(float)), *o = v;
    if (!v) return NULL;
    for (y = 0; y < ny; y++)
        for (x = 0; x < nx; x++)
            for (i = 0; i < P; i++, o += P) memcpy(o, img + (size_t)(y + i) * w + x, (size_t)P * sizeof(float));
    return v;
}

static float tn__gp_ssd(const float *a, const float *b, int n)
{
    float s = 0;
    int i;
    for (i = 0; i < n; i++) s += (a[i] - b[i]) * (a[i] - b[i]);
    return s;
}

typedef struct tn__gp_exact {
    const float *q, *k;  /* query and key patch vectors */
    size_t nq, nk;
    int d;               /* patch length */
    float *kbest;        /* per key: alpha + its best distance to any query (pass 1 writes) */
    int *nn;             /* per query: its key (pass 2 writes) */
} tn__gp_exact;

static void tn__gp_key_pass(void *c, size_t b, size_t e)
{
    tn__gp_exact *x = (tn__gp_exact *)c;
    size_t j, i;
    for (j = b; j < e; j++) {
        float best = FLT_MAX;
        for (i = 0; i < x->nq; i++) {
            float s = tn__gp_ssd(x->k + j * x->d, x->q + i * x->d, x->d);
            if (s < best) best = s;
        }
        x->kbest[j] += best;
    }
}

static void tn__gp_query_pass(void *c, size_t b, size_t e)
{
    tn__gp_exact *x = (tn__gp_exact *)c;
    size_t i, j;
    for (i = b; i < e; i++) {
        float best = FLT_MAX;
        int bj = 0;
        for (j = 0; j < x->nk; j++) {
            float s = tn__gp_ssd(x->q + i * x->d, x->k + j * x->d, x->d) / x->kbest[j];
            if (s < best) {
                best = s;
                bj = (int)j;
            }
        }
        x->nn[i] = bj;
    }
}

/* PatchMatch: improves nnf (key window index per query window) by two sweeps of propagation
   from the left / upper (then right / lower) neighbours and a random search around the match. */
static void tn__gp_patchmatch(const float *q, int qnx, int qny, const float *k, int knx, int kny, int d, int *nnf, tn_rng *rng)
{
    int sweep, x, y;
    for (sweep = 0; sweep < 2; sweep++) {
        int dir = sweep ? -1 : 1;
        for (y = sweep ? qny - 1 : 0; y >= 0 && y < qny; y += dir)
            for (x = sweep ? qnx - 1 : 0; x >= 0 && x < qnx; x += dir) {
                size_t i = (size_t)y * qnx + x;
                const float *qi = q + i * d;
                int b = nnf[i], bx = b % knx, by = b / knx, r, c;
                float best = tn__gp_ssd(qi, k + (size_t)b * d, d);
                for (c = 0; c < 2; c++) { /* the neighbour's match, shifted back by one */
                    int nx = c ? x : x - dir, ny = c ? y - dir : y, m, mx, my;
                    if (nx < 0 || nx >= qnx || ny < 0 || ny >= qny) continue;
                    m = nnf[(size_t)ny * qnx + nx];
                    mx = m % knx + (c ? 0 : dir);
                    my = m / knx + (c ? dir : 0);
                    if (mx < 0 || mx >= knx || my < 0 || my >= kny) continue;
                    {
                        float s = tn__gp_ssd(qi, k + ((size_t)my * knx + mx) * d, d);
                        if (s < best) {
                            best = s;
                            bx = mx;
                            by = my;
                        }
                    }
                }
                for (r = knx > kny ? knx : kny; r >= 1; r /= 2) { /* random search, radius halving */
                    int mx = bx + (int)tn_rng_below(rng, (uint32_t)(2 * r + 1)) - r, my = by + (int)tn_rng_below(rng, (uint32_t)(2 * r + 1)) - r;
                    float s;
                    mx = mx < 0 ? 0 : mx >= knx ? knx - 1 : mx;
                    my = my < 0 ? 0 : my >= kny ? kny - 1 : my;
                    s = tn__gp_ssd(qi, k + ((size_t)my * knx + mx) * d, d);
                    if (s < best) {
                        best = s;
                        bx = mx;
                        by = my;
                    }
                }
                nnf[i] = by * knx + bx;
            }
    }
}

/* img (w x h) = the average of the value windows nnf places over each pixel. */
static void tn__gp_fold(const float *val, int vw, int P, const int *nnf, int w, int h, float *img, float *cnt)
{
    int qnx = w - P + 1, qny = h - P + 1, vnx = vw - P + 1, x, y, i, j;
    size_t n = (size_t)w * h, p;
    memset(img, 0, n * sizeof(float));
    memset(cnt, 0, n * sizeof(float));
    for (y = 0; y < qny; y++)
        for (x = 0; x < qnx; x++) {
            int m = nnf[(size_t)y * qnx + x], mx = m % vnx, my = m / vnx;
            for (j = 0; j < P; j++)
                for (i = 0; i < P; i++) {
                    img[(size_t)(y + j) * w + x + i] += val[(size_t)(my + j) * vw + mx + i];
                    cnt[(size_t)(y + j) * w + x + i] += 1;
                }
        }
    for (p = 0; p < n; p++) img[p] /= cnt[p];
}

/* ex at (sx, sy) of its mirror period (2 n - 2 per side): every part of ex, mirrored or not. */
static float tn__gp_mirrored(const tn_image *ex, int sx, int sy)
{
    return ex->data[(size_t)tn__reflect_whole(sy, ex->height) * ex->width + tn__reflect_whole(sx, ex->width)];
}

/* The distance of a and b on a circle of p. */
static int tn__gp_wrapdist(int a, int b, int p)
{
    int d = ((a - b) % p + p) % p;
    return d < p - d ? d : p - d;
}

/* Whether the len px from a on ex's mirror period (side n) lie within one mirror image of ex:
   a block across a mirror line has a straight crease of symmetry. */
static int tn__gp_one_image(int a, int len, int n)
{
    int p = n > 1 ? 2 * n - 2 : 1;
    a = ((a % p) + p) % p;
    return a + len - 1 <= n - 1 || (a >= n - 1 && a + len - 1 <= p);
}

/* The source of block (x0, y0) of side B in a quilt, which reaches ovl px left and ovu px up
   into the blocks already placed in y: among up to 1024 random places of ex's mirror period,
   one whose surroundings in ex match that overlap (Efros and Freeman's quilting: any within
   10 % of the best), within one mirror image of ex, and not the left or upper block's own
   continuation, which would rebuild ex. Blocks then meet at the level and slope they have on
   both sides. */
static void tn__gp_quilt_pick(const tn_image *y, const tn_image *ex, int x0, int y0, int B, int ovl, int ovu, const int *left, const int *up,
                              tn_rng *rng, int *ox, int *oy)
{
    int pw = ex->width > 1 ? 2 * ex->width - 2 : 1, ph = ex->height > 1 ? 2 * ex->height - 2 : 1, c, n = 1024;
    int cx[1024], cy[1024];
    float err[1024], best = FLT_MAX;
    int chosen = 0, k, m = 0;
    for (c = 0; c < n; c++) {
        int sx = (int)tn_rng_below(rng, (uint32_t)pw), sy = (int)tn_rng_below(rng, (uint32_t)ph), u, v;
        float e = 0;
        cx[c] = sx;
        cy[c] = sy;
        err[c] = FLT_MAX;
        if (!tn__gp_one_image(sx - ovl, ovl + B, ex->width) || !tn__gp_one_image(sy - ovu, ovu + B, ex->height)) continue;
        if ((left && tn__gp_wrapdist(sx, left[0] + B, pw) <= B / 2 && tn__gp_wrapdist(sy, left[1], ph) <= B / 2) ||
            (up && tn__gp_wrapdist(sx, up[0], pw) <= B / 2 && tn__gp_wrapdist(sy, up[1] + B, ph) <= B / 2))
            continue;
        for (v = y0 - ovu; v < y0 + B && v < y->height; v++)
            for (u = x0 - ovl; u < x0 + B && u < y->width; u++)
                if (u < x0 || v < y0) {
                    float d = y->data[(size_t)v * y->width + u] - tn__gp_mirrored(ex, sx + u - x0, sy + v - y0);
                    e += d * d;
                }
        err[c] = e;
        if (e < best) best = e;
    }
    for (k = 0; k < n; k++) m += err[k] <= 1.1f * best;
    if (m > 0) {
        int pick = (int)tn_rng_below(rng, (uint32_t)m);
        for (k = 0; k < n; k++)
            if (err[k] <= 1.1f * best && pick-- == 0) {
                chosen = k;
                break;
            }
    }
    *ox = cx[chosen];
    *oy = cy[chosen];
}

/* The cheapest path across a rows x cols cost grid (row-major), one column per row, moving at
   most one column between rows: path[r] = its column in row r. tmp holds rows x cols. */
static void tn__gp_min_cut(const float *cost, int rows, int cols, float *tmp, int *path)
{
    int r, c;
    for (c = 0; c < cols; c++) tmp[c] = cost[c];
    for (r = 1; r < rows; r++)
        for (c = 0; c < cols; c++) {
            float b = tmp[(size_t)(r - 1) * cols + c];
            if (c > 0 && tmp[(size_t)(r - 1) * cols + c - 1] < b) b = tmp[(size_t)(r - 1) * cols + c - 1];
            if (c + 1 < cols && tmp[(size_t)(r - 1) * cols + c + 1] < b) b = tmp[(size_t)(r - 1) * cols + c + 1];
            tmp[(size_t)r * cols + c] = cost[(size_t)r * cols + c] + b;
        }
    path[rows - 1] = 0;
    for (c = 1; c < cols; c++)
        if (tmp[(size_t)(rows - 1) * cols + c] < tmp[(size_t)(rows - 1) * cols + path[rows - 1]]) path[rows - 1] = c;
    for (r = rows - 2; r >= 0; r--) {
        int p = path[r + 1], b = p;
        if (p > 0 && tmp[(size_t)r * cols + p - 1] < tmp[(size_t)r * cols + b]) b = p - 1;
        if (p + 1 < cols && tmp[(size_t)r * cols + p + 1] < tmp[(size_t)r * cols + b]) b = p + 1;
        path[r] = b;
    }
}

/* Marks with -1 the pixels of a rw x rh cost grid on the old side of the cheapest cut through
   an overlap ov px wide: down its left ov columns (across 0) or across its upper ov rows
   (across 1); pixels marked already cost 0. tmp and cut hold rw * rh and rw + rh. */
static tn_status tn__gp_cut_overlap(float *cost, int rw, int rh, int ov, int across, float *tmp, int *cut)
{
    int n = across ? rw : rh, i, j;
    float *c2 = (float *)tn__alloc((size_t)n * ov * sizeof(float));
    if (!c2) return tn__fail(TN_ERR_OUT_OF_MEMORY, "gpnn: out of memory");
    for (i = 0; i < n; i++)
        for (j = 0; j < ov; j++) {
            float c = across ? cost[(size_t)j * rw + i] : cost[(size_t)i * rw + j];
            c2[(size_t)i * ov + j] = c < 0 ? 0 : c;
        }
    tn__gp_min_cut(c2, n, ov, tmp, cut);
    TN_FREE(c2);
    for (i = 0; i < n; i++)
        for (j = 0; j <= cut[i]; j++) *(across ? &cost[(size_t)j * rw + i] : &cost[(size_t)i * rw + j]) = -1;
    return TN_OK;
}

/* Writes block (x0, y0) of side B from ex at (sx, sy) into y, over its overlap of ovl px left and
   ovu px up only beyond the cheapest cut through the squared difference there (Efros and
   Freeman), so blocks meet along a winding seam where they agree, not along a straight line. */
static tn_status tn__gp_quilt_place(tn_image *y, const tn_image *ex, int x0, int y0, int B, int ovl, int ovu, int sx, int sy)
{
    tn_status st;
    int rx = x0 - ovl, ry = y0 - ovu, rw = (x0 + B < y->width ? x0 + B : y->width) - rx, rh = (y0 + B < y->height ? y0 + B : y->height) - ry, u, v;
    size_t n = (size_t)rw * rh;
    float *cost = (float *)tn__alloc(3 * n * sizeof(float)), *tmp = cost + n, *val = tmp + n;
    int *cut = (int *)tn__alloc((size_t)(rw + rh) * sizeof(int));
    if (!cost || !cut) {
        TN_FREE(cost);
        TN_FREE(cut);
        return tn__fail(TN_ERR_OUT_OF_MEMORY, "gpnn: out of memory");
    }
    for (v = 0; v < rh; v++)
        for (u = 0; u < rw; u++) {
            float d;
            val[(size_t)v * rw + u] = tn__gp_mirrored(ex, sx + rx + u - x0, sy + ry + v - y0);
            d = y->data[(size_t)(ry + v) * y->width + rx + u] - val[(size_t)v * rw + u];
            cost[(size_t)v * rw + u] = d * d;
        }
    if ((ovl > 0 && (st = tn__gp_cut_overlap(cost, rw, rh, ovl, 0, tmp, cut))) || (ovu > 0 && (st = tn__gp_cut_overlap(cost, rw, rh, ovu, 1, tmp, cut)))) {
        TN_FREE(cost);
        TN_FREE(cut);
        return st;
    }
    for (v = 0; v < rh; v++)
        for (u = 0; u < rw; u++)
            if (cost[(size_t)v * rw + u] >= 0) y->data[(size_t)(ry + v) * y->width + rx + u] = val[(size_t)v * rw + u];
    TN_FREE(cost);
    TN_FREE(cut);
    return TN_OK;
}

/* *y = a w x h map of blocks of ex of side B, taken from ex mirrored about its border (uniform
   over the mirror period, so every part of ex is drawn as often; a start inside ex only drew its
   far sides twice): at random places, or with quilt a quilt (tn__gp_quilt_pick, _place) whose
   blocks reach half their side into the ones before. GPNN's start for an output larger than the
   example (blocks of its smaller side) or for a new arrangement of its parts (tn_gpnn_opts.blocks). */
static tn_status tn__gp_blocks(tn_image *y, const tn_image *ex, int w, int h, int B, int quilt, tn_rng *rng)
{
    int bx, by, x, y0, nbx, nby, *src, ov;
    tn_status st = tn_image_create(y, w, h, 1);
    if (st) return st;
    if (B < 1) B = 1;
    ov = B / 2;
    nbx = (w + B - 1) / B;
    nby = (h + B - 1) / B;
    if (!(src = (int *)tn__alloc((size_t)nbx * nby * 2 * sizeof(int)))) return tn__fail(TN_ERR_OUT_OF_MEMORY, "gpnn: out of memory");
    for (by = 0; by < nby && !st; by++)
        for (bx = 0; bx < nbx && !st; bx++) {
            int *o = src + 2 * ((size_t)by * nbx + bx), ox, oy;
            if (quilt && (bx || by) && ov > 0) {
                tn__gp_quilt_pick(y, ex, bx * B, by * B, B, bx ? ov : 0, by ? ov : 0, bx ? o - 2 : NULL, by ? o - 2 * nbx : NULL, rng, &ox, &oy);
                st = tn__gp_quilt_place(y, ex, bx * B, by * B, B, bx ? ov : 0, by ? ov : 0, ox, oy);
            } else {
                int tries = 0;
                do { /* a quilt's first block too within one mirror image, if one holds it */
                    ox = (int)tn_rng_below(rng, (uint32_t)(ex->width > 1 ? 2 * ex->width - 2 : 1));
                    oy = (int)tn_rng_below(rng, (uint32_t)(ex->height > 1 ? 2 * ex->height - 2 : 1));
                } while (quilt && ++tries < 1024 && !(tn__gp_one_image(ox, B, ex->width) && tn__gp_one_image(oy, B, ex->height)));
                for (y0 = by * B; y0 < h && y0 < (by + 1) * B; y0++)
                    for (x = bx * B; x < w && x < (bx + 1) * B; x++) y->data[(size_t)y0 * w + x] = tn__gp_mirrored(ex, x - bx * B + ox, y0 - by * B + oy);
            }
            o[0] = ox;
            o[1] = oy;
        }
    TN_FREE(src);
    return st;
}

/* *y = a w x h quilt of blocks of side B of ex without its tilt (the least-squares plane),
   with the tilt added back stretched over the quilt: quilted with it, the tilt became blocks
   of high and low ground side by side, relief at the blocks' period that ex lacks. */
static tn_status tn__gp_quilt_start(tn_image *y, const tn_image *ex, int w, int h, int B, tn_rng *rng)
{
    tn_image flat = {0, 0, 0, NULL};
    double mx = (ex->width - 1) / 2.0, my = (ex->height - 1) / 2.0, sxx = 0, syy = 0, sxz = 0, syz = 0, gx, gy;
    int x, yy;
    tn_status st = tn_image_copy(&flat, ex);
    if (st) return st;
    for (yy = 0; yy < ex->height; yy++) /* x and y are centred and uncorrelated on a full grid */
        for (x = 0; x < ex->width; x++) {
            double z = ex->data[(size_t)yy * ex->width + x];
            sxx += (x - mx) * (x - mx);
            syy += (yy - my) * (yy - my);
            sxz += (x - mx) * z;
            syz += (yy - my) * z;
        }
    gx = sxx > 0 ? sxz / sxx : 0;
    gy = syy > 0 ? syz / syy : 0;
    for (yy = 0; yy < ex->height; yy++)
        for (x = 0; x < ex->width; x++) flat.data[(size_t)yy * ex->width + x] -= (float)(gx * (x - mx) + gy * (yy - my));
    st = tn__gp_blocks(y, &flat, w, h, B, 1, rng);
    tn_image_free(&flat);
    for (yy = 0; !st && yy < h; yy++)
        for (x = 0; x < w; x++)
            y->data[(size_t)yy * w + x] += (float)(gx * ((x + 0.5) * ex->width / w - 0.5 - mx) + gy * ((yy + 0.5) * ex->height / h - 0.5 - my));
    return st;
}

TN_API tn_status tn_gpnn_sample(tn_image *out, const tn_image *example, int w, int h, const tn_gpnn_opts *opts)
{
    tn_gpnn_opts o;
    tn_image ex[TN_SINGAN_MAX_SCALES], one = {0, 0, 0, NULL}, y = {0, 0, 0, NULL}, t = {0, 0, 0, NULL}, keys = {0, 0, 0, NULL};
    float lo, hi, *cnt = NULL, *qv = NULL, *kv = NULL, *kbest = NULL;
    int *nnf = NULL, *prev = NULL, levels, L, P, it, pqnx = 0, pqny = 0, pknx = 0;
    double mean = 0, var = 0, dmean = 0;
    size_t i, n;
    tn_rng rng;
    tn_status st;
    TN_ASSERT(out);
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    if (o.patch == 0) o.patch = 7;
    if (o.coarsest == 0) o.coarsest = 25;
    if (o.factor == 0) o.factor = 0.75f;
    if (o.iters == 0) o.iters = 10;
    if (o.noise == 0) o.noise = 5.0f;
    if (o.noise < 0) o.noise = 0;
    P = o.patch;
    if (P < 3 || P > 15 || !(P & 1) || o.coarsest < P || o.coarsest > 4096 || !(o.factor >= 0.5f && o.factor <= 0.9f) || o.iters < 1 ||
        o.iters > 1000 || !(o.noise <= 100) || !(o.alpha >= 0 && o.alpha <= 1e6f) || o.extend < 0 || o.extend > 1 || o.blocks < 0 || o.blocks > 64)
        return tn__fail(TN_ERR_INVALID_ARG, "gpnn: bad option (patch %d odd in 3..15, coarsest %d >= patch, factor %g in 0.5..0.9, iters %d in 1..1000, "
                        "noise %g <= 100, alpha %g in 0..1e6, extend %d 0 or 1, blocks %d in 0..64)", o.patch, o.coarsest, (double)o.factor, o.iters,
                        (double)o.noise, (double)o.alpha, o.extend, o.blocks);
    if ((st = tn__sg_check_dem(example, o.coarsest, &lo, &hi))) return st;
    if (w < 1 || h < 1 || w > (1 << 14) || h > (1 << 14)) return tn__fail(TN_ERR_INVALID_ARG, "gpnn: output %d x %d (sides 1..16384)", w, h);
    {
        int mn = example->width < example->height ? example->width : example->height;
        levels = 1 + (int)floor(log((double)mn / o.coarsest) / log(1.0 / o.factor) + 0.5);
        if (levels > TN_SINGAN_MAX_SCALES) levels = TN_SINGAN_MAX_SCALES;
        if (levels < 1) levels = 1;
    }
    if (tn__sg_size(w, o.factor, levels - 1) < P || tn__sg_size(h, o.factor, levels - 1) < P)
        return tn__fail(TN_ERR_INVALID_ARG, "gpnn: output %d x %d is smaller than a %d px patch at the coarsest scale (%d scales of factor %g)", w, h, P,
                        levels, (double)o.factor);
    memset(ex, 0, sizeof ex);
    if ((st = tn_image_create(&one, example->width, example->height, 1))) return st;
    n = (size_t)example->width * example->height;
    for (i = 0; i < n; i++) one.data[i] = example->data[i * example->channels];
    tn_rng_seed(&rng, o.seed, 0x67706e6eULL);
    for (L = 0; L < levels && !st; L++) { /* the example pyramid, level 0 coarsest */
        int ew = tn__sg_size(one.width, o.factor, levels - 1 - L), eh = tn__sg_size(one.height, o.factor, levels - 1 - L);
        st = L == levels - 1 ? tn_image_copy(&ex[L], &one) : tn_image_resize(&ex[L], &one, ew, eh, TN_RESIZE_AREA);
    }
    if (st) goto done;
    n = (size_t)ex[0].width * ex[0].height; /* the noise's scale: the std of the coarsest example */
    for (i = 0; i < n; i++) mean += ex[0].data[i] / (double)n;
    for (i = 0; i < n; i++) var += (ex[0].data[i] - mean) * (ex[0].data[i] - mean) / (double)n;
    {   /* alpha's unit: the mean squared difference of the example's patches one pixel apart */
        const tn_image *e = &ex[levels - 1];
        int xx, yy;
        for (yy = 0; yy < e->height; yy++)
            for (xx = 0; xx + 1 < e->width; xx++) {
                double dd = e->data[(size_t)yy * e->width + xx + 1] - e->data[(size_t)yy * e->width + xx];
                dmean += dd * dd;
            }
        dmean = dmean / ((double)e->height * (e->width - 1)) * P * P;
    }
    for (L = 0; L < levels && !st; L++) {
        int ow = tn__sg_size(w, o.factor, levels - 1 - L), oh = tn__sg_size(h, o.factor, levels - 1 - L);
        int kw = ex[L].width, kh = ex[L].height, qnx = ow - P + 1, qny = oh - P + 1, knx = kw - P + 1, kny = kh - P + 1, d = P * P;
        size_t nq = (size_t)qnx * qny, nk = (size_t)knx * kny;
        int exact = (double)nq * nk * d <= 3e8;
        if (L == 0) { /* the example's coarsest scale at the output's size, plus noise */
            int side = kw < kh ? kw : kh;
            if (o.blocks > 0) st = tn__gp_quilt_start(&y, &ex[0], ow, oh, (side + o.blocks - 1) / o.blocks, &rng);
            else if (ow == kw && oh == kh) st = tn_image_copy(&y, &ex[0]);
            else if (o.extend && (ow > kw || oh > kh)) st = tn__gp_blocks(&y, &ex[0], ow, oh, side, 0, &rng);
            else st = tn_image_resize(&y, &ex[0], ow, oh, TN_RESIZE_BICUBIC);
            for (i = 0; !st && i < (size_t)ow * oh; i++) y.data[i] += o.noise * (float)sqrt(var) * tn_rng_normal(&rng);
            if (!st) st = tn_image_copy(&keys, &ex[0]);
        } else {
            if (!(st = tn_image_resize(&t, &y, ow, oh, TN_RESIZE_BICUBIC))) {
                tn_image_free(&y);
                y = t;
                t.data = NULL;
                tn_image_free(&keys);
                st = tn_image_resize(&keys, &ex[L - 1], kw, kh, TN_RESIZE_BICUBIC);
            }
        }
        if (st) break;
        TN_FREE(cnt);
        TN_FREE(nnf);
        if (!(cnt = (float *)tn__alloc((size_t)ow * oh * sizeof(float))) || !(nnf = (int *)tn__alloc(nq * sizeof(int)))) {
            st = tn__fail(TN_ERR_OUT_OF_MEMORY, "gpnn: out of memory");
            break;
        }
        for (i = 0; i < nq; i++) { /* PatchMatch's start: the coarser scale's matches, scaled up */
            int qx = (int)(i % qnx), qy = (int)(i / qnx), kx, ky;
            if (prev) {
                long cx, cy;
                float tt;
                int m;
                tn__sg_coord(qx, o.factor, &cx, &tt);
                tn__sg_coord(qy, o.factor, &cy, &tt);
                cx = cx < 0 ? 0 : cx >= pqnx ? pqnx - 1 : cx;
                cy = cy < 0 ? 0 : cy >= pqny ? pqny - 1 : cy;
                m = prev[cy * pqnx + cx];
                kx = (int)floor((m % pknx + 0.5) / o.factor - 0.5 + (qx - ((cx + 0.5) / o.factor - 0.5)) + 0.5);
                ky = (int)floor((m / pknx + 0.5) / o.factor - 0.5 + (qy - ((cy + 0.5) / o.factor - 0.5)) + 0.5);
            } else {
                kx = (int)tn_rng_below(&rng, (uint32_t)knx);
                ky = (int)tn_rng_below(&rng, (uint32_t)kny);
            }
            kx = kx < 0 ? 0 : kx >= knx ? knx - 1 : kx;
            ky = ky < 0 ? 0 : ky >= kny ? kny - 1 : ky;
            nnf[i] = ky * knx + kx;
        }
        for (it = 0; it < o.iters && !st; it++) {
            TN_FREE(qv);
            TN_FREE(kv);
            if (!(qv = tn__gp_patches(y.data, ow, oh, P)) || !(kv = tn__gp_patches(it == 0 ? keys.data : ex[L].data, kw, kh, P))) {
                st = tn__fail(TN_ERR_OUT_OF_MEMORY, "gpnn: out of memory");
                break;
            }
            if (exact) {
                tn__gp_exact x;
                size_t j;
                TN_FREE(kbest);
                if (!(kbest = (float *)tn__alloc(nk * sizeof(float)))) {
                    st = tn__fail(TN_ERR_OUT_OF_MEMORY, "gpnn: out of memory");
                    break;
                }
                for (j = 0; j < nk; j++) kbest[j] = o.alpha > 0 ? (float)(o.alpha * dmean) + 1e-30f : 1.0f;
                x.q = qv;
                x.k = kv;
                x.nq = nq;
                x.nk = nk;
                x.d = d;
                x.kbest = kbest;
                x.nn = nnf;
                if (o.alpha > 0) tn_parallel_for(nk, 16, tn__gp_key_pass, &x);
                tn_parallel_for(nq, 16, tn__gp_query_pass, &x);
            } else
                tn__gp_patchmatch(qv, qnx, qny, kv, knx, kny, d, nnf, &rng);
            tn__gp_fold(ex[L].data, kw, P, nnf, ow, oh, y.data, cnt);
            if ((st = tn__progress("gpnn", ((double)L + (it + 1.0) / o.iters) / levels))) break;
        }
        TN_FREE(prev);
        prev = nnf;
        nnf = NULL;
        pqnx = qnx;
        pqny = qny;
        pknx = knx;
    }
done:
    for (L = 0; L < TN_SINGAN_MAX_SCALES; L++) tn_image_free(&ex[L]);
    tn_image_free(&one);
    tn_image_free(&t);
    tn_image_free(&keys);
    TN_FREE(cnt);
    TN_FREE(qv);
    TN_FREE(kv);
    TN_FREE(kbest);
    TN_FREE(nnf);
    TN_FREE(prev);
    if (st) tn_image_free(&y);
    else *out = y;
    return st;
}
#endif /* TN_NO_SINGAN */

