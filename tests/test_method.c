/* test_method.c - @@method: the registry of learned methods. Every method is found by name and
   enumerates; a tiny model of each, trained through its descriptor, saves, loads back through
   tn_method_load_any by its metadata, and generates a window equal to the same pixels of the
   whole map; unknown names, non-model files and missing inputs fail with a message. */
#include "terrainnet.h"
#include "tn_test.h"

static const char *const names[4] = {"texgan", "singan", "gnn", "kpd"};

TN_TEST(every_method_is_found_and_enumerates)
{
    int i, k, n = 0;
    for (i = 0; tn_method_at(i); i++) {
        const tn_method *m = tn_method_at(i);
        n++;
        TN_CHECK(tn_method_find(m->name) == m);
        TN_CHECK(m->summary && m->summary[0]);
        TN_CHECK(m->opts_size > 0 && m->defaults && m->train && m->save && m->load && m->free && m->channels && m->halo &&
                 m->generate_window);
        for (k = 0; k < i; k++) TN_CHECK(tn_method_at(k) != m);
    }
    TN_CHECK(n == 4);
    for (k = 0; k < 4; k++) TN_CHECK(tn_method_find(names[k]) && !strcmp(tn_method_find(names[k])->name, names[k]));
    TN_CHECK(tn_method_find("nope") == NULL);
    TN_CHECK(tn_method_find(NULL) == NULL);
    TN_CHECK(tn_method_at(-1) == NULL);
    TN_CHECK(tn_method_at(n) == NULL && tn_method_at(n + 5) == NULL);
}

/* win equals the pixels of whole at (x0, y0), every channel. */
static int window_matches(const tn_image *win, const tn_image *whole, int x0, int y0)
{
    int x, y, c;
    if (!win->data || !whole->data || win->channels != whole->channels) return 0;
    for (y = 0; y < win->height; y++)
        for (x = 0; x < win->width; x++)
            for (c = 0; c < win->channels; c++)
                if (TN_PIXEL(win, x, y, c) != TN_PIXEL(whole, x0 + x, y0 + y, c)) return 0;
    return 1;
}

/* What a window is generated from: seed and the method's generation options; the rest zero. */
static tn_method_input input_of(uint64_t seed, const void *opts)
{
    tn_method_input in;
    memset(&in, 0, sizeof in);
    in.seed = seed;
    in.opts = opts;
    return in;
}

/* Trains a model of method `name` on ex with opts, saves it, loads it back by its metadata, and
   checks that `win` of the loaded model equals those pixels of its W x H whole map and of the
   trained model's window. */
static void round_trip(const char *name, const tn_method_example *ex, const void *opts, const tn_method_input *in, int W, int H,
                       tn_rect win)
{
    const tn_method *m = tn_method_find(name), *back = NULL;
    const char *path = tn_test_tmp_path("method", "model.tnw");
    void *model = NULL, *loaded = NULL;
    tn_image whole = {0, 0, 0, NULL}, a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_rect all;
    TN_CHECK(m != NULL);
    if (!m) return;
    TN_CHECK(m->train(&model, ex, opts, NULL) == TN_OK);
    if (!model) return;
    TN_CHECK(m->save(path, model) == TN_OK);
    TN_CHECK(tn_method_load_any(&back, &loaded, path) == TN_OK);
    TN_CHECK(back == m && loaded != NULL);
    if (loaded) {
        all.x = all.y = 0;
        all.w = W;
        all.h = H;
        TN_CHECK(m->channels(loaded) == m->channels(model));
        TN_CHECK(m->generate_window(&whole, loaded, in, all) == TN_OK);
        TN_CHECK(m->generate_window(&a, loaded, in, win) == TN_OK);
        TN_CHECK(m->generate_window(&b, model, in, win) == TN_OK);
        TN_CHECK(whole.width == W && whole.height == H && whole.channels == m->channels(loaded));
        TN_CHECK(a.width == win.w && a.height == win.h);
        TN_CHECK(window_matches(&a, &whole, win.x, win.y));
        TN_CHECK(window_matches(&b, &a, 0, 0)); /* the file kept every weight */
    }
    tn_image_free(&whole);
    tn_image_free(&a);
    tn_image_free(&b);
    m->free(loaded);
    m->free(model);
    remove(path);
}

/* round_trip of a method that learns one example image. */
static void round_trip_image(const char *name, const tn_image *image, const void *opts, const tn_method_input *in, int W, int H,
                             tn_rect win)
{
    tn_method_example e;
    memset(&e, 0, sizeof e);
    e.image = image;
    round_trip(name, &e, opts, in, W, H, win);
}

/* round_trip_image on tn_test_dem(side, seed). */
static void round_trip_dem(const char *name, int side, uint64_t seed, const void *opts, const tn_method_input *in, int W, int H,
                           tn_rect win)
{
    tn_image dem = tn_test_dem(side, seed);
    round_trip_image(name, &dem, opts, in, W, H, win);
    tn_image_free(&dem);
}

TN_TEST(texgan_round_trip)
{
    const tn_method *m = tn_method_find("texgan");
    tn_image ex = tn_test_exemplar(48, 48, 3, 4);
    tn_method_input in = input_of(9, NULL);
    tn_texgan_opts o;
    tn_rect win = {5, 250, 20, 30}; /* across the 256-row bands a window is computed in */
    if (!m) TN_SKIP("texgan compiled out");
    TN_CHECK(m->opts_size == sizeof o);
    memset(&o, 0, sizeof o);
    m->defaults(&o);
    TN_CHECK(o.stages == 4 && o.patch == 64); /* tn_texgan_defaults: what zero means */
    tn_test_tiny_texgan_opts(&o);
    o.train.max_iters = 2;
    round_trip_image("texgan", &ex, &o, &in, 40, 300, win);
    tn_image_free(&ex);
}

TN_TEST(singan_round_trip)
{
    tn_singan_opts o;
    tn_singan_gen_opts go;
    tn_method_input in;
    tn_rect win = {13, 7, 20, 15};
    if (!tn_method_find("singan")) TN_SKIP("singan compiled out");
    tn_test_tiny_singan_opts(&o, 4);
    memset(&go, 0, sizeof go);
    go.seed = 1234; /* the input's seed wins */
    in = input_of(5, &go);
    round_trip_dem("singan", 24, 1, &o, &in, 40, 30, win);
}

TN_TEST(gnn_round_trip)
{
    tn_contour_set sk;
    tn_sketch_random_opts ro;
    tn_gnn_opts o;
    tn_gnn_generate_opts go;
    tn_method_input in;
    tn_rect win = {50, 30, 40, 30};
    if (!tn_method_find("gnn")) TN_SKIP("gnn compiled out");
    tn_test_tiny_gnn_opts(&o, 3);
    o.radius = 6;
    memset(&ro, 0, sizeof ro);
    ro.seed = 3;
    ro.nodes = 20;
    memset(&sk, 0, sizeof sk);
    TN_CHECK(tn_sketch_random(&sk, NULL, 96, 80, &ro) == TN_OK);
    memset(&go, 0, sizeof go);
    go.gain = 1.0f; /* the network as trained: no gain test per window */
    in = input_of(5, &go);
    in.width = 96;
    in.height = 80;
    in.sketch = &sk;
    round_trip_dem("gnn", 40, 12, &o, &in, 96, 80, win);
    tn_contour_set_free(&sk);
}

TN_TEST(kpd_round_trip)
{
    const tn_method *m = tn_method_find("kpd");
    tn_test_kpd_set k;
    tn_method_example e;
    tn_method_input in = input_of(0, NULL);
    tn_kpd_opts o;
    tn_rect win = {11, 17, 20, 15};
    if (!m) TN_SKIP("kpd compiled out");
    TN_CHECK(m->halo(NULL) == TN_KPD_HALO);
    TN_CHECK(tn_test_kpd_set_make(&k, 40));
    tn_test_small_kpd_opts(&o, 2);
    memset(&e, 0, sizeof e);
    e.samples = k.s;
    e.count = 4;
    in.dem = &k.dem;
    in.insolation = &k.ins;
    in.climate = &k.c;
    in.time = 4.5f; /* between two months */
    if (k.tex[3].data) round_trip("kpd", &e, &o, &in, 40, 40, win);
    tn_test_kpd_set_free(&k);
}

/* Fails with `code` and a message naming the file; nothing is handed out. */
static void load_fails(const char *path, tn_status code)
{
    const tn_method *m = tn_method_at(0);
    void *model = &model;
    tn_clear_error();
    TN_CHECK(tn_method_load_any(&m, &model, path) == code);
    TN_CHECK(m == NULL && model == NULL);
    TN_CHECK(strstr(tn_last_error(), path) != NULL);
}

TN_TEST(unknown_methods_and_non_models_fail_with_a_message)
{
    const char *text = tn_test_tmp_path("method", "not_a_model.txt"), *plain = tn_test_tmp_path("method", "weights.tnw"),
               *other = tn_test_tmp_path("method", "other.tnw");
    tn_params *p = tn_params_create();
    int shape[1] = {3};
    TN_CHECK(tn_test_write_text(text, "elevation,42\n"));
    load_fails(text, TN_ERR_FORMAT);
    load_fails(tn_test_tmp_path("method", "missing.tnw"), TN_ERR_IO);
    /* weights without a method: not a model */
    TN_CHECK(p && tn_params_add(p, "w", 1, shape) != NULL);
    TN_CHECK(tn_params_save(plain, p) == TN_OK);
    load_fails(plain, TN_ERR_FORMAT);
    TN_CHECK(strstr(tn_last_error(), "names no method") != NULL);
    /* a method this build does not have */
    TN_CHECK(tn_params_set_meta(p, "method", "hydrogan") == TN_OK);
    TN_CHECK(tn_params_save(other, p) == TN_OK);
    load_fails(other, TN_ERR_FORMAT);
    TN_CHECK(strstr(tn_last_error(), "hydrogan") != NULL);
    { /* its tensors damaged: the method is read from the metadata before the CRC-32 and the tensors */
        FILE *fp = fopen(other, "r+b");
        TN_CHECK(fp && fseek(fp, -6, SEEK_END) == 0 && fputc(0x5a, fp) != EOF);
        if (fp) fclose(fp);
        load_fails(other, TN_ERR_FORMAT);
        TN_CHECK(strstr(tn_last_error(), "hydrogan") != NULL);
    }
    tn_params_free(p);
    remove(text);
    remove(plain);
    remove(other);
}

TN_TEST(missing_inputs_fail_with_a_message)
{
    int i;
    tn_method_example e;
    memset(&e, 0, sizeof e);
    for (i = 0; tn_method_at(i); i++) { /* an empty example: every method says what it trains on */
        const tn_method *m = tn_method_at(i);
        void *model = &model;
        tn_clear_error();
        TN_CHECK(m->train(&model, &e, NULL, NULL) == TN_ERR_INVALID_ARG);
        TN_CHECK(model == NULL && strstr(tn_last_error(), m->name) != NULL);
    }
}

int main(void)
{
    TN_RUN(every_method_is_found_and_enumerates);
    TN_RUN(texgan_round_trip);
    TN_RUN(singan_round_trip);
    TN_RUN(gnn_round_trip);
    TN_RUN(kpd_round_trip);
    TN_RUN(unknown_methods_and_non_models_fail_with_a_message);
    TN_RUN(missing_inputs_fail_with_a_message);
    return tn_test_summary("test_method");
}
