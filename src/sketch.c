/* ============================================================================================
   @@sketch  contour sets: ridge and valley polylines (paper 000, sections 4.1 and 5)
   One type carries extracted ridge/valley networks, their contour parts and user sketches: a
   canvas size and a list of polylines, each point (x, y, height) in canvas pixels and the
   height units of its source (metres for an extracted DEM, [0, 1] for a drawn sketch).
   On it: the .tns text format, sketches drawn as images (thinning + tracing), rasterising,
   random sketches (5.2: MST of random nodes, MST of their Voronoi vertices), cutting polylines
   into 5-10 point contour parts (4.1) and aligning sketch parts to DEM parts (5.3, A1/A2:
   chain codes, rotation by k pi/4, longest common substring, height mean/std, seeded pick).
   ============================================================================================ */
#ifndef TN_NO_SKETCH

typedef enum tn_contour_type { TN_VALLEY = 0, TN_RIDGE = 1 } tn_contour_type;

typedef struct tn_contour {
    tn_contour_type type;
    int order;             /* Strahler order (1 = source segment); 0 when unknown */
    int npoints;
    float mean_gradient;   /* mean slope magnitude along the polyline; 0 when unknown */
    float *points;         /* npoints * 3 floats: x, y, height */
} tn_contour;

typedef struct tn_contour_set {
    int width, height;     /* canvas size in pixels */
    int count;
    tn_contour *items;
} tn_contour_set;

/* Frees every polyline and zeroes *set. Safe on a zeroed set. */
TN_API void tn_contour_set_free(tn_contour_set *set);

/* ---- sketch files (.tns) ---------------------------------------------------------------------
   A human-editable text format for any contour set (user sketches, extracted ridge/valley
   networks, contour parts). Line by line, '#' starts a comment, blank lines are ignored:

       terrainnet-sketch 1              first line: magic and version
       canvas 256 256                   canvas width and height in pixels (once, before polylines)
       ridge order 2 gradient 0.13      opens a polyline: `ridge` or `valley`, then optional
                                        `order N` (Strahler, default 0), `gradient G` (mean slope,
                                        default 0), `start H` and `rate R` (see below)
       10 20 0.8                        one point per line: x y [h], pixels, (0, 0) = top-left
       40.5 22 0.75                     pixel centre; x in [-0.5, W - 0.5], y likewise
       end                              closes the polyline

   A point without h takes start + rate * (arc length in pixels from the first point), so
   `valley start 0.2 rate 0.001` rises 0.001 per pixel. Heights are [0, 1] for drawn sketches
   and metres for extracted networks. Saving writes every height, order and gradient as the
   shortest locale-free text that reads back as the same float, so load(save(s)) == s exactly;
   reading ignores the C locale too. Errors carry "file:line:". */

#define TN_SKETCH_MAX_SIDE 65536           /* largest canvas side */
#define TN_SKETCH_MAX_POINTS (1 << 26)     /* most points in one file */
#define TN_SKETCH_MAX_COVER 1              /* strokes cover the canvas at most once over (below) */

/* The strokes' limit. A set's polylines drawn pixel by pixel (as tn_sketch_densify draws them:
   a polyline's first point, then for each segment whose ends lie in different pixels its span
   max(|dx|, |dy|) rounded up) may cover at most TN_SKETCH_MAX_COVER x width x height + 4096
   pixels, and never more than TN_SKETCH_MAX_POINTS. A traced drawing covers at most about half
   its canvas (one-pixel lines need gaps between them), an extracted network about a tenth; the
   work of generating from a sketch grows with its strokes. Every function that takes a contour
   set refuses more with TN_ERR_TOO_LARGE, the parser as soon as the strokes pass the limit. */

/* Parses .tns text (n bytes, need not be NUL-terminated). `name` (may be NULL) prefixes messages.
   Fails with TN_ERR_FORMAT (not a sketch, unknown version), TN_ERR_CORRUPT (malformed line,
   missing canvas or end, point outside the canvas), TN_ERR_NUMERIC (NaN/Inf), TN_ERR_TOO_LARGE
   (canvas side, point count or strokes over the limits). On success *out is allocated (tn_contour_set_free). */
TN_API tn_status tn_sketch_parse(tn_contour_set *out, const char *text, size_t n, const char *name);
/* Loads a .tns file, or a sketch drawn as an image (see tn_sketch_from_image) when the file is
   not .tns text. *out is untouched on failure. */
TN_API tn_status tn_sketch_load(tn_contour_set *out, const char *path);
/* Writes the set as .tns text into a TN_MALLOC'd buffer (free with tn_free). Fails with
   TN_ERR_NUMERIC on NaN/Inf points and TN_ERR_INVALID_ARG on a bad canvas, an empty polyline, an
   order outside 0-1000 or a point outside the canvas (so whatever is written reads back). */
TN_API tn_status tn_sketch_format(char **text, size_t *size, const tn_contour_set *set);
/* Saves as .tns through a temporary file and a rename: on any error the target is untouched. */
TN_API tn_status tn_sketch_save(const char *path, const tn_contour_set *set);

/* Reads a sketch drawn as an RGB(A) image: strokes in saturated red are ridges, saturated blue
   are valleys; everything else (white, black, grey, yellow, ...) is background. A pixel is a
   stroke when v = max(r, b) >= 0.1, v - g >= v / 2 and |r - b| >= v / 2; its height is v, so a
   bright stroke is high and a dark one low (heights in [0.1, 1]). Strokes of any width are
   thinned (tn_skeletonize) and traced into polylines between endpoints and junctions; the canvas
   is the image size. Fails with TN_ERR_SHAPE for 1-2 channel images, TN_ERR_EMPTY without strokes. */
TN_API tn_status tn_sketch_from_image(tn_contour_set *out, const tn_image *img);

/* Thins a binary mask (w*h bytes, non-zero = set) in place to one-pixel-wide 8-connected lines
   that keep the topology: Guo-Hall thinning (keeps two-pixel diagonal strokes), then any pixel
   whose removal keeps the 8-connected topology and that is not an endpoint is removed. Used for
   drawn sketches and for extracted ridge/valley networks. */
TN_API tn_status tn_skeletonize(uint8_t *mask, int width, int height);

/* Resamples every polyline to an 8-connected chain of integer pixels (consecutive points
   differ by at most 1 in x and y, no repeats), heights linear between the original points.
   Use before tn_contour_parts_make on sketches whose points are far apart. *out allocated here. */
TN_API tn_status tn_sketch_densify(tn_contour_set *out, const tn_contour_set *in);

/* Rasterises to a width x height x 3 image (any size; coordinates scale from the canvas):
   channel 0 = 1 on ridge pixels, channel 1 = 1 on valley pixels, channel 2 = the sketch height
   there (0 elsewhere; where lines overlap, the later polyline wins). *out allocated here. */
TN_API tn_status tn_sketch_rasterise(tn_image *out, const tn_contour_set *set, int width, int height);
/* RGB preview: ridges yellow, valleys blue, over a hillshade of `dem` (resized; may be NULL for
   a grey background). Lines are 1 px wide up to 511 px and thicker above. *out allocated here. */
TN_API tn_status tn_sketch_preview(tn_image *out, const tn_contour_set *set, const tn_image *dem, int width, int height);

/* ---- random sketches (section 5.2) ---------------------------------------------------------
   n random nodes with heights in [0.5, 1] joined by a Euclidean minimum spanning tree are the
   candidate ridges; the Voronoi vertices of the nodes (circumcentres of their Delaunay
   triangles, inside the canvas) with heights in [0, 0.5] joined by another MST are the candidate
   valleys. Each edge is drawn as an 8-connected pixel line; ridge edges that touch or cross the
   user's sketch pixels are dropped, then valley edges that touch or cross the sketch or a kept
   ridge, so nothing crosses in the output. Kept edges are chained between branch points, heights
   linear along each edge. */

typedef struct tn_sketch_random_opts {
    uint64_t seed;
    int nodes;            /* random ridge nodes, at most 8192; 0 = width * height / 1024, clamped to [8, 2048];
                             negative: TN_ERR_INVALID_ARG */
} tn_sketch_random_opts;
/* *out = the user's polylines (user may be NULL or empty) followed by the random ridges and
   valleys, on a width x height canvas (user's canvas size must match when given, else
   TN_ERR_SHAPE). Same seed, same output. opts may be NULL. */
TN_API tn_status tn_sketch_random(tn_contour_set *out, const tn_contour_set *user, int width, int height,
                                  const tn_sketch_random_opts *opts);

/* Delaunay triangulation (Bowyer-Watson, O(n^2); fine for a few thousand points) of n points
   xy[2n]: *ntriangles triangles of 3 point indices each (winding unspecified), TN_MALLOC'd, free
   with tn_free. Exact duplicate points are skipped; fewer than 3 distinct points give none. */
TN_API tn_status tn_delaunay(int **triangles, int *ntriangles, const float *xy, int n);
/* Euclidean minimum spanning tree (Prim, O(n^2)) of n >= 1 points: *edges holds n - 1 pairs of
   point indices (TN_MALLOC'd, free with tn_free). Ties go to the lower index. NaN/Inf
   coordinates fail with TN_ERR_NUMERIC. */
TN_API tn_status tn_mst(int **edges, const float *xy, int n);

/* ---- contour parts (section 4.1) -----------------------------------------------------------
   The polylines form a graph: ends of the same type at the same or 8-adjacent pixels meet (a
   junction). From each free end (lowest line index first; then from any closed loop left), a
   depth-first walk lists the points of the lines it reaches, each line from the end it is
   entered by, the lines on its far end first (lowest index first), a shared junction pixel
   once. The list is cut into parts of 5-10 points (seeded random lengths; a tail that would be
   shorter than 5 is taken into the last part when that stays <= 10 points); where consecutive
   points are not 8-adjacent (|dx| or |dy| > 1.5 px: the walk jumped back to a junction) the
   window is split at the break and pieces under 5 points are dropped. So parts run through
   junctions. A part takes the type, order and gradient of the line its first point is on; its
   index is its position in *parts (same input and seed, same parts). Used for DEM networks and
   densified sketches alike. An empty input gives an empty set. */
TN_API tn_status tn_contour_parts_make(tn_contour_set *parts, const tn_contour_set *lines, uint64_t seed);

/* ---- alignment (section 5.3, algorithms A1 and A2) ------------------------------------------
   Every part becomes an 8-direction chain code (steps quantised to k * pi/4), reversed when it
   runs right-to-left (first x > last x); each DEM part is rotated by the multiple of pi/4 nearest
   to the angle between the two parts' first-to-last vectors. The longest common substring of
   the codes picks the 10 best DEM parts (ties: smaller height score), the height score on the
   common substring, |mean(d)| + std(d) with d the height differences after each set is scaled
   to [0, 1] by its own range, ranks them, and one of the best 5 is chosen with the seeded RNG.
   Only parts of the same type (ridge/valley) are candidates when the DEM has any. */

typedef struct tn_align_opts {
    uint64_t seed;
    int top;              /* candidates kept by LCS length; 0 = 10 (at most 64) */
    int choices;          /* random pick among the best this many by height; 0 = 5 (1 = greedy) */
    int raw_heights;      /* 1: compare heights as given instead of scaling each set to [0, 1] */
} tn_align_opts;
/* match[i] (caller-allocated, sketch_parts->count ints) = index of the DEM part aligned to sketch
   part i. TN_ERR_EMPTY when either set has no parts; threaded, same result for any thread count.
   Reports progress as stage "align" every 1024 sketch parts (cancellable). */
TN_API tn_status tn_sketch_align(int *match, const tn_contour_set *sketch_parts,
                                 const tn_contour_set *dem_parts, const tn_align_opts *opts);
#endif /* TN_NO_SKETCH */

/* --------------------------------------------------------------------------------------------
   >>sketch  (@@sketch implementation)
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_SKETCH

TN_API void tn_contour_set_free(tn_contour_set *set) {
    int i;
    if (!set) return;
    for (i = 0; i < set->count; i++) TN_FREE(set->items[i].points);
    TN_FREE(set->items);
    memset(set, 0, sizeof(*set));
}

/* ---- small builders shared by the sketch code ---- */

/* Widens [*lo, *hi] to take in every point height of s (start from FLT_MAX, -FLT_MAX). */
TN__INTERNAL_SHARED void tn__cset_height_range(const tn_contour_set *s, float *lo, float *hi)
{
    int c, j;
    for (c = 0; c < s->count; c++)
        for (j = 0; j < s->items[c].npoints; j++) {
            float h = s->items[c].points[3 * j + 2];
            if (h < *lo) *lo = h;
            if (h > *hi) *hi = h;
        }
}

/* Appends a polyline (points copied) to *s, whose items array has capacity *cap bytes. */
TN__INTERNAL tn_status tn__cset_add(tn_contour_set *s, size_t *cap, tn_contour_type type, int order, float gradient,
                              const float *pts, int npts)
{
    tn_contour *c;
    tn_status st;
    if (s->count == INT_MAX) return tn__fail(TN_ERR_TOO_LARGE, "more than %d polylines", INT_MAX);
    st = tn__reserve((void **)&s->items, cap, ((size_t)s->count + 1) * sizeof(tn_contour));
    if (st) return st;
    c = &s->items[s->count];
    c->points = (float *)tn__alloc((size_t)npts * 3 * sizeof(float));
    if (!c->points) return TN_ERR_OUT_OF_MEMORY;
    if (npts) memcpy(c->points, pts, (size_t)npts * 3 * sizeof(float));
    c->type = type;
    c->order = order;
    c->npoints = npts;
    c->mean_gradient = gradient;
    s->count++;
    return TN_OK;
}

/* A growable list of (x, y, h) points; cap in bytes (tn__reserve). */
typedef struct tn__pts { float *p; int n; size_t cap; } tn__pts;

static tn_status tn__pts_push(tn__pts *b, float x, float y, float h)
{
    tn_status st;
    if (b->n >= TN_SKETCH_MAX_POINTS) return tn__fail(TN_ERR_TOO_LARGE, "polyline longer than %d points", TN_SKETCH_MAX_POINTS);
    st = tn__reserve((void **)&b->p, &b->cap, ((size_t)b->n + 1) * 3 * sizeof(float));
    if (st) return st;
    b->p[3 * b->n] = x;
    b->p[3 * b->n + 1] = y;
    b->p[3 * b->n + 2] = h;
    b->n++;
    return TN_OK;
}

/* Appends the 8-connected integer-pixel chain through pts (canvas coordinates mapped by pixel
   centres: x' = (x + 0.5) * sx - 0.5), heights linear along each segment, no repeated pixels. */
static tn_status tn__chain_pixels(const float *pts, int n, float sx, float sy, tn__pts *out)
{
    int i, t, steps;
    tn_status st;
    for (i = 0; i < n; i++) {
        float x1 = (pts[3 * i] + 0.5f) * sx - 0.5f, y1 = (pts[3 * i + 1] + 0.5f) * sy - 0.5f, h1 = pts[3 * i + 2];
        float x0 = x1, y0 = y1, h0 = h1;
        if (i > 0) {
            x0 = (pts[3 * i - 3] + 0.5f) * sx - 0.5f;
            y0 = (pts[3 * i - 2] + 0.5f) * sy - 0.5f;
            h0 = pts[3 * i - 1];
        }
        {
            float span = ceilf(fmaxf(fabsf(x1 - x0), fabsf(y1 - y0)));
            /* far-off points (a programmatic set): the int cast would be undefined, the walk endless */
            if (!(span <= (float)TN_SKETCH_MAX_POINTS))
                return tn__fail(TN_ERR_TOO_LARGE, "polyline segment %d spans %g pixels", i, (double)span);
            steps = (int)span;
        }
        for (t = i > 0 ? 1 : 0; t <= steps; t++) {
            float f = steps ? (float)t / (float)steps : 1.0f;
            float px = floorf(x0 + f * (x1 - x0) + 0.5f), py = floorf(y0 + f * (y1 - y0) + 0.5f);
            if (out->n && out->p[3 * out->n - 3] == px && out->p[3 * out->n - 2] == py) continue;
            if ((st = tn__pts_push(out, px, py, h0 + f * (h1 - h0)))) return st;
        }
    }
    return TN_OK;
}

/* Pixels a segment adds to its polyline drawn pixel by pixel (tn__chain_pixels at scale 1): none
   within one pixel, else its span rounded up. In double: the same count from the parser and from
   the set it made, on any FPU. */
static uint64_t tn__stroke_pixels(const float *a, const float *b)
{
    double dx = fabs((double)b[0] - a[0]), dy = fabs((double)b[1] - a[1]);
    if (floor((double)a[0] + 0.5) == floor((double)b[0] + 0.5) && floor((double)a[1] + 0.5) == floor((double)b[1] + 0.5)) return 0;
    return (uint64_t)ceil(dx > dy ? dx : dy);
}

/* Most stroke pixels a w x h canvas takes (TN_SKETCH_MAX_COVER). */
static uint64_t tn__stroke_limit(int w, int h)
{
    uint64_t l = (uint64_t)TN_SKETCH_MAX_COVER * (uint64_t)w * (uint64_t)h + 4096;
    return l < (uint64_t)TN_SKETCH_MAX_POINTS ? l : (uint64_t)TN_SKETCH_MAX_POINTS;
}

/* Checks that every point is finite, the canvas sane and the strokes within their limit; `what`
   names the set in messages. */
static tn_status tn__cset_check(const tn_contour_set *s, const char *what)
{
    uint64_t strokes = 0;
    int i, j;
    if (!s || s->width <= 0 || s->height <= 0) return tn__fail(TN_ERR_INVALID_ARG, "%s: no canvas size", what);
    if (s->width > TN_SKETCH_MAX_SIDE || s->height > TN_SKETCH_MAX_SIDE)
        return tn__fail(TN_ERR_TOO_LARGE, "%s: canvas %d x %d exceeds %d", what, s->width, s->height, TN_SKETCH_MAX_SIDE);
    if (s->count < 0 || (s->count > 0 && !s->items)) return tn__fail(TN_ERR_INVALID_ARG, "%s: bad polyline list", what);
    for (i = 0; i < s->count; i++) {
        const tn_contour *c = &s->items[i];
        if (c->npoints <= 0 || !c->points) return tn__fail(TN_ERR_INVALID_ARG, "%s: polyline %d is empty", what, i);
        if (!isfinite(c->mean_gradient)) return tn__fail(TN_ERR_NUMERIC, "%s: polyline %d has a NaN/Inf gradient", what, i);
        for (j = 0; j < 3 * c->npoints; j++) {
            if (!isfinite(c->points[j])) return tn__fail(TN_ERR_NUMERIC, "%s: polyline %d point %d is NaN/Inf", what, i, j / 3);
            /* pixel coordinates are rounded to int: keep them where that is defined */
            if (j % 3 != 2 && fabsf(c->points[j]) > (float)(16 * TN_SKETCH_MAX_SIDE))
                return tn__fail(TN_ERR_INVALID_ARG, "%s: polyline %d point %d lies far outside the canvas", what, i, j / 3);
        }
        strokes++;
        for (j = 1; j < c->npoints; j++) strokes += tn__stroke_pixels(c->points + 3 * j - 3, c->points + 3 * j);
    }
    if (strokes > tn__stroke_limit(s->width, s->height))
        return tn__fail(TN_ERR_TOO_LARGE, "%s: the polylines drawn pixel by pixel cover %llu pixels, over the limit of %llu for a %d x %d "
                        "canvas (%d per canvas pixel + 4096, at most %d)", what, (unsigned long long)strokes,
                        (unsigned long long)tn__stroke_limit(s->width, s->height), s->width, s->height, TN_SKETCH_MAX_COVER, TN_SKETCH_MAX_POINTS);
    return TN_OK;
}

/* ---- .tns text ---- */

#define TN__TNS_MAXTOK 16

typedef struct tn__tns_parser {
    const char *name;
    int line;
    tn_contour_set set;
    size_t set_cap;
    tn__pts pts;
    long total_points;
    uint64_t strokes;      /* pixels drawn so far (tn__stroke_pixels) */
} tn__tns_parser;

/* Fails with "name:line: message". */
static tn_status tn__tns_err(tn__tns_parser *p, tn_status s, const char *fmt, ...)
{
    char msg[256];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    return tn__fail(s, "%s:%d: %s", p->name, p->line, msg);
}

/* Whether a number read as a double rounds to a finite float: below FLT_MAX plus half its ulp
   (2^103; the tie rounds up, to Inf). So every float the writer writes reads back, FLT_MAX too. */
static int tn__tns_float_ok(double v)
{
    return fabs(v) < (double)FLT_MAX + ldexp(1.0, 103);
}

/* Reads a number token for field `what`; NaN/Inf -> TN_ERR_NUMERIC, text -> TN_ERR_CORRUPT. */
static tn_status tn__tns_num(tn__tns_parser *p, const char *tok, const char *what, double *v)
{
    if (!tn__io_number(tok, strlen(tok), v)) return tn__tns_err(p, TN_ERR_CORRUPT, "%s is not a number", what);
    if (!tn__tns_float_ok(*v)) return tn__tns_err(p, TN_ERR_NUMERIC, "%s is NaN, Inf or out of float range", what);
    return TN_OK;
}

/* Polyline header: `ridge|valley [order N] [gradient G] [start H] [rate R]`. */
static tn_status tn__tns_open(tn__tns_parser *p, char **tok, int ntok, int *order, float *grad, int *has_start,
                              double *start, double *rate)
{
    int i;
    double v;
    tn_status st;
    *order = 0;
    *grad = 0.0f;
    *has_start = 0;
    *start = *rate = 0.0;
    if ((ntok - 1) % 2) return tn__tns_err(p, TN_ERR_CORRUPT, "'%s' attributes come in pairs: order N, gradient G, start H, rate R", tok[0]);
    for (i = 1; i + 1 < ntok; i += 2) {
        if ((st = tn__tns_num(p, tok[i + 1], tok[i], &v))) return st;
        if (!strcmp(tok[i], "order")) {
            if (v < 0 || v > 1000 || v != floor(v)) return tn__tns_err(p, TN_ERR_CORRUPT, "order must be an integer 0-1000");
            *order = (int)v;
        } else if (!strcmp(tok[i], "gradient")) *grad = (float)v;
        else if (!strcmp(tok[i], "start")) { *start = v; *has_start = 1; }
        else if (!strcmp(tok[i], "rate")) *rate = v;
        else return tn__tns_err(p, TN_ERR_CORRUPT, "unknown polyline attribute '%s'", tok[i]);
    }
    return TN_OK;
}

static tn_status tn__tns_parse_lines(tn__tns_parser *p, char *buf)
{
    char *line = buf, *next, *tok[TN__TNS_MAXTOK];
    int ntok, state = 0, open_line = 0, order = 0, has_start = 0;
    float grad = 0.0f;
    double start = 0, rate = 0, arc = 0;
    tn_contour_type type = TN_RIDGE;
    tn_status st;
    for (; line; line = next) {
        char *c;
        p->line++;
        next = strchr(line, '\n');
        if (next) *next++ = 0;
        if ((c = strchr(line, '#'))) *c = 0;
        for (ntok = 0, c = line;;) {
            while (*c == ' ' || *c == '\t' || *c == '\r' || *c == '\f' || *c == '\v') c++;
            if (!*c) break;
            if (ntok == TN__TNS_MAXTOK) return tn__tns_err(p, TN_ERR_CORRUPT, "too many fields on one line");
            tok[ntok++] = c;
            while (*c && *c != ' ' && *c != '\t' && *c != '\r' && *c != '\f' && *c != '\v') c++;
            if (*c) *c++ = 0;
        }
        if (!ntok) continue;
        if (state == 0) {
            if (strcmp(tok[0], "terrainnet-sketch"))
                return tn__tns_err(p, TN_ERR_FORMAT, "not a terrainnet sketch (the first line must be 'terrainnet-sketch 1')");
            if (ntok != 2 || strcmp(tok[1], "1"))
                return tn__tns_err(p, TN_ERR_FORMAT, "unsupported sketch version '%s' (this reader knows 1)", ntok > 1 ? tok[1] : "");
            state = 1;
        } else if (state == 1) {
            if (!strcmp(tok[0], "canvas")) {
                double w, h;
                if (p->set.width) return tn__tns_err(p, TN_ERR_CORRUPT, "a second 'canvas' line");
                if (ntok != 3) return tn__tns_err(p, TN_ERR_CORRUPT, "expected 'canvas WIDTH HEIGHT'");
                if ((st = tn__tns_num(p, tok[1], "canvas width", &w)) || (st = tn__tns_num(p, tok[2], "canvas height", &h))) return st;
                if (w < 1 || h < 1 || w != floor(w) || h != floor(h))
                    return tn__tns_err(p, TN_ERR_CORRUPT, "canvas size must be positive integers");
                if (w > TN_SKETCH_MAX_SIDE || h > TN_SKETCH_MAX_SIDE)
                    return tn__tns_err(p, TN_ERR_TOO_LARGE, "canvas side over the limit of %d pixels", TN_SKETCH_MAX_SIDE);
                p->set.width = (int)w;
                p->set.height = (int)h;
            } else if (!strcmp(tok[0], "ridge") || !strcmp(tok[0], "valley")) {
                if (!p->set.width) return tn__tns_err(p, TN_ERR_CORRUPT, "'%s' before the 'canvas W H' line", tok[0]);
                type = tok[0][0] == 'r' ? TN_RIDGE : TN_VALLEY;
                if ((st = tn__tns_open(p, tok, ntok, &order, &grad, &has_start, &start, &rate))) return st;
                p->pts.n = 0;
                arc = 0;
                open_line = p->line;
                state = 2;
            } else if (!strcmp(tok[0], "end")) return tn__tns_err(p, TN_ERR_CORRUPT, "'end' without an open ridge/valley");
            else return tn__tns_err(p, TN_ERR_CORRUPT, "unknown keyword '%s' (expected canvas, ridge or valley)", tok[0]);
        } else {
            double x, y, h;
            if (!strcmp(tok[0], "end")) {
                if (ntok != 1) return tn__tns_err(p, TN_ERR_CORRUPT, "'end' takes no arguments");
                if (!p->pts.n) return tn__tns_err(p, TN_ERR_CORRUPT, "the polyline opened at line %d has no points", open_line);
                if ((st = tn__cset_add(&p->set, &p->set_cap, type, order, grad, p->pts.p, p->pts.n))) return st;
                state = 1;
                continue;
            }
            if (!strcmp(tok[0], "ridge") || !strcmp(tok[0], "valley") || !strcmp(tok[0], "canvas"))
                return tn__tns_err(p, TN_ERR_CORRUPT, "missing 'end' for the polyline opened at line %d", open_line);
            if (ntok < 2 || ntok > 3) return tn__tns_err(p, TN_ERR_CORRUPT, "expected a point 'x y [h]' or 'end', got '%s'", tok[0]);
            if ((st = tn__tns_num(p, tok[0], "x", &x)) || (st = tn__tns_num(p, tok[1], "y", &y))) return st;
            if (x < -0.5 || y < -0.5 || x > p->set.width - 0.5 || y > p->set.height - 0.5)
                return tn__tns_err(p, TN_ERR_CORRUPT, "point (%g, %g) lies outside the %d x %d canvas", x, y, p->set.width, p->set.height);
            if (p->pts.n) arc += sqrt((x - p->pts.p[3 * p->pts.n - 3]) * (x - p->pts.p[3 * p->pts.n - 3]) +
                                      (y - p->pts.p[3 * p->pts.n - 2]) * (y - p->pts.p[3 * p->pts.n - 2]));
            if (ntok == 3) {
                if ((st = tn__tns_num(p, tok[2], "height", &h))) return st;
            } else if (has_start) h = start + rate * arc;
            else return tn__tns_err(p, TN_ERR_CORRUPT, "point without a height in a polyline without 'start H'");
            if (!tn__tns_float_ok(h)) return tn__tns_err(p, TN_ERR_NUMERIC, "height out of float range");
            if (++p->total_points > TN_SKETCH_MAX_POINTS)
                return tn__tns_err(p, TN_ERR_TOO_LARGE, "more than %d points", TN_SKETCH_MAX_POINTS);
            if ((st = tn__pts_push(&p->pts, (float)x, (float)y, (float)h))) return st;
            /* refused as it passes, before the rest of a huge file is read */
            p->strokes += p->pts.n == 1 ? 1 : tn__stroke_pixels(p->pts.p + 3 * p->pts.n - 6, p->pts.p + 3 * p->pts.n - 3);
            if (p->strokes > tn__stroke_limit(p->set.width, p->set.height))
                return tn__tns_err(p, TN_ERR_TOO_LARGE, "the polylines drawn pixel by pixel pass the limit of %llu pixels for a %d x %d "
                                   "canvas (%d per canvas pixel + 4096, at most %d) at point %ld",
                                   (unsigned long long)tn__stroke_limit(p->set.width, p->set.height), p->set.width, p->set.height,
                                   TN_SKETCH_MAX_COVER, TN_SKETCH_MAX_POINTS, p->total_points);
        }
    }
    if (state == 0) return tn__fail(TN_ERR_FORMAT, "%s: empty file, not a terrainnet sketch", p->name);
    if (state == 2) return tn__tns_err(p, TN_ERR_CORRUPT, "end of file inside the polyline opened at line %d (missing 'end')", open_line);
    if (!p->set.width) return tn__tns_err(p, TN_ERR_CORRUPT, "no 'canvas WIDTH HEIGHT' line");
    return TN_OK;
}

TN_API tn_status tn_sketch_parse(tn_contour_set *out, const char *text, size_t n, const char *name)
{
    tn__tns_parser p;
    char *buf;
    tn_status st;
    TN_ASSERT(out);
    memset(&p, 0, sizeof p);
    p.name = name && name[0] ? name : "sketch";
    if (!text && n) return tn__fail(TN_ERR_INVALID_ARG, "%s: NULL text", p.name);
    if (n && memchr(text, 0, n)) return tn__fail(TN_ERR_FORMAT, "%s: binary data, not a terrainnet sketch", p.name);
    buf = (char *)tn__alloc(n + 1);
    if (!buf) return TN_ERR_OUT_OF_MEMORY;
    if (n) memcpy(buf, text, n);
    buf[n] = 0;
    st = tn__tns_parse_lines(&p, buf);
    TN_FREE(buf);
    TN_FREE(p.pts.p);
    if (st) {
        tn_contour_set_free(&p.set);
        return st;
    }
    *out = p.set;
    return TN_OK;
}

/* Appends the numbers in the locale-free shortest text that reads back as the same float,
   separated by spaces (so load(save(s)) == s), then `tail`. */
static tn_status tn__tns_put_numbers(void **buf, size_t *len, size_t *cap, const float *v, int n, const char *tail)
{
    char num[48];
    int i, k;
    tn_status st = TN_OK;
    for (i = 0; !st && i < n; i++) {
        k = tn__io_format_number(num + 1, sizeof num - 1, (double)v[i], 1);
        num[0] = ' ';
        st = i ? tn__io_append(buf, len, cap, num, (size_t)k + 1) : tn__io_append(buf, len, cap, num + 1, (size_t)k);
    }
    return st ? st : tn__io_append(buf, len, cap, tail, strlen(tail));
}

TN_API tn_status tn_sketch_format(char **text, size_t *size, const tn_contour_set *set)
{
    char line[96];
    void *buf = NULL;
    size_t len = 0, cap = 0;
    int i, j, k;
    tn_status st;
    TN_ASSERT(text && size);
    *text = NULL;
    *size = 0;
    if ((st = tn__cset_check(set, "sketch"))) return st;
    for (i = 0; i < set->count; i++) { /* write only what tn_sketch_parse reads back */
        const tn_contour *c = &set->items[i];
        if (c->order < 0 || c->order > 1000) return tn__fail(TN_ERR_INVALID_ARG, "sketch: polyline %d has order %d (0-1000)", i, c->order);
        for (j = 0; j < c->npoints; j++) {
            float x = c->points[3 * j], y = c->points[3 * j + 1];
            if (x < -0.5f || y < -0.5f || x > set->width - 0.5f || y > set->height - 0.5f)
                return tn__fail(TN_ERR_INVALID_ARG, "sketch: polyline %d point %d (%g, %g) lies outside the %d x %d canvas", i, j,
                                (double)x, (double)y, set->width, set->height);
        }
    }
    k = snprintf(line, sizeof line, "terrainnet-sketch 1\n# %d polylines; points are x y height\ncanvas %d %d\n", set->count,
                 set->width, set->height);
    st = tn__io_append(&buf, &len, &cap, line, (size_t)k);
    for (i = 0; !st && i < set->count; i++) {
        const tn_contour *c = &set->items[i];
        k = snprintf(line, sizeof line, c->order ? "%s order %d" : "%s", c->type == TN_RIDGE ? "ridge" : "valley", c->order);
        st = tn__io_append(&buf, &len, &cap, line, (size_t)k);
        if (!st && c->mean_gradient != 0.0f) {
            st = tn__io_append(&buf, &len, &cap, " gradient ", 10);
            if (!st) st = tn__tns_put_numbers(&buf, &len, &cap, &c->mean_gradient, 1, "\n");
        } else if (!st) st = tn__io_append(&buf, &len, &cap, "\n", 1);
        for (j = 0; !st && j < c->npoints; j++) st = tn__tns_put_numbers(&buf, &len, &cap, c->points + 3 * j, 3, "\n");
        if (!st) st = tn__io_append(&buf, &len, &cap, "end\n", 4);
    }
    if (!st && !(st = tn__io_append(&buf, &len, &cap, "", 1))) len--; /* NUL-terminated: text is a C string */
    if (st) {
        TN_FREE(buf);
        return st;
    }
    *text = (char *)buf;
    *size = len;
    return TN_OK;
}

TN_API tn_status tn_sketch_save(const char *path, const tn_contour_set *set)
{
    char *text = NULL;
    size_t n = 0;
    tn_status st;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "sketch save: empty path");
    if ((st = tn_sketch_format(&text, &n, set))) return tn__fail_context(st, path);
    st = tn__io_write_atomic(path, (const uint8_t *)text, n);
    TN_FREE(text);
    return st;
}

TN_API tn_status tn_sketch_load(tn_contour_set *out, const char *path)
{
    static const char magic[] = "terrainnet-sketch";
    uint8_t *buf = NULL;
    size_t n = 0, plen;
    tn_image img = {0, 0, 0, NULL};
    tn_status st;
    TN_ASSERT(out);
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "sketch load: empty path");
    if ((st = tn__io_read_file(path, &buf, &n))) return st;
    plen = strlen(path);
    if ((n >= sizeof magic - 1 && !memcmp(buf, magic, sizeof magic - 1)) || (plen > 4 && !strcmp(path + plen - 4, ".tns"))) {
        st = tn_sketch_parse(out, (const char *)buf, n, path);
        TN_FREE(buf);
        return st;
    }
    st = tn_image_load_memory(&img, buf, n, path, NULL, NULL);
    TN_FREE(buf);
    if (st) return st;
    st = tn_sketch_from_image(out, &img);
    tn_image_free(&img);
    return st ? tn__fail_context(st, path) : TN_OK;
}

/* ---- sketches drawn as images ---- */


/* The 8 neighbours of (x, y) clockwise from north, P2..P9 in the thinning papers' naming; 0 outside. */
TN__INTERNAL void tn__nbrs(const uint8_t *m, int w, int h, int x, int y, int p[8])
{
    static const int ox[8] = {0, 1, 1, 1, 0, -1, -1, -1}, oy[8] = {-1, -1, 0, 1, 1, 1, 0, -1};
    int k;
    for (k = 0; k < 8; k++) {
        int xx = x + ox[k], yy = y + oy[k];
        p[k] = (xx >= 0 && yy >= 0 && xx < w && yy < h && m[(size_t)yy * w + xx]) ? 1 : 0;
    }
}

/* Removing a set pixel keeps the 8-connected topology iff exactly one of the four "north, east,
   south, west" corners starts a run of foreground (Yokoi's 8-connectivity number == 1). */
TN__INTERNAL int tn__yokoi8(const int p[8])
{
    int k, c = 0;
    for (k = 0; k < 8; k += 2) {
        int a = !p[k], b = !p[(k + 1) & 7], d = !p[(k + 2) & 7];
        c += a - a * b * d;
    }
    return c;
}

/* Guo-Hall sub-iteration test of the set pixel i (pass 0 or 1) on the current mask. */
static int tn__guohall_deletes(const uint8_t *m, int w, int h, size_t i, int pass)
{
    int p[8], p2, p3, p4, p5, p6, p7, p8, p9, cc, n1, n2;
    tn__nbrs(m, w, h, (int)(i % (size_t)w), (int)(i / (size_t)w), p);
    p2 = p[0]; p3 = p[1]; p4 = p[2]; p5 = p[3]; p6 = p[4]; p7 = p[5]; p8 = p[6]; p9 = p[7];
    cc = (!p2 && (p3 || p4)) + (!p4 && (p5 || p6)) + (!p6 && (p7 || p8)) + (!p8 && (p9 || p2));
    if (cc != 1) return 0;
    n1 = (p9 || p2) + (p3 || p4) + (p5 || p6) + (p7 || p8);
    n2 = (p2 || p3) + (p4 || p5) + (p6 || p7) + (p8 || p9);
    if (n2 < n1) n1 = n2;
    if (n1 < 2 || n1 > 3) return 0;
    return !(pass == 0 ? ((p6 || p7 || !p9) && p8) : ((p2 || p3 || !p5) && p4));
}

/* Simple (Yokoi number 1) and not an endpoint: the second stage removes it. */
static int tn__skel_removable(const uint8_t *m, int w, int h, size_t i)
{
    int p[8], b = 0, k;
    tn__nbrs(m, w, h, (int)(i % (size_t)w), (int)(i / (size_t)w), p);
    for (k = 0; k < 8; k++) b += p[k];
    return b >= 2 && tn__yokoi8(p) == 1;
}

/* Work lists of pixel indices for tn_skeletonize (the heap one kept in min-heap order). */
typedef struct tn__skel_list { size_t *v; size_t n, cap; } tn__skel_list;

static tn_status tn__skel_grow(tn__skel_list *l)
{
    size_t cap = l->cap * sizeof(size_t);
    tn_status st;
    if (l->n < l->cap) return TN_OK;
    if ((st = tn__reserve((void **)&l->v, &cap, (l->n + 1) * sizeof(size_t)))) return st;
    l->cap = cap / sizeof(size_t);
    return TN_OK;
}

/* Appends i unless flag[i] has `bit` (then it is queued already). */
static tn_status tn__skel_push(tn__skel_list *l, uint8_t *flag, size_t i, uint8_t bit)
{
    tn_status st;
    if (flag[i] & bit) return TN_OK;
    if ((st = tn__skel_grow(l))) return st;
    flag[i] |= bit;
    l->v[l->n++] = i;
    return TN_OK;
}

static tn_status tn__skel_heap_push(tn__skel_list *hp, uint8_t *flag, size_t i, uint8_t bit)
{
    size_t k;
    tn_status st;
    if (flag[i] & bit) return TN_OK;
    if ((st = tn__skel_grow(hp))) return st;
    flag[i] |= bit;
    for (k = hp->n++; k && hp->v[(k - 1) / 2] > i; k = (k - 1) / 2) hp->v[k] = hp->v[(k - 1) / 2];
    hp->v[k] = i;
    return TN_OK;
}

static size_t tn__skel_heap_pop(tn__skel_list *hp)
{
    size_t top = hp->v[0], last = hp->v[--hp->n], k = 0, c;
    for (; (c = 2 * k + 1) < hp->n; k = c) {
        if (c + 1 < hp->n && hp->v[c + 1] < hp->v[c]) c++;
        if (hp->v[c] >= last) break;
        hp->v[k] = hp->v[c];
    }
    if (hp->n) hp->v[k] = last;
    return top;
}

/* Guo-Hall thinning (a Zhang-Suen variant that, unlike plain Zhang-Suen, keeps two-pixel-thick
   diagonal strokes, so thin drawn lines survive), then every remaining simple pixel that is not
   an endpoint is dropped sequentially, which removes the staircase corners two pixels thick and
   keeps the topology one pixel at a time. Pixels outside the mask count as background.
   Rescanning the whole mask until nothing changes costs O(n) per round, with as many rounds as
   strokes are thick: superlinear on blobs. A pixel's test reads only its 3x3 neighbourhood, so
   after one full scan per stage only the neighbours of deleted pixels are tested again:
   - stage 1 (parallel sub-iterations, pass 0 / 1): per pass a list of pixels whose
     neighbourhood changed since that pass last tested them; a pass's deletions apply together;
   - stage 2 (sequential raster sweeps): a deletion queues the neighbours after it into the
     current sweep (a min-heap keeps raster order) and those before it into the next sweep.
   Every skipped test would have answered as before, so the output is bit-identical to the
   rescans; the work is O(n) plus O(log) per re-test, and re-tests are at most 8 per deletion. */
TN_API tn_status tn_skeletonize(uint8_t *m, int w, int h)
{
    static const int ox[8] = {0, 1, 1, 1, 0, -1, -1, -1}, oy[8] = {-1, -1, 0, 1, 1, 1, 0, -1};
    enum { IN_PASS0 = 1, IN_PASS1 = 2, IN_NOW = 4, IN_NEXT = 8 };
    tn__skel_list q[2] = {{NULL, 0, 0}, {NULL, 0, 0}}, del = {NULL, 0, 0}, heap = {NULL, 0, 0};
    uint8_t *flag;
    size_t n, i, k, cnt;
    int pass, d, full[2] = {1, 1}, idle = 0, sweep;
    tn_status st = TN_OK;
    if (!m || w <= 0 || h <= 0) return tn__fail(TN_ERR_INVALID_ARG, "skeletonize: empty mask");
    n = (size_t)w * h;
    if (!(flag = (uint8_t *)tn__calloc(n))) return TN_ERR_OUT_OF_MEMORY;
    for (i = 0; i < n; i++) m[i] = m[i] != 0;
    /* stage 1: passes alternate until two in a row delete nothing (= a whole idle round) */
    for (pass = 0; !st && idle < 2; pass ^= 1) {
        uint8_t bit = (uint8_t)(pass ? IN_PASS1 : IN_PASS0);
        cnt = full[pass] ? n : q[pass].n;
        del.n = 0;
        for (k = 0; !st && k < cnt; k++) {
            i = full[pass] ? k : q[pass].v[k];
            flag[i] &= (uint8_t)~bit;
            if (m[i] && tn__guohall_deletes(m, w, h, i, pass)) {
                if ((st = tn__skel_grow(&del))) break;
                del.v[del.n++] = i;
            }
        }
        q[pass].n = 0;
        full[pass] = 0;
        for (k = 0; k < del.n; k++) m[del.v[k]] = 0;
        for (k = 0; !st && k < del.n; k++) {
            int x = (int)(del.v[k] % (size_t)w), y = (int)(del.v[k] / (size_t)w);
            for (d = 0; !st && d < 8; d++) {
                int xx = x + ox[d], yy = y + oy[d];
                size_t j = (size_t)yy * w + xx;
                if (xx < 0 || yy < 0 || xx >= w || yy >= h || !m[j]) continue;
                if (!(st = tn__skel_push(&q[0], flag, j, IN_PASS0))) st = tn__skel_push(&q[1], flag, j, IN_PASS1);
            }
        }
        idle = del.n ? 0 : idle + 1;
    }
    /* stage 2: sweep 0 scans everything; later sweeps test the queued pixels in raster order */
    del.n = 0; /* the next sweep's pixels */
    for (sweep = 0; !st && (sweep == 0 || del.n); sweep++) {
        for (k = 0; !st && k < del.n; k++) {
            flag[del.v[k]] &= (uint8_t)~IN_NEXT;
            st = tn__skel_heap_push(&heap, flag, del.v[k], IN_NOW);
        }
        del.n = 0;
        for (k = 0; !st && (sweep == 0 ? k < n : heap.n > 0); k++) {
            int x, y;
            if (sweep == 0) i = k;
            else {
                i = tn__skel_heap_pop(&heap);
                flag[i] &= (uint8_t)~IN_NOW;
            }
            if (!m[i] || !tn__skel_removable(m, w, h, i)) continue;
            m[i] = 0;
            x = (int)(i % (size_t)w);
            y = (int)(i / (size_t)w);
            for (d = 0; !st && d < 8; d++) {
                int xx = x + ox[d], yy = y + oy[d];
                size_t j = (size_t)yy * w + xx;
                if (xx < 0 || yy < 0 || xx >= w || yy >= h || !m[j]) continue;
                if (j < i) st = tn__skel_push(&del, flag, j, IN_NEXT);
                else if (sweep > 0) st = tn__skel_heap_push(&heap, flag, j, IN_NOW); /* sweep 0 gets there anyway */
            }
        }
    }
    TN_FREE(flag);
    TN_FREE(q[0].v);
    TN_FREE(q[1].v);
    TN_FREE(del.v);
    TN_FREE(heap.v);
    return st;
}

/* D8 neighbour offsets: E, SE, S, SW, W, NW, N, NE (flow directions in >>extract too). */
TN__INTERNAL const int tn__d8x[8] = {1, 1, 0, -1, -1, -1, 0, 1};
TN__INTERNAL const int tn__d8y[8] = {0, 1, 1, 1, 0, -1, -1, -1};

/* Number of set 8-neighbours. */
static int tn__skel_degree(const uint8_t *m, int w, int h, int x, int y)
{
    int p[8], k, b = 0;
    tn__nbrs(m, w, h, x, y, p);
    for (k = 0; k < 8; k++) b += p[k];
    return b;
}

/* Traces the skeleton into polylines between nodes (endpoints, junctions: degree != 2) and
   closed loops. Each polyline's pixels are listed as cell indices in *cells (per line offsets in
   *starts, count + 1 entries). Deterministic raster order. */
typedef struct tn__trace {
    size_t *cells, *starts;
    size_t ncells, nlines, cap_c, cap_s; /* caps in bytes (tn__reserve) */
} tn__trace;

static tn_status tn__trace_push(tn__trace *t, size_t cell)
{
    tn_status st = tn__reserve((void **)&t->cells, &t->cap_c, (t->ncells + 1) * sizeof(size_t));
    if (st) return st;
    t->cells[t->ncells++] = cell;
    return TN_OK;
}

static tn_status tn__trace_end_line(tn__trace *t)
{
    tn_status st = tn__reserve((void **)&t->starts, &t->cap_s, (t->nlines + 2) * sizeof(size_t));
    if (st) return st;
    if (t->nlines == 0) t->starts[0] = 0;
    t->starts[++t->nlines] = t->ncells;
    return TN_OK;
}

static void tn__trace_free(tn__trace *t)
{
    TN_FREE(t->cells);
    TN_FREE(t->starts);
    memset(t, 0, sizeof *t);
}

static tn_status tn__trace_skeleton(const uint8_t *m, int w, int h, tn__trace *t)
{
    const int *ox = tn__d8x, *oy = tn__d8y;
    size_t n = (size_t)w * h, i;
    uint8_t *deg = (uint8_t *)tn__alloc(n), *vis = (uint8_t *)tn__calloc(n);
    tn_status st = TN_OK;
    int pass;
    memset(t, 0, sizeof *t);
    if (!deg || !vis) {
        TN_FREE(deg);
        TN_FREE(vis);
        return TN_ERR_OUT_OF_MEMORY;
    }
    for (i = 0; i < n; i++) deg[i] = m[i] ? (uint8_t)tn__skel_degree(m, w, h, (int)(i % (size_t)w), (int)(i / (size_t)w)) : 0;
    /* pass 0: lines leaving nodes; pass 1: closed loops of degree-2 pixels left over */
    for (pass = 0; pass < 2 && !st; pass++)
        for (i = 0; i < n && !st; i++) {
            int x = (int)(i % (size_t)w), y = (int)(i / (size_t)w), d;
            if (!m[i]) continue;
            if (pass == 0 && deg[i] == 2) continue;
            if (pass == 1 && vis[i]) continue;
            if (pass == 0 && deg[i] == 0) { /* isolated pixel: a one-point line */
                vis[i] = 1;
                if (!(st = tn__trace_push(t, i))) st = tn__trace_end_line(t);
                continue;
            }
            for (d = 0; d < 8 && !st; d++) {
                int nx = x + ox[d], ny = y + oy[d];
                size_t q, prev = i, cur;
                if (nx < 0 || ny < 0 || nx >= w || ny >= h) continue;
                q = (size_t)ny * w + nx;
                if (!m[q]) continue;
                if (pass == 1 && d > 0 && vis[q]) continue;
                if (deg[q] != 2) { /* node next to node: a two-point line, listed once */
                    if (pass == 0 && q > i) {
                        if (!(st = tn__trace_push(t, i)) && !(st = tn__trace_push(t, q))) st = tn__trace_end_line(t);
                    }
                    continue;
                }
                if (vis[q]) continue;
                vis[i] = 1;
                if ((st = tn__trace_push(t, i))) break;
                cur = q;
                for (;;) {
                    int cx = (int)(cur % (size_t)w), cy = (int)(cur / (size_t)w), e;
                    size_t next = (size_t)-1;
                    if ((st = tn__trace_push(t, cur))) break;
                    if (deg[cur] != 2 || (pass == 1 && cur == i)) break;
                    vis[cur] = 1;
                    for (e = 0; e < 8; e++) {
                        int ex = cx + ox[e], ey = cy + oy[e];
                        size_t r;
                        if (ex < 0 || ey < 0 || ex >= w || ey >= h) continue;
                        r = (size_t)ey * w + ex;
                        if (!m[r] || r == prev) continue;
                        if (r == i && pass == 1 && prev != i) { next = r; break; }
                        if (deg[r] == 2 && vis[r]) continue;
                        next = r;
                        break;
                    }
                    if (next == (size_t)-1) break;
                    prev = cur;
                    cur = next;
                }
                if (!st) st = tn__trace_end_line(t);
                if (pass == 1) break; /* one loop per start pixel */
            }
        }
    TN_FREE(deg);
    TN_FREE(vis);
    if (st) tn__trace_free(t);
    return st;
}

TN_API tn_status tn_sketch_from_image(tn_contour_set *out, const tn_image *img)
{
    tn_contour_set set;
    size_t cap = 0, n, i, bytes;
    uint8_t *mask = NULL;
    float *hgt = NULL;
    int type, strokes = 0;
    tn_status st = TN_OK;
    TN_ASSERT(out);
    if (!img || !img->data || img->width <= 0 || img->height <= 0) return tn__fail(TN_ERR_EMPTY, "sketch image: empty image");
    if (img->channels < 3)
        return tn__fail(TN_ERR_SHAPE, "sketch image: needs colour (red ridges, blue valleys), got %d channel(s)", img->channels);
    if (img->width > TN_SKETCH_MAX_SIDE || img->height > TN_SKETCH_MAX_SIDE)
        return tn__fail(TN_ERR_TOO_LARGE, "sketch image: %d x %d exceeds the canvas limit", img->width, img->height);
    /* an Inf channel passes the stroke test and would become an Inf height */
    if ((n = tn_image_range(NULL, NULL, img)) != 0)
        return tn__fail(TN_ERR_NUMERIC, "sketch image: %zu NaN/Inf samples", n);
    n = (size_t)img->width * img->height;
    if (tn__size4(n, 1, sizeof(float), 1, &bytes)) return TN_ERR_TOO_LARGE;
    memset(&set, 0, sizeof set);
    set.width = img->width;
    set.height = img->height;
    mask = (uint8_t *)tn__alloc(n);
    hgt = (float *)tn__alloc(bytes);
    if (!mask || !hgt) st = TN_ERR_OUT_OF_MEMORY;
    for (type = 0; !st && type < 2; type++) {
        tn__trace t;
        tn__pts pts = {NULL, 0, 0};
        size_t l, k;
        for (i = 0; i < n; i++) {
            const float *p = img->data + i * (size_t)img->channels;
            float r = p[0], g = p[1], b = p[2], v = r > b ? r : b;
            int on = v >= 0.1f && v - g >= 0.5f * v && fabsf(r - b) >= 0.5f * v && ((r > b) == (type == TN_RIDGE));
            mask[i] = (uint8_t)on;
            hgt[i] = on ? v : 0.0f;
            strokes += on;
        }
        if ((st = tn_skeletonize(mask, img->width, img->height))) break;
        if ((st = tn__trace_skeleton(mask, img->width, img->height, &t))) break;
        for (l = 0; !st && l < t.nlines; l++) { /* chains of 3+ pixels become polylines */
            if (t.starts[l + 1] - t.starts[l] < 3) continue;
            pts.n = 0;
            for (k = t.starts[l]; !st && k < t.starts[l + 1]; k++) {
                size_t c = t.cells[k];
                st = tn__pts_push(&pts, (float)(c % (size_t)img->width), (float)(c / (size_t)img->width), hgt[c]);
            }
            if (!st) st = tn__cset_add(&set, &cap, (tn_contour_type)type, 0, 0.0f, pts.p, pts.n);
        }
        TN_FREE(pts.p);
        tn__trace_free(&t);
    }
    TN_FREE(mask);
    TN_FREE(hgt);
    if (!st && !strokes) st = tn__fail(TN_ERR_EMPTY, "sketch image: no red (ridge) or blue (valley) strokes");
    if (!st && !set.count) st = tn__fail(TN_ERR_EMPTY, "sketch image: strokes too small to trace (need 3+ pixels)");
    if (st) {
        tn_contour_set_free(&set);
        return st;
    }
    *out = set;
    return TN_OK;
}

/* ---- densify, rasterise, preview ---- */

TN_API tn_status tn_sketch_densify(tn_contour_set *out, const tn_contour_set *in)
{
    tn_contour_set set;
    tn__pts pts = {NULL, 0, 0};
    size_t cap = 0;
    int i;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__cset_check(in, "densify"))) return st;
    memset(&set, 0, sizeof set);
    set.width = in->width;
    set.height = in->height;
    for (i = 0; !st && i < in->count; i++) {
        const tn_contour *c = &in->items[i];
        pts.n = 0;
        if (!(st = tn__chain_pixels(c->points, c->npoints, 1.0f, 1.0f, &pts)))
            st = tn__cset_add(&set, &cap, c->type, c->order, c->mean_gradient, pts.p, pts.n);
    }
    TN_FREE(pts.p);
    if (st) {
        tn_contour_set_free(&set);
        return st;
    }
    *out = set;
    return TN_OK;
}

TN_API tn_status tn_sketch_rasterise(tn_image *out, const tn_contour_set *set, int width, int height)
{
    tn_image r = {0, 0, 0, NULL};
    tn__pts pts = {NULL, 0, 0};
    int i, j;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn__cset_check(set, "rasterise"))) return st;
    if (width <= 0 || height <= 0) return tn__fail(TN_ERR_INVALID_ARG, "rasterise: size %d x %d", width, height);
    if ((st = tn_image_create(&r, width, height, 3))) return st;
    for (i = 0; !st && i < set->count; i++) {
        const tn_contour *c = &set->items[i];
        pts.n = 0;
        st = tn__chain_pixels(c->points, c->npoints, (float)width / (float)set->width, (float)height / (float)set->height, &pts);
        for (j = 0; !st && j < pts.n; j++) {
            int x = (int)pts.p[3 * j], y = (int)pts.p[3 * j + 1];
            float *px;
            if (x < 0 || y < 0 || x >= width || y >= height) continue;
            px = &TN_PIXEL(&r, x, y, 0);
            px[0] = c->type == TN_RIDGE ? 1.0f : 0.0f;
            px[1] = c->type == TN_RIDGE ? 0.0f : 1.0f;
            px[2] = pts.p[3 * j + 2];
        }
    }
    TN_FREE(pts.p);
    if (st) {
        tn_image_free(&r);
        return st;
    }
    *out = r;
    return TN_OK;
}

TN_API tn_status tn_sketch_preview(tn_image *out, const tn_contour_set *set, const tn_image *dem, int width, int height)
{
    tn_image lines = {0, 0, 0, NULL}, rgb = {0, 0, 0, NULL}, small = {0, 0, 0, NULL}, shade = {0, 0, 0, NULL};
    int x, y, u, v, rad = width > height ? width / 512 : height / 512;
    size_t i, n;
    tn_status st;
    TN_ASSERT(out);
    if ((st = tn_sketch_rasterise(&lines, set, width, height))) return st;
    if ((st = tn_image_create(&rgb, width, height, 3))) goto fail;
    n = (size_t)width * height;
    if (dem && dem->data) {
        if ((st = tn_image_resize(&small, dem, width, height, TN_RESIZE_BILINEAR)) || (st = tn_image_hillshade(&shade, &small, NULL)))
            goto fail;
        for (i = 0; i < n; i++) rgb.data[3 * i] = rgb.data[3 * i + 1] = rgb.data[3 * i + 2] = 0.15f + 0.7f * shade.data[i];
    } else
        for (i = 0; i < 3 * n; i++) rgb.data[i] = 0.35f;
    for (y = 0; y < height; y++)
        for (x = 0; x < width; x++) {
            const float *l = &TN_PIXEL(&lines, x, y, 0);
            if (l[0] == 0.0f && l[1] == 0.0f) continue;
            for (v = y - rad; v <= y + rad; v++)
                for (u = x - rad; u <= x + rad; u++) {
                    float *p;
                    if (u < 0 || v < 0 || u >= width || v >= height) continue;
                    p = &TN_PIXEL(&rgb, u, v, 0);
                    if (l[0] != 0.0f) { p[0] = 1.0f; p[1] = 0.9f; p[2] = 0.0f; }            /* ridge: yellow */
                    else if (p[2] != 0.0f || p[0] != 1.0f) { p[0] = 0.1f; p[1] = 0.35f; p[2] = 1.0f; } /* valley: blue */
                }
        }
    tn_image_free(&lines);
    tn_image_free(&small);
    tn_image_free(&shade);
    *out = rgb;
    return TN_OK;
fail:
    tn_image_free(&lines);
    tn_image_free(&rgb);
    tn_image_free(&small);
    tn_image_free(&shade);
    return st;
}

/* ---- Delaunay triangulation and minimum spanning tree ---- */

typedef struct tn__tri { int v[3]; double cx, cy, r2; } tn__tri;

/* Circumcircle of triangle (a, b, c); a degenerate (collinear) one gets an infinite circle so the
   next insertion replaces it. */
static void tn__circumcircle(tn__tri *t, const double *p)
{
    double ax = p[2 * t->v[0]], ay = p[2 * t->v[0] + 1], bx = p[2 * t->v[1]] - ax, by = p[2 * t->v[1] + 1] - ay;
    double cx = p[2 * t->v[2]] - ax, cy = p[2 * t->v[2] + 1] - ay, d = 2.0 * (bx * cy - by * cx);
    double b2 = bx * bx + by * by, c2 = cx * cx + cy * cy, ux, uy;
    if (fabs(d) < 1e-12 * (b2 + c2)) {
        t->cx = ax;
        t->cy = ay;
        t->r2 = HUGE_VAL;
        return;
    }
    ux = (cy * b2 - by * c2) / d;
    uy = (bx * c2 - cx * b2) / d;
    t->cx = ax + ux;
    t->cy = ay + uy;
    t->r2 = ux * ux + uy * uy;
}

TN_API tn_status tn_delaunay(int **triangles, int *ntriangles, const float *xy, int n)
{
    double *p = NULL, lo_x, lo_y, hi_x, hi_y, span;
    tn__tri *tri = NULL;
    int *bad = NULL, *edges = NULL, *res = NULL;
    size_t tri_cap = 0, bad_cap = 0, edge_cap = 0;
    int ntri = 0, i, j, k, nbad, nedge, nres = 0;
    tn_status st = TN_OK;
    TN_ASSERT(triangles && ntriangles);
    *triangles = NULL;
    *ntriangles = 0;
    if (n < 0 || n > (1 << 24) || (n > 0 && !xy)) return tn__fail(TN_ERR_INVALID_ARG, "delaunay: %d points", n);
    if (!(p = (double *)tn__alloc(((size_t)n + 3) * 2 * sizeof(double)))) return TN_ERR_OUT_OF_MEMORY;
    lo_x = lo_y = 0.0;
    hi_x = hi_y = 1.0;
    for (i = 0; i < n; i++) {
        if (!isfinite(xy[2 * i]) || !isfinite(xy[2 * i + 1])) {
            TN_FREE(p);
            return tn__fail(TN_ERR_NUMERIC, "delaunay: point %d is NaN/Inf", i);
        }
        p[2 * i] = xy[2 * i];
        p[2 * i + 1] = xy[2 * i + 1];
        if (i == 0 || p[2 * i] < lo_x) lo_x = p[2 * i];
        if (i == 0 || p[2 * i] > hi_x) hi_x = p[2 * i];
        if (i == 0 || p[2 * i + 1] < lo_y) lo_y = p[2 * i + 1];
        if (i == 0 || p[2 * i + 1] > hi_y) hi_y = p[2 * i + 1];
    }
    /* super triangle far around the points; removed at the end */
    span = fmax(fmax(hi_x - lo_x, hi_y - lo_y), 1.0) * 64.0;
    p[2 * n] = 0.5 * (lo_x + hi_x) - 2.0 * span;
    p[2 * n + 1] = lo_y - span;
    p[2 * n + 2] = 0.5 * (lo_x + hi_x) + 2.0 * span;
    p[2 * n + 3] = lo_y - span;
    p[2 * n + 4] = 0.5 * (lo_x + hi_x);
    p[2 * n + 5] = hi_y + 2.0 * span;
    if ((st = tn__reserve((void **)&tri, &tri_cap, sizeof(tn__tri)))) goto done;
    tri[0].v[0] = n;
    tri[0].v[1] = n + 1;
    tri[0].v[2] = n + 2;
    tn__circumcircle(&tri[0], p);
    ntri = 1;
    for (i = 0; i < n; i++) {
        double x = p[2 * i], y = p[2 * i + 1];
        int dup = 0;
        for (nbad = 0, j = 0; j < ntri; j++) {
            double dx = x - tri[j].cx, dy = y - tri[j].cy;
            if (dx * dx + dy * dy >= tri[j].r2) continue;
            if ((st = tn__reserve((void **)&bad, &bad_cap, ((size_t)nbad + 1) * sizeof(int)))) goto done;
            bad[nbad++] = j;
            for (k = 0; k < 3; k++) dup |= p[2 * tri[j].v[k]] == x && p[2 * tri[j].v[k] + 1] == y;
        }
        if (dup || !nbad) continue; /* exact duplicate of a vertex */
        /* the cavity boundary: edges of bad triangles not shared by two of them */
        for (nedge = 0, j = 0; j < nbad; j++)
            for (k = 0; k < 3; k++) {
                int a = tri[bad[j]].v[k], b = tri[bad[j]].v[(k + 1) % 3], e, shared = 0;
                for (e = 0; e < nbad && !shared; e++) {
                    const int *w = tri[bad[e]].v;
                    if (e == j) continue;
                    shared = (w[0] == b && w[1] == a) || (w[1] == b && w[2] == a) || (w[2] == b && w[0] == a) ||
                             (w[0] == a && w[1] == b) || (w[1] == a && w[2] == b) || (w[2] == a && w[0] == b);
                }
                if (shared) continue;
                if ((st = tn__reserve((void **)&edges, &edge_cap, ((size_t)nedge + 1) * 2 * sizeof(int)))) goto done;
                edges[2 * nedge] = a;
                edges[2 * nedge + 1] = b;
                nedge++;
            }
        /* remove bad triangles (highest index first, swap with the last), add the fan */
        for (j = nbad - 1; j >= 0; j--) tri[bad[j]] = tri[--ntri];
        if ((st = tn__reserve((void **)&tri, &tri_cap, ((size_t)ntri + nedge) * sizeof(tn__tri)))) goto done;
        for (j = 0; j < nedge; j++) {
            tri[ntri].v[0] = edges[2 * j];
            tri[ntri].v[1] = edges[2 * j + 1];
            tri[ntri].v[2] = i;
            tn__circumcircle(&tri[ntri], p);
            ntri++;
        }
    }
    if (!(res = (int *)tn__alloc(((size_t)ntri + 1) * 3 * sizeof(int)))) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    for (j = 0; j < ntri; j++) {
        if (tri[j].v[0] >= n || tri[j].v[1] >= n || tri[j].v[2] >= n) continue;
        res[3 * nres] = tri[j].v[0];
        res[3 * nres + 1] = tri[j].v[1];
        res[3 * nres + 2] = tri[j].v[2];
        nres++;
    }
done:
    TN_FREE(p);
    TN_FREE(tri);
    TN_FREE(bad);
    TN_FREE(edges);
    if (st) {
        TN_FREE(res);
        return st;
    }
    *triangles = res;
    *ntriangles = nres;
    return TN_OK;
}

TN_API tn_status tn_mst(int **edges, const float *xy, int n)
{
    double *best;
    int *from, *e, i, j, k;
    uint8_t *in;
    TN_ASSERT(edges);
    *edges = NULL;
    if (n < 1 || n > (1 << 24) || !xy) return tn__fail(TN_ERR_INVALID_ARG, "mst: %d points", n);
    for (i = 0; i < 2 * n; i++) /* NaN distances never compare smaller: no vertex would be picked */
        if (!isfinite(xy[i])) return tn__fail(TN_ERR_NUMERIC, "mst: point %d is NaN/Inf", i / 2);
    best = (double *)tn__alloc((size_t)n * sizeof(double));
    from = (int *)tn__alloc((size_t)n * sizeof(int));
    in = (uint8_t *)tn__calloc((size_t)n);
    e = (int *)tn__alloc((size_t)n * 2 * sizeof(int));
    if (!best || !from || !in || !e) {
        TN_FREE(best); TN_FREE(from); TN_FREE(in); TN_FREE(e);
        return TN_ERR_OUT_OF_MEMORY;
    }
    for (i = 0; i < n; i++) {
        best[i] = HUGE_VAL;
        from[i] = 0;
    }
    k = 0; /* the vertex added last */
    in[0] = 1;
    for (i = 1; i < n; i++) {
        int pick = -1;
        for (j = 0; j < n; j++) {
            double dx, dy, d;
            if (in[j]) continue;
            dx = (double)xy[2 * j] - xy[2 * k];
            dy = (double)xy[2 * j + 1] - xy[2 * k + 1];
            d = dx * dx + dy * dy;
            if (d < best[j]) { best[j] = d; from[j] = k; }
            if (pick < 0 || best[j] < best[pick]) pick = j;
        }
        in[pick] = 1;
        e[2 * (i - 1)] = from[pick];
        e[2 * (i - 1) + 1] = pick;
        k = pick;
    }
    TN_FREE(best);
    TN_FREE(from);
    TN_FREE(in);
    *edges = e;
    return TN_OK;
}

/* ---- random sketches ---- */

/* Pixel occupancy for "does this edge cross anything": an 8-connected chain crosses the marked
   pixels when it steps on one, or steps diagonally between two marked pixels (an X crossing). */
static void tn__occ_mark(uint8_t *occ, int w, int h, const tn__pts *c)
{
    int j;
    for (j = 0; j < c->n; j++) {
        int x = (int)c->p[3 * j], y = (int)c->p[3 * j + 1];
        if (x >= 0 && y >= 0 && x < w && y < h) occ[(size_t)y * w + x] = 1;
    }
}

static int tn__occ_hits(const uint8_t *occ, int w, int h, const tn__pts *c)
{
    int j;
    for (j = 0; j < c->n; j++) {
        int x = (int)c->p[3 * j], y = (int)c->p[3 * j + 1];
        if (x < 0 || y < 0 || x >= w || y >= h) continue;
        if (occ[(size_t)y * w + x]) return 1;
        if (j > 0) {
            int px = (int)c->p[3 * j - 3], py = (int)c->p[3 * j - 2];
            if (px != x && py != y && px >= 0 && py >= 0 && px < w && py < h && occ[(size_t)py * w + x] && occ[(size_t)y * w + px])
                return 1;
        }
    }
    return 0;
}

/* Keeps the edges (pairs into xy) whose pixel chain misses occ; kept[] gets them, *nkept their count. */
static tn_status tn__keep_free_edges(const float *xy, const int *edges, int nedges, const uint8_t *occ, int w, int h, int *kept,
                                     int *nkept, tn__pts *tmp)
{
    int i;
    tn_status st;
    float ends[6] = {0, 0, 0, 0, 0, 0};
    *nkept = 0;
    for (i = 0; i < nedges; i++) {
        int a = edges[2 * i], b = edges[2 * i + 1];
        ends[0] = xy[2 * a]; ends[1] = xy[2 * a + 1]; ends[3] = xy[2 * b]; ends[4] = xy[2 * b + 1];
        tmp->n = 0;
        if ((st = tn__chain_pixels(ends, 2, 1.0f, 1.0f, tmp))) return st;
        if (tn__occ_hits(occ, w, h, tmp)) continue;
        kept[2 * *nkept] = a;
        kept[2 * *nkept + 1] = b;
        (*nkept)++;
    }
    return TN_OK;
}

/* Chains the kept edges of a forest (vertex positions/heights vx, vy, vh) between vertices of
   degree != 2 and appends each chain as an 8-connected pixel polyline of the given type. */
static tn_status tn__add_chains(const float *vx, const float *vh, int nv, const int *edges, int nedges, tn_contour_type type,
                                tn_contour_set *out, size_t *cap)
{
    int *deg = NULL, *adj_start = NULL, *adj = NULL, *fill = NULL, i, k;
    uint8_t *used = NULL;
    tn__pts ctrl = {NULL, 0, 0}, pix = {NULL, 0, 0};
    tn_status st = TN_OK;
    deg = (int *)tn__calloc(((size_t)nv + 1) * sizeof(int));
    adj_start = (int *)tn__calloc(((size_t)nv + 1) * sizeof(int));
    fill = (int *)tn__calloc(((size_t)nv + 1) * sizeof(int));
    adj = (int *)tn__alloc(((size_t)nedges * 2 + 1) * sizeof(int));
    used = (uint8_t *)tn__calloc((size_t)nedges + 1);
    if (!deg || !adj_start || !fill || !adj || !used) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    for (k = 0; k < nedges; k++) { deg[edges[2 * k]]++; deg[edges[2 * k + 1]]++; }
    for (i = 0; i < nv; i++) adj_start[i + 1] = adj_start[i] + deg[i];
    for (k = 0; k < nedges; k++) { /* adjacency holds edge ids */
        adj[adj_start[edges[2 * k]] + fill[edges[2 * k]]++] = k;
        adj[adj_start[edges[2 * k + 1]] + fill[edges[2 * k + 1]]++] = k;
    }
    for (i = 0; i < nv && !st; i++) {
        int a;
        if (deg[i] == 2 || deg[i] == 0) continue;
        for (a = adj_start[i]; a < adj_start[i + 1] && !st; a++) {
            int e = adj[a], v = i;
            if (used[e]) continue;
            ctrl.n = 0;
            st = tn__pts_push(&ctrl, vx[2 * v], vx[2 * v + 1], vh[v]);
            while (!st && e >= 0) {
                int b;
                used[e] = 1;
                v = edges[2 * e] == v ? edges[2 * e + 1] : edges[2 * e];
                st = tn__pts_push(&ctrl, vx[2 * v], vx[2 * v + 1], vh[v]);
                e = -1;
                if (deg[v] != 2) break;
                for (b = adj_start[v]; b < adj_start[v + 1]; b++)
                    if (!used[adj[b]]) e = adj[b];
            }
            pix.n = 0;
            if (!st) st = tn__chain_pixels(ctrl.p, ctrl.n, 1.0f, 1.0f, &pix);
            if (!st && pix.n >= 2) st = tn__cset_add(out, cap, type, 0, 0.0f, pix.p, pix.n);
        }
    }
done:
    TN_FREE(deg);
    TN_FREE(adj_start);
    TN_FREE(fill);
    TN_FREE(adj);
    TN_FREE(used);
    TN_FREE(ctrl.p);
    TN_FREE(pix.p);
    return st;
}

/* The zero rule of tn_sketch_random_opts: one ridge node per 1024 px of the canvas, 8 to 2048. */
static void tn__sketch_random_opts_defaults(tn_sketch_random_opts *o, int width, int height)
{
    if (o->nodes == 0) o->nodes = tn__clampi((int)((double)width * height / 1024.0), 8, 2048);
}

TN_API tn_status tn_sketch_random(tn_contour_set *out, const tn_contour_set *user, int width, int height,
                                  const tn_sketch_random_opts *opts)
{
    tn_sketch_random_opts o;
    tn_contour_set set;
    tn__pts tmp = {NULL, 0, 0};
    tn_rng rng;
    uint8_t *occ = NULL;
    float *node = NULL, *nh = NULL, *vor = NULL, *vh = NULL;
    int *redges = NULL, *vedges = NULL, *tris = NULL, *keep_r = NULL, *keep_v = NULL;
    int n, ntri = 0, nv = 0, nkr = 0, nkv = 0, i, j;
    size_t cap = 0;
    tn_status st = TN_OK;
    TN_ASSERT(out);
    memset(&set, 0, sizeof set);
    if (width < 2 || height < 2) return tn__fail(TN_ERR_INVALID_ARG, "random sketch: canvas %d x %d (need at least 2 x 2)", width, height);
    if (width > TN_SKETCH_MAX_SIDE || height > TN_SKETCH_MAX_SIDE)
        return tn__fail(TN_ERR_TOO_LARGE, "random sketch: canvas %d x %d exceeds %d", width, height, TN_SKETCH_MAX_SIDE);
    if (user && user->count) {
        if ((st = tn__cset_check(user, "random sketch: user sketch"))) return st;
        if (user->width != width || user->height != height)
            return tn__fail(TN_ERR_SHAPE, "random sketch: the user sketch canvas is %d x %d, not %d x %d", user->width,
                            user->height, width, height);
    }
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    if (o.nodes < 0) return tn__fail(TN_ERR_INVALID_ARG, "random sketch: %d nodes", o.nodes);
    tn__sketch_random_opts_defaults(&o, width, height);
    n = o.nodes;
    if (n > 8192) return tn__fail(TN_ERR_TOO_LARGE, "random sketch: %d nodes (at most 8192)", n);
    tn_rng_seed(&rng, o.seed, 0x5e7c4u);
    set.width = width;
    set.height = height;
    node = (float *)tn__alloc((size_t)n * 2 * sizeof(float));
    nh = (float *)tn__alloc((size_t)n * sizeof(float));
    if (!node || !nh) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    for (i = 0; i < n; i++) {
        node[2 * i] = tn_rng_uniform(&rng) * (float)(width - 1);
        node[2 * i + 1] = tn_rng_uniform(&rng) * (float)(height - 1);
        nh[i] = 0.5f + 0.5f * tn_rng_uniform(&rng);
    }
    if ((st = tn_mst(&redges, node, n)) || (st = tn_delaunay(&tris, &ntri, node, n))) goto done;
    /* Voronoi vertices = circumcentres of the Delaunay triangles, kept inside the canvas */
    vor = (float *)tn__alloc(((size_t)ntri + 1) * 2 * sizeof(float));
    vh = (float *)tn__alloc(((size_t)ntri + 1) * sizeof(float));
    if (!vor || !vh) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    for (i = 0; i < ntri; i++) {
        double pts[6];
        tn__tri t;
        for (j = 0; j < 3; j++) {
            pts[2 * j] = node[2 * tris[3 * i + j]];
            pts[2 * j + 1] = node[2 * tris[3 * i + j] + 1];
            t.v[j] = j;
        }
        tn__circumcircle(&t, pts);
        if (!(t.r2 < HUGE_VAL) || t.cx < 0 || t.cy < 0 || t.cx > width - 1 || t.cy > height - 1) continue;
        vor[2 * nv] = (float)t.cx;
        vor[2 * nv + 1] = (float)t.cy;
        vh[nv++] = 0.5f * tn_rng_uniform(&rng);
    }
    if (nv >= 2 && (st = tn_mst(&vedges, vor, nv))) goto done;
    /* user pixels first: ridge edges must miss them; then kept ridges too: valley edges must miss both */
    keep_r = (int *)tn__alloc((size_t)n * 2 * sizeof(int));
    keep_v = (int *)tn__alloc(((size_t)nv + 1) * 2 * sizeof(int));
    occ = (uint8_t *)tn__calloc((size_t)width * height);
    if (!keep_r || !keep_v || !occ) { st = TN_ERR_OUT_OF_MEMORY; goto done; }
    for (i = 0; user && i < user->count && !st; i++) {
        tmp.n = 0;
        if (!(st = tn__chain_pixels(user->items[i].points, user->items[i].npoints, 1.0f, 1.0f, &tmp))) tn__occ_mark(occ, width, height, &tmp);
    }
    if (st || (st = tn__keep_free_edges(node, redges, n - 1, occ, width, height, keep_r, &nkr, &tmp))) goto done;
    for (i = 0; i < nkr && !st; i++) {
        float ends[6] = {0, 0, 0, 0, 0, 0};
        ends[0] = node[2 * keep_r[2 * i]]; ends[1] = node[2 * keep_r[2 * i] + 1];
        ends[3] = node[2 * keep_r[2 * i + 1]]; ends[4] = node[2 * keep_r[2 * i + 1] + 1];
        tmp.n = 0;
        if (!(st = tn__chain_pixels(ends, 2, 1.0f, 1.0f, &tmp))) tn__occ_mark(occ, width, height, &tmp);
    }
    if (st || (nv >= 2 && (st = tn__keep_free_edges(vor, vedges, nv - 1, occ, width, height, keep_v, &nkv, &tmp)))) goto done;
    for (i = 0; user && i < user->count && !st; i++)
        st = tn__cset_add(&set, &cap, user->items[i].type, user->items[i].order, user->items[i].mean_gradient,
                          user->items[i].points, user->items[i].npoints);
    if (!st) st = tn__add_chains(node, nh, n, keep_r, nkr, TN_RIDGE, &set, &cap);
    if (!st) st = tn__add_chains(vor, vh, nv, keep_v, nkv, TN_VALLEY, &set, &cap);
done:
    TN_FREE(node); TN_FREE(nh); TN_FREE(vor); TN_FREE(vh);
    TN_FREE(redges); TN_FREE(vedges); TN_FREE(tris); TN_FREE(keep_r); TN_FREE(keep_v);
    TN_FREE(occ);
    TN_FREE(tmp.p);
    if (st) {
        tn_contour_set_free(&set);
        return st;
    }
    *out = set;
    return TN_OK;
}

/* ---- contour parts ---- */

/* A polyline end for the contour-graph DFS: end e = 2 * line (first point) or 2 * line + 1 (last),
   at pixel (x, y) of a type; sorted so the ends at and around a pixel are found by bisection. */
typedef struct tn__pend { int type, y, x, e; } tn__pend;

static int tn__pend_cmp(const void *pa, const void *pb)
{
    const tn__pend *a = (const tn__pend *)pa, *b = (const tn__pend *)pb;
    if (a->type != b->type) return a->type < b->type ? -1 : 1;
    if (a->y != b->y) return a->y < b->y ? -1 : 1;
    if (a->x != b->x) return a->x < b->x ? -1 : 1;
    return (a->e > b->e) - (a->e < b->e);
}

typedef struct tn__pgraph {
    const tn_contour_set *lines;
    tn__pend *ends;     /* 2 * count, sorted */
    int *stack;
    size_t nstack, cap_stack; /* cap in bytes */
    uint8_t *seen;      /* per line */
    float *pts;         /* the DFS list: x, y, h */
    int *src;           /* line of each listed point */
    size_t npts;
} tn__pgraph;

static tn__pend tn__pend_of(const tn_contour_set *s, int e)
{
    const tn_contour *c = &s->items[e / 2];
    const float *p = c->points + (e & 1 ? 3 * (c->npoints - 1) : 0);
    tn__pend r;
    r.type = (int)c->type;
    r.x = (int)floorf(p[0] + 0.5f);
    r.y = (int)floorf(p[1] + 0.5f);
    r.e = e;
    return r;
}

/* Counts the ends of other lines at the same or an 8-adjacent pixel as end e (same type), in
   sorted order. push != 0 also pushes those of unseen lines (their entry end) onto the DFS stack. */
static int tn__pend_attached(tn__pgraph *g, int e, int push, tn_status *st)
{
    const tn__pend me = tn__pend_of(g->lines, e);
    const int m = 2 * g->lines->count;
    int dy, dx, found = 0;
    for (dy = -1; dy <= 1; dy++)
        for (dx = -1; dx <= 1; dx++) {
            tn__pend key;
            int lo = 0, hi = m;
            key.type = me.type;
            key.y = me.y + dy;
            key.x = me.x + dx;
            key.e = -1;
            while (lo < hi) { /* first end >= key */
                int mid = lo + (hi - lo) / 2;
                if (tn__pend_cmp(&g->ends[mid], &key) < 0) lo = mid + 1;
                else hi = mid;
            }
            for (; lo < m && g->ends[lo].type == key.type && g->ends[lo].y == key.y && g->ends[lo].x == key.x; lo++) {
                int o = g->ends[lo].e;
                if (o / 2 == e / 2) continue;
                found++;
                if (!push || g->seen[o / 2]) continue;
                if ((g->nstack + 1) * sizeof(int) > g->cap_stack &&
                    (*st = tn__reserve((void **)&g->stack, &g->cap_stack, (g->nstack + 1) * sizeof(int))))
                    return found;
                g->stack[g->nstack++] = o;
            }
        }
    return found;
}

/* Depth-first walk of the contour graph from end e: each line is listed from the end it is
   entered by; lines hanging on its far end come next, then those on its near end. */
static tn_status tn__pgraph_dfs(tn__pgraph *g, int e, size_t *cap_pts, size_t *cap_src)
{
    tn_status st = tn__reserve((void **)&g->stack, &g->cap_stack, sizeof(int));
    if (st) return st;
    g->nstack = 0;
    g->stack[g->nstack++] = e;
    while (g->nstack) {
        int in = g->stack[--g->nstack], l = in / 2, k;
        const tn_contour *c = &g->lines->items[l];
        size_t n0, top;
        if (g->seen[l]) continue;
        g->seen[l] = 1;
        if ((st = tn__reserve((void **)&g->pts, cap_pts, (g->npts + (size_t)c->npoints) * 3 * sizeof(float))) ||
            (st = tn__reserve((void **)&g->src, cap_src, (g->npts + (size_t)c->npoints) * sizeof(int))))
            return st;
        for (k = 0; k < c->npoints; k++) {
            const float *p = c->points + 3 * (in & 1 ? c->npoints - 1 - k : k);
            float *q = g->pts + 3 * g->npts;
            if (g->npts && q[-3] == p[0] && q[-2] == p[1]) continue; /* a shared junction pixel */
            memcpy(q, p, 3 * sizeof(float));
            g->src[g->npts++] = l;
        }
        n0 = g->nstack;
        tn__pend_attached(g, in ^ 1, 1, &st);
        if (!st) tn__pend_attached(g, in, 1, &st);
        if (st) return st;
        top = g->nstack; /* reversed, so the far end's lines come next (in sorted order), then the near end's */
        for (; n0 + 1 < top; n0++, top--) {
            int t = g->stack[n0];
            g->stack[n0] = g->stack[top - 1];
            g->stack[top - 1] = t;
        }
    }
    return TN_OK;
}

/* Cuts the DFS list into parts: runs of 8-adjacent points, each cut into windows of 5-10 points
   (a tail under 5 joins the last window when that stays <= 10); shorter runs are dropped. */
static tn_status tn__parts_cut(const tn__pgraph *g, tn_rng *rng, tn_contour_set *set, size_t *cap)
{
    const float *p = g->pts;
    size_t at = 0, n = g->npts;
    tn_status st = TN_OK;
    while (!st && at < n) {
        size_t end = at + 1;
        while (end < n && fabsf(p[3 * end] - p[3 * end - 3]) <= 1.5f && fabsf(p[3 * end + 1] - p[3 * end - 2]) <= 1.5f) end++;
        while (!st && end - at >= 5) {
            int left = (int)(end - at), len = 5 + (int)tn_rng_below(rng, 6);
            const tn_contour *c = &g->lines->items[g->src[at]];
            if (len > left) len = left;
            if (left - len > 0 && left - len < 5) len = left <= 10 ? left : left - 5; /* no short tail */
            st = tn__cset_add(set, cap, c->type, c->order, c->mean_gradient, p + 3 * at, len);
            at += (size_t)len;
        }
        at = end;
    }
    return st;
}

TN_API tn_status tn_contour_parts_make(tn_contour_set *parts, const tn_contour_set *lines, uint64_t seed)
{
    tn_contour_set set;
    tn__pgraph g;
    tn_rng rng;
    size_t cap = 0, cap_pts = 0, cap_src = 0;
    int i, pass;
    tn_status st;
    TN_ASSERT(parts);
    if ((st = tn__cset_check(lines, "contour parts"))) return st;
    memset(&set, 0, sizeof set);
    memset(&g, 0, sizeof g);
    set.width = lines->width;
    set.height = lines->height;
    tn_rng_seed(&rng, seed, 0x9a27u);
    g.lines = lines;
    if (lines->count) {
        g.ends = (tn__pend *)tn__alloc((size_t)lines->count * 2 * sizeof(tn__pend));
        g.seen = (uint8_t *)tn__calloc((size_t)lines->count);
        if (!g.ends || !g.seen) st = TN_ERR_OUT_OF_MEMORY;
    }
    if (!st) {
        for (i = 0; i < 2 * lines->count; i++) g.ends[i] = tn__pend_of(lines, i);
        if (lines->count) qsort(g.ends, (size_t)lines->count * 2, sizeof(tn__pend), tn__pend_cmp);
    }
    /* DFS from every free end (an endpoint of the graph) in line order, then from whatever is
       left (closed loops) at its first point */
    for (pass = 0; pass < 2 && !st; pass++)
        for (i = 0; i < lines->count && !st; i++) {
            int e = -1;
            if (g.seen[i]) continue;
            if (pass == 1) e = 2 * i;
            else if (!tn__pend_attached(&g, 2 * i, 0, &st)) e = 2 * i;
            else if (!tn__pend_attached(&g, 2 * i + 1, 0, &st)) e = 2 * i + 1;
            if (e < 0) continue;
            g.npts = 0;
            if (!(st = tn__pgraph_dfs(&g, e, &cap_pts, &cap_src))) st = tn__parts_cut(&g, &rng, &set, &cap);
        }
    TN_FREE(g.ends);
    TN_FREE(g.stack);
    TN_FREE(g.seen);
    TN_FREE(g.pts);
    TN_FREE(g.src);
    if (st) {
        tn_contour_set_free(&set);
        return st;
    }
    *parts = set;
    return TN_OK;
}

/* ---- alignment ---- */

/* Chain codes of a set of parts, each oriented left to right (A1). */
typedef struct tn__chains {
    int count;
    int *off;          /* codes of part i: code[off[i] .. off[i + 1]) */
    uint8_t *code;     /* 0..7: direction k * pi/4 (x right, y down) */
    int *at;           /* index into h of the start point of each code's step */
    float *h;          /* heights, oriented, scaled to [0, 1] unless raw; hoff[i] indexes part i */
    int *hoff;
    float *angle;      /* direction of the first-to-last vector, in units of pi/4 */
    uint8_t *type;
} tn__chains;

#define TN__ALIGN_MAXCODES 255

static void tn__chains_free(tn__chains *c)
{
    TN_FREE(c->off); TN_FREE(c->code); TN_FREE(c->at); TN_FREE(c->h); TN_FREE(c->hoff); TN_FREE(c->angle); TN_FREE(c->type);
    memset(c, 0, sizeof *c);
}

static tn_status tn__chains_make(const tn_contour_set *s, int raw, int flip, tn__chains *c)
{
    size_t npts = 0;
    int i, j;
    float lo = 0, hi = 0, scale;
    memset(c, 0, sizeof *c);
    for (i = 0; i < s->count; i++) {
        npts += (size_t)s->items[i].npoints;
        for (j = 0; j < s->items[i].npoints; j++) {
            float h = s->items[i].points[3 * j + 2];
            if ((i == 0 && j == 0) || h < lo) lo = h;
            if ((i == 0 && j == 0) || h > hi) hi = h;
        }
    }
    if (npts >= (size_t)INT_MAX) return tn__fail(TN_ERR_TOO_LARGE, "align: %zu points", npts);
    scale = raw ? 1.0f : (hi > lo ? 1.0f / (hi - lo) : 0.0f);
    if (raw) lo = 0.0f;
    c->count = s->count;
    c->off = (int *)tn__alloc(((size_t)s->count + 1) * sizeof(int));
    c->hoff = (int *)tn__alloc(((size_t)s->count + 1) * sizeof(int));
    c->code = (uint8_t *)tn__alloc(npts + 1);
    c->at = (int *)tn__alloc((npts + 1) * sizeof(int));
    c->h = (float *)tn__alloc((npts + 1) * sizeof(float));
    c->angle = (float *)tn__alloc(((size_t)s->count + 1) * sizeof(float));
    c->type = (uint8_t *)tn__alloc((size_t)s->count + 1);
    if (!c->off || !c->hoff || !c->code || !c->at || !c->h || !c->angle || !c->type) {
        tn__chains_free(c);
        return TN_ERR_OUT_OF_MEMORY;
    }
    c->off[0] = c->hoff[0] = 0;
    for (i = 0; i < s->count; i++) {
        const tn_contour *p = &s->items[i];
        int n = p->npoints, rev, nc = 0, base = c->hoff[i];
        const float *f = p->points, *l = p->points + 3 * (n - 1);
        rev = (f[0] > l[0] || (f[0] == l[0] && f[1] > l[1])) != flip; /* run in the main direction */
        for (j = 0; j < n; j++) c->h[base + j] = (p->points[3 * (rev ? n - 1 - j : j) + 2] - lo) * scale;
        c->angle[i] = (float)(atan2(rev ? f[1] - l[1] : l[1] - f[1], rev ? f[0] - l[0] : l[0] - f[0]) / 0.78539816339744831);
        for (j = 0; j + 1 < n && nc < TN__ALIGN_MAXCODES; j++) {
            const float *a = p->points + 3 * (rev ? n - 1 - j : j), *b = p->points + 3 * (rev ? n - 2 - j : j + 1);
            float dx = b[0] - a[0], dy = b[1] - a[1];
            if (dx == 0.0f && dy == 0.0f) continue; /* repeated point: no step */
            c->code[c->off[i] + nc] = (uint8_t)((int)lrint(atan2(dy, dx) / 0.78539816339744831) & 7);
            c->at[c->off[i] + nc] = base + j;
            nc++;
        }
        c->off[i + 1] = c->off[i] + nc;
        c->hoff[i + 1] = base + n;
        c->type[i] = (uint8_t)(p->type == TN_RIDGE);
    }
    return TN_OK;
}

typedef struct tn__align_cand { int len; float score; int index; } tn__align_cand;

/* a ranks before b by LCS length, then height score, then index */
static int tn__cand_better(const tn__align_cand *a, const tn__align_cand *b)
{
    if (a->len != b->len) return a->len > b->len;
    if (a->score != b->score) return a->score < b->score;
    return a->index < b->index;
}

typedef struct tn__align_job {
    const tn__chains *sk, *skr, *dem; /* skr: the sketch parts run the other way */
    int top, choices, any_type[2];
    uint64_t seed;
    int *match;
    size_t first;                     /* this batch starts at sketch part `first` */
} tn__align_job;

/* |mean(d)| + std(d) of the height differences on the common substring (P from pi, Q from qi,
   len steps, so len + 1 points); without a common step the first points are compared. */
static float tn__align_score(const tn__chains *sk, int i, int pi, const tn__chains *dem, int q, int qi, int len)
{
    double s = 0, s2 = 0, d;
    int t, m = len + 1, a, b;
    if (len == 0) {
        m = sk->hoff[i + 1] - sk->hoff[i];
        if (dem->hoff[q + 1] - dem->hoff[q] < m) m = dem->hoff[q + 1] - dem->hoff[q];
    }
    for (t = 0; t < m; t++) {
        if (len == 0) { a = sk->hoff[i] + t; b = dem->hoff[q] + t; }
        else if (t < len) { a = sk->at[pi + t]; b = dem->at[qi + t]; }
        else { a = sk->at[pi + len - 1] + 1; b = dem->at[qi + len - 1] + 1; }
        d = (double)sk->h[a] - dem->h[b];
        s += d;
        s2 += d * d;
    }
    s /= m;
    s2 = s2 / m - s * s;
    return (float)(fabs(s) + sqrt(s2 > 0 ? s2 : 0));
}

/* A sketch part's codes in the 8 rotations: rot[k][x] = code x turned by k * pi/4, and (for
   parts of at most 64 codes) bit x of mask[k][c] set when rot[k][x] == c. */
typedef struct tn__align_rot {
    uint8_t rot[8][TN__ALIGN_MAXCODES];
    uint64_t mask[8][8];
} tn__align_rot;

static void tn__align_rotations(const tn__chains *sk, int i, tn__align_rot *r)
{
    int k, x, np = sk->off[i + 1] - sk->off[i];
    memset(r->mask, 0, sizeof r->mask);
    for (k = 0; k < 8; k++)
        for (x = 0; x < np; x++) {
            r->rot[k][x] = (uint8_t)((sk->code[sk->off[i] + x] + k) & 7);
            if (x < 64) r->mask[k][r->rot[k][x]] |= (uint64_t)1 << x;
        }
}

/* Longest common substring of sketch part i's codes, rotated onto DEM part q by the multiple of
   pi/4 nearest the angle between their first-to-last vectors; *ps / *qs: where it starts.
   Bit-parallel for parts up to 64 codes: e[y] holds the x where p[x - L + 1 .. x] equals
   q[y - L + 1 .. y], grown one level L at a time until it empties. Longer parts walk only the
   diagonals that overlap by at least `need` codes (an answer < need then only says "not enough"). */
static int tn__align_lcs(const tn__chains *sk, int i, const tn__align_rot *r, const tn__chains *dem, int q, int need,
                         int *ps, int *qs)
{
    const uint8_t *p, *qc = dem->code + dem->off[q];
    int np = sk->off[i + 1] - sk->off[i], nq = dem->off[q + 1] - dem->off[q], x, y, d, len = 0, k;
    *ps = sk->off[i];
    *qs = dem->off[q];
    if (need < 1) need = 1;
    if (np < need || nq < need) return 0;
    k = (int)lrintf(dem->angle[q] - sk->angle[i]) & 7;
    if (np <= 64) {
        uint64_t e[TN__ALIGN_MAXCODES], any = 0;
        const uint64_t *m = r->mask[k];
        int hit = -1;
        for (y = nq - 1; y >= 0; y--) {
            e[y] = m[qc[y]];
            if (e[y]) hit = y;
            any |= e[y];
        }
        while (any) {
            len++;
            *ps = sk->off[i] + (int)tn__z_ctz64(e[hit]) - len + 1;
            *qs = dem->off[q] + hit - len + 1;
            any = 0;
            for (y = nq - 1; y >= len; y--) {
                e[y] = (e[y - 1] << 1) & m[qc[y]];
                if (e[y]) hit = y;
                any |= e[y];
            }
        }
        return len;
    }
    p = r->rot[k];
    for (d = need - np; d <= nq - need; d++) { /* q index = p index + d */
        int x0 = d < 0 ? -d : 0, x1 = np < nq - d ? np : nq - d, run = 0;
        for (x = x0; x < x1; x++) {
            run = p[x] == qc[x + d] ? run + 1 : 0;
            if (run > len) {
                len = run;
                *ps = sk->off[i] + x + 1 - run;
                *qs = dem->off[q] + x + d + 1 - run;
            }
        }
    }
    return len;
}

static void tn__align_rows(void *ctx, size_t begin, size_t end)
{
    const tn__align_job *job = (const tn__align_job *)ctx;
    begin += job->first;
    end += job->first;
    const tn__chains *dem = job->dem;
    tn__align_cand cand[64], c, r;
    tn__align_rot rotf, rotr;
    size_t i;
    for (i = begin; i < end; i++) {
        int ncand = 0, q, x, y, at, type = job->sk->type[i], ps, qs, ps2, qs2, need;
        tn_rng rng;
        tn__align_rotations(job->sk, (int)i, &rotf);
        tn__align_rotations(job->skr, (int)i, &rotr);
        for (q = 0; q < dem->count; q++) {
            if (job->any_type[type] && dem->type[q] != type) continue;
            need = ncand == job->top ? cand[ncand - 1].len : 0; /* to enter a full list */
            /* both directions of the sketch part: A1's left-to-right rule alone is not rotation invariant */
            c.len = tn__align_lcs(job->sk, (int)i, &rotf, dem, q, need, &ps, &qs);
            r.len = tn__align_lcs(job->skr, (int)i, &rotr, dem, q, need, &ps2, &qs2);
            if (c.len < need && r.len < need) continue;
            c.index = r.index = q;
            c.score = r.score = HUGE_VALF;
            if (c.len >= r.len) c.score = tn__align_score(job->sk, (int)i, ps, dem, q, qs, c.len);
            if (r.len >= c.len) r.score = tn__align_score(job->skr, (int)i, ps2, dem, q, qs2, r.len);
            if (tn__cand_better(&r, &c)) c = r;
            if (ncand == job->top && !tn__cand_better(&c, &cand[ncand - 1])) continue;
            if (ncand < job->top) ncand++;
            for (at = ncand - 1; at > 0 && tn__cand_better(&c, &cand[at - 1]); at--) cand[at] = cand[at - 1];
            cand[at] = c;
        }
        if (!ncand) { job->match[i] = -1; continue; }
        /* rank the top list by height score, pick one of the best `choices` */
        for (x = 1; x < ncand; x++) {
            c = cand[x];
            for (y = x; y > 0 && (c.score < cand[y - 1].score || (c.score == cand[y - 1].score && c.index < cand[y - 1].index)); y--)
                cand[y] = cand[y - 1];
            cand[y] = c;
        }
        tn_rng_seed(&rng, job->seed, (uint64_t)i);
        job->match[i] = cand[tn_rng_below(&rng, (uint32_t)(ncand < job->choices ? ncand : job->choices))].index;
    }
}

/* The zero rules of tn_align_opts: 10 candidates (also for a negative count; at most 64), a
   pick among the best 5 (also for a negative count). */
static void tn__align_opts_defaults(tn_align_opts *o)
{
    if (o->top <= 0) o->top = 10;
    if (o->top > 64) o->top = 64;
    if (o->choices <= 0) o->choices = 5;
}

TN_API tn_status tn_sketch_align(int *match, const tn_contour_set *sketch_parts, const tn_contour_set *dem_parts,
                                 const tn_align_opts *opts)
{
    tn_align_opts o;
    tn__chains sk, skr, dem;
    tn__align_job job;
    int i;
    tn_status st;
    TN_ASSERT(match);
    if ((st = tn__cset_check(sketch_parts, "align: sketch parts")) || (st = tn__cset_check(dem_parts, "align: DEM parts")))
        return st;
    if (!sketch_parts->count) return tn__fail(TN_ERR_EMPTY, "align: the sketch has no parts");
    if (!dem_parts->count) return tn__fail(TN_ERR_EMPTY, "align: the DEM has no contour parts");
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    tn__align_opts_defaults(&o);
    memset(&job, 0, sizeof job);
    job.top = o.top;
    job.choices = o.choices;
    job.seed = o.seed;
    job.match = match;
    if ((st = tn__chains_make(sketch_parts, o.raw_heights, 0, &sk))) return st;
    if ((st = tn__chains_make(sketch_parts, o.raw_heights, 1, &skr))) {
        tn__chains_free(&sk);
        return st;
    }
    if ((st = tn__chains_make(dem_parts, o.raw_heights, 0, &dem))) {
        tn__chains_free(&sk);
        tn__chains_free(&skr);
        return st;
    }
    for (i = 0; i < dem.count; i++) job.any_type[dem.type[i] ? 1 : 0] = 1;
    job.sk = &sk;
    job.skr = &skr;
    job.dem = &dem;
    /* batches between progress reports; each part's result is independent of the split */
    for (job.first = 0; !st && job.first < (size_t)sk.count; job.first += 1024) {
        size_t n = (size_t)sk.count - job.first < 1024 ? (size_t)sk.count - job.first : 1024;
        tn_parallel_for(n, 8, tn__align_rows, &job);
        st = tn__progress("align", (double)(job.first + n) / (double)sk.count);
    }
    tn__chains_free(&sk);
    tn__chains_free(&skr);
    tn__chains_free(&dem);
    return st;
}
#endif /* TN_NO_SKETCH */

