/* test_layout: the section-layout checker (tests/check_layout.c) on the real header, and on
   copies of it with planted violations that must each be reported at the right line - and
   look-alikes (a call written only in a comment or a string) that must not. Run from the
   repository root, like every test; without terrainnet.h in the working directory it skips. */
#define CHECK_LAYOUT_NO_MAIN
#include "check_layout.c"
#include "tn_test.h"

static char *header;   /* terrainnet.h as read (NUL-terminated) */
static size_t header_n;
static char *allow;    /* tests/layout_allow.txt, NULL if absent */
static cl_report rep;  /* the report of the last check() */

/* Checks text (NUL-terminated) with the given allow-list; returns the violation count. */
static int check(const char *text, const char *allow_text)
{
    cl_report_free(&rep);
    return cl_check("terrainnet.h", text, strlen(text), allow_text, "allow", &rep);
}

/* A copy of text with the first occurrence of find replaced by repl; the test fails when find
   is not there (the header changed under the test). Caller frees. */
static char *edit(const char *text, const char *find, const char *repl)
{
    const char *at = strstr(text, find);
    size_t n = strlen(text), a, f = strlen(find), r = strlen(repl);
    char *out;
    TN_CHECK(at != NULL);
    if (!at) at = text + n, f = 0;
    a = (size_t)(at - text);
    out = (char *)malloc(n - f + r + 1);
    if (!out) exit(1);
    memcpy(out, text, a);
    memcpy(out + a, repl, r);
    memcpy(out + a + r, at + f, n - a - f + 1);
    return out;
}

/* *text = edit(*text, find, repl), freeing the old copy. */
static void redo(char **text, const char *find, const char *repl)
{
    char *t = edit(*text, find, repl);
    free(*text);
    *text = t;
}

/* Line (1-based) of the first occurrence of s in text, 0 if none. */
static int line_of(const char *text, const char *s)
{
    const char *at = strstr(text, s), *p;
    int line = 1;
    if (!at) return 0;
    for (p = text; p < at; p++) line += *p == '\n';
    return line;
}

/* Does the report have a message at this line (any line if 0) containing both words? */
static int reported(int line, const char *w1, const char *w2)
{
    char key[64];
    const char *p = rep.text ? rep.text : "";
    snprintf(key, sizeof key, "terrainnet.h:%d: ", line);
    while (*p) {
        const char *e = strchr(p, '\n');
        size_t n = e ? (size_t)(e - p) : strlen(p);
        char msg[CL_MSG_MAX + 400];
        if (n >= sizeof msg) n = sizeof msg - 1;
        memcpy(msg, p, n);
        msg[n] = 0;
        if ((!line || !strncmp(msg, key, strlen(key))) && (!w1 || strstr(msg, w1)) && (!w2 || strstr(msg, w2)))
            return 1;
        p += n + (e != NULL);
    }
    return 0;
}

/* Prints the report, so a failure shows what the checker said. */
static void show_report(const char *why)
{
    const char *p = rep.text ? rep.text : "";
    while (*p) {
        const char *e = strchr(p, '\n');
        int n = e ? (int)(e - p) : (int)strlen(p);
        fprintf(stderr, "FAIL %s: %.*s\n", why, n, p);
        p += n + (e != NULL);
    }
}

#define NEED_HEADER() \
    do { if (!header) TN_SKIP("terrainnet.h not in the working directory"); } while (0)

TN_TEST(real_header_passes)
{
    NEED_HEADER();
    if (check(header, allow) != 0) show_report("terrainnet.h layout");
    TN_CHECK(rep.errors == 0);
    if (rep.waived) fprintf(stderr, "note: %d layout violations waived by tests/layout_allow.txt\n", rep.waived);
}

/* The table of contents with @@metrics and @@gemm swapped: their banners are now out of order. */
TN_TEST(swapped_toc_entries)
{
    char *a;
    NEED_HEADER();
    a = edit(header, "    @@metrics   ", "    @@TMPSWAP   ");
    redo(&a, "    @@gemm      ", "    @@metrics   ");
    redo(&a, "    @@TMPSWAP   ", "    @@gemm      ");
    TN_CHECK(check(a, NULL) > 0);
    /* @@gemm's declaration banner now comes after @@metrics although the TOC lists gemm first */
    TN_CHECK(reported(line_of(a, "\n   @@gemm  ") + 1, "declaration banner @@gemm comes after @@metrics", NULL));
    TN_CHECK(reported(line_of(a, "   >>gemm  (@@gemm implementation)"), "banner >>gemm (@@gemm) comes after @@metrics",
                      NULL));
    free(a);
}

/* Two implementation banners swapped (>>noise now opens the code of @@sketch and vice versa). */
TN_TEST(swapped_implementation_banners)
{
    char *a;
    NEED_HEADER();
    a = edit(header, "   >>noise  (@@noise implementation)", "   >>TMP  (@@noise implementation)");
    redo(&a, "   >>sketch  (@@sketch implementation)", "   >>noise  (@@noise implementation)");
    redo(&a, "   >>TMP  (@@noise implementation)", "   >>sketch  (@@sketch implementation)");
    TN_CHECK(check(a, NULL) > 0);
    TN_CHECK(reported(line_of(a, "   >>noise  (@@noise implementation)"), "banner >>noise (@@noise) comes after @@sketch", NULL));
    free(a);
}

/* A banner that names no section, and one that names a tag outside the table of contents. */
TN_TEST(banner_without_tag)
{
    char *a;
    NEED_HEADER();
    a = edit(header, "   >>metrics  (@@metrics implementation)", "   >>metrics  (image comparison)");
    TN_CHECK(check(a, NULL) > 0);
    TN_CHECK(reported(line_of(a, "   >>metrics  (image comparison)"), "banner >>metrics names no section", NULL));
    TN_CHECK(reported(0, "@@metrics has no implementation banner", NULL));
    free(a);
    a = edit(header, "   >>loss  (@@loss implementation)", "   >>loss  (@@losses implementation)");
    TN_CHECK(check(a, NULL) > 0);
    TN_CHECK(reported(line_of(a, ">>loss  (@@losses"), "@@losses is not a tag", NULL));
    free(a);
    /* a sub-part claiming to be a section of its own, and one that is not in @@ order */
    a = edit(header, "   >>png  (part of @@io implementation)", "   >>png  (@@io implementation)");
    TN_CHECK(check(a, NULL) > 0);
    TN_CHECK(reported(line_of(a, "   >>png  (@@io"), "banner >>png says \"(@@io implementation)\"", NULL));
    free(a);
    a = edit(header, "   >>render  (@@render implementation)",
             "   >>render  (@@render implementation)\n   >>late_image  (part of @@image implementation)");
    TN_CHECK(check(a, NULL) > 0);
    TN_CHECK(reported(line_of(a, "   >>late_image"), "banner >>late_image (@@image) comes after @@render", NULL));
    free(a);
    /* a >>name in a comment must name a banner */
    a = edit(header, "   Uses the tn__vd SIMD layer from >>imageops.", "   Uses the tn__vd SIMD layer from >>imgops.");
    TN_CHECK(check(a, NULL) > 0);
    TN_CHECK(reported(line_of(a, ">>imgops"), "no such banner", NULL));
    free(a);
}

/* A tag missing from the table of contents, and a second declaration banner. */
TN_TEST(tags_and_declaration_banners)
{
    char *a;
    NEED_HEADER();
    a = edit(header, "    @@loss      MSE,", "    @@lossy     MSE,");
    TN_CHECK(check(a, NULL) > 0);
    TN_CHECK(reported(line_of(a, "   @@loss  losses"), "@@loss is not a tag", NULL));
    TN_CHECK(reported(line_of(a, "    @@lossy "), "@@lossy has no declaration banner", NULL));
    free(a);
    a = edit(header, "   @@render  previews", "   @@metrics  again\n   @@render  previews");
    TN_CHECK(check(a, NULL) > 0);
    TN_CHECK(reported(line_of(a, "   @@metrics  again"), "second declaration banner for @@metrics", NULL));
    free(a);
}

/* Calls from an early section into later ones, in code, through a function pointer and in macros
   of both halves; each at its line. */
TN_TEST(forward_calls_reported)
{
    const char *planted =
        "static int tn__planted_call(const tn_image *img)\n"
        "{\n"
        "    return tn_image_save(\"x.png\", img, NULL) != TN_OK;\n" /* @@core -> @@io */
        "}\n"
        "static void *tn__planted_ptr(void)\n"
        "{\n"
        "    tn_status (*fn)(const tn_image *, const tn_image *, tn_image *) = tn_render_preview;\n"
        "    return (void *)&fn;\n"
        "}\n"
        "#define TN__PLANTED_FREE(p) tn_params_free(p)\n"
        "\n/* --------------------------------------------------------------------------------------------\n"
        "   >>thread  (@@thread implementation)";
    char *a;
    NEED_HEADER();
    a = edit(header, "/* --------------------------------------------------------------------------------------------\n"
                     "   >>thread  (@@thread implementation)", planted);
    redo(&a, "TN_API void tn_set_threads(int n);",
         "TN_API void tn_set_threads(int n);\n#define TN_PLANTED_DECL_MACRO(m) tn_noise_perlin(m, 8, 8, NULL)");
    TN_CHECK(check(a, NULL) == 4);
    TN_CHECK(reported(line_of(a, "    return tn_image_save("), "@@core calls tn_image_save", "@@io"));
    TN_CHECK(reported(line_of(a, "= tn_render_preview;"), "@@core takes the address of tn_render_preview", "@@render"));
    TN_CHECK(reported(line_of(a, "#define TN__PLANTED_FREE"), "tn_params_free", "(in a macro)"));
    TN_CHECK(reported(line_of(a, "#define TN_PLANTED_DECL_MACRO"), "@@thread calls tn_noise_perlin", "@@noise"));
    if (rep.errors != 4) show_report("forward_calls_reported");
    free(a);
}

/* The same names in comments, strings, character literals, member accesses and prototypes are
   not uses; a call to an earlier section is fine. */
TN_TEST(look_alikes_not_reported)
{
    const char *planted =
        "/* tn__planted_quiet calls tn_render_preview() and tn_image_save() - in a comment only */\n"
        "static const char *tn__planted_quiet(void)\n"
        "{\n"
        "    // tn_style_transfer(out, noise, src, NULL); is only a line comment\n"
        "    const char *s = \"tn_texgan_train(\\\"model\\\")\";\n"
        "    char q = 't'; /* tn_render_view */\n"
        "    (void)q;\n"
        "    tn_status tn_render_preview_result = TN_OK; /* a local name with the prefix, not a function */\n"
        "    (void)tn_render_preview_result;\n"
        "    (void)tn_status_string(TN_OK);\n" /* same section */
        "    return s;\n"
        "}\n"
        "TN_API tn_status tn_image_save(const char *path, const tn_image *img, const tn_save_opts *opts);\n"
        "\n/* --------------------------------------------------------------------------------------------\n"
        "   >>thread  (@@thread implementation)";
    char *a;
    NEED_HEADER();
    a = edit(header, "/* --------------------------------------------------------------------------------------------\n"
                     "   >>thread  (@@thread implementation)", planted);
    TN_CHECK(check(a, NULL) == 0);
    if (rep.errors) show_report("look_alikes_not_reported");
    free(a);
}

/* A public function declared among one section's declarations but defined in another's code. */
TN_TEST(declaration_in_wrong_section)
{
    char *a;
    NEED_HEADER();
    a = edit(header, "TN_API void tn_set_threads(int n);",
             "TN_API void tn_set_threads(int n);\nTN_API tn_status tn_metrics_planted(void);");
    redo(&a, "   >>metrics  (@@metrics implementation)\n", "   >>metrics  (@@metrics implementation)\n"
             "   -------------------------------------------------------------------------------------------- */\n"
             "TN_API tn_status tn_metrics_planted(void) { return TN_OK; }\n/*\n");
    TN_CHECK(check(a, NULL) == 1);
    TN_CHECK(reported(line_of(a, "TN_API tn_status tn_metrics_planted(void);"),
                      "tn_metrics_planted is declared in @@thread but defined in @@metrics", NULL));
    if (rep.errors != 1) show_report("declaration_in_wrong_section");
    free(a);
}

/* The allow-list waives a listed (section, name) pair; a stale entry is only a note; a
   malformed line is an error. */
TN_TEST(allow_list)
{
    char *a;
    NEED_HEADER();
    a = edit(header, "TN_API void tn_set_threads(int n);",
             "TN_API void tn_set_threads(int n);\n#define TN_PLANTED_DECL_MACRO(m) tn_noise_perlin(m, 8, 8, NULL)");
    TN_CHECK(check(a, "# planted\n@@thread tn_noise_perlin   # until fixed\n") == 0);
    TN_CHECK(rep.waived == 1 && rep.notes == 0);
    TN_CHECK(check(a, "@@core tn_noise_perlin\n") == 1); /* the wrong section does not waive it */
    TN_CHECK(rep.notes == 1);
    TN_CHECK(strstr(rep.text, "\"@@core tn_noise_perlin\" matches nothing any more") != NULL);
    TN_CHECK(check(header, "tn_noise_perlin\n") == 1);
    TN_CHECK(strstr(rep.text, "allow:1: not an allow-list entry") != NULL);
    free(a);
}

/* A small header written from scratch: the smallest layout that passes, then broken ways. */
TN_TEST(tiny_header)
{
    const char *ok =
        "/* tiny\nTABLE OF CONTENTS\n    @@a   first\n    @@b   second\n          (wrapped)\n*/\n"
        "#ifdef __cplusplus\nextern \"C\" {\n#endif\n"
        "/* ==\n   @@a  first\n   == */\nvoid tn_a(void);\n"
        "/* ==\n   @@b  second\n   == */\nvoid tn_b(void);\nstatic inline int tn_b_inline(void) { return 2; }\n"
        "#ifdef __cplusplus\n}\n#endif\n"
        "/* //// end header file //// */\n"
        "#ifdef __cplusplus\nextern \"C\" {\n#endif\n"
        "/* --\n   >>a  (@@a implementation)\n   -- */\n"
        "static int tn__table[2] = {1, 2};\n"
        "void tn_a(void) { (void)tn__table; }\n"
        "/* --\n   >>b  (@@b implementation)\n   -- */\n"
        "static void tn__b1(void) { tn_a(); }\n"
        "/* --\n   >>b_more  (part of @@b implementation; uses >>b)\n   -- */\n"
        "void tn_b(void) { tn__b1(); if (tn__table[0] == 1) tn_a(); }\n"
        "#ifdef __cplusplus\n}\n#endif\n";
    char *a;
    TN_CHECK(check(ok, NULL) == 0);
    if (rep.errors) show_report("tiny_header ok");
    /* a calls b's static helper through a prototype; and a's variable is defined in b */
    a = edit(ok, "void tn_a(void) { (void)tn__table; }",
             "static void tn__b1(void);\nvoid tn_a(void) { (void)tn__table; tn__b1(); }");
    TN_CHECK(check(a, NULL) == 1 && reported(line_of(a, "void tn_a(void) {"), "@@a calls tn__b1", "@@b"));
    redo(&a, "static int tn__table[2] = {1, 2};", "static int tn__table[2];");
    redo(&a, "static void tn__b1(void) { tn_a(); }", "static int tn__table[2] = {1, 2};\nstatic void tn__b1(void) { tn_a(); }");
    TN_CHECK(check(a, NULL) == 2 && reported(line_of(a, "void tn_a(void) {"), "@@a uses tn__table", "@@b"));
    free(a);
    /* no end-of-header line; a banner before it */
    a = edit(ok, "/* //// end header file //// */\n", "");
    TN_CHECK(check(a, NULL) > 0 && reported(0, "no \"//// end header file\" line", NULL));
    TN_CHECK(reported(line_of(a, "   >>a  ("), "implementation banner >>a before the end", NULL));
    free(a);
    /* a tag without an implementation */
    a = edit(ok, "/* --\n   >>b  (@@b implementation)\n   -- */\n", "");
    redo(&a, "   >>b_more  (part of @@b implementation; uses >>b)", "   >>b_more  (part of @@b implementation)");
    TN_CHECK(check(a, NULL) == 0); /* parts alone may open a section (as @@io's >>png does) */
    free(a);
    a = edit(ok, "   >>b_more  (part of @@b implementation; uses >>b)", "   >>b_more  (part of @@b implementation)");
    redo(&a, "/* --\n   >>b  (@@b implementation)\n   -- */\n", "");
    redo(&a, "void tn_b(void) {", "/* --\n   >>b  (@@b implementation)\n   -- */\nvoid tn_b(void) {");
    TN_CHECK(check(a, NULL) == 1 && reported(line_of(a, "   >>b  ("), "a section's own banner opens it", NULL));
    free(a);
    /* no table of contents at all */
    a = edit(ok, "TABLE OF CONTENTS", "CONTENTS");
    TN_CHECK(check(a, NULL) == 1 && reported(0, "no \"TABLE OF CONTENTS\" line", NULL));
    free(a);
}

int main(void)
{
    size_t allow_n;
    header = cl_read_file("terrainnet.h", &header_n);
    allow = cl_read_file("tests/layout_allow.txt", &allow_n); /* waivers, while the lead fixes the header */
    TN_RUN(real_header_passes);
    TN_RUN(swapped_toc_entries);
    TN_RUN(swapped_implementation_banners);
    TN_RUN(banner_without_tag);
    TN_RUN(tags_and_declaration_banners);
    TN_RUN(forward_calls_reported);
    TN_RUN(look_alikes_not_reported);
    TN_RUN(declaration_in_wrong_section);
    TN_RUN(allow_list);
    TN_RUN(tiny_header);
    cl_report_free(&rep);
    free(header);
    free(allow);
    return tn_test_summary("test_layout");
}
