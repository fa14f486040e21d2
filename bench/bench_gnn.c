/* bench_gnn: the sketch-to-terrain graph network (paper 000, sections 4.2-5.4) on one region of
   ../shared/data: train on a 128 x 128 crop for a fixed budget, then
   - reconstruction: generate from the crop's own extracted network, SSIM / PSNR to the crop;
   - neighbours (paper Table 1): each of the 8 neighbouring 128 crops generated from its own
     extracted network, mean SSIM / PSNR, next to two baselines on the same sketch pixels: the
     constant mean of their heights and their membrane (Laplace) interpolation; at the default
     extraction threshold (dense sketch) and at 200 and 500 cells (sparse sketches). The GNN
     figures use the residual gain tested on each sketch (the default, tn_gnn_gain: its mean is
     printed); the `gain1` lines are the network as trained (gain 1).
   - spectrum distance (tn_realism_compare) of the neighbours to the truth, GNN vs membrane;
   - speed: training steps/s, the training time at which the reconstruction first reaches SSIM
     0.95 and 0.97 (the run is trained in segments of 150 iterations, checkpoint + resume, which
     is bit-identical to one run but for the embedding phase starting at a segment boundary),
     generation of 128 x 128 (with a 30-step fine-tune too) and of
     512 x 512 (the sketch of the map's top-left 512 crop; tiled internally), peak memory (RSS).
   The crop is where <region>_128.png lies in <region>_full.png, moved inwards if needed so its
   8 neighbours fit (moved=0 keeps it there and scores the neighbours that fit: a model of the
   128 example itself, trained by gnn-train). Heights in metres by the mapping of dem_index.csv.
   Usage: bench_gnn [region] [minutes] [threads] [key=value ...]   (defaults alps_montblanc 3 2),
   from the repository root (the drawn sketch is examples/data/sketch_a.tns).
   Variants (the measurements of design choices in docs/gnn.md): iters=N trains N iterations
   instead of a time budget (the same model on any machine and load), seed=S (training seed,
   default 1), smooth=W sketch=W further=W (tn_gnn_opts' loss weights), phase=P (embed_phase, the
   share of the budget at the end that trains for the example alone; default the library's,
   -1 = none), index=-1 (part_index:
   the projection index on parts without an embedding too), gain=G (the generation's
   residual gain for the GNN figures; default 0 = tested on each sketch), pictures=1 (writes
   gnn_fig10_<region>.png: the example crop, then the Figure 10 sketch as membrane, GNN and GNN
   with 48 random nodes, hillshaded), finetune=N (fine-tune steps of the neighbours' GNN figures,
   the drawn sketch's and the 512 map's; default 0), model=PATH (load the model from PATH and
   skip training when it exists, else train and save it there), grow=G (tn_gnn_generate_opts.grow of
   every generation: 0 = auto, the default; -1 = never densify by example, the form before it),
   moved=0 (see above).
   Prints `name: value unit` lines. */
#include "terrainnet.h"
#include "bench_data.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <sys/resource.h>
#include <unistd.h>

static double peak_rss_mb(void)
{
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    return ru.ru_maxrss / 1024.0; /* kB on Linux */
}

#define SIDE 128

typedef struct scores { double ssim, psnr, spec; int n; } scores;

static void add(scores *s, const tn_image *ref, const tn_image *img)
{
    tn_metrics m;
    tn_realism r;
    if (tn_compare(&m, ref, img, 0)) return;
    s->ssim += m.ssim;
    s->psnr += m.psnr;
    if (!tn_realism_compare(&r, ref, img, NULL)) s->spec += r.spectrum_distance;
    s->n++;
}

/* The crop's own network at threshold thr (0 = default); its sketch pixels' share in *cover. */
static int sketch_of(const tn_image *crop, int thr, tn_contour_set *out, double *cover)
{
    tn_extraction ex;
    tn_extract_opts eo;
    tn_image r = {0, 0, 0, NULL};
    size_t i, n = 0;
    memset(&eo, 0, sizeof eo);
    eo.threshold = thr;
    if (tn_extract(&ex, crop, &eo)) return 0;
    *out = ex.contours;
    memset(&ex.contours, 0, sizeof ex.contours);
    tn_extraction_free(&ex);
    if (!out->count || tn_sketch_rasterise(&r, out, crop->width, crop->height)) return 0;
    for (i = 0; i < (size_t)r.width * r.height; i++) n += r.data[3 * i] > 0 || r.data[3 * i + 1] > 0;
    *cover = (double)n / ((double)r.width * r.height);
    tn_image_free(&r);
    return 1;
}

/* The constant baseline: the mean height of the sketch pixels. */
static int mean_baseline(const tn_contour_set *sk, int w, int h, tn_image *out)
{
    tn_image r = {0, 0, 0, NULL};
    double s = 0;
    size_t i, n = 0;
    if (tn_sketch_rasterise(&r, sk, w, h) || tn_image_create(out, w, h, 1)) return 0;
    for (i = 0; i < (size_t)w * h; i++)
        if (r.data[3 * i] > 0 || r.data[3 * i + 1] > 0) { s += r.data[3 * i + 2]; n++; }
    for (i = 0; i < (size_t)w * h; i++) out->data[i] = (float)(n ? s / (double)n : 0.0);
    tn_image_free(&r);
    return 1;
}


/* The paper's Figure 10 sketch (examples/data/sketch_a.tns: a ridge shaped like the letter A,
   high at the apex, inside a low circular valley; heights in [0, 1]) on a side x side canvas;
   rot = 1 turns it by 90 degrees, (x, y) -> (side-1-y, x). */
static int a_in_circle(int side, int rot, tn_contour_set *s)
{
    float k;
    int i, j;
    if (tn_sketch_load(s, "examples/data/sketch_a.tns") != TN_OK) {
        fprintf(stderr, "bench_gnn: %s\n", tn_last_error());
        return 0;
    }
    k = (float)(side - 1) / (float)(s->width - 1);
    for (i = 0; i < s->count; i++)
        for (j = 0; j < s->items[i].npoints; j++) {
            float *p = s->items[i].points + 3 * j, x = p[0] * k, y = p[1] * k;
            p[0] = rot ? (float)(side - 1) - y : x;
            p[1] = rot ? x : y;
        }
    s->width = s->height = side;
    return 1;
}

/* Hillshaded colour panels side by side (heights on the example's lo..hi, its pixel spacing),
   each scaled to `side` px (nearest), 4 px apart: the picture of a figure. */
static void save_panels(const char *path, const tn_image *const *dem, int n, int side, float lo, float hi, const double *dxy)
{
    tn_render_opts ro;
    tn_image strip = {0, 0, 0, NULL}, pv = {0, 0, 0, NULL}, sc = {0, 0, 0, NULL};
    int i, y;
    memset(&ro, 0, sizeof ro);
    ro.lo = lo;
    ro.hi = hi;
    ro.shade.dx = (float)dxy[0];
    ro.shade.dy = (float)dxy[1];
    if (tn_image_create(&strip, n * side + (n - 1) * 4, side, 3)) return;
    for (i = 0; i < n; i++) {
        if (!tn_render_preview(&pv, dem[i], &ro) && !tn_image_resize(&sc, &pv, side, side, TN_RESIZE_NEAREST))
            for (y = 0; y < side; y++)
                memcpy(&TN_PIXEL(&strip, i * (side + 4), y, 0), &TN_PIXEL(&sc, 0, y, 0), (size_t)side * 3 * sizeof(float));
        tn_image_free(&pv);
        tn_image_free(&sc);
    }
    if (!tn_image_save(path, &strip, NULL)) printf("picture: %s\n", path);
    tn_image_free(&strip);
}

/* Relief along the sketch's lines: at every densified point, the terrain 3 px to each side
   (normal from the points 2 before and after, nearest pixel) minus its mean over the 15 points
   around it on the same line; RMS over the points, in the terrain's units. The membrane has
   next to none; hatching across a line (a period of the 5-10 px parts) raises it. */
static double along_relief(const tn_contour_set *sk, const tn_image *img)
{
    tn_contour_set dn;
    double sum = 0;
    long cnt = 0;
    int c, i, side, q;
    memset(&dn, 0, sizeof dn);
    if (tn_sketch_densify(&dn, sk)) return -1;
    for (c = 0; c < dn.count; c++) {
        const tn_contour *L = &dn.items[c];
        int n = L->npoints;
        float *v;
        if (n < 20 || !(v = (float *)malloc((size_t)n * sizeof(float)))) continue;
        for (side = -1; side <= 1; side += 2) {
            for (i = 0; i < n; i++) {
                int a = i < 2 ? 0 : i - 2, b = i + 2 >= n ? n - 1 : i + 2, x, y;
                float tx = L->points[3 * b] - L->points[3 * a], ty = L->points[3 * b + 1] - L->points[3 * a + 1], tl = sqrtf(tx * tx + ty * ty);
                if (!(tl > 0)) tl = 1;
                x = (int)floorf(L->points[3 * i] - 3.0f * side * ty / tl + 0.5f);
                y = (int)floorf(L->points[3 * i + 1] + 3.0f * side * tx / tl + 0.5f);
                x = x < 0 ? 0 : x >= img->width ? img->width - 1 : x;
                y = y < 0 ? 0 : y >= img->height ? img->height - 1 : y;
                v[i] = TN_PIXEL(img, x, y, 0);
            }
            for (i = 7; i < n - 7; i++) {
                double m = 0;
                for (q = i - 7; q <= i + 7; q++) m += v[q];
                m = v[i] - m / 15.0;
                sum += m * m;
                cnt++;
            }
        }
        free(v);
    }
    tn_contour_set_free(&dn);
    return cnt ? sqrt(sum / (double)cnt) : -1;
}

/* Ordering share and realism distance to the example of one user-sketch output. */
static void user_scores(const char *name, const tn_contour_set *sk, const tn_image *ex, const tn_image *img)
{
    double share = 0;
    int n = 0;
    tn_realism r;
    tn_gnn_ordering(&share, sk, img, 0, &n);
    printf("user_%s_ordering: %.1f %% (%d points)\n", name, 100.0 * share, n);
    if (!tn_realism_compare(&r, ex, img, NULL)) printf("user_%s_realism_distance: %.4f\n", name, r.distance);
    printf("user_%s_along_relief: %.2f (RMS beside the lines, example units)\n", name, along_relief(sk, img));
}

static int progress(void *user, const char *stage, double f)
{
    static double last;
    double t = tn_time_seconds();
    (void)user;
    /* every 15 s: the short stages (hundreds of extractions a run) would flood the log */
    if (t - last > 15.0) {
        double eta = tn_progress_eta();
        last = t;
        if (eta >= 0) fprintf(stderr, "  %s %3.0f %% (eta %.0f s)\n", stage, 100.0 * f, eta);
        else fprintf(stderr, "  %s %3.0f %%\n", stage, 100.0 * f);
    }
    return 0;
}

/* trace=1: after every segment, the model's output (gain 1) on windows of the full map, mean SSIM
   per density: ring 1 = the 8 neighbours, ring 2 = the windows two crops away (those inside the
   map). With holdout=0 that is the network as it trains; with holdouts, the early network so far. */
typedef struct trace_set { tn_image win[24]; tn_contour_set sk[3][24]; int ok[3][24], n, ring[24]; } trace_set;

static void trace_prepare(trace_set *t, const tn_image *full, int cx, int cy, const int *thr)
{
    int dx, dy, ti;
    double cover;
    memset(t, 0, sizeof *t);
    for (dy = -2; dy <= 2; dy++)
        for (dx = -2; dx <= 2; dx++) {
            int x = cx + dx * SIDE, y = cy + dy * SIDE, r = abs(dx) > abs(dy) ? abs(dx) : abs(dy);
            if (!r || x < 0 || y < 0 || x + SIDE > full->width || y + SIDE > full->height) continue;
            tn_image_crop(&t->win[t->n], full, x, y, SIDE, SIDE);
            t->ring[t->n] = r;
            for (ti = 0; ti < 3; ti++) t->ok[ti][t->n] = sketch_of(&t->win[t->n], thr[ti], &t->sk[ti][t->n], &cover);
            t->n++;
        }
}

static void trace_print(const trace_set *t, const tn_gnn *model, long iters, double recon)
{
    tn_gnn_generate_opts go;
    int ti, i, ring;
    memset(&go, 0, sizeof go);
    go.gain = 1.0f;
    printf("trace: %ld iterations recon %.4f", iters, recon);
    for (ring = 1; ring <= 2; ring++) {
        printf(" ring%d", ring);
        for (ti = 0; ti < 3; ti++) {
            scores s = {0, 0, 0, 0};
            for (i = 0; i < t->n; i++) {
                tn_image out = {0, 0, 0, NULL};
                tn_metrics m;
                if (t->ring[i] != ring || !t->ok[ti][i]) continue;
                if (!tn_gnn_generate(&out, model, &t->sk[ti][i], SIDE, SIDE, &go) && !tn_compare(&m, &t->win[i], &out, 0)) {
                    s.ssim += m.ssim;
                    s.n++;
                }
                tn_image_free(&out);
            }
            printf(" %.4f", s.n ? s.ssim / s.n : 0.0);
        }
    }
    printf("\n");
    fflush(stdout);
}

int main(int argc, char **argv)
{
    const char *region = argc > 1 ? argv[1] : "alps_montblanc";
    double minutes = argc > 2 ? atof(argv[2]) : 3.0, h0, h1, t0, dxy[2];
    int threads = argc > 3 ? atoi(argv[3]) : 2, thr[3] = {0, 200, 500}, cx, cy, d, ti, dx, dy;
    tn_image full = {0, 0, 0, NULL}, c128 = {0, 0, 0, NULL}, crop = {0, 0, 0, NULL}, out = {0, 0, 0, NULL};
    tn_gnn model;
    tn_gnn_opts o;
    tn_gnn_stats st;
    tn_gnn_generate_opts go;
    tn_contour_set sk;
    double cover;
    scores rec = {0, 0, 0, 0};
    double t95 = -1, t97 = -1;
    float gain = 0.0f, phase = 0.0f; /* 0: tn_gnn_defaults' embed_phase */
    double done = 0;
    long iters = 0, phase_from = -1;
    int seg, a, pictures = 0, trace = 0, hold = 1, nhold = 0, finetune = 0, grow = 0, moved = 1;
    const char *model_path = NULL;
    tn_image hw[4];
    trace_set ts;
    char ckpt[256];
    memset(&o, 0, sizeof o);
    o.train.seed = 1;
    for (a = 4; a < argc; a++) {
        const char *eq = strchr(argv[a], '=');
        double v = eq ? atof(eq + 1) : 0.0;
        size_t kl = eq ? (size_t)(eq - argv[a]) : 0;
        if (kl == 5 && !strncmp(argv[a], "iters", kl)) iters = (long)v;
        else if (kl == 4 && !strncmp(argv[a], "seed", kl)) o.train.seed = (uint64_t)v;
        else if (kl == 6 && !strncmp(argv[a], "smooth", kl)) o.smooth_weight = (float)v;
        else if (kl == 6 && !strncmp(argv[a], "sketch", kl)) o.sketch_weight = (float)v;
        else if (kl == 7 && !strncmp(argv[a], "further", kl)) o.further_weight = (float)v;
        else if (kl == 4 && !strncmp(argv[a], "gain", kl)) gain = (float)v;
        else if (kl == 4 && !strncmp(argv[a], "grow", kl)) grow = (int)v;
        else if (kl == 5 && !strncmp(argv[a], "phase", kl)) phase = (float)v;
        else if (kl == 8 && !strncmp(argv[a], "pictures", kl)) pictures = v != 0;
        else if (kl == 5 && !strncmp(argv[a], "index", kl)) o.part_index = (int)v;
        else if (kl == 5 && !strncmp(argv[a], "trace", kl)) trace = v != 0;
        else if (kl == 7 && !strncmp(argv[a], "holdout", kl)) hold = v != 0;
        else if (kl == 8 && !strncmp(argv[a], "phasenet", kl)) o.phase_network = (int)v;
        else if (kl == 8 && !strncmp(argv[a], "finetune", kl)) finetune = (int)v;
        else if (kl == 5 && !strncmp(argv[a], "model", kl)) model_path = eq + 1;
        else if (kl == 5 && !strncmp(argv[a], "moved", kl)) moved = v != 0;
        else {
            fprintf(stderr, "bench_gnn: unknown variant '%s' (iters= seed= smooth= sketch= further= phase= index= gain= grow= holdout= phasenet= finetune= model= moved= pictures= trace=)\n", argv[a]);
            return 2;
        }
        printf("variant: %s\n", argv[a]);
    }
    if (iters > 0) minutes = 1e6;
    if (!(minutes > 0)) minutes = 3.0;
    tn_set_threads(threads);
    snprintf(ckpt, sizeof ckpt, "/tmp/bench_gnn_%s_%ld.ckpt", region, (long)getpid());
    if (!height_mapping(region, dxy, &h0, &h1) || !load_metres(region, "full", h0, h1, &full) || !load_metres(region, "128", h0, h1, &c128)) {
        fprintf(stderr, "bench_gnn: cannot read %s from %s (set TN_DATA)\n", region, data_dir());
        return 1;
    }
    if (!locate(&full, &c128, &cx, &cy)) {
        fprintf(stderr, "bench_gnn: %s_128 not found in %s_full\n", region, region);
        return 1;
    }
    /* moved=0 scores the neighbours that fit on the map; moved=1 needs all eight */
    if (moved && (full.width < 3 * SIDE || full.height < 3 * SIDE)) {
        fprintf(stderr, "bench_gnn: %s_full is %dx%d px, under the 384 px that moved=1 needs (use moved=0)\n", region, full.width, full.height);
        return 1;
    }
    if (moved) {
        if (cx < SIDE) cx = SIDE;
        if (cy < SIDE) cy = SIDE;
        if (cx + 2 * SIDE > full.width) cx = full.width - 2 * SIDE;
        if (cy + 2 * SIDE > full.height) cy = full.height - 2 * SIDE;
    }
    printf("region: %s\n", region);
    printf("crop: %d %d px (x y of the trained 128 crop in %s_full)\n", cx, cy, region);
    printf("threads: %d\n", threads);
    tn_image_crop(&crop, &full, cx, cy, SIDE, SIDE);

    o.train.minutes = minutes;
    o.train.checkpoint = ckpt;
    /* the windows gnn-train would take, as long as they are two windows away: never the
       neighbours scored below (every region of ../shared/data has room) */
    if (hold && (cx >= 2 * SIDE || cy >= 2 * SIDE || cx + 3 * SIDE <= full.width || cy + 3 * SIDE <= full.height) &&
        (nhold = tn_gnn_holdout_windows(hw, &full, cx, cy, SIDE, SIDE, 4)) > 0) {
        o.holdout = hw;
        o.holdout_count = nhold;
    }
    printf("holdout_windows: %d\n", nhold);
    if (phase == 0) {
        tn_gnn_opts d = o;
        tn_gnn_defaults(&d);
        phase = d.embed_phase;
    }
    tn_set_progress(progress, NULL);
    if (!sketch_of(&crop, 0, &sk, &cover)) {
        fprintf(stderr, "bench_gnn: no network in the crop\n");
        return 1;
    }
    memset(&go, 0, sizeof go);
    go.grow = grow;
    if (trace) trace_prepare(&ts, &full, cx, cy, thr);
    if (model_path && !access(model_path, F_OK)) { /* model=PATH: a model trained before */
        if (tn_gnn_load(&model, model_path)) {
            fprintf(stderr, "bench_gnn: %s\n", tn_last_error());
            return 1;
        }
        printf("model: %s (loaded, %ld iterations)\n", model_path, model.iterations);
    } else {
        t0 = tn_time_seconds();
        for (seg = 1;; seg++) {
            tn_metrics mt;
            o.train.max_iters = iters > 0 && iters < 150L * seg ? iters : 150L * seg;
            o.train.resume = seg > 1;
            /* the segments' iteration caps are not the budget: the embedding phase follows the whole
               run's, switched on from the first segment that starts in its last `phase` share */
            o.embed_phase = seg > 1 && phase > 0 && done >= 1.0 - phase ? 0.9999f : -1.0f;
            if (o.embed_phase > 0 && phase_from < 0) phase_from = st.iterations;
            if (tn_gnn_train(&model, &crop, &o, &st)) {
                fprintf(stderr, "bench_gnn: training failed: %s\n", tn_last_error());
                return 1;
            }
            done = iters > 0 ? (double)st.iterations / (double)iters : st.seconds / (minutes * 60.0);
            if (!tn_gnn_generate(&out, &model, &sk, SIDE, SIDE, &go) && !tn_compare(&mt, &crop, &out, 0)) {
                if (mt.ssim >= 0.95 && t95 < 0) t95 = st.seconds;
                if (mt.ssim >= 0.97 && t97 < 0) t97 = st.seconds;
                fprintf(stderr, "  %ld iterations, %.0f s: reconstruction SSIM %.4f\n", st.iterations, st.seconds, mt.ssim);
                if (trace) trace_print(&ts, &model, st.iterations, mt.ssim);
            }
            tn_image_free(&out);
            if (st.iterations < 150L * seg) break; /* the budget ended the run */
            tn_gnn_free(&model);
        }
        remove(ckpt);
        printf("train_minutes: %.2f min\n", (tn_time_seconds() - t0) / 60.0);
        printf("train_iterations: %ld\n", st.iterations);
        printf("train_steps_per_s: %.2f steps/s\n", st.seconds > 0 ? st.iterations / st.seconds : 0.0);
        if (t95 >= 0) printf("train_seconds_to_ssim_0.95: %.0f s\n", t95);
        else printf("train_seconds_to_ssim_0.95: not reached\n");
        if (t97 >= 0) printf("train_seconds_to_ssim_0.97: %.0f s\n", t97);
        else printf("train_seconds_to_ssim_0.97: not reached\n");
        printf("train_parts: %d\n", st.parts);
        printf("train_edges: %d (fixed)\n", st.edges);
        printf("train_loss_mse: %.5f (normalised heights^2)\n", st.loss_mse);
        printf("train_loss_ssim: %.4f (1 - SSIM; in the embedding phase at the end)\n", st.loss_ssim);
        printf("train_embed_phase_from: %ld iterations\n", phase_from);
        if (nhold) {
            printf("train_holdout_checks: %d\n", st.holdout_checks);
            printf("train_holdout_best_iteration: %ld\n", st.holdout_iteration);
            printf("train_holdout_best_ssim: %.4f (last check %.4f)\n", st.holdout_ssim, st.holdout_last_ssim);
        }
        if (model_path && tn_gnn_save(model_path, &model)) fprintf(stderr, "bench_gnn: %s\n", tn_last_error());
    }
    {
        const tn_tensor *gs = tn_params_find(model.weights, "gain.scale");
        printf("gain_scale: %.2f (the gain test's, calibrated on the holdouts; 1 = none)\n", gs ? (double)gs->data[0] : 1.0);
    }

    /* reconstruction from the crop's own network */
    t0 = tn_time_seconds();
    if (tn_gnn_generate(&out, &model, &sk, SIDE, SIDE, &go)) {
        fprintf(stderr, "bench_gnn: generation failed: %s\n", tn_last_error());
        return 1;
    }
    printf("generate_128_ms: %.0f ms\n", (tn_time_seconds() - t0) * 1e3);
    {
        tn_image ft = {0, 0, 0, NULL};
        go.finetune = 30;
        t0 = tn_time_seconds();
        if (!tn_gnn_generate(&ft, &model, &sk, SIDE, SIDE, &go)) printf("generate_128_finetune30_ms: %.0f ms\n", (tn_time_seconds() - t0) * 1e3);
        tn_image_free(&ft);
        go.finetune = 0;
    }
    add(&rec, &crop, &out);
    printf("recon_ssim: %.4f\n", rec.ssim);
    printf("recon_psnr: %.2f dB\n", rec.psnr);
    printf("recon_along_relief: %.2f (truth %.2f; RMS beside the lines)\n", along_relief(&sk, &out), along_relief(&sk, &crop));
    tn_image_free(&out);
    rec.ssim = rec.psnr = rec.spec = 0;
    rec.n = 0;
    tn_gnn_membrane(&out, &sk, SIDE, SIDE);
    add(&rec, &crop, &out);
    printf("recon_membrane_ssim: %.4f\n", rec.ssim);
    printf("recon_membrane_psnr: %.2f dB\n", rec.psnr);
    tn_image_free(&out);
    tn_contour_set_free(&sk);
    { /* an example stored in coarse height steps (8-bit) is learnt without them (gnn-train's
         dequantize): its reconstruction from the network of the example without the steps */
        float step = tn_image_height_step(&crop, 1);
        tn_image sm = {0, 0, 0, NULL};
        double cover2;
        if (step > 0 && !tn_image_dequantize(&sm, &crop, step) && sketch_of(&sm, 0, &sk, &cover2)) {
            scores r2 = {0, 0, 0, 0}, m2 = {0, 0, 0, 0};
            if (!tn_gnn_generate(&out, &model, &sk, SIDE, SIDE, &go)) add(&r2, &sm, &out);
            tn_image_free(&out);
            if (!tn_gnn_membrane(&out, &sk, SIDE, SIDE)) add(&m2, &sm, &out);
            tn_image_free(&out);
            printf("recon_smooth_ssim: %.4f (the example without its %.2f m steps, from its own network, as gnn-train learns it; membrane %.4f)\n",
                   r2.ssim, (double)step, m2.ssim);
            tn_contour_set_free(&sk);
        }
        tn_image_free(&sm);
    }

    /* the 8 neighbours, dense and sparse sketches */
    for (ti = 0; ti < 3; ti++) {
        scores g = {0, 0, 0, 0}, mem = {0, 0, 0, 0}, mean = {0, 0, 0, 0}, raw = {0, 0, 0, 0};
        double cov = 0, gains = 0;
        int nc = 0;
        for (dy = -1; dy <= 1; dy++)
            for (dx = -1; dx <= 1; dx++) {
                tn_image nb = {0, 0, 0, NULL};
                if (!dx && !dy) continue;
                if (tn_image_crop(&nb, &full, cx + dx * SIDE, cy + dy * SIDE, SIDE, SIDE)) continue; /* off the map (moved=0) */
                if (!sketch_of(&nb, thr[ti], &sk, &cover)) {
                    tn_image_free(&nb);
                    continue;
                }
                cov += cover;
                nc++;
                {
                    float gn = 1.0f;
                    go.gain = gain;
                    if (!tn_gnn_gain(&gn, &model, &sk, SIDE, SIDE, &go)) gains += gn;
                    if (gain == 0.0f) go.gain = gn > 0 ? gn : -1.0f; /* tested once, not again inside generate */
                }
                go.finetune = finetune;
                if (!tn_gnn_generate(&out, &model, &sk, SIDE, SIDE, &go)) add(&g, &nb, &out);
                else fprintf(stderr, "  neighbour (%d, %d): %s\n", dx, dy, tn_last_error());
                go.finetune = 0;
                tn_image_free(&out);
                go.gain = 1.0f; /* the network as trained, without the gain tested on the sketch */
                if (!tn_gnn_generate(&out, &model, &sk, SIDE, SIDE, &go)) add(&raw, &nb, &out);
                go.gain = gain;
                tn_image_free(&out);
                if (!tn_gnn_membrane(&out, &sk, SIDE, SIDE)) add(&mem, &nb, &out);
                tn_image_free(&out);
                if (mean_baseline(&sk, SIDE, SIDE, &out)) add(&mean, &nb, &out);
                tn_image_free(&out);
                tn_contour_set_free(&sk);
                tn_image_free(&nb);
            }
        d = thr[ti];
        if (!nc || !g.n || !mem.n || !mean.n) {
            printf("neighbours_t%d: no sketch\n", d);
            continue;
        }
        printf("neighbours_t%d_sketch_pixels: %.1f %%\n", d, 100.0 * cov / nc);
        printf("neighbours_t%d_gnn_ssim: %.4f (%d crops)\n", d, g.ssim / g.n, g.n);
        printf("neighbours_t%d_gnn_psnr: %.2f dB\n", d, g.psnr / g.n);
        printf("neighbours_t%d_gain_mean: %.3f (tn_gnn_gain)\n", d, gains / nc);
        if (raw.n) printf("neighbours_t%d_gnn_gain1_ssim: %.4f (gain 1: the network as trained)\n", d, raw.ssim / raw.n);
        if (raw.n) printf("neighbours_t%d_gnn_gain1_psnr: %.2f dB\n", d, raw.psnr / raw.n);
        if (raw.n) printf("neighbours_t%d_gnn_gain1_spectrum_distance: %.3f\n", d, raw.spec / raw.n);
        printf("neighbours_t%d_membrane_ssim: %.4f\n", d, mem.ssim / mem.n);
        printf("neighbours_t%d_membrane_psnr: %.2f dB\n", d, mem.psnr / mem.n);
        printf("neighbours_t%d_mean_ssim: %.4f\n", d, mean.ssim / mean.n);
        printf("neighbours_t%d_mean_psnr: %.2f dB\n", d, mean.psnr / mean.n);
        printf("neighbours_t%d_gnn_spectrum_distance: %.3f\n", d, g.spec / g.n);
        printf("neighbours_t%d_membrane_spectrum_distance: %.3f\n", d, mem.spec / mem.n);
    }
    /* a sparse drawn sketch (paper Figure 10): ordering, realism, random sketches, rotation */
    {
        tn_contour_set a, ar, units;
        tn_image g = {0, 0, 0, NULL}, gr = {0, 0, 0, NULL}, mem = {0, 0, 0, NULL};
        tn_metrics mt;
        int c, j, U = 256, x, y;
        if (!a_in_circle(U, 0, &a) || !a_in_circle(U, 1, &ar) || !a_in_circle(U, 0, &units)) return 1;
        for (c = 0; c < units.count; c++)
            for (j = 0; j < units.items[c].npoints; j++) units.items[c].points[3 * j + 2] = model.lo + (model.hi - model.lo) * units.items[c].points[3 * j + 2];
        memset(&go, 0, sizeof go);
        go.grow = grow;
        go.seed = 1;
        if (!tn_gnn_membrane(&mem, &units, U, U)) user_scores("membrane", &a, &crop, &mem);
        t0 = tn_time_seconds();
        go.finetune = finetune;
        if (!tn_gnn_generate(&g, &model, &a, U, U, &go)) {
            printf("user_generate_256_ms: %.0f ms\n", (tn_time_seconds() - t0) * 1e3);
            user_scores("gnn", &a, &crop, &g);
        }
        if (!tn_gnn_generate(&gr, &model, &ar, U, U, &go) && g.data) { /* rotate the output back: (x, y) of gr is (S-1-y, x) of g */
            tn_image back = {0, 0, 0, NULL};
            tn_image_create(&back, U, U, 1);
            for (y = 0; y < U; y++)
                for (x = 0; x < U; x++) TN_PIXEL(&back, x, y, 0) = TN_PIXEL(&gr, U - 1 - y, x, 0);
            if (!tn_compare(&mt, &g, &back, 0)) printf("user_rotation_90_ssim: %.4f (output of the rotated sketch vs the rotated output)\n", mt.ssim);
            tn_image_free(&back);
        }
        tn_image_free(&gr);
        go.finetune = 0;
        go.random_nodes = 48;
        if (!tn_gnn_generate(&gr, &model, &a, U, U, &go)) user_scores("gnn_random48", &a, &crop, &gr);
        if (pictures && g.data && gr.data && mem.data) {
            const tn_image *panel[4];
            char path[300];
            panel[0] = &crop;
            panel[1] = &mem;
            panel[2] = &g;
            panel[3] = &gr;
            snprintf(path, sizeof path, "gnn_fig10_%s.png", region);
            save_panels(path, panel, 4, U, model.lo, model.hi, dxy);
        }
        tn_image_free(&g);
        tn_image_free(&gr);
        go.random_nodes = 0;
        go.finetune = 30;
        go.order_weight = 1;
        if (!tn_gnn_generate(&g, &model, &a, U, U, &go)) user_scores("gnn_finetune30_order", &a, &crop, &g);
        tn_image_free(&g);
        memset(&go, 0, sizeof go);
        go.grow = grow;
        tn_image_free(&mem);
        tn_contour_set_free(&a);
        tn_contour_set_free(&ar);
        tn_contour_set_free(&units);
    }
    /* 512 x 512 from the sketch of the map's top-left 512 crop */
    if (full.width >= 512 && full.height >= 512) {
        tn_image big = {0, 0, 0, NULL};
        scores b = {0, 0, 0, 0}, bm = {0, 0, 0, 0};
        tn_image_crop(&big, &full, 0, 0, 512, 512);
        if (sketch_of(&big, 0, &sk, &cover)) {
            go.finetune = finetune;
            t0 = tn_time_seconds();
            if (!tn_gnn_generate(&out, &model, &sk, 512, 512, &go)) {
                printf("generate_512_s: %.2f s\n", tn_time_seconds() - t0);
                add(&b, &big, &out);
            } else
                fprintf(stderr, "  512: %s\n", tn_last_error());
            tn_image_free(&out);
            if (!tn_gnn_membrane(&out, &sk, 512, 512)) add(&bm, &big, &out);
            tn_image_free(&out);
            if (b.n && bm.n) printf("generate_512_ssim: %.4f (membrane %.4f)\n", b.ssim, bm.ssim);
            tn_contour_set_free(&sk);
        }
        tn_image_free(&big);
    }
    printf("peak_rss: %.0f MB\n", peak_rss_mb());
    tn_gnn_free(&model);
    tn_image_free(&crop);
    tn_image_free(&c128);
    tn_image_free(&full);
    return 0;
}
