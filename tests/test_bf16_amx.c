/* test_bf16_amx: the AMX path of >>gemm_bf16 (tile copies of the packed blocks, zero padding, the
   32 x 32 blocks of four accumulator tiles, K blocks, alpha/beta, threads) on any x86-64 CPU: the
   tile intrinsics are replaced by a scalar model of the tile unit that follows the Intel SDM's
   pseudo-code for LDTILECFG, TILELOADD, TDPBF16PS and TILESTORED, and the CPU is told it has
   AMX. Each product is compared bit for bit with a scalar model of the same sums. What this
   cannot check is the tile unit itself: on a CPU with AMX, test_bf16 runs the real one. */
#if defined(__x86_64__) && ((defined(__clang__) && __clang_major__ >= 12) || (!defined(__clang__) && defined(__GNUC__) && __GNUC__ >= 11))
#define AMX_MODEL 1
#include <immintrin.h>
#include <stdint.h>
#include <string.h>
#include <math.h>
#include <assert.h>

/* tile state is per thread, as on the CPU */
static __thread unsigned char model_tile[8][16][64];
static __thread unsigned char model_rows[8];
static __thread unsigned short model_colsb[8];
static __thread int model_configured;
static int model_dp_calls; /* all threads (atomic) */

static void model_loadconfig(const void *cfg)
{
    const unsigned char *c = (const unsigned char *)cfg;
    int t;
    assert(c[0] == 1); /* palette 1 */
    for (t = 0; t < 8; t++) {
        model_colsb[t] = (unsigned short)(c[16 + 2 * t] | c[17 + 2 * t] << 8);
        model_rows[t] = c[48 + t];
        assert(model_rows[t] <= 16 && model_colsb[t] <= 64);
    }
    model_configured = 1;
}

static void model_loadd(int t, const void *base, long stride)
{
    int r;
    assert(model_configured);
    memset(model_tile[t], 0, sizeof model_tile[t]);
    for (r = 0; r < model_rows[t]; r++) memcpy(model_tile[t][r], (const char *)base + r * stride, model_colsb[t]);
}

static void model_stored(int t, void *base, long stride)
{
    int r;
    assert(model_configured);
    for (r = 0; r < model_rows[t]; r++) memcpy((char *)base + r * stride, model_tile[t][r], model_colsb[t]);
}

static float model_bf16(const unsigned char *p)
{
    uint32_t u = (uint32_t)(p[0] | p[1] << 8) << 16;
    float f;
    memcpy(&f, &u, sizeof f);
    return f;
}

/* TDPBF16PS: for each row m, pair k, column n: c += a.bf16[2k] * b[k].bf16[2n], then the odd ones. */
static void model_dpbf16ps(int c, int a, int b)
{
    int m, k, n;
    assert(model_configured && model_colsb[a] / 4 == model_rows[b] && model_colsb[c] == model_colsb[b] &&
           model_rows[c] == model_rows[a]);
    __atomic_fetch_add(&model_dp_calls, 1, __ATOMIC_RELAXED);
    for (m = 0; m < model_rows[c]; m++)
        for (k = 0; k < model_colsb[a] / 4; k++)
            for (n = 0; n < model_colsb[c] / 4; n++) {
                float acc;
                memcpy(&acc, &model_tile[c][m][4 * n], sizeof acc);
                acc = fmaf(model_bf16(&model_tile[a][m][4 * k]), model_bf16(&model_tile[b][k][4 * n]), acc);
                acc = fmaf(model_bf16(&model_tile[a][m][4 * k + 2]), model_bf16(&model_tile[b][k][4 * n + 2]), acc);
                memcpy(&model_tile[c][m][4 * n], &acc, sizeof acc);
            }
}

#undef _tile_loadconfig
#undef _tile_zero
#undef _tile_loadd
#undef _tile_stored
#undef _tile_dpbf16ps
#undef _tile_release
#define _tile_loadconfig(cfg) model_loadconfig(cfg)
#define _tile_zero(t) memset(model_tile[t], 0, sizeof model_tile[t])
#define _tile_loadd(t, base, stride) model_loadd(t, (const void *)(base), (long)(stride))
#define _tile_stored(t, base, stride) model_stored(t, (void *)(base), (long)(stride))
#define _tile_dpbf16ps(c, a, b) model_dpbf16ps(c, a, b)
#define _tile_release() (model_configured = 0)
#endif

/* Only @@core ... @@train compiled in (the engine): the tile path of @@gemm is all this tests. */
#define TN_NO_NOISE
#define TN_NO_SKETCH
#define TN_NO_EXTRACT
#define TN_NO_FINEDETAIL
#define TN_NO_STYLE
#define TN_NO_TEXGAN
#define TN_NO_SINGAN
#define TN_NO_GNN
#define TN_NO_SEASON
#define TN_NO_RENDER
#define TN_NO_EXPORT
#define TN_NO_WORLD
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include "tn_test.h"

#ifdef AMX_MODEL
static float *rand_matrix(tn_rng *rng, size_t n)
{
    float *p = (float *)malloc((n ? n : 1) * sizeof(float));
    size_t i;
    for (i = 0; i < n; i++) p[i] = 2.0f * tn_rng_uniform(rng) - 1.0f;
    return p;
}

/* One element as the tiles sum it: K in the driver's blocks, each from zero with the even k of a
   pair first, C = alpha * block + beta * C (beta of later blocks 1). */
static float amx_element_model(const float *a, const float *b, int K, float alpha, float beta, float c)
{
    int kblocks = (K + TN__GEMM_KC - 1) / TN__GEMM_KC, kcb = (K + kblocks - 1) / kblocks, pc, k;
    for (pc = 0; pc < K; pc += kcb) {
        int kc = K - pc < kcb ? K - pc : kcb;
        float acc = 0.0f, bt = pc == 0 ? beta : 1.0f, v;
        for (k = 0; k < kc; k += 2) {
            acc = fmaf(a[pc + k], b[pc + k], acc);
            if (k + 1 < kc) acc = fmaf(a[pc + k + 1], b[pc + k + 1], acc);
        }
        v = alpha * acc;
        c = bt == 0.0f ? v : v + bt * c;
    }
    return c;
}

static int amx_case(int ta, int tb, int M, int N, int K, float alpha, float beta, int threads)
{
    tn_rng rng;
    int lda = ta ? M : K, ldb = tb ? K : N, i, j, k, same = 1;
    float *A, *B, *C, *C0, *arow, *bcol;
    tn_rng_seed(&rng, (uint64_t)(M * 131 + N * 7 + K), (uint64_t)(ta * 2 + tb));
    A = rand_matrix(&rng, (size_t)M * K);
    B = rand_matrix(&rng, (size_t)K * N);
    C = rand_matrix(&rng, (size_t)M * N);
    C0 = (float *)malloc((size_t)M * N * sizeof(float));
    memcpy(C0, C, (size_t)M * N * sizeof(float));
    arow = (float *)malloc((size_t)K * sizeof(float));
    bcol = (float *)malloc((size_t)K * sizeof(float));
    tn_set_threads(threads);
    model_dp_calls = 0;
    tn_gemm(TN_PRECISION_BF16, ta, tb, M, N, K, alpha, A, lda, B, ldb, beta, C, N);
    tn_set_threads(0);
    if (model_dp_calls == 0) same = 0; /* the tiles were not used */
    for (i = 0; i < M && same; i++)
        for (j = 0; j < N && same; j++) {
            float m;
            for (k = 0; k < K; k++) {
                arow[k] = tn__bf16_round(ta ? A[(size_t)k * lda + i] : A[(size_t)i * lda + k]);
                bcol[k] = tn__bf16_round(tb ? B[(size_t)j * ldb + k] : B[(size_t)k * ldb + j]);
            }
            m = amx_element_model(arow, bcol, K, alpha, beta, C0[(size_t)i * N + j]);
            if (memcmp(&m, &C[(size_t)i * N + j], sizeof m)) {
                fprintf(stderr, "  AMX path ta=%d tb=%d M=%d N=%d K=%d t=%d at %d,%d: %.9g, model %.9g\n", ta, tb, M, N, K,
                        threads, i, j, C[(size_t)i * N + j], m);
                same = 0;
            }
        }
    free(A);
    free(B);
    free(C);
    free(C0);
    free(arow);
    free(bcol);
    return same;
}

TN_TEST(amx_path_matches_the_tile_model)
{
    static const int shapes[][3] = {{32, 32, 32}, {9, 33, 385}, {33, 31, 383}, {100, 260, 50},
                                    {70, 40, 21},  {64, 300, 800}, {1, 1000, 3}, {800, 40, 2}};
    static const float ab[][2] = {{1.0f, 0.0f}, {1.0f, 1.0f}, {2.0f, -1.5f}};
    int s, t, v;
    unsigned real, pass;
    tn__cpu_probed = 0;
    real = tn_cpu_features();
    for (pass = 0; pass < 2; pass++) { /* the portable data movement, then AVX-512's where the CPU has it */
        if (pass == 1 && !(real & TN_CPU_AVX512F)) break;
        /* told it has tiles; the model stands in */
        tn__cpu_flags = TN_CPU_AVX2 | TN_CPU_AMX_BF16 | (pass ? real & (TN_CPU_AVX512F | TN_CPU_AVX512_BF16) : 0u);
        tn__cpu_probed = 1;
        TN_CHECK(!strcmp(tn_gemm_bf16_kernel(), "amx-bf16"));
        for (s = 0; s < (int)(sizeof shapes / sizeof shapes[0]); s++)
            for (t = 0; t < 4; t++)
                for (v = 0; v < 3; v++)
                    TN_CHECK(amx_case(t >> 1, t & 1, shapes[s][0], shapes[s][1], shapes[s][2], ab[v][0], ab[v][1], 1 + (s & 1)));
    }
    TN_CHECK(!model_configured); /* released */
    tn__cpu_probed = 0;
}

/* ---- convolutions on the tiles (tn__conv_forward_amx, tn__conv_weight_grad_amx) ---- */

static float bf(float v) { return tn__bf16_round(v); }

/* The padded input as the tiles see it: bf16, zero padding (or reflected), zero past the padded
   width Wp and past the channels. */
static float xpad(const tn__conv_geom *g, const float *x, int c, int iyp, int ixp)
{
    int iy = tn__conv_src(iyp, 0, 1, g->pad, 1, g->H, g->reflect), ix;
    if (c >= g->C || iy < 0 || ixp >= g->W + 2 * g->pad) return 0.0f;
    ix = tn__conv_src(ixp, 0, 1, g->pad, 1, g->W, g->reflect);
    return ix < 0 ? 0.0f : bf(x[((size_t)c * g->H + iy) * g->W + ix]);
}

/* y[m][oy][ox] as the forward's tiles sum it: taps in order, each over 32-channel steps of
   channel pairs (even channel first; a single step has (C + 1) / 2 pairs, later steps 16, zeros
   past C), from zero; then + bias, then + beta * y. Up to 32 channels x taps, over channels x
   taps in w's order instead (the taps as channels of a 1 x 1 convolution), pairs of them. */
static float conv_model(const tn__conv_geom *g, const float *x, const float *w, const float *bias, float beta, float y0,
                        int m, int oy, int ox)
{
    int ntaps = g->KH * g->KW, ksteps = (g->C + 31) / 32, kpairs = ksteps == 1 ? (g->C + 1) / 2 : 16, t, s, h;
    float acc = 0.0f, v;
    if (ntaps > 1 && g->C * ntaps <= 32)
        for (h = 0; h < (g->C * ntaps + 1) / 2 * 2; h++) {
            int c = h / ntaps;
            t = h % ntaps;
            acc = fmaf(h < g->C * ntaps ? bf(w[(size_t)m * g->C * ntaps + h]) : 0.0f,
                       xpad(g, x, c, oy + t / g->KW * g->dil, ox + t % g->KW * g->dil), acc);
        }
    else
        for (t = 0; t < ntaps; t++)
            for (s = 0; s < ksteps; s++)
                for (h = 0; h < 2 * kpairs; h++) {
                    int c = 32 * s + h;
                    float a = c < g->C ? bf(w[((size_t)m * g->C + c) * ntaps + t]) : 0.0f;
                    acc = fmaf(a, xpad(g, x, c, oy + t / g->KW * g->dil, ox + t % g->KW * g->dil), acc);
                }
    v = bias ? acc + bias[m] : acc;
    return beta == 0.0f ? v : v + beta * y0;
}

/* dw[m][c][t] + the tiles' sum: images, output rows, then positions 0 .. Wq (OW rounded up to 32;
   dy zero past OW) in order, from zero (also with the taps as channels: only products with dy
   zero change, and they add +0). */
static float dw_model(const tn__conv_geom *g, int N, int M, const float *x, const float *dy, float dw0, int m, int c, int t)
{
    int wq = (g->OW + 31) / 32 * 32, n, oy, ox;
    float acc = 0.0f;
    for (n = 0; n < N; n++)
        for (oy = 0; oy < g->OH; oy++)
            for (ox = 0; ox < wq; ox++) {
                float d = ox < g->OW ? bf(dy[(((size_t)n * M + m) * g->OH + oy) * g->OW + ox]) : 0.0f;
                acc = fmaf(xpad(g, x + (size_t)n * g->C * g->H * g->W, c, oy + t / g->KW * g->dil, ox + t % g->KW * g->dil), d, acc);
            }
    return dw0 + acc;
}

static int amx_conv_case(int C, int M, int H, int W, int K, int pad, int dil, int reflect, int N, int threads)
{
    tn__conv_geom g;
    tn_ctx *ctx = tn_ctx_create();
    tn_rng rng;
    size_t nx, nw, ny, i;
    int m, c, t, oy, ox, n, same = 1, calls;
    float *x, *w, *b, *y, *y2, *y0, *dy, *dw, *dw0, *db;
    g.C = C; g.H = H; g.W = W; g.KH = g.KW = K; g.stride = 1; g.pad = pad; g.dil = dil; g.reflect = reflect;
    g.OH = H + 2 * pad - dil * (K - 1);
    g.OW = W + 2 * pad - dil * (K - 1);
    nx = (size_t)N * C * H * W;
    nw = (size_t)M * C * K * K;
    ny = (size_t)N * M * g.OH * g.OW;
    tn_rng_seed(&rng, (uint64_t)(C * 1000 + M), (uint64_t)(H * 100 + W));
    x = rand_matrix(&rng, nx);
    w = rand_matrix(&rng, nw);
    b = rand_matrix(&rng, (size_t)M);
    y0 = rand_matrix(&rng, ny);
    dy = rand_matrix(&rng, ny);
    dw0 = rand_matrix(&rng, nw);
    y = (float *)malloc(ny * sizeof(float));
    y2 = (float *)malloc(ny * sizeof(float));
    dw = (float *)malloc(nw * sizeof(float));
    db = (float *)calloc((size_t)M, sizeof(float));
    memcpy(y2, y0, ny * sizeof(float));
    memcpy(dw, dw0, nw * sizeof(float));
    tn_set_threads(threads);
    model_dp_calls = 0;
    TN_CHECK(tn__conv_forward(ctx, &g, N, M, x, w, b, y, 0.0f) == 1);
    TN_CHECK(tn__conv_forward(ctx, &g, N, M, x, w, NULL, y2, -0.75f) == 1);
    calls = model_dp_calls;
    TN_CHECK(tn__conv_weight_grad(ctx, &g, N, M, x, dy, dw, db) == 1);
    tn_set_threads(0);
    if (calls == 0 || model_dp_calls == calls) same = 0; /* the tiles were not used */
    for (n = 0; n < N && same; n++)
        for (m = 0; m < M && same; m++)
            for (oy = 0; oy < g.OH && same; oy++)
                for (ox = 0; ox < g.OW && same; ox++) {
                    size_t at = (((size_t)n * M + m) * g.OH + oy) * g.OW + ox;
                    const float *xn = x + (size_t)n * C * H * W;
                    float e1 = conv_model(&g, xn, w, b, 0.0f, 0.0f, m, oy, ox), e2 = conv_model(&g, xn, w, NULL, -0.75f, y0[at], m, oy, ox);
                    if (memcmp(&e1, &y[at], sizeof e1) || memcmp(&e2, &y2[at], sizeof e2)) {
                        fprintf(stderr, "  AMX conv C=%d M=%d %dx%d k%d pad %d dil %d at %d,%d,%d,%d: %.9g %.9g, model %.9g %.9g\n", C, M,
                                H, W, K, pad, dil, n, m, oy, ox, y[at], y2[at], e1, e2);
                        same = 0;
                    }
                }
    for (m = 0; m < M && same; m++)
        for (c = 0; c < C && same; c++)
            for (t = 0; t < K * K && same; t++) {
                size_t at = ((size_t)m * C + c) * K * K + t;
                float e = dw_model(&g, N, M, x, dy, dw0[at], m, c, t);
                if (memcmp(&e, &dw[at], sizeof e)) {
                    fprintf(stderr, "  AMX conv dw C=%d M=%d %dx%d k%d at %d,%d,%d: %.9g, model %.9g\n", C, M, H, W, K, m, c, t, dw[at], e);
                    same = 0;
                }
            }
    for (m = 0; m < M && same; m++) { /* the bias gradient: float32 sums of dy */
        double s = 0;
        for (n = 0; n < N; n++)
            for (i = 0; i < (size_t)g.OH * g.OW; i++) s += dy[((size_t)n * M + m) * g.OH * g.OW + i];
        if (fabs(db[m] - s) > 1e-4 * (1 + fabs(s))) same = 0;
    }
    free(x); free(w); free(b); free(y); free(y2); free(y0); free(dy); free(dw); free(dw0); free(db);
    tn_ctx_free(ctx);
    return same;
}

TN_TEST(amx_convolutions_match_the_tile_model)
{
    /* C, M, H, W, K, pad, dil, reflect, N: SinGAN's valid 32 -> 32; taps as channels (3 x 9),
       odd M, two images; two channel steps (the second partial), dilation, reflection; taps as
       channels (1 x 9), three M tiles; 1 x 1 to one channel; 5 x 5 taps, a row wider than 32
       positions with a partial chunk; 4 x 9 taps as channels (36 > 32: not) */
    static const int cases[][9] = {{32, 32, 12, 40, 3, 0, 1, 0, 1}, {3, 20, 9, 33, 3, 1, 1, 0, 2}, {40, 8, 7, 20, 3, 2, 2, 1, 1},
                                   {1, 33, 8, 70, 3, 1, 1, 0, 1},   {16, 1, 10, 10, 1, 0, 1, 0, 1}, {5, 17, 3, 97, 5, 2, 1, 0, 1},
                                   {4, 9, 6, 35, 3, 0, 1, 0, 2}};
    unsigned real, pass;
    int k;
    tn__cpu_probed = 0;
    real = tn_cpu_features();
    tn_set_precision(TN_PRECISION_BF16);
    for (pass = 0; pass < 2; pass++) { /* the portable data movement, then AVX-512's where the CPU has it */
        if (pass == 1 && !(real & TN_CPU_AVX512F)) break;
        /* told it has tiles; the model stands in */
        tn__cpu_flags = TN_CPU_AVX2 | TN_CPU_AMX_BF16 | (pass ? real & (TN_CPU_AVX512F | TN_CPU_AVX512_BF16) : 0u);
        tn__cpu_probed = 1;
        for (k = 0; k < (int)(sizeof cases / sizeof cases[0]); k++) {
            const int *c = cases[k];
            TN_CHECK(amx_conv_case(c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8], 1 + (k & 1)));
        }
    }
    tn_set_precision(TN_PRECISION_AUTO);
    TN_CHECK(!model_configured);
    tn__cpu_probed = 0;
}

/* The VCVTNE2PS2BF16 conversions (tn__bf16_halves, tn__bf16_pair_words, on CPUs with
   AVX512-BF16) against tn__bf16_bits: the same bytes for ties, subnormals, infinities, NaNs and
   a million random bit patterns. */
TN_TEST(bf16_vector_conversions_keep_the_bytes)
{
    static const uint32_t special[] = {0x00000000u, 0x80000000u, 0x00000001u, 0x807fffffu, 0x00800000u, 0x3f808000u, 0x3f818000u,
                                       0x3f808001u, 0x7f7fffffu, 0xff7f8000u, 0x7f800000u, 0xff800000u, 0x7fc00000u, 0x7f800001u,
                                       0xffbfffffu, 0x7fffffffu, 0x3f7fffffu, 0x477fe000u};
    enum { n = 1 << 20 };
    float *x = (float *)malloc(n * sizeof(float)), *x1 = (float *)malloc(n * sizeof(float));
    uint16_t *h = (uint16_t *)malloc(n * sizeof(uint16_t));
    uint32_t *wd = (uint32_t *)malloc(n * sizeof(uint32_t)), u;
    tn_rng rng;
    int i, bad = 0;
    tn__cpu_probed = 0;
    if (!(tn_cpu_features() & TN_CPU_AVX512_BF16)) {
        fprintf(stderr, "  no AVX512-BF16 here: the scalar and AVX2 conversions only\n");
    }
    tn_rng_seed(&rng, 5, 6);
    for (i = 0; i < n; i++) {
        u = i < (int)(sizeof special / sizeof special[0]) ? special[i] : tn_rng_u32(&rng);
        memcpy(&x[i], &u, sizeof u);
        u = tn_rng_u32(&rng);
        memcpy(&x1[i], &u, sizeof u);
    }
    tn__bf16_halves(x, h, n - 5); /* a tail past the last whole group */
    tn__bf16_pair_words(x, x1, wd, n - 7);
    for (i = 0; i < n - 7 && bad < 5; i++) {
        uint32_t want = tn__bf16_bits(x[i]) >> 16 | (tn__bf16_bits(x1[i]) & 0xffff0000u);
        if (h[i] != (uint16_t)(tn__bf16_bits(x[i]) >> 16) || wd[i] != want) {
            memcpy(&u, &x[i], sizeof u);
            fprintf(stderr, "  %08x: halves %04x pair %08x, want %04x %08x\n", u, h[i], wd[i], (unsigned)(want & 0xffffu), want);
            bad++;
        }
    }
    TN_CHECK(bad == 0);
    tn__bf16_pair_words(x, NULL, wd, 100);
    for (i = 0; i < 100; i++) TN_CHECK(wd[i] == tn__bf16_bits(x[i]) >> 16);
    free(x);
    free(x1);
    free(h);
    free(wd);
}
#endif

int main(void)
{
    (void)tn_test_data;
#ifdef AMX_MODEL
    TN_RUN(bf16_vector_conversions_keep_the_bytes);
    TN_RUN(amx_path_matches_the_tile_model);
    TN_RUN(amx_convolutions_match_the_tile_model);
#else
    fprintf(stderr, "test_bf16_amx: no AMX kernel in this build (x86-64 with GCC >= 11 or clang >= 12)\n");
#endif
    return tn_test_summary("test_bf16_amx");
}
