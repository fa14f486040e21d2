/* bench_geotiff.c - GeoTIFF read/write speed on a 3601 x 3601 int16 DEM (an SRTM-1 tile's size),
   against GDAL in the same run when gdal_translate is installed.
   The DEM is the shared SRTM-3 tile N47E009 resampled bicubically to 3601^2 (a Perlin map in
   metres when the data is absent). terrainnet writes it as int16 Deflate + predictor 2; GDAL
   (gdal_translate -co COMPRESS=DEFLATE -co PREDICTOR=2) writes it too. Printed, best of 3:
     geotiff_read_<who wrote>_ms   tn_image_load of the file (all threads, chunks in parallel)
     gdal_translate_raw_ms         gdal_translate -of ENVI of GDAL's file (decode + raw write)
     geotiff_write_int16_ms / geotiff_write_float32_ms, and the file sizes. */
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static double best_load(const char *path, int threads)
{
    double best = 1e30;
    int k;
    tn_set_threads(threads);
    for (k = 0; k < 3; k++) {
        tn_image img = {0, 0, 0, NULL};
        double t0 = tn_time_seconds();
        if (tn_image_load(&img, path, NULL) != TN_OK) { fprintf(stderr, "%s: %s\n", path, tn_last_error()); return -1; }
        t0 = tn_time_seconds() - t0;
        if (t0 < best) best = t0;
        tn_image_free(&img);
    }
    tn_set_threads(0);
    return best * 1e3;
}

static long file_size(const char *path)
{
    FILE *f = fopen(path, "rb");
    long n = -1;
    if (f && fseek(f, 0, SEEK_END) == 0) n = ftell(f);
    if (f) fclose(f);
    return n;
}

int main(int argc, char **argv)
{
    const char *dir = argc > 1 ? argv[1] : "/tmp";
    const char *hgt = "../shared/data/dem/alps_n47e009/original/N47E009.hgt";
    char tn_path[512], gd_path[512], raw_path[512], cmd[2048];
    tn_image src = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL};
    tn_save_opts so;
    double t0, best;
    int k, gdal;
    snprintf(tn_path, sizeof tn_path, "%s/bench_geotiff_tn.tif", dir);
    snprintf(gd_path, sizeof gd_path, "%s/bench_geotiff_gdal.tif", dir);
    snprintf(raw_path, sizeof raw_path, "%s/bench_geotiff_gdal.raw", dir);
    if (tn_image_load(&src, hgt, NULL) == TN_OK) {
        if (tn_image_resize(&dem, &src, 3601, 3601, TN_RESIZE_BICUBIC) != TN_OK) return 1;
        printf("dem: N47E009.hgt resampled to 3601 x 3601\n");
    } else {
        tn_perlin_opts po;
        size_t i;
        memset(&po, 0, sizeof po);
        if (tn_noise_perlin(&dem, 3601, 3601, &po) != TN_OK) return 1;
        for (i = 0; i < (size_t)3601 * 3601; i++) dem.data[i] = 400.0f + 2500.0f * dem.data[i];
        printf("dem: Perlin noise 3601 x 3601 (shared data absent)\n");
    }
    printf("threads: %d\n", tn_get_threads());
    memset(&so, 0, sizeof so);
    for (k = 0, best = 1e30; k < 3; k++) {
        so.bit_depth = 32;
        t0 = tn_time_seconds();
        if (tn_image_save(tn_path, &dem, &so) != TN_OK) { fprintf(stderr, "%s\n", tn_last_error()); return 1; }
        t0 = tn_time_seconds() - t0;
        if (t0 < best) best = t0;
    }
    printf("geotiff_write_float32_ms: %.1f ms\ngeotiff_float32_size: %.2f MB\n", best * 1e3, file_size(tn_path) / 1e6);
    for (k = 0, best = 1e30; k < 3; k++) {
        so.bit_depth = 16;
        t0 = tn_time_seconds();
        if (tn_image_save(tn_path, &dem, &so) != TN_OK) { fprintf(stderr, "%s\n", tn_last_error()); return 1; }
        t0 = tn_time_seconds() - t0;
        if (t0 < best) best = t0;
    }
    printf("geotiff_write_int16_ms: %.1f ms\ngeotiff_int16_size: %.2f MB\n", best * 1e3, file_size(tn_path) / 1e6);
    printf("geotiff_read_tn_written_ms: %.1f ms\n", best_load(tn_path, 0));
    printf("geotiff_read_tn_written_1thread_ms: %.1f ms\n", best_load(tn_path, 1));
    snprintf(cmd, sizeof cmd, "gdal_translate -q -co COMPRESS=DEFLATE -co PREDICTOR=2 %s %s 2>/dev/null", tn_path, gd_path);
    gdal = system("gdal_translate --version > /dev/null 2>&1") == 0 && system(cmd) == 0;
    if (!gdal) {
        printf("gdal_translate: not installed (no GDAL baseline)\n");
        return 0;
    }
    printf("gdal_int16_size: %.2f MB\n", file_size(gd_path) / 1e6);
    {
        double tn_ms = best_load(gd_path, 0), tn1_ms = best_load(gd_path, 1), gd_ms = 1e30;
        snprintf(cmd, sizeof cmd, "gdal_translate -q -of ENVI %s %s", gd_path, raw_path);
        for (k = 0; k < 3; k++) {
            t0 = tn_time_seconds();
            if (system(cmd) != 0) return 1;
            t0 = tn_time_seconds() - t0;
            if (t0 * 1e3 < gd_ms) gd_ms = t0 * 1e3;
        }
        printf("geotiff_read_gdal_written_ms: %.1f ms\n", tn_ms);
        printf("geotiff_read_gdal_written_1thread_ms: %.1f ms\n", tn1_ms);
        printf("gdal_translate_raw_ms: %.1f ms\n", gd_ms);
        printf("read_speedup_vs_gdal_translate: %.2f x\n", gd_ms / tn_ms);
        printf("read_speedup_vs_gdal_translate_1thread: %.2f x\n", gd_ms / tn1_ms);
    }
    remove(raw_path);
    snprintf(cmd, sizeof cmd, "%s.hdr", raw_path);
    remove(cmd);
    snprintf(cmd, sizeof cmd, "%s/bench_geotiff_gdal.raw.aux.xml", dir);
    remove(cmd);
    remove(tn_path);
    remove(gd_path);
    tn_image_free(&dem);
    tn_image_free(&src);
    return 0;
}
