/* Tests of @@core and @@thread: status strings, errors (per thread, forwarded from pool workers),
   size checks, RNG, pool, progress. */
#define TN_INTERNALS /* private tn__ code: the header's internals block */
#include "terrainnet.h"
#include "tn_test.h"
#if defined(__unix__) || defined(__APPLE__)
#include <unistd.h>
#endif
#ifndef TN_NO_THREADS
#include <pthread.h>
#endif

TN_TEST(status_strings_are_distinct)
{
    int i, j;
    for (i = 0; i < TN_STATUS_COUNT; i++) {
        TN_CHECK(tn_status_string((tn_status)i) != NULL);
        for (j = 0; j < i; j++) TN_CHECK(strcmp(tn_status_string((tn_status)i), tn_status_string((tn_status)j)) != 0);
    }
    TN_CHECK(strcmp(tn_status_string((tn_status)999), "unknown status") == 0);
}

TN_TEST(image_create_rejects_bad_sizes)
{
    tn_image img = {0, 0, 0, NULL};
    tn_clear_error();
    TN_CHECK(tn_image_create(&img, 0, 10, 1) == TN_ERR_INVALID_ARG);
    TN_CHECK(strlen(tn_last_error()) > 0);
    TN_CHECK(tn_image_create(&img, -5, 10, 1) == TN_ERR_INVALID_ARG);
    TN_CHECK(tn_image_create(&img, 2000000000, 2000000000, 4) == TN_ERR_TOO_LARGE);
    TN_CHECK(img.data == NULL);
    TN_CHECK(tn_image_create(&img, 3, 2, 2) == TN_OK);
    TN_CHECK(img.width == 3 && img.height == 2 && img.channels == 2 && img.data[11] == 0.0f);
    TN_PIXEL(&img, 2, 1, 1) = 7.0f;
    TN_CHECK(img.data[11] == 7.0f);
    tn_image_free(&img);
    TN_CHECK(img.data == NULL && img.width == 0);
    tn_image_free(&img); /* safe twice */
}

TN_TEST(image_range_skips_nan)
{
    tn_image img = {0, 0, 0, NULL};
    float lo, hi;
    TN_CHECK(tn_image_create(&img, 4, 1, 1) == TN_OK);
    img.data[0] = 3.0f; img.data[1] = (float)NAN; img.data[2] = -2.0f; img.data[3] = 1.0f;
    TN_CHECK(tn_image_range(&lo, &hi, &img) == 1);
    TN_CHECK(lo == -2.0f && hi == 3.0f);
    tn_image_free(&img);
}

/* Reference sequence of the PCG32 paper's demo program (pcg32-demo, seed 42, stream 54). */
TN_TEST(rng_matches_pcg32_reference)
{
    static const uint32_t expect[6] = {0xa15c02b7u, 0x7b47f409u, 0xba1d3330u, 0x83d2f293u, 0xbfa4784bu, 0xcbed606eu};
    tn_rng r;
    int i;
    tn_rng_seed(&r, 42u, 54u);
    for (i = 0; i < 6; i++) TN_CHECK(tn_rng_u32(&r) == expect[i]);
}

TN_TEST(rng_distributions)
{
    tn_rng r;
    int i, counts[7] = {0};
    double sum = 0, sum2 = 0;
    tn_rng_seed(&r, 1, 2);
    for (i = 0; i < 70000; i++) {
        float u = tn_rng_uniform(&r);
        TN_CHECK(u >= 0.0f && u < 1.0f);
        counts[tn_rng_below(&r, 7)]++;
    }
    for (i = 0; i < 7; i++) TN_CHECK(counts[i] > 9400 && counts[i] < 10600);
    for (i = 0; i < 100000; i++) {
        double g = tn_rng_normal(&r);
        sum += g;
        sum2 += g * g;
    }
    TN_CHECK_NEAR(sum / 100000, 0.0, 0.02);
    TN_CHECK_NEAR(sum2 / 100000, 1.0, 0.02);
}

typedef struct { double *out; } fill_ctx;
static void fill_range(void *ctx, size_t b, size_t e)
{
    fill_ctx *c = (fill_ctx *)ctx;
    size_t i;
    for (i = b; i < e; i++) c->out[i] = sin((double)i) * 3.0 + (double)i;
}

TN_TEST(parallel_for_same_for_any_thread_count)
{
    enum { N = 100003 };
    double *a = (double *)malloc(N * sizeof(double)), *b = (double *)malloc(N * sizeof(double));
    fill_ctx c;
    tn_set_threads(1);
    c.out = a;
    tn_parallel_for(N, 64, fill_range, &c);
    tn_set_threads(2);
    TN_CHECK(tn_get_threads() == 2);
    c.out = b;
    tn_parallel_for(N, 64, fill_range, &c);
    TN_CHECK(memcmp(a, b, N * sizeof(double)) == 0);
    TN_CHECK(a[N - 1] == sin((double)(N - 1)) * 3.0 + (double)(N - 1));
    tn_set_threads(0);
    TN_CHECK(tn_get_threads() >= 1);
    free(a);
    free(b);
}

typedef struct { int hits[8]; int nested_nth[8]; } run_ctx;
static void inner_task(void *ctx, int ith, int nth) { (void)ith; *(int *)ctx = nth; }
static void outer_task(void *ctx, int ith, int nth)
{
    run_ctx *c = (run_ctx *)ctx;
    (void)nth;
    c->hits[ith]++;
    tn_parallel_run(inner_task, &c->nested_nth[ith]); /* nested: must run inline with nth 1 */
}

TN_TEST(parallel_run_covers_every_thread_and_nests)
{
    run_ctx c;
    int i, rep;
    memset(&c, 0, sizeof c);
    tn_set_threads(2);
    for (rep = 0; rep < 1000; rep++) tn_parallel_run(outer_task, &c);
    for (i = 0; i < 2; i++) TN_CHECK(c.hits[i] == 1000);
    TN_CHECK(c.hits[2] == 0);
    TN_CHECK(c.nested_nth[0] == 1 && c.nested_nth[1] == 1);
    tn_set_threads(0);
}

/* ---- per-thread error detail ---- */

/* Fails with "image size <tag> x <n> x 1 is not positive". */
static void fail_with(int tag, int n)
{
    tn_image img = {0, 0, 0, NULL};
    (void)tn_image_create(&img, tag, n, 1);
}

static int is_failure_of(const char *msg, int tag, int n)
{
    char want[128];
    snprintf(want, sizeof want, "image size %d x %d x 1 is not positive", tag, n);
    return strcmp(msg, want) == 0;
}

#ifndef TN_NO_THREADS
enum { ERR_ROUNDS = 20000 };
typedef struct {
    pthread_mutex_t *mu;
    pthread_cond_t *cv;
    int *ready;
    int tag, wrong, fresh_empty;
} err_thread;

static void *err_thread_main(void *arg)
{
    err_thread *t = (err_thread *)arg;
    int i;
    t->fresh_empty = tn_last_error()[0] == 0; /* a new thread starts with no message */
    pthread_mutex_lock(t->mu); /* start together, so the two loops overlap */
    if (++*t->ready == 2) pthread_cond_broadcast(t->cv);
    while (*t->ready < 2) pthread_cond_wait(t->cv, t->mu);
    pthread_mutex_unlock(t->mu);
    for (i = 1; i <= ERR_ROUNDS; i++) {
        fail_with(t->tag, i);
        if (!is_failure_of(tn_last_error(), t->tag, i)) t->wrong++;
    }
    return NULL;
}
#endif

TN_TEST(last_error_is_per_thread)
{
#ifdef TN_NO_THREADS
    TN_SKIP("built with TN_NO_THREADS");
#else
    pthread_mutex_t mu = PTHREAD_MUTEX_INITIALIZER;
    pthread_cond_t cv = PTHREAD_COND_INITIALIZER;
    pthread_t tid[2];
    err_thread t[2];
    int ready = 0, i;
    fail_with(-99, 1); /* the main thread's own message, which the threads must not touch */
    for (i = 0; i < 2; i++) {
        t[i].mu = &mu;
        t[i].cv = &cv;
        t[i].ready = &ready;
        t[i].tag = -1 - i;
        t[i].wrong = 0;
        t[i].fresh_empty = 0;
        TN_CHECK(pthread_create(&tid[i], NULL, err_thread_main, &t[i]) == 0);
    }
    for (i = 0; i < 2; i++) pthread_join(tid[i], NULL);
    for (i = 0; i < 2; i++) TN_CHECK(t[i].wrong == 0 && t[i].fresh_empty);
    TN_CHECK(is_failure_of(tn_last_error(), -99, 1));
    tn_clear_error();
    TN_CHECK(tn_last_error()[0] == 0);
#endif
}

/* Threads whose share is listed in fail_mask fail with tag -(10 + ith). */
static void failing_task(void *ctx, int ith, int nth)
{
    int mask = *(const int *)ctx;
    (void)nth;
    if (mask & (1 << ith)) fail_with(-(10 + ith), 5);
}

TN_TEST(worker_failure_reaches_the_caller)
{
    int mask;
    tn_set_threads(4);
    if (tn_get_threads() < 4) TN_SKIP("fewer than 4 threads (TN_NO_THREADS)");
    tn_clear_error();
    mask = 1 << 1; /* a worker fails, the caller does not: the caller gets the worker's message */
    tn_parallel_run(failing_task, &mask);
    TN_CHECK(is_failure_of(tn_last_error(), -11, 5));
    mask = (1 << 3) | (1 << 2); /* several workers: the lowest ith, whatever the timing */
    tn_parallel_run(failing_task, &mask);
    TN_CHECK(is_failure_of(tn_last_error(), -12, 5));
    mask = (1 << 0) | (1 << 2); /* the caller failed too: its own message stays */
    tn_parallel_run(failing_task, &mask);
    TN_CHECK(is_failure_of(tn_last_error(), -10, 5));
    fail_with(-20, 5);
    mask = 0; /* nobody fails: the message is left alone */
    tn_parallel_run(failing_task, &mask);
    TN_CHECK(is_failure_of(tn_last_error(), -20, 5));
    tn_set_threads(0);
}

static int cancel_after_half(void *user, const char *stage, double f)
{
    (void)stage;
    ++*(int *)user;
    return f >= 0.5;
}

TN_TEST(progress_hook_can_cancel)
{
    int calls = 0;
    tn_set_progress(cancel_after_half, &calls);
    TN_CHECK(tn__progress("stage", 0.25) == TN_OK);
    TN_CHECK(tn__progress("stage", 0.75) == TN_ERR_CANCELLED);
    TN_CHECK(strstr(tn_last_error(), "stage") != NULL);
    TN_CHECK(calls == 2);
    tn_set_progress(NULL, NULL);
    TN_CHECK(tn__progress("stage", 0.75) == TN_OK);
}

#if !defined(TN_NO_THREADS) && defined(TN__TLS)
static int count_reports(void *user, const char *stage, double f)
{
    (void)stage;
    (void)f;
    ++*(int *)user;
    return 0;
}

static void *progress_thread_main(void *arg)
{
    (void)tn__progress("other thread", 0.5); /* no hook of its own yet: reaches nobody */
    tn_set_progress(count_reports, arg);
    (void)tn__progress("other thread", 0.5);
    (void)tn__progress("other thread", 1.0);
    return NULL; /* its hook ends with it; the main thread's was never replaced */
}
#endif

TN_TEST(progress_hook_is_per_thread)
{
#if defined(TN_NO_THREADS) || !defined(TN__TLS)
    TN_SKIP("no thread-local storage: one hook for the process");
#else
    int mine = 0, theirs = 0;
    pthread_t tid;
    tn_set_progress(count_reports, &mine);
    TN_CHECK(pthread_create(&tid, NULL, progress_thread_main, &theirs) == 0);
    pthread_join(tid, NULL);
    TN_CHECK(tn__progress("main thread", 1.0) == TN_OK);
    TN_CHECK(mine == 1 && theirs == 2);
    tn_set_progress(NULL, NULL);
#endif
}

TN_TEST(time_is_wall_time)
{
    /* training budgets, checkpoints and ETAs run on tn_time_seconds: a second asleep is a
       second (clock(), the process's CPU time, stood still: the strict -std=c99 build fell
       back to it) */
#if defined(__unix__) || defined(__APPLE__)
    double t0 = tn_time_seconds(), dt;
    sleep(1);
    dt = tn_time_seconds() - t0;
    printf("# a second asleep: %.3f s\n", dt);
    TN_CHECK(dt > 0.9 && dt < 30);
#else
    TN_SKIP("no sleep() here");
#endif
}

TN_TEST(size_checks_overflow)
{
    size_t out = 0;
    TN_CHECK(tn__size4(1000, 1000, 3, 4, &out) == TN_OK && out == 12000000u);
    TN_CHECK(tn__size4((size_t)1 << (4 * sizeof(size_t)), (size_t)1 << (4 * sizeof(size_t)), 1, 1, &out) == TN_ERR_TOO_LARGE); /* 2^64 or 2^32 */
    TN_CHECK(tn__size4(SIZE_MAX / 2, 3, 1, 1, &out) == TN_ERR_TOO_LARGE);
}

int main(void)
{
    TN_RUN(status_strings_are_distinct);
    TN_RUN(image_create_rejects_bad_sizes);
    TN_RUN(image_range_skips_nan);
    TN_RUN(rng_matches_pcg32_reference);
    TN_RUN(rng_distributions);
    TN_RUN(parallel_for_same_for_any_thread_count);
    TN_RUN(parallel_run_covers_every_thread_and_nests);
    TN_RUN(last_error_is_per_thread);
    TN_RUN(worker_failure_reaches_the_caller);
    TN_RUN(progress_hook_can_cancel);
    TN_RUN(progress_hook_is_per_thread);
    TN_RUN(size_checks_overflow);
    TN_RUN(time_is_wall_time);
    return tn_test_summary("test_core");
}
