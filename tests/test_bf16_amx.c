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
    tn__cpu_flags = TN_CPU_AVX2 | TN_CPU_AMX_BF16; /* told it has tiles; the model stands in */
    tn__cpu_probed = 1;
    TN_CHECK(!strcmp(tn_gemm_bf16_kernel(), "amx-bf16"));
    for (s = 0; s < (int)(sizeof shapes / sizeof shapes[0]); s++)
        for (t = 0; t < 4; t++)
            for (v = 0; v < 3; v++)
                TN_CHECK(amx_case(t >> 1, t & 1, shapes[s][0], shapes[s][1], shapes[s][2], ab[v][0], ab[v][1], 1 + (s & 1)));
    TN_CHECK(!model_configured); /* released */
    tn__cpu_probed = 0;
}
#endif

int main(void)
{
    (void)tn_test_data;
#ifdef AMX_MODEL
    TN_RUN(amx_path_matches_the_tile_model);
#else
    fprintf(stderr, "test_bf16_amx: no AMX kernel in this build (x86-64 with GCC >= 11 or clang >= 12)\n");
#endif
    return tn_test_summary("test_bf16_amx");
}
