/* test_api: the argument order of docs/api.md ("the output first") over every TN_API declaration
   of terrainnet.h, and over planted declarations in the old orders that it must reject. The
   compiler catches most swapped arguments by type, not an order that drifts back in a new
   function; this does. Run from the repository root; without terrainnet.h it skips. */
#include "tn_test.h"
#include <ctype.h>

#define API_MAX_PARAMS 16

typedef struct api_param {
    char text[160];
    char type[64]; /* the first tn_ name (or base type word) of the parameter */
    int ptr;       /* pointer levels */
    int konst;     /* const before the first '*': an input */
} api_param;

typedef struct api_decl {
    char name[96];
    int n;
    api_param p[API_MAX_PARAMS];
} api_decl;

static char violations[8192]; /* one line per broken rule of the last check */
static int nviolations;

static void report(const char *name, const char *why)
{
    size_t l = strlen(violations);
    snprintf(violations + l, sizeof violations - l, "%s: %s\n", name, why);
    nviolations++;
}

static int ends_with(const char *s, const char *tail)
{
    size_t a = strlen(s), b = strlen(tail);
    return a >= b && strcmp(s + a - b, tail) == 0;
}

static void parse_param(const char *s, size_t n, api_param *p)
{
    size_t i, k = 0;
    const char *star;
    while (n && isspace((unsigned char)*s)) s++, n--;
    while (n && isspace((unsigned char)s[n - 1])) n--;
    if (n >= sizeof p->text) n = sizeof p->text - 1;
    memcpy(p->text, s, n);
    p->text[n] = 0;
    p->ptr = 0;
    for (i = 0; i < n; i++) p->ptr += p->text[i] == '*';
    star = strchr(p->text, '*');
    p->konst = 0;
    {
        const char *c = strstr(p->text, "const");
        p->konst = c && (!star || c < star);
    }
    /* the type word: skip "const", take the first identifier */
    p->type[0] = 0;
    for (i = 0; i < n && !p->type[0];) {
        if (isalpha((unsigned char)p->text[i]) || p->text[i] == '_') {
            size_t j = i;
            while (j < n && (isalnum((unsigned char)p->text[j]) || p->text[j] == '_')) j++;
            if (!(j - i == 5 && strncmp(p->text + i, "const", 5) == 0)) {
                k = j - i < sizeof p->type ? j - i : sizeof p->type - 1;
                memcpy(p->type, p->text + i, k);
                p->type[k] = 0;
            }
            i = j;
        } else i++;
    }
}

/* One declaration "TN_API ret name(params)" (comments removed) into *d; 0 if it is not one. */
static int parse_decl(const char *s, size_t n, api_decl *d)
{
    const char *open = (const char *)memchr(s, '(', n), *q, *a;
    const char *close = s + n;
    int depth = 0;
    size_t l;
    if (!open) return 0;
    q = open;
    while (q > s && isspace((unsigned char)q[-1])) q--;
    a = q;
    while (a > s && (isalnum((unsigned char)a[-1]) || a[-1] == '_')) a--;
    l = (size_t)(q - a);
    if (l == 0 || l >= sizeof d->name) return 0;
    memcpy(d->name, a, l);
    d->name[l] = 0;
    while (close > open && *close != ')') close--;
    d->n = 0;
    for (q = a = open + 1; q <= close; q++) {
        if (*q == '(') depth++;
        else if (*q == ')' && depth > 0 && q < close) depth--;
        else if ((*q == ',' && depth == 0) || q == close) {
            if (d->n < API_MAX_PARAMS) parse_param(a, (size_t)(q - a), &d->p[d->n++]);
            a = q + 1;
        }
    }
    if (d->n == 1 && strcmp(d->p[0].text, "void") == 0) d->n = 0;
    return 1;
}

/* Handles: a function on one of these takes it first, as `this` (tn_ctx_reset(ctx), tensor ops
   on their context, tn_train_next(run), ...), whatever it writes. */
static int is_handle(const char *type)
{
    static const char *const h[] = {"tn_ctx", "tn_params", "tn_optim", "tn_train", "tn_rng", "tn_best_k", "tn_tensor", "tn_flow"};
    size_t i;
    for (i = 0; i < sizeof h / sizeof h[0]; i++)
        if (strcmp(type, h[i]) == 0) return 1;
    return 0;
}

/* A parameter the call writes as its result: a non-const pointer to a terrainnet object, or a
   pointer to a pointer it allocates. Extra results (stats, state, info) and callback user
   pointers go last and do not count. */
static int is_result(const api_param *p)
{
    if (!p->ptr || p->konst) return 0;
    if (strcmp(p->type, "void") == 0 || ends_with(p->type, "_stats") || ends_with(p->type, "_state") || strcmp(p->type, "tn_image_info") == 0 ||
        strcmp(p->type, "tn_rng") == 0)
        return 0;
    return p->ptr >= 2 || strncmp(p->type, "tn_", 3) == 0;
}

static int is_path(const api_param *p) { return strcmp(p->type, "char") == 0 && p->konst && p->ptr == 1; }

static int is_load(const char *name)
{
    return ends_with(name, "_load") || ends_with(name, "_load_ex") || ends_with(name, "_load_memory") || ends_with(name, "_open") ||
           ends_with(name, "_open_memory") || ends_with(name, "_parse");
}

static int is_save(const char *name)
{
    return ends_with(name, "_save") || strstr(name, "_write_") || ends_with(name, "_file") || strcmp(name, "tn_export_glb") == 0 ||
           strcmp(name, "tn_export_obj") == 0 || strcmp(name, "tn_export_unity_raw") == 0;
}

static void check_decl(const api_decl *d)
{
    int i;
    if (d->n == 0) return;
    if (is_save(d->name)) {
        if (!is_path(&d->p[0])) report(d->name, "a save names the file it writes first");
        return;
    }
    if (is_load(d->name) && !(d->p[0].ptr && !d->p[0].konst)) {
        report(d->name, "a load takes the object it fills first");
        return;
    }
    if (is_handle(d->p[0].type) || (d->p[0].ptr && !d->p[0].konst)) return;
    for (i = 1; i < d->n; i++)
        if (is_result(&d->p[i])) {
            char why[256];
            snprintf(why, sizeof why, "the result (%s) comes after an input (%s); the output first", d->p[i].text, d->p[0].text);
            report(d->name, why);
            return;
        }
}

/* A save's object (its second parameter) is what its load fills (its first), same type. */
static void check_pairs(const api_decl *d, int n)
{
    int i, j;
    for (i = 0; i < n; i++) {
        char load[96];
        size_t l = strlen(d[i].name);
        if (!ends_with(d[i].name, "_save") || d[i].n < 2) continue;
        snprintf(load, sizeof load, "%.*s_load", (int)(l - 5), d[i].name);
        for (j = 0; j < n; j++)
            if (strcmp(d[j].name, load) == 0 && d[j].n >= 2 && strcmp(d[j].p[0].type, d[i].p[1].type) != 0) report(load, "its object is not its save's");
    }
}

/* Checks every "TN_API ...;" declaration of text; returns the number of declarations. */
static int check_text(const char *text, api_decl *decls, int max)
{
    const char *s = text;
    int n = 0;
    violations[0] = 0;
    nviolations = 0;
    while ((s = strstr(s, "TN_API ")) != NULL) {
        const char *e = s;
        char buf[2048];
        size_t k = 0;
        int at_line = s == text || s[-1] == '\n';
        /* to the end of the declaration, comments dropped */
        while (*e && *e != ';' && *e != '{' && k < sizeof buf - 1) {
            if (e[0] == '/' && e[1] == '*') {
                const char *c = strstr(e + 2, "*/");
                e = c ? c + 2 : e + strlen(e);
                continue;
            }
            buf[k++] = *e++;
        }
        buf[k] = 0;
        if (at_line && *e == ';' && n < max && parse_decl(buf, k, &decls[n])) check_decl(&decls[n++]);
        s = *e ? e + 1 : e;
    }
    check_pairs(decls, n);
    return n;
}

static api_decl decls[1024];

TN_TEST(header_follows_the_rule)
{
    FILE *f = fopen("terrainnet.h", "rb");
    char *text;
    long size;
    int n;
    if (!f) {
        TN_SKIP("no terrainnet.h in the working directory");
        return;
    }
    fseek(f, 0, SEEK_END);
    size = ftell(f);
    fseek(f, 0, SEEK_SET);
    text = (char *)malloc((size_t)size + 1);
    TN_CHECK(text && fread(text, 1, (size_t)size, f) == (size_t)size);
    fclose(f);
    if (!text) return;
    text[size] = 0;
    n = check_text(text, decls, (int)(sizeof decls / sizeof decls[0]));
    TN_CHECK(n > 300); /* the parse found the API */
    TN_CHECK(nviolations == 0);
    if (nviolations) fprintf(stderr, "%s", violations);
    free(text);
}

TN_TEST(old_orders_rejected)
{
    static const struct {
        const char *decl, *why;
    } bad[] = {
        {"TN_API tn_status tn_gnn_load(const char *path, tn_gnn *model);\n", "a load takes"},
        {"TN_API tn_status tn_gnn_save(const tn_gnn *model, const char *path);\n", "a save names"},
        {"TN_API tn_status tn_image_load(const char *path, tn_image *img, tn_image_info *info);\n", "a load takes"},
        {"TN_API tn_status tn_render_preview(const tn_image *dem, const tn_render_opts *opts, tn_image *out);\n", "the output first"},
        {"TN_API tn_status tn_gnn_train(const tn_image *dem, const tn_gnn_opts *opts, tn_gnn *model, tn_gnn_stats *stats);\n",
         "the output first"},
        {"TN_API tn_status tn_delaunay(const float *xy, int n, int **triangles, int *ntriangles);\n", "the output first"},
        {"TN_API tn_status tn_world_write_tiles(const tn_world *w, const char *dir, const tn_world_run_opts *o, tn_world_run_stats *s);\n",
         "a save names"},
        {"TN_API tn_status tn_x_save(const char *path, const tn_x *m);\nTN_API tn_status tn_x_load(tn_y *m, const char *path);\n",
         "not its save's"},
    };
    static const char *const good[] = {
        "TN_API tn_status tn_gnn_load(tn_gnn *model, const char *path);\nTN_API tn_status tn_gnn_save(const char *path, const tn_gnn *model);\n",
        "TN_API tn_status tn_gnn_train(tn_gnn *model, const tn_image *dem, const tn_gnn_opts *opts, tn_gnn_stats *stats);\n",
        "TN_API tn_tensor *tn_add(tn_ctx *ctx, tn_tensor *a, tn_tensor *b);\n",
        "TN_API const char *tn_params_meta_key(const tn_params *p, int i, const char **value);\n",
        "TN_API tn_status tn_texgan_synthesize_stream(const tn_texgan *m, uint64_t seed, int w, int h, int t, tn_band_fn fn, void *user);\n",
        "/* TN_API tn_status tn_gnn_load(const char *path, tn_gnn *model); in a comment */\n",
    };
    size_t i;
    for (i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        check_text(bad[i].decl, decls, 8);
        TN_CHECK(nviolations == 1 && strstr(violations, bad[i].why) != NULL);
        if (!(nviolations == 1 && strstr(violations, bad[i].why))) fprintf(stderr, "planted %s: %s\n", bad[i].decl, violations);
    }
    for (i = 0; i < sizeof good / sizeof good[0]; i++) {
        check_text(good[i], decls, 8);
        TN_CHECK(nviolations == 0);
        if (nviolations) fprintf(stderr, "good %s: %s\n", good[i], violations);
    }
}

int main(void)
{
    TN_RUN(header_follows_the_rule);
    TN_RUN(old_orders_rejected);
    return tn_test_summary("test_api");
}
