/* ============================================================================================
   @@season  seasonal terrain: insolation, climate, seasonal textures (paper 003)
   A heightfield and a climate (12 monthly mean temperatures T and precipitations P, a latitude)
   give the terrain's look for every month of the year.
   Insolation: the daily direct-beam sum of extraterrestrial sunlight (no atmosphere) on each
   pixel's slope, on the 15th of every month, in W h/m^2 per day. The sun's path comes from the
   latitude, Spencer's declination and orbit-eccentricity series and the hour angle; the day is
   cut into steps (15 min by default) and the cosine of incidence is integrated EXACTLY over each
   step (it is a + b cos(w) + c sin(w) in the hour angle w), clipped at sunrise, sunset and the
   moment the sun passes behind the pixel's own slope. Terrain shadows come from horizon angles
   cast once per pixel in `directions` azimuths (ray marching over the heightfield with geometric
   steps, stopped when no higher point can follow) and looked up per step. So a flat plane gives
   the textbook daily extraterrestrial insolation and a tilted plane its closed form, to
   rounding; GRASS r.sun's beam output is the real-DEM reference (docs/season.md).
   Climate: a small CSV (docs/season.md) or a built-in Koppen preset (a named station's monthly
   normals per group); temperature follows elevation at the lapse rate (-0.6 C / 100 m by
   default) from the climate's reference height.
   Seasonal texturer (no data files): a cyclic year of degree-day snow (snow below +1 C, melt
   proportional to the positive temperature plus an insolation term, Hock 1999), vegetation
   greenness from temperature and moisture with a memory, forest below the warmest-month 10 C
   isotherm (the tree line), bare rock on steep slopes, colours measured from the real ground
   textures of ../shared/data/textures. Its state can be read at any time of the year, so frames
   between months follow the snow and vegetation, not a cross-fade of two pictures.
   ============================================================================================ */
#ifndef TN_NO_SEASON
#if defined(TN_NO_ENGINE) || defined(TN_NO_NOISE)
#error "terrainnet: @@season needs the tensor engine, @@noise; define TN_NO_SEASON too, or none of them"
#endif

/* Zero = default. */
typedef struct tn_insolation_opts {
    float dx, dy;            /* pixel spacing in metres (heights must be metres); 0 = 1, dy 0 = dx */
    int month;               /* 1..12: that month only (one channel); 0 = all twelve (12 channels) */
    int day;                 /* day of the month the sun path is taken on; 0 = 15 */
    float step_minutes;      /* time step of the shadow test; 0 = 15 (r.sun's default is 30) */
    int directions;          /* horizon azimuths; 0 = 32 */
    float max_distance;      /* horizon search radius in metres; 0 = the whole map */
    int no_shadows;          /* 1: slope and aspect only, no terrain horizon */
    float solar_constant;    /* W/m^2; 0 = 1367 (as r.sun) */
} tn_insolation_opts;

/* Fills *o with the defaults (what zero fields mean). */
TN_API void tn_insolation_defaults(tn_insolation_opts *o);
/* Daily direct-beam insolation (W h/m^2 per day) on channel 0 of dem (heights in metres, finite,
   at least 2 x 2) at latitude_deg (-90..90; south negative; row 0 is north). *out (allocated
   here) has 12 channels, channel m = month m + 1, or one channel with opts->month. Threaded,
   bit-identical for any thread count; progress "insolation". */
TN_API tn_status tn_insolation(tn_image *out, const tn_image *dem, double latitude_deg, const tn_insolation_opts *opts);
/* Sun on day_of_year (1..366): declination (radians) and the orbit's eccentricity factor
   (Spencer 1971). Either output may be NULL. */
TN_API void tn_sun_day(double *declination, double *eccentricity, int day_of_year);
/* Day of the year of `day` in `month` (1..12) of a non-leap year. */
TN_API int tn_day_of_year(int month, int day);

/* A year of climate: monthly means. Temperatures hold at `elevation` metres. */
typedef struct tn_climate {
    float t[12];             /* mean air temperature, degrees C, January first */
    float p[12];             /* precipitation, mm per month */
    float latitude;          /* degrees, south negative; valid when has_latitude */
    int has_latitude;
    float elevation;         /* reference height of t in metres (the station's) */
    char name[64];           /* preset code and station, or the file name */
} tn_climate;

/* Checks a climate: finite values, -90 <= T <= 60, 0 <= P <= 5000, |latitude| <= 90. */
TN_API tn_status tn_climate_check(const tn_climate *c);
/* Parses the CSV text of docs/season.md ("month,t_c,p_mm" rows for months 1..12, each once;
   optional "latitude,L" and "elevation,H" rows; '#' comments). A missing month, a NaN, an
   unknown row or |latitude| > 90 fails with a message naming the line. name may be NULL. */
TN_API tn_status tn_climate_parse(tn_climate *out, const char *text, size_t size, const char *name);
TN_API tn_status tn_climate_load(tn_climate *out, const char *path);
/* Built-in Koppen presets ("Af", "Aw", "BWh", "Csa", "Cfb", "Dfb", "Dfc", "ET"; a group letter
   "A".."E" picks the first of its group). Unknown codes fail with TN_ERR_INVALID_ARG. */
TN_API tn_status tn_climate_koppen(tn_climate *out, const char *code);
/* The i-th preset's code (i from 0), or NULL past the end. */
TN_API const char *tn_climate_koppen_code(int i);
/* Temperature of month m (0..11) at height h (metres): t[m] + lapse_rate * (h - elevation);
   lapse_rate 0 = -0.006 C/m. */
TN_API float tn_climate_temperature(const tn_climate *c, int month, float height, float lapse_rate);

/* Zero = default. */
typedef struct tn_season_opts {
    tn_insolation_opts insolation; /* how insolation is computed when none is given (dx, dy also
                                      give the slopes here; month is ignored) */
    float lapse_rate;        /* C per metre; 0 = -0.006 */
    float melt_factor;       /* degree-day snow melt, mm / (C day); 0 = 2 */
    float radiation_factor;  /* extra melt per mean W/m^2 of insolation, mm m^2 / (W C day); 0 = 0.006 */
    float snow_temp;         /* precipitation falls as snow below this, C; 0 = 1 */
    float rock_slope;        /* degrees where bare rock takes over (half-way); 0 = 40 */
    float shade;             /* 0..1 hillshade mixed into the colours (0 = flat albedo) */
    float detail;            /* 0..1 strength of the fine noise that breaks up the zones; 0 = 0.5, < 0 = none */
    uint64_t seed;           /* of the detail noise */
} tn_season_opts;

/* Per-pixel seasonal state at one time of the year. */
typedef struct tn_season_state {
    tn_image snow;           /* snow water equivalent, mm */
    tn_image green;          /* vegetation greenness 0..1 */
} tn_season_state;

TN_API void tn_season_defaults(tn_season_opts *o);
/* Procedural seasonal textures of dem (metres) under climate at `count` times of the year:
   times[i] in months from mid-January (0 = Jan 15, 1 = Feb 15, 11.5 = Dec 30; taken modulo 12).
   insolation: 12-channel tn_insolation output for this dem, or NULL to compute it (latitude
   from latitude_deg if finite, else the climate's; neither fails). out[i] (RGB in [0, 1],
   allocated here) and state[i] (may be NULL) are filled for each time. A wrong-sized insolation
   fails with TN_ERR_SHAPE. Progress "season". */
TN_API tn_status tn_season_texture(tn_image *out, const tn_image *dem, const tn_climate *climate,
                                   double latitude_deg, const tn_image *insolation, const float *times,
                                   int count, const tn_season_opts *opts, tn_season_state *state);
TN_API void tn_season_state_free(tn_season_state *s);
/* A preview sheet: the images side by side in `columns` columns (0 = 4), each scaled to
   `cell` pixels wide (0 = 256), 4 px gaps. *out allocated here. */
TN_API tn_status tn_season_sheet(tn_image *out, const tn_image *images, int count, int columns, int cell);
/* The same with a caption over each image: labels[i] (NULL or labels NULL: none), in capitals,
   digits and - / . : % (other characters show as blanks), e.g. tn_season_time_label's. */
TN_API tn_status tn_season_sheet_labelled(tn_image *out, const tn_image *images, const char *const *labels, int count, int columns,
                                          int cell);
/* "JAN", or "MAR 30" for a time between months: time in months from mid-January (as
   tn_season_texture takes them). Writes at most size bytes to buf; returns buf. */
TN_API char *tn_season_time_label(char *buf, size_t size, float time);

/* KPD generator (paper 003, 3.1-3.2): a SPADE-style network whose denormalisation blocks take
   the heightfield (height and its gradient) plus the year of climate rotated so the target month
   comes first: per-pixel temperature at the lapse rate (T12), precipitation (P12) and insolation
   (S12). Three levels (1/4, 1/2, 1/1 of the map), one KPD residual block each; the normalisation
   is positional (over the channels of each pixel), so a pixel depends only on its neighbourhood
   and any window equals those pixels of a whole-map run (halo TN_KPD_HALO). Trained with hinge
   GAN + feature matching (SPADE's, without the VAE) + L1, every term skipping masked pixels
   (clouds, no data). A time between two months interpolates the blocks' gamma and beta (Eq. 1). */

#define TN_KPD_HALO 64

/* What the network is given besides the heightfield (the paper's Table 1 conditions). */
typedef enum tn_kpd_condition {
    TN_KPD_OURS = 0,   /* T12 + P12 + S12, rotated so the target month comes first */
    TN_KPD_COND1,      /* T'12 + P'12 in calendar order + the month index */
    TN_KPD_COND2,      /* T1 + P1: the target month's only */
    TN_KPD_COND3,      /* latitude + the month index */
    TN_KPD_COND4,      /* T12 + P12 rotated, no insolation */
    TN_KPD_CONDITIONS
} tn_kpd_condition;

/* Name of a condition ("ours", "cond1" .. "cond4"); tn_kpd_condition_parse reads one (or "1".."4"). */
TN_API const char *tn_kpd_condition_name(tn_kpd_condition c);
TN_API tn_status tn_kpd_condition_parse(tn_kpd_condition *out, const char *s);

/* One training picture: a heightfield under a climate at a time of the year, and what it looked
   like then. Nothing is owned. */
typedef struct tn_season_sample {
    const tn_image *dem;        /* heights in metres, one channel */
    const tn_image *insolation; /* its 12-channel tn_insolation; needed by TN_KPD_OURS only */
    const tn_climate *climate;  /* latitude needed by TN_KPD_COND3 */
    float time;                 /* months from mid-January, as tn_season_texture's times */
    const tn_image *target;     /* the dem's size; every sample has the same channel count */
    const tn_image *mask;       /* one channel, > 0.5 = a valid pixel; NULL = all valid */
} tn_season_sample;

/* Zero = default (tn_kpd_defaults). */
typedef struct tn_kpd_opts {
    tn_kpd_condition condition;
    int width;                  /* features at the coarsest level (half that at the finer two); 0 = 32 */
    int crop;                   /* training window side, a multiple of 8; 0 = 64 */
    int batch;                  /* windows per step; 0 = 4 */
    float lr;                   /* Adam (0, 0.999) of G and D; 0 = 2e-4 (the paper's) */
    float l1_weight;            /* masked L1 to the target; 0 = 10, < 0 = none */
    float fm_weight;            /* discriminator feature matching (SPADE's x10); 0 = 10, < 0 = none */
    float gan_weight;           /* hinge adversarial term of G; 0 = 1, < 0 = no discriminator */
    float lo, hi;               /* target values mapped to [-1, 1]; both 0 = [0, 1] */
    float lapse_rate;           /* C per metre; 0 = -0.006 */
    tn_train_opts train;        /* budget (minutes 0 = 10), checkpoint, resume, seed */
} tn_kpd_opts;

/* A trained generator. Free with tn_kpd_free. */
typedef struct tn_kpd {
    tn_kpd_condition condition;
    int cond_channels, out_channels, width;
    float lo, hi, lapse_rate;
    float h_offset, h_scale, g_scale; /* height and gradient normalisation of the training DEMs */
    long iterations;
    double train_seconds;
    tn_params *weights;         /* "kpd.config" and the generator's tensors */
} tn_kpd;

typedef struct tn_kpd_stats {
    long iterations, resumed_from;
    double seconds, seconds_per_iter;
    float loss_l1, loss_g, loss_d; /* averages over the last 50 iterations (L1 in target units) */
    float loss_l1_first;           /* L1 of this run's first iteration */
    int checkpoints;
} tn_kpd_stats;

TN_API void tn_kpd_defaults(tn_kpd_opts *o);
/* Trains on `count` samples (random crop x crop windows of them, at least a quarter valid).
   Progress "season-train". *model allocated here; stats may be NULL. */
TN_API tn_status tn_kpd_train(tn_kpd *model, const tn_season_sample *samples, int count, const tn_kpd_opts *opts,
                              tn_kpd_stats *stats);
TN_API void tn_kpd_free(tn_kpd *model);
/* .tnw stamped with method "kpd"; load refuses other methods' files (TN_ERR_FORMAT). */
TN_API tn_status tn_kpd_save(const char *path, const tn_kpd *model);
TN_API tn_status tn_kpd_load(tn_kpd *model, const char *path);
/* The window (x0, y0, w, h) of the texture of dem under climate at `time` (months from
   mid-January; between two months the gamma/beta of both are interpolated), in the target's
   units: any window equals those pixels of the whole map exactly. insolation: dem's 12-channel
   tn_insolation (TN_KPD_OURS; NULL fails). Runs in tiles of 256 px; *out allocated here. */
TN_API tn_status tn_kpd_generate(tn_image *out, const tn_kpd *model, const tn_image *dem, const tn_climate *climate,
                                 const tn_image *insolation, float time, int x0, int y0, int w, int h);

/* A season data set (docs/season.md): a text file of sites and their dated pictures. Paths are
   relative to the file's folder.
       dem,PATH[,LO,HI]       a new site: heights in metres (LO HI map a file without a range)
       spacing,DX             its pixel size in metres (default 1)
       climate,PATH | koppen,CODE      its climate (required)
       latitude,L             overrides the climate's
       frame,WHEN,IMAGE[,EXCLUDE...]  WHEN = YYYY-MM-DD or months from mid-January; every
                              EXCLUDE image marks pixels > 0.5 as unusable (clouds, no data)
       range,LO,HI            target values (e.g. -0.2,0.9 for NDVI; default 0,1)
   tn_season_data_load reads every file, computes each site's insolation, and checks sizes,
   NaNs and channel counts. */
typedef struct tn_season_data {
    int sites, count;
    tn_image *dems, *insolation;   /* [sites] */
    tn_climate *climates;          /* [sites] */
    tn_image *targets, *masks;     /* [count] */
    tn_season_sample *samples;     /* [count], pointing into the above */
    char (*labels)[32];            /* [count] WHEN as written */
    float lo, hi;
} tn_season_data;
TN_API tn_status tn_season_data_load(tn_season_data *out, const char *path);
TN_API void tn_season_data_free(tn_season_data *d);
/* Months from mid-January of a date "YYYY-MM-DD" (or a plain number of months); -1 if malformed. */
TN_API float tn_season_time_of(const char *when);
#endif /* TN_NO_SEASON */

/* --------------------------------------------------------------------------------------------
   >>season  (@@season implementation)
   Insolation runs row by row over the thread pool: each pixel casts its horizon in every
   direction into a small per-thread buffer, then sums its 12 months, so memory stays at a few
   rows whatever the map size. The sun's per-step direction and the exact step integrals of
   sin/cos are shared by all pixels of a month; a pixel only adds its normal's three
   coefficients.
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_SEASON

#define TN__SEASON_PI 3.14159265358979323846
#define TN__HORIZON_GROWTH 1.15 /* distance ratio of successive far horizon samples */

TN_API void tn_insolation_defaults(tn_insolation_opts *o)
{
    if (o->dx <= 0) o->dx = 1.0f;
    if (o->dy <= 0) o->dy = o->dx;
    if (o->day <= 0) o->day = 15;
    if (o->step_minutes <= 0) o->step_minutes = 15.0f;
    if (o->directions <= 0) o->directions = 32;
    if (o->solar_constant <= 0) o->solar_constant = 1367.0f;
}

TN_API int tn_day_of_year(int month, int day)
{
    static const int first[12] = {0, 31, 59, 90, 120, 151, 181, 212, 243, 273, 304, 334};
    month = tn__clampi(month, 1, 12);
    return first[month - 1] + day;
}

TN_API void tn_sun_day(double *declination, double *eccentricity, int day_of_year)
{
    double g = 2.0 * TN__SEASON_PI * (double)(day_of_year - 1) / 365.0;
    if (declination)
        *declination = 0.006918 - 0.399912 * cos(g) + 0.070257 * sin(g) - 0.006758 * cos(2 * g) + 0.000907 * sin(2 * g) -
                       0.002697 * cos(3 * g) + 0.00148 * sin(3 * g);
    if (eccentricity) *eccentricity = 1.000110 + 0.034221 * cos(g) + 0.001280 * sin(g) + 0.000719 * cos(2 * g) + 0.000077 * sin(2 * g);
}

/* One time step of a month, clipped to the hours the sun is above the horizontal: hour angles
   [a, b], the exact integrals of 1, cos and sin over it, and the sun at its middle (tangent of the
   elevation, horizon direction k and the weight of k + 1). */
typedef struct tn__sun_step {
    double a, b;
    float d, dsin, dcos; /* b - a, sin b - sin a, cos b - cos a */
    float tan_el, w;
    int k;
} tn__sun_step;

typedef struct tn__sun_month {
    double sd, cd;        /* sin and cos of the declination */
    double scale;         /* solar constant x eccentricity x 24 h / 2 pi: W h/m^2 per radian */
    double ws, dstep;     /* sunset hour angle; step length */
    int first;            /* index of steps[0] among the day's steps from -pi */
    int nsteps;
    tn__sun_step *steps;
} tn__sun_month;

typedef struct tn__insol_job {
    const float *h;
    int w, ht, nm, dirs, nsamp;
    float dx, dy, hmax;
    double sphi, cphi;
    const int *ix, *iy;           /* [dirs][nsamp] whole-pixel offsets of the horizon samples, */
    const float *fx, *fy, *inv_t; /* their bilinear weights and 1 / distance (1/m) */
    const unsigned char *need;    /* [dirs] the sun shines from this direction on some day */
    const tn__sun_month *months;
    int no_shadows;
    float *hbuf;                  /* [threads][w * dirs] */
    float *out;
    int row0, row1;
} tn__insol_job;

/* Sun at hour angle w: tangent of its elevation and horizon direction index + weight. */
static void tn__sun_at(double sphi, double cphi, double sd, double cd, double w, int dirs, float *tan_el, int *k, float *wt)
{
    double e = -cd * sin(w), n = cphi * sd - sphi * cd * cos(w), u = sphi * sd + cphi * cd * cos(w);
    double hz = sqrt(e * e + n * n), az = atan2(e, n), f;
    *tan_el = (float)(hz > 1e-12 ? u / hz : 1e30);
    if (az < 0) az += 2.0 * TN__SEASON_PI;
    f = az / (2.0 * TN__SEASON_PI) * dirs;
    *k = (int)floor(f);
    *wt = (float)(f - *k);
    if (*k >= dirs) *k -= dirs;
    if (*k < 0) *k = 0;
}

/* Tangent of the horizon elevation from every pixel of row y in direction k, into
   hz[x * dirs + k]; -1e30 where a ray leaves the map at once (nothing blocks). A sample's offset
   from its pixel is the same for every pixel, so its integer part and bilinear weights are
   tabulated, and a direction is swept along the whole row so neighbouring pixels read
   neighbouring memory. A ray stops at the map's edge or where even the map's highest point
   could not rise above the horizon found so far. */
static void tn__insol_horizon(const tn__insol_job *j, int y, int k, float *hz)
{
    const float *h = j->h;
    size_t o = (size_t)k * j->nsamp;
    const int *ix = j->ix + o, *iy = j->iy + o;
    const float *fx = j->fx + o, *fy = j->fy + o, *it = j->inv_t + o;
    int x, s, w = j->w;
    for (x = 0; x < w; x++) {
        float h0 = h[(size_t)y * w + x], best = -1e30f, rise = j->hmax - h0;
        for (s = 0; s < j->nsamp; s++) {
            int cx = x + ix[s], cy = y + iy[s], cx1, cy1;
            const float *p, *q;
            float t;
            if (cx < 0 || cy < 0 || cx > w - 1 || cy > j->ht - 1 || rise * it[s] <= best) break;
            cx1 = cx < w - 1 ? 1 : 0;
            cy1 = cy < j->ht - 1 ? w : 0;
            p = h + (size_t)cy * w + cx;
            q = p + cy1;
            t = ((p[0] + (p[cx1] - p[0]) * fx[s]) * (1.0f - fy[s]) + (q[0] + (q[cx1] - q[0]) * fx[s]) * fy[s] - h0) * it[s];
            if (t > best) best = t;
        }
        hz[(size_t)x * j->dirs + k] = best;
    }
}

/* Daily sum of max(0, A + B cos w + C sin w) while the sun is up and above the pixel's horizon.
   The positive part of the sinusoid is the arc |w - psi| < alpha (mod 2 pi); its overlap with the
   daylight [-ws, ws] is at most two intervals. Without shadows each is one closed form; with
   them the steps inside an interval use the month's shared integrals and the (at most two)
   steps it cuts are integrated exactly between the cut points, the shadow tested at the lit
   part's middle. */
static double tn__insol_day(const tn__insol_job *j, const tn__sun_month *m, double A, double B, double C, const float *hz)
{
    const double twopi = 2.0 * TN__SEASON_PI;
    double R = sqrt(B * B + C * C), psi = 0, alpha = TN__SEASON_PI, sum = 0, lo[3], hi[3];
    int nint = 0, c, s;
    if (m->nsteps == 0) return 0.0;
    if (R <= 1e-12 || A >= R) {
        if (A <= 0) return 0.0;
        lo[0] = -m->ws;
        hi[0] = m->ws;
        nint = 1;
    } else {
        if (A <= -R) return 0.0;
        alpha = acos(-A / R);
        psi = atan2(C, B);
        for (c = -1; c <= 1; c++) {
            double l = psi + c * twopi - alpha, h = psi + c * twopi + alpha;
            if (l < -m->ws) l = -m->ws;
            if (h > m->ws) h = m->ws;
            if (h > l) lo[nint] = l, hi[nint] = h, nint++;
        }
    }
    for (c = 0; c < nint; c++) {
        int s0, s1;
        if (j->no_shadows) {
            sum += A * (hi[c] - lo[c]) + B * (sin(hi[c]) - sin(lo[c])) - C * (cos(hi[c]) - cos(lo[c]));
            continue;
        }
        s0 = (int)floor((lo[c] + TN__SEASON_PI) / m->dstep) - m->first;
        s1 = (int)floor((hi[c] + TN__SEASON_PI) / m->dstep) - m->first;
        if (s0 < 0) s0 = 0;
        if (s1 > m->nsteps - 1) s1 = m->nsteps - 1;
        for (s = s0; s <= s1; s++) {
            const tn__sun_step *st = &m->steps[s];
            double l = st->a > lo[c] ? st->a : lo[c], h = st->b < hi[c] ? st->b : hi[c];
            float te = st->tan_el, w = st->w;
            int k = st->k, k1;
            if (h <= l) continue;
            if (l == st->a && h == st->b) {
                k1 = k + 1 == j->dirs ? 0 : k + 1;
                if (te >= hz[k] + (hz[k1] - hz[k]) * w) sum += A * st->d + B * st->dsin - C * st->dcos;
                continue;
            }
            tn__sun_at(j->sphi, j->cphi, m->sd, m->cd, 0.5 * (l + h), j->dirs, &te, &k, &w);
            k1 = k + 1 == j->dirs ? 0 : k + 1;
            if (te >= hz[k] + (hz[k1] - hz[k]) * w) sum += A * (h - l) + B * (sin(h) - sin(l)) - C * (cos(h) - cos(l));
        }
    }
    return sum * m->scale;
}

static void tn__insol_rows(void *ctx, int ith, int nth)
{
    const tn__insol_job *j = (const tn__insol_job *)ctx;
    float *hzrow = j->hbuf + (size_t)ith * j->dirs * j->w;
    int x, y, mo, k;
    for (y = j->row0 + ith; y < j->row1; y += nth) {
        if (!j->no_shadows)
            for (k = 0; k < j->dirs; k++) {
                if (j->need[k]) tn__insol_horizon(j, y, k, hzrow);
                else for (x = 0; x < j->w; x++) hzrow[(size_t)x * j->dirs + k] = -1e30f;
            }
        const float *r = j->h + (size_t)y * j->w;
        const float *up = y > 0 ? r - j->w : r, *dn = y < j->ht - 1 ? r + j->w : r;
        float ry = (y > 0 && y < j->ht - 1 ? 2.0f : 1.0f) * j->dy;
        for (x = 0; x < j->w; x++) {
            int xl = x > 0 ? x - 1 : x, xr = x < j->w - 1 ? x + 1 : x;
            double gx = (r[xr] - r[xl]) / ((double)(xr - xl) * j->dx), gs = (dn[x] - up[x]) / (double)ry;
            double inv = 1.0 / sqrt(gx * gx + gs * gs + 1.0), nE = -gx * inv, nN = gs * inv, nU = inv;
            float *o = j->out + ((size_t)y * j->w + x) * j->nm;
            const float *hz = hzrow + (size_t)x * j->dirs;
            for (mo = 0; mo < j->nm; mo++) {
                const tn__sun_month *m = &j->months[mo];
                double A = m->sd * (nN * j->cphi + nU * j->sphi), B = m->cd * (nU * j->cphi - nN * j->sphi), C = -m->cd * nE;
                o[mo] = (float)tn__insol_day(j, m, A, B, C, hz);
            }
        }
    }
}

TN_API tn_status tn_insolation(tn_image *out, const tn_image *dem, double latitude_deg, const tn_insolation_opts *opts)
{
    static const int mdays[12] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
    tn_insolation_opts o;
    tn__insol_job j;
    tn__sun_month months[12];
    tn_image res = {0, 0, 0, NULL};
    float *fx = NULL, *fy = NULL, *it = NULL, *hbuf = NULL, *h = NULL;
    int *ix = NULL, *iy = NULL;
    unsigned char *need = NULL;
    double phi, dstep, tmax, base;
    size_t n, i;
    int mo, nm, m0, s, k, nthr, band;
    tn_status st = TN_OK;
    memset(months, 0, sizeof months);
    if (!dem || !out) return tn__fail(TN_ERR_INVALID_ARG, "insolation: NULL argument");
    if (!dem->data || dem->width < 2 || dem->height < 2 || dem->channels < 1)
        return tn__fail(TN_ERR_EMPTY, "insolation: the heightfield must be at least 2 x 2 (got %d x %d)", dem->width, dem->height);
    if (!(latitude_deg >= -90.0 && latitude_deg <= 90.0))
        return tn__fail(TN_ERR_INVALID_ARG, "insolation: latitude %g is outside -90..90", latitude_deg);
    if (opts) o = *opts;
    else memset(&o, 0, sizeof o);
    if (!(o.dx >= 0 && o.dy >= 0 && o.step_minutes >= 0 && o.max_distance >= 0 && o.solar_constant >= 0) ||
        !isfinite(o.dx) || !isfinite(o.dy) || !isfinite(o.step_minutes) || !isfinite(o.max_distance) || !isfinite(o.solar_constant))
        return tn__fail(TN_ERR_INVALID_ARG, "insolation: spacing, step, distance and solar constant must be finite and >= 0");
    if (o.month < 0 || o.month > 12) return tn__fail(TN_ERR_INVALID_ARG, "insolation: month %d is not 1..12 (0 = all)", o.month);
    if (o.directions < 0 || o.directions > 1024) return tn__fail(TN_ERR_INVALID_ARG, "insolation: directions %d is not 4..1024", o.directions);
    if (o.directions && o.directions < 4) return tn__fail(TN_ERR_INVALID_ARG, "insolation: at least 4 horizon directions (got %d)", o.directions);
    if (o.step_minutes > 720) return tn__fail(TN_ERR_INVALID_ARG, "insolation: a time step of %g min is over half a day", o.step_minutes);
    tn_insolation_defaults(&o);
    nm = o.month ? 1 : 12;
    m0 = o.month ? o.month - 1 : 0;
    for (mo = m0; mo < m0 + nm; mo++)
        if (o.day > mdays[mo]) return tn__fail(TN_ERR_INVALID_ARG, "insolation: day %d does not exist in month %d", o.day, mo + 1);
    n = (size_t)dem->width * dem->height;
    if (!(h = (float *)tn__alloc(n * sizeof(float)))) return tn__oom();
    for (i = 0; i < n; i++) {
        h[i] = dem->data[i * dem->channels];
        if (!isfinite(h[i])) {
            TN_FREE(h);
            return tn__fail(TN_ERR_NUMERIC, "insolation: NaN/Inf height at pixel (%d, %d)", (int)(i % dem->width), (int)(i / dem->width));
        }
    }
    memset(&j, 0, sizeof j);
    j.h = h;
    j.w = dem->width;
    j.ht = dem->height;
    j.nm = nm;
    j.dx = o.dx;
    j.dy = o.dy;
    j.no_shadows = o.no_shadows;
    j.dirs = o.directions;
    phi = latitude_deg * TN__SEASON_PI / 180.0;
    j.sphi = sin(phi);
    j.cphi = cos(phi);
    /* 90 degrees exactly: cos is 6e-17, the sun circles at a fixed height, which is right */
    j.hmax = h[0];
    for (i = 1; i < n; i++)
        if (h[i] > j.hmax) j.hmax = h[i];
    /* horizon samples: one pixel apart for the first 8, then 15 % further each */
    base = o.dx < o.dy ? o.dx : o.dy;
    tmax = sqrt((double)j.w * j.w * o.dx * o.dx + (double)j.ht * j.ht * o.dy * o.dy);
    if (o.max_distance > 0 && o.max_distance < tmax) tmax = o.max_distance;
    {
        double t = base;
        j.nsamp = 0;
        while (t <= tmax && j.nsamp < 4096) { j.nsamp++; t = j.nsamp < 8 ? t + base : t * TN__HORIZON_GROWTH; }
        if (j.nsamp < 1) j.nsamp = 1;
    }
    nthr = tn_get_threads();
    {
        size_t tab = (size_t)j.dirs * j.nsamp;
        if (!(fx = (float *)tn__alloc(tab * sizeof(float))) || !(fy = (float *)tn__alloc(tab * sizeof(float))) ||
            !(it = (float *)tn__alloc(tab * sizeof(float))) || !(ix = (int *)tn__alloc(tab * sizeof(int))) ||
            !(iy = (int *)tn__alloc(tab * sizeof(int))) || !(need = (unsigned char *)tn__calloc((size_t)j.dirs)) ||
            !(hbuf = (float *)tn__alloc((size_t)nthr * j.dirs * j.w * sizeof(float)))) { st = tn__oom(); goto done; }
    }
    for (k = 0; k < j.dirs; k++) {
        double az = 2.0 * TN__SEASON_PI * k / j.dirs, t = base;
        for (s = 0; s < j.nsamp; s++) {
            size_t q = (size_t)k * j.nsamp + s;
            double px = t * sin(az) / o.dx, py = -t * cos(az) / o.dy;
            if (fabs(px) < 1e-9) px = 0; /* exactly along the grid: no neighbour needed */
            if (fabs(py) < 1e-9) py = 0;
            ix[q] = (int)floor(px);
            iy[q] = (int)floor(py);
            fx[q] = (float)(px - ix[q]);
            fy[q] = (float)(py - iy[q]);
            it[q] = (float)(1.0 / t);
            t = s + 1 < 8 ? t + base : t * TN__HORIZON_GROWTH;
        }
    }
    j.ix = ix;
    j.iy = iy;
    j.fx = fx;
    j.fy = fy;
    j.inv_t = it;
    j.need = need;
    j.hbuf = hbuf;
    /* the months' sun paths, cut into steps of the day, clipped to sunrise .. sunset */
    dstep = 2.0 * TN__SEASON_PI * o.step_minutes / 1440.0;
    for (mo = 0; mo < nm; mo++) {
        tn__sun_month *m = &months[mo];
        double dec, ecc, ws, cw;
        int nst = (int)ceil(2.0 * TN__SEASON_PI / dstep - 1e-9);
        tn_sun_day(&dec, &ecc, tn_day_of_year(m0 + mo + 1, o.day));
        m->sd = sin(dec);
        m->cd = cos(dec);
        m->scale = o.solar_constant * ecc * 24.0 / (2.0 * TN__SEASON_PI);
        cw = -(j.sphi * m->sd) / (j.cphi * m->cd);
        ws = j.cphi < 1e-12 ? (j.sphi * m->sd > 0 ? TN__SEASON_PI : 0.0) : cw <= -1.0 ? TN__SEASON_PI : cw >= 1.0 ? 0.0 : acos(cw);
        if (!(m->steps = (tn__sun_step *)tn__alloc((size_t)nst * sizeof(tn__sun_step)))) { st = tn__oom(); goto done; }
        m->ws = ws;
        m->dstep = dstep;
        m->first = -1;
        for (s = 0; s < nst; s++) {
            double a = -TN__SEASON_PI + s * dstep, b = a + dstep;
            tn__sun_step *p = &m->steps[m->nsteps];
            if (b > TN__SEASON_PI) b = TN__SEASON_PI;
            if (a < -ws) a = -ws;
            if (b > ws) b = ws;
            if (b <= a) continue;
            if (m->first < 0) m->first = s;
            p->a = a;
            p->b = b;
            p->d = (float)(b - a);
            p->dsin = (float)(sin(b) - sin(a));
            p->dcos = (float)(cos(b) - cos(a));
            tn__sun_at(j.sphi, j.cphi, m->sd, m->cd, 0.5 * (a + b), j.dirs, &p->tan_el, &p->k, &p->w);
            m->nsteps++;
            {   /* the directions the sun passes through in this step (and one either side) */
                int q, kk;
                for (q = 0; q <= 8; q++) {
                    float te, ww;
                    tn__sun_at(j.sphi, j.cphi, m->sd, m->cd, a + (b - a) * q / 8.0, j.dirs, &te, &kk, &ww);
                    need[kk] = need[(kk + 1) % j.dirs] = need[(kk + j.dirs - 1) % j.dirs] = need[(kk + 2) % j.dirs] = 1;
                }
            }
        }
    }
    j.months = months;
    if ((st = tn_image_create(&res, j.w, j.ht, nm))) goto done;
    j.out = res.data;
    /* bands of rows between progress reports; rows inside a band go to the threads in turn */
    band = 16;
    for (j.row0 = 0; j.row0 < j.ht; j.row0 += band) {
        j.row1 = j.row0 + band < j.ht ? j.row0 + band : j.ht;
        tn_parallel_run(tn__insol_rows, &j);
        if ((st = tn__progress("insolation", (double)j.row1 / j.ht))) goto done;
    }
    *out = res;
    res.data = NULL;
done:
    for (mo = 0; mo < 12; mo++) TN_FREE(months[mo].steps);
    tn_image_free(&res);
    TN_FREE(h);
    TN_FREE(fx);
    TN_FREE(fy);
    TN_FREE(ix);
    TN_FREE(iy);
    TN_FREE(need);
    TN_FREE(it);
    TN_FREE(hbuf);
    return st;
}

/* ---- climate ---- */

TN_API tn_status tn_climate_check(const tn_climate *c)
{
    int m;
    if (!c) return tn__fail(TN_ERR_INVALID_ARG, "climate: NULL");
    for (m = 0; m < 12; m++) {
        if (!isfinite(c->t[m]) || !isfinite(c->p[m])) return tn__fail(TN_ERR_NUMERIC, "climate %s: month %d has a NaN/Inf value", c->name, m + 1);
        if (c->t[m] < -90.0f || c->t[m] > 60.0f)
            return tn__fail(TN_ERR_INVALID_ARG, "climate %s: month %d temperature %g C is outside -90..60", c->name, m + 1, c->t[m]);
        if (c->p[m] < 0.0f || c->p[m] > 5000.0f)
            return tn__fail(TN_ERR_INVALID_ARG, "climate %s: month %d precipitation %g mm is outside 0..5000", c->name, m + 1, c->p[m]);
    }
    if (c->has_latitude && !(c->latitude >= -90.0f && c->latitude <= 90.0f))
        return tn__fail(TN_ERR_INVALID_ARG, "climate %s: latitude %g is outside -90..90", c->name, c->latitude);
    if (!isfinite(c->elevation) || c->elevation < -1000.0f || c->elevation > 9000.0f)
        return tn__fail(TN_ERR_INVALID_ARG, "climate %s: reference elevation %g m is outside -1000..9000", c->name, c->elevation);
    return TN_OK;
}

/* The fields of one CSV line (commas, optional spaces); returns how many, at most max. */
static int tn__climate_fields(const char *s, size_t n, const char **fb, size_t *fl, int max)
{
    int k = 0;
    size_t i = 0;
    while (i <= n && k < max + 1) {
        size_t b = i, e;
        while (i < n && s[i] != ',') i++;
        e = i;
        while (b < e && tn__io_space((unsigned char)s[b])) b++;
        while (e > b && tn__io_space((unsigned char)s[e - 1])) e--;
        if (k < max) { fb[k] = s + b; fl[k] = e - b; }
        k++;
        i++;
    }
    return k;
}

TN_API tn_status tn_climate_parse(tn_climate *out, const char *text, size_t size, const char *name)
{
    tn_climate c;
    int seen[12] = {0}, line = 0, m;
    size_t i = 0;
    if (!text || !out) return tn__fail(TN_ERR_INVALID_ARG, "climate: NULL argument");
    memset(&c, 0, sizeof c);
    snprintf(c.name, sizeof c.name, "%s", name ? name : "climate");
    while (i < size) {
        const char *fb[4];
        size_t fl[4], b = i, e;
        double v[3];
        int nf;
        while (i < size && text[i] != '\n') i++;
        e = i++;
        line++;
        while (b < e && tn__io_space((unsigned char)text[b])) b++;
        if (b == e || text[b] == '#') continue;
        nf = tn__climate_fields(text + b, e - b, fb, fl, 4);
        if (tn__io_token_is(fb[0], fl[0], "month")) continue; /* the header row */
        if (tn__io_token_is(fb[0], fl[0], "latitude") || tn__io_token_is(fb[0], fl[0], "elevation")) {
            int lat = tn__io_token_is(fb[0], fl[0], "latitude");
            if (nf != 2 || !tn__io_number(fb[1], fl[1], &v[0]))
                return tn__fail(TN_ERR_FORMAT, "%s:%d: expected \"%s,<number>\"", c.name, line, lat ? "latitude" : "elevation");
            if (!isfinite(v[0])) return tn__fail(TN_ERR_NUMERIC, "%s:%d: %s is NaN/Inf", c.name, line, lat ? "latitude" : "elevation");
            if (lat && (v[0] < -90.0 || v[0] > 90.0)) return tn__fail(TN_ERR_INVALID_ARG, "%s:%d: latitude %g is outside -90..90", c.name, line, v[0]);
            if (lat) c.latitude = (float)v[0], c.has_latitude = 1;
            else c.elevation = (float)v[0];
            continue;
        }
        if (nf != 3 || !tn__io_number(fb[0], fl[0], &v[0]) || !tn__io_number(fb[1], fl[1], &v[1]) || !tn__io_number(fb[2], fl[2], &v[2]))
            return tn__fail(TN_ERR_FORMAT, "%s:%d: expected \"month,t_c,p_mm\" (three numbers), \"latitude,L\" or \"elevation,H\"", c.name, line);
        if (!(v[0] >= 1 && v[0] <= 12) || v[0] != floor(v[0])) return tn__fail(TN_ERR_FORMAT, "%s:%d: month %g is not 1..12", c.name, line, v[0]);
        m = (int)v[0] - 1;
        if (seen[m]) return tn__fail(TN_ERR_FORMAT, "%s:%d: month %d given twice", c.name, line, m + 1);
        if (!isfinite(v[1]) || !isfinite(v[2])) return tn__fail(TN_ERR_NUMERIC, "%s:%d: month %d has a NaN/Inf value", c.name, line, m + 1);
        seen[m] = 1;
        c.t[m] = (float)v[1];
        c.p[m] = (float)v[2];
    }
    for (m = 0; m < 12; m++)
        if (!seen[m]) {
            int k, have = 0;
            for (k = 0; k < 12; k++) have += seen[k];
            return tn__fail(TN_ERR_FORMAT, "%s: a climate needs all 12 months; %d given, month %d is missing", c.name, have, m + 1);
        }
    {
        tn_status st = tn_climate_check(&c);
        if (st) return st;
    }
    *out = c;
    return TN_OK;
}

TN_API tn_status tn_climate_load(tn_climate *out, const char *path)
{
    uint8_t *buf = NULL;
    size_t n = 0;
    tn_status st;
    if (!path || !out) return tn__fail(TN_ERR_INVALID_ARG, "climate: NULL argument");
    if ((st = tn__io_read_file(path, &buf, &n))) return st;
    st = tn_climate_parse(out, (const char *)buf, n, path);
    TN_FREE(buf);
    return st;
}

/* Monthly normals of one station per Koppen type, rounded from the published normals (sources
   in docs/season.md); typical values to start from, not a data set. */
typedef struct tn__koppen_preset {
    const char *code, *station;
    float lat, elev, t[12], p[12];
} tn__koppen_preset;

static const tn__koppen_preset tn__koppen[] = {
    {"Af", "Singapore (Changi)", 1.37f, 15.0f,
     {26.6f, 27.1f, 27.6f, 28.0f, 28.4f, 28.4f, 28.0f, 27.9f, 27.7f, 27.6f, 27.0f, 26.5f},
     {242, 162, 185, 179, 172, 162, 158, 176, 169, 194, 256, 288}},
    {"Aw", "Darwin Airport", -12.42f, 30.0f,
     {28.6f, 28.3f, 28.4f, 28.3f, 27.0f, 25.3f, 25.0f, 25.8f, 27.6f, 28.9f, 29.3f, 29.1f},
     {427, 374, 317, 102, 21, 1, 1, 5, 15, 70, 142, 249}},
    {"BWh", "Cairo", 30.05f, 23.0f,
     {14.0f, 15.3f, 17.6f, 21.1f, 24.9f, 27.2f, 28.0f, 28.0f, 26.3f, 23.6f, 19.3f, 15.6f},
     {5, 4, 4, 1, 0, 0, 0, 0, 0, 1, 4, 6}},
    {"Cfb", "Ljubljana", 46.07f, 299.0f,
     {-0.3f, 1.6f, 6.0f, 10.6f, 15.6f, 19.1f, 21.1f, 20.4f, 15.6f, 10.9f, 5.0f, 0.8f},
     {69, 70, 89, 98, 109, 143, 113, 133, 147, 144, 129, 100}},
    {"Csa", "Rome (Ciampino)", 41.80f, 105.0f,
     {7.5f, 8.2f, 10.2f, 12.6f, 17.2f, 21.1f, 24.1f, 24.5f, 20.8f, 16.4f, 11.4f, 8.4f},
     {67, 73, 58, 81, 53, 34, 19, 37, 73, 113, 115, 81}},
    {"Dfc", "Fairbanks", 64.80f, 133.0f,
     {-21.9f, -18.6f, -10.7f, 0.1f, 9.5f, 15.6f, 16.9f, 13.8f, 7.8f, -3.7f, -15.1f, -19.9f},
     {14, 11, 8, 7, 16, 36, 53, 48, 28, 22, 17, 17}},
    {"Dfb", "Moscow", 55.83f, 156.0f,
     {-6.5f, -6.7f, -1.0f, 6.7f, 13.2f, 17.0f, 19.2f, 17.0f, 11.3f, 5.6f, -1.2f, -5.2f},
     {52, 41, 35, 37, 49, 80, 85, 82, 68, 71, 55, 52}},
    {"ET", "Utqiagvik (Barrow)", 71.29f, 9.0f,
     {-25.4f, -27.2f, -26.0f, -17.9f, -6.3f, 2.3f, 5.0f, 3.9f, 0.4f, -8.4f, -17.5f, -23.0f},
     {4, 4, 3, 4, 4, 7, 27, 26, 16, 11, 6, 4}},
};
#define TN__KOPPEN_N ((int)(sizeof tn__koppen / sizeof tn__koppen[0]))

TN_API const char *tn_climate_koppen_code(int i) { return i >= 0 && i < TN__KOPPEN_N ? tn__koppen[i].code : NULL; }

TN_API tn_status tn_climate_koppen(tn_climate *out, const char *code)
{
    int i, m;
    if (!code || !out) return tn__fail(TN_ERR_INVALID_ARG, "koppen: NULL argument");
    for (i = 0; i < TN__KOPPEN_N; i++) {
        const tn__koppen_preset *k = &tn__koppen[i];
        size_t n = strlen(code);
        if (tn__io_token_is(code, n, k->code) || (n == 1 && tn__io_lower((unsigned char)code[0]) == tn__io_lower((unsigned char)k->code[0]))) {
            memset(out, 0, sizeof *out);
            for (m = 0; m < 12; m++) out->t[m] = k->t[m], out->p[m] = k->p[m];
            out->latitude = k->lat;
            out->has_latitude = 1;
            out->elevation = k->elev;
            snprintf(out->name, sizeof out->name, "%s %s", k->code, k->station);
            return TN_OK;
        }
    }
    return tn__fail(TN_ERR_INVALID_ARG, "koppen: unknown preset \"%s\" (Af, Aw, BWh, Cfb, Csa, Dfc, Dfb, ET or a group letter A-E)", code);
}

TN_API float tn_climate_temperature(const tn_climate *c, int month, float height, float lapse_rate)
{
    if (lapse_rate == 0.0f) lapse_rate = -0.006f;
    month = ((month % 12) + 12) % 12;
    return c->t[month] + lapse_rate * (height - c->elevation);
}

/* ---- seasonal texturer ---- */

TN_API void tn_season_defaults(tn_season_opts *o)
{
    tn_insolation_defaults(&o->insolation);
    if (o->lapse_rate == 0.0f) o->lapse_rate = -0.006f;
    if (o->melt_factor <= 0.0f) o->melt_factor = 2.0f;
    if (o->radiation_factor <= 0.0f) o->radiation_factor = 0.006f;
    if (o->snow_temp == 0.0f) o->snow_temp = 1.0f;
    if (o->rock_slope <= 0.0f) o->rock_slope = 40.0f;
    if (o->detail == 0.0f) o->detail = 0.5f;
    if (o->detail < 0.0f) o->detail = 0.0f;
}

/* Mean colours (sRGB) of the real ground textures in ../shared/data/textures (docs/season.md:
   grass_threejs_grasslight, rock_pebbles_gatys, sand_ripples, snow_surface, soil_cracked_mud);
   forest and straw are mixtures of them (no forest photo there). */
static const float tn__col_grass[3] = {0.383f, 0.519f, 0.131f};
static const float tn__col_rock[3] = {0.524f, 0.519f, 0.541f};
static const float tn__col_sand[3] = {0.661f, 0.596f, 0.489f};
static const float tn__col_snow[3] = {0.718f, 0.754f, 0.815f};
static const float tn__col_soil[3] = {0.647f, 0.600f, 0.577f};

#define TN__SEASON_SUB 4      /* model steps per month (about a week) */
#define TN__SEASON_LUT 2401   /* temperature tables: -60..60 C every 0.05 C */

static float tn__smooth(float e0, float e1, float x)
{
    float t = tn__clampf((x - e0) / (e1 - e0), 0.0f, 1.0f);
    return t * t * (3.0f - 2.0f * t);
}

typedef struct tn__season_job {
    const tn_image *dem, *ins, *slope, *noise, *shade;
    const tn_climate *clim;
    tn_season_opts o;
    float pdd[TN__SEASON_LUT], snowfrac[TN__SEASON_LUT], cover[TN__SEASON_LUT];
    float tc[12 * TN__SEASON_SUB], pc[12 * TN__SEASON_SUB]; /* climate per step (station height), mm/day */
    int start;                                                /* first spin-up step */
    int row0;                                                 /* first row of the band being run */
    const float *times;
    int count;
    float ins_sx, ins_sy;                                     /* insolation map pixels per DEM pixel */
    tn_image *out;
    tn_season_state *state;
} tn__season_job;

static float tn__season_lut(const float *lut, float t)
{
    float f = (t + 60.0f) * 20.0f;
    int i;
    if (f <= 0.0f) return lut[0];
    if (f >= (float)(TN__SEASON_LUT - 1)) return lut[TN__SEASON_LUT - 1];
    i = (int)f;
    return lut[i] + (lut[i + 1] - lut[i]) * (f - (float)i);
}

static void tn__season_pixel(const tn__season_job *j, int x, int y, size_t pix)
{
    const int ns = 12 * TN__SEASON_SUB;
    const float dt = 365.0f / (float)ns, relax = 1.0f - expf(-dt / 20.0f), cap = 150.0f;
    float ins[12], hist_swe[12 * TN__SEASON_SUB + 1], hist_g[12 * TN__SEASON_SUB + 1];
    float h = j->dem->data[pix * j->dem->channels], slope = j->slope->data[pix];
    float nz = j->noise ? j->noise->data[pix] - 0.5f : 0.0f;
    float toff = j->o.lapse_rate * (h - j->clim->elevation) + 3.0f * j->o.detail * nz;
    float swe = 0.0f, water = 0.5f * cap, g = 0.0f, twarm = -1e9f, wsum = 0.0f;
    int m, s, i, c;
    {   /* the insolation map may be coarser than the DEM: bilinear */
        float fx = ((float)x + 0.5f) * j->ins_sx - 0.5f, fy = ((float)y + 0.5f) * j->ins_sy - 0.5f;
        int iw = j->ins->width, ih = j->ins->height, x0, y0, x1, y1;
        fx = tn__clampf(fx, 0.0f, (float)(iw - 1));
        fy = tn__clampf(fy, 0.0f, (float)(ih - 1));
        x0 = (int)fx; y0 = (int)fy;
        x1 = x0 + 1 < iw ? x0 + 1 : x0;
        y1 = y0 + 1 < ih ? y0 + 1 : y0;
        fx -= (float)x0; fy -= (float)y0;
        for (m = 0; m < 12; m++) {
            float a = TN_PIXEL(j->ins, x0, y0, m), b = TN_PIXEL(j->ins, x1, y0, m), cc = TN_PIXEL(j->ins, x0, y1, m), d = TN_PIXEL(j->ins, x1, y1, m);
            ins[m] = ((a + (b - a) * fx) * (1.0f - fy) + (cc + (d - cc) * fx) * fy) / 24.0f; /* mean W/m^2 */
        }
    }
    for (m = 0; m < 12; m++) {
        float t = j->clim->t[m] + toff;
        if (t > twarm) twarm = t;
    }
    /* one spin-up year from the step after the warmest month (least snow), then the recorded
       year from mid-January; history[k] is the state at k / SUB months after mid-January */
    {
    const int rec0 = ns + (ns - j->start) % ns; /* first step of the recorded year */
    for (i = 0; i <= rec0 + ns; i++) {
        int k = (j->start + i) % ns, rec = i - rec0;
        int m0 = k / TN__SEASON_SUB;
        float f = (float)(k % TN__SEASON_SUB) / (float)TN__SEASON_SUB;
        float t = j->tc[k] + toff, p = j->pc[k] * dt, ir = ins[m0] + (ins[(m0 + 1) % 12] - ins[m0]) * f;
        float pdd = tn__season_lut(j->pdd, t) * dt, sf = tn__season_lut(j->snowfrac, t);
        float melt = (j->o.melt_factor + j->o.radiation_factor * ir) * pdd, cover, pet, target;
        swe += p * sf;
        if (melt > swe) melt = swe;
        swe -= melt;
        if (swe > 5000.0f) swe = 5000.0f; /* a glacier: no point growing it further */
        cover = swe >= 150.0f ? 1.0f : tn__season_lut(j->cover, swe * 0.4f - 60.0f); /* 1 - exp(-swe / 15), 1 past 150 mm */
        pet = (1.0f - cover) * 0.17f * (t > 0.0f ? t : 0.0f) * dt;
        water = tn__clampf(water + p * (1.0f - sf) + melt - pet, 0.0f, cap);
        target = (1.0f - cover) * tn__smooth(2.0f, 14.0f, t) * tn__smooth(0.0f, 0.5f, water / cap);
        g += (target - g) * relax;
        if (rec >= 0) {
            wsum += water / cap;
            hist_swe[rec] = swe;
            hist_g[rec] = g;
        }
    }
    }
    wsum /= (float)(ns + 1);
    for (c = 0; c < j->count; c++) {
        float tm = fmodf(j->times[c], 12.0f), pos, fr, sw, gr, cover, steep, rock, veg, forest, arid, col[3], lum;
        int k0;
        if (tm < 0.0f) tm += 12.0f;
        pos = tm * (float)TN__SEASON_SUB;
        k0 = (int)pos;
        if (k0 >= ns) k0 = ns - 1;
        fr = pos - (float)k0;
        sw = hist_swe[k0] + (hist_swe[k0 + 1] - hist_swe[k0]) * fr;
        gr = hist_g[k0] + (hist_g[k0 + 1] - hist_g[k0]) * fr;
        steep = 1.0f - tn__smooth(35.0f, 60.0f, slope);           /* snow slides off cliffs */
        cover = (1.0f - expf(-sw / 15.0f)) * (0.15f + 0.85f * steep);
        rock = tn__smooth(j->o.rock_slope - 10.0f, j->o.rock_slope + 10.0f, slope);
        veg = tn__smooth(2.0f, 8.0f, twarm) * tn__smooth(0.05f, 0.4f, wsum);
        forest = tn__smooth(9.0f, 12.0f, twarm) * tn__smooth(0.3f, 0.7f, wsum); /* tree line: warmest month 10 C */
        arid = 1.0f - tn__smooth(0.05f, 0.5f, wsum);
        if (twarm < 2.0f) arid = 0.0f;
        for (s = 0; s < 3; s++) {
            float straw = tn__col_grass[s] + (tn__col_sand[s] - tn__col_grass[s]) * 0.65f;
            float grass = straw + (tn__col_grass[s] - straw) * gr;
            float fgreen = tn__col_grass[s] * 0.5f, fdorm = 0.5f * fgreen + 0.25f * tn__col_soil[s];
            float fcol = fdorm + (fgreen - fdorm) * (0.4f + 0.6f * gr); /* conifers keep some green */
            float vcol = grass + (fcol - grass) * forest;
            float bare = tn__col_soil[s] + (tn__col_sand[s] - tn__col_soil[s]) * arid;
            float v;
            if (twarm < 2.0f) bare = tn__col_rock[s] * 0.85f + tn__col_soil[s] * 0.15f;
            v = bare + (vcol - bare) * veg * (1.0f - rock);
            v += (tn__col_rock[s] - v) * rock;
            v += (tn__col_snow[s] - v) * cover;
            col[s] = v;
        }
        lum = 1.0f + 0.16f * j->o.detail * nz;
        if (j->shade) lum *= 1.0f - j->o.shade + j->o.shade * j->shade->data[pix] / 0.7071f;
        for (s = 0; s < 3; s++) j->out[c].data[pix * 3 + s] = tn__clampf(col[s] * lum, 0.0f, 1.0f);
        if (j->state) {
            j->state[c].snow.data[pix] = sw;
            j->state[c].green.data[pix] = gr;
        }
    }
}

static void tn__season_rows(void *ctx, size_t begin, size_t end)
{
    const tn__season_job *j = (const tn__season_job *)ctx;
    size_t y;
    int x;
    for (y = begin + (size_t)j->row0; y < end + (size_t)j->row0; y++)
        for (x = 0; x < j->dem->width; x++) tn__season_pixel(j, x, (int)y, y * (size_t)j->dem->width + (size_t)x);
}

TN_API void tn_season_state_free(tn_season_state *s)
{
    if (!s) return;
    tn_image_free(&s->snow);
    tn_image_free(&s->green);
}

TN_API tn_status tn_season_texture(tn_image *out, const tn_image *dem, const tn_climate *climate,
                                   double latitude_deg, const tn_image *insolation, const float *times,
                                   int count, const tn_season_opts *opts, tn_season_state *state)
{
    tn__season_job *j = NULL;
    tn_image ins = {0, 0, 0, NULL}, small = {0, 0, 0, NULL}, slope = {0, 0, 0, NULL}, noise = {0, 0, 0, NULL}, shade = {0, 0, 0, NULL};
    tn_status st = TN_OK;
    int i, k, m, made = 0;
    size_t n;
    if (!dem || !climate || !times || !out) return tn__fail(TN_ERR_INVALID_ARG, "season: NULL argument");
    if (!dem->data || dem->width < 2 || dem->height < 2 || dem->channels < 1)
        return tn__fail(TN_ERR_EMPTY, "season: the heightfield must be at least 2 x 2");
    if (count < 1 || count > 10000) return tn__fail(TN_ERR_INVALID_ARG, "season: %d times (1..10000)", count);
    for (i = 0; i < count; i++)
        if (!isfinite(times[i])) return tn__fail(TN_ERR_NUMERIC, "season: time %d is NaN/Inf", i);
    if ((st = tn_climate_check(climate))) return st;
    if (!isfinite(latitude_deg)) {
        if (!climate->has_latitude) return tn__fail(TN_ERR_INVALID_ARG, "season: no latitude (give one, or a climate with a latitude)");
        latitude_deg = climate->latitude;
    }
    if (!(latitude_deg >= -90.0 && latitude_deg <= 90.0)) return tn__fail(TN_ERR_INVALID_ARG, "season: latitude %g is outside -90..90", latitude_deg);
    if (insolation && (insolation->width != dem->width || insolation->height != dem->height || insolation->channels != 12 || !insolation->data))
        return tn__fail(TN_ERR_SHAPE, "season: the insolation must be 12 channels of %d x %d (got %d channels of %d x %d)", dem->width,
                        dem->height, insolation->channels, insolation->width, insolation->height);
    n = (size_t)dem->width * dem->height;
    if (!(j = (tn__season_job *)tn__calloc(sizeof *j))) return tn__oom();
    if (opts) j->o = *opts;
    if (!isfinite(j->o.lapse_rate) || !isfinite(j->o.melt_factor) || !isfinite(j->o.radiation_factor) || !isfinite(j->o.snow_temp) ||
        !isfinite(j->o.rock_slope) || !isfinite(j->o.shade) || !isfinite(j->o.detail) || j->o.shade < 0.0f || j->o.shade > 1.0f ||
        j->o.detail > 1.0f || j->o.rock_slope > 90.0f) {
        st = tn__fail(TN_ERR_INVALID_ARG, "season: options must be finite, shade and detail at most 1, rock slope at most 90");
        goto done;
    }
    tn_season_defaults(&j->o);
    {
        size_t q;
        for (q = 0; q < n; q++)
            if (!isfinite(dem->data[q * dem->channels])) { st = tn__fail(TN_ERR_NUMERIC, "season: NaN/Inf height at pixel %zu", q); goto done; }
    }
    if (!insolation) {
        /* shadows and aspect at up to 1024 px: beyond that the year's insolation costs more than
           the texture, and snow patterns follow slopes larger than a few pixels */
        tn_insolation_opts io = j->o.insolation;
        int side = dem->width > dem->height ? dem->width : dem->height;
        io.month = 0;
        if (side > 1024) {
            int w = (int)((double)dem->width * 1024 / side + 0.5), h = (int)((double)dem->height * 1024 / side + 0.5);
            if (w < 2) w = 2;
            if (h < 2) h = 2;
            if ((st = tn_image_resize(&small, dem, w, h, TN_RESIZE_AREA))) goto done;
            io.dx = j->o.insolation.dx * (float)dem->width / (float)w;
            io.dy = j->o.insolation.dy * (float)dem->height / (float)h;
            st = tn_insolation(&ins, &small, latitude_deg, &io);
        } else st = tn_insolation(&ins, dem, latitude_deg, &io);
        if (st) goto done;
        insolation = &ins;
    }
    j->ins = insolation;
    j->ins_sx = (float)insolation->width / (float)dem->width;
    j->ins_sy = (float)insolation->height / (float)dem->height;
    if ((st = tn_image_slope(&slope, dem, j->o.insolation.dx, j->o.insolation.dy))) goto done;
    if (j->o.detail > 0.0f) {
        tn_perlin_opts po;
        memset(&po, 0, sizeof po);
        po.seed = j->o.seed;
        po.octaves = 5;
        po.frequency = (float)(dem->width > 32 ? dem->width / 16 : 2);
        if ((st = tn_noise_perlin(&noise, dem->width, dem->height, &po))) goto done;
        j->noise = &noise;
    }
    if (j->o.shade > 0.0f) {
        tn_hillshade_opts ho;
        memset(&ho, 0, sizeof ho);
        ho.dx = j->o.insolation.dx;
        ho.dy = j->o.insolation.dy;
        if ((st = tn_image_hillshade(&shade, dem, &ho))) goto done;
        j->shade = &shade;
    }
    /* tables of the expected positive degree-days and snow share per day for a month mean t,
       daily temperatures spread normally with 4 C (Calov & Greve 2005) */
    for (i = 0; i < TN__SEASON_LUT; i++) {
        double t = -60.0 + i * 0.05, sig = 4.0, z = t / sig;
        j->pdd[i] = (float)(sig * exp(-0.5 * z * z) / sqrt(2.0 * TN__SEASON_PI) + t * 0.5 * (1.0 + erf(z / sqrt(2.0))));
        j->snowfrac[i] = (float)(0.5 * (1.0 + erf((j->o.snow_temp - t) / (sig * sqrt(2.0)))));
        j->cover[i] = (float)(1.0 - exp(-(i * 0.125) / 15.0)); /* snow cover of 0..300 mm SWE in 1/8 mm steps */
    }
    /* the climate per model step: linear between mid-month values, cyclic */
    {
        int wm = 0;
        for (k = 0; k < 12 * TN__SEASON_SUB; k++) {
            int m0 = k / TN__SEASON_SUB, m1 = (m0 + 1) % 12;
            float f = (float)(k % TN__SEASON_SUB) / (float)TN__SEASON_SUB;
            j->tc[k] = climate->t[m0] + (climate->t[m1] - climate->t[m0]) * f;
            j->pc[k] = (climate->p[m0] + (climate->p[m1] - climate->p[m0]) * f) * 12.0f / 365.0f;
        }
        for (m = 1; m < 12; m++)
            if (climate->t[m] > climate->t[wm]) wm = m;
        j->start = ((wm + 1) % 12) * TN__SEASON_SUB;
    }
    j->dem = dem;
    j->slope = &slope;
    j->clim = climate;
    j->times = times;
    j->count = count;
    j->out = out;
    j->state = state;
    for (made = 0; made < count; made++) {
        if ((st = tn_image_create(&out[made], dem->width, dem->height, 3))) goto done;
        if (state) {
            memset(&state[made], 0, sizeof state[made]);
            if ((st = tn_image_create(&state[made].snow, dem->width, dem->height, 1)) ||
                (st = tn_image_create(&state[made].green, dem->width, dem->height, 1))) { made++; goto done; }
        }
    }
    for (j->row0 = 0; j->row0 < dem->height; j->row0 += 32) {
        int y1 = j->row0 + 32 < dem->height ? j->row0 + 32 : dem->height;
        tn_parallel_for((size_t)(y1 - j->row0), 1, tn__season_rows, j);
        if ((st = tn__progress("season", (double)y1 / dem->height))) goto done;
    }
done:
    if (st) for (i = 0; i < made; i++) {
        tn_image_free(&out[i]);
        if (state) tn_season_state_free(&state[i]);
    }
    tn_image_free(&ins);
    tn_image_free(&small);
    tn_image_free(&slope);
    tn_image_free(&noise);
    tn_image_free(&shade);
    TN_FREE(j);
    return st;
}

/* A 5 x 7 pixel font for sheet captions: each glyph is 7 rows of 5 bits (bit 4 = left). */
static const char tn__font_chars[] = "ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789-/.:%";
static const unsigned char tn__font_rows[][7] = {
    {14, 17, 17, 31, 17, 17, 17}, {30, 17, 17, 30, 17, 17, 30}, {14, 17, 16, 16, 16, 17, 14}, {30, 17, 17, 17, 17, 17, 30},
    {31, 16, 16, 30, 16, 16, 31}, {31, 16, 16, 30, 16, 16, 16}, {14, 17, 16, 23, 17, 17, 15}, {17, 17, 17, 31, 17, 17, 17},
    {14, 4, 4, 4, 4, 4, 14},      {7, 2, 2, 2, 2, 18, 12},      {17, 18, 20, 24, 20, 18, 17}, {16, 16, 16, 16, 16, 16, 31},
    {17, 27, 21, 21, 17, 17, 17}, {17, 17, 25, 21, 19, 17, 17}, {14, 17, 17, 17, 17, 17, 14}, {30, 17, 17, 30, 16, 16, 16},
    {14, 17, 17, 17, 21, 18, 13}, {30, 17, 17, 30, 20, 18, 17}, {15, 16, 16, 14, 1, 1, 30},   {31, 4, 4, 4, 4, 4, 4},
    {17, 17, 17, 17, 17, 17, 14}, {17, 17, 17, 17, 17, 10, 4},  {17, 17, 17, 21, 21, 21, 10}, {17, 17, 10, 4, 10, 17, 17},
    {17, 17, 10, 4, 4, 4, 4},     {31, 1, 2, 4, 8, 16, 31},     {14, 17, 19, 21, 25, 17, 14}, {4, 12, 4, 4, 4, 4, 14},
    {14, 17, 1, 2, 4, 8, 31},     {31, 2, 4, 2, 1, 17, 14},     {2, 6, 10, 18, 31, 2, 2},     {31, 16, 30, 1, 1, 17, 14},
    {6, 8, 16, 30, 17, 17, 14},   {31, 1, 2, 4, 8, 8, 8},       {14, 17, 17, 14, 17, 17, 14}, {14, 17, 17, 15, 1, 2, 12},
    {0, 0, 0, 31, 0, 0, 0},       {1, 1, 2, 4, 8, 16, 16},      {0, 0, 0, 0, 0, 12, 12},      {0, 12, 12, 0, 12, 12, 0},
    {24, 25, 2, 4, 8, 19, 3}};

/* Draws text in dark grey at (x0, y0), each font pixel scale x scale, clipped to img. */
static void tn__draw_text(tn_image *img, int x0, int y0, int scale, const char *text)
{
    int k, r, b, u, v, c;
    for (k = 0; text[k]; k++) {
        int ch = text[k] >= 'a' && text[k] <= 'z' ? text[k] - 32 : text[k];
        const char *at = ch ? strchr(tn__font_chars, ch) : NULL;
        if (!at) continue; /* a blank */
        for (r = 0; r < 7; r++)
            for (b = 0; b < 5; b++)
                if (tn__font_rows[at - tn__font_chars][r] & (16 >> b))
                    for (v = 0; v < scale; v++)
                        for (u = 0; u < scale; u++) {
                            int x = x0 + (6 * k + b) * scale + u, y = y0 + r * scale + v;
                            if (x >= 0 && y >= 0 && x < img->width && y < img->height)
                                for (c = 0; c < img->channels; c++) TN_PIXEL(img, x, y, c) = 0.15f;
                        }
    }
}

TN_API char *tn_season_time_label(char *buf, size_t size, float time)
{
    static const char *const names[12] = {"JAN", "FEB", "MAR", "APR", "MAY", "JUN", "JUL", "AUG", "SEP", "OCT", "NOV", "DEC"};
    static const int days[12] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
    double t = isfinite(time) ? fmod((double)time, 12.0) : 0.0, day;
    int m = 0;
    if (!buf || !size) return buf;
    if (t < 0) t += 12.0;
    if (fabs(t - floor(t + 0.5)) < 0.02) { /* a month's 15th: its name */
        snprintf(buf, size, "%s", names[(int)floor(t + 0.5) % 12]);
        return buf;
    }
    day = 15.0 + t * 365.0 / 12.0; /* days from the 1st of January */
    while (day >= days[m]) {
        day -= days[m];
        m = (m + 1) % 12;
    }
    snprintf(buf, size, "%s %d", names[m], (int)day + 1);
    return buf;
}

TN_API tn_status tn_season_sheet(tn_image *out, const tn_image *images, int count, int columns, int cell)
{
    return tn_season_sheet_labelled(out, images, NULL, count, columns, cell);
}

TN_API tn_status tn_season_sheet_labelled(tn_image *out, const tn_image *images, const char *const *labels, int count, int columns,
                                          int cell)
{
    tn_image sheet = {0, 0, 0, NULL}, tmp = {0, 0, 0, NULL};
    int i, rows, ch = 0, gap = 4, x, y, c, scale = 2, top = 0;
    tn_status st = TN_OK;
    if (!images || !out || count < 1) return tn__fail(TN_ERR_INVALID_ARG, "season sheet: no images");
    if (columns < 0 || cell < 0 || cell > 8192) return tn__fail(TN_ERR_INVALID_ARG, "season sheet: bad columns %d or cell %d", columns, cell);
    if (!columns) columns = 4;
    if (!cell) cell = 256;
    if (columns > count) columns = count;
    for (i = 0; i < count; i++) {
        int h;
        if (!images[i].data || images[i].width < 1 || images[i].height < 1 || (images[i].channels != 1 && images[i].channels != 3))
            return tn__fail(TN_ERR_SHAPE, "season sheet: image %d is empty or not 1 or 3 channels", i);
        h = (int)((double)images[i].height * cell / images[i].width + 0.5);
        if (h < 1) h = 1;
        if (h > ch) ch = h;
        if (labels && labels[i] && labels[i][0]) top = 7 * scale + 6; /* a caption strip over every image */
    }
    if (cell < 96) scale = 1, top = top ? 7 + 4 : 0;
    rows = (count + columns - 1) / columns;
    if ((st = tn_image_create(&sheet, columns * cell + (columns + 1) * gap, rows * (ch + top) + (rows + 1) * gap, 3))) return st;
    for (i = 0; i < (int)((size_t)sheet.width * sheet.height * 3); i++) sheet.data[i] = 1.0f;
    for (i = 0; i < count; i++) {
        int h = (int)((double)images[i].height * cell / images[i].width + 0.5), ox = gap + (i % columns) * (cell + gap),
            oy = gap + (i / columns) * (ch + top + gap) + top;
        if (labels && labels[i]) tn__draw_text(&sheet, ox, oy - top + (top - 7 * scale) / 2, scale, labels[i]);
        if (h < 1) h = 1;
        if ((st = tn_image_resize(&tmp, &images[i], cell, h, cell < images[i].width ? TN_RESIZE_AREA : TN_RESIZE_BILINEAR))) goto done;
        for (y = 0; y < h; y++)
            for (x = 0; x < cell; x++)
                for (c = 0; c < 3; c++) TN_PIXEL(&sheet, ox + x, oy + y, c) = TN_PIXEL(&tmp, x, y, tmp.channels == 3 ? c : 0);
        tn_image_free(&tmp);
    }
    *out = sheet;
    sheet.data = NULL;
done:
    tn_image_free(&tmp);
    tn_image_free(&sheet);
    return st;
}

/* ---- KPD generator (paper 003, 3.1-3.2) ---- */

#define TN__KPD_FORMAT 1
#define TN__KPD_CONFIG 12 /* format, condition, cond/out channels, width, lo, hi, lapse, h offset/scale, g scale, spare */

static const char *const tn__kpd_names[TN_KPD_CONDITIONS] = {"ours", "cond1", "cond2", "cond3", "cond4"};

TN_API const char *tn_kpd_condition_name(tn_kpd_condition c)
{
    return (int)c >= 0 && c < TN_KPD_CONDITIONS ? tn__kpd_names[c] : "unknown";
}

TN_API tn_status tn_kpd_condition_parse(tn_kpd_condition *out, const char *s)
{
    int i;
    if (!s || !out) return tn__fail(TN_ERR_INVALID_ARG, "kpd: NULL condition");
    for (i = 0; i < TN_KPD_CONDITIONS; i++)
        if (tn__io_token_is(s, strlen(s), tn__kpd_names[i]) || (i > 0 && s[0] == '0' + i && !s[1])) {
            *out = (tn_kpd_condition)i;
            return TN_OK;
        }
    return tn__fail(TN_ERR_INVALID_ARG, "kpd: unknown condition \"%s\" (ours, cond1, cond2, cond3, cond4)", s);
}

/* Conditioning channels: height, its x and y gradient, then the condition's climate maps. */
static int tn__kpd_cond_channels(tn_kpd_condition c)
{
    static const int extra[TN_KPD_CONDITIONS] = {36, 25, 2, 2, 24};
    return 3 + extra[c];
}

TN_API void tn_kpd_defaults(tn_kpd_opts *o)
{
    if (o->width <= 0) o->width = 32;
    if (o->crop <= 0) o->crop = 64;
    if (o->batch <= 0) o->batch = 4;
    if (o->lr == 0) o->lr = 2e-4f;
    if (o->l1_weight == 0) o->l1_weight = 10.0f;
    if (o->fm_weight == 0) o->fm_weight = 10.0f;
    if (o->gan_weight == 0) o->gan_weight = 1.0f;
    if (o->lo == 0 && o->hi == 0) o->hi = 1.0f;
    if (o->lapse_rate == 0) o->lapse_rate = -0.006f;
    tn_train_defaults(&o->train, 10.0);
}

/* The rules of tn_kpd_opts after tn_kpd_defaults, one message each. */
static tn_status tn__kpd_validate(const tn_kpd_opts *o)
{
    const char *w = "season-train";
    tn_status st;
    if ((st = tn__opt_int(w, "condition", (int)o->condition, 0, TN_KPD_CONDITIONS - 1)) || (st = tn__opt_int(w, "width", o->width, 4, 256)) ||
        (st = tn__opt_int(w, "crop", o->crop, 16, INT_MAX)))
        return st;
    if (o->crop & 7) return tn__fail(TN_ERR_INVALID_ARG, "season-train: option crop = %d, allowed a multiple of 8", o->crop);
    if ((st = tn__opt_int(w, "batch", o->batch, 1, 64)) || (st = tn__opt_float(w, "lr", o->lr, "()", 0, 10)) ||
        (st = tn__opt_float(w, "l1_weight", o->l1_weight, "()", -HUGE_VAL, HUGE_VAL)) ||
        (st = tn__opt_float(w, "fm_weight", o->fm_weight, "()", -HUGE_VAL, HUGE_VAL)) ||
        (st = tn__opt_float(w, "gan_weight", o->gan_weight, "()", -HUGE_VAL, HUGE_VAL)) ||
        (st = tn__opt_float(w, "lapse_rate", o->lapse_rate, "()", -HUGE_VAL, HUGE_VAL)))
        return st;
    if (!(o->hi > o->lo) || !isfinite(o->hi - o->lo))
        return tn__fail(TN_ERR_INVALID_ARG, "season-train: options lo = %g, hi = %g, allowed finite with lo < hi", (double)o->lo, (double)o->hi);
    if (o->l1_weight < 0 && o->gan_weight < 0)
        return tn__fail(TN_ERR_INVALID_ARG, "season-train: options l1_weight and gan_weight both < 0 (off), allowed at most one off");
    return TN_OK;
}

/* The conditioning maps of the window (wx, wy, ww, wh) for month m (0..11) into dst (C x wh x
   ww). Outside the DEM the nearest edge pixel stands in (maps are padded to a multiple of 4). */
static void tn__kpd_cond(const tn_kpd *A, const tn_image *dem, const tn_climate *c, const tn_image *ins, int m, int wx, int wy,
                         int ww, int wh, float *dst)
{
    int W = dem->width, H = dem->height, x, y, k, ch = 0;
    size_t plane = (size_t)ww * wh;
    const float *hd = dem->data;
    int dc = dem->channels;
#define TN__KPD_H(xx, yy) hd[((size_t)tn__clampi(yy, 0, H - 1) * W + tn__clampi(xx, 0, W - 1)) * dc]
    for (y = 0; y < wh; y++)
        for (x = 0; x < ww; x++) {
            int gx = wx + x, gy = wy + y;
            size_t i = (size_t)y * ww + x;
            float h = TN__KPD_H(gx, gy);
            dst[i] = (h - A->h_offset) / A->h_scale;
            dst[plane + i] = 0.5f * (TN__KPD_H(gx + 1, gy) - TN__KPD_H(gx - 1, gy)) / A->g_scale;
            dst[2 * plane + i] = 0.5f * (TN__KPD_H(gx, gy + 1) - TN__KPD_H(gx, gy - 1)) / A->g_scale;
        }
    ch = 3;
    for (k = 0; k < 12; k++) { /* temperature maps */
        int mk;
        if (A->condition == TN_KPD_COND3) break;
        if (A->condition == TN_KPD_COND2 && k > 0) break;
        mk = A->condition == TN_KPD_COND1 ? k : (m + k) % 12;
        for (y = 0; y < wh; y++)
            for (x = 0; x < ww; x++)
                dst[ch * plane + (size_t)y * ww + x] =
                    (tn_climate_temperature(c, mk, TN__KPD_H(wx + x, wy + y), A->lapse_rate) - 10.0f) / 15.0f;
        ch++;
    }
    for (k = 0; k < 12; k++) { /* precipitation: constant maps */
        int mk;
        size_t i;
        if (A->condition == TN_KPD_COND3) break;
        if (A->condition == TN_KPD_COND2 && k > 0) break;
        mk = A->condition == TN_KPD_COND1 ? k : (m + k) % 12;
        for (i = 0; i < plane; i++) dst[ch * plane + i] = c->p[mk] / 100.0f - 1.0f;
        ch++;
    }
    if (A->condition == TN_KPD_OURS)
        for (k = 0; k < 12; k++, ch++) {
            int mk = (m + k) % 12;
            for (y = 0; y < wh; y++)
                for (x = 0; x < ww; x++) {
                    size_t s = ((size_t)tn__clampi(wy + y, 0, H - 1) * W + tn__clampi(wx + x, 0, W - 1)) * 12 + mk;
                    dst[ch * plane + (size_t)y * ww + x] = ins->data[s] / 5000.0f - 1.0f;
                }
        }
    if (A->condition == TN_KPD_COND3) {
        size_t i;
        for (i = 0; i < plane; i++) dst[ch * plane + i] = c->latitude / 90.0f;
        ch++;
    }
    if (A->condition == TN_KPD_COND1 || A->condition == TN_KPD_COND3) {
        size_t i;
        for (i = 0; i < plane; i++) dst[ch * plane + i] = (float)(m + 1) / 12.0f;
        ch++;
    }
#undef TN__KPD_H
    TN_ASSERT(ch == A->cond_channels);
}

static void tn__kpd_write_config(const tn_kpd *A, float *c)
{
    c[0] = TN__KPD_FORMAT;
    c[1] = (float)A->condition;
    c[2] = (float)A->cond_channels;
    c[3] = (float)A->out_channels;
    c[4] = (float)A->width;
    c[5] = A->lo;
    c[6] = A->hi;
    c[7] = A->lapse_rate;
    c[8] = A->h_offset;
    c[9] = A->h_scale;
    c[10] = A->g_scale;
    c[11] = 0;
}

static tn_status tn__kpd_read_config(const float *c, tn_kpd *A, const char *name)
{
    int i;
    for (i = 0; i < TN__KPD_CONFIG; i++)
        if (!isfinite(c[i])) return tn__fail(TN_ERR_CORRUPT, "%s: NaN/Inf in kpd.config", name);
    if (c[0] != TN__KPD_FORMAT || !(c[1] >= 0 && c[1] < TN_KPD_CONDITIONS) || c[1] != floor(c[1]) || !(c[3] >= 1 && c[3] <= 16) ||
        c[3] != floor(c[3]) || !(c[4] >= 4 && c[4] <= 256) || c[4] != floor(c[4]) || !(c[6] > c[5]) || !isfinite(c[6] - c[5]) ||
        !(c[9] > 0) || !(c[10] > 0))
        return tn__fail(TN_ERR_CORRUPT, "%s: damaged kpd.config", name);
    A->condition = (tn_kpd_condition)(int)c[1];
    A->cond_channels = tn__kpd_cond_channels(A->condition);
    if (c[2] != (float)A->cond_channels) return tn__fail(TN_ERR_CORRUPT, "%s: kpd.config has %g conditioning channels, not %d", name, (double)c[2], A->cond_channels);
    A->out_channels = (int)c[3];
    A->width = (int)c[4];
    A->lo = c[5];
    A->hi = c[6];
    A->lapse_rate = c[7];
    A->h_offset = c[8];
    A->h_scale = c[9];
    A->g_scale = c[10];
    return TN_OK;
}

/* ---- the generator ---- */

static tn_status tn__kpd_conv_add(tn_params *p, const char *name, int cin, int cout, int k, int bias, tn_rng *rng)
{
    int ws[4];
    tn_tensor *w;
    ws[0] = cout;
    ws[1] = cin;
    ws[2] = ws[3] = k;
    if (!(w = tn__param_new(p, name, "w", -1, 4, ws, 1)) || (bias && !tn__param_new(p, name, "b", -1, 1, &cout, 1))) return tn__oom();
    if (rng) tn_init_kaiming(w, rng, 1.0f);
    return TN_OK;
}

static tn_tensor *tn__kpd_conv(tn_ctx *ctx, const tn_params *p, const char *name, tn_tensor *x)
{
    tn_tensor *w = tn__param_named(p, name, "w", -1);
    tn_conv_opts co;
    memset(&co, 0, sizeof co);
    co.pad = w->shape[2] / 2;
    return tn_conv2d(ctx, x, w, tn__param_named(p, name, "b", -1), &co);
}

/* A KPD block on c channels: shared 3 x 3 conv of the conditioning (ReLU), gamma and beta convs. */
static tn_status tn__kpd_block_add(tn_params *p, const char *pre, int cond, int c, tn_rng *rng)
{
    char n[48];
    tn_status st;
    snprintf(n, sizeof n, "%ss.", pre);
    if ((st = tn__kpd_conv_add(p, n, cond, c, 3, 1, rng))) return st;
    snprintf(n, sizeof n, "%sg.", pre);
    if ((st = tn__kpd_conv_add(p, n, c, c, 3, 1, rng))) return st;
    snprintf(n, sizeof n, "%sb.", pre);
    return tn__kpd_conv_add(p, n, c, c, 3, 1, rng);
}

/* Conditioning of one level: this month's, and the next month's with its weight (N x 1 x 1 x 1)
   when the time lies between two months (c1 NULL otherwise). */
typedef struct tn__kpd_level { tn_tensor *c0, *c1, *f; } tn__kpd_level;

/* Positional normalisation: each pixel's features to zero mean and unit variance over channels. */
static tn_tensor *tn__kpd_pono(tn_ctx *ctx, tn_tensor *x)
{
    tn_tensor *xc = tn_sub(ctx, x, tn_mean_axis(ctx, x, 1));
    return tn_div(ctx, xc, tn_pow_abs(ctx, tn_scale_shift(ctx, tn_mean_axis(ctx, tn_square(ctx, xc), 1), 1.0f, 1e-5f), 0.5f));
}

static void tn__kpd_gb(tn_ctx *ctx, const tn_params *p, const char *pre, tn_tensor *c, tn_tensor **g, tn_tensor **b)
{
    char n[48];
    tn_tensor *a;
    snprintf(n, sizeof n, "%ss.", pre);
    a = tn_relu(ctx, tn__kpd_conv(ctx, p, n, c));
    snprintf(n, sizeof n, "%sg.", pre);
    *g = tn__kpd_conv(ctx, p, n, a);
    snprintf(n, sizeof n, "%sb.", pre);
    *b = tn__kpd_conv(ctx, p, n, a);
}

/* norm(x) (1 + gamma) + beta, gamma and beta interpolated between the two months (Eq. 1). */
static tn_tensor *tn__kpd_block(tn_ctx *ctx, const tn_params *p, const char *pre, tn_tensor *x, const tn__kpd_level *L)
{
    tn_tensor *g, *b;
    tn__kpd_gb(ctx, p, pre, L->c0, &g, &b);
    if (L->c1) {
        tn_tensor *g1, *b1;
        tn__kpd_gb(ctx, p, pre, L->c1, &g1, &b1);
        g = tn_add(ctx, g, tn_mul(ctx, tn_sub(ctx, g1, g), L->f));
        b = tn_add(ctx, b, tn_mul(ctx, tn_sub(ctx, b1, b), L->f));
    }
    return tn_add(ctx, tn_mul(ctx, tn__kpd_pono(ctx, x), tn_scale_shift(ctx, g, 1.0f, 1.0f)), b);
}

static tn_status tn__kpd_resblk_add(tn_params *p, const char *pre, int cond, int cin, int cout, tn_rng *rng)
{
    char n[48];
    int cm = cin < cout ? cin : cout;
    tn_status st;
    snprintf(n, sizeof n, "%sk0.", pre);
    if ((st = tn__kpd_block_add(p, n, cond, cin, rng))) return st;
    snprintf(n, sizeof n, "%sc0.", pre);
    if ((st = tn__kpd_conv_add(p, n, cin, cm, 3, 1, rng))) return st;
    snprintf(n, sizeof n, "%sk1.", pre);
    if ((st = tn__kpd_block_add(p, n, cond, cm, rng))) return st;
    snprintf(n, sizeof n, "%sc1.", pre);
    if ((st = tn__kpd_conv_add(p, n, cm, cout, 3, 1, rng))) return st;
    if (cin == cout) return TN_OK;
    snprintf(n, sizeof n, "%sks.", pre);
    if ((st = tn__kpd_block_add(p, n, cond, cin, rng))) return st;
    snprintf(n, sizeof n, "%scs.", pre);
    return tn__kpd_conv_add(p, n, cin, cout, 1, 0, rng);
}

/* SPADE ResBlk with KPD blocks: two (KPD, leaky ReLU, conv) steps, a learned shortcut when the
   width changes. */
static tn_tensor *tn__kpd_resblk(tn_ctx *ctx, const tn_params *p, const char *pre, tn_tensor *x, const tn__kpd_level *L)
{
    char n[48];
    tn_tensor *h, *s = x;
    snprintf(n, sizeof n, "%sk0.", pre);
    h = tn_leaky_relu(ctx, tn__kpd_block(ctx, p, n, x, L), 0.2f);
    snprintf(n, sizeof n, "%sc0.", pre);
    h = tn__kpd_conv(ctx, p, n, h);
    snprintf(n, sizeof n, "%sk1.", pre);
    h = tn_leaky_relu(ctx, tn__kpd_block(ctx, p, n, h, L), 0.2f);
    snprintf(n, sizeof n, "%sc1.", pre);
    h = tn__kpd_conv(ctx, p, n, h);
    snprintf(n, sizeof n, "%scs.w", pre);
    if (tn_params_find(p, n)) {
        snprintf(n, sizeof n, "%sks.", pre);
        s = tn_leaky_relu(ctx, tn__kpd_block(ctx, p, n, x, L), 0.2f);
        snprintf(n, sizeof n, "%scs.", pre);
        s = tn__kpd_conv(ctx, p, n, s);
    }
    return tn_add(ctx, s, h);
}

static tn_status tn__kpd_model_params(const tn_kpd *A, tn_rng *rng, tn_params **out)
{
    tn_params *p = tn_params_create();
    int W = A->width, W2 = A->width / 2, C = A->cond_channels, n = TN__KPD_CONFIG;
    tn_status st;
    *out = NULL;
    if (!p || !tn_params_add_buffer(p, "kpd.config", 1, &n)) {
        tn_params_free(p);
        return tn__oom();
    }
    if ((st = tn__kpd_conv_add(p, "in.", C, W, 3, 1, rng)) || (st = tn__kpd_resblk_add(p, "r0.", C, W, W, rng)) ||
        (st = tn__kpd_resblk_add(p, "r1.", C, W, W2, rng)) || (st = tn__kpd_resblk_add(p, "r2.", C, W2, W2, rng)) ||
        (st = tn__kpd_conv_add(p, "out.", W2, A->out_channels, 3, 1, rng))) {
        tn_params_free(p);
        return st;
    }
    if (rng) { /* start near a flat mid-grey: small output weights */
        tn_tensor *w = tn_params_find(p, "out.w");
        size_t i;
        for (i = 0; i < w->numel; i++) w->data[i] *= 0.1f;
    }
    tn__kpd_write_config(A, tn_params_find(p, "kpd.config")->data);
    *out = p;
    return TN_OK;
}

/* Whether a model file or a checkpoint holds the generator its config names: the input and
   output convolutions fix its width and outputs, checked on the file's own tensors before the
   model is allocated. */
static tn_status tn__kpd_file_matches(const tn_params *f, const tn_kpd *A, const char *name)
{
    int in[4], out[4];
    in[0] = A->width;
    in[1] = A->cond_channels;
    out[0] = A->out_channels;
    out[1] = A->width / 2;
    in[2] = in[3] = out[2] = out[3] = 3;
    if (!tn__params_has(f, "in.w", 4, in) || !tn__params_has(f, "out.w", 4, out))
        return tn__fail(TN_ERR_CORRUPT, "%s: the kpd config names a generator %d wide with %d outputs; the file's differs", name, A->width,
                        A->out_channels);
    return TN_OK;
}

/* The generator on N windows (sides multiples of 4): cond0/cond1 are N x C x H x W (cond1 and f
   NULL when no window lies between months). Output N x out x H x W in [-1, 1]. */
static tn_tensor *tn__kpd_forward(tn_ctx *ctx, const tn_params *p, tn_tensor *cond0, tn_tensor *cond1, tn_tensor *f)
{
    tn__kpd_level L[3];
    tn_tensor *x;
    L[0].c0 = cond0;
    L[0].c1 = cond1;
    L[0].f = L[1].f = L[2].f = f;
    L[1].c0 = tn_avg_pool2d(ctx, cond0, 2, 2);
    L[1].c1 = cond1 ? tn_avg_pool2d(ctx, cond1, 2, 2) : NULL;
    L[2].c0 = tn_avg_pool2d(ctx, L[1].c0, 2, 2);
    L[2].c1 = cond1 ? tn_avg_pool2d(ctx, L[1].c1, 2, 2) : NULL;
    x = tn__kpd_conv(ctx, p, "in.", L[2].c0);
    if (cond1) { /* the input conv is interpolated like the blocks */
        tn_tensor *x1 = tn__kpd_conv(ctx, p, "in.", L[2].c1);
        x = tn_add(ctx, x, tn_mul(ctx, tn_sub(ctx, x1, x), f));
    }
    x = tn__kpd_resblk(ctx, p, "r0.", x, &L[2]);
    x = tn__kpd_resblk(ctx, p, "r1.", tn_upsample_nearest(ctx, x, 2), &L[1]);
    x = tn__kpd_resblk(ctx, p, "r2.", tn_upsample_nearest(ctx, x, 2), &L[0]);
    return tn_tanh(ctx, tn__kpd_conv(ctx, p, "out.", tn_leaky_relu(ctx, x, 0.2f)));
}

/* Months from mid-January -> month index m0 (0..11) and the weight of the next month. */
static void tn__kpd_months(float time, int *m0, float *f)
{
    double t = fmod((double)time, 12.0), fl;
    if (t < 0) t += 12.0;
    fl = floor(t);
    *m0 = (int)fl % 12;
    *f = (float)(t - fl);
    if (*f < 1e-6f) *f = 0.0f;
}

/* ---- training ---- */

typedef struct tn__kpd_train {
    tn_kpd A;
    tn_kpd_opts o;
    const tn_season_sample *s;
    int count;
    tn_params *g, *d;
    tn_optim *og, *od;
    tn_patch_disc disc;
    tn_train *run;
    tn_rng rng;
    float *c0, *c1, *f, *real, *mask, *fake; /* the batch */
    int any_between;
} tn__kpd_train;

static tn_status tn__kpd_check_samples(const tn_season_sample *s, int count, tn_kpd_condition cond, int *channels)
{
    int i;
    if (!s || count < 1) return tn__fail(TN_ERR_EMPTY, "season-train: no training pictures");
    for (i = 0; i < count; i++) {
        const tn_season_sample *q = &s[i];
        size_t k, n;
        tn_status st;
        if (!q->dem || !q->dem->data || !q->target || !q->target->data || !q->climate)
            return tn__fail(TN_ERR_INVALID_ARG, "season-train: picture %d has no DEM, target or climate", i);
        if (q->target->width != q->dem->width || q->target->height != q->dem->height)
            return tn__fail(TN_ERR_SHAPE, "season-train: picture %d is %d x %d, its DEM %d x %d", i, q->target->width, q->target->height,
                            q->dem->width, q->dem->height);
        if (q->target->channels != s[0].target->channels)
            return tn__fail(TN_ERR_SHAPE, "season-train: picture %d has %d channels, picture 0 %d", i, q->target->channels, s[0].target->channels);
        if (q->mask && (q->mask->width != q->dem->width || q->mask->height != q->dem->height || q->mask->channels != 1))
            return tn__fail(TN_ERR_SHAPE, "season-train: the mask of picture %d is %d x %d x %d, not %d x %d x 1", i, q->mask->width,
                            q->mask->height, q->mask->channels, q->dem->width, q->dem->height);
        if (cond == TN_KPD_OURS && (!q->insolation || q->insolation->width != q->dem->width || q->insolation->height != q->dem->height ||
                                    q->insolation->channels != 12))
            return tn__fail(TN_ERR_SHAPE, "season-train: picture %d needs its DEM's 12-month insolation", i);
        if (cond == TN_KPD_COND3 && !q->climate->has_latitude) return tn__fail(TN_ERR_INVALID_ARG, "season-train: picture %d's climate has no latitude", i);
        if (!isfinite(q->time)) return tn__fail(TN_ERR_NUMERIC, "season-train: picture %d has a NaN time", i);
        if ((st = tn_climate_check(q->climate))) return st;
        n = (size_t)q->dem->width * q->dem->height;
        for (k = 0; k < n; k++) {
            int c, valid = !q->mask || q->mask->data[k] > 0.5f;
            if (!isfinite(q->dem->data[k * q->dem->channels])) return tn__fail(TN_ERR_NUMERIC, "season-train: picture %d's DEM has NaN/Inf heights", i);
            if (q->insolation && cond == TN_KPD_OURS)
                for (c = 0; c < 12; c++)
                    if (!isfinite(q->insolation->data[k * 12 + c])) return tn__fail(TN_ERR_NUMERIC, "season-train: picture %d's insolation has NaN/Inf", i);
            for (c = 0; valid && c < q->target->channels; c++)
                if (!isfinite(q->target->data[k * q->target->channels + c]))
                    return tn__fail(TN_ERR_NUMERIC, "season-train: picture %d has NaN/Inf at an unmasked pixel (%zu, %zu)", i, k % q->dem->width,
                                    k / q->dem->width);
        }
    }
    *channels = s[0].target->channels;
    return TN_OK;
}

/* Height and gradient scales of the training DEMs (each distinct DEM once). */
static void tn__kpd_scales(const tn_season_sample *s, int count, tn_kpd *A)
{
    double sh = 0, shh = 0, sg = 0, n = 0, ng = 0;
    int i, j;
    for (i = 0; i < count; i++) {
        const tn_image *d = s[i].dem;
        int x, y;
        for (j = 0; j < i && s[j].dem != d; j++) {}
        if (j < i) continue;
        for (y = 0; y < d->height; y++)
            for (x = 0; x < d->width; x++) {
                double h = d->data[((size_t)y * d->width + x) * d->channels];
                sh += h;
                shh += h * h;
                n++;
                if (x + 1 < d->width) {
                    double g = d->data[((size_t)y * d->width + x + 1) * d->channels] - h;
                    sg += g * g;
                    ng++;
                }
            }
    }
    A->h_offset = (float)(sh / n);
    A->h_scale = (float)sqrt(shh / n - (sh / n) * (sh / n));
    if (!(A->h_scale >= 1.0f)) A->h_scale = 1.0f;
    A->g_scale = ng > 0 ? (float)sqrt(sg / ng) : 1.0f;
    if (!(A->g_scale >= 0.01f)) A->g_scale = 0.01f;
}

/* One batch: random windows with at least a quarter of valid pixels (a few tries each). */
static void tn__kpd_batch(tn__kpd_train *t)
{
    int b, N = t->o.batch, S = t->o.crop, C = t->A.cond_channels, O = t->A.out_channels;
    size_t plane = (size_t)S * S;
    t->any_between = 0;
    for (b = 0; b < N; b++) {
        const tn_season_sample *q = NULL;
        int x0 = 0, y0 = 0, tries, x, y, c, m0;
        float f, best = -1;
        for (tries = 0; tries < 8; tries++) {
            const tn_season_sample *r = &t->s[tn_rng_below(&t->rng, (uint32_t)t->count)];
            int rx = (int)tn_rng_below(&t->rng, (uint32_t)(r->dem->width - S + 1)), ry = (int)tn_rng_below(&t->rng, (uint32_t)(r->dem->height - S + 1));
            float v = 0;
            if (r->mask)
                for (y = 0; y < S; y++)
                    for (x = 0; x < S; x++) v += r->mask->data[(size_t)(ry + y) * r->dem->width + rx + x] > 0.5f;
            else
                v = (float)plane;
            if (v > best) best = v, q = r, x0 = rx, y0 = ry;
            if (v >= 0.25f * (float)plane) break;
        }
        tn__kpd_months(q->time, &m0, &f);
        tn__kpd_cond(&t->A, q->dem, q->climate, q->insolation, m0, x0, y0, S, S, t->c0 + (size_t)b * C * plane);
        tn__kpd_cond(&t->A, q->dem, q->climate, q->insolation, (m0 + 1) % 12, x0, y0, S, S, t->c1 + (size_t)b * C * plane);
        t->f[b] = f;
        if (f > 0) t->any_between = 1;
        for (y = 0; y < S; y++)
            for (x = 0; x < S; x++) {
                size_t src = (size_t)(y0 + y) * q->dem->width + x0 + x, i = (size_t)y * S + x;
                float m = q->mask ? (q->mask->data[src] > 0.5f) : 1.0f;
                t->mask[(size_t)b * plane + i] = m;
                for (c = 0; c < O; c++) {
                    float v = q->target->data[src * O + c];
                    v = m > 0 ? 2.0f * (v - t->A.lo) / (t->A.hi - t->A.lo) - 1.0f : 0.0f;
                    t->real[((size_t)b * O + c) * plane + i] = v;
                }
            }
    }
}

static tn_tensor *tn__kpd_const(tn_ctx *ctx, const float *data, int n, int c, int h, int w)
{
    tn_tensor *t = tn_tensor_4d(ctx, n, c, h, w);
    if (t) memcpy(t->data, data, t->numel * sizeof(float));
    return t;
}

/* sum(s * w) / sum(w) */
static tn_tensor *tn__kpd_wmean(tn_ctx *ctx, tn_tensor *s, tn_tensor *w, float wsum)
{
    return tn_scale_shift(ctx, tn_sum(ctx, tn_mul(ctx, s, w)), 1.0f / wsum, 0.0f);
}

/* One G step then one D step on its (mask-composited) fake. l: L1 (target units), G adversarial, D. */
static tn_status tn__kpd_step(tn__kpd_train *t, tn_ctx *ctx, float *l)
{
    int N = t->o.batch, S = t->o.crop, C = t->A.cond_channels, O = t->A.out_channels, gan = t->o.gan_weight > 0, k;
    int fs[4];
    tn_tensor *c0, *c1 = NULL, *f = NULL, *real, *mask, *fake, *comp, *l1, *loss, *wm = NULL;
    float msum = 0, wsum = 0;
    size_t i;
    tn_status st;
    tn__kpd_batch(t);
    for (i = 0; i < (size_t)N * S * S; i++) msum += t->mask[i];
    tn_ctx_reset(ctx);
    tn_ctx_set_grad(ctx, 1);
    c0 = tn__kpd_const(ctx, t->c0, N, C, S, S);
    if (t->any_between) {
        c1 = tn__kpd_const(ctx, t->c1, N, C, S, S);
        fs[0] = N;
        fs[1] = fs[2] = fs[3] = 1;
        if ((f = tn_tensor_new(ctx, 4, fs))) memcpy(f->data, t->f, (size_t)N * sizeof(float));
    }
    real = tn__kpd_const(ctx, t->real, N, O, S, S);
    mask = tn__kpd_const(ctx, t->mask, N, 1, S, S);
    fake = tn__kpd_forward(ctx, t->g, c0, c1, f);
    comp = tn_add(ctx, tn_mul(ctx, fake, mask), tn_mul(ctx, real, tn_scale_shift(ctx, mask, -1.0f, 1.0f)));
    l1 = tn_scale_shift(ctx, tn_sum(ctx, tn_mul(ctx, tn_abs(ctx, tn_sub(ctx, fake, real)), mask)), 1.0f / (msum * O + 1e-6f), 0.0f);
    loss = tn_scale_shift(ctx, l1, t->o.l1_weight > 0 ? t->o.l1_weight : 0.0f, 0.0f);
    l[1] = l[2] = 0;
    if (gan) {
        tn_tensor *ff[TN_DISC_MAX_LAYERS + 1], *fr[TN_DISC_MAX_LAYERS + 1], *sf, *lg, *fm = NULL;
        wm = tn_avg_pool2d(ctx, mask, 1 << t->disc.layers, 1 << t->disc.layers);
        if (wm)
            for (i = 0; i < wm->numel; i++) wsum += wm->data[i];
        tn_patch_disc_begin(ctx, &t->disc);
        sf = tn_patch_disc_features(ctx, &t->disc, tn_concat(ctx, c0, comp, 1), ff);
        tn_ctx_set_grad(ctx, 0);
        tn_patch_disc_features(ctx, &t->disc, tn_concat(ctx, c0, real, 1), fr);
        tn_ctx_set_grad(ctx, 1);
        lg = tn_scale_shift(ctx, tn__kpd_wmean(ctx, sf, wm, wsum + 1e-6f), -1.0f, 0.0f);
        for (k = 0; k < t->disc.layers; k++) {
            tn_tensor *d = tn_mean(ctx, tn_abs(ctx, tn_sub(ctx, ff[k], fr[k])));
            fm = fm ? tn_add(ctx, fm, d) : d;
        }
        loss = tn_add(ctx, loss, tn_scale_shift(ctx, lg, t->o.gan_weight, 0.0f));
        if (fm && t->o.fm_weight > 0) loss = tn_add(ctx, loss, tn_scale_shift(ctx, fm, t->o.fm_weight / (float)t->disc.layers, 0.0f));
        if (lg) l[1] = lg->data[0];
    }
    if (!loss) return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : tn__fail(TN_ERR_OUT_OF_MEMORY, "season-train: out of memory");
    tn_params_zero_grad(t->g);
    if ((st = tn_backward(ctx, loss))) return st;
    tn_optim_step(t->og);
    l[0] = l1->data[0] * 0.5f * (t->A.hi - t->A.lo);
    if (gan) { /* D step: the composited fake is a constant */
        tn_tensor *sr, *sf2, *ld;
        memcpy(t->fake, comp->data, comp->numel * sizeof(float));
        tn_ctx_reset(ctx);
        c0 = tn__kpd_const(ctx, t->c0, N, C, S, S);
        real = tn__kpd_const(ctx, t->real, N, O, S, S);
        comp = tn__kpd_const(ctx, t->fake, N, O, S, S);
        wm = tn_avg_pool2d(ctx, tn__kpd_const(ctx, t->mask, N, 1, S, S), 1 << t->disc.layers, 1 << t->disc.layers);
        tn_patch_disc_begin(ctx, &t->disc);
        sr = tn_patch_disc_score(ctx, &t->disc, tn_concat(ctx, c0, real, 1));
        sf2 = tn_patch_disc_score(ctx, &t->disc, tn_concat(ctx, c0, comp, 1));
        ld = tn_add(ctx, tn__kpd_wmean(ctx, tn_relu(ctx, tn_scale_shift(ctx, sr, -1.0f, 1.0f)), wm, wsum + 1e-6f),
                    tn__kpd_wmean(ctx, tn_relu(ctx, tn_scale_shift(ctx, sf2, 1.0f, 1.0f)), wm, wsum + 1e-6f));
        if (!ld) return tn_ctx_status(ctx) ? tn_ctx_status(ctx) : tn__fail(TN_ERR_OUT_OF_MEMORY, "season-train: out of memory");
        tn_params_zero_grad(t->d);
        if ((st = tn_backward(ctx, ld))) return st;
        tn_optim_step(t->od);
        l[2] = ld->data[0];
    }
    if (!isfinite(l[0]) || !isfinite(l[1]) || !isfinite(l[2]))
        return tn__fail(TN_ERR_NUMERIC, "season-train: training diverged at iteration %ld (L1 %g, G %g, D %g)", tn_train_iteration(t->run),
                        (double)l[0], (double)l[1], (double)l[2]);
    return TN_OK;
}

static uint64_t tn__kpd_digest(const tn_season_sample *s, int count)
{
    uint64_t h = 1469598103934665603ULL;
    int i;
    for (i = 0; i < count; i++) {
        uint64_t v[3];
        int k;
        v[0] = tn_image_digest(s[i].target);
        v[1] = tn_image_digest(s[i].dem);
        memcpy(&v[2], &s[i].time, sizeof(float));
        v[2] &= 0xffffffffULL;
        for (k = 0; k < 3; k++) h = (h ^ v[k]) * 1099511628211ULL;
    }
    return h;
}

static void tn__kpd_train_free(tn__kpd_train *t)
{
    tn_optim_free(t->og);
    tn_optim_free(t->od);
    tn_params_free(t->g);
    tn_params_free(t->d);
    tn_train_free(t->run);
    TN_FREE(t->c0);
}

TN_API tn_status tn_kpd_train(tn_kpd *model, const tn_season_sample *samples, int count, const tn_kpd_opts *opts, tn_kpd_stats *stats)
{
    tn__kpd_train t;
    tn_ctx *ctx = NULL;
    tn_optim_opts oo;
    float hist[50][3], first = NAN;
    int nh = 0, minside = 1 << 30, i, N, S;
    size_t plane, total;
    uint64_t digest;
    tn_status st;
    TN_ASSERT(model);
    memset(&t, 0, sizeof t);
    if (opts) t.o = *opts;
    tn_kpd_defaults(&t.o);
    if ((st = tn__kpd_validate(&t.o))) return st;
    if ((st = tn__kpd_check_samples(samples, count, t.o.condition, &t.A.out_channels))) return st;
    if (t.A.out_channels > 16) return tn__fail(TN_ERR_INVALID_ARG, "season-train: %d target channels (at most 16)", t.A.out_channels);
    for (i = 0; i < count; i++) {
        if (samples[i].dem->width < minside) minside = samples[i].dem->width;
        if (samples[i].dem->height < minside) minside = samples[i].dem->height;
    }
    if (t.o.crop > minside) t.o.crop = minside & ~7;
    if (t.o.crop < 16) return tn__fail(TN_ERR_INVALID_ARG, "season-train: a DEM of %d px a side is smaller than the 16 px training window", minside);
    t.s = samples;
    t.count = count;
    digest = tn__kpd_digest(samples, count);
    if ((st = tn_train_create(&t.run, "kpd", "season-train", &t.o.train))) return st;
    if (t.o.train.resume) { /* the checkpoint's architecture wins */
        tn_params *ck;
        tn_tensor *cfg;
        int oc = t.A.out_channels;
        if ((st = tn_train_open_checkpoint(t.run, &ck))) goto done;
        if (!(cfg = tn_params_find(ck, "kpd.config")) || cfg->numel != TN__KPD_CONFIG) {
            st = tn__fail(TN_ERR_FORMAT, "%s: not a kpd checkpoint", t.o.train.checkpoint);
            goto done;
        }
        if ((st = tn__kpd_read_config(cfg->data, &t.A, t.o.train.checkpoint))) goto done;
        if (t.A.out_channels != oc) {
            st = tn__fail(TN_ERR_SHAPE, "%s: the checkpoint makes %d channels, these pictures have %d", t.o.train.checkpoint, t.A.out_channels, oc);
            goto done;
        }
        if ((st = tn__kpd_file_matches(ck, &t.A, t.o.train.checkpoint))) goto done; /* before the config sizes anything */
        if (t.A.condition != t.o.condition) { /* the checkpoint's condition may need other inputs */
            t.o.condition = t.A.condition;
            if ((st = tn__kpd_check_samples(samples, count, t.o.condition, &oc))) goto done;
        }
    } else {
        t.A.condition = t.o.condition;
        t.A.cond_channels = tn__kpd_cond_channels(t.o.condition);
        t.A.width = t.o.width;
        t.A.lo = t.o.lo;
        t.A.hi = t.o.hi;
        t.A.lapse_rate = t.o.lapse_rate;
        tn__kpd_scales(samples, count, &t.A);
    }
    tn_rng_seed(&t.rng, tn_train_seed(t.run), 0x6b7064ULL);
    if ((st = tn__kpd_model_params(&t.A, &t.rng, &t.g))) goto done;
    if (!(t.d = tn_params_create())) {
        st = tn__oom();
        goto done;
    }
    if (t.o.gan_weight > 0 && (st = tn_patch_disc_add(t.d, "d.", t.A.cond_channels + t.A.out_channels, 32, 3, 3, &t.rng, &t.disc))) goto done;
    memset(&oo, 0, sizeof oo);
    oo.lr = t.o.lr;
    oo.beta1 = 0.0f;
    oo.beta2 = 0.999f;
    if (!(t.og = tn_optim_create(t.g, &oo)) || !(t.od = tn_optim_create(t.d, &oo))) {
        st = TN_ERR_INVALID_ARG;
        goto done;
    }
    if ((st = tn_train_add_net(t.run, "g", t.g, t.og)) || (st = tn_train_add_net(t.run, "d", t.d, t.od)) ||
        (st = tn_train_add_rng(t.run, "main", &t.rng)) || (st = tn_train_set_example(t.run, digest)) ||
        (st = tn_train_set_meta_number(t.run, "crop", t.o.crop)) || (st = tn_train_set_meta_number(t.run, "batch", t.o.batch)))
        goto done;
    if (t.o.train.resume) {
        double v;
        if ((st = tn_train_check_example(t.run, digest)) || (st = tn_train_meta_number(t.run, "crop", 16, 1 << 20, &v))) goto done;
        if (v != 8 * floor(v / 8)) { /* the windows pool by 8 */
            st = tn__fail(TN_ERR_CORRUPT, "%s: bad crop %g (a multiple of 8)", t.o.train.checkpoint, v);
            goto done;
        }
        t.o.crop = (int)v;
        if ((st = tn_train_meta_number(t.run, "batch", 1, 64, &v))) goto done;
        t.o.batch = (int)v;
        if ((st = tn_train_restore(t.run))) goto done;
        if (t.o.crop > minside) {
            st = tn__fail(TN_ERR_SHAPE, "%s: trained on %d px windows, larger than these DEMs", t.o.train.checkpoint, t.o.crop);
            goto done;
        }
    }
    N = t.o.batch;
    S = t.o.crop;
    plane = (size_t)S * S;
    total = (size_t)N * plane * (2 * (size_t)t.A.cond_channels + 2 * (size_t)t.A.out_channels + 1) + (size_t)N;
    if (!(t.c0 = (float *)TN_MALLOC(total * sizeof(float))) || !(ctx = tn_ctx_create())) {
        st = tn__fail(TN_ERR_OUT_OF_MEMORY, "season-train: out of memory");
        goto done;
    }
    t.c1 = t.c0 + (size_t)N * plane * t.A.cond_channels;
    t.real = t.c1 + (size_t)N * plane * t.A.cond_channels;
    t.fake = t.real + (size_t)N * plane * t.A.out_channels;
    t.mask = t.fake + (size_t)N * plane * t.A.out_channels;
    t.f = t.mask + (size_t)N * plane;
    while (tn_train_next(t.run)) {
        float l[3];
        tn_status e = tn__kpd_step(&t, ctx, l);
        if (e) {
            tn_train_fail(t.run, e);
            break;
        }
        if (nh == 0) first = l[0];
        memcpy(hist[nh % 50], l, sizeof l);
        nh++;
    }
    st = tn_train_finish(t.run);
    if (stats) {
        int k, m = nh < 50 ? nh : 50;
        long it = tn_train_iteration(t.run), it0 = tn_train_start_iteration(t.run);
        memset(stats, 0, sizeof *stats);
        stats->iterations = it;
        stats->resumed_from = t.o.train.resume ? it0 : 0;
        stats->seconds = tn_train_seconds(t.run);
        stats->seconds_per_iter = it > it0 ? (tn_train_seconds(t.run) - tn_train_start_seconds(t.run)) / (double)(it - it0) : 0.0;
        for (k = 0; k < m; k++) {
            stats->loss_l1 += hist[k][0] / (float)m;
            stats->loss_g += hist[k][1] / (float)m;
            stats->loss_d += hist[k][2] / (float)m;
        }
        stats->loss_l1_first = first;
        stats->checkpoints = tn_train_checkpoints(t.run);
    }
    if (!st) {
        tn__kpd_write_config(&t.A, tn_params_find(t.g, "kpd.config")->data);
        st = tn__train_stamp(t.g, "kpd", TN__KPD_FORMAT, t.run, digest, samples[0].target->width, samples[0].target->height,
                             t.A.out_channels);
    }
    if (!st) {
        *model = t.A;
        model->iterations = tn_train_iteration(t.run);
        model->train_seconds = tn_train_seconds(t.run);
        model->weights = t.g;
        t.g = NULL;
    }
done:
    tn_ctx_free(ctx);
    tn__kpd_train_free(&t);
    return st;
}

TN_API void tn_kpd_free(tn_kpd *model)
{
    if (!model) return;
    tn_params_free(model->weights);
    memset(model, 0, sizeof *model);
}

TN_API tn_status tn_kpd_save(const char *path, const tn_kpd *model)
{
    if (!model || !model->weights || !tn_params_find(model->weights, "kpd.config")) return tn__fail(TN_ERR_INVALID_ARG, "kpd save: not a trained or loaded model");
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "kpd save: empty path");
    return tn_params_save(path, model->weights);
}

TN_API tn_status tn_kpd_load(tn_kpd *model, const char *path)
{
    tn_params *f = NULL, *w = NULL;
    tn_tensor *cfg = NULL;
    tn_kpd m;
    tn_status st;
    TN_ASSERT(model);
    memset(&m, 0, sizeof m);
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "kpd load: empty path");
    if ((st = tn__model_open(&f, path, "kpd", TN__KPD_FORMAT, NULL))) return st;
    if (!(cfg = tn_params_find(f, "kpd.config")) || cfg->numel != TN__KPD_CONFIG)
        st = tn__fail(TN_ERR_FORMAT, "%s: not a kpd model (no kpd.config)", path);
    if (!st) st = tn__kpd_read_config(cfg->data, &m, path);
    if (!st) st = tn__kpd_file_matches(f, &m, path);
    if (!st) st = tn__kpd_model_params(&m, NULL, &w);
    if (!st) st = tn__params_assign(w, f, path);
    if (!st) st = tn__model_check_finite(w, path);
    if (!st) tn__model_training(f, path, &m.iterations, &m.train_seconds);
    tn_params_free(f);
    if (st) {
        tn_params_free(w);
        return st;
    }
    m.weights = w;
    *model = m;
    return TN_OK;
}

/* ---- generation: windows with a halo, aligned to 4 px so the pooled levels line up ---- */

TN_API tn_status tn_kpd_generate(tn_image *out, const tn_kpd *model, const tn_image *dem, const tn_climate *climate,
                                 const tn_image *insolation, float time, int x0, int y0, int w, int h)
{
    const int T = 256, Hl = TN_KPD_HALO;
    int W, Hh, Wp, Hp, C, O, m0, tx, ty;
    float f;
    size_t k, n;
    tn_ctx *ctx = NULL;
    float *buf = NULL;
    tn_image res = {0, 0, 0, NULL};
    tn_status st;
    TN_ASSERT(out);
    if (!model || !model->weights || !tn_params_find(model->weights, "kpd.config")) return tn__fail(TN_ERR_INVALID_ARG, "season: not a trained or loaded kpd model");
    if (!dem || !dem->data || dem->width < 1 || dem->height < 1) return tn__fail(TN_ERR_EMPTY, "season: empty DEM");
    if (!climate) return tn__fail(TN_ERR_INVALID_ARG, "season: no climate");
    if ((st = tn_climate_check(climate))) return st;
    if (!isfinite(time)) return tn__fail(TN_ERR_NUMERIC, "season: the time of the year is NaN/Inf");
    W = dem->width;
    Hh = dem->height;
    if (w < 1 || h < 1 || x0 < 0 || y0 < 0 || x0 > W - w || y0 > Hh - h)
        return tn__fail(TN_ERR_INVALID_ARG, "season: window %d,%d %d x %d outside the %d x %d DEM", x0, y0, w, h, W, Hh);
    if (model->condition == TN_KPD_OURS &&
        (!insolation || !insolation->data || insolation->width != W || insolation->height != Hh || insolation->channels != 12))
        return tn__fail(TN_ERR_SHAPE, "season: this model needs the DEM's 12-month insolation (tn_insolation)");
    if (model->condition == TN_KPD_COND3 && !climate->has_latitude) return tn__fail(TN_ERR_INVALID_ARG, "season: this model needs the climate's latitude");
    n = (size_t)W * Hh;
    for (k = 0; k < n; k++)
        if (!isfinite(dem->data[k * dem->channels])) return tn__fail(TN_ERR_NUMERIC, "season: the DEM has NaN/Inf heights");
    if (model->condition == TN_KPD_OURS)
        for (k = 0; k < n * 12; k++)
            if (!isfinite(insolation->data[k])) return tn__fail(TN_ERR_NUMERIC, "season: the insolation has NaN/Inf");
    Wp = (W + 3) & ~3;
    Hp = (Hh + 3) & ~3;
    C = model->cond_channels;
    O = model->out_channels;
    tn__kpd_months(time, &m0, &f);
    if ((st = tn_image_create(&res, w, h, O))) return st;
    if (!(ctx = tn_ctx_create()) || !(buf = (float *)TN_MALLOC((size_t)2 * C * (T + 2 * Hl + 8) * (T + 2 * Hl + 8) * sizeof(float)))) {
        st = tn__fail(TN_ERR_OUT_OF_MEMORY, "season: out of memory");
        goto done;
    }
    tn_ctx_set_grad(ctx, 0);
    for (ty = y0; ty < y0 + h && !st; ty += T)
        for (tx = x0; tx < x0 + w && !st; tx += T) {
            int tw = x0 + w - tx < T ? x0 + w - tx : T, th = y0 + h - ty < T ? y0 + h - ty : T;
            int ax0 = (tx - Hl) < 0 ? 0 : (tx - Hl) & ~3, ay0 = (ty - Hl) < 0 ? 0 : (ty - Hl) & ~3;
            int ax1 = (tx + tw + Hl + 3) & ~3, ay1 = (ty + th + Hl + 3) & ~3, aw, ah, x, y, c;
            size_t pl;
            tn_tensor *c0, *c1 = NULL, *ft = NULL, *g;
            if (ax1 > Wp) ax1 = Wp;
            if (ay1 > Hp) ay1 = Hp;
            aw = ax1 - ax0;
            ah = ay1 - ay0;
            pl = (size_t)aw * ah;
            tn_ctx_reset(ctx);
            tn__kpd_cond(model, dem, climate, insolation, m0, ax0, ay0, aw, ah, buf);
            c0 = tn__kpd_const(ctx, buf, 1, C, ah, aw);
            if (f > 0) {
                tn__kpd_cond(model, dem, climate, insolation, (m0 + 1) % 12, ax0, ay0, aw, ah, buf + (size_t)C * pl);
                c1 = tn__kpd_const(ctx, buf + (size_t)C * pl, 1, C, ah, aw);
                if ((ft = tn_tensor_1d(ctx, 1))) ft->data[0] = f;
            }
            g = tn__kpd_forward(ctx, model->weights, c0, c1, ft);
            if (!g) {
                st = tn_ctx_status(ctx) ? tn_ctx_status(ctx) : tn__fail(TN_ERR_OUT_OF_MEMORY, "season: out of memory");
                break;
            }
            for (y = 0; y < th; y++)
                for (x = 0; x < tw; x++)
                    for (c = 0; c < O; c++) {
                        float v = g->data[(size_t)c * pl + (size_t)(ty - ay0 + y) * aw + (tx - ax0 + x)];
                        res.data[((size_t)(ty - y0 + y) * w + (tx - x0 + x)) * O + c] = model->lo + 0.5f * (v + 1.0f) * (model->hi - model->lo);
                    }
            if ((st = tn__progress("season", (double)((ty - y0) * w + (tx - x0 + tw) * th) / ((double)w * h)))) break;
        }
done:
    TN_FREE(buf);
    tn_ctx_free(ctx);
    if (st) {
        tn_image_free(&res);
        return st;
    }
    *out = res;
    return TN_OK;
}

/* ---- data sets ---- */

TN_API float tn_season_time_of(const char *when)
{
    static const int days[12] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
    int y, m, d;
    char tail;
    double v;
    if (!when) return -1.0f;
    if (sscanf(when, "%d-%d-%d%c", &y, &m, &d, &tail) == 3 && y > 0 && m >= 1 && m <= 12 && d >= 1 && d <= days[m - 1] + (m == 2))
        return (float)fmod((m - 1) + (d - 15.0) / days[m - 1] + 12.0, 12.0);
    if (tn__io_number(when, strlen(when), &v) && isfinite(v)) return (float)fmod(fmod(v, 12.0) + 12.0, 12.0);
    return -1.0f;
}

TN_API void tn_season_data_free(tn_season_data *d)
{
    int i;
    if (!d) return;
    for (i = 0; i < d->sites; i++) {
        tn_image_free(&d->dems[i]);
        tn_image_free(&d->insolation[i]);
    }
    for (i = 0; i < d->count; i++) {
        tn_image_free(&d->targets[i]);
        tn_image_free(&d->masks[i]);
    }
    TN_FREE(d->dems);
    TN_FREE(d->insolation);
    TN_FREE(d->climates);
    TN_FREE(d->targets);
    TN_FREE(d->masks);
    TN_FREE(d->samples);
    TN_FREE(d->labels);
    memset(d, 0, sizeof *d);
}

/* The last error again, prefixed with the data file's line. */
static tn_status tn__season_fail_at(tn_status st, const char *where)
{
    char msg[1040];
    snprintf(msg, sizeof msg, "%s", tn_last_error());
    return tn__fail(st, "%s: %s", where, msg);
}

/* path relative to the data file's folder (absolute paths stay) */
static void tn__season_path(const char *base, const char *f, size_t fl, char *out, size_t cap)
{
    const char *slash = strrchr(base, '/');
    size_t bl = slash ? (size_t)(slash - base + 1) : 0;
    if (fl > 0 && f[0] == '/') bl = 0;
    if (bl + fl + 1 > cap) {
        out[0] = 0;
        return;
    }
    memcpy(out, base, bl);
    memcpy(out + bl, f, fl);
    out[bl + fl] = 0;
}

static tn_status tn__season_grow(tn_season_data *d, int need_sites, int need_frames, int *cap_s, int *cap_f)
{
    if (need_sites > *cap_s) {
        int c = *cap_s ? *cap_s * 2 : 4;
        tn_image *a = (tn_image *)TN_REALLOC(d->dems, (size_t)c * sizeof *a), *b;
        tn_climate *cl;
        if (!a) return tn__oom();
        d->dems = a;
        if (!(b = (tn_image *)TN_REALLOC(d->insolation, (size_t)c * sizeof *b))) return tn__oom();
        d->insolation = b;
        if (!(cl = (tn_climate *)TN_REALLOC(d->climates, (size_t)c * sizeof *cl))) return tn__oom();
        d->climates = cl;
        *cap_s = c;
    }
    if (need_frames > *cap_f) {
        int c = *cap_f ? *cap_f * 2 : 16;
        tn_image *a = (tn_image *)TN_REALLOC(d->targets, (size_t)c * sizeof *a), *b;
        tn_season_sample *s;
        char(*lb)[32];
        if (!a) return tn__oom();
        d->targets = a;
        if (!(b = (tn_image *)TN_REALLOC(d->masks, (size_t)c * sizeof *b))) return tn__oom();
        d->masks = b;
        if (!(s = (tn_season_sample *)TN_REALLOC(d->samples, (size_t)c * sizeof *s))) return tn__oom();
        d->samples = s;
        if (!(lb = (char(*)[32])TN_REALLOC(d->labels, (size_t)c * sizeof *lb))) return tn__oom();
        d->labels = lb;
        *cap_f = c;
    }
    return TN_OK;
}

/* Refuses up front a site whose frame rows cannot fit in memory (a few KB of rows naming one
   large frame again and again would ask for tens of GB): each frame keeps a picture of at least
   one channel and a mask, 8 bytes per DEM pixel, and their total for the rows from `from` to the
   next dem row must stay within what the memory budget has left. */
static tn_status tn__season_frames_fit(const char *s, size_t from, size_t n, const tn_image *dem, const char *name)
{
    size_t i = from, rows = 0, left, limit = tn_get_memory_limit(), used = tn_memory_in_use();
    double need;
    while (i < n) {
        size_t b = i, e, fl[1];
        const char *fb[1];
        while (i < n && s[i] != '\n') i++;
        e = i++;
        while (b < e && tn__io_space((unsigned char)s[b])) b++;
        if (b == e || s[b] == '#') continue;
        (void)tn__climate_fields(s + b, e - b, fb, fl, 1);
        if (tn__io_token_is(fb[0], fl[0], "dem")) break;
        if (tn__io_token_is(fb[0], fl[0], "frame")) rows++;
    }
    left = used < limit ? limit - used : 0;
    need = (double)rows * (double)dem->width * (double)dem->height * 8.0;
    if (need > (double)left)
        return tn__fail(TN_ERR_TOO_LARGE, "%s: %zu frame rows of %d x %d need at least %.0f MB, over the %.0f MB the memory limit leaves "
                        "(tn_set_memory_limit, --max-memory)", name, rows, dem->width, dem->height, need / 1048576.0, (double)left / 1048576.0);
    return TN_OK;
}

/* One frame: the picture, and its validity from the exclusion masks; a frame without a valid
   pixel is left out (*skip = 1). */
static tn_status tn__season_frame(tn_season_data *d, const char *path, const char *line_name, const tn_image *dem, const char **fb,
                                  const size_t *fl, int nf, int *skip)
{
    char p[1024];
    tn_image *t = &d->targets[d->count], *m = &d->masks[d->count];
    size_t k, n = (size_t)dem->width * dem->height, valid = 0;
    int i, c;
    tn_status st;
    *skip = 0;
    memset(t, 0, sizeof *t);
    memset(m, 0, sizeof *m);
    tn__season_path(path, fb[2], fl[2], p, sizeof p);
    if ((st = tn_image_load(t, p, NULL))) return tn__season_fail_at(st, line_name);
    if (t->width != dem->width || t->height != dem->height) {
        st = tn__fail(TN_ERR_SHAPE, "%s: %s is %d x %d, its DEM %d x %d", line_name, p, t->width, t->height, dem->width, dem->height);
        goto fail;
    }
    if ((st = tn_image_create(m, dem->width, dem->height, 1))) goto fail;
    for (k = 0; k < n; k++) m->data[k] = 1.0f;
    for (i = 3; i < nf && i < 8; i++) {
        tn_image e = {0, 0, 0, NULL};
        tn__season_path(path, fb[i], fl[i], p, sizeof p);
        if ((st = tn_image_load(&e, p, NULL))) {
            st = tn__season_fail_at(st, line_name);
            goto fail;
        }
        if (e.width != dem->width || e.height != dem->height) {
            st = tn__fail(TN_ERR_SHAPE, "%s: mask %s is %d x %d, its DEM %d x %d", line_name, p, e.width, e.height, dem->width, dem->height);
            tn_image_free(&e);
            goto fail;
        }
        for (k = 0; k < n; k++)
            if (!(e.data[k * e.channels] <= 0.5f)) m->data[k] = 0.0f;
        tn_image_free(&e);
    }
    for (k = 0; k < n; k++) {
        if (m->data[k] <= 0.5f) {
            for (c = 0; c < t->channels; c++) t->data[k * t->channels + c] = 0.0f; /* masked: never used */
            continue;
        }
        for (c = 0; c < t->channels; c++)
            if (!isfinite(t->data[k * t->channels + c])) {
                st = tn__fail(TN_ERR_NUMERIC, "%s: NaN/Inf at pixel (%zu, %zu) that no mask excludes", line_name, k % dem->width, k / dem->width);
                goto fail;
            }
        valid++;
    }
    if (!valid) {
        *skip = 1;
        tn_image_free(t);
        tn_image_free(m);
    }
    return TN_OK;
fail:
    tn_image_free(t);
    tn_image_free(m);
    return st;
}

TN_API tn_status tn_season_data_load(tn_season_data *out, const char *path)
{
    tn_season_data d;
    uint8_t *buf = NULL;
    size_t n = 0, i = 0;
    int line = 0, cap_s = 0, cap_f = 0, have_clim = 0, k, *site_of = NULL;
    double spacing = 1.0, lat = NAN;
    float *dx = NULL;
    float lo = 0.0f, hi = 1.0f;
    tn_status st;
    TN_ASSERT(out);
    memset(&d, 0, sizeof d);
    memset(out, 0, sizeof *out);
    if (!path) return tn__fail(TN_ERR_INVALID_ARG, "season data: NULL path");
    if ((st = tn__io_read_file(path, &buf, &n))) return st;
    while (i < n && !st) {
        const char *fb[9], *s = (const char *)buf;
        size_t fl[9], b = i, e;
        char name[64], p[1024];
        int nf;
        double v[2];
        while (i < n && s[i] != '\n') i++;
        e = i++;
        line++;
        while (b < e && tn__io_space((unsigned char)s[b])) b++;
        if (b == e || s[b] == '#') continue;
        nf = tn__climate_fields(s + b, e - b, fb, fl, 9);
        snprintf(name, sizeof name, "%.40s:%d", path, line);
        if (tn__io_token_is(fb[0], fl[0], "dem")) {
            tn_image *dm;
            if (nf != 2 && nf != 4) { st = tn__fail(TN_ERR_FORMAT, "%s: expected \"dem,PATH[,LO,HI]\"", name); break; }
            if (d.sites > 0 && !have_clim) { st = tn__fail(TN_ERR_FORMAT, "%s: the site before has no climate or koppen row", name); break; }
            if ((st = tn__season_grow(&d, d.sites + 1, 0, &cap_s, &cap_f))) break;
            dm = &d.dems[d.sites];
            memset(dm, 0, sizeof *dm);
            memset(&d.insolation[d.sites], 0, sizeof(tn_image));
            tn__season_path(path, fb[1], fl[1], p, sizeof p);
            if ((st = tn_image_load(dm, p, NULL))) { st = tn__season_fail_at(st, name); break; }
            {
                float *nd = (float *)TN_REALLOC(dx, (size_t)cap_s * sizeof(float));
                if (!nd) { st = tn__oom(); break; }
                dx = nd;
                dx[d.sites] = 1.0f;
            }
            d.sites++;
            if ((st = tn__season_frames_fit(s, i, n, dm, name))) break;
            if (nf == 4) {
                size_t q, np = (size_t)dm->width * dm->height * dm->channels;
                if (!tn__io_number(fb[2], fl[2], &v[0]) || !tn__io_number(fb[3], fl[3], &v[1]) || !(v[1] > v[0]) || !isfinite(v[1] - v[0])) {
                    st = tn__fail(TN_ERR_FORMAT, "%s: LO,HI must be numbers with LO < HI", name);
                    break;
                }
                for (q = 0; q < np; q++) dm->data[q] = (float)(v[0] + dm->data[q] * (v[1] - v[0]));
            }
            have_clim = 0;
            lat = NAN;
        } else if (d.sites == 0) {
            if (tn__io_token_is(fb[0], fl[0], "range") && nf == 3 && tn__io_number(fb[1], fl[1], &v[0]) && tn__io_number(fb[2], fl[2], &v[1]) &&
                v[1] > v[0] && isfinite(v[1] - v[0])) {
                lo = (float)v[0];
                hi = (float)v[1];
            } else
                st = tn__fail(TN_ERR_FORMAT, "%s: expected \"range,LO,HI\" (LO < HI) or a \"dem,PATH\" row first", name);
        } else if (tn__io_token_is(fb[0], fl[0], "spacing")) {
            if (nf != 2 || !tn__io_number(fb[1], fl[1], &spacing) || !(spacing > 0) || !isfinite(spacing)) st = tn__fail(TN_ERR_FORMAT, "%s: expected \"spacing,DX\" (DX > 0)", name);
            else dx[d.sites - 1] = (float)spacing;
        } else if (tn__io_token_is(fb[0], fl[0], "latitude")) {
            if (nf != 2 || !tn__io_number(fb[1], fl[1], &lat) || !(lat >= -90 && lat <= 90)) st = tn__fail(TN_ERR_FORMAT, "%s: expected \"latitude,L\" (-90..90)", name);
            else if (have_clim) d.climates[d.sites - 1].latitude = (float)lat, d.climates[d.sites - 1].has_latitude = 1;
        } else if (tn__io_token_is(fb[0], fl[0], "climate") || tn__io_token_is(fb[0], fl[0], "koppen")) {
            tn_climate *c = &d.climates[d.sites - 1];
            char code[32];
            if (nf != 2) { st = tn__fail(TN_ERR_FORMAT, "%s: expected \"climate,PATH\" or \"koppen,CODE\"", name); break; }
            if (tn__io_token_is(fb[0], fl[0], "climate")) {
                tn__season_path(path, fb[1], fl[1], p, sizeof p);
                st = tn_climate_load(c, p);
            } else {
                snprintf(code, sizeof code, "%.*s", (int)(fl[1] < 31 ? fl[1] : 31), fb[1]);
                st = tn_climate_koppen(c, code);
            }
            if (st) { st = tn__season_fail_at(st, name); break; }
            if (isfinite(lat)) c->latitude = (float)lat, c->has_latitude = 1;
            have_clim = 1;
        } else if (tn__io_token_is(fb[0], fl[0], "frame")) {
            char when[32];
            float tm;
            int skip = 0;
            if (nf < 3 || nf > 8) { st = tn__fail(TN_ERR_FORMAT, "%s: expected \"frame,WHEN,IMAGE[,EXCLUDE...]\" (at most 5 masks)", name); break; }
            if (!have_clim) { st = tn__fail(TN_ERR_FORMAT, "%s: a frame before its site's climate or koppen row", name); break; }
            snprintf(when, sizeof when, "%.*s", (int)(fl[1] < 31 ? fl[1] : 31), fb[1]);
            if ((tm = tn_season_time_of(when)) < 0) { st = tn__fail(TN_ERR_FORMAT, "%s: \"%s\" is neither YYYY-MM-DD nor a number of months", name, when); break; }
            if ((st = tn__season_grow(&d, 0, d.count + 1, &cap_s, &cap_f))) break;
            {
                int *so = (int *)TN_REALLOC(site_of, (size_t)cap_f * sizeof(int));
                if (!so) { st = tn__oom(); break; }
                site_of = so;
            }
            if ((st = tn__season_frame(&d, path, name, &d.dems[d.sites - 1], fb, fl, nf, &skip))) break;
            if (skip) continue;
            snprintf(d.labels[d.count], 32, "%s", when);
            d.samples[d.count].time = tm;
            site_of[d.count] = d.sites - 1;
            d.count++;
        } else if (tn__io_token_is(fb[0], fl[0], "range")) {
            st = tn__fail(TN_ERR_FORMAT, "%s: the range row goes before the first dem row", name);
        } else
            st = tn__fail(TN_ERR_FORMAT, "%s: unknown row (dem, spacing, climate, koppen, latitude, frame, range)", name);
    }
    TN_FREE(buf);
    if (!st && d.sites > 0 && !have_clim) st = tn__fail(TN_ERR_FORMAT, "%s: the last site has no climate or koppen row", path);
    if (!st && d.count == 0) st = tn__fail(TN_ERR_EMPTY, "%s: no frame with a valid pixel", path);
    for (k = 0; !st && k < d.sites; k++) { /* insolation of each site, at its latitude */
        tn_insolation_opts io;
        tn_image ins = {0, 0, 0, NULL};
        memset(&io, 0, sizeof io);
        io.dx = dx[k];
        if (!d.climates[k].has_latitude) {
            st = tn__fail(TN_ERR_INVALID_ARG, "%s: site %d has no latitude (a latitude row, or a climate that has one)", path, k + 1);
            break;
        }
        if ((st = tn_insolation(&ins, &d.dems[k], d.climates[k].latitude, &io))) break;
        d.insolation[k] = ins;
    }
    TN_FREE(dx);
    if (st) {
        TN_FREE(site_of);
        tn_season_data_free(&d);
        return st;
    }
    for (k = 0; k < d.count; k++) {
        tn_season_sample *q = &d.samples[k];
        int s_ = site_of[k];
        q->dem = &d.dems[s_];
        q->insolation = &d.insolation[s_];
        q->climate = &d.climates[s_];
        q->target = &d.targets[k];
        q->mask = &d.masks[k];
    }
    TN_FREE(site_of);
    d.lo = lo;
    d.hi = hi;
    *out = d;
    return TN_OK;
}
#endif /* TN_NO_SEASON */

