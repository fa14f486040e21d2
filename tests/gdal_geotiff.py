#!/usr/bin/env python3
"""terrainnet's GeoTIFF reader and writer against GDAL (python3-gdal, gdal-bin) as the reference.

Read: GDAL writes a 203 x 157 raster with each compression (NONE, PACKBITS, LZW, DEFLATE),
predictor (1, 2, 3), strips and tiles, data type, byte order and BigTIFF; `terrainnet convert`
turns it into PFM (floats) and every sample must equal GDAL's ReadAsArray (8-bit data: code/255),
and `terrainnet info` must print GDAL's geotransform.
Write: `terrainnet convert` writes float32 and int16 GeoTIFFs from GDAL-made ones; GDAL must
read the same values, geotransform and CRS, and gdalinfo must accept the file.
Real DEM: an SRTM .hgt converted by gdal_translate reads the same as terrainnet's .hgt reader.

usage: python3 tests/gdal_geotiff.py BIN/terrainnet WORKDIR [SRTM.hgt]
Prints "gdal_geotiff: N passed, M failed" (and FAIL lines); exit status 1 on failure.
"""
import os
import subprocess
import sys

import numpy as np
from osgeo import gdal, osr

gdal.UseExceptions()
T, W = sys.argv[1], sys.argv[2]
HGT = sys.argv[3] if len(sys.argv) > 3 else None
os.makedirs(W, exist_ok=True)
passed = failed = 0


def check(cond, what):
    global passed, failed
    if cond:
        passed += 1
    else:
        failed += 1
        print("FAIL gdal_geotiff: " + what)


def run(*args):
    return subprocess.run([T] + list(args), capture_output=True, text=True)


def read_pfm(path):
    with open(path, "rb") as f:
        kind = f.readline().strip()
        w, h = map(int, f.readline().split())
        scale = float(f.readline())
        ch = 3 if kind == b"PF" else 1
        a = np.frombuffer(f.read(), dtype="<f4" if scale < 0 else ">f4").reshape(h, w, ch)[::-1]
    return np.moveaxis(a, 2, 0).astype(np.float64)  # bands, rows, cols


def info_gt(path):
    r = run("info", path)
    for line in r.stdout.splitlines():
        if line.startswith("geotransform: "):
            return tuple(float(v) for v in line.split()[1:])
    return None


def gt_equal(a, b):
    return a is not None and b is not None and all(abs(x - y) <= 1e-12 * (1 + abs(y)) for x, y in zip(a, b))


TYPES = {"Byte": np.uint8, "Int8": np.int8, "UInt16": np.uint16, "Int16": np.int16, "UInt32": np.uint32,
         "Int32": np.int32, "Float32": np.float32, "Float64": np.float64}
WIDTH, HEIGHT = 203, 157


def data(tname, bands, seed=1):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:HEIGHT, 0:WIDTH]
    out = []
    for b in range(bands):
        base = 1500 + 900 * np.sin(x / 23.0 + b) * np.cos(y / 17.0) + rng.normal(0, 40, (HEIGHT, WIDTH))
        if tname == "Byte": a = (base / 2400 * 255).clip(0, 255)
        elif tname == "Int8": a = (base / 2400 * 255 - 128).clip(-128, 127)
        elif tname == "UInt16": a = base * 20
        elif tname == "Int16": a = base * 20 - 32768
        elif tname == "UInt32": a = base * 1.7e6
        elif tname == "Int32": a = base * 1.7e6 - 2.1e9
        else: a = base * 1.37
        out.append(np.round(a) if not tname.startswith("Float") else a)
    return out


def gdal_write(path, tname, bands, opts, gt=(600000.0, 10.0, 0.0, 5100000.0, 0.0, -10.0), epsg=32632, point=False):
    gtype = gdal.GDT_Byte if tname == "Int8" else getattr(gdal, "GDT_" + tname)
    if tname == "Int8":
        opts = opts + ["PIXELTYPE=SIGNEDBYTE"]
    ds = gdal.GetDriverByName("GTiff").Create(path, WIDTH, HEIGHT, bands, gtype, opts)
    s = osr.SpatialReference()
    s.ImportFromEPSG(epsg)
    ds.SetProjection(s.ExportToWkt())
    ds.SetGeoTransform(gt)
    if point:
        ds.SetMetadataItem("AREA_OR_POINT", "Point")
    for b, a in enumerate(data(tname, bands)):
        arr = a.astype(TYPES[tname])
        ds.GetRasterBand(b + 1).WriteArray(arr.view(np.uint8) if tname == "Int8" else arr)
    ds = None


def expected(path, tname):
    d = gdal.Open(path)
    a = d.ReadAsArray().astype(np.float64)
    if a.ndim == 2:
        a = a[None]
    if tname == "Int8" and gdal.__version__ < "3.7":  # GDAL 3.6 reads SIGNEDBYTE as Byte codes
        a = np.where(a > 127, a - 256, a)
    if tname == "Byte" or (tname == "UInt16" and d.RasterCount >= 3 and
                           d.GetRasterBand(1).GetColorInterpretation() == gdal.GCI_RedBand):
        a = (a.astype(np.float32) * np.float32(1.0 / (255.0 if tname == "Byte" else 65535.0))).astype(np.float64)
    else:
        a = a.astype(np.float32).astype(np.float64)
    return a, d.GetGeoTransform()


def read_case(name, tname, bands, opts, **kw):
    src = os.path.join(W, name + ".tif")
    gdal_write(src, tname, bands, opts, **kw)
    want, gt = expected(src, tname)
    if bands in (1, 3):
        out = os.path.join(W, name + ".pfm")
        r = run("convert", src, out)
        got = read_pfm(out) if r.returncode == 0 else None
    else:  # PFM holds 1 or 3 channels: go through terrainnet's float32 GeoTIFF
        out = os.path.join(W, name + "_tn.tif")
        r = run("convert", src, out)
        got = gdal.Open(out).ReadAsArray().astype(np.float64) if r.returncode == 0 else None
    if got is None:
        check(False, "%s: terrainnet convert failed: %s" % (name, r.stderr.strip()))
        return
    # GDAL's NaN/Inf are voids terrainnet fills (only GDAL 3.6's big-endian predictor-3 files give them)
    known = np.isfinite(want)
    ok = got.shape == want.shape and np.array_equal(got[known], want[known]) and np.all(np.isfinite(got))
    check(ok, "%s: %s" % (name, "shape %s vs %s" % (got.shape, want.shape) if got.shape != want.shape
                         else "%d samples differ" % np.sum(got[known] != want[known])))
    if not known.all():
        voids = run("info", src).stdout
        check("voids_filled: %d" % np.sum(~known) in voids, "%s: %d non-finite GDAL samples, terrainnet says %s" % (name, np.sum(~known), voids))
    check(gt_equal(info_gt(src), gt), "%s: geotransform %s, GDAL %s" % (name, info_gt(src), gt))


def main():
    n = 0
    # compression x predictor x strips/tiles x byte order, for int16 and float32
    for tname in ("Int16", "Float32"):
        for comp in ("NONE", "PACKBITS", "LZW", "DEFLATE"):
            for pred in ("1", "2", "3") if tname == "Float32" else ("1", "2"):
                if comp in ("NONE", "PACKBITS") and pred != "1":
                    continue
                for tiled in (False, True):
                    for endian in ("LITTLE", "BIG"):
                        opts = ["COMPRESS=" + comp, "ENDIANNESS=" + endian]
                        if comp in ("LZW", "DEFLATE"):
                            opts.append("PREDICTOR=" + pred)
                        opts += ["TILED=YES", "BLOCKXSIZE=64", "BLOCKYSIZE=32"] if tiled else ["BLOCKYSIZE=7"]
                        read_case("r%03d_%s_%s_p%s_%s_%s" % (n, tname, comp, pred, "tiled" if tiled else "strips", endian),
                                  tname, 1, opts)
                        n += 1
    # every data type, plain and Deflate + its predictor, classic and BigTIFF
    for tname in TYPES:
        pred = "3" if tname.startswith("Float") else "2"
        for big in ("NO", "YES"):
            read_case("t%03d_%s_none_big%s" % (n, tname, big), tname, 1, ["BIGTIFF=" + big]); n += 1
            read_case("t%03d_%s_deflate_p%s_big%s" % (n, tname, pred, big), tname, 1,
                      ["BIGTIFF=" + big, "COMPRESS=DEFLATE", "PREDICTOR=" + pred, "TILED=YES"]); n += 1
    # samples per pixel, pixel and band interleaving
    for bands, tname, inter in ((3, "Byte", "PIXEL"), (4, "UInt16", "PIXEL"), (3, "Int16", "BAND"), (2, "Float32", "BAND"),
                                (6, "Int16", "PIXEL")):
        read_case("b%03d_%s_%d_%s" % (n, tname, bands, inter), tname, bands,
                  ["INTERLEAVE=" + inter, "COMPRESS=LZW", "PREDICTOR=2" if not tname.startswith("Float") else "PREDICTOR=3"]); n += 1
    # georeferences: geographic PixelIsPoint, rotated
    read_case("g%03d_geographic_point" % n, "Int16", 1, ["COMPRESS=DEFLATE"], gt=(9.25, 0.001, 0.0, 47.75, 0.0, -0.0005),
              epsg=4326, point=True); n += 1
    read_case("g%03d_rotated" % n, "Float32", 1, ["COMPRESS=DEFLATE"], gt=(1000.0, 1.5, 0.25, 2000.0, 0.5, -1.5)); n += 1
    print("gdal_geotiff: read %d GDAL-written files" % n)

    # write: terrainnet's float32 and int16 GeoTIFFs as GDAL sees them
    for src_name, kw in (("w_utm", {}), ("w_geo_point", dict(gt=(9.25, 0.001, 0.0, 47.75, 0.0, -0.0005), epsg=4326, point=True)),
                         ("w_rot", dict(gt=(1000.0, 1.5, 0.25, 2000.0, 0.5, -1.5)))):
        src = os.path.join(W, src_name + ".tif")
        gdal_write(src, "Int16", 1, ["COMPRESS=LZW"], **kw)
        s = gdal.Open(src)
        for bits in ("32", "16"):
            out = os.path.join(W, "%s_tn%s.tif" % (src_name, bits))
            r = run("convert", src, out) if bits == "32" else run("convert", "--bits", "16", src, out)
            if r.returncode != 0:
                check(False, "%s: terrainnet convert failed: %s" % (out, r.stderr.strip()))
                continue
            d = gdal.Open(out)
            check(np.array_equal(d.ReadAsArray().astype(np.float64), s.ReadAsArray().astype(np.float64)), out + ": values")
            check(gt_equal(d.GetGeoTransform(), s.GetGeoTransform()), "%s: geotransform %s vs %s" % (out, d.GetGeoTransform(), s.GetGeoTransform()))
            a, b = osr.SpatialReference(d.GetProjection()), osr.SpatialReference(s.GetProjection())
            check(a.IsSame(b) == 1, out + ": CRS differs")
            check(d.GetMetadataItem("AREA_OR_POINT") == s.GetMetadataItem("AREA_OR_POINT"), out + ": AREA_OR_POINT")
            dt = d.GetRasterBand(1).DataType
            check(dt == (gdal.GDT_Float32 if bits == "32" else gdal.GDT_Int16), out + ": data type %d" % dt)
            p = subprocess.run(["gdalinfo", "-stats", out], capture_output=True, text=True)
            check(p.returncode == 0 and "ERROR" not in p.stderr, out + ": gdalinfo: " + p.stderr.strip())
    # a float DEM with fractions survives float32 bit-exactly
    src = os.path.join(W, "w_float.tif")
    gdal_write(src, "Float32", 1, ["COMPRESS=DEFLATE", "PREDICTOR=3"])
    out = os.path.join(W, "w_float_tn.tif")
    r = run("convert", src, out)
    check(r.returncode == 0 and np.array_equal(gdal.Open(out).ReadAsArray(), gdal.Open(src).ReadAsArray()), "float32 write: values")

    # the real SRTM tile: gdal_translate's GeoTIFF reads like the .hgt itself
    if HGT and os.path.exists(HGT):
        tif = os.path.join(W, "srtm.tif")
        subprocess.run(["gdal_translate", "-q", "-co", "COMPRESS=DEFLATE", "-co", "PREDICTOR=2", "-co", "TILED=YES", HGT, tif], check=True)
        r1, r2 = run("convert", HGT, os.path.join(W, "srtm_hgt.pfm")), run("convert", tif, os.path.join(W, "srtm_tif.pfm"))
        check(r1.returncode == 0 and r2.returncode == 0 and
              np.array_equal(read_pfm(os.path.join(W, "srtm_hgt.pfm")), read_pfm(os.path.join(W, "srtm_tif.pfm"))),
              "SRTM: GeoTIFF and .hgt readings differ")
        check(gt_equal(info_gt(tif), gdal.Open(HGT).GetGeoTransform()), "SRTM geotransform %s vs %s" % (info_gt(tif), gdal.Open(HGT).GetGeoTransform()))
    print("gdal_geotiff: %d passed, %d failed" % (passed, failed))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
