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
#endif /* TN_NO_ENGINE */

