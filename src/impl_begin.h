#ifdef __cplusplus
}
#endif
#endif /* TERRAINNET_H */

/* //// end header file ////////////////////////////////////////////////////////////////////// */

#if defined(TERRAINNET_IMPLEMENTATION) && !defined(TN_IMPLEMENTATION_LINKED)
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
#if !defined(_WIN32) && (defined(__unix__) || defined(__APPLE__) || defined(__EMSCRIPTEN__))
#include <sys/time.h> /* gettimeofday: wall time where a strict C mode hides clock_gettime */
#define TN__HAVE_GETTIMEOFDAY 1
#endif

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

/* 8 GiB where size_t holds it; on 32-bit targets (wasm32, -m32) 8 << 30 wraps to 0 and every
   allocation would be refused, so the limit is 2 GiB, which such a process cannot reach anyway. */
#ifndef TN_MAX_ALLOC
#if SIZE_MAX > 0xffffffffu
#define TN_MAX_ALLOC ((size_t)8 << 30)
#else
#define TN_MAX_ALLOC ((size_t)1 << 31)
#endif
#endif

#if !defined(TN_NO_THREADS)
#include <pthread.h>
#include <unistd.h>
#endif

/* SIMD kernels (blur, SSIM, GEMM) when the compiler targets AVX-512 or AVX2+FMA; portable C otherwise. */
#if defined(__AVX512F__) || (defined(__AVX2__) && defined(__FMA__))
#include <immintrin.h>
#endif
/* >>gemm_bf16: cpuid at run time on x86 with GCC/clang; its AVX512-BF16 and AMX kernels carry
   target attributes (GCC >= 11, clang >= 12, x86-64), so they need the intrinsics whatever -m flags. */
#if (defined(__x86_64__) || defined(__i386__)) && (defined(__GNUC__) || defined(__clang__))
#include <cpuid.h>
#define TN__X86_CPUID 1
#if defined(__x86_64__) && ((defined(__clang__) && __clang_major__ >= 12) || (!defined(__clang__) && __GNUC__ >= 11))
#define TN__BF16_HW 1
#include <immintrin.h>
#endif
#endif

/* Static helpers that several sections share: with some sections compiled out (TN_NO_...), some
   go unused, which is not worth a warning. */
#if defined(__GNUC__) || defined(__clang__)
#define TN__SHARED static __attribute__((unused))
#else
#define TN__SHARED static
#endif
/* Private code that tests reach through the internals block (src/internal.h): static, unless the
   implementation is compiled with TN_INTERNALS for programs that link it (the Makefile's objects). */
#ifdef TN_INTERNALS
#define TN__INTERNAL
#define TN__INTERNAL_SHARED
#else
#define TN__INTERNAL static
#define TN__INTERNAL_SHARED TN__SHARED
#endif

#ifdef __cplusplus
extern "C" {
#endif

