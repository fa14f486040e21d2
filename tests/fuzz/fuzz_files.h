/* fuzz_files.h - scratch files for fuzz drivers whose code under test reads paths (model loaders,
   season lists): one directory per process under $TMPDIR (or /tmp), made on first use. */
#ifndef FUZZ_FILES_H
#define FUZZ_FILES_H
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#if defined(__unix__) || defined(__APPLE__)
#include <sys/stat.h>
#include <unistd.h>
#define FUZZ_PID ((long)getpid())
#define FUZZ_MKDIR(d) mkdir(d, 0700)
#else
#include <direct.h>
#define FUZZ_PID 0L
#define FUZZ_MKDIR(d) _mkdir(d)
#endif

static char fuzz_dir[400], fuzz_leaves[16][32];
static int fuzz_nleaves;

/* Removes the scratch files and directory at exit. */
static void fuzz_cleanup(void)
{
    char p[512];
    int i;
    for (i = 0; i < fuzz_nleaves; i++) {
        snprintf(p, sizeof p, "%.400s/%.31s", fuzz_dir, fuzz_leaves[i]);
        remove(p);
    }
    remove(fuzz_dir);
}

/* The path of `leaf` (a short name) in this process's scratch directory (a static buffer of four
   in turn). */
static const char *fuzz_path(const char *leaf)
{
    static char buf[4][512];
    static int k;
    int i;
    if (!fuzz_dir[0]) {
        const char *t = getenv("TMPDIR");
        snprintf(fuzz_dir, sizeof fuzz_dir, "%s/tn_fuzz_%ld", t && t[0] ? t : "/tmp", FUZZ_PID);
        FUZZ_MKDIR(fuzz_dir);
        atexit(fuzz_cleanup);
    }
    for (i = 0; i < fuzz_nleaves && strcmp(fuzz_leaves[i], leaf); i++) {}
    if (i == fuzz_nleaves && i < 16) snprintf(fuzz_leaves[fuzz_nleaves++], sizeof fuzz_leaves[0], "%s", leaf);
    k = (k + 1) & 3;
    snprintf(buf[k], sizeof buf[k], "%s/%s", fuzz_dir, leaf);
    return buf[k];
}

/* Writes n bytes to path; 0 on failure (the driver then skips the input). */
static int fuzz_write(const char *path, const void *data, size_t n)
{
    FILE *f = fopen(path, "wb");
    int ok = f && fwrite(data, 1, n, f) == n;
    if (f && fclose(f) != 0) ok = 0;
    return ok;
}
#endif
