/* test_export.c - @@export: .glb structure (header, chunks, accessors, bounds), geometry
   (normals up, counter-clockwise triangles seen from above, decimation keeps the last sample),
   OBJ counts and its material files, bad input, normal maps (OpenGL vs DirectX green), Unity
   RAW (size rule, full code range), splat maps (weights sum to 1, rock on steep slopes, snow
   high, vegetation low, masks replace the height rules, bad input). Validity by the Khronos glTF validator is
   checked in test_cli.sh when the validator is installed. */
#include "terrainnet.h"
#include "tn_test.h"

static uint32_t le32(const uint8_t *p) { return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24); }

static float lef(const uint8_t *p)
{
    uint32_t u = le32(p);
    float f;
    memcpy(&f, &u, 4);
    return f;
}

/* A tilted plane with a bump: heights rise to the east, so every normal leans west. */
static tn_image slope_dem(int w, int h)
{
    tn_image d = {0, 0, 0, NULL};
    int x, y;
    if (tn_image_create(&d, w, h, 1)) return d;
    for (y = 0; y < h; y++)
        for (x = 0; x < w; x++) TN_PIXEL(&d, x, y, 0) = 100.0f + 2.0f * (float)x + 0.5f * (float)((x * 7 + y * 3) % 5);
    return d;
}

/* Reads the .glb's JSON count of accessor `i` (the n-th "count":). */
static long json_count(const char *js, int i)
{
    const char *p = js;
    int k;
    for (k = 0; k <= i; k++) {
        p = strstr(p, "\"count\":");
        if (!p) return -1;
        p += 8;
    }
    return atol(p);
}

TN_TEST(glb_structure_and_geometry)
{
    const char *path = tn_test_tmp_path("export", "plane.glb");
    tn_image dem = slope_dem(10, 7), tex = {0, 0, 0, NULL};
    tn_mesh_opts o;
    uint8_t *b;
    size_t n, i;
    uint32_t jlen, blen;
    const uint8_t *bin;
    char *js;
    long nv, ni;
    int up = 1, ccw = 1;
    memset(&o, 0, sizeof o);
    o.dx = 30.0f;
    o.step = 3; /* samples 0 3 6 9 across, 0 3 6 down: 4 x 3 vertices */
    TN_CHECK(tn_image_create(&tex, 5, 4, 3) == TN_OK);
    o.texture = &tex;
    TN_CHECK(tn_export_glb(path, &dem, &o) == TN_OK);
    b = tn_test_read_file(path, &n);
    TN_CHECK(b && n > 20 && !memcmp(b, "glTF", 4) && le32(b + 4) == 2 && le32(b + 8) == n);
    if (!b || n < 28) return;
    jlen = le32(b + 12);
    TN_CHECK(!memcmp(b + 16, "JSON", 4) && jlen % 4 == 0);
    blen = le32(b + 20 + jlen);
    TN_CHECK(!memcmp(b + 24 + jlen, "BIN\0", 4) && blen % 4 == 0 && 28 + jlen + blen == n);
    js = (char *)malloc(jlen + 1);
    memcpy(js, b + 20, jlen);
    js[jlen] = 0;
    bin = b + 28 + jlen;
    nv = json_count(js, 0);
    ni = json_count(js, 3);
    TN_CHECK(nv == 12 && ni == 3 * 2 * 6);
    TN_CHECK(strstr(js, "\"mimeType\":\"image/png\"") != NULL && strstr(js, "\"baseColorTexture\"") != NULL);
    TN_CHECK(strstr(js, "\"max\":[270,") != NULL); /* the last column is kept: 9 * 30 m */
    if (nv == 12 && ni == 36) {
        const uint8_t *pos = bin, *nrm = bin + 12 * 12, *idx = bin + 12 * 12 * 2 + 12 * 8;
        TN_CHECK(lef(pos + 12 * 11) == 270.0f && lef(pos + 12 * 11 + 8) == 180.0f && lef(pos + 12 * 11 + 4) == TN_PIXEL(&dem, 9, 6, 0));
        for (i = 0; i < 12; i++) {
            float nx = lef(nrm + 12 * i), ny = lef(nrm + 12 * i + 4), nz = lef(nrm + 12 * i + 8);
            if (!(ny > 0 && nx < 0 && fabsf(nx * nx + ny * ny + nz * nz - 1.0f) < 1e-5f)) up = 0;
        }
        for (i = 0; i < 12; i++) { /* (b - a) x (c - a) must point up: counter-clockwise from above */
            const uint8_t *a = pos + 12 * le32(idx + 12 * i), *bb = pos + 12 * le32(idx + 12 * i + 4), *c = pos + 12 * le32(idx + 12 * i + 8);
            float ux = lef(bb) - lef(a), uz = lef(bb + 8) - lef(a + 8), vx = lef(c) - lef(a), vz = lef(c + 8) - lef(a + 8);
            if (!(uz * vx - ux * vz > 0)) ccw = 0;
        }
        TN_CHECK(up);
        TN_CHECK(ccw);
    }
    free(js);
    free(b);
    tn_image_free(&dem);
    tn_image_free(&tex);
    remove(path);
}

TN_TEST(obj_counts_and_material)
{
    const char *path = tn_test_tmp_path("export", "mesh.obj");
    const char *mtl = tn_test_tmp_path("export", "mesh.mtl"), *png = tn_test_tmp_path("export", "mesh.png");
    tn_image dem = slope_dem(6, 5), tex = {0, 0, 0, NULL}, back = {0, 0, 0, NULL};
    tn_mesh_opts o;
    uint8_t *b;
    size_t n;
    int v = 0, f = 0, vt = 0;
    char *p;
    memset(&o, 0, sizeof o);
    TN_CHECK(tn_image_create(&tex, 3, 2, 1) == TN_OK);
    tex.data[1] = 1.0f;
    o.texture = &tex;
    TN_CHECK(tn_export_obj(path, &dem, &o) == TN_OK);
    b = tn_test_read_file(path, &n);
    TN_CHECK(b != NULL);
    if (!b) return;
    for (p = (char *)b; p && *p; p = strchr(p, '\n') ? strchr(p, '\n') + 1 : NULL) {
        if (!strncmp(p, "v ", 2)) v++;
        if (!strncmp(p, "vt ", 3)) vt++;
        if (!strncmp(p, "f ", 2)) f++;
    }
    TN_CHECK(v == 30 && vt == 30 && f == 5 * 4 * 2);
    TN_CHECK(strstr((char *)b, "mtllib ") != NULL && strstr((char *)b, "usemtl terrain") != NULL);
    free(b);
    b = tn_test_read_file(mtl, &n);
    TN_CHECK(b && strstr((char *)b, "map_Kd ") != NULL);
    free(b);
    TN_CHECK(tn_image_load(&back, png, NULL) == TN_OK && back.width == 3 && back.channels == 3 && back.data[3] == 1.0f);
    tn_image_free(&back);
    tn_image_free(&dem);
    tn_image_free(&tex);
    remove(path);
    remove(mtl);
    remove(png);
}

TN_TEST(bad_input)
{
    const char *path = tn_test_tmp_path("export", "bad.glb");
    tn_image dem = slope_dem(4, 4), tiny = slope_dem(1, 5), tex = {0, 0, 0, NULL};
    tn_mesh_opts o;
    FILE *f;
    memset(&o, 0, sizeof o);
    remove(path);
    TN_CHECK(tn_export_glb(path, &tiny, NULL) == TN_ERR_EMPTY);
    TN_CHECK(tn_export_glb("", &dem, NULL) == TN_ERR_INVALID_ARG);
    o.z_scale = INFINITY;
    TN_CHECK(tn_export_obj(path, &dem, &o) == TN_ERR_INVALID_ARG);
    o.z_scale = 0;
    o.step = 70000;
    TN_CHECK(tn_export_glb(path, &dem, &o) == TN_ERR_INVALID_ARG);
    o.step = 0;
    TN_CHECK(tn_image_create(&tex, 2, 2, 2) == TN_OK);
    o.texture = &tex;
    TN_CHECK(tn_export_glb(path, &dem, &o) == TN_ERR_SHAPE);
    o.texture = NULL;
    dem.data[5] = NAN;
    TN_CHECK(tn_export_glb(path, &dem, &o) == TN_ERR_NUMERIC && strstr(tn_last_error(), "NaN") != NULL);
    f = fopen(path, "rb");
    TN_CHECK(f == NULL); /* nothing written on failure */
    if (f) fclose(f);
    tn_image_free(&dem);
    tn_image_free(&tiny);
    tn_image_free(&tex);
}

TN_TEST(normal_maps_and_unity_raw)
{
    const char *path = tn_test_tmp_path("export", "t.raw");
    tn_image dem = slope_dem(33, 33), small = slope_dem(10, 7), gl = {0, 0, 0, NULL}, dx = {0, 0, 0, NULL};
    uint8_t *b;
    size_t n, i;
    float lo = 0, hi = 0, mn, mx;
    unsigned cmin = 65535, cmax = 0;
    int mirrored = 1;
    TN_CHECK(tn_normal_map(&gl, &dem, 1, 1, 1, 0) == TN_OK && tn_normal_map(&dx, &dem, 1, 1, 1, 1) == TN_OK);
    TN_CHECK(gl.channels == 3 && TN_PIXEL(&gl, 5, 5, 0) < 0.5f && TN_PIXEL(&gl, 5, 5, 2) > 0.5f); /* leans west, up */
    for (i = 0; i < (size_t)33 * 33; i++)
        if (fabsf(gl.data[3 * i + 1] + dx.data[3 * i + 1] - 1.0f) > 1e-6f || gl.data[3 * i] != dx.data[3 * i]) mirrored = 0;
    TN_CHECK(mirrored);
    TN_CHECK(tn_image_range(&mn, &mx, &gl) == 0 && mn >= 0.0f && mx <= 1.0f);
    TN_CHECK(tn_export_unity_raw(path, &dem, 0, &lo, &hi) == TN_OK); /* 33 x 33 already: no resampling */
    {
        FILE *f = fopen(path, "rb");
        b = (uint8_t *)malloc(4 * 33 * 33);
        n = f && b ? fread(b, 1, 4 * 33 * 33, f) : 0;
        if (f) fclose(f);
    }
    TN_CHECK(n == 2 * 33 * 33);
    for (i = 0; i < n / 2; i++) {
        unsigned c = (unsigned)b[2 * i] | ((unsigned)b[2 * i + 1] << 8);
        if (c < cmin) cmin = c;
        if (c > cmax) cmax = c;
    }
    TN_CHECK(cmin == 0 && cmax == 65535 && lo == 100.0f && hi > lo);
    free(b);
    TN_CHECK(tn_export_unity_raw(path, &small, 0, NULL, NULL) == TN_OK); /* resampled to 33 */
    {
        FILE *f = fopen(path, "rb");
        long len = -1;
        if (f) {
            fseek(f, 0, SEEK_END);
            len = ftell(f);
            fclose(f);
        }
        TN_CHECK(len == 2 * 33 * 33);
    }
    TN_CHECK(tn_export_unity_raw(path, &dem, 100, NULL, NULL) == TN_ERR_INVALID_ARG); /* not 2^n + 1 */
    TN_CHECK(tn_export_unity_raw(path, &dem, 8193, NULL, NULL) == TN_ERR_INVALID_ARG);
    dem.data[7] = NAN;
    TN_CHECK(tn_export_unity_raw(path, &dem, 0, NULL, NULL) == TN_ERR_NUMERIC);
    tn_image_free(&gl);
    TN_CHECK(tn_normal_map(&gl, &dem, 1, 1, 1, 0) == TN_ERR_NUMERIC && gl.data == NULL);
    tn_image_free(&gl);
    tn_image_free(&dx);
    tn_image_free(&dem);
    tn_image_free(&small);
    remove(path);
}

/* A valley profile: flat floor (low), steep walls, flat high plateau; heights in metres at 10 m spacing. */
static tn_image splat_dem(void)
{
    tn_image d = {0, 0, 0, NULL};
    int x, y;
    if (tn_image_create(&d, 60, 8, 1)) return d;
    for (y = 0; y < 8; y++)
        for (x = 0; x < 60; x++) TN_PIXEL(&d, x, y, 0) = x < 20 ? 0.0f : x < 40 ? 50.0f * (float)(x - 20) : 1000.0f; /* 79 deg walls */
    return d;
}

TN_TEST(splat_map)
{
    tn_image dem = splat_dem(), w = {0, 0, 0, NULL}, snow = {0, 0, 0, NULL}, small = {0, 0, 0, NULL};
    tn_splat_opts o;
    size_t i;
    int sums = 1, y;
    memset(&o, 0, sizeof o);
    o.dx = 10.0f;
    TN_CHECK(tn_export_splat(&w, &dem, &o) == TN_OK && w.channels == 4 && w.width == 60 && w.height == 8);
    for (i = 0; i < (size_t)60 * 8; i++) {
        const float *p = w.data + 4 * i;
        if (fabsf(p[0] + p[1] + p[2] + p[3] - 1.0f) > 1e-5f || p[0] < 0 || p[1] < 0 || p[2] < 0 || p[3] < 0) sums = 0;
    }
    TN_CHECK(sums);
    TN_CHECK(TN_PIXEL(&w, 5, 4, 0) > 0.99f);  /* flat valley floor: vegetation */
    TN_CHECK(TN_PIXEL(&w, 30, 4, 2) > 0.99f); /* the wall: rock */
    TN_CHECK(TN_PIXEL(&w, 55, 4, 3) > 0.99f); /* the flat plateau, top of the range: snow */
    /* the snow line at 1.5 of the range: no snow, the plateau is bare ground (above the tree line) */
    o.snow_line = 2.0f;
    tn_image_free(&w);
    TN_CHECK(tn_export_splat(&w, &dem, &o) == TN_OK && TN_PIXEL(&w, 55, 4, 1) > 0.99f && TN_PIXEL(&w, 55, 4, 3) == 0.0f);
    /* a snow mask on the lower half of the rows replaces the snow line; rock stays on the wall */
    TN_CHECK(tn_image_create(&snow, 60, 8, 1) == TN_OK);
    for (i = 0; i < (size_t)60 * 4; i++) snow.data[60 * 4 + i] = 1.0f;
    o.snow = &snow;
    tn_image_free(&w);
    TN_CHECK(tn_export_splat(&w, &dem, &o) == TN_OK);
    for (y = 0; y < 8; y++) {
        TN_CHECK(TN_PIXEL(&w, 5, y, 3) == (y >= 4 ? 1.0f : 0.0f));
        TN_CHECK(TN_PIXEL(&w, 30, y, 2) > 0.99f);
    }
    /* spacing matters: at 1000 m per pixel the walls are gentle (2.9 deg) and carry no rock */
    o.dx = 1000.0f;
    o.snow = NULL;
    tn_image_free(&w);
    TN_CHECK(tn_export_splat(&w, &dem, &o) == TN_OK && TN_PIXEL(&w, 30, 4, 2) == 0.0f);
    /* bad input: mask size, NaN mask, NaN DEM, bad options, tiny DEM; *out untouched */
    tn_image_free(&w);
    TN_CHECK(tn_image_create(&small, 10, 8, 1) == TN_OK);
    o.vegetation = &small;
    TN_CHECK(tn_export_splat(&w, &dem, &o) == TN_ERR_SHAPE && w.data == NULL);
    o.vegetation = &snow;
    snow.data[3] = NAN;
    TN_CHECK(tn_export_splat(&w, &dem, &o) == TN_ERR_NUMERIC && w.data == NULL);
    o.vegetation = NULL;
    o.height_blend = -1.0f;
    TN_CHECK(tn_export_splat(&w, &dem, &o) == TN_ERR_INVALID_ARG && w.data == NULL);
    o.height_blend = 0.0f;
    dem.data[9] = INFINITY;
    TN_CHECK(tn_export_splat(&w, &dem, &o) == TN_ERR_NUMERIC && w.data == NULL);
    small.height = 1;
    TN_CHECK(tn_export_splat(&w, &small, NULL) == TN_ERR_EMPTY && w.data == NULL);
    small.height = 8;
    tn_image_free(&dem);
    tn_image_free(&snow);
    tn_image_free(&small);
}

int main(void)
{
    TN_RUN(glb_structure_and_geometry);
    TN_RUN(obj_counts_and_material);
    TN_RUN(bad_input);
    TN_RUN(normal_maps_and_unity_raw);
    TN_RUN(splat_map);
    return tn_test_summary("test_export");
}
