/* train_tiny_cnn: the tensor engine in one page. A two-layer CNN learns to turn a heightmap into
   its slope map (a fixed 3x3 operator) from random Perlin patches, then saves its weights.
   bin/train_tiny_cnn [steps]   -> tiny_cnn.tnw */
#define TERRAINNET_IMPLEMENTATION
#include "terrainnet.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

int main(int argc, char **argv)
{
    int steps = argc > 1 ? atoi(argv[1]) : 300, step;
    int w1s[4] = {16, 1, 3, 3}, w2s[4] = {1, 16, 3, 3}, n16 = 16, n1 = 1;
    tn_params *p = tn_params_create();
    tn_tensor *w1 = tn_params_add(p, "conv1.weight", 4, w1s), *b1 = tn_params_add(p, "conv1.bias", 1, &n16);
    tn_tensor *w2 = tn_params_add(p, "conv2.weight", 4, w2s), *b2 = tn_params_add(p, "conv2.bias", 1, &n1);
    tn_ctx *ctx = tn_ctx_create();
    tn_optim_opts oo;
    tn_optim *opt;
    tn_conv_opts co;
    tn_rng rng;
    tn_status st = TN_OK;
    float loss_first = 0, loss_last = 0;
    if (steps < 1 || steps > 100000) steps = 300;
    tn_rng_seed(&rng, 1, 1);
    tn_init_kaiming(w1, &rng, 1.4f);
    tn_init_kaiming(w2, &rng, 1.0f);
    memset(&oo, 0, sizeof oo); /* zero = defaults: Adam, betas 0.9/0.999 */
    oo.lr = 3e-3f;
    opt = tn_optim_create(p, &oo);
    memset(&co, 0, sizeof co);
    co.pad = 1;
    co.padding = TN_PADDING_REFLECT;
    for (step = 0; step < steps && !st; step++) {
        tn_image dem = {0, 0, 0, NULL}, slope = {0, 0, 0, NULL};
        tn_perlin_opts po;
        tn_tensor *x, *t, *y, *loss;
        memset(&po, 0, sizeof po);
        po.seed = (uint64_t)step;
        po.octaves = 5;
        st = tn_noise_perlin(&dem, 64, 64, &po);
        if (!st) st = tn_image_slope(&slope, &dem, 1.0f / 64, 1.0f / 64);
        if (!st) {
            tn_ctx_reset(ctx); /* last step's temporaries */
            x = tn_tensor_from_image(ctx, &dem);
            t = tn_scale_shift(ctx, tn_tensor_from_image(ctx, &slope), 1.0f / 90.0f, 0.0f);
            y = tn_conv2d(ctx, tn_leaky_relu(ctx, tn_conv2d(ctx, x, w1, b1, &co), 0.2f), w2, b2, &co);
            loss = tn_mse_loss(ctx, y, t);
            tn_params_zero_grad(p);
            st = tn_backward(ctx, loss);
            if (!st) {
                tn_optim_step(opt);
                if (step == 0) loss_first = loss->data[0];
                loss_last = loss->data[0];
                if (step % 50 == 0) printf("step %4d  loss %.5f\n", step, loss->data[0]);
            }
        }
        tn_image_free(&dem);
        tn_image_free(&slope);
    }
    if (!st) st = tn_params_save("tiny_cnn.tnw", p);
    if (st) fprintf(stderr, "train_tiny_cnn: %s: %s\n", tn_status_string(st), tn_last_error());
    else printf("loss %.5f -> %.5f; weights in tiny_cnn.tnw (%zu values)\n", loss_first, loss_last, tn_params_numel(p));
    tn_optim_free(opt);
    tn_params_free(p);
    tn_ctx_free(ctx);
    return st ? 1 : 0;
}
