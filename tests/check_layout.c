/* check_layout - checks the section layout of terrainnet.h (STYLE.md, "terrainnet's conventions").

   build/check/check_layout [--allow FILE] [--defs] [HEADER]   (defaults: tests/layout_allow.txt, terrainnet.h)
   Prints one "HEADER:LINE: message" per violation and a closing "check_layout: ..." line; exits 1
   when there is any violation that the allow-list does not waive.

   1. Tags. The table of contents (the lines after "TABLE OF CONTENTS" in the top comment, up to
      the first blank line) lists every @@tag once; any @@word written anywhere in the file is one
      of them. Each tag opens its declarations once, with a line that starts with "@@tag", before
      "//// end header file", in table-of-contents order.
   2. Implementation banners: every line after the end of the declarations that starts with ">>x"
      is ">>tag  (@@tag implementation...)" or ">>x  (part of @@tag implementation...)". Each tag
      has at least one banner, its own >>tag banner (if any) first; banners come in
      table-of-contents order, a tag's parts together. A ">>x" written in a comment names a banner.
   3. Dependencies. A tn_ / tn__ function, or file-scope variable, belongs to the section that
      defines it. Using it - a call, or the name passed as a function pointer - in the code or the
      macros of an earlier section (declarations or implementation) is a violation: sections
      depend only on sections above them. Comments, string and character literals do not count,
      nor do prototypes or struct members of the same name (after . or ->).
   4. A public tn_ function declared in a section's declarations is defined in the same section.

   Violations of 3 and 4 can be waived in the allow-list file, one "@@section name" line each
   (the section that uses or declares the name): a stop-gap until the header is fixed. Waivers
   that no longer match anything are reported as notes, so the list can be emptied.

   Plain C99 without dependencies, so that CI needs nothing but a compiler. tests/test_layout.c
   includes this file with CHECK_LAYOUT_NO_MAIN and plants violations in copies of the header. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <ctype.h>
#include <stdarg.h>

/* ---- growable report text ----------------------------------------------------------------- */

typedef struct cl_report {
    char *text; /* NUL-terminated, one message per line; owned, free with cl_report_free */
    size_t len, cap;
    int errors; /* violations not waived */
    int waived; /* violations waived by the allow-list */
    int notes;  /* stale waivers and other remarks that do not fail the check */
} cl_report;

static void cl_report_free(cl_report *r)
{
    free(r->text);
    memset(r, 0, sizeof *r);
}

static void cl_put(cl_report *r, const char *s)
{
    size_t n = strlen(s);
    if (r->len + n + 1 > r->cap) {
        size_t cap = r->cap ? r->cap : 1024;
        char *p;
        while (cap < r->len + n + 1) cap *= 2;
        p = (char *)realloc(r->text, cap);
        if (!p) return; /* out of memory: the message is lost, the counts still tell */
        r->text = p;
        r->cap = cap;
    }
    memcpy(r->text + r->len, s, n + 1);
    r->len += n;
}

#define CL_MSG_MAX 600

/* ---- tags and banners ---------------------------------------------------------------------- */

#define CL_NAME_MAX 64

typedef struct cl_tag {
    char name[CL_NAME_MAX];
    int toc_line;  /* line in the table of contents */
    int decl_line; /* its declaration banner, 0 if none yet */
    int impl_line; /* its first implementation banner, 0 if none */
} cl_tag;

typedef struct cl_banner {
    char name[CL_NAME_MAX]; /* the x of >>x */
    int line, tag;
} cl_banner;

/* A tn_ name defined at file scope: a function or a variable. */
typedef struct cl_def {
    const char *name;
    int len, line, sect, is_fn, defined; /* defined = 0: only a tentative declaration so far */
} cl_def;

typedef struct cl_mention {
    const char *s;
    int len, line;
} cl_mention;

typedef struct cl_waiver {
    char sect[CL_NAME_MAX], name[CL_NAME_MAX];
    int used;
} cl_waiver;

enum { CL_IDENT, CL_PUNCT, CL_STRING };
enum { CL_CODE, CL_MACRO, CL_DIRECTIVE }; /* where a token stands */

typedef struct cl_tok {
    const char *s;
    int len, line;
    unsigned char kind, where;
    char c; /* punctuation: the character; 'A' for "->", '~' for "==" "<=" ">=" "!=" */
} cl_tok;

typedef struct cl_ctx {
    const char *file, *text;
    size_t n;
    cl_report *r;
    int nlines;
    const char **line_at; /* start of each line, 1-based */
    int *sect;            /* section (tag index) of each line, 1-based */
    cl_tag *tags;
    int ntags;
    cl_banner *banners;
    int nbanners;
    int toc_line, end_line; /* "TABLE OF CONTENTS" and "//// end header file" lines */
    cl_tok *toks;
    int ntoks, ctoks;
    cl_mention *mentions; /* >>x written in comments (checked against the banners) */
    int nmentions, cmentions;
    cl_def *defs;
    int ndefs, cdefs;
    int *hash; /* open addressing into defs, -1 = empty */
    int hcap;
    cl_waiver *waivers;
    int nwaivers;
    int oom;
} cl_ctx;

static void cl_vmsg(cl_ctx *c, const char *kind, int line, const char *fmt, va_list ap)
{
    char msg[CL_MSG_MAX], full[CL_MSG_MAX + 300];
    vsnprintf(msg, sizeof msg, fmt, ap);
    if (line > 0) snprintf(full, sizeof full, "%s:%d: %s%s\n", c->file, line, kind, msg);
    else snprintf(full, sizeof full, "%s: %s%s\n", c->file, kind, msg);
    cl_put(c->r, full);
}

static void cl_error(cl_ctx *c, int line, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    cl_vmsg(c, "", line, fmt, ap);
    va_end(ap);
    c->r->errors++;
}

static void cl_note(cl_ctx *c, int line, const char *fmt, ...)
{
    va_list ap;
    va_start(ap, fmt);
    cl_vmsg(c, "note: ", line, fmt, ap);
    va_end(ap);
    c->r->notes++;
}

static int cl_is_ident0(int ch) { return isalpha((unsigned char)ch) || ch == '_'; }
static int cl_is_ident(int ch) { return isalnum((unsigned char)ch) || ch == '_'; }

/* Length of the identifier at s (0 if none), bounded by end. */
static int cl_ident_len(const char *s, const char *end)
{
    int k = 0;
    if (s >= end || !cl_is_ident0(*s)) return 0;
    while (s + k < end && cl_is_ident(s[k])) k++;
    return k;
}

static const char *cl_line_end(cl_ctx *c, int line)
{
    return line < c->nlines ? c->line_at[line + 1] : c->text + c->n;
}

/* First non-blank character of a line. */
static const char *cl_first(cl_ctx *c, int line)
{
    const char *p = c->line_at[line], *e = cl_line_end(c, line);
    while (p < e && (*p == ' ' || *p == '\t')) p++;
    return p;
}

static int cl_find_tag(cl_ctx *c, const char *s, int len)
{
    int i;
    for (i = 0; i < c->ntags; i++)
        if ((int)strlen(c->tags[i].name) == len && !memcmp(c->tags[i].name, s, (size_t)len)) return i;
    return -1;
}

static void cl_copy_name(char *dst, const char *s, int len)
{
    if (len >= CL_NAME_MAX) len = CL_NAME_MAX - 1;
    memcpy(dst, s, (size_t)len);
    dst[len] = 0;
}

static int cl_line_has(cl_ctx *c, int line, const char *needle)
{
    const char *p = c->line_at[line], *e = cl_line_end(c, line);
    size_t k = strlen(needle);
    for (; p + k <= e; p++)
        if (!memcmp(p, needle, k)) return 1;
    return 0;
}

static int cl_split_lines(cl_ctx *c)
{
    size_t i;
    int k = 1;
    c->nlines = 1;
    for (i = 0; i < c->n; i++)
        if (c->text[i] == '\n' && i + 1 < c->n) c->nlines++;
    c->line_at = (const char **)malloc(sizeof(char *) * (size_t)(c->nlines + 2));
    c->sect = (int *)calloc((size_t)(c->nlines + 2), sizeof(int));
    if (!c->line_at || !c->sect) return 0;
    c->line_at[1] = c->text;
    for (i = 0; i < c->n; i++)
        if (c->text[i] == '\n' && i + 1 < c->n) c->line_at[++k] = c->text + i + 1;
    return 1;
}

/* Check 1: table of contents, @@ mentions, declaration banners. */
static void cl_check_tags(cl_ctx *c)
{
    int line, i, last = -1, last_line = 0;
    for (line = 1; line <= c->nlines && !c->toc_line; line++)
        if (cl_line_has(c, line, "TABLE OF CONTENTS")) c->toc_line = line;
    for (line = 1; line <= c->nlines && !c->end_line; line++)
        if (cl_line_has(c, line, "//// end header file")) c->end_line = line;
    if (!c->toc_line) {
        cl_error(c, 0, "no \"TABLE OF CONTENTS\" line: the tags cannot be checked");
        return;
    }
    if (!c->end_line) cl_error(c, 0, "no \"//// end header file\" line between declarations and implementation");
    if (!c->end_line) c->end_line = c->nlines + 1;
    c->tags = (cl_tag *)calloc((size_t)c->nlines + 1, sizeof(cl_tag));
    if (!c->tags) { c->oom = 1; return; }
    /* the table of contents: "@@tag  description" lines up to a blank line or the comment's end */
    for (line = c->toc_line + 1; line <= c->nlines; line++) {
        const char *p = cl_first(c, line), *e = cl_line_end(c, line);
        int len, t;
        if (p >= e || *p == '\n' || *p == '\r' || (p[0] == '*' && p + 1 < e && p[1] == '/')) break;
        if (p[0] != '@' || p + 1 >= e || p[1] != '@') continue; /* a wrapped description */
        len = cl_ident_len(p + 2, e);
        if (!len) { cl_error(c, line, "table of contents: \"@@\" without a tag name"); continue; }
        if ((t = cl_find_tag(c, p + 2, len)) >= 0) {
            cl_error(c, line, "table of contents lists @@%s twice (first at line %d)", c->tags[t].name,
                     c->tags[t].toc_line);
            continue;
        }
        cl_copy_name(c->tags[c->ntags].name, p + 2, len);
        c->tags[c->ntags++].toc_line = line;
        if (cl_line_has(c, line, "*/")) break;
    }
    if (!c->ntags) { cl_error(c, c->toc_line, "the table of contents lists no @@tag"); return; }
    /* every @@word anywhere names a tag */
    for (line = 1; line <= c->nlines; line++) {
        const char *p = c->line_at[line], *e = cl_line_end(c, line);
        for (; p + 1 < e; p++) {
            int len;
            if (p[0] != '@' || p[1] != '@') continue;
            len = cl_ident_len(p + 2, e);
            if (len && cl_find_tag(c, p + 2, len) < 0)
                cl_error(c, line, "@@%.*s is not a tag of the table of contents", len, p + 2);
            p += 1 + len;
        }
    }
    /* declaration banners: lines starting with @@tag between the table of contents and the end */
    for (line = 1; line <= c->nlines; line++) {
        const char *p = cl_first(c, line), *e = cl_line_end(c, line);
        int len, t;
        if (line > c->toc_line && line <= c->tags[c->ntags - 1].toc_line) continue; /* the TOC itself */
        if (p + 1 >= e || p[0] != '@' || p[1] != '@') continue;
        len = cl_ident_len(p + 2, e);
        if ((t = cl_find_tag(c, p + 2, len)) < 0) continue; /* reported above */
        if (line > c->end_line) {
            cl_error(c, line, "declaration banner @@%s after the end of the declarations (line %d); an "
                     "implementation banner reads \">>%s  (@@%s implementation)\"", c->tags[t].name, c->end_line,
                     c->tags[t].name, c->tags[t].name);
            continue;
        }
        if (line < c->toc_line) continue; /* above the table of contents: the manual, not a banner */
        if (c->tags[t].decl_line) {
            cl_error(c, line, "second declaration banner for @@%s (the first is at line %d)", c->tags[t].name,
                     c->tags[t].decl_line);
            continue;
        }
        c->tags[t].decl_line = line;
        if (t < last)
            cl_error(c, line, "declaration banner @@%s comes after @@%s (line %d), but the table of contents lists "
                     "@@%s first: sections must be in the same order everywhere", c->tags[t].name,
                     c->tags[last].name, last_line, c->tags[t].name);
        else { last = t; last_line = line; }
    }
    for (i = 0; i < c->ntags; i++)
        if (!c->tags[i].decl_line)
            cl_error(c, c->tags[i].toc_line, "@@%s has no declaration banner (a line starting with \"@@%s\" "
                     "among the declarations)", c->tags[i].name, c->tags[i].name);
}

/* Check 2: implementation banners. */
static void cl_check_banners(cl_ctx *c)
{
    int line, i, cur = -1, cur_line = 0;
    c->banners = (cl_banner *)calloc((size_t)c->nlines + 1, sizeof(cl_banner));
    if (!c->banners) { c->oom = 1; return; }
    for (line = 1; line <= c->nlines; line++) {
        const char *p = cl_first(c, line), *e = cl_line_end(c, line), *q;
        int len, tlen, t, part = 0, b;
        if (p + 1 >= e || p[0] != '>' || p[1] != '>' || !(len = cl_ident_len(p + 2, e))) continue;
        if (line < c->end_line) {
            cl_error(c, line, "implementation banner >>%.*s before the end of the declarations (line %d)", len,
                     p + 2, c->end_line);
            continue;
        }
        for (b = 0; b < c->nbanners; b++)
            if ((int)strlen(c->banners[b].name) == len && !memcmp(c->banners[b].name, p + 2, (size_t)len))
                cl_error(c, line, "second banner >>%.*s (the first is at line %d)", len, p + 2, c->banners[b].line);
        cl_copy_name(c->banners[c->nbanners].name, p + 2, len); /* kept even when wrong: comments name it */
        c->banners[c->nbanners].line = line;
        c->banners[c->nbanners].tag = -1;
        b = c->nbanners++;
        q = p + 2 + len;
        while (q < e && (*q == ' ' || *q == '\t')) q++;
        if (q < e && *q == '(') {
            q++;
            if (e - q >= 8 && !memcmp(q, "part of ", 8)) { part = 1; q += 8; }
        }
        tlen = (e - q >= 3 && q[0] == '@' && q[1] == '@') ? cl_ident_len(q + 2, e) : 0;
        if (!tlen || e - (q + 2 + tlen) < 15 || memcmp(q + 2 + tlen, " implementation", 15)) {
            cl_error(c, line, "banner >>%.*s names no section: write \">>%.*s  (@@TAG implementation)\" or "
                     "\">>%.*s  (part of @@TAG implementation)\"", len, p + 2, len, p + 2, len, p + 2);
            continue;
        }
        if ((t = cl_find_tag(c, q + 2, tlen)) < 0) continue; /* unknown @@word: reported by check 1 */
        if (!part && (tlen != len || memcmp(p + 2, q + 2, (size_t)len))) {
            cl_error(c, line, "banner >>%.*s says \"(@@%s implementation)\": the banner of another tag's part "
                     "says \"(part of @@%s implementation)\"", len, p + 2, c->tags[t].name, c->tags[t].name);
            continue;
        }
        if (part && cl_find_tag(c, p + 2, len) >= 0) {
            cl_error(c, line, "banner >>%.*s is part of @@%s but has the name of another tag", len, p + 2,
                     c->tags[t].name);
            continue;
        }
        c->banners[b].tag = t;
        if (!c->tags[t].impl_line) c->tags[t].impl_line = line;
        if (t < cur) {
            cl_error(c, line, "banner >>%.*s (@@%s) comes after @@%s (line %d), but the table of contents lists "
                     "@@%s first: sections must be in the same order everywhere, a section's parts together",
                     len, p + 2, c->tags[t].name, c->tags[cur].name, cur_line, c->tags[t].name);
            continue;
        }
        if (t == cur && !part)
            cl_error(c, line, "banner >>%s comes after a part of @@%s (line %d): a section's own banner opens it",
                     c->tags[t].name, c->tags[t].name, c->tags[t].impl_line);
        if (t != cur) { cur = t; cur_line = line; }
    }
    for (i = 0; i < c->ntags; i++)
        if (!c->tags[i].impl_line)
            cl_error(c, c->tags[i].toc_line, "@@%s has no implementation banner (\">>%s  (@@%s implementation)\" "
                     "after the end of the declarations)", c->tags[i].name, c->tags[i].name, c->tags[i].name);
}

/* The section of every line: the last banner above it, in its half; text above a half's first
   banner (includes, config macros) belongs to the first section. */
static void cl_assign_sections(cl_ctx *c)
{
    int line, cur = 0, b = 0;
    int *decl_at = (int *)malloc(sizeof(int) * (size_t)(c->nlines + 2));
    if (!decl_at) { c->oom = 1; return; }
    for (line = 0; line <= c->nlines + 1; line++) decl_at[line] = -1;
    for (line = 0; line < c->ntags; line++)
        if (c->tags[line].decl_line) decl_at[c->tags[line].decl_line] = line;
    for (line = 1; line <= c->nlines; line++) {
        if (line == c->end_line) cur = 0;
        if (line < c->end_line && decl_at[line] >= 0) cur = decl_at[line];
        for (; b < c->nbanners && c->banners[b].line <= line; b++)
            if (c->banners[b].tag >= 0) cur = c->banners[b].tag;
        c->sect[line] = cur;
    }
    free(decl_at);
}

/* ---- tokens -------------------------------------------------------------------------------- */

static void cl_push(cl_ctx *c, const char *s, int len, int line, int kind, int where, char ch)
{
    cl_tok *t;
    if (c->ntoks == c->ctoks) {
        int cap = c->ctoks ? 2 * c->ctoks : 4096;
        cl_tok *p = (cl_tok *)realloc(c->toks, sizeof(cl_tok) * (size_t)cap);
        if (!p) { c->oom = 1; return; }
        c->toks = p;
        c->ctoks = cap;
    }
    t = &c->toks[c->ntoks++];
    t->s = s;
    t->len = len;
    t->line = line;
    t->kind = (unsigned char)kind;
    t->where = (unsigned char)where;
    t->c = ch;
}

static void cl_mention_add(cl_ctx *c, const char *s, int len, int line)
{
    if (c->nmentions == c->cmentions) {
        int cap = c->cmentions ? 2 * c->cmentions : 64;
        cl_mention *m = (cl_mention *)realloc(c->mentions, sizeof(cl_mention) * (size_t)cap);
        if (!m) { c->oom = 1; return; }
        c->mentions = m;
        c->cmentions = cap;
    }
    c->mentions[c->nmentions].s = s;
    c->mentions[c->nmentions].len = len;
    c->mentions[c->nmentions++].line = line;
}

/* Splits the text into identifiers, punctuation and string tokens. Comments vanish (">>x" inside
   them is remembered); preprocessor lines are marked: a #define's body is CL_MACRO, the rest of a
   directive CL_DIRECTIVE. */
static void cl_tokenize(cl_ctx *c)
{
    const char *s = c->text, *end = c->text + c->n;
    size_t i = 0, n = c->n;
    int line = 1, bol = 1, dir = 0, dir_words = 0, is_define = 0;
    while (i < n && !c->oom) {
        char ch = s[i];
        if (ch == '\n') { line++; i++; bol = 1; dir = 0; continue; }
        if (ch == '\\' && i + 1 < n && (s[i + 1] == '\n' || (s[i + 1] == '\r' && i + 2 < n && s[i + 2] == '\n'))) {
            i += s[i + 1] == '\n' ? 2 : 3; /* line splice: a directive goes on */
            line++;
            continue;
        }
        if (ch == ' ' || ch == '\t' || ch == '\r' || ch == '\f' || ch == '\v') { i++; continue; }
        if (ch == '/' && i + 1 < n && s[i + 1] == '*') {
            for (i += 2; i < n && !(s[i] == '*' && i + 1 < n && s[i + 1] == '/'); i++) {
                if (s[i] == '\n') line++;
                else if (s[i] == '>' && i + 2 < n && s[i + 1] == '>' && cl_ident_len(s + i + 2, end))
                    cl_mention_add(c, s + i + 2, cl_ident_len(s + i + 2, end), line);
            }
            i += 2;
            continue;
        }
        if (ch == '/' && i + 1 < n && s[i + 1] == '/') {
            for (i += 2; i < n && s[i] != '\n'; i++) {
                if (s[i] == '\\' && i + 1 < n && s[i + 1] == '\n') { i++; line++; }
                else if (s[i] == '>' && i + 2 < n && s[i + 1] == '>' && cl_ident_len(s + i + 2, end))
                    cl_mention_add(c, s + i + 2, cl_ident_len(s + i + 2, end), line);
            }
            continue;
        }
        if (ch == '#' && bol) { dir = 1; dir_words = 0; is_define = 0; bol = 0; i++; continue; }
        bol = 0;
        if (ch == '"' || ch == '\'') {
            size_t start = i++;
            while (i < n && s[i] != ch && s[i] != '\n') i += (s[i] == '\\' && i + 1 < n) ? 2 : 1;
            if (i < n && s[i] == ch) i++;
            if (!dir || is_define) cl_push(c, s + start, (int)(i - start), line, CL_STRING, dir ? CL_MACRO : CL_CODE, 0);
            continue;
        }
        if (isdigit((unsigned char)ch) || (ch == '.' && i + 1 < n && isdigit((unsigned char)s[i + 1]))) {
            for (i++; i < n; i++) { /* a preprocessing number: 1e-5f, 0x1fULL, 1.5 */
                if ((s[i] == '+' || s[i] == '-') && strchr("eEpP", s[i - 1])) continue;
                if (!cl_is_ident(s[i]) && s[i] != '.') break;
            }
            continue;
        }
        if (cl_is_ident0(ch)) {
            int len = cl_ident_len(s + i, end);
            if (!dir) cl_push(c, s + i, len, line, CL_IDENT, CL_CODE, 0);
            else {
                if (dir_words == 0) is_define = len == 6 && !memcmp(s + i, "define", 6);
                else if (is_define && dir_words > 1) cl_push(c, s + i, len, line, CL_IDENT, CL_MACRO, 0);
                dir_words++;
            }
            i += (size_t)len;
            continue;
        }
        if (!dir || is_define) {
            char pc = ch;
            if (ch == '-' && i + 1 < n && s[i + 1] == '>') { pc = 'A'; i++; } /* -> */
            else if (ch == '>' || ch == '<' || ch == '!' || ch == '=') {
                /* comparisons are not assignments: "==", "<=", ">=", "!=" */
                if (i + 1 < n && s[i + 1] == '=') { pc = '~'; i++; }
            }
            cl_push(c, s + i, 1, line, CL_PUNCT, dir ? CL_MACRO : CL_CODE, pc);
        }
        i++;
    }
}

/* ---- definitions and uses ------------------------------------------------------------------ */

static unsigned cl_hash(const char *s, int len)
{
    unsigned h = 2166136261u;
    int k;
    for (k = 0; k < len; k++) h = (h ^ (unsigned char)s[k]) * 16777619u;
    return h;
}

static int cl_lookup(cl_ctx *c, const char *s, int len)
{
    unsigned h;
    if (!c->hcap) return -1;
    for (h = cl_hash(s, len) & (unsigned)(c->hcap - 1);; h = (h + 1) & (unsigned)(c->hcap - 1)) {
        int d = c->hash[h];
        if (d < 0) return -1;
        if (c->defs[d].len == len && !memcmp(c->defs[d].name, s, (size_t)len)) return d;
    }
}

static void cl_define(cl_ctx *c, const cl_tok *t, int is_fn, int defined)
{
    int d = cl_lookup(c, t->s, t->len), sect = c->sect[t->line];
    unsigned h;
    if (d >= 0) {
        cl_def *o = &c->defs[d];
        if (!defined) return; /* a later tentative declaration changes nothing */
        if (o->defined && o->sect != sect)
            cl_error(c, t->line, "%.*s is defined in @@%s and again in @@%s (line %d)", t->len, t->s,
                     c->tags[o->sect].name, c->tags[sect].name, o->line);
        if (!o->defined) { o->defined = 1; o->sect = sect; o->line = t->line; o->is_fn = is_fn; }
        return;
    }
    if (2 * (c->ndefs + 1) > c->hcap) { /* grow and rehash */
        int cap = c->hcap ? 2 * c->hcap : 1024, k;
        int *hash = (int *)malloc(sizeof(int) * (size_t)cap);
        if (!hash) { c->oom = 1; return; }
        for (k = 0; k < cap; k++) hash[k] = -1;
        free(c->hash);
        c->hash = hash;
        c->hcap = cap;
        for (k = 0; k < c->ndefs; k++) {
            for (h = cl_hash(c->defs[k].name, c->defs[k].len) & (unsigned)(cap - 1); hash[h] >= 0;
                 h = (h + 1) & (unsigned)(cap - 1)) {}
            hash[h] = k;
        }
    }
    if (c->ndefs == c->cdefs) {
        int cap = c->cdefs ? 2 * c->cdefs : 512;
        cl_def *p = (cl_def *)realloc(c->defs, sizeof(cl_def) * (size_t)cap);
        if (!p) { c->oom = 1; return; }
        c->defs = p;
        c->cdefs = cap;
    }
    c->defs[c->ndefs].name = t->s;
    c->defs[c->ndefs].len = t->len;
    c->defs[c->ndefs].line = t->line;
    c->defs[c->ndefs].sect = sect;
    c->defs[c->ndefs].is_fn = is_fn;
    c->defs[c->ndefs].defined = defined;
    for (h = cl_hash(t->s, t->len) & (unsigned)(c->hcap - 1); c->hash[h] >= 0; h = (h + 1) & (unsigned)(c->hcap - 1)) {}
    c->hash[h] = c->ndefs++;
}

static int cl_is_tn(const cl_tok *t) { return t->kind == CL_IDENT && t->len > 3 && !memcmp(t->s, "tn_", 3); }
static int cl_tok_is(const cl_tok *t, const char *w)
{
    return t->kind == CL_IDENT && t->len == (int)strlen(w) && !memcmp(t->s, w, (size_t)t->len);
}
static int cl_is_punct(const cl_tok *t, char ch) { return t && t->kind == CL_PUNCT && t->c == ch; }

/* A name that can be the declarator of a function: not a macro (all capitals) nor __attribute__. */
static int cl_can_declare(const cl_tok *t)
{
    int k, lower = 0;
    if (t->len >= 2 && t->s[0] == '_' && t->s[1] == '_') return 0;
    for (k = 0; k < t->len; k++)
        if (islower((unsigned char)t->s[k])) lower = 1;
    return lower;
}

static int cl_waived(cl_ctx *c, int sect, const cl_tok *t)
{
    int k;
    for (k = 0; k < c->nwaivers; k++)
        if (!strcmp(c->waivers[k].sect, c->tags[sect].name) && (int)strlen(c->waivers[k].name) == t->len &&
            !memcmp(c->waivers[k].name, t->s, (size_t)t->len)) {
            c->waivers[k].used = 1;
            return 1;
        }
    return 0;
}

static void cl_use(cl_ctx *c, const cl_tok *t, const cl_tok *nt)
{
    int d = cl_lookup(c, t->s, t->len), s = c->sect[t->line];
    const cl_def *df;
    if (d < 0) return;
    df = &c->defs[d];
    if (df->sect <= s) return;
    if (cl_waived(c, s, t)) { c->r->waived++; return; }
    cl_error(c, t->line, "@@%s %s %.*s, defined in the later section @@%s (line %d): a section may use only "
             "sections above it%s", c->tags[s].name,
             !df->is_fn ? "uses" : cl_is_punct(nt, '(') ? "calls" : "takes the address of", t->len, t->s,
             c->tags[df->sect].name, df->line, t->where == CL_MACRO ? " (in a macro)" : "");
}

/* Check 4 for one prototype: a public function belongs to the section that declares it. */
static void cl_declared(cl_ctx *c, const cl_tok *t)
{
    int d = cl_lookup(c, t->s, t->len), s = c->sect[t->line];
    if (t->line >= c->end_line || t->s[3] == '_' || d < 0 || !c->defs[d].is_fn || c->defs[d].sect == s) return;
    if (cl_waived(c, s, t)) { c->r->waived++; return; }
    cl_error(c, t->line, "%.*s is declared in @@%s but defined in @@%s (line %d)", t->len, t->s, c->tags[s].name,
             c->tags[c->defs[d].sect].name, c->defs[d].line);
}

/* The token after k in the same stream (code, or the same macro); NULL at its end. */
static const cl_tok *cl_next(cl_ctx *c, int k)
{
    int j;
    if (c->toks[k].where == CL_MACRO)
        return k + 1 < c->ntoks && c->toks[k + 1].where == CL_MACRO ? &c->toks[k + 1] : NULL;
    for (j = k + 1; j < c->ntoks; j++)
        if (c->toks[j].where == CL_CODE) return &c->toks[j];
    return NULL;
}

/* Walks the file-scope structure of the code. Pass 0 collects definitions (functions with a
   body, file-scope variables); pass 1 checks every use against them, and every prototype of the
   declarations against its definition. At file scope (depth 0), names before an '=' are
   declarators, not uses; an "extern "C" {" brace does not count as a level. */
static void cl_walk(cl_ctx *c, int pass)
{
    int k, depth = 0, in_fn = 0, paren = 0, saw_eq = 0, is_typedef = 0, decl = -1, data = -1;
    int prev = -1;
    for (k = 0; k < c->ntoks; k++) {
        const cl_tok *t = &c->toks[k], *pt = prev >= 0 ? &c->toks[prev] : NULL, *nt = cl_next(c, k);
        int member;
        if (t->where == CL_MACRO) { /* a #define body: every tn_ name is a use, unless after . or -> */
            const cl_tok *mp = k > 0 && c->toks[k - 1].where == CL_MACRO ? &c->toks[k - 1] : NULL;
            if (pass == 1 && cl_is_tn(t) && !cl_is_punct(mp, '.') && !cl_is_punct(mp, 'A')) cl_use(c, t, nt);
            continue;
        }
        if (pass == 0 && pt && c->sect[pt->line] != c->sect[t->line] && depth != 0)
            cl_error(c, t->line, "@@%s starts inside a block of @@%s (brace depth %d): unbalanced braces, "
                     "maybe across #if branches?", c->tags[c->sect[t->line]].name, c->tags[c->sect[pt->line]].name,
                     depth);
        prev = k;
        member = cl_is_punct(pt, '.') || cl_is_punct(pt, 'A');
        if (t->kind == CL_PUNCT) {
            switch (t->c) {
            case '(': if (depth == 0) paren++; break;
            case ')': if (depth == 0 && paren > 0) paren--; break;
            case '=': if (depth == 0 && paren == 0) saw_eq = 1; break;
            case '{':
                if (depth == 0 && k >= 2 && c->toks[k - 1].kind == CL_STRING && cl_tok_is(&c->toks[k - 2], "extern"))
                    break; /* extern "C" { */
                if (depth == 0 && !saw_eq && decl >= 0 && !is_typedef) {
                    in_fn = 1;
                    if (pass == 0 && cl_is_tn(&c->toks[decl])) cl_define(c, &c->toks[decl], 1, 1);
                }
                depth++;
                break;
            case '}':
                if (depth == 0) break; /* closes extern "C" */
                depth--;
                if (depth == 0 && in_fn) { in_fn = 0; saw_eq = 0; is_typedef = 0; decl = -1; data = -1; paren = 0; }
                break;
            case ',':
            case ';':
                if (depth != 0 || paren != 0) break;
                if (pass == 0 && data >= 0 && decl < 0 && !is_typedef && cl_is_tn(&c->toks[data]))
                    cl_define(c, &c->toks[data], 0, saw_eq);
                if (pass == 1 && decl >= 0 && !saw_eq && !is_typedef && cl_is_tn(&c->toks[decl]))
                    cl_declared(c, &c->toks[decl]);
                data = -1;
                saw_eq = 0;
                if (t->c == ';') { decl = -1; is_typedef = 0; }
                break;
            default: break;
            }
            continue;
        }
        if (t->kind != CL_IDENT) continue;
        if (depth == 0 && !saw_eq) {
            if (cl_tok_is(t, "typedef")) is_typedef = 1;
            if (cl_is_punct(nt, '(')) {
                if (decl < 0 && cl_can_declare(t)) decl = k;
            } else if (paren == 0 && (cl_is_punct(nt, '[') || cl_is_punct(nt, '=') || cl_is_punct(nt, ';') ||
                                      cl_is_punct(nt, ','))) {
                data = k;
            }
            continue;
        }
        if (pass == 1 && !member && cl_is_tn(t)) cl_use(c, t, nt);
    }
    if (pass == 0 && depth != 0) cl_error(c, c->nlines, "the file ends inside a block (brace depth %d)", depth);
}

/* Parses the allow-list: "@@section name" per line, '#' starts a comment. */
static void cl_read_waivers(cl_ctx *c, const char *text, const char *file)
{
    const char *p = text;
    int line = 0, cap = 0;
    while (p && *p) {
        const char *e = strchr(p, '\n'), *q;
        char sect[CL_NAME_MAX], name[CL_NAME_MAX];
        int a, b;
        if (!e) e = p + strlen(p);
        line++;
        for (q = p; q < e && *q != '#'; q++) {}
        if (sscanf(p, " @@%63[A-Za-z0-9_] %63[A-Za-z0-9_]", sect, name) == 2 && (int)strlen(sect) < (int)(q - p)) {
            if (c->nwaivers == cap) {
                cl_waiver *w;
                cap = cap ? 2 * cap : 16;
                w = (cl_waiver *)realloc(c->waivers, sizeof(cl_waiver) * (size_t)cap);
                if (!w) { c->oom = 1; return; }
                c->waivers = w;
            }
            strcpy(c->waivers[c->nwaivers].sect, sect);
            strcpy(c->waivers[c->nwaivers].name, name);
            c->waivers[c->nwaivers++].used = 0;
        } else {
            for (a = 0; p + a < q && isspace((unsigned char)p[a]); a++) {}
            for (b = 0; p + a + b < q && !isspace((unsigned char)p[a + b]); b++) {}
            if (p + a < q) {
                char msg[CL_MSG_MAX];
                snprintf(msg, sizeof msg, "%s:%d: not an allow-list entry (\"@@section name\"): %.*s\n", file, line,
                         (int)(q - p - a), p + a);
                cl_put(c->r, msg);
                c->r->errors++;
            }
        }
        p = *e ? e + 1 : e;
    }
}

static int cl_list_defs; /* --defs: print every definition found (to see what the check sees) */

/* Checks one header text. file names it in messages; allow (may be NULL) is the allow-list text.
   Appends the messages to r and returns the number of violations that are not waived. */
static int cl_check(const char *file, const char *text, size_t n, const char *allow, const char *allow_file,
                    cl_report *r)
{
    cl_ctx c;
    int k;
    memset(&c, 0, sizeof c);
    c.file = file;
    c.text = text;
    c.n = n;
    c.r = r;
    if (allow) cl_read_waivers(&c, allow, allow_file ? allow_file : "allow-list");
    if (!cl_split_lines(&c)) c.oom = 1;
    if (!c.oom) cl_check_tags(&c);
    if (!c.oom && c.ntags) {
        cl_check_banners(&c);
        if (!c.oom) cl_assign_sections(&c);
        if (!c.oom) cl_tokenize(&c);
        for (k = 0; k < c.nmentions && !c.oom; k++) {
            int b, found = 0;
            const cl_mention *m = &c.mentions[k];
            for (b = 0; b < c.nbanners && !found; b++)
                found = (int)strlen(c.banners[b].name) == m->len && !memcmp(c.banners[b].name, m->s, (size_t)m->len);
            if (!found) cl_error(&c, m->line, "the comment names >>%.*s, but there is no such banner", m->len, m->s);
        }
        if (!c.oom) cl_walk(&c, 0);
        if (!c.oom) cl_walk(&c, 1);
        if (cl_list_defs)
            for (k = 0; k < c.ndefs; k++)
                printf("%s:%d: @@%s %s %.*s%s\n", file, c.defs[k].line, c.tags[c.defs[k].sect].name,
                       c.defs[k].is_fn ? "function" : "variable", c.defs[k].len, c.defs[k].name,
                       c.defs[k].defined ? "" : " (tentative)");
    }
    for (k = 0; k < c.nwaivers && !c.oom; k++)
        if (!c.waivers[k].used)
            cl_note(&c, 0, "allow-list entry \"@@%s %s\" matches nothing any more: delete it", c.waivers[k].sect,
                    c.waivers[k].name);
    if (c.oom) { cl_put(r, "check_layout: out of memory\n"); r->errors++; }
    free(c.line_at);
    free(c.sect);
    free(c.tags);
    free(c.banners);
    free(c.toks);
    free(c.mentions);
    free(c.defs);
    free(c.hash);
    free(c.waivers);
    return r->errors;
}

/* Reads a whole file into a NUL-terminated buffer; NULL if it cannot. */
static char *cl_read_file(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    char *buf = NULL;
    long size;
    if (!f) return NULL;
    if (fseek(f, 0, SEEK_END) == 0 && (size = ftell(f)) >= 0 && fseek(f, 0, SEEK_SET) == 0 &&
        (buf = (char *)malloc((size_t)size + 1)) != NULL) {
        if (fread(buf, 1, (size_t)size, f) != (size_t)size) { free(buf); buf = NULL; }
        else { buf[size] = 0; *n = (size_t)size; }
    }
    fclose(f);
    return buf;
}

#ifndef CHECK_LAYOUT_NO_MAIN
int main(int argc, char **argv)
{
    const char *header = "terrainnet.h", *allow_path = "tests/layout_allow.txt";
    char *text, *allow;
    size_t n, an;
    cl_report r;
    int i;
    for (i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--allow") && i + 1 < argc) allow_path = argv[++i];
        else if (!strcmp(argv[i], "--defs")) cl_list_defs = 1;
        else if (argv[i][0] == '-') {
            fprintf(stderr, "usage: check_layout [--allow FILE] [--defs] [HEADER]\n");
            return 2;
        } else header = argv[i];
    }
    if (!(text = cl_read_file(header, &n))) {
        fprintf(stderr, "check_layout: cannot read %s\n", header);
        return 2;
    }
    allow = cl_read_file(allow_path, &an); /* a missing allow-list waives nothing */
    memset(&r, 0, sizeof r);
    cl_check(header, text, n, allow, allow_path, &r);
    if (r.text) fputs(r.text, stdout);
    printf("check_layout: %s: %d violation%s%s", header, r.errors, r.errors == 1 ? "" : "s",
           r.waived ? "" : "\n");
    if (r.waived) printf(" (%d more waived by %s)\n", r.waived, allow_path);
    cl_report_free(&r);
    free(text);
    free(allow);
    return r.errors ? 1 : 0;
}
#endif
