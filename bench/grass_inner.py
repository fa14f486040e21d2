#!/usr/bin/python3
"""Runs INSIDE a GRASS session (grass --tmp-location XY --exec ...); used by bench/grass_watershed.sh
and bench/compare_grass.sh.
  time   DEM.f32 N RUNS            -> prints grass_rwatershed_sfd_<N>: <ms> ms (median of RUNS)
  export DEM.f32 W H T OUTPREFIX   -> r.watershed -s accumulation and r.stream.extract (threshold T)
                                      streams + directions as raw float32/int32 files OUTPREFIX.{acc,str,dir}"""
import sys, time, statistics
import grass.script as gs

def load(path, w, h):
    gs.run_command("r.in.bin", flags="f", input=path, output="dem", bytes=4, order="native",
                   north=h, south=0, east=w, west=0, rows=h, cols=w, overwrite=True, quiet=True)
    gs.run_command("g.region", raster="dem", quiet=True)

mode = sys.argv[1]
if mode == "time":
    path, n, runs = sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    load(path, n, n)
    ts = []
    for _ in range(runs):
        t0 = time.perf_counter()
        gs.run_command("r.watershed", flags="s", elevation="dem", accumulation="acc", overwrite=True, quiet=True)
        ts.append((time.perf_counter() - t0) * 1e3)
    st = gs.parse_command("r.univar", map="acc", flags="g")
    print(f"# r.watershed -s acc: max {abs(float(st['max'])):.0f}")
    print(f"grass_rwatershed_sfd_{n}: {statistics.median(ts):.1f} ms (min {min(ts):.1f} max {max(ts):.1f}, runs {runs}, t1, includes GRASS start-up of the module)")
elif mode == "export":
    path, w, h, thr, out = sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), sys.argv[6]
    load(path, w, h)
    gs.run_command("r.watershed", flags="s", elevation="dem", accumulation="acc", overwrite=True, quiet=True)
    gs.run_command("r.out.bin", flags="f", input="acc", output=out + ".acc", bytes=4, null=0, overwrite=True, quiet=True)
    gs.run_command("r.stream.extract", elevation="dem", accumulation="acc", threshold=thr, d8cut=0, stream_raster="str", direction="sdir",
                   overwrite=True, quiet=True)
    gs.run_command("r.out.bin", input="str", output=out + ".str", bytes=4, null=0, overwrite=True, quiet=True)
    gs.run_command("r.out.bin", input="sdir", output=out + ".dir", bytes=4, null=0, overwrite=True, quiet=True)
