#!/usr/bin/python3
"""Runs INSIDE a GRASS session (grass --tmp-location EPSG:32632 --exec ...); used by bench/compare_rsun.sh.
  DEM.f32 W H DX DY LAT OUTPREFIX DAY... -> r.sun beam irradiation (W h/m^2 per day, 15 min steps,
  terrain shadows on, slope and aspect from r.slope.aspect) of each DAY as raw float32 files
  OUTPREFIX_<day>.f32, and the seconds each r.sun run took. r.sun needs a projected location: the
  DEM is placed on the UTM zone's central meridian (grid north = true north) with its centre at
  LAT (northern hemisphere), so r.sun's latitudes are the DEM's."""
import sys, time, math
import grass.script as gs

path, w, h, dx, dy, lat, out = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4]), float(sys.argv[5]), float(sys.argv[6]), sys.argv[7]
days = [int(d) for d in sys.argv[8:]]
p = math.radians(lat)
north_c = 0.9996 * (111132.954 * lat - 16038.509 * math.sin(2 * p) + 16.833 * math.sin(4 * p))  # UTM northing of LAT
s0, w0 = north_c - h * dy / 2, 500000 - w * dx / 2
gs.run_command("r.in.bin", flags="f", input=path, output="dem", bytes=4, order="native",
               north=s0 + h * dy, south=s0, east=w0 + w * dx, west=w0, rows=h, cols=w, overwrite=True, quiet=True)
gs.run_command("g.region", raster="dem", quiet=True)
gs.run_command("r.slope.aspect", elevation="dem", slope="slope", aspect="aspect", overwrite=True, quiet=True)
for d in days:
    t0 = time.perf_counter()
    gs.run_command("r.sun", elevation="dem", slope="slope", aspect="aspect", day=d, step=0.25,
                   beam_rad="beam", nprocs=2, overwrite=True, quiet=True)
    print(f"# r.sun day {d}: {time.perf_counter() - t0:.1f} s")
    gs.run_command("r.out.bin", flags="f", input="beam", output=f"{out}_{d}.f32", bytes=4, null=0, overwrite=True, quiet=True)
