#!/bin/sh
# CLI tests: help text, clear errors with non-zero exit, and real conversions/metrics/renders.
# Ends with "test_cli: N passed, N failed, N skipped".
set -u
T=bin/terrainnet
D=${TN_SHARED_DATA:-../shared/data}
W=build/test/cli
rm -rf "$W"; mkdir -p "$W"
pass=0; fail=0; skip=0
ok()   { pass=$((pass + 1)); }
bad()  { echo "FAIL test_cli: $1"; fail=$((fail + 1)); }
skipped() { echo "skipped test_cli: $1"; skip=$((skip + 1)); }

# every subcommand answers --help with exit 0 and a usage line
for c in info convert metrics render noise texgan-train texgan-synth detail-maps; do
    if $T $c --help 2>&1 | grep -q "usage: terrainnet $c"; then ok; else bad "$c --help"; fi
done
if $T --help | grep -q commands; then ok; else bad "--help"; fi

# errors: one clear message, non-zero exit, no crash
expect_error() { # name, grep pattern, command...
    name=$1; pat=$2; shift 2
    "$@" > "$W/out.txt" 2>&1; rc=$?
    if [ $rc -ne 0 ] && [ $rc -lt 128 ] && grep -qi "$pat" "$W/out.txt"; then ok; else bad "$name (rc $rc): $(head -c 300 "$W/out.txt")"; fi
}
expect_error "unknown command" "unknown command" $T frobnicate
expect_error "missing file" "no_such_file.png" $T info no_such_file.png
expect_error "info without file" "missing FILE" $T info
expect_error "convert bad range" "range" $T convert a.png b.png --range 5 1
expect_error "metrics one arg" "needs" $T metrics a.png
expect_error "render no -o" "missing" $T render a.png
printf 'P5\n99999999 99999999\n255\n' > "$W/huge.pgm"
expect_error "absurd pgm size" "too large" $T info "$W/huge.pgm"
printf '\211PNG\r\n\032\nthis is not a png' > "$W/garbage.png"
expect_error "garbage png" "garbage.png" $T info "$W/garbage.png"
expect_error "bad threads" "threads" $T --threads 0 info x.png

# procedural terrain needs no data: a 16-bit heightmap in metres, then its pictures
if $T noise -o "$W/noise.png" --size 96 64 --seed 3 --range 100 900 && $T info "$W/noise.png" > "$W/ninfo.txt" &&
    grep -q "height_range_m: 100 900" "$W/ninfo.txt" && grep -q "size: 96 x 64" "$W/ninfo.txt"; then ok; else bad "noise"; fi
if $T noise -o "$W/noise2.png" --size 96 64 --seed 3 --range 100 900 && cmp -s "$W/noise.png" "$W/noise2.png"; then ok;
else bad "noise is not deterministic"; fi
expect_error "noise bad weight" "weight" $T noise -o "$W/x.png" --draw "$W/noise.png" --draw-weight 3


# texture GAN: a tiny model trained on a generated exemplar, resumed, synthesised, detail-mapped
TG="--patch 16 --stages 2 --gen-width 16 --disc-width 8 --batch 2 --local 4"
expect_error "texgan-train no -o" "missing -o" $T texgan-train "$W/noise.png"
expect_error "texgan-synth bad size" "size needs" $T texgan-synth m.tnw --size 0x5 -o "$W/x.pfm"
expect_error "texgan-synth not a model" "not a terrainnet weights" $T texgan-synth "$W/noise.png" --size 8x8 -o "$W/x.pfm"
expect_error "detail-maps one arg" "needs" $T detail-maps "$W/noise.png" -o "$W/dm"
if $T texgan-train "$W/noise.png" -o "$W/tg.tnw" --iters 2 $TG > "$W/tg.txt" 2>&1 && grep -q "iterations: 2" "$W/tg.txt" &&
    $T texgan-train "$W/noise.png" -o "$W/tg.tnw" --iters 4 --resume $TG > "$W/tg2.txt" 2>&1 && grep -q "resumed at 2" "$W/tg2.txt"; then ok;
else bad "texgan-train/resume: $(cat "$W/tg.txt" "$W/tg2.txt" 2>/dev/null | head -c 400)"; fi
if $T texgan-synth "$W/tg.tnw" --size 100x70 -o "$W/s1.pfm" --seed 4 > /dev/null && $T texgan-synth "$W/tg.tnw" --size 100x70 -o "$W/s2.pfm" --seed 4 > /dev/null &&
    cmp -s "$W/s1.pfm" "$W/s2.pfm" && $T info "$W/s1.pfm" | grep -q "size: 100 x 70"; then ok; else bad "texgan-synth deterministic pfm"; fi
if $T texgan-synth "$W/tg.tnw" --size 100x70 -o "$W/s1.png" --colour-correct > /dev/null && $T info "$W/s1.png" | grep -q "size: 100 x 70"; then ok;
else bad "texgan-synth png"; fi
if $T detail-maps "$W/tg.tnw" "$W/noise.png" -o "$W/dm" --size 200x140 --compose "$W/comp.png" --preview "$W/prev.png" > "$W/dm.txt" 2>&1 &&
    grep -q "low map: 20 x 14" "$W/dm.txt" && grep -q "tiling 2.08333" "$W/dm_detail.txt" && $T info "$W/comp.png" | grep -q "size: 200 x 140" &&
    [ -f "$W/dm_low.png" ] && [ -f "$W/dm_high.png" ] && [ -f "$W/prev.png" ]; then ok; else bad "detail-maps: $(head -c 400 "$W/dm.txt")"; fi
head -c 300 "$W/tg.tnw" > "$W/tg_bad.tnw"
expect_error "detail-maps corrupt model" "damaged\|truncated" $T detail-maps "$W/tg_bad.tnw" "$W/noise.png" -o "$W/dm2"

HGT="$D/dem/alps_n47e009/original/N47E009.hgt"
if [ -f "$HGT" ]; then
    $T info "$HGT" > "$W/info.txt" 2>&1
    if grep -q "size: 1201 x 1201" "$W/info.txt" && grep -q "format: hgt" "$W/info.txt"; then ok; else bad "info hgt: $(cat "$W/info.txt")"; fi
    # hgt -> 16-bit png keeps metres through the tEXt range
    if $T convert "$HGT" "$W/alps.png" && $T info "$W/alps.png" > "$W/info2.txt" 2>&1 &&
        grep -q "height_range_m: 388 2937" "$W/info2.txt"; then ok; else bad "hgt->png keeps metres: $(cat "$W/info2.txt")"; fi
    $T metrics "$HGT" "$W/alps.png" > "$W/m.txt" 2>&1
    if grep -q "ssim: 1.000000" "$W/m.txt" && grep -q "^rmse: " "$W/m.txt"; then ok; else bad "metrics identical: $(cat "$W/m.txt")"; fi
    # a blurred copy scores lower
    if $T convert "$W/alps.png" "$W/alps.pgm" && $T render "$W/alps.pgm" -o "$W/preview.png" &&
        $T info "$W/preview.png" | grep -q "channels: 3"; then ok; else bad "render preview"; fi
    if $T render "$HGT" --3d --size 320 180 -o "$W/view.png" && $T info "$W/view.png" | grep -q "size: 320 x 180"; then ok;
    else bad "render 3d"; fi
    # never clobber: a failed convert leaves an existing output untouched
    cp "$W/alps.png" "$W/keep.png"
    $T convert "$W/garbage.png" "$W/keep.png" > /dev/null 2>&1
    if cmp -s "$W/alps.png" "$W/keep.png"; then ok; else bad "failed convert changed the existing output"; fi
else
    skipped "real DEM tests ($HGT absent)"
fi
echo "test_cli: $pass passed, $fail failed, $skip skipped"
[ $fail -eq 0 ]
