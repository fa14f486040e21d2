/* ============================================================================================
   @@optim  parameters, initialisation, optimisers, .tnw files
   tn_params owns a model's tensors (learned weights and saved buffers such as running means)
   in its own arena. Optimisers update every tensor of a tn_params that has a gradient.
   .tnw layout (little-endian): "TNW1", u32 version, u32 count; version 2 then has u32 n and n
   bytes of metadata, UTF-8 "key=value\n" lines; then per tensor u16 name length, name bytes,
   u8 ndim, u8 flags (1 = buffer), u32 dims[ndim], float32 data[numel]; finally u32 CRC-32 of
   every byte before it. Version 1 (no metadata) is written when a set has no metadata.
   ============================================================================================ */
#ifndef TN_NO_ENGINE

typedef struct tn_params tn_params;
TN_API tn_params *tn_params_create(void);
TN_API void tn_params_free(tn_params *p);
/* A new zeroed learned tensor with a gradient; names must be unique (< 40 chars). NULL on failure. */
TN_API tn_tensor *tn_params_add(tn_params *p, const char *name, int ndim, const int *shape);
/* A saved tensor without a gradient (running statistics, power-iteration vectors). */
TN_API tn_tensor *tn_params_add_buffer(tn_params *p, const char *name, int ndim, const int *shape);
TN_API int tn_params_count(const tn_params *p);
TN_API tn_tensor *tn_params_get(const tn_params *p, int i);
TN_API tn_tensor *tn_params_find(const tn_params *p, const char *name);
TN_API size_t tn_params_numel(const tn_params *p);  /* learned values only */
TN_API void tn_params_zero_grad(tn_params *p);
/* Scales gradients so their global L2 norm is at most max_norm; returns the norm before. */
TN_API float tn_params_clip_grad(tn_params *p, float max_norm);
/* Saves atomically (temporary file + rename). */
TN_API tn_status tn_params_save(const char *path, const tn_params *p);
/* Loads into existing tensors; every name and shape must match, otherwise nothing changes and
   the error names the first mismatch. */
TN_API tn_status tn_params_load(tn_params *p, const char *path);
TN_API tn_status tn_params_load_memory(tn_params *p, const uint8_t *data, size_t size, const char *name);
/* Reads any .tnw file into a new set holding exactly its tensors and metadata (for tools that
   inspect a file, and loaders whose layout depends on the file). *out is NULL on failure. */
TN_API tn_status tn_params_open(tn_params **out, const char *path);
TN_API tn_status tn_params_open_memory(tn_params **out, const uint8_t *data, size_t size, const char *name);

/* Metadata: text key/value pairs saved with the tensors (keys [A-Za-z0-9_.-], < 64 chars; values
   printable, no newline, < 1024 chars). Setting a key again replaces it; value NULL removes it.
   Loading a file replaces the set's metadata with the file's. */
TN_API tn_status tn_params_set_meta(tn_params *p, const char *key, const char *value);
/* The value of key, or NULL. Valid until the key is set again or the set is freed. */
TN_API const char *tn_params_meta(const tn_params *p, const char *key);
TN_API int tn_params_meta_count(const tn_params *p);
/* The i-th pair in insertion order (0 <= i < count); *value may be NULL if not wanted. */
TN_API const char *tn_params_meta_key(const tn_params *p, int i, const char **value);

/* Initialisers. fan_in = numel / shape[0]. */
TN_API void tn_init_uniform(tn_tensor *t, tn_rng *rng, float lo, float hi);
TN_API void tn_init_normal(tn_tensor *t, tn_rng *rng, float mean, float std);
/* He/Kaiming normal for ReLU-like layers: std = gain / sqrt(fan_in). */
TN_API void tn_init_kaiming(tn_tensor *t, tn_rng *rng, float gain);

typedef enum tn_optim_kind { TN_OPTIM_ADAM = 0, TN_OPTIM_SGD } tn_optim_kind;
typedef struct tn_optim_opts {
    tn_optim_kind kind;
    float lr;             /* 0 = 1e-3 */
    float beta1, beta2;   /* Adam; both 0 = 0.9, 0.999 (set beta2 to use beta1 = 0) */
    float eps;            /* Adam; 0 = 1e-8 */
    float weight_decay;   /* L2 added to the gradient (Adam, SGD) */
    float momentum;       /* SGD */
    float lr_decay;       /* multiply the rate by this every decay_every steps; 0 = no decay */
    int decay_every;      /* 0 = 1 */
    float clip_norm;      /* > 0: clip the global gradient norm before each step */
} tn_optim_opts;
typedef struct tn_optim tn_optim;
/* NULL with tn_last_error() set for NaN/Inf settings, betas outside [0, 1) or negative momentum. */
TN_API tn_optim *tn_optim_create(tn_params *p, const tn_optim_opts *opts);
TN_API void tn_optim_free(tn_optim *o);
/* One update from the current gradients (does not zero them). */
TN_API void tn_optim_step(tn_optim *o);
TN_API float tn_optim_lr(const tn_optim *o);
/* Changes the base rate (a schedule's phase); the moments and the step count are kept. */
TN_API void tn_optim_set_lr(tn_optim *o, float lr);

/* L-BFGS on a flat vector: fn returns f(x) and writes its gradient. History m (0 = 10),
   backtracking line search (Armijo). Stops after max_iter iterations, when the gradient norm
   drops below tol, or when no step lowers f. final_f may be NULL. n == 0, a NULL x or fn, history
   outside 0..65536 or NaN/Inf options fail with TN_ERR_INVALID_ARG; a NaN/Inf objective or
   gradient with TN_ERR_NUMERIC. */
typedef float (*tn_lbfgs_fn)(void *user, const float *x, float *grad);
typedef struct tn_lbfgs_opts { int max_iter; int history; float tol; float first_step; } tn_lbfgs_opts;
TN_API tn_status tn_lbfgs(float *x, size_t n, tn_lbfgs_fn fn, void *user, const tn_lbfgs_opts *opts, float *final_f);
#endif /* TN_NO_ENGINE */

/* --------------------------------------------------------------------------------------------
   >>optim  (@@optim implementation)
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_ENGINE

struct tn_params {
    tn_ctx *ctx;
    tn_tensor **t;
    int n, cap;
    char **meta;  /* 2 * nmeta strings: key, value, key, value, ... (each malloc'd) */
    int nmeta, metacap;
    int *slot;    /* name hash table, hcap (a power of two) slots of tensor index + 1, 0 = empty:
                     a linear search made loading n tensors O(n^2) (100k names took minutes) */
    int hcap;
};

TN_API tn_params *tn_params_create(void)
{
    tn_params *p = (tn_params *)TN_MALLOC(sizeof(tn_params));
    if (!p) return NULL;
    memset(p, 0, sizeof *p);
    p->ctx = tn_ctx_create();
    if (!p->ctx) {
        TN_FREE(p);
        return NULL;
    }
    return p;
}

static void tn__meta_clear(tn_params *p)
{
    int i;
    for (i = 0; i < 2 * p->nmeta; i++) TN_FREE(p->meta[i]);
    TN_FREE(p->meta);
    p->meta = NULL;
    p->nmeta = p->metacap = 0;
}

TN_API void tn_params_free(tn_params *p)
{
    if (!p) return;
    tn__meta_clear(p);
    tn_ctx_free(p->ctx);
    TN_FREE(p->t);
    TN_FREE(p->slot);
    TN_FREE(p);
}

static uint32_t tn__name_hash(const char *s)
{
    uint32_t h = 2166136261u; /* FNV-1a */
    while (*s) h = (h ^ (uint8_t)*s++) * 16777619u;
    return h;
}

static void tn__params_slot_put(int *slot, int hcap, const char *name, int index)
{
    uint32_t m = (uint32_t)hcap - 1, h = tn__name_hash(name) & m;
    while (slot[h]) h = (h + 1) & m;
    slot[h] = index + 1;
}

/* Keeps the table at most half full: doubles it and reinserts every name. */
static int tn__params_slot_grow(tn_params *p)
{
    int hcap = p->hcap ? p->hcap : 64, *slot, i;
    while (hcap < 2 * (p->n + 1)) hcap *= 2;
    if (hcap == p->hcap) return 1;
    slot = (int *)TN_MALLOC((size_t)hcap * sizeof(int));
    if (!slot) return 0;
    memset(slot, 0, (size_t)hcap * sizeof(int));
    for (i = 0; i < p->n; i++) tn__params_slot_put(slot, hcap, p->t[i]->name, i);
    TN_FREE(p->slot);
    p->slot = slot;
    p->hcap = hcap;
    return 1;
}

static tn_tensor *tn__params_new(tn_params *p, const char *name, int ndim, const int *shape, int learned)
{
    tn_tensor *t;
    size_t numel = 1;
    int i;
    /* checked here rather than asserted: names and shapes come from model files (.tnw configs) too */
    TN_ASSERT(p);
    if (!name || !name[0] || strlen(name) >= sizeof t->name) {
        tn__fail(TN_ERR_INVALID_ARG, "parameters: name '%.60s' is empty or has 40 or more characters", name ? name : "(null)");
        return NULL;
    }
    if (tn_params_find(p, name)) {
        tn__fail(TN_ERR_INVALID_ARG, "parameters: a tensor named '%s' already exists", name);
        return NULL;
    }
    if (ndim < 1 || ndim > TN_MAX_DIMS || !shape) {
        tn__fail(TN_ERR_INVALID_ARG, "parameters: '%s' has %d dims (1..%d)", name, ndim, TN_MAX_DIMS);
        return NULL;
    }
    for (i = 0; i < ndim; i++) {
        if (shape[i] < 1) {
            tn__fail(TN_ERR_INVALID_ARG, "parameters: '%s' dim %d is %d", name, i, shape[i]);
            return NULL;
        }
        if (!tn__mul_size(numel, (size_t)shape[i], &numel) || numel > TN_MAX_ALLOC / sizeof(float)) {
            tn__fail(TN_ERR_TOO_LARGE, "parameters: '%s' is too large", name);
            return NULL;
        }
    }
    if (p->n == p->cap) {
        int cap = p->cap ? p->cap * 2 : 32;
        tn_tensor **nt = (tn_tensor **)TN_REALLOC(p->t, (size_t)cap * sizeof(tn_tensor *));
        if (!nt) {
            tn__fail(TN_ERR_OUT_OF_MEMORY, "parameters: out of memory");
            return NULL;
        }
        p->t = nt;
        p->cap = cap;
    }
    if (!tn__params_slot_grow(p)) {
        tn__fail(TN_ERR_OUT_OF_MEMORY, "parameters: out of memory");
        return NULL;
    }
    t = tn_tensor_new(p->ctx, ndim, shape);
    if (!t) return NULL;
    if (learned && !tn_tensor_requires_grad(p->ctx, t)) return NULL;
    strcpy(t->name, name);
    tn__params_slot_put(p->slot, p->hcap, name, p->n);
    p->t[p->n++] = t;
    return t;
}

TN_API tn_tensor *tn_params_add(tn_params *p, const char *name, int ndim, const int *shape) { return tn__params_new(p, name, ndim, shape, 1); }
TN_API tn_tensor *tn_params_add_buffer(tn_params *p, const char *name, int ndim, const int *shape) { return tn__params_new(p, name, ndim, shape, 0); }
TN_API int tn_params_count(const tn_params *p) { return p->n; }
TN_API tn_tensor *tn_params_get(const tn_params *p, int i) { return i >= 0 && i < p->n ? p->t[i] : NULL; }

TN_API tn_tensor *tn_params_find(const tn_params *p, const char *name)
{
    uint32_t m, h;
    if (!p->hcap) return NULL;
    m = (uint32_t)p->hcap - 1;
    for (h = tn__name_hash(name) & m; p->slot[h]; h = (h + 1) & m)
        if (!strcmp(p->t[p->slot[h] - 1]->name, name)) return p->t[p->slot[h] - 1];
    return NULL;
}

TN_API size_t tn_params_numel(const tn_params *p)
{
    size_t n = 0;
    int i;
    for (i = 0; i < p->n; i++)
        if (p->t[i]->requires_grad) n += p->t[i]->numel;
    return n;
}

TN_API void tn_params_zero_grad(tn_params *p)
{
    int i;
    for (i = 0; i < p->n; i++)
        if (p->t[i]->grad) memset(p->t[i]->grad, 0, p->t[i]->numel * sizeof(float));
}

TN_API float tn_params_clip_grad(tn_params *p, float max_norm)
{
    double s = 0;
    float norm;
    int i;
    size_t k;
    for (i = 0; i < p->n; i++)
        if (p->t[i]->grad)
            for (k = 0; k < p->t[i]->numel; k++) s += (double)p->t[i]->grad[k] * p->t[i]->grad[k];
    norm = (float)sqrt(s);
    if (max_norm > 0 && norm > max_norm) {
        float f = max_norm / (norm + 1e-6f);
        for (i = 0; i < p->n; i++)
            if (p->t[i]->grad)
                for (k = 0; k < p->t[i]->numel; k++) p->t[i]->grad[k] *= f;
    }
    return norm;
}

TN_API void tn_init_uniform(tn_tensor *t, tn_rng *rng, float lo, float hi)
{
    size_t i;
    for (i = 0; i < t->numel; i++) t->data[i] = lo + (hi - lo) * tn_rng_uniform(rng);
}

TN_API void tn_init_normal(tn_tensor *t, tn_rng *rng, float mean, float std)
{
    size_t i;
    for (i = 0; i < t->numel; i++) t->data[i] = mean + std * tn_rng_normal(rng);
}

TN_API void tn_init_kaiming(tn_tensor *t, tn_rng *rng, float gain)
{
    size_t fan_in = t->numel / (size_t)t->shape[0];
    tn_init_normal(t, rng, 0.0f, gain / sqrtf((float)(fan_in ? fan_in : 1)));
}

/* ---- .tnw files ---- */

static float tn__get_f32(const uint8_t *p)
{
    uint32_t u = tn__get_u32(p);
    float f;
    memcpy(&f, &u, 4);
    return f;
}

/* The metadata block of a version-2 file ("key=value\n" lines); its length goes to *n. */
static size_t tn__meta_size(const tn_params *p)
{
    size_t n = 0;
    int i;
    for (i = 0; i < p->nmeta; i++) n += strlen(p->meta[2 * i]) + 1 + strlen(p->meta[2 * i + 1]) + 1;
    return n;
}

static size_t tn__meta_write(const tn_params *p, uint8_t *out)
{
    size_t off = 0, l;
    int i;
    for (i = 0; i < p->nmeta; i++) {
        l = strlen(p->meta[2 * i]);
        memcpy(out + off, p->meta[2 * i], l);
        off += l;
        out[off++] = '=';
        l = strlen(p->meta[2 * i + 1]);
        memcpy(out + off, p->meta[2 * i + 1], l);
        off += l;
        out[off++] = '\n';
    }
    return off;
}

TN_API tn_status tn_params_save(const char *path, const tn_params *p)
{
    size_t meta = tn__meta_size(p), size = 12 + 4 + (p->nmeta ? 4 + meta : 0), off, k;
    uint8_t *buf;
    tn_status st;
    int i, d;
    for (i = 0; i < p->n; i++) size += 2 + strlen(p->t[i]->name) + 2 + 4 * (size_t)p->t[i]->ndim + 4 * p->t[i]->numel;
    buf = (uint8_t *)tn__alloc(size);
    if (!buf) return tn__fail_context(TN_ERR_OUT_OF_MEMORY, path);
    memcpy(buf, "TNW1", 4);
    tn__put_u32(buf + 4, p->nmeta ? 2 : 1);
    tn__put_u32(buf + 8, (uint32_t)p->n);
    off = 12;
    if (p->nmeta) {
        tn__put_u32(buf + 12, (uint32_t)meta);
        off = 16 + tn__meta_write(p, buf + 16);
    }
    for (i = 0; i < p->n; i++) {
        const tn_tensor *t = p->t[i];
        size_t nl = strlen(t->name);
        buf[off] = (uint8_t)nl;
        buf[off + 1] = (uint8_t)(nl >> 8);
        memcpy(buf + off + 2, t->name, nl);
        off += 2 + nl;
        buf[off++] = (uint8_t)t->ndim;
        buf[off++] = (uint8_t)(t->requires_grad ? 0 : 1);
        for (d = 0; d < t->ndim; d++, off += 4) tn__put_u32(buf + off, (uint32_t)t->shape[d]);
        for (k = 0; k < t->numel; k++, off += 4) tn__put_f32(buf + off, t->data[k]);
    }
    tn__put_u32(buf + off, tn__crc32(0, buf, off));
    st = tn__io_write_atomic(path, buf, size);
    TN_FREE(buf);
    return st;
}

#define TN__TNW_VERSION 2
#define TN__META_MAX 65536
/* No model format needs more tensors (the largest, a GNN, has a few hundred): a file claiming
   more is refused before anything is parsed. */
#define TN__TNW_MAX_TENSORS 65536

static int tn__meta_key_ok(const char *k)
{
    size_t i, n = k ? strlen(k) : 0;
    if (n == 0 || n >= 64) return 0;
    for (i = 0; i < n; i++)
        if (!((k[i] >= 'a' && k[i] <= 'z') || (k[i] >= 'A' && k[i] <= 'Z') || (k[i] >= '0' && k[i] <= '9') || k[i] == '_' || k[i] == '.' || k[i] == '-')) return 0;
    return 1;
}

static int tn__meta_value_ok(const char *v, size_t n)
{
    size_t i;
    if (n >= 1024) return 0;
    for (i = 0; i < n; i++)
        if ((unsigned char)v[i] < 0x20 || v[i] == 0x7f) return 0;
    return 1;
}

static tn_status tn__meta_set(tn_params *p, const char *key, size_t kn, const char *value, size_t vn)
{
    char *k, *v;
    int i;
    for (i = 0; i < p->nmeta; i++)
        if (strlen(p->meta[2 * i]) == kn && !memcmp(p->meta[2 * i], key, kn)) break;
    if (!value) { /* remove, keeping the order of the rest */
        if (i == p->nmeta) return TN_OK;
        TN_FREE(p->meta[2 * i]);
        TN_FREE(p->meta[2 * i + 1]);
        memmove(p->meta + 2 * i, p->meta + 2 * i + 2, (size_t)(p->nmeta - i - 1) * 2 * sizeof(char *));
        p->nmeta--;
        return TN_OK;
    }
    if (!(v = tn__strndup(value, vn))) return tn__fail(TN_ERR_OUT_OF_MEMORY, "metadata: out of memory");
    if (i < p->nmeta) {
        TN_FREE(p->meta[2 * i + 1]);
        p->meta[2 * i + 1] = v;
        return TN_OK;
    }
    if (p->nmeta == p->metacap) {
        int cap = p->metacap ? 2 * p->metacap : 16;
        char **m = (char **)TN_REALLOC(p->meta, 2 * (size_t)cap * sizeof(char *));
        if (!m) { TN_FREE(v); return tn__fail(TN_ERR_OUT_OF_MEMORY, "metadata: out of memory"); }
        p->meta = m;
        p->metacap = cap;
    }
    if (!(k = tn__strndup(key, kn))) { TN_FREE(v); return tn__fail(TN_ERR_OUT_OF_MEMORY, "metadata: out of memory"); }
    p->meta[2 * p->nmeta] = k;
    p->meta[2 * p->nmeta + 1] = v;
    p->nmeta++;
    return TN_OK;
}

TN_API tn_status tn_params_set_meta(tn_params *p, const char *key, const char *value)
{
    TN_ASSERT(p);
    if (!tn__meta_key_ok(key)) return tn__fail(TN_ERR_INVALID_ARG, "metadata: bad key '%.80s'", key ? key : "(null)");
    if (value && !tn__meta_value_ok(value, strlen(value)))
        return tn__fail(TN_ERR_INVALID_ARG, "metadata: the value of '%s' is too long or holds control characters", key);
    return tn__meta_set(p, key, strlen(key), value, value ? strlen(value) : 0);
}

TN_API const char *tn_params_meta(const tn_params *p, const char *key)
{
    int i;
    for (i = 0; p && key && i < p->nmeta; i++)
        if (!strcmp(p->meta[2 * i], key)) return p->meta[2 * i + 1];
    return NULL;
}

TN_API int tn_params_meta_count(const tn_params *p) { return p ? p->nmeta : 0; }

TN_API const char *tn_params_meta_key(const tn_params *p, int i, const char **value)
{
    if (!p || i < 0 || i >= p->nmeta) return NULL;
    if (value) *value = p->meta[2 * i + 1];
    return p->meta[2 * i];
}

/* Parses the metadata block into p: every line key=value, checked as tn_params_set_meta would. */
static tn_status tn__meta_parse(tn_params *p, const uint8_t *b, size_t n, const char *name)
{
    size_t off = 0;
    while (off < n) {
        const char *line = (const char *)b + off, *eq, *nl = (const char *)memchr(line, '\n', n - off);
        char key[64];
        size_t len, kn;
        tn_status st;
        if (!nl) return tn__fail(TN_ERR_CORRUPT, "%s: metadata line without an end", name);
        len = (size_t)(nl - line);
        eq = (const char *)memchr(line, '=', len);
        kn = eq ? (size_t)(eq - line) : 0;
        if (!eq || kn == 0 || kn >= sizeof key) return tn__fail(TN_ERR_CORRUPT, "%s: bad metadata line", name);
        memcpy(key, line, kn);
        key[kn] = 0;
        if (!tn__meta_key_ok(key) || !tn__meta_value_ok(eq + 1, len - kn - 1) || tn_params_meta(p, key))
            return tn__fail(TN_ERR_CORRUPT, "%s: bad or repeated metadata key '%s'", name, key);
        if ((st = tn__meta_set(p, key, kn, eq + 1, len - kn - 1))) return st;
        off += len + 1;
    }
    return TN_OK;
}

/* Reads a .tnw image's header and metadata into a new set (no tensors yet); *off is where the
   tensors start. With check_crc 0 the CRC-32 is not checked: tn__tnw_peek. */
static tn_status tn__tnw_read_head(const uint8_t *b, size_t n, const char *name, int check_crc, tn_params **out, size_t *off)
{
    uint32_t count, version;
    tn_params *p;
    tn_status st = TN_OK;
    *out = NULL;
    *off = 12;
    if (n < 16 || memcmp(b, "TNW1", 4) != 0) return tn__fail(TN_ERR_FORMAT, "%s: not a terrainnet weights (.tnw) file", name);
    version = tn__get_u32(b + 4);
    if (version < 1 || version > TN__TNW_VERSION)
        return tn__fail(TN_ERR_FORMAT, "%s: .tnw version %u is not supported (this library reads 1..%d; a newer terrainnet wrote it?)", name,
                        (unsigned)version, TN__TNW_VERSION);
    if (check_crc && tn__crc32(0, b, n - 4) != tn__get_u32(b + n - 4))
        return tn__fail(TN_ERR_CORRUPT, "%s: CRC-32 mismatch (the file is damaged)", name);
    count = tn__get_u32(b + 8);
    if (count > (n - 16) / 9) return tn__fail(TN_ERR_CORRUPT, "%s: %u tensors cannot fit in %zu bytes", name, (unsigned)count, n);
    if (count > TN__TNW_MAX_TENSORS)
        return tn__fail(TN_ERR_TOO_LARGE, "%s: %u tensors, more than any model has (at most %d)", name, (unsigned)count, TN__TNW_MAX_TENSORS);
    if (!(p = tn_params_create())) return tn__fail(TN_ERR_OUT_OF_MEMORY, "%s: out of memory", name);
    if (version >= 2) {
        size_t ml = tn__get_u32(b + 12);
        *off = 16;
        if (ml > TN__META_MAX || ml > n - 4 - *off) st = tn__fail(TN_ERR_CORRUPT, "%s: bad metadata size", name);
        if (!st) st = tn__meta_parse(p, b + *off, ml, name);
        *off += ml;
    }
    if (st) {
        tn_params_free(p);
        return st;
    }
    *out = p;
    return TN_OK;
}

/* The metadata of a .tnw image, read without checking the CRC-32 or parsing any tensor: how a
   model loader learns the file's method before it pays for the rest (tn__model_open). */
TN__SHARED tn_status tn__tnw_peek(const uint8_t *b, size_t n, const char *name, tn_params **out)
{
    size_t off;
    return tn__tnw_read_head(b, n, name, 0, out, &off);
}

/* Reads a .tnw image into a new set: every tensor with its name, shape and flag, the metadata.
   Everything is bounds-checked before it is allocated; NaN/Inf data is refused. */
static tn_status tn__tnw_read(const uint8_t *b, size_t n, const char *name, tn_params **out)
{
    size_t off, k;
    uint32_t count, i;
    tn_params *p;
    tn_status st;
    if ((st = tn__tnw_read_head(b, n, name, 1, &p, &off))) return st;
    count = tn__get_u32(b + 8);
    for (i = 0; i < count && !st; i++) {
        char tname[64];
        size_t nl, numel = 1;
        int ndim, d, shape[TN_MAX_DIMS], flags;
        tn_tensor *t;
        if (off + 4 > n - 4) { st = tn__fail(TN_ERR_CORRUPT, "%s: truncated at tensor %u", name, (unsigned)i); break; }
        nl = (size_t)b[off] | ((size_t)b[off + 1] << 8);
        if (nl == 0 || nl >= 40 || off + 2 + nl + 2 > n - 4) { st = tn__fail(TN_ERR_CORRUPT, "%s: bad name at tensor %u", name, (unsigned)i); break; }
        memcpy(tname, b + off + 2, nl);
        tname[nl] = 0;
        off += 2 + nl;
        ndim = b[off];
        flags = b[off + 1];
        off += 2;
        if (ndim < 1 || ndim > TN_MAX_DIMS || off + 4 * (size_t)ndim > n - 4) {
            st = tn__fail(TN_ERR_CORRUPT, "%s: tensor '%s' has %d dims or is truncated", name, tname, ndim);
            break;
        }
        for (d = 0; d < ndim; d++) {
            uint32_t v = tn__get_u32(b + off + 4 * (size_t)d);
            if (v < 1 || v > (uint32_t)INT_MAX || !tn__mul_size(numel, v, &numel)) break;
            shape[d] = (int)v;
        }
        off += 4 * (size_t)ndim;
        if (d < ndim || numel > (n - 4 - off) / 4) { st = tn__fail(TN_ERR_CORRUPT, "%s: truncated data of '%s'", name, tname); break; }
        if (tn_params_find(p, tname)) { st = tn__fail(TN_ERR_CORRUPT, "%s: tensor '%s' appears twice", name, tname); break; }
        for (k = 0; k < numel; k++) {
            float v = tn__get_f32(b + off + 4 * k);
            if (v != v || v > FLT_MAX || v < -FLT_MAX) break;
        }
        if (k < numel) { st = tn__fail(TN_ERR_NUMERIC, "%s: tensor '%s' holds NaN/Inf", name, tname); break; }
        t = flags & 1 ? tn_params_add_buffer(p, tname, ndim, shape) : tn_params_add(p, tname, ndim, shape);
        if (!t) { st = tn__fail_context(TN_ERR_OUT_OF_MEMORY, name); break; }
        for (k = 0; k < numel; k++) t->data[k] = tn__get_f32(b + off + 4 * k);
        off += 4 * numel;
    }
    if (!st && off != n - 4) st = tn__fail(TN_ERR_CORRUPT, "%s: %zu unexpected bytes after the last tensor", name, n - 4 - off);
    if (st) {
        tn_params_free(p);
        return st;
    }
    *out = p;
    return TN_OK;
}

TN_API tn_status tn_params_open_memory(tn_params **out, const uint8_t *data, size_t size, const char *name)
{
    TN_ASSERT(out);
    *out = NULL;
    if (!data) return tn__fail(TN_ERR_INVALID_ARG, "weights: no data");
    return tn__tnw_read(data, size, name ? name : "weights", out);
}

TN_API tn_status tn_params_open(tn_params **out, const char *path)
{
    uint8_t *buf = NULL;
    size_t n = 0;
    tn_status st;
    TN_ASSERT(out);
    *out = NULL;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "weights: empty path");
    if ((st = tn__io_read_file(path, &buf, &n))) return st;
    st = tn__tnw_read(buf, n, path, out);
    TN_FREE(buf);
    return st;
}

/* Whether p holds `name` with exactly this shape. Model loaders check the shapes their config
   implies against the file's tensors with it before building the model, so a config cannot make
   them allocate more than the file holds. */
TN__SHARED int tn__params_has(const tn_params *p, const char *name, int ndim, const int *shape)
{
    const tn_tensor *t = tn_params_find(p, name);
    int i;
    if (!t || t->ndim != ndim) return 0;
    for (i = 0; i < ndim; i++)
        if (t->shape[i] != shape[i]) return 0;
    return 1;
}

/* Copies src's tensors into p's same-named ones: the same count, every name present with the
   same shape, checked before anything changes; then the metadata. */
static tn_status tn__params_assign(tn_params *p, const tn_params *src, const char *name)
{
    int i, j;
    if (src->n != p->n) return tn__fail(TN_ERR_SHAPE, "%s: holds %d tensors, the model has %d", name, src->n, p->n);
    for (i = 0; i < src->n; i++) {
        const tn_tensor *s = src->t[i], *t = tn_params_find(p, s->name);
        if (!t) return tn__fail(TN_ERR_SHAPE, "%s: tensor '%s' is not in the model", name, s->name);
        if (s->ndim != t->ndim) return tn__fail(TN_ERR_SHAPE, "%s: tensor '%s' has %d dims, the model's has %d", name, s->name, s->ndim, t->ndim);
        for (j = 0; j < s->ndim; j++)
            if (s->shape[j] != t->shape[j])
                return tn__fail(TN_ERR_SHAPE, "%s: tensor '%s' dim %d is %d, the model's is %d", name, s->name, j, s->shape[j], t->shape[j]);
    }
    for (i = 0; i < src->n; i++) memcpy(tn_params_find(p, src->t[i]->name)->data, src->t[i]->data, src->t[i]->numel * sizeof(float));
    tn__meta_clear(p);
    for (i = 0; i < src->nmeta; i++) {
        const char *k = src->meta[2 * i], *v = src->meta[2 * i + 1];
        tn_status st = tn__meta_set(p, k, strlen(k), v, strlen(v));
        if (st) return st;
    }
    return TN_OK;
}

TN_API tn_status tn_params_load_memory(tn_params *p, const uint8_t *data, size_t size, const char *name)
{
    tn_params *f = NULL;
    tn_status st;
    TN_ASSERT(p);
    name = name ? name : "weights";
    if ((st = tn_params_open_memory(&f, data, size, name))) return st;
    st = tn__params_assign(p, f, name);
    tn_params_free(f);
    return st;
}

TN_API tn_status tn_params_load(tn_params *p, const char *path)
{
    tn_params *f = NULL;
    tn_status st;
    TN_ASSERT(p);
    if ((st = tn_params_open(&f, path))) return st;
    st = tn__params_assign(p, f, path);
    tn_params_free(f);
    return st;
}

/* ---- optimisers ---- */

struct tn_optim {
    tn_params *p;
    int n;          /* tensors of p when created: tensors added later are not optimised */
    tn_optim_opts o;
    float **m, **v; /* per tensor state (Adam: both; SGD: m = velocity) */
    long step;
};

static void tn__optim_opts_defaults(tn_optim_opts *o)
{
    if (o->lr <= 0) o->lr = 1e-3f;
    if (o->beta1 == 0 && o->beta2 == 0) { o->beta1 = 0.9f; o->beta2 = 0.999f; }
    if (o->eps <= 0) o->eps = 1e-8f;
    if (o->decay_every <= 0) o->decay_every = 1;
}

/* NaN/Inf or out-of-range settings would turn every weight into NaN at the first step. */
static int tn__optim_opts_ok(const tn_optim_opts *o)
{
    const float f[8] = {o->lr, o->beta1, o->beta2, o->eps, o->weight_decay, o->momentum, o->lr_decay, o->clip_norm};
    int i;
    for (i = 0; i < 8; i++)
        if (!(fabsf(f[i]) <= FLT_MAX)) return 0;
    return (o->kind == TN_OPTIM_ADAM || o->kind == TN_OPTIM_SGD) && o->beta1 >= 0.0f && o->beta1 < 1.0f &&
           o->beta2 >= 0.0f && o->beta2 < 1.0f && o->momentum >= 0.0f && o->lr_decay >= 0.0f;
}

TN_API tn_optim *tn_optim_create(tn_params *p, const tn_optim_opts *opts)
{
    tn_optim *o;
    int i;
    if (!p) {
        tn__fail(TN_ERR_INVALID_ARG, "optimiser: no parameters");
        return NULL;
    }
    if (opts && !tn__optim_opts_ok(opts)) {
        tn__fail(TN_ERR_INVALID_ARG, "optimiser: a setting is NaN/Inf or out of range (kind %d, lr %g, betas %g %g, momentum %g)",
                 (int)opts->kind, (double)opts->lr, (double)opts->beta1, (double)opts->beta2, (double)opts->momentum);
        return NULL;
    }
    o = (tn_optim *)TN_MALLOC(sizeof(tn_optim));
    if (!o) {
        tn__fail(TN_ERR_OUT_OF_MEMORY, "optimiser: out of memory");
        return NULL;
    }
    memset(o, 0, sizeof *o);
    o->p = p;
    if (opts) o->o = *opts;
    tn__optim_opts_defaults(&o->o);
    o->m = (float **)TN_MALLOC(2 * sizeof(float *) * (size_t)(p->n ? p->n : 1));
    if (!o->m) { TN_FREE(o); return NULL; }
    memset(o->m, 0, 2 * sizeof(float *) * (size_t)(p->n ? p->n : 1));
    o->n = p->n;
    o->v = o->m + p->n;
    for (i = 0; i < p->n; i++) {
        size_t n = p->t[i]->requires_grad ? p->t[i]->numel : 0;
        o->m[i] = n ? (float *)tn__calloc(n * sizeof(float)) : NULL;
        o->v[i] = n && o->o.kind == TN_OPTIM_ADAM ? (float *)tn__calloc(n * sizeof(float)) : NULL;
        if (n && (!o->m[i] || (o->o.kind == TN_OPTIM_ADAM && !o->v[i]))) {
            o->p = p;
            tn_optim_free(o);
            return NULL;
        }
    }
    return o;
}

TN_API void tn_optim_free(tn_optim *o)
{
    int i;
    if (!o) return;
    for (i = 0; i < o->n; i++) {
        TN_FREE(o->m[i]);
        TN_FREE(o->v[i]);
    }
    TN_FREE(o->m);
    TN_FREE(o);
}

TN_API void tn_optim_set_lr(tn_optim *o, float lr)
{
    if (lr > 0 && lr <= FLT_MAX) o->o.lr = lr;
}

TN_API float tn_optim_lr(const tn_optim *o)
{
    if (o->o.lr_decay <= 0) return o->o.lr;
    return o->o.lr * powf(o->o.lr_decay, (float)(o->step / o->o.decay_every));
}

TN_API void tn_optim_step(tn_optim *o)
{
    float lr = tn_optim_lr(o), wd = o->o.weight_decay;
    float b1 = o->o.beta1, b2 = o->o.beta2, c1, c2;
    int i;
    size_t k;
    if (o->o.clip_norm > 0) tn_params_clip_grad(o->p, o->o.clip_norm);
    o->step++;
    c1 = 1.0f - powf(b1, (float)o->step);
    c2 = 1.0f - powf(b2, (float)o->step);
    for (i = 0; i < o->n; i++) {
        tn_tensor *t = o->p->t[i];
        float *m = o->m[i], *v = o->v[i];
        if (!t->requires_grad || !t->grad) continue;
        for (k = 0; k < t->numel; k++) {
            float g = t->grad[k] + wd * t->data[k];
            if (o->o.kind == TN_OPTIM_ADAM) {
                m[k] = b1 * m[k] + (1 - b1) * g;
                v[k] = b2 * v[k] + (1 - b2) * g * g;
                t->data[k] -= lr * (m[k] / c1) / (sqrtf(v[k] / c2) + o->o.eps);
            } else {
                m[k] = o->o.momentum * m[k] + g;
                t->data[k] -= lr * m[k];
            }
        }
    }
}

static double tn__dot(const float *a, const float *b, size_t n)
{
    double s = 0;
    size_t i;
    for (i = 0; i < n; i++) s += (double)a[i] * b[i];
    return s;
}

static void tn__lbfgs_opts_defaults(tn_lbfgs_opts *o)
{
    if (o->history <= 0) o->history = 10;
    if (o->max_iter <= 0) o->max_iter = 100;
    if (!(o->tol > 0)) o->tol = 1e-7f;
    if (!(o->first_step > 0)) o->first_step = 1.0f;
}

TN_API tn_status tn_lbfgs(float *x, size_t n, tn_lbfgs_fn fn, void *user, const tn_lbfgs_opts *opts, float *final_f)
{
    tn_lbfgs_opts lo = {0, 0, 0.0f, 0.0f};
    int m, max_iter;
    float tol, first;
    float *S, *Y, *g, *gn, *d, *xn, f, fn_;
    double *rho, *alpha;
    int it, k, hist = 0, head = 0;
    size_t bytes = 0;
    tn_status st = TN_OK;
    if (!x || !fn || n == 0) return tn__fail(TN_ERR_INVALID_ARG, "L-BFGS: %s", n ? "no vector or function" : "empty vector");
    if (opts && (opts->history < 0 || opts->history > 65536 || opts->max_iter < 0 || !(fabsf(opts->tol) <= FLT_MAX) ||
                 !(fabsf(opts->first_step) <= FLT_MAX)))
        return tn__fail(TN_ERR_INVALID_ARG, "L-BFGS: bad options (history %d, max_iter %d, tol %g, first_step %g)",
                        opts->history, opts->max_iter, (double)opts->tol, (double)opts->first_step);
    if (opts) lo = *opts;
    tn__lbfgs_opts_defaults(&lo);
    m = lo.history;
    max_iter = lo.max_iter;
    tol = lo.tol;
    first = lo.first_step;
    if (tn__size4((size_t)(2 * m + 4), n, sizeof(float), 1, &bytes)) return TN_ERR_TOO_LARGE;
    S = (float *)tn__alloc(bytes);
    rho = (double *)tn__alloc(2 * (size_t)m * sizeof(double));
    if (!S || !rho) {
        TN_FREE(S);
        TN_FREE(rho);
        return TN_ERR_OUT_OF_MEMORY;
    }
    alpha = rho + m;
    Y = S + (size_t)m * n;
    g = Y + (size_t)m * n;
    gn = g + n;
    d = gn + n;
    xn = d + n;
    f = fn(user, x, g);
    for (it = 0; it < max_iter; it++) {
        double gnorm = sqrt(tn__dot(g, g, n)), step, gd;
        size_t i;
        if (f != f || !(gnorm <= DBL_MAX)) { /* a NaN/Inf gradient would stall the line search silently */
            st = tn__fail(TN_ERR_NUMERIC, "L-BFGS: the objective or its gradient is NaN/Inf");
            break;
        }
        if (gnorm < tol) break;
        if ((st = tn__progress("lbfgs", (double)it / max_iter))) break;
        /* two-loop recursion: d = -H g */
        for (i = 0; i < n; i++) d[i] = -g[i];
        for (k = 0; k < hist; k++) {
            int j = (head - 1 - k + m) % m;
            alpha[j] = rho[j] * tn__dot(S + (size_t)j * n, d, n);
            for (i = 0; i < n; i++) d[i] -= (float)alpha[j] * Y[(size_t)j * n + i];
        }
        if (hist) {
            int j = (head - 1 + m) % m;
            double gamma = tn__dot(S + (size_t)j * n, Y + (size_t)j * n, n) / tn__dot(Y + (size_t)j * n, Y + (size_t)j * n, n);
            for (i = 0; i < n; i++) d[i] *= (float)gamma;
        }
        for (k = hist - 1; k >= 0; k--) {
            int j = (head - 1 - k + m) % m;
            double beta = rho[j] * tn__dot(Y + (size_t)j * n, d, n);
            for (i = 0; i < n; i++) d[i] += (float)(alpha[j] - beta) * S[(size_t)j * n + i];
        }
        gd = tn__dot(g, d, n);
        if (gd >= 0) { /* not a descent direction: restart from steepest descent */
            for (i = 0; i < n; i++) d[i] = -g[i];
            gd = -gnorm * gnorm;
            hist = 0;
        }
        step = hist ? 1.0 : first / (gnorm > 1 ? gnorm : 1.0);
        for (k = 0; k < 30; k++) { /* backtracking, Armijo c = 1e-4 */
            for (i = 0; i < n; i++) xn[i] = x[i] + (float)step * d[i];
            fn_ = fn(user, xn, gn);
            if (fn_ == fn_ && fn_ <= f + 1e-4 * step * gd) break;
            step *= 0.5;
        }
        if (k == 30) break; /* no decrease possible at float precision */
        {
            float *s = S + (size_t)head * n, *y = Y + (size_t)head * n;
            double sy;
            for (i = 0; i < n; i++) {
                s[i] = xn[i] - x[i];
                y[i] = gn[i] - g[i];
            }
            sy = tn__dot(s, y, n);
            if (sy > 1e-10) {
                rho[head] = 1.0 / sy;
                head = (head + 1) % m;
                if (hist < m) hist++;
            }
        }
        memcpy(x, xn, n * sizeof(float));
        memcpy(g, gn, n * sizeof(float));
        f = fn_;
    }
    if (final_f) *final_f = f;
    TN_FREE(S);
    TN_FREE(rho);
    return st;
}
#endif /* TN_NO_ENGINE */

