/* ============================================================================================
   @@gnn  sketch-to-terrain graph network (paper 000, sections 4.2-5.4)
   Learns ONE example DEM so that a sketch of ridges and valleys becomes terrain in its style.
   The example's own network (@@extract) is cut into contour parts of 5-10 px (@@sketch); a
   bipartite graph joins every pixel to its k nearest parts (4.2) plus random pixel-part edges
   redrawn every step, with 5 % of the parts masked per step (A.2). An edge carries the
   projection index of the pixel along the part (for a part without an embedding, how far the
   pixel lies beyond the part's end instead: there the index only says where a random cut
   fell), the distance to that projection (and a closeness exp(-d/2)), the part's height there
   minus the pixel's baseline and, in training, optional Gaussian noise (A.4); a part node
   carries its ridge/valley sign and a learned embedding (one per example part). Pixels start
   from an MLP of (+1 ridge, -1 valley, 0 other; baseline height), parts from N(0, s^2) or zero
   (A.3). T rounds of gather (pixels -> parts) and scatter (parts -> pixels) update both sides
   residually; each is a graph attention over two-layer MLP encodings of [receiver, sender,
   edge, mean of the sender's neighbours] (A.5); a readout MLP gives the height. Losses: MSE +
   SSIM + gradient difference + smoothness on the normalised heights (6.1's l_gt, l_ssim,
   l_gradient, l_smooth; 6.1's sketch and distance terms are options; weights in
   tn_gnn_defaults).
   Baseline: the network predicts a RESIDUAL over the membrane (Laplace) interpolation of the
   sketch pixels' heights, the strong baseline the neighbour test rewards (docs/gnn.md), so the
   model starts at it and learns what the example adds;
   `membrane = -1` trains the paper's direct form instead.
   Generalising from one example: embeddings let the network memorise the example (the
   reconstruction), but a part of another terrain given an aligned part's embedding (5.3) gets
   that part's memorised residual, which measured worse than none. So training drops half the
   embeddings per step and spends half the steps on the example's own sparser networks (higher
   extraction thresholds, no embeddings, a random share of their parts dropped and the membrane
   rebuilt each step): the network also learns a geometry-only mode that fills what a dense or
   sparse sketch leaves out. That mode wanders from step to step as training goes on, so
   holdout windows of the user's DEM score it every 150 steps and the best check's weights are
   kept as the early network, which every sketch but the example's own network runs on.
   Generation gives a sketch part the embedding
   of an identical example part (its own network: reconstruction) and none otherwise by default;
   the paper's alignment is TN_GNN_EMBED_ALIGNED. An optional fine-tune (5.4) then adjusts only
   the sketch parts' embeddings (loss on the sketch pixels + smoothness, optionally a
   ridge-above / valley-below hinge). The residual is scaled by a gain tested on the sketch
   itself (tn_gnn_gain: some of its lines held out and predicted from the rest), so a sketch
   unlike the example gets less of the example's detail. Output in the example's height units.
   Seamless tiles: a pixel's neighbour parts lie within `radius` px and the membrane is solved on
   overlapping blocks, so a pixel depends only on the sketch within a fixed distance; any window
   computed alone (tn_gnn_generate_window) equals the whole map's pixels, and large maps run in
   tiles with memory of one tile. A drawing of a few strokes is densified by example first
   (tn_gnn_grow: blocks of the example's own network quilted between the strokes, never
   crossing them), or on request by random sketches (5.2).
   ============================================================================================ */
#ifndef TN_NO_GNN
#if defined(TN_NO_ENGINE) || defined(TN_NO_SKETCH) || defined(TN_NO_EXTRACT) || defined(TN_NO_FINEDETAIL)
#error "terrainnet: @@gnn needs the tensor engine, @@sketch, @@extract, @@finedetail; define TN_NO_GNN too, or none of them"
#endif

/* Zero = default (tn_gnn_defaults gives the values and the reasons). */
typedef struct tn_gnn_opts {
    int hidden;            /* node state and MLP hidden width; 0 = 32 (A.5) */
    int rounds;            /* T gather/scatter rounds; 0 = 2 */
    int k;                 /* fixed edges per pixel (its k nearest parts); 0 = 10 (4.2) */
    float radius;          /* only parts closer than this many pixels are a pixel's neighbours, so a
                              pixel depends on the sketch within a fixed distance (seamless tiles);
                              0 = 24 */
    int embed;             /* part embedding dims; 0 = 16 */
    int random_edges;      /* random pixel-part edges per step; 0 = 10000 (4.2), < 0 = none */
    float mask;            /* share of parts masked per step; 0 = 0.05 (A.2), < 0 = none */
    float edge_noise;      /* std of the Gaussian edge feature in training (A.4 uses 1); 0 = none */
    float part_noise;      /* std of the parts' random initial states (A.3 uses 1); 0 = zero states */
    float embed_drop;      /* share of the example's parts trained without their embedding per
                              step (what a part of another sketch gets); 0 = 0.5, < 0 = none */
    int sparse_levels;     /* also train on the example's networks at 4, 12 and 36 times the
                              extraction threshold (sparse sketches, no embeddings), half the
                              steps; 0 = 3, < 0 = none */
    float thin;            /* on a sparse level, drop up to this share of its parts per step
                              (a random share, membrane and edges rebuilt): many sparse sketches
                              from one example; 0 = 0.5, < 0 = none */
    float embed_phase;     /* the last share of this run's budget trains only the example's part
                              embeddings (rate x 5), on its own network with every part present: the
                              reconstruction sharpens while the network, and with it every sketch
                              of other terrain, stays as trained (with an early network, see
                              phase_network, everything trains). A schedule like the budget, so a
                              resumed run takes this run's value; 0 = 0.5 with an early network,
                              else 0.25; < 0 = none */
    int part_index;        /* edge feature of a part without an embedding (a dropped one, a sparse
                              level's, any part of another sketch): 0 = how far the pixel lies
                              beyond the part's end along it (0 beside it); -1 = the projection
                              index along the part, as for parts with an embedding (A.4), which
                              there only says where a random cut fell (docs/gnn.md) */
    int membrane;          /* 0 = predict a residual over the membrane of the sketch heights;
                              -1 = predict the height itself (the paper's form) */
    float lr;              /* Adam rate; 0 = 2e-3 */
    float mse_weight;      /* l_gt (MSE of the normalised heights); 0 = 1, < 0 = off */
    float ssim_weight;     /* 1 - SSIM; 0 = 0.1, < 0 = off */
    float grad_weight;     /* gradient-difference loss; 0 = 0.1, < 0 = off */
    float sketch_weight;   /* 6.1's sketch loss: pixels 1-4 px from a part lie below a ridge's and above a
                              valley's height at their projection (cross-entropy of a Gumbel-softmax
                              of the two heights, temperature 0.05 std); 0 = off (docs/gnn.md: it cost
                              neighbour SSIM) */
    float smooth_weight;   /* 6.1's smoothness: |y_p - y_q| of random pixel pairs under 5 px apart
                              (Manhattan); 0 = 0.1, < 0 = off */
    float further_weight;  /* 6.1's distance term, as read here: a pixel 1-6 px from its nearest part
                              keeps near the part's height there, weighted 1 / (10 d^2); 0 = off */
    const tn_image *holdout; /* holdout_count terrains of the example's style and units (one
                              channel, at least 16 x 16) that training never sees, e.g. windows of
                              the same DEM away from the example (tn_gnn_holdout_windows); NULL =
                              none. Every holdout_every iterations before the embedding phase, and
                              as it starts, the network without embeddings rebuilds each one from
                              its extracted network (the extraction threshold and 4 x it); the
                              weights of the best mean SSIM become the model's early network,
                              which every sketch but the example's own network runs on: early
                              stopping, as the network's fill of other terrain swings from check
                              to check and falls as it trains on (docs/gnn.md). At the end they
                              also calibrate the scale of the gain test (tn_gnn_gain) */
    int holdout_count;
    int holdout_every;     /* iterations between holdout checks; 0 = 150 */
    int phase_network;     /* with holdouts (an early network): the embedding phase trains the
                              network too, everything at 4 x the rate and 10 x the SSIM weight
                              on the whole graph (no masked parts, no random edges), since the
                              trained network then serves only the example's own network;
                              0 = on, -1 = off
                              (without holdouts the phase always leaves the network as it is) */
    tn_extract_opts extract; /* how the example's ridges and valleys are found (zero = defaults) */
    int dequantize;        /* train on the example (and the holdouts) without its height steps
                              (tn_image_dequantize): 0 = when they are coarse (tn_image_height_step's
                              coarse_only: 8-bit heightmaps), 1 = whenever it is stored in steps,
                              -1 = never */
    tn_train_opts train;   /* budget (minutes 0 = 10), checkpoints, resume (the checkpoint's
                              architecture wins; the example must be the same), seed */
} tn_gnn_opts;

/* A trained model: the network, the example's contour parts (with heights, so generation needs
   nothing else) and the example's height normalisation. Free with tn_gnn_free. */
typedef struct tn_gnn {
    int hidden, rounds, k, embed;
    float radius;            /* neighbour radius in pixels */
    int membrane;            /* 1: output = membrane of the sketch heights + learned residual */
    int parts;               /* example parts (one embedding each) */
    int width, height;       /* example size */
    float mean, std;         /* example heights = mean + std * network units */
    float lo, hi;            /* example height range */
    float part_noise;        /* std of the parts' initial states */
    long iterations;         /* training iterations done */
    double train_seconds;
    tn_params *weights;      /* "gnn.config", "gnn.part_pts", "gnn.part_info", "gnn.emb", "gnn.*";
                                "early.gnn.*": the early network (holdouts in training), which
                                every sketch but the example's own network runs on */
} tn_gnn;

typedef struct tn_gnn_stats {
    long iterations;          /* total, including resumed ones */
    long resumed_from;        /* iteration the run resumed at (0 = fresh) */
    double seconds;           /* total training seconds, including resumed time */
    double seconds_per_iter;  /* this run's average */
    float loss, loss_mse, loss_ssim, loss_grad; /* averages over the last 50 iterations (unweighted terms) */
    int parts, edges;         /* example parts; fixed edges of the example graph */
    int levels;               /* sketch densities trained on (1 + sparse levels found) */
    int checkpoints;          /* checkpoints written by this run */
    long embed_phase_from;    /* first iteration of the embedding phase in this run (-1 = none) */
    int holdout_checks;       /* holdout checks so far (opts->holdout), resumed ones included */
    long holdout_iteration;   /* iteration of the best check, whose network the model has (-1 = none) */
    double holdout_ssim;      /* its mean SSIM over the holdouts' sketches */
    double holdout_last_ssim; /* the last check's */
    float gain_scale;         /* the scale of the residual gain's test (tn_gnn_gain), calibrated on
                                 the holdouts' sketches; 1 without holdouts */
    float dequantized;        /* the height step the example was trained without (option
                                 dequantize); 0 = none */
} tn_gnn_stats;

/* Sketch height units at generation. */
enum { TN_GNN_HEIGHTS_AUTO = 0,   /* UNIT if every sketch height lies in [0, 1] and the example's
                                     range does not, else EXAMPLE */
       TN_GNN_HEIGHTS_EXAMPLE,    /* the example's units (an extracted network of a similar DEM) */
       TN_GNN_HEIGHTS_UNIT };     /* [0, 1] mapped linearly to the example's lo..hi (drawn sketches) */

/* Which sketch parts take an example part's embedding at generation. */
enum { TN_GNN_EMBED_AUTO = 0,     /* a part identical to an example part (same pixels and heights,
                                     e.g. the example's own network) takes its embedding, every
                                     other part none: the network's geometry-only mode, trained by
                                     embedding dropout and the sparse levels */
       TN_GNN_EMBED_ALIGNED,      /* every part takes its aligned example part's (paper 5.3) */
       TN_GNN_EMBED_NONE };       /* no part does */

typedef struct tn_gnn_generate_opts {
    uint64_t seed;           /* random sketches, alignment pick, parts' initial states, the gain's held-out
                                lines; part cutting too except under EMBED_AUTO, which cuts with the
                                model's training seed (the example's own network then gives the
                                example's own parts) */
    int heights;             /* TN_GNN_HEIGHTS_* */
    int embeddings;          /* TN_GNN_EMBED_* */
    int align_choices;       /* EMBED_ALIGNED: pick at random among the best this many aligned
                                example parts; 0 = 1 (the best), the paper uses 5 (variety) */
    int random_nodes;        /* random sketches (5.2) densify the sketch: this many random ridge nodes
                                (tn_sketch_random; their ridges and valleys avoid the sketch's
                                lines, heights in the example's range); 0 = none, at most 8192 */
    int finetune;            /* embedding fine-tune steps (5.4); 0 = none */
    float finetune_lr;       /* Adam rate of the fine-tune; 0 = 1e-2 */
    float smooth_weight;     /* fine-tune smoothness weight; 0 = 0.1, < 0 = off */
    float order_weight;      /* fine-tune sketch-ordering weight (6.1's sketch loss as a hinge): a ridge
                                pixel below, or a valley pixel above, a pixel 3 px across its line is
                                penalised by the difference; 0 = 1, < 0 = off */
    float gain;              /* how much of the network's residual over the membrane is added:
                                0 = validated on the sketch (tn_gnn_gain), > 0 = this factor
                                (1 = the network as trained), < 0 = none (the membrane) */
    int grow;                /* densify by example (tn_gnn_grow) before the network runs: 0 = when
                                the sketch's line pixels per map pixel are under a sixth of the
                                example network's (a drawing of a few strokes: 6-10 % of it; an
                                extracted network at 500 cells, 30 %, is not grown) and random_nodes
                                is 0; 1 = always; -1 = never. A grown sketch's drawn ridges also
                                take the peaks and saddles of the example's main ridges along them,
                                and the gullies and spurs of their flanks (docs/gnn.md, stop 46), so
                                their heights differ from the asked ones by about that relief */
    int detail;              /* fine detail by example (tn_fine_detail): the output's low-pass plus the
                                detail of the example heights the model holds (gnn-train stores them),
                                matched by shape; on a grown sketch, first the fine relief of the ground
                                the added lines were traced from, from 6 px of the strokes on (docs/gnn.md,
                                stop 73). 0 = on a grown sketch (a drawing of a few strokes: the
                                network gives its layout, not the example's roughness), when the model
                                holds its example; 1 = always (fails without the example); -1 = never */
    int map_scale;           /* a grown drawing larger than its example (tn_gnn_plan.map_scale): 0 = by
                                its size, -1 or 1 = never, N >= 2 = this factor. The drawing is also
                                generated N times smaller; that map, upsampled, gives the large
                                scales, this one the detail, which fades on the drawn valleys' floors
                                as on the example's main valleys */
} tn_gnn_generate_opts;

/* Fills *o with the defaults (what zero fields mean). */
TN_API void tn_gnn_defaults(tn_gnn_opts *o);
/* Windows for opts->holdout, as gnn-train takes them: up to max of the w x h windows of dem
   (channel 0) two windows away from the training window at (x, y), spread around it; the
   adjacent ones when none of those fits; windows with a NaN/Inf left out. Writes them to out[]
   (free each with tn_image_free) and returns how many (0 when none fits or max <= 0). */
TN_API int tn_gnn_holdout_windows(tn_image *out, const tn_image *dem, int x, int y, int w, int h, int max);
/* Trains on channel 0 of dem (at least 16 x 16, finite). Reports progress as "gnn-train".
   *model is allocated here (free with tn_gnn_free); stats may be NULL. A DEM without any
   extracted contour or contour part fails with TN_ERR_EMPTY. */
TN_API tn_status tn_gnn_train(tn_gnn *model, const tn_image *dem, const tn_gnn_opts *opts, tn_gnn_stats *stats);
TN_API void tn_gnn_free(tn_gnn *model);
/* .tnw model files stamped with method "gnn"; load refuses other methods' files and
   checkpoints with TN_ERR_FORMAT, and damaged configurations with TN_ERR_CORRUPT. */
TN_API tn_status tn_gnn_save(const char *path, const tn_gnn *model);
TN_API tn_status tn_gnn_load(tn_gnn *model, const char *path);
/* The example's contour parts as the model stores them (example units). *out allocated here. */
TN_API tn_status tn_gnn_parts(tn_contour_set *out, const tn_gnn *model);

/* Terrain of width x height following `sketch` (polylines; coordinates scale from its canvas),
   in the example's height units. *out (one channel) is allocated here. opts may be NULL.
   Same inputs and seed, same output, for any thread count. An empty sketch or one without a
   part of 5 px fails with TN_ERR_EMPTY, NaN/Inf points with TN_ERR_NUMERIC. */
TN_API tn_status tn_gnn_generate(tn_image *out, const tn_gnn *model, const tn_contour_set *sketch, int width,
                                 int height, const tn_gnn_generate_opts *opts);
/* Pixels (x, y) .. (x + w - 1, y + h - 1) of the width x height map tn_gnn_generate would give,
   computed alone (the same values bit for bit; tests/test_gnn.c checks it). Seamless tiles: a
   pixel depends only on the sketch within a fixed distance, 2 * rounds * (radius + 13) px for
   the network plus the membrane's blocks (see >>gnn), so the window is computed on itself grown
   by that halo (plus tn_fine_detail_halo with the fine detail). Large maps and windows run in
   tiles of 256 px (+ halo) internally, so memory follows the tile, not the map (the fine-tune's
   too: it works on windows of maps over 256^2; the fine detail's tiles are 1024 px). */
TN_API tn_status tn_gnn_generate_window(tn_image *out, const tn_gnn *model, const tn_contour_set *sketch, int width, int height, int x,
                                        int y, int w, int h, const tn_gnn_generate_opts *opts);

/* The residual gain that opts->gain = 0 uses: how far the network's residual over the membrane is
   to be trusted on this sketch, tested on the sketch itself. Three times, 30 % of the user's
   lines (not random ones) are held out; the rest is generated (without fine-tune) and the
   least-squares factor a of the residual r against the held-out pixels' true offsets t - m
   (sum r (t - m) / sum r^2 over them) is pooled, times the model's scale (calibrated on the
   holdouts in training, tn_gnn_stats.gain_scale; 1 without) and clamped to [0, 1]. Maps over 512 px a side
   are tested on their central 512 x 512 window, so any window of one map gets the same gain.
   1 when the network cannot be tested: every part is one of the example's own (its network:
   the reconstruction), fewer than 8 user lines (a drawing of a few strokes: a held-out stroke
   says little about the rest), a model without membrane, or opts->gain != 0 (then that
   setting, clamped at 0). */
TN_API tn_status tn_gnn_gain(float *gain, const tn_gnn *model, const tn_contour_set *sketch, int width, int height,
                             const tn_gnn_generate_opts *opts);

/* Does a terrain obey its sketch's ordering? Along every densified sketch line (coordinates
   scaled from the sketch canvas to the terrain), each point is compared with the two pixels
   `distance` px away across the line (normal from the points 2 before and after; 0 = 3 px):
   *share = the fraction of ridge points above both and valley points below both (points whose
   across pixels leave the map are skipped; *count, may be NULL, = the points compared). */
TN_API tn_status tn_gnn_ordering(double *share, const tn_contour_set *sketch, const tn_image *terrain, float distance, int *count);

/* What gnn-generate does with a sketch before the network runs, for printing: see tn_gnn_plan. */
typedef struct tn_gnn_plan {
    int user_lines;       /* the sketch's polylines */
    int grown_lines;      /* polylines tn_gnn_grow added (0: not grown) */
    double user_density;  /* the sketch's line pixels per map pixel */
    double example_density; /* the example network's, per example pixel */
    float gain;           /* the residual gain generation uses (tn_gnn_gain) */
    double gain_raw;      /* the held-out lines' estimate before scale and clamp; NAN = untested */
    double gain_scale;    /* the model's scale of the test (1 without holdouts) */
    const char *gain_why; /* one line: why the gain is what it is (static text) */
    int detail;           /* 1: the fine detail by example is added (tn_gnn_generate_opts.detail) */
    const char *detail_why; /* one line: why it is or is not (static text) */
    int map_scale;        /* 1, or the factor N of the map-scale level (tn_gnn_generate_opts.map_scale) */
    float floor_detail;   /* with it: the share of the detail left on a drawn valley's floor */
    const char *map_scale_why; /* one line: why (static text) */
} tn_gnn_plan;
/* Fills *plan for tn_gnn_generate with the same arguments (without running the network
   beyond the gain test). */
TN_API tn_status tn_gnn_plan_of(tn_gnn_plan *plan, const tn_gnn *model, const tn_contour_set *sketch, int width, int height,
                                const tn_gnn_generate_opts *opts);
#endif /* TN_NO_GNN */

/* --------------------------------------------------------------------------------------------
   >>gnn  (@@gnn implementation)
   Layout: membrane solve; the parts as flat arrays; the k-nearest-parts search (a bucket grid,
   rings searched outwards until the k-th distance is certain); a step's graph (fixed edges
   minus masked parts plus random edges, both edge lists in CSR order); two fused graph ops
   (attention aggregation and mean aggregation) that never materialise an edges x hidden
   tensor except the gradient scratch of training; the network; training on @@train; model
   files; generation.
   Why fused ops: with k = 10 a 128^2 example has 164k edges; gather/linear/scatter through the
   generic ops would hold ~10 edges x 32 tensors per round. The attention op takes the per-node
   terms of the first MLP layer (receiver and sender rows, computed once per node by GEMM) and
   only the 5 edge features per edge, so a round costs a few hundred flops per edge; the
   second MLP layer is applied after the attention-weighted sum (it is linear and the weights
   sum to 1, so that equals summing the encodings).
   Determinism: every reduction runs in a fixed order per destination or per source (CSR lists
   built by stable counting sorts), parameter gradients by GEMM or a serial sum.
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_GNN

#define TN__GNN_FORMAT 1
#define TN__GNN_CONFIG 24
#define TN__GNN_F 5          /* edge features: projection index (or overhang), distance, closeness, height difference, noise */
#define TN__GNN_MAXH 256
/* TN__GNN_DIST, the distance scale of the edge features: in src/internal.h */
#define TN__GNN_MAX_LEVELS 4 /* sketch densities in training */
#define TN__GNN_MAX_EDGES (1 << 25) /* ~1800^2 pixels at k = 10: ~2.5 GB of graph in training */

TN_API void tn_gnn_defaults(tn_gnn_opts *o)
{
    TN_ASSERT(o);
    /* H = 32, two-layer MLPs and k = 10 are the paper's (A.5, 4.2); T = 2 the issue's prototype.
       The embedding (16) gives each 5-10 px part room to memorise its neighbourhood. The paper's
       edge and part noise are off unless asked for, and the loss weights (MSE 1, SSIM 0.1,
       gradient 0.1 on heights of std 1) stay as measured best in docs/gnn.md ("Design choices"). */
    if (o->hidden <= 0) o->hidden = 32;
    if (o->rounds <= 0) o->rounds = 2;
    if (o->k <= 0) o->k = 10;
    if (!(o->radius > 0)) o->radius = 24.0f;
    if (o->embed <= 0) o->embed = 16;
    if (o->random_edges == 0) o->random_edges = 10000;
    if (o->mask == 0) o->mask = 0.05f;
    if (o->edge_noise < 0) o->edge_noise = 0;
    if (o->part_noise < 0) o->part_noise = 0;
    if (o->embed_drop == 0) o->embed_drop = 0.5f;
    if (o->sparse_levels == 0) o->sparse_levels = 3;
    if (o->sparse_levels > TN__GNN_MAX_LEVELS - 1) o->sparse_levels = TN__GNN_MAX_LEVELS - 1;
    if (o->thin == 0) o->thin = 0.5f;
    /* the embeddings catch up at the end on what dropout and the sparse levels kept from them,
       while the network keeps most of its training: a quarter of the budget; with an early
       network for other terrain the phase trains everything for the example alone, so half
       (docs/gnn.md, "Embedding phase") */
    if (o->embed_phase == 0) o->embed_phase = o->holdout && o->holdout_count > 0 && o->phase_network >= 0 ? 0.5f : 0.25f;
    if (o->lr == 0) o->lr = 2e-3f;
    if (o->mse_weight == 0) o->mse_weight = 1.0f;
    if (o->ssim_weight == 0) o->ssim_weight = 0.1f;
    if (o->grad_weight == 0) o->grad_weight = 0.1f;
    /* smoothness 0.1 keeps the reconstruction and helps the neighbours; 6.1's sketch and distance
       terms cost the neighbours and the drawn sketch's ordering, so they stay off (docs/gnn.md,
       "Design choices") */
    if (o->smooth_weight == 0) o->smooth_weight = 0.1f;
    if (o->holdout_every <= 0) o->holdout_every = 150;
    tn_train_defaults(&o->train, 10.0);
}

/* The rules of tn_gnn_opts after tn_gnn_defaults, one message each (negative rates and shares
   mean "none" where the field says so). */
static tn_status tn__gnn_validate(const tn_gnn_opts *o)
{
    const char *w = "gnn";
    tn_status st;
    if ((st = tn__opt_int(w, "hidden", o->hidden, 1, TN__GNN_MAXH)) || (st = tn__opt_int(w, "rounds", o->rounds, 1, 16)) ||
        (st = tn__opt_int(w, "k", o->k, 1, 64)) || (st = tn__opt_float(w, "radius", o->radius, "(]", 0, 4096)) ||
        (st = tn__opt_int(w, "embed", o->embed, 1, 256)) || (st = tn__opt_float(w, "lr", o->lr, "()", 0, 10)) ||
        (st = tn__opt_float(w, "mask", o->mask, "()", -HUGE_VAL, 1)) || (st = tn__opt_float(w, "embed_drop", o->embed_drop, "()", -HUGE_VAL, 1)) ||
        (st = tn__opt_float(w, "thin", o->thin, "()", -HUGE_VAL, 1)) || (st = tn__opt_float(w, "embed_phase", o->embed_phase, "()", -HUGE_VAL, 1)) ||
        (st = tn__opt_float(w, "edge_noise", o->edge_noise, "[]", 0, 100)) || (st = tn__opt_float(w, "part_noise", o->part_noise, "[]", 0, 100)) ||
        (st = tn__opt_float(w, "mse_weight", o->mse_weight, "()", -HUGE_VAL, HUGE_VAL)) ||
        (st = tn__opt_float(w, "ssim_weight", o->ssim_weight, "()", -HUGE_VAL, HUGE_VAL)) ||
        (st = tn__opt_float(w, "grad_weight", o->grad_weight, "()", -HUGE_VAL, HUGE_VAL)) ||
        (st = tn__opt_int(w, "random_edges", o->random_edges, INT_MIN, 1 << 24)) ||
        (st = tn__opt_float(w, "sketch_weight", o->sketch_weight, "[]", 0, 1e6)) ||
        (st = tn__opt_float(w, "smooth_weight", o->smooth_weight, "(]", -HUGE_VAL, 1e6)) ||
        (st = tn__opt_float(w, "further_weight", o->further_weight, "[]", 0, 1e6)) ||
        (st = tn__opt_int(w, "holdout_count", o->holdout_count, 0, 64)) || (st = tn__opt_int(w, "dequantize", o->dequantize, -1, 1)))
        return st;
    if (o->holdout_count > 0 && !o->holdout)
        return tn__fail(TN_ERR_INVALID_ARG, "gnn: option holdout_count = %d, allowed 0 while holdout is NULL", o->holdout_count);
    return TN_OK;
}

TN_API int tn_gnn_holdout_windows(tn_image *out, const tn_image *dem, int x, int y, int w, int h, int max)
{
    int ring, dx, dy, c, k, m = 0, cx[24], cy[24];
    if (!dem || !dem->data || !out || w <= 0 || h <= 0) return 0;
    for (ring = 2; ring >= 1 && !m; ring--) {
        c = 0;
        for (dy = -ring; dy <= ring; dy++)
            for (dx = -ring; dx <= ring; dx++)
                if ((abs(dx) == ring || abs(dy) == ring) && x + dx * w >= 0 && y + dy * h >= 0 && x + (dx + 1) * w <= dem->width &&
                    y + (dy + 1) * h <= dem->height) {
                    cx[c] = x + dx * w;
                    cy[c++] = y + dy * h;
                }
        for (k = 0; k < max && k < c; k++) {
            int u, v, bad = 0, x0 = cx[k * c / (c < max ? c : max)], y0 = cy[k * c / (c < max ? c : max)];
            if (tn_image_create(&out[m], w, h, 1)) return m;
            for (v = 0; v < h && !bad; v++)
                for (u = 0; u < w; u++) bad += !isfinite(TN_PIXEL(&out[m], u, v, 0) = TN_PIXEL(dem, x0 + u, y0 + v, 0));
            if (bad) tn_image_free(&out[m]);
            else m++;
        }
    }
    return m;
}

/* The membrane between a sketch's lines (>>gnn_membrane): in blocks of bounded influence, and
   the rasterised sketch with it. */
static tn_status tn__gnn_membrane_rect(const float *val, const uint8_t *fixed, int W, int H, int rx, int ry, int rw, int rh,
                                       float *out); /* >>gnn_membrane */
static tn_status tn__gnn_sketch_pixels(const tn_contour_set *set, int W, int H, float *type, float *height,
                                       float *membrane); /* >>gnn_membrane */

/* Across-line pixel pairs of a densified sketch already in the map's pixels: for point i, the
   pixel p and the pixels q1, q2 at +-d along the normal (-1 when outside). sign: +1 ridge. */
static void tn__gnn_across(const tn_contour *c, int i, int W, int H, float d, int *p, int *q1, int *q2)
{
    int a = i - 2 > 0 ? i - 2 : 0, b = i + 2 < c->npoints - 1 ? i + 2 : c->npoints - 1;
    float tx = c->points[3 * b] - c->points[3 * a], ty = c->points[3 * b + 1] - c->points[3 * a + 1], n = sqrtf(tx * tx + ty * ty);
    float x = c->points[3 * i], y = c->points[3 * i + 1];
    int px = (int)floorf(x + 0.5f), py = (int)floorf(y + 0.5f), k;
    *p = *q1 = *q2 = -1;
    if (!(n > 0) || px < 0 || py < 0 || px >= W || py >= H) return;
    *p = py * W + px;
    for (k = 0; k < 2; k++) {
        float s = k ? -d : d;
        int qx = (int)floorf(x - s * ty / n + 0.5f), qy = (int)floorf(y + s * tx / n + 0.5f);
        if (qx >= 0 && qy >= 0 && qx < W && qy < H) *(k ? q2 : q1) = qy * W + qx;
    }
}

/* ---- parts as flat arrays ---- */

/* tn__gnn_parts: in src/internal.h (test_gnn checks the projections). */

TN__INTERNAL void tn__gnn_parts_free(tn__gnn_parts *p)
{
    TN_FREE(p->start);
    TN_FREE(p->of);
    TN_FREE(p->pts);
    TN_FREE(p->sign);
    memset(p, 0, sizeof *p);
}

/* Heights become (h - mean) / std. */
TN__INTERNAL tn_status tn__gnn_parts_make(const tn_contour_set *set, float mean, float std, tn__gnn_parts *p)
{
    int i, j, k = 0;
    memset(p, 0, sizeof *p);
    p->n = set->count;
    for (i = 0; i < set->count; i++) p->npts += set->items[i].npoints;
    p->start = (int *)tn__alloc(((size_t)p->n + 1) * sizeof(int));
    p->of = (int *)tn__alloc(((size_t)p->npts + 1) * sizeof(int));
    p->pts = (float *)tn__alloc(((size_t)p->npts + 1) * 3 * sizeof(float));
    p->sign = (float *)tn__alloc(((size_t)p->n + 1) * sizeof(float));
    if (!p->start || !p->of || !p->pts || !p->sign) {
        tn__gnn_parts_free(p);
        return TN_ERR_OUT_OF_MEMORY;
    }
    for (i = 0; i < set->count; i++) {
        const tn_contour *c = &set->items[i];
        p->start[i] = k;
        p->sign[i] = c->type == TN_RIDGE ? 1.0f : -1.0f;
        for (j = 0; j < c->npoints; j++, k++) {
            p->of[k] = i;
            p->pts[3 * k] = c->points[3 * j];
            p->pts[3 * k + 1] = c->points[3 * j + 1];
            p->pts[3 * k + 2] = (c->points[3 * j + 2] - mean) / std;
        }
    }
    p->start[p->n] = k;
    return TN_OK;
}

/* Edge features of pixel (x, y) against one part, given its nearest point (index j of the
   part) and squared distance; base = the pixel's baseline height (0 without membrane). */
static void tn__gnn_edge_features(const tn__gnn_parts *P, int part, int j, float d2, float base, float *f)
{
    int n = P->start[part + 1] - P->start[part];
    float d = sqrtf(d2);
    f[0] = n > 1 ? 2.0f * (float)j / (float)(n - 1) - 1.0f : 0.0f;
    f[1] = d / TN__GNN_DIST;
    f[2] = expf(-0.5f * d);
    f[3] = P->pts[3 * (P->start[part] + j) + 2] - base;
    f[4] = 0.0f;
}

/* Nearest point of a part to (x, y): index within the part (lowest on ties) and squared distance. */
TN__INTERNAL int tn__gnn_project(const tn__gnn_parts *P, int part, float x, float y, float *d2)
{
    int a = P->start[part], b = P->start[part + 1], j, best = 0;
    float bd = FLT_MAX;
    for (j = a; j < b; j++) {
        float dx = P->pts[3 * j] - x, dy = P->pts[3 * j + 1] - y, e = dx * dx + dy * dy;
        if (e < bd) { bd = e; best = j - a; }
    }
    *d2 = bd;
    return best;
}

/* Edge feature 0 of a part without an embedding (A.overhang): how far (x, y) lies beyond the
   part's end along its direction, 0 beside it. The projection index (f0, as computed) only says
   where a random cut fell on such a part; this does not depend on the cut. */
TN__INTERNAL float tn__gnn_overhang(const tn__gnn_parts *P, int part, float f0, float x, float y)
{
    int a = P->start[part], n = P->start[part + 1] - a, j, o;
    float tx, ty, tl, v;
    if (n < 2) return 0.0f;
    j = (int)floorf((f0 + 1.0f) * 0.5f * (float)(n - 1) + 0.5f);
    if (j > 0 && j < n - 1) return 0.0f;
    o = j == 0 ? 1 : n - 2;
    tx = P->pts[3 * (a + j)] - P->pts[3 * (a + o)];
    ty = P->pts[3 * (a + j) + 1] - P->pts[3 * (a + o) + 1];
    tl = sqrtf(tx * tx + ty * ty);
    if (!(tl > 0)) return 0.0f;
    v = ((x - P->pts[3 * (a + j)]) * tx + (y - P->pts[3 * (a + j) + 1]) * ty) / tl;
    return v > 0 ? v / TN__GNN_DIST : 0.0f;
}

/* ---- k nearest parts of every pixel ---- */

#define TN__GNN_CELL 8

typedef struct tn__gnn_cand { int part, pt; float d2; } tn__gnn_cand;

typedef struct tn__gnn_knn_job {
    const tn__gnn_parts *P;
    int W, H, ox, oy, k, gw, gh, rcap;  /* window W x H at (ox, oy) of the map; rcap: last ring searched */
    float r2;                           /* squared search radius; 0 = none */
    const int *cell_start, *cell_pts;   /* bucket grid of point indices */
    const float *base;                  /* per pixel baseline (normalised) or NULL */
    int *nbr;                           /* npix x k parts (-1 = none) */
    float *feat;                        /* npix x k x F */
    tn_status st[TN__MAX_THREADS];
} tn__gnn_knn_job;

static int tn__gnn_cand_cmp(const void *a, const void *b)
{
    const tn__gnn_cand *x = (const tn__gnn_cand *)a, *y = (const tn__gnn_cand *)b;
    if (x->d2 != y->d2) return x->d2 < y->d2 ? -1 : 1;
    return (x->part > y->part) - (x->part < y->part);
}

static void tn__gnn_knn_task(void *vjob, int ith, int nth)
{
    tn__gnn_knn_job *J = (tn__gnn_knn_job *)vjob;
    const tn__gnn_parts *P = J->P;
    int *stamp = (int *)tn__alloc((size_t)P->n * sizeof(int)), *slot = (int *)tn__alloc((size_t)P->n * sizeof(int));
    tn__gnn_cand *cand = (tn__gnn_cand *)tn__alloc((size_t)P->n * sizeof(tn__gnn_cand));
    int y0 = (int)((long)J->H * ith / nth), y1 = (int)((long)J->H * (ith + 1) / nth), x, y, i, k = J->k;
    if (!stamp || !slot || !cand) {
        J->st[ith] = TN_ERR_OUT_OF_MEMORY;
        TN_FREE(stamp); TN_FREE(slot); TN_FREE(cand);
        return;
    }
    for (i = 0; i < P->n; i++) stamp[i] = -1;
    for (y = y0; y < y1; y++)
        for (x = 0; x < J->W; x++) {
            int pix = y * J->W + x, bx = x / TN__GNN_CELL, by = y / TN__GNN_CELL, r, nc = 0, rmax = J->gw > J->gh ? J->gw : J->gh;
            float gx = (float)(x + J->ox), gy = (float)(y + J->oy);
            size_t o = (size_t)pix * k;
            if (J->rcap < rmax) rmax = J->rcap;
            for (r = 0; r <= rmax; r++) {
                int cx, cy;
                for (cy = by - r; cy <= by + r; cy++) {
                    if (cy < 0 || cy >= J->gh) continue;
                    for (cx = bx - r; cx <= bx + r; cx++) {
                        int c, q;
                        if (cx < 0 || cx >= J->gw || (abs(cx - bx) != r && abs(cy - by) != r)) continue;
                        c = cy * J->gw + cx;
                        for (q = J->cell_start[c]; q < J->cell_start[c + 1]; q++) {
                            int pt = J->cell_pts[q], part = P->of[pt];
                            float dx = P->pts[3 * pt] - gx, dy = P->pts[3 * pt + 1] - gy, d2 = dx * dx + dy * dy;
                            if (J->r2 > 0 && !(d2 < J->r2)) continue;
                            if (stamp[part] != pix) {
                                stamp[part] = pix;
                                slot[part] = nc;
                                cand[nc].part = part;
                                cand[nc].pt = pt;
                                cand[nc++].d2 = d2;
                            } else {
                                tn__gnn_cand *cd = &cand[slot[part]];
                                if (d2 < cd->d2 || (d2 == cd->d2 && pt < cd->pt)) { cd->d2 = d2; cd->pt = pt; }
                            }
                        }
                    }
                }
                /* every point beyond ring r is farther than r cells */
                if (nc >= k) {
                    float bound = (float)(r * TN__GNN_CELL), b2 = bound * bound;
                    int below = 0;
                    for (i = 0; i < nc; i++) below += cand[i].d2 <= b2;
                    if (below >= k) break;
                }
            }
            /* candidates found in different rings: order them fully (ties: lower part index) */
            qsort(cand, (size_t)nc, sizeof *cand, tn__gnn_cand_cmp);
            for (i = 0; i < nc; i++) slot[cand[i].part] = i;
            for (i = 0; i < k; i++) {
                float *f = J->feat + (o + (size_t)i) * TN__GNN_F;
                if (i >= nc) {
                    J->nbr[o + (size_t)i] = -1;
                    memset(f, 0, TN__GNN_F * sizeof(float));
                    continue;
                }
                J->nbr[o + (size_t)i] = cand[i].part;
                tn__gnn_edge_features(P, cand[i].part, cand[i].pt - P->start[cand[i].part], cand[i].d2, J->base ? J->base[pix] : 0.0f, f);
            }
        }
    TN_FREE(stamp);
    TN_FREE(slot);
    TN_FREE(cand);
}

/* The k nearest parts (closer than `radius` px when radius > 0) of every pixel of the W x H
   window at (ox, oy) of the map (parts in map coordinates); base: the window's baselines.
   nbr (npix x k) and feat (npix x k x F) allocated here. Points outside the window sit in the
   grid's border cells, nearer than they are, so the ring search stays exact. */
static tn_status tn__gnn_knn(const tn__gnn_parts *P, int W, int H, int ox, int oy, int k, float radius, const float *base, int **nbr,
                             float **feat)
{
    tn__gnn_knn_job J;
    int *cnt = NULL, i, ncell;
    size_t npix = (size_t)W * H;
    tn_status st = TN_OK;
    memset(&J, 0, sizeof J);
    J.P = P;
    J.W = W;
    J.H = H;
    J.k = k;
    J.ox = ox;
    J.oy = oy;
    J.base = base;
    J.gw = (W + TN__GNN_CELL - 1) / TN__GNN_CELL;
    J.gh = (H + TN__GNN_CELL - 1) / TN__GNN_CELL;
    J.r2 = radius > 0 ? radius * radius : 0.0f;
    J.rcap = radius > 0 ? (int)ceilf(radius / TN__GNN_CELL) + 1 : INT_MAX;
    ncell = J.gw * J.gh;
    cnt = (int *)tn__calloc(((size_t)ncell + 1) * sizeof(int));
    J.cell_pts = (int *)tn__alloc(((size_t)P->npts + 1) * sizeof(int));
    *nbr = (int *)tn__alloc(npix * k * sizeof(int));
    *feat = (float *)tn__alloc(npix * k * TN__GNN_F * sizeof(float));
    if (!cnt || !J.cell_pts || !*nbr || !*feat) st = TN_ERR_OUT_OF_MEMORY;
    if (!st) {
        int *cp = (int *)J.cell_pts, *fill;
#define TN__GNN_CELLOF(pt) \
    ((P->pts[3 * (pt) + 1] - oy < 0 ? 0 : (int)(P->pts[3 * (pt) + 1] - oy) / TN__GNN_CELL >= J.gh ? J.gh - 1 : (int)(P->pts[3 * (pt) + 1] - oy) / TN__GNN_CELL) * J.gw + \
     (P->pts[3 * (pt)] - ox < 0 ? 0 : (int)(P->pts[3 * (pt)] - ox) / TN__GNN_CELL >= J.gw ? J.gw - 1 : (int)(P->pts[3 * (pt)] - ox) / TN__GNN_CELL))
        for (i = 0; i < P->npts; i++) cnt[TN__GNN_CELLOF(i) + 1]++;
        for (i = 0; i < ncell; i++) cnt[i + 1] += cnt[i];
        if (!(fill = (int *)tn__alloc(((size_t)ncell + 1) * sizeof(int)))) st = TN_ERR_OUT_OF_MEMORY;
        else {
            memcpy(fill, cnt, (size_t)ncell * sizeof(int));
            for (i = 0; i < P->npts; i++) cp[fill[TN__GNN_CELLOF(i)]++] = i;
            TN_FREE(fill);
        }
#undef TN__GNN_CELLOF
    }
    if (!st) {
        J.cell_start = cnt;
        J.nbr = *nbr;
        J.feat = *feat;
        tn_parallel_run(tn__gnn_knn_task, &J);
        for (i = 0; i < TN__MAX_THREADS; i++)
            if (J.st[i]) st = tn__fail(J.st[i], "gnn: out of memory searching nearest parts");
    }
    TN_FREE(cnt);
    TN_FREE((void *)J.cell_pts);
    if (st) {
        TN_FREE(*nbr);
        TN_FREE(*feat);
        *nbr = NULL;
        *feat = NULL;
    }
    return st;
}

/* ---- a graph: edges with features, laid out per direction in destination order ---- */

/* One direction of the bipartite graph. Its edges are numbered by position in destination
   order (destination d owns positions dst_start[d] .. dst_start[d + 1] - 1), so the per-edge
   arrays the ops stream (features, attention weights, gradient rows) are read sequentially;
   only the per-source pass jumps, through src_pos. */
typedef struct tn__gnn_dir {
    int nsrc, ndst, E;
    const int *dst_start;              /* ndst + 1 */
    const int *src_of, *dst_of;        /* per position */
    const float *feat;                 /* per position, F features */
    const int *src_start, *src_pos;    /* positions of each source's edges */
} tn__gnn_dir;

typedef struct tn__gnn_graph {
    int npix, nparts, E, cap;
    int *e_pix, *e_part;               /* edges as built */
    float *feat;                       /* E x F as built */
    int *pix_start, *pix_edges, *part_start, *part_edges;  /* CSR by pixel / by part (edge ids) */
    int *ints;                         /* 7 x cap: per-direction position arrays + scratch */
    float *feats;                      /* 2 x cap x F: features in each direction's order */
    tn__gnn_dir g2p, p2g;              /* pixels -> parts (gather), parts -> pixels (scatter) */
} tn__gnn_graph;

static void tn__gnn_graph_free(tn__gnn_graph *g)
{
    TN_FREE(g->e_pix);
    TN_FREE(g->e_part);
    TN_FREE(g->feat);
    TN_FREE(g->pix_start);
    TN_FREE(g->pix_edges);
    TN_FREE(g->part_start);
    TN_FREE(g->part_edges);
    TN_FREE(g->ints);
    TN_FREE(g->feats);
    memset(g, 0, sizeof *g);
}

static tn_status tn__gnn_graph_alloc(tn__gnn_graph *g, int npix, int nparts, int cap)
{
    memset(g, 0, sizeof *g);
    g->npix = npix;
    g->nparts = nparts;
    g->cap = cap;
    g->e_pix = (int *)tn__alloc((size_t)cap * sizeof(int));
    g->e_part = (int *)tn__alloc((size_t)cap * sizeof(int));
    g->feat = (float *)tn__alloc((size_t)cap * TN__GNN_F * sizeof(float));
    g->pix_start = (int *)tn__alloc(((size_t)npix + 1) * sizeof(int));
    g->pix_edges = (int *)tn__alloc((size_t)cap * sizeof(int));
    g->part_start = (int *)tn__alloc(((size_t)nparts + 1) * sizeof(int));
    g->part_edges = (int *)tn__alloc((size_t)cap * sizeof(int));
    g->ints = (int *)tn__alloc((size_t)cap * 7 * sizeof(int));
    g->feats = (float *)tn__alloc((size_t)cap * 2 * TN__GNN_F * sizeof(float));
    if (!g->e_pix || !g->e_part || !g->feat || !g->pix_start || !g->pix_edges || !g->part_start || !g->part_edges || !g->ints ||
        !g->feats) {
        tn__gnn_graph_free(g);
        return TN_ERR_OUT_OF_MEMORY;
    }
    return TN_OK;
}

/* Stable counting sort of the edges by key: start (n + 1) and list (E). */
static void tn__gnn_csr(const int *key, int E, int n, int *start, int *list)
{
    int i;
    memset(start, 0, ((size_t)n + 1) * sizeof(int));
    for (i = 0; i < E; i++) start[key[i] + 1]++;
    for (i = 0; i < n; i++) start[i + 1] += start[i];
    for (i = 0; i < E; i++) list[start[key[i]]++] = i;
    for (i = n; i > 0; i--) start[i] = start[i - 1];
    start[0] = 0;
}

/* One direction from the two CSR lists: dst_edges orders the positions, src_edges lists each
   source's edges; inv (scratch, E) maps an edge id to its position. */
static void tn__gnn_dir_make(tn__gnn_dir *D, int nsrc, int ndst, int E, const int *src, const int *dst, const float *feat,
                             const int *dst_start, const int *dst_edges, const int *src_start, const int *src_edges, int *src_of,
                             int *dst_of, int *src_pos, float *dfeat, int *inv)
{
    int k;
    for (k = 0; k < E; k++) {
        int e = dst_edges[k];
        inv[e] = k;
        src_of[k] = src[e];
        dst_of[k] = dst[e];
        memcpy(dfeat + (size_t)k * TN__GNN_F, feat + (size_t)e * TN__GNN_F, TN__GNN_F * sizeof(float));
    }
    for (k = 0; k < E; k++) src_pos[k] = inv[src_edges[k]];
    D->nsrc = nsrc;
    D->ndst = ndst;
    D->E = E;
    D->dst_start = dst_start;
    D->src_of = src_of;
    D->dst_of = dst_of;
    D->feat = dfeat;
    D->src_start = src_start;
    D->src_pos = src_pos;
}

static void tn__gnn_graph_finish(tn__gnn_graph *g)
{
    int *I = g->ints;
    size_t c = (size_t)g->cap;
    tn__gnn_csr(g->e_pix, g->E, g->npix, g->pix_start, g->pix_edges);
    tn__gnn_csr(g->e_part, g->E, g->nparts, g->part_start, g->part_edges);
    tn__gnn_dir_make(&g->g2p, g->npix, g->nparts, g->E, g->e_pix, g->e_part, g->feat, g->part_start, g->part_edges, g->pix_start,
                     g->pix_edges, I, I + c, I + 2 * c, g->feats, I + 6 * c);
    tn__gnn_dir_make(&g->p2g, g->nparts, g->npix, g->E, g->e_part, g->e_pix, g->feat, g->pix_start, g->pix_edges, g->part_start,
                     g->part_edges, I + 3 * c, I + 4 * c, I + 5 * c, g->feats + c * TN__GNN_F, I + 6 * c);
}

/* Feature 0 of the edges to parts without an embedding (known[of[part]] == 0, of NULL: the
   identity; known NULL: none has one) becomes their overhang; P in the coordinates of the window
   at (ox, oy), W pixels wide. */
static void tn__gnn_overhangs(tn__gnn_graph *g, const tn__gnn_parts *P, const uint8_t *known, const int *of, int W, int ox, int oy)
{
    int e;
    for (e = 0; e < g->E; e++) {
        float *f = g->feat + (size_t)e * TN__GNN_F;
        int r = g->e_part[e], p = g->e_pix[e];
        if (!known || !known[of ? of[r] : r]) f[0] = tn__gnn_overhang(P, r, f[0], (float)(p % W + ox), (float)(p / W + oy));
    }
}

/* ---- fused graph ops ---- */

/* Attention aggregation: for every destination d,
       h_e = relu(U[src_e] + V[d] + Wc feat_e),  s_e = a . h_e,  alpha = softmax over d's edges,
       Y[d] = sum_e alpha_e h_e  (0 for a destination without edges).
   U: nsrc x H, V: ndst x H, Wc: H x F, a: H. The forward keeps only alpha (E floats); the
   backward recomputes h_e. */
/* SIMD over the hidden axis (the tn__vf layer of >>imageops plus max and mask); a scalar tail
   handles widths that are not a multiple of the vector. */
#if TN__VF_N == 16
#define tn__gnn_relu_v(z) _mm512_max_ps((z), _mm512_setzero_ps())
#define tn__gnn_ifpos_v(h, v) _mm512_maskz_mov_ps(_mm512_cmp_ps_mask((h), _mm512_setzero_ps(), _CMP_GT_OQ), (v))
#elif TN__VF_N == 8
#define tn__gnn_relu_v(z) _mm256_max_ps((z), _mm256_setzero_ps())
#define tn__gnn_ifpos_v(h, v) _mm256_and_ps(_mm256_cmp_ps((h), _mm256_setzero_ps(), _CMP_GT_OQ), (v))
#else
#define tn__gnn_relu_v(z) ((z) > 0 ? (z) : 0.0f)
#define tn__gnn_ifpos_v(h, v) ((h) > 0 ? (v) : 0.0f)
#endif

/* sum of the lanes, in a fixed order */
static inline float tn__gnn_hsum(tn__vf v)
{
    float lanes[TN__VF_N], s = 0;
    int l;
    tn__vf_store(lanes, v);
    for (l = 0; l < TN__VF_N; l++) s += lanes[l];
    return s;
}

/* y[i] = a * x[i] + y[i] */
static inline void tn__gnn_axpy(float a, const float *x, float *y, int n)
{
    tn__vf va = tn__vf_set1(a);
    int i = 0;
    for (; i + TN__VF_N <= n; i += TN__VF_N) tn__vf_store(y + i, tn__vf_madd(va, tn__vf_load(x + i), tn__vf_load(y + i)));
    for (; i < n; i++) y[i] += a * x[i];
}

/* y[i] += a * x[i], the product rounded before the sum (the bytes of the scalar loop, unlike
   tn__gnn_axpy's fused multiply-add; a = 1 is a plain sum) */
static inline void tn__gnn_add_scaled(float a, const float *x, float *y, int n)
{
    tn__vf va = tn__vf_set1(a);
    int i = 0;
    for (; i + TN__VF_N <= n; i += TN__VF_N) tn__vf_store(y + i, tn__vf_add(tn__vf_load(y + i), tn__vf_mul(va, tn__vf_load(x + i))));
    for (; i < n; i++) y[i] += a * x[i];
}

typedef struct tn__gnn_att {
    const tn__gnn_dir *g;
    const float *U, *V, *WcT, *a, *dY;   /* WcT: F x H, so the per-edge loop runs along H */
    float *Y, *alpha, *dots, *dz, *dU, *dV, *da_rows, *dw_rows;
    int H;
} tn__gnn_att;

/* h = relu(U[src] + V[d] + Wc f) of the edge at position k into h; returns dot(w_dot, h). */
static inline float tn__gnn_att_h(const tn__gnn_att *J, int k, int d, const float *w_dot, float *h)
{
    const float *u = J->U + (size_t)J->g->src_of[k] * J->H, *v = J->V + (size_t)d * J->H, *f = J->g->feat + (size_t)k * TN__GNN_F;
    const float *w = J->WcT;
    int i = 0, H = J->H;
    float s;
    tn__vf f0 = tn__vf_set1(f[0]), f1 = tn__vf_set1(f[1]), f2 = tn__vf_set1(f[2]), f3 = tn__vf_set1(f[3]), f4 = tn__vf_set1(f[4]);
    tn__vf acc = tn__vf_set1(0.0f);
    for (; i + TN__VF_N <= H; i += TN__VF_N) {
        tn__vf z = tn__vf_add(tn__vf_load(u + i), tn__vf_load(v + i));
        z = tn__vf_madd(f0, tn__vf_load(w + i), z);
        z = tn__vf_madd(f1, tn__vf_load(w + H + i), z);
        z = tn__vf_madd(f2, tn__vf_load(w + 2 * H + i), z);
        z = tn__vf_madd(f3, tn__vf_load(w + 3 * H + i), z);
        z = tn__vf_madd(f4, tn__vf_load(w + 4 * H + i), z);
        z = tn__gnn_relu_v(z);
        tn__vf_store(h + i, z);
        acc = tn__vf_madd(z, tn__vf_load(w_dot + i), acc);
    }
    s = tn__gnn_hsum(acc);
    for (; i < H; i++) {
        float z = u[i] + v[i] + f[0] * w[i] + f[1] * w[H + i] + f[2] * w[2 * H + i] + f[3] * w[3 * H + i] + f[4] * w[4 * H + i];
        h[i] = z > 0 ? z : 0.0f;
        s += h[i] * w_dot[i];
    }
    return s;
}

static void tn__gnn_att_fwd(void *vj, size_t b, size_t end)
{
    const tn__gnn_att *J = (const tn__gnn_att *)vj;
    float h[TN__GNN_MAXH], acc[TN__GNN_MAXH];
    int H = J->H, i;
    size_t d;
    for (d = b; d < end; d++) {
        int k0 = J->g->dst_start[d], k1 = J->g->dst_start[d + 1], k;
        float m = -FLT_MAX, sum = 0, *y = J->Y + d * H;
        for (i = 0; i < H; i++) acc[i] = 0;
        for (k = k0; k < k1; k++) {
            float s = tn__gnn_att_h(J, k, (int)d, J->a, h), w;
            if (J->alpha) J->alpha[k] = s;
            if (s > m) { /* online softmax: rescale what was summed so far */
                float r = k == k0 ? 0.0f : expf(m - s);
                for (i = 0; i < H; i++) acc[i] *= r;
                sum *= r;
                m = s;
            }
            w = expf(s - m);
            sum += w;
            tn__gnn_axpy(w, h, acc, H);
        }
        for (i = 0; i < H; i++) y[i] = k1 > k0 ? acc[i] / sum : 0.0f;
        if (J->alpha)
            for (k = k0; k < k1; k++) J->alpha[k] = expf(J->alpha[k] - m) / sum;
    }
}

/* Per destination: h recomputed into the dz rows, then turned into dz in place; the
   destination's shares of da and dWc go to its own rows (summed serially afterwards). */
static void tn__gnn_att_bwd_dst(void *vj, size_t b, size_t end)
{
    const tn__gnn_att *J = (const tn__gnn_att *)vj;
    int H = J->H, i, j;
    size_t d;
    for (d = b; d < end; d++) {
        int k0 = J->g->dst_start[d], k1 = J->g->dst_start[d + 1], k;
        const float *g = J->dY + d * H, *a = J->a;
        float *dv = J->dV ? J->dV + d * H : J->da_rows + d * H, *dar = J->da_rows + d * H, *dwr = J->dw_rows + d * H * TN__GNN_F, mean = 0;
        for (i = 0; i < H; i++) dar[i] = 0;
        for (i = 0; i < H * TN__GNN_F; i++) dwr[i] = 0;
        for (k = k0; k < k1; k++) {
            J->dots[k] = tn__gnn_att_h(J, k, (int)d, g, J->dz + (size_t)k * H);
            mean += J->alpha[k] * J->dots[k];
        }
        for (k = k0; k < k1; k++) {
            float al = J->alpha[k], ds = al * (J->dots[k] - mean), *dz = J->dz + (size_t)k * H;
            const float *f = J->g->feat + (size_t)k * TN__GNN_F;
            tn__vf val = tn__vf_set1(al), vds = tn__vf_set1(ds), f0 = tn__vf_set1(f[0]), f1 = tn__vf_set1(f[1]), f2 = tn__vf_set1(f[2]);
            tn__vf f3 = tn__vf_set1(f[3]), f4 = tn__vf_set1(f[4]);
            for (i = 0; i + TN__VF_N <= H; i += TN__VF_N) {
                tn__vf hv = tn__vf_load(dz + i), z;
                tn__vf_store(dar + i, tn__vf_madd(vds, hv, tn__vf_load(dar + i)));
                z = tn__gnn_ifpos_v(hv, tn__vf_madd(val, tn__vf_load(g + i), tn__vf_mul(vds, tn__vf_load(a + i))));
                tn__vf_store(dz + i, z);
                if (J->dV) tn__vf_store(dv + i, tn__vf_add(tn__vf_load(dv + i), z));
                tn__vf_store(dwr + i, tn__vf_madd(f0, z, tn__vf_load(dwr + i)));
                tn__vf_store(dwr + H + i, tn__vf_madd(f1, z, tn__vf_load(dwr + H + i)));
                tn__vf_store(dwr + 2 * H + i, tn__vf_madd(f2, z, tn__vf_load(dwr + 2 * H + i)));
                tn__vf_store(dwr + 3 * H + i, tn__vf_madd(f3, z, tn__vf_load(dwr + 3 * H + i)));
                tn__vf_store(dwr + 4 * H + i, tn__vf_madd(f4, z, tn__vf_load(dwr + 4 * H + i)));
            }
            for (; i < H; i++) {
                float hv = dz[i];
                dar[i] += ds * hv;
                dz[i] = hv > 0 ? al * g[i] + ds * a[i] : 0.0f;
                if (J->dV) dv[i] += dz[i];
                for (j = 0; j < TN__GNN_F; j++) dwr[(size_t)j * H + i] += f[j] * dz[i];
            }
        }
    }
}

static void tn__gnn_att_bwd_src(void *vj, size_t b, size_t end)
{
    const tn__gnn_att *J = (const tn__gnn_att *)vj;
    size_t s;
    for (s = b; s < end; s++) {
        int k;
        float *du = J->dU + s * J->H;
        for (k = J->g->src_start[s]; k < J->g->src_start[s + 1]; k++) tn__gnn_axpy(1.0f, J->dz + (size_t)J->g->src_pos[k] * J->H, du, J->H);
    }
}

static float *tn__gnn_transpose_wc(tn_ctx *ctx, const tn_tensor *Wc)
{
    int H = Wc->shape[0], i, j;
    float *t = tn__ctx_floats(ctx, (size_t)H * TN__GNN_F, 0);
    if (t)
        for (i = 0; i < H; i++)
            for (j = 0; j < TN__GNN_F; j++) t[(size_t)j * H + i] = Wc->data[(size_t)i * TN__GNN_F + j];
    return t;
}

static void tn__gnn_attend_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *U = out->src[0], *V = out->src[1], *Wc = out->src[2], *a = out->src[3];
    tn__gnn_att J;
    const tn__gnn_dir *g = (const tn__gnn_dir *)out->aux;
    int H = out->shape[1], E = g->E, i, j;
    size_t d;
    memset(&J, 0, sizeof J);
    J.g = g;
    J.H = H;
    J.U = U->data;
    J.V = V->data;
    J.WcT = tn__gnn_transpose_wc(ctx, Wc);
    J.a = a->data;
    J.dY = out->grad;
    memcpy(&J.alpha, (char *)out->aux + sizeof(tn__gnn_dir), sizeof(float *));
    J.dz = tn__ctx_floats(ctx, (size_t)(E > 0 ? E : 1) * H, 0);
    J.dots = tn__ctx_floats(ctx, (size_t)(E > 0 ? E : 1), 0);
    J.da_rows = tn__ctx_floats(ctx, (size_t)g->ndst * H, 0);
    J.dw_rows = tn__ctx_floats(ctx, (size_t)g->ndst * H * TN__GNN_F, 0);
    J.dV = V->requires_grad ? tn__grad(ctx, V) : NULL;
    J.dU = U->requires_grad ? tn__grad(ctx, U) : NULL;
    if (!J.WcT || !J.dz || !J.dots || !J.da_rows || !J.dw_rows || (a->requires_grad && !tn__grad(ctx, a)) ||
        (Wc->requires_grad && !tn__grad(ctx, Wc)))
        return;
    if ((V->requires_grad && !J.dV) || (U->requires_grad && !J.dU)) return;
    tn_parallel_for((size_t)g->ndst, 64, tn__gnn_att_bwd_dst, &J);
    if (J.dU) tn_parallel_for((size_t)g->nsrc, 64, tn__gnn_att_bwd_src, &J);
    for (d = 0; d < (size_t)g->ndst; d++) {
        if (a->requires_grad) tn__gnn_axpy(1.0f, J.da_rows + d * H, a->grad, H);
        if (Wc->requires_grad) /* dWc is H x F; the rows hold F x H */
            for (j = 0; j < TN__GNN_F; j++)
                for (i = 0; i < H; i++) Wc->grad[(size_t)i * TN__GNN_F + j] += J.dw_rows[(d * TN__GNN_F + j) * H + i];
    }
}

static tn_tensor *tn__gnn_attend(tn_ctx *ctx, tn_tensor *U, tn_tensor *V, tn_tensor *Wc, tn_tensor *a, const tn__gnn_dir *g)
{
    tn__gnn_att J;
    tn_tensor *o;
    int shape[2], H, E;
    void *aux;
    if (!U || !V || !Wc || !a) return NULL;
    H = U->shape[1];
    TN_ASSERT(H <= TN__GNN_MAXH && V->shape[1] == H && U->shape[0] == g->nsrc && V->shape[0] == g->ndst);
    TN_ASSERT(Wc->shape[0] == H && Wc->shape[1] == TN__GNN_F && (int)a->numel == H);
    E = g->E;
    shape[0] = g->ndst;
    shape[1] = H;
    /* a is a parameter of the same set as Wc: it needs a gradient only when Wc does */
    o = tn__op_make(ctx, 2, shape, tn__gnn_attend_backward, U, V, Wc, 0);
    if (!o) return NULL;
    o->src[3] = a;
    memset(&J, 0, sizeof J);
    J.g = g;
    J.H = H;
    J.U = U->data;
    J.V = V->data;
    J.WcT = tn__gnn_transpose_wc(ctx, Wc);
    J.a = a->data;
    J.Y = o->data;
    if (!J.WcT) return NULL;
    if (o->backward) { /* the backward needs the directions and the attention weights */
        aux = tn_ctx_alloc(ctx, sizeof(tn__gnn_dir) + sizeof(float *));
        J.alpha = tn__ctx_floats(ctx, (size_t)(E > 0 ? E : 1), 0);
        if (!aux || !J.alpha) return NULL;
        memcpy(aux, g, sizeof *g);
        memcpy((char *)aux + sizeof(tn__gnn_dir), &J.alpha, sizeof(float *));
        o->aux = aux;
    }
    tn_parallel_for((size_t)g->ndst, 64, tn__gnn_att_fwd, &J);
    return o;
}

/* Mean aggregation: Y[d] = mean of X[src_e] over d's edges (0 without edges). */
typedef struct tn__gnn_mean_job {
    const tn__gnn_dir *g;
    const float *X, *dY;
    float *Y, *dX;
    int H;
} tn__gnn_mean_job;

static void tn__gnn_mean_fwd(void *vj, size_t b, size_t end)
{
    const tn__gnn_mean_job *J = (const tn__gnn_mean_job *)vj;
    size_t d;
    int i;
    for (d = b; d < end; d++) {
        int k0 = J->g->dst_start[d], k1 = J->g->dst_start[d + 1], k;
        float *y = J->Y + d * J->H, inv = k1 > k0 ? 1.0f / (float)(k1 - k0) : 0.0f;
        for (i = 0; i < J->H; i++) y[i] = 0;
        for (k = k0; k < k1; k++) tn__gnn_add_scaled(1.0f, J->X + (size_t)J->g->src_of[k] * J->H, y, J->H);
        for (i = 0; i < J->H; i++) y[i] *= inv;
    }
}

static void tn__gnn_mean_bwd(void *vj, size_t b, size_t end)
{
    const tn__gnn_mean_job *J = (const tn__gnn_mean_job *)vj;
    size_t s;
    for (s = b; s < end; s++) {
        int k;
        float *dx = J->dX + s * J->H;
        for (k = J->g->src_start[s]; k < J->g->src_start[s + 1]; k++) {
            int d = J->g->dst_of[J->g->src_pos[k]];
            float inv = 1.0f / (float)(J->g->dst_start[d + 1] - J->g->dst_start[d]);
            tn__gnn_add_scaled(inv, J->dY + (size_t)d * J->H, dx, J->H);
        }
    }
}

static void tn__gnn_mean_backward(tn_ctx *ctx, tn_tensor *out)
{
    tn_tensor *x = out->src[0];
    tn__gnn_mean_job J;
    memset(&J, 0, sizeof J);
    J.g = (const tn__gnn_dir *)out->aux;
    J.H = out->shape[1];
    J.dY = out->grad;
    if (!(J.dX = tn__grad(ctx, x))) return;
    tn_parallel_for((size_t)J.g->nsrc, 64, tn__gnn_mean_bwd, &J);
}

static tn_tensor *tn__gnn_mean(tn_ctx *ctx, tn_tensor *x, const tn__gnn_dir *g)
{
    tn__gnn_mean_job J;
    tn_tensor *o;
    int shape[2];
    if (!x) return NULL;
    TN_ASSERT(x->ndim == 2 && x->shape[0] == g->nsrc);
    shape[0] = g->ndst;
    shape[1] = x->shape[1];
    o = tn__op_make(ctx, 2, shape, tn__gnn_mean_backward, x, NULL, NULL, 0);
    if (!o) return NULL;
    if (o->backward) {
        void *aux = tn_ctx_alloc(ctx, sizeof *g);
        if (!aux) return NULL;
        memcpy(aux, g, sizeof *g);
        o->aux = aux;
    }
    memset(&J, 0, sizeof J);
    J.g = g;
    J.X = x->data;
    J.Y = o->data;
    J.H = x->shape[1];
    tn_parallel_for((size_t)g->ndst, 64, tn__gnn_mean_fwd, &J);
    return o;
}

/* ---- the network ---- */

typedef struct tn__gnn_arch {
    int hidden, rounds, k, embed, membrane, parts, width, height, npts;
    int overhang;              /* parts without an embedding: feature 0 = tn__gnn_overhang */
    float mean, std, lo, hi, part_noise, radius;
} tn__gnn_arch;

static tn_status tn__gnn_linear_add(tn_params *p, const char *name, int in, int out, tn_rng *rng)
{
    int w[2];
    w[0] = in;
    w[1] = out;
    return tn_mlp_add(p, name, w, 1, rng);
}

/* Every learned tensor of the network (not the embeddings). */
static tn_status tn__gnn_add_net(tn_params *p, const tn__gnn_arch *A, tn_rng *rng)
{
    int H = A->hidden, D = A->embed, t, wi[3], wc[2];
    char name[40];
    tn_status st;
    tn_tensor *x;
    wi[0] = 2; wi[1] = H; wi[2] = H;
    if ((st = tn_mlp_add(p, "gnn.init.", wi, 2, rng))) return st;
    wc[0] = H;
    wc[1] = TN__GNN_F;
    for (t = 0; t < A->rounds; t++) {
        int side;
        for (side = 0; side < 2; side++) {
            char c = side ? 's' : 'g';
            /* u: the sender's row, v: the receiver's; gather senders are pixels [f, mean E],
               receivers parts [E, sign, emb]; scatter senders are parts [E, sign, emb, mean f],
               receivers pixels [f] */
            snprintf(name, sizeof name, "gnn.%d%c.u.", t, c);
            if ((st = tn__gnn_linear_add(p, name, side ? 2 * H + 1 + D : 2 * H, H, rng))) return st;
            snprintf(name, sizeof name, "gnn.%d%c.v.", t, c);
            if ((st = tn__gnn_linear_add(p, name, side ? H : H + 1 + D, H, rng))) return st;
            snprintf(name, sizeof name, "gnn.%d%c.cw", t, c);
            if (!(x = tn_params_add(p, name, 2, wc))) return TN_ERR_OUT_OF_MEMORY;
            if (rng) tn_init_kaiming(x, rng, 1.41f);
            snprintf(name, sizeof name, "gnn.%d%c.a", t, c);
            if (!(x = tn_params_add(p, name, 1, &H))) return TN_ERR_OUT_OF_MEMORY;
            if (rng) tn_init_normal(x, rng, 0.0f, 0.1f);
            snprintf(name, sizeof name, "gnn.%d%c.o.", t, c);
            if ((st = tn__gnn_linear_add(p, name, H, H, rng))) return st;
            /* residual branches start small so the first steps do not scramble the states */
            snprintf(name, sizeof name, "gnn.%d%c.o.w0", t, c);
            if (rng && (x = tn_params_find(p, name))) {
                size_t i;
                for (i = 0; i < x->numel; i++) x->data[i] *= 0.3f;
            }
        }
    }
    wi[0] = H; wi[1] = H; wi[2] = 1;
    if ((st = tn_mlp_add(p, "gnn.out.", wi, 2, rng))) return st;
    if (rng && (x = tn_params_find(p, "gnn.out.w1"))) { /* start at the baseline */
        size_t i;
        for (i = 0; i < x->numel; i++) x->data[i] *= 0.1f;
    }
    return TN_OK;
}

static tn_tensor *tn__gnn_param(const tn_params *p, const char *fmt, int t, char c)
{
    char name[40];
    snprintf(name, sizeof name, fmt, t, c);
    return tn_params_find(p, name);
}

static tn_tensor *tn__gnn_lin(tn_ctx *ctx, const tn_params *p, int t, char c, const char *which, tn_tensor *x)
{
    char name[40];
    snprintf(name, sizeof name, "gnn.%d%c.%s.", t, c, which);
    return tn_mlp(ctx, p, name, 1, x, TN_ACT_NONE);
}

/* Inputs of one forward pass. */
typedef struct tn__gnn_in {
    const tn__gnn_graph *g;
    tn_tensor *pix_in;    /* npix x 2: type, baseline height */
    tn_tensor *part_in;   /* nparts x (1 + D): sign, embedding */
    tn_tensor *E0;        /* nparts x H */
    tn_tensor *base;      /* npix x 1 baseline (zeros without membrane) */
} tn__gnn_in;

/* Round t of gather (pixels -> parts) and scatter (parts -> pixels): *f (npix x H) and *E
   (nparts x H) updated, NULL on failure. */
static void tn__gnn_round(tn_ctx *ctx, const tn_params *w, int t, const tn__gnn_in *in, tn_tensor **fp, tn_tensor **Ep)
{
    const tn__gnn_graph *g = in->g;
    tn_tensor *f = *fp, *E = *Ep, *pn, *U, *V, *Y;
    /* gather: pixels -> parts */
    U = tn__gnn_lin(ctx, w, t, 'g', "u", tn_concat(ctx, f, tn__gnn_mean(ctx, E, &g->p2g), 1));
    pn = tn_concat(ctx, E, in->part_in, 1);
    V = tn__gnn_lin(ctx, w, t, 'g', "v", pn);
    Y = tn__gnn_attend(ctx, U, V, tn__gnn_param(w, "gnn.%d%c.cw", t, 'g'), tn__gnn_param(w, "gnn.%d%c.a", t, 'g'), &g->g2p);
    E = tn_add(ctx, E, tn__gnn_lin(ctx, w, t, 'g', "o", Y));
    /* scatter: parts -> pixels */
    pn = tn_concat(ctx, tn_concat(ctx, E, in->part_in, 1), tn__gnn_mean(ctx, f, &g->g2p), 1);
    U = tn__gnn_lin(ctx, w, t, 's', "u", pn);
    V = tn__gnn_lin(ctx, w, t, 's', "v", f);
    Y = tn__gnn_attend(ctx, U, V, tn__gnn_param(w, "gnn.%d%c.cw", t, 's'), tn__gnn_param(w, "gnn.%d%c.a", t, 's'), &g->p2g);
    *fp = tn_add(ctx, f, tn__gnn_lin(ctx, w, t, 's', "o", Y));
    *Ep = E;
}

/* The prediction (npix x 1, normalised heights). */
static tn_tensor *tn__gnn_forward(tn_ctx *ctx, const tn_params *w, const tn__gnn_arch *A, const tn__gnn_in *in)
{
    tn_tensor *f = tn_mlp(ctx, w, "gnn.init.", 2, in->pix_in, TN_ACT_RELU), *E = in->E0, *r;
    int t;
    for (t = 0; t < A->rounds && f && E; t++) tn__gnn_round(ctx, w, t, in, &f, &E);
    r = tn_mlp(ctx, w, "gnn.out.", 2, f, TN_ACT_RELU);
    return tn_add(ctx, r, in->base);
}

/* Node inputs shared by training and generation: pixel (type, baseline) rows, baseline column,
   part (sign, embedding) rows. emb: nparts x D. */
static tn_status tn__gnn_inputs(tn_ctx *ctx, const tn__gnn_graph *g, const float *type, const float *base, const float *level,
                                const float *sign, tn_tensor *emb, tn__gnn_in *in)
{
    tn_tensor *s;
    int i;
    memset(in, 0, sizeof *in);
    in->g = g;
    in->pix_in = tn_tensor_2d(ctx, g->npix, 2);
    in->base = tn_tensor_2d(ctx, g->npix, 1);
    s = tn_tensor_2d(ctx, g->nparts, 1);
    if (!in->pix_in || !in->base || !s) return tn_ctx_status(ctx);
    for (i = 0; i < g->npix; i++) {
        in->pix_in->data[2 * i] = type[i];
        in->pix_in->data[2 * i + 1] = base ? base[i] - (level ? level[i] : 0.0f) : 0.0f;
        in->base->data[i] = base ? base[i] : 0.0f;
    }
    for (i = 0; i < g->nparts; i++) s->data[i] = sign[i];
    in->part_in = tn_concat(ctx, s, emb, 1);
    return in->part_in ? TN_OK : tn_ctx_status(ctx);
}

/* ---- configuration tensor ---- */

static void tn__gnn_write_config(const tn__gnn_arch *A, float *c)
{
    memset(c, 0, TN__GNN_CONFIG * sizeof(float));
    c[0] = TN__GNN_FORMAT;
    c[1] = (float)A->hidden;
    c[2] = (float)A->rounds;
    c[3] = (float)A->k;
    c[4] = (float)A->embed;
    c[5] = (float)A->membrane;
    c[6] = (float)A->parts;
    c[7] = (float)A->width;
    c[8] = (float)A->height;
    c[9] = A->mean;
    c[10] = A->std;
    c[11] = A->lo;
    c[12] = A->hi;
    c[13] = A->part_noise;
    c[14] = (float)A->npts;
    c[15] = TN__GNN_F;
    c[16] = A->radius;
    c[17] = (float)A->overhang;
}

static int tn__gnn_whole(float v, float lo, float hi) { return v >= lo && v <= hi && v == floorf(v); }

/* Every field range-checked: a damaged file fails here, not in an allocation or an index. */
static tn_status tn__gnn_read_config(const float *c, tn__gnn_arch *A, const char *name)
{
    memset(A, 0, sizeof *A);
    if (!tn__gnn_whole(c[0], 1, 1e6) || c[0] > TN__GNN_FORMAT)
        return tn__fail(TN_ERR_FORMAT, "%s: gnn configuration format %g is not supported", name, (double)c[0]);
    if (!tn__gnn_whole(c[1], 1, TN__GNN_MAXH) || !tn__gnn_whole(c[2], 1, 16) || !tn__gnn_whole(c[3], 1, 64) ||
        !tn__gnn_whole(c[4], 1, 256) || !tn__gnn_whole(c[5], 0, 1) || !tn__gnn_whole(c[6], 1, 1 << 24) ||
        !tn__gnn_whole(c[7], 16, TN_SKETCH_MAX_SIDE) || !tn__gnn_whole(c[8], 16, TN_SKETCH_MAX_SIDE) || !isfinite(c[9]) ||
        !(c[10] > 0) || !isfinite(c[10]) || !isfinite(c[11]) || !isfinite(c[12]) || !(c[13] >= 0 && c[13] <= 100) ||
        !tn__gnn_whole(c[14], 5, 1 << 26) || c[15] != TN__GNN_F || !(c[16] >= 0 && c[16] <= 4096) ||
        !tn__gnn_whole(c[17], 0, 1))
        return tn__fail(TN_ERR_CORRUPT, "%s: damaged gnn configuration", name);
    if ((double)c[7] * c[8] * c[3] > TN__GNN_MAX_EDGES) /* training refuses such an example */
        return tn__fail(TN_ERR_CORRUPT, "%s: the gnn configuration's %g x %g example at k = %g needs more than %d graph edges", name, (double)c[7],
                        (double)c[8], (double)c[3], TN__GNN_MAX_EDGES);
    A->hidden = (int)c[1];
    A->rounds = (int)c[2];
    A->k = (int)c[3];
    A->embed = (int)c[4];
    A->membrane = (int)c[5];
    A->parts = (int)c[6];
    A->width = (int)c[7];
    A->height = (int)c[8];
    A->mean = c[9];
    A->std = c[10];
    A->lo = c[11];
    A->hi = c[12];
    A->part_noise = c[13];
    A->npts = (int)c[14];
    A->radius = c[16] > 0 ? c[16] : 24.0f; /* files written before the radius existed */
    A->overhang = (int)c[17];              /* 0 in files written before it existed */
    return TN_OK;
}

/* The model's tensors: config, parts (buffers), embeddings and the network. */
static tn_status tn__gnn_model_params(const tn__gnn_arch *A, tn_rng *rng, tn_params **out)
{
    tn_params *p = tn_params_create();
    int s[2], nc = TN__GNN_CONFIG;
    tn_tensor *t;
    tn_status st = TN_OK;
    *out = NULL;
    if (!p) return tn__fail(TN_ERR_OUT_OF_MEMORY, "gnn: out of memory");
    if (!(t = tn_params_add_buffer(p, "gnn.config", 1, &nc))) st = TN_ERR_OUT_OF_MEMORY;
    if (!st) tn__gnn_write_config(A, t->data);
    s[0] = A->npts;
    s[1] = 3;
    if (!st && !tn_params_add_buffer(p, "gnn.part_pts", 2, s)) st = TN_ERR_OUT_OF_MEMORY;
    s[0] = A->parts;
    s[1] = 4;
    if (!st && !tn_params_add_buffer(p, "gnn.part_info", 2, s)) st = TN_ERR_OUT_OF_MEMORY;
    s[1] = A->embed;
    if (!st && !(t = tn_params_add(p, "gnn.emb", 2, s))) st = TN_ERR_OUT_OF_MEMORY;
    if (!st && rng) tn_init_normal(t, rng, 0.0f, 1.0f);
    if (!st) st = tn__gnn_add_net(p, A, rng);
    if (st) {
        tn_params_free(p);
        return tn__fail(st, "gnn: cannot build the network (%s)", tn_status_string(st));
    }
    *out = p;
    return TN_OK;
}

/* Stored parts (example units) -> contour set. */
static tn_status tn__gnn_stored_parts(const tn_params *w, const tn__gnn_arch *A, const char *name, tn_contour_set *out)
{
    const tn_tensor *pts = tn_params_find(w, "gnn.part_pts"), *info = tn_params_find(w, "gnn.part_info");
    tn_contour_set set;
    int i, off = 0;
    memset(&set, 0, sizeof set);
    if (!pts || !info || (int)pts->numel != 3 * A->npts || (int)info->numel != 4 * A->parts)
        return tn__fail(TN_ERR_CORRUPT, "%s: gnn parts missing or of the wrong size", name);
    for (i = 0; i < A->parts; i++) {
        float ty = info->data[4 * i], np = info->data[4 * i + 1];
        if ((ty != 0 && ty != 1) || !tn__gnn_whole(np, 1, (float)(A->npts - off)) || !tn__gnn_whole(info->data[4 * i + 2], 0, 1000) ||
            !isfinite(info->data[4 * i + 3]))
            return tn__fail(TN_ERR_CORRUPT, "%s: gnn part %d is damaged", name, i);
        off += (int)np;
    }
    if (off != A->npts) return tn__fail(TN_ERR_CORRUPT, "%s: gnn parts hold %d points, the configuration says %d", name, off, A->npts);
    for (i = 0; i < 3 * A->npts; i++)
        if (!isfinite(pts->data[i]) || (i % 3 != 2 && fabsf(pts->data[i]) > (float)(2 * TN_SKETCH_MAX_SIDE)))
            return tn__fail(TN_ERR_CORRUPT, "%s: gnn part point %d is damaged", name, i / 3);
    set.width = A->width;
    set.height = A->height;
    set.count = A->parts;
    if (!(set.items = (tn_contour *)tn__calloc((size_t)A->parts * sizeof(tn_contour)))) return TN_ERR_OUT_OF_MEMORY;
    for (i = 0, off = 0; i < A->parts; i++) {
        tn_contour *c = &set.items[i];
        c->type = info->data[4 * i] == 1 ? TN_RIDGE : TN_VALLEY;
        c->npoints = (int)info->data[4 * i + 1];
        c->order = (int)info->data[4 * i + 2];
        c->mean_gradient = info->data[4 * i + 3];
        if (!(c->points = (float *)tn__alloc((size_t)c->npoints * 3 * sizeof(float)))) {
            tn_contour_set_free(&set);
            return TN_ERR_OUT_OF_MEMORY;
        }
        memcpy(c->points, pts->data + (size_t)off * 3, (size_t)c->npoints * 3 * sizeof(float));
        off += c->npoints;
    }
    *out = set;
    return TN_OK;
}

static void tn__gnn_store_parts(tn_params *w, const tn_contour_set *parts)
{
    float *pts = tn_params_find(w, "gnn.part_pts")->data, *info = tn_params_find(w, "gnn.part_info")->data;
    int i, off = 0;
    for (i = 0; i < parts->count; i++) {
        const tn_contour *c = &parts->items[i];
        info[4 * i] = c->type == TN_RIDGE ? 1.0f : 0.0f;
        info[4 * i + 1] = (float)c->npoints;
        info[4 * i + 2] = (float)c->order;
        info[4 * i + 3] = c->mean_gradient;
        memcpy(pts + (size_t)off * 3, c->points, (size_t)c->npoints * 3 * sizeof(float));
        off += c->npoints;
    }
}

static void tn__gnn_model_fields(tn_gnn *m, const tn__gnn_arch *A)
{
    m->hidden = A->hidden;
    m->rounds = A->rounds;
    m->k = A->k;
    m->radius = A->radius;
    m->embed = A->embed;
    m->membrane = A->membrane;
    m->parts = A->parts;
    m->width = A->width;
    m->height = A->height;
    m->mean = A->mean;
    m->std = A->std;
    m->lo = A->lo;
    m->hi = A->hi;
    m->part_noise = A->part_noise;
}

static tn_status tn__gnn_arch_of(const tn_gnn *m, tn__gnn_arch *A)
{
    const tn_tensor *c;
    if (!m || !m->weights || !(c = tn_params_find(m->weights, "gnn.config")) || c->numel != TN__GNN_CONFIG)
        return tn__fail(TN_ERR_INVALID_ARG, "gnn: no model");
    return tn__gnn_read_config(c->data, A, "gnn model");
}

/* ---- training ---- */

/* One sketch density of the example: its network's parts, pixel types, baseline and fixed
   edges. Level 0 is the example's own network (its parts own the embeddings); the sparser
   levels are the example's networks at higher extraction thresholds, trained without
   embeddings, so the network also learns to fill what a sparse sketch leaves out. */
typedef struct tn__gnn_level {
    tn__gnn_parts P;
    int *nbr;                  /* npix x k parts */
    float *nfeat;              /* their features */
    float *type, *base;        /* per pixel: +1 / -1 / 0, baseline (normalised) */
} tn__gnn_level;

typedef struct tn__gnn_train {
    tn__gnn_arch A;
    tn_gnn_opts o;
    tn_params *w;
    tn_optim *opt;
    tn_train *run;
    tn_rng rng;
    tn__gnn_level lv[TN__GNN_MAX_LEVELS];
    tn__gnn_level thinned;     /* this step's thinned sparse level */
    int nlevels, maxparts, npix;
    float *target;
    uint8_t *masked, *known;   /* per part: masked this step; keeps its embedding this step */
    tn__gnn_graph g;
    float range;               /* normalised height range (SSIM data range) */
    long phase_from;           /* first iteration of the embedding phase, -1 before it */
    float alone_ramp;          /* the phase for the example alone: how far its rate and SSIM weight have risen (0 .. 1) */
    tn_contour_set *hsk;       /* holdout i's sketches at [2 i] (the threshold) and [2 i + 1] (4 x) */
    tn_params *best;           /* holdouts given: the best check's weights and "holdout" = {mean SSIM,
                                  iteration (-1 = none yet), checks, last check's SSIM, its iteration,
                                  the embedding phase's first iteration (-1 = not begun)} */
} tn__gnn_train;

static void tn__gnn_level_free(tn__gnn_level *L)
{
    tn__gnn_parts_free(&L->P);
    TN_FREE(L->nbr);
    TN_FREE(L->nfeat);
    TN_FREE(L->type);
    TN_FREE(L->base);
    memset(L, 0, sizeof *L);
}

static void tn__gnn_train_free(tn__gnn_train *s)
{
    int i;
    tn_train_free(s->run);
    tn_optim_free(s->opt);
    tn_params_free(s->w);
    for (i = 0; i < TN__GNN_MAX_LEVELS; i++) tn__gnn_level_free(&s->lv[i]);
    tn__gnn_level_free(&s->thinned);
    TN_FREE(s->target);
    TN_FREE(s->masked);
    TN_FREE(s->known);
    tn__gnn_graph_free(&s->g);
    for (i = 0; s->hsk && i < 2 * s->o.holdout_count; i++) tn_contour_set_free(&s->hsk[i]);
    TN_FREE(s->hsk);
    tn_params_free(s->best);
}

/* A level from the example's polylines and their parts. */
static tn_status tn__gnn_level_make(const tn__gnn_arch *A, const tn_contour_set *lines, const tn_contour_set *parts, tn__gnn_level *L)
{
    size_t n = (size_t)A->width * A->height, i;
    float *hgt;
    tn_status st;
    memset(L, 0, sizeof *L);
    L->type = (float *)tn__alloc(n * sizeof(float));
    L->base = (float *)tn__alloc(n * sizeof(float));
    hgt = (float *)tn__alloc(n * sizeof(float));
    if (!L->type || !L->base || !hgt) {
        TN_FREE(hgt);
        return TN_ERR_OUT_OF_MEMORY;
    }
    st = tn__gnn_sketch_pixels(lines, A->width, A->height, L->type, hgt, L->base);
    TN_FREE(hgt);
    if (st) return st;
    for (i = 0; i < n; i++) L->base[i] = A->membrane ? (L->base[i] - A->mean) / A->std : 0.0f;
    if ((st = tn__gnn_parts_make(parts, A->mean, A->std, &L->P))) return st;
    return tn__gnn_knn(&L->P, A->width, A->height, 0, 0, A->k, A->radius, L->base, &L->nbr, &L->nfeat);
}

/* A random thinning of sparse level L into T: each part kept with probability 1 - q, q uniform
   in [0, thin); the sketch pixels are the kept parts' points, so the membrane and the nearest
   parts are rebuilt. */
static tn_status tn__gnn_level_thin(tn__gnn_train *s, const tn__gnn_level *L, tn__gnn_level *T)
{
    const tn__gnn_parts *P = &L->P;
    int W = s->A.width, H = s->A.height, i, j, n = 0, m = 0, kept = 0;
    float q = s->o.thin * tn_rng_uniform(&s->rng);
    size_t npix = (size_t)W * H;
    uint8_t *fixed;
    float *hgt;
    tn_status st = TN_OK;
    tn__gnn_level_free(T);
    for (i = 0; i < P->n; i++) {
        s->masked[i] = (uint8_t)(tn_rng_uniform(&s->rng) < q);
        kept += !s->masked[i];
    }
    if (!kept) s->masked[0] = 0;
    T->type = (float *)tn__calloc(npix * sizeof(float));
    T->base = (float *)tn__alloc(npix * sizeof(float));
    T->P.start = (int *)tn__alloc(((size_t)P->n + 1) * sizeof(int));
    T->P.of = (int *)tn__alloc(((size_t)P->npts + 1) * sizeof(int));
    T->P.pts = (float *)tn__alloc(((size_t)P->npts + 1) * 3 * sizeof(float));
    T->P.sign = (float *)tn__alloc(((size_t)P->n + 1) * sizeof(float));
    fixed = (uint8_t *)tn__calloc(npix);
    hgt = (float *)tn__calloc(npix * sizeof(float));
    if (!T->type || !T->base || !T->P.start || !T->P.of || !T->P.pts || !T->P.sign || !fixed || !hgt) st = TN_ERR_OUT_OF_MEMORY;
    for (i = 0; !st && i < P->n; i++) {
        if (s->masked[i]) continue;
        T->P.start[n] = m;
        T->P.sign[n] = P->sign[i];
        for (j = P->start[i]; j < P->start[i + 1]; j++, m++) {
            int x = (int)floorf(P->pts[3 * j] + 0.5f), y = (int)floorf(P->pts[3 * j + 1] + 0.5f);
            memcpy(T->P.pts + 3 * (size_t)m, P->pts + 3 * (size_t)j, 3 * sizeof(float));
            T->P.of[m] = n;
            if (x < 0 || y < 0 || x >= W || y >= H) continue;
            fixed[(size_t)y * W + x] = 1;
            T->type[(size_t)y * W + x] = P->sign[i];
            hgt[(size_t)y * W + x] = P->pts[3 * j + 2];
        }
        n++;
    }
    if (!st) {
        T->P.n = n;
        T->P.npts = m;
        T->P.start[n] = m;
        if (s->A.membrane) st = tn__gnn_membrane_rect(hgt, fixed, W, H, 0, 0, W, H, T->base);
        else memset(T->base, 0, npix * sizeof(float));
    }
    if (!st) st = tn__gnn_knn(&T->P, W, H, 0, 0, s->A.k, s->A.radius, T->base, &T->nbr, &T->nfeat);
    TN_FREE(fixed);
    TN_FREE(hgt);
    return st;
}

/* This step's graph on level L: the fixed edges of unmasked parts, then random pixel-part
   edges, then the noise feature (finished by the caller, once it knows which parts keep their
   embedding). whole: every part, no random edges (the graph generation uses). */
static void tn__gnn_step_graph(tn__gnn_train *s, const tn__gnn_level *L, int whole)
{
    tn__gnn_graph *g = &s->g;
    int p, j, i, k = s->A.k, nparts = L->P.n, nm = 0, nrand = s->o.random_edges > 0 && !whole ? s->o.random_edges : 0;
    float mask = s->o.mask > 0 && !whole ? s->o.mask : 0.0f, noise = s->o.edge_noise > 0 ? s->o.edge_noise : 0.0f;
    for (i = 0; i < nparts; i++) {
        s->masked[i] = (uint8_t)(mask > 0 && tn_rng_uniform(&s->rng) < mask);
        nm += s->masked[i];
    }
    if (nm == nparts) memset(s->masked, 0, (size_t)nparts); /* keep something to learn from */
    g->nparts = nparts;
    g->E = 0;
    for (p = 0; p < s->npix; p++)
        for (j = 0; j < k; j++) {
            int r = L->nbr[(size_t)p * k + j];
            if (r < 0 || s->masked[r]) continue;
            g->e_pix[g->E] = p;
            g->e_part[g->E] = r;
            memcpy(g->feat + (size_t)g->E * TN__GNN_F, L->nfeat + ((size_t)p * k + j) * TN__GNN_F, TN__GNN_F * sizeof(float));
            g->E++;
        }
    for (i = 0; i < nrand; i++) {
        int pix = (int)tn_rng_below(&s->rng, (uint32_t)s->npix), r = (int)tn_rng_below(&s->rng, (uint32_t)nparts), jj;
        float d2;
        if (s->masked[r]) continue;
        jj = tn__gnn_project(&L->P, r, (float)(pix % s->A.width), (float)(pix / s->A.width), &d2);
        g->e_pix[g->E] = pix;
        g->e_part[g->E] = r;
        tn__gnn_edge_features(&L->P, r, jj, d2, L->base[pix], g->feat + (size_t)g->E * TN__GNN_F);
        g->E++;
    }
    if (noise > 0)
        for (i = 0; i < g->E; i++) g->feat[(size_t)i * TN__GNN_F + 4] = noise * tn_rng_normal(&s->rng);
}

static tn_tensor *tn__gnn_part_states(tn_ctx *ctx, const tn__gnn_arch *A, int nparts, tn_rng *rng)
{
    tn_tensor *E0 = tn_tensor_2d(ctx, nparts, A->hidden);
    size_t i;
    if (E0 && A->part_noise > 0)
        for (i = 0; i < E0->numel; i++) E0->data[i] = A->part_noise * tn_rng_normal(rng);
    return E0;
}

#define TN__GNN_SAMPLES 4096 /* pixels (pairs) a step's sketch, smooth and further terms look at */
#define TN__GNN_ALONE_RATE 4.0f  /* the phase for the example alone: rate and SSIM weight factors */
#define TN__GNN_ALONE_SSIM 10.0f /* (chosen on the Sahara, the hardest to rebuild: docs/gnn.md) */
#define TN__GNN_ALONE_RAMP 100.0f /* iterations over which both rise from 1 x: a jump let Adam, whose second
                                     moments lag, take steps that left Grand Canyon's network dead (docs/gnn.md) */
#define TN__GNN_TAU 0.05f    /* sketch-loss temperature, in normalised height units */

/* 6.1's sketch term: pixels 1-4 px from a part and not on a line lie below a ridge's (above a
   valley's) height at their projection. For a pair of logits the Gumbel-softmax's cross-entropy
   is softplus(-z), z = sign (h_proj - y) / tau + logistic noise: a BCE on z. NULL if nothing
   was sampled. */
static tn_tensor *tn__gnn_sketch_loss(tn__gnn_train *s, tn_ctx *ctx, const tn__gnn_level *L, tn_tensor *y, int *idx, tn_tensor *a, tn_tensor *b)
{
    const tn__gnn_graph *g = &s->g;
    int n = 0, tries;
    tn_tensor *one;
    for (tries = 0; g->E > 0 && tries < 4 * TN__GNN_SAMPLES && n < TN__GNN_SAMPLES; tries++) {
        int e = (int)tn_rng_below(&s->rng, (uint32_t)g->E);
        const float *f = g->feat + (size_t)e * TN__GNN_F;
        float d = f[1] * TN__GNN_DIST, sg = L->P.sign[g->e_part[e]], u;
        if (d < 0.7f || d > 4.0f || L->type[g->e_pix[e]] != 0) continue; /* a line pixel would be pushed off its own line */
        u = 1e-6f + 0.999998f * tn_rng_uniform(&s->rng);
        idx[n] = g->e_pix[e];
        a->data[n] = -sg / TN__GNN_TAU;
        b->data[n] = sg * (f[3] + L->base[g->e_pix[e]]) / TN__GNN_TAU + logf(u / (1.0f - u));
        n++;
    }
    if (!n || !(one = tn_tensor_2d(ctx, n, 1))) return NULL;
    tn_tensor_fill(one, 1.0f);
    return tn_bce_logits_loss(ctx, tn_add(ctx, tn_mul(ctx, tn_gather_rows(ctx, y, idx, n), tn_slice(ctx, a, 0, 0, n)), tn_slice(ctx, b, 0, 0, n)),
                              one);
}

/* 6.1's smoothness: mean |y_p - y_q| over random pixel pairs under 5 px apart (Manhattan). */
static tn_tensor *tn__gnn_smooth_loss(tn__gnn_train *s, tn_ctx *ctx, tn_tensor *y, int *idx)
{
    int n = 0, W = s->A.width, H = s->A.height, cap = TN__GNN_SAMPLES;
    while (n < cap) {
        int x = (int)tn_rng_below(&s->rng, (uint32_t)W), yy = (int)tn_rng_below(&s->rng, (uint32_t)H);
        int dx = (int)tn_rng_below(&s->rng, 9) - 4, dy = (int)tn_rng_below(&s->rng, 9) - 4;
        if (abs(dx) + abs(dy) >= 5 || (!dx && !dy) || x + dx < 0 || x + dx >= W || yy + dy < 0 || yy + dy >= H) continue;
        idx[n] = yy * W + x;
        idx[cap + n] = (yy + dy) * W + x + dx;
        n++;
    }
    return tn_mean(ctx, tn_abs(ctx, tn_sub(ctx, tn_gather_rows(ctx, y, idx, cap), tn_gather_rows(ctx, y, idx + cap, cap))));
}

/* 6.1's distance term as read here: a pixel 1-6 px from its nearest part keeps near the part's
   height there, weighted 1 / (10 d^2) (weights normalised to sum 1). NULL if nothing sampled. */
static tn_tensor *tn__gnn_further_loss(tn__gnn_train *s, tn_ctx *ctx, const tn__gnn_level *L, tn_tensor *y, int *idx, tn_tensor *a, tn_tensor *b)
{
    int n = 0, tries, k = s->A.k;
    double wsum = 0;
    for (tries = 0; tries < 4 * TN__GNN_SAMPLES && n < TN__GNN_SAMPLES; tries++) {
        int p = (int)tn_rng_below(&s->rng, (uint32_t)s->npix), j;
        float bd = FLT_MAX, bh = 0;
        for (j = 0; j < k; j++) {
            const float *f = L->nfeat + ((size_t)p * k + j) * TN__GNN_F;
            if (L->nbr[(size_t)p * k + j] >= 0 && f[1] * TN__GNN_DIST < bd) {
                bd = f[1] * TN__GNN_DIST;
                bh = f[3] + L->base[p];
            }
        }
        if (bd < 0.7f || bd > 6.0f) continue;
        idx[n] = p;
        b->data[n] = bh;
        a->data[n] = 1.0f / (10.0f * bd * bd);
        wsum += a->data[n++];
    }
    if (!n) return NULL;
    return tn_scale_shift(ctx, tn_sum(ctx, tn_mul(ctx, tn_square(ctx, tn_sub(ctx, tn_gather_rows(ctx, y, idx, n), tn_slice(ctx, b, 0, 0, n))),
                                                 tn_slice(ctx, a, 0, 0, n))), (float)(1.0 / wsum), 0.0f);
}

/* The weighted sketch, smooth and further terms on this step's prediction y (npix x 1) over
   level L, added to *loss (zero weights cost nothing). */
static tn_status tn__gnn_shape_losses(tn__gnn_train *s, tn_ctx *ctx, const tn__gnn_level *L, tn_tensor *y, tn_tensor **loss)
{
    int *idx = (int *)tn_ctx_alloc(ctx, 2 * (size_t)TN__GNN_SAMPLES * sizeof(int));
    tn_tensor *a = tn_tensor_2d(ctx, TN__GNN_SAMPLES, 1), *b = tn_tensor_2d(ctx, TN__GNN_SAMPLES, 1), *t;
    if (!idx || !a || !b) return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : TN_ERR_OUT_OF_MEMORY;
    if (s->o.sketch_weight > 0 && (t = tn__gnn_sketch_loss(s, ctx, L, y, idx, a, b)))
        *loss = tn_add(ctx, *loss, tn_scale_shift(ctx, t, s->o.sketch_weight, 0.0f));
    if (s->o.smooth_weight > 0 && (t = tn__gnn_smooth_loss(s, ctx, y, idx)))
        *loss = tn_add(ctx, *loss, tn_scale_shift(ctx, t, s->o.smooth_weight, 0.0f));
    if (s->o.further_weight > 0 && (t = tn__gnn_further_loss(s, ctx, L, y, idx, a, b)))
        *loss = tn_add(ctx, *loss, tn_scale_shift(ctx, t, s->o.further_weight, 0.0f));
    return *loss ? TN_OK : tn_ctx_status(ctx);
}

/* One step; the unweighted loss terms go to l[0..2], the total to l[3]. phase: 0 = a training
   step; 1 = the embedding phase's (the example's own network, every embedding); 2 = the same on
   the whole graph (no masked parts, no random edges: the example alone). */
static tn_status tn__gnn_step(tn__gnn_train *s, tn_ctx *ctx, int phase, float *l)
{
    tn__gnn_in in;
    tn_tensor *pred, *tgt, *loss = NULL, *t, *emb;
    int shape[2], lev = 0, i;
    const tn__gnn_level *L;
    tn_status st;
    tn_ctx_reset(ctx);
    /* half the steps on the example's own network, half on a sparser one */
    if (s->nlevels > 1 && tn_rng_uniform(&s->rng) >= 0.5f) lev = 1 + (int)tn_rng_below(&s->rng, (uint32_t)(s->nlevels - 1));
    if (phase) lev = 0;
    L = &s->lv[lev];
    if (lev > 0 && s->o.thin > 0) {
        if ((st = tn__gnn_level_thin(s, L, &s->thinned))) return st;
        L = &s->thinned;
    }
    tn__gnn_step_graph(s, L, phase == 2);
    shape[0] = L->P.n;
    shape[1] = s->A.embed;
    if (lev == 0) { /* embedding dropout: a dropped part is seen as a part of an unknown sketch */
        tn_tensor *keep = tn_tensor_2d(ctx, L->P.n, 1);
        float drop = s->o.embed_drop > 0 && !phase ? s->o.embed_drop : 0.0f;
        if (!keep) return tn_ctx_status(ctx);
        for (i = 0; i < L->P.n; i++) {
            keep->data[i] = drop > 0 && tn_rng_uniform(&s->rng) < drop ? 0.0f : 1.0f;
            s->known[i] = keep->data[i] != 0;
        }
        emb = tn_mul(ctx, tn_params_find(s->w, "gnn.emb"), keep);
    } else
        emb = tn_tensor_new(ctx, 2, shape);
    if (s->A.overhang) tn__gnn_overhangs(&s->g, &L->P, lev == 0 ? s->known : NULL, NULL, s->A.width, 0, 0);
    tn__gnn_graph_finish(&s->g);
    if ((st = tn__gnn_inputs(ctx, &s->g, L->type, s->A.membrane ? L->base : NULL, NULL, L->P.sign, emb, &in))) return st;
    in.E0 = tn__gnn_part_states(ctx, &s->A, L->P.n, &s->rng);
    {
        int s4[4];
        s4[0] = s4[1] = 1;
        s4[2] = s->A.height;
        s4[3] = s->A.width;
        pred = tn_reshape(ctx, tn__gnn_forward(ctx, s->w, &s->A, &in), 4, s4);
    }
    tgt = tn_tensor_4d(ctx, 1, 1, s->A.height, s->A.width);
    if (!pred || !tgt) return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : TN_ERR_OUT_OF_MEMORY;
    memcpy(tgt->data, s->target, (size_t)s->npix * sizeof(float));
    l[0] = l[1] = l[2] = 0;
    if (s->o.mse_weight > 0 && (t = tn_mse_loss(ctx, pred, tgt))) {
        l[0] = t->data[0];
        loss = tn_scale_shift(ctx, t, s->o.mse_weight, 0.0f);
    }
    if (s->o.ssim_weight > 0 && (t = tn_ssim_loss(ctx, pred, tgt, s->range))) {
        l[1] = t->data[0];
        t = tn_scale_shift(ctx, t, s->o.ssim_weight * (phase == 2 ? 1.0f + (TN__GNN_ALONE_SSIM - 1.0f) * s->alone_ramp : 1.0f), 0.0f);
        loss = loss ? tn_add(ctx, loss, t) : t;
    }
    if (s->o.grad_weight > 0 && (t = tn_gdl_loss(ctx, pred, tgt))) {
        l[2] = t->data[0];
        t = tn_scale_shift(ctx, t, s->o.grad_weight, 0.0f);
        loss = loss ? tn_add(ctx, loss, t) : t;
    }
    if (!loss) return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : tn__fail(TN_ERR_INVALID_ARG, "gnn: every loss term is off");
    if (s->o.sketch_weight > 0 || s->o.smooth_weight > 0 || s->o.further_weight > 0) {
        int s2[2];
        s2[0] = s->npix;
        s2[1] = 1;
        if ((st = tn__gnn_shape_losses(s, ctx, L, tn_reshape(ctx, pred, 2, s2), &loss))) return st;
    }
    l[3] = loss->data[0];
    if (!isfinite(l[3])) return tn__fail(TN_ERR_NUMERIC, "gnn: the loss diverged at iteration %ld (lower the learning rate)", tn_train_iteration(s->run));
    tn_params_zero_grad(s->w);
    if ((st = tn_backward(ctx, loss))) return st;
    tn_optim_step(s->opt);
    return TN_OK;
}

/* what: "the DEM" or a holdout's name, for the messages */
static tn_status tn__gnn_check_dem(const tn_image *dem, const char *what, float *lo, float *hi, double *mean, double *std)
{
    size_t i, n;
    double s = 0, s2 = 0;
    if (!dem) return tn__fail(TN_ERR_INVALID_ARG, "gnn: no %s", what);
    if (!dem->data || dem->width <= 0 || dem->height <= 0 || dem->channels <= 0) return tn__fail(TN_ERR_EMPTY, "gnn: %s is empty", what);
    if (dem->width < 16 || dem->height < 16)
        return tn__fail(TN_ERR_INVALID_ARG, "gnn: %s is %d x %d; at least 16 x 16 is needed", what, dem->width, dem->height);
    if ((size_t)dem->width * dem->height > ((size_t)1 << 24))
        return tn__fail(TN_ERR_TOO_LARGE, "gnn: %s is %d x %d; train on a crop of at most 16 M pixels", what, dem->width, dem->height);
    n = (size_t)dem->width * dem->height;
    *lo = FLT_MAX;
    *hi = -FLT_MAX;
    for (i = 0; i < n; i++) {
        float v = dem->data[i * dem->channels];
        if (!isfinite(v)) return tn__fail(TN_ERR_NUMERIC, "gnn: %s has a NaN/Inf height at pixel (%d, %d)", what, (int)(i % dem->width), (int)(i / dem->width));
        if (v < *lo) *lo = v;
        if (v > *hi) *hi = v;
        s += v;
        s2 += (double)v * v;
    }
    *mean = s / (double)n;
    *std = sqrt(fmax(s2 / (double)n - *mean * *mean, 0.0));
    if (!(*hi > *lo)) return tn__fail(TN_ERR_EMPTY, "gnn: %s is flat (no ridges or valleys)", what);
    return TN_OK;
}

/* ---- holdout checks (early stopping) ---- */

/* The scale of the held-out lines' gain estimate, calibrated on the holdouts in training
   (tn__gnn_gain_calibrate, "gain.scale"); 1 for a model without one. Scales run 0 .. 2 in steps of 0.05. */
#define TN__GNN_GAIN_SCALES 41
static double tn__gnn_gain_scale(const tn_params *w)
{
    const tn_tensor *t = tn_params_find(w, "gain.scale");
    return t ? t->data[0] : 1.0;
}

/* The residual gain of a tested sketch: its raw estimate times the scale, within [0, 1]. */
static float tn__gnn_gain_of(double scale, double raw)
{
    return tn__clampf((float)(scale * raw), 0.0f, 1.0f);
}

/* The holdouts' networks at the example's extraction threshold and 4 x it (the first sparse
   level's), and the best-weights set, a copy of every tensor of s->w. */
static tn_status tn__gnn_holdout_make(tn__gnn_train *s)
{
    int i, d, n = s->o.holdout_count, base = s->o.extract.threshold > 0 ? s->o.extract.threshold : tn_extract_default_threshold(s->A.width, s->A.height);
    tn_tensor *info;
    tn_status st;
    if (n <= 0) return TN_OK;
    if (!(s->hsk = (tn_contour_set *)tn__alloc(2 * (size_t)n * sizeof *s->hsk))) return TN_ERR_OUT_OF_MEMORY;
    memset(s->hsk, 0, 2 * (size_t)n * sizeof *s->hsk);
    for (i = 0; i < n; i++) {
        const tn_image *h = &s->o.holdout[i];
        float lo, hi;
        double mean, std;
        char what[32];
        if (h->data && h->channels != 1) return tn__fail(TN_ERR_INVALID_ARG, "gnn: holdout %d has %d channels (one: heights)", i, h->channels);
        snprintf(what, sizeof what, "holdout %d", i);
        st = tn__gnn_check_dem(h, what, &lo, &hi, &mean, &std);
        if (st == TN_ERR_EMPTY && h->data && h->width > 0 && h->height > 0) continue; /* flat: no sketch to check on */
        if (st) return st;
        for (d = 0; d < 2; d++) {
            tn_extract_opts eo = s->o.extract;
            tn_extraction ex;
            eo.threshold = base * (d ? 4 : 1);
            if ((st = tn_extract(&ex, h, &eo))) return st;
            s->hsk[2 * i + d] = ex.contours;
            memset(&ex.contours, 0, sizeof ex.contours);
            tn_extraction_free(&ex);
        }
    }
    if (!(s->best = tn_params_create())) return TN_ERR_OUT_OF_MEMORY;
    for (i = 0; i < tn_params_count(s->w); i++) {
        const tn_tensor *t = tn_params_get(s->w, i);
        if (!tn_params_add_buffer(s->best, t->name, t->ndim, t->shape)) return TN_ERR_OUT_OF_MEMORY;
    }
    d = 6;
    if (!(info = tn_params_add_buffer(s->best, "holdout", 1, &d))) return TN_ERR_OUT_OF_MEMORY;
    info->data[1] = info->data[4] = info->data[5] = -1.0f;
    return TN_OK;
}

/* Rebuilds the holdouts from their sketches with the network as it is (no embeddings, the
   residual as trained) and keeps its weights when the mean SSIM is the best so far. */
static tn_status tn__gnn_holdout_check(tn__gnn_train *s)
{
    tn_tensor *info = tn_params_find(s->best, "holdout");
    tn_gnn m;
    tn_gnn_generate_opts go;
    double sum = 0;
    int i, n = 0;
    tn_status st;
    memset(&m, 0, sizeof m);
    tn__gnn_model_fields(&m, &s->A);
    m.weights = s->w;
    memset(&go, 0, sizeof go);
    go.embeddings = TN_GNN_EMBED_NONE;
    go.gain = 1.0f;
    for (i = 0; i < 2 * s->o.holdout_count; i++) {
        const tn_image *h = &s->o.holdout[i / 2];
        tn_image out = {0, 0, 0, NULL};
        tn_metrics mt;
        if (!s->hsk[i].count) continue;
        st = tn_gnn_generate(&out, &m, &s->hsk[i], h->width, h->height, &go);
        if (st == TN_ERR_EMPTY) continue; /* no part of 5 px */
        if (!st) st = tn_compare(&mt, h, &out, 0);
        tn_image_free(&out);
        if (st) return st;
        sum += mt.ssim;
        n++;
    }
    info->data[4] = (float)tn_train_iteration(s->run);
    if (!n) return TN_OK;
    info->data[2] += 1.0f;
    info->data[3] = (float)(sum / n);
    if (info->data[1] < 0 || info->data[3] > info->data[0]) {
        for (i = 0; i < tn_params_count(s->w); i++) {
            const tn_tensor *t = tn_params_get(s->w, i);
            memcpy(tn_params_find(s->best, t->name)->data, t->data, t->numel * sizeof(float));
        }
        info->data[0] = info->data[3];
        info->data[1] = (float)tn_train_iteration(s->run);
    }
    return TN_OK;
}

/* The early network: an "early.<name>" buffer beside every learned tensor of w (the network
   and the embeddings). */
static tn_status tn__gnn_early_add(tn_params *w)
{
    int i, n = tn_params_count(w);
    for (i = 0; i < n; i++) {
        const tn_tensor *t = tn_params_get(w, i);
        char name[48];
        if (!t->requires_grad) continue;
        snprintf(name, sizeof name, "early.%s", t->name);
        if (!tn_params_add_buffer(w, name, t->ndim, t->shape)) return TN_ERR_OUT_OF_MEMORY;
    }
    return TN_OK;
}

/* The run's end: a check of the network unless it had one (at the embedding phase's start or at
   this iteration); the best check's weights become the model's early network, unless that
   check was of the final network (the run's end, or the phase's start when the phase freezes
   the network). */
static tn_status tn__gnn_holdout_end(tn__gnn_train *s)
{
    tn_tensor *info;
    long it = tn_train_iteration(s->run), final_it;
    int i;
    tn_status st;
    if (!s->best) return TN_OK;
    info = tn_params_find(s->best, "holdout");
    final_it = info->data[5] < 0 ? it : s->o.phase_network < 0 ? (long)info->data[5] : -1;
    if (info->data[5] < 0 && info->data[4] != (float)it && (st = tn__gnn_holdout_check(s))) return st;
    if (info->data[1] < 0 || (long)info->data[1] == final_it) return TN_OK;
    if ((st = tn__gnn_early_add(s->w))) return st;
    for (i = 0; i < tn_params_count(s->w); i++) {
        tn_tensor *t = tn_params_get(s->w, i);
        if (!strncmp(t->name, "early.", 6)) memcpy(t->data, tn_params_find(s->best, t->name + 6)->data, t->numel * sizeof(float));
    }
    return TN_OK;
}

/* One iteration; in the embedding phase every tensor but the embeddings is frozen (no gradient,
   so the optimiser leaves it and its moments alone) and the embeddings move at 5 x the rate,
   unless an early network serves other terrain (phase_network, and a holdout check found one):
   then everything trains, at up to 4 x with SSIM weighted up to 10 x (both rising over its first
   TN__GNN_ALONE_RAMP iterations), on the whole graph.
   Holdout checks come every holdout_every iterations before the phase and once as it starts
   (the early network is chosen from those). */
static tn_status tn__gnn_iteration(tn__gnn_train *s, tn_ctx *ctx, float *l)
{
    int phase = s->o.embed_phase > 0 && tn_train_fraction(s->run) >= 1.0 - s->o.embed_phase, i, n = tn_params_count(s->w), alone;
    long it = tn_train_iteration(s->run);
    tn_tensor *emb = tn_params_find(s->w, "gnn.emb");
    tn_status st;
    if (!phase && s->best && it > 0 && it % s->o.holdout_every == 0 && (st = tn__gnn_holdout_check(s))) return st;
    if (!phase) return tn__gnn_step(s, ctx, 0, l);
    if (s->phase_from < 0) {
        tn_tensor *info = s->best ? tn_params_find(s->best, "holdout") : NULL;
        s->phase_from = it;
        if (info && info->data[5] < 0) {
            info->data[5] = (float)it;
            if (info->data[4] != (float)it && (st = tn__gnn_holdout_check(s))) return st;
        }
    }
    /* an early network serves other terrain: the example alone, everything, whole graph, faster (docs/gnn.md) */
    alone = s->o.phase_network >= 0 && s->best && tn_params_find(s->best, "holdout")->data[1] >= 0;
    if (!alone)
        for (i = 0; i < n; i++) tn_params_get(s->w, i)->requires_grad = tn_params_get(s->w, i) == emb;
    if (alone) { /* iterations since the phase began (the checks' record, so a resumed run agrees) */
        float since = (float)it - tn_params_find(s->best, "holdout")->data[5] + 1.0f;
        s->alone_ramp = since < TN__GNN_ALONE_RAMP ? since / TN__GNN_ALONE_RAMP : 1.0f;
    }
    tn_optim_set_lr(s->opt, (alone ? 1.0f + (TN__GNN_ALONE_RATE - 1.0f) * s->alone_ramp : 5.0f) * s->o.lr);
    st = tn__gnn_step(s, ctx, alone ? 2 : 1, l);
    tn_optim_set_lr(s->opt, s->o.lr);
    if (!alone)
        for (i = 0; i < n; i++) tn_params_get(s->w, i)->requires_grad = tn_params_get(s->w, i)->grad != NULL; /* learned, not buffers */
    return st;
}

/* The settings a checkpoint keeps (a resumed run continues with the ones it started with). */
#define TN__GNN_SETTINGS(X)                                                                                        \
    X("random_edges", random_edges, int, -1e9, 1e9) X("mask", mask, float, -1, 1) X("embed_drop", embed_drop, float, -1, 1) \
    X("sparse_levels", sparse_levels, int, -1, TN__GNN_MAX_LEVELS - 1) X("thin", thin, float, -1, 1)               \
    X("threshold", extract.threshold, int, -1, 1e9) X("edge_noise", edge_noise, float, -1, 100) X("lr", lr, float, 0, 10) \
    X("mse_weight", mse_weight, float, -1e6, 1e6) X("ssim_weight", ssim_weight, float, -1e6, 1e6)                     \
    X("grad_weight", grad_weight, float, -1e6, 1e6)
/* settings added later: a checkpoint without them trained without them */
#define TN__GNN_LATER_SETTINGS(X) \
    X("sketch_weight", sketch_weight, float, 0, 1e6) X("smooth_weight", smooth_weight, float, -1, 1e6) X("further_weight", further_weight, float, 0, 1e6)

static tn_status tn__gnn_set_meta(tn__gnn_train *s, uint64_t digest)
{
    tn_status st = tn_train_set_example(s->run, digest);
#define TN__GNN_PUT(key, field, type, lo, hi) \
    if (!st) st = tn_train_set_meta_number(s->run, key, (double)s->o.field);
    TN__GNN_SETTINGS(TN__GNN_PUT)
    TN__GNN_LATER_SETTINGS(TN__GNN_PUT)
#undef TN__GNN_PUT
    return st;
}

static tn_status tn__gnn_get_meta(tn__gnn_train *s, uint64_t digest)
{
    double d = 0;
    tn_status st = tn_train_check_example(s->run, digest);
#define TN__GNN_GET(key, field, type, lo, hi) \
    if (!st && !(st = tn_train_meta_number(s->run, key, lo, hi, &d))) s->o.field = (type)d;
    TN__GNN_SETTINGS(TN__GNN_GET)
#undef TN__GNN_GET
#define TN__GNN_GET_LATER(key, field, type, lo, hi) \
    if (!st) { \
        s->o.field = 0; \
        if (tn_train_meta(s->run, key) && !(st = tn_train_meta_number(s->run, key, lo, hi, &d))) s->o.field = (type)d; \
    }
    TN__GNN_LATER_SETTINGS(TN__GNN_GET_LATER)
#undef TN__GNN_GET_LATER
    return st;
}
#undef TN__GNN_SETTINGS
#undef TN__GNN_LATER_SETTINGS

static tn_status tn__gnn_gain_calibrate(tn__gnn_train *s);
static tn_status tn__gnn_file_matches(const tn_params *f, const tn__gnn_arch *A, const char *name);

/* The example's heights (example units), which the fine detail by example draws on at generation. */
static tn_status tn__gnn_store_example(tn_params *w, const tn_image *dem)
{
    int shape[2];
    tn_tensor *t;
    shape[0] = dem->height;
    shape[1] = dem->width;
    if (!(t = tn_params_add_buffer(w, "detail.example", 2, shape))) return tn__oom();
    memcpy(t->data, dem->data, (size_t)dem->width * dem->height * sizeof(float));
    return TN_OK;
}

/* The holdouts without the example's height steps (windows of the same DEM, stored alike), in
   *own, which o->holdout then points to. Holdouts validation will refuse are left as they are. */
static tn_status tn__gnn_holdouts_without_steps(tn_gnn_opts *o, float step, tn_image **own)
{
    int i;
    tn_status st;
    if (o->holdout_count <= 0 || !o->holdout) return TN_OK;
    for (i = 0; i < o->holdout_count; i++)
        if (!o->holdout[i].data || o->holdout[i].channels != 1) return TN_OK;
    if (!(*own = (tn_image *)tn__alloc((size_t)o->holdout_count * sizeof **own))) return tn__fail(TN_ERR_OUT_OF_MEMORY, "gnn: out of memory");
    memset(*own, 0, (size_t)o->holdout_count * sizeof **own);
    for (i = 0; i < o->holdout_count; i++)
        if ((st = tn_image_dequantize(&(*own)[i], &o->holdout[i], step))) return st;
    o->holdout = *own;
    return TN_OK;
}

TN_API tn_status tn_gnn_train(tn_gnn *model, const tn_image *dem, const tn_gnn_opts *opts_in, tn_gnn_stats *stats)
{
    tn__gnn_train s;
    tn_extraction ex;
    tn_contour_set parts;
    tn_ctx *ctx = NULL;
    tn_image one = {0, 0, 0, NULL}, *hold = NULL;
    const tn_image *d1 = dem;
    float lo = 0, hi = 0, hist[50][4], dq_step = 0;
    double mean = 0, std = 0;
    int nh = 0, i;
    size_t n;
    uint64_t digest, seed;
    const char *sd;
    int ck_best = 0;
    tn_status st;
    TN_ASSERT(model);
    memset(&s, 0, sizeof s);
    memset(&ex, 0, sizeof ex);
    memset(&parts, 0, sizeof parts);
    s.phase_from = -1;
    if (opts_in) s.o = *opts_in;
    tn_gnn_defaults(&s.o);
    if ((st = tn__gnn_check_dem(dem, "the DEM", &lo, &hi, &mean, &std))) return st;
    if ((st = tn__gnn_validate(&s.o))) return st;
    if ((size_t)dem->width * dem->height * (size_t)s.o.k + (size_t)(s.o.random_edges > 0 ? s.o.random_edges : 0) > TN__GNN_MAX_EDGES)
        return tn__fail(TN_ERR_TOO_LARGE, "gnn: %d x %d pixels with %d edges each exceed %d edges; train on a crop", dem->width, dem->height,
                        s.o.k, TN__GNN_MAX_EDGES);
    if (dem->channels > 1) { /* channel 0 only, as every DEM function */
        if ((st = tn_image_create(&one, dem->width, dem->height, 1))) return st;
        for (n = 0; n < (size_t)dem->width * dem->height; n++) one.data[n] = dem->data[n * dem->channels];
        d1 = &one;
    }
    digest = tn_image_digest(d1);
    if ((st = tn__train_without_steps(&one, &d1, s.o.dequantize, &dq_step))) goto done;
    if (dq_step > 0 && (st = tn__gnn_holdouts_without_steps(&s.o, dq_step, &hold))) goto done;
    seed = s.o.train.seed;
    if ((st = tn_train_create(&s.run, "gnn", "gnn-train", &s.o.train))) goto done;
    if (s.o.train.resume) { /* the checkpoint's seed and architecture win */
        tn_params *ck;
        tn_tensor *cfg;
        if ((st = tn_train_open_checkpoint(s.run, &ck))) goto done;
        if (!(cfg = tn_params_find(ck, "gnn.config")) || cfg->numel != TN__GNN_CONFIG) {
            st = tn__fail(TN_ERR_FORMAT, "%s: not a gnn checkpoint", s.o.train.checkpoint);
            goto done;
        }
        if ((st = tn__gnn_read_config(cfg->data, &s.A, s.o.train.checkpoint))) goto done;
        if ((st = tn__gnn_file_matches(ck, &s.A, s.o.train.checkpoint))) goto done; /* before the config sizes anything */
        if ((st = tn__gnn_get_meta(&s, digest))) goto done;
        ck_best = tn_params_find(ck, "best.holdout") != NULL;
        sd = tn_params_meta(ck, "seed");
        if (!sd || !tn__parse_hex64(sd, strlen(sd), &seed)) {
            st = tn__fail(TN_ERR_CORRUPT, "%s: the checkpoint names no seed", s.o.train.checkpoint);
            goto done;
        }
    }
    /* the example's network and parts: deterministic in the DEM, the extraction options and
       the seed, so a resumed run rebuilds the same graph */
    tn__progress_within("gnn-prepare", 0.0); /* its dozen extractions (example, holdouts, levels) as one stage */
    if ((st = tn_extract(&ex, d1, &s.o.extract))) goto done;
    if (!ex.contours.count) {
        st = tn__fail(TN_ERR_EMPTY, "gnn: no ridge or valley was extracted from the DEM (try a lower extraction threshold)");
        goto done;
    }
    if ((st = tn_contour_parts_make(&parts, &ex.contours, seed))) goto done;
    if (!parts.count) {
        st = tn__fail(TN_ERR_EMPTY, "gnn: the DEM's ridges and valleys give no contour part of 5 px");
        goto done;
    }
    if (!s.o.train.resume) {
        s.A.hidden = s.o.hidden;
        s.A.rounds = s.o.rounds;
        s.A.k = s.o.k;
        s.A.radius = s.o.radius;
        s.A.embed = s.o.embed;
        s.A.membrane = s.o.membrane >= 0;
        s.A.width = d1->width;
        s.A.height = d1->height;
        s.A.mean = (float)mean;
        s.A.std = (float)(std > 1e-30 ? std : 1.0);
        s.A.lo = lo;
        s.A.hi = hi;
        s.A.part_noise = s.o.part_noise > 0 ? s.o.part_noise : 0.0f;
        s.A.overhang = s.o.part_index >= 0;
        s.A.parts = parts.count;
        s.A.npts = 0;
        for (i = 0; i < parts.count; i++) s.A.npts += parts.items[i].npoints;
    } else if (s.A.parts != parts.count || s.A.width != d1->width || s.A.height != d1->height) {
        st = tn__fail(TN_ERR_SHAPE, "%s: the checkpoint's example has %d parts at %d x %d, this one %d at %d x %d", s.o.train.checkpoint,
                      s.A.parts, s.A.width, s.A.height, parts.count, d1->width, d1->height);
        goto done;
    }
    tn_rng_seed(&s.rng, seed, 0x676e6eULL);
    if ((st = tn__gnn_model_params(&s.A, &s.rng, &s.w))) goto done;
    tn__gnn_store_parts(s.w, &parts);
    {
        tn_optim_opts oo;
        memset(&oo, 0, sizeof oo);
        oo.lr = s.o.lr;
        oo.beta1 = 0.9f;
        oo.beta2 = 0.999f;
        if (!(s.opt = tn_optim_create(s.w, &oo))) { st = TN_ERR_INVALID_ARG; goto done; }
    }
    if ((st = tn_train_add_net(s.run, "gnn", s.w, s.opt)) || (st = tn_train_add_rng(s.run, "main", &s.rng))) goto done;
    tn__progress_within("gnn-prepare", 0.3);
    if ((st = tn__gnn_set_meta(&s, digest)) || (st = tn__gnn_holdout_make(&s))) goto done;
    /* the best weights travel with the checkpoint (one written without holdouts starts the checks afresh) */
    if (s.best && (!s.o.train.resume || ck_best) && (st = tn_train_add_params(s.run, "best.", s.best))) goto done;
    if (s.o.train.resume && (st = tn_train_restore(s.run))) goto done;
    if (s.best && s.o.train.resume && !ck_best && (st = tn_train_add_params(s.run, "best.", s.best))) goto done;
    /* the levels: the example's own network, then its sparser networks */
    tn__progress_within("gnn-prepare", 0.7);
    s.npix = s.A.width * s.A.height;
    if (!(s.target = (float *)tn__alloc((size_t)s.npix * sizeof(float)))) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    for (i = 0; i < s.npix; i++) s.target[i] = (d1->data[i] - s.A.mean) / s.A.std;
    s.range = (s.A.hi - s.A.lo) / s.A.std;
    if ((st = tn__gnn_level_make(&s.A, &ex.contours, &parts, &s.lv[0]))) goto done;
    s.nlevels = 1;
    s.maxparts = parts.count;
    for (i = 1; i <= (s.o.sparse_levels > 0 ? s.o.sparse_levels : 0); i++) {
        static const int factor[TN__GNN_MAX_LEVELS] = {1, 4, 12, 36};
        tn_extract_opts eo = s.o.extract;
        tn_extraction sx;
        tn_contour_set sp;
        int base_thr = eo.threshold > 0 ? eo.threshold : tn_extract_default_threshold(d1->width, d1->height);
        eo.threshold = base_thr * factor[i];
        memset(&sp, 0, sizeof sp);
        if ((st = tn_extract(&sx, d1, &eo))) goto done;
        if (sx.contours.count && !(st = tn_contour_parts_make(&sp, &sx.contours, seed + (uint64_t)i)) && sp.count) {
            st = tn__gnn_level_make(&s.A, &sx.contours, &sp, &s.lv[s.nlevels]);
            if (sp.count > s.maxparts) s.maxparts = sp.count;
            s.nlevels++;
        }
        tn_contour_set_free(&sp);
        tn_extraction_free(&sx);
        if (st) goto done;
    }
    tn__progress_within(NULL, 0.0);
    if ((st = tn__progress("gnn-prepare", 1.0))) goto done;
    if (!(s.masked = (uint8_t *)tn__alloc((size_t)s.maxparts)) || !(s.known = (uint8_t *)tn__alloc((size_t)s.maxparts))) {
        st = TN_ERR_OUT_OF_MEMORY;
        goto done;
    }
    if ((st = tn__gnn_graph_alloc(&s.g, s.npix, s.maxparts, s.npix * s.A.k + (s.o.random_edges > 0 ? s.o.random_edges : 0)))) goto done;
    if (!(ctx = tn_ctx_create())) { st = tn__fail(TN_ERR_OUT_OF_MEMORY, "gnn: out of memory"); goto done; }
    while (tn_train_next(s.run)) {
        float l[4];
        tn_status e = tn__gnn_iteration(&s, ctx, l);
        if (e) {
            tn_train_fail(s.run, e);
            break;
        }
        memcpy(hist[nh % 50], l, sizeof l);
        nh++;
    }
    st = tn_train_finish(s.run);
    if (!st) st = tn__gnn_holdout_end(&s);
    if (!st) st = tn__gnn_gain_calibrate(&s);
    if (stats) {
        int k, m = nh < 50 ? nh : 50;
        long it = tn_train_iteration(s.run), it0 = tn_train_start_iteration(s.run);
        memset(stats, 0, sizeof *stats);
        stats->iterations = it;
        stats->resumed_from = s.o.train.resume ? it0 : 0;
        stats->seconds = tn_train_seconds(s.run);
        stats->seconds_per_iter = it > it0 ? (tn_train_seconds(s.run) - tn_train_start_seconds(s.run)) / (double)(it - it0) : 0.0;
        for (k = 0; k < m; k++) {
            stats->loss_mse += hist[k][0] / (float)m;
            stats->loss_ssim += hist[k][1] / (float)m;
            stats->loss_grad += hist[k][2] / (float)m;
            stats->loss += hist[k][3] / (float)m;
        }
        stats->parts = s.A.parts;
        for (i = 0; i < s.npix * s.A.k; i++) stats->edges += s.lv[0].nbr[i] >= 0;
        stats->levels = s.nlevels;
        stats->checkpoints = tn_train_checkpoints(s.run);
        stats->embed_phase_from = s.phase_from;
        stats->holdout_iteration = -1;
        stats->gain_scale = (float)tn__gnn_gain_scale(s.w);
        stats->dequantized = dq_step;
        if (s.best) {
            const tn_tensor *info = tn_params_find(s.best, "holdout");
            stats->holdout_ssim = info->data[0];
            stats->holdout_iteration = (long)info->data[1];
            stats->holdout_checks = (int)info->data[2];
            stats->holdout_last_ssim = info->data[3];
        }
    }
    if (!st) st = tn__gnn_store_example(s.w, d1);
    if (!st) st = tn__train_stamp(s.w, "gnn", TN__GNN_FORMAT, s.run, digest, d1->width, d1->height, 1);
    if (!st) {
        memset(model, 0, sizeof *model);
        tn__gnn_model_fields(model, &s.A);
        model->iterations = tn_train_iteration(s.run);
        model->train_seconds = tn_train_seconds(s.run);
        model->weights = s.w;
        s.w = NULL; /* handed over */
    }
done:
    tn__progress_within(NULL, 0.0);
    tn_ctx_free(ctx);
    tn_image_free(&one);
    if (hold)
        for (i = 0; i < s.o.holdout_count; i++) tn_image_free(&hold[i]);
    TN_FREE(hold);
    tn_extraction_free(&ex);
    tn_contour_set_free(&parts);
    tn__gnn_train_free(&s);
    return st;
}

/* ---- model files ---- */

TN_API void tn_gnn_free(tn_gnn *model)
{
    if (!model) return;
    tn_params_free(model->weights);
    memset(model, 0, sizeof *model);
}

static tn_status tn__gnn_check_model(const tn_gnn *m)
{
    tn__gnn_arch A;
    return tn__gnn_arch_of(m, &A);
}

TN_API tn_status tn_gnn_save(const char *path, const tn_gnn *model)
{
    tn_status st;
    if ((st = tn__gnn_check_model(model))) return st;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "gnn save: empty path");
    return tn_params_save(path, model->weights);
}

/* Whether a model file holds the tensors its config implies, checked on the file's own tensors
   before the model is allocated: the parts, the embeddings and the example scale with the
   config's counts, the network with its width and rounds. */
static tn_status tn__gnn_file_matches(const tn_params *f, const tn__gnn_arch *A, const char *name)
{
    int pts[2], info[2], emb[2], ex[2];
    char last[40];
    pts[0] = A->npts;
    pts[1] = 3;
    info[0] = emb[0] = A->parts;
    info[1] = 4;
    emb[1] = A->embed;
    ex[0] = A->height;
    ex[1] = A->width;
    if (!tn__params_has(f, "gnn.part_pts", 2, pts) || !tn__params_has(f, "gnn.part_info", 2, info) || !tn__params_has(f, "gnn.emb", 2, emb))
        return tn__fail(TN_ERR_CORRUPT, "%s: the gnn config names %d parts of %d points with %d-wide embeddings; the file's part tensors differ",
                        name, A->parts, A->npts, A->embed);
    snprintf(last, sizeof last, "gnn.%ds.a", A->rounds - 1);
    if (!tn__params_has(f, last, 1, &A->hidden))
        return tn__fail(TN_ERR_CORRUPT, "%s: the gnn config names %d rounds of width %d; the file's network differs", name, A->rounds, A->hidden);
    if (tn_params_find(f, "detail.example") && !tn__params_has(f, "detail.example", 2, ex))
        return tn__fail(TN_ERR_CORRUPT, "%s: the gnn config names a %d x %d example; the file's detail.example differs", name, A->width, A->height);
    return TN_OK;
}

TN_API tn_status tn_gnn_load(tn_gnn *model, const char *path)
{
    tn_params *f = NULL, *w = NULL;
    tn_tensor *cfg;
    tn__gnn_arch A;
    tn_contour_set parts;
    tn_gnn m;
    tn_status st;
    TN_ASSERT(model);
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "gnn load: empty path");
    if ((st = tn__model_open(&f, path, "gnn", TN__GNN_FORMAT, NULL))) return st;
    memset(&parts, 0, sizeof parts);
    if (!(cfg = tn_params_find(f, "gnn.config")) || cfg->numel != TN__GNN_CONFIG)
        st = tn__fail(TN_ERR_FORMAT, "%s: not a gnn model (no gnn.config)", path);
    if (!st) st = tn__gnn_read_config(cfg->data, &A, path);
    if (!st) st = tn__gnn_file_matches(f, &A, path);
    if (!st) st = tn__gnn_model_params(&A, NULL, &w);
    if (!st && tn_params_find(f, "early.gnn.emb")) st = tn__gnn_early_add(w);
    if (!st && tn_params_find(f, "gain.scale")) {
        int one = 1;
        if (!tn_params_add_buffer(w, "gain.scale", 1, &one)) st = TN_ERR_OUT_OF_MEMORY;
    }
    if (!st && tn_params_find(f, "detail.example")) { /* models before it have none: no detail by example */
        int shape[2];
        shape[0] = A.height;
        shape[1] = A.width;
        if (!tn_params_add_buffer(w, "detail.example", 2, shape)) st = TN_ERR_OUT_OF_MEMORY;
    }
    if (!st) st = tn__params_assign(w, f, path);
    if (!st && !(tn__gnn_gain_scale(w) >= 0 && tn__gnn_gain_scale(w) <= 0.05 * (TN__GNN_GAIN_SCALES - 1))) /* NaN too */
        st = tn__fail(TN_ERR_CORRUPT, "%s: gain.scale %g is not in 0 .. 2", path, tn__gnn_gain_scale(w));
    if (!st) st = tn__gnn_stored_parts(w, &A, path, &parts); /* validates the parts */
    if (!st && tn_params_find(w, "detail.example")) {
        const tn_tensor *e = tn_params_find(w, "detail.example");
        size_t i;
        for (i = 0; i < e->numel; i++)
            if (!isfinite(e->data[i])) {
                st = tn__fail(TN_ERR_CORRUPT, "%s: NaN/Inf in the example heights (detail.example)", path);
                break;
            }
    }
    if (!st) {
        const tn_tensor *e = tn_params_find(w, "gnn.emb"), *e2 = tn_params_find(w, "early.gnn.emb");
        size_t i;
        for (i = 0; i < e->numel; i++)
            if (!isfinite(e->data[i]) || (e2 && !isfinite(e2->data[i]))) {
                st = tn__fail(TN_ERR_CORRUPT, "%s: NaN/Inf embedding", path);
                break;
            }
    }
    tn_contour_set_free(&parts);
    if (st) {
        tn_params_free(f);
        tn_params_free(w);
        return st;
    }
    memset(&m, 0, sizeof m);
    tn__gnn_model_fields(&m, &A);
    tn__model_training(f, path, &m.iterations, &m.train_seconds);
    tn_params_free(f);
    m.weights = w;
    *model = m;
    return TN_OK;
}

TN_API tn_status tn_gnn_parts(tn_contour_set *out, const tn_gnn *model)
{
    tn__gnn_arch A;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__gnn_arch_of(model, &A))) return st;
    return tn__gnn_stored_parts(model->weights, &A, "gnn", out);
}

/* ---- generation ---- */

/* The sketch in the output's pixels and the example's height units. */
static tn_status tn__gnn_sketch_units(const tn__gnn_arch *A, const tn_contour_set *sk, int W, int H, int heights, tn_contour_set *out)
{
    tn_contour_set s;
    float sx = (float)W / (float)sk->width, sy = (float)H / (float)sk->height, hmin = FLT_MAX, hmax = -FLT_MAX, a = 1, b = 0;
    int i, j;
    tn__cset_height_range(sk, &hmin, &hmax);
    if (heights == TN_GNN_HEIGHTS_AUTO)
        heights = hmin >= 0 && hmax <= 1 && !(A->lo >= 0 && A->hi <= 1) ? TN_GNN_HEIGHTS_UNIT : TN_GNN_HEIGHTS_EXAMPLE;
    if (heights == TN_GNN_HEIGHTS_UNIT) {
        a = A->hi - A->lo;
        b = A->lo;
    }
    memset(&s, 0, sizeof s);
    s.width = W;
    s.height = H;
    s.count = sk->count;
    if (!(s.items = (tn_contour *)tn__calloc((size_t)sk->count * sizeof(tn_contour)))) return TN_ERR_OUT_OF_MEMORY;
    for (i = 0; i < sk->count; i++) {
        const tn_contour *c = &sk->items[i];
        tn_contour *d = &s.items[i];
        *d = *c;
        if (!(d->points = (float *)tn__alloc((size_t)c->npoints * 3 * sizeof(float)))) {
            tn_contour_set_free(&s);
            return TN_ERR_OUT_OF_MEMORY;
        }
        for (j = 0; j < c->npoints; j++) { /* pixel centres map to pixel centres */
            d->points[3 * j] = (c->points[3 * j] + 0.5f) * sx - 0.5f;
            d->points[3 * j + 1] = (c->points[3 * j + 1] + 0.5f) * sy - 0.5f;
            d->points[3 * j + 2] = a * c->points[3 * j + 2] + b;
        }
    }
    *out = s;
    return TN_OK;
}

/* match[i] = the example part identical to sketch part i (same points within 1e-3 px, heights
   within htol), else -1; htol < 0: -1 for all. Parts are few (hundreds to thousands) and most
   pairs fail on the point count or the first point, so a plain double loop is enough. */
static void tn__gnn_same_parts(const tn_contour_set *sk, const tn_contour_set *ex, float htol, int *match)
{
    int i, j, q;
    for (i = 0; i < sk->count; i++) {
        const tn_contour *a = &sk->items[i];
        match[i] = -1;
        for (j = 0; htol >= 0 && j < ex->count && match[i] < 0; j++) {
            const tn_contour *b = &ex->items[j];
            int same = a->npoints == b->npoints && a->type == b->type;
            for (q = 0; same && q < a->npoints; q++)
                same = fabsf(a->points[3 * q] - b->points[3 * q]) <= 1e-3f && fabsf(a->points[3 * q + 1] - b->points[3 * q + 1]) <= 1e-3f &&
                       fabsf(a->points[3 * q + 2] - b->points[3 * q + 2]) <= htol;
            if (same) match[i] = j;
        }
    }
}

TN__INTERNAL tn_status tn__gnn_grow(const tn_contour_set *user, const tn_contour_set *example, const tn_image *dem, int width, int height,
                                    const tn_gnn_grow_opts *opts, tn_contour_set *out, int *added, float *relief, float *ground); /* >>gnn_grow */
TN__INTERNAL tn_status tn__gnn_grow_ground(const tn_contour_set *example, const tn_image *dem, int kind, float *prof, float *median, uint8_t *mask,
                                           float *dist, int *near); /* >>gnn_grow */
TN__INTERNAL tn_status tn__gnn_grow_crest(tn_contour_set *set, int nuser, const tn_contour_set *example, int kind, uint64_t seed); /* >>gnn_grow */
TN__INTERNAL tn_status tn__gnn_grow_flanks(const tn_contour_set *set, int nuser, const tn_contour_set *example, const tn_image *dem, uint64_t seed,
                                           float *field); /* >>gnn_grow */
/* The ground tn__gnn_grow adds falls away from a user ridge (rises away from a user valley) by
   TN__GNN_FALL x the example lines' local relief over TN__GNN_FALL_REACH px (tn__gnn_grow_fall) */
#define TN__GNN_FALL 2.0f
#define TN__GNN_FALL_REACH 48

/* What every window of one generation shares: the sketch's parts, cut once from the whole
   sketch so that every window sees the same parts in the same order, their embeddings and
   initial states, and the rasterised sketch. */
typedef struct tn__gnn_gen {
    tn__gnn_arch A;
    int W, H, halo;
    int grown;                 /* polylines tn_gnn_grow added (0: not grown) */
    uint8_t *pin;              /* W x H, grown sketches only: the user's own line pixels (1 ridge, 2
                                  valley), whose heights the output keeps (tn__gnn_pin); NULL = none */
    float *pin_d;              /* W x H: chamfer distance to them */
    uint8_t *drawn;            /* W x H or NULL: the user's ridges where they were drawn, when the
                                  example's bends moved them (tn__gnn_grow_crest) */
    float *drawn_d;            /* W x H: chamfer distance to them */
    float *flank;              /* W x H or NULL: the drawn ridges' flanks by example (tn__gnn_grow_flanks), normalised units */
    float *ground;             /* W x H or NULL: the grown ground's fine band (tn__gnn_ground_band), example units */
    float *ground_lp;          /* W x H: the rest of that ground */
    float ground_rms;          /* the band's RMS */
    float side;                /* least slope from a stroke to its banks (normalised units per px; tn__gnn_incise) */
    double user_density, example_density; /* line pixels per pixel: the sketch's, the example's */
    float gain;                /* share of the residual over the membrane that is added */
    double gain_raw;           /* the held-out lines' least-squares gain before scale and clamp
                                  (tn__gnn_gain_validate); NAN = not tested */
    tn__gnn_parts P;           /* every part of the sketch, normalised heights */
    float *emb;                /* P.n x embed */
    uint8_t *known;            /* P.n: the part has an example part's embedding */
    float *E0;                 /* P.n x hidden initial states; NULL = zero */
    float *type, *hgt;         /* W x H: +1 / -1 / 0; the sketch height (example units) or 0 */
    uint8_t *fixed;            /* W x H: sketch pixel */
    float *base;               /* W x H: the whole map's membrane (example units), or NULL: each
                                  region solves its own (tn_gnn_prepare sets it for its windows) */
    int level;                 /* px: > 0 (the network's reach, A.radius), the network sees each
                                  pixel's baseline less how far the membrane's mean within this
                                  radius lies outside [level_lo, level_hi], the example's own such
                                  means (tn__gnn_region_level); 0 = as it is */
    float level_lo, level_hi;  /* normalised */
    const tn_params *w;        /* the network it runs on (tn__gnn_pick_net) */
    tn_params *own_w;          /* w when it is the model's early network */
    int detail;                /* 1: fd's fine detail is added to the output */
    const char *detail_why;
    tn__fd fd;                 /* the example's patch index (@@finedetail), built for generation only */
} tn__gnn_gen;

/* One region of the map with its own graph: the parts that can reach it, in the sketch's order. */
typedef struct tn__gnn_region {
    int rx, ry, rw, rh;
    tn__gnn_parts P;
    int *of;                   /* region part -> sketch part */
    float *type, *base;        /* rw x rh; base normalised (0 without membrane) */
    float *level;              /* rw x rh or NULL: subtracted from base in the pixels' input (G->level) */
    tn__gnn_graph g;
} tn__gnn_region;

static void tn__gnn_gen_free(tn__gnn_gen *G)
{
    tn__gnn_parts_free(&G->P);
    TN_FREE(G->emb);
    TN_FREE(G->known);
    TN_FREE(G->E0);
    TN_FREE(G->type);
    TN_FREE(G->hgt);
    TN_FREE(G->fixed);
    TN_FREE(G->base);
    TN_FREE(G->pin);
    TN_FREE(G->pin_d);
    TN_FREE(G->drawn);
    TN_FREE(G->drawn_d);
    TN_FREE(G->flank);
    TN_FREE(G->ground);
    TN_FREE(G->ground_lp);
    tn_params_free(G->own_w);
    tn__fd_free(&G->fd);
    memset(G, 0, sizeof *G);
}

static void tn__gnn_region_free(tn__gnn_region *R)
{
    tn__gnn_parts_free(&R->P);
    TN_FREE(R->of);
    TN_FREE(R->type);
    TN_FREE(R->base);
    TN_FREE(R->level);
    tn__gnn_graph_free(&R->g);
    memset(R, 0, sizeof *R);
}

/* The integral image of v (width x height) into I ((width + 1) x (height + 1), zeroed). */
static void tn__gnn_integral(const float *v, int width, int height, double *I)
{
    const size_t W1 = (size_t)width + 1;
    int x, y;
    for (y = 0; y < height; y++)
        for (x = 0; x < width; x++) {
            size_t q = (size_t)(y + 1) * W1 + x + 1;
            I[q] = v[(size_t)y * width + x] + I[q - 1] + I[q - W1] - I[q - W1 - 1];
        }
}

/* The sum of integral image I ((width + 1) x (height + 1)) over the box of radius r around (x, y),
   clipped to the map; *area = the clipped box's pixels. */
static double tn__gnn_box_sum(const double *I, int width, int height, int x, int y, int r, double *area)
{
    const size_t W1 = (size_t)width + 1;
    int x0 = x - r < 0 ? 0 : x - r, y0 = y - r < 0 ? 0 : y - r, x1 = x + r + 1 > width ? width : x + r + 1, y1 = y + r + 1 > height ? height : y + r + 1;
    *area = (double)(x1 - x0) * (y1 - y0);
    return I[(size_t)y1 * W1 + x1] - I[(size_t)y0 * W1 + x1] - I[(size_t)y1 * W1 + x0] + I[(size_t)y0 * W1 + x0];
}

/* The range of the example's (dem, example units) means within L px, clipped to it, normalised. */
static tn_status tn__gnn_level_range(const tn_image *dem, const tn__gnn_arch *A, int L, float *lo, float *hi)
{
    const int W = dem->width, H = dem->height;
    double *I = (double *)tn__calloc(((size_t)W + 1) * (H + 1) * sizeof(double)), a = DBL_MAX, b = -DBL_MAX;
    int x, y;
    if (!I) return TN_ERR_OUT_OF_MEMORY;
    tn__gnn_integral(dem->data, W, H, I);
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) {
            double area, m = tn__gnn_box_sum(I, W, H, x, y, L, &area) / area;
            a = fmin(a, m), b = fmax(b, m);
        }
    TN_FREE(I);
    *lo = (float)((a - A->mean) / A->std);
    *hi = (float)((b - A->mean) / A->std);
    return TN_OK;
}

/* R->base (example units) and R->level from one membrane of the region grown by G->level px:
   how far each pixel's mean membrane (normalised) within G->level px (the network's reach),
   clipped to the map, lies outside the example's own such means, so the network sees a
   drawing's ground at levels the example has. It learnt the example's heights: given a
   drawing's ground above (below) them it pulls the land beside the strokes down (up) by as much
   or more (docs/gnn.md), and a drawn valley was then dug below its asked height to stay lowest.
   base_map as in tn__gnn_region_make. */
static tn_status tn__gnn_region_level(const tn__gnn_gen *G, const float *base_map, tn__gnn_region *R)
{
    const int L = G->level;
    int ex = R->rx - L > 0 ? R->rx - L : 0, ey = R->ry - L > 0 ? R->ry - L : 0, x, y;
    int ew = (R->rx + R->rw + L < G->W ? R->rx + R->rw + L : G->W) - ex, eh = (R->ry + R->rh + L < G->H ? R->ry + R->rh + L : G->H) - ey;
    float *eb = (float *)tn__alloc((size_t)ew * eh * sizeof(float));
    double *I = (double *)tn__calloc(((size_t)ew + 1) * (eh + 1) * sizeof(double));
    tn_status st = TN_OK;
    R->level = (float *)tn__alloc((size_t)R->rw * R->rh * sizeof(float));
    if (!eb || !I || !R->level) st = TN_ERR_OUT_OF_MEMORY;
    if (!st && base_map)
        for (y = 0; y < eh; y++) memcpy(eb + (size_t)y * ew, base_map + (size_t)(ey + y) * G->W + ex, (size_t)ew * sizeof(float));
    else if (!st)
        st = tn__gnn_membrane_rect(G->hgt, G->fixed, G->W, G->H, ex, ey, ew, eh, eb);
    for (y = 0; !st && y < R->rh; y++)
        memcpy(R->base + (size_t)y * R->rw, eb + (size_t)(R->ry - ey + y) * ew + (R->rx - ex), (size_t)R->rw * sizeof(float));
    if (!st) tn__gnn_integral(eb, ew, eh, I);
    for (y = 0; !st && y < R->rh; y++)
        for (x = 0; x < R->rw; x++) {
            double area, m = (tn__gnn_box_sum(I, ew, eh, R->rx + x - ex, R->ry + y - ey, L, &area) / area - G->A.mean) / G->A.std;
            R->level[(size_t)y * R->rw + x] = (float)(m - fmin(fmax(m, (double)G->level_lo), (double)G->level_hi));
        }
    TN_FREE(eb);
    TN_FREE(I);
    return st;
}

/* The graph of the region: its pixels' k nearest parts within the radius, from the parts with a
   point less than radius + 1 px from the region (every part a region pixel can reach). base_map:
   the whole map's membrane (example units) to take the region's from, or NULL to solve it. */
static tn_status tn__gnn_region_make(const tn__gnn_gen *G, int rx, int ry, int rw, int rh, const float *base_map, tn__gnn_region *R)
{
    const tn__gnn_parts *S = &G->P;
    size_t npix = (size_t)rw * rh, i;
    float m = G->A.radius + 1.0f;
    int *nbr = NULL, j, p, n = 0, q = 0, y;
    float *nfeat = NULL;
    tn_status st = TN_OK;
    memset(R, 0, sizeof *R);
    R->rx = rx;
    R->ry = ry;
    R->rw = rw;
    R->rh = rh;
    R->type = (float *)tn__alloc(npix * sizeof(float));
    R->base = (float *)tn__alloc(npix * sizeof(float));
    R->of = (int *)tn__alloc(((size_t)S->n + 1) * sizeof(int));
    R->P.start = (int *)tn__alloc(((size_t)S->n + 1) * sizeof(int));
    R->P.of = (int *)tn__alloc(((size_t)S->npts + 1) * sizeof(int));
    R->P.pts = (float *)tn__alloc(((size_t)S->npts + 1) * 3 * sizeof(float));
    R->P.sign = (float *)tn__alloc(((size_t)S->n + 1) * sizeof(float));
    if (!R->type || !R->base || !R->of || !R->P.start || !R->P.of || !R->P.pts || !R->P.sign) st = TN_ERR_OUT_OF_MEMORY;
    for (y = 0; !st && y < rh; y++) memcpy(R->type + (size_t)y * rw, G->type + (size_t)(ry + y) * G->W + rx, (size_t)rw * sizeof(float));
    if (!st && G->A.membrane) {
        if (G->level > 0)
            st = tn__gnn_region_level(G, base_map, R);
        else if (base_map)
            for (y = 0; y < rh; y++) memcpy(R->base + (size_t)y * rw, base_map + (size_t)(ry + y) * G->W + rx, (size_t)rw * sizeof(float));
        else
            st = tn__gnn_membrane_rect(G->hgt, G->fixed, G->W, G->H, rx, ry, rw, rh, R->base);
        for (i = 0; !st && i < npix; i++) R->base[i] = (R->base[i] - G->A.mean) / G->A.std;
    } else if (!st)
        memset(R->base, 0, npix * sizeof(float));
    for (p = 0; !st && p < S->n; p++) {
        int near = 0;
        for (j = S->start[p]; j < S->start[p + 1] && !near; j++) {
            float x = S->pts[3 * j], yy = S->pts[3 * j + 1];
            near = x > (float)rx - m && x < (float)(rx + rw - 1) + m && yy > (float)ry - m && yy < (float)(ry + rh - 1) + m;
        }
        if (!near && (n > 0 || p < S->n - 1)) continue; /* none near: the last part stays, without edges (no empty tensor) */
        R->of[n] = p;
        R->P.start[n] = q;
        R->P.sign[n] = S->sign[p];
        for (j = S->start[p]; j < S->start[p + 1]; j++, q++) {
            memcpy(R->P.pts + 3 * (size_t)q, S->pts + 3 * (size_t)j, 3 * sizeof(float));
            R->P.of[q] = n;
        }
        n++;
    }
    if (st) return st;
    R->P.n = n;
    R->P.npts = q;
    R->P.start[n] = q;
    if ((st = tn__gnn_knn(&R->P, rw, rh, rx, ry, G->A.k, G->A.radius, R->base, &nbr, &nfeat))) return st;
    if (!(st = tn__gnn_graph_alloc(&R->g, (int)npix, n > 0 ? n : 1, (int)npix * G->A.k))) {
        R->g.nparts = n;
        for (i = 0; i < npix; i++)
            for (j = 0; j < G->A.k; j++) {
                int r = nbr[i * G->A.k + j];
                if (r < 0) continue;
                R->g.e_pix[R->g.E] = (int)i;
                R->g.e_part[R->g.E] = r;
                memcpy(R->g.feat + (size_t)R->g.E * TN__GNN_F, nfeat + (i * G->A.k + j) * TN__GNN_F, TN__GNN_F * sizeof(float));
                R->g.E++;
            }
        if (G->A.overhang) tn__gnn_overhangs(&R->g, &R->P, G->known, R->of, rw, rx, ry);
        tn__gnn_graph_finish(&R->g);
    }
    TN_FREE(nbr);
    TN_FREE(nfeat);
    return st;
}

/* The region's node inputs. emb: the region's parts' embeddings as a tensor (the fine-tune's,
   R->P.n rows) or NULL for G's. */
static tn_status tn__gnn_region_inputs(tn_ctx *ctx, const tn__gnn_gen *G, const tn__gnn_region *R, tn_tensor *emb, tn__gnn_in *in)
{
    tn_tensor *E0;
    int i, D = G->A.embed, Hd = G->A.hidden;
    tn_status st;
    if (!emb) {
        if (!(emb = tn_tensor_2d(ctx, R->P.n, D))) return tn_ctx_status(ctx);
        for (i = 0; i < R->P.n; i++) memcpy(emb->data + (size_t)i * D, G->emb + (size_t)R->of[i] * D, (size_t)D * sizeof(float));
    }
    if ((st = tn__gnn_inputs(ctx, &R->g, R->type, G->A.membrane ? R->base : NULL, R->level, R->P.sign, emb, in))) return st;
    if (!(E0 = tn_tensor_2d(ctx, R->P.n, Hd))) return tn_ctx_status(ctx);
    if (G->E0)
        for (i = 0; i < R->P.n; i++) memcpy(E0->data + (size_t)i * Hd, G->E0 + (size_t)R->of[i] * Hd, (size_t)Hd * sizeof(float));
    in->E0 = E0;
    return TN_OK;
}

/* The region's prediction (npix x 1, normalised), with gradients (the fine-tune). */
static tn_tensor *tn__gnn_region_forward(tn_ctx *ctx, const tn__gnn_gen *G, const tn_params *w, const tn__gnn_region *R, tn_tensor *emb)
{
    tn__gnn_in in;
    if (tn__gnn_region_inputs(ctx, G, R, emb, &in)) return NULL;
    return tn__gnn_forward(ctx, w, &G->A, &in);
}

/* The same prediction without gradients, one stage at a time with the context reset in between,
   so memory holds the graph and one round's intermediates, not every round's (the same ops on
   the same values: the same floats). pred: npix floats (normalised). */
static tn_status tn__gnn_region_predict(tn_ctx *ctx, const tn__gnn_gen *G, const tn_params *w, const tn__gnn_region *R, float *pred)
{
    tn__gnn_in in;
    tn_tensor *f = NULL, *E = NULL, *r = NULL;
    size_t nf = (size_t)R->rw * R->rh * G->A.hidden, ne = (size_t)R->P.n * G->A.hidden;
    float *fb = (float *)tn__alloc(nf * sizeof(float)), *eb = (float *)tn__alloc(ne * sizeof(float));
    int t;
    tn_status st = TN_OK;
    if (!fb || !eb) st = TN_ERR_OUT_OF_MEMORY;
    for (t = -1; !st && t <= G->A.rounds; t++) {
        tn_ctx_reset(ctx);
        tn_ctx_set_grad(ctx, 0);
        if ((st = tn__gnn_region_inputs(ctx, G, R, NULL, &in))) break;
        if (t < 0) { /* initial states */
            f = tn_mlp(ctx, w, "gnn.init.", 2, in.pix_in, TN_ACT_RELU);
            E = in.E0;
        } else {
            f = tn_tensor_2d(ctx, R->rw * R->rh, G->A.hidden);
            E = tn_tensor_2d(ctx, R->P.n, G->A.hidden);
            if (f && E) {
                memcpy(f->data, fb, nf * sizeof(float));
                memcpy(E->data, eb, ne * sizeof(float));
            }
            if (f && E && t < G->A.rounds) tn__gnn_round(ctx, w, t, &in, &f, &E);
            else if (f && E) r = tn_add(ctx, tn_mlp(ctx, w, "gnn.out.", 2, f, TN_ACT_RELU), in.base);
        }
        if (!f || !E || (t == G->A.rounds && !r)) {
            st = tn_ctx_status(ctx) ? tn_ctx_status(ctx) : TN_ERR_OUT_OF_MEMORY;
            break;
        }
        if (t == G->A.rounds) memcpy(pred, r->data, (size_t)R->rw * R->rh * sizeof(float));
        else {
            memcpy(fb, f->data, nf * sizeof(float));
            memcpy(eb, E->data, ne * sizeof(float));
        }
    }
    TN_FREE(fb);
    TN_FREE(eb);
    tn_ctx_reset(ctx);
    return st;
}

#define TN__GNN_FT_ONE (256 * 256) /* maps up to this many pixels fine-tune as one region (exact) */
#define TN__GNN_FT_TILE 192        /* else: windows of this core ... */
#define TN__GNN_FT_MARGIN 16       /* ... grown by this much context (>= 4: a loss pair's far pixel) */

/* What every window of the fine-tune shares: the whole map's counts, the across-line pairs
   (global pixels), the weights, and scratch for a window's index lists. */
typedef struct tn__gnn_ft {
    int nsk, npairs, *ip, *iq, *ix; /* ix: two index lists of cap each */
    float *psign, *tg, sw, ow;      /* tg: cap floats */
    size_t cap;
} tn__gnn_ft;

/* The fine-tune's loss on the pixels window R owns (its core cx, cy, cw, ch), each term divided
   by its count over the whole map, so the windows' losses add up to the whole map's. NULL if
   the core has nothing to fit. */
static tn_tensor *tn__gnn_ft_loss(tn_ctx *ctx, const tn__gnn_gen *G, const tn__gnn_ft *F, const tn__gnn_region *R, tn_tensor *pred, int cx, int cy,
                                  int cw, int ch)
{
    int *a = F->ix, *b = F->ix + F->cap, n = 0, i, x, y;
    tn_tensor *loss = NULL, *t;
#define TN__GNN_LOC(px, py) (((py) - R->ry) * R->rw + (px) - R->rx)
    for (y = cy; y < cy + ch; y++) /* sketch pixels: their heights */
        for (x = cx; x < cx + cw; x++)
            if (G->type[(size_t)y * G->W + x] != 0) {
                a[n] = TN__GNN_LOC(x, y);
                F->tg[n++] = (G->hgt[(size_t)y * G->W + x] - G->A.mean) / G->A.std;
            }
    if (n > 0 && (t = tn_tensor_2d(ctx, n, 1))) {
        memcpy(t->data, F->tg, (size_t)n * sizeof(float));
        loss = tn_scale_shift(ctx, tn_sum(ctx, tn_square(ctx, tn_sub(ctx, tn_gather_rows(ctx, pred, a, n), t))), 1.0f / (float)F->nsk, 0.0f);
    }
    if (F->sw > 0) { /* smoothness: squared differences to the right and lower neighbours (tn_tv_loss) */
        n = 0;
        for (y = cy; y < cy + ch; y++)
            for (x = cx; x < cx + cw; x++) {
                if (x + 1 < G->W) a[n] = TN__GNN_LOC(x, y), b[n++] = TN__GNN_LOC(x + 1, y);
                if (y + 1 < G->H) a[n] = TN__GNN_LOC(x, y), b[n++] = TN__GNN_LOC(x, y + 1);
            }
        if (n > 0) {
            t = tn_scale_shift(ctx, tn_sum(ctx, tn_square(ctx, tn_sub(ctx, tn_gather_rows(ctx, pred, a, n), tn_gather_rows(ctx, pred, b, n)))),
                               F->sw / (float)(G->W * G->H), 0.0f);
            loss = loss ? tn_add(ctx, loss, t) : t;
        }
    }
    if (F->npairs > 0) { /* relu(sign * (h_q - h_p)): ridges above, valleys below their across pixels */
        tn_tensor *sg;
        n = 0;
        for (i = 0; i < F->npairs; i++) {
            int px = F->ip[i] % G->W, py = F->ip[i] / G->W;
            if (px < cx || px >= cx + cw || py < cy || py >= cy + ch) continue;
            a[n] = TN__GNN_LOC(px, py);
            b[n] = TN__GNN_LOC(F->iq[i] % G->W, F->iq[i] / G->W);
            F->tg[n++] = F->psign[i];
        }
        if (n > 0 && (sg = tn_tensor_2d(ctx, n, 1))) {
            memcpy(sg->data, F->tg, (size_t)n * sizeof(float));
            t = tn_mul(ctx, tn_sub(ctx, tn_gather_rows(ctx, pred, b, n), tn_gather_rows(ctx, pred, a, n)), sg);
            t = tn_scale_shift(ctx, tn_sum(ctx, tn_relu(ctx, t)), F->ow / (float)F->npairs, 0.0f);
            loss = loss ? tn_add(ctx, loss, t) : t;
        }
    }
#undef TN__GNN_LOC
    return loss;
}

/* 5.4: only the sketch parts' embeddings move, loss on the sketch pixels + smoothness + the
   ridges' ordering. A small map is one region (exact); a larger one runs window by window,
   each with a margin of context, adding every window's gradient before the step, so memory
   follows the window, not the map (the generation after it is exact for any split). */
static tn_status tn__gnn_finetune(tn__gnn_gen *G, const tn_gnn_generate_opts *o)
{
    tn__gnn_region R;
    tn_ctx *ctx = NULL;
    tn_params *ft = NULL, *frozen = NULL;
    tn_optim *fopt = NULL;
    tn_optim_opts oo;
    tn_tensor *emb;
    tn__gnn_ft F;
    int one = (size_t)G->W * G->H <= TN__GNN_FT_ONE, tile = one ? (G->W > G->H ? G->W : G->H) : TN__GNN_FT_TILE;
    int margin = one ? 0 : TN__GNN_FT_MARGIN, nwx = (G->W + tile - 1) / tile, nwy = (G->H + tile - 1) / tile;
    int step, s[2], i, npix = G->W * G->H, wi, made = 0;
    float *base = NULL; /* the whole map's membrane, solved once: the windows' graphs are made again each step */
    size_t maxpix = (size_t)(tile + 2 * margin) * (tile + 2 * margin);
    tn_status st = TN_OK;
    memset(&R, 0, sizeof R);
    memset(&F, 0, sizeof F);
    /* ordering on by default: it lifts a drawn sketch's ordering on weak models and leaves good
       ones be (docs/gnn.md) */
    F.sw = o->smooth_weight == 0 ? 0.1f : o->smooth_weight > 0 ? o->smooth_weight : 0.0f;
    F.ow = o->order_weight == 0 ? 1.0f : o->order_weight > 0 ? o->order_weight : 0.0f;
    for (i = 0; i < npix; i++) F.nsk += G->type[i] != 0;
    if (maxpix > (size_t)npix) maxpix = (size_t)npix;
    F.cap = 2 * (maxpix > (size_t)G->P.npts ? maxpix : (size_t)G->P.npts) + 1; /* 2 smoothness pairs a pixel, 2 ordering pairs a point */
    s[0] = G->P.n;
    s[1] = G->A.embed;
    if (!(ctx = tn_ctx_create()) || !(ft = tn_params_create()) || !(emb = tn_params_add(ft, "emb", 2, s)) || !(frozen = tn_params_create()) ||
        !(F.ip = (int *)tn__alloc(((size_t)G->P.npts * 2 + 1) * sizeof(int))) || !(F.iq = (int *)tn__alloc(((size_t)G->P.npts * 2 + 1) * sizeof(int))) ||
        !(F.psign = (float *)tn__alloc(((size_t)G->P.npts * 2 + 1) * sizeof(float))) ||
        !(F.ix = (int *)tn__alloc(2 * F.cap * sizeof(int))) || !(F.tg = (float *)tn__alloc(F.cap * sizeof(float)))) {
        st = tn__fail(TN_ERR_OUT_OF_MEMORY, "gnn: out of memory");
        goto done;
    }
    if (!one && G->A.membrane) {
        if (!(base = (float *)tn__alloc((size_t)npix * sizeof(float)))) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
        if ((st = tn__gnn_membrane_rect(G->hgt, G->fixed, G->W, G->H, 0, 0, G->W, G->H, base))) goto done;
    }
    memcpy(emb->data, G->emb, (size_t)G->P.n * G->A.embed * sizeof(float));
    memset(&oo, 0, sizeof oo);
    oo.lr = o->finetune_lr > 0 ? o->finetune_lr : 1e-2f;
    if (!(fopt = tn_optim_create(ft, &oo))) { st = TN_ERR_INVALID_ARG; goto done; }
    /* a frozen copy of the network (buffers: no gradient), so the model is only read */
    for (i = 0; i < tn_params_count(G->w); i++) {
        const tn_tensor *t = tn_params_get(G->w, i);
        tn_tensor *c = tn_params_add_buffer(frozen, t->name, t->ndim, t->shape);
        if (!c) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
        memcpy(c->data, t->data, t->numel * sizeof(float));
    }
    if (F.ow > 0) { /* across-line pairs of every part point: (p, q) and the sign */
        int p, j, a, b, c;
        for (p = 0; p < G->P.n; p++) {
            tn_contour c0;
            memset(&c0, 0, sizeof c0);
            c0.npoints = G->P.start[p + 1] - G->P.start[p];
            c0.points = G->P.pts + 3 * (size_t)G->P.start[p];
            for (j = 0; j < c0.npoints; j++) {
                tn__gnn_across(&c0, j, G->W, G->H, 3.0f, &a, &b, &c);
                if (a < 0) continue;
                if (b >= 0) { F.ip[F.npairs] = a; F.iq[F.npairs] = b; F.psign[F.npairs++] = G->P.sign[p]; }
                if (c >= 0) { F.ip[F.npairs] = a; F.iq[F.npairs] = c; F.psign[F.npairs++] = G->P.sign[p]; }
            }
        }
    }
    for (step = 0; step < o->finetune && !st; step++) {
        tn_params_zero_grad(ft);
        for (wi = 0; wi < nwx * nwy && !st; wi++) {
            int cx = (wi % nwx) * tile, cy = (wi / nwx) * tile, cw = G->W - cx < tile ? G->W - cx : tile, ch = G->H - cy < tile ? G->H - cy : tile;
            int rx = cx - margin > 0 ? cx - margin : 0, ry = cy - margin > 0 ? cy - margin : 0;
            int rx1 = cx + cw + margin < G->W ? cx + cw + margin : G->W, ry1 = cy + ch + margin < G->H ? cy + ch + margin : G->H;
            tn_tensor *pred, *loss, *ew;
            if (!made || nwx * nwy > 1) { /* one window keeps its graph; more are made again each step (memory) */
                tn__gnn_region_free(&R);
                if ((st = tn__gnn_region_make(G, rx, ry, rx1 - rx, ry1 - ry, base, &R))) break;
                made = 1;
            }
            tn_ctx_reset(ctx);
            ew = tn_gather_rows(ctx, emb, R.of, R.P.n);
            if (!ew || !(pred = tn__gnn_region_forward(ctx, G, frozen, &R, ew))) { st = tn_ctx_status(ctx) ? tn_ctx_status(ctx) : TN_ERR_OUT_OF_MEMORY; break; }
            if (!(loss = tn__gnn_ft_loss(ctx, G, &F, &R, pred, cx, cy, cw, ch))) {
                if ((st = tn_ctx_status(ctx))) break;
                continue; /* nothing to fit in this window */
            }
            if (!(st = tn_backward(ctx, loss))) st = tn__progress("gnn-finetune", (double)(step * nwx * nwy + wi + 1) / ((double)o->finetune * nwx * nwy));
        }
        if (!st) tn_optim_step(fopt);
    }
    if (!st) memcpy(G->emb, emb->data, (size_t)G->P.n * G->A.embed * sizeof(float));
done:
    tn__gnn_region_free(&R);
    tn_ctx_free(ctx);
    tn_optim_free(fopt);
    tn_params_free(ft);
    tn_params_free(frozen);
    TN_FREE(F.ip);
    TN_FREE(F.iq);
    TN_FREE(F.psign);
    TN_FREE(F.ix);
    TN_FREE(F.tg);
    TN_FREE(base);
    return st;
}

/* The network a sketch runs on: the trained one for the example's own network (every part
   known: the reconstruction), the early one (the best holdout check's, opts->holdout in
   training) for any other sketch, when the model has one. */
static tn_status tn__gnn_pick_net(const tn_gnn *model, int known, tn__gnn_gen *G)
{
    int i;
    G->w = model->weights;
    if (known || !tn_params_find(model->weights, "early.gnn.emb")) return TN_OK;
    if (!(G->own_w = tn_params_create())) return TN_ERR_OUT_OF_MEMORY;
    for (i = 0; i < tn_params_count(model->weights); i++) {
        const tn_tensor *t = tn_params_get(model->weights, i), *e;
        tn_tensor *c;
        char name[48];
        if (!strncmp(t->name, "early.", 6)) continue;
        snprintf(name, sizeof name, "early.%s", t->name);
        e = tn_params_find(model->weights, name);
        if (!(c = tn_params_add_buffer(G->own_w, t->name, t->ndim, t->shape))) return TN_ERR_OUT_OF_MEMORY;
        memcpy(c->data, (e ? e : t)->data, t->numel * sizeof(float));
    }
    G->w = G->own_w;
    return TN_OK;
}

/* Everything of a generation but the network passes: sketch in the output's pixels and the
   example's units, random sketches, parts, embeddings (matched or aligned, then fine-tuned),
   part states, raster. */
/* The seed the sketch's lines are cut into parts with: under EMBED_AUTO the model's training
   seed, so the example's own network is cut exactly as in training and every part keeps its
   embedding (the reconstruction); otherwise opts->seed. */
static uint64_t tn__gnn_cut_seed(const tn_gnn *model, const tn_gnn_generate_opts *opts)
{
    const char *sd = tn_params_meta(model->weights, "seed");
    uint64_t v;
    if (opts->embeddings == TN_GNN_EMBED_AUTO && sd && tn__parse_hex64(sd, strlen(sd), &v)) return v;
    return opts->seed;
}

/* G from a sketch already in the example's units on the width x height canvas (random lines
   included): parts, their embeddings and initial states, the rasterised sketch. *known = 1 when
   every part is one of the example's own (EMBED_AUTO matched them all). */
static tn_status tn__gnn_gen_build(const tn_gnn *model, const tn_contour_set *sk, int width, int height, const tn_gnn_generate_opts *opts,
                                   tn__gnn_gen *G, int *known)
{
    tn_contour_set dense, parts, ex_parts;
    tn_image r = {0, 0, 0, NULL};
    tn_align_opts ao;
    int *match = NULL, i, nf = 0;
    size_t n = (size_t)width * height, q;
    tn_status st;
    memset(&dense, 0, sizeof dense);
    memset(&parts, 0, sizeof parts);
    memset(&ex_parts, 0, sizeof ex_parts);
    *known = 0;
    G->W = width;
    G->H = height;
    G->halo = 2 * G->A.rounds * ((int)ceilf(G->A.radius) + 13);
    G->gain = 1.0f;
    G->gain_raw = NAN;
    if ((st = tn_sketch_densify(&dense, sk))) goto done;
    if ((st = tn_contour_parts_make(&parts, &dense, tn__gnn_cut_seed(model, opts)))) goto done;
    if (!parts.count) {
        st = tn__fail(TN_ERR_EMPTY, "gnn generate: the sketch has no part of 5 px (draw longer lines)");
        goto done;
    }
    /* the example part whose embedding each sketch part takes (-1: none) */
    if ((st = tn__gnn_stored_parts(model->weights, &G->A, "gnn", &ex_parts))) goto done;
    if (!(match = (int *)tn__alloc((size_t)parts.count * sizeof(int)))) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    if (opts->embeddings == TN_GNN_EMBED_ALIGNED) { /* 5.3: shape (LCS of chain codes) and heights */
        memset(&ao, 0, sizeof ao);
        ao.seed = opts->seed;
        ao.choices = opts->align_choices > 0 ? opts->align_choices : 1;
        if ((st = tn_sketch_align(match, &parts, &ex_parts, &ao))) goto done;
    } else {
        tn__gnn_same_parts(&parts, &ex_parts, opts->embeddings == TN_GNN_EMBED_AUTO ? 1e-3f * G->A.std : -1.0f, match);
        for (i = 0, *known = opts->embeddings == TN_GNN_EMBED_AUTO; i < parts.count; i++) *known &= match[i] >= 0;
    }
    if ((st = tn__gnn_pick_net(model, *known, G))) goto done;
    if ((st = tn__gnn_parts_make(&parts, G->A.mean, G->A.std, &G->P))) goto done;
    G->emb = (float *)tn__calloc((size_t)G->P.n * G->A.embed * sizeof(float));
    G->known = (uint8_t *)tn__alloc((size_t)G->P.n + 1);
    G->type = (float *)tn__alloc(n * sizeof(float));
    G->hgt = (float *)tn__alloc(n * sizeof(float));
    G->fixed = (uint8_t *)tn__alloc(n);
    if (!G->emb || !G->known || !G->type || !G->hgt || !G->fixed) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    {
        const tn_tensor *me = tn_params_find(G->w, "gnn.emb");
        for (i = 0; i < G->P.n; i++)
            if ((G->known[i] = (uint8_t)(match[i] >= 0))) memcpy(G->emb + (size_t)i * G->A.embed, me->data + (size_t)match[i] * G->A.embed, (size_t)G->A.embed * sizeof(float));
    }
    if (G->A.part_noise > 0) { /* each part's state from its own stream: the same in every window */
        if (!(G->E0 = (float *)tn__alloc((size_t)G->P.n * G->A.hidden * sizeof(float)))) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
        for (i = 0; i < G->P.n; i++) {
            tn_rng pr;
            int h;
            tn_rng_seed(&pr, opts->seed ^ 0x67656eULL, (uint64_t)i);
            for (h = 0; h < G->A.hidden; h++) G->E0[(size_t)i * G->A.hidden + h] = G->A.part_noise * tn_rng_normal(&pr);
        }
    }
    if ((st = tn_sketch_rasterise(&r, sk, width, height))) goto done;
    for (q = 0; q < n; q++) {
        const float *px = r.data + 3 * q;
        G->fixed[q] = (uint8_t)(px[0] > 0 || px[1] > 0);
        nf += G->fixed[q];
        G->type[q] = px[0] > 0 ? 1.0f : px[1] > 0 ? -1.0f : 0.0f;
        G->hgt[q] = G->fixed[q] ? px[2] : 0.0f;
    }
    if (!nf) st = tn__fail(TN_ERR_EMPTY, "gnn generate: the sketch covers no pixel of the %d x %d map", width, height);
done:
    tn_image_free(&r);
    tn_contour_set_free(&dense);
    tn_contour_set_free(&parts);
    tn_contour_set_free(&ex_parts);
    TN_FREE(match);
    return st;
}

static tn_status tn__gnn_gen_run(const tn__gnn_gen *G, const tn_params *w, tn_ctx *ctx, int x, int y, int ww, int wh, float *dst, float *base_dst,
                                 const char *stage);

/* Fewer user lines than this keep gain 1: a held-out stroke of a drawing of a few says little
   about the rest (a 4-stroke drawing tested to gain 0, the membrane; docs/gnn.md), while
   extracted networks have tens to hundreds of lines. */
#define TN__GNN_GAIN_MIN_LINES 8

#define TN__GNN_ONE_PASS (384 * 384) /* maps up to this many pixels run as one region */

/* tn_gnn_gain's test (see its comment): sk in example units, its first n_user lines the user's.
   *raw = the held-out lines' pooled least-squares gain, before scale and clamp; NAN = untested. */
static tn_status tn__gnn_gain_validate(const tn_gnn *model, const tn__gnn_gen *G, const tn_contour_set *sk, int n_user,
                                       const tn_gnn_generate_opts *opts, double *raw)
{
    int vw = G->W < 512 ? G->W : 512, vh = G->H < 512 ? G->H : 512, vx = (G->W - vw) / 2, vy = (G->H - vh) / 2, round, i;
    size_t nv = (size_t)vw * vh, q, held = 0;
    double num = 0, den = 0;
    tn_contour_set keep, drop;
    float *pred = (float *)tn__alloc(nv * sizeof(float)), *base = (float *)tn__alloc(nv * sizeof(float));
    tn_ctx *ctx = tn_ctx_create();
    tn_rng rng;
    tn_status st = TN_OK;
    *raw = NAN;
    keep = drop = *sk;
    keep.items = (tn_contour *)tn__alloc(((size_t)sk->count + 1) * sizeof(tn_contour));
    drop.items = (tn_contour *)tn__alloc(((size_t)sk->count + 1) * sizeof(tn_contour));
    if (!pred || !base || !ctx || !keep.items || !drop.items) st = tn__fail(TN_ERR_OUT_OF_MEMORY, "gnn: out of memory");
    tn_rng_seed(&rng, opts->seed, 0x6761696eULL);
    for (round = 0; !st && n_user >= TN__GNN_GAIN_MIN_LINES && round < 3; round++) {
        tn__gnn_gen T;
        tn_image hr = {0, 0, 0, NULL};
        int known;
        keep.count = drop.count = 0;
        for (i = 0; i < sk->count; i++) {
            if (i < n_user && tn_rng_uniform(&rng) < 0.3f) drop.items[drop.count++] = sk->items[i];
            else keep.items[keep.count++] = sk->items[i];
        }
        if (!drop.count || keep.count == sk->count - n_user) continue; /* nothing held out, or no user line left */
        /* each round cuts the whole sketch again before its window's one tile reports (a huge sketch: seconds) */
        if ((size_t)G->W * G->H > TN__GNN_ONE_PASS && (st = tn__progress("gnn-prepare", (round + 1) / 4.0))) break;
        memset(&T, 0, sizeof T);
        T.A = G->A;
        st = tn__gnn_gen_build(model, &keep, G->W, G->H, opts, &T, &known);
        if (st == TN_ERR_EMPTY) { /* the kept lines are too short to test with: not a failure */
            tn__gnn_gen_free(&T);
            st = TN_OK;
            continue;
        }
        if (!st) st = tn__gnn_gen_run(&T, G->w, ctx, vx, vy, vw, vh, pred, base, "gnn-gain");
        if (!st) st = tn_sketch_rasterise(&hr, &drop, G->W, G->H);
        for (q = 0; !st && q < nv; q++) {
            size_t m = (size_t)(vy + (int)(q / vw)) * G->W + vx + (int)(q % vw);
            const float *px = hr.data + 3 * m;
            double r = (double)pred[q] - base[q];
            if (!(px[0] > 0 || px[1] > 0) || T.fixed[m]) continue;
            num += r * ((double)px[2] - base[q]);
            den += r * r;
            held++;
        }
        tn_image_free(&hr);
        tn__gnn_gen_free(&T);
    }
    if (!st && held >= 16 && den > 0) *raw = num / den;
    TN_FREE(pred);
    TN_FREE(base);
    TN_FREE(keep.items);
    TN_FREE(drop.items);
    tn_ctx_free(ctx);
    return st;
}

/* ---- densify by example (tn_gnn_grow; issue 30) ---- */

/* Chamfer distance (1, sqrt 2) to the nearest set pixel of src, and that pixel's index (-1 and
   FLT_MAX when src has none): two raster passes. */
static void tn__gnn_chamfer(const uint8_t *src, int W, int H, float *d, int *near)
{
    static const int dx[4] = {-1, 0, 1, -1}, dy[4] = {-1, -1, -1, 0};
    static const float dw[4] = {1.41421356f, 1.0f, 1.41421356f, 1.0f};
    int x, y, k, pass;
    for (y = 0; y < H; y++)
        for (x = 0; x < W; x++) {
            size_t i = (size_t)y * W + x;
            d[i] = src[i] ? 0.0f : FLT_MAX;
            near[i] = src[i] ? (int)i : -1;
        }
    for (pass = 0; pass < 2; pass++) {
        int s = pass ? -1 : 1;
        for (y = pass ? H - 1 : 0; pass ? y >= 0 : y < H; y += s)
            for (x = pass ? W - 1 : 0; pass ? x >= 0 : x < W; x += s) {
                size_t i = (size_t)y * W + x;
                for (k = 0; k < 4; k++) {
                    int qx = x + s * dx[k], qy = y + s * dy[k];
                    size_t q;
                    if (qx < 0 || qy < 0 || qx >= W || qy >= H) continue;
                    q = (size_t)qy * W + qx;
                    if (near[q] >= 0 && d[q] + dw[k] < d[i]) {
                        d[i] = d[q] + dw[k];
                        near[i] = near[q];
                    }
                }
            }
    }
}

/* Some line of s runs 5 px or more (a contour part's length). */
static int tn__gnn_has_part_length(const tn_contour_set *s)
{
    tn_contour_set d;
    int i, yes = 0;
    if (tn_sketch_densify(&d, s)) return 0;
    for (i = 0; i < d.count && !yes; i++) yes = d.items[i].npoints >= 5;
    tn_contour_set_free(&d);
    return yes;
}

/* Line pixels of a set per canvas pixel. */
static tn_status tn__gnn_line_density(const tn_contour_set *s, double *density)
{
    tn_image r = {0, 0, 0, NULL};
    size_t i, n = (size_t)s->width * s->height, k = 0;
    tn_status st = tn_sketch_rasterise(&r, s, s->width, s->height);
    if (st) return st;
    for (i = 0; i < n; i++) k += r.data[3 * i] > 0 || r.data[3 * i + 1] > 0;
    tn_image_free(&r);
    *density = (double)k / (double)n;
    return TN_OK;
}

/* The example heights the model keeps (detail.example, on its network's pixels) as a view in *ex;
   0 when it keeps none (models trained before them). */
static int tn__gnn_example_dem(const tn_gnn *model, const tn__gnn_arch *A, tn_image *ex)
{
    const tn_tensor *e = tn_params_find(model->weights, "detail.example");
    ex->width = A->width, ex->height = A->height, ex->channels = 1;
    ex->data = e ? e->data : NULL;
    return e != NULL;
}

#define TN__GNN_BAND_SIGMA 3.0f /* px: the grown ground gives the output what is finer than this Gaussian ... */
#define TN__GNN_BAND_NEAR 6.0f   /* ... none of it within this many px of the user's strokes (they are the network's) ... */
#define TN__GNN_BAND_FAR 16.0f   /* ... all of it from here on (a smoothstep between) ... */
#define TN__GNN_BAND_GATE 3.0f   /* ... and none where the output's low-pass and the ground's part by more than
                                    2 x this many times the band's RMS (all within 1 x) */

/* The grown ground's fine band for tn__gnn_ground_apply. G->ground on entry: tn__gnn_grow's
   ground (the quilted example on the strokes' ground, example units); its closed basins are
   filled (tn_fill_depressions: the quilt dams valleys at its seams, and their detail closed lakes
   in the output), and it is split by a Gaussian of TN__GNN_BAND_SIGMA px into G->ground_lp and
   the rest, G->ground, whose RMS is G->ground_rms. */
static tn_status tn__gnn_ground_band(tn__gnn_gen *G, int width, int height)
{
    tn_image t = {0, 0, 0, NULL}, f = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    size_t i, n = (size_t)width * height;
    double s2 = 0;
    tn_status st;
    if (!G->ground) return TN_OK;
    t.width = width, t.height = height, t.channels = 1, t.data = G->ground;
    if ((st = tn_fill_depressions(&f, &t)) || (st = tn_image_blur(&b, &f, TN__GNN_BAND_SIGMA))) {
        tn_image_free(&f);
        return st;
    }
    for (i = 0; i < n; i++) {
        G->ground[i] = f.data[i] - b.data[i];
        s2 += (double)G->ground[i] * G->ground[i];
    }
    tn_image_free(&f);
    G->ground_rms = (float)sqrt(s2 / (double)n);
    G->ground_lp = b.data;
    return TN_OK;
}

/* px a window's terrain is read around it by tn__gnn_ground_apply (tn_image_blur's radius) */
static int tn__gnn_band_halo(const tn__gnn_gen *G) { return G->ground ? (int)(4.0f * TN__GNN_BAND_SIGMA + 0.5f) + 1 : 0; }

/* Terrain t (window g of the map, example units) takes the grown ground's fine band in place of
   its own (both below a Gaussian of TN__GNN_BAND_SIGMA px), from TN__GNN_BAND_NEAR to
   TN__GNN_BAND_FAR px of the user's strokes on, where its low-pass is the ground's (within
   TN__GNN_BAND_GATE x the band's RMS, none from twice that): the network renders the grown lines
   as rounded knolls between them, and the ground they were traced from has the example's own
   crests and gullies there; where the output went its own way (a drained valley, sunk ground),
   they do not fit. Pixels within tn__gnn_band_halo of the window's inner edges are not right (the
   caller's halo covers them). */
static tn_status tn__gnn_ground_apply(const tn__gnn_gen *G, tn_image *t, tn_rect g)
{
    const float tau = TN__GNN_BAND_GATE * G->ground_rms;
    tn_image b = {0, 0, 0, NULL};
    int u, v;
    tn_status st;
    if (!G->ground || !G->pin_d) return TN_OK;
    if ((st = tn_image_blur(&b, t, TN__GNN_BAND_SIGMA))) return st;
    for (v = 0; v < g.h; v++)
        for (u = 0; u < g.w; u++) {
            size_t q = (size_t)(g.y + v) * G->W + g.x + u, i = (size_t)v * g.w + u;
            float w = tn__clampf((G->pin_d[q] - TN__GNN_BAND_NEAR) / (TN__GNN_BAND_FAR - TN__GNN_BAND_NEAR), 0, 1);
            float k = tau > 0 ? tn__clampf(2 - fabsf(b.data[i] - G->ground_lp[q]) / tau, 0, 1) : 0;
            t->data[i] += k * w * w * (3 - 2 * w) * (G->ground[q] - (t->data[i] - b.data[i]));
        }
    tn_image_free(&b);
    return TN_OK;
}

/* Whether the fine detail by example runs (opts->detail, the model's example); generation
   builds its index (tn__gnn_detail_index), a plan does not need it. */
static tn_status tn__gnn_detail_plan(const tn_gnn *model, const tn_gnn_generate_opts *o, tn__gnn_gen *G)
{
    const tn_tensor *e = tn_params_find(model->weights, "detail.example");
    if (o->detail < 0) {
        G->detail_why = "off (--detail none)";
        return TN_OK;
    }
    if (!e) {
        G->detail_why = "none: the model holds no example heights (trained before them: train it again for the detail)";
        return o->detail > 0 ? tn__fail(TN_ERR_INVALID_ARG, "gnn generate: %s", G->detail_why) : TN_OK;
    }
    if (o->detail == 0 && !G->grown) {
        G->detail_why = "off: the sketch is not grown (a dense network carries its own detail; --detail example adds it)";
        return TN_OK;
    }
    G->detail = 1;
    G->detail_why = "the example's fine detail, matched by shape to the terrain's low-pass (below 2 px)";
    return TN_OK;
}

/* The example's patch index, for a generation whose plan has the fine detail. */
static tn_status tn__gnn_detail_index(const tn_gnn *model, tn__gnn_gen *G)
{
    tn_image ex;
    tn__gnn_example_dem(model, &G->A, &ex);
    return tn__fd_build(&ex, NULL, &G->fd);
}

#define TN__GNN_SCALE_MAX 64 /* the largest map-scale factor (tn_gnn_generate_opts.map_scale) */

/* The rules of tn_gnn_generate_opts (zero = default throughout), one message each. */
static tn_status tn__gnn_generate_validate(const tn_gnn_generate_opts *o)
{
    const char *w = "gnn generate";
    tn_status st;
    if ((st = tn__opt_int(w, "heights", o->heights, TN_GNN_HEIGHTS_AUTO, TN_GNN_HEIGHTS_UNIT)) ||
        (st = tn__opt_int(w, "embeddings", o->embeddings, TN_GNN_EMBED_AUTO, TN_GNN_EMBED_NONE)) ||
        (st = tn__opt_int(w, "finetune", o->finetune, 0, INT_MAX)) || (st = tn__opt_int(w, "align_choices", o->align_choices, 0, INT_MAX)) ||
        (st = tn__opt_int(w, "random_nodes", o->random_nodes, 0, 8192)) || (st = tn__opt_int(w, "grow", o->grow, -1, 1)) ||
        (st = tn__opt_int(w, "detail", o->detail, -1, 1)) || (st = tn__opt_int(w, "map_scale", o->map_scale, -1, TN__GNN_SCALE_MAX)) ||
        (st = tn__opt_float(w, "finetune_lr", o->finetune_lr, "[)", 0, 10)) ||
        (st = tn__opt_float(w, "smooth_weight", o->smooth_weight, "(]", -HUGE_VAL, 1e6)) ||
        (st = tn__opt_float(w, "order_weight", o->order_weight, "(]", -HUGE_VAL, 1e6)) ||
        (st = tn__opt_float(w, "gain", o->gain, "(]", -HUGE_VAL, 1e6)))
        return st;
    return TN_OK;
}

/* G->drawn: the user's ridges (the first nuser lines of sk, map px) where they were drawn, before
   the example's bends move them (tn__gnn_grow_crest); the notch keeps them followed there too. */
static tn_status tn__gnn_drawn_mask(const tn_contour_set *sk, int nuser, int width, int height, tn__gnn_gen *G)
{
    tn_contour_set u = *sk;
    tn_image r = {0, 0, 0, NULL};
    size_t q, n = (size_t)width * height;
    tn_status st;
    u.count = nuser < sk->count ? nuser : sk->count;
    if ((st = tn_sketch_rasterise(&r, &u, width, height))) return st;
    if (!(G->drawn = (uint8_t *)tn__alloc(n))) st = TN_ERR_OUT_OF_MEMORY;
    for (q = 0; !st && q < n; q++) G->drawn[q] = (uint8_t)(r.data[3 * q] > 0);
    tn_image_free(&r);
    return st;
}

static tn_status tn__gnn_gen_make(const tn_gnn *model, const tn_contour_set *sketch, int width, int height, const tn_gnn_generate_opts *opts,
                                  tn__gnn_gen *G)
{
    tn_gnn_generate_opts o;
    tn_contour_set sk, rnd;
    tn_image dem;
    int i, known = 0;
    tn_status st;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    memset(G, 0, sizeof *G);
    memset(&sk, 0, sizeof sk);
    memset(&rnd, 0, sizeof rnd);
    if ((st = tn__gnn_arch_of(model, &G->A))) return st;
    if (!sketch || sketch->count <= 0) return tn__fail(TN_ERR_EMPTY, "gnn generate: the sketch is empty");
    if ((st = tn__cset_check(sketch, "gnn generate"))) return st;
    if (width < 16 || height < 16 || width > TN_SKETCH_MAX_SIDE || height > TN_SKETCH_MAX_SIDE)
        return tn__fail(TN_ERR_INVALID_ARG, "gnn generate: size %d x %d (16 .. %d a side)", width, height, TN_SKETCH_MAX_SIDE);
    if ((st = tn__gnn_generate_validate(&o))) return st;
    if ((st = tn__gnn_sketch_units(&G->A, sketch, width, height, o.heights, &sk))) goto done;
    if (o.random_nodes > 0) { /* 5.2: random ridges and valleys around the user's lines, in the example's range */
        tn_sketch_random_opts ro;
        memset(&ro, 0, sizeof ro);
        ro.seed = o.seed;
        ro.nodes = o.random_nodes;
        if ((st = tn_sketch_random(&rnd, &sk, width, height, &ro))) goto done;
        for (i = sk.count; i < rnd.count; i++) {
            int j;
            for (j = 0; j < rnd.items[i].npoints; j++) rnd.items[i].points[3 * j + 2] = G->A.lo + (G->A.hi - G->A.lo) * rnd.items[i].points[3 * j + 2];
        }
        tn_contour_set_free(&sk);
        sk = rnd;
        memset(&rnd, 0, sizeof rnd);
    }
    if ((size_t)width * height > TN__GNN_ONE_PASS && (st = tn__progress("gnn-prepare", 0.0))) goto done; /* growing and cutting the whole sketch are silent */
    if (o.grow >= 0 && tn__gnn_has_part_length(&sk)) { /* densify by example: a drawing of a few strokes gets the example's
                                                            network between them (a sketch without a 5 px line fails below, ungrown) */
        tn_contour_set ex;
        float relief = 0;
        memset(&ex, 0, sizeof ex);
        if (!(st = tn__gnn_stored_parts(model->weights, &G->A, "gnn", &ex)) && !(st = tn__gnn_line_density(&sk, &G->user_density)))
            st = tn__gnn_line_density(&ex, &G->example_density);
        if (!st && (o.grow == 1 || (o.random_nodes == 0 && G->user_density < G->example_density / 6))) {
            tn_gnn_grow_opts go;
            int with_dem = tn__gnn_example_dem(model, &G->A, &dem);
            memset(&go, 0, sizeof go);
            go.seed = o.seed;
            if (!(st = tn_sketch_densify(&rnd, &sk))) { /* the drawn ridges' peaks and saddles, before the ground grows around them */
                tn_contour_set_free(&sk);
                sk = rnd;
                memset(&rnd, 0, sizeof rnd);
                st = tn__gnn_drawn_mask(&sk, sketch->count, width, height, G);
                if (!st) st = tn__gnn_grow_crest(&sk, sketch->count, &ex, TN_RIDGE, o.seed);
            }
            if (!st && with_dem && o.detail >= 0 && !(G->ground = (float *)tn__calloc((size_t)width * height * sizeof(float))))
                st = TN_ERR_OUT_OF_MEMORY; /* the band goes with the fine detail */
            if (!st && !(st = tn__gnn_grow(&sk, &ex, with_dem ? &dem : NULL, width, height, &go, &rnd, &G->grown, &relief, G->ground)) &&
                !(st = tn__gnn_ground_band(G, width, height))) {
                G->side = TN__GNN_FALL * relief / TN__GNN_FALL_REACH / G->A.std; /* the added ground's fall (tn__gnn_grow_fall) */
                tn_contour_set_free(&sk);
                sk = rnd;
                memset(&rnd, 0, sizeof rnd);
            }
        }
        tn_contour_set_free(&ex);
        if (st) goto done;
    }
    if ((st = tn__gnn_gen_build(model, &sk, width, height, &o, G, &known))) goto done;
    if ((st = tn__gnn_detail_plan(model, &o, G))) goto done;
    if (G->drawn && G->grown <= 0) { /* nothing grew: no pinned strokes, no notch to read it (G->drawn implies G->drawn_d) */
        TN_FREE(G->drawn);
        G->drawn = NULL;
    }
    if (G->grown > 0) { /* the user's lines of a grown sketch keep their heights (tn__gnn_pin) */
        tn_contour_set u = sk;
        tn_image r = {0, 0, 0, NULL};
        size_t q, n = (size_t)width * height;
        int *near = (int *)tn__alloc(n * sizeof(int));
        u.count = sketch->count;
        G->pin = (uint8_t *)tn__alloc(n);
        G->pin_d = (float *)tn__alloc(n * sizeof(float));
        if (!near || !G->pin || !G->pin_d) st = TN_ERR_OUT_OF_MEMORY;
        if (!st && !(st = tn_sketch_rasterise(&r, &u, width, height))) {
            for (q = 0; q < n; q++) G->pin[q] = (uint8_t)(r.data[3 * q] > 0 ? 1 : r.data[3 * q + 1] > 0 ? 2 : 0);
            tn__gnn_chamfer(G->pin, width, height, G->pin_d, near);
            for (q = 0; G->drawn && q < n && G->drawn[q] == (G->pin[q] == 1); q++) {}
            if (q == n) { /* the bends moved no ridge */
                TN_FREE(G->drawn);
                G->drawn = NULL;
            }
            if (G->drawn && !(G->drawn_d = (float *)tn__alloc(n * sizeof(float)))) st = TN_ERR_OUT_OF_MEMORY;
            if (!st && G->drawn) tn__gnn_chamfer(G->drawn, width, height, G->drawn_d, near);
        }
        tn_image_free(&r);
        TN_FREE(near);
        if (!st && tn__gnn_example_dem(model, &G->A, &dem)) {
            /* the ground at the example's levels (tn__gnn_region_level), and the drawn ridges'
               flanks by example, on the output before the notch (which keeps them followed) */
            G->level = (int)ceilf(G->A.radius);
            st = tn__gnn_level_range(&dem, &G->A, G->level, &G->level_lo, &G->level_hi);
            if (!st) st = tn__gnn_stored_parts(model->weights, &G->A, "gnn", &rnd);
            if (!st && !(G->flank = (float *)tn__alloc(n * sizeof(float)))) st = TN_ERR_OUT_OF_MEMORY;
            if (!st) st = tn__gnn_grow_flanks(&sk, sketch->count, &rnd, &dem, o.seed, G->flank);
            for (q = 0; !st && q < n; q++) G->flank[q] /= G->A.std;
            tn_contour_set_free(&rnd);
        }
        if (st) goto done;
    }
    if (o.gain != 0) G->gain = o.gain > 0 ? o.gain : 0.0f;
    else if (G->A.membrane && !known && !(st = tn__gnn_gain_validate(model, G, &sk, sketch->count, &o, &G->gain_raw)) && isfinite(G->gain_raw))
        G->gain = tn__gnn_gain_of(tn__gnn_gain_scale(G->w), G->gain_raw);
    if (!st && o.finetune > 0) st = tn__gnn_finetune(G, &o);
done:
    tn_contour_set_free(&sk);
    tn_contour_set_free(&rnd);
    if (st) tn__gnn_gen_free(G);
    return st;
}

/* Pixels (x, y, w, h) of the map into dst (row stride `stride`, example units): the region
   grown by the halo, its graph and one pass without gradients; the membrane plus G->gain times
   the network's residual. base_dst (may be NULL): the membrane there. */
#define TN__GNN_PIN 12 /* px over which the residual of a grown sketch is pinned to 0 on the user's lines */
#define TN__GNN_BESIDE 1.5f /* px: the ground beside a stroke (its 8 neighbours) */
#define TN__GNN_PIN_ACROSS -1 /* tn__gnn_pin's wall for the fine detail: its mean change at each distance from the strokes */

/* Weight of a stroke pixel at distance e (< L) in the smooth means along the strokes: the
   nearest ones dominate, and it falls to 0 at L. */
static float tn__gnn_line_kernel(float e, int L)
{
    return (1 - e / L) * (1 - e / L) / (e + 0.5f);
}

/* A grown sketch's user lines keep their heights: a change a - b near them (the network's
   residual; the fine detail's), minus a smooth local mean of that change on them (kernel
   (1 - d/L)^2 / (d + 0.5), d < L = TN__GNN_PIN), faded in by a smoothstep of the distance to them.
   The network alone moves the strokes of a weak model (docs/gnn.md) and the detail's low-pass
   lowers a drawn crest; that the land beside a stroke stays
   below a ridge and above a valley is the notch's work (tn__gnn_incise). With wall > 0 (the
   network's change): the network keeps a stroke's own pixels and moves the ground beside them,
   which leaves a drawn ridge a wall of a pixel above its ground (a valley a slot), a thin line in
   map view; within wall px of the strokes the correction moves linearly from the mean change
   beside them (their 8 neighbours) to the one on them, so the flanks rise to the stroke, and
   the banks the notch reads (wall = TN__GNN_BANK) stay where they were. With wall =
   TN__GNN_PIN_ACROSS (the detail's change): each pixel takes back the smooth mean of the change
   at its own distance from the strokes (kernel (1 - d/L)^2; the strokes and their 8 neighbours
   pooled, so the detail still rounds the top): the example's detail matched to a drawn crest
   raises a band 0-3 px wide, and taking back only its mean on the strokes, faded over L, dug a
   groove along its foot 5-7 px out (an embankment); its texture stays. Reads a and b (rw
   floats a row, origin (rx, ry)) within L of the window (x, y, ww, wh), which the caller computed
   exactly; writes the correction of each window pixel into corr (ww x wh). */
static void tn__gnn_pin(const tn__gnn_gen *G, const float *a, const float *b, int rx, int ry, int rw, int x, int y, int ww, int wh, int wall,
                        float *corr)
{
    const int L = TN__GNN_PIN;
    int u, v, px, py;
    for (v = 0; v < wh; v++)
        for (u = 0; u < ww; u++) {
            int X = x + u, Y = y + v;
            float d = G->pin_d[(size_t)Y * G->W + X], phi, ramp = 0;
            double num = 0, den = 0, nb = 0, db = 0;
            corr[(size_t)v * ww + u] = 0;
            if (!(d < (float)L)) continue;
            if (wall > 0 && d > 0 && d < (float)wall) ramp = 1 - d / (float)wall;
            for (py = Y - L + 1; py < Y + L; py++)
                for (px = X - L + 1; px < X + L; px++) {
                    float e, k, dq;
                    size_t i;
                    if (px < 0 || py < 0 || px >= G->W || py >= G->H) continue;
                    dq = G->pin_d[(size_t)py * G->W + px];
                    if (wall == TN__GNN_PIN_ACROSS ? (d <= TN__GNN_BESIDE ? dq > TN__GNN_BESIDE : fabsf(dq - d) > 0.5f)
                                                   : dq > 0 && !(ramp > 0 && dq <= TN__GNN_BESIDE))
                        continue;
                    e = sqrtf((float)((px - X) * (px - X) + (py - Y) * (py - Y)));
                    if (e >= (float)L) continue;
                    k = wall == TN__GNN_PIN_ACROSS && d > 0 ? (1 - e / L) * (1 - e / L) : tn__gnn_line_kernel(e, L);
                    i = (size_t)(py - ry) * rw + (px - rx);
                    e = a[i] - b[i];
                    if (dq > 0 && wall != TN__GNN_PIN_ACROSS) nb += k * e, db += k;
                    else num += k * e, den += k;
                }
            phi = 1 - d / L;
            phi = phi * phi * (3 - 2 * phi);
            num = den > 0 ? num / den : 0;
            corr[(size_t)v * ww + u] = (float)(phi * num + (db > 0 ? ramp * (nb / db - num) : 0));
        }
}

#define TN__GNN_BANK 4  /* px: a stroke's banks, which stay above a valley and below a ridge */
#define TN__GNN_NOTCH 7 /* px: half-width of the notch that deepens a valley or raises a ridge */

/* How far stroke pixel (X, Y) of type t (1 ridge, 2 valley) must rise (a ridge) or sink (a
   valley, negative) to lie margin above (below) its banks: the output TN__GNN_BANK px away and
   3 px or more from every stroke (dist, W x H: the strokes' distance; across the stroke, not
   along it). val: the output on the area (ax, ay, aw, ah). */
static float tn__gnn_bank_need(const tn__gnn_gen *G, const float *dist, int t, float margin, const float *val, int ax, int ay, int aw, int ah, int X,
                               int Y)
{
    const int Bk = TN__GNN_BANK;
    float m = t == 1 ? -FLT_MAX : FLT_MAX, h = val[(size_t)(Y - ay) * aw + (X - ax)], need;
    int a, b, any = 0;
    for (b = Y - Bk - 1; b <= Y + Bk + 1; b++)
        for (a = X - Bk - 1; a <= X + Bk + 1; a++) {
            float e = sqrtf((float)((a - X) * (a - X) + (b - Y) * (b - Y))), q;
            if (fabsf(e - (float)Bk) > 0.5f || a < ax || b < ay || a >= ax + aw || b >= ay + ah || dist[(size_t)b * G->W + a] < Bk - 1) continue;
            q = val[(size_t)(b - ay) * aw + (a - ax)];
            m = t == 1 ? fmaxf(m, q) : fminf(m, q);
            any = 1;
        }
    if (!any) return 0;
    need = t == 1 ? m + margin - h : h - (m - margin);
    return need > 0 ? (t == 1 ? need : -need) : 0;
}

/* The highest of val (on the area) on the ridge strokes of G->pin within ceil(TN__GNN_CREST_BEND_MAX)
   px of (X, Y): the moved crest beside a ridge pixel as drawn; -FLT_MAX = none. */
static float tn__gnn_crest_near(const tn__gnn_gen *G, const float *val, int ax, int ay, int aw, int ah, int X, int Y)
{
    const int R = (int)ceilf(TN__GNN_CREST_BEND_MAX);
    float m = -FLT_MAX;
    int a, b;
    for (b = Y - R; b <= Y + R; b++)
        for (a = X - R; a <= X + R; a++)
            if (a >= ax && b >= ay && a < ax + aw && b < ay + ah && (a - X) * (a - X) + (b - Y) * (b - Y) <= R * R && G->pin[(size_t)b * G->W + a] == 1)
                m = fmaxf(m, val[(size_t)(b - ay) * aw + (a - ax)]);
    return m;
}

/* The notch at (X, Y): the asks def (on the area) of the stroke pixels of mask within
   TN__GNN_NOTCH px, averaged with the line kernel, times (1 - d/7)^2 (d: dist at (X, Y)). */
static float tn__gnn_notch_at(const tn__gnn_gen *G, const uint8_t *mask, const float *dist, const float *def, int ax, int ay, int aw, int ah, int X,
                              int Y)
{
    const int Wn = TN__GNN_NOTCH;
    float d = dist[(size_t)Y * G->W + X];
    double num = 0, den = 0;
    int a, b;
    if (!(d < (float)Wn)) return 0;
    for (b = Y - Wn + 1; b < Y + Wn; b++)
        for (a = X - Wn + 1; a < X + Wn; a++) {
            float e, k;
            if (a < ax || b < ay || a >= ax + aw || b >= ay + ah || !mask[(size_t)b * G->W + a]) continue;
            e = sqrtf((float)((a - X) * (a - X) + (b - Y) * (b - Y)));
            if (e >= (float)Wn) continue;
            k = tn__gnn_line_kernel(e, Wn);
            num += k * def[(size_t)(b - ay) * aw + (a - ax)];
            den += k;
        }
    return den > 0 ? (1 - d / Wn) * (1 - d / Wn) * (float)(num / den) : 0;
}

/* A grown sketch's user lines stay the lowest (valley) or highest (ridge) ground across them:
   where a bank (tn__gnn_bank_need) is not at least side per px (G->side, the added lines' fall,
   TN__GNN_FALL; less at the map-scale level, whose floors are broader) above a valley pixel
   (below a ridge pixel), the stroke is deepened (raised) by the shortfall in a notch of
   (1 - d/7)^2 around it, as a gully is cut into a hillside. The membrane and the network leave a
   stroke on a hillside where the land around it tilts more than the stroke's own profile (a
   tributary above a main valley); lifting the low bank instead left levees at a fixed distance.
   A ridge the example's bends moved off its drawn place is raised there too where the ground
   across it as drawn is higher (G->drawn): the user asked for the ridge there. By the shortfall
   alone, of which the notch closes 4/5, and never above the moved crest beside it: a margin, the
   full fix or ground higher than the crest raised drawn ridges above their asked heights. val: the pinned output (normalised; with side 0 any
   units: tn__gnn_gen_detailed runs it on metres) on the area (ax, ay, aw, ah), which
   holds every pixel within TN__GNN_NOTCH + TN__GNN_BANK + 1 of the window (x, y, ww, wh); def:
   scratch of aw x ah (2 x that with G->drawn); the result goes into out (ww x wh). */
static void tn__gnn_incise(const tn__gnn_gen *G, float side, const float *val, int ax, int ay, int aw, int ah, int x, int y, int ww,
                           int wh, float *def, float *out)
{
    const int Wn = TN__GNN_NOTCH, Bk = TN__GNN_BANK;
    const float keep = 1 - (1 - (float)Bk / Wn) * (1 - (float)Bk / Wn); /* what the notch leaves of a bank-to-stroke difference */
    float *def2 = G->drawn ? def + (size_t)aw * ah : NULL;
    int u, v;
    for (v = 0; v < ah; v++)
        for (u = 0; u < aw; u++) {
            int X = ax + u, Y = ay + v, t = G->pin[(size_t)Y * G->W + X];
            int far = X < x - Wn || Y < y - Wn || X >= x + ww + Wn || Y >= y + wh + Wn;
            def[(size_t)v * aw + u] = t && !far ? tn__gnn_bank_need(G, G->pin_d, t, side * Bk, val, ax, ay, aw, ah, X, Y) / keep : 0;
            if (def2) {
                float need = G->drawn[(size_t)Y * G->W + X] && !far ? tn__gnn_bank_need(G, G->drawn_d, 1, 0, val, ax, ay, aw, ah, X, Y) : 0;
                if (need > 0) need = fminf(need, fmaxf(tn__gnn_crest_near(G, val, ax, ay, aw, ah, X, Y) - val[(size_t)v * aw + u], 0));
                def2[(size_t)v * aw + u] = need;
            }
        }
    for (v = 0; v < wh; v++)
        for (u = 0; u < ww; u++) {
            int X = x + u, Y = y + v;
            float h = val[(size_t)(Y - ay) * aw + (X - ax)] + tn__gnn_notch_at(G, G->pin, G->pin_d, def, ax, ay, aw, ah, X, Y);
            if (def2) h += tn__gnn_notch_at(G, G->drawn, G->drawn_d, def2, ax, ay, aw, ah, X, Y);
            out[(size_t)v * ww + u] = h;
        }
}

static tn_status tn__gnn_gen_window(const tn__gnn_gen *G, const tn_params *w, tn_ctx *ctx, int x, int y, int ww, int wh, float *dst, float *base_dst,
                                    size_t stride)
{
    tn__gnn_region R;
    float *pred = NULL, *corr = NULL, *val = NULL, *inc = NULL;
    /* the notch reads the pinned output within L of the window, the pinning pred within L of that */
    int L = G->pin ? TN__GNN_PIN : 0, gx = x - 2 * L > 0 ? x - 2 * L : 0, gy = y - 2 * L > 0 ? y - 2 * L : 0;
    int gx1 = x + ww + 2 * L < G->W ? x + ww + 2 * L : G->W, gy1 = y + wh + 2 * L < G->H ? y + wh + 2 * L : G->H;
    int ax = x - L > 0 ? x - L : 0, ay = y - L > 0 ? y - L : 0, aw = (x + ww + L < G->W ? x + ww + L : G->W) - ax,
        ah = (y + wh + L < G->H ? y + wh + L : G->H) - ay;
    int rx = gx - G->halo > 0 ? gx - G->halo : 0, ry = gy - G->halo > 0 ? gy - G->halo : 0, u, v;
    int rx1 = gx1 + G->halo < G->W ? gx1 + G->halo : G->W, ry1 = gy1 + G->halo < G->H ? gy1 + G->halo : G->H;
    tn_status st;
    if ((size_t)(rx1 - rx) * (ry1 - ry) * G->A.k > TN__GNN_MAX_EDGES)
        return tn__fail(TN_ERR_TOO_LARGE, "gnn generate: a %d x %d window needs more than %d edges", ww, wh, TN__GNN_MAX_EDGES);
    if ((st = tn__gnn_region_make(G, rx, ry, rx1 - rx, ry1 - ry, G->base, &R))) return st;
    if (!(pred = (float *)tn__alloc((size_t)R.rw * R.rh * sizeof(float))) ||
        !(val = (float *)tn__alloc((size_t)aw * ah * sizeof(float))))
        st = TN_ERR_OUT_OF_MEMORY;
    if (!st && G->pin && (!(corr = (float *)tn__alloc((size_t)aw * ah * (G->drawn ? 2 : 1) * sizeof(float))) ||
                          !(inc = (float *)tn__alloc((size_t)ww * wh * sizeof(float)))))
        st = TN_ERR_OUT_OF_MEMORY;
    if (!st) st = tn__gnn_region_predict(ctx, G, w, &R, pred);
    if (!st && corr) tn__gnn_pin(G, pred, R.base, R.rx, R.ry, R.rw, ax, ay, aw, ah, TN__GNN_BANK, corr);
    for (v = 0; !st && v < ah; v++)
        for (u = 0; u < aw; u++) {
            size_t i = (size_t)(ay - ry + v) * R.rw + (ax - rx + u), j = (size_t)v * aw + u;
            float r = pred[i] - (corr ? corr[j] : 0.0f);
            val[j] = G->gain == 1.0f && !corr ? pred[i] : R.base[i] + G->gain * (r - R.base[i]);
            if (G->flank) val[j] += G->flank[(size_t)(ay + v) * G->W + ax + u];
        }
    if (!st && inc) tn__gnn_incise(G, G->side, val, ax, ay, aw, ah, x, y, ww, wh, corr, inc); /* corr is free by now: the notch's scratch */
    for (v = 0; !st && v < wh; v++)
        for (u = 0; u < ww; u++) {
            size_t i = (size_t)(y - ry + v) * R.rw + (x - rx + u);
            float p = inc ? inc[(size_t)v * ww + u] : val[(size_t)(y - ay + v) * aw + (x - ax + u)];
            float h = G->A.mean + G->A.std * p;
            if (!isfinite(h)) {
                st = tn__fail(TN_ERR_NUMERIC, "gnn generate: the network gave NaN/Inf (damaged model?)");
                break;
            }
            dst[(size_t)v * stride + u] = h;
            if (base_dst) base_dst[(size_t)v * stride + u] = G->A.mean + G->A.std * R.base[i];
        }
    tn__gnn_region_free(&R);
    TN_FREE(pred);
    TN_FREE(corr);
    TN_FREE(val);
    TN_FREE(inc);
    return st;
}

#define TN__GNN_TILE 512          /* core of a generation tile; the 148 px halo comes on top, a smaller core recomputes more of it */

/* Window (x, y, ww, wh) of G's map into dst (and the membrane into base_dst, may be NULL), ww
   floats a row, in tiles; a pixel depends only on the sketch within the halo, so any split
   gives the same pixels. */
static tn_status tn__gnn_gen_run(const tn__gnn_gen *G, const tn_params *w, tn_ctx *ctx, int x, int y, int ww, int wh, float *dst, float *base_dst,
                                 const char *stage)
{
    int tile = (size_t)ww * wh <= TN__GNN_ONE_PASS ? (ww > wh ? ww : wh) : TN__GNN_TILE, tx, ty, done_t = 0;
    int nt = ((ww + tile - 1) / tile) * ((wh + tile - 1) / tile);
    tn_status st = TN_OK;
    for (ty = 0; !st && ty < wh; ty += tile)
        for (tx = 0; !st && tx < ww; tx += tile) {
            int tw = ww - tx < tile ? ww - tx : tile, th = wh - ty < tile ? wh - ty : tile;
            size_t o = (size_t)ty * ww + tx;
            st = tn__gnn_gen_window(G, w, ctx, x + tx, y + ty, tw, th, dst + o, base_dst ? base_dst + o : NULL, (size_t)ww);
            if (!st && (nt > 1 || (size_t)ww * wh > TN__GNN_ONE_PASS)) st = tn__progress(stage, (double)++done_t / nt);
        }
    return st;
}

#define TN__GNN_KEEP 3         /* px from a user line within which its own cross profile is kept through the detail */
#define TN__GNN_KEEP_FINE 0.5f /* px: the Gaussian below which the example's detail stays there too */

/* A grown sketch's user lines keep their cross profile through the fine detail. The detail keeps
   the terrain's low-pass (sigma 2 px), which rounds a drawn crest (floor) into a flat band whose
   highest point the example's texture then decides: a band that reads as two lines in map view.
   Within TN__GNN_KEEP px of a user line the band between the Gaussians of TN__GNN_KEEP_FINE px
   and of the low-pass is the terrain's own, not the example's, faded out by a smoothstep of the
   distance (swapped, not added: the band's power stays). Reads t and d within the low-pass's
   reach (tn_image_blur: 4 sigma) of the pixels it changes. t and d: the terrain and its detail
   over g (map pixels); d is changed in place. */
static tn_status tn__gnn_keep_profile(const tn__gnn_gen *G, const tn_image *t, tn_rect g, tn_image *d)
{
    tn_image b[4] = {{0, 0, 0, NULL}, {0, 0, 0, NULL}, {0, 0, 0, NULL}, {0, 0, 0, NULL}};
    int u, v, k;
    tn_status st = TN_OK;
    for (k = 0; !st && k < 4; k++) st = tn_image_blur(&b[k], k < 2 ? t : d, k & 1 ? G->fd.sigma : TN__GNN_KEEP_FINE);
    for (v = 0; !st && v < g.h; v++)
        for (u = 0; u < g.w; u++) {
            float e = G->pin_d[(size_t)(g.y + v) * G->W + g.x + u], w = 1 - e / TN__GNN_KEEP;
            size_t i = (size_t)v * g.w + u;
            if (!(w > 0)) continue;
            d->data[i] += w * w * (3 - 2 * w) * (b[0].data[i] - b[1].data[i] - (b[2].data[i] - b[3].data[i]));
        }
    for (k = 0; k < 4; k++) tn_image_free(&b[k]);
    return st;
}

#define TN__GNN_DETAIL_TILE 1024 /* the fine detail's tiles: the network runs again on their halo (7 %) */

/* Window (x, y, ww, wh) with the fine detail by example, ww floats a row, in tiles: each tile's
   terrain is computed grown by the detail's halo (tn_rect_halo; plus, on a grown sketch, the
   pinning's reach, whose strokes are pinned again after the detail, the low-pass's reach of
   tn__gnn_keep_profile before that, and the notch's after it), detailed, and cropped. On a grown
   sketch the notch runs again after the detail, asking only that the strokes stay above (below)
   their banks: the example's detail on a bank (a crater's rim) can top a drawn ridge the notch
   had cleared. */
static tn_status tn__gnn_gen_detailed(const tn__gnn_gen *G, tn_ctx *ctx, int x, int y, int ww, int wh, float *dst)
{
    const int N = G->pin ? TN__GNN_NOTCH + TN__GNN_BANK + 1 : 0; /* px the notch reads around its window */
    int halo = tn_fine_detail_halo(NULL), tx, ty, v, T = TN__GNN_DETAIL_TILE;
    tn_status st = TN_OK;
    for (ty = 0; !st && ty < wh; ty += T)
        for (tx = 0; !st && tx < ww; tx += T) {
            tn_rect r, g, a;
            tn_image t = {0, 0, 0, NULL}, d = {0, 0, 0, NULL};
            float *val = NULL, *def = NULL, *out = NULL;
            size_t na;
            r.x = x + tx, r.y = y + ty;
            r.w = ww - tx < T ? ww - tx : T;
            r.h = wh - ty < T ? wh - ty : T;
            g = tn_rect_halo(r, halo + (G->pin ? TN__GNN_PIN + (int)(4.0f * G->fd.sigma + 0.5f) + N : 0) + tn__gnn_band_halo(G), G->W, G->H);
            a = tn_rect_halo(r, N, G->W, G->H);
            na = (size_t)a.w * a.h;
            if (!(st = tn_image_create(&t, g.w, g.h, 1)) && !(st = tn__gnn_gen_run(G, G->w, ctx, g.x, g.y, g.w, g.h, t.data, NULL, "gnn-generate")) &&
                !(st = tn__gnn_ground_apply(G, &t, g)) && !(st = tn__fd_apply(&G->fd, &t, (g.x + g.y) & 1, &d)) && !(G->pin && (st = tn__gnn_keep_profile(G, &t, g, &d)))) {
                if (G->pin && (!(val = (float *)tn__alloc(na * sizeof(float))) || !(def = (float *)tn__alloc(na * (G->drawn ? 2 : 1) * sizeof(float))) ||
                               !(out = (float *)tn__alloc((size_t)r.w * r.h * sizeof(float)))))
                    st = TN_ERR_OUT_OF_MEMORY;
                else if (G->pin) {
                    size_t i;
                    int u;
                    tn__gnn_pin(G, d.data, t.data, g.x, g.y, g.w, a.x, a.y, a.w, a.h, TN__GNN_PIN_ACROSS, val); /* the strokes keep their heights through the detail too */
                    for (v = 0, i = 0; v < a.h; v++)
                        for (u = 0; u < a.w; u++, i++) val[i] = d.data[(size_t)(a.y - g.y + v) * g.w + (a.x - g.x + u)] - val[i];
                    tn__gnn_incise(G, 0, val, a.x, a.y, a.w, a.h, r.x, r.y, r.w, r.h, def, out);
                }
                for (v = 0; !st && v < r.h; v++)
                    memcpy(dst + (size_t)(ty + v) * ww + tx, out ? out + (size_t)v * r.w : d.data + (size_t)(r.y - g.y + v) * g.w + (r.x - g.x),
                           (size_t)r.w * sizeof(float));
            }
            tn_image_free(&t);
            tn_image_free(&d);
            TN_FREE(val);
            TN_FREE(def);
            TN_FREE(out);
        }
    return st;
}

/* The gain test's scale, "gain.scale" of s->w, from the holdouts: each holdout sketch of
   TN__GNN_GAIN_MIN_LINES lines or more is generated as any other sketch (the network other terrain
   runs on, its gain tested on its lines) and the scale, 0 .. 2 in steps of 0.05, is the smallest
   with the best mean SSIM over them of the membrane plus min(1, scale x its raw estimate) times
   the residual. The held-out lines are where the membrane errs most, and SSIM wants less
   residual than least squares, so the raw estimate runs high where the style fits loosely. */
static tn_status tn__gnn_gain_calibrate(tn__gnn_train *s)
{
    double ssim[TN__GNN_GAIN_SCALES] = {0}, best = -2;
    tn_gnn m;
    tn_gnn_generate_opts go;
    tn_tensor *sc;
    tn_ctx *ctx = NULL;
    int i, k, n = 0, one = 1;
    tn_status st = TN_OK;
    if (!s->best) return TN_OK;
    memset(&m, 0, sizeof m);
    tn__gnn_model_fields(&m, &s->A);
    m.weights = s->w;
    memset(&go, 0, sizeof go);
    if (!(ctx = tn_ctx_create())) return tn__fail(TN_ERR_OUT_OF_MEMORY, "gnn: out of memory");
    for (i = 0; !st && i < 2 * s->o.holdout_count; i++) {
        const tn_image *h = &s->o.holdout[i / 2];
        tn_image out = {0, 0, 0, NULL};
        tn__gnn_gen G;
        float *pred = NULL, *base = NULL;
        size_t q, np = (size_t)h->width * h->height;
        if (s->hsk[i].count < TN__GNN_GAIN_MIN_LINES) continue;
        st = tn__gnn_gen_make(&m, &s->hsk[i], h->width, h->height, &go, &G);
        if (st == TN_ERR_EMPTY) { /* no part of 5 px */
            st = TN_OK;
            continue;
        }
        if (st) break;
        if (isfinite(G.gain_raw)) {
            pred = (float *)tn__alloc(np * sizeof(float));
            base = (float *)tn__alloc(np * sizeof(float));
            G.gain = 1.0f;
            if (!pred || !base) st = TN_ERR_OUT_OF_MEMORY;
            if (!st) st = tn__gnn_gen_run(&G, G.w, ctx, 0, 0, h->width, h->height, pred, base, "gnn-gain-scale");
            if (!st) st = tn_image_create(&out, h->width, h->height, 1);
            for (k = 0; !st && k < TN__GNN_GAIN_SCALES; k++) {
                float g = tn__gnn_gain_of(0.05 * k, G.gain_raw);
                tn_metrics mt;
                for (q = 0; q < np; q++) out.data[q] = base[q] + g * (pred[q] - base[q]);
                if (!(st = tn_compare(&mt, h, &out, 0))) ssim[k] += mt.ssim;
            }
            n += !st;
        }
        tn_image_free(&out);
        TN_FREE(pred);
        TN_FREE(base);
        tn__gnn_gen_free(&G);
    }
    tn_ctx_free(ctx);
    if (st || !n) return st;
    if (!(sc = tn_params_find(s->w, "gain.scale")) && !(sc = tn_params_add_buffer(s->w, "gain.scale", 1, &one))) return TN_ERR_OUT_OF_MEMORY;
    for (k = 0; k < TN__GNN_GAIN_SCALES; k++)
        if (ssim[k] > best) {
            best = ssim[k];
            sc->data[0] = 0.05f * (float)k;
        }
    return TN_OK;
}

TN_API tn_status tn_gnn_ordering(double *share, const tn_contour_set *sketch, const tn_image *terrain, float distance, int *count)
{
    tn_contour_set sk, dense;
    int i, j, n = 0, good = 0, W, H;
    float d = distance > 0 ? distance : 3.0f;
    tn__gnn_arch A;
    tn_status st;
    TN_ASSERT(share);
    *share = 0;
    if (count) *count = 0;
    if (!sketch || sketch->count <= 0) return tn__fail(TN_ERR_EMPTY, "gnn ordering: the sketch is empty");
    if ((st = tn__cset_check(sketch, "gnn ordering"))) return st;
    if (!terrain || !terrain->data || terrain->width <= 0 || terrain->height <= 0) return tn__fail(TN_ERR_EMPTY, "gnn ordering: no terrain");
    if (!(distance >= 0 && distance < 4096)) return tn__fail(TN_ERR_INVALID_ARG, "gnn ordering: distance %g", (double)distance);
    W = terrain->width;
    H = terrain->height;
    memset(&A, 0, sizeof A);
    if ((st = tn__gnn_sketch_units(&A, sketch, W, H, TN_GNN_HEIGHTS_EXAMPLE, &sk))) return st; /* in the terrain's pixels */
    st = tn_sketch_densify(&dense, &sk);
    tn_contour_set_free(&sk);
    if (st) return st;
    for (i = 0; i < dense.count; i++)
        for (j = 0; j < dense.items[i].npoints; j++) {
            int p, q1, q2;
            float hp, h1, h2;
            tn__gnn_across(&dense.items[i], j, W, H, d, &p, &q1, &q2);
            if (p < 0 || q1 < 0 || q2 < 0) continue;
            hp = terrain->data[(size_t)p * terrain->channels];
            h1 = terrain->data[(size_t)q1 * terrain->channels];
            h2 = terrain->data[(size_t)q2 * terrain->channels];
            n++;
            good += dense.items[i].type == TN_RIDGE ? hp > h1 && hp > h2 : hp < h1 && hp < h2;
        }
    tn_contour_set_free(&dense);
    *share = n ? (double)good / n : 0.0;
    if (count) *count = n;
    return TN_OK;
}
#endif /* TN_NO_GNN */

