/* terrainnet command-line tool: every library feature as a subcommand.
   Build: make   (bin/terrainnet). Run `bin/terrainnet --help`. */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#if !defined(_WIN32)
#include <unistd.h>
#endif

/* ---- small helpers ------------------------------------------------------------------------ */

static int fail_status(tn_status st)
{
    const char *msg = tn_last_error();
    fprintf(stderr, "terrainnet: error: %s%s%s\n", tn_status_string(st), msg[0] ? ": " : "", msg);
    return 1;
}

static int usage_error(const char *cmd, const char *msg, const char *arg)
{
    fprintf(stderr, "terrainnet %s: %s%s%s\n(see `terrainnet %s --help`)\n", cmd, msg, arg ? " " : "", arg ? arg : "", cmd);
    return 2;
}

static int parse_double(const char *s, double *out)
{
    char *end;
    double v;
    if (!s || !*s) return 0;
    v = strtod(s, &end);
    if (*end || v != v || v > 1e300 || v < -1e300) return 0;
    *out = v;
    return 1;
}

static int parse_int(const char *s, int *out)
{
    char *end;
    long v;
    if (!s || !*s) return 0;
    v = strtol(s, &end, 10);
    if (*end || v < -1000000000L || v > 1000000000L) return 0;
    *out = (int)v;
    return 1;
}

static int wants_help(int argc, char **argv)
{
    int i;
    for (i = 0; i < argc; i++)
        if (!strcmp(argv[i], "--help") || !strcmp(argv[i], "-h")) return 1;
    return 0;
}

/* Progress: a bar with ETA when stderr is a terminal, otherwise a plain line every ~10 %. */
typedef struct progress_state { double t0; int tty; int last_decile; char stage[64]; } progress_state;

static int cli_progress(void *user, const char *stage, double f)
{
    progress_state *p = (progress_state *)user;
    double el;
    if (strncmp(p->stage, stage, sizeof p->stage - 1) != 0) {
        snprintf(p->stage, sizeof p->stage, "%s", stage);
        p->t0 = tn_time_seconds();
        p->last_decile = -1;
    }
    el = tn_time_seconds() - p->t0;
    if (p->tty) {
        int i, w = 30, fill = (int)(f * w + 0.5);
        double eta = f > 0.01 ? el * (1.0 - f) / f : 0.0;
        fprintf(stderr, "\r%-18.18s [", stage);
        for (i = 0; i < w; i++) fputc(i < fill ? '#' : '.', stderr);
        fprintf(stderr, "] %5.1f%%  %6.1fs  ETA %6.1fs", 100.0 * f, el, eta);
        if (f >= 1.0) fputc('\n', stderr);
    } else {
        int d = (int)(f * 10.0);
        if (d != p->last_decile) {
            p->last_decile = d;
            fprintf(stderr, "%s: %3.0f%% (%.1f s)\n", stage, 100.0 * f, el);
        }
    }
    return 0;
}

static progress_state g_progress;

static void install_progress(void)
{
#if !defined(_WIN32)
    g_progress.tty = isatty(2);
#endif
    g_progress.last_decile = -1;
    tn_set_progress(cli_progress, &g_progress);
}

/* ---- info -------------------------------------------------------------------------------- */

static int cmd_info(int argc, char **argv)
{
    tn_image img = {0, 0, 0, NULL};
    tn_image_info info;
    tn_load_opts lo;
    tn_status st;
    float mn, mx;
    size_t bad, i, n;
    double sum = 0.0;
    const char *path = NULL;
    int a;
    if (wants_help(argc, argv)) {
        printf("usage: terrainnet info FILE [--raw-size W H]\n"
               "Prints the format, size, channels, bit depth, height range (metres when the file\n"
               "records them) and value statistics of an image or heightmap.\n");
        return 0;
    }
    memset(&lo, 0, sizeof lo);
    for (a = 0; a < argc; a++) {
        if (!strcmp(argv[a], "--raw-size") && a + 2 < argc) {
            if (!parse_int(argv[a + 1], &lo.raw_width) || !parse_int(argv[a + 2], &lo.raw_height))
                return usage_error("info", "bad --raw-size", argv[a + 1]);
            a += 2;
        } else if (argv[a][0] == '-') return usage_error("info", "unknown option", argv[a]);
        else if (!path) path = argv[a];
        else return usage_error("info", "too many arguments:", argv[a]);
    }
    if (!path) return usage_error("info", "missing FILE", NULL);
    if ((st = tn_image_load_ex(path, &img, &info, &lo))) return fail_status(st);
    bad = tn_image_range(&img, &mn, &mx);
    n = (size_t)img.width * img.height * img.channels;
    for (i = 0; i < n; i++) sum += img.data[i];
    printf("file: %s\nformat: %s\nsize: %d x %d\nchannels: %d\nbit_depth: %d\n", path, tn_format_name(info.format),
           img.width, img.height, img.channels, info.bit_depth);
    if (info.interlaced) printf("interlaced: adam7\n");
    if (info.has_range) printf("height_range_m: %.6g %.6g\n", info.range_lo, info.range_hi);
    else if (info.format == TN_FORMAT_HGT || info.format == TN_FORMAT_ASC) printf("units: metres (as stored)\n");
    else printf("units: normalised [0, 1] (the file records no height range)\n");
    if (info.cellsize > 0) printf("cellsize: %.6g\norigin: %.6g %.6g\n", info.cellsize, info.x_origin, info.y_origin);
    if (info.voids_filled) printf("voids_filled: %zu\n", info.voids_filled);
    printf("min: %.6g\nmax: %.6g\nmean: %.6g\n", mn, mx, sum / (double)n);
    if (bad) printf("nan_or_inf: %zu\n", bad);
    tn_image_free(&img);
    return 0;
}

/* ---- convert ----------------------------------------------------------------------------- */

static int cmd_convert(int argc, char **argv)
{
    tn_image img = {0, 0, 0, NULL};
    tn_image_info info;
    tn_load_opts lo;
    tn_save_opts so;
    tn_status st;
    const char *in = NULL, *out = NULL;
    int a, keep_range = 1;
    if (wants_help(argc, argv)) {
        printf("usage: terrainnet convert IN OUT [--range LO HI] [--bits 8|16] [--raw-size W H] [--cellsize M]\n"
               "Converts between PNG, PGM/PPM, PFM, SRTM .hgt, ESRI .asc and .r16 (format from OUT's\n"
               "extension). Heights keep their metres: a range recorded in IN (or given with --range,\n"
               "which maps codes 0..max of an 8/16-bit output to LO..HI) is written to OUT where the\n"
               "format can hold it. OUT is written atomically and never half-written.\n");
        return 0;
    }
    memset(&lo, 0, sizeof lo);
    memset(&so, 0, sizeof so);
    for (a = 0; a < argc; a++) {
        if (!strcmp(argv[a], "--range") && a + 2 < argc) {
            if (!parse_double(argv[a + 1], &so.range_lo) || !parse_double(argv[a + 2], &so.range_hi) ||
                so.range_hi <= so.range_lo)
                return usage_error("convert", "--range needs two numbers LO < HI", NULL);
            so.has_range = 1;
            keep_range = 0;
            a += 2;
        } else if (!strcmp(argv[a], "--bits") && a + 1 < argc) {
            if (!parse_int(argv[a + 1], &so.bit_depth) || (so.bit_depth != 8 && so.bit_depth != 16))
                return usage_error("convert", "--bits must be 8 or 16, not", argv[a + 1]);
            a++;
        } else if (!strcmp(argv[a], "--raw-size") && a + 2 < argc) {
            if (!parse_int(argv[a + 1], &lo.raw_width) || !parse_int(argv[a + 2], &lo.raw_height))
                return usage_error("convert", "bad --raw-size", argv[a + 1]);
            a += 2;
        } else if (!strcmp(argv[a], "--cellsize") && a + 1 < argc) {
            if (!parse_double(argv[a + 1], &so.cellsize) || so.cellsize <= 0)
                return usage_error("convert", "bad --cellsize", argv[a + 1]);
            a++;
        } else if (argv[a][0] == '-') return usage_error("convert", "unknown option", argv[a]);
        else if (!in) in = argv[a];
        else if (!out) out = argv[a];
        else return usage_error("convert", "too many arguments:", argv[a]);
    }
    if (!in || !out) return usage_error("convert", "needs IN and OUT", NULL);
    if ((st = tn_image_load_ex(in, &img, &info, &lo))) return fail_status(st);
    if (keep_range && info.has_range) {
        so.has_range = 1;
        so.range_lo = info.range_lo;
        so.range_hi = info.range_hi;
    }
    if (!so.cellsize && info.cellsize > 0) so.cellsize = info.cellsize;
    st = tn_image_save(out, &img, &so);
    tn_image_free(&img);
    if (st) return fail_status(st);
    return 0;
}

/* ---- metrics ----------------------------------------------------------------------------- */

static int cmd_metrics(int argc, char **argv)
{
    tn_image a_img = {0, 0, 0, NULL}, b_img = {0, 0, 0, NULL};
    tn_metrics m;
    tn_status st;
    const char *pa = NULL, *pb = NULL;
    double range = 0.0;
    int a;
    if (wants_help(argc, argv)) {
        printf("usage: terrainnet metrics REFERENCE IMAGE [--range R]\n"
               "Compares IMAGE with REFERENCE (same size and channels). The data range R defaults to\n"
               "max(REFERENCE) - min(REFERENCE), so the figures do not depend on units.\n"
               "Prints ssim (Gaussian 11x11, sigma 1.5, as scikit-image), psnr (dB), rmse and mae.\n");
        return 0;
    }
    for (a = 0; a < argc; a++) {
        if (!strcmp(argv[a], "--range") && a + 1 < argc) {
            if (!parse_double(argv[a + 1], &range) || range <= 0)
                return usage_error("metrics", "--range must be a positive number, not", argv[a + 1]);
            a++;
        } else if (argv[a][0] == '-') return usage_error("metrics", "unknown option", argv[a]);
        else if (!pa) pa = argv[a];
        else if (!pb) pb = argv[a];
        else return usage_error("metrics", "too many arguments:", argv[a]);
    }
    if (!pa || !pb) return usage_error("metrics", "needs REFERENCE and IMAGE", NULL);
    if ((st = tn_image_load(pa, &a_img, NULL))) return fail_status(st);
    if ((st = tn_image_load(pb, &b_img, NULL))) {
        tn_image_free(&a_img);
        return fail_status(st);
    }
    st = tn_compare(&a_img, &b_img, range, &m);
    tn_image_free(&a_img);
    tn_image_free(&b_img);
    if (st) return fail_status(st);
    printf("ssim: %.6f\npsnr: %.4f\nrmse: %.6g\nmae: %.6g\n", m.ssim, m.psnr, m.rmse, m.mae);
    return 0;
}

/* ---- render ------------------------------------------------------------------------------ */

static int cmd_render(int argc, char **argv)
{
    tn_image dem = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_view_opts vo;
    tn_status st;
    const char *in = NULL, *outp = NULL;
    int a, view = 0;
    double v;
    if (wants_help(argc, argv)) {
        printf("usage: terrainnet render DEM -o OUT.png [--3d] [--size W H] [--azimuth DEG] [--pitch DEG]\n"
               "                                [--relief F] [--light DEG]\n"
               "Writes a preview: hypsometric colours times a hillshade (default), or with --3d a\n"
               "perspective view of the terrain (camera --azimuth clockwise from north, default 180 =\n"
               "from the south; --pitch downward angle, default 30; --relief = height of the full\n"
               "range as a fraction of the DEM width, default 0.2). --light sets the sun azimuth.\n");
        return 0;
    }
    memset(&vo, 0, sizeof vo);
    for (a = 0; a < argc; a++) {
        if (!strcmp(argv[a], "-o") && a + 1 < argc) outp = argv[++a];
        else if (!strcmp(argv[a], "--3d")) view = 1;
        else if (!strcmp(argv[a], "--size") && a + 2 < argc) {
            if (!parse_int(argv[a + 1], &vo.width) || !parse_int(argv[a + 2], &vo.height) || vo.width < 16 ||
                vo.height < 16 || vo.width > 16384 || vo.height > 16384)
                return usage_error("render", "--size needs W H between 16 and 16384", NULL);
            a += 2;
        } else if ((!strcmp(argv[a], "--azimuth") || !strcmp(argv[a], "--pitch") || !strcmp(argv[a], "--relief") ||
                    !strcmp(argv[a], "--light")) && a + 1 < argc) {
            if (!parse_double(argv[a + 1], &v)) return usage_error("render", "not a number:", argv[a + 1]);
            if (!strcmp(argv[a], "--azimuth")) vo.azimuth_deg = (float)v;
            else if (!strcmp(argv[a], "--pitch")) vo.pitch_deg = (float)v;
            else if (!strcmp(argv[a], "--relief")) vo.relief = (float)v;
            else vo.colours.shade.azimuth_deg = (float)v;
            a++;
        } else if (argv[a][0] == '-') return usage_error("render", "unknown option", argv[a]);
        else if (!in) in = argv[a];
        else return usage_error("render", "too many arguments:", argv[a]);
    }
    if (!in) return usage_error("render", "missing DEM", NULL);
    if (!outp) return usage_error("render", "missing -o OUT.png", NULL);
    if ((st = tn_image_load(in, &dem, NULL))) return fail_status(st);
    st = view ? tn_render_view(&dem, &vo, &out) : tn_render_preview(&dem, &vo.colours, &out);
    tn_image_free(&dem);
    if (st) return fail_status(st);
    {
        tn_save_opts so;
        memset(&so, 0, sizeof so);
        so.bit_depth = 8;
        st = tn_image_save(outp, &out, &so);
    }
    tn_image_free(&out);
    if (st) return fail_status(st);
    return 0;
}

/* ---- noise ------------------------------------------------------------------------------- */

static int cmd_noise(int argc, char **argv)
{
    tn_image out = {0, 0, 0, NULL}, drawn = {0, 0, 0, NULL}, blended = {0, 0, 0, NULL};
    tn_perlin_opts po;
    tn_explicit_opts eo;
    tn_save_opts so;
    tn_status st;
    const char *outp = NULL, *draw = NULL;
    int a, w = 512, h = 512, explicit_noise = 0;
    double v, seed = 1, weight = 0.5, range_lo = 0, range_hi = 0;
    if (wants_help(argc, argv)) {
        printf("usage: terrainnet noise -o OUT [--type perlin|explicit] [--size N [M]] [--seed S]\n"
               "                        [--octaves N] [--frequency F] [--lacunarity L] [--gain G]\n"
               "                        [--periodic] [--draw MAP --draw-weight W] [--range LO HI]\n"
               "Writes a procedural heightmap in [0, 1] (or metres with --range): Perlin fBm\n"
               "(default: 8 octaves, 4 cells across, lacunarity 2, gain 0.5) or explicit multi-scale\n"
               "smoothed noise. --size N is N x N (default 512); N M is N wide, M high. --periodic\n"
               "makes Perlin tile seamlessly. --draw blends a drawn grey map (resized to the output)\n"
               "with weight W in [0, 1] (default 0.5) to steer the layout.\n");
        return 0;
    }
    memset(&po, 0, sizeof po);
    memset(&eo, 0, sizeof eo);
    for (a = 0; a < argc; a++) {
        if (!strcmp(argv[a], "-o") && a + 1 < argc) outp = argv[++a];
        else if (!strcmp(argv[a], "--size") && a + 1 < argc) {
            if (!parse_int(argv[a + 1], &w) || w < 1 || w > 65536)
                return usage_error("noise", "--size needs N (or N M) between 1 and 65536", NULL);
            h = w;
            a++;
            if (a + 1 < argc && parse_int(argv[a + 1], &h)) {
                if (h < 1 || h > 65536) return usage_error("noise", "--size needs N (or N M) between 1 and 65536", NULL);
                a++;
            }
        } else if (!strcmp(argv[a], "--type") && a + 1 < argc) {
            a++;
            if (!strcmp(argv[a], "explicit")) explicit_noise = 1;
            else if (!strcmp(argv[a], "perlin")) explicit_noise = 0;
            else return usage_error("noise", "--type must be perlin or explicit, not", argv[a]);
        }
        else if (!strcmp(argv[a], "--periodic")) po.periodic = 1;
        else if (!strcmp(argv[a], "--draw") && a + 1 < argc) draw = argv[++a];
        else if (!strcmp(argv[a], "--range") && a + 2 < argc) {
            if (!parse_double(argv[a + 1], &range_lo) || !parse_double(argv[a + 2], &range_hi) || range_hi <= range_lo)
                return usage_error("noise", "--range needs two numbers LO < HI", NULL);
            a += 2;
        } else if ((!strcmp(argv[a], "--seed") || !strcmp(argv[a], "--octaves") || !strcmp(argv[a], "--frequency") ||
                    !strcmp(argv[a], "--lacunarity") || !strcmp(argv[a], "--gain") || !strcmp(argv[a], "--draw-weight")) &&
                   a + 1 < argc) {
            if (!parse_double(argv[a + 1], &v) || v < 0) return usage_error("noise", "not a non-negative number:", argv[a + 1]);
            if (!strcmp(argv[a], "--seed")) seed = v;
            else if (!strcmp(argv[a], "--octaves")) po.octaves = (int)v;
            else if (!strcmp(argv[a], "--frequency")) po.frequency = (float)v;
            else if (!strcmp(argv[a], "--lacunarity")) po.lacunarity = (float)v;
            else if (!strcmp(argv[a], "--gain")) po.gain = (float)v;
            else if (v > 1) return usage_error("noise", "--draw-weight must be in [0, 1]", NULL);
            else weight = v;
            a++;
        } else return usage_error("noise", "unknown option or missing value:", argv[a]);
    }
    if (!outp) return usage_error("noise", "missing -o OUT", NULL);
    po.seed = eo.seed = (uint64_t)seed;
    st = explicit_noise ? tn_noise_explicit(&out, w, h, &eo) : tn_noise_perlin(&out, w, h, &po);
    if (st) return fail_status(st);
    if (draw) {
        if ((st = tn_image_load(draw, &drawn, NULL)) || (st = tn_noise_blend(&blended, &out, &drawn, (float)weight))) {
            tn_image_free(&out);
            tn_image_free(&drawn);
            return fail_status(st);
        }
        tn_image_free(&out);
        tn_image_free(&drawn);
        out = blended;
    }
    memset(&so, 0, sizeof so);
    if (range_hi > range_lo) {
        size_t i;
        for (i = 0; i < (size_t)w * h; i++) out.data[i] = (float)(range_lo + out.data[i] * (range_hi - range_lo));
        so.has_range = 1;
        so.range_lo = range_lo;
        so.range_hi = range_hi;
    }
    st = tn_image_save(outp, &out, &so);
    tn_image_free(&out);
    return st ? fail_status(st) : 0;
}

/* ---- texture GAN and detail maps ---------------------------------------------------------- */

/* "W", "WxH" or "W H"-style size; returns 1 on success. */
static int parse_size(const char *s, int *w, int *h)
{
    char buf[64], *x;
    if (!s || strlen(s) >= sizeof buf) return 0;
    strcpy(buf, s);
    x = strchr(buf, 'x');
    if (!x) x = strchr(buf, 'X');
    if (x) *x = 0;
    if (!parse_int(buf, w) || (x ? !parse_int(x + 1, h) : !parse_int(buf, h))) return 0;
    return *w >= 1 && *h >= 1 && *w <= (1 << 20) && *h <= (1 << 20);
}

static int cmd_texgan_train(int argc, char **argv)
{
    tn_image ex = {0, 0, 0, NULL}, nrm = {0, 0, 0, NULL};
    tn_texgan model;
    tn_texgan_opts o;
    tn_texgan_stats s;
    tn_status st;
    const char *in = NULL, *outp = NULL, *normal = NULL, *ckpt = NULL;
    char ckbuf[1024];
    int a;
    double v;
    if (wants_help(argc, argv)) {
        printf("usage: terrainnet texgan-train EXEMPLAR -o MODEL.tnw [--minutes M] [--iters N] [--resume]\n"
               "             [--checkpoint PATH] [--checkpoint-seconds S] [--normal MAP] [--seed S]\n"
               "             [--patch N] [--batch N] [--gen-width N] [--disc-width N] [--disc-layers N]\n"
               "             [--stages N] [--scale S] [--augment] [--local N] [--global N] [--periodic N]\n"
               "Trains a spatial GAN (PSGAN-style, spectral-norm + hinge) on random patches of one texture\n"
               "photo and writes the model (EMA generator + architecture). --normal stacks a normal map as\n"
               "channels 4-6. Defaults: 15 minutes in total (resumed time included), 64 px patches, batch\n"
               "4, 4 stages of 64-32-16 channels from 16 noise dims. The full training state is saved\n"
               "atomically to MODEL.tnw.ckpt (or --checkpoint) every 60 s (--checkpoint-seconds), so a\n"
               "killed run loses at most one interval; --resume continues it identically. --scale S learns\n"
               "the exemplar downscaled by S (features S times larger, e.g. crack cells) and upsamples.\n"
               "--augment flips/transposes real patches (small exemplars without a light direction).\n");
        return 0;
    }
    memset(&o, 0, sizeof o);
    for (a = 0; a < argc; a++) {
        const char *k = argv[a];
        if (!strcmp(k, "-o") && a + 1 < argc) outp = argv[++a];
        else if (!strcmp(k, "--resume")) o.resume = 1;
        else if (!strcmp(k, "--augment")) o.augment = 1;
        else if (!strcmp(k, "--normal") && a + 1 < argc) normal = argv[++a];
        else if (!strcmp(k, "--checkpoint") && a + 1 < argc) ckpt = argv[++a];
        else if ((!strcmp(k, "--minutes") || !strcmp(k, "--checkpoint-seconds") || !strcmp(k, "--iters") || !strcmp(k, "--seed") ||
                  !strcmp(k, "--patch") || !strcmp(k, "--batch") || !strcmp(k, "--gen-width") || !strcmp(k, "--disc-width") || !strcmp(k, "--disc-layers") ||
                  !strcmp(k, "--stages") || !strcmp(k, "--scale") || !strcmp(k, "--local") || !strcmp(k, "--global") || !strcmp(k, "--periodic")) &&
                 a + 1 < argc) {
            if (!parse_double(argv[a + 1], &v) || v < 0 || v > 1e9) return usage_error("texgan-train", "not a non-negative number:", argv[a + 1]);
            if (!strcmp(k, "--minutes")) o.minutes = v;
            else if (!strcmp(k, "--checkpoint-seconds")) o.checkpoint_seconds = v;
            else if (!strcmp(k, "--iters")) o.max_iters = (long)v;
            else if (!strcmp(k, "--seed")) o.seed = (uint64_t)v;
            else if (!strcmp(k, "--patch")) o.patch = (int)v;
            else if (!strcmp(k, "--batch")) o.batch = (int)v;
            else if (!strcmp(k, "--gen-width")) o.gen_width = (int)v;
            else if (!strcmp(k, "--disc-width")) o.disc_width = (int)v;
            else if (!strcmp(k, "--disc-layers")) o.disc_layers = (int)v;
            else if (!strcmp(k, "--stages")) o.stages = (int)v;
            else if (!strcmp(k, "--scale")) o.scale = (int)v;
            else if (!strcmp(k, "--local")) o.noise_local = (int)v;
            else if (!strcmp(k, "--global")) o.noise_global = (int)v;
            else o.noise_periodic = (int)v;
            a++;
        } else if (k[0] == '-') return usage_error("texgan-train", "unknown option or missing value:", k);
        else if (!in) in = k;
        else return usage_error("texgan-train", "too many arguments:", k);
    }
    if (!in) return usage_error("texgan-train", "missing EXEMPLAR", NULL);
    if (!outp) return usage_error("texgan-train", "missing -o MODEL.tnw", NULL);
    if (!ckpt) {
        snprintf(ckbuf, sizeof ckbuf, "%s.ckpt", outp);
        ckpt = ckbuf;
    }
    o.checkpoint = ckpt;
    if ((st = tn_image_load(in, &ex, NULL))) return fail_status(st);
    if (normal) {
        tn_image both = {0, 0, 0, NULL};
        size_t i, n = (size_t)ex.width * ex.height;
        int c;
        if ((st = tn_image_load(normal, &nrm, NULL))) { tn_image_free(&ex); return fail_status(st); }
        if (nrm.width != ex.width || nrm.height != ex.height || ex.channels + nrm.channels > TN_TEXGAN_MAX_CHANNELS) {
            tn_image_free(&ex);
            tn_image_free(&nrm);
            fprintf(stderr, "terrainnet texgan-train: the normal map must have the exemplar's size\n");
            return 1;
        }
        if ((st = tn_image_create(&both, ex.width, ex.height, ex.channels + nrm.channels))) { tn_image_free(&ex); tn_image_free(&nrm); return fail_status(st); }
        for (i = 0; i < n; i++)
            for (c = 0; c < both.channels; c++)
                both.data[i * both.channels + c] = c < ex.channels ? ex.data[i * ex.channels + c] : nrm.data[i * nrm.channels + c - ex.channels];
        tn_image_free(&ex);
        tn_image_free(&nrm);
        ex = both;
    }
    st = tn_texgan_train(&model, &ex, &o, &s);
    tn_image_free(&ex);
    if (st) return fail_status(st);
    st = tn_texgan_save(&model, outp);
    if (!st)
        printf("iterations: %ld (resumed at %ld)\ntrain_minutes: %.2f\nseconds_per_iteration: %.4f\nloss_d: %.4f\nloss_g: %.4f\n"
               "checkpoints: %d (%s)\nmodel: %s\n",
               s.iterations, s.resumed_from, s.seconds / 60.0, s.seconds_per_iter, (double)s.loss_d, (double)s.loss_g, s.checkpoints, ckpt, outp);
    tn_texgan_free(&model);
    return st ? fail_status(st) : 0;
}

static int cmd_texgan_synth(int argc, char **argv)
{
    tn_texgan model;
    tn_status st;
    const char *in = NULL, *outp = NULL;
    int a, w = 0, h = 0, colour = 0;
    double v, seed = 1, t0;
    float shift[TN_TEXGAN_MAX_CHANNELS];
    if (wants_help(argc, argv)) {
        printf("usage: terrainnet texgan-synth MODEL.tnw --size WxH -o OUT [--seed S] [--colour-correct]\n"
               "Synthesises a texture of any size from a trained model, tile by tile (2 noise cells of\n"
               "overlap, cropped and stitched; memory is one band of tiles). .pfm/.ppm/.pgm outputs are\n"
               "streamed to disk band by band; other formats (.png) are built in memory and saved whole.\n"
               "Channels beyond 3 go to OUT.ch3-5.EXT. The same seed gives the same bytes on any machine.\n"
               "--colour-correct shifts the mean colour to the exemplar's (measured on a 1024 px window).\n");
        return 0;
    }
    for (a = 0; a < argc; a++) {
        if (!strcmp(argv[a], "-o") && a + 1 < argc) outp = argv[++a];
        else if (!strcmp(argv[a], "--size") && a + 1 < argc) {
            if (!parse_size(argv[++a], &w, &h)) return usage_error("texgan-synth", "--size needs WxH, e.g. 8192x8192, not", argv[a]);
        } else if (!strcmp(argv[a], "--seed") && a + 1 < argc) {
            if (!parse_double(argv[a + 1], &v) || v < 0) return usage_error("texgan-synth", "not a non-negative number:", argv[a + 1]);
            seed = v;
            a++;
        } else if (!strcmp(argv[a], "--colour-correct")) colour = 1;
        else if (argv[a][0] == '-') return usage_error("texgan-synth", "unknown option or missing value:", argv[a]);
        else if (!in) in = argv[a];
        else return usage_error("texgan-synth", "too many arguments:", argv[a]);
    }
    if (!in) return usage_error("texgan-synth", "missing MODEL", NULL);
    if (!outp) return usage_error("texgan-synth", "missing -o OUT", NULL);
    if (!w) return usage_error("texgan-synth", "missing --size WxH", NULL);
    if ((st = tn_texgan_load(&model, in))) return fail_status(st);
    t0 = tn_time_seconds();
    if (colour) {
        tn_image probe = {0, 0, 0, NULL};
        st = tn_texgan_synthesize_window(&model, (uint64_t)seed, 0, 0, w < 1024 ? w : 1024, h < 1024 ? h : 1024, &probe);
        if (!st) st = tn_texture_colour_shift(&probe, model.mean, model.lo, model.hi, shift);
        tn_image_free(&probe);
    }
    if (!st) st = tn_texgan_synthesize_file(&model, (uint64_t)seed, w, h, colour ? shift : NULL, outp);
    if (!st) printf("synthesised %d x %d in %.2f s -> %s\n", w, h, tn_time_seconds() - t0, outp);
    tn_texgan_free(&model);
    return st ? fail_status(st) : 0;
}

static int is_tnw_file(const char *path)
{
    FILE *f = fopen(path, "rb");
    char m[4] = {0, 0, 0, 0};
    int ok;
    if (!f) return 0;
    ok = fread(m, 1, 4, f) == 4 && !memcmp(m, "TNW1", 4);
    fclose(f);
    return ok;
}

static int cmd_detail_maps(int argc, char **argv)
{
    tn_image ex = {0, 0, 0, NULL}, synth = {0, 0, 0, NULL}, img = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL};
    tn_detail_maps maps;
    tn_detail_opts o;
    tn_texgan model;
    tn_status st;
    const char *src = NULL, *exp_ = NULL, *prefix = NULL, *compose = NULL, *preview = NULL, *demp = NULL;
    int a, w = 0, h = 0, have_model;
    double v, seed = 1;
    if (wants_help(argc, argv)) {
        printf("usage: terrainnet detail-maps MODEL_OR_SYNTH EXEMPLAR -o PREFIX [--size WxH] [--seed S]\n"
               "             [--factor F] [--sigma S] [--no-colour] [--compose OUT] [--preview OUT.png [--dem DEM]]\n"
               "Writes PREFIX_low.png (16-bit: Gaussian low-pass of the colour-corrected synthesis,\n"
               "downsampled by F, default 10 = 100x less memory), PREFIX_high.png (8-bit: exemplar minus\n"
               "its Gaussian blur, as value/2 + 0.5) and PREFIX_detail.txt (texture size, tiling factor,\n"
               "F, sigma (default F/2), value range). From a MODEL the texture (--size, default 8x the\n"
               "exemplar) is synthesised band by band; from a SYNTH image its own size is used.\n"
               "--compose writes the full-resolution texture as a shader would rebuild it (at --size);\n"
               "--preview writes naive tiling vs detail mapping, far and near, over a hillshaded terrain.\n");
        return 0;
    }
    memset(&o, 0, sizeof o);
    for (a = 0; a < argc; a++) {
        const char *k = argv[a];
        if (!strcmp(k, "-o") && a + 1 < argc) prefix = argv[++a];
        else if (!strcmp(k, "--compose") && a + 1 < argc) compose = argv[++a];
        else if (!strcmp(k, "--preview") && a + 1 < argc) preview = argv[++a];
        else if (!strcmp(k, "--dem") && a + 1 < argc) demp = argv[++a];
        else if (!strcmp(k, "--no-colour")) o.no_colour_correct = 1;
        else if (!strcmp(k, "--size") && a + 1 < argc) {
            if (!parse_size(argv[++a], &w, &h)) return usage_error("detail-maps", "--size needs WxH, e.g. 4096x4096, not", argv[a]);
        } else if ((!strcmp(k, "--seed") || !strcmp(k, "--factor") || !strcmp(k, "--sigma")) && a + 1 < argc) {
            if (!parse_double(argv[a + 1], &v) || v < 0 || v > 1e9) return usage_error("detail-maps", "not a non-negative number:", argv[a + 1]);
            if (!strcmp(k, "--seed")) seed = v;
            else if (!strcmp(k, "--factor")) {
                if (v < 1 || v > 4096) return usage_error("detail-maps", "--factor must be 1..4096", NULL);
                o.factor = (int)v;
            } else o.sigma = (float)v;
            a++;
        } else if (k[0] == '-') return usage_error("detail-maps", "unknown option or missing value:", k);
        else if (!src) src = k;
        else if (!exp_) exp_ = k;
        else return usage_error("detail-maps", "too many arguments:", k);
    }
    if (!src || !exp_) return usage_error("detail-maps", "needs MODEL_OR_SYNTH and EXEMPLAR", NULL);
    if (!prefix) return usage_error("detail-maps", "missing -o PREFIX", NULL);
    if ((st = tn_image_load(exp_, &ex, NULL))) return fail_status(st);
    have_model = is_tnw_file(src);
    if (have_model) {
        if (!(st = tn_texgan_load(&model, src))) {
            if (!w) { w = 8 * ex.width; h = 8 * ex.height; }
            st = tn_detail_maps_from_model(&maps, &model, (uint64_t)seed, w, h, &ex, &o);
            tn_texgan_free(&model);
        }
    } else {
        if (!(st = tn_image_load(src, &synth, NULL))) st = tn_detail_maps_from_image(&maps, &synth, &ex, &o);
        tn_image_free(&synth);
        if (!w && !st) { w = maps.width; h = maps.height; }
    }
    if (st) { tn_image_free(&ex); return fail_status(st); }
    st = tn_detail_maps_save(&maps, prefix);
    if (!st)
        printf("texture: %d x %d\nlow map: %d x %d (factor %d, %.0fx less memory)\nhigh map: %d x %d, tiled %.3f x %.3f\n", maps.width,
               maps.height, maps.low.width, maps.low.height, maps.factor,
               (double)maps.width * maps.height / ((double)maps.low.width * maps.low.height), maps.high.width, maps.high.height,
               (double)maps.tiling_x, (double)maps.tiling_y);
    if (!st && compose) {
        tn_save_opts so;
        memset(&so, 0, sizeof so);
        so.bit_depth = 8;
        st = tn_detail_compose(&maps, w, h, &img);
        if (!st) st = tn_image_save(compose, &img, &so);
        tn_image_free(&img);
    }
    if (!st && preview) {
        if (demp) st = tn_image_load(demp, &dem, NULL);
        if (!st) st = tn_detail_preview(&maps, &ex, demp ? &dem : NULL, 0, &img);
        if (!st) st = tn_image_save(preview, &img, NULL);
        tn_image_free(&img);
        tn_image_free(&dem);
    }
    tn_detail_maps_free(&maps);
    tn_image_free(&ex);
    return st ? fail_status(st) : 0;
}

/* ---- main -------------------------------------------------------------------------------- */

typedef struct command { const char *name; int (*fn)(int, char **); const char *summary; } command;

static const command commands[] = {
    {"info", cmd_info, "describe an image or heightmap file"},
    {"convert", cmd_convert, "convert between heightmap/image formats, keeping metres"},
    {"metrics", cmd_metrics, "compare two images: SSIM, PSNR, RMSE, MAE"},
    {"render", cmd_render, "hillshaded colour preview or 3D view of a DEM"},
    {"noise", cmd_noise, "procedural heightmap: Perlin fBm or explicit noise, optional drawn map"},
    {"texgan-train", cmd_texgan_train, "train a spatial GAN on one texture photo (checkpoints, resume)"},
    {"texgan-synth", cmd_texgan_synth, "synthesise a texture of any size from a model, streamed tile by tile"},
    {"detail-maps", cmd_detail_maps, "low/high detail maps (+ composed texture, tiling preview)"},
};

static void print_usage(FILE *f)
{
    size_t i;
    fprintf(f, "terrainnet %s - learn terrain from one example; synthesise terrain and textures\n\n"
               "usage: terrainnet [--threads N] COMMAND [ARGS]   (COMMAND --help for details)\n\ncommands:\n",
            TN_VERSION_STRING);
    for (i = 0; i < sizeof commands / sizeof commands[0]; i++)
        fprintf(f, "  %-13s %s\n", commands[i].name, commands[i].summary);
}

int main(int argc, char **argv)
{
    int a = 1;
    size_t i;
    while (a < argc && argv[a][0] == '-') {
        if (!strcmp(argv[a], "--help") || !strcmp(argv[a], "-h")) {
            print_usage(stdout);
            return 0;
        } else if (!strcmp(argv[a], "--version")) {
            printf("terrainnet %s\n", TN_VERSION_STRING);
            return 0;
        } else if (!strcmp(argv[a], "--threads") && a + 1 < argc) {
            int n;
            if (!parse_int(argv[a + 1], &n) || n < 1 || n > 64) {
                fprintf(stderr, "terrainnet: --threads needs a number from 1 to 64\n");
                return 2;
            }
            tn_set_threads(n);
            a += 2;
        } else {
            fprintf(stderr, "terrainnet: unknown option %s\n", argv[a]);
            print_usage(stderr);
            return 2;
        }
    }
    if (a >= argc) {
        print_usage(stderr);
        return 2;
    }
    install_progress();
    for (i = 0; i < sizeof commands / sizeof commands[0]; i++)
        if (!strcmp(argv[a], commands[i].name)) return commands[i].fn(argc - a - 1, argv + a + 1);
    fprintf(stderr, "terrainnet: unknown command '%s'\n", argv[a]);
    print_usage(stderr);
    return 2;
}
