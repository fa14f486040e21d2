/* Tests of @@gemm: tn_sgemm against a double-accumulating reference over many shapes (tiny,
   primes, tile and block edges), all four transpose combinations, alpha/beta variants, padded
   leading dimensions, and bit-identical results for 1 and 2 threads. */
#include "terrainnet.h"
#include "tn_test.h"

/* Element (r, c) of op(X), X row-major with row stride ld. */
static double ref_get(const float *X, int ld, int trans, int r, int c)
{
    return trans ? X[(size_t)c * ld + r] : X[(size_t)r * ld + c];
}

/* C = alpha * op(A) op(B) + beta * C in double; beta == 0 ignores C. Mag gets the sum of the
   magnitudes of all terms, which scales the float rounding error. */
static void ref_sgemm(int ta, int tb, int M, int N, int K, float alpha, const float *A, int lda, const float *B,
                      int ldb, float beta, double *C, double *Mag, int ldc)
{
    int i, j, k;
    for (i = 0; i < M; i++)
        for (j = 0; j < N; j++) {
            double s = 0.0, m = 0.0, c = beta == 0.0f ? 0.0 : beta * C[(size_t)i * ldc + j];
            for (k = 0; k < K; k++) {
                double t = ref_get(A, lda, ta, i, k) * ref_get(B, ldb, tb, k, j);
                s += t;
                m += fabs(t);
            }
            C[(size_t)i * ldc + j] = alpha * s + c;
            Mag[(size_t)i * ldc + j] = fabs(alpha) * m + fabs(c);
        }
}

static float *rand_matrix(tn_rng *rng, size_t n)
{
    float *p = (float *)malloc((n ? n : 1) * sizeof(float));
    size_t i;
    for (i = 0; i < n; i++) p[i] = 2.0f * tn_rng_uniform(rng) - 1.0f;
    return p;
}

/* Runs one case and compares with the reference; NaN-fills C first when beta == 0 (it must not
   be read). Checks that padding columns beyond N are untouched. Returns 1 when it matches. */
static int check_case(int ta, int tb, int M, int N, int K, float alpha, float beta, int pad)
{
    tn_rng rng;
    int lda = (ta ? M : K) + pad, ldb = (tb ? K : N) + pad, ldc = N + pad;
    int rows_a = ta ? K : M, rows_b = tb ? N : K;
    float *A, *B, *C;
    double *R, *Mag;
    size_t i, nc = (size_t)M * ldc;
    int ok = 1;
    tn_rng_seed(&rng, (uint64_t)(M * 1000003 + N * 1009 + K), (uint64_t)(ta * 2 + tb));
    A = rand_matrix(&rng, (size_t)rows_a * lda);
    B = rand_matrix(&rng, (size_t)rows_b * ldb);
    C = rand_matrix(&rng, nc);
    R = (double *)malloc((nc ? nc : 1) * sizeof(double));
    Mag = (double *)calloc(nc ? nc : 1, sizeof(double));
    for (i = 0; i < nc; i++) {
        if (beta == 0.0f && (int)(i % (size_t)ldc) < N) C[i] = (float)NAN;
        R[i] = C[i];
    }
    tn_sgemm(ta, tb, M, N, K, alpha, A, lda, B, ldb, beta, C, ldc);
    ref_sgemm(ta, tb, M, N, K, alpha, A, lda, B, ldb, beta, R, Mag, ldc);
    for (i = 0; i < nc && ok; i++) {
        int col = (int)(i % (size_t)ldc);
        /* float rounding: a few eps times the magnitude of the terms (random signs keep the
           K-term worst case K * eps far away) */
        double tol = 1e-5 * Mag[i] + 1e-30;
        if (col >= N) ok = C[i] == (float)R[i]; /* padding untouched */
        else ok = fabs(C[i] - R[i]) <= tol;
        if (!ok)
            fprintf(stderr, "  mismatch ta=%d tb=%d M=%d N=%d K=%d alpha=%g beta=%g pad=%d at %d,%d: %.9g vs %.9g\n",
                    ta, tb, M, N, K, alpha, beta, pad, (int)(i / (size_t)ldc), col, C[i], R[i]);
    }
    free(A);
    free(B);
    free(C);
    free(R);
    free(Mag);
    return ok;
}

TN_TEST(gemm_tiny_and_prime_shapes_all_transposes)
{
    static const int dims[] = {1, 2, 3, 5, 7, 13, 17, 31, 33, 37, 64};
    int nd = (int)(sizeof dims / sizeof dims[0]), a, b, c, t;
    for (t = 0; t < 4; t++)
        for (a = 0; a < nd; a++)
            for (b = 0; b < nd; b++)
                for (c = 0; c < nd; c += 2) TN_CHECK(check_case(t >> 1, t & 1, dims[a], dims[b], dims[c], 1.0f, 0.0f, 0));
}

TN_TEST(gemm_block_edges_all_transposes)
{
    /* around the tile sizes (MR <= 8, NR <= 32) and the K/N/M block sizes (384/512/768) */
    static const int shapes[][3] = {{8, 32, 384}, {9, 33, 385}, {7, 31, 383}, {100, 513, 50}, {769, 40, 20},
                                    {64, 1000, 576}, {130, 70, 800}, {1, 1000, 3}, {1000, 1, 3}, {3, 5, 1200}};
    int s, t;
    for (s = 0; s < (int)(sizeof shapes / sizeof shapes[0]); s++)
        for (t = 0; t < 4; t++)
            TN_CHECK(check_case(t >> 1, t & 1, shapes[s][0], shapes[s][1], shapes[s][2], 1.0f, 0.0f, 0));
}

TN_TEST(gemm_alpha_beta_and_leading_dimensions)
{
    static const float ab[][2] = {{1.0f, 1.0f}, {-0.5f, 0.0f}, {2.0f, -1.5f}, {0.25f, 1.0f}, {1.0f, 0.5f}};
    static const int shapes[][3] = {{1, 1, 1}, {6, 17, 9}, {45, 77, 130}, {129, 300, 400}};
    int s, v, t, pad;
    for (s = 0; s < 4; s++)
        for (v = 0; v < 5; v++)
            for (t = 0; t < 4; t++)
                for (pad = 0; pad <= 5; pad += 5)
                    TN_CHECK(check_case(t >> 1, t & 1, shapes[s][0], shapes[s][1], shapes[s][2], ab[v][0], ab[v][1], pad));
}

TN_TEST(gemm_degenerate_sizes)
{
    float A[6] = {1, 2, 3, 4, 5, 6}, B[6] = {1, 1, 1, 1, 1, 1}, C[4] = {1, 2, 3, 4};
    float nanv = (float)NAN, Cn[4];
    int i;
    tn_sgemm(0, 0, 2, 2, 0, 1.0f, A, 1, B, 2, 3.0f, C, 2); /* K == 0: C = beta * C */
    TN_CHECK(C[0] == 3.0f && C[3] == 12.0f);
    for (i = 0; i < 4; i++) Cn[i] = nanv;
    tn_sgemm(0, 0, 2, 2, 0, 1.0f, A, 1, B, 2, 0.0f, Cn, 2); /* beta == 0: C not read */
    TN_CHECK(Cn[0] == 0.0f && Cn[3] == 0.0f);
    A[0] = nanv;
    tn_sgemm(0, 0, 2, 2, 3, 0.0f, A, 3, B, 2, 1.0f, C, 2); /* alpha == 0: A and B not used */
    TN_CHECK(C[0] == 3.0f && C[1] == 6.0f);
    tn_sgemm(0, 0, 0, 2, 3, 1.0f, A, 3, B, 2, 1.0f, C, 2); /* M == 0: nothing happens */
    TN_CHECK(C[0] == 3.0f);
}

/* Same inputs on 1 and 2 threads (and 3, more than the cores) must give identical bits. */
static int same_bits_for_thread_counts(int ta, int tb, int M, int N, int K, float beta)
{
    tn_rng rng;
    int lda = ta ? M : K, ldb = tb ? K : N, t, same = 1;
    float *A, *B, *C0, *C1;
    size_t nc = (size_t)M * N;
    tn_rng_seed(&rng, 7, 11);
    A = rand_matrix(&rng, (size_t)M * K);
    B = rand_matrix(&rng, (size_t)K * N);
    C0 = rand_matrix(&rng, nc);
    C1 = (float *)malloc(nc * sizeof(float));
    memcpy(C1, C0, nc * sizeof(float));
    tn_set_threads(1);
    tn_sgemm(ta, tb, M, N, K, 0.75f, A, lda, B, ldb, beta, C0, N);
    for (t = 2; t <= 3; t++) {
        float *Ct = rand_matrix(&rng, nc);
        memcpy(Ct, C1, nc * sizeof(float));
        tn_set_threads(t);
        tn_sgemm(ta, tb, M, N, K, 0.75f, A, lda, B, ldb, beta, Ct, N);
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

TN_TEST(gemm_bit_identical_for_any_thread_count)
{
    /* wide (threads split N), tall (threads split M), with K over several blocks */
    TN_CHECK(same_bits_for_thread_counts(0, 0, 64, 1000, 900, 0.0f));
    TN_CHECK(same_bits_for_thread_counts(1, 1, 64, 1000, 900, 1.0f));
    TN_CHECK(same_bits_for_thread_counts(0, 1, 1000, 40, 800, 0.5f));
    TN_CHECK(same_bits_for_thread_counts(1, 0, 301, 299, 777, 0.0f));
}

typedef struct nested_ctx {
    const float *A, *B;
    float *C[4];
    int n;
} nested_ctx;

static void nested_task(void *ctx, int ith, int nth)
{
    nested_ctx *c = (nested_ctx *)ctx;
    int i;
    for (i = ith; i < 4; i += nth) tn_sgemm(0, 0, c->n, c->n, c->n, 1.0f, c->A, c->n, c->B, c->n, 0.0f, c->C[i], c->n);
}

TN_TEST(gemm_inside_a_parallel_region)
{
    /* GEMMs run from pool workers (nested: each runs inline) must not share packing scratch */
    tn_rng rng;
    nested_ctx c;
    int i, n = 200, same = 1;
    float *ref = (float *)malloc((size_t)n * n * sizeof(float));
    tn_rng_seed(&rng, 3, 4);
    c.n = n;
    c.A = rand_matrix(&rng, (size_t)n * n);
    c.B = rand_matrix(&rng, (size_t)n * n);
    for (i = 0; i < 4; i++) c.C[i] = (float *)malloc((size_t)n * n * sizeof(float));
    tn_set_threads(1);
    tn_sgemm(0, 0, n, n, n, 1.0f, c.A, n, c.B, n, 0.0f, ref, n);
    tn_set_threads(2);
    tn_parallel_run(nested_task, &c);
    tn_set_threads(0);
    for (i = 0; i < 4; i++) same = same && memcmp(ref, c.C[i], (size_t)n * n * sizeof(float)) == 0;
    TN_CHECK(same);
    for (i = 0; i < 4; i++) free(c.C[i]);
    free((void *)c.A);
    free((void *)c.B);
    free(ref);
}

int main(void)
{
    (void)tn_test_data; /* the harness helper; these tests need no data files */
    TN_RUN(gemm_tiny_and_prime_shapes_all_transposes);
    TN_RUN(gemm_block_edges_all_transposes);
    TN_RUN(gemm_alpha_beta_and_leading_dimensions);
    TN_RUN(gemm_degenerate_sizes);
    TN_RUN(gemm_bit_identical_for_any_thread_count);
    TN_RUN(gemm_inside_a_parallel_region);
    return tn_test_summary("test_gemm");
}
