/* ============================================================================================
   @@render  previews: hillshaded colour map and 3D perspective view
   ============================================================================================ */
#ifndef TN_NO_RENDER

typedef struct tn_render_opts {
    float lo, hi;              /* height range for the colour ramp; lo == hi: the DEM's own range */
    tn_hillshade_opts shade;   /* light and spacing (zero = defaults) */
    float shade_strength;      /* 0..1 how much the hillshade darkens the colours; 0 = default 0.7; else TN_ERR_INVALID_ARG */
    int sea;                   /* 0: land colours only (heights that say nothing of the sea: a valley
                                  floor stays green); 1: water below sea_level, land above it */
    float sea_level;           /* with sea = 1: the shore's height in the DEM's units (0 on a DEM in metres) */
} tn_render_opts;

/* Hillshaded, colour-ramped RGB preview in [0, 1], same size as the DEM (channel 0 is used):
   green lowlands, tan and brown hills, grey rock, snow over [lo, hi], and with opts->sea blues
   below the sea level. opts may be NULL. Caller frees *out. */
TN_API tn_status tn_render_preview(tn_image *out, const tn_image *dem, const tn_render_opts *opts);

typedef struct tn_view_opts {
    int width, height;         /* output size; 0 = 960 x 540 */
    float azimuth_deg;         /* camera direction, clockwise from north, looking at the centre; 0 = from the south (180) */
    float pitch_deg;           /* downward look angle; 0 = default 30 */
    float distance;            /* camera distance in DEM widths from the centre; 0 = default 1.1 */
    float fov_deg;             /* horizontal field of view; 0 = default 60 */
    float relief;              /* height of the full DEM range as a fraction of the DEM width; 0 = 0.2,
                                  or from spacing and exaggeration when spacing > 0 */
    float spacing;             /* metres per pixel of a DEM in metres (e.g. an .hgt: tn_image_info.cellsize);
                                  0 = unknown: relief applies */
    float exaggeration;        /* with spacing: vertical exaggeration of the true relief; 0 = 2 */
    tn_render_opts colours;    /* colouring of the surface */
} tn_view_opts;

/* 3D perspective view of the DEM (ray-marched height field, front-to-back with a per-column
   occlusion buffer, distance haze, sky). RGB in [0, 1]. opts may be NULL. Caller frees *out. */
TN_API tn_status tn_render_view(tn_image *out, const tn_image *dem, const tn_view_opts *opts);
#endif /* TN_NO_RENDER */

/* --------------------------------------------------------------------------------------------
   >>render  (@@render implementation)
   The preview multiplies a hypsometric colour ramp by a hillshade. The ramp is a land ramp unless
   the caller says where the sea is: a range mapped to [0, 1] cannot tell an inland valley floor
   (the Rhine at 431 m on the Alps) from a coast (issue 34). The 3D view is the classic
   height-field ray caster: every screen column marches a ray away from the camera; a sample
   whose projected top lies above everything drawn so far in that column fills the gap. Columns
   are independent, so they run in parallel and the image does not depend on the thread count.
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_RENDER

/* The zero rule of tn_render_opts: shade strength 0.7, land colours only. lo == hi (the DEM's
   own range) is resolved in tn_render_preview, and shade by tn_image_hillshade. */
static void tn__render_opts_defaults(tn_render_opts *o)
{
    if (o->shade_strength == 0) o->shade_strength = 0.7f;
}

/* Colour of stop table s (rows t, r, g, b; t rising from 0 to 1) at t in [0, 1]. */
static void tn__render_stops(const float (*s)[4], int n, float t, float *rgb)
{
    int i = 1, c;
    float f;
    if (!(t > 0.0f)) t = 0.0f;
    if (t > 1.0f) t = 1.0f;
    while (i < n - 1 && t > s[i][0]) i++;
    f = (t - s[i - 1][0]) / (s[i][0] - s[i - 1][0]);
    for (c = 0; c < 3; c++) rgb[c] = s[i - 1][c + 1] + f * (s[i][c + 1] - s[i - 1][c + 1]);
}

/* Land from the lowest to the highest height: green lowlands, tan and brown hills, grey rock,
   snow; the sea from its deepest point to the shore: deep to shallow blue. */
static const float tn__render_land[][4] = {{0.00f, 0.30f, 0.55f, 0.27f}, {0.25f, 0.56f, 0.68f, 0.36f},
                                           {0.48f, 0.74f, 0.66f, 0.44f}, {0.66f, 0.55f, 0.42f, 0.30f},
                                           {0.80f, 0.55f, 0.53f, 0.51f}, {0.91f, 0.85f, 0.85f, 0.86f},
                                           {1.00f, 1.00f, 1.00f, 1.00f}};
static const float tn__render_sea[][4] = {{0.00f, 0.10f, 0.22f, 0.45f}, {0.85f, 0.30f, 0.55f, 0.75f}, {1.00f, 0.45f, 0.66f, 0.80f}};

TN_API tn_status tn_render_preview(tn_image *out, const tn_image *dem, const tn_render_opts *opts)
{
    tn_render_opts o;
    tn_image ramp = {0, 0, 0, NULL}, shade = {0, 0, 0, NULL};
    tn_status st;
    size_t i, n;
    float k;
    if ((st = tn__dem_check(dem, 2, "render preview"))) return st;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    if (!(o.shade_strength >= 0 && o.shade_strength <= 1))
        return tn__fail(TN_ERR_INVALID_ARG, "render preview: shade_strength %g is not in 0..1", (double)o.shade_strength);
    tn__render_opts_defaults(&o);
    k = o.shade_strength;
    if (!(o.lo == o.lo && o.hi == o.hi && (!o.sea || o.sea_level == o.sea_level)))
        return tn__fail(TN_ERR_INVALID_ARG, "render preview: lo, hi or sea_level is NaN");
    if (o.lo == o.hi && tn_image_range(&o.lo, &o.hi, dem)) return tn__fail(TN_ERR_NUMERIC, "render preview: the DEM holds NaN/Inf");
    if ((st = tn_image_create(&ramp, dem->width, dem->height, 3))) return st;
    if ((st = tn_image_hillshade(&shade, dem, &o.shade))) {
        tn_image_free(&ramp);
        return st;
    }
    n = (size_t)dem->width * dem->height;
    for (i = 0; i < n; i++) {
        float f = (1.0f - k) + k * 1.25f * shade.data[i], h = dem->data[i * dem->channels], rgb[3];
        int c;
        if (o.sea && h < o.sea_level) /* depth below the shore, down to the lowest point */
            tn__render_stops(tn__render_sea, 3, o.sea_level > o.lo ? (h - o.lo) / (o.sea_level - o.lo) : 1.0f, rgb);
        else {
            float base = o.sea && o.sea_level > o.lo ? o.sea_level : o.lo;
            tn__render_stops(tn__render_land, 7, o.hi > base ? (h - base) / (o.hi - base) : 0.0f, rgb);
        }
        for (c = 0; c < 3; c++) ramp.data[i * 3 + c] = tn__clampf(rgb[c] * f, 0.0f, 1.0f);
    }
    tn_image_free(&shade);
    *out = ramp;
    return TN_OK;
}

typedef struct tn__view_job {
    const tn_image *dem, *colour;
    tn_image *out;
    float lo, scale;            /* height -> world z: (h - lo) * scale */
    float cx, cy, cz;           /* camera position in pixel units */
    float yaw, pitch, fov;      /* radians */
    float far_dist, focal;
} tn__view_job;

static void tn__view_columns(void *ctx, size_t b, size_t e)
{
    const tn__view_job *j = (const tn__view_job *)ctx;
    tn_image *out = j->out;
    const float W = (float)j->dem->width, H = (float)j->dem->height;
    const float horizon = 0.5f * (float)out->height - tanf(j->pitch) * j->focal;
    size_t sx;
    for (sx = b; sx < e; sx++) {
        float ang = j->yaw + ((float)sx / (float)(out->width - 1) - 0.5f) * j->fov;
        float dx = sinf(ang), dy = -cosf(ang); /* north is -y */
        float cosd = cosf(ang - j->yaw);        /* distance along the view axis: no fish-eye */
        int ybuf = out->height, y;
        float t = 1.0f;
        while (t < j->far_dist && ybuf > 0) {
            float px = j->cx + dx * t, py = j->cy + dy * t;
            float step = 0.35f + t * 0.004f;
            if (px >= 0 && py >= 0 && px <= W - 1 && py <= H - 1) {
                float z = (tn__sample_bilinear(j->dem, px, py, 0) - j->lo) * j->scale;
                float depth = t * cosd;
                float fsy = horizon + (j->cz - z) / depth * j->focal;
                int sy = fsy < -1.0f ? -1 : fsy < (float)ybuf ? (int)fsy : ybuf; /* clamped before the cast */
                if (sy < ybuf) {
                    float haze = tn__clampf(t / j->far_dist, 0.0f, 1.0f);
                    float col[3];
                    int c;
                    haze = haze * haze * 0.8f;
                    for (c = 0; c < 3; c++) {
                        static const float sky[3] = {0.78f, 0.85f, 0.95f};
                        float v = tn__sample_bilinear(j->colour, px, py, c);
                        col[c] = v + (sky[c] - v) * haze;
                    }
                    for (y = sy < 0 ? 0 : sy; y < ybuf; y++) {
                        int c2;
                        for (c2 = 0; c2 < 3; c2++) TN_PIXEL(out, sx, y, c2) = col[c2];
                    }
                    ybuf = sy < 0 ? 0 : sy;
                }
            }
            t += step;
        }
        for (y = 0; y < ybuf; y++) { /* sky gradient above the terrain */
            float f = tn__clampf((float)y / (float)out->height, 0.0f, 1.0f);
            TN_PIXEL(out, sx, y, 0) = 0.45f + 0.35f * f;
            TN_PIXEL(out, sx, y, 1) = 0.62f + 0.25f * f;
            TN_PIXEL(out, sx, y, 2) = 0.88f + 0.08f * f;
        }
    }
}

/* The zero rules of tn_view_opts: 960 x 540 when either side is 0; seen from the south (180),
   30 degrees down, from 1.1 DEM widths, 60 degree field of view, relief 0.2 (the last three
   also replace negative values), exaggeration 2 (the relief when spacing is given).
   colours is resolved by tn_render_preview. */
static void tn__view_opts_defaults(tn_view_opts *o)
{
    if (o->width == 0 || o->height == 0) {
        o->width = 960;
        o->height = 540;
    }
    if (o->azimuth_deg == 0) o->azimuth_deg = 180.0f;
    if (o->pitch_deg == 0) o->pitch_deg = 30.0f;
    if (o->distance <= 0) o->distance = 1.1f;
    if (o->fov_deg <= 0) o->fov_deg = 60.0f;
    if (o->relief <= 0) o->relief = 0.2f;
    if (o->exaggeration <= 0) o->exaggeration = 2.0f;
}

TN_API tn_status tn_render_view(tn_image *out, const tn_image *dem, const tn_view_opts *opts)
{
    tn_view_opts o;
    tn_image colour = {0, 0, 0, NULL}, img = {0, 0, 0, NULL};
    tn__view_job j;
    tn_status st;
    float lo, hi, size, dist, zmax;
    if ((st = tn__dem_check(dem, 2, "render view"))) return st;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    if (o.width < 0 || o.height < 0 || !(fabsf(o.azimuth_deg) <= 1e6f) || !(fabsf(o.pitch_deg) < 89.0f) ||
        !(fabsf(o.distance) <= 1e6f) || !(o.fov_deg <= 170.0f && o.fov_deg >= -1e6f) || !(fabsf(o.relief) <= 1e6f) ||
        !(o.spacing == 0 || (o.spacing >= 1e-6f && o.spacing <= 1e9f)) || !(fabsf(o.exaggeration) <= 1e6f))
        return tn__fail(TN_ERR_INVALID_ARG, "render view: bad options (size %d x %d, angles and distances finite, |pitch| < 89, fov <= 170, "
                        "spacing 0 or 1e-6..1e9)", o.width, o.height);
    tn__view_opts_defaults(&o);
    if (o.width > 16384 || o.height > 16384)
        return tn__fail(TN_ERR_INVALID_ARG, "render view: output %d x %d is too large (max 16384)", o.width, o.height);
    if (tn_image_range(&lo, &hi, dem)) return tn__fail(TN_ERR_NUMERIC, "render view: the DEM holds NaN/Inf");
    if ((st = tn_render_preview(&colour, dem, &o.colours))) return st;
    if ((st = tn_image_create(&img, o.width, o.height, 3))) {
        tn_image_free(&colour);
        return st;
    }
    size = (float)(dem->width > dem->height ? dem->width : dem->height);
    dist = o.distance * size;
    /* with the pixel size known, the relief is the true one times the exaggeration */
    zmax = o.spacing > 0 ? o.exaggeration * (hi - lo) / o.spacing : o.relief * size;
    j.dem = dem;
    j.colour = &colour;
    j.out = &img;
    j.lo = lo;
    j.scale = hi > lo ? zmax / (hi - lo) : 0.0f;
    j.yaw = o.azimuth_deg * 0.017453293f + 3.14159265f; /* the camera looks back towards the centre */
    j.pitch = o.pitch_deg * 0.017453293f;
    j.fov = o.fov_deg * 0.017453293f;
    j.cx = 0.5f * (float)(dem->width - 1) + sinf(j.yaw - 3.14159265f) * dist;
    j.cy = 0.5f * (float)(dem->height - 1) - cosf(j.yaw - 3.14159265f) * dist;
    j.cz = 0.5f * zmax + tanf(j.pitch) * dist;
    j.far_dist = dist + 1.5f * size;
    j.focal = 0.5f * (float)o.width / tanf(0.5f * j.fov);
    tn_parallel_for((size_t)o.width, 8, tn__view_columns, &j);
    tn_image_free(&colour);
    *out = img;
    return TN_OK;
}
#endif /* TN_NO_RENDER */

