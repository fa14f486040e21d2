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

