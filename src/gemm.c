/* ============================================================================================
   @@gemm  single-precision matrix multiply (the engine under tensors and convolutions)
   ============================================================================================ */
#ifndef TN_NO_ENGINE

/* C = alpha * op(A) * op(B) + beta * C, all row-major. op(X) = X, or X^T when trans_x != 0.
   op(A) is M x K, op(B) is K x N, C is M x N; lda/ldb/ldc are row strides in floats (of A and B
   as stored, i.e. before op). beta == 0 means C is only written (it may hold NaN on entry).
   M, N or K == 0 is allowed (K == 0 gives C = beta * C). Runs on the terrainnet pool; the
   result is bit-identical for any thread count, because every C element is always summed over
   K in the same order (threads split only M or N). Never fails: if its packing scratch cannot
   be allocated it falls back to a slow unpacked loop. */
TN_API void tn_sgemm(int trans_a, int trans_b, int M, int N, int K, float alpha, const float *A, int lda,
                     const float *B, int ldb, float beta, float *C, int ldc);

/* Precision of the products under convolutions and dense layers (mixed precision: weights,
   gradients and optimiser state stay float32; only the GEMM operands become bfloat16).
   TN_PRECISION_FP32: tn_sgemm as above, the reference; forcing it gives exactly the bytes of
   terrainnet before bf16 existed. TN_PRECISION_BF16: A and B are rounded to bfloat16 (round to
   nearest even, bf16 subnormals flushed to zero) when packed, products are accumulated in
   float32 and C is float32. Run on AMX tiles (TDPBF16PS) when the CPU and OS allow them,
   else on AVX512-BF16 (VDPBF16PS), else emulated with float32 FMAs in VDPBF16PS's order (odd k
   of each pair first), so the emulation and AVX512-BF16 give the same bytes; AMX sums each
   pair in the other order, so its bytes differ (in the last bits). For a given CPU the bytes
   do not depend on the thread count. TN_PRECISION_AUTO (the zero value, the default) is FP32
   for now; compile with TN_AUTO_BF16=1 to make it BF16 on CPUs with AMX-BF16 or AVX512-BF16.
   The setting is process-wide; change it between steps, not while a product runs. */
typedef enum { TN_PRECISION_AUTO = 0, TN_PRECISION_BF16, TN_PRECISION_FP32 } tn_precision;
TN_API void tn_set_precision(tn_precision p);
/* The setting as given (AUTO stays AUTO). */
TN_API tn_precision tn_get_precision(void);
/* What a setting means on this CPU: TN_PRECISION_BF16 or TN_PRECISION_FP32 (AUTO resolved;
   AUTO passed here means the process-wide setting). */
TN_API tn_precision tn_precision_resolve(tn_precision p);
/* "auto" / "bf16" / "fp32" <-> tn_precision; parse returns TN_ERR_INVALID_ARG for anything else. */
TN_API const char *tn_precision_name(tn_precision p);
TN_API tn_status tn_precision_parse(tn_precision *p, const char *s);

/* CPU features found at run time (cpuid, and the OS's consent for AVX-512 / AMX state). */
#define TN_CPU_AVX2 1u
#define TN_CPU_AVX512F 2u
#define TN_CPU_AVX512_BF16 4u
#define TN_CPU_AMX_BF16 8u /* tiles usable: cpuid AMX-TILE + AMX-BF16 and, on Linux, arch_prctl permission */
TN_API unsigned tn_cpu_features(void);
/* The kernel TN_PRECISION_BF16 runs on here: "amx-bf16", "avx512-bf16" or "emulated". */
TN_API const char *tn_gemm_bf16_kernel(void);

/* tn_sgemm in a given precision (AUTO: the process-wide setting). Same arguments and guarantees. */
TN_API void tn_gemm(tn_precision precision, int trans_a, int trans_b, int M, int N, int K, float alpha, const float *A,
                    int lda, const float *B, int ldb, float beta, float *C, int ldc);
#endif /* TN_NO_ENGINE */

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
#ifndef TN_NO_ENGINE

/* The micro-tile, TN__GEMM_MR x TN__GEMM_NR (two vectors of TN__GEMM_VW), and the K block
   TN__GEMM_KC are in src/internal.h, where test_bf16 sees them too. */
#if defined(__AVX512F__)
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
#define TN__GEMM_ROWS(X) X(0) X(1) X(2) X(3) X(4) X(5)
#define TN__V __m256
#define TN__VZERO() _mm256_setzero_ps()
#define TN__VSET(x) _mm256_set1_ps(x)
#define TN__VLOAD(p) _mm256_load_ps(p)
#define TN__VLOADU(p) _mm256_loadu_ps(p)
#define TN__VSTOREU(p, v) _mm256_storeu_ps(p, v)
#define TN__VMUL(a, b) _mm256_mul_ps(a, b)
#define TN__VFMA(a, b, c) _mm256_fmadd_ps(a, b, c)
#endif

/* Block sizes (floats) for Zen 4 (32K L1D, 1M L2): an A micro-panel (MR x KC, 12 KiB) fits in
   L1, the packed B block (KC x NC, 384 KiB) in L2, the packed A block (MC x KC) in L2/L3.
   Measured KC 256..576, NC 192..512, MC 256..2048: all within ~3% of each other; KC 256 or
   NC 512 lose a little on the convolution shape. */
/* TN__GEMM_KC 384: src/internal.h */
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
TN__INTERNAL void tn__gemm_pack_a(int trans, const float *A, int lda, int i0, int mc, int k0, int kc, float *pa)
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
TN__INTERNAL size_t tn__gemm_b_stride(int kc) { return (size_t)kc * TN__GEMM_NR + 16; }

/* Packs op(B)[k0 .. k0+kc) x [j0 .. j0+nc) as NR-column micro-panels (panel q/NR starts at
   pb + (q/NR) * tn__gemm_b_stride(kc), element (k, j) at k*NR + j); columns past nc are zero.
   Source rows are read whole, so the hardware prefetcher streams them. */
TN__INTERNAL void tn__gemm_pack_b(int trans, const float *B, int ldb, int k0, int kc, int j0, int nc, float *pb)
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
    int kern;      /* TN__KERN_*: float32, or which bf16 kernel */
} tn__gemm_job;

/* The product's kernels: float32, and the bf16 ones of >>gemm_bf16 (below), which the driver
   reaches through these few functions (their TN__KERN_ names: src/internal.h). */
typedef void (*tn__gemm_kernel_fn)(int kc, const float *pa, const float *pb, float *c, int ldc, float alpha, float beta);
static int tn__gemm_kern(tn_precision p);
TN__INTERNAL float tn__bf16_round(float f);
TN__INTERNAL void tn__gemm_bf16_prep(int kern, float *p, int panels, size_t stride, int kc, int w);
static tn__gemm_kernel_fn tn__gemm_bf16_kernel_fn(int kern);
#ifdef TN__BF16_HW
/* AMX scratch per slot, in bf16 halves: the A block as rows of KP, then the B block */
#define TN__AMX_KP ((TN__GEMM_KC + 31) / 32 * 32)
#define TN__AMX_A_HALVES ((size_t)((TN__GEMM_MC + 31) / 32 * 32) * TN__AMX_KP)
#define TN__AMX_B_HALVES ((size_t)((TN__GEMM_NC + 31) / 32 * 32) * TN__AMX_KP)
static uint16_t *tn__gemm_amx_scratch(int *slot);
static void tn__gemm_amx_pack_a(const tn__gemm_job *g, int ic, int mc, int pc, int kc, float *pa, uint16_t *ta);
static void tn__gemm_amx_block(const tn__gemm_job *g, int ic, int mc, int pc, int jc, int nc, int kc, const uint16_t *ta,
                               const float *pb, uint16_t *tb, float beta);
#endif

static float tn__gemm_get(const float *X, int ld, int trans, int r, int c)
{
    return trans ? X[(size_t)c * ld + r] : X[(size_t)r * ld + c];
}

/* Unpacked loops for tiny products, single-row products and the out-of-memory fallback: rows
   [m0, m1) x columns [n0, n1) of C. With op(B) rows contiguous it adds scaled rows of op(B)
   (vectorisable); otherwise it takes dot products. */
static void tn__gemm_simple(const tn__gemm_job *g, int m0, int m1, int n0, int n1)
{
    int i, j, k, bf = g->kern != TN__KERN_FP32; /* bf16: operands rounded as they are read */
    for (i = m0; i < m1; i++) {
        float *crow = g->C + (size_t)i * g->ldc;
        if (!g->trans_b) {
            for (j = n0; j < n1; j++) crow[j] = g->beta == 0.0f ? 0.0f : g->beta * crow[j];
            for (k = 0; k < g->K; k++) {
                float a = tn__gemm_get(g->A, g->lda, g->trans_a, i, k);
                const float *brow = g->B + (size_t)k * g->ldb;
                if (bf) {
                    a = g->alpha * tn__bf16_round(a);
                    for (j = n0; j < n1; j++) crow[j] += a * tn__bf16_round(brow[j]);
                    continue;
                }
                a *= g->alpha;
                for (j = n0; j < n1; j++) crow[j] += a * brow[j];
            }
        } else {
            for (j = n0; j < n1; j++) {
                const float *bcol = g->B + (size_t)j * g->ldb; /* op(B)(k, j) = bcol[k] */
                float s = 0.0f;
                if (bf)
                    for (k = 0; k < g->K; k++)
                        s += tn__bf16_round(tn__gemm_get(g->A, g->lda, g->trans_a, i, k)) * tn__bf16_round(bcol[k]);
                else
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
   K block. kern: TN__KERN_FP32, or a bf16 kernel that reads the same panels (converted). */
static void tn__gemm_macro(const tn__gemm_job *g, int kern, int ic, int mc, int jc, int nc, int kc, const float *pa,
                           const float *pb, float beta)
{
    float tile[TN__GEMM_MR * TN__GEMM_NR];
    int p, q, i, j;
    if (kern != TN__KERN_FP32 && kern != TN__KERN_EMU) { /* the emulation is the float32 kernel */
        tn__gemm_kernel_fn kernel = tn__gemm_bf16_kernel_fn(kern);
        for (p = 0; p < mc; p += TN__GEMM_MR)
            for (q = 0; q < nc; q += TN__GEMM_NR) {
                int mr = mc - p < TN__GEMM_MR ? mc - p : TN__GEMM_MR, nr = nc - q < TN__GEMM_NR ? nc - q : TN__GEMM_NR;
                const float *ap = pa + (size_t)p * kc, *bp = pb + (size_t)(q / TN__GEMM_NR) * tn__gemm_b_stride(kc);
                float *c = g->C + (size_t)(ic + p) * g->ldc + jc + q;
                if (mr == TN__GEMM_MR && nr == TN__GEMM_NR) {
                    kernel(kc, ap, bp, c, g->ldc, g->alpha, beta);
                    continue;
                }
                kernel(kc, ap, bp, tile, TN__GEMM_NR, 1.0f, 0.0f);
                for (i = 0; i < mr; i++)
                    for (j = 0; j < nr; j++) {
                        float *cij = c + (size_t)i * g->ldc + j;
                        float t = g->alpha * tile[i * TN__GEMM_NR + j];
                        *cij = beta == 0.0f ? t : t + beta * *cij;
                    }
            }
        return;
    }
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
    int ic, pc, jc, kern = g->kern, slot = -1;
#ifdef TN__BF16_HW
    uint16_t *ta = NULL; /* AMX: its own copies of the blocks (A, then B) */
    if (kern == TN__KERN_AMX && !(ta = tn__gemm_amx_scratch(&slot))) kern = TN__KERN_EMU; /* out of memory */
#endif
    for (ic = m0; ic < m1; ic += TN__GEMM_MC) {
        int mc = m1 - ic < TN__GEMM_MC ? m1 - ic : TN__GEMM_MC;
        for (pc = 0; pc < g->K; pc += kcb) {
            int kc = g->K - pc < kcb ? g->K - pc : kcb;
            float beta = pc == 0 ? g->beta : 1.0f; /* later K blocks accumulate into C */
#ifdef TN__BF16_HW
            if (kern == TN__KERN_AMX) { /* bf16 copies straight from A and B (B: from the callback's panels) */
                tn__gemm_amx_pack_a(g, ic, mc, pc, kc, pa, ta);
                for (jc = n0; jc < n1; jc += TN__GEMM_NC) {
                    int nc = n1 - jc < TN__GEMM_NC ? n1 - jc : TN__GEMM_NC;
                    if (g->pack_b) g->pack_b(g->pack_ctx, pc, kc, jc, nc, pb);
                    tn__gemm_amx_block(g, ic, mc, pc, jc, nc, kc, ta, g->pack_b ? pb : NULL, ta + TN__AMX_A_HALVES, beta);
                }
                continue;
            }
#endif
            tn__gemm_pack_a(g->trans_a, g->A, g->lda, ic, mc, pc, kc, pa);
            if (kern != TN__KERN_FP32)
                tn__gemm_bf16_prep(kern, pa, (mc + TN__GEMM_MR - 1) / TN__GEMM_MR, (size_t)kc * TN__GEMM_MR, kc, TN__GEMM_MR);
            for (jc = n0; jc < n1; jc += TN__GEMM_NC) {
                int nc = n1 - jc < TN__GEMM_NC ? n1 - jc : TN__GEMM_NC;
                if (g->pack_b) g->pack_b(g->pack_ctx, pc, kc, jc, nc, pb);
                else tn__gemm_pack_b(g->trans_b, g->B, g->ldb, pc, kc, jc, nc, pb);
                if (kern != TN__KERN_FP32)
                    tn__gemm_bf16_prep(kern, pb, (nc + TN__GEMM_NR - 1) / TN__GEMM_NR, tn__gemm_b_stride(kc), kc, TN__GEMM_NR);
                tn__gemm_macro(g, kern, ic, mc, jc, nc, kc, pa, pb, beta);
            }
        }
    }
    if (slot >= 0) tn__gemm_release_slot(slot);
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

TN_API void tn_gemm(tn_precision precision, int trans_a, int trans_b, int M, int N, int K, float alpha, const float *A,
                    int lda, const float *B, int ldb, float beta, float *C, int ldc)
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
    g.kern = tn__gemm_kern(precision);
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

TN_API void tn_sgemm(int trans_a, int trans_b, int M, int N, int K, float alpha, const float *A, int lda,
                     const float *B, int ldb, float beta, float *C, int ldc)
{
    tn_gemm(TN_PRECISION_FP32, trans_a, trans_b, M, N, K, alpha, A, lda, B, ldb, beta, C, ldc);
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
   region; results are the same as tn_gemm(TN_PRECISION_AUTO, ...)'s for the same B. */
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
    g.kern = tn__gemm_kern(TN_PRECISION_AUTO);
    if (M > 0 && N > 0 && K > 0) tn__gemm_blocked(&g, 0, M, 0, N, buf, buf + (rows * TN__GEMM_KC + 15) / 16 * 16);
}

/* --------------------------------------------------------------------------------------------
   >>gemm_bf16  (part of @@gemm implementation: bfloat16 operands, float32 accumulation)
   The driver above packs A and B in float32 whatever the precision (so the transposes and the
   convolution's own packing serve both); a bf16 product then converts each packed block once, in
   the layout its kernel reads. Operands are rounded to nearest even, bf16 subnormals to zero.
   - emulated (any CPU): in place, values rounded and the rows of each k pair swapped, so the
     float32 kernel's sequential FMAs take k = 1, 0, 3, 2, ...: the order of VDPBF16PS (Intel SDM:
     the odd product of a pair is added first). A product of two bf16 is exact in float32, so each
     FMA rounds exactly as VDPBF16PS's additions do; the two agree bit for bit except for float32
     subnormal sums (VDPBF16PS flushes them) and the sign of a zero.
   - AVX512-BF16: in place, each k pair of bf16 in one 32-bit word (k even in the low half), the
     float32 kernel's MR x NR tiles with VDPBF16PS.
   - AMX: A rows and B pair rows copied into 16 x 32 bf16 tiles, 32 x 32 blocks of C in four
     16 x 16 float32 tiles with TDPBF16PS (which adds a pair's even product first).
   The AVX512-BF16 and AMX kernels carry target attributes and are chosen by cpuid at run time.
   Every kernel sums each C element over k in an order fixed by K alone, as the float32 path does.
   -------------------------------------------------------------------------------------------- */

static int tn__precision_setting = TN_PRECISION_AUTO;
static unsigned tn__cpu_flags;
static int tn__cpu_probed;
/* Tests: run bf16 products on this kernel (TN__KERN_EMU ...) instead of the best one, when the
   CPU has it; 0 = the best. */
TN__INTERNAL int tn__gemm_bf16_force;

#ifdef TN__X86_CPUID
static unsigned long long tn__xgetbv0(void)
{
    unsigned lo, hi;
    __asm__ __volatile__("xgetbv" : "=a"(lo), "=d"(hi) : "c"(0));
    return ((unsigned long long)hi << 32) | lo;
}
#endif

#if defined(TN__BF16_HW) && defined(__linux__)
/* arch_prctl(ARCH_REQ_XCOMP_PERM, XFEATURE_XTILEDATA): Linux (>= 5.16) gives a process the AMX
   tile state only when asked. A raw syscall (158): glibc has no wrapper. 0 when granted. */
static long tn__amx_request(void)
{
    long ret;
    __asm__ __volatile__("syscall" : "=a"(ret) : "0"(158L), "D"(0x1023L), "S"(18L) : "rcx", "r11", "memory");
    return ret;
}
#endif

TN_API unsigned tn_cpu_features(void)
{
    if (!tn__cpu_probed) {
        unsigned f = 0;
#ifdef TN__X86_CPUID
        unsigned a, b, c, d;
        if (__get_cpuid_max(0, NULL) >= 7 && __get_cpuid(1, &a, &b, &c, &d) && (c >> 27 & 1u)) { /* OSXSAVE */
            unsigned long long xcr0 = tn__xgetbv0();
            __cpuid_count(7, 0, a, b, c, d);
            if ((xcr0 & 6u) == 6u && (b >> 5 & 1u)) f |= TN_CPU_AVX2;
            if ((xcr0 & 0xe6u) == 0xe6u && (b >> 16 & 1u)) { /* ZMM and opmask state enabled */
                unsigned a1, b1, c1, d1;
                f |= TN_CPU_AVX512F;
                __cpuid_count(7, 1, a1, b1, c1, d1);
                if (a1 >> 5 & 1u) f |= TN_CPU_AVX512_BF16;
                (void)b1;
                (void)c1;
                (void)d1;
            }
#if defined(TN__BF16_HW) && defined(__linux__)
            /* AMX-BF16 (edx 22), AMX-TILE (edx 24), XTILECFG + XTILEDATA in XCR0, and permission */
            if ((d >> 22 & 1u) && (d >> 24 & 1u) && (xcr0 & 0x60000u) == 0x60000u && tn__amx_request() == 0)
                f |= TN_CPU_AMX_BF16;
#endif
        }
#endif
        tn__cpu_flags = f;
        tn__cpu_probed = 1;
    }
    return tn__cpu_flags;
}

/* The best bf16 kernel this CPU (and this compiler) has. */
static int tn__gemm_bf16_best(void)
{
    int k = TN__KERN_EMU, force = tn__gemm_bf16_force;
#ifdef TN__BF16_HW
    unsigned f = tn_cpu_features();
    if (f & TN_CPU_AMX_BF16) k = TN__KERN_AMX;
    else if (f & TN_CPU_AVX512_BF16) k = TN__KERN_AVX512BF16;
    if (force == TN__KERN_EMU || (force == TN__KERN_AVX512BF16 && (f & TN_CPU_AVX512_BF16))) k = force;
#else
    (void)force; /* the emulation is the only kernel */
#endif
    return k;
}

TN_API const char *tn_gemm_bf16_kernel(void)
{
    int k = tn__gemm_bf16_best();
    return k == TN__KERN_AMX ? "amx-bf16" : k == TN__KERN_AVX512BF16 ? "avx512-bf16" : "emulated";
}

TN_API void tn_set_precision(tn_precision p)
{
    TN_ASSERT(p == TN_PRECISION_AUTO || p == TN_PRECISION_BF16 || p == TN_PRECISION_FP32);
    tn__precision_setting = (int)p;
}

TN_API tn_precision tn_get_precision(void) { return (tn_precision)tn__precision_setting; }

TN_API tn_precision tn_precision_resolve(tn_precision p)
{
    if (p == TN_PRECISION_AUTO) p = (tn_precision)tn__precision_setting;
    if (p == TN_PRECISION_AUTO) {
#if defined(TN_AUTO_BF16) && TN_AUTO_BF16
        p = tn_cpu_features() & (TN_CPU_AVX512_BF16 | TN_CPU_AMX_BF16) ? TN_PRECISION_BF16 : TN_PRECISION_FP32;
#else
        p = TN_PRECISION_FP32; /* until bf16 training is validated on the matrix units */
#endif
    }
    return p;
}

TN_API const char *tn_precision_name(tn_precision p)
{
    return p == TN_PRECISION_BF16 ? "bf16" : p == TN_PRECISION_FP32 ? "fp32" : "auto";
}

TN_API tn_status tn_precision_parse(tn_precision *p, const char *s)
{
    if (s && !strcmp(s, "auto")) *p = TN_PRECISION_AUTO;
    else if (s && !strcmp(s, "bf16")) *p = TN_PRECISION_BF16;
    else if (s && !strcmp(s, "fp32")) *p = TN_PRECISION_FP32;
    else return tn__fail(TN_ERR_INVALID_ARG, "precision '%s': expected auto, bf16 or fp32", s ? s : "(null)");
    return TN_OK;
}

static int tn__gemm_kern(tn_precision p)
{
    return tn_precision_resolve(p) == TN_PRECISION_BF16 ? tn__gemm_bf16_best() : TN__KERN_FP32;
}

/* The bf16 nearest to f (ties to even), as the upper half of float32 bits; subnormals become
   zeros of their sign (the matrix units treat bf16 subnormals as zero), NaN stays a quiet NaN. */
TN__INTERNAL uint32_t tn__bf16_bits(float f)
{
    uint32_t u, r;
    memcpy(&u, &f, sizeof u);
    r = (u + 0x7fffu + (u >> 16 & 1u)) & 0xffff0000u; /* carries into the exponent, up to infinity */
    r = u & 0x7f800000u ? r : u & 0x80000000u;
    return (u & 0x7fffffffu) > 0x7f800000u ? (u | 0x00400000u) & 0xffff0000u : r; /* selects: vectorises */
}

TN__INTERNAL float tn__bf16_round(float f)
{
    uint32_t u = tn__bf16_bits(f);
    memcpy(&f, &u, sizeof f);
    return f;
}

#ifdef __AVX2__
/* tn__bf16_bits of 8 floats: the same selects, in integer lanes. */
static __m256i tn__bf16_bits8(__m256 x)
{
    __m256i u = _mm256_castps_si256(x), hi = _mm256_set1_epi32((int)0xffff0000u);
    __m256i lsb = _mm256_and_si256(_mm256_srli_epi32(u, 16), _mm256_set1_epi32(1));
    __m256i r = _mm256_and_si256(_mm256_add_epi32(u, _mm256_add_epi32(lsb, _mm256_set1_epi32(0x7fff))), hi);
    __m256i sub = _mm256_cmpeq_epi32(_mm256_and_si256(u, _mm256_set1_epi32(0x7f800000)), _mm256_setzero_si256());
    __m256i nan = _mm256_cmpgt_epi32(_mm256_and_si256(u, _mm256_set1_epi32(0x7fffffff)), _mm256_set1_epi32(0x7f800000));
    r = _mm256_blendv_epi8(r, _mm256_and_si256(u, _mm256_set1_epi32((int)0x80000000u)), sub);
    return _mm256_blendv_epi8(r, _mm256_and_si256(_mm256_or_si256(u, _mm256_set1_epi32(0x00400000)), hi), nan);
}
#endif

/* x[0 .. n) rounded to bf16 in place. */
TN__INTERNAL void tn__bf16_round_n(float *x, size_t n)
{
    size_t i = 0;
#ifdef __AVX2__
    for (; i + 8 <= n; i += 8) _mm256_storeu_ps(x + i, _mm256_castsi256_ps(tn__bf16_bits8(_mm256_loadu_ps(x + i))));
#endif
    for (; i < n; i++) x[i] = tn__bf16_round(x[i]);
}

#ifdef TN__BF16_HW
/* out[j] = bf16(x[j]) for j < n, 32 at a time; returns n. */
__attribute__((target("avx512f,avx512bw,avx512bf16"))) static int tn__bf16_halves512(const float *x, uint16_t *out, int n)
{
    int j;
    for (j = 0; j + 32 <= n; j += 32)
        _mm512_storeu_si512((void *)(out + j), (__m512i)_mm512_cvtne2ps_pbh(_mm512_loadu_ps(x + j + 16), _mm512_loadu_ps(x + j)));
    if (j < n) { /* the tail, masked (rows of 26 .. 260 values: tails matter) */
        __mmask32 k = (__mmask32)(((uint64_t)1 << (n - j)) - 1u);
        __m512 lo = _mm512_maskz_loadu_ps((__mmask16)k, x + j), hi = _mm512_maskz_loadu_ps((__mmask16)(k >> 16), x + j + 16);
        _mm512_mask_storeu_epi16((void *)(out + j), k, (__m512i)_mm512_cvtne2ps_pbh(hi, lo));
    }
    return n;
}

/* out[j] = the bf16 of x[j] (tn__bf16_bits's upper half), j < n. (Only the AMX paths use it.) */
static void tn__bf16_halves(const float *x, uint16_t *out, int n)
{
    int j = 0;
    if (tn__cpu_flags & TN_CPU_AVX512_BF16) j = tn__bf16_halves512(x, out, n);
    for (; j < n; j++) out[j] = (uint16_t)(tn__bf16_bits(x[j]) >> 16);
}
#endif

#ifdef TN__BF16_HW
/* tn__bf16_pair_words with VCVTNE2PS2BF16: round to nearest even, subnormal inputs to zeros of
   their sign, NaN quieted (Intel SDM, convert_fp32_to_bfloat16): tn__bf16_bits's bytes, which
   test_bf16_amx checks. Returns w. */
__attribute__((target("avx512f,avx512bw,avx512bf16"))) static int tn__bf16_pair_words512(const float *r0, const float *r1,
                                                                                            void *out, int w)
{
    const __m512i inter = _mm512_set_epi16(31, 15, 30, 14, 29, 13, 28, 12, 27, 11, 26, 10, 25, 9, 24, 8, 23, 7, 22, 6, 21, 5,
                                           20, 4, 19, 3, 18, 2, 17, 1, 16, 0);
    int j;
    for (j = 0; j + 16 <= w; j += 16) {
        __m512 hi = r1 ? _mm512_loadu_ps(r1 + j) : _mm512_setzero_ps();
        __m512i both = (__m512i)_mm512_cvtne2ps_pbh(hi, _mm512_loadu_ps(r0 + j)); /* r0's 16 low, r1's high */
        _mm512_storeu_si512((void *)((uint32_t *)out + j), _mm512_permutexvar_epi16(inter, both));
    }
    if (j < w) { /* the tail, masked */
        __mmask16 k = (__mmask16)((1u << (w - j)) - 1u);
        __m512 hi = r1 ? _mm512_maskz_loadu_ps(k, r1 + j) : _mm512_setzero_ps();
        __m512i both = (__m512i)_mm512_cvtne2ps_pbh(hi, _mm512_maskz_loadu_ps(k, r0 + j));
        _mm512_mask_storeu_epi32((void *)((uint32_t *)out + j), k, _mm512_permutexvar_epi16(inter, both));
    }
    return w;
}
#endif

/* out[j] = bf16(r0[j]) | bf16(r1[j]) << 16 for j < w (r1 NULL: zeros). out may be r0 itself (each
   group is read before it is written) but not r1. */
static void tn__bf16_pair_words(const float *r0, const float *r1, void *out, int w)
{
    int j = 0;
#ifdef TN__BF16_HW
    if (tn__cpu_flags & TN_CPU_AVX512_BF16) j = tn__bf16_pair_words512(r0, r1, out, w);
#endif
#ifdef __AVX2__
    for (; j + 8 <= w; j += 8) {
        __m256i lo = _mm256_srli_epi32(tn__bf16_bits8(_mm256_loadu_ps(r0 + j)), 16);
        __m256i up = r1 ? tn__bf16_bits8(_mm256_loadu_ps(r1 + j)) : _mm256_setzero_si256();
        _mm256_storeu_si256((__m256i *)(void *)((uint32_t *)out + j), _mm256_or_si256(lo, up));
    }
#endif
    for (; j < w; j++) {
        uint32_t word = tn__bf16_bits(r0[j]) >> 16 | (r1 ? tn__bf16_bits(r1[j]) : 0u);
        memcpy((uint32_t *)out + j, &word, sizeof word);
    }
}

/* Converts `panels` packed panels (stride floats apart, kc rows of w values each) in place:
   emulated, rows rounded and each k pair swapped; AVX512-BF16, k pairs as 32-bit words (row
   k/2 of w words at the panel's start; a pair is read before its words are written, and later
   pairs lie further on). */
TN__INTERNAL void tn__gemm_bf16_prep(int kern, float *p, int panels, size_t stride, int kc, int w)
{
    int q, k, j;
    TN_ASSERT(w == TN__GEMM_MR || w == TN__GEMM_NR);
    for (q = 0; q < panels; q++, p += stride) {
        if (kern == TN__KERN_EMU) {
            tn__bf16_round_n(p, (size_t)kc * w); /* a panel's rows are contiguous */
            for (k = 0; k + 1 < kc; k += 2) { /* swaps with fixed trip counts: unrolled, vectorised */
                float *r0 = p + (size_t)k * w, *r1 = r0 + w, t;
                if (w == TN__GEMM_NR)
                    for (j = 0; j < TN__GEMM_NR; j++) t = r0[j], r0[j] = r1[j], r1[j] = t;
                else
                    for (j = 0; j < TN__GEMM_MR; j++) t = r0[j], r0[j] = r1[j], r1[j] = t;
            }
            continue;
        }
        for (k = 0; k < kc; k += 2) /* pair 0's words land on its row k = 0 (allowed) */
            tn__bf16_pair_words(p + (size_t)k * w, k + 1 < kc ? p + (size_t)(k + 1) * w : NULL, p + (size_t)(k / 2) * w, w);
    }
}

#ifdef TN__BF16_HW
/* MR x NR tile from pair-packed panels (see tn__gemm_bf16_prep), same contract as tn__gemm_kernel
   (kc counts k, not pairs). */
__attribute__((target("avx512f,avx512bw,avx512bf16"))) static void
tn__gemm_kernel_avx512bf16(int kc, const float *pa_, const float *pb_, float *c, int ldc, float alpha, float beta)
{
    const uint32_t *pa = (const uint32_t *)(const void *)pa_, *pb = (const uint32_t *)(const void *)pb_;
    __m512 acc[TN__GEMM_MR][TN__GEMM_NR / 16], va = _mm512_set1_ps(alpha), vb = _mm512_set1_ps(beta);
    __m512i bv[TN__GEMM_NR / 16];
    int pairs = (kc + 1) / 2, p, i, v;
    for (i = 0; i < TN__GEMM_MR; i++)
        for (v = 0; v < TN__GEMM_NR / 16; v++) acc[i][v] = _mm512_setzero_ps();
    for (p = 0; p < pairs; p++, pa += TN__GEMM_MR, pb += TN__GEMM_NR) {
        for (v = 0; v < TN__GEMM_NR / 16; v++) bv[v] = _mm512_loadu_si512((const void *)(pb + 16 * v));
        for (i = 0; i < TN__GEMM_MR; i++) {
            __m512i a = _mm512_set1_epi32((int)pa[i]);
            for (v = 0; v < TN__GEMM_NR / 16; v++) acc[i][v] = _mm512_dpbf16_ps(acc[i][v], (__m512bh)a, (__m512bh)bv[v]);
        }
    }
    for (i = 0; i < TN__GEMM_MR; i++)
        for (v = 0; v < TN__GEMM_NR / 16; v++) {
            float *ci = c + (size_t)i * ldc + 16 * v;
            if (beta == 0.0f) _mm512_storeu_ps(ci, _mm512_mul_ps(acc[i][v], va));
            else _mm512_storeu_ps(ci, _mm512_fmadd_ps(acc[i][v], va, _mm512_mul_ps(vb, _mm512_loadu_ps(ci))));
        }
}
#endif

static tn__gemm_kernel_fn tn__gemm_bf16_kernel_fn(int kern)
{
#ifdef TN__BF16_HW
    if (kern == TN__KERN_AVX512BF16) return tn__gemm_kernel_avx512bf16;
#endif
    (void)kern;
    return tn__gemm_kernel;
}

#ifdef TN__BF16_HW
static void *tn__gemm_amx_raw[TN__GEMM_SLOTS];

/* A slot's AMX copies (TN__AMX_A_HALVES + TN__AMX_B_HALVES, 64-byte aligned), allocated on first
   use and kept; NULL (and no slot held) when out of slots or memory. */
static uint16_t *tn__gemm_amx_scratch(int *slot)
{
    int s = tn__gemm_claim_slot();
    *slot = -1;
    if (s < 0) return NULL;
    if (!tn__gemm_amx_raw[s]) tn__gemm_amx_raw[s] = TN_MALLOC((TN__AMX_A_HALVES + TN__AMX_B_HALVES) * 2 + 64);
    if (!tn__gemm_amx_raw[s]) {
        tn__gemm_release_slot(s);
        return NULL;
    }
    *slot = s;
    return (uint16_t *)(((uintptr_t)tn__gemm_amx_raw[s] + 63) & ~(uintptr_t)63);
}

/* dst[k * dstride + i] = word k of row i (rows `sstride` words apart), 16 x 16 32-bit words:
   unpacks within 128-bit lanes, then a 4 x 4 transpose of the lanes. */
__attribute__((target("avx512f"))) static void tn__transpose16_words(const void *src, size_t sstride, uint32_t *dst, size_t dstride)
{
    __m512i r[16], t[16];
    int i;
    for (i = 0; i < 16; i++) r[i] = _mm512_loadu_si512((const void *)((const uint32_t *)src + i * sstride));
    for (i = 0; i < 16; i += 2) {
        t[i] = _mm512_unpacklo_epi32(r[i], r[i + 1]);
        t[i + 1] = _mm512_unpackhi_epi32(r[i], r[i + 1]);
    }
    for (i = 0; i < 16; i += 4) { /* r[i + c], lane L: column 4 L + c of rows i .. i + 3 */
        r[i] = _mm512_unpacklo_epi64(t[i], t[i + 2]);
        r[i + 1] = _mm512_unpackhi_epi64(t[i], t[i + 2]);
        r[i + 2] = _mm512_unpacklo_epi64(t[i + 1], t[i + 3]);
        r[i + 3] = _mm512_unpackhi_epi64(t[i + 1], t[i + 3]);
    }
    for (i = 0; i < 4; i++) { /* column c = i: lanes L of r[i], r[4 + i], r[8 + i], r[12 + i] -> row 4 L + c */
        __m512i u0 = _mm512_shuffle_i32x4(r[i], r[4 + i], 0x44), u1 = _mm512_shuffle_i32x4(r[i], r[4 + i], 0xee);
        __m512i u2 = _mm512_shuffle_i32x4(r[8 + i], r[12 + i], 0x44), u3 = _mm512_shuffle_i32x4(r[8 + i], r[12 + i], 0xee);
        _mm512_storeu_si512((void *)(dst + (size_t)i * dstride), _mm512_shuffle_i32x4(u0, u2, 0x88));
        _mm512_storeu_si512((void *)(dst + (size_t)(4 + i) * dstride), _mm512_shuffle_i32x4(u0, u2, 0xdd));
        _mm512_storeu_si512((void *)(dst + (size_t)(8 + i) * dstride), _mm512_shuffle_i32x4(u1, u3, 0x88));
        _mm512_storeu_si512((void *)(dst + (size_t)(12 + i) * dstride), _mm512_shuffle_i32x4(u1, u3, 0xdd));
    }
}

/* op(A)[ic .. ic+mc) x [pc .. pc+kc) as bf16 rows of kp = kc rounded up to 32, rows up to a
   multiple of 32; the padding is zero. A row-major: each row converted straight from A; A
   transposed: through the float32 panels of tn__gemm_pack_a (pa), a panel converted at once. */
static void tn__gemm_amx_pack_a(const tn__gemm_job *g, int ic, int mc, int pc, int kc, float *pa, uint16_t *ta)
{
    int kp = (kc + 31) / 32 * 32, mp = (mc + 31) / 32 * 32, i, k, r;
    if (!g->trans_a) {
        for (i = 0; i < mc; i++) {
            tn__bf16_halves(g->A + (size_t)(ic + i) * g->lda + pc, ta + (size_t)i * kp, kc);
            memset(ta + (size_t)i * kp + kc, 0, (size_t)(kp - kc) * sizeof(uint16_t));
        }
    } else {
        uint16_t *h = (uint16_t *)(void *)pa; /* each panel's halves over its own first half */
        tn__gemm_pack_a(1, g->A, g->lda, ic, mc, pc, kc, pa);
        for (i = 0; i < mc; i += TN__GEMM_MR) {
            const float *panel = pa + (size_t)i * kc;
            uint16_t *hp = h + (size_t)i * kc * 2;
            tn__bf16_halves(panel, hp, kc * TN__GEMM_MR); /* halves never overtake the floats read */
            for (r = 0; r < TN__GEMM_MR && i + r < mc; r++) {
                uint16_t *row = ta + (size_t)(i + r) * kp;
                for (k = 0; k < kc; k++) row[k] = hp[(size_t)k * TN__GEMM_MR + r];
                memset(row + kc, 0, (size_t)(kp - kc) * sizeof(uint16_t));
            }
        }
    }
    memset(ta + (size_t)mc * kp, 0, (size_t)(mp - mc) * kp * sizeof(uint16_t));
}

/* op(B)[pc .. pc+kc) x [jc .. jc+nc) straight from B in the layout of tn__gemm_amx_pack_b. B
   row-major: pair words of rows k, k + 1; transposed: each column's run of k converted, whose
   words are the pairs, then 16 x 16 words transposed. */
static void tn__gemm_amx_pack_b_direct(const tn__gemm_job *g, int pc, int kc, int jc, int nc, uint16_t *tb)
{
    int kp = (kc + 31) / 32 * 32, groups = (nc + 31) / 32 * 2, q, k, jj;
    uint16_t tmp[16 * TN__AMX_KP];
    for (q = 0; q < groups; q++) {
        uint16_t *d = tb + (size_t)q * kp * 16;
        int cols = nc - 16 * q < 16 ? (nc - 16 * q > 0 ? nc - 16 * q : 0) : 16;
        if (cols == 0) {
            memset(d, 0, (size_t)kp * 16 * sizeof(uint16_t));
            continue;
        }
        if (!g->trans_b) {
            for (k = 0; k < kp; k += 2, d += 32) {
                const float *r0 = g->B + (size_t)(pc + k) * g->ldb + jc + 16 * q;
                if (k >= kc) {
                    memset(d, 0, 64);
                    continue;
                }
                tn__bf16_pair_words(r0, k + 1 < kc ? r0 + g->ldb : NULL, d, cols);
                memset(d + 2 * cols, 0, (size_t)(16 - cols) * 4);
            }
            continue;
        }
        for (jj = 0; jj < 16; jj++) { /* column jj's k run as halves, zero past kc (and past nc) */
            uint16_t *t = tmp + (size_t)jj * kp;
            if (jj < cols) tn__bf16_halves(g->B + (size_t)(jc + 16 * q + jj) * g->ldb + pc, t, kc);
            memset(t + (jj < cols ? kc : 0), 0, (size_t)(jj < cols ? kp - kc : kp) * sizeof(uint16_t));
        }
        if (tn__cpu_flags & TN_CPU_AVX512F)
            for (k = 0; k < kp / 2; k += 16) tn__transpose16_words(tmp + 2 * k, (size_t)kp / 2, (uint32_t *)(void *)d + (size_t)k * 16, 16);
        else
            for (k = 0; k < kp / 2; k++)
                for (jj = 0; jj < 16; jj++) memcpy(d + ((size_t)k * 16 + jj) * 2, tmp + (size_t)jj * kp + 2 * k, 4);
    }
}

/* The packed B block (NR-column panels) as 16-column groups of kp/2 rows of 16 (k even, k odd)
   bf16 pairs: 64-byte tile rows. Columns up to a multiple of 32; the padding is zero. */
static void tn__gemm_amx_pack_b(const float *pb, int nc, int kc, uint16_t *tb)
{
    int kp = (kc + 31) / 32 * 32, groups = (nc + 31) / 32 * 2, panels = (nc + TN__GEMM_NR - 1) / TN__GEMM_NR, g, k;
    size_t panel = tn__gemm_b_stride(kc);
    for (g = 0; g < groups; g++) { /* columns [16 g, 16 g + 16): in panel 16 g / NR unless past the last */
        const float *src = pb + (size_t)(g * 16 / TN__GEMM_NR) * panel + g * 16 % TN__GEMM_NR;
        int live = g * 16 < panels * TN__GEMM_NR; /* packed columns past nc are zero already */
        for (k = 0; k < kp; k += 2) { /* one 64-byte tile row per k pair */
            uint16_t *d = tb + (size_t)g * kp * 16 + (size_t)k * 16;
            if (live && k < kc)
                tn__bf16_pair_words(src + (size_t)k * TN__GEMM_NR, k + 1 < kc ? src + (size_t)(k + 1) * TN__GEMM_NR : NULL, d, 16);
            else
                memset(d, 0, 64);
        }
    }
}

/* The LDTILECFG block: palette 1, then bytes per row and rows of each of the 8 tiles. */
typedef struct tn__amx_cfg {
    unsigned char palette, start_row, reserved[14];
    unsigned short colsb[16];
    unsigned char rows[16];
} tn__amx_cfg;

/* d[0 .. n) = alpha * v (+ beta * d, not fused: the scalar loop's bytes). */
__attribute__((target("avx512f"))) static void tn__amx_gemm_out512(float *d, const float *v, int n, float alpha, float beta)
{
    __m512 al = _mm512_set1_ps(alpha), bt = _mm512_set1_ps(beta);
    int i;
    for (i = 0; i < n; i += 16) {
        __mmask16 k = (__mmask16)(n - i >= 16 ? 0xffffu : (1u << (n - i)) - 1u);
        __m512 x = _mm512_mul_ps(al, _mm512_maskz_loadu_ps(k, v + i));
        if (beta != 0.0f) x = _mm512_add_ps(x, _mm512_mul_ps(bt, _mm512_maskz_loadu_ps(k, d + i)));
        _mm512_mask_storeu_ps(d + i, k, x);
    }
}

static void tn__amx_gemm_out(float *d, const float *v, int n, float alpha, float beta)
{
    int i;
    if (tn__cpu_flags & TN_CPU_AVX512F) {
        tn__amx_gemm_out512(d, v, n, alpha, beta);
        return;
    }
    for (i = 0; i < n; i++) {
        float x = alpha * v[i];
        d[i] = beta == 0.0f ? x : x + beta * d[i];
    }
}

/* C[ic.., jc..] (+)= A block x B block on the tiles: tmm0-3 the 2 x 2 C tiles of a 32 x 32 block,
   tmm4-5 two A tiles (16 rows x 32 k), tmm6-7 two B tiles (16 pair rows x 16 columns). */
__attribute__((target("amx-tile,amx-bf16"))) static void tn__gemm_amx_tiles(const tn__gemm_job *g, int ic, int mc, int jc,
                                                                               int nc, int kc, const uint16_t *ta,
                                                                               const uint16_t *tb, float beta)
{
    tn__amx_cfg cfg;
    float tile[32 * 32];
    int kp = (kc + 31) / 32 * 32, i, j, k, r, t;
    memset(&cfg, 0, sizeof cfg);
    cfg.palette = 1;
    for (t = 0; t < 8; t++) {
        cfg.rows[t] = 16;
        cfg.colsb[t] = 64;
    }
    _tile_loadconfig(&cfg);
    for (i = 0; i < mc; i += 32)
        for (j = 0; j < nc; j += 32) {
            const uint16_t *a0 = ta + (size_t)i * kp, *a1 = a0 + (size_t)16 * kp;
            const uint16_t *b0 = tb + (size_t)(j / 16) * kp * 16, *b1 = b0 + (size_t)kp * 16;
            int rows = mc - i < 32 ? mc - i : 32, cols = nc - j < 32 ? nc - j : 32;
            _tile_zero(0);
            _tile_zero(1);
            _tile_zero(2);
            _tile_zero(3);
            for (k = 0; k < kp; k += 32) {
                _tile_loadd(4, a0 + k, kp * 2);
                _tile_loadd(5, a1 + k, kp * 2);
                _tile_loadd(6, b0 + (size_t)k * 16, 64);
                _tile_loadd(7, b1 + (size_t)k * 16, 64);
                _tile_dpbf16ps(0, 4, 6);
                _tile_dpbf16ps(1, 4, 7);
                _tile_dpbf16ps(2, 5, 6);
                _tile_dpbf16ps(3, 5, 7);
            }
            if (rows == 32 && cols == 32 && g->alpha == 1.0f && beta == 0.0f) { /* C = the sums: straight */
                float *c0 = g->C + (size_t)(ic + i) * g->ldc + jc + j;
                long ldc = (long)g->ldc * 4;
                _tile_stored(0, c0, ldc);
                _tile_stored(1, c0 + 16, ldc);
                _tile_stored(2, c0 + (size_t)16 * g->ldc, ldc);
                _tile_stored(3, c0 + (size_t)16 * g->ldc + 16, ldc);
                continue;
            }
            _tile_stored(0, tile, 128);
            _tile_stored(1, tile + 16, 128);
            _tile_stored(2, tile + 16 * 32, 128);
            _tile_stored(3, tile + 16 * 32 + 16, 128);
            for (r = 0; r < rows; r++)
                tn__amx_gemm_out(g->C + (size_t)(ic + i + r) * g->ldc + jc + j, tile + r * 32, cols, g->alpha, beta);
        }
    _tile_release();
}

/* pb: the float32 panels of g->pack_b, or NULL: B packed straight. */
static void tn__gemm_amx_block(const tn__gemm_job *g, int ic, int mc, int pc, int jc, int nc, int kc, const uint16_t *ta,
                               const float *pb, uint16_t *tb, float beta)
{
    if (pb) tn__gemm_amx_pack_b(pb, nc, kc, tb);
    else tn__gemm_amx_pack_b_direct(g, pc, kc, jc, nc, tb);
    tn__gemm_amx_tiles(g, ic, mc, jc, nc, kc, ta, tb, beta);
}

/* Direct convolution on the tiles (stride 1, no im2col), for >>ops' tn__conv_forward_amx and
   tn__conv_weight_grad_amx. The input is converted once to bf16 padded rows in which every
   channel's (or channel pair's) row of Wr values follows the previous channel's, so a tile of 16
   channels x 32 positions of one row is one load with a stride of Wr elements, tap (ky, kx) is a
   fixed offset from it, and all reads of one output row stay within KH padded rows (a few tens of
   KiB: separate planes per channel made tens of streams and ran at a quarter of the speed). The
   sum over C*KH*KW becomes taps x 32-channel steps of TDPBF16PS. Outputs are computed in chunks of
   32 positions of one output row (the last one of a row partly past OW, dropped). */
typedef struct tn__amx_conv {
    const uint32_t *xp;    /* padded row iy at xp + iy * prow * Wr: channel-pair rows of Wr words
                              (word = bf16 channels 2p, 2p + 1) */
    int Wr, prow;          /* prow: channel-pair rows per padded row (kpairs if ksteps is 1, else 16 ksteps) */
    const uint16_t *wa;    /* A tiles of 16 rows x 32 bf16: tile ((mt * ntaps + t) * ksteps + s) */
    const int *off;        /* word offset of each tap */
    int ntaps, ksteps, kpairs, M; /* kpairs: channel pairs of the last step (16 but for C < 32) */
    int OW, OH;
    float *y;              /* M planes of OH x OW: y = beta * y + conv (+ bias) */
    const float *bias;     /* M floats, or NULL */
    float beta;
    float *rows;           /* the caller's: 32 rows of OW rounded up to 32 floats */
} tn__amx_conv;

/* The weight gradient, also without im2col: dW[m][c][t] = sum over images and positions of
   dy[m][oy][ox] x[c][oy + ky dil][ox + kx dil] (padded input). A tiles: 16 channels x 32 positions
   of the padded input (bf16 rows laid out as above, Wr halves each), at the tap's offset; B tiles:
   16 position pairs x 16 output channels of dy transposed to pair words (each output row padded
   to Wq, a multiple of 32, with zeros). C tiles hold dW^T (channels x output channels) of one tap;
   each element is summed over images, then output rows and chunks in order, whatever the split
   of the items (tap, block of 32 channels, block of 32 output channels). */
typedef struct tn__amx_dw {
    const uint16_t *xh;    /* per image: Hp padded rows of cp channel rows of Wr halves */
    const uint32_t *dyt;   /* per image: OH * Wq / 2 rows of mp words */
    int Wr, Wq, Hp;
    const int *off;
    int N, ntaps, cp, mp, C, M, OH;
    float *dw;             /* M x C x ntaps, added to */
} tn__amx_dw;

static void tn__amx_cfg_set(tn__amx_cfg *cfg, int arows_bytes, int brows)
{
    int t;
    memset(cfg, 0, sizeof *cfg);
    cfg->palette = 1;
    for (t = 0; t < 8; t++) {
        cfg->rows[t] = (unsigned char)(t >= 6 ? brows : 16);
        cfg->colsb[t] = (unsigned short)(t == 4 || t == 5 ? arows_bytes : 64);
    }
}

/* Item it of ntaps * ceil(cp / 32) * ceil(mp / 32) over output rows [oy0, oy1) of image n: its 32 x 32
   block of sums (acc, rows of 32 floats) loaded into the tiles, added to and stored back. Rows in
   bands, every item on a band before the next band, so the band's input stays in L2 (an item over
   a whole image read it once per item, from L3). */
__attribute__((target("amx-tile,amx-bf16"))) static void tn__amx_dw_item(const tn__amx_dw *d, int it, int n, int oy0, int oy1,
                                                                            float *acc)
{
    tn__amx_cfg cfg;
    int cpairs = (d->cp + 31) / 32, mpairs = (d->mp + 31) / 32, t = it / (cpairs * mpairs);
    int cb = it / mpairs % cpairs * 32, mb = it % mpairs * 32, c2 = cb + 16 < d->cp, m2 = mb + 16 < d->mp, oy, ox;
    long astride = (long)d->Wr * 2, bstride = (long)d->mp * 4;
    size_t rowx = (size_t)d->cp * d->Wr;
    const uint32_t *b = d->dyt + ((size_t)n * d->OH + oy0) * (d->Wq / 2) * d->mp + mb;
    tn__amx_cfg_set(&cfg, 64, 16);
    _tile_loadconfig(&cfg);
    _tile_loadd(0, acc, 128);
    _tile_loadd(1, acc + 16, 128);
    _tile_loadd(2, acc + 16 * 32, 128);
    _tile_loadd(3, acc + 16 * 32 + 16, 128);
    for (oy = oy0; oy < oy1; oy++) {
        const uint16_t *a = d->xh + ((size_t)n * d->Hp + oy) * rowx + (size_t)cb * d->Wr + d->off[t];
        for (ox = 0; ox < d->Wq; ox += 32, a += 32, b += (size_t)16 * d->mp) {
            _tile_loadd(4, a, astride);
            _tile_loadd(6, b, bstride);
            _tile_dpbf16ps(0, 4, 6);
            if (m2) {
                _tile_loadd(7, b + 16, bstride);
                _tile_dpbf16ps(1, 4, 7);
            }
            if (c2) {
                _tile_loadd(5, a + (size_t)16 * d->Wr, astride);
                _tile_dpbf16ps(2, 5, 6);
                if (m2) _tile_dpbf16ps(3, 5, 7);
            }
        }
    }
    _tile_stored(0, acc, 128);
    _tile_stored(1, acc + 16, 128);
    _tile_stored(2, acc + 16 * 32, 128);
    _tile_stored(3, acc + 16 * 32 + 16, 128);
    _tile_release();
}

/* d[0 .. n) = (v + *bias) + beta * d (no bias: v + beta * d; beta 0: d not read). */
__attribute__((target("avx512f"))) static void tn__amx_conv_out512(float *d, const float *v, int n, const float *bias, float beta)
{
    __m512 bm = _mm512_set1_ps(bias ? *bias : 0.0f), bt = _mm512_set1_ps(beta);
    int i;
    for (i = 0; i < n; i += 16) {
        __mmask16 k = (__mmask16)(n - i >= 16 ? 0xffffu : (1u << (n - i)) - 1u);
        __m512 x = _mm512_maskz_loadu_ps(k, v + i);
        if (bias) x = _mm512_add_ps(x, bm);
        if (beta != 0.0f) x = _mm512_add_ps(x, _mm512_mul_ps(bt, _mm512_maskz_loadu_ps(k, d + i))); /* not fused: as below */
        _mm512_mask_storeu_ps(d + i, k, x);
    }
}

static void tn__amx_conv_out(float *d, const float *v, int n, const float *bias, float beta)
{
    int i;
    if (tn__cpu_flags & TN_CPU_AVX512F) { /* every AMX CPU; not the tile model of test_bf16_amx */
        tn__amx_conv_out512(d, v, n, bias, beta);
        return;
    }
    for (i = 0; i < n; i++) {
        float x = bias ? v[i] + *bias : v[i];
        d[i] = beta == 0.0f ? x : x + beta * d[i];
    }
}

/* Chunks [k0, k1) of one image, chunk k = 32 positions of output row k / ceil(OW / 32). With a
   single step of fewer than 16 channel pairs (C < 32) the tiles are configured that short. */
__attribute__((target("amx-tile,amx-bf16"))) static void tn__amx_conv_rows(const tn__amx_conv *c, int k0, int k1)
{
    tn__amx_cfg cfg;
    int cw = (c->OW + 31) / 32, wq = cw * 32, mtiles = (c->M + 15) / 16, k, mt, t, s, r;
    long rstride = (long)wq * 4;
    size_t tiles_per_mt = (size_t)c->ntaps * c->ksteps * 512, ohw = (size_t)c->OH * c->OW, rowx = (size_t)c->prow * c->Wr;
    long bstride = (long)c->Wr * 4;
    tn__amx_cfg_set(&cfg, c->ksteps == 1 ? 4 * c->kpairs : 64, c->ksteps == 1 ? c->kpairs : 16);
    _tile_loadconfig(&cfg);
    for (k = k0; k < k1;) { /* the chunks of one output row, each pair of M tiles in turn: one pair's
                               A tiles stay in L1 along the row */
        int oy = k / cw, kend = (oy + 1) * cw < k1 ? (oy + 1) * cw : k1, kk, ox0 = k % cw * 32;
        int ox1 = (kend - oy * cw) * 32 < c->OW ? (kend - oy * cw) * 32 : c->OW;
        for (mt = 0; mt < mtiles; mt += 2) {
            int two = mt + 1 < mtiles, rows = c->M - mt * 16 < 32 ? c->M - mt * 16 : 32;
            for (kk = k; kk < kend; kk++) {
                int ox = kk % cw * 32;
                const uint16_t *a = c->wa + (size_t)mt * tiles_per_mt;
                _tile_zero(0);
                _tile_zero(1);
                _tile_zero(2);
                _tile_zero(3);
                for (t = 0; t < c->ntaps; t++) {
                    const uint32_t *b = c->xp + oy * rowx + ox + c->off[t];
                    for (s = 0; s < c->ksteps; s++, a += 512, b += (size_t)16 * c->Wr) {
                        _tile_loadd(4, a, 64);
                        _tile_loadd(6, b, bstride);
                        _tile_loadd(7, b + 16, bstride);
                        _tile_dpbf16ps(0, 4, 6);
                        _tile_dpbf16ps(1, 4, 7);
                        if (two) {
                            _tile_loadd(5, a + tiles_per_mt, 64);
                            _tile_dpbf16ps(2, 5, 6);
                            _tile_dpbf16ps(3, 5, 7);
                        }
                    }
                }
                _tile_stored(0, c->rows + ox, rstride);
                _tile_stored(1, c->rows + ox + 16, rstride);
                _tile_stored(2, c->rows + (size_t)16 * wq + ox, rstride);
                _tile_stored(3, c->rows + (size_t)16 * wq + ox + 16, rstride);
            }
            /* then output channel by channel: 32 outputs a row at a time were 32 planes apart (a
               multiple of 4 KiB in large maps: one cache set) and cost more than the products */
            for (r = 0; r < rows; r++)
                tn__amx_conv_out(c->y + (size_t)(mt * 16 + r) * ohw + (size_t)oy * c->OW + ox0, c->rows + (size_t)r * wq + ox0,
                                 ox1 - ox0, c->bias ? c->bias + mt * 16 + r : NULL, c->beta);
        }
        k = kend;
    }
    _tile_release();
}
#endif
#endif /* TN_NO_ENGINE */
