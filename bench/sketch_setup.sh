#!/bin/sh
# Issue 30's measurement at its own setup, in one command: for each region, the default gnn-train
# of the 128 example (the _full DEM with --crop where the MANIFEST puts the 128 crop, MINUTES on
# THREADS, as a user trains a style), then bench_gnn's reconstruction and neighbours of that model
# (moved=0: the neighbours that fit around the example), then eight drawings on it
# (bench_sketch, with maps of BIG x BIG and the strips), then one summary table of the targets.
# The drawings: the four of examples/data (valley, summit, ring, cross) and the four of
# bench/drawings (spine, horseshoe, fork, twin), copied together into OUT/drawings. FROM=DIR runs
# every DIR/sketch_NAME.tns instead (e.g. FROM=bench/heldout, the drawings kept out of every choice).
#   sh bench/sketch_setup.sh [OUT] [REGION ...]
#   (defaults: OUT build/sketch_setup; alps_montblanc sahara_erg_oriental grandcanyon_hoppe8bit
#    himalaya_everest moon_nearside_lola4ppd; MINUTES=10 THREADS=2 BIG=1024 FROM=)
# Run from the repository root after `make bin/terrainnet bin/bench_gnn bin/bench_sketch`, with
# ../shared/data (or TN_DATA) holding the DEMs. About 16 minutes a region at the defaults, nothing
# else running. Writes OUT/REGION.tnw, OUT/REGION.train.log, OUT/REGION.gnn.log,
# OUT/REGION.sketch.log, OUT/gnn_fig10_REGION.png, OUT/sketch_REGION_DRAWING.png and
# OUT/summary.md. A model already in OUT is used, not trained.
set -e
OUT=${1:-build/sketch_setup}
[ $# -gt 0 ] && shift
REGIONS=${*:-alps_montblanc sahara_erg_oriental grandcanyon_hoppe8bit himalaya_everest moon_nearside_lola4ppd}
MINUTES=${MINUTES:-10}
THREADS=${THREADS:-2}
BIG=${BIG:-1024}
DATA=${TN_DATA:-../shared/data}
for b in bin/terrainnet bin/bench_gnn bin/bench_sketch; do
    [ -x $b ] || { echo "sketch_setup: $b is missing (make $b; run from the repository root)" >&2; exit 2; }
done
mkdir -p "$OUT/drawings"
if [ -n "${FROM:-}" ]; then
    cp "$FROM"/sketch_*.tns "$OUT/drawings/" || { echo "sketch_setup: no sketch_*.tns in $FROM" >&2; exit 2; }
    DRAWINGS=$(cd "$FROM" && ls sketch_*.tns | sed 's/^sketch_//; s/\.tns$//' | tr '\n' ' ')
else
    DRAWINGS="valley summit ring cross spine horseshoe fork twin"
    cp examples/data/sketch_valley.tns examples/data/sketch_summit.tns examples/data/sketch_ring.tns \
        examples/data/sketch_cross.tns bench/drawings/sketch_*.tns "$OUT/drawings/"
fi
failed=
for r in $REGIONS; do
    dem="$DATA/dem/$r/${r}_full.png"
    # the 128 crop ("rows Y-.. cols X-.. of REGION_full.png") and the metre mapping of the 16-bit codes
    at=$(sed -n "s/^| \`dem\/$r\/${r}_128.png\`.*| rows \([0-9]*\)-[0-9]* cols \([0-9]*\)-[0-9]* of ${r}_full.png.*/\2 \1/p" "$DATA/MANIFEST.md")
    range=$(awk -F, -v p="dem/$r/${r}_full.png" '$1 == p { print $8, $9; exit }' "$DATA/dem_index.csv")
    [ -n "$at" ] && [ -n "$range" ] || { echo "sketch_setup: $r: no 128 crop in $DATA/MANIFEST.md or no row in dem_index.csv" >&2; exit 1; }
    if [ ! -f "$OUT/$r.tnw" ]; then
        echo "== $r: gnn-train --crop $at, $MINUTES min, $THREADS threads ($(date -u +%H:%M:%S) UTC)"
        # shellcheck disable=SC2086
        ./bin/terrainnet --threads "$THREADS" gnn-train "$dem" --crop $at --range $range --minutes "$MINUTES" \
            --checkpoint "$OUT/$r.tnw.ckpt" -o "$OUT/$r.tnw" > "$OUT/$r.train.log" 2>&1 || { tail -n 5 "$OUT/$r.train.log" >&2; exit 1; }
        rm -f "$OUT/$r.tnw.ckpt"
    fi
    # a bench that fails on one region is reported and the next region still runs
    echo "== $r: bench_gnn ($(date -u +%H:%M:%S) UTC)"
    ./bin/bench_gnn "$r" "$MINUTES" "$THREADS" pictures=1 moved=0 model="$OUT/$r.tnw" > "$OUT/$r.gnn.log" ||
        { echo "sketch_setup: $r: bench_gnn failed (see above)" >&2; failed="$failed $r"; }
    [ -f "gnn_fig10_$r.png" ] && mv "gnn_fig10_$r.png" "$OUT/"
    echo "== $r: bench_sketch ($(date -u +%H:%M:%S) UTC)"
    ./bin/bench_sketch "$r" "$OUT/$r.tnw" "$THREADS" pictures="$OUT" big="$BIG" \
        drawings="$(echo $DRAWINGS | tr ' ' ,)" from="$OUT/drawings" > "$OUT/$r.sketch.log" ||
        { echo "sketch_setup: $r: bench_sketch failed (see above)" >&2; failed="$failed $r"; }
done
# The summary: per drawing the issue's targets (follow >= 90 %, height error <= 10 %, the three
# distances <= 1.5 x the real crops'; for an 8-bit example also without the height steps, in
# brackets), the summits per area against the real crops', the 256 and
# BIG generation seconds, and per region the reconstruction (of an 8-bit example also without its
# steps, as gnn-train learns it) and the neighbours against the membrane.
first() { sed -n "s/$2/\1/p" "$1" | head -1; } # FILE SED-PATTERN: the first line's \1
num='\([^ ;]*\)'
{
    echo "| region | drawing | follow % | height error % | slope x | curvature x | spectrum x | peaks x | s (256) | s ($BIG) |"
    echo "|---|---|---|---|---|---|---|---|---|---|"
    for r in $REGIONS; do
        L="$OUT/$r.sketch.log"
        [ -f "$L" ] || continue
        for d in $DRAWINGS; do
            row="| $r | $d | $(first "$L" "^${d}_new_follow: $num.*") | $(first "$L" "^${d}_new_height_error: $num.*")"
            for k in slope curvature spectrum peaks; do
                row="$row | $(first "$L" "^${d}_new_$k: [^(]*($num x real).*")"
                # an 8-bit example: also without the height steps, as gnn-train learns it
                sm=$(first "$L" "^${d}_new_smooth: .*$k [^(]*($num x real).*")
                [ -n "$sm" ] && row="$row ($sm)"
            done
            echo "$row | $(first "$L" "^${d}_new_gain: .*seconds: $num.*") | $(first "$L" "^${d}_${BIG}_map_scale: .*; seconds $num;.*") |"
        done
    done
    echo
    echo "| region | reconstruction SSIM | neighbours t0 SSIM (membrane) | t200 | t500 | neighbour crops | train iterations |"
    echo "|---|---|---|---|---|---|---|"
    for r in $REGIONS; do
        G="$OUT/$r.gnn.log"
        [ -f "$G" ] || continue
        sm=$(first "$G" "^recon_smooth_ssim: $num.*") # an 8-bit example: as learnt, without its steps
        row="| $r | $(first "$G" "^recon_ssim: $num.*")${sm:+ (without the steps: $sm)}"
        for t in 0 200 500; do row="$row | $(first "$G" "^neighbours_t${t}_gnn_ssim: $num.*") ($(first "$G" "^neighbours_t${t}_membrane_ssim: $num.*"))"; done
        echo "$row | $(first "$G" "^neighbours_t0_gnn_ssim: .*(\([0-9]*\) crops).*") | $(./bin/terrainnet info "$OUT/$r.tnw" | sed -n 's/^iterations: //p') |"
    done
} > "$OUT/summary.md"
cat "$OUT/summary.md"
[ -z "$failed" ] || { echo "sketch_setup: a bench failed on:$failed" >&2; exit 1; }
