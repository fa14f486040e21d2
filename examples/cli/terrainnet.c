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
    const char *outp = NULL, *draw = NULL, *like = NULL;
    int a, w = 512, h = 512, explicit_noise = 0;
    double v, seed = 1, weight = 0.5, range_lo = 0, range_hi = 0;
    if (wants_help(argc, argv)) {
        printf("usage: terrainnet noise -o OUT [--type perlin|explicit] [--size N [M]] [--seed S]\n"
               "                        [--octaves N] [--frequency F] [--lacunarity L] [--gain G]\n"
               "                        [--periodic] [--draw MAP --draw-weight W] [--range LO HI]\n"
               "                        [--like SOURCE]\n"
               "Writes a procedural heightmap in [0, 1] (or metres with --range): Perlin fBm\n"
               "(default: 8 octaves, 4 cells across, lacunarity 2, gain 0.5) or explicit multi-scale\n"
               "smoothed noise. --size N is N x N (default 512); N M is N wide, M high. --periodic\n"
               "makes Perlin tile seamlessly. --draw blends a drawn grey map (resized to the output)\n"
               "with weight W in [0, 1] (default 0.5) to steer the layout. --like SOURCE picks the\n"
               "Perlin gain (0.45..0.9) whose slopes and spectrum are closest to the DEM SOURCE: a\n"
               "content map for `terrainnet style --style SOURCE` (prints the gain).\n");
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
        else if (!strcmp(argv[a], "--like") && a + 1 < argc) like = argv[++a];
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
    if (like) {
        tn_image src = {0, 0, 0, NULL};
        float gain = 0.0f;
        if (explicit_noise) return usage_error("noise", "--like picks a Perlin gain; it does not go with --type explicit", NULL);
        if (!(st = tn_image_load(like, &src, NULL))) st = tn_style_content_noise(&out, w, h, &src, &po, &gain);
        tn_image_free(&src);
        if (!st) printf("gain: %.2f\n", gain);
    } else {
        st = explicit_noise ? tn_noise_explicit(&out, w, h, &eo) : tn_noise_perlin(&out, w, h, &po);
    }
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

/* ---- sketches ---------------------------------------------------------------------------- */

/* Parses "--size W [H]" at argv[*a]; returns 0 on a bad value. */
static int parse_size(int argc, char **argv, int *a, int *w, int *h)
{
    if (*a + 1 >= argc || !parse_int(argv[*a + 1], w) || *w < 2 || *w > TN_SKETCH_MAX_SIDE) return 0;
    *h = *w;
    (*a)++;
    if (*a + 1 < argc && parse_int(argv[*a + 1], h)) {
        if (*h < 2 || *h > TN_SKETCH_MAX_SIDE) return 0;
        (*a)++;
    }
    return 1;
}

/* Rasterises the set (16-bit PNG or float PFM by extension) and/or writes a preview. */
static tn_status write_sketch_images(const tn_contour_set *s, int w, int h, const char *raster, const char *preview,
                                     const char *dem_path)
{
    tn_image img = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL};
    tn_status st = TN_OK;
    if (raster) {
        tn_save_opts so;
        memset(&so, 0, sizeof so);
        so.bit_depth = 16;
        if ((st = tn_sketch_rasterise(s, w, h, &img)) || (st = tn_image_save(raster, &img, &so))) goto done;
        tn_image_free(&img);
    }
    if (preview) {
        if (dem_path && (st = tn_image_load(dem_path, &dem, NULL))) goto done;
        if ((st = tn_sketch_preview(s, dem_path ? &dem : NULL, w, h, &img))) goto done;
        st = tn_image_save(preview, &img, NULL);
    }
done:
    tn_image_free(&img);
    tn_image_free(&dem);
    return st;
}

static int cmd_sketch(int argc, char **argv)
{
    tn_contour_set s = {0, 0, 0, NULL};
    const char *in = NULL, *outp = NULL, *preview = NULL, *tns = NULL, *dem = NULL;
    int a, w = 0, h = 0;
    tn_status st;
    if (wants_help(argc, argv)) {
        printf("usage: terrainnet sketch IN.tns|IN.png [-o RASTER] [--size W [H]] [--preview PNG] [--dem DEM]\n"
               "                         [--tns OUT.tns]\n"
               "Reads a sketch: .tns text, or a drawing (red strokes = ridges, blue = valleys, brighter =\n"
               "higher; thinned and traced to polylines). -o writes a 3-channel raster (ridge mask, valley\n"
               "mask, height; 16-bit PNG, or .pfm for floats) at --size (default: the sketch canvas).\n"
               "--preview draws ridges yellow and valleys blue (over a hillshade of --dem if given).\n"
               "--tns writes the sketch as .tns text (e.g. to edit a traced drawing).\n");
        return 0;
    }
    for (a = 0; a < argc; a++) {
        if (!strcmp(argv[a], "-o") && a + 1 < argc) outp = argv[++a];
        else if (!strcmp(argv[a], "--preview") && a + 1 < argc) preview = argv[++a];
        else if (!strcmp(argv[a], "--tns") && a + 1 < argc) tns = argv[++a];
        else if (!strcmp(argv[a], "--dem") && a + 1 < argc) dem = argv[++a];
        else if (!strcmp(argv[a], "--size")) {
            if (!parse_size(argc, argv, &a, &w, &h)) return usage_error("sketch", "--size needs W [H] between 2 and 65536", NULL);
        } else if (argv[a][0] == '-' || in) return usage_error("sketch", "unknown option or extra argument:", argv[a]);
        else in = argv[a];
    }
    if (!in) return usage_error("sketch", "missing the input sketch (.tns or image)", NULL);
    if (!outp && !preview && !tns) return usage_error("sketch", "nothing to write: give -o, --preview or --tns", NULL);
    if ((st = tn_sketch_load(in, &s))) return fail_status(st);
    if (!w) { w = s.width; h = s.height; }
    st = tns ? tn_sketch_save(tns, &s) : TN_OK;
    if (!st) st = write_sketch_images(&s, w, h, outp, preview, dem);
    if (!st) printf("%d polylines on a %d x %d canvas\n", s.count, s.width, s.height);
    tn_contour_set_free(&s);
    return st ? fail_status(st) : 0;
}

static int cmd_sketch_random(int argc, char **argv)
{
    tn_contour_set user = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_sketch_random_opts o;
    const char *in = NULL, *outp = NULL, *preview = NULL;
    int a, w = 0, h = 0, nodes = 0;
    double seed = 1;
    tn_status st;
    if (wants_help(argc, argv)) {
        printf("usage: terrainnet sketch-random -o OUT.tns [--sketch IN.tns|IN.png] [--size W [H]] [--seed S]\n"
               "                                [--nodes N] [--preview PNG]\n"
               "Adds random ridges and valleys to a sketch (paper 000, section 5.2): N random nodes\n"
               "(heights 0.5-1) joined by a minimum spanning tree give ridges, the Voronoi vertices\n"
               "(heights 0-0.5) joined by another give valleys; edges crossing the sketch (or, for\n"
               "valleys, a kept ridge) are dropped. The output holds the sketch's own polylines first.\n"
               "--size defaults to the sketch canvas (required without --sketch); --nodes defaults to\n"
               "W*H/1024 clamped to 8-2048 (at most 8192); --seed defaults to 1.\n");
        return 0;
    }
    for (a = 0; a < argc; a++) {
        if (!strcmp(argv[a], "-o") && a + 1 < argc) outp = argv[++a];
        else if (!strcmp(argv[a], "--sketch") && a + 1 < argc) in = argv[++a];
        else if (!strcmp(argv[a], "--preview") && a + 1 < argc) preview = argv[++a];
        else if (!strcmp(argv[a], "--size")) {
            if (!parse_size(argc, argv, &a, &w, &h)) return usage_error("sketch-random", "--size needs W [H] between 2 and 65536", NULL);
        } else if (!strcmp(argv[a], "--seed") && a + 1 < argc) {
            if (!parse_double(argv[++a], &seed) || seed < 0) return usage_error("sketch-random", "--seed needs a non-negative number, not", argv[a]);
        } else if (!strcmp(argv[a], "--nodes") && a + 1 < argc) {
            if (!parse_int(argv[++a], &nodes) || nodes < 2 || nodes > 8192)
                return usage_error("sketch-random", "--nodes needs a number from 2 to 8192, not", argv[a]);
        } else return usage_error("sketch-random", "unknown option or missing value:", argv[a]);
    }
    if (!outp) return usage_error("sketch-random", "missing -o OUT.tns", NULL);
    if (in && (st = tn_sketch_load(in, &user))) return fail_status(st);
    if (!w) {
        if (!in) return usage_error("sketch-random", "give --size W [H] or --sketch", NULL);
        w = user.width;
        h = user.height;
    }
    memset(&o, 0, sizeof o);
    o.seed = (uint64_t)seed;
    o.nodes = nodes;
    st = tn_sketch_random(in ? &user : NULL, w, h, &o, &out);
    if (!st) st = tn_sketch_save(outp, &out);
    if (!st && preview) st = write_sketch_images(&out, w, h, NULL, preview, NULL);
    if (!st) printf("%d polylines (%d from the sketch) on a %d x %d canvas\n", out.count, user.count, w, h);
    tn_contour_set_free(&user);
    tn_contour_set_free(&out);
    return st ? fail_status(st) : 0;
}

static int cmd_align(int argc, char **argv)
{
    char tmp_path[4096];
    tn_contour_set sk = {0, 0, 0, NULL}, dense = {0, 0, 0, NULL}, parts = {0, 0, 0, NULL}, dem = {0, 0, 0, NULL},
                   demparts = {0, 0, 0, NULL};
    tn_align_opts o;
    const char *files[2] = {NULL, NULL}, *outp = NULL, *parts_out = NULL;
    int a, nfiles = 0, cut_dem = 0, choices = 0, *match = NULL, i;
    double seed = 1, t0;
    tn_status st;
    FILE *f;
    if (wants_help(argc, argv)) {
        printf("usage: terrainnet align SKETCH DEMPARTS.tns -o MAP.txt [--seed S] [--choices K] [--cut-dem]\n"
               "                        [--parts-out PARTS.tns]\n"
               "Cuts the sketch (.tns or drawn image) into 5-10 pixel parts and aligns each to a DEM\n"
               "contour part (paper 000, section 5.3: chain codes, rotation by k*pi/4, longest common\n"
               "substring, top 10, height mean/std, random pick among the best K = 5). DEMPARTS holds\n"
               "the DEM's contour parts (one polyline per part, index = position); with --cut-dem it\n"
               "holds whole contours and is cut here with the same seed. MAP.txt: one line per sketch\n"
               "part, `SKETCH_PART DEM_PART`. --parts-out writes the sketch parts the map refers to.\n");
        return 0;
    }
    for (a = 0; a < argc; a++) {
        if (!strcmp(argv[a], "-o") && a + 1 < argc) outp = argv[++a];
        else if (!strcmp(argv[a], "--parts-out") && a + 1 < argc) parts_out = argv[++a];
        else if (!strcmp(argv[a], "--cut-dem")) cut_dem = 1;
        else if (!strcmp(argv[a], "--seed") && a + 1 < argc) {
            if (!parse_double(argv[++a], &seed) || seed < 0) return usage_error("align", "--seed needs a non-negative number, not", argv[a]);
        } else if (!strcmp(argv[a], "--choices") && a + 1 < argc) {
            if (!parse_int(argv[++a], &choices) || choices < 1 || choices > 64)
                return usage_error("align", "--choices needs a number from 1 to 64, not", argv[a]);
        } else if (argv[a][0] == '-' || nfiles == 2) return usage_error("align", "unknown option or extra argument:", argv[a]);
        else files[nfiles++] = argv[a];
    }
    if (nfiles != 2) return usage_error("align", "needs SKETCH and DEMPARTS files", NULL);
    if (!outp) return usage_error("align", "missing -o MAP.txt", NULL);
    if ((st = tn_sketch_load(files[0], &sk)) || (st = tn_sketch_load(files[1], &dem)) || (st = tn_sketch_densify(&sk, &dense)) ||
        (st = tn_contour_parts_make(&dense, (uint64_t)seed, &parts)))
        goto done;
    if (cut_dem && (st = tn_contour_parts_make(&dem, (uint64_t)seed, &demparts))) goto done;
    if (!(match = (int *)malloc(((size_t)parts.count + 1) * sizeof(int)))) { fprintf(stderr, "terrainnet: out of memory\n"); goto done; }
    memset(&o, 0, sizeof o);
    o.seed = (uint64_t)seed;
    o.choices = choices;
    t0 = tn_time_seconds();
    if ((st = tn_sketch_align(&parts, cut_dem ? &demparts : &dem, &o, match))) goto done;
    t0 = tn_time_seconds() - t0;
    if (parts_out && (st = tn_sketch_save(parts_out, &parts))) goto done;
    /* written beside the target and renamed over it, so a failed run leaves an old map intact */
    if (strlen(outp) + 5 > sizeof tmp_path) { fprintf(stderr, "terrainnet: error: path too long: %s\n", outp); st = TN_ERR_IO; goto done; }
    sprintf(tmp_path, "%s.tmp", outp);
    if (!(f = fopen(tmp_path, "w"))) {
        fprintf(stderr, "terrainnet: error: cannot write %s\n", tmp_path);
        st = TN_ERR_IO;
        goto done;
    }
    fprintf(f, "# terrainnet align: sketch part -> DEM part (%d sketch parts, %d DEM parts, seed %.0f)\n", parts.count,
            (cut_dem ? &demparts : &dem)->count, seed);
    for (i = 0; i < parts.count; i++) fprintf(f, "%d %d\n", i, match[i]);
    if (fclose(f) != 0 || rename(tmp_path, outp) != 0) {
        fprintf(stderr, "terrainnet: error: write failed: %s\n", outp);
        remove(tmp_path);
        st = TN_ERR_IO;
        goto done;
    }
    printf("aligned %d sketch parts to %d DEM parts in %.1f ms\n", parts.count, (cut_dem ? &demparts : &dem)->count, t0 * 1e3);
done:
    free(match);
    tn_contour_set_free(&sk);
    tn_contour_set_free(&dense);
    tn_contour_set_free(&parts);
    tn_contour_set_free(&dem);
    tn_contour_set_free(&demparts);
    if (st == TN_ERR_IO && !tn_last_error()[0]) return 1;
    return st ? fail_status(st) : (match ? 0 : 1);
}


/* ---- extract ----------------------------------------------------------------------------- */

/* Writes a w x h byte mask as an 8-bit PNG (0 / 255). */
static tn_status save_mask(const char *path, const uint8_t *m, int w, int h)
{
    tn_image img = {0, 0, 0, NULL};
    tn_save_opts so;
    tn_status st;
    size_t i;
    if ((st = tn_image_create(&img, w, h, 1))) return st;
    for (i = 0; i < (size_t)w * h; i++) img.data[i] = m[i] ? 1.0f : 0.0f;
    memset(&so, 0, sizeof so);
    so.bit_depth = 8;
    st = tn_image_save(path, &img, &so);
    tn_image_free(&img);
    return st;
}

static int cmd_extract(int argc, char **argv)
{
    tn_image dem = {0, 0, 0, NULL};
    tn_extract_opts eo;
    tn_extraction ex;
    tn_status st = TN_OK;
    const char *in = NULL, *tns = NULL, *preview = NULL, *valleys = NULL, *ridges = NULL, *accp = NULL;
    int a, i, nv = 0, nr = 0;
    double v;
    if (wants_help(argc, argv)) {
        printf("usage: terrainnet extract DEM [-o SKETCH.tns] [--preview PNG] [--threshold CELLS] [--valleys PNG] [--ridges PNG]\n"
               "                          [--accumulation FILE.pfm] [--spacing DX [DY]]\n"
               "Extracts the ridge and valley network of a DEM (paper 000, section 4.1): priority-flood\n"
               "depression filling, D8 flow, flow accumulation; cells draining at least CELLS cells are\n"
               "valleys (default: 0.1 %% of the map, at least 8), the same on the inverted DEM gives ridges.\n"
               "Then closing, Strahler order, thinning to 1-px lines, dropping dangling lines under 10 px\n"
               "and the flattest 1 %%, splitting at 48 px. Prints a summary (name: value lines).\n"
               "  --preview PNG        ridges yellow, valleys blue over a hillshade (paper Figure 6)\n"
               "  --valleys/--ridges   binary masks (accumulation >= CELLS) before closing and thinning\n"
               "  --accumulation PFM   cells draining through each cell (valley flow), float\n"
               "  --spacing DX [DY]    pixel spacing in height units for the gradient filter (default 1)\n");
        return 0;
    }
    memset(&eo, 0, sizeof eo);
    for (a = 0; a < argc; a++) {
        if (!strcmp(argv[a], "-o") && a + 1 < argc) tns = argv[++a];
        else if (!strcmp(argv[a], "--preview") && a + 1 < argc) preview = argv[++a];
        else if (!strcmp(argv[a], "--valleys") && a + 1 < argc) valleys = argv[++a];
        else if (!strcmp(argv[a], "--ridges") && a + 1 < argc) ridges = argv[++a];
        else if (!strcmp(argv[a], "--accumulation") && a + 1 < argc) accp = argv[++a];
        else if (!strcmp(argv[a], "--threshold") && a + 1 < argc) {
            if (!parse_int(argv[a + 1], &eo.threshold) || eo.threshold < 1)
                return usage_error("extract", "--threshold needs a positive cell count, not", argv[a + 1]);
            a++;
        } else if (!strcmp(argv[a], "--spacing") && a + 1 < argc) {
            if (!parse_double(argv[a + 1], &v) || v <= 0) return usage_error("extract", "--spacing needs DX > 0, not", argv[a + 1]);
            eo.dx = eo.dy = (float)v;
            a++;
            if (a + 1 < argc && parse_double(argv[a + 1], &v)) {
                if (v <= 0) return usage_error("extract", "--spacing needs DY > 0, not", argv[a + 1]);
                eo.dy = (float)v;
                a++;
            }
        } else if (argv[a][0] == '-') return usage_error("extract", "unknown option or missing value:", argv[a]);
        else if (!in) in = argv[a];
        else return usage_error("extract", "too many arguments:", argv[a]);
    }
    if (!in) return usage_error("extract", "missing DEM", NULL);
    if ((st = tn_image_load(in, &dem, NULL))) return fail_status(st);
    if ((st = tn_extract(&dem, &eo, &ex))) {
        tn_image_free(&dem);
        return fail_status(st);
    }
    for (i = 0; i < ex.contours.count; i++) {
        if (ex.contours.items[i].type == TN_VALLEY) nv++;
        else nr++;
    }
    printf("size: %d x %d\nthreshold: %d\nvalley_contours: %d\nridge_contours: %d\n"
           "valley_max_strahler: %d\nridge_max_strahler: %d\n",
           ex.width, ex.height, ex.threshold, nv, nr, ex.valley_max_order, ex.ridge_max_order);
    if (!st && tns) st = tn_sketch_save(tns, &ex.contours);
    if (!st && valleys) st = save_mask(valleys, ex.valley_mask, ex.width, ex.height);
    if (!st && ridges) st = save_mask(ridges, ex.ridge_mask, ex.width, ex.height);
    if (!st && accp) {
        tn_image acc = {0, 0, 0, NULL};
        if (!(st = tn_image_create(&acc, ex.width, ex.height, 1))) {
            size_t k;
            for (k = 0; k < (size_t)ex.width * ex.height; k++) acc.data[k] = (float)ex.valley_flow.acc[k];
            st = tn_image_save(accp, &acc, NULL);
            tn_image_free(&acc);
        }
    }
    if (!st && preview) {
        tn_image pv = {0, 0, 0, NULL};
        if (!(st = tn_sketch_preview(&ex.contours, &dem, dem.width, dem.height, &pv))) {
            tn_save_opts so;
            memset(&so, 0, sizeof so);
            so.bit_depth = 8;
            st = tn_image_save(preview, &pv, &so);
            tn_image_free(&pv);
        }
    }
    tn_extraction_free(&ex);
    tn_image_free(&dem);
    return st ? fail_status(st) : 0;
}

/* ---- realism ----------------------------------------------------------------------------- */

/* Parses "--flag X [Y]" spacing; returns the number of extra arguments used, -1 on error. */
static int parse_spacing(int argc, char **argv, int a, float *dx, float *dy)
{
    double v;
    if (a + 1 >= argc || !parse_double(argv[a + 1], &v) || v <= 0) return -1;
    *dx = *dy = (float)v;
    if (a + 2 < argc && parse_double(argv[a + 2], &v)) {
        if (v <= 0) return -1;
        *dy = (float)v;
        return 2;
    }
    return 1;
}

static int cmd_realism(int argc, char **argv)
{
    tn_image img[2] = {{0, 0, 0, NULL}, {0, 0, 0, NULL}};
    tn_realism_opts ro;
    tn_realism r;
    tn_status st;
    const char *path[2] = {NULL, NULL};
    double range[2][2] = {{0, 0}, {0, 0}};
    int a, k;
    if (wants_help(argc, argv)) {
        printf("usage: terrainnet realism REFERENCE TERRAIN [--spacing DX [DY]] [--spacing-b DX [DY]]\n"
               "                          [--range-a LO HI] [--range-b LO HI] [--threshold CELLS]\n"
               "Realism report of TERRAIN against REFERENCE (e.g. a generated DEM against its example),\n"
               "one `name: value` line per figure: slope and curvature (Laplacian) histogram distances\n"
               "(earth mover's distance / the reference's mean, 0 = same distribution), distance of the\n"
               "radially averaged power spectra (RMS of log10 ratios) and each spectrum's log-log slope,\n"
               "drainage density and Strahler bifurcation ratio of each, SSIM and PSNR (same size only,\n"
               "else nan), and `distance`, the mean of the relative differences (0 = identical).\n"
               "Heights must share units: --range-a/-b map a [0, 1] file (PNG without a recorded range)\n"
               "to LO..HI; --spacing is the pixel size in height units (default 1; -b defaults to A's).\n");
        return 0;
    }
    memset(&ro, 0, sizeof ro);
    for (a = 0; a < argc; a++) {
        if (!strcmp(argv[a], "--spacing") || !strcmp(argv[a], "--spacing-b")) {
            int used = !strcmp(argv[a], "--spacing") ? parse_spacing(argc, argv, a, &ro.dx_a, &ro.dy_a)
                                                      : parse_spacing(argc, argv, a, &ro.dx_b, &ro.dy_b);
            if (used < 0) return usage_error("realism", "--spacing needs DX [DY] > 0 after", argv[a]);
            a += used;
        } else if ((!strcmp(argv[a], "--range-a") || !strcmp(argv[a], "--range-b")) && a + 2 < argc) {
            k = argv[a][8] == 'b';
            if (!parse_double(argv[a + 1], &range[k][0]) || !parse_double(argv[a + 2], &range[k][1]) || range[k][1] <= range[k][0])
                return usage_error("realism", "needs two numbers LO < HI after", argv[a]);
            a += 2;
        } else if (!strcmp(argv[a], "--threshold") && a + 1 < argc) {
            if (!parse_int(argv[a + 1], &ro.threshold) || ro.threshold < 1)
                return usage_error("realism", "--threshold needs a positive cell count, not", argv[a + 1]);
            a++;
        } else if (argv[a][0] == '-') return usage_error("realism", "unknown option or missing value:", argv[a]);
        else if (!path[0]) path[0] = argv[a];
        else if (!path[1]) path[1] = argv[a];
        else return usage_error("realism", "too many arguments:", argv[a]);
    }
    if (!path[0] || !path[1]) return usage_error("realism", "needs REFERENCE and TERRAIN", NULL);
    for (k = 0; k < 2; k++) {
        if ((st = tn_image_load(path[k], &img[k], NULL))) {
            tn_image_free(&img[0]);
            return fail_status(st);
        }
        if (range[k][1] > range[k][0]) {
            size_t i, n = (size_t)img[k].width * img[k].height * img[k].channels;
            for (i = 0; i < n; i++) img[k].data[i] = (float)(range[k][0] + img[k].data[i] * (range[k][1] - range[k][0]));
        }
    }
    st = tn_realism_compare(&img[0], &img[1], &ro, &r);
    tn_image_free(&img[0]);
    tn_image_free(&img[1]);
    if (st) return fail_status(st);
    printf("slope_distance: %.6f\ncurvature_distance: %.6f\nspectrum_distance: %.6f\n"
           "spectrum_slope_a: %.4f\nspectrum_slope_b: %.4f\ndrainage_density_a: %.6f\ndrainage_density_b: %.6f\n"
           "bifurcation_ratio_a: %.4f\nbifurcation_ratio_b: %.4f\nssim: %.6f\npsnr: %.4f\ndistance: %.6f\n",
           r.slope_distance, r.curvature_distance, r.spectrum_distance, r.spectrum_slope_a, r.spectrum_slope_b,
           r.drainage_density_a, r.drainage_density_b, r.bifurcation_ratio_a, r.bifurcation_ratio_b, r.ssim, r.psnr,
           r.distance);
    return 0;
}


/* ---- style -------------------------------------------------------------------------------- */

static int cmd_style(int argc, char **argv)
{
    tn_image content = {0, 0, 0, NULL}, style = {0, 0, 0, NULL}, out = {0, 0, 0, NULL}, tmp = {0, 0, 0, NULL};
    tn_style_opts so;
    tn_params *vgg = NULL;
    tn_status st;
    const char *outp = NULL, *cpath = NULL, *spath = NULL, *weights = NULL;
    int a, size = 0;
    double v, t0;
    if (wants_help(argc, argv)) {
        printf("usage: terrainnet style --content IN --style SOURCE -o OUT [--iters N]\n"
               "                        [--optimizer lbfgs|sgd|adam] [--weights vgg19.tnw] [--size N]\n"
               "                        [--levels N] [--seed S] [--lr R] [--content-weight A]\n"
               "                        [--style-weight B] [--sw-weight W] [--hist-weight H] [--tv-weight G]\n"
               "                        [--drain-weight D] [--valley-weight V] [--no-drain]\n"
               "Restyles the content map (e.g. from `terrainnet noise`) with the morphology of the\n"
               "SOURCE heightmap. The output has the content's size (or N x N with --size) and the\n"
               "source's height units. Defaults: built-in random-feature network (no file needed),\n"
               "L-BFGS, 40 iterations per pyramid level (Adam 150, SGD 300), levels down to 64 px\n"
               "(32 px with the drainage terms).\n"
               "--weights uses VGG-19 from a .tnw file (examples/vgg19_to_tnw.py makes one) with the\n"
               "paper's layers and weights. Weights: 0 = default, negative = term off.\n"
               "--drain-weight / --valley-weight (built-in net) weigh the drainage terms: closed\n"
               "basins as deep as the source's, and valleys carved as deep as the source's for the\n"
               "same drainage area. By default they are on (10 and 1) for fluvial sources (under 5 %%\n"
               "of the source in closed basins) and off for dunes, craters and karst; --no-drain\n"
               "switches them off (see README).\n");
        return 0;
    }
    memset(&so, 0, sizeof so);
    for (a = 0; a < argc; a++) {
        if (!strcmp(argv[a], "-o") && a + 1 < argc) outp = argv[++a];
        else if (!strcmp(argv[a], "--content") && a + 1 < argc) cpath = argv[++a];
        else if (!strcmp(argv[a], "--style") && a + 1 < argc) spath = argv[++a];
        else if (!strcmp(argv[a], "--weights") && a + 1 < argc) weights = argv[++a];
        else if (!strcmp(argv[a], "--no-drain")) so.drain_weight = so.valley_weight = -1.0f;
        else if (!strcmp(argv[a], "--optimizer") && a + 1 < argc) {
            a++;
            if (!strcmp(argv[a], "lbfgs")) so.optimizer = TN_STYLE_LBFGS;
            else if (!strcmp(argv[a], "sgd")) so.optimizer = TN_STYLE_SGD;
            else if (!strcmp(argv[a], "adam")) so.optimizer = TN_STYLE_ADAM;
            else return usage_error("style", "--optimizer must be lbfgs, sgd or adam, not", argv[a]);
        } else if ((!strcmp(argv[a], "--iters") || !strcmp(argv[a], "--size") || !strcmp(argv[a], "--levels") ||
                    !strcmp(argv[a], "--seed")) && a + 1 < argc) {
            int n;
            if (!parse_int(argv[a + 1], &n) || n < 1 || n > 1000000) return usage_error("style", "not a positive integer:", argv[a + 1]);
            if (!strcmp(argv[a], "--iters")) so.iters = n;
            else if (!strcmp(argv[a], "--size")) size = n;
            else if (!strcmp(argv[a], "--levels")) so.levels = n;
            else so.seed = (uint64_t)n;
            a++;
        } else if ((!strcmp(argv[a], "--lr") || !strcmp(argv[a], "--content-weight") || !strcmp(argv[a], "--style-weight") ||
                    !strcmp(argv[a], "--sw-weight") || !strcmp(argv[a], "--hist-weight") || !strcmp(argv[a], "--tv-weight") ||
                    !strcmp(argv[a], "--drain-weight") || !strcmp(argv[a], "--valley-weight")) &&
                   a + 1 < argc) {
            if (!parse_double(argv[a + 1], &v)) return usage_error("style", "not a number:", argv[a + 1]);
            if (!strcmp(argv[a], "--lr")) so.lr = (float)v;
            else if (!strcmp(argv[a], "--content-weight")) so.content_weight = (float)v;
            else if (!strcmp(argv[a], "--style-weight")) so.style_weight = (float)v;
            else if (!strcmp(argv[a], "--sw-weight")) so.sw_weight = (float)v;
            else if (!strcmp(argv[a], "--hist-weight")) so.hist_weight = (float)v;
            else if (!strcmp(argv[a], "--drain-weight")) so.drain_weight = (float)v;
            else if (!strcmp(argv[a], "--valley-weight")) so.valley_weight = (float)v;
            else so.tv_weight = (float)v;
            a++;
        } else return usage_error("style", "unknown option or missing value:", argv[a]);
    }
    if (!cpath || !spath) return usage_error("style", "needs --content IN and --style SOURCE", NULL);
    if (!outp) return usage_error("style", "missing -o OUT", NULL);
    if (size && size < 16) return usage_error("style", "--size must be at least 16", NULL);
    if ((st = tn_image_load(cpath, &content, NULL))) return fail_status(st);
    if ((st = tn_image_load(spath, &style, NULL))) goto done;
    if (size && (st = tn_image_resize(&tmp, &content, size, size, TN_RESIZE_BICUBIC))) goto done;
    if (size) {
        tn_image_free(&content);
        content = tmp;
        tmp.data = NULL;
    }
    if (weights && (st = tn_vgg19_load(&vgg, weights))) goto done;
    so.vgg = vgg;
    t0 = tn_time_seconds();
    if ((st = tn_style_transfer(&out, &content, &style, &so))) goto done;
    fprintf(stderr, "style: %d x %d in %.1f s (%s network)\n", out.width, out.height, tn_time_seconds() - t0,
            vgg ? "VGG-19" : "built-in");
    st = tn_image_save(outp, &out, NULL);
done:
    tn_image_free(&content);
    tn_image_free(&style);
    tn_image_free(&out);
    tn_image_free(&tmp);
    tn_params_free(vgg);
    return st ? fail_status(st) : 0;
}


/* ---- texture GAN and detail maps ---------------------------------------------------------- */

/* "W", "WxH" or "W H"-style size; returns 1 on success. */
static int parse_wxh(const char *s, int *w, int *h)
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
               "             [--feat-weight W] [--nearest]\n"
               "Trains a spatial GAN (PSGAN-style, spectral-norm + hinge) on random patches of one texture\n"
               "photo and writes the model (EMA generator + architecture). --normal stacks a normal map as\n"
               "channels 4-6. Defaults: 15 minutes in total (resumed time included), 64 px patches, batch\n"
               "4, 4 stages of 64-32-16 channels from 16 noise dims. The full training state is saved\n"
               "atomically to MODEL.tnw.ckpt (or --checkpoint) every 60 s (--checkpoint-seconds), so a\n"
               "killed run loses at most one interval; --resume continues it identically. --scale S learns\n"
               "the exemplar downscaled by S (features S times larger, e.g. crack cells) and upsamples.\n"
               "--augment flips/transposes real patches (small exemplars without a light direction).\n"
               "--feat-weight W weights the feature-statistics term of the generator loss (default 1, 0 = off).\n"
               "--nearest builds the first design (nearest upsampling, no per-pixel stage noise).\n");
        return 0;
    }
    memset(&o, 0, sizeof o);
    for (a = 0; a < argc; a++) {
        const char *k = argv[a];
        if (!strcmp(k, "-o") && a + 1 < argc) outp = argv[++a];
        else if (!strcmp(k, "--resume")) o.train.resume = 1;
        else if (!strcmp(k, "--augment")) o.augment = 1;
        else if (!strcmp(k, "--nearest")) o.nearest = 1;
        else if (!strcmp(k, "--normal") && a + 1 < argc) normal = argv[++a];
        else if (!strcmp(k, "--checkpoint") && a + 1 < argc) ckpt = argv[++a];
        else if ((!strcmp(k, "--minutes") || !strcmp(k, "--checkpoint-seconds") || !strcmp(k, "--iters") || !strcmp(k, "--seed") ||
                  !strcmp(k, "--patch") || !strcmp(k, "--batch") || !strcmp(k, "--gen-width") || !strcmp(k, "--disc-width") || !strcmp(k, "--disc-layers") ||
                  !strcmp(k, "--stages") || !strcmp(k, "--scale") || !strcmp(k, "--local") || !strcmp(k, "--global") || !strcmp(k, "--periodic") ||
                  !strcmp(k, "--feat-weight")) &&
                 a + 1 < argc) {
            if (!parse_double(argv[a + 1], &v) || v < 0 || v > 1e9) return usage_error("texgan-train", "not a non-negative number:", argv[a + 1]);
            if (!strcmp(k, "--minutes")) o.train.minutes = v;
            else if (!strcmp(k, "--checkpoint-seconds")) o.train.checkpoint_seconds = v;
            else if (!strcmp(k, "--iters")) o.train.max_iters = (long)v;
            else if (!strcmp(k, "--seed")) o.train.seed = (uint64_t)v;
            else if (!strcmp(k, "--patch")) o.patch = (int)v;
            else if (!strcmp(k, "--batch")) o.batch = (int)v;
            else if (!strcmp(k, "--gen-width")) o.gen_width = (int)v;
            else if (!strcmp(k, "--disc-width")) o.disc_width = (int)v;
            else if (!strcmp(k, "--disc-layers")) o.disc_layers = (int)v;
            else if (!strcmp(k, "--stages")) o.stages = (int)v;
            else if (!strcmp(k, "--scale")) o.scale = (int)v;
            else if (!strcmp(k, "--local")) o.noise_local = (int)v;
            else if (!strcmp(k, "--global")) o.noise_global = (int)v;
            else if (!strcmp(k, "--feat-weight")) o.feat_weight = v > 0 ? (float)v : -1.0f;
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
    o.train.checkpoint = ckpt;
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
            if (!parse_wxh(argv[++a], &w, &h)) return usage_error("texgan-synth", "--size needs WxH, e.g. 8192x8192, not", argv[a]);
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
            if (!parse_wxh(argv[++a], &w, &h)) return usage_error("detail-maps", "--size needs WxH, e.g. 4096x4096, not", argv[a]);
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
    {"sketch", cmd_sketch, "read a .tns or drawn sketch; rasterise, preview or convert it"},
    {"sketch-random", cmd_sketch_random, "enrich a sketch with random ridges and valleys (MST + Voronoi)"},
    {"align", cmd_align, "align sketch parts to a DEM's contour parts (chain codes + LCS)"},
    {"extract", cmd_extract, "ridge and valley network of a DEM: masks, accumulation, preview"},
    {"realism", cmd_realism, "realism report: slope/curvature/spectrum distances, drainage, SSIM"},
    {"style", cmd_style, "restyle a map with the morphology of a real heightmap (style transfer)"},
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
