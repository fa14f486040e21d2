/* Tests of @@sketch: .tns round trip and every error path, drawn (PNG) sketches, densify and
   rasterisation, MST and Delaunay, random sketches (no crossings, determinism), contour parts
   and alignment (a planted rotated copy aligns to its source). */
#define TN_INTERNALS /* private tn__ code: the header's internals block */
#include "terrainnet.h"
#include "tn_test.h"
#include <float.h>
#include <locale.h>

static const char *demo_tns =
    "terrainnet-sketch 1\n"
    "# a ridge with heights, a valley with start and rate\n"
    "canvas 64 48\n"
    "\n"
    "ridge order 2 gradient 0.25   # trailing comment\n"
    "  10 20 0.8\n"
    "  30.5 22 0.75\n"
    "  50 40 0.123456789\n"
    "end\n"
    "valley start 0.2 rate 0.01\n"
    "0 0\n"
    "3 4\n"
    "3 4 0.9\n"
    "end\n";

static int sets_equal(const tn_contour_set *a, const tn_contour_set *b)
{
    int i;
    if (a->width != b->width || a->height != b->height || a->count != b->count) return 0;
    for (i = 0; i < a->count; i++) {
        const tn_contour *x = &a->items[i], *y = &b->items[i];
        if (x->type != y->type || x->order != y->order || x->npoints != y->npoints || x->mean_gradient != y->mean_gradient) return 0;
        if (memcmp(x->points, y->points, (size_t)x->npoints * 3 * sizeof(float))) return 0;
    }
    return 1;
}

TN_TEST(tns_parse_and_round_trip)
{
    tn_contour_set s = {0, 0, 0, NULL}, t = {0, 0, 0, NULL}, u = {0, 0, 0, NULL};
    char *text = NULL, *text2 = NULL, *text3 = NULL;
    size_t n = 0, n2 = 0, n3 = 0;
    int i;
    TN_CHECK(tn_sketch_parse(&s, demo_tns, strlen(demo_tns), "demo.tns") == TN_OK);
    TN_CHECK(s.width == 64 && s.height == 48 && s.count == 2);
    if (s.count != 2) return;
    TN_CHECK(s.items[0].type == TN_RIDGE && s.items[0].order == 2 && s.items[0].mean_gradient == 0.25f);
    TN_CHECK(s.items[0].npoints == 3 && s.items[0].points[3] == 30.5f && s.items[0].points[8] == 0.123456789f);
    TN_CHECK(s.items[1].type == TN_VALLEY && s.items[1].npoints == 3);
    TN_CHECK_NEAR(s.items[1].points[2], 0.2, 1e-7);          /* start */
    TN_CHECK_NEAR(s.items[1].points[5], 0.2 + 0.01 * 5, 1e-6); /* start + rate * arc length 5 */
    TN_CHECK(s.items[1].points[8] == 0.9f);                  /* an explicit height wins */
    /* awkward floats survive: format -> parse gives identical bits, and formatting is stable */
    s.items[0].points[1] = 1.0f / 3.0f;
    s.items[0].points[2] = -1.17549435e-38f;
    s.items[1].points[2] = 12345.678f;
    TN_CHECK(tn_sketch_format(&text, &n, &s) == TN_OK);
    TN_CHECK(tn_sketch_parse(&t, text, n, "mem") == TN_OK);
    TN_CHECK(sets_equal(&s, &t));
    TN_CHECK(tn_sketch_format(&text2, &n2, &t) == TN_OK);
    TN_CHECK(n == n2 && text && text2 && !memcmp(text, text2, n));
    /* through a file */
    TN_CHECK(tn_sketch_save("build/test/sketch_rt.tns", &s) == TN_OK);
    TN_CHECK(tn_sketch_load(&u, "build/test/sketch_rt.tns") == TN_OK);
    TN_CHECK(sets_equal(&s, &u));
    /* what the reader would reject is not written */
    s.items[0].points[0] = 64.0f;
    TN_CHECK(tn_sketch_format(&text3, &n3, &s) == TN_ERR_INVALID_ARG && strstr(tn_last_error(), "outside"));
    s.items[0].points[0] = 10.0f;
    s.items[1].order = 1001;
    TN_CHECK(tn_sketch_format(&text3, &n3, &s) == TN_ERR_INVALID_ARG);
    s.items[1].order = 0;
    TN_CHECK(tn_sketch_format(&text3, &n3, &s) == TN_OK);
    /* a failed save (NaN) leaves the file as it was */
    s.items[0].points[0] = NAN;
    TN_CHECK(tn_sketch_save("build/test/sketch_rt.tns", &s) == TN_ERR_NUMERIC);
    tn_contour_set_free(&t);
    TN_CHECK(tn_sketch_load(&t, "build/test/sketch_rt.tns") == TN_OK && sets_equal(&t, &u));
    for (i = 0; i < 2; i++) tn_free(i ? text2 : text);
    tn_free(text3);
    tn_contour_set_free(&s);
    tn_contour_set_free(&t);
    tn_contour_set_free(&u);
}

/* A set of n random-bit floats (finite, in canvas) of every magnitude. */
static tn_status random_float_set(tn_contour_set *s, int n, uint64_t seed)
{
    tn_rng r;
    size_t cap = 0;
    float *pts = (float *)malloc((size_t)n * 3 * sizeof(float));
    int i;
    tn_status st;
    if (!pts) return TN_ERR_OUT_OF_MEMORY;
    tn_rng_seed(&r, seed, 1);
    for (i = 0; i < 3 * n; i++) {
        uint32_t u = tn_rng_u32(&r);
        float f;
        if (i % 3 < 2) u = (u & 0x007fffffu) | ((uint32_t)(120 + (u >> 27) % 6) << 23); /* 2^-7..2^-2 times 64 below */
        else if (((u >> 23) & 0xffu) == 0xffu) u &= ~0x00800000u; /* every finite float: no NaN/Inf */
        memcpy(&f, &u, sizeof f);
        pts[i] = i % 3 < 2 ? f * 64.0f : f;
    }
    pts[5] = FLT_MAX; /* its shortest text, 3.4028235e+38, is above FLT_MAX as a double */
    pts[8] = -FLT_MAX;
    memset(s, 0, sizeof *s);
    s->width = s->height = 256; /* its jumps of up to 16 px stay within the strokes' limit */
    st = tn__cset_add(s, &cap, TN_RIDGE, 3, pts[2], pts, n);
    free(pts);
    return st;
}

/* Every float, including subnormals and 9-significant-digit values, reads back with the same bits. */
static void check_float_round_trip(uint64_t seed)
{
    tn_contour_set s, t = {0, 0, 0, NULL};
    char *text = NULL;
    size_t n = 0;
    TN_CHECK(random_float_set(&s, 2000, seed) == TN_OK);
    TN_CHECK(tn_sketch_format(&text, &n, &s) == TN_OK);
    TN_CHECK(text && !strchr(text, ',') && text[n] == 0);
    TN_CHECK(tn_sketch_parse(&t, text, n, "floats") == TN_OK);
    TN_CHECK(sets_equal(&s, &t));
    tn_free(text);
    tn_contour_set_free(&s);
    tn_contour_set_free(&t);
}

TN_TEST(tns_numbers_round_trip_exactly) { check_float_round_trip(7); }

/* A comma-decimal locale changes neither what is written nor what is read. */
TN_TEST(tns_comma_locale)
{
    static const char *names[] = {"de_DE.UTF-8", "de_DE.utf8", "de_DE", "fr_FR.UTF-8", "fr_FR.utf8"};
    tn_contour_set s = {0, 0, 0, NULL};
    char *old = setlocale(LC_NUMERIC, NULL), saved[64];
    size_t i;
    snprintf(saved, sizeof saved, "%s", old ? old : "C");
    for (i = 0; i < sizeof names / sizeof names[0]; i++)
        if (setlocale(LC_NUMERIC, names[i])) break;
    if (i == sizeof names / sizeof names[0]) { TN_SKIP("no comma-decimal locale (de_DE.UTF-8) installed"); return; }
    TN_CHECK(tn_sketch_parse(&s, demo_tns, strlen(demo_tns), "demo.tns") == TN_OK);
    TN_CHECK(s.count == 2 && s.items[0].points[3] == 30.5f && s.items[0].mean_gradient == 0.25f);
    check_float_round_trip(11);
    setlocale(LC_NUMERIC, saved);
    tn_contour_set_free(&s);
}

/* Every malformed input fails with the right code and names the line. */
TN_TEST(tns_malformed)
{
    static const struct { const char *text; tn_status st; const char *msg; } cases[] = {
        {"", TN_ERR_FORMAT, "empty file"},
        {"hello\n", TN_ERR_FORMAT, "bad.tns:1:"},
        {"# c\nterrainnet-sketch 2\n", TN_ERR_FORMAT, "bad.tns:2: unsupported sketch version"},
        {"terrainnet-sketch 1\nridge\n1 1 1\nend\n", TN_ERR_CORRUPT, "bad.tns:2: 'ridge' before the 'canvas"},
        {"terrainnet-sketch 1\ncanvas 8 8\ncanvas 8 8\n", TN_ERR_CORRUPT, "bad.tns:3: a second 'canvas'"},
        {"terrainnet-sketch 1\ncanvas 8\n", TN_ERR_CORRUPT, "bad.tns:2: expected 'canvas"},
        {"terrainnet-sketch 1\ncanvas 0 8\n", TN_ERR_CORRUPT, "bad.tns:2: canvas size"},
        {"terrainnet-sketch 1\ncanvas 100000 8\n", TN_ERR_TOO_LARGE, "bad.tns:2: canvas side"},
        {"terrainnet-sketch 1\ncanvas 8 8\nridge\n1 1 1\n", TN_ERR_CORRUPT, "bad.tns:5: end of file inside the polyline opened at line 3"},
        {"terrainnet-sketch 1\ncanvas 8 8\nridge\n1 1 1\nvalley\n", TN_ERR_CORRUPT, "bad.tns:5: missing 'end' for the polyline opened at line 3"},
        {"terrainnet-sketch 1\ncanvas 8 8\nridge\nend\n", TN_ERR_CORRUPT, "bad.tns:4: the polyline opened at line 3 has no points"},
        {"terrainnet-sketch 1\ncanvas 8 8\nend\n", TN_ERR_CORRUPT, "bad.tns:3: 'end' without"},
        {"terrainnet-sketch 1\ncanvas 8 8\nmountain\n", TN_ERR_CORRUPT, "bad.tns:3: unknown keyword 'mountain'"},
        {"terrainnet-sketch 1\ncanvas 8 8\nridge colour 3\n", TN_ERR_CORRUPT, "bad.tns:3: unknown polyline attribute 'colour'"},
        {"terrainnet-sketch 1\ncanvas 8 8\nridge order\n", TN_ERR_CORRUPT, "bad.tns:3: 'ridge' attributes come in pairs"},
        {"terrainnet-sketch 1\ncanvas 8 8\nridge order 1.5\n", TN_ERR_CORRUPT, "bad.tns:3: order must be"},
        {"terrainnet-sketch 1\ncanvas 8 8\nridge\n1 x 1\n", TN_ERR_CORRUPT, "bad.tns:4: y is not a number"},
        {"terrainnet-sketch 1\ncanvas 8 8\nridge\n1 1 nan\n", TN_ERR_NUMERIC, "bad.tns:4: height is NaN"},
        {"terrainnet-sketch 1\ncanvas 8 8\nridge\ninf 1 1\n", TN_ERR_NUMERIC, "bad.tns:4: x is NaN"},
        {"terrainnet-sketch 1\ncanvas 8 8\nridge start 1 rate 1e38\n1 1\n7 7\nend\n", TN_ERR_NUMERIC, "bad.tns:5: height out of float range"},
        {"terrainnet-sketch 1\ncanvas 8 8\nridge\n1 1\n", TN_ERR_CORRUPT, "bad.tns:4: point without a height"},
        {"terrainnet-sketch 1\ncanvas 8 8\nridge\n9 1 0\n", TN_ERR_CORRUPT, "bad.tns:4: point (9, 1) lies outside the 8 x 8 canvas"},
        {"terrainnet-sketch 1\ncanvas 8 8\nridge\n1 1 1 1\n", TN_ERR_CORRUPT, "bad.tns:4: expected a point"},
        {"terrainnet-sketch 1\ncanvas 8 8\nridge\n1 1 1\nend now\n", TN_ERR_CORRUPT, "bad.tns:5: 'end' takes no arguments"},
        {"terrainnet-sketch 1\n", TN_ERR_CORRUPT, "bad.tns:2: no 'canvas"},
        {"terrainnet-sketch 1\ncanvas 8 8\nridge 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17\n", TN_ERR_CORRUPT, "bad.tns:3: too many fields"},
    };
    size_t i;
    tn_contour_set s = {0, 0, 0, NULL};
    static const char binary[] = "terrainnet-sketch 1\ncanvas 8 8\0ridge";
    for (i = 0; i < sizeof cases / sizeof cases[0]; i++) {
        tn_status st = tn_sketch_parse(&s, cases[i].text, strlen(cases[i].text), "bad.tns");
        if (st != cases[i].st || !strstr(tn_last_error(), cases[i].msg)) {
            fprintf(stderr, "case %zu: status %d (want %d), message '%s' (want '%s')\n", i, (int)st, (int)cases[i].st,
                    tn_last_error(), cases[i].msg);
            TN_CHECK(0);
        }
        TN_CHECK(s.items == NULL && s.count == 0);
    }
    TN_CHECK(tn_sketch_parse(&s, binary, sizeof binary - 1, "bin") == TN_ERR_FORMAT);
    TN_CHECK(tn_sketch_load(&s, "build/test/no_such_sketch.tns") == TN_ERR_IO);
    /* an empty but valid sketch parses; operations that need content say so */
    TN_CHECK(tn_sketch_parse(&s, "terrainnet-sketch 1\ncanvas 4 4\n", 31, "e") == TN_OK && s.count == 0);
    {
        int m[1];
        TN_CHECK(tn_sketch_align(m, &s, &s, NULL) == TN_ERR_EMPTY);
    }
    tn_contour_set_free(&s);
}

/* .tns text of one ridge on a 16 x 16 canvas: n points, each in another pixel than the one
   before (alternating x 1 and 2: one stroke pixel each) when `step`, else all inside pixel (1, 1). */
static char *strokes_tns(int n, int step, size_t *len)
{
    char *t = (char *)malloc((size_t)n * 16 + 64), *q = t;
    int i;
    if (!t) return NULL;
    q += sprintf(q, "terrainnet-sketch 1\ncanvas 16 16\nridge\n");
    for (i = 0; i < n; i++) q += sprintf(q, step ? "%d 1 0.5\n" : "1.%d 1 0.5\n", step ? 1 + i % 2 : i % 4);
    q += sprintf(q, "end\n");
    *len = (size_t)(q - t);
    return t;
}

/* The strokes' limit (issue 33, item 10): a sketch whose polylines, drawn pixel by pixel, cover
   its canvas more than once over (+ 4096 px) is refused before any heavy work, by the parser as
   soon as it passes the limit and by every function that takes a set. Before, a 5-million-segment
   sketch on 512 x 512 parsed and gnn-generate ran past 120 s at 3 GB. */
TN_TEST(strokes_limit)
{
    const int limit = 16 * 16 + 4096;
    tn_contour_set s = {0, 0, 0, NULL}, d = {0, 0, 0, NULL};
    tn_contour c;
    size_t n;
    char *t, *text = NULL;
    int i;
    /* at the limit: parses, saves and densifies */
    if ((t = strokes_tns(limit, 1, &n))) {
        TN_CHECK(tn_sketch_parse(&s, t, n, "lim.tns") == TN_OK && s.count == 1 && s.items[0].npoints == limit);
        TN_CHECK(tn_sketch_format(&text, &n, &s) == TN_OK);
        TN_CHECK(tn_sketch_densify(&d, &s) == TN_OK);
        tn_free(text);
        tn_contour_set_free(&d);
        tn_contour_set_free(&s);
        free(t);
    }
    /* one point more: refused, naming the limit and where */
    if ((t = strokes_tns(limit + 1, 1, &n))) {
        TN_CHECK(tn_sketch_parse(&s, t, n, "over.tns") == TN_ERR_TOO_LARGE && s.count == 0);
        TN_CHECK(strstr(tn_last_error(), "over.tns:4356:") && strstr(tn_last_error(), "limit of 4352 pixels for a 16 x 16 canvas") &&
                 strstr(tn_last_error(), "at point 4353"));
        free(t);
    }
    /* a huge file stops at the limit: 2 million points (before: parsed whole) */
    if ((t = strokes_tns(2000000, 1, &n))) {
        TN_CHECK(tn_sketch_parse(&s, t, n, "huge.tns") == TN_ERR_TOO_LARGE && strstr(tn_last_error(), "huge.tns:4356:"));
        free(t);
    }
    /* points inside one pixel draw nothing more: 20,000 of them pass */
    if ((t = strokes_tns(20000, 0, &n))) {
        TN_CHECK(tn_sketch_parse(&s, t, n, "dots.tns") == TN_OK && s.items[0].npoints == 20000);
        tn_contour_set_free(&s);
        free(t);
    }
    /* a set in memory: 400 points zigzagging across the canvas (15 px a segment, 5986 px) */
    memset(&c, 0, sizeof c);
    c.npoints = 400;
    c.points = (float *)calloc((size_t)c.npoints * 3, sizeof(float));
    s.width = s.height = 16;
    s.count = 1;
    s.items = &c;
    for (i = 0; c.points && i < c.npoints; i++) {
        c.points[3 * i] = i % 2 ? 15.0f : 0.0f;
        c.points[3 * i + 1] = (float)(i % 16);
    }
    if (c.points) {
        tn_contour_set parts = {0, 0, 0, NULL};
        tn_image r = {0, 0, 0, NULL};
        TN_CHECK(tn_sketch_densify(&d, &s) == TN_ERR_TOO_LARGE && strstr(tn_last_error(), "densify: the polylines drawn pixel by pixel cover 5986 pixels, over the limit of 4352"));
        TN_CHECK(tn_contour_parts_make(&parts, &s, 1) == TN_ERR_TOO_LARGE);
        TN_CHECK(tn_sketch_rasterise(&r, &s, 16, 16) == TN_ERR_TOO_LARGE);
        TN_CHECK(tn_sketch_format(&text, &n, &s) == TN_ERR_TOO_LARGE && text == NULL);
        c.npoints = 290; /* 1 + 289 x 15 = 4336 px */
        TN_CHECK(tn_sketch_densify(&d, &s) == TN_OK && d.count == 1);
        tn_contour_set_free(&d);
    }
    free(c.points);
}

/* A drawn sketch: a bright red horizontal stroke (3 px wide) and a dark blue diagonal. */
TN_TEST(png_sketch_read)
{
    tn_image img = {0, 0, 0, NULL};
    tn_contour_set s = {0, 0, 0, NULL}, t = {0, 0, 0, NULL};
    int x, y, i, nr = 0, nv = 0;
    TN_CHECK(tn_image_create(&img, 64, 48, 3) == TN_OK);
    for (i = 0; i < 64 * 48 * 3; i++) img.data[i] = 1.0f; /* white paper */
    for (y = 9; y <= 11; y++)
        for (x = 5; x <= 55; x++) { TN_PIXEL(&img, x, y, 0) = 0.9f; TN_PIXEL(&img, x, y, 1) = 0.0f; TN_PIXEL(&img, x, y, 2) = 0.0f; }
    for (i = 0; i < 30; i++) {
        TN_PIXEL(&img, 10 + i, 15 + i, 0) = 0.0f; TN_PIXEL(&img, 10 + i, 15 + i, 1) = 0.0f; TN_PIXEL(&img, 10 + i, 15 + i, 2) = 0.3f;
        TN_PIXEL(&img, 11 + i, 15 + i, 0) = 0.0f; TN_PIXEL(&img, 11 + i, 15 + i, 1) = 0.0f; TN_PIXEL(&img, 11 + i, 15 + i, 2) = 0.3f;
    }
    TN_CHECK(tn_image_save("build/test/sketch_drawn.png", &img, NULL) == TN_OK);
    TN_CHECK(tn_sketch_load(&s, "build/test/sketch_drawn.png") == TN_OK);
    TN_CHECK(s.width == 64 && s.height == 48);
    for (i = 0; i < s.count; i++) {
        const tn_contour *c = &s.items[i];
        int j;
        if (c->type == TN_RIDGE) {
            nr += c->npoints;
            for (j = 0; j < c->npoints; j++) {
                TN_CHECK(c->points[3 * j + 1] >= 9 && c->points[3 * j + 1] <= 11);
                TN_CHECK_NEAR(c->points[3 * j + 2], 0.9, 0.01);
            }
        } else {
            nv += c->npoints;
            for (j = 0; j < c->npoints; j++) {
                float d = c->points[3 * j] - c->points[3 * j + 1]; /* on the x - y = -5 or -4 diagonal */
                TN_CHECK(d >= -5.5f && d <= -3.5f);
                TN_CHECK_NEAR(c->points[3 * j + 2], 0.3, 0.01);
            }
        }
        for (j = 1; j < c->npoints; j++) /* traced lines are 8-connected */
            TN_CHECK(fabsf(c->points[3 * j] - c->points[3 * j - 3]) <= 1 && fabsf(c->points[3 * j + 1] - c->points[3 * j - 2]) <= 1);
    }
    TN_CHECK(nr >= 40 && nr <= 52); /* thinned to one pixel wide, ~49 long */
    if (!(nv >= 24 && nv <= 31)) fprintf(stderr, "valley points %d\n", nv);
    TN_CHECK(nv >= 24 && nv <= 31);
    /* grey, white and yellow are not strokes; a grey image has none */
    for (i = 0; i < 64 * 48 * 3; i++) img.data[i] = (i % 3 == 2) ? 0.0f : 0.8f;
    TN_CHECK(tn_sketch_from_image(&t, &img) == TN_ERR_EMPTY && t.count == 0);
    tn_image_free(&img);
    TN_CHECK(tn_image_create(&img, 8, 8, 1) == TN_OK);
    TN_CHECK(tn_sketch_from_image(&t, &img) == TN_ERR_SHAPE);
    tn_image_free(&img);
    tn_contour_set_free(&s);
}

TN_TEST(densify_and_rasterise)
{
    static const char *txt = "terrainnet-sketch 1\ncanvas 32 16\nridge\n2 3 0.2\n12 3 0.7\nend\nvalley\n20 0 0.1\n20 10 0.6\nend\n";
    tn_contour_set s = {0, 0, 0, NULL}, d = {0, 0, 0, NULL};
    tn_image r = {0, 0, 0, NULL};
    int j;
    TN_CHECK(tn_sketch_parse(&s, txt, strlen(txt), "r") == TN_OK);
    TN_CHECK(tn_sketch_densify(&d, &s) == TN_OK);
    TN_CHECK(d.count == 2 && d.items[0].npoints == 11 && d.items[1].npoints == 11);
    for (j = 0; d.count == 2 && j < 11; j++) {
        TN_CHECK(d.items[0].points[3 * j] == 2 + j && d.items[0].points[3 * j + 1] == 3);
        TN_CHECK_NEAR(d.items[0].points[3 * j + 2], 0.2 + 0.05 * j, 1e-6);
    }
    /* same resolution: exact pixels and heights */
    TN_CHECK(tn_sketch_rasterise(&r, &s, 32, 16) == TN_OK);
    TN_CHECK(r.channels == 3);
    TN_CHECK(TN_PIXEL(&r, 2, 3, 0) == 1.0f && TN_PIXEL(&r, 2, 3, 1) == 0.0f && TN_PIXEL(&r, 2, 3, 2) == 0.2f);
    TN_CHECK_NEAR(TN_PIXEL(&r, 7, 3, 2), 0.45, 1e-6);
    TN_CHECK(TN_PIXEL(&r, 20, 5, 1) == 1.0f && TN_PIXEL(&r, 20, 5, 0) == 0.0f);
    TN_CHECK_NEAR(TN_PIXEL(&r, 20, 5, 2), 0.35, 1e-6);
    TN_CHECK(TN_PIXEL(&r, 2, 4, 0) == 0.0f && TN_PIXEL(&r, 2, 4, 2) == 0.0f);
    tn_image_free(&r);
    /* double resolution: the ridge at y = 3 lands on row (3.5 * 2 - 0.5) = 6.5 -> 7, 21 pixels long */
    TN_CHECK(tn_sketch_rasterise(&r, &s, 64, 32) == TN_OK);
    {
        int x, cnt = 0;
        for (x = 0; x < 64; x++) cnt += TN_PIXEL(&r, x, 7, 0) == 1.0f;
        TN_CHECK(cnt == 21);
    }
    tn_image_free(&r);
    tn_contour_set_free(&s);
    tn_contour_set_free(&d);
}

TN_TEST(mst_known_points)
{
    /* a 3 x 2 grid with x spacing 1 and y spacing 3, plus a point near (2, 0): MST weight known */
    static const float p[] = {0, 0, 1, 0, 2, 0, 0, 3, 1, 3, 2, 3, 2.5f, 0.5f};
    int *e = NULL, i, deg[7] = {0};
    double w = 0;
    TN_CHECK(tn_mst(&e, p, 7) == TN_OK);
    for (i = 0; e && i < 6; i++) {
        double dx = p[2 * e[2 * i]] - p[2 * e[2 * i + 1]], dy = p[2 * e[2 * i] + 1] - p[2 * e[2 * i + 1] + 1];
        w += sqrt(dx * dx + dy * dy);
        deg[e[2 * i]]++;
        deg[e[2 * i + 1]]++;
    }
    /* edges: (0,1) 1, (1,2) 1, (2,6) sqrt(.5), (6,5) sqrt(6.5) beats any vertical 3, (3,4) 1, (4,5) 1 */
    TN_CHECK_NEAR(w, 1 + 1 + sqrt(0.5) + sqrt(6.5) + 1 + 1, 1e-6);
    for (i = 0; i < 7; i++) TN_CHECK(deg[i] >= 1);
    tn_free(e);
}

TN_TEST(delaunay_empty_circumcircles)
{
    tn_rng r;
    float p[2 * 300];
    int *t = NULL, nt = 0, i, j, bad = 0, used[300] = {0};
    tn_rng_seed(&r, 7, 1);
    for (i = 0; i < 600; i++) p[i] = tn_rng_uniform(&r) * 100.0f;
    TN_CHECK(tn_delaunay(&t, &nt, p, 300) == TN_OK);
    TN_CHECK(nt > 500 && nt <= 2 * 300 - 5); /* 2n - 2 - hull */
    for (i = 0; i < nt; i++) {
        double ax = p[2 * t[3 * i]], ay = p[2 * t[3 * i] + 1], bx = p[2 * t[3 * i + 1]], by = p[2 * t[3 * i + 1] + 1];
        double cx = p[2 * t[3 * i + 2]], cy = p[2 * t[3 * i + 2] + 1];
        double d = 2 * (ax * (by - cy) + bx * (cy - ay) + cx * (ay - by));
        double ux = ((ax * ax + ay * ay) * (by - cy) + (bx * bx + by * by) * (cy - ay) + (cx * cx + cy * cy) * (ay - by)) / d;
        double uy = ((ax * ax + ay * ay) * (cx - bx) + (bx * bx + by * by) * (ax - cx) + (cx * cx + cy * cy) * (bx - ax)) / d;
        double r2 = (ax - ux) * (ax - ux) + (ay - uy) * (ay - uy);
        for (j = 0; j < 3; j++) used[t[3 * i + j]] = 1;
        for (j = 0; j < 300; j++) {
            double dx = p[2 * j] - ux, dy = p[2 * j + 1] - uy;
            if (dx * dx + dy * dy < r2 * (1 - 1e-9)) bad++;
        }
    }
    TN_CHECK(bad == 0);
    for (i = 0; i < 300; i++) TN_CHECK(used[i]);
    tn_free(t);
    /* duplicates are skipped, fewer than 3 points give no triangle */
    {
        static const float q[] = {0, 0, 1, 0, 0, 1, 1, 0};
        TN_CHECK(tn_delaunay(&t, &nt, q, 4) == TN_OK && nt == 1);
        tn_free(t);
        TN_CHECK(tn_delaunay(&t, &nt, q, 2) == TN_OK && nt == 0);
        tn_free(t);
    }
}

static int seg_cross(const float *a, const float *b, const float *c, const float *d)
{
    double d1 = (d[0] - c[0]) * (a[1] - c[1]) - (d[1] - c[1]) * (a[0] - c[0]);
    double d2 = (d[0] - c[0]) * (b[1] - c[1]) - (d[1] - c[1]) * (b[0] - c[0]);
    double d3 = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
    double d4 = (b[0] - a[0]) * (d[1] - a[1]) - (b[1] - a[1]) * (d[0] - a[0]);
    return d1 * d2 < 0 && d3 * d4 < 0;
}

/* 1 if the pixel polylines a and b share a pixel or cross diagonally. */
static int polylines_touch(const tn_contour *a, const tn_contour *b)
{
    int i, j;
    for (i = 0; i < a->npoints; i++)
        for (j = 0; j < b->npoints; j++) {
            if (a->points[3 * i] == b->points[3 * j] && a->points[3 * i + 1] == b->points[3 * j + 1]) return 1;
            if (i + 1 < a->npoints && j + 1 < b->npoints &&
                seg_cross(a->points + 3 * i, a->points + 3 * i + 3, b->points + 3 * j, b->points + 3 * j + 3))
                return 1;
        }
    return 0;
}

TN_TEST(random_sketch_no_crossings_and_deterministic)
{
    static const char *txt = "terrainnet-sketch 1\ncanvas 128 96\nridge start 0.9 rate -0.002\n5 48\n64 40\n122 60\nend\n"
                             "valley start 0.1 rate 0\n60 2\n70 90\nend\n";
    tn_contour_set user = {0, 0, 0, NULL}, dense = {0, 0, 0, NULL}, a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL}, c = {0, 0, 0, NULL};
    tn_sketch_random_opts o;
    int i, j, nr = 0, nv = 0, touching = 0;
    char *ta = NULL, *tb = NULL;
    size_t na = 0, nb = 0;
    memset(&o, 0, sizeof o);
    o.seed = 11;
    o.nodes = 40;
    TN_CHECK(tn_sketch_parse(&user, txt, strlen(txt), "u") == TN_OK);
    TN_CHECK(tn_sketch_random(&a, &user, 128, 96, &o) == TN_OK);
    TN_CHECK(a.count > 2 && sets_equal(&user, &user));
    /* the user's polylines come first, unchanged */
    TN_CHECK(a.items[0].npoints == 3 && !memcmp(a.items[0].points, user.items[0].points, 9 * sizeof(float)));
    TN_CHECK(tn_sketch_densify(&dense, &user) == TN_OK);
    for (i = 2; i < a.count; i++) {
        const tn_contour *c1 = &a.items[i];
        if (c1->type == TN_RIDGE) nr++; else nv++;
        for (j = 0; j < c1->npoints; j++) {
            float h = c1->points[3 * j + 2];
            TN_CHECK(c1->type == TN_RIDGE ? h >= 0.5f && h <= 1.0f : h >= 0.0f && h <= 0.5f);
            TN_CHECK(c1->points[3 * j] >= 0 && c1->points[3 * j] <= 127 && c1->points[3 * j + 1] >= 0 && c1->points[3 * j + 1] <= 95);
        }
        for (j = 1; j < c1->npoints; j++)
            TN_CHECK(fabsf(c1->points[3 * j] - c1->points[3 * j - 3]) <= 1 && fabsf(c1->points[3 * j + 1] - c1->points[3 * j - 2]) <= 1);
        /* no random polyline crosses the user's sketch */
        touching += polylines_touch(c1, &dense.items[0]) + polylines_touch(c1, &dense.items[1]);
        /* no random valley crosses a random ridge */
        for (j = 2; j < a.count; j++)
            if (c1->type == TN_VALLEY && a.items[j].type == TN_RIDGE) touching += polylines_touch(c1, &a.items[j]);
    }
    TN_CHECK(nr > 0 && nv > 0);
    TN_CHECK(touching == 0);
    for (o.seed = 100; o.seed < 120; o.seed++) { /* more layouts: still nothing crosses */
        TN_CHECK(tn_sketch_random(&c, &user, 128, 96, &o) == TN_OK);
        for (i = 2; i < c.count; i++) {
            touching += polylines_touch(&c.items[i], &dense.items[0]) + polylines_touch(&c.items[i], &dense.items[1]);
            for (j = 2; j < c.count; j++)
                if (c.items[i].type == TN_VALLEY && c.items[j].type == TN_RIDGE) touching += polylines_touch(&c.items[i], &c.items[j]);
        }
        tn_contour_set_free(&c);
    }
    TN_CHECK(touching == 0);
    o.seed = 11;
    TN_CHECK(tn_sketch_random(&b, &user, 128, 96, &o) == TN_OK);
    TN_CHECK(sets_equal(&a, &b));
    TN_CHECK(tn_sketch_format(&ta, &na, &a) == TN_OK && tn_sketch_format(&tb, &nb, &b) == TN_OK && na == nb && !memcmp(ta, tb, na));
    o.seed = 12;
    TN_CHECK(tn_sketch_random(&c, &user, 128, 96, &o) == TN_OK);
    TN_CHECK(!sets_equal(&a, &c));
    tn_contour_set_free(&c);
    TN_CHECK(tn_sketch_random(&c, &user, 64, 96, &o) == TN_ERR_SHAPE);
    TN_CHECK(tn_sketch_random(&c, NULL, 1, 96, &o) == TN_ERR_INVALID_ARG);
    tn_free(ta);
    tn_free(tb);
    tn_contour_set_free(&user);
    tn_contour_set_free(&dense);
    tn_contour_set_free(&a);
    tn_contour_set_free(&b);
}

TN_TEST(parts_lengths_and_adjacency)
{
    tn_contour_set lines = {0, 0, 0, NULL}, parts = {0, 0, 0, NULL}, again = {0, 0, 0, NULL};
    size_t cap = 0;
    float pts[3 * 200];
    int i, j, k, covered = 0;
    lines.width = lines.height = 300;
    /* a 97-point staircase; a 60-point line with a break after point 23; a 4-point stub */
    for (i = 0; i < 97; i++) { pts[3 * i] = (float)(i / 2 + 1); pts[3 * i + 1] = (float)((i + 1) / 2 + 1); pts[3 * i + 2] = (float)i; }
    TN_CHECK(tn__cset_add(&lines, &cap, TN_RIDGE, 3, 0.5f, pts, 97) == TN_OK);
    for (i = 0; i < 60; i++) { pts[3 * i] = (float)(i + (i > 23 ? 5 : 0)); pts[3 * i + 1] = 200; pts[3 * i + 2] = 1; }
    TN_CHECK(tn__cset_add(&lines, &cap, TN_VALLEY, 1, 0.0f, pts, 60) == TN_OK);
    TN_CHECK(tn__cset_add(&lines, &cap, TN_VALLEY, 1, 0.0f, pts, 4) == TN_OK);
    TN_CHECK(tn_contour_parts_make(&parts, &lines, 5) == TN_OK);
    TN_CHECK(parts.width == 300 && parts.count >= 15);
    for (i = 0; i < parts.count; i++) {
        const tn_contour *p = &parts.items[i];
        TN_CHECK(p->npoints >= 5 && p->npoints <= 10);
        for (j = 1; j < p->npoints; j++)
            TN_CHECK(fabsf(p->points[3 * j] - p->points[3 * j - 3]) <= 1 && fabsf(p->points[3 * j + 1] - p->points[3 * j - 2]) <= 1);
        if (p->type == TN_RIDGE) {
            TN_CHECK(p->order == 3 && p->mean_gradient == 0.5f);
            covered += p->npoints;
            /* consecutive ridge parts continue each other */
            if (i > 0 && parts.items[i - 1].type == TN_RIDGE)
                TN_CHECK(p->points[2] == parts.items[i - 1].points[3 * parts.items[i - 1].npoints - 1] + 1);
        } else {
            /* no valley part spans the break between x = 23 and x = 29 */
            for (k = 0; k < p->npoints; k++) TN_CHECK(p->points[3 * k] <= 23 || p->points[3 * k] >= 29);
        }
    }
    TN_CHECK(covered == 97); /* the whole ridge is used: no short tail is lost */
    TN_CHECK(tn_contour_parts_make(&again, &lines, 5) == TN_OK && sets_equal(&parts, &again));
    tn_contour_set_free(&again);
    TN_CHECK(tn_contour_parts_make(&again, &lines, 6) == TN_OK && !sets_equal(&parts, &again));
    tn_contour_set_free(&again);
    tn_contour_set_free(&parts);
    tn_contour_set_free(&lines);
}

/* The cutter follows the contour graph across junctions: a T of three polylines meeting at one
   pixel is listed A, C (through the junction: C is the lower line index), then B after a break; a ring of four lines without
   a free end is still cut. Every pixel ends up in exactly one part, except the junction and the
   ring's start, where the list resumes after a break (C starts at the junction; the ring closes). */
TN_TEST(parts_follow_the_graph_across_junctions)
{
    tn_contour_set lines = {0, 0, 0, NULL}, parts = {0, 0, 0, NULL};
    size_t cap = 0;
    float pts[3 * 16];
    uint8_t hit[64 * 64];
    int i, j, across = 0, total = 0, seed;
    lines.width = lines.height = 64;
    /* A: (10..20, 10) ending at the junction; C: (20, 10..20) leaving it downwards; B: (20..30, 10) */
    for (i = 0; i <= 10; i++) { pts[3 * i] = (float)(10 + i); pts[3 * i + 1] = 10; pts[3 * i + 2] = 1; }
    TN_CHECK(tn__cset_add(&lines, &cap, TN_VALLEY, 2, 0.0f, pts, 11) == TN_OK);
    for (i = 0; i <= 10; i++) { pts[3 * i] = 20; pts[3 * i + 1] = (float)(10 + i); pts[3 * i + 2] = 2; }
    TN_CHECK(tn__cset_add(&lines, &cap, TN_VALLEY, 1, 0.0f, pts, 11) == TN_OK);
    for (i = 0; i <= 10; i++) { pts[3 * i] = (float)(20 + i); pts[3 * i + 1] = 10; pts[3 * i + 2] = 3; }
    TN_CHECK(tn__cset_add(&lines, &cap, TN_VALLEY, 1, 0.0f, pts, 11) == TN_OK);
    /* a ring: four sides of the square (40..50) x (40..50), each from corner to corner */
    for (j = 0; j < 4; j++) {
        for (i = 0; i <= 10; i++) {
            int t = j < 2 ? i : 10 - i;
            pts[3 * i] = (float)(40 + (j == 0 ? t : j == 1 ? 10 : j == 2 ? t : 0));
            pts[3 * i + 1] = (float)(40 + (j == 0 ? 0 : j == 1 ? t : j == 2 ? 10 : t));
            pts[3 * i + 2] = 5;
        }
        TN_CHECK(tn__cset_add(&lines, &cap, TN_RIDGE, 1, 0.0f, pts, 11) == TN_OK);
    }
    for (seed = 1; seed <= 20; seed++) {
        TN_CHECK(tn_contour_parts_make(&parts, &lines, (uint64_t)seed) == TN_OK);
        memset(hit, 0, sizeof hit);
        total = 0;
        for (i = 0; i < parts.count; i++) {
            const tn_contour *p = &parts.items[i];
            int left = 0, down = 0;
            TN_CHECK(p->npoints >= 5 && p->npoints <= 10);
            for (j = 0; j < p->npoints; j++) {
                int x = (int)p->points[3 * j], y = (int)p->points[3 * j + 1];
                if (j) TN_CHECK(abs(x - (int)p->points[3 * j - 3]) + abs(y - (int)p->points[3 * j - 2]) == 1);
                hit[y * 64 + x]++;
                total++;
                if (p->type == TN_VALLEY) { left += y == 10 && x < 20; down += x == 20 && y > 10; }
            }
            if (left && down) {
                across++;
                TN_CHECK(p->order == 2); /* attributes of the line the part starts on: A */
            }
        }
        for (j = 0; j < 64 * 64; j++) TN_CHECK(j == 10 * 64 + 20 || j == 40 * 64 + 40 ? hit[j] == 2 : hit[j] <= 1);
        TN_CHECK(total == 32 + 41); /* T: 31 pixels and the junction again; ring: 40 and its start again */
        tn_contour_set_free(&parts);
    }
    printf("parts across the junction: %d of 20 seeds\n", across);
    TN_CHECK(across >= 10); /* parts run from A into C through the junction (unless a cut falls on it) */
    tn_contour_set_free(&lines);
}

static int cancel_progress(void *user, const char *stage, double f)
{
    (void)f;
    *(int *)user += !strcmp(stage, "align");
    return 1;
}

/* DEM parts: random pixel walks; the sketch = a few of them rotated by pi/2 about the canvas
   centre (x, y) -> (H - 1 - y, x). Each must align to its source. */
TN_TEST(align_planted_rotated_copy)
{
    tn_contour_set dem = {0, 0, 0, NULL}, sk = {0, 0, 0, NULL};
    size_t cap = 0, cap2 = 0;
    tn_rng r;
    float pts[30];
    int i, j, src[6] = {3, 77, 150, 222, 301, 399}, match[6], match2[6];
    tn_align_opts o;
    tn_rng_seed(&r, 3, 3);
    dem.width = dem.height = sk.width = sk.height = 128;
    for (i = 0; i < 400; i++) {
        int n = 5 + (int)tn_rng_below(&r, 6), x = 20 + (int)tn_rng_below(&r, 80), y = 20 + (int)tn_rng_below(&r, 80);
        float h = tn_rng_uniform(&r) * 1000.0f;
        for (j = 0; j < n; j++) {
            pts[3 * j] = (float)x;
            pts[3 * j + 1] = (float)y;
            pts[3 * j + 2] = h + 5.0f * j;
            x += (int)tn_rng_below(&r, 3) - 1 + (j % 2);
            y += (int)tn_rng_below(&r, 3) - 1;
        }
        TN_CHECK(tn__cset_add(&dem, &cap, i % 3 ? TN_RIDGE : TN_VALLEY, 1, 0.0f, pts, n) == TN_OK);
    }
    for (i = 0; i < 6; i++) {
        const tn_contour *c = &dem.items[src[i]];
        for (j = 0; j < c->npoints; j++) {
            pts[3 * j] = 127.0f - c->points[3 * j + 1];
            pts[3 * j + 1] = c->points[3 * j];
            pts[3 * j + 2] = c->points[3 * j + 2];
        }
        TN_CHECK(tn__cset_add(&sk, &cap2, c->type, 0, 0.0f, pts, c->npoints) == TN_OK);
    }
    memset(&o, 0, sizeof o);
    o.choices = 1;
    o.raw_heights = 1;
    TN_CHECK(tn_sketch_align(match, &sk, &dem, &o) == TN_OK);
    for (i = 0; i < 6; i++) {
        if (match[i] != src[i]) fprintf(stderr, "part %d aligned to %d, source %d\n", i, match[i], src[i]);
        TN_CHECK(match[i] == src[i]);
    }
    /* default choices (5): seeded, reproducible for any thread count, and of the right type */
    o.choices = 0;
    o.seed = 9;
    tn_set_threads(1);
    TN_CHECK(tn_sketch_align(match, &sk, &dem, &o) == TN_OK);
    tn_set_threads(2);
    TN_CHECK(tn_sketch_align(match2, &sk, &dem, &o) == TN_OK);
    tn_set_threads(0);
    TN_CHECK(!memcmp(match, match2, sizeof match));
    for (i = 0; i < 6; i++) TN_CHECK(match[i] >= 0 && match[i] < 400 && dem.items[match[i]].type == sk.items[i].type);
    /* progress reaches the hook, which can cancel */
    i = 0;
    tn_set_progress(cancel_progress, &i);
    TN_CHECK(tn_sketch_align(match, &sk, &dem, &o) == TN_ERR_CANCELLED && i == 1);
    tn_set_progress(NULL, NULL);
    tn_contour_set_free(&dem);
    tn_contour_set_free(&sk);
}

/* Parts longer than 64 codes take the diagonal-walk path of the substring search. */
TN_TEST(align_long_parts)
{
    tn_contour_set dem = {0, 0, 0, NULL}, sk = {0, 0, 0, NULL};
    size_t cap = 0, cap2 = 0;
    tn_rng r;
    float pts[3 * 100];
    int i, j, match[1];
    tn_align_opts o;
    tn_rng_seed(&r, 4, 4);
    dem.width = dem.height = sk.width = sk.height = 400;
    for (i = 0; i < 5; i++) {
        int x = 150, y = 150;
        for (j = 0; j < 100; j++) {
            pts[3 * j] = (float)x;
            pts[3 * j + 1] = (float)y;
            pts[3 * j + 2] = (float)(i * 10 + j);
            x += (int)tn_rng_below(&r, 2);
            y += (int)tn_rng_below(&r, 3) - 1;
        }
        TN_CHECK(tn__cset_add(&dem, &cap, TN_RIDGE, 1, 0.0f, pts, 100) == TN_OK);
    }
    for (j = 0; j < 100; j++) { /* part 3 turned by pi (x, y) -> (399 - x, 399 - y) */
        pts[3 * j] = 399.0f - dem.items[3].points[3 * j];
        pts[3 * j + 1] = 399.0f - dem.items[3].points[3 * j + 1];
        pts[3 * j + 2] = dem.items[3].points[3 * j + 2];
    }
    TN_CHECK(tn__cset_add(&sk, &cap2, TN_RIDGE, 0, 0.0f, pts, 100) == TN_OK);
    memset(&o, 0, sizeof o);
    o.choices = 1;
    o.raw_heights = 1; /* every DEM part is in the top 10 here, so heights decide */
    TN_CHECK(tn_sketch_align(match, &sk, &dem, &o) == TN_OK);
    if (match[0] != 3) fprintf(stderr, "long part aligned to %d\n", match[0]);
    TN_CHECK(match[0] == 3);
    tn_contour_set_free(&dem);
    tn_contour_set_free(&sk);
}

int main(void)
{
    TN_RUN(tns_parse_and_round_trip);
    TN_RUN(tns_numbers_round_trip_exactly);
    TN_RUN(tns_comma_locale);
    TN_RUN(tns_malformed);
    TN_RUN(strokes_limit);
    TN_RUN(png_sketch_read);
    TN_RUN(densify_and_rasterise);
    TN_RUN(mst_known_points);
    TN_RUN(delaunay_empty_circumcircles);
    TN_RUN(random_sketch_no_crossings_and_deterministic);
    TN_RUN(parts_lengths_and_adjacency);
    TN_RUN(parts_follow_the_graph_across_junctions);
    TN_RUN(align_planted_rotated_copy);
    TN_RUN(align_long_parts);
    return tn_test_summary("test_sketch");
}
