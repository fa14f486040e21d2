/* ============================================================================================
   @@core  status codes, errors, allocation, RNG, progress, timing
   ============================================================================================ */

typedef enum tn_status {
    TN_OK = 0,
    TN_ERR_INVALID_ARG,     /* a bad argument value (negative size, unknown option, ...) */
    TN_ERR_OUT_OF_MEMORY,   /* an allocation failed */
    TN_ERR_TOO_LARGE,       /* sizes overflow or exceed TN_MAX_ALLOC */
    TN_ERR_IO,              /* open/read/write failed */
    TN_ERR_FORMAT,          /* unknown or unsupported file format or variant */
    TN_ERR_CORRUPT,         /* the data is damaged: bad CRC, bad zlib stream, truncated */
    TN_ERR_NUMERIC,         /* NaN/Inf in input, or a computation diverged */
    TN_ERR_SHAPE,           /* mismatched sizes/shapes between arguments or with a file */
    TN_ERR_EMPTY,           /* nothing to work on (empty image, empty sketch) */
    TN_ERR_CANCELLED,       /* the progress callback asked to stop */
    TN_STATUS_COUNT
} tn_status;

/* Name of a status code, e.g. "corrupt data". Never NULL. */
TN_API const char *tn_status_string(tn_status s);
/* Detail of the calling thread's most recent failure ("alps.png: CRC mismatch in IDAT chunk");
   "" if none. Each thread has its own buffer, owned by the library and overwritten by that
   thread's next failure: read it right after a failure. */
TN_API const char *tn_last_error(void);
/* Clears the calling thread's last error message. */
TN_API void tn_clear_error(void);

/* Deterministic RNG: PCG32 (O'Neill). The same seed/stream gives the same sequence everywhere. */
typedef struct tn_rng { uint64_t state, inc; } tn_rng;
TN_API void     tn_rng_seed(tn_rng *r, uint64_t seed, uint64_t stream);
TN_API uint32_t tn_rng_u32(tn_rng *r);
TN_API uint32_t tn_rng_below(tn_rng *r, uint32_t n);  /* uniform in [0, n), unbiased; n > 0 */
TN_API float    tn_rng_uniform(tn_rng *r);            /* uniform in [0, 1), 24 random bits */
TN_API float    tn_rng_normal(tn_rng *r);             /* standard normal (Box-Muller) */

/* Progress: long operations call the hook with a stage name and a fraction in [0, 1].
   Return non-zero from the hook to cancel; the operation then fails with TN_ERR_CANCELLED.
   The hook is the calling thread's (as tn_last_error): set it in the thread that runs the
   operation; two threads running methods side by side each report to their own. Built without
   thread-local storage (TN_NO_TLS, or a compiler without it) it is one for the process. */
typedef int (*tn_progress_fn)(void *user, const char *stage, double fraction);
TN_API void tn_set_progress(tn_progress_fn fn, void *user);

/* Memory budget: the total of the library's live allocations (each of 64 KiB or more, made
   through TN_MALLOC / TN_REALLOC inside the library: images, tensor arenas, decode buffers) may
   not pass the limit. An allocation that would pass it fails and the call returns
   TN_ERR_TOO_LARGE with a message naming the limit, so a hostile file (a decompression bomb, a
   model config naming millions of parts) fails early instead of taking the machine's memory.
   Default: half of the physical memory where the system tells it (sysconf), else TN_MAX_ALLOC;
   TN_MEMORY_LIMIT (bytes) at compile time replaces that default. tn_set_memory_limit(0) restores
   the default, SIZE_MAX removes the limit. Process-wide; safe to call from any thread. Memory the
   library hands out counts until it is freed through the library (tn_free, tn_image_free, ...). */
TN_API void tn_set_memory_limit(size_t bytes);
TN_API size_t tn_get_memory_limit(void);
TN_API size_t tn_memory_in_use(void);  /* the counted total now */

/* Monotonic wall-clock seconds (for benches and ETA). */
TN_API double tn_time_seconds(void);

/* One terminal line for a progress hook to redraw with '\r':
   "style              [##########..........]  50.0%   12.3s  ETA   12.3s", durations as 12.3s,
   4m05s or 2h07m ("--" when < 0: unknown), the bar as wide as fits in size - 1 characters
   (none below 57). buf gets at most size bytes, NUL included (size >= 1). Returns buf. */
TN_API char *tn_progress_line(char *buf, size_t size, const char *stage, double fraction, double elapsed_s, double eta_s);

/* --------------------------------------------------------------------------------------------
   >>core  (@@core implementation)
   -------------------------------------------------------------------------------------------- */

/* Error detail, one per thread, so pool workers and the caller's other threads never overwrite
   each other's message. `fails` counts the failures recorded on this thread; the pool compares it
   around a task to see whether a worker failed (>>thread forwards that message to the caller).
   Thread-local storage where the compiler has it (C++11, C11, MSVC, gcc/clang's __thread, which
   -std=c99 -pedantic accepts); otherwise, or with TN_NO_TLS, a pthread key; without threads a
   plain static. */
typedef struct tn__error_state {
    char msg[1024];
    unsigned long fails;
    int over_limit;      /* the memory budget refused an allocation; not yet reported */
    int msg_over_limit;  /* msg is about the memory budget */
} tn__error_state;

/* TN__TLS, the storage class of thread-locals where there is one: in src/internal.h */

#if defined(TN_NO_THREADS)
static tn__error_state tn__error_static;
static tn__error_state *tn__err(void) { return &tn__error_static; }
#elif defined(TN__TLS)
static TN__TLS tn__error_state tn__error_tls;
static tn__error_state *tn__err(void) { return &tn__error_tls; }
#else
/* pthread key: each thread's state is allocated on its first use and freed when it exits;
   if that allocation fails the thread falls back to one shared state. */
static pthread_key_t tn__error_key;
static pthread_once_t tn__error_once = PTHREAD_ONCE_INIT;
static int tn__error_key_ok;
static tn__error_state tn__error_shared;
static void tn__error_state_free(void *e) { TN_FREE(e); }
static void tn__error_key_create(void) { tn__error_key_ok = pthread_key_create(&tn__error_key, tn__error_state_free) == 0; }
static tn__error_state *tn__err(void)
{
    tn__error_state *e;
    pthread_once(&tn__error_once, tn__error_key_create);
    if (!tn__error_key_ok) return &tn__error_shared;
    e = (tn__error_state *)pthread_getspecific(tn__error_key);
    if (!e && (e = (tn__error_state *)TN_MALLOC(sizeof *e)) != NULL) {
        memset(e, 0, sizeof *e);
        if (pthread_setspecific(tn__error_key, e) != 0) {
            TN_FREE(e);
            e = NULL;
        }
    }
    return e ? e : &tn__error_shared;
}
#endif

TN_API const char *tn_status_string(tn_status s)
{
    static const char *const names[TN_STATUS_COUNT] = {
        "ok", "invalid argument", "out of memory", "too large", "i/o error",
        "unknown or unsupported format", "corrupt data", "numeric error (NaN/Inf or divergence)",
        "shape mismatch", "empty input", "cancelled"};
    if ((int)s < 0 || (int)s >= TN_STATUS_COUNT) return "unknown status";
    return names[s];
}

TN_API const char *tn_last_error(void) { return tn__err()->msg; }
TN_API void tn_clear_error(void)
{
    tn__error_state *e = tn__err();
    e->msg[0] = 0;
    e->over_limit = e->msg_over_limit = 0;
}

/* Records a failure message (printf-style) and returns the status, so callers can write
   `return tn__fail(TN_ERR_IO, "%s: cannot open", path);`. */
static tn_status tn__fail(tn_status s, const char *fmt, ...)
{
    tn__error_state *e = tn__err();
    va_list ap;
    char limit[256];
    /* an allocation the memory budget refused reaches its caller as NULL; whoever reports that
       as out of memory reports the budget instead */
    int over = s == TN_ERR_OUT_OF_MEMORY && e->over_limit && e->msg_over_limit;
    if (over) {
        size_t l = strlen(e->msg) < sizeof limit ? strlen(e->msg) : sizeof limit - 1;
        memcpy(limit, e->msg, l);
        limit[l] = 0;
    }
    va_start(ap, fmt);
    vsnprintf(e->msg, sizeof e->msg, fmt, ap);
    va_end(ap);
    e->msg_over_limit = 0;
    if (over) { /* the budget's message first; the caller's "out of memory ..." after it */
        char caller[512];
        size_t l = strlen(e->msg) < sizeof caller ? strlen(e->msg) : sizeof caller - 1;
        memcpy(caller, e->msg, l);
        caller[l] = 0;
        snprintf(e->msg, sizeof e->msg, "%s; refused: %s", limit, caller);
        s = TN_ERR_TOO_LARGE;
        e->over_limit = 0;
        e->msg_over_limit = 1;
    }
    e->fails++;
    return s;
}

/* The status for an allocation that came back NULL where no message was written: the memory
   budget's TN_ERR_TOO_LARGE when it refused (its message stands), else TN_ERR_OUT_OF_MEMORY. */
static tn_status tn__oom(void) { return tn__err()->msg_over_limit ? TN_ERR_TOO_LARGE : TN_ERR_OUT_OF_MEMORY; }

/* Prefixes the current message with a context string ("alps.png: " ...), keeping the status. */
static tn_status tn__fail_context(tn_status s, const char *context)
{
    char *msg = tn__err()->msg;
    const size_t cap = sizeof tn__err()->msg;
    size_t lc, lm;
    if (s == TN_ERR_OUT_OF_MEMORY && tn__err()->msg_over_limit) s = TN_ERR_TOO_LARGE;
    if (!context || !context[0]) return s;
    lc = strlen(context);
    lm = strlen(msg);
    if (lc + 3 >= cap) return s;
    if (lc + 2 + lm >= cap) lm = cap - lc - 3;
    memmove(msg + lc + 2, msg, lm);
    msg[lc + 2 + lm] = 0;
    memcpy(msg, context, lc);
    msg[lc] = ':';
    msg[lc + 1] = ' ';
    return s;
}

/* The memory budget. Every TN_MALLOC / TN_REALLOC / TN_FREE after this point (the
   whole library below @@core) goes through the wrappers here: allocations of TN__MEM_TRACK_MIN
   bytes and more are recorded in a pointer -> size table (open addressing, linear probing), so
   frees need no size and buffers the caller frees keep their plain layout; small ones are not
   counted (their number is bounded by the work, their total by the big ones they index). */
#define TN__MEM_TRACK_MIN ((size_t)64 << 10)
static void *tn__raw_malloc(size_t n) { return TN_MALLOC(n); }
static void *tn__raw_realloc(void *p, size_t n) { return TN_REALLOC(p, n); }
static void tn__raw_free(void *p) { TN_FREE(p); }

typedef struct tn__mem_entry { void *p; size_t n; } tn__mem_entry;
static tn__mem_entry *tn__mem_slot; /* tn__mem_cap slots (a power of two), p == NULL: empty */
static size_t tn__mem_cap, tn__mem_count, tn__mem_live, tn__mem_limit;
#if !defined(TN_NO_THREADS)
static pthread_mutex_t tn__mem_mutex = PTHREAD_MUTEX_INITIALIZER;
#define TN__MEM_LOCK() pthread_mutex_lock(&tn__mem_mutex)
#define TN__MEM_UNLOCK() pthread_mutex_unlock(&tn__mem_mutex)
#else
#define TN__MEM_LOCK() ((void)0)
#define TN__MEM_UNLOCK() ((void)0)
#endif

static size_t tn__mem_default_limit(void)
{
#if defined(TN_MEMORY_LIMIT)
    return (size_t)(TN_MEMORY_LIMIT);
#else
#if !defined(TN_NO_THREADS) && defined(_SC_PHYS_PAGES) && defined(_SC_PAGESIZE)
    long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGESIZE);
    if (pages > 0 && page > 0) {
        double half = 0.5 * (double)pages * (double)page;
        return half >= (double)SIZE_MAX ? SIZE_MAX : (size_t)half;
    }
#endif
    return TN_MAX_ALLOC;
#endif
}

static size_t tn__mem_hash(const void *p, size_t cap) { return (size_t)(((uint64_t)(uintptr_t)p >> 4) * 0x9E3779B97F4A7C15ULL >> 20) & (cap - 1); }

/* Records p (n bytes); the lock is held. If the table cannot grow, p goes uncounted. */
static void tn__mem_put(void *p, size_t n)
{
    size_t h;
    if (2 * (tn__mem_count + 1) > tn__mem_cap) {
        size_t cap = tn__mem_cap ? 2 * tn__mem_cap : 1024, i;
        tn__mem_entry *slot = (tn__mem_entry *)tn__raw_malloc(cap * sizeof *slot);
        if (!slot) return;
        memset(slot, 0, cap * sizeof *slot);
        for (i = 0; i < tn__mem_cap; i++)
            if (tn__mem_slot[i].p) {
                for (h = tn__mem_hash(tn__mem_slot[i].p, cap); slot[h].p; h = (h + 1) & (cap - 1)) {}
                slot[h] = tn__mem_slot[i];
            }
        tn__raw_free(tn__mem_slot);
        tn__mem_slot = slot;
        tn__mem_cap = cap;
    }
    for (h = tn__mem_hash(p, tn__mem_cap); tn__mem_slot[h].p && tn__mem_slot[h].p != p; h = (h + 1) & (tn__mem_cap - 1)) {}
    if (tn__mem_slot[h].p) tn__mem_live -= tn__mem_slot[h].n; /* freed behind our back, then reused */
    else tn__mem_count++;
    tn__mem_slot[h].p = p;
    tn__mem_slot[h].n = n;
    tn__mem_live += n;
}

/* Forgets p and returns its size (0 if it was not counted); the lock is held. Deletion shifts
   the entries after it back, so probing never needs tombstones. */
static size_t tn__mem_take(void *p)
{
    size_t h, j, k, n, m = tn__mem_cap - 1;
    if (!p || !tn__mem_count) return 0;
    for (h = tn__mem_hash(p, tn__mem_cap); tn__mem_slot[h].p != p; h = (h + 1) & m)
        if (!tn__mem_slot[h].p) return 0;
    n = tn__mem_slot[h].n;
    tn__mem_live -= n;
    tn__mem_count--;
    for (j = h;;) {
        tn__mem_slot[h].p = NULL;
        for (;;) {
            j = (j + 1) & m;
            if (!tn__mem_slot[j].p) return n;
            k = tn__mem_hash(tn__mem_slot[j].p, tn__mem_cap);
            if (h <= j ? (h < k && k <= j) : (h < k || k <= j)) continue; /* k lies cyclically in (h, j]: stays */
            break;
        }
        tn__mem_slot[h] = tn__mem_slot[j];
        h = j;
    }
}

/* Whether growing the total by (n - old) bytes stays within the limit; the lock is held. */
static int tn__mem_admit(size_t old, size_t n)
{
    if (!tn__mem_limit) tn__mem_limit = tn__mem_default_limit();
    return n <= old || (tn__mem_live <= tn__mem_limit && n - old <= tn__mem_limit - tn__mem_live);
}

static void tn__mem_refuse(size_t n, size_t live, size_t limit)
{
    tn__error_state *e;
    tn__fail(TN_ERR_TOO_LARGE, "%.1f MB more would take terrainnet's memory from %.1f MB past its limit of %.1f MB (tn_set_memory_limit, --max-memory)",
             (double)n / 1048576.0, (double)live / 1048576.0, (double)limit / 1048576.0);
    e = tn__err();
    e->over_limit = 1;
    e->msg_over_limit = 1;
}

static void *tn__mem_malloc(size_t n)
{
    void *p = NULL;
    size_t live = 0, limit = 0;
    int ok;
    if (n < TN__MEM_TRACK_MIN) return tn__raw_malloc(n);
    TN__MEM_LOCK();
    ok = tn__mem_admit(0, n);
    if (ok && (p = tn__raw_malloc(n)) != NULL) tn__mem_put(p, n);
    live = tn__mem_live;
    limit = tn__mem_limit;
    TN__MEM_UNLOCK();
    if (!ok) tn__mem_refuse(n, live, limit);
    return p;
}

static void *tn__mem_realloc(void *p, size_t n)
{
    void *q = NULL;
    size_t old, live, limit;
    int ok;
    TN__MEM_LOCK();
    old = tn__mem_take(p); /* put back below if the realloc fails */
    ok = n < TN__MEM_TRACK_MIN || tn__mem_admit(old, n);
    if (ok) q = tn__raw_realloc(p, n);
    if (q && n >= TN__MEM_TRACK_MIN) tn__mem_put(q, n);
    else if (!q && old) tn__mem_put(p, old);
    live = tn__mem_live;
    limit = tn__mem_limit;
    TN__MEM_UNLOCK();
    if (!ok) tn__mem_refuse(n - old, live, limit);
    return q;
}

static void tn__mem_free(void *p)
{
    if (!p) return;
    TN__MEM_LOCK();
    (void)tn__mem_take(p);
    TN__MEM_UNLOCK();
    tn__raw_free(p);
}

TN_API void tn_set_memory_limit(size_t bytes)
{
    TN__MEM_LOCK();
    tn__mem_limit = bytes ? bytes : tn__mem_default_limit();
    TN__MEM_UNLOCK();
}

TN_API size_t tn_get_memory_limit(void)
{
    size_t l;
    TN__MEM_LOCK();
    if (!tn__mem_limit) tn__mem_limit = tn__mem_default_limit();
    l = tn__mem_limit;
    TN__MEM_UNLOCK();
    return l;
}

TN_API size_t tn_memory_in_use(void)
{
    size_t l;
    TN__MEM_LOCK();
    l = tn__mem_live;
    TN__MEM_UNLOCK();
    return l;
}

#undef TN_MALLOC
#undef TN_REALLOC
#undef TN_FREE
#define TN_MALLOC(sz) tn__mem_malloc(sz)
#define TN_REALLOC(p, sz) tn__mem_realloc(p, sz)
#define TN_FREE(p) tn__mem_free(p)

/* a * b with overflow check; returns 0 on overflow. */
static int tn__mul_size(size_t a, size_t b, size_t *out)
{
    if (a != 0 && b > SIZE_MAX / a) return 0;
    *out = a * b;
    return 1;
}

/* a * b * c * d bytes, checked against overflow and TN_MAX_ALLOC. */
TN__INTERNAL tn_status tn__size4(size_t a, size_t b, size_t c, size_t d, size_t *out)
{
    size_t t;
    if (!tn__mul_size(a, b, &t) || !tn__mul_size(t, c, &t) || !tn__mul_size(t, d, &t) || t > TN_MAX_ALLOC)
        return tn__fail(TN_ERR_TOO_LARGE, "size %zu x %zu x %zu x %zu exceeds the allocation limit", a, b, c, d);
    *out = t;
    return TN_OK;
}

/* Allocation that records an error message on failure. */
static void *tn__alloc(size_t bytes)
{
    void *p;
    if (bytes > TN_MAX_ALLOC) {
        tn__fail(TN_ERR_TOO_LARGE, "allocation of %zu bytes exceeds the limit", bytes);
        return NULL;
    }
    p = TN_MALLOC(bytes ? bytes : 1);
    if (!p) tn__fail(TN_ERR_OUT_OF_MEMORY, "out of memory allocating %zu bytes", bytes);
    return p;
}

static void *tn__calloc(size_t bytes)
{
    void *p = tn__alloc(bytes);
    if (p) memset(p, 0, bytes ? bytes : 1);
    return p;
}

/* Grows *buf (capacity *cap bytes) to hold at least `need` bytes, doubling. */
static tn_status tn__reserve(void **buf, size_t *cap, size_t need)
{
    size_t ncap;
    void *p;
    if (need <= *cap) return TN_OK;
    if (need > TN_MAX_ALLOC) return tn__fail(TN_ERR_TOO_LARGE, "buffer of %zu bytes exceeds the limit", need);
    ncap = *cap ? *cap : 256;
    while (ncap < need) ncap = ncap > TN_MAX_ALLOC / 2 ? TN_MAX_ALLOC : ncap * 2;
    p = TN_REALLOC(*buf, ncap);
    if (!p) return tn__fail(TN_ERR_OUT_OF_MEMORY, "out of memory growing a buffer to %zu bytes", ncap);
    *buf = p;
    *cap = ncap;
    return TN_OK;
}

TN_API void tn_rng_seed(tn_rng *r, uint64_t seed, uint64_t stream)
{
    r->state = 0;
    r->inc = (stream << 1) | 1u;
    (void)tn_rng_u32(r);
    r->state += seed;
    (void)tn_rng_u32(r);
}

TN_API uint32_t tn_rng_u32(tn_rng *r)
{
    uint64_t old = r->state;
    uint32_t xorshifted, rot;
    r->state = old * 6364136223846793005ULL + r->inc;
    xorshifted = (uint32_t)(((old >> 18) ^ old) >> 27);
    rot = (uint32_t)(old >> 59);
    return (xorshifted >> rot) | (xorshifted << ((32u - rot) & 31u));
}

TN_API uint32_t tn_rng_below(tn_rng *r, uint32_t n)
{
    uint32_t threshold, x;
    TN_ASSERT(n > 0);
    threshold = (uint32_t)(0u - n) % n; /* rejection keeps it unbiased */
    do x = tn_rng_u32(r); while (x < threshold);
    return x % n;
}

TN_API float tn_rng_uniform(tn_rng *r) { return (float)(tn_rng_u32(r) >> 8) * (1.0f / 16777216.0f); }

TN_API float tn_rng_normal(tn_rng *r)
{
    double u1 = ((double)(tn_rng_u32(r) >> 8) + 0.5) / 16777216.0;
    double u2 = (double)(tn_rng_u32(r) >> 8) / 16777216.0;
    return (float)(sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2));
}

/* SplitMix64 (Steele et al.): one 64-bit key to a well-mixed seed, for per-tile and per-stage RNGs. */
TN__SHARED uint64_t tn__splitmix64(uint64_t x)
{
    x += 0x9E3779B97F4A7C15ULL;
    x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ULL;
    x = (x ^ (x >> 27)) * 0x94D049BB133111EBULL;
    return x ^ (x >> 31);
}

TN__SHARED char *tn__strndup(const char *s, size_t n)
{
    char *d = (char *)TN_MALLOC(n + 1);
    if (!d) return NULL;
    memcpy(d, s, n);
    d[n] = 0;
    return d;
}

/* Per thread where the compiler has thread-local storage (TN__TLS above): only the thread that
   called the operation reports (the pool's workers never do), so its hook is the one it set. */
#ifdef TN__TLS
static TN__TLS tn_progress_fn tn__progress_fn;
static TN__TLS void *tn__progress_user;
static TN__TLS const char *tn__progress_outer;
static TN__TLS double tn__progress_outer_f;
#else
static tn_progress_fn tn__progress_fn;
static void *tn__progress_user;
static const char *tn__progress_outer;
static double tn__progress_outer_f;
#endif

TN_API void tn_set_progress(tn_progress_fn fn, void *user)
{
    tn__progress_fn = fn;
    tn__progress_user = user;
}

/* Until called with NULL, every report goes out as `stage` at `fraction`: the steps of a longer
   operation's preparation (gnn-train's extractions) show as one stage, not dozens, and still cancel. */
TN__INTERNAL_SHARED void tn__progress_within(const char *stage, double fraction)
{
    tn__progress_outer = stage;
    tn__progress_outer_f = fraction;
}

/* Reports progress; returns TN_ERR_CANCELLED (with a message) if the hook asks to stop. */
TN__INTERNAL_SHARED tn_status tn__progress(const char *stage, double fraction)
{
    if (tn__progress_outer) stage = tn__progress_outer, fraction = tn__progress_outer_f;
    if (tn__progress_fn && tn__progress_fn(tn__progress_user, stage, fraction))
        return tn__fail(TN_ERR_CANCELLED, "%s: cancelled by the progress callback", stage);
    return TN_OK;
}

/* Wall time. Under a strict -std=c99, <time.h> hides clock_gettime; gettimeofday stays declared.
   clock() is the process's CPU time on POSIX (threads add, waiting does not), so it would make
   a training budget of 10 minutes on 2 threads about 5 minutes long; Windows' clock() is wall
   time. */
TN_API double tn_time_seconds(void)
{
#if defined(CLOCK_MONOTONIC) && !defined(_WIN32)
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
#elif defined(TN__HAVE_GETTIMEOFDAY)
    struct timeval tv;
    gettimeofday(&tv, NULL);
    return (double)tv.tv_sec + 1e-6 * (double)tv.tv_usec;
#else
    return (double)clock() / (double)CLOCKS_PER_SEC;
#endif
}

TN__INTERNAL_SHARED float tn__clampf(float v, float lo, float hi) { return v < lo ? lo : (v > hi ? hi : v); }

/* v beyond [lo, hi] compressed smoothly into a band of that width beyond it (no plateau at the
   edge: slope 1 there): generated terrain kept within its example's heights, where an
   undertrained scale or a stack of copied relief would run far past them. */
TN__SHARED float tn__soft_limit(float v, float lo, float hi, float band)
{
    if (!(band > 0)) return v;
    if (v > hi) return hi + band * tanhf((v - hi) * (1.0f / band));
    if (v < lo) return lo - band * tanhf((lo - v) * (1.0f / band));
    return v;
}

/* qsort's order of floats, ascending. */
TN__SHARED int tn__cmp_float(const void *a, const void *b)
{
    float x = *(const float *)a, y = *(const float *)b;
    return x < y ? -1 : x > y;
}
static int tn__clampi(int v, int lo, int hi) { return v < lo ? lo : (v > hi ? hi : v); }

/* Option rules for the tn__X_validate functions, which run after tn_X_defaults: each rule fails
   on its own, and its message names the option and the range it allows, so a user knows which
   field to fix ("gnn: option lr = -0.5, allowed (0, 10)"). */
TN__SHARED tn_status tn__opt_int(const char *who, const char *name, int v, int lo, int hi)
{
    if (v >= lo && v <= hi) return TN_OK;
    if (lo == INT_MIN) return tn__fail(TN_ERR_INVALID_ARG, "%s: option %s = %d, allowed <= %d", who, name, v, hi);
    if (hi == INT_MAX) return tn__fail(TN_ERR_INVALID_ARG, "%s: option %s = %d, allowed >= %d", who, name, v, lo);
    return tn__fail(TN_ERR_INVALID_ARG, "%s: option %s = %d, allowed %d .. %d", who, name, v, lo, hi);
}

/* A finite value in an interval whose ends are open or closed as `ends` says ("[]", "[)", "(]",
   "()"); -HUGE_VAL or HUGE_VAL for no bound. NaN and infinities always fail. */
TN__SHARED tn_status tn__opt_float(const char *who, const char *name, double v, const char *ends, double lo, double hi)
{
    char range[64];
    int lo_open = ends[0] == '(', hi_open = ends[1] == ')';
    if (isfinite(v) && (lo_open ? v > lo : v >= lo) && (hi_open ? v < hi : v <= hi)) return TN_OK;
    if (isfinite(lo) && isfinite(hi)) snprintf(range, sizeof range, "%c%g, %g%c", ends[0], lo, hi, ends[1]);
    else if (isfinite(hi)) snprintf(range, sizeof range, "%s %g", hi_open ? "<" : "<=", hi);
    else if (isfinite(lo)) snprintf(range, sizeof range, "%s %g", lo_open ? ">" : ">=", lo);
    else snprintf(range, sizeof range, "finite");
    return tn__fail(TN_ERR_INVALID_ARG, "%s: option %s = %g, allowed %s", who, name, v, range);
}

/* A duration in at most 6 characters: "12.3s", "4m05s", "2h07m", "999h+" or "--". */
static void tn__duration_text(char out[8], double s)
{
    if (!(s >= 0)) snprintf(out, 8, "--");
    else if (s < 99.95) snprintf(out, 8, "%.1fs", s);
    else if (s < 3600.0) snprintf(out, 8, "%dm%02ds", (int)(s / 60.0), (int)fmod(s, 60.0));
    else if (s < 999.0 * 3600.0) snprintf(out, 8, "%dh%02dm", (int)(s / 3600.0), (int)fmod(s / 60.0, 60.0));
    else snprintf(out, 8, "999h+");
}

TN_API char *tn_progress_line(char *buf, size_t size, const char *stage, double fraction, double elapsed_s, double eta_s)
{
    char el[8], eta[8], bar[64];
    double f = fraction >= 0 ? (fraction <= 1 ? fraction : 1.0) : 0.0; /* NaN -> 0 */
    int w = (int)(size > 1000 ? 1000 : size) - 1 - 48, i, fill; /* 48: stage, brackets, percent, times */
    TN_ASSERT(buf && size >= 1);
    w = w > (int)sizeof bar - 1 ? (int)sizeof bar - 1 : w;
    tn__duration_text(el, elapsed_s);
    tn__duration_text(eta, eta_s);
    if (w >= 8) {
        fill = (int)(f * w + 0.5);
        for (i = 0; i < w; i++) bar[i] = i < fill ? '#' : '.';
        bar[w] = 0;
        snprintf(buf, size, "%-18.18s [%s] %5.1f%%  %6s  ETA %6s", stage ? stage : "", bar, 100.0 * f, el, eta);
    } else {
        snprintf(buf, size, "%-18.18s %5.1f%%  %6s  ETA %6s", stage ? stage : "", 100.0 * f, el, eta);
    }
    return buf;
}

