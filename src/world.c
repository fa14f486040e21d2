/* ============================================================================================
   @@world  worlds in tiles: a generator and local operations, computed tile by tile
   A world is a pipeline (one generator, then local operations) over a raster far larger than
   memory, cut into tiles that are computed alone, in any order, on any machine: a tile is
   exactly the pixels a whole-map run would have there (the halo contract). A generator computes
   any rectangle from global pixel positions and the seed; an operation of halo h computes a
   rectangle from its input grown by h (tn_rect_halo), so a tile needs the sum of the halos
   around it. What cannot be local (style transfer, depression filling, flow accumulation,
   colour correction) is refused with the reason; seasonal texturing (procedural, or the KPD
   network) is local with its horizon search bounded (distance=). docs/world.md lists each
   method's halo.
   SPEC text, one setting or stage a line ('#' starts a comment):
       world 16384 16384         size of the generator's raster in pixels (width height)
       seed 42
       height 0 3000             metres of generator value 0 and 1 = the 16-bit range of every tile
       cellsize 30               metres per pixel (optional; 0 = auto: relief spans 10% of the side)
       tile 1024                 output tile side (optional)
       perlin frequency=16 octaves=10
       hillshade azimuth=315
   ============================================================================================ */
#ifndef TN_NO_WORLD
#if defined(TN_NO_ENGINE) || defined(TN_NO_NOISE) || defined(TN_NO_SKETCH) || defined(TN_NO_TEXGAN) || defined(TN_NO_SINGAN) || defined(TN_NO_GNN) || defined(TN_NO_SEASON) || defined(TN_NO_EXPORT)
#error "terrainnet: @@world needs the tensor engine, @@noise, @@sketch, @@texgan, @@singan, @@gnn, @@season, @@export; define TN_NO_WORLD too, or none of them"
#endif

typedef struct tn_world {
    int width, height;         /* the generator's raster in pixels */
    int tile;                  /* output tile side in pixels */
    uint64_t seed;
    float lo, hi;              /* metres of generator value 0 and 1; the range of every height tile */
    float cellsize;            /* metres per pixel; 0 = auto (hillshade's relief rule on lo..hi) */
    int out_width, out_height, out_channels; /* the pipeline's output raster */
    int out_heights;           /* 1: tiles hold heights in metres (16-bit PNG, range lo..hi recorded);
                                  0: values in [0, 1] (8-bit PNG: shading, normals, colour) */
    int rows, cols;            /* the tile grid over the output raster */
    int halo;                  /* generator pixels of context a tile needs on each side */
    uint64_t digest;           /* of the normalised SPEC text */
    char *text;                /* the normalised SPEC (DIR/world.spec holds it); library-owned */
    void *impl;                /* the stages; library-owned */
} tn_world;

typedef struct tn_world_opts {
    int tile;                  /* overrides the SPEC's tile side (16..65536); 0 = the SPEC's, else 1024 */
    const char *base_dir;      /* where relative model paths in the SPEC start; NULL = the SPEC file's
                                  directory (tn_world_load) or the working directory (tn_world_parse) */
} tn_world_opts;

/* Parses a SPEC (text, NUL-terminated) into *w (free with tn_world_free). Unknown settings,
   methods or parameters, a pipeline without a generator first, non-local methods and halos
   the world is too small for fail with TN_ERR_INVALID_ARG and say why. opts may be NULL. */
TN_API tn_status tn_world_parse(tn_world *w, const char *text, const tn_world_opts *opts);
/* Reads and parses a SPEC file. */
TN_API tn_status tn_world_load(tn_world *w, const char *path, const tn_world_opts *opts);
TN_API void tn_world_free(tn_world *w);
/* Any rectangle of the output raster, in global pixel coordinates (inside the raster): the same
   pixels a whole-map run gives there. Memory is bounded by the rectangle plus its halo. */
TN_API tn_status tn_world_rect(tn_image *out, const tn_world *w, tn_rect r);
/* Tile (row, col) of the grid: columns col * tile .., rows row * tile .. (smaller at the far edges). */
TN_API tn_rect tn_world_tile_rect(const tn_world *w, int row, int col);

typedef struct tn_world_run_opts {
    int row0, row1, col0, col1; /* tiles rows [row0, row1) x columns [col0, col1); row1 = 0: all rows,
                                   col1 = 0: all columns */
    int part, parts;            /* take the k-th selected tile (row-major) when k % parts == part;
                                   parts 0 = 1 (MPI ranks, job arrays) */
} tn_world_run_opts;

typedef struct tn_world_run_stats {
    int written, skipped;      /* tiles computed and written; tiles already in DIR */
    int repaired;              /* of the written: files in DIR that did not match the manifest's size
                                  and digest (or, unlisted, did not decode as this world's tile) */
    double seconds;
} tn_world_run_stats;

/* Writes the selected tiles as DIR/r{row}_c{col}.png (created atomically; a tile already there
   is skipped, so a run resumes, when it matches DIR/manifest.txt's size and digest or, unlisted,
   decodes as this tile; a damaged or foreign file is computed again). DIR must exist; DIR/world.spec is written on
   first use and a different world in DIR is refused. Progress stage "world". stats may be NULL. */
TN_API tn_status tn_world_write_tiles(const char *dir, const tn_world *w, const tn_world_run_opts *opts,
                                      tn_world_run_stats *stats);
/* Writes DIR/world.vrt (a GDAL mosaic of the whole grid, heights in metres through the band's
   offset and scale; above 64 x 64 tiles a mosaic of DIR/world_bI_J.vrt, each of 64 x 64 tiles)
   and DIR/manifest.txt (version, seed, SPEC digest, and each present tile's FNV-1a 64 digest of
   its file bytes and its size; a file that fails the check above is not present), both
   atomically. present (may be NULL) gets the count. */
TN_API tn_status tn_world_write_index(const char *dir, const tn_world *w, int *present);
/* One line on world method i ("perlin: generator, halo 0; frequency= ..."), NULL past the end. */
TN_API const char *tn_world_method_help(int i);
#endif /* TN_NO_WORLD */

/* --------------------------------------------------------------------------------------------
   >>world  (@@world implementation)
   A stage computes any rectangle of its own raster. The runner asks the stage below it for the
   rectangle grown by the stage's halo (tn_rect_halo, scaled by the stage's factor) and hands
   that over with its position; a generator computes from global positions alone. So a tile is
   the whole-map pixels whenever every stage is, and memory holds one rectangle per stage.
   A new method is one row of tn__world_methods: setup (parameters -> halo, factor, output
   raster) and run (rectangle + grown input -> rectangle).
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_WORLD

#define TN__WORLD_MAX_KV 8
#define TN__WORLD_MAX_STAGES 16
#define TN__WORLD_MAX_SIDE (1 << 28)
/* The grid's bound: the index lists every tile (a VRT source, a manifest check each), so a grid
   of 2^48 tiles hung the index writer; 2^20 tiles keep it to seconds. Above TN__WORLD_VRT_BLOCK^2
   tiles, world.vrt is a mosaic of block VRTs of that many tiles a side, each file a few MB. */
#define TN__WORLD_MAX_TILES (1 << 20)
#define TN__WORLD_VRT_BLOCK 64

struct tn__world_method;

typedef struct tn__world_stage {
    const struct tn__world_method *m;
    int line;                             /* SPEC line, for messages */
    int nkv;
    char key[TN__WORLD_MAX_KV][32];
    char val[TN__WORLD_MAX_KV][512];
    unsigned used;                        /* bit k: key k was read by setup */
    int halo;                             /* input pixels of context on each side */
    int factor;                           /* input pixels per output pixel (1: same raster) */
    int in_w, in_h, in_c, in_heights;     /* the input raster (none for a generator) */
    int out_w, out_h, out_c, out_heights; /* this stage's raster */
    float p[8];                           /* method parameters */
    int np;                               /* explicit noise: how many sigmas in p[2..] */
    const tn_method *method;              /* a learned stage's (texgan, singan, gnn, singan-refine, kpd) */
    void *model;                          /* its model (method->free) */
    tn_method_input input;                /* a learned generator's: the world's seed and size */
    tn_climate *climate;                  /* season, kpd */
    tn_gnn_prepared *gnn;                 /* gnn: the generation prepared at setup (the gain tested once) */
    tn_singan_prepared *singan;           /* singan: the world's map prepared at setup (its gate; its layout with layout=1) */
} tn__world_stage;

typedef struct tn__world_method {
    const char *name;
    int source;          /* 1: a generator (the first stage, and only there) */
    const char *refuse;  /* not NULL: cannot be computed tile by tile, and why */
    const char *help;    /* parameters and halo, for tn_world_method_help */
    tn_status (*setup)(tn__world_stage *s, const tn_world *w, const char *base_dir);
    tn_status (*run)(const tn__world_stage *s, const tn_world *w, tn_rect r, const tn_image *in, tn_rect in_r, tn_image *out);
} tn__world_method;

typedef struct tn__world_impl {
    int n;
    tn__world_stage st[TN__WORLD_MAX_STAGES];
} tn__world_impl;

/* ---- stage parameters ---- */

static int tn__world_find(tn__world_stage *s, const char *key)
{
    int k;
    for (k = 0; k < s->nkv; k++)
        if (!strcmp(s->key[k], key)) {
            s->used |= 1u << k;
            return k;
        }
    return -1;
}

/* Parameter `key` as a number in [lo, hi] (def when absent). */
static tn_status tn__world_num(tn__world_stage *s, const char *key, double def, double lo, double hi, double *out)
{
    int k = tn__world_find(s, key);
    double v;
    *out = def;
    if (k < 0) return TN_OK;
    if (!tn__io_number(s->val[k], strlen(s->val[k]), &v) || !(v >= lo && v <= hi))
        return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: %s %s=%s must be a number from %g to %g", s->line, s->m->name, key,
                        s->val[k], lo, hi);
    *out = v;
    return TN_OK;
}

/* Metres per input pixel for slopes: the SPEC's cellsize, else hillshade's "auto" rule applied
   to the world's height range (not to a tile's, which would differ from tile to tile). */
static float tn__world_spacing(const tn__world_stage *s, const tn_world *w)
{
    int side = s->in_w > s->in_h ? s->in_w : s->in_h;
    float f = (float)w->width / (float)s->in_w;
    if (w->cellsize > 0) return w->cellsize * f;
    return w->hi > w->lo ? (w->hi - w->lo) / (TN__SHADE_AUTO_RELIEF * (float)side) : 1.0f;
}

static tn_status tn__world_need_heights(const tn__world_stage *s)
{
    if (s->in_heights) return TN_OK;
    return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: %s needs heights, but the stage before it gives values in [0, 1]", s->line,
                    s->m->name);
}

/* A Gaussian of `radius` (tn_image_blur's kernel) must fit the raster the whole-map run blurs,
   else that run folds the kernel and a tile cannot match it. */
static tn_status tn__world_fits(const tn__world_stage *s, int radius, int w, int h)
{
    if (radius < w && radius < h) return TN_OK;
    return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: %s: a halo of %d pixels needs a raster larger than %d x %d", s->line,
                    s->m->name, radius, w, h);
}

static void tn__world_same_raster(tn__world_stage *s)
{
    s->out_w = s->in_w;
    s->out_h = s->in_h;
    s->out_c = s->in_c;
    s->out_heights = s->in_heights;
    s->factor = 1;
}

/* A stage that keeps the raster's size and makes a picture of c channels, not heights. */
static void tn__world_picture_raster(tn__world_stage *s, int c)
{
    tn__world_same_raster(s);
    s->out_c = c;
    s->out_heights = 0;
}

/* out = the r part of img, which covers img_r. */
static tn_status tn__world_crop(const tn_image *img, tn_rect img_r, tn_rect r, tn_image *out)
{
    return tn_image_crop(out, img, r.x - img_r.x, r.y - img_r.y, r.w, r.h);
}

/* ---- generators ---- */

static tn_status tn__world_perlin_setup(tn__world_stage *s, const tn_world *w, const char *base_dir)
{
    tn_perlin_opts o, chk;
    double v[6];
    tn_status st;
    float amp = 1.0f, sum = 0.0f;
    int i;
    (void)base_dir;
    if ((st = tn__world_num(s, "frequency", 4, 1e-6, 1e6, &v[0])) || (st = tn__world_num(s, "octaves", 8, 1, 24, &v[1])) ||
        (st = tn__world_num(s, "lacunarity", 2, 1e-3, 16, &v[2])) || (st = tn__world_num(s, "gain", 0.5, 1e-6, 4, &v[3])) ||
        (st = tn__world_num(s, "contrast", 1, 1e-6, 1e6, &v[4])) || (st = tn__world_num(s, "periodic", 0, 0, 1, &v[5])))
        return st;
    memset(&o, 0, sizeof o);
    o.frequency = (float)v[0];
    o.octaves = (int)v[1];
    o.lacunarity = (float)v[2];
    o.gain = (float)v[3];
    o.periodic = v[5] != 0;
    if ((st = tn__perlin_resolve(&o, &chk))) return st;
    for (i = 0; i < o.octaves; i++, amp *= o.gain) sum += amp;
    for (i = 0; i < 6; i++) s->p[i] = (float)v[i];
    s->p[6] = sum;
    s->out_w = w->width;
    s->out_h = w->height;
    s->out_c = 1;
    s->out_heights = 1;
    return TN_OK;
}

/* Value v in [0, 1] (nominal) -> metres. */
static float tn__world_metres(const tn_world *w, float v) { return w->lo + v * (w->hi - w->lo); }

/* Perlin fBm at global positions. tn_noise_perlin stretches each map to its own min..max, a
   whole-map statistic; here the fixed bound of improved noise (|n| <= 1 per octave, so |fBm|
   <= the sum of amplitudes S) maps it instead: v = 0.5 + 0.5 contrast fBm / S. */
static tn_status tn__world_perlin_run(const tn__world_stage *s, const tn_world *w, tn_rect r, const tn_image *in, tn_rect in_r,
                                      tn_image *out)
{
    tn_perlin_opts o;
    tn_image img = {0, 0, 0, NULL};
    tn_status st;
    size_t i, n = (size_t)r.w * r.h;
    float k = 0.5f * s->p[4] / s->p[6];
    (void)in;
    (void)in_r;
    memset(&o, 0, sizeof o);
    o.seed = w->seed;
    o.frequency = s->p[0];
    o.octaves = (int)s->p[1];
    o.lacunarity = s->p[2];
    o.gain = s->p[3];
    o.periodic = s->p[5] != 0;
    if ((st = tn_image_create(&img, r.w, r.h, 1))) return st;
    if ((st = tn__perlin_window(&o, w->width, w->height, r.x, r.y, r.w, r.h, img.data))) {
        tn_image_free(&img);
        return st;
    }
    for (i = 0; i < n; i++) img.data[i] = tn__world_metres(w, 0.5f + k * img.data[i]);
    *out = img;
    return TN_OK;
}

static int tn__world_gauss_radius(float sigma) { return (int)floor(4.0 * sigma + 0.5); }

static tn_status tn__world_explicit_setup(tn__world_stage *s, const tn_world *w, const char *base_dir)
{
    double layers, contrast;
    tn_status st;
    int k = tn__world_find(s, "sigma"), i;
    (void)base_dir;
    if ((st = tn__world_num(s, "layers", 5, 1, 30, &layers)) || (st = tn__world_num(s, "contrast", 1, 1e-6, 1e6, &contrast))) return st;
    s->p[0] = (float)layers;
    s->p[1] = (float)contrast;
    if (k < 0) { /* tn_noise_explicit's defaults at 1024 px: a world-size sigma would need a world-size halo */
        s->p[2] = 16.0f;
        s->p[3] = 32.0f;
        s->np = 2;
    } else {
        const char *v = s->val[k];
        while (*v) {
            size_t len = strcspn(v, ",");
            double x;
            if (s->np >= 6 || !tn__io_number(v, len, &x) || !(x >= 0 && x <= 1e4))
                return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: explicit sigma=%s must be up to 6 numbers 0..1e4, e.g. sigma=16,32",
                                s->line, s->val[k]);
            s->p[2 + s->np++] = (float)x;
            v += len + (v[len] == ',');
        }
    }
    s->halo = 0;
    for (i = 0; i < s->np; i++) {
        if (s->p[2 + i] <= 0) continue;
        if ((st = tn__world_fits(s, tn__world_gauss_radius(s->p[2 + i]), w->width, w->height))) return st;
        s->halo += tn__world_gauss_radius(s->p[2 + i]);
    }
    s->out_w = w->width;
    s->out_h = w->height;
    s->out_c = 1;
    s->out_heights = 1;
    return TN_OK;
}

/* Uniform [0, 1) of (seed, layer, cell): a hash, so any cell is computed alone. */
static float tn__world_cell_uniform(uint64_t seed, int layer, int cx, int cy)
{
    uint64_t h = tn__splitmix64(tn__splitmix64(seed ^ ((uint64_t)layer << 58)) ^ (((uint64_t)(uint32_t)cy << 32) | (uint32_t)cx));
    return (float)(h >> 40) * (1.0f / 16777216.0f);
}

/* Explicit noise (Algorithm 1 as tn_noise_explicit) made position-based: layer i's random matrix
   ((W >> i) x (H >> i) cells) is a hash of each cell instead of an RNG sequence, the layers are
   averaged, then smoothed by the sigmas: computed on r grown by their radii, which the
   generator's own halo covers. No min..max stretch (a whole-map statistic): v = 0.5 +
   contrast (mean - 0.5). */
static tn_status tn__world_explicit_run(const tn__world_stage *s, const tn_world *w, tn_rect r, const tn_image *in, tn_rect in_r,
                                        tn_image *out)
{
    tn_rect g = tn_rect_halo(r, s->halo, w->width, w->height);
    tn_image img = {0, 0, 0, NULL}, res = {0, 0, 0, NULL};
    int layers = (int)s->p[0], x, y, l, i;
    tn_status st;
    size_t n;
    (void)in;
    (void)in_r;
    if ((st = tn_image_create(&img, g.w, g.h, 1))) return st;
    for (y = 0; y < g.h; y++)
        for (x = 0; x < g.w; x++) {
            float acc = 0.0f;
            for (l = 1; l <= layers; l++) {
                long long sw = w->width >> l, sh = w->height >> l, gx = g.x + x, gy = g.y + y;
                if (sw < 1) sw = 1;
                if (sh < 1) sh = 1;
                acc += tn__world_cell_uniform(w->seed, l, (int)((2 * gx + 1) * sw / (2LL * w->width)),
                                              (int)((2 * gy + 1) * sh / (2LL * w->height)));
            }
            img.data[(size_t)y * g.w + x] = acc / (float)layers;
        }
    for (i = 0; i < s->np && !st; i++)
        if (s->p[2 + i] > 0) st = tn_image_blur(&img, &img, s->p[2 + i]);
    if (!st) st = tn__world_crop(&img, g, r, &res);
    tn_image_free(&img);
    if (st) return st;
    n = (size_t)r.w * r.h;
    for (i = 0; i < (int)n; i++) res.data[i] = tn__world_metres(w, 0.5f + s->p[1] * (res.data[i] - 0.5f));
    *out = res;
    return TN_OK;
}

/* "dir/path" unless path is absolute or dir is empty; malloc'ed. */
static char *tn__world_join(const char *dir, const char *path)
{
    size_t a = dir ? strlen(dir) : 0, b = strlen(path);
    char *p = (char *)tn__alloc(a + b + 2);
    if (!p) return NULL;
    if (!a || path[0] == '/') memcpy(p, path, b + 1);
    else {
        memcpy(p, dir, a);
        p[a] = '/';
        memcpy(p + a + 1, path, b + 1);
    }
    return p;
}

/* A learned stage's model=FILE.tnw, loaded by the method of that name (@@method), which refuses
   another method's file. A generator's raster is the world's, one channel of heights unless the
   setup says otherwise. */
static tn_status tn__world_model(tn__world_stage *s, const tn_world *w, const char *base_dir, const char *method)
{
    int k = tn__world_find(s, "model");
    char *path;
    tn_status st;
    if (k < 0) return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: %s needs model=FILE.tnw", s->line, s->m->name);
    if (!(path = tn__world_join(base_dir, s->val[k]))) return tn__oom();
    s->method = tn_method_find(method);
    st = s->method->load(&s->model, path);
    TN_FREE(path);
    if (st) {
        char where[64];
        snprintf(where, sizeof where, "world: line %d: %s", s->line, s->m->name);
        return tn__fail_context(st, where);
    }
    s->input.seed = w->seed;
    s->input.width = w->width;
    s->input.height = w->height;
    s->out_w = w->width;
    s->out_h = w->height;
    s->out_c = s->method->channels(s->model);
    s->out_heights = 1;
    return TN_OK;
}

/* A learned generator's windows are exact (tn_method.generate_window): a tile is its own window
   of the world-sized map, at the world's seed. */
static tn_status tn__world_learned_run(const tn__world_stage *s, const tn_world *w, tn_rect r, const tn_image *in, tn_rect in_r,
                                       tn_image *out)
{
    (void)w;
    (void)in;
    (void)in_r;
    return s->method->generate_window(out, s->model, &s->input, r);
}

static tn_status tn__world_texgan_setup(tn__world_stage *s, const tn_world *w, const char *base_dir)
{
    tn_status st = tn__world_model(s, w, base_dir, "texgan");
    if (st) return st;
    if (s->out_c > 4)
        return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: texgan model with %d channels; a tile holds at most 4", s->line, s->out_c);
    s->out_heights = s->out_c == 1; /* a one-channel model learnt a heightfield */
    return TN_OK;
}

/* Values map from the texture GAN's range to metres (one channel) or to [0, 1]. */
static tn_status tn__world_texgan_run(const tn__world_stage *s, const tn_world *w, tn_rect r, const tn_image *in, tn_rect in_r,
                                      tn_image *out)
{
    const tn_texgan *m = (const tn_texgan *)s->model;
    float span = m->hi > m->lo ? m->hi - m->lo : 1.0f;
    tn_status st = tn__world_learned_run(s, w, r, in, in_r, out);
    size_t i, n = (size_t)r.w * r.h * m->channels;
    for (i = 0; !st && i < n; i++) {
        float v = (out->data[i] - m->lo) / span;
        out->data[i] = s->out_heights ? tn__world_metres(w, v) : v;
    }
    return st;
}

/* SinGAN samples are exact windows of one infinite terrain per seed (tn_singan_sample), already
   in the model's metres; the world's height range clips them. With layout=1 the world is one
   laid-out map (the example's arrangement, rearranged and bent). What every tile shares (the
   gate, and with layout=1 the layout of the whole world) is made once here (tn_singan_prepare);
   the tiles are windows of it. */
static tn_status tn__world_singan_setup(tn__world_stage *s, const tn_world *w, const char *base_dir)
{
    tn_singan_gen_opts go;
    double layout;
    tn_status st = tn__world_model(s, w, base_dir, "singan");
    if (st || (st = tn__world_num(s, "layout", 0, 0, 1, &layout))) return st;
    if (layout != 0 && layout != 1) return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: singan layout=%g must be 0 or 1", s->line, layout);
    memset(&go, 0, sizeof go);
    go.seed = w->seed;
    go.layout = (int)layout;
    return tn_singan_prepare(&s->singan, (const tn_singan *)s->model, w->width, w->height, &go);
}

static tn_status tn__world_singan_run(const tn__world_stage *s, const tn_world *w, tn_rect r, const tn_image *in, tn_rect in_r,
                                      tn_image *out)
{
    (void)w;
    (void)in;
    (void)in_r;
    return tn_singan_prepared_window(out, s->singan, r.x, r.y, r.w, r.h);
}

/* GNN terrain of a sketch: tn_gnn_prepare once at setup (the sketch, its canvas scaled to the
   world, grown, cut into parts and rasterised at the world's size, the gain tested), then each
   tile is a tn_gnn_prepared_window (exact windows: a pixel depends on the sketch within 2 rounds
   (radius + 13) px and the membrane's blocks). The prepared generation holds about 20 bytes per
   world pixel, so the row is capped at TN__WORLD_GNN_MAX_PX. The fine-tune (a whole-map
   optimisation) is not offered. */
#define TN__WORLD_GNN_MAX_PX (4096LL * 4096LL)

static tn_status tn__world_gnn_setup(tn__world_stage *s, const tn_world *w, const char *base_dir)
{
    static const char *hname[3] = {"auto", "example", "unit"}, *ename[3] = {"auto", "aligned", "none"};
    int ks = tn__world_find(s, "sketch"), kh = tn__world_find(s, "heights"), ke = tn__world_find(s, "embed");
    int i, hv = 0, ev = 0;
    tn_contour_set sketch;
    tn_gnn_generate_opts go;
    char *path;
    tn_status st;
    if (ks < 0) return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: gnn needs model=FILE.tnw and sketch=FILE.tns", s->line);
    if ((long long)w->width * w->height > TN__WORLD_GNN_MAX_PX || w->width < 16 || w->height < 16)
        return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: gnn worlds are 16 .. 4096 x 4096 pixels (this one %d x %d): GNN generation "
                        "prepares the whole sketch at the world's size (~20 bytes per world pixel), so its memory follows the world, "
                        "not the tile", s->line, w->width, w->height);
    for (i = 0; i < 3; i++) {
        if (kh >= 0 && !strcmp(s->val[kh], hname[i])) hv = i + 1;
        if (ke >= 0 && !strcmp(s->val[ke], ename[i])) ev = i + 1;
    }
    if ((kh >= 0 && !hv) || (ke >= 0 && !ev))
        return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: gnn heights=auto|example|unit, embed=auto|aligned|none", s->line);
    if ((st = tn__world_model(s, w, base_dir, "gnn"))) return st;
    if (!(path = tn__world_join(base_dir, s->val[ks]))) return tn__oom();
    st = tn_sketch_load(&sketch, path);
    TN_FREE(path);
    if (st) return st;
    memset(&go, 0, sizeof go);
    go.seed = w->seed;
    go.heights = hv ? hv - 1 : TN_GNN_HEIGHTS_AUTO;
    go.embeddings = ev ? ev - 1 : TN_GNN_EMBED_AUTO;
    st = tn_gnn_prepare(&s->gnn, (const tn_gnn *)s->model, &sketch, w->width, w->height, &go);
    tn_contour_set_free(&sketch);
    return st;
}

static tn_status tn__world_gnn_run(const tn__world_stage *s, const tn_world *w, tn_rect r, const tn_image *in, tn_rect in_r, tn_image *out)
{
    (void)w;
    (void)in;
    (void)in_r;
    return tn_gnn_prepared_window(out, s->gnn, r.x, r.y, r.w, r.h);
}

/* ---- local operations ---- */

/* SinGAN refinement (tn_singan_refine) of the heights before it: the input resized to the grid
   of scale K replaces that scale's upsampled coarser output, then the generators of K and the
   finer scales run. Everything after the resize is already local (valid convolutions, noise and
   upsampling at global positions), and the area resize is too: map pixel i averages input
   pixels [i s, (i + 1) s), s = W / mw. So a tile needs the scale-K window its generators read
   (their margins M and the bilinear footprints, walked down the scales by tn__world_sg_need)
   and the input under that window's resize taps. The halo bounds both: at each scale the margin
   grows by M (a generator) and then becomes e f + 1.5 px a scale down (a bilinear pair), and the
   grids differ by at most s / 2 input pixels (mw is W f^n rounded). */
static tn_status tn__world_refine_setup(tn__world_stage *s, const tn_world *w, const char *base_dir)
{
    tn__sg_arch A;
    double from, noise;
    int K, n, mw, mh, level;
    float e = 0.0f, sc;
    tn_status st;
    if ((st = tn__world_need_heights(s))) return st;
    if ((st = tn__world_model(s, w, base_dir, "singan"))) return st;
    if ((st = tn__sg_arch_of((const tn_singan *)s->model, &A))) return st;
    if (A.scales < 2) return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: singan-refine: the model has one scale only", s->line);
    if ((st = tn__world_num(s, "from_scale", A.scales - 3 > 1 ? A.scales - 3 : 1, 1, A.scales - 1, &from)) ||
        (st = tn__world_num(s, "noise", 1, 0, 100, &noise)))
        return st;
    K = (int)from;
    n = A.scales - 1 - K;
    mw = tn__sg_size(s->in_w, A.factor, n);
    mh = tn__sg_size(s->in_h, A.factor, n);
    if (n > 0 && (mw >= s->in_w || mh >= s->in_h))
        return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: singan-refine: a %d x %d raster is too small for scale %d", s->line, s->in_w,
                        s->in_h, K);
    s->p[0] = (float)K;
    s->p[1] = noise == 0 ? -1.0f : (float)noise; /* gen opts: 0 means 1, < 0 no noise */
    for (level = A.scales - 1; level >= K; level--) {
        if (tn__sg_net(&A, level) < A.trained) e += TN__SG_M;
        if (level > K) e = e * A.factor + 1.5f;
    }
    sc = (float)s->in_w / (float)mw > (float)s->in_h / (float)mh ? (float)s->in_w / (float)mw : (float)s->in_h / (float)mh;
    s->halo = (int)ceil((double)e * sc + 0.5 * sc) + 2;
    tn__world_same_raster(s); /* a halo past the raster's edge is clipped: the whole-map run clamps there too */
    return TN_OK;
}

/* The scale-K window [*a, *b) that scale `level`'s window [*a, *b) reads: tn__sg_window's
   margin, then tn__sg_base's bilinear pairs, scale by scale (one axis). */
static void tn__world_sg_need(const tn__sg_arch *A, int K, int level, long *a, long *b)
{
    for (; level >= K; level--) {
        long i0, i1;
        float t;
        if (tn__sg_net(A, level) < A->trained) {
            *a -= TN__SG_M;
            *b += TN__SG_M;
        }
        if (level == K) break;
        tn__sg_coord(*a, A->factor, &i0, &t);
        tn__sg_coord(*b - 1, A->factor, &i1, &t);
        *a = i0;
        *b = i1 + 2;
    }
}

/* Window [a, b) of an axis of n map pixels clipped to the map (the clamp reads its edge). */
static void tn__world_clip_axis(long *a, long *b, int n)
{
    if (*a < 0) *a = 0;
    if (*a > n - 1) *a = n - 1;
    if (*b > n) *b = n;
    if (*b < *a + 1) *b = *a + 1;
}

/* The taps of map pixels [a, b) of tn_image_resize's area filter from n_in to n_out pixels,
   made relative to input pixel i0; 0 if one falls outside [i0, i0 + len) (a halo too small). */
static int tn__world_sub_taps(const tn__taps *full, long a, long b, int i0, int len, tn__taps *sub)
{
    size_t i, cnt = (size_t)(b - a) * full->ntaps;
    sub->ntaps = full->ntaps;
    for (i = 0; i < cnt; i++) {
        int v = full->idx[(size_t)a * full->ntaps + i] - i0;
        if (v < 0 || v >= len) return 0;
        sub->idx[i] = v;
        sub->wt[i] = full->wt[(size_t)a * full->ntaps + i];
    }
    return 1;
}

static tn_status tn__world_refine_run(const tn__world_stage *s, const tn_world *w, tn_rect r, const tn_image *in, tn_rect in_r,
                                      tn_image *out)
{
    const tn_singan *m = (const tn_singan *)s->model;
    tn__sg_arch A;
    tn_singan_gen_opts go, o;
    tn__sg_gen_run run;
    tn__taps fx, fy, sx, sy;
    tn_image one = {0, 0, 0, NULL};
    float *map = NULL, *tmp = NULL;
    long ax = r.x, bx = (long)r.x + r.w, ay = r.y, by = (long)r.y + r.h;
    int K = (int)s->p[0], n, mw, mh, ok = 1;
    size_t i;
    tn_status st;
    memset(&go, 0, sizeof go);
    memset(&fx, 0, sizeof fx);
    memset(&fy, 0, sizeof fy);
    memset(&sx, 0, sizeof sx);
    memset(&sy, 0, sizeof sy);
    go.seed = w->seed;
    go.noise = s->p[1];
    go.from_scale = K;
    if ((st = tn__sg_gen_prepare(m, &go, 0, &A, &o, &run))) return st;
    n = A.scales - 1 - K;
    mw = tn__sg_size(s->in_w, A.factor, n);
    mh = tn__sg_size(s->in_h, A.factor, n);
    tn__world_sg_need(&A, K, A.scales - 1, &ax, &bx);
    tn__world_sg_need(&A, K, A.scales - 1, &ay, &by);
    tn__world_clip_axis(&ax, &bx, mw);
    tn__world_clip_axis(&ay, &by, mh);
    /* the input in network units, as tn__sg_input makes it before resizing */
    if ((st = tn_image_create(&one, in->width, in->height, 1))) return st;
    for (i = 0; i < (size_t)in->width * in->height; i++) one.data[i] = (in->data[i * in->channels] - m->offset) / m->range;
    if (!(map = (float *)tn__alloc((size_t)(bx - ax) * (by - ay) * sizeof(float)))) st = tn__oom();
    if (!st && n == 0) { /* scale K is the finest: the input itself */
        long y;
        ok = ax >= in_r.x && bx <= (long)in_r.x + in_r.w && ay >= in_r.y && by <= (long)in_r.y + in_r.h;
        for (y = ay; ok && y < by; y++)
            memcpy(map + (size_t)(y - ay) * (bx - ax), one.data + (size_t)(y - in_r.y) * in->width + (ax - in_r.x), (size_t)(bx - ax) * sizeof(float));
    } else if (!st) { /* tn_image_resize's area taps and row passes on the window */
        tn__resize_job job;
        if (!(st = tn__taps_build(&fx, s->in_w, mw, TN_RESIZE_AREA)) && !(st = tn__taps_build(&fy, s->in_h, mh, TN_RESIZE_AREA))) {
            sx.idx = (int *)tn__alloc((size_t)(bx - ax) * fx.ntaps * sizeof(int));
            sx.wt = (float *)tn__alloc((size_t)(bx - ax) * fx.ntaps * sizeof(float));
            sy.idx = (int *)tn__alloc((size_t)(by - ay) * fy.ntaps * sizeof(int));
            sy.wt = (float *)tn__alloc((size_t)(by - ay) * fy.ntaps * sizeof(float));
            tmp = (float *)tn__alloc((size_t)in->height * (bx - ax) * sizeof(float));
            if (!sx.idx || !sx.wt || !sy.idx || !sy.wt || !tmp) st = tn__oom();
        }
        if (!st) ok = tn__world_sub_taps(&fx, ax, bx, in_r.x, in_r.w, &sx) && tn__world_sub_taps(&fy, ay, by, in_r.y, in_r.h, &sy);
        if (!st && ok) {
            job.src = &one;
            job.tmp = tmp;
            job.out = map;
            job.out_w = (int)(bx - ax);
            job.tx = &sx;
            job.ty = &sy;
            tn__resize_rows_x(&job, 0, (size_t)in->height);
            tn__resize_rows_y(&job, 0, (size_t)(by - ay));
        }
    }
    if (!st && !ok)
        st = tn__fail(TN_ERR_INVALID_ARG, "world: line %d: singan-refine: halo %d too small for tile %d,%d %dx%d", s->line, s->halo, r.x,
                      r.y, r.w, r.h);
    if (!st) {
        run.map = map;
        run.mw = mw;
        run.mh = mh;
        run.map_level = K;
        run.mx0 = (int)ax;
        run.my0 = (int)ay;
        run.mstride = (int)(bx - ax);
        st = tn__sg_generate(m, &run, A.scales - 1, r.x, r.y, r.w, r.h, o.tile, out);
    }
    tn__taps_free(&fx);
    tn__taps_free(&fy);
    tn__taps_free(&sx);
    tn__taps_free(&sy);
    TN_FREE(tmp);
    TN_FREE(map);
    tn_image_free(&one);
    return st;
}


/* The seasonal rows' shared settings (season, kpd): the climate (koppen= or climate=), latitude=,
   time= and the insolation's bounded horizon. Insolation casts horizons: over the whole map a
   pixel's shadow may come from any distance, which no tile can see, so the world bounds the
   horizon search by `distance` metres (tn_insolation_opts.max_distance) and that is the
   insolation's halo, *ins_halo: ceil(distance / spacing) px, + 1 for the bilinear horizon
   samples and + 1 for the slopes. The ray's early stop uses the grown rectangle's highest point
   instead of the map's, a bound as valid for every sample the ray reaches there, so the
   horizons are the same. p[0] latitude, p[1] time, p[2] distance, p[3] directions, p[5] spacing. */
static tn_status tn__world_climate_setup(tn__world_stage *s, const tn_world *w, const char *base_dir, int *ins_halo)
{
    int kc = tn__world_find(s, "climate"), kk = tn__world_find(s, "koppen");
    double lat, tm, dist, dirs;
    float spacing;
    tn_status st;
    if ((kc < 0) == (kk < 0))
        return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: %s needs climate=FILE.csv or koppen=CODE (one)", s->line, s->m->name);
    if (w->cellsize <= 0)
        return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: %s needs `cellsize METRES`: insolation, slopes and the horizon distance "
                        "are in metres", s->line, s->m->name);
    if (!(s->climate = (tn_climate *)tn__calloc(sizeof *s->climate))) return tn__oom();
    if (kk >= 0) st = tn_climate_koppen(s->climate, s->val[kk]);
    else {
        char *path = tn__world_join(base_dir, s->val[kc]);
        st = path ? tn_climate_load(s->climate, path) : TN_ERR_OUT_OF_MEMORY;
        TN_FREE(path);
    }
    if (st) return st;
    if ((st = tn__world_num(s, "latitude", s->climate->has_latitude ? s->climate->latitude : 1e9, -90, 90, &lat)) ||
        (st = tn__world_num(s, "time", 6, 0, 12, &tm)) || (st = tn__world_num(s, "distance", 3000, 1e-3, 1e7, &dist)) ||
        (st = tn__world_num(s, "directions", 32, 4, 1024, &dirs)))
        return st;
    if (lat > 90) return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: %s needs latitude= (the climate has none)", s->line, s->m->name);
    spacing = tn__world_spacing(s, w);
    s->p[0] = (float)lat;
    s->p[1] = (float)tm;
    s->p[2] = (float)dist;
    s->p[3] = (float)(int)dirs;
    s->p[5] = spacing;
    if (ceil(dist / spacing) + 2 > (double)INT_MAX / 4)
        return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: %s distance=%g m is %g px", s->line, s->m->name, dist, dist / spacing);
    *ins_halo = (int)ceil(dist / spacing) + 2;
    if (s->in_w < 2 || s->in_h < 2)
        return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: %s needs a raster of at least 2 x 2", s->line, s->m->name);
    return TN_OK;
}

/* The insolation options of a seasonal row: its spacing and bounded horizon (tn__world_climate_setup). */
static void tn__world_insolation_opts(tn_insolation_opts *io, const tn__world_stage *s)
{
    memset(io, 0, sizeof *io);
    io->dx = io->dy = s->p[5];
    io->max_distance = s->p[2];
    io->directions = (int)s->p[3];
}

/* Seasonal texture (tn_season_texture, procedural) of the heights before it at one time of the
   year, its insolation's horizon bounded (tn__world_climate_setup). The rest is per pixel
   (climate, snow and vegetation year, slope, hillshade: halo 1). Two whole-map steps are left
   out: the detail noise (tn_noise_perlin of the whole map, stretched to its own min..max;
   detail = none) and the downsampled insolation of maps over 1024 px (the world computes it at
   full size). */
static tn_status tn__world_season_setup(tn__world_stage *s, const tn_world *w, const char *base_dir)
{
    double shade;
    tn_status st;
    if ((st = tn__world_need_heights(s))) return st;
    if ((st = tn__world_climate_setup(s, w, base_dir, &s->halo))) return st;
    if ((st = tn__world_num(s, "shade", 0, 0, 1, &shade))) return st;
    s->p[4] = (float)shade;
    tn__world_picture_raster(s, 3);
    return TN_OK;
}

static tn_status tn__world_season_run(const tn__world_stage *s, const tn_world *w, tn_rect r, const tn_image *in, tn_rect in_r,
                                      tn_image *out)
{
    tn_season_opts so;
    tn_image ins = {0, 0, 0, NULL}, tex = {0, 0, 0, NULL};
    float t = s->p[1];
    tn_status st;
    (void)w;
    memset(&so, 0, sizeof so);
    tn__world_insolation_opts(&so.insolation, s);
    so.shade = s->p[4];
    so.detail = -1.0f; /* the detail noise is a whole-map Perlin map stretched to its min..max */
    st = tn_insolation(&ins, in, s->p[0], &so.insolation);
    if (!st) st = tn_season_texture(&tex, in, s->climate, s->p[0], &ins, &t, 1, &so, NULL);
    if (!st) st = tn__world_crop(&tex, in_r, r, out);
    tn_image_free(&ins);
    tn_image_free(&tex);
    return st;
}

/* tn_kpd_generate average-pools the map it is given to 1/2 and 1/4, so its windows start at
   multiples of 4 of that map: the map the kpd row hands it must start at a multiple of 4 of the
   row's raster for its pooled cells to be the whole map's. */
#define TN__WORLD_KPD_ALIGN 4

/* The KPD seasonal network (tn_kpd_generate through the "kpd" method) on the heights before it,
   at one time of the year, its values mapped from the model's range to [0, 1]. Its windows are
   exact (a pixel depends on the map within the model's halo) once the map it is given starts on
   the same 4 px grid as the whole map: the run hands it r grown by the halo and one pooled cell
   (so no window it computes reads the map's clamped edge) and aligned outward in the row's own
   coordinates, and the insolation (models of condition "ours") is computed around that map
   with the season row's bounded horizon. p[6]: the growth before alignment. */
static tn_status tn__world_kpd_setup(tn__world_stage *s, const tn_world *w, const char *base_dir)
{
    const tn_kpd *m;
    int ins_halo;
    tn_status st;
    if ((st = tn__world_need_heights(s))) return st;
    if ((st = tn__world_climate_setup(s, w, base_dir, &ins_halo))) return st;
    if ((st = tn__world_model(s, w, base_dir, "kpd"))) return st;
    m = (const tn_kpd *)s->model;
    if (s->out_c > 4)
        return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: kpd model with %d channels; a tile holds at most 4", s->line, s->out_c);
    s->climate->latitude = s->p[0]; /* the row's latitude=, which the insolation used too (condition cond3 reads it) */
    s->climate->has_latitude = 1;
    s->p[6] = (float)(s->method->halo(s->model) + TN__WORLD_KPD_ALIGN);
    s->halo = (int)s->p[6] + TN__WORLD_KPD_ALIGN - 1 + (m->condition == TN_KPD_OURS ? ins_halo : 0);
    tn__world_picture_raster(s, s->out_c);
    return TN_OK;
}

/* Axis [*a, *b) grown by g and aligned outward to TN__WORLD_KPD_ALIGN, clipped to [0, n). */
static void tn__world_kpd_axis(long *a, long *b, int g, int n)
{
    *a -= g;
    *b += g;
    *a = *a < 0 ? 0 : *a / TN__WORLD_KPD_ALIGN * TN__WORLD_KPD_ALIGN;
    *b = (*b + TN__WORLD_KPD_ALIGN - 1) / TN__WORLD_KPD_ALIGN * TN__WORLD_KPD_ALIGN;
    if (*b > n) *b = n;
}

static tn_status tn__world_kpd_run(const tn__world_stage *s, const tn_world *w, tn_rect r, const tn_image *in, tn_rect in_r,
                                   tn_image *out)
{
    const tn_kpd *m = (const tn_kpd *)s->model;
    tn_method_input mi;
    tn_image ins = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL}, dins = {0, 0, 0, NULL};
    long ax = r.x, bx = (long)r.x + r.w, ay = r.y, by = (long)r.y + r.h;
    tn_rect d, win;
    float span = m->hi - m->lo;
    size_t i, n;
    tn_status st;
    (void)w;
    tn__world_kpd_axis(&ax, &bx, (int)s->p[6], s->in_w);
    tn__world_kpd_axis(&ay, &by, (int)s->p[6], s->in_h);
    d.x = (int)ax;
    d.y = (int)ay;
    d.w = (int)(bx - ax);
    d.h = (int)(by - ay);
    memset(&mi, 0, sizeof mi);
    st = tn__world_crop(in, in_r, d, &dem);
    if (!st && m->condition == TN_KPD_OURS) {
        tn_insolation_opts io;
        tn__world_insolation_opts(&io, s);
        st = tn_insolation(&ins, in, s->p[0], &io);
        if (!st) st = tn__world_crop(&ins, in_r, d, &dins);
        mi.insolation = &dins;
    }
    mi.dem = &dem;
    mi.climate = s->climate;
    mi.time = s->p[1];
    win.x = r.x - d.x;
    win.y = r.y - d.y;
    win.w = r.w;
    win.h = r.h;
    if (!st) st = s->method->generate_window(out, s->model, &mi, win);
    n = (size_t)r.w * r.h * s->out_c;
    for (i = 0; !st && i < n; i++) out->data[i] = (out->data[i] - m->lo) / span;
    tn_image_free(&ins);
    tn_image_free(&dins);
    tn_image_free(&dem);
    return st;
}

static tn_status tn__world_blur_setup(tn__world_stage *s, const tn_world *w, const char *base_dir)
{
    double sigma;
    tn_status st;
    (void)w;
    (void)base_dir;
    if ((st = tn__world_num(s, "sigma", 1, 1e-3, 1e4, &sigma))) return st;
    s->p[0] = (float)sigma;
    s->halo = tn__world_gauss_radius(s->p[0]);
    tn__world_same_raster(s);
    return tn__world_fits(s, s->halo, s->in_w, s->in_h);
}

static tn_status tn__world_blur_run(const tn__world_stage *s, const tn_world *w, tn_rect r, const tn_image *in, tn_rect in_r,
                                    tn_image *out)
{
    tn_image b = {0, 0, 0, NULL};
    tn_status st = tn_image_blur(&b, in, s->p[0]);
    (void)w;
    if (!st) st = tn__world_crop(&b, in_r, r, out);
    tn_image_free(&b);
    return st;
}

static tn_status tn__world_hillshade_setup(tn__world_stage *s, const tn_world *w, const char *base_dir)
{
    double v[3];
    tn_status st;
    (void)base_dir;
    if ((st = tn__world_need_heights(s))) return st;
    if ((st = tn__world_num(s, "azimuth", 315, -360, 360, &v[0])) || (st = tn__world_num(s, "altitude", 45, 1e-3, 90, &v[1])) ||
        (st = tn__world_num(s, "z", 1, 1e-6, 1e6, &v[2])))
        return st;
    s->p[0] = (float)v[0];
    s->p[1] = (float)v[1];
    s->p[2] = (float)v[2];
    s->p[3] = tn__world_spacing(s, w);
    s->halo = 1; /* Horn's 3 x 3 window */
    tn__world_picture_raster(s, 1);
    return TN_OK;
}

static tn_status tn__world_hillshade_run(const tn__world_stage *s, const tn_world *w, tn_rect r, const tn_image *in, tn_rect in_r,
                                         tn_image *out)
{
    tn_hillshade_opts o;
    tn_image b = {0, 0, 0, NULL};
    tn_status st;
    (void)w;
    memset(&o, 0, sizeof o);
    o.azimuth_deg = s->p[0] == 0 ? 360.0f : s->p[0]; /* 0 would mean "default" to tn_image_hillshade */
    o.altitude_deg = s->p[1];
    o.z_factor = s->p[2];
    o.dx = o.dy = s->p[3];
    st = tn_image_hillshade(&b, in, &o);
    if (!st) st = tn__world_crop(&b, in_r, r, out);
    tn_image_free(&b);
    return st;
}

static tn_status tn__world_normalmap_setup(tn__world_stage *s, const tn_world *w, const char *base_dir)
{
    double z, dx;
    tn_status st;
    (void)base_dir;
    if ((st = tn__world_need_heights(s))) return st;
    if ((st = tn__world_num(s, "z", 1, 1e-6, 1e6, &z)) || (st = tn__world_num(s, "directx", 0, 0, 1, &dx))) return st;
    s->p[0] = (float)z;
    s->p[1] = (float)dx;
    s->p[2] = tn__world_spacing(s, w);
    s->halo = 1; /* central differences */
    tn__world_picture_raster(s, 3);
    return TN_OK;
}

static tn_status tn__world_normalmap_run(const tn__world_stage *s, const tn_world *w, tn_rect r, const tn_image *in, tn_rect in_r,
                                         tn_image *out)
{
    tn_image b = {0, 0, 0, NULL};
    tn_status st = tn_normal_map(&b, in, s->p[2], s->p[2], s->p[0], s->p[1] != 0);
    (void)w;
    if (!st) st = tn__world_crop(&b, in_r, r, out);
    tn_image_free(&b);
    return st;
}

static tn_status tn__world_detail_setup(tn__world_stage *s, const tn_world *w, const char *base_dir)
{
    double f, sigma;
    float rest, sl = 0.0f;
    tn_status st;
    (void)w;
    (void)base_dir;
    if ((st = tn__world_num(s, "factor", 10, 1, 4096, &f))) return st;
    if ((st = tn__world_num(s, "sigma", 0.5 * (int)f, 1e-3, 1e4, &sigma))) return st;
    s->factor = (int)f;
    /* tn__dm_finish's low-pass: the f x f area average, then the Gaussian of the remaining width */
    rest = (float)sigma * (float)sigma - (float)(s->factor * s->factor) / 12.0f;
    if (rest > 0 && sqrtf(rest) / (float)s->factor > 0.05f) sl = sqrtf(rest) / (float)s->factor;
    s->p[0] = sl;
    s->out_w = (s->in_w + s->factor - 1) / s->factor;
    s->out_h = (s->in_h + s->factor - 1) / s->factor;
    s->out_c = s->in_c;
    s->out_heights = s->in_heights;
    s->halo = (sl > 0 ? tn__world_gauss_radius(sl) : 0) * s->factor;
    return tn__world_fits(s, s->halo / s->factor, s->out_w, s->out_h);
}

/* The low detail map of tn_detail_maps_from_image (without its colour correction, a whole-map
   mean) for rectangle r of the low raster: in is block-aligned (its start is a multiple of f,
   its end one or the raster's edge), so its block sums are the whole map's, added in the same
   order by the same code. */
static tn_status tn__world_detail_run(const tn__world_stage *s, const tn_world *w, tn_rect r, const tn_image *in, tn_rect in_r,
                                      tn_image *out)
{
    tn__dm_acc a;
    tn_image low = {0, 0, 0, NULL};
    tn_rect low_r;
    int f = s->factor, x, y, c;
    size_t n;
    tn_status st;
    (void)w;
    memset(&a, 0, sizeof a);
    a.f = f;
    a.channels = in->channels;
    a.wl = (in->width + f - 1) / f;
    a.hl = (in->height + f - 1) / f;
    if ((st = tn__size4((size_t)a.wl, (size_t)a.hl, (size_t)a.channels, sizeof(double), &n))) return st;
    if (!(a.sum = (double *)tn__calloc(n))) return tn__oom();
    tn__dm_acc_band(&a, 0, in);
    st = tn_image_create(&low, a.wl, a.hl, a.channels);
    for (y = 0; !st && y < a.hl; y++)
        for (x = 0; x < a.wl; x++) {
            int bw = (x + 1) * f <= in->width ? f : in->width - x * f, bh = (y + 1) * f <= in->height ? f : in->height - y * f;
            for (c = 0; c < a.channels; c++) {
                size_t k = ((size_t)y * a.wl + x) * a.channels + c;
                low.data[k] = (float)(a.sum[k] / ((double)bw * bh));
            }
        }
    TN_FREE(a.sum);
    if (!st && s->p[0] > 0) st = tn_image_blur(&low, &low, s->p[0]);
    low_r.x = in_r.x / f;
    low_r.y = in_r.y / f;
    low_r.w = a.wl;
    low_r.h = a.hl;
    if (!st) st = tn__world_crop(&low, low_r, r, out);
    tn_image_free(&low);
    return st;
}

/* ---- the method table ---- */

static const tn__world_method tn__world_methods[] = {
    {"perlin", 1, NULL, "generator, halo 0: frequency=4 (cells across the world) octaves=8 lacunarity=2 gain=0.5 contrast=1 periodic=0",
     tn__world_perlin_setup, tn__world_perlin_run},
    {"explicit", 1, NULL, "generator, halo = sum of round(4 sigma): layers=5 sigma=16,32 contrast=1", tn__world_explicit_setup,
     tn__world_explicit_run},
    {"texgan", 1, NULL, "generator, halo 0 (4-6 noise cells inside the model's windows): model=FILE.tnw (1 channel: heights)",
     tn__world_texgan_setup, tn__world_texgan_run},
    {"singan", 1, NULL, "generator, halo 0 (exact windows of the model's infinite sample): model=FILE.tnw (heights in its metres; "
                        "the world's height range clips them) layout=0 (1: the example's arrangement over the whole world, made at "
                        "setup; worlds up to 4096 x 4096)", tn__world_singan_setup, tn__world_singan_run},
    {"gnn", 1, NULL, "generator, halo 0 outside (2 rounds (radius + 13) px inside tn_gnn_prepared_window), worlds up to 4096 x 4096: "
                     "model=FILE.tnw sketch=FILE.tns (its canvas scaled to the world) heights=auto|example|unit embed=auto|aligned|none",
     tn__world_gnn_setup, tn__world_gnn_run},
    {"singan-refine", 0, NULL, "operation on heights, halo from the model's scales (tn_singan_refine: the input in the model's "
                               "metres): model=FILE.tnw from_scale=scales-3 noise=1", tn__world_refine_setup, tn__world_refine_run},
    {"season", 0, NULL, "operation on heights, RGB out, halo ceil(distance / cellsize) + 2: climate=FILE.csv or koppen=CODE "
                        "latitude=(the climate's) time=6 (months from mid-January) distance=3000 (horizon metres) directions=32 shade=0 "
                        "(no detail noise)", tn__world_season_setup, tn__world_season_run},
    {"kpd", 0, NULL, "operation on heights, the model's channels in [0, 1] out, halo the model's (64) + 7 (4 px alignment) + "
                     "ceil(distance / cellsize) + 2 (insolation, condition ours): model=FILE.tnw climate=FILE.csv or koppen=CODE "
                     "latitude=(the climate's) time=6 distance=3000 directions=32", tn__world_kpd_setup, tn__world_kpd_run},
    {"blur", 0, NULL, "operation, halo round(4 sigma): sigma=1", tn__world_blur_setup, tn__world_blur_run},
    {"hillshade", 0, NULL, "operation on heights, halo 1: azimuth=315 altitude=45 z=1 (spacing: cellsize)", tn__world_hillshade_setup,
     tn__world_hillshade_run},
    {"normalmap", 0, NULL, "operation on heights, halo 1: z=1 directx=0 (spacing: cellsize)", tn__world_normalmap_setup,
     tn__world_normalmap_run},
    {"detail", 0, NULL, "operation, 1/factor size, halo factor x round(4 sigma_low): factor=10 sigma=factor/2 (no colour correction)",
     tn__world_detail_setup, tn__world_detail_run},
    {"style", 0, "style transfer optimises the whole map at once (its losses are statistics over every pixel, and maps over 512 px "
                 "run as feathered tiles that see each other's results), so a tile cannot equal a whole-map run; "
                 "run `terrainnet style` on a map of up to 2048 px instead", NULL, NULL, NULL},
    {"fill", 0, "depression filling is global: a pit is raised to the lowest spill point of its basin, which may lie any number "
                "of tiles away; run `terrainnet extract` on a whole map instead", NULL, NULL, NULL},
    {"flow", 0, "flow accumulation is global: a pixel counts every pixel upstream of it, across any number of tiles; run "
                "`terrainnet extract` on a whole map instead", NULL, NULL, NULL},
    {"extract", 0, "ridge and valley extraction fills depressions and accumulates flow, both global", NULL, NULL, NULL},
    {"colour-correct", 0, "colour correction shifts by the mean of the whole texture, a whole-map statistic (the world's detail "
                          "stage leaves it out)", NULL, NULL, NULL},
};
#define TN__WORLD_NMETHODS ((int)(sizeof tn__world_methods / sizeof tn__world_methods[0]))

TN_API const char *tn_world_method_help(int i)
{
    static char buf[TN__WORLD_NMETHODS][400];
    const tn__world_method *m;
    if (i < 0 || i >= TN__WORLD_NMETHODS) return NULL;
    m = &tn__world_methods[i];
    snprintf(buf[i], sizeof buf[i], "%s: %s%s", m->name, m->refuse ? "not local: " : "", m->refuse ? m->refuse : m->help);
    return buf[i];
}

/* ---- SPEC parsing ---- */

static uint64_t tn__world_fnv(uint64_t h, const uint8_t *p, size_t n)
{
    size_t i;
    for (i = 0; i < n; i++) {
        h ^= p[i];
        h *= 0x100000001b3ULL;
    }
    return h;
}

#define TN__WORLD_FNV0 0xcbf29ce484222325ULL

static void tn__world_release(tn__world_impl *im)
{
    int k;
    if (!im) return;
    for (k = 0; k < im->n; k++) {
        if (im->st[k].method) im->st[k].method->free(im->st[k].model);
        TN_FREE(im->st[k].climate);
        tn_gnn_prepared_free(im->st[k].gnn);
        tn_singan_prepared_free(im->st[k].singan);
    }
    TN_FREE(im);
}

TN_API void tn_world_free(tn_world *w)
{
    if (!w) return;
    tn__world_release((tn__world_impl *)w->impl);
    TN_FREE(w->text);
    memset(w, 0, sizeof *w);
}

/* Splits line into up to `max` space-separated words (in place). */
static int tn__world_words(char *line, char **word, int max)
{
    int n = 0;
    while (*line) {
        while (*line == ' ' || *line == '\t' || *line == '\r') *line++ = 0;
        if (!*line) break;
        if (n == max) return max + 1;
        word[n++] = line;
        while (*line && *line != ' ' && *line != '\t' && *line != '\r') line++;
    }
    return n;
}

static int tn__world_int(const char *s, long long lo, long long hi, int *out)
{
    double v;
    if (!tn__io_number(s, strlen(s), &v) || v != floor(v) || v < (double)lo || v > (double)hi) return 0;
    *out = (int)v;
    return 1;
}

static int tn__world_u64(const char *s, uint64_t *out)
{
    uint64_t v = 0;
    if (!*s) return 0;
    for (; *s; s++) {
        if (*s < '0' || *s > '9' || v > (UINT64_MAX - (uint64_t)(*s - '0')) / 10) return 0;
        v = v * 10 + (uint64_t)(*s - '0');
    }
    *out = v;
    return 1;
}

static tn_status tn__world_parse(tn_world *w, tn__world_impl *im, char *text, const tn_world_opts *opts, const char *base_dir)
{
    static const char *const settings[5] = {"world", "seed", "height", "cellsize", "tile"};
    char *line = text, *word[TN__WORLD_MAX_KV + 2];
    int ln = 0, have_size = 0, k, i, seen[5] = {0, 0, 0, 0, 0};
    tn_status st;
    w->tile = 1024;
    w->seed = 1;
    w->lo = 0.0f;
    w->hi = 1.0f;
    while (line) {
        char *next = strchr(line, '\n'), *hash;
        int nw;
        double a, b;
        if (next) *next++ = 0;
        ln++;
        if ((hash = strchr(line, '#')) != NULL) *hash = 0;
        nw = tn__world_words(line, word, TN__WORLD_MAX_KV + 1);
        line = next;
        if (nw == 0) continue;
        for (k = 0; k < 5; k++) /* a second value would silently win (and size what was set up for the first) */
            if (!strcmp(word[0], settings[k])) {
                if (seen[k]) return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: `%s` given twice (first on line %d)", ln, settings[k], seen[k]);
                seen[k] = ln;
            }
        if (!strcmp(word[0], "world")) {
            if (nw != 3 || !tn__world_int(word[1], 1, TN__WORLD_MAX_SIDE, &w->width) || !tn__world_int(word[2], 1, TN__WORLD_MAX_SIDE, &w->height))
                return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: `world WIDTH HEIGHT` in pixels, 1..%d", ln, TN__WORLD_MAX_SIDE);
            have_size = 1;
        } else if (!strcmp(word[0], "seed")) {
            if (nw != 2 || !tn__world_u64(word[1], &w->seed))
                return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: `seed N` with N a whole number 0..2^64-1", ln);
        } else if (!strcmp(word[0], "height")) {
            if (nw != 3 || !tn__io_number(word[1], strlen(word[1]), &a) || !tn__io_number(word[2], strlen(word[2]), &b) ||
                !(a < b) || !(fabs(a) <= 1e9 && fabs(b) <= 1e9))
                return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: `height LO HI` in metres with LO < HI", ln);
            w->lo = (float)a;
            w->hi = (float)b;
        } else if (!strcmp(word[0], "cellsize")) {
            if (nw != 2 || !tn__io_number(word[1], strlen(word[1]), &a) || !(a >= 0 && a <= 1e9))
                return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: `cellsize METRES` (0 = auto)", ln);
            w->cellsize = (float)a;
        } else if (!strcmp(word[0], "tile")) {
            if (nw != 2 || !tn__world_int(word[1], 16, 65536, &w->tile))
                return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: `tile N` with N 16..65536", ln);
        } else {
            tn__world_stage *s;
            const tn__world_method *m = NULL;
            for (k = 0; k < TN__WORLD_NMETHODS; k++)
                if (!strcmp(word[0], tn__world_methods[k].name)) m = &tn__world_methods[k];
            if (!m)
                return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: unknown setting or method '%s' (settings: world seed height "
                                "cellsize tile; methods: perlin explicit texgan singan gnn singan-refine season kpd blur hillshade normalmap detail)", ln, word[0]);
            if (m->refuse) return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: %s cannot be computed tile by tile: %s", ln, m->name, m->refuse);
            if (im->n == TN__WORLD_MAX_STAGES) return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: more than %d stages", ln, TN__WORLD_MAX_STAGES);
            if (nw > TN__WORLD_MAX_KV + 1) return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: more than %d parameters", ln, TN__WORLD_MAX_KV);
            s = &im->st[im->n++];
            s->m = m;
            s->line = ln;
            for (i = 1; i < nw; i++) {
                char *eq = strchr(word[i], '=');
                if (!eq || eq == word[i] || (size_t)(eq - word[i]) >= sizeof s->key[0] || strlen(eq + 1) >= sizeof s->val[0] || !eq[1])
                    return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: %s: parameters are KEY=VALUE, not '%s'", ln, m->name, word[i]);
                memcpy(s->key[s->nkv], word[i], (size_t)(eq - word[i]));
                s->key[s->nkv][eq - word[i]] = 0;
                strcpy(s->val[s->nkv], eq + 1);
                s->nkv++;
            }
        }
    }
    if (!have_size) return tn__fail(TN_ERR_INVALID_ARG, "world: the SPEC needs `world WIDTH HEIGHT`");
    if (im->n == 0 || !im->st[0].m->source)
        return tn__fail(TN_ERR_INVALID_ARG, "world: the first stage must be a generator (perlin, explicit, texgan, singan or gnn)");
    if (opts && opts->tile) {
        if (opts->tile < 16 || opts->tile > 65536) return tn__fail(TN_ERR_INVALID_ARG, "world: tile side %d is not 16..65536", opts->tile);
        w->tile = opts->tile;
    }
    for (k = 1; k < im->n; k++) /* before any stage is set up: a gnn row's setup runs generations */
        if (im->st[k].m->source) return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: only the first stage may be a generator", im->st[k].line);
    w->halo = 0;
    for (k = 0; k < im->n; k++) {
        tn__world_stage *s = &im->st[k];
        if (k > 0) {
            s->in_w = im->st[k - 1].out_w;
            s->in_h = im->st[k - 1].out_h;
            s->in_c = im->st[k - 1].out_c;
            s->in_heights = im->st[k - 1].out_heights;
        }
        s->factor = 1;
        if ((st = s->m->setup(s, w, base_dir))) return st;
        for (i = 0; i < s->nkv; i++)
            if (!(s->used & (1u << i)))
                return tn__fail(TN_ERR_INVALID_ARG, "world: line %d: %s has no parameter '%s' (%s)", s->line, s->m->name, s->key[i], s->m->help);
    }
    /* halo in generator pixels: each stage's context, scaled back through the factors below it */
    {
        long long h = 0;
        for (k = im->n - 1; k >= 0; k--) h = h * im->st[k].factor + im->st[k].halo;
        w->halo = h > INT_MAX ? INT_MAX : (int)h;
    }
    w->out_width = im->st[im->n - 1].out_w;
    w->out_height = im->st[im->n - 1].out_h;
    w->out_channels = im->st[im->n - 1].out_c;
    w->out_heights = im->st[im->n - 1].out_heights;
    w->cols = (w->out_width + w->tile - 1) / w->tile;
    w->rows = (w->out_height + w->tile - 1) / w->tile;
    if ((long long)w->rows * w->cols > TN__WORLD_MAX_TILES)
        return tn__fail(TN_ERR_TOO_LARGE, "world: a %d x %d raster in tiles of %d is a %d x %d grid, more than %d tiles; use a larger `tile` (up to 65536)",
                        w->out_width, w->out_height, w->tile, w->rows, w->cols, TN__WORLD_MAX_TILES);
    return TN_OK;
}

/* The SPEC as DIR/world.spec holds it: settings in a fixed order, then the stages as written. */
static tn_status tn__world_normalise(tn_world *w, const tn__world_impl *im)
{
    tn__text t = {NULL, 0, 0, 0};
    char lo[40], hi[40], cs[40];
    int k, i;
    tn__io_format_number(lo, sizeof lo, w->lo, 1);
    tn__io_format_number(hi, sizeof hi, w->hi, 1);
    tn__io_format_number(cs, sizeof cs, w->cellsize, 1);
    tn__text_add(&t, "# terrainnet world %s\nworld %d %d\nseed %llu\nheight %s %s\ncellsize %s\ntile %d\n", TN_VERSION_STRING,
                  w->width, w->height, (unsigned long long)w->seed, lo, hi, cs, w->tile);
    for (k = 0; k < im->n; k++) {
        tn__text_add(&t, "%s", im->st[k].m->name);
        for (i = 0; i < im->st[k].nkv; i++) tn__text_add(&t, " %s=%s", im->st[k].key[i], im->st[k].val[i]);
        tn__text_add(&t, "\n");
    }
    if (t.failed) {
        TN_FREE(t.s);
        return tn__oom();
    }
    w->text = t.s;
    w->digest = tn__world_fnv(TN__WORLD_FNV0, (const uint8_t *)t.s, t.n);
    return TN_OK;
}

static tn_status tn__world_parse_with(const char *text, const tn_world_opts *opts, const char *base_dir, tn_world *out)
{
    tn_world w;
    tn__world_impl *im;
    size_t n;
    char *copy;
    tn_status st;
    TN_ASSERT(out);
    if (!text) return tn__fail(TN_ERR_INVALID_ARG, "world: no SPEC text");
    memset(&w, 0, sizeof w);
    n = strlen(text);
    im = (tn__world_impl *)tn__calloc(sizeof *im);
    copy = (char *)tn__alloc(n + 1);
    if (!im || !copy) {
        TN_FREE(im);
        TN_FREE(copy);
        return tn__oom();
    }
    memcpy(copy, text, n + 1);
    st = tn__world_parse(&w, im, copy, opts, base_dir);
    TN_FREE(copy);
    w.impl = im;
    if (!st) st = tn__world_normalise(&w, im);
    if (st) {
        tn_world_free(&w);
        return st;
    }
    *out = w;
    return TN_OK;
}

TN_API tn_status tn_world_parse(tn_world *w, const char *text, const tn_world_opts *opts)
{
    return tn__world_parse_with(text, opts, opts ? opts->base_dir : NULL, w);
}

TN_API tn_status tn_world_load(tn_world *w, const char *path, const tn_world_opts *opts)
{
    uint8_t *buf = NULL;
    size_t n = 0, i;
    char *text, *dir, *slash;
    tn_status st;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "world: empty SPEC path");
    if ((st = tn__io_read_file(path, &buf, &n))) return st;
    for (i = 0; i < n; i++)
        if (buf[i] == 0) {
            TN_FREE(buf);
            return tn__fail(TN_ERR_FORMAT, "%s: a SPEC is text (found a NUL byte)", path);
        }
    text = (char *)tn__alloc(n + 1);
    dir = (char *)tn__alloc(strlen(path) + 1);
    if (!text || !dir) {
        TN_FREE(buf);
        TN_FREE(text);
        TN_FREE(dir);
        return tn__oom();
    }
    if (n) memcpy(text, buf, n);
    text[n] = 0;
    TN_FREE(buf);
    strcpy(dir, path);
    slash = strrchr(dir, '/');
    if (slash) *slash = 0;
    else dir[0] = 0;
    st = tn__world_parse_with(text, opts, opts && opts->base_dir ? opts->base_dir : dir, w);
    TN_FREE(text);
    TN_FREE(dir);
    return st ? tn__fail_context(st, path) : TN_OK;
}

/* ---- tiles ---- */

/* Rectangle r of stage k's raster: stage k - 1 computes r (scaled by the factor) grown by
   stage k's halo, then stage k runs on it. */
static tn_status tn__world_compute(const tn_world *w, int k, tn_rect r, tn_image *out)
{
    const tn__world_stage *s = &((const tn__world_impl *)w->impl)->st[k];
    tn_image in = {0, 0, 0, NULL};
    tn_rect sr, in_r;
    tn_status st;
    if (k == 0) return s->m->run(s, w, r, NULL, r, out);
    sr.x = r.x * s->factor;
    sr.y = r.y * s->factor;
    sr.w = r.w * s->factor; /* past the raster's edge in a partial block: tn_rect_halo clips it */
    sr.h = r.h * s->factor;
    in_r = tn_rect_halo(sr, s->halo, s->in_w, s->in_h);
    if ((st = tn__world_compute(w, k - 1, in_r, &in))) return st;
    st = s->m->run(s, w, r, &in, in_r, out);
    tn_image_free(&in);
    return st;
}

TN_API tn_status tn_world_rect(tn_image *out, const tn_world *w, tn_rect r)
{
    TN_ASSERT(w && out);
    if (!w->impl) return tn__fail(TN_ERR_INVALID_ARG, "world: not parsed");
    if (r.w <= 0 || r.h <= 0 || r.x < 0 || r.y < 0 || r.x > w->out_width - r.w || r.y > w->out_height - r.h)
        return tn__fail(TN_ERR_INVALID_ARG, "world: rectangle %d,%d %dx%d is not inside the %d x %d world", r.x, r.y, r.w, r.h,
                        w->out_width, w->out_height);
    return tn__world_compute(w, ((const tn__world_impl *)w->impl)->n - 1, r, out);
}

TN_API tn_rect tn_world_tile_rect(const tn_world *w, int row, int col)
{
    tn_rect r;
    r.x = col * w->tile;
    r.y = row * w->tile;
    r.w = w->out_width - r.x < w->tile ? w->out_width - r.x : w->tile;
    r.h = w->out_height - r.y < w->tile ? w->out_height - r.y : w->tile;
    return r;
}

static int tn__world_exists(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (!f) return 0;
    fclose(f);
    return 1;
}

/* DIR/world.spec: written on first use; another world's is refused, so a resumed or shared
   directory never mixes tiles of two worlds. */
static tn_status tn__world_claim_dir(const tn_world *w, const char *dir)
{
    char *path = tn__world_join(dir, "world.spec");
    uint8_t *buf = NULL;
    size_t n = 0, len = strlen(w->text);
    tn_status st = TN_OK;
    if (!path) return tn__oom();
    if (tn__world_exists(path)) {
        st = tn__io_read_file(path, &buf, &n);
        if (!st && (n != len || memcmp(buf, w->text, len) != 0))
            st = tn__fail(TN_ERR_INVALID_ARG, "%s holds another world (its world.spec differs from this SPEC); use another directory",
                          dir);
        TN_FREE(buf);
    } else {
        st = tn__io_write_atomic(path, (const uint8_t *)w->text, len);
    }
    TN_FREE(path);
    return st;
}

static tn_status tn__world_save_tile(const tn_world *w, tn_image *img, const char *path)
{
    tn_save_opts o;
    size_t i, n = (size_t)img->width * img->height * img->channels;
    memset(&o, 0, sizeof o);
    o.format = TN_FORMAT_PNG;
    if (w->out_heights) { /* one world-wide range: every tile quantises alike, and one VRT scale reads them */
        o.bit_depth = 16;
        o.has_range = 1;
        o.range_lo = w->lo;
        o.range_hi = w->hi;
        for (i = 0; i < n; i++) img->data[i] = tn__clampf(img->data[i], w->lo, w->hi);
    } else {
        o.bit_depth = 8;
        for (i = 0; i < n; i++) img->data[i] = tn__clampf(img->data[i], 0.0f, 1.0f);
    }
    return tn_image_save(path, img, &o);
}

/* The tiles DIR/manifest.txt lists, by (row, col): digest and size of each file. A resumed run
   trusts a tile on disk only when it matches its line (an empty or damaged file must not count
   as present or reach the manifest); an unlisted tile must decode as this world's tile. */
typedef struct tn__world_listed { int row, col; uint64_t digest; long long size; } tn__world_listed;
typedef struct tn__world_manifest { tn__world_listed *slot; size_t cap; } tn__world_manifest;

static size_t tn__world_listed_hash(int row, int col, size_t cap)
{
    return (size_t)((((uint64_t)(uint32_t)row << 32) | (uint32_t)col) * 0x9E3779B97F4A7C15ULL >> 17) & (cap - 1);
}

static const tn__world_listed *tn__world_listed_find(const tn__world_manifest *m, int row, int col)
{
    size_t h;
    if (!m->cap) return NULL;
    for (h = tn__world_listed_hash(row, col, m->cap); m->slot[h].row >= 0; h = (h + 1) & (m->cap - 1))
        if (m->slot[h].row == row && m->slot[h].col == col) return &m->slot[h];
    return NULL;
}

/* Reads DIR/manifest.txt when there is one (none, or one this library cannot read: empty). */
static tn_status tn__world_manifest_read(const tn_world *w, const char *dir, tn__world_manifest *m)
{
    char *path = tn__world_join(dir, "manifest.txt");
    uint8_t *buf = NULL;
    size_t n = 0, i = 0, lines = 0, k;
    m->slot = NULL;
    m->cap = 0;
    if (!path) return tn__oom();
    if (!tn__world_exists(path) || tn__io_read_file(path, &buf, &n)) {
        TN_FREE(path);
        tn_clear_error();
        return TN_OK;
    }
    TN_FREE(path);
    for (k = 0; k < n; k++) lines += buf[k] == '\n';
    for (m->cap = 16; m->cap < 2 * lines + 2; m->cap *= 2) {}
    if (!(m->slot = (tn__world_listed *)tn__alloc(m->cap * sizeof *m->slot))) {
        TN_FREE(buf);
        return tn__oom();
    }
    for (k = 0; k < m->cap; k++) m->slot[k].row = -1;
    while (i < n) {
        char line[128];
        size_t b = i, len;
        int row, col, used = 0;
        unsigned long long size = 0;
        char hex[17];
        while (i < n && buf[i] != '\n') i++;
        len = i - b < sizeof line - 1 ? i - b : sizeof line - 1;
        memcpy(line, buf + b, len);
        line[len] = 0;
        i++;
        if (sscanf(line, "r%d_c%d.png %16[0-9a-f]%n", &row, &col, hex, &used) == 3 && row >= 0 && col >= 0 && row < w->rows && col < w->cols &&
            strlen(hex) == 16 && !tn__world_listed_find(m, row, col)) {
            size_t h = tn__world_listed_hash(row, col, m->cap);
            uint64_t d = 0;
            for (k = 0; k < 16; k++) d = d << 4 | (uint64_t)(hex[k] <= '9' ? hex[k] - '0' : hex[k] - 'a' + 10);
            while (m->slot[h].row >= 0) h = (h + 1) & (m->cap - 1);
            m->slot[h].row = row;
            m->slot[h].col = col;
            m->slot[h].digest = d;
            m->slot[h].size = sscanf(line + used, "%llu", &size) == 1 ? (long long)size : -1; /* older manifests: no size */
        }
    }
    TN_FREE(buf);
    return TN_OK;
}

/* Whether the file at path is this world's tile (row, col): its size and digest as listed, or,
   unlisted, a PNG that decodes to the tile's size, channels, bit depth and range. *digest and
   *size get the file's. */
static int tn__world_tile_ok(const tn_world *w, const tn__world_manifest *m, int row, int col, const char *path, uint64_t *digest, size_t *size)
{
    const tn__world_listed *l = tn__world_listed_find(m, row, col);
    uint8_t *buf = NULL;
    size_t n = 0;
    int ok = 0;
    if (tn__io_read_file(path, &buf, &n)) {
        tn_clear_error();
        return 0;
    }
    *digest = tn__world_fnv(TN__WORLD_FNV0, buf, n);
    *size = n;
    if (l) ok = *digest == l->digest && (l->size < 0 || (size_t)l->size == n);
    else {
        tn_image img = {0, 0, 0, NULL};
        tn_image_info info;
        tn_rect r = tn_world_tile_rect(w, row, col);
        if (!tn_image_load_memory(&img, buf, n, path, NULL, &info))
            ok = info.format == TN_FORMAT_PNG && img.width == r.w && img.height == r.h && img.channels == w->out_channels &&
                 info.bit_depth == (w->out_heights ? 16 : 8) &&
                 (!w->out_heights || (info.has_range && (float)info.range_lo == w->lo && (float)info.range_hi == w->hi));
        tn_image_free(&img);
        tn_clear_error();
    }
    TN_FREE(buf);
    return ok;
}

/* Refuses, before DIR/world.spec is written, a tile that cannot be computed: the first stage
   alone holds the tile grown by the halo in floats, which must fit TN_MAX_ALLOC and what the
   memory budget leaves (a `tile 65536` failed only after claiming the directory). A lower bound,
   so nothing that could succeed is refused. */
static tn_status tn__world_tile_fits(const tn_world *w)
{
    tn_rect r = tn_world_tile_rect(w, 0, 0);
    double one = ((double)r.w + 2.0 * w->halo) * ((double)r.h + 2.0 * w->halo) * sizeof(float);
    double limit = (double)tn_get_memory_limit() - (double)tn_memory_in_use();
    if (limit > (double)TN_MAX_ALLOC) limit = (double)TN_MAX_ALLOC;
    if (one > limit)
        return tn__fail(TN_ERR_TOO_LARGE, "world: a tile of %d x %d with its halo of %d needs at least %.0f MB, over the %.0f MB the allocation "
                        "and memory limits allow (tn_set_memory_limit, --max-memory); use a smaller `tile`", r.w, r.h, w->halo,
                        one / 1048576.0, limit / 1048576.0);
    return TN_OK;
}

TN_API tn_status tn_world_write_tiles(const char *dir, const tn_world *w, const tn_world_run_opts *opts, tn_world_run_stats *stats)
{
    tn_world_run_opts o;
    tn_world_run_stats s;
    tn_status st;
    int row, col;
    long long k = 0, total, done = 0;
    tn__world_manifest man;
    uint64_t digest;
    size_t size;
    TN_ASSERT(w);
    memset(&o, 0, sizeof o);
    memset(&s, 0, sizeof s);
    if (opts) o = *opts;
    if (!dir || !dir[0]) return tn__fail(TN_ERR_INVALID_ARG, "world: no output directory");
    if (!w->impl) return tn__fail(TN_ERR_INVALID_ARG, "world: not parsed");
    if (o.row1 == 0) o.row1 = w->rows;
    if (o.col1 == 0) o.col1 = w->cols;
    if (o.parts == 0) o.parts = 1;
    if (o.row0 < 0 || o.row0 >= o.row1 || o.row1 > w->rows || o.col0 < 0 || o.col0 >= o.col1 || o.col1 > w->cols)
        return tn__fail(TN_ERR_INVALID_ARG, "world: tiles rows %d:%d, columns %d:%d are not inside the %d x %d grid", o.row0, o.row1,
                        o.col0, o.col1, w->rows, w->cols);
    if (o.parts < 1 || o.part < 0 || o.part >= o.parts) return tn__fail(TN_ERR_INVALID_ARG, "world: part %d of %d", o.part, o.parts);
    if ((st = tn__world_tile_fits(w))) return st;
    if ((st = tn__world_claim_dir(w, dir))) return st;
    if ((st = tn__world_manifest_read(w, dir, &man))) return st;
    s.seconds = tn_time_seconds();
    total = ((long long)(o.row1 - o.row0) * (o.col1 - o.col0) - o.part + o.parts - 1) / o.parts;
    for (row = o.row0; row < o.row1 && !st; row++)
        for (col = o.col0; col < o.col1 && !st; col++, k++) {
            char leaf[48], *path;
            if (k % o.parts != o.part) continue;
            snprintf(leaf, sizeof leaf, "r%d_c%d.png", row, col);
            if (!(path = tn__world_join(dir, leaf))) {
                st = tn__oom();
                break;
            }
            if (tn__world_exists(path) && tn__world_tile_ok(w, &man, row, col, path, &digest, &size)) s.skipped++;
            else {
                if (tn__world_exists(path)) s.repaired++; /* damaged or foreign: computed again */
                tn_image img = {0, 0, 0, NULL};
                st = tn_world_rect(&img, w, tn_world_tile_rect(w, row, col));
                if (!st) st = tn__world_save_tile(w, &img, path);
                tn_image_free(&img);
                if (!st) s.written++;
            }
            TN_FREE(path);
            if (!st) st = tn__progress("world", (double)++done / (double)(total > 0 ? total : 1));
        }
    s.seconds = tn_time_seconds() - s.seconds;
    TN_FREE(man.slot);
    if (stats) *stats = s;
    return st;
}

/* GDAL mosaic of tiles rows [r0, r1) x columns [c0, c1), its pixels from that block's corner;
   blocks: its sources are the block mosaics of TN__WORLD_VRT_BLOCK tiles a side instead. The
   whole grid's (r0 = c0 = 0) carries the geotransform. */
static void tn__world_vrt(tn__text *vrt, const tn_world *w, int r0, int r1, int c0, int c1, int blocks)
{
    static const char *colour[4] = {"Red", "Green", "Blue", "Alpha"};
    char num[3][40];
    int c, row, col, step = blocks ? TN__WORLD_VRT_BLOCK : 1;
    tn_rect o = tn_world_tile_rect(w, r0, c0), e = tn_world_tile_rect(w, r1 - 1, c1 - 1);
    tn__io_format_number(num[0], sizeof num[0], w->lo, 1);
    tn__io_format_number(num[1], sizeof num[1], ((double)w->hi - w->lo) / 65535.0, 0);
    tn__text_add(vrt, "<VRTDataset rasterXSize=\"%d\" rasterYSize=\"%d\">\n", e.x + e.w - o.x, e.y + e.h - o.y);
    if (w->cellsize > 0 && r0 == 0 && c0 == 0) {
        tn__io_format_number(num[2], sizeof num[2], (double)w->cellsize * w->width / w->out_width, 0);
        tn__text_add(vrt, "  <GeoTransform>0, %s, 0, 0, 0, -%s</GeoTransform>\n", num[2], num[2]);
    }
    for (c = 0; c < w->out_channels; c++) {
        /* heights: Float32 metres, code * (hi - lo) / 65535 + lo per source, so every GDAL reader
           (gdalinfo -stats, QGIS, gdal_translate) sees metres without applying a band scale */
        tn__text_add(vrt, "  <VRTRasterBand dataType=\"%s\" band=\"%d\">\n", w->out_heights ? "Float32" : "Byte", c + 1);
        if (!w->out_heights && w->out_channels >= 3) tn__text_add(vrt, "    <ColorInterp>%s</ColorInterp>\n", colour[c]);
        for (row = r0; row < r1; row += step)
            for (col = c0; col < c1; col += step) {
                tn_rect r = tn_world_tile_rect(w, row, col);
                if (blocks) {
                    tn_rect z = tn_world_tile_rect(w, row + step < r1 ? row + step - 1 : r1 - 1, col + step < c1 ? col + step - 1 : c1 - 1);
                    int bw = z.x + z.w - r.x, bh = z.y + z.h - r.y;
                    tn__text_add(vrt,
                                 "    <SimpleSource>\n      <SourceFilename relativeToVRT=\"1\">world_b%d_%d.vrt</SourceFilename>\n"
                                 "      <SourceBand>%d</SourceBand>\n      <SourceProperties RasterXSize=\"%d\" RasterYSize=\"%d\" "
                                 "DataType=\"%s\" BlockXSize=\"128\" BlockYSize=\"128\"/>\n"
                                 "      <SrcRect xOff=\"0\" yOff=\"0\" xSize=\"%d\" ySize=\"%d\"/>\n"
                                 "      <DstRect xOff=\"%d\" yOff=\"%d\" xSize=\"%d\" ySize=\"%d\"/>\n    </SimpleSource>\n",
                                 row / step, col / step, c + 1, bw, bh, w->out_heights ? "Float32" : "Byte", bw, bh, r.x - o.x, r.y - o.y, bw, bh);
                    continue;
                }
                tn__text_add(vrt,
                             "    <%s>\n      <SourceFilename relativeToVRT=\"1\">r%d_c%d.png</SourceFilename>\n"
                             "      <SourceBand>%d</SourceBand>\n      <SourceProperties RasterXSize=\"%d\" RasterYSize=\"%d\" "
                             "DataType=\"%s\" BlockXSize=\"%d\" BlockYSize=\"1\"/>\n"
                             "      <SrcRect xOff=\"0\" yOff=\"0\" xSize=\"%d\" ySize=\"%d\"/>\n"
                             "      <DstRect xOff=\"%d\" yOff=\"%d\" xSize=\"%d\" ySize=\"%d\"/>\n",
                             w->out_heights ? "ComplexSource" : "SimpleSource", row, col, c + 1, r.w, r.h,
                             w->out_heights ? "UInt16" : "Byte", r.w, r.w, r.h, r.x - o.x, r.y - o.y, r.w, r.h);
                if (w->out_heights) tn__text_add(vrt, "      <ScaleOffset>%s</ScaleOffset>\n      <ScaleRatio>%s</ScaleRatio>\n", num[0], num[1]);
                tn__text_add(vrt, "    </%s>\n", w->out_heights ? "ComplexSource" : "SimpleSource");
            }
        tn__text_add(vrt, "  </VRTRasterBand>\n");
    }
    tn__text_add(vrt, "</VRTDataset>\n");
}

TN_API tn_status tn_world_write_index(const char *dir, const tn_world *w, int *present)
{
    tn__text vrt = {NULL, 0, 0, 0}, man = {NULL, 0, 0, 0};
    tn__world_manifest old;
    char num[3][40], hex[17], *path = NULL;
    int row, col, count = 0;
    tn_status st = TN_OK;
    TN_ASSERT(w);
    if (!dir || !dir[0]) return tn__fail(TN_ERR_INVALID_ARG, "world: no output directory");
    if (!w->impl) return tn__fail(TN_ERR_INVALID_ARG, "world: not parsed");
    if ((st = tn__world_claim_dir(w, dir))) return st;
    if ((st = tn__world_manifest_read(w, dir, &old))) return st;
    tn__io_format_number(num[0], sizeof num[0], w->lo, 1);
    if ((long long)w->rows * w->cols <= (long long)TN__WORLD_VRT_BLOCK * TN__WORLD_VRT_BLOCK)
        tn__world_vrt(&vrt, w, 0, w->rows, 0, w->cols, 0);
    else { /* a mosaic of block mosaics: no file holds more than a block's sources */
        int br, bc;
        for (br = 0; br < w->rows && !st; br += TN__WORLD_VRT_BLOCK)
            for (bc = 0; bc < w->cols && !st; bc += TN__WORLD_VRT_BLOCK) {
                tn__text blk = {NULL, 0, 0, 0};
                char leaf[48];
                tn__world_vrt(&blk, w, br, br + TN__WORLD_VRT_BLOCK < w->rows ? br + TN__WORLD_VRT_BLOCK : w->rows, bc,
                              bc + TN__WORLD_VRT_BLOCK < w->cols ? bc + TN__WORLD_VRT_BLOCK : w->cols, 0);
                snprintf(leaf, sizeof leaf, "world_b%d_%d.vrt", br / TN__WORLD_VRT_BLOCK, bc / TN__WORLD_VRT_BLOCK);
                if (blk.failed || !(path = tn__world_join(dir, leaf))) st = tn__oom();
                if (!st) st = tn__io_write_atomic(path, (const uint8_t *)blk.s, blk.n);
                TN_FREE(path);
                path = NULL;
                TN_FREE(blk.s);
            }
        tn__world_vrt(&vrt, w, 0, w->rows, 0, w->cols, 1);
    }
    tn__hex64(hex, w->digest);
    tn__text_add(&man, "terrainnet world manifest\nversion %s\nspec_digest %s\nseed %llu\nsize %d %d\ntile %d\ngrid %d %d\n",
                  TN_VERSION_STRING, hex, (unsigned long long)w->seed, w->out_width, w->out_height, w->tile, w->rows, w->cols);
    if (w->out_heights) {
        tn__io_format_number(num[2], sizeof num[2], w->hi, 1);
        tn__text_add(&man, "range %s %s\n", num[0], num[2]);
    }
    for (row = 0; row < w->rows && !st; row++)
        for (col = 0; col < w->cols && !st; col++) {
            char leaf[48];
            uint64_t digest;
            size_t n = 0;
            snprintf(leaf, sizeof leaf, "r%d_c%d.png", row, col);
            if (!(path = tn__world_join(dir, leaf))) {
                st = tn__oom();
                break;
            }
            if (tn__world_exists(path) && tn__world_tile_ok(w, &old, row, col, path, &digest, &n)) { /* a damaged tile is not present */
                tn__hex64(hex, digest);
                tn__text_add(&man, "%s %s %zu\n", leaf, hex, n);
                count++;
            }
            TN_FREE(path);
            path = NULL;
        }
    TN_FREE(old.slot);
    tn__text_add(&man, "tiles %d of %d\n", count, w->rows * w->cols);
    if (!st && (vrt.failed || man.failed)) st = tn__oom();
    if (!st && !(path = tn__world_join(dir, "world.vrt"))) st = tn__oom();
    if (!st) st = tn__io_write_atomic(path, (const uint8_t *)vrt.s, vrt.n);
    TN_FREE(path);
    path = NULL;
    if (!st && !(path = tn__world_join(dir, "manifest.txt"))) st = tn__oom();
    if (!st) st = tn__io_write_atomic(path, (const uint8_t *)man.s, man.n);
    TN_FREE(path);
    TN_FREE(vrt.s);
    TN_FREE(man.s);
    if (!st && present) *present = count;
    return st;
}
#endif /* TN_NO_WORLD */

