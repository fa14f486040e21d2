/* fuzz_replay.h - the main() every fuzz driver gets when built without libFuzzer
   (-DTN_FUZZ_MAIN): runs each file named on the command line through LLVMFuzzerTestOneInput
   once, so a crash found elsewhere replays under any compiler or sanitizer. Define
   TN_FUZZ_NAME before including. */
#ifdef TN_FUZZ_MAIN
#include <stdio.h>
#include <stdlib.h>
int main(int argc, char **argv)
{
    int i, ran = 0;
    for (i = 1; i < argc; i++) {
        FILE *f = fopen(argv[i], "rb");
        uint8_t *buf;
        long len;
        if (!f) { fprintf(stderr, "%s: cannot open\n", argv[i]); continue; }
        if (fseek(f, 0, SEEK_END) != 0 || (len = ftell(f)) < 0 || fseek(f, 0, SEEK_SET) != 0) { fclose(f); continue; }
        buf = (uint8_t *)malloc((size_t)len + 1);
        if (buf && fread(buf, 1, (size_t)len, f) == (size_t)len) {
            LLVMFuzzerTestOneInput(buf, (size_t)len);
            ran++;
        }
        free(buf);
        fclose(f);
    }
    printf("%s: ran %d inputs\n", TN_FUZZ_NAME, ran);
    return 0;
}
#endif
