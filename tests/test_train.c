/* test_train.c - @@train: runs with budgets, checkpoints and bit-identical resume (also after
   SIGKILL), cancel, .tnw metadata and model checks, and the shared building blocks (MLP, conv
   block, patch discriminator, EMA, best-k, GAN losses); texgan files written before @@train. */
#define _POSIX_C_SOURCE 200809L /* fork, kill, waitpid, nanosleep */
#include "terrainnet.h"
#include "tn_test.h"
#include <signal.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static void sleep_ms(long ms)
{
    struct timespec ts;
    ts.tv_sec = ms / 1000;
    ts.tv_nsec = (ms % 1000) * 1000000L;
    nanosleep(&ts, NULL);
}

/* ---- a toy method: an MLP fitting sin(3x) from batches drawn by its own RNG ---- */

typedef struct toy {
    tn_params *p;
    tn_optim *o;
    tn_rng rng;
    tn_train *run;
    tn_ctx *ctx;
} toy;

static const int toy_widths[4] = {1, 16, 16, 1};

static tn_status toy_begin(toy *t, const tn_train_opts *opts)
{
    tn_optim_opts oo;
    tn_status st;
    memset(t, 0, sizeof *t);
    if ((st = tn_train_create(&t->run, "toy", "toy-train", opts))) return st;
    tn_rng_seed(&t->rng, opts->seed, 1);
    t->p = tn_params_create();
    t->ctx = tn_ctx_create();
    if ((st = tn_mlp_add(t->p, "f.", toy_widths, 3, &t->rng))) return st;
    memset(&oo, 0, sizeof oo);
    oo.lr = 3e-3f;
    t->o = tn_optim_create(t->p, &oo);
    if ((st = tn_train_add_net(t->run, "f", t->p, t->o))) return st;
    if ((st = tn_train_add_rng(t->run, "data", &t->rng))) return st;
    if ((st = tn_train_set_meta(t->run, "width", "16"))) return st;
    return opts->resume ? tn_train_restore(t->run) : TN_OK;
}

static float toy_step(toy *t)
{
    tn_tensor *x, *y, *loss;
    int i;
    tn_ctx_reset(t->ctx);
    x = tn_tensor_2d(t->ctx, 32, 1);
    y = tn_tensor_2d(t->ctx, 32, 1);
    for (i = 0; i < 32; i++) {
        x->data[i] = 2.0f * tn_rng_uniform(&t->rng) - 1.0f;
        y->data[i] = sinf(3.0f * x->data[i]);
    }
    loss = tn_mse_loss(t->ctx, tn_mlp(t->ctx, t->p, "f.", 3, x, TN_ACT_TANH), y);
    tn_params_zero_grad(t->p);
    tn_backward(t->ctx, loss);
    tn_optim_step(t->o);
    return loss->data[0];
}

static tn_status toy_run(const tn_train_opts *opts, toy *t, float *last_loss)
{
    tn_status st = toy_begin(t, opts);
    float l = 0;
    if (st) return st;
    while (tn_train_next(t->run)) l = toy_step(t);
    if (last_loss) *last_loss = l;
    return tn_train_finish(t->run);
}

static void toy_free(toy *t)
{
    tn_train_free(t->run);
    tn_optim_free(t->o);
    tn_params_free(t->p);
    tn_ctx_free(t->ctx);
}

static int same_data(const tn_params *a, const tn_params *b)
{
    int i;
    if (tn_params_count(a) != tn_params_count(b)) return 0;
    for (i = 0; i < tn_params_count(a); i++) {
        const tn_tensor *x = tn_params_get(a, i), *y = tn_params_get(b, i);
        if (x->numel != y->numel || memcmp(x->data, y->data, x->numel * sizeof(float))) return 0;
    }
    return 1;
}

TN_TEST(budget_learns_and_stops)
{
    tn_train_opts o;
    toy t;
    float loss = 1;
    memset(&o, 0, sizeof o);
    o.max_iters = 400;
    o.seed = 3;
    TN_CHECK(toy_run(&o, &t, &loss) == TN_OK);
    TN_CHECK(tn_train_iteration(t.run) == 400);
    TN_CHECK(loss < 0.05f); /* sin(3x) starts near 0.5 MSE */
    TN_CHECK(tn_train_checkpoints(t.run) == 0);
    toy_free(&t);
    o.max_iters = 0;
    o.minutes = 0.2 / 60.0; /* 0.2 s */
    TN_CHECK(toy_run(&o, &t, NULL) == TN_OK);
    TN_CHECK(tn_train_seconds(t.run) >= 0.2 && tn_train_seconds(t.run) < 5.0 && tn_train_iteration(t.run) > 0);
    toy_free(&t);
}

/* Issue 33 item 8: a checkpoint that cannot be written (here: into a missing directory, as on a
   full disk) is a warning; training runs to its end and succeeds. */
TN_TEST(failed_checkpoint_is_a_warning)
{
    tn_train_opts o;
    toy t;
    const char *msg = NULL;
    memset(&o, 0, sizeof o);
    o.max_iters = 20;
    o.checkpoint_iters = 5;
    o.checkpoint = tn_test_tmp_path("train", "no_such_dir/x.ckpt");
    TN_CHECK(toy_run(&o, &t, NULL) == TN_OK);
    TN_CHECK(tn_train_iteration(t.run) == 20);
    TN_CHECK(tn_train_checkpoint_failures(t.run, &msg) >= 4 && msg && strstr(msg, "x.ckpt"));
    TN_CHECK(tn_train_checkpoints(t.run) == 0);
    toy_free(&t);
}

TN_TEST(resume_is_bit_identical)
{
    const char *ck = tn_test_tmp_path("train", "toy.ckpt");
    tn_train_opts o;
    toy full, part, res;
    memset(&o, 0, sizeof o);
    o.seed = 11;
    o.max_iters = 120;
    TN_CHECK(toy_run(&o, &full, NULL) == TN_OK);
    o.max_iters = 50;
    o.checkpoint = ck;
    TN_CHECK(toy_run(&o, &part, NULL) == TN_OK);
    TN_CHECK(tn_train_checkpoints(part.run) == 1); /* the final one */
    o.max_iters = 120;
    o.resume = 1;
    o.seed = 999; /* the checkpoint's seed and RNG state win */
    TN_CHECK(toy_run(&o, &res, NULL) == TN_OK);
    TN_CHECK(tn_train_start_iteration(res.run) == 50 && tn_train_iteration(res.run) == 120);
    TN_CHECK(tn_train_seed(res.run) == 11);
    TN_CHECK(strcmp(tn_train_meta(res.run, "width"), "16") == 0);
    TN_CHECK(same_data(full.p, res.p));
    TN_CHECK(!same_data(full.p, part.p));
    toy_free(&full);
    toy_free(&part);
    toy_free(&res);
    { /* another method's checkpoint is refused by name */
        tn_train *r = NULL;
        tn_params *ck2 = NULL;
        TN_CHECK(tn_train_create(&r, "other", "other-train", &o) == TN_OK);
        TN_CHECK(tn_train_open_checkpoint(r, &ck2) == TN_ERR_FORMAT && strstr(tn_last_error(), "toy") != NULL);
        tn_train_free(r);
    }
    remove(ck);
}

static int cancel_after(void *user, const char *stage, double f)
{
    int *n = (int *)user;
    (void)f;
    if (strcmp(stage, "toy-train") != 0) return 0;
    if (tn_progress_eta() < 0) return 1; /* training runs always know an ETA */
    return ++*n >= 30;
}

TN_TEST(cancel_keeps_a_checkpoint)
{
    const char *ck = tn_test_tmp_path("train", "cancel.ckpt");
    tn_train_opts o;
    toy t, r;
    int n = 0;
    memset(&o, 0, sizeof o);
    o.seed = 2;
    o.max_iters = 1000;
    o.checkpoint = ck;
    remove(ck);
    tn_set_progress(cancel_after, &n);
    TN_CHECK(toy_run(&o, &t, NULL) == TN_ERR_CANCELLED);
    tn_set_progress(NULL, NULL);
    TN_CHECK(strstr(tn_last_error(), "cancel") != NULL);
    TN_CHECK(tn_train_iteration(t.run) == 30);
    o.resume = 1;
    o.max_iters = 40;
    TN_CHECK(toy_run(&o, &r, NULL) == TN_OK);
    TN_CHECK(tn_train_start_iteration(r.run) == 30);
    toy_free(&t);
    toy_free(&r);
    remove(ck);
}

TN_TEST(bad_settings_are_refused)
{
    tn_train_opts o;
    tn_train *r = NULL;
    memset(&o, 0, sizeof o);
    o.minutes = NAN;
    TN_CHECK(tn_train_create(&r, "toy", "t", &o) == TN_ERR_INVALID_ARG && r == NULL);
    o.minutes = 0;
    o.max_iters = -5;
    TN_CHECK(tn_train_create(&r, "toy", "t", &o) == TN_ERR_INVALID_ARG);
    o.max_iters = 0;
    o.resume = 1;
    TN_CHECK(tn_train_create(&r, "toy", "t", &o) == TN_ERR_INVALID_ARG); /* resume without a path */
    o.resume = 0;
    TN_CHECK(tn_train_create(&r, "bad name!", "t", &o) == TN_ERR_INVALID_ARG);
    o.resume = 1;
    o.checkpoint = tn_test_tmp_path("train", "missing.ckpt");
    remove(o.checkpoint);
    {
        toy t;
        TN_CHECK(toy_begin(&t, &o) == TN_ERR_IO);
        toy_free(&t);
    }
}

/* A run killed with SIGKILL loses at most one checkpoint interval, and its resume continues as
   if nothing had happened. */
TN_TEST(sigkill_then_resume)
{
    const char *ck = tn_test_tmp_path("train", "kill.ckpt");
    tn_train_opts o;
    toy full, res;
    pid_t pid;
    int status = 0, waited = 0;
    long at;
    memset(&o, 0, sizeof o);
    o.seed = 21;
    o.max_iters = 3000000; /* far more than the child lives */
    o.checkpoint = ck;
    o.checkpoint_iters = 100;
    o.checkpoint_seconds = 1e6;
    remove(ck);
    fflush(NULL);
    pid = fork();
    if (pid == 0) {
        toy t;
        toy_run(&o, &t, NULL);
        _exit(0);
    }
    TN_CHECK(pid > 0);
    if (pid <= 0) return;
    for (waited = 0; waited < 400; waited++) { /* until a checkpoint exists, then a little more */
        FILE *f = fopen(ck, "rb");
        if (f) {
            fclose(f);
            break;
        }
        sleep_ms(25);
    }
    sleep_ms(50);
    kill(pid, SIGKILL);
    waitpid(pid, &status, 0);
    TN_CHECK(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
    o.resume = 1;
    o.max_iters = 1; /* read the position only: no more iterations than it holds */
    {
        tn_params *p = NULL;
        double v = 0;
        TN_CHECK(tn_params_open(&p, ck) == TN_OK); /* the file is whole: writes are atomic */
        if (!p) return;
        v = atof(tn_params_meta(p, "iteration"));
        tn_params_free(p);
        at = (long)v;
    }
    TN_CHECK(at >= 100 && at % 100 == 0);
    o.max_iters = at + 150;
    TN_CHECK(toy_run(&o, &res, NULL) == TN_OK);
    TN_CHECK(tn_train_start_iteration(res.run) == at);
    o.resume = 0;
    o.checkpoint = NULL;
    TN_CHECK(toy_run(&o, &full, NULL) == TN_OK);
    TN_CHECK(same_data(full.p, res.p));
    toy_free(&full);
    toy_free(&res);
    remove(ck);
}

/* ---- .tnw metadata and model checks ---- */

TN_TEST(metadata_round_trip_and_checks)
{
    const char *path = tn_test_tmp_path("train", "meta.tnw");
    tn_params *p = tn_params_create(), *q = NULL;
    tn_model_provenance pv;
    tn_image img = {0, 0, 0, NULL};
    int n = 3;
    const char *v = NULL;
    TN_CHECK(tn_params_add(p, "w", 1, &n) != NULL);
    TN_CHECK(tn_params_set_meta(p, "a.b", "x y z") == TN_OK);
    TN_CHECK(tn_params_set_meta(p, "bad key", "1") == TN_ERR_INVALID_ARG);
    TN_CHECK(tn_params_set_meta(p, "k", "line\nbreak") == TN_ERR_INVALID_ARG);
    TN_CHECK(tn_params_set_meta(p, "a.b", "replaced") == TN_OK && tn_params_meta_count(p) == 1);
    TN_CHECK(tn_image_create(&img, 4, 3, 1) == TN_OK);
    memset(&pv, 0, sizeof pv);
    pv.seed = 77;
    pv.iterations = 123;
    pv.seconds = 4.5;
    pv.example_digest = tn_image_digest(&img);
    pv.example_width = 4;
    pv.example_height = 3;
    pv.example_channels = 1;
    TN_CHECK(pv.example_digest != 0);
    img.data[5] = 1.0f;
    TN_CHECK(tn_image_digest(&img) != pv.example_digest);
    TN_CHECK(tn_model_stamp(p, "toy", 2, &pv) == TN_OK);
    TN_CHECK(tn_params_save(path, p) == TN_OK);
    TN_CHECK(tn_params_open(&q, path) == TN_OK);
    if (!q) return;
    TN_CHECK(strcmp(tn_params_meta(q, "a.b"), "replaced") == 0);
    TN_CHECK(strcmp(tn_params_meta(q, "method"), "toy") == 0);
    TN_CHECK(strcmp(tn_params_meta(q, "iterations"), "123") == 0);
    TN_CHECK(strcmp(tn_params_meta(q, "train_seconds"), "4.5") == 0);
    TN_CHECK(strncmp(tn_params_meta(q, "example"), "4x3x1:", 6) == 0);
    TN_CHECK(strcmp(tn_params_meta_key(q, 0, &v), "a.b") == 0 && strcmp(v, "replaced") == 0);
    TN_CHECK(tn_model_check(q, "toy", 2, NULL, path) == TN_OK);
    TN_CHECK(tn_model_check(q, "toy", 1, NULL, path) == TN_ERR_FORMAT && strstr(tn_last_error(), "newer") != NULL);
    TN_CHECK(tn_model_check(q, "texgan", 1, "texgan.config", path) == TN_ERR_FORMAT && strstr(tn_last_error(), "a toy model") != NULL);
    TN_CHECK(tn_params_set_meta(q, "kind", "checkpoint") == TN_OK);
    TN_CHECK(tn_model_check(q, "toy", 2, NULL, path) == TN_ERR_FORMAT && strstr(tn_last_error(), "checkpoint") != NULL);
    TN_CHECK(tn_params_set_meta(q, "kind", NULL) == TN_OK && tn_params_meta(q, "kind") == NULL);
    TN_CHECK(tn_params_set_meta(q, "method", NULL) == TN_OK);
    TN_CHECK(tn_model_check(q, "toy", 2, NULL, path) == TN_ERR_FORMAT);
    TN_CHECK(tn_model_check(q, "toy", 2, "w", path) == TN_OK); /* a legacy file, recognised by a tensor */
    tn_params_free(q);
    q = tn_params_create();
    TN_CHECK(tn_params_add(q, "w", 1, &n) != NULL);
    TN_CHECK(tn_params_load(q, path) == TN_OK && strcmp(tn_params_meta(q, "a.b"), "replaced") == 0);
    tn_params_free(q);
    { /* a newer container version is refused with a message saying so */
        FILE *f = fopen(path, "r+b");
        unsigned char three = 3;
        TN_CHECK(f != NULL);
        if (f) {
            fseek(f, 4, SEEK_SET);
            fwrite(&three, 1, 1, f);
            fclose(f);
        }
        q = NULL;
        TN_CHECK(tn_params_open(&q, path) == TN_ERR_FORMAT && q == NULL && strstr(tn_last_error(), "newer") != NULL);
    }
    tn_params_free(p);
    tn_image_free(&img);
    remove(path);
}

/* A texgan model given where a texgan model is expected loads; another method's is refused. */
TN_TEST(texgan_refuses_other_methods)
{
    const char *path = tn_test_tmp_path("train", "other.tnw");
    tn_params *p = tn_params_create();
    tn_texgan m;
    int n = 40;
    memset(&m, 0, sizeof m);
    TN_CHECK(tn_params_add_buffer(p, "texgan.config", 1, &n) != NULL);
    TN_CHECK(tn_model_stamp(p, "singan", 1, NULL) == TN_OK);
    TN_CHECK(tn_params_save(path, p) == TN_OK);
    TN_CHECK(tn_texgan_load(&m, path) == TN_ERR_FORMAT && m.weights == NULL);
    TN_CHECK(strstr(tn_last_error(), "singan") != NULL);
    TN_CHECK(tn_model_stamp(p, "texgan", 99, NULL) == TN_OK && tn_params_save(path, p) == TN_OK);
    TN_CHECK(tn_texgan_load(&m, path) == TN_ERR_FORMAT && strstr(tn_last_error(), "newer") != NULL);
    tn_params_free(p);
    remove(path);
}

/* Loads path with the loader of methods[i]; a model that loads is freed. */
static tn_status load_with(int i, const char *path)
{
    tn_gnn g;
    tn_singan s;
    tn_texgan t;
    tn_kpd k;
    tn_status st;
    switch (i) {
    case 0: if (!(st = tn_gnn_load(&g, path))) tn_gnn_free(&g); break;
    case 1: if (!(st = tn_singan_load(&s, path))) tn_singan_free(&s); break;
    case 2: if (!(st = tn_texgan_load(&t, path))) tn_texgan_free(&t); break;
    default: if (!(st = tn_kpd_load(&k, path))) tn_kpd_free(&k); break;
    }
    return st;
}

/* A loader refuses another method's file from its metadata, before the CRC-32 and the tensors:
   a damaged file of another method is refused for its method, while a damaged file of the
   loader's own method fails on the CRC. */
TN_TEST(loaders_check_the_method_before_the_crc)
{
    static const char *const methods[4] = {"gnn", "singan", "texgan", "kpd"};
    const char *path = tn_test_tmp_path("train", "damaged.tnw");
    int i, j, n = 40;
    for (i = 0; i < 4; i++) {
        tn_params *p = tn_params_create();
        FILE *f;
        TN_CHECK(p && tn_params_add(p, "w", 1, &n) != NULL);
        TN_CHECK(tn_model_stamp(p, methods[i], 1, NULL) == TN_OK && tn_params_save(path, p) == TN_OK);
        tn_params_free(p);
        f = fopen(path, "r+b"); /* the last value (before the CRC) becomes a tiny nonzero float */
        TN_CHECK(f && fseek(f, -6, SEEK_END) == 0 && fputc(1, f) == 1 && fclose(f) == 0);
        for (j = 0; j < 4; j++) {
            char want[64];
            tn_clear_error();
            if (j == i) {
                TN_CHECK(load_with(j, path) == TN_ERR_CORRUPT && strstr(tn_last_error(), "CRC-32 mismatch") != NULL);
                continue;
            }
            snprintf(want, sizeof want, "a %s model, not a %s model", methods[i], methods[j]);
            TN_CHECK(load_with(j, path) == TN_ERR_FORMAT && strstr(tn_last_error(), want) != NULL);
        }
    }
    remove(path);
}

/* ---- texgan files written before @@train (tests/refs, made by the code at 35647d3) ---- */

static void refs_opts(tn_texgan_opts *o)
{
    memset(o, 0, sizeof *o);
    o->noise_local = 4;
    o->stages = 2;
    o->gen_width = 16;
    o->disc_width = 8;
    o->disc_layers = 1;
    o->patch = 16;
    o->batch = 2;
    o->lr = 1e-3f;
    o->train.minutes = 100;
    o->train.seed = 5;
}

/* Largest difference over the generator tensors (the config holds timings). */
static double gen_diff(const tn_texgan *a, const tn_texgan *b)
{
    double d = 0;
    int i;
    size_t k;
    if (tn_params_count(a->weights) != tn_params_count(b->weights)) return 1e30;
    for (i = 1; i < tn_params_count(a->weights); i++) {
        const tn_tensor *x = tn_params_get(a->weights, i), *y = tn_params_get(b->weights, i);
        if (x->numel != y->numel) return 1e30;
        for (k = 0; k < x->numel; k++)
            if (fabs((double)x->data[k] - y->data[k]) > d) d = fabs((double)x->data[k] - y->data[k]);
    }
    return d;
}

TN_TEST(texgan_v1_files_load_and_reproduce)
{
    const char *ck = tn_test_tmp_path("train", "v1.ckpt");
    tn_image ex = tn_test_exemplar(40, 36, 3, 1);
    tn_texgan old, fresh, resumed;
    tn_texgan_opts o;
    FILE *in, *out;
    char buf[4096];
    size_t n;
    TN_CHECK(tn_texgan_load(&old, tn_test_ref("texgan_v1_model.tnw")) == TN_OK);
    if (!old.weights) return;
    TN_CHECK(old.iterations == 6 && old.stages == 2 && old.channels == 3);
    refs_opts(&o);
    o.train.max_iters = 6;
    TN_CHECK(tn_texgan_train(&fresh, &ex, &o, NULL) == TN_OK);
    /* the same seed trains the same weights as the code before @@train (bit-identical on the
       machine that made the file; the tolerance allows another CPU's kernels) */
    TN_CHECK(gen_diff(&old, &fresh) <= 1e-5);
    TN_CHECK(strcmp(tn_params_meta(fresh.weights, "method"), "texgan") == 0);
    /* the old checkpoint (3 iterations) resumes to the same model; copied first: a resume
       writes its checkpoint back */
    in = fopen(tn_test_ref("texgan_v1_checkpoint.tnw"), "rb");
    out = fopen(ck, "wb");
    TN_CHECK(in && out);
    while (in && out && (n = fread(buf, 1, sizeof buf, in)) > 0) fwrite(buf, 1, n, out);
    if (in) fclose(in);
    if (out) fclose(out);
    o.train.checkpoint = ck;
    o.train.resume = 1;
    TN_CHECK(tn_texgan_train(&resumed, &ex, &o, NULL) == TN_OK);
    TN_CHECK(resumed.iterations == 6);
    TN_CHECK(gen_diff(&old, &resumed) <= 1e-5);
    tn_texgan_free(&old);
    tn_texgan_free(&fresh);
    tn_texgan_free(&resumed);
    tn_image_free(&ex);
    remove(ck);
}

/* ---- building blocks ---- */

TN_TEST(blocks_shapes_and_gradients)
{
    tn_params *p = tn_params_create();
    tn_ctx *ctx = tn_ctx_create();
    tn_rng rng;
    tn_patch_disc d;
    tn_tensor *x, *y, *s;
    int w3[3] = {5, 7, 2};
    tn_rng_seed(&rng, 4, 0);
    TN_CHECK(tn_mlp_add(p, "m.", w3, 2, &rng) == TN_OK);
    TN_CHECK(tn_mlp_add(p, "m.", w3, 2, &rng) != TN_OK); /* names taken */
    TN_CHECK(tn_conv_block_add(p, "c.", 3, 8, 3, 1, &rng) == TN_OK);
    TN_CHECK(tn_conv_block_add(p, "e.", 3, 8, 4, 1, &rng) == TN_ERR_INVALID_ARG); /* even kernel */
    TN_CHECK(tn_patch_disc_add(p, "d.", 8, 4, 2, 3, &rng, &d) == TN_OK);
    TN_CHECK(tn_patch_disc_add(p, "z.", 8, 4, 99, 3, &rng, &d) == TN_ERR_INVALID_ARG);
    TN_CHECK(tn_patch_disc_add(p, "d.", 8, 4, 2, 3, &rng, &d) != TN_OK); /* names taken */
    TN_CHECK(tn_patch_disc_add(p, "q.", 8, 4, 2, 3, &rng, &d) == TN_OK);
    x = tn_tensor_2d(ctx, 4, 5);
    tn_init_normal(x, &rng, 0, 1);
    y = tn_mlp(ctx, p, "m.", 2, x, TN_ACT_RELU);
    TN_CHECK(y && y->shape[0] == 4 && y->shape[1] == 2);
    x = tn_tensor_4d(ctx, 2, 3, 16, 16);
    tn_init_normal(x, &rng, 0, 1);
    y = tn_conv_block(ctx, p, "c.", x, TN_ACT_LEAKY);
    TN_CHECK(y && y->shape[1] == 8 && y->shape[2] == 16 && y->shape[3] == 16);
    tn_patch_disc_begin(ctx, &d);
    s = tn_patch_disc_score(ctx, &d, y);
    TN_CHECK(s && s->shape[1] == 1 && s->shape[2] == 4 && s->shape[3] == 4); /* two stride-2 layers */
    tn_params_zero_grad(p);
    TN_CHECK(tn_backward(ctx, tn_nonsat_g_loss(ctx, s)) == TN_OK);
    TN_CHECK(tn_params_find(p, "c.w")->grad[0] != 0.0f && tn_params_find(p, "q.w0")->grad[0] != 0.0f);
    { /* GAN losses at known points: softplus(0) = log 2; hinge at 0 = 1 + 1 */
        tn_tensor *z = tn_tensor_2d(ctx, 2, 2);
        TN_CHECK_NEAR(tn_nonsat_d_loss(ctx, z, z)->data[0], 2.0 * log(2.0), 1e-6);
        TN_CHECK_NEAR(tn_nonsat_g_loss(ctx, z)->data[0], log(2.0), 1e-6);
        TN_CHECK_NEAR(tn_hinge_d_loss(ctx, z, z)->data[0], 2.0, 1e-6);
    }
    tn_ctx_free(ctx);
    tn_params_free(p);
}

TN_TEST(ema_and_best_k)
{
    tn_params *src = tn_params_create(), *avg = tn_params_create();
    tn_best_k *b = tn_best_k_create(2);
    const tn_params *best;
    double sc = 0;
    long it = 0;
    int n = 2;
    tn_tensor *s = tn_params_add(src, "w", 1, &n), *a = tn_params_add_buffer(avg, "w", 1, &n);
    s->data[0] = 1.0f;
    a->data[0] = 0.0f;
    tn_ema_update(avg, src, 0.9f, 0); /* warm-up: decay 1/10 at step 0 */
    TN_CHECK_NEAR(a->data[0], 0.9, 1e-6);
    tn_ema_update(avg, src, 0.5f, 1000); /* capped at 0.5 */
    TN_CHECK_NEAR(a->data[0], 0.95, 1e-6);
    TN_CHECK(tn_best_k_create(0) == NULL);
    s->data[0] = 3.0f;
    TN_CHECK(tn_best_k_offer(b, src, 3.0, 1) == 1);
    s->data[0] = 1.0f;
    TN_CHECK(tn_best_k_offer(b, src, 1.0, 2) == 1);
    s->data[0] = 5.0f;
    TN_CHECK(tn_best_k_offer(b, src, 5.0, 3) == 0); /* worse than both */
    TN_CHECK(tn_best_k_offer(b, src, NAN, 4) == 0);
    s->data[0] = 2.0f;
    TN_CHECK(tn_best_k_offer(b, src, 2.0, 5) == 1);
    TN_CHECK(tn_best_k_count(b) == 2);
    best = tn_best_k_get(b, 0, &sc, &it);
    TN_CHECK(best && sc == 1.0 && it == 2 && tn_params_find(best, "w")->data[0] == 1.0f);
    best = tn_best_k_get(b, 1, &sc, &it);
    TN_CHECK(best && sc == 2.0 && it == 5 && tn_params_find(best, "w")->data[0] == 2.0f);
    TN_CHECK(tn_best_k_get(b, 2, NULL, NULL) == NULL);
    tn_best_k_free(b);
    tn_params_free(src);
    tn_params_free(avg);
}

int main(void)
{
    TN_RUN(budget_learns_and_stops);
    TN_RUN(failed_checkpoint_is_a_warning);
    TN_RUN(resume_is_bit_identical);
    TN_RUN(cancel_keeps_a_checkpoint);
    TN_RUN(bad_settings_are_refused);
    TN_RUN(sigkill_then_resume);
    TN_RUN(metadata_round_trip_and_checks);
    TN_RUN(texgan_refuses_other_methods);
    TN_RUN(loaders_check_the_method_before_the_crc);
    TN_RUN(texgan_v1_files_load_and_reproduce);
    TN_RUN(blocks_shapes_and_gradients);
    TN_RUN(ema_and_best_k);
    return tn_test_summary("test_train");
}
