/* --------------------------------------------------------------------------------------------
   >>formats  (part of @@io implementation; goes after >>png, whose tn__png_decode/encode it calls)
   Everything in @@io but the PNG codec: format detection (magic bytes, then extension), reading
   a whole file with one fread, saving through "<path>.tmp" + rename() so a failed save
   never clobbers the old file, the integer-format value mapping shared with PNG, and the codecs
   for PGM/PPM (P2 P3 P5 P6), PFM, SRTM .hgt, ESRI ASCII grid .asc and headerless .r16.
   Every parser works on one memory buffer with explicit bounds: sizes go through tn__size4
   (TN_ERR_TOO_LARGE) and are checked against the bytes actually present (TN_ERR_CORRUPT)
   before anything is allocated. Text is parsed without strtod/locale.
   NaN/Inf: refused on save (TN_ERR_NUMERIC); PFM files holding them fail to load with
   TN_ERR_NUMERIC because terrain code downstream cannot use them; in .asc a "nan"/"inf" value
   is treated like NODATA.
   Voids (.hgt -32768, .asc NODATA) are filled in two steps: onion peeling, ring by ring from
   the known cells (each void cell next to known ones takes the mean of its known 8-neighbours,
   weights 1 orthogonal, 1/2 diagonal; order-independent), then SOR sweeps of the 4-neighbour
   Laplace equation over the filled cells, so holes get the smooth harmonic surface spanning
   their rim (a plane is reproduced). More void cells than 1/16 of the relaxation's budget of
   2e8 updates take a push-pull pyramid instead (means up the levels, bilinear down), in
   O(cells). info->voids_filled counts the cells; a grid with no
   valid cell fails with TN_ERR_EMPTY. Single-threaded and deterministic.
   -------------------------------------------------------------------------------------------- */

/* Little-endian words for the binary formats (.tnw, .glb). */
TN__SHARED void tn__put_u32(uint8_t *p, uint32_t v) { p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); p[2] = (uint8_t)(v >> 16); p[3] = (uint8_t)(v >> 24); }
TN__SHARED uint32_t tn__get_u32(const uint8_t *p) { return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24); }

TN__SHARED void tn__put_f32(uint8_t *p, float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    tn__put_u32(p, u);
}

TN_API const char *tn_format_name(tn_format f)
{
    switch (f) {
    case TN_FORMAT_AUTO: return "auto";
    case TN_FORMAT_PNG: return "png";
    case TN_FORMAT_PNM: return "pnm";
    case TN_FORMAT_PFM: return "pfm";
    case TN_FORMAT_HGT: return "hgt";
    case TN_FORMAT_ASC: return "asc";
    case TN_FORMAT_R16: return "r16";
    case TN_FORMAT_TIFF: return "tiff";
    }
    return "unknown";
}

TN_API void tn_free(void *p) { TN_FREE(p); }

/* ---- small text helpers (no <ctype.h>, no locale) ---- */

static int tn__io_space(int c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f'; }
static int tn__io_digit(int c) { return c >= '0' && c <= '9'; }
static int tn__io_lower(int c) { return c >= 'A' && c <= 'Z' ? c + ('a' - 'A') : c; }

/* Case-insensitive: is the n-byte token t equal to word? */
static int tn__io_token_is(const char *t, size_t n, const char *word)
{
    size_t i;
    for (i = 0; i < n; i++)
        if (!word[i] || tn__io_lower((unsigned char)t[i]) != tn__io_lower((unsigned char)word[i])) return 0;
    return word[n] == 0;
}

/* Next whitespace-separated token of p[*i..n): sets *tb (start) and *tl (length), advances *i.
   Returns 0 at the end of the buffer. */
static int tn__io_token(const uint8_t *p, size_t n, size_t *i, size_t *tb, size_t *tl)
{
    size_t k = *i;
    while (k < n && tn__io_space(p[k])) k++;
    if (k >= n) { *i = k; return 0; }
    *tb = k;
    while (k < n && !tn__io_space(p[k])) k++;
    *tl = k - *tb;
    *i = k;
    return 1;
}

/* Parses a whole token as a decimal number ("-12.5e3", "nan", "inf"); returns 0 if it is not
   one. Own parser because strtod follows the locale ("1,5") and needs a NUL-terminated string. */
static int tn__io_number(const char *s, size_t n, double *out)
{
    size_t i = 0;
    int neg = 0, digits = 0, exp10 = 0, e = 0, eneg = 0, edigits = 0;
    uint64_t m = 0;
    double v;
    if (n == 0 || n > 400) return 0;
    if (s[i] == '+' || s[i] == '-') neg = s[i++] == '-';
    if (tn__io_token_is(s + i, n - i, "nan")) { *out = neg ? -NAN : NAN; return 1; }
    if (tn__io_token_is(s + i, n - i, "inf") || tn__io_token_is(s + i, n - i, "infinity")) {
        *out = neg ? -HUGE_VAL : HUGE_VAL;
        return 1;
    }
    for (; i < n && tn__io_digit(s[i]); i++, digits++) {
        if (m < 100000000000000000ULL) m = m * 10 + (uint64_t)(s[i] - '0');
        else exp10++; /* digits beyond 17 only scale */
    }
    if (i < n && s[i] == '.')
        for (i++; i < n && tn__io_digit(s[i]); i++, digits++)
            if (m < 100000000000000000ULL) { m = m * 10 + (uint64_t)(s[i] - '0'); exp10--; }
    if (!digits) return 0;
    if (i < n && (s[i] == 'e' || s[i] == 'E')) {
        i++;
        if (i < n && (s[i] == '+' || s[i] == '-')) eneg = s[i++] == '-';
        for (; i < n && tn__io_digit(s[i]); i++, edigits++)
            if (e < 100000) e = e * 10 + (s[i] - '0');
        if (!edigits) return 0;
        exp10 += eneg ? -e : e;
    }
    if (i != n) return 0;
    if (m == 0 || exp10 < -400) v = 0.0;
    else if (exp10 > 400) v = HUGE_VAL;
    else if (exp10 >= 0) v = (double)m * pow(10.0, exp10);
    else v = (double)m / pow(10.0, -exp10); /* 10^k is exact up to 22: one rounding */
    *out = neg ? -v : v;
    return 1;
}

/* Writes the shortest "%.*g" text of v that reads back as v (as a float if as_float), with '.'
   as the decimal point whatever the locale. Returns the length. */
static int tn__io_format_number(char *buf, size_t cap, double v, int as_float)
{
    int prec, len = 0, k;
    for (prec = as_float ? 6 : 15; prec <= 17; prec++) {
        double back = 0;
        len = snprintf(buf, cap, "%.*g", prec, v);
        if (len < 0 || (size_t)len >= cap) return 0;
        for (k = 0; k < len; k++)
            if (buf[k] == ',') buf[k] = '.';
        if (tn__io_number(buf, (size_t)len, &back) &&
            (as_float ? (float)back == (float)v : back == v)) break;
    }
    return len;
}

/* ---- byte order ---- */

static unsigned tn__io_be16(const uint8_t *p) { return ((unsigned)p[0] << 8) | p[1]; }
static unsigned tn__io_le16(const uint8_t *p) { return p[0] | ((unsigned)p[1] << 8); }

static float tn__io_f32(const uint8_t *p, int little)
{
    uint32_t u = little ? (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24)
                        : (uint32_t)p[3] | ((uint32_t)p[2] << 8) | ((uint32_t)p[1] << 16) | ((uint32_t)p[0] << 24);
    float f;
    memcpy(&f, &u, 4);
    return f;
}

static void tn__io_put_f32le(uint8_t *p, float f)
{
    uint32_t u;
    memcpy(&u, &f, 4);
    p[0] = (uint8_t)u; p[1] = (uint8_t)(u >> 8); p[2] = (uint8_t)(u >> 16); p[3] = (uint8_t)(u >> 24);
}

static int tn__io_finite(float v) { return v == v && v <= FLT_MAX && v >= -FLT_MAX; }

/* ---- integer code mapping (shared by PNG, PNM, R16) ---- */

/* Chooses how img maps to integer codes 0..max on save: [*lo, *hi] and whether to record it.
   opts->has_range: that range, recorded. Otherwise data inside [0, 1] is written as is (0..1,
   not recorded) and anything else is mapped from its own min..max and recorded. The image must
   already be free of NaN/Inf. */
static tn_status tn__io_save_mapping(const tn_image *img, const tn_save_opts *opts, double *lo, double *hi, int *record)
{
    float mn, mx;
    if (opts->has_range) {
        double a = opts->range_lo, b = opts->range_hi;
        /* beyond float the file could not be read back (tn_image stores floats) */
        if (!(a == a && b == b && fabs(a) <= FLT_MAX && fabs(b) <= FLT_MAX) || a == b)
            return tn__fail(TN_ERR_INVALID_ARG, "save range [%g, %g] is empty, not finite or beyond float", a, b);
        *lo = a;
        *hi = b;
        *record = 1;
        return TN_OK;
    }
    tn_image_range(&mn, &mx, img);
    if (mn >= 0.0f && mx <= 1.0f) {
        *lo = 0.0;
        *hi = 1.0;
        *record = 0;
        return TN_OK;
    }
    *lo = mn;
    *hi = mx;
    if (*hi == *lo) *hi = *lo + 1.0; /* a constant image: every code is 0 -> lo */
    if (*hi == *lo) *hi = *lo + fabs(*lo) * 1e-6;
    *record = 1;
    return TN_OK;
}

/* round(clamp((v - lo) / (hi - lo), 0, 1) * maxcode), with scale = maxcode / (hi - lo). */
static unsigned tn__io_code(float v, double lo, double scale, unsigned maxcode)
{
    double t = ((double)v - lo) * scale;
    if (!(t > 0.0)) return 0;
    if (t >= (double)maxcode) return maxcode;
    return (unsigned)(t + 0.5);
}

/* Inverse of tn__io_code on load: code/max, or lo..hi when the file records a range. */
static float tn__io_uncode(unsigned code, unsigned maxcode, int has_range, double lo, double hi)
{
    if (!has_range) return (float)code / (float)maxcode;
    return (float)(lo + (hi - lo) * ((double)code / (double)maxcode));
}

/* ---- void filling (.hgt, .asc) ---- */

#define TN__IO_FILL_UPDATES 2e8 /* the relaxation's budget of cell updates, at least 16 a void cell */

/* Voids of more cells than the relaxation covers 16 times (TN__IO_FILL_UPDATES): a push-pull
   pyramid in O(cells), where onion peeling took a minute (a 1 MB TIFF of 16384^2 NODATA with
   one known row). Up: each level halves the grid (rounded up), a cell the mean of its known
   children (known if one is); down: an unknown cell takes the bilinear value of the level above
   at its centre. z: w x h, its voids (mask 1) written. */
static tn_status tn__io_fill_pyramid(float *z, const uint8_t *mask, size_t w, size_t h)
{
    float *lv[64];
    uint8_t *kn[64];
    size_t lw[64], lh[64], x, y;
    int L = 0, l, unknown = 1, i, j;
    tn_status st = TN_OK;
    lv[0] = z, lw[0] = w, lh[0] = h, kn[0] = NULL;
    while (unknown && L < 63 && !st) { /* up */
        const size_t cw = (lw[L] + 1) / 2, ch = (lh[L] + 1) / 2;
        lv[L + 1] = (float *)tn__alloc(cw * ch * sizeof(float));
        kn[L + 1] = (uint8_t *)tn__alloc(cw * ch);
        if (!lv[L + 1] || !kn[L + 1]) {
            TN_FREE(lv[L + 1]);
            TN_FREE(kn[L + 1]);
            st = tn__oom();
            break;
        }
        unknown = 0;
        for (y = 0; y < ch; y++)
            for (x = 0; x < cw; x++) {
                double sum = 0;
                int cnt = 0;
                for (j = 0; j < 2; j++)
                    for (i = 0; i < 2; i++) {
                        size_t fx = 2 * x + (size_t)i, fy = 2 * y + (size_t)j, f = fy * lw[L] + fx;
                        if (fx < lw[L] && fy < lh[L] && (L ? kn[L][f] : !mask[f])) sum += lv[L][f], cnt++;
                    }
                lv[L + 1][y * cw + x] = cnt ? (float)(sum / cnt) : 0.0f;
                kn[L + 1][y * cw + x] = (uint8_t)(cnt > 0);
                unknown |= !cnt;
            }
        lw[L + 1] = cw, lh[L + 1] = ch;
        L++;
    }
    for (l = L - 1; l >= 0 && !st; l--) { /* down: level l + 1 is whole */
        const size_t cw = lw[l + 1], ch = lh[l + 1];
        for (y = 0; y < lh[l]; y++) {
            float t = ((float)y + 0.5f) / 2 - 0.5f;
            size_t y0, y1;
            const float *ra, *rb;
            t = t < 0 ? 0 : t > (float)(ch - 1) ? (float)(ch - 1) : t;
            y0 = (size_t)t, y1 = y0 + 1 < ch ? y0 + 1 : y0;
            t -= (float)y0;
            ra = lv[l + 1] + y0 * cw, rb = lv[l + 1] + y1 * cw;
            for (x = 0; x < lw[l]; x++) {
                size_t f = y * lw[l] + x, x0, x1;
                float u;
                if (l ? kn[l][f] : !mask[f]) continue;
                u = ((float)x + 0.5f) / 2 - 0.5f;
                u = u < 0 ? 0 : u > (float)(cw - 1) ? (float)(cw - 1) : u;
                x0 = (size_t)u, x1 = x0 + 1 < cw ? x0 + 1 : x0;
                u -= (float)x0;
                lv[l][f] = (1 - t) * ((1 - u) * ra[x0] + u * ra[x1]) + t * ((1 - u) * rb[x0] + u * rb[x1]);
            }
        }
    }
    for (l = 1; l <= L; l++) {
        TN_FREE(lv[l]);
        TN_FREE(kn[l]);
    }
    return st;
}

/* Fills the cells of a w x h grid whose mask byte is 1 (see the banner); mask is scratch.
   *filled gets the number of void cells. */
static tn_status tn__io_fill_voids(float *z, uint8_t *mask, size_t w, size_t h, const char *name, size_t *filled)
{
    static const int ox[8] = {-1, 0, 1, -1, 1, -1, 0, 1}, oy[8] = {-1, -1, -1, 0, 0, 1, 1, 1};
    size_t n = w * h, nv = 0, i, k, head, tail, bytes = 0, rings = 0;
    size_t *q;
    double omega, passes;
    int pass, d;
    *filled = 0;
    for (i = 0; i < n; i++) nv += mask[i] != 0;
    if (nv == 0) return TN_OK;
    if (nv == n) return tn__fail(TN_ERR_EMPTY, "%s: every cell is void / NODATA", name);
    if ((double)nv * 16 > TN__IO_FILL_UPDATES) {
        tn_status st = tn__io_fill_pyramid(z, mask, w, h);
        if (!st) *filled = nv;
        return st;
    }
    if (tn__size4(nv, sizeof(size_t), 1, 1, &bytes)) return TN_ERR_TOO_LARGE;
    q = (size_t *)tn__alloc(bytes);
    if (!q) return tn__oom();
    /* mask: 0 known, 1 void not yet queued, 2 void queued; the first ring touches known cells */
    tail = 0;
    for (i = 0; i < n; i++) {
        size_t x = i % w, y = i / w;
        if (mask[i] != 1) continue;
        for (d = 0; d < 8; d++) {
            size_t xx = x + (size_t)(ptrdiff_t)ox[d], yy = y + (size_t)(ptrdiff_t)oy[d]; /* wraps past 0: caught by < */
            if (xx < w && yy < h && mask[yy * w + xx] == 0) { mask[i] = 2; q[tail++] = i; break; }
        }
    }
    for (head = 0; head < tail;) {
        size_t end = tail;
        for (k = head; k < end; k++) { /* reads only cells known before this ring */
            size_t c = q[k], x = c % w, y = c / w;
            double sum = 0.0, wsum = 0.0;
            for (d = 0; d < 8; d++) {
                size_t xx = x + (size_t)(ptrdiff_t)ox[d], yy = y + (size_t)(ptrdiff_t)oy[d];
                if (xx < w && yy < h && mask[yy * w + xx] == 0) {
                    double wt = (ox[d] && oy[d]) ? 0.5 : 1.0;
                    sum += wt * z[yy * w + xx];
                    wsum += wt;
                }
            }
            z[c] = (float)(sum / wsum);
        }
        for (k = head; k < end; k++) mask[q[k]] = 0;
        for (k = head; k < end; k++) {
            size_t c = q[k], x = c % w, y = c / w;
            for (d = 0; d < 8; d++) {
                size_t xx = x + (size_t)(ptrdiff_t)ox[d], yy = y + (size_t)(ptrdiff_t)oy[d];
                if (xx < w && yy < h && mask[yy * w + xx] == 1) { mask[yy * w + xx] = 2; q[tail++] = yy * w + xx; }
            }
        }
        head = end;
        rings++;
    }
    /* SOR with the optimal factor for a hole about 2*rings+1 cells wide; passes grow with the
       hole size, capped at about TN__IO_FILL_UPDATES cell updates. mask now holds each void cell's in-image
       4-neighbours (bits left, right, up, down) so the sweeps need no divisions. Sweeping in
       ring order (rim inwards) converged faster than memory order in tests. */
    for (k = 0; k < tail; k++) {
        size_t c = q[k], x = c % w, y = c / w;
        mask[c] = (uint8_t)((x > 0) | ((x + 1 < w) << 1) | ((y > 0) << 2) | ((y + 1 < h) << 3));
    }
    omega = 2.0 / (1.0 + sin(3.141592653589793 / (2.0 * (double)rings + 2.0)));
    if (omega > 1.95) omega = 1.95;
    passes = 32.0 + 4.0 * (double)rings;
    if (passes * (double)nv > TN__IO_FILL_UPDATES) passes = TN__IO_FILL_UPDATES / (double)nv;
    if (passes < 16) passes = 16;
    for (pass = 0; pass < (int)passes; pass++) {
        double change = 0.0, scale = 0.0;
        for (k = 0; k < tail; k++) {
            size_t c = q[k];
            int m = mask[c];
            double sum, old = z[c], avg;
            if (m == 15) avg = 0.25 * ((double)z[c - 1] + z[c + 1] + z[c - w] + z[c + w]);
            else {
                int cnt = 0;
                sum = 0.0;
                if (m & 1) { sum += z[c - 1]; cnt++; }
                if (m & 2) { sum += z[c + 1]; cnt++; }
                if (m & 4) { sum += z[c - w]; cnt++; }
                if (m & 8) { sum += z[c + w]; cnt++; }
                if (!cnt) continue; /* a 1x1 grid */
                avg = sum / cnt;
            }
            z[c] = (float)(old + omega * (avg - old));
            if (fabs(z[c] - old) > change) change = fabs(z[c] - old);
            if (fabs(old) > scale) scale = fabs(old);
        }
        if (change <= 1e-6 * scale) break;
    }
    TN_FREE(q);
    *filled = nv;
    return TN_OK;
}

/* ---- PGM / PPM ---- */

/* Parses a "# terrainnet.range <lo> <hi>" comment body; other comments are ignored. */
static void tn__pnm_comment(const uint8_t *p, size_t n, int *has_range, double *lo, double *hi)
{
    size_t i = 0, tb, tl;
    double a, b;
    if (!tn__io_token(p, n, &i, &tb, &tl) || !tn__io_token_is((const char *)p + tb, tl, "terrainnet.range")) return;
    if (!tn__io_token(p, n, &i, &tb, &tl) || !tn__io_number((const char *)p + tb, tl, &a)) return;
    if (!tn__io_token(p, n, &i, &tb, &tl) || !tn__io_number((const char *)p + tb, tl, &b)) return;
    if (tn__io_token(p, n, &i, &tb, &tl)) return;
    if (a != a || b != b || a == b) return; /* malformed: just a comment */
    *has_range = fabs(a) <= FLT_MAX && fabs(b) <= FLT_MAX ? 1 : -1; /* -1: beyond float, refused */
    *lo = a;
    *hi = b;
}

/* Skips whitespace and (when allowed) '#' comments, noting a range comment. */
static void tn__pnm_skip(const uint8_t *p, size_t n, size_t *i, int comments, int *has_range, double *lo, double *hi)
{
    size_t k = *i;
    for (;;) {
        while (k < n && tn__io_space(p[k])) k++;
        if (comments && k < n && p[k] == '#') {
            size_t b = ++k;
            while (k < n && p[k] != '\n' && p[k] != '\r') k++;
            tn__pnm_comment(p + b, k - b, has_range, lo, hi);
            continue;
        }
        break;
    }
    *i = k;
}

/* Unsigned decimal at p[*i]; 1 ok, 0 not a number, -1 larger than max. */
static int tn__pnm_uint(const uint8_t *p, size_t n, size_t *i, unsigned long max, unsigned long *v)
{
    size_t k = *i;
    unsigned long x = 0;
    int over = 0;
    if (k >= n || !tn__io_digit(p[k])) return 0;
    for (; k < n && tn__io_digit(p[k]); k++) {
        unsigned d = (unsigned)(p[k] - '0');
        if (x > (max - d) / 10) over = 1;
        else x = x * 10 + d;
    }
    if (k < n && !tn__io_space(p[k]) && p[k] != '#') return 0; /* "12x" */
    *i = k;
    *v = x;
    return over ? -1 : 1;
}

static int tn__pnm_bits(unsigned long maxval)
{
    int b = 1;
    while (((1ul << b) - 1) < maxval) b++;
    return b;
}

static tn_status tn__pnm_decode(const uint8_t *p, size_t n, const char *name, tn_image *img, tn_image_info *info)
{
    unsigned long dim[3] = {0, 0, 0};
    static const char *const what[3] = {"width", "height", "maxval"};
    size_t i = 2, count, bytes = 0, k, bps, rem;
    int kind, ch, has_range = 0, r, j;
    double lo = 0.0, hi = 0.0;
    tn_status st;
    if (n < 2 || p[0] != 'P') return tn__fail(TN_ERR_FORMAT, "%s: not a PGM/PPM file", name);
    kind = p[1] - '0';
    if (kind == 1 || kind == 4 || kind == 7)
        return tn__fail(TN_ERR_FORMAT, "%s: P%d (PBM bitmap / PAM) is not supported; use P2/P3/P5/P6", name, kind);
    if (kind != 2 && kind != 3 && kind != 5 && kind != 6) return tn__fail(TN_ERR_FORMAT, "%s: not a PGM/PPM file", name);
    if (n > 2 && !tn__io_space(p[2]) && p[2] != '#') return tn__fail(TN_ERR_FORMAT, "%s: not a PGM/PPM file", name);
    ch = (kind == 3 || kind == 6) ? 3 : 1;
    for (j = 0; j < 3; j++) {
        tn__pnm_skip(p, n, &i, 1, &has_range, &lo, &hi);
        r = tn__pnm_uint(p, n, &i, j < 2 ? (unsigned long)INT_MAX : 65535ul, &dim[j]);
        if (r == 0) {
            if (i >= n) return tn__fail(TN_ERR_CORRUPT, "%s: truncated PNM header (no %s)", name, what[j]);
            return tn__fail(TN_ERR_CORRUPT, "%s: bad PNM %s", name, what[j]);
        }
        if (r < 0 && j < 2) return tn__fail(TN_ERR_TOO_LARGE, "%s: PNM %s too large", name, what[j]);
        if (r < 0 || dim[j] == 0)
            return tn__fail(j < 2 ? TN_ERR_CORRUPT : TN_ERR_FORMAT, "%s: PNM %s %s is not supported (1..%s)", name,
                            what[j], r < 0 ? "> 65535" : "0", j < 2 ? "2^31-1" : "65535");
    }
    if (tn__size4(dim[0], dim[1], (size_t)ch, sizeof(float), &bytes)) return tn__fail_context(TN_ERR_TOO_LARGE, name);
    if (has_range < 0) return tn__fail(TN_ERR_NUMERIC, "%s: terrainnet.range [%g, %g] is beyond float range", name, lo, hi);
    count = (size_t)dim[0] * dim[1] * (size_t)ch;
    bps = dim[2] > 255 ? 2 : 1;
    if (kind >= 5) { /* exactly one whitespace byte, then raw samples */
        if (i >= n) return tn__fail(TN_ERR_CORRUPT, "%s: truncated PNM (no pixel data)", name);
        if (!tn__io_space(p[i])) return tn__fail(TN_ERR_CORRUPT, "%s: no whitespace after the PNM maxval", name);
        i++;
        rem = n - i;
        if (rem / bps < count)
            return tn__fail(TN_ERR_CORRUPT, "%s: truncated PNM: %zu of %zu data bytes", name, rem, count * bps);
    } else {
        tn__pnm_skip(p, n, &i, 1, &has_range, &lo, &hi);
        rem = n - i;
        if (count > rem / 2 + 1) /* every sample needs a digit and all but the last a separator */
            return tn__fail(TN_ERR_CORRUPT, "%s: truncated PNM: %zu samples cannot fit in %zu bytes", name, count, rem);
    }
    st = tn_image_create(img, (int)dim[0], (int)dim[1], ch);
    if (st) return tn__fail_context(st, name);
    for (k = 0; k < count; k++) {
        unsigned long c;
        if (kind >= 5) {
            c = bps == 2 ? tn__io_be16(p + i + 2 * k) : p[i + k];
        } else {
            tn__pnm_skip(p, n, &i, 1, &has_range, &lo, &hi);
            r = tn__pnm_uint(p, n, &i, 65535ul, &c);
            if (r == 0) {
                tn_image_free(img);
                if (i >= n) return tn__fail(TN_ERR_CORRUPT, "%s: truncated PNM: %zu of %zu samples", name, k, count);
                return tn__fail(TN_ERR_CORRUPT, "%s: bad PNM sample %zu", name, k);
            }
            if (r < 0) c = 65536ul;
        }
        if (c > dim[2]) {
            tn_image_free(img);
            return tn__fail(TN_ERR_CORRUPT, "%s: PNM sample %zu exceeds maxval %lu", name, k, dim[2]);
        }
        img->data[k] = (float)c; /* converted below, once the range comment (if any) is known */
    }
    if (has_range < 0) { /* a range comment among the samples */
        tn_image_free(img);
        return tn__fail(TN_ERR_NUMERIC, "%s: terrainnet.range [%g, %g] is beyond float range", name, lo, hi);
    }
    for (k = 0; k < count; k++)
        img->data[k] = tn__io_uncode((unsigned)img->data[k], (unsigned)dim[2], has_range, lo, hi);
    info->bit_depth = tn__pnm_bits(dim[2]);
    info->file_channels = ch;
    info->has_range = has_range;
    info->range_lo = has_range ? lo : 0.0;
    info->range_hi = has_range ? hi : 0.0;
    return TN_OK;
}

/* Writes binary P5 (1 channel) or P6 (3 channels), 8 or 16 bits big-endian. */
static tn_status tn__pnm_encode(const tn_image *img, int bits, double lo, double hi, int record, uint8_t **out,
                                size_t *out_size)
{
    char hdr[256], a[40], b[40];
    size_t count, data = 0, total, k;
    unsigned maxc = bits == 16 ? 65535u : 255u;
    double scale = (double)maxc / (hi - lo);
    int len;
    uint8_t *buf, *d;
    tn_status st;
    if (img->channels != 1 && img->channels != 3)
        return tn__fail(TN_ERR_SHAPE, "PGM/PPM stores 1 or 3 channels, not %d", img->channels);
    if (record) {
        tn__io_format_number(a, sizeof a, lo, 0);
        tn__io_format_number(b, sizeof b, hi, 0);
        len = snprintf(hdr, sizeof hdr, "P%d\n# terrainnet.range %s %s\n%d %d\n%u\n", img->channels == 1 ? 5 : 6, a, b,
                       img->width, img->height, maxc);
    } else {
        len = snprintf(hdr, sizeof hdr, "P%d\n%d %d\n%u\n", img->channels == 1 ? 5 : 6, img->width, img->height, maxc);
    }
    st = tn__size4((size_t)img->width, (size_t)img->height, (size_t)img->channels, (size_t)bits / 8, &data);
    if (st) return st;
    count = data / ((size_t)bits / 8);
    total = (size_t)len + data;
    buf = (uint8_t *)tn__alloc(total);
    if (!buf) return tn__oom();
    memcpy(buf, hdr, (size_t)len);
    d = buf + len;
    for (k = 0; k < count; k++) {
        unsigned c = tn__io_code(img->data[k], lo, scale, maxc);
        if (bits == 16) { d[2 * k] = (uint8_t)(c >> 8); d[2 * k + 1] = (uint8_t)c; }
        else d[k] = (uint8_t)c;
    }
    *out = buf;
    *out_size = total;
    return TN_OK;
}

/* ---- PFM ---- */

static tn_status tn__pfm_decode(const uint8_t *p, size_t n, const char *name, tn_image *img, tn_image_info *info)
{
    unsigned long w = 0, h = 0;
    size_t i = 2, tb, tl, bytes = 0, need, row, x, bad = 0;
    int ch, r, little, dummy = 0;
    double scale = 0.0, dlo, dhi;
    tn_status st;
    if (n < 2 || p[0] != 'P' || (p[1] != 'F' && p[1] != 'f')) return tn__fail(TN_ERR_FORMAT, "%s: not a PFM file", name);
    ch = p[1] == 'F' ? 3 : 1;
    tn__pnm_skip(p, n, &i, 0, &dummy, &dlo, &dhi);
    r = tn__pnm_uint(p, n, &i, (unsigned long)INT_MAX, &w);
    if (r > 0) {
        tn__pnm_skip(p, n, &i, 0, &dummy, &dlo, &dhi);
        r = tn__pnm_uint(p, n, &i, (unsigned long)INT_MAX, &h);
    }
    if (r < 0) return tn__fail(TN_ERR_TOO_LARGE, "%s: PFM size too large", name);
    if (r == 0) return tn__fail(TN_ERR_CORRUPT, "%s: %s PFM size", name, i >= n ? "truncated header: no" : "bad");
    if (w == 0 || h == 0) return tn__fail(TN_ERR_CORRUPT, "%s: PFM size %lu x %lu is empty", name, w, h);
    if (!tn__io_token(p, n, &i, &tb, &tl)) return tn__fail(TN_ERR_CORRUPT, "%s: truncated PFM header (no scale)", name);
    if (!tn__io_number((const char *)p + tb, tl, &scale) || scale == 0.0 || scale != scale || fabs(scale) > DBL_MAX)
        return tn__fail(TN_ERR_CORRUPT, "%s: bad PFM scale", name);
    little = scale < 0.0; /* the sign of the scale gives the byte order */
    if (tn__size4(w, h, (size_t)ch, sizeof(float), &bytes)) return tn__fail_context(TN_ERR_TOO_LARGE, name);
    if (i >= n || !tn__io_space(p[i])) return tn__fail(TN_ERR_CORRUPT, "%s: truncated PFM (no pixel data)", name);
    i++;
    need = bytes; /* 4 bytes per sample in the file too */
    if (n - i < need) return tn__fail(TN_ERR_CORRUPT, "%s: truncated PFM: %zu of %zu data bytes", name, n - i, need);
    st = tn_image_create(img, (int)w, (int)h, ch);
    if (st) return tn__fail_context(st, name);
    for (row = 0; row < h; row++) { /* rows are stored bottom to top */
        const uint8_t *src = p + i + row * w * (size_t)ch * 4;
        float *dst = img->data + (h - 1 - row) * w * (size_t)ch;
        for (x = 0; x < w * (size_t)ch; x++) {
            float v = tn__io_f32(src + 4 * x, little);
            bad += !tn__io_finite(v);
            dst[x] = v;
        }
    }
    if (bad) {
        tn_image_free(img);
        return tn__fail(TN_ERR_NUMERIC, "%s: %zu NaN/Inf samples in the PFM (terrain code cannot use them)", name, bad);
    }
    info->bit_depth = 32;
    info->file_channels = ch;
    return TN_OK;
}

/* Writes little-endian PFM (scale -1), bottom row first. */
static tn_status tn__pfm_encode(const tn_image *img, uint8_t **out, size_t *out_size)
{
    char hdr[64];
    size_t data = 0, row, x, w = (size_t)img->width, h = (size_t)img->height, ch = (size_t)img->channels;
    int len;
    uint8_t *buf;
    tn_status st;
    if (img->channels != 1 && img->channels != 3)
        return tn__fail(TN_ERR_SHAPE, "PFM stores 1 or 3 channels, not %d", img->channels);
    len = snprintf(hdr, sizeof hdr, "P%c\n%d %d\n-1.0\n", ch == 3 ? 'F' : 'f', img->width, img->height);
    st = tn__size4(w, h, ch, 4, &data);
    if (st) return st;
    buf = (uint8_t *)tn__alloc((size_t)len + data);
    if (!buf) return tn__oom();
    memcpy(buf, hdr, (size_t)len);
    for (row = 0; row < h; row++) {
        uint8_t *dst = buf + len + row * w * ch * 4;
        const float *src = img->data + (h - 1 - row) * w * ch;
        for (x = 0; x < w * ch; x++) tn__io_put_f32le(dst + 4 * x, src[x]);
    }
    *out = buf;
    *out_size = (size_t)len + data;
    return TN_OK;
}

/* ---- SRTM .hgt ---- */

/* The pixel size in metres of an SRTM tile (1" or 3" of arc): the mean of its north-south and
   east-west spacing at the latitude its name gives ("N47E009.hgt": 47.5 degrees; else 0). */
static double tn__hgt_spacing(const char *name, size_t side)
{
    const char *base = name, *q;
    double ns = (side == 3601 ? 1.0 : 3.0) * 30.87, lat = 0;
    for (q = name; *q; q++)
        if (*q == '/' || *q == '\\') base = q + 1;
    if ((base[0] == 'N' || base[0] == 'S' || base[0] == 'n' || base[0] == 's') && base[1] >= '0' && base[1] <= '9' && base[2] >= '0' &&
        base[2] <= '9')
        lat = (base[1] - '0') * 10 + (base[2] - '0') + ((base[0] == 'S' || base[0] == 's') ? -0.5 : 0.5);
    return 0.5 * (ns + ns * cos(lat * 0.017453292519943295));
}

static tn_status tn__hgt_decode(const uint8_t *p, size_t n, const char *name, tn_image *img, tn_image_info *info)
{
    size_t side, count, k, nvoid = 0;
    uint8_t *mask;
    tn_status st;
    if (n == (size_t)1201 * 1201 * 2) side = 1201;
    else if (n == (size_t)3601 * 3601 * 2) side = 3601;
    else
        return tn__fail(TN_ERR_CORRUPT, "%s: %zu bytes is not an SRTM tile (1201^2 or 3601^2 int16 = %zu or %zu bytes)",
                        name, n, (size_t)1201 * 1201 * 2, (size_t)3601 * 3601 * 2);
    count = side * side;
    mask = (uint8_t *)tn__calloc(count);
    if (!mask) return tn__fail_context(TN_ERR_OUT_OF_MEMORY, name);
    st = tn_image_create(img, (int)side, (int)side, 1);
    if (st) { TN_FREE(mask); return tn__fail_context(st, name); }
    for (k = 0; k < count; k++) {
        unsigned u = tn__io_be16(p + 2 * k);
        int v = u >= 32768u ? (int)u - 65536 : (int)u;
        if (v == -32768) { mask[k] = 1; nvoid++; }
        else img->data[k] = (float)v;
    }
    st = nvoid ? tn__io_fill_voids(img->data, mask, side, side, name, &info->voids_filled) : TN_OK;
    TN_FREE(mask);
    if (st) { tn_image_free(img); return st; }
    info->bit_depth = 16;
    info->file_channels = 1;
    info->cellsize = tn__hgt_spacing(name, side);
    return TN_OK;
}

/* Writes metres rounded to int16, clamped to +-32767 (-32768 would read back as a void). */
static tn_status tn__hgt_encode(const tn_image *img, uint8_t **out, size_t *out_size)
{
    size_t count, k;
    uint8_t *buf;
    if (img->channels != 1 || img->width != img->height || (img->width != 1201 && img->width != 3601))
        return tn__fail(TN_ERR_SHAPE, ".hgt holds 1201x1201 or 3601x3601 single-channel grids, not %dx%dx%d",
                        img->width, img->height, img->channels);
    count = (size_t)img->width * (size_t)img->height;
    buf = (uint8_t *)tn__alloc(count * 2);
    if (!buf) return tn__oom();
    for (k = 0; k < count; k++) {
        double v = floor((double)img->data[k] + 0.5);
        int s = v < -32767.0 ? -32767 : (v > 32767.0 ? 32767 : (int)v);
        unsigned u = (unsigned)(s & 0xffff);
        buf[2 * k] = (uint8_t)(u >> 8);
        buf[2 * k + 1] = (uint8_t)u;
    }
    *out = buf;
    *out_size = count * 2;
    return TN_OK;
}

/* ---- ESRI ASCII grid .asc ---- */

/* Header keys, in the order of tn__asc_decode's switch. */
static const char *const tn__asc_keys[] = {"ncols", "nrows", "xllcorner", "xllcenter", "yllcorner",
                                            "yllcenter", "cellsize", "dx", "dy", "nodata_value"};
#define TN__ASC_NKEYS 10

static int tn__asc_key(const char *t, size_t n)
{
    int k;
    for (k = 0; k < TN__ASC_NKEYS; k++)
        if (tn__io_token_is(t, n, tn__asc_keys[k])) return k;
    return -1;
}

static tn_status tn__asc_decode(const uint8_t *p, size_t n, const char *name, tn_image *img, tn_image_info *info)
{
    double val[TN__ASC_NKEYS];
    int seen[TN__ASC_NKEYS] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
    size_t i = 0, tb, tl, bytes = 0, count, k, nvoid = 0, w, h;
    double cs;
    uint8_t *mask;
    tn_status st;
    memset(val, 0, sizeof val);
    for (;;) { /* "key value" pairs until the first number */
        size_t at = i;
        double v = 0.0;
        int key, ok;
        if (!tn__io_token(p, n, &i, &tb, &tl)) break;
        if (tn__io_number((const char *)p + tb, tl, &v)) { i = at; break; }
        key = tn__asc_key((const char *)p + tb, tl);
        if (key < 0)
            return tn__fail(TN_ERR_FORMAT, "%s: unknown .asc header key '%.*s'", name, (int)(tl > 32 ? 32 : tl),
                            (const char *)p + tb);
        ok = tn__io_token(p, n, &i, &tb, &tl) && tn__io_number((const char *)p + tb, tl, &v);
        if (ok && !(fabs(v) <= DBL_MAX) && !(key == 9 && v != v)) ok = 0; /* only NODATA_value may be nan */
        if (!ok) return tn__fail(TN_ERR_CORRUPT, "%s: missing or bad value for .asc key %s", name, tn__asc_keys[key]);
        val[key] = v;
        seen[key] = 1;
    }
    if (!seen[0] || !seen[1] || val[0] < 1 || val[1] < 1 || val[0] != floor(val[0]) || val[1] != floor(val[1]))
        return tn__fail(TN_ERR_CORRUPT, "%s: .asc header needs positive integer ncols and nrows", name);
    if (val[0] > INT_MAX || val[1] > INT_MAX) return tn__fail(TN_ERR_TOO_LARGE, "%s: .asc grid too large", name);
    w = (size_t)val[0];
    h = (size_t)val[1];
    if (tn__size4(w, h, 1, sizeof(float), &bytes)) return tn__fail_context(TN_ERR_TOO_LARGE, name);
    count = w * h;
    if (count > (n - i) / 2 + 1)
        return tn__fail(TN_ERR_CORRUPT, "%s: truncated .asc: %zu values cannot fit in %zu bytes", name, count, n - i);
    mask = (uint8_t *)tn__calloc(count);
    if (!mask) return tn__fail_context(TN_ERR_OUT_OF_MEMORY, name);
    st = tn_image_create(img, (int)w, (int)h, 1);
    if (st) { TN_FREE(mask); return tn__fail_context(st, name); }
    for (k = 0; k < count && st == TN_OK; k++) {
        double v = 0.0;
        if (!tn__io_token(p, n, &i, &tb, &tl))
            st = tn__fail(TN_ERR_CORRUPT, "%s: truncated .asc: %zu of %zu values", name, k, count);
        else if (!tn__io_number((const char *)p + tb, tl, &v))
            st = tn__fail(TN_ERR_CORRUPT, "%s: bad .asc value '%.*s' (value %zu)", name, (int)(tl > 32 ? 32 : tl),
                          (const char *)p + tb, k);
        else if (v != v || fabs(v) > DBL_MAX || (seen[9] && (v == val[9] || (float)v == (float)val[9]))) {
            mask[k] = 1;
            nvoid++;
        } else if (fabs(v) > FLT_MAX)
            st = tn__fail(TN_ERR_CORRUPT, "%s: .asc value %g out of float range", name, v);
        else
            img->data[k] = (float)v;
    }
    if (st == TN_OK && tn__io_token(p, n, &i, &tb, &tl))
        st = tn__fail(TN_ERR_CORRUPT, "%s: .asc has more values than ncols x nrows = %zu", name, count);
    if (st == TN_OK && nvoid) st = tn__io_fill_voids(img->data, mask, w, h, name, &info->voids_filled);
    TN_FREE(mask);
    if (st) { tn_image_free(img); return st; }
    cs = seen[6] ? val[6] : (seen[7] ? val[7] : (seen[8] ? val[8] : 0.0));
    info->bit_depth = 32;
    info->file_channels = 1;
    info->cellsize = cs;
    info->x_origin = seen[3] && !seen[2] ? val[3] - 0.5 * cs : val[2]; /* centre -> corner */
    info->y_origin = seen[5] && !seen[4] ? val[5] - 0.5 * cs : val[4];
    info->has_nodata = seen[9];
    info->nodata = seen[9] ? val[9] : 0.0;
    if (cs > 0.0 && fabs(info->y_origin + cs * (double)h) <= DBL_MAX) { /* CRS unknown: no spacing in metres */
        double *gt = info->georef.transform;
        info->georef.has_transform = 1;
        gt[0] = info->x_origin;
        gt[1] = cs;
        gt[3] = info->y_origin + cs * (double)h;
        gt[5] = -cs;
    }
    return TN_OK;
}

/* Appends k bytes to a growing TN_MALLOC'd buffer. */
static tn_status tn__io_append(void **buf, size_t *len, size_t *cap, const void *d, size_t k)
{
    tn_status st = tn__reserve(buf, cap, *len + k);
    if (st) return st;
    memcpy((uint8_t *)*buf + *len, d, k);
    *len += k;
    return TN_OK;
}

/* Writes the header (origin 0, the given cell size) and one text row per image row. */
static tn_status tn__asc_encode(const tn_image *img, double cellsize, uint8_t **out, size_t *out_size)
{
    char line[160], num[48];
    void *buf = NULL;
    size_t len = 0, cap = 0, x, y;
    int k;
    tn_status st;
    if (img->channels != 1) return tn__fail(TN_ERR_SHAPE, ".asc stores 1 channel, not %d", img->channels);
    tn__io_format_number(num, sizeof num, cellsize, 0);
    k = snprintf(line, sizeof line, "ncols %d\nnrows %d\nxllcorner 0\nyllcorner 0\ncellsize %s\n", img->width,
                 img->height, num);
    st = tn__io_append(&buf, &len, &cap, line, (size_t)k);
    for (y = 0; y < (size_t)img->height && !st; y++) {
        for (x = 0; x < (size_t)img->width && !st; x++) {
            k = tn__io_format_number(num + 1, sizeof num - 1, img->data[y * (size_t)img->width + x], 1);
            num[0] = ' ';
            st = x ? tn__io_append(&buf, &len, &cap, num, (size_t)k + 1) : tn__io_append(&buf, &len, &cap, num + 1, (size_t)k);
        }
        if (!st) st = tn__io_append(&buf, &len, &cap, "\n", 1);
    }
    if (st) { TN_FREE(buf); return st; }
    *out = (uint8_t *)buf;
    *out_size = len;
    return TN_OK;
}

/* ---- headerless little-endian 16-bit .r16 ---- */

static tn_status tn__r16_decode(const uint8_t *p, size_t n, const char *name, const tn_load_opts *opts, tn_image *img,
                                tn_image_info *info)
{
    size_t w, h, bytes = 0, k;
    int rw = opts ? opts->raw_width : 0, rh = opts ? opts->raw_height : 0;
    tn_status st;
    if (rw < 0 || rh < 0 || (rw == 0) != (rh == 0))
        return tn__fail(TN_ERR_INVALID_ARG, "%s: raw_width/raw_height %d x %d: give both or neither", name, rw, rh);
    if (rw) {
        w = (size_t)rw;
        h = (size_t)rh;
        if (tn__size4(w, h, 1, sizeof(float), &bytes)) return tn__fail_context(TN_ERR_TOO_LARGE, name);
        if (n != w * h * 2)
            return tn__fail(TN_ERR_SHAPE, "%s: %zu bytes, but %zu x %zu 16-bit samples need %zu", name, n, w, h, w * h * 2);
    } else {
        size_t s = n / 2, side;
        if (n == 0) return tn__fail(TN_ERR_EMPTY, "%s: empty .r16 file", name);
        side = (size_t)sqrt((double)s);
        while (side * side > s) side--;
        while ((side + 1) * (side + 1) <= s) side++;
        if (n % 2 || side * side != s)
            return tn__fail(TN_ERR_SHAPE, "%s: %zu bytes is not a square 16-bit grid; give raw_width/raw_height", name, n);
        if (side > (size_t)INT_MAX) return tn__fail(TN_ERR_TOO_LARGE, "%s: .r16 grid too large", name);
        w = h = side;
        if (tn__size4(w, h, 1, sizeof(float), &bytes)) return tn__fail_context(TN_ERR_TOO_LARGE, name);
    }
    st = tn_image_create(img, (int)w, (int)h, 1);
    if (st) return tn__fail_context(st, name);
    for (k = 0; k < w * h; k++) img->data[k] = (float)tn__io_le16(p + 2 * k) / 65535.0f;
    info->bit_depth = 16;
    info->file_channels = 1;
    return TN_OK;
}

static tn_status tn__r16_encode(const tn_image *img, double lo, double hi, uint8_t **out, size_t *out_size)
{
    size_t count, k;
    double scale = 65535.0 / (hi - lo);
    uint8_t *buf;
    if (img->channels != 1) return tn__fail(TN_ERR_SHAPE, ".r16 stores 1 channel, not %d", img->channels);
    count = (size_t)img->width * (size_t)img->height;
    buf = (uint8_t *)tn__alloc(count * 2);
    if (!buf) return tn__oom();
    for (k = 0; k < count; k++) {
        unsigned c = tn__io_code(img->data[k], lo, scale, 65535u);
        buf[2 * k] = (uint8_t)c;
        buf[2 * k + 1] = (uint8_t)(c >> 8);
    }
    *out = buf;
    *out_size = count * 2;
    return TN_OK;
}

/* ---- TIFF / GeoTIFF ----
   Reader: the IFD chain is walked (visited offsets remembered, so a loop is an error) to the
   first image that is neither an overview nor a mask. Every tag value, strip and tile is
   checked against the file size before use, and each compressed chunk against the largest
   expansion of its codec (Deflate 1032:1, LZW 4096:1, PackBits 64:1) before the image is
   allocated, so a small file cannot claim gigabytes. Chunks are independent: threads decode
   contiguous runs of them with private scratch, straight into the float image; the first
   failing chunk is decoded again on the caller to give a deterministic message.
   LZW keeps each table entry as (start, length) in the chunk's own output: every entry is an
   earlier string plus one byte and lies contiguously in what was already written, so a code
   costs one memcpy and no string table. The floating-point predictor follows libtiff's fpAcc:
   bytes are differenced along the row, then stored as byte planes, most significant first.
   GDAL conventions are followed where the TIFF spec is silent: GDAL_NODATA as ASCII, the
   geotransform from scale + first tiepoint (Y scale taken as negative) or the 4x4 matrix,
   PixelIsPoint moved half a pixel. */

enum {
    TN__TT_SUBFILE, TN__TT_WIDTH, TN__TT_HEIGHT, TN__TT_BITS, TN__TT_COMPRESSION, TN__TT_PHOTOMETRIC, TN__TT_FILLORDER,
    TN__TT_STRIP_OFFSETS, TN__TT_SPP, TN__TT_ROWS_PER_STRIP, TN__TT_STRIP_BYTES, TN__TT_PLANAR, TN__TT_PREDICTOR,
    TN__TT_TILE_W, TN__TT_TILE_H, TN__TT_TILE_OFFSETS, TN__TT_TILE_BYTES, TN__TT_SAMPLE_FORMAT, TN__TT_SCALE,
    TN__TT_TIEPOINT, TN__TT_TRANSFORM, TN__TT_GEOKEYS, TN__TT_GEODOUBLES, TN__TT_GEOASCII, TN__TT_NODATA, TN__TT_COUNT
};
static const unsigned tn__tif_tag_ids[TN__TT_COUNT] = {254, 256, 257, 258, 259, 262, 266, 273, 277, 278, 279, 284, 317,
                                                       322, 323, 324, 325, 339, 33550, 33922, 34264, 34735, 34736,
                                                       34737, 42113};
/* bytes per value of TIFF field types 1..18 (0 = unknown type) */
static const uint8_t tn__tif_type_size[19] = {0, 1, 1, 2, 4, 8, 1, 1, 2, 4, 8, 4, 8, 4, 0, 0, 8, 8, 8};

#define TN__TIF_MAX_IFDS 256
#define TN__TIF_SLACK 16 /* spare bytes after a chunk buffer (inflate copies 8 bytes at a time) */

typedef struct tn__tif_tag {
    int present;
    unsigned type;
    uint64_t count;
    size_t off; /* where the values start in the file */
} tn__tif_tag;

typedef struct tn__tif {
    const uint8_t *p;
    size_t n;
    const char *name;
    int le, big; /* little-endian; BigTIFF */
    tn__tif_tag tag[TN__TT_COUNT];
    /* layout of the chosen image */
    size_t w, h, spp, bps;          /* bps: bytes per sample */
    int fmt, comp, pred, tiled, planar;
    size_t cw, chh;                 /* chunk (strip or tile) width and height in pixels */
    size_t across, per_plane, nchunks;
    size_t row_samples, row_bytes, chunk_bytes; /* of one full chunk */
    uint64_t *offs, *cnts;
    float *out;
} tn__tif;

/* Unsigned integer of `bytes` bytes at off in file order (bounds checked by the caller). */
static uint64_t tn__tif_u(const tn__tif *t, size_t off, int bytes)
{
    uint64_t v = 0;
    int i;
    if (t->le)
        for (i = bytes - 1; i >= 0; i--) v = (v << 8) | t->p[off + (size_t)i];
    else
        for (i = 0; i < bytes; i++) v = (v << 8) | t->p[off + (size_t)i];
    return v;
}

/* Value i of a tag as an unsigned integer; 0 if the type is not an integer one or it is negative. */
static int tn__tif_int(const tn__tif *t, const tn__tif_tag *g, uint64_t i, uint64_t *v)
{
    size_t o = g->off;
    uint64_t u;
    if (i >= g->count) return 0;
    switch (g->type) {
    case 1: case 7: *v = t->p[o + i]; return 1;
    case 3: *v = tn__tif_u(t, o + 2 * i, 2); return 1;
    case 4: case 13: *v = tn__tif_u(t, o + 4 * i, 4); return 1;
    case 16: case 18: *v = tn__tif_u(t, o + 8 * i, 8); return 1;
    case 6: u = t->p[o + i]; if (u & 0x80u) return 0; *v = u; return 1;
    case 8: u = tn__tif_u(t, o + 2 * i, 2); if (u & 0x8000u) return 0; *v = u; return 1;
    case 9: u = tn__tif_u(t, o + 4 * i, 4); if (u & 0x80000000u) return 0; *v = u; return 1;
    case 17: u = tn__tif_u(t, o + 8 * i, 8); if (u >> 63) return 0; *v = u; return 1;
    default: return 0;
    }
}

/* Value i of a numeric tag as a double; 0 for ASCII / unknown types. */
static int tn__tif_num(const tn__tif *t, const tn__tif_tag *g, uint64_t i, double *v)
{
    size_t o = g->off;
    uint64_t u, d;
    double f;
    float ff;
    uint32_t u32;
    if (i >= g->count) return 0;
    switch (g->type) {
    case 6: *v = (double)(int8_t)t->p[o + i]; return 1;
    case 8: u = tn__tif_u(t, o + 2 * i, 2); *v = u >= 32768u ? (double)u - 65536.0 : (double)u; return 1;
    case 9: u = tn__tif_u(t, o + 4 * i, 4); *v = u >= 0x80000000u ? (double)u - 4294967296.0 : (double)u; return 1;
    case 17: u = tn__tif_u(t, o + 8 * i, 8); *v = (u >> 63) ? -(double)(~u + 1) : (double)u; return 1;
    case 5: case 10:
        u = tn__tif_u(t, o + 8 * i, 4);
        d = tn__tif_u(t, o + 8 * i + 4, 4);
        if (g->type == 10)
            *v = (u >= 0x80000000u ? (double)u - 4294967296.0 : (double)u) / (d >= 0x80000000u ? (double)d - 4294967296.0 : (double)d);
        else
            *v = (double)u / (double)d;
        return d != 0;
    case 11:
        u32 = (uint32_t)tn__tif_u(t, o + 4 * i, 4);
        memcpy(&ff, &u32, 4);
        *v = ff;
        return 1;
    case 12:
        u = tn__tif_u(t, o + 8 * i, 8);
        memcpy(&f, &u, 8);
        *v = f;
        return 1;
    default: break;
    }
    if (!tn__tif_int(t, g, i, &u)) return 0;
    *v = (double)u;
    return 1;
}

/* A single-valued integer tag, or def when absent. */
static tn_status tn__tif_scalar(const tn__tif *t, int k, uint64_t def, uint64_t *v)
{
    const tn__tif_tag *g = &t->tag[k];
    if (!g->present) { *v = def; return TN_OK; }
    if (g->count < 1 || !tn__tif_int(t, g, 0, v))
        return tn__fail(TN_ERR_CORRUPT, "%s: TIFF tag %u has no usable value", t->name, tn__tif_tag_ids[k]);
    return TN_OK;
}

/* Reads the IFD at off into t->tag (the tags terrainnet uses) and *next. */
static tn_status tn__tif_ifd(tn__tif *t, uint64_t off, uint64_t *next)
{
    size_t hdr = t->big ? 8 : 2, esz = t->big ? 20 : 12, inl = t->big ? 8 : 4, e;
    uint64_t cnt, i;
    int k;
    memset(t->tag, 0, sizeof t->tag);
    *next = 0;
    if (off < 8 || off > t->n || t->n - off < hdr)
        return tn__fail(TN_ERR_CORRUPT, "%s: TIFF directory offset %llu is outside the file (%zu bytes)", t->name,
                        (unsigned long long)off, t->n);
    cnt = tn__tif_u(t, (size_t)off, (int)hdr);
    if (cnt == 0) return tn__fail(TN_ERR_CORRUPT, "%s: empty TIFF directory", t->name);
    if (cnt > (t->n - off - hdr) / esz)
        return tn__fail(TN_ERR_CORRUPT, "%s: TIFF directory of %llu entries runs past the end of the file", t->name,
                        (unsigned long long)cnt);
    for (i = 0; i < cnt; i++) {
        unsigned id, type;
        uint64_t count, bytes;
        size_t tsz;
        e = (size_t)off + hdr + (size_t)i * esz;
        id = (unsigned)tn__tif_u(t, e, 2);
        type = (unsigned)tn__tif_u(t, e + 2, 2);
        count = tn__tif_u(t, e + 4, (int)inl);
        for (k = 0; k < TN__TT_COUNT && tn__tif_tag_ids[k] != id; k++) {}
        if (k == TN__TT_COUNT) continue; /* a tag terrainnet does not use */
        tsz = type < 19 ? tn__tif_type_size[type] : 0;
        if (!tsz) return tn__fail(TN_ERR_CORRUPT, "%s: TIFF tag %u has unknown field type %u", t->name, id, type);
        if (count > t->n / tsz)
            return tn__fail(TN_ERR_CORRUPT, "%s: TIFF tag %u claims %llu values, more than the file holds", t->name, id,
                            (unsigned long long)count);
        bytes = count * tsz;
        t->tag[k].present = 1;
        t->tag[k].type = type;
        t->tag[k].count = count;
        if (bytes <= inl) {
            t->tag[k].off = e + 4 + inl;
        } else {
            uint64_t at = tn__tif_u(t, e + 4 + inl, (int)inl);
            if (at > t->n || t->n - at < bytes)
                return tn__fail(TN_ERR_CORRUPT, "%s: TIFF tag %u: %llu bytes at offset %llu run past the end of the file (%zu bytes)",
                                t->name, id, (unsigned long long)bytes, (unsigned long long)at, t->n);
            t->tag[k].off = (size_t)at;
        }
    }
    e = (size_t)off + hdr + (size_t)cnt * esz;
    if (t->n - e >= inl) *next = tn__tif_u(t, e, (int)inl); /* a missing next pointer ends the chain */
    return TN_OK;
}

/* ---- chunk codecs: each writes at most cap bytes and reports how many in *len ---- */

TN__INTERNAL tn_status tn__tif_packbits(const char *name, const uint8_t *s, size_t n, uint8_t *out, size_t cap, size_t *len)
{
    size_t i = 0, o = 0, L;
    while (o < cap && i < n) {
        int c = s[i] >= 128 ? (int)s[i] - 256 : (int)s[i];
        i++;
        if (c >= 0) {
            L = (size_t)c + 1;
            if (L > n - i) return tn__fail(TN_ERR_CORRUPT, "%s: PackBits literal run past the end of its strip/tile", name);
            if (L > cap - o) L = cap - o;
            memcpy(out + o, s + i, L);
            i += (size_t)c + 1;
            o += L;
        } else if (c != -128) {
            L = (size_t)(1 - c);
            if (i >= n) return tn__fail(TN_ERR_CORRUPT, "%s: PackBits repeat run past the end of its strip/tile", name);
            if (L > cap - o) L = cap - o;
            memset(out + o, s[i++], L);
            o += L;
        }
    }
    *len = o;
    return TN_OK;
}

/* TIFF LZW (MSB-first codes of 9..12 bits, "early change"); tab holds 4096 entry starts and
   lens their lengths. Output beyond cap ends the decoding (as libtiff, which reads what it needs). */
TN__INTERNAL tn_status tn__tif_lzw(const char *name, const uint8_t *s, size_t n, uint8_t *out, size_t cap, size_t *len,
                             size_t *tab, uint16_t *lens)
{
    size_t o = 0, bit = 0, total = n * 8, prev_start = 0, L, src;
    unsigned width = 9, next = 258, prev_len = 0, code;
    int have_prev = 0;
    *len = 0;
    if (n >= 2 && s[0] == 0 && (s[1] & 1))
        return tn__fail(TN_ERR_FORMAT, "%s: old-style (pre-1991) TIFF LZW is not supported", name);
    while (o < cap && bit + width <= total) {
        size_t i = bit >> 3;
        uint32_t v = (uint32_t)s[i] << 16;
        if (i + 1 < n) v |= (uint32_t)s[i + 1] << 8;
        if (i + 2 < n) v |= s[i + 2];
        code = (unsigned)(v >> (24 - (bit & 7) - width)) & ((1u << width) - 1);
        bit += width;
        if (code == 256) { /* clear */
            width = 9;
            next = 258;
            have_prev = 0;
            continue;
        }
        if (code == 257) break; /* end of information */
        if (!have_prev) {
            if (code > 255) return tn__fail(TN_ERR_CORRUPT, "%s: LZW code %u right after a clear", name, code);
            out[o] = (uint8_t)code;
            prev_start = o++;
            prev_len = 1;
            have_prev = 1;
            continue;
        }
        if (code > next || (code == next && next >= 4096))
            return tn__fail(TN_ERR_CORRUPT, "%s: LZW code %u beyond the %u-entry table", name, code, next);
        if (code < 256) {
            out[o] = (uint8_t)code;
            L = 1;
        } else if (code < next) {
            src = tab[code];
            L = lens[code];
            if (L > cap - o) L = cap - o;
            memcpy(out + o, out + src, L);
        } else { /* code == next: the previous string plus its own first byte */
            L = (size_t)prev_len + 1;
            if (L > cap - o) L = cap - o;
            memcpy(out + o, out + prev_start, L < prev_len ? L : prev_len);
            if (L > prev_len) out[o + prev_len] = out[prev_start];
        }
        if (next < 4096) { /* the previous string plus this one's first byte lies contiguously */
            tab[next] = prev_start;
            lens[next] = (uint16_t)(prev_len + 1);
            next++;
        }
        width = next < 511 ? 9 : next < 1023 ? 10 : next < 2047 ? 11 : 12;
        prev_start = o;
        prev_len = (unsigned)L;
        o += L;
    }
    *len = o;
    return TN_OK;
}

/* Per-thread scratch for chunk decoding. */
typedef struct tn__tif_scratch {
    uint8_t *raw, *row;
    tn__inflate *z;
    size_t *lzw_tab;
    uint16_t *lzw_len;
} tn__tif_scratch;

static void tn__tif_scratch_free(tn__tif_scratch *s)
{
    TN_FREE(s->raw);
    TN_FREE(s->row);
    TN_FREE(s->z);
    TN_FREE(s->lzw_tab);
    TN_FREE(s->lzw_len);
    memset(s, 0, sizeof *s);
}

static tn_status tn__tif_scratch_make(const tn__tif *t, tn__tif_scratch *s)
{
    memset(s, 0, sizeof *s);
    s->raw = (uint8_t *)tn__alloc(t->chunk_bytes + TN__TIF_SLACK);
    s->row = (uint8_t *)tn__alloc(t->row_bytes);
    if (t->comp == 8 || t->comp == 32946) s->z = (tn__inflate *)tn__alloc(sizeof *s->z);
    if (t->comp == 5) {
        s->lzw_tab = (size_t *)tn__alloc(4096 * sizeof(size_t));
        s->lzw_len = (uint16_t *)tn__alloc(4096 * sizeof(uint16_t));
    }
    if (!s->raw || !s->row || ((t->comp == 8 || t->comp == 32946) && !s->z) || (t->comp == 5 && (!s->lzw_tab || !s->lzw_len))) {
        tn__tif_scratch_free(s);
        return tn__fail_context(TN_ERR_OUT_OF_MEMORY, t->name);
    }
    return TN_OK;
}

/* double -> float without the undefined behaviour of converting values beyond float */
static float tn__tif_d2f(double v)
{
    if (v > FLT_MAX) return HUGE_VALF;
    if (v < -FLT_MAX) return -HUGE_VALF;
    return (float)v;
}

/* count samples of bps bytes (file order, little-endian if le) -> floats at d, d + step, ... */
static void tn__tif_convert(const uint8_t *s, size_t count, size_t bps, int fmt, int le, float *d, size_t step)
{
    size_t i;
    if (bps == 1) {
        if (fmt == 2) for (i = 0; i < count; i++, d += step) *d = (float)(int8_t)s[i];
        else for (i = 0; i < count; i++, d += step) *d = (float)s[i];
    } else if (bps == 2) {
        for (i = 0; i < count; i++, d += step, s += 2) {
            unsigned u = le ? (unsigned)s[0] | ((unsigned)s[1] << 8) : ((unsigned)s[0] << 8) | s[1];
            *d = fmt == 2 ? (float)(u >= 32768u ? (int)u - 65536 : (int)u) : (float)u;
        }
    } else if (bps == 4) {
        for (i = 0; i < count; i++, d += step, s += 4) {
            uint32_t u = le ? (uint32_t)s[0] | ((uint32_t)s[1] << 8) | ((uint32_t)s[2] << 16) | ((uint32_t)s[3] << 24)
                            : (uint32_t)s[3] | ((uint32_t)s[2] << 8) | ((uint32_t)s[1] << 16) | ((uint32_t)s[0] << 24);
            if (fmt == 3) { float f; memcpy(&f, &u, 4); *d = f; }
            else if (fmt == 2) *d = (float)(u >= 0x80000000u ? (double)u - 4294967296.0 : (double)u);
            else *d = (float)u;
        }
    } else {
        for (i = 0; i < count; i++, d += step, s += 8) {
            uint64_t u = 0;
            int b;
            if (le) for (b = 7; b >= 0; b--) u = (u << 8) | s[b];
            else for (b = 0; b < 8; b++) u = (u << 8) | s[b];
            if (fmt == 3) { double f; memcpy(&f, &u, 8); *d = tn__tif_d2f(f); }
            else if (fmt == 2) *d = (u >> 63) ? -(float)(~u + 1) : (float)u;
            else *d = (float)u;
        }
    }
}

/* Undoes predictor 2 on one row of n samples in file order: each sample adds the one `stride`
   samples before it, in bps-byte integer arithmetic that wraps. */
static void tn__tif_unpredict_h(uint8_t *r, size_t n, size_t stride, size_t bps, int le)
{
    size_t i;
    int b;
    if (bps == 1) {
        for (i = stride; i < n; i++) r[i] = (uint8_t)(r[i] + r[i - stride]);
        return;
    }
    if (bps == 2) { /* the common int16 DEM: 16-bit sums without the byte loop */
        int hi = le ? 1 : 0, lo = 1 - hi;
        for (i = stride; i < n; i++) {
            uint8_t *c = r + 2 * i, *p = c - 2 * stride;
            unsigned v = ((unsigned)c[hi] << 8 | c[lo]) + ((unsigned)p[hi] << 8 | p[lo]);
            c[hi] = (uint8_t)(v >> 8);
            c[lo] = (uint8_t)v;
        }
        return;
    }
    for (i = stride; i < n; i++) {
        uint8_t *c = r + i * bps, *p = c - stride * bps;
        unsigned carry = 0;
        for (b = 0; b < (int)bps; b++) { /* byte-wise add from the least significant byte */
            int k = le ? b : (int)bps - 1 - b;
            unsigned sum = (unsigned)c[k] + p[k] + carry;
            c[k] = (uint8_t)sum;
            carry = sum >> 8;
        }
    }
}

/* Undoes predictor 3 on one row of n samples: byte differencing with stride `stride`, then byte
   planes (most significant first) back to big-endian samples in out. */
static void tn__tif_unpredict_fp(uint8_t *r, size_t n, size_t stride, size_t bps, uint8_t *out)
{
    size_t i, bytes = n * bps, b;
    for (i = stride; i < bytes; i++) r[i] = (uint8_t)(r[i] + r[i - stride]);
    for (b = 0; b < bps; b++) {
        const uint8_t *plane = r + b * n;
        for (i = 0; i < n; i++) out[i * bps + b] = plane[i];
    }
}

/* Decodes chunk k (strip or tile, with its plane) into t->out. */
static tn_status tn__tif_chunk(const tn__tif *t, size_t k, tn__tif_scratch *sc)
{
    size_t plane = k / t->per_plane, idx = k % t->per_plane, x0, y0, vw, vh, need, got = 0, r;
    size_t S = t->planar == 2 ? 1 : t->spp;
    const uint8_t *src = t->p + (size_t)t->offs[k];
    size_t srcn = (size_t)t->cnts[k];
    tn_status st = TN_OK;
    if (t->tiled) {
        x0 = (idx % t->across) * t->cw;
        y0 = (idx / t->across) * t->chh;
        vw = t->w - x0 < t->cw ? t->w - x0 : t->cw;
        vh = t->h - y0 < t->chh ? t->h - y0 : t->chh;
        need = t->chunk_bytes; /* tiles are always stored whole */
    } else {
        x0 = 0;
        y0 = idx * t->chh;
        vw = t->w;
        vh = t->h - y0 < t->chh ? t->h - y0 : t->chh;
        need = vh * t->row_bytes;
    }
    switch (t->comp) {
    case 1:
        if (srcn < need)
            return tn__fail(TN_ERR_CORRUPT, "%s: %s %zu holds %zu bytes, %zu needed", t->name, t->tiled ? "tile" : "strip", k, srcn, need);
        memcpy(sc->raw, src, need);
        got = need;
        break;
    case 32773: st = tn__tif_packbits(t->name, src, srcn, sc->raw, t->chunk_bytes, &got); break;
    case 5: st = tn__tif_lzw(t->name, src, srcn, sc->raw, t->chunk_bytes, &got, sc->lzw_tab, sc->lzw_len); break;
    default: {
        char what[96];
        snprintf(what, sizeof what, "%s: %s %zu", t->name, t->tiled ? "tile" : "strip", k);
        sc->z->what = what;
        sc->z->out = sc->raw;
        sc->z->len = 0;
        sc->z->cap = sc->z->max = t->chunk_bytes;
        st = tn__z_inflate_run(sc->z, src, srcn);
        sc->raw = sc->z->out; /* a same-size realloc inside inflate may have moved it */
        if (st == TN_ERR_TOO_LARGE)
            st = tn__fail(TN_ERR_CORRUPT, "%s: %s %zu inflates beyond its %zu bytes", t->name, t->tiled ? "tile" : "strip", k,
                          t->chunk_bytes);
        got = sc->z->len;
        break;
    }
    }
    if (st) return st;
    if (got < need)
        return tn__fail(TN_ERR_CORRUPT, "%s: %s %zu decodes to %zu bytes, %zu needed", t->name, t->tiled ? "tile" : "strip", k, got, need);
    for (r = 0; r < vh; r++) {
        uint8_t *row = sc->raw + r * t->row_bytes;
        int le = t->le;
        float *dst = t->out + ((y0 + r) * t->w + x0) * t->spp + plane;
        if (t->pred == 2) tn__tif_unpredict_h(row, t->row_samples, S, t->bps, le);
        if (t->pred == 3) {
            tn__tif_unpredict_fp(row, t->row_samples, S, t->bps, sc->row);
            row = sc->row;
            le = 0;
        }
        if (t->planar == 2) tn__tif_convert(row, vw, t->bps, t->fmt, le, dst, t->spp);
        else tn__tif_convert(row, vw * t->spp, t->bps, t->fmt, le, dst, 1);
    }
    return TN_OK;
}

typedef struct tn__tif_job {
    const tn__tif *t;
    size_t *bad;     /* per thread: first failing chunk, or nchunks */
} tn__tif_job;

static void tn__tif_task(void *ctx, int ith, int nth)
{
    tn__tif_job *j = (tn__tif_job *)ctx;
    const tn__tif *t = j->t;
    size_t b = (size_t)((unsigned long long)t->nchunks * (unsigned)ith / (unsigned)nth);
    size_t e = (size_t)((unsigned long long)t->nchunks * ((unsigned)ith + 1) / (unsigned)nth), k;
    tn__tif_scratch sc;
    j->bad[ith] = t->nchunks;
    if (b >= e) return;
    if (tn__tif_scratch_make(t, &sc)) { j->bad[ith] = b; return; }
    for (k = b; k < e; k++)
        if (tn__tif_chunk(t, k, &sc)) { j->bad[ith] = k; break; }
    tn__tif_scratch_free(&sc);
}

/* Value of a short-valued GeoKey (location 0), or 0 if absent. */
static int tn__tif_geokey(const tn__tif *t, unsigned id, unsigned *v)
{
    const tn__tif_tag *g = &t->tag[TN__TT_GEOKEYS];
    uint64_t nk, i, e[4];
    int j;
    if (!g->present || g->type != 3 || g->count < 4 || !tn__tif_int(t, g, 3, &nk)) return 0;
    for (i = 0; i < nk && 4 + 4 * i + 3 < g->count; i++) {
        for (j = 0; j < 4; j++) tn__tif_int(t, g, 4 + 4 * i + (uint64_t)j, &e[j]);
        if (e[0] != id) continue;
        if (e[1] != 0 || e[2] != 1) return 0;
        *v = (unsigned)e[3];
        return 1;
    }
    return 0;
}

/* Value of a double-valued GeoKey (location GeoDoubleParams). */
static int tn__tif_geokey_double(const tn__tif *t, unsigned id, double *v)
{
    const tn__tif_tag *g = &t->tag[TN__TT_GEOKEYS];
    uint64_t nk, i, e[4];
    int j;
    if (!g->present || g->type != 3 || g->count < 4 || !tn__tif_int(t, g, 3, &nk) || !t->tag[TN__TT_GEODOUBLES].present) return 0;
    for (i = 0; i < nk && 4 + 4 * i + 3 < g->count; i++) {
        for (j = 0; j < 4; j++) tn__tif_int(t, g, 4 + 4 * i + (uint64_t)j, &e[j]);
        if (e[0] != id) continue;
        return e[1] == 34736 && e[2] >= 1 && tn__tif_num(t, &t->tag[TN__TT_GEODOUBLES], e[3], v) && v[0] == v[0];
    }
    return 0;
}

/* Metres per degree along a meridian (*mlat) and a parallel (*mlon) at latitude lat (degrees)
   on the ellipsoid with semi-major axis a and flattening f. */
static void tn__geo_metres_per_degree(double lat, double a, double f, double *mlat, double *mlon)
{
    double e2 = f * (2.0 - f), s = sin(lat * 3.141592653589793 / 180.0), w = 1.0 - e2 * s * s;
    double rad = 3.141592653589793 / 180.0;
    *mlat = rad * a * (1.0 - e2) / (w * sqrt(w));
    *mlon = rad * a * cos(lat * rad) / sqrt(w);
}

/* Pixel spacing in metres from the transform and the CRS's units (see tn_georef). */
static void tn__georef_spacing(tn_georef *g, const tn__tif *t, size_t w, size_t h)
{
    const double *gt = g->transform;
    unsigned u = 0;
    double unit = 1.0;
    g->dx = g->dy = 0.0;
    if (!g->has_transform) return;
    if (g->model_type == 1) {
        if (tn__tif_geokey(t, 3076, &u)) { /* ProjLinearUnitsGeoKey: EPSG unit codes */
            if (u == 9001) unit = 1.0;
            else if (u == 9002) unit = 0.3048;
            else if (u == 9003) unit = 1200.0 / 3937.0;
            else if (u == 9036) unit = 1000.0;
            else if (u == 9030) unit = 1852.0;
            else if (u == 9096) unit = 0.9144;
            else if (u == 32767 && tn__tif_geokey_double(t, 3077, &unit) && unit > 0) {}
            else return; /* a unit terrainnet does not know */
        }
        g->dx = unit * sqrt(gt[1] * gt[1] + gt[4] * gt[4]);
        g->dy = unit * sqrt(gt[2] * gt[2] + gt[5] * gt[5]);
    } else if (g->model_type == 2) {
        double a = 6378137.0, f = 1.0 / 298.257223563, v, lat, mlat, mlon;
        if (tn__tif_geokey(t, 2054, &u)) { /* GeogAngularUnitsGeoKey */
            if (u == 9102 || u == 9122) unit = 1.0;
            else if (u == 9101) unit = 180.0 / 3.141592653589793;
            else if (u == 9105) unit = 0.9;
            else if (u == 32767 && tn__tif_geokey_double(t, 2055, &v) && v > 0) unit = v * 180.0 / 3.141592653589793;
            else return;
        }
        if (tn__tif_geokey_double(t, 2057, &v) && v > 1e6 && v < 1e8) {
            double b;
            a = v;
            if (tn__tif_geokey_double(t, 2059, &v) && v > 1.0) f = 1.0 / v;
            else if (tn__tif_geokey_double(t, 2058, &b) && b > 0 && b <= a) f = (a - b) / a;
        }
        lat = unit * (gt[3] + gt[4] * 0.5 * (double)w + gt[5] * 0.5 * (double)h);
        if (!(lat >= -90.0 && lat <= 90.0)) return;
        tn__geo_metres_per_degree(lat, a, f, &mlat, &mlon);
        g->dx = unit * sqrt(gt[1] * gt[1] * mlon * mlon + gt[4] * gt[4] * mlat * mlat);
        g->dy = unit * sqrt(gt[2] * gt[2] * mlon * mlon + gt[5] * gt[5] * mlat * mlat);
    }
    if (!(g->dx <= DBL_MAX && g->dy <= DBL_MAX)) g->dx = g->dy = 0.0;
}

/* Is keys[0..nkeys) a well-formed GeoKey directory whose parameters lie in ndoubles / nascii? */
static int tn__georef_keys_ok(const uint16_t *keys, int nkeys, int ndoubles, int nascii)
{
    int i, nk;
    if (nkeys == 0) return 1;
    if (nkeys < 4 || keys[0] != 1) return 0;
    nk = keys[3];
    if (4 + 4 * nk > nkeys) return 0;
    for (i = 0; i < nk; i++) {
        const uint16_t *e = keys + 4 + 4 * i;
        if (e[1] == 0 && e[2] != 1) return 0;
        if (e[1] == 34736 && (int)e[3] + (int)e[2] > ndoubles) return 0;
        if (e[1] == 34737 && (int)e[3] + (int)e[2] > nascii) return 0;
        if (e[1] != 0 && e[1] != 34736 && e[1] != 34737) return 0;
    }
    return 1;
}

/* Fills g from the geo tags of the chosen image (all optional; malformed ones are ignored). */
static void tn__tif_georef(const tn__tif *t, tn_georef *g)
{
    const tn__tif_tag *sc = &t->tag[TN__TT_SCALE], *tp = &t->tag[TN__TT_TIEPOINT], *tm = &t->tag[TN__TT_TRANSFORM];
    double s[3], tie[6], m[16], *gt = g->transform;
    unsigned v;
    uint64_t i, u;
    int ok = 1;
    memset(g, 0, sizeof *g);
    if (tn__tif_geokey(t, 1024, &v)) g->model_type = (int)v;
    if (tn__tif_geokey(t, 1025, &v)) g->pixel_is_point = v == 2;
    if (sc->present && sc->count >= 2 && tp->present && tp->count >= 6) {
        for (i = 0; i < 2; i++) ok &= tn__tif_num(t, sc, i, &s[i]);
        for (i = 0; i < 6; i++) ok &= tn__tif_num(t, tp, i, &tie[i]);
        if (ok && s[0] != 0.0 && s[1] != 0.0) {
            gt[1] = s[0];
            gt[5] = -fabs(s[1]);
            gt[2] = gt[4] = 0.0;
            gt[0] = tie[3] - tie[0] * gt[1];
            gt[3] = tie[4] - tie[1] * gt[5];
            g->has_transform = 1;
        }
    } else if (tm->present && tm->count >= 16) {
        for (i = 0; i < 16; i++) ok &= tn__tif_num(t, tm, i, &m[i]);
        if (ok) {
            gt[0] = m[3]; gt[1] = m[0]; gt[2] = m[1];
            gt[3] = m[7]; gt[4] = m[4]; gt[5] = m[5];
            g->has_transform = gt[1] * gt[5] - gt[2] * gt[4] != 0.0;
        }
    }
    if (g->has_transform && g->pixel_is_point) {
        gt[0] -= 0.5 * (gt[1] + gt[2]);
        gt[3] -= 0.5 * (gt[4] + gt[5]);
    }
    for (i = 0; i < 6 && g->has_transform; i++)
        if (!(fabs(gt[i]) <= DBL_MAX)) g->has_transform = 0;
    if (!g->has_transform) memset(gt, 0, 6 * sizeof *gt);
    tn__georef_spacing(g, t, t->w, t->h);
    /* keep the directory verbatim when it fits and is well formed */
    {
        const tn__tif_tag *k = &t->tag[TN__TT_GEOKEYS], *d = &t->tag[TN__TT_GEODOUBLES], *a = &t->tag[TN__TT_GEOASCII];
        if (!k->present || k->type != 3 || k->count > TN_GEOREF_MAX_KEYS) return;
        if (d->present && (d->type != 12 || d->count > TN_GEOREF_MAX_DOUBLES)) return;
        if (a->present && (a->type != 2 || a->count >= TN_GEOREF_MAX_ASCII)) return;
        for (i = 0; i < k->count; i++) {
            tn__tif_int(t, k, i, &u);
            g->keys[i] = (uint16_t)u;
        }
        for (i = 0; d->present && i < d->count; i++) tn__tif_num(t, d, i, &g->doubles[i]);
        if (a->present) memcpy(g->ascii, t->p + a->off, (size_t)a->count);
        g->nkeys = (int)k->count;
        g->ndoubles = d->present ? (int)d->count : 0;
        g->nascii = a->present ? (int)a->count : 0;
        g->ascii[g->nascii] = 0;
        if (!tn__georef_keys_ok(g->keys, g->nkeys, g->ndoubles, g->nascii)) g->nkeys = g->ndoubles = g->nascii = 0;
    }
}

/* Byte ranges of strips or tiles that overlap or repeat let a few KB of deflate decode again and
   again into gigabytes; every chunk must own its bytes. The
   (offset, count) pairs are sorted by offset and each must end before the next starts. */
static tn_status tn__tif_disjoint(const tn__tif *t, const char *what)
{
    uint64_t *r;
    size_t k;
    tn_status st = TN_OK;
    if (t->nchunks < 2) return TN_OK;
    if (!(r = (uint64_t *)tn__alloc(t->nchunks * 2 * sizeof(uint64_t)))) return tn__fail_context(TN_ERR_OUT_OF_MEMORY, t->name);
    for (k = 0; k < t->nchunks; k++) {
        r[2 * k] = t->offs[k];
        r[2 * k + 1] = t->cnts[k];
    }
    qsort(r, t->nchunks, 2 * sizeof(uint64_t), tn__z_cmp_u64); /* compares the offsets */
    for (k = 0; k + 1 < t->nchunks && !st; k++)
        if (r[2 * k] + r[2 * k + 1] > r[2 * k + 2])
            st = tn__fail(TN_ERR_CORRUPT, "%s: TIFF %ss overlap or share bytes (%llu bytes at offset %llu reach into the %s at %llu)", t->name,
                          what, (unsigned long long)r[2 * k + 1], (unsigned long long)r[2 * k], what, (unsigned long long)r[2 * k + 2]);
    TN_FREE(r);
    return st;
}

/* Checks the chosen image's tags and fills the layout fields of t. */
static tn_status tn__tif_layout(tn__tif *t)
{
    uint64_t w, h, spp, comp, pred, planar, fill, photo, tw = 0, th = 0, rps;
    uint64_t bits = 0, fmt = 0, i;
    size_t bytes = 0, ndown, S;
    tn_status st;
    const tn__tif_tag *bt = &t->tag[TN__TT_BITS], *ft = &t->tag[TN__TT_SAMPLE_FORMAT];
    if (!t->tag[TN__TT_WIDTH].present || !t->tag[TN__TT_HEIGHT].present)
        return tn__fail(TN_ERR_CORRUPT, "%s: TIFF image without width or height", t->name);
    if ((st = tn__tif_scalar(t, TN__TT_WIDTH, 0, &w)) || (st = tn__tif_scalar(t, TN__TT_HEIGHT, 0, &h)) ||
        (st = tn__tif_scalar(t, TN__TT_SPP, 1, &spp)) || (st = tn__tif_scalar(t, TN__TT_COMPRESSION, 1, &comp)) ||
        (st = tn__tif_scalar(t, TN__TT_PREDICTOR, 1, &pred)) || (st = tn__tif_scalar(t, TN__TT_PLANAR, 1, &planar)) ||
        (st = tn__tif_scalar(t, TN__TT_FILLORDER, 1, &fill)) || (st = tn__tif_scalar(t, TN__TT_PHOTOMETRIC, 1, &photo)))
        return st;
    if (w == 0 || h == 0) return tn__fail(TN_ERR_CORRUPT, "%s: TIFF image of %llu x %llu pixels", t->name, (unsigned long long)w, (unsigned long long)h);
    if (w > INT_MAX || h > INT_MAX) return tn__fail(TN_ERR_TOO_LARGE, "%s: TIFF image of %llu x %llu pixels is too large", t->name,
                                                    (unsigned long long)w, (unsigned long long)h);
    if (spp == 0 || spp > 64) return tn__fail(TN_ERR_FORMAT, "%s: %llu samples per pixel (1..64 are supported)", t->name, (unsigned long long)spp);
    for (i = 0; i < spp; i++) { /* one value per sample, or a single value for all */
        uint64_t b = 0, f = 1;
        if (bt->present && !tn__tif_int(t, bt, bt->count == 1 ? 0 : i, &b))
            return tn__fail(TN_ERR_CORRUPT, "%s: TIFF BitsPerSample has %llu values for %llu samples", t->name,
                            (unsigned long long)bt->count, (unsigned long long)spp);
        if (!bt->present) b = 1;
        if (ft->present && !tn__tif_int(t, ft, ft->count == 1 ? 0 : i, &f))
            return tn__fail(TN_ERR_CORRUPT, "%s: TIFF SampleFormat has %llu values for %llu samples", t->name,
                            (unsigned long long)ft->count, (unsigned long long)spp);
        if (f == 4) f = 1; /* "undefined" data: read as unsigned */
        if (i && (b != bits || f != fmt))
            return tn__fail(TN_ERR_FORMAT, "%s: TIFF samples of different types are not supported", t->name);
        bits = b;
        fmt = f;
    }
    if (fmt < 1 || fmt > 3) return tn__fail(TN_ERR_FORMAT, "%s: TIFF sample format %llu is not supported (integers or floats)", t->name, (unsigned long long)fmt);
    if (!(bits == 8 || bits == 16 || bits == 32 || bits == 64) || (fmt == 3 && bits < 32))
        return tn__fail(TN_ERR_FORMAT, "%s: %llu-bit %s TIFF samples are not supported (8/16/32/64-bit integers, 32/64-bit floats)",
                        t->name, (unsigned long long)bits, fmt == 3 ? "float" : "integer");
    if (comp != 1 && comp != 5 && comp != 8 && comp != 32946 && comp != 32773)
        return tn__fail(TN_ERR_FORMAT, "%s: TIFF compression %llu%s is not supported (none, PackBits, LZW, Deflate); "
                        "re-save with gdal_translate -co COMPRESS=DEFLATE", t->name, (unsigned long long)comp,
                        comp == 7 ? " (JPEG)" : comp == 50000 ? " (ZSTD)" : comp == 34887 ? " (LERC)" : comp == 34925 ? " (LZMA)" : "");
    if (pred != 1 && pred != 2 && pred != 3) return tn__fail(TN_ERR_FORMAT, "%s: TIFF predictor %llu is not supported", t->name, (unsigned long long)pred);
    if (pred == 3 && fmt != 3) return tn__fail(TN_ERR_CORRUPT, "%s: floating-point predictor on integer samples", t->name);
    if (planar != 1 && planar != 2) return tn__fail(TN_ERR_CORRUPT, "%s: TIFF planar configuration %llu", t->name, (unsigned long long)planar);
    if (fill != 1) return tn__fail(TN_ERR_FORMAT, "%s: TIFF fill order %llu (bits reversed) is not supported", t->name, (unsigned long long)fill);
    if (photo == 6) return tn__fail(TN_ERR_FORMAT, "%s: YCbCr TIFF is not supported", t->name);
    t->w = (size_t)w;
    t->h = (size_t)h;
    t->spp = (size_t)spp;
    t->bps = (size_t)bits / 8;
    t->fmt = (int)fmt;
    t->comp = (int)comp;
    t->pred = (int)pred;
    t->planar = spp == 1 ? 1 : (int)planar;
    if ((st = tn__size4(t->w, t->h, t->spp, sizeof(float), &bytes))) return tn__fail_context(st, t->name);
    t->tiled = t->tag[TN__TT_TILE_W].present || t->tag[TN__TT_TILE_OFFSETS].present;
    if (t->tiled) {
        if ((st = tn__tif_scalar(t, TN__TT_TILE_W, 0, &tw)) || (st = tn__tif_scalar(t, TN__TT_TILE_H, 0, &th))) return st;
        if (tw == 0 || th == 0 || tw > INT_MAX || th > INT_MAX)
            return tn__fail(TN_ERR_CORRUPT, "%s: TIFF tile size %llu x %llu", t->name, (unsigned long long)tw, (unsigned long long)th);
        t->cw = (size_t)tw;
        t->chh = (size_t)th;
        t->across = (t->w + t->cw - 1) / t->cw;
        ndown = (t->h + t->chh - 1) / t->chh;
    } else {
        if ((st = tn__tif_scalar(t, TN__TT_ROWS_PER_STRIP, 0xffffffffu, &rps))) return st;
        if (rps == 0) return tn__fail(TN_ERR_CORRUPT, "%s: TIFF RowsPerStrip is 0", t->name);
        t->cw = t->w;
        t->chh = rps < h ? (size_t)rps : t->h;
        t->across = 1;
        ndown = (t->h + t->chh - 1) / t->chh;
    }
    S = t->planar == 2 ? 1 : t->spp;
    if ((st = tn__size4(t->cw, S, t->bps, 1, &t->row_bytes)) || (st = tn__size4(t->row_bytes, t->chh, 1, 1, &t->chunk_bytes)))
        return tn__fail_context(st, t->name);
    t->row_samples = t->cw * S;
    if (!tn__mul_size(t->across, ndown, &t->per_plane) || !tn__mul_size(t->per_plane, t->planar == 2 ? t->spp : 1, &t->nchunks))
        return tn__fail(TN_ERR_TOO_LARGE, "%s: too many TIFF strips/tiles", t->name);
    {
        const tn__tif_tag *ot = &t->tag[t->tiled ? TN__TT_TILE_OFFSETS : TN__TT_STRIP_OFFSETS];
        const tn__tif_tag *ct = &t->tag[t->tiled ? TN__TT_TILE_BYTES : TN__TT_STRIP_BYTES];
        const char *what = t->tiled ? "tile" : "strip";
        size_t k;
        if (!ot->present || !ct->present)
            return tn__fail(TN_ERR_CORRUPT, "%s: TIFF without %s offsets or byte counts", t->name, what);
        if (ot->count < t->nchunks || ct->count < t->nchunks)
            return tn__fail(TN_ERR_CORRUPT, "%s: TIFF lists %llu %s offsets and %llu byte counts for %zu %ss", t->name,
                            (unsigned long long)ot->count, what, (unsigned long long)ct->count, t->nchunks, what);
        t->offs = (uint64_t *)tn__alloc(t->nchunks * sizeof(uint64_t));
        t->cnts = (uint64_t *)tn__alloc(t->nchunks * sizeof(uint64_t));
        if (!t->offs || !t->cnts) return tn__fail_context(TN_ERR_OUT_OF_MEMORY, t->name);
        for (k = 0; k < t->nchunks; k++) {
            uint64_t o, c, ratio = comp == 8 || comp == 32946 ? 1032 : comp == 5 ? 4096 : comp == 32773 ? 64 : 1;
            size_t rows = t->tiled ? t->chh : (t->h - (k % t->per_plane) * t->chh < t->chh ? t->h - (k % t->per_plane) * t->chh : t->chh);
            if (!tn__tif_int(t, ot, k, &o) || !tn__tif_int(t, ct, k, &c))
                return tn__fail(TN_ERR_CORRUPT, "%s: bad TIFF %s offset or byte count %zu", t->name, what, k);
            if (c == 0)
                return tn__fail(TN_ERR_CORRUPT, "%s: TIFF %s %zu is empty (sparse files are not supported)", t->name, what, k);
            if (o > t->n || t->n - o < c)
                return tn__fail(TN_ERR_CORRUPT, "%s: TIFF %s %zu (%llu bytes at offset %llu) runs past the end of the file (%zu bytes)",
                                t->name, what, k, (unsigned long long)c, (unsigned long long)o, t->n);
            if ((double)rows * (double)t->row_bytes > (double)c * (double)ratio + 64.0)
                return tn__fail(TN_ERR_CORRUPT, "%s: TIFF %s %zu: %llu bytes cannot hold %zu bytes of pixels", t->name, what, k,
                                (unsigned long long)c, rows * t->row_bytes);
            t->offs[k] = o;
            t->cnts[k] = c;
        }
        if ((st = tn__tif_disjoint(t, what))) return st;
    }
    return TN_OK;
}

/* Fills the voids (mask 1) of channel c of an interleaved image, one channel at a time. */
static tn_status tn__tif_fill(tn_image *img, uint8_t *mask, const char *name, size_t *filled)
{
    size_t n = (size_t)img->width * (size_t)img->height, ch = (size_t)img->channels, c, i, f;
    float *plane;
    uint8_t *m;
    tn_status st = TN_OK;
    *filled = 0;
    if (ch == 1) return tn__io_fill_voids(img->data, mask, (size_t)img->width, (size_t)img->height, name, filled);
    plane = (float *)tn__alloc(n * sizeof(float));
    m = (uint8_t *)tn__alloc(n);
    if (!plane || !m) st = tn__fail_context(TN_ERR_OUT_OF_MEMORY, name);
    for (c = 0; c < ch && !st; c++) {
        size_t nv = 0;
        for (i = 0; i < n; i++) {
            plane[i] = img->data[i * ch + c];
            m[i] = mask[i * ch + c];
            nv += m[i];
        }
        if (!nv) continue;
        st = tn__io_fill_voids(plane, m, (size_t)img->width, (size_t)img->height, name, &f);
        *filled += f;
        for (i = 0; i < n && !st; i++) img->data[i * ch + c] = plane[i];
    }
    TN_FREE(plane);
    TN_FREE(m);
    return st;
}

static tn_status tn__tif_decode(const uint8_t *p, size_t n, const char *name, tn_image *img, tn_image_info *info)
{
    tn__tif t;
    uint64_t off, visited[TN__TIF_MAX_IFDS], next = 0, sub, photo = 1;
    size_t nvis = 0, k, count, nvoid = 0, nth, bad;
    tn_status st;
    tn__tif_job job;
    float nodata = 0.0f, scale = 0.0f;
    int has_nodata = 0;
    double nd = 0.0;
    memset(&t, 0, sizeof t);
    t.p = p;
    t.n = n;
    t.name = name;
    if (n < 8 || !((p[0] == 'I' && p[1] == 'I') || (p[0] == 'M' && p[1] == 'M')))
        return tn__fail(TN_ERR_FORMAT, "%s: not a TIFF file", name);
    t.le = p[0] == 'I';
    off = tn__tif_u(&t, 2, 2);
    if (off == 43) {
        if (n < 16 || tn__tif_u(&t, 4, 2) != 8 || tn__tif_u(&t, 6, 2) != 0)
            return tn__fail(TN_ERR_CORRUPT, "%s: bad BigTIFF header", name);
        t.big = 1;
        off = tn__tif_u(&t, 8, 8);
    } else if (off == 42) {
        off = tn__tif_u(&t, 4, 4);
    } else {
        return tn__fail(TN_ERR_FORMAT, "%s: not a TIFF file (version %llu)", name, (unsigned long long)off);
    }
    for (;;) { /* the first image that is neither reduced resolution (bit 0) nor a mask (bit 2) */
        for (k = 0; k < nvis; k++)
            if (visited[k] == off) return tn__fail(TN_ERR_CORRUPT, "%s: the TIFF directory chain loops", name);
        if (nvis == TN__TIF_MAX_IFDS)
            return tn__fail(TN_ERR_FORMAT, "%s: no full-resolution image in the first %d TIFF directories", name, TN__TIF_MAX_IFDS);
        visited[nvis++] = off;
        if ((st = tn__tif_ifd(&t, off, &next))) return st;
        if ((st = tn__tif_scalar(&t, TN__TT_SUBFILE, 0, &sub))) return st;
        if (!(sub & 5)) break;
        if (next == 0) return tn__fail(TN_ERR_FORMAT, "%s: the TIFF holds only overviews or masks", name);
        off = next;
    }
    st = tn__tif_layout(&t);
    if (!st && (st = tn_image_create(img, (int)t.w, (int)t.h, (int)t.spp)) != TN_OK) st = tn__fail_context(st, name);
    if (st) {
        TN_FREE(t.offs);
        TN_FREE(t.cnts);
        return st;
    }
    t.out = img->data;
    nth = (size_t)tn_get_threads();
    if (nth < 1) nth = 1;
    job.t = &t;
    job.bad = (size_t *)tn__alloc(nth * sizeof(size_t));
    if (!job.bad) st = tn__fail_context(TN_ERR_OUT_OF_MEMORY, name);
    if (!st) {
        for (k = 0; k < nth; k++) job.bad[k] = t.nchunks; /* a pool short of threads leaves some unset */
        if (t.nchunks < 2 || (double)t.w * (double)t.h * (double)t.spp < 65536.0) {
            tn__tif_task(&job, 0, 1); /* small images are not worth waking the pool */
            nth = 1;
        } else {
            tn_parallel_run(tn__tif_task, &job);
        }
        for (bad = t.nchunks, k = 0; k < nth; k++)
            if (job.bad[k] < bad) bad = job.bad[k];
        if (bad < t.nchunks) { /* again on this thread, for a deterministic message */
            tn__tif_scratch sc;
            st = tn__tif_scratch_make(&t, &sc);
            if (!st) st = tn__tif_chunk(&t, bad, &sc);
            tn__tif_scratch_free(&sc);
            if (!st) st = tn__fail(TN_ERR_OUT_OF_MEMORY, "%s: out of memory decoding TIFF chunk %zu", name, bad);
        }
    }
    TN_FREE(job.bad);
    TN_FREE(t.offs);
    TN_FREE(t.cnts);
    if (st) { tn_image_free(img); return st; }
    /* GDAL_NODATA: ASCII text of the value */
    if (t.tag[TN__TT_NODATA].present && t.tag[TN__TT_NODATA].type == 2) {
        const char *s = (const char *)p + t.tag[TN__TT_NODATA].off;
        size_t len = (size_t)t.tag[TN__TT_NODATA].count, b = 0;
        while (len && (s[len - 1] == 0 || tn__io_space((unsigned char)s[len - 1]))) len--;
        while (b < len && tn__io_space((unsigned char)s[b])) b++;
        if (tn__io_number(s + b, len - b, &nd)) {
            has_nodata = 1;
            nodata = tn__tif_d2f(nd);
        }
    }
    tn__tif_scalar(&t, TN__TT_PHOTOMETRIC, 1, &photo);
    if (t.fmt == 1 && (t.bps == 1 || (photo == 2 && t.bps <= 2))) scale = t.bps == 1 ? 1.0f / 255.0f : 1.0f / 65535.0f;
    count = t.w * t.h * t.spp;
    for (k = 0; k < count; k++) {
        float v = img->data[k];
        nvoid += !tn__io_finite(v) || (has_nodata && v == nodata);
    }
    if (nvoid) {
        uint8_t *mask = (uint8_t *)tn__calloc(count);
        if (!mask) { tn_image_free(img); return tn__fail_context(TN_ERR_OUT_OF_MEMORY, name); }
        for (k = 0; k < count; k++) {
            float v = img->data[k];
            if (!tn__io_finite(v) || (has_nodata && v == nodata)) { mask[k] = 1; img->data[k] = 0.0f; }
        }
        if (scale != 0.0f) for (k = 0; k < count; k++) img->data[k] *= scale;
        st = tn__tif_fill(img, mask, name, &info->voids_filled);
        TN_FREE(mask);
        if (st) { tn_image_free(img); return st; }
    } else if (scale != 0.0f) {
        for (k = 0; k < count; k++) img->data[k] *= scale;
    }
    info->bit_depth = (int)t.bps * 8;
    info->file_channels = (int)t.spp;
    info->has_nodata = has_nodata;
    info->nodata = has_nodata ? nd : 0.0;
    tn__tif_georef(&t, &info->georef);
    {
        const double *gt = info->georef.transform;
        if (info->georef.has_transform && gt[2] == 0.0 && gt[4] == 0.0 && gt[1] == -gt[5] && gt[1] > 0) {
            info->cellsize = gt[1];
            info->x_origin = gt[0];
            info->y_origin = gt[3] + gt[5] * (double)t.h;
        }
    }
    return TN_OK;
}

/* ---- TIFF writer ---- */

TN__INTERNAL double tn__tif_classic_max = TN__TIF_CLASSIC_MAX; /* lowered by tests to reach BigTIFF */

typedef struct tn__tif_enc {
    const tn_image *img;
    int bits, level;
    double lo, scale; /* uint8: code = (v - lo) * scale */
    size_t rps, nstrips, row_bytes;
    uint8_t **z;
    size_t *zn;
    tn_status *st;
} tn__tif_enc;

/* Encodes strips [b, e): samples little-endian, forward predictor, zlib. */
static void tn__tif_enc_range(void *ctx, size_t b, size_t e)
{
    tn__tif_enc *j = (tn__tif_enc *)ctx;
    const tn_image *img = j->img;
    size_t ch = (size_t)img->channels, w = (size_t)img->width, s, r, i;
    size_t n = w * ch; /* samples per row */
    uint8_t *raw = (uint8_t *)tn__alloc(j->row_bytes * j->rps), *tmp = (uint8_t *)tn__alloc(j->row_bytes);
    for (s = b; s < e; s++) {
        size_t y0 = s * j->rps, rows = (size_t)img->height - y0 < j->rps ? (size_t)img->height - y0 : j->rps;
        if (!raw || !tmp) { j->st[s] = TN_ERR_OUT_OF_MEMORY; continue; }
        for (r = 0; r < rows; r++) {
            const float *src = img->data + (y0 + r) * n;
            uint8_t *row = raw + r * j->row_bytes;
            if (j->bits == 32) { /* predictor 3: byte planes, most significant first, then differences */
                for (i = 0; i < n; i++) {
                    uint32_t u;
                    memcpy(&u, &src[i], 4);
                    tmp[i] = (uint8_t)(u >> 24);
                    tmp[n + i] = (uint8_t)(u >> 16);
                    tmp[2 * n + i] = (uint8_t)(u >> 8);
                    tmp[3 * n + i] = (uint8_t)u;
                }
                for (i = 0; i < ch; i++) row[i] = tmp[i];
                for (i = ch; i < 4 * n; i++) row[i] = (uint8_t)(tmp[i] - tmp[i - ch]);
            } else if (j->bits == 16) { /* predictor 2 on int16 */
                unsigned prev[64];
                for (i = 0; i < n; i++) {
                    double v = floor((double)src[i] + 0.5);
                    unsigned u = (unsigned)((int)v & 0xffff), d = i < ch ? u : (u - prev[i % ch]) & 0xffffu;
                    prev[i % ch] = u;
                    row[2 * i] = (uint8_t)d;
                    row[2 * i + 1] = (uint8_t)(d >> 8);
                }
            } else { /* uint8 codes, predictor 2 */
                unsigned prev[64];
                for (i = 0; i < n; i++) {
                    unsigned c = tn__io_code(src[i], j->lo, j->scale, 255u);
                    row[i] = (uint8_t)(i < ch ? c : (c - prev[i % ch]) & 0xffu);
                    prev[i % ch] = c;
                }
            }
        }
        j->st[s] = tn_zlib_deflate(&j->z[s], &j->zn[s], raw, rows * j->row_bytes, j->level);
    }
    TN_FREE(raw);
    TN_FREE(tmp);
}

/* IFD entry builder: entries are added in increasing tag order; values that do not fit in the
   entry go to the value area, whose final offset is known before anything is written. */
typedef struct tn__tif_out {
    uint8_t *buf;
    int big;
    size_t ifd, nent, maxent, vals, vpos; /* IFD at ifd, value area starts at vals, next free byte vpos */
} tn__tif_out;

static void tn__tif_put(uint8_t *p, uint64_t v, int bytes)
{
    int i;
    for (i = 0; i < bytes; i++) p[i] = (uint8_t)(v >> (8 * i));
}

/* Adds an entry of `count` values of `type`; data holds them little-endian already. */
static void tn__tif_entry(tn__tif_out *o, unsigned tag, unsigned type, uint64_t count, const uint8_t *data)
{
    size_t esz = o->big ? 20 : 12, inl = o->big ? 8 : 4, bytes = (size_t)count * tn__tif_type_size[type];
    uint8_t *e = o->buf + o->ifd + (o->big ? 8 : 2) + o->nent * esz;
    TN_ASSERT(o->nent < o->maxent);
    tn__tif_put(e, tag, 2);
    tn__tif_put(e + 2, type, 2);
    tn__tif_put(e + 4, count, (int)inl);
    if (bytes <= inl) {
        memcpy(e + 4 + inl, data, bytes);
    } else {
        tn__tif_put(e + 4 + inl, o->vpos, (int)inl);
        memcpy(o->buf + o->vpos, data, bytes);
        o->vpos += (bytes + 1) & ~(size_t)1; /* word-aligned values */
    }
    o->nent++;
}

static void tn__tif_entry1(tn__tif_out *o, unsigned tag, unsigned type, uint64_t v)
{
    uint8_t d[8];
    tn__tif_put(d, v, tn__tif_type_size[type]);
    tn__tif_entry(o, tag, type, 1, d);
}

static tn_status tn__tif_encode(const tn_image *img, int bits, int level, const tn_georef *geo, double lo, double hi,
                                uint8_t **out, size_t *out_size)
{
    tn__tif_enc j;
    tn__tif_out o;
    size_t ch = (size_t)img->channels, k, total_z = 0, vbytes, head, data_at, size, nent, i;
    int big, rgb = bits == 8 && (ch == 3 || ch == 4), has_geo = geo && geo->has_transform, use_matrix = 0;
    uint8_t *tmp = NULL, small[64 * 2];
    double gt[6];
    tn_status st = TN_OK;
    if (ch > 64) return tn__fail(TN_ERR_SHAPE, "TIFF: %zu channels (1..64 are written)", ch);
    if (bits == 16) {
        size_t count = (size_t)img->width * (size_t)img->height * ch;
        for (k = 0; k < count; k++)
            if (!(img->data[k] >= -32768.5f && img->data[k] < 32767.5f))
                return tn__fail(TN_ERR_INVALID_ARG, "TIFF int16: value %g is outside -32768..32767; save as float32 (bit_depth 32)",
                                (double)img->data[k]);
    }
    if (has_geo) {
        memcpy(gt, geo->transform, sizeof gt);
        for (k = 0; k < 6; k++)
            if (!(fabs(gt[k]) <= DBL_MAX)) return tn__fail(TN_ERR_INVALID_ARG, "TIFF: georeference transform is not finite");
        if (gt[1] * gt[5] - gt[2] * gt[4] == 0.0) return tn__fail(TN_ERR_INVALID_ARG, "TIFF: georeference transform is singular");
        if (geo->nkeys < 0 || geo->nkeys > TN_GEOREF_MAX_KEYS || geo->ndoubles < 0 || geo->ndoubles > TN_GEOREF_MAX_DOUBLES ||
            geo->nascii < 0 || geo->nascii >= TN_GEOREF_MAX_ASCII || !tn__georef_keys_ok(geo->keys, geo->nkeys, geo->ndoubles, geo->nascii))
            return tn__fail(TN_ERR_INVALID_ARG, "TIFF: malformed GeoKey directory in the georeference");
        for (k = 4; geo->nkeys && k + 3 < (size_t)geo->nkeys; k += 4) /* PixelIsPoint: back to the pixel centre */
            if (geo->keys[k] == 1025 && geo->keys[k + 1] == 0 && geo->keys[k + 3] == 2) {
                gt[0] += 0.5 * (gt[1] + gt[2]);
                gt[3] += 0.5 * (gt[4] + gt[5]);
            }
        if (!(fabs(gt[0]) <= DBL_MAX && fabs(gt[3]) <= DBL_MAX))
            return tn__fail(TN_ERR_INVALID_ARG, "TIFF: georeference transform overflows at the pixel centre");
        use_matrix = gt[2] != 0.0 || gt[4] != 0.0 || gt[5] > 0.0;
    }
    memset(&j, 0, sizeof j);
    memset(&o, 0, sizeof o);
    j.img = img;
    j.bits = bits;
    j.level = level;
    j.lo = lo;
    j.scale = 255.0 / (hi - lo);
    j.row_bytes = (size_t)img->width * ch * (size_t)bits / 8;
    j.rps = 262144 / j.row_bytes; /* about 256 KiB strips: good ratio, enough strips to share out */
    if (j.rps < 1) j.rps = 1;
    if (j.rps > (size_t)img->height) j.rps = (size_t)img->height;
    j.nstrips = ((size_t)img->height + j.rps - 1) / j.rps;
    j.z = (uint8_t **)tn__calloc(j.nstrips * sizeof(uint8_t *));
    j.zn = (size_t *)tn__calloc(j.nstrips * sizeof(size_t));
    j.st = (tn_status *)tn__calloc(j.nstrips * sizeof(tn_status));
    if (!j.z || !j.zn || !j.st) { st = tn__oom(); goto done; }
    tn_parallel_for(j.nstrips, 1, tn__tif_enc_range, &j);
    for (k = 0; k < j.nstrips; k++) {
        if (j.st[k] && !st) st = tn__fail(j.st[k], "TIFF: compressing strip %zu failed", k);
        total_z += j.zn[k];
    }
    if (st) goto done;
    nent = 12 + (ch > (rgb ? 3u : 1u)) + (has_geo ? (use_matrix ? 1 : 2) : 0) +
           (has_geo && geo->nkeys ? 1 + (geo->ndoubles > 0) + (geo->nascii > 0) : 0);
    vbytes = 16 * 2 + 3 * ch * 2 + 2 * j.nstrips * 8 + 16 * 8 + 6 * 8 + 3 * 8 +
             (has_geo ? (size_t)geo->nkeys * 2 + (size_t)geo->ndoubles * 8 + (size_t)geo->nascii + 8 : 0);
    big = (double)total_z + (double)vbytes + 1024.0 + (double)nent * 20.0 > tn__tif_classic_max;
    head = big ? 16 : 8;
    memset(&o, 0, sizeof o);
    o.big = big;
    o.ifd = head;
    o.maxent = nent;
    o.vals = head + (big ? 8 : 2) + nent * (big ? 20 : 12) + (big ? 8 : 4);
    o.vpos = o.vals;
    data_at = (o.vals + vbytes + 15) & ~(size_t)15;
    size = data_at + total_z;
    o.buf = (uint8_t *)tn__calloc(size);
    tmp = (uint8_t *)tn__alloc(j.nstrips * 8 + 16 * 8 + (has_geo ? (size_t)geo->nkeys * 2 + (size_t)geo->ndoubles * 8 : 0));
    if (!o.buf || !tmp) { st = tn__oom(); goto done; }
    memcpy(o.buf, "II", 2);
    if (big) {
        tn__tif_put(o.buf + 2, 43, 2);
        tn__tif_put(o.buf + 4, 8, 2);
        tn__tif_put(o.buf + 8, head, 8);
        tn__tif_put(o.buf + head, nent, 8);
    } else {
        tn__tif_put(o.buf + 2, 42, 2);
        tn__tif_put(o.buf + 4, head, 4);
        tn__tif_put(o.buf + head, nent, 2);
    }
    tn__tif_entry1(&o, 256, 4, (uint64_t)img->width);
    tn__tif_entry1(&o, 257, 4, (uint64_t)img->height);
    for (i = 0; i < ch; i++) tn__tif_put(small + 2 * i, (uint64_t)bits, 2);
    tn__tif_entry(&o, 258, 3, ch, small);
    tn__tif_entry1(&o, 259, 3, 8);
    tn__tif_entry1(&o, 262, 3, rgb ? 2 : 1);
    for (k = 0, i = data_at; k < j.nstrips; i += j.zn[k], k++) tn__tif_put(tmp + k * (big ? 8 : 4), i, big ? 8 : 4);
    tn__tif_entry(&o, 273, big ? 16 : 4, j.nstrips, tmp);
    tn__tif_entry1(&o, 277, 3, ch);
    tn__tif_entry1(&o, 278, 4, j.rps);
    for (k = 0; k < j.nstrips; k++) tn__tif_put(tmp + k * (big ? 8 : 4), j.zn[k], big ? 8 : 4);
    tn__tif_entry(&o, 279, big ? 16 : 4, j.nstrips, tmp);
    tn__tif_entry1(&o, 284, 3, 1);
    tn__tif_entry1(&o, 317, 3, bits == 32 ? 3 : 2);
    if (ch > (rgb ? 3u : 1u)) { /* extra samples: alpha of an RGBA picture, else unspecified */
        size_t ne = ch - (rgb ? 3u : 1u);
        for (i = 0; i < ne; i++) tn__tif_put(small + 2 * i, rgb ? 2 : 0, 2);
        tn__tif_entry(&o, 338, 3, ne, small);
    }
    for (i = 0; i < ch; i++) tn__tif_put(small + 2 * i, bits == 32 ? 3 : bits == 16 ? 2 : 1, 2);
    tn__tif_entry(&o, 339, 3, ch, small);
    if (has_geo) {
        double v[16];
        uint64_t u;
        size_t nv;
        if (use_matrix) {
            memset(v, 0, sizeof v);
            v[0] = gt[1]; v[1] = gt[2]; v[3] = gt[0];
            v[4] = gt[4]; v[5] = gt[5]; v[7] = gt[3];
            v[10] = 0.0; v[15] = 1.0;
            nv = 16;
        } else {
            v[0] = gt[1]; v[1] = -gt[5]; v[2] = 0.0;
            nv = 3;
        }
        for (i = 0; i < nv; i++) { memcpy(&u, &v[i], 8); tn__tif_put(tmp + 8 * i, u, 8); }
        if (!use_matrix) {
            tn__tif_entry(&o, 33550, 12, 3, tmp);
            v[0] = v[1] = v[2] = 0.0;
            v[3] = gt[0]; v[4] = gt[3]; v[5] = 0.0;
            for (i = 0; i < 6; i++) { memcpy(&u, &v[i], 8); tn__tif_put(tmp + 8 * i, u, 8); }
            tn__tif_entry(&o, 33922, 12, 6, tmp);
        } else {
            tn__tif_entry(&o, 34264, 12, 16, tmp);
        }
        if (geo->nkeys) {
            for (i = 0; i < (size_t)geo->nkeys; i++) tn__tif_put(tmp + 2 * i, geo->keys[i], 2);
            tn__tif_entry(&o, 34735, 3, (uint64_t)geo->nkeys, tmp);
            if (geo->ndoubles) {
                for (i = 0; i < (size_t)geo->ndoubles; i++) { memcpy(&u, &geo->doubles[i], 8); tn__tif_put(tmp + 8 * i, u, 8); }
                tn__tif_entry(&o, 34736, 12, (uint64_t)geo->ndoubles, tmp);
            }
            if (geo->nascii) tn__tif_entry(&o, 34737, 2, (uint64_t)geo->nascii, (const uint8_t *)geo->ascii);
        }
    }
    TN_ASSERT(o.nent == nent && o.vpos <= data_at);
    for (k = 0, i = data_at; k < j.nstrips; i += j.zn[k], k++) memcpy(o.buf + i, j.z[k], j.zn[k]);
    *out = o.buf;
    *out_size = size;
    o.buf = NULL;
done:
    TN_FREE(o.buf);
    TN_FREE(tmp);
    for (k = 0; j.z && k < j.nstrips; k++) TN_FREE(j.z[k]);
    TN_FREE(j.z);
    TN_FREE(j.zn);
    TN_FREE(j.st);
    return st;
}

/* ---- detection ---- */

static tn_format tn__io_format_from_magic(const uint8_t *p, size_t n)
{
    static const uint8_t png_sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
    size_t i = 0, tb, tl;
    if (n >= 8 && memcmp(p, png_sig, 8) == 0) return TN_FORMAT_PNG;
    if (n >= 4 && ((p[0] == 'I' && p[1] == 'I' && (p[2] == 42 || p[2] == 43) && p[3] == 0) ||
                   (p[0] == 'M' && p[1] == 'M' && p[2] == 0 && (p[3] == 42 || p[3] == 43))))
        return TN_FORMAT_TIFF;
    if (n >= 3 && p[0] == 'P' && (tn__io_space(p[2]) || p[2] == '#')) {
        if (p[1] == 'F' || p[1] == 'f') return TN_FORMAT_PFM;
        if (p[1] >= '1' && p[1] <= '7') return TN_FORMAT_PNM; /* P1/P4/P7 get a clear "unsupported" */
    }
    if (tn__io_token(p, n < 64 ? n : 64, &i, &tb, &tl) && tn__asc_key((const char *)p + tb, tl) >= 0 &&
        !tn__io_token_is((const char *)p + tb, tl, "dx") && !tn__io_token_is((const char *)p + tb, tl, "dy"))
        return TN_FORMAT_ASC;
    return TN_FORMAT_AUTO;
}

/* Format named by the extension of path (case-insensitive), or AUTO. */
static tn_format tn__io_format_from_name(const char *path)
{
    static const char *const ext[] = {"png", "pgm", "ppm", "pnm", "pfm", "hgt", "asc", "r16", "raw", "tif", "tiff"};
    static const tn_format fmt[] = {TN_FORMAT_PNG, TN_FORMAT_PNM, TN_FORMAT_PNM, TN_FORMAT_PNM, TN_FORMAT_PFM,
                                    TN_FORMAT_HGT, TN_FORMAT_ASC, TN_FORMAT_R16, TN_FORMAT_R16, TN_FORMAT_TIFF, TN_FORMAT_TIFF};
    const char *s, *dot = NULL;
    size_t k;
    if (!path) return TN_FORMAT_AUTO;
    for (s = path; *s; s++) {
        if (*s == '/' || *s == '\\') dot = NULL;
        else if (*s == '.') dot = s;
    }
    if (!dot) return TN_FORMAT_AUTO;
    for (k = 0; k < sizeof ext / sizeof ext[0]; k++)
        if (tn__io_token_is(dot + 1, strlen(dot + 1), ext[k])) return fmt[k];
    return TN_FORMAT_AUTO;
}

/* ---- load ---- */

TN_API tn_status tn_image_load_memory(tn_image *img, const void *data, size_t size, const char *name,
                                      const tn_load_opts *opts, tn_image_info *info)
{
    static const uint8_t empty[1] = {0};
    const uint8_t *p = data ? (const uint8_t *)data : empty;
    const char *label = name && name[0] ? name : "<memory>";
    tn_format f = opts ? opts->format : TN_FORMAT_AUTO;
    tn_image tmp;
    tn_image_info inf;
    tn_status st;
    TN_ASSERT(img);
    if (!data && size) return tn__fail(TN_ERR_INVALID_ARG, "%s: NULL data with size %zu", label, size);
    memset(&tmp, 0, sizeof tmp);
    memset(&inf, 0, sizeof inf);
    if ((int)f < (int)TN_FORMAT_AUTO || (int)f > (int)TN_FORMAT_TIFF)
        return tn__fail(TN_ERR_INVALID_ARG, "%s: unknown format code %d", label, (int)f);
    if (f == TN_FORMAT_AUTO) f = tn__io_format_from_magic(p, size);
    if (f == TN_FORMAT_AUTO) f = tn__io_format_from_name(name);
    if (f == TN_FORMAT_AUTO)
        return tn__fail(TN_ERR_FORMAT, "%s: unknown file format (no known magic bytes or extension)", label);
    switch (f) {
    case TN_FORMAT_PNG: st = tn__png_decode(p, size, label, &tmp, &inf); break;
    case TN_FORMAT_PNM: st = tn__pnm_decode(p, size, label, &tmp, &inf); break;
    case TN_FORMAT_PFM: st = tn__pfm_decode(p, size, label, &tmp, &inf); break;
    case TN_FORMAT_HGT: st = tn__hgt_decode(p, size, label, &tmp, &inf); break;
    case TN_FORMAT_ASC: st = tn__asc_decode(p, size, label, &tmp, &inf); break;
    case TN_FORMAT_R16: st = tn__r16_decode(p, size, label, opts, &tmp, &inf); break;
    case TN_FORMAT_TIFF: st = tn__tif_decode(p, size, label, &tmp, &inf); break;
    default: st = tn__fail(TN_ERR_FORMAT, "%s: unknown file format", label); break;
    }
    if (st) {
        tn_image_free(&tmp);
        return st;
    }
    inf.format = f;
    *img = tmp;
    if (info) *info = inf;
    return TN_OK;
}

#include <errno.h> /* ENOENT: "no such file" */

/* Reads a whole file with one fread. *out is TN_MALLOC'd. */
TN__INTERNAL tn_status tn__io_read_file(const char *path, uint8_t **out, size_t *out_size)
{
    FILE *f;
    long end = -1;
    size_t n, got;
    uint8_t *buf;
    errno = 0;
    if (!(f = fopen(path, "rb"))) {
        if (errno == ENOENT) return tn__fail(TN_ERR_IO, "%s: no such file", path);
        return tn__fail(TN_ERR_IO, "%s: cannot open for reading%s%s", path, errno ? ": " : "", errno ? strerror(errno) : "");
    }
    if (fseek(f, 0, SEEK_END) != 0 || (end = ftell(f)) < 0 || fseek(f, 0, SEEK_SET) != 0) {
        fclose(f);
        return tn__fail(TN_ERR_IO, "%s: cannot determine the file size", path);
    }
    if ((unsigned long long)end > (unsigned long long)TN_MAX_ALLOC || end == 0) {
        /* a directory reports a size of 0 or LONG_MAX but fails to read: say so */
        int c = fgetc(f), err = ferror(f);
        fclose(f);
        if (err) return tn__fail(TN_ERR_IO, "%s: cannot read (a directory?)", path);
        if (end != 0) return tn__fail(TN_ERR_TOO_LARGE, "%s: %ld bytes exceeds the allocation limit", path, end);
        if (c != EOF) return tn__fail(TN_ERR_IO, "%s: the size is unknown (not a regular file?)", path);
        *out = (uint8_t *)tn__alloc(1); /* an empty file: the parsers report it */
        *out_size = 0;
        return *out ? TN_OK : tn__fail_context(TN_ERR_OUT_OF_MEMORY, path);
    }
    n = (size_t)end;
    buf = (uint8_t *)tn__alloc(n);
    if (!buf) { fclose(f); return tn__fail_context(TN_ERR_OUT_OF_MEMORY, path); }
    got = fread(buf, 1, n, f);
    if (got != n || ferror(f)) {
        fclose(f);
        TN_FREE(buf);
        return tn__fail(TN_ERR_IO, "%s: read failed (%zu of %zu bytes)", path, got, n);
    }
    fclose(f);
    *out = buf;
    *out_size = n;
    return TN_OK;
}

TN_API tn_status tn_image_load_ex(tn_image *img, const char *path, const tn_load_opts *opts, tn_image_info *info)
{
    uint8_t *buf = NULL;
    size_t n = 0;
    tn_status st;
    TN_ASSERT(img);
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "load: empty path");
    st = tn__io_read_file(path, &buf, &n);
    if (st) return st;
    st = tn_image_load_memory(img, buf, n, path, opts, info);
    TN_FREE(buf);
    return st;
}

TN_API tn_status tn_image_load(tn_image *img, const char *path, tn_image_info *info)
{
    return tn_image_load_ex(img, path, NULL, info);
}

/* ---- save ---- */

/* The zero rules of tn_save_opts for writing a `channels`-channel image as `format`: float32
   for TIFF, else 16 bits for one channel and for .r16, else 8; PNG/TIFF level 6; .asc cell size
   1 (also for a negative or non-finite one, which is not refused). The format itself is picked
   by tn_image_save. */
static void tn__save_opts_defaults(tn_save_opts *o, int channels, tn_format format)
{
    if (!o->bit_depth) o->bit_depth = format == TN_FORMAT_TIFF ? 32 : channels == 1 || format == TN_FORMAT_R16 ? 16 : 8;
    if (!o->compression) o->compression = 6;
    if (!(o->cellsize > 0.0 && o->cellsize <= DBL_MAX)) o->cellsize = 1.0;
}

TN_API tn_status tn_image_save_memory(uint8_t **out, size_t *out_size, const tn_image *img, tn_format format,
                                      const tn_save_opts *opts)
{
    tn_save_opts o;
    double lo = 0.0, hi = 1.0;
    int record = 0;
    size_t bad;
    tn_status st;
    TN_ASSERT(out && out_size);
    *out = NULL;
    *out_size = 0;
    if (!img || !img->data || img->width <= 0 || img->height <= 0 || img->channels <= 0)
        return tn__fail(TN_ERR_INVALID_ARG, "save: the image is empty");
    bad = tn_image_range(NULL, NULL, img);
    if (bad) return tn__fail(TN_ERR_NUMERIC, "save: the image has %zu NaN/Inf samples", bad);
    memset(&o, 0, sizeof o);
    if (opts) o = *opts;
    tn__save_opts_defaults(&o, img->channels, format);
    if (format == TN_FORMAT_PNG || format == TN_FORMAT_PNM || format == TN_FORMAT_R16) {
        if (o.bit_depth != 8 && o.bit_depth != 16) return tn__fail(TN_ERR_INVALID_ARG, "save: bit depth %d (use 8 or 16)", o.bit_depth);
        if (format == TN_FORMAT_R16 && o.bit_depth != 16) return tn__fail(TN_ERR_INVALID_ARG, "save: .r16 is always 16-bit");
        st = tn__io_save_mapping(img, &o, &lo, &hi, &record);
        if (st) return st;
    }
    if (format == TN_FORMAT_TIFF) {
        if (o.bit_depth != 8 && o.bit_depth != 16 && o.bit_depth != 32)
            return tn__fail(TN_ERR_INVALID_ARG, "save: TIFF bit depth %d (32 float, 16 int16, 8 uint8)", o.bit_depth);
        if (o.compression < 0 || o.compression > 9)
            return tn__fail(TN_ERR_INVALID_ARG, "save: TIFF deflate level %d (0-9)", o.compression);
        if (o.bit_depth == 8 && (st = tn__io_save_mapping(img, &o, &lo, &hi, &record)) != TN_OK) return st;
        return tn__tif_encode(img, o.bit_depth, o.compression, o.georef, lo, hi, out, out_size);
    }
    switch (format) {
    case TN_FORMAT_PNG:
        if (img->channels > 4) return tn__fail(TN_ERR_SHAPE, "PNG stores 1 to 4 channels, not %d", img->channels);
        if (o.compression < 0 || o.compression > 9)
            return tn__fail(TN_ERR_INVALID_ARG, "save: PNG compression level %d (0-9)", o.compression);
        return tn__png_encode(img, o.bit_depth, lo, hi, record, o.compression, out, out_size);
    case TN_FORMAT_PNM: return tn__pnm_encode(img, o.bit_depth, lo, hi, record, out, out_size);
    case TN_FORMAT_PFM: return tn__pfm_encode(img, out, out_size);
    case TN_FORMAT_HGT: return tn__hgt_encode(img, out, out_size);
    case TN_FORMAT_ASC: return tn__asc_encode(img, o.cellsize, out, out_size);
    case TN_FORMAT_R16: return tn__r16_encode(img, lo, hi, out, out_size);
    default: break;
    }
    return tn__fail(TN_ERR_INVALID_ARG, "save: no format given (%d)", (int)format);
}

/* A number that differs between processes, for temporary file names. */
static unsigned long tn__io_process_id(void)
{
#if !defined(TN_NO_THREADS) && defined(_POSIX_VERSION)
    return (unsigned long)getpid();
#else
    return (unsigned long)time(NULL);
#endif
}

static unsigned long tn__io_tmp_counter;

/* Atomic saves, with <stdio.h> and <unistd.h> only. A save of PATH writes "PATH.tmp", flushes it
   to disk (fsync where POSIX has it) and renames it over PATH, so a failed or killed save never
   leaves PATH torn. The temporary's name is the same for every save of PATH, so a killed save
   leaves at most one and the next save replaces it (per-process names left one behind for
   good per killed save). A save holds its temporary: in this process through the
   list of targets being saved, across processes through a lockf lock, which the system drops
   with a killed process. A save that finds the temporary held writes "PATH.tmp.PID.N" instead;
   only a kill during such an overlap leaves one of those. */
#if defined(_POSIX_VERSION) && !defined(_WIN32)
#define TN__IO_POSIX 1
#if !defined(__cplusplus) && !defined(fileno)
int fileno(FILE *stream); /* POSIX <stdio.h>; a strict -std=c99 hides it */
#endif
#if !defined(F_TLOCK) && !defined(__cplusplus)
#include <sys/types.h>
int lockf(int fd, int cmd, off_t len); /* POSIX (XSI) <unistd.h>; a strict -std=c99 hides it */
#define F_TLOCK 2                      /* the values of every POSIX system */
#define F_TEST 3
#endif
#if defined(F_TLOCK)
#define TN__IO_LOCKF 1
#endif
#endif

/* The targets this process is saving (64-bit name hashes; a collision only costs a fallback
   name). Threads saving one target must not share its temporary: lockf locks are per process. */
#define TN__IO_SAVING 64
static uint64_t tn__io_saving[TN__IO_SAVING];
#if !defined(TN_NO_THREADS)
static pthread_mutex_t tn__io_saving_mutex = PTHREAD_MUTEX_INITIALIZER;
#define TN__IO_SAVING_LOCK() pthread_mutex_lock(&tn__io_saving_mutex)
#define TN__IO_SAVING_UNLOCK() pthread_mutex_unlock(&tn__io_saving_mutex)
#else
#define TN__IO_SAVING_LOCK() (void)0
#define TN__IO_SAVING_UNLOCK() (void)0
#endif

static uint64_t tn__io_name_hash(const char *path)
{
    uint64_t h = 1469598103934665603ull;
    for (; *path; path++) h = (h ^ (unsigned char)*path) * 1099511628211ull;
    return h ? h : 1;
}

/* Marks path as being saved here; 0 when it already is (or 64 saves run at once). */
static int tn__io_saving_enter(const char *path)
{
    uint64_t h = tn__io_name_hash(path);
    int i, free_slot = -1;
    TN__IO_SAVING_LOCK();
    for (i = 0; i < TN__IO_SAVING; i++) {
        if (tn__io_saving[i] == h) free_slot = -2;
        if (!tn__io_saving[i] && free_slot == -1) free_slot = i;
    }
    if (free_slot >= 0) tn__io_saving[free_slot] = h;
    TN__IO_SAVING_UNLOCK();
    return free_slot >= 0;
}

static void tn__io_saving_leave(const char *path)
{
    uint64_t h = tn__io_name_hash(path);
    int i;
    TN__IO_SAVING_LOCK();
    for (i = 0; i < TN__IO_SAVING; i++)
        if (tn__io_saving[i] == h) {
            tn__io_saving[i] = 0;
            break;
        }
    TN__IO_SAVING_UNLOCK();
}

/* Opens tmp, the temporary of a target this process holds (tn__io_saving_enter), for writing,
   and locks it; a leftover of a killed save (unlocked) is replaced. NULL: another process's
   save holds it. */
static FILE *tn__io_claim(const char *tmp)
{
#if defined(TN__IO_LOCKF)
    FILE *f = fopen(tmp, "r+b");
    if (f) {
        int leftover = lockf(fileno(f), F_TLOCK, 0) == 0;
        if (leftover) remove(tmp);
        fclose(f);
        if (!leftover) return NULL;
    }
    if (!(f = fopen(tmp, "wbx"))) return NULL; /* created by another save in between */
    if (lockf(fileno(f), F_TLOCK, 0) != 0) {   /* taken by a save that thought it a leftover */
        fclose(f);
        return NULL;
    }
    return f;
#else
    return fopen(tmp, "wb");
#endif
}

/* Makes a rename in path's directory durable (POSIX; a no-op elsewhere or where it fails). */
static void tn__io_sync_dir(const char *path)
{
#if defined(TN__IO_POSIX)
    const char *slash = strrchr(path, '/');
    char dir[1024];
    FILE *f;
    size_t dl = slash ? (size_t)(slash - path) : 0;
    if (dl >= sizeof dir) return;
    if (!slash) strcpy(dir, ".");
    else if (dl == 0) strcpy(dir, "/");
    else {
        memcpy(dir, path, dl);
        dir[dl] = 0;
    }
    if (!(f = fopen(dir, "rb"))) return; /* a directory opens read-only on POSIX systems */
    (void)fsync(fileno(f));
    fclose(f);
#else
    (void)path;
#endif
}

/* A save in progress: the temporary of path (above), open for writing as f. tn__io_temp_open
   claims it; tn__io_temp_finish flushes it to disk and renames it over path, or removes it. A
   streamed writer (texgan) writes f in pieces between the two. */
typedef struct tn__io_temp {
    FILE *f, *check;
    char *tmp;
    const char *path;
    int held, shared; /* holds path in this process; shared: PATH.tmp (not a name of its own) */
} tn__io_temp;

/* own: a name of this save's own, for when PATH.tmp turned out not to be this save's. */
static tn_status tn__io_temp_open(tn__io_temp *t, const char *path, int own)
{
    size_t cap = strlen(path) + 64;
    memset(t, 0, sizeof *t);
    t->path = path;
    if (!(t->tmp = (char *)tn__alloc(cap))) return tn__oom();
    t->held = tn__io_saving_enter(path);
    if (t->held && !own) {
        snprintf(t->tmp, cap, "%s.tmp", path);
        if ((t->f = tn__io_claim(t->tmp)) != NULL) t->shared = 1;
    }
    if (!t->f) { /* another save of path runs: a name of this save's own */
        unsigned long serial = ++tn__io_tmp_counter ^ (unsigned long)((size_t)&cap >> 4) << 16; /* distinct per thread stack */
        snprintf(t->tmp, cap, "%s.tmp.%lu.%lu", path, tn__io_process_id(), serial);
        t->f = fopen(t->tmp, "wb");
    }
    if (!t->f) {
        if (t->held) tn__io_saving_leave(path);
        TN_FREE(t->tmp);
        return tn__fail(TN_ERR_IO, "%s: cannot create a temporary file next to it", path);
    }
    return TN_OK;
}

/* Ends the save: ok (nothing failed while writing) puts the temporary in place, otherwise it is
   removed. 1: done; 0: failed (the error is set); -1: PATH.tmp was taken from this save (its
   writes are lost; nothing is set), so the caller writes again under tn__io_temp_open(.., 1). */
static int tn__io_temp_finish(tn__io_temp *t, int ok)
{
    int unrenamed = 0;
    ok = fflush(t->f) == 0 && ok;
#if defined(TN__IO_POSIX)
    ok = fsync(fileno(t->f)) == 0 && ok; /* on disk before the rename */
#endif
    ok = !ferror(t->f) && ok;
#if defined(TN__IO_LOCKF)
    /* the name is still this save's file (locked by no other process): a save that took the
       file for a leftover before this one locked it would hold the name now */
    if (ok && t->shared && (!(t->check = fopen(t->tmp, "rb")) || lockf(fileno(t->check), F_TEST, 0) != 0)) {
        if (t->check) fclose(t->check);
        fclose(t->f);
        if (t->held) tn__io_saving_leave(t->path);
        TN_FREE(t->tmp);
        return -1;
    }
#endif
    if (ok && rename(t->tmp, t->path) != 0) {
#ifdef _WIN32
        fclose(t->f), t->f = NULL; /* no rename over an open or existing file */
        unrenamed = !(remove(t->path) == 0 && rename(t->tmp, t->path) == 0);
#else
        unrenamed = 1;
#endif
        ok = !unrenamed;
    }
    if (!ok) remove(t->tmp); /* while still held */
    if (t->check) fclose(t->check); /* after the rename: closing either drops the lock */
    if (t->f && fclose(t->f) != 0) ok = 0;
    if (t->held) tn__io_saving_leave(t->path);
    TN_FREE(t->tmp);
    if (unrenamed) return tn__fail(TN_ERR_IO, "%s: cannot rename the temporary file into place", t->path), 0;
    if (!ok) return tn__fail(TN_ERR_IO, "%s: write failed (disk full?)", t->path), 0;
    tn__io_sync_dir(t->path);
    return 1;
}

/* Ends a save that failed before its end (its error is set): the temporary is removed. */
TN__SHARED void tn__io_temp_discard(tn__io_temp *t)
{
    remove(t->tmp); /* while still held */
    fclose(t->f);
    if (t->held) tn__io_saving_leave(t->path);
    TN_FREE(t->tmp);
}

/* Writes buf to path's temporary, flushes it to disk and renames it over path. */
static tn_status tn__io_write_atomic(const char *path, const uint8_t *buf, size_t n)
{
    tn__io_temp t;
    int own, r = 0;
    tn_status st;
    for (own = 0; own < 2; own++) {
        if ((st = tn__io_temp_open(&t, path, own))) return st;
        r = tn__io_temp_finish(&t, fwrite(buf, 1, n, t.f) == n);
        if (r >= 0) break;
    }
    return r == 1 ? TN_OK : TN_ERR_IO;
}

TN_API tn_status tn_image_save(const char *path, const tn_image *img, const tn_save_opts *opts)
{
    tn_format f = opts ? opts->format : TN_FORMAT_AUTO;
    uint8_t *buf = NULL;
    size_t n = 0;
    tn_status st;
    if (!path || !path[0]) return tn__fail(TN_ERR_INVALID_ARG, "save: empty path");
    if (f == TN_FORMAT_AUTO) f = tn__io_format_from_name(path);
    if (f == TN_FORMAT_AUTO)
        return tn__fail(TN_ERR_FORMAT, "%s: cannot tell the format from the extension (png pgm ppm pnm pfm hgt asc r16 raw tif tiff)", path);
    st = tn_image_save_memory(&buf, &n, img, f, opts);
    if (st) return tn__fail_context(st, path);
    st = tn__io_write_atomic(path, buf, n);
    TN_FREE(buf);
    return st;
}

