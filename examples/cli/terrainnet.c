/* terrainnet command-line tool: every library feature as a subcommand.
   Build: make   (bin/terrainnet). Run `bin/terrainnet --help`.
   A command is a static argument struct, a table of its positionals and options (parsed, checked
   and turned into --help by the option parser below), a run function and a cli_command naming
   them; `commands` lists them. */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"

#include <assert.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <float.h>
#include <errno.h>
#include <limits.h>
#include <stdarg.h>
#include <signal.h>
#if !defined(_WIN32)
#include <unistd.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#endif

/* ---- small helpers ------------------------------------------------------------------------ */

/* A training command stopped by Ctrl-C: its checkpoint holds the run (exit status 130). */
static int train_interrupted(const char *cmd, long iterations, const char *ckpt)
{
    fprintf(stderr, "terrainnet %s: interrupted after %ld iterations; the checkpoint %s holds them: run the same command with "
                    "--resume to continue\n", cmd, iterations, ckpt);
    return 130;
}

/* A run whose checkpoints all failed (TN_ERR_IO: a full disk, a missing or read-only directory)
   still trains and saves its model (the library makes a failed checkpoint a warning); say so,
   since without a checkpoint neither Ctrl-C nor --resume can continue the run. Called after the
   save, while tn_last_error() still holds the checkpoint's failure. */
static void checkpoint_warning(const char *cmd, long iterations, long resumed_from, int checkpoints, const char *ckpt)
{
    const char *why = tn_last_error();
    if (checkpoints > 0 || iterations <= resumed_from) return;
    fprintf(stderr, "terrainnet %s: warning: no checkpoint could be written to %s (%s); the model was saved, but the run cannot be resumed\n", cmd,
            ckpt, why[0] && strstr(why, ckpt) ? why : "a full disk, or a missing or read-only directory?");
}

/* The height step a training took away from its example (the trainers' --dequantize). */
static void print_dequantized(float step)
{
    if (step > 0) printf("dequantized: trained without the example's height steps of %g\n", (double)step);
    else printf("dequantized: no\n");
}

static void progress_close(void);

/* TERRAINNET_TRAIN_SECONDS=S caps every training budget at S seconds (tests/readme_runs.sh runs
   the README's command lines so); an iteration budget still applies. */
static void train_budget_cap(tn_train_opts *t)
{
    const char *e = getenv("TERRAINNET_TRAIN_SECONDS");
    double s = e ? strtod(e, NULL) : 0;
    if (s > 0 && (t->minutes <= 0 || t->minutes * 60.0 > s)) t->minutes = s / 60.0;
}

static int fail_status(tn_status st)
{
    const char *msg = tn_last_error();
    progress_close();
    fprintf(stderr, "terrainnet: error: %s%s%s\n", tn_status_string(st), msg[0] ? ": " : "", msg);
    return 1;
}

/* A usage error (exit status 2): "terrainnet CMD: message" and where to read more. */
#if defined(__GNUC__)
__attribute__((format(printf, 2, 3)))
#endif
static int usage_error(const char *cmd, const char *fmt, ...)
{
    va_list ap;
    fprintf(stderr, "terrainnet %s: ", cmd);
    va_start(ap, fmt);
    vfprintf(stderr, fmt, ap);
    va_end(ap);
    fprintf(stderr, "\n(see `terrainnet %s --help`)\n", cmd);
    return 2;
}

/* Progress: on a terminal one line redrawn in place (a bar with elapsed time and ETA, at most
   ~12 times a second, as wide as the terminal); otherwise a plain line every ~10 %. */
typedef struct progress_state {
    double t0, last_draw;
    int tty, last_decile, open; /* open: a bar line is on screen without its newline */
    char stage[64];
} progress_state;

/* Ctrl-C asks the running operation to stop at its next progress report (training then saves
   its checkpoint first, so `--resume` continues); a second Ctrl-C kills at once. */
static volatile sig_atomic_t g_interrupted;

static void on_interrupt(int sig)
{
    g_interrupted = 1;
    signal(sig, SIG_DFL);
}

/* Columns of the terminal on stderr: its window size, else $COLUMNS, else 80. */
static size_t terminal_columns(void)
{
    const char *c = getenv("COLUMNS");
    long n = c ? strtol(c, NULL, 10) : 0;
#if defined(TIOCGWINSZ)
    struct winsize ws;
    if (ioctl(2, TIOCGWINSZ, &ws) == 0 && ws.ws_col >= 20) n = ws.ws_col;
#endif
    return n >= 20 && n <= 1000 ? (size_t)n : 80;
}

static progress_state g_progress;

/* Ends a bar line left open (an operation stopped before 100 %), so what follows starts afresh. */
static void progress_close(void)
{
    if (g_progress.open) fputc('\n', stderr);
    g_progress.open = 0;
}

static int cli_progress(void *user, const char *stage, double f)
{
    progress_state *p = (progress_state *)user;
    double now = tn_time_seconds(), el;
    int changed = strncmp(p->stage, stage, sizeof p->stage - 1) != 0;
    size_t word = strcspn(stage, " ");
    if (g_interrupted) return 1;
    if (changed) { /* a new operation restarts the clock; a new step of the same one ("singan-train scale 3/9") does not */
        int same = word == strcspn(p->stage, " ") && !strncmp(p->stage, stage, word) && tn_progress_eta() >= 0;
        snprintf(p->stage, sizeof p->stage, "%s", stage);
        if (!same) {
            p->t0 = now;
            p->last_decile = -1;
        }
    }
    el = now - p->t0;
    if (p->tty) {
        char line[1001];
        double eta = tn_progress_eta() >= 0 ? tn_progress_eta() : f > 0.01 ? el * (1.0 - f) / f : -1.0; /* training runs know theirs */
        if (!changed && f < 1.0 && now - p->last_draw < 0.08) return 0;
        if (changed) progress_close();
        p->last_draw = now;
        tn_progress_line(line, terminal_columns() < sizeof line ? terminal_columns() : sizeof line, stage, f, el, f >= 1.0 ? 0.0 : eta);
        fprintf(stderr, "\r%s", line);
        p->open = 1;
        if (f >= 1.0) progress_close();
        fflush(stderr);
    } else {
        int d = (int)(f * 10.0);
        if (d != p->last_decile) {
            p->last_decile = d;
            if (tn_progress_eta() >= 0) fprintf(stderr, "%s: %3.0f%% (%.1f s, ETA %.0f s)\n", stage, 100.0 * f, el, tn_progress_eta());
            else fprintf(stderr, "%s: %3.0f%% (%.1f s)\n", stage, 100.0 * f, el);
        }
    }
    return 0;
}

static void install_progress(void)
{
#if !defined(_WIN32)
    g_progress.tty = isatty(2);
#endif
    g_progress.last_decile = -1;
    tn_set_progress(cli_progress, &g_progress);
    signal(SIGINT, on_interrupt);
}

/* ---- heights in metres --------------------------------------------------------------------- */

/* An integer file (PNG, PNM, RAW) that records no height range loads as [0, 1] codes. */
static int unitless(const tn_image_info *info)
{
    return !info->has_range && (info->format == TN_FORMAT_PNG || info->format == TN_FORMAT_PNM || info->format == TN_FORMAT_R16);
}

/* A DEM as metres: the file's own range, else --range LO HI (hi > lo) applied to its [0, 1]
   codes. *metres: 0 when the heights stayed [0, 1] codes (a float or GeoTIFF file's values
   count as metres). info may be NULL. */
static tn_status load_dem_metres(const char *path, double lo, double hi, tn_image *dem, int *metres, tn_image_info *info)
{
    tn_image_info own;
    tn_status st;
    size_t i;
    if (!info) info = &own;
    st = tn_image_load(dem, path, info);
    *metres = !st && !unitless(info);
    if (st || *metres || !(hi > lo)) return st;
    for (i = 0; i < (size_t)dem->width * dem->height * dem->channels; i++) dem->data[i] = (float)(lo + dem->data[i] * (hi - lo));
    *metres = 1;
    return TN_OK;
}

/* What a command that needs metres says when it got [0, 1] codes. */
static void warn_unitless(const char *cmd, const char *path, const char *effect)
{
    progress_close();
    fprintf(stderr, "terrainnet %s: warning: %s records no height range, so its heights are read as 0..1 m (%s); give --range LO HI, "
                    "the metres of its lowest and highest code\n", cmd, path, effect);
}

/* ---- option parser ----------------------------------------------------------------------- */

/* A command declares its arguments once, as rows of a cli_opt table: positionals (ARG_POS, in
   order, all required) and options, each pointing at a field of the command's static argument
   struct. The parser applies the SET defaults, fills the fields from argv and checks every value;
   --help is printed from the same rows, so the usage text cannot drift from what is accepted.
   A usage error exits with status 2. */
typedef enum cli_kind {
    ARG_POS, ARG_STR,           /* const char * */
    ARG_FLAG,                   /* no value: int set to 1 */
    ARG_CHOICE,                 /* one of the words of meta, "a|b|c": int set to its index */
    ARG_INT, ARG_LONG, ARG_U64, /* int, long, uint64_t (decimal) */
    ARG_DOUBLE, ARG_FLOAT,      /* finite numbers */
    ARG_WXH                     /* "WxH" or "N" (= NxN): ints at dst and dst2 */
} cli_kind;

enum {
    REQ = 1,     /* the option must be given */
    PAIR = 2,    /* two numbers, at dst and dst2 */
    OPT2 = 4,    /* with PAIR: the second may be left out (then it equals the first) */
    ORDERED = 8, /* with PAIR (ARG_DOUBLE): the first must be below the second */
    ABOVE = 16,  /* the range excludes min */
    SET = 32,    /* def is parsed into the field before argv; else it is only shown (the field
                    stays 0 and the library applies that default) */
    HIDDEN = 64  /* an alias kept for old command lines: accepted, left out of --help */
};
#define NO_MAX 1e300 /* max of a range open at the top */

typedef struct cli_opt {
    const char *name;  /* long option name without "--", or the positional's name */
    char short_name;   /* 'o' for -o, else 0 */
    cli_kind kind;
    int flags;
    void *dst, *dst2;  /* where the value goes: a field of the command's argument struct */
    double min, max;   /* accepted range of a number when min < max */
    const char *meta;  /* value placeholder in --help ("N [M]", "LO HI"); ARG_CHOICE: the words */
    const char *help;  /* one line; --help wraps it */
    const char *def;   /* default as --help shows it; with SET also the field's initial value */
} cli_opt;

typedef struct cli_command {
    const char *name;
    const cli_opt *opts;
    int nopts;
    int (*run)(void);  /* runs the command on its parsed argument struct */
    const char *summary;
    const char *about; /* --help text after the synopsis; wrapped, '\n' starts a paragraph */
} cli_command;

/* Command X has its arguments in the static struct X_arg, its table in X_opts, its code in run_X. */
#define CLI_CMD(x) x##_opts, (int)(sizeof x##_opts / sizeof x##_opts[0]), run_##x

/* What a number of o must be, e.g. "a whole number from 2 to 8192". */
static const char *cli_wanted(const cli_opt *o, char *buf, size_t n)
{
    const char *num = o->kind == ARG_DOUBLE || o->kind == ARG_FLOAT ? "number" : "whole number";
    int top = o->max < NO_MAX, nonneg = o->min == 0 && (!top || o->max >= 1e9);
    if (o->min >= o->max) snprintf(buf, n, "a %s%s", o->kind == ARG_U64 ? "non-negative " : "", num);
    else if (o->flags & ABOVE) snprintf(buf, n, "a positive %s", num); /* ABOVE goes with min 0 */
    else if (nonneg) snprintf(buf, n, "a non-negative %s", num);
    else if (!top) snprintf(buf, n, "a %s of at least %.10g", num, o->min);
    else snprintf(buf, n, "a %s from %.10g to %.10g", num, o->min, o->max);
    if (o->min < o->max && top && ((o->flags & ABOVE) || nonneg)) snprintf(buf + strlen(buf), n - strlen(buf), " up to %.10g", o->max);
    return buf;
}

/* Parses s as one number of o into dst; 0 if it is none or out of range. */
static int cli_number(const cli_opt *o, const char *s, void *dst)
{
    char *end;
    long l = 0;
    unsigned long long u = 0;
    double v;
    errno = 0;
    if (o->kind == ARG_DOUBLE || o->kind == ARG_FLOAT) v = strtod(s, &end);
    else if (o->kind == ARG_U64) v = (double)(u = strtoull(s, &end, 10));
    else v = (double)(l = strtol(s, &end, 10));
    if (end == s || *end || errno || !(v >= -1e300 && v <= 1e300) || (o->kind == ARG_U64 && strchr(s, '-'))) return 0;
    if ((o->kind == ARG_FLOAT && fabs(v) > FLT_MAX) || ((o->kind == ARG_INT || o->kind == ARG_WXH) && (l < INT_MIN || l > INT_MAX))) return 0;
    if (o->min < o->max && (v < o->min || v > o->max || (v == o->min && (o->flags & ABOVE)))) return 0;
    switch (o->kind) {
    case ARG_DOUBLE: *(double *)dst = v; break;
    case ARG_FLOAT: *(float *)dst = (float)v; break;
    case ARG_U64: *(uint64_t *)dst = (uint64_t)u; break;
    case ARG_LONG: *(long *)dst = l; break;
    default: *(int *)dst = (int)l;
    }
    return 1;
}

/* "--name" or "-o" */
static const char *cli_spelled(const cli_opt *o, char *buf, size_t n)
{
    if (o->short_name) snprintf(buf, n, "-%c", o->short_name);
    else snprintf(buf, n, "--%s", o->name);
    return buf;
}

/* Stores the value(s) of option o from argv[0..n-1]; returns how many it used, -1 after a usage error. */
static int cli_value(const cli_command *c, const cli_opt *o, int n, char **argv)
{
    char sp[64], want[96], buf[64], *x = NULL;
    const char *bad = argv[0], *m = o->meta, *bar;
    int i;
    cli_spelled(o, sp, sizeof sp);
    if (n < ((o->flags & PAIR) && !(o->flags & OPT2) ? 2 : 1)) return usage_error(c->name, "missing value for %s %s", sp, o->meta), -1;
    if (o->kind == ARG_STR) return *(const char **)o->dst = argv[0], 1;
    if (o->kind == ARG_CHOICE) {
        for (i = 0;; i++, m = bar + 1) {
            if (!(bar = strchr(m, '|'))) bar = m + strlen(m);
            if ((size_t)(bar - m) == strlen(argv[0]) && !strncmp(m, argv[0], (size_t)(bar - m))) return *(int *)o->dst = i, 1;
            if (!*bar) return usage_error(c->name, "%s must be one of %s, not %s", sp, o->meta, argv[0]), -1;
        }
    }
    if (o->kind == ARG_WXH) {
        snprintf(buf, sizeof buf, "%s", argv[0]);
        if ((x = strchr(buf, 'x')) != NULL || (x = strchr(buf, 'X')) != NULL) *x++ = 0;
        if (strlen(argv[0]) < sizeof buf && cli_number(o, buf, o->dst) && cli_number(o, x ? x : buf, o->dst2)) return 1;
        return usage_error(c->name, "%s needs WxH (e.g. 512x512), each side %s, not %s", sp, cli_wanted(o, want, sizeof want), argv[0]), -1;
    }
    if (cli_number(o, argv[0], o->dst)) {
        cli_opt any = *o; /* OPT2: the next word is the second value if it is a number at all */
        any.min = any.max = 0;
        if (!(o->flags & PAIR)) return 1;
        if ((o->flags & OPT2) && (n < 2 || !cli_number(&any, argv[1], o->dst2))) return cli_number(o, argv[0], o->dst2);
        if (!cli_number(o, argv[1], o->dst2)) bad = argv[1];
        else if (!(o->flags & ORDERED) || *(double *)o->dst < *(double *)o->dst2) return 2;
        else return usage_error(c->name, "%s needs two numbers %s with LO < HI, not %s %s", sp, o->meta, argv[0], argv[1]), -1;
    }
    return usage_error(c->name, "%s needs %s, not %s", sp, cli_wanted(o, want, sizeof want), bad), -1;
}

/* "A", "A and B", "A, B and C": the positionals (pos = 1) or the required options of c. */
static const char *cli_list(const cli_command *c, int pos, char *buf, size_t n)
{
    int i, k = 0, total = 0;
    char sp[64];
    for (i = 0; i < c->nopts; i++) total += pos ? c->opts[i].kind == ARG_POS : (c->opts[i].flags & REQ) != 0;
    for (buf[0] = 0, i = 0; i < c->nopts; i++) {
        const cli_opt *o = &c->opts[i];
        size_t len = strlen(buf);
        if (pos ? o->kind != ARG_POS : !(o->flags & REQ)) continue;
        k++;
        snprintf(buf + len, n - len, "%s%s%s%s", k == 1 ? "" : k == total ? " and " : ", ", pos ? o->name : cli_spelled(o, sp, sizeof sp),
                 pos ? "" : " ", pos ? "" : o->meta);
    }
    return total == 1 ? "missing" : "needs";
}

/* Fills c's argument struct (zero, as static) from argv; 0, or 2 after a usage error. */
static int cli_parse(const cli_command *c, int argc, char **argv)
{
    char list[512];
    unsigned char given[64] = {0};
    int a, i, k, npos = 0, used;
    assert(c->nopts <= (int)sizeof given);
    for (i = 0; i < c->nopts; i++) {
        char *def = (char *)c->opts[i].def;
        if ((c->opts[i].flags & SET) && cli_value(c, &c->opts[i], 1, &def) != 1) assert(!"a SET default must parse");
    }
    for (a = 0; a < argc; a++) {
        const char *s = argv[a];
        const cli_opt *o = NULL;
        if (s[0] != '-') { /* the next positional */
            for (i = k = 0; i < c->nopts && !o; i++)
                if (c->opts[i].kind == ARG_POS && k++ == npos) o = &c->opts[i];
            if (!o) return usage_error(c->name, k ? "too many arguments: %s" : "unexpected argument %s", s);
            *(const char **)o->dst = s;
            npos++;
            continue;
        }
        for (i = 0; i < c->nopts && !o; i++)
            if (c->opts[i].kind != ARG_POS && (s[1] == '-' ? !strcmp(s + 2, c->opts[i].name) : s[1] == c->opts[i].short_name && s[1] && !s[2]))
                o = &c->opts[i];
        if (!o) return usage_error(c->name, "unknown option %s", s);
        if (o->kind == ARG_FLAG) *(int *)o->dst = 1;
        else if ((used = cli_value(c, o, argc - a - 1, argv + a + 1)) < 0) return 2;
        else a += used;
        given[o - c->opts] = 1;
    }
    for (i = k = 0; i < c->nopts; i++) k += c->opts[i].kind == ARG_POS;
    if (npos < k) return usage_error(c->name, "%s %s", cli_list(c, 1, list, sizeof list), list);
    for (i = 0; i < c->nopts; i++)
        if ((c->opts[i].flags & REQ) && !given[i]) return usage_error(c->name, "%s %s", cli_list(c, 0, list, sizeof list), list);
    return 0;
}

/* ---- generated help ---------------------------------------------------------------------- */

#define HELP_WIDTH 100

/* Prints the words of text from column col on, wrapping to lines indented by indent; '\n' in
   text starts a new line. */
static void cli_wrap(const char *text, int col, int indent)
{
    int fresh = 1;
    for (;;) {
        int len = (int)strcspn(text, " \n");
        if (!fresh && col + 1 + len > HELP_WIDTH) col = printf("\n%*s", indent, "") - 1, fresh = 1;
        col += printf("%s%.*s", fresh ? "" : " ", len, text);
        fresh = 0;
        text += len;
        if (*text == '\n') col = printf("\n%*s", indent, "") - 1, fresh = 1;
        if (!*text++) break;
    }
    putchar('\n');
}

/* "-o, --output OUT", "    --size N [M]" or a positional's name. */
static const char *cli_label(const cli_opt *o, char *buf, size_t n)
{
    if (o->kind == ARG_POS) snprintf(buf, n, "%s", o->name);
    else snprintf(buf, n, "%c%c%c --%s%s%s", o->short_name ? '-' : ' ', o->short_name ? o->short_name : ' ', o->short_name ? ',' : ' ',
                  o->name, o->meta ? " " : "", o->meta ? o->meta : "");
    return buf;
}

/* Usage generated from c's table: synopsis, about text, arguments, options with defaults. */
static void cli_help(const cli_command *c)
{
    char item[160], sp[64], text[700];
    int i, pass, header, w = 10, col = printf("usage: terrainnet %s", c->name), indent = col;
    for (pass = 0; pass < 3; pass++) /* synopsis: positionals, required options, the others */
        for (i = 0; i < c->nopts; i++) {
            const cli_opt *o = &c->opts[i];
            int req = (o->flags & REQ) != 0, opt = o->kind != ARG_POS && !req;
            if (pass != (o->kind == ARG_POS ? 0 : req ? 1 : 2) || (o->flags & HIDDEN)) continue;
            snprintf(item, sizeof item, "%s%s%s%s%s", opt ? "[" : "", o->kind == ARG_POS ? o->name : cli_spelled(o, sp, sizeof sp),
                     o->meta ? " " : "", o->meta ? o->meta : "", opt ? "]" : "");
            if (col + 1 + (int)strlen(item) > HELP_WIDTH) col = printf("\n%*s", indent, "") - 1;
            col += printf(" %s", item);
        }
    putchar('\n');
    cli_wrap(c->about, 0, 0);
    for (i = 0; i < c->nopts; i++)
        if (!(c->opts[i].flags & HIDDEN) && (col = (int)strlen(cli_label(&c->opts[i], item, sizeof item))) > w && col <= 28) w = col;
    for (pass = 0; pass < 2; pass++) /* arguments, then options */
        for (i = 0, header = 0; i < c->nopts; i++) {
            const cli_opt *o = &c->opts[i];
            if ((o->kind == ARG_POS) == pass || (o->flags & HIDDEN)) continue;
            if (!header++) printf(pass ? "\noptions:\n" : "\narguments:\n");
            col = printf("  %s", cli_label(o, item, sizeof item));
            printf("%-*s", col > w + 2 ? w + 5 : w + 4 - col, col > w + 2 ? "\n" : "");
            snprintf(text, sizeof text, "%s%s%s%s", o->help, o->flags & REQ ? " (required)" : o->def ? " (default: " : "",
                     o->flags & REQ || !o->def ? "" : o->def, o->flags & REQ || !o->def ? "" : ")");
            cli_wrap(text, w + 4, w + 4);
        }
    printf("%s  %-*s  show this help\n", header ? "" : "\noptions:\n", w, "-h, --help");
}

/* ---- info -------------------------------------------------------------------------------- */

static struct info_args { const char *path; int tensors; tn_load_opts lo; } info_arg;
static const cli_opt info_opts[] = {
    {"FILE", 0, ARG_POS, 0, &info_arg.path, NULL, 0, 0, NULL, "image, heightmap, model or checkpoint (.tnw) file", NULL},
    {"raw-size", 0, ARG_INT, PAIR, &info_arg.lo.raw_width, &info_arg.lo.raw_height, 0, 0, "W H",
     "size of a headerless .r16 file", "a square from the file size"},
    {"tensors", 0, ARG_FLAG, 0, &info_arg.tensors, NULL, 0, 0, NULL, ".tnw: list every tensor with its shape", NULL},
};

static int is_tnw(const char *path)
{
    char magic[4] = {0, 0, 0, 0};
    FILE *f = fopen(path, "rb");
    size_t n = f ? fread(magic, 1, 4, f) : 0;
    if (f) fclose(f);
    return n == 4 && !memcmp(magic, "TNW1", 4);
}

/* A .tnw: what it is (its metadata; a model is loaded by its method, which checks it whole), its
   tensors, and a digest of all their values. */
static int info_tnw(const char *path, int list)
{
    tn_params *p = NULL;
    tn_status st = tn_params_open(&p, path);
    const tn_method *m = NULL, *legacy = NULL;
    void *model = NULL;
    const char *kind, *method;
    char why[512] = "";
    size_t learned = 0, buffers = 0, k;
    uint64_t h = 0xcbf29ce484222325ULL;
    int i, d;
    if (st) return fail_status(st);
    method = tn_params_meta(p, "method");
    kind = tn_params_meta(p, "kind");
    for (i = 0; !method && tn_method_at(i); i++)
        if (tn_method_at(i)->legacy_tensor && tn_params_find(p, tn_method_at(i)->legacy_tensor)) legacy = tn_method_at(i);
    if (!kind && tn_method_load_any(&m, &model, path)) snprintf(why, sizeof why, "%s", tn_last_error());
    printf("file: %s\nkind: %s", path, kind ? kind : method || legacy ? "model" : "weights");
    if (legacy && !kind) printf(" (%s, before metadata)", legacy->name);
    printf("\n");
    for (i = 0; i < tn_params_meta_count(p); i++) {
        const char *v, *key = tn_params_meta_key(p, i, &v);
        if (strcmp(key, "kind") != 0) printf("%s: %s\n", key, v);
    }
    if (m) printf("summary: %s\nchannels: %d\n", m->summary, m->channels(model));
    else if ((method || legacy) && !kind) printf("loads: no: %s\n", why);
    if (m) m->free(model);
    for (i = 0; i < tn_params_count(p); i++) {
        const tn_tensor *t = tn_params_get(p, i);
        if (t->requires_grad) learned += t->numel;
        else buffers += t->numel;
        for (k = 0; k < t->numel; k++) {
            uint32_t u;
            memcpy(&u, &t->data[k], 4);
            for (d = 0; d < 4; d++) h = (h ^ ((u >> (8 * d)) & 0xffu)) * 0x100000001b3ULL;
        }
        if (list) {
            printf("tensor: %-24s %s", t->name, t->requires_grad ? "learned" : "buffer ");
            for (d = 0; d < t->ndim; d++) printf("%s%d", d ? " x " : " ", t->shape[d]);
            printf("\n");
        }
    }
    printf("tensors: %d\nlearned_values: %zu\nbuffer_values: %zu\nvalues_digest: %016llx\n", tn_params_count(p), learned, buffers,
           (unsigned long long)h);
    tn_params_free(p);
    return 0;
}

static int run_info(void)
{
    struct info_args *a = &info_arg;
    tn_image img = {0, 0, 0, NULL};
    tn_image_info info;
    tn_status st;
    float mn, mx;
    size_t bad, i, n;
    double sum = 0.0;
    if (is_tnw(a->path)) return info_tnw(a->path, a->tensors);
    if ((st = tn_image_load_ex(&img, a->path, &a->lo, &info))) return fail_status(st);
    bad = tn_image_range(&mn, &mx, &img);
    n = (size_t)img.width * img.height * img.channels;
    for (i = 0; i < n; i++) sum += img.data[i];
    printf("file: %s\nformat: %s\nsize: %d x %d\nchannels: %d\nbit_depth: %d\n", a->path, tn_format_name(info.format),
           img.width, img.height, img.channels, info.bit_depth);
    if (info.interlaced) printf("interlaced: adam7\n");
    if (info.has_range) printf("height_range_m: %.6g %.6g\n", info.range_lo, info.range_hi);
    else if (info.format == TN_FORMAT_HGT || info.format == TN_FORMAT_ASC) printf("units: metres (as stored)\n");
    else if (info.format == TN_FORMAT_TIFF && info.bit_depth > 8 && info.file_channels < 3) printf("units: as stored (metres for a DEM)\n");
    else printf("units: normalised [0, 1] (the file records no height range)\n");
    if (info.cellsize > 0) printf("cellsize: %.6g\norigin: %.6g %.6g\n", info.cellsize, info.x_origin, info.y_origin);
    if (info.georef.has_transform) {
        const double *t = info.georef.transform;
        printf("crs: %s\ngeotransform: %.17g %.17g %.17g %.17g %.17g %.17g\n",
               info.georef.model_type == 1 ? "projected" : info.georef.model_type == 2 ? "geographic" : "not stated", t[0], t[1], t[2], t[3], t[4], t[5]);
        if (info.georef.dx > 0) printf("spacing_m: %.6g %.6g\n", info.georef.dx, info.georef.dy);
    }
    if (info.has_nodata) printf("nodata: %.17g\n", info.nodata);
    if (info.voids_filled) printf("voids_filled: %zu\n", info.voids_filled);
    printf("min: %.6g\nmax: %.6g\nmean: %.6g\n", mn, mx, sum / (double)n);
    if (bad) printf("nan_or_inf: %zu\n", bad);
    tn_image_free(&img);
    return 0;
}

static const cli_command info_cmd = {"info", CLI_CMD(info), "describe an image, heightmap, model or checkpoint",
    "Prints the format, size, channels, bit depth, height range (metres when the file records them) and value statistics "
    "of an image or heightmap. For a .tnw model or checkpoint: its method, format, library version and provenance (seed, "
    "iterations, training seconds, the example's size and digest), its tensors and a digest of their values; a model is "
    "loaded by its method, which says what it generates and how many channels (or why the file does not load)."};

/* ---- convert ----------------------------------------------------------------------------- */

static struct convert_args { const char *in, *out; tn_load_opts lo; tn_save_opts so; } convert_arg;
static const cli_opt convert_opts[] = {
    {"IN", 0, ARG_POS, 0, &convert_arg.in, NULL, 0, 0, NULL, "file to read", NULL},
    {"OUT", 0, ARG_POS, 0, &convert_arg.out, NULL, 0, 0, NULL, "file to write; its extension picks the format", NULL},
    {"range", 0, ARG_DOUBLE, PAIR | ORDERED, &convert_arg.so.range_lo, &convert_arg.so.range_hi, 0, 0, "LO HI",
     "heights that codes 0..max of an 8/16-bit OUT stand for", "the range recorded in IN"},
    {"bits", 0, ARG_INT, 0, &convert_arg.so.bit_depth, NULL, 8, 16, "8|16", "bit depth of an integer format (.tif: 16 = int16 metres, 8 = 8-bit picture)",
     "16 for one channel, else 8; .tif float32"},
    {"raw-size", 0, ARG_INT, PAIR, &convert_arg.lo.raw_width, &convert_arg.lo.raw_height, 0, 0, "W H",
     "size of a headerless .r16 IN", "a square from the file size"},
    {"cellsize", 0, ARG_DOUBLE, ABOVE, &convert_arg.so.cellsize, NULL, 0, NO_MAX, "M", "cell size of an .asc OUT", "IN's, else 1"},
};

static int run_convert(void)
{
    struct convert_args *a = &convert_arg;
    tn_image img = {0, 0, 0, NULL};
    tn_image_info info;
    tn_status st;
    if (a->so.bit_depth && a->so.bit_depth != 8 && a->so.bit_depth != 16)
        return usage_error("convert", "--bits must be 8 or 16, not %d", a->so.bit_depth);
    a->so.has_range = a->so.range_hi > a->so.range_lo; /* --range given (it checks LO < HI) */
    if ((st = tn_image_load_ex(&img, a->in, &a->lo, &info))) return fail_status(st);
    if (!a->so.has_range && info.has_range) {
        a->so.has_range = 1;
        a->so.range_lo = info.range_lo;
        a->so.range_hi = info.range_hi;
    }
    if (!a->so.cellsize && info.cellsize > 0) a->so.cellsize = info.cellsize;
    a->so.georef = &info.georef; /* a GeoTIFF OUT lines up with IN */
    st = tn_image_save(a->out, &img, &a->so);
    tn_image_free(&img);
    if (st) return fail_status(st);
    return 0;
}

static const cli_command convert_cmd = {"convert", CLI_CMD(convert), "convert between heightmap/image formats, keeping metres",
    "Converts between PNG, PGM/PPM, PFM, SRTM .hgt, ESRI .asc, .r16 and GeoTIFF (.tif; format from OUT's extension). Heights keep their "
    "metres: a range recorded in IN (or given with --range) is written to OUT where the format can hold it; a GeoTIFF OUT "
    "carries IN's georeference. OUT is written atomically and never half-written."};

/* ---- metrics ----------------------------------------------------------------------------- */

static struct metrics_args { const char *ref, *img; double range; } metrics_arg;
static const cli_opt metrics_opts[] = {
    {"REFERENCE", 0, ARG_POS, 0, &metrics_arg.ref, NULL, 0, 0, NULL, "the image to compare with", NULL},
    {"IMAGE", 0, ARG_POS, 0, &metrics_arg.img, NULL, 0, 0, NULL, "the image to judge (same size and channels)", NULL},
    {"range", 0, ARG_DOUBLE, ABOVE, &metrics_arg.range, NULL, 0, NO_MAX, "R", "data range for SSIM and PSNR", "max(REFERENCE) - min(REFERENCE)"},
};

static int run_metrics(void)
{
    struct metrics_args *a = &metrics_arg;
    tn_image a_img = {0, 0, 0, NULL}, b_img = {0, 0, 0, NULL};
    tn_metrics m;
    tn_status st;
    if ((st = tn_image_load(&a_img, a->ref, NULL))) return fail_status(st);
    if ((st = tn_image_load(&b_img, a->img, NULL))) {
        tn_image_free(&a_img);
        return fail_status(st);
    }
    st = tn_compare(&m, &a_img, &b_img, a->range);
    tn_image_free(&a_img);
    tn_image_free(&b_img);
    if (st) return fail_status(st);
    printf("ssim: %.6f\npsnr: %.4f\nrmse: %.6g\nmae: %.6g\n", m.ssim, m.psnr, m.rmse, m.mae);
    return 0;
}

static const cli_command metrics_cmd = {"metrics", CLI_CMD(metrics), "compare two images: SSIM, PSNR, RMSE, MAE",
    "Compares IMAGE with REFERENCE. The default data range does not depend on units. Prints ssim (Gaussian 11x11, sigma "
    "1.5, as scikit-image), psnr (dB), rmse and mae."};

/* ---- render ------------------------------------------------------------------------------ */

static struct render_args { const char *in, *out; int view; double sea; tn_view_opts vo; } render_arg = {.sea = NAN};
static const cli_opt render_opts[] = {
    {"DEM", 0, ARG_POS, 0, &render_arg.in, NULL, 0, 0, NULL, "heightmap to draw", NULL},
    {"output", 'o', ARG_STR, REQ, &render_arg.out, NULL, 0, 0, "OUT.png", "picture to write (8-bit)", NULL},
    {"3d", 0, ARG_FLAG, 0, &render_arg.view, NULL, 0, 0, NULL, "perspective view of the terrain instead of the map view", NULL},
    {"size", 0, ARG_INT, PAIR, &render_arg.vo.width, &render_arg.vo.height, 16, 16384, "W H", "size of the 3D view", "960 540"},
    {"azimuth", 0, ARG_FLOAT, 0, &render_arg.vo.azimuth_deg, NULL, 0, 0, "DEG", "3D camera direction, clockwise from north", "180, from the south"},
    {"pitch", 0, ARG_FLOAT, 0, &render_arg.vo.pitch_deg, NULL, 0, 0, "DEG", "3D camera's downward angle", "30"},
    {"relief", 0, ARG_FLOAT, 0, &render_arg.vo.relief, NULL, 0, 0, "F", "3D height of the full range as a fraction of the DEM width",
     "0.2, or from --spacing"},
    {"spacing", 0, ARG_FLOAT, ABOVE, &render_arg.vo.spacing, NULL, 0, NO_MAX, "M",
     "3D: metres per pixel of a DEM in metres, for its true relief times --exaggeration", "an .hgt's or GeoTIFF's own, else none"},
    {"exaggeration", 0, ARG_FLOAT, ABOVE, &render_arg.vo.exaggeration, NULL, 0, 1000, "F", "3D: vertical exaggeration with a known spacing", "2"},
    {"sea-level", 0, ARG_DOUBLE, 0, &render_arg.sea, NULL, 0, 0, "H",
     "draw water below height H (the DEM's units)", "0 on a DEM that records metres (a range, .hgt, GeoTIFF, .asc), else no sea"},
    {"light", 0, ARG_FLOAT, 0, &render_arg.vo.colours.shade.azimuth_deg, NULL, 0, 0, "DEG", "sun azimuth, clockwise from north", "315"},
};

static int run_render(void)
{
    struct render_args *a = &render_arg;
    tn_image dem = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_image_info info;
    tn_save_opts so;
    tn_status st;
    if ((st = tn_image_load_ex(&dem, a->in, NULL, &info))) return fail_status(st);
    if (isnan(a->sea) && (info.has_range || info.format == TN_FORMAT_HGT || info.format == TN_FORMAT_TIFF || info.format == TN_FORMAT_ASC))
        a->sea = 0; /* metres: the sea is below 0 m */
    a->vo.colours.sea = !isnan(a->sea);
    a->vo.colours.sea_level = a->vo.colours.sea ? (float)a->sea : 0.0f;
    if (!a->vo.spacing && !a->vo.relief) /* a pixel size in metres: the true relief, exaggerated */
        a->vo.spacing = info.format == TN_FORMAT_HGT ? (float)info.cellsize : info.georef.dx > 0 ? (float)(0.5 * (info.georef.dx + info.georef.dy)) : 0.0f;
    st = a->view ? tn_render_view(&out, &dem, &a->vo) : tn_render_preview(&out, &dem, &a->vo.colours);
    tn_image_free(&dem);
    if (st) return fail_status(st);
    memset(&so, 0, sizeof so);
    so.bit_depth = 8;
    if (!a->view) so.georef = &info.georef; /* a .tif map preview lies over its DEM in GIS tools */
    st = tn_image_save(a->out, &out, &so);
    tn_image_free(&out);
    if (st) return fail_status(st);
    return 0;
}

static const cli_command render_cmd = {"render", CLI_CMD(render), "hillshaded colour preview or 3D view of a DEM",
    "Writes a preview: hypsometric colours times a hillshade (default), or with --3d a perspective view of the terrain."};

/* ---- export ------------------------------------------------------------------------------ */

static struct export_args {
    const char *in, *out, *texture, *snow, *vegetation, *splat_preview;
    int to, drape, raw_size;
    double range[2];
    tn_mesh_opts mo;
    tn_splat_opts so;
} export_arg;
enum { EXPORT_GLB, EXPORT_OBJ, EXPORT_NORMAL_GL, EXPORT_NORMAL_DX, EXPORT_UNITY_RAW, EXPORT_NORMAL, EXPORT_SPLAT }; /* --to words */
static const cli_opt export_opts[] = {
    {"DEM", 0, ARG_POS, 0, &export_arg.in, NULL, 0, 0, NULL, "heightmap to export (heights in metres when the file records them)", NULL},
    {"to", 0, ARG_CHOICE, REQ, &export_arg.to, NULL, 0, 0, "glb|obj|normal-gl|normal-dx|unity-raw|normal|splat",
     "glTF 2.0 binary mesh; Wavefront OBJ (+ .mtl and .png with a texture); normal map PNG, OpenGL (green = north) or DirectX "
     "(green = south); Unity terrain RAW (16-bit, 2^n + 1 square); normal = normal-gl; splat map PNG, RGBA = weights of "
     "vegetation, bare ground, rock, snow (sum 1)", NULL},
    {"output", 'o', ARG_STR, REQ, &export_arg.out, NULL, 0, 0, "OUT", "file to write", NULL},
    {"spacing", 0, ARG_FLOAT, PAIR | OPT2 | ABOVE, &export_arg.mo.dx, &export_arg.mo.dy, 0, NO_MAX, "DX [DY]", "pixel spacing in metres",
     "a GeoTIFF's own, else 1"},
    {"range", 0, ARG_DOUBLE, PAIR | ORDERED, &export_arg.range[0], &export_arg.range[1], 0, 0, "LO HI",
     "metres that codes 0..max of an 8/16-bit DEM without a recorded range stand for", "the file's range, else its [0, 1] codes"},
    {"heights", 0, ARG_DOUBLE, PAIR | ORDERED | HIDDEN, &export_arg.range[0], &export_arg.range[1], 0, 0, "LO HI", "--range", NULL},
    {"z-scale", 0, ARG_FLOAT, 0, &export_arg.mo.z_scale, NULL, 0, 0, "F", "height exaggeration", "1"},
    {"step", 0, ARG_INT, 0, &export_arg.mo.step, NULL, 1, 65536, "N", "keep every N-th sample (grid decimation)", "1"},
    {"texture", 0, ARG_STR, 0, &export_arg.texture, NULL, 0, 0, "IMG", "colour image draped over the mesh", NULL},
    {"preview-texture", 0, ARG_FLAG, 0, &export_arg.drape, NULL, 0, 0, NULL, "drape the DEM's own hillshaded colour preview", NULL},
    {"raw-size", 0, ARG_INT, 0, &export_arg.raw_size, NULL, 33, 4097, "N", "unity-raw: side 2^n + 1 (the DEM is resampled to it)",
     "the smallest 2^n + 1 not below the DEM's larger side"},
    {"rock-slope", 0, ARG_FLOAT, ABOVE, &export_arg.so.rock_slope_deg, NULL, 0, 90, "DEG", "splat: slope where rock is half the weight", "35"},
    {"tree-line", 0, ARG_FLOAT, 0, &export_arg.so.tree_line, NULL, 0, 0, "F", "splat: height fraction of the DEM's range where vegetation ends",
     "0.5"},
    {"snow-line", 0, ARG_FLOAT, 0, &export_arg.so.snow_line, NULL, 0, 0, "F", "splat: height fraction where snow starts", "0.8"},
    {"snow", 0, ARG_STR, 0, &export_arg.snow, NULL, 0, 0, "MASK", "splat: snow mask in [0, 1] (the DEM's size), instead of the snow line", NULL},
    {"vegetation", 0, ARG_STR, 0, &export_arg.vegetation, NULL, 0, 0, "MASK", "splat: vegetation mask in [0, 1], instead of the tree line", NULL},
    {"splat-preview", 0, ARG_STR, 0, &export_arg.splat_preview, NULL, 0, 0, "PNG",
     "splat: the materials as colours (green, brown, grey, white) times a hillshade", NULL},
};

/* The splat map and its optional colour preview. */
static tn_status export_splat(struct export_args *a, const tn_image *dem)
{
    static const float colour[4][3] = {{0.30f, 0.50f, 0.18f}, {0.55f, 0.42f, 0.28f}, {0.50f, 0.50f, 0.50f}, {0.97f, 0.97f, 1.0f}};
    tn_image snow = {0, 0, 0, NULL}, veg = {0, 0, 0, NULL}, w = {0, 0, 0, NULL}, shade = {0, 0, 0, NULL}, pv = {0, 0, 0, NULL};
    tn_save_opts so;
    tn_status st = TN_OK;
    size_t i, np;
    memset(&so, 0, sizeof so);
    so.bit_depth = 8;
    a->so.dx = a->mo.dx;
    a->so.dy = a->mo.dy;
    if (!(a->mo.dx > 0)) /* slopes decide rock: at 1 m per pixel a DEM in metres is nearly all cliff */
        fprintf(stderr, "export: no --spacing: slopes assume pixels 1 height unit wide (give the pixel size in metres)\n");
    if (a->snow) st = tn_image_load(&snow, a->snow, NULL);
    if (!st && a->vegetation) st = tn_image_load(&veg, a->vegetation, NULL);
    a->so.snow = snow.data ? &snow : NULL;
    a->so.vegetation = veg.data ? &veg : NULL;
    if (!st) st = tn_export_splat(&w, dem, &a->so);
    if (!st) st = tn_image_save(a->out, &w, &so);
    if (!st && a->splat_preview) {
        tn_hillshade_opts ho;
        memset(&ho, 0, sizeof ho);
        ho.dx = a->mo.dx;
        ho.dy = a->mo.dy > 0 ? a->mo.dy : a->mo.dx;
        st = tn_image_hillshade(&shade, dem, &ho);
        if (!st) st = tn_image_create(&pv, dem->width, dem->height, 3);
        np = (size_t)dem->width * dem->height;
        for (i = 0; !st && i < np; i++) {
            int c, m;
            float light = 0.35f + 0.65f * shade.data[i];
            for (c = 0; c < 3; c++) {
                float v = 0;
                for (m = 0; m < 4; m++) v += w.data[4 * i + m] * colour[m][c];
                pv.data[3 * i + c] = v * light;
            }
        }
        if (!st) st = tn_image_save(a->splat_preview, &pv, &so);
    }
    if (!st) {
        double sum[4] = {0, 0, 0, 0};
        np = (size_t)w.width * w.height;
        for (i = 0; i < 4 * np; i++) sum[i % 4] += w.data[i];
        printf("cover: vegetation %.1f %%, bare ground %.1f %%, rock %.1f %%, snow %.1f %%\n", 100.0 * sum[0] / np, 100.0 * sum[1] / np,
               100.0 * sum[2] / np, 100.0 * sum[3] / np);
    }
    tn_image_free(&snow);
    tn_image_free(&veg);
    tn_image_free(&w);
    tn_image_free(&shade);
    tn_image_free(&pv);
    return st;
}

/* The normal map and Unity RAW exports: images, not meshes. */
static tn_status export_image(struct export_args *a, const tn_image *dem)
{
    tn_status st;
    if (a->to == EXPORT_SPLAT) return export_splat(a, dem);
    if (a->to == EXPORT_UNITY_RAW) {
        float lo = 0, hi = 0;
        if (!(st = tn_export_unity_raw(a->out, dem, a->raw_size, &lo, &hi)))
            printf("heights: %.6g %.6g (set the Unity terrain height to %.6g m)\n", lo, hi, hi - lo);
    } else {
        tn_image n = {0, 0, 0, NULL};
        tn_save_opts so;
        memset(&so, 0, sizeof so);
        so.bit_depth = 8;
        st = tn_normal_map(&n, dem, a->mo.dx, a->mo.dy, a->mo.z_scale > 0 ? a->mo.z_scale : 1.0f, a->to == EXPORT_NORMAL_DX);
        if (!st) st = tn_image_save(a->out, &n, &so);
        tn_image_free(&n);
    }
    return st;
}

static int run_export(void)
{
    struct export_args *a = &export_arg;
    tn_image dem = {0, 0, 0, NULL}, tex = {0, 0, 0, NULL};
    tn_image_info info;
    tn_status st;
    int metres;
    if (a->texture && a->drape) return usage_error("export", "--texture and --preview-texture exclude each other");
    if ((st = load_dem_metres(a->in, a->range[0], a->range[1], &dem, &metres, &info))) return fail_status(st);
    if (!a->mo.dx && info.georef.dx > 0) { /* a GeoTIFF knows its pixel size in metres */
        a->mo.dx = (float)info.georef.dx;
        a->mo.dy = (float)info.georef.dy;
    }
    if ((a->to == EXPORT_GLB || a->to == EXPORT_OBJ) && !metres && !a->mo.dx)
        warn_unitless("export", a->in, "with no --spacing either, 1 m pixels: the mesh comes out nearly flat; give --spacing M too");
    if (a->texture) st = tn_image_load(&tex, a->texture, NULL);
    else if (a->drape) st = tn_render_preview(&tex, &dem, NULL);
    if (!st && a->to != EXPORT_GLB && a->to != EXPORT_OBJ) st = export_image(a, &dem);
    else if (!st) {
        a->mo.texture = tex.data ? &tex : NULL;
        st = a->to == EXPORT_GLB ? tn_export_glb(a->out, &dem, &a->mo) : tn_export_obj(a->out, &dem, &a->mo);
    }
    if (!st) printf("wrote %s (from %d x %d samples)\n", a->out, dem.width, dem.height);
    tn_image_free(&dem);
    tn_image_free(&tex);
    return st ? fail_status(st) : 0;
}

static const cli_command export_cmd = {"export", CLI_CMD(export), "a DEM for engines and 3D tools (glb, obj, normal/splat map, Unity RAW)",
    "Writes the DEM as a regular grid mesh in metres (y up; x east, z south) with normals and UVs: a glTF 2.0 binary (.glb, "
    "the texture embedded) or an OBJ (with <stem>.mtl and <stem>.png when textured); or as an 8-bit normal map PNG in the "
    "OpenGL or DirectX convention; or as a Unity terrain RAW; or as an 8-bit RGBA splat map (weights of vegetation, bare "
    "ground, rock and snow from slope and height, or from given masks; give --spacing in metres for a DEM in metres)."};

/* ---- noise ------------------------------------------------------------------------------- */

static struct noise_args {
    const char *out, *draw, *like;
    int w, h, explicit_noise;
    uint64_t seed;
    double weight, range_lo, range_hi;
    tn_perlin_opts po;
} noise_arg;
static const cli_opt noise_opts[] = {
    {"output", 'o', ARG_STR, REQ, &noise_arg.out, NULL, 0, 0, "OUT", "heightmap to write", NULL},
    {"type", 0, ARG_CHOICE, SET, &noise_arg.explicit_noise, NULL, 0, 0, "perlin|explicit",
     "Perlin fBm or explicit multi-scale smoothed noise", "perlin"},
    {"size", 0, ARG_INT, PAIR | OPT2 | SET, &noise_arg.w, &noise_arg.h, 1, 65536, "N [M]", "N x N, or N wide and M high", "512"},
    {"seed", 0, ARG_U64, SET, &noise_arg.seed, NULL, 0, 0, "S", "random seed", "1"},
    {"octaves", 0, ARG_INT, 0, &noise_arg.po.octaves, NULL, 0, NO_MAX, "N", "Perlin octaves", "8"},
    {"frequency", 0, ARG_FLOAT, 0, &noise_arg.po.frequency, NULL, 0, NO_MAX, "F", "Perlin cells across the width", "4"},
    {"lacunarity", 0, ARG_FLOAT, 0, &noise_arg.po.lacunarity, NULL, 0, NO_MAX, "L", "Perlin frequency factor per octave", "2"},
    {"gain", 0, ARG_FLOAT, 0, &noise_arg.po.gain, NULL, 0, NO_MAX, "G", "Perlin amplitude factor per octave", "0.5"},
    {"periodic", 0, ARG_FLAG, 0, &noise_arg.po.periodic, NULL, 0, 0, NULL, "Perlin tiles seamlessly", NULL},
    {"draw", 0, ARG_STR, 0, &noise_arg.draw, NULL, 0, 0, "MAP", "drawn grey map (resized to the output) blended in to steer the layout", NULL},
    {"draw-weight", 0, ARG_DOUBLE, SET, &noise_arg.weight, NULL, 0, 1, "W", "weight of the drawn map", "0.5"},
    {"range", 0, ARG_DOUBLE, PAIR | ORDERED, &noise_arg.range_lo, &noise_arg.range_hi, 0, 0, "LO HI",
     "heights in metres instead of [0, 1]", "[0, 1]"},
    {"like", 0, ARG_STR, 0, &noise_arg.like, NULL, 0, 0, "SOURCE",
     "pick the Perlin gain (0.45..0.9) whose slopes and spectrum are closest to the DEM SOURCE, a content map for `terrainnet style --style "
     "SOURCE` (prints the gain)", NULL},
};

static int run_noise(void)
{
    struct noise_args *a = &noise_arg;
    tn_image out = {0, 0, 0, NULL}, drawn = {0, 0, 0, NULL}, blended = {0, 0, 0, NULL};
    tn_explicit_opts eo;
    tn_save_opts so;
    tn_status st;
    memset(&eo, 0, sizeof eo);
    a->po.seed = eo.seed = a->seed;
    if (a->like) {
        tn_image src = {0, 0, 0, NULL};
        float gain = 0.0f;
        if (a->explicit_noise) return usage_error("noise", "--like picks a Perlin gain; it does not go with --type explicit");
        if (!(st = tn_image_load(&src, a->like, NULL))) st = tn_style_content_noise(&out, a->w, a->h, &src, &a->po, &gain);
        tn_image_free(&src);
        if (!st) printf("gain: %.2f\n", gain);
    } else {
        st = a->explicit_noise ? tn_noise_explicit(&out, a->w, a->h, &eo) : tn_noise_perlin(&out, a->w, a->h, &a->po);
    }
    if (st) return fail_status(st);
    if (a->draw) {
        if ((st = tn_image_load(&drawn, a->draw, NULL)) || (st = tn_noise_blend(&blended, &out, &drawn, (float)a->weight))) {
            tn_image_free(&out);
            tn_image_free(&drawn);
            return fail_status(st);
        }
        tn_image_free(&out);
        tn_image_free(&drawn);
        out = blended;
    }
    memset(&so, 0, sizeof so);
    if (a->range_hi > a->range_lo) {
        size_t i;
        for (i = 0; i < (size_t)a->w * a->h; i++) out.data[i] = (float)(a->range_lo + out.data[i] * (a->range_hi - a->range_lo));
        so.has_range = 1;
        so.range_lo = a->range_lo;
        so.range_hi = a->range_hi;
    }
    st = tn_image_save(a->out, &out, &so);
    tn_image_free(&out);
    return st ? fail_status(st) : 0;
}

static const cli_command noise_cmd = {"noise", CLI_CMD(noise), "procedural heightmap: Perlin fBm or explicit noise, optional drawn map",
    "Writes a procedural heightmap in [0, 1] (or metres with --range): Perlin fBm or explicit multi-scale smoothed noise, "
    "optionally blended with a drawn map."};

/* ---- sketches ---------------------------------------------------------------------------- */

/* Rasterises the set (16-bit PNG or float PFM by extension) and/or writes a preview. */
static tn_status write_sketch_images(const tn_contour_set *s, int w, int h, const char *raster, const char *preview,
                                     const char *dem_path)
{
    tn_image img = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL};
    tn_status st = TN_OK;
    if (raster) {
        tn_save_opts so;
        memset(&so, 0, sizeof so);
        so.bit_depth = 16;
        if ((st = tn_sketch_rasterise(&img, s, w, h)) || (st = tn_image_save(raster, &img, &so))) goto done;
        tn_image_free(&img);
    }
    if (preview) {
        if (dem_path && (st = tn_image_load(&dem, dem_path, NULL))) goto done;
        if ((st = tn_sketch_preview(&img, s, dem_path ? &dem : NULL, w, h))) goto done;
        st = tn_image_save(preview, &img, NULL);
    }
done:
    tn_image_free(&img);
    tn_image_free(&dem);
    return st;
}

static struct sketch_args { const char *in, *out, *preview, *tns, *dem; int w, h; } sketch_arg;
static const cli_opt sketch_opts[] = {
    {"IN.tns|IN.png", 0, ARG_POS, 0, &sketch_arg.in, NULL, 0, 0, NULL,
     "the sketch: .tns text, or a drawing (red strokes = ridges, blue = valleys, brighter = higher; thinned and traced to polylines)", NULL},
    {"output", 'o', ARG_STR, 0, &sketch_arg.out, NULL, 0, 0, "RASTER",
     "3-channel raster (ridge mask, valley mask, height): 16-bit PNG, or .pfm for floats", NULL},
    {"size", 0, ARG_INT, PAIR | OPT2, &sketch_arg.w, &sketch_arg.h, 2, TN_SKETCH_MAX_SIDE, "W [H]", "raster and preview size", "the sketch canvas"},
    {"preview", 0, ARG_STR, 0, &sketch_arg.preview, NULL, 0, 0, "PNG", "ridges yellow and valleys blue (over a hillshade of --dem if given)", NULL},
    {"dem", 0, ARG_STR, 0, &sketch_arg.dem, NULL, 0, 0, "DEM", "heightmap under the preview", NULL},
    {"tns", 0, ARG_STR, 0, &sketch_arg.tns, NULL, 0, 0, "OUT.tns", "the sketch as .tns text (e.g. to edit a traced drawing)", NULL},
};

static int run_sketch(void)
{
    struct sketch_args *a = &sketch_arg;
    tn_contour_set s = {0, 0, 0, NULL};
    int w = a->w, h = a->h;
    tn_status st;
    if (!a->out && !a->preview && !a->tns) return usage_error("sketch", "nothing to write: give -o, --preview or --tns");
    if ((st = tn_sketch_load(&s, a->in))) return fail_status(st);
    if (!w) { w = s.width; h = s.height; }
    st = a->tns ? tn_sketch_save(a->tns, &s) : TN_OK;
    if (!st) st = write_sketch_images(&s, w, h, a->out, a->preview, a->dem);
    if (!st) printf("%d polylines on a %d x %d canvas\n", s.count, s.width, s.height);
    tn_contour_set_free(&s);
    return st ? fail_status(st) : 0;
}

static const cli_command sketch_cmd = {"sketch", CLI_CMD(sketch), "read a .tns or drawn sketch; rasterise, preview or convert it",
    "Reads a sketch and writes it as a raster (-o), a preview and/or .tns text."};

static struct sketch_random_args { const char *in, *out, *preview; int w, h; tn_sketch_random_opts o; } sketch_random_arg;
static const cli_opt sketch_random_opts[] = {
    {"output", 'o', ARG_STR, REQ, &sketch_random_arg.out, NULL, 0, 0, "OUT.tns", "the enriched sketch", NULL},
    {"sketch", 0, ARG_STR, 0, &sketch_random_arg.in, NULL, 0, 0, "IN.tns|IN.png", "the sketch to enrich", "none, random lines only"},
    {"size", 0, ARG_INT, PAIR | OPT2, &sketch_random_arg.w, &sketch_random_arg.h, 2, TN_SKETCH_MAX_SIDE, "W [H]",
     "canvas size (required without --sketch)", "the sketch canvas"},
    {"seed", 0, ARG_U64, SET, &sketch_random_arg.o.seed, NULL, 0, 0, "S", "random seed", "1"},
    {"nodes", 0, ARG_INT, 0, &sketch_random_arg.o.nodes, NULL, 2, 8192, "N", "random ridge nodes", "W*H/1024 clamped to 8-2048"},
    {"preview", 0, ARG_STR, 0, &sketch_random_arg.preview, NULL, 0, 0, "PNG", "ridges yellow and valleys blue", NULL},
};

static int run_sketch_random(void)
{
    struct sketch_random_args *a = &sketch_random_arg;
    tn_contour_set user = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_status st;
    if (!a->w && !a->in) return usage_error("sketch-random", "give --size W [H] or --sketch");
    if (a->in && (st = tn_sketch_load(&user, a->in))) return fail_status(st);
    if (!a->w) {
        a->w = user.width;
        a->h = user.height;
    }
    st = tn_sketch_random(&out, a->in ? &user : NULL, a->w, a->h, &a->o);
    if (!st) st = tn_sketch_save(a->out, &out);
    if (!st && a->preview) st = write_sketch_images(&out, a->w, a->h, NULL, a->preview, NULL);
    if (!st) printf("%d polylines (%d from the sketch) on a %d x %d canvas\n", out.count, user.count, a->w, a->h);
    tn_contour_set_free(&user);
    tn_contour_set_free(&out);
    return st ? fail_status(st) : 0;
}

static const cli_command sketch_random_cmd = {"sketch-random", CLI_CMD(sketch_random), "enrich a sketch with random ridges and valleys (MST + Voronoi)",
    "Adds random ridges and valleys to a sketch (paper 000, section 5.2): N random nodes (heights 0.5-1) joined by a "
    "minimum spanning tree give ridges, the Voronoi vertices (heights 0-0.5) joined by another give valleys; edges "
    "crossing the sketch (or, for valleys, a kept ridge) are dropped. The output holds the sketch's own polylines first."};

static struct align_args { const char *sketch, *dem, *out, *parts_out; int cut_dem; tn_align_opts o; } align_arg;
static const cli_opt align_opts[] = {
    {"SKETCH", 0, ARG_POS, 0, &align_arg.sketch, NULL, 0, 0, NULL, "the sketch (.tns or drawn image)", NULL},
    {"DEMPARTS.tns", 0, ARG_POS, 0, &align_arg.dem, NULL, 0, 0, NULL, "the DEM's contour parts (one polyline per part, index = position)", NULL},
    {"output", 'o', ARG_STR, REQ, &align_arg.out, NULL, 0, 0, "MAP.txt", "the map: one line per sketch part, `SKETCH_PART DEM_PART`", NULL},
    {"seed", 0, ARG_U64, SET, &align_arg.o.seed, NULL, 0, 0, "S", "random seed of the cuts and picks", "1"},
    {"choices", 0, ARG_INT, 0, &align_arg.o.choices, NULL, 1, 64, "K", "random pick among the best K by height (1 = greedy)", "5"},
    {"cut-dem", 0, ARG_FLAG, 0, &align_arg.cut_dem, NULL, 0, 0, NULL, "DEMPARTS holds whole contours: cut them here with the same seed", NULL},
    {"parts-out", 0, ARG_STR, 0, &align_arg.parts_out, NULL, 0, 0, "PARTS.tns", "the sketch parts the map refers to", NULL},
};

static int run_align(void)
{
    struct align_args *a = &align_arg;
    char tmp_path[4096];
    tn_contour_set sk = {0, 0, 0, NULL}, dense = {0, 0, 0, NULL}, parts = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL},
                   demparts = {0, 0, 0, NULL};
    int *match = NULL, i;
    double t0;
    tn_status st;
    FILE *f;
    if ((st = tn_sketch_load(&sk, a->sketch)) || (st = tn_sketch_load(&dem, a->dem)) || (st = tn_sketch_densify(&dense, &sk)) ||
        (st = tn_contour_parts_make(&parts, &dense, a->o.seed)))
        goto done;
    if (a->cut_dem && (st = tn_contour_parts_make(&demparts, &dem, a->o.seed))) goto done;
    if (!(match = (int *)malloc(((size_t)parts.count + 1) * sizeof(int)))) { fprintf(stderr, "terrainnet: out of memory\n"); goto done; }
    t0 = tn_time_seconds();
    if ((st = tn_sketch_align(match, &parts, a->cut_dem ? &demparts : &dem, &a->o))) goto done;
    t0 = tn_time_seconds() - t0;
    if (a->parts_out && (st = tn_sketch_save(a->parts_out, &parts))) goto done;
    /* written beside the target and renamed over it, so a failed run leaves an old map intact */
    if (strlen(a->out) + 5 > sizeof tmp_path) { fprintf(stderr, "terrainnet: error: path too long: %s\n", a->out); st = TN_ERR_IO; goto done; }
    sprintf(tmp_path, "%s.tmp", a->out);
    if (!(f = fopen(tmp_path, "w"))) {
        fprintf(stderr, "terrainnet: error: cannot write %s\n", tmp_path);
        st = TN_ERR_IO;
        goto done;
    }
    fprintf(f, "# terrainnet align: sketch part -> DEM part (%d sketch parts, %d DEM parts, seed %llu)\n", parts.count,
            (a->cut_dem ? &demparts : &dem)->count, (unsigned long long)a->o.seed);
    for (i = 0; i < parts.count; i++) fprintf(f, "%d %d\n", i, match[i]);
    if (fclose(f) != 0 || rename(tmp_path, a->out) != 0) {
        fprintf(stderr, "terrainnet: error: write failed: %s\n", a->out);
        remove(tmp_path);
        st = TN_ERR_IO;
        goto done;
    }
    printf("aligned %d sketch parts to %d DEM parts in %.1f ms\n", parts.count, (a->cut_dem ? &demparts : &dem)->count, t0 * 1e3);
done:
    free(match);
    tn_contour_set_free(&sk);
    tn_contour_set_free(&dense);
    tn_contour_set_free(&parts);
    tn_contour_set_free(&dem);
    tn_contour_set_free(&demparts);
    if (st == TN_ERR_IO && !tn_last_error()[0]) return 1;
    return st ? fail_status(st) : (match ? 0 : 1);
}

static const cli_command align_cmd = {"align", CLI_CMD(align), "align sketch parts to a DEM's contour parts (chain codes + LCS)",
    "Cuts the sketch into 5-10 pixel parts and aligns each to a DEM contour part (paper 000, section 5.3: chain codes, "
    "rotation by k*pi/4, longest common substring, top 10, height mean/std, random pick among the best K)."};

/* ---- extract ----------------------------------------------------------------------------- */

/* Writes a w x h byte mask as an 8-bit PNG (0 / 255). */
static tn_status save_mask(const char *path, const uint8_t *m, int w, int h)
{
    tn_image img = {0, 0, 0, NULL};
    tn_save_opts so;
    tn_status st;
    size_t i;
    if ((st = tn_image_create(&img, w, h, 1))) return st;
    for (i = 0; i < (size_t)w * h; i++) img.data[i] = m[i] ? 1.0f : 0.0f;
    memset(&so, 0, sizeof so);
    so.bit_depth = 8;
    st = tn_image_save(path, &img, &so);
    tn_image_free(&img);
    return st;
}

static struct extract_args { const char *in, *tns, *preview, *valleys, *ridges, *acc; tn_extract_opts eo; } extract_arg;
static const cli_opt extract_opts[] = {
    {"DEM", 0, ARG_POS, 0, &extract_arg.in, NULL, 0, 0, NULL, "heightmap to analyse", NULL},
    {"output", 'o', ARG_STR, 0, &extract_arg.tns, NULL, 0, 0, "SKETCH.tns", "the ridge and valley polylines as a sketch", NULL},
    {"preview", 0, ARG_STR, 0, &extract_arg.preview, NULL, 0, 0, "PNG", "ridges yellow, valleys blue over a hillshade (paper Figure 6)", NULL},
    {"threshold", 0, ARG_INT, 0, &extract_arg.eo.threshold, NULL, 1, NO_MAX, "CELLS",
     "cells draining at least CELLS cells are valleys", "0.1 % of the map, at least 8"},
    {"valleys", 0, ARG_STR, 0, &extract_arg.valleys, NULL, 0, 0, "PNG",
     "binary valley mask (accumulation >= CELLS) before closing and thinning", NULL},
    {"ridges", 0, ARG_STR, 0, &extract_arg.ridges, NULL, 0, 0, "PNG", "binary ridge mask, the same on the inverted DEM", NULL},
    {"accumulation", 0, ARG_STR, 0, &extract_arg.acc, NULL, 0, 0, "FILE.pfm", "cells draining through each cell (valley flow), float", NULL},
    {"spacing", 0, ARG_FLOAT, PAIR | OPT2 | ABOVE, &extract_arg.eo.dx, &extract_arg.eo.dy, 0, NO_MAX, "DX [DY]",
     "pixel spacing in height units for the gradient filter", "1"},
};

static int run_extract(void)
{
    struct extract_args *a = &extract_arg;
    tn_image dem = {0, 0, 0, NULL};
    tn_extraction ex;
    tn_status st = TN_OK;
    int i, nv = 0, nr = 0;
    if ((st = tn_image_load(&dem, a->in, NULL))) return fail_status(st);
    if ((st = tn_extract(&ex, &dem, &a->eo))) {
        tn_image_free(&dem);
        return fail_status(st);
    }
    for (i = 0; i < ex.contours.count; i++) {
        if (ex.contours.items[i].type == TN_VALLEY) nv++;
        else nr++;
    }
    printf("size: %d x %d\nthreshold: %d\nvalley_contours: %d\nridge_contours: %d\n"
           "valley_max_strahler: %d\nridge_max_strahler: %d\n",
           ex.width, ex.height, ex.threshold, nv, nr, ex.valley_max_order, ex.ridge_max_order);
    if (!st && a->tns) st = tn_sketch_save(a->tns, &ex.contours);
    if (!st && a->valleys) st = save_mask(a->valleys, ex.valley_mask, ex.width, ex.height);
    if (!st && a->ridges) st = save_mask(a->ridges, ex.ridge_mask, ex.width, ex.height);
    if (!st && a->acc) {
        tn_image acc = {0, 0, 0, NULL};
        if (!(st = tn_image_create(&acc, ex.width, ex.height, 1))) {
            size_t k;
            for (k = 0; k < (size_t)ex.width * ex.height; k++) acc.data[k] = (float)ex.valley_flow.acc[k];
            st = tn_image_save(a->acc, &acc, NULL);
            tn_image_free(&acc);
        }
    }
    if (!st && a->preview) {
        tn_image pv = {0, 0, 0, NULL};
        if (!(st = tn_sketch_preview(&pv, &ex.contours, &dem, dem.width, dem.height))) {
            tn_save_opts so;
            memset(&so, 0, sizeof so);
            so.bit_depth = 8;
            st = tn_image_save(a->preview, &pv, &so);
            tn_image_free(&pv);
        }
    }
    tn_extraction_free(&ex);
    tn_image_free(&dem);
    return st ? fail_status(st) : 0;
}

static const cli_command extract_cmd = {"extract", CLI_CMD(extract), "ridge and valley network of a DEM: masks, accumulation, preview",
    "Extracts the ridge and valley network of a DEM (paper 000, section 4.1): priority-flood depression filling, D8 flow, "
    "flow accumulation; cells draining at least CELLS cells are valleys, the same on the inverted DEM gives ridges. Then "
    "closing, Strahler order, thinning to 1-px lines, dropping dangling lines under 10 px and the flattest 1 %, splitting "
    "at 48 px. Prints a summary (name: value lines)."};

/* ---- realism ----------------------------------------------------------------------------- */

static struct realism_args { const char *path[2]; double range[2][2]; tn_realism_opts ro; } realism_arg;
static const cli_opt realism_opts[] = {
    {"REFERENCE", 0, ARG_POS, 0, &realism_arg.path[0], NULL, 0, 0, NULL, "the terrain to compare with (e.g. a generator's example)", NULL},
    {"TERRAIN", 0, ARG_POS, 0, &realism_arg.path[1], NULL, 0, 0, NULL, "the terrain to judge", NULL},
    {"spacing", 0, ARG_FLOAT, PAIR | OPT2 | ABOVE, &realism_arg.ro.dx_a, &realism_arg.ro.dy_a, 0, NO_MAX, "DX [DY]",
     "REFERENCE's pixel size in height units", "1"},
    {"spacing-b", 0, ARG_FLOAT, PAIR | OPT2 | ABOVE, &realism_arg.ro.dx_b, &realism_arg.ro.dy_b, 0, NO_MAX, "DX [DY]",
     "TERRAIN's pixel size in height units", "REFERENCE's"},
    {"range-a", 0, ARG_DOUBLE, PAIR | ORDERED, &realism_arg.range[0][0], &realism_arg.range[0][1], 0, 0, "LO HI",
     "heights of a [0, 1] REFERENCE (PNG without a recorded range)", "as stored"},
    {"range-b", 0, ARG_DOUBLE, PAIR | ORDERED, &realism_arg.range[1][0], &realism_arg.range[1][1], 0, 0, "LO HI",
     "heights of a [0, 1] TERRAIN", "as stored"},
    {"threshold", 0, ARG_INT, 0, &realism_arg.ro.threshold, NULL, 1, NO_MAX, "CELLS",
     "valley threshold for drainage density and bifurcation", "by size"},
};

static int run_realism(void)
{
    struct realism_args *a = &realism_arg;
    tn_image img[2] = {{0, 0, 0, NULL}, {0, 0, 0, NULL}};
    tn_realism r;
    tn_status st;
    int k;
    for (k = 0; k < 2; k++) {
        if ((st = tn_image_load(&img[k], a->path[k], NULL))) {
            tn_image_free(&img[0]);
            return fail_status(st);
        }
        if (a->range[k][1] > a->range[k][0]) {
            size_t i, n = (size_t)img[k].width * img[k].height * img[k].channels;
            for (i = 0; i < n; i++) img[k].data[i] = (float)(a->range[k][0] + img[k].data[i] * (a->range[k][1] - a->range[k][0]));
        }
    }
    st = tn_realism_compare(&r, &img[0], &img[1], &a->ro);
    tn_image_free(&img[0]);
    tn_image_free(&img[1]);
    if (st) return fail_status(st);
    printf("slope_distance: %.6f\ncurvature_distance: %.6f\nspectrum_distance: %.6f\n"
           "spectrum_slope_a: %.4f\nspectrum_slope_b: %.4f\ndrainage_density_a: %.6f\ndrainage_density_b: %.6f\n"
           "bifurcation_ratio_a: %.4f\nbifurcation_ratio_b: %.4f\n",
           r.slope_distance, r.curvature_distance, r.spectrum_distance, r.spectrum_slope_a, r.spectrum_slope_b,
           r.drainage_density_a, r.drainage_density_b, r.bifurcation_ratio_a, r.bifurcation_ratio_b);
    if (isfinite(r.ssim)) printf("ssim: %.6f\npsnr: %.4f\n", r.ssim, r.psnr);
    else printf("ssim: n/a (sizes differ)\npsnr: n/a (sizes differ)\n"); /* pixel by pixel needs one size */
    printf("distance: %.6f\n", r.distance);
    return 0;
}

static const cli_command realism_cmd = {"realism", CLI_CMD(realism), "realism report: slope/curvature/spectrum distances, drainage, SSIM",
    "Realism report of TERRAIN against REFERENCE, one `name: value` line per figure: slope and curvature (Laplacian) "
    "histogram distances (earth mover's distance / the reference's mean, 0 = same distribution), distance of the radially "
    "averaged power spectra (RMS of log10 ratios) and each spectrum's log-log slope, drainage density and Strahler "
    "bifurcation ratio of each, SSIM and PSNR (same size only, else nan), and `distance`, the mean of the relative "
    "differences (0 = identical). Heights must share units."};

/* ---- style -------------------------------------------------------------------------------- */

static struct style_args {
    const char *out, *content, *style, *weights;
    int size, no_drain, optimizer;
    tn_style_opts so;
} style_arg;
static const cli_opt style_opts[] = {
    {"content", 0, ARG_STR, REQ, &style_arg.content, NULL, 0, 0, "IN", "the map to restyle (e.g. from `terrainnet noise`)", NULL},
    {"style", 0, ARG_STR, REQ, &style_arg.style, NULL, 0, 0, "SOURCE", "the heightmap whose morphology and height units the output takes", NULL},
    {"output", 'o', ARG_STR, REQ, &style_arg.out, NULL, 0, 0, "OUT", "the restyled heightmap", NULL},
    {"iters", 0, ARG_INT, 0, &style_arg.so.iters, NULL, 1, 1000000, "N", "iterations per pyramid level", "L-BFGS 40, Adam 150, SGD 300"},
    {"optimizer", 0, ARG_CHOICE, SET, &style_arg.optimizer, NULL, 0, 0, "lbfgs|sgd|adam", "optimiser", "lbfgs"},
    {"weights", 0, ARG_STR, 0, &style_arg.weights, NULL, 0, 0, "vgg19.tnw",
     "VGG-19 weights (examples/vgg19_to_tnw.py makes them), with the paper's layers and loss weights", "the built-in random-feature network"},
    {"size", 0, ARG_INT, 0, &style_arg.size, NULL, 16, 1000000, "N", "output N x N (the content resized)", "the content's size"},
    {"levels", 0, ARG_INT, 0, &style_arg.so.levels, NULL, 1, 1000000, "N", "pyramid levels", "down to 64 px, 32 px with the drainage terms"},
    {"seed", 0, ARG_U64, 0, &style_arg.so.seed, NULL, 1, 1000000, "S", "seed of the built-in network's random filters", "0"},
    {"lr", 0, ARG_FLOAT, 0, &style_arg.so.lr, NULL, 0, 0, "R", "SGD / Adam learning rate", "by optimiser and network"},
    {"content-weight", 0, ARG_FLOAT, 0, &style_arg.so.content_weight, NULL, 0, 0, "A", "content term weight (alpha)", "0"},
    {"style-weight", 0, ARG_FLOAT, 0, &style_arg.so.style_weight, NULL, 0, 0, "B", "Gram term weight (beta)", "0"},
    {"sw-weight", 0, ARG_FLOAT, 0, &style_arg.so.sw_weight, NULL, 0, 0, "W", "sliced Wasserstein term weight (built-in net)", "0"},
    {"hist-weight", 0, ARG_FLOAT, 0, &style_arg.so.hist_weight, NULL, 0, 0, "H", "height and slope histogram terms weight (built-in net)", "0"},
    {"tv-weight", 0, ARG_FLOAT, 0, &style_arg.so.tv_weight, NULL, 0, 0, "G", "total variation term weight (gamma)", "0"},
    {"drain-weight", 0, ARG_FLOAT, 0, &style_arg.so.drain_weight, NULL, 0, 0, "D",
     "closed basins as deep as the source's (built-in net)", "10 for fluvial sources (under 5 % in closed basins), else off"},
    {"valley-weight", 0, ARG_FLOAT, 0, &style_arg.so.valley_weight, NULL, 0, 0, "V",
     "valleys carved as deep as the source's for the same drainage area (built-in net)", "1 for fluvial sources, else off"},
    {"no-drain", 0, ARG_FLAG, 0, &style_arg.no_drain, NULL, 0, 0, NULL, "drainage terms off (--drain-weight -1 --valley-weight -1)", NULL},
};

static int run_style(void)
{
    struct style_args *a = &style_arg;
    tn_image content = {0, 0, 0, NULL}, style = {0, 0, 0, NULL}, out = {0, 0, 0, NULL}, tmp = {0, 0, 0, NULL};
    tn_params *vgg = NULL;
    tn_status st;
    double t0;
    a->so.optimizer = a->optimizer == 1 ? TN_STYLE_SGD : a->optimizer == 2 ? TN_STYLE_ADAM : TN_STYLE_LBFGS;
    if (a->no_drain) a->so.drain_weight = a->so.valley_weight = -1.0f;
    if ((st = tn_image_load(&content, a->content, NULL))) return fail_status(st);
    if ((st = tn_image_load(&style, a->style, NULL))) goto done;
    if (a->size && (st = tn_image_resize(&tmp, &content, a->size, a->size, TN_RESIZE_BICUBIC))) goto done;
    if (a->size) {
        tn_image_free(&content);
        content = tmp;
        tmp.data = NULL;
    }
    if (a->weights && (st = tn_vgg19_load(&vgg, a->weights))) goto done;
    a->so.vgg = vgg;
    t0 = tn_time_seconds();
    if ((st = tn_style_transfer(&out, &content, &style, &a->so))) goto done;
    fprintf(stderr, "style: %d x %d in %.1f s (%s network)\n", out.width, out.height, tn_time_seconds() - t0,
            vgg ? "VGG-19" : "built-in");
    st = tn_image_save(a->out, &out, NULL);
done:
    tn_image_free(&content);
    tn_image_free(&style);
    tn_image_free(&out);
    tn_image_free(&tmp);
    tn_params_free(vgg);
    return st ? fail_status(st) : 0;
}

static const cli_command style_cmd = {"style", CLI_CMD(style), "restyle a map with the morphology of a real heightmap (style transfer)",
    "Restyles the content map with the morphology of the SOURCE heightmap (see README). The output has the content's size "
    "and the source's height units. Loss weights: 0 = the network's default, negative = term off. The drainage terms are "
    "on by default for fluvial sources and off for dunes, craters and karst."};

/* ---- texture GAN and detail maps ---------------------------------------------------------- */

static struct texgan_train_args { const char *in, *out, *normal, *ckpt; double feat_weight; tn_texgan_opts o; } texgan_train_arg;
static const cli_opt texgan_train_opts[] = {
    {"EXEMPLAR", 0, ARG_POS, 0, &texgan_train_arg.in, NULL, 0, 0, NULL, "the texture photo to learn", NULL},
    {"output", 'o', ARG_STR, REQ, &texgan_train_arg.out, NULL, 0, 0, "MODEL.tnw", "the model: EMA generator + architecture", NULL},
    {"minutes", 0, ARG_DOUBLE, 0, &texgan_train_arg.o.train.minutes, NULL, 0, 1e9, "M", "wall-clock budget of the whole run, resumed time included", "15"},
    {"iters", 0, ARG_LONG, 0, &texgan_train_arg.o.train.max_iters, NULL, 0, 1e9, "N", "stop after N iterations in total", "0 = only the time budget"},
    {"resume", 0, ARG_FLAG, 0, &texgan_train_arg.o.train.resume, NULL, 0, 0, NULL, "continue the checkpoint identically", NULL},
    {"checkpoint", 0, ARG_STR, 0, &texgan_train_arg.ckpt, NULL, 0, 0, "PATH", "full training state, saved atomically", "MODEL.tnw.ckpt"},
    {"checkpoint-seconds", 0, ARG_DOUBLE, 0, &texgan_train_arg.o.train.checkpoint_seconds, NULL, 0, 1e9, "S",
     "checkpoint interval (a killed run loses at most one)", "60"},
    {"normal", 0, ARG_STR, 0, &texgan_train_arg.normal, NULL, 0, 0, "MAP", "normal map stacked as channels 4-6 (the exemplar's size)", NULL},
    {"seed", 0, ARG_U64, 0, &texgan_train_arg.o.train.seed, NULL, 0, 0, "S", "random seed", "0"},
    {"patch", 0, ARG_INT, 0, &texgan_train_arg.o.patch, NULL, 0, 1e9, "N", "training patch side in pixels", "64"},
    {"batch", 0, ARG_INT, 0, &texgan_train_arg.o.batch, NULL, 0, 1e9, "N", "patches per step", "4"},
    {"gen-width", 0, ARG_INT, 0, &texgan_train_arg.o.gen_width, NULL, 0, 1e9, "N", "channels of the first generator stage, halving per stage", "64"},
    {"disc-width", 0, ARG_INT, 0, &texgan_train_arg.o.disc_width, NULL, 0, 1e9, "N", "channels of the first discriminator layer", "32"},
    {"disc-layers", 0, ARG_INT, 0, &texgan_train_arg.o.disc_layers, NULL, 0, 1e9, "N", "stride-2 discriminator layers", "3"},
    {"stages", 0, ARG_INT, 0, &texgan_train_arg.o.stages, NULL, 0, 1e9, "N", "generator stages: one noise cell = 2^N pixels", "4"},
    {"scale", 0, ARG_INT, 0, &texgan_train_arg.o.scale, NULL, 0, 1e9, "S",
     "learn the exemplar downscaled by S (features S times larger, e.g. crack cells) and upsample", "1"},
    {"augment", 0, ARG_FLAG, 0, &texgan_train_arg.o.augment, NULL, 0, 0, NULL,
     "flip/transpose real patches (small exemplars without a light direction)", NULL},
    {"local", 0, ARG_INT, 0, &texgan_train_arg.o.noise_local, NULL, 0, 1e9, "N", "local noise dims per cell", "16"},
    {"global", 0, ARG_INT, 0, &texgan_train_arg.o.noise_global, NULL, 0, 1e9, "N", "noise dims constant over one image", "0"},
    {"periodic", 0, ARG_INT, 0, &texgan_train_arg.o.noise_periodic, NULL, 0, 1e9, "N", "periodic (sin) noise channels", "0"},
    {"feat-weight", 0, ARG_DOUBLE, SET, &texgan_train_arg.feat_weight, NULL, 0, 1e9, "W",
     "weight of the feature-statistics term of the generator loss (0 = off)", "1"},
    {"nearest", 0, ARG_FLAG, 0, &texgan_train_arg.o.nearest, NULL, 0, 0, NULL,
     "the first design: nearest upsampling, no per-pixel stage noise", NULL},
};

static int run_texgan_train(void)
{
    struct texgan_train_args *a = &texgan_train_arg;
    tn_image ex = {0, 0, 0, NULL}, nrm = {0, 0, 0, NULL};
    tn_texgan model;
    tn_texgan_stats s;
    tn_status st;
    char ckbuf[1024];
    a->o.feat_weight = a->feat_weight > 0 ? (float)a->feat_weight : -1.0f;
    if (!a->ckpt) {
        snprintf(ckbuf, sizeof ckbuf, "%s.ckpt", a->out);
        a->ckpt = ckbuf;
    }
    a->o.train.checkpoint = a->ckpt;
    train_budget_cap(&a->o.train);
    if ((st = tn_image_load(&ex, a->in, NULL))) return fail_status(st);
    if (a->normal) {
        tn_image both = {0, 0, 0, NULL};
        size_t i, n = (size_t)ex.width * ex.height;
        int c;
        if ((st = tn_image_load(&nrm, a->normal, NULL))) { tn_image_free(&ex); return fail_status(st); }
        if (nrm.width != ex.width || nrm.height != ex.height || ex.channels + nrm.channels > TN_TEXGAN_MAX_CHANNELS) {
            tn_image_free(&ex);
            tn_image_free(&nrm);
            fprintf(stderr, "terrainnet texgan-train: the normal map must have the exemplar's size\n");
            return 1;
        }
        if ((st = tn_image_create(&both, ex.width, ex.height, ex.channels + nrm.channels))) { tn_image_free(&ex); tn_image_free(&nrm); return fail_status(st); }
        for (i = 0; i < n; i++)
            for (c = 0; c < both.channels; c++)
                both.data[i * both.channels + c] = c < ex.channels ? ex.data[i * ex.channels + c] : nrm.data[i * nrm.channels + c - ex.channels];
        tn_image_free(&ex);
        tn_image_free(&nrm);
        ex = both;
    }
    st = tn_texgan_train(&model, &ex, &a->o, &s);
    tn_image_free(&ex);
    if (st == TN_ERR_CANCELLED) return train_interrupted("texgan-train", s.iterations, a->ckpt);
    if (st) return fail_status(st);
    st = tn_texgan_save(a->out, &model);
    if (!st)
        printf("iterations: %ld (resumed at %ld)\ntrain_minutes: %.2f\nseconds_per_iteration: %.4f\nloss_d: %.4f\nloss_g: %.4f\n"
               "checkpoints: %d (%s)\nmodel: %s\n",
               s.iterations, s.resumed_from, s.seconds / 60.0, s.seconds_per_iter, (double)s.loss_d, (double)s.loss_g, s.checkpoints, a->ckpt, a->out);
    if (!st) checkpoint_warning("texgan-train", s.iterations, s.resumed_from, s.checkpoints, a->ckpt);
    tn_texgan_free(&model);
    return st ? fail_status(st) : 0;
}

static const cli_command texgan_train_cmd = {"texgan-train", CLI_CMD(texgan_train), "train a spatial GAN on one texture photo (checkpoints, resume)",
    "Trains a spatial GAN (PSGAN-style, spectral-norm + hinge) on random patches of one texture photo and writes the "
    "model. The full training state is saved atomically to the checkpoint every interval, so a killed run loses at most "
    "one; --resume continues it identically."};

static struct texgan_synth_args { const char *in, *out; int w, h, colour; uint64_t seed; } texgan_synth_arg;
static const cli_opt texgan_synth_opts[] = {
    {"MODEL.tnw", 0, ARG_POS, 0, &texgan_synth_arg.in, NULL, 0, 0, NULL, "a model from texgan-train", NULL},
    {"size", 0, ARG_WXH, REQ, &texgan_synth_arg.w, &texgan_synth_arg.h, 1, 1 << 20, "WxH", "texture size, e.g. 8192x8192", NULL},
    {"output", 'o', ARG_STR, REQ, &texgan_synth_arg.out, NULL, 0, 0, "OUT", "texture to write (.pfm/.ppm/.pgm streamed band by band)", NULL},
    {"seed", 0, ARG_U64, SET, &texgan_synth_arg.seed, NULL, 0, 0, "S", "random seed: the same seed gives the same bytes on any machine", "1"},
    {"colour-correct", 0, ARG_FLAG, 0, &texgan_synth_arg.colour, NULL, 0, 0, NULL,
     "shift the mean colour to the exemplar's (measured on a 1024 px window)", NULL},
};

static int run_texgan_synth(void)
{
    struct texgan_synth_args *a = &texgan_synth_arg;
    tn_texgan model;
    tn_status st;
    double t0;
    float shift[TN_TEXGAN_MAX_CHANNELS];
    if ((st = tn_texgan_load(&model, a->in))) return fail_status(st);
    t0 = tn_time_seconds();
    if (a->colour) {
        tn_image probe = {0, 0, 0, NULL};
        st = tn_texgan_synthesize_window(&probe, &model, a->seed, 0, 0, a->w < 1024 ? a->w : 1024, a->h < 1024 ? a->h : 1024);
        if (!st) st = tn_texture_colour_shift(shift, &probe, model.mean, model.lo, model.hi);
        tn_image_free(&probe);
    }
    if (!st) st = tn_texgan_synthesize_file(a->out, &model, a->seed, a->w, a->h, a->colour ? shift : NULL);
    if (!st) printf("synthesised %d x %d in %.2f s -> %s\n", a->w, a->h, tn_time_seconds() - t0, a->out);
    tn_texgan_free(&model);
    return st ? fail_status(st) : 0;
}

static const cli_command texgan_synth_cmd = {"texgan-synth", CLI_CMD(texgan_synth), "synthesise a texture of any size from a model, streamed tile by tile",
    "Synthesises a texture of any size from a trained model, tile by tile (2 noise cells of overlap, cropped and "
    "stitched; memory is one band of tiles). .pfm/.ppm/.pgm outputs are streamed to disk band by band; other formats "
    "(.png) are built in memory and saved whole. Channels beyond 3 go to OUT.ch3-5.EXT."};

static int is_tnw_file(const char *path)
{
    FILE *f = fopen(path, "rb");
    char m[4] = {0, 0, 0, 0};
    int ok;
    if (!f) return 0;
    ok = fread(m, 1, 4, f) == 4 && !memcmp(m, "TNW1", 4);
    fclose(f);
    return ok;
}

static struct detail_maps_args {
    const char *src, *exemplar, *prefix, *compose, *preview, *dem;
    int w, h;
    uint64_t seed;
    tn_detail_opts o;
} detail_maps_arg;
static const cli_opt detail_maps_opts[] = {
    {"MODEL_OR_SYNTH", 0, ARG_POS, 0, &detail_maps_arg.src, NULL, 0, 0, NULL,
     "a texgan model (synthesised band by band) or a synthesised image", NULL},
    {"EXEMPLAR", 0, ARG_POS, 0, &detail_maps_arg.exemplar, NULL, 0, 0, NULL, "the texture photo the model learnt", NULL},
    {"output", 'o', ARG_STR, REQ, &detail_maps_arg.prefix, NULL, 0, 0, "PREFIX",
     "writes PREFIX_low.png, PREFIX_high.png and PREFIX_detail.txt", NULL},
    {"size", 0, ARG_WXH, 0, &detail_maps_arg.w, &detail_maps_arg.h, 1, 1 << 20, "WxH",
     "texture size from a model, e.g. 4096x4096", "8x the exemplar; a SYNTH image's own size"},
    {"seed", 0, ARG_U64, SET, &detail_maps_arg.seed, NULL, 0, 0, "S", "synthesis seed", "1"},
    {"factor", 0, ARG_INT, 0, &detail_maps_arg.o.factor, NULL, 1, 4096, "F", "low map downsampling (F = 10: 100x less memory)", "10"},
    {"sigma", 0, ARG_FLOAT, 0, &detail_maps_arg.o.sigma, NULL, 0, 1e9, "S", "Gaussian split sigma in pixels", "F/2"},
    {"no-colour", 0, ARG_FLAG, 0, &detail_maps_arg.o.no_colour_correct, NULL, 0, 0, NULL, "keep the synthesis' own mean colour", NULL},
    {"compose", 0, ARG_STR, 0, &detail_maps_arg.compose, NULL, 0, 0, "OUT",
     "the full-resolution texture as a shader would rebuild it (at --size)", NULL},
    {"preview", 0, ARG_STR, 0, &detail_maps_arg.preview, NULL, 0, 0, "OUT.png",
     "naive tiling vs detail mapping, far and near, over a hillshaded terrain", NULL},
    {"dem", 0, ARG_STR, 0, &detail_maps_arg.dem, NULL, 0, 0, "DEM", "the terrain under the preview", "a built-in one"},
};

static int run_detail_maps(void)
{
    struct detail_maps_args *a = &detail_maps_arg;
    tn_image ex = {0, 0, 0, NULL}, synth = {0, 0, 0, NULL}, img = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL};
    tn_detail_maps maps;
    tn_texgan model;
    tn_status st;
    if ((st = tn_image_load(&ex, a->exemplar, NULL))) return fail_status(st);
    if (is_tnw_file(a->src)) {
        if (!(st = tn_texgan_load(&model, a->src))) {
            if (!a->w) { a->w = 8 * ex.width; a->h = 8 * ex.height; }
            st = tn_detail_maps_from_model(&maps, &model, a->seed, a->w, a->h, &ex, &a->o);
            tn_texgan_free(&model);
        }
    } else {
        if (!(st = tn_image_load(&synth, a->src, NULL))) st = tn_detail_maps_from_image(&maps, &synth, &ex, &a->o);
        tn_image_free(&synth);
        if (!a->w && !st) { a->w = maps.width; a->h = maps.height; }
    }
    if (st) { tn_image_free(&ex); return fail_status(st); }
    st = tn_detail_maps_save(a->prefix, &maps);
    if (!st)
        printf("texture: %d x %d\nlow map: %d x %d (factor %d, %.0fx less memory)\nhigh map: %d x %d, tiled %.3f x %.3f\n", maps.width,
               maps.height, maps.low.width, maps.low.height, maps.factor,
               (double)maps.width * maps.height / ((double)maps.low.width * maps.low.height), maps.high.width, maps.high.height,
               (double)maps.tiling_x, (double)maps.tiling_y);
    if (!st && a->compose) {
        tn_save_opts so;
        memset(&so, 0, sizeof so);
        so.bit_depth = 8;
        st = tn_detail_compose(&img, &maps, a->w, a->h);
        if (!st) st = tn_image_save(a->compose, &img, &so);
        tn_image_free(&img);
    }
    if (!st && a->preview) {
        if (a->dem) st = tn_image_load(&dem, a->dem, NULL);
        if (!st) st = tn_detail_preview(&img, &maps, &ex, a->dem ? &dem : NULL, 0);
        if (!st) st = tn_image_save(a->preview, &img, NULL);
        tn_image_free(&img);
        tn_image_free(&dem);
    }
    tn_detail_maps_free(&maps);
    tn_image_free(&ex);
    return st ? fail_status(st) : 0;
}

static const cli_command detail_maps_cmd = {"detail-maps", CLI_CMD(detail_maps), "low/high detail maps (+ composed texture, tiling preview)",
    "Writes PREFIX_low.png (16-bit: Gaussian low-pass of the colour-corrected synthesis, downsampled by F), "
    "PREFIX_high.png (8-bit: exemplar minus its Gaussian blur, as value/2 + 0.5) and PREFIX_detail.txt (texture size, "
    "tiling factor, F, sigma, value range)."};

/* ---- world ------------------------------------------------------------------------------- */

static struct world_args {
    const char *spec, *dir, *tiles, *part;
    int tile, no_index;
} world_arg;
static const cli_opt world_opts[] = {
    {"SPEC", 0, ARG_POS, 0, &world_arg.spec, NULL, 0, 0, NULL, "the world: size, seed, height range, generator and operations (docs/world.md)", NULL},
    {"output", 'o', ARG_STR, REQ, &world_arg.dir, NULL, 0, 0, "DIR", "tiles DIR/r{row}_c{col}.png, DIR/world.vrt, DIR/manifest.txt (created if missing)", NULL},
    {"tiles", 0, ARG_STR, 0, &world_arg.tiles, NULL, 0, 0, "I0:I1,J0:J1", "only tile rows I0..I1-1 and columns J0..J1-1", "all"},
    {"tile", 0, ARG_INT, 0, &world_arg.tile, NULL, 16, 65536, "N", "tile side in pixels", "the SPEC's, else 1024"},
    {"part", 0, ARG_STR, 0, &world_arg.part, NULL, 0, 0, "K/N", "only every N-th selected tile from the K-th (K = 0..N-1): one of N processes", "0/1"},
    {"no-index", 0, ARG_FLAG, 0, &world_arg.no_index, NULL, 0, 0, NULL, "skip world.vrt and manifest.txt (a last run without it writes them)", NULL},
};

static int run_world(void)
{
    struct world_args *a = &world_arg;
    tn_world w;
    tn_world_opts wo;
    tn_world_run_opts ro;
    tn_world_run_stats s;
    tn_status st;
    int present = 0, n = 0;
    memset(&wo, 0, sizeof wo);
    memset(&ro, 0, sizeof ro);
    wo.tile = a->tile;
    if (a->tiles && (sscanf(a->tiles, "%d:%d,%d:%d%n", &ro.row0, &ro.row1, &ro.col0, &ro.col1, &n) != 4 || a->tiles[n] ||
                     ro.row1 <= ro.row0 || ro.col1 <= ro.col0 || ro.row0 < 0 || ro.col0 < 0))
        return usage_error("world", "--tiles needs I0:I1,J0:J1 with I0 < I1 and J0 < J1 (e.g. 0:4,2:3), not %s", a->tiles);
    if (a->part && (sscanf(a->part, "%d/%d%n", &ro.part, &ro.parts, &n) != 2 || a->part[n] || ro.parts < 1 || ro.part < 0 || ro.part >= ro.parts))
        return usage_error("world", "--part needs K/N with 0 <= K < N (e.g. 1/4), not %s", a->part);
    if ((st = tn_world_load(&w, a->spec, &wo))) return fail_status(st);
#if !defined(_WIN32)
    mkdir(a->dir, 0777); /* an existing one is fine; a failure shows when the first file is written */
#endif
    printf("world: %d x %d x %d %s, %d x %d tiles of %d px, halo %d px\n", w.out_width, w.out_height, w.out_channels,
           w.out_heights ? "heights (16-bit, metres)" : "values (8-bit)", w.rows, w.cols, w.tile, w.halo);
    if (!(st = tn_world_write_tiles(a->dir, &w, &ro, &s))) {
        printf("tiles: %d written, %d already there, %.2f s (%.3f tiles/s)\n", s.written, s.skipped, s.seconds,
               s.seconds > 0 ? s.written / s.seconds : 0.0);
        if (!a->no_index && !(st = tn_world_write_index(a->dir, &w, &present)))
            printf("index: %s/world.vrt, %s/manifest.txt (%d of %d tiles present)\n", a->dir, a->dir, present, w.rows * w.cols);
    }
    tn_world_free(&w);
    return st ? fail_status(st) : 0;
}

static const cli_command world_cmd = {"world", CLI_CMD(world), "a world of any size in tiles equal to a whole-map run (PNG tiles + GDAL VRT)",
    "SPEC lines: `world W H` (pixels), `seed N`, `height LO HI` (metres of value 0 and 1; the 16-bit range of every tile), "
    "`cellsize M`, `tile N`, then a generator (perlin, explicit, texgan model=F.tnw, singan model=F.tnw, gnn model=F.tnw sketch=S.tns) "
    "and local operations (singan-refine model=F.tnw, season koppen=CODE|climate=F.csv distance=M, kpd model=F.tnw koppen=CODE|climate=F.csv, "
    "blur, hillshade, normalmap, detail), "
    "each `name key=value ...`. Every tile is exactly the pixels a whole-map run has there, so any subset "
    "can be computed alone, in any order, on any machine; tiles already in DIR are skipped (resume), files appear atomically. "
    "Methods that are not local (style, fill, flow, extract) are refused with the reason. See docs/world.md."};

/* ---- SinGAN: random terrain, refinement, upscaling ---------------------------------------- */

static struct singan_train_args { const char *in, *out, *ckpt; double range[2]; tn_singan_opts o; } singan_train_arg;
static const cli_opt singan_train_opts[] = {
    {"DEM", 0, ARG_POS, 0, &singan_train_arg.in, NULL, 0, 0, NULL, "the example heightmap (channel 0; heights kept in its units)", NULL},
    {"output", 'o', ARG_STR, REQ, &singan_train_arg.out, NULL, 0, 0, "MODEL.tnw", "the model: one generator per scale + the height mapping", NULL},
    {"range", 0, ARG_DOUBLE, PAIR | ORDERED, &singan_train_arg.range[0], &singan_train_arg.range[1], 0, 0, "LO HI",
     "metres that codes 0..max of an 8/16-bit DEM without a recorded range stand for (samples then come out in metres)",
     "the file's range, else its [0, 1] codes"},
    {"heights", 0, ARG_DOUBLE, PAIR | ORDERED | HIDDEN, &singan_train_arg.range[0], &singan_train_arg.range[1], 0, 0, "LO HI", "--range", NULL},
    {"minutes", 0, ARG_DOUBLE, 0, &singan_train_arg.o.train.minutes, NULL, 0, 1e9, "M", "wall-clock budget of the whole run, shared by the scales", "10"},
    {"iters", 0, ARG_LONG, 0, &singan_train_arg.o.train.max_iters, NULL, 0, 1e9, "N", "stop after N iterations in total (N / scales per scale)", "0 = only the time budget"},
    {"scale-iters", 0, ARG_INT, 0, &singan_train_arg.o.iters, NULL, 0, 1e9, "N", "iterations per scale at most", "2000"},
    {"resume", 0, ARG_FLAG, 0, &singan_train_arg.o.train.resume, NULL, 0, 0, NULL, "continue the checkpoint identically", NULL},
    {"checkpoint", 0, ARG_STR, 0, &singan_train_arg.ckpt, NULL, 0, 0, "PATH", "full training state, saved atomically", "MODEL.tnw.ckpt"},
    {"checkpoint-seconds", 0, ARG_DOUBLE, 0, &singan_train_arg.o.train.checkpoint_seconds, NULL, 0, 1e9, "S", "checkpoint at least this often", "60"},
    {"seed", 0, ARG_U64, 0, &singan_train_arg.o.train.seed, NULL, 0, 0, "S", "random seed", "0"},
    {"coarsest", 0, ARG_INT, 0, &singan_train_arg.o.coarsest, NULL, 0, 1e9, "PX", "side of the coarsest scale", "25"},
    {"factor", 0, ARG_FLOAT, 0, &singan_train_arg.o.factor, NULL, 0, 0, "R", "size ratio between scales (0.5..0.9)", "0.75"},
    {"channels", 0, ARG_INT, 0, &singan_train_arg.o.channels, NULL, 0, 1e9, "N", "network width at the coarsest scale", "32"},
    {"max-channels", 0, ARG_INT, 0, &singan_train_arg.o.max_channels, NULL, 0, 1e9, "N", "the width doubles every 4 scales up to N", "32"},
    {"dequantize", 0, ARG_INT, 0, &singan_train_arg.o.dequantize, NULL, -1, 1, "N",
     "train without the example's height steps: 1 whenever it is stored in steps, -1 never",
     "0 = when the steps are coarse (8-bit heightmaps)"},
};

static int run_singan_train(void)
{
    struct singan_train_args *a = &singan_train_arg;
    tn_image dem = {0, 0, 0, NULL};
    tn_singan model;
    tn_singan_stats s;
    tn_status st;
    char ckbuf[1024];
    if (!a->ckpt) {
        snprintf(ckbuf, sizeof ckbuf, "%s.ckpt", a->out);
        a->ckpt = ckbuf;
    }
    int metres;
    a->o.train.checkpoint = a->ckpt;
    train_budget_cap(&a->o.train);
    if ((st = load_dem_metres(a->in, a->range[0], a->range[1], &dem, &metres, NULL))) return fail_status(st);
    printf("units: %s\n", metres ? "metres" : "the file's [0, 1] codes (no recorded range; give --range LO HI for metres)");
    fflush(stdout);
    st = tn_singan_train(&model, &dem, &a->o, &s);
    tn_image_free(&dem);
    if (st == TN_ERR_CANCELLED) return train_interrupted("singan-train", s.iterations, a->ckpt);
    if (st) return fail_status(st);
    st = tn_singan_save(a->out, &model);
    if (!st) {
        int i;
        printf("scales: %d (trained %d)\niterations: %ld (resumed at %ld)\nper_scale:", s.scales, s.trained, s.iterations, s.resumed_from);
        for (i = 0; i < s.scales; i++) printf(" %ld", s.scale_iters[i]);
        printf("\ntrain_minutes: %.2f\nseconds_per_iteration: %.4f (finest scale %.4f)\nloss_d: %.4f\nloss_g: %.4f\nloss_rec: %.5f\n"
               "checkpoints: %d (%s)\nmodel: %s\n",
               s.seconds / 60.0, s.seconds_per_iter, s.seconds_per_iter_finest, (double)s.loss_d, (double)s.loss_g, (double)s.loss_rec,
               s.checkpoints, a->ckpt, a->out);
        print_dequantized(s.dequantized);
        checkpoint_warning("singan-train", s.iterations, s.resumed_from, s.checkpoints, a->ckpt);
    }
    tn_singan_free(&model);
    return st ? fail_status(st) : 0;
}

static const cli_command singan_train_cmd = {"singan-train", CLI_CMD(singan_train), "train a multi-scale SinGAN on one DEM (checkpoints, resume)",
    "Trains SinGAN (one small generator per scale, coarse to fine, spectral-norm + hinge patch discriminators and a "
    "reconstruction loss) on one heightmap and writes the model; the time budget is shared over the scales by their cost "
    "and progress names the scale being trained. The full training state is saved atomically to the checkpoint every "
    "interval; --resume continues it identically. See docs/singan.md."};

static struct singan_gen_args { const char *model, *in, *out; int w, h, x0, y0, mw, mh; double factor; tn_singan_gen_opts g; } singan_gen_arg;
static const cli_opt singan_sample_opts[] = {
    {"MODEL.tnw", 0, ARG_POS, 0, &singan_gen_arg.model, NULL, 0, 0, NULL, "a model from singan-train", NULL},
    {"output", 'o', ARG_STR, REQ, &singan_gen_arg.out, NULL, 0, 0, "OUT", "heightmap to write (the example's units)", NULL},
    {"size", 0, ARG_WXH, 0, &singan_gen_arg.w, &singan_gen_arg.h, 1, 1 << 20, "WxH", "output size", "the example's size"},
    {"origin", 0, ARG_INT, PAIR, &singan_gen_arg.x0, &singan_gen_arg.y0, -(1 << 29), 1 << 29, "X Y",
     "the window's corner in the infinite sample (tiles of one seed fit together exactly)", "0 0"},
    {"seed", 0, ARG_U64, 0, &singan_gen_arg.g.seed, NULL, 0, 0, "S", "random seed", "0"},
    {"noise", 0, ARG_FLOAT, 0, &singan_gen_arg.g.noise, NULL, -1, 100, "K", "multiplier of the trained noise amplitudes (< 0: none)", "1"},
    {"fine-noise", 0, ARG_FLOAT, 0, &singan_gen_arg.g.fine_noise, NULL, -1, 100, "K",
     "a further multiplier of the finest generator's noise (1: as trained; < 0: none)", "0.7 (1 with --layout)"},
    {"layout", 0, ARG_FLAG, 0, &singan_gen_arg.g.layout, NULL, 0, 0, NULL,
     "the example's own arrangement (or its parts in a new one: --layout-blocks), rearranged by patches (GPNN) and bent by a smooth warp, under SinGAN's finer scales; "
     "a finite map (origin 0 0, or --map)", NULL},
    {"map", 0, ARG_WXH, 0, &singan_gen_arg.mw, &singan_gen_arg.mh, 1, 1 << 20, "WxH",
     "the whole map, of which --origin and --size give a window (a laid-out map is made once, then only the window is generated; "
     "windows fit together exactly)", "the window"},
    {"layout-scale", 0, ARG_INT, 0, &singan_gen_arg.g.layout_scale, NULL, 1, 64, "K",
     "with --layout: the first scale that runs on the layout (1: the layout replaces the coarsest scale; higher keeps more of the example)", "3"},
    {"layout-warp", 0, ARG_FLOAT, 0, &singan_gen_arg.g.layout_warp, NULL, -1, 4096, "PX",
     "with --layout: RMS displacement of the warp in output px (< 0: none)", "16"},
    {"layout-turn", 0, ARG_INT, 0, &singan_gen_arg.g.layout_turn, NULL, -1, 2, "T",
     "with --layout: the layout mirrored by the seed: 1 = in x, y, both or neither (any pixel shape); 2 = the quarter turns too "
     "(square pixels only); -1 = as the example",
     "1"},
    {"layout-blocks", 0, ARG_INT, 0, &singan_gen_arg.g.layout_blocks, NULL, 0, 64, "N",
     "with --layout: GPNN starts from a quilt of N x N blocks of the example, a new arrangement of its parts (2 is what "
     "docs/singan.md measured; 0: from the example itself, its own arrangement bent and turned)", "0"},
};
static const cli_opt singan_refine_opts[] = {
    {"MODEL.tnw", 0, ARG_POS, 0, &singan_gen_arg.model, NULL, 0, 0, NULL, "a model from singan-train", NULL},
    {"IN", 0, ARG_POS, 0, &singan_gen_arg.in, NULL, 0, 0, NULL, "a smooth map in the example's units and pixel size", NULL},
    {"output", 'o', ARG_STR, REQ, &singan_gen_arg.out, NULL, 0, 0, "OUT", "refined heightmap (IN's size)", NULL},
    {"from-scale", 0, ARG_INT, 0, &singan_gen_arg.g.from_scale, NULL, 1, 64, "K", "first scale whose generator runs (higher = finer detail only)", "scales - 3"},
    {"seed", 0, ARG_U64, 0, &singan_gen_arg.g.seed, NULL, 0, 0, "S", "random seed", "0"},
    {"noise", 0, ARG_FLOAT, 0, &singan_gen_arg.g.noise, NULL, -1, 100, "K", "multiplier of the trained noise amplitudes (< 0: none)", "1"},
    {"fine-noise", 0, ARG_FLOAT, 0, &singan_gen_arg.g.fine_noise, NULL, -1, 100, "K",
     "a further multiplier of the finest generator's noise (1: as trained; < 0: none)", "1"},
};
static const cli_opt singan_upscale_opts[] = {
    {"MODEL.tnw", 0, ARG_POS, 0, &singan_gen_arg.model, NULL, 0, 0, NULL, "a model from singan-train", NULL},
    {"IN", 0, ARG_POS, 0, &singan_gen_arg.in, NULL, 0, 0, NULL, "the map to upscale (the example's units)", NULL},
    {"output", 'o', ARG_STR, REQ, &singan_gen_arg.out, NULL, 0, 0, "OUT", "upscaled heightmap (factor x IN's size)", NULL},
    {"factor", 0, ARG_DOUBLE, REQ | ABOVE, &singan_gen_arg.factor, NULL, 1, 64, "F", "upscaling factor", NULL},
    {"from-scale", 0, ARG_INT, 0, &singan_gen_arg.g.from_scale, NULL, 1, 64, "K",
     "the scale IN stands for + 1 (= scales: IN at the example's pixel size, the finest generator repeats)", "output at the example's pixel size"},
    {"seed", 0, ARG_U64, 0, &singan_gen_arg.g.seed, NULL, 0, 0, "S", "random seed", "0"},
    {"noise", 0, ARG_FLOAT, 0, &singan_gen_arg.g.noise, NULL, -1, 100, "K", "multiplier of the trained noise amplitudes (< 0: none)", "1"},
    {"fine-noise", 0, ARG_FLOAT, 0, &singan_gen_arg.g.fine_noise, NULL, -1, 100, "K",
     "a further multiplier of the finest generator's noise (1: as trained; < 0: none)", "1"},
};

/* kind: 0 sample, 1 refine, 2 upscale */
static int singan_generate(int kind)
{
    struct singan_gen_args *a = &singan_gen_arg;
    tn_singan model;
    tn_image in = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_status st;
    double t0;
    if ((st = tn_singan_load(&model, a->model))) return fail_status(st);
    if (kind && (st = tn_image_load(&in, a->in, NULL))) {
        tn_singan_free(&model);
        return fail_status(st);
    }
    t0 = tn_time_seconds();
    if (kind == 0 && a->mw) {
        tn_singan_prepared *p = NULL;
        if (!(st = tn_singan_prepare(&p, &model, a->mw, a->mh, &a->g)))
            st = tn_singan_prepared_window(&out, p, a->x0, a->y0, a->w ? a->w : a->mw - a->x0, a->h ? a->h : a->mh - a->y0);
        tn_singan_prepared_free(p);
    } else if (kind == 0) st = tn_singan_sample(&out, &model, a->x0, a->y0, a->w ? a->w : model.width, a->h ? a->h : model.height, &a->g);
    else if (kind == 1) st = tn_singan_refine(&out, &model, &in, &a->g);
    else st = tn_singan_upscale(&out, &model, &in, (float)a->factor, &a->g);
    if (!st) {
        fprintf(stderr, "singan: %d x %d in %.2f s\n", out.width, out.height, tn_time_seconds() - t0);
        st = tn_image_save(a->out, &out, NULL);
    }
    tn_image_free(&in);
    tn_image_free(&out);
    tn_singan_free(&model);
    return st ? fail_status(st) : 0;
}
static int run_singan_sample(void) { return singan_generate(0); }
static int run_singan_refine(void) { return singan_generate(1); }
static int run_singan_upscale(void) { return singan_generate(2); }

static const cli_command singan_sample_cmd = {"singan-sample", CLI_CMD(singan_sample), "random terrain of any size from a SinGAN model",
    "Samples new terrain like the example, at any size, in the example's height units. The sample is defined on an "
    "infinite grid: --origin X Y with --size gives that window, and windows of one seed fit together exactly. Large "
    "sizes are made tile by tile in bounded memory."};
static const cli_command singan_refine_cmd = {"singan-refine", CLI_CMD(singan_refine), "add a SinGAN model's detail to a smooth map",
    "Injects IN (a smooth map, e.g. a GNN output, a membrane or a blurred DEM) at scale K of the model and runs the "
    "finer generators: the example's detail on IN's layout."};
static const cli_command singan_upscale_cmd = {"singan-upscale", CLI_CMD(singan_upscale), "upscale a map with a SinGAN model's learned detail",
    "Super-resolution: IN stands for a scale log(F)/log(1/0.75) scales coarser than the output, and the generators above "
    "it add the detail; by default the output has the example's pixel size."};

/* ---- sketch-to-terrain GNN ----------------------------------------------------------------- */

/* The side x side window of highest relief (max - min; first on ties, scanned on an 8 px grid
   through 8 x 8 block extremes): the part of a large DEM with the most to learn. */
static void highest_relief_window(const tn_image *dem, int side, int *x0, int *y0)
{
    int bw = dem->width / 8, bh = dem->height / 8, nb = side / 8, x, y, u, v;
    float *lo, *hi, best = -1;
    *x0 = *y0 = 0;
    if (nb < 1 || bw < nb || bh < nb) return;
    lo = (float *)malloc((size_t)bw * bh * sizeof(float));
    hi = (float *)malloc((size_t)bw * bh * sizeof(float));
    if (!lo || !hi) {
        free(lo);
        free(hi);
        return;
    }
    for (y = 0; y < bh; y++)
        for (x = 0; x < bw; x++) {
            float a = FLT_MAX, b = -FLT_MAX;
            for (v = 0; v < 8; v++)
                for (u = 0; u < 8; u++) {
                    float h = TN_PIXEL(dem, 8 * x + u, 8 * y + v, 0);
                    if (h < a) a = h;
                    if (h > b) b = h;
                }
            lo[y * bw + x] = a;
            hi[y * bw + x] = b;
        }
    for (y = 0; y + nb <= bh; y++)
        for (x = 0; x + nb <= bw; x++) {
            float a = FLT_MAX, b = -FLT_MAX;
            for (v = 0; v < nb; v++)
                for (u = 0; u < nb; u++) {
                    if (lo[(y + v) * bw + x + u] < a) a = lo[(y + v) * bw + x + u];
                    if (hi[(y + v) * bw + x + u] > b) b = hi[(y + v) * bw + x + u];
                }
            if (b - a > best) {
                best = b - a;
                *x0 = 8 * x;
                *y0 = 8 * y;
            }
        }
    free(lo);
    free(hi);
}

static struct gnn_train_args {
    const char *in, *out, *ckpt;
    int crop[2], size, holdout;
    double range[2];
    tn_gnn_opts o;
} gnn_train_arg = {.crop = {-1, -1}, .holdout = 4}; /* -1: not given */
static const cli_opt gnn_train_opts[] = {
    {"DEM", 0, ARG_POS, 0, &gnn_train_arg.in, NULL, 0, 0, NULL, "the example heightmap (its style is learnt)", NULL},
    {"output", 'o', ARG_STR, REQ, &gnn_train_arg.out, NULL, 0, 0, "MODEL.tnw", "the model: network, the example's parts and heights", NULL},
    {"minutes", 0, ARG_DOUBLE, 0, &gnn_train_arg.o.train.minutes, NULL, 0, 1e9, "M", "wall-clock budget of the whole run, resumed time included", "10"},
    {"iters", 0, ARG_LONG, 0, &gnn_train_arg.o.train.max_iters, NULL, 0, 1e9, "N", "stop after N iterations in total", "0 = only the time budget"},
    {"crop", 0, ARG_INT, PAIR, &gnn_train_arg.crop[0], &gnn_train_arg.crop[1], 0, 1 << 20, "X Y", "top-left corner of the training window",
     "the window of highest relief"},
    {"size", 0, ARG_INT, 0, &gnn_train_arg.size, NULL, 16, 4096, "N", "side of the training window (whole DEM if smaller)", "128"},
    {"holdout", 0, ARG_INT, 0, &gnn_train_arg.holdout, NULL, 0, 16, "N",
     "early stopping: every 150 iterations the network rebuilds up to N windows of the DEM two windows away from the training "
     "window (adjacent ones when none fits) from their ridges and valleys; the best becomes the model's early network, on "
     "which every sketch but the example's own runs; at the end they calibrate gnn-generate's residual gain test "
     "(gain_scale:)", "4; 0 = none"},
    {"range", 0, ARG_DOUBLE, PAIR | ORDERED, &gnn_train_arg.range[0], &gnn_train_arg.range[1], 0, 0, "LO HI",
     "metres that codes 0..max of an 8/16-bit DEM without a recorded range stand for", "the file's range, else its [0, 1] codes"},
    {"heights", 0, ARG_DOUBLE, PAIR | ORDERED | HIDDEN, &gnn_train_arg.range[0], &gnn_train_arg.range[1], 0, 0, "LO HI", "--range", NULL},
    {"resume", 0, ARG_FLAG, 0, &gnn_train_arg.o.train.resume, NULL, 0, 0, NULL, "continue the checkpoint identically", NULL},
    {"checkpoint", 0, ARG_STR, 0, &gnn_train_arg.ckpt, NULL, 0, 0, "PATH", "full training state, saved atomically", "MODEL.tnw.ckpt"},
    {"checkpoint-seconds", 0, ARG_DOUBLE, 0, &gnn_train_arg.o.train.checkpoint_seconds, NULL, 0, 1e9, "S", "checkpoint interval", "60"},
    {"seed", 0, ARG_U64, 0, &gnn_train_arg.o.train.seed, NULL, 0, 0, "S", "random seed", "0"},
    {"threshold", 0, ARG_INT, 0, &gnn_train_arg.o.extract.threshold, NULL, 1, NO_MAX, "CELLS",
     "extraction threshold of the example's network (extract --threshold)", "0.1 % of the window, at least 8"},
    {"radius", 0, ARG_FLOAT, ABOVE, &gnn_train_arg.o.radius, NULL, 0, 4096, "PX", "a pixel's neighbour parts lie within this distance", "24"},
    {"sketch-weight", 0, ARG_FLOAT, 0, &gnn_train_arg.o.sketch_weight, NULL, 0, 1e6, "W",
     "paper 6.1's sketch loss: terrain beside a ridge below it, beside a valley above it", "0 = off"},
    {"smooth-weight", 0, ARG_FLOAT, 0, &gnn_train_arg.o.smooth_weight, NULL, -1, 1e6, "W", "paper 6.1's smoothness loss (-1 = off)", "0.1"},
    {"further-weight", 0, ARG_FLOAT, 0, &gnn_train_arg.o.further_weight, NULL, 0, 1e6, "W",
     "paper 6.1's distance loss: terrain next to a line keeps near its height", "0 = off"},
    {"embed-phase", 0, ARG_FLOAT, 0, &gnn_train_arg.o.embed_phase, NULL, -1, 0.99, "S",
     "share of the budget at the end that trains for the example alone (a sharper reconstruction): everything with --holdout, "
     "else only the part embeddings (-1 = none)",
     "0.5 with --holdout, else 0.25"},
    {"dequantize", 0, ARG_INT, 0, &gnn_train_arg.o.dequantize, NULL, -1, 1, "N",
     "train without the example's height steps: 1 whenever it is stored in steps, -1 never",
     "0 = when the steps are coarse (8-bit heightmaps)"},
};

static int run_gnn_train(void)
{
    struct gnn_train_args *a = &gnn_train_arg;
    tn_image dem = {0, 0, 0, NULL}, win = {0, 0, 0, NULL}, hold[16];
    tn_gnn model;
    tn_gnn_stats s;
    tn_status st;
    char ckbuf[1024];
    int side = a->size ? a->size : 128, x = a->crop[0], y = a->crop[1], w, h, metres, given = a->crop[0] >= 0, nhold = 0, i, corner = 0;
    int dem_w, dem_h;
    if (!a->ckpt) {
        snprintf(ckbuf, sizeof ckbuf, "%s.ckpt", a->out);
        a->ckpt = ckbuf;
    }
    a->o.train.checkpoint = a->ckpt;
    train_budget_cap(&a->o.train);
    if ((st = load_dem_metres(a->in, a->range[0], a->range[1], &dem, &metres, NULL))) return fail_status(st);
    w = side < dem.width ? side : dem.width;
    h = side < dem.height ? side : dem.height;
    if (!given) highest_relief_window(&dem, side, &x, &y);
    dem_w = dem.width;
    dem_h = dem.height;
    if (x + w > dem.width || y + h > dem.height) {
        tn_image_free(&dem);
        return usage_error("gnn-train", "the %d x %d window at (%d, %d) does not fit in the %d x %d DEM", w, h, x, y, dem.width, dem.height);
    }
    st = tn_image_crop(&win, &dem, x, y, w, h);
    if (!st) nhold = tn_gnn_holdout_windows(hold, &dem, x, y, w, h, a->holdout);
    if (!st && !nhold && a->holdout > 0) { /* holdouts are whole windows beside the training one: would the corner have some? */
        corner = tn_gnn_holdout_windows(hold, &dem, 0, 0, w, h, a->holdout);
        for (i = 0; i < corner; i++) tn_image_free(&hold[i]);
    }
    tn_image_free(&dem);
    if (st) return fail_status(st);
    printf("window: %d x %d at (%d, %d)%s\nunits: %s\nholdout_windows: %d\n", w, h, x, y, given ? "" : " (highest relief)",
           metres ? "metres" : "the file's [0, 1] codes (no recorded range; give --range LO HI for metres)", nhold);
    if (!nhold && a->holdout > 0) {
        printf("holdout_why: holdouts are %d x %d windows beside the training window, shifted by whole windows, and none fits in "
               "the %d x %d DEM", w, h, dem_w, dem_h);
        if (corner) printf("; --crop 0 0 gives %d\n", corner);
        else printf("; a DEM at least twice the window's side (or a smaller --size) gives some\n");
    }
    fflush(stdout);
    a->o.holdout = nhold ? hold : NULL;
    a->o.holdout_count = nhold;
    st = tn_gnn_train(&model, &win, &a->o, &s);
    tn_image_free(&win);
    for (i = 0; i < nhold; i++) tn_image_free(&hold[i]);
    if (st == TN_ERR_CANCELLED) return train_interrupted("gnn-train", s.iterations, a->ckpt);
    if (st) return fail_status(st);
    st = tn_gnn_save(a->out, &model);
    if (!st)
        printf("parts: %d\nsketch_levels: %d\niterations: %ld (resumed at %ld)\nembed_phase_from: %ld\ntrain_minutes: %.2f\n"
               "steps_per_second: %.2f\nloss_mse: %.5f\nloss_ssim: %.4f\ncheckpoints: %d (%s)\nmodel: %s\n",
               s.parts, s.levels, s.iterations, s.resumed_from, s.embed_phase_from, s.seconds / 60.0,
               s.seconds_per_iter > 0 ? 1.0 / s.seconds_per_iter : 0.0, (double)s.loss_mse, (double)s.loss_ssim, s.checkpoints, a->ckpt, a->out);
    if (!st) checkpoint_warning("gnn-train", s.iterations, s.resumed_from, s.checkpoints, a->ckpt);
    if (!st && nhold)
        printf("holdout_ssim: %.4f (iteration %ld, the best of %d checks; the trained network's %.4f)\nearly_network: %s\n", s.holdout_ssim,
               s.holdout_iteration, s.holdout_checks, s.holdout_last_ssim,
               tn_params_find(model.weights, "early.gnn.emb") ? "kept, for every sketch but the example's own network" : "none (the trained network was the best)");
    if (!st) printf("gain_scale: %.2f (of the residual gain's test, calibrated on the holdouts; 1 = none)\n", (double)s.gain_scale);
    if (!st) print_dequantized(s.dequantized);
    tn_gnn_free(&model);
    return st ? fail_status(st) : 0;
}

static const cli_command gnn_train_cmd = {"gnn-train", CLI_CMD(gnn_train), "learn one DEM for sketch-to-terrain generation (graph network)",
    "Learns one example DEM (paper 000): its ridge and valley network is cut into 5-10 px parts and a graph network learns "
    "to turn such a network, and sparser ones, into the example's terrain. Trains on a window of the DEM (default the "
    "128 x 128 window of highest relief); windows of the DEM away from it check the network as it trains, and the best "
    "check's network is kept for sketches of other terrain (--holdout). The model records the example's parts and heights, so gnn-generate needs only "
    "it and a sketch. The full training state is saved atomically to the checkpoint every interval and on Ctrl-C; "
    "--resume continues it identically."};

static struct gnn_generate_args {
    const char *model, *sketch, *out, *preview, *detail;
    int w, h, heights, embeddings, grow;
    double range[2];
    tn_gnn_generate_opts o;
    tn_singan_gen_opts detail_opts;
} gnn_generate_arg = {.o = {.finetune = -1}}; /* -1: not given */
static const cli_opt gnn_generate_opts[] = {
    {"MODEL.tnw", 0, ARG_POS, 0, &gnn_generate_arg.model, NULL, 0, 0, NULL, "a model from gnn-train", NULL},
    {"SKETCH", 0, ARG_POS, 0, &gnn_generate_arg.sketch, NULL, 0, 0, NULL,
     "a .tns sketch, a drawn sketch image (as `sketch` reads: red ridges, blue valleys) or a DEM, whose extracted network "
     "is then the sketch", NULL},
    {"output", 'o', ARG_STR, REQ, &gnn_generate_arg.out, NULL, 0, 0, "OUT", "the terrain, in the example's units (metres)", NULL},
    {"size", 0, ARG_WXH, 0, &gnn_generate_arg.w, &gnn_generate_arg.h, 16, TN_SKETCH_MAX_SIDE, "WxH", "output size (the sketch scales to it)",
     "the sketch's canvas or the DEM's size"},
    {"seed", 0, ARG_U64, 0, &gnn_generate_arg.o.seed, NULL, 0, 0, "S", "random seed (part cutting, random sketches, alignment)", "0"},
    {"random", 0, ARG_INT, 0, &gnn_generate_arg.o.random_nodes, NULL, 0, 8192, "N",
     "densify the sketch with random ridges and valleys from N random nodes (paper 5.2)", "0 = none"},
    {"grow", 0, ARG_CHOICE, 0, &gnn_generate_arg.grow, NULL, 0, 0, "auto|on|off",
     "densify by example: fill the space between the sketch's lines with blocks of the example's own ridge/valley network, "
     "placed to continue the lines (never crossing them; heights from the lines and the example's own heights)",
     "auto: on when the sketch's lines cover under a sixth of the example network's density (a drawing of a few strokes) "
     "and --random is 0"},
    {"finetune", 0, ARG_INT, 0, &gnn_generate_arg.o.finetune, NULL, 0, 100000, "STEPS",
     "tune the sketch parts' embeddings to the sketch's heights and ridge/valley ordering first (paper 5.4)",
     "30 for a drawn sketch (an image, or a .tns in heights 0..1) that is not grown (--grow), else 0 = none"},
    {"embeddings", 0, ARG_CHOICE, 0, &gnn_generate_arg.embeddings, NULL, 0, 0, "auto|aligned|none",
     "which sketch parts take an example part's embedding: identical ones, every one by alignment, none", "auto"},
    {"heights", 0, ARG_CHOICE, 0, &gnn_generate_arg.heights, NULL, 0, 0, "auto|example|unit",
     "sketch heights are the example's units, or [0, 1] over the example's range", "unit when all lie in [0, 1]"},
    {"range", 0, ARG_DOUBLE, PAIR | ORDERED, &gnn_generate_arg.range[0], &gnn_generate_arg.range[1], 0, 0, "LO HI",
     "a DEM SKETCH without a recorded range: the metres its codes 0..max stand for", NULL},
    {"order-weight", 0, ARG_FLOAT, 0, &gnn_generate_arg.o.order_weight, NULL, -1, 1e6, "W",
     "with --finetune: weight of keeping ridges above and valleys below the terrain beside them (-1 = off)", "1"},
    {"gain", 0, ARG_FLOAT, 0, &gnn_generate_arg.o.gain, NULL, -1, 1e6, "G",
     "share of the network's relief added to the membrane of the sketch heights (1 = the network as trained, -1 = none)",
     "0 = tested on the sketch: held-out lines, scaled as the model's holdouts showed"},
    {"detail", 0, ARG_STR, 0, &gnn_generate_arg.detail, NULL, 0, 0, "auto|example|none|SINGAN.tnw",
     "the fine scales: the example's own detail matched by shape to the terrain, on a grown sketch after the fine relief of "
     "the ground grown between its strokes (fine detail by example; the model holds its example), or a singan-train model of "
     "the same example (singan-refine), or none",
     "auto: by example on a grown sketch (a drawing of a few strokes)"},
    {"detail-from-scale", 0, ARG_INT, 0, &gnn_generate_arg.detail_opts.from_scale, NULL, 1, 64, "K",
     "with --detail SINGAN.tnw: first SinGAN scale that runs on the terrain (higher = finer detail only)", "scales - 3"},
    {"map-scale", 0, ARG_INT, 0, &gnn_generate_arg.o.map_scale, NULL, -1, 64, "N",
     "a grown drawing larger than twice the example is also generated N times smaller for the large scales (broad valleys "
     "and massifs), and the detail fades on its drawn valleys' floors as on the example's main valleys (-1 = off)",
     "0 = by the drawing's size"},
    {"preview", 0, ARG_STR, 0, &gnn_generate_arg.preview, NULL, 0, 0, "PNG", "hillshaded colour preview of the terrain", NULL},
};

/* The sketch of SKETCH: .tns text, a drawing, or a DEM's extracted network. */
static tn_status load_gnn_sketch(const char *path, double lo, double hi, tn_contour_set *out, const char **kind)
{
    FILE *f = fopen(path, "rb");
    char head[20] = {0};
    tn_image img = {0, 0, 0, NULL};
    tn_status st;
    int metres;
    if (f) {
        size_t n = fread(head, 1, sizeof head - 1, f);
        fclose(f);
        head[n] = 0;
    }
    if (!strncmp(head, "terrainnet-sketch", 17)) {
        *kind = "sketch (.tns)";
        return tn_sketch_load(out, path);
    }
    if ((st = load_dem_metres(path, lo, hi, &img, &metres, NULL))) return st;
    if (img.channels >= 3) {
        *kind = "drawn sketch";
        st = tn_sketch_from_image(out, &img);
    } else {
        tn_extraction ex;
        *kind = "DEM (its extracted network)";
        if (!(st = tn_extract(&ex, &img, NULL))) {
            *out = ex.contours;
            memset(&ex.contours, 0, sizeof ex.contours);
            tn_extraction_free(&ex);
            if (!out->count) st = TN_ERR_EMPTY, fprintf(stderr, "terrainnet: %s: no ridge or valley was extracted from the DEM\n", path);
        }
    }
    tn_image_free(&img);
    return st;
}

/* Every height in 0..1: a drawing's relative heights (as TN_GNN_HEIGHTS_AUTO reads them). */
static int relative_heights(const tn_contour_set *sk)
{
    int i, j;
    for (i = 0; i < sk->count; i++)
        for (j = 0; j < sk->items[i].npoints; j++)
            if (!(sk->items[i].points[3 * j + 2] >= 0 && sk->items[i].points[3 * j + 2] <= 1)) return 0;
    return 1;
}

static int run_gnn_generate(void)
{
    struct gnn_generate_args *a = &gnn_generate_arg;
    tn_gnn model;
    tn_gnn_plan plan;
    tn_gnn_prepared *prep = NULL;
    tn_singan detail;
    tn_contour_set sk;
    tn_image terrain = {0, 0, 0, NULL};
    const char *kind = "";
    double t0, lo, hi;
    size_t i;
    tn_status st;
    memset(&sk, 0, sizeof sk);
    memset(&detail, 0, sizeof detail);
    a->o.detail = !a->detail || !strcmp(a->detail, "auto") ? 0 : !strcmp(a->detail, "example") ? 1 : -1;
    if (a->detail && (!strcmp(a->detail, "auto") || !strcmp(a->detail, "example") || !strcmp(a->detail, "none"))) a->detail = NULL;
    if (a->detail && (st = tn_singan_load(&detail, a->detail))) return fail_status(st);
    if ((st = tn_gnn_load(&model, a->model))) {
        tn_singan_free(&detail);
        return fail_status(st);
    }
    if ((st = load_gnn_sketch(a->sketch, a->range[0], a->range[1], &sk, &kind))) {
        tn_gnn_free(&model);
        tn_singan_free(&detail);
        return fail_status(st);
    }
    if (!a->w) {
        a->w = sk.width;
        a->h = sk.height;
    }
    a->o.heights = a->heights == 1 ? TN_GNN_HEIGHTS_EXAMPLE : a->heights == 2 ? TN_GNN_HEIGHTS_UNIT : TN_GNN_HEIGHTS_AUTO;
    a->o.embeddings = a->embeddings == 1 ? TN_GNN_EMBED_ALIGNED : a->embeddings == 2 ? TN_GNN_EMBED_NONE : TN_GNN_EMBED_AUTO;
    a->o.grow = a->grow == 1 ? 1 : a->grow == 2 ? -1 : 0;
    t0 = tn_time_seconds();
    memset(&plan, 0, sizeof plan);
    { /* prepared once without the fine-tune: its plan (the gain, tested once, with its reason) decides the fine-tune's
         default, and without one the same preparation generates the map */
        tn_gnn_generate_opts o0 = a->o;
        o0.finetune = 0;
        if (a->o.finetune > 0) st = tn_gnn_plan_of(&plan, &model, &sk, a->w, a->h, &o0); /* the fine-tune generates on its own */
        else if (!(st = tn_gnn_prepare(&prep, &model, &sk, a->w, a->h, &o0))) plan = *tn_gnn_prepared_plan(prep);
    }
    if (a->o.finetune < 0) /* a drawing keeps its ridges above and valleys below the land beside them (docs/gnn.md); a grown
                              one has the example's network around its strokes instead, and the fine-tune would cost 10 x */
        a->o.finetune = relative_heights(&sk) && !plan.grown_lines ? 30 : 0;
    if (!st && plan.gain <= 0)
        fprintf(stderr, "terrainnet: gnn-generate: residual gain 0: %s\n", plan.gain_why);
    if (!st && a->o.finetune == 0) st = tn_gnn_prepared_window(&terrain, prep, 0, 0, a->w, a->h);
    else if (!st) { /* the fine-tune changes the parts' embeddings: a generation of its own, at the tested gain */
        if (a->o.gain == 0) a->o.gain = plan.gain > 0 ? plan.gain : -1.0f;
        st = tn_gnn_generate(&terrain, &model, &sk, a->w, a->h, &a->o);
    }
    tn_gnn_prepared_free(prep);
    if (!st && a->detail) { /* SinGAN adds the fine detail the graph network cannot rebuild (paper 000) */
        tn_image refined = {0, 0, 0, NULL};
        a->detail_opts.seed = a->o.seed;
        if (!(st = tn_singan_refine(&refined, &detail, &terrain, &a->detail_opts))) {
            tn_image_free(&terrain);
            terrain = refined;
        }
    }
    if (!st) st = tn_image_save(a->out, &terrain, NULL);
    if (!st && a->preview) {
        tn_image shade = {0, 0, 0, NULL};
        tn_save_opts so;
        memset(&so, 0, sizeof so);
        so.bit_depth = 8;
        if (!(st = tn_render_preview(&shade, &terrain, NULL))) st = tn_image_save(a->preview, &shade, &so);
        tn_image_free(&shade);
    }
    if (!st) {
        lo = hi = terrain.data[0];
        for (i = 0; i < (size_t)terrain.width * terrain.height; i++) {
            if (terrain.data[i] < lo) lo = terrain.data[i];
            if (terrain.data[i] > hi) hi = terrain.data[i];
        }
        printf("sketch: %s, %d polylines on %d x %d\nsize: %d x %d\n", kind, sk.count, sk.width, sk.height, a->w, a->h);
        printf("line_density: %.4f (the example's network: %.4f)\ngrown_lines: %d%s\n", plan.user_density, plan.example_density,
               plan.grown_lines, plan.grown_lines ? " (densified by example: blocks of the example's network between the lines)" : "");
        printf("residual_gain: %.3f\nresidual_gain_why: %s", plan.gain > 0 ? plan.gain : 0.0, plan.gain_why);
        if (isfinite(plan.gain_raw)) printf(" (estimate %.3f x scale %.2f, clamped to 0..1)", plan.gain_raw, plan.gain_scale);
        printf("\ndetail: %s", a->detail ? "singan-refine with the given model" : plan.detail_why);
        printf("\nmap_scale: %d (%s)", plan.map_scale, plan.map_scale_why);
        if (plan.map_scale > 1) printf("\nfloor_detail: %.2f (of the detail left on a drawn valley's floor, as on the example's main valleys)", plan.floor_detail);
        printf("\nfinetune_steps: %d\nseconds: %.2f\nheight_range: %.6g %.6g\noutput: %s\n", a->o.finetune, tn_time_seconds() - t0, lo, hi, a->out);
    }
    tn_image_free(&terrain);
    tn_contour_set_free(&sk);
    tn_gnn_free(&model);
    tn_singan_free(&detail);
    return st ? fail_status(st) : 0;
}

static const cli_command gnn_generate_cmd = {"gnn-generate", CLI_CMD(gnn_generate), "terrain from a sketch in the style of a gnn-train model",
    "Turns a sketch of ridges and valleys into terrain in the style and units of the model's example. The sketch is cut "
    "into 5-10 px parts as in training; --random adds random ridges and valleys around it (they never cross it). Any "
    "size: a pixel depends only on the sketch near it, so large maps are computed in seamless tiles with bounded memory. "
    "The same inputs and seed give the same output on any thread count."};

/* ---- insolation, season ------------------------------------------------------------------- */

/* Loads a DEM for the seasonal commands, which need metres: --range LO HI maps a file without a
   recorded range (values 0..1) to metres, and without it they say so. */
static tn_status season_load_dem(const char *cmd, const char *path, double lo, double hi, tn_image *dem)
{
    int metres;
    tn_status st = load_dem_metres(path, lo, hi, dem, &metres, NULL);
    if (!st && !metres) warn_unitless(cmd, path, "slopes, shadows and the snow line come out wrong");
    return st;
}

static struct insolation_args { const char *in, *out; double lat, lo, hi; tn_insolation_opts o; } insolation_arg;
static const cli_opt insolation_opts[] = {
    {"DEM", 0, ARG_POS, 0, &insolation_arg.in, NULL, 0, 0, NULL, "heightmap in metres", NULL},
    {"lat", 0, ARG_DOUBLE, REQ, &insolation_arg.lat, NULL, -90, 90, "DEG", "latitude (south negative; row 0 is north)", NULL},
    {"output", 'o', ARG_STR, REQ, &insolation_arg.out, NULL, 0, 0, "PREFIX",
     "writes PREFIX_01.pfm .. PREFIX_12.pfm (W h/m^2 per day), their pictures PREFIX_MM.png and PREFIX_sheet.png, the labelled year", NULL},
    {"month", 0, ARG_INT, 0, &insolation_arg.o.month, NULL, 1, 12, "M", "only month M (PREFIX_MM.pfm)", "all twelve"},
    {"spacing", 0, ARG_FLOAT, PAIR | OPT2 | ABOVE, &insolation_arg.o.dx, &insolation_arg.o.dy, 0, NO_MAX, "DX [DY]", "pixel spacing in metres", "1"},
    {"range", 0, ARG_DOUBLE, PAIR | ORDERED, &insolation_arg.lo, &insolation_arg.hi, 0, 0, "LO HI",
     "metres of the lowest and highest code, for a file that records no range", "the file's values"},
    {"heights", 0, ARG_DOUBLE, PAIR | ORDERED | HIDDEN, &insolation_arg.lo, &insolation_arg.hi, 0, 0, "LO HI", "--range", NULL},
    {"step", 0, ARG_FLOAT, 0, &insolation_arg.o.step_minutes, NULL, 1, 720, "MIN", "time step of the shadow test", "15"},
    {"directions", 0, ARG_INT, 0, &insolation_arg.o.directions, NULL, 4, 1024, "N", "horizon azimuths", "32"},
    {"day", 0, ARG_INT, 0, &insolation_arg.o.day, NULL, 1, 31, "D", "day of the month of the sun path", "15"},
    {"no-shadows", 0, ARG_FLAG, 0, &insolation_arg.o.no_shadows, NULL, 0, 0, NULL, "slope and aspect only, no terrain horizon", NULL},
};

/* Channel c of a multi-channel image as a one-channel image. */
static tn_status season_channel(const tn_image *src, int c, tn_image *dst)
{
    size_t i, n = (size_t)src->width * src->height;
    tn_status st = tn_image_create(dst, src->width, src->height, 1);
    if (st) return st;
    for (i = 0; i < n; i++) dst->data[i] = src->data[i * src->channels + c];
    return TN_OK;
}

/* Insolation as a picture: black (none) through red and orange to pale yellow at top. */
static tn_status insolation_preview(const tn_image *one, float top, tn_image *rgb)
{
    static const float stops[5][4] = {{0.0f, 0.0f, 0.0f, 0.02f}, {0.3f, 0.35f, 0.05f, 0.35f}, {0.6f, 0.85f, 0.25f, 0.1f},
                                      {0.85f, 1.0f, 0.65f, 0.1f}, {1.0f, 1.0f, 1.0f, 0.75f}};
    size_t i, n = (size_t)one->width * one->height;
    tn_status st = tn_image_create(rgb, one->width, one->height, 3);
    for (i = 0; !st && i < n; i++) {
        float t = top > 0 ? one->data[i] / top : 0.0f, f;
        int k = 1, c;
        t = t < 0 ? 0 : t > 1 ? 1 : t;
        while (k < 4 && t > stops[k][0]) k++;
        f = (t - stops[k - 1][0]) / (stops[k][0] - stops[k - 1][0]);
        for (c = 0; c < 3; c++) rgb->data[i * 3 + c] = stops[k - 1][c + 1] + f * (stops[k][c + 1] - stops[k - 1][c + 1]);
    }
    return st;
}

static int run_insolation(void)
{
    struct insolation_args *a = &insolation_arg;
    tn_image dem = {0, 0, 0, NULL}, out = {0, 0, 0, NULL}, one = {0, 0, 0, NULL}, pics[12], sheet = {0, 0, 0, NULL};
    tn_save_opts so;
    tn_status st;
    char path[4096], label[12][24];
    const char *labels[12];
    float top = 0, lo0, hi0;
    int c;
    double t0 = tn_time_seconds();
    if ((st = season_load_dem("insolation", a->in, a->lo, a->hi, &dem))) return fail_status(st);
    st = tn_insolation(&out, &dem, a->lat, &a->o);
    tn_image_free(&dem);
    if (st) return fail_status(st);
    memset(pics, 0, sizeof pics);
    memset(&so, 0, sizeof so);
    so.bit_depth = 8;
    if (tn_image_range(&lo0, &hi0, &out) == TN_OK) top = hi0; /* one scale for the year, so months compare */
    for (c = 0; c < out.channels && !st; c++) {
        int month = a->o.month ? a->o.month : c + 1;
        float lo, hi;
        double sum = 0;
        size_t i, n = (size_t)out.width * out.height;
        snprintf(path, sizeof path, "%s_%02d.pfm", a->out, month);
        if ((st = season_channel(&out, c, &one))) break;
        tn_image_range(&lo, &hi, &one);
        for (i = 0; i < n; i++) sum += one.data[i];
        st = tn_image_save(path, &one, NULL);
        if (!st) printf("%s: month %2d mean %.0f min %.0f max %.0f W h/m^2 per day\n", path, month, sum / (double)n, lo, hi);
        snprintf(path, sizeof path, "%s_%02d.png", a->out, month);
        if (!st) st = insolation_preview(&one, top, &pics[c]);
        if (!st) st = tn_image_save(path, &pics[c], &so);
        snprintf(label[c], sizeof label[c], "%s MEAN %.0f", tn_season_time_label(path, 8, (float)(month - 1)), sum / (double)n);
        labels[c] = label[c];
        tn_image_free(&one);
    }
    if (!st) printf("previews: %s_MM.png, black = 0 to pale yellow = %.0f W h/m^2 per day (the year's highest)\n", a->out, top);
    if (!st && out.channels > 1) {
        snprintf(path, sizeof path, "%s_sheet.png", a->out);
        if (!(st = tn_season_sheet_labelled(&sheet, pics, labels, out.channels, 4, out.width < 256 ? out.width : 256)))
            st = tn_image_save(path, &sheet, &so);
        if (!st) printf("sheet: %s (the year, each month with its mean in W h/m^2 per day)\n", path);
    }
    for (c = 0; c < 12; c++) tn_image_free(&pics[c]);
    tn_image_free(&sheet);
    tn_image_free(&out);
    if (st) return fail_status(st);
    printf("insolation: %.2f s\n", tn_time_seconds() - t0);
    return 0;
}

static const cli_command insolation_cmd = {"insolation", CLI_CMD(insolation), "monthly direct-sun maps with terrain shadows (PFM + PNG sheet)",
    "Daily direct-beam insolation outside the atmosphere (W h/m^2 per day) on each pixel's slope on the 15th of every month, "
    "with shadows cast by the terrain (docs/season.md). Heights must be metres: give --spacing, and --range for a file "
    "that records no range."};

static struct season_args {
    const char *in, *out, *climate, *koppen, *insol;
    double lat, lo, hi;
    int month, months, frames, columns;
    tn_season_opts o;
    const char *model;
} season_arg = {NULL, NULL, NULL, NULL, NULL, -999.0, 0, 0, 0, 0, 0, 0, {{0, 0, 0, 0, 0, 0, 0, 0, 0}, 0, 0, 0, 0, 0, 0, 0, 0}, NULL}; /* lat -999: not given */
static const cli_opt season_opts[] = {
    {"DEM", 0, ARG_POS, 0, &season_arg.in, NULL, 0, 0, NULL, "heightmap in metres", NULL},
    {"output", 'o', ARG_STR, REQ, &season_arg.out, NULL, 0, 0, "PREFIX",
     "writes PREFIX_MM.png per month (or PREFIX_fNNN.png per frame) and PREFIX_sheet.png, the year at a glance", NULL},
    {"climate", 0, ARG_STR, 0, &season_arg.climate, NULL, 0, 0, "CSV", "12 months of temperature and precipitation (docs/season.md)", NULL},
    {"koppen", 0, ARG_STR, 0, &season_arg.koppen, NULL, 0, 0, "CODE", "built-in climate: Af, Aw, BWh, Cfb, Csa, Dfc, Dfb, ET", NULL},
    {"lat", 0, ARG_DOUBLE, 0, &season_arg.lat, NULL, -90, 90, "DEG", "latitude (south negative)", "the climate's"},
    {"month", 0, ARG_INT, 0, &season_arg.month, NULL, 1, 12, "M", "only month M (its 15th)", NULL},
    {"months", 0, ARG_FLAG, 0, &season_arg.months, NULL, 0, 0, NULL, "all twelve months (the default)", NULL},
    {"frames", 0, ARG_INT, 0, &season_arg.frames, NULL, 1, 1000, "N", "N frames evenly through the year from mid-January", NULL},
    {"spacing", 0, ARG_FLOAT, PAIR | OPT2 | ABOVE, &season_arg.o.insolation.dx, &season_arg.o.insolation.dy, 0, NO_MAX, "DX [DY]",
     "pixel spacing in metres", "1"},
    {"range", 0, ARG_DOUBLE, PAIR | ORDERED, &season_arg.lo, &season_arg.hi, 0, 0, "LO HI",
     "metres of the lowest and highest code, for a file that records no range", "the file's values"},
    {"heights", 0, ARG_DOUBLE, PAIR | ORDERED | HIDDEN, &season_arg.lo, &season_arg.hi, 0, 0, "LO HI", "--range", NULL},
    {"insolation", 0, ARG_STR, 0, &season_arg.insol, NULL, 0, 0, "PREFIX", "read PREFIX_01..12.pfm from `terrainnet insolation`", "computed"},
    {"shade", 0, ARG_FLOAT, SET, &season_arg.o.shade, NULL, 0, 1, "F", "hillshade mixed into the colours (0 = albedo only)", "0.5"},
    {"seed", 0, ARG_U64, 0, &season_arg.o.seed, NULL, 0, 0, "S", "seed of the fine detail noise", "0"},
    {"columns", 0, ARG_INT, 0, &season_arg.columns, NULL, 1, 64, "N", "columns of the preview sheet", "4"},
    {"model", 0, ARG_STR, 0, &season_arg.model, NULL, 0, 0, "MODEL.tnw",
     "a KPD network from season-train instead of the procedural texturer (times between months interpolate its gamma/beta)", NULL},
};

/* Reads PREFIX_01..12.pfm into one 12-channel image. */
static tn_status season_read_insolation(const char *prefix, tn_image *out)
{
    tn_image one = {0, 0, 0, NULL}, all = {0, 0, 0, NULL};
    char path[4096];
    tn_status st = TN_OK;
    size_t i, n = 0;
    int m;
    for (m = 0; m < 12 && !st; m++) {
        snprintf(path, sizeof path, "%s_%02d.pfm", prefix, m + 1);
        if ((st = tn_image_load(&one, path, NULL))) break;
        if (m == 0) {
            n = (size_t)one.width * one.height;
            if ((st = tn_image_create(&all, one.width, one.height, 12))) break;
        } else if (one.width != all.width || one.height != all.height) {
            fprintf(stderr, "terrainnet: %s is %d x %d, month 1 was %d x %d\n", path, one.width, one.height, all.width, all.height);
            st = TN_ERR_SHAPE;
        }
        for (i = 0; !st && i < n; i++) all.data[i * 12 + m] = one.data[i * one.channels];
        tn_image_free(&one);
    }
    if (st) tn_image_free(&all);
    else *out = all;
    return st;
}

/* The KPD network's pictures at each time, mapped from its value range to [0, 1] for saving (a
   one-channel model, e.g. NDVI, also writes the values as PREFIX_*.pfm). */
static tn_status season_network(const struct season_args *a, const tn_image *dem, tn_climate *clim, tn_image *ins, const float *times,
                                int count, tn_image *imgs)
{
    tn_kpd m;
    tn_status st;
    int i;
    size_t k;
    char path[4096];
    if ((st = tn_kpd_load(&m, a->model))) return st;
    if (a->lat >= -90) clim->latitude = (float)a->lat, clim->has_latitude = 1;
    if (m.condition == TN_KPD_OURS && !ins->data) st = tn_insolation(ins, dem, clim->has_latitude ? clim->latitude : NAN, &a->o.insolation);
    for (i = 0; i < count && !st; i++) {
        if ((st = tn_kpd_generate(&imgs[i], &m, dem, clim, ins->data ? ins : NULL, times[i], 0, 0, dem->width, dem->height))) break;
        if (m.out_channels == 1) {
            if (a->frames) snprintf(path, sizeof path, "%s_f%03d.pfm", a->out, i);
            else snprintf(path, sizeof path, "%s_%02d.pfm", a->out, a->month ? a->month : i + 1);
            if ((st = tn_image_save(path, &imgs[i], NULL))) break;
        }
        for (k = 0; k < (size_t)imgs[i].width * imgs[i].height * imgs[i].channels; k++) {
            float v = (imgs[i].data[k] - m.lo) / (m.hi - m.lo);
            imgs[i].data[k] = v < 0 ? 0 : v > 1 ? 1 : v;
        }
    }
    tn_kpd_free(&m);
    return st;
}

static int run_season(void)
{
    struct season_args *a = &season_arg;
    tn_image dem = {0, 0, 0, NULL}, ins = {0, 0, 0, NULL}, sheet = {0, 0, 0, NULL}, *imgs = NULL;
    tn_climate clim;
    tn_save_opts so;
    tn_status st;
    float times[1000];
    char path[4096];
    int i, count;
    double t0 = tn_time_seconds();
    if (!a->climate == !a->koppen) return usage_error("season", "give exactly one of --climate CSV and --koppen CODE");
    if ((a->month != 0) + (a->frames != 0) + (a->months != 0) > 1) return usage_error("season", "--month, --months and --frames exclude each other");
    st = a->climate ? tn_climate_load(&clim, a->climate) : tn_climate_koppen(&clim, a->koppen);
    if (st) return fail_status(st);
    count = a->month ? 1 : a->frames ? a->frames : 12;
    for (i = 0; i < count; i++) times[i] = a->month ? (float)(a->month - 1) : a->frames ? 12.0f * (float)i / (float)count : (float)i;
    if ((st = season_load_dem("season", a->in, a->lo, a->hi, &dem))) return fail_status(st);
    if (a->insol && (st = season_read_insolation(a->insol, &ins))) {
        tn_image_free(&dem);
        return fail_status(st);
    }
    if (!(imgs = (tn_image *)calloc((size_t)count, sizeof *imgs))) {
        tn_image_free(&dem);
        tn_image_free(&ins);
        fprintf(stderr, "terrainnet: out of memory\n");
        return 1;
    }
    /* without --lat (still -999) the climate's latitude is used */
    if (a->model) st = season_network(a, &dem, &clim, &ins, times, count, imgs);
    else st = tn_season_texture(imgs, &dem, &clim, a->lat < -90 ? NAN : a->lat, ins.data ? &ins : NULL, times, count, &a->o, NULL);
    memset(&so, 0, sizeof so);
    so.bit_depth = 8;
    for (i = 0; i < count && !st; i++) {
        if (a->frames) snprintf(path, sizeof path, "%s_f%03d.png", a->out, i);
        else snprintf(path, sizeof path, "%s_%02d.png", a->out, a->month ? a->month : i + 1);
        st = tn_image_save(path, &imgs[i], &so);
    }
    if (!st && count > 1) { /* the year at a glance, each picture under its date */
        char(*label)[16] = (char(*)[16])calloc((size_t)count, sizeof *label);
        const char **labels = (const char **)calloc((size_t)count, sizeof *labels);
        for (i = 0; label && labels && i < count; i++) labels[i] = tn_season_time_label(label[i], sizeof label[i], times[i]);
        snprintf(path, sizeof path, "%s_sheet.png", a->out);
        if (!label || !labels) st = TN_ERR_OUT_OF_MEMORY;
        else if (!(st = tn_season_sheet_labelled(&sheet, imgs, labels, count, a->columns, dem.width < 256 ? dem.width : 256)))
            st = tn_image_save(path, &sheet, &so);
        free(label);
        free(labels);
    }
    if (!st) printf("season: %s, %d image%s of %d x %d in %.2f s\n", clim.name, count, count > 1 ? "s" : "", dem.width, dem.height, tn_time_seconds() - t0);
    for (i = 0; i < count; i++) tn_image_free(&imgs[i]);
    free(imgs);
    tn_image_free(&sheet);
    tn_image_free(&dem);
    tn_image_free(&ins);
    return st ? fail_status(st) : 0;
}

static struct season_train_args { const char *data, *out, *ckpt, *cond, *exclude; tn_kpd_opts o; } season_train_arg;
static const cli_opt season_train_opts[] = {
    {"DATA", 0, ARG_POS, 0, &season_train_arg.data, NULL, 0, 0, NULL,
     "a season data file (sites, climates, dated pictures; docs/season.md), or a folder holding one as season.csv", NULL},
    {"output", 'o', ARG_STR, REQ, &season_train_arg.out, NULL, 0, 0, "MODEL.tnw", "the KPD generator", NULL},
    {"minutes", 0, ARG_DOUBLE, 0, &season_train_arg.o.train.minutes, NULL, 0, 1e9, "M", "wall-clock budget", "10"},
    {"iters", 0, ARG_LONG, 0, &season_train_arg.o.train.max_iters, NULL, 0, 1e9, "N", "stop after N iterations", "0 = only the time budget"},
    {"resume", 0, ARG_FLAG, 0, &season_train_arg.o.train.resume, NULL, 0, 0, NULL, "continue the checkpoint identically", NULL},
    {"checkpoint", 0, ARG_STR, 0, &season_train_arg.ckpt, NULL, 0, 0, "PATH", "full training state, saved atomically", "MODEL.tnw.ckpt"},
    {"checkpoint-seconds", 0, ARG_DOUBLE, 0, &season_train_arg.o.train.checkpoint_seconds, NULL, 0, 1e9, "S", "checkpoint at least this often", "60"},
    {"seed", 0, ARG_U64, 0, &season_train_arg.o.train.seed, NULL, 0, 0, "S", "random seed", "0"},
    {"condition", 0, ARG_STR, 0, &season_train_arg.cond, NULL, 0, 0, "C",
     "ours (T12+P12+S12 rotated), cond1 (T'12+P'12+month), cond2 (T1+P1), cond3 (latitude+month), cond4 (T12+P12)", "ours"},
    {"exclude", 0, ARG_STR, 0, &season_train_arg.exclude, NULL, 0, 0, "PREFIX", "leave out the frames whose date starts with PREFIX (held out)", NULL},
    {"width", 0, ARG_INT, 0, &season_train_arg.o.width, NULL, 4, 256, "N", "features at the coarsest level", "32"},
    {"crop", 0, ARG_INT, 0, &season_train_arg.o.crop, NULL, 16, 4096, "PX", "training window side (a multiple of 8)", "64"},
    {"batch", 0, ARG_INT, 0, &season_train_arg.o.batch, NULL, 1, 64, "N", "windows per step", "4"},
    {"lr", 0, ARG_FLOAT, 0, &season_train_arg.o.lr, NULL, 0, 1, "R", "Adam rate", "2e-4"},
    {"gan", 0, ARG_FLOAT, 0, &season_train_arg.o.gan_weight, NULL, -1, 1000, "W", "adversarial weight (< 0: L1 only)", "1"},
};

static int run_season_train(void)
{
    struct season_train_args *a = &season_train_arg;
    tn_season_data d;
    tn_season_sample *use = NULL;
    tn_kpd model;
    tn_kpd_stats s;
    tn_status st;
    char ckbuf[1024], dirbuf[4096];
    int i, n = 0;
    if (!a->ckpt) {
        snprintf(ckbuf, sizeof ckbuf, "%s.ckpt", a->out);
        a->ckpt = ckbuf;
    }
    a->o.train.checkpoint = a->ckpt;
    train_budget_cap(&a->o.train);
    if (a->cond && (st = tn_kpd_condition_parse(&a->o.condition, a->cond))) return fail_status(st);
    { /* a folder holding season.csv */
        FILE *f;
        snprintf(dirbuf, sizeof dirbuf, "%s/season.csv", a->data);
        if ((f = fopen(dirbuf, "rb"))) {
            fclose(f);
            a->data = dirbuf;
        }
    }
    if ((st = tn_season_data_load(&d, a->data))) return fail_status(st);
    if (!(use = (tn_season_sample *)calloc((size_t)d.count, sizeof *use))) {
        tn_season_data_free(&d);
        fprintf(stderr, "terrainnet: out of memory\n");
        return 1;
    }
    for (i = 0; i < d.count; i++)
        if (!a->exclude || strncmp(d.labels[i], a->exclude, strlen(a->exclude))) use[n++] = d.samples[i];
    printf("data: %d site%s, %d usable frames, %d for training\n", d.sites, d.sites > 1 ? "s" : "", d.count, n);
    a->o.lo = d.lo;
    a->o.hi = d.hi;
    st = tn_kpd_train(&model, use, n, &a->o, &s);
    free(use);
    tn_season_data_free(&d);
    if (st == TN_ERR_CANCELLED) return train_interrupted("season-train", s.iterations, a->ckpt);
    if (st) return fail_status(st);
    st = tn_kpd_save(a->out, &model);
    if (!st)
        printf("condition: %s\niterations: %ld (resumed at %ld)\ntrain_minutes: %.2f\nseconds_per_iteration: %.4f\n"
               "loss_l1: %.5f (first %.5f)\nloss_g: %.4f\nloss_d: %.4f\ncheckpoints: %d (%s)\nmodel: %s\n",
               tn_kpd_condition_name(model.condition), s.iterations, s.resumed_from, s.seconds / 60.0, s.seconds_per_iter, (double)s.loss_l1,
               (double)s.loss_l1_first, (double)s.loss_g, (double)s.loss_d, s.checkpoints, a->ckpt, a->out);
    if (!st) checkpoint_warning("season-train", s.iterations, s.resumed_from, s.checkpoints, a->ckpt);
    tn_kpd_free(&model);
    return st ? fail_status(st) : 0;
}

static const cli_command season_train_cmd = {"season-train", CLI_CMD(season_train), "train the KPD seasonal texture network on dated pictures",
    "Trains paper 003's KPD generator (SPADE-style blocks conditioned on the heightfield and the year of temperature, "
    "precipitation and insolation rotated to the target month) on the pictures of a season data file, with clouds and "
    "no-data pixels left out of every loss. Checkpoints atomically; --resume continues identically. See docs/season.md."};

static const cli_command season_cmd = {"season", CLI_CMD(season), "seasonal textures of a DEM for a climate (procedural, or a KPD network)",
    "Textures for every month (or N frames through the year) from the built-in procedural texturer: degree-day snow through "
    "a cyclic year with insolation and the -0.6 C / 100 m lapse rate, vegetation greenness from temperature and moisture, "
    "forest below the tree line, bare rock on steep slopes, colours measured from real ground textures; or, with --model, "
    "a KPD network from season-train (docs/season.md)."};

/* ---- main -------------------------------------------------------------------------------- */

static const cli_command *const commands[] = {
    &info_cmd, &convert_cmd, &metrics_cmd, &render_cmd, &noise_cmd, &sketch_cmd, &sketch_random_cmd, &align_cmd,
    &extract_cmd, &realism_cmd, &style_cmd, &texgan_train_cmd, &texgan_synth_cmd, &detail_maps_cmd, &gnn_train_cmd,
    &gnn_generate_cmd, &singan_train_cmd, &singan_sample_cmd, &singan_refine_cmd, &singan_upscale_cmd, &insolation_cmd,
    &season_cmd, &season_train_cmd, &export_cmd, &world_cmd,
};
#define NCOMMANDS (sizeof commands / sizeof commands[0])

static void print_usage(FILE *f)
{
    size_t i;
    fprintf(f, "terrainnet %s - learn terrain from one example; synthesise terrain and textures\n\n"
               "usage: terrainnet [--threads N] [--precision auto|bf16|fp32] [--max-memory MB] COMMAND [ARGS]\n"
               "       (`terrainnet COMMAND --help` or `terrainnet help COMMAND` for its arguments;\n"
               "       --precision: of the products under convolutions and dense layers, bf16 with\n"
               "       float32 sums and weights, or float32; auto = fp32 for now;\n"
               "       --max-memory caps the library's memory, default %.0f MB, half the RAM)\n\ncommands:\n",
            TN_VERSION_STRING, (double)tn_get_memory_limit() / 1048576.0);
    for (i = 0; i < NCOMMANDS; i++) fprintf(f, "  %-13s %s\n", commands[i]->name, commands[i]->summary);
}

/* Edit distance (insert, delete, substitute, swap two neighbours) between two short words. */
static int edit_distance(const char *a, const char *b)
{
    int d[32][32], i, j, n = (int)strlen(a), m = (int)strlen(b);
    if (n > 31 || m > 31) return 99;
    for (i = 0; i <= n; i++) d[i][0] = i;
    for (j = 0; j <= m; j++) d[0][j] = j;
    for (i = 1; i <= n; i++)
        for (j = 1; j <= m; j++) {
            int v = d[i - 1][j - 1] + (a[i - 1] != b[j - 1]);
            if (d[i - 1][j] + 1 < v) v = d[i - 1][j] + 1;
            if (d[i][j - 1] + 1 < v) v = d[i][j - 1] + 1;
            if (i > 1 && j > 1 && a[i - 1] == b[j - 2] && a[i - 2] == b[j - 1] && d[i - 2][j - 2] + 1 < v) v = d[i - 2][j - 2] + 1;
            d[i][j] = v;
        }
    return d[n][m];
}

/* The command nearest to a mistyped one (at most a third of its letters off), or NULL. */
static const char *nearest_command(const char *word)
{
    const char *best = NULL;
    int i, bd = 99;
    for (i = 0; i < (int)NCOMMANDS; i++) {
        int dist = edit_distance(word, commands[i]->name);
        if (dist < bd) bd = dist, best = commands[i]->name;
    }
    return bd <= 1 + (int)strlen(word) / 3 ? best : NULL;
}

int main(int argc, char **argv)
{
    const cli_command *c = NULL;
    int a = 1, i, rc, help;
    while (a < argc && argv[a][0] == '-') {
        if (!strcmp(argv[a], "--help") || !strcmp(argv[a], "-h")) {
            print_usage(stdout);
            return 0;
        } else if (!strcmp(argv[a], "--version")) {
            printf("terrainnet %s\n", TN_VERSION_STRING);
            return 0;
        } else if (!strcmp(argv[a], "--threads") && a + 1 < argc) {
            char *end;
            long n = strtol(argv[a + 1], &end, 10);
            if (*end || end == argv[a + 1] || n < 1 || n > 64) {
                fprintf(stderr, "terrainnet: --threads needs a number from 1 to 64\n");
                return 2;
            }
            tn_set_threads((int)n);
            a += 2;
        } else if (!strcmp(argv[a], "--precision") && a + 1 < argc) {
            tn_precision p;
            if (tn_precision_parse(&p, argv[a + 1]) != TN_OK) {
                fprintf(stderr, "terrainnet: --precision needs auto, bf16 or fp32\n");
                return 2;
            }
            tn_set_precision(p);
            a += 2;
        } else if (!strcmp(argv[a], "--max-memory") && a + 1 < argc) {
            char *end;
            double mb = strtod(argv[a + 1], &end);
            if (*end || end == argv[a + 1] || !(mb >= 16 && mb <= 1e12)) {
                fprintf(stderr, "terrainnet: --max-memory needs megabytes from 16 to 1e12\n");
                return 2;
            }
            tn_set_memory_limit(mb * 1048576.0 >= (double)SIZE_MAX ? SIZE_MAX : (size_t)(mb * 1048576.0));
            a += 2;
        } else {
            fprintf(stderr, "terrainnet: unknown option %s\n", argv[a]);
            print_usage(stderr);
            return 2;
        }
    }
    if (a >= argc) {
        print_usage(stderr);
        return 2;
    }
    help = !strcmp(argv[a], "help"); /* `terrainnet help [COMMAND]` */
    if (help && a + 1 >= argc) {
        print_usage(stdout);
        return 0;
    }
    for (i = 0; i < (int)NCOMMANDS; i++)
        if (!strcmp(argv[a + help], commands[i]->name)) c = commands[i];
    if (!c) {
        const char *near = nearest_command(argv[a + help]);
        if (near) {
            fprintf(stderr, "terrainnet: unknown command '%s'; did you mean '%s'? (`terrainnet --help` lists them all)\n", argv[a + help], near);
            return 2;
        }
        fprintf(stderr, "terrainnet: unknown command '%s'\n", argv[a + help]);
        print_usage(stderr);
        return 2;
    }
    for (i = a + 1; i < argc; i++) help |= !strcmp(argv[i], "--help") || !strcmp(argv[i], "-h");
    if (help) {
        cli_help(c);
        return 0;
    }
    if ((rc = cli_parse(c, argc - a - 1, argv + a + 1))) return rc;
    install_progress();
    rc = c->run();
    progress_close();
    return rc;
}
