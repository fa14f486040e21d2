/* bench_season: @@season (paper 003) figures, all measured in this run.
   - insolation vs the closed forms: worst relative error of the flat plane over 7 latitudes x 12
     months, and of a 30-degree south-facing plane (Klein 1977), with and without the horizon test;
   - the year (12 maps) of a 1024 x 1024 real DEM (alps_n47e009_full, 62.6 x 92.6 m pixels) on 1
     and 2 threads, next to the same run without terrain shadows (the horizon's share);
   - the procedural texturer: one month and a year of a 4096 x 4096 heightfield (the 1024 DEM
     upsampled bicubically, 15.65 x 23.15 m pixels), insolation included;
   - hemisphere (paper Figure 7): Cfb at 46 N against the same climate shifted by six months at
     46 S on the same DEM: RMSE between month m and month m + 6 textures (0 = same sequence),
     next to the RMSE between months m and m + 6 at 46 N (how different the seasons are).
   - real data (../shared/data/seasonal_slovenia, Sentinel-2 NDVI, cloud and no-data masks): the
     procedural texturer's greenness (Cfb, Ljubljana normals at the patch's 664-801 m, no fit to
     the images) against the masked mean NDVI of every 2017 frame under 30 % cloud; a linear map
     green -> NDVI fitted on 2017 then predicts the 2015 frames (held out), next to the
     same-month-of-2017 baseline (mean NDVI of 2017's frames in that calendar month).
   GRASS r.sun comparison: bench/compare_rsun.sh (needs grass). Prints `name: value unit` lines.
   Usage: bench_season [threads] [ndvi]   (default 2; `ndvi` runs only the real-data part) */
#include "terrainnet.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PI 3.14159265358979323846

static const char *data_path(const char *rel)
{
    static char buf[1024];
    const char *d = getenv("TN_SHARED_DATA");
    snprintf(buf, sizeof buf, "%s/%s", d && d[0] ? d : "../shared/data", rel);
    return buf;
}

static double ws_of(double phi, double d)
{
    double c = -tan(phi) * tan(d);
    return c <= -1 ? PI : c >= 1 ? 0 : acos(c);
}

/* Klein's daily extraterrestrial insolation on a south-facing plane of slope beta (beta 0 = flat). */
static double klein(double lat, double beta, int doy)
{
    double d, e, phi = lat * PI / 180, pb = (lat - beta) * PI / 180, w1, w2, ws;
    tn_sun_day(&d, &e, doy);
    w1 = ws_of(phi, d);
    w2 = ws_of(pb, d);
    ws = w1 < w2 ? w1 : w2;
    return 24.0 / PI * 1367.0 * e * (cos(pb) * cos(d) * sin(ws) + ws * sin(pb) * sin(d));
}

static double analytic_error(double beta, int shadows)
{
    static const double lats[] = {0, 15, 30, 45.8, 60, 70, 85};
    tn_image dem = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_insolation_opts o;
    double worst = 0, g = tan(beta * PI / 180);
    int x, y, m;
    size_t l;
    tn_image_create(&dem, 16, 16, 1);
    for (y = 0; y < 16; y++)
        for (x = 0; x < 16; x++) dem.data[y * 16 + x] = (float)(500 + g * (15 - y) * 10.0);
    memset(&o, 0, sizeof o);
    o.dx = 10;
    o.no_shadows = !shadows;
    for (l = 0; l < sizeof lats / sizeof lats[0]; l++) {
        if (beta > 0 && lats[l] < beta) continue; /* Klein's form assumes the slope faces the equator */
        if (tn_insolation(&out, &dem, lats[l], &o)) { fprintf(stderr, "%s\n", tn_last_error()); exit(1); }
        for (m = 0; m < 12; m++) {
            double ref = klein(lats[l], beta, tn_day_of_year(m + 1, 15)), v = TN_PIXEL(&out, 8, 8, m);
            double err = ref > 1 ? fabs(v - ref) / ref : fabs(v - ref) / 1000.0;
            if (err > worst) worst = err;
        }
        tn_image_free(&out);
    }
    tn_image_free(&dem);
    return worst;
}

static double rmse_rgb(const tn_image *a, const tn_image *b)
{
    double s = 0;
    size_t i, n = (size_t)a->width * a->height * 3;
    for (i = 0; i < n; i++) s += (double)(a->data[i] - b->data[i]) * (a->data[i] - b->data[i]);
    return sqrt(s / n);
}

/* Masked mean NDVI of one frame (cloud and no-data pixels left out); -2 if none is clear. */
static double frame_ndvi(const char *stem)
{
    char p[512];
    tn_image nd = {0, 0, 0, NULL}, cl = {0, 0, 0, NULL}, no = {0, 0, 0, NULL};
    double s = 0;
    size_t i, n, k = 0;
    snprintf(p, sizeof p, "seasonal_slovenia/frames/%s_ndvi.pfm", stem);
    if (tn_image_load(&nd, data_path(p), NULL)) return -2;
    snprintf(p, sizeof p, "seasonal_slovenia/frames/%s_cloud.pgm", stem);
    if (tn_image_load(&cl, data_path(p), NULL)) { tn_image_free(&nd); return -2; }
    snprintf(p, sizeof p, "seasonal_slovenia/frames/%s_nodata.pgm", stem);
    if (tn_image_load(&no, data_path(p), NULL)) { tn_image_free(&nd); tn_image_free(&cl); return -2; }
    n = (size_t)nd.width * nd.height;
    if (cl.width == nd.width && cl.height == nd.height && no.width == nd.width && no.height == nd.height)
        for (i = 0; i < n; i++)
            if (cl.data[i] < 0.5f && no.data[i] < 0.5f && isfinite(nd.data[i])) s += nd.data[i], k++;
    tn_image_free(&nd); tn_image_free(&cl); tn_image_free(&no);
    return k ? s / k : -2;
}

static int ndvi_check(void)
{
    static const int first[12] = {0, 31, 59, 90, 120, 151, 181, 212, 243, 273, 304, 334};
    char line[256], stems[64][32];
    float times[64];
    int year[64], month[64], nf = 0, i;
    double obs[64], green[64], sx = 0, sy = 0, sxx = 0, syy = 0, sxy = 0, a, b, r, mae_m = 0, mae_b = 0;
    double msum[12] = {0}, mcnt[12] = {0};
    int k17 = 0, k15 = 0;
    FILE *f = fopen(data_path("seasonal_slovenia/frames.csv"), "r");
    tn_image dem = {0, 0, 0, NULL}, out[64];
    tn_season_state st[64];
    tn_season_opts so;
    tn_climate c;
    if (!f || tn_image_load(&dem, data_path("seasonal_slovenia/dem_m.pfm"), NULL)) {
        printf("# no seasonal_slovenia data\n");
        if (f) fclose(f);
        return 0;
    }
    while (fgets(line, sizeof line, f) && nf < 64) {
        int y, mo, d;
        double cf;
        char stem[32];
        if (sscanf(line, "%d-%d-%d%*[^,],%31[^,],%lf", &y, &mo, &d, stem, &cf) != 5 || cf > 0.3) continue;
        if ((obs[nf] = frame_ndvi(stem)) < -1) continue;
        snprintf(stems[nf], sizeof stems[nf], "%s", stem);
        year[nf] = y;
        month[nf] = mo - 1;
        times[nf] = (float)((first[mo - 1] + d - 15) / (365.0 / 12.0));
        nf++;
    }
    fclose(f);
    memset(&so, 0, sizeof so);
    so.insolation.dx = 10.0f;
    so.detail = -1;
    tn_climate_koppen(&c, "Cfb");
    if (tn_season_texture(out, &dem, &c, 45.87, NULL, times, nf, &so, st)) { fprintf(stderr, "%s\n", tn_last_error()); return 1; }
    for (i = 0; i < nf; i++) {
        size_t q, n = (size_t)dem.width * dem.height;
        double g = 0;
        for (q = 0; q < n; q++) g += st[i].green.data[q];
        green[i] = g / n;
        tn_image_free(&out[i]);
        tn_season_state_free(&st[i]);
        if (year[i] != 2017) continue;
        k17++;
        sx += green[i]; sy += obs[i]; sxx += green[i] * green[i]; syy += obs[i] * obs[i]; sxy += green[i] * obs[i];
        msum[month[i]] += obs[i];
        mcnt[month[i]] += 1;
    }
    r = (sxy - sx * sy / k17) / sqrt((sxx - sx * sx / k17) * (syy - sy * sy / k17));
    b = (sxy - sx * sy / k17) / (sxx - sx * sx / k17);
    a = (sy - b * sx) / k17;
    for (i = 0; i < nf; i++) {
        if (year[i] != 2015 || !mcnt[month[i]]) continue;
        k15++;
        mae_m += fabs(a + b * green[i] - obs[i]);
        mae_b += fabs(msum[month[i]] / mcnt[month[i]] - obs[i]);
        printf("# %s: ndvi %.3f  model %.3f  same-month-2017 %.3f\n", stems[i], obs[i], a + b * green[i], msum[month[i]] / mcnt[month[i]]);
    }
    printf("ndvi_2017_frames: %d (cloud <= 30 %%)\n", k17);
    printf("ndvi_2017_pearson_procedural_greenness: %.3f\n", r);
    if (k15) {
        printf("ndvi_2015_heldout_mae_procedural: %.3f (%d frames, green -> ndvi fitted on 2017)\n", mae_m / k15, k15);
        printf("ndvi_2015_heldout_mae_same_month_2017: %.3f\n", mae_b / k15);
    }
    tn_image_free(&dem);
    return 0;
}

int main(int argc, char **argv)
{
    int threads = argc > 1 ? atoi(argv[1]) : 2, m;
    tn_image dem = {0, 0, 0, NULL}, big = {0, 0, 0, NULL}, ins = {0, 0, 0, NULL};
    tn_insolation_opts o;
    tn_season_opts so;
    tn_climate c, cs;
    double t0, t1, t2, tns;
    size_t i, n;
    float times[12];
    tn_image tex[12], texs[12];
    if (argc > 2 && !strcmp(argv[2], "ndvi")) return ndvi_check();
    if (threads < 1) threads = 2;

    printf("insolation_flat_max_rel_error: %.2e (7 latitudes x 12 months)\n", analytic_error(0, 1));
    printf("insolation_south30_max_rel_error_no_shadows: %.2e\n", analytic_error(30, 0));
    printf("insolation_south30_max_rel_error_shadows: %.2e\n", analytic_error(30, 1));

    if (tn_image_load(&dem, data_path("dem/alps_n47e009/alps_n47e009_full.png"), NULL)) {
        printf("# no ../shared/data: %s\n", tn_last_error());
        return 0;
    }
    n = (size_t)dem.width * dem.height;
    for (i = 0; i < n; i++) dem.data[i] = 388.0f + dem.data[i] * (2937.0f - 388.0f);
    memset(&o, 0, sizeof o);
    o.dx = 62.6f;
    o.dy = 92.6f;
    tn_set_threads(1);
    t0 = tn_time_seconds();
    tn_insolation(&ins, &dem, 47.4, &o);
    t1 = tn_time_seconds() - t0;
    tn_image_free(&ins);
    tn_set_threads(threads);
    t0 = tn_time_seconds();
    tn_insolation(&ins, &dem, 47.4, &o);
    t2 = tn_time_seconds() - t0;
    tn_image_free(&ins);
    o.no_shadows = 1;
    t0 = tn_time_seconds();
    tn_insolation(&ins, &dem, 47.4, &o);
    tns = tn_time_seconds() - t0;
    tn_image_free(&ins);
    printf("insolation_year_1024_t1: %.2f s\n", t1);
    printf("insolation_year_1024_t%d: %.2f s (speed-up %.2f)\n", threads, t2, t1 / t2);
    printf("insolation_year_1024_no_shadows_t%d: %.2f s (horizon share %.0f %%)\n", threads, tns, 100.0 * (t2 - tns) / t2);

    /* 4096^2 texturing */
    memset(&so, 0, sizeof so);
    so.insolation.dx = 62.6f / 4;
    so.insolation.dy = 92.6f / 4;
    so.shade = 0.5f;
    tn_climate_koppen(&c, "Cfb");
    if (tn_image_resize(&big, &dem, 4096, 4096, TN_RESIZE_BICUBIC)) return 1;
    times[0] = 3.0f;
    t0 = tn_time_seconds();
    if (tn_season_texture(tex, &big, &c, 47.4, NULL, times, 1, &so, NULL)) { fprintf(stderr, "%s\n", tn_last_error()); return 1; }
    t1 = tn_time_seconds() - t0;
    tn_image_free(&tex[0]);
    printf("season_texture_4096_one_month_t%d: %.2f s (insolation at 1024 included)\n", threads, t1);
    for (m = 0; m < 12; m++) times[m] = (float)m;
    t0 = tn_time_seconds();
    if (tn_season_texture(tex, &big, &c, 47.4, NULL, times, 12, &so, NULL)) { fprintf(stderr, "%s\n", tn_last_error()); return 1; }
    t1 = tn_time_seconds() - t0;
    for (m = 0; m < 12; m++) tn_image_free(&tex[m]);
    printf("season_texture_4096_year_t%d: %.2f s\n", threads, t1);
    tn_image_free(&big);

    /* hemisphere: a 256 crop, Cfb at 46 N vs Cfb shifted six months at 46 S */
    {
        tn_image crop = {0, 0, 0, NULL};
        double same = 0, shifted = 0;
        tn_image_crop(&crop, &dem, 416, 720, 256, 256);
        so.insolation.dx = 62.6f;
        so.insolation.dy = 92.6f;
        cs = c;
        for (m = 0; m < 12; m++) cs.t[m] = c.t[(m + 6) % 12], cs.p[m] = c.p[(m + 6) % 12];
        if (tn_season_texture(tex, &crop, &c, 46.0, NULL, times, 12, &so, NULL) ||
            tn_season_texture(texs, &crop, &cs, -46.0, NULL, times, 12, &so, NULL)) { fprintf(stderr, "%s\n", tn_last_error()); return 1; }
        for (m = 0; m < 12; m++) {
            shifted += rmse_rgb(&tex[m], &texs[(m + 6) % 12]) / 12;
            same += rmse_rgb(&tex[m], &tex[(m + 6) % 12]) / 12;
        }
        printf("hemisphere_rmse_north_m_vs_south_m_plus_6: %.4f (rgb 0..1; mirrored sun, same terrain)\n", shifted);
        printf("hemisphere_rmse_north_m_vs_north_m_plus_6: %.4f (baseline: how much six months change)\n", same);
        for (m = 0; m < 12; m++) { tn_image_free(&tex[m]); tn_image_free(&texs[m]); }
        tn_image_free(&crop);
    }
    tn_image_free(&dem);
    return ndvi_check();
}
