#!/usr/bin/env python3
"""Writes the GDAL-made TIFF fixtures of tests/test_geotiff.c into tests/refs/tiff/.

Needs python3-gdal (Debian: apt-get install python3-gdal gdal-bin). Each file holds the
pattern of tn_test_tiff_pattern() in test_geotiff.c (same formula here, per data type), so the
test can check every sample without GDAL; tests/refs/tiff/fixtures.txt lists, one line per file:
    name type bands nodata gt0 gt1 gt2 gt3 gt4 gt5 model dx dy
(nodata "-" = none, model 0/1/2 as tn_georef.model_type, dx dy = expected spacing in metres or
0 0). Run from the repository root:  python3 tests/refs/make_tiff_refs.py
"""
import os
import numpy as np
from osgeo import gdal, osr

W, H = 37, 23
OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "tiff")

TYPES = {  # name: (gdal type, numpy type)
    "uint8": (gdal.GDT_Byte, np.uint8), "int8": (gdal.GDT_Byte, np.int8),  # GDAL 3.6: Byte + PIXELTYPE=SIGNEDBYTE
    "uint16": (gdal.GDT_UInt16, np.uint16), "int16": (gdal.GDT_Int16, np.int16),
    "uint32": (gdal.GDT_UInt32, np.uint32), "int32": (gdal.GDT_Int32, np.int32),
    "float32": (gdal.GDT_Float32, np.float32), "float64": (gdal.GDT_Float64, np.float64),
}


def pattern(tname, bands):
    """Same formula as tn_test_tiff_pattern in tests/test_geotiff.c."""
    y, x = np.mgrid[0:H, 0:W].astype(np.int64)
    out = []
    for c in range(bands):
        v = (x * x * 3 + y * 17 + c * 101 + x * y) % 100003
        if tname == "uint8": a = v % 256
        elif tname == "int8": a = v % 256 - 128
        elif tname == "uint16": a = (v * 37) % 65536
        elif tname == "int16": a = (v * 37) % 65536 - 32768
        elif tname == "uint32": a = (v * 2654435761) % 4294967296
        elif tname == "int32": a = (v * 2654435761) % 4294967296 - 2147483648
        elif tname == "float32": a = (v % 1000) * 0.25 - 100.5
        else: a = (v % 1000) * 0.125 - 50.0625
        out.append(a.astype(TYPES[tname][1]))
    return out


def srs(epsg):
    s = osr.SpatialReference()
    s.ImportFromEPSG(epsg)
    return s.ExportToWkt()


GEO = (9.25, 0.001, 0.0, 47.75, 0.0, -0.0005)          # lon/lat degrees
UTM = (500000.0, 2.0, 0.0, 5200000.0, 0.0, -3.0)        # metres
ROT = (1000.0, 1.5, 0.25, 2000.0, 0.5, -1.5)            # rotated, metres


def write(name, tname, bands=1, opts=(), nodata=None, gt=UTM, epsg=32633, holes=None, point=False):
    opts = list(opts) + (["PIXELTYPE=SIGNEDBYTE"] if tname == "int8" else [])
    ds = gdal.GetDriverByName("GTiff").Create(os.path.join(OUT, name), W, H, bands, TYPES[tname][0], opts)
    if gt is not None:
        ds.SetGeoTransform(gt)
        ds.SetProjection(srs(epsg))
    if point:
        ds.SetMetadataItem("AREA_OR_POINT", "Point")
    for c, a in enumerate(pattern(tname, bands)):
        b = ds.GetRasterBand(c + 1)
        if nodata is not None:
            b.SetNoDataValue(nodata)
            for (x0, y0, w, h) in holes or ():
                a[y0:y0 + h, x0:x0 + w] = nodata
        b.WriteArray(a.view(np.uint8) if tname == "int8" else a)
    ds = None
    back = gdal.Open(os.path.join(OUT, name))
    g = back.GetGeoTransform(can_return_null=True) if gt is not None else None
    model = 0
    dx = dy = 0.0
    if g is not None:
        model = 2 if epsg == 4326 else 1
        if model == 1:
            dx, dy = np.hypot(g[1], g[4]), np.hypot(g[2], g[5])
        else:  # WGS 84 at the centre latitude, as tn__georef_spacing
            a_, f = 6378137.0, 1 / 298.257223563
            e2 = f * (2 - f)
            lat = g[3] + g[4] * W / 2 + g[5] * H / 2
            s = np.sin(np.radians(lat))
            w_ = 1 - e2 * s * s
            mlat = np.radians(1) * a_ * (1 - e2) / (w_ * np.sqrt(w_))
            mlon = np.radians(1) * a_ * np.cos(np.radians(lat)) / np.sqrt(w_)
            dx, dy = abs(g[1]) * mlon, abs(g[5]) * mlat
    line = "%s %s %d %s %s %d %.17g %.17g" % (name, tname, bands, "-" if nodata is None else repr(float(nodata)),
                                            " ".join("%.17g" % v for v in (g or (0, 0, 0, 0, 0, 0))), model, dx, dy)
    return line


def main():
    os.makedirs(OUT, exist_ok=True)
    for f in os.listdir(OUT):
        if f.endswith(".tif"):
            os.remove(os.path.join(OUT, f))
    lines = []
    T16 = ["TILED=YES", "BLOCKXSIZE=16", "BLOCKYSIZE=16"]
    S5 = ["BLOCKYSIZE=5"]  # several strips, the last one short
    for t in TYPES:
        pred = "3" if t.startswith("float") else "2"
        lines.append(write("%s_none_strips.tif" % t, t, opts=S5))
        lines.append(write("%s_deflate_p%s_tiled.tif" % (t, pred), t, opts=T16 + ["COMPRESS=DEFLATE", "PREDICTOR=" + pred]))
    for comp in ("PACKBITS", "LZW", "DEFLATE"):
        lines.append(write("int16_%s_strips.tif" % comp.lower(), "int16", opts=S5 + ["COMPRESS=" + comp]))
        lines.append(write("int16_%s_tiled_be.tif" % comp.lower(), "int16", opts=T16 + ["COMPRESS=" + comp, "ENDIANNESS=BIG"]))
    lines.append(write("int16_lzw_p2_strips_be.tif", "int16", opts=S5 + ["COMPRESS=LZW", "PREDICTOR=2", "ENDIANNESS=BIG"]))
    lines.append(write("uint16_lzw_p2_tiled.tif", "uint16", opts=T16 + ["COMPRESS=LZW", "PREDICTOR=2"]))
    lines.append(write("int32_deflate_p2_strips_be.tif", "int32", opts=S5 + ["COMPRESS=DEFLATE", "PREDICTOR=2", "ENDIANNESS=BIG"]))
    # (GDAL 3.6.2 / its libtiff write ENDIANNESS=BIG with PREDICTOR=3 byte-swapped: GDAL itself reads
    # those values back wrong, and terrainnet reads them exactly as GDAL does; so no such fixture)
    lines.append(write("float32_lzw_strips_be.tif", "float32", opts=S5 + ["COMPRESS=LZW", "ENDIANNESS=BIG"]))
    lines.append(write("float32_packbits_tiled.tif", "float32", opts=T16 + ["COMPRESS=PACKBITS"]))
    lines.append(write("float64_lzw_tiled_be_bigtiff.tif", "float64", opts=T16 + ["COMPRESS=LZW", "ENDIANNESS=BIG", "BIGTIFF=YES"]))
    lines.append(write("float64_deflate_p3_strips_bigtiff.tif", "float64", opts=S5 + ["COMPRESS=DEFLATE", "PREDICTOR=3", "BIGTIFF=YES"]))
    lines.append(write("int16_deflate_p2_strips_bigtiff.tif", "int16", opts=S5 + ["COMPRESS=DEFLATE", "PREDICTOR=2", "BIGTIFF=YES"]))
    lines.append(write("int16_none_tiled_bigtiff_be.tif", "int16", opts=T16 + ["BIGTIFF=YES", "ENDIANNESS=BIG"]))
    # samples per pixel and planar configuration
    lines.append(write("uint8_rgb_deflate_p2.tif", "uint8", 3, opts=S5 + ["COMPRESS=DEFLATE", "PREDICTOR=2"]))
    lines.append(write("uint16_b4_lzw_p2_tiled.tif", "uint16", 4, opts=T16 + ["COMPRESS=LZW", "PREDICTOR=2"]))
    lines.append(write("int16_b3_planar2_deflate_p2_tiled.tif", "int16", 3, opts=T16 + ["COMPRESS=DEFLATE", "PREDICTOR=2", "INTERLEAVE=BAND"]))
    lines.append(write("float32_b2_planar2_p3_strips.tif", "float32", 2, opts=S5 + ["COMPRESS=DEFLATE", "PREDICTOR=3", "INTERLEAVE=BAND"]))
    lines.append(write("float32_b3_planar2_strips_be.tif", "float32", 3, opts=S5 + ["COMPRESS=LZW", "INTERLEAVE=BAND", "ENDIANNESS=BIG"]))
    # nodata: voids are filled (test_geotiff checks the count and the filled range)
    lines.append(write("int16_nodata_deflate.tif", "int16", opts=["COMPRESS=DEFLATE"], nodata=-32768, holes=[(10, 5, 4, 3), (0, 0, 2, 2)]))
    lines.append(write("float32_nodata_nan_lzw.tif", "float32", opts=["COMPRESS=LZW", "PREDICTOR=3"], nodata=float("nan"), holes=[(20, 10, 3, 3)]))
    # georeferences: geographic PixelIsPoint, rotated (ModelTransformation), none
    lines.append(write("int16_geographic_point.tif", "int16", opts=["COMPRESS=DEFLATE"], gt=GEO, epsg=4326, point=True))
    lines.append(write("float32_rotated.tif", "float32", opts=["COMPRESS=DEFLATE"], gt=ROT))
    lines.append(write("uint16_no_georef.tif", "uint16", opts=["COMPRESS=LZW"], gt=None))
    with open(os.path.join(OUT, "fixtures.txt"), "w") as f:
        f.write("# made by tests/refs/make_tiff_refs.py with GDAL %s: name type bands nodata gt0..gt5 model dx dy\n" % gdal.__version__)
        f.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
