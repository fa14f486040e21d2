/* terrainnet.h - learn terrain from one example, synthesise terrain and textures on a CPU.
   Public domain / MIT-0 style: no warranty, use as you like.

RECIPE
    In exactly ONE C or C++ file:
        #define TERRAINNET_IMPLEMENTATION
        #include "terrainnet.h"
    Everywhere else just #include "terrainnet.h". Link with -lm and -pthread
    (or define TN_NO_THREADS to build without pthreads). A project with many programs compiles
    those two lines once as their own file (as the repository's src/terrainnet.c) and links the
    object into every program.

USAGE
    tn_image dem = {0};
    tn_image_info info;
    if (tn_image_load(&dem, "alps.png", &info) != TN_OK) {
        fprintf(stderr, "%s\n", tn_last_error());
        return 1;
    }
    tn_image shade = {0};
    tn_render_preview(&shade, &dem, NULL);        // hillshaded, colour-ramped RGB
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
    TN_IMPLEMENTATION_LINKED  ignore TERRAINNET_IMPLEMENTATION in this file: the program links a
                        separately compiled implementation (how the repository builds its examples)
    TN_INTERNALS        for the repository's tests and benches, not the API: declares the private
                        tn__ code of the internals block (after "end header file"), and makes
                        the implementation export it; define it both in the program and where
                        the implementation it links is compiled. Without it nothing changes.
    TN_NO_<PART>        compile a part out (declarations and code), as stb_image's STBI_NO_PNG:
                        TN_NO_STYLE, TN_NO_TEXGAN, TN_NO_SINGAN, TN_NO_GNN, TN_NO_SEASON,
                        TN_NO_WORLD, TN_NO_EXPORT, TN_NO_RENDER, TN_NO_EXTRACT, TN_NO_SKETCH,
                        TN_NO_NOISE, TN_NO_FINEDETAIL, and TN_NO_ENGINE (the tensor engine,
                        @@gemm ... @@train). A part that needs one compiled out stops the build
                        with #error naming it: @@world needs every generator and @@export;
                        @@style, @@texgan, @@singan, @@gnn and @@season need the engine;
                        @@style, @@texgan and @@season need @@noise; @@style and @@gnn need
                        @@extract, which needs @@sketch; @@gnn needs @@finedetail; @@method
                        (in with the engine) lists the learned methods compiled in. @@core,
                        @@thread, @@image, @@io and @@metrics are always in.
                        All of them but RENDER: about a fifth of the full size.
    TN_MAX_ALLOC        largest single allocation sized from user data (default 8 GiB; 2 GiB on
                        32-bit targets); larger requests fail with TN_ERR_TOO_LARGE

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
    wanted) last: tn_image_load(&img, path, &info), tn_render_preview(&out, &dem, &opts). A struct
    the call fills (a new tn_image, a model being trained or loaded) is an output. Calls older
    than this rule that take their output first (tn_image_crop(dst, src, ...), the other image
    operations, noise makers, tn_style_transfer, tn_texgan_train/load, tn_detail_maps_*) keep
    their order for now.

TABLE OF CONTENTS (grep for the tag; each appears once in the declarations, once in the code)
    @@core      status codes, errors, allocation, RNG, progress, timing
    @@thread    thread pool and parallel-for
    @@image     tn_image, crop/pad/resize, blur, gradients, normals, hillshade, colours, height steps
    @@io        file formats: PNG (own inflate/deflate), GeoTIFF, PGM/PPM, PFM, SRTM .hgt, .asc, .r16
    @@metrics   SSIM, PSNR, RMSE, MAE
    @@gemm      SGEMM: packed, cache-blocked, AVX-512 / AVX2 / portable kernels, threaded
    @@tensor    tensors, arena contexts, the autograd tape
    @@ops       differentiable ops: broadcasting arithmetic, conv (im2col), pooling, norms, graph ops
    @@loss      MSE, L1, BCE, hinge and non-saturating GAN, Gram, TV, SSIM, gradient difference
    @@optim     parameters, .tnw files, Adam / SGD / L-BFGS
    @@train     training runs (budget, progress, checkpoints, resume), model files, shared blocks
    @@noise     procedural maps: Perlin fBm, explicit multi-scale noise, drawn-map blending
    @@finedetail  detail by example: a terrain's low-pass plus an example DEM's fine detail, patch-matched
    @@sketch    contour sets, .tns sketch files, drawn sketches, random sketches, parts, alignment
    @@extract   ridges and valleys from a DEM: fill, D8, accumulation, Strahler, skeleton; realism
    @@style     terrain style transfer: built-in random-feature net or VGG-19, pyramid, L-BFGS/SGD/Adam
    @@texgan    single-texture spatial GAN, tiled huge textures, colour correction, detail maps
    @@singan    multi-scale single-image GAN (SinGAN): random terrain of any size, refinement, upscaling
    @@gnn       sketch-to-terrain graph network: example parts, bipartite graph, attention, membrane residual
    @@season    seasonal terrain: insolation with terrain shadows, climate (CSV, Koppen), seasonal textures, KPD network
    @@method    one interface for the learned methods: a descriptor each (train, save/load, windows), by name
    @@render    previews: hillshaded colour map and 3D perspective view
    @@export    for engines and 3D tools: .glb and OBJ meshes, normal maps, Unity RAW, splat maps
    @@world     worlds in tiles equal to a whole-map run: SPEC pipelines, halos, PNG tiles, GDAL VRT, manifest
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

