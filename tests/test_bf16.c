/* Tests of @@gemm's bfloat16 products (>>gemm_bf16) and of convolutions and dense layers in bf16.
   Tolerances (documented in docs/engine.md):
   - against a double reference over the bf16-rounded operands: 1e-5 x the sum of |terms| (float32
     accumulation only, as test_gemm);
   - against a double reference over the float32 operands: (2^-7 + 2^-15 + 1e-5) x the sum of |a b|
     (bf16 keeps 8 significant bits: rounding moves an operand by at most 2^-8 relative, so a
     product by at most 2^-7 + 2^-16);
   - the emulated kernel (and VDPBF16PS where the CPU has it) bit for bit against a scalar model
     of VDPBF16PS: fmaf with the odd k of each pair first, float32 K blocks added in order;
   - conv2d and linear layers: bf16 results and gradients within 2^-7 of the float32 ones in
     relative L2 norm, bit-identical between 1, 2 and 3 threads. */
#define TN_INTERNALS /* private tn__ code: the header's internals block */
#include "terrainnet.h"
#include "tn_test.h"
#include <float.h>

static double get_op(const float *X, int ld, int trans, int r, int c)
{
    return trans ? X[(size_t)c * ld + r] : X[(size_t)r * ld + c];
}

static float *rand_matrix(tn_rng *rng, size_t n)
{
    float *p = (float *)malloc((n ? n : 1) * sizeof(float));
    size_t i;
    for (i = 0; i < n; i++) p[i] = 2.0f * tn_rng_uniform(rng) - 1.0f;
    return p;
}

static float *rounded_copy(const float *x, size_t n)
{
    float *p = (float *)malloc((n ? n : 1) * sizeof(float));
    size_t i;
    for (i = 0; i < n; i++) p[i] = tn__bf16_round(x[i]);
    return p;
}

TN_TEST(bf16_rounding)
{
    float one_tie = 1.0f + 1.0f / 256.0f, odd_tie = 1.0f + 3.0f / 256.0f, above = 1.0f + 1.0f / 256.0f + 1.0f / 65536.0f;
    float sub = FLT_MIN / 4.0f, big = FLT_MAX;
    TN_CHECK(tn__bf16_round(1.0f) == 1.0f);
    TN_CHECK(tn__bf16_round(one_tie) == 1.0f);                         /* tie: to even (down) */
    TN_CHECK(tn__bf16_round(odd_tie) == 1.0f + 4.0f / 256.0f);         /* tie: to even (up) */
    TN_CHECK(tn__bf16_round(above) == 1.0f + 2.0f / 256.0f);           /* above the tie: up */
    TN_CHECK(tn__bf16_round(-above) == -(1.0f + 2.0f / 256.0f));
    TN_CHECK(tn__bf16_round(sub) == 0.0f && !signbit(tn__bf16_round(sub)));
    TN_CHECK(tn__bf16_round(-sub) == 0.0f && signbit(tn__bf16_round(-sub)));
    TN_CHECK(isinf(tn__bf16_round(big)) && tn__bf16_round(big) > 0); /* rounds past the largest bf16 */
    TN_CHECK(isinf(tn__bf16_round((float)INFINITY)));
    TN_CHECK(isnan(tn__bf16_round((float)NAN)));
    TN_CHECK(tn__bf16_round(FLT_MIN) == FLT_MIN); /* the smallest normal is a bf16 */
    { /* the vector rounding (AVX2 builds) gives the scalar's bits, specials included */
        float v[19] = {1.0f, 0, 0, 0, 0, 0, 0, FLT_MAX, (float)INFINITY, -(float)INFINITY, (float)NAN, -0.0f, 0.0f, 3.14159f, -2.5e-39f,
                       65504.0f, 1e-30f, -7.0f, 0.1f};
        float w[19];
        int i, same = 1;
        v[1] = one_tie;
        v[2] = odd_tie;
        v[3] = above;
        v[4] = -above;
        v[5] = sub;
        v[6] = -sub;
        memcpy(w, v, sizeof v);
        tn__bf16_round_n(w, 19);
        for (i = 0; i < 19; i++) {
            float r = tn__bf16_round(v[i]);
            same = same && !memcmp(&r, &w[i], sizeof r);
        }
        TN_CHECK(same);
    }
}

TN_TEST(bf16_precision_setting)
{
    tn_precision p = TN_PRECISION_AUTO;
    unsigned f = tn_cpu_features();
    const char *k = tn_gemm_bf16_kernel();
    TN_CHECK(tn_get_precision() == TN_PRECISION_AUTO);
    TN_CHECK(tn_precision_resolve(TN_PRECISION_AUTO) == TN_PRECISION_FP32); /* the default, for now */
    TN_CHECK(tn_precision_resolve(TN_PRECISION_BF16) == TN_PRECISION_BF16);
    tn_set_precision(TN_PRECISION_BF16);
    TN_CHECK(tn_precision_resolve(TN_PRECISION_AUTO) == TN_PRECISION_BF16);
    TN_CHECK(tn_precision_resolve(TN_PRECISION_FP32) == TN_PRECISION_FP32);
    tn_set_precision(TN_PRECISION_AUTO);
    TN_CHECK(tn_precision_parse(&p, "bf16") == TN_OK && p == TN_PRECISION_BF16);
    TN_CHECK(tn_precision_parse(&p, "fp32") == TN_OK && p == TN_PRECISION_FP32);
    TN_CHECK(tn_precision_parse(&p, "auto") == TN_OK && p == TN_PRECISION_AUTO);
    TN_CHECK(tn_precision_parse(&p, "fp16") == TN_ERR_INVALID_ARG && p == TN_PRECISION_AUTO);
    TN_CHECK(!strcmp(tn_precision_name(TN_PRECISION_BF16), "bf16") && !strcmp(tn_precision_name(TN_PRECISION_FP32), "fp32"));
    TN_CHECK(!(f & TN_CPU_AVX512_BF16) || (f & TN_CPU_AVX512F));
    TN_CHECK(!strcmp(k, "amx-bf16") || !strcmp(k, "avx512-bf16") || !strcmp(k, "emulated"));
    fprintf(stderr, "  cpu features 0x%x, bf16 kernel: %s\n", f, k);
}

static double worst_ratio; /* largest |C - R| / (sum of |a b|) seen against the float32 operands */

/* tn_gemm in bf16 against double references over rounded and unrounded operands. */
static int check_bf16_case(int ta, int tb, int M, int N, int K, float alpha, float beta)
{
    tn_rng rng;
    int lda = ta ? M : K, ldb = tb ? K : N, i, j, k, ok = 1;
    size_t na = (size_t)M * K, nb = (size_t)K * N, nc = (size_t)M * N;
    float *A, *B, *C, *Ar, *Br, *C0;
    tn_rng_seed(&rng, (uint64_t)(M * 7919 + N * 31 + K), (uint64_t)(ta * 2 + tb + 10));
    A = rand_matrix(&rng, na);
    B = rand_matrix(&rng, nb);
    C = rand_matrix(&rng, nc);
    C0 = (float *)malloc((nc ? nc : 1) * sizeof(float));
    memcpy(C0, C, nc * sizeof(float));
    Ar = rounded_copy(A, na);
    Br = rounded_copy(B, nb);
    tn_gemm(TN_PRECISION_BF16, ta, tb, M, N, K, alpha, A, lda, B, ldb, beta, C, N);
    for (i = 0; i < M && ok; i++)
        for (j = 0; j < N && ok; j++) {
            double s = 0, sm = 0, r = 0, rm = 0, c0 = beta == 0.0f ? 0.0 : beta * (double)C0[(size_t)i * N + j], got;
            for (k = 0; k < K; k++) {
                double t = get_op(Ar, lda, ta, i, k) * get_op(Br, ldb, tb, k, j);
                double u = get_op(A, lda, ta, i, k) * get_op(B, ldb, tb, k, j);
                s += t;
                sm += fabs(t);
                r += u;
                rm += fabs(u);
            }
            got = C[(size_t)i * N + j];
            sm = fabs(alpha) * sm + fabs(c0);
            rm = fabs(alpha) * rm;
            if (fabs(got - (alpha * s + c0)) > 1e-5 * sm + 1e-30 ||
                fabs(got - (alpha * r + c0)) > (1.0 / 128 + 1.0 / 32768 + 1e-5) * rm + 1e-5 * fabs(c0) + 1e-30) {
                fprintf(stderr, "  bf16 mismatch ta=%d tb=%d M=%d N=%d K=%d at %d,%d: %.9g vs %.9g (bf16 ops) %.9g (fp32 ops)\n",
                        ta, tb, M, N, K, i, j, got, alpha * s + c0, alpha * r + c0);
                ok = 0;
            }
            if (rm > 0 && fabs(got - (alpha * r + c0)) / rm > worst_ratio) worst_ratio = fabs(got - (alpha * r + c0)) / rm;
        }
    free(A);
    free(B);
    free(C);
    free(C0);
    free(Ar);
    free(Br);
    return ok;
}

TN_TEST(gemm_bf16_odd_shapes_all_transposes)
{
    static const int dims[] = {1, 2, 3, 7, 16, 17, 31, 33, 65};
    int nd = (int)(sizeof dims / sizeof dims[0]), a, b, c, t;
    for (t = 0; t < 4; t++)
        for (a = 0; a < nd; a++)
            for (b = 0; b < nd; b++)
                for (c = 0; c < nd; c += 2) TN_CHECK(check_bf16_case(t >> 1, t & 1, dims[a], dims[b], dims[c], 1.0f, 0.0f));
}

TN_TEST(gemm_bf16_block_edges_alpha_beta)
{
    /* tile edges (MR 6/8, NR 16/32, AMX 32), K blocks of 384 with odd block lengths, K = 1 */
    static const int shapes[][3] = {{9, 33, 385}, {33, 31, 383}, {100, 513, 50}, {769, 40, 21},
                                    {64, 300, 800}, {1, 1000, 3}, {1000, 1, 3}, {40, 40, 1}, {70, 260, 1}};
    static const float ab[][2] = {{1.0f, 0.0f}, {1.0f, 1.0f}, {-0.5f, 0.0f}, {2.0f, -1.5f}};
    int s, t, v;
    worst_ratio = 0;
    for (s = 0; s < (int)(sizeof shapes / sizeof shapes[0]); s++)
        for (t = 0; t < 4; t++)
            for (v = 0; v < 4; v++)
                TN_CHECK(check_bf16_case(t >> 1, t & 1, shapes[s][0], shapes[s][1], shapes[s][2], ab[v][0], ab[v][1]));
    fprintf(stderr, "  worst |bf16 - exact| / sum|ab|: %.3g (bound 2^-7 = %.3g)\n", worst_ratio, 1.0 / 128);
}

/* VDPBF16PS on one element: K cut in the driver's blocks, each summed from zero with the odd k of
   a pair first (fmaf: the product of two bf16 is exact), blocks added to C in order. */
static float vdpbf16ps_model(const float *a, const float *b, int K)
{
    int kblocks = (K + TN__GEMM_KC - 1) / TN__GEMM_KC, kcb = (K + kblocks - 1) / kblocks, pc, k;
    float c = 0.0f;
    for (pc = 0; pc < K; pc += kcb) {
        int kc = K - pc < kcb ? K - pc : kcb;
        float acc = 0.0f;
        for (k = 0; k < kc; k += 2) {
            if (k + 1 < kc) acc = fmaf(a[pc + k + 1], b[pc + k + 1], acc);
            acc = fmaf(a[pc + k], b[pc + k], acc);
        }
        c = pc == 0 ? acc : c + acc;
    }
    return c;
}

/* The result of kernel `kern` (forced) for M x N x K against the model, bit for bit. */
static int matches_model(int kern, int ta, int M, int N, int K)
{
    tn_rng rng;
    float *A, *B, *C, *Ar, *Br, *arow, *bcol;
    int i, j, k, same = 1;
    tn_rng_seed(&rng, 99, (uint64_t)K);
    A = rand_matrix(&rng, (size_t)M * K);
    B = rand_matrix(&rng, (size_t)K * N);
    C = (float *)malloc((size_t)M * N * sizeof(float));
    Ar = rounded_copy(A, (size_t)M * K);
    Br = rounded_copy(B, (size_t)K * N);
    arow = (float *)malloc((size_t)K * sizeof(float));
    bcol = (float *)malloc((size_t)K * sizeof(float));
    tn__gemm_bf16_force = kern;
    tn_gemm(TN_PRECISION_BF16, ta, 0, M, N, K, 1.0f, A, ta ? M : K, B, N, 0.0f, C, N);
    tn__gemm_bf16_force = 0;
    for (i = 0; i < M; i++)
        for (j = 0; j < N; j++) {
            float m;
            for (k = 0; k < K; k++) {
                arow[k] = (float)get_op(Ar, ta ? M : K, ta, i, k);
                bcol[k] = Br[(size_t)k * N + j];
            }
            m = vdpbf16ps_model(arow, bcol, K);
            if (memcmp(&m, &C[(size_t)i * N + j], sizeof m) != 0 && same) {
                fprintf(stderr, "  kernel %d M=%d N=%d K=%d at %d,%d: %.9g, model %.9g\n", kern, M, N, K, i, j, C[(size_t)i * N + j], m);
                same = 0;
            }
        }
    free(A);
    free(B);
    free(C);
    free(Ar);
    free(Br);
    free(arow);
    free(bcol);
    return same;
}

TN_TEST(gemm_bf16_emulation_is_vdpbf16ps_bit_for_bit)
{
    static const int shapes[][3] = {{8, 32, 64}, {13, 45, 77}, {50, 70, 384}, {20, 33, 800}, {7, 100, 1001}};
    int s, ta;
    for (s = 0; s < (int)(sizeof shapes / sizeof shapes[0]); s++)
        for (ta = 0; ta < 2; ta++) {
            TN_CHECK(matches_model(TN__KERN_EMU, ta, shapes[s][0], shapes[s][1], shapes[s][2]));
            if (tn_cpu_features() & TN_CPU_AVX512_BF16) /* the hardware against the same model */
                TN_CHECK(matches_model(TN__KERN_AVX512BF16, ta, shapes[s][0], shapes[s][1], shapes[s][2]));
        }
    if (!(tn_cpu_features() & TN_CPU_AVX512_BF16)) fprintf(stderr, "  (no AVX512-BF16 here: emulation checked alone)\n");
}

/* The panels the VDPBF16PS kernel reads, converted in place by tn__gemm_bf16_prep: word (pair q,
   row or column r) holds bf16(k = 2q) low and bf16(k = 2q + 1) high (0 past kc). Checked on any
   CPU, with every panel and pair, odd kc and edge panels. */
static int pair_words_ok(const float *packed, int panels, size_t stride, int kc, int w, const float *src, int ld, int rows)
{
    int p, q, r;
    for (p = 0; p < panels; p++) {
        const uint32_t *words = (const uint32_t *)(const void *)(packed + (size_t)p * stride);
        for (q = 0; q < (kc + 1) / 2; q++)
            for (r = 0; r < w; r++) {
                int row = p * w + r;
                uint32_t lo = row < rows ? tn__bf16_bits(src[(size_t)row * ld + 2 * q]) >> 16 : 0;
                uint32_t hi = row < rows && 2 * q + 1 < kc ? tn__bf16_bits(src[(size_t)row * ld + 2 * q + 1]) >> 16 : 0;
                if (words[(size_t)q * w + r] != (lo | hi << 16)) return 0;
            }
    }
    return 1;
}

TN_TEST(gemm_bf16_pair_packing_layout)
{
    static const int kcs[] = {1, 2, 7, 64, 383};
    int i, mc = 13, nc = 45;
    tn_rng rng;
    tn_rng_seed(&rng, 3, 3);
    for (i = 0; i < 5; i++) {
        int kc = kcs[i], pa_panels = (mc + TN__GEMM_MR - 1) / TN__GEMM_MR, pb_panels = (nc + TN__GEMM_NR - 1) / TN__GEMM_NR;
        float *A = rand_matrix(&rng, (size_t)mc * kc), *Bt = rand_matrix(&rng, (size_t)nc * kc);
        float *pa = (float *)malloc((size_t)pa_panels * TN__GEMM_MR * kc * sizeof(float));
        float *pb = (float *)malloc((size_t)pb_panels * tn__gemm_b_stride(kc) * sizeof(float));
        tn__gemm_pack_a(0, A, kc, 0, mc, 0, kc, pa);
        tn__gemm_pack_b(1, Bt, kc, 0, kc, 0, nc, pb); /* op(B) = Bt^T: column j of op(B) is row j of Bt */
        tn__gemm_bf16_prep(TN__KERN_AVX512BF16, pa, pa_panels, (size_t)kc * TN__GEMM_MR, kc, TN__GEMM_MR);
        tn__gemm_bf16_prep(TN__KERN_AVX512BF16, pb, pb_panels, tn__gemm_b_stride(kc), kc, TN__GEMM_NR);
        TN_CHECK(pair_words_ok(pa, pa_panels, (size_t)kc * TN__GEMM_MR, kc, TN__GEMM_MR, A, kc, mc));
        TN_CHECK(pair_words_ok(pb, pb_panels, tn__gemm_b_stride(kc), kc, TN__GEMM_NR, Bt, kc, nc));
        free(A);
        free(Bt);
        free(pa);
        free(pb);
    }
}

static int bf16_same_bits_for_thread_counts(int ta, int tb, int M, int N, int K, float beta)
{
    tn_rng rng;
    int lda = ta ? M : K, ldb = tb ? K : N, t, same = 1;
    float *A, *B, *C0, *C1;
    size_t nc = (size_t)M * N;
    tn_rng_seed(&rng, 7, 12);
    A = rand_matrix(&rng, (size_t)M * K);
    B = rand_matrix(&rng, (size_t)K * N);
    C0 = rand_matrix(&rng, nc);
    C1 = (float *)malloc(nc * sizeof(float));
    memcpy(C1, C0, nc * sizeof(float));
    tn_set_threads(1);
    tn_gemm(TN_PRECISION_BF16, ta, tb, M, N, K, 0.75f, A, lda, B, ldb, beta, C0, N);
    for (t = 2; t <= 3; t++) {
        float *Ct = (float *)malloc(nc * sizeof(float));
        memcpy(Ct, C1, nc * sizeof(float));
        tn_set_threads(t);
        tn_gemm(TN_PRECISION_BF16, ta, tb, M, N, K, 0.75f, A, lda, B, ldb, beta, Ct, N);
        same = same && memcmp(C0, Ct, nc * sizeof(float)) == 0;
        free(Ct);
    }
    tn_set_threads(0);
    free(A);
    free(B);
    free(C0);
    free(C1);
    return same;
}

TN_TEST(gemm_bf16_bit_identical_for_any_thread_count)
{
    TN_CHECK(bf16_same_bits_for_thread_counts(0, 0, 64, 1000, 900, 0.0f));
    TN_CHECK(bf16_same_bits_for_thread_counts(1, 1, 64, 1000, 900, 1.0f));
    TN_CHECK(bf16_same_bits_for_thread_counts(0, 1, 1000, 40, 800, 0.5f));
    TN_CHECK(bf16_same_bits_for_thread_counts(1, 0, 301, 299, 777, 0.0f));
}

TN_TEST(gemm_fp32_forced_is_sgemm)
{
    tn_rng rng;
    int n = 150, differ;
    float *A, *B, *C0, *C1, *C2, *C3;
    size_t nn = (size_t)n * n;
    tn_rng_seed(&rng, 5, 6);
    A = rand_matrix(&rng, nn);
    B = rand_matrix(&rng, nn);
    C0 = (float *)malloc(nn * sizeof(float));
    C1 = (float *)malloc(nn * sizeof(float));
    C2 = (float *)malloc(nn * sizeof(float));
    C3 = (float *)malloc(nn * sizeof(float));
    tn_sgemm(0, 1, n, n, n, 1.0f, A, n, B, n, 0.0f, C0, n);
    tn_gemm(TN_PRECISION_FP32, 0, 1, n, n, n, 1.0f, A, n, B, n, 0.0f, C1, n);
    tn_gemm(TN_PRECISION_AUTO, 0, 1, n, n, n, 1.0f, A, n, B, n, 0.0f, C2, n); /* default setting: fp32 */
    tn_set_precision(TN_PRECISION_BF16);
    tn_sgemm(0, 1, n, n, n, 1.0f, A, n, B, n, 0.0f, C3, n); /* tn_sgemm ignores the setting */
    TN_CHECK(memcmp(C0, C3, nn * sizeof(float)) == 0);
    tn_gemm(TN_PRECISION_AUTO, 0, 1, n, n, n, 1.0f, A, n, B, n, 0.0f, C3, n);
    differ = memcmp(C0, C3, nn * sizeof(float)) != 0; /* now bf16 */
    tn_set_precision(TN_PRECISION_AUTO);
    TN_CHECK(memcmp(C0, C1, nn * sizeof(float)) == 0);
    TN_CHECK(memcmp(C0, C2, nn * sizeof(float)) == 0);
    TN_CHECK(differ);
    free(A);
    free(B);
    free(C0);
    free(C1);
    free(C2);
    free(C3);
}

/* ---- conv2d and linear layers in bf16 ---- */

typedef struct layer_out { float *y, *dx, *dw, *db; size_t ny, nx, nw, nb; } layer_out;

static float *dup_floats(const float *p, size_t n)
{
    float *q = (float *)malloc(n * sizeof(float));
    memcpy(q, p, n * sizeof(float));
    return q;
}

/* conv2d (kind 0: 3x3 pad 1; 1: 3x3 stride 2 reflect; 2: 1x1; 3: conv with Cin >= 8, flipped-
   kernel input gradient; 5: SinGAN's valid 32 -> 32; 6: valid 1 -> 32, two images) or linear
   (kind 4), loss = sum(y * r), on `threads` in `prec`. Kinds 3, 5 and 6 are large enough for the
   products to be split between threads (AMX: the tile convolutions, 6 with the taps as channels). */
static void run_layer(int kind, tn_precision prec, int threads, layer_out *o)
{
    tn_ctx *c = tn_ctx_create();
    tn_rng rng;
    tn_tensor *x, *w, *b, *y, *r;
    tn_set_threads(threads);
    tn_set_precision(prec);
    tn_rng_seed(&rng, 21, (uint64_t)kind);
    if (kind == 4) {
        x = tn_tensor_requires_grad(c, tn_tensor_2d(c, 300, 70));
        w = tn_tensor_requires_grad(c, tn_tensor_2d(c, 90, 70));
        b = tn_tensor_requires_grad(c, tn_tensor_1d(c, 90));
    } else if (kind >= 5) {
        int cin = kind == 5 ? 32 : 1;
        x = tn_tensor_requires_grad(c, kind == 5 ? tn_tensor_4d(c, 1, 32, 40, 44) : tn_tensor_4d(c, 2, 1, 100, 90));
        w = tn_tensor_requires_grad(c, tn_tensor_4d(c, 32, cin, 3, 3));
        b = tn_tensor_requires_grad(c, tn_tensor_1d(c, 32));
    } else {
        int cin = kind == 3 ? 16 : 5, k = kind == 2 ? 1 : 3;
        x = tn_tensor_requires_grad(c, tn_tensor_4d(c, 2, cin, 37, 41));
        w = tn_tensor_requires_grad(c, tn_tensor_4d(c, 12, cin, k, k));
        b = tn_tensor_requires_grad(c, tn_tensor_1d(c, 12));
    }
    tn_init_uniform(x, &rng, -1, 1);
    tn_init_uniform(w, &rng, -1, 1);
    tn_init_uniform(b, &rng, -1, 1);
    if (kind == 4) {
        y = tn_linear(c, x, w, b);
    } else {
        tn_conv_opts co;
        memset(&co, 0, sizeof co);
        co.pad = kind == 2 || kind >= 5 ? 0 : 1;
        co.stride = kind == 1 ? 2 : 1;
        co.padding = kind == 1 ? TN_PADDING_REFLECT : TN_PADDING_ZERO;
        y = tn_conv2d(c, x, w, b, &co);
    }
    r = tn_tensor_new(c, y->ndim, y->shape);
    tn_init_uniform(r, &rng, -1, 1);
    TN_CHECK(tn_backward(c, tn_sum(c, tn_mul(c, y, r))) == TN_OK);
    o->ny = y->numel;
    o->nx = x->numel;
    o->nw = w->numel;
    o->nb = b->numel;
    o->y = dup_floats(y->data, y->numel);
    o->dx = dup_floats(x->grad, x->numel);
    o->dw = dup_floats(w->grad, w->numel);
    o->db = dup_floats(b->grad, b->numel);
    tn_ctx_free(c);
    tn_set_precision(TN_PRECISION_AUTO);
    tn_set_threads(0);
}

static void free_layer(layer_out *o)
{
    free(o->y);
    free(o->dx);
    free(o->dw);
    free(o->db);
}

static double rel_l2(const float *a, const float *ref, size_t n)
{
    double d = 0, r = 0;
    size_t i;
    for (i = 0; i < n; i++) {
        d += ((double)a[i] - ref[i]) * ((double)a[i] - ref[i]);
        r += (double)ref[i] * ref[i];
    }
    return r > 0 ? sqrt(d / r) : sqrt(d);
}

static int same_layer(const layer_out *a, const layer_out *b)
{
    return !memcmp(a->y, b->y, a->ny * sizeof(float)) && !memcmp(a->dx, b->dx, a->nx * sizeof(float)) &&
           !memcmp(a->dw, b->dw, a->nw * sizeof(float)) && !memcmp(a->db, b->db, a->nb * sizeof(float));
}

TN_TEST(conv_and_linear_bf16_gradients)
{
    static const char *names[7] = {"conv3x3", "conv3x3_s2_reflect", "conv1x1", "conv3x3_cin16", "linear", "conv3x3_valid_c32",
                                   "conv3x3_valid_c1"};
    int kind;
    for (kind = 0; kind < 7; kind++) {
        layer_out f, h1, h2, h3, d;
        double ey, ex, ew, eb;
        run_layer(kind, TN_PRECISION_FP32, 1, &f);
        run_layer(kind, TN_PRECISION_AUTO, 2, &d); /* the default: exactly fp32 */
        run_layer(kind, TN_PRECISION_BF16, 1, &h1);
        run_layer(kind, TN_PRECISION_BF16, 2, &h2);
        run_layer(kind, TN_PRECISION_BF16, 3, &h3);
        ey = rel_l2(h1.y, f.y, f.ny);
        ex = rel_l2(h1.dx, f.dx, f.nx);
        ew = rel_l2(h1.dw, f.dw, f.nw);
        eb = rel_l2(h1.db, f.db, f.nb);
        fprintf(stderr, "  %s bf16 vs fp32, relative L2: y %.2e dx %.2e dw %.2e db %.2e\n", names[kind], ey, ex, ew, eb);
        TN_CHECK(ey <= 1.0 / 128 && ex <= 1.0 / 128 && ew <= 1.0 / 128 && eb <= 1.0 / 128);
        TN_CHECK(ey > 0); /* bf16 was used */
        TN_CHECK(same_layer(&h1, &h2) && same_layer(&h1, &h3));
        TN_CHECK(same_layer(&f, &d));
        free_layer(&f);
        free_layer(&d);
        free_layer(&h1);
        free_layer(&h2);
        free_layer(&h3);
    }
}

int main(void)
{
    (void)tn_test_data;
    TN_RUN(bf16_rounding);
    TN_RUN(bf16_precision_setting);
    TN_RUN(gemm_bf16_odd_shapes_all_transposes);
    TN_RUN(gemm_bf16_block_edges_alpha_beta);
    TN_RUN(gemm_bf16_emulation_is_vdpbf16ps_bit_for_bit);
    TN_RUN(gemm_bf16_pair_packing_layout);
    TN_RUN(gemm_bf16_bit_identical_for_any_thread_count);
    TN_RUN(gemm_fp32_forced_is_sgemm);
    TN_RUN(conv_and_linear_bf16_gradients);
    return tn_test_summary("test_bf16");
}
