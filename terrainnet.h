/* terrainnet.h - learn terrain from one example, synthesise terrain and textures on a CPU.
   Public domain / MIT-0 style: no warranty, use as you like.

RECIPE
    In exactly ONE C or C++ file:
        #define TERRAINNET_IMPLEMENTATION
        #include "terrainnet.h"
    Everywhere else just #include "terrainnet.h". Link with -lm and -pthread
    (or define TN_NO_THREADS to build without pthreads).

USAGE
    tn_image dem = {0};
    tn_image_info info;
    if (tn_image_load("alps.png", &dem, &info) != TN_OK) {
        fprintf(stderr, "%s\n", tn_last_error());
        return 1;
    }
    tn_image shade = {0};
    tn_render_preview(&dem, NULL, &shade);        // hillshaded, colour-ramped RGB
    tn_image_save("alps_preview.png", &shade, NULL);
    tn_image_free(&shade);
    tn_image_free(&dem);

CONFIGURATION (define before including the implementation)
    TN_MALLOC(sz) / TN_REALLOC(p,sz) / TN_FREE(p)  allocation; define all three or none
    TN_ASSERT(x)        programmer-error checks (default: assert); never used on user input
    TN_NO_THREADS       no pthread use at all; everything runs on the calling thread
    TN_NO_TLS           keep the per-thread error detail under a pthread key instead of in
                        thread-local storage (for toolchains whose thread-locals misbehave)
    TN_API              linkage of every public function (default extern; `static` for private use)
    TN_MAX_ALLOC        largest single allocation sized from user data (default 8 GiB); larger
                        requests fail with TN_ERR_TOO_LARGE instead of exhausting memory

ERRORS
    Every fallible call returns tn_status (TN_OK = 0). tn_status_string() names the code and
    tn_last_error() gives the detail of the calling thread's most recent failure (file, reason);
    each thread has its own, and a failure inside the pool's workers is handed to the thread
    that started the parallel work. Nothing in the library exits or aborts on user input;
    TN_ASSERT only guards programmer misuse (e.g. a NULL where the API says non-NULL).

MEMORY
    Functions that fill a struct (tn_image and friends) allocate its buffers; the caller frees them
    with the matching *_free(). On failure nothing is left allocated in the output.

THREADS
    A persistent pool (default: all online CPUs; tn_set_threads(n) to change) runs parallel loops.
    Work is split so results are bit-identical for any thread count.

ARGUMENTS
    Order: the object the call works on (a ctx, params, optimiser or trained model; something
    changed in place; the thing being saved), then inputs, a file path first among them, then
    options (const tn_x_opts *, NULL = defaults), then outputs, the optional ones (NULL = not
    wanted) last: tn_image_load(path, &img, &info), tn_render_preview(&dem, &opts, &out). A struct
    the call fills (a new tn_image, a model being trained or loaded) is an output. Calls older
    than this rule that take their output first (tn_image_crop(dst, src, ...), the other image
    operations, noise makers, tn_style_transfer, tn_texgan_train/load, tn_detail_maps_*) keep
    their order for now.

TABLE OF CONTENTS (grep for the tag; each appears once in the declarations, once in the code)
    @@core      status codes, errors, allocation, RNG, progress, timing
    @@thread    thread pool and parallel-for
    @@image     tn_image, crop/pad/resize, blur, gradients, normals, hillshade, colour ramp
    @@io        file formats: PNG (own inflate/deflate), PGM/PPM, PFM, SRTM .hgt, .asc, .r16
    @@metrics   SSIM, PSNR, RMSE, MAE
    @@gemm      SGEMM: packed, cache-blocked, AVX-512 / AVX2 / portable kernels, threaded
    @@tensor    tensors, arena contexts, the autograd tape
    @@ops       differentiable ops: broadcasting arithmetic, conv (im2col), pooling, norms, graph ops
    @@loss      MSE, L1, BCE, hinge and non-saturating GAN, Gram, TV, SSIM, gradient difference
    @@optim     parameters, .tnw files, Adam / SGD / L-BFGS
    @@train     training runs (budget, progress, checkpoints, resume), model files, shared blocks
    @@noise     procedural maps: Perlin fBm, explicit multi-scale noise, drawn-map blending
    @@sketch    contour sets, .tns sketch files, drawn sketches, random sketches, parts, alignment
    @@extract   ridges and valleys from a DEM: fill, D8, accumulation, Strahler, skeleton; realism
    @@style     terrain style transfer: built-in random-feature net or VGG-19, pyramid, L-BFGS/SGD/Adam
    @@texgan    single-texture spatial GAN, tiled huge textures, colour correction, detail maps
    @@gnn       sketch-to-terrain graph network: example parts, bipartite graph, attention, membrane residual
    @@render    previews: hillshaded colour map and 3D perspective view
    @@export    for engines and 3D tools: glTF 2.0 binary (.glb) and OBJ meshes, normal maps, Unity RAW
*/
#ifndef TERRAINNET_H
#define TERRAINNET_H

#include <stddef.h>
#include <stdint.h>

#ifndef TN_API
#define TN_API extern
#endif

#define TN_VERSION_MAJOR 0
#define TN_VERSION_MINOR 1
#define TN_VERSION_STRING "0.1.0"

#ifdef __cplusplus
extern "C" {
#endif

/* ============================================================================================
   @@core  status codes, errors, allocation, RNG, progress, timing
   ============================================================================================ */

typedef enum tn_status {
    TN_OK = 0,
    TN_ERR_INVALID_ARG,     /* a bad argument value (negative size, unknown option, ...) */
    TN_ERR_OUT_OF_MEMORY,   /* an allocation failed */
    TN_ERR_TOO_LARGE,       /* sizes overflow or exceed TN_MAX_ALLOC */
    TN_ERR_IO,              /* open/read/write failed */
    TN_ERR_FORMAT,          /* unknown or unsupported file format or variant */
    TN_ERR_CORRUPT,         /* the data is damaged: bad CRC, bad zlib stream, truncated */
    TN_ERR_NUMERIC,         /* NaN/Inf in input, or a computation diverged */
    TN_ERR_SHAPE,           /* mismatched sizes/shapes between arguments or with a file */
    TN_ERR_EMPTY,           /* nothing to work on (empty image, empty sketch) */
    TN_ERR_CANCELLED,       /* the progress callback asked to stop */
    TN_STATUS_COUNT
} tn_status;

/* Name of a status code, e.g. "corrupt data". Never NULL. */
TN_API const char *tn_status_string(tn_status s);
/* Detail of the calling thread's most recent failure ("alps.png: CRC mismatch in IDAT chunk");
   "" if none. Each thread has its own buffer, owned by the library and overwritten by that
   thread's next failure: read it right after a failure. */
TN_API const char *tn_last_error(void);
/* Clears the calling thread's last error message. */
TN_API void tn_clear_error(void);

/* Deterministic RNG: PCG32 (O'Neill). The same seed/stream gives the same sequence everywhere. */
typedef struct tn_rng { uint64_t state, inc; } tn_rng;
TN_API void     tn_rng_seed(tn_rng *r, uint64_t seed, uint64_t stream);
TN_API uint32_t tn_rng_u32(tn_rng *r);
TN_API uint32_t tn_rng_below(tn_rng *r, uint32_t n);  /* uniform in [0, n), unbiased; n > 0 */
TN_API float    tn_rng_uniform(tn_rng *r);            /* uniform in [0, 1), 24 random bits */
TN_API float    tn_rng_normal(tn_rng *r);             /* standard normal (Box-Muller) */

/* Progress: long operations call the hook with a stage name and a fraction in [0, 1].
   Return non-zero from the hook to cancel; the operation then fails with TN_ERR_CANCELLED. */
typedef int (*tn_progress_fn)(void *user, const char *stage, double fraction);
TN_API void tn_set_progress(tn_progress_fn fn, void *user);

/* Monotonic wall-clock seconds (for benches and ETA). */
TN_API double tn_time_seconds(void);

/* ============================================================================================
   @@thread  thread pool and parallel-for
   ============================================================================================ */

/* Number of threads used by parallel work; n <= 0 means "all online CPUs". Cheap to call;
   the pool grows lazily. With TN_NO_THREADS it is always 1. */
TN_API void tn_set_threads(int n);
TN_API int  tn_get_threads(void);

/* Runs fn(ctx, ith, nth) for ith = 0..nth-1 on nth threads (the caller runs ith = 0) and returns
   when all are done. nth = tn_get_threads(), or 1 when called from inside a parallel region.
   If a pool thread records a failure and the caller's share does not, the caller's
   tn_last_error() then holds that thread's message (the lowest ith's when several fail). */
typedef void (*tn_task_fn)(void *ctx, int ith, int nth);
TN_API void tn_parallel_run(tn_task_fn fn, void *ctx);

/* Splits [0, n) into contiguous ranges of at least `grain` items and runs fn on each range in
   parallel. Use only where each index's result does not depend on the split. */
typedef void (*tn_range_fn)(void *ctx, size_t begin, size_t end);
TN_API void tn_parallel_for(size_t n, size_t grain, tn_range_fn fn, void *ctx);

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
TN_API size_t    tn_image_range(const tn_image *img, float *lo, float *hi);

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
TN_API tn_status tn_image_gradient(const tn_image *dem, float dx, float dy, tn_image *gx, tn_image *gy);
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
/* Hypsometric terrain colours (water-blue, green lowlands, brown, rock grey, snow white) for
   heights mapped linearly from [lo, hi] (lo == hi: the DEM's own range). RGB in [0, 1]. */
TN_API tn_status tn_image_colour_ramp(tn_image *dst, const tn_image *dem, float lo, float hi);


/* ============================================================================================
   @@io  file formats
   PNG: every bit depth and colour type, Adam7, CRC and Adler-32 checked (own inflate); writes
        8/16-bit with real deflate. A heightmap's metre range rides in a tEXt chunk
        "terrainnet.range" = "<lo> <hi>", so a 16-bit round trip restores real units.
   PGM/PPM (P2/P3/P5/P6, 8/16-bit; range in a "# terrainnet.range lo hi" comment), PFM (float),
   SRTM .hgt (1201^2 or 3601^2 big-endian int16 metres, voids -32768 filled), ESRI ASCII grid
   .asc (NODATA filled), headerless 16-bit little-endian .r16 (size given or square inferred).
   Format is picked by magic bytes, then by extension.
   Pixel values on load: integer formats give [0, 1] (code / max code), or metres when the file
   carries a range; .hgt and .asc give their values as stored (metres); PFM gives raw floats.
   A recorded range beyond float range fails with TN_ERR_NUMERIC (a NaN one is ignored); the
   range text is read and written without the C locale.
   ============================================================================================ */

typedef enum tn_format {
    TN_FORMAT_AUTO = 0, TN_FORMAT_PNG, TN_FORMAT_PNM, TN_FORMAT_PFM, TN_FORMAT_HGT, TN_FORMAT_ASC, TN_FORMAT_R16
} tn_format;

/* What a file held, filled by the loaders. */
typedef struct tn_image_info {
    tn_format format;
    int bit_depth;           /* bits per sample in the file (1..16; 32 for float formats) */
    int file_channels;       /* samples per pixel in the file (palette PNG: 1) */
    int interlaced;          /* PNG Adam7 */
    int has_range;           /* 1 if the file gives a height mapping; pixels were converted with it */
    double range_lo, range_hi; /* code 0 -> range_lo, max code -> range_hi */
    double cellsize;         /* .asc cell size (0 if unknown) */
    double x_origin, y_origin; /* .asc lower-left corner */
    size_t voids_filled;     /* .hgt / .asc cells that were void/NODATA and were filled */
} tn_image_info;

typedef struct tn_load_opts {
    tn_format format;        /* force a format; AUTO = magic bytes, then extension */
    int raw_width, raw_height; /* .r16 size; 0 = infer a square from the file size */
} tn_load_opts;

typedef struct tn_save_opts {
    tn_format format;        /* AUTO = from the extension */
    int bit_depth;           /* 8 or 16 for integer formats; 0 = 16 for 1-channel images, else 8 */
    int has_range;           /* 1: map [range_lo, range_hi] to codes 0..max and record it */
    double range_lo, range_hi; /* has_range == 0: values in [0, 1] are written as they are,
                                  anything else is mapped from its own min..max and recorded */
    int compression;         /* PNG deflate level 0-9; 0 = default (6) */
    double cellsize;         /* .asc cell size; 0 = 1 */
} tn_save_opts;

/* Loads any supported file. info and opts may be NULL. On failure *img is untouched. */
TN_API tn_status tn_image_load(const char *path, tn_image *img, tn_image_info *info);
TN_API tn_status tn_image_load_ex(const char *path, tn_image *img, tn_image_info *info, const tn_load_opts *opts);
/* Same from memory; `name` (may be NULL) is used for the extension fallback and in messages. */
TN_API tn_status tn_image_load_memory(const void *data, size_t size, const char *name, tn_image *img,
                                      tn_image_info *info, const tn_load_opts *opts);
/* Saves; the format comes from opts or the extension. Writes to a temporary file and renames it,
   so a failed save never leaves a half-written file in place. opts may be NULL. */
TN_API tn_status tn_image_save(const char *path, const tn_image *img, const tn_save_opts *opts);
/* Encodes to a malloc'ed (TN_MALLOC) buffer the caller frees with TN_FREE / tn_free. */
TN_API tn_status tn_image_save_memory(const tn_image *img, const tn_save_opts *opts, tn_format format,
                                      uint8_t **out, size_t *out_size);
/* zlib streams (RFC 1950) with terrainnet's own deflate (level 0-9; 0 and zlib's -1 = 6) and inflate (Adler-32
   checked; output over max_out bytes, 0 = TN_MAX_ALLOC, fails with TN_ERR_TOO_LARGE). The output
   buffer is allocated here; free it with tn_free. */
TN_API tn_status tn_zlib_deflate(const uint8_t *src, size_t n, int level, uint8_t **out, size_t *out_size);
TN_API tn_status tn_zlib_inflate(const uint8_t *src, size_t n, uint8_t **out, size_t *out_size, size_t max_out);
/* Name of a format ("png", "pnm", ...). */
TN_API const char *tn_format_name(tn_format f);
/* Frees a buffer returned by the library (tn_image_save_memory and the like). */
TN_API void tn_free(void *p);

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
TN_API tn_status tn_compare(const tn_image *ref, const tn_image *img, double data_range, tn_metrics *out);
/* SSIM only (same definition). */
TN_API tn_status tn_ssim(const tn_image *ref, const tn_image *img, double data_range, double *ssim);

/* ============================================================================================
   @@gemm  single-precision matrix multiply (the engine under tensors and convolutions)
   ============================================================================================ */

/* C = alpha * op(A) * op(B) + beta * C, all row-major. op(X) = X, or X^T when trans_x != 0.
   op(A) is M x K, op(B) is K x N, C is M x N; lda/ldb/ldc are row strides in floats (of A and B
   as stored, i.e. before op). beta == 0 means C is only written (it may hold NaN on entry).
   M, N or K == 0 is allowed (K == 0 gives C = beta * C). Runs on the terrainnet pool; the
   result is bit-identical for any thread count, because every C element is always summed over
   K in the same order (threads split only M or N). Never fails: if its packing scratch cannot
   be allocated it falls back to a slow unpacked loop. */
TN_API void tn_sgemm(int trans_a, int trans_b, int M, int N, int K, float alpha, const float *A, int lda,
                     const float *B, int ldb, float beta, float *C, int ldc);

/* ============================================================================================
   @@tensor  tensors, arenas and the autograd tape
   A tn_tensor is float32 with up to 4 dimensions (NCHW for images, N x D for graph features).
   Every tensor lives in a tn_ctx, a bump arena: parameters in a context that lives as long as the
   model, per-step temporaries in one that is reset each step (after the first steps a training
   loop does no malloc at all). Operations whose inputs require gradients record themselves on the
   context's tape; tn_backward(ctx, loss) replays the tape in reverse, accumulating gradients
   (+=) into every tensor that requires them: parameters, and inputs that asked (style transfer).
   Misuse by the programmer (mismatched shapes) trips TN_ASSERT. Running out of memory marks the
   context as failed: the op returns NULL, later ops given NULL return NULL, and tn_backward /
   tn_ctx_status report TN_ERR_OUT_OF_MEMORY.
   ============================================================================================ */

#define TN_MAX_DIMS 4

typedef struct tn_ctx tn_ctx;
typedef struct tn_tensor tn_tensor;
typedef void (*tn_backward_fn)(tn_ctx *ctx, tn_tensor *out);

struct tn_tensor {
    int ndim;
    int shape[TN_MAX_DIMS];   /* unused trailing entries are 1 */
    size_t numel;
    float *data;
    float *grad;              /* NULL until a gradient flows here (parameters: allocated up front) */
    int requires_grad;
    /* the tape record: how this tensor was made */
    tn_backward_fn backward;
    tn_tensor *src[4];
    int ip[12];               /* op integer parameters */
    float fp[4];              /* op float parameters */
    void *aux;                /* op scratch kept for the backward pass (in the same context) */
    char name[40];            /* parameters: the name saved in .tnw files */
};

/* Creates an empty arena context. Caller frees with tn_ctx_free. NULL if out of memory. */
TN_API tn_ctx *tn_ctx_create(void);
TN_API void tn_ctx_free(tn_ctx *ctx);
/* Forgets every tensor made since creation (or the last reset), keeping the memory. */
TN_API void tn_ctx_reset(tn_ctx *ctx);
/* TN_OK, or the first failure inside the context (out of memory). */
TN_API tn_status tn_ctx_status(const tn_ctx *ctx);
/* Bytes handed out since the last reset. */
TN_API size_t tn_ctx_used(const tn_ctx *ctx);
/* Turns tape recording off (inference) or on (default). */
TN_API void tn_ctx_set_grad(tn_ctx *ctx, int enabled);
/* Scratch memory from the arena (64-byte aligned, uninitialised); NULL on failure. */
TN_API void *tn_ctx_alloc(tn_ctx *ctx, size_t bytes);

/* New zero-filled tensor of the given shape (1 to 4 dims, every size >= 1). NULL on failure. */
TN_API tn_tensor *tn_tensor_new(tn_ctx *ctx, int ndim, const int *shape);
TN_API tn_tensor *tn_tensor_1d(tn_ctx *ctx, int n);
TN_API tn_tensor *tn_tensor_2d(tn_ctx *ctx, int rows, int cols);
TN_API tn_tensor *tn_tensor_4d(tn_ctx *ctx, int n, int c, int h, int w);
/* Makes t a leaf that collects a gradient (allocates t->grad, zeroed). Returns t. */
TN_API tn_tensor *tn_tensor_requires_grad(tn_ctx *ctx, tn_tensor *t);
TN_API void tn_tensor_fill(tn_tensor *t, float v);
/* 1 if a and b have the same dims. */
TN_API int tn_tensor_same_shape(const tn_tensor *a, const tn_tensor *b);
/* Views an image (one batch item, H x W x C interleaved) as a new 1 x C x H x W tensor (copy). */
TN_API tn_tensor *tn_tensor_from_image(tn_ctx *ctx, const tn_image *img);
/* Copies batch item `n` of an N x C x H x W tensor into a new image. Caller frees *img. */
TN_API tn_status tn_tensor_to_image(const tn_tensor *t, int n, tn_image *img);

/* Runs the tape backwards from `loss` (a one-element tensor, gradient 1). Gradients accumulate:
   zero parameter gradients between steps (tn_params_zero_grad). */
TN_API tn_status tn_backward(tn_ctx *ctx, tn_tensor *loss);

/* ============================================================================================
   @@ops  differentiable operations
   Every op takes the context its output lives in, returns a new tensor (NULL if an input is
   NULL or memory ran out) and records its backward pass when an input requires a gradient.
   Shapes follow PyTorch: images N x C x H x W, conv weights Cout x Cin x KH x KW, transposed
   conv weights Cin x Cout x KH x KW, linear weights out x in.
   ============================================================================================ */

/* Elementwise with NumPy broadcasting (shapes aligned at the right, size-1 dims stretch). */
TN_API tn_tensor *tn_add(tn_ctx *ctx, tn_tensor *a, tn_tensor *b);
TN_API tn_tensor *tn_sub(tn_ctx *ctx, tn_tensor *a, tn_tensor *b);
TN_API tn_tensor *tn_mul(tn_ctx *ctx, tn_tensor *a, tn_tensor *b);
TN_API tn_tensor *tn_div(tn_ctx *ctx, tn_tensor *a, tn_tensor *b);
/* a * scale + shift */
TN_API tn_tensor *tn_scale_shift(tn_ctx *ctx, tn_tensor *a, float scale, float shift);
/* Unary functions */
TN_API tn_tensor *tn_relu(tn_ctx *ctx, tn_tensor *a);
TN_API tn_tensor *tn_leaky_relu(tn_ctx *ctx, tn_tensor *a, float slope);
TN_API tn_tensor *tn_elu(tn_ctx *ctx, tn_tensor *a, float alpha);
TN_API tn_tensor *tn_tanh(tn_ctx *ctx, tn_tensor *a);
TN_API tn_tensor *tn_sigmoid(tn_ctx *ctx, tn_tensor *a);
TN_API tn_tensor *tn_softplus(tn_ctx *ctx, tn_tensor *a);
TN_API tn_tensor *tn_abs(tn_ctx *ctx, tn_tensor *a);
TN_API tn_tensor *tn_square(tn_ctx *ctx, tn_tensor *a);
/* |a|^p elementwise (p > 0; gradient 0 at a == 0 for p <= 1) */
TN_API tn_tensor *tn_pow_abs(tn_ctx *ctx, tn_tensor *a, float p);

/* Matrix product of 2-D tensors: op(a) x op(b), op = transpose when the flag is set. */
TN_API tn_tensor *tn_matmul(tn_ctx *ctx, tn_tensor *a, tn_tensor *b, int trans_a, int trans_b);
/* x (N x in) times W^T (W: out x in) plus bias (out; may be NULL). */
TN_API tn_tensor *tn_linear(tn_ctx *ctx, tn_tensor *x, tn_tensor *w, tn_tensor *bias);

/* Reductions: over everything (a one-element tensor) or over one axis (kept as size 1). */
TN_API tn_tensor *tn_sum(tn_ctx *ctx, tn_tensor *a);
TN_API tn_tensor *tn_mean(tn_ctx *ctx, tn_tensor *a);
TN_API tn_tensor *tn_sum_axis(tn_ctx *ctx, tn_tensor *a, int axis);
TN_API tn_tensor *tn_mean_axis(tn_ctx *ctx, tn_tensor *a, int axis);

/* Shape ops (they copy). */
TN_API tn_tensor *tn_reshape(tn_ctx *ctx, tn_tensor *a, int ndim, const int *shape);
/* out dim i = a dim perm[i] */
TN_API tn_tensor *tn_permute(tn_ctx *ctx, tn_tensor *a, const int *perm);
/* Concatenation / slicing along any axis (axis 1 = channels for images). */
TN_API tn_tensor *tn_concat(tn_ctx *ctx, tn_tensor *a, tn_tensor *b, int axis);
TN_API tn_tensor *tn_slice(tn_ctx *ctx, tn_tensor *a, int axis, int start, int len);

typedef enum tn_padding { TN_PADDING_ZERO = 0, TN_PADDING_REFLECT } tn_padding;
typedef struct tn_conv_opts {
    int stride;      /* 0 = 1 */
    int pad;         /* zero = no padding; same on all sides */
    int dilation;    /* 0 = 1 */
    tn_padding padding;
    int output_padding; /* transposed conv only: extra rows/cols at the bottom/right */
} tn_conv_opts;
/* 2-D convolution (cross-correlation) via im2col + SGEMM. bias may be NULL; opts NULL = stride 1,
   no padding. */
TN_API tn_tensor *tn_conv2d(tn_ctx *ctx, tn_tensor *x, tn_tensor *w, tn_tensor *bias, const tn_conv_opts *opts);
/* Transposed convolution (the gradient of conv2d with respect to its input), w: Cin x Cout x KH x KW.
   Output size (H - 1) * stride - 2 * pad + dilation * (KH - 1) + output_padding + 1. */
TN_API tn_tensor *tn_conv_transpose2d(tn_ctx *ctx, tn_tensor *x, tn_tensor *w, tn_tensor *bias, const tn_conv_opts *opts);
/* Pooling with a square window k and stride s (no padding; partial windows dropped). */
TN_API tn_tensor *tn_avg_pool2d(tn_ctx *ctx, tn_tensor *x, int k, int s);
TN_API tn_tensor *tn_max_pool2d(tn_ctx *ctx, tn_tensor *x, int k, int s);
/* Upsampling: nearest by an integer factor; bilinear to any size (align_corners = false). */
TN_API tn_tensor *tn_upsample_nearest(tn_ctx *ctx, tn_tensor *x, int factor);
TN_API tn_tensor *tn_upsample_bilinear(tn_ctx *ctx, tn_tensor *x, int out_h, int out_w);

/* Normalisation. batch norm: statistics over N, H, W per channel; in training it updates the
   running mean/var (momentum 0.1) in place, in eval it uses them. gamma/beta (C) may be NULL. */
TN_API tn_tensor *tn_batch_norm(tn_ctx *ctx, tn_tensor *x, tn_tensor *gamma, tn_tensor *beta, tn_tensor *running_mean,
                                tn_tensor *running_var, int training, float eps);
/* Instance norm: statistics over H, W per (n, c); gamma/beta (C) may be NULL. */
TN_API tn_tensor *tn_instance_norm(tn_ctx *ctx, tn_tensor *x, tn_tensor *gamma, tn_tensor *beta, float eps);
/* SPADE: parameter-free instance norm of x, then x_norm * (1 + gamma) + beta with per-pixel
   gamma/beta tensors shaped like x (made by convolutions of a conditioning map). */
TN_API tn_tensor *tn_spade_norm(tn_ctx *ctx, tn_tensor *x, tn_tensor *gamma, tn_tensor *beta, float eps);
/* Spectral normalisation: w / sigma(w), w viewed as rows = shape[0]. u (rows) is the persistent
   power-iteration vector, updated in place (`iters` steps, 1 is usual during training). */
TN_API tn_tensor *tn_spectral_norm(tn_ctx *ctx, tn_tensor *w, tn_tensor *u, int iters);

/* Graph ops on row-major N x D features. idx / seg hold row numbers. */
TN_API tn_tensor *tn_gather_rows(tn_ctx *ctx, tn_tensor *x, const int *idx, int n);
/* out[seg[i]] += x[i] for i < rows(x); out has nseg rows (segment sum). */
TN_API tn_tensor *tn_scatter_add_rows(tn_ctx *ctx, tn_tensor *x, const int *seg, int nseg);
/* Softmax of scores (E x H: E entries, H heads) within each segment (seg[e] in [0, nseg)). */
TN_API tn_tensor *tn_segment_softmax(tn_ctx *ctx, tn_tensor *scores, const int *seg, int nseg);
/* softmax((logits + Gumbel noise) / tau) over the last axis of an N x K tensor. */
TN_API tn_tensor *tn_gumbel_softmax(tn_ctx *ctx, tn_tensor *logits, float tau, tn_rng *rng);
/* Inverted dropout with probability p when training; identity otherwise. */
TN_API tn_tensor *tn_dropout(tn_ctx *ctx, tn_tensor *x, float p, int training, tn_rng *rng);

/* ============================================================================================
   @@loss  losses (each returns a one-element tensor)
   ============================================================================================ */
TN_API tn_tensor *tn_mse_loss(tn_ctx *ctx, tn_tensor *pred, tn_tensor *target);
TN_API tn_tensor *tn_l1_loss(tn_ctx *ctx, tn_tensor *pred, tn_tensor *target);
/* mean of softplus(x) - x * t: binary cross-entropy on logits, stable for any x. */
TN_API tn_tensor *tn_bce_logits_loss(tn_ctx *ctx, tn_tensor *logits, tn_tensor *target);
/* Hinge GAN: discriminator mean(relu(1 - real)) + mean(relu(1 + fake)); generator -mean(fake). */
TN_API tn_tensor *tn_hinge_d_loss(tn_ctx *ctx, tn_tensor *real_scores, tn_tensor *fake_scores);
TN_API tn_tensor *tn_hinge_g_loss(tn_ctx *ctx, tn_tensor *fake_scores);
/* Non-saturating GAN: discriminator mean(softplus(-real)) + mean(softplus(fake)); generator
   mean(softplus(-fake)). */
TN_API tn_tensor *tn_nonsat_d_loss(tn_ctx *ctx, tn_tensor *real_scores, tn_tensor *fake_scores);
TN_API tn_tensor *tn_nonsat_g_loss(tn_ctx *ctx, tn_tensor *fake_scores);
/* Gram matrices of N x C x H x W features: N x C x C... returned as (N*C) x C, scaled by `scale`
   (e.g. 1 / (C*H*W)). */
TN_API tn_tensor *tn_gram(tn_ctx *ctx, tn_tensor *x, float scale);
/* Total variation sum over pixels of (dx^2 + dy^2)^(beta/2) (beta 2: the plain squared TV). */
TN_API tn_tensor *tn_tv_loss(tn_ctx *ctx, tn_tensor *x, float beta);
/* 1 - SSIM (Gaussian 11 x 11, sigma 1.5, valid region), differentiable; data range R. */
TN_API tn_tensor *tn_ssim_loss(tn_ctx *ctx, tn_tensor *x, tn_tensor *y, float data_range);
/* Gradient-difference loss: mean | |dx(a)| - |dx(b)| | + mean | |dy(a)| - |dy(b)| |. */
TN_API tn_tensor *tn_gdl_loss(tn_ctx *ctx, tn_tensor *a, tn_tensor *b);


/* ============================================================================================
   @@optim  parameters, initialisation, optimisers, .tnw files
   tn_params owns a model's tensors (learned weights and saved buffers such as running means)
   in its own arena. Optimisers update every tensor of a tn_params that has a gradient.
   .tnw layout (little-endian): "TNW1", u32 version, u32 count; version 2 then has u32 n and n
   bytes of metadata, UTF-8 "key=value\n" lines; then per tensor u16 name length, name bytes,
   u8 ndim, u8 flags (1 = buffer), u32 dims[ndim], float32 data[numel]; finally u32 CRC-32 of
   every byte before it. Version 1 (no metadata) is written when a set has no metadata.
   ============================================================================================ */

typedef struct tn_params tn_params;
TN_API tn_params *tn_params_create(void);
TN_API void tn_params_free(tn_params *p);
/* A new zeroed learned tensor with a gradient; names must be unique (< 40 chars). NULL on failure. */
TN_API tn_tensor *tn_params_add(tn_params *p, const char *name, int ndim, const int *shape);
/* A saved tensor without a gradient (running statistics, power-iteration vectors). */
TN_API tn_tensor *tn_params_add_buffer(tn_params *p, const char *name, int ndim, const int *shape);
TN_API int tn_params_count(const tn_params *p);
TN_API tn_tensor *tn_params_get(const tn_params *p, int i);
TN_API tn_tensor *tn_params_find(const tn_params *p, const char *name);
TN_API size_t tn_params_numel(const tn_params *p);  /* learned values only */
TN_API void tn_params_zero_grad(tn_params *p);
/* Scales gradients so their global L2 norm is at most max_norm; returns the norm before. */
TN_API float tn_params_clip_grad(tn_params *p, float max_norm);
/* Saves atomically (temporary file + rename). */
TN_API tn_status tn_params_save(const tn_params *p, const char *path);
/* Loads into existing tensors; every name and shape must match, otherwise nothing changes and
   the error names the first mismatch. */
TN_API tn_status tn_params_load(tn_params *p, const char *path);
TN_API tn_status tn_params_load_memory(tn_params *p, const uint8_t *data, size_t size, const char *name);
/* Reads any .tnw file into a new set holding exactly its tensors and metadata (for tools that
   inspect a file, and loaders whose layout depends on the file). *out is NULL on failure. */
TN_API tn_status tn_params_open(const char *path, tn_params **out);
TN_API tn_status tn_params_open_memory(const uint8_t *data, size_t size, const char *name, tn_params **out);

/* Metadata: text key/value pairs saved with the tensors (keys [A-Za-z0-9_.-], < 64 chars; values
   printable, no newline, < 1024 chars). Setting a key again replaces it; value NULL removes it.
   Loading a file replaces the set's metadata with the file's. */
TN_API tn_status tn_params_set_meta(tn_params *p, const char *key, const char *value);
/* The value of key, or NULL. Valid until the key is set again or the set is freed. */
TN_API const char *tn_params_meta(const tn_params *p, const char *key);
TN_API int tn_params_meta_count(const tn_params *p);
/* The i-th pair in insertion order (0 <= i < count); *value may be NULL if not wanted. */
TN_API const char *tn_params_meta_key(const tn_params *p, int i, const char **value);

/* Initialisers. fan_in = numel / shape[0]. */
TN_API void tn_init_uniform(tn_tensor *t, tn_rng *rng, float lo, float hi);
TN_API void tn_init_normal(tn_tensor *t, tn_rng *rng, float mean, float std);
/* He/Kaiming normal for ReLU-like layers: std = gain / sqrt(fan_in). */
TN_API void tn_init_kaiming(tn_tensor *t, tn_rng *rng, float gain);

typedef enum tn_optim_kind { TN_OPTIM_ADAM = 0, TN_OPTIM_SGD } tn_optim_kind;
typedef struct tn_optim_opts {
    tn_optim_kind kind;
    float lr;             /* 0 = 1e-3 */
    float beta1, beta2;   /* Adam; both 0 = 0.9, 0.999 (set beta2 to use beta1 = 0) */
    float eps;            /* Adam; 0 = 1e-8 */
    float weight_decay;   /* L2 added to the gradient (Adam, SGD) */
    float momentum;       /* SGD */
    float lr_decay;       /* multiply the rate by this every decay_every steps; 0 = no decay */
    int decay_every;      /* 0 = 1 */
    float clip_norm;      /* > 0: clip the global gradient norm before each step */
} tn_optim_opts;
typedef struct tn_optim tn_optim;
/* NULL with tn_last_error() set for NaN/Inf settings, betas outside [0, 1) or negative momentum. */
TN_API tn_optim *tn_optim_create(tn_params *p, const tn_optim_opts *opts);
TN_API void tn_optim_free(tn_optim *o);
/* One update from the current gradients (does not zero them). */
TN_API void tn_optim_step(tn_optim *o);
TN_API float tn_optim_lr(const tn_optim *o);

/* L-BFGS on a flat vector: fn returns f(x) and writes its gradient. History m (0 = 10),
   backtracking line search (Armijo). Stops after max_iter iterations, when the gradient norm
   drops below tol, or when no step lowers f. final_f may be NULL. n == 0, a NULL x or fn, history
   outside 0..65536 or NaN/Inf options fail with TN_ERR_INVALID_ARG; a NaN/Inf objective or
   gradient with TN_ERR_NUMERIC. */
typedef float (*tn_lbfgs_fn)(void *user, const float *x, float *grad);
typedef struct tn_lbfgs_opts { int max_iter; int history; float tol; float first_step; } tn_lbfgs_opts;
TN_API tn_status tn_lbfgs(float *x, size_t n, tn_lbfgs_fn fn, void *user, const tn_lbfgs_opts *opts, float *final_f);

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
TN_API tn_status tn_train_create(const char *method, const char *stage, const tn_train_opts *opts, tn_train **out);
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
/* The run's seed (a resumed run reports the seed of the run that wrote the checkpoint). */
TN_API uint64_t tn_train_seed(const tn_train *run);
TN_API int tn_train_checkpoints(const tn_train *run);
/* Writes a checkpoint now (to opts->checkpoint, or to path if not NULL). */
TN_API tn_status tn_train_checkpoint(tn_train *run, const char *path);

/* Seconds left in the operation now reporting progress (from inside a progress hook), < 0 when
   unknown. Training runs keep it current. */
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

/* Keep the best k snapshots of a parameter set by a score (lower is better). */
typedef struct tn_best_k tn_best_k;
TN_API tn_best_k *tn_best_k_create(int k);
TN_API void tn_best_k_free(tn_best_k *b);
/* Copies p if its score is among the k best so far (NaN scores are never kept). 1 = kept. */
TN_API int tn_best_k_offer(tn_best_k *b, const tn_params *p, double score, long iteration);
TN_API int tn_best_k_count(const tn_best_k *b);
/* The i-th best (0 = best); score and iteration may be NULL. */
TN_API const tn_params *tn_best_k_get(const tn_best_k *b, int i, double *score, long *iteration);

/* ============================================================================================
   @@noise  procedural maps (paper 002, section 2.1)
   Perlin fBm (improved gradient noise, seeded permutation, octaves summed with frequency x
   lacunarity and amplitude x gain per octave, as Algorithm 2) and explicit noise (Algorithm 1:
   uniform random matrices at several scales, upscaled, Gaussian-smoothed, averaged). Outputs are
   one-channel images normalised to [0, 1]; the same seed gives the same map everywhere, for any
   thread count.
   ============================================================================================ */

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

/* ============================================================================================
   @@sketch  contour sets: ridge and valley polylines (paper 000, sections 4.1 and 5)
   One type carries extracted ridge/valley networks, their contour parts and user sketches: a
   canvas size and a list of polylines, each point (x, y, height) in canvas pixels and the
   height units of its source (metres for an extracted DEM, [0, 1] for a drawn sketch).
   On it: the .tns text format, sketches drawn as images (thinning + tracing), rasterising,
   random sketches (5.2: MST of random nodes, MST of their Voronoi vertices), cutting polylines
   into 5-10 point contour parts (4.1) and aligning sketch parts to DEM parts (5.3, A1/A2:
   chain codes, rotation by k pi/4, longest common substring, height mean/std, seeded pick).
   ============================================================================================ */

typedef enum tn_contour_type { TN_VALLEY = 0, TN_RIDGE = 1 } tn_contour_type;

typedef struct tn_contour {
    tn_contour_type type;
    int order;             /* Strahler order (1 = source segment); 0 when unknown */
    int npoints;
    float mean_gradient;   /* mean slope magnitude along the polyline; 0 when unknown */
    float *points;         /* npoints * 3 floats: x, y, height */
} tn_contour;

typedef struct tn_contour_set {
    int width, height;     /* canvas size in pixels */
    int count;
    tn_contour *items;
} tn_contour_set;

/* Frees every polyline and zeroes *set. Safe on a zeroed set. */
TN_API void tn_contour_set_free(tn_contour_set *set);

/* ---- sketch files (.tns) ---------------------------------------------------------------------
   A human-editable text format for any contour set (user sketches, extracted ridge/valley
   networks, contour parts). Line by line, '#' starts a comment, blank lines are ignored:

       terrainnet-sketch 1              first line: magic and version
       canvas 256 256                   canvas width and height in pixels (once, before polylines)
       ridge order 2 gradient 0.13      opens a polyline: `ridge` or `valley`, then optional
                                        `order N` (Strahler, default 0), `gradient G` (mean slope,
                                        default 0), `start H` and `rate R` (see below)
       10 20 0.8                        one point per line: x y [h], pixels, (0, 0) = top-left
       40.5 22 0.75                     pixel centre; x in [-0.5, W - 0.5], y likewise
       end                              closes the polyline

   A point without h takes start + rate * (arc length in pixels from the first point), so
   `valley start 0.2 rate 0.001` rises 0.001 per pixel. Heights are [0, 1] for drawn sketches
   and metres for extracted networks. Saving writes every height, order and gradient as the
   shortest locale-free text that reads back as the same float, so load(save(s)) == s exactly;
   reading ignores the C locale too. Errors carry "file:line:". */

#define TN_SKETCH_MAX_SIDE 65536           /* largest canvas side */
#define TN_SKETCH_MAX_POINTS (1 << 26)     /* most points in one file */

/* Parses .tns text (n bytes, need not be NUL-terminated). `name` (may be NULL) prefixes messages.
   Fails with TN_ERR_FORMAT (not a sketch, unknown version), TN_ERR_CORRUPT (malformed line,
   missing canvas or end, point outside the canvas), TN_ERR_NUMERIC (NaN/Inf), TN_ERR_TOO_LARGE
   (canvas side or point count over the limits). On success *out is allocated (tn_contour_set_free). */
TN_API tn_status tn_sketch_parse(const char *text, size_t n, const char *name, tn_contour_set *out);
/* Loads a .tns file, or a sketch drawn as an image (see tn_sketch_from_image) when the file is
   not .tns text. *out is untouched on failure. */
TN_API tn_status tn_sketch_load(const char *path, tn_contour_set *out);
/* Writes the set as .tns text into a TN_MALLOC'd buffer (free with tn_free). Fails with
   TN_ERR_NUMERIC on NaN/Inf points and TN_ERR_INVALID_ARG on a bad canvas, an empty polyline, an
   order outside 0-1000 or a point outside the canvas (so whatever is written reads back). */
TN_API tn_status tn_sketch_format(const tn_contour_set *set, char **text, size_t *size);
/* Saves as .tns through a temporary file and a rename: on any error the target is untouched. */
TN_API tn_status tn_sketch_save(const char *path, const tn_contour_set *set);

/* Reads a sketch drawn as an RGB(A) image: strokes in saturated red are ridges, saturated blue
   are valleys; everything else (white, black, grey, yellow, ...) is background. A pixel is a
   stroke when v = max(r, b) >= 0.1, v - g >= v / 2 and |r - b| >= v / 2; its height is v, so a
   bright stroke is high and a dark one low (heights in [0.1, 1]). Strokes of any width are
   thinned (tn_skeletonize) and traced into polylines between endpoints and junctions; the canvas
   is the image size. Fails with TN_ERR_SHAPE for 1-2 channel images, TN_ERR_EMPTY without strokes. */
TN_API tn_status tn_sketch_from_image(const tn_image *img, tn_contour_set *out);

/* Thins a binary mask (w*h bytes, non-zero = set) in place to one-pixel-wide 8-connected lines
   that keep the topology: Guo-Hall thinning (keeps two-pixel diagonal strokes), then any pixel
   whose removal keeps the 8-connected topology and that is not an endpoint is removed. Used for
   drawn sketches and for extracted ridge/valley networks. */
TN_API tn_status tn_skeletonize(uint8_t *mask, int width, int height);

/* Resamples every polyline to an 8-connected chain of integer pixels (consecutive points
   differ by at most 1 in x and y, no repeats), heights linear between the original points.
   Use before tn_contour_parts_make on sketches whose points are far apart. *out allocated here. */
TN_API tn_status tn_sketch_densify(const tn_contour_set *in, tn_contour_set *out);

/* Rasterises to a width x height x 3 image (any size; coordinates scale from the canvas):
   channel 0 = 1 on ridge pixels, channel 1 = 1 on valley pixels, channel 2 = the sketch height
   there (0 elsewhere; where lines overlap, the later polyline wins). *out allocated here. */
TN_API tn_status tn_sketch_rasterise(const tn_contour_set *set, int width, int height, tn_image *out);
/* RGB preview: ridges yellow, valleys blue, over a hillshade of `dem` (resized; may be NULL for
   a grey background). Lines are 1 px wide up to 511 px and thicker above. *out allocated here. */
TN_API tn_status tn_sketch_preview(const tn_contour_set *set, const tn_image *dem, int width, int height, tn_image *out);

/* ---- random sketches (section 5.2) ---------------------------------------------------------
   n random nodes with heights in [0.5, 1] joined by a Euclidean minimum spanning tree are the
   candidate ridges; the Voronoi vertices of the nodes (circumcentres of their Delaunay
   triangles, inside the canvas) with heights in [0, 0.5] joined by another MST are the candidate
   valleys. Each edge is drawn as an 8-connected pixel line; ridge edges that touch or cross the
   user's sketch pixels are dropped, then valley edges that touch or cross the sketch or a kept
   ridge, so nothing crosses in the output. Kept edges are chained between branch points, heights
   linear along each edge. */

typedef struct tn_sketch_random_opts {
    uint64_t seed;
    int nodes;            /* random ridge nodes, at most 8192; 0 = width * height / 1024, clamped to [8, 2048];
                             negative: TN_ERR_INVALID_ARG */
} tn_sketch_random_opts;
/* *out = the user's polylines (user may be NULL or empty) followed by the random ridges and
   valleys, on a width x height canvas (user's canvas size must match when given, else
   TN_ERR_SHAPE). Same seed, same output. opts may be NULL. */
TN_API tn_status tn_sketch_random(const tn_contour_set *user, int width, int height, const tn_sketch_random_opts *opts,
                                  tn_contour_set *out);

/* Delaunay triangulation (Bowyer-Watson, O(n^2); fine for a few thousand points) of n points
   xy[2n]: *ntriangles triangles of 3 point indices each (winding unspecified), TN_MALLOC'd, free
   with tn_free. Exact duplicate points are skipped; fewer than 3 distinct points give none. */
TN_API tn_status tn_delaunay(const float *xy, int n, int **triangles, int *ntriangles);
/* Euclidean minimum spanning tree (Prim, O(n^2)) of n >= 1 points: *edges holds n - 1 pairs of
   point indices (TN_MALLOC'd, free with tn_free). Ties go to the lower index. NaN/Inf
   coordinates fail with TN_ERR_NUMERIC. */
TN_API tn_status tn_mst(const float *xy, int n, int **edges);

/* ---- contour parts (section 4.1) -----------------------------------------------------------
   The polylines form a graph: ends of the same type at the same or 8-adjacent pixels meet (a
   junction). From each free end (lowest line index first; then from any closed loop left), a
   depth-first walk lists the points of the lines it reaches, each line from the end it is
   entered by, the lines on its far end first (lowest index first), a shared junction pixel
   once. The list is cut into parts of 5-10 points (seeded random lengths; a tail that would be
   shorter than 5 is taken into the last part when that stays <= 10 points); where consecutive
   points are not 8-adjacent (|dx| or |dy| > 1.5 px: the walk jumped back to a junction) the
   window is split at the break and pieces under 5 points are dropped. So parts run through
   junctions. A part takes the type, order and gradient of the line its first point is on; its
   index is its position in *parts (same input and seed, same parts). Used for DEM networks and
   densified sketches alike. An empty input gives an empty set. */
TN_API tn_status tn_contour_parts_make(const tn_contour_set *lines, uint64_t seed, tn_contour_set *parts);

/* ---- alignment (section 5.3, algorithms A1 and A2) ------------------------------------------
   Every part becomes an 8-direction chain code (steps quantised to k * pi/4), reversed when it
   runs right-to-left (first x > last x); each DEM part is rotated by the multiple of pi/4 nearest
   to the angle between the two parts' first-to-last vectors. The longest common substring of
   the codes picks the 10 best DEM parts (ties: smaller height score), the height score on the
   common substring, |mean(d)| + std(d) with d the height differences after each set is scaled
   to [0, 1] by its own range, ranks them, and one of the best 5 is chosen with the seeded RNG.
   Only parts of the same type (ridge/valley) are candidates when the DEM has any. */

typedef struct tn_align_opts {
    uint64_t seed;
    int top;              /* candidates kept by LCS length; 0 = 10 (at most 64) */
    int choices;          /* random pick among the best this many by height; 0 = 5 (1 = greedy) */
    int raw_heights;      /* 1: compare heights as given instead of scaling each set to [0, 1] */
} tn_align_opts;
/* match[i] (caller-allocated, sketch_parts->count ints) = index of the DEM part aligned to sketch
   part i. TN_ERR_EMPTY when either set has no parts; threaded, same result for any thread count.
   Reports progress as stage "align" every 1024 sketch parts (cancellable). */
TN_API tn_status tn_sketch_align(const tn_contour_set *sketch_parts, const tn_contour_set *dem_parts,
                                 const tn_align_opts *opts, int *match);

/* ============================================================================================
   @@extract  ridge and valley networks from a DEM (paper 000, section 4.1); realism report
   Valleys: depression filling (priority-flood + epsilon, so every cell drains), D8 steepest
   descent (diagonals at sqrt 2), flow accumulation; cells draining at least `threshold` cells are
   valley cells. Ridges: the same on the inverted DEM. The masks are then, in the paper's order,
   closed (3x3), Strahler-ordered, thinned (Zhang-Suen + removal of the remaining simple pixels,
   so lines are one pixel wide and 8-connected with the topology kept), traced into polylines
   between junctions and endpoints, filtered (dangling contours under 10 px; contours whose mean
   gradient is in the lowest 1 % of all contours' or exactly 0) and split when long. The polylines
   are 8-connected pixel chains, so tn_contour_parts_make (@@sketch) cuts them into parts directly
   and tn_sketch_preview draws them over the DEM (the paper's Figure 6).
   ============================================================================================ */

#define TN_FLOW_OUTLET 255   /* direction code of a cell that drains off the map (no lower neighbour) */

/* D8 flow on a DEM. dir: 0..7 = E, SE, S, SW, W, NW, N, NE (x right, y down the rows), or
   TN_FLOW_OUTLET. acc: cells draining through each cell, itself included (>= 1). */
typedef struct tn_flow {
    int width, height;
    uint8_t *dir;
    uint32_t *acc;
} tn_flow;

/* Priority-flood depression filling with epsilon (Barnes et al. 2014): every cell ends at least
   one float step (nextafter) above the cell it was flooded from, so every cell has a strictly
   lower neighbour or lies on the border. Channel 0 is used; the result has one channel.
   NaN/Inf heights fail with TN_ERR_NUMERIC. Caller frees *dst. */
TN_API tn_status tn_fill_depressions(tn_image *dst, const tn_image *dem);
/* D8 directions of a (filled) DEM into flow->dir (allocated here; acc left NULL). A cell drains
   to its steepest strictly lower neighbour (drop / distance, distance 1 or sqrt 2; ties go to
   the first in E, SE, S, ... order). Border cells are outlets: they drain off the map, so no flow
   runs along the edges. Threaded. */
TN_API tn_status tn_flow_directions(tn_flow *flow, const tn_image *filled);
/* Flow accumulation from flow->dir into flow->acc (allocated here), O(n) by walking down from
   cells nobody drains into; threaded by strips of rows (same result for any thread count).
   Fails with TN_ERR_CORRUPT if the directions hold a cycle, point off the map or hold a code
   other than 0-7 and TN_FLOW_OUTLET. */
TN_API tn_status tn_flow_accumulation(tn_flow *flow);
/* All three on dem (invert != 0: on -dem, for ridges). Cells the fill raised (depressions and
   flats) drain instead to the cell the flood reached them from, visiting cells as GRASS
   r.watershed's A* search does (lowest first, equal heights oldest first, S N W E before the
   diagonals), so flow crosses flats and lakes where r.watershed -s puts it; the rest is the D8
   of tn_flow_directions. Caller frees with tn_flow_free. */
TN_API tn_status tn_flow_compute(tn_flow *flow, const tn_image *dem, int invert);
TN_API void      tn_flow_free(tn_flow *flow);

/* Strahler order of the network cells (mask != 0) along the flow directions: sources are 1; a
   cell whose upstream network cells reach their maximum order k at least twice gets k + 1, else
   k. order[] (w*h bytes, caller's) is 0 off the network. The network must be closed downstream
   (a threshold mask on the accumulation is). Returns the highest order in *max_order. Direction
   codes other than 0-7 and TN_FLOW_OUTLET, or ones stepping off the map, fail with TN_ERR_CORRUPT. */
TN_API tn_status tn_strahler_order(const tn_flow *flow, const uint8_t *mask, uint8_t *order, int *max_order);

enum { TN_EXTRACT_BOTH = 0, TN_EXTRACT_VALLEYS = 1, TN_EXTRACT_RIDGES = 2 };

/* Zero means the default everywhere. */
typedef struct tn_extract_opts {
    int threshold;        /* accumulation threshold in cells; 0 = tn_extract_default_threshold() */
    int closing;          /* closing radius in px (3x3 = 1); 0 = 1, < 0 = no closing */
    int min_length;       /* dangling contours shorter than this (px) are dropped; 0 = 10 */
    float drop_fraction;  /* contours whose mean gradient is under this quantile of the contours'
                             mean gradients (or is 0: flat lakes) are dropped; 0 = 0.01, < 0 = keep all */
    int max_length;       /* longer polylines are split into near-equal pieces (px); 0 = 48 */
    float dx, dy;         /* pixel spacing used for gradients; 0 = 1 */
    int which;            /* TN_EXTRACT_BOTH / _VALLEYS / _RIDGES */
} tn_extract_opts;

/* Everything extraction computed; free with tn_extraction_free. Masks are w*h bytes (0/1). */
typedef struct tn_extraction {
    int width, height, threshold;
    tn_flow valley_flow, ridge_flow;        /* on the DEM and on the inverted DEM */
    uint8_t *valley_mask, *ridge_mask;      /* accumulation >= threshold, before closing/thinning */
    uint8_t *valley_order, *ridge_order;    /* Strahler order of the raw network cells */
    int valley_max_order, ridge_max_order;
    tn_contour_set contours;                /* final polylines: valleys first, then ridges */
} tn_extraction;

/* Default accumulation threshold for a w x h DEM: max(8, w*h / 1000) cells, i.e. a valley drains
   at least 0.1 % of the map, so the same terrain gives the same network at any resolution. */
TN_API int       tn_extract_default_threshold(int width, int height);
/* Runs the whole pipeline on channel 0 of dem. opts may be NULL. */
TN_API tn_status tn_extract(const tn_image *dem, const tn_extract_opts *opts, tn_extraction *out);
TN_API void      tn_extraction_free(tn_extraction *ex);

/* Realism of a terrain img against a reference (both channel 0, heights in the same units).
   Histogram distances are earth mover's distances between 256-bin histograms over a common
   range, divided by the reference's mean value (slope) or mean |value| (curvature): 0 for the
   same distribution, about 1 when one is a scaled-down copy. */
typedef struct tn_realism_opts {
    float dx_a, dy_a;     /* pixel spacing of the reference in height units; 0 = 1 (dy 0 = dx) */
    float dx_b, dy_b;     /* of the compared terrain; 0 = the reference's */
    int threshold;        /* valley threshold for density and bifurcation; 0 = default per size */
} tn_realism_opts;

typedef struct tn_realism {
    double slope_distance;        /* slope (|gradient|) histograms, relative EMD */
    double curvature_distance;    /* Laplacian histograms, relative EMD */
    double spectrum_distance;     /* RMS difference of log10 radially averaged power spectra */
    double spectrum_slope_a, spectrum_slope_b; /* log-log slope of each spectrum (terrain: about -2..-4) */
    double drainage_density_a, drainage_density_b; /* valley line length per cell (px / px^2) */
    double bifurcation_ratio_a, bifurcation_ratio_b; /* mean Strahler N_k / N_k+1 (0 if order 1 only) */
    double ssim, psnr;            /* NaN when the sizes differ; psnr +inf for identical inputs */
    double distance;              /* summary: mean of the three distances, the relative density and
                                     bifurcation differences and the relative spectral slope difference */
} tn_realism;

/* Spectra use the centred largest power-of-two square crop (Hann window); both sides >= 16. */
TN_API tn_status tn_realism_compare(const tn_image *ref, const tn_image *img, const tn_realism_opts *opts,
                                    tn_realism *out);

/* ============================================================================================
   @@style  terrain style transfer (paper 002, sections 2.2, 3, 4)
   The output map, initialised from the content map, is optimised so that the deep-feature
   statistics of a real heightmap (the style source) appear in it:
       alpha * content + beta * style + gamma * TV   (+ histogram terms with the built-in net).
   The style source is resized to the output size when the output is no larger than it; for a
   larger output it keeps its own pixel size (the output is a larger field of the same
   morphology: each pyramid level matches the source's level of the same pixel size, and the
   automatic pyramid stops where the source's coarsest level would be too small).
   Work runs coarse to fine over an image pyramid (each level x2): the coarse levels lay out
   ridges and valleys, the fine ones add detail; levels larger than `tile` are optimised in
   overlapping tiles, so 2048 x 2048 runs in the memory of a 512 x 512 map.
   Heights: maps are standardised internally; the output is returned in the style source's
   height units (metres when the source has them), with the source's mean and spread.

   Built-in feature network (no weights file): fixed random zero-mean filters (Kaiming normal,
   seeded), reflect padding, ReLU, 2 x 2 average pooling:
       conv 5x5 1->24 | pool | conv 3x3 24->32 | pool | conv 3x3 32->48 | pool | conv 3x3 48->64
   Style = per layer Gram-matrix distance (relative to the source's Gram) plus a sliced
   Wasserstein distance (Heitz et al. 2021: features projected on C fixed random directions,
   sorted, compared with the source's sorted projections); histogram terms match the sorted
   heights and slopes of the source; content = relative squared distance of the third layer.
   Drainage terms (drain_weight, valley_weight; by default on for fluvial sources, i.e. under
   5 % of the source in closed basins deeper than 0.1 % of its height range, off for dunes,
   craters and karst): the depression depths (depression-filled map minus map, @@extract's
   priority flood) are sorted-matched to the source's, so a source without closed basins
   removes them; and every cell's relief (height minus its Gaussian-smoothed surroundings,
   sigma 2 px) is pulled towards the source's mean relief for cells of the same D8 drainage
   area (log2 bins), on all levels but the finest, so valleys are carved where water collects
   and the network connects. The filled map and the drainage bins are recomputed every
   evaluation and held constant in the gradient. Those levels run on a canvas grown by a
   mirrored margin (1/8 of the smaller side) that is cut off afterwards, so the truncated
   drainage at the canvas edge leaves no frame on the map. With the terms on, the automatic
   pyramid goes one level coarser (coarsest side >= 32).

   VGG-19 (tn_vgg19_load): the paper's network. Greyscale is fed as three identical channels in
   [0, 1] with ImageNet normalisation (mean 0.485 0.456 0.406, std 0.229 0.224 0.225), max
   pooling; content conv5_2 (0.5 * sum of squares), style conv1_1 conv2_1 conv3_1 conv4_1
   conv5_1 (sum (G1 - G2)^2 / (4 * 3^2 * (H*W)^2), the published code's normaliser),
   TV sum (dx^2 + dy^2)^1.25; default weights are the published code's (content 2.5e-11,
   style 1e-5, TV 1e-10).
   .tnw tensor names and layout (PyTorch order, float32): conv<g>_<i>.weight  Cout x Cin x 3 x 3
   and conv<g>_<i>.bias  Cout, for the 16 convolutions conv1_1 conv1_2 conv2_1 conv2_2
   conv3_1..conv3_4 conv4_1..conv4_4 conv5_1..conv5_4 (channels 64, 128, 256, 512, 512; conv1_1
   has Cin 3), exactly these 32 tensors. examples/vgg19_to_tnw.py converts a torchvision
   state dict (torchvision.models.vgg19 features.N.weight/bias).
   ============================================================================================ */

typedef enum tn_style_optimizer { TN_STYLE_LBFGS = 0, TN_STYLE_SGD, TN_STYLE_ADAM } tn_style_optimizer;

typedef struct tn_style_opts {
    tn_style_optimizer optimizer; /* L-BFGS (default), SGD with exponential decay, Adam */
    int iters;            /* iterations per pyramid level; 0 = default (L-BFGS 40, Adam 150, SGD 300) */
    int levels;           /* pyramid levels; 0 = auto (coarsest side >= 64, >= 32 with drainage terms; at most 6) */
    int tile;             /* levels wider or taller than this are optimised in tiles; 0 = 512 */
    /* Loss weights; 0 = the network's default, negative = term off. */
    float content_weight; /* alpha */
    float style_weight;   /* beta: Gram term */
    float sw_weight;      /* built-in net: sliced Wasserstein term */
    float hist_weight;    /* built-in net: height and slope histogram terms */
    float drain_weight;   /* built-in net: closed basins (depressions) as deep as the source's; 0 = 10 for fluvial sources, else off */
    float valley_weight;  /* built-in net: valley relief per drainage area as in the source (all but the finest level); 0 = 1 for fluvial sources, else off */
    float tv_weight;      /* gamma */
    float lr;             /* SGD / Adam learning rate; 0 = default (SGD decays x0.96 every iters/20 steps) */
    uint64_t seed;        /* random filters and projections of the built-in net */
    const tn_params *vgg; /* VGG-19 weights from tn_vgg19_load; NULL = the built-in network */
} tn_style_opts;

/* Restyles `content` (any one-channel map, e.g. tn_noise_perlin output; channel 0 is used) with
   the morphology of `style` (a heightmap). *out has the content's size and the style's height
   units. opts may be NULL. Reports progress as stage "style". NaN/Inf in either map fails with
   TN_ERR_NUMERIC; maps smaller than 16 x 16 with TN_ERR_INVALID_ARG. */
TN_API tn_status tn_style_transfer(tn_image *out, const tn_image *content, const tn_image *style, const tn_style_opts *opts);

/* The VGG-19 convolution layout above with zero weights (to fill and save, e.g. for tests). */
TN_API tn_status tn_vgg19_create(tn_params **out);
/* Loads VGG-19 convolution weights from a .tnw file; a wrong tensor name, count or shape fails
   with TN_ERR_SHAPE naming the tensor. Caller frees with tn_params_free. */
TN_API tn_status tn_vgg19_load(tn_params **out, const char *path);

/* How well a map reproduces a source's morphology (paper 002, Table 1, plus two distances).
   Both are normalised to [0, 1]. SSIM compares with the source resized to the map's size; the
   distances are tn_realism_compare's (@@extract) against the source at the pixel scale
   tn_style_transfer matches: resized to the map, or its own size when the map is larger. */
typedef struct tn_style_scores {
    double ssim;            /* SSIM(source, map), Table 1: higher is closer */
    double slope_hist_dist; /* tn_realism slope_distance (relative EMD of slope histograms): lower is closer */
    double spectrum_dist;   /* tn_realism spectrum_distance (RMS log10 spectrum difference): lower is closer */
} tn_style_scores;
TN_API tn_status tn_style_compare(const tn_image *map, const tn_image *source, tn_style_scores *out);

/* A Perlin fBm content map of width x height for `source`: the gain is picked from 0.45, 0.50,
   ..., 0.90 to minimise tn_style_compare's slope-histogram + spectrum distances to the source,
   so the content starts with the source's roughness and the transfer rebuilds its morphology
   (smooth gain-0.5 content against a rough source is what made Table-1 SSIM fall; README).
   opts: seed, octaves, frequency, lacunarity, periodic (its gain is ignored); NULL = defaults.
   *gain_out (may be NULL) gets the gain. Costs ten noise maps and ten comparisons. */
TN_API tn_status tn_style_content_noise(tn_image *out, int width, int height, const tn_image *source,
                                        const tn_perlin_opts *opts, float *gain_out);

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
TN_API tn_status tn_texgan_save(const tn_texgan *model, const char *path);
TN_API tn_status tn_texgan_load(tn_texgan *model, const char *path);

/* Synthesises the w x h window at pixel (x0, y0) of the infinite texture of `seed` (x0, y0 >= 0)
   in one generator pass. *out is allocated here. */
TN_API tn_status tn_texgan_synthesize_window(const tn_texgan *model, uint64_t seed, int x0, int y0, int w, int h,
                                             tn_image *out);
/* Called with consecutive row bands of a tiled synthesis: rows [y0, y0 + band->height). */
typedef tn_status (*tn_band_fn)(void *user, int y0, const tn_image *band);
/* Tiled synthesis of a width x height texture: z split into tiles of tile_cells cells (0 = 32)
   with 4 cells of overlap (2 for nearest models), each tile run alone and cropped; bands of one tile row are handed to
   fn in order. Memory is bounded by one band. Identical to tn_texgan_synthesize_window(0, 0). */
TN_API tn_status tn_texgan_synthesize_stream(const tn_texgan *model, uint64_t seed, int width, int height,
                                             int tile_cells, tn_band_fn fn, void *user);
/* Whole image in memory (tiled internally). */
TN_API tn_status tn_texgan_synthesize(const tn_texgan *model, uint64_t seed, int width, int height, tn_image *out);
/* Streams a synthesis to disk band by band (PFM or 8-bit PPM/PGM by extension; other formats are
   built in memory and saved whole). Channels beyond 3 go to "<stem>.ch3-5<ext>" and so on.
   shift (channels floats, may be NULL) is added before writing (colour correction), results
   clipped to the model's range. Files appear atomically. */
TN_API tn_status tn_texgan_synthesize_file(const tn_texgan *model, uint64_t seed, int width, int height,
                                           const float *shift, const char *path);

/* Colour correction: adds a per-channel shift so that the mean of the result, clipped to
   [lo, hi], equals target_mean (found by bisection, so clipping does not spoil it). In place. */
TN_API tn_status tn_texture_colour_correct(tn_image *img, const float *target_mean, float lo, float hi);
/* The per-channel shift the same correction would apply (for streamed outputs). */
TN_API tn_status tn_texture_colour_shift(const tn_image *img, const float *target_mean, float lo, float hi,
                                         float *shift);

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
TN_API void tn_detail_texel(const tn_detail_maps *maps, float u, float v, float *out);
/* The whole composed texture at width x height (0, 0 = the maps' size). */
TN_API tn_status tn_detail_compose(const tn_detail_maps *maps, int width, int height, tn_image *out);
/* PREFIX_low.png, PREFIX_high.png (8-bit) and PREFIX_detail.txt (size, tiling, factor, sigma,
   range) as a sidecar, since the tiling factor must travel with the maps. */
TN_API tn_status tn_detail_maps_save(const tn_detail_maps *maps, const char *prefix);
TN_API tn_status tn_detail_maps_load(tn_detail_maps *maps, const char *prefix);
/* Side-by-side preview (2 x 2 panels of `panel` pixels, 0 = 384): top far view of the whole
   texture, bottom a near crop at full resolution; left naive tiling of the exemplar, right
   the detail-mapped texture; all shaded by the hillshade of dem (NULL = a Perlin terrain). */
TN_API tn_status tn_detail_preview(const tn_detail_maps *maps, const tn_image *exemplar, const tn_image *dem,
                                   int panel, tn_image *out);

/* ============================================================================================
   @@gnn  sketch-to-terrain graph network (paper 000, sections 4.2-5.4)
   Learns ONE example DEM so that a sketch of ridges and valleys becomes terrain in its style.
   The example's own network (@@extract) is cut into contour parts of 5-10 px (@@sketch); a
   bipartite graph joins every pixel to its k nearest parts (4.2) plus random pixel-part edges
   redrawn every step, with 5 % of the parts masked per step (A.2). An edge carries the
   projection index of the pixel along the part, the distance to that projection (and a
   closeness exp(-d/2)), the part's height there minus the pixel's baseline and, in training,
   optional Gaussian noise (A.4); a part node carries its ridge/valley sign and a learned
   embedding (one per example part). Pixels start from an MLP of (+1 ridge, -1 valley, 0 other;
   baseline height), parts from N(0, s^2) or zero (A.3). T rounds of gather (pixels -> parts)
   and scatter (parts -> pixels) update both sides residually; each is a graph attention over
   two-layer MLP encodings of [receiver, sender, edge, mean of the sender's neighbours] (A.5); a
   readout MLP gives the height. Losses: MSE + SSIM + gradient difference on the normalised
   heights (6.1's l_gt, l_ssim, l_gradient; weights in tn_gnn_defaults).
   Baseline: the network predicts a RESIDUAL over the membrane (Laplace) interpolation of the
   sketch pixels' heights, the strong baseline the neighbour test rewards (issue 14: SSIM 0.937
   on alps_montblanc 128), so the model starts at it and learns what the example adds;
   `membrane = -1` trains the paper's direct form instead.
   Generalising from one example: embeddings let the network memorise the example (the
   reconstruction), but a part of another terrain given an aligned part's embedding (5.3) gets
   that part's memorised residual, which measured worse than none. So training drops half the
   embeddings per step and spends half the steps on the example's own sparser networks (higher
   extraction thresholds, no embeddings, a random share of their parts dropped and the membrane
   rebuilt each step): the network also learns a geometry-only mode that fills what a dense or
   sparse sketch leaves out. Generation gives a sketch part the embedding
   of an identical example part (its own network: reconstruction) and none otherwise by default;
   the paper's alignment is TN_GNN_EMBED_ALIGNED. An optional fine-tune (5.4) then adjusts only
   the sketch parts' embeddings (loss on the sketch pixels + smoothness). Output in the
   example's height units.
   ============================================================================================ */

/* Zero = default (tn_gnn_defaults gives the values and the reasons). */
typedef struct tn_gnn_opts {
    int hidden;            /* node state and MLP hidden width; 0 = 32 (A.5) */
    int rounds;            /* T gather/scatter rounds; 0 = 2 */
    int k;                 /* fixed edges per pixel (its k nearest parts); 0 = 10 (4.2) */
    int embed;             /* part embedding dims; 0 = 16 */
    int random_edges;      /* random pixel-part edges per step; 0 = 10000 (4.2), < 0 = none */
    float mask;            /* share of parts masked per step; 0 = 0.05 (A.2), < 0 = none */
    float edge_noise;      /* std of the Gaussian edge feature in training (A.4 uses 1); 0 = none */
    float part_noise;      /* std of the parts' random initial states (A.3 uses 1); 0 = zero states */
    float embed_drop;      /* share of the example's parts trained without their embedding per
                              step (what a part of another sketch gets); 0 = 0.5, < 0 = none */
    int sparse_levels;     /* also train on the example's networks at 4, 12 and 36 times the
                              extraction threshold (sparse sketches, no embeddings), half the
                              steps; 0 = 3, < 0 = none */
    float thin;            /* on a sparse level, drop up to this share of its parts per step
                              (a random share, membrane and edges rebuilt): many sparse sketches
                              from one example; 0 = 0.5, < 0 = none */
    int membrane;          /* 0 = predict a residual over the membrane of the sketch heights;
                              -1 = predict the height itself (the paper's form) */
    float lr;              /* Adam rate; 0 = 2e-3 */
    float mse_weight;      /* l_gt (MSE of the normalised heights); 0 = 1, < 0 = off */
    float ssim_weight;     /* 1 - SSIM; 0 = 0.1, < 0 = off */
    float grad_weight;     /* gradient-difference loss; 0 = 0.1, < 0 = off */
    tn_extract_opts extract; /* how the example's ridges and valleys are found (zero = defaults) */
    tn_train_opts train;   /* budget (minutes 0 = 10), checkpoints, resume (the checkpoint's
                              architecture wins; the example must be the same), seed */
} tn_gnn_opts;

/* A trained model: the network, the example's contour parts (with heights, so generation needs
   nothing else) and the example's height normalisation. Free with tn_gnn_free. */
typedef struct tn_gnn {
    int hidden, rounds, k, embed;
    int membrane;            /* 1: output = membrane of the sketch heights + learned residual */
    int parts;               /* example parts (one embedding each) */
    int width, height;       /* example size */
    float mean, std;         /* example heights = mean + std * network units */
    float lo, hi;            /* example height range */
    float part_noise;        /* std of the parts' initial states */
    long iterations;         /* training iterations done */
    double train_seconds;
    tn_params *weights;      /* "gnn.config", "gnn.part_pts", "gnn.part_info", "gnn.emb", "gnn.*" */
} tn_gnn;

typedef struct tn_gnn_stats {
    long iterations;          /* total, including resumed ones */
    long resumed_from;        /* iteration the run resumed at (0 = fresh) */
    double seconds;           /* total training seconds, including resumed time */
    double seconds_per_iter;  /* this run's average */
    float loss, loss_mse, loss_ssim, loss_grad; /* averages over the last 50 iterations (unweighted terms) */
    int parts, edges;         /* example parts; fixed edges of the example graph */
    int levels;               /* sketch densities trained on (1 + sparse levels found) */
    int checkpoints;          /* checkpoints written by this run */
} tn_gnn_stats;

/* Sketch height units at generation. */
enum { TN_GNN_HEIGHTS_AUTO = 0,   /* UNIT if every sketch height lies in [0, 1] and the example's
                                     range does not, else EXAMPLE */
       TN_GNN_HEIGHTS_EXAMPLE,    /* the example's units (an extracted network of a similar DEM) */
       TN_GNN_HEIGHTS_UNIT };     /* [0, 1] mapped linearly to the example's lo..hi (drawn sketches) */

/* Which sketch parts take an example part's embedding at generation. */
enum { TN_GNN_EMBED_AUTO = 0,     /* a part identical to an example part (same pixels and heights,
                                     e.g. the example's own network) takes its embedding, every
                                     other part none: the network's geometry-only mode, trained by
                                     embedding dropout and the sparse levels */
       TN_GNN_EMBED_ALIGNED,      /* every part takes its aligned example part's (paper 5.3) */
       TN_GNN_EMBED_NONE };       /* no part does */

typedef struct tn_gnn_generate_opts {
    uint64_t seed;           /* part cutting, alignment pick, parts' initial states */
    int heights;             /* TN_GNN_HEIGHTS_* */
    int embeddings;          /* TN_GNN_EMBED_* */
    int align_choices;       /* EMBED_ALIGNED: pick at random among the best this many aligned
                                example parts; 0 = 1 (the best), the paper uses 5 (variety) */
    int finetune;            /* embedding fine-tune steps (5.4); 0 = none */
    float finetune_lr;       /* Adam rate of the fine-tune; 0 = 1e-2 */
    float smooth_weight;     /* fine-tune smoothness weight; 0 = 0.1, < 0 = off */
} tn_gnn_generate_opts;

/* Fills *o with the defaults (what zero fields mean). */
TN_API void tn_gnn_defaults(tn_gnn_opts *o);
/* Trains on channel 0 of dem (at least 16 x 16, finite). Reports progress as "gnn-train".
   *model is allocated here (free with tn_gnn_free); stats may be NULL. A DEM without any
   extracted contour or contour part fails with TN_ERR_EMPTY. */
TN_API tn_status tn_gnn_train(const tn_image *dem, const tn_gnn_opts *opts, tn_gnn *model, tn_gnn_stats *stats);
TN_API void tn_gnn_free(tn_gnn *model);
/* .tnw model files stamped with method "gnn"; load refuses other methods' files and
   checkpoints with TN_ERR_FORMAT, and damaged configurations with TN_ERR_CORRUPT. */
TN_API tn_status tn_gnn_save(const tn_gnn *model, const char *path);
TN_API tn_status tn_gnn_load(tn_gnn *model, const char *path);
/* The example's contour parts as the model stores them (example units). *out allocated here. */
TN_API tn_status tn_gnn_parts(const tn_gnn *model, tn_contour_set *out);

/* Terrain of width x height following `sketch` (polylines; coordinates scale from its canvas),
   in the example's height units. *out (one channel) is allocated here. opts may be NULL.
   Same inputs and seed, same output, for any thread count. An empty sketch or one without a
   part of 5 px fails with TN_ERR_EMPTY, NaN/Inf points with TN_ERR_NUMERIC. */
TN_API tn_status tn_gnn_generate(const tn_gnn *model, const tn_contour_set *sketch, int width, int height,
                                 const tn_gnn_generate_opts *opts, tn_image *out);

/* The membrane baseline: heights fixed on the sketch's rasterised ridge and valley pixels
   (tn_sketch_rasterise), the discrete Laplace equation elsewhere (4 neighbours, no flux across
   the border), in the sketch's height units. *out (one channel) allocated here. */
TN_API tn_status tn_gnn_membrane(const tn_contour_set *sketch, int width, int height, tn_image *out);

/* ============================================================================================
   @@render  previews: hillshaded colour map and 3D perspective view
   ============================================================================================ */

typedef struct tn_render_opts {
    float lo, hi;              /* height range for the colour ramp; lo == hi: the DEM's own range */
    tn_hillshade_opts shade;   /* light and spacing (zero = defaults) */
    float shade_strength;      /* 0..1 how much the hillshade darkens the colours; 0 = default 0.7; else TN_ERR_INVALID_ARG */
} tn_render_opts;

/* Hillshaded, colour-ramped RGB preview in [0, 1], same size as the DEM (channel 0 is used).
   opts may be NULL. Caller frees *out. */
TN_API tn_status tn_render_preview(const tn_image *dem, const tn_render_opts *opts, tn_image *out);

typedef struct tn_view_opts {
    int width, height;         /* output size; 0 = 960 x 540 */
    float azimuth_deg;         /* camera direction, clockwise from north, looking at the centre; 0 = from the south (180) */
    float pitch_deg;           /* downward look angle; 0 = default 30 */
    float distance;            /* camera distance in DEM widths from the centre; 0 = default 1.1 */
    float fov_deg;             /* horizontal field of view; 0 = default 60 */
    float relief;              /* height of the full DEM range as a fraction of the DEM width; 0 = 0.2 */
    tn_render_opts colours;    /* colouring of the surface */
} tn_view_opts;

/* 3D perspective view of the DEM (ray-marched height field, front-to-back with a per-column
   occlusion buffer, distance haze, sky). RGB in [0, 1]. opts may be NULL. Caller frees *out. */
TN_API tn_status tn_render_view(const tn_image *dem, const tn_view_opts *opts, tn_image *out);

/* ============================================================================================
   @@export  heightfields for engines and 3D tools: glTF 2.0 binary (.glb) and OBJ meshes,
   normal maps, Unity terrain RAW
   A regular grid mesh of the DEM in metres: x east = column * dx, y up = height * z_scale,
   z south = row * dy (glTF is y-up and right-handed), two triangles per cell wound
   counter-clockwise seen from above, smooth normals from central differences of the mesh,
   UV (0, 0) at the north-west corner. step > 1 keeps every step-th sample, and always the last
   row and column, so the mesh covers the whole DEM.
   ============================================================================================ */

typedef struct tn_mesh_opts {
    float dx, dy;              /* pixel spacing in metres; <= 0 = 1 (dy <= 0: = dx) */
    float z_scale;             /* height exaggeration; 0 = 1 */
    int step;                  /* grid decimation 1..65536; 0 = 1 */
    const tn_image *texture;   /* optional colour image (1, 3 or 4 channels, values in [0, 1]) draped
                                  over the whole mesh: embedded as PNG in a .glb; written beside an
                                  .obj as <stem>.png with <stem>.mtl */
} tn_mesh_opts;

/* Writes the mesh atomically. Channel 0 of dem is the height. NaN/Inf heights or texture values
   fail with TN_ERR_NUMERIC, a DEM under 2 x 2 with TN_ERR_EMPTY, meshes over 2^32 vertices or
   TN_MAX_ALLOC bytes with TN_ERR_TOO_LARGE. opts may be NULL. */
TN_API tn_status tn_export_glb(const tn_image *dem, const char *path, const tn_mesh_opts *opts);
TN_API tn_status tn_export_obj(const tn_image *dem, const char *path, const tn_mesh_opts *opts);

/* Normal map of the DEM as RGB in [0, 1] (n / 2 + 0.5, n from tn_image_normals): red = x east,
   blue = z up, green = y north with directx 0 (OpenGL, "Y+") or y south with directx 1
   (DirectX, "Y-"). Save it as an 8-bit PNG for an engine. */
TN_API tn_status tn_normal_map(const tn_image *dem, float dx, float dy, float z_scale, int directx, tn_image *out);
/* Unity terrain RAW: size x size 16-bit little-endian codes, size = 2^n + 1 (33..4097; 0 = the
   smallest not below the DEM's larger side), the DEM resampled bicubic to it when its size
   differs; codes 0..65535 span the DEM's range, returned in *lo and *hi (may be NULL) for the
   terrain's height setting. Written atomically. */
TN_API tn_status tn_export_unity_raw(const tn_image *dem, const char *path, int size, float *lo, float *hi);

#ifdef __cplusplus
}
#endif
#endif /* TERRAINNET_H */

/* //// end header file ////////////////////////////////////////////////////////////////////// */

#ifdef TERRAINNET_IMPLEMENTATION
#ifndef TERRAINNET_IMPLEMENTATION_DONE
#define TERRAINNET_IMPLEMENTATION_DONE

#include <stdlib.h>
#include <stdio.h>
#include <string.h>
#include <math.h>
#include <stdarg.h>
#include <limits.h>
#include <float.h>
#include <time.h>

#if defined(TN_MALLOC) && defined(TN_FREE) && defined(TN_REALLOC)
/* all three given */
#elif !defined(TN_MALLOC) && !defined(TN_FREE) && !defined(TN_REALLOC)
#define TN_MALLOC(sz) malloc(sz)
#define TN_REALLOC(p, sz) realloc(p, sz)
#define TN_FREE(p) free(p)
#else
#error "terrainnet: define all of TN_MALLOC, TN_REALLOC and TN_FREE, or none of them"
#endif

#ifndef TN_ASSERT
#include <assert.h>
#define TN_ASSERT(x) assert(x)
#endif

#ifndef TN_MAX_ALLOC
#define TN_MAX_ALLOC ((size_t)8 << 30)
#endif

#if !defined(TN_NO_THREADS)
#include <pthread.h>
#include <unistd.h>
#endif

/* SIMD kernels (blur, SSIM, GEMM) when the compiler targets AVX-512 or AVX2+FMA; portable C otherwise. */
#if defined(__AVX512F__) || (defined(__AVX2__) && defined(__FMA__))
#include <immintrin.h>
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* --------------------------------------------------------------------------------------------
   >>core  (@@core implementation)
   -------------------------------------------------------------------------------------------- */

/* Error detail, one per thread, so pool workers and the caller's other threads never overwrite
   each other's message. `fails` counts the failures recorded on this thread; the pool compares it
   around a task to see whether a worker failed (>>thread forwards that message to the caller).
   Thread-local storage where the compiler has it (C++11, C11, MSVC, gcc/clang's __thread, which
   -std=c99 -pedantic accepts); otherwise, or with TN_NO_TLS, a pthread key; without threads a
   plain static. */
typedef struct tn__error_state { char msg[1024]; unsigned long fails; } tn__error_state;

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

#if defined(TN_NO_THREADS)
static tn__error_state tn__error_static;
static tn__error_state *tn__err(void) { return &tn__error_static; }
#elif defined(TN__TLS)
static TN__TLS tn__error_state tn__error_tls;
static tn__error_state *tn__err(void) { return &tn__error_tls; }
#else
/* pthread key: each thread's state is allocated on its first use and freed when it exits;
   if that allocation fails the thread falls back to one shared state. */
static pthread_key_t tn__error_key;
static pthread_once_t tn__error_once = PTHREAD_ONCE_INIT;
static int tn__error_key_ok;
static tn__error_state tn__error_shared;
static void tn__error_state_free(void *e) { TN_FREE(e); }
static void tn__error_key_create(void) { tn__error_key_ok = pthread_key_create(&tn__error_key, tn__error_state_free) == 0; }
static tn__error_state *tn__err(void)
{
    tn__error_state *e;
    pthread_once(&tn__error_once, tn__error_key_create);
    if (!tn__error_key_ok) return &tn__error_shared;
    e = (tn__error_state *)pthread_getspecific(tn__error_key);
    if (!e && (e = (tn__error_state *)TN_MALLOC(sizeof *e)) != NULL) {
        memset(e, 0, sizeof *e);
        if (pthread_setspecific(tn__error_key, e) != 0) {
            TN_FREE(e);
            e = NULL;
        }
    }
    return e ? e : &tn__error_shared;
}
#endif

TN_API const char *tn_status_string(tn_status s)
{
    static const char *const names[TN_STATUS_COUNT] = {
        "ok", "invalid argument", "out of memory", "too large", "i/o error",
        "unknown or unsupported format", "corrupt data", "numeric error (NaN/Inf or divergence)",
        "shape mismatch", "empty input", "cancelled"};
    if ((int)s < 0 || (int)s >= TN_STATUS_COUNT) return "unknown status";
    return names[s];
}

TN_API const char *tn_last_error(void) { return tn__err()->msg; }
TN_API void tn_clear_error(void) { tn__err()->msg[0] = 0; }

/* Records a failure message (printf-style) and returns the status, so callers can write
   `return tn__fail(TN_ERR_IO, "%s: cannot open", path);`. */
static tn_status tn__fail(tn_status s, const char *fmt, ...)
{
    tn__error_state *e = tn__err();
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(e->msg, sizeof e->msg, fmt, ap);
    va_end(ap);
    e->fails++;
    return s;
}

/* Prefixes the current message with a context string ("alps.png: " ...), keeping the status. */
static tn_status tn__fail_context(tn_status s, const char *context)
{
    char *msg = tn__err()->msg;
    const size_t cap = sizeof tn__err()->msg;
    size_t lc, lm;
    if (!context || !context[0]) return s;
    lc = strlen(context);
    lm = strlen(msg);
    if (lc + 3 >= cap) return s;
    if (lc + 2 + lm >= cap) lm = cap - lc - 3;
    memmove(msg + lc + 2, msg, lm);
    msg[lc + 2 + lm] = 0;
    memcpy(msg, context, lc);
    msg[lc] = ':';
    msg[lc + 1] = ' ';
    return s;
}

/* a * b with overflow check; returns 0 on overflow. */
static int tn__mul_size(size_t a, size_t b, size_t *out)
{
    if (a != 0 && b > SIZE_MAX / a) return 0;
    *out = a * b;
    return 1;
}

/* a * b * c * d bytes, checked against overflow and TN_MAX_ALLOC. */
static tn_status tn__size4(size_t a, size_t b, size_t c, size_t d, size_t *out)
{
    size_t t;
    if (!tn__mul_size(a, b, &t) || !tn__mul_size(t, c, &t) || !tn__mul_size(t, d, &t) || t > TN_MAX_ALLOC)
        return tn__fail(TN_ERR_TOO_LARGE, "size %zu x %zu x %zu x %zu exceeds the allocation limit", a, b, c, d);
    *out = t;
    return TN_OK;
}

/* Allocation that records an error message on failure. */
static void *tn__alloc(size_t bytes)
{
    void *p;
    if (bytes > TN_MAX_ALLOC) {
        tn__fail(TN_ERR_TOO_LARGE, "allocation of %zu bytes exceeds the limit", bytes);
        return NULL;
    }
    p = TN_MALLOC(bytes ? bytes : 1);
    if (!p) tn__fail(TN_ERR_OUT_OF_MEMORY, "out of memory allocating %zu bytes", bytes);
    return p;
}

static void *tn__calloc(size_t bytes)
{
    void *p = tn__alloc(bytes);
    if (p) memset(p, 0, bytes ? bytes : 1);
    return p;
}

/* Grows *buf (capacity *cap bytes) to hold at least `need` bytes, doubling. */
static tn_status tn__reserve(void **buf, size_t *cap, size_t need)
{
    size_t ncap;
    void *p;
    if (need <= *cap) return TN_OK;
    if (need > TN_MAX_ALLOC) return tn__fail(TN_ERR_TOO_LARGE, "buffer of %zu bytes exceeds the limit", need);
    ncap = *cap ? *cap : 256;
    while (ncap < need) ncap = ncap > TN_MAX_ALLOC / 2 ? TN_MAX_ALLOC : ncap * 2;
    p = TN_REALLOC(*buf, ncap);
    if (!p) return tn__fail(TN_ERR_OUT_OF_MEMORY, "out of memory growing a buffer to %zu bytes", ncap);
    *buf = p;
    *cap = ncap;
    return TN_OK;
}

TN_API void tn_rng_seed(tn_rng *r, uint64_t seed, uint64_t stream)
{
    r->state = 0;
    r->inc = (stream << 1) | 1u;
    (void)tn_rng_u32(r);
    r->state += seed;
    (void)tn_rng_u32(r);
}

TN_API uint32_t tn_rng_u32(tn_rng *r)
{
    uint64_t old = r->state;
    uint32_t xorshifted, rot;
    r->state = old * 6364136223846793005ULL + r->inc;
    xorshifted = (uint32_t)(((old >> 18) ^ old) >> 27);
    rot = (uint32_t)(old >> 59);
    return (xorshifted >> rot) | (xorshifted << ((32u - rot) & 31u));
}

TN_API uint32_t tn_rng_below(tn_rng *r, uint32_t n)
{
    uint32_t threshold, x;
    TN_ASSERT(n > 0);
    threshold = (uint32_t)(0u - n) % n; /* rejection keeps it unbiased */
    do x = tn_rng_u32(r); while (x < threshold);
    return x % n;
}

TN_API float tn_rng_uniform(tn_rng *r) { return (float)(tn_rng_u32(r) >> 8) * (1.0f / 16777216.0f); }

TN_API float tn_rng_normal(tn_rng *r)
{
    double u1 = ((double)(tn_rng_u32(r) >> 8) + 0.5) / 16777216.0;
    double u2 = (double)(tn_rng_u32(r) >> 8) / 16777216.0;
    return (float)(sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2));
}

static tn_progress_fn tn__progress_fn;
static void *tn__progress_user;

TN_API void tn_set_progress(tn_progress_fn fn, void *user)
{
    tn__progress_fn = fn;
    tn__progress_user = user;
}

/* Reports progress; returns TN_ERR_CANCELLED (with a message) if the hook asks to stop. */
static tn_status tn__progress(const char *stage, double fraction)
{
    if (tn__progress_fn && tn__progress_fn(tn__progress_user, stage, fraction))
        return tn__fail(TN_ERR_CANCELLED, "%s: cancelled by the progress callback", stage);
    return TN_OK;
}

TN_API double tn_time_seconds(void)
{
#if defined(CLOCK_MONOTONIC) && !defined(_WIN32)
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
#else
    return (double)clock() / (double)CLOCKS_PER_SEC;
#endif
}

static float tn__clampf(float v, float lo, float hi) { return v < lo ? lo : (v > hi ? hi : v); }
static int tn__clampi(int v, int lo, int hi) { return v < lo ? lo : (v > hi ? hi : v); }

/* --------------------------------------------------------------------------------------------
   >>thread  (@@thread implementation)
   A persistent pool: workers sleep on a condition variable, the caller publishes a task and a
   generation number, every worker runs its share `ith` and the caller waits for the count.
   -------------------------------------------------------------------------------------------- */

#define TN__MAX_THREADS 64

static int tn__threads_wanted = 0; /* 0 = not yet decided */

#if !defined(TN_NO_THREADS)
static int tn__online_cpus(void)
{
#if !defined(TN_NO_THREADS) && defined(_SC_NPROCESSORS_ONLN)
    long n = sysconf(_SC_NPROCESSORS_ONLN);
    if (n < 1) n = 1;
    if (n > TN__MAX_THREADS) n = TN__MAX_THREADS;
    return (int)n;
#else
    return 1;
#endif
}
#endif

TN_API void tn_set_threads(int n)
{
#ifdef TN_NO_THREADS
    (void)n;
    tn__threads_wanted = 1;
#else
    if (n <= 0) n = tn__online_cpus();
    if (n > TN__MAX_THREADS) n = TN__MAX_THREADS;
    tn__threads_wanted = n;
#endif
}

TN_API int tn_get_threads(void)
{
    if (!tn__threads_wanted) tn_set_threads(0);
    return tn__threads_wanted;
}

/* Workers and the caller first spin on the generation / pending counters (~50 us) and only then
   sleep on the condition variables, so back-to-back parallel regions (a network's layers) never
   enter the kernel while an idle program still sleeps. No lost wake-ups: workers sleep under the
   mutex; the caller sets caller_sleeping before its last check of `pending`, and the last worker
   decrements `pending` before it reads caller_sleeping, so one of the two sees the other. */
#ifndef TN_NO_THREADS

#if defined(__GNUC__) || defined(__clang__)
#define TN__LOAD(p) __atomic_load_n(p, __ATOMIC_SEQ_CST)
#define TN__STORE(p, v) __atomic_store_n(p, v, __ATOMIC_SEQ_CST)
#define TN__DEC(p) __atomic_sub_fetch(p, 1, __ATOMIC_SEQ_CST)
#ifndef TN_POOL_SPIN
#define TN_POOL_SPIN 2000 /* x PAUSE (~25 ns on Zen 4) = ~50 us */
#endif
#if defined(__x86_64__) || defined(__i386__)
#define TN__PAUSE() __builtin_ia32_pause()
#elif defined(__aarch64__)
#define TN__PAUSE() __asm__ __volatile__("yield")
#else
#define TN__PAUSE() ((void)0)
#endif
#else /* no atomics: plain accesses, only ever made under the mutex */
#define TN__LOAD(p) (*(p))
#define TN__STORE(p, v) (*(p) = (v))
#define TN__DEC(p) (--*(p))
#define TN__PAUSE() ((void)0)
#undef TN_POOL_SPIN
#define TN_POOL_SPIN 0
#endif

typedef struct tn__pool {
    pthread_mutex_t mu;
    pthread_cond_t wake, done;
    pthread_t tid[TN__MAX_THREADS];
    int started;          /* worker threads created (excluding the caller) */
    unsigned long gen;    /* +2 per published task; odd while fn/ctx/nth are being written (atomic) */
    tn_task_fn fn;        /* the task: written under mu while gen is odd (atomic) */
    void *ctx;
    int nth;              /* threads taking part in the current task */
    int pending;          /* workers still running the current task (atomic) */
    int sleeping_workers; /* workers blocked on `wake` (changed under mu) */
    int caller_sleeping;  /* the caller is blocked on `done` (atomic) */
    int busy;             /* a parallel region is active: nested calls run inline */
} tn__pool;

static tn__pool tn__the_pool = {PTHREAD_MUTEX_INITIALIZER, PTHREAD_COND_INITIALIZER,
                                PTHREAD_COND_INITIALIZER, {0}, 0, 0, 0, 0, 0, 0, 0, 0, 0};

typedef struct tn__worker_arg { int ith; unsigned long gen0; } tn__worker_arg;
static tn__worker_arg tn__worker_args[TN__MAX_THREADS];

/* The error detail of a worker that failed during the current task (the lowest-numbered one,
   so the choice does not depend on timing), for the caller to take over: the detail is per
   thread, and the caller returns the status. Both under tn__the_pool.mu; ith 0 = none. */
static int tn__pool_error_ith;
static char tn__pool_error_msg[sizeof tn__err()->msg];

static void tn__pool_keep_error(tn__pool *p, int ith)
{
    pthread_mutex_lock(&p->mu);
    if (!tn__pool_error_ith || ith < tn__pool_error_ith) {
        tn__pool_error_ith = ith;
        memcpy(tn__pool_error_msg, tn__err()->msg, sizeof tn__pool_error_msg);
    }
    pthread_mutex_unlock(&p->mu);
}

typedef struct tn__pool_task { unsigned long gen; tn_task_fn fn; void *ctx; int nth; } tn__pool_task;

/* Waits for a task newer than generation `seen` and returns a consistent copy of it: spin first
   (seqlock-style read: the copy counts only if gen was even and unchanged around it), then sleep
   on `wake`, where the mutex makes the copy consistent. A worker that takes no part in a task may
   miss it entirely; that is fine, nobody waits for it. */
static tn__pool_task tn__pool_wait_task(tn__pool *p, unsigned long seen)
{
    tn__pool_task t;
    long spin;
    for (spin = 0; spin < TN_POOL_SPIN; spin++) {
        t.gen = TN__LOAD(&p->gen);
        if (t.gen != seen && !(t.gen & 1)) {
            t.fn = TN__LOAD(&p->fn);
            t.ctx = TN__LOAD(&p->ctx);
            t.nth = TN__LOAD(&p->nth);
            if (TN__LOAD(&p->gen) == t.gen) return t;
        }
        TN__PAUSE();
    }
    pthread_mutex_lock(&p->mu);
    p->sleeping_workers++;
    while (TN__LOAD(&p->gen) == seen) pthread_cond_wait(&p->wake, &p->mu);
    p->sleeping_workers--;
    t.gen = p->gen;
    t.fn = p->fn;
    t.ctx = p->ctx;
    t.nth = p->nth;
    pthread_mutex_unlock(&p->mu);
    return t;
}

/* A participant finished: the last one wakes the caller if it went to sleep. */
static void tn__pool_task_done(tn__pool *p)
{
#if TN_POOL_SPIN
    if (TN__DEC(&p->pending) == 0 && TN__LOAD(&p->caller_sleeping)) {
        pthread_mutex_lock(&p->mu);
        pthread_cond_signal(&p->done);
        pthread_mutex_unlock(&p->mu);
    }
#else
    pthread_mutex_lock(&p->mu);
    if (--p->pending == 0) pthread_cond_signal(&p->done);
    pthread_mutex_unlock(&p->mu);
#endif
}

static void *tn__worker_main(void *arg)
{
    tn__pool *p = &tn__the_pool;
    int ith = ((tn__worker_arg *)arg)->ith;
    unsigned long seen = ((tn__worker_arg *)arg)->gen0; /* the generation current at creation */
    for (;;) {
        tn__pool_task t = tn__pool_wait_task(p, seen);
        seen = t.gen;
        if (ith < t.nth) {
            unsigned long fails = tn__err()->fails;
            t.fn(t.ctx, ith, t.nth);
            if (tn__err()->fails != fails) tn__pool_keep_error(p, ith);
            tn__pool_task_done(p);
        }
    }
    return NULL;
}
#endif

TN_API void tn_parallel_run(tn_task_fn fn, void *ctx)
{
#ifdef TN_NO_THREADS
    fn(ctx, 0, 1);
#else
    tn__pool *p = &tn__the_pool;
    int nth = tn_get_threads();
    unsigned long fails;
    long spin;
    pthread_mutex_lock(&p->mu);
    if (p->busy || nth <= 1) {
        pthread_mutex_unlock(&p->mu);
        fn(ctx, 0, 1);
        return;
    }
    while (p->started < nth - 1) {
        int ith = p->started + 1;
        tn__worker_args[ith].ith = ith;
        tn__worker_args[ith].gen0 = p->gen;
        if (pthread_create(&p->tid[ith], NULL, tn__worker_main, &tn__worker_args[ith]) != 0) break;
        pthread_detach(p->tid[ith]);
        p->started++;
    }
    if (nth > p->started + 1) nth = p->started + 1; /* thread creation failed: use what we have */
    if (nth <= 1) {
        pthread_mutex_unlock(&p->mu);
        fn(ctx, 0, 1);
        return;
    }
    p->busy = 1;
    tn__pool_error_ith = 0;
    TN__STORE(&p->pending, nth - 1);
    TN__STORE(&p->gen, p->gen + 1); /* odd: spinning workers ignore the half-written task */
    TN__STORE(&p->fn, fn);
    TN__STORE(&p->ctx, ctx);
    TN__STORE(&p->nth, nth);
    TN__STORE(&p->gen, p->gen + 1); /* even again: published */
    if (p->sleeping_workers > 0) pthread_cond_broadcast(&p->wake);
    pthread_mutex_unlock(&p->mu);
    fails = tn__err()->fails;
    fn(ctx, 0, nth);
    for (spin = 0; spin < TN_POOL_SPIN && TN__LOAD(&p->pending) > 0; spin++) TN__PAUSE();
    pthread_mutex_lock(&p->mu);
    if (TN__LOAD(&p->pending) > 0) {
        TN__STORE(&p->caller_sleeping, 1); /* pairs with the last worker's decrement-then-check */
        while (TN__LOAD(&p->pending) > 0) pthread_cond_wait(&p->done, &p->mu);
        TN__STORE(&p->caller_sleeping, 0);
    }
    if (tn__pool_error_ith && tn__err()->fails == fails) { /* a worker failed, the caller did not */
        memcpy(tn__err()->msg, tn__pool_error_msg, sizeof tn__pool_error_msg);
        tn__err()->fails++;
    }
    p->busy = 0;
    pthread_mutex_unlock(&p->mu);
#endif
}

typedef struct tn__range_job {
    size_t n, grain;
    tn_range_fn fn;
    void *ctx;
} tn__range_job;

static void tn__range_task(void *arg, int ith, int nth)
{
    tn__range_job *j = (tn__range_job *)arg;
    size_t chunk = (j->n + (size_t)nth - 1) / (size_t)nth;
    size_t b = (size_t)ith * chunk, e = b + chunk;
    if (e > j->n) e = j->n;
    if (b < e) j->fn(j->ctx, b, e);
}

TN_API void tn_parallel_for(size_t n, size_t grain, tn_range_fn fn, void *ctx)
{
    tn__range_job job;
    if (n == 0) return;
    if (grain < 1) grain = 1;
    if (n < 2 * grain || tn_get_threads() <= 1) {
        fn(ctx, 0, n);
        return;
    }
    job.n = n;
    job.grain = grain;
    job.fn = fn;
    job.ctx = ctx;
    tn_parallel_run(tn__range_task, &job);
}

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

TN_API size_t tn_image_range(const tn_image *img, float *lo, float *hi)
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
static int tn__reflect_whole(long long i, int n)
{
    long long p = 2LL * n - 2, m;
    if (n == 1) return 0;
    m = i % p;
    if (m < 0) m += p;
    return (int)(m >= n ? p - m : m);
}

/* ---- crop / pad ---------------------------------------------------------------------------- */

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

TN_API tn_status tn_image_gradient(const tn_image *dem, float dx, float dy, tn_image *gx, tn_image *gy)
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

/* --------------------------------------------------------------------------------------------
   >>png  (part of @@io implementation)
   PNG codec with terrainnet's own zlib, so the library needs nothing but libc.
   - CRC-32 (slicing-by-8, tables built once) and Adler-32 checks.
   - Inflate (RFC 1950/1951): 64-bit bit buffer refilled 8 bytes at a time, two-level Huffman
     tables (10-bit root for literal/length, 8-bit for distances) so a symbol costs one or two
     lookups; the output is a growable buffer capped by max_out (zip bombs -> TN_ERR_TOO_LARGE).
   - Deflate: zlib's LZ77 (3-byte hash chains, greedy at levels 1-3, lazy evaluation at 4-9 with
     zlib's good/lazy/nice/chain table), blocks of 16K symbols written as dynamic Huffman (code
     lengths from Moffat-Katajainen, limited to 15/7 bits with the Kraft-fixing heuristic), fixed
     or stored, whichever is smallest.
   - PNG decode: every colour type/bit depth, Adam7, all filters, tRNS, PLTE; strict checking
     (CRC of every chunk, IHDR, chunk order, IEND, exact pixel data size). IDAT is inflated straight
     into a buffer of the exact raw size, unfiltered in place, then converted to floats.
   - PNG encode: 8/16-bit grey, grey+alpha, RGB, RGBA; per-row filter chosen by the minimum sum of
     absolute differences; the metre range rides in tEXt "terrainnet.range".
   -------------------------------------------------------------------------------------------- */

/* ---- byte helpers ---- */

static uint32_t tn__png_be32(const uint8_t *p)
{
    return ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | (uint32_t)p[3];
}

static void tn__png_put_be32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)(v >> 24);
    p[1] = (uint8_t)(v >> 16);
    p[2] = (uint8_t)(v >> 8);
    p[3] = (uint8_t)v;
}

/* Little-endian 64-bit load from any address (a plain memcpy on little-endian machines). */
static uint64_t tn__z_load64le(const uint8_t *p)
{
#if defined(__BYTE_ORDER__) && defined(__ORDER_LITTLE_ENDIAN__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    uint64_t v;
    memcpy(&v, p, 8);
    return v;
#else
    return (uint64_t)p[0] | ((uint64_t)p[1] << 8) | ((uint64_t)p[2] << 16) | ((uint64_t)p[3] << 24) |
           ((uint64_t)p[4] << 32) | ((uint64_t)p[5] << 40) | ((uint64_t)p[6] << 48) | ((uint64_t)p[7] << 56);
#endif
}

static uint32_t tn__z_load32le(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

/* Index of the lowest set bit of a non-zero x. */
static unsigned tn__z_ctz64(uint64_t x)
{
#if defined(__GNUC__) || defined(__clang__)
    return (unsigned)__builtin_ctzll(x);
#else
    unsigned n = 0;
    while (!(x & 1u)) { x >>= 1; n++; }
    return n;
#endif
}

/* ---- CRC-32 (zlib's polynomial 0xEDB88320), slicing-by-8 ---- */

static uint32_t tn__crc_tab[8][256];

static void tn__crc_build(void)
{
    uint32_t i, j, c;
    for (i = 0; i < 256; i++) {
        c = i;
        for (j = 0; j < 8; j++) c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
        tn__crc_tab[0][i] = c;
    }
    for (i = 0; i < 256; i++) {
        c = tn__crc_tab[0][i];
        for (j = 1; j < 8; j++) {
            c = tn__crc_tab[0][c & 0xffu] ^ (c >> 8);
            tn__crc_tab[j][i] = c;
        }
    }
}

#ifndef TN_NO_THREADS
static pthread_once_t tn__crc_once = PTHREAD_ONCE_INIT;
#else
static int tn__crc_ready;
#endif

/* Standard CRC-32 as zlib's crc32(): start with crc = 0, chain calls over consecutive pieces. */
static uint32_t tn__crc32(uint32_t crc, const uint8_t *p, size_t n)
{
#ifndef TN_NO_THREADS
    pthread_once(&tn__crc_once, tn__crc_build);
#else
    if (!tn__crc_ready) { tn__crc_build(); tn__crc_ready = 1; }
#endif
    crc = ~crc;
    while (n >= 8) {
        uint32_t a = crc ^ tn__z_load32le(p), b = tn__z_load32le(p + 4);
        crc = tn__crc_tab[7][a & 0xffu] ^ tn__crc_tab[6][(a >> 8) & 0xffu] ^ tn__crc_tab[5][(a >> 16) & 0xffu] ^
              tn__crc_tab[4][a >> 24] ^ tn__crc_tab[3][b & 0xffu] ^ tn__crc_tab[2][(b >> 8) & 0xffu] ^
              tn__crc_tab[1][(b >> 16) & 0xffu] ^ tn__crc_tab[0][b >> 24];
        p += 8;
        n -= 8;
    }
    while (n--) crc = tn__crc_tab[0][(crc ^ *p++) & 0xffu] ^ (crc >> 8);
    return ~crc;
}

/* Adler-32 as zlib's adler32(): start with a = 1. Sums are reduced every 5552 bytes, the most
   that cannot overflow 32 bits. */
static uint32_t tn__adler32(uint32_t adler, const uint8_t *p, size_t n)
{
    uint32_t a = adler & 0xffffu, b = adler >> 16;
    while (n) {
        size_t k = n < 5552 ? n : 5552;
        n -= k;
        while (k >= 8) {
            a += p[0]; b += a; a += p[1]; b += a; a += p[2]; b += a; a += p[3]; b += a;
            a += p[4]; b += a; a += p[5]; b += a; a += p[6]; b += a; a += p[7]; b += a;
            p += 8;
            k -= 8;
        }
        while (k--) { a += *p++; b += a; }
        a %= 65521u;
        b %= 65521u;
    }
    return (b << 16) | a;
}

/* ---- deflate tables shared by inflate and deflate ---- */

static const uint16_t tn__z_len_base[29] = {3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31, 35, 43, 51, 59,
                                            67, 83, 99, 115, 131, 163, 195, 227, 258};
static const uint8_t tn__z_len_extra[29] = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3,
                                            4, 4, 4, 4, 5, 5, 5, 5, 0};
static const uint16_t tn__z_dist_base[30] = {1, 2, 3, 4, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129, 193,
                                             257, 385, 513, 769, 1025, 1537, 2049, 3073, 4097, 6145,
                                             8193, 12289, 16385, 24577};
static const uint8_t tn__z_dist_extra[30] = {0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6,
                                             7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13};
/* Order in which code length code lengths are sent. */
static const uint8_t tn__z_clen_order[19] = {16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15};

static unsigned tn__z_reverse(unsigned code, unsigned len)
{
    unsigned r = 0;
    while (len--) { r = (r << 1) | (code & 1u); code >>= 1; }
    return r;
}

/* Lengths of the fixed literal/length (0..287) and distance (288..319) codes. */
static void tn__z_fixed_lengths(uint8_t *lens)
{
    int i;
    for (i = 0; i < 144; i++) lens[i] = 8;
    for (; i < 256; i++) lens[i] = 9;
    for (; i < 280; i++) lens[i] = 7;
    for (; i < 288; i++) lens[i] = 8;
    for (; i < 320; i++) lens[i] = 5;
}

/* ---- inflate ----
   A table entry is (value << 16) | (extra << 8) | (kind << 5) | nbits: nbits = bits the code
   takes at this level; for a SUB entry extra = index bits of the subtable and value its offset. */

#define TN__Z_LIT_ROOT 10
#define TN__Z_DIST_ROOT 8
#define TN__Z_LIT_TABLE ((1 << TN__Z_LIT_ROOT) + 288 * (1 << (15 - TN__Z_LIT_ROOT)))
#define TN__Z_DIST_TABLE ((1 << TN__Z_DIST_ROOT) + 32 * (1 << (15 - TN__Z_DIST_ROOT)))
#define TN__Z_SLACK 16 /* spare output bytes so match copies may run 8 bytes at a time */

enum { TN__ZK_LIT = 0, TN__ZK_LEN = 1, TN__ZK_EOB = 2, TN__ZK_SUB = 3, TN__ZK_BAD = 4 };
#define TN__ZE(kind, extra, value) (((uint32_t)(value) << 16) | ((uint32_t)(extra) << 8) | ((uint32_t)(kind) << 5))

typedef struct tn__inflate {
    const uint8_t *in, *in_end; /* next unread byte, end of input */
    uint64_t bits;              /* bit buffer, LSB first */
    unsigned nbits;             /* valid bits in `bits` */
    unsigned overrun;           /* zero bytes fed past the end of input */
    const char *what;           /* message prefix: "zlib" or "<file>: IDAT" */
    uint8_t *out;               /* output, cap + TN__Z_SLACK bytes allocated */
    size_t len, cap, max;
    uint32_t lit_payload[288], dist_payload[32], clen_payload[19];
    uint32_t lit[TN__Z_LIT_TABLE];
    uint32_t dist[TN__Z_DIST_TABLE];
    uint32_t clen[1 << 7];
} tn__inflate;

static void tn__z_init_payloads(tn__inflate *s)
{
    int i;
    for (i = 0; i < 256; i++) s->lit_payload[i] = TN__ZE(TN__ZK_LIT, 0, i);
    s->lit_payload[256] = TN__ZE(TN__ZK_EOB, 0, 0);
    for (i = 0; i < 29; i++) s->lit_payload[257 + i] = TN__ZE(TN__ZK_LEN, tn__z_len_extra[i], tn__z_len_base[i]);
    s->lit_payload[286] = s->lit_payload[287] = TN__ZE(TN__ZK_BAD, 0, 0);
    for (i = 0; i < 30; i++) s->dist_payload[i] = TN__ZE(TN__ZK_LEN, tn__z_dist_extra[i], tn__z_dist_base[i]);
    s->dist_payload[30] = s->dist_payload[31] = TN__ZE(TN__ZK_BAD, 0, 0);
    for (i = 0; i < 19; i++) s->clen_payload[i] = TN__ZE(TN__ZK_LIT, 0, i);
}

/* Builds a two-level decoding table from canonical code lengths (0 = unused symbol). Returns 0,
   or -1 for an over-subscribed code or an incomplete one (zlib's rule: a lone 1-bit code, or no
   code at all, is allowed where `allow_single`). Subtables all have maxlen - root index bits. */
static int tn__z_build(uint32_t *table, unsigned root, const uint8_t *lens, unsigned n, const uint32_t *payload,
                       int allow_single)
{
    unsigned count[16], next[16], offs[16], len, sym, maxlen = 0, i, k, sub_bits = 0;
    uint16_t sorted[320];
    int left = 1;
    uint32_t code, prefix, cur_prefix = 0xffffffffu, sub_base = 0, sub_off = 1u << root;
    memset(count, 0, sizeof count);
    for (sym = 0; sym < n; sym++) count[lens[sym]]++;
    count[0] = 0;
    for (len = 1; len <= 15; len++) {
        left = left * 2 - (int)count[len];
        if (left < 0) return -1;
        if (count[len]) maxlen = len;
    }
    if (left > 0 && !(allow_single && maxlen <= 1)) return -1;
    for (i = 0; i < (1u << root); i++) table[i] = TN__ZE(TN__ZK_BAD, 0, 0);
    offs[1] = 0;
    for (len = 1; len < 15; len++) offs[len + 1] = offs[len] + count[len];
    for (sym = 0; sym < n; sym++)
        if (lens[sym]) sorted[offs[lens[sym]]++] = (uint16_t)sym;
    code = 0;
    next[0] = 0;
    for (len = 1; len <= 15; len++) {
        code = (code + count[len - 1]) << 1;
        next[len] = code;
    }
    for (k = 0, len = 1; len <= 15; len++) {
        for (i = 0; i < count[len]; i++, k++) {
            uint32_t entry;
            sym = sorted[k];
            code = next[len]++;
            entry = payload[sym];
            if (len <= root) {
                unsigned r = tn__z_reverse(code, len);
                for (; r < (1u << root); r += 1u << len) table[r] = entry | len;
            } else {
                unsigned r, sl = len - root;
                prefix = code >> sl;
                if (prefix != cur_prefix) { /* codes sharing a root prefix are consecutive */
                    unsigned j;
                    cur_prefix = prefix;
                    sub_bits = maxlen - root;
                    sub_base = sub_off;
                    sub_off += 1u << sub_bits;
                    for (j = 0; j < (1u << sub_bits); j++) table[sub_base + j] = TN__ZE(TN__ZK_BAD, 0, 0);
                    table[tn__z_reverse(prefix, root)] = TN__ZE(TN__ZK_SUB, sub_bits, sub_base) | root;
                }
                r = tn__z_reverse(code & ((1u << sl) - 1u), sl);
                for (; r < (1u << sub_bits); r += 1u << sl) table[sub_base + r] = entry | sl;
            }
        }
    }
    return 0;
}

/* Fills the bit buffer to at least 56 bits; past the end of input zero bytes are fed and
   counted, so a truncated stream fails at the end (or here, once it is hopeless). */
static int tn__z_refill(tn__inflate *s)
{
    if (s->in_end - s->in >= 8) {
        s->bits |= tn__z_load64le(s->in) << s->nbits;
        s->in += (63 - s->nbits) >> 3;
        s->nbits |= 56;
        return 0;
    }
    while (s->nbits <= 56) {
        if (s->in < s->in_end) s->bits |= (uint64_t)*s->in++ << s->nbits;
        else s->overrun++;
        s->nbits += 8;
    }
    return s->overrun > 16 ? -1 : 0;
}

static uint32_t tn__z_getbits(tn__inflate *s, unsigned n)
{
    uint32_t v = (uint32_t)(s->bits & ((1u << n) - 1u));
    s->bits >>= n;
    s->nbits -= n;
    return v;
}

/* Drops bits to the next byte boundary and hands the whole bytes in the bit buffer back to the
   input, so stored blocks and the trailer can be read bytewise. Returns -1 if past the end. */
static int tn__z_align(tn__inflate *s)
{
    unsigned nbytes;
    s->bits >>= s->nbits & 7u;
    s->nbits -= s->nbits & 7u;
    nbytes = s->nbits >> 3;
    if (s->overrun > nbytes) return -1;
    s->in -= nbytes - s->overrun;
    s->bits = 0;
    s->nbits = 0;
    s->overrun = 0;
    return 0;
}

static tn_status tn__z_grow(tn__inflate *s, size_t need)
{
    size_t ncap;
    uint8_t *p;
    if (need > s->max) return tn__fail(TN_ERR_TOO_LARGE, "%s: data inflates beyond the %zu byte limit", s->what, s->max);
    ncap = s->cap ? s->cap : 4096;
    while (ncap < need) ncap = ncap > s->max / 2 ? s->max : ncap * 2;
    if (ncap > s->max) ncap = s->max;
    p = (uint8_t *)TN_REALLOC(s->out, ncap + TN__Z_SLACK);
    if (!p) return tn__fail(TN_ERR_OUT_OF_MEMORY, "%s: out of memory growing the output to %zu bytes", s->what, ncap);
    s->out = p;
    s->cap = ncap;
    return TN_OK;
}

/* Decodes one Huffman-coded block with the tables in s->lit / s->dist. The hot loop keeps the
   bit buffer and output position in locals (stores through `out` would otherwise force reloads),
   and after a literal tries a second one without refilling. */
static tn_status tn__z_codes(tn__inflate *s)
{
    const uint32_t *lit = s->lit, *dist = s->dist;
    const uint8_t *in = s->in, *in_end = s->in_end;
    uint64_t bits = s->bits;
    unsigned nbits = s->nbits, overrun = s->overrun;
    uint8_t *out = s->out;
    size_t olen = s->len, cap = s->cap;
    uint32_t e, extra, length, d;
    tn_status st = TN_OK;
    for (;;) {
        if (nbits < 48) {
            if (in_end - in >= 8) {
                bits |= tn__z_load64le(in) << nbits;
                in += (63 - nbits) >> 3;
                nbits |= 56;
            } else {
                while (nbits <= 56) {
                    if (in < in_end) bits |= (uint64_t)*in++ << nbits;
                    else overrun++;
                    nbits += 8;
                }
                if (overrun > 16) { st = tn__fail(TN_ERR_CORRUPT, "%s: compressed data is truncated", s->what); break; }
            }
        }
        e = lit[bits & ((1u << TN__Z_LIT_ROOT) - 1u)];
        if (((e >> 5) & 7u) == TN__ZK_SUB) {
            bits >>= TN__Z_LIT_ROOT;
            nbits -= TN__Z_LIT_ROOT;
            e = lit[(e >> 16) + (bits & ((1u << ((e >> 8) & 31u)) - 1u))];
        }
        bits >>= e & 31u;
        nbits -= e & 31u;
        if (((e >> 5) & 7u) == TN__ZK_LIT) {
            if (olen + 2 > cap) {
                s->len = olen;
                if ((st = tn__z_grow(s, olen + 1)) != TN_OK) break;
                out = s->out;
                cap = s->cap;
            }
            out[olen++] = (uint8_t)(e >> 16);
            /* >= 33 bits remain: a second root-level literal needs no refill */
            e = lit[bits & ((1u << TN__Z_LIT_ROOT) - 1u)];
            if ((e & (7u << 5)) == (TN__ZK_LIT << 5) && olen < cap) {
                bits >>= e & 31u;
                nbits -= e & 31u;
                out[olen++] = (uint8_t)(e >> 16);
            }
            continue;
        }
        if (((e >> 5) & 7u) == TN__ZK_EOB) break;
        if (((e >> 5) & 7u) != TN__ZK_LEN) { st = tn__fail(TN_ERR_CORRUPT, "%s: invalid Huffman code", s->what); break; }
        extra = (e >> 8) & 31u;
        length = (e >> 16) + (uint32_t)(bits & ((1u << extra) - 1u));
        bits >>= extra;
        nbits -= extra;
        e = dist[bits & ((1u << TN__Z_DIST_ROOT) - 1u)];
        if (((e >> 5) & 7u) == TN__ZK_SUB) {
            bits >>= TN__Z_DIST_ROOT;
            nbits -= TN__Z_DIST_ROOT;
            e = dist[(e >> 16) + (bits & ((1u << ((e >> 8) & 31u)) - 1u))];
        }
        bits >>= e & 31u;
        nbits -= e & 31u;
        if (((e >> 5) & 7u) != TN__ZK_LEN) { st = tn__fail(TN_ERR_CORRUPT, "%s: invalid Huffman code", s->what); break; }
        extra = (e >> 8) & 31u;
        d = (e >> 16) + (uint32_t)(bits & ((1u << extra) - 1u));
        bits >>= extra;
        nbits -= extra;
        if (d > olen) {
            st = tn__fail(TN_ERR_CORRUPT, "%s: match distance %u reaches before the start of the data", s->what, (unsigned)d);
            break;
        }
        if (length > cap - olen) {
            s->len = olen;
            if ((st = tn__z_grow(s, olen + length)) != TN_OK) break;
            out = s->out;
            cap = s->cap;
        }
        {
            uint8_t *dst = out + olen;
            const uint8_t *src = dst - d;
            uint32_t i;
            if (d >= 8) { /* chunks of 8 never read bytes they write; overshoot lands in the slack */
                for (i = 0; i < length; i += 8) memcpy(dst + i, src + i, 8);
            } else if (d == 1) {
                memset(dst, src[0], length);
            } else {
                for (i = 0; i < length; i++) dst[i] = src[i];
            }
            olen += length;
        }
    }
    s->in = in;
    s->bits = bits;
    s->nbits = nbits;
    s->overrun = overrun;
    s->len = olen;
    return st;
}

/* Reads a dynamic block header (RFC 1951 3.2.7) and builds the tables. */
static tn_status tn__z_dynamic(tn__inflate *s)
{
    uint8_t lens[320], clens[19];
    unsigned hlit, hdist, hclen, i, n;
    if (tn__z_refill(s)) goto truncated;
    hlit = tn__z_getbits(s, 5) + 257;
    hdist = tn__z_getbits(s, 5) + 1;
    hclen = tn__z_getbits(s, 4) + 4;
    if (hlit > 286 || hdist > 30) return tn__fail(TN_ERR_CORRUPT, "%s: too many length or distance codes", s->what);
    memset(clens, 0, sizeof clens);
    for (i = 0; i < hclen; i++) {
        if (s->nbits < 3 && tn__z_refill(s)) goto truncated;
        clens[tn__z_clen_order[i]] = (uint8_t)tn__z_getbits(s, 3);
    }
    if (tn__z_build(s->clen, 7, clens, 19, s->clen_payload, 0))
        return tn__fail(TN_ERR_CORRUPT, "%s: invalid code length code", s->what);
    n = 0;
    while (n < hlit + hdist) {
        uint32_t e, sym, rep, val;
        if (s->nbits < 16 && tn__z_refill(s)) goto truncated;
        e = s->clen[s->bits & 127u];
        if (((e >> 5) & 7u) != TN__ZK_LIT) return tn__fail(TN_ERR_CORRUPT, "%s: invalid code length code", s->what);
        s->bits >>= e & 31u;
        s->nbits -= e & 31u;
        sym = e >> 16;
        if (sym < 16) {
            lens[n++] = (uint8_t)sym;
            continue;
        }
        if (sym == 16) {
            if (n == 0) return tn__fail(TN_ERR_CORRUPT, "%s: repeated code length with no previous length", s->what);
            val = lens[n - 1];
            rep = 3 + tn__z_getbits(s, 2);
        } else if (sym == 17) {
            val = 0;
            rep = 3 + tn__z_getbits(s, 3);
        } else {
            val = 0;
            rep = 11 + tn__z_getbits(s, 7);
        }
        if (n + rep > hlit + hdist) return tn__fail(TN_ERR_CORRUPT, "%s: code lengths overflow the table", s->what);
        while (rep--) lens[n++] = (uint8_t)val;
    }
    if (lens[256] == 0) return tn__fail(TN_ERR_CORRUPT, "%s: block has no end-of-block code", s->what);
    if (tn__z_build(s->lit, TN__Z_LIT_ROOT, lens, hlit, s->lit_payload, 1))
        return tn__fail(TN_ERR_CORRUPT, "%s: invalid literal/length code lengths", s->what);
    if (tn__z_build(s->dist, TN__Z_DIST_ROOT, lens + hlit, hdist, s->dist_payload, 1))
        return tn__fail(TN_ERR_CORRUPT, "%s: invalid distance code lengths", s->what);
    return TN_OK;
truncated:
    return tn__fail(TN_ERR_CORRUPT, "%s: compressed data is truncated", s->what);
}

/* Runs a whole zlib stream (header, blocks, Adler-32) into s->out (which may be preallocated
   with cap == max, as the PNG decoder does). */
static tn_status tn__z_inflate_run(tn__inflate *s, const uint8_t *src, size_t n)
{
    unsigned final = 0, type;
    tn_status st;
    uint8_t fixed[320];
    if (n < 2) return tn__fail(TN_ERR_CORRUPT, "%s: stream is truncated", s->what);
    if ((src[0] & 15u) != 8 || (src[0] >> 4) > 7 || ((unsigned)src[0] * 256u + src[1]) % 31u != 0)
        return tn__fail(TN_ERR_CORRUPT, "%s: bad stream header", s->what);
    if (src[1] & 32u) return tn__fail(TN_ERR_CORRUPT, "%s: preset dictionaries are not supported", s->what);
    tn__z_init_payloads(s);
    s->in = src + 2;
    s->in_end = src + n;
    s->bits = 0;
    s->nbits = 0;
    s->overrun = 0;
    while (!final) {
        if (tn__z_refill(s)) return tn__fail(TN_ERR_CORRUPT, "%s: compressed data is truncated", s->what);
        final = tn__z_getbits(s, 1);
        type = tn__z_getbits(s, 2);
        if (type == 0) {
            size_t blen, nlen;
            if (tn__z_align(s) || s->in_end - s->in < 4) return tn__fail(TN_ERR_CORRUPT, "%s: compressed data is truncated", s->what);
            blen = (size_t)s->in[0] | ((size_t)s->in[1] << 8);
            nlen = (size_t)s->in[2] | ((size_t)s->in[3] << 8);
            s->in += 4;
            if (blen != (~nlen & 0xffffu)) return tn__fail(TN_ERR_CORRUPT, "%s: stored block length check failed", s->what);
            if ((size_t)(s->in_end - s->in) < blen) return tn__fail(TN_ERR_CORRUPT, "%s: compressed data is truncated", s->what);
            if (blen > s->cap - s->len && (st = tn__z_grow(s, s->len + blen)) != TN_OK) return st;
            memcpy(s->out + s->len, s->in, blen);
            s->len += blen;
            s->in += blen;
        } else if (type == 1) {
            tn__z_fixed_lengths(fixed);
            tn__z_build(s->lit, TN__Z_LIT_ROOT, fixed, 288, s->lit_payload, 0);
            tn__z_build(s->dist, TN__Z_DIST_ROOT, fixed + 288, 32, s->dist_payload, 0);
            if ((st = tn__z_codes(s)) != TN_OK) return st;
        } else if (type == 2) {
            if ((st = tn__z_dynamic(s)) != TN_OK) return st;
            if ((st = tn__z_codes(s)) != TN_OK) return st;
        } else {
            return tn__fail(TN_ERR_CORRUPT, "%s: invalid block type 3", s->what);
        }
    }
    if (tn__z_align(s) || s->in_end - s->in < 4) return tn__fail(TN_ERR_CORRUPT, "%s: stream is truncated before its checksum", s->what);
    if (tn__png_be32(s->in) != tn__adler32(1, s->out, s->len))
        return tn__fail(TN_ERR_CORRUPT, "%s: Adler-32 checksum mismatch", s->what);
    return TN_OK;
}

/* Inflates a zlib stream into a new TN_MALLOC'ed buffer (caller frees with TN_FREE). Output
   larger than max_out (0 = TN_MAX_ALLOC) fails with TN_ERR_TOO_LARGE. */
TN_API tn_status tn_zlib_inflate(const uint8_t *src, size_t n, uint8_t **out, size_t *out_size, size_t max_out)
{
    tn__inflate *s;
    tn_status st;
    size_t guess;
    *out = NULL;
    *out_size = 0;
    if (max_out == 0 || max_out > TN_MAX_ALLOC) max_out = TN_MAX_ALLOC;
    s = (tn__inflate *)tn__alloc(sizeof *s);
    if (!s) return TN_ERR_OUT_OF_MEMORY;
    s->what = "zlib";
    s->out = NULL;
    s->len = s->cap = 0;
    s->max = max_out;
    guess = n < ((size_t)1 << 28) ? n * 4 : ((size_t)1 << 30);
    if (guess < 4096) guess = 4096;
    if (guess > max_out) guess = max_out;
    st = tn__z_grow(s, guess);
    if (st == TN_OK) st = tn__z_inflate_run(s, src, n);
    if (st == TN_OK) {
        *out = s->out;
        *out_size = s->len;
    } else {
        TN_FREE(s->out);
    }
    TN_FREE(s);
    return st;
}

/* ---- deflate ---- */

#define TN__Z_WSIZE 32768u
#define TN__Z_HASH_BITS 15
#define TN__Z_BLOCK_SYMS 16383u /* zlib's literal buffer at memLevel 8 */

typedef struct tn__deflate {
    const uint8_t *src;
    size_t n;
    size_t *head;           /* per hash: last position + 1 (0 = none) */
    uint16_t *prev;         /* per position mod WSIZE: distance to the previous same-hash position, 0 = none */
    uint16_t *sym_len;      /* literal byte (sym_dist == 0) or match length 3..258 */
    uint16_t *sym_dist;
    size_t nsym, block_start, covered;
    uint32_t lfreq[288], dfreq[30];
    uint8_t *out;
    size_t olen, ocap;
    uint64_t bits;
    unsigned nbits;
    unsigned good, lazy, nice, chain;
    unsigned hash_shift;    /* 32 - hash bits; small inputs use small tables */
    uint8_t len_code[259];  /* match length -> length code 0..28 */
    uint8_t dist_code[512]; /* (d-1) < 256 ? [d-1] : [256 + ((d-1) >> 7)] -> distance code */
} tn__deflate;

static unsigned tn__z_dcode(const tn__deflate *s, unsigned d)
{
    return d <= 256 ? s->dist_code[d - 1] : s->dist_code[256 + ((d - 1) >> 7)];
}

static void tn__z_put(tn__deflate *s, uint32_t v, unsigned n)
{
    s->bits |= (uint64_t)v << s->nbits;
    s->nbits += n;
    if (s->nbits >= 32) {
        uint8_t *o = s->out + s->olen;
        o[0] = (uint8_t)s->bits;
        o[1] = (uint8_t)(s->bits >> 8);
        o[2] = (uint8_t)(s->bits >> 16);
        o[3] = (uint8_t)(s->bits >> 24);
        s->olen += 4;
        s->bits >>= 32;
        s->nbits -= 32;
    }
}

/* Writes out pending bits, zero-padding to a byte boundary. */
static void tn__z_put_align(tn__deflate *s)
{
    while (s->nbits > 0) {
        s->out[s->olen++] = (uint8_t)s->bits;
        s->bits >>= 8;
        s->nbits = s->nbits > 8 ? s->nbits - 8 : 0;
    }
    s->bits = 0;
}

/* Moffat-Katajainen in-place minimum-redundancy code lengths: a[] holds n >= 2 weights sorted
   ascending and on return the code length of each. */
static void tn__z_moffat(uint32_t *a, int n)
{
    int root, leaf, next, avbl, used, dpth;
    a[0] += a[1];
    root = 0;
    leaf = 2;
    for (next = 1; next < n - 1; next++) {
        if (leaf >= n || a[root] < a[leaf]) { a[next] = a[root]; a[root++] = (uint32_t)next; }
        else a[next] = a[leaf++];
        if (leaf >= n || (root < next && a[root] < a[leaf])) { a[next] += a[root]; a[root++] = (uint32_t)next; }
        else a[next] += a[leaf++];
    }
    a[n - 2] = 0;
    for (next = n - 3; next >= 0; next--) a[next] = a[a[next]] + 1;
    avbl = 1;
    used = dpth = 0;
    root = n - 2;
    next = n - 1;
    while (avbl > 0) {
        while (root >= 0 && (int)a[root] == dpth) { used++; root--; }
        while (avbl > used) { a[next--] = (uint32_t)dpth; avbl--; }
        avbl = 2 * used;
        dpth++;
        used = 0;
    }
}

static int tn__z_cmp_u64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return x < y ? -1 : (x > y);
}

/* Huffman code lengths for freq[0..n-1], at most maxbits long. At least two symbols get codes
   (as zlib does) so every code is complete. */
static void tn__z_huff_lengths(const uint32_t *freq, unsigned n, unsigned maxbits, uint8_t *lens)
{
    uint64_t keys[320];
    uint32_t w[320];
    unsigned count[321], m = 0, i, len, k;
    uint32_t total;
    memset(lens, 0, n);
    for (i = 0; i < n; i++)
        if (freq[i]) keys[m++] = ((uint64_t)freq[i] << 16) | i;
    for (i = 0; m < 2 && i < n; i++) /* dummy symbols of weight 0 to reach two codes */
        if (!freq[i]) keys[m++] = i;
    if (m < 2) { lens[0] = 1; return; }
    qsort(keys, m, sizeof keys[0], tn__z_cmp_u64);
    for (i = 0; i < m; i++) w[i] = (uint32_t)(keys[i] >> 16);
    tn__z_moffat(w, (int)m);
    memset(count, 0, sizeof count);
    for (i = 0; i < m; i++) count[w[i]]++;
    for (len = maxbits + 1; len <= 320; len++) { count[maxbits] += count[len]; count[len] = 0; }
    total = 0;
    for (len = maxbits; len > 0; len--) total += (uint32_t)count[len] << (maxbits - len);
    while (total > (1u << maxbits)) { /* lengthen a shorter code to make room */
        count[maxbits]--;
        for (len = maxbits - 1; len > 0; len--)
            if (count[len]) { count[len]--; count[len + 1] += 2; break; }
        total--;
    }
    for (k = 0, len = maxbits; len > 0; len--) /* least frequent symbols get the longest codes */
        for (i = 0; i < count[len]; i++) lens[keys[k++] & 0xffffu] = (uint8_t)len;
}

/* Canonical codes, bit-reversed for LSB-first output. */
static void tn__z_make_codes(const uint8_t *lens, unsigned n, uint16_t *codes)
{
    unsigned count[16], next[16], i, code = 0;
    memset(count, 0, sizeof count);
    for (i = 0; i < n; i++) count[lens[i]]++;
    count[0] = 0;
    for (i = 1; i < 16; i++) { code = (code + count[i - 1]) << 1; next[i] = code; }
    for (i = 0; i < n; i++)
        codes[i] = lens[i] ? (uint16_t)tn__z_reverse(next[lens[i]]++, lens[i]) : 0;
}

/* Run-length codes (16/17/18) for a code length sequence; returns the count. */
static unsigned tn__z_rle(const uint8_t *lens, unsigned n, uint8_t *sym, uint8_t *ext, uint32_t *freq)
{
    unsigned i = 0, m = 0, run, r;
    while (i < n) {
        unsigned cur = lens[i];
        run = 1;
        while (i + run < n && lens[i + run] == cur) run++;
        i += run;
        if (cur == 0) {
            while (run >= 11) { r = run < 138 ? run : 138; sym[m] = 18; ext[m++] = (uint8_t)(r - 11); run -= r; }
            if (run >= 3) { sym[m] = 17; ext[m++] = (uint8_t)(run - 3); run = 0; }
        } else {
            sym[m] = (uint8_t)cur; ext[m++] = 0;
            run--;
            while (run >= 3) { r = run < 6 ? run : 6; sym[m] = 16; ext[m++] = (uint8_t)(r - 3); run -= r; }
        }
        while (run--) { sym[m] = (uint8_t)cur; ext[m++] = 0; }
    }
    for (i = 0; i < m; i++) freq[sym[i]]++;
    return m;
}

static void tn__z_write_syms(tn__deflate *s, const uint16_t *lcode, const uint8_t *llen, const uint16_t *dcode,
                             const uint8_t *dlen)
{
    size_t i;
    for (i = 0; i < s->nsym; i++) {
        unsigned l = s->sym_len[i], d = s->sym_dist[i];
        if (!d) {
            tn__z_put(s, lcode[l], llen[l]);
        } else {
            unsigned lc = s->len_code[l], dc = tn__z_dcode(s, d);
            tn__z_put(s, lcode[257 + lc], llen[257 + lc]);
            if (tn__z_len_extra[lc]) tn__z_put(s, l - tn__z_len_base[lc], tn__z_len_extra[lc]);
            tn__z_put(s, dcode[dc], dlen[dc]);
            if (tn__z_dist_extra[dc]) tn__z_put(s, d - tn__z_dist_base[dc], tn__z_dist_extra[dc]);
        }
    }
    tn__z_put(s, lcode[256], llen[256]);
}

/* Emits the symbols gathered since block_start as one block (or several stored ones), choosing
   the smallest of dynamic, fixed and stored. */
static tn_status tn__z_flush_block(tn__deflate *s, int final)
{
    uint8_t llen[288], dlen[30], clen[19], rsym[320], rext[320], fixed[320];
    uint16_t lcode[288], dcode[30], ccode[19];
    uint32_t cfreq[19];
    unsigned nl, nd, nc, nr, i;
    uint64_t extra_bits = 0, dyn, fix, stored;
    size_t span = s->covered - s->block_start, chunks, need;
    tn_status st;

    s->lfreq[256] = 1;
    tn__z_huff_lengths(s->lfreq, 286, 15, llen);
    llen[286] = llen[287] = 0;
    tn__z_huff_lengths(s->dfreq, 30, 15, dlen);
    for (nl = 286; nl > 257 && !llen[nl - 1]; nl--) {}
    for (nd = 30; nd > 1 && !dlen[nd - 1]; nd--) {}
    memset(cfreq, 0, sizeof cfreq);
    nr = tn__z_rle(llen, nl, rsym, rext, cfreq);
    nr += tn__z_rle(dlen, nd, rsym + nr, rext + nr, cfreq);
    tn__z_huff_lengths(cfreq, 19, 7, clen);
    for (nc = 19; nc > 4 && !clen[tn__z_clen_order[nc - 1]]; nc--) {}

    tn__z_fixed_lengths(fixed);
    for (i = 0; i < 29; i++) extra_bits += (uint64_t)s->lfreq[257 + i] * tn__z_len_extra[i];
    for (i = 0; i < 30; i++) extra_bits += (uint64_t)s->dfreq[i] * tn__z_dist_extra[i];
    dyn = 3 + 14 + 3 * (uint64_t)nc + extra_bits;
    fix = 3 + extra_bits;
    for (i = 0; i < 286; i++) {
        dyn += (uint64_t)s->lfreq[i] * llen[i];
        fix += (uint64_t)s->lfreq[i] * fixed[i];
    }
    for (i = 0; i < 30; i++) {
        dyn += (uint64_t)s->dfreq[i] * dlen[i];
        fix += (uint64_t)s->dfreq[i] * 5;
    }
    for (i = 0; i < nr; i++) dyn += clen[rsym[i]] + (rsym[i] == 16 ? 2 : rsym[i] == 17 ? 3 : rsym[i] == 18 ? 7 : 0);
    chunks = span ? (span + 65534) / 65535 : 1;
    stored = 10 + (uint64_t)chunks * 40 + (uint64_t)span * 8;

    need = s->olen + span + chunks * 5 + 1024; /* stored size bounds the choice below */
    if ((st = tn__reserve((void **)&s->out, &s->ocap, need)) != TN_OK) return st;

    if (stored <= dyn && stored <= fix) {
        const uint8_t *p = s->src + s->block_start;
        size_t left = span, c;
        do {
            c = left < 65535 ? left : 65535;
            left -= c;
            tn__z_put(s, (final && !left) ? 1u : 0u, 1);
            tn__z_put(s, 0, 2);
            tn__z_put_align(s);
            s->out[s->olen++] = (uint8_t)c;
            s->out[s->olen++] = (uint8_t)(c >> 8);
            s->out[s->olen++] = (uint8_t)~c;
            s->out[s->olen++] = (uint8_t)(~c >> 8);
            memcpy(s->out + s->olen, p, c);
            s->olen += c;
            p += c;
        } while (left);
    } else if (fix <= dyn) {
        uint16_t fcode[320];
        tn__z_make_codes(fixed, 288, fcode);
        tn__z_make_codes(fixed + 288, 30, fcode + 288);
        tn__z_put(s, final ? 1u : 0u, 1);
        tn__z_put(s, 1, 2);
        tn__z_write_syms(s, fcode, fixed, fcode + 288, fixed + 288);
    } else {
        tn__z_make_codes(llen, 288, lcode);
        tn__z_make_codes(dlen, 30, dcode);
        tn__z_make_codes(clen, 19, ccode);
        tn__z_put(s, final ? 1u : 0u, 1);
        tn__z_put(s, 2, 2);
        tn__z_put(s, nl - 257, 5);
        tn__z_put(s, nd - 1, 5);
        tn__z_put(s, nc - 4, 4);
        for (i = 0; i < nc; i++) tn__z_put(s, clen[tn__z_clen_order[i]], 3);
        for (i = 0; i < nr; i++) {
            tn__z_put(s, ccode[rsym[i]], clen[rsym[i]]);
            if (rsym[i] >= 16) tn__z_put(s, rext[i], rsym[i] == 16 ? 2u : rsym[i] == 17 ? 3u : 7u);
        }
        tn__z_write_syms(s, lcode, llen, dcode, dlen);
    }
    memset(s->lfreq, 0, sizeof s->lfreq);
    memset(s->dfreq, 0, sizeof s->dfreq);
    s->nsym = 0;
    s->block_start = s->covered;
    return TN_OK;
}

static void tn__z_tally_lit(tn__deflate *s, unsigned c)
{
    s->sym_len[s->nsym] = (uint16_t)c;
    s->sym_dist[s->nsym++] = 0;
    s->lfreq[c]++;
    s->covered++;
}

static void tn__z_tally_match(tn__deflate *s, unsigned len, unsigned dist)
{
    s->sym_len[s->nsym] = (uint16_t)len;
    s->sym_dist[s->nsym++] = (uint16_t)dist;
    s->lfreq[257 + s->len_code[len]]++;
    s->dfreq[tn__z_dcode(s, dist)]++;
    s->covered += len;
}

/* Adds position p (p + 3 <= n) to its hash chain; returns the previous head (position + 1). */
static size_t tn__z_insert(tn__deflate *s, size_t p)
{
    const uint8_t *q = s->src + p;
    uint32_t h = ((((uint32_t)q[0] << 16) | ((uint32_t)q[1] << 8) | q[2]) * 2654435761u) >> s->hash_shift;
    size_t cand = s->head[h];
    s->head[h] = p + 1;
    s->prev[p & (TN__Z_WSIZE - 1)] = (uint16_t)((cand && p - (cand - 1) < TN__Z_WSIZE) ? p - (cand - 1) : 0);
    return cand;
}

/* Longest match for position p along the chain starting at cand (position + 1), if longer than
   `best`; returns its length (0 if none is longer) and distance. */
static unsigned tn__z_longest(const tn__deflate *s, size_t p, size_t cand, unsigned best, unsigned *dist_out)
{
    const uint8_t *cur = s->src + p;
    size_t avail = s->n - p;
    unsigned maxlen = avail < 258 ? (unsigned)avail : 258u, nice = s->nice, chain = s->chain, found = 0;
    size_t c = cand - 1;
    if (best >= s->good) chain >>= 2;
    if (nice > maxlen) nice = maxlen;
    if (best >= maxlen) return 0;
    while (chain--) {
        size_t d = p - c;
        const uint8_t *m = s->src + c;
        unsigned pd;
        if (d >= TN__Z_WSIZE) break;
        if (m[best] == cur[best] && m[0] == cur[0] && m[1] == cur[1]) {
            unsigned l = 0;
            while (l + 8 <= maxlen) {
                uint64_t x = tn__z_load64le(m + l) ^ tn__z_load64le(cur + l);
                if (x) { l += tn__z_ctz64(x) >> 3; goto counted; }
                l += 8;
            }
            while (l < maxlen && m[l] == cur[l]) l++;
        counted:
            if (l > best) {
                best = found = l;
                *dist_out = (unsigned)d;
                if (l >= nice) break;
            }
        }
        pd = s->prev[c & (TN__Z_WSIZE - 1)];
        if (!pd || pd > c) break;
        c -= pd;
    }
    return found;
}

static void tn__z_level_params(tn__deflate *s, int level)
{
    /* zlib's configuration_table: good, lazy (greedy levels: max insert length), nice, chain */
    static const unsigned cfg[10][4] = {{8, 16, 128, 128}, {4, 4, 8, 4}, {4, 5, 16, 8}, {4, 6, 32, 32},
                                        {4, 4, 16, 16}, {8, 16, 32, 32}, {8, 16, 128, 128}, {8, 32, 128, 256},
                                        {32, 128, 258, 1024}, {32, 258, 258, 4096}};
    s->good = cfg[level][0];
    s->lazy = cfg[level][1];
    s->nice = cfg[level][2];
    s->chain = cfg[level][3];
}

/* Greedy parse (zlib's deflate_fast): take the first good match, insert its positions only if short. */
static tn_status tn__z_parse_greedy(tn__deflate *s)
{
    size_t p = 0, n = s->n, q, cand;
    unsigned len, dist = 0;
    tn_status st;
    while (p < n) {
        len = 0;
        if (p + 3 <= n) {
            cand = tn__z_insert(s, p);
            if (cand) {
                len = tn__z_longest(s, p, cand, 2, &dist);
                if (len == 3 && dist > 4096) len = 0;
            }
        }
        if (len >= 3) {
            tn__z_tally_match(s, len, dist);
            if (len <= s->lazy)
                for (q = p + 1; q < p + len && q + 3 <= n; q++) tn__z_insert(s, q);
            p += len;
        } else {
            tn__z_tally_lit(s, s->src[p]);
            p++;
        }
        if (s->nsym >= TN__Z_BLOCK_SYMS && (st = tn__z_flush_block(s, 0)) != TN_OK) return st;
    }
    return TN_OK;
}

/* Lazy parse (zlib's deflate_slow): a match at p is emitted only if p + 1 has no longer one. */
static tn_status tn__z_parse_lazy(tn__deflate *s)
{
    size_t p = 0, n = s->n, q, end, cand;
    unsigned prev_len = 0, prev_dist = 0, cur_len, cur_dist = 0;
    int pending = 0; /* src[p - 1] is not yet emitted */
    tn_status st;
    while (p < n) {
        cur_len = 0;
        if (p + 3 <= n) {
            cand = tn__z_insert(s, p);
            if (cand && prev_len < s->lazy) {
                cur_len = tn__z_longest(s, p, cand, prev_len > 2 ? prev_len : 2, &cur_dist);
                if (cur_len == 3 && cur_dist > 4096) cur_len = 0;
            }
        }
        if (prev_len >= 3 && cur_len <= prev_len) {
            tn__z_tally_match(s, prev_len, prev_dist);
            end = p - 1 + prev_len;
            for (q = p + 1; q < end && q + 3 <= n; q++) tn__z_insert(s, q);
            p = end;
            pending = 0;
            prev_len = 0;
        } else {
            if (pending) tn__z_tally_lit(s, s->src[p - 1]);
            pending = 1;
            prev_len = cur_len;
            prev_dist = cur_dist;
            p++;
        }
        if (s->nsym >= TN__Z_BLOCK_SYMS && (st = tn__z_flush_block(s, 0)) != TN_OK) return st;
    }
    if (pending) tn__z_tally_lit(s, s->src[n - 1]);
    return TN_OK;
}

/* Compresses src into a zlib stream in a new TN_MALLOC'ed buffer (caller frees with TN_FREE).
   level 1-9 as zlib; 0 (or out of range) means 6. */
TN_API tn_status tn_zlib_deflate(const uint8_t *src, size_t n, int level, uint8_t **out, size_t *out_size)
{
    tn__deflate *s;
    tn_status st = TN_OK;
    unsigned i, d, code;
    uint32_t adler;
    *out = NULL;
    *out_size = 0;
    if (level < -1 || level > 9) return tn__fail(TN_ERR_INVALID_ARG, "deflate: level %d (0-9; 0 and zlib's -1 = 6)", level);
    if (!src && n) return tn__fail(TN_ERR_INVALID_ARG, "deflate: NULL input");
    if (level <= 0) level = 6;
    s = (tn__deflate *)tn__calloc(sizeof *s);
    if (!s) return TN_ERR_OUT_OF_MEMORY;
    s->src = src;
    s->n = n;
    tn__z_level_params(s, level);
    for (code = 0; code < 29; code++)
        for (i = tn__z_len_base[code]; i < (unsigned)tn__z_len_base[code] + (1u << tn__z_len_extra[code]) && i <= 258; i++)
            s->len_code[i] = (uint8_t)code;
    s->len_code[258] = 28; /* 258 has its own code, not 284 + 31 */
    for (code = 0; code < 30; code++)
        for (d = tn__z_dist_base[code]; d < (unsigned)tn__z_dist_base[code] + (1u << tn__z_dist_extra[code]); d++)
            s->dist_code[d <= 256 ? d - 1 : 256 + ((d - 1) >> 7)] = (uint8_t)code;
    for (i = 8; i < TN__Z_HASH_BITS && ((size_t)1 << i) < n; i++) {}
    s->hash_shift = 32 - i;
    s->head = (size_t *)tn__calloc(sizeof(size_t) << i);
    s->prev = (uint16_t *)tn__calloc(sizeof(uint16_t) * (n < TN__Z_WSIZE ? n + 1 : TN__Z_WSIZE)); /* p < n */
    s->sym_len = (uint16_t *)tn__alloc(sizeof(uint16_t) * TN__Z_BLOCK_SYMS);
    s->sym_dist = (uint16_t *)tn__alloc(sizeof(uint16_t) * TN__Z_BLOCK_SYMS);
    if (!s->head || !s->prev || !s->sym_len || !s->sym_dist) st = TN_ERR_OUT_OF_MEMORY;
    if (st == TN_OK) st = tn__reserve((void **)&s->out, &s->ocap, n / 2 + 1024);
    if (st == TN_OK) {
        s->out[0] = 0x78; /* deflate, 32K window; FLEVEL as zlib sets it */
        s->out[1] = level == 1 ? 0x01 : level < 6 ? 0x5e : level == 6 ? 0x9c : 0xda;
        s->olen = 2;
        st = level <= 3 ? tn__z_parse_greedy(s) : tn__z_parse_lazy(s);
    }
    if (st == TN_OK) st = tn__z_flush_block(s, 1);
    if (st == TN_OK) st = tn__reserve((void **)&s->out, &s->ocap, s->olen + 16);
    if (st == TN_OK) {
        tn__z_put_align(s);
        adler = tn__adler32(1, src, n);
        tn__png_put_be32(s->out + s->olen, adler);
        s->olen += 4;
        *out = s->out;
        *out_size = s->olen;
    } else {
        TN_FREE(s->out);
    }
    TN_FREE(s->head);
    TN_FREE(s->prev);
    TN_FREE(s->sym_len);
    TN_FREE(s->sym_dist);
    TN_FREE(s);
    return st;
}

/* ---- PNG decode ---- */

static const uint8_t tn__png_sig[8] = {137, 80, 78, 71, 13, 10, 26, 10};

/* Adam7 passes: x0, y0, dx, dy. */
static const uint8_t tn__png_adam7[7][4] = {{0, 0, 8, 8}, {4, 0, 8, 8}, {0, 4, 4, 8}, {2, 0, 4, 4},
                                            {0, 2, 2, 4}, {1, 0, 2, 2}, {0, 1, 1, 2}};

typedef struct tn__png {
    const char *name;
    uint32_t w, h;
    int depth, ctype, interlace;
    int spp;                /* samples per pixel in the file */
    int channels;           /* float channels produced */
    unsigned npal, ntrns;   /* palette entries, palette alpha entries */
    uint8_t pal[256][4];
    int has_trns;           /* grey/RGB transparent colour */
    uint16_t trns[3];
    int has_range;
    double lo, hi;
} tn__png;

/* Width in pixels of an Adam7 pass (or the whole image for pass -1). */
static uint32_t tn__png_pass_dim(uint32_t size, int start, int step)
{
    return size > (uint32_t)start ? (size - (uint32_t)start + (uint32_t)step - 1) / (uint32_t)step : 0;
}

/* Bytes of one row of `pw` pixels, without the filter byte. */
static size_t tn__png_rowbytes(const tn__png *p, uint32_t pw)
{
    return ((size_t)pw * (size_t)(p->spp * p->depth) + 7) / 8;
}

static tn_status tn__png_ihdr(tn__png *p, const uint8_t *d, uint32_t len)
{
    int ok;
    size_t bytes;
    if (len != 13) return tn__fail(TN_ERR_CORRUPT, "%s: IHDR chunk has length %u, not 13", p->name, (unsigned)len);
    p->w = tn__png_be32(d);
    p->h = tn__png_be32(d + 4);
    p->depth = d[8];
    p->ctype = d[9];
    p->interlace = d[12];
    if (p->w == 0 || p->h == 0) return tn__fail(TN_ERR_CORRUPT, "%s: image size %u x %u is empty", p->name, (unsigned)p->w, (unsigned)p->h);
    if (p->w > (1u << 24) || p->h > (1u << 24))
        return tn__fail(TN_ERR_TOO_LARGE, "%s: image size %u x %u is too large", p->name, (unsigned)p->w, (unsigned)p->h);
    switch (p->ctype) {
    case 0: ok = p->depth == 1 || p->depth == 2 || p->depth == 4 || p->depth == 8 || p->depth == 16; p->spp = 1; break;
    case 3: ok = p->depth == 1 || p->depth == 2 || p->depth == 4 || p->depth == 8; p->spp = 1; break;
    case 2: ok = p->depth == 8 || p->depth == 16; p->spp = 3; break;
    case 4: ok = p->depth == 8 || p->depth == 16; p->spp = 2; break;
    case 6: ok = p->depth == 8 || p->depth == 16; p->spp = 4; break;
    default: return tn__fail(TN_ERR_CORRUPT, "%s: invalid colour type %d", p->name, p->ctype);
    }
    if (!ok) return tn__fail(TN_ERR_CORRUPT, "%s: invalid bit depth %d for colour type %d", p->name, p->depth, p->ctype);
    if (d[10] != 0) return tn__fail(TN_ERR_CORRUPT, "%s: unknown compression method %d", p->name, d[10]);
    if (d[11] != 0) return tn__fail(TN_ERR_CORRUPT, "%s: unknown filter method %d", p->name, d[11]);
    if (p->interlace > 1) return tn__fail(TN_ERR_CORRUPT, "%s: unknown interlace method %d", p->name, p->interlace);
    /* the smallest float image this header can lead to (tRNS may add alpha; checked exactly later) */
    return tn__size4(p->w, p->h, (size_t)(p->ctype == 3 ? 3 : p->spp), sizeof(float), &bytes) != TN_OK
               ? tn__fail(TN_ERR_TOO_LARGE, "%s: image size %u x %u exceeds the allocation limit", p->name,
                          (unsigned)p->w, (unsigned)p->h)
               : TN_OK;
}

/* >>formats: locale-free number parsing and printing, unlike strtod / "%g" */
static int tn__io_number(const char *s, size_t n, double *out);
static int tn__io_format_number(char *buf, size_t cap, double v, int as_float);

/* tEXt "terrainnet.range" = "<lo> <hi>"; anything malformed (or NaN) is ignored (ancillary
   chunk). A range beyond float sets has_range = -1: the decode then fails with TN_ERR_NUMERIC,
   since the pixels could not be converted. */
static void tn__png_text(tn__png *p, const uint8_t *d, uint32_t len)
{
    static const char key[] = "terrainnet.range";
    const char *t = (const char *)d + sizeof key;
    size_t tl, i = 0, b[2], e[2];
    double v[2];
    int k;
    if (len < sizeof key || memcmp(d, key, sizeof key) != 0) return; /* sizeof key includes the NUL */
    tl = len - sizeof key;
    for (k = 0; k < 2; k++) {
        while (i < tl && t[i] == ' ') i++;
        b[k] = i;
        while (i < tl && t[i] != ' ') i++;
        e[k] = i;
        if (!tn__io_number(t + b[k], e[k] - b[k], &v[k]) || v[k] != v[k]) return;
    }
    while (i < tl && t[i] == ' ') i++;
    if (i != tl) return; /* trailing junk */
    p->has_range = fabs(v[0]) <= FLT_MAX && fabs(v[1]) <= FLT_MAX ? 1 : -1;
    p->lo = v[0];
    p->hi = v[1];
}

static void tn__png_trns(tn__png *p, const uint8_t *d, uint32_t len)
{
    unsigned i;
    if (p->ctype == 3) {
        if (len > 256) return;
        p->ntrns = len;
        for (i = 0; i < len; i++) p->pal[i][3] = d[i];
    } else if (p->ctype == 0 && len == 2) {
        p->has_trns = 1;
        p->trns[0] = (uint16_t)((d[0] << 8) | d[1]);
    } else if (p->ctype == 2 && len == 6) {
        p->has_trns = 1;
        for (i = 0; i < 3; i++) p->trns[i] = (uint16_t)((d[2 * i] << 8) | d[2 * i + 1]);
    } /* tRNS is not allowed with an alpha channel; ignored like any malformed ancillary chunk */
}

/* Undoes the row filters in place; rows are (1 + rowbytes) apart, each led by its filter type. */
static tn_status tn__png_unfilter(const tn__png *p, uint8_t *data, size_t rowbytes, uint32_t rows)
{
    size_t bpp = (size_t)((p->spp * p->depth + 7) / 8), i, stride = rowbytes + 1;
    uint32_t r;
    for (r = 0; r < rows; r++) {
        uint8_t *row = data + r * stride + 1;
        const uint8_t *up = r ? row - stride : NULL;
        int f = row[-1];
        switch (f) {
        case 0: break;
        case 1:
            for (i = bpp; i < rowbytes; i++) row[i] = (uint8_t)(row[i] + row[i - bpp]);
            break;
        case 2:
            if (up)
                for (i = 0; i < rowbytes; i++) row[i] = (uint8_t)(row[i] + up[i]);
            break;
        case 3:
            if (up) {
                for (i = 0; i < bpp && i < rowbytes; i++) row[i] = (uint8_t)(row[i] + (up[i] >> 1));
                for (; i < rowbytes; i++) row[i] = (uint8_t)(row[i] + ((row[i - bpp] + up[i]) >> 1));
            } else {
                for (i = bpp; i < rowbytes; i++) row[i] = (uint8_t)(row[i] + (row[i - bpp] >> 1));
            }
            break;
        case 4:
            if (up) {
                for (i = 0; i < bpp && i < rowbytes; i++) row[i] = (uint8_t)(row[i] + up[i]);
                for (; i < rowbytes; i++) { /* Paeth; no && so compilers emit conditional moves: the
                                              choice is unpredictable, branches made this 5x slower */
                    int a = row[i - bpp], b = up[i], c = up[i - bpp], bc = b - c, ac = a - c;
                    int pa = abs(bc), pb = abs(ac), pc = abs(ac + bc);
                    int bcs = pb <= pc ? b : c, not_a = (pa > pb) | (pa > pc); /* no && : stays branch-free */
                    row[i] = (uint8_t)(row[i] + (not_a ? bcs : a));
                }
            } else {
                for (i = bpp; i < rowbytes; i++) row[i] = (uint8_t)(row[i] + row[i - bpp]);
            }
            break;
        default:
            return tn__fail(TN_ERR_CORRUPT, "%s: invalid filter type %d in row %u", p->name, f, (unsigned)r);
        }
    }
    return TN_OK;
}

/* Sample i of a row (any depth). */
static unsigned tn__png_sample(const uint8_t *row, size_t i, int depth)
{
    size_t bit;
    if (depth == 8) return row[i];
    if (depth == 16) return ((unsigned)row[2 * i] << 8) | row[2 * i + 1];
    bit = i * (size_t)depth;
    return (row[bit >> 3] >> (8 - depth - (int)(bit & 7))) & ((1u << depth) - 1u);
}

/* Converts `count` pixels of an unfiltered row into floats at dst, dst_step floats apart.
   lut maps codes of depth <= 8 to [0, 1]. Returns -1 on a palette index out of range. */
static int tn__png_row(const tn__png *p, const uint8_t *row, uint32_t count, float *dst, size_t dst_step,
                       const float *lut)
{
    uint32_t x;
    int c, ch = p->channels, depth = p->depth;
    /* (float)(v * (1.0 / 65535)) in double equals the correctly rounded v / 65535.0f for every
       16-bit v (checked exhaustively in the tests) and is cheaper than a float divide */
    const double inv16 = 1.0 / 65535.0;
    if (p->ctype == 3) {
        for (x = 0; x < count; x++, dst += dst_step) {
            unsigned idx = tn__png_sample(row, x, depth);
            if (idx >= p->npal) return -1;
            for (c = 0; c < ch; c++) dst[c] = lut[p->pal[idx][c]];
        }
        return 0;
    }
    if (p->has_range) { /* every sample was coded with the recorded range (no palette, no tRNS) */
        double scale = (p->hi - p->lo) / (double)((1u << depth) - 1u);
        size_t spp = (size_t)p->spp;
        for (x = 0; x < count; x++, dst += dst_step)
            for (c = 0; c < ch; c++) dst[c] = (float)(p->lo + scale * tn__png_sample(row, x * spp + (size_t)c, depth));
        return 0;
    }
    if (depth == 16 && p->ctype == 0 && ch == 1) { /* the DEM case: keep it tight */
        for (x = 0; x < count; x++, dst += dst_step)
            dst[0] = (float)((double)(((unsigned)row[2 * x] << 8) | row[2 * x + 1]) * inv16);
        return 0;
    }
    if (depth == 8 && !p->has_trns) {
        size_t spp = (size_t)p->spp;
        for (x = 0; x < count; x++, dst += dst_step, row += spp)
            for (c = 0; c < ch; c++) dst[c] = lut[row[c]];
        return 0;
    }
    for (x = 0; x < count; x++, dst += dst_step) {
        int transparent = p->has_trns;
        for (c = 0; c < p->spp; c++) {
            unsigned v = tn__png_sample(row, (size_t)x * (size_t)p->spp + (size_t)c, depth);
            if (transparent && v != p->trns[c]) transparent = 0;
            dst[c] = depth == 16 ? (float)((double)v * inv16) : lut[v];
        }
        if (p->has_trns) dst[p->spp] = transparent ? 0.0f : 1.0f;
    }
    return 0;
}

/* Inflates, unfilters and converts the concatenated IDAT data into img. */
static tn_status tn__png_pixels(tn__png *p, const uint8_t *z, size_t zn, tn_image *img)
{
    size_t raw_size = 0, fbytes, off, rb;
    tn__inflate *s = NULL;
    float *data = NULL, lut[256];
    char what[256];
    tn_status st = TN_OK;
    int pass, npass = p->interlace ? 7 : 1;
    unsigned i, maxcode = (1u << (p->depth > 8 ? 8 : p->depth)) - 1u;
    uint32_t r;

    for (pass = 0; pass < npass; pass++) {
        const uint8_t *a = p->interlace ? tn__png_adam7[pass] : NULL;
        uint32_t pw = a ? tn__png_pass_dim(p->w, a[0], a[2]) : p->w;
        uint32_t ph = a ? tn__png_pass_dim(p->h, a[1], a[3]) : p->h;
        size_t bytes;
        if (!pw || !ph) continue;
        if ((st = tn__size4(ph, tn__png_rowbytes(p, pw) + 1, 1, 1, &bytes)) != TN_OK) return st;
        raw_size += bytes;
    }
    if (raw_size > TN_MAX_ALLOC) return tn__fail(TN_ERR_TOO_LARGE, "%s: pixel data of %zu bytes exceeds the limit", p->name, raw_size);
    if ((st = tn__size4(p->w, p->h, (size_t)p->channels, sizeof(float), &fbytes)) != TN_OK)
        return tn__fail(st, "%s: image size %u x %u x %d exceeds the allocation limit", p->name, (unsigned)p->w,
                        (unsigned)p->h, p->channels);
    /* deflate expands at most 1032:1, so a short stream cannot make us allocate much */
    if (raw_size / 1032 > zn + 64)
        return tn__fail(TN_ERR_CORRUPT, "%s: %zu bytes of IDAT cannot hold %zu bytes of pixel data", p->name, zn, raw_size);

    s = (tn__inflate *)tn__alloc(sizeof *s);
    if (!s) return TN_ERR_OUT_OF_MEMORY;
    snprintf(what, sizeof what, "%s: IDAT", p->name);
    s->what = what;
    s->out = (uint8_t *)tn__alloc(raw_size + TN__Z_SLACK);
    s->len = 0;
    s->cap = s->max = raw_size;
    if (!s->out) st = TN_ERR_OUT_OF_MEMORY;
    if (st == TN_OK) {
        st = tn__z_inflate_run(s, z, zn);
        if (st == TN_ERR_TOO_LARGE) st = tn__fail(TN_ERR_CORRUPT, "%s: IDAT holds more than the %zu bytes of pixel data", p->name, raw_size);
        else if (s->len != raw_size)
            st = tn__fail(TN_ERR_CORRUPT, "%s: IDAT holds %zu bytes of pixel data, expected %zu", p->name, s->len, raw_size);
    }
    if (st == TN_OK) {
        data = (float *)tn__alloc(fbytes);
        if (!data) st = TN_ERR_OUT_OF_MEMORY;
    }
    for (i = 0; i < 256; i++) lut[i] = (float)i / (float)(i <= maxcode ? maxcode : 255u);
    if (p->ctype == 3) for (i = 0; i < 256; i++) lut[i] = (float)i / 255.0f;
    for (off = 0, pass = 0; st == TN_OK && pass < npass; pass++) {
        const uint8_t *a = p->interlace ? tn__png_adam7[pass] : NULL;
        uint32_t pw = a ? tn__png_pass_dim(p->w, a[0], a[2]) : p->w;
        uint32_t ph = a ? tn__png_pass_dim(p->h, a[1], a[3]) : p->h;
        uint32_t x0 = a ? a[0] : 0, y0 = a ? a[1] : 0, dx = a ? a[2] : 1, dy = a ? a[3] : 1;
        if (!pw || !ph) continue;
        rb = tn__png_rowbytes(p, pw);
        if ((st = tn__png_unfilter(p, s->out + off, rb, ph)) != TN_OK) break;
        for (r = 0; r < ph; r++) {
            float *dst = data + ((size_t)(y0 + r * dy) * p->w + x0) * (size_t)p->channels;
            if (tn__png_row(p, s->out + off + (size_t)r * (rb + 1) + 1, pw, dst, (size_t)dx * (size_t)p->channels, lut)) {
                st = tn__fail(TN_ERR_CORRUPT, "%s: palette index out of range (palette has %u entries)", p->name, p->npal);
                break;
            }
        }
        off += (size_t)ph * (rb + 1);
    }
    TN_FREE(s->out);
    TN_FREE(s);
    if (st != TN_OK) {
        TN_FREE(data);
        return st;
    }
    img->width = (int)p->w;
    img->height = (int)p->h;
    img->channels = p->channels;
    img->data = data;
    return TN_OK;
}

/* Decodes a whole PNG file held in memory into img (allocated here; untouched on failure).
   Samples become floats code / (2^depth - 1); palettes expand to RGB, or RGBA with tRNS; grey or
   RGB with tRNS gain an alpha channel. info (may be NULL) gets format, bit_depth, file_channels
   (palette: 1), interlaced, and the tEXt "terrainnet.range" mapping, which is applied (v = lo +
   n (hi - lo)) to every sample of non-palette images without tRNS, as the writer coded them. `name` (may be NULL) prefixes error messages.
   Errors: TN_ERR_FORMAT (signature, unknown critical chunk), TN_ERR_CORRUPT (CRC naming the
   chunk, IHDR, chunk order, truncation, zlib, pixel data size, palette index),
   TN_ERR_TOO_LARGE (sides > 2^24 or buffers beyond TN_MAX_ALLOC, checked before allocating). */
static tn_status tn__png_decode(const uint8_t *buf, size_t n, const char *name, tn_image *img, tn_image_info *info)
{
    tn__png *p;
    size_t pos = 8, idat_total = 0, nidat = 0, first_idat = 0;
    int seen_plte = 0, idat_done = 0, seen_iend = 0, i;
    uint8_t *z = NULL;
    const uint8_t *zsrc;
    tn_status st = TN_OK;
    if (!name) name = "png";
    if (n < 8 || memcmp(buf, tn__png_sig, 8) != 0) return tn__fail(TN_ERR_FORMAT, "%s: not a PNG file (bad signature)", name);
    p = (tn__png *)tn__calloc(sizeof *p);
    if (!p) return TN_ERR_OUT_OF_MEMORY;
    p->name = name;
    for (i = 0; i < 256; i++) p->pal[i][3] = 255;

    /* pass 1: walk and check every chunk, parse the small ones, measure IDAT */
    while (st == TN_OK && !seen_iend) {
        uint32_t len;
        const uint8_t *type, *d;
        char tname[5];
        int k;
        if (n - pos < 12) { st = tn__fail(TN_ERR_CORRUPT, "%s: file is truncated (no IEND chunk)", name); break; }
        len = tn__png_be32(buf + pos);
        type = buf + pos + 4;
        d = buf + pos + 8;
        for (k = 0; k < 4; k++) {
            int ch = type[k];
            if (!((ch >= 'A' && ch <= 'Z') || (ch >= 'a' && ch <= 'z'))) break;
            tname[k] = (char)ch;
        }
        tname[4] = 0;
        if (k < 4) { st = tn__fail(TN_ERR_CORRUPT, "%s: invalid chunk type at byte %zu", name, pos + 4); break; }
        if (len > 0x7fffffffu) { st = tn__fail(TN_ERR_CORRUPT, "%s: %s chunk length %u is invalid", name, tname, (unsigned)len); break; }
        if ((size_t)len > n - pos - 12) { st = tn__fail(TN_ERR_CORRUPT, "%s: file is truncated inside the %s chunk", name, tname); break; }
        if (tn__crc32(0, type, (size_t)len + 4) != tn__png_be32(d + len)) {
            st = tn__fail(TN_ERR_CORRUPT, "%s: CRC mismatch in %s chunk", name, tname);
            break;
        }
        if (pos == 8 && memcmp(type, "IHDR", 4) != 0) {
            st = tn__fail(TN_ERR_CORRUPT, "%s: first chunk is %s, not IHDR", name, tname);
            break;
        }
        if (nidat && memcmp(type, "IDAT", 4) != 0) idat_done = 1;
        if (!memcmp(type, "IHDR", 4)) {
            if (pos != 8) st = tn__fail(TN_ERR_CORRUPT, "%s: more than one IHDR chunk", name);
            else st = tn__png_ihdr(p, d, len);
        } else if (!memcmp(type, "PLTE", 4)) {
            if (nidat) st = tn__fail(TN_ERR_CORRUPT, "%s: PLTE chunk after IDAT", name);
            else if (seen_plte) st = tn__fail(TN_ERR_CORRUPT, "%s: more than one PLTE chunk", name);
            else if (len == 0 || len % 3 != 0 || len > 768)
                st = tn__fail(TN_ERR_CORRUPT, "%s: PLTE chunk length %u is invalid", name, (unsigned)len);
            else if (p->ctype == 3 && len / 3 > (1u << p->depth))
                st = tn__fail(TN_ERR_CORRUPT, "%s: palette has %u entries, more than %d-bit indices allow", name, (unsigned)len / 3, p->depth);
            else {
                unsigned e;
                seen_plte = 1;
                p->npal = len / 3;
                for (e = 0; e < p->npal; e++) {
                    p->pal[e][0] = d[3 * e];
                    p->pal[e][1] = d[3 * e + 1];
                    p->pal[e][2] = d[3 * e + 2];
                }
            }
        } else if (!memcmp(type, "IDAT", 4)) {
            if (p->ctype == 3 && !seen_plte) st = tn__fail(TN_ERR_CORRUPT, "%s: palette image without a PLTE chunk", name);
            else if (idat_done) st = tn__fail(TN_ERR_CORRUPT, "%s: IDAT chunks are not consecutive", name);
            else {
                if (!nidat) first_idat = pos;
                nidat++;
                idat_total += len;
            }
        } else if (!memcmp(type, "IEND", 4)) {
            seen_iend = 1;
        } else if (!memcmp(type, "tRNS", 4)) {
            if (!nidat) tn__png_trns(p, d, len);
        } else if (!memcmp(type, "tEXt", 4)) {
            tn__png_text(p, d, len);
        } else if (!(type[0] & 0x20)) {
            st = tn__fail(TN_ERR_FORMAT, "%s: unsupported critical chunk %s", name, tname);
        }
        pos += (size_t)len + 12;
    }
    if (st == TN_OK && !nidat) st = tn__fail(TN_ERR_CORRUPT, "%s: no IDAT chunk", name);
    if (st == TN_OK) {
        if (p->ctype == 3 && p->ntrns > p->npal) p->ntrns = 0; /* malformed tRNS: ignore */
        p->channels = p->ctype == 3 ? (p->ntrns ? 4 : 3) : p->spp + (p->has_trns ? 1 : 0);
        if (p->ctype == 3 || p->has_trns) p->has_range = 0; /* the writer never records one there */
        if (p->has_range < 0)
            st = tn__fail(TN_ERR_NUMERIC, "%s: terrainnet.range [%g, %g] is beyond float range", name, p->lo, p->hi);
    }
    if (st == TN_OK) {
        /* pass 2: gather IDAT payloads (a single chunk is used in place) */
        if (nidat == 1) {
            zsrc = buf + first_idat + 8;
        } else {
            size_t q = first_idat, zo = 0;
            z = (uint8_t *)tn__alloc(idat_total);
            if (!z) st = TN_ERR_OUT_OF_MEMORY;
            while (st == TN_OK && zo < idat_total) {
                uint32_t len = tn__png_be32(buf + q);
                memcpy(z + zo, buf + q + 8, len);
                zo += len;
                q += (size_t)len + 12;
            }
            zsrc = z;
        }
        if (st == TN_OK) st = tn__png_pixels(p, zsrc, idat_total, img);
    }
    if (st == TN_OK && info) {
        memset(info, 0, sizeof *info);
        info->format = TN_FORMAT_PNG;
        info->bit_depth = p->depth;
        info->file_channels = p->spp;
        info->interlaced = p->interlace;
        info->has_range = p->has_range;
        info->range_lo = p->has_range ? p->lo : 0.0;
        info->range_hi = p->has_range ? p->hi : 0.0;
    }
    TN_FREE(z);
    TN_FREE(p);
    return st;
}

/* ---- PNG encode ---- */

/* |v| of a byte read as signed: min(v, 256 - v), branch-free. */
#define TN__PNG_ABS8(v) ((v) < 256u - (v) ? (v) : 256u - (v))

/* Filters row (prev = previous raw row, all zeros for the first) with each of the 5 filters
   into cand (5 x n bytes) and returns the type with the smallest sum of |filtered byte as
   signed| (the usual estimate of how well a row compresses). The first bpp bytes are done apart
   so the main loop has no conditions. */
static int tn__png_pick_filter(const uint8_t *row, const uint8_t *prev, size_t n, size_t bpp, uint8_t *cand)
{
    size_t i, cost[5] = {0, 0, 0, 0, 0};
    int f, best = 0;
    uint8_t *c0 = cand, *c1 = cand + n, *c2 = cand + 2 * n, *c3 = cand + 3 * n, *c4 = cand + 4 * n;
    for (i = 0; i < bpp && i < n; i++) {
        c0[i] = c1[i] = row[i];
        c2[i] = c4[i] = (uint8_t)(row[i] - prev[i]);
        c3[i] = (uint8_t)(row[i] - (prev[i] >> 1));
    }
    for (; i < n; i++) {
        int a = row[i - bpp], b = prev[i], c = prev[i - bpp];
        int pa = abs(b - c), pb = abs(a - c), pc = abs(a + b - 2 * c);
        int bcs = pb <= pc ? b : c, not_a = (pa > pb) | (pa > pc);
        c0[i] = row[i];
        c1[i] = (uint8_t)(row[i] - a);
        c2[i] = (uint8_t)(row[i] - b);
        c3[i] = (uint8_t)(row[i] - ((a + b) >> 1));
        c4[i] = (uint8_t)(row[i] - (not_a ? bcs : a));
    }
    for (i = 0; i < n; i++) { /* five independent sums: no single add chain */
        uint32_t v0 = c0[i], v1 = c1[i], v2 = c2[i], v3 = c3[i], v4 = c4[i];
        cost[0] += TN__PNG_ABS8(v0);
        cost[1] += TN__PNG_ABS8(v1);
        cost[2] += TN__PNG_ABS8(v2);
        cost[3] += TN__PNG_ABS8(v3);
        cost[4] += TN__PNG_ABS8(v4);
    }
    for (f = 1; f < 5; f++)
        if (cost[f] < cost[best]) best = f;
    return best;
}

static void tn__png_put_chunk(uint8_t *o, const char *type, const uint8_t *data, uint32_t len)
{
    tn__png_put_be32(o, len);
    memcpy(o + 4, type, 4);
    if (len) memcpy(o + 8, data, len);
    tn__png_put_be32(o + 8 + len, tn__crc32(0, o + 4, (size_t)len + 4));
}

#define TN__PNG_IDAT_MAX ((size_t)1 << 20)

/* Encodes img (1-4 channels: grey, grey+alpha, RGB, RGBA) as an 8- or 16-bit PNG with codes
   round(clamp((v - lo) / (hi - lo), 0, 1) * max) (NaN -> 0); record_range writes tEXt
   "terrainnet.range" = "<lo> <hi>" (shortest round-trip text) so decoding restores v exactly up to quantisation. level
   0-9 (0 = 6). *out is TN_MALLOC'ed (caller frees with TN_FREE). Fails with TN_ERR_INVALID_ARG
   on bad image/depth/range. */
static tn_status tn__png_encode(const tn_image *img, int bit_depth, double lo, double hi, int record_range,
                                int level, uint8_t **out, size_t *out_size)
{
    static const uint8_t ctypes[5] = {0, 0, 4, 2, 6};
    size_t w, h, ch, bps, bpp, rowbytes, fsize, x, zn = 0, total, nchunks, o, i;
    uint8_t *filt = NULL, *rows = NULL, *z = NULL, *buf = NULL, ihdr[13];
    char text[96];
    size_t tlen = 0;
    double maxcode = bit_depth == 16 ? 65535.0 : 255.0, scale;
    tn_status st = TN_OK;
    uint32_t y;
    *out = NULL;
    *out_size = 0;
    if (!img || !img->data || img->width <= 0 || img->height <= 0 || img->channels < 1 || img->channels > 4)
        return tn__fail(TN_ERR_INVALID_ARG, "png: cannot encode an image of %d x %d x %d", img ? img->width : 0,
                        img ? img->height : 0, img ? img->channels : 0);
    if (bit_depth != 8 && bit_depth != 16) return tn__fail(TN_ERR_INVALID_ARG, "png: bit depth %d is not 8 or 16", bit_depth);
    if (!(lo - lo == 0) || !(hi - hi == 0) || lo == hi)
        return tn__fail(TN_ERR_INVALID_ARG, "png: value range [%g, %g] is not usable", lo, hi);
    w = (size_t)img->width;
    h = (size_t)img->height;
    ch = (size_t)img->channels;
    bps = (size_t)bit_depth / 8;
    bpp = ch * bps;
    if ((st = tn__size4(w, bpp, 1, 1, &rowbytes)) != TN_OK) return st;
    if ((st = tn__size4(h, rowbytes + 1, 1, 1, &fsize)) != TN_OK) return st;
    filt = (uint8_t *)tn__alloc(fsize);
    rows = (uint8_t *)tn__calloc(rowbytes * 8); /* current, previous, 5 candidates, zero row */
    if (!filt || !rows) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    scale = maxcode / (hi - lo);
    for (y = 0; y < (uint32_t)h; y++) {
        uint8_t *cur = rows + (y & 1u) * rowbytes, *prev = y ? rows + ((y + 1) & 1u) * rowbytes : rows + 7 * rowbytes;
        const float *src = img->data + (size_t)y * w * ch;
        int f;
        for (x = 0; x < w * ch; x++) {
            double t = ((double)src[x] - lo) * scale;
            unsigned code;
            if (!(t > 0.0)) t = 0.0; /* also NaN */
            if (t > maxcode) t = maxcode;
            code = (unsigned)(t + 0.5);
            if (bps == 2) {
                cur[2 * x] = (uint8_t)(code >> 8);
                cur[2 * x + 1] = (uint8_t)code;
            } else {
                cur[x] = (uint8_t)code;
            }
        }
        f = tn__png_pick_filter(cur, prev, rowbytes, bpp, rows + 2 * rowbytes);
        filt[(size_t)y * (rowbytes + 1)] = (uint8_t)f;
        memcpy(filt + (size_t)y * (rowbytes + 1) + 1, rows + (2 + (size_t)f) * rowbytes, rowbytes);
    }
    if ((st = tn_zlib_deflate(filt, fsize, level, &z, &zn)) != TN_OK) goto done;
    if (record_range) {
        memcpy(text, "terrainnet.range", 17);
        /* shortest round-trip text with '.', whatever the C locale (the reader is locale-free too) */
        size_t a = (size_t)tn__io_format_number(text + 17, 32, lo, 0);
        text[17 + a] = ' ';
        tlen = 18 + a + (size_t)tn__io_format_number(text + 18 + a, 32, hi, 0);
    }
    nchunks = zn ? (zn + TN__PNG_IDAT_MAX - 1) / TN__PNG_IDAT_MAX : 1;
    total = 8 + 25 + (tlen ? 12 + tlen : 0) + nchunks * 12 + zn + 12;
    buf = (uint8_t *)tn__alloc(total);
    if (!buf) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    memcpy(buf, tn__png_sig, 8);
    tn__png_put_be32(ihdr, (uint32_t)w);
    tn__png_put_be32(ihdr + 4, (uint32_t)h);
    ihdr[8] = (uint8_t)bit_depth;
    ihdr[9] = ctypes[ch];
    ihdr[10] = ihdr[11] = ihdr[12] = 0;
    tn__png_put_chunk(buf + 8, "IHDR", ihdr, 13);
    o = 8 + 25;
    if (tlen) {
        tn__png_put_chunk(buf + o, "tEXt", (const uint8_t *)text, (uint32_t)tlen);
        o += 12 + tlen;
    }
    for (i = 0; i < nchunks; i++) {
        size_t c = zn - i * TN__PNG_IDAT_MAX;
        if (c > TN__PNG_IDAT_MAX) c = TN__PNG_IDAT_MAX;
        tn__png_put_chunk(buf + o, "IDAT", z + i * TN__PNG_IDAT_MAX, (uint32_t)c);
        o += 12 + c;
    }
    tn__png_put_chunk(buf + o, "IEND", NULL, 0);
    o += 12;
    *out = buf;
    *out_size = o;
done:
    TN_FREE(filt);
    TN_FREE(rows);
    TN_FREE(z);
    return st;
}

/* --------------------------------------------------------------------------------------------
   >>formats  (part of @@io implementation; goes after >>png, whose tn__png_decode/encode it calls)
   Everything in @@io but the PNG codec: format detection (magic bytes, then extension), reading
   a whole file with one fread, saving through "<path>.tmp.<pid>.<n>" + rename() so a failed save
   never clobbers the old file, the integer-format value mapping shared with PNG, and the codecs
   for PGM/PPM (P2 P3 P5 P6), PFM, SRTM .hgt, ESRI ASCII grid .asc and headerless .r16.
   Every parser works on one memory buffer with explicit bounds: sizes go through tn__size4
   (TN_ERR_TOO_LARGE) and are checked against the bytes actually present (TN_ERR_CORRUPT)
   before anything is allocated. Text is parsed without strtod/locale.
   NaN/Inf: refused on save (TN_ERR_NUMERIC); PFM files holding them fail to load with
   TN_ERR_NUMERIC because terrain code downstream cannot use them; in .asc a "nan"/"inf" value
   is treated like NODATA.
   Voids (.hgt -32768, .asc NODATA) are filled in two steps: onion peeling, ring by ring from
   the known cells (each void cell next to known ones takes the mean of its known 8-neighbours,
   weights 1 orthogonal, 1/2 diagonal; order-independent), then SOR sweeps of the 4-neighbour
   Laplace equation over the filled cells, so holes get the smooth harmonic surface spanning
   their rim (a plane is reproduced). info->voids_filled counts the cells; a grid with no
   valid cell fails with TN_ERR_EMPTY. Single-threaded and deterministic.
   -------------------------------------------------------------------------------------------- */

TN_API const char *tn_format_name(tn_format f)
{
    switch (f) {
    case TN_FORMAT_AUTO: return "auto";
    case TN_FORMAT_PNG: return "png";
    case TN_FORMAT_PNM: return "pnm";
    case TN_FORMAT_PFM: return "pfm";
    case TN_FORMAT_HGT: return "hgt";
    case TN_FORMAT_ASC: return "asc";
    case TN_FORMAT_R16: return "r16";
    }
    return "unknown";
}

TN_API void tn_free(void *p) { TN_FREE(p); }

/* ---- small text helpers (no <ctype.h>, no locale) ---- */

static int tn__io_space(int c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f'; }
static int tn__io_digit(int c) { return c >= '0' && c <= '9'; }
static int tn__io_lower(int c) { return c >= 'A' && c <= 'Z' ? c + ('a' - 'A') : c; }

/* Case-insensitive: is the n-byte token t equal to word? */
static int tn__io_token_is(const char *t, size_t n, const char *word)
{
    size_t i;
    for (i = 0; i < n; i++)
        if (!word[i] || tn__io_lower((unsigned char)t[i]) != tn__io_lower((unsigned char)word[i])) return 0;
    return word[n] == 0;
}

/* Next whitespace-separated token of p[*i..n): sets *tb (start) and *tl (length), advances *i.
   Returns 0 at the end of the buffer. */
static int tn__io_token(const uint8_t *p, size_t n, size_t *i, size_t *tb, size_t *tl)
{
    size_t k = *i;
    while (k < n && tn__io_space(p[k])) k++;
    if (k >= n) { *i = k; return 0; }
    *tb = k;
    while (k < n && !tn__io_space(p[k])) k++;
    *tl = k - *tb;
    *i = k;
    return 1;
}

/* Parses a whole token as a decimal number ("-12.5e3", "nan", "inf"); returns 0 if it is not
   one. Own parser because strtod follows the locale ("1,5") and needs a NUL-terminated string. */
static int tn__io_number(const char *s, size_t n, double *out)
{
    size_t i = 0;
    int neg = 0, digits = 0, exp10 = 0, e = 0, eneg = 0, edigits = 0;
    uint64_t m = 0;
    double v;
    if (n == 0 || n > 400) return 0;
    if (s[i] == '+' || s[i] == '-') neg = s[i++] == '-';
    if (tn__io_token_is(s + i, n - i, "nan")) { *out = neg ? -NAN : NAN; return 1; }
    if (tn__io_token_is(s + i, n - i, "inf") || tn__io_token_is(s + i, n - i, "infinity")) {
        *out = neg ? -HUGE_VAL : HUGE_VAL;
        return 1;
    }
    for (; i < n && tn__io_digit(s[i]); i++, digits++) {
        if (m < 100000000000000000ULL) m = m * 10 + (uint64_t)(s[i] - '0');
        else exp10++; /* digits beyond 17 only scale */
    }
    if (i < n && s[i] == '.')
        for (i++; i < n && tn__io_digit(s[i]); i++, digits++)
            if (m < 100000000000000000ULL) { m = m * 10 + (uint64_t)(s[i] - '0'); exp10--; }
    if (!digits) return 0;
    if (i < n && (s[i] == 'e' || s[i] == 'E')) {
        i++;
        if (i < n && (s[i] == '+' || s[i] == '-')) eneg = s[i++] == '-';
        for (; i < n && tn__io_digit(s[i]); i++, edigits++)
            if (e < 100000) e = e * 10 + (s[i] - '0');
        if (!edigits) return 0;
        exp10 += eneg ? -e : e;
    }
    if (i != n) return 0;
    if (m == 0 || exp10 < -400) v = 0.0;
    else if (exp10 > 400) v = HUGE_VAL;
    else if (exp10 >= 0) v = (double)m * pow(10.0, exp10);
    else v = (double)m / pow(10.0, -exp10); /* 10^k is exact up to 22: one rounding */
    *out = neg ? -v : v;
    return 1;
}

/* Writes the shortest "%.*g" text of v that reads back as v (as a float if as_float), with '.'
   as the decimal point whatever the locale. Returns the length. */
static int tn__io_format_number(char *buf, size_t cap, double v, int as_float)
{
    int prec, len = 0, k;
    for (prec = as_float ? 6 : 15; prec <= 17; prec++) {
        double back = 0;
        len = snprintf(buf, cap, "%.*g", prec, v);
        if (len < 0 || (size_t)len >= cap) return 0;
        for (k = 0; k < len; k++)
            if (buf[k] == ',') buf[k] = '.';
        if (tn__io_number(buf, (size_t)len, &back) &&
            (as_float ? (float)back == (float)v : back == v)) break;
    }
    return len;
}

/* ---- byte order ---- */

static unsigned tn__io_be16(const uint8_t *p) { return ((unsigned)p[0] << 8) | p[1]; }
static unsigned tn__io_le16(const uint8_t *p) { return p[0] | ((unsigned)p[1] << 8); }

static float tn__io_f32(const uint8_t *p, int little)
{
    uint32_t u = little ? (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24)
                        : (uint32_t)p[3] | ((uint32_t)p[2] << 8) | ((uint32_t)p[1] << 16) | ((uint32_t)p[0] << 24);
    float f;
    memcpy(&f, &u, 4);
    return f;
}

static void tn__io_put_f32le(uint8_t *p, float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    p[0] = (uint8_t)u; p[1] = (uint8_t)(u >> 8); p[2] = (uint8_t)(u >> 16); p[3] = (uint8_t)(u >> 24);
}

static int tn__io_finite(float v) { return v == v && v <= FLT_MAX && v >= -FLT_MAX; }

/* ---- integer code mapping (shared by PNG, PNM, R16) ---- */

/* Chooses how img maps to integer codes 0..max on save: [*lo, *hi] and whether to record it.
   opts->has_range: that range, recorded. Otherwise data inside [0, 1] is written as is (0..1,
   not recorded) and anything else is mapped from its own min..max and recorded. The image must
   already be free of NaN/Inf. */
static tn_status tn__io_save_mapping(const tn_image *img, const tn_save_opts *opts, double *lo, double *hi, int *record)
{
    float mn, mx;
    if (opts->has_range) {
        double a = opts->range_lo, b = opts->range_hi;
        /* beyond float the file could not be read back (tn_image stores floats) */
        if (!(a == a && b == b && fabs(a) <= FLT_MAX && fabs(b) <= FLT_MAX) || a == b)
            return tn__fail(TN_ERR_INVALID_ARG, "save range [%g, %g] is empty, not finite or beyond float", a, b);
        *lo = a;
        *hi = b;
        *record = 1;
        return TN_OK;
    }
    tn_image_range(img, &mn, &mx);
    if (mn >= 0.0f && mx <= 1.0f) {
        *lo = 0.0;
        *hi = 1.0;
        *record = 0;
        return TN_OK;
    }
    *lo = mn;
    *hi = mx;
    if (*hi == *lo) *hi = *lo + 1.0; /* a constant image: every code is 0 -> lo */
    if (*hi == *lo) *hi = *lo + fabs(*lo) * 1e-6;
    *record = 1;
    return TN_OK;
}

/* round(clamp((v - lo) / (hi - lo), 0, 1) * maxcode), with scale = maxcode / (hi - lo). */
static unsigned tn__io_code(float v, double lo, double scale, unsigned maxcode)
{
    double t = ((double)v - lo) * scale;
    if (!(t > 0.0)) return 0;
    if (t >= (double)maxcode) return maxcode;
    return (unsigned)(t + 0.5);
}

/* Inverse of tn__io_code on load: code/max, or lo..hi when the file records a range. */
static float tn__io_uncode(unsigned code, unsigned maxcode, int has_range, double lo, double hi)
{
    if (!has_range) return (float)code / (float)maxcode;
    return (float)(lo + (hi - lo) * ((double)code / (double)maxcode));
}

/* ---- void filling (.hgt, .asc) ---- */

/* Fills the cells of a w x h grid whose mask byte is 1 (see the banner); mask is scratch.
   *filled gets the number of void cells. */
static tn_status tn__io_fill_voids(float *z, uint8_t *mask, size_t w, size_t h, const char *name, size_t *filled)
{
    static const int ox[8] = {-1, 0, 1, -1, 1, -1, 0, 1}, oy[8] = {-1, -1, -1, 0, 0, 1, 1, 1};
    size_t n = w * h, nv = 0, i, k, head, tail, bytes = 0, rings = 0;
    size_t *q;
    double omega, passes;
    int pass, d;
    *filled = 0;
    for (i = 0; i < n; i++) nv += mask[i] != 0;
    if (nv == 0) return TN_OK;
    if (nv == n) return tn__fail(TN_ERR_EMPTY, "%s: every cell is void / NODATA", name);
    if (tn__size4(nv, sizeof(size_t), 1, 1, &bytes)) return TN_ERR_TOO_LARGE;
    q = (size_t *)tn__alloc(bytes);
    if (!q) return TN_ERR_OUT_OF_MEMORY;
    /* mask: 0 known, 1 void not yet queued, 2 void queued; the first ring touches known cells */
    tail = 0;
    for (i = 0; i < n; i++) {
        size_t x = i % w, y = i / w;
        if (mask[i] != 1) continue;
        for (d = 0; d < 8; d++) {
            size_t xx = x + (size_t)(ptrdiff_t)ox[d], yy = y + (size_t)(ptrdiff_t)oy[d]; /* wraps past 0: caught by < */
            if (xx < w && yy < h && mask[yy * w + xx] == 0) { mask[i] = 2; q[tail++] = i; break; }
        }
    }
    for (head = 0; head < tail;) {
        size_t end = tail;
        for (k = head; k < end; k++) { /* reads only cells known before this ring */
            size_t c = q[k], x = c % w, y = c / w;
            double sum = 0.0, wsum = 0.0;
            for (d = 0; d < 8; d++) {
                size_t xx = x + (size_t)(ptrdiff_t)ox[d], yy = y + (size_t)(ptrdiff_t)oy[d];
                if (xx < w && yy < h && mask[yy * w + xx] == 0) {
                    double wt = (ox[d] && oy[d]) ? 0.5 : 1.0;
                    sum += wt * z[yy * w + xx];
                    wsum += wt;
                }
            }
            z[c] = (float)(sum / wsum);
        }
        for (k = head; k < end; k++) mask[q[k]] = 0;
        for (k = head; k < end; k++) {
            size_t c = q[k], x = c % w, y = c / w;
            for (d = 0; d < 8; d++) {
                size_t xx = x + (size_t)(ptrdiff_t)ox[d], yy = y + (size_t)(ptrdiff_t)oy[d];
                if (xx < w && yy < h && mask[yy * w + xx] == 1) { mask[yy * w + xx] = 2; q[tail++] = yy * w + xx; }
            }
        }
        head = end;
        rings++;
    }
    /* SOR with the optimal factor for a hole about 2*rings+1 cells wide; passes grow with the
       hole size, capped at about 2e8 cell updates. mask now holds each void cell's in-image
       4-neighbours (bits left, right, up, down) so the sweeps need no divisions. Sweeping in
       ring order (rim inwards) converged faster than memory order in tests. */
    for (k = 0; k < tail; k++) {
        size_t c = q[k], x = c % w, y = c / w;
        mask[c] = (uint8_t)((x > 0) | ((x + 1 < w) << 1) | ((y > 0) << 2) | ((y + 1 < h) << 3));
    }
    omega = 2.0 / (1.0 + sin(3.141592653589793 / (2.0 * (double)rings + 2.0)));
    if (omega > 1.95) omega = 1.95;
    passes = 32.0 + 4.0 * (double)rings;
    if (passes * (double)nv > 2e8) passes = 2e8 / (double)nv;
    if (passes < 16) passes = 16;
    for (pass = 0; pass < (int)passes; pass++) {
        double change = 0.0, scale = 0.0;
        for (k = 0; k < tail; k++) {
            size_t c = q[k];
            int m = mask[c];
            double sum, old = z[c], avg;
            if (m == 15) avg = 0.25 * ((double)z[c - 1] + z[c + 1] + z[c - w] + z[c + w]);
            else {
                int cnt = 0;
                sum = 0.0;
                if (m & 1) { sum += z[c - 1]; cnt++; }
                if (m & 2) { sum += z[c + 1]; cnt++; }
                if (m & 4) { sum += z[c - w]; cnt++; }
                if (m & 8) { sum += z[c + w]; cnt++; }
                if (!cnt) continue; /* a 1x1 grid */
                avg = sum / cnt;
            }
            z[c] = (float)(old + omega * (avg - old));
            if (fabs(z[c] - old) > change) change = fabs(z[c] - old);
            if (fabs(old) > scale) scale = fabs(old);
        }
        if (change <= 1e-6 * scale) break;
    }
    TN_FREE(q);
    *filled = nv;
    return TN_OK;
}

/* ---- PGM / PPM ---- */

/* Parses a "# terrainnet.range <lo> <hi>" comment body; other comments are ignored. */
static void tn__pnm_comment(const uint8_t *p, size_t n, int *has_range, double *lo, double *hi)
{
    size_t i = 0, tb, tl;
    double a, b;
    if (!tn__io_token(p, n, &i, &tb, &tl) || !tn__io_token_is((const char *)p + tb, tl, "terrainnet.range")) return;
    if (!tn__io_token(p, n, &i, &tb, &tl) || !tn__io_number((const char *)p + tb, tl, &a)) return;
    if (!tn__io_token(p, n, &i, &tb, &tl) || !tn__io_number((const char *)p + tb, tl, &b)) return;
    if (tn__io_token(p, n, &i, &tb, &tl)) return;
    if (a != a || b != b || a == b) return; /* malformed: just a comment */
    *has_range = fabs(a) <= FLT_MAX && fabs(b) <= FLT_MAX ? 1 : -1; /* -1: beyond float, refused */
    *lo = a;
    *hi = b;
}

/* Skips whitespace and (when allowed) '#' comments, noting a range comment. */
static void tn__pnm_skip(const uint8_t *p, size_t n, size_t *i, int comments, int *has_range, double *lo, double *hi)
{
    size_t k = *i;
    for (;;) {
        while (k < n && tn__io_space(p[k])) k++;
        if (comments && k < n && p[k] == '#') {
            size_t b = ++k;
            while (k < n && p[k] != '\n' && p[k] != '\r') k++;
            tn__pnm_comment(p + b, k - b, has_range, lo, hi);
            continue;
        }
        break;
    }
    *i = k;
}

/* Unsigned decimal at p[*i]; 1 ok, 0 not a number, -1 larger than max. */
static int tn__pnm_uint(const uint8_t *p, size_t n, size_t *i, unsigned long max, unsigned long *v)
{
    size_t k = *i;
    unsigned long x = 0;
    int over = 0;
    if (k >= n || !tn__io_digit(p[k])) return 0;
    for (; k < n && tn__io_digit(p[k]); k++) {
        unsigned d = (unsigned)(p[k] - '0');
        if (x > (max - d) / 10) over = 1;
        else x = x * 10 + d;
    }
    if (k < n && !tn__io_space(p[k]) && p[k] != '#') return 0; /* "12x" */
    *i = k;
    *v = x;
    return over ? -1 : 1;
}

static int tn__pnm_bits(unsigned long maxval)
{
    int b = 1;
    while (((1ul << b) - 1) < maxval) b++;
    return b;
}

static tn_status tn__pnm_decode(const uint8_t *p, size_t n, const char *name, tn_image *img, tn_image_info *info)
{
    unsigned long dim[3] = {0, 0, 0};
    static const char *const what[3] = {"width", "height", "maxval"};
    size_t i = 2, count, bytes = 0, k, bps, rem;
    int kind, ch, has_range = 0, r, j;
    double lo = 0.0, hi = 0.0;
    tn_status st;
    if (n < 2 || p[0] != 'P') return tn__fail(TN_ERR_FORMAT, "%s: not a PGM/PPM file", name);
    kind = p[1] - '0';
    if (kind == 1 || kind == 4 || kind == 7)
        return tn__fail(TN_ERR_FORMAT, "%s: P%d (PBM bitmap / PAM) is not supported; use P2/P3/P5/P6", name, kind);
    if (kind != 2 && kind != 3 && kind != 5 && kind != 6) return tn__fail(TN_ERR_FORMAT, "%s: not a PGM/PPM file", name);
    if (n > 2 && !tn__io_space(p[2]) && p[2] != '#') return tn__fail(TN_ERR_FORMAT, "%s: not a PGM/PPM file", name);
    ch = (kind == 3 || kind == 6) ? 3 : 1;
    for (j = 0; j < 3; j++) {
        tn__pnm_skip(p, n, &i, 1, &has_range, &lo, &hi);
        r = tn__pnm_uint(p, n, &i, j < 2 ? (unsigned long)INT_MAX : 65535ul, &dim[j]);
        if (r == 0) {
            if (i >= n) return tn__fail(TN_ERR_CORRUPT, "%s: truncated PNM header (no %s)", name, what[j]);
            return tn__fail(TN_ERR_CORRUPT, "%s: bad PNM %s", name, what[j]);
        }
        if (r < 0 && j < 2) return tn__fail(TN_ERR_TOO_LARGE, "%s: PNM %s too large", name, what[j]);
        if (r < 0 || dim[j] == 0)
            return tn__fail(j < 2 ? TN_ERR_CORRUPT : TN_ERR_FORMAT, "%s: PNM %s %s is not supported (1..%s)", name,
                            what[j], r < 0 ? "> 65535" : "0", j < 2 ? "2^31-1" : "65535");
    }
    if (tn__size4(dim[0], dim[1], (size_t)ch, sizeof(float), &bytes)) return tn__fail_context(TN_ERR_TOO_LARGE, name);
    if (has_range < 0) return tn__fail(TN_ERR_NUMERIC, "%s: terrainnet.range [%g, %g] is beyond float range", name, lo, hi);
    count = (size_t)dim[0] * dim[1] * (size_t)ch;
    bps = dim[2] > 255 ? 2 : 1;
    if (kind >= 5) { /* exactly one whitespace byte, then raw samples */
        if (i >= n) return tn__fail(TN_ERR_CORRUPT, "%s: truncated PNM (no pixel data)", name);
        if (!tn__io_space(p[i])) return tn__fail(TN_ERR_CORRUPT, "%s: no whitespace after the PNM maxval", name);
        i++;
        rem = n - i;
        if (rem / bps < count)
            return tn__fail(TN_ERR_CORRUPT, "%s: truncated PNM: %zu of %zu data bytes", name, rem, count * bps);
    } else {
        tn__pnm_skip(p, n, &i, 1, &has_range, &lo, &hi);
        rem = n - i;
        if (count > rem / 2 + 1) /* every sample needs a digit and all but the last a separator */
            return tn__fail(TN_ERR_CORRUPT, "%s: truncated PNM: %zu samples cannot fit in %zu bytes", name, count, rem);
    }
    st = tn_image_create(img, (int)dim[0], (int)dim[1], ch);
    if (st) return tn__fail_context(st, name);
    for (k = 0; k < count; k++) {
        unsigned long c;
        if (kind >= 5) {
            c = bps == 2 ? tn__io_be16(p + i + 2 * k) : p[i + k];
        } else {
            tn__pnm_skip(p, n, &i, 1, &has_range, &lo, &hi);
            r = tn__pnm_uint(p, n, &i, 65535ul, &c);
            if (r == 0) {
                tn_image_free(img);
                if (i >= n) return tn__fail(TN_ERR_CORRUPT, "%s: truncated PNM: %zu of %zu samples", name, k, count);
                return tn__fail(TN_ERR_CORRUPT, "%s: bad PNM sample %zu", name, k);
            }
            if (r < 0) c = 65536ul;
        }
        if (c > dim[2]) {
            tn_image_free(img);
            return tn__fail(TN_ERR_CORRUPT, "%s: PNM sample %zu exceeds maxval %lu", name, k, dim[2]);
        }
        img->data[k] = (float)c; /* converted below, once the range comment (if any) is known */
    }
    if (has_range < 0) { /* a range comment among the samples */
        tn_image_free(img);
        return tn__fail(TN_ERR_NUMERIC, "%s: terrainnet.range [%g, %g] is beyond float range", name, lo, hi);
    }
    for (k = 0; k < count; k++)
        img->data[k] = tn__io_uncode((unsigned)img->data[k], (unsigned)dim[2], has_range, lo, hi);
    info->bit_depth = tn__pnm_bits(dim[2]);
    info->file_channels = ch;
    info->has_range = has_range;
    info->range_lo = has_range ? lo : 0.0;
    info->range_hi = has_range ? hi : 0.0;
    return TN_OK;
}

/* Writes binary P5 (1 channel) or P6 (3 channels), 8 or 16 bits big-endian. */
static tn_status tn__pnm_encode(const tn_image *img, int bits, double lo, double hi, int record, uint8_t **out,
                                size_t *out_size)
{
    char hdr[256], a[40], b[40];
    size_t count, data = 0, total, k;
    unsigned maxc = bits == 16 ? 65535u : 255u;
    double scale = (double)maxc / (hi - lo);
    int len;
    uint8_t *buf, *d;
    tn_status st;
    if (img->channels != 1 && img->channels != 3)
        return tn__fail(TN_ERR_SHAPE, "PGM/PPM stores 1 or 3 channels, not %d", img->channels);
    if (record) {
        tn__io_format_number(a, sizeof a, lo, 0);
        tn__io_format_number(b, sizeof b, hi, 0);
        len = snprintf(hdr, sizeof hdr, "P%d\n# terrainnet.range %s %s\n%d %d\n%u\n", img->channels == 1 ? 5 : 6, a, b,
                       img->width, img->height, maxc);
    } else {
        len = snprintf(hdr, sizeof hdr, "P%d\n%d %d\n%u\n", img->channels == 1 ? 5 : 6, img->width, img->height, maxc);
    }
    st = tn__size4((size_t)img->width, (size_t)img->height, (size_t)img->channels, (size_t)bits / 8, &data);
    if (st) return st;
    count = data / ((size_t)bits / 8);
    total = (size_t)len + data;
    buf = (uint8_t *)tn__alloc(total);
    if (!buf) return TN_ERR_OUT_OF_MEMORY;
    memcpy(buf, hdr, (size_t)len);
    d = buf + len;
    for (k = 0; k < count; k++) {
        unsigned c = tn__io_code(img->data[k], lo, scale, maxc);
        if (bits == 16) { d[2 * k] = (uint8_t)(c >> 8); d[2 * k + 1] = (uint8_t)c; }
        else d[k] = (uint8_t)c;
    }
    *out = buf;
    *out_size = total;
    return TN_OK;
}

/* ---- PFM ---- */

static tn_status tn__pfm_decode(const uint8_t *p, size_t n, const char *name, tn_image *img, tn_image_info *info)
{
    unsigned long w = 0, h = 0;
    size_t i = 2, tb, tl, bytes = 0, need, row, x, bad = 0;
    int ch, r, little, dummy = 0;
    double scale = 0.0, dlo, dhi;
    tn_status st;
    if (n < 2 || p[0] != 'P' || (p[1] != 'F' && p[1] != 'f')) return tn__fail(TN_ERR_FORMAT, "%s: not a PFM file", name);
    ch = p[1] == 'F' ? 3 : 1;
    tn__pnm_skip(p, n, &i, 0, &dummy, &dlo, &dhi);
    r = tn__pnm_uint(p, n, &i, (unsigned long)INT_MAX, &w);
    if (r > 0) {
        tn__pnm_skip(p, n, &i, 0, &dummy, &dlo, &dhi);
        r = tn__pnm_uint(p, n, &i, (unsigned long)INT_MAX, &h);
    }
    if (r < 0) return tn__fail(TN_ERR_TOO_LARGE, "%s: PFM size too large", name);
    if (r == 0) return tn__fail(TN_ERR_CORRUPT, "%s: %s PFM size", name, i >= n ? "truncated header: no" : "bad");
    if (w == 0 || h == 0) return tn__fail(TN_ERR_CORRUPT, "%s: PFM size %lu x %lu is empty", name, w, h);
    if (!tn__io_token(p, n, &i, &tb, &tl)) return tn__fail(TN_ERR_CORRUPT, "%s: truncated PFM header (no scale)", name);
    if (!tn__io_number((const char *)p + tb, tl, &scale) || scale == 0.0 || scale != scale || fabs(scale) > DBL_MAX)
        return tn__fail(TN_ERR_CORRUPT, "%s: bad PFM scale", name);
    little = scale < 0.0; /* the sign of the scale gives the byte order */
    if (tn__size4(w, h, (size_t)ch, sizeof(float), &bytes)) return tn__fail_context(TN_ERR_TOO_LARGE, name);
    if (i >= n || !tn__io_space(p[i])) return tn__fail(TN_ERR_CORRUPT, "%s: truncated PFM (no pixel data)", name);
    i++;
    need = bytes; /* 4 bytes per sample in the file too */
    if (n - i < need) return tn__fail(TN_ERR_CORRUPT, "%s: truncated PFM: %zu of %zu data bytes", name, n - i, need);
    st = tn_image_create(img, (int)w, (int)h, ch);
    if (st) return tn__fail_context(st, name);
    for (row = 0; row < h; row++) { /* rows are stored bottom to top */
        const uint8_t *src = p + i + row * w * (size_t)ch * 4;
        float *dst = img->data + (h - 1 - row) * w * (size_t)ch;
        for (x = 0; x < w * (size_t)ch; x++) {
            float v = tn__io_f32(src + 4 * x, little);
            bad += !tn__io_finite(v);
            dst[x] = v;
        }
    }
    if (bad) {
        tn_image_free(img);
        return tn__fail(TN_ERR_NUMERIC, "%s: %zu NaN/Inf samples in the PFM (terrain code cannot use them)", name, bad);
    }
    info->bit_depth = 32;
    info->file_channels = ch;
    return TN_OK;
}

/* Writes little-endian PFM (scale -1), bottom row first. */
static tn_status tn__pfm_encode(const tn_image *img, uint8_t **out, size_t *out_size)
{
    char hdr[64];
    size_t data = 0, row, x, w = (size_t)img->width, h = (size_t)img->height, ch = (size_t)img->channels;
    int len;
    uint8_t *buf;
    tn_status st;
    if (img->channels != 1 && img->channels != 3)
        return tn__fail(TN_ERR_SHAPE, "PFM stores 1 or 3 channels, not %d", img->channels);
    len = snprintf(hdr, sizeof hdr, "P%c\n%d %d\n-1.0\n", ch == 3 ? 'F' : 'f', img->width, img->height);
    st = tn__size4(w, h, ch, 4, &data);
    if (st) return st;
    buf = (uint8_t *)tn__alloc((size_t)len + data);
    if (!buf) return TN_ERR_OUT_OF_MEMORY;
    memcpy(buf, hdr, (size_t)len);
    for (row = 0; row < h; row++) {
        uint8_t *dst = buf + len + row * w * ch * 4;
        const float *src = img->data + (h - 1 - row) * w * ch;
        for (x = 0; x < w * ch; x++) tn__io_put_f32le(dst + 4 * x, src[x]);
    }
    *out = buf;
    *out_size = (size_t)len + data;
    return TN_OK;
}

/* ---- SRTM .hgt ---- */

static tn_status tn__hgt_decode(const uint8_t *p, size_t n, const char *name, tn_image *img, tn_image_info *info)
{
    size_t side, count, k, nvoid = 0;
    uint8_t *mask;
    tn_status st;
    if (n == (size_t)1201 * 1201 * 2) side = 1201;
    else if (n == (size_t)3601 * 3601 * 2) side = 3601;
    else
        return tn__fail(TN_ERR_CORRUPT, "%s: %zu bytes is not an SRTM tile (1201^2 or 3601^2 int16 = %zu or %zu bytes)",
                        name, n, (size_t)1201 * 1201 * 2, (size_t)3601 * 3601 * 2);
    count = side * side;
    mask = (uint8_t *)tn__calloc(count);
    if (!mask) return tn__fail_context(TN_ERR_OUT_OF_MEMORY, name);
    st = tn_image_create(img, (int)side, (int)side, 1);
    if (st) { TN_FREE(mask); return tn__fail_context(st, name); }
    for (k = 0; k < count; k++) {
        unsigned u = tn__io_be16(p + 2 * k);
        int v = u >= 32768u ? (int)u - 65536 : (int)u;
        if (v == -32768) { mask[k] = 1; nvoid++; }
        else img->data[k] = (float)v;
    }
    st = nvoid ? tn__io_fill_voids(img->data, mask, side, side, name, &info->voids_filled) : TN_OK;
    TN_FREE(mask);
    if (st) { tn_image_free(img); return st; }
    info->bit_depth = 16;
    info->file_channels = 1;
    return TN_OK;
}

/* Writes metres rounded to int16, clamped to +-32767 (-32768 would read back as a void). */
static tn_status tn__hgt_encode(const tn_image *img, uint8_t **out, size_t *out_size)
{
    size_t count, k;
    uint8_t *buf;
    if (img->channels != 1 || img->width != img->height || (img->width != 1201 && img->width != 3601))
        return tn__fail(TN_ERR_SHAPE, ".hgt holds 1201x1201 or 3601x3601 single-channel grids, not %dx%dx%d",
                        img->width, img->height, img->channels);
    count = (size_t)img->width * (size_t)img->height;
    buf = (uint8_t *)tn__alloc(count * 2);
    if (!buf) return TN_ERR_OUT_OF_MEMORY;
    for (k = 0; k < count; k++) {
        double v = floor((double)img->data[k] + 0.5);
        int s = v < -32767.0 ? -32767 : (v > 32767.0 ? 32767 : (int)v);
        unsigned u = (unsigned)(s & 0xffff);
        buf[2 * k] = (uint8_t)(u >> 8);
        buf[2 * k + 1] = (uint8_t)u;
    }
    *out = buf;
    *out_size = count * 2;
    return TN_OK;
}

/* ---- ESRI ASCII grid .asc ---- */

/* Header keys, in the order of tn__asc_decode's switch. */
static const char *const tn__asc_keys[] = {"ncols", "nrows", "xllcorner", "xllcenter", "yllcorner",
                                            "yllcenter", "cellsize", "dx", "dy", "nodata_value"};
#define TN__ASC_NKEYS 10

static int tn__asc_key(const char *t, size_t n)
{
    int k;
    for (k = 0; k < TN__ASC_NKEYS; k++)
        if (tn__io_token_is(t, n, tn__asc_keys[k])) return k;
    return -1;
}

static tn_status tn__asc_decode(const uint8_t *p, size_t n, const char *name, tn_image *img, tn_image_info *info)
{
    double val[TN__ASC_NKEYS];
    int seen[TN__ASC_NKEYS] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
    size_t i = 0, tb, tl, bytes = 0, count, k, nvoid = 0, w, h;
    double cs;
    uint8_t *mask;
    tn_status st;
    memset(val, 0, sizeof val);
    for (;;) { /* "key value" pairs until the first number */
        size_t at = i;
        double v = 0.0;
        int key, ok;
        if (!tn__io_token(p, n, &i, &tb, &tl)) break;
        if (tn__io_number((const char *)p + tb, tl, &v)) { i = at; break; }
        key = tn__asc_key((const char *)p + tb, tl);
        if (key < 0)
            return tn__fail(TN_ERR_FORMAT, "%s: unknown .asc header key '%.*s'", name, (int)(tl > 32 ? 32 : tl),
                            (const char *)p + tb);
        ok = tn__io_token(p, n, &i, &tb, &tl) && tn__io_number((const char *)p + tb, tl, &v);
        if (ok && !(fabs(v) <= DBL_MAX) && !(key == 9 && v != v)) ok = 0; /* only NODATA_value may be nan */
        if (!ok) return tn__fail(TN_ERR_CORRUPT, "%s: missing or bad value for .asc key %s", name, tn__asc_keys[key]);
        val[key] = v;
        seen[key] = 1;
    }
    if (!seen[0] || !seen[1] || val[0] < 1 || val[1] < 1 || val[0] != floor(val[0]) || val[1] != floor(val[1]))
        return tn__fail(TN_ERR_CORRUPT, "%s: .asc header needs positive integer ncols and nrows", name);
    if (val[0] > INT_MAX || val[1] > INT_MAX) return tn__fail(TN_ERR_TOO_LARGE, "%s: .asc grid too large", name);
    w = (size_t)val[0];
    h = (size_t)val[1];
    if (tn__size4(w, h, 1, sizeof(float), &bytes)) return tn__fail_context(TN_ERR_TOO_LARGE, name);
    count = w * h;
    if (count > (n - i) / 2 + 1)
        return tn__fail(TN_ERR_CORRUPT, "%s: truncated .asc: %zu values cannot fit in %zu bytes", name, count, n - i);
    mask = (uint8_t *)tn__calloc(count);
    if (!mask) return tn__fail_context(TN_ERR_OUT_OF_MEMORY, name);
    st = tn_image_create(img, (int)w, (int)h, 1);
    if (st) { TN_FREE(mask); return tn__fail_context(st, name); }
    for (k = 0; k < count && st == TN_OK; k++) {
        double v = 0.0;
        if (!tn__io_token(p, n, &i, &tb, &tl))
            st = tn__fail(TN_ERR_CORRUPT, "%s: truncated .asc: %zu of %zu values", name, k, count);
        else if (!tn__io_number((const char *)p + tb, tl, &v))
            st = tn__fail(TN_ERR_CORRUPT, "%s: bad .asc value '%.*s' (value %zu)", name, (int)(tl > 32 ? 32 : tl),
                          (const char *)p + tb, k);
        else if (v != v || fabs(v) > DBL_MAX || (seen[9] && (v == val[9] || (float)v == (float)val[9]))) {
            mask[k] = 1;
            nvoid++;
        } else if (fabs(v) > FLT_MAX)
            st = tn__fail(TN_ERR_CORRUPT, "%s: .asc value %g out of float range", name, v);
        else
            img->data[k] = (float)v;
    }
    if (st == TN_OK && tn__io_token(p, n, &i, &tb, &tl))
        st = tn__fail(TN_ERR_CORRUPT, "%s: .asc has more values than ncols x nrows = %zu", name, count);
    if (st == TN_OK && nvoid) st = tn__io_fill_voids(img->data, mask, w, h, name, &info->voids_filled);
    TN_FREE(mask);
    if (st) { tn_image_free(img); return st; }
    cs = seen[6] ? val[6] : (seen[7] ? val[7] : (seen[8] ? val[8] : 0.0));
    info->bit_depth = 32;
    info->file_channels = 1;
    info->cellsize = cs;
    info->x_origin = seen[3] && !seen[2] ? val[3] - 0.5 * cs : val[2]; /* centre -> corner */
    info->y_origin = seen[5] && !seen[4] ? val[5] - 0.5 * cs : val[4];
    return TN_OK;
}

/* Appends k bytes to a growing TN_MALLOC'd buffer. */
static tn_status tn__io_append(void **buf, size_t *len, size_t *cap, const void *d, size_t k)
{
    tn_status st = tn__reserve(buf, cap, *len + k);
    if (st) return st;
    memcpy((uint8_t *)*buf + *len, d, k);
    *len += k;
    return TN_OK;
}

/* Writes the header (origin 0, the given cell size) and one text row per image row. */
static tn_status tn__asc_encode(const tn_image *img, double cellsize, uint8_t **out, size_t *out_size)
{
    char line[160], num[48];
    void *buf = NULL;
    size_t len = 0, cap = 0, x, y;
    int k;
    tn_status st;
    if (img->channels != 1) return tn__fail(TN_ERR_SHAPE, ".asc stores 1 channel, not %d", img->channels);
    tn__io_format_number(num, sizeof num, cellsize, 0);
    k = snprintf(line, sizeof line, "ncols %d\nnrows %d\nxllcorner 0\nyllcorner 0\ncellsize %s\n", img->width,
                 img->height, num);
    st = tn__io_append(&buf, &len, &cap, line, (size_t)k);
    for (y = 0; y < (size_t)img->height && !st; y++) {
        for (x = 0; x < (size_t)img->width && !st; x++) {
            k = tn__io_format_number(num + 1, sizeof num - 1, img->data[y * (size_t)img->width + x], 1);
            num[0] = ' ';
            st = x ? tn__io_append(&buf, &len, &cap, num, (size_t)k + 1) : tn__io_append(&buf, &len, &cap, num + 1, (size_t)k);
        }
        if (!st) st = tn__io_append(&buf, &len, &cap, "\n", 1);
    }
    if (st) { TN_FREE(buf); return st; }
    *out = (uint8_t *)buf;
    *out_size = len;
    return TN_OK;
}

/* ---- headerless little-endian 16-bit .r16 ---- */

static tn_status tn__r16_decode(const uint8_t *p, size_t n, const char *name, const tn_load_opts *opts, tn_image *img,
                                tn_image_info *info)
{
    size_t w, h, bytes = 0, k;
    int rw = opts ? opts->raw_width : 0, rh = opts ? opts->raw_height : 0;
    tn_status st;
    if (rw < 0 || rh < 0 || (rw == 0) != (rh == 0))
        return tn__fail(TN_ERR_INVALID_ARG, "%s: raw_width/raw_height %d x %d: give both or neither", name, rw, rh);
    if (rw) {
        w = (size_t)rw;
        h = (size_t)rh;
        if (tn__size4(w, h, 1, sizeof(float), &bytes)) return tn__fail_context(TN_ERR_TOO_LARGE, name);
        if (n != w * h * 2)
            return tn__fail(TN_ERR_SHAPE, "%s: %zu bytes, but %zu x %zu 16-bit samples need %zu", name, n, w, h, w * h * 2);
    } else {
        size_t s = n / 2, side;
        if (n == 0) return tn__fail(TN_ERR_EMPTY, "%s: empty .r16 file", name);
        side = (size_t)sqrt((double)s);
        while (side * side > s) side--;
        while ((side + 1) * (side + 1) <= s) side++;
        if (n % 2 || side * side != s)
            return tn__fail(TN_ERR_SHAPE, "%s: %zu bytes is not a square 16-bit grid; give raw_width/raw_height", name, n);
        if (side > (size_t)INT_MAX) return tn__fail(TN_ERR_TOO_LARGE, "%s: .r16 grid too large", name);
        w = h = side;
        if (tn__size4(w, h, 1, sizeof(float), &bytes)) return tn__fail_context(TN_ERR_TOO_LARGE, name);
    }
    st = tn_image_create(img, (int)w, (int)h, 1);
    if (st) return tn__fail_context(st, name);
    for (k = 0; k < w * h; k++) img->data[k] = (float)tn__io_le16(p + 2 * k) / 65535.0f;
    info->bit_depth = 16;
    info->file_channels = 1;
    return TN_OK;
}

static tn_status tn__r16_encode(const tn_image *img, double lo, double hi, uint8_t **out, size_t *out_size)
{
    size_t count, k;
    double scale = 65535.0 / (hi - lo);
    uint8_t *buf;
    if (img->channels != 1) return tn__fail(TN_ERR_SHAPE, ".r16 stores 1 channel, not %d", img->channels);
    count = (size_t)img->width * (size_t)img->height;
    buf = (uint8_t *)tn__alloc(count * 2);
    if (!buf) return TN_ERR_OUT_OF_MEMORY;
    for (k = 0; k < count; k++) {
        unsigned c = tn__io_code(img->data[k], lo, scale, 65535u);
        buf[2 * k] = (uint8_t)c;
        buf[2 * k + 1] = (uint8_t)(c >> 8);
    }
    *out = buf;
    *out_size = count * 2;
    return TN_OK;
}

/* ---- detection ---- */

static tn_format tn__io_format_from_magic(const uint8_t *p, size_t n)
{
    static const uint8_t png_sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    size_t i = 0, tb, tl;
    if (n >= 8 && memcmp(p, png_sig, 8) == 0) return TN_FORMAT_PNG;
    if (n >= 3 && p[0] == 'P' && (tn__io_space(p[2]) || p[2] == '#')) {
        if (p[1] == 'F' || p[1] == 'f') return TN_FORMAT_PFM;
        if (p[1] >= '1' && p[1] <= '7') return TN_FORMAT_PNM; /* P1/P4/P7 get a clear "unsupported" */
    }
    if (tn__io_token(p, n < 64 ? n : 64, &i, &tb, &tl) && tn__asc_key((const char *)p + tb, tl) >= 0 &&
        !tn__io_token_is((const char *)p + tb, tl, "dx") && !tn__io_token_is((const char *)p + tb, tl, "dy"))
        return TN_FORMAT_ASC;
    return TN_FORMAT_AUTO;
}

/* Format named by the extension of path (case-insensitive), or AUTO. */
static tn_format tn__io_format_from_name(const char *path)
{
    static const char *const ext[] = {"png", "pgm", "ppm", "pnm", "pfm", "hgt", "asc", "r16", "raw"};
    static const tn_format fmt[] = {TN_FORMAT_PNG, TN_FORMAT_PNM, TN_FORMAT_PNM, TN_FORMAT_PNM, TN_FORMAT_PFM,
                                    TN_FORMAT_HGT, TN_FORMAT_ASC, TN_FORMAT_R16, TN_FORMAT_R16};
    const char *s, *dot = NULL;
    size_t k;
    if (!path) return TN_FORMAT_AUTO;
    for (s = path; *s; s++) {
        if (*s == '/' || *s == '\\') dot = NULL;
        else if (*s == '.') dot = s;
    }
    if (!dot) return TN_FORMAT_AUTO;
    for (k = 0; k < sizeof ext / sizeof ext[0]; k++)
        if (tn__io_token_is(dot + 1, strlen(dot + 1), ext[k])) return fmt[k];
    return TN_FORMAT_AUTO;
}

/* ---- load ---- */

TN_API tn_status tn_image_load_memory(const void *data, size_t size, const char *name, tn_image *img,
                                      tn_image_info *info, const tn_load_opts *opts)
{
    static const uint8_t empty[1] = {0};
    const uint8_t *p = data ? (const uint8_t *)data : empty;
    const char *label = name && name[0] ? name : "<memory>";
    tn_format f = opts ? opts->format : TN_FORMAT_AUTO;
    tn_image tmp;
    tn_image_info inf;
    tn_status st;
    TN_ASSERT(img);
    if (!data && size) return tn__fail(TN_ERR_INVALID_ARG, "%s: NULL data with size %zu", label, size);
    memset(&tmp, 0, sizeof tmp);
    memset(&inf, 0, sizeof inf);
    if ((int)f < (int)TN_FORMAT_AUTO || (int)f > (int)TN_FORMAT_R16)
        return tn__fail(TN_ERR_INVALID_ARG, "%s: unknown format code %d", label, (int)f);
    if (f == TN_FORMAT_AUTO) f = tn__io_format_from_magic(p, size);
    if (f == TN_FORMAT_AUTO) f = tn__io_format_from_name(name);
    if (f == TN_FORMAT_AUTO)
        return tn__fail(TN_ERR_FORMAT, "%s: unknown file format (no known magic bytes or extension)", label);
    switch (f) {
    case TN_FORMAT_PNG: st = tn__png_decode(p, size, label, &tmp, &inf); break;
    case TN_FORMAT_PNM: st = tn__pnm_decode(p, size, label, &tmp, &inf); break;
    case TN_FORMAT_PFM: st = tn__pfm_decode(p, size, label, &tmp, &inf); break;
    case TN_FORMAT_HGT: st = tn__hgt_decode(p, size, label, &tmp, &inf); break;
    case TN_FORMAT_ASC: st = tn__asc_decode(p, size, label, &tmp, &inf); break;
    case TN_FORMAT_R16: st = tn__r16_decode(p, size, label, opts, &tmp, &inf); break;
    default: st = tn__fail(TN_ERR_FORMAT, "%s: unknown file format", label); break;
    }
    if (st) {
        tn_image_free(&tmp);
        return st;
    }
    inf.format = f;
    *img = tmp;
    if (info) *info = inf;
    return TN_OK;
}

/* Reads a whole file with one fread. *out is TN_MALLOC'd. */
static tn_status tn__io_read_file(const char *path, uint8_t **out, size_t *out_size)
{
    FILE *f = fopen(path, "rb");
    long end = -1;
    size_t n, got;
    uint8_t *buf;
    if (!f) return tn__fail(TN_ERR_IO, "%s: cannot open for reading", path);
    if (fseek(f, 0, SEEK_END) != 0 || (end = ftell(f)) < 0 || fseek(f, 0, SEEK_SET) != 0) {
        fclose(f);
        return tn__fail(TN_ERR_IO, "%s: cannot determine the file size", path);
    }
    if ((unsigned long long)end > (unsigned long long)TN_MAX_ALLOC || end == 0) {
        /* a directory reports a size of 0 or LONG_MAX but fails to read: say so */
        int c = fgetc(f), err = ferror(f);
        fclose(f);
        if (err) return tn__fail(TN_ERR_IO, "%s: cannot read (a directory?)", path);
        if (end != 0) return tn__fail(TN_ERR_TOO_LARGE, "%s: %ld bytes exceeds the allocation limit", path, end);
        if (c != EOF) return tn__fail(TN_ERR_IO, "%s: the size is unknown (not a regular file?)", path);
        *out = (uint8_t *)tn__alloc(1); /* an empty file: the parsers report it */
        *out_size = 0;
        return *out ? TN_OK : tn__fail_context(TN_ERR_OUT_OF_MEMORY, path);
    }
    n = (size_t)end;
    buf = (uint8_t *)tn__alloc(n);
    if (!buf) { fclose(f); return tn__fail_context(TN_ERR_OUT_OF_MEMORY, path); }
    got = fread(buf, 1, n, f);
    if (got != n || ferror(f)) {
        fclose(f);
        TN_FREE(buf);
        return tn__fail(TN_ERR_IO, "%s: read failed (%zu of %zu bytes)", path, got, n);
    }
    fclose(f);
    *out = buf;
    *out_size = n;
    return TN_OK;
}

TN_API tn_status tn_image_load_ex(const char *path, tn_image *img, tn_image_info *info, const tn_load_opts *opts)
{
    uint8_t *buf = NULL;
    size_t n = 0;
    tn_status st;
    TN_ASSERT(img);
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "load: empty path");
    st = tn__io_read_file(path, &buf, &n);
    if (st) return st;
    st = tn_image_load_memory(buf, n, path, img, info, opts);
    TN_FREE(buf);
    return st;
}

TN_API tn_status tn_image_load(const char *path, tn_image *img, tn_image_info *info)
{
    return tn_image_load_ex(path, img, info, NULL);
}

/* ---- save ---- */

/* The zero rules of tn_save_opts for writing a `channels`-channel image as `format`: 16 bits
   for one channel and for .r16, else 8; PNG level 6; .asc cell size 1 (also for a negative or
   non-finite one, which is not refused). The format itself is picked by tn_image_save. */
static void tn__save_opts_defaults(tn_save_opts *o, int channels, tn_format format)
{
    if (!o->bit_depth) o->bit_depth = channels == 1 || format == TN_FORMAT_R16 ? 16 : 8;
    if (!o->compression) o->compression = 6;
    if (!(o->cellsize > 0.0 && o->cellsize <= DBL_MAX)) o->cellsize = 1.0;
}

TN_API tn_status tn_image_save_memory(const tn_image *img, const tn_save_opts *opts, tn_format format, uint8_t **out,
                                      size_t *out_size)
{
    tn_save_opts o;
    double lo = 0.0, hi = 1.0;
    int record = 0;
    size_t bad;
    tn_status st;
    TN_ASSERT(out && out_size);
    *out = NULL;
    *out_size = 0;
    if (!img || !img->data || img->width <= 0 || img->height <= 0 || img->channels <= 0)
        return tn__fail(TN_ERR_INVALID_ARG, "save: the image is empty");
    bad = tn_image_range(img, NULL, NULL);
    if (bad) return tn__fail(TN_ERR_NUMERIC, "save: the image has %zu NaN/Inf samples", bad);
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    tn__save_opts_defaults(&o, img->channels, format);
    if (format == TN_FORMAT_PNG || format == TN_FORMAT_PNM || format == TN_FORMAT_R16) {
        if (o.bit_depth != 8 && o.bit_depth != 16) return tn__fail(TN_ERR_INVALID_ARG, "save: bit depth %d (use 8 or 16)", o.bit_depth);
        if (format == TN_FORMAT_R16 && o.bit_depth != 16) return tn__fail(TN_ERR_INVALID_ARG, "save: .r16 is always 16-bit");
        st = tn__io_save_mapping(img, &o, &lo, &hi, &record);
        if (st) return st;
    }
    switch (format) {
    case TN_FORMAT_PNG:
        if (img->channels > 4) return tn__fail(TN_ERR_SHAPE, "PNG stores 1 to 4 channels, not %d", img->channels);
        if (o.compression < 0 || o.compression > 9)
            return tn__fail(TN_ERR_INVALID_ARG, "save: PNG compression level %d (0-9)", o.compression);
        return tn__png_encode(img, o.bit_depth, lo, hi, record, o.compression, out, out_size);
    case TN_FORMAT_PNM: return tn__pnm_encode(img, o.bit_depth, lo, hi, record, out, out_size);
    case TN_FORMAT_PFM: return tn__pfm_encode(img, out, out_size);
    case TN_FORMAT_HGT: return tn__hgt_encode(img, out, out_size);
    case TN_FORMAT_ASC: return tn__asc_encode(img, o.cellsize, out, out_size);
    case TN_FORMAT_R16: return tn__r16_encode(img, lo, hi, out, out_size);
    default: break;
    }
    return tn__fail(TN_ERR_INVALID_ARG, "save: no format given (%d)", (int)format);
}

/* A number that differs between processes, for temporary file names. */
static unsigned long tn__io_process_id(void)
{
#if !defined(TN_NO_THREADS) && defined(_POSIX_VERSION)
    return (unsigned long)getpid();
#else
    return (unsigned long)time(NULL);
#endif
}

static unsigned long tn__io_tmp_counter;

/* Writes buf to "<path>.tmp.<pid>.<n>" and renames it over path; removes the temporary on failure. */
static tn_status tn__io_write_atomic(const char *path, const uint8_t *buf, size_t n)
{
    size_t cap = strlen(path) + 64;
    char *tmp = (char *)tn__alloc(cap);
    unsigned long serial = ++tn__io_tmp_counter;
    FILE *f;
    int ok;
    if (!tmp) return TN_ERR_OUT_OF_MEMORY;
    serial ^= (unsigned long)((size_t)&cap >> 4) << 16; /* distinct per thread stack */
    snprintf(tmp, cap, "%s.tmp.%lu.%lu", path, tn__io_process_id(), serial);
    f = fopen(tmp, "wb");
    if (!f) {
        TN_FREE(tmp);
        return tn__fail(TN_ERR_IO, "%s: cannot create a temporary file next to it", path);
    }
    ok = fwrite(buf, 1, n, f) == n;
    ok = fflush(f) == 0 && ok;
    ok = !ferror(f) && ok;
    ok = fclose(f) == 0 && ok;
    if (!ok) {
        remove(tmp);
        TN_FREE(tmp);
        return tn__fail(TN_ERR_IO, "%s: write failed (disk full?)", path);
    }
    if (rename(tmp, path) != 0) {
#ifdef _WIN32
        if (remove(path) == 0 && rename(tmp, path) == 0) { TN_FREE(tmp); return TN_OK; } /* no replacing rename */
#endif
        remove(tmp);
        TN_FREE(tmp);
        return tn__fail(TN_ERR_IO, "%s: cannot rename the temporary file into place", path);
    }
    TN_FREE(tmp);
    return TN_OK;
}

TN_API tn_status tn_image_save(const char *path, const tn_image *img, const tn_save_opts *opts)
{
    tn_format f = opts ? opts->format : TN_FORMAT_AUTO;
    uint8_t *buf = NULL;
    size_t n = 0;
    tn_status st;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "save: empty path");
    if (f == TN_FORMAT_AUTO) f = tn__io_format_from_name(path);
    if (f == TN_FORMAT_AUTO)
        return tn__fail(TN_ERR_FORMAT, "%s: cannot tell the format from the extension (png pgm ppm pnm pfm hgt asc r16 raw)", path);
    st = tn_image_save_memory(img, opts, f, &buf, &n);
    if (st) return tn__fail_context(st, path);
    st = tn__io_write_atomic(path, buf, n);
    TN_FREE(buf);
    return st;
}

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
        if (tn_image_range(ref, &lo, &hi) != 0)
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

TN_API tn_status tn_ssim(const tn_image *ref, const tn_image *img, double data_range, double *ssim)
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

TN_API tn_status tn_compare(const tn_image *ref, const tn_image *img, double data_range, tn_metrics *out)
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

/* --------------------------------------------------------------------------------------------
   >>gemm  (@@gemm implementation)
   Goto/BLIS-style SGEMM (Goto & van de Geijn, "Anatomy of high-performance matrix multiplication",
   TOMS 2008). op(A) is packed into MR-row micro-panels (an MC x KC block), op(B) into NR-column
   micro-panels (a KC x NC block sized for L2); packing absorbs the transposes, so one register-
   blocked micro-kernel serves all four cases. Loop nest: rows by MC, K by KC (pack A), columns by
   NC (pack B), then each A micro-panel stays in L1 while the B micro-panels stream from L2.
   Kernels: AVX-512 8x32, AVX2+FMA 6x16, portable C 8x16 (auto-vectorised). Edge tiles go through
   a small temporary tile. Threads split N (or M when N is narrow) in whole tiles; K blocks are
   always summed in the same order, so results do not depend on the thread count.
   -------------------------------------------------------------------------------------------- */

#if defined(__AVX512F__)
#define TN__GEMM_MR 8
#define TN__GEMM_VW 16
#define TN__GEMM_ROWS(X) X(0) X(1) X(2) X(3) X(4) X(5) X(6) X(7)
#define TN__V __m512
#define TN__VZERO() _mm512_setzero_ps()
#define TN__VSET(x) _mm512_set1_ps(x)
#define TN__VLOAD(p) _mm512_load_ps(p)
#define TN__VLOADU(p) _mm512_loadu_ps(p)
#define TN__VSTOREU(p, v) _mm512_storeu_ps(p, v)
#define TN__VMUL(a, b) _mm512_mul_ps(a, b)
#define TN__VFMA(a, b, c) _mm512_fmadd_ps(a, b, c)
#elif defined(__AVX2__) && defined(__FMA__)
#define TN__GEMM_MR 6
#define TN__GEMM_VW 8
#define TN__GEMM_ROWS(X) X(0) X(1) X(2) X(3) X(4) X(5)
#define TN__V __m256
#define TN__VZERO() _mm256_setzero_ps()
#define TN__VSET(x) _mm256_set1_ps(x)
#define TN__VLOAD(p) _mm256_load_ps(p)
#define TN__VLOADU(p) _mm256_loadu_ps(p)
#define TN__VSTOREU(p, v) _mm256_storeu_ps(p, v)
#define TN__VMUL(a, b) _mm256_mul_ps(a, b)
#define TN__VFMA(a, b, c) _mm256_fmadd_ps(a, b, c)
#else /* portable: 8x16 measured best over gcc and clang at -O2 (SSE2) */
#define TN__GEMM_MR 8
#define TN__GEMM_VW 8
#endif
#define TN__GEMM_NR (2 * TN__GEMM_VW)

/* Block sizes (floats) for Zen 4 (32K L1D, 1M L2): an A micro-panel (MR x KC, 12 KiB) fits in
   L1, the packed B block (KC x NC, 384 KiB) in L2, the packed A block (MC x KC) in L2/L3.
   Measured KC 256..576, NC 192..512, MC 256..2048: all within ~3% of each other; KC 256 or
   NC 512 lose a little on the convolution shape. */
#define TN__GEMM_KC 384
#define TN__GEMM_MC 768
#define TN__GEMM_NC 256
/* Below this many multiply-adds the pool's wake-up costs more than a second thread saves
   (condvar pool: 128^3 is slower on 2 threads, 192^3 faster; a spinning pool pays from 128^3). */
#define TN__GEMM_PAR_MIN (128 * 128 * 128)
/* Up to this many multiply-adds packing costs more than it saves: plain loops (measured: the
   packed path costs ~0.2 us fixed and wins from about 8x8x8 on). */
#define TN__GEMM_SMALL (8 * 8 * 8)

#ifdef TN__V
/* One MR x NR tile: c = alpha * (packed A panel x packed B panel) + beta * c (c only read when
   beta != 0). Two vectors per row; all MR*2 accumulators stay in registers. */
static void tn__gemm_kernel(int kc, const float *pa, const float *pb, float *c, int ldc, float alpha, float beta)
{
    TN__V b0, b1, a, va = TN__VSET(alpha), vb = TN__VSET(beta);
    int k;
#define TN__GEMM_DECL(i) TN__V c##i##a = TN__VZERO(), c##i##b = TN__VZERO();
#define TN__GEMM_FMA(i)                                                                         \
    a = TN__VSET(pa[i]);                                                                        \
    c##i##a = TN__VFMA(a, b0, c##i##a);                                                         \
    c##i##b = TN__VFMA(a, b1, c##i##b);
#define TN__GEMM_PREFETCH(i)                                                                    \
    _mm_prefetch((const char *)(c + (i) * ldc), _MM_HINT_T0);                                   \
    _mm_prefetch((const char *)(c + (i) * ldc + TN__GEMM_NR - 1), _MM_HINT_T0);
#define TN__GEMM_STORE(i)                                                                       \
    TN__VSTOREU(c + (i) * ldc, TN__VMUL(c##i##a, va));                                          \
    TN__VSTOREU(c + (i) * ldc + TN__GEMM_VW, TN__VMUL(c##i##b, va));
#define TN__GEMM_UPDATE(i)                                                                      \
    TN__VSTOREU(c + (i) * ldc, TN__VFMA(c##i##a, va, TN__VMUL(vb, TN__VLOADU(c + (i) * ldc)))); \
    TN__VSTOREU(c + (i) * ldc + TN__GEMM_VW,                                                    \
                TN__VFMA(c##i##b, va, TN__VMUL(vb, TN__VLOADU(c + (i) * ldc + TN__GEMM_VW))));
    TN__GEMM_ROWS(TN__GEMM_DECL)
    TN__GEMM_ROWS(TN__GEMM_PREFETCH)
    for (k = 0; k < kc; k++) {
        b0 = TN__VLOAD(pb);
        b1 = TN__VLOAD(pb + TN__GEMM_VW);
        TN__GEMM_ROWS(TN__GEMM_FMA)
        pa += TN__GEMM_MR;
        pb += TN__GEMM_NR;
    }
    if (beta == 0.0f) {
        TN__GEMM_ROWS(TN__GEMM_STORE)
    } else {
        TN__GEMM_ROWS(TN__GEMM_UPDATE)
    }
#undef TN__GEMM_DECL
#undef TN__GEMM_FMA
#undef TN__GEMM_PREFETCH
#undef TN__GEMM_STORE
#undef TN__GEMM_UPDATE
}
#else
/* Portable kernel: the fixed-size j loop is what compilers vectorise (the accumulator tile
   lives in L1 rather than registers, still ~4x faster than unpacked loops). */
static void tn__gemm_kernel(int kc, const float *pa, const float *pb, float *c, int ldc, float alpha, float beta)
{
    float acc[TN__GEMM_MR * TN__GEMM_NR];
    int i, j, k;
    for (i = 0; i < TN__GEMM_MR * TN__GEMM_NR; i++) acc[i] = 0.0f;
    for (k = 0; k < kc; k++, pa += TN__GEMM_MR, pb += TN__GEMM_NR)
        for (i = 0; i < TN__GEMM_MR; i++) {
            float ai = pa[i];
            for (j = 0; j < TN__GEMM_NR; j++) acc[i * TN__GEMM_NR + j] += ai * pb[j];
        }
    for (i = 0; i < TN__GEMM_MR; i++) {
        float *crow = c + (size_t)i * ldc;
        if (beta == 0.0f)
            for (j = 0; j < TN__GEMM_NR; j++) crow[j] = alpha * acc[i * TN__GEMM_NR + j];
        else
            for (j = 0; j < TN__GEMM_NR; j++) crow[j] = alpha * acc[i * TN__GEMM_NR + j] + beta * crow[j];
    }
}
#endif

#ifdef TN__V
#define TN__GEMM_TR8 1
/* dst[k*dstride + r] = src[r*ld + k] for an 8 x 8 block: the in-register transpose (unpack,
   shuffle, 128-bit permute) that makes transposed packing as fast as a copy. */
static void tn__gemm_tr8x8(const float *src, int ld, float *dst, int dstride)
{
    __m256 r0 = _mm256_loadu_ps(src), r1 = _mm256_loadu_ps(src + ld), r2 = _mm256_loadu_ps(src + 2 * (size_t)ld);
    __m256 r3 = _mm256_loadu_ps(src + 3 * (size_t)ld), r4 = _mm256_loadu_ps(src + 4 * (size_t)ld);
    __m256 r5 = _mm256_loadu_ps(src + 5 * (size_t)ld), r6 = _mm256_loadu_ps(src + 6 * (size_t)ld);
    __m256 r7 = _mm256_loadu_ps(src + 7 * (size_t)ld);
    __m256 t0 = _mm256_unpacklo_ps(r0, r1), t1 = _mm256_unpackhi_ps(r0, r1);
    __m256 t2 = _mm256_unpacklo_ps(r2, r3), t3 = _mm256_unpackhi_ps(r2, r3);
    __m256 t4 = _mm256_unpacklo_ps(r4, r5), t5 = _mm256_unpackhi_ps(r4, r5);
    __m256 t6 = _mm256_unpacklo_ps(r6, r7), t7 = _mm256_unpackhi_ps(r6, r7);
    __m256 u0 = _mm256_shuffle_ps(t0, t2, 0x44), u1 = _mm256_shuffle_ps(t0, t2, 0xEE);
    __m256 u2 = _mm256_shuffle_ps(t1, t3, 0x44), u3 = _mm256_shuffle_ps(t1, t3, 0xEE);
    __m256 u4 = _mm256_shuffle_ps(t4, t6, 0x44), u5 = _mm256_shuffle_ps(t4, t6, 0xEE);
    __m256 u6 = _mm256_shuffle_ps(t5, t7, 0x44), u7 = _mm256_shuffle_ps(t5, t7, 0xEE);
    _mm256_storeu_ps(dst, _mm256_permute2f128_ps(u0, u4, 0x20));
    _mm256_storeu_ps(dst + dstride, _mm256_permute2f128_ps(u1, u5, 0x20));
    _mm256_storeu_ps(dst + 2 * (size_t)dstride, _mm256_permute2f128_ps(u2, u6, 0x20));
    _mm256_storeu_ps(dst + 3 * (size_t)dstride, _mm256_permute2f128_ps(u3, u7, 0x20));
    _mm256_storeu_ps(dst + 4 * (size_t)dstride, _mm256_permute2f128_ps(u0, u4, 0x31));
    _mm256_storeu_ps(dst + 5 * (size_t)dstride, _mm256_permute2f128_ps(u1, u5, 0x31));
    _mm256_storeu_ps(dst + 6 * (size_t)dstride, _mm256_permute2f128_ps(u2, u6, 0x31));
    _mm256_storeu_ps(dst + 7 * (size_t)dstride, _mm256_permute2f128_ps(u3, u7, 0x31));
}
#else
#define TN__GEMM_TR8 0
static void tn__gemm_tr8x8(const float *src, int ld, float *dst, int dstride)
{
    int r, k;
    for (r = 0; r < 8; r++)
        for (k = 0; k < 8; k++) dst[(size_t)k * dstride + r] = src[(size_t)r * ld + k];
}
#endif

/* Packs op(A)[i0 .. i0+mc) x [k0 .. k0+kc) as MR-row micro-panels, k-major inside a panel
   (pa[p*kc*MR + k*MR + r]); rows past mc are zero. */
static void tn__gemm_pack_a(int trans, const float *A, int lda, int i0, int mc, int k0, int kc, float *pa)
{
    int p, r, k;
    for (p = 0; p < mc; p += TN__GEMM_MR, pa += (size_t)kc * TN__GEMM_MR) {
        int rows = mc - p < TN__GEMM_MR ? mc - p : TN__GEMM_MR;
        if (trans) { /* op(A)(i,k) = A[k*lda + i]: each k is a contiguous run of rows */
            for (k = 0; k < kc; k++) {
                const float *src = A + (size_t)(k0 + k) * lda + i0 + p;
                float *dst = pa + (size_t)k * TN__GEMM_MR;
                for (r = 0; r < rows; r++) dst[r] = src[r];
                for (; r < TN__GEMM_MR; r++) dst[r] = 0.0f;
            }
        } else {
            k = 0;
            if (TN__GEMM_TR8 && TN__GEMM_MR == 8 && rows == 8) /* whole 8 x 8 blocks */
                for (; k + 8 <= kc; k += 8)
                    tn__gemm_tr8x8(A + (size_t)(i0 + p) * lda + k0 + k, lda, pa + (size_t)k * 8, 8);
            for (r = 0; r < rows; r++) {
                const float *src = A + (size_t)(i0 + p + r) * lda + k0;
                int kr;
                for (kr = k; kr < kc; kr++) pa[(size_t)kr * TN__GEMM_MR + r] = src[kr];
            }
            for (; r < TN__GEMM_MR; r++)
                for (k = 0; k < kc; k++) pa[(size_t)k * TN__GEMM_MR + r] = 0.0f;
        }
    }
}

/* Distance between packed B micro-panels: one cache line more than the panel, so that the
   row-by-row packing does not write every panel at the same L1 set (4 KiB aliasing). */
static size_t tn__gemm_b_stride(int kc) { return (size_t)kc * TN__GEMM_NR + 16; }

/* Packs op(B)[k0 .. k0+kc) x [j0 .. j0+nc) as NR-column micro-panels (panel q/NR starts at
   pb + (q/NR) * tn__gemm_b_stride(kc), element (k, j) at k*NR + j); columns past nc are zero.
   Source rows are read whole, so the hardware prefetcher streams them. */
static void tn__gemm_pack_b(int trans, const float *B, int ldb, int k0, int kc, int j0, int nc, float *pb)
{
    size_t panel = tn__gemm_b_stride(kc);
    int q, j, k;
    if (!trans) { /* op(B)(k,j) = B[k*ldb + j]: row k is contiguous */
        for (k = 0; k < kc; k++) {
            const float *src = B + (size_t)(k0 + k) * ldb + j0;
            float *dst = pb + (size_t)k * TN__GEMM_NR;
            for (q = 0; q + TN__GEMM_NR <= nc; q += TN__GEMM_NR, dst += panel)
                memcpy(dst, src + q, sizeof(float) * TN__GEMM_NR);
            if (q < nc) {
                for (j = 0; j < nc - q; j++) dst[j] = src[q + j];
                for (; j < TN__GEMM_NR; j++) dst[j] = 0.0f;
            }
        }
        return;
    }
    for (q = 0; q < nc; q += TN__GEMM_NR, pb += panel) { /* op(B)(k,j) = B[j*ldb + k] */
        int cols = nc - q < TN__GEMM_NR ? nc - q : TN__GEMM_NR, kk = 0, kend;
        if (TN__GEMM_TR8 && cols == TN__GEMM_NR) /* whole 8 x 8 blocks */
            for (; kk + 8 <= kc; kk += 8)
                for (j = 0; j < TN__GEMM_NR; j += 8)
                    tn__gemm_tr8x8(B + (size_t)(j0 + q + j) * ldb + k0 + kk, ldb, pb + (size_t)kk * TN__GEMM_NR + j,
                                   TN__GEMM_NR);
        for (; kk < kc; kk += 64) { /* 64 k at a time: the written part stays in L1 */
            kend = kc - kk < 64 ? kc : kk + 64;
            for (j = 0; j < cols; j++) {
                const float *src = B + (size_t)(j0 + q + j) * ldb + k0;
                for (k = kk; k < kend; k++) pb[(size_t)k * TN__GEMM_NR + j] = src[k];
            }
            for (; j < TN__GEMM_NR; j++)
                for (k = kk; k < kend; k++) pb[(size_t)k * TN__GEMM_NR + j] = 0.0f;
        }
    }
}

/* Packs op(B)[k0 .. k0+kc) x [j0 .. j0+nc) in the layout of tn__gemm_pack_b, for a B that is
   never stored (the convolution packs straight from its input instead of an im2col buffer). */
typedef void (*tn__gemm_pack_fn)(void *ctx, int k0, int kc, int j0, int nc, float *pb);

typedef struct tn__gemm_job {
    int trans_a, trans_b, M, N, K;
    float alpha, beta;
    const float *A, *B;
    int lda, ldb, ldc;
    float *C;
    int split_n;   /* threads split columns (1) or rows (0) */
    int max_parts; /* at most this many threads get work */
    tn__gemm_pack_fn pack_b; /* if set, produces the packed B blocks (B is unused) */
    void *pack_ctx;
} tn__gemm_job;

static float tn__gemm_get(const float *X, int ld, int trans, int r, int c)
{
    return trans ? X[(size_t)c * ld + r] : X[(size_t)r * ld + c];
}

/* Unpacked loops for tiny products, single-row products and the out-of-memory fallback: rows
   [m0, m1) x columns [n0, n1) of C. With op(B) rows contiguous it adds scaled rows of op(B)
   (vectorisable); otherwise it takes dot products. */
static void tn__gemm_simple(const tn__gemm_job *g, int m0, int m1, int n0, int n1)
{
    int i, j, k;
    for (i = m0; i < m1; i++) {
        float *crow = g->C + (size_t)i * g->ldc;
        if (!g->trans_b) {
            for (j = n0; j < n1; j++) crow[j] = g->beta == 0.0f ? 0.0f : g->beta * crow[j];
            for (k = 0; k < g->K; k++) {
                float a = g->alpha * tn__gemm_get(g->A, g->lda, g->trans_a, i, k);
                const float *brow = g->B + (size_t)k * g->ldb;
                for (j = n0; j < n1; j++) crow[j] += a * brow[j];
            }
        } else {
            for (j = n0; j < n1; j++) {
                const float *bcol = g->B + (size_t)j * g->ldb; /* op(B)(k, j) = bcol[k] */
                float s = 0.0f;
                for (k = 0; k < g->K; k++) s += tn__gemm_get(g->A, g->lda, g->trans_a, i, k) * bcol[k];
                crow[j] = g->beta == 0.0f ? g->alpha * s : g->alpha * s + g->beta * crow[j];
            }
        }
    }
}

/* Packing scratch: one grow-once slot per concurrently running GEMM share. Slots are claimed
   under a mutex rather than indexed by `ith`, because a GEMM called from inside another parallel
   region runs as ith 0 on a worker while the caller may be in ith 0 of its own GEMM. */
#define TN__GEMM_SLOTS (2 * TN__MAX_THREADS)
static void *tn__gemm_slot_raw[TN__GEMM_SLOTS];
static unsigned char tn__gemm_slot_busy[TN__GEMM_SLOTS];
#ifndef TN_NO_THREADS
static pthread_mutex_t tn__gemm_slot_mu = PTHREAD_MUTEX_INITIALIZER;
#endif

static int tn__gemm_claim_slot(void)
{
    int s;
#ifndef TN_NO_THREADS
    pthread_mutex_lock(&tn__gemm_slot_mu);
#endif
    for (s = 0; s < TN__GEMM_SLOTS && tn__gemm_slot_busy[s]; s++) {}
    if (s < TN__GEMM_SLOTS) tn__gemm_slot_busy[s] = 1;
#ifndef TN_NO_THREADS
    pthread_mutex_unlock(&tn__gemm_slot_mu);
#endif
    return s < TN__GEMM_SLOTS ? s : -1;
}

static void tn__gemm_release_slot(int s)
{
#ifndef TN_NO_THREADS
    pthread_mutex_lock(&tn__gemm_slot_mu);
#endif
    tn__gemm_slot_busy[s] = 0;
#ifndef TN_NO_THREADS
    pthread_mutex_unlock(&tn__gemm_slot_mu);
#endif
}

/* 64-byte aligned packing space for one slot (A block then B block), allocated on first use
   and kept; NULL if the allocation fails. */
static float *tn__gemm_slot_buffer(int s)
{
    size_t floats = (size_t)TN__GEMM_MC * TN__GEMM_KC + TN__GEMM_NC / TN__GEMM_NR * tn__gemm_b_stride(TN__GEMM_KC);
    if (!tn__gemm_slot_raw[s]) tn__gemm_slot_raw[s] = TN_MALLOC(floats * sizeof(float) + 64);
    if (!tn__gemm_slot_raw[s]) return NULL;
    return (float *)(((uintptr_t)tn__gemm_slot_raw[s] + 63) & ~(uintptr_t)63);
}

/* C[ic.., jc..] (+)= op(A) block x op(B) block from the packed buffers; beta applies to this
   K block. */
static void tn__gemm_macro(const tn__gemm_job *g, int ic, int mc, int jc, int nc, int kc, const float *pa,
                           const float *pb, float beta)
{
    float tile[TN__GEMM_MR * TN__GEMM_NR];
    int p, q, i, j;
    for (p = 0; p < mc; p += TN__GEMM_MR) {
        int mr = mc - p < TN__GEMM_MR ? mc - p : TN__GEMM_MR;
        const float *ap = pa + (size_t)p * kc;
        for (q = 0; q < nc; q += TN__GEMM_NR) {
            int nr = nc - q < TN__GEMM_NR ? nc - q : TN__GEMM_NR;
            const float *bp = pb + (size_t)(q / TN__GEMM_NR) * tn__gemm_b_stride(kc);
            float *c = g->C + (size_t)(ic + p) * g->ldc + jc + q;
            if (mr == TN__GEMM_MR && nr == TN__GEMM_NR) {
                tn__gemm_kernel(kc, ap, bp, c, g->ldc, g->alpha, beta);
                continue;
            }
            tn__gemm_kernel(kc, ap, bp, tile, TN__GEMM_NR, 1.0f, 0.0f); /* edge: via a full tile */
            for (i = 0; i < mr; i++)
                for (j = 0; j < nr; j++) {
                    float *cij = c + (size_t)i * g->ldc + j;
                    float t = g->alpha * tile[i * TN__GEMM_NR + j];
                    *cij = beta == 0.0f ? t : t + beta * *cij;
                }
        }
    }
}

/* Rows [m0, m1) x columns [n0, n1) of C with the blocked loop nest. K is cut into equal blocks
   of at most KC, the same for every thread count. */
static void tn__gemm_blocked(const tn__gemm_job *g, int m0, int m1, int n0, int n1, float *pa, float *pb)
{
    int kblocks = (g->K + TN__GEMM_KC - 1) / TN__GEMM_KC, kcb = (g->K + kblocks - 1) / kblocks;
    int ic, pc, jc;
    for (ic = m0; ic < m1; ic += TN__GEMM_MC) {
        int mc = m1 - ic < TN__GEMM_MC ? m1 - ic : TN__GEMM_MC;
        for (pc = 0; pc < g->K; pc += kcb) {
            int kc = g->K - pc < kcb ? g->K - pc : kcb;
            float beta = pc == 0 ? g->beta : 1.0f; /* later K blocks accumulate into C */
            tn__gemm_pack_a(g->trans_a, g->A, g->lda, ic, mc, pc, kc, pa);
            for (jc = n0; jc < n1; jc += TN__GEMM_NC) {
                int nc = n1 - jc < TN__GEMM_NC ? n1 - jc : TN__GEMM_NC;
                if (g->pack_b) g->pack_b(g->pack_ctx, pc, kc, jc, nc, pb);
                else tn__gemm_pack_b(g->trans_b, g->B, g->ldb, pc, kc, jc, nc, pb);
                tn__gemm_macro(g, ic, mc, jc, nc, kc, pa, pb, beta);
            }
        }
    }
}

/* One thread's share: a contiguous range of whole tiles along the split dimension. */
static void tn__gemm_task(void *ctx, int ith, int nth)
{
    const tn__gemm_job *g = (const tn__gemm_job *)ctx;
    int m0 = 0, m1 = g->M, n0 = 0, n1 = g->N, slot;
    float *buf;
    if (nth > g->max_parts) nth = g->max_parts;
    if (ith >= nth) return;
    if (g->split_n) {
        int tiles = (g->N + TN__GEMM_NR - 1) / TN__GEMM_NR;
        n0 = (int)((long long)tiles * ith / nth) * TN__GEMM_NR;
        n1 = (int)((long long)tiles * (ith + 1) / nth) * TN__GEMM_NR;
        if (n1 > g->N) n1 = g->N;
    } else {
        int tiles = (g->M + TN__GEMM_MR - 1) / TN__GEMM_MR;
        m0 = (int)((long long)tiles * ith / nth) * TN__GEMM_MR;
        m1 = (int)((long long)tiles * (ith + 1) / nth) * TN__GEMM_MR;
        if (m1 > g->M) m1 = g->M;
    }
    if (m0 >= m1 || n0 >= n1) return;
    slot = tn__gemm_claim_slot();
    buf = slot >= 0 ? tn__gemm_slot_buffer(slot) : NULL;
    if (buf) tn__gemm_blocked(g, m0, m1, n0, n1, buf, buf + (size_t)TN__GEMM_MC * TN__GEMM_KC);
    else tn__gemm_simple(g, m0, m1, n0, n1); /* out of slots or memory: slow but correct */
    if (slot >= 0) tn__gemm_release_slot(slot);
}

/* C = beta * C for the degenerate cases (K == 0 or alpha == 0); beta == 0 writes zeros. */
static void tn__gemm_scale_c(float *C, int ldc, int M, int N, float beta)
{
    int i, j;
    for (i = 0; i < M; i++) {
        float *crow = C + (size_t)i * ldc;
        for (j = 0; j < N; j++) crow[j] = beta == 0.0f ? 0.0f : beta * crow[j];
    }
}

TN_API void tn_sgemm(int trans_a, int trans_b, int M, int N, int K, float alpha, const float *A, int lda,
                     const float *B, int ldb, float beta, float *C, int ldc)
{
    tn__gemm_job g;
    double macs = (double)M * N * K;
    TN_ASSERT(M >= 0 && N >= 0 && K >= 0);
    if (M == 0 || N == 0) return;
    TN_ASSERT(C && ldc >= N);
    if (K == 0 || alpha == 0.0f) {
        tn__gemm_scale_c(C, ldc, M, N, beta);
        return;
    }
    TN_ASSERT(A && B);
    TN_ASSERT(lda >= (trans_a ? M : K) && ldb >= (trans_b ? K : N));
    g.trans_a = trans_a != 0;
    g.trans_b = trans_b != 0;
    g.M = M;
    g.N = N;
    g.K = K;
    g.alpha = alpha;
    g.beta = beta;
    g.A = A;
    g.B = B;
    g.lda = lda;
    g.ldb = ldb;
    g.ldc = ldc;
    g.C = C;
    g.pack_b = NULL;
    g.pack_ctx = NULL;
    if (macs <= TN__GEMM_SMALL) {
        tn__gemm_simple(&g, 0, M, 0, N);
        return;
    }
    /* Split N while each thread still gets a few tiles of it (packs of A are then duplicated,
       which is cheap); otherwise split M. */
    g.split_n = (N + TN__GEMM_NR - 1) / TN__GEMM_NR >= 4 * tn_get_threads() || N >= M;
    g.max_parts = g.split_n ? (N + TN__GEMM_NR - 1) / TN__GEMM_NR : (M + TN__GEMM_MR - 1) / TN__GEMM_MR;
    if (macs < TN__GEMM_PAR_MIN) tn__gemm_task(&g, 0, 1);
    else tn_parallel_run(tn__gemm_task, &g);
}

/* Floats of packing space tn__sgemm_gen_b needs for M rows: an A block, then (64-byte aligned)
   a B block. */
static size_t tn__sgemm_gen_b_floats(int M)
{
    size_t rows = (size_t)(M < TN__GEMM_MC ? M : TN__GEMM_MC);
    rows = (rows + TN__GEMM_MR - 1) / TN__GEMM_MR * TN__GEMM_MR;
    return (rows * TN__GEMM_KC + 15) / 16 * 16 + TN__GEMM_NC / TN__GEMM_NR * tn__gemm_b_stride(TN__GEMM_KC);
}

/* C = A B + beta C (A M x K, row-major) on the calling thread, B packed block by block by `pack`,
   using `buf` (64-byte aligned, tn__sgemm_gen_b_floats(M) floats). For use inside a parallel
   region; results are the same as tn_sgemm's for the same B. */
static void tn__sgemm_gen_b(int M, int N, int K, const float *A, int lda, tn__gemm_pack_fn pack, void *pack_ctx,
                            float beta, float *C, int ldc, float *buf)
{
    tn__gemm_job g;
    size_t rows = (size_t)(M < TN__GEMM_MC ? M : TN__GEMM_MC);
    rows = (rows + TN__GEMM_MR - 1) / TN__GEMM_MR * TN__GEMM_MR;
    memset(&g, 0, sizeof g);
    g.M = M;
    g.N = N;
    g.K = K;
    g.alpha = 1.0f;
    g.beta = beta;
    g.A = A;
    g.lda = lda;
    g.ldb = N;
    g.ldc = ldc;
    g.C = C;
    g.pack_b = pack;
    g.pack_ctx = pack_ctx;
    if (M > 0 && N > 0 && K > 0) tn__gemm_blocked(&g, 0, M, 0, N, buf, buf + (rows * TN__GEMM_KC + 15) / 16 * 16);
}

/* --------------------------------------------------------------------------------------------
   >>tensor  (@@tensor implementation)
   The arena is a list of blocks; a reset keeps them, and when a step needed more than one block
   the reset merges them into one, so the next identical step fits without calling malloc.
   The tape is an array of tensor pointers in creation order, stored in the arena as well.
   -------------------------------------------------------------------------------------------- */

typedef struct tn__block {
    struct tn__block *next;
    size_t size, used;
    unsigned char *base; /* 64-byte aligned start inside the allocation */
} tn__block;

struct tn_ctx {
    tn__block *blocks;      /* current block first */
    size_t total_used, peak;
    tn_tensor **tape;
    size_t tape_len, tape_cap;
    int grad_enabled;
    tn_status status;
};

#define TN__BLOCK_MIN ((size_t)1 << 20)

static tn__block *tn__block_new(size_t size)
{
    unsigned char *raw;
    tn__block *b;
    if (size > TN_MAX_ALLOC) return NULL;
    raw = (unsigned char *)TN_MALLOC(sizeof(tn__block) + size + 64);
    if (!raw) return NULL;
    b = (tn__block *)raw;
    b->next = NULL;
    b->size = size;
    b->used = 0;
    b->base = raw + sizeof(tn__block);
    b->base += (64 - ((uintptr_t)b->base & 63)) & 63;
    return b;
}

TN_API tn_ctx *tn_ctx_create(void)
{
    tn_ctx *c = (tn_ctx *)TN_MALLOC(sizeof(tn_ctx));
    if (!c) return NULL;
    memset(c, 0, sizeof *c);
    c->grad_enabled = 1;
    return c;
}

TN_API void tn_ctx_free(tn_ctx *ctx)
{
    tn__block *b, *n;
    if (!ctx) return;
    for (b = ctx->blocks; b; b = n) {
        n = b->next;
        TN_FREE(b);
    }
    TN_FREE(ctx->tape);
    TN_FREE(ctx);
}

TN_API void tn_ctx_reset(tn_ctx *ctx)
{
    tn__block *b, *n;
    if (ctx->blocks && ctx->blocks->next) { /* merge into one block big enough for the peak */
        size_t want = ctx->peak + ctx->peak / 8 + 4096;
        for (b = ctx->blocks; b; b = n) {
            n = b->next;
            TN_FREE(b);
        }
        ctx->blocks = tn__block_new(want < TN__BLOCK_MIN ? TN__BLOCK_MIN : want);
    }
    if (ctx->blocks) ctx->blocks->used = 0;
    ctx->total_used = 0;
    ctx->tape_len = 0;
    ctx->status = TN_OK;
}

TN_API tn_status tn_ctx_status(const tn_ctx *ctx) { return ctx->status; }
TN_API size_t tn_ctx_used(const tn_ctx *ctx) { return ctx->total_used; }
TN_API void tn_ctx_set_grad(tn_ctx *ctx, int enabled) { ctx->grad_enabled = enabled != 0; }

TN_API void *tn_ctx_alloc(tn_ctx *ctx, size_t bytes)
{
    tn__block *b = ctx->blocks;
    void *p;
    bytes = (bytes + 63) & ~(size_t)63;
    if (!b || b->size - b->used < bytes) {
        size_t sz = bytes > TN__BLOCK_MIN ? bytes : TN__BLOCK_MIN;
        if (b && sz < b->size * 2 && b->size * 2 <= TN_MAX_ALLOC) sz = b->size * 2;
        b = tn__block_new(sz);
        if (!b) {
            if (!ctx->status) ctx->status = tn__fail(TN_ERR_OUT_OF_MEMORY, "tensor arena: cannot allocate %zu bytes", sz);
            return NULL;
        }
        b->next = ctx->blocks;
        ctx->blocks = b;
    }
    p = b->base + b->used;
    b->used += bytes;
    ctx->total_used += bytes;
    if (ctx->total_used > ctx->peak) ctx->peak = ctx->total_used;
    return p;
}

static float *tn__ctx_floats(tn_ctx *ctx, size_t n, int zero)
{
    float *p = (float *)tn_ctx_alloc(ctx, n * sizeof(float));
    if (p && zero) memset(p, 0, n * sizeof(float));
    return p;
}

/* A tensor in the arena; its data is zeroed only when `zero` (ops that write every element skip it). */
static tn_tensor *tn__tensor_make(tn_ctx *ctx, int ndim, const int *shape, int zero)
{
    tn_tensor *t;
    size_t n = 1;
    int i;
    TN_ASSERT(ndim >= 1 && ndim <= TN_MAX_DIMS);
    for (i = 0; i < ndim; i++) {
        TN_ASSERT(shape[i] >= 1);
        if (!tn__mul_size(n, (size_t)shape[i], &n) || n > TN_MAX_ALLOC / sizeof(float)) {
            if (!ctx->status) ctx->status = tn__fail(TN_ERR_TOO_LARGE, "tensor of %d dims is too large", ndim);
            return NULL;
        }
    }
    t = (tn_tensor *)tn_ctx_alloc(ctx, sizeof(tn_tensor));
    if (!t) return NULL;
    memset(t, 0, sizeof *t);
    t->ndim = ndim;
    for (i = 0; i < TN_MAX_DIMS; i++) t->shape[i] = i < ndim ? shape[i] : 1;
    t->numel = n;
    t->data = tn__ctx_floats(ctx, n, zero);
    return t->data ? t : NULL;
}

TN_API tn_tensor *tn_tensor_new(tn_ctx *ctx, int ndim, const int *shape) { return tn__tensor_make(ctx, ndim, shape, 1); }

TN_API tn_tensor *tn_tensor_1d(tn_ctx *ctx, int n) { return tn_tensor_new(ctx, 1, &n); }
TN_API tn_tensor *tn_tensor_2d(tn_ctx *ctx, int rows, int cols)
{
    int s[2];
    s[0] = rows; s[1] = cols;
    return tn_tensor_new(ctx, 2, s);
}
TN_API tn_tensor *tn_tensor_4d(tn_ctx *ctx, int n, int c, int h, int w)
{
    int s[4];
    s[0] = n; s[1] = c; s[2] = h; s[3] = w;
    return tn_tensor_new(ctx, 4, s);
}

TN_API tn_tensor *tn_tensor_requires_grad(tn_ctx *ctx, tn_tensor *t)
{
    if (!t) return NULL;
    if (!t->grad) t->grad = tn__ctx_floats(ctx, t->numel, 1);
    t->requires_grad = 1;
    return t->grad ? t : NULL;
}

TN_API void tn_tensor_fill(tn_tensor *t, float v)
{
    size_t i;
    for (i = 0; i < t->numel; i++) t->data[i] = v;
}

TN_API int tn_tensor_same_shape(const tn_tensor *a, const tn_tensor *b)
{
    int i;
    if (a->ndim != b->ndim) return 0;
    for (i = 0; i < a->ndim; i++)
        if (a->shape[i] != b->shape[i]) return 0;
    return 1;
}

TN_API tn_tensor *tn_tensor_from_image(tn_ctx *ctx, const tn_image *img)
{
    tn_tensor *t = tn_tensor_4d(ctx, 1, img->channels, img->height, img->width);
    size_t i, hw = (size_t)img->width * img->height;
    int c;
    if (!t) return NULL;
    for (c = 0; c < img->channels; c++)
        for (i = 0; i < hw; i++) t->data[(size_t)c * hw + i] = img->data[i * img->channels + c];
    return t;
}

TN_API tn_status tn_tensor_to_image(const tn_tensor *t, int n, tn_image *img)
{
    tn_image out = {0, 0, 0, NULL};
    size_t i, hw;
    int c;
    tn_status st;
    if (!t || t->ndim != 4 || n < 0 || n >= t->shape[0])
        return tn__fail(TN_ERR_INVALID_ARG, "tensor_to_image needs an N x C x H x W tensor and a valid batch index");
    if ((st = tn_image_create(&out, t->shape[3], t->shape[2], t->shape[1]))) return st;
    hw = (size_t)t->shape[2] * t->shape[3];
    for (c = 0; c < t->shape[1]; c++)
        for (i = 0; i < hw; i++)
            out.data[i * out.channels + c] = t->data[((size_t)n * t->shape[1] + c) * hw + i];
    *img = out;
    return TN_OK;
}

/* The gradient buffer of t, allocated (zeroed) on first use. */
static float *tn__grad(tn_ctx *ctx, tn_tensor *t)
{
    if (!t->grad) t->grad = tn__ctx_floats(ctx, t->numel, 1);
    return t->grad;
}

/* Creates an op's output (zeroed when `zero`) and, when any source needs a gradient, records it
   on the tape. */
static tn_tensor *tn__op_make(tn_ctx *ctx, int ndim, const int *shape, tn_backward_fn bw, tn_tensor *s0, tn_tensor *s1,
                              tn_tensor *s2, int zero)
{
    tn_tensor *t = tn__tensor_make(ctx, ndim, shape, zero);
    int need;
    if (!t) return NULL;
    need = ctx->grad_enabled && ((s0 && s0->requires_grad) || (s1 && s1->requires_grad) || (s2 && s2->requires_grad));
    t->src[0] = s0;
    t->src[1] = s1;
    t->src[2] = s2;
    if (need) {
        if (ctx->tape_len == ctx->tape_cap) {
            size_t cap = ctx->tape_cap ? ctx->tape_cap * 2 : 256;
            tn_tensor **nt = (tn_tensor **)TN_REALLOC(ctx->tape, cap * sizeof(tn_tensor *));
            if (!nt) {
                if (!ctx->status) ctx->status = tn__fail(TN_ERR_OUT_OF_MEMORY, "autograd tape: out of memory");
                return NULL;
            }
            ctx->tape = nt;
            ctx->tape_cap = cap;
        }
        ctx->tape[ctx->tape_len++] = t;
        t->requires_grad = 1;
        t->backward = bw;
    }
    return t;
}

static tn_tensor *tn__op(tn_ctx *ctx, int ndim, const int *shape, tn_backward_fn bw, tn_tensor *s0, tn_tensor *s1,
                         tn_tensor *s2)
{
    return tn__op_make(ctx, ndim, shape, bw, s0, s1, s2, 1);
}

/* Same shape as a. */
static tn_tensor *tn__op_like(tn_ctx *ctx, const tn_tensor *a, tn_backward_fn bw, tn_tensor *s0, tn_tensor *s1)
{
    return tn__op(ctx, a->ndim, a->shape, bw, s0, s1, NULL);
}

TN_API tn_status tn_backward(tn_ctx *ctx, tn_tensor *loss)
{
    size_t i;
    if (!loss) return ctx->status ? ctx->status : tn__fail(TN_ERR_INVALID_ARG, "backward: loss is NULL");
    if (ctx->status) return ctx->status;
    if (loss->numel != 1) return tn__fail(TN_ERR_SHAPE, "backward: the loss must have one element, not %zu", loss->numel);
    if (!loss->requires_grad) return tn__fail(TN_ERR_INVALID_ARG, "backward: the loss does not depend on anything that requires a gradient");
    if (!tn__grad(ctx, loss)) return ctx->status;
    loss->grad[0] += 1.0f;
    for (i = ctx->tape_len; i-- > 0;) {
        tn_tensor *t = ctx->tape[i];
        if (t->grad && t->backward) t->backward(ctx, t);
        if (ctx->status) return ctx->status;
    }
    return TN_OK;
}

/* --------------------------------------------------------------------------------------------
   >>ops  (@@ops implementation)
   Broadcasting binary ops walk 4-D index space with per-operand strides (0 on stretched dims);
   the backward pass runs the same walk and sums into the stretched operand. Large elementwise
   loops run on the pool; a split never changes any element's value.
   -------------------------------------------------------------------------------------------- */

#define TN__PAR_GRAIN 16384

/* Shape of a padded to 4 dims on the left (NumPy alignment). */
static void tn__shape4(const tn_tensor *a, int *s)
{
    int i, off = 4 - a->ndim;
    for (i = 0; i < 4; i++) s[i] = i < off ? 1 : a->shape[i - off];
}

/* Contiguous strides of a 4-D shape, with 0 where the dim is 1 and the output's is not. */
static void tn__bstrides(const int *s, const int *os, size_t *st)
{
    size_t acc = 1;
    int i;
    for (i = 3; i >= 0; i--) {
        st[i] = (s[i] == 1 && os[i] != 1) ? 0 : acc;
        acc *= (size_t)s[i];
    }
}

/* Output shape of broadcasting a with b; asserts they are compatible. */
static int tn__broadcast_shape(const tn_tensor *a, const tn_tensor *b, int *os)
{
    int sa[4], sb[4], i, nd = a->ndim > b->ndim ? a->ndim : b->ndim;
    tn__shape4(a, sa);
    tn__shape4(b, sb);
    for (i = 0; i < 4; i++) {
        TN_ASSERT(sa[i] == sb[i] || sa[i] == 1 || sb[i] == 1);
        os[i] = sa[i] > sb[i] ? sa[i] : sb[i];
    }
    return nd;
}

enum { TN__BIN_ADD, TN__BIN_SUB, TN__BIN_MUL, TN__BIN_DIV };

typedef struct tn__bin_job {
    const float *a, *b;
    float *o;
    int os[4];
    size_t sa[4], sb[4];
    int op;
} tn__bin_job;

/* Forward over output rows [b, e) of the flattened (n, c, h) index. */
static void tn__bin_rows(void *ctx, size_t rb, size_t re)
{
    const tn__bin_job *j = (const tn__bin_job *)ctx;
    size_t r;
    int W = j->os[3];
    for (r = rb; r < re; r++) {
        size_t n = r / ((size_t)j->os[1] * j->os[2]), c = (r / j->os[2]) % j->os[1], h = r % j->os[2];
        const float *pa = j->a + n * j->sa[0] + c * j->sa[1] + h * j->sa[2];
        const float *pb = j->b + n * j->sb[0] + c * j->sb[1] + h * j->sb[2];
        float *po = j->o + r * (size_t)W;
        size_t ia = j->sa[3], ib = j->sb[3];
        int x;
        switch (j->op) {
        case TN__BIN_ADD: for (x = 0; x < W; x++) po[x] = pa[x * ia] + pb[x * ib]; break;
        case TN__BIN_SUB: for (x = 0; x < W; x++) po[x] = pa[x * ia] - pb[x * ib]; break;
        case TN__BIN_MUL: for (x = 0; x < W; x++) po[x] = pa[x * ia] * pb[x * ib]; break;
        default: for (x = 0; x < W; x++) po[x] = pa[x * ia] / pb[x * ib]; break;
        }
    }
}

/* Gradient of a binary op for one operand (which = 0: a, 1: b), summed over stretched dims.
   Serial: the sums into stretched dims must keep a fixed order for determinism. */
static void tn__bin_backward_one(const tn_tensor *out, int which)
{
    tn_tensor *a = out->src[0], *b = out->src[1];
    float *g = which ? b->grad : a->grad;
    const float *go = out->grad;
    int os[4], sa4[4], sb4[4], op = out->ip[0];
    size_t sa[4], sb[4], n, c, h;
    tn__shape4(out, os);
    tn__shape4(a, sa4);
    tn__shape4(b, sb4);
    tn__bstrides(sa4, os, sa);
    tn__bstrides(sb4, os, sb);
    for (n = 0; n < (size_t)os[0]; n++)
        for (c = 0; c < (size_t)os[1]; c++)
            for (h = 0; h < (size_t)os[2]; h++) {
                size_t r = (n * os[1] + c) * os[2] + h, x;
                const float *pg = go + r * os[3];
                const float *pa = a->data + n * sa[0] + c * sa[1] + h * sa[2];
                const float *pb = b->data + n * sb[0] + c * sb[1] + h * sb[2];
                float *pd = g + (which ? n * sb[0] + c * sb[1] + h * sb[2] : n * sa[0] + c * sa[1] + h * sa[2]);
                size_t sd = which ? sb[3] : sa[3];
                for (x = 0; x < (size_t)os[3]; x++) {
                    float gv = pg[x], av = pa[x * sa[3]], bv = pb[x * sb[3]], d;
                    switch (op) {
                    case TN__BIN_ADD: d = gv; break;
                    case TN__BIN_SUB: d = which ? -gv : gv; break;
                    case TN__BIN_MUL: d = which ? gv * av : gv * bv; break;
                    default: d = which ? -gv * av / (bv * bv) : gv / bv; break;
                    }
                    pd[x * sd] += d;
                }
            }
}

static void tn__bin_backward(tn_ctx *ctx, tn_tensor *out)
{
    if (out->src[0]->requires_grad && tn__grad(ctx, out->src[0])) tn__bin_backward_one(out, 0);
    if (out->src[1]->requires_grad && tn__grad(ctx, out->src[1])) tn__bin_backward_one(out, 1);
}

static tn_tensor *tn__binary(tn_ctx *ctx, tn_tensor *a, tn_tensor *b, int op)
{
    int os[4], sa4[4], sb4[4], nd, shape[4], i;
    tn_tensor *o;
    tn__bin_job j;
    if (!a || !b) return NULL;
    nd = tn__broadcast_shape(a, b, os);
    for (i = 0; i < nd; i++) shape[i] = os[4 - nd + i];
    o = tn__op(ctx, nd, shape, tn__bin_backward, a, b, NULL);
    if (!o) return NULL;
    o->ip[0] = op;
    tn__shape4(a, sa4);
    tn__shape4(b, sb4);
    j.a = a->data;
    j.b = b->data;
    j.o = o->data;
    memcpy(j.os, os, sizeof os);
    tn__bstrides(sa4, os, j.sa);
    tn__bstrides(sb4, os, j.sb);
    j.op = op;
    tn_parallel_for((size_t)os[0] * os[1] * os[2], 1 + TN__PAR_GRAIN / (size_t)os[3], tn__bin_rows, &j);
    return o;
}

TN_API tn_tensor *tn_add(tn_ctx *ctx, tn_tensor *a, tn_tensor *b) { return tn__binary(ctx, a, b, TN__BIN_ADD); }
TN_API tn_tensor *tn_sub(tn_ctx *ctx, tn_tensor *a, tn_tensor *b) { return tn__binary(ctx, a, b, TN__BIN_SUB); }
TN_API tn_tensor *tn_mul(tn_ctx *ctx, tn_tensor *a, tn_tensor *b) { return tn__binary(ctx, a, b, TN__BIN_MUL); }
TN_API tn_tensor *tn_div(tn_ctx *ctx, tn_tensor *a, tn_tensor *b) { return tn__binary(ctx, a, b, TN__BIN_DIV); }

/* ---- unary elementwise ---- */

enum { TN__UN_SCALE, TN__UN_RELU, TN__UN_LEAKY, TN__UN_ELU, TN__UN_TANH, TN__UN_SIGMOID, TN__UN_SOFTPLUS,
       TN__UN_ABS, TN__UN_SQUARE, TN__UN_POWABS };

typedef struct tn__un_job { const float *x; float *y; int op; float p0, p1; } tn__un_job;

static float tn__unary_f(int op, float x, float p0, float p1)
{
    switch (op) {
    case TN__UN_SCALE: return x * p0 + p1;
    case TN__UN_RELU: return x > 0 ? x : 0.0f;
    case TN__UN_LEAKY: return x > 0 ? x : x * p0;
    case TN__UN_ELU: return x > 0 ? x : p0 * (expf(x) - 1.0f);
    case TN__UN_TANH: return tanhf(x);
    case TN__UN_SIGMOID: return x >= 0 ? 1.0f / (1.0f + expf(-x)) : expf(x) / (1.0f + expf(x));
    case TN__UN_SOFTPLUS: return x > 20.0f ? x : log1pf(expf(x));
    case TN__UN_ABS: return fabsf(x);
    case TN__UN_SQUARE: return x * x;
    default: return powf(fabsf(x), p0);
    }
}

/* dy/dx given x and y = f(x). */
static float tn__unary_df(int op, float x, float y, float p0)
{
    switch (op) {
    case TN__UN_SCALE: return p0;
    case TN__UN_RELU: return x > 0 ? 1.0f : 0.0f;
    case TN__UN_LEAKY: return x > 0 ? 1.0f : p0;
    case TN__UN_ELU: return x > 0 ? 1.0f : y + p0;
    case TN__UN_TANH: return 1.0f - y * y;
    case TN__UN_SIGMOID: return y * (1.0f - y);
    case TN__UN_SOFTPLUS: return x >= 0 ? 1.0f / (1.0f + expf(-x)) : expf(x) / (1.0f + expf(x));
    case TN__UN_ABS: return x > 0 ? 1.0f : (x < 0 ? -1.0f : 0.0f);
    case TN__UN_SQUARE: return 2.0f * x;
    default: return x == 0.0f ? 0.0f : p0 * y / x;
    }
}

static void tn__unary_range(void *ctx, size_t b, size_t e)
{
    const tn__un_job *j = (const tn__un_job *)ctx;
    size_t i;
    if (j->op == TN__UN_RELU) {
        for (i = b; i < e; i++) j->y[i] = j->x[i] > 0 ? j->x[i] : 0.0f;
        return;
    }
    for (i = b; i < e; i++) j->y[i] = tn__unary_f(j->op, j->x[i], j->p0, j->p1);
}

static void tn__unary_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *a = out->src[0];
    float *g = tn__grad(ctx, a);
    size_t i;
    if (!g) return;
    for (i = 0; i < a->numel; i++)
        g[i] += out->grad[i] * tn__unary_df(out->ip[0], a->data[i], out->data[i], out->fp[0]);
}

static tn_tensor *tn__unary(tn_ctx *ctx, tn_tensor *a, int op, float p0, float p1)
{
    tn_tensor *o;
    tn__un_job j;
    if (!a) return NULL;
    o = tn__op_like(ctx, a, tn__unary_backward, a, NULL);
    if (!o) return NULL;
    o->ip[0] = op;
    o->fp[0] = p0;
    o->fp[1] = p1;
    j.x = a->data;
    j.y = o->data;
    j.op = op;
    j.p0 = p0;
    j.p1 = p1;
    tn_parallel_for(a->numel, TN__PAR_GRAIN, tn__unary_range, &j);
    return o;
}

TN_API tn_tensor *tn_scale_shift(tn_ctx *ctx, tn_tensor *a, float scale, float shift) { return tn__unary(ctx, a, TN__UN_SCALE, scale, shift); }
TN_API tn_tensor *tn_relu(tn_ctx *ctx, tn_tensor *a) { return tn__unary(ctx, a, TN__UN_RELU, 0, 0); }
TN_API tn_tensor *tn_leaky_relu(tn_ctx *ctx, tn_tensor *a, float slope) { return tn__unary(ctx, a, TN__UN_LEAKY, slope, 0); }
TN_API tn_tensor *tn_elu(tn_ctx *ctx, tn_tensor *a, float alpha) { return tn__unary(ctx, a, TN__UN_ELU, alpha, 0); }
TN_API tn_tensor *tn_tanh(tn_ctx *ctx, tn_tensor *a) { return tn__unary(ctx, a, TN__UN_TANH, 0, 0); }
TN_API tn_tensor *tn_sigmoid(tn_ctx *ctx, tn_tensor *a) { return tn__unary(ctx, a, TN__UN_SIGMOID, 0, 0); }
TN_API tn_tensor *tn_softplus(tn_ctx *ctx, tn_tensor *a) { return tn__unary(ctx, a, TN__UN_SOFTPLUS, 0, 0); }
TN_API tn_tensor *tn_abs(tn_ctx *ctx, tn_tensor *a) { return tn__unary(ctx, a, TN__UN_ABS, 0, 0); }
TN_API tn_tensor *tn_square(tn_ctx *ctx, tn_tensor *a) { return tn__unary(ctx, a, TN__UN_SQUARE, 0, 0); }
TN_API tn_tensor *tn_pow_abs(tn_ctx *ctx, tn_tensor *a, float p) { return tn__unary(ctx, a, TN__UN_POWABS, p, 0); }

/* ---- matmul / linear ---- */

static void tn__matmul_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *a = out->src[0], *b = out->src[1];
    int ta = out->ip[0], tb = out->ip[1];
    int M = out->shape[0], N = out->shape[1], K = ta ? a->shape[0] : a->shape[1];
    /* C = op(A) op(B): dA = dC op(B)^T (stored transposed when ta), dB likewise */
    if (a->requires_grad && tn__grad(ctx, a)) {
        if (!ta) tn_sgemm(0, !tb, M, K, N, 1.0f, out->grad, N, b->data, b->shape[1], 1.0f, a->grad, a->shape[1]);
        else tn_sgemm(tb, 1, K, M, N, 1.0f, b->data, b->shape[1], out->grad, N, 1.0f, a->grad, a->shape[1]);
    }
    if (b->requires_grad && tn__grad(ctx, b)) {
        if (!tb) tn_sgemm(!ta, 0, K, N, M, 1.0f, a->data, a->shape[1], out->grad, N, 1.0f, b->grad, b->shape[1]);
        else tn_sgemm(1, ta, N, K, M, 1.0f, out->grad, N, a->data, a->shape[1], 1.0f, b->grad, b->shape[1]);
    }
}

TN_API tn_tensor *tn_matmul(tn_ctx *ctx, tn_tensor *a, tn_tensor *b, int trans_a, int trans_b)
{
    int M, K, K2, N, shape[2];
    tn_tensor *o;
    if (!a || !b) return NULL;
    TN_ASSERT(a->ndim == 2 && b->ndim == 2);
    M = trans_a ? a->shape[1] : a->shape[0];
    K = trans_a ? a->shape[0] : a->shape[1];
    K2 = trans_b ? b->shape[1] : b->shape[0];
    N = trans_b ? b->shape[0] : b->shape[1];
    TN_ASSERT(K == K2);
    (void)K2;
    shape[0] = M;
    shape[1] = N;
    o = tn__op(ctx, 2, shape, tn__matmul_backward, a, b, NULL);
    if (!o) return NULL;
    o->ip[0] = trans_a != 0;
    o->ip[1] = trans_b != 0;
    tn_sgemm(trans_a, trans_b, M, N, K, 1.0f, a->data, a->shape[1], b->data, b->shape[1], 0.0f, o->data, N);
    return o;
}

TN_API tn_tensor *tn_linear(tn_ctx *ctx, tn_tensor *x, tn_tensor *w, tn_tensor *bias)
{
    tn_tensor *y = tn_matmul(ctx, x, w, 0, 1);
    return bias ? tn_add(ctx, y, bias) : y;
}

/* ---- reductions ---- */

static void tn__sum_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *a = out->src[0];
    float *g = tn__grad(ctx, a), v;
    size_t i;
    if (!g) return;
    v = out->grad[0] * out->fp[0];
    for (i = 0; i < a->numel; i++) g[i] += v;
}

/* Deterministic sum: fixed-size chunks summed in double, then the chunks in order. */
static double tn__sum_floats(const float *x, size_t n)
{
    double total = 0.0;
    size_t i = 0;
    while (i < n) {
        size_t e = i + 4096 < n ? i + 4096 : n;
        float acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};
        double part = 0.0;
        for (; i + 8 <= e; i += 8) {
            int k;
            for (k = 0; k < 8; k++) acc[k] += x[i + k];
        }
        for (; i < e; i++) part += x[i];
        part += ((double)acc[0] + acc[1]) + ((double)acc[2] + acc[3]) + ((double)acc[4] + acc[5]) + ((double)acc[6] + acc[7]);
        total += part;
    }
    return total;
}

static tn_tensor *tn__reduce_all(tn_ctx *ctx, tn_tensor *a, float factor)
{
    int one = 1;
    tn_tensor *o;
    if (!a) return NULL;
    o = tn__op(ctx, 1, &one, tn__sum_backward, a, NULL, NULL);
    if (!o) return NULL;
    o->fp[0] = factor;
    o->data[0] = (float)(tn__sum_floats(a->data, a->numel) * factor);
    return o;
}

TN_API tn_tensor *tn_sum(tn_ctx *ctx, tn_tensor *a) { return tn__reduce_all(ctx, a, 1.0f); }
TN_API tn_tensor *tn_mean(tn_ctx *ctx, tn_tensor *a) { return a ? tn__reduce_all(ctx, a, 1.0f / (float)a->numel) : NULL; }

/* outer x len x inner view of a tensor around one axis */
static void tn__axis_split(const tn_tensor *a, int axis, size_t *outer, size_t *len, size_t *inner)
{
    int i;
    *outer = *inner = 1;
    for (i = 0; i < axis; i++) *outer *= (size_t)a->shape[i];
    *len = (size_t)a->shape[axis];
    for (i = axis + 1; i < a->ndim; i++) *inner *= (size_t)a->shape[i];
}

static void tn__sum_axis_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *a = out->src[0];
    float *g = tn__grad(ctx, a);
    size_t o, l, i, outer, len, inner;
    if (!g) return;
    tn__axis_split(a, out->ip[0], &outer, &len, &inner);
    for (o = 0; o < outer; o++)
        for (l = 0; l < len; l++)
            for (i = 0; i < inner; i++) g[(o * len + l) * inner + i] += out->grad[o * inner + i] * out->fp[0];
}

static tn_tensor *tn__reduce_axis(tn_ctx *ctx, tn_tensor *a, int axis, int mean)
{
    int shape[4], k;
    size_t o, l, i, outer, len, inner;
    tn_tensor *r;
    if (!a) return NULL;
    TN_ASSERT(axis >= 0 && axis < a->ndim);
    for (k = 0; k < a->ndim; k++) shape[k] = k == axis ? 1 : a->shape[k];
    r = tn__op(ctx, a->ndim, shape, tn__sum_axis_backward, a, NULL, NULL);
    if (!r) return NULL;
    tn__axis_split(a, axis, &outer, &len, &inner);
    r->ip[0] = axis;
    r->fp[0] = mean ? 1.0f / (float)len : 1.0f;
    for (o = 0; o < outer; o++)
        for (l = 0; l < len; l++)
            for (i = 0; i < inner; i++) r->data[o * inner + i] += a->data[(o * len + l) * inner + i];
    if (mean)
        for (i = 0; i < r->numel; i++) r->data[i] *= r->fp[0];
    return r;
}

TN_API tn_tensor *tn_sum_axis(tn_ctx *ctx, tn_tensor *a, int axis) { return tn__reduce_axis(ctx, a, axis, 0); }
TN_API tn_tensor *tn_mean_axis(tn_ctx *ctx, tn_tensor *a, int axis) { return tn__reduce_axis(ctx, a, axis, 1); }

/* ---- shape ops ---- */

static void tn__copy_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *a = out->src[0];
    float *g = tn__grad(ctx, a);
    size_t i;
    if (!g) return;
    for (i = 0; i < a->numel; i++) g[i] += out->grad[i];
}

TN_API tn_tensor *tn_reshape(tn_ctx *ctx, tn_tensor *a, int ndim, const int *shape)
{
    tn_tensor *o;
    if (!a) return NULL;
    o = tn__op(ctx, ndim, shape, tn__copy_backward, a, NULL, NULL);
    if (!o) return NULL;
    TN_ASSERT(o->numel == a->numel);
    memcpy(o->data, a->data, a->numel * sizeof(float));
    return o;
}

/* Offset in a (contiguous) of output index idx under permutation perm. */
static void tn__permute_walk(const tn_tensor *a, const int *perm, const tn_tensor *o, const float *src, float *dst, int backward)
{
    size_t astr[4], ostride[4], idx[4];
    int i;
    size_t k, acc = 1;
    for (i = 3; i >= 0; i--) {
        astr[i] = acc;
        acc *= (size_t)a->shape[i];
    }
    for (i = 0; i < 4; i++) ostride[i] = i < a->ndim ? astr[perm[i]] : 0;
    for (k = 0; k < o->numel; k++) {
        size_t rem = k, off = 0;
        for (i = 3; i >= 0; i--) {
            idx[i] = rem % (size_t)o->shape[i];
            rem /= (size_t)o->shape[i];
            off += idx[i] * ostride[i];
        }
        if (backward) dst[off] += src[k];
        else dst[k] = src[off];
    }
}

static void tn__permute_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *a = out->src[0];
    if (!tn__grad(ctx, a)) return;
    tn__permute_walk(a, out->ip, out, out->grad, a->grad, 1);
}

TN_API tn_tensor *tn_permute(tn_ctx *ctx, tn_tensor *a, const int *perm)
{
    int shape[4], i;
    tn_tensor *o;
    if (!a) return NULL;
    for (i = 0; i < a->ndim; i++) {
        TN_ASSERT(perm[i] >= 0 && perm[i] < a->ndim);
        shape[i] = a->shape[perm[i]];
    }
    o = tn__op(ctx, a->ndim, shape, tn__permute_backward, a, NULL, NULL);
    if (!o) return NULL;
    for (i = 0; i < 4; i++) o->ip[i] = i < a->ndim ? perm[i] : i;
    tn__permute_walk(a, o->ip, o, a->data, o->data, 0);
    return o;
}

static void tn__concat_backward(tn_ctx *ctx, tn_tensor *out)
{
    size_t o, outer, la, lb, inner, i;
    tn_tensor *a = out->src[0], *b = out->src[1];
    tn__axis_split(a, out->ip[0], &outer, &la, &inner);
    lb = (size_t)b->shape[out->ip[0]];
    for (o = 0; o < outer; o++) {
        const float *g = out->grad + o * (la + lb) * inner;
        if (a->requires_grad && tn__grad(ctx, a))
            for (i = 0; i < la * inner; i++) a->grad[o * la * inner + i] += g[i];
        if (b->requires_grad && tn__grad(ctx, b))
            for (i = 0; i < lb * inner; i++) b->grad[o * lb * inner + i] += g[la * inner + i];
    }
}

TN_API tn_tensor *tn_concat(tn_ctx *ctx, tn_tensor *a, tn_tensor *b, int axis)
{
    int shape[4], i;
    size_t o, outer, la, lb, inner;
    tn_tensor *r;
    if (!a || !b) return NULL;
    TN_ASSERT(a->ndim == b->ndim && axis >= 0 && axis < a->ndim);
    for (i = 0; i < a->ndim; i++) {
        TN_ASSERT(i == axis || a->shape[i] == b->shape[i]);
        shape[i] = i == axis ? a->shape[i] + b->shape[i] : a->shape[i];
    }
    r = tn__op(ctx, a->ndim, shape, tn__concat_backward, a, b, NULL);
    if (!r) return NULL;
    r->ip[0] = axis;
    tn__axis_split(a, axis, &outer, &la, &inner);
    lb = (size_t)b->shape[axis];
    for (o = 0; o < outer; o++) {
        memcpy(r->data + o * (la + lb) * inner, a->data + o * la * inner, la * inner * sizeof(float));
        memcpy(r->data + (o * (la + lb) + la) * inner, b->data + o * lb * inner, lb * inner * sizeof(float));
    }
    return r;
}

static void tn__slice_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *a = out->src[0];
    size_t o, outer, len, inner, i, n = (size_t)out->ip[2];
    if (!tn__grad(ctx, a)) return;
    tn__axis_split(a, out->ip[0], &outer, &len, &inner);
    for (o = 0; o < outer; o++)
        for (i = 0; i < n * inner; i++) a->grad[(o * len + (size_t)out->ip[1]) * inner + i] += out->grad[o * n * inner + i];
}

TN_API tn_tensor *tn_slice(tn_ctx *ctx, tn_tensor *a, int axis, int start, int len)
{
    int shape[4], i;
    size_t o, outer, alen, inner;
    tn_tensor *r;
    if (!a) return NULL;
    TN_ASSERT(axis >= 0 && axis < a->ndim && start >= 0 && len >= 1 && start + len <= a->shape[axis]);
    for (i = 0; i < a->ndim; i++) shape[i] = i == axis ? len : a->shape[i];
    r = tn__op(ctx, a->ndim, shape, tn__slice_backward, a, NULL, NULL);
    if (!r) return NULL;
    r->ip[0] = axis;
    r->ip[1] = start;
    r->ip[2] = len;
    tn__axis_split(a, axis, &outer, &alen, &inner);
    for (o = 0; o < outer; o++)
        memcpy(r->data + o * (size_t)len * inner, a->data + (o * alen + (size_t)start) * inner, (size_t)len * inner * sizeof(float));
    return r;
}

/* ---- convolution ----
   im2col lays the receptive field of every output pixel out as a column:
   col[(ci * KH + ky) * KW + kx][oy * OW + ox] = x[ci][oy * s - p + ky * d][ox * s - p + kx * d]
   so the convolution is a GEMM, W (M x C*KH*KW) times col. The output rows are cut into row groups
   whose number depends on the geometry only (never on the thread count); a thread takes whole
   groups and runs im2col + GEMM on L2-sized sub-bands of each, so the threads never meet. The
   weight gradient is summed per group, then over the groups in a fixed order: 1 and 2 threads
   give the same bits. The input gradient is itself a convolution (stride 1, zero padding: with
   the flipped, transposed kernel), otherwise col2im of W^T dY in two phases (even groups, then
   odd ones) whose groups never write the same input rows. */

typedef struct tn__conv_geom {
    int C, H, W, KH, KW, OH, OW, stride, pad, dil, reflect;
} tn__conv_geom;

/* Source index along one axis for output position o and kernel tap k; -1 = zero padding. */
static int tn__conv_src(int o, int k, int stride, int pad, int dil, int size, int reflect)
{
    int i = o * stride - pad + k * dil;
    if (i >= 0 && i < size) return i;
    if (!reflect) return -1;
    if (size == 1) return 0;
    while (i < 0 || i >= size) i = i < 0 ? -i : 2 * (size - 1) - i;
    return i;
}

/* Output columns [*lo, *hi) whose tap kx reads inside the row without padding: ix = ox*s + x0. */
static void tn__conv_inner(const tn__conv_geom *g, int kx, int *lo, int *hi)
{
    int x0 = kx * g->dil - g->pad, s = g->stride;
    *lo = x0 < 0 ? (-x0 + s - 1) / s : 0;
    *hi = g->W - 1 - x0 < 0 ? 0 : (g->W - 1 - x0) / s + 1;
    if (*hi > g->OW) *hi = g->OW;
    if (*lo > *hi) *lo = *hi;
}

/* d[0 .. ox1-ox0) = input row xr as tap kx sees it at output columns [ox0, ox1) (xr NULL: a
   padding row); [lo, hi) is the tap's inner range (tn__conv_inner). */
static void tn__conv_span(const tn__conv_geom *g, const float *xr, int kx, int lo, int hi, int ox0, int ox1, float *d)
{
    int ox, a = lo > ox0 ? lo : ox0, b = hi < ox1 ? hi : ox1, x0 = kx * g->dil - g->pad;
    d -= ox0; /* d[ox] from here on */
    if (!xr) {
        memset(d + ox0, 0, (size_t)(ox1 - ox0) * sizeof(float));
        return;
    }
    if (a > ox1) a = ox1;
    if (b < a) b = a;
    for (ox = ox0; ox < a; ox++) { /* left edge */
        int ix = g->reflect ? tn__conv_src(ox, kx, g->stride, g->pad, g->dil, g->W, 1) : -1;
        d[ox] = ix < 0 ? 0.0f : xr[ix];
    }
    if (g->stride == 1) memcpy(d + a, xr + x0 + a, (size_t)(b - a) * sizeof(float));
    else
        for (ox = a; ox < b; ox++) d[ox] = xr[ox * g->stride + x0];
    for (ox = b; ox < ox1; ox++) { /* right edge */
        int ix = g->reflect ? tn__conv_src(ox, kx, g->stride, g->pad, g->dil, g->W, 1) : -1;
        d[ox] = ix < 0 ? 0.0f : xr[ix];
    }
}

/* col = im2col(x) for output rows [oy0, oy1) of one image (col row r holds (oy1 - oy0) * OW). */
static void tn__im2col_band(const tn__conv_geom *g, const float *x, float *col, int oy0, int oy1)
{
    size_t band = (size_t)(oy1 - oy0) * g->OW;
    int ci, ky, kx, oy, lo, hi;
    for (ci = 0; ci < g->C; ci++)
        for (ky = 0; ky < g->KH; ky++)
            for (kx = 0; kx < g->KW; kx++, col += band) {
                tn__conv_inner(g, kx, &lo, &hi);
                for (oy = oy0; oy < oy1; oy++) {
                    int iy = tn__conv_src(oy, ky, g->stride, g->pad, g->dil, g->H, g->reflect);
                    const float *xr = iy < 0 ? NULL : x + ((size_t)ci * g->H + iy) * g->W;
                    tn__conv_span(g, xr, kx, lo, hi, 0, g->OW, col + (size_t)(oy - oy0) * g->OW);
                }
            }
}

/* im2col packed straight into the GEMM's B panels (tn__gemm_pack_fn): column j of the band is
   output pixel oy0 * OW + j of image x; row C*KH*KW, if asked for, is ones (times the bias). */
#define TN__CONV_KW_TAB 16
typedef struct tn__conv_pack {
    const tn__conv_geom *g;
    const float *x;
    int oy0;
    int lo[TN__CONV_KW_TAB], hi[TN__CONV_KW_TAB]; /* tn__conv_inner of each kx (if KW fits) */
} tn__conv_pack;

static void tn__conv_pack_init(tn__conv_pack *p, const tn__conv_geom *g, const float *x, int oy0)
{
    int kx;
    p->g = g;
    p->x = x;
    p->oy0 = oy0;
    for (kx = 0; kx < g->KW && kx < TN__CONV_KW_TAB; kx++) tn__conv_inner(g, kx, &p->lo[kx], &p->hi[kx]);
}

static void tn__conv_pack_b(void *ctx, int k0, int kc, int j0, int nc, float *pb)
{
    const tn__conv_pack *p = (const tn__conv_pack *)ctx;
    const tn__conv_geom *g = p->g;
    size_t panel = tn__gemm_b_stride(kc);
    int k, t, kx = (k0 % g->KW) - 1, ky = (k0 / g->KW) % g->KH, ci = k0 / (g->KW * g->KH);
    for (k = 0; k < kc; k++) { /* row by row: each source row is read sequentially */
        int lo, hi, x0, j = 0;
        if (k0 + k == g->C * g->KH * g->KW) { /* the bias row: ones */
            float *d = pb + (size_t)k * TN__GEMM_NR;
            for (j = 0; j < nc; j += TN__GEMM_NR, d += panel)
                for (t = 0; t < TN__GEMM_NR; t++) d[t] = j + t < nc ? 1.0f : 0.0f;
            continue;
        }
        if (++kx == g->KW && (kx = 0, ++ky == g->KH)) { /* next tap (ci, ky, kx) */
            ky = 0;
            ci++;
        }
        x0 = kx * g->dil - g->pad;
        if (kx < TN__CONV_KW_TAB) {
            lo = p->lo[kx];
            hi = p->hi[kx];
        } else {
            tn__conv_inner(g, kx, &lo, &hi);
        }
        while (j < nc) { /* one output row at a time, in pieces that stay inside one panel */
            int pix = j0 + j, oy = p->oy0 + pix / g->OW, ox = pix % g->OW, end = j + g->OW - ox;
            int iy = tn__conv_src(oy, ky, g->stride, g->pad, g->dil, g->H, g->reflect);
            const float *xr = iy < 0 ? NULL : p->x + ((size_t)ci * g->H + iy) * g->W;
            if (end > nc) end = nc;
            while (j < end) {
                int n = TN__GEMM_NR - j % TN__GEMM_NR;
                float *d = pb + (size_t)(j / TN__GEMM_NR) * panel + (size_t)k * TN__GEMM_NR + j % TN__GEMM_NR;
                if (n > end - j) n = end - j;
                if (xr && g->stride == 1 && n == TN__GEMM_NR && ox >= lo && ox + n <= hi)
                    memcpy(d, xr + x0 + ox, TN__GEMM_NR * sizeof(float)); /* inlined */
                else
                    tn__conv_span(g, xr, kx, lo, hi, ox, ox + n, d);
                j += n;
                ox += n;
            }
        }
        if (nc % TN__GEMM_NR) /* columns past nc are zero, as in tn__gemm_pack_b */
            for (t = nc % TN__GEMM_NR; t < TN__GEMM_NR; t++)
                pb[(size_t)(nc / TN__GEMM_NR) * panel + (size_t)k * TN__GEMM_NR + t] = 0.0f;
    }
}

/* dx += col2im(col) for output rows [oy0, oy1) of one image: the adjoint of tn__im2col_band, each
   element's additions in a fixed order. */
static void tn__col2im_band(const tn__conv_geom *g, const float *col, float *dx, int oy0, int oy1)
{
    size_t band = (size_t)(oy1 - oy0) * g->OW;
    int ci, ky, kx, oy, ox, lo, hi;
    for (ci = 0; ci < g->C; ci++)
        for (ky = 0; ky < g->KH; ky++)
            for (kx = 0; kx < g->KW; kx++, col += band) {
                int x0 = kx * g->dil - g->pad;
                tn__conv_inner(g, kx, &lo, &hi);
                for (oy = oy0; oy < oy1; oy++) {
                    int iy = tn__conv_src(oy, ky, g->stride, g->pad, g->dil, g->H, g->reflect);
                    const float *d = col + (size_t)(oy - oy0) * g->OW;
                    float *xr = dx + ((size_t)ci * g->H + (iy < 0 ? 0 : iy)) * g->W;
                    if (iy < 0) continue;
                    for (ox = 0; ox < lo; ox++) {
                        int ix = tn__conv_src(ox, kx, g->stride, g->pad, g->dil, g->W, g->reflect);
                        if (ix >= 0) xr[ix] += d[ox];
                    }
                    if (g->stride == 1)
                        for (ox = lo; ox < hi; ox++) xr[ox + x0] += d[ox];
                    else
                        for (ox = lo; ox < hi; ox++) xr[ox * g->stride + x0] += d[ox];
                    for (ox = hi; ox < g->OW; ox++) {
                        int ix = tn__conv_src(ox, kx, g->stride, g->pad, g->dil, g->W, g->reflect);
                        if (ix >= 0) xr[ix] += d[ox];
                    }
                }
            }
}

static int tn__conv_is_1x1(const tn__conv_geom *g)
{
    return g->KH == 1 && g->KW == 1 && g->stride == 1 && g->pad == 0;
}

/* Row groups: at most 16 and about 256 output pixels or more each; their M x K weight-gradient
   partials stay under 16 MiB. A function of the geometry only, so results never depend on it. */
static int tn__conv_groups(const tn__conv_geom *g, int M)
{
    size_t k = (size_t)g->C * g->KH * g->KW, groups = (size_t)g->OH * g->OW / 256;
    if (groups > 16) groups = 16;
    if (groups > (size_t)g->OH) groups = (size_t)g->OH;
    if (groups * M * k > ((size_t)1 << 22)) groups = ((size_t)1 << 22) / (M * k);
    return groups < 1 ? 1 : (int)groups;
}

/* Output rows per sub-band: about 64K floats (256 KiB) of columns, so im2col's output is still in
   L2 when the GEMM packs it. */
#ifndef TN__CONV_SUB_FLOATS
#define TN__CONV_SUB_FLOATS (1 << 16)
#endif
static int tn__conv_sub_rows(const tn__conv_geom *g)
{
    size_t per_row = (size_t)g->C * g->KH * g->KW * g->OW, rows = (size_t)TN__CONV_SUB_FLOATS / (per_row ? per_row : 1);
    if (rows < 1) rows = 1;
    if (rows > (size_t)g->OH) rows = (size_t)g->OH;
    return (int)rows;
}

/* One convolution pass over row groups; which pass the task function decides. */
typedef struct tn__conv_job {
    tn__conv_geom g;
    int N, M, K, groups, sub, phase; /* col2im: groups of this parity; dw: partials transposed */
    int mparts;                      /* forward: output channels split this many ways */
    int kd, dw_direct;               /* dw: K (+ 1 with the bias gradient); sums straight into dw */
    const float *x, *w, *bias, *dy;  /* x: N x C x H x W, w: M x K, dy: N x M x OH x OW */
    float *y, *dx, *dw;              /* y like dy, dx like x; dw: groups partials of M x K */
    float beta;                      /* forward: y = beta * y + conv */
    const float *wb;                 /* forward: w with the bias appended to each row (or w) */
    float *scratch;                  /* per thread: scratch_floats for columns / packing */
    size_t scratch_floats;
    int next;                        /* next unclaimed item (atomic) */
} tn__conv_job;

static void tn__conv_group_rows(const tn__conv_job *j, int gi, int *r0, int *r1)
{
    *r0 = (int)((long long)j->g.OH * gi / j->groups);
    *r1 = (int)((long long)j->g.OH * (gi + 1) / j->groups);
}

/* The next item for thread ith of nth, -1 when none is left. With atomics a free thread takes
   the next one (an item's result does not depend on which thread computes it, and a thread the
   OS preempts then holds up only its current item); otherwise a fixed contiguous share. */
#if !defined(TN_NO_THREADS) && (defined(__GNUC__) || defined(__clang__))
#define TN__CONV_DYNAMIC 1
#endif
static int tn__conv_claim(const tn__conv_job *j, int items, int ith, int nth, int *cursor)
{
#ifdef TN__CONV_DYNAMIC
    int it = __atomic_fetch_add((int *)&j->next, 1, __ATOMIC_RELAXED);
    (void)ith;
    (void)nth;
    (void)cursor;
    return it < items ? it : -1;
#else
    int b = (int)((long long)items * ith / nth), e = (int)((long long)items * (ith + 1) / nth);
    (void)j;
    if (*cursor < b) *cursor = b;
    return *cursor < e ? (*cursor)++ : -1;
#endif
}

/* Products up to this size go through tn_sgemm's unpacked loops (on an im2col buffer of at most
   this many floats); decided on the whole M, so every split computes them the same way. */
#define TN__CONV_TINY TN__GEMM_SMALL
#ifndef TN__CONV_FWD_PIX
#define TN__CONV_FWD_PIX 2048
#endif

/* Items are (image, group, channel part): y rows = W im2col(x rows) (+ bias), with im2col packed
   straight into the GEMM panels. Each output element's sum is the same for any split. */
static void tn__conv_fwd_task(void *ctx, int ith, int nth)
{
    const tn__conv_job *j = (const tn__conv_job *)ctx;
    const tn__conv_geom *g = &j->g;
    size_t ohw = (size_t)g->OH * g->OW, chw = (size_t)g->C * g->H * g->W;
    float *buf = j->scratch + (size_t)ith * j->scratch_floats, *col = buf + j->scratch_floats - TN__CONV_TINY;
    int parts = j->groups * j->mparts, mtiles = (j->M + TN__GEMM_MR - 1) / TN__GEMM_MR, it, cur = -1, r0, r1, oy, m;
    while ((it = tn__conv_claim(j, j->N * parts, ith, nth, &cur)) >= 0) {
        int mp = it % j->mparts, m0 = mtiles * mp / j->mparts * TN__GEMM_MR, m1 = mtiles * (mp + 1) / j->mparts * TN__GEMM_MR;
        const float *xn = j->x + (size_t)(it / parts) * chw, *wm;
        float *yn = j->y + (size_t)(it / parts) * j->M * ohw;
        if (m1 > j->M) m1 = j->M;
        if (m0 >= m1) continue;
        wm = j->w + (size_t)m0 * j->K;
        tn__conv_group_rows(j, it % parts / j->mparts, &r0, &r1);
        for (oy = r0; oy < r1; oy += j->sub) {
            int oy1 = oy + j->sub < r1 ? oy + j->sub : r1, band = (oy1 - oy) * g->OW;
            float *yb = yn + (size_t)m0 * ohw + (size_t)oy * g->OW;
            if ((double)j->M * band * j->K <= TN__CONV_TINY) {
                tn__im2col_band(g, xn, col, oy, oy1);
                tn_sgemm(0, 0, m1 - m0, band, j->K, 1.0f, wm, j->K, col, band, j->beta, yb, (int)ohw);
            } else { /* the bias is folded in as weight column K against a row of ones */
                tn__conv_pack pk;
                int kb = j->K + (j->bias != NULL);
                tn__conv_pack_init(&pk, g, xn, oy);
                tn__sgemm_gen_b(m1 - m0, band, kb, j->wb + (size_t)m0 * kb, kb, tn__conv_pack_b, &pk, j->beta, yb, (int)ohw, buf);
                continue;
            }
            if (j->bias)
                for (m = m0; m < m1; m++) {
                    float *p = yb + (size_t)(m - m0) * ohw, bm = j->bias[m];
                    int i;
                    for (i = 0; i < band; i++) p[i] += bm;
                }
        }
    }
}

/* Items are groups: partial[group] = sum over images and sub-bands of dy rows x im2col(x rows)^T. */
static void tn__conv_dw_task(void *ctx, int ith, int nth)
{
    const tn__conv_job *j = (const tn__conv_job *)ctx;
    const tn__conv_geom *g = &j->g;
    size_t ohw = (size_t)g->OH * g->OW, chw = (size_t)g->C * g->H * g->W;
    float *col = j->scratch + (size_t)ith * j->scratch_floats;
    int gi, cur = -1, r0, r1, oy, n;
    while ((gi = tn__conv_claim(j, j->groups, ith, nth, &cur)) >= 0) {
        float *part = j->dw + (size_t)gi * j->M * j->kd, beta = j->dw_direct ? 1.0f : 0.0f;
        tn__conv_group_rows(j, gi, &r0, &r1);
        for (n = 0; n < j->N; n++)
            for (oy = r0; oy < r1; oy += j->sub) {
                int oy1 = oy + j->sub < r1 ? oy + j->sub : r1, band = (oy1 - oy) * g->OW;
                const float *xn = j->x + (size_t)n * chw, *dyb = j->dy + (size_t)n * j->M * ohw + (size_t)oy * g->OW;
                const float *cb = col;
                int ldc = band;
                if (tn__conv_is_1x1(g)) {
                    cb = xn + (size_t)oy * g->OW;
                    ldc = (int)ohw;
                } else {
                    int i;
                    tn__im2col_band(g, xn, col, oy, oy1);
                    if (j->kd > j->K) /* a row of ones: the bias gradient comes out as column K */
                        for (i = 0; i < band; i++) col[(size_t)j->K * band + i] = 1.0f;
                }
                if (j->phase) /* transposed partial: kd x M = col dy^T */
                    tn_sgemm(0, 1, j->kd, j->M, band, 1.0f, cb, ldc, dyb, (int)ohw, beta, part, j->M);
                else
                    tn_sgemm(0, 1, j->M, j->kd, band, 1.0f, dyb, (int)ohw, cb, ldc, beta, part, j->kd);
                beta = 1.0f; /* the first product of a group initialises its partial */
            }
    }
}

/* Items are (image, group of parity `phase`) pairs: dx += col2im(W^T dy rows). */
static void tn__conv_dx_task(void *ctx, int ith, int nth)
{
    const tn__conv_job *j = (const tn__conv_job *)ctx;
    const tn__conv_geom *g = &j->g;
    size_t ohw = (size_t)g->OH * g->OW, chw = (size_t)g->C * g->H * g->W;
    float *col = j->scratch + (size_t)ith * j->scratch_floats;
    int per = (j->groups - j->phase + 1) / 2, it, cur = -1, r0, r1, oy;
    while ((it = tn__conv_claim(j, j->N * per, ith, nth, &cur)) >= 0) {
        int n = it / per;
        tn__conv_group_rows(j, 2 * (it % per) + j->phase, &r0, &r1);
        for (oy = r0; oy < r1; oy += j->sub) {
            int oy1 = oy + j->sub < r1 ? oy + j->sub : r1, band = (oy1 - oy) * g->OW;
            tn_sgemm(1, 0, j->K, band, j->M, 1.0f, j->w, j->K, j->dy + (size_t)n * j->M * ohw + (size_t)oy * g->OW,
                     (int)ohw, 0.0f, col, band);
            tn__col2im_band(g, col, j->dx + (size_t)n * chw, oy, oy1);
        }
    }
}

/* Sets up a job's split and `floats` of scratch per thread; 0 when the arena is out of memory. */
static int tn__conv_job_init(tn_ctx *ctx, tn__conv_job *j, const tn__conv_geom *g, int N, int M, int groups, size_t floats)
{
    memset(j, 0, sizeof *j);
    j->g = *g;
    j->N = N;
    j->M = M;
    j->K = g->C * g->KH * g->KW;
    j->groups = groups;
    j->sub = tn__conv_sub_rows(g);
    j->mparts = 1;
    j->scratch_floats = (floats + 15) / 16 * 16; /* 64-byte aligned per thread */
    j->scratch = tn__ctx_floats(ctx, (size_t)tn_get_threads() * j->scratch_floats, 0);
    return j->scratch != NULL;
}

/* Column buffer of one sub-band (im2col for the weight gradient, W^T dy for col2im). */
static size_t tn__conv_col_floats(const tn__conv_geom *g)
{
    return (size_t)g->C * g->KH * g->KW * tn__conv_sub_rows(g) * g->OW;
}

/* Runs fn over the pool, or inline when there is a single item (the GEMMs then use the pool). */
static void tn__conv_run(tn_task_fn fn, tn__conv_job *j, int items)
{
    j->next = 0;
    if (items <= 1 || tn_get_threads() <= 1) fn(j, 0, 1);
    else tn_parallel_run(fn, j);
}

/* y = beta * y + conv(x, w) (+ bias): x N x g.C x H x W, w M x K, y N x M x OH x OW. */
static int tn__conv_forward(tn_ctx *ctx, const tn__conv_geom *g, int N, int M, const float *x, const float *w,
                            const float *bias, float *y, float beta)
{
    tn__conv_job j;
    int items, nth = tn_get_threads(), mtiles = (M + TN__GEMM_MR - 1) / TN__GEMM_MR;
    if (!tn__conv_job_init(ctx, &j, g, N, M, tn__conv_groups(g, M), tn__sgemm_gen_b_floats(M) + TN__CONV_TINY))
        return 0;
    j.sub = (int)(TN__CONV_FWD_PIX / (size_t)g->OW); /* pixels per GEMM */
    if (j.sub < 1) j.sub = 1;
    items = N * j.groups;
    if (items < 2 * nth) { /* few groups (small images): also split the output channels */
        j.mparts = (2 * nth + items - 1) / items;
        if (j.mparts > mtiles) j.mparts = mtiles;
    }
    j.x = x;
    j.w = j.wb = w;
    j.bias = bias;
    j.y = y;
    j.beta = beta;
    if (bias) { /* M x (K + 1): [w | bias] */
        float *wb = tn__ctx_floats(ctx, (size_t)M * (j.K + 1), 0);
        int m;
        if (!wb) return 0;
        for (m = 0; m < M; m++) {
            memcpy(wb + (size_t)m * (j.K + 1), w + (size_t)m * j.K, (size_t)j.K * sizeof(float));
            wb[(size_t)m * (j.K + 1) + j.K] = bias[m];
        }
        j.wb = wb;
    }
    tn__conv_run(tn__conv_fwd_task, &j, items * j.mparts);
    return 1;
}

/* Adds bias[c] to every pixel of channel c; its gradient is the per-channel sum. */
static void tn__bias_add(float *y, const float *bias, int N, int C, size_t hw)
{
    int n, c;
    size_t i;
    for (n = 0; n < N; n++)
        for (c = 0; c < C; c++) {
            float *p = y + ((size_t)n * C + c) * hw, b = bias[c];
            for (i = 0; i < hw; i++) p[i] += b;
        }
}

typedef struct tn__bias_job { float *gb; const float *gy; int N, C; size_t hw; } tn__bias_job;

static void tn__bias_grad_channels(void *ctx, size_t cb, size_t ce)
{
    const tn__bias_job *j = (const tn__bias_job *)ctx;
    size_t c;
    int n;
    for (c = cb; c < ce; c++)
        for (n = 0; n < j->N; n++) j->gb[c] += (float)tn__sum_floats(j->gy + ((size_t)n * j->C + c) * j->hw, j->hw);
}

static void tn__bias_grad(float *gb, const float *gy, int N, int C, size_t hw)
{
    tn__bias_job j;
    j.gb = gb;
    j.gy = gy;
    j.N = N;
    j.C = C;
    j.hw = hw;
    tn_parallel_for((size_t)C, hw * N >= 16384 ? 1 : (size_t)C, tn__bias_grad_channels, &j);
}

typedef struct tn__conv_sum_job {
    float *dw, *db;
    const float *parts;
    size_t n;
    int groups, M, K, kd, transposed;
} tn__conv_sum_job;

/* Element i = (m, k) of the M x kd weight(+bias) gradient += the groups' partials, in group order. */
static void tn__conv_sum_parts(void *ctx, size_t b, size_t e)
{
    const tn__conv_sum_job *s = (const tn__conv_sum_job *)ctx;
    size_t i;
    int k;
    for (i = b; i < e; i++) {
        size_t m = i / (size_t)s->kd, c = i % (size_t)s->kd, at = s->transposed ? c * s->M + m : i;
        float acc = s->parts[at];
        for (k = 1; k < s->groups; k++) acc += s->parts[(size_t)k * s->n + at];
        if (c < (size_t)s->K) s->dw[m * s->K + c] += acc;
        else s->db[m] += acc;
    }
}

/* Whether the weight gradient is better computed transposed (col dy^T): the micro-kernel pads
   rows to MR and columns to NR, so take the form with less padding (a lone bias column would
   cost a whole NR panel), then the one whose packing has fewer element-by-element leftovers. */
static int tn__conv_dw_transposed(int M, int K)
{
    long long mr = TN__GEMM_MR, nr = TN__GEMM_NR;
    long long plain = (M + mr - 1) / mr * mr * ((K + nr - 1) / nr * nr), trans = (K + mr - 1) / mr * mr * ((M + nr - 1) / nr * nr);
    if (plain != trans) return trans < plain;
    return K % TN__GEMM_MR + M % TN__GEMM_NR < M % TN__GEMM_MR + K % TN__GEMM_NR;
}

/* dw (M x K) += sum over images of dy (M x OH*OW) x im2col(x)^T, and db (M, if not NULL) += the
   sums of dy's channels, taken in the same pass over dy (1x1: separately). */
static int tn__conv_weight_grad(tn_ctx *ctx, const tn__conv_geom *g, int N, int M, const float *x, const float *dy,
                                float *dw, float *db)
{
    tn__conv_job j;
    tn__conv_sum_job s;
    int fuse = db && !tn__conv_is_1x1(g);
    if (db && !fuse) tn__bias_grad(db, dy, N, M, (size_t)g->OH * g->OW);
    if (!tn__conv_job_init(ctx, &j, g, N, M, tn__conv_groups(g, M), tn__conv_col_floats(g) + (size_t)g->OH * g->OW))
        return 0;
    j.x = x;
    j.dy = dy;
    j.kd = j.K + fuse;
    j.phase = tn__conv_dw_transposed(M, j.kd); /* here: the partials are kd x M */
    j.dw_direct = j.groups == 1 && !j.phase && !fuse;
    j.dw = j.dw_direct ? dw : tn__ctx_floats(ctx, (size_t)j.groups * M * j.kd, 0);
    if (!j.dw) return 0;
    tn__conv_run(tn__conv_dw_task, &j, j.groups);
    if (j.dw_direct) return 1;
    s.dw = dw;
    s.db = db;
    s.parts = j.dw;
    s.n = (size_t)M * j.kd;
    s.groups = j.groups;
    s.M = M;
    s.K = j.K;
    s.kd = j.kd;
    s.transposed = j.phase;
    tn_parallel_for(s.n, 16384, tn__conv_sum_parts, &s);
    return 1;
}

/* Hull [*lo, *hi] of the input rows that output rows [r0, r1) read; *lo > *hi when none. */
static void tn__conv_row_hull(const tn__conv_geom *g, int r0, int r1, int *lo, int *hi)
{
    int oy, ky;
    *lo = g->H;
    *hi = -1;
    for (oy = r0; oy < r1; oy++)
        for (ky = 0; ky < g->KH; ky++) {
            int iy = tn__conv_src(oy, ky, g->stride, g->pad, g->dil, g->H, g->reflect);
            if (iy < 0) continue;
            if (iy < *lo) *lo = iy;
            if (iy > *hi) *hi = iy;
        }
}

/* Most groups (<= `groups`) for which groups g and g + 2 read disjoint input rows, so each col2im
   phase (even or odd groups) can run in parallel without two threads adding into one element. */
static int tn__conv_col2im_groups(const tn__conv_geom *g, int groups)
{
    for (; groups > 2; groups--) {
        int k, ok = 1, lo0, hi0, lo2, hi2;
        for (k = 0; ok && k + 2 < groups; k++) {
            tn__conv_row_hull(g, (int)((long long)g->OH * k / groups), (int)((long long)g->OH * (k + 1) / groups), &lo0, &hi0);
            tn__conv_row_hull(g, (int)((long long)g->OH * (k + 2) / groups), (int)((long long)g->OH * (k + 3) / groups), &lo2, &hi2);
            ok = lo0 > hi0 || lo2 > hi2 || hi0 < lo2 || hi2 < lo0;
        }
        if (ok) break;
    }
    return groups;
}

/* dx = beta * dx + conv^T(dy, w): the input gradient of y = conv(x, w) (x N x g.C x H x W). */
static int tn__conv_input_grad(tn_ctx *ctx, const tn__conv_geom *g, int N, int M, const float *dy, const float *w,
                               float *dx, float beta)
{
    tn__conv_job j;
    int pad2 = (g->KH - 1) * g->dil - g->pad;
    if (g->stride == 1 && !g->reflect && g->KH == g->KW && pad2 >= 0 && g->C >= 8 &&
        g->OH + 2 * pad2 - g->dil * (g->KH - 1) == g->H && g->OW + 2 * pad2 - g->dil * (g->KW - 1) == g->W) {
        /* dx = conv(dy, w'), w'[c][m][ky][kx] = w[m][c][KH-1-ky][KW-1-kx], padding dil*(K-1) - pad */
        tn__conv_geom f;
        size_t kk = (size_t)g->KH * g->KW, c, m, t;
        float *wf = tn__ctx_floats(ctx, (size_t)g->C * M * kk, 0);
        if (!wf) return 0;
        for (c = 0; c < (size_t)g->C; c++)
            for (m = 0; m < (size_t)M; m++)
                for (t = 0; t < kk; t++) wf[(c * M + m) * kk + t] = w[(m * g->C + c) * kk + kk - 1 - t];
        f = *g;
        f.C = M; f.H = g->OH; f.W = g->OW; f.OH = g->H; f.OW = g->W; f.pad = pad2;
        return tn__conv_forward(ctx, &f, N, g->C, dy, wf, NULL, dx, beta);
    }
    if (beta == 0.0f) memset(dx, 0, (size_t)N * g->C * g->H * g->W * sizeof(float));
    if (!tn__conv_job_init(ctx, &j, g, N, M, tn__conv_col2im_groups(g, tn__conv_groups(g, M)), tn__conv_col_floats(g)))
        return 0;
    j.w = w;
    j.dy = dy;
    j.dx = dx;
    for (j.phase = 0; j.phase < 2 && j.phase < j.groups; j.phase++)
        tn__conv_run(tn__conv_dx_task, &j, N * ((j.groups - j.phase + 1) / 2));
    return 1;
}

static void tn__conv_geom_read(tn__conv_geom *g, const tn_tensor *t)
{
    g->C = t->ip[0]; g->H = t->ip[1]; g->W = t->ip[2]; g->KH = t->ip[3]; g->KW = t->ip[4];
    g->OH = t->ip[5]; g->OW = t->ip[6]; g->stride = t->ip[7]; g->pad = t->ip[8]; g->dil = t->ip[9];
    g->reflect = t->ip[10];
}

static void tn__conv_geom_write(const tn__conv_geom *g, tn_tensor *t)
{
    t->ip[0] = g->C; t->ip[1] = g->H; t->ip[2] = g->W; t->ip[3] = g->KH; t->ip[4] = g->KW;
    t->ip[5] = g->OH; t->ip[6] = g->OW; t->ip[7] = g->stride; t->ip[8] = g->pad; t->ip[9] = g->dil;
    t->ip[10] = g->reflect;
}

static void tn__conv2d_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0], *w = out->src[1], *b = out->src[2];
    tn__conv_geom g;
    int N = x->shape[0], Cout = w->shape[0];
    float *db = b && b->requires_grad ? tn__grad(ctx, b) : NULL;
    tn__conv_geom_read(&g, out);
    if (b && b->requires_grad && !db) return;
    if (w->requires_grad) { /* the bias gradient rides along */
        if (!tn__grad(ctx, w) || !tn__conv_weight_grad(ctx, &g, N, Cout, x->data, out->grad, w->grad, db)) return;
    } else if (db) {
        tn__bias_grad(db, out->grad, N, Cout, (size_t)g.OH * g.OW);
    }
    if (x->requires_grad && tn__grad(ctx, x)) tn__conv_input_grad(ctx, &g, N, Cout, out->grad, w->data, x->grad, 1.0f);
}

/* The zero rules of tn_conv_opts: stride and dilation 1 (also for negative values). */
static void tn__conv_opts_defaults(tn_conv_opts *o)
{
    if (o->stride <= 0) o->stride = 1;
    if (o->dilation <= 0) o->dilation = 1;
}

TN_API tn_tensor *tn_conv2d(tn_ctx *ctx, tn_tensor *x, tn_tensor *w, tn_tensor *bias, const tn_conv_opts *opts)
{
    tn__conv_geom g;
    tn_conv_opts co;
    tn_tensor *o;
    int shape[4];
    if (!x || !w) return NULL;
    TN_ASSERT(x->ndim == 4 && w->ndim == 4 && w->shape[1] == x->shape[1]);
    memset(&co, 0, sizeof co);
    if (opts) co = *opts;
    tn__conv_opts_defaults(&co);
    g.C = x->shape[1]; g.H = x->shape[2]; g.W = x->shape[3];
    g.KH = w->shape[2]; g.KW = w->shape[3];
    g.stride = co.stride;
    g.pad = co.pad;
    g.dil = co.dilation;
    g.reflect = co.padding == TN_PADDING_REFLECT;
    TN_ASSERT(!g.reflect || (g.pad < g.H && g.pad < g.W));
    g.OH = (g.H + 2 * g.pad - g.dil * (g.KH - 1) - 1) / g.stride + 1;
    g.OW = (g.W + 2 * g.pad - g.dil * (g.KW - 1) - 1) / g.stride + 1;
    TN_ASSERT(g.OH >= 1 && g.OW >= 1);
    TN_ASSERT(!bias || (int)bias->numel == w->shape[0]);
    shape[0] = x->shape[0]; shape[1] = w->shape[0]; shape[2] = g.OH; shape[3] = g.OW;
    o = tn__op_make(ctx, 4, shape, tn__conv2d_backward, x, w, bias, 0); /* every element is written */
    if (!o) return NULL;
    tn__conv_geom_write(&g, o);
    if (!tn__conv_forward(ctx, &g, shape[0], shape[1], x->data, w->data, bias ? bias->data : NULL, o->data, 0.0f))
        return NULL;
    return o;
}

/* Transposed convolution: y = conv^T(x, w) for the conv whose input is y (g.C = Cout, g.H/W = y
   size, g.OH/OW = x size), so its forward is that conv's input gradient, and its backward is that
   conv's forward (dx) and weight gradient (dw). */
static void tn__convt_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0], *w = out->src[1], *b = out->src[2];
    tn__conv_geom g;
    int N = x->shape[0], Cin = x->shape[1];
    tn__conv_geom_read(&g, out);
    if (b && b->requires_grad && tn__grad(ctx, b)) tn__bias_grad(b->grad, out->grad, N, g.C, (size_t)g.H * g.W);
    if (x->requires_grad && tn__grad(ctx, x) && !tn__conv_forward(ctx, &g, N, Cin, out->grad, w->data, NULL, x->grad, 1.0f))
        return;
    if (w->requires_grad && tn__grad(ctx, w)) tn__conv_weight_grad(ctx, &g, N, Cin, out->grad, x->data, w->grad, NULL);
}

TN_API tn_tensor *tn_conv_transpose2d(tn_ctx *ctx, tn_tensor *x, tn_tensor *w, tn_tensor *bias, const tn_conv_opts *opts)
{
    tn__conv_geom g;
    tn_conv_opts co;
    tn_tensor *o;
    int op, shape[4];
    if (!x || !w) return NULL;
    TN_ASSERT(x->ndim == 4 && w->ndim == 4 && w->shape[0] == x->shape[1]);
    memset(&co, 0, sizeof co);
    if (opts) co = *opts;
    tn__conv_opts_defaults(&co);
    g.C = w->shape[1];
    g.KH = w->shape[2]; g.KW = w->shape[3];
    g.stride = co.stride;
    g.pad = co.pad;
    g.dil = co.dilation;
    g.reflect = 0;
    op = co.output_padding;
    g.OH = x->shape[2]; g.OW = x->shape[3];
    g.H = (g.OH - 1) * g.stride - 2 * g.pad + g.dil * (g.KH - 1) + op + 1;
    g.W = (g.OW - 1) * g.stride - 2 * g.pad + g.dil * (g.KW - 1) + op + 1;
    TN_ASSERT(g.H >= 1 && g.W >= 1);
    TN_ASSERT(!bias || (int)bias->numel == g.C);
    shape[0] = x->shape[0]; shape[1] = g.C; shape[2] = g.H; shape[3] = g.W;
    o = tn__op_make(ctx, 4, shape, tn__convt_backward, x, w, bias, 0); /* input_grad with beta 0 writes all */
    if (!o) return NULL;
    tn__conv_geom_write(&g, o);
    if (!tn__conv_input_grad(ctx, &g, shape[0], x->shape[1], x->data, w->data, o->data, 0.0f)) return NULL;
    if (bias) tn__bias_add(o->data, bias->data, shape[0], g.C, (size_t)g.H * g.W);
    return o;
}

/* ---- pooling and upsampling ---- */

static void tn__pool_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    int k = out->ip[0], s = out->ip[1], is_max = out->ip[2];
    int H = x->shape[2], W = x->shape[3], OH = out->shape[2], OW = out->shape[3];
    size_t nc, NC = (size_t)x->shape[0] * x->shape[1];
    const int *arg = (const int *)out->aux;
    if (!tn__grad(ctx, x)) return;
    for (nc = 0; nc < NC; nc++) {
        int oy, ox, dy, dx;
        float *gx = x->grad + nc * H * W;
        const float *go = out->grad + nc * OH * OW;
        for (oy = 0; oy < OH; oy++)
            for (ox = 0; ox < OW; ox++) {
                size_t oi = (size_t)oy * OW + ox;
                if (is_max) gx[arg[nc * OH * OW + oi]] += go[oi];
                else
                    for (dy = 0; dy < k; dy++)
                        for (dx = 0; dx < k; dx++) gx[(size_t)(oy * s + dy) * W + ox * s + dx] += go[oi] / (float)(k * k);
            }
    }
}

static tn_tensor *tn__pool2d(tn_ctx *ctx, tn_tensor *x, int k, int s, int is_max)
{
    int shape[4], H, W, OH, OW;
    size_t nc, NC;
    tn_tensor *o;
    int *arg = NULL;
    if (!x) return NULL;
    TN_ASSERT(x->ndim == 4 && k >= 1 && s >= 1 && x->shape[2] >= k && x->shape[3] >= k);
    H = x->shape[2]; W = x->shape[3];
    OH = (H - k) / s + 1; OW = (W - k) / s + 1;
    shape[0] = x->shape[0]; shape[1] = x->shape[1]; shape[2] = OH; shape[3] = OW;
    o = tn__op(ctx, 4, shape, tn__pool_backward, x, NULL, NULL);
    if (!o) return NULL;
    o->ip[0] = k; o->ip[1] = s; o->ip[2] = is_max;
    NC = (size_t)x->shape[0] * x->shape[1];
    if (is_max) {
        arg = (int *)tn_ctx_alloc(ctx, o->numel * sizeof(int));
        if (!arg) return NULL;
        o->aux = arg;
    }
    for (nc = 0; nc < NC; nc++) {
        int oy, ox, dy, dx;
        const float *xi = x->data + nc * H * W;
        for (oy = 0; oy < OH; oy++)
            for (ox = 0; ox < OW; ox++) {
                float acc = is_max ? -FLT_MAX : 0.0f;
                int best = 0;
                for (dy = 0; dy < k; dy++)
                    for (dx = 0; dx < k; dx++) {
                        int idx = (oy * s + dy) * W + ox * s + dx;
                        float v = xi[idx];
                        if (!is_max) acc += v;
                        else if (v > acc) { acc = v; best = idx; }
                    }
                o->data[nc * OH * OW + (size_t)oy * OW + ox] = is_max ? acc : acc / (float)(k * k);
                if (is_max) arg[nc * OH * OW + (size_t)oy * OW + ox] = best;
            }
    }
    return o;
}

TN_API tn_tensor *tn_avg_pool2d(tn_ctx *ctx, tn_tensor *x, int k, int s) { return tn__pool2d(ctx, x, k, s, 0); }
TN_API tn_tensor *tn_max_pool2d(tn_ctx *ctx, tn_tensor *x, int k, int s) { return tn__pool2d(ctx, x, k, s, 1); }

/* Bilinear source coordinate (align_corners = false), clamped like PyTorch. */
static void tn__bilinear_src(int o, int in, int out, int *i0, int *i1, float *f)
{
    float s = ((float)o + 0.5f) * (float)in / (float)out - 0.5f;
    if (s < 0) s = 0;
    *i0 = (int)s;
    if (*i0 > in - 1) *i0 = in - 1;
    *i1 = *i0 + 1 < in ? *i0 + 1 : *i0;
    *f = s - (float)*i0;
}

static void tn__upsample_walk(const tn_tensor *x, const tn_tensor *o, const float *src, float *dst, int backward)
{
    int H = x->shape[2], W = x->shape[3], OH = o->shape[2], OW = o->shape[3], mode = o->ip[0];
    size_t nc, NC = (size_t)x->shape[0] * x->shape[1];
    for (nc = 0; nc < NC; nc++) {
        int oy, ox;
        const float *s_in = backward ? NULL : src + nc * H * W;
        float *d_in = backward ? dst + nc * H * W : NULL;
        for (oy = 0; oy < OH; oy++) {
            int y0, y1;
            float fy;
            if (mode == 0) { y0 = y1 = oy * H / OH; fy = 0; }
            else tn__bilinear_src(oy, H, OH, &y0, &y1, &fy);
            for (ox = 0; ox < OW; ox++) {
                int x0, x1;
                float fx;
                size_t oi = nc * OH * OW + (size_t)oy * OW + ox;
                if (mode == 0) { x0 = x1 = ox * W / OW; fx = 0; }
                else tn__bilinear_src(ox, W, OW, &x0, &x1, &fx);
                if (backward) {
                    float g = src[oi];
                    d_in[y0 * W + x0] += g * (1 - fy) * (1 - fx);
                    d_in[y0 * W + x1] += g * (1 - fy) * fx;
                    d_in[y1 * W + x0] += g * fy * (1 - fx);
                    d_in[y1 * W + x1] += g * fy * fx;
                } else {
                    float a = s_in[y0 * W + x0] + fx * (s_in[y0 * W + x1] - s_in[y0 * W + x0]);
                    float b = s_in[y1 * W + x0] + fx * (s_in[y1 * W + x1] - s_in[y1 * W + x0]);
                    dst[oi] = a + fy * (b - a);
                }
            }
        }
    }
}

static void tn__upsample_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    if (!tn__grad(ctx, x)) return;
    tn__upsample_walk(x, out, out->grad, x->grad, 1);
}

static tn_tensor *tn__upsample(tn_ctx *ctx, tn_tensor *x, int oh, int ow, int mode)
{
    int shape[4];
    tn_tensor *o;
    if (!x) return NULL;
    TN_ASSERT(x->ndim == 4 && oh >= 1 && ow >= 1);
    shape[0] = x->shape[0]; shape[1] = x->shape[1]; shape[2] = oh; shape[3] = ow;
    o = tn__op(ctx, 4, shape, tn__upsample_backward, x, NULL, NULL);
    if (!o) return NULL;
    o->ip[0] = mode;
    tn__upsample_walk(x, o, x->data, o->data, 0);
    return o;
}

TN_API tn_tensor *tn_upsample_nearest(tn_ctx *ctx, tn_tensor *x, int factor)
{
    TN_ASSERT(factor >= 1);
    return x ? tn__upsample(ctx, x, x->shape[2] * factor, x->shape[3] * factor, 0) : NULL;
}

TN_API tn_tensor *tn_upsample_bilinear(tn_ctx *ctx, tn_tensor *x, int out_h, int out_w)
{
    return tn__upsample(ctx, x, out_h, out_w, 1);
}

/* ---- normalisation ----
   One kernel serves batch and instance norm: a "set" is the group of elements sharing a mean
   (a channel across the batch, or one (n, c) plane). aux keeps mean and 1/std per set. */

typedef struct tn__norm_info { int per_instance; int nset; float eps; } tn__norm_info;

static int tn__norm_set(const tn_tensor *x, int per_instance, int n, int c)
{
    return per_instance ? n * x->shape[1] + c : c;
}

static void tn__norm_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0], *gamma = out->src[1], *beta = out->src[2];
    int N = x->shape[0], C = x->shape[1], per_inst = out->ip[0], training = out->ip[1], n, c, s;
    int nset = per_inst ? N * C : C;
    size_t hw = (size_t)x->shape[2] * x->shape[3], i;
    const float *mean = (const float *)out->aux, *istd = mean + nset;
    double *sg = (double *)tn_ctx_alloc(ctx, 2 * (size_t)nset * sizeof(double)), *sgx;
    if (!sg) return;
    sgx = sg + nset;
    memset(sg, 0, 2 * (size_t)nset * sizeof(double));
    /* sums of dy*gamma and dy*gamma*xhat per set, and the affine gradients */
    for (n = 0; n < N; n++)
        for (c = 0; c < C; c++) {
            const float *xp = x->data + ((size_t)n * C + c) * hw, *gp = out->grad + ((size_t)n * C + c) * hw;
            float gm = gamma ? gamma->data[c] : 1.0f;
            double a = 0, b = 0;
            s = tn__norm_set(x, per_inst, n, c);
            for (i = 0; i < hw; i++) {
                double xh = ((double)xp[i] - mean[s]) * istd[s];
                a += gp[i];
                b += gp[i] * xh;
            }
            if (gamma && gamma->requires_grad && tn__grad(ctx, gamma)) gamma->grad[c] += (float)b;
            if (beta && beta->requires_grad && tn__grad(ctx, beta)) beta->grad[c] += (float)a;
            sg[s] += a * gm;
            sgx[s] += b * gm;
        }
    if (!x->requires_grad || !tn__grad(ctx, x)) return;
    for (n = 0; n < N; n++)
        for (c = 0; c < C; c++) {
            const float *xp = x->data + ((size_t)n * C + c) * hw, *gp = out->grad + ((size_t)n * C + c) * hw;
            float *dx = x->grad + ((size_t)n * C + c) * hw;
            float gm = gamma ? gamma->data[c] : 1.0f;
            double m = per_inst ? (double)hw : (double)hw * N;
            s = tn__norm_set(x, per_inst, n, c);
            for (i = 0; i < hw; i++) {
                if (!training) dx[i] += gp[i] * gm * istd[s];
                else {
                    double xh = ((double)xp[i] - mean[s]) * istd[s];
                    dx[i] += (float)(istd[s] / m * (m * gp[i] * gm - sg[s] - xh * sgx[s]));
                }
            }
        }
}

static tn_tensor *tn__norm(tn_ctx *ctx, tn_tensor *x, tn_tensor *gamma, tn_tensor *beta, int per_inst, int training,
                           tn_tensor *rmean, tn_tensor *rvar, float eps)
{
    int N, C, n, c, s, nset;
    size_t hw, i;
    tn_tensor *o;
    float *mean, *istd;
    if (!x) return NULL;
    TN_ASSERT(x->ndim == 4);
    N = x->shape[0];
    C = x->shape[1];
    hw = (size_t)x->shape[2] * x->shape[3];
    nset = per_inst ? N * C : C;
    TN_ASSERT(!gamma || (int)gamma->numel == C);
    TN_ASSERT(!beta || (int)beta->numel == C);
    o = tn__op(ctx, 4, x->shape, tn__norm_backward, x, gamma, beta);
    if (!o) return NULL;
    o->ip[0] = per_inst;
    o->ip[1] = training;
    mean = tn__ctx_floats(ctx, 2 * (size_t)nset, 1);
    if (!mean) return NULL;
    istd = mean + nset;
    o->aux = mean;
    if (training) {
        double *s1 = (double *)tn_ctx_alloc(ctx, 2 * (size_t)nset * sizeof(double)), *s2;
        if (!s1) return NULL;
        s2 = s1 + nset;
        memset(s1, 0, 2 * (size_t)nset * sizeof(double));
        for (n = 0; n < N; n++)
            for (c = 0; c < C; c++) {
                const float *xp = x->data + ((size_t)n * C + c) * hw;
                s = tn__norm_set(x, per_inst, n, c);
                for (i = 0; i < hw; i++) s1[s] += xp[i];
            }
        for (s = 0; s < nset; s++) s1[s] /= (double)hw * (per_inst ? 1 : N);
        for (n = 0; n < N; n++)
            for (c = 0; c < C; c++) {
                const float *xp = x->data + ((size_t)n * C + c) * hw;
                s = tn__norm_set(x, per_inst, n, c);
                for (i = 0; i < hw; i++) s2[s] += ((double)xp[i] - s1[s]) * ((double)xp[i] - s1[s]);
            }
        for (s = 0; s < nset; s++) {
            double m = (double)hw * (per_inst ? 1 : N), var = s2[s] / m;
            mean[s] = (float)s1[s];
            istd[s] = (float)(1.0 / sqrt(var + eps));
            if (!per_inst && rmean && rvar) { /* PyTorch: running var uses the unbiased variance */
                rmean->data[s] = 0.9f * rmean->data[s] + 0.1f * (float)s1[s];
                rvar->data[s] = 0.9f * rvar->data[s] + 0.1f * (float)(m > 1 ? s2[s] / (m - 1) : var);
            }
        }
    } else {
        TN_ASSERT(rmean && rvar);
        for (s = 0; s < nset; s++) {
            mean[s] = rmean->data[s];
            istd[s] = 1.0f / sqrtf(rvar->data[s] + eps);
        }
    }
    for (n = 0; n < N; n++)
        for (c = 0; c < C; c++) {
            const float *xp = x->data + ((size_t)n * C + c) * hw;
            float *yp = o->data + ((size_t)n * C + c) * hw;
            float g = gamma ? gamma->data[c] : 1.0f, b = beta ? beta->data[c] : 0.0f;
            s = tn__norm_set(x, per_inst, n, c);
            for (i = 0; i < hw; i++) yp[i] = (xp[i] - mean[s]) * istd[s] * g + b;
        }
    return o;
}

TN_API tn_tensor *tn_batch_norm(tn_ctx *ctx, tn_tensor *x, tn_tensor *gamma, tn_tensor *beta, tn_tensor *running_mean,
                                tn_tensor *running_var, int training, float eps)
{
    return tn__norm(ctx, x, gamma, beta, 0, training, running_mean, running_var, eps);
}

TN_API tn_tensor *tn_instance_norm(tn_ctx *ctx, tn_tensor *x, tn_tensor *gamma, tn_tensor *beta, float eps)
{
    return tn__norm(ctx, x, gamma, beta, 1, 1, NULL, NULL, eps);
}

TN_API tn_tensor *tn_spade_norm(tn_ctx *ctx, tn_tensor *x, tn_tensor *gamma, tn_tensor *beta, float eps)
{
    tn_tensor *xn = tn_instance_norm(ctx, x, NULL, NULL, eps);
    return tn_add(ctx, tn_mul(ctx, xn, tn_scale_shift(ctx, gamma, 1.0f, 1.0f)), beta);
}

/* ---- spectral norm ---- */

static void tn__spectral_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *w = out->src[0];
    int rows = w->shape[0], cols = (int)(w->numel / (size_t)rows), r, c;
    const float *u = (const float *)out->aux, *v = u + rows;
    float sigma = out->fp[0];
    double dot = 0;
    size_t i;
    if (!tn__grad(ctx, w)) return;
    for (i = 0; i < w->numel; i++) dot += (double)out->grad[i] * out->data[i];
    for (r = 0; r < rows; r++)
        for (c = 0; c < cols; c++) {
            size_t k = (size_t)r * cols + c;
            w->grad[k] += (float)((out->grad[k] - dot * u[r] * v[c]) / sigma);
        }
}

static float tn__normalize(float *x, int n)
{
    double s = 0;
    int i;
    for (i = 0; i < n; i++) s += (double)x[i] * x[i];
    s = sqrt(s) + 1e-12;
    for (i = 0; i < n; i++) x[i] = (float)(x[i] / s);
    return (float)s;
}

TN_API tn_tensor *tn_spectral_norm(tn_ctx *ctx, tn_tensor *w, tn_tensor *u, int iters)
{
    int rows, cols, it, r;
    float *uv, *v, sigma;
    tn_tensor *o;
    size_t i;
    if (!w || !u) return NULL;
    rows = w->shape[0];
    cols = (int)(w->numel / (size_t)rows);
    TN_ASSERT((int)u->numel == rows);
    o = tn__op(ctx, w->ndim, w->shape, tn__spectral_backward, w, NULL, NULL);
    uv = tn__ctx_floats(ctx, (size_t)rows + cols, 0);
    if (!o || !uv) return NULL;
    v = uv + rows;
    if (tn__normalize(u->data, rows) < 1e-6f) { /* a zero vector: restart from a fixed one */
        for (r = 0; r < rows; r++) u->data[r] = 1.0f;
        tn__normalize(u->data, rows);
    }
    for (it = 0; it < (iters < 1 ? 1 : iters); it++) {
        tn_sgemm(1, 0, cols, 1, rows, 1.0f, w->data, cols, u->data, 1, 0.0f, v, 1); /* v = W^T u */
        tn__normalize(v, cols);
        tn_sgemm(0, 0, rows, 1, cols, 1.0f, w->data, cols, v, 1, 0.0f, u->data, 1); /* u = W v */
        tn__normalize(u->data, rows);
    }
    memcpy(uv, u->data, (size_t)rows * sizeof(float));
    {
        double s = 0; /* sigma = u^T W v */
        for (r = 0; r < rows; r++) {
            double d = 0;
            int c;
            for (c = 0; c < cols; c++) d += (double)w->data[(size_t)r * cols + c] * v[c];
            s += d * uv[r];
        }
        sigma = (float)(fabs(s) > 1e-12 ? s : 1e-12);
    }
    o->aux = uv;
    o->fp[0] = sigma;
    for (i = 0; i < w->numel; i++) o->data[i] = w->data[i] / sigma;
    return o;
}

/* ---- graph ops ---- */

static void tn__gather_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    const int *idx = (const int *)out->aux;
    int i, n = out->shape[0];
    size_t d = out->numel / (size_t)n, k;
    if (!tn__grad(ctx, x)) return;
    for (i = 0; i < n; i++)
        for (k = 0; k < d; k++) x->grad[(size_t)idx[i] * d + k] += out->grad[(size_t)i * d + k];
}

static int *tn__copy_index(tn_ctx *ctx, const int *idx, int n)
{
    int *p = (int *)tn_ctx_alloc(ctx, (size_t)n * sizeof(int));
    if (p) memcpy(p, idx, (size_t)n * sizeof(int));
    return p;
}

TN_API tn_tensor *tn_gather_rows(tn_ctx *ctx, tn_tensor *x, const int *idx, int n)
{
    int shape[4], i;
    size_t d;
    tn_tensor *o;
    if (!x) return NULL;
    TN_ASSERT(n >= 1);
    memcpy(shape, x->shape, sizeof shape);
    shape[0] = n;
    d = x->numel / (size_t)x->shape[0];
    o = tn__op(ctx, x->ndim, shape, tn__gather_backward, x, NULL, NULL);
    if (!o || !(o->aux = tn__copy_index(ctx, idx, n))) return NULL;
    for (i = 0; i < n; i++) {
        TN_ASSERT(idx[i] >= 0 && idx[i] < x->shape[0]);
        memcpy(o->data + (size_t)i * d, x->data + (size_t)idx[i] * d, d * sizeof(float));
    }
    return o;
}

static void tn__scatter_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    const int *seg = (const int *)out->aux;
    int i, n = x->shape[0];
    size_t d = x->numel / (size_t)n, k;
    if (!tn__grad(ctx, x)) return;
    for (i = 0; i < n; i++)
        for (k = 0; k < d; k++) x->grad[(size_t)i * d + k] += out->grad[(size_t)seg[i] * d + k];
}

TN_API tn_tensor *tn_scatter_add_rows(tn_ctx *ctx, tn_tensor *x, const int *seg, int nseg)
{
    int shape[4], i, n;
    size_t d, k;
    tn_tensor *o;
    if (!x) return NULL;
    TN_ASSERT(nseg >= 1);
    n = x->shape[0];
    memcpy(shape, x->shape, sizeof shape);
    shape[0] = nseg;
    d = x->numel / (size_t)n;
    o = tn__op(ctx, x->ndim, shape, tn__scatter_backward, x, NULL, NULL);
    if (!o || !(o->aux = tn__copy_index(ctx, seg, n))) return NULL;
    for (i = 0; i < n; i++) {
        TN_ASSERT(seg[i] >= 0 && seg[i] < nseg);
        for (k = 0; k < d; k++) o->data[(size_t)seg[i] * d + k] += x->data[(size_t)i * d + k];
    }
    return o;
}

static void tn__segsoftmax_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    const int *seg = (const int *)out->aux;
    int E = x->shape[0], H = (int)(x->numel / (size_t)E), nseg = out->ip[0], e, h;
    double *dot = (double *)tn_ctx_alloc(ctx, (size_t)nseg * H * sizeof(double));
    if (!dot || !tn__grad(ctx, x)) return;
    memset(dot, 0, (size_t)nseg * H * sizeof(double));
    for (e = 0; e < E; e++)
        for (h = 0; h < H; h++) dot[(size_t)seg[e] * H + h] += (double)out->grad[(size_t)e * H + h] * out->data[(size_t)e * H + h];
    for (e = 0; e < E; e++)
        for (h = 0; h < H; h++) {
            size_t k = (size_t)e * H + h;
            x->grad[k] += (float)(out->data[k] * (out->grad[k] - dot[(size_t)seg[e] * H + h]));
        }
}

TN_API tn_tensor *tn_segment_softmax(tn_ctx *ctx, tn_tensor *scores, const int *seg, int nseg)
{
    int E, H, e, h;
    float *mx;
    double *sum;
    tn_tensor *o;
    if (!scores) return NULL;
    E = scores->shape[0];
    H = (int)(scores->numel / (size_t)E);
    o = tn__op(ctx, scores->ndim, scores->shape, tn__segsoftmax_backward, scores, NULL, NULL);
    if (!o || !(o->aux = tn__copy_index(ctx, seg, E))) return NULL;
    o->ip[0] = nseg;
    mx = tn__ctx_floats(ctx, (size_t)nseg * H, 0);
    sum = (double *)tn_ctx_alloc(ctx, (size_t)nseg * H * sizeof(double));
    if (!mx || !sum) return NULL;
    for (e = 0; e < nseg * H; e++) { mx[e] = -FLT_MAX; sum[e] = 0; }
    for (e = 0; e < E; e++) {
        TN_ASSERT(seg[e] >= 0 && seg[e] < nseg);
        for (h = 0; h < H; h++) {
            float v = scores->data[(size_t)e * H + h];
            if (v > mx[(size_t)seg[e] * H + h]) mx[(size_t)seg[e] * H + h] = v;
        }
    }
    for (e = 0; e < E; e++)
        for (h = 0; h < H; h++) {
            size_t k = (size_t)e * H + h, s = (size_t)seg[e] * H + h;
            o->data[k] = expf(scores->data[k] - mx[s]);
            sum[s] += o->data[k];
        }
    for (e = 0; e < E; e++)
        for (h = 0; h < H; h++) o->data[(size_t)e * H + h] = (float)(o->data[(size_t)e * H + h] / sum[(size_t)seg[e] * H + h]);
    return o;
}

static void tn__row_softmax_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    int N = x->shape[0], K = (int)(x->numel / (size_t)N), n, k;
    float inv_tau = out->fp[0];
    if (!tn__grad(ctx, x)) return;
    for (n = 0; n < N; n++) {
        const float *y = out->data + (size_t)n * K, *g = out->grad + (size_t)n * K;
        double dot = 0;
        for (k = 0; k < K; k++) dot += (double)g[k] * y[k];
        for (k = 0; k < K; k++) x->grad[(size_t)n * K + k] += (float)(y[k] * (g[k] - dot) * inv_tau);
    }
}

TN_API tn_tensor *tn_gumbel_softmax(tn_ctx *ctx, tn_tensor *logits, float tau, tn_rng *rng)
{
    int N, K, n, k;
    tn_tensor *o;
    if (!logits) return NULL;
    TN_ASSERT(tau > 0);
    N = logits->shape[0];
    K = (int)(logits->numel / (size_t)N);
    o = tn__op(ctx, logits->ndim, logits->shape, tn__row_softmax_backward, logits, NULL, NULL);
    if (!o) return NULL;
    o->fp[0] = 1.0f / tau;
    for (n = 0; n < N; n++) {
        float *y = o->data + (size_t)n * K, mx = -FLT_MAX;
        double s = 0;
        for (k = 0; k < K; k++) {
            float u = rng ? tn_rng_uniform(rng) : 0.5f;
            float g = -logf(-logf(u * 0.999998f + 1e-6f));
            y[k] = (logits->data[(size_t)n * K + k] + (rng ? g : 0.0f)) / tau;
            if (y[k] > mx) mx = y[k];
        }
        for (k = 0; k < K; k++) { y[k] = expf(y[k] - mx); s += y[k]; }
        for (k = 0; k < K; k++) y[k] = (float)(y[k] / s);
    }
    return o;
}

static void tn__mask_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    const float *m = (const float *)out->aux;
    size_t i;
    if (!tn__grad(ctx, x)) return;
    for (i = 0; i < x->numel; i++) x->grad[i] += out->grad[i] * m[i];
}

TN_API tn_tensor *tn_dropout(tn_ctx *ctx, tn_tensor *x, float p, int training, tn_rng *rng)
{
    tn_tensor *o;
    float *m, keep;
    size_t i;
    if (!x) return NULL;
    if (!training || p <= 0.0f) return x;
    TN_ASSERT(p < 1.0f && rng);
    o = tn__op(ctx, x->ndim, x->shape, tn__mask_backward, x, NULL, NULL);
    m = tn__ctx_floats(ctx, x->numel, 0);
    if (!o || !m) return NULL;
    keep = 1.0f / (1.0f - p);
    for (i = 0; i < x->numel; i++) {
        m[i] = tn_rng_uniform(rng) < p ? 0.0f : keep;
        o->data[i] = x->data[i] * m[i];
    }
    o->aux = m;
    return o;
}

/* --------------------------------------------------------------------------------------------
   >>loss  (@@loss implementation) - mostly compositions of the ops above, so their gradients
   come for free and are checked by the same finite-difference tests.
   -------------------------------------------------------------------------------------------- */

TN_API tn_tensor *tn_mse_loss(tn_ctx *ctx, tn_tensor *pred, tn_tensor *target)
{
    return tn_mean(ctx, tn_square(ctx, tn_sub(ctx, pred, target)));
}

TN_API tn_tensor *tn_l1_loss(tn_ctx *ctx, tn_tensor *pred, tn_tensor *target)
{
    return tn_mean(ctx, tn_abs(ctx, tn_sub(ctx, pred, target)));
}

TN_API tn_tensor *tn_bce_logits_loss(tn_ctx *ctx, tn_tensor *logits, tn_tensor *target)
{
    return tn_mean(ctx, tn_sub(ctx, tn_softplus(ctx, logits), tn_mul(ctx, logits, target)));
}

TN_API tn_tensor *tn_hinge_d_loss(tn_ctx *ctx, tn_tensor *real_scores, tn_tensor *fake_scores)
{
    tn_tensor *r = tn_mean(ctx, tn_relu(ctx, tn_scale_shift(ctx, real_scores, -1.0f, 1.0f)));
    tn_tensor *f = tn_mean(ctx, tn_relu(ctx, tn_scale_shift(ctx, fake_scores, 1.0f, 1.0f)));
    return tn_add(ctx, r, f);
}

TN_API tn_tensor *tn_hinge_g_loss(tn_ctx *ctx, tn_tensor *fake_scores)
{
    return tn_scale_shift(ctx, tn_mean(ctx, fake_scores), -1.0f, 0.0f);
}

TN_API tn_tensor *tn_nonsat_d_loss(tn_ctx *ctx, tn_tensor *real_scores, tn_tensor *fake_scores)
{
    tn_tensor *r = tn_mean(ctx, tn_softplus(ctx, tn_scale_shift(ctx, real_scores, -1.0f, 0.0f)));
    return tn_add(ctx, r, tn_mean(ctx, tn_softplus(ctx, fake_scores)));
}

TN_API tn_tensor *tn_nonsat_g_loss(tn_ctx *ctx, tn_tensor *fake_scores)
{
    return tn_mean(ctx, tn_softplus(ctx, tn_scale_shift(ctx, fake_scores, -1.0f, 0.0f)));
}

static void tn__gram_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    int N = x->shape[0], C = x->shape[1], n, i, j;
    int hw = x->shape[2] * x->shape[3];
    float *gs = tn__ctx_floats(ctx, (size_t)C * C, 0);
    if (!gs || !tn__grad(ctx, x)) return;
    for (n = 0; n < N; n++) {
        const float *g = out->grad + (size_t)n * C * C;
        for (i = 0; i < C; i++) /* dG + dG^T, scaled */
            for (j = 0; j < C; j++) gs[i * C + j] = (g[i * C + j] + g[j * C + i]) * out->fp[0];
        tn_sgemm(0, 0, C, hw, C, 1.0f, gs, C, x->data + (size_t)n * C * hw, hw, 1.0f, x->grad + (size_t)n * C * hw, hw);
    }
}

TN_API tn_tensor *tn_gram(tn_ctx *ctx, tn_tensor *x, float scale)
{
    int shape[2], N, C, hw, n;
    tn_tensor *o;
    if (!x) return NULL;
    TN_ASSERT(x->ndim == 4);
    N = x->shape[0];
    C = x->shape[1];
    hw = x->shape[2] * x->shape[3];
    shape[0] = N * C;
    shape[1] = C;
    o = tn__op(ctx, 2, shape, tn__gram_backward, x, NULL, NULL);
    if (!o) return NULL;
    o->fp[0] = scale;
    for (n = 0; n < N; n++) {
        const float *f = x->data + (size_t)n * C * hw;
        tn_sgemm(0, 1, C, C, hw, scale, f, hw, f, hw, 0.0f, o->data + (size_t)n * C * C, C);
    }
    return o;
}

/* Forward differences along x and y, both cropped to (H-1) x (W-1). */
static void tn__diffs(tn_ctx *ctx, tn_tensor *x, tn_tensor **dx, tn_tensor **dy)
{
    int H = x->shape[2], W = x->shape[3];
    tn_tensor *top = tn_slice(ctx, x, 2, 0, H - 1), *bot = tn_slice(ctx, x, 2, 1, H - 1);
    tn_tensor *left = tn_slice(ctx, x, 3, 0, W - 1), *right = tn_slice(ctx, x, 3, 1, W - 1);
    *dx = tn_slice(ctx, tn_sub(ctx, right, left), 2, 0, H - 1);
    *dy = tn_slice(ctx, tn_sub(ctx, bot, top), 3, 0, W - 1);
}

TN_API tn_tensor *tn_tv_loss(tn_ctx *ctx, tn_tensor *x, float beta)
{
    tn_tensor *dx, *dy, *s;
    if (!x) return NULL;
    TN_ASSERT(x->ndim == 4 && x->shape[2] >= 2 && x->shape[3] >= 2);
    tn__diffs(ctx, x, &dx, &dy);
    s = tn_add(ctx, tn_square(ctx, dx), tn_square(ctx, dy));
    return tn_sum(ctx, beta == 2.0f ? s : tn_pow_abs(ctx, s, 0.5f * beta));
}

TN_API tn_tensor *tn_gdl_loss(tn_ctx *ctx, tn_tensor *a, tn_tensor *b)
{
    tn_tensor *ax, *ay, *bx, *by;
    if (!a || !b) return NULL;
    TN_ASSERT(a->ndim == 4 && a->shape[2] >= 2 && a->shape[3] >= 2);
    tn__diffs(ctx, a, &ax, &ay);
    tn__diffs(ctx, b, &bx, &by);
    return tn_add(ctx, tn_l1_loss(ctx, tn_abs(ctx, ax), tn_abs(ctx, bx)), tn_l1_loss(ctx, tn_abs(ctx, ay), tn_abs(ctx, by)));
}

/* Separable 11-tap Gaussian (sigma 1.5, like skimage), valid region, on every plane. */
static tn_tensor *tn__ssim_blur(tn_ctx *ctx, tn_tensor *x, tn_tensor *kh, tn_tensor *kv)
{
    int shape[4];
    tn_tensor *p;
    shape[0] = x->shape[0] * x->shape[1];
    shape[1] = 1;
    shape[2] = x->shape[2];
    shape[3] = x->shape[3];
    p = tn_reshape(ctx, x, 4, shape);
    return tn_conv2d(ctx, tn_conv2d(ctx, p, kh, NULL, NULL), kv, NULL, NULL);
}

TN_API tn_tensor *tn_ssim_loss(tn_ctx *ctx, tn_tensor *x, tn_tensor *y, float data_range)
{
    tn_tensor *kh, *kv, *mx, *my, *sxx, *syy, *sxy, *num, *den, *vx, *vy, *cxy, *mxy, *m2;
    float c1 = (0.01f * data_range) * (0.01f * data_range), c2 = (0.03f * data_range) * (0.03f * data_range);
    double g[11], s = 0;
    int i;
    if (!x || !y) return NULL;
    TN_ASSERT(tn_tensor_same_shape(x, y) && x->ndim == 4 && x->shape[2] >= 11 && x->shape[3] >= 11);
    kh = tn_tensor_4d(ctx, 1, 1, 1, 11);
    kv = tn_tensor_4d(ctx, 1, 1, 11, 1);
    if (!kh || !kv) return NULL;
    for (i = 0; i < 11; i++) s += g[i] = exp(-0.5 * (i - 5) * (i - 5) / 2.25);
    for (i = 0; i < 11; i++) kh->data[i] = kv->data[i] = (float)(g[i] / s);
    mx = tn__ssim_blur(ctx, x, kh, kv);
    my = tn__ssim_blur(ctx, y, kh, kv);
    sxx = tn__ssim_blur(ctx, tn_square(ctx, x), kh, kv);
    syy = tn__ssim_blur(ctx, tn_square(ctx, y), kh, kv);
    sxy = tn__ssim_blur(ctx, tn_mul(ctx, x, y), kh, kv);
    mxy = tn_mul(ctx, mx, my);
    vx = tn_sub(ctx, sxx, tn_square(ctx, mx));
    vy = tn_sub(ctx, syy, tn_square(ctx, my));
    cxy = tn_sub(ctx, sxy, mxy);
    num = tn_mul(ctx, tn_scale_shift(ctx, mxy, 2.0f, c1), tn_scale_shift(ctx, cxy, 2.0f, c2));
    m2 = tn_add(ctx, tn_square(ctx, mx), tn_square(ctx, my));
    den = tn_mul(ctx, tn_scale_shift(ctx, m2, 1.0f, c1), tn_scale_shift(ctx, tn_add(ctx, vx, vy), 1.0f, c2));
    return tn_scale_shift(ctx, tn_mean(ctx, tn_div(ctx, num, den)), -1.0f, 1.0f);
}


/* --------------------------------------------------------------------------------------------
   >>optim  (@@optim implementation)
   -------------------------------------------------------------------------------------------- */

struct tn_params {
    tn_ctx *ctx;
    tn_tensor **t;
    int n, cap;
    char **meta;  /* 2 * nmeta strings: key, value, key, value, ... (each malloc'd) */
    int nmeta, metacap;
};

TN_API tn_params *tn_params_create(void)
{
    tn_params *p = (tn_params *)TN_MALLOC(sizeof(tn_params));
    if (!p) return NULL;
    memset(p, 0, sizeof *p);
    p->ctx = tn_ctx_create();
    if (!p->ctx) {
        TN_FREE(p);
        return NULL;
    }
    return p;
}

static void tn__meta_clear(tn_params *p)
{
    int i;
    for (i = 0; i < 2 * p->nmeta; i++) TN_FREE(p->meta[i]);
    TN_FREE(p->meta);
    p->meta = NULL;
    p->nmeta = p->metacap = 0;
}

TN_API void tn_params_free(tn_params *p)
{
    if (!p) return;
    tn__meta_clear(p);
    tn_ctx_free(p->ctx);
    TN_FREE(p->t);
    TN_FREE(p);
}

static tn_tensor *tn__params_new(tn_params *p, const char *name, int ndim, const int *shape, int learned)
{
    tn_tensor *t;
    size_t numel = 1;
    int i;
    /* checked here rather than asserted: names and shapes come from model files (.tnw configs) too */
    TN_ASSERT(p);
    if (!name || !name[0] || strlen(name) >= sizeof t->name) {
        tn__fail(TN_ERR_INVALID_ARG, "parameters: name '%.60s' is empty or has 40 or more characters", name ? name : "(null)");
        return NULL;
    }
    if (tn_params_find(p, name)) {
        tn__fail(TN_ERR_INVALID_ARG, "parameters: a tensor named '%s' already exists", name);
        return NULL;
    }
    if (ndim < 1 || ndim > TN_MAX_DIMS || !shape) {
        tn__fail(TN_ERR_INVALID_ARG, "parameters: '%s' has %d dims (1..%d)", name, ndim, TN_MAX_DIMS);
        return NULL;
    }
    for (i = 0; i < ndim; i++) {
        if (shape[i] < 1) {
            tn__fail(TN_ERR_INVALID_ARG, "parameters: '%s' dim %d is %d", name, i, shape[i]);
            return NULL;
        }
        if (!tn__mul_size(numel, (size_t)shape[i], &numel) || numel > TN_MAX_ALLOC / sizeof(float)) {
            tn__fail(TN_ERR_TOO_LARGE, "parameters: '%s' is too large", name);
            return NULL;
        }
    }
    if (p->n == p->cap) {
        int cap = p->cap ? p->cap * 2 : 32;
        tn_tensor **nt = (tn_tensor **)TN_REALLOC(p->t, (size_t)cap * sizeof(tn_tensor *));
        if (!nt) {
            tn__fail(TN_ERR_OUT_OF_MEMORY, "parameters: out of memory");
            return NULL;
        }
        p->t = nt;
        p->cap = cap;
    }
    t = tn_tensor_new(p->ctx, ndim, shape);
    if (!t) return NULL;
    if (learned && !tn_tensor_requires_grad(p->ctx, t)) return NULL;
    strcpy(t->name, name);
    p->t[p->n++] = t;
    return t;
}

TN_API tn_tensor *tn_params_add(tn_params *p, const char *name, int ndim, const int *shape) { return tn__params_new(p, name, ndim, shape, 1); }
TN_API tn_tensor *tn_params_add_buffer(tn_params *p, const char *name, int ndim, const int *shape) { return tn__params_new(p, name, ndim, shape, 0); }
TN_API int tn_params_count(const tn_params *p) { return p->n; }
TN_API tn_tensor *tn_params_get(const tn_params *p, int i) { return i >= 0 && i < p->n ? p->t[i] : NULL; }

TN_API tn_tensor *tn_params_find(const tn_params *p, const char *name)
{
    int i;
    for (i = 0; i < p->n; i++)
        if (!strcmp(p->t[i]->name, name)) return p->t[i];
    return NULL;
}

TN_API size_t tn_params_numel(const tn_params *p)
{
    size_t n = 0;
    int i;
    for (i = 0; i < p->n; i++)
        if (p->t[i]->requires_grad) n += p->t[i]->numel;
    return n;
}

TN_API void tn_params_zero_grad(tn_params *p)
{
    int i;
    for (i = 0; i < p->n; i++)
        if (p->t[i]->grad) memset(p->t[i]->grad, 0, p->t[i]->numel * sizeof(float));
}

TN_API float tn_params_clip_grad(tn_params *p, float max_norm)
{
    double s = 0;
    float norm;
    int i;
    size_t k;
    for (i = 0; i < p->n; i++)
        if (p->t[i]->grad)
            for (k = 0; k < p->t[i]->numel; k++) s += (double)p->t[i]->grad[k] * p->t[i]->grad[k];
    norm = (float)sqrt(s);
    if (max_norm > 0 && norm > max_norm) {
        float f = max_norm / (norm + 1e-6f);
        for (i = 0; i < p->n; i++)
            if (p->t[i]->grad)
                for (k = 0; k < p->t[i]->numel; k++) p->t[i]->grad[k] *= f;
    }
    return norm;
}

TN_API void tn_init_uniform(tn_tensor *t, tn_rng *rng, float lo, float hi)
{
    size_t i;
    for (i = 0; i < t->numel; i++) t->data[i] = lo + (hi - lo) * tn_rng_uniform(rng);
}

TN_API void tn_init_normal(tn_tensor *t, tn_rng *rng, float mean, float std)
{
    size_t i;
    for (i = 0; i < t->numel; i++) t->data[i] = mean + std * tn_rng_normal(rng);
}

TN_API void tn_init_kaiming(tn_tensor *t, tn_rng *rng, float gain)
{
    size_t fan_in = t->numel / (size_t)t->shape[0];
    tn_init_normal(t, rng, 0.0f, gain / sqrtf((float)(fan_in ? fan_in : 1)));
}

/* ---- .tnw files ---- */

static void tn__put_u32(uint8_t *p, uint32_t v) { p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); p[2] = (uint8_t)(v >> 16); p[3] = (uint8_t)(v >> 24); }
static uint32_t tn__get_u32(const uint8_t *p) { return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24); }

static void tn__put_f32(uint8_t *p, float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    tn__put_u32(p, u);
}

static float tn__get_f32(const uint8_t *p)
{
    uint32_t u = tn__get_u32(p);
    float f;
    memcpy(&f, &u, 4);
    return f;
}

/* The metadata block of a version-2 file ("key=value\n" lines); its length goes to *n. */
static size_t tn__meta_size(const tn_params *p)
{
    size_t n = 0;
    int i;
    for (i = 0; i < p->nmeta; i++) n += strlen(p->meta[2 * i]) + 1 + strlen(p->meta[2 * i + 1]) + 1;
    return n;
}

static size_t tn__meta_write(const tn_params *p, uint8_t *out)
{
    size_t off = 0, l;
    int i;
    for (i = 0; i < p->nmeta; i++) {
        l = strlen(p->meta[2 * i]);
        memcpy(out + off, p->meta[2 * i], l);
        off += l;
        out[off++] = '=';
        l = strlen(p->meta[2 * i + 1]);
        memcpy(out + off, p->meta[2 * i + 1], l);
        off += l;
        out[off++] = '\n';
    }
    return off;
}

TN_API tn_status tn_params_save(const tn_params *p, const char *path)
{
    size_t meta = tn__meta_size(p), size = 12 + 4 + (p->nmeta ? 4 + meta : 0), off, k;
    uint8_t *buf;
    tn_status st;
    int i, d;
    for (i = 0; i < p->n; i++) size += 2 + strlen(p->t[i]->name) + 2 + 4 * (size_t)p->t[i]->ndim + 4 * p->t[i]->numel;
    buf = (uint8_t *)tn__alloc(size);
    if (!buf) return tn__fail_context(TN_ERR_OUT_OF_MEMORY, path);
    memcpy(buf, "TNW1", 4);
    tn__put_u32(buf + 4, p->nmeta ? 2 : 1);
    tn__put_u32(buf + 8, (uint32_t)p->n);
    off = 12;
    if (p->nmeta) {
        tn__put_u32(buf + 12, (uint32_t)meta);
        off = 16 + tn__meta_write(p, buf + 16);
    }
    for (i = 0; i < p->n; i++) {
        const tn_tensor *t = p->t[i];
        size_t nl = strlen(t->name);
        buf[off] = (uint8_t)nl;
        buf[off + 1] = (uint8_t)(nl >> 8);
        memcpy(buf + off + 2, t->name, nl);
        off += 2 + nl;
        buf[off++] = (uint8_t)t->ndim;
        buf[off++] = (uint8_t)(t->requires_grad ? 0 : 1);
        for (d = 0; d < t->ndim; d++, off += 4) tn__put_u32(buf + off, (uint32_t)t->shape[d]);
        for (k = 0; k < t->numel; k++, off += 4) tn__put_f32(buf + off, t->data[k]);
    }
    tn__put_u32(buf + off, tn__crc32(0, buf, off));
    st = tn__io_write_atomic(path, buf, size);
    TN_FREE(buf);
    return st;
}

#define TN__TNW_VERSION 2
#define TN__META_MAX 65536

static int tn__meta_key_ok(const char *k)
{
    size_t i, n = k ? strlen(k) : 0;
    if (n == 0 || n >= 64) return 0;
    for (i = 0; i < n; i++)
        if (!((k[i] >= 'a' && k[i] <= 'z') || (k[i] >= 'A' && k[i] <= 'Z') || (k[i] >= '0' && k[i] <= '9') || k[i] == '_' || k[i] == '.' || k[i] == '-')) return 0;
    return 1;
}

static int tn__meta_value_ok(const char *v, size_t n)
{
    size_t i;
    if (n >= 1024) return 0;
    for (i = 0; i < n; i++)
        if ((unsigned char)v[i] < 0x20 || v[i] == 0x7f) return 0;
    return 1;
}

static char *tn__strndup(const char *s, size_t n)
{
    char *d = (char *)TN_MALLOC(n + 1);
    if (!d) return NULL;
    memcpy(d, s, n);
    d[n] = 0;
    return d;
}

static tn_status tn__meta_set(tn_params *p, const char *key, size_t kn, const char *value, size_t vn)
{
    char *k, *v;
    int i;
    for (i = 0; i < p->nmeta; i++)
        if (strlen(p->meta[2 * i]) == kn && !memcmp(p->meta[2 * i], key, kn)) break;
    if (!value) { /* remove, keeping the order of the rest */
        if (i == p->nmeta) return TN_OK;
        TN_FREE(p->meta[2 * i]);
        TN_FREE(p->meta[2 * i + 1]);
        memmove(p->meta + 2 * i, p->meta + 2 * i + 2, (size_t)(p->nmeta - i - 1) * 2 * sizeof(char *));
        p->nmeta--;
        return TN_OK;
    }
    if (!(v = tn__strndup(value, vn))) return tn__fail(TN_ERR_OUT_OF_MEMORY, "metadata: out of memory");
    if (i < p->nmeta) {
        TN_FREE(p->meta[2 * i + 1]);
        p->meta[2 * i + 1] = v;
        return TN_OK;
    }
    if (p->nmeta == p->metacap) {
        int cap = p->metacap ? 2 * p->metacap : 16;
        char **m = (char **)TN_REALLOC(p->meta, 2 * (size_t)cap * sizeof(char *));
        if (!m) { TN_FREE(v); return tn__fail(TN_ERR_OUT_OF_MEMORY, "metadata: out of memory"); }
        p->meta = m;
        p->metacap = cap;
    }
    if (!(k = tn__strndup(key, kn))) { TN_FREE(v); return tn__fail(TN_ERR_OUT_OF_MEMORY, "metadata: out of memory"); }
    p->meta[2 * p->nmeta] = k;
    p->meta[2 * p->nmeta + 1] = v;
    p->nmeta++;
    return TN_OK;
}

TN_API tn_status tn_params_set_meta(tn_params *p, const char *key, const char *value)
{
    TN_ASSERT(p);
    if (!tn__meta_key_ok(key)) return tn__fail(TN_ERR_INVALID_ARG, "metadata: bad key '%.80s'", key ? key : "(null)");
    if (value && !tn__meta_value_ok(value, strlen(value)))
        return tn__fail(TN_ERR_INVALID_ARG, "metadata: the value of '%s' is too long or holds control characters", key);
    return tn__meta_set(p, key, strlen(key), value, value ? strlen(value) : 0);
}

TN_API const char *tn_params_meta(const tn_params *p, const char *key)
{
    int i;
    for (i = 0; p && key && i < p->nmeta; i++)
        if (!strcmp(p->meta[2 * i], key)) return p->meta[2 * i + 1];
    return NULL;
}

TN_API int tn_params_meta_count(const tn_params *p) { return p ? p->nmeta : 0; }

TN_API const char *tn_params_meta_key(const tn_params *p, int i, const char **value)
{
    if (!p || i < 0 || i >= p->nmeta) return NULL;
    if (value) *value = p->meta[2 * i + 1];
    return p->meta[2 * i];
}

/* Parses the metadata block into p: every line key=value, checked as tn_params_set_meta would. */
static tn_status tn__meta_parse(tn_params *p, const uint8_t *b, size_t n, const char *name)
{
    size_t off = 0;
    while (off < n) {
        const char *line = (const char *)b + off, *eq, *nl = (const char *)memchr(line, '\n', n - off);
        char key[64];
        size_t len, kn;
        tn_status st;
        if (!nl) return tn__fail(TN_ERR_CORRUPT, "%s: metadata line without an end", name);
        len = (size_t)(nl - line);
        eq = (const char *)memchr(line, '=', len);
        kn = eq ? (size_t)(eq - line) : 0;
        if (!eq || kn == 0 || kn >= sizeof key) return tn__fail(TN_ERR_CORRUPT, "%s: bad metadata line", name);
        memcpy(key, line, kn);
        key[kn] = 0;
        if (!tn__meta_key_ok(key) || !tn__meta_value_ok(eq + 1, len - kn - 1) || tn_params_meta(p, key))
            return tn__fail(TN_ERR_CORRUPT, "%s: bad or repeated metadata key '%s'", name, key);
        if ((st = tn__meta_set(p, key, kn, eq + 1, len - kn - 1))) return st;
        off += len + 1;
    }
    return TN_OK;
}

/* Reads a .tnw image into a new set: every tensor with its name, shape and flag, the metadata.
   Everything is bounds-checked before it is allocated; NaN/Inf data is refused. */
static tn_status tn__tnw_read(const uint8_t *b, size_t n, const char *name, tn_params **out)
{
    size_t off = 12, k;
    uint32_t count, i, version;
    tn_params *p;
    tn_status st = TN_OK;
    *out = NULL;
    if (n < 16 || memcmp(b, "TNW1", 4) != 0) return tn__fail(TN_ERR_FORMAT, "%s: not a terrainnet weights (.tnw) file", name);
    version = tn__get_u32(b + 4);
    if (version < 1 || version > TN__TNW_VERSION)
        return tn__fail(TN_ERR_FORMAT, "%s: .tnw version %u is not supported (this library reads 1..%d; a newer terrainnet wrote it?)", name,
                        (unsigned)version, TN__TNW_VERSION);
    if (tn__crc32(0, b, n - 4) != tn__get_u32(b + n - 4)) return tn__fail(TN_ERR_CORRUPT, "%s: CRC-32 mismatch (the file is damaged)", name);
    count = tn__get_u32(b + 8);
    if (count > (n - 16) / 9) return tn__fail(TN_ERR_CORRUPT, "%s: %u tensors cannot fit in %zu bytes", name, (unsigned)count, n);
    if (!(p = tn_params_create())) return tn__fail(TN_ERR_OUT_OF_MEMORY, "%s: out of memory", name);
    if (version >= 2) {
        size_t ml = tn__get_u32(b + 12);
        off = 16;
        if (ml > TN__META_MAX || ml > n - 4 - off) st = tn__fail(TN_ERR_CORRUPT, "%s: bad metadata size", name);
        if (!st) st = tn__meta_parse(p, b + off, ml, name);
        off += ml;
    }
    for (i = 0; i < count && !st; i++) {
        char tname[64];
        size_t nl, numel = 1;
        int ndim, d, shape[TN_MAX_DIMS], flags;
        tn_tensor *t;
        if (off + 4 > n - 4) { st = tn__fail(TN_ERR_CORRUPT, "%s: truncated at tensor %u", name, (unsigned)i); break; }
        nl = (size_t)b[off] | ((size_t)b[off + 1] << 8);
        if (nl == 0 || nl >= 40 || off + 2 + nl + 2 > n - 4) { st = tn__fail(TN_ERR_CORRUPT, "%s: bad name at tensor %u", name, (unsigned)i); break; }
        memcpy(tname, b + off + 2, nl);
        tname[nl] = 0;
        off += 2 + nl;
        ndim = b[off];
        flags = b[off + 1];
        off += 2;
        if (ndim < 1 || ndim > TN_MAX_DIMS || off + 4 * (size_t)ndim > n - 4) {
            st = tn__fail(TN_ERR_CORRUPT, "%s: tensor '%s' has %d dims or is truncated", name, tname, ndim);
            break;
        }
        for (d = 0; d < ndim; d++) {
            uint32_t v = tn__get_u32(b + off + 4 * (size_t)d);
            if (v < 1 || v > (uint32_t)INT_MAX || !tn__mul_size(numel, v, &numel)) break;
            shape[d] = (int)v;
        }
        off += 4 * (size_t)ndim;
        if (d < ndim || numel > (n - 4 - off) / 4) { st = tn__fail(TN_ERR_CORRUPT, "%s: truncated data of '%s'", name, tname); break; }
        if (tn_params_find(p, tname)) { st = tn__fail(TN_ERR_CORRUPT, "%s: tensor '%s' appears twice", name, tname); break; }
        for (k = 0; k < numel; k++) {
            float v = tn__get_f32(b + off + 4 * k);
            if (v != v || v > FLT_MAX || v < -FLT_MAX) break;
        }
        if (k < numel) { st = tn__fail(TN_ERR_NUMERIC, "%s: tensor '%s' holds NaN/Inf", name, tname); break; }
        t = flags & 1 ? tn_params_add_buffer(p, tname, ndim, shape) : tn_params_add(p, tname, ndim, shape);
        if (!t) { st = tn__fail_context(TN_ERR_OUT_OF_MEMORY, name); break; }
        for (k = 0; k < numel; k++) t->data[k] = tn__get_f32(b + off + 4 * k);
        off += 4 * numel;
    }
    if (!st && off != n - 4) st = tn__fail(TN_ERR_CORRUPT, "%s: %zu unexpected bytes after the last tensor", name, n - 4 - off);
    if (st) {
        tn_params_free(p);
        return st;
    }
    *out = p;
    return TN_OK;
}

TN_API tn_status tn_params_open_memory(const uint8_t *data, size_t size, const char *name, tn_params **out)
{
    TN_ASSERT(out);
    *out = NULL;
    if (!data) return tn__fail(TN_ERR_INVALID_ARG, "weights: no data");
    return tn__tnw_read(data, size, name ? name : "weights", out);
}

TN_API tn_status tn_params_open(const char *path, tn_params **out)
{
    uint8_t *buf = NULL;
    size_t n = 0;
    tn_status st;
    TN_ASSERT(out);
    *out = NULL;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "weights: empty path");
    if ((st = tn__io_read_file(path, &buf, &n))) return st;
    st = tn__tnw_read(buf, n, path, out);
    TN_FREE(buf);
    return st;
}

/* Copies src's tensors into p's same-named ones: the same count, every name present with the
   same shape, checked before anything changes; then the metadata. */
static tn_status tn__params_assign(tn_params *p, const tn_params *src, const char *name)
{
    int i, j;
    if (src->n != p->n) return tn__fail(TN_ERR_SHAPE, "%s: holds %d tensors, the model has %d", name, src->n, p->n);
    for (i = 0; i < src->n; i++) {
        const tn_tensor *s = src->t[i], *t = tn_params_find(p, s->name);
        if (!t) return tn__fail(TN_ERR_SHAPE, "%s: tensor '%s' is not in the model", name, s->name);
        if (s->ndim != t->ndim) return tn__fail(TN_ERR_SHAPE, "%s: tensor '%s' has %d dims, the model's has %d", name, s->name, s->ndim, t->ndim);
        for (j = 0; j < s->ndim; j++)
            if (s->shape[j] != t->shape[j])
                return tn__fail(TN_ERR_SHAPE, "%s: tensor '%s' dim %d is %d, the model's is %d", name, s->name, j, s->shape[j], t->shape[j]);
    }
    for (i = 0; i < src->n; i++) memcpy(tn_params_find(p, src->t[i]->name)->data, src->t[i]->data, src->t[i]->numel * sizeof(float));
    tn__meta_clear(p);
    for (i = 0; i < src->nmeta; i++) {
        const char *k = src->meta[2 * i], *v = src->meta[2 * i + 1];
        tn_status st = tn__meta_set(p, k, strlen(k), v, strlen(v));
        if (st) return st;
    }
    return TN_OK;
}

TN_API tn_status tn_params_load_memory(tn_params *p, const uint8_t *data, size_t size, const char *name)
{
    tn_params *f = NULL;
    tn_status st;
    TN_ASSERT(p);
    name = name ? name : "weights";
    if ((st = tn_params_open_memory(data, size, name, &f))) return st;
    st = tn__params_assign(p, f, name);
    tn_params_free(f);
    return st;
}

TN_API tn_status tn_params_load(tn_params *p, const char *path)
{
    tn_params *f = NULL;
    tn_status st;
    TN_ASSERT(p);
    if ((st = tn_params_open(path, &f))) return st;
    st = tn__params_assign(p, f, path);
    tn_params_free(f);
    return st;
}

/* ---- optimisers ---- */

struct tn_optim {
    tn_params *p;
    tn_optim_opts o;
    float **m, **v; /* per tensor state (Adam: both; SGD: m = velocity) */
    long step;
};

static void tn__optim_opts_defaults(tn_optim_opts *o)
{
    if (o->lr <= 0) o->lr = 1e-3f;
    if (o->beta1 == 0 && o->beta2 == 0) { o->beta1 = 0.9f; o->beta2 = 0.999f; }
    if (o->eps <= 0) o->eps = 1e-8f;
    if (o->decay_every <= 0) o->decay_every = 1;
}

/* NaN/Inf or out-of-range settings would turn every weight into NaN at the first step. */
static int tn__optim_opts_ok(const tn_optim_opts *o)
{
    const float f[8] = {o->lr, o->beta1, o->beta2, o->eps, o->weight_decay, o->momentum, o->lr_decay, o->clip_norm};
    int i;
    for (i = 0; i < 8; i++)
        if (!(fabsf(f[i]) <= FLT_MAX)) return 0;
    return (o->kind == TN_OPTIM_ADAM || o->kind == TN_OPTIM_SGD) && o->beta1 >= 0.0f && o->beta1 < 1.0f &&
           o->beta2 >= 0.0f && o->beta2 < 1.0f && o->momentum >= 0.0f && o->lr_decay >= 0.0f;
}

TN_API tn_optim *tn_optim_create(tn_params *p, const tn_optim_opts *opts)
{
    tn_optim *o;
    int i;
    if (!p) {
        tn__fail(TN_ERR_INVALID_ARG, "optimiser: no parameters");
        return NULL;
    }
    if (opts && !tn__optim_opts_ok(opts)) {
        tn__fail(TN_ERR_INVALID_ARG, "optimiser: a setting is NaN/Inf or out of range (kind %d, lr %g, betas %g %g, momentum %g)",
                 (int)opts->kind, (double)opts->lr, (double)opts->beta1, (double)opts->beta2, (double)opts->momentum);
        return NULL;
    }
    o = (tn_optim *)TN_MALLOC(sizeof(tn_optim));
    if (!o) {
        tn__fail(TN_ERR_OUT_OF_MEMORY, "optimiser: out of memory");
        return NULL;
    }
    memset(o, 0, sizeof *o);
    o->p = p;
    if (opts) o->o = *opts;
    tn__optim_opts_defaults(&o->o);
    o->m = (float **)TN_MALLOC(2 * sizeof(float *) * (size_t)(p->n ? p->n : 1));
    if (!o->m) { TN_FREE(o); return NULL; }
    o->v = o->m + p->n;
    for (i = 0; i < p->n; i++) {
        size_t n = p->t[i]->requires_grad ? p->t[i]->numel : 0;
        o->m[i] = n ? (float *)tn__calloc(n * sizeof(float)) : NULL;
        o->v[i] = n && o->o.kind == TN_OPTIM_ADAM ? (float *)tn__calloc(n * sizeof(float)) : NULL;
        if (n && (!o->m[i] || (o->o.kind == TN_OPTIM_ADAM && !o->v[i]))) {
            o->p = p;
            tn_optim_free(o);
            return NULL;
        }
    }
    return o;
}

TN_API void tn_optim_free(tn_optim *o)
{
    int i;
    if (!o) return;
    for (i = 0; i < o->p->n; i++) {
        TN_FREE(o->m[i]);
        TN_FREE(o->v[i]);
    }
    TN_FREE(o->m);
    TN_FREE(o);
}

TN_API float tn_optim_lr(const tn_optim *o)
{
    if (o->o.lr_decay <= 0) return o->o.lr;
    return o->o.lr * powf(o->o.lr_decay, (float)(o->step / o->o.decay_every));
}

TN_API void tn_optim_step(tn_optim *o)
{
    float lr = tn_optim_lr(o), wd = o->o.weight_decay;
    float b1 = o->o.beta1, b2 = o->o.beta2, c1, c2;
    int i;
    size_t k;
    if (o->o.clip_norm > 0) tn_params_clip_grad(o->p, o->o.clip_norm);
    o->step++;
    c1 = 1.0f - powf(b1, (float)o->step);
    c2 = 1.0f - powf(b2, (float)o->step);
    for (i = 0; i < o->p->n; i++) {
        tn_tensor *t = o->p->t[i];
        float *m = o->m[i], *v = o->v[i];
        if (!t->requires_grad || !t->grad) continue;
        for (k = 0; k < t->numel; k++) {
            float g = t->grad[k] + wd * t->data[k];
            if (o->o.kind == TN_OPTIM_ADAM) {
                m[k] = b1 * m[k] + (1 - b1) * g;
                v[k] = b2 * v[k] + (1 - b2) * g * g;
                t->data[k] -= lr * (m[k] / c1) / (sqrtf(v[k] / c2) + o->o.eps);
            } else {
                m[k] = o->o.momentum * m[k] + g;
                t->data[k] -= lr * m[k];
            }
        }
    }
}

static double tn__dot(const float *a, const float *b, size_t n)
{
    double s = 0;
    size_t i;
    for (i = 0; i < n; i++) s += (double)a[i] * b[i];
    return s;
}

static void tn__lbfgs_opts_defaults(tn_lbfgs_opts *o)
{
    if (o->history <= 0) o->history = 10;
    if (o->max_iter <= 0) o->max_iter = 100;
    if (!(o->tol > 0)) o->tol = 1e-7f;
    if (!(o->first_step > 0)) o->first_step = 1.0f;
}

TN_API tn_status tn_lbfgs(float *x, size_t n, tn_lbfgs_fn fn, void *user, const tn_lbfgs_opts *opts, float *final_f)
{
    tn_lbfgs_opts lo = {0, 0, 0.0f, 0.0f};
    int m, max_iter;
    float tol, first;
    float *S, *Y, *g, *gn, *d, *xn, f, fn_;
    double *rho, *alpha;
    int it, k, hist = 0, head = 0;
    size_t bytes = 0;
    tn_status st = TN_OK;
    if (!x || !fn || n == 0) return tn__fail(TN_ERR_INVALID_ARG, "L-BFGS: %s", n ? "no vector or function" : "empty vector");
    if (opts && (opts->history < 0 || opts->history > 65536 || opts->max_iter < 0 || !(fabsf(opts->tol) <= FLT_MAX) ||
                 !(fabsf(opts->first_step) <= FLT_MAX)))
        return tn__fail(TN_ERR_INVALID_ARG, "L-BFGS: bad options (history %d, max_iter %d, tol %g, first_step %g)",
                        opts->history, opts->max_iter, (double)opts->tol, (double)opts->first_step);
    if (opts) lo = *opts;
    tn__lbfgs_opts_defaults(&lo);
    m = lo.history;
    max_iter = lo.max_iter;
    tol = lo.tol;
    first = lo.first_step;
    if (tn__size4((size_t)(2 * m + 4), n, sizeof(float), 1, &bytes)) return TN_ERR_TOO_LARGE;
    S = (float *)tn__alloc(bytes);
    rho = (double *)tn__alloc(2 * (size_t)m * sizeof(double));
    if (!S || !rho) {
        TN_FREE(S);
        TN_FREE(rho);
        return TN_ERR_OUT_OF_MEMORY;
    }
    alpha = rho + m;
    Y = S + (size_t)m * n;
    g = Y + (size_t)m * n;
    gn = g + n;
    d = gn + n;
    xn = d + n;
    f = fn(user, x, g);
    for (it = 0; it < max_iter; it++) {
        double gnorm = sqrt(tn__dot(g, g, n)), step, gd;
        size_t i;
        if (f != f || !(gnorm <= DBL_MAX)) { /* a NaN/Inf gradient would stall the line search silently */
            st = tn__fail(TN_ERR_NUMERIC, "L-BFGS: the objective or its gradient is NaN/Inf");
            break;
        }
        if (gnorm < tol) break;
        if ((st = tn__progress("lbfgs", (double)it / max_iter))) break;
        /* two-loop recursion: d = -H g */
        for (i = 0; i < n; i++) d[i] = -g[i];
        for (k = 0; k < hist; k++) {
            int j = (head - 1 - k + m) % m;
            alpha[j] = rho[j] * tn__dot(S + (size_t)j * n, d, n);
            for (i = 0; i < n; i++) d[i] -= (float)alpha[j] * Y[(size_t)j * n + i];
        }
        if (hist) {
            int j = (head - 1 + m) % m;
            double gamma = tn__dot(S + (size_t)j * n, Y + (size_t)j * n, n) / tn__dot(Y + (size_t)j * n, Y + (size_t)j * n, n);
            for (i = 0; i < n; i++) d[i] *= (float)gamma;
        }
        for (k = hist - 1; k >= 0; k--) {
            int j = (head - 1 - k + m) % m;
            double beta = rho[j] * tn__dot(Y + (size_t)j * n, d, n);
            for (i = 0; i < n; i++) d[i] += (float)(alpha[j] - beta) * S[(size_t)j * n + i];
        }
        gd = tn__dot(g, d, n);
        if (gd >= 0) { /* not a descent direction: restart from steepest descent */
            for (i = 0; i < n; i++) d[i] = -g[i];
            gd = -gnorm * gnorm;
            hist = 0;
        }
        step = hist ? 1.0 : first / (gnorm > 1 ? gnorm : 1.0);
        for (k = 0; k < 30; k++) { /* backtracking, Armijo c = 1e-4 */
            for (i = 0; i < n; i++) xn[i] = x[i] + (float)step * d[i];
            fn_ = fn(user, xn, gn);
            if (fn_ == fn_ && fn_ <= f + 1e-4 * step * gd) break;
            step *= 0.5;
        }
        if (k == 30) break; /* no decrease possible at float precision */
        {
            float *s = S + (size_t)head * n, *y = Y + (size_t)head * n;
            double sy;
            for (i = 0; i < n; i++) {
                s[i] = xn[i] - x[i];
                y[i] = gn[i] - g[i];
            }
            sy = tn__dot(s, y, n);
            if (sy > 1e-10) {
                rho[head] = 1.0 / sy;
                head = (head + 1) % m;
                if (hist < m) hist++;
            }
        }
        memcpy(x, xn, n * sizeof(float));
        memcpy(g, gn, n * sizeof(float));
        f = fn_;
    }
    if (final_f) *final_f = f;
    TN_FREE(S);
    TN_FREE(rho);
    return st;
}

/* --------------------------------------------------------------------------------------------
   >>train  (@@train implementation)
   -------------------------------------------------------------------------------------------- */

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
    tn_status st;
};

static double tn__progress_eta_s = -1.0;

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

TN_API tn_status tn_train_create(const char *method, const char *stage, const tn_train_opts *opts, tn_train **out)
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

TN_API long tn_train_iteration(const tn_train *run) { return run->it; }
TN_API long tn_train_start_iteration(const tn_train *run) { return run->it0; }
TN_API double tn_train_seconds(const tn_train *run) { return run->seconds; }
TN_API double tn_train_start_seconds(const tn_train *run) { return run->sec0; }
TN_API uint64_t tn_train_seed(const tn_train *run) { return run->o.seed; }
TN_API int tn_train_checkpoints(const tn_train *run) { return run->ckpts; }

TN_API void tn_train_set_position(tn_train *run, long iteration, double seconds)
{
    run->it = run->it0 = run->last_ck_it = iteration;
    run->seconds = run->sec0 = seconds;
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
    st = tn_params_save(ck, path);
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
        if ((st = tn_params_open(run->o.checkpoint, &run->ck))) return st;
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
            if ((run->st = tn_train_checkpoint(run, NULL))) {
                run->stopped = 1;
                return 0;
            }
            run->last_ck = now;
        }
        frac = run->seconds / (run->o.minutes * 60.0);
        if (run->o.max_iters && (double)run->it / (double)run->o.max_iters > frac) frac = (double)run->it / (double)run->o.max_iters;
        tn__train_eta(run);
        run->st = tn__progress(run->stage, frac > 1.0 ? 1.0 : frac);
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
        tn_status st = tn_train_checkpoint(run, NULL); /* leaves the cancel message alone when it succeeds */
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

TN_API tn_tensor *tn_patch_disc_score(tn_ctx *ctx, const tn_patch_disc *d, tn_tensor *x)
{
    tn_conv_opts co;
    int l;
    memset(&co, 0, sizeof co);
    co.pad = d->k / 2;
    for (l = 0; l <= d->layers; l++) {
        co.stride = l == d->layers ? 1 : 2;
        x = tn_conv2d(ctx, x, d->wn[l], tn__param_named(d->p, d->prefix, "b", l), &co);
        if (l < d->layers) x = tn_leaky_relu(ctx, x, 0.2f);
    }
    return x;
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

/* --------------------------------------------------------------------------------------------
   >>noise  (@@noise implementation)
   Improved Perlin noise (Perlin 2002): quintic fade, a seeded permutation of 0..255, 8 gradient
   directions. Rows are independent, so the map is computed row-parallel and is identical for any
   thread count.
   -------------------------------------------------------------------------------------------- */

typedef struct tn__perlin_job {
    uint8_t perm[512];
    int width, height, octaves, periodic;
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
        float *row = j->out + y * (size_t)j->width, freq = j->freq, amp = 1.0f;
        for (x = 0; x < j->width; x++) row[x] = 0.0f;
        for (o = 0; o < j->octaves; o++) {
            const int *hx0 = j->hx0 + (size_t)o * j->width, *hx1 = j->hx1 + (size_t)o * j->width;
            const float *fxs = j->fx + (size_t)o * j->width, *uxs = j->ux + (size_t)o * j->width;
            float cells_y = tn__perlin_cells(j, freq * (float)j->height / (float)j->width), fy, v;
            int y0, y1;
            tn__perlin_coord(j, (int)y, j->height, cells_y, (float)(o * 37), &y0, &y1, &fy);
            v = tn__fade(fy);
            for (x = 0; x < j->width; x++) {
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
    tn_image_range(img, &lo, &hi);
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

TN_API tn_status tn_noise_perlin(tn_image *out, int width, int height, const tn_perlin_opts *opts)
{
    tn_perlin_opts o;
    tn__perlin_job *j;
    tn_image img = {0, 0, 0, NULL};
    tn_rng rng;
    tn_status st;
    int i;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    if (o.octaves < 0 || !(o.frequency >= 0.0f) || !(o.lacunarity >= 0.0f) || !(o.gain >= 0.0f)) /* also NaN */
        return tn__fail(TN_ERR_INVALID_ARG, "perlin: negative or NaN octaves, frequency, lacunarity or gain");
    tn__perlin_opts_defaults(&o);
    if (o.octaves > 24 || o.frequency > 1e6f || o.lacunarity > 16.0f || o.gain > 4.0f)
        return tn__fail(TN_ERR_INVALID_ARG, "perlin: octaves <= 24, frequency <= 1e6, lacunarity <= 16, gain <= 4");
    /* the finest octave's lattice coordinates must fit an int (they are floored to cells) */
    if ((double)o.frequency * pow((double)o.lacunarity, o.octaves - 1) > 1e9)
        return tn__fail(TN_ERR_INVALID_ARG, "perlin: frequency x lacunarity^(octaves - 1) exceeds 1e9 cells");
    if ((st = tn_image_create(&img, width, height, 1))) return st;
    j = (tn__perlin_job *)tn__alloc(sizeof *j);
    if (!j) {
        tn_image_free(&img);
        return TN_ERR_OUT_OF_MEMORY;
    }
    for (i = 0; i < 256; i++) j->perm[i] = (uint8_t)i;
    tn_rng_seed(&rng, o.seed, 0x5e71u);
    for (i = 255; i > 0; i--) { /* Fisher-Yates */
        int k = (int)tn_rng_below(&rng, (uint32_t)i + 1);
        uint8_t t = j->perm[i];
        j->perm[i] = j->perm[k];
        j->perm[k] = t;
    }
    for (i = 0; i < 256; i++) j->perm[256 + i] = j->perm[i];
    j->width = width;
    j->height = height;
    j->octaves = o.octaves;
    j->periodic = o.periodic != 0;
    j->freq = o.frequency;
    j->lacunarity = o.lacunarity;
    j->gain = o.gain;
    j->out = img.data;
    j->hx0 = (int *)tn__alloc(2 * (size_t)o.octaves * (size_t)width * (sizeof(int) + sizeof(float)));
    if (!j->hx0) {
        TN_FREE(j);
        tn_image_free(&img);
        return TN_ERR_OUT_OF_MEMORY;
    }
    j->hx1 = j->hx0 + (size_t)o.octaves * width;
    j->fx = (float *)(j->hx1 + (size_t)o.octaves * width);
    j->ux = j->fx + (size_t)o.octaves * width;
    {
        float freq = o.frequency;
        int oc, x;
        for (oc = 0; oc < o.octaves; oc++, freq *= o.lacunarity) {
            float cells_x = tn__perlin_cells(j, freq);
            for (x = 0; x < width; x++) {
                size_t k = (size_t)oc * width + x;
                int x0, x1;
                tn__perlin_coord(j, x, width, cells_x, (float)(oc * 59), &x0, &x1, &j->fx[k]);
                j->hx0[k] = j->perm[x0];
                j->hx1[k] = j->perm[x1];
                j->ux[k] = tn__fade(j->fx[k]);
            }
        }
    }
    tn_parallel_for((size_t)height, 4, tn__perlin_rows, j);
    TN_FREE(j->hx0);
    TN_FREE(j);
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
    if (tn_image_range(&d, NULL, NULL)) {
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

/* --------------------------------------------------------------------------------------------
   >>sketch  (@@sketch implementation)
   -------------------------------------------------------------------------------------------- */

TN_API void tn_contour_set_free(tn_contour_set *set) {
    int i;
    if (!set) return;
    for (i = 0; i < set->count; i++) TN_FREE(set->items[i].points);
    TN_FREE(set->items);
    memset(set, 0, sizeof(*set));
}

/* ---- small builders shared by the sketch code ---- */

/* Appends a polyline (points copied) to *s, whose items array has capacity *cap bytes. */
static tn_status tn__cset_add(tn_contour_set *s, size_t *cap, tn_contour_type type, int order, float gradient,
                              const float *pts, int npts)
{
    tn_contour *c;
    tn_status st;
    if (s->count == INT_MAX) return tn__fail(TN_ERR_TOO_LARGE, "more than %d polylines", INT_MAX);
    st = tn__reserve((void **)&s->items, cap, ((size_t)s->count + 1) * sizeof(tn_contour));
    if (st) return st;
    c = &s->items[s->count];
    c->points = (float *)tn__alloc((size_t)npts * 3 * sizeof(float));
    if (!c->points) return TN_ERR_OUT_OF_MEMORY;
    if (npts) memcpy(c->points, pts, (size_t)npts * 3 * sizeof(float));
    c->type = type;
    c->order = order;
    c->npoints = npts;
    c->mean_gradient = gradient;
    s->count++;
    return TN_OK;
}

/* A growable list of (x, y, h) points; cap in bytes (tn__reserve). */
typedef struct tn__pts { float *p; int n; size_t cap; } tn__pts;

static tn_status tn__pts_push(tn__pts *b, float x, float y, float h)
{
    tn_status st;
    if (b->n >= TN_SKETCH_MAX_POINTS) return tn__fail(TN_ERR_TOO_LARGE, "polyline longer than %d points", TN_SKETCH_MAX_POINTS);
    st = tn__reserve((void **)&b->p, &b->cap, ((size_t)b->n + 1) * 3 * sizeof(float));
    if (st) return st;
    b->p[3 * b->n] = x;
    b->p[3 * b->n + 1] = y;
    b->p[3 * b->n + 2] = h;
    b->n++;
    return TN_OK;
}

/* Appends the 8-connected integer-pixel chain through pts (canvas coordinates mapped by pixel
   centres: x' = (x + 0.5) * sx - 0.5), heights linear along each segment, no repeated pixels. */
static tn_status tn__chain_pixels(const float *pts, int n, float sx, float sy, tn__pts *out)
{
    int i, t, steps;
    tn_status st;
    for (i = 0; i < n; i++) {
        float x1 = (pts[3 * i] + 0.5f) * sx - 0.5f, y1 = (pts[3 * i + 1] + 0.5f) * sy - 0.5f, h1 = pts[3 * i + 2];
        float x0 = x1, y0 = y1, h0 = h1;
        if (i > 0) {
            x0 = (pts[3 * i - 3] + 0.5f) * sx - 0.5f;
            y0 = (pts[3 * i - 2] + 0.5f) * sy - 0.5f;
            h0 = pts[3 * i - 1];
        }
        {
            float span = ceilf(fmaxf(fabsf(x1 - x0), fabsf(y1 - y0)));
            /* far-off points (a programmatic set): the int cast would be undefined, the walk endless */
            if (!(span <= (float)TN_SKETCH_MAX_POINTS))
                return tn__fail(TN_ERR_TOO_LARGE, "polyline segment %d spans %g pixels", i, (double)span);
            steps = (int)span;
        }
        for (t = i > 0 ? 1 : 0; t <= steps; t++) {
            float f = steps ? (float)t / (float)steps : 1.0f;
            float px = floorf(x0 + f * (x1 - x0) + 0.5f), py = floorf(y0 + f * (y1 - y0) + 0.5f);
            if (out->n && out->p[3 * out->n - 3] == px && out->p[3 * out->n - 2] == py) continue;
            if ((st = tn__pts_push(out, px, py, h0 + f * (h1 - h0)))) return st;
        }
    }
    return TN_OK;
}

/* Checks that every point is finite and the canvas sane; `what` names the set in messages. */
static tn_status tn__cset_check(const tn_contour_set *s, const char *what)
{
    int i, j;
    if (!s || s->width <= 0 || s->height <= 0) return tn__fail(TN_ERR_INVALID_ARG, "%s: no canvas size", what);
    if (s->width > TN_SKETCH_MAX_SIDE || s->height > TN_SKETCH_MAX_SIDE)
        return tn__fail(TN_ERR_TOO_LARGE, "%s: canvas %d x %d exceeds %d", what, s->width, s->height, TN_SKETCH_MAX_SIDE);
    if (s->count < 0 || (s->count > 0 && !s->items)) return tn__fail(TN_ERR_INVALID_ARG, "%s: bad polyline list", what);
    for (i = 0; i < s->count; i++) {
        const tn_contour *c = &s->items[i];
        if (c->npoints <= 0 || !c->points) return tn__fail(TN_ERR_INVALID_ARG, "%s: polyline %d is empty", what, i);
        if (!isfinite(c->mean_gradient)) return tn__fail(TN_ERR_NUMERIC, "%s: polyline %d has a NaN/Inf gradient", what, i);
        for (j = 0; j < 3 * c->npoints; j++) {
            if (!isfinite(c->points[j])) return tn__fail(TN_ERR_NUMERIC, "%s: polyline %d point %d is NaN/Inf", what, i, j / 3);
            /* pixel coordinates are rounded to int: keep them where that is defined */
            if (j % 3 != 2 && fabsf(c->points[j]) > (float)(16 * TN_SKETCH_MAX_SIDE))
                return tn__fail(TN_ERR_INVALID_ARG, "%s: polyline %d point %d lies far outside the canvas", what, i, j / 3);
        }
    }
    return TN_OK;
}

/* ---- .tns text ---- */

#define TN__TNS_MAXTOK 16

typedef struct tn__tns_parser {
    const char *name;
    int line;
    tn_contour_set set;
    size_t set_cap;
    tn__pts pts;
    long total_points;
} tn__tns_parser;

/* Fails with "name:line: message". */
static tn_status tn__tns_err(tn__tns_parser *p, tn_status s, const char *fmt, ...)
{
    char msg[256];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    return tn__fail(s, "%s:%d: %s", p->name, p->line, msg);
}

/* Reads a number token for field `what`; NaN/Inf -> TN_ERR_NUMERIC, text -> TN_ERR_CORRUPT. */
static tn_status tn__tns_num(tn__tns_parser *p, const char *tok, const char *what, double *v)
{
    if (!tn__io_number(tok, strlen(tok), v)) return tn__tns_err(p, TN_ERR_CORRUPT, "%s is not a number", what);
    if (!isfinite(*v) || fabs(*v) > 3.0e38) return tn__tns_err(p, TN_ERR_NUMERIC, "%s is NaN, Inf or out of float range", what);
    return TN_OK;
}

/* Polyline header: `ridge|valley [order N] [gradient G] [start H] [rate R]`. */
static tn_status tn__tns_open(tn__tns_parser *p, char **tok, int ntok, int *order, float *grad, int *has_start,
                              double *start, double *rate)
{
    int i;
    double v;
    tn_status st;
    *order = 0;
    *grad = 0.0f;
    *has_start = 0;
    *start = *rate = 0.0;
    if ((ntok - 1) % 2) return tn__tns_err(p, TN_ERR_CORRUPT, "'%s' attributes come in pairs: order N, gradient G, start H, rate R", tok[0]);
    for (i = 1; i + 1 < ntok; i += 2) {
        if ((st = tn__tns_num(p, tok[i + 1], tok[i], &v))) return st;
        if (!strcmp(tok[i], "order")) {
            if (v < 0 || v > 1000 || v != floor(v)) return tn__tns_err(p, TN_ERR_CORRUPT, "order must be an integer 0-1000");
            *order = (int)v;
        } else if (!strcmp(tok[i], "gradient")) *grad = (float)v;
        else if (!strcmp(tok[i], "start")) { *start = v; *has_start = 1; }
        else if (!strcmp(tok[i], "rate")) *rate = v;
        else return tn__tns_err(p, TN_ERR_CORRUPT, "unknown polyline attribute '%s'", tok[i]);
    }
    return TN_OK;
}

static tn_status tn__tns_parse_lines(tn__tns_parser *p, char *buf)
{
    char *line = buf, *next, *tok[TN__TNS_MAXTOK];
    int ntok, state = 0, open_line = 0, order = 0, has_start = 0;
    float grad = 0.0f;
    double start = 0, rate = 0, arc = 0;
    tn_contour_type type = TN_RIDGE;
    tn_status st;
    for (; line; line = next) {
        char *c;
        p->line++;
        next = strchr(line, '\n');
        if (next) *next++ = 0;
        if ((c = strchr(line, '#'))) *c = 0;
        for (ntok = 0, c = line;;) {
            while (*c == ' ' || *c == '\t' || *c == '\r' || *c == '\f' || *c == '\v') c++;
            if (!*c) break;
            if (ntok == TN__TNS_MAXTOK) return tn__tns_err(p, TN_ERR_CORRUPT, "too many fields on one line");
            tok[ntok++] = c;
            while (*c && *c != ' ' && *c != '\t' && *c != '\r' && *c != '\f' && *c != '\v') c++;
            if (*c) *c++ = 0;
        }
        if (!ntok) continue;
        if (state == 0) {
            if (strcmp(tok[0], "terrainnet-sketch"))
                return tn__tns_err(p, TN_ERR_FORMAT, "not a terrainnet sketch (the first line must be 'terrainnet-sketch 1')");
            if (ntok != 2 || strcmp(tok[1], "1"))
                return tn__tns_err(p, TN_ERR_FORMAT, "unsupported sketch version '%s' (this reader knows 1)", ntok > 1 ? tok[1] : "");
            state = 1;
        } else if (state == 1) {
            if (!strcmp(tok[0], "canvas")) {
                double w, h;
                if (p->set.width) return tn__tns_err(p, TN_ERR_CORRUPT, "a second 'canvas' line");
                if (ntok != 3) return tn__tns_err(p, TN_ERR_CORRUPT, "expected 'canvas WIDTH HEIGHT'");
                if ((st = tn__tns_num(p, tok[1], "canvas width", &w)) || (st = tn__tns_num(p, tok[2], "canvas height", &h))) return st;
                if (w < 1 || h < 1 || w != floor(w) || h != floor(h))
                    return tn__tns_err(p, TN_ERR_CORRUPT, "canvas size must be positive integers");
                if (w > TN_SKETCH_MAX_SIDE || h > TN_SKETCH_MAX_SIDE)
                    return tn__tns_err(p, TN_ERR_TOO_LARGE, "canvas side over the limit of %d pixels", TN_SKETCH_MAX_SIDE);
                p->set.width = (int)w;
                p->set.height = (int)h;
            } else if (!strcmp(tok[0], "ridge") || !strcmp(tok[0], "valley")) {
                if (!p->set.width) return tn__tns_err(p, TN_ERR_CORRUPT, "'%s' before the 'canvas W H' line", tok[0]);
                type = tok[0][0] == 'r' ? TN_RIDGE : TN_VALLEY;
                if ((st = tn__tns_open(p, tok, ntok, &order, &grad, &has_start, &start, &rate))) return st;
                p->pts.n = 0;
                arc = 0;
                open_line = p->line;
                state = 2;
            } else if (!strcmp(tok[0], "end")) return tn__tns_err(p, TN_ERR_CORRUPT, "'end' without an open ridge/valley");
            else return tn__tns_err(p, TN_ERR_CORRUPT, "unknown keyword '%s' (expected canvas, ridge or valley)", tok[0]);
        } else {
            double x, y, h;
            if (!strcmp(tok[0], "end")) {
                if (ntok != 1) return tn__tns_err(p, TN_ERR_CORRUPT, "'end' takes no arguments");
                if (!p->pts.n) return tn__tns_err(p, TN_ERR_CORRUPT, "the polyline opened at line %d has no points", open_line);
                if ((st = tn__cset_add(&p->set, &p->set_cap, type, order, grad, p->pts.p, p->pts.n))) return st;
                state = 1;
                continue;
            }
            if (!strcmp(tok[0], "ridge") || !strcmp(tok[0], "valley") || !strcmp(tok[0], "canvas"))
                return tn__tns_err(p, TN_ERR_CORRUPT, "missing 'end' for the polyline opened at line %d", open_line);
            if (ntok < 2 || ntok > 3) return tn__tns_err(p, TN_ERR_CORRUPT, "expected a point 'x y [h]' or 'end', got '%s'", tok[0]);
            if ((st = tn__tns_num(p, tok[0], "x", &x)) || (st = tn__tns_num(p, tok[1], "y", &y))) return st;
            if (x < -0.5 || y < -0.5 || x > p->set.width - 0.5 || y > p->set.height - 0.5)
                return tn__tns_err(p, TN_ERR_CORRUPT, "point (%g, %g) lies outside the %d x %d canvas", x, y, p->set.width, p->set.height);
            if (p->pts.n) arc += sqrt((x - p->pts.p[3 * p->pts.n - 3]) * (x - p->pts.p[3 * p->pts.n - 3]) +
                                      (y - p->pts.p[3 * p->pts.n - 2]) * (y - p->pts.p[3 * p->pts.n - 2]));
            if (ntok == 3) {
                if ((st = tn__tns_num(p, tok[2], "height", &h))) return st;
            } else if (has_start) h = start + rate * arc;
            else return tn__tns_err(p, TN_ERR_CORRUPT, "point without a height in a polyline without 'start H'");
            if (!isfinite(h) || fabs(h) > 3.0e38) return tn__tns_err(p, TN_ERR_NUMERIC, "height out of float range");
            if (++p->total_points > TN_SKETCH_MAX_POINTS)
                return tn__tns_err(p, TN_ERR_TOO_LARGE, "more than %d points", TN_SKETCH_MAX_POINTS);
            if ((st = tn__pts_push(&p->pts, (float)x, (float)y, (float)h))) return st;
        }
    }
    if (state == 0) return tn__fail(TN_ERR_FORMAT, "%s: empty file, not a terrainnet sketch", p->name);
    if (state == 2) return tn__tns_err(p, TN_ERR_CORRUPT, "end of file inside the polyline opened at line %d (missing 'end')", open_line);
    if (!p->set.width) return tn__tns_err(p, TN_ERR_CORRUPT, "no 'canvas WIDTH HEIGHT' line");
    return TN_OK;
}

TN_API tn_status tn_sketch_parse(const char *text, size_t n, const char *name, tn_contour_set *out)
{
    tn__tns_parser p;
    char *buf;
    tn_status st;
    TN_ASSERT(out);
    memset(&p, 0, sizeof p);
    p.name = name && name[0] ? name : "sketch";
    if (!text && n) return tn__fail(TN_ERR_INVALID_ARG, "%s: NULL text", p.name);
    if (n && memchr(text, 0, n)) return tn__fail(TN_ERR_FORMAT, "%s: binary data, not a terrainnet sketch", p.name);
    buf = (char *)tn__alloc(n + 1);
    if (!buf) return TN_ERR_OUT_OF_MEMORY;
    if (n) memcpy(buf, text, n);
    buf[n] = 0;
    st = tn__tns_parse_lines(&p, buf);
    TN_FREE(buf);
    TN_FREE(p.pts.p);
    if (st) {
        tn_contour_set_free(&p.set);
        return st;
    }
    *out = p.set;
    return TN_OK;
}

/* Appends the numbers in the locale-free shortest text that reads back as the same float,
   separated by spaces (so load(save(s)) == s), then `tail`. */
static tn_status tn__tns_put_numbers(void **buf, size_t *len, size_t *cap, const float *v, int n, const char *tail)
{
    char num[48];
    int i, k;
    tn_status st = TN_OK;
    for (i = 0; !st && i < n; i++) {
        k = tn__io_format_number(num + 1, sizeof num - 1, (double)v[i], 1);
        num[0] = ' ';
        st = i ? tn__io_append(buf, len, cap, num, (size_t)k + 1) : tn__io_append(buf, len, cap, num + 1, (size_t)k);
    }
    return st ? st : tn__io_append(buf, len, cap, tail, strlen(tail));
}

TN_API tn_status tn_sketch_format(const tn_contour_set *set, char **text, size_t *size)
{
    char line[96];
    void *buf = NULL;
    size_t len = 0, cap = 0;
    int i, j, k;
    tn_status st;
    TN_ASSERT(text && size);
    *text = NULL;
    *size = 0;
    if ((st = tn__cset_check(set, "sketch"))) return st;
    for (i = 0; i < set->count; i++) { /* write only what tn_sketch_parse reads back */
        const tn_contour *c = &set->items[i];
        if (c->order < 0 || c->order > 1000) return tn__fail(TN_ERR_INVALID_ARG, "sketch: polyline %d has order %d (0-1000)", i, c->order);
        for (j = 0; j < c->npoints; j++) {
            float x = c->points[3 * j], y = c->points[3 * j + 1];
            if (x < -0.5f || y < -0.5f || x > set->width - 0.5f || y > set->height - 0.5f)
                return tn__fail(TN_ERR_INVALID_ARG, "sketch: polyline %d point %d (%g, %g) lies outside the %d x %d canvas", i, j,
                                (double)x, (double)y, set->width, set->height);
        }
    }
    k = snprintf(line, sizeof line, "terrainnet-sketch 1\n# %d polylines; points are x y height\ncanvas %d %d\n", set->count,
                 set->width, set->height);
    st = tn__io_append(&buf, &len, &cap, line, (size_t)k);
    for (i = 0; !st && i < set->count; i++) {
        const tn_contour *c = &set->items[i];
        k = snprintf(line, sizeof line, c->order ? "%s order %d" : "%s", c->type == TN_RIDGE ? "ridge" : "valley", c->order);
        st = tn__io_append(&buf, &len, &cap, line, (size_t)k);
        if (!st && c->mean_gradient != 0.0f) {
            st = tn__io_append(&buf, &len, &cap, " gradient ", 10);
            if (!st) st = tn__tns_put_numbers(&buf, &len, &cap, &c->mean_gradient, 1, "\n");
        } else if (!st) st = tn__io_append(&buf, &len, &cap, "\n", 1);
        for (j = 0; !st && j < c->npoints; j++) st = tn__tns_put_numbers(&buf, &len, &cap, c->points + 3 * j, 3, "\n");
        if (!st) st = tn__io_append(&buf, &len, &cap, "end\n", 4);
    }
    if (!st && !(st = tn__io_append(&buf, &len, &cap, "", 1))) len--; /* NUL-terminated: text is a C string */
    if (st) {
        TN_FREE(buf);
        return st;
    }
    *text = (char *)buf;
    *size = len;
    return TN_OK;
}

TN_API tn_status tn_sketch_save(const char *path, const tn_contour_set *set)
{
    char *text = NULL;
    size_t n = 0;
    tn_status st;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "sketch save: empty path");
    if ((st = tn_sketch_format(set, &text, &n))) return tn__fail_context(st, path);
    st = tn__io_write_atomic(path, (const uint8_t *)text, n);
    TN_FREE(text);
    return st;
}

TN_API tn_status tn_sketch_load(const char *path, tn_contour_set *out)
{
    static const char magic[] = "terrainnet-sketch";
    uint8_t *buf = NULL;
    size_t n = 0, plen;
    tn_image img = {0, 0, 0, NULL};
    tn_status st;
    TN_ASSERT(out);
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "sketch load: empty path");
    if ((st = tn__io_read_file(path, &buf, &n))) return st;
    plen = strlen(path);
    if ((n >= sizeof magic - 1 && !memcmp(buf, magic, sizeof magic - 1)) || (plen > 4 && !strcmp(path + plen - 4, ".tns"))) {
        st = tn_sketch_parse((const char *)buf, n, path, out);
        TN_FREE(buf);
        return st;
    }
    st = tn_image_load_memory(buf, n, path, &img, NULL, NULL);
    TN_FREE(buf);
    if (st) return st;
    st = tn_sketch_from_image(&img, out);
    tn_image_free(&img);
    return st ? tn__fail_context(st, path) : TN_OK;
}

/* ---- sketches drawn as images ---- */


/* The 8 neighbours of (x, y) clockwise from north, P2..P9 in the thinning papers' naming; 0 outside. */
static void tn__nbrs(const uint8_t *m, int w, int h, int x, int y, int p[8])
{
    static const int ox[8] = {0, 1, 1, 1, 0, -1, -1, -1}, oy[8] = {-1, -1, 0, 1, 1, 1, 0, -1};
    int k;
    for (k = 0; k < 8; k++) {
        int xx = x + ox[k], yy = y + oy[k];
        p[k] = (xx >= 0 && yy >= 0 && xx < w && yy < h && m[(size_t)yy * w + xx]) ? 1 : 0;
    }
}

/* Removing a set pixel keeps the 8-connected topology iff exactly one of the four "north, east,
   south, west" corners starts a run of foreground (Yokoi's 8-connectivity number == 1). */
static int tn__yokoi8(const int p[8])
{
    int k, c = 0;
    for (k = 0; k < 8; k += 2) {
        int a = !p[k], b = !p[(k + 1) & 7], d = !p[(k + 2) & 7];
        c += a - a * b * d;
    }
    return c;
}

/* Guo-Hall sub-iteration test of the set pixel i (pass 0 or 1) on the current mask. */
static int tn__guohall_deletes(const uint8_t *m, int w, int h, size_t i, int pass)
{
    int p[8], p2, p3, p4, p5, p6, p7, p8, p9, cc, n1, n2;
    tn__nbrs(m, w, h, (int)(i % (size_t)w), (int)(i / (size_t)w), p);
    p2 = p[0]; p3 = p[1]; p4 = p[2]; p5 = p[3]; p6 = p[4]; p7 = p[5]; p8 = p[6]; p9 = p[7];
    cc = (!p2 && (p3 || p4)) + (!p4 && (p5 || p6)) + (!p6 && (p7 || p8)) + (!p8 && (p9 || p2));
    if (cc != 1) return 0;
    n1 = (p9 || p2) + (p3 || p4) + (p5 || p6) + (p7 || p8);
    n2 = (p2 || p3) + (p4 || p5) + (p6 || p7) + (p8 || p9);
    if (n2 < n1) n1 = n2;
    if (n1 < 2 || n1 > 3) return 0;
    return !(pass == 0 ? ((p6 || p7 || !p9) && p8) : ((p2 || p3 || !p5) && p4));
}

/* Simple (Yokoi number 1) and not an endpoint: the second stage removes it. */
static int tn__skel_removable(const uint8_t *m, int w, int h, size_t i)
{
    int p[8], b = 0, k;
    tn__nbrs(m, w, h, (int)(i % (size_t)w), (int)(i / (size_t)w), p);
    for (k = 0; k < 8; k++) b += p[k];
    return b >= 2 && tn__yokoi8(p) == 1;
}

/* Work lists of pixel indices for tn_skeletonize (the heap one kept in min-heap order). */
typedef struct tn__skel_list { size_t *v; size_t n, cap; } tn__skel_list;

static tn_status tn__skel_grow(tn__skel_list *l)
{
    size_t cap = l->cap * sizeof(size_t);
    tn_status st;
    if (l->n < l->cap) return TN_OK;
    if ((st = tn__reserve((void **)&l->v, &cap, (l->n + 1) * sizeof(size_t)))) return st;
    l->cap = cap / sizeof(size_t);
    return TN_OK;
}

/* Appends i unless flag[i] has `bit` (then it is queued already). */
static tn_status tn__skel_push(tn__skel_list *l, uint8_t *flag, size_t i, uint8_t bit)
{
    tn_status st;
    if (flag[i] & bit) return TN_OK;
    if ((st = tn__skel_grow(l))) return st;
    flag[i] |= bit;
    l->v[l->n++] = i;
    return TN_OK;
}

static tn_status tn__skel_heap_push(tn__skel_list *hp, uint8_t *flag, size_t i, uint8_t bit)
{
    size_t k;
    tn_status st;
    if (flag[i] & bit) return TN_OK;
    if ((st = tn__skel_grow(hp))) return st;
    flag[i] |= bit;
    for (k = hp->n++; k && hp->v[(k - 1) / 2] > i; k = (k - 1) / 2) hp->v[k] = hp->v[(k - 1) / 2];
    hp->v[k] = i;
    return TN_OK;
}

static size_t tn__skel_heap_pop(tn__skel_list *hp)
{
    size_t top = hp->v[0], last = hp->v[--hp->n], k = 0, c;
    for (; (c = 2 * k + 1) < hp->n; k = c) {
        if (c + 1 < hp->n && hp->v[c + 1] < hp->v[c]) c++;
        if (hp->v[c] >= last) break;
        hp->v[k] = hp->v[c];
    }
    if (hp->n) hp->v[k] = last;
    return top;
}

/* Guo-Hall thinning (a Zhang-Suen variant that, unlike plain Zhang-Suen, keeps two-pixel-thick
   diagonal strokes, so thin drawn lines survive), then every remaining simple pixel that is not
   an endpoint is dropped sequentially, which removes the staircase corners two pixels thick and
   keeps the topology one pixel at a time. Pixels outside the mask count as background.
   Rescanning the whole mask until nothing changes costs O(n) per round, with as many rounds as
   strokes are thick: superlinear on blobs. A pixel's test reads only its 3x3 neighbourhood, so
   after one full scan per stage only the neighbours of deleted pixels are tested again:
   - stage 1 (parallel sub-iterations, pass 0 / 1): per pass a list of pixels whose
     neighbourhood changed since that pass last tested them; a pass's deletions apply together;
   - stage 2 (sequential raster sweeps): a deletion queues the neighbours after it into the
     current sweep (a min-heap keeps raster order) and those before it into the next sweep.
   Every skipped test would have answered as before, so the output is bit-identical to the
   rescans; the work is O(n) plus O(log) per re-test, and re-tests are at most 8 per deletion. */
TN_API tn_status tn_skeletonize(uint8_t *m, int w, int h)
{
    static const int ox[8] = {0, 1, 1, 1, 0, -1, -1, -1}, oy[8] = {-1, -1, 0, 1, 1, 1, 0, -1};
    enum { IN_PASS0 = 1, IN_PASS1 = 2, IN_NOW = 4, IN_NEXT = 8 };
    tn__skel_list q[2] = {{NULL, 0, 0}, {NULL, 0, 0}}, del = {NULL, 0, 0}, heap = {NULL, 0, 0};
    uint8_t *flag;
    size_t n, i, k, cnt;
    int pass, d, full[2] = {1, 1}, idle = 0, sweep;
    tn_status st = TN_OK;
    if (!m || w <= 0 || h <= 0) return tn__fail(TN_ERR_INVALID_ARG, "skeletonize: empty mask");
    n = (size_t)w * h;
    if (!(flag = (uint8_t *)tn__calloc(n))) return TN_ERR_OUT_OF_MEMORY;
    for (i = 0; i < n; i++) m[i] = m[i] != 0;
    /* stage 1: passes alternate until two in a row delete nothing (= a whole idle round) */
    for (pass = 0; !st && idle < 2; pass ^= 1) {
        uint8_t bit = (uint8_t)(pass ? IN_PASS1 : IN_PASS0);
        cnt = full[pass] ? n : q[pass].n;
        del.n = 0;
        for (k = 0; !st && k < cnt; k++) {
            i = full[pass] ? k : q[pass].v[k];
            flag[i] &= (uint8_t)~bit;
            if (m[i] && tn__guohall_deletes(m, w, h, i, pass)) {
                if ((st = tn__skel_grow(&del))) break;
                del.v[del.n++] = i;
            }
        }
        q[pass].n = 0;
        full[pass] = 0;
        for (k = 0; k < del.n; k++) m[del.v[k]] = 0;
        for (k = 0; !st && k < del.n; k++) {
            int x = (int)(del.v[k] % (size_t)w), y = (int)(del.v[k] / (size_t)w);
            for (d = 0; !st && d < 8; d++) {
                int xx = x + ox[d], yy = y + oy[d];
                size_t j = (size_t)yy * w + xx;
                if (xx < 0 || yy < 0 || xx >= w || yy >= h || !m[j]) continue;
                if (!(st = tn__skel_push(&q[0], flag, j, IN_PASS0))) st = tn__skel_push(&q[1], flag, j, IN_PASS1);
            }
        }
        idle = del.n ? 0 : idle + 1;
    }
    /* stage 2: sweep 0 scans everything; later sweeps test the queued pixels in raster order */
    del.n = 0; /* the next sweep's pixels */
    for (sweep = 0; !st && (sweep == 0 || del.n); sweep++) {
        for (k = 0; !st && k < del.n; k++) {
            flag[del.v[k]] &= (uint8_t)~IN_NEXT;
            st = tn__skel_heap_push(&heap, flag, del.v[k], IN_NOW);
        }
        del.n = 0;
        for (k = 0; !st && (sweep == 0 ? k < n : heap.n > 0); k++) {
            int x, y;
            if (sweep == 0) i = k;
            else {
                i = tn__skel_heap_pop(&heap);
                flag[i] &= (uint8_t)~IN_NOW;
            }
            if (!m[i] || !tn__skel_removable(m, w, h, i)) continue;
            m[i] = 0;
            x = (int)(i % (size_t)w);
            y = (int)(i / (size_t)w);
            for (d = 0; !st && d < 8; d++) {
                int xx = x + ox[d], yy = y + oy[d];
                size_t j = (size_t)yy * w + xx;
                if (xx < 0 || yy < 0 || xx >= w || yy >= h || !m[j]) continue;
                if (j < i) st = tn__skel_push(&del, flag, j, IN_NEXT);
                else if (sweep > 0) st = tn__skel_heap_push(&heap, flag, j, IN_NOW); /* sweep 0 gets there anyway */
            }
        }
    }
    TN_FREE(flag);
    TN_FREE(q[0].v);
    TN_FREE(q[1].v);
    TN_FREE(del.v);
    TN_FREE(heap.v);
    return st;
}

/* D8 neighbour offsets: E, SE, S, SW, W, NW, N, NE (flow directions in >>extract too). */
static const int tn__d8x[8] = {1, 1, 0, -1, -1, -1, 0, 1};
static const int tn__d8y[8] = {0, 1, 1, 1, 0, -1, -1, -1};

/* Number of set 8-neighbours. */
static int tn__skel_degree(const uint8_t *m, int w, int h, int x, int y)
{
    int p[8], k, b = 0;
    tn__nbrs(m, w, h, x, y, p);
    for (k = 0; k < 8; k++) b += p[k];
    return b;
}

/* Traces the skeleton into polylines between nodes (endpoints, junctions: degree != 2) and
   closed loops. Each polyline's pixels are listed as cell indices in *cells (per line offsets in
   *starts, count + 1 entries). Deterministic raster order. */
typedef struct tn__trace {
    size_t *cells, *starts;
    size_t ncells, nlines, cap_c, cap_s; /* caps in bytes (tn__reserve) */
} tn__trace;

static tn_status tn__trace_push(tn__trace *t, size_t cell)
{
    tn_status st = tn__reserve((void **)&t->cells, &t->cap_c, (t->ncells + 1) * sizeof(size_t));
    if (st) return st;
    t->cells[t->ncells++] = cell;
    return TN_OK;
}

static tn_status tn__trace_end_line(tn__trace *t)
{
    tn_status st = tn__reserve((void **)&t->starts, &t->cap_s, (t->nlines + 2) * sizeof(size_t));
    if (st) return st;
    if (t->nlines == 0) t->starts[0] = 0;
    t->starts[++t->nlines] = t->ncells;
    return TN_OK;
}

static void tn__trace_free(tn__trace *t)
{
    TN_FREE(t->cells);
    TN_FREE(t->starts);
    memset(t, 0, sizeof *t);
}

static tn_status tn__trace_skeleton(const uint8_t *m, int w, int h, tn__trace *t)
{
    const int *ox = tn__d8x, *oy = tn__d8y;
    size_t n = (size_t)w * h, i;
    uint8_t *deg = (uint8_t *)tn__alloc(n), *vis = (uint8_t *)tn__calloc(n);
    tn_status st = TN_OK;
    int pass;
    memset(t, 0, sizeof *t);
    if (!deg || !vis) {
        TN_FREE(deg);
        TN_FREE(vis);
        return TN_ERR_OUT_OF_MEMORY;
    }
    for (i = 0; i < n; i++) deg[i] = m[i] ? (uint8_t)tn__skel_degree(m, w, h, (int)(i % (size_t)w), (int)(i / (size_t)w)) : 0;
    /* pass 0: lines leaving nodes; pass 1: closed loops of degree-2 pixels left over */
    for (pass = 0; pass < 2 && !st; pass++)
        for (i = 0; i < n && !st; i++) {
            int x = (int)(i % (size_t)w), y = (int)(i / (size_t)w), d;
            if (!m[i]) continue;
            if (pass == 0 && deg[i] == 2) continue;
            if (pass == 1 && vis[i]) continue;
            if (pass == 0 && deg[i] == 0) { /* isolated pixel: a one-point line */
                vis[i] = 1;
                if (!(st = tn__trace_push(t, i))) st = tn__trace_end_line(t);
                continue;
            }
            for (d = 0; d < 8 && !st; d++) {
                int nx = x + ox[d], ny = y + oy[d];
                size_t q, prev = i, cur;
                if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
                q = (size_t)ny * w + nx;
                if (!m[q]) continue;
                if (pass == 1 && d > 0 && vis[q]) continue;
                if (deg[q] != 2) { /* node next to node: a two-point line, listed once */
                    if (pass == 0 && q > i) {
                        if (!(st = tn__trace_push(t, i)) && !(st = tn__trace_push(t, q))) st = tn__trace_end_line(t);
                    }
                    continue;
                }
                if (vis[q]) continue;
                vis[i] = 1;
                if ((st = tn__trace_push(t, i))) break;
                cur = q;
                for (;;) {
                    int cx = (int)(cur % (size_t)w), cy = (int)(cur / (size_t)w), e;
                    size_t next = (size_t)-1;
                    if ((st = tn__trace_push(t, cur))) break;
                    if (deg[cur] != 2 || (pass == 1 && cur == i)) break;
                    vis[cur] = 1;
                    for (e = 0; e < 8; e++) {
                        int ex = cx + ox[e], ey = cy + oy[e];
                        size_t r;
                        if (ex < 0 || ey < 0 || ex >= w || ey >= h) continue;
                        r = (size_t)ey * w + ex;
                        if (!m[r] || r == prev) continue;
                        if (r == i && pass == 1 && prev != i) { next = r; break; }
                        if (deg[r] == 2 && vis[r]) continue;
                        next = r;
                        break;
                    }
                    if (next == (size_t)-1) break;
                    prev = cur;
                    cur = next;
                }
                if (!st) st = tn__trace_end_line(t);
                if (pass == 1) break; /* one loop per start pixel */
            }
        }
    TN_FREE(deg);
    TN_FREE(vis);
    if (st) tn__trace_free(t);
    return st;
}

TN_API tn_status tn_sketch_from_image(const tn_image *img, tn_contour_set *out)
{
    tn_contour_set set;
    size_t cap = 0, n, i, bytes;
    uint8_t *mask = NULL;
    float *hgt = NULL;
    int type, strokes = 0;
    tn_status st = TN_OK;
    TN_ASSERT(out);
    if (!img || !img->data || img->width <= 0 || img->height <= 0) return tn__fail(TN_ERR_EMPTY, "sketch image: empty image");
    if (img->channels < 3)
        return tn__fail(TN_ERR_SHAPE, "sketch image: needs colour (red ridges, blue valleys), got %d channel(s)", img->channels);
    if (img->width > TN_SKETCH_MAX_SIDE || img->height > TN_SKETCH_MAX_SIDE)
        return tn__fail(TN_ERR_TOO_LARGE, "sketch image: %d x %d exceeds the canvas limit", img->width, img->height);
    /* an Inf channel passes the stroke test and would become an Inf height */
    if ((n = tn_image_range(img, NULL, NULL)) != 0)
        return tn__fail(TN_ERR_NUMERIC, "sketch image: %zu NaN/Inf samples", n);
    n = (size_t)img->width * img->height;
    if (tn__size4(n, 1, sizeof(float), 1, &bytes)) return TN_ERR_TOO_LARGE;
    memset(&set, 0, sizeof set);
    set.width = img->width;
    set.height = img->height;
    mask = (uint8_t *)tn__alloc(n);
    hgt = (float *)tn__alloc(bytes);
    if (!mask || !hgt) st = TN_ERR_OUT_OF_MEMORY;
    for (type = 0; !st && type < 2; type++) {
        tn__trace t;
        tn__pts pts = {NULL, 0, 0};
        size_t l, k;
        for (i = 0; i < n; i++) {
            const float *p = img->data + i * (size_t)img->channels;
            float r = p[0], g = p[1], b = p[2], v = r > b ? r : b;
            int on = v >= 0.1f && v - g >= 0.5f * v && fabsf(r - b) >= 0.5f * v && ((r > b) == (type == TN_RIDGE));
            mask[i] = (uint8_t)on;
            hgt[i] = on ? v : 0.0f;
            strokes += on;
        }
        if ((st = tn_skeletonize(mask, img->width, img->height))) break;
        if ((st = tn__trace_skeleton(mask, img->width, img->height, &t))) break;
        for (l = 0; !st && l < t.nlines; l++) { /* chains of 3+ pixels become polylines */
            if (t.starts[l + 1] - t.starts[l] < 3) continue;
            pts.n = 0;
            for (k = t.starts[l]; !st && k < t.starts[l + 1]; k++) {
                size_t c = t.cells[k];
                st = tn__pts_push(&pts, (float)(c % (size_t)img->width), (float)(c / (size_t)img->width), hgt[c]);
            }
            if (!st) st = tn__cset_add(&set, &cap, (tn_contour_type)type, 0, 0.0f, pts.p, pts.n);
        }
        TN_FREE(pts.p);
        tn__trace_free(&t);
    }
    TN_FREE(mask);
    TN_FREE(hgt);
    if (!st && !strokes) st = tn__fail(TN_ERR_EMPTY, "sketch image: no red (ridge) or blue (valley) strokes");
    if (!st && !set.count) st = tn__fail(TN_ERR_EMPTY, "sketch image: strokes too small to trace (need 3+ pixels)");
    if (st) {
        tn_contour_set_free(&set);
        return st;
    }
    *out = set;
    return TN_OK;
}

/* ---- densify, rasterise, preview ---- */

TN_API tn_status tn_sketch_densify(const tn_contour_set *in, tn_contour_set *out)
{
    tn_contour_set set;
    tn__pts pts = {NULL, 0, 0};
    size_t cap = 0;
    int i;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__cset_check(in, "densify"))) return st;
    memset(&set, 0, sizeof set);
    set.width = in->width;
    set.height = in->height;
    for (i = 0; !st && i < in->count; i++) {
        const tn_contour *c = &in->items[i];
        pts.n = 0;
        if (!(st = tn__chain_pixels(c->points, c->npoints, 1.0f, 1.0f, &pts)))
            st = tn__cset_add(&set, &cap, c->type, c->order, c->mean_gradient, pts.p, pts.n);
    }
    TN_FREE(pts.p);
    if (st) {
        tn_contour_set_free(&set);
        return st;
    }
    *out = set;
    return TN_OK;
}

TN_API tn_status tn_sketch_rasterise(const tn_contour_set *set, int width, int height, tn_image *out)
{
    tn_image r = {0, 0, 0, NULL};
    tn__pts pts = {NULL, 0, 0};
    int i, j;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__cset_check(set, "rasterise"))) return st;
    if (width <= 0 || height <= 0) return tn__fail(TN_ERR_INVALID_ARG, "rasterise: size %d x %d", width, height);
    if ((st = tn_image_create(&r, width, height, 3))) return st;
    for (i = 0; !st && i < set->count; i++) {
        const tn_contour *c = &set->items[i];
        pts.n = 0;
        st = tn__chain_pixels(c->points, c->npoints, (float)width / (float)set->width, (float)height / (float)set->height, &pts);
        for (j = 0; !st && j < pts.n; j++) {
            int x = (int)pts.p[3 * j], y = (int)pts.p[3 * j + 1];
            float *px;
            if (x < 0 || y < 0 || x >= width || y >= height) continue;
            px = &TN_PIXEL(&r, x, y, 0);
            px[0] = c->type == TN_RIDGE ? 1.0f : 0.0f;
            px[1] = c->type == TN_RIDGE ? 0.0f : 1.0f;
            px[2] = pts.p[3 * j + 2];
        }
    }
    TN_FREE(pts.p);
    if (st) {
        tn_image_free(&r);
        return st;
    }
    *out = r;
    return TN_OK;
}

TN_API tn_status tn_sketch_preview(const tn_contour_set *set, const tn_image *dem, int width, int height, tn_image *out)
{
    tn_image lines = {0, 0, 0, NULL}, rgb = {0, 0, 0, NULL}, small = {0, 0, 0, NULL}, shade = {0, 0, 0, NULL};
    int x, y, u, v, rad = width > height ? width / 512 : height / 512;
    size_t i, n;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn_sketch_rasterise(set, width, height, &lines))) return st;
    if ((st = tn_image_create(&rgb, width, height, 3))) goto fail;
    n = (size_t)width * height;
    if (dem && dem->data) {
        if ((st = tn_image_resize(&small, dem, width, height, TN_RESIZE_BILINEAR)) || (st = tn_image_hillshade(&shade, &small, NULL)))
            goto fail;
        for (i = 0; i < n; i++) rgb.data[3 * i] = rgb.data[3 * i + 1] = rgb.data[3 * i + 2] = 0.15f + 0.7f * shade.data[i];
    } else
        for (i = 0; i < 3 * n; i++) rgb.data[i] = 0.35f;
    for (y = 0; y < height; y++)
        for (x = 0; x < width; x++) {
            const float *l = &TN_PIXEL(&lines, x, y, 0);
            if (l[0] == 0.0f && l[1] == 0.0f) continue;
            for (v = y - rad; v <= y + rad; v++)
                for (u = x - rad; u <= x + rad; u++) {
                    float *p;
                    if (u < 0 || v < 0 || u >= width || v >= height) continue;
                    p = &TN_PIXEL(&rgb, u, v, 0);
                    if (l[0] != 0.0f) { p[0] = 1.0f; p[1] = 0.9f; p[2] = 0.0f; }            /* ridge: yellow */
                    else if (p[2] != 0.0f || p[0] != 1.0f) { p[0] = 0.1f; p[1] = 0.35f; p[2] = 1.0f; } /* valley: blue */
                }
        }
    tn_image_free(&lines);
    tn_image_free(&small);
    tn_image_free(&shade);
    *out = rgb;
    return TN_OK;
fail:
    tn_image_free(&lines);
    tn_image_free(&rgb);
    tn_image_free(&small);
    tn_image_free(&shade);
    return st;
}

/* ---- Delaunay triangulation and minimum spanning tree ---- */

typedef struct tn__tri { int v[3]; double cx, cy, r2; } tn__tri;

/* Circumcircle of triangle (a, b, c); a degenerate (collinear) one gets an infinite circle so the
   next insertion replaces it. */
static void tn__circumcircle(tn__tri *t, const double *p)
{
    double ax = p[2 * t->v[0]], ay = p[2 * t->v[0] + 1], bx = p[2 * t->v[1]] - ax, by = p[2 * t->v[1] + 1] - ay;
    double cx = p[2 * t->v[2]] - ax, cy = p[2 * t->v[2] + 1] - ay, d = 2.0 * (bx * cy - by * cx);
    double b2 = bx * bx + by * by, c2 = cx * cx + cy * cy, ux, uy;
    if (fabs(d) < 1e-12 * (b2 + c2)) {
        t->cx = ax;
        t->cy = ay;
        t->r2 = HUGE_VAL;
        return;
    }
    ux = (cy * b2 - by * c2) / d;
    uy = (bx * c2 - cx * b2) / d;
    t->cx = ax + ux;
    t->cy = ay + uy;
    t->r2 = ux * ux + uy * uy;
}

TN_API tn_status tn_delaunay(const float *xy, int n, int **triangles, int *ntriangles)
{
    double *p = NULL, lo_x, lo_y, hi_x, hi_y, span;
    tn__tri *tri = NULL;
    int *bad = NULL, *edges = NULL, *res = NULL;
    size_t tri_cap = 0, bad_cap = 0, edge_cap = 0;
    int ntri = 0, i, j, k, nbad, nedge, nres = 0;
    tn_status st = TN_OK;
    TN_ASSERT(triangles && ntriangles);
    *triangles = NULL;
    *ntriangles = 0;
    if (n < 0 || n > (1 << 24) || (n > 0 && !xy)) return tn__fail(TN_ERR_INVALID_ARG, "delaunay: %d points", n);
    if (!(p = (double *)tn__alloc(((size_t)n + 3) * 2 * sizeof(double)))) return TN_ERR_OUT_OF_MEMORY;
    lo_x = lo_y = 0.0;
    hi_x = hi_y = 1.0;
    for (i = 0; i < n; i++) {
        if (!isfinite(xy[2 * i]) || !isfinite(xy[2 * i + 1])) {
            TN_FREE(p);
            return tn__fail(TN_ERR_NUMERIC, "delaunay: point %d is NaN/Inf", i);
        }
        p[2 * i] = xy[2 * i];
        p[2 * i + 1] = xy[2 * i + 1];
        if (i == 0 || p[2 * i] < lo_x) lo_x = p[2 * i];
        if (i == 0 || p[2 * i] > hi_x) hi_x = p[2 * i];
        if (i == 0 || p[2 * i + 1] < lo_y) lo_y = p[2 * i + 1];
        if (i == 0 || p[2 * i + 1] > hi_y) hi_y = p[2 * i + 1];
    }
    /* super triangle far around the points; removed at the end */
    span = fmax(fmax(hi_x - lo_x, hi_y - lo_y), 1.0) * 64.0;
    p[2 * n] = 0.5 * (lo_x + hi_x) - 2.0 * span;
    p[2 * n + 1] = lo_y - span;
    p[2 * n + 2] = 0.5 * (lo_x + hi_x) + 2.0 * span;
    p[2 * n + 3] = lo_y - span;
    p[2 * n + 4] = 0.5 * (lo_x + hi_x);
    p[2 * n + 5] = hi_y + 2.0 * span;
    if ((st = tn__reserve((void **)&tri, &tri_cap, sizeof(tn__tri)))) goto done;
    tri[0].v[0] = n;
    tri[0].v[1] = n + 1;
    tri[0].v[2] = n + 2;
    tn__circumcircle(&tri[0], p);
    ntri = 1;
    for (i = 0; i < n; i++) {
        double x = p[2 * i], y = p[2 * i + 1];
        int dup = 0;
        for (nbad = 0, j = 0; j < ntri; j++) {
            double dx = x - tri[j].cx, dy = y - tri[j].cy;
            if (dx * dx + dy * dy >= tri[j].r2) continue;
            if ((st = tn__reserve((void **)&bad, &bad_cap, ((size_t)nbad + 1) * sizeof(int)))) goto done;
            bad[nbad++] = j;
            for (k = 0; k < 3; k++) dup |= p[2 * tri[j].v[k]] == x && p[2 * tri[j].v[k] + 1] == y;
        }
        if (dup || !nbad) continue; /* exact duplicate of a vertex */
        /* the cavity boundary: edges of bad triangles not shared by two of them */
        for (nedge = 0, j = 0; j < nbad; j++)
            for (k = 0; k < 3; k++) {
                int a = tri[bad[j]].v[k], b = tri[bad[j]].v[(k + 1) % 3], e, shared = 0;
                for (e = 0; e < nbad && !shared; e++) {
                    const int *w = tri[bad[e]].v;
                    if (e == j) continue;
                    shared = (w[0] == b && w[1] == a) || (w[1] == b && w[2] == a) || (w[2] == b && w[0] == a) ||
                             (w[0] == a && w[1] == b) || (w[1] == a && w[2] == b) || (w[2] == a && w[0] == b);
                }
                if (shared) continue;
                if ((st = tn__reserve((void **)&edges, &edge_cap, ((size_t)nedge + 1) * 2 * sizeof(int)))) goto done;
                edges[2 * nedge] = a;
                edges[2 * nedge + 1] = b;
                nedge++;
            }
        /* remove bad triangles (highest index first, swap with the last), add the fan */
        for (j = nbad - 1; j >= 0; j--) tri[bad[j]] = tri[--ntri];
        if ((st = tn__reserve((void **)&tri, &tri_cap, ((size_t)ntri + nedge) * sizeof(tn__tri)))) goto done;
        for (j = 0; j < nedge; j++) {
            tri[ntri].v[0] = edges[2 * j];
            tri[ntri].v[1] = edges[2 * j + 1];
            tri[ntri].v[2] = i;
            tn__circumcircle(&tri[ntri], p);
            ntri++;
        }
    }
    if (!(res = (int *)tn__alloc(((size_t)ntri + 1) * 3 * sizeof(int)))) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    for (j = 0; j < ntri; j++) {
        if (tri[j].v[0] >= n || tri[j].v[1] >= n || tri[j].v[2] >= n) continue;
        res[3 * nres] = tri[j].v[0];
        res[3 * nres + 1] = tri[j].v[1];
        res[3 * nres + 2] = tri[j].v[2];
        nres++;
    }
done:
    TN_FREE(p);
    TN_FREE(tri);
    TN_FREE(bad);
    TN_FREE(edges);
    if (st) {
        TN_FREE(res);
        return st;
    }
    *triangles = res;
    *ntriangles = nres;
    return TN_OK;
}

TN_API tn_status tn_mst(const float *xy, int n, int **edges)
{
    double *best;
    int *from, *e, i, j, k;
    uint8_t *in;
    TN_ASSERT(edges);
    *edges = NULL;
    if (n < 1 || n > (1 << 24) || !xy) return tn__fail(TN_ERR_INVALID_ARG, "mst: %d points", n);
    for (i = 0; i < 2 * n; i++) /* NaN distances never compare smaller: no vertex would be picked */
        if (!isfinite(xy[i])) return tn__fail(TN_ERR_NUMERIC, "mst: point %d is NaN/Inf", i / 2);
    best = (double *)tn__alloc((size_t)n * sizeof(double));
    from = (int *)tn__alloc((size_t)n * sizeof(int));
    in = (uint8_t *)tn__calloc((size_t)n);
    e = (int *)tn__alloc((size_t)n * 2 * sizeof(int));
    if (!best || !from || !in || !e) {
        TN_FREE(best); TN_FREE(from); TN_FREE(in); TN_FREE(e);
        return TN_ERR_OUT_OF_MEMORY;
    }
    for (i = 0; i < n; i++) {
        best[i] = HUGE_VAL;
        from[i] = 0;
    }
    k = 0; /* the vertex added last */
    in[0] = 1;
    for (i = 1; i < n; i++) {
        int pick = -1;
        for (j = 0; j < n; j++) {
            double dx, dy, d;
            if (in[j]) continue;
            dx = (double)xy[2 * j] - xy[2 * k];
            dy = (double)xy[2 * j + 1] - xy[2 * k + 1];
            d = dx * dx + dy * dy;
            if (d < best[j]) { best[j] = d; from[j] = k; }
            if (pick < 0 || best[j] < best[pick]) pick = j;
        }
        in[pick] = 1;
        e[2 * (i - 1)] = from[pick];
        e[2 * (i - 1) + 1] = pick;
        k = pick;
    }
    TN_FREE(best);
    TN_FREE(from);
    TN_FREE(in);
    *edges = e;
    return TN_OK;
}

/* ---- random sketches ---- */

/* Pixel occupancy for "does this edge cross anything": an 8-connected chain crosses the marked
   pixels when it steps on one, or steps diagonally between two marked pixels (an X crossing). */
static void tn__occ_mark(uint8_t *occ, int w, int h, const tn__pts *c)
{
    int j;
    for (j = 0; j < c->n; j++) {
        int x = (int)c->p[3 * j], y = (int)c->p[3 * j + 1];
        if (x >= 0 && y >= 0 && x < w && y < h) occ[(size_t)y * w + x] = 1;
    }
}

static int tn__occ_hits(const uint8_t *occ, int w, int h, const tn__pts *c)
{
    int j;
    for (j = 0; j < c->n; j++) {
        int x = (int)c->p[3 * j], y = (int)c->p[3 * j + 1];
        if (x < 0 || y < 0 || x >= w || y >= h) continue;
        if (occ[(size_t)y * w + x]) return 1;
        if (j > 0) {
            int px = (int)c->p[3 * j - 3], py = (int)c->p[3 * j - 2];
            if (px != x && py != y && px >= 0 && py >= 0 && px < w && py < h && occ[(size_t)py * w + x] && occ[(size_t)y * w + px])
                return 1;
        }
    }
    return 0;
}

/* Keeps the edges (pairs into xy) whose pixel chain misses occ; kept[] gets them, *nkept their count. */
static tn_status tn__keep_free_edges(const float *xy, const int *edges, int nedges, const uint8_t *occ, int w, int h, int *kept,
                                     int *nkept, tn__pts *tmp)
{
    int i;
    tn_status st;
    float ends[6] = {0, 0, 0, 0, 0, 0};
    *nkept = 0;
    for (i = 0; i < nedges; i++) {
        int a = edges[2 * i], b = edges[2 * i + 1];
        ends[0] = xy[2 * a]; ends[1] = xy[2 * a + 1]; ends[3] = xy[2 * b]; ends[4] = xy[2 * b + 1];
        tmp->n = 0;
        if ((st = tn__chain_pixels(ends, 2, 1.0f, 1.0f, tmp))) return st;
        if (tn__occ_hits(occ, w, h, tmp)) continue;
        kept[2 * *nkept] = a;
        kept[2 * *nkept + 1] = b;
        (*nkept)++;
    }
    return TN_OK;
}

/* Chains the kept edges of a forest (vertex positions/heights vx, vy, vh) between vertices of
   degree != 2 and appends each chain as an 8-connected pixel polyline of the given type. */
static tn_status tn__add_chains(const float *vx, const float *vh, int nv, const int *edges, int nedges, tn_contour_type type,
                                tn_contour_set *out, size_t *cap)
{
    int *deg = NULL, *adj_start = NULL, *adj = NULL, *fill = NULL, i, k;
    uint8_t *used = NULL;
    tn__pts ctrl = {NULL, 0, 0}, pix = {NULL, 0, 0};
    tn_status st = TN_OK;
    deg = (int *)tn__calloc(((size_t)nv + 1) * sizeof(int));
    adj_start = (int *)tn__calloc(((size_t)nv + 1) * sizeof(int));
    fill = (int *)tn__calloc(((size_t)nv + 1) * sizeof(int));
    adj = (int *)tn__alloc(((size_t)nedges * 2 + 1) * sizeof(int));
    used = (uint8_t *)tn__calloc((size_t)nedges + 1);
    if (!deg || !adj_start || !fill || !adj || !used) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    for (k = 0; k < nedges; k++) { deg[edges[2 * k]]++; deg[edges[2 * k + 1]]++; }
    for (i = 0; i < nv; i++) adj_start[i + 1] = adj_start[i] + deg[i];
    for (k = 0; k < nedges; k++) { /* adjacency holds edge ids */
        adj[adj_start[edges[2 * k]] + fill[edges[2 * k]]++] = k;
        adj[adj_start[edges[2 * k + 1]] + fill[edges[2 * k + 1]]++] = k;
    }
    for (i = 0; i < nv && !st; i++) {
        int a;
        if (deg[i] == 2 || deg[i] == 0) continue;
        for (a = adj_start[i]; a < adj_start[i + 1] && !st; a++) {
            int e = adj[a], v = i;
            if (used[e]) continue;
            ctrl.n = 0;
            st = tn__pts_push(&ctrl, vx[2 * v], vx[2 * v + 1], vh[v]);
            while (!st && e >= 0) {
                int b;
                used[e] = 1;
                v = edges[2 * e] == v ? edges[2 * e + 1] : edges[2 * e];
                st = tn__pts_push(&ctrl, vx[2 * v], vx[2 * v + 1], vh[v]);
                e = -1;
                if (deg[v] != 2) break;
                for (b = adj_start[v]; b < adj_start[v + 1]; b++)
                    if (!used[adj[b]]) e = adj[b];
            }
            pix.n = 0;
            if (!st) st = tn__chain_pixels(ctrl.p, ctrl.n, 1.0f, 1.0f, &pix);
            if (!st && pix.n >= 2) st = tn__cset_add(out, cap, type, 0, 0.0f, pix.p, pix.n);
        }
    }
done:
    TN_FREE(deg);
    TN_FREE(adj_start);
    TN_FREE(fill);
    TN_FREE(adj);
    TN_FREE(used);
    TN_FREE(ctrl.p);
    TN_FREE(pix.p);
    return st;
}

/* The zero rule of tn_sketch_random_opts: one ridge node per 1024 px of the canvas, 8 to 2048. */
static void tn__sketch_random_opts_defaults(tn_sketch_random_opts *o, int width, int height)
{
    if (o->nodes == 0) o->nodes = tn__clampi((int)((double)width * height / 1024.0), 8, 2048);
}

TN_API tn_status tn_sketch_random(const tn_contour_set *user, int width, int height, const tn_sketch_random_opts *opts,
                                  tn_contour_set *out)
{
    tn_sketch_random_opts o;
    tn_contour_set set;
    tn__pts tmp = {NULL, 0, 0};
    tn_rng rng;
    uint8_t *occ = NULL;
    float *node = NULL, *nh = NULL, *vor = NULL, *vh = NULL;
    int *redges = NULL, *vedges = NULL, *tris = NULL, *keep_r = NULL, *keep_v = NULL;
    int n, ntri = 0, nv = 0, nkr = 0, nkv = 0, i, j;
    size_t cap = 0;
    tn_status st = TN_OK;
    TN_ASSERT(out);
    memset(&set, 0, sizeof set);
    if (width < 2 || height < 2) return tn__fail(TN_ERR_INVALID_ARG, "random sketch: canvas %d x %d (need at least 2 x 2)", width, height);
    if (width > TN_SKETCH_MAX_SIDE || height > TN_SKETCH_MAX_SIDE)
        return tn__fail(TN_ERR_TOO_LARGE, "random sketch: canvas %d x %d exceeds %d", width, height, TN_SKETCH_MAX_SIDE);
    if (user && user->count) {
        if ((st = tn__cset_check(user, "random sketch: user sketch"))) return st;
        if (user->width != width || user->height != height)
            return tn__fail(TN_ERR_SHAPE, "random sketch: the user sketch canvas is %d x %d, not %d x %d", user->width,
                            user->height, width, height);
    }
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    if (o.nodes < 0) return tn__fail(TN_ERR_INVALID_ARG, "random sketch: %d nodes", o.nodes);
    tn__sketch_random_opts_defaults(&o, width, height);
    n = o.nodes;
    if (n > 8192) return tn__fail(TN_ERR_TOO_LARGE, "random sketch: %d nodes (at most 8192)", n);
    tn_rng_seed(&rng, o.seed, 0x5e7c4u);
    set.width = width;
    set.height = height;
    node = (float *)tn__alloc((size_t)n * 2 * sizeof(float));
    nh = (float *)tn__alloc((size_t)n * sizeof(float));
    if (!node || !nh) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    for (i = 0; i < n; i++) {
        node[2 * i] = tn_rng_uniform(&rng) * (float)(width - 1);
        node[2 * i + 1] = tn_rng_uniform(&rng) * (float)(height - 1);
        nh[i] = 0.5f + 0.5f * tn_rng_uniform(&rng);
    }
    if ((st = tn_mst(node, n, &redges)) || (st = tn_delaunay(node, n, &tris, &ntri))) goto done;
    /* Voronoi vertices = circumcentres of the Delaunay triangles, kept inside the canvas */
    vor = (float *)tn__alloc(((size_t)ntri + 1) * 2 * sizeof(float));
    vh = (float *)tn__alloc(((size_t)ntri + 1) * sizeof(float));
    if (!vor || !vh) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    for (i = 0; i < ntri; i++) {
        double pts[6];
        tn__tri t;
        for (j = 0; j < 3; j++) {
            pts[2 * j] = node[2 * tris[3 * i + j]];
            pts[2 * j + 1] = node[2 * tris[3 * i + j] + 1];
            t.v[j] = j;
        }
        tn__circumcircle(&t, pts);
        if (!(t.r2 < HUGE_VAL) || t.cx < 0 || t.cy < 0 || t.cx > width - 1 || t.cy > height - 1) continue;
        vor[2 * nv] = (float)t.cx;
        vor[2 * nv + 1] = (float)t.cy;
        vh[nv++] = 0.5f * tn_rng_uniform(&rng);
    }
    if (nv >= 2 && (st = tn_mst(vor, nv, &vedges))) goto done;
    /* user pixels first: ridge edges must miss them; then kept ridges too: valley edges must miss both */
    keep_r = (int *)tn__alloc((size_t)n * 2 * sizeof(int));
    keep_v = (int *)tn__alloc(((size_t)nv + 1) * 2 * sizeof(int));
    occ = (uint8_t *)tn__calloc((size_t)width * height);
    if (!keep_r || !keep_v || !occ) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    for (i = 0; user && i < user->count && !st; i++) {
        tmp.n = 0;
        if (!(st = tn__chain_pixels(user->items[i].points, user->items[i].npoints, 1.0f, 1.0f, &tmp))) tn__occ_mark(occ, width, height, &tmp);
    }
    if (st || (st = tn__keep_free_edges(node, redges, n - 1, occ, width, height, keep_r, &nkr, &tmp))) goto done;
    for (i = 0; i < nkr && !st; i++) {
        float ends[6] = {0, 0, 0, 0, 0, 0};
        ends[0] = node[2 * keep_r[2 * i]]; ends[1] = node[2 * keep_r[2 * i] + 1];
        ends[3] = node[2 * keep_r[2 * i + 1]]; ends[4] = node[2 * keep_r[2 * i + 1] + 1];
        tmp.n = 0;
        if (!(st = tn__chain_pixels(ends, 2, 1.0f, 1.0f, &tmp))) tn__occ_mark(occ, width, height, &tmp);
    }
    if (st || (nv >= 2 && (st = tn__keep_free_edges(vor, vedges, nv - 1, occ, width, height, keep_v, &nkv, &tmp)))) goto done;
    for (i = 0; user && i < user->count && !st; i++)
        st = tn__cset_add(&set, &cap, user->items[i].type, user->items[i].order, user->items[i].mean_gradient,
                          user->items[i].points, user->items[i].npoints);
    if (!st) st = tn__add_chains(node, nh, n, keep_r, nkr, TN_RIDGE, &set, &cap);
    if (!st) st = tn__add_chains(vor, vh, nv, keep_v, nkv, TN_VALLEY, &set, &cap);
done:
    TN_FREE(node); TN_FREE(nh); TN_FREE(vor); TN_FREE(vh);
    TN_FREE(redges); TN_FREE(vedges); TN_FREE(tris); TN_FREE(keep_r); TN_FREE(keep_v);
    TN_FREE(occ);
    TN_FREE(tmp.p);
    if (st) {
        tn_contour_set_free(&set);
        return st;
    }
    *out = set;
    return TN_OK;
}

/* ---- contour parts ---- */

/* A polyline end for the contour-graph DFS: end e = 2 * line (first point) or 2 * line + 1 (last),
   at pixel (x, y) of a type; sorted so the ends at and around a pixel are found by bisection. */
typedef struct tn__pend { int type, y, x, e; } tn__pend;

static int tn__pend_cmp(const void *pa, const void *pb)
{
    const tn__pend *a = (const tn__pend *)pa, *b = (const tn__pend *)pb;
    if (a->type != b->type) return a->type < b->type ? -1 : 1;
    if (a->y != b->y) return a->y < b->y ? -1 : 1;
    if (a->x != b->x) return a->x < b->x ? -1 : 1;
    return (a->e > b->e) - (a->e < b->e);
}

typedef struct tn__pgraph {
    const tn_contour_set *lines;
    tn__pend *ends;     /* 2 * count, sorted */
    int *stack;
    size_t nstack, cap_stack; /* cap in bytes */
    uint8_t *seen;      /* per line */
    float *pts;         /* the DFS list: x, y, h */
    int *src;           /* line of each listed point */
    size_t npts;
} tn__pgraph;

static tn__pend tn__pend_of(const tn_contour_set *s, int e)
{
    const tn_contour *c = &s->items[e / 2];
    const float *p = c->points + (e & 1 ? 3 * (c->npoints - 1) : 0);
    tn__pend r;
    r.type = (int)c->type;
    r.x = (int)floorf(p[0] + 0.5f);
    r.y = (int)floorf(p[1] + 0.5f);
    r.e = e;
    return r;
}

/* Counts the ends of other lines at the same or an 8-adjacent pixel as end e (same type), in
   sorted order. push != 0 also pushes those of unseen lines (their entry end) onto the DFS stack. */
static int tn__pend_attached(tn__pgraph *g, int e, int push, tn_status *st)
{
    const tn__pend me = tn__pend_of(g->lines, e);
    const int m = 2 * g->lines->count;
    int dy, dx, found = 0;
    for (dy = -1; dy <= 1; dy++)
        for (dx = -1; dx <= 1; dx++) {
            tn__pend key;
            int lo = 0, hi = m;
            key.type = me.type;
            key.y = me.y + dy;
            key.x = me.x + dx;
            key.e = -1;
            while (lo < hi) { /* first end >= key */
                int mid = lo + (hi - lo) / 2;
                if (tn__pend_cmp(&g->ends[mid], &key) < 0) lo = mid + 1;
                else hi = mid;
            }
            for (; lo < m && g->ends[lo].type == key.type && g->ends[lo].y == key.y && g->ends[lo].x == key.x; lo++) {
                int o = g->ends[lo].e;
                if (o / 2 == e / 2) continue;
                found++;
                if (!push || g->seen[o / 2]) continue;
                if ((g->nstack + 1) * sizeof(int) > g->cap_stack &&
                    (*st = tn__reserve((void **)&g->stack, &g->cap_stack, (g->nstack + 1) * sizeof(int))))
                    return found;
                g->stack[g->nstack++] = o;
            }
        }
    return found;
}

/* Depth-first walk of the contour graph from end e: each line is listed from the end it is
   entered by; lines hanging on its far end come next, then those on its near end. */
static tn_status tn__pgraph_dfs(tn__pgraph *g, int e, size_t *cap_pts, size_t *cap_src)
{
    tn_status st = tn__reserve((void **)&g->stack, &g->cap_stack, sizeof(int));
    if (st) return st;
    g->nstack = 0;
    g->stack[g->nstack++] = e;
    while (g->nstack) {
        int in = g->stack[--g->nstack], l = in / 2, k;
        const tn_contour *c = &g->lines->items[l];
        size_t n0, top;
        if (g->seen[l]) continue;
        g->seen[l] = 1;
        if ((st = tn__reserve((void **)&g->pts, cap_pts, (g->npts + (size_t)c->npoints) * 3 * sizeof(float))) ||
            (st = tn__reserve((void **)&g->src, cap_src, (g->npts + (size_t)c->npoints) * sizeof(int))))
            return st;
        for (k = 0; k < c->npoints; k++) {
            const float *p = c->points + 3 * (in & 1 ? c->npoints - 1 - k : k);
            float *q = g->pts + 3 * g->npts;
            if (g->npts && q[-3] == p[0] && q[-2] == p[1]) continue; /* a shared junction pixel */
            memcpy(q, p, 3 * sizeof(float));
            g->src[g->npts++] = l;
        }
        n0 = g->nstack;
        tn__pend_attached(g, in ^ 1, 1, &st);
        if (!st) tn__pend_attached(g, in, 1, &st);
        if (st) return st;
        top = g->nstack; /* reversed, so the far end's lines come next (in sorted order), then the near end's */
        for (; n0 + 1 < top; n0++, top--) {
            int t = g->stack[n0];
            g->stack[n0] = g->stack[top - 1];
            g->stack[top - 1] = t;
        }
    }
    return TN_OK;
}

/* Cuts the DFS list into parts: runs of 8-adjacent points, each cut into windows of 5-10 points
   (a tail under 5 joins the last window when that stays <= 10); shorter runs are dropped. */
static tn_status tn__parts_cut(const tn__pgraph *g, tn_rng *rng, tn_contour_set *set, size_t *cap)
{
    const float *p = g->pts;
    size_t at = 0, n = g->npts;
    tn_status st = TN_OK;
    while (!st && at < n) {
        size_t end = at + 1;
        while (end < n && fabsf(p[3 * end] - p[3 * end - 3]) <= 1.5f && fabsf(p[3 * end + 1] - p[3 * end - 2]) <= 1.5f) end++;
        while (!st && end - at >= 5) {
            int left = (int)(end - at), len = 5 + (int)tn_rng_below(rng, 6);
            const tn_contour *c = &g->lines->items[g->src[at]];
            if (len > left) len = left;
            if (left - len > 0 && left - len < 5) len = left <= 10 ? left : left - 5; /* no short tail */
            st = tn__cset_add(set, cap, c->type, c->order, c->mean_gradient, p + 3 * at, len);
            at += (size_t)len;
        }
        at = end;
    }
    return st;
}

TN_API tn_status tn_contour_parts_make(const tn_contour_set *lines, uint64_t seed, tn_contour_set *parts)
{
    tn_contour_set set;
    tn__pgraph g;
    tn_rng rng;
    size_t cap = 0, cap_pts = 0, cap_src = 0;
    int i, pass;
    tn_status st;
    TN_ASSERT(parts);
    if ((st = tn__cset_check(lines, "contour parts"))) return st;
    memset(&set, 0, sizeof set);
    memset(&g, 0, sizeof g);
    set.width = lines->width;
    set.height = lines->height;
    tn_rng_seed(&rng, seed, 0x9a27u);
    g.lines = lines;
    if (lines->count) {
        g.ends = (tn__pend *)tn__alloc((size_t)lines->count * 2 * sizeof(tn__pend));
        g.seen = (uint8_t *)tn__calloc((size_t)lines->count);
        if (!g.ends || !g.seen) st = TN_ERR_OUT_OF_MEMORY;
    }
    if (!st) {
        for (i = 0; i < 2 * lines->count; i++) g.ends[i] = tn__pend_of(lines, i);
        if (lines->count) qsort(g.ends, (size_t)lines->count * 2, sizeof(tn__pend), tn__pend_cmp);
    }
    /* DFS from every free end (an endpoint of the graph) in line order, then from whatever is
       left (closed loops) at its first point */
    for (pass = 0; pass < 2 && !st; pass++)
        for (i = 0; i < lines->count && !st; i++) {
            int e = -1;
            if (g.seen[i]) continue;
            if (pass == 1) e = 2 * i;
            else if (!tn__pend_attached(&g, 2 * i, 0, &st)) e = 2 * i;
            else if (!tn__pend_attached(&g, 2 * i + 1, 0, &st)) e = 2 * i + 1;
            if (e < 0) continue;
            g.npts = 0;
            if (!(st = tn__pgraph_dfs(&g, e, &cap_pts, &cap_src))) st = tn__parts_cut(&g, &rng, &set, &cap);
        }
    TN_FREE(g.ends);
    TN_FREE(g.stack);
    TN_FREE(g.seen);
    TN_FREE(g.pts);
    TN_FREE(g.src);
    if (st) {
        tn_contour_set_free(&set);
        return st;
    }
    *parts = set;
    return TN_OK;
}

/* ---- alignment ---- */

/* Chain codes of a set of parts, each oriented left to right (A1). */
typedef struct tn__chains {
    int count;
    int *off;          /* codes of part i: code[off[i] .. off[i + 1]) */
    uint8_t *code;     /* 0..7: direction k * pi/4 (x right, y down) */
    int *at;           /* index into h of the start point of each code's step */
    float *h;          /* heights, oriented, scaled to [0, 1] unless raw; hoff[i] indexes part i */
    int *hoff;
    float *angle;      /* direction of the first-to-last vector, in units of pi/4 */
    uint8_t *type;
} tn__chains;

#define TN__ALIGN_MAXCODES 255

static void tn__chains_free(tn__chains *c)
{
    TN_FREE(c->off); TN_FREE(c->code); TN_FREE(c->at); TN_FREE(c->h); TN_FREE(c->hoff); TN_FREE(c->angle); TN_FREE(c->type);
    memset(c, 0, sizeof *c);
}

static tn_status tn__chains_make(const tn_contour_set *s, int raw, int flip, tn__chains *c)
{
    size_t npts = 0;
    int i, j;
    float lo = 0, hi = 0, scale;
    memset(c, 0, sizeof *c);
    for (i = 0; i < s->count; i++) {
        npts += (size_t)s->items[i].npoints;
        for (j = 0; j < s->items[i].npoints; j++) {
            float h = s->items[i].points[3 * j + 2];
            if ((i == 0 && j == 0) || h < lo) lo = h;
            if ((i == 0 && j == 0) || h > hi) hi = h;
        }
    }
    if (npts >= (size_t)INT_MAX) return tn__fail(TN_ERR_TOO_LARGE, "align: %zu points", npts);
    scale = raw ? 1.0f : (hi > lo ? 1.0f / (hi - lo) : 0.0f);
    if (raw) lo = 0.0f;
    c->count = s->count;
    c->off = (int *)tn__alloc(((size_t)s->count + 1) * sizeof(int));
    c->hoff = (int *)tn__alloc(((size_t)s->count + 1) * sizeof(int));
    c->code = (uint8_t *)tn__alloc(npts + 1);
    c->at = (int *)tn__alloc((npts + 1) * sizeof(int));
    c->h = (float *)tn__alloc((npts + 1) * sizeof(float));
    c->angle = (float *)tn__alloc(((size_t)s->count + 1) * sizeof(float));
    c->type = (uint8_t *)tn__alloc((size_t)s->count + 1);
    if (!c->off || !c->hoff || !c->code || !c->at || !c->h || !c->angle || !c->type) {
        tn__chains_free(c);
        return TN_ERR_OUT_OF_MEMORY;
    }
    c->off[0] = c->hoff[0] = 0;
    for (i = 0; i < s->count; i++) {
        const tn_contour *p = &s->items[i];
        int n = p->npoints, rev, nc = 0, base = c->hoff[i];
        const float *f = p->points, *l = p->points + 3 * (n - 1);
        rev = (f[0] > l[0] || (f[0] == l[0] && f[1] > l[1])) != flip; /* run in the main direction */
        for (j = 0; j < n; j++) c->h[base + j] = (p->points[3 * (rev ? n - 1 - j : j) + 2] - lo) * scale;
        c->angle[i] = (float)(atan2(rev ? f[1] - l[1] : l[1] - f[1], rev ? f[0] - l[0] : l[0] - f[0]) / 0.78539816339744831);
        for (j = 0; j + 1 < n && nc < TN__ALIGN_MAXCODES; j++) {
            const float *a = p->points + 3 * (rev ? n - 1 - j : j), *b = p->points + 3 * (rev ? n - 2 - j : j + 1);
            float dx = b[0] - a[0], dy = b[1] - a[1];
            if (dx == 0.0f && dy == 0.0f) continue; /* repeated point: no step */
            c->code[c->off[i] + nc] = (uint8_t)((int)lrint(atan2(dy, dx) / 0.78539816339744831) & 7);
            c->at[c->off[i] + nc] = base + j;
            nc++;
        }
        c->off[i + 1] = c->off[i] + nc;
        c->hoff[i + 1] = base + n;
        c->type[i] = (uint8_t)(p->type == TN_RIDGE);
    }
    return TN_OK;
}

typedef struct tn__align_cand { int len; float score; int index; } tn__align_cand;

/* a ranks before b by LCS length, then height score, then index */
static int tn__cand_better(const tn__align_cand *a, const tn__align_cand *b)
{
    if (a->len != b->len) return a->len > b->len;
    if (a->score != b->score) return a->score < b->score;
    return a->index < b->index;
}

typedef struct tn__align_job {
    const tn__chains *sk, *skr, *dem; /* skr: the sketch parts run the other way */
    int top, choices, any_type[2];
    uint64_t seed;
    int *match;
    size_t first;                     /* this batch starts at sketch part `first` */
} tn__align_job;

/* |mean(d)| + std(d) of the height differences on the common substring (P from pi, Q from qi,
   len steps, so len + 1 points); without a common step the first points are compared. */
static float tn__align_score(const tn__chains *sk, int i, int pi, const tn__chains *dem, int q, int qi, int len)
{
    double s = 0, s2 = 0, d;
    int t, m = len + 1, a, b;
    if (len == 0) {
        m = sk->hoff[i + 1] - sk->hoff[i];
        if (dem->hoff[q + 1] - dem->hoff[q] < m) m = dem->hoff[q + 1] - dem->hoff[q];
    }
    for (t = 0; t < m; t++) {
        if (len == 0) { a = sk->hoff[i] + t; b = dem->hoff[q] + t; }
        else if (t < len) { a = sk->at[pi + t]; b = dem->at[qi + t]; }
        else { a = sk->at[pi + len - 1] + 1; b = dem->at[qi + len - 1] + 1; }
        d = (double)sk->h[a] - dem->h[b];
        s += d;
        s2 += d * d;
    }
    s /= m;
    s2 = s2 / m - s * s;
    return (float)(fabs(s) + sqrt(s2 > 0 ? s2 : 0));
}

/* A sketch part's codes in the 8 rotations: rot[k][x] = code x turned by k * pi/4, and (for
   parts of at most 64 codes) bit x of mask[k][c] set when rot[k][x] == c. */
typedef struct tn__align_rot {
    uint8_t rot[8][TN__ALIGN_MAXCODES];
    uint64_t mask[8][8];
} tn__align_rot;

static void tn__align_rotations(const tn__chains *sk, int i, tn__align_rot *r)
{
    int k, x, np = sk->off[i + 1] - sk->off[i];
    memset(r->mask, 0, sizeof r->mask);
    for (k = 0; k < 8; k++)
        for (x = 0; x < np; x++) {
            r->rot[k][x] = (uint8_t)((sk->code[sk->off[i] + x] + k) & 7);
            if (x < 64) r->mask[k][r->rot[k][x]] |= (uint64_t)1 << x;
        }
}

/* Longest common substring of sketch part i's codes, rotated onto DEM part q by the multiple of
   pi/4 nearest the angle between their first-to-last vectors; *ps / *qs: where it starts.
   Bit-parallel for parts up to 64 codes: e[y] holds the x where p[x - L + 1 .. x] equals
   q[y - L + 1 .. y], grown one level L at a time until it empties. Longer parts walk only the
   diagonals that overlap by at least `need` codes (an answer < need then only says "not enough"). */
static int tn__align_lcs(const tn__chains *sk, int i, const tn__align_rot *r, const tn__chains *dem, int q, int need,
                         int *ps, int *qs)
{
    const uint8_t *p, *qc = dem->code + dem->off[q];
    int np = sk->off[i + 1] - sk->off[i], nq = dem->off[q + 1] - dem->off[q], x, y, d, len = 0, k;
    *ps = sk->off[i];
    *qs = dem->off[q];
    if (need < 1) need = 1;
    if (np < need || nq < need) return 0;
    k = (int)lrintf(dem->angle[q] - sk->angle[i]) & 7;
    if (np <= 64) {
        uint64_t e[TN__ALIGN_MAXCODES], any = 0;
        const uint64_t *m = r->mask[k];
        int hit = -1;
        for (y = nq - 1; y >= 0; y--) {
            e[y] = m[qc[y]];
            if (e[y]) hit = y;
            any |= e[y];
        }
        while (any) {
            len++;
            *ps = sk->off[i] + (int)tn__z_ctz64(e[hit]) - len + 1;
            *qs = dem->off[q] + hit - len + 1;
            any = 0;
            for (y = nq - 1; y >= len; y--) {
                e[y] = (e[y - 1] << 1) & m[qc[y]];
                if (e[y]) hit = y;
                any |= e[y];
            }
        }
        return len;
    }
    p = r->rot[k];
    for (d = need - np; d <= nq - need; d++) { /* q index = p index + d */
        int x0 = d < 0 ? -d : 0, x1 = np < nq - d ? np : nq - d, run = 0;
        for (x = x0; x < x1; x++) {
            run = p[x] == qc[x + d] ? run + 1 : 0;
            if (run > len) {
                len = run;
                *ps = sk->off[i] + x + 1 - run;
                *qs = dem->off[q] + x + d + 1 - run;
            }
        }
    }
    return len;
}

static void tn__align_rows(void *ctx, size_t begin, size_t end)
{
    const tn__align_job *job = (const tn__align_job *)ctx;
    begin += job->first;
    end += job->first;
    const tn__chains *dem = job->dem;
    tn__align_cand cand[64], c, r;
    tn__align_rot rotf, rotr;
    size_t i;
    for (i = begin; i < end; i++) {
        int ncand = 0, q, x, y, at, type = job->sk->type[i], ps, qs, ps2, qs2, need;
        tn_rng rng;
        tn__align_rotations(job->sk, (int)i, &rotf);
        tn__align_rotations(job->skr, (int)i, &rotr);
        for (q = 0; q < dem->count; q++) {
            if (job->any_type[type] && dem->type[q] != type) continue;
            need = ncand == job->top ? cand[ncand - 1].len : 0; /* to enter a full list */
            /* both directions of the sketch part: A1's left-to-right rule alone is not rotation invariant */
            c.len = tn__align_lcs(job->sk, (int)i, &rotf, dem, q, need, &ps, &qs);
            r.len = tn__align_lcs(job->skr, (int)i, &rotr, dem, q, need, &ps2, &qs2);
            if (c.len < need && r.len < need) continue;
            c.index = r.index = q;
            c.score = r.score = HUGE_VALF;
            if (c.len >= r.len) c.score = tn__align_score(job->sk, (int)i, ps, dem, q, qs, c.len);
            if (r.len >= c.len) r.score = tn__align_score(job->skr, (int)i, ps2, dem, q, qs2, r.len);
            if (tn__cand_better(&r, &c)) c = r;
            if (ncand == job->top && !tn__cand_better(&c, &cand[ncand - 1])) continue;
            if (ncand < job->top) ncand++;
            for (at = ncand - 1; at > 0 && tn__cand_better(&c, &cand[at - 1]); at--) cand[at] = cand[at - 1];
            cand[at] = c;
        }
        if (!ncand) { job->match[i] = -1; continue; }
        /* rank the top list by height score, pick one of the best `choices` */
        for (x = 1; x < ncand; x++) {
            c = cand[x];
            for (y = x; y > 0 && (c.score < cand[y - 1].score || (c.score == cand[y - 1].score && c.index < cand[y - 1].index)); y--)
                cand[y] = cand[y - 1];
            cand[y] = c;
        }
        tn_rng_seed(&rng, job->seed, (uint64_t)i);
        job->match[i] = cand[tn_rng_below(&rng, (uint32_t)(ncand < job->choices ? ncand : job->choices))].index;
    }
}

/* The zero rules of tn_align_opts: 10 candidates (also for a negative count; at most 64), a
   pick among the best 5 (also for a negative count). */
static void tn__align_opts_defaults(tn_align_opts *o)
{
    if (o->top <= 0) o->top = 10;
    if (o->top > 64) o->top = 64;
    if (o->choices <= 0) o->choices = 5;
}

TN_API tn_status tn_sketch_align(const tn_contour_set *sketch_parts, const tn_contour_set *dem_parts, const tn_align_opts *opts,
                                 int *match)
{
    tn_align_opts o;
    tn__chains sk, skr, dem;
    tn__align_job job;
    int i;
    tn_status st;
    TN_ASSERT(match);
    if ((st = tn__cset_check(sketch_parts, "align: sketch parts")) || (st = tn__cset_check(dem_parts, "align: DEM parts")))
        return st;
    if (!sketch_parts->count) return tn__fail(TN_ERR_EMPTY, "align: the sketch has no parts");
    if (!dem_parts->count) return tn__fail(TN_ERR_EMPTY, "align: the DEM has no contour parts");
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    tn__align_opts_defaults(&o);
    memset(&job, 0, sizeof job);
    job.top = o.top;
    job.choices = o.choices;
    job.seed = o.seed;
    job.match = match;
    if ((st = tn__chains_make(sketch_parts, o.raw_heights, 0, &sk))) return st;
    if ((st = tn__chains_make(sketch_parts, o.raw_heights, 1, &skr))) {
        tn__chains_free(&sk);
        return st;
    }
    if ((st = tn__chains_make(dem_parts, o.raw_heights, 0, &dem))) {
        tn__chains_free(&sk);
        tn__chains_free(&skr);
        return st;
    }
    for (i = 0; i < dem.count; i++) job.any_type[dem.type[i] ? 1 : 0] = 1;
    job.sk = &sk;
    job.skr = &skr;
    job.dem = &dem;
    /* batches between progress reports; each part's result is independent of the split */
    for (job.first = 0; !st && job.first < (size_t)sk.count; job.first += 1024) {
        size_t n = (size_t)sk.count - job.first < 1024 ? (size_t)sk.count - job.first : 1024;
        tn_parallel_for(n, 8, tn__align_rows, &job);
        st = tn__progress("align", (double)(job.first + n) / (double)sk.count);
    }
    tn__chains_free(&sk);
    tn__chains_free(&skr);
    tn__chains_free(&dem);
    return st;
}

/* --------------------------------------------------------------------------------------------
   >>extract  (@@extract implementation)
   Filling works on order-preserving integer keys of the float heights (key + 1 = nextafter), so
   the priority queue is a radix heap: priority-flood pops never decrease, which is all a radix
   heap needs, and pushes/pops are O(1) amortised without the cache misses of a binary heap.
   Accumulation and Strahler order walk down from cells with no upstream neighbour, each cell
   once it has heard from all of them (Kahn's order without a queue); accumulation runs one
   strip of rows per thread and then finishes the flow that crossed strips in strip order.
   -------------------------------------------------------------------------------------------- */

/* Order-preserving map float -> uint32 (-0 and +0 share a key). */
static uint32_t tn__fkey(float f)
{
    uint32_t u;
    if (f == 0.0f) f = 0.0f;
    memcpy(&u, &f, 4);
    return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

static float tn__fkey_inv(uint32_t k)
{
    uint32_t u = (k & 0x80000000u) ? (k & 0x7fffffffu) : ~k;
    float f;
    memcpy(&f, &u, 4);
    return f;
}

/* Monotone priority queue of (key, cell): a radix heap with byte digits (Ahuja et al. 1990).
   Bucket [l][v] holds the keys that agree with `last` above byte l and have byte l equal to v
   (above last's); level 0 bucket v holds the single key (last & ~0xff) | v. When level 0 runs
   dry, the lowest non-empty bucket above gives the new `last` (its minimum) and its items move
   down at least one level, so each item moves at most three times. Equal keys pop first in,
   first out (moves keep the order), as in r.watershed's A* search, whose tie order decides
   where flow crosses flats. */
typedef struct tn__rheap_item { uint32_t key, cell; } tn__rheap_item;
typedef struct tn__rheap {
    tn__rheap_item *b[4][256];
    uint32_t n[4][256];
    size_t cap[4][256]; /* bytes */
    uint64_t used[4][4]; /* bit v of level l: bucket [l][v] is not empty */
    uint32_t head[256];  /* next item to pop in each level-0 bucket */
    uint32_t last;
    size_t size;
} tn__rheap;

static int tn__ctz64(uint64_t x)
{
#if defined(__GNUC__) || defined(__clang__)
    return __builtin_ctzll(x);
#else
    int b = 0;
    while (!(x & 1u)) { x >>= 1; b++; }
    return b;
#endif
}

static tn_status tn__rheap_push(tn__rheap *h, uint32_t key, uint32_t cell)
{
    uint32_t x = key ^ h->last;
    int l = x >> 8 ? (x >> 16 ? (x >> 24 ? 3 : 2) : 1) : 0, v = (int)(key >> (8 * l)) & 255;
    tn__rheap_item *it;
    if ((size_t)(h->n[l][v] + 1) * sizeof(tn__rheap_item) > h->cap[l][v]) {
        void *p = h->b[l][v];
        tn_status st = tn__reserve(&p, &h->cap[l][v], (size_t)(h->n[l][v] + 1) * sizeof(tn__rheap_item));
        if (st) return st;
        h->b[l][v] = (tn__rheap_item *)p;
    }
    it = h->b[l][v] + h->n[l][v]++;
    it->key = key;
    it->cell = cell;
    h->used[l][v >> 6] |= (uint64_t)1 << (v & 63);
    h->size++;
    return TN_OK;
}

/* Lowest non-empty bucket of level l, or -1. */
static int tn__rheap_first(const tn__rheap *h, int l)
{
    int q;
    for (q = 0; q < 4; q++)
        if (h->used[l][q]) return q * 64 + tn__ctz64(h->used[l][q]);
    return -1;
}

/* Pops a minimum; the heap must not be empty. */
static tn_status tn__rheap_pop(tn__rheap *h, uint32_t *key, uint32_t *cell)
{
    int v = tn__rheap_first(h, 0);
    if (v < 0) {
        int l = 1, u;
        uint32_t i, m, mn = 0xffffffffu;
        tn__rheap_item *b;
        while ((u = tn__rheap_first(h, l)) < 0) l++;
        b = h->b[l][u];
        m = h->n[l][u];
        for (i = 0; i < m; i++) if (b[i].key < mn) mn = b[i].key;
        h->last = mn;
        h->n[l][u] = 0;
        h->used[l][u >> 6] &= ~((uint64_t)1 << (u & 63));
        h->size -= m;
        for (i = 0; i < m; i++) { /* all land below level l, never in this bucket */
            tn_status st = tn__rheap_push(h, b[i].key, b[i].cell);
            if (st) return st;
        }
        v = tn__rheap_first(h, 0);
    }
    {
        tn__rheap_item *it = h->b[0][v] + h->head[v]++;
        *key = it->key;
        *cell = it->cell;
        if (h->head[v] == h->n[0][v]) {
            h->head[v] = h->n[0][v] = 0;
            h->used[0][v >> 6] &= ~((uint64_t)1 << (v & 63));
        }
        h->size--;
    }
    return TN_OK;
}

/* The cell a pop will return next (for prefetching), or `none` when level 0 is empty. */
static uint32_t tn__rheap_peek(const tn__rheap *h, uint32_t none)
{
    int v = tn__rheap_first(h, 0);
    return v < 0 ? none : h->b[0][v][h->head[v]].cell;
}

static void tn__rheap_free(tn__rheap *h)
{
    int l, v;
    for (l = 0; l < 4; l++)
        for (v = 0; v < 256; v++) TN_FREE(h->b[l][v]);
}

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
static tn_status tn__dem_check(const tn_image *dem, int min_side, const char *what)
{
    if (!dem || !dem->data || dem->width <= 0 || dem->height <= 0 || dem->channels <= 0)
        return tn__fail(TN_ERR_EMPTY, "%s: the DEM is empty", what);
    if (dem->width < min_side || dem->height < min_side)
        return tn__fail(TN_ERR_INVALID_ARG, "%s: the DEM must be at least %d x %d pixels", what, min_side, min_side);
    return tn__dem_finite(dem, what);
}

/* Channel 0 of src as a new one-channel image (D8 and the metrics read plain height grids). */
static tn_status tn__channel0_image(const tn_image *src, tn_image *dst)
{
    size_t i, n = (size_t)src->width * src->height;
    tn_status st = tn__image_alloc(dst, src->width, src->height, 1);
    if (st) return st;
    for (i = 0; i < n; i++) dst->data[i] = src->data[i * (size_t)src->channels];
    return TN_OK;
}

/* Min-heap of (priority, cell) for the cells of depressions: 4-ary, items of 16 bytes,
   so a node's children share one cache line. */
typedef struct tn__pheap_item { uint64_t pri; uint32_t cell, pad; } tn__pheap_item;
typedef struct tn__pheap { tn__pheap_item *a; size_t n, cap; } tn__pheap; /* cap in bytes */

static tn_status tn__pheap_push(tn__pheap *h, uint64_t pri, uint32_t cell)
{
    size_t i;
    tn_status st = tn__reserve((void **)&h->a, &h->cap, (h->n + 1) * sizeof(tn__pheap_item));
    if (st) return st;
    for (i = h->n++; i > 0 && h->a[(i - 1) / 4].pri > pri; i = (i - 1) / 4) h->a[i] = h->a[(i - 1) / 4];
    h->a[i].pri = pri;
    h->a[i].cell = cell;
    return TN_OK;
}

/* The smallest of the children c .. min(c + 4, n) - 1 (c < n), branch-free when all four exist:
   the comparisons are unpredictable. Priorities are unique (they hold a sequence number). */
static size_t tn__pheap_minchild(const tn__pheap_item *a, size_t c, size_t n)
{
    size_t b, k;
    if (c + 4 <= n) {
        size_t b01 = a[c + 1].pri < a[c].pri ? c + 1 : c, b23 = a[c + 3].pri < a[c + 2].pri ? c + 3 : c + 2;
        return a[b23].pri < a[b01].pri ? b23 : b01;
    }
    for (b = c, k = c + 1; k < n; k++) b = a[k].pri < a[b].pri ? k : b;
    return b;
}

/* Replaces the top by `it` (sifted down); returns the old top's cell. */
static uint32_t tn__pheap_replace(tn__pheap *h, tn__pheap_item it)
{
    uint32_t top = h->a[0].cell;
    size_t i = 0, c, b;
    while ((c = 4 * i + 1) < h->n && h->a[b = tn__pheap_minchild(h->a, c, h->n)].pri < it.pri) {
        h->a[i] = h->a[b];
        i = b;
    }
    h->a[i] = it;
    return top;
}

/* Pops the top. The last item came from the bottom, so the hole goes down to a leaf along the
   smaller children and the item climbs back from there: fewer comparisons than testing it on
   the way down. */
static uint32_t tn__pheap_pop(tn__pheap *h)
{
    uint32_t top = h->a[0].cell;
    tn__pheap_item last = h->a[--h->n];
    size_t i = 0, c, b;
    while ((c = 4 * i + 1) < h->n) {
        b = tn__pheap_minchild(h->a, c, h->n);
        h->a[i] = h->a[b];
        i = b;
    }
    while (i > 0 && h->a[(i - 1) / 4].pri > last.pri) {
        h->a[i] = h->a[(i - 1) / 4];
        i = (i - 1) / 4;
    }
    h->a[i] = last;
    return top;
}

/* Filling runs on a copy of the keys framed by one cell of closed sentinels (TN__FRAME), so no
   neighbour lookup needs a bounds check. */
#define TN__CLOSED 0x80000000u /* in the key word: saves a cache miss per neighbour */
#define TN__FRAME 0xffffffffu

typedef struct tn__fill_state {
    uint32_t *keys;           /* framed: (w + 2) x (h + 2) */
    uint8_t *par;             /* framed, or NULL: direction from each raised cell to the cell that raised it */
    ptrdiff_t off[8];         /* neighbour offsets in the framed grid */
    tn__rheap *q;
    tn__pheap pit;
    uint32_t *trace;          /* stack of slope cells processed out of order (Zhou et al. 2016) */
    size_t ntrace, cap_trace; /* cap in bytes */
    uint32_t seq;
    tn__pheap_item next;      /* the lowest pit cell the last expansion found (when has_next) */
    int has_next;
} tn__fill_state;

/* r.watershed's neighbour order (S, N, W, E, NE, SW, SE, NW): cardinal cells join the queues
   first, so they are the older ones when a flat or depression is crossed. */
static const uint8_t tn__fill_order[8] = {2, 6, 4, 0, 7, 3, 1, 5};

/* Closes the open neighbours of c (filled key k) for a flood at level lvl (k for a cell at its
   own height; the water level inside a depression): lower ones are raised to k + 1 and join the
   pit heap; ones at lvl..k are raised to k + 1 and queue at lvl, behind the cells already there
   (so a flat fills in rings from all its lower edges, oldest first, as in r.watershed's A*
   search); higher ones keep their height and go on the trace stack. Raised cells remember c. */
static tn_status tn__fill_expand(tn__fill_state *f, uint32_t c, uint32_t k, uint32_t lvl)
{
    int o;
    for (o = 0; o < 8; o++) {
        const int d = tn__fill_order[o];
        size_t ni = (size_t)((ptrdiff_t)c + f->off[d]);
        uint32_t v = f->keys[ni];
        tn_status st;
        if (v & TN__CLOSED) continue;
        if (v <= k) {
            f->keys[ni] = (k + 1) | TN__CLOSED;
            if (f->par) f->par[ni] = (uint8_t)((d + 4) & 7);
            if (v < lvl) { /* in a depression: one step above c */
                tn__pheap_item it;
                it.pri = ((uint64_t)v << 32) | f->seq++;
                it.cell = (uint32_t)ni;
                it.pad = 0;
                /* the lowest stays out of the heap: it is often the next pop (the flood runs downhill) */
                if (f->has_next && f->next.pri < it.pri) {
                    if ((st = tn__pheap_push(&f->pit, it.pri, it.cell))) return st;
                } else {
                    if (f->has_next && (st = tn__pheap_push(&f->pit, f->next.pri, f->next.cell))) return st;
                    f->next = it;
                    f->has_next = 1;
                }
            } else if ((st = tn__rheap_push(f->q, lvl, (uint32_t)ni))) return st;
        }
    }
    for (o = 7; o >= 0; o--) { /* reversed, so the trace stack hands them out in the order above */
        const int d = tn__fill_order[o];
        size_t ni = (size_t)((ptrdiff_t)c + f->off[d]);
        uint32_t v = f->keys[ni];
        if (v & TN__CLOSED) continue;
        f->keys[ni] = v | TN__CLOSED;
        if ((f->ntrace + 1) * sizeof(uint32_t) > f->cap_trace) {
            tn_status st = tn__reserve((void **)&f->trace, &f->cap_trace, (f->ntrace + 1) * sizeof(uint32_t));
            if (st) return st;
        }
        f->trace[f->ntrace++] = (uint32_t)ni;
    }
    return TN_OK;
}

/* Fills the framed keys in place by priority-flood + epsilon (Barnes et al. 2014), visiting
   cells in r.watershed's A* order (lowest first, equal heights oldest first), with two speed-ups
   that keep most cells out of the priority queue and its random memory access:
   - slope tracing (Zhou, Sun & Fu 2016): a cell reached from below whose open neighbours are all
     strictly higher keeps its height and is expanded at once, depth first, where its
     neighbourhood is still in cache; only cells with a lower open neighbour wait in the queue;
   - the pit queue of the improved variant, here a heap on the ORIGINAL heights (ties first come,
     first served): a depression fills from its outlet along its deepest path first, like
     r.watershed's least-cost search, so flow follows the depression's thalweg (or, on an
     inverted DEM, a summit's crest) instead of parallel straight lines.
   The main queue is a radix heap of (level, cell): every key pushed is at or above the last one
   popped. When par is given, each raised cell records the cell that raised it: r.watershed's
   flow direction on flats and in depressions, and a strict descent of the filled keys. */
static tn_status tn__fill_keys(uint32_t *keys, uint8_t *par, int w, int h)
{
    tn__fill_state f;
    const size_t W = (size_t)w + 2, n = (size_t)w * h;
    size_t done = 0;
    tn_status st = TN_OK;
    uint32_t flood = 0; /* level of the last main-queue pop: the water level inside a depression */
    int x, y, d;
    memset(&f, 0, sizeof f);
    f.q = (tn__rheap *)tn__calloc(sizeof(tn__rheap));
    if (!f.q) return TN_ERR_OUT_OF_MEMORY;
    f.keys = keys;
    f.par = par;
    for (d = 0; d < 8; d++) f.off[d] = (ptrdiff_t)tn__d8y[d] * (ptrdiff_t)W + tn__d8x[d];
    for (y = 0; y < h && !st; y++)
        for (x = 0; x < w && !st; x += (y == 0 || y == h - 1 || x == w - 1) ? 1 : w - 1) {
            size_t i = (size_t)(y + 1) * W + (size_t)x + 1;
            st = tn__rheap_push(f.q, keys[i], (uint32_t)i);
            keys[i] |= TN__CLOSED;
        }
    while (!st && (f.q->size || f.pit.n || f.has_next)) {
        uint32_t k, c, lvl;
        if (f.has_next) { /* the heap's minimum is either it or the heap's top */
            f.has_next = 0;
            c = f.pit.n && f.pit.a[0].pri < f.next.pri ? tn__pheap_replace(&f.pit, f.next) : f.next.cell;
            lvl = flood;
        } else if (f.pit.n) {
            c = tn__pheap_pop(&f.pit);
            lvl = flood;
        } else if ((st = tn__rheap_pop(f.q, &lvl, &c))) break;
        else flood = lvl;
        k = keys[c] & ~TN__CLOSED; /* above lvl for a raised cell */
        { /* the pops jump around the map: fetch the next cell's rows while this one is processed */
            uint32_t nx = f.has_next ? f.next.cell : f.pit.n ? f.pit.a[0].cell : tn__rheap_peek(f.q, c);
            TN__PREFETCH(keys + nx - W - 1);
            TN__PREFETCH(keys + nx - 1);
            TN__PREFETCH(keys + nx + W - 1);
        }
        if ((st = tn__fill_expand(&f, c, k, lvl))) break;
        while (f.ntrace && !st) {
            const uint32_t t = f.trace[--f.ntrace], kt = keys[t] & ~TN__CLOSED, *p = keys + t;
            /* closed neighbours (and the frame) have the top bit set, so they are never <= kt.
               An open neighbour as low or lower may drain elsewhere at a lower level (and raising
               it here would start a pit cascade above the queue's level): wait in order */
            int lower = p[f.off[0]] <= kt || p[f.off[1]] <= kt || p[f.off[2]] <= kt || p[f.off[3]] <= kt ||
                        p[f.off[4]] <= kt || p[f.off[5]] <= kt || p[f.off[6]] <= kt || p[f.off[7]] <= kt;
            st = lower ? tn__rheap_push(f.q, kt, t) : tn__fill_expand(&f, t, kt, kt);
            done++;
        }
        if (!st && (++done & 0xfffff) < 16) st = tn__progress("fill", (double)done / (double)n);
    }
    tn__rheap_free(f.q);
    TN_FREE(f.q);
    TN_FREE(f.pit.a);
    TN_FREE(f.trace);
    return st;
}

typedef struct tn__keys_job { const tn_image *dem; int invert; uint32_t *k; } tn__keys_job;

static void tn__keys_rows(void *ctx, size_t y0, size_t y1)
{
    const tn__keys_job *j = (const tn__keys_job *)ctx;
    const size_t w = (size_t)j->dem->width, W = w + 2, C = (size_t)j->dem->channels;
    size_t x, y;
    for (y = y0; y < y1; y++) {
        const float *src = j->dem->data + y * w * C;
        uint32_t *row = j->k + (y + 1) * W;
        row[0] = row[w + 1] = TN__FRAME;
        for (x = 0; x < w; x++) row[x + 1] = tn__fkey(j->invert ? -src[x * C] : src[x * C]) >> 1;
    }
}

/* Heights of channel 0 as 31-bit keys (the float key without its last bit, so the top bit is
   free for the closed flag) in a grid framed by TN__FRAME; invert flips the sign (ridges).
   Fails on NaN/Inf. */
static tn_status tn__dem_keys(const tn_image *dem, int invert, const char *what, uint32_t **out)
{
    const int w = dem->width, h = dem->height;
    const size_t W = (size_t)w + 2;
    size_t bytes, x;
    tn__keys_job j;
    tn_status st = tn__size4(W, (size_t)h + 2, 1, sizeof(uint32_t), &bytes);
    if (st) return st;
    if (W * ((size_t)h + 2) > 0xfffffffeu) return tn__fail(TN_ERR_TOO_LARGE, "%s: %d x %d cells exceed the 2^32 cell limit", what, w, h);
    if ((st = tn__dem_finite(dem, what))) return st;
    j.k = (uint32_t *)tn__alloc(bytes);
    if (!j.k) return TN_ERR_OUT_OF_MEMORY;
    j.dem = dem;
    j.invert = invert;
    for (x = 0; x < W; x++) j.k[x] = j.k[(size_t)(h + 1) * W + x] = TN__FRAME;
    tn_parallel_for((size_t)h, tn__row_grain(w), tn__keys_rows, &j);
    *out = j.k;
    return TN_OK;
}

typedef struct tn__heights_job { const uint32_t *keys; const tn_image *dem; int invert; float *out; } tn__heights_job;

/* Filled heights from framed keys: untouched cells keep their exact height; raised cells get the
   float of their key, which is above every float of the key below (so each raise stays strict). */
static void tn__keys_to_heights(void *ctx, size_t y0, size_t y1)
{
    const tn__heights_job *j = (const tn__heights_job *)ctx;
    const size_t w = (size_t)j->dem->width, C = (size_t)j->dem->channels;
    size_t x, y;
    for (y = y0; y < y1; y++) {
        const uint32_t *kr = j->keys + (y + 1) * (w + 2) + 1;
        const float *src = j->dem->data + y * w * C;
        float *o = j->out + y * w;
        for (x = 0; x < w; x++) {
            float v = j->invert ? -src[x * C] : src[x * C];
            uint32_t key = kr[x] & ~TN__CLOSED;
            o[x] = key == (tn__fkey(v) >> 1) ? v : tn__fkey_inv(key << 1);
        }
    }
}

/* Depression-filled channel 0 of dem (negated first when invert) into a new one-channel image.
   With par, also a new framed (w + 2) x (h + 2) grid of the flood's flow directions for the
   raised cells (TN_FLOW_OUTLET elsewhere). */
static tn_status tn__fill_image(const tn_image *dem, int invert, const char *what, tn_image *out, uint8_t **par)
{
    uint32_t *keys = NULL;
    uint8_t *p = NULL;
    tn__heights_job j;
    tn_status st;
    if (!dem || !dem->data || dem->width <= 0 || dem->height <= 0 || dem->channels <= 0)
        return tn__fail(TN_ERR_EMPTY, "%s: the DEM is empty", what);
    if ((st = tn__dem_keys(dem, invert, what, &keys))) return st;
    if (par) {
        const size_t framed = ((size_t)dem->width + 2) * ((size_t)dem->height + 2);
        if (!(p = (uint8_t *)tn__alloc(framed))) {
            TN_FREE(keys);
            return TN_ERR_OUT_OF_MEMORY;
        }
        memset(p, TN_FLOW_OUTLET, framed);
    }
    if ((st = tn__fill_keys(keys, p, dem->width, dem->height)) || (st = tn__image_alloc(out, dem->width, dem->height, 1))) {
        TN_FREE(keys);
        TN_FREE(p);
        return st;
    }
    if (par) *par = p;
    j.keys = keys;
    j.dem = dem;
    j.invert = invert;
    j.out = out->data;
    tn_parallel_for((size_t)dem->height, tn__row_grain(dem->width), tn__keys_to_heights, &j);
    TN_FREE(keys);
    return TN_OK;
}

TN_API tn_status tn_fill_depressions(tn_image *dst, const tn_image *dem)
{
    tn_image out = {0, 0, 0, NULL};
    tn_status st;
    TN_ASSERT(dst);
    if ((st = tn__fill_image(dem, 0, "fill depressions", &out, NULL))) return st;
    *dst = out;
    return TN_OK;
}

typedef struct tn__d8_job { const float *h; const uint8_t *par; uint8_t *dir; int w, hgt; } tn__d8_job;

static void tn__d8_rows(void *ctx, size_t y0, size_t y1)
{
    const tn__d8_job *j = (const tn__d8_job *)ctx;
    const int w = j->w, H = j->hgt;
    int x, y, d;
    for (y = (int)y0; y < (int)y1; y++) {
        uint8_t *dr = j->dir + (size_t)y * w;
        const float *up, *row, *dn, *nb[8];
        if (y == 0 || y == H - 1 || w < 3) { /* the border drains off the map */
            memset(dr, TN_FLOW_OUTLET, (size_t)w);
            continue;
        }
        dr[0] = dr[w - 1] = TN_FLOW_OUTLET;
        /* interior: fixed neighbour offsets and no bounds checks, so the loop vectorises; the
           strict > keeps the first of equal drops in E, SE, S, ... order */
        up = j->h + (size_t)(y - 1) * w;
        row = up + w;
        dn = row + w;
        nb[0] = row + 1; nb[1] = dn + 1; nb[2] = dn; nb[3] = dn - 1;
        nb[4] = row - 1; nb[5] = up - 1; nb[6] = up; nb[7] = up + 1;
        for (x = 1; x < w - 1; x++) {
            double hc = row[x], best = 0.0;
            int bd = TN_FLOW_OUTLET;
            for (d = 0; d < 8; d++) {
                double drop = hc - (double)nb[d][x];
                if (d & 1) drop *= 0.70710678118654752;
                if (drop > best) { best = drop; bd = d; }
            }
            dr[x] = (uint8_t)bd;
        }
        if (j->par) { /* raised cells drain to the cell the flood came from */
            const uint8_t *pr = j->par + (size_t)(y + 1) * (size_t)(w + 2) + 1;
            for (x = 1; x < w - 1; x++)
                if (pr[x] != TN_FLOW_OUTLET) dr[x] = pr[x];
        }
    }
}

/* D8 of a filled DEM; par (framed, or NULL) overrides the directions of raised cells. */
static tn_status tn__flow_dirs(tn_flow *flow, const tn_image *filled, const uint8_t *par)
{
    tn__d8_job j;
    tn_image tmp = {0, 0, 0, NULL};
    tn_status st;
    size_t n;
    TN_ASSERT(flow);
    if ((st = tn__dem_check(filled, 1, "flow directions"))) return st;
    n = (size_t)filled->width * filled->height;
    if (filled->channels != 1) { /* D8 reads a plain height grid */
        if ((st = tn__channel0_image(filled, &tmp))) return st;
        filled = &tmp;
    }
    memset(flow, 0, sizeof *flow);
    flow->dir = (uint8_t *)tn__alloc(n);
    if (!flow->dir) {
        tn_image_free(&tmp);
        return TN_ERR_OUT_OF_MEMORY;
    }
    flow->width = filled->width;
    flow->height = filled->height;
    j.h = filled->data;
    j.par = par;
    j.dir = flow->dir;
    j.w = filled->width;
    j.hgt = filled->height;
    tn_parallel_for((size_t)filled->height, tn__row_grain(filled->width), tn__d8_rows, &j);
    tn_image_free(&tmp);
    return TN_OK;
}

TN_API tn_status tn_flow_directions(tn_flow *flow, const tn_image *filled)
{
    return tn__flow_dirs(flow, filled, NULL);
}

/* Receiver of cell i, or -1 for an outlet. */
static ptrdiff_t tn__receiver(const tn_flow *f, size_t i)
{
    int d = f->dir[i];
    if (d >= 8) return -1;
    return (ptrdiff_t)i + tn__d8y[d] * (ptrdiff_t)f->width + tn__d8x[d];
}

typedef struct tn__indeg_job { const tn_flow *f; const uint8_t *mask; uint8_t *indeg; } tn__indeg_job;

/* In-degree of each cell: neighbours draining into it (only mask cells when mask is given).
   Each cell counts its own upstream neighbours, so rows are independent. */
static void tn__indeg_rows(void *ctx, size_t y0, size_t y1)
{
    const tn__indeg_job *j = (const tn__indeg_job *)ctx;
    const int w = j->f->width, h = j->f->height;
    const uint8_t *dir = j->f->dir, *mask = j->mask;
    int x, y, d;
    for (y = (int)y0; y < (int)y1; y++) {
        uint8_t *out = j->indeg + (size_t)y * w;
        int inner = y > 0 && y < h - 1 && w >= 3;
        for (x = 0; x < w; x++) {
            int c = 0;
            if (inner && x > 0 && x < w - 1) { /* interior: the vectorisable loop below */
                x = w - 2;
                continue;
            }
            for (d = 0; d < 8; d++) {
                int nx = x + tn__d8x[d], ny = y + tn__d8y[d];
                size_t ni;
                if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
                ni = (size_t)ny * w + nx;
                /* neighbour in direction d drains here if its direction is the opposite one */
                if (dir[ni] == (uint8_t)((d + 4) & 7) && (!mask || mask[ni])) c++;
            }
            out[x] = (uint8_t)c;
        }
        if (inner) { /* one term per neighbour: neighbour d drains here if it points back (d + 4) */
            const uint8_t *u = dir + (size_t)(y - 1) * w, *m = u + w, *l = m + w;
            if (!mask) {
                for (x = 1; x < w - 1; x++)
                    out[x] = (uint8_t)((m[x + 1] == 4) + (l[x + 1] == 5) + (l[x] == 6) + (l[x - 1] == 7) +
                                       (m[x - 1] == 0) + (u[x - 1] == 1) + (u[x] == 2) + (u[x + 1] == 3));
            } else {
                const uint8_t *mu = mask + (size_t)(y - 1) * w, *mm = mu + w, *ml = mm + w;
                /* a masked-off neighbour reads as direction 8, which points nowhere (written this
                   way, not as (dir == k) & (mask != 0): gcc 12 -O2 vectorised that into -1 terms) */
                for (x = 1; x < w - 1; x++)
                    out[x] = (uint8_t)(((mm[x + 1] ? m[x + 1] : 8) == 4) + ((ml[x + 1] ? l[x + 1] : 8) == 5) +
                                       ((ml[x] ? l[x] : 8) == 6) + ((ml[x - 1] ? l[x - 1] : 8) == 7) +
                                       ((mm[x - 1] ? m[x - 1] : 8) == 0) + ((mu[x - 1] ? u[x - 1] : 8) == 1) +
                                       ((mu[x] ? u[x] : 8) == 2) + ((mu[x + 1] ? u[x + 1] : 8) == 3));
            }
        }
    }
}

static tn_status tn__indegree(const tn_flow *f, const uint8_t *mask, uint8_t **out)
{
    tn__indeg_job j;
    uint8_t *indeg = (uint8_t *)tn__alloc((size_t)f->width * f->height);
    if (!indeg) return TN_ERR_OUT_OF_MEMORY;
    j.f = f;
    j.mask = mask;
    j.indeg = indeg;
    tn_parallel_for((size_t)f->height, tn__row_grain(f->width), tn__indeg_rows, &j);
    *out = indeg;
    return TN_OK;
}

static tn_status tn__flow_check(const tn_flow *f, const char *what)
{
    if (!f || !f->dir || f->width <= 0 || f->height <= 0)
        return tn__fail(TN_ERR_INVALID_ARG, "%s: no flow directions", what);
    return TN_OK;
}

typedef struct tn__pack_job { const tn_flow *f; const uint8_t *indeg; uint8_t *pk; } tn__pack_job;

/* In-degree and direction in one byte (indeg << 4 | dir, 15 = outlet): the walk below then
   touches two arrays per step instead of three. */
static void tn__pack_rows(void *ctx, size_t y0, size_t y1)
{
    const tn__pack_job *j = (const tn__pack_job *)ctx;
    size_t i, w = (size_t)j->f->width;
    for (i = y0 * w; i < y1 * w; i++) {
        int d = j->f->dir[i];
        j->pk[i] = (uint8_t)(j->indeg[i] << 4 | (d < 8 ? d : 15));
    }
}

/* One strip of rows for the threaded accumulation walk. */
typedef struct tn__acc_job {
    uint8_t *pk;
    uint32_t *acc;
    ptrdiff_t off[16];
    size_t w, rows, nstrips;
    size_t *seen;             /* per strip */
    uint32_t *out_cell, *out_add; /* per strip: 2w slots of flow leaving the strip */
    size_t *nout;
} tn__acc_job;

/* Walks down from cell c carrying a (acc of c, already stored) while each next cell has heard
   from all its upstream cells; cells in [lo, hi) only, flow leaving that range goes to the
   outbox (ocell == NULL: flow off the map, which the caller reports as undrained). Returns the cells finished. */
static size_t tn__acc_walk(const tn__acc_job *j, size_t c, uint32_t a, size_t lo, size_t hi, uint32_t *ocell,
                           uint32_t *oadd, size_t *nout)
{
    size_t seen = 0;
    for (;;) {
        size_t r;
        unsigned v;
        seen++;
        if ((j->pk[c] & 15) == 15) break;
        r = (size_t)((ptrdiff_t)c + j->off[j->pk[c] & 15]);
        if (r < lo || r >= hi) { /* another strip's cell: hand the flow over */
            if (ocell) {
                ocell[*nout] = (uint32_t)r;
                oadd[(*nout)++] = a;
            }
            break;
        }
        a = (j->acc[r] += a);
        v = j->pk[r];
        if ((v >> 4) > 1) {
            j->pk[r] = (uint8_t)(v - 16);
            break;
        }
        j->pk[r] = (uint8_t)(0xf0 | (v & 15));
        c = r;
    }
    return seen;
}

/* Strip ith of nth: every walk that stays inside it. A cell with upstream cells in another strip
   waits (its in-degree never reaches zero here) for the sequential pass over the outboxes. */
static void tn__acc_strip(void *ctx, int ith, int nth)
{
    const tn__acc_job *j = (const tn__acc_job *)ctx;
    size_t s, i;
    for (s = (size_t)ith; s < j->nstrips; s += (size_t)nth) {
        size_t lo = j->rows * s / j->nstrips * j->w, hi = j->rows * (s + 1) / j->nstrips * j->w, seen = 0;
        for (i = lo; i < hi; i++) j->acc[i] = 1;
        j->nout[s] = 0;
        for (i = lo; i < hi; i++)
            if (!(j->pk[i] >> 4)) /* no upstream cells, and not reached by a walk (15) */
                seen += tn__acc_walk(j, i, 1, lo, hi, j->out_cell + 2 * j->w * s, j->out_add + 2 * j->w * s, &j->nout[s]);
        j->seen[s] = seen;
    }
}

static tn_status tn__flow_accumulate(tn_flow *flow);

/* Directions handed in by a caller: every code must be 0-7 or TN_FLOW_OUTLET and lead to a cell
   of the map. The walks would take other codes for outlets, and a step off the left or right
   edge for the neighbouring row. Flows made here (tn_flow_compute) skip this. */
static tn_status tn__flow_codes_check(const tn_flow *f, const char *what)
{
    int x, y;
    tn_status st;
    if ((st = tn__flow_check(f, what))) return st;
    for (y = 0; y < f->height; y++)
        for (x = 0; x < f->width; x++) {
            int d = f->dir[(size_t)y * f->width + x], tx, ty;
            if (d == TN_FLOW_OUTLET) continue;
            if (d >= 8) return tn__fail(TN_ERR_CORRUPT, "%s: direction code %d at (%d, %d)", what, d, x, y);
            tx = x + tn__d8x[d];
            ty = y + tn__d8y[d];
            if (tx < 0 || ty < 0 || tx >= f->width || ty >= f->height)
                return tn__fail(TN_ERR_CORRUPT, "%s: the direction at (%d, %d) points off the map", what, x, y);
        }
    return TN_OK;
}

TN_API tn_status tn_flow_accumulation(tn_flow *flow)
{
    tn_status st = tn__flow_codes_check(flow, "flow accumulation");
    return st ? st : tn__flow_accumulate(flow);
}

static tn_status tn__flow_accumulate(tn_flow *flow)
{
    size_t i, s, n, seen = 0, S;
    uint8_t *pk = NULL;
    tn__acc_job a;
    tn__pack_job j;
    tn_status st;
    int d;
    if ((st = tn__flow_check(flow, "flow accumulation"))) return st;
    n = (size_t)flow->width * flow->height;
    if ((st = tn__indegree(flow, NULL, &pk))) return st;
    j.f = flow;
    j.indeg = pk;
    j.pk = pk; /* row by row in place: each byte is read before it is written */
    tn_parallel_for((size_t)flow->height, tn__row_grain(flow->width), tn__pack_rows, &j);
    memset(&a, 0, sizeof a);
    /* one strip per thread; the sums do not depend on the split, so neither does the result */
    S = (size_t)tn_get_threads();
    if (S > (size_t)flow->height) S = (size_t)flow->height;
    a.pk = pk;
    a.w = (size_t)flow->width;
    a.rows = (size_t)flow->height;
    a.nstrips = S;
    for (d = 0; d < 16; d++) a.off[d] = d < 8 ? tn__d8y[d] * (ptrdiff_t)flow->width + tn__d8x[d] : 0;
    a.acc = (uint32_t *)tn__alloc(n * sizeof(uint32_t));
    a.seen = (size_t *)tn__alloc(2 * S * sizeof(size_t));
    a.out_cell = (uint32_t *)tn__alloc(4 * a.w * S * sizeof(uint32_t));
    if (!a.acc || !a.seen || !a.out_cell) {
        st = TN_ERR_OUT_OF_MEMORY;
        goto done;
    }
    a.nout = a.seen + S;
    a.out_add = a.out_cell + 2 * a.w * S;
    tn_parallel_run(tn__acc_strip, &a);
    for (s = 0; s < S; s++) seen += a.seen[s];
    /* flow that crossed strips, in strip order: add it, and walk on (anywhere) from each cell
       that has now heard from all its upstream cells */
    for (s = 0; s < S; s++)
        for (i = 0; i < a.nout[s]; i++) {
            size_t r = a.out_cell[2 * a.w * s + i];
            unsigned v;
            uint32_t acc_r;
            if (r >= n) continue; /* points off the map: left undrained */
            v = pk[r];
            acc_r = (a.acc[r] += a.out_add[2 * a.w * s + i]);
            if ((v >> 4) > 1) {
                pk[r] = (uint8_t)(v - 16);
                continue;
            }
            pk[r] = (uint8_t)(0xf0 | (v & 15));
            seen += tn__acc_walk(&a, r, acc_r, 0, n, NULL, NULL, NULL);
        }
    if (seen != n) st = tn__fail(TN_ERR_CORRUPT, "flow accumulation: the directions hold a cycle (%zu cells never drained)", n - seen);
done:
    TN_FREE(pk);
    TN_FREE(a.seen);
    TN_FREE(a.out_cell);
    if (st) {
        TN_FREE(a.acc);
        return st;
    }
    TN_FREE(flow->acc);
    flow->acc = a.acc;
    return TN_OK;
}

TN_API void tn_flow_free(tn_flow *flow)
{
    if (!flow) return;
    TN_FREE(flow->dir);
    TN_FREE(flow->acc);
    memset(flow, 0, sizeof *flow);
}

TN_API tn_status tn_flow_compute(tn_flow *flow, const tn_image *dem, int invert)
{
    tn_image filled = {0, 0, 0, NULL};
    uint8_t *par = NULL;
    tn_status st;
    TN_ASSERT(flow);
    memset(flow, 0, sizeof *flow);
    if ((st = tn__fill_image(dem, invert, "flow", &filled, &par))) return st;
    st = tn__flow_dirs(flow, &filled, par);
    tn_image_free(&filled);
    TN_FREE(par);
    if (!st) st = tn__flow_accumulate(flow); /* own directions: valid codes */
    if (st) tn_flow_free(flow);
    return st;
}

static tn_status tn__strahler(const tn_flow *flow, const uint8_t *mask, uint8_t *order, int *max_order);

TN_API tn_status tn_strahler_order(const tn_flow *flow, const uint8_t *mask, uint8_t *order, int *max_order)
{
    tn_status st = tn__flow_codes_check(flow, "strahler order");
    return st ? st : tn__strahler(flow, mask, order, max_order);
}

static tn_status tn__strahler(const tn_flow *flow, const uint8_t *mask, uint8_t *order, int *max_order)
{
    size_t i, n, masked = 0, seen = 0;
    uint8_t *indeg = NULL, *cnt;
    int top = 0;
    tn_status st;
    if ((st = tn__flow_check(flow, "strahler order"))) return st;
    TN_ASSERT(mask && order);
    n = (size_t)flow->width * flow->height;
    if ((st = tn__indegree(flow, mask, &indeg))) return st;
    cnt = (uint8_t *)tn__calloc(n); /* how many upstream cells reached order[] so far */
    if (!cnt) {
        TN_FREE(indeg);
        return TN_ERR_OUT_OF_MEMORY;
    }
    memset(order, 0, n);
    for (i = 0; i < n; i++) {
        size_t c = i;
        masked += mask[i] != 0;
        if (!mask[i] || indeg[i]) continue;
        for (;;) {
            ptrdiff_t r;
            int o = order[c] == 0 ? 1 : (cnt[c] >= 2 ? order[c] + 1 : order[c]);
            seen++;
            if (o > 255) o = 255;
            order[c] = (uint8_t)o;
            if (o > top) top = o;
            r = tn__receiver(flow, c);
            if (r < 0 || !mask[r]) break;
            if (o > order[r]) { order[r] = (uint8_t)o; cnt[r] = 1; }
            else if (o == order[r] && cnt[r] < 255) cnt[r]++;
            if (--indeg[r]) break;
            indeg[r] = 0x80;
            c = (size_t)r;
        }
    }
    TN_FREE(indeg);
    TN_FREE(cnt);
    if (max_order) *max_order = top;
    /* cells on a cycle never run out of upstream cells, so the walk never reaches them */
    if (seen != masked) return tn__fail(TN_ERR_CORRUPT, "strahler order: the directions hold a cycle (%zu network cells never reached)", masked - seen);
    return TN_OK;
}

/* ---- morphology and thinning ---------------------------------------------------------------- */

/* Square dilation (grow != 0) or erosion of radius r, separable; outside the map counts as set
   for erosion and as clear for dilation, so borders neither erode nor grow. */
static tn_status tn__morph(uint8_t *m, int w, int h, int r, int grow)
{
    size_t n = (size_t)w * h;
    uint8_t *t = (uint8_t *)tn__alloc(n);
    int x, y, k;
    if (!t) return TN_ERR_OUT_OF_MEMORY;
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++) {
            int v = grow ? 0 : 1;
            for (k = -r; k <= r; k++) {
                int xx = x + k, s;
                if (xx < 0 || xx >= w) continue;
                s = m[(size_t)y * w + xx] != 0;
                if (grow ? s : !s) { v = grow; break; }
            }
            t[(size_t)y * w + x] = (uint8_t)v;
        }
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++) {
            int v = grow ? 0 : 1;
            for (k = -r; k <= r; k++) {
                int yy = y + k, s;
                if (yy < 0 || yy >= h) continue;
                s = t[(size_t)yy * w + x];
                if (grow ? s : !s) { v = grow; break; }
            }
            m[(size_t)y * w + x] = (uint8_t)v;
        }
    TN_FREE(t);
    return TN_OK;
}




/* ---- contour graph ------------------------------------------------------------------------ */

/* Polylines are built with tn__pts / tn__pts_push and stored with tn__cset_add; skeletons are
   traced by tn__trace_skeleton (>>sketch). */







/* ---- extraction pipeline ------------------------------------------------------------------ */

/* q-quantile of v[0..n) exactly, by a two-pass radix select on order-preserving keys. */
static float tn__quantile(const float *v, size_t n, double q)
{
    size_t *hist, i, k, acc = 0;
    uint32_t hi = 0, lo = 0;
    int pass;
    if (!n) return 0.0f;
    hist = (size_t *)tn__calloc(65536 * sizeof(size_t));
    if (!hist) return 0.0f;
    k = (size_t)(q * (double)(n - 1));
    for (pass = 0; pass < 2; pass++) {
        uint32_t b;
        memset(hist, 0, 65536 * sizeof(size_t));
        for (i = 0; i < n; i++) {
            uint32_t key = tn__fkey(v[i]);
            if (pass == 0) hist[key >> 16]++;
            else if ((key >> 16) == hi) hist[key & 0xffffu]++;
        }
        for (b = 0; b < 65536; b++) {
            if (acc + hist[b] > k) break;
            acc += hist[b];
        }
        if (pass == 0) hi = b;
        else lo = b;
    }
    TN_FREE(hist);
    return tn__fkey_inv((hi << 16) | lo);
}

TN_API int tn_extract_default_threshold(int width, int height)
{
    double t = (double)width * (double)height / 1000.0;
    return t < 8.0 ? 8 : (int)(t + 0.5);
}

TN_API void tn_extraction_free(tn_extraction *ex)
{
    if (!ex) return;
    tn_flow_free(&ex->valley_flow);
    tn_flow_free(&ex->ridge_flow);
    TN_FREE(ex->valley_mask);
    TN_FREE(ex->ridge_mask);
    TN_FREE(ex->valley_order);
    TN_FREE(ex->ridge_order);
    tn_contour_set_free(&ex->contours);
    memset(ex, 0, sizeof *ex);
}

/* Removes dangling lines shorter than min_len pixels (keeping the junction they hang on) until
   none is left; returns through *st. */
static tn_status tn__prune_spurs(uint8_t *skel, int w, int h, int min_len)
{
    int round;
    for (round = 0; round < 8; round++) {
        tn__trace t;
        size_t l, removed = 0;
        tn_status st = tn__trace_skeleton(skel, w, h, &t);
        if (st) return st;
        for (l = 0; l < t.nlines; l++) {
            size_t a = t.starts[l], b = t.starts[l + 1], k;
            size_t c0 = t.cells[a], c1 = t.cells[b - 1];
            int d0 = tn__skel_degree(skel, w, h, (int)(c0 % (size_t)w), (int)(c0 / (size_t)w));
            int d1 = tn__skel_degree(skel, w, h, (int)(c1 % (size_t)w), (int)(c1 / (size_t)w));
            if ((int)(b - a) >= min_len) continue;
            if (c0 == c1 && b - a > 1) continue; /* a closed loop: not dangling */
            if (d0 > 1 && d1 > 1) continue;      /* junction to junction: keeps the network connected */
            for (k = a; k < b; k++) {
                size_t c = t.cells[k];
                if ((k == a && d0 > 2) || (k == b - 1 && d1 > 2)) continue;
                if (skel[c]) { skel[c] = 0; removed++; }
            }
        }
        tn__trace_free(&t);
        if (!removed) break;
    }
    return TN_OK;
}

/* Network of one type: mask, Strahler order, closing, thinning, tracing, filtering, splitting. */
static tn_status tn__extract_type(const tn_image *dem, const tn_image *grad, const tn_extract_opts *o,
                                  int ridge, tn_extraction *ex, size_t *cap)
{
    const int w = dem->width, h = dem->height;
    const size_t n = (size_t)w * h;
    tn_flow *flow = ridge ? &ex->ridge_flow : &ex->valley_flow;
    uint8_t *mask, *order, *skel = NULL, *ord2 = NULL;
    tn__trace t;
    tn__pts pl = {NULL, 0, 0};
    tn_status st;
    size_t i, l;
    int pass, top = 0;
    float grad_floor = 0.0f;
    if ((st = tn_flow_compute(flow, dem, ridge))) return st;
    if ((st = tn__progress(ridge ? "ridges" : "valleys", 0.3))) return st;
    mask = (uint8_t *)tn__alloc(n);
    order = (uint8_t *)tn__alloc(n);
    if (ridge) { ex->ridge_mask = mask; ex->ridge_order = order; }
    else { ex->valley_mask = mask; ex->valley_order = order; }
    if (!mask || !order) return TN_ERR_OUT_OF_MEMORY;
    for (i = 0; i < n; i++) mask[i] = flow->acc[i] >= (uint32_t)ex->threshold;
    if ((st = tn__strahler(flow, mask, order, &top))) return st; /* own flow: valid codes */
    if (ridge) ex->ridge_max_order = top;
    else ex->valley_max_order = top;
    skel = (uint8_t *)tn__alloc(n);
    ord2 = (uint8_t *)tn__alloc(n);
    if (!skel || !ord2) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    memcpy(skel, mask, n);
    memcpy(ord2, order, n);
    if (o->closing > 0) {
        if ((st = tn__morph(skel, w, h, o->closing, 1)) || (st = tn__morph(skel, w, h, o->closing, 0))) goto done;
        /* cells the closing added take the highest order next to them */
        for (pass = 0; pass <= o->closing; pass++)
            for (i = 0; i < n; i++)
                if (skel[i] && !ord2[i]) {
                    int k, x = (int)(i % (size_t)w), y = (int)(i / (size_t)w), best = 0;
                    for (k = 0; k < 8; k++) {
                        int xx = x + tn__d8x[k], yy = y + tn__d8y[k];
                        if (xx >= 0 && yy >= 0 && xx < w && yy < h && ord2[(size_t)yy * w + xx] > best)
                            best = ord2[(size_t)yy * w + xx];
                    }
                    ord2[i] = (uint8_t)best;
                }
    }
    if ((st = tn_skeletonize(skel, w, h))) goto done;
    if ((st = tn__progress(ridge ? "ridges" : "valleys", 0.7))) goto done;
    if ((st = tn__prune_spurs(skel, w, h, o->min_length))) goto done;
    if ((st = tn__trace_skeleton(skel, w, h, &t))) goto done;
    if (o->drop_fraction > 0 && t.nlines) { /* the floor: this quantile of the contours' mean gradients */
        float *means = (float *)tn__alloc(t.nlines * sizeof(float));
        size_t m = 0;
        if (!means) { st = TN_ERR_OUT_OF_MEMORY; tn__trace_free(&t); goto done; }
        for (l = 0; l < t.nlines; l++) {
            size_t a = t.starts[l], b = t.starts[l + 1], k;
            double g = 0.0;
            if ((int)(b - a) < o->min_length) continue;
            for (k = a; k < b; k++) g += grad->data[t.cells[k]];
            means[m++] = (float)(g / (double)(b - a));
        }
        grad_floor = m ? tn__quantile(means, m, o->drop_fraction) : 0.0f;
        TN_FREE(means);
    }
    for (l = 0; l < t.nlines && !st; l++) {
        size_t a = t.starts[l], b = t.starts[l + 1], k;
        int counts[256], npts = (int)(b - a), best = 0, bestc = 0, pieces, j;
        double gsum = 0.0;
        float gmean;
        if (npts < o->min_length) continue; /* what pruning left short: isolated bits */
        memset(counts, 0, sizeof counts);
        for (k = a; k < b; k++) {
            counts[ord2[t.cells[k]]]++;
            gsum += grad->data[t.cells[k]];
        }
        for (j = 1; j < 256; j++) /* the most common order; ties to the higher */
            if (counts[j] && counts[j] >= bestc) { best = j; bestc = counts[j]; }
        gmean = (float)(gsum / (double)npts);
        /* lowest drop_fraction of the contours, and dead flat ones (lakes, plains) */
        if (o->drop_fraction > 0 && (gmean < grad_floor || gmean <= 0.0f)) continue;
        pl.n = 0;
        for (k = a; k < b && !st; k++) {
            size_t c = t.cells[k];
            st = tn__pts_push(&pl, (float)(c % (size_t)w), (float)(c / (size_t)w), dem->data[c * (size_t)dem->channels]);
        }
        if (st) break;
        pieces = (npts - 1 + o->max_length - 2) / (o->max_length - 1);
        if (pieces < 1) pieces = 1;
        for (j = 0; j < pieces && !st; j++) { /* near-equal pieces sharing their end points */
            int s = (int)((long)j * (npts - 1) / pieces), e = (int)((long)(j + 1) * (npts - 1) / pieces);
            st = tn__cset_add(&ex->contours, cap, ridge ? TN_RIDGE : TN_VALLEY, best, gmean, pl.p + (size_t)s * 3, e - s + 1);
        }
    }
    tn__trace_free(&t);
done:
    TN_FREE(pl.p);
    TN_FREE(skel);
    TN_FREE(ord2);
    return st;
}

/* The zero rules of tn_extract_opts for a width x height DEM: the size's default threshold,
   closing radius 1, min_length 10, max_length 48, drop_fraction 0.01. A zero spacing is left
   to tn_image_gradient, whose own rule makes it 1. */
static void tn__extract_opts_defaults(tn_extract_opts *o, int width, int height)
{
    if (o->threshold == 0) o->threshold = tn_extract_default_threshold(width, height);
    if (o->closing == 0) o->closing = 1;
    if (o->min_length == 0) o->min_length = 10;
    if (o->max_length == 0) o->max_length = 48;
    if (o->drop_fraction == 0.0f) o->drop_fraction = 0.01f;
}

TN_API tn_status tn_extract(const tn_image *dem, const tn_extract_opts *opts, tn_extraction *out)
{
    tn_extract_opts o;
    tn_extraction ex;
    tn_image grad = {0, 0, 0, NULL}, gx = {0, 0, 0, NULL}, gy = {0, 0, 0, NULL};
    tn_status st;
    size_t i, n, cap = 0;
    TN_ASSERT(out);
    if ((st = tn__dem_check(dem, 1, "extract"))) return st;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    if (o.threshold < 0 || o.min_length < 0 || o.max_length < 0 || o.which < 0 || o.which > 2 ||
        !(o.drop_fraction < 1.0f) || !(o.dx >= 0.0f) || !(o.dy >= 0.0f))
        return tn__fail(TN_ERR_INVALID_ARG, "extract: negative threshold/lengths, drop_fraction >= 1 or a bad spacing");
    tn__extract_opts_defaults(&o, dem->width, dem->height);
    if (o.closing > 16) return tn__fail(TN_ERR_INVALID_ARG, "extract: closing radius %d is over 16", o.closing);
    if (o.max_length < 2) return tn__fail(TN_ERR_INVALID_ARG, "extract: max_length must be at least 2");
    memset(&ex, 0, sizeof ex);
    ex.width = dem->width;
    ex.height = dem->height;
    ex.threshold = o.threshold;
    ex.contours.width = dem->width;
    ex.contours.height = dem->height;
    n = (size_t)dem->width * dem->height;
    /* gradient magnitude: mean per contour and the floor of the lowest drop_fraction */
    if ((st = tn_image_gradient(dem, o.dx, o.dy, &gx, &gy))) return st;
    for (i = 0; i < n; i++) gx.data[i] = sqrtf(gx.data[i] * gx.data[i] + gy.data[i] * gy.data[i]);
    grad = gx;
    tn_image_free(&gy);
    if (o.which != TN_EXTRACT_RIDGES) st = tn__extract_type(dem, &grad, &o, 0, &ex, &cap);
    if (!st && o.which != TN_EXTRACT_VALLEYS) st = tn__extract_type(dem, &grad, &o, 1, &ex, &cap);
    tn_image_free(&grad);
    if (!st) st = tn__progress("extract", 1.0);
    if (st) {
        tn_extraction_free(&ex);
        return st;
    }
    *out = ex;
    return TN_OK;
}

/* ---- realism report ----------------------------------------------------------------------- */

/* In-place radix-2 complex FFT of n (a power of two) interleaved doubles, stride 1. */
static void tn__fft(double *re, double *im, int n)
{
    int i, j, len;
    for (i = 1, j = 0; i < n; i++) { /* bit reversal */
        int bit = n >> 1;
        for (; j & bit; bit >>= 1) j ^= bit;
        j ^= bit;
        if (i < j) {
            double t = re[i]; re[i] = re[j]; re[j] = t;
            t = im[i]; im[i] = im[j]; im[j] = t;
        }
    }
    for (len = 2; len <= n; len <<= 1) {
        double ang = -6.283185307179586 / len, wr = cos(ang), wi = sin(ang);
        for (i = 0; i < n; i += len) {
            double cr = 1.0, ci = 0.0;
            for (j = 0; j < len / 2; j++) {
                int a = i + j, b = i + j + len / 2;
                double xr = re[b] * cr - im[b] * ci, xi = re[b] * ci + im[b] * cr, t;
                re[b] = re[a] - xr; im[b] = im[a] - xi;
                re[a] += xr; im[a] += xi;
                t = cr * wr - ci * wi;
                ci = cr * wi + ci * wr;
                cr = t;
            }
        }
    }
}

#define TN__SPEC_BINS 24

/* Radially averaged power spectral density of the centred largest power-of-two square crop
   (mean removed, Hann window): bins[k] = mean |F|^2 / sum(w^2) over frequencies in log-spaced
   band k of [1/64 .. 0.5] cycles/px... scaled to the crop: band edges f_lo * (0.5/f_lo)^(k/K)
   with f_lo = 2 / S. Empty bands are 0. */
static tn_status tn__radial_spectrum(const tn_image *img, double f_lo, double *bins, int *size)
{
    int S = 16, x, y, k;
    double *re, *im, *win, mean = 0.0, wsum = 0.0, cnt[TN__SPEC_BINS];
    size_t bytes;
    tn_status st;
    while (S * 2 <= img->width && S * 2 <= img->height && S < 4096) S *= 2;
    if (img->width < 16 || img->height < 16)
        return tn__fail(TN_ERR_INVALID_ARG, "realism: terrain of %d x %d is under 16 x 16", img->width, img->height);
    *size = S;
    if (f_lo <= 0) f_lo = 2.0 / S;
    if ((st = tn__size4((size_t)S, (size_t)S, 2, sizeof(double), &bytes))) return st;
    re = (double *)tn__alloc(bytes);
    win = (double *)tn__alloc((size_t)S * sizeof(double));
    if (!re || !win) {
        TN_FREE(re);
        TN_FREE(win);
        return TN_ERR_OUT_OF_MEMORY;
    }
    im = re + (size_t)S * S;
    {
        int x0 = (img->width - S) / 2, y0 = (img->height - S) / 2;
        for (y = 0; y < S; y++)
            for (x = 0; x < S; x++) {
                double v = TN_PIXEL(img, x0 + x, y0 + y, 0);
                re[(size_t)y * S + x] = v;
                mean += v;
            }
    }
    mean /= (double)S * S;
    for (x = 0; x < S; x++) win[x] = 0.5 - 0.5 * cos(6.283185307179586 * (x + 0.5) / S);
    for (y = 0; y < S; y++)
        for (x = 0; x < S; x++) {
            double w2 = win[x] * win[y];
            re[(size_t)y * S + x] = (re[(size_t)y * S + x] - mean) * w2;
            im[(size_t)y * S + x] = 0.0;
            wsum += w2 * w2;
        }
    for (y = 0; y < S; y++) tn__fft(re + (size_t)y * S, im + (size_t)y * S, S);
    { /* columns through a scratch row */
        double *cr = (double *)tn__alloc((size_t)S * 2 * sizeof(double)), *ci;
        if (!cr) {
            TN_FREE(re);
            TN_FREE(win);
            return TN_ERR_OUT_OF_MEMORY;
        }
        ci = cr + S;
        for (x = 0; x < S; x++) {
            for (y = 0; y < S; y++) { cr[y] = re[(size_t)y * S + x]; ci[y] = im[(size_t)y * S + x]; }
            tn__fft(cr, ci, S);
            for (y = 0; y < S; y++) { re[(size_t)y * S + x] = cr[y]; im[(size_t)y * S + x] = ci[y]; }
        }
        TN_FREE(cr);
    }
    for (k = 0; k < TN__SPEC_BINS; k++) bins[k] = cnt[k] = 0.0;
    for (y = 0; y < S; y++)
        for (x = 0; x < S; x++) {
            int fx = x <= S / 2 ? x : x - S, fy = y <= S / 2 ? y : y - S;
            double f = sqrt((double)fx * fx + (double)fy * fy) / S, p;
            if (f < f_lo || f > 0.5) continue;
            k = (int)(log(f / f_lo) / log(0.5 / f_lo) * TN__SPEC_BINS);
            if (k >= TN__SPEC_BINS) k = TN__SPEC_BINS - 1;
            p = re[(size_t)y * S + x] * re[(size_t)y * S + x] + im[(size_t)y * S + x] * im[(size_t)y * S + x];
            bins[k] += p / wsum;
            cnt[k] += 1.0;
        }
    for (k = 0; k < TN__SPEC_BINS; k++) bins[k] = cnt[k] > 0 ? bins[k] / cnt[k] : 0.0;
    TN_FREE(re);
    TN_FREE(win);
    return TN_OK;
}

/* Least-squares slope of log10(bins) against log10(band centre frequency). */
static double tn__spectrum_slope(const double *bins, double f_lo)
{
    double sx = 0, sy = 0, sxx = 0, sxy = 0, m = 0;
    int k;
    for (k = 0; k < TN__SPEC_BINS; k++) {
        double f = f_lo * pow(0.5 / f_lo, (k + 0.5) / TN__SPEC_BINS), lx, ly;
        if (bins[k] <= 0) continue;
        lx = log10(f);
        ly = log10(bins[k]);
        sx += lx; sy += ly; sxx += lx * lx; sxy += lx * ly; m += 1;
    }
    if (m < 2 || m * sxx - sx * sx <= 0) return 0.0;
    return (m * sxy - sx * sy) / (m * sxx - sx * sx);
}

/* Relative earth mover's distance between the distributions of a[0..na) and b[0..nb) on 256
   bins over [lo, hi], divided by `scale` (the reference's mean magnitude). */
static double tn__hist_emd(const float *a, size_t na, const float *b, size_t nb, float lo, float hi, double scale)
{
    double ha[256], hb[256], ca = 0, cb = 0, emd = 0, bw = (double)(hi - lo) / 256.0;
    size_t i;
    int k;
    if (!(hi > lo) || !(scale > 0)) return 0.0;
    memset(ha, 0, sizeof ha);
    memset(hb, 0, sizeof hb);
    for (i = 0; i < na; i++) { k = (int)((a[i] - lo) / (hi - lo) * 256.0f); ha[k < 0 ? 0 : k > 255 ? 255 : k] += 1.0 / (double)na; }
    for (i = 0; i < nb; i++) { k = (int)((b[i] - lo) / (hi - lo) * 256.0f); hb[k < 0 ? 0 : k > 255 ? 255 : k] += 1.0 / (double)nb; }
    for (k = 0; k < 256; k++) {
        ca += ha[k];
        cb += hb[k];
        emd += fabs(ca - cb) * bw;
    }
    return emd / scale;
}

/* Slope magnitude (field 0) and 5-point Laplacian (field 1) of channel 0, interior cells only. */
static tn_status tn__slope_curv(const tn_image *dem, float dx, float dy, float **slope, float **curv, size_t *count)
{
    const int w = dem->width, h = dem->height;
    size_t n = (size_t)(w - 2) * (h - 2), i = 0;
    float *s, *c, ix, iy;
    int x, y;
    ix = 1.0f / dx;
    iy = 1.0f / dy;
    s = (float *)tn__alloc(n * sizeof(float));
    c = (float *)tn__alloc(n * sizeof(float));
    if (!s || !c) {
        TN_FREE(s);
        TN_FREE(c);
        return TN_ERR_OUT_OF_MEMORY;
    }
    for (y = 1; y < h - 1; y++)
        for (x = 1; x < w - 1; x++) {
            float z = TN_PIXEL(dem, x, y, 0), zl = TN_PIXEL(dem, x - 1, y, 0), zr = TN_PIXEL(dem, x + 1, y, 0);
            float zu = TN_PIXEL(dem, x, y - 1, 0), zd = TN_PIXEL(dem, x, y + 1, 0);
            float gx = tn__grad_x(dem, x, y) * ix, gy = tn__grad_y(dem, x, y) * iy; /* interior: (zr - zl) / 2 */
            s[i] = sqrtf(gx * gx + gy * gy);
            c[i] = (zr + zl - 2.0f * z) * ix * ix + (zd + zu - 2.0f * z) * iy * iy;
            i++;
        }
    *slope = s;
    *curv = c;
    *count = n;
    return TN_OK;
}

/* Drainage density (valley line length per cell) and mean bifurcation ratio of one DEM. */
static tn_status tn__drainage(const tn_image *dem, int threshold, double *density, double *rb)
{
    tn_extract_opts o;
    tn_extraction ex;
    tn_status st;
    double len = 0, nk[256];
    size_t i, n;
    int k, j, m = 0;
    memset(&o, 0, sizeof o);
    o.threshold = threshold;
    o.which = TN_EXTRACT_VALLEYS;
    if ((st = tn_extract(dem, &o, &ex))) return st;
    for (i = 0; i < (size_t)ex.contours.count; i++) {
        const tn_contour *c = &ex.contours.items[i];
        for (j = 1; j < c->npoints; j++)
            len += hypot(c->points[j * 3] - c->points[j * 3 - 3], c->points[j * 3 + 1] - c->points[j * 3 - 2]);
    }
    *density = len / ((double)dem->width * dem->height);
    /* streams of order k: network cells of order k whose receiver is off the network or of another order */
    memset(nk, 0, sizeof nk);
    n = (size_t)dem->width * dem->height;
    for (i = 0; i < n; i++) {
        ptrdiff_t r;
        if (!ex.valley_order[i]) continue;
        r = tn__receiver(&ex.valley_flow, i);
        if (r < 0 || ex.valley_order[r] != ex.valley_order[i]) nk[ex.valley_order[i]] += 1;
    }
    *rb = 0;
    for (k = 1; k < ex.valley_max_order && k < 255; k++)
        if (nk[k + 1] > 0) { *rb += nk[k] / nk[k + 1]; m++; }
    if (m) *rb /= m;
    tn_extraction_free(&ex);
    return TN_OK;
}

/* The zero rules of tn_realism_opts: the compared terrain's spacing is the reference's (dy_b
   only when dx_b is 0 too), then each dx 0 = 1 and each dy 0 = its dx (square pixels).
   threshold stays 0: tn_extract picks the default for each map's own size. */
static void tn__realism_opts_defaults(tn_realism_opts *o)
{
    if (o->dx_b == 0) {
        o->dx_b = o->dx_a;
        if (o->dy_b == 0) o->dy_b = o->dy_a;
    }
    if (o->dx_a == 0) o->dx_a = 1.0f;
    if (o->dy_a == 0) o->dy_a = o->dx_a;
    if (o->dx_b == 0) o->dx_b = 1.0f;
    if (o->dy_b == 0) o->dy_b = o->dx_b;
}

/* The morphology part of the realism report: slope and curvature histogram distances and the
   radially averaged spectra (distance and log-log slopes). Also the style scores (>>style).
   o has its defaults applied (positive spacings). */
static tn_status tn__realism_shape(const tn_image *ref, const tn_image *img, const tn_realism_opts *o, tn_realism *r)
{
    float *sa = NULL, *ca = NULL, *sb = NULL, *cb = NULL;
    size_t na = 0, nb = 0, i;
    double spa[TN__SPEC_BINS], spb[TN__SPEC_BINS], f_lo, mean_s = 0, mean_c = 0, d2 = 0, dm = 0;
    float hi_s = 0, hi_c = 0;
    int Sa, Sb, k, s0 = 16;
    tn_status st;
    if ((st = tn__slope_curv(ref, o->dx_a, o->dy_a, &sa, &ca, &na)) || (st = tn__slope_curv(img, o->dx_b, o->dy_b, &sb, &cb, &nb)))
        goto done;
    for (i = 0; i < na; i++) {
        mean_s += sa[i];
        mean_c += fabsf(ca[i]);
        if (sa[i] > hi_s) hi_s = sa[i];
        if (fabsf(ca[i]) > hi_c) hi_c = fabsf(ca[i]);
    }
    for (i = 0; i < nb; i++) {
        if (sb[i] > hi_s) hi_s = sb[i];
        if (fabsf(cb[i]) > hi_c) hi_c = fabsf(cb[i]);
    }
    mean_s /= (double)na;
    mean_c /= (double)na;
    r->slope_distance = tn__hist_emd(sa, na, sb, nb, 0.0f, hi_s, mean_s);
    r->curvature_distance = tn__hist_emd(ca, na, cb, nb, -hi_c, hi_c, mean_c);
    /* spectra on common bands: from 2 cycles across the smaller crop to Nyquist */
    while (s0 * 2 <= ref->width && s0 * 2 <= ref->height && s0 * 2 <= img->width && s0 * 2 <= img->height && s0 < 4096) s0 *= 2;
    f_lo = 2.0 / s0;
    if ((st = tn__radial_spectrum(ref, f_lo, spa, &Sa)) || (st = tn__radial_spectrum(img, f_lo, spb, &Sb))) goto done;
    for (k = 0; k < TN__SPEC_BINS; k++)
        if (spa[k] > 0 && spb[k] > 0) {
            double d = log10(spa[k]) - log10(spb[k]);
            d2 += d * d;
            dm += 1;
        }
    r->spectrum_distance = dm > 0 ? sqrt(d2 / dm) : 0.0;
    r->spectrum_slope_a = tn__spectrum_slope(spa, f_lo);
    r->spectrum_slope_b = tn__spectrum_slope(spb, f_lo);
done:
    TN_FREE(sa);
    TN_FREE(ca);
    TN_FREE(sb);
    TN_FREE(cb);
    return st;
}

TN_API tn_status tn_realism_compare(const tn_image *ref, const tn_image *img, const tn_realism_opts *opts, tn_realism *out)
{
    tn_realism_opts o;
    tn_realism r;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__dem_check(ref, 1, "realism (reference)")) || (st = tn__dem_check(img, 1, "realism (terrain)"))) return st;
    if (ref->width < 16 || ref->height < 16 || img->width < 16 || img->height < 16)
        return tn__fail(TN_ERR_INVALID_ARG, "realism: both terrains must be at least 16 x 16");
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    if (!(o.dx_a >= 0 && o.dy_a >= 0 && o.dx_b >= 0 && o.dy_b >= 0) || o.threshold < 0 ||
        !(o.dx_a <= FLT_MAX && o.dy_a <= FLT_MAX && o.dx_b <= FLT_MAX && o.dy_b <= FLT_MAX))
        return tn__fail(TN_ERR_INVALID_ARG, "realism: spacing must be finite and >= 0, threshold >= 0");
    tn__realism_opts_defaults(&o);
    memset(&r, 0, sizeof r);
    if ((st = tn__realism_shape(ref, img, &o, &r))) return st;
    if ((st = tn__progress("realism", 0.6))) return st;
    if ((st = tn__drainage(ref, o.threshold, &r.drainage_density_a, &r.bifurcation_ratio_a)) ||
        (st = tn__drainage(img, o.threshold, &r.drainage_density_b, &r.bifurcation_ratio_b)))
        return st;
    if (ref->width == img->width && ref->height == img->height && ref->width >= 11 && ref->height >= 11) {
        tn_image a1 = *ref, b1 = *img;
        tn_image ta = {0, 0, 0, NULL}, tb = {0, 0, 0, NULL};
        tn_metrics m;
        if (ref->channels != 1 || img->channels != 1) { /* compare channel 0 only */
            if ((st = tn__channel0_image(ref, &ta)) || (st = tn__channel0_image(img, &tb))) {
                tn_image_free(&ta);
                return st;
            }
            a1 = ta;
            b1 = tb;
        }
        st = tn_compare(&a1, &b1, 0.0, &m);
        tn_image_free(&ta);
        tn_image_free(&tb);
        if (st) return st;
        r.ssim = m.ssim;
        r.psnr = m.psnr;
    } else {
        r.ssim = r.psnr = NAN;
    }
    {
        double s = r.slope_distance + r.curvature_distance + r.spectrum_distance;
        double da = r.drainage_density_a, ba = r.bifurcation_ratio_a, pa = r.spectrum_slope_a;
        s += da > 0 ? fabs(r.drainage_density_b - da) / da : 0.0;
        s += ba > 0 ? fabs(r.bifurcation_ratio_b - ba) / ba : 0.0;
        s += pa != 0 ? fabs(r.spectrum_slope_b - pa) / fabs(pa) : 0.0;
        r.distance = s / 6.0;
    }
    st = tn__progress("realism", 1.0);
    if (!st) *out = r;
    return st;
}

/* --------------------------------------------------------------------------------------------
   >>style  (@@style implementation)
   One evaluation = reset the level's arena, run the feature net on the current map with the
   tape on, sum the loss terms, backward; the gradient wrt the map drives L-BFGS / SGD / Adam.
   Targets (source Grams, sorted source projections, sorted heights and slopes, content
   features) are computed once per pyramid level and kept outside the arena.
   -------------------------------------------------------------------------------------------- */

/* Order-preserving map of a float to an unsigned key (negative floats reversed). */
static uint32_t tn__float_key(float f)
{
    uint32_t u;
    memcpy(&u, &f, sizeof u);
    return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

/* idx = the permutation that sorts v ascending: stable LSD radix sort, 3 passes of 11 bits
   (float keys are exact, so ties keep index order and the result is deterministic).
   scratch holds 3 * n uint32. */
static void tn__argsort_f32(const float *v, size_t n, uint32_t *idx, uint32_t *scratch)
{
    uint32_t *key = scratch, *k2 = scratch + n, *i2 = scratch + 2 * n, *ia = idx, *t;
    size_t cnt[2048], i;
    int pass;
    for (i = 0; i < n; i++) {
        key[i] = tn__float_key(v[i]);
        ia[i] = (uint32_t)i;
    }
    for (pass = 0; pass < 3; pass++) {
        int sh = pass * 11;
        size_t sum = 0;
        memset(cnt, 0, sizeof cnt);
        for (i = 0; i < n; i++) cnt[(key[i] >> sh) & 2047]++;
        for (i = 0; i < 2048; i++) {
            size_t c = cnt[i];
            cnt[i] = sum;
            sum += c;
        }
        for (i = 0; i < n; i++) {
            size_t d = cnt[(key[i] >> sh) & 2047]++;
            k2[d] = key[i];
            i2[d] = ia[i];
        }
        t = key; key = k2; k2 = t;
        t = ia; ia = i2; i2 = t;
    }
    if (ia != idx) memcpy(idx, ia, n * sizeof *idx);
}

/* Element i of a sorted row of length nt read as a row of length n (quantile resampling). */
static float tn__quantile_at(const float *sorted, size_t nt, size_t i, size_t n)
{
    size_t j = (size_t)(((double)i + 0.5) * (double)nt / (double)n);
    return sorted[j < nt ? j : nt - 1];
}

/* Per-row sorting work, rows split round-robin over threads (each row's result is independent of
   the split). mode 0: sorted copy of each row into out; mode 1: residual of the sorted row
   against the target (written back at the unsorted positions) and the row's squared sum. */
typedef struct tn__rowsort_job {
    const float *x, *target;
    float *out;
    double *rowsum;
    size_t rows, n, nt;
    int mode, failed;
} tn__rowsort_job;

static void tn__rowsort_task(void *ctx, int ith, int nth)
{
    tn__rowsort_job *j = (tn__rowsort_job *)ctx;
    uint32_t *idx = (uint32_t *)TN_MALLOC(4 * j->n * sizeof(uint32_t));
    size_t r, i;
    if (!idx) {
        j->failed = 1;
        return;
    }
    for (r = (size_t)ith; r < j->rows; r += (size_t)nth) {
        const float *x = j->x + r * j->n;
        float *o = j->out + r * j->n;
        tn__argsort_f32(x, j->n, idx, idx + j->n);
        if (j->mode == 0) {
            for (i = 0; i < j->n; i++) o[i] = x[idx[i]];
        } else {
            const float *t = j->target + r * j->nt;
            double s = 0;
            for (i = 0; i < j->n; i++) {
                float d = x[idx[i]] - tn__quantile_at(t, j->nt, i, j->n);
                o[idx[i]] = d;
                s += (double)d * d;
            }
            j->rowsum[r] = s;
        }
    }
    TN_FREE(idx);
}

static tn_status tn__rowsort_run(tn__rowsort_job *j)
{
    j->failed = 0;
    tn_parallel_run(tn__rowsort_task, j);
    return j->failed ? tn__fail(TN_ERR_OUT_OF_MEMORY, "style: out of memory sorting %zu values", j->n) : TN_OK;
}

static void tn__sorted_match_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    const float *r = (const float *)out->aux;
    float *g = tn__grad(ctx, x), k;
    size_t i;
    if (!g) return;
    k = 2.0f * out->grad[0] * out->fp[0];
    for (i = 0; i < x->numel; i++) g[i] += k * r[i];
}

/* scale * mean((sort(row of x) - target row)^2) over the rows of x (rows x n): the squared 1-D
   Wasserstein-2 distance between each row's values and the sorted target row (length nt). */
static tn_tensor *tn__sorted_match(tn_ctx *ctx, tn_tensor *x, const float *target, size_t nt, float scale)
{
    int one = 1;
    tn__rowsort_job j;
    tn_tensor *o;
    double s = 0;
    size_t r;
    if (!x) return NULL;
    o = tn__op(ctx, 1, &one, tn__sorted_match_backward, x, NULL, NULL);
    if (!o) return NULL;
    memset(&j, 0, sizeof j);
    j.x = x->data;
    j.target = target;
    j.rows = (size_t)x->shape[0];
    j.n = x->numel / j.rows;
    j.nt = nt;
    j.mode = 1;
    j.out = tn__ctx_floats(ctx, x->numel, 0);
    j.rowsum = (double *)tn_ctx_alloc(ctx, j.rows * sizeof(double));
    if (!j.out || !j.rowsum) return NULL;
    if (tn__rowsort_run(&j)) {
        if (!ctx->status) ctx->status = TN_ERR_OUT_OF_MEMORY;
        return NULL;
    }
    for (r = 0; r < j.rows; r++) s += j.rowsum[r];
    o->aux = j.out;
    o->fp[0] = scale / (float)x->numel;
    o->data[0] = (float)(s * scale / (double)x->numel);
    return o;
}

/* ---- feature networks ---- */

#define TN__STYLE_MAXL 5
static const int tn__sn_ch[4] = {24, 32, 48, 64}, tn__sn_k[4] = {5, 3, 3, 3};
static const int tn__vgg_groups[5] = {2, 2, 4, 4, 4}, tn__vgg_ch[5] = {64, 128, 256, 512, 512};

typedef struct tn__style_net {
    int vgg;
    int nconv;
    tn_tensor *w[16], *b[16];
    tn_params *own; /* the built-in net's weights; VGG weights are borrowed */
} tn__style_net;

static tn_status tn__style_net_builtin(tn__style_net *net, uint64_t seed)
{
    tn_rng rng;
    int l, cin = 1;
    memset(net, 0, sizeof *net);
    if (!(net->own = tn_params_create())) return tn__fail(TN_ERR_OUT_OF_MEMORY, "style: out of memory");
    tn_rng_seed(&rng, seed, 0x57f1e);
    for (l = 0; l < 4; l++) {
        int shape[4], o;
        char name[64];
        size_t k, fan;
        tn_tensor *w;
        shape[0] = tn__sn_ch[l];
        shape[1] = cin;
        shape[2] = shape[3] = tn__sn_k[l];
        sprintf(name, "f%d.weight", l + 1);
        if (!(w = tn_params_add_buffer(net->own, name, 4, shape))) return tn__fail(TN_ERR_OUT_OF_MEMORY, "style: out of memory");
        tn_init_kaiming(w, &rng, 1.41421356f);
        fan = w->numel / (size_t)shape[0];
        for (o = 0; o < shape[0]; o++) { /* zero-mean filters respond to shape, not to height level */
            float *f = w->data + (size_t)o * fan;
            double m = 0;
            for (k = 0; k < fan; k++) m += f[k];
            for (k = 0; k < fan; k++) f[k] -= (float)(m / (double)fan);
        }
        net->w[l] = w;
        cin = shape[0];
    }
    net->nconv = 4;
    return TN_OK;
}

TN_API tn_status tn_vgg19_create(tn_params **out)
{
    tn_params *p = tn_params_create();
    int g, i, cin = 3;
    if (!out) return tn__fail(TN_ERR_INVALID_ARG, "vgg19: out is NULL");
    if (!p) return tn__fail(TN_ERR_OUT_OF_MEMORY, "vgg19: out of memory");
    for (g = 0; g < 5; g++)
        for (i = 0; i < tn__vgg_groups[g]; i++) {
            int ws[4], bs = tn__vgg_ch[g];
            char name[64];
            ws[0] = tn__vgg_ch[g];
            ws[1] = cin;
            ws[2] = ws[3] = 3;
            sprintf(name, "conv%d_%d.weight", g + 1, i + 1);
            if (!tn_params_add_buffer(p, name, 4, ws)) break;
            sprintf(name, "conv%d_%d.bias", g + 1, i + 1);
            if (!tn_params_add_buffer(p, name, 1, &bs)) break;
            cin = ws[0];
        }
    if (tn_params_count(p) != 32) {
        tn_params_free(p);
        return tn__fail(TN_ERR_OUT_OF_MEMORY, "vgg19: out of memory");
    }
    *out = p;
    return TN_OK;
}

TN_API tn_status tn_vgg19_load(tn_params **out, const char *path)
{
    tn_params *p = NULL;
    tn_status st;
    if (!out || !path) return tn__fail(TN_ERR_INVALID_ARG, "vgg19: NULL argument");
    if ((st = tn_vgg19_create(&p))) return st;
    if ((st = tn_params_load(p, path))) {
        tn_params_free(p);
        return st;
    }
    *out = p;
    return TN_OK;
}

static tn_status tn__style_net_vgg(tn__style_net *net, const tn_params *p)
{
    int g, i, k = 0, cin = 3;
    memset(net, 0, sizeof *net);
    net->vgg = 1;
    for (g = 0; g < 5; g++)
        for (i = 0; i < tn__vgg_groups[g]; i++, k++) {
            char name[64];
            tn_tensor *w, *b;
            sprintf(name, "conv%d_%d.weight", g + 1, i + 1);
            w = tn_params_find(p, name);
            sprintf(name, "conv%d_%d.bias", g + 1, i + 1);
            b = tn_params_find(p, name);
            if (!w || !b || w->ndim != 4 || w->shape[0] != tn__vgg_ch[g] || w->shape[1] != cin || w->shape[2] != 3 ||
                w->shape[3] != 3 || (int)b->numel != tn__vgg_ch[g])
                return tn__fail(TN_ERR_SHAPE, "style: the VGG-19 weights lack conv%d_%d or have the wrong shape (use tn_vgg19_load)", g + 1, i + 1);
            net->w[k] = w;
            net->b[k] = b;
            cin = tn__vgg_ch[g];
        }
    net->nconv = k;
    return TN_OK;
}

/* Runs the net on x (1 x 1 x H x W, in the net's input space); fills the style layers and the
   content layer and returns how many style layers there are (0 when out of memory). */
static int tn__style_forward(tn_ctx *ctx, const tn__style_net *net, tn_tensor *x, tn_tensor **style, tn_tensor **content)
{
    tn_conv_opts co;
    tn_tensor *h = x;
    int l;
    memset(&co, 0, sizeof co);
    if (!net->vgg) {
        co.padding = TN_PADDING_REFLECT;
        for (l = 0; l < 4; l++) {
            if (l) h = tn_avg_pool2d(ctx, h, 2, 2);
            co.pad = tn__sn_k[l] / 2;
            h = tn_relu(ctx, tn_conv2d(ctx, h, net->w[l], NULL, &co));
            style[l] = h;
        }
        *content = style[2];
        return h ? 4 : 0;
    } else {
        static const float mean[3] = {0.485f, 0.456f, 0.406f}, sd[3] = {0.229f, 0.224f, 0.225f};
        int g, i, k = 0;
        h = NULL;
        for (i = 0; i < 3; i++) {
            tn_tensor *c = tn_scale_shift(ctx, x, 1.0f / sd[i], -mean[i] / sd[i]);
            h = h ? tn_concat(ctx, h, c, 1) : c;
        }
        co.pad = 1;
        *content = NULL;
        for (g = 0; g < 5 && !*content; g++) {
            if (g) h = tn_max_pool2d(ctx, h, 2, 2);
            for (i = 0; i < tn__vgg_groups[g]; i++, k++) {
                h = tn_relu(ctx, tn_conv2d(ctx, h, net->w[k], net->b[k], &co));
                if (i == 0) style[g] = h;
                if (g == 4 && i == 1) {
                    *content = h;
                    break;
                }
            }
        }
        return *content ? 5 : 0;
    }
}

/* ---- one pyramid level (or one tile of it): targets, loss, gradient ---- */

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

static void tn__style_level_free(tn__style_level *L)
{
    int l;
    for (l = 0; l < TN__STYLE_MAXL; l++) {
        TN_FREE(L->gram[l]);
        TN_FREE(L->dirs[l]);
        TN_FREE(L->sorted[l]);
    }
    TN_FREE(L->content);
    TN_FREE(L->hsorted);
    TN_FREE(L->ssorted);
    TN_FREE(L->dsorted);
    tn_ctx_free(L->ctx);
    memset(L, 0, sizeof *L);
}

/* Slope magnitude (forward differences) of a 1 x 1 x H x W map, as a 1 x (H-1)(W-1) row. */
static tn_tensor *tn__style_slope(tn_ctx *ctx, tn_tensor *x)
{
    tn_tensor *dx, *dy, *s;
    int shape[2];
    tn__diffs(ctx, x, &dx, &dy);
    s = tn_pow_abs(ctx, tn_scale_shift(ctx, tn_add(ctx, tn_square(ctx, dx), tn_square(ctx, dy)), 1.0f, 1e-6f), 0.5f);
    if (!s) return NULL;
    shape[0] = 1;
    shape[1] = (int)s->numel;
    return tn_reshape(ctx, s, 2, shape);
}

static tn_tensor *tn__style_map_tensor(tn_ctx *ctx, const float *v, int w, int h)
{
    tn_tensor *t = tn_tensor_4d(ctx, 1, 1, h, w);
    if (t) memcpy(t->data, v, (size_t)w * h * sizeof(float));
    return t;
}

static float *tn__style_dup(const float *v, size_t n)
{
    float *p = (float *)tn__alloc(n * sizeof(float));
    if (p) memcpy(p, v, n * sizeof(float));
    return p;
}

static tn_status tn__style_sort_rows(const float *x, size_t rows, size_t n, float *out)
{
    tn__rowsort_job j;
    memset(&j, 0, sizeof j);
    j.x = x;
    j.out = out;
    j.rows = rows;
    j.n = n;
    return tn__rowsort_run(&j);
}

/* Source statistics from `ncrop` source tiles (each L->w x L->h; the optimised tiles may differ
   in size): Grams are averaged; each crop's sorted projections are resampled to n / ncrop
   values (at least 1), pooled and sorted. */
static tn_status tn__style_targets(tn__style_level *L, const float *const *crops, int ncrop, uint64_t seed)
{
    tn_ctx *ctx = L->ctx;
    tn_rng rng;
    int c, l;
    tn_status st = TN_OK;
    float *pool[TN__STYLE_MAXL];
    memset(pool, 0, sizeof pool);
    tn_rng_seed(&rng, seed, 0x5d1ec7);
    for (c = 0; c < ncrop && !st; c++) {
        tn_tensor *x, *sf[TN__STYLE_MAXL], *cf;
        tn_ctx_reset(ctx);
        tn_ctx_set_grad(ctx, 0);
        x = tn__style_map_tensor(ctx, crops[c], L->w, L->h);
        L->nstyle = x ? tn__style_forward(ctx, L->net, x, sf, &cf) : 0;
        if (!L->nstyle) {
            st = tn_ctx_status(ctx) ? tn_ctx_status(ctx) : tn__fail(TN_ERR_OUT_OF_MEMORY, "style: out of memory");
            break;
        }
        for (l = 0; l < L->nstyle && !st; l++) {
            int C = sf[l]->shape[1];
            size_t hw = sf[l]->numel / (size_t)C, k, part = hw >= (size_t)ncrop ? hw / (size_t)ncrop : 1, i;
            tn_tensor *g = tn_gram(ctx, sf[l], L->net->vgg ? 1.0f : 1.0f / (float)hw), *D, *F2, *P;
            int shape[2];
            L->ch[l] = C;
            if (!g) { st = TN_ERR_OUT_OF_MEMORY; break; }
            if (!L->gram[l] && !(L->gram[l] = (float *)tn__calloc((size_t)C * C * sizeof(float)))) { st = TN_ERR_OUT_OF_MEMORY; break; }
            for (k = 0; k < (size_t)C * C; k++) L->gram[l][k] += g->data[k] / (float)ncrop;
            if (L->net->vgg || L->wsw <= 0) continue;
            if (!L->dirs[l]) { /* C random unit directions */
                if (!(L->dirs[l] = (float *)tn__alloc((size_t)C * C * sizeof(float)))) { st = TN_ERR_OUT_OF_MEMORY; break; }
                for (i = 0; i < (size_t)C; i++) {
                    double s = 0;
                    for (k = 0; k < (size_t)C; k++) {
                        float v = tn_rng_normal(&rng);
                        L->dirs[l][i * C + k] = v;
                        s += (double)v * v;
                    }
                    for (k = 0; k < (size_t)C; k++) L->dirs[l][i * C + k] /= (float)sqrt(s > 0 ? s : 1);
                }
                L->snt[l] = part * (size_t)ncrop;
                if (!(pool[l] = (float *)tn__alloc((size_t)C * L->snt[l] * sizeof(float)))) { st = TN_ERR_OUT_OF_MEMORY; break; }
            }
            D = tn_tensor_2d(ctx, C, C);
            shape[0] = C;
            shape[1] = (int)hw;
            F2 = tn_reshape(ctx, sf[l], 2, shape);
            if (D) memcpy(D->data, L->dirs[l], (size_t)C * C * sizeof(float));
            P = tn_matmul(ctx, D, F2, 0, 0);
            {
                float *srt = P ? tn__ctx_floats(ctx, P->numel, 0) : NULL;
                if (!srt || (st = tn__style_sort_rows(P->data, (size_t)C, hw, srt))) { st = st ? st : TN_ERR_OUT_OF_MEMORY; break; }
                for (i = 0; i < (size_t)C; i++)
                    for (k = 0; k < part; k++)
                        pool[l][i * L->snt[l] + (size_t)c * part + k] = tn__quantile_at(srt + i * hw, hw, k, part);
            }
        }
    }
    for (l = 0; l < L->nstyle && !st; l++) {
        size_t k, n = (size_t)L->ch[l] * L->ch[l];
        double s = 0;
        for (k = 0; k < n; k++) s += (double)L->gram[l][k] * L->gram[l][k];
        L->gnorm[l] = s > 1e-30 ? s : 1e-30;
        if (!pool[l]) continue;
        if (!(L->sorted[l] = (float *)tn__alloc((size_t)L->ch[l] * L->snt[l] * sizeof(float)))) { st = TN_ERR_OUT_OF_MEMORY; break; }
        if ((st = tn__style_sort_rows(pool[l], (size_t)L->ch[l], L->snt[l], L->sorted[l]))) break;
        s = 0;
        for (k = 0; k < (size_t)L->ch[l] * L->snt[l]; k++) s += (double)L->sorted[l][k] * L->sorted[l][k];
        s /= (double)L->ch[l] * L->snt[l];
        L->svar[l] = s > 1e-30 ? s : 1e-30;
    }
    for (l = 0; l < TN__STYLE_MAXL; l++) TN_FREE(pool[l]);
    tn_ctx_set_grad(ctx, 1);
    return st;
}

/* Depression-filled copy of a w x h map (priority flood, @@extract): water leaves every cell. */
static tn_status tn__style_fill(const float *v, int w, int h, float *filled)
{
    tn_image m, f = {0, 0, 0, NULL};
    tn_status st;
    m.width = w;
    m.height = h;
    m.channels = 1;
    m.data = (float *)v;
    if ((st = tn_fill_depressions(&f, &m))) return st;
    memcpy(filled, f.data, (size_t)w * h * sizeof(float));
    tn_image_free(&f);
    return TN_OK;
}

/* Gaussian kernel of the relief (sigma 2 px, 9 x 9) as a 1 x 1 x 9 x 9 tensor. */
static tn_tensor *tn__style_relief_kernel(tn_ctx *ctx)
{
    tn_tensor *k = tn_tensor_4d(ctx, 1, 1, 9, 9);
    double g[9], s = 0;
    int i, j;
    if (!k) return NULL;
    for (i = 0; i < 9; i++) s += g[i] = exp(-0.125 * (i - 4) * (i - 4));
    for (i = 0; i < 9; i++)
        for (j = 0; j < 9; j++) k->data[i * 9 + j] = (float)(g[i] * g[j] / (s * s));
    return k;
}

/* Relief = height minus its Gaussian-smoothed height (reflect padding): negative in valley bottoms,
   positive on ridges. xs is the map the smoothing reads (x itself, or x with cells held fixed). */
static tn_tensor *tn__style_relief(tn_ctx *ctx, tn_tensor *x, tn_tensor *xs)
{
    tn_conv_opts co;
    memset(&co, 0, sizeof co);
    co.padding = TN_PADDING_REFLECT;
    co.pad = 4;
    return tn_sub(ctx, x, tn_conv2d(ctx, xs, tn__style_relief_kernel(ctx), NULL, &co));
}

#define TN__STYLE_LAKE 255 /* drainage bin of a cell left alone: in a depression */
#define TN__STYLE_BAND 2   /* px: cells this close to the edge drain straight off the map and share
                              one bin (TN__STYLE_ABINS) */

/* Distance of cell (x, y) from the nearest edge of a w x h map. */
static int tn__style_edge_dist(int x, int y, int w, int h)
{
    int a = x < w - 1 - x ? x : w - 1 - x, b = y < h - 1 - y ? y : h - 1 - y;
    return a < b ? a : b;
}

/* Points the cells of a TN__STYLE_BAND-wide border band straight at their nearest edge (the
   border row itself is an outlet). Left to D8, the band collects the flow of everything next
   to it and runs it along the edge, and the relief term then cuts a channel parallel to the
   border. In their own bin, the band's cells are neither carved nor raised into a rim (as
   cells draining only themselves would be), so flow leaves the map at any angle. */
static void tn__style_band_outflow(tn_flow *f)
{
    int w = f->width, h = f->height, x, y;
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++) {
            int l = x, r = w - 1 - x, t = y, b = h - 1 - y, m = l < r ? l : r, v = t < b ? t : b;
            uint8_t *d = &f->dir[(size_t)y * w + x];
            if (m >= TN__STYLE_BAND && v >= TN__STYLE_BAND) {
                x = w - TN__STYLE_BAND - 1; /* skip the interior of the row */
                continue;
            }
            if (!m || !v) *d = TN_FLOW_OUTLET;
            else if (m <= v) *d = l <= r ? 4 : 0; /* W or E (tn__d8x order) */
            else *d = t <= b ? 6 : 2;             /* N or S */
        }
}

/* Drainage bin of every cell of a w x h map v: floor(log2(D8 flow accumulation)) on its filled
   copy, capped at TN__STYLE_ABINS - 1; TN__STYLE_LAKE inside depressions (filled > v), where
   the flow crosses flats in straight lines that should not be carved, and near the edge. */
static tn_status tn__style_drain_bins(const float *filled, const float *v, int w, int h, uint8_t *bin)
{
    tn_image m;
    tn_flow f;
    size_t i, n = (size_t)w * h;
    tn_status st;
    m.width = w;
    m.height = h;
    m.channels = 1;
    m.data = (float *)filled;
    memset(&f, 0, sizeof f);
    if (!(st = tn_flow_directions(&f, &m))) tn__style_band_outflow(&f);
    if (st || (st = tn__flow_accumulate(&f))) { /* codes valid by construction: no check pass */
        tn_flow_free(&f);
        return st;
    }
    for (i = 0; i < n; i++) {
        uint32_t a = f.acc[i];
        int b = 0;
        while (a > 1 && b < TN__STYLE_ABINS - 1) { a >>= 1; b++; }
        int edge = tn__style_edge_dist((int)(i % (size_t)w), (int)(i / (size_t)w), w, h) < TN__STYLE_BAND;
        bin[i] = filled[i] > v[i] ? TN__STYLE_LAKE : edge ? TN__STYLE_ABINS : (uint8_t)b;
    }
    tn_flow_free(&f);
    return TN_OK;
}

/* The source's mean relief per drainage bin (empty bins take the next lower bin's value) and
   its mean squared relief, from the source level x and its filled copy. */
static tn_status tn__style_relief_targets(tn__style_level *L, tn_tensor *x, const float *filled, int w, int h)
{
    size_t i, n = (size_t)w * h;
    tn_tensor *rt = tn__style_relief(L->ctx, x, x);
    float *r = rt ? rt->data : NULL;
    uint8_t *bin = (uint8_t *)tn__alloc(n);
    double sum[TN__STYLE_ABINS + 1], cnt[TN__STYLE_ABINS + 1], s2 = 0;
    int b;
    tn_status st = r && bin ? TN_OK : TN_ERR_OUT_OF_MEMORY;
    if (!st) st = tn__style_drain_bins(filled, x->data, w, h, bin);
    if (!st) {
        memset(sum, 0, sizeof sum);
        memset(cnt, 0, sizeof cnt);
        for (i = 0; i < n; i++) {
            s2 += (double)r[i] * r[i];
            if (bin[i] == TN__STYLE_LAKE) continue;
            sum[bin[i]] += r[i];
            cnt[bin[i]] += 1;
        }
        for (b = 0; b < TN__STYLE_ABINS; b++) L->relief_t[b] = cnt[b] > 0 ? (float)(sum[b] / cnt[b]) : (b ? L->relief_t[b - 1] : 0.0f);
        L->relief_t[TN__STYLE_ABINS] = cnt[TN__STYLE_ABINS] > 0 ? (float)(sum[TN__STYLE_ABINS] / cnt[TN__STYLE_ABINS]) : 0.0f;
        s2 /= (double)n;
        L->relief2 = s2 > 1e-30 ? s2 : 1e-30;
    }
    TN_FREE(bin);
    return st;
}

/* Sorted heights and slopes of the whole source level (w x h). */
static tn_status tn__style_hist_targets(tn__style_level *L, const float *src, int w, int h)
{
    tn_ctx *ctx = L->ctx;
    tn_tensor *x, *s;
    float *f = NULL;
    tn_status st;
    size_t k;
    double m = 0;
    tn_ctx_reset(ctx);
    tn_ctx_set_grad(ctx, 0);
    x = tn__style_map_tensor(ctx, src, w, h);
    s = x ? tn__style_slope(ctx, x) : NULL;
    tn_ctx_set_grad(ctx, 1);
    if (!s) return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : TN_ERR_OUT_OF_MEMORY;
    L->hn = x->numel;
    L->sn = s->numel;
    L->hsorted = (float *)tn__alloc(L->hn * sizeof(float));
    L->ssorted = (float *)tn__alloc(L->sn * sizeof(float));
    if (!L->hsorted || !L->ssorted) return TN_ERR_OUT_OF_MEMORY;
    if ((st = tn__style_sort_rows(x->data, 1, L->hn, L->hsorted)) || (st = tn__style_sort_rows(s->data, 1, L->sn, L->ssorted))) return st;
    for (k = 0; k < L->sn; k++) m += (double)L->ssorted[k] * L->ssorted[k];
    L->s2 = m / (double)L->sn > 1e-30 ? m / (double)L->sn : 1e-30;
    if (L->wdep <= 0 && L->wrel <= 0) return TN_OK;
    L->dn = L->hn;
    if (!(L->dsorted = (float *)tn__alloc(L->dn * sizeof(float))) || !(f = (float *)tn__alloc(L->dn * sizeof(float))))
        return TN_ERR_OUT_OF_MEMORY;
    if (!(st = tn__style_fill(src, w, h, f)) && !(st = tn__style_relief_targets(L, x, f, w, h))) {
        for (k = 0; k < L->dn; k++) f[k] -= src[k]; /* depression depths */
        st = tn__style_sort_rows(f, 1, L->dn, L->dsorted);
    }
    TN_FREE(f);
    return st;
}

/* Content-layer features of the anchor map (w x h). */
static tn_status tn__style_content_target(tn__style_level *L, const float *anchor)
{
    tn_ctx *ctx = L->ctx;
    tn_tensor *x, *sf[TN__STYLE_MAXL], *cf = NULL;
    size_t k;
    double s = 0;
    tn_ctx_reset(ctx);
    tn_ctx_set_grad(ctx, 0);
    x = tn__style_map_tensor(ctx, anchor, L->w, L->h);
    if (!x || !tn__style_forward(ctx, L->net, x, sf, &cf)) {
        tn_ctx_set_grad(ctx, 1);
        return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : TN_ERR_OUT_OF_MEMORY;
    }
    tn_ctx_set_grad(ctx, 1);
    TN_FREE(L->content);
    if (!(L->content = tn__style_dup(cf->data, cf->numel))) return TN_ERR_OUT_OF_MEMORY;
    memcpy(L->cshape, cf->shape, sizeof L->cshape);
    for (k = 0; k < cf->numel; k++) s += (double)cf->data[k] * cf->data[k];
    s /= (double)cf->numel;
    L->cnorm = s > 1e-30 ? s : 1e-30;
    return TN_OK;
}

static tn_tensor *tn__style_acc(tn_ctx *ctx, tn_tensor *acc, tn_tensor *term) { return acc ? tn_add(ctx, acc, term) : term; }

/* The total loss of map x (1 x 1 x h x w, recorded on the tape). */
static tn_tensor *tn__style_loss(tn__style_level *L, tn_tensor *x)
{
    tn_ctx *ctx = L->ctx;
    tn_tensor *sf[TN__STYLE_MAXL], *cf = NULL, *loss = NULL, *t;
    int l, ns = tn__style_forward(ctx, L->net, x, sf, &cf);
    double hw0 = (double)L->w * L->h;
    size_t q;
    if (!ns) return NULL;
    if (L->wc > 0) {
        t = tn_tensor_new(ctx, 4, L->cshape);
        if (!t) return NULL;
        memcpy(t->data, L->content, t->numel * sizeof(float));
        t = tn_sum(ctx, tn_square(ctx, tn_sub(ctx, cf, t)));
        loss = tn_scale_shift(ctx, t, L->net->vgg ? 0.5f * L->wc : (float)(L->wc / (L->cnorm * (double)cf->numel)), 0.0f);
    }
    for (l = 0; l < ns; l++) {
        int C = sf[l]->shape[1];
        size_t hw = sf[l]->numel / (size_t)C;
        if (L->wg > 0) {
            tn_tensor *g = tn_gram(ctx, sf[l], L->net->vgg ? 1.0f : 1.0f / (float)hw), *gt = tn_tensor_2d(ctx, C, C);
            double k = L->net->vgg ? L->wg / (4.0 * 9.0 * hw0 * hw0) : L->wg / (L->gnorm[l] * ns);
            if (!gt) return NULL;
            memcpy(gt->data, L->gram[l], (size_t)C * C * sizeof(float));
            loss = tn__style_acc(ctx, loss, tn_scale_shift(ctx, tn_sum(ctx, tn_square(ctx, tn_sub(ctx, g, gt))), (float)k, 0.0f));
        }
        if (L->wsw > 0 && L->sorted[l]) {
            tn_tensor *D = tn_tensor_2d(ctx, C, C), *P;
            int shape[2];
            if (!D) return NULL;
            memcpy(D->data, L->dirs[l], (size_t)C * C * sizeof(float));
            shape[0] = C;
            shape[1] = (int)hw;
            P = tn_matmul(ctx, D, tn_reshape(ctx, sf[l], 2, shape), 0, 0);
            loss = tn__style_acc(ctx, loss, tn__sorted_match(ctx, P, L->sorted[l], L->snt[l], (float)(L->wsw / (L->svar[l] * ns))));
        }
    }
    if (L->dsorted) { /* drainage terms; the filled map and the drainage bins are held constant */
        tn_tensor *f = tn_tensor_new(ctx, 4, x->shape), *rt = tn_tensor_new(ctx, 4, x->shape), *r;
        tn_tensor *fixed = tn_tensor_new(ctx, 4, x->shape), *free_ = tn_tensor_new(ctx, 4, x->shape);
        uint8_t *bin = (uint8_t *)tn_ctx_alloc(ctx, x->numel);
        int shape[2];
        if (!f || !rt || !fixed || !free_ || !bin) return NULL;
        if ((ctx->status = tn__style_fill(x->data, L->w, L->h, f->data)) ||
            (ctx->status = tn__style_drain_bins(f->data, x->data, L->w, L->h, bin)))
            return NULL;
        shape[0] = 1;
        shape[1] = (int)x->numel;
        /* closed basins as deep as the source's: depths filled - x, sorted-matched */
        if (L->wdep > 0)
            loss = tn__style_acc(ctx, loss, tn__sorted_match(ctx, tn_reshape(ctx, tn_sub(ctx, f, x), 2, shape), L->dsorted, L->dn, L->wdep));
        /* valleys as far below their surroundings as the source's with the same drainage area; cells
           left alone (lakes, the edge) are also held fixed in the smoothing, so nothing pushes them */
        if (L->wrel > 0) {
            for (q = 0; q < x->numel; q++) {
                int keep = bin[q] == TN__STYLE_LAKE;
                free_->data[q] = keep ? 0.0f : 1.0f;
                fixed->data[q] = keep ? x->data[q] : 0.0f;
            }
            r = tn__style_relief(ctx, x, tn_add(ctx, tn_mul(ctx, x, free_), fixed));
            if (!r) return NULL;
            for (q = 0; q < x->numel; q++) rt->data[q] = bin[q] == TN__STYLE_LAKE ? r->data[q] : L->relief_t[bin[q]];
            t = tn_sum(ctx, tn_square(ctx, tn_sub(ctx, r, rt)));
            loss = tn__style_acc(ctx, loss, tn_scale_shift(ctx, t, (float)(L->wrel / (L->relief2 * (double)x->numel)), 0.0f));
        }
    }
    if (L->wh > 0 && L->hsorted) {
        int shape[2];
        shape[0] = 1;
        shape[1] = (int)x->numel;
        loss = tn__style_acc(ctx, loss, tn__sorted_match(ctx, tn_reshape(ctx, x, 2, shape), L->hsorted, L->hn, L->wh));
        loss = tn__style_acc(ctx, loss, tn__sorted_match(ctx, tn__style_slope(ctx, x), L->ssorted, L->sn, (float)(L->wh / L->s2)));
    }
    if (L->wtv > 0) {
        t = tn_tv_loss(ctx, x, L->net->vgg ? 2.5f : 2.0f);
        loss = tn__style_acc(ctx, loss, tn_scale_shift(ctx, t, L->net->vgg ? L->wtv : (float)(L->wtv / hw0), 0.0f));
    }
    return loss;
}

/* Loss and gradient at xd (the tn_lbfgs callback). Failures are kept in L->status; NaN is returned. */
static float tn__style_eval(void *user, const float *xd, float *grad)
{
    tn__style_level *L = (tn__style_level *)user;
    tn_ctx *ctx = L->ctx;
    size_t n = (size_t)L->w * L->h;
    tn_tensor *x, *loss;
    tn_status st;
    if (L->status) return NAN;
    tn_ctx_reset(ctx);
    x = tn_tensor_requires_grad(ctx, tn__style_map_tensor(ctx, xd, L->w, L->h));
    loss = x ? tn__style_loss(L, x) : NULL;
    if (!loss) {
        L->status = tn_ctx_status(ctx) ? tn_ctx_status(ctx) : tn__fail(TN_ERR_INVALID_ARG, "style: no loss term is switched on");
        return NAN;
    }
    if ((st = tn_backward(ctx, loss))) {
        L->status = st;
        return NAN;
    }
    memcpy(grad, x->grad, n * sizeof(float));
    if (!(loss->data[0] == loss->data[0]) || loss->data[0] > FLT_MAX) {
        L->status = tn__fail(TN_ERR_NUMERIC, "style: the loss diverged (NaN/Inf); lower the learning rate");
        return NAN;
    }
    return loss->data[0];
}

/* ---- optimisation ---- */

typedef struct tn__style_cfg {
    tn_style_opts o;
    tn__style_net net;
    double work_done, work_total; /* progress in pixel-iterations */
    tn_progress_fn user_fn;
    void *user_data;
    double span, frac;            /* work of the tile being optimised, and the fraction done */
    int level;                    /* pyramid level being optimised (0 = full size) */
} tn__style_cfg;

/* Reports the fraction f of the tile being optimised as progress of the whole transfer. */
static int tn__style_report(tn__style_cfg *c, double f)
{
    c->frac = f;
    if (!c->user_fn) return 0;
    return c->user_fn(c->user_data, "style", c->work_total > 0 ? (c->work_done + f * c->span) / c->work_total : 0.0);
}

/* Installed for the whole transfer: the optimiser's own progress moves "style" on; the priority
   floods of the drainage terms (and their targets) report "fill", which only gets a chance to
   cancel, so the user sees one stage that never goes back. */
static int tn__style_progress_fwd(void *user, const char *stage, double f)
{
    tn__style_cfg *c = (tn__style_cfg *)user;
    return tn__style_report(c, strcmp(stage, "lbfgs") ? c->frac : f);
}

static tn_status tn__style_optimise(tn__style_level *L, float *x, tn__style_cfg *c)
{
    size_t n = (size_t)L->w * L->h;
    int it, iters = c->o.iters;
    tn_status st = TN_OK;
    c->span = (double)iters * (double)n;
    c->frac = 0;
    if (c->o.optimizer == TN_STYLE_LBFGS) {
        tn_lbfgs_opts lo;
        float f;
        memset(&lo, 0, sizeof lo);
        lo.max_iter = iters;
        lo.history = 10;
        lo.tol = 1e-9f;
        st = tn_lbfgs(x, n, tn__style_eval, L, &lo, &f);
        if (L->status) st = L->status; /* the real cause, not "objective is NaN" */
        if (st == TN_ERR_CANCELLED) st = tn__fail(TN_ERR_CANCELLED, "style: cancelled by the progress callback");
    } else {
        tn_params *p = tn_params_create();
        tn_optim_opts oo;
        tn_optim *opt = NULL;
        tn_tensor *t = NULL;
        int len = (int)n;
        memset(&oo, 0, sizeof oo);
        oo.kind = c->o.optimizer == TN_STYLE_ADAM ? TN_OPTIM_ADAM : TN_OPTIM_SGD;
        oo.lr = c->o.lr;
        if (c->o.optimizer == TN_STYLE_SGD) { /* the paper's schedule: x0.96 every 1/20 of the run */
            oo.lr_decay = 0.96f;
            oo.decay_every = iters / 20 > 0 ? iters / 20 : 1;
        }
        if (p) t = tn_params_add(p, "map", 1, &len);
        if (t) opt = tn_optim_create(p, &oo);
        if (!opt) st = tn__fail(TN_ERR_OUT_OF_MEMORY, "style: out of memory");
        if (t) memcpy(t->data, x, n * sizeof(float));
        for (it = 0; it < iters && !st; it++) {
            memset(t->grad, 0, n * sizeof(float));
            tn__style_eval(L, t->data, t->grad);
            if ((st = L->status)) break;
            tn_optim_step(opt);
            if (tn__style_report(c, (double)(it + 1) / iters)) st = tn__fail(TN_ERR_CANCELLED, "style: cancelled by the progress callback");
        }
        if (!st) memcpy(x, t->data, n * sizeof(float));
        tn_optim_free(opt);
        tn_params_free(p);
    }
    c->work_done += c->span;
    c->frac = 0; /* the next level's target fills report from here, not one tile ahead */
    return st;
}

/* Copies the w x h window at (x0, y0) of a one-channel map into dst. */
static void tn__style_window(float *dst, const tn_image *m, int x0, int y0, int w, int h)
{
    int y;
    for (y = 0; y < h; y++) memcpy(dst + (size_t)y * w, m->data + (size_t)(y0 + y) * m->width + x0, (size_t)w * sizeof(float));
}

/* Tile origins along one axis: tiles of length t overlapping by ov, the last one flush with the end. */
static int tn__style_tile_pos(int size, int t, int ov, int *pos, int max)
{
    int n = 0, p = 0;
    if (t >= size) {
        pos[0] = 0;
        return 1;
    }
    for (;;) {
        if (p + t >= size) {
            pos[n++] = size - t;
            return n;
        }
        if (n == max - 1) return 0; /* more tiles needed than pos holds */
        pos[n++] = p;
        p += t - ov;
    }
}

/* Blend weight of pixel i of a tile of length t at origin p on an axis of length size. */
static float tn__style_ramp(int i, int t, int p, int size, int ov)
{
    float w = 1.0f;
    if (p > 0 && i < ov) w = (float)(i + 1) / (float)(ov + 1);
    if (p + t < size && t - 1 - i < ov) {
        float v = (float)(t - i) / (float)(ov + 1);
        if (v < w) w = v;
    }
    return w;
}

#define TN__STYLE_MAXTILES 64

/* Tile length along an axis of `size` for tiles of nominal length t overlapping by t / 8: the
   fewest tiles of at most t that cover it, grown by the overlap (1024 -> 2 tiles of 576). */
static int tn__style_tile_len(int size, int t)
{
    int n = (size + t - 1) / t, len = (size + n - 1) / n + (n > 1 ? t / 8 : 0);
    return len < size ? len : size;
}

/* A level optimising w x h maps with the configured net and weights (targets still empty). */
static void tn__style_level_init(tn__style_level *L, const tn__style_cfg *c, int w, int h)
{
    memset(L, 0, sizeof *L);
    L->net = &c->net;
    L->w = w;
    L->h = h;
    L->wc = c->o.content_weight;
    L->wg = c->o.style_weight;
    L->wsw = c->o.sw_weight;
    L->wh = c->o.hist_weight;
    L->wtv = c->o.tv_weight;
    L->wdep = c->o.drain_weight;
    L->wrel = c->level > 0 ? c->o.valley_weight : -1.0f; /* the finest level only adds detail */
    L->ctx = tn_ctx_create();
}

/* Optimises one pyramid level: x (init in, result out), anchor = content target (x's size),
   src = source (x's size, or smaller when x carries a margin: its tiles give the targets). */
static tn_status tn__style_level_run(tn__style_cfg *c, const tn_image *src, const tn_image *anchor, tn_image *x)
{
    int W = x->width, H = x->height, T = c->o.tile, SW = src->width, SH = src->height;
    int tw = tn__style_tile_len(W, T), th = tn__style_tile_len(H, T), ov = T / 8;
    int sw = tn__style_tile_len(SW, T), sh = tn__style_tile_len(SH, T);
    int px[TN__STYLE_MAXTILES], py[TN__STYLE_MAXTILES], nx, ny, i, j, k, ncrop;
    float *buf = NULL, *wsum = NULL, *acc = NULL, **crops = NULL;
    size_t tn = (size_t)tw * th, sn = (size_t)sw * sh, n = (size_t)W * H, q;
    tn__style_level L;
    tn_status st = TN_OK;
    nx = tn__style_tile_pos(SW, sw, ov, px, TN__STYLE_MAXTILES); /* the caller checked the counts */
    ny = tn__style_tile_pos(SH, sh, ov, py, TN__STYLE_MAXTILES);
    ncrop = nx * ny;
    tn__style_level_init(&L, c, sw, sh);
    buf = (float *)tn__alloc((tn + sn * (size_t)ncrop) * sizeof(float));
    crops = (float **)tn__alloc((size_t)ncrop * sizeof(float *));
    acc = (float *)tn__calloc(2 * n * sizeof(float));
    if (!L.ctx || !buf || !crops || !acc) {
        st = tn__fail(TN_ERR_OUT_OF_MEMORY, "style: out of memory");
        goto done;
    }
    wsum = acc + n;
    for (j = 0, k = 0; j < ny; j++)
        for (i = 0; i < nx; i++, k++) {
            crops[k] = buf + tn + sn * (size_t)k;
            tn__style_window(crops[k], src, px[i], py[j], sw, sh);
        }
    if ((st = tn__style_targets(&L, (const float *const *)crops, ncrop, c->o.seed))) goto done;
    if (!c->net.vgg && (L.wh > 0 || L.wdep > 0 || L.wrel > 0) && (st = tn__style_hist_targets(&L, src->data, SW, SH))) goto done;
    L.w = tw; /* the targets are statistics: they hold for tiles of x's size too */
    L.h = th;
    nx = tn__style_tile_pos(W, tw, ov, px, TN__STYLE_MAXTILES);
    ny = tn__style_tile_pos(H, th, ov, py, TN__STYLE_MAXTILES);
    for (j = 0; j < ny && !st; j++)
        for (i = 0; i < nx && !st; i++) {
            int y, xx;
            tn__style_window(buf, anchor, px[i], py[j], tw, th);
            if (L.wc > 0 && (st = tn__style_content_target(&L, buf))) break;
            tn__style_window(buf, x, px[i], py[j], tw, th);
            if ((st = tn__style_optimise(&L, buf, c))) break;
            for (y = 0; y < th; y++)
                for (xx = 0; xx < tw; xx++) {
                    float w = tn__style_ramp(xx, tw, px[i], W, ov) * tn__style_ramp(y, th, py[j], H, ov);
                    size_t o = (size_t)(py[j] + y) * W + px[i] + xx;
                    acc[o] += w * buf[(size_t)y * tw + xx];
                    wsum[o] += w;
                }
        }
    if (!st)
        for (q = 0; q < n; q++) x->data[q] = acc[q] / wsum[q];
done:
    tn__style_level_free(&L);
    TN_FREE(buf);
    TN_FREE(crops);
    TN_FREE(acc);
    return st;
}

/* Affine normalisation of a map to the net's input space: standardised (built-in) or [0, 1]
   (VGG). Returns the offset and scale so that v = z * scale + offset. */
static void tn__style_normalise(tn_image *m, int unit_range, double *offset, double *scale)
{
    size_t i, n = (size_t)m->width * m->height;
    double a, b;
    if (unit_range) {
        float lo, hi;
        tn_image_range(m, &lo, &hi);
        a = lo;
        b = hi - lo;
    } else {
        double s = 0, s2 = 0;
        for (i = 0; i < n; i++) s += m->data[i];
        a = s / (double)n;
        for (i = 0; i < n; i++) s2 += (m->data[i] - a) * (m->data[i] - a);
        b = sqrt(s2 / (double)n);
    }
    if (!(b > 1e-12)) b = 1;
    for (i = 0; i < n; i++) m->data[i] = (float)((m->data[i] - a) / b);
    *offset = a;
    *scale = b;
}

static tn_status tn__style_resize(tn_image *dst, const tn_image *src, int w, int h)
{
    int down = w <= src->width && h <= src->height;
    return tn_image_resize(dst, src, w, h, down ? TN_RESIZE_AREA : TN_RESIZE_BICUBIC);
}

/* The source at the pixel scale the transfer matches (dst, one channel): resized to the map's
   w x h when the map is no larger than it, kept at its own size when the map is larger on either
   side: an upsampled source has smoothed statistics and the result turns blobby (docs/style.md).
   The map is then a larger field with the source's morphology, each pyramid level matched to
   the source's level of the same pixel size (tn__style_level_run only takes statistics from it). */
static tn_status tn__style_source_scale(tn_image *dst, const tn_image *src, int w, int h)
{
    if (w > src->width || h > src->height) return tn_image_copy(dst, src);
    return tn__style_resize(dst, src, w, h);
}

/* Size of pyramid level k (0 = full size, each level halves), at least 16 x 16. */
static void tn__style_level_size(int W, int H, int k, int *lw, int *lh)
{
    *lw = (int)(W / (double)(1 << k) + 0.5);
    *lh = (int)(H / (double)(1 << k) + 0.5);
    if (*lw < 16) *lw = 16;
    if (*lh < 16) *lh = 16;
}

/* The zero rules of tn_style_opts that follow from the options alone: iterations and learning
   rate per optimiser, tile 512, loss weights per network (VGG-19 or built-in), seed 1. Two
   rules need the maps and are applied in tn_style_transfer: the built-in net's drain_weight
   and valley_weight (tn__style_auto_drainage) and levels (tn__style_auto_levels). */
static void tn__style_opts_defaults(tn_style_opts *o)
{
    int vgg = o->vgg != NULL;
    if (!o->iters) o->iters = o->optimizer == TN_STYLE_LBFGS ? 40 : (o->optimizer == TN_STYLE_ADAM ? 150 : 300);
    if (!o->tile) o->tile = 512;
    if (o->content_weight == 0) o->content_weight = vgg ? 2.5e-11f : 0.1f;
    if (o->style_weight == 0) o->style_weight = vgg ? 1e-5f : 1.0f;
    if (o->sw_weight == 0) o->sw_weight = vgg ? -1.0f : 1.0f;
    if (o->hist_weight == 0) o->hist_weight = vgg ? -1.0f : 1.0f;
    if (vgg && o->drain_weight == 0) o->drain_weight = -1.0f;
    if (vgg && o->valley_weight == 0) o->valley_weight = -1.0f;
    if (o->tv_weight == 0) o->tv_weight = vgg ? 1e-10f : -1.0f;
    if (o->lr == 0) o->lr = o->optimizer == TN_STYLE_SGD ? (vgg ? 150.0f : 0.5f) : (vgg ? 0.01f : 0.02f);
    if (!o->seed) o->seed = 1;
}

/* Checks options whose defaults are applied (a zero never fails here). */
static tn_status tn__style_opts_check(const tn_style_opts *o)
{
    const float w[7] = {o->content_weight, o->style_weight, o->sw_weight, o->hist_weight, o->drain_weight, o->valley_weight, o->tv_weight};
    int i;
    if (o->optimizer != TN_STYLE_LBFGS && o->optimizer != TN_STYLE_SGD && o->optimizer != TN_STYLE_ADAM)
        return tn__fail(TN_ERR_INVALID_ARG, "style: unknown optimizer %d", (int)o->optimizer);
    if (o->iters < 0 || o->iters > 1000000) return tn__fail(TN_ERR_INVALID_ARG, "style: iters must be in 0..1000000");
    if (o->levels < 0 || o->levels > 8) return tn__fail(TN_ERR_INVALID_ARG, "style: levels must be in 0..8");
    if (o->tile < 0 || (o->tile > 0 && o->tile < 32)) return tn__fail(TN_ERR_INVALID_ARG, "style: tile must be 0 or >= 32");
    for (i = 0; i < 7; i++)
        if (!(w[i] >= -FLT_MAX && w[i] <= FLT_MAX)) return tn__fail(TN_ERR_INVALID_ARG, "style: loss weights must be finite");
    if (!(o->lr > 0 && o->lr <= FLT_MAX)) return tn__fail(TN_ERR_INVALID_ARG, "style: the learning rate must be positive and finite");
    return TN_OK;
}

/* Resolves and checks the options, and builds the network. */
static tn_status tn__style_setup(tn__style_cfg *c, const tn_style_opts *opts)
{
    tn_status st;
    memset(c, 0, sizeof *c);
    if (opts) c->o = *opts;
    tn__style_opts_defaults(&c->o);
    if ((st = tn__style_opts_check(&c->o))) return st;
    return c->o.vgg ? tn__style_net_vgg(&c->net, c->o.vgg) : tn__style_net_builtin(&c->net, c->o.seed);
}

/* Margin (px per side) of a w x h level: 1/8 of the smaller side, at least 2, on levels with
   the valley term (built-in net, all but the finest level); 0 elsewhere. */
static int tn__style_margin(const tn__style_cfg *c, int level, int w, int h)
{
    int m = (w < h ? w : h) / 8;
    if (level == 0 || !(c->o.valley_weight > 0) || c->net.vgg) return 0;
    return m < 2 ? 2 : m;
}

/* Tile size for a w x h level grown by margin m: a level that fits one tile stays in one. */
static int tn__style_margin_tile(const tn__style_cfg *c, int w, int h, int m)
{
    return w <= c->o.tile && h <= c->o.tile && m ? (w > h ? w : h) + 2 * m : c->o.tile;
}

/* Runs a level, with the valley term on a canvas grown by the mirrored margin and cut back
   afterwards. Drainage is truncated at the map's edge, and the valley term, optimised there,
   leaves a frame (a low edge and a rim a few px in); with the margin, the frame falls outside. */
static tn_status tn__style_level_margin(tn__style_cfg *c, const tn_image *s, tn_image *a, tn_image *x)
{
    tn_image pa = {0, 0, 0, NULL}, px = {0, 0, 0, NULL};
    int w = x->width, h = x->height, m = tn__style_margin(c, c->level, w, h), tile = c->o.tile;
    tn_status st;
    if (!m) return tn__style_level_run(c, s, a, x);
    c->o.tile = tn__style_margin_tile(c, w, h, m);
    if (!(st = tn_image_pad(&pa, a, m, m, m, m, TN_PAD_REFLECT)) && !(st = tn_image_pad(&px, x, m, m, m, m, TN_PAD_REFLECT)) &&
        !(st = tn__style_level_run(c, s, &pa, &px))) {
        tn_image_free(x);
        st = tn_image_crop(x, &px, m, m, w, h);
    }
    c->o.tile = tile;
    tn_image_free(&pa);
    tn_image_free(&px);
    return st;
}

#define TN__STYLE_BASIN_DEPTH 1e-3 /* of the height range: a cell this far under its filled level is in a closed basin */
#define TN__STYLE_BASIN_SHARE 0.05 /* sources with less of their area in closed basins are fluvial */

/* Default drainage terms from the source s (at map size): on (drain 10, valley 1) when under
   5 % of it lies in closed basins deeper than 0.1 % of its range, i.e. water leaves it through
   valleys (mountains, canyons; the shallow flats of 8-bit DEMs do not count); off for dunes,
   craters and karst, whose closed basins the valley term would cut open. */
static tn_status tn__style_auto_drainage(tn__style_cfg *c, const tn_image *s)
{
    size_t i, n = (size_t)s->width * s->height, deep = 0;
    float lo, hi, *f;
    tn_status st;
    int fluvial;
    if (c->o.drain_weight != 0 && c->o.valley_weight != 0) return TN_OK;
    if (!(f = (float *)tn__alloc(n * sizeof(float)))) return TN_ERR_OUT_OF_MEMORY;
    tn_image_range(s, &lo, &hi);
    if (!(st = tn__style_fill(s->data, s->width, s->height, f)))
        for (i = 0; i < n; i++) deep += f[i] - s->data[i] > TN__STYLE_BASIN_DEPTH * (hi - lo);
    TN_FREE(f);
    fluvial = (double)deep < TN__STYLE_BASIN_SHARE * (double)n;
    if (c->o.drain_weight == 0) c->o.drain_weight = fluvial ? 10.0f : -1.0f;
    if (c->o.valley_weight == 0) c->o.valley_weight = fluvial ? 1.0f : -1.0f;
    return st;
}

/* Pyramid levels for a W x H map when levels is 0: halve while the coarsest side stays >= 64,
   or >= 32 when the built-in net's drainage terms are on (they carve the valley network from
   one level coarser); at most 6. */
static int tn__style_auto_levels(const tn__style_cfg *c, int W, int H)
{
    int nl, coarsest = !c->net.vgg && (c->o.drain_weight > 0 || c->o.valley_weight > 0) ? 32 : 64;
    if (c->o.levels) return c->o.levels;
    for (nl = 1; nl < 6 && ((W < H ? W : H) >> nl) >= coarsest;) nl++;
    return nl;
}

TN_API tn_status tn_style_transfer(tn_image *out, const tn_image *content, const tn_image *style, const tn_style_opts *opts)
{
    tn__style_cfg *c;
    tn_image cm = {0, 0, 0, NULL}, sm = {0, 0, 0, NULL}, cur = {0, 0, 0, NULL};
    double sa, sb, ca, cb;
    int W, H, nl, k;
    tn_status st;
    size_t i;
    if (!out || !content || !style || !content->data || !style->data || content->channels < 1 || style->channels < 1)
        return tn__fail(TN_ERR_INVALID_ARG, "style: needs a content map and a style map");
    W = content->width;
    H = content->height;
    if (W < 16 || H < 16 || style->width < 16 || style->height < 16)
        return tn__fail(TN_ERR_INVALID_ARG, "style: maps must be at least 16 x 16 (content %d x %d, style %d x %d)", W, H,
                        style->width, style->height);
    if (tn_image_range(content, NULL, NULL)) return tn__fail(TN_ERR_NUMERIC, "style: the content map holds NaN/Inf");
    if (tn_image_range(style, NULL, NULL)) return tn__fail(TN_ERR_NUMERIC, "style: the style map holds NaN/Inf");
    if (!(c = (tn__style_cfg *)tn__alloc(sizeof *c))) return TN_ERR_OUT_OF_MEMORY;
    st = tn__style_setup(c, opts); /* clears c */
    c->user_fn = tn__progress_fn;  /* restored at the end */
    c->user_data = tn__progress_user;
    if (st) goto done;
    tn_set_progress(tn__style_progress_fwd, c);
    if ((st = tn__channel0_image(style, &cur))) goto done;
    st = tn__style_source_scale(&sm, &cur, W, H);
    tn_image_free(&cur);
    if (st || (st = tn__channel0_image(content, &cm))) goto done;
    tn__style_normalise(&sm, c->net.vgg, &sa, &sb);
    tn__style_normalise(&cm, c->net.vgg, &ca, &cb);
    if (!c->net.vgg && (st = tn__style_auto_drainage(c, &sm))) goto done;
    /* a source smaller than the map also bounds the pyramid: its coarsest level must hold statistics */
    nl = tn__style_auto_levels(c, W < sm.width ? W : sm.width, H < sm.height ? H : sm.height);
    for (k = nl - 1; k >= 0; k--) { /* progress total: pixel-iterations over all levels and tiles */
        int lw, lh, tw, th, m, T, nx, ny, p[TN__STYLE_MAXTILES];
        tn__style_level_size(W, H, k, &lw, &lh);
        m = tn__style_margin(c, k, lw, lh);
        T = tn__style_margin_tile(c, lw, lh, m);
        lw += 2 * m;
        lh += 2 * m;
        tw = tn__style_tile_len(lw, T);
        th = tn__style_tile_len(lh, T);
        nx = tn__style_tile_pos(lw, tw, T / 8, p, TN__STYLE_MAXTILES);
        ny = tn__style_tile_pos(lh, th, T / 8, p, TN__STYLE_MAXTILES);
        if (!nx || !ny) {
            st = tn__fail(TN_ERR_INVALID_ARG, "style: tiles of %d px are too small for a %d x %d map (at most %d per side)", c->o.tile, W, H,
                          TN__STYLE_MAXTILES);
            goto done;
        }
        c->work_total += (double)c->o.iters * tw * th * nx * ny;
    }
    for (k = nl - 1; k >= 0 && !st; k--) {
        int lw, lh;
        tn_image s = {0, 0, 0, NULL}, a = {0, 0, 0, NULL}, x = {0, 0, 0, NULL};
        tn__style_level_size(sm.width, sm.height, k, &lw, &lh); /* the source's level k: the same pixel scale as the map's */
        st = tn__style_resize(&s, &sm, lw, lh);
        tn__style_level_size(W, H, k, &lw, &lh);
        if (!st) st = cur.data ? tn_image_resize(&x, &cur, lw, lh, TN_RESIZE_BILINEAR) : tn__style_resize(&x, &cm, lw, lh);
        if (!st) st = tn_image_copy(&a, &x); /* finer levels are anchored to the coarser result */
        c->level = k;
        if (!st) st = tn__style_level_margin(c, &s, &a, &x);
        tn_image_free(&s);
        tn_image_free(&a);
        tn_image_free(&cur);
        cur = x;
    }
    if (!st && c->user_fn && c->user_fn(c->user_data, "style", 1.0)) st = tn__fail(TN_ERR_CANCELLED, "style: cancelled by the progress callback");
    if (!st) {
        for (i = 0; i < (size_t)W * H; i++) cur.data[i] = (float)(cur.data[i] * sb + sa);
        *out = cur;
        cur.data = NULL;
    }
done:
    tn_set_progress(c->user_fn, c->user_data);
    tn_image_free(&cur);
    tn_image_free(&cm);
    tn_image_free(&sm);
    tn_params_free(c->net.own);
    TN_FREE(c);
    (void)ca;
    (void)cb;
    return st;
}

/* ---- morphology scores: Table 1 SSIM, the realism report's slope and spectrum distances ---- */

TN_API tn_status tn_style_compare(const tn_image *map, const tn_image *source, tn_style_scores *out)
{
    tn_image a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL}, t = {0, 0, 0, NULL}, n = {0, 0, 0, NULL};
    tn_status st;
    if (!map || !source || !out || !map->data || !source->data || map->channels < 1 || source->channels < 1)
        return tn__fail(TN_ERR_INVALID_ARG, "style compare: needs a map and a source");
    if (map->width < 16 || map->height < 16 || source->width < 2 || source->height < 2)
        return tn__fail(TN_ERR_INVALID_ARG, "style compare: the map must be at least 16 x 16");
    if (tn_image_range(map, NULL, NULL) || tn_image_range(source, NULL, NULL))
        return tn__fail(TN_ERR_NUMERIC, "style compare: NaN/Inf in the input");
    if (!(st = tn__channel0_image(map, &a)) && !(st = tn__channel0_image(source, &t)) &&
        !(st = tn__style_resize(&b, &t, map->width, map->height))) {
        int native = map->width > t.width || map->height > t.height;
        tn_realism_opts ro;
        tn_realism r;
        tn__normalise01(&a);
        tn__normalise01(&b);
        /* the distances compare with the source at the pixel scale the transfer matches */
        if (native && !(st = tn_image_copy(&n, &t))) tn__normalise01(&n);
        memset(&ro, 0, sizeof ro);
        tn__realism_opts_defaults(&ro);
        memset(&r, 0, sizeof r);
        memset(out, 0, sizeof *out);
        if (!st && !(st = tn_ssim(&b, &a, 1.0, &out->ssim)) && !(st = tn__realism_shape(native ? &n : &b, &a, &ro, &r))) {
            out->slope_hist_dist = r.slope_distance;
            out->spectrum_dist = r.spectrum_distance;
        }
    }
    tn_image_free(&a);
    tn_image_free(&b);
    tn_image_free(&t);
    tn_image_free(&n);
    return st;
}

TN_API tn_status tn_style_content_noise(tn_image *out, int width, int height, const tn_image *source,
                                        const tn_perlin_opts *opts, float *gain_out)
{
    tn_image best = {0, 0, 0, NULL}, cand = {0, 0, 0, NULL};
    tn_perlin_opts po;
    tn_style_scores sc;
    double best_d = 0.0;
    float best_g = 0.5f;
    tn_status st = TN_OK;
    int k;
    if (!out || !source) return tn__fail(TN_ERR_INVALID_ARG, "style content noise: needs an output and a source");
    if (opts) po = *opts;
    else memset(&po, 0, sizeof po);
    for (k = 0; k < 10 && !st; k++) {
        po.gain = 0.45f + 0.05f * (float)k;
        if ((st = tn_noise_perlin(&cand, width, height, &po)) || (st = tn_style_compare(&cand, source, &sc))) break;
        if (!best.data || sc.slope_hist_dist + sc.spectrum_dist < best_d) {
            tn_image_free(&best);
            best = cand;
            cand.data = NULL;
            best_d = sc.slope_hist_dist + sc.spectrum_dist;
            best_g = po.gain;
        }
        tn_image_free(&cand);
    }
    tn_image_free(&cand);
    if (st) {
        tn_image_free(&best);
        return st;
    }
    *out = best;
    if (gain_out) *gain_out = best_g;
    return TN_OK;
}

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

static uint64_t tn__splitmix64(uint64_t x)
{
    x += 0x9E3779B97F4A7C15ULL;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
    return x ^ (x >> 31);
}

static int tn__tg_zdim(const tn_texgan *m) { return m->noise_local + m->noise_global + m->noise_periodic; }

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
static int tn__tg_out_size(const tn_texgan *m, int cells)
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
    c[11] = (float)m->train_seconds;
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

TN_API tn_status tn_texgan_save(const tn_texgan *model, const char *path)
{
    tn_tensor *cfg;
    if (!model || !model->weights) return tn__fail(TN_ERR_INVALID_ARG, "texgan save: no model");
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "texgan save: empty path");
    cfg = tn_params_find(model->weights, "texgan.config");
    tn__tg_write_config(model, (int)cfg->data[12], (int)cfg->data[13], cfg->data);
    return tn_params_save(model->weights, path);
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
    if ((st = tn_params_open(path, &f))) return st;
    memset(&m, 0, sizeof m);
    st = tn_model_check(f, "texgan", TN__TG_FORMAT, "texgan.config", path);
    if (!st && (!(cfg = tn_params_find(f, "texgan.config")) || cfg->numel != TN__TG_CONFIG))
        st = tn__fail(TN_ERR_FORMAT, "%s: not a texgan model (no texgan.config)", path);
    if (!st) st = tn__tg_read_config(&m, NULL, NULL, cfg->data, path);
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
static void tn__tg_noise(const tn_texgan *m, const float *waves, tn_tensor *z, int item, uint64_t seed, long cx0, long cy0)
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
static void tn__tg_noise_plane(float *dst, uint64_t seed, int stage, long cx0, long cy0, int h, int w)
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
static tn_tensor *tn__tg_pixel_norm(tn_ctx *ctx, tn_tensor *x)
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
static tn_tensor *tn__tg_generate(tn_ctx *ctx, const tn_texgan *m, tn_params *p, const char *prefix, tn_tensor *z,
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

/* ---- feature statistics (the anti-collapse term) ----
   A GAN on a small exemplar can collapse to a flat colour: the discriminator separates it
   perfectly and its gradient stops pointing anywhere useful. The generator therefore also
   matches, on its fake batch, the means and centred covariances of TN__TG_FEATS fixed random
   5x5 filters (ReLU) at scales 1, 2, 4 to the exemplar's: a flat output has zero covariance,
   so this term pulls it back towards the exemplar's variety whatever the discriminator does. */
#define TN__TG_FEATS 32
#define TN__TG_FSCALES 3

static void tn__tg_make_filters(tn__tg_train *s)
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
static tn_status tn__tg_feat_ref(tn__tg_train *s, tn_ctx *ctx, const float *ex, int W, int H)
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
static tn_tensor *tn__tg_feat_loss(tn_ctx *ctx, tn__tg_train *s, tn_tensor *x)
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

/* The settings a checkpoint keeps beside the architecture (its config tensor). */
static const char *const tn__tg_settings[6] = {"patch", "batch", "lr", "ema", "augment", "feat_weight"};

static tn_status tn__tg_put_settings(tn__tg_train *s)
{
    const double v[6] = {(double)s->patch, (double)s->batch, s->lr, s->ema, (double)s->augment, s->feat_weight};
    tn_status st = TN_OK;
    char buf[40];
    int i;
    for (i = 0; i < 6 && !st; i++) {
        tn__io_format_number(buf, sizeof buf, v[i], i >= 2);
        st = tn_train_set_meta(s->run, tn__tg_settings[i], buf);
    }
    return st;
}

static tn_status tn__tg_get_settings(tn__tg_train *s, const char *path)
{
    double v[6];
    int i;
    for (i = 0; i < 6; i++) {
        const char *t = tn_train_meta(s->run, tn__tg_settings[i]);
        if (!t || !tn__io_number(t, strlen(t), &v[i]) || !(fabs(v[i]) < 1e9))
            return tn__fail(TN_ERR_CORRUPT, "%s: bad or missing texgan setting '%s'", path, tn__tg_settings[i]);
    }
    if (v[0] != floor(v[0]) || v[1] != floor(v[1]) || v[0] < 8 || v[0] > 4096 || v[1] < 1 || v[1] > 1024 || !(v[2] > 0 && v[2] < 1) ||
        !(v[3] > 0 && v[3] < 1) || !(v[5] >= 0 && v[5] < 1e6))
        return tn__fail(TN_ERR_CORRUPT, "%s: bad training settings", path);
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
    if (!st) st = tn__tg_get_settings(s, path);
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
    if (tn_image_range(ex, lo, hi)) return tn__fail(TN_ERR_NUMERIC, "texgan: the exemplar holds NaN/Inf");
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

/* The model's metadata: method, format and where it came from. */
static tn_status tn__tg_stamp(tn__tg_train *s, const tn_image *ex, uint64_t seed)
{
    tn_model_provenance pv;
    memset(&pv, 0, sizeof pv);
    pv.seed = seed;
    pv.iterations = tn_train_iteration(s->run);
    pv.seconds = tn_train_seconds(s->run);
    pv.example_digest = tn_image_digest(ex);
    pv.example_width = ex->width;
    pv.example_height = ex->height;
    pv.example_channels = ex->channels;
    return tn_model_stamp(s->m.weights, "texgan", TN__TG_FORMAT, &pv);
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
    if ((st = tn_train_create("texgan", "texgan-train", &o.train, &s.run))) return st;
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
        st = tn__tg_stamp(&s, ex0, tn_train_seed(s.run));
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

static tn_tensor *tn__tg_generate_fast(tn_ctx *ctx, const tn_texgan *m, tn_tensor *z, uint64_t seed, long cx0, long cy0)
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

TN_API tn_status tn_texgan_synthesize_window(const tn_texgan *model, uint64_t seed, int x0, int y0, int w, int h, tn_image *out)
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

static tn_status tn__tg_collect_band(void *user, int y0, const tn_image *band)
{
    tn_image *img = (tn_image *)user;
    memcpy(img->data + (size_t)y0 * img->width * img->channels, band->data,
           (size_t)band->width * band->height * band->channels * sizeof(float));
    return TN_OK;
}

TN_API tn_status tn_texgan_synthesize(const tn_texgan *model, uint64_t seed, int width, int height, tn_image *out)
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

typedef struct tn__tg_writer {
    FILE *f[TN_TEXGAN_MAX_CHANNELS];
    char *tmp[TN_TEXGAN_MAX_CHANNELS], *final[TN_TEXGAN_MAX_CHANNELS];
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
            if (fseek(w->f[g], off, SEEK_SET) != 0 || fwrite(w->row, 1, rowbytes, w->f[g]) != rowbytes)
                return tn__fail(TN_ERR_IO, "%s: write failed (disk full?)", w->final[g]);
        }
    }
    return TN_OK;
}

static void tn__tg_writer_close(tn__tg_writer *w, tn_status *st)
{
    int g;
    for (g = 0; g < w->groups; g++) {
        if (w->f[g]) {
            int bad = fflush(w->f[g]) != 0 || ferror(w->f[g]);
            bad = (fclose(w->f[g]) != 0) || bad;
            if (bad && !*st) *st = tn__fail(TN_ERR_IO, "%s: write failed (disk full?)", w->final[g]);
        }
        if (w->tmp[g]) {
            if (!*st && rename(w->tmp[g], w->final[g]) != 0) *st = tn__fail(TN_ERR_IO, "%s: cannot rename the temporary file into place", w->final[g]);
            if (*st) remove(w->tmp[g]);
        }
        TN_FREE(w->tmp[g]);
        TN_FREE(w->final[g]);
    }
    TN_FREE(w->row);
}

/* Whole image in memory, then saved per channel group (formats that cannot stream). */
static tn_status tn__tg_save_whole(const tn_texgan *m, uint64_t seed, int width, int height, const float *shift, const char *path)
{
    tn_image img = {0, 0, 0, NULL}, part = {0, 0, 0, NULL};
    tn_save_opts so;
    tn_status st = tn_texgan_synthesize(m, seed, width, height, &img);
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

TN_API tn_status tn_texgan_synthesize_file(const tn_texgan *model, uint64_t seed, int width, int height, const float *shift,
                                           const char *path)
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
        size_t cap;
        w.final[g] = tn__tg_group_path(path, g, model->channels);
        cap = w.final[g] ? strlen(w.final[g]) + 40 : 0;
        w.tmp[g] = cap ? (char *)tn__alloc(cap) : NULL;
        if (!w.final[g] || !w.tmp[g]) { st = TN_ERR_OUT_OF_MEMORY; break; }
        snprintf(w.tmp[g], cap, "%s.tmp.%lu.%lu", w.final[g], tn__io_process_id(), ++tn__io_tmp_counter);
        if (!(w.f[g] = fopen(w.tmp[g], "wb"))) {
            st = tn__fail(TN_ERR_IO, "%s: cannot create a temporary file next to it", w.final[g]);
            TN_FREE(w.tmp[g]);
            w.tmp[g] = NULL;
            break;
        }
        if (w.pfm) w.hdr[g] = fprintf(w.f[g], "P%c\n%d %d\n-1.0\n", fc == 3 ? 'F' : 'f', width, height);
        else w.hdr[g] = fprintf(w.f[g], "P%d\n%d %d\n255\n", fc == 3 ? 6 : 5, width, height);
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

TN_API tn_status tn_texture_colour_shift(const tn_image *img, const float *target, float lo, float hi, float *shift)
{
    int c, it;
    if (!img || !img->data || img->width <= 0 || img->height <= 0 || img->channels <= 0) return tn__fail(TN_ERR_EMPTY, "colour correction: empty image");
    if (!(lo < hi) || !(lo >= -FLT_MAX && hi <= FLT_MAX))
        return tn__fail(TN_ERR_INVALID_ARG, "colour correction: range %g..%g is empty or not finite", (double)lo, (double)hi);
    if (tn_image_range(img, NULL, NULL)) return tn__fail(TN_ERR_NUMERIC, "colour correction: the image holds NaN/Inf");
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
    if ((st = tn_texture_colour_shift(img, target, lo, hi, shift))) return st;
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
    if (tn_image_range(ex, NULL, NULL)) return tn__fail(TN_ERR_NUMERIC, "detail maps: the exemplar holds NaN/Inf");
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
static void tn__dm_seamless(const tn_image *h, float *out, int axis)
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
    if (tn_image_range(synth, NULL, NULL)) return tn__fail(TN_ERR_NUMERIC, "detail maps: the synthesis holds NaN/Inf");
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

TN_API void tn_detail_texel(const tn_detail_maps *m, float u, float v, float *out)
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

TN_API tn_status tn_detail_compose(const tn_detail_maps *m, int width, int height, tn_image *out)
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
        if ((st = tn_image_load(path, img, NULL))) return st;
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
        st = tn_image_load(p, &part, NULL);
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

TN_API tn_status tn_detail_maps_save(const tn_detail_maps *m, const char *prefix)
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

TN_API tn_status tn_detail_preview(const tn_detail_maps *m, const tn_image *ex, const tn_image *dem, int panel, tn_image *out)
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
                tn_detail_texel(m, tu, tv, q);
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

/* --------------------------------------------------------------------------------------------
   >>gnn  (@@gnn implementation)
   Layout: membrane solve; the parts as flat arrays; the k-nearest-parts search (a bucket grid,
   rings searched outwards until the k-th distance is certain); a step's graph (fixed edges
   minus masked parts plus random edges, both edge lists in CSR order); two fused graph ops
   (attention aggregation and mean aggregation) that never materialise an edges x hidden
   tensor except the gradient scratch of training; the network; training on @@train; model
   files; generation.
   Why fused ops: with k = 10 a 128^2 example has 164k edges; gather/linear/scatter through the
   generic ops would hold ~10 edges x 32 tensors per round. The attention op takes the per-node
   terms of the first MLP layer (receiver and sender rows, computed once per node by GEMM) and
   only the 5 edge features per edge, so a round costs a few hundred flops per edge; the
   second MLP layer is applied after the attention-weighted sum (it is linear and the weights
   sum to 1, so that equals summing the encodings).
   Determinism: every reduction runs in a fixed order per destination or per source (CSR lists
   built by stable counting sorts), parameter gradients by GEMM or a serial sum.
   -------------------------------------------------------------------------------------------- */

#define TN__GNN_FORMAT 1
#define TN__GNN_CONFIG 24
#define TN__GNN_F 5          /* edge features: projection index, distance, closeness, height difference, noise */
#define TN__GNN_MAXH 256
#define TN__GNN_DIST 16.0f   /* distance scale of the edge features (px) */
#define TN__GNN_MAX_LEVELS 4 /* sketch densities in training */
#define TN__GNN_MAX_EDGES (1 << 25) /* ~1800^2 pixels at k = 10: ~2.5 GB of graph in training */

TN_API void tn_gnn_defaults(tn_gnn_opts *o)
{
    TN_ASSERT(o);
    /* H = 32, two-layer MLPs and k = 10 are the paper's (A.5, 4.2); T = 2 the issue's prototype.
       The embedding (16) gives each 5-10 px part room to memorise its neighbourhood. Noise:
       with the paper's N(0, 1) edge noise and part states, alps_montblanc 128 (600 steps)
       reconstructed at SSIM 0.959 and its neighbours at 0.901; without, 0.962 and 0.906
       (membrane 0.898), so both are off unless asked for. Loss weights: MSE 1, SSIM 0.1,
       gradient 0.1 on normalised heights (std 1); SSIM weight 1 (with the noise on) gave
       0.956 / 0.899 instead of 0.959 / 0.901. */
    if (o->hidden <= 0) o->hidden = 32;
    if (o->rounds <= 0) o->rounds = 2;
    if (o->k <= 0) o->k = 10;
    if (o->embed <= 0) o->embed = 16;
    if (o->random_edges == 0) o->random_edges = 10000;
    if (o->mask == 0) o->mask = 0.05f;
    if (o->edge_noise < 0) o->edge_noise = 0;
    if (o->part_noise < 0) o->part_noise = 0;
    if (o->embed_drop == 0) o->embed_drop = 0.5f;
    if (o->sparse_levels == 0) o->sparse_levels = 3;
    if (o->sparse_levels > TN__GNN_MAX_LEVELS - 1) o->sparse_levels = TN__GNN_MAX_LEVELS - 1;
    if (o->thin == 0) o->thin = 0.5f;
    if (o->lr <= 0) o->lr = 2e-3f;
    if (o->mse_weight == 0) o->mse_weight = 1.0f;
    if (o->ssim_weight == 0) o->ssim_weight = 0.1f;
    if (o->grad_weight == 0) o->grad_weight = 0.1f;
    tn_train_defaults(&o->train, 10.0);
}

/* ---- membrane (Laplace) interpolation ---- */

/* out = val on fixed pixels; sum over 4-neighbours inside the map of (out_q - out_p) = 0 on the
   others (Neumann border). Jacobi-preconditioned conjugate gradients, started from the same
   problem solved at half resolution and upsampled, so a 512^2 map needs ~100s of iterations,
   not ~1000s. Needs at least one fixed pixel. Serial and in double: same result everywhere. */
static tn_status tn__gnn_membrane_solve(const float *val, const uint8_t *fixed, int W, int H, float *out)
{
    size_t n = (size_t)W * H, i;
    double *x = NULL, *r = NULL, *d = NULL, *q = NULL, rz, scale = 0, tol;
    int it, maxit = 4 * (W + H) + 200, x0, y0;
    tn_status st = TN_OK;
    for (i = 0; i < n; i++)
        if (fixed[i] && fabs((double)val[i]) > scale) scale = fabs((double)val[i]);
    /* initial guess: the coarse solution upsampled (nearest), or the mean of the fixed values */
    if (W >= 32 && H >= 32) {
        int cw = (W + 1) / 2, ch = (H + 1) / 2;
        float *cv = (float *)tn__alloc((size_t)cw * ch * sizeof(float) * 2);
        uint8_t *cf = (uint8_t *)tn__calloc((size_t)cw * ch);
        int *cnt = (int *)tn__calloc((size_t)cw * ch * sizeof(int));
        if (!cv || !cf || !cnt) st = TN_ERR_OUT_OF_MEMORY;
        if (!st) {
            memset(cv, 0, (size_t)cw * ch * sizeof(float));
            for (y0 = 0; y0 < H; y0++)
                for (x0 = 0; x0 < W; x0++) {
                    size_t c = (size_t)(y0 / 2) * cw + x0 / 2, f = (size_t)y0 * W + x0;
                    if (!fixed[f]) continue;
                    cv[c] += val[f];
                    cnt[c]++;
                    cf[c] = 1;
                }
            for (i = 0; i < (size_t)cw * ch; i++)
                if (cnt[i]) cv[i] /= (float)cnt[i];
            st = tn__gnn_membrane_solve(cv, cf, cw, ch, cv + (size_t)cw * ch);
        }
        if (!st)
            for (y0 = 0; y0 < H; y0++)
                for (x0 = 0; x0 < W; x0++) out[(size_t)y0 * W + x0] = cv[(size_t)cw * ch + (size_t)(y0 / 2) * cw + x0 / 2];
        TN_FREE(cv);
        TN_FREE(cf);
        TN_FREE(cnt);
        if (st) return st;
    } else {
        double s = 0;
        size_t nf = 0;
        for (i = 0; i < n; i++)
            if (fixed[i]) { s += val[i]; nf++; }
        for (i = 0; i < n; i++) out[i] = (float)(nf ? s / (double)nf : 0.0);
    }
    x = (double *)tn__alloc(n * sizeof(double));
    r = (double *)tn__alloc(n * sizeof(double));
    d = (double *)tn__alloc(n * sizeof(double));
    q = (double *)tn__alloc(n * sizeof(double));
    if (!x || !r || !d || !q) {
        TN_FREE(x); TN_FREE(r); TN_FREE(d); TN_FREE(q);
        return TN_ERR_OUT_OF_MEMORY;
    }
    for (i = 0; i < n; i++) x[i] = fixed[i] ? (double)val[i] : (double)out[i];
#define TN__GNN_DEG(X, Y) (((X) > 0) + ((X) < W - 1) + ((Y) > 0) + ((Y) < H - 1))
    /* r = -(L x) on free pixels (the residual of the Laplace equation), 0 on fixed ones */
    rz = 0;
    for (y0 = 0; y0 < H; y0++)
        for (x0 = 0; x0 < W; x0++) {
            size_t p = (size_t)y0 * W + x0;
            double s = 0;
            if (fixed[p]) { r[p] = d[p] = 0; continue; }
            if (x0 > 0) s += x[p - 1] - x[p];
            if (x0 < W - 1) s += x[p + 1] - x[p];
            if (y0 > 0) s += x[p - W] - x[p];
            if (y0 < H - 1) s += x[p + W] - x[p];
            r[p] = s;
            d[p] = s / TN__GNN_DEG(x0, y0);
            rz += r[p] * d[p];
        }
    tol = 1e-7 * (scale > 1e-30 ? scale : 1.0);
    tol = tol * tol * (double)n;
    for (it = 0; it < maxit && rz > tol; it++) {
        double dq = 0, alpha, rz2 = 0, beta;
        for (y0 = 0; y0 < H; y0++)
            for (x0 = 0; x0 < W; x0++) {
                size_t p = (size_t)y0 * W + x0;
                double s = 0;
                if (fixed[p]) { q[p] = 0; continue; }
                s = TN__GNN_DEG(x0, y0) * d[p];
                if (x0 > 0) s -= d[p - 1];
                if (x0 < W - 1) s -= d[p + 1];
                if (y0 > 0) s -= d[p - W];
                if (y0 < H - 1) s -= d[p + W];
                q[p] = s;
                dq += d[p] * s;
            }
        if (!(dq > 0)) break;
        alpha = rz / dq;
        for (i = 0; i < n; i++) {
            x[i] += alpha * d[i];
            r[i] -= alpha * q[i];
        }
        for (y0 = 0; y0 < H; y0++)
            for (x0 = 0; x0 < W; x0++) {
                size_t p = (size_t)y0 * W + x0;
                if (!fixed[p]) rz2 += r[p] * r[p] / TN__GNN_DEG(x0, y0);
            }
        beta = rz2 / rz;
        rz = rz2;
        for (y0 = 0; y0 < H; y0++)
            for (x0 = 0; x0 < W; x0++) {
                size_t p = (size_t)y0 * W + x0;
                if (!fixed[p]) d[p] = r[p] / TN__GNN_DEG(x0, y0) + beta * d[p];
            }
    }
#undef TN__GNN_DEG
    for (i = 0; i < n; i++) out[i] = (float)x[i];
    TN_FREE(x); TN_FREE(r); TN_FREE(d); TN_FREE(q);
    return TN_OK;
}

/* Rasterised sketch -> pixel type (+1 ridge, -1 valley, 0 none), fixed heights, membrane. */
static tn_status tn__gnn_sketch_pixels(const tn_contour_set *set, int W, int H, float *type, float *height, float *membrane)
{
    tn_image r = {0, 0, 0, NULL};
    uint8_t *fixed;
    size_t i, n = (size_t)W * H, nf = 0;
    tn_status st;
    if ((st = tn_sketch_rasterise(set, W, H, &r))) return st;
    if (!(fixed = (uint8_t *)tn__alloc(n))) {
        tn_image_free(&r);
        return TN_ERR_OUT_OF_MEMORY;
    }
    for (i = 0; i < n; i++) {
        const float *p = r.data + 3 * i;
        fixed[i] = (uint8_t)(p[0] > 0 || p[1] > 0);
        nf += fixed[i];
        if (type) type[i] = p[0] > 0 ? 1.0f : p[1] > 0 ? -1.0f : 0.0f;
        height[i] = fixed[i] ? p[2] : 0.0f;
    }
    if (!nf) st = tn__fail(TN_ERR_EMPTY, "gnn: the sketch covers no pixel of the %d x %d map", W, H);
    if (!st && membrane) st = tn__gnn_membrane_solve(height, fixed, W, H, membrane);
    TN_FREE(fixed);
    tn_image_free(&r);
    return st;
}

TN_API tn_status tn_gnn_membrane(const tn_contour_set *sketch, int width, int height, tn_image *out)
{
    tn_image m = {0, 0, 0, NULL};
    float *h;
    tn_status st;
    TN_ASSERT(out);
    if (!sketch || sketch->count <= 0) return tn__fail(TN_ERR_EMPTY, "membrane: the sketch is empty");
    if ((st = tn__cset_check(sketch, "membrane"))) return st;
    if ((st = tn_image_create(&m, width, height, 1))) return st;
    if (!(h = (float *)tn__alloc((size_t)width * height * sizeof(float)))) {
        tn_image_free(&m);
        return TN_ERR_OUT_OF_MEMORY;
    }
    st = tn__gnn_sketch_pixels(sketch, width, height, NULL, h, m.data);
    TN_FREE(h);
    if (st) {
        tn_image_free(&m);
        return st;
    }
    *out = m;
    return TN_OK;
}

/* ---- parts as flat arrays ---- */

typedef struct tn__gnn_parts {
    int n, npts;
    int *start;        /* n + 1 offsets into pts */
    int *of;           /* npts: part of each point */
    float *pts;        /* npts x 3: x, y, normalised height */
    float *sign;       /* n: +1 ridge, -1 valley */
} tn__gnn_parts;

static void tn__gnn_parts_free(tn__gnn_parts *p)
{
    TN_FREE(p->start);
    TN_FREE(p->of);
    TN_FREE(p->pts);
    TN_FREE(p->sign);
    memset(p, 0, sizeof *p);
}

/* Heights become (h - mean) / std. */
static tn_status tn__gnn_parts_make(const tn_contour_set *set, float mean, float std, tn__gnn_parts *p)
{
    int i, j, k = 0;
    memset(p, 0, sizeof *p);
    p->n = set->count;
    for (i = 0; i < set->count; i++) p->npts += set->items[i].npoints;
    p->start = (int *)tn__alloc(((size_t)p->n + 1) * sizeof(int));
    p->of = (int *)tn__alloc(((size_t)p->npts + 1) * sizeof(int));
    p->pts = (float *)tn__alloc(((size_t)p->npts + 1) * 3 * sizeof(float));
    p->sign = (float *)tn__alloc(((size_t)p->n + 1) * sizeof(float));
    if (!p->start || !p->of || !p->pts || !p->sign) {
        tn__gnn_parts_free(p);
        return TN_ERR_OUT_OF_MEMORY;
    }
    for (i = 0; i < set->count; i++) {
        const tn_contour *c = &set->items[i];
        p->start[i] = k;
        p->sign[i] = c->type == TN_RIDGE ? 1.0f : -1.0f;
        for (j = 0; j < c->npoints; j++, k++) {
            p->of[k] = i;
            p->pts[3 * k] = c->points[3 * j];
            p->pts[3 * k + 1] = c->points[3 * j + 1];
            p->pts[3 * k + 2] = (c->points[3 * j + 2] - mean) / std;
        }
    }
    p->start[p->n] = k;
    return TN_OK;
}

/* Edge features of pixel (x, y) against one part, given its nearest point (index j of the
   part) and squared distance; base = the pixel's baseline height (0 without membrane). */
static void tn__gnn_edge_features(const tn__gnn_parts *P, int part, int j, float d2, float base, float *f)
{
    int n = P->start[part + 1] - P->start[part];
    float d = sqrtf(d2);
    f[0] = n > 1 ? 2.0f * (float)j / (float)(n - 1) - 1.0f : 0.0f;
    f[1] = d / TN__GNN_DIST;
    f[2] = expf(-0.5f * d);
    f[3] = P->pts[3 * (P->start[part] + j) + 2] - base;
    f[4] = 0.0f;
}

/* Nearest point of a part to (x, y): index within the part (lowest on ties) and squared distance. */
static int tn__gnn_project(const tn__gnn_parts *P, int part, float x, float y, float *d2)
{
    int a = P->start[part], b = P->start[part + 1], j, best = 0;
    float bd = FLT_MAX;
    for (j = a; j < b; j++) {
        float dx = P->pts[3 * j] - x, dy = P->pts[3 * j + 1] - y, e = dx * dx + dy * dy;
        if (e < bd) { bd = e; best = j - a; }
    }
    *d2 = bd;
    return best;
}

/* ---- k nearest parts of every pixel ---- */

#define TN__GNN_CELL 8

typedef struct tn__gnn_cand { int part, pt; float d2; } tn__gnn_cand;

typedef struct tn__gnn_knn_job {
    const tn__gnn_parts *P;
    int W, H, k, gw, gh;
    const int *cell_start, *cell_pts;   /* bucket grid of point indices */
    const float *base;                  /* per pixel baseline (normalised) or NULL */
    int *nbr;                           /* npix x k parts (-1 = none) */
    float *feat;                        /* npix x k x F */
    tn_status st[TN__MAX_THREADS];
} tn__gnn_knn_job;

static int tn__gnn_cand_cmp(const void *a, const void *b)
{
    const tn__gnn_cand *x = (const tn__gnn_cand *)a, *y = (const tn__gnn_cand *)b;
    if (x->d2 != y->d2) return x->d2 < y->d2 ? -1 : 1;
    return (x->part > y->part) - (x->part < y->part);
}

static void tn__gnn_knn_task(void *vjob, int ith, int nth)
{
    tn__gnn_knn_job *J = (tn__gnn_knn_job *)vjob;
    const tn__gnn_parts *P = J->P;
    int *stamp = (int *)tn__alloc((size_t)P->n * sizeof(int)), *slot = (int *)tn__alloc((size_t)P->n * sizeof(int));
    tn__gnn_cand *cand = (tn__gnn_cand *)tn__alloc((size_t)P->n * sizeof(tn__gnn_cand));
    int y0 = (int)((long)J->H * ith / nth), y1 = (int)((long)J->H * (ith + 1) / nth), x, y, i, k = J->k;
    if (!stamp || !slot || !cand) {
        J->st[ith] = TN_ERR_OUT_OF_MEMORY;
        TN_FREE(stamp); TN_FREE(slot); TN_FREE(cand);
        return;
    }
    for (i = 0; i < P->n; i++) stamp[i] = -1;
    for (y = y0; y < y1; y++)
        for (x = 0; x < J->W; x++) {
            int pix = y * J->W + x, bx = x / TN__GNN_CELL, by = y / TN__GNN_CELL, r, nc = 0, rmax = J->gw > J->gh ? J->gw : J->gh;
            size_t o = (size_t)pix * k;
            for (r = 0; r <= rmax; r++) {
                int cx, cy;
                for (cy = by - r; cy <= by + r; cy++) {
                    if (cy < 0 || cy >= J->gh) continue;
                    for (cx = bx - r; cx <= bx + r; cx++) {
                        int c, q;
                        if (cx < 0 || cx >= J->gw || (abs(cx - bx) != r && abs(cy - by) != r)) continue;
                        c = cy * J->gw + cx;
                        for (q = J->cell_start[c]; q < J->cell_start[c + 1]; q++) {
                            int pt = J->cell_pts[q], part = P->of[pt];
                            float dx = P->pts[3 * pt] - (float)x, dy = P->pts[3 * pt + 1] - (float)y, d2 = dx * dx + dy * dy;
                            if (stamp[part] != pix) {
                                stamp[part] = pix;
                                slot[part] = nc;
                                cand[nc].part = part;
                                cand[nc].pt = pt;
                                cand[nc++].d2 = d2;
                            } else {
                                tn__gnn_cand *cd = &cand[slot[part]];
                                if (d2 < cd->d2 || (d2 == cd->d2 && pt < cd->pt)) { cd->d2 = d2; cd->pt = pt; }
                            }
                        }
                    }
                }
                /* every point beyond ring r is farther than r cells */
                if (nc >= k) {
                    float bound = (float)(r * TN__GNN_CELL), b2 = bound * bound;
                    int below = 0;
                    for (i = 0; i < nc; i++) below += cand[i].d2 <= b2;
                    if (below >= k) break;
                }
            }
            /* candidates found in different rings: order them fully (ties: lower part index) */
            qsort(cand, (size_t)nc, sizeof *cand, tn__gnn_cand_cmp);
            for (i = 0; i < nc; i++) slot[cand[i].part] = i;
            for (i = 0; i < k; i++) {
                float *f = J->feat + (o + (size_t)i) * TN__GNN_F;
                if (i >= nc) {
                    J->nbr[o + (size_t)i] = -1;
                    memset(f, 0, TN__GNN_F * sizeof(float));
                    continue;
                }
                J->nbr[o + (size_t)i] = cand[i].part;
                tn__gnn_edge_features(P, cand[i].part, cand[i].pt - P->start[cand[i].part], cand[i].d2, J->base ? J->base[pix] : 0.0f, f);
            }
        }
    TN_FREE(stamp);
    TN_FREE(slot);
    TN_FREE(cand);
}

/* nbr (npix x k) and feat (npix x k x F) allocated here. */
static tn_status tn__gnn_knn(const tn__gnn_parts *P, int W, int H, int k, const float *base, int **nbr, float **feat)
{
    tn__gnn_knn_job J;
    int *cnt = NULL, i, ncell;
    size_t npix = (size_t)W * H;
    tn_status st = TN_OK;
    memset(&J, 0, sizeof J);
    J.P = P;
    J.W = W;
    J.H = H;
    J.k = k;
    J.base = base;
    J.gw = (W + TN__GNN_CELL - 1) / TN__GNN_CELL;
    J.gh = (H + TN__GNN_CELL - 1) / TN__GNN_CELL;
    ncell = J.gw * J.gh;
    cnt = (int *)tn__calloc(((size_t)ncell + 1) * sizeof(int));
    J.cell_pts = (int *)tn__alloc(((size_t)P->npts + 1) * sizeof(int));
    *nbr = (int *)tn__alloc(npix * k * sizeof(int));
    *feat = (float *)tn__alloc(npix * k * TN__GNN_F * sizeof(float));
    if (!cnt || !J.cell_pts || !*nbr || !*feat) st = TN_ERR_OUT_OF_MEMORY;
    if (!st) {
        int *cp = (int *)J.cell_pts, *fill;
#define TN__GNN_CELLOF(pt) \
    ((P->pts[3 * (pt) + 1] < 0 ? 0 : (int)P->pts[3 * (pt) + 1] / TN__GNN_CELL >= J.gh ? J.gh - 1 : (int)P->pts[3 * (pt) + 1] / TN__GNN_CELL) * J.gw + \
     (P->pts[3 * (pt)] < 0 ? 0 : (int)P->pts[3 * (pt)] / TN__GNN_CELL >= J.gw ? J.gw - 1 : (int)P->pts[3 * (pt)] / TN__GNN_CELL))
        for (i = 0; i < P->npts; i++) cnt[TN__GNN_CELLOF(i) + 1]++;
        for (i = 0; i < ncell; i++) cnt[i + 1] += cnt[i];
        if (!(fill = (int *)tn__alloc(((size_t)ncell + 1) * sizeof(int)))) st = TN_ERR_OUT_OF_MEMORY;
        else {
            memcpy(fill, cnt, (size_t)ncell * sizeof(int));
            for (i = 0; i < P->npts; i++) cp[fill[TN__GNN_CELLOF(i)]++] = i;
            TN_FREE(fill);
        }
#undef TN__GNN_CELLOF
    }
    if (!st) {
        J.cell_start = cnt;
        J.nbr = *nbr;
        J.feat = *feat;
        tn_parallel_run(tn__gnn_knn_task, &J);
        for (i = 0; i < TN__MAX_THREADS; i++)
            if (J.st[i]) st = tn__fail(J.st[i], "gnn: out of memory searching nearest parts");
    }
    TN_FREE(cnt);
    TN_FREE((void *)J.cell_pts);
    if (st) {
        TN_FREE(*nbr);
        TN_FREE(*feat);
        *nbr = NULL;
        *feat = NULL;
    }
    return st;
}

/* ---- a graph: edges with features, laid out per direction in destination order ---- */

/* One direction of the bipartite graph. Its edges are numbered by position in destination
   order (destination d owns positions dst_start[d] .. dst_start[d + 1] - 1), so the per-edge
   arrays the ops stream (features, attention weights, gradient rows) are read sequentially;
   only the per-source pass jumps, through src_pos. */
typedef struct tn__gnn_dir {
    int nsrc, ndst, E;
    const int *dst_start;              /* ndst + 1 */
    const int *src_of, *dst_of;        /* per position */
    const float *feat;                 /* per position, F features */
    const int *src_start, *src_pos;    /* positions of each source's edges */
} tn__gnn_dir;

typedef struct tn__gnn_graph {
    int npix, nparts, E, cap;
    int *e_pix, *e_part;               /* edges as built */
    float *feat;                       /* E x F as built */
    int *pix_start, *pix_edges, *part_start, *part_edges;  /* CSR by pixel / by part (edge ids) */
    int *ints;                         /* 7 x cap: per-direction position arrays + scratch */
    float *feats;                      /* 2 x cap x F: features in each direction's order */
    tn__gnn_dir g2p, p2g;              /* pixels -> parts (gather), parts -> pixels (scatter) */
} tn__gnn_graph;

static void tn__gnn_graph_free(tn__gnn_graph *g)
{
    TN_FREE(g->e_pix);
    TN_FREE(g->e_part);
    TN_FREE(g->feat);
    TN_FREE(g->pix_start);
    TN_FREE(g->pix_edges);
    TN_FREE(g->part_start);
    TN_FREE(g->part_edges);
    TN_FREE(g->ints);
    TN_FREE(g->feats);
    memset(g, 0, sizeof *g);
}

static tn_status tn__gnn_graph_alloc(tn__gnn_graph *g, int npix, int nparts, int cap)
{
    memset(g, 0, sizeof *g);
    g->npix = npix;
    g->nparts = nparts;
    g->cap = cap;
    g->e_pix = (int *)tn__alloc((size_t)cap * sizeof(int));
    g->e_part = (int *)tn__alloc((size_t)cap * sizeof(int));
    g->feat = (float *)tn__alloc((size_t)cap * TN__GNN_F * sizeof(float));
    g->pix_start = (int *)tn__alloc(((size_t)npix + 1) * sizeof(int));
    g->pix_edges = (int *)tn__alloc((size_t)cap * sizeof(int));
    g->part_start = (int *)tn__alloc(((size_t)nparts + 1) * sizeof(int));
    g->part_edges = (int *)tn__alloc((size_t)cap * sizeof(int));
    g->ints = (int *)tn__alloc((size_t)cap * 7 * sizeof(int));
    g->feats = (float *)tn__alloc((size_t)cap * 2 * TN__GNN_F * sizeof(float));
    if (!g->e_pix || !g->e_part || !g->feat || !g->pix_start || !g->pix_edges || !g->part_start || !g->part_edges || !g->ints ||
        !g->feats) {
        tn__gnn_graph_free(g);
        return TN_ERR_OUT_OF_MEMORY;
    }
    return TN_OK;
}

/* Stable counting sort of the edges by key: start (n + 1) and list (E). */
static void tn__gnn_csr(const int *key, int E, int n, int *start, int *list)
{
    int i;
    memset(start, 0, ((size_t)n + 1) * sizeof(int));
    for (i = 0; i < E; i++) start[key[i] + 1]++;
    for (i = 0; i < n; i++) start[i + 1] += start[i];
    for (i = 0; i < E; i++) list[start[key[i]]++] = i;
    for (i = n; i > 0; i--) start[i] = start[i - 1];
    start[0] = 0;
}

/* One direction from the two CSR lists: dst_edges orders the positions, src_edges lists each
   source's edges; inv (scratch, E) maps an edge id to its position. */
static void tn__gnn_dir_make(tn__gnn_dir *D, int nsrc, int ndst, int E, const int *src, const int *dst, const float *feat,
                             const int *dst_start, const int *dst_edges, const int *src_start, const int *src_edges, int *src_of,
                             int *dst_of, int *src_pos, float *dfeat, int *inv)
{
    int k;
    for (k = 0; k < E; k++) {
        int e = dst_edges[k];
        inv[e] = k;
        src_of[k] = src[e];
        dst_of[k] = dst[e];
        memcpy(dfeat + (size_t)k * TN__GNN_F, feat + (size_t)e * TN__GNN_F, TN__GNN_F * sizeof(float));
    }
    for (k = 0; k < E; k++) src_pos[k] = inv[src_edges[k]];
    D->nsrc = nsrc;
    D->ndst = ndst;
    D->E = E;
    D->dst_start = dst_start;
    D->src_of = src_of;
    D->dst_of = dst_of;
    D->feat = dfeat;
    D->src_start = src_start;
    D->src_pos = src_pos;
}

static void tn__gnn_graph_finish(tn__gnn_graph *g)
{
    int *I = g->ints;
    size_t c = (size_t)g->cap;
    tn__gnn_csr(g->e_pix, g->E, g->npix, g->pix_start, g->pix_edges);
    tn__gnn_csr(g->e_part, g->E, g->nparts, g->part_start, g->part_edges);
    tn__gnn_dir_make(&g->g2p, g->npix, g->nparts, g->E, g->e_pix, g->e_part, g->feat, g->part_start, g->part_edges, g->pix_start,
                     g->pix_edges, I, I + c, I + 2 * c, g->feats, I + 6 * c);
    tn__gnn_dir_make(&g->p2g, g->nparts, g->npix, g->E, g->e_part, g->e_pix, g->feat, g->pix_start, g->pix_edges, g->part_start,
                     g->part_edges, I + 3 * c, I + 4 * c, I + 5 * c, g->feats + c * TN__GNN_F, I + 6 * c);
}

/* ---- fused graph ops ---- */

/* Attention aggregation: for every destination d,
       h_e = relu(U[src_e] + V[d] + Wc feat_e),  s_e = a . h_e,  alpha = softmax over d's edges,
       Y[d] = sum_e alpha_e h_e  (0 for a destination without edges).
   U: nsrc x H, V: ndst x H, Wc: H x F, a: H. The forward keeps only alpha (E floats); the
   backward recomputes h_e. */
/* SIMD over the hidden axis (the tn__vf layer of >>imageops plus max and mask); a scalar tail
   handles widths that are not a multiple of the vector. */
#if TN__VF_N == 16
#define tn__gnn_relu_v(z) _mm512_max_ps((z), _mm512_setzero_ps())
#define tn__gnn_ifpos_v(h, v) _mm512_maskz_mov_ps(_mm512_cmp_ps_mask((h), _mm512_setzero_ps(), _CMP_GT_OQ), (v))
#elif TN__VF_N == 8
#define tn__gnn_relu_v(z) _mm256_max_ps((z), _mm256_setzero_ps())
#define tn__gnn_ifpos_v(h, v) _mm256_and_ps(_mm256_cmp_ps((h), _mm256_setzero_ps(), _CMP_GT_OQ), (v))
#else
#define tn__gnn_relu_v(z) ((z) > 0 ? (z) : 0.0f)
#define tn__gnn_ifpos_v(h, v) ((h) > 0 ? (v) : 0.0f)
#endif

/* sum of the lanes, in a fixed order */
static inline float tn__gnn_hsum(tn__vf v)
{
    float lanes[TN__VF_N], s = 0;
    int l;
    tn__vf_store(lanes, v);
    for (l = 0; l < TN__VF_N; l++) s += lanes[l];
    return s;
}

/* y[i] = a * x[i] + y[i] */
static inline void tn__gnn_axpy(float a, const float *x, float *y, int n)
{
    tn__vf va = tn__vf_set1(a);
    int i = 0;
    for (; i + TN__VF_N <= n; i += TN__VF_N) tn__vf_store(y + i, tn__vf_madd(va, tn__vf_load(x + i), tn__vf_load(y + i)));
    for (; i < n; i++) y[i] += a * x[i];
}

typedef struct tn__gnn_att {
    const tn__gnn_dir *g;
    const float *U, *V, *WcT, *a, *dY;   /* WcT: F x H, so the per-edge loop runs along H */
    float *Y, *alpha, *dots, *dz, *dU, *dV, *da_rows, *dw_rows;
    int H;
} tn__gnn_att;

/* h = relu(U[src] + V[d] + Wc f) of the edge at position k into h; returns dot(w_dot, h). */
static inline float tn__gnn_att_h(const tn__gnn_att *J, int k, int d, const float *w_dot, float *h)
{
    const float *u = J->U + (size_t)J->g->src_of[k] * J->H, *v = J->V + (size_t)d * J->H, *f = J->g->feat + (size_t)k * TN__GNN_F;
    const float *w = J->WcT;
    int i = 0, H = J->H;
    float s;
    tn__vf f0 = tn__vf_set1(f[0]), f1 = tn__vf_set1(f[1]), f2 = tn__vf_set1(f[2]), f3 = tn__vf_set1(f[3]), f4 = tn__vf_set1(f[4]);
    tn__vf acc = tn__vf_set1(0.0f);
    for (; i + TN__VF_N <= H; i += TN__VF_N) {
        tn__vf z = tn__vf_add(tn__vf_load(u + i), tn__vf_load(v + i));
        z = tn__vf_madd(f0, tn__vf_load(w + i), z);
        z = tn__vf_madd(f1, tn__vf_load(w + H + i), z);
        z = tn__vf_madd(f2, tn__vf_load(w + 2 * H + i), z);
        z = tn__vf_madd(f3, tn__vf_load(w + 3 * H + i), z);
        z = tn__vf_madd(f4, tn__vf_load(w + 4 * H + i), z);
        z = tn__gnn_relu_v(z);
        tn__vf_store(h + i, z);
        acc = tn__vf_madd(z, tn__vf_load(w_dot + i), acc);
    }
    s = tn__gnn_hsum(acc);
    for (; i < H; i++) {
        float z = u[i] + v[i] + f[0] * w[i] + f[1] * w[H + i] + f[2] * w[2 * H + i] + f[3] * w[3 * H + i] + f[4] * w[4 * H + i];
        h[i] = z > 0 ? z : 0.0f;
        s += h[i] * w_dot[i];
    }
    return s;
}

static void tn__gnn_att_fwd(void *vj, size_t b, size_t end)
{
    const tn__gnn_att *J = (const tn__gnn_att *)vj;
    float h[TN__GNN_MAXH], acc[TN__GNN_MAXH];
    int H = J->H, i;
    size_t d;
    for (d = b; d < end; d++) {
        int k0 = J->g->dst_start[d], k1 = J->g->dst_start[d + 1], k;
        float m = -FLT_MAX, sum = 0, *y = J->Y + d * H;
        for (i = 0; i < H; i++) acc[i] = 0;
        for (k = k0; k < k1; k++) {
            float s = tn__gnn_att_h(J, k, (int)d, J->a, h), w;
            if (J->alpha) J->alpha[k] = s;
            if (s > m) { /* online softmax: rescale what was summed so far */
                float r = k == k0 ? 0.0f : expf(m - s);
                for (i = 0; i < H; i++) acc[i] *= r;
                sum *= r;
                m = s;
            }
            w = expf(s - m);
            sum += w;
            tn__gnn_axpy(w, h, acc, H);
        }
        for (i = 0; i < H; i++) y[i] = k1 > k0 ? acc[i] / sum : 0.0f;
        if (J->alpha)
            for (k = k0; k < k1; k++) J->alpha[k] = expf(J->alpha[k] - m) / sum;
    }
}

/* Per destination: h recomputed into the dz rows, then turned into dz in place; the
   destination's shares of da and dWc go to its own rows (summed serially afterwards). */
static void tn__gnn_att_bwd_dst(void *vj, size_t b, size_t end)
{
    const tn__gnn_att *J = (const tn__gnn_att *)vj;
    int H = J->H, i, j;
    size_t d;
    for (d = b; d < end; d++) {
        int k0 = J->g->dst_start[d], k1 = J->g->dst_start[d + 1], k;
        const float *g = J->dY + d * H, *a = J->a;
        float *dv = J->dV ? J->dV + d * H : J->da_rows + d * H, *dar = J->da_rows + d * H, *dwr = J->dw_rows + d * H * TN__GNN_F, mean = 0;
        for (i = 0; i < H; i++) dar[i] = 0;
        for (i = 0; i < H * TN__GNN_F; i++) dwr[i] = 0;
        for (k = k0; k < k1; k++) {
            J->dots[k] = tn__gnn_att_h(J, k, (int)d, g, J->dz + (size_t)k * H);
            mean += J->alpha[k] * J->dots[k];
        }
        for (k = k0; k < k1; k++) {
            float al = J->alpha[k], ds = al * (J->dots[k] - mean), *dz = J->dz + (size_t)k * H;
            const float *f = J->g->feat + (size_t)k * TN__GNN_F;
            tn__vf val = tn__vf_set1(al), vds = tn__vf_set1(ds), f0 = tn__vf_set1(f[0]), f1 = tn__vf_set1(f[1]), f2 = tn__vf_set1(f[2]);
            tn__vf f3 = tn__vf_set1(f[3]), f4 = tn__vf_set1(f[4]);
            for (i = 0; i + TN__VF_N <= H; i += TN__VF_N) {
                tn__vf hv = tn__vf_load(dz + i), z;
                tn__vf_store(dar + i, tn__vf_madd(vds, hv, tn__vf_load(dar + i)));
                z = tn__gnn_ifpos_v(hv, tn__vf_madd(val, tn__vf_load(g + i), tn__vf_mul(vds, tn__vf_load(a + i))));
                tn__vf_store(dz + i, z);
                if (J->dV) tn__vf_store(dv + i, tn__vf_add(tn__vf_load(dv + i), z));
                tn__vf_store(dwr + i, tn__vf_madd(f0, z, tn__vf_load(dwr + i)));
                tn__vf_store(dwr + H + i, tn__vf_madd(f1, z, tn__vf_load(dwr + H + i)));
                tn__vf_store(dwr + 2 * H + i, tn__vf_madd(f2, z, tn__vf_load(dwr + 2 * H + i)));
                tn__vf_store(dwr + 3 * H + i, tn__vf_madd(f3, z, tn__vf_load(dwr + 3 * H + i)));
                tn__vf_store(dwr + 4 * H + i, tn__vf_madd(f4, z, tn__vf_load(dwr + 4 * H + i)));
            }
            for (; i < H; i++) {
                float hv = dz[i];
                dar[i] += ds * hv;
                dz[i] = hv > 0 ? al * g[i] + ds * a[i] : 0.0f;
                if (J->dV) dv[i] += dz[i];
                for (j = 0; j < TN__GNN_F; j++) dwr[(size_t)j * H + i] += f[j] * dz[i];
            }
        }
    }
}

static void tn__gnn_att_bwd_src(void *vj, size_t b, size_t end)
{
    const tn__gnn_att *J = (const tn__gnn_att *)vj;
    size_t s;
    for (s = b; s < end; s++) {
        int k;
        float *du = J->dU + s * J->H;
        for (k = J->g->src_start[s]; k < J->g->src_start[s + 1]; k++) tn__gnn_axpy(1.0f, J->dz + (size_t)J->g->src_pos[k] * J->H, du, J->H);
    }
}

static float *tn__gnn_transpose_wc(tn_ctx *ctx, const tn_tensor *Wc)
{
    int H = Wc->shape[0], i, j;
    float *t = tn__ctx_floats(ctx, (size_t)H * TN__GNN_F, 0);
    if (t)
        for (i = 0; i < H; i++)
            for (j = 0; j < TN__GNN_F; j++) t[(size_t)j * H + i] = Wc->data[(size_t)i * TN__GNN_F + j];
    return t;
}

static void tn__gnn_attend_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *U = out->src[0], *V = out->src[1], *Wc = out->src[2], *a = out->src[3];
    tn__gnn_att J;
    const tn__gnn_dir *g = (const tn__gnn_dir *)out->aux;
    int H = out->shape[1], E = g->E, i, j;
    size_t d;
    memset(&J, 0, sizeof J);
    J.g = g;
    J.H = H;
    J.U = U->data;
    J.V = V->data;
    J.WcT = tn__gnn_transpose_wc(ctx, Wc);
    J.a = a->data;
    J.dY = out->grad;
    memcpy(&J.alpha, (char *)out->aux + sizeof(tn__gnn_dir), sizeof(float *));
    J.dz = tn__ctx_floats(ctx, (size_t)(E > 0 ? E : 1) * H, 0);
    J.dots = tn__ctx_floats(ctx, (size_t)(E > 0 ? E : 1), 0);
    J.da_rows = tn__ctx_floats(ctx, (size_t)g->ndst * H, 0);
    J.dw_rows = tn__ctx_floats(ctx, (size_t)g->ndst * H * TN__GNN_F, 0);
    J.dV = V->requires_grad ? tn__grad(ctx, V) : NULL;
    J.dU = U->requires_grad ? tn__grad(ctx, U) : NULL;
    if (!J.WcT || !J.dz || !J.dots || !J.da_rows || !J.dw_rows || (a->requires_grad && !tn__grad(ctx, a)) ||
        (Wc->requires_grad && !tn__grad(ctx, Wc)))
        return;
    if ((V->requires_grad && !J.dV) || (U->requires_grad && !J.dU)) return;
    tn_parallel_for((size_t)g->ndst, 64, tn__gnn_att_bwd_dst, &J);
    if (J.dU) tn_parallel_for((size_t)g->nsrc, 64, tn__gnn_att_bwd_src, &J);
    for (d = 0; d < (size_t)g->ndst; d++) {
        if (a->requires_grad) tn__gnn_axpy(1.0f, J.da_rows + d * H, a->grad, H);
        if (Wc->requires_grad) /* dWc is H x F; the rows hold F x H */
            for (j = 0; j < TN__GNN_F; j++)
                for (i = 0; i < H; i++) Wc->grad[(size_t)i * TN__GNN_F + j] += J.dw_rows[(d * TN__GNN_F + j) * H + i];
    }
}

static tn_tensor *tn__gnn_attend(tn_ctx *ctx, tn_tensor *U, tn_tensor *V, tn_tensor *Wc, tn_tensor *a, const tn__gnn_dir *g)
{
    tn__gnn_att J;
    tn_tensor *o;
    int shape[2], H, E;
    void *aux;
    if (!U || !V || !Wc || !a) return NULL;
    H = U->shape[1];
    TN_ASSERT(H <= TN__GNN_MAXH && V->shape[1] == H && U->shape[0] == g->nsrc && V->shape[0] == g->ndst);
    TN_ASSERT(Wc->shape[0] == H && Wc->shape[1] == TN__GNN_F && (int)a->numel == H);
    E = g->E;
    shape[0] = g->ndst;
    shape[1] = H;
    /* a is a parameter of the same set as Wc: it needs a gradient only when Wc does */
    o = tn__op_make(ctx, 2, shape, tn__gnn_attend_backward, U, V, Wc, 0);
    if (!o) return NULL;
    o->src[3] = a;
    memset(&J, 0, sizeof J);
    J.g = g;
    J.H = H;
    J.U = U->data;
    J.V = V->data;
    J.WcT = tn__gnn_transpose_wc(ctx, Wc);
    J.a = a->data;
    J.Y = o->data;
    if (!J.WcT) return NULL;
    if (o->backward) { /* the backward needs the directions and the attention weights */
        aux = tn_ctx_alloc(ctx, sizeof(tn__gnn_dir) + sizeof(float *));
        J.alpha = tn__ctx_floats(ctx, (size_t)(E > 0 ? E : 1), 0);
        if (!aux || !J.alpha) return NULL;
        memcpy(aux, g, sizeof *g);
        memcpy((char *)aux + sizeof(tn__gnn_dir), &J.alpha, sizeof(float *));
        o->aux = aux;
    }
    tn_parallel_for((size_t)g->ndst, 64, tn__gnn_att_fwd, &J);
    return o;
}

/* Mean aggregation: Y[d] = mean of X[src_e] over d's edges (0 without edges). */
typedef struct tn__gnn_mean_job {
    const tn__gnn_dir *g;
    const float *X, *dY;
    float *Y, *dX;
    int H;
} tn__gnn_mean_job;

static void tn__gnn_mean_fwd(void *vj, size_t b, size_t end)
{
    const tn__gnn_mean_job *J = (const tn__gnn_mean_job *)vj;
    size_t d;
    int i;
    for (d = b; d < end; d++) {
        int k0 = J->g->dst_start[d], k1 = J->g->dst_start[d + 1], k;
        float *y = J->Y + d * J->H, inv = k1 > k0 ? 1.0f / (float)(k1 - k0) : 0.0f;
        for (i = 0; i < J->H; i++) y[i] = 0;
        for (k = k0; k < k1; k++) {
            const float *x = J->X + (size_t)J->g->src_of[k] * J->H;
            for (i = 0; i < J->H; i++) y[i] += x[i];
        }
        for (i = 0; i < J->H; i++) y[i] *= inv;
    }
}

static void tn__gnn_mean_bwd(void *vj, size_t b, size_t end)
{
    const tn__gnn_mean_job *J = (const tn__gnn_mean_job *)vj;
    size_t s;
    int i;
    for (s = b; s < end; s++) {
        int k;
        float *dx = J->dX + s * J->H;
        for (k = J->g->src_start[s]; k < J->g->src_start[s + 1]; k++) {
            int d = J->g->dst_of[J->g->src_pos[k]];
            float inv = 1.0f / (float)(J->g->dst_start[d + 1] - J->g->dst_start[d]);
            const float *dy = J->dY + (size_t)d * J->H;
            for (i = 0; i < J->H; i++) dx[i] += inv * dy[i];
        }
    }
}

static void tn__gnn_mean_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    tn__gnn_mean_job J;
    memset(&J, 0, sizeof J);
    J.g = (const tn__gnn_dir *)out->aux;
    J.H = out->shape[1];
    J.dY = out->grad;
    if (!(J.dX = tn__grad(ctx, x))) return;
    tn_parallel_for((size_t)J.g->nsrc, 64, tn__gnn_mean_bwd, &J);
}

static tn_tensor *tn__gnn_mean(tn_ctx *ctx, tn_tensor *x, const tn__gnn_dir *g)
{
    tn__gnn_mean_job J;
    tn_tensor *o;
    int shape[2];
    if (!x) return NULL;
    TN_ASSERT(x->ndim == 2 && x->shape[0] == g->nsrc);
    shape[0] = g->ndst;
    shape[1] = x->shape[1];
    o = tn__op_make(ctx, 2, shape, tn__gnn_mean_backward, x, NULL, NULL, 0);
    if (!o) return NULL;
    if (o->backward) {
        void *aux = tn_ctx_alloc(ctx, sizeof *g);
        if (!aux) return NULL;
        memcpy(aux, g, sizeof *g);
        o->aux = aux;
    }
    memset(&J, 0, sizeof J);
    J.g = g;
    J.X = x->data;
    J.Y = o->data;
    J.H = x->shape[1];
    tn_parallel_for((size_t)g->ndst, 64, tn__gnn_mean_fwd, &J);
    return o;
}

/* ---- the network ---- */

typedef struct tn__gnn_arch {
    int hidden, rounds, k, embed, membrane, parts, width, height, npts;
    float mean, std, lo, hi, part_noise;
} tn__gnn_arch;

static tn_status tn__gnn_linear_add(tn_params *p, const char *name, int in, int out, tn_rng *rng)
{
    int w[2];
    w[0] = in;
    w[1] = out;
    return tn_mlp_add(p, name, w, 1, rng);
}

/* Every learned tensor of the network (not the embeddings). */
static tn_status tn__gnn_add_net(tn_params *p, const tn__gnn_arch *A, tn_rng *rng)
{
    int H = A->hidden, D = A->embed, t, wi[3], wc[2];
    char name[40];
    tn_status st;
    tn_tensor *x;
    wi[0] = 2; wi[1] = H; wi[2] = H;
    if ((st = tn_mlp_add(p, "gnn.init.", wi, 2, rng))) return st;
    wc[0] = H;
    wc[1] = TN__GNN_F;
    for (t = 0; t < A->rounds; t++) {
        int side;
        for (side = 0; side < 2; side++) {
            char c = side ? 's' : 'g';
            /* u: the sender's row, v: the receiver's; gather senders are pixels [f, mean E],
               receivers parts [E, sign, emb]; scatter senders are parts [E, sign, emb, mean f],
               receivers pixels [f] */
            snprintf(name, sizeof name, "gnn.%d%c.u.", t, c);
            if ((st = tn__gnn_linear_add(p, name, side ? 2 * H + 1 + D : 2 * H, H, rng))) return st;
            snprintf(name, sizeof name, "gnn.%d%c.v.", t, c);
            if ((st = tn__gnn_linear_add(p, name, side ? H : H + 1 + D, H, rng))) return st;
            snprintf(name, sizeof name, "gnn.%d%c.cw", t, c);
            if (!(x = tn_params_add(p, name, 2, wc))) return TN_ERR_OUT_OF_MEMORY;
            if (rng) tn_init_kaiming(x, rng, 1.41f);
            snprintf(name, sizeof name, "gnn.%d%c.a", t, c);
            if (!(x = tn_params_add(p, name, 1, &H))) return TN_ERR_OUT_OF_MEMORY;
            if (rng) tn_init_normal(x, rng, 0.0f, 0.1f);
            snprintf(name, sizeof name, "gnn.%d%c.o.", t, c);
            if ((st = tn__gnn_linear_add(p, name, H, H, rng))) return st;
            /* residual branches start small so the first steps do not scramble the states */
            snprintf(name, sizeof name, "gnn.%d%c.o.w0", t, c);
            if (rng && (x = tn_params_find(p, name))) {
                size_t i;
                for (i = 0; i < x->numel; i++) x->data[i] *= 0.3f;
            }
        }
    }
    wi[0] = H; wi[1] = H; wi[2] = 1;
    if ((st = tn_mlp_add(p, "gnn.out.", wi, 2, rng))) return st;
    if (rng && (x = tn_params_find(p, "gnn.out.w1"))) { /* start at the baseline */
        size_t i;
        for (i = 0; i < x->numel; i++) x->data[i] *= 0.1f;
    }
    return TN_OK;
}

static tn_tensor *tn__gnn_param(const tn_params *p, const char *fmt, int t, char c)
{
    char name[40];
    snprintf(name, sizeof name, fmt, t, c);
    return tn_params_find(p, name);
}

static tn_tensor *tn__gnn_lin(tn_ctx *ctx, const tn_params *p, int t, char c, const char *which, tn_tensor *x)
{
    char name[40];
    snprintf(name, sizeof name, "gnn.%d%c.%s.", t, c, which);
    return tn_mlp(ctx, p, name, 1, x, TN_ACT_NONE);
}

/* Inputs of one forward pass. */
typedef struct tn__gnn_in {
    const tn__gnn_graph *g;
    tn_tensor *pix_in;    /* npix x 2: type, baseline height */
    tn_tensor *part_in;   /* nparts x (1 + D): sign, embedding */
    tn_tensor *E0;        /* nparts x H */
    tn_tensor *base;      /* npix x 1 baseline (zeros without membrane) */
} tn__gnn_in;

/* The prediction (npix x 1, normalised heights). */
static tn_tensor *tn__gnn_forward(tn_ctx *ctx, const tn_params *w, const tn__gnn_arch *A, const tn__gnn_in *in)
{
    const tn__gnn_graph *g = in->g;
    tn_tensor *f = tn_mlp(ctx, w, "gnn.init.", 2, in->pix_in, TN_ACT_RELU), *E = in->E0, *r;
    int t;
    for (t = 0; t < A->rounds && f && E; t++) {
        tn_tensor *pn, *U, *V, *Y;
        /* gather: pixels -> parts */
        U = tn__gnn_lin(ctx, w, t, 'g', "u", tn_concat(ctx, f, tn__gnn_mean(ctx, E, &g->p2g), 1));
        pn = tn_concat(ctx, E, in->part_in, 1);
        V = tn__gnn_lin(ctx, w, t, 'g', "v", pn);
        Y = tn__gnn_attend(ctx, U, V, tn__gnn_param(w, "gnn.%d%c.cw", t, 'g'), tn__gnn_param(w, "gnn.%d%c.a", t, 'g'), &g->g2p);
        E = tn_add(ctx, E, tn__gnn_lin(ctx, w, t, 'g', "o", Y));
        /* scatter: parts -> pixels */
        pn = tn_concat(ctx, tn_concat(ctx, E, in->part_in, 1), tn__gnn_mean(ctx, f, &g->g2p), 1);
        U = tn__gnn_lin(ctx, w, t, 's', "u", pn);
        V = tn__gnn_lin(ctx, w, t, 's', "v", f);
        Y = tn__gnn_attend(ctx, U, V, tn__gnn_param(w, "gnn.%d%c.cw", t, 's'), tn__gnn_param(w, "gnn.%d%c.a", t, 's'), &g->p2g);
        f = tn_add(ctx, f, tn__gnn_lin(ctx, w, t, 's', "o", Y));
    }
    r = tn_mlp(ctx, w, "gnn.out.", 2, f, TN_ACT_RELU);
    return tn_add(ctx, r, in->base);
}

/* Node inputs shared by training and generation: pixel (type, baseline) rows, baseline column,
   part (sign, embedding) rows. emb: nparts x D. */
static tn_status tn__gnn_inputs(tn_ctx *ctx, const tn__gnn_graph *g, const float *type, const float *base, const float *sign,
                                tn_tensor *emb, tn__gnn_in *in)
{
    tn_tensor *s;
    int i;
    memset(in, 0, sizeof *in);
    in->g = g;
    in->pix_in = tn_tensor_2d(ctx, g->npix, 2);
    in->base = tn_tensor_2d(ctx, g->npix, 1);
    s = tn_tensor_2d(ctx, g->nparts, 1);
    if (!in->pix_in || !in->base || !s) return tn_ctx_status(ctx);
    for (i = 0; i < g->npix; i++) {
        in->pix_in->data[2 * i] = type[i];
        in->pix_in->data[2 * i + 1] = base ? base[i] : 0.0f;
        in->base->data[i] = base ? base[i] : 0.0f;
    }
    for (i = 0; i < g->nparts; i++) s->data[i] = sign[i];
    in->part_in = tn_concat(ctx, s, emb, 1);
    return in->part_in ? TN_OK : tn_ctx_status(ctx);
}

/* ---- configuration tensor ---- */

static void tn__gnn_write_config(const tn__gnn_arch *A, float *c)
{
    memset(c, 0, TN__GNN_CONFIG * sizeof(float));
    c[0] = TN__GNN_FORMAT;
    c[1] = (float)A->hidden;
    c[2] = (float)A->rounds;
    c[3] = (float)A->k;
    c[4] = (float)A->embed;
    c[5] = (float)A->membrane;
    c[6] = (float)A->parts;
    c[7] = (float)A->width;
    c[8] = (float)A->height;
    c[9] = A->mean;
    c[10] = A->std;
    c[11] = A->lo;
    c[12] = A->hi;
    c[13] = A->part_noise;
    c[14] = (float)A->npts;
    c[15] = TN__GNN_F;
}

static int tn__gnn_whole(float v, float lo, float hi) { return v >= lo && v <= hi && v == floorf(v); }

/* Every field range-checked: a damaged file fails here, not in an allocation or an index. */
static tn_status tn__gnn_read_config(const float *c, tn__gnn_arch *A, const char *name)
{
    memset(A, 0, sizeof *A);
    if (!tn__gnn_whole(c[0], 1, 1e6) || c[0] > TN__GNN_FORMAT)
        return tn__fail(TN_ERR_FORMAT, "%s: gnn configuration format %g is not supported", name, (double)c[0]);
    if (!tn__gnn_whole(c[1], 1, TN__GNN_MAXH) || !tn__gnn_whole(c[2], 1, 16) || !tn__gnn_whole(c[3], 1, 64) ||
        !tn__gnn_whole(c[4], 1, 256) || !tn__gnn_whole(c[5], 0, 1) || !tn__gnn_whole(c[6], 1, 1 << 24) ||
        !tn__gnn_whole(c[7], 16, TN_SKETCH_MAX_SIDE) || !tn__gnn_whole(c[8], 16, TN_SKETCH_MAX_SIDE) || !isfinite(c[9]) ||
        !(c[10] > 0) || !isfinite(c[10]) || !isfinite(c[11]) || !isfinite(c[12]) || !(c[13] >= 0 && c[13] <= 100) ||
        !tn__gnn_whole(c[14], 5, 1 << 26) || c[15] != TN__GNN_F)
        return tn__fail(TN_ERR_CORRUPT, "%s: damaged gnn configuration", name);
    A->hidden = (int)c[1];
    A->rounds = (int)c[2];
    A->k = (int)c[3];
    A->embed = (int)c[4];
    A->membrane = (int)c[5];
    A->parts = (int)c[6];
    A->width = (int)c[7];
    A->height = (int)c[8];
    A->mean = c[9];
    A->std = c[10];
    A->lo = c[11];
    A->hi = c[12];
    A->part_noise = c[13];
    A->npts = (int)c[14];
    return TN_OK;
}

/* The model's tensors: config, parts (buffers), embeddings and the network. */
static tn_status tn__gnn_model_params(const tn__gnn_arch *A, tn_rng *rng, tn_params **out)
{
    tn_params *p = tn_params_create();
    int s[2], nc = TN__GNN_CONFIG;
    tn_tensor *t;
    tn_status st = TN_OK;
    *out = NULL;
    if (!p) return tn__fail(TN_ERR_OUT_OF_MEMORY, "gnn: out of memory");
    if (!(t = tn_params_add_buffer(p, "gnn.config", 1, &nc))) st = TN_ERR_OUT_OF_MEMORY;
    if (!st) tn__gnn_write_config(A, t->data);
    s[0] = A->npts;
    s[1] = 3;
    if (!st && !tn_params_add_buffer(p, "gnn.part_pts", 2, s)) st = TN_ERR_OUT_OF_MEMORY;
    s[0] = A->parts;
    s[1] = 4;
    if (!st && !tn_params_add_buffer(p, "gnn.part_info", 2, s)) st = TN_ERR_OUT_OF_MEMORY;
    s[1] = A->embed;
    if (!st && !(t = tn_params_add(p, "gnn.emb", 2, s))) st = TN_ERR_OUT_OF_MEMORY;
    if (!st && rng) tn_init_normal(t, rng, 0.0f, 1.0f);
    if (!st) st = tn__gnn_add_net(p, A, rng);
    if (st) {
        tn_params_free(p);
        return tn__fail(st, "gnn: cannot build the network (%s)", tn_status_string(st));
    }
    *out = p;
    return TN_OK;
}

/* Stored parts (example units) -> contour set. */
static tn_status tn__gnn_stored_parts(const tn_params *w, const tn__gnn_arch *A, const char *name, tn_contour_set *out)
{
    const tn_tensor *pts = tn_params_find(w, "gnn.part_pts"), *info = tn_params_find(w, "gnn.part_info");
    tn_contour_set set;
    int i, off = 0;
    memset(&set, 0, sizeof set);
    if (!pts || !info || (int)pts->numel != 3 * A->npts || (int)info->numel != 4 * A->parts)
        return tn__fail(TN_ERR_CORRUPT, "%s: gnn parts missing or of the wrong size", name);
    for (i = 0; i < A->parts; i++) {
        float ty = info->data[4 * i], np = info->data[4 * i + 1];
        if ((ty != 0 && ty != 1) || !tn__gnn_whole(np, 1, (float)(A->npts - off)) || !tn__gnn_whole(info->data[4 * i + 2], 0, 1000) ||
            !isfinite(info->data[4 * i + 3]))
            return tn__fail(TN_ERR_CORRUPT, "%s: gnn part %d is damaged", name, i);
        off += (int)np;
    }
    if (off != A->npts) return tn__fail(TN_ERR_CORRUPT, "%s: gnn parts hold %d points, the configuration says %d", name, off, A->npts);
    for (i = 0; i < 3 * A->npts; i++)
        if (!isfinite(pts->data[i]) || (i % 3 != 2 && fabsf(pts->data[i]) > (float)(2 * TN_SKETCH_MAX_SIDE)))
            return tn__fail(TN_ERR_CORRUPT, "%s: gnn part point %d is damaged", name, i / 3);
    set.width = A->width;
    set.height = A->height;
    set.count = A->parts;
    if (!(set.items = (tn_contour *)tn__calloc((size_t)A->parts * sizeof(tn_contour)))) return TN_ERR_OUT_OF_MEMORY;
    for (i = 0, off = 0; i < A->parts; i++) {
        tn_contour *c = &set.items[i];
        c->type = info->data[4 * i] == 1 ? TN_RIDGE : TN_VALLEY;
        c->npoints = (int)info->data[4 * i + 1];
        c->order = (int)info->data[4 * i + 2];
        c->mean_gradient = info->data[4 * i + 3];
        if (!(c->points = (float *)tn__alloc((size_t)c->npoints * 3 * sizeof(float)))) {
            tn_contour_set_free(&set);
            return TN_ERR_OUT_OF_MEMORY;
        }
        memcpy(c->points, pts->data + (size_t)off * 3, (size_t)c->npoints * 3 * sizeof(float));
        off += c->npoints;
    }
    *out = set;
    return TN_OK;
}

static void tn__gnn_store_parts(tn_params *w, const tn_contour_set *parts)
{
    float *pts = tn_params_find(w, "gnn.part_pts")->data, *info = tn_params_find(w, "gnn.part_info")->data;
    int i, off = 0;
    for (i = 0; i < parts->count; i++) {
        const tn_contour *c = &parts->items[i];
        info[4 * i] = c->type == TN_RIDGE ? 1.0f : 0.0f;
        info[4 * i + 1] = (float)c->npoints;
        info[4 * i + 2] = (float)c->order;
        info[4 * i + 3] = c->mean_gradient;
        memcpy(pts + (size_t)off * 3, c->points, (size_t)c->npoints * 3 * sizeof(float));
        off += c->npoints;
    }
}

static void tn__gnn_model_fields(tn_gnn *m, const tn__gnn_arch *A)
{
    m->hidden = A->hidden;
    m->rounds = A->rounds;
    m->k = A->k;
    m->embed = A->embed;
    m->membrane = A->membrane;
    m->parts = A->parts;
    m->width = A->width;
    m->height = A->height;
    m->mean = A->mean;
    m->std = A->std;
    m->lo = A->lo;
    m->hi = A->hi;
    m->part_noise = A->part_noise;
}

static tn_status tn__gnn_arch_of(const tn_gnn *m, tn__gnn_arch *A)
{
    const tn_tensor *c;
    if (!m || !m->weights || !(c = tn_params_find(m->weights, "gnn.config")) || c->numel != TN__GNN_CONFIG)
        return tn__fail(TN_ERR_INVALID_ARG, "gnn: no model");
    return tn__gnn_read_config(c->data, A, "gnn model");
}

/* ---- training ---- */

/* One sketch density of the example: its network's parts, pixel types, baseline and fixed
   edges. Level 0 is the example's own network (its parts own the embeddings); the sparser
   levels are the example's networks at higher extraction thresholds, trained without
   embeddings, so the network also learns to fill what a sparse sketch leaves out. */
typedef struct tn__gnn_level {
    tn__gnn_parts P;
    int *nbr;                  /* npix x k parts */
    float *nfeat;              /* their features */
    float *type, *base;        /* per pixel: +1 / -1 / 0, baseline (normalised) */
} tn__gnn_level;

typedef struct tn__gnn_train {
    tn__gnn_arch A;
    tn_gnn_opts o;
    tn_params *w;
    tn_optim *opt;
    tn_train *run;
    tn_rng rng;
    tn__gnn_level lv[TN__GNN_MAX_LEVELS];
    tn__gnn_level thinned;     /* this step's thinned sparse level */
    int nlevels, maxparts, npix;
    float *target;
    uint8_t *masked;
    tn__gnn_graph g;
    float range;               /* normalised height range (SSIM data range) */
} tn__gnn_train;

static void tn__gnn_level_free(tn__gnn_level *L)
{
    tn__gnn_parts_free(&L->P);
    TN_FREE(L->nbr);
    TN_FREE(L->nfeat);
    TN_FREE(L->type);
    TN_FREE(L->base);
    memset(L, 0, sizeof *L);
}

static void tn__gnn_train_free(tn__gnn_train *s)
{
    int i;
    tn_train_free(s->run);
    tn_optim_free(s->opt);
    tn_params_free(s->w);
    for (i = 0; i < TN__GNN_MAX_LEVELS; i++) tn__gnn_level_free(&s->lv[i]);
    tn__gnn_level_free(&s->thinned);
    TN_FREE(s->target);
    TN_FREE(s->masked);
    tn__gnn_graph_free(&s->g);
}

/* A level from the example's polylines and their parts. */
static tn_status tn__gnn_level_make(const tn__gnn_arch *A, const tn_contour_set *lines, const tn_contour_set *parts, tn__gnn_level *L)
{
    size_t n = (size_t)A->width * A->height, i;
    float *hgt;
    tn_status st;
    memset(L, 0, sizeof *L);
    L->type = (float *)tn__alloc(n * sizeof(float));
    L->base = (float *)tn__alloc(n * sizeof(float));
    hgt = (float *)tn__alloc(n * sizeof(float));
    if (!L->type || !L->base || !hgt) {
        TN_FREE(hgt);
        return TN_ERR_OUT_OF_MEMORY;
    }
    st = tn__gnn_sketch_pixels(lines, A->width, A->height, L->type, hgt, L->base);
    TN_FREE(hgt);
    if (st) return st;
    for (i = 0; i < n; i++) L->base[i] = A->membrane ? (L->base[i] - A->mean) / A->std : 0.0f;
    if ((st = tn__gnn_parts_make(parts, A->mean, A->std, &L->P))) return st;
    return tn__gnn_knn(&L->P, A->width, A->height, A->k, L->base, &L->nbr, &L->nfeat);
}

/* A random thinning of sparse level L into T: each part kept with probability 1 - q, q uniform
   in [0, thin); the sketch pixels are the kept parts' points, so the membrane and the nearest
   parts are rebuilt (700-step runs at 128^2 took 6 % longer with it). */
static tn_status tn__gnn_level_thin(tn__gnn_train *s, const tn__gnn_level *L, tn__gnn_level *T)
{
    const tn__gnn_parts *P = &L->P;
    int W = s->A.width, H = s->A.height, i, j, n = 0, m = 0, kept = 0;
    float q = s->o.thin * tn_rng_uniform(&s->rng);
    size_t npix = (size_t)W * H;
    uint8_t *fixed;
    float *hgt;
    tn_status st = TN_OK;
    tn__gnn_level_free(T);
    for (i = 0; i < P->n; i++) {
        s->masked[i] = (uint8_t)(tn_rng_uniform(&s->rng) < q);
        kept += !s->masked[i];
    }
    if (!kept) s->masked[0] = 0;
    T->type = (float *)tn__calloc(npix * sizeof(float));
    T->base = (float *)tn__alloc(npix * sizeof(float));
    T->P.start = (int *)tn__alloc(((size_t)P->n + 1) * sizeof(int));
    T->P.of = (int *)tn__alloc(((size_t)P->npts + 1) * sizeof(int));
    T->P.pts = (float *)tn__alloc(((size_t)P->npts + 1) * 3 * sizeof(float));
    T->P.sign = (float *)tn__alloc(((size_t)P->n + 1) * sizeof(float));
    fixed = (uint8_t *)tn__calloc(npix);
    hgt = (float *)tn__calloc(npix * sizeof(float));
    if (!T->type || !T->base || !T->P.start || !T->P.of || !T->P.pts || !T->P.sign || !fixed || !hgt) st = TN_ERR_OUT_OF_MEMORY;
    for (i = 0; !st && i < P->n; i++) {
        if (s->masked[i]) continue;
        T->P.start[n] = m;
        T->P.sign[n] = P->sign[i];
        for (j = P->start[i]; j < P->start[i + 1]; j++, m++) {
            int x = (int)floorf(P->pts[3 * j] + 0.5f), y = (int)floorf(P->pts[3 * j + 1] + 0.5f);
            memcpy(T->P.pts + 3 * (size_t)m, P->pts + 3 * (size_t)j, 3 * sizeof(float));
            T->P.of[m] = n;
            if (x < 0 || y < 0 || x >= W || y >= H) continue;
            fixed[(size_t)y * W + x] = 1;
            T->type[(size_t)y * W + x] = P->sign[i];
            hgt[(size_t)y * W + x] = P->pts[3 * j + 2];
        }
        n++;
    }
    if (!st) {
        T->P.n = n;
        T->P.npts = m;
        T->P.start[n] = m;
        if (s->A.membrane) st = tn__gnn_membrane_solve(hgt, fixed, W, H, T->base);
        else memset(T->base, 0, npix * sizeof(float));
    }
    if (!st) st = tn__gnn_knn(&T->P, W, H, s->A.k, T->base, &T->nbr, &T->nfeat);
    TN_FREE(fixed);
    TN_FREE(hgt);
    return st;
}

/* This step's graph on level L: the fixed edges of unmasked parts, then random pixel-part
   edges, then the noise feature. */
static void tn__gnn_step_graph(tn__gnn_train *s, const tn__gnn_level *L)
{
    tn__gnn_graph *g = &s->g;
    int p, j, i, k = s->A.k, nparts = L->P.n, nm = 0;
    float mask = s->o.mask > 0 ? s->o.mask : 0.0f, noise = s->o.edge_noise > 0 ? s->o.edge_noise : 0.0f;
    for (i = 0; i < nparts; i++) {
        s->masked[i] = (uint8_t)(mask > 0 && tn_rng_uniform(&s->rng) < mask);
        nm += s->masked[i];
    }
    if (nm == nparts) memset(s->masked, 0, (size_t)nparts); /* keep something to learn from */
    g->nparts = nparts;
    g->E = 0;
    for (p = 0; p < s->npix; p++)
        for (j = 0; j < k; j++) {
            int r = L->nbr[(size_t)p * k + j];
            if (r < 0 || s->masked[r]) continue;
            g->e_pix[g->E] = p;
            g->e_part[g->E] = r;
            memcpy(g->feat + (size_t)g->E * TN__GNN_F, L->nfeat + ((size_t)p * k + j) * TN__GNN_F, TN__GNN_F * sizeof(float));
            g->E++;
        }
    for (i = 0; i < (s->o.random_edges > 0 ? s->o.random_edges : 0); i++) {
        int pix = (int)tn_rng_below(&s->rng, (uint32_t)s->npix), r = (int)tn_rng_below(&s->rng, (uint32_t)nparts), jj;
        float d2;
        if (s->masked[r]) continue;
        jj = tn__gnn_project(&L->P, r, (float)(pix % s->A.width), (float)(pix / s->A.width), &d2);
        g->e_pix[g->E] = pix;
        g->e_part[g->E] = r;
        tn__gnn_edge_features(&L->P, r, jj, d2, L->base[pix], g->feat + (size_t)g->E * TN__GNN_F);
        g->E++;
    }
    if (noise > 0)
        for (i = 0; i < g->E; i++) g->feat[(size_t)i * TN__GNN_F + 4] = noise * tn_rng_normal(&s->rng);
    tn__gnn_graph_finish(g);
}

static tn_tensor *tn__gnn_part_states(tn_ctx *ctx, const tn__gnn_arch *A, int nparts, tn_rng *rng)
{
    tn_tensor *E0 = tn_tensor_2d(ctx, nparts, A->hidden);
    size_t i;
    if (E0 && A->part_noise > 0)
        for (i = 0; i < E0->numel; i++) E0->data[i] = A->part_noise * tn_rng_normal(rng);
    return E0;
}

/* One step; the unweighted loss terms go to l[0..2], the total to l[3]. */
static tn_status tn__gnn_step(tn__gnn_train *s, tn_ctx *ctx, float *l)
{
    tn__gnn_in in;
    tn_tensor *pred, *tgt, *loss = NULL, *t, *emb;
    int shape[2], lev = 0, i;
    const tn__gnn_level *L;
    tn_status st;
    tn_ctx_reset(ctx);
    /* half the steps on the example's own network, half on a sparser one */
    if (s->nlevels > 1 && tn_rng_uniform(&s->rng) >= 0.5f) lev = 1 + (int)tn_rng_below(&s->rng, (uint32_t)(s->nlevels - 1));
    L = &s->lv[lev];
    if (lev > 0 && s->o.thin > 0) {
        if ((st = tn__gnn_level_thin(s, L, &s->thinned))) return st;
        L = &s->thinned;
    }
    tn__gnn_step_graph(s, L);
    shape[0] = L->P.n;
    shape[1] = s->A.embed;
    if (lev == 0) { /* embedding dropout: a dropped part is seen as a part of an unknown sketch */
        tn_tensor *keep = tn_tensor_2d(ctx, L->P.n, 1);
        float drop = s->o.embed_drop > 0 ? s->o.embed_drop : 0.0f;
        if (!keep) return tn_ctx_status(ctx);
        for (i = 0; i < L->P.n; i++) keep->data[i] = drop > 0 && tn_rng_uniform(&s->rng) < drop ? 0.0f : 1.0f;
        emb = tn_mul(ctx, tn_params_find(s->w, "gnn.emb"), keep);
    } else
        emb = tn_tensor_new(ctx, 2, shape);
    if ((st = tn__gnn_inputs(ctx, &s->g, L->type, s->A.membrane ? L->base : NULL, L->P.sign, emb, &in))) return st;
    in.E0 = tn__gnn_part_states(ctx, &s->A, L->P.n, &s->rng);
    {
        int s4[4];
        s4[0] = s4[1] = 1;
        s4[2] = s->A.height;
        s4[3] = s->A.width;
        pred = tn_reshape(ctx, tn__gnn_forward(ctx, s->w, &s->A, &in), 4, s4);
    }
    tgt = tn_tensor_4d(ctx, 1, 1, s->A.height, s->A.width);
    if (!pred || !tgt) return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : TN_ERR_OUT_OF_MEMORY;
    memcpy(tgt->data, s->target, (size_t)s->npix * sizeof(float));
    l[0] = l[1] = l[2] = 0;
    if (s->o.mse_weight > 0 && (t = tn_mse_loss(ctx, pred, tgt))) {
        l[0] = t->data[0];
        loss = tn_scale_shift(ctx, t, s->o.mse_weight, 0.0f);
    }
    if (s->o.ssim_weight > 0 && (t = tn_ssim_loss(ctx, pred, tgt, s->range))) {
        l[1] = t->data[0];
        t = tn_scale_shift(ctx, t, s->o.ssim_weight, 0.0f);
        loss = loss ? tn_add(ctx, loss, t) : t;
    }
    if (s->o.grad_weight > 0 && (t = tn_gdl_loss(ctx, pred, tgt))) {
        l[2] = t->data[0];
        t = tn_scale_shift(ctx, t, s->o.grad_weight, 0.0f);
        loss = loss ? tn_add(ctx, loss, t) : t;
    }
    if (!loss) return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : tn__fail(TN_ERR_INVALID_ARG, "gnn: every loss term is off");
    l[3] = loss->data[0];
    if (!isfinite(l[3])) return tn__fail(TN_ERR_NUMERIC, "gnn: the loss diverged at iteration %ld (lower the learning rate)", tn_train_iteration(s->run));
    tn_params_zero_grad(s->w);
    if ((st = tn_backward(ctx, loss))) return st;
    tn_optim_step(s->opt);
    return TN_OK;
}

static tn_status tn__gnn_check_dem(const tn_image *dem, float *lo, float *hi, double *mean, double *std)
{
    size_t i, n;
    double s = 0, s2 = 0;
    if (!dem) return tn__fail(TN_ERR_INVALID_ARG, "gnn: no DEM");
    if (!dem->data || dem->width <= 0 || dem->height <= 0 || dem->channels <= 0) return tn__fail(TN_ERR_EMPTY, "gnn: the DEM is empty");
    if (dem->width < 16 || dem->height < 16)
        return tn__fail(TN_ERR_INVALID_ARG, "gnn: the DEM is %d x %d; at least 16 x 16 is needed", dem->width, dem->height);
    if ((size_t)dem->width * dem->height > ((size_t)1 << 24))
        return tn__fail(TN_ERR_TOO_LARGE, "gnn: the DEM is %d x %d; train on a crop of at most 16 M pixels", dem->width, dem->height);
    n = (size_t)dem->width * dem->height;
    *lo = FLT_MAX;
    *hi = -FLT_MAX;
    for (i = 0; i < n; i++) {
        float v = dem->data[i * dem->channels];
        if (!isfinite(v)) return tn__fail(TN_ERR_NUMERIC, "gnn: the DEM has a NaN/Inf height at pixel (%d, %d)", (int)(i % dem->width), (int)(i / dem->width));
        if (v < *lo) *lo = v;
        if (v > *hi) *hi = v;
        s += v;
        s2 += (double)v * v;
    }
    *mean = s / (double)n;
    *std = sqrt(fmax(s2 / (double)n - *mean * *mean, 0.0));
    if (!(*hi > *lo)) return tn__fail(TN_ERR_EMPTY, "gnn: the DEM is flat (no ridges or valleys to learn)");
    return TN_OK;
}

static tn_status tn__gnn_set_meta(tn__gnn_train *s, uint64_t digest)
{
    char buf[64];
    tn_status st;
    snprintf(buf, sizeof buf, "%016llx", (unsigned long long)digest);
    st = tn_train_set_meta(s->run, "example", buf);
#define TN__GNN_META_I(key, v) \
    if (!st) { snprintf(buf, sizeof buf, "%ld", (long)(v)); st = tn_train_set_meta(s->run, key, buf); }
#define TN__GNN_META_F(key, v) \
    if (!st) { snprintf(buf, sizeof buf, "%.9g", (double)(v)); st = tn_train_set_meta(s->run, key, buf); }
    TN__GNN_META_I("random_edges", s->o.random_edges)
    TN__GNN_META_F("mask", s->o.mask)
    TN__GNN_META_F("embed_drop", s->o.embed_drop)
    TN__GNN_META_I("sparse_levels", s->o.sparse_levels)
    TN__GNN_META_F("thin", s->o.thin)
    TN__GNN_META_I("threshold", s->o.extract.threshold)
    TN__GNN_META_F("edge_noise", s->o.edge_noise)
    TN__GNN_META_F("lr", s->o.lr)
    TN__GNN_META_F("mse_weight", s->o.mse_weight)
    TN__GNN_META_F("ssim_weight", s->o.ssim_weight)
    TN__GNN_META_F("grad_weight", s->o.grad_weight)
#undef TN__GNN_META_I
#undef TN__GNN_META_F
    return st;
}

/* A resumed run continues with the settings it started with (they are part of its state). */
static tn_status tn__gnn_get_meta(tn__gnn_train *s, uint64_t digest, const char *name)
{
    const char *v;
    char buf[32];
    snprintf(buf, sizeof buf, "%016llx", (unsigned long long)digest);
    if (!(v = tn_train_meta(s->run, "example")) || strcmp(v, buf) != 0)
        return tn__fail(TN_ERR_SHAPE, "%s: the checkpoint was trained on another example DEM", name);
#define TN__GNN_GET(key, dst, lo, hi)                                                     \
    if (!(v = tn_train_meta(s->run, key))) return tn__fail(TN_ERR_CORRUPT, "%s: no %s in the checkpoint", name, key); \
    else {                                                                                \
        char *end;                                                                        \
        double d = strtod(v, &end);                                               \
        if (end == v || *end || !(d >= (lo) && d <= (hi))) return tn__fail(TN_ERR_CORRUPT, "%s: bad %s '%s'", name, key, v); \
        dst = d;                                                                          \
    }
    TN__GNN_GET("random_edges", s->o.random_edges, -1e9, 1e9)
    TN__GNN_GET("mask", s->o.mask, -1, 1)
    TN__GNN_GET("embed_drop", s->o.embed_drop, -1, 1)
    TN__GNN_GET("sparse_levels", s->o.sparse_levels, -1, TN__GNN_MAX_LEVELS - 1)
    TN__GNN_GET("thin", s->o.thin, -1, 1)
    TN__GNN_GET("threshold", s->o.extract.threshold, -1, 1e9)
    TN__GNN_GET("edge_noise", s->o.edge_noise, -1, 100)
    TN__GNN_GET("lr", s->o.lr, 0, 10)
    TN__GNN_GET("mse_weight", s->o.mse_weight, -1e6, 1e6)
    TN__GNN_GET("ssim_weight", s->o.ssim_weight, -1e6, 1e6)
    TN__GNN_GET("grad_weight", s->o.grad_weight, -1e6, 1e6)
#undef TN__GNN_GET
    return TN_OK;
}

TN_API tn_status tn_gnn_train(const tn_image *dem, const tn_gnn_opts *opts_in, tn_gnn *model, tn_gnn_stats *stats)
{
    tn__gnn_train s;
    tn_extraction ex;
    tn_contour_set parts;
    tn_ctx *ctx = NULL;
    tn_image one = {0, 0, 0, NULL};
    const tn_image *d1 = dem;
    float lo = 0, hi = 0, hist[50][4];
    double mean = 0, std = 0;
    int nh = 0, i;
    size_t n;
    uint64_t digest, seed;
    const char *sd;
    tn_status st;
    TN_ASSERT(model);
    memset(&s, 0, sizeof s);
    memset(&ex, 0, sizeof ex);
    memset(&parts, 0, sizeof parts);
    if (opts_in) s.o = *opts_in;
    tn_gnn_defaults(&s.o);
    if ((st = tn__gnn_check_dem(dem, &lo, &hi, &mean, &std))) return st;
    if (s.o.hidden > TN__GNN_MAXH || s.o.rounds > 16 || s.o.k > 64 || s.o.embed > 256 || !(s.o.lr < 10) || !isfinite(s.o.mask) ||
        s.o.mask >= 1 || !(s.o.embed_drop < 1) || !(s.o.thin < 1) || !(s.o.edge_noise <= 100) || !(s.o.part_noise <= 100) || !isfinite(s.o.mse_weight) ||
        !isfinite(s.o.ssim_weight) || !isfinite(s.o.grad_weight) || s.o.random_edges > (1 << 24))
        return tn__fail(TN_ERR_INVALID_ARG, "gnn: bad option (hidden %d <= %d, rounds %d <= 16, k %d <= 64, embed %d <= 256, "
                        "mask %g < 1, finite weights and noise, random edges <= 2^24)", s.o.hidden, TN__GNN_MAXH, s.o.rounds, s.o.k,
                        s.o.embed, (double)s.o.mask, s.o.random_edges);
    if ((size_t)dem->width * dem->height * (size_t)s.o.k + (size_t)(s.o.random_edges > 0 ? s.o.random_edges : 0) > TN__GNN_MAX_EDGES)
        return tn__fail(TN_ERR_TOO_LARGE, "gnn: %d x %d pixels with %d edges each exceed %d edges; train on a crop", dem->width, dem->height,
                        s.o.k, TN__GNN_MAX_EDGES);
    if (dem->channels > 1) { /* channel 0 only, as every DEM function */
        if ((st = tn_image_create(&one, dem->width, dem->height, 1))) return st;
        for (n = 0; n < (size_t)dem->width * dem->height; n++) one.data[n] = dem->data[n * dem->channels];
        d1 = &one;
    }
    digest = tn_image_digest(d1);
    seed = s.o.train.seed;
    if ((st = tn_train_create("gnn", "gnn-train", &s.o.train, &s.run))) goto done;
    if (s.o.train.resume) { /* the checkpoint's seed and architecture win */
        tn_params *ck;
        tn_tensor *cfg;
        if ((st = tn_train_open_checkpoint(s.run, &ck))) goto done;
        if (!(cfg = tn_params_find(ck, "gnn.config")) || cfg->numel != TN__GNN_CONFIG) {
            st = tn__fail(TN_ERR_FORMAT, "%s: not a gnn checkpoint", s.o.train.checkpoint);
            goto done;
        }
        if ((st = tn__gnn_read_config(cfg->data, &s.A, s.o.train.checkpoint))) goto done;
        if ((st = tn__gnn_get_meta(&s, digest, s.o.train.checkpoint))) goto done;
        sd = tn_params_meta(ck, "seed");
        if (!sd || !tn__parse_hex64(sd, strlen(sd), &seed)) {
            st = tn__fail(TN_ERR_CORRUPT, "%s: the checkpoint names no seed", s.o.train.checkpoint);
            goto done;
        }
    }
    /* the example's network and parts: deterministic in the DEM, the extraction options and
       the seed, so a resumed run rebuilds the same graph */
    if ((st = tn_extract(d1, &s.o.extract, &ex))) goto done;
    if (!ex.contours.count) {
        st = tn__fail(TN_ERR_EMPTY, "gnn: no ridge or valley was extracted from the DEM (try a lower extraction threshold)");
        goto done;
    }
    if ((st = tn_contour_parts_make(&ex.contours, seed, &parts))) goto done;
    if (!parts.count) {
        st = tn__fail(TN_ERR_EMPTY, "gnn: the DEM's ridges and valleys give no contour part of 5 px");
        goto done;
    }
    if (!s.o.train.resume) {
        s.A.hidden = s.o.hidden;
        s.A.rounds = s.o.rounds;
        s.A.k = s.o.k;
        s.A.embed = s.o.embed;
        s.A.membrane = s.o.membrane >= 0;
        s.A.width = d1->width;
        s.A.height = d1->height;
        s.A.mean = (float)mean;
        s.A.std = (float)(std > 1e-30 ? std : 1.0);
        s.A.lo = lo;
        s.A.hi = hi;
        s.A.part_noise = s.o.part_noise > 0 ? s.o.part_noise : 0.0f;
        s.A.parts = parts.count;
        s.A.npts = 0;
        for (i = 0; i < parts.count; i++) s.A.npts += parts.items[i].npoints;
    } else if (s.A.parts != parts.count || s.A.width != d1->width || s.A.height != d1->height) {
        st = tn__fail(TN_ERR_SHAPE, "%s: the checkpoint's example has %d parts at %d x %d, this one %d at %d x %d", s.o.train.checkpoint,
                      s.A.parts, s.A.width, s.A.height, parts.count, d1->width, d1->height);
        goto done;
    }
    tn_rng_seed(&s.rng, seed, 0x676e6eULL);
    if ((st = tn__gnn_model_params(&s.A, &s.rng, &s.w))) goto done;
    tn__gnn_store_parts(s.w, &parts);
    {
        tn_optim_opts oo;
        memset(&oo, 0, sizeof oo);
        oo.lr = s.o.lr;
        oo.beta1 = 0.9f;
        oo.beta2 = 0.999f;
        if (!(s.opt = tn_optim_create(s.w, &oo))) { st = TN_ERR_INVALID_ARG; goto done; }
    }
    if ((st = tn_train_add_net(s.run, "gnn", s.w, s.opt)) || (st = tn_train_add_rng(s.run, "main", &s.rng))) goto done;
    if ((st = tn__gnn_set_meta(&s, digest))) goto done;
    if (s.o.train.resume && (st = tn_train_restore(s.run))) goto done;
    /* the levels: the example's own network, then its sparser networks */
    s.npix = s.A.width * s.A.height;
    if (!(s.target = (float *)tn__alloc((size_t)s.npix * sizeof(float)))) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    for (i = 0; i < s.npix; i++) s.target[i] = (d1->data[i] - s.A.mean) / s.A.std;
    s.range = (s.A.hi - s.A.lo) / s.A.std;
    if ((st = tn__gnn_level_make(&s.A, &ex.contours, &parts, &s.lv[0]))) goto done;
    s.nlevels = 1;
    s.maxparts = parts.count;
    for (i = 1; i <= (s.o.sparse_levels > 0 ? s.o.sparse_levels : 0); i++) {
        static const int factor[TN__GNN_MAX_LEVELS] = {1, 4, 12, 36};
        tn_extract_opts eo = s.o.extract;
        tn_extraction sx;
        tn_contour_set sp;
        int base_thr = eo.threshold > 0 ? eo.threshold : tn_extract_default_threshold(d1->width, d1->height);
        eo.threshold = base_thr * factor[i];
        memset(&sp, 0, sizeof sp);
        if ((st = tn_extract(d1, &eo, &sx))) goto done;
        if (sx.contours.count && !(st = tn_contour_parts_make(&sx.contours, seed + (uint64_t)i, &sp)) && sp.count) {
            st = tn__gnn_level_make(&s.A, &sx.contours, &sp, &s.lv[s.nlevels]);
            if (sp.count > s.maxparts) s.maxparts = sp.count;
            s.nlevels++;
        }
        tn_contour_set_free(&sp);
        tn_extraction_free(&sx);
        if (st) goto done;
    }
    if (!(s.masked = (uint8_t *)tn__alloc((size_t)s.maxparts))) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    if ((st = tn__gnn_graph_alloc(&s.g, s.npix, s.maxparts, s.npix * s.A.k + (s.o.random_edges > 0 ? s.o.random_edges : 0)))) goto done;
    if (!(ctx = tn_ctx_create())) { st = tn__fail(TN_ERR_OUT_OF_MEMORY, "gnn: out of memory"); goto done; }
    while (tn_train_next(s.run)) {
        float l[4];
        tn_status e = tn__gnn_step(&s, ctx, l);
        if (e) {
            tn_train_fail(s.run, e);
            break;
        }
        memcpy(hist[nh % 50], l, sizeof l);
        nh++;
    }
    st = tn_train_finish(s.run);
    if (stats) {
        int k, m = nh < 50 ? nh : 50;
        long it = tn_train_iteration(s.run), it0 = tn_train_start_iteration(s.run);
        memset(stats, 0, sizeof *stats);
        stats->iterations = it;
        stats->resumed_from = s.o.train.resume ? it0 : 0;
        stats->seconds = tn_train_seconds(s.run);
        stats->seconds_per_iter = it > it0 ? (tn_train_seconds(s.run) - tn_train_start_seconds(s.run)) / (double)(it - it0) : 0.0;
        for (k = 0; k < m; k++) {
            stats->loss_mse += hist[k][0] / (float)m;
            stats->loss_ssim += hist[k][1] / (float)m;
            stats->loss_grad += hist[k][2] / (float)m;
            stats->loss += hist[k][3] / (float)m;
        }
        stats->parts = s.A.parts;
        for (i = 0; i < s.npix * s.A.k; i++) stats->edges += s.lv[0].nbr[i] >= 0;
        stats->levels = s.nlevels;
        stats->checkpoints = tn_train_checkpoints(s.run);
    }
    if (!st) {
        tn_model_provenance pv;
        memset(&pv, 0, sizeof pv);
        pv.seed = tn_train_seed(s.run);
        pv.iterations = tn_train_iteration(s.run);
        pv.seconds = tn_train_seconds(s.run);
        pv.example_digest = digest;
        pv.example_width = d1->width;
        pv.example_height = d1->height;
        pv.example_channels = 1;
        st = tn_model_stamp(s.w, "gnn", TN__GNN_FORMAT, &pv);
    }
    if (!st) {
        memset(model, 0, sizeof *model);
        tn__gnn_model_fields(model, &s.A);
        model->iterations = tn_train_iteration(s.run);
        model->train_seconds = tn_train_seconds(s.run);
        model->weights = s.w;
        s.w = NULL; /* handed over */
    }
done:
    tn_ctx_free(ctx);
    tn_image_free(&one);
    tn_extraction_free(&ex);
    tn_contour_set_free(&parts);
    tn__gnn_train_free(&s);
    return st;
}

/* ---- model files ---- */

TN_API void tn_gnn_free(tn_gnn *model)
{
    if (!model) return;
    tn_params_free(model->weights);
    memset(model, 0, sizeof *model);
}

static tn_status tn__gnn_check_model(const tn_gnn *m)
{
    tn__gnn_arch A;
    return tn__gnn_arch_of(m, &A);
}

TN_API tn_status tn_gnn_save(const tn_gnn *model, const char *path)
{
    tn_status st;
    if ((st = tn__gnn_check_model(model))) return st;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "gnn save: empty path");
    return tn_params_save(model->weights, path);
}

TN_API tn_status tn_gnn_load(tn_gnn *model, const char *path)
{
    tn_params *f = NULL, *w = NULL;
    tn_tensor *cfg;
    tn__gnn_arch A;
    tn_contour_set parts;
    tn_gnn m;
    double v;
    tn_status st;
    TN_ASSERT(model);
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "gnn load: empty path");
    if ((st = tn_params_open(path, &f))) return st;
    memset(&parts, 0, sizeof parts);
    st = tn_model_check(f, "gnn", TN__GNN_FORMAT, NULL, path);
    if (!st && (!(cfg = tn_params_find(f, "gnn.config")) || cfg->numel != TN__GNN_CONFIG))
        st = tn__fail(TN_ERR_FORMAT, "%s: not a gnn model (no gnn.config)", path);
    if (!st) st = tn__gnn_read_config(cfg->data, &A, path);
    if (!st) st = tn__gnn_model_params(&A, NULL, &w);
    if (!st) st = tn__params_assign(w, f, path);
    if (!st) st = tn__gnn_stored_parts(w, &A, path, &parts); /* validates the parts */
    if (!st) {
        const tn_tensor *e = tn_params_find(w, "gnn.emb");
        size_t i;
        for (i = 0; i < e->numel; i++)
            if (!isfinite(e->data[i])) {
                st = tn__fail(TN_ERR_CORRUPT, "%s: NaN/Inf embedding", path);
                break;
            }
    }
    tn_contour_set_free(&parts);
    if (st) {
        tn_params_free(f);
        tn_params_free(w);
        return st;
    }
    memset(&m, 0, sizeof m);
    tn__gnn_model_fields(&m, &A);
    if (tn__meta_get_whole(f, "iterations", 1e15, &v, path)) m.iterations = (long)v;
    {
        const char *s = tn_params_meta(f, "train_seconds");
        m.train_seconds = s ? strtod(s, NULL) : 0.0;
    }
    tn_clear_error();
    tn_params_free(f);
    m.weights = w;
    *model = m;
    return TN_OK;
}

TN_API tn_status tn_gnn_parts(const tn_gnn *model, tn_contour_set *out)
{
    tn__gnn_arch A;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__gnn_arch_of(model, &A))) return st;
    return tn__gnn_stored_parts(model->weights, &A, "gnn", out);
}

/* ---- generation ---- */

/* The sketch in the output's pixels and the example's height units. */
static tn_status tn__gnn_sketch_units(const tn__gnn_arch *A, const tn_contour_set *sk, int W, int H, int heights, tn_contour_set *out)
{
    tn_contour_set s;
    float sx = (float)W / (float)sk->width, sy = (float)H / (float)sk->height, hmin = FLT_MAX, hmax = -FLT_MAX, a = 1, b = 0;
    int i, j;
    for (i = 0; i < sk->count; i++)
        for (j = 0; j < sk->items[i].npoints; j++) {
            float h = sk->items[i].points[3 * j + 2];
            if (h < hmin) hmin = h;
            if (h > hmax) hmax = h;
        }
    if (heights == TN_GNN_HEIGHTS_AUTO)
        heights = hmin >= 0 && hmax <= 1 && !(A->lo >= 0 && A->hi <= 1) ? TN_GNN_HEIGHTS_UNIT : TN_GNN_HEIGHTS_EXAMPLE;
    if (heights == TN_GNN_HEIGHTS_UNIT) {
        a = A->hi - A->lo;
        b = A->lo;
    }
    memset(&s, 0, sizeof s);
    s.width = W;
    s.height = H;
    s.count = sk->count;
    if (!(s.items = (tn_contour *)tn__calloc((size_t)sk->count * sizeof(tn_contour)))) return TN_ERR_OUT_OF_MEMORY;
    for (i = 0; i < sk->count; i++) {
        const tn_contour *c = &sk->items[i];
        tn_contour *d = &s.items[i];
        *d = *c;
        if (!(d->points = (float *)tn__alloc((size_t)c->npoints * 3 * sizeof(float)))) {
            tn_contour_set_free(&s);
            return TN_ERR_OUT_OF_MEMORY;
        }
        for (j = 0; j < c->npoints; j++) { /* pixel centres map to pixel centres */
            d->points[3 * j] = (c->points[3 * j] + 0.5f) * sx - 0.5f;
            d->points[3 * j + 1] = (c->points[3 * j + 1] + 0.5f) * sy - 0.5f;
            d->points[3 * j + 2] = a * c->points[3 * j + 2] + b;
        }
    }
    *out = s;
    return TN_OK;
}

/* match[i] = the example part identical to sketch part i (same points within 1e-3 px, heights
   within htol), else -1; htol < 0: -1 for all. Parts are few (hundreds to thousands) and most
   pairs fail on the point count or the first point, so a plain double loop is enough. */
static void tn__gnn_same_parts(const tn_contour_set *sk, const tn_contour_set *ex, float htol, int *match)
{
    int i, j, q;
    for (i = 0; i < sk->count; i++) {
        const tn_contour *a = &sk->items[i];
        match[i] = -1;
        for (j = 0; htol >= 0 && j < ex->count && match[i] < 0; j++) {
            const tn_contour *b = &ex->items[j];
            int same = a->npoints == b->npoints && a->type == b->type;
            for (q = 0; same && q < a->npoints; q++)
                same = fabsf(a->points[3 * q] - b->points[3 * q]) <= 1e-3f && fabsf(a->points[3 * q + 1] - b->points[3 * q + 1]) <= 1e-3f &&
                       fabsf(a->points[3 * q + 2] - b->points[3 * q + 2]) <= htol;
            if (same) match[i] = j;
        }
    }
}

TN_API tn_status tn_gnn_generate(const tn_gnn *model, const tn_contour_set *sketch, int width, int height,
                                 const tn_gnn_generate_opts *opts, tn_image *out)
{
    tn_gnn_generate_opts o;
    tn__gnn_arch A;
    tn_contour_set sk, dense, parts, ex_parts;
    tn__gnn_parts P;
    tn__gnn_graph g;
    tn__gnn_in in;
    tn_align_opts ao;
    tn_image res = {0, 0, 0, NULL};
    tn_ctx *ctx = NULL;
    tn_params *ft = NULL, *frozen = NULL;
    tn_optim *fopt = NULL;
    tn_tensor *emb, *pred;
    tn_rng rng;
    int *match = NULL, *nbr = NULL, i, j, npix;
    float *type = NULL, *hgt = NULL, *base = NULL, *nfeat = NULL;
    tn_status st;
    TN_ASSERT(out);
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    memset(&sk, 0, sizeof sk);
    memset(&dense, 0, sizeof dense);
    memset(&parts, 0, sizeof parts);
    memset(&ex_parts, 0, sizeof ex_parts);
    memset(&P, 0, sizeof P);
    memset(&g, 0, sizeof g);
    if ((st = tn__gnn_arch_of(model, &A))) return st;
    if (!sketch || sketch->count <= 0) return tn__fail(TN_ERR_EMPTY, "gnn generate: the sketch is empty");
    if ((st = tn__cset_check(sketch, "gnn generate"))) return st;
    if (width < 16 || height < 16 || width > TN_SKETCH_MAX_SIDE || height > TN_SKETCH_MAX_SIDE)
        return tn__fail(TN_ERR_INVALID_ARG, "gnn generate: size %d x %d (16 .. %d a side)", width, height, TN_SKETCH_MAX_SIDE);
    if (o.heights < TN_GNN_HEIGHTS_AUTO || o.heights > TN_GNN_HEIGHTS_UNIT || o.embeddings < TN_GNN_EMBED_AUTO ||
        o.embeddings > TN_GNN_EMBED_NONE || o.finetune < 0 || o.align_choices < 0 ||
        !(o.finetune_lr >= 0 && o.finetune_lr < 10) || !(o.smooth_weight <= 1e6))
        return tn__fail(TN_ERR_INVALID_ARG, "gnn generate: bad option (heights %d, finetune %d, align_choices %d)", o.heights, o.finetune,
                        o.align_choices);
    if ((size_t)width * height * A.k > TN__GNN_MAX_EDGES)
        return tn__fail(TN_ERR_TOO_LARGE, "gnn generate: %d x %d pixels with %d edges each exceed %d edges", width, height, A.k, TN__GNN_MAX_EDGES);
    npix = width * height;
    if ((st = tn__gnn_sketch_units(&A, sketch, width, height, o.heights, &sk))) goto done;
    if ((st = tn_sketch_densify(&sk, &dense))) goto done;
    if ((st = tn_contour_parts_make(&dense, o.seed, &parts))) goto done;
    if (!parts.count) {
        st = tn__fail(TN_ERR_EMPTY, "gnn generate: the sketch has no part of 5 px (draw longer lines)");
        goto done;
    }
    /* the example part whose embedding each sketch part takes (-1: none) */
    if ((st = tn__gnn_stored_parts(model->weights, &A, "gnn", &ex_parts))) goto done;
    if (!(match = (int *)tn__alloc((size_t)parts.count * sizeof(int)))) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    if (o.embeddings == TN_GNN_EMBED_ALIGNED) { /* 5.3: shape (LCS of chain codes) and heights */
        memset(&ao, 0, sizeof ao);
        ao.seed = o.seed;
        ao.choices = o.align_choices > 0 ? o.align_choices : 1;
        if ((st = tn_sketch_align(&parts, &ex_parts, &ao, match))) goto done;
    } else
        tn__gnn_same_parts(&parts, &ex_parts, o.embeddings == TN_GNN_EMBED_AUTO ? 1e-3f * A.std : -1.0f, match);
    /* baseline and pixel types from the rasterised sketch */
    type = (float *)tn__alloc((size_t)npix * sizeof(float));
    hgt = (float *)tn__alloc((size_t)npix * sizeof(float));
    base = (float *)tn__alloc((size_t)npix * sizeof(float));
    if (!type || !hgt || !base) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    if ((st = tn__gnn_sketch_pixels(&sk, width, height, type, hgt, base))) goto done;
    for (i = 0; i < npix; i++) {
        base[i] = A.membrane ? (base[i] - A.mean) / A.std : 0.0f;
        hgt[i] = type[i] != 0 ? (hgt[i] - A.mean) / A.std : 0.0f;
    }
    if ((st = tn__gnn_parts_make(&parts, A.mean, A.std, &P))) goto done;
    if ((st = tn__gnn_knn(&P, width, height, A.k, base, &nbr, &nfeat))) goto done;
    if ((st = tn__gnn_graph_alloc(&g, npix, P.n, npix * A.k))) goto done;
    for (i = 0; i < npix; i++)
        for (j = 0; j < A.k; j++) {
            int r = nbr[(size_t)i * A.k + j];
            if (r < 0) continue;
            g.e_pix[g.E] = i;
            g.e_part[g.E] = r;
            memcpy(g.feat + (size_t)g.E * TN__GNN_F, nfeat + ((size_t)i * A.k + j) * TN__GNN_F, TN__GNN_F * sizeof(float));
            g.E++;
        }
    tn__gnn_graph_finish(&g);
    if (!(ctx = tn_ctx_create())) { st = tn__fail(TN_ERR_OUT_OF_MEMORY, "gnn: out of memory"); goto done; }
    /* the sketch parts' embeddings, as a learnable set for the fine-tune */
    {
        int s[2];
        const tn_tensor *me = tn_params_find(model->weights, "gnn.emb");
        s[0] = P.n;
        s[1] = A.embed;
        if (!(ft = tn_params_create()) || !(emb = tn_params_add(ft, "emb", 2, s))) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
        for (i = 0; i < P.n; i++)
            if (match[i] >= 0) memcpy(emb->data + (size_t)i * A.embed, me->data + (size_t)match[i] * A.embed, (size_t)A.embed * sizeof(float));
    }
    tn_rng_seed(&rng, o.seed, 0x67656eULL);
    if (o.finetune > 0) { /* 5.4: only the embeddings move; loss on the sketch pixels + smoothness */
        tn_optim_opts oo;
        int step, shape[4];
        float sw = o.smooth_weight == 0 ? 0.1f : o.smooth_weight > 0 ? o.smooth_weight : 0.0f;
        tn_rng frng = rng;
        int nsk = 0;
        for (i = 0; i < npix; i++) nsk += type[i] != 0;
        memset(&oo, 0, sizeof oo);
        oo.lr = o.finetune_lr > 0 ? o.finetune_lr : 1e-2f;
        if (!(fopt = tn_optim_create(ft, &oo))) { st = TN_ERR_INVALID_ARG; goto done; }
        /* a frozen copy of the network (buffers: no gradient), so the model is only read */
        if (!(frozen = tn_params_create())) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
        for (i = 0; i < tn_params_count(model->weights); i++) {
            const tn_tensor *t = tn_params_get(model->weights, i);
            tn_tensor *c = tn_params_add_buffer(frozen, t->name, t->ndim, t->shape);
            if (!c) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
            memcpy(c->data, t->data, t->numel * sizeof(float));
        }
        shape[0] = shape[1] = 1;
        shape[2] = height;
        shape[3] = width;
        for (step = 0; step < o.finetune && !st; step++) {
            tn_tensor *p4, *mask, *tg, *loss;
            tn_ctx_reset(ctx);
            frng = rng; /* the same part states as the final pass */
            if ((st = tn__gnn_inputs(ctx, &g, type, A.membrane ? base : NULL, P.sign, emb, &in))) break;
            in.E0 = tn__gnn_part_states(ctx, &A, P.n, &frng);
            p4 = tn_reshape(ctx, tn__gnn_forward(ctx, frozen, &A, &in), 4, shape);
            mask = tn_tensor_4d(ctx, 1, 1, height, width);
            tg = tn_tensor_4d(ctx, 1, 1, height, width);
            if (!p4 || !mask || !tg) { st = tn_ctx_status(ctx); break; }
            for (i = 0; i < npix; i++) {
                mask->data[i] = type[i] != 0 ? 1.0f : 0.0f;
                tg->data[i] = hgt[i];
            }
            loss = tn_scale_shift(ctx, tn_sum(ctx, tn_square(ctx, tn_mul(ctx, tn_sub(ctx, p4, tg), mask))), 1.0f / (float)(nsk ? nsk : 1), 0.0f);
            if (sw > 0) loss = tn_add(ctx, loss, tn_scale_shift(ctx, tn_tv_loss(ctx, p4, 2.0f), sw / (float)npix, 0.0f));
            tn_params_zero_grad(ft);
            if ((st = tn_backward(ctx, loss))) break;
            tn_optim_step(fopt);
        }
        if (st) goto done;
    }
    tn_ctx_reset(ctx);
    tn_ctx_set_grad(ctx, 0);
    if ((st = tn__gnn_inputs(ctx, &g, type, A.membrane ? base : NULL, P.sign, emb, &in))) goto done;
    in.E0 = tn__gnn_part_states(ctx, &A, P.n, &rng);
    pred = tn__gnn_forward(ctx, model->weights, &A, &in);
    if (!pred) { st = tn_ctx_status(ctx) ? tn_ctx_status(ctx) : TN_ERR_OUT_OF_MEMORY; goto done; }
    if ((st = tn_image_create(&res, width, height, 1))) goto done;
    for (i = 0; i < npix; i++) {
        res.data[i] = A.mean + A.std * pred->data[i];
        if (!isfinite(res.data[i])) { st = tn__fail(TN_ERR_NUMERIC, "gnn generate: the network gave NaN/Inf (damaged model?)"); goto done; }
    }
    *out = res;
    res.data = NULL;
done:
    tn_image_free(&res);
    tn_ctx_free(ctx);
    tn_optim_free(fopt);
    tn_params_free(ft);
    tn_params_free(frozen);
    tn_contour_set_free(&sk);
    tn_contour_set_free(&dense);
    tn_contour_set_free(&parts);
    tn_contour_set_free(&ex_parts);
    tn__gnn_parts_free(&P);
    tn__gnn_graph_free(&g);
    TN_FREE(match);
    TN_FREE(nbr);
    TN_FREE(nfeat);
    TN_FREE(type);
    TN_FREE(hgt);
    TN_FREE(base);
    return st;
}

/* --------------------------------------------------------------------------------------------
   >>render  (@@render implementation)
   The preview multiplies a hypsometric colour ramp by a hillshade. The 3D view is the classic
   height-field ray caster: every screen column marches a ray away from the camera; a sample
   whose projected top lies above everything drawn so far in that column fills the gap. Columns
   are independent, so they run in parallel and the image does not depend on the thread count.
   -------------------------------------------------------------------------------------------- */

/* The zero rule of tn_render_opts: shade strength 0.7. lo == hi (the DEM's own range) is the
   colour ramp's rule, and shade is resolved by tn_image_hillshade. */
static void tn__render_opts_defaults(tn_render_opts *o)
{
    if (o->shade_strength == 0) o->shade_strength = 0.7f;
}

TN_API tn_status tn_render_preview(const tn_image *dem, const tn_render_opts *opts, tn_image *out)
{
    tn_render_opts o;
    tn_image ramp = {0, 0, 0, NULL}, shade = {0, 0, 0, NULL};
    tn_status st;
    size_t i, n;
    float k;
    if ((st = tn__dem_check(dem, 2, "render preview"))) return st;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    if (!(o.shade_strength >= 0 && o.shade_strength <= 1))
        return tn__fail(TN_ERR_INVALID_ARG, "render preview: shade_strength %g is not in 0..1", (double)o.shade_strength);
    tn__render_opts_defaults(&o);
    k = o.shade_strength;
    if ((st = tn_image_colour_ramp(&ramp, dem, o.lo, o.hi))) return st;
    if ((st = tn_image_hillshade(&shade, dem, &o.shade))) {
        tn_image_free(&ramp);
        return st;
    }
    n = (size_t)dem->width * dem->height;
    for (i = 0; i < n; i++) {
        float f = (1.0f - k) + k * 1.25f * shade.data[i];
        int c;
        for (c = 0; c < 3; c++) ramp.data[i * 3 + c] = tn__clampf(ramp.data[i * 3 + c] * f, 0.0f, 1.0f);
    }
    tn_image_free(&shade);
    *out = ramp;
    return TN_OK;
}

typedef struct tn__view_job {
    const tn_image *dem, *colour;
    tn_image *out;
    float lo, scale;            /* height -> world z: (h - lo) * scale */
    float cx, cy, cz;           /* camera position in pixel units */
    float yaw, pitch, fov;      /* radians */
    float far_dist, focal;
} tn__view_job;

/* Bilinear sample of channel c at (x, y), clamped to the image. */
static float tn__sample_bilinear(const tn_image *im, float x, float y, int c)
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

static void tn__view_columns(void *ctx, size_t b, size_t e)
{
    const tn__view_job *j = (const tn__view_job *)ctx;
    tn_image *out = j->out;
    const float W = (float)j->dem->width, H = (float)j->dem->height;
    const float horizon = 0.5f * (float)out->height - tanf(j->pitch) * j->focal;
    size_t sx;
    for (sx = b; sx < e; sx++) {
        float ang = j->yaw + ((float)sx / (float)(out->width - 1) - 0.5f) * j->fov;
        float dx = sinf(ang), dy = -cosf(ang); /* north is -y */
        float cosd = cosf(ang - j->yaw);        /* distance along the view axis: no fish-eye */
        int ybuf = out->height, y;
        float t = 1.0f;
        while (t < j->far_dist && ybuf > 0) {
            float px = j->cx + dx * t, py = j->cy + dy * t;
            float step = 0.35f + t * 0.004f;
            if (px >= 0 && py >= 0 && px <= W - 1 && py <= H - 1) {
                float z = (tn__sample_bilinear(j->dem, px, py, 0) - j->lo) * j->scale;
                float depth = t * cosd;
                float fsy = horizon + (j->cz - z) / depth * j->focal;
                int sy = fsy < -1.0f ? -1 : fsy < (float)ybuf ? (int)fsy : ybuf; /* clamped before the cast */
                if (sy < ybuf) {
                    float haze = tn__clampf(t / j->far_dist, 0.0f, 1.0f);
                    float col[3];
                    int c;
                    haze = haze * haze * 0.8f;
                    for (c = 0; c < 3; c++) {
                        static const float sky[3] = {0.78f, 0.85f, 0.95f};
                        float v = tn__sample_bilinear(j->colour, px, py, c);
                        col[c] = v + (sky[c] - v) * haze;
                    }
                    for (y = sy < 0 ? 0 : sy; y < ybuf; y++) {
                        int c2;
                        for (c2 = 0; c2 < 3; c2++) TN_PIXEL(out, sx, y, c2) = col[c2];
                    }
                    ybuf = sy < 0 ? 0 : sy;
                }
            }
            t += step;
        }
        for (y = 0; y < ybuf; y++) { /* sky gradient above the terrain */
            float f = tn__clampf((float)y / (float)out->height, 0.0f, 1.0f);
            TN_PIXEL(out, sx, y, 0) = 0.45f + 0.35f * f;
            TN_PIXEL(out, sx, y, 1) = 0.62f + 0.25f * f;
            TN_PIXEL(out, sx, y, 2) = 0.88f + 0.08f * f;
        }
    }
}

/* The zero rules of tn_view_opts: 960 x 540 when either side is 0; seen from the south (180),
   30 degrees down, from 1.1 DEM widths, 60 degree field of view, relief 0.2 (the last three
   also replace negative values). colours is resolved by tn_render_preview. */
static void tn__view_opts_defaults(tn_view_opts *o)
{
    if (o->width == 0 || o->height == 0) {
        o->width = 960;
        o->height = 540;
    }
    if (o->azimuth_deg == 0) o->azimuth_deg = 180.0f;
    if (o->pitch_deg == 0) o->pitch_deg = 30.0f;
    if (o->distance <= 0) o->distance = 1.1f;
    if (o->fov_deg <= 0) o->fov_deg = 60.0f;
    if (o->relief <= 0) o->relief = 0.2f;
}

TN_API tn_status tn_render_view(const tn_image *dem, const tn_view_opts *opts, tn_image *out)
{
    tn_view_opts o;
    tn_image colour = {0, 0, 0, NULL}, img = {0, 0, 0, NULL};
    tn__view_job j;
    tn_status st;
    float lo, hi, size, dist, zmax;
    if ((st = tn__dem_check(dem, 2, "render view"))) return st;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    if (o.width < 0 || o.height < 0 || !(fabsf(o.azimuth_deg) <= 1e6f) || !(fabsf(o.pitch_deg) < 89.0f) ||
        !(fabsf(o.distance) <= 1e6f) || !(o.fov_deg <= 170.0f && o.fov_deg >= -1e6f) || !(fabsf(o.relief) <= 1e6f))
        return tn__fail(TN_ERR_INVALID_ARG, "render view: bad options (size %d x %d, angles and distances finite, |pitch| < 89, fov <= 170)",
                        o.width, o.height);
    tn__view_opts_defaults(&o);
    if (o.width > 16384 || o.height > 16384)
        return tn__fail(TN_ERR_INVALID_ARG, "render view: output %d x %d is too large (max 16384)", o.width, o.height);
    if (tn_image_range(dem, &lo, &hi)) return tn__fail(TN_ERR_NUMERIC, "render view: the DEM holds NaN/Inf");
    if ((st = tn_render_preview(dem, &o.colours, &colour))) return st;
    if ((st = tn_image_create(&img, o.width, o.height, 3))) {
        tn_image_free(&colour);
        return st;
    }
    size = (float)(dem->width > dem->height ? dem->width : dem->height);
    dist = o.distance * size;
    zmax = o.relief * size;
    j.dem = dem;
    j.colour = &colour;
    j.out = &img;
    j.lo = lo;
    j.scale = hi > lo ? zmax / (hi - lo) : 0.0f;
    j.yaw = o.azimuth_deg * 0.017453293f + 3.14159265f; /* the camera looks back towards the centre */
    j.pitch = o.pitch_deg * 0.017453293f;
    j.fov = o.fov_deg * 0.017453293f;
    j.cx = 0.5f * (float)(dem->width - 1) + sinf(j.yaw - 3.14159265f) * dist;
    j.cy = 0.5f * (float)(dem->height - 1) - cosf(j.yaw - 3.14159265f) * dist;
    j.cz = 0.5f * zmax + tanf(j.pitch) * dist;
    j.far_dist = dist + 1.5f * size;
    j.focal = 0.5f * (float)o.width / tanf(0.5f * j.fov);
    tn_parallel_for((size_t)o.width, 8, tn__view_columns, &j);
    tn_image_free(&colour);
    *out = img;
    return TN_OK;
}

/* --------------------------------------------------------------------------------------------
   >>export  (@@export implementation)
   -------------------------------------------------------------------------------------------- */

typedef struct tn__mesh {
    int nx, ny;                /* vertices per row and per column */
    float *pos, *nrm, *uv;     /* 3, 3, 2 floats per vertex */
    uint32_t *idx;             /* 6 per cell */
    float lo[3], hi[3];        /* position bounds (glTF wants them) */
} tn__mesh;

static void tn__mesh_opts_defaults(tn_mesh_opts *o)
{
    if (!(o->dx > 0)) o->dx = 1.0f;
    if (!(o->dy > 0)) o->dy = o->dx;
    if (o->z_scale == 0) o->z_scale = 1.0f;
    if (o->step <= 0) o->step = 1;
}

static void tn__mesh_free(tn__mesh *m)
{
    TN_FREE(m->pos);
    memset(m, 0, sizeof *m);
}

/* Sample index of mesh vertex i along an axis of n samples with stride step (the last sample
   always included). */
static int tn__mesh_sample(int i, int step, int n) { return i * step < n - 1 ? i * step : n - 1; }

static tn_status tn__mesh_check(const tn_image *dem, const tn_mesh_opts *o, const char *path)
{
    float lo, hi;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "export: empty path");
    if (!dem || !dem->data || dem->width < 2 || dem->height < 2) return tn__fail(TN_ERR_EMPTY, "%s: the DEM must be at least 2 x 2", path);
    if (!(fabsf(o->dx) <= 1e30f) || !(fabsf(o->dy) <= 1e30f) || !(fabsf(o->z_scale) <= 1e30f) || o->step > 65536)
        return tn__fail(TN_ERR_INVALID_ARG, "%s: bad mesh options (spacing %g x %g, z scale %g, step %d)", path, (double)o->dx, (double)o->dy,
                        (double)o->z_scale, o->step);
    if (tn_image_range(dem, &lo, &hi)) return tn__fail(TN_ERR_NUMERIC, "%s: the DEM holds NaN/Inf", path);
    if (o->texture) {
        const tn_image *t = o->texture;
        if (!t->data || t->width < 1 || t->height < 1 || t->channels < 1 || t->channels > 4 || t->channels == 2)
            return tn__fail(TN_ERR_SHAPE, "%s: the texture must have 1, 3 or 4 channels", path);
        if (tn_image_range(t, &lo, &hi)) return tn__fail(TN_ERR_NUMERIC, "%s: the texture holds NaN/Inf", path);
    }
    return TN_OK;
}

/* Builds the grid mesh (one allocation for all arrays). */
static tn_status tn__mesh_build(const tn_image *dem, const tn_mesh_opts *o, tn__mesh *m, const char *path)
{
    int i, j, k;
    size_t nv, ncell, bytes = 0, v;
    memset(m, 0, sizeof *m);
    m->nx = (dem->width - 1 + o->step - 1) / o->step + 1;
    m->ny = (dem->height - 1 + o->step - 1) / o->step + 1;
    nv = (size_t)m->nx * m->ny;
    ncell = (size_t)(m->nx - 1) * (m->ny - 1);
    if (nv > 0xffffffffu || tn__size4(nv * 8 + ncell * 6, 4, 1, 1, &bytes)) return tn__fail(TN_ERR_TOO_LARGE, "%s: the mesh is too large (use a step)", path);
    if (!(m->pos = (float *)tn__alloc(bytes))) return tn__fail_context(TN_ERR_OUT_OF_MEMORY, path);
    m->nrm = m->pos + 3 * nv;
    m->uv = m->nrm + 3 * nv;
    m->idx = (uint32_t *)(m->uv + 2 * nv);
    for (k = 0; k < 3; k++) {
        m->lo[k] = FLT_MAX;
        m->hi[k] = -FLT_MAX;
    }
    for (j = 0, v = 0; j < m->ny; j++)
        for (i = 0; i < m->nx; i++, v++) {
            int sx = tn__mesh_sample(i, o->step, dem->width), sy = tn__mesh_sample(j, o->step, dem->height);
            float *p = m->pos + 3 * v;
            p[0] = (float)sx * o->dx;
            p[1] = TN_PIXEL(dem, sx, sy, 0) * o->z_scale;
            p[2] = (float)sy * o->dy;
            m->uv[2 * v] = (float)sx / (float)(dem->width - 1);
            m->uv[2 * v + 1] = (float)sy / (float)(dem->height - 1);
            for (k = 0; k < 3; k++) {
                if (p[k] < m->lo[k]) m->lo[k] = p[k];
                if (p[k] > m->hi[k]) m->hi[k] = p[k];
            }
        }
    for (j = 0, v = 0; j < m->ny; j++)
        for (i = 0; i < m->nx; i++, v++) { /* central differences of the mesh, one-sided at its edges */
            int i0 = i > 0 ? i - 1 : i, i1 = i < m->nx - 1 ? i + 1 : i, j0 = j > 0 ? j - 1 : j, j1 = j < m->ny - 1 ? j + 1 : j;
            const float *a = m->pos + 3 * ((size_t)j * m->nx + i0), *b = m->pos + 3 * ((size_t)j * m->nx + i1);
            const float *c = m->pos + 3 * ((size_t)j0 * m->nx + i), *d = m->pos + 3 * ((size_t)j1 * m->nx + i);
            double hx = (b[1] - a[1]) / (double)(b[0] - a[0]), hz = (d[1] - c[1]) / (double)(d[2] - c[2]);
            double len = sqrt(hx * hx + 1.0 + hz * hz);
            m->nrm[3 * v] = (float)(-hx / len);
            m->nrm[3 * v + 1] = (float)(1.0 / len);
            m->nrm[3 * v + 2] = (float)(-hz / len);
        }
    for (j = 0, v = 0; j + 1 < m->ny; j++)
        for (i = 0; i + 1 < m->nx; i++) {
            uint32_t a = (uint32_t)((size_t)j * m->nx + i), b = a + 1, c = a + (uint32_t)m->nx, d = c + 1;
            uint32_t *t = m->idx + 6 * v++;
            t[0] = a; t[1] = c; t[2] = b; /* counter-clockwise seen from +y */
            t[3] = b; t[4] = c; t[5] = d;
        }
    return TN_OK;
}

/* The texture as an 8-bit RGB(A) PNG in memory (grey expanded to RGB). */
static tn_status tn__mesh_texture_png(const tn_image *t, uint8_t **png, size_t *n)
{
    tn_image rgb = {0, 0, 0, NULL};
    tn_save_opts so;
    tn_status st;
    size_t i, np = (size_t)t->width * t->height;
    int c, ch = t->channels == 1 ? 3 : t->channels;
    if ((st = tn_image_create(&rgb, t->width, t->height, ch))) return st;
    for (i = 0; i < np; i++)
        for (c = 0; c < ch; c++) {
            float v = t->data[i * t->channels + (t->channels == 1 ? 0 : c)];
            rgb.data[i * ch + c] = v < 0 ? 0.0f : v > 1 ? 1.0f : v;
        }
    memset(&so, 0, sizeof so);
    so.bit_depth = 8;
    st = tn_image_save_memory(&rgb, &so, TN_FORMAT_PNG, png, n);
    tn_image_free(&rgb);
    return st;
}

/* A growing text buffer (JSON, OBJ). */
typedef struct tn__text { char *s; size_t n, cap; int failed; } tn__text;

static void tn__text_add(tn__text *t, const char *fmt, ...)
{
    va_list ap;
    int k;
    if (t->failed) return;
    for (;;) {
        size_t room = t->cap - t->n;
        va_start(ap, fmt);
        k = t->s ? vsnprintf(t->s + t->n, room, fmt, ap) : -1;
        va_end(ap);
        if (k >= 0 && (size_t)k < room) {
            t->n += (size_t)k;
            return;
        }
        {
            size_t cap = t->cap ? 2 * t->cap : 4096;
            char *s;
            if (k > 0 && cap < t->n + (size_t)k + 1) cap = t->n + (size_t)k + 1;
            if (cap > TN_MAX_ALLOC || !(s = (char *)TN_REALLOC(t->s, cap))) {
                t->failed = 1;
                return;
            }
            t->s = s;
            t->cap = cap;
        }
    }
}

/* A float as the shortest text that reads back as the same float, '.' whatever the locale. */
static void tn__text_num(tn__text *t, float v)
{
    char b[40];
    tn__io_format_number(b, sizeof b, (double)v, 1);
    tn__text_add(t, "%s", b);
}

static void tn__glb_put_chunk(uint8_t *out, size_t *off, const char *type, const uint8_t *data, size_t n, size_t padded, uint8_t pad)
{
    tn__put_u32(out + *off, (uint32_t)padded);
    memcpy(out + *off + 4, type, 4);
    memcpy(out + *off + 8, data, n);
    memset(out + *off + 8 + n, pad, padded - n);
    *off += 8 + padded;
}

TN_API tn_status tn_export_glb(const tn_image *dem, const char *path, const tn_mesh_opts *opts)
{
    tn_mesh_opts o;
    tn__mesh m;
    tn__text js = {NULL, 0, 0, 0};
    uint8_t *png = NULL, *out = NULL, *bin = NULL;
    size_t png_n = 0, nv, ni, off[5], binlen, jpad, bpad, total, pos = 0;
    tn_status st;
    int k;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    tn__mesh_opts_defaults(&o);
    if ((st = tn__mesh_check(dem, &o, path))) return st;
    if ((st = tn__mesh_build(dem, &o, &m, path))) return st;
    if (o.texture && (st = tn__mesh_texture_png(o.texture, &png, &png_n))) {
        tn__mesh_free(&m);
        return tn__fail_context(st, path);
    }
    nv = (size_t)m.nx * m.ny;
    ni = (size_t)(m.nx - 1) * (m.ny - 1) * 6;
    off[0] = 0;                       /* positions */
    off[1] = off[0] + nv * 12;        /* normals */
    off[2] = off[1] + nv * 12;        /* UVs */
    off[3] = off[2] + nv * 8;         /* indices */
    off[4] = off[3] + ni * 4;         /* PNG */
    binlen = off[4] + png_n;
    tn__text_add(&js, "{\"asset\":{\"version\":\"2.0\",\"generator\":\"terrainnet %s\"},\"scene\":0,\"scenes\":[{\"nodes\":[0]}],"
                      "\"nodes\":[{\"mesh\":0,\"name\":\"terrain\"}],\"meshes\":[{\"primitives\":[{\"attributes\":"
                      "{\"POSITION\":0,\"NORMAL\":1,\"TEXCOORD_0\":2},\"indices\":3,\"material\":0}]}],",
                 TN_VERSION_STRING);
    tn__text_add(&js, "\"materials\":[{\"pbrMetallicRoughness\":{%s\"metallicFactor\":0,\"roughnessFactor\":1}}],",
                 png ? "\"baseColorTexture\":{\"index\":0}," : "");
    if (png)
        tn__text_add(&js, "\"textures\":[{\"sampler\":0,\"source\":0}],\"samplers\":[{\"magFilter\":9729,\"minFilter\":9987,"
                          "\"wrapS\":33071,\"wrapT\":33071}],\"images\":[{\"bufferView\":4,\"mimeType\":\"image/png\"}],");
    tn__text_add(&js, "\"buffers\":[{\"byteLength\":%lu}],\"bufferViews\":[", (unsigned long)binlen);
    tn__text_add(&js, "{\"buffer\":0,\"byteOffset\":%lu,\"byteLength\":%lu,\"target\":34962},", (unsigned long)off[0], (unsigned long)(nv * 12));
    tn__text_add(&js, "{\"buffer\":0,\"byteOffset\":%lu,\"byteLength\":%lu,\"target\":34962},", (unsigned long)off[1], (unsigned long)(nv * 12));
    tn__text_add(&js, "{\"buffer\":0,\"byteOffset\":%lu,\"byteLength\":%lu,\"target\":34962},", (unsigned long)off[2], (unsigned long)(nv * 8));
    tn__text_add(&js, "{\"buffer\":0,\"byteOffset\":%lu,\"byteLength\":%lu,\"target\":34963}", (unsigned long)off[3], (unsigned long)(ni * 4));
    if (png) tn__text_add(&js, ",{\"buffer\":0,\"byteOffset\":%lu,\"byteLength\":%lu}", (unsigned long)off[4], (unsigned long)png_n);
    tn__text_add(&js, "],\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":%lu,\"type\":\"VEC3\",\"min\":[", (unsigned long)nv);
    for (k = 0; k < 3; k++) {
        tn__text_num(&js, m.lo[k]);
        tn__text_add(&js, k < 2 ? "," : "],\"max\":[");
    }
    for (k = 0; k < 3; k++) {
        tn__text_num(&js, m.hi[k]);
        tn__text_add(&js, k < 2 ? "," : "]},");
    }
    tn__text_add(&js, "{\"bufferView\":1,\"componentType\":5126,\"count\":%lu,\"type\":\"VEC3\"},", (unsigned long)nv);
    tn__text_add(&js, "{\"bufferView\":2,\"componentType\":5126,\"count\":%lu,\"type\":\"VEC2\"},", (unsigned long)nv);
    tn__text_add(&js, "{\"bufferView\":3,\"componentType\":5125,\"count\":%lu,\"type\":\"SCALAR\"}]}", (unsigned long)ni);
    jpad = (js.n + 3) & ~(size_t)3;
    bpad = (binlen + 3) & ~(size_t)3;
    total = 12 + 8 + jpad + 8 + bpad;
    if (js.failed) st = tn__fail(TN_ERR_OUT_OF_MEMORY, "%s: out of memory", path);
    else if (total > 0xffffffffu || total > TN_MAX_ALLOC) st = tn__fail(TN_ERR_TOO_LARGE, "%s: over 4 GiB, the .glb limit (use a step)", path);
    else if (!(out = (uint8_t *)tn__alloc(total)) || !(bin = (uint8_t *)tn__alloc(binlen))) st = tn__fail_context(TN_ERR_OUT_OF_MEMORY, path);
    if (!st) {
        size_t i;
        for (i = 0; i < 3 * nv; i++) tn__put_f32(bin + off[0] + 4 * i, m.pos[i]);
        for (i = 0; i < 3 * nv; i++) tn__put_f32(bin + off[1] + 4 * i, m.nrm[i]);
        for (i = 0; i < 2 * nv; i++) tn__put_f32(bin + off[2] + 4 * i, m.uv[i]);
        for (i = 0; i < ni; i++) tn__put_u32(bin + off[3] + 4 * i, m.idx[i]);
        if (png_n) memcpy(bin + off[4], png, png_n);
        memcpy(out, "glTF", 4);
        tn__put_u32(out + 4, 2);
        tn__put_u32(out + 8, (uint32_t)total);
        pos = 12;
        tn__glb_put_chunk(out, &pos, "JSON", (const uint8_t *)js.s, js.n, jpad, ' ');
        tn__glb_put_chunk(out, &pos, "BIN\0", bin, binlen, bpad, 0);
        st = tn__io_write_atomic(path, out, total);
    }
    TN_FREE(out);
    TN_FREE(bin);
    TN_FREE(js.s);
    tn_free(png);
    tn__mesh_free(&m);
    return st;
}

/* path without its extension (a copy). */
static char *tn__path_stem(const char *path)
{
    const char *dot = strrchr(path, '.'), *slash = strrchr(path, '/');
    size_t n = dot && (!slash || dot > slash) ? (size_t)(dot - path) : strlen(path);
    return tn__strndup(path, n);
}

TN_API tn_status tn_export_obj(const tn_image *dem, const char *path, const tn_mesh_opts *opts)
{
    tn_mesh_opts o;
    tn__mesh m;
    tn__text t = {NULL, 0, 0, 0};
    char *stem = NULL;
    const char *leaf;
    size_t nv, i;
    tn_status st;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    tn__mesh_opts_defaults(&o);
    if ((st = tn__mesh_check(dem, &o, path))) return st;
    if ((st = tn__mesh_build(dem, &o, &m, path))) return st;
    if (!(stem = tn__path_stem(path))) {
        tn__mesh_free(&m);
        return tn__fail_context(TN_ERR_OUT_OF_MEMORY, path);
    }
    leaf = strrchr(stem, '/') ? strrchr(stem, '/') + 1 : stem;
    nv = (size_t)m.nx * m.ny;
    tn__text_add(&t, "# terrainnet %s: %d x %d grid, y up, metres\n", TN_VERSION_STRING, m.nx, m.ny);
    if (o.texture) tn__text_add(&t, "mtllib %s.mtl\nusemtl terrain\n", leaf);
    for (i = 0; i < nv && !t.failed; i++) {
        tn__text_add(&t, "v ");
        tn__text_num(&t, m.pos[3 * i]);
        tn__text_add(&t, " ");
        tn__text_num(&t, m.pos[3 * i + 1]);
        tn__text_add(&t, " ");
        tn__text_num(&t, m.pos[3 * i + 2]);
        tn__text_add(&t, "\nvt ");
        tn__text_num(&t, m.uv[2 * i]);
        tn__text_add(&t, " ");
        tn__text_num(&t, 1.0f - m.uv[2 * i + 1]); /* OBJ's v points up the image */
        tn__text_add(&t, "\nvn ");
        tn__text_num(&t, m.nrm[3 * i]);
        tn__text_add(&t, " ");
        tn__text_num(&t, m.nrm[3 * i + 1]);
        tn__text_add(&t, " ");
        tn__text_num(&t, m.nrm[3 * i + 2]);
        tn__text_add(&t, "\n");
    }
    for (i = 0; i < (size_t)(m.nx - 1) * (m.ny - 1) * 2 && !t.failed; i++) {
        const uint32_t *f = m.idx + 3 * i;
        tn__text_add(&t, "f %lu/%lu/%lu %lu/%lu/%lu %lu/%lu/%lu\n", (unsigned long)f[0] + 1, (unsigned long)f[0] + 1, (unsigned long)f[0] + 1,
                     (unsigned long)f[1] + 1, (unsigned long)f[1] + 1, (unsigned long)f[1] + 1, (unsigned long)f[2] + 1,
                     (unsigned long)f[2] + 1, (unsigned long)f[2] + 1);
    }
    if (t.failed) st = tn__fail(TN_ERR_TOO_LARGE, "%s: the OBJ text is too large for memory (use a step)", path);
    if (!st && o.texture) { /* the material and its image beside the mesh */
        tn__text mtl = {NULL, 0, 0, 0};
        uint8_t *png = NULL;
        size_t png_n = 0, sl = strlen(stem);
        char *mp = (char *)tn__alloc(sl + 5);
        if (!mp) st = TN_ERR_OUT_OF_MEMORY;
        if (!st) st = tn__mesh_texture_png(o.texture, &png, &png_n);
        if (!st) {
            memcpy(mp, stem, sl);
            memcpy(mp + sl, ".png", 5);
            st = tn__io_write_atomic(mp, png, png_n);
        }
        if (!st) {
            tn__text_add(&mtl, "newmtl terrain\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nmap_Kd %s.png\n", leaf);
            memcpy(mp + sl, ".mtl", 5);
            st = mtl.failed ? TN_ERR_OUT_OF_MEMORY : tn__io_write_atomic(mp, (const uint8_t *)mtl.s, mtl.n);
        }
        tn_free(png);
        TN_FREE(mtl.s);
        TN_FREE(mp);
    }
    if (!st) st = tn__io_write_atomic(path, (const uint8_t *)t.s, t.n);
    TN_FREE(t.s);
    TN_FREE(stem);
    tn__mesh_free(&m);
    return st;
}

TN_API tn_status tn_normal_map(const tn_image *dem, float dx, float dy, float z_scale, int directx, tn_image *out)
{
    tn_image n = {0, 0, 0, NULL};
    size_t i, np;
    float lo, hi;
    tn_status st;
    TN_ASSERT(out);
    if (dem && dem->data && tn_image_range(dem, &lo, &hi)) return tn__fail(TN_ERR_NUMERIC, "normal map: the DEM holds NaN/Inf");
    if ((st = tn_image_normals(&n, dem, dx, dy, z_scale))) return st;
    np = (size_t)n.width * n.height;
    for (i = 0; i < np; i++) {
        float *p = n.data + 3 * i;
        if (directx) p[1] = -p[1];
        p[0] = 0.5f * p[0] + 0.5f;
        p[1] = 0.5f * p[1] + 0.5f;
        p[2] = 0.5f * p[2] + 0.5f;
    }
    *out = n;
    return TN_OK;
}

TN_API tn_status tn_export_unity_raw(const tn_image *dem, const char *path, int size, float *lo, float *hi)
{
    tn_image r = {0, 0, 0, NULL};
    const tn_image *src = dem;
    uint8_t *buf;
    float a, b;
    size_t i, np;
    tn_status st = TN_OK;
    int big;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "unity raw: empty path");
    if (!dem || !dem->data || dem->width < 2 || dem->height < 2) return tn__fail(TN_ERR_EMPTY, "%s: the DEM must be at least 2 x 2", path);
    big = dem->width > dem->height ? dem->width : dem->height;
    if (size == 0)
        for (size = 33; size < big && size < 4097; size = 2 * size - 1) {}
    if (size < 33 || size > 4097 || ((size - 1) & (size - 2)) != 0)
        return tn__fail(TN_ERR_INVALID_ARG, "%s: Unity RAW size %d is not 2^n + 1 in 33..4097", path, size);
    if (tn_image_range(dem, &a, &b)) return tn__fail(TN_ERR_NUMERIC, "%s: the DEM holds NaN/Inf", path);
    if (dem->width != size || dem->height != size || dem->channels != 1) {
        tn_image one = {0, 0, 0, NULL};
        if (dem->channels != 1) { /* channel 0 is the height */
            if ((st = tn_image_create(&one, dem->width, dem->height, 1))) return st;
            np = (size_t)dem->width * dem->height;
            for (i = 0; i < np; i++) one.data[i] = dem->data[i * dem->channels];
        }
        st = tn_image_resize(&r, dem->channels != 1 ? &one : dem, size, size, TN_RESIZE_BICUBIC);
        tn_image_free(&one);
        if (st) return st;
        src = &r;
    }
    np = (size_t)size * size;
    if (!(buf = (uint8_t *)tn__alloc(2 * np))) {
        tn_image_free(&r);
        return tn__fail_context(TN_ERR_OUT_OF_MEMORY, path);
    }
    for (i = 0; i < np; i++) { /* bicubic may overshoot the range a little: clamped */
        double t = b > a ? ((double)src->data[i] - a) / ((double)b - a) : 0.0;
        unsigned c = (unsigned)(65535.0 * (t < 0 ? 0 : t > 1 ? 1 : t) + 0.5);
        buf[2 * i] = (uint8_t)c;
        buf[2 * i + 1] = (uint8_t)(c >> 8);
    }
    st = tn__io_write_atomic(path, buf, 2 * np);
    TN_FREE(buf);
    tn_image_free(&r);
    if (!st && lo) *lo = a;
    if (!st && hi) *hi = b;
    return st;
}

#ifdef __cplusplus
}
#endif
#endif /* TERRAINNET_IMPLEMENTATION_DONE */
#endif /* TERRAINNET_IMPLEMENTATION */
