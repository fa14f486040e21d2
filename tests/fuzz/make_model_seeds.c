/* make_model_seeds.c - writes fuzz_model's seeds: one tiny model of each method (gnn, singan,
   texgan, kpd), trained for an iteration or two on generated data, small enough for the fuzzer's
   -max_len. Run from the repository root:
     cc -std=c99 -O1 -I. tests/fuzz/make_model_seeds.c -o build/make_model_seeds -lm -pthread
     ./build/make_model_seeds tests/fuzz/corpus/fuzz_model */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <string.h>

/* Smooth hills with ridges and valleys to extract (metres). */
static tn_image hills(int n)
{
    tn_image d = {0, 0, 0, NULL};
    int x, y;
    if (tn_image_create(&d, n, n, 1)) return d;
    for (y = 0; y < n; y++)
        for (x = 0; x < n; x++) d.data[y * n + x] = (float)(400.0 * sin(x * 0.21) * cos(y * 0.17) + 150.0 * sin((x + y) * 0.43) + 3.0 * x);
    return d;
}

static int done(tn_status st, const char *what)
{
    if (st) fprintf(stderr, "%s: %s\n", what, tn_last_error());
    else printf("wrote %s\n", what);
    return st != TN_OK;
}

int main(int argc, char **argv)
{
    const char *dir = argc > 1 ? argv[1] : ".";
    char path[512];
    tn_image dem = hills(48), tex = {0, 0, 0, NULL};
    int bad = 0;
    size_t i;
    if (!dem.data) return 1;
    { /* gnn */
        tn_gnn_opts o;
        tn_gnn m;
        memset(&o, 0, sizeof o);
        o.hidden = 4;
        o.rounds = 1;
        o.k = 4;
        o.embed = 2;
        o.random_edges = -1;
        o.train.max_iters = 2;
        o.train.minutes = 5;
        snprintf(path, sizeof path, "%s/gnn.tnw", dir);
        if (!(bad |= done(tn_gnn_train(&m, &dem, &o, NULL), "gnn train"))) {
            bad |= done(tn_gnn_save(path, &m), path);
            tn_gnn_free(&m);
        }
    }
    { /* singan */
        tn_singan_opts o;
        tn_singan m;
        memset(&o, 0, sizeof o);
        o.coarsest = 16;
        o.channels = o.max_channels = 4;
        o.patch = 16;
        o.train.max_iters = 2;
        o.train.minutes = 5;
        snprintf(path, sizeof path, "%s/singan.tnw", dir);
        if (!(bad |= done(tn_singan_train(&m, &dem, &o, NULL), "singan train"))) {
            bad |= done(tn_singan_save(path, &m), path);
            tn_singan_free(&m);
        }
    }
    { /* texgan */
        tn_texgan_opts o;
        tn_texgan m;
        memset(&o, 0, sizeof o);
        o.stages = 2;
        o.gen_width = 16;
        o.disc_width = 4;
        o.disc_layers = 1;
        o.noise_local = 2;
        o.patch = 16;
        o.batch = 1;
        o.train.max_iters = 1;
        o.train.minutes = 5;
        if (tn_image_create(&tex, 32, 32, 3)) return 1;
        for (i = 0; i < (size_t)32 * 32 * 3; i++) tex.data[i] = dem.data[i % ((size_t)48 * 48)] * 0.001f;
        snprintf(path, sizeof path, "%s/texgan.tnw", dir);
        if (!(bad |= done(tn_texgan_train(&m, &tex, &o, NULL), "texgan train"))) {
            bad |= done(tn_texgan_save(path, &m), path);
            tn_texgan_free(&m);
        }
    }
    { /* kpd: procedural textures of the DEM as its targets */
        tn_kpd_opts o;
        tn_kpd m;
        tn_season_sample s[2];
        tn_climate c;
        tn_image ins = {0, 0, 0, NULL}, t[2] = {{0, 0, 0, NULL}, {0, 0, 0, NULL}};
        tn_insolation_opts io;
        float times[2] = {0.0f, 6.0f};
        memset(&io, 0, sizeof io);
        io.dx = 30.0f;
        io.directions = 8;
        memset(&o, 0, sizeof o);
        o.width = 4;
        o.crop = 32;
        o.batch = 1;
        o.train.max_iters = 1;
        o.train.minutes = 5;
        memset(s, 0, sizeof s);
        if (tn_climate_koppen(&c, "Dfb") || tn_insolation(&ins, &dem, 55.8, &io) || tn_season_texture(t, &dem, &c, 55.8, &ins, times, 2, NULL, NULL))
            return 1;
        for (i = 0; i < 2; i++) {
            s[i].dem = &dem;
            s[i].insolation = &ins;
            s[i].climate = &c;
            s[i].time = times[i];
            s[i].target = &t[i];
        }
        snprintf(path, sizeof path, "%s/kpd.tnw", dir);
        if (!(bad |= done(tn_kpd_train(&m, s, 2, &o, NULL), "kpd train"))) {
            bad |= done(tn_kpd_save(path, &m), path);
            tn_kpd_free(&m);
        }
        tn_image_free(&ins);
        tn_image_free(&t[0]);
        tn_image_free(&t[1]);
    }
    tn_image_free(&dem);
    tn_image_free(&tex);
    return bad;
}
