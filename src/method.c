/* ============================================================================================
   @@method  one interface for the learned methods: a descriptor each, found by name
   Each learned method (texgan, singan, gnn, kpd) registers one tn_method: its name (the
   method= metadata of its model files), its training options and their defaults, train,
   save/load/free, and the window of a whole-map output with the halo of input it reads. The
   world's learned stages, the CLI's `info` and bench_singan reach a model through it, so a new
   method is its own section file plus its descriptor here (docs/train.md, "Adding a learned
   method"). A field a method cannot support is NULL, and its comment says why.
   ============================================================================================ */
#ifndef TN_NO_ENGINE

/* What a method trains on. Nothing is owned. */
typedef struct tn_method_example {
    const tn_image *image;                  /* texgan, singan, gnn: the one example */
    const struct tn_season_sample *samples; /* kpd: dated pictures of heightfields */
    int count;                              /* of samples */
} tn_method_example;

/* What a window is generated from besides the model. Nothing is owned. */
typedef struct tn_method_input {
    uint64_t seed;                          /* the sample (texgan, singan, gnn); wins over the seed
                                               of opts */
    int width, height;                      /* gnn: the whole map (the sketch's canvas is scaled to
                                               it). texgan and singan sample an infinite plane and
                                               kpd the whole of dem: they ignore them */
    const struct tn_contour_set *sketch;    /* gnn */
    const tn_image *dem;                    /* kpd: heights in metres */
    const tn_image *insolation;             /* kpd: dem's 12-channel tn_insolation */
    const struct tn_climate *climate;       /* kpd */
    float time;                             /* kpd: months from mid-January */
    const void *opts;                       /* the method's generation options (tn_singan_gen_opts,
                                               tn_gnn_generate_opts); NULL = defaults. texgan and
                                               kpd have none */
} tn_method_input;

/* A learned method. Models are opaque here (void *): a tn_texgan, tn_singan, tn_gnn or tn_kpd
   allocated by train or load and released by free; a caller that knows the method may cast. */
typedef struct tn_method {
    const char *name;          /* "texgan", "singan", "gnn", "kpd": the model files' method= */
    const char *summary;       /* one line: what it learns and generates from what */
    const char *legacy_tensor; /* a tensor that names this method's files written before metadata
                                  (NULL = none) */
    size_t opts_size;          /* sizeof the method's training options (tn_gnn_opts, ...) */
    void (*defaults)(void *opts);  /* the method's own tn_x_defaults: what zero fields mean */
    /* Trains a new *model on ex with opts (the method's options struct, NULL = defaults); stats is
       the method's stats struct or NULL. */
    tn_status (*train)(void **model, const tn_method_example *ex, const void *opts, void *stats);
    tn_status (*save)(const char *path, const void *model);  /* the file first, as tn_x_save */
    /* A new *model from path; a file of another method or a checkpoint fails with TN_ERR_FORMAT. */
    tn_status (*load)(void **model, const char *path);
    void (*free)(void *model);  /* the model and its struct; NULL is fine */
    int (*channels)(const void *model);  /* of every generated window */
    /* Pixels of in->dem around a window that its pixels depend on (kpd); 0 when the method reads
       no input raster (texgan and singan sample a plane; gnn reads its whole sketch). */
    int (*halo)(const void *model);
    /* The pixels `window` of the whole-map output: equal to the same pixels of any larger window
       or of the whole map. *out is allocated here. */
    tn_status (*generate_window)(tn_image *out, const void *model, const tn_method_input *in, tn_rect window);
} tn_method;

/* The method called name, or NULL (unknown, or compiled out). */
TN_API const tn_method *tn_method_find(const char *name);
/* Method i of those compiled in (0, 1, ...), NULL past the end. */
TN_API const tn_method *tn_method_at(int i);
/* Loads the model at path with the method its method= metadata (or its legacy tensor) names:
   *m the method, *model the model (free with (*m)->free). A file that is not a model, or a model
   of a method this build does not have, fails with TN_ERR_FORMAT and says which. */
TN_API tn_status tn_method_load_any(const tn_method **m, void **model, const char *path);
#endif /* TN_NO_ENGINE */

/* --------------------------------------------------------------------------------------------
   >>method  (@@method implementation)
   Each descriptor wraps its method's own calls: a model struct allocated here around the
   method's load/train, which fill it in place; options passed through untouched, so each
   method's defaults stay in its own tn_x_defaults.
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_ENGINE

/* Hands a model filled by a method's load or train to the caller, or frees its struct when
   that failed (the method left nothing else allocated). */
TN__SHARED tn_status tn__method_keep(void **model, void *m, tn_status st)
{
    if (st) {
        TN_FREE(m);
        m = NULL;
    }
    *model = m;
    return st;
}

/* The defaults, load, save and free adapters of a method whose calls are tn_P_defaults(opts),
   tn_P_load(model, path), tn_P_save(path, model) and tn_P_free(model) on a model of TYPE. */
#define TN__METHOD_MODEL_OPS(P, TYPE, OPTS)                                                    \
    static void tn__method_##P##_defaults(void *o) { tn_##P##_defaults((OPTS *)o); }            \
    static tn_status tn__method_##P##_load(void **model, const char *path)                      \
    {                                                                                           \
        TYPE *m = (TYPE *)tn__calloc(sizeof(TYPE));                                             \
        return tn__method_keep(model, m, m ? tn_##P##_load(m, path) : tn__oom());               \
    }                                                                                           \
    static tn_status tn__method_##P##_save(const char *path, const void *model)                 \
    {                                                                                           \
        return tn_##P##_save(path, (const TYPE *)model);                                        \
    }                                                                                           \
    static void tn__method_##P##_free(void *model)                                              \
    {                                                                                           \
        if (model) tn_##P##_free((TYPE *)model);                                                \
        TN_FREE(model);                                                                         \
    }

/* The descriptor's fields from defaults to free, as the macros here and a method's own train
   (kpd) name them. */
#define TN__METHOD_OPS(P) tn__method_##P##_defaults, tn__method_##P##_train, tn__method_##P##_save, tn__method_##P##_load, tn__method_##P##_free

/* TN__METHOD_MODEL_OPS and train for a method that learns one example image:
   tn_P_train(model, image, opts, stats). */
#define TN__METHOD_IMAGE_OPS(P, TYPE, OPTS, STATS)                                              \
    TN__METHOD_MODEL_OPS(P, TYPE, OPTS)                                                         \
    static tn_status tn__method_##P##_train(void **model, const tn_method_example *ex, const void *opts, void *stats) \
    {                                                                                           \
        TYPE *m;                                                                                \
        *model = NULL;                                                                          \
        if (!ex || !ex->image) return tn__fail(TN_ERR_INVALID_ARG, #P " train: needs one example image (tn_method_example.image)"); \
        if (!(m = (TYPE *)tn__calloc(sizeof(TYPE)))) return tn__oom();                          \
        return tn__method_keep(model, m, tn_##P##_train(m, ex->image, (const OPTS *)opts, (STATS *)stats)); \
    }

/* *opts = the caller's generation options, or zeros (the method's defaults). */
TN__SHARED void tn__method_gen_opts(void *opts, size_t size, const void *given)
{
    if (given) memcpy(opts, given, size);
    else memset(opts, 0, size);
}

TN__SHARED int tn__method_no_halo(const void *model)
{
    (void)model;
    return 0;
}

TN__SHARED int tn__method_one_channel(const void *model)
{
    (void)model;
    return 1;
}

#ifndef TN_NO_TEXGAN
TN__METHOD_IMAGE_OPS(texgan, tn_texgan, tn_texgan_opts, tn_texgan_stats)

static int tn__method_texgan_channels(const void *model) { return ((const tn_texgan *)model)->channels; }

/* One generator pass holds the window's whole feature maps, so bands of 256 rows bound the
   memory; windows are exact, so the bands join seamlessly. */
static tn_status tn__method_texgan_window(tn_image *out, const void *model, const tn_method_input *in, tn_rect r)
{
    const tn_texgan *m = (const tn_texgan *)model;
    tn_image img = {0, 0, 0, NULL}, band = {0, 0, 0, NULL};
    tn_status st;
    int y0;
    if ((st = tn_image_create(&img, r.w, r.h, m->channels))) return st;
    for (y0 = 0; y0 < r.h && !st; y0 += 256) {
        int bh = r.h - y0 < 256 ? r.h - y0 : 256;
        st = tn_texgan_synthesize_window(&band, m, in->seed, r.x, r.y + y0, r.w, bh);
        if (!st) memcpy(img.data + (size_t)y0 * r.w * m->channels, band.data, (size_t)bh * r.w * m->channels * sizeof(float));
        tn_image_free(&band);
    }
    if (st) tn_image_free(&img);
    else *out = img;
    return st;
}

static const tn_method tn__method_texgan = {"texgan", "spatial GAN of one texture or heightfield: windows of an infinite texture per seed",
    "texgan.config", sizeof(tn_texgan_opts), TN__METHOD_OPS(texgan), tn__method_texgan_channels, tn__method_no_halo, tn__method_texgan_window};
#endif

#ifndef TN_NO_SINGAN
TN__METHOD_IMAGE_OPS(singan, tn_singan, tn_singan_opts, tn_singan_stats)

static tn_status tn__method_singan_window(tn_image *out, const void *model, const tn_method_input *in, tn_rect r)
{
    tn_singan_gen_opts go;
    tn__method_gen_opts(&go, sizeof go, in->opts);
    go.seed = in->seed;
    return tn_singan_sample(out, (const tn_singan *)model, r.x, r.y, r.w, r.h, &go);
}

static const tn_method tn__method_singan = {"singan", "multi-scale GAN of one DEM: windows of an infinite terrain per seed, in the example's metres",
    NULL, sizeof(tn_singan_opts), TN__METHOD_OPS(singan), tn__method_one_channel, tn__method_no_halo, tn__method_singan_window};
#endif

#ifndef TN_NO_GNN
TN__METHOD_IMAGE_OPS(gnn, tn_gnn, tn_gnn_opts, tn_gnn_stats)

static tn_status tn__method_gnn_window(tn_image *out, const void *model, const tn_method_input *in, tn_rect r)
{
    tn_gnn_generate_opts go;
    if (!in->sketch) return tn__fail(TN_ERR_INVALID_ARG, "gnn generate: needs a sketch (tn_method_input.sketch)");
    tn__method_gen_opts(&go, sizeof go, in->opts);
    go.seed = in->seed;
    return tn_gnn_generate_window(out, (const tn_gnn *)model, in->sketch, in->width, in->height, r.x, r.y, r.w, r.h, &go);
}

static const tn_method tn__method_gnn = {"gnn", "sketch-to-terrain graph network of one DEM: terrain following a sketch, in the example's metres",
    NULL, sizeof(tn_gnn_opts), TN__METHOD_OPS(gnn), tn__method_one_channel, tn__method_no_halo, tn__method_gnn_window};
#endif

#ifndef TN_NO_SEASON
TN__METHOD_MODEL_OPS(kpd, tn_kpd, tn_kpd_opts)

static tn_status tn__method_kpd_train(void **model, const tn_method_example *ex, const void *opts, void *stats)
{
    tn_kpd *m;
    *model = NULL;
    if (!ex || !ex->samples || ex->count < 1)
        return tn__fail(TN_ERR_INVALID_ARG, "kpd train: needs dated samples (tn_method_example.samples, count)");
    if (!(m = (tn_kpd *)tn__calloc(sizeof *m))) return tn__oom();
    return tn__method_keep(model, m, tn_kpd_train(m, ex->samples, ex->count, (const tn_kpd_opts *)opts, (tn_kpd_stats *)stats));
}

static int tn__method_kpd_channels(const void *model) { return ((const tn_kpd *)model)->out_channels; }

static int tn__method_kpd_halo(const void *model)
{
    (void)model;
    return TN_KPD_HALO;
}

static tn_status tn__method_kpd_window(tn_image *out, const void *model, const tn_method_input *in, tn_rect r)
{
    if (!in->dem || !in->climate) return tn__fail(TN_ERR_INVALID_ARG, "kpd generate: needs a dem and a climate (tn_method_input)");
    return tn_kpd_generate(out, (const tn_kpd *)model, in->dem, in->climate, in->insolation, in->time, r.x, r.y, r.w, r.h);
}

static const tn_method tn__method_kpd = {"kpd", "seasonal texture network (KPD) of dated pictures: a DEM's texture under a climate at a time of the year",
    NULL, sizeof(tn_kpd_opts), TN__METHOD_OPS(kpd), tn__method_kpd_channels, tn__method_kpd_halo, tn__method_kpd_window};
#endif

/* The registry: one line a method (NULL ends it, so it may be empty when all are compiled out). */
static const tn_method *const tn__methods[] = {
#ifndef TN_NO_TEXGAN
    &tn__method_texgan,
#endif
#ifndef TN_NO_SINGAN
    &tn__method_singan,
#endif
#ifndef TN_NO_GNN
    &tn__method_gnn,
#endif
#ifndef TN_NO_SEASON
    &tn__method_kpd,
#endif
    NULL};

TN_API const tn_method *tn_method_at(int i)
{
    int k;
    for (k = 0; tn__methods[k] && k < i; k++) {}
    return i >= 0 ? tn__methods[k] : NULL;
}

TN_API const tn_method *tn_method_find(const char *name)
{
    int k;
    for (k = 0; name && tn__methods[k]; k++)
        if (!strcmp(tn__methods[k]->name, name)) return tn__methods[k];
    return NULL;
}

TN_API tn_status tn_method_load_any(const tn_method **m, void **model, const char *path)
{
    tn_params *f = NULL;
    const tn_method *found = NULL;
    const char *name = NULL;
    uint8_t *buf = NULL;
    size_t n = 0;
    tn_status st;
    int k;
    TN_ASSERT(m && model);
    *m = NULL;
    *model = NULL;
    if ((st = tn__io_read_file(path, &buf, &n))) return st;
    if (tn__tnw_peek(buf, n, path, &f) == TN_OK) name = tn_params_meta(f, "method"); /* the method's loader does the full read */
    if (!name) { /* a file of before the metadata (its legacy tensor names the method), or a damaged header: read it all */
        tn_params_free(f);
        f = NULL;
        tn_clear_error();
        st = tn_params_open_memory(&f, buf, n, path);
    }
    TN_FREE(buf);
    if (st) return st;
    if (name) found = tn_method_find(name);
    for (k = 0; !name && tn__methods[k]; k++)
        if (tn__methods[k]->legacy_tensor && tn_params_find(f, tn__methods[k]->legacy_tensor)) found = tn__methods[k];
    if (!found && name) st = tn__fail(TN_ERR_FORMAT, "%s: a model of method '%s', which this build does not have", path, name);
    else if (!found) st = tn__fail(TN_ERR_FORMAT, "%s: not a model (the file names no method)", path);
    tn_params_free(f);
    if (st) return st;
    if ((st = found->load(model, path))) return st;
    *m = found;
    return TN_OK;
}
#endif /* TN_NO_ENGINE */
