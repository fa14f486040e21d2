/* test_progress.c - @@core progress output: tn_progress_line fits the given width exactly, fills
   the bar in proportion, formats durations (seconds, minutes, hours, unknown) and survives odd
   input (NaN or out-of-range fractions, a NULL stage, tiny buffers). */
#include "terrainnet.h"
#include "tn_test.h"

static int count(const char *s, char c)
{
    int n = 0;
    for (; *s; s++) n += *s == c;
    return n;
}

TN_TEST(line_fits_and_fills)
{
    char buf[200];
    size_t cols;
    for (cols = 57; cols <= 160; cols += 13) { /* the bar stops growing at 63 */
        tn_progress_line(buf, cols, "texgan-train", 0.5, 12.34, 12.34);
        TN_CHECK(strlen(buf) == (cols <= 112 ? cols - 1 : 111));
    }
    tn_progress_line(buf, 81, "style", 0.25, 3.0, 9.0);
    TN_CHECK(strlen(buf) == 80);
    TN_CHECK(count(buf, '#') == 8 && strchr(buf, ']') - strchr(buf, '[') == 33); /* a bar 32 wide, a quarter full */
    TN_CHECK(strstr(buf, " 25.0%") != NULL && strstr(buf, "3.0s") != NULL && strstr(buf, "ETA   9.0s") != NULL);
    TN_CHECK(strncmp(buf, "style              [", 20) == 0);
    tn_progress_line(buf, 81, "style", 1.0, 3.0, 0.0);
    TN_CHECK(count(buf, '#') == 32 && strstr(buf, "100.0%") != NULL);
}

TN_TEST(durations)
{
    char buf[200];
    tn_progress_line(buf, 81, "a", 0.1, 245.0, 2.0 * 3600.0 + 7.0 * 60.0 + 30.0);
    TN_CHECK(strstr(buf, " 4m05s  ETA  2h07m") != NULL);
    tn_progress_line(buf, 81, "a", 0.1, 0.0, -1.0);
    TN_CHECK(strstr(buf, "ETA     --") != NULL);
    tn_progress_line(buf, 81, "a", 0.1, 1e9, 1e9);
    TN_CHECK(strstr(buf, "999h+  ETA  999h+") != NULL);
}

TN_TEST(odd_input)
{
    char buf[200], tiny[4];
    tn_progress_line(buf, 81, NULL, NAN, NAN, NAN);
    TN_CHECK(strlen(buf) == 80 && strstr(buf, "  0.0%") != NULL && count(buf, '#') == 0);
    tn_progress_line(buf, 81, "a very long stage name indeed", 7.0, 1.0, 1.0);
    TN_CHECK(strlen(buf) == 80 && strstr(buf, "100.0%") != NULL && strncmp(buf, "a very long stage  [", 20) == 0);
    tn_progress_line(buf, 40, "narrow", 0.5, 1.0, 1.0); /* no room for a bar: the numbers only */
    TN_CHECK(strchr(buf, '[') == NULL && strlen(buf) <= 39 && strstr(buf, " 50.0%") != NULL);
    tn_progress_line(tiny, sizeof tiny, "abc", 0.5, 1.0, 1.0);
    TN_CHECK(strlen(tiny) == 3);
    tn_progress_line(tiny, 1, "abc", 0.5, 1.0, 1.0);
    TN_CHECK(tiny[0] == 0);
}

int main(void)
{
    TN_RUN(line_fits_and_fills);
    TN_RUN(durations);
    TN_RUN(odd_input);
    return tn_test_summary("test_progress");
}
