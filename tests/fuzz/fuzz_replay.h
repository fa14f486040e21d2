/* fuzz_replay.h - the main() every fuzz driver gets when built without libFuzzer
   (-DTN_FUZZ_MAIN): runs each file named on the command line through LLVMFuzzerTestOneInput
   once, so a crash found elsewhere replays under any compiler or sanitizer. Without arguments it
   replays the committed corpus, every file of tests/fuzz/seeds and tests/fuzz/corpus/NAME (run
   from the repository root), and ends with the test summary line `make test` counts. Define
   TN_FUZZ_NAME before including. */
#ifdef TN_FUZZ_MAIN
#include <stdio.h>
#include <stdlib.h>
#if defined(__unix__) || defined(__APPLE__)
#include <dirent.h>
#include <sys/stat.h>
#endif

/* Runs one file; 1 if it was read (a crash or sanitizer report ends the process instead). */
static int tn_fuzz_run_file(const char *path)
{
    FILE *f = fopen(path, "rb");
    uint8_t *buf;
    long len;
    int ran = 0;
    if (!f) { fprintf(stderr, "%s: cannot open\n", path); return 0; }
    if (fseek(f, 0, SEEK_END) != 0 || (len = ftell(f)) < 0 || fseek(f, 0, SEEK_SET) != 0) { fclose(f); return 0; }
    buf = (uint8_t *)malloc((size_t)len + 1);
    if (buf && fread(buf, 1, (size_t)len, f) == (size_t)len) {
        LLVMFuzzerTestOneInput(buf, (size_t)len);
        ran = 1;
    }
    free(buf);
    fclose(f);
    return ran;
}

/* Every regular file of dir; -1 if dir cannot be listed. */
static int tn_fuzz_run_dir(const char *dir)
{
    int ran = 0;
#if defined(__unix__) || defined(__APPLE__)
    DIR *d = opendir(dir);
    struct dirent *e;
    char path[1024];
    struct stat sb;
    if (!d) return -1;
    while ((e = readdir(d)) != NULL) {
        snprintf(path, sizeof path, "%s/%s", dir, e->d_name);
        if (e->d_name[0] != '.' && stat(path, &sb) == 0 && S_ISREG(sb.st_mode)) ran += tn_fuzz_run_file(path);
    }
    closedir(d);
#else
    (void)dir;
    ran = -1;
#endif
    return ran;
}

int main(int argc, char **argv)
{
    int i, ran = 0;
    if (argc < 2) {
        int a = tn_fuzz_run_dir("tests/fuzz/seeds"), b = tn_fuzz_run_dir("tests/fuzz/corpus/" TN_FUZZ_NAME);
        if (a < 0 && b < 0) {
            printf("skipped %s: no tests/fuzz/seeds or tests/fuzz/corpus/%s here (run from the repository root)\n", TN_FUZZ_NAME, TN_FUZZ_NAME);
            printf("%s: 0 passed, 0 failed, 1 skipped\n", TN_FUZZ_NAME);
            return 0;
        }
        /* every input ran to its end: no crash, no sanitizer report, no failed check */
        printf("%s: %d passed, 0 failed, 0 skipped\n", TN_FUZZ_NAME, (a > 0 ? a : 0) + (b > 0 ? b : 0));
        return 0;
    }
    for (i = 1; i < argc; i++) ran += tn_fuzz_run_file(argv[i]);
    printf("%s: ran %d inputs\n", TN_FUZZ_NAME, ran);
    return 0;
}
#endif
