/* tn_test.h - the tiny harness every tests/test_*.c uses.
   TN_TEST(name) { ... TN_CHECK(cond); ... }   and in main: TN_RUN(name); return tn_test_summary("file");
   A test passes when none of its checks fail; TN_SKIP("why") marks it skipped (e.g. no ../shared/data).
   The last line of every test program is "<file>: N passed, N failed, N skipped". */
#ifndef TN_TEST_H
#define TN_TEST_H
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>

static int tn_test_passed, tn_test_failed, tn_test_skipped;
static int tn_test_cur_failed, tn_test_cur_skipped;
static const char *tn_test_cur_name;

#define TN_TEST(name) static void name(void)
#define TN_CHECK(cond)                                                                   \
    do {                                                                                 \
        if (!(cond)) {                                                                   \
            fprintf(stderr, "FAIL %s (%s:%d): %s\n", tn_test_cur_name, __FILE__, __LINE__, #cond); \
            tn_test_cur_failed++;                                                        \
        }                                                                                \
    } while (0)
/* Checks |a - b| <= tol and prints both values when it fails. */
#define TN_CHECK_NEAR(a, b, tol)                                                         \
    do {                                                                                 \
        double tn__a = (double)(a), tn__b = (double)(b);                                 \
        if (!(fabs(tn__a - tn__b) <= (double)(tol))) {                                   \
            fprintf(stderr, "FAIL %s (%s:%d): %s = %.9g, %s = %.9g, tol %g\n", tn_test_cur_name, \
                    __FILE__, __LINE__, #a, tn__a, #b, tn__b, (double)(tol));            \
            tn_test_cur_failed++;                                                        \
        }                                                                                \
    } while (0)
#define TN_SKIP(why)                                                                     \
    do {                                                                                 \
        fprintf(stderr, "skipped %s: %s\n", tn_test_cur_name, why);                      \
        tn_test_cur_skipped = 1;                                                         \
        return;                                                                          \
    } while (0)
#define TN_RUN(name)                                                                     \
    do {                                                                                 \
        tn_test_cur_name = #name;                                                        \
        tn_test_cur_failed = 0;                                                          \
        tn_test_cur_skipped = 0;                                                         \
        name();                                                                          \
        if (tn_test_cur_failed) tn_test_failed++;                                        \
        else if (tn_test_cur_skipped) tn_test_skipped++;                                 \
        else tn_test_passed++;                                                           \
    } while (0)

static const char *tn_test_data(const char *rel);
static const char *tn_test_ref(const char *rel);

/* A scratch file path $TMPDIR/tn_test_<tag>_<leaf> (or /tmp); four buffers rotate, so up to
   four paths can be in use at once. */
static const char *tn_test_tmp_path(const char *tag, const char *leaf)
{
    static char buf[4][512];
    static int k;
    const char *dir = getenv("TMPDIR");
    k = (k + 1) & 3;
    snprintf(buf[k], sizeof buf[k], "%s/tn_test_%s_%s", dir && dir[0] ? dir : "/tmp", tag, leaf);
    return buf[k];
}

static int tn_test_summary(const char *file)
{
    (void)tn_test_data; /* not every test file reads shared data or writes scratch files */
    (void)tn_test_tmp_path;
    (void)tn_test_ref;
    printf("%s: %d passed, %d failed, %d skipped\n", file, tn_test_passed, tn_test_failed, tn_test_skipped);
    return tn_test_failed ? 1 : 0;
}

/* Path of a reference file kept in the repository (tests/refs/, tests run from the top). */
static const char *tn_test_ref(const char *rel)
{
    static char buf[512];
    snprintf(buf, sizeof buf, "tests/refs/%s", rel);
    return buf;
}

/* Path of a file under ../shared/data (or $TN_SHARED_DATA), or NULL when it is not there. */
static const char *tn_test_data(const char *rel)
{
    static char buf[1024];
    const char *root = getenv("TN_SHARED_DATA");
    FILE *f;
    if (!root) root = "../shared/data";
    snprintf(buf, sizeof buf, "%s/%s", root, rel);
    f = fopen(buf, "rb");
    if (!f) return NULL;
    fclose(f);
    return buf;
}
#endif
