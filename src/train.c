/* ============================================================================================
   @@train  training runs: budget, progress, checkpoints, resume; shared building blocks; models
   Every learned method trains through one tn_train run. The method registers what makes up its
   state (networks with their optimisers, extra parameter sets such as EMA weights, RNGs, its
   own config) and calls tn_train_next() before each iteration. The run keeps the time and
   iteration budgets, reports progress with an ETA, writes atomic checkpoints, and on resume
   restores everything so the continuation is bit-identical to an uninterrupted run (for the
   same iteration budget; time budgets stop wherever the clock says).
   Checkpoint = .tnw holding every registered set ("<prefix><tensor>"), Adam moments
   ("am.<tensor>", "av.<tensor>") and metadata: method, kind=checkpoint, iteration,
   microseconds trained, optimiser steps ("step.<net>"), RNG states ("rng.<name>" = hex).
   A model file carries metadata too (tn_model_stamp): method, format, library version, seed,
   iterations, training seconds, and a digest of the example it learned from.
   ============================================================================================ */
#ifndef TN_NO_ENGINE

/* What zero means is resolved by tn_train_defaults; methods embed this in their options. */
typedef struct tn_train_opts {
    double minutes;             /* wall-clock budget of the whole run, resumed time included;
                                   0 = the method's default */
    long max_iters;             /* stop after this many iterations in total; 0 = only the time budget */
    const char *checkpoint;     /* checkpoint file (.tnw); NULL = none */
    double checkpoint_seconds;  /* save at least this often; 0 = 60 */
    long checkpoint_iters;      /* also save every this many iterations; 0 = only by time */
    int resume;                 /* 1: continue from `checkpoint` */
    uint64_t seed;
} tn_train_opts;

/* Resolves the zero fields; default_minutes is the method's own default budget. */
TN_API void tn_train_defaults(tn_train_opts *o, double default_minutes);

typedef struct tn_train tn_train;
/* Starts a run of `method` (e.g. "texgan"), reporting progress as `stage`. Settings are checked
   (NaN/negative budgets, resume without a checkpoint path). Free with tn_train_free. */
TN_API tn_status tn_train_create(tn_train **out, const char *method, const char *stage, const tn_train_opts *opts);
TN_API void tn_train_free(tn_train *run);
/* Registers state. Names/prefixes must stay the same between the run that wrote a checkpoint
   and the one resuming. The run does not own what is registered. */
TN_API tn_status tn_train_add_net(tn_train *run, const char *name, tn_params *p, tn_optim *o);
TN_API tn_status tn_train_add_params(tn_train *run, const char *prefix, tn_params *p);
TN_API tn_status tn_train_add_rng(tn_train *run, const char *name, tn_rng *rng);
/* Metadata stored in checkpoints as "config.<key>" (the method's settings); tn_train_meta reads
   the opened checkpoint's value when resuming, else the value set. */
TN_API tn_status tn_train_set_meta(tn_train *run, const char *key, const char *value);
TN_API const char *tn_train_meta(const tn_train *run, const char *key);
/* A number setting, written without the C locale so that it reads back to the same float or
   integer; reading fails with TN_ERR_CORRUPT (naming the checkpoint and key) when it is missing,
   malformed or outside [lo, hi], so a damaged checkpoint never becomes a wild setting. */
TN_API tn_status tn_train_set_meta_number(tn_train *run, const char *key, double value);
TN_API tn_status tn_train_meta_number(const tn_train *run, const char *key, double lo, double hi, double *out);
/* The example a run learns from (its tn_image_digest) as config.example; on resume
   tn_train_check_example refuses, with TN_ERR_SHAPE, a checkpoint trained on another example. */
TN_API tn_status tn_train_set_example(tn_train *run, uint64_t digest);
TN_API tn_status tn_train_check_example(const tn_train *run, uint64_t digest);
/* Renames the stage progress reports from now on (e.g. "singan-train scale 3/8"); truncated to
   47 characters. */
TN_API void tn_train_set_stage(tn_train *run, const char *stage);
/* Opens opts->checkpoint for a resume: a .tnw of this method (its architecture is in it, so
   methods call this before building their networks). The set stays owned by the run; a method
   may upgrade a checkpoint of an older layout in it before tn_train_restore. */
TN_API tn_status tn_train_open_checkpoint(tn_train *run, tn_params **ck);
/* Restores everything registered from the opened checkpoint (every tensor must be there with
   its shape), the counters, optimiser steps and RNG states. */
TN_API tn_status tn_train_restore(tn_train *run);
/* Sets the counters directly (for checkpoints of older layouts). */
TN_API void tn_train_set_position(tn_train *run, long iteration, double seconds);
/* Call before every iteration: 1 = run one, 0 = stop (budget spent, cancelled or failed; see
   tn_train_finish). From the second call on it counts the iteration just done, saves a
   checkpoint when one is due and reports progress. */
TN_API int tn_train_next(tn_train *run);
/* Records a failed iteration: the run stops, tn_train_finish returns st. */
TN_API void tn_train_fail(tn_train *run, tn_status st);
/* Ends the run: a final checkpoint if anything was done since the last one (also after a
   cancel, so a cancelled run resumes), and the first error (TN_ERR_CANCELLED if cancelled). */
TN_API tn_status tn_train_finish(tn_train *run);
/* Iterations done (the index of the one about to run), in total and at the start of this run. */
TN_API long tn_train_iteration(const tn_train *run);
TN_API long tn_train_start_iteration(const tn_train *run);
TN_API double tn_train_seconds(const tn_train *run);
TN_API double tn_train_start_seconds(const tn_train *run);
/* Share of the budget used so far, 0..1: time or iterations, whichever is further along. */
TN_API double tn_train_fraction(const tn_train *run);
/* The run's seed (a resumed run reports the seed of the run that wrote the checkpoint). */
TN_API uint64_t tn_train_seed(const tn_train *run);
TN_API int tn_train_checkpoints(const tn_train *run);
/* Checkpoints that could not be written (TN_ERR_IO: a full disk, a missing directory): a warning,
   not a failure, so training goes on and the model is still saved to its own path. Returns how
   many failed; *message (may be NULL) gets the last failure's detail, "" if none. */
TN_API int tn_train_checkpoint_failures(const tn_train *run, const char **message);
/* Writes a checkpoint now (to opts->checkpoint, or to path if not NULL). */
TN_API tn_status tn_train_checkpoint(tn_train *run, const char *path);

/* Seconds left in the operation now reporting progress (from inside a progress hook), < 0 when
   unknown. Training runs keep it current; per thread, as the hook. */
TN_API double tn_progress_eta(void);

/* Model files: tn_model_stamp writes the metadata every model carries; tn_model_check refuses a
   file of another method or of a newer format with TN_ERR_FORMAT and a message that says so. */
typedef struct tn_model_provenance {
    uint64_t seed;
    long iterations;
    double seconds;             /* training wall-clock seconds */
    uint64_t example_digest;    /* tn_image_digest of the example (0 = none) */
    int example_width, example_height, example_channels;
} tn_model_provenance;
TN_API tn_status tn_model_stamp(tn_params *p, const char *method, int format, const tn_model_provenance *prov);
/* legacy_tensor: a tensor name that identifies files of this method written before metadata
   existed (NULL = none accepted). */
TN_API tn_status tn_model_check(const tn_params *p, const char *method, int max_format, const char *legacy_tensor,
                                const char *name);
/* FNV-1a 64 of the size and the float bits of every sample (a fingerprint of an example). */
TN_API uint64_t tn_image_digest(const tn_image *img);

/* Building blocks shared by the learned methods. */

/* Exponential moving average: every learned tensor of src blends into avg's tensor of the same
   name, with decay min(decay, (1 + step) / (10 + step)) so early weights fade quickly. */
TN_API void tn_ema_update(tn_params *avg, const tn_params *src, float decay, long step);

typedef enum tn_activation { TN_ACT_NONE = 0, TN_ACT_RELU, TN_ACT_LEAKY, TN_ACT_TANH, TN_ACT_SIGMOID } tn_activation;
TN_API tn_tensor *tn_activate(tn_ctx *ctx, tn_tensor *x, tn_activation act);

/* MLP: layers `widths[0] -> ... -> widths[n]` ("<prefix>w<i>" (out x in), "<prefix>b<i>"), He
   initialised from rng; tn_mlp applies it to N x widths[0] rows with `act` between layers and
   none after the last. */
TN_API tn_status tn_mlp_add(tn_params *p, const char *prefix, const int *widths, int n, tn_rng *rng);
TN_API tn_tensor *tn_mlp(tn_ctx *ctx, const tn_params *p, const char *prefix, int n, tn_tensor *x, tn_activation act);

/* Conv block: k x k conv with "same" zero padding ("<prefix>w", "<prefix>b"), then instance norm
   with learned gain/offset ("<prefix>g", "<prefix>o") when norm is 1, then the activation. */
TN_API tn_status tn_conv_block_add(tn_params *p, const char *prefix, int cin, int cout, int k, int norm, tn_rng *rng);
TN_API tn_tensor *tn_conv_block(tn_ctx *ctx, const tn_params *p, const char *prefix, tn_tensor *x, tn_activation act);

/* Spectral-normalised patch discriminator: `layers` k x k convs of stride 2 (width, 2 width,
   ...; leaky ReLU 0.2), then a k x k score conv: a per-location score map. Tensors
   "<prefix>w<l>", "<prefix>b<l>", power-iteration vectors "<prefix>u<l>" (buffers). */
#define TN_DISC_MAX_LAYERS 8
typedef struct tn_patch_disc {
    tn_params *p;
    char prefix[16];
    int layers, k;
    tn_tensor *wn[TN_DISC_MAX_LAYERS + 1]; /* this step's normalised weights (tn_patch_disc_begin) */
} tn_patch_disc;
/* Adds the tensors to p and fills *d (initialised from rng; rng NULL leaves them zero). */
TN_API tn_status tn_patch_disc_add(tn_params *p, const char *prefix, int cin, int width, int layers, int k, tn_rng *rng,
                                   tn_patch_disc *d);
/* One power iteration per layer and the normalised weights for this step (share them between
   the real and the fake pass of a step). */
TN_API void tn_patch_disc_begin(tn_ctx *ctx, tn_patch_disc *d);
TN_API tn_tensor *tn_patch_disc_score(tn_ctx *ctx, const tn_patch_disc *d, tn_tensor *x);
/* The same score, and the activations after each stride-2 layer in feats[0 .. layers-1] (for
   feature matching); feats may be NULL. */
TN_API tn_tensor *tn_patch_disc_features(tn_ctx *ctx, const tn_patch_disc *d, tn_tensor *x, tn_tensor **feats);

/* Keep the best k snapshots of a parameter set by a score (lower is better). */
typedef struct tn_best_k tn_best_k;
TN_API tn_best_k *tn_best_k_create(int k);
TN_API void tn_best_k_free(tn_best_k *b);
/* Copies p if its score is among the k best so far (NaN scores are never kept). 1 = kept. */
TN_API int tn_best_k_offer(tn_best_k *b, const tn_params *p, double score, long iteration);
TN_API int tn_best_k_count(const tn_best_k *b);
/* The i-th best (0 = best); score and iteration may be NULL. */
TN_API const tn_params *tn_best_k_get(const tn_best_k *b, int i, double *score, long *iteration);
#endif /* TN_NO_ENGINE */

/* --------------------------------------------------------------------------------------------
   >>train  (@@train implementation)
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_ENGINE

#define TN__TRAIN_MAX 8

typedef struct tn__train_item {
    char name[24];      /* net name, set prefix or RNG name */
    tn_params *p;
    tn_optim *o;
    tn_rng *rng;
} tn__train_item;

struct tn_train {
    char method[32], stage[48];
    tn_train_opts o;
    tn__train_item nets[TN__TRAIN_MAX], sets[TN__TRAIN_MAX], rngs[TN__TRAIN_MAX];
    int nnets, nsets, nrngs;
    tn_params *meta;        /* the method's settings (metadata only) */
    tn_params *ck;          /* the checkpoint opened for a resume */
    long it, it0, last_ck_it;
    double seconds, sec0, t0, last_ck;
    int started, stopped, ckpts;
    int ck_failures;        /* checkpoints that could not be written (warnings) */
    char ck_warning[256];
    tn_status st;
};

/* A checkpoint that could not be written is a warning (training goes on); other failures stop. */
static tn_status tn__train_try_checkpoint(tn_train *run)
{
    tn_status st = tn_train_checkpoint(run, NULL);
    if (st != TN_ERR_IO) return st;
    run->ck_failures++;
    {
        const char *m = tn_last_error();
        size_t l = strlen(m) < sizeof run->ck_warning ? strlen(m) : sizeof run->ck_warning - 1;
        memcpy(run->ck_warning, m, l);
        run->ck_warning[l] = 0;
    }
    return TN_OK;
}

#ifdef TN__TLS
static TN__TLS double tn__progress_eta_s = -1.0;
#else
static double tn__progress_eta_s = -1.0;
#endif

TN_API double tn_progress_eta(void) { return tn__progress_eta_s; }

TN_API void tn_train_defaults(tn_train_opts *o, double default_minutes)
{
    TN_ASSERT(o);
    if (o->minutes <= 0) o->minutes = default_minutes > 0 ? default_minutes : 10.0;
    if (o->max_iters < 0) o->max_iters = 0;
    if (o->checkpoint_seconds <= 0) o->checkpoint_seconds = 60.0;
    if (o->checkpoint_iters < 0) o->checkpoint_iters = 0;
}

static int tn__train_name_ok(const char *s, size_t cap) { return s && strlen(s) < cap; }

TN_API tn_status tn_train_create(tn_train **out, const char *method, const char *stage, const tn_train_opts *opts)
{
    tn_train *r;
    TN_ASSERT(out);
    *out = NULL;
    if (!tn__meta_key_ok(method) || strlen(method) >= sizeof r->method || !stage || strlen(stage) >= sizeof r->stage)
        return tn__fail(TN_ERR_INVALID_ARG, "training: bad method or stage name");
    if (opts && (!(opts->minutes <= 1e9) || !(opts->checkpoint_seconds <= 1e9) || opts->max_iters < 0 || opts->checkpoint_iters < 0))
        return tn__fail(TN_ERR_INVALID_ARG, "%s: bad training budget (minutes %g, checkpoint every %g s)", method, opts->minutes,
                        opts->checkpoint_seconds);
    if (opts && opts->resume && (!opts->checkpoint || !opts->checkpoint[0]))
        return tn__fail(TN_ERR_INVALID_ARG, "%s: resume needs a checkpoint path", method);
    r = (tn_train *)tn__calloc(sizeof *r);
    if (!r) return TN_ERR_OUT_OF_MEMORY;
    strcpy(r->method, method);
    strcpy(r->stage, stage);
    if (opts) r->o = *opts;
    tn_train_defaults(&r->o, 0.0);
    if (!(r->meta = tn_params_create())) {
        TN_FREE(r);
        return tn__fail(TN_ERR_OUT_OF_MEMORY, "%s: out of memory", method);
    }
    *out = r;
    return TN_OK;
}

TN_API void tn_train_free(tn_train *run)
{
    if (!run) return;
    tn_params_free(run->meta);
    tn_params_free(run->ck);
    TN_FREE(run);
}

static tn_status tn__train_add(tn_train *run, tn__train_item *items, int *n, const char *name, tn_params *p, tn_optim *o, tn_rng *rng)
{
    TN_ASSERT(run && name);
    if (*n >= TN__TRAIN_MAX || !tn__train_name_ok(name, sizeof items->name))
        return tn__fail(TN_ERR_INVALID_ARG, "%s: too many registered items or name '%s' too long", run->method, name);
    memset(&items[*n], 0, sizeof items[*n]);
    strcpy(items[*n].name, name);
    items[*n].p = p;
    items[*n].o = o;
    items[*n].rng = rng;
    (*n)++;
    return TN_OK;
}

TN_API tn_status tn_train_add_net(tn_train *run, const char *name, tn_params *p, tn_optim *o)
{
    TN_ASSERT(p && o && o->p == p);
    if (!tn__meta_key_ok(name)) return tn__fail(TN_ERR_INVALID_ARG, "training: bad net name");
    return tn__train_add(run, run->nets, &run->nnets, name, p, o, NULL);
}

TN_API tn_status tn_train_add_params(tn_train *run, const char *prefix, tn_params *p)
{
    TN_ASSERT(p);
    return tn__train_add(run, run->sets, &run->nsets, prefix, p, NULL, NULL);
}

TN_API tn_status tn_train_add_rng(tn_train *run, const char *name, tn_rng *rng)
{
    TN_ASSERT(rng);
    if (!tn__meta_key_ok(name)) return tn__fail(TN_ERR_INVALID_ARG, "training: bad RNG name");
    return tn__train_add(run, run->rngs, &run->nrngs, name, NULL, NULL, rng);
}

TN_API tn_status tn_train_set_meta(tn_train *run, const char *key, const char *value) { return tn_params_set_meta(run->meta, key, value); }

TN_API const char *tn_train_meta(const tn_train *run, const char *key)
{
    char k[80];
    if (!run->ck) return tn_params_meta(run->meta, key);
    snprintf(k, sizeof k, "config.%s", key);
    return tn_params_meta(run->ck, k);
}

static void tn__hex64(char *buf, uint64_t v);

TN_API tn_status tn_train_set_meta_number(tn_train *run, const char *key, double value)
{
    char buf[40];
    tn__io_format_number(buf, sizeof buf, value, 0);
    return tn_train_set_meta(run, key, buf);
}

TN_API tn_status tn_train_meta_number(const tn_train *run, const char *key, double lo, double hi, double *out)
{
    const char *v = tn_train_meta(run, key), *name = run->o.checkpoint ? run->o.checkpoint : run->method;
    double d;
    if (!v) return tn__fail(TN_ERR_CORRUPT, "%s: no %s in the checkpoint", name, key);
    if (!tn__io_number(v, strlen(v), &d) || !(d >= lo && d <= hi)) return tn__fail(TN_ERR_CORRUPT, "%s: bad %s '%s'", name, key, v);
    *out = d;
    return TN_OK;
}

TN_API void tn_train_set_stage(tn_train *run, const char *stage)
{
    snprintf(run->stage, sizeof run->stage, "%s", stage ? stage : "");
}

TN_API tn_status tn_train_set_example(tn_train *run, uint64_t digest)
{
    char buf[20];
    tn__hex64(buf, digest);
    return tn_train_set_meta(run, "example", buf);
}

TN_API tn_status tn_train_check_example(const tn_train *run, uint64_t digest)
{
    const char *v = tn_train_meta(run, "example");
    char buf[20];
    tn__hex64(buf, digest);
    if (!v || strcmp(v, buf) != 0)
        return tn__fail(TN_ERR_SHAPE, "%s: the checkpoint was trained on another example", run->o.checkpoint ? run->o.checkpoint : run->method);
    return TN_OK;
}

TN_API long tn_train_iteration(const tn_train *run) { return run->it; }
TN_API long tn_train_start_iteration(const tn_train *run) { return run->it0; }
TN_API double tn_train_seconds(const tn_train *run) { return run->seconds; }
TN_API double tn_train_start_seconds(const tn_train *run) { return run->sec0; }
TN_API double tn_train_fraction(const tn_train *run)
{
    double frac = run->seconds / (run->o.minutes * 60.0);
    if (run->o.max_iters && (double)run->it / (double)run->o.max_iters > frac) frac = (double)run->it / (double)run->o.max_iters;
    return frac > 1.0 ? 1.0 : frac;
}
TN_API uint64_t tn_train_seed(const tn_train *run) { return run->o.seed; }
TN_API int tn_train_checkpoints(const tn_train *run) { return run->ckpts; }
TN_API int tn_train_checkpoint_failures(const tn_train *run, const char **message)
{
    if (message) *message = run->ck_warning;
    return run->ck_failures;
}

TN_API void tn_train_set_position(tn_train *run, long iteration, double seconds)
{
    run->it = run->it0 = run->last_ck_it = iteration;
    run->seconds = run->sec0 = seconds;
}

/* ---- the example ---- */

/* The example a learned method trains on (their option `dequantize`): *d without its height
   steps, made in *own, when mode is 1 and it is stored in steps, or mode is 0 and they are coarse
   (tn_image_height_step: the finest scales would learn them as a grain). *step = the step taken
   away, 0 = none. */
TN__SHARED tn_status tn__train_without_steps(tn_image *own, const tn_image **d, int mode, float *step)
{
    float s = mode < 0 ? 0.0f : tn_image_height_step(*d, mode == 0);
    tn_status st;
    *step = 0;
    if (!(s > 0)) return TN_OK;
    if ((st = tn_image_dequantize(own, *d, s))) return st;
    *d = own;
    *step = s;
    return TN_OK;
}

/* ---- metadata numbers (locale-free) ---- */

static tn_status tn__meta_put_num(tn_params *p, const char *key, double v)
{
    char buf[40];
    tn__io_format_number(buf, sizeof buf, v, 0);
    return tn_params_set_meta(p, key, buf);
}

/* A whole number in [0, max] from metadata; 0 (with an error) if absent or malformed. */
static int tn__meta_get_whole(const tn_params *p, const char *key, double max, double *out, const char *name)
{
    const char *v = tn_params_meta(p, key);
    double d;
    if (!v || !tn__io_number(v, strlen(v), &d) || !(d >= 0 && d <= max) || d != floor(d)) {
        tn__fail(TN_ERR_CORRUPT, "%s: metadata '%s' is missing or not a whole number in 0..%.0f", name, key, max);
        return 0;
    }
    *out = d;
    return 1;
}

static void tn__hex64(char *buf, uint64_t v)
{
    static const char hex[] = "0123456789abcdef";
    int i;
    for (i = 0; i < 16; i++) buf[i] = hex[(v >> (60 - 4 * i)) & 15u];
    buf[16] = 0;
}

static int tn__parse_hex64(const char *s, size_t n, uint64_t *out)
{
    uint64_t v = 0;
    size_t i;
    if (n == 0 || n > 16) return 0;
    for (i = 0; i < n; i++) {
        int c = s[i], d = c >= '0' && c <= '9' ? c - '0' : c >= 'a' && c <= 'f' ? c - 'a' + 10 : -1;
        if (d < 0) return 0;
        v = (v << 4) | (uint64_t)d;
    }
    *out = v;
    return 1;
}

/* ---- checkpoints ---- */

static tn_status tn__train_copy_tensor(tn_params *ck, const char *prefix, const tn_tensor *t, const float *data, const char *method)
{
    char name[64];
    tn_tensor *c;
    snprintf(name, sizeof name, "%s%s", prefix, t->name);
    if (strlen(name) >= 40) return tn__fail(TN_ERR_INVALID_ARG, "%s: checkpoint tensor name %s too long", method, name);
    if (!(c = tn_params_add_buffer(ck, name, t->ndim, t->shape))) return tn__fail_context(TN_ERR_OUT_OF_MEMORY, method);
    memcpy(c->data, data, t->numel * sizeof(float));
    return TN_OK;
}

/* The whole state as one set of tensors + metadata. */
static tn_status tn__train_state(tn_train *run, tn_params **out)
{
    tn_params *ck = tn_params_create();
    tn_status st = TN_OK;
    char key[64], hex[40];
    int i, j;
    *out = NULL;
    if (!ck) return tn__fail(TN_ERR_OUT_OF_MEMORY, "%s: out of memory", run->method);
    st = tn_params_set_meta(ck, "method", run->method);
    if (!st) st = tn_params_set_meta(ck, "kind", "checkpoint");
    if (!st) st = tn_params_set_meta(ck, "library", TN_VERSION_STRING);
    if (!st) st = tn__meta_put_num(ck, "iteration", (double)run->it);
    if (!st) st = tn__meta_put_num(ck, "microseconds", floor(run->seconds * 1e6));
    if (!st) {
        tn__hex64(hex, run->o.seed);
        st = tn_params_set_meta(ck, "seed", hex);
    }
    for (i = 0; i < run->nnets && !st; i++) {
        snprintf(key, sizeof key, "step.%s", run->nets[i].name);
        st = tn__meta_put_num(ck, key, (double)run->nets[i].o->step);
    }
    for (i = 0; i < run->nrngs && !st; i++) {
        snprintf(key, sizeof key, "rng.%s", run->rngs[i].name);
        tn__hex64(hex, run->rngs[i].rng->state);
        hex[16] = ':';
        tn__hex64(hex + 17, run->rngs[i].rng->inc);
        st = tn_params_set_meta(ck, key, hex);
    }
    for (i = 0; i < tn_params_meta_count(run->meta) && !st; i++) {
        const char *v = NULL, *k = tn_params_meta_key(run->meta, i, &v);
        snprintf(key, sizeof key, "config.%s", k);
        st = tn_params_set_meta(ck, key, v);
    }
    for (i = 0; i < run->nsets && !st; i++)
        for (j = 0; j < tn_params_count(run->sets[i].p) && !st; j++) {
            const tn_tensor *t = tn_params_get(run->sets[i].p, j);
            st = tn__train_copy_tensor(ck, run->sets[i].name, t, t->data, run->method);
        }
    for (i = 0; i < run->nnets && !st; i++)
        for (j = 0; j < tn_params_count(run->nets[i].p) && !st; j++) {
            const tn_tensor *t = tn_params_get(run->nets[i].p, j);
            st = tn__train_copy_tensor(ck, "", t, t->data, run->method);
            if (!st && t->requires_grad) st = tn__train_copy_tensor(ck, "am.", t, run->nets[i].o->m[j], run->method);
            if (!st && t->requires_grad && run->nets[i].o->v[j]) st = tn__train_copy_tensor(ck, "av.", t, run->nets[i].o->v[j], run->method);
        }
    if (st) {
        tn_params_free(ck);
        return st;
    }
    *out = ck;
    return TN_OK;
}

TN_API tn_status tn_train_checkpoint(tn_train *run, const char *path)
{
    tn_params *ck = NULL;
    tn_status st;
    path = path ? path : run->o.checkpoint;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "%s: no checkpoint path", run->method);
    if ((st = tn__train_state(run, &ck))) return st;
    st = tn_params_save(path, ck);
    tn_params_free(ck);
    if (!st) {
        run->ckpts++;
        run->last_ck_it = run->it;
    }
    return st;
}

TN_API tn_status tn_train_open_checkpoint(tn_train *run, tn_params **ck)
{
    tn_status st;
    const char *m;
    TN_ASSERT(ck);
    *ck = NULL;
    if (!run->o.resume) return tn__fail(TN_ERR_INVALID_ARG, "%s: not resuming", run->method);
    if (!run->ck) {
        if ((st = tn_params_open(&run->ck, run->o.checkpoint))) return st;
        m = tn_params_meta(run->ck, "method");
        if (m && strcmp(m, run->method) != 0) {
            st = tn__fail(TN_ERR_FORMAT, "%s: a checkpoint of method '%s', not '%s'", run->o.checkpoint, m, run->method);
            tn_params_free(run->ck);
            run->ck = NULL;
            return st;
        }
    }
    *ck = run->ck;
    return TN_OK;
}

/* Copies a checkpoint tensor back; its presence and shape are required. */
static tn_status tn__train_take(const tn_params *ck, const char *prefix, const tn_tensor *t, float *data, const char *path)
{
    char name[64];
    const tn_tensor *c;
    int d;
    snprintf(name, sizeof name, "%s%s", prefix, t->name);
    c = tn_params_find(ck, name);
    if (!c) return tn__fail(TN_ERR_SHAPE, "%s: checkpoint has no tensor '%s'", path, name);
    for (d = 0; d < TN_MAX_DIMS; d++)
        if (c->ndim != t->ndim || c->shape[d] != t->shape[d]) return tn__fail(TN_ERR_SHAPE, "%s: checkpoint tensor '%s' has another shape", path, name);
    memcpy(data, c->data, t->numel * sizeof(float));
    return TN_OK;
}

TN_API tn_status tn_train_restore(tn_train *run)
{
    tn_params *ck;
    const char *path = run->o.checkpoint;
    char key[64];
    double it, us, step;
    long steps[TN__TRAIN_MAX];
    tn_rng rngs[TN__TRAIN_MAX];
    int i, j;
    tn_status st = tn_train_open_checkpoint(run, &ck);
    if (st) return st;
    /* every scalar first, so a bad file changes nothing */
    if (!tn__meta_get_whole(ck, "iteration", 2147483647.0, &it, path) || !tn__meta_get_whole(ck, "microseconds", 1e15, &us, path))
        return TN_ERR_CORRUPT;
    for (i = 0; i < run->nnets; i++) {
        snprintf(key, sizeof key, "step.%s", run->nets[i].name);
        if (!tn__meta_get_whole(ck, key, 2147483647.0, &step, path)) return TN_ERR_CORRUPT;
        steps[i] = (long)step;
    }
    for (i = 0; i < run->nrngs; i++) {
        const char *v;
        snprintf(key, sizeof key, "rng.%s", run->rngs[i].name);
        v = tn_params_meta(ck, key);
        if (!v || strlen(v) != 33 || v[16] != ':' || !tn__parse_hex64(v, 16, &rngs[i].state) || !tn__parse_hex64(v + 17, 16, &rngs[i].inc) ||
            !(rngs[i].inc & 1u))
            return tn__fail(TN_ERR_CORRUPT, "%s: bad RNG state '%s'", path, key);
    }
    for (i = 0; i < run->nsets; i++) /* then the tensors: presence and shapes */
        for (j = 0; j < tn_params_count(run->sets[i].p); j++) {
            tn_tensor *t = tn_params_get(run->sets[i].p, j);
            char name[64];
            const tn_tensor *c;
            snprintf(name, sizeof name, "%s%s", run->sets[i].name, t->name);
            if (!(c = tn_params_find(ck, name)) || c->numel != t->numel) return tn__fail(TN_ERR_SHAPE, "%s: checkpoint lacks '%s' or it has another size", path, name);
        }
    for (i = 0; i < run->nsets && !st; i++)
        for (j = 0; j < tn_params_count(run->sets[i].p) && !st; j++) {
            tn_tensor *t = tn_params_get(run->sets[i].p, j);
            st = tn__train_take(ck, run->sets[i].name, t, t->data, path);
        }
    for (i = 0; i < run->nnets && !st; i++)
        for (j = 0; j < tn_params_count(run->nets[i].p) && !st; j++) {
            tn_tensor *t = tn_params_get(run->nets[i].p, j);
            st = tn__train_take(ck, "", t, t->data, path);
            if (!st && t->requires_grad) st = tn__train_take(ck, "am.", t, run->nets[i].o->m[j], path);
            if (!st && t->requires_grad && run->nets[i].o->v[j]) st = tn__train_take(ck, "av.", t, run->nets[i].o->v[j], path);
        }
    if (st) return st;
    { /* checkpoints of older layouts may not name their seed */
        const char *sd = tn_params_meta(ck, "seed");
        uint64_t seed;
        if (sd && tn__parse_hex64(sd, strlen(sd), &seed)) run->o.seed = seed;
    }
    for (i = 0; i < run->nnets; i++) run->nets[i].o->step = steps[i];
    for (i = 0; i < run->nrngs; i++) *run->rngs[i].rng = rngs[i];
    tn_train_set_position(run, (long)it, us * 1e-6);
    return TN_OK;
}

/* ---- the loop ---- */

static void tn__train_eta(tn_train *run)
{
    double left = run->o.minutes * 60.0 - run->seconds, done = (double)(run->it - run->it0);
    if (run->o.max_iters && done > 0) {
        double per = (run->seconds - run->sec0) / done, by_iter = per * (double)(run->o.max_iters - run->it);
        if (by_iter < left) left = by_iter;
    }
    tn__progress_eta_s = left > 0 ? left : 0.0;
}

TN_API int tn_train_next(tn_train *run)
{
    double now, frac;
    if (run->stopped) return 0;
    now = tn_time_seconds();
    if (!run->started) {
        run->started = 1;
        run->t0 = run->last_ck = now;
        run->sec0 = run->seconds;
        run->it0 = run->last_ck_it = run->it;
    } else {
        run->it++;
        run->seconds = run->sec0 + (now - run->t0);
        if (run->o.checkpoint && run->o.checkpoint[0] &&
            (now - run->last_ck >= run->o.checkpoint_seconds || (run->o.checkpoint_iters && run->it % run->o.checkpoint_iters == 0))) {
            if ((run->st = tn__train_try_checkpoint(run))) {
                run->stopped = 1;
                return 0;
            }
            run->last_ck = now;
        }
        frac = tn_train_fraction(run);
        tn__train_eta(run);
        run->st = tn__progress(run->stage, frac);
        tn__progress_eta_s = -1.0;
        if (run->st) {
            run->stopped = 1;
            return 0;
        }
    }
    if (run->seconds >= run->o.minutes * 60.0 || (run->o.max_iters && run->it >= run->o.max_iters)) {
        run->stopped = 1;
        return 0;
    }
    return 1;
}

TN_API void tn_train_fail(tn_train *run, tn_status st)
{
    if (!run->st) run->st = st;
    run->stopped = 1;
}

TN_API tn_status tn_train_finish(tn_train *run)
{
    run->stopped = 1;
    if ((run->st == TN_OK || run->st == TN_ERR_CANCELLED) && run->o.checkpoint && run->o.checkpoint[0] && run->it != run->last_ck_it) {
        tn_status st = tn__train_try_checkpoint(run); /* leaves the cancel message alone when it succeeds */
        if (st) return st;
    }
    return run->st;
}

/* ---- model files ---- */

TN_API uint64_t tn_image_digest(const tn_image *img)
{
    uint64_t h = 0xcbf29ce484222325ULL;
    size_t n, i;
    int k, dims[3];
    if (!img || !img->data) return 0;
    dims[0] = img->width;
    dims[1] = img->height;
    dims[2] = img->channels;
    for (k = 0; k < 3; k++) {
        h ^= (uint64_t)(uint32_t)dims[k];
        h *= 0x100000001b3ULL;
    }
    n = (size_t)img->width * img->height * img->channels;
    for (i = 0; i < n; i++) {
        uint32_t u;
        memcpy(&u, &img->data[i], 4);
        for (k = 0; k < 4; k++) {
            h ^= (u >> (8 * k)) & 0xffu;
            h *= 0x100000001b3ULL;
        }
    }
    return h;
}

TN_API tn_status tn_model_stamp(tn_params *p, const char *method, int format, const tn_model_provenance *prov)
{
    char buf[64];
    tn_status st;
    TN_ASSERT(p && method);
    st = tn_params_set_meta(p, "method", method);
    if (!st) st = tn__meta_put_num(p, "format", (double)format);
    if (!st) st = tn_params_set_meta(p, "library", TN_VERSION_STRING);
    if (!st && prov) {
        tn__hex64(buf, prov->seed);
        st = tn_params_set_meta(p, "seed", buf);
        if (!st) st = tn__meta_put_num(p, "iterations", (double)prov->iterations);
        if (!st) st = tn__meta_put_num(p, "train_seconds", floor(prov->seconds * 1000.0 + 0.5) / 1000.0);
        if (!st && prov->example_digest) {
            char hex[20];
            tn__hex64(hex, prov->example_digest);
            snprintf(buf, sizeof buf, "%dx%dx%d:%s", prov->example_width, prov->example_height, prov->example_channels, hex);
            st = tn_params_set_meta(p, "example", buf);
        }
    }
    return st;
}

/* tn_model_stamp with the provenance of a finished run: its seed, iterations and seconds, and the
   example's digest and size (what each method's training does last). */
TN__SHARED tn_status tn__train_stamp(tn_params *p, const char *method, int format, const tn_train *run, uint64_t digest, int width,
                                     int height, int channels)
{
    tn_model_provenance pv;
    memset(&pv, 0, sizeof pv);
    pv.seed = tn_train_seed(run);
    pv.iterations = tn_train_iteration(run);
    pv.seconds = tn_train_seconds(run);
    pv.example_digest = digest;
    pv.example_width = width;
    pv.example_height = height;
    pv.example_channels = channels;
    return tn_model_stamp(p, method, format, &pv);
}

TN_API tn_status tn_model_check(const tn_params *p, const char *method, int max_format, const char *legacy_tensor, const char *name)
{
    const char *m = tn_params_meta(p, "method"), *kind = tn_params_meta(p, "kind");
    double f;
    name = name ? name : "model";
    if (!m) {
        if (legacy_tensor && tn_params_find(p, legacy_tensor)) return TN_OK;
        return tn__fail(TN_ERR_FORMAT, "%s: not a %s model (the file names no method)", name, method);
    }
    if (strcmp(m, method) != 0) return tn__fail(TN_ERR_FORMAT, "%s: a %s model, not a %s model", name, m, method);
    if (kind && !strcmp(kind, "checkpoint"))
        return tn__fail(TN_ERR_FORMAT, "%s: a %s training checkpoint, not a model (resume training from it)", name, method);
    if (!tn__meta_get_whole(p, "format", 1e6, &f, name)) return TN_ERR_CORRUPT;
    if (f > max_format)
        return tn__fail(TN_ERR_FORMAT, "%s: %s model format %.0f is newer than this library's (%d): update terrainnet", name, method, f, max_format);
    return TN_OK;
}

/* Opens a model file for a loader: tn_params_open, then tn_model_check. A file that names another
   method (or is a checkpoint, or a newer format) is refused from its metadata alone, before the
   CRC-32 and the tensors are read: a wrong loader costs a peek, not a parse. */
TN__SHARED tn_status tn__model_open(tn_params **out, const char *path, const char *method, int max_format, const char *legacy_tensor)
{
    uint8_t *buf = NULL;
    size_t n = 0;
    tn_params *head = NULL;
    tn_status st;
    *out = NULL;
    if ((st = tn__io_read_file(path, &buf, &n))) return st;
    if (tn__tnw_peek(buf, n, path, &head) == TN_OK && tn_params_meta(head, "method"))
        st = tn_model_check(head, method, max_format, legacy_tensor, path);
    else
        tn_clear_error(); /* a damaged header: the full read below says what is wrong */
    tn_params_free(head);
    if (!st) st = tn_params_open_memory(out, buf, n, path);
    if (!st) st = tn_model_check(*out, method, max_format, legacy_tensor, path);
    if (st) {
        tn_params_free(*out);
        *out = NULL;
    }
    TN_FREE(buf);
    return st;
}

/* Every value of a loaded model's weights is finite, else TN_ERR_CORRUPT naming the tensor. */
TN__SHARED tn_status tn__model_check_finite(const tn_params *p, const char *name)
{
    int i;
    for (i = 0; i < tn_params_count(p); i++) {
        const tn_tensor *t = tn_params_get(p, i);
        size_t k;
        for (k = 0; k < t->numel; k++)
            if (!isfinite(t->data[k])) return tn__fail(TN_ERR_CORRUPT, "%s: NaN/Inf in tensor '%s'", name, t->name);
    }
    return TN_OK;
}

/* The training iterations and seconds a model file records (0 where it records none). */
TN__SHARED void tn__model_training(const tn_params *f, const char *name, long *iterations, double *seconds)
{
    double v;
    const char *s = tn_params_meta(f, "train_seconds");
    *iterations = tn__meta_get_whole(f, "iterations", 1e15, &v, name) ? (long)v : 0;
    *seconds = s ? strtod(s, NULL) : 0.0;
    tn_clear_error();
}

/* ---- building blocks ---- */

TN_API void tn_ema_update(tn_params *avg, const tn_params *src, float decay, long step)
{
    float d = (float)(1.0 + (double)step) / (float)(10.0 + (double)step);
    int i;
    if (d > decay) d = decay;
    for (i = 0; i < tn_params_count(src); i++) {
        const tn_tensor *t = tn_params_get(src, i);
        tn_tensor *e;
        size_t k;
        if (!t->requires_grad || !(e = tn_params_find(avg, t->name))) continue;
        TN_ASSERT(e->numel == t->numel);
        for (k = 0; k < t->numel; k++) e->data[k] = d * e->data[k] + (1.0f - d) * t->data[k];
    }
}

TN_API tn_tensor *tn_activate(tn_ctx *ctx, tn_tensor *x, tn_activation act)
{
    switch (act) {
    case TN_ACT_RELU: return tn_relu(ctx, x);
    case TN_ACT_LEAKY: return tn_leaky_relu(ctx, x, 0.2f);
    case TN_ACT_TANH: return tn_tanh(ctx, x);
    case TN_ACT_SIGMOID: return tn_sigmoid(ctx, x);
    default: return x;
    }
}

/* Block tensors are named "<prefix><kind><i>" ("<prefix><kind>" for i < 0). */
static const char *tn__param_name(char *buf, size_t cap, const char *prefix, const char *kind, int i)
{
    if (i >= 0) snprintf(buf, cap, "%s%s%d", prefix, kind, i);
    else snprintf(buf, cap, "%s%s", prefix, kind);
    return buf;
}

static tn_tensor *tn__param_named(const tn_params *p, const char *prefix, const char *kind, int i)
{
    char name[64];
    return tn_params_find(p, tn__param_name(name, sizeof name, prefix, kind, i));
}

static tn_tensor *tn__param_new(tn_params *p, const char *prefix, const char *kind, int i, int ndim, const int *shape, int learned)
{
    char name[64];
    tn__param_name(name, sizeof name, prefix, kind, i);
    return learned ? tn_params_add(p, name, ndim, shape) : tn_params_add_buffer(p, name, ndim, shape);
}

TN_API tn_status tn_mlp_add(tn_params *p, const char *prefix, const int *widths, int n, tn_rng *rng)
{
    int i;
    if (n < 1 || n > 64 || !widths) return tn__fail(TN_ERR_INVALID_ARG, "MLP: %d layers", n);
    for (i = 0; i <= n; i++)
        if (widths[i] < 1) return tn__fail(TN_ERR_INVALID_ARG, "MLP: layer width %d", widths[i]);
    for (i = 0; i < n; i++) {
        int ws[2], bs = widths[i + 1];
        tn_tensor *w, *b;
        ws[0] = widths[i + 1];
        ws[1] = widths[i];
        w = tn__param_new(p, prefix, "w", i, 2, ws, 1);
        b = w ? tn__param_new(p, prefix, "b", i, 1, &bs, 1) : NULL;
        if (!b) return tn_last_error()[0] ? TN_ERR_INVALID_ARG : TN_ERR_OUT_OF_MEMORY;
        if (rng) tn_init_kaiming(w, rng, i < n - 1 ? 1.41f : 1.0f);
    }
    return TN_OK;
}

TN_API tn_tensor *tn_mlp(tn_ctx *ctx, const tn_params *p, const char *prefix, int n, tn_tensor *x, tn_activation act)
{
    int i;
    for (i = 0; i < n && x; i++) {
        x = tn_linear(ctx, x, tn__param_named(p, prefix, "w", i), tn__param_named(p, prefix, "b", i));
        if (i < n - 1) x = tn_activate(ctx, x, act);
    }
    return x;
}

TN_API tn_status tn_conv_block_add(tn_params *p, const char *prefix, int cin, int cout, int k, int norm, tn_rng *rng)
{
    int ws[4], bs = cout;
    tn_tensor *w, *g;
    if (cin < 1 || cout < 1 || k < 1 || !(k & 1)) return tn__fail(TN_ERR_INVALID_ARG, "conv block: %d -> %d channels, kernel %d (odd)", cin, cout, k);
    ws[0] = cout;
    ws[1] = cin;
    ws[2] = ws[3] = k;
    if (!(w = tn__param_new(p, prefix, "w", -1, 4, ws, 1)) || !tn__param_new(p, prefix, "b", -1, 1, &bs, 1)) return TN_ERR_INVALID_ARG;
    if (rng) tn_init_kaiming(w, rng, 1.41f);
    if (norm) {
        if (!(g = tn__param_new(p, prefix, "g", -1, 1, &bs, 1)) || !tn__param_new(p, prefix, "o", -1, 1, &bs, 1)) return TN_ERR_INVALID_ARG;
        tn_tensor_fill(g, 1.0f);
    }
    return TN_OK;
}

TN_API tn_tensor *tn_conv_block(tn_ctx *ctx, const tn_params *p, const char *prefix, tn_tensor *x, tn_activation act)
{
    tn_tensor *w = tn__param_named(p, prefix, "w", -1), *g = tn__param_named(p, prefix, "g", -1);
    tn_conv_opts co;
    TN_ASSERT(w);
    memset(&co, 0, sizeof co);
    co.pad = w->shape[2] / 2;
    x = tn_conv2d(ctx, x, w, tn__param_named(p, prefix, "b", -1), &co);
    if (g) x = tn_instance_norm(ctx, x, g, tn__param_named(p, prefix, "o", -1), 1e-5f);
    return tn_activate(ctx, x, act);
}

TN_API tn_status tn_patch_disc_add(tn_params *p, const char *prefix, int cin, int width, int layers, int k, tn_rng *rng, tn_patch_disc *d)
{
    int l, c = cin;
    TN_ASSERT(d && p && prefix);
    memset(d, 0, sizeof *d);
    if (layers < 0 || layers > TN_DISC_MAX_LAYERS || cin < 1 || width < 1 || (long)width << layers > 65536 || k < 1 || !(k & 1) ||
        strlen(prefix) >= sizeof d->prefix)
        return tn__fail(TN_ERR_INVALID_ARG, "patch discriminator: %d layers of width %d, kernel %d", layers, width, k);
    for (l = 0; l <= layers; l++) {
        int cout = l == layers ? 1 : width << l, ws[4];
        tn_tensor *w, *u;
        ws[0] = cout;
        ws[1] = c;
        ws[2] = ws[3] = k;
        if (!(w = tn__param_new(p, prefix, "w", l, 4, ws, 1)) || !tn__param_new(p, prefix, "b", l, 1, &cout, 1) ||
            !(u = tn__param_new(p, prefix, "u", l, 1, &cout, 0)))
            return TN_ERR_OUT_OF_MEMORY;
        c = cout;
    }
    d->p = p;
    strcpy(d->prefix, prefix);
    d->layers = layers;
    d->k = k;
    if (rng) /* initialised after every tensor exists: weights then vectors, layer by layer */
        for (l = 0; l <= layers; l++) {
            tn_init_kaiming(tn__param_named(p, prefix, "w", l), rng, 1.0f);
            tn_init_normal(tn__param_named(p, prefix, "u", l), rng, 0.0f, 1.0f);
        }
    return TN_OK;
}

TN_API void tn_patch_disc_begin(tn_ctx *ctx, tn_patch_disc *d)
{
    int l;
    for (l = 0; l <= d->layers; l++)
        d->wn[l] = tn_spectral_norm(ctx, tn__param_named(d->p, d->prefix, "w", l), tn__param_named(d->p, d->prefix, "u", l), 1);
}

TN_API tn_tensor *tn_patch_disc_features(tn_ctx *ctx, const tn_patch_disc *d, tn_tensor *x, tn_tensor **feats)
{
    tn_conv_opts co;
    int l;
    memset(&co, 0, sizeof co);
    co.pad = d->k / 2;
    for (l = 0; l <= d->layers; l++) {
        co.stride = l == d->layers ? 1 : 2;
        x = tn_conv2d(ctx, x, d->wn[l], tn__param_named(d->p, d->prefix, "b", l), &co);
        if (l < d->layers) x = tn_leaky_relu(ctx, x, 0.2f);
        if (l < d->layers && feats) feats[l] = x;
    }
    return x;
}

TN_API tn_tensor *tn_patch_disc_score(tn_ctx *ctx, const tn_patch_disc *d, tn_tensor *x)
{
    return tn_patch_disc_features(ctx, d, x, NULL);
}

struct tn_best_k {
    int k, n;
    tn_params **snap;
    double *score;
    long *iter;
};

TN_API tn_best_k *tn_best_k_create(int k)
{
    tn_best_k *b;
    if (k < 1 || k > 1024) {
        tn__fail(TN_ERR_INVALID_ARG, "best-k: k = %d (1..1024)", k);
        return NULL;
    }
    b = (tn_best_k *)tn__calloc(sizeof *b);
    if (!b) return NULL;
    b->k = k;
    b->snap = (tn_params **)tn__calloc((size_t)k * sizeof *b->snap);
    b->score = (double *)tn__calloc((size_t)k * sizeof *b->score);
    b->iter = (long *)tn__calloc((size_t)k * sizeof *b->iter);
    if (!b->snap || !b->score || !b->iter) {
        tn_best_k_free(b);
        return NULL;
    }
    return b;
}

TN_API void tn_best_k_free(tn_best_k *b)
{
    int i;
    if (!b) return;
    for (i = 0; b->snap && i < b->k; i++) tn_params_free(b->snap[i]);
    TN_FREE(b->snap);
    TN_FREE(b->score);
    TN_FREE(b->iter);
    TN_FREE(b);
}

/* A copy of p (tensors, flags and metadata). */
static tn_params *tn__params_clone(const tn_params *p)
{
    tn_params *c = tn_params_create();
    int i;
    for (i = 0; c && i < tn_params_count(p); i++) {
        const tn_tensor *t = tn_params_get(p, i);
        tn_tensor *d = t->requires_grad ? tn_params_add(c, t->name, t->ndim, t->shape) : tn_params_add_buffer(c, t->name, t->ndim, t->shape);
        if (!d) break;
        memcpy(d->data, t->data, t->numel * sizeof(float));
    }
    if (c && i < tn_params_count(p)) {
        tn_params_free(c);
        return NULL;
    }
    return c;
}

TN_API int tn_best_k_offer(tn_best_k *b, const tn_params *p, double score, long iteration)
{
    int pos, i;
    tn_params *c;
    if (score != score) return 0;
    for (pos = 0; pos < b->n && b->score[pos] <= score; pos++) {}
    if (pos >= b->k) return 0;
    if (!(c = tn__params_clone(p))) return 0;
    if (b->n == b->k) tn_params_free(b->snap[--b->n]);
    for (i = b->n; i > pos; i--) {
        b->snap[i] = b->snap[i - 1];
        b->score[i] = b->score[i - 1];
        b->iter[i] = b->iter[i - 1];
    }
    b->snap[pos] = c;
    b->score[pos] = score;
    b->iter[pos] = iteration;
    b->n++;
    return 1;
}

TN_API int tn_best_k_count(const tn_best_k *b) { return b ? b->n : 0; }

TN_API const tn_params *tn_best_k_get(const tn_best_k *b, int i, double *score, long *iteration)
{
    if (!b || i < 0 || i >= b->n) return NULL;
    if (score) *score = b->score[i];
    if (iteration) *iteration = b->iter[i];
    return b->snap[i];
}
#endif /* TN_NO_ENGINE */

