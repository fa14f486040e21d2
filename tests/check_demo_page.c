/* check_demo_page.c - judges a headless-Chromium screenshot of demo/index.html (tests/demo_page.sh).
   usage: check_demo_page SHOT.png BOXES.txt
   BOXES.txt is the page's own report (its load script): "images: N", then one line per picture,
   "LOADED X Y W H" in CSS pixels (= screenshot pixels at device scale 1). Passes (exit 0) when
   the screenshot is not blank and every picture inside it loaded and shows an image: its box has
   a luminance spread a flat placeholder or a broken-image icon on the grey box does not have.
   Prints "name: value" lines and one FAIL line per bad picture. */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <string.h>
#include <math.h>

/* Mean and standard deviation of the luminance over a box (clipped to the image). */
static void box_stats(const tn_image *s, int x0, int y0, int w, int h, double *mean, double *sd)
{
    double sum = 0, sq = 0;
    long n = 0;
    int x, y;
    for (y = y0 < 0 ? 0 : y0; y < y0 + h && y < s->height; y++)
        for (x = x0 < 0 ? 0 : x0; x < x0 + w && x < s->width; x++) {
            double l = s->channels >= 3 ? 0.299 * TN_PIXEL(s, x, y, 0) + 0.587 * TN_PIXEL(s, x, y, 1) + 0.114 * TN_PIXEL(s, x, y, 2)
                                        : TN_PIXEL(s, x, y, 0);
            sum += l;
            sq += l * l;
            n++;
        }
    *mean = n ? sum / n : 0;
    *sd = n ? sqrt(fmax(0.0, sq / n - *mean * *mean)) : 0;
}

int main(int argc, char **argv)
{
    tn_image shot = {0, 0, 0, NULL};
    FILE *f;
    char line[256];
    int images = -1, seen = 0, checked = 0, bad = 0;
    double mean, sd;
    if (argc != 3) {
        fprintf(stderr, "usage: check_demo_page SHOT.png BOXES.txt\n");
        return 2;
    }
    if (tn_image_load(&shot, argv[1], NULL)) {
        fprintf(stderr, "check_demo_page: %s\n", tn_last_error());
        return 1;
    }
    if (!(f = fopen(argv[2], "r"))) {
        fprintf(stderr, "check_demo_page: cannot read %s\n", argv[2]);
        tn_image_free(&shot);
        return 1;
    }
    box_stats(&shot, 0, 0, shot.width, shot.height, &mean, &sd);
    printf("screenshot: %d x %d, luminance mean %.3f sd %.3f\n", shot.width, shot.height, mean, sd);
    if (sd < 0.05) {
        printf("FAIL the screenshot is blank\n");
        bad++;
    }
    while (fgets(line, sizeof line, f)) {
        int loaded, x, y, w, h;
        if (sscanf(line, "images: %d", &images) == 1) continue;
        if (sscanf(line, "%d %d %d %d %d", &loaded, &x, &y, &w, &h) != 5) continue;
        seen++;
        if (!loaded) {
            printf("FAIL picture %d did not load\n", seen);
            bad++;
            continue;
        }
        if (w < 16 || h < 16 || x < 0 || y < 0 || x + w > shot.width || y + h > shot.height) continue; /* outside the shot */
        checked++;
        box_stats(&shot, x, y, w, h, &mean, &sd);
        printf("picture %d: box %d %d %d %d, luminance mean %.3f sd %.3f\n", seen, x, y, w, h, mean, sd);
        if (sd < 0.04) {
            printf("FAIL picture %d shows no image (flat box)\n", seen);
            bad++;
        }
    }
    fclose(f);
    tn_image_free(&shot);
    if (images < 1 || seen != images) {
        printf("FAIL the page reported %d pictures, listed %d\n", images, seen);
        bad++;
    }
    if (checked * 2 < seen) {
        printf("FAIL only %d of %d pictures lie inside the screenshot\n", checked, seen);
        bad++;
    }
    printf("check_demo_page: %d pictures, %d checked in the screenshot, %d failures\n", seen, checked, bad);
    return bad ? 1 : 0;
}
