#!/bin/sh
# GRASS GIS r.watershed -s (SFD = D8) on a raw float32 DEM, timed inside one headless GRASS session.
# Usage: sh bench/grass_watershed.sh DEM.f32 N [RUNS]   (Debian: apt-get install grass-core)
set -e
command -v grass > /dev/null || { echo "# grass not installed"; exit 1; }
HERE=$(cd "$(dirname "$0")" && pwd)
grass --tmp-location XY --exec /usr/bin/python3 "$HERE/grass_inner.py" time "$1" "$2" "${3:-1}" 2>&1 |
    grep -E '^(grass_|#)' || true
