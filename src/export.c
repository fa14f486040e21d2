/* ============================================================================================
   @@export  heightfields for engines and 3D tools: glTF 2.0 binary (.glb) and OBJ meshes,
   normal maps, Unity terrain RAW, splat maps
   A regular grid mesh of the DEM in metres: x east = column * dx, y up = height * z_scale,
   z south = row * dy (glTF is y-up and right-handed), two triangles per cell wound
   counter-clockwise seen from above, smooth normals from central differences of the mesh,
   UV (0, 0) at the north-west corner. step > 1 keeps every step-th sample, and always the last
   row and column, so the mesh covers the whole DEM.
   ============================================================================================ */
#ifndef TN_NO_EXPORT

typedef struct tn_mesh_opts {
    float dx, dy;              /* pixel spacing in metres; <= 0 = 1 (dy <= 0: = dx) */
    float z_scale;             /* height exaggeration; 0 = 1 */
    int step;                  /* grid decimation 1..65536; 0 = 1 */
    const tn_image *texture;   /* optional colour image (1, 3 or 4 channels, values in [0, 1]) draped
                                  over the whole mesh: embedded as PNG in a .glb; written beside an
                                  .obj as <stem>.png with <stem>.mtl */
} tn_mesh_opts;

/* Writes the mesh atomically. Channel 0 of dem is the height. NaN/Inf heights or texture values
   fail with TN_ERR_NUMERIC, a DEM under 2 x 2 with TN_ERR_EMPTY, meshes over 2^32 vertices or
   TN_MAX_ALLOC bytes with TN_ERR_TOO_LARGE. opts may be NULL. */
TN_API tn_status tn_export_glb(const char *path, const tn_image *dem, const tn_mesh_opts *opts);
TN_API tn_status tn_export_obj(const char *path, const tn_image *dem, const tn_mesh_opts *opts);

/* Normal map of the DEM as RGB in [0, 1] (n / 2 + 0.5, n from tn_image_normals): red = x east,
   blue = z up, green = y north with directx 0 (OpenGL, "Y+") or y south with directx 1
   (DirectX, "Y-"). Save it as an 8-bit PNG for an engine. */
TN_API tn_status tn_normal_map(tn_image *out, const tn_image *dem, float dx, float dy, float z_scale, int directx);
/* Unity terrain RAW: size x size 16-bit little-endian codes, size = 2^n + 1 (33..4097; 0 = the
   smallest not below the DEM's larger side), the DEM resampled bicubic to it when its size
   differs; codes 0..65535 span the DEM's range, returned in *lo and *hi (may be NULL) for the
   terrain's height setting. Written atomically. */
TN_API tn_status tn_export_unity_raw(const char *path, const tn_image *dem, int size, float *lo, float *hi);

/* Splat map: per-pixel weights of four ground materials for an engine's terrain shader,
   RGBA = (vegetation, bare ground, rock, snow), each in [0, 1], summing to 1 at every pixel.
   Rock takes the steep slopes, snow what is left of the high ground, vegetation what is left of
   the low ground, bare ground the rest:
       rock = ramp(slope, rock_slope_deg, rock_blend_deg)
       snow = (1 - rock) * S,  S = ramp(h, snow_line, height_blend), or the snow mask
       vegetation = (1 - rock) * (1 - S) * V,  V = 1 - ramp(h, tree_line, height_blend), or the
                    vegetation mask
       bare ground = (1 - rock) * (1 - S) * (1 - V)
   where ramp(x, c, w) rises smoothly (smoothstep) from 0 at c - w/2 to 1 at c + w/2 and h is the
   height as a fraction of the DEM's own range (0 = lowest, 1 = highest). Slopes are in degrees
   with the given spacing, so give the real spacing for a DEM in metres. Zero fields = defaults,
   resolved in one place. */
typedef struct tn_splat_opts {
    float dx, dy;              /* pixel spacing in the DEM's height units; <= 0 = 1 (dy <= 0: = dx) */
    float rock_slope_deg;      /* slope where rock is half the weight; 0 = 35 */
    float rock_blend_deg;      /* width of the rock transition; 0 = 10 */
    float tree_line;           /* height fraction where vegetation gives way to bare ground; 0 = 0.5
                                  (negative: no vegetation from height) */
    float snow_line;           /* height fraction where snow starts; 0 = 0.8 (above 1.5: no snow) */
    float height_blend;        /* width of both height transitions, as a fraction; 0 = 0.1 */
    const tn_image *snow;      /* optional mask in [0, 1] (channel 0, the DEM's size), e.g. a seasonal
                                  snow mask; replaces the snow line */
    const tn_image *vegetation; /* optional mask in [0, 1], the DEM's size; replaces the tree line */
} tn_splat_opts;
/* Fills *out (4 channels, the DEM's size; caller frees). opts may be NULL. NaN/Inf heights or
   mask values fail with TN_ERR_NUMERIC, a mask of another size with TN_ERR_SHAPE, a DEM under
   2 x 2 with TN_ERR_EMPTY, bad options with TN_ERR_INVALID_ARG; *out is untouched then. */
TN_API tn_status tn_export_splat(tn_image *out, const tn_image *dem, const tn_splat_opts *opts);
#endif /* TN_NO_EXPORT */

/* --------------------------------------------------------------------------------------------
   >>export  (@@export implementation)
   -------------------------------------------------------------------------------------------- */
#ifndef TN_NO_EXPORT

typedef struct tn__mesh {
    int nx, ny;                /* vertices per row and per column */
    float *pos, *nrm, *uv;     /* 3, 3, 2 floats per vertex */
    uint32_t *idx;             /* 6 per cell */
    float lo[3], hi[3];        /* position bounds (glTF wants them) */
} tn__mesh;

static void tn__mesh_opts_defaults(tn_mesh_opts *o)
{
    if (!(o->dx > 0)) o->dx = 1.0f;
    if (!(o->dy > 0)) o->dy = o->dx;
    if (o->z_scale == 0) o->z_scale = 1.0f;
    if (o->step <= 0) o->step = 1;
}

static void tn__mesh_free(tn__mesh *m)
{
    TN_FREE(m->pos);
    memset(m, 0, sizeof *m);
}

/* Sample index of mesh vertex i along an axis of n samples with stride step (the last sample
   always included). */
static int tn__mesh_sample(int i, int step, int n) { return i * step < n - 1 ? i * step : n - 1; }

static tn_status tn__mesh_check(const tn_image *dem, const tn_mesh_opts *o, const char *path)
{
    float lo, hi;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "export: empty path");
    if (!dem || !dem->data || dem->width < 2 || dem->height < 2) return tn__fail(TN_ERR_EMPTY, "%s: the DEM must be at least 2 x 2", path);
    if (!(fabsf(o->dx) <= 1e30f) || !(fabsf(o->dy) <= 1e30f) || !(fabsf(o->z_scale) <= 1e30f) || o->step > 65536)
        return tn__fail(TN_ERR_INVALID_ARG, "%s: bad mesh options (spacing %g x %g, z scale %g, step %d)", path, (double)o->dx, (double)o->dy,
                        (double)o->z_scale, o->step);
    if (tn_image_range(&lo, &hi, dem)) return tn__fail(TN_ERR_NUMERIC, "%s: the DEM holds NaN/Inf", path);
    if (o->texture) {
        const tn_image *t = o->texture;
        if (!t->data || t->width < 1 || t->height < 1 || t->channels < 1 || t->channels > 4 || t->channels == 2)
            return tn__fail(TN_ERR_SHAPE, "%s: the texture must have 1, 3 or 4 channels", path);
        if (tn_image_range(&lo, &hi, t)) return tn__fail(TN_ERR_NUMERIC, "%s: the texture holds NaN/Inf", path);
    }
    return TN_OK;
}

/* Builds the grid mesh (one allocation for all arrays). */
static tn_status tn__mesh_build(const tn_image *dem, const tn_mesh_opts *o, tn__mesh *m, const char *path)
{
    int i, j, k;
    size_t nv, ncell, bytes = 0, v;
    memset(m, 0, sizeof *m);
    m->nx = (dem->width - 1 + o->step - 1) / o->step + 1;
    m->ny = (dem->height - 1 + o->step - 1) / o->step + 1;
    nv = (size_t)m->nx * m->ny;
    ncell = (size_t)(m->nx - 1) * (m->ny - 1);
    if (nv > 0xffffffffu || tn__size4(nv * 8 + ncell * 6, 4, 1, 1, &bytes)) return tn__fail(TN_ERR_TOO_LARGE, "%s: the mesh is too large (use a step)", path);
    if (!(m->pos = (float *)tn__alloc(bytes))) return tn__fail_context(TN_ERR_OUT_OF_MEMORY, path);
    m->nrm = m->pos + 3 * nv;
    m->uv = m->nrm + 3 * nv;
    m->idx = (uint32_t *)(m->uv + 2 * nv);
    for (k = 0; k < 3; k++) {
        m->lo[k] = FLT_MAX;
        m->hi[k] = -FLT_MAX;
    }
    for (j = 0, v = 0; j < m->ny; j++)
        for (i = 0; i < m->nx; i++, v++) {
            int sx = tn__mesh_sample(i, o->step, dem->width), sy = tn__mesh_sample(j, o->step, dem->height);
            float *p = m->pos + 3 * v;
            p[0] = (float)sx * o->dx;
            p[1] = TN_PIXEL(dem, sx, sy, 0) * o->z_scale;
            p[2] = (float)sy * o->dy;
            m->uv[2 * v] = (float)sx / (float)(dem->width - 1);
            m->uv[2 * v + 1] = (float)sy / (float)(dem->height - 1);
            for (k = 0; k < 3; k++) {
                if (p[k] < m->lo[k]) m->lo[k] = p[k];
                if (p[k] > m->hi[k]) m->hi[k] = p[k];
            }
        }
    for (j = 0, v = 0; j < m->ny; j++)
        for (i = 0; i < m->nx; i++, v++) { /* central differences of the mesh, one-sided at its edges */
            int i0 = i > 0 ? i - 1 : i, i1 = i < m->nx - 1 ? i + 1 : i, j0 = j > 0 ? j - 1 : j, j1 = j < m->ny - 1 ? j + 1 : j;
            const float *a = m->pos + 3 * ((size_t)j * m->nx + i0), *b = m->pos + 3 * ((size_t)j * m->nx + i1);
            const float *c = m->pos + 3 * ((size_t)j0 * m->nx + i), *d = m->pos + 3 * ((size_t)j1 * m->nx + i);
            double hx = (b[1] - a[1]) / (double)(b[0] - a[0]), hz = (d[1] - c[1]) / (double)(d[2] - c[2]);
            double len = sqrt(hx * hx + 1.0 + hz * hz);
            m->nrm[3 * v] = (float)(-hx / len);
            m->nrm[3 * v + 1] = (float)(1.0 / len);
            m->nrm[3 * v + 2] = (float)(-hz / len);
        }
    for (j = 0, v = 0; j + 1 < m->ny; j++)
        for (i = 0; i + 1 < m->nx; i++) {
            uint32_t a = (uint32_t)((size_t)j * m->nx + i), b = a + 1, c = a + (uint32_t)m->nx, d = c + 1;
            uint32_t *t = m->idx + 6 * v++;
            t[0] = a; t[1] = c; t[2] = b; /* counter-clockwise seen from +y */
            t[3] = b; t[4] = c; t[5] = d;
        }
    return TN_OK;
}

/* The texture as an 8-bit RGB(A) PNG in memory (grey expanded to RGB). */
static tn_status tn__mesh_texture_png(const tn_image *t, uint8_t **png, size_t *n)
{
    tn_image rgb = {0, 0, 0, NULL};
    tn_save_opts so;
    tn_status st;
    size_t i, np = (size_t)t->width * t->height;
    int c, ch = t->channels == 1 ? 3 : t->channels;
    if ((st = tn_image_create(&rgb, t->width, t->height, ch))) return st;
    for (i = 0; i < np; i++)
        for (c = 0; c < ch; c++) {
            float v = t->data[i * t->channels + (t->channels == 1 ? 0 : c)];
            rgb.data[i * ch + c] = v < 0 ? 0.0f : v > 1 ? 1.0f : v;
        }
    memset(&so, 0, sizeof so);
    so.bit_depth = 8;
    st = tn_image_save_memory(png, n, &rgb, TN_FORMAT_PNG, &so);
    tn_image_free(&rgb);
    return st;
}

/* A growing text buffer (JSON, OBJ). */
typedef struct tn__text { char *s; size_t n, cap; int failed; } tn__text;

static void tn__text_add(tn__text *t, const char *fmt, ...)
{
    va_list ap;
    int k;
    if (t->failed) return;
    for (;;) {
        size_t room = t->cap - t->n;
        va_start(ap, fmt);
        k = t->s ? vsnprintf(t->s + t->n, room, fmt, ap) : -1;
        va_end(ap);
        if (k >= 0 && (size_t)k < room) {
            t->n += (size_t)k;
            return;
        }
        {
            size_t cap = t->cap ? 2 * t->cap : 4096;
            char *s;
            if (k > 0 && cap < t->n + (size_t)k + 1) cap = t->n + (size_t)k + 1;
            if (cap > TN_MAX_ALLOC || !(s = (char *)TN_REALLOC(t->s, cap))) {
                t->failed = 1;
                return;
            }
            t->s = s;
            t->cap = cap;
        }
    }
}

/* A float as the shortest text that reads back as the same float, '.' whatever the locale. */
static void tn__text_num(tn__text *t, float v)
{
    char b[40];
    tn__io_format_number(b, sizeof b, (double)v, 1);
    tn__text_add(t, "%s", b);
}

static void tn__glb_put_chunk(uint8_t *out, size_t *off, const char *type, const uint8_t *data, size_t n, size_t padded, uint8_t pad)
{
    tn__put_u32(out + *off, (uint32_t)padded);
    memcpy(out + *off + 4, type, 4);
    memcpy(out + *off + 8, data, n);
    memset(out + *off + 8 + n, pad, padded - n);
    *off += 8 + padded;
}

TN_API tn_status tn_export_glb(const char *path, const tn_image *dem, const tn_mesh_opts *opts)
{
    tn_mesh_opts o;
    tn__mesh m;
    tn__text js = {NULL, 0, 0, 0};
    uint8_t *png = NULL, *out = NULL, *bin = NULL;
    size_t png_n = 0, nv, ni, off[5], binlen, jpad, bpad, total, pos = 0;
    tn_status st;
    int k;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    tn__mesh_opts_defaults(&o);
    if ((st = tn__mesh_check(dem, &o, path))) return st;
    if ((st = tn__mesh_build(dem, &o, &m, path))) return st;
    if (o.texture && (st = tn__mesh_texture_png(o.texture, &png, &png_n))) {
        tn__mesh_free(&m);
        return tn__fail_context(st, path);
    }
    nv = (size_t)m.nx * m.ny;
    ni = (size_t)(m.nx - 1) * (m.ny - 1) * 6;
    off[0] = 0;                       /* positions */
    off[1] = off[0] + nv * 12;        /* normals */
    off[2] = off[1] + nv * 12;        /* UVs */
    off[3] = off[2] + nv * 8;         /* indices */
    off[4] = off[3] + ni * 4;         /* PNG */
    binlen = off[4] + png_n;
    tn__text_add(&js, "{\"asset\":{\"version\":\"2.0\",\"generator\":\"terrainnet %s\"},\"scene\":0,\"scenes\":[{\"nodes\":[0]}],"
                      "\"nodes\":[{\"mesh\":0,\"name\":\"terrain\"}],\"meshes\":[{\"primitives\":[{\"attributes\":"
                      "{\"POSITION\":0,\"NORMAL\":1,\"TEXCOORD_0\":2},\"indices\":3,\"material\":0}]}],",
                 TN_VERSION_STRING);
    tn__text_add(&js, "\"materials\":[{\"pbrMetallicRoughness\":{%s\"metallicFactor\":0,\"roughnessFactor\":1}}],",
                 png ? "\"baseColorTexture\":{\"index\":0}," : "");
    if (png)
        tn__text_add(&js, "\"textures\":[{\"sampler\":0,\"source\":0}],\"samplers\":[{\"magFilter\":9729,\"minFilter\":9987,"
                          "\"wrapS\":33071,\"wrapT\":33071}],\"images\":[{\"bufferView\":4,\"mimeType\":\"image/png\"}],");
    tn__text_add(&js, "\"buffers\":[{\"byteLength\":%lu}],\"bufferViews\":[", (unsigned long)binlen);
    tn__text_add(&js, "{\"buffer\":0,\"byteOffset\":%lu,\"byteLength\":%lu,\"target\":34962},", (unsigned long)off[0], (unsigned long)(nv * 12));
    tn__text_add(&js, "{\"buffer\":0,\"byteOffset\":%lu,\"byteLength\":%lu,\"target\":34962},", (unsigned long)off[1], (unsigned long)(nv * 12));
    tn__text_add(&js, "{\"buffer\":0,\"byteOffset\":%lu,\"byteLength\":%lu,\"target\":34962},", (unsigned long)off[2], (unsigned long)(nv * 8));
    tn__text_add(&js, "{\"buffer\":0,\"byteOffset\":%lu,\"byteLength\":%lu,\"target\":34963}", (unsigned long)off[3], (unsigned long)(ni * 4));
    if (png) tn__text_add(&js, ",{\"buffer\":0,\"byteOffset\":%lu,\"byteLength\":%lu}", (unsigned long)off[4], (unsigned long)png_n);
    tn__text_add(&js, "],\"accessors\":[{\"bufferView\":0,\"componentType\":5126,\"count\":%lu,\"type\":\"VEC3\",\"min\":[", (unsigned long)nv);
    for (k = 0; k < 3; k++) {
        tn__text_num(&js, m.lo[k]);
        tn__text_add(&js, k < 2 ? "," : "],\"max\":[");
    }
    for (k = 0; k < 3; k++) {
        tn__text_num(&js, m.hi[k]);
        tn__text_add(&js, k < 2 ? "," : "]},");
    }
    tn__text_add(&js, "{\"bufferView\":1,\"componentType\":5126,\"count\":%lu,\"type\":\"VEC3\"},", (unsigned long)nv);
    tn__text_add(&js, "{\"bufferView\":2,\"componentType\":5126,\"count\":%lu,\"type\":\"VEC2\"},", (unsigned long)nv);
    tn__text_add(&js, "{\"bufferView\":3,\"componentType\":5125,\"count\":%lu,\"type\":\"SCALAR\"}]}", (unsigned long)ni);
    jpad = (js.n + 3) & ~(size_t)3;
    bpad = (binlen + 3) & ~(size_t)3;
    total = 12 + 8 + jpad + 8 + bpad;
    if (js.failed) st = tn__fail(TN_ERR_OUT_OF_MEMORY, "%s: out of memory", path);
    else if (total > 0xffffffffu || total > TN_MAX_ALLOC) st = tn__fail(TN_ERR_TOO_LARGE, "%s: over 4 GiB, the .glb limit (use a step)", path);
    else if (!(out = (uint8_t *)tn__alloc(total)) || !(bin = (uint8_t *)tn__alloc(binlen))) st = tn__fail_context(TN_ERR_OUT_OF_MEMORY, path);
    if (!st) {
        size_t i;
        for (i = 0; i < 3 * nv; i++) tn__put_f32(bin + off[0] + 4 * i, m.pos[i]);
        for (i = 0; i < 3 * nv; i++) tn__put_f32(bin + off[1] + 4 * i, m.nrm[i]);
        for (i = 0; i < 2 * nv; i++) tn__put_f32(bin + off[2] + 4 * i, m.uv[i]);
        for (i = 0; i < ni; i++) tn__put_u32(bin + off[3] + 4 * i, m.idx[i]);
        if (png_n) memcpy(bin + off[4], png, png_n);
        memcpy(out, "glTF", 4);
        tn__put_u32(out + 4, 2);
        tn__put_u32(out + 8, (uint32_t)total);
        pos = 12;
        tn__glb_put_chunk(out, &pos, "JSON", (const uint8_t *)js.s, js.n, jpad, ' ');
        tn__glb_put_chunk(out, &pos, "BIN\0", bin, binlen, bpad, 0);
        st = tn__io_write_atomic(path, out, total);
    }
    TN_FREE(out);
    TN_FREE(bin);
    TN_FREE(js.s);
    tn_free(png);
    tn__mesh_free(&m);
    return st;
}

/* path without its extension (a copy). */
static char *tn__path_stem(const char *path)
{
    const char *dot = strrchr(path, '.'), *slash = strrchr(path, '/');
    size_t n = dot && (!slash || dot > slash) ? (size_t)(dot - path) : strlen(path);
    return tn__strndup(path, n);
}

TN_API tn_status tn_export_obj(const char *path, const tn_image *dem, const tn_mesh_opts *opts)
{
    tn_mesh_opts o;
    tn__mesh m;
    tn__text t = {NULL, 0, 0, 0};
    char *stem = NULL;
    const char *leaf;
    size_t nv, i;
    tn_status st;
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    tn__mesh_opts_defaults(&o);
    if ((st = tn__mesh_check(dem, &o, path))) return st;
    if ((st = tn__mesh_build(dem, &o, &m, path))) return st;
    if (!(stem = tn__path_stem(path))) {
        tn__mesh_free(&m);
        return tn__fail_context(TN_ERR_OUT_OF_MEMORY, path);
    }
    leaf = strrchr(stem, '/') ? strrchr(stem, '/') + 1 : stem;
    nv = (size_t)m.nx * m.ny;
    tn__text_add(&t, "# terrainnet %s: %d x %d grid, y up, metres\n", TN_VERSION_STRING, m.nx, m.ny);
    if (o.texture) tn__text_add(&t, "mtllib %s.mtl\nusemtl terrain\n", leaf);
    for (i = 0; i < nv && !t.failed; i++) {
        tn__text_add(&t, "v ");
        tn__text_num(&t, m.pos[3 * i]);
        tn__text_add(&t, " ");
        tn__text_num(&t, m.pos[3 * i + 1]);
        tn__text_add(&t, " ");
        tn__text_num(&t, m.pos[3 * i + 2]);
        tn__text_add(&t, "\nvt ");
        tn__text_num(&t, m.uv[2 * i]);
        tn__text_add(&t, " ");
        tn__text_num(&t, 1.0f - m.uv[2 * i + 1]); /* OBJ's v points up the image */
        tn__text_add(&t, "\nvn ");
        tn__text_num(&t, m.nrm[3 * i]);
        tn__text_add(&t, " ");
        tn__text_num(&t, m.nrm[3 * i + 1]);
        tn__text_add(&t, " ");
        tn__text_num(&t, m.nrm[3 * i + 2]);
        tn__text_add(&t, "\n");
    }
    for (i = 0; i < (size_t)(m.nx - 1) * (m.ny - 1) * 2 && !t.failed; i++) {
        const uint32_t *f = m.idx + 3 * i;
        tn__text_add(&t, "f %lu/%lu/%lu %lu/%lu/%lu %lu/%lu/%lu\n", (unsigned long)f[0] + 1, (unsigned long)f[0] + 1, (unsigned long)f[0] + 1,
                     (unsigned long)f[1] + 1, (unsigned long)f[1] + 1, (unsigned long)f[1] + 1, (unsigned long)f[2] + 1,
                     (unsigned long)f[2] + 1, (unsigned long)f[2] + 1);
    }
    if (t.failed) st = tn__fail(TN_ERR_TOO_LARGE, "%s: the OBJ text is too large for memory (use a step)", path);
    if (!st && o.texture) { /* the material and its image beside the mesh */
        tn__text mtl = {NULL, 0, 0, 0};
        uint8_t *png = NULL;
        size_t png_n = 0, sl = strlen(stem);
        char *mp = (char *)tn__alloc(sl + 5);
        if (!mp) st = TN_ERR_OUT_OF_MEMORY;
        if (!st) st = tn__mesh_texture_png(o.texture, &png, &png_n);
        if (!st) {
            memcpy(mp, stem, sl);
            memcpy(mp + sl, ".png", 5);
            st = tn__io_write_atomic(mp, png, png_n);
        }
        if (!st) {
            tn__text_add(&mtl, "newmtl terrain\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nmap_Kd %s.png\n", leaf);
            memcpy(mp + sl, ".mtl", 5);
            st = mtl.failed ? TN_ERR_OUT_OF_MEMORY : tn__io_write_atomic(mp, (const uint8_t *)mtl.s, mtl.n);
        }
        tn_free(png);
        TN_FREE(mtl.s);
        TN_FREE(mp);
    }
    if (!st) st = tn__io_write_atomic(path, (const uint8_t *)t.s, t.n);
    TN_FREE(t.s);
    TN_FREE(stem);
    tn__mesh_free(&m);
    return st;
}

TN_API tn_status tn_normal_map(tn_image *out, const tn_image *dem, float dx, float dy, float z_scale, int directx)
{
    tn_image n = {0, 0, 0, NULL};
    size_t i, np;
    float lo, hi;
    tn_status st;
    TN_ASSERT(out);
    if (dem && dem->data && tn_image_range(&lo, &hi, dem)) return tn__fail(TN_ERR_NUMERIC, "normal map: the DEM holds NaN/Inf");
    if ((st = tn_image_normals(&n, dem, dx, dy, z_scale))) return st;
    np = (size_t)n.width * n.height;
    for (i = 0; i < np; i++) {
        float *p = n.data + 3 * i;
        if (directx) p[1] = -p[1];
        p[0] = 0.5f * p[0] + 0.5f;
        p[1] = 0.5f * p[1] + 0.5f;
        p[2] = 0.5f * p[2] + 0.5f;
    }
    *out = n;
    return TN_OK;
}

TN_API tn_status tn_export_unity_raw(const char *path, const tn_image *dem, int size, float *lo, float *hi)
{
    tn_image r = {0, 0, 0, NULL};
    const tn_image *src = dem;
    uint8_t *buf;
    float a, b;
    size_t i, np;
    tn_status st = TN_OK;
    int big;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "unity raw: empty path");
    if (!dem || !dem->data || dem->width < 2 || dem->height < 2) return tn__fail(TN_ERR_EMPTY, "%s: the DEM must be at least 2 x 2", path);
    big = dem->width > dem->height ? dem->width : dem->height;
    if (size == 0)
        for (size = 33; size < big && size < 4097; size = 2 * size - 1) {}
    if (size < 33 || size > 4097 || ((size - 1) & (size - 2)) != 0)
        return tn__fail(TN_ERR_INVALID_ARG, "%s: Unity RAW size %d is not 2^n + 1 in 33..4097", path, size);
    if (tn_image_range(&a, &b, dem)) return tn__fail(TN_ERR_NUMERIC, "%s: the DEM holds NaN/Inf", path);
    if (dem->width != size || dem->height != size || dem->channels != 1) {
        tn_image one = {0, 0, 0, NULL};
        if (dem->channels != 1) { /* channel 0 is the height */
            if ((st = tn_image_create(&one, dem->width, dem->height, 1))) return st;
            np = (size_t)dem->width * dem->height;
            for (i = 0; i < np; i++) one.data[i] = dem->data[i * dem->channels];
        }
        st = tn_image_resize(&r, dem->channels != 1 ? &one : dem, size, size, TN_RESIZE_BICUBIC);
        tn_image_free(&one);
        if (st) return st;
        src = &r;
    }
    np = (size_t)size * size;
    if (!(buf = (uint8_t *)tn__alloc(2 * np))) {
        tn_image_free(&r);
        return tn__fail_context(TN_ERR_OUT_OF_MEMORY, path);
    }
    for (i = 0; i < np; i++) { /* bicubic may overshoot the range a little: clamped */
        double t = b > a ? ((double)src->data[i] - a) / ((double)b - a) : 0.0;
        unsigned c = (unsigned)(65535.0 * (t < 0 ? 0 : t > 1 ? 1 : t) + 0.5);
        buf[2 * i] = (uint8_t)c;
        buf[2 * i + 1] = (uint8_t)(c >> 8);
    }
    st = tn__io_write_atomic(path, buf, 2 * np);
    TN_FREE(buf);
    tn_image_free(&r);
    if (!st && lo) *lo = a;
    if (!st && hi) *hi = b;
    return st;
}

static void tn__splat_opts_defaults(tn_splat_opts *o)
{
    if (!(o->dx > 0)) o->dx = 1.0f;
    if (!(o->dy > 0)) o->dy = o->dx;
    if (o->rock_slope_deg == 0) o->rock_slope_deg = 35.0f;
    if (o->rock_blend_deg == 0) o->rock_blend_deg = 10.0f;
    if (o->tree_line == 0) o->tree_line = 0.5f;
    if (o->snow_line == 0) o->snow_line = 0.8f;
    if (o->height_blend == 0) o->height_blend = 0.1f;
}

/* Smooth 0 -> 1 around c over a width w (a step when w is 0). */
static float tn__splat_ramp(float x, float c, float w)
{
    float t = w > 0 ? (x - (c - 0.5f * w)) / w : (x >= c ? 1.0f : 0.0f);
    t = t < 0 ? 0 : t > 1 ? 1 : t;
    return t * t * (3.0f - 2.0f * t);
}

static tn_status tn__splat_mask_check(const tn_image *m, const tn_image *dem, const char *what)
{
    float lo, hi;
    if (!m) return TN_OK;
    if (!m->data || m->channels < 1) return tn__fail(TN_ERR_EMPTY, "splat map: the %s mask is empty", what);
    if (m->width != dem->width || m->height != dem->height)
        return tn__fail(TN_ERR_SHAPE, "splat map: the %s mask is %d x %d, the DEM %d x %d", what, m->width, m->height, dem->width,
                        dem->height);
    if (tn_image_range(&lo, &hi, m)) return tn__fail(TN_ERR_NUMERIC, "splat map: the %s mask holds NaN/Inf", what);
    return TN_OK;
}

TN_API tn_status tn_export_splat(tn_image *out, const tn_image *dem, const tn_splat_opts *opts)
{
    tn_splat_opts o;
    tn_image slope = {0, 0, 0, NULL}, w = {0, 0, 0, NULL}, one = {0, 0, 0, NULL};
    const tn_image *h = dem;
    float lo, hi, span;
    size_t i, np;
    tn_status st;
    TN_ASSERT(out);
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    if (!dem || !dem->data || dem->width < 2 || dem->height < 2 || dem->channels < 1)
        return tn__fail(TN_ERR_EMPTY, "splat map: the DEM must be at least 2 x 2");
    if (!(fabsf(o.dx) <= FLT_MAX && fabsf(o.dy) <= FLT_MAX && fabsf(o.rock_slope_deg) <= FLT_MAX && o.rock_blend_deg >= 0 &&
          o.rock_blend_deg <= FLT_MAX && fabsf(o.tree_line) <= FLT_MAX && fabsf(o.snow_line) <= FLT_MAX && o.height_blend >= 0 &&
          o.height_blend <= FLT_MAX))
        return tn__fail(TN_ERR_INVALID_ARG, "splat map: options must be finite, blend widths >= 0");
    tn__splat_opts_defaults(&o);
    if (tn_image_range(&lo, &hi, dem)) return tn__fail(TN_ERR_NUMERIC, "splat map: the DEM holds NaN/Inf");
    if ((st = tn__splat_mask_check(o.snow, dem, "snow")) || (st = tn__splat_mask_check(o.vegetation, dem, "vegetation"))) return st;
    np = (size_t)dem->width * dem->height;
    if (dem->channels != 1) { /* channel 0 is the height */
        if ((st = tn_image_create(&one, dem->width, dem->height, 1))) return st;
        for (i = 0; i < np; i++) one.data[i] = dem->data[i * dem->channels];
        h = &one;
        tn_image_range(&lo, &hi, h);
    }
    span = hi > lo ? hi - lo : 1.0f;
    if ((st = tn_image_slope(&slope, h, o.dx, o.dy)) || (st = tn_image_create(&w, dem->width, dem->height, 4))) goto done;
    for (i = 0; i < np; i++) {
        float f = (h->data[i] - lo) / span, s, v, rock = tn__splat_ramp(slope.data[i], o.rock_slope_deg, o.rock_blend_deg);
        float *p = w.data + 4 * i;
        s = o.snow ? o.snow->data[i * o.snow->channels] : tn__splat_ramp(f, o.snow_line, o.height_blend);
        v = o.vegetation ? o.vegetation->data[i * o.vegetation->channels] : 1.0f - tn__splat_ramp(f, o.tree_line, o.height_blend);
        s = s < 0 ? 0 : s > 1 ? 1 : s;
        v = v < 0 ? 0 : v > 1 ? 1 : v;
        p[3] = (1.0f - rock) * s;
        p[0] = (1.0f - rock) * (1.0f - s) * v;
        p[2] = rock;
        p[1] = 1.0f - p[0] - p[2] - p[3]; /* the remainder, so the four sum to 1 exactly in float */
        if (p[1] < 0) p[1] = 0;
    }
    *out = w;
    w.data = NULL;
done:
    tn_image_free(&w);
    tn_image_free(&slope);
    tn_image_free(&one);
    return st;
}
#endif /* TN_NO_EXPORT */

