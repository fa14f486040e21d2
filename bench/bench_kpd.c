/* bench_kpd: the KPD seasonal texture network (paper 003) on real and paired data.
     bench_kpd [REAL_MINUTES [TABLE_MINUTES [real|table|speed|all]]]   (defaults 5, 3, all; a negative
     REAL_MINUTES -N trains the real part for N iterations instead, for runs beside other work)
   real:  Sentinel-2 NDVI of ../shared/data/seasonal_slovenia: trained on the 2017 frames, scored
          on the 2015 dates it never saw, next to the nearest-date 2017 frame and the mean of the
          2017 frames of the same calendar month (clouds and no-data left out everywhere).
   table: the paper's Table 1 on pairs from the procedural texturer: 4 DEMs x 6 Koppen climates
          for training, 2 other DEMs x 2 other climates held out; every condition trained for
          TABLE_MINUTES; RMSE (0..255), SSIM, a multi-scale gradient distance (in place of LPIPS,
          which needs downloaded weights), dAD and dSSIM of consecutive months; the hemisphere
          test (a climate shifted by six months, latitude mirrored); interpolation of gamma/beta
          between months vs interpolation of the output pictures, against the texturer's truth
          half-way between months.
   speed: texturing a 4096 x 4096 heightfield (one month, and between two months).
   Prints `name: value unit` lines. */
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>

static const char *data_path(const char *rel)
{
    static char buf[1024];
    const char *root = getenv("TN_SHARED_DATA");
    snprintf(buf, sizeof buf, "%s/%s", root ? root : "../shared/data", rel);
    return buf;
}

static int quiet(void *u, const char *s, double f)
{
    (void)u; (void)s; (void)f;
    return 0;
}

/* masked RMSE of a against b over pixels valid in m1 (and m2 when given) */
static double masked_rmse(const tn_image *a, const tn_image *b, const tn_image *m1, const tn_image *m2, double *count)
{
    size_t k, n = (size_t)a->width * a->height;
    double s = 0, c = 0;
    for (k = 0; k < n; k++) {
        if (m1 && m1->data[k] <= 0.5f) continue;
        if (m2 && m2->data[k] <= 0.5f) continue;
        s += (a->data[k] - b->data[k]) * (a->data[k] - b->data[k]);
        c++;
    }
    if (count) *count = c;
    return c > 0 ? sqrt(s / c) : NAN;
}

static int real_part(double minutes)
{
    tn_season_data d;
    tn_season_sample tr[64];
    tn_kpd_opts o;
    tn_kpd m;
    tn_kpd_stats st;
    int n = 0, i, j;
    double se[4] = {0, 0, 0, 0}, cnt = 0, t0, course[3] = {0, 0, 0};
    int nco = 0;
    char csv[1100];
    const char *root = getenv("TN_SHARED_DATA");
    FILE *f;
    /* the example file's paths are relative to examples/data; a TN_SHARED_DATA elsewhere gets a copy */
    snprintf(csv, sizeof csv, "examples/data/slovenia_season.csv");
    if (root) {
        char line[2048];
        FILE *in = fopen(csv, "r");
        snprintf(csv, sizeof csv, "/tmp/bench_kpd_slovenia.csv");
        f = fopen(csv, "w");
        while (in && f && fgets(line, sizeof line, in)) {
            char *p;
            while ((p = strstr(line, "../../../shared/data/"))) {
                char rest[2048];
                snprintf(rest, sizeof rest, "%s", p + 21);
                snprintf(p, sizeof line - (size_t)(p - line), "%s/%s", root, rest);
            }
            fputs(line, f);
        }
        if (in) fclose(in);
        if (f) fclose(f);
    }
    if (tn_season_data_load(&d, csv)) {
        printf("# real: no seasonal_slovenia data (%s)\n", tn_last_error());
        return 0;
    }
    for (i = 0; i < d.count; i++)
        if (!strncmp(d.labels[i], "2017", 4)) tr[n++] = d.samples[i];
    memset(&o, 0, sizeof o);
    o.lo = d.lo;
    o.hi = d.hi;
    if (minutes < 0) o.train.max_iters = (long)-minutes, o.train.minutes = 1e6;
    else o.train.minutes = minutes;
    t0 = tn_time_seconds();
    if (tn_kpd_train(&m, tr, n, &o, &st)) {
        printf("# real: %s\n", tn_last_error());
        return 1;
    }
    printf("ndvi_train_frames: %d (2017, clear pixels only)\n", n);
    printf("ndvi_train_iterations: %ld (%.3f s/it, %.1f s)\n", st.iterations, st.seconds_per_iter, tn_time_seconds() - t0);
    printf("ndvi_train_l1: %.4f first, %.4f last 50 NDVI\n", st.loss_l1_first, st.loss_l1);
    for (i = 0; i < d.count; i++) {
        const tn_season_sample *q = &d.samples[i];
        tn_image out = {0, 0, 0, NULL}, rnd = {0, 0, 0, NULL}, mean = {0, 0, 0, NULL}, mcount = {0, 0, 0, NULL};
        int best = -1, mon;
        float bd = 99;
        size_t k, np = (size_t)q->dem->width * q->dem->height;
        double c, e[4];
        if (strncmp(d.labels[i], "2015", 4)) continue;
        mon = atoi(d.labels[i] + 5);
        tn_image_create(&mean, q->dem->width, q->dem->height, 1);
        tn_image_create(&mcount, q->dem->width, q->dem->height, 1);
        for (j = 0; j < d.count; j++) {
            float dt;
            size_t v = 0;
            if (strncmp(d.labels[j], "2017", 4)) continue;
            for (k = 0; k < np; k++) v += d.samples[j].mask->data[k] > 0.5f;
            if (atoi(d.labels[j] + 5) == mon)
                for (k = 0; k < np; k++)
                    if (d.samples[j].mask->data[k] > 0.5f) mean.data[k] += d.samples[j].target->data[k], mcount.data[k] += 1;
            if (v < np / 2) continue;
            dt = fabsf(d.samples[j].time - q->time);
            if (dt > 6) dt = 12 - dt;
            if (dt < bd) bd = dt, best = j;
        }
        for (k = 0; k < np; k++) {
            if (mcount.data[k] > 0) mean.data[k] /= mcount.data[k];
            mcount.data[k] = mcount.data[k] > 0;
        }
        if (tn_kpd_generate(&out, &m, q->dem, q->climate, q->insolation, q->time, 0, 0, q->dem->width, q->dem->height) ||
            tn_kpd_generate(&rnd, &m, q->dem, q->climate, q->insolation, floorf(q->time + 0.5f), 0, 0, q->dem->width, q->dem->height)) {
            printf("# real: %s\n", tn_last_error());
            return 1;
        }
        /* every score over the pixels valid in the truth, the nearest 2017 frame and the month mean */
        for (k = 0; k < np; k++)
            if (d.samples[best].mask->data[k] <= 0.5f) mcount.data[k] = 0;
        e[0] = masked_rmse(&out, q->target, q->mask, &mcount, &c);
        e[1] = masked_rmse(d.samples[best].target, q->target, q->mask, &mcount, NULL);
        e[2] = masked_rmse(&mean, q->target, q->mask, &mcount, NULL);
        e[3] = masked_rmse(&rnd, q->target, q->mask, &mcount, NULL);
        { /* the course of the season: mean NDVI of the picture's usable pixels */
            double so = 0, sm = 0, sn = 0, sb = 0, sa = 0;
            for (k = 0; k < np; k++)
                if (q->mask->data[k] > 0.5f && mcount.data[k] > 0.5f) so += q->target->data[k], sm += out.data[k], sb += d.samples[best].target->data[k], sa += mean.data[k], sn++;
            printf("# %s mean NDVI: observed %.3f, KPD %.3f, nearest 2017 frame %.3f, 2017 month mean %.3f\n", d.labels[i], so / sn, sm / sn, sb / sn, sa / sn);
            course[0] += fabs(sm / sn - so / sn);
            course[1] += fabs(sb / sn - so / sn);
            course[2] += fabs(sa / sn - so / sn);
            nco++;
        }
        printf("# %s (time %.2f): KPD %.4f, at the nearest whole month %.4f; nearest 2017 frame %s %.4f; 2017 month-%02d mean %.4f; %.0f px\n",
               d.labels[i], q->time, e[0], e[3], d.labels[best], e[1], mon, e[2], c);
        for (j = 0; j < 4; j++) se[j] += e[j] * e[j] * c;
        cnt += c;
        tn_image_free(&out);
        tn_image_free(&rnd);
        tn_image_free(&mean);
        tn_image_free(&mcount);
    }
    printf("ndvi_heldout_2015_rmse_kpd: %.4f NDVI\n", sqrt(se[0] / cnt));
    printf("ndvi_heldout_2015_rmse_kpd_whole_month: %.4f NDVI (no interpolation between months)\n", sqrt(se[3] / cnt));
    printf("ndvi_heldout_2015_rmse_nearest_2017_frame: %.4f NDVI\n", sqrt(se[1] / cnt));
    printf("ndvi_heldout_2015_rmse_2017_month_mean: %.4f NDVI\n", sqrt(se[2] / cnt));
    printf("ndvi_kpd_over_nearest_frame: %.3f ratio\n", sqrt(se[0] / cnt) / sqrt(se[1] / cnt));
    printf("ndvi_heldout_2015_mean_abs_error_of_frame_means: KPD %.3f, nearest 2017 frame %.3f, 2017 month mean %.3f NDVI\n", course[0] / nco,
           course[1] / nco, course[2] / nco);
    /* the course of the year: the network's mean NDVI for each month against the 2017 frames' */
    printf("# month: KPD mean NDVI | 2017 clear-pixel mean of that month's frames\n");
    for (i = 0; i < 12; i++) {
        tn_image out = {0, 0, 0, NULL};
        double s = 0, o17 = 0, c17 = 0;
        size_t k, np = (size_t)d.dems[0].width * d.dems[0].height;
        tn_kpd_generate(&out, &m, &d.dems[0], &d.climates[0], &d.insolation[0], (float)i, 0, 0, d.dems[0].width, d.dems[0].height);
        for (k = 0; k < np; k++) s += out.data[k];
        for (j = 0; j < d.count; j++)
            if (!strncmp(d.labels[j], "2017", 4) && atoi(d.labels[j] + 5) == i + 1)
                for (k = 0; k < np; k++)
                    if (d.samples[j].mask->data[k] > 0.5f) o17 += d.samples[j].target->data[k], c17++;
        printf("# %02d: %.3f | %s%.3f\n", i + 1, s / np, c17 > 0 ? "" : "(none) ", c17 > 0 ? o17 / c17 : 0.0);
        tn_image_free(&out);
    }
    tn_kpd_free(&m);
    tn_season_data_free(&d);
    return 0;
}

/* ---- Table 1 on procedural pairs ---- */

typedef struct site {
    tn_image dem, ins, tex[12], half[12];
    tn_climate c;
} site;

static const struct { const char *path; float lo, hi, dx, dy; } dems[6] = {
    {"dem/alps_montblanc/alps_montblanc_128.png", 454, 4810, 92.7f, 92.7f},
    {"dem/himalaya_everest/himalaya_everest_128.png", 2362, 8838, 92.6f, 92.6f},
    {"dem/volcano_sthelens_10m/volcano_sthelens_10m_128.png", 902, 2539, 10.0f, 10.0f},
    {"dem/alps_n47e009/alps_n47e009_128.png", 388, 2937, 62.6f, 92.6f},
    {"dem/volcano_fuji_terrainrgb/volcano_fuji_terrainrgb_128.png", 13, 3751, 62.0f, 62.0f}, /* held out */
    {"dem/fault_jacksboro_tn/fault_jacksboro_tn_128.png", 236, 1076, 74.3f, 92.6f},         /* held out */
};
static const char *train_climates[6] = {"Af", "Aw", "BWh", "Cfb", "Dfc", "ET"};
static const char *test_climates[2] = {"Csa", "Dfb"};

static int site_make(site *s, int di, const tn_climate *c, int halves)
{
    tn_insolation_opts io;
    tn_season_opts so;
    float t[12];
    size_t k;
    int m;
    memset(s, 0, sizeof *s);
    s->c = *c;
    if (tn_image_load(&s->dem, data_path(dems[di].path), NULL)) return 0;
    for (k = 0; k < (size_t)s->dem.width * s->dem.height; k++) s->dem.data[k] = dems[di].lo + s->dem.data[k] * (dems[di].hi - dems[di].lo);
    memset(&io, 0, sizeof io);
    io.dx = dems[di].dx;
    io.dy = dems[di].dy;
    io.step_minutes = 30;
    if (tn_insolation(&s->ins, &s->dem, c->latitude, &io)) return 0;
    memset(&so, 0, sizeof so);
    so.insolation = io;
    so.detail = -1;
    for (m = 0; m < 12; m++) t[m] = (float)m;
    if (tn_season_texture(s->tex, &s->dem, c, c->latitude, &s->ins, t, 12, &so, NULL)) return 0;
    if (halves) {
        for (m = 0; m < 12; m++) t[m] = (float)m + 0.5f;
        if (tn_season_texture(s->half, &s->dem, c, c->latitude, &s->ins, t, 12, &so, NULL)) return 0;
    }
    return 1;
}

static void site_free(site *s)
{
    int m;
    tn_image_free(&s->dem);
    tn_image_free(&s->ins);
    for (m = 0; m < 12; m++) tn_image_free(&s->tex[m]), tn_image_free(&s->half[m]);
}

/* mean | |grad a| - |grad b| | over three scales (box 1, 2, 4), on the luminance, x 255 */
static double grad_distance(const tn_image *a, const tn_image *b)
{
    int s, x, y, W = a->width, H = a->height;
    double tot = 0;
    for (s = 1; s <= 4; s *= 2) {
        int w = W / s, h = H / s, i, j, c;
        double acc = 0, n = 0;
        float *la = (float *)calloc((size_t)w * h, sizeof(float)), *lb = (float *)calloc((size_t)w * h, sizeof(float));
        for (y = 0; y < h; y++)
            for (x = 0; x < w; x++)
                for (j = 0; j < s; j++)
                    for (i = 0; i < s; i++)
                        for (c = 0; c < 3; c++) {
                            size_t q = ((size_t)(y * s + j) * W + x * s + i) * 3 + c;
                            la[y * w + x] += a->data[q] / (3.0f * s * s);
                            lb[y * w + x] += b->data[q] / (3.0f * s * s);
                        }
        for (y = 0; y + 1 < h; y++)
            for (x = 0; x + 1 < w; x++) {
                double ga = hypot(la[y * w + x + 1] - la[y * w + x], la[(y + 1) * w + x] - la[y * w + x]);
                double gb = hypot(lb[y * w + x + 1] - lb[y * w + x], lb[(y + 1) * w + x] - lb[y * w + x]);
                acc += fabs(ga - gb);
                n++;
            }
        tot += acc / n / 3.0;
        free(la);
        free(lb);
    }
    return tot * 255.0;
}

static double mean_abs_diff_of_diffs(const tn_image *g0, const tn_image *g1, const tn_image *t0, const tn_image *t1)
{
    size_t k, n = (size_t)g0->width * g0->height * g0->channels;
    double s = 0;
    for (k = 0; k < n; k++) s += fabs(fabs(g1->data[k] - g0->data[k]) - fabs(t1->data[k] - t0->data[k]));
    return s / n * 255.0;
}

static int table_part(double minutes)
{
    site train[24], test[4];
    tn_season_sample *smp;
    int nt = 0, ns = 0, i, m, cnd;
    double t0 = tn_time_seconds();
    double hemi[TN_KPD_CONDITIONS], hemi_truth[TN_KPD_CONDITIONS];
    tn_kpd models[TN_KPD_CONDITIONS];
    for (i = 0; i < 4; i++) {
        int k;
        for (k = 0; k < 6; k++) {
            tn_climate c;
            tn_climate_koppen(&c, train_climates[k]);
            if (!site_make(&train[nt], i, &c, 0)) {
                printf("# table: no data (%s)\n", tn_last_error());
                return 0;
            }
            nt++;
        }
    }
    for (i = 0; i < 2; i++) {
        int k;
        for (k = 0; k < 2; k++) {
            tn_climate c;
            tn_climate_koppen(&c, test_climates[k]);
            if (!site_make(&test[ns], 4 + i, &c, 1)) {
                printf("# table: no data (%s)\n", tn_last_error());
                return 0;
            }
            ns++;
        }
    }
    printf("table_pairs: %d training sites x 12 months, %d held-out sites (other DEMs, other climates), %.1f s to make\n", nt, ns, tn_time_seconds() - t0);
    smp = (tn_season_sample *)calloc((size_t)nt * 12, sizeof *smp);
    for (i = 0; i < nt; i++)
        for (m = 0; m < 12; m++) {
            tn_season_sample *q = &smp[i * 12 + m];
            q->dem = &train[i].dem;
            q->insolation = &train[i].ins;
            q->climate = &train[i].c;
            q->time = (float)m;
            q->target = &train[i].tex[m];
        }
    printf("# condition: RMSE (0..255) | SSIM | gradient distance | dAD | dSSIM   (held-out sites, 12 months)\n");
    for (cnd = 0; cnd < TN_KPD_CONDITIONS; cnd++) {
        tn_kpd_opts o;
        tn_kpd_stats st;
        double se = 0, ssim = 0, gd = 0, dad = 0, dss = 0, n = 0, nd = 0;
        memset(&o, 0, sizeof o);
        o.condition = (tn_kpd_condition)cnd;
        o.train.minutes = minutes;
        if (tn_kpd_train(&models[cnd], smp, nt * 12, &o, &st)) {
            printf("# table: %s\n", tn_last_error());
            return 1;
        }
        for (i = 0; i < ns; i++) {
            tn_image g[13];
            for (m = 0; m < 12; m++)
                tn_kpd_generate(&g[m], &models[cnd], &test[i].dem, &test[i].c, &test[i].ins, (float)m, 0, 0, test[i].dem.width, test[i].dem.height);
            for (m = 0; m < 12; m++) {
                tn_metrics mt;
                double sg = 0, st_ = 0;
                int m1 = (m + 1) % 12;
                tn_compare(&mt, &test[i].tex[m], &g[m], 1.0);
                se += mt.rmse * mt.rmse;
                ssim += mt.ssim;
                gd += grad_distance(&g[m], &test[i].tex[m]);
                n++;
                dad += mean_abs_diff_of_diffs(&test[i].tex[m], &test[i].tex[m1], &g[m], &g[m1]);
                tn_ssim(&sg, &g[m], &g[m1], 1.0);
                tn_ssim(&st_, &test[i].tex[m], &test[i].tex[m1], 1.0);
                dss += fabs(sg - st_);
                nd++;
            }
            if (i == 0) { /* hemisphere: the climate six months later, south of the equator */
                site sh;
                tn_climate c = test[i].c;
                double e = 0, et = 0;
                int k;
                for (k = 0; k < 12; k++) c.t[k] = test[i].c.t[(k + 6) % 12], c.p[k] = test[i].c.p[(k + 6) % 12];
                c.latitude = -c.latitude;
                if (site_make(&sh, 4, &c, 0)) {
                    for (m = 0; m < 12; m++) {
                        tn_image gs;
                        tn_metrics a, b;
                        tn_kpd_generate(&gs, &models[cnd], &sh.dem, &sh.c, &sh.ins, (float)m, 0, 0, sh.dem.width, sh.dem.height);
                        tn_compare(&a, &g[(m + 6) % 12], &gs, 1.0);
                        tn_compare(&b, &sh.tex[m], &gs, 1.0);
                        e += a.rmse * a.rmse;
                        et += b.rmse * b.rmse;
                        tn_image_free(&gs);
                    }
                    site_free(&sh);
                }
                hemi[cnd] = sqrt(e / 12) * 255;
                hemi_truth[cnd] = sqrt(et / 12) * 255;
            }
            for (m = 0; m < 12; m++) tn_image_free(&g[m]);
        }
        printf("table1_%s: RMSE %.1f | SSIM %.3f | grad %.2f | dAD %.2f | dSSIM %.3f   (%ld its, %.3f s/it)\n", tn_kpd_condition_name((tn_kpd_condition)cnd),
               sqrt(se / n) * 255, ssim / n, gd / n, dad / nd, dss / nd, st.iterations, st.seconds_per_iter);
    }
    printf("# hemisphere (Figure 7): climate shifted by 6 months and latitude mirrored; RMSE (0..255) of the month-m output vs\n"
           "# the unshifted output of month m+6, and vs the texturer's truth for the shifted climate\n");
    for (cnd = 0; cnd < TN_KPD_CONDITIONS; cnd++)
        printf("hemisphere_%s: %.1f vs shifted output, %.1f vs truth\n", tn_kpd_condition_name((tn_kpd_condition)cnd), hemi[cnd], hemi_truth[cnd]);
    { /* half-way between months: gamma/beta interpolation (Eq. 1) vs the mean of the two outputs */
        double ef = 0, ei = 0, n = 0, dadf = 0, dadi = 0;
        for (i = 0; i < ns; i++)
            for (m = 0; m < 12; m++) {
                tn_image a, b, h, avg;
                tn_metrics mf, mi;
                size_t k;
                int m1 = (m + 1) % 12;
                tn_kpd_generate(&a, &models[0], &test[i].dem, &test[i].c, &test[i].ins, (float)m, 0, 0, test[i].dem.width, test[i].dem.height);
                tn_kpd_generate(&b, &models[0], &test[i].dem, &test[i].c, &test[i].ins, (float)m1, 0, 0, test[i].dem.width, test[i].dem.height);
                tn_kpd_generate(&h, &models[0], &test[i].dem, &test[i].c, &test[i].ins, (float)m + 0.5f, 0, 0, test[i].dem.width, test[i].dem.height);
                tn_image_copy(&avg, &a);
                for (k = 0; k < (size_t)a.width * a.height * 3; k++) avg.data[k] = 0.5f * (a.data[k] + b.data[k]);
                tn_compare(&mf, &test[i].half[m], &h, 1.0);
                tn_compare(&mi, &test[i].half[m], &avg, 1.0);
                ef += mf.rmse * mf.rmse;
                ei += mi.rmse * mi.rmse;
                dadf += mean_abs_diff_of_diffs(&test[i].tex[m], &test[i].half[m], &a, &h);
                dadi += mean_abs_diff_of_diffs(&test[i].tex[m], &test[i].half[m], &a, &avg);
                n++;
                tn_image_free(&a);
                tn_image_free(&b);
                tn_image_free(&h);
                tn_image_free(&avg);
            }
        printf("halfmonth_rmse_gamma_beta: %.1f (0..255, vs the texturer at m + 0.5)\n", sqrt(ef / n) * 255);
        printf("halfmonth_rmse_image_average: %.1f\n", sqrt(ei / n) * 255);
        printf("halfmonth_dad_gamma_beta: %.2f\nhalfmonth_dad_image_average: %.2f\n", dadf / n, dadi / n);
    }
    { /* a sheet: truth and Ours for the first held-out site, every second month */
        tn_image cells[12], sheet;
        for (m = 0; m < 6; m++) {
            tn_image_copy(&cells[m], &test[0].tex[2 * m]);
            tn_kpd_generate(&cells[6 + m], &models[0], &test[0].dem, &test[0].c, &test[0].ins, (float)(2 * m), 0, 0, test[0].dem.width, test[0].dem.height);
        }
        if (!tn_season_sheet(&sheet, cells, 12, 6, 128)) {
            tn_save_opts so;
            memset(&so, 0, sizeof so);
            so.bit_depth = 8;
            tn_image_save("build/bench_kpd_sheet.png", &sheet, &so);
            printf("# build/bench_kpd_sheet.png: top the texturer's truth, bottom KPD (Ours), Jan Mar May Jul Sep Nov, held-out DEM and climate\n");
            tn_image_free(&sheet);
        }
        for (m = 0; m < 12; m++) tn_image_free(&cells[m]);
    }
    for (cnd = 0; cnd < TN_KPD_CONDITIONS; cnd++) tn_kpd_free(&models[cnd]);
    for (i = 0; i < nt; i++) site_free(&train[i]);
    for (i = 0; i < ns; i++) site_free(&test[i]);
    free(smp);
    return 0;
}

/* 4096 x 4096 texturing time: a real 1024 DEM upsampled 4x, its insolation computed at 1024 and
   upsampled (as tn_season_texture does for large maps), a KPD model of 20 iterations (the weights
   do not change the cost). */
static int speed_part(void)
{
    tn_image dem = {0, 0, 0, NULL}, big = {0, 0, 0, NULL}, ins = {0, 0, 0, NULL}, insb = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_insolation_opts io;
    tn_climate c;
    tn_season_sample s;
    tn_kpd_opts o;
    tn_kpd m;
    tn_image tex = {0, 0, 0, NULL};
    float t = 0;
    double t0;
    size_t k;
    if (tn_image_load(&dem, data_path("dem/alps_n47e009/alps_n47e009_full.png"), NULL)) {
        printf("# speed: no data\n");
        return 0;
    }
    for (k = 0; k < (size_t)dem.width * dem.height; k++) dem.data[k] = 388.0f + dem.data[k] * (2937.0f - 388.0f);
    memset(&io, 0, sizeof io);
    io.dx = 62.6f;
    io.dy = 92.6f;
    tn_climate_koppen(&c, "Cfb");
    t0 = tn_time_seconds();
    if (tn_insolation(&ins, &dem, 47.4, &io) || tn_image_resize(&big, &dem, 4096, 4096, TN_RESIZE_BILINEAR) ||
        tn_image_resize(&insb, &ins, 4096, 4096, TN_RESIZE_BILINEAR) || tn_season_texture(&tex, &dem, &c, 47.4, &ins, &t, 1, NULL, NULL)) {
        printf("# speed: %s\n", tn_last_error());
        return 1;
    }
    printf("kpd_4096_inputs: %.1f s (insolation at 1024, both upsampled)\n", tn_time_seconds() - t0);
    memset(&s, 0, sizeof s);
    s.dem = &dem;
    s.insolation = &ins;
    s.climate = &c;
    s.target = &tex;
    memset(&o, 0, sizeof o);
    o.train.max_iters = 20;
    if (tn_kpd_train(&m, &s, 1, &o, NULL)) {
        printf("# speed: %s\n", tn_last_error());
        return 1;
    }
    t0 = tn_time_seconds();
    if (tn_kpd_generate(&out, &m, &big, &c, &insb, 6.0f, 0, 0, 4096, 4096)) {
        printf("# speed: %s\n", tn_last_error());
        return 1;
    }
    printf("kpd_4096_one_month: %.1f s (2 threads)\n", tn_time_seconds() - t0);
    tn_image_free(&out);
    t0 = tn_time_seconds();
    tn_kpd_generate(&out, &m, &big, &c, &insb, 6.5f, 0, 0, 4096, 4096);
    printf("kpd_4096_between_months: %.1f s (two conditionings)\n", tn_time_seconds() - t0);
    tn_image_free(&out);
    tn_image_free(&tex);
    tn_image_free(&dem);
    tn_image_free(&big);
    tn_image_free(&ins);
    tn_image_free(&insb);
    tn_kpd_free(&m);
    return 0;
}

int main(int argc, char **argv)
{
    double rm = argc > 1 ? atof(argv[1]) : 5.0, tm = argc > 2 ? atof(argv[2]) : 3.0;
    const char *part = argc > 3 ? argv[3] : "all";
    int rc = 0;
    tn_set_progress(quiet, NULL);
    tn_set_threads(2);
    if (!strcmp(part, "all") || !strcmp(part, "real")) rc |= real_part(rm);
    if (!strcmp(part, "all") || !strcmp(part, "table")) rc |= table_part(tm);
    if (!strcmp(part, "all") || !strcmp(part, "speed")) rc |= speed_part();
    return rc;
}
