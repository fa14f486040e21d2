/* @@season: insolation against the closed forms (flat plane, tilted planes), terrain shadows,
   thread-count independence, the climate CSV and presets, the seasonal texturer's snow and
   vegetation, and bad input. */
#include "terrainnet.h"
#include "tn_test.h"

#define PI 3.14159265358979323846

/* Daily extraterrestrial insolation on a horizontal plane (W h/m^2): (24/pi) Gsc E0
   (cos phi cos d sin ws + ws sin phi sin d), ws = acos(-tan phi tan d) (Duffie & Beckman 1.10.3). */
static double flat_h0(double lat_deg, int doy)
{
    double d, e, phi = lat_deg * PI / 180.0, c, ws;
    tn_sun_day(&d, &e, doy);
    c = -tan(phi) * tan(d);
    ws = c <= -1 ? PI : c >= 1 ? 0 : acos(c);
    return 24.0 / PI * 1367.0 * e * (cos(phi) * cos(d) * sin(ws) + ws * sin(phi) * sin(d));
}

/* A south-facing plane of slope beta (north hemisphere): the horizontal at latitude phi - beta,
   with the sunset hour angle min(ws(phi), ws(phi - beta)) (Klein 1977). */
static double south_plane_h0(double lat_deg, double beta_deg, int doy)
{
    double d, e, phi = lat_deg * PI / 180.0, pb = (lat_deg - beta_deg) * PI / 180.0, c1, c2, w1, w2, ws;
    tn_sun_day(&d, &e, doy);
    c1 = -tan(phi) * tan(d);
    c2 = -tan(pb) * tan(d);
    w1 = c1 <= -1 ? PI : c1 >= 1 ? 0 : acos(c1);
    w2 = c2 <= -1 ? PI : c2 >= 1 ? 0 : acos(c2);
    ws = w1 < w2 ? w1 : w2;
    return 24.0 / PI * 1367.0 * e * (cos(pb) * cos(d) * sin(ws) + ws * sin(pb) * sin(d));
}

/* A brute-force reference for any plane: the sun vector every 2 s of the day. */
static double plane_numeric(double lat_deg, double nE, double nN, double nU, int doy)
{
    double d, e, phi = lat_deg * PI / 180.0, sum = 0, dw = 2.0 * PI / 43200.0;
    int i;
    tn_sun_day(&d, &e, doy);
    for (i = 0; i < 43200; i++) {
        double w = -PI + (i + 0.5) * dw;
        double sE = -cos(d) * sin(w), sN = cos(phi) * sin(d) - sin(phi) * cos(d) * cos(w), sU = sin(phi) * sin(d) + cos(phi) * cos(d) * cos(w);
        double ci = nE * sE + nN * sN + nU * sU;
        if (sU > 0 && ci > 0) sum += ci * dw;
    }
    return 1367.0 * e * 24.0 / (2.0 * PI) * sum;
}

/* A plane z = a x_east + b y_north (metres) on a w x h grid of spacing sp. */
static tn_image plane(int w, int h, float sp, double a, double b)
{
    tn_image im = {0, 0, 0, NULL};
    int x, y;
    tn_image_create(&im, w, h, 1);
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++) im.data[(size_t)y * w + x] = (float)(1000.0 + a * x * sp + b * (h - 1 - y) * sp);
    return im;
}

TN_TEST(test_flat_plane_matches_formula)
{
    static const double lats[] = {0.0, 45.87, -33.9, 68.0, 80.0, -89.0};
    tn_image dem = plane(8, 8, 30.0f, 0, 0), out = {0, 0, 0, NULL};
    tn_insolation_opts o;
    size_t li;
    int m;
    memset(&o, 0, sizeof o);
    o.dx = 30.0f;
    for (li = 0; li < sizeof lats / sizeof lats[0]; li++) {
        TN_CHECK(tn_insolation(&out, &dem, lats[li], &o) == TN_OK);
        TN_CHECK(out.channels == 12);
        for (m = 0; m < 12 && out.data; m++) {
            double ref = flat_h0(lats[li], tn_day_of_year(m + 1, 15));
            TN_CHECK_NEAR(TN_PIXEL(&out, 4, 4, m), ref, 1e-4 * ref + 0.05);
            TN_CHECK_NEAR(TN_PIXEL(&out, 0, 7, m), ref, 1e-4 * ref + 0.05); /* border pixels too */
        }
        tn_image_free(&out);
    }
    /* the textbook value: 45.87 N in mid-June about 11.6 kWh/m^2, mid-December about 2.3 */
    TN_CHECK(flat_h0(45.87, 166) > 11000 && flat_h0(45.87, 166) < 12000);
    TN_CHECK(flat_h0(45.87, 349) > 2500 && flat_h0(45.87, 349) < 3500);
    tn_image_free(&dem);
}

TN_TEST(test_tilted_planes)
{
    tn_insolation_opts o;
    tn_image out = {0, 0, 0, NULL};
    int m, sh;
    double beta = 30.0, g = tan(beta * PI / 180.0);
    memset(&o, 0, sizeof o);
    o.dx = 10.0f;
    for (sh = 0; sh < 2; sh++) { /* without and with the horizon test (a plane shades nothing but itself) */
        tn_image south = plane(24, 24, 10.0f, 0, g); /* rises to the north: faces south */
        tn_image east = plane(24, 24, 10.0f, -0.5, 0.2);
        double inv = 1.0 / sqrt(0.25 + 0.04 + 1.0);
        o.no_shadows = !sh;
        TN_CHECK(tn_insolation(&out, &south, 46.0, &o) == TN_OK);
        for (m = 0; m < 12 && out.data; m++) {
            double ref = south_plane_h0(46.0, beta, tn_day_of_year(m + 1, 15));
            TN_CHECK_NEAR(TN_PIXEL(&out, 12, 12, m), ref, (sh ? 2e-3 : 1e-4) * ref + 0.05);
        }
        tn_image_free(&out);
        TN_CHECK(tn_insolation(&out, &east, -20.0, &o) == TN_OK);
        for (m = 0; m < 12 && out.data; m++) {
            double ref = plane_numeric(-20.0, 0.5 * inv, -0.2 * inv, inv, tn_day_of_year(m + 1, 15));
            TN_CHECK_NEAR(TN_PIXEL(&out, 12, 12, m), ref, (sh ? 3e-3 : 2e-4) * ref + 0.5);
        }
        tn_image_free(&out);
        tn_image_free(&south);
        tn_image_free(&east);
    }
}

TN_TEST(test_wall_shadow_and_threads)
{
    /* flat ground with a 100 m wall along the south edge: in December at 46 N (noon sun 20.7
       degrees high) its foot (50 m away, 63 degrees) is in shadow all day, the north edge
       (580 m, 10 degrees) only early and late; in June the foot is lit most of the day */
    tn_image dem = plane(64, 64, 10.0f, 0, 0), a = {0, 0, 0, NULL}, b = {0, 0, 0, NULL};
    tn_insolation_opts o;
    int x, y;
    size_t i, n;
    for (y = 60; y < 64; y++)
        for (x = 0; x < 64; x++) dem.data[y * 64 + x] += 100.0f;
    memset(&o, 0, sizeof o);
    o.dx = 10.0f;
    tn_set_threads(1);
    TN_CHECK(tn_insolation(&a, &dem, 46.0, &o) == TN_OK);
    tn_set_threads(2);
    TN_CHECK(tn_insolation(&b, &dem, 46.0, &o) == TN_OK);
    tn_set_threads(0);
    if (!a.data || !b.data) return;
    n = (size_t)64 * 64 * 12;
    for (i = 0; i < n; i++) if (a.data[i] != b.data[i]) break;
    TN_CHECK(i == n);
    TN_CHECK(TN_PIXEL(&a, 32, 55, 11) < 0.05 * flat_h0(46.0, 349));
    TN_CHECK(TN_PIXEL(&a, 32, 2, 11) > 0.85 * flat_h0(46.0, 349) && TN_PIXEL(&a, 32, 2, 11) < flat_h0(46.0, 349));
    TN_CHECK(TN_PIXEL(&a, 32, 55, 5) > 0.6 * flat_h0(46.0, 166));
    /* one month alone equals that month of the year */
    o.month = 12;
    tn_image_free(&b);
    TN_CHECK(tn_insolation(&b, &dem, 46.0, &o) == TN_OK);
    TN_CHECK(b.channels == 1 && b.data && b.data[55 * 64 + 32] == TN_PIXEL(&a, 32, 55, 11));
    tn_image_free(&a);
    tn_image_free(&b);
    tn_image_free(&dem);
}

TN_TEST(test_insolation_bad_input)
{
    tn_image dem = plane(8, 8, 1.0f, 0, 0), out = {0, 0, 0, NULL}, tiny = {0, 0, 0, NULL};
    tn_insolation_opts o;
    memset(&o, 0, sizeof o);
    TN_CHECK(tn_insolation(&out, &dem, 91.0, NULL) == TN_ERR_INVALID_ARG);
    TN_CHECK(strstr(tn_last_error(), "latitude") != NULL);
    TN_CHECK(tn_insolation(&out, &dem, NAN, NULL) == TN_ERR_INVALID_ARG);
    o.month = 13;
    TN_CHECK(tn_insolation(&out, &dem, 10.0, &o) == TN_ERR_INVALID_ARG);
    o.month = 2;
    o.day = 30;
    TN_CHECK(tn_insolation(&out, &dem, 10.0, &o) == TN_ERR_INVALID_ARG);
    o.day = 0;
    o.dx = -1;
    TN_CHECK(tn_insolation(&out, &dem, 10.0, &o) == TN_ERR_INVALID_ARG);
    dem.data[5] = NAN;
    TN_CHECK(tn_insolation(&out, &dem, 10.0, NULL) == TN_ERR_NUMERIC);
    tn_image_create(&tiny, 1, 5, 1);
    TN_CHECK(tn_insolation(&out, &tiny, 10.0, NULL) == TN_ERR_EMPTY);
    TN_CHECK(out.data == NULL);
    tn_image_free(&tiny);
    tn_image_free(&dem);
}

TN_TEST(test_climate_csv)
{
    static const char good[] = "# Ljubljana-like\nlatitude, 45.9\nelevation,299\nmonth,t_c,p_mm\n"
                               "1,-0.3,69\n2,1.6,70\n3,6,89\n4,10.6,98\n5,15.6,109\n6,19.1,143\n7,21.1,113\n8,20.4,133\n"
                               "9,15.6,147\n10,10.9,144\n11,5,129\n12,0.8,100\n";
    tn_climate c;
    char buf[1024];
    char *p;
    TN_CHECK(tn_climate_parse(&c, good, strlen(good), "good.csv") == TN_OK);
    TN_CHECK(c.has_latitude && fabs(c.latitude - 45.9f) < 1e-5 && c.elevation == 299.0f);
    TN_CHECK(c.t[0] == -0.3f && c.p[11] == 100.0f);
    /* the lapse rate: 1299 m is 6 C colder than the station */
    TN_CHECK_NEAR(tn_climate_temperature(&c, 6, 1299.0f, 0.0f), 21.1 - 6.0, 1e-4);
    /* eleven months */
    snprintf(buf, sizeof buf, "%s", good);
    p = strstr(buf, "12,0.8,100\n");
    *p = 0;
    TN_CHECK(tn_climate_parse(&c, buf, strlen(buf), "eleven.csv") == TN_ERR_FORMAT);
    TN_CHECK(strstr(tn_last_error(), "11 given") != NULL && strstr(tn_last_error(), "month 12") != NULL);
    /* NaN */
    snprintf(buf, sizeof buf, "%s", good);
    memcpy(strstr(buf, "4,10.6,98"), "4,nan ,98", 9);
    TN_CHECK(tn_climate_parse(&c, buf, strlen(buf), "nan.csv") == TN_ERR_NUMERIC);
    TN_CHECK(strstr(tn_last_error(), "nan.csv:8") != NULL);
    /* latitude out of range, a month twice, garbage */
    snprintf(buf, sizeof buf, "%s", good);
    memcpy(strstr(buf, "45.9"), "95.9", 4);
    TN_CHECK(tn_climate_parse(&c, buf, strlen(buf), "lat.csv") == TN_ERR_INVALID_ARG);
    TN_CHECK(strstr(tn_last_error(), "latitude") != NULL);
    snprintf(buf, sizeof buf, "%s", good);
    memcpy(strstr(buf, "\n2,1.6"), "\n1,1.6", 6);
    TN_CHECK(tn_climate_parse(&c, buf, strlen(buf), "twice.csv") == TN_ERR_FORMAT);
    TN_CHECK(tn_climate_parse(&c, "1,2\n", 4, "short.csv") == TN_ERR_FORMAT);
    TN_CHECK(tn_climate_load(&c, "/nonexistent/climate.csv") == TN_ERR_IO);
}

TN_TEST(test_koppen_presets)
{
    tn_climate c;
    int i, m, n = 0;
    const char *code;
    for (i = 0; (code = tn_climate_koppen_code(i)) != NULL; i++, n++) {
        float lo = 1e9f, hi = -1e9f, ptot = 0;
        TN_CHECK(tn_climate_koppen(&c, code) == TN_OK);
        TN_CHECK(tn_climate_check(&c) == TN_OK && c.has_latitude);
        for (m = 0; m < 12; m++) {
            if (c.t[m] < lo) lo = c.t[m];
            if (c.t[m] > hi) hi = c.t[m];
            ptot += c.p[m];
        }
        /* each preset satisfies its own group's Koppen rule */
        if (code[0] == 'A') TN_CHECK(lo >= 18.0f);
        if (code[0] == 'B') TN_CHECK(ptot < 200.0f);
        if (code[0] == 'C') TN_CHECK(lo > -3.0f && lo < 18.0f && hi >= 10.0f);
        if (code[0] == 'D') TN_CHECK(lo <= -3.0f && hi >= 10.0f);
        if (code[0] == 'E') TN_CHECK(hi < 10.0f);
    }
    TN_CHECK(n >= 5);
    TN_CHECK(tn_climate_koppen(&c, "D") == TN_OK && strncmp(c.name, "Dfc", 3) == 0);
    TN_CHECK(tn_climate_koppen(&c, "cfb") == TN_OK && c.latitude > 45);
    TN_CHECK(tn_climate_koppen(&c, "Xyz") == TN_ERR_INVALID_ARG);
}

/* a cone 200 m .. 2600 m high on 10 km, pixels 80 m */
static tn_image cone(int n)
{
    tn_image im = {0, 0, 0, NULL};
    int x, y;
    tn_image_create(&im, n, n, 1);
    for (y = 0; y < n; y++)
        for (x = 0; x < n; x++) {
            double r = sqrt((x - n / 2.0) * (x - n / 2.0) + (y - n / 2.0) * (y - n / 2.0)) / (n / 2.0);
            im.data[y * n + x] = (float)(200.0 + 2400.0 * (r < 1 ? 1 - r : 0));
        }
    return im;
}

TN_TEST(test_season_snow_and_green)
{
    tn_image dem = cone(48), out[3], bad = {0, 0, 0, NULL};
    tn_season_state st[3];
    tn_season_opts o;
    tn_climate c;
    float times[3] = {0.0f, 6.0f, 3.0f}; /* mid-January, mid-July, mid-April */
    int n = 48;
    memset(&o, 0, sizeof o);
    o.insolation.dx = 80.0f;
    o.insolation.step_minutes = 30.0f;
    o.insolation.directions = 16;
    TN_CHECK(tn_climate_koppen(&c, "Cfb") == TN_OK);
    TN_CHECK(tn_season_texture(out, &dem, &c, NAN, NULL, times, 3, &o, st) == TN_OK);
    if (!out[0].data) return;
    /* January: snow on the summit, little in the lowland corner; July: none on the lowland */
    TN_CHECK(TN_PIXEL(&st[0].snow, n / 2, n / 2, 0) > 50.0f);
    TN_CHECK(TN_PIXEL(&st[0].snow, 0, 0, 0) < TN_PIXEL(&st[0].snow, n / 2, n / 2, 0) * 0.2f);
    TN_CHECK(TN_PIXEL(&st[1].snow, 0, 0, 0) < 1.0f);
    /* greenness: lowland summer greener than winter */
    TN_CHECK(TN_PIXEL(&st[1].green, 0, 0, 0) > TN_PIXEL(&st[0].green, 0, 0, 0) + 0.3f);
    /* mid-April at mid-height: the north face keeps more snow than the south face */
    TN_CHECK(TN_PIXEL(&st[2].snow, n / 2, n / 2 - 12, 0) > TN_PIXEL(&st[2].snow, n / 2, n / 2 + 12, 0) + 1.0f);
    /* colours in range; the snowy summit is brighter in winter than the lowland in summer */
    TN_CHECK(TN_PIXEL(&out[0], n / 2, n / 2, 2) > TN_PIXEL(&out[1], 0, 0, 2));
    tn_image_free(&out[0]); tn_image_free(&out[1]); tn_image_free(&out[2]);
    tn_season_state_free(&st[0]); tn_season_state_free(&st[1]); tn_season_state_free(&st[2]);
    /* bad input: a wrong-sized insolation, no latitude, NaN time */
    tn_image_create(&bad, 47, 48, 12);
    TN_CHECK(tn_season_texture(out, &dem, &c, NAN, &bad, times, 1, &o, NULL) == TN_ERR_SHAPE);
    TN_CHECK(strstr(tn_last_error(), "insolation") != NULL);
    tn_image_free(&bad);
    c.has_latitude = 0;
    TN_CHECK(tn_season_texture(out, &dem, &c, NAN, NULL, times, 1, &o, NULL) == TN_ERR_INVALID_ARG);
    times[0] = NAN;
    TN_CHECK(tn_season_texture(out, &dem, &c, 46.0, NULL, times, 1, &o, NULL) == TN_ERR_NUMERIC);
    c.t[3] = NAN;
    times[0] = 0;
    TN_CHECK(tn_season_texture(out, &dem, &c, 46.0, NULL, times, 1, &o, NULL) == TN_ERR_NUMERIC);
    tn_image_free(&dem);
}

TN_TEST(test_season_real_dem)
{
    tn_image dem = {0, 0, 0, NULL}, out[2];
    tn_season_state st[2];
    tn_season_opts o;
    tn_climate c;
    float times[2] = {1.0f, 7.0f};
    double s0 = 0, s1 = 0;
    size_t i, n;
    if (tn_image_load(&dem, tn_test_data("dem/alps_montblanc/alps_montblanc_128.png"), NULL)) TN_SKIP("no ../shared/data");
    n = (size_t)dem.width * dem.height;
    for (i = 0; i < n; i++) dem.data[i] = 454.0f + dem.data[i] * (4810.0f - 454.0f); /* MANIFEST.md's mapping */
    memset(&o, 0, sizeof o);
    o.insolation.dx = 92.7f;
    o.insolation.step_minutes = 30.0f;
    TN_CHECK(tn_climate_koppen(&c, "Cfb") == TN_OK);
    TN_CHECK(tn_season_texture(out, &dem, &c, 45.8, NULL, times, 2, &o, st) == TN_OK);
    if (!out[0].data) { tn_image_free(&dem); return; }
    for (i = 0; i < n; i++) { s0 += st[0].snow.data[i] > 10.0f; s1 += st[1].snow.data[i] > 10.0f; }
    /* Mont Blanc: most of the 560-4240 m crop is snowy in February, far less in August, and
       the highest ground keeps snow through summer */
    printf("# alps_montblanc_128 (Cfb, 45.8 N): snowy share %.3f in February, %.3f in August\n", s0 / n, s1 / n);
    TN_CHECK(s0 / n > 0.7 && s1 / n < 0.5 * s0 / n && s1 > 0);
    tn_image_free(&out[0]); tn_image_free(&out[1]);
    tn_season_state_free(&st[0]); tn_season_state_free(&st[1]);
    tn_image_free(&dem);
}

/* ---- KPD generator ---- */

static int same_image(const tn_image *a, const tn_image *b)
{
    return a->data && b->data && a->width == b->width && a->height == b->height && a->channels == b->channels &&
           !memcmp(a->data, b->data, (size_t)a->width * a->height * a->channels * sizeof(float));
}

/* Any window equals those pixels of the whole map, at a month and between two months, and at 1
   and 2 threads; the file round trip keeps every weight. */
TN_TEST(test_kpd_window_equals_whole_map)
{
    tn_test_kpd_set k;
    tn_kpd_opts o;
    tn_kpd m, m2;
    tn_image whole = {0, 0, 0, NULL}, win = {0, 0, 0, NULL}, whole2 = {0, 0, 0, NULL}, between = {0, 0, 0, NULL};
    int x, y, c, ok = 1, moved = 0;
    const char *path = tn_test_tmp_path("season", "kpd.tnw");
    TN_CHECK(tn_test_kpd_set_make(&k, 72));
    tn_test_small_kpd_opts(&o, 4);
    TN_CHECK(tn_kpd_train(&m, k.s, 4, &o, NULL) == TN_OK);
    if (!m.weights) { tn_test_kpd_set_free(&k); return; }
    TN_CHECK(m.out_channels == 3 && m.cond_channels == 39 && m.iterations == 4);
    tn_set_threads(2);
    TN_CHECK(tn_kpd_generate(&whole, &m, &k.dem, &k.c, &k.ins, 4.0f, 0, 0, 72, 72) == TN_OK);
    TN_CHECK(tn_kpd_generate(&win, &m, &k.dem, &k.c, &k.ins, 4.0f, 21, 38, 30, 27) == TN_OK);
    for (y = 0; y < 27 && whole.data && win.data; y++)
        for (x = 0; x < 30; x++)
            for (c = 0; c < 3; c++) ok &= TN_PIXEL(&win, x, y, c) == TN_PIXEL(&whole, 21 + x, 38 + y, c);
    TN_CHECK(ok);
    tn_set_threads(1);
    TN_CHECK(tn_kpd_generate(&whole2, &m, &k.dem, &k.c, &k.ins, 4.0f, 0, 0, 72, 72) == TN_OK);
    TN_CHECK(same_image(&whole, &whole2));
    tn_image_free(&whole2);
    TN_CHECK(tn_kpd_generate(&whole2, &m, &k.dem, &k.c, &k.ins, 16.0f, 0, 0, 72, 72) == TN_OK); /* a year later */
    TN_CHECK(same_image(&whole, &whole2));
    /* between April and May: not April's picture, and a window still equals the whole map */
    TN_CHECK(tn_kpd_generate(&between, &m, &k.dem, &k.c, &k.ins, 3.5f, 0, 0, 72, 72) == TN_OK);
    tn_image_free(&win);
    TN_CHECK(tn_kpd_generate(&win, &m, &k.dem, &k.c, &k.ins, 3.5f, 40, 9, 32, 50) == TN_OK);
    ok = 1;
    for (y = 0; y < 50 && between.data && win.data; y++)
        for (x = 0; x < 32; x++)
            for (c = 0; c < 3; c++) {
                ok &= TN_PIXEL(&win, x, y, c) == TN_PIXEL(&between, 40 + x, 9 + y, c);
                moved += TN_PIXEL(&between, 40 + x, 9 + y, c) != TN_PIXEL(&whole, 40 + x, 9 + y, c);
            }
    TN_CHECK(ok && moved > 0);
    tn_set_threads(0);
    TN_CHECK(tn_kpd_save(path, &m) == TN_OK);
    TN_CHECK(tn_kpd_load(&m2, path) == TN_OK);
    if (m2.weights) {
        TN_CHECK(m2.condition == TN_KPD_OURS && m2.h_offset == m.h_offset && m2.g_scale == m.g_scale && m2.iterations == 4);
        TN_CHECK(tn_test_same_params(m.weights, m2.weights, 0));
    }
    tn_kpd_free(&m2);
    tn_image_free(&whole);
    tn_image_free(&whole2);
    tn_image_free(&win);
    tn_image_free(&between);
    tn_kpd_free(&m);
    tn_test_kpd_set_free(&k);
    remove(path);
}

/* Training lowers the masked L1, and an interrupted run resumes bit-identically. */
TN_TEST(test_kpd_learns_and_resumes)
{
    tn_test_kpd_set k;
    tn_kpd_opts o;
    tn_kpd a, b;
    tn_kpd_stats st;
    const char *ck = tn_test_tmp_path("season", "kpd_ck.tnw");
    TN_CHECK(tn_test_kpd_set_make(&k, 48));
    tn_test_small_kpd_opts(&o, 40);
    o.gan_weight = -1; /* L1 only: a quick, steady descent */
    TN_CHECK(tn_kpd_train(&a, k.s, 4, &o, &st) == TN_OK);
    printf("# kpd L1 first %.4f, last 50 mean %.4f\n", st.loss_l1_first, st.loss_l1);
    TN_CHECK(st.loss_l1 < 0.7f * st.loss_l1_first);
    tn_kpd_free(&a);
    tn_test_small_kpd_opts(&o, 6);
    TN_CHECK(tn_kpd_train(&a, k.s, 4, &o, NULL) == TN_OK);
    remove(ck);
    tn_test_small_kpd_opts(&o, 3);
    o.train.checkpoint = ck;
    TN_CHECK(tn_kpd_train(&b, k.s, 4, &o, NULL) == TN_OK);
    tn_kpd_free(&b);
    o.train.max_iters = 6;
    o.train.resume = 1;
    o.train.seed = 99; /* the checkpoint's seed wins */
    TN_CHECK(tn_kpd_train(&b, k.s, 4, &o, &st) == TN_OK);
    TN_CHECK(st.resumed_from == 3 && st.iterations == 6);
    if (a.weights && b.weights) TN_CHECK(tn_test_same_params(a.weights, b.weights, 0));
    /* a checkpoint of these pictures refuses other pictures */
    k.s[0].time = 1.0f;
    TN_CHECK(tn_kpd_train(&a, k.s, 4, &o, NULL) == TN_ERR_SHAPE);
    tn_kpd_free(&a);
    tn_kpd_free(&b);
    tn_test_kpd_set_free(&k);
    remove(ck);
}

/* Resumes season-train from ck (3 more iterations of tn_test_small_kpd_opts on k). */
static tn_status kpd_resume(tn_test_kpd_set *k, const char *ck)
{
    tn_kpd_opts o;
    tn_kpd m;
    tn_status st;
    tn_test_small_kpd_opts(&o, 6);
    o.train.checkpoint = ck;
    o.train.resume = 1;
    st = tn_kpd_train(&m, k->s, 4, &o, NULL);
    if (!st) tn_kpd_free(&m);
    return st;
}

/* Writes a fresh 3-iteration checkpoint of k to ck, then changes kpd.config[index] (CRC valid)
   or, with index < 0, the metadata entry named ...`key`. */
static int kpd_patched_checkpoint(tn_test_kpd_set *k, const char *ck, int index, float value, const char *key, const char *text)
{
    tn_kpd_opts o;
    tn_kpd m;
    tn_params *p = NULL;
    tn_tensor *c;
    int ok, i;
    remove(ck);
    tn_test_small_kpd_opts(&o, 3);
    o.train.checkpoint = ck;
    if (tn_kpd_train(&m, k->s, 4, &o, NULL)) return 0;
    tn_kpd_free(&m);
    ok = tn_params_open(&p, ck) == TN_OK && (c = tn_params_find(p, "kpd.config")) != NULL;
    if (ok && index >= 0) c->data[index] = value;
    for (i = 0; ok && index < 0 && i < tn_params_meta_count(p); i++) {
        const char *v, *name = tn_params_meta_key(p, i, &v);
        size_t n = strlen(name), kn = strlen(key);
        if (n >= kn && !strcmp(name + n - kn, key)) {
            char full[128];
            snprintf(full, sizeof full, "%s", name);
            ok = tn_params_set_meta(p, full, text) == TN_OK;
            index = 0;
        }
    }
    ok = ok && index >= 0 && tn_params_save(ck, p) == TN_OK;
    tn_params_free(p);
    return ok;
}

/* A resume whose checkpoint config was changed (issue 33): refused on the checkpoint's own
   tensors before anything is built from the config, at once, under a 64 MB budget, nothing left
   allocated. Before, the 256-wide generator (66 MB with its Adam moments and critic) was built
   first and the budget stopped it with "out of memory". */
static int kpd_resume_refused(tn_test_kpd_set *k, const char *ck, const char *why)
{
    double t0 = tn_time_seconds();
    size_t base = tn_memory_in_use();
    tn_status st;
    tn_set_memory_limit((size_t)64 << 20);
    tn_clear_error();
    st = kpd_resume(k, ck);
    tn_set_memory_limit(0);
    fprintf(stderr, "   %s (%.2f s)\n", tn_last_error(), tn_time_seconds() - t0);
    return st == TN_ERR_CORRUPT && strstr(tn_last_error(), why) && tn_time_seconds() - t0 < 5.0 && tn_memory_in_use() == base;
}

TN_TEST(test_kpd_resume_config_sizes)
{
    tn_test_kpd_set k;
    const char *ck = tn_test_tmp_path("season", "kpd_resume.ckpt");
    TN_CHECK(tn_test_kpd_set_make(&k, 48));
    /* the checkpoint as written resumes */
    TN_CHECK(kpd_patched_checkpoint(&k, ck, 4, 8.0f, NULL, NULL) && kpd_resume(&k, ck) == TN_OK);
    /* the widest generator over the 8-wide one's tensors */
    TN_CHECK(kpd_patched_checkpoint(&k, ck, 4, 256.0f, NULL, NULL) && kpd_resume_refused(&k, ck, "names a generator 256 wide"));
    /* a value range that overflows */
    TN_CHECK(kpd_patched_checkpoint(&k, ck, 5, -3e38f, NULL, NULL));
    {
        tn_params *p = NULL;
        tn_tensor *c;
        if (tn_params_open(&p, ck) == TN_OK && (c = tn_params_find(p, "kpd.config"))) {
            c->data[6] = 3e38f;
            TN_CHECK(tn_params_save(ck, p) == TN_OK);
        }
        tn_params_free(p);
        TN_CHECK(kpd_resume_refused(&k, ck, "damaged kpd.config"));
    }
    /* training windows that do not pool by 8 */
    TN_CHECK(kpd_patched_checkpoint(&k, ck, -1, 0, "crop", "36") && kpd_resume_refused(&k, ck, "bad crop 36"));
    tn_test_kpd_set_free(&k);
    remove(ck);
}

TN_TEST(test_kpd_bad_input)
{
    tn_test_kpd_set k;
    tn_kpd_opts o;
    tn_kpd m;
    tn_image out = {0, 0, 0, NULL}, small = {0, 0, 0, NULL};
    tn_season_data d;
    char p[512], other[512];
    FILE *f;
    float keep;
    snprintf(p, sizeof p, "%s", tn_test_tmp_path("season", "bad.csv"));
    snprintf(other, sizeof other, "%s", tn_test_tmp_path("season", "other.tnw"));
    TN_CHECK(tn_test_kpd_set_make(&k, 40));
    tn_test_small_kpd_opts(&o, 1);
    TN_CHECK(tn_kpd_train(&m, NULL, 0, &o, NULL) == TN_ERR_EMPTY);
    keep = k.tex[1].data[5];
    k.tex[1].data[5] = NAN; /* pixel 5 is valid */
    TN_CHECK(tn_kpd_train(&m, k.s, 4, &o, NULL) == TN_ERR_NUMERIC);
    k.tex[1].data[0] = NAN; /* pixel 0 is masked: allowed */
    k.tex[1].data[5] = keep;
    TN_CHECK(tn_kpd_train(&m, k.s, 4, &o, NULL) == TN_OK);
    TN_CHECK(tn_image_create(&small, 20, 40, 1) == TN_OK);
    k.s[2].mask = &small;
    TN_CHECK(tn_kpd_train(&m, k.s, 4, &o, NULL) == TN_ERR_SHAPE);
    k.s[2].mask = &k.mask;
    k.s[3].insolation = NULL;
    TN_CHECK(tn_kpd_train(&m, k.s, 4, &o, NULL) == TN_ERR_SHAPE);
    k.s[3].insolation = &k.ins;
    o.crop = 20; /* not a multiple of 8 */
    TN_CHECK(tn_kpd_train(&m, k.s, 4, &o, NULL) == TN_ERR_INVALID_ARG);
    TN_CHECK(strcmp(tn_last_error(), "season-train: option crop = 20, allowed a multiple of 8") == 0);
    if (m.weights) {
        TN_CHECK(tn_kpd_generate(&out, &m, &k.dem, &k.c, NULL, 2.0f, 0, 0, 40, 40) == TN_ERR_SHAPE);
        TN_CHECK(tn_kpd_generate(&out, &m, &k.dem, &k.c, &k.ins, NAN, 0, 0, 40, 40) == TN_ERR_NUMERIC);
        TN_CHECK(tn_kpd_generate(&out, &m, &k.dem, &k.c, &k.ins, 2.0f, 30, 0, 20, 40) == TN_ERR_INVALID_ARG);
        keep = k.dem.data[7];
        k.dem.data[7] = NAN;
        TN_CHECK(tn_kpd_generate(&out, &m, &k.dem, &k.c, &k.ins, 2.0f, 0, 0, 40, 40) == TN_ERR_NUMERIC);
        TN_CHECK(out.data == NULL);
        k.dem.data[7] = keep;
    }
    tn_kpd_free(&m);
    /* another method's model file */
    {
        tn_params *q = tn_params_create();
        int one = 1;
        tn_model_provenance pv;
        memset(&pv, 0, sizeof pv);
        tn_params_add(q, "singan.config", 1, &one);
        tn_model_stamp(q, "singan", 1, &pv);
        TN_CHECK(tn_params_save(other, q) == TN_OK);
        tn_params_free(q);
        TN_CHECK(tn_kpd_load(&m, other) == TN_ERR_FORMAT);
        TN_CHECK(m.weights == NULL);
    }
    /* data files: a climate of 11 months, an unknown row, a mask of the wrong size */
    TN_CHECK(tn_test_write_text(p, "dem,nothing_here.pfm\n"));
    TN_CHECK(tn_season_data_load(&d, p) == TN_ERR_IO);
    TN_CHECK(tn_image_save(tn_test_tmp_path("season", "d.pfm"), &k.dem, NULL) == TN_OK);
    TN_CHECK(tn_image_save(tn_test_tmp_path("season", "m.pgm"), &small, NULL) == TN_OK);
    TN_CHECK(tn_image_save(tn_test_tmp_path("season", "t.pfm"), &k.tex[0], NULL) == TN_OK);
    if ((f = fopen(tn_test_tmp_path("season", "c.csv"), "w"))) {
        int mth;
        for (mth = 1; mth <= 11; mth++) fprintf(f, "%d,%d,50\n", mth, mth);
        fclose(f);
    }
    tn_test_write_text(p, "dem,tn_test_season_d.pfm\nclimate,tn_test_season_c.csv\n");
    TN_CHECK(tn_season_data_load(&d, p) == TN_ERR_FORMAT);
    printf("# %s\n", tn_last_error());
    tn_test_write_text(p, "dem,tn_test_season_d.pfm\nkoppen,Dfb\nsnow,1\n");
    TN_CHECK(tn_season_data_load(&d, p) == TN_ERR_FORMAT);
    tn_test_write_text(p, "dem,tn_test_season_d.pfm\nkoppen,Dfb\nframe,2017-02-30,tn_test_season_t.pfm\n");
    TN_CHECK(tn_season_data_load(&d, p) == TN_ERR_FORMAT);
    tn_test_write_text(p, "dem,tn_test_season_d.pfm\nkoppen,Dfb\nframe,2017-02-03,tn_test_season_t.pfm,tn_test_season_m.pgm\n");
    TN_CHECK(tn_season_data_load(&d, p) == TN_ERR_SHAPE);
    tn_test_write_text(p, "range,0,1\ndem,tn_test_season_d.pfm\nspacing,30\nkoppen,Dfb\nframe,2017-02-03,tn_test_season_t.pfm\nframe,4.5,tn_test_season_t.pfm\n");
    TN_CHECK(tn_season_data_load(&d, p) == TN_OK);
    if (!d.count) fprintf(stderr, "%s\n", tn_last_error());
    TN_CHECK(d.count == 2 && d.sites == 1 && d.samples[1].time == 4.5f && d.insolation[0].channels == 12);
    if (d.count == 2) TN_CHECK(fabsf(d.samples[0].time - (1.0f + (3.0f - 15.0f) / 28.0f)) < 1e-6f);
    tn_season_data_free(&d);
    remove(p);
    remove(other);
    remove(tn_test_tmp_path("season", "d.pfm"));
    remove(tn_test_tmp_path("season", "m.pgm"));
    remove(tn_test_tmp_path("season", "t.pfm"));
    remove(tn_test_tmp_path("season", "c.csv"));
    tn_image_free(&small);
    tn_test_kpd_set_free(&k);
}

/* The real Sentinel-2 set: cloudy frames are left out, dates become times of the year. */
TN_TEST(test_season_data_slovenia)
{
    tn_season_data d;
    int i, n2015 = 0;
    if (!tn_test_data("seasonal_slovenia/frames.csv")) TN_SKIP("no ../shared/data");
    TN_CHECK(tn_season_data_load(&d, "examples/data/slovenia_season.csv") == TN_OK);
    if (!d.count) return;
    /* 47 acquisitions, 15 entirely under cloud */
    TN_CHECK(d.count == 32 && d.sites == 1 && d.lo == -0.2f && d.hi == 0.9f);
    TN_CHECK(d.dems[0].width == 100 && d.dems[0].height == 101 && d.insolation[0].channels == 12);
    for (i = 0; i < d.count; i++) {
        n2015 += !strncmp(d.labels[i], "2015", 4);
        TN_CHECK(d.samples[i].time >= 0 && d.samples[i].time < 12);
    }
    TN_CHECK(n2015 == 5);
    /* south-facing slopes get more sun in December than north-facing ones: the insolation's
       spread is real */
    {
        float lo = 1e9f, hi = -1e9f;
        size_t p;
        for (p = 0; p < 100 * 101; p++) {
            float v = d.insolation[0].data[p * 12 + 11];
            lo = v < lo ? v : lo;
            hi = v > hi ? v : hi;
        }
        TN_CHECK(hi > 1.3f * lo);
    }
    tn_season_data_free(&d);
}

int main(void)
{
    TN_RUN(test_flat_plane_matches_formula);
    TN_RUN(test_tilted_planes);
    TN_RUN(test_wall_shadow_and_threads);
    TN_RUN(test_insolation_bad_input);
    TN_RUN(test_climate_csv);
    TN_RUN(test_koppen_presets);
    TN_RUN(test_season_snow_and_green);
    TN_RUN(test_season_real_dem);
    TN_RUN(test_kpd_window_equals_whole_map);
    TN_RUN(test_kpd_learns_and_resumes);
    TN_RUN(test_kpd_resume_config_sizes);
    TN_RUN(test_kpd_bad_input);
    TN_RUN(test_season_data_slovenia);
    return tn_test_summary("test_season");
}
