/* ==== internals (TN_INTERNALS) ================================================================
   Not the API: private tn__ code that the repository's white-box tests and benches reach, with no
   promise that any of it stays. A program sees this block when it defines TN_INTERNALS before
   including the header (and links an implementation compiled with TN_INTERNALS, whose TN__INTERNAL
   functions and variables are then external instead of static); the implementation itself sees
   the types. Any other program sees none of it. Listed by section, in table-of-contents order;
   add a name only when a test cannot reach the behaviour through the public API. */
#if (defined(TN_INTERNALS) || (defined(TERRAINNET_IMPLEMENTATION) && !defined(TN_IMPLEMENTATION_LINKED))) && \
    !defined(TN__INTERNALS_H)
#define TN__INTERNALS_H
#ifdef __cplusplus
extern "C" {
#endif

/* ---- types and constants (the implementation uses these too) ---- */
/* core: thread-local storage class, where the compiler has one (test_core: progress hooks) */
#if !defined(TN_NO_THREADS) && !defined(TN_NO_TLS)
#if defined(_MSC_VER)
#define TN__TLS __declspec(thread)
#elif defined(__cplusplus) && __cplusplus >= 201103L
#define TN__TLS thread_local
#elif defined(__STDC_VERSION__) && __STDC_VERSION__ >= 201112L
#define TN__TLS _Thread_local
#elif defined(__GNUC__) || defined(__clang__)
#define TN__TLS __thread
#endif
#endif
#define TN__TIF_CLASSIC_MAX 0xffffff00u /* io_formats: files past this are written as BigTIFF */
#ifndef TN_NO_ENGINE
/* gemm: the micro-tile of the kernel the compiler targets (MR rows x two vectors of VW floats;
   portable: 8x16 measured best over gcc and clang at -O2, SSE2) and the K block (see gemm.c's
   block sizes). A test sees the library's values when compiled with the same -m flags. */
#if defined(__AVX512F__)
#define TN__GEMM_MR 8
#define TN__GEMM_VW 16
#elif defined(__AVX2__) && defined(__FMA__)
#define TN__GEMM_MR 6
#define TN__GEMM_VW 8
#else
#define TN__GEMM_MR 8
#define TN__GEMM_VW 8
#endif
#define TN__GEMM_NR (2 * TN__GEMM_VW)
#define TN__GEMM_KC 384
/* gemm: the product's kernels, float32 and the bf16 ones of >>gemm_bf16 */
enum { TN__KERN_FP32 = 0, TN__KERN_EMU, TN__KERN_AVX512BF16, TN__KERN_AMX };
#endif
#ifndef TN_NO_EXTRACT
/* extract: min-heap of (priority, cell) for the cells of depressions: 4-ary, items of 16 bytes,
   so a node's children share one cache line. */
typedef struct tn__pheap_item { uint64_t pri; uint32_t cell, pad; } tn__pheap_item;
typedef struct tn__pheap { tn__pheap_item *a; size_t n, cap; } tn__pheap; /* cap in bytes */
#endif
#ifndef TN_NO_GNN
#define TN__GNN_DIST 16.0f /* gnn: distance scale of the edge features (px) */
#define TN__GNN_PROFILE 48 /* gnn grow: how far the main lines' profiles reach (px) */
#define TN__GNN_CREST_BEND_MAX 1.5f /* gnn grow: px a drawn ridge moves at most (softly) for the example's
                                       bends; the notch keeps it above the ground 4 px across it as
                                       drawn (tn__gnn_incise) */
/* gnn: the parts of a sketch as flat arrays */
typedef struct tn__gnn_parts {
    int n, npts;
    int *start;        /* n + 1 offsets into pts */
    int *of;           /* npts: part of each point */
    float *pts;        /* npts x 3: x, y, normalised height */
    float *sign;       /* n: +1 ridge, -1 valley */
} tn__gnn_parts;
#endif
#ifndef TN_NO_TEXGAN
#define TN__TG_FEATS 32 /* texgan: fixed random filters of the feature-statistics term */
/* texgan: the training state */
typedef struct tn__tg_train {
    tn_texgan m;            /* EMA generator = m.weights "g.*" */
    tn_params *g, *d;
    tn_patch_disc disc;     /* over d */
    tn_optim *og, *od;
    tn_rng rng;
    tn_train *run;
    int disc_width, disc_layers, patch, batch, augment;
    float lr, ema, feat_weight;
    float *filt;            /* TN__TG_FEATS random 5x5 filters over the channels (fixed seed) */
    double *ref;            /* exemplar feature means + covariances, per scale */
} tn__tg_train;
#endif
#ifndef TN_NO_STYLE
/* style: the feature network, one pyramid level (or one tile of it), the transfer's settings */
#define TN__STYLE_MAXL 5
typedef struct tn__style_net {
    int vgg;
    int nconv;
    tn_tensor *w[16], *b[16];
    tn_params *own; /* the built-in net's weights; VGG weights are borrowed */
} tn__style_net;
#define TN__STYLE_ABINS 32    /* drainage bins: floor(log2(flow accumulation)) */
typedef struct tn__style_level {
    const tn__style_net *net;
    tn_ctx *ctx;
    int w, h;                 /* size of the optimised map */
    float wc, wg, wsw, wh, wtv;
    int nstyle;
    float *gram[TN__STYLE_MAXL];  /* C x C source Grams */
    double gnorm[TN__STYLE_MAXL]; /* their squared Frobenius norms */
    float *dirs[TN__STYLE_MAXL];  /* C x C random unit directions (rows) */
    float *sorted[TN__STYLE_MAXL];/* C x snt sorted source projections */
    size_t snt[TN__STYLE_MAXL];
    double svar[TN__STYLE_MAXL];  /* mean square of the sorted projections */
    int ch[TN__STYLE_MAXL];
    float *content;           /* content-layer features of the anchor map */
    int cshape[4];
    double cnorm;
    float *hsorted, *ssorted; /* sorted source heights and slopes */
    size_t hn, sn;
    float wdep, wrel;
    float *dsorted;           /* sorted source depression depths (filled - height) */
    size_t dn;
    float relief_t[TN__STYLE_ABINS + 1]; /* source's mean relief per accumulation bin; the edge */
    double relief2;           /* source's mean squared relief */
    double s2;
    tn_status status;
} tn__style_level;
typedef struct tn__style_cfg {
    tn_style_opts o;
    tn__style_net net;
    double work_done, work_total; /* progress in pixel-iterations */
    tn_progress_fn user_fn;
    void *user_data;
    double span, frac;            /* work of the tile being optimised, and the fraction done */
    int level;                    /* pyramid level being optimised (0 = full size) */
} tn__style_cfg;
#endif

#ifdef TN_INTERNALS
/* ---- src/core.c ---- */
tn_status tn__size4(size_t a, size_t b, size_t c, size_t d, size_t *out);
tn_status tn__progress(const char *stage, double fraction);
void tn__progress_within(const char *stage, double fraction);
float tn__clampf(float v, float lo, float hi);
/* ---- src/io.c ---- */
uint32_t tn__crc32(uint32_t crc, const uint8_t *p, size_t n);
uint32_t tn__png_be32(const uint8_t *p);
void tn__png_put_be32(uint8_t *p, uint32_t v);
tn_status tn__png_decode(const uint8_t *buf, size_t n, const char *name, tn_image *img, tn_image_info *info);
tn_status tn__png_encode(const tn_image *img, int bit_depth, double lo, double hi, int record_range,
                         int level, uint8_t **out, size_t *out_size);
/* ---- src/io_formats.c ---- */
extern double tn__tif_classic_max; /* lowered by tests to reach BigTIFF */
tn_status tn__io_read_file(const char *path, uint8_t **out, size_t *out_size);
tn_status tn__tif_packbits(const char *name, const uint8_t *s, size_t n, uint8_t *out, size_t cap, size_t *len);
tn_status tn__tif_lzw(const char *name, const uint8_t *s, size_t n, uint8_t *out, size_t cap, size_t *len,
                      size_t *tab, uint16_t *lens);
#ifndef TN_NO_ENGINE
/* ---- src/gemm.c ---- */
extern int tn__gemm_bf16_force; /* run bf16 products on this kernel instead of the best; 0 = the best */
void tn__gemm_pack_a(int trans, const float *A, int lda, int i0, int mc, int k0, int kc, float *pa);
size_t tn__gemm_b_stride(int kc);
void tn__gemm_pack_b(int trans, const float *B, int ldb, int k0, int kc, int j0, int nc, float *pb);
float tn__bf16_round(float f);
void tn__bf16_round_n(float *x, size_t n);
uint32_t tn__bf16_bits(float f);
void tn__gemm_bf16_prep(int kern, float *p, int panels, size_t stride, int kc, int w);
/* ---- src/loss.c ---- */
void tn__argsort_f32(const float *v, size_t n, uint32_t *idx, uint32_t *scratch);
#endif
#ifndef TN_NO_SKETCH
/* ---- src/sketch.c ---- */
extern const int tn__d8x[8], tn__d8y[8];
tn_status tn__cset_add(tn_contour_set *s, size_t *cap, tn_contour_type type, int order, float gradient,
                       const float *pts, int npts);
void tn__cset_height_range(const tn_contour_set *s, float *lo, float *hi);
void tn__nbrs(const uint8_t *m, int w, int h, int x, int y, int p[8]);
int tn__yokoi8(const int p[8]);
#endif
#ifndef TN_NO_EXTRACT
/* ---- src/extract.c ---- */
tn_status tn__channel0_image(const tn_image *src, tn_image *dst);
uint32_t tn__fkey(float f);
tn_status tn__pheap_push(tn__pheap *h, uint64_t pri, uint32_t cell);
uint32_t tn__pheap_replace(tn__pheap *h, tn__pheap_item it);
uint32_t tn__pheap_pop(tn__pheap *h);
#endif
#ifndef TN_NO_GNN
/* ---- src/gnn.c, src/gnn_membrane.c, src/gnn_grow.c ---- */
tn_status tn__gnn_parts_make(const tn_contour_set *set, float mean, float std, tn__gnn_parts *p);
void tn__gnn_parts_free(tn__gnn_parts *p);
int tn__gnn_project(const tn__gnn_parts *P, int part, float x, float y, float *d2);
float tn__gnn_overhang(const tn__gnn_parts *P, int part, float f0, float x, float y);
tn_status tn__gnn_membrane_solve(const float *val, const uint8_t *fixed, int W, int H, float *out);
tn_status tn__gnn_grow_profile(const tn_contour_set *example, const tn_image *er, int kind, float *prof, uint8_t *mask, float *dist,
                               int *near);
tn_status tn__gnn_grow(const tn_contour_set *user, const tn_contour_set *example, const tn_image *dem, int width, int height,
                       const tn_gnn_grow_opts *opts, tn_contour_set *out, int *added, float *relief, float *ground);
tn_status tn__gnn_grow_crest(tn_contour_set *set, int nuser, const tn_contour_set *example, int kind, uint64_t seed);
tn_status tn__gnn_grow_width_field(const float *kv, const int *nearv, int width, int height, float *K);
tn_status tn__gnn_fall_ratio(const tn_image *dem, double *ratio);
tn_status tn__gnn_quilt_erode(const float *ground, const tn_image *ur, const float *Dr, const tn_image *dem, int Ac, float relief,
                              float mix, int width, int height, float *prel);
tn_status tn__gnn_grow_flanks(const tn_contour_set *set, int nuser, const tn_contour_set *example, const tn_image *dem, uint64_t seed, float *field);
#endif
#ifndef TN_NO_TEXGAN
/* ---- src/texgan.c ---- */
int tn__tg_zdim(const tn_texgan *m);
int tn__tg_out_size(const tn_texgan *m, int cells);
void tn__tg_noise(const tn_texgan *m, const float *waves, tn_tensor *z, int item, uint64_t seed, long cx0, long cy0);
void tn__tg_noise_plane(float *dst, uint64_t seed, int stage, long cx0, long cy0, int h, int w);
tn_tensor *tn__tg_pixel_norm(tn_ctx *ctx, tn_tensor *x);
tn_tensor *tn__tg_generate(tn_ctx *ctx, const tn_texgan *m, tn_params *p, const char *prefix, tn_tensor *z,
                           const uint64_t *seeds, long cx0, long cy0);
tn_tensor *tn__tg_generate_fast(tn_ctx *ctx, const tn_texgan *m, tn_tensor *z, uint64_t seed, long cx0, long cy0);
void tn__tg_make_filters(tn__tg_train *s);
tn_status tn__tg_feat_ref(tn__tg_train *s, tn_ctx *ctx, const float *ex, int W, int H);
tn_tensor *tn__tg_feat_loss(tn_ctx *ctx, tn__tg_train *s, tn_tensor *x);
tn_status tn__tg_collect_band(void *user, int y0, const tn_image *band);
void tn__dm_seamless(const tn_image *h, float *out, int axis);
#endif
#ifndef TN_NO_STYLE
/* ---- src/singan.c ---- */
tn_status tn__sg_warp(tn_image *map, float amp, float smooth, uint64_t seed);
tn_status tn__sg_match_detail(tn_image *map, const tn_image *ref);

/* ---- src/style.c ---- */
tn_status tn__style_auto_drainage(tn__style_cfg *c, const tn_image *s);
void tn__style_band_outflow(tn_flow *f);
tn_status tn__style_content_target(tn__style_level *L, const float *anchor);
tn_status tn__style_drain_bins(const float *filled, const float *v, int w, int h, uint8_t *bin);
float tn__style_eval(void *user, const float *xd, float *grad);
tn_status tn__style_hist_targets(tn__style_level *L, const float *src, int w, int h);
void tn__style_level_free(tn__style_level *L);
void tn__style_level_init(tn__style_level *L, const tn__style_cfg *c, int w, int h);
void tn__style_normalise(tn_image *m, int unit_range, double *offset, double *scale);
tn_status tn__style_optimise(tn__style_level *L, float *x, tn__style_cfg *c);
tn_status tn__style_setup(tn__style_cfg *c, const tn_style_opts *opts);
tn_status tn__style_targets(tn__style_level *L, const float *const *crops, int ncrop, uint64_t seed);
#endif
#endif /* TN_INTERNALS */

#ifdef __cplusplus
}
#endif
#endif /* TN__INTERNALS_H */
