/* ============================================================================================
   @@io  file formats
   PNG: every bit depth and colour type, Adam7, CRC and Adler-32 checked (own inflate); writes
        8/16-bit with real deflate. A heightmap's metre range rides in a tEXt chunk
        "terrainnet.range" = "<lo> <hi>", so a 16-bit round trip restores real units.
   PGM/PPM (P2/P3/P5/P6, 8/16-bit; range in a "# terrainnet.range lo hi" comment), PFM (float),
   SRTM .hgt (1201^2 or 3601^2 big-endian int16 metres, voids -32768 filled), ESRI ASCII grid
   .asc (NODATA filled), headerless 16-bit little-endian .r16 (size given or square inferred),
   TIFF / GeoTIFF (.tif .tiff, see below).
   Format is picked by magic bytes, then by extension.
   Pixel values on load: integer formats give [0, 1] (code / max code), or metres when the file
   carries a range; .hgt and .asc give their values as stored (metres); PFM gives raw floats.
   TIFF / GeoTIFF read: classic and BigTIFF, either byte order, strips or tiles, planar
   configuration 1 or 2, no compression / PackBits / LZW / Deflate, predictor 1, 2 (horizontal)
   or 3 (floating point); 8/16/32/64-bit signed and unsigned integers, 32/64-bit floats, any
   number of samples; the first full-resolution image of the file (overviews and masks are
   skipped). Values are as stored (metres for a DEM), except 8-bit unsigned data and RGB
   pictures of 8/16-bit unsigned integers, which give [0, 1] like PNG. GDAL_NODATA cells and NaN/Inf
   are voids, filled like .hgt voids. The georeference (ModelPixelScale + ModelTiepoint or
   ModelTransformation, and the GeoKey directory) goes to info->georef; see tn_georef.
   TIFF write: one image, strips, Deflate with predictor: float32 (predictor 3; the default),
   int16 (bit_depth 16: metres rounded, predictor 2) or uint8 (bit_depth 8: [0, 1] pictures as
   codes 0..255, RGB for 3 or 4 channels); BigTIFF only when the file would pass 4 GiB. The
   georeference in opts->georef (e.g. the input's info.georef) is written with it, so a result
   lines up with its source in GIS tools.
   A recorded range beyond float range fails with TN_ERR_NUMERIC (a NaN one is ignored); the
   range text is read and written without the C locale.
   ============================================================================================ */

typedef enum tn_format {
    TN_FORMAT_AUTO = 0, TN_FORMAT_PNG, TN_FORMAT_PNM, TN_FORMAT_PFM, TN_FORMAT_HGT, TN_FORMAT_ASC, TN_FORMAT_R16,
    TN_FORMAT_TIFF
} tn_format;

/* Capacities of the GeoKey directory kept in a tn_georef; a file whose directory is larger
   still gives its transform and spacing, but its keys are not carried over (nkeys = 0). */
#define TN_GEOREF_MAX_KEYS 512    /* uint16 entries: 4 header + 4 per key (127 keys) */
#define TN_GEOREF_MAX_DOUBLES 64
#define TN_GEOREF_MAX_ASCII 4096

/* Where a raster lies on the Earth, as a GeoTIFF states it. The transform is GDAL's
   geotransform, to pixel corners (a PixelIsPoint file is moved half a pixel, as GDAL does):
   column c, row r (0, 0 = top-left corner of the top-left pixel) lie at
   X = t[0] + c t[1] + r t[2],  Y = t[3] + c t[4] + r t[5]  in the CRS's units.
   The GeoKey directory and its double/ASCII parameters are kept verbatim so a save carries the
   CRS over without terrainnet having to understand it. */
typedef struct tn_georef {
    int has_transform;       /* 1: transform holds a geotransform */
    double transform[6];
    int model_type;          /* GTModelTypeGeoKey: 1 projected, 2 geographic (lon/lat), 3 geocentric, 0 not stated */
    int pixel_is_point;      /* GTRasterTypeGeoKey said PixelIsPoint */
    double dx, dy;           /* pixel spacing in metres along a row and down a column; 0 if unknown
                                (no transform or no CRS units); geographic degrees are converted at
                                the raster's centre latitude on the file's ellipsoid (default WGS 84) */
    int nkeys, ndoubles, nascii; /* used entries of the arrays below (0 = no GeoKey directory) */
    uint16_t keys[TN_GEOREF_MAX_KEYS];     /* GeoKeyDirectoryTag */
    double doubles[TN_GEOREF_MAX_DOUBLES]; /* GeoDoubleParamsTag */
    char ascii[TN_GEOREF_MAX_ASCII];       /* GeoAsciiParamsTag, NUL-terminated */
} tn_georef;

/* What a file held, filled by the loaders. */
typedef struct tn_image_info {
    tn_format format;
    int bit_depth;           /* bits per sample in the file (1..16; 32 for float formats; TIFF 8..64) */
    int file_channels;       /* samples per pixel in the file (palette PNG: 1) */
    int interlaced;          /* PNG Adam7 */
    int has_range;           /* 1 if the file gives a height mapping; pixels were converted with it */
    double range_lo, range_hi; /* code 0 -> range_lo, max code -> range_hi */
    double cellsize;         /* .asc cell size; a GeoTIFF's square pixel size in CRS units; an SRTM .hgt's
                                mean spacing in metres at its name's latitude (0 if unknown) */
    double x_origin, y_origin; /* .asc / GeoTIFF lower-left corner */
    size_t voids_filled;     /* .hgt / .asc / TIFF cells that were void/NODATA and were filled */
    int has_nodata;          /* the file named a NODATA value (.asc NODATA_value, TIFF GDAL_NODATA) */
    double nodata;
    tn_georef georef;        /* GeoTIFF georeference; .asc gives a transform from its header */
} tn_image_info;

typedef struct tn_load_opts {
    tn_format format;        /* force a format; AUTO = magic bytes, then extension */
    int raw_width, raw_height; /* .r16 size; 0 = infer a square from the file size */
} tn_load_opts;

typedef struct tn_save_opts {
    tn_format format;        /* AUTO = from the extension */
    int bit_depth;           /* 8 or 16 for integer formats; 0 = 16 for 1-channel images, else 8.
                                TIFF: 32 float32 (0 = this), 16 int16 metres, 8 uint8 */
    int has_range;           /* 1: map [range_lo, range_hi] to codes 0..max and record it */
    double range_lo, range_hi; /* has_range == 0: values in [0, 1] are written as they are,
                                  anything else is mapped from its own min..max and recorded */
    int compression;         /* PNG / TIFF deflate level 0-9; 0 = default (6) */
    double cellsize;         /* .asc cell size; 0 = 1 */
    const tn_georef *georef; /* TIFF: georeference to write (NULL or one without transform = none);
                                a transform must be finite with non-zero pixel sizes */
} tn_save_opts;

/* Loads any supported file. info and opts may be NULL. On failure *img is untouched. */
TN_API tn_status tn_image_load(tn_image *img, const char *path, tn_image_info *info);
TN_API tn_status tn_image_load_ex(tn_image *img, const char *path, const tn_load_opts *opts, tn_image_info *info);
/* Same from memory; `name` (may be NULL) is used for the extension fallback and in messages. */
TN_API tn_status tn_image_load_memory(tn_image *img, const void *data, size_t size, const char *name,
                                      const tn_load_opts *opts, tn_image_info *info);
/* Saves; the format comes from opts or the extension. Writes to a temporary file and renames it,
   so a failed save never leaves a half-written file in place. opts may be NULL. */
TN_API tn_status tn_image_save(const char *path, const tn_image *img, const tn_save_opts *opts);
/* Encodes to a malloc'ed (TN_MALLOC) buffer the caller frees with TN_FREE / tn_free. */
TN_API tn_status tn_image_save_memory(uint8_t **out, size_t *out_size, const tn_image *img,
                                      tn_format format, const tn_save_opts *opts);
/* zlib streams (RFC 1950) with terrainnet's own deflate (level 0-9; 0 and zlib's -1 = 6) and inflate (Adler-32
   checked; output over max_out bytes, 0 = TN_MAX_ALLOC, fails with TN_ERR_TOO_LARGE). The output
   buffer is allocated here; free it with tn_free. */
TN_API tn_status tn_zlib_deflate(uint8_t **out, size_t *out_size, const uint8_t *src, size_t n, int level);
TN_API tn_status tn_zlib_inflate(uint8_t **out, size_t *out_size, const uint8_t *src, size_t n, size_t max_out);
/* Name of a format ("png", "pnm", ...). */
TN_API const char *tn_format_name(tn_format f);
/* Frees a buffer returned by the library (tn_image_save_memory and the like). */
TN_API void tn_free(void *p);

/* --------------------------------------------------------------------------------------------
   >>png  (part of @@io implementation)
   PNG codec with terrainnet's own zlib, so the library needs nothing but libc.
   - CRC-32 (slicing-by-8, tables built once) and Adler-32 checks.
   - Inflate (RFC 1950/1951): 64-bit bit buffer refilled 8 bytes at a time, two-level Huffman
     tables (10-bit root for literal/length, 8-bit for distances) so a symbol costs one or two
     lookups; the output is a growable buffer capped by max_out (zip bombs -> TN_ERR_TOO_LARGE).
   - Deflate: zlib's LZ77 (3-byte hash chains, greedy at levels 1-3, lazy evaluation at 4-9 with
     zlib's good/lazy/nice/chain table), blocks of 16K symbols written as dynamic Huffman (code
     lengths from Moffat-Katajainen, limited to 15/7 bits with the Kraft-fixing heuristic), fixed
     or stored, whichever is smallest.
   - PNG decode: every colour type/bit depth, Adam7, all filters, tRNS, PLTE; strict checking
     (CRC of every chunk, IHDR, chunk order, IEND, exact pixel data size). IDAT is inflated straight
     into a buffer of the exact raw size, unfiltered in place, then converted to floats.
   - PNG encode: 8/16-bit grey, grey+alpha, RGB, RGBA; per-row filter chosen by the minimum sum of
     absolute differences; the metre range rides in tEXt "terrainnet.range".
   -------------------------------------------------------------------------------------------- */

/* ---- byte helpers ---- */

TN__INTERNAL uint32_t tn__png_be32(const uint8_t *p)
{
    return ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | (uint32_t)p[3];
}

TN__INTERNAL void tn__png_put_be32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)(v >> 24);
    p[1] = (uint8_t)(v >> 16);
    p[2] = (uint8_t)(v >> 8);
    p[3] = (uint8_t)v;
}

/* Little-endian 64-bit load from any address (a plain memcpy on little-endian machines). */
static uint64_t tn__z_load64le(const uint8_t *p)
{
#if defined(__BYTE_ORDER__) && defined(__ORDER_LITTLE_ENDIAN__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    uint64_t v;
    memcpy(&v, p, 8);
    return v;
#else
    return (uint64_t)p[0] | ((uint64_t)p[1] << 8) | ((uint64_t)p[2] << 16) | ((uint64_t)p[3] << 24) |
           ((uint64_t)p[4] << 32) | ((uint64_t)p[5] << 40) | ((uint64_t)p[6] << 48) | ((uint64_t)p[7] << 56);
#endif
}

static uint32_t tn__z_load32le(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

/* Index of the lowest set bit of a non-zero x. */
static unsigned tn__z_ctz64(uint64_t x)
{
#if defined(__GNUC__) || defined(__clang__)
    return (unsigned)__builtin_ctzll(x);
#else
    unsigned n = 0;
    while (!(x & 1u)) { x >>= 1; n++; }
    return n;
#endif
}

/* ---- CRC-32 (zlib's polynomial 0xEDB88320), slicing-by-8 ---- */

static uint32_t tn__crc_tab[8][256];

static void tn__crc_build(void)
{
    uint32_t i, j, c;
    for (i = 0; i < 256; i++) {
        c = i;
        for (j = 0; j < 8; j++) c = (c >> 1) ^ (0xEDB88320u & (0u - (c & 1u)));
        tn__crc_tab[0][i] = c;
    }
    for (i = 0; i < 256; i++) {
        c = tn__crc_tab[0][i];
        for (j = 1; j < 8; j++) {
            c = tn__crc_tab[0][c & 0xffu] ^ (c >> 8);
            tn__crc_tab[j][i] = c;
        }
    }
}

#ifndef TN_NO_THREADS
static pthread_once_t tn__crc_once = PTHREAD_ONCE_INIT;
#else
static int tn__crc_ready;
#endif

/* Standard CRC-32 as zlib's crc32(): start with crc = 0, chain calls over consecutive pieces. */
TN__INTERNAL uint32_t tn__crc32(uint32_t crc, const uint8_t *p, size_t n)
{
#ifndef TN_NO_THREADS
    pthread_once(&tn__crc_once, tn__crc_build);
#else
    if (!tn__crc_ready) { tn__crc_build(); tn__crc_ready = 1; }
#endif
    crc = ~crc;
    while (n >= 8) {
        uint32_t a = crc ^ tn__z_load32le(p), b = tn__z_load32le(p + 4);
        crc = tn__crc_tab[7][a & 0xffu] ^ tn__crc_tab[6][(a >> 8) & 0xffu] ^ tn__crc_tab[5][(a >> 16) & 0xffu] ^
              tn__crc_tab[4][a >> 24] ^ tn__crc_tab[3][b & 0xffu] ^ tn__crc_tab[2][(b >> 8) & 0xffu] ^
              tn__crc_tab[1][(b >> 16) & 0xffu] ^ tn__crc_tab[0][b >> 24];
        p += 8;
        n -= 8;
    }
    while (n--) crc = tn__crc_tab[0][(crc ^ *p++) & 0xffu] ^ (crc >> 8);
    return ~crc;
}

/* Adler-32 as zlib's adler32(): start with a = 1. Sums are reduced every 5552 bytes, the most
   that cannot overflow 32 bits. */
static uint32_t tn__adler32(uint32_t adler, const uint8_t *p, size_t n)
{
    uint32_t a = adler & 0xffffu, b = adler >> 16;
    while (n) {
        size_t k = n < 5552 ? n : 5552;
        n -= k;
        while (k >= 8) {
            a += p[0]; b += a; a += p[1]; b += a; a += p[2]; b += a; a += p[3]; b += a;
            a += p[4]; b += a; a += p[5]; b += a; a += p[6]; b += a; a += p[7]; b += a;
            p += 8;
            k -= 8;
        }
        while (k--) { a += *p++; b += a; }
        a %= 65521u;
        b %= 65521u;
    }
    return (b << 16) | a;
}

/* ---- deflate tables shared by inflate and deflate ---- */

static const uint16_t tn__z_len_base[29] = {3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31, 35, 43, 51, 59,
                                            67, 83, 99, 115, 131, 163, 195, 227, 258};
static const uint8_t tn__z_len_extra[29] = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3,
                                            4, 4, 4, 4, 5, 5, 5, 5, 0};
static const uint16_t tn__z_dist_base[30] = {1, 2, 3, 4, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129, 193,
                                             257, 385, 513, 769, 1025, 1537, 2049, 3073, 4097, 6145,
                                             8193, 12289, 16385, 24577};
static const uint8_t tn__z_dist_extra[30] = {0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6,
                                             7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13};
/* Order in which code length code lengths are sent. */
static const uint8_t tn__z_clen_order[19] = {16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15};

static unsigned tn__z_reverse(unsigned code, unsigned len)
{
    unsigned r = 0;
    while (len--) { r = (r << 1) | (code & 1u); code >>= 1; }
    return r;
}

/* Lengths of the fixed literal/length (0..287) and distance (288..319) codes. */
static void tn__z_fixed_lengths(uint8_t *lens)
{
    int i;
    for (i = 0; i < 144; i++) lens[i] = 8;
    for (; i < 256; i++) lens[i] = 9;
    for (; i < 280; i++) lens[i] = 7;
    for (; i < 288; i++) lens[i] = 8;
    for (; i < 320; i++) lens[i] = 5;
}

/* ---- inflate ----
   A table entry is (value << 16) | (extra << 8) | (kind << 5) | nbits: nbits = bits the code
   takes at this level; for a SUB entry extra = index bits of the subtable and value its offset. */

#define TN__Z_LIT_ROOT 10
#define TN__Z_DIST_ROOT 8
#define TN__Z_LIT_TABLE ((1 << TN__Z_LIT_ROOT) + 288 * (1 << (15 - TN__Z_LIT_ROOT)))
#define TN__Z_DIST_TABLE ((1 << TN__Z_DIST_ROOT) + 32 * (1 << (15 - TN__Z_DIST_ROOT)))
#define TN__Z_SLACK 16 /* spare output bytes so match copies may run 8 bytes at a time */

enum { TN__ZK_LIT = 0, TN__ZK_LEN = 1, TN__ZK_EOB = 2, TN__ZK_SUB = 3, TN__ZK_BAD = 4 };
#define TN__ZE(kind, extra, value) (((uint32_t)(value) << 16) | ((uint32_t)(extra) << 8) | ((uint32_t)(kind) << 5))

typedef struct tn__inflate {
    const uint8_t *in, *in_end; /* next unread byte, end of input */
    uint64_t bits;              /* bit buffer, LSB first */
    unsigned nbits;             /* valid bits in `bits` */
    unsigned overrun;           /* zero bytes fed past the end of input */
    const char *what;           /* message prefix: "zlib" or "<file>: IDAT" */
    uint8_t *out;               /* output, cap + TN__Z_SLACK bytes allocated */
    size_t len, cap, max;
    uint32_t lit_payload[288], dist_payload[32], clen_payload[19];
    uint32_t lit[TN__Z_LIT_TABLE];
    uint32_t dist[TN__Z_DIST_TABLE];
    uint32_t clen[1 << 7];
} tn__inflate;

static void tn__z_init_payloads(tn__inflate *s)
{
    int i;
    for (i = 0; i < 256; i++) s->lit_payload[i] = TN__ZE(TN__ZK_LIT, 0, i);
    s->lit_payload[256] = TN__ZE(TN__ZK_EOB, 0, 0);
    for (i = 0; i < 29; i++) s->lit_payload[257 + i] = TN__ZE(TN__ZK_LEN, tn__z_len_extra[i], tn__z_len_base[i]);
    s->lit_payload[286] = s->lit_payload[287] = TN__ZE(TN__ZK_BAD, 0, 0);
    for (i = 0; i < 30; i++) s->dist_payload[i] = TN__ZE(TN__ZK_LEN, tn__z_dist_extra[i], tn__z_dist_base[i]);
    s->dist_payload[30] = s->dist_payload[31] = TN__ZE(TN__ZK_BAD, 0, 0);
    for (i = 0; i < 19; i++) s->clen_payload[i] = TN__ZE(TN__ZK_LIT, 0, i);
}

/* Builds a two-level decoding table from canonical code lengths (0 = unused symbol). Returns 0,
   or -1 for an over-subscribed code or an incomplete one (zlib's rule: a lone 1-bit code, or no
   code at all, is allowed where `allow_single`). Subtables all have maxlen - root index bits. */
static int tn__z_build(uint32_t *table, unsigned root, const uint8_t *lens, unsigned n, const uint32_t *payload,
                       int allow_single)
{
    unsigned count[16], next[16], offs[16], len, sym, maxlen = 0, i, k, sub_bits = 0;
    uint16_t sorted[320];
    int left = 1;
    uint32_t code, prefix, cur_prefix = 0xffffffffu, sub_base = 0, sub_off = 1u << root;
    memset(count, 0, sizeof count);
    for (sym = 0; sym < n; sym++) count[lens[sym]]++;
    count[0] = 0;
    for (len = 1; len <= 15; len++) {
        left = left * 2 - (int)count[len];
        if (left < 0) return -1;
        if (count[len]) maxlen = len;
    }
    if (left > 0 && !(allow_single && maxlen <= 1)) return -1;
    for (i = 0; i < (1u << root); i++) table[i] = TN__ZE(TN__ZK_BAD, 0, 0);
    offs[1] = 0;
    for (len = 1; len < 15; len++) offs[len + 1] = offs[len] + count[len];
    for (sym = 0; sym < n; sym++)
        if (lens[sym]) sorted[offs[lens[sym]]++] = (uint16_t)sym;
    code = 0;
    next[0] = 0;
    for (len = 1; len <= 15; len++) {
        code = (code + count[len - 1]) << 1;
        next[len] = code;
    }
    for (k = 0, len = 1; len <= 15; len++) {
        for (i = 0; i < count[len]; i++, k++) {
            uint32_t entry;
            sym = sorted[k];
            code = next[len]++;
            entry = payload[sym];
            if (len <= root) {
                unsigned r = tn__z_reverse(code, len);
                for (; r < (1u << root); r += 1u << len) table[r] = entry | len;
            } else {
                unsigned r, sl = len - root;
                prefix = code >> sl;
                if (prefix != cur_prefix) { /* codes sharing a root prefix are consecutive */
                    unsigned j;
                    cur_prefix = prefix;
                    sub_bits = maxlen - root;
                    sub_base = sub_off;
                    sub_off += 1u << sub_bits;
                    for (j = 0; j < (1u << sub_bits); j++) table[sub_base + j] = TN__ZE(TN__ZK_BAD, 0, 0);
                    table[tn__z_reverse(prefix, root)] = TN__ZE(TN__ZK_SUB, sub_bits, sub_base) | root;
                }
                r = tn__z_reverse(code & ((1u << sl) - 1u), sl);
                for (; r < (1u << sub_bits); r += 1u << sl) table[sub_base + r] = entry | sl;
            }
        }
    }
    return 0;
}

/* Fills the bit buffer to at least 56 bits; past the end of input zero bytes are fed and
   counted, so a truncated stream fails at the end (or here, once it is hopeless). */
static int tn__z_refill(tn__inflate *s)
{
    if (s->in_end - s->in >= 8) {
        s->bits |= tn__z_load64le(s->in) << s->nbits;
        s->in += (63 - s->nbits) >> 3;
        s->nbits |= 56;
        return 0;
    }
    while (s->nbits <= 56) {
        if (s->in < s->in_end) s->bits |= (uint64_t)*s->in++ << s->nbits;
        else s->overrun++;
        s->nbits += 8;
    }
    return s->overrun > 16 ? -1 : 0;
}

static uint32_t tn__z_getbits(tn__inflate *s, unsigned n)
{
    uint32_t v = (uint32_t)(s->bits & ((1u << n) - 1u));
    s->bits >>= n;
    s->nbits -= n;
    return v;
}

/* Drops bits to the next byte boundary and hands the whole bytes in the bit buffer back to the
   input, so stored blocks and the trailer can be read bytewise. Returns -1 if past the end. */
static int tn__z_align(tn__inflate *s)
{
    unsigned nbytes;
    s->bits >>= s->nbits & 7u;
    s->nbits -= s->nbits & 7u;
    nbytes = s->nbits >> 3;
    if (s->overrun > nbytes) return -1;
    s->in -= nbytes - s->overrun;
    s->bits = 0;
    s->nbits = 0;
    s->overrun = 0;
    return 0;
}

static tn_status tn__z_grow(tn__inflate *s, size_t need)
{
    size_t ncap;
    uint8_t *p;
    if (need > s->max) return tn__fail(TN_ERR_TOO_LARGE, "%s: data inflates beyond the %zu byte limit", s->what, s->max);
    ncap = s->cap ? s->cap : 4096;
    while (ncap < need) ncap = ncap > s->max / 2 ? s->max : ncap * 2;
    if (ncap > s->max) ncap = s->max;
    p = (uint8_t *)TN_REALLOC(s->out, ncap + TN__Z_SLACK);
    if (!p) return tn__fail(TN_ERR_OUT_OF_MEMORY, "%s: out of memory growing the output to %zu bytes", s->what, ncap);
    s->out = p;
    s->cap = ncap;
    return TN_OK;
}

/* Decodes one Huffman-coded block with the tables in s->lit / s->dist. The hot loop keeps the
   bit buffer and output position in locals (stores through `out` would otherwise force reloads),
   and after a literal tries a second one without refilling. */
static tn_status tn__z_codes(tn__inflate *s)
{
    const uint32_t *lit = s->lit, *dist = s->dist;
    const uint8_t *in = s->in, *in_end = s->in_end;
    uint64_t bits = s->bits;
    unsigned nbits = s->nbits, overrun = s->overrun;
    uint8_t *out = s->out;
    size_t olen = s->len, cap = s->cap;
    uint32_t e, extra, length, d;
    tn_status st = TN_OK;
    for (;;) {
        if (nbits < 48) {
            if (in_end - in >= 8) {
                bits |= tn__z_load64le(in) << nbits;
                in += (63 - nbits) >> 3;
                nbits |= 56;
            } else {
                while (nbits <= 56) {
                    if (in < in_end) bits |= (uint64_t)*in++ << nbits;
                    else overrun++;
                    nbits += 8;
                }
                if (overrun > 16) { st = tn__fail(TN_ERR_CORRUPT, "%s: compressed data is truncated", s->what); break; }
            }
        }
        e = lit[bits & ((1u << TN__Z_LIT_ROOT) - 1u)];
        if (((e >> 5) & 7u) == TN__ZK_SUB) {
            bits >>= TN__Z_LIT_ROOT;
            nbits -= TN__Z_LIT_ROOT;
            e = lit[(e >> 16) + (bits & ((1u << ((e >> 8) & 31u)) - 1u))];
        }
        bits >>= e & 31u;
        nbits -= e & 31u;
        if (((e >> 5) & 7u) == TN__ZK_LIT) {
            if (olen + 2 > cap) {
                s->len = olen;
                if ((st = tn__z_grow(s, olen + 1)) != TN_OK) break;
                out = s->out;
                cap = s->cap;
            }
            out[olen++] = (uint8_t)(e >> 16);
            /* >= 33 bits remain: a second root-level literal needs no refill */
            e = lit[bits & ((1u << TN__Z_LIT_ROOT) - 1u)];
            if ((e & (7u << 5)) == (TN__ZK_LIT << 5) && olen < cap) {
                bits >>= e & 31u;
                nbits -= e & 31u;
                out[olen++] = (uint8_t)(e >> 16);
            }
            continue;
        }
        if (((e >> 5) & 7u) == TN__ZK_EOB) break;
        if (((e >> 5) & 7u) != TN__ZK_LEN) { st = tn__fail(TN_ERR_CORRUPT, "%s: invalid Huffman code", s->what); break; }
        extra = (e >> 8) & 31u;
        length = (e >> 16) + (uint32_t)(bits & ((1u << extra) - 1u));
        bits >>= extra;
        nbits -= extra;
        e = dist[bits & ((1u << TN__Z_DIST_ROOT) - 1u)];
        if (((e >> 5) & 7u) == TN__ZK_SUB) {
            bits >>= TN__Z_DIST_ROOT;
            nbits -= TN__Z_DIST_ROOT;
            e = dist[(e >> 16) + (bits & ((1u << ((e >> 8) & 31u)) - 1u))];
        }
        bits >>= e & 31u;
        nbits -= e & 31u;
        if (((e >> 5) & 7u) != TN__ZK_LEN) { st = tn__fail(TN_ERR_CORRUPT, "%s: invalid Huffman code", s->what); break; }
        extra = (e >> 8) & 31u;
        d = (e >> 16) + (uint32_t)(bits & ((1u << extra) - 1u));
        bits >>= extra;
        nbits -= extra;
        if (d > olen) {
            st = tn__fail(TN_ERR_CORRUPT, "%s: match distance %u reaches before the start of the data", s->what, (unsigned)d);
            break;
        }
        if (length > cap - olen) {
            s->len = olen;
            if ((st = tn__z_grow(s, olen + length)) != TN_OK) break;
            out = s->out;
            cap = s->cap;
        }
        {
            uint8_t *dst = out + olen;
            const uint8_t *src = dst - d;
            uint32_t i;
            if (d >= 8) { /* chunks of 8 never read bytes they write; overshoot lands in the slack */
                for (i = 0; i < length; i += 8) memcpy(dst + i, src + i, 8);
            } else if (d == 1) {
                memset(dst, src[0], length);
            } else {
                for (i = 0; i < length; i++) dst[i] = src[i];
            }
            olen += length;
        }
    }
    s->in = in;
    s->bits = bits;
    s->nbits = nbits;
    s->overrun = overrun;
    s->len = olen;
    return st;
}

/* Reads a dynamic block header (RFC 1951 3.2.7) and builds the tables. */
static tn_status tn__z_dynamic(tn__inflate *s)
{
    uint8_t lens[320], clens[19];
    unsigned hlit, hdist, hclen, i, n;
    if (tn__z_refill(s)) goto truncated;
    hlit = tn__z_getbits(s, 5) + 257;
    hdist = tn__z_getbits(s, 5) + 1;
    hclen = tn__z_getbits(s, 4) + 4;
    if (hlit > 286 || hdist > 30) return tn__fail(TN_ERR_CORRUPT, "%s: too many length or distance codes", s->what);
    memset(clens, 0, sizeof clens);
    for (i = 0; i < hclen; i++) {
        if (s->nbits < 3 && tn__z_refill(s)) goto truncated;
        clens[tn__z_clen_order[i]] = (uint8_t)tn__z_getbits(s, 3);
    }
    if (tn__z_build(s->clen, 7, clens, 19, s->clen_payload, 0))
        return tn__fail(TN_ERR_CORRUPT, "%s: invalid code length code", s->what);
    n = 0;
    while (n < hlit + hdist) {
        uint32_t e, sym, rep, val;
        if (s->nbits < 16 && tn__z_refill(s)) goto truncated;
        e = s->clen[s->bits & 127u];
        if (((e >> 5) & 7u) != TN__ZK_LIT) return tn__fail(TN_ERR_CORRUPT, "%s: invalid code length code", s->what);
        s->bits >>= e & 31u;
        s->nbits -= e & 31u;
        sym = e >> 16;
        if (sym < 16) {
            lens[n++] = (uint8_t)sym;
            continue;
        }
        if (sym == 16) {
            if (n == 0) return tn__fail(TN_ERR_CORRUPT, "%s: repeated code length with no previous length", s->what);
            val = lens[n - 1];
            rep = 3 + tn__z_getbits(s, 2);
        } else if (sym == 17) {
            val = 0;
            rep = 3 + tn__z_getbits(s, 3);
        } else {
            val = 0;
            rep = 11 + tn__z_getbits(s, 7);
        }
        if (n + rep > hlit + hdist) return tn__fail(TN_ERR_CORRUPT, "%s: code lengths overflow the table", s->what);
        while (rep--) lens[n++] = (uint8_t)val;
    }
    if (lens[256] == 0) return tn__fail(TN_ERR_CORRUPT, "%s: block has no end-of-block code", s->what);
    if (tn__z_build(s->lit, TN__Z_LIT_ROOT, lens, hlit, s->lit_payload, 1))
        return tn__fail(TN_ERR_CORRUPT, "%s: invalid literal/length code lengths", s->what);
    if (tn__z_build(s->dist, TN__Z_DIST_ROOT, lens + hlit, hdist, s->dist_payload, 1))
        return tn__fail(TN_ERR_CORRUPT, "%s: invalid distance code lengths", s->what);
    return TN_OK;
truncated:
    return tn__fail(TN_ERR_CORRUPT, "%s: compressed data is truncated", s->what);
}

/* Runs a whole zlib stream (header, blocks, Adler-32) into s->out (which may be preallocated
   with cap == max, as the PNG decoder does). */
static tn_status tn__z_inflate_run(tn__inflate *s, const uint8_t *src, size_t n)
{
    unsigned final = 0, type;
    tn_status st;
    uint8_t fixed[320];
    if (n < 2) return tn__fail(TN_ERR_CORRUPT, "%s: stream is truncated", s->what);
    if ((src[0] & 15u) != 8 || (src[0] >> 4) > 7 || ((unsigned)src[0] * 256u + src[1]) % 31u != 0)
        return tn__fail(TN_ERR_CORRUPT, "%s: bad stream header", s->what);
    if (src[1] & 32u) return tn__fail(TN_ERR_CORRUPT, "%s: preset dictionaries are not supported", s->what);
    tn__z_init_payloads(s);
    s->in = src + 2;
    s->in_end = src + n;
    s->bits = 0;
    s->nbits = 0;
    s->overrun = 0;
    while (!final) {
        if (tn__z_refill(s)) return tn__fail(TN_ERR_CORRUPT, "%s: compressed data is truncated", s->what);
        final = tn__z_getbits(s, 1);
        type = tn__z_getbits(s, 2);
        if (type == 0) {
            size_t blen, nlen;
            if (tn__z_align(s) || s->in_end - s->in < 4) return tn__fail(TN_ERR_CORRUPT, "%s: compressed data is truncated", s->what);
            blen = (size_t)s->in[0] | ((size_t)s->in[1] << 8);
            nlen = (size_t)s->in[2] | ((size_t)s->in[3] << 8);
            s->in += 4;
            if (blen != (~nlen & 0xffffu)) return tn__fail(TN_ERR_CORRUPT, "%s: stored block length check failed", s->what);
            if ((size_t)(s->in_end - s->in) < blen) return tn__fail(TN_ERR_CORRUPT, "%s: compressed data is truncated", s->what);
            if (blen > s->cap - s->len && (st = tn__z_grow(s, s->len + blen)) != TN_OK) return st;
            memcpy(s->out + s->len, s->in, blen);
            s->len += blen;
            s->in += blen;
        } else if (type == 1) {
            tn__z_fixed_lengths(fixed);
            tn__z_build(s->lit, TN__Z_LIT_ROOT, fixed, 288, s->lit_payload, 0);
            tn__z_build(s->dist, TN__Z_DIST_ROOT, fixed + 288, 32, s->dist_payload, 0);
            if ((st = tn__z_codes(s)) != TN_OK) return st;
        } else if (type == 2) {
            if ((st = tn__z_dynamic(s)) != TN_OK) return st;
            if ((st = tn__z_codes(s)) != TN_OK) return st;
        } else {
            return tn__fail(TN_ERR_CORRUPT, "%s: invalid block type 3", s->what);
        }
    }
    if (tn__z_align(s) || s->in_end - s->in < 4) return tn__fail(TN_ERR_CORRUPT, "%s: stream is truncated before its checksum", s->what);
    if (tn__png_be32(s->in) != tn__adler32(1, s->out, s->len))
        return tn__fail(TN_ERR_CORRUPT, "%s: Adler-32 checksum mismatch", s->what);
    return TN_OK;
}

/* Inflates a zlib stream into a new TN_MALLOC'ed buffer (caller frees with TN_FREE). Output
   larger than max_out (0 = TN_MAX_ALLOC) fails with TN_ERR_TOO_LARGE. */
TN_API tn_status tn_zlib_inflate(uint8_t **out, size_t *out_size, const uint8_t *src, size_t n, size_t max_out)
{
    tn__inflate *s;
    tn_status st;
    size_t guess;
    *out = NULL;
    *out_size = 0;
    if (max_out == 0 || max_out > TN_MAX_ALLOC) max_out = TN_MAX_ALLOC;
    s = (tn__inflate *)tn__alloc(sizeof *s);
    if (!s) return tn__oom();
    s->what = "zlib";
    s->out = NULL;
    s->len = s->cap = 0;
    s->max = max_out;
    guess = n < ((size_t)1 << 28) ? n * 4 : ((size_t)1 << 30);
    if (guess < 4096) guess = 4096;
    if (guess > max_out) guess = max_out;
    st = tn__z_grow(s, guess);
    if (st == TN_OK) st = tn__z_inflate_run(s, src, n);
    if (st == TN_OK) {
        *out = s->out;
        *out_size = s->len;
    } else {
        TN_FREE(s->out);
    }
    TN_FREE(s);
    return st;
}

/* ---- deflate ---- */

#define TN__Z_WSIZE 32768u
#define TN__Z_HASH_BITS 15
#define TN__Z_BLOCK_SYMS 16383u /* zlib's literal buffer at memLevel 8 */

typedef struct tn__deflate {
    const uint8_t *src;
    size_t n;
    size_t *head;           /* per hash: last position + 1 (0 = none) */
    uint16_t *prev;         /* per position mod WSIZE: distance to the previous same-hash position, 0 = none */
    uint16_t *sym_len;      /* literal byte (sym_dist == 0) or match length 3..258 */
    uint16_t *sym_dist;
    size_t nsym, block_start, covered;
    uint32_t lfreq[288], dfreq[30];
    uint8_t *out;
    size_t olen, ocap;
    uint64_t bits;
    unsigned nbits;
    unsigned good, lazy, nice, chain;
    unsigned hash_shift;    /* 32 - hash bits; small inputs use small tables */
    uint8_t len_code[259];  /* match length -> length code 0..28 */
    uint8_t dist_code[512]; /* (d-1) < 256 ? [d-1] : [256 + ((d-1) >> 7)] -> distance code */
} tn__deflate;

static unsigned tn__z_dcode(const tn__deflate *s, unsigned d)
{
    return d <= 256 ? s->dist_code[d - 1] : s->dist_code[256 + ((d - 1) >> 7)];
}

static void tn__z_put(tn__deflate *s, uint32_t v, unsigned n)
{
    s->bits |= (uint64_t)v << s->nbits;
    s->nbits += n;
    if (s->nbits >= 32) {
        uint8_t *o = s->out + s->olen;
        o[0] = (uint8_t)s->bits;
        o[1] = (uint8_t)(s->bits >> 8);
        o[2] = (uint8_t)(s->bits >> 16);
        o[3] = (uint8_t)(s->bits >> 24);
        s->olen += 4;
        s->bits >>= 32;
        s->nbits -= 32;
    }
}

/* Writes out pending bits, zero-padding to a byte boundary. */
static void tn__z_put_align(tn__deflate *s)
{
    while (s->nbits > 0) {
        s->out[s->olen++] = (uint8_t)s->bits;
        s->bits >>= 8;
        s->nbits = s->nbits > 8 ? s->nbits - 8 : 0;
    }
    s->bits = 0;
}

/* Moffat-Katajainen in-place minimum-redundancy code lengths: a[] holds n >= 2 weights sorted
   ascending and on return the code length of each. */
static void tn__z_moffat(uint32_t *a, int n)
{
    int root, leaf, next, avbl, used, dpth;
    a[0] += a[1];
    root = 0;
    leaf = 2;
    for (next = 1; next < n - 1; next++) {
        if (leaf >= n || a[root] < a[leaf]) { a[next] = a[root]; a[root++] = (uint32_t)next; }
        else a[next] = a[leaf++];
        if (leaf >= n || (root < next && a[root] < a[leaf])) { a[next] += a[root]; a[root++] = (uint32_t)next; }
        else a[next] += a[leaf++];
    }
    a[n - 2] = 0;
    for (next = n - 3; next >= 0; next--) a[next] = a[a[next]] + 1;
    avbl = 1;
    used = dpth = 0;
    root = n - 2;
    next = n - 1;
    while (avbl > 0) {
        while (root >= 0 && (int)a[root] == dpth) { used++; root--; }
        while (avbl > used) { a[next--] = (uint32_t)dpth; avbl--; }
        avbl = 2 * used;
        dpth++;
        used = 0;
    }
}

static int tn__z_cmp_u64(const void *a, const void *b)
{
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return x < y ? -1 : (x > y);
}

/* Huffman code lengths for freq[0..n-1], at most maxbits long. At least two symbols get codes
   (as zlib does) so every code is complete. */
static void tn__z_huff_lengths(const uint32_t *freq, unsigned n, unsigned maxbits, uint8_t *lens)
{
    uint64_t keys[320];
    uint32_t w[320];
    unsigned count[321], m = 0, i, len, k;
    uint32_t total;
    memset(lens, 0, n);
    for (i = 0; i < n; i++)
        if (freq[i]) keys[m++] = ((uint64_t)freq[i] << 16) | i;
    for (i = 0; m < 2 && i < n; i++) /* dummy symbols of weight 0 to reach two codes */
        if (!freq[i]) keys[m++] = i;
    if (m < 2) { lens[0] = 1; return; }
    qsort(keys, m, sizeof keys[0], tn__z_cmp_u64);
    for (i = 0; i < m; i++) w[i] = (uint32_t)(keys[i] >> 16);
    tn__z_moffat(w, (int)m);
    memset(count, 0, sizeof count);
    for (i = 0; i < m; i++) count[w[i]]++;
    for (len = maxbits + 1; len <= 320; len++) { count[maxbits] += count[len]; count[len] = 0; }
    total = 0;
    for (len = maxbits; len > 0; len--) total += (uint32_t)count[len] << (maxbits - len);
    while (total > (1u << maxbits)) { /* lengthen a shorter code to make room */
        count[maxbits]--;
        for (len = maxbits - 1; len > 0; len--)
            if (count[len]) { count[len]--; count[len + 1] += 2; break; }
        total--;
    }
    for (k = 0, len = maxbits; len > 0; len--) /* least frequent symbols get the longest codes */
        for (i = 0; i < count[len]; i++) lens[keys[k++] & 0xffffu] = (uint8_t)len;
}

/* Canonical codes, bit-reversed for LSB-first output. */
static void tn__z_make_codes(const uint8_t *lens, unsigned n, uint16_t *codes)
{
    unsigned count[16], next[16], i, code = 0;
    memset(count, 0, sizeof count);
    for (i = 0; i < n; i++) count[lens[i]]++;
    count[0] = 0;
    for (i = 1; i < 16; i++) { code = (code + count[i - 1]) << 1; next[i] = code; }
    for (i = 0; i < n; i++)
        codes[i] = lens[i] ? (uint16_t)tn__z_reverse(next[lens[i]]++, lens[i]) : 0;
}

/* Run-length codes (16/17/18) for a code length sequence; returns the count. */
static unsigned tn__z_rle(const uint8_t *lens, unsigned n, uint8_t *sym, uint8_t *ext, uint32_t *freq)
{
    unsigned i = 0, m = 0, run, r;
    while (i < n) {
        unsigned cur = lens[i];
        run = 1;
        while (i + run < n && lens[i + run] == cur) run++;
        i += run;
        if (cur == 0) {
            while (run >= 11) { r = run < 138 ? run : 138; sym[m] = 18; ext[m++] = (uint8_t)(r - 11); run -= r; }
            if (run >= 3) { sym[m] = 17; ext[m++] = (uint8_t)(run - 3); run = 0; }
        } else {
            sym[m] = (uint8_t)cur; ext[m++] = 0;
            run--;
            while (run >= 3) { r = run < 6 ? run : 6; sym[m] = 16; ext[m++] = (uint8_t)(r - 3); run -= r; }
        }
        while (run--) { sym[m] = (uint8_t)cur; ext[m++] = 0; }
    }
    for (i = 0; i < m; i++) freq[sym[i]]++;
    return m;
}

static void tn__z_write_syms(tn__deflate *s, const uint16_t *lcode, const uint8_t *llen, const uint16_t *dcode,
                             const uint8_t *dlen)
{
    size_t i;
    for (i = 0; i < s->nsym; i++) {
        unsigned l = s->sym_len[i], d = s->sym_dist[i];
        if (!d) {
            tn__z_put(s, lcode[l], llen[l]);
        } else {
            unsigned lc = s->len_code[l], dc = tn__z_dcode(s, d);
            tn__z_put(s, lcode[257 + lc], llen[257 + lc]);
            if (tn__z_len_extra[lc]) tn__z_put(s, l - tn__z_len_base[lc], tn__z_len_extra[lc]);
            tn__z_put(s, dcode[dc], dlen[dc]);
            if (tn__z_dist_extra[dc]) tn__z_put(s, d - tn__z_dist_base[dc], tn__z_dist_extra[dc]);
        }
    }
    tn__z_put(s, lcode[256], llen[256]);
}

/* Emits the symbols gathered since block_start as one block (or several stored ones), choosing
   the smallest of dynamic, fixed and stored. */
static tn_status tn__z_flush_block(tn__deflate *s, int final)
{
    uint8_t llen[288], dlen[30], clen[19], rsym[320], rext[320], fixed[320];
    uint16_t lcode[288], dcode[30], ccode[19];
    uint32_t cfreq[19];
    unsigned nl, nd, nc, nr, i;
    uint64_t extra_bits = 0, dyn, fix, stored;
    size_t span = s->covered - s->block_start, chunks, need;
    tn_status st;

    s->lfreq[256] = 1;
    tn__z_huff_lengths(s->lfreq, 286, 15, llen);
    llen[286] = llen[287] = 0;
    tn__z_huff_lengths(s->dfreq, 30, 15, dlen);
    for (nl = 286; nl > 257 && !llen[nl - 1]; nl--) {}
    for (nd = 30; nd > 1 && !dlen[nd - 1]; nd--) {}
    memset(cfreq, 0, sizeof cfreq);
    nr = tn__z_rle(llen, nl, rsym, rext, cfreq);
    nr += tn__z_rle(dlen, nd, rsym + nr, rext + nr, cfreq);
    tn__z_huff_lengths(cfreq, 19, 7, clen);
    for (nc = 19; nc > 4 && !clen[tn__z_clen_order[nc - 1]]; nc--) {}

    tn__z_fixed_lengths(fixed);
    for (i = 0; i < 29; i++) extra_bits += (uint64_t)s->lfreq[257 + i] * tn__z_len_extra[i];
    for (i = 0; i < 30; i++) extra_bits += (uint64_t)s->dfreq[i] * tn__z_dist_extra[i];
    dyn = 3 + 14 + 3 * (uint64_t)nc + extra_bits;
    fix = 3 + extra_bits;
    for (i = 0; i < 286; i++) {
        dyn += (uint64_t)s->lfreq[i] * llen[i];
        fix += (uint64_t)s->lfreq[i] * fixed[i];
    }
    for (i = 0; i < 30; i++) {
        dyn += (uint64_t)s->dfreq[i] * dlen[i];
        fix += (uint64_t)s->dfreq[i] * 5;
    }
    for (i = 0; i < nr; i++) dyn += clen[rsym[i]] + (rsym[i] == 16 ? 2 : rsym[i] == 17 ? 3 : rsym[i] == 18 ? 7 : 0);
    chunks = span ? (span + 65534) / 65535 : 1;
    stored = 10 + (uint64_t)chunks * 40 + (uint64_t)span * 8;

    need = s->olen + span + chunks * 5 + 1024; /* stored size bounds the choice below */
    if ((st = tn__reserve((void **)&s->out, &s->ocap, need)) != TN_OK) return st;

    if (stored <= dyn && stored <= fix) {
        const uint8_t *p = s->src + s->block_start;
        size_t left = span, c;
        do {
            c = left < 65535 ? left : 65535;
            left -= c;
            tn__z_put(s, (final && !left) ? 1u : 0u, 1);
            tn__z_put(s, 0, 2);
            tn__z_put_align(s);
            s->out[s->olen++] = (uint8_t)c;
            s->out[s->olen++] = (uint8_t)(c >> 8);
            s->out[s->olen++] = (uint8_t)~c;
            s->out[s->olen++] = (uint8_t)(~c >> 8);
            memcpy(s->out + s->olen, p, c);
            s->olen += c;
            p += c;
        } while (left);
    } else if (fix <= dyn) {
        uint16_t fcode[320];
        tn__z_make_codes(fixed, 288, fcode);
        tn__z_make_codes(fixed + 288, 30, fcode + 288);
        tn__z_put(s, final ? 1u : 0u, 1);
        tn__z_put(s, 1, 2);
        tn__z_write_syms(s, fcode, fixed, fcode + 288, fixed + 288);
    } else {
        tn__z_make_codes(llen, 288, lcode);
        tn__z_make_codes(dlen, 30, dcode);
        tn__z_make_codes(clen, 19, ccode);
        tn__z_put(s, final ? 1u : 0u, 1);
        tn__z_put(s, 2, 2);
        tn__z_put(s, nl - 257, 5);
        tn__z_put(s, nd - 1, 5);
        tn__z_put(s, nc - 4, 4);
        for (i = 0; i < nc; i++) tn__z_put(s, clen[tn__z_clen_order[i]], 3);
        for (i = 0; i < nr; i++) {
            tn__z_put(s, ccode[rsym[i]], clen[rsym[i]]);
            if (rsym[i] >= 16) tn__z_put(s, rext[i], rsym[i] == 16 ? 2u : rsym[i] == 17 ? 3u : 7u);
        }
        tn__z_write_syms(s, lcode, llen, dcode, dlen);
    }
    memset(s->lfreq, 0, sizeof s->lfreq);
    memset(s->dfreq, 0, sizeof s->dfreq);
    s->nsym = 0;
    s->block_start = s->covered;
    return TN_OK;
}

static void tn__z_tally_lit(tn__deflate *s, unsigned c)
{
    s->sym_len[s->nsym] = (uint16_t)c;
    s->sym_dist[s->nsym++] = 0;
    s->lfreq[c]++;
    s->covered++;
}

static void tn__z_tally_match(tn__deflate *s, unsigned len, unsigned dist)
{
    s->sym_len[s->nsym] = (uint16_t)len;
    s->sym_dist[s->nsym++] = (uint16_t)dist;
    s->lfreq[257 + s->len_code[len]]++;
    s->dfreq[tn__z_dcode(s, dist)]++;
    s->covered += len;
}

/* Adds position p (p + 3 <= n) to its hash chain; returns the previous head (position + 1). */
static size_t tn__z_insert(tn__deflate *s, size_t p)
{
    const uint8_t *q = s->src + p;
    uint32_t h = ((((uint32_t)q[0] << 16) | ((uint32_t)q[1] << 8) | q[2]) * 2654435761u) >> s->hash_shift;
    size_t cand = s->head[h];
    s->head[h] = p + 1;
    s->prev[p & (TN__Z_WSIZE - 1)] = (uint16_t)((cand && p - (cand - 1) < TN__Z_WSIZE) ? p - (cand - 1) : 0);
    return cand;
}

/* Longest match for position p along the chain starting at cand (position + 1), if longer than
   `best`; returns its length (0 if none is longer) and distance. */
static unsigned tn__z_longest(const tn__deflate *s, size_t p, size_t cand, unsigned best, unsigned *dist_out)
{
    const uint8_t *cur = s->src + p;
    size_t avail = s->n - p;
    unsigned maxlen = avail < 258 ? (unsigned)avail : 258u, nice = s->nice, chain = s->chain, found = 0;
    size_t c = cand - 1;
    if (best >= s->good) chain >>= 2;
    if (nice > maxlen) nice = maxlen;
    if (best >= maxlen) return 0;
    while (chain--) {
        size_t d = p - c;
        const uint8_t *m = s->src + c;
        unsigned pd;
        if (d >= TN__Z_WSIZE) break;
        if (m[best] == cur[best] && m[0] == cur[0] && m[1] == cur[1]) {
            unsigned l = 0;
            while (l + 8 <= maxlen) {
                uint64_t x = tn__z_load64le(m + l) ^ tn__z_load64le(cur + l);
                if (x) { l += tn__z_ctz64(x) >> 3; goto counted; }
                l += 8;
            }
            while (l < maxlen && m[l] == cur[l]) l++;
        counted:
            if (l > best) {
                best = found = l;
                *dist_out = (unsigned)d;
                if (l >= nice) break;
            }
        }
        pd = s->prev[c & (TN__Z_WSIZE - 1)];
        if (!pd || pd > c) break;
        c -= pd;
    }
    return found;
}

static void tn__z_level_params(tn__deflate *s, int level)
{
    /* zlib's configuration_table: good, lazy (greedy levels: max insert length), nice, chain */
    static const unsigned cfg[10][4] = {{8, 16, 128, 128}, {4, 4, 8, 4}, {4, 5, 16, 8}, {4, 6, 32, 32},
                                        {4, 4, 16, 16}, {8, 16, 32, 32}, {8, 16, 128, 128}, {8, 32, 128, 256},
                                        {32, 128, 258, 1024}, {32, 258, 258, 4096}};
    s->good = cfg[level][0];
    s->lazy = cfg[level][1];
    s->nice = cfg[level][2];
    s->chain = cfg[level][3];
}

/* Greedy parse (zlib's deflate_fast): take the first good match, insert its positions only if short. */
static tn_status tn__z_parse_greedy(tn__deflate *s)
{
    size_t p = 0, n = s->n, q, cand;
    unsigned len, dist = 0;
    tn_status st;
    while (p < n) {
        len = 0;
        if (p + 3 <= n) {
            cand = tn__z_insert(s, p);
            if (cand) {
                len = tn__z_longest(s, p, cand, 2, &dist);
                if (len == 3 && dist > 4096) len = 0;
            }
        }
        if (len >= 3) {
            tn__z_tally_match(s, len, dist);
            if (len <= s->lazy)
                for (q = p + 1; q < p + len && q + 3 <= n; q++) tn__z_insert(s, q);
            p += len;
        } else {
            tn__z_tally_lit(s, s->src[p]);
            p++;
        }
        if (s->nsym >= TN__Z_BLOCK_SYMS && (st = tn__z_flush_block(s, 0)) != TN_OK) return st;
    }
    return TN_OK;
}

/* Lazy parse (zlib's deflate_slow): a match at p is emitted only if p + 1 has no longer one. */
static tn_status tn__z_parse_lazy(tn__deflate *s)
{
    size_t p = 0, n = s->n, q, end, cand;
    unsigned prev_len = 0, prev_dist = 0, cur_len, cur_dist = 0;
    int pending = 0; /* src[p - 1] is not yet emitted */
    tn_status st;
    while (p < n) {
        cur_len = 0;
        if (p + 3 <= n) {
            cand = tn__z_insert(s, p);
            if (cand && prev_len < s->lazy) {
                cur_len = tn__z_longest(s, p, cand, prev_len > 2 ? prev_len : 2, &cur_dist);
                if (cur_len == 3 && cur_dist > 4096) cur_len = 0;
            }
        }
        if (prev_len >= 3 && cur_len <= prev_len) {
            tn__z_tally_match(s, prev_len, prev_dist);
            end = p - 1 + prev_len;
            for (q = p + 1; q < end && q + 3 <= n; q++) tn__z_insert(s, q);
            p = end;
            pending = 0;
            prev_len = 0;
        } else {
            if (pending) tn__z_tally_lit(s, s->src[p - 1]);
            pending = 1;
            prev_len = cur_len;
            prev_dist = cur_dist;
            p++;
        }
        if (s->nsym >= TN__Z_BLOCK_SYMS && (st = tn__z_flush_block(s, 0)) != TN_OK) return st;
    }
    if (pending) tn__z_tally_lit(s, s->src[n - 1]);
    return TN_OK;
}

/* Compresses src into a zlib stream in a new TN_MALLOC'ed buffer (caller frees with TN_FREE).
   level 1-9 as zlib; 0 (or out of range) means 6. */
TN_API tn_status tn_zlib_deflate(uint8_t **out, size_t *out_size, const uint8_t *src, size_t n, int level)
{
    tn__deflate *s;
    tn_status st = TN_OK;
    unsigned i, d, code;
    uint32_t adler;
    *out = NULL;
    *out_size = 0;
    if (level < -1 || level > 9) return tn__fail(TN_ERR_INVALID_ARG, "deflate: level %d (0-9; 0 and zlib's -1 = 6)", level);
    if (!src && n) return tn__fail(TN_ERR_INVALID_ARG, "deflate: NULL input");
    if (level <= 0) level = 6;
    s = (tn__deflate *)tn__calloc(sizeof *s);
    if (!s) return tn__oom();
    s->src = src;
    s->n = n;
    tn__z_level_params(s, level);
    for (code = 0; code < 29; code++)
        for (i = tn__z_len_base[code]; i < (unsigned)tn__z_len_base[code] + (1u << tn__z_len_extra[code]) && i <= 258; i++)
            s->len_code[i] = (uint8_t)code;
    s->len_code[258] = 28; /* 258 has its own code, not 284 + 31 */
    for (code = 0; code < 30; code++)
        for (d = tn__z_dist_base[code]; d < (unsigned)tn__z_dist_base[code] + (1u << tn__z_dist_extra[code]); d++)
            s->dist_code[d <= 256 ? d - 1 : 256 + ((d - 1) >> 7)] = (uint8_t)code;
    for (i = 8; i < TN__Z_HASH_BITS && ((size_t)1 << i) < n; i++) {}
    s->hash_shift = 32 - i;
    s->head = (size_t *)tn__calloc(sizeof(size_t) << i);
    s->prev = (uint16_t *)tn__calloc(sizeof(uint16_t) * (n < TN__Z_WSIZE ? n + 1 : TN__Z_WSIZE)); /* p < n */
    s->sym_len = (uint16_t *)tn__alloc(sizeof(uint16_t) * TN__Z_BLOCK_SYMS);
    s->sym_dist = (uint16_t *)tn__alloc(sizeof(uint16_t) * TN__Z_BLOCK_SYMS);
    if (!s->head || !s->prev || !s->sym_len || !s->sym_dist) st = tn__oom();
    if (st == TN_OK) st = tn__reserve((void **)&s->out, &s->ocap, n / 2 + 1024);
    if (st == TN_OK) {
        s->out[0] = 0x78; /* deflate, 32K window; FLEVEL as zlib sets it */
        s->out[1] = level == 1 ? 0x01 : level < 6 ? 0x5e : level == 6 ? 0x9c : 0xda;
        s->olen = 2;
        st = level <= 3 ? tn__z_parse_greedy(s) : tn__z_parse_lazy(s);
    }
    if (st == TN_OK) st = tn__z_flush_block(s, 1);
    if (st == TN_OK) st = tn__reserve((void **)&s->out, &s->ocap, s->olen + 16);
    if (st == TN_OK) {
        tn__z_put_align(s);
        adler = tn__adler32(1, src, n);
        tn__png_put_be32(s->out + s->olen, adler);
        s->olen += 4;
        *out = s->out;
        *out_size = s->olen;
    } else {
        TN_FREE(s->out);
    }
    TN_FREE(s->head);
    TN_FREE(s->prev);
    TN_FREE(s->sym_len);
    TN_FREE(s->sym_dist);
    TN_FREE(s);
    return st;
}

/* ---- PNG decode ---- */

static const uint8_t tn__png_sig[8] = {137, 80, 78, 71, 13, 10, 26, 10};

/* Adam7 passes: x0, y0, dx, dy. */
static const uint8_t tn__png_adam7[7][4] = {{0, 0, 8, 8}, {4, 0, 8, 8}, {0, 4, 4, 8}, {2, 0, 4, 4},
                                            {0, 2, 2, 4}, {1, 0, 2, 2}, {0, 1, 1, 2}};

typedef struct tn__png {
    const char *name;
    uint32_t w, h;
    int depth, ctype, interlace;
    int spp;                /* samples per pixel in the file */
    int channels;           /* float channels produced */
    unsigned npal, ntrns;   /* palette entries, palette alpha entries */
    uint8_t pal[256][4];
    int has_trns;           /* grey/RGB transparent colour */
    uint16_t trns[3];
    int has_range;
    double lo, hi;
} tn__png;

/* Width in pixels of an Adam7 pass (or the whole image for pass -1). */
static uint32_t tn__png_pass_dim(uint32_t size, int start, int step)
{
    return size > (uint32_t)start ? (size - (uint32_t)start + (uint32_t)step - 1) / (uint32_t)step : 0;
}

/* Bytes of one row of `pw` pixels, without the filter byte. */
static size_t tn__png_rowbytes(const tn__png *p, uint32_t pw)
{
    return ((size_t)pw * (size_t)(p->spp * p->depth) + 7) / 8;
}

static tn_status tn__png_ihdr(tn__png *p, const uint8_t *d, uint32_t len)
{
    int ok;
    size_t bytes;
    if (len != 13) return tn__fail(TN_ERR_CORRUPT, "%s: IHDR chunk has length %u, not 13", p->name, (unsigned)len);
    p->w = tn__png_be32(d);
    p->h = tn__png_be32(d + 4);
    p->depth = d[8];
    p->ctype = d[9];
    p->interlace = d[12];
    if (p->w == 0 || p->h == 0) return tn__fail(TN_ERR_CORRUPT, "%s: image size %u x %u is empty", p->name, (unsigned)p->w, (unsigned)p->h);
    if (p->w > (1u << 24) || p->h > (1u << 24))
        return tn__fail(TN_ERR_TOO_LARGE, "%s: image size %u x %u is too large", p->name, (unsigned)p->w, (unsigned)p->h);
    switch (p->ctype) {
    case 0: ok = p->depth == 1 || p->depth == 2 || p->depth == 4 || p->depth == 8 || p->depth == 16; p->spp = 1; break;
    case 3: ok = p->depth == 1 || p->depth == 2 || p->depth == 4 || p->depth == 8; p->spp = 1; break;
    case 2: ok = p->depth == 8 || p->depth == 16; p->spp = 3; break;
    case 4: ok = p->depth == 8 || p->depth == 16; p->spp = 2; break;
    case 6: ok = p->depth == 8 || p->depth == 16; p->spp = 4; break;
    default: return tn__fail(TN_ERR_CORRUPT, "%s: invalid colour type %d", p->name, p->ctype);
    }
    if (!ok) return tn__fail(TN_ERR_CORRUPT, "%s: invalid bit depth %d for colour type %d", p->name, p->depth, p->ctype);
    if (d[10] != 0) return tn__fail(TN_ERR_CORRUPT, "%s: unknown compression method %d", p->name, d[10]);
    if (d[11] != 0) return tn__fail(TN_ERR_CORRUPT, "%s: unknown filter method %d", p->name, d[11]);
    if (p->interlace > 1) return tn__fail(TN_ERR_CORRUPT, "%s: unknown interlace method %d", p->name, p->interlace);
    /* the smallest float image this header can lead to (tRNS may add alpha; checked exactly later) */
    return tn__size4(p->w, p->h, (size_t)(p->ctype == 3 ? 3 : p->spp), sizeof(float), &bytes) != TN_OK
               ? tn__fail(TN_ERR_TOO_LARGE, "%s: image size %u x %u exceeds the allocation limit", p->name,
                          (unsigned)p->w, (unsigned)p->h)
               : TN_OK;
}

/* >>formats: locale-free number parsing and printing, unlike strtod / "%g" */
static int tn__io_number(const char *s, size_t n, double *out);
static int tn__io_format_number(char *buf, size_t cap, double v, int as_float);

/* tEXt "terrainnet.range" = "<lo> <hi>"; anything malformed (or NaN) is ignored (ancillary
   chunk). A range beyond float sets has_range = -1: the decode then fails with TN_ERR_NUMERIC,
   since the pixels could not be converted. */
static void tn__png_text(tn__png *p, const uint8_t *d, uint32_t len)
{
    static const char key[] = "terrainnet.range";
    const char *t = (const char *)d + sizeof key;
    size_t tl, i = 0, b[2], e[2];
    double v[2];
    int k;
    if (len < sizeof key || memcmp(d, key, sizeof key) != 0) return; /* sizeof key includes the NUL */
    tl = len - sizeof key;
    for (k = 0; k < 2; k++) {
        while (i < tl && t[i] == ' ') i++;
        b[k] = i;
        while (i < tl && t[i] != ' ') i++;
        e[k] = i;
        if (!tn__io_number(t + b[k], e[k] - b[k], &v[k]) || v[k] != v[k]) return;
    }
    while (i < tl && t[i] == ' ') i++;
    if (i != tl) return; /* trailing junk */
    p->has_range = fabs(v[0]) <= FLT_MAX && fabs(v[1]) <= FLT_MAX ? 1 : -1;
    p->lo = v[0];
    p->hi = v[1];
}

static void tn__png_trns(tn__png *p, const uint8_t *d, uint32_t len)
{
    unsigned i;
    if (p->ctype == 3) {
        if (len > 256) return;
        p->ntrns = len;
        for (i = 0; i < len; i++) p->pal[i][3] = d[i];
    } else if (p->ctype == 0 && len == 2) {
        p->has_trns = 1;
        p->trns[0] = (uint16_t)((d[0] << 8) | d[1]);
    } else if (p->ctype == 2 && len == 6) {
        p->has_trns = 1;
        for (i = 0; i < 3; i++) p->trns[i] = (uint16_t)((d[2 * i] << 8) | d[2 * i + 1]);
    } /* tRNS is not allowed with an alpha channel; ignored like any malformed ancillary chunk */
}

/* Undoes the row filters in place; rows are (1 + rowbytes) apart, each led by its filter type. */
static tn_status tn__png_unfilter(const tn__png *p, uint8_t *data, size_t rowbytes, uint32_t rows)
{
    size_t bpp = (size_t)((p->spp * p->depth + 7) / 8), i, stride = rowbytes + 1;
    uint32_t r;
    for (r = 0; r < rows; r++) {
        uint8_t *row = data + r * stride + 1;
        const uint8_t *up = r ? row - stride : NULL;
        int f = row[-1];
        switch (f) {
        case 0: break;
        case 1:
            for (i = bpp; i < rowbytes; i++) row[i] = (uint8_t)(row[i] + row[i - bpp]);
            break;
        case 2:
            if (up)
                for (i = 0; i < rowbytes; i++) row[i] = (uint8_t)(row[i] + up[i]);
            break;
        case 3:
            if (up) {
                for (i = 0; i < bpp && i < rowbytes; i++) row[i] = (uint8_t)(row[i] + (up[i] >> 1));
                for (; i < rowbytes; i++) row[i] = (uint8_t)(row[i] + ((row[i - bpp] + up[i]) >> 1));
            } else {
                for (i = bpp; i < rowbytes; i++) row[i] = (uint8_t)(row[i] + (row[i - bpp] >> 1));
            }
            break;
        case 4:
            if (up) {
                for (i = 0; i < bpp && i < rowbytes; i++) row[i] = (uint8_t)(row[i] + up[i]);
                for (; i < rowbytes; i++) { /* Paeth; no && so compilers emit conditional moves: the
                                              choice is unpredictable, branches made this 5x slower */
                    int a = row[i - bpp], b = up[i], c = up[i - bpp], bc = b - c, ac = a - c;
                    int pa = abs(bc), pb = abs(ac), pc = abs(ac + bc);
                    int bcs = pb <= pc ? b : c, not_a = (pa > pb) | (pa > pc); /* no && : stays branch-free */
                    row[i] = (uint8_t)(row[i] + (not_a ? bcs : a));
                }
            } else {
                for (i = bpp; i < rowbytes; i++) row[i] = (uint8_t)(row[i] + row[i - bpp]);
            }
            break;
        default:
            return tn__fail(TN_ERR_CORRUPT, "%s: invalid filter type %d in row %u", p->name, f, (unsigned)r);
        }
    }
    return TN_OK;
}

/* Sample i of a row (any depth). */
static unsigned tn__png_sample(const uint8_t *row, size_t i, int depth)
{
    size_t bit;
    if (depth == 8) return row[i];
    if (depth == 16) return ((unsigned)row[2 * i] << 8) | row[2 * i + 1];
    bit = i * (size_t)depth;
    return (row[bit >> 3] >> (8 - depth - (int)(bit & 7))) & ((1u << depth) - 1u);
}

/* Converts `count` pixels of an unfiltered row into floats at dst, dst_step floats apart.
   lut maps codes of depth <= 8 to [0, 1]. Returns -1 on a palette index out of range. */
static int tn__png_row(const tn__png *p, const uint8_t *row, uint32_t count, float *dst, size_t dst_step,
                       const float *lut)
{
    uint32_t x;
    int c, ch = p->channels, depth = p->depth;
    /* (float)(v * (1.0 / 65535)) in double equals the correctly rounded v / 65535.0f for every
       16-bit v (checked exhaustively in the tests) and is cheaper than a float divide */
    const double inv16 = 1.0 / 65535.0;
    if (p->ctype == 3) {
        for (x = 0; x < count; x++, dst += dst_step) {
            unsigned idx = tn__png_sample(row, x, depth);
            if (idx >= p->npal) return -1;
            for (c = 0; c < ch; c++) dst[c] = lut[p->pal[idx][c]];
        }
        return 0;
    }
    if (p->has_range) { /* every sample was coded with the recorded range (no palette, no tRNS) */
        double scale = (p->hi - p->lo) / (double)((1u << depth) - 1u);
        size_t spp = (size_t)p->spp;
        for (x = 0; x < count; x++, dst += dst_step)
            for (c = 0; c < ch; c++) dst[c] = (float)(p->lo + scale * tn__png_sample(row, x * spp + (size_t)c, depth));
        return 0;
    }
    if (depth == 16 && p->ctype == 0 && ch == 1) { /* the DEM case: keep it tight */
        for (x = 0; x < count; x++, dst += dst_step)
            dst[0] = (float)((double)(((unsigned)row[2 * x] << 8) | row[2 * x + 1]) * inv16);
        return 0;
    }
    if (depth == 8 && !p->has_trns) {
        size_t spp = (size_t)p->spp;
        for (x = 0; x < count; x++, dst += dst_step, row += spp)
            for (c = 0; c < ch; c++) dst[c] = lut[row[c]];
        return 0;
    }
    for (x = 0; x < count; x++, dst += dst_step) {
        int transparent = p->has_trns;
        for (c = 0; c < p->spp; c++) {
            unsigned v = tn__png_sample(row, (size_t)x * (size_t)p->spp + (size_t)c, depth);
            if (transparent && v != p->trns[c]) transparent = 0;
            dst[c] = depth == 16 ? (float)((double)v * inv16) : lut[v];
        }
        if (p->has_trns) dst[p->spp] = transparent ? 0.0f : 1.0f;
    }
    return 0;
}

/* Inflates, unfilters and converts the concatenated IDAT data into img. */
static tn_status tn__png_pixels(tn__png *p, const uint8_t *z, size_t zn, tn_image *img)
{
    size_t raw_size = 0, fbytes, off, rb;
    tn__inflate *s = NULL;
    float *data = NULL, lut[256];
    char what[256];
    tn_status st = TN_OK;
    int pass, npass = p->interlace ? 7 : 1;
    unsigned i, maxcode = (1u << (p->depth > 8 ? 8 : p->depth)) - 1u;
    uint32_t r;

    for (pass = 0; pass < npass; pass++) {
        const uint8_t *a = p->interlace ? tn__png_adam7[pass] : NULL;
        uint32_t pw = a ? tn__png_pass_dim(p->w, a[0], a[2]) : p->w;
        uint32_t ph = a ? tn__png_pass_dim(p->h, a[1], a[3]) : p->h;
        size_t bytes;
        if (!pw || !ph) continue;
        if ((st = tn__size4(ph, tn__png_rowbytes(p, pw) + 1, 1, 1, &bytes)) != TN_OK) return st;
        raw_size += bytes;
    }
    if (raw_size > TN_MAX_ALLOC) return tn__fail(TN_ERR_TOO_LARGE, "%s: pixel data of %zu bytes exceeds the limit", p->name, raw_size);
    if ((st = tn__size4(p->w, p->h, (size_t)p->channels, sizeof(float), &fbytes)) != TN_OK)
        return tn__fail(st, "%s: image size %u x %u x %d exceeds the allocation limit", p->name, (unsigned)p->w,
                        (unsigned)p->h, p->channels);
    /* deflate expands at most 1032:1, so a short stream cannot make us allocate much */
    if (raw_size / 1032 > zn + 64)
        return tn__fail(TN_ERR_CORRUPT, "%s: %zu bytes of IDAT cannot hold %zu bytes of pixel data", p->name, zn, raw_size);

    s = (tn__inflate *)tn__alloc(sizeof *s);
    if (!s) return tn__oom();
    snprintf(what, sizeof what, "%s: IDAT", p->name);
    s->what = what;
    s->out = (uint8_t *)tn__alloc(raw_size + TN__Z_SLACK);
    s->len = 0;
    s->cap = s->max = raw_size;
    if (!s->out) st = tn__oom();
    if (st == TN_OK) {
        st = tn__z_inflate_run(s, z, zn);
        if (st == TN_ERR_TOO_LARGE) st = tn__fail(TN_ERR_CORRUPT, "%s: IDAT holds more than the %zu bytes of pixel data", p->name, raw_size);
        else if (s->len != raw_size)
            st = tn__fail(TN_ERR_CORRUPT, "%s: IDAT holds %zu bytes of pixel data, expected %zu", p->name, s->len, raw_size);
    }
    if (st == TN_OK) {
        data = (float *)tn__alloc(fbytes);
        if (!data) st = tn__oom();
    }
    for (i = 0; i < 256; i++) lut[i] = (float)i / (float)(i <= maxcode ? maxcode : 255u);
    if (p->ctype == 3) for (i = 0; i < 256; i++) lut[i] = (float)i / 255.0f;
    for (off = 0, pass = 0; st == TN_OK && pass < npass; pass++) {
        const uint8_t *a = p->interlace ? tn__png_adam7[pass] : NULL;
        uint32_t pw = a ? tn__png_pass_dim(p->w, a[0], a[2]) : p->w;
        uint32_t ph = a ? tn__png_pass_dim(p->h, a[1], a[3]) : p->h;
        uint32_t x0 = a ? a[0] : 0, y0 = a ? a[1] : 0, dx = a ? a[2] : 1, dy = a ? a[3] : 1;
        if (!pw || !ph) continue;
        rb = tn__png_rowbytes(p, pw);
        if ((st = tn__png_unfilter(p, s->out + off, rb, ph)) != TN_OK) break;
        for (r = 0; r < ph; r++) {
            float *dst = data + ((size_t)(y0 + r * dy) * p->w + x0) * (size_t)p->channels;
            if (tn__png_row(p, s->out + off + (size_t)r * (rb + 1) + 1, pw, dst, (size_t)dx * (size_t)p->channels, lut)) {
                st = tn__fail(TN_ERR_CORRUPT, "%s: palette index out of range (palette has %u entries)", p->name, p->npal);
                break;
            }
        }
        off += (size_t)ph * (rb + 1);
    }
    TN_FREE(s->out);
    TN_FREE(s);
    if (st != TN_OK) {
        TN_FREE(data);
        return st;
    }
    img->width = (int)p->w;
    img->height = (int)p->h;
    img->channels = p->channels;
    img->data = data;
    return TN_OK;
}

/* Decodes a whole PNG file held in memory into img (allocated here; untouched on failure).
   Samples become floats code / (2^depth - 1); palettes expand to RGB, or RGBA with tRNS; grey or
   RGB with tRNS gain an alpha channel. info (may be NULL) gets format, bit_depth, file_channels
   (palette: 1), interlaced, and the tEXt "terrainnet.range" mapping, which is applied (v = lo +
   n (hi - lo)) to every sample of non-palette images without tRNS, as the writer coded them. `name` (may be NULL) prefixes error messages.
   Errors: TN_ERR_FORMAT (signature, unknown critical chunk), TN_ERR_CORRUPT (CRC naming the
   chunk, IHDR, chunk order, truncation, zlib, pixel data size, palette index),
   TN_ERR_TOO_LARGE (sides > 2^24 or buffers beyond TN_MAX_ALLOC, checked before allocating). */
TN__INTERNAL tn_status tn__png_decode(const uint8_t *buf, size_t n, const char *name, tn_image *img, tn_image_info *info)
{
    tn__png *p;
    size_t pos = 8, idat_total = 0, nidat = 0, first_idat = 0;
    int seen_plte = 0, idat_done = 0, seen_iend = 0, i;
    uint8_t *z = NULL;
    const uint8_t *zsrc;
    tn_status st = TN_OK;
    if (!name) name = "png";
    if (n < 8 || memcmp(buf, tn__png_sig, 8) != 0) return tn__fail(TN_ERR_FORMAT, "%s: not a PNG file (bad signature)", name);
    p = (tn__png *)tn__calloc(sizeof *p);
    if (!p) return tn__oom();
    p->name = name;
    for (i = 0; i < 256; i++) p->pal[i][3] = 255;

    /* pass 1: walk and check every chunk, parse the small ones, measure IDAT */
    while (st == TN_OK && !seen_iend) {
        uint32_t len;
        const uint8_t *type, *d;
        char tname[5];
        int k;
        if (n - pos < 12) { st = tn__fail(TN_ERR_CORRUPT, "%s: file is truncated (no IEND chunk)", name); break; }
        len = tn__png_be32(buf + pos);
        type = buf + pos + 4;
        d = buf + pos + 8;
        for (k = 0; k < 4; k++) {
            int ch = type[k];
            if (!((ch >= 'A' && ch <= 'Z') || (ch >= 'a' && ch <= 'z'))) break;
            tname[k] = (char)ch;
        }
        tname[4] = 0;
        if (k < 4) { st = tn__fail(TN_ERR_CORRUPT, "%s: invalid chunk type at byte %zu", name, pos + 4); break; }
        if (len > 0x7fffffffu) { st = tn__fail(TN_ERR_CORRUPT, "%s: %s chunk length %u is invalid", name, tname, (unsigned)len); break; }
        if ((size_t)len > n - pos - 12) { st = tn__fail(TN_ERR_CORRUPT, "%s: file is truncated inside the %s chunk", name, tname); break; }
        if (tn__crc32(0, type, (size_t)len + 4) != tn__png_be32(d + len)) {
            st = tn__fail(TN_ERR_CORRUPT, "%s: CRC mismatch in %s chunk", name, tname);
            break;
        }
        if (pos == 8 && memcmp(type, "IHDR", 4) != 0) {
            st = tn__fail(TN_ERR_CORRUPT, "%s: first chunk is %s, not IHDR", name, tname);
            break;
        }
        if (nidat && memcmp(type, "IDAT", 4) != 0) idat_done = 1;
        if (!memcmp(type, "IHDR", 4)) {
            if (pos != 8) st = tn__fail(TN_ERR_CORRUPT, "%s: more than one IHDR chunk", name);
            else st = tn__png_ihdr(p, d, len);
        } else if (!memcmp(type, "PLTE", 4)) {
            if (nidat) st = tn__fail(TN_ERR_CORRUPT, "%s: PLTE chunk after IDAT", name);
            else if (seen_plte) st = tn__fail(TN_ERR_CORRUPT, "%s: more than one PLTE chunk", name);
            else if (len == 0 || len % 3 != 0 || len > 768)
                st = tn__fail(TN_ERR_CORRUPT, "%s: PLTE chunk length %u is invalid", name, (unsigned)len);
            else if (p->ctype == 3 && len / 3 > (1u << p->depth))
                st = tn__fail(TN_ERR_CORRUPT, "%s: palette has %u entries, more than %d-bit indices allow", name, (unsigned)len / 3, p->depth);
            else {
                unsigned e;
                seen_plte = 1;
                p->npal = len / 3;
                for (e = 0; e < p->npal; e++) {
                    p->pal[e][0] = d[3 * e];
                    p->pal[e][1] = d[3 * e + 1];
                    p->pal[e][2] = d[3 * e + 2];
                }
            }
        } else if (!memcmp(type, "IDAT", 4)) {
            if (p->ctype == 3 && !seen_plte) st = tn__fail(TN_ERR_CORRUPT, "%s: palette image without a PLTE chunk", name);
            else if (idat_done) st = tn__fail(TN_ERR_CORRUPT, "%s: IDAT chunks are not consecutive", name);
            else {
                if (!nidat) first_idat = pos;
                nidat++;
                idat_total += len;
            }
        } else if (!memcmp(type, "IEND", 4)) {
            seen_iend = 1;
        } else if (!memcmp(type, "tRNS", 4)) {
            if (!nidat) tn__png_trns(p, d, len);
        } else if (!memcmp(type, "tEXt", 4)) {
            tn__png_text(p, d, len);
        } else if (!(type[0] & 0x20)) {
            st = tn__fail(TN_ERR_FORMAT, "%s: unsupported critical chunk %s", name, tname);
        }
        pos += (size_t)len + 12;
    }
    if (st == TN_OK && !nidat) st = tn__fail(TN_ERR_CORRUPT, "%s: no IDAT chunk", name);
    if (st == TN_OK) {
        if (p->ctype == 3 && p->ntrns > p->npal) p->ntrns = 0; /* malformed tRNS: ignore */
        p->channels = p->ctype == 3 ? (p->ntrns ? 4 : 3) : p->spp + (p->has_trns ? 1 : 0);
        if (p->ctype == 3 || p->has_trns) p->has_range = 0; /* the writer never records one there */
        if (p->has_range < 0)
            st = tn__fail(TN_ERR_NUMERIC, "%s: terrainnet.range [%g, %g] is beyond float range", name, p->lo, p->hi);
    }
    if (st == TN_OK) {
        /* pass 2: gather IDAT payloads (a single chunk is used in place) */
        if (nidat == 1) {
            zsrc = buf + first_idat + 8;
        } else {
            size_t q = first_idat, zo = 0;
            z = (uint8_t *)tn__alloc(idat_total);
            if (!z) st = tn__oom();
            while (st == TN_OK && zo < idat_total) {
                uint32_t len = tn__png_be32(buf + q);
                memcpy(z + zo, buf + q + 8, len);
                zo += len;
                q += (size_t)len + 12;
            }
            zsrc = z;
        }
        if (st == TN_OK) st = tn__png_pixels(p, zsrc, idat_total, img);
    }
    if (st == TN_OK && info) {
        memset(info, 0, sizeof *info);
        info->format = TN_FORMAT_PNG;
        info->bit_depth = p->depth;
        info->file_channels = p->spp;
        info->interlaced = p->interlace;
        info->has_range = p->has_range;
        info->range_lo = p->has_range ? p->lo : 0.0;
        info->range_hi = p->has_range ? p->hi : 0.0;
    }
    TN_FREE(z);
    TN_FREE(p);
    return st;
}

/* ---- PNG encode ---- */

/* |v| of a byte read as signed: min(v, 256 - v), branch-free. */
#define TN__PNG_ABS8(v) ((v) < 256u - (v) ? (v) : 256u - (v))

/* Filters row (prev = previous raw row, all zeros for the first) with each of the 5 filters
   into cand (5 x n bytes) and returns the type with the smallest sum of |filtered byte as
   signed| (the usual estimate of how well a row compresses). The first bpp bytes are done apart
   so the main loop has no conditions. */
static int tn__png_pick_filter(const uint8_t *row, const uint8_t *prev, size_t n, size_t bpp, uint8_t *cand)
{
    size_t i, cost[5] = {0, 0, 0, 0, 0};
    int f, best = 0;
    uint8_t *c0 = cand, *c1 = cand + n, *c2 = cand + 2 * n, *c3 = cand + 3 * n, *c4 = cand + 4 * n;
    for (i = 0; i < bpp && i < n; i++) {
        c0[i] = c1[i] = row[i];
        c2[i] = c4[i] = (uint8_t)(row[i] - prev[i]);
        c3[i] = (uint8_t)(row[i] - (prev[i] >> 1));
    }
    for (; i < n; i++) {
        int a = row[i - bpp], b = prev[i], c = prev[i - bpp];
        int pa = abs(b - c), pb = abs(a - c), pc = abs(a + b - 2 * c);
        int bcs = pb <= pc ? b : c, not_a = (pa > pb) | (pa > pc);
        c0[i] = row[i];
        c1[i] = (uint8_t)(row[i] - a);
        c2[i] = (uint8_t)(row[i] - b);
        c3[i] = (uint8_t)(row[i] - ((a + b) >> 1));
        c4[i] = (uint8_t)(row[i] - (not_a ? bcs : a));
    }
    for (i = 0; i < n; i++) { /* five independent sums: no single add chain */
        uint32_t v0 = c0[i], v1 = c1[i], v2 = c2[i], v3 = c3[i], v4 = c4[i];
        cost[0] += TN__PNG_ABS8(v0);
        cost[1] += TN__PNG_ABS8(v1);
        cost[2] += TN__PNG_ABS8(v2);
        cost[3] += TN__PNG_ABS8(v3);
        cost[4] += TN__PNG_ABS8(v4);
    }
    for (f = 1; f < 5; f++)
        if (cost[f] < cost[best]) best = f;
    return best;
}

static void tn__png_put_chunk(uint8_t *o, const char *type, const uint8_t *data, uint32_t len)
{
    tn__png_put_be32(o, len);
    memcpy(o + 4, type, 4);
    if (len) memcpy(o + 8, data, len);
    tn__png_put_be32(o + 8 + len, tn__crc32(0, o + 4, (size_t)len + 4));
}

#define TN__PNG_IDAT_MAX ((size_t)1 << 20)

/* Encodes img (1-4 channels: grey, grey+alpha, RGB, RGBA) as an 8- or 16-bit PNG with codes
   round(clamp((v - lo) / (hi - lo), 0, 1) * max) (NaN -> 0); record_range writes tEXt
   "terrainnet.range" = "<lo> <hi>" (shortest round-trip text) so decoding restores v exactly up to quantisation. level
   0-9 (0 = 6). *out is TN_MALLOC'ed (caller frees with TN_FREE). Fails with TN_ERR_INVALID_ARG
   on bad image/depth/range. */
TN__INTERNAL tn_status tn__png_encode(const tn_image *img, int bit_depth, double lo, double hi, int record_range,
                                int level, uint8_t **out, size_t *out_size)
{
    static const uint8_t ctypes[5] = {0, 0, 4, 2, 6};
    size_t w, h, ch, bps, bpp, rowbytes, fsize, x, zn = 0, total, nchunks, o, i;
    uint8_t *filt = NULL, *rows = NULL, *z = NULL, *buf = NULL, ihdr[13];
    char text[96];
    size_t tlen = 0;
    double maxcode = bit_depth == 16 ? 65535.0 : 255.0, scale;
    tn_status st = TN_OK;
    uint32_t y;
    *out = NULL;
    *out_size = 0;
    if (!img || !img->data || img->width <= 0 || img->height <= 0 || img->channels < 1 || img->channels > 4)
        return tn__fail(TN_ERR_INVALID_ARG, "png: cannot encode an image of %d x %d x %d", img ? img->width : 0,
                        img ? img->height : 0, img ? img->channels : 0);
    if (bit_depth != 8 && bit_depth != 16) return tn__fail(TN_ERR_INVALID_ARG, "png: bit depth %d is not 8 or 16", bit_depth);
    if (!(lo - lo == 0) || !(hi - hi == 0) || lo == hi)
        return tn__fail(TN_ERR_INVALID_ARG, "png: value range [%g, %g] is not usable", lo, hi);
    w = (size_t)img->width;
    h = (size_t)img->height;
    ch = (size_t)img->channels;
    bps = (size_t)bit_depth / 8;
    bpp = ch * bps;
    if ((st = tn__size4(w, bpp, 1, 1, &rowbytes)) != TN_OK) return st;
    if ((st = tn__size4(h, rowbytes + 1, 1, 1, &fsize)) != TN_OK) return st;
    filt = (uint8_t *)tn__alloc(fsize);
    rows = (uint8_t *)tn__calloc(rowbytes * 8); /* current, previous, 5 candidates, zero row */
    if (!filt || !rows) { st = tn__oom(); goto done; }
    scale = maxcode / (hi - lo);
    for (y = 0; y < (uint32_t)h; y++) {
        uint8_t *cur = rows + (y & 1u) * rowbytes, *prev = y ? rows + ((y + 1) & 1u) * rowbytes : rows + 7 * rowbytes;
        const float *src = img->data + (size_t)y * w * ch;
        int f;
        for (x = 0; x < w * ch; x++) {
            double t = ((double)src[x] - lo) * scale;
            unsigned code;
            if (!(t > 0.0)) t = 0.0; /* also NaN */
            if (t > maxcode) t = maxcode;
            code = (unsigned)(t + 0.5);
            if (bps == 2) {
                cur[2 * x] = (uint8_t)(code >> 8);
                cur[2 * x + 1] = (uint8_t)code;
            } else {
                cur[x] = (uint8_t)code;
            }
        }
        f = tn__png_pick_filter(cur, prev, rowbytes, bpp, rows + 2 * rowbytes);
        filt[(size_t)y * (rowbytes + 1)] = (uint8_t)f;
        memcpy(filt + (size_t)y * (rowbytes + 1) + 1, rows + (2 + (size_t)f) * rowbytes, rowbytes);
    }
    if ((st = tn_zlib_deflate(&z, &zn, filt, fsize, level)) != TN_OK) goto done;
    if (record_range) {
        memcpy(text, "terrainnet.range", 17);
        /* shortest round-trip text with '.', whatever the C locale (the reader is locale-free too) */
        size_t a = (size_t)tn__io_format_number(text + 17, 32, lo, 0);
        text[17 + a] = ' ';
        tlen = 18 + a + (size_t)tn__io_format_number(text + 18 + a, 32, hi, 0);
    }
    nchunks = zn ? (zn + TN__PNG_IDAT_MAX - 1) / TN__PNG_IDAT_MAX : 1;
    total = 8 + 25 + (tlen ? 12 + tlen : 0) + nchunks * 12 + zn + 12;
    buf = (uint8_t *)tn__alloc(total);
    if (!buf) { st = tn__oom(); goto done; }
    memcpy(buf, tn__png_sig, 8);
    tn__png_put_be32(ihdr, (uint32_t)w);
    tn__png_put_be32(ihdr + 4, (uint32_t)h);
    ihdr[8] = (uint8_t)bit_depth;
    ihdr[9] = ctypes[ch];
    ihdr[10] = ihdr[11] = ihdr[12] = 0;
    tn__png_put_chunk(buf + 8, "IHDR", ihdr, 13);
    o = 8 + 25;
    if (tlen) {
        tn__png_put_chunk(buf + o, "tEXt", (const uint8_t *)text, (uint32_t)tlen);
        o += 12 + tlen;
    }
    for (i = 0; i < nchunks; i++) {
        size_t c = zn - i * TN__PNG_IDAT_MAX;
        if (c > TN__PNG_IDAT_MAX) c = TN__PNG_IDAT_MAX;
        tn__png_put_chunk(buf + o, "IDAT", z + i * TN__PNG_IDAT_MAX, (uint32_t)c);
        o += 12 + c;
    }
    tn__png_put_chunk(buf + o, "IEND", NULL, 0);
    o += 12;
    *out = buf;
    *out_size = o;
done:
    TN_FREE(filt);
    TN_FREE(rows);
    TN_FREE(z);
    return st;
}

