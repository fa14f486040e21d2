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
for c in info convert metrics render noise sketch sketch-random align extract realism style texgan-train texgan-synth detail-maps export; do
    if $T $c --help 2>&1 | grep -q "usage: terrainnet $c"; then ok; else bad "$c --help"; fi
done
if $T --help | grep -q commands; then ok; else bad "--help"; fi

# the generated help lists every option of each command with its help text; -h and `help CMD`
# print the same; `terrainnet --help` lists the command
while read -r c opts; do
    if $T $c --help > "$W/help.txt" 2> "$W/help_err.txt" && [ ! -s "$W/help_err.txt" ]; then ok; else bad "$c --help: exit status or stderr"; fi
    for o in $opts; do
        if grep -qE -- "^ +(-o, )?$o([ ,]|\$).*[a-z]" "$W/help.txt"; then ok; else bad "$c --help does not list $o"; fi
    done
    if $T $c -h | cmp -s - "$W/help.txt" && $T help $c | cmp -s - "$W/help.txt"; then ok; else bad "$c: -h or help $c differs from --help"; fi
    if $T --help | grep -q "^  $c "; then ok; else bad "terrainnet --help does not list $c"; fi
done <<EOF
info --raw-size --tensors
convert --range --bits --raw-size --cellsize
metrics --range
render -o --output --3d --size --azimuth --pitch --relief --light
noise -o --type --size --seed --octaves --frequency --lacunarity --gain --periodic --draw --draw-weight --range --like
sketch -o --size --preview --dem --tns
sketch-random -o --sketch --size --seed --nodes --preview
align -o --seed --choices --cut-dem --parts-out
extract -o --preview --threshold --valleys --ridges --accumulation --spacing
realism --spacing --spacing-b --range-a --range-b --threshold
style --content --style -o --iters --optimizer --weights --size --levels --seed --lr --content-weight --style-weight --sw-weight --hist-weight --tv-weight --drain-weight --valley-weight --no-drain
texgan-train -o --minutes --iters --resume --checkpoint --checkpoint-seconds --normal --seed --patch --batch --gen-width --disc-width --disc-layers --stages --scale --augment --local --global --periodic --feat-weight --nearest
texgan-synth --size -o --seed --colour-correct
detail-maps -o --size --seed --factor --sigma --no-colour --compose --preview --dem
export --to -o --spacing --z-scale --step --texture --preview-texture --raw-size --rock-slope --tree-line --snow-line --snow --vegetation --splat-preview
EOF
if $T noise --help | grep -q -- "--size N \[M\] .*(default: 512)" && $T render --help | grep -q -- "-o, --output OUT.png .*(required)"; then ok;
else bad "help shows defaults and required options"; fi
if $T help | grep -q commands && $T help noise | grep -q "usage: terrainnet noise"; then ok; else bad "terrainnet help [CMD]"; fi
# every option the README's command-line section shows is one its command's help lists
if [ -f README.md ]; then
    awk '/^    bin\/terrainnet [a-z]/ { cmd = $2 }
         /^    bin\/terrainnet / || (/^                    +\[/ && cmd != "") {
             for (i = 1; i <= NF; i++) { t = $i; if (t == "#") break; gsub(/[][]/, "", t); if (t ~ /^-/) print cmd, t }
             next }
         { cmd = "" }' README.md > "$W/readme_opts.txt"
    if [ -s "$W/readme_opts.txt" ]; then ok; else bad "no options found in the README's command-line section"; fi
    while read -r c o; do
        if $T $c --help | grep -qE -- "^ +(-o, )?$o([ ,]|\$)"; then ok; else bad "README shows $c $o, which $c --help does not list"; fi
    done < "$W/readme_opts.txt"
fi

# usage errors: exit status 2 and a message naming the command and what is wrong
expect_usage() { # name, grep pattern (fixed string), command...
    name=$1; pat=$2; shift 2
    "$@" > "$W/out.txt" 2>&1; rc=$?
    if [ $rc -eq 2 ] && grep -qF -- "$pat" "$W/out.txt"; then ok; else bad "$name (rc $rc): $(head -c 300 "$W/out.txt")"; fi
}
for c in info convert metrics render noise sketch sketch-random align extract realism style texgan-train texgan-synth detail-maps export; do
    expect_usage "$c unknown option" "terrainnet $c: unknown option --no-such-option" $T $c --no-such-option
done
expect_usage "missing value" "noise: missing value for --seed S" $T noise -o "$W/x.png" --seed
expect_usage "missing -o value" "render: missing value for -o OUT.png" $T render a.png -o
expect_usage "missing second value" "info: missing value for --raw-size W H" $T info a.r16 --raw-size 5
expect_usage "not a number" "noise: --seed needs a non-negative whole number, not abc" $T noise -o "$W/x.png" --seed abc
expect_usage "trailing garbage" "noise: --octaves needs a non-negative whole number, not 8x" $T noise -o "$W/x.png" --octaves 8x
expect_usage "fraction for a count" "style: --iters needs a whole number from 1 to 1000000, not 2.5" $T style --content a --style b -o c --iters 2.5
expect_usage "float out of range" "render: --pitch needs a number, not 1e999" $T render a.png -o b.png --pitch 1e999
expect_usage "int out of range" "sketch-random: --nodes needs a whole number from 2 to 8192, not 1" $T sketch-random -o x.tns --nodes 1
expect_usage "int overflow" "texgan-train: --patch needs a non-negative whole number up to 1000000000, not 99999999999" \
    $T texgan-train a.png -o x.tnw --patch 99999999999
expect_usage "positive" "extract: --spacing needs a positive number, not 0" $T extract a.png --spacing 0
expect_usage "second value" "extract: --spacing needs a positive number, not -2" $T extract a.png --spacing 1 -2
expect_usage "bad choice" "noise: --type must be one of perlin|explicit, not fbm" $T noise -o "$W/x.png" --type fbm
expect_usage "bad WxH" "texgan-synth: --size needs WxH" $T texgan-synth m.tnw -o x.pfm --size 12x
expect_usage "extra positional" "metrics: too many arguments: c" $T metrics a b c
expect_usage "no positionals" "noise: unexpected argument stray" $T noise -o "$W/x.png" stray
expect_usage "missing positionals" "convert: needs IN and OUT" $T convert a.png
expect_usage "missing required option" "sketch-random: missing -o OUT.tns" $T sketch-random --size 8
expect_usage "missing required options" "style: needs --content IN, --style SOURCE and -o OUT" $T style --content a
expect_usage "help of an unknown command" "unknown command 'frobnicate'" $T help frobnicate

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
# style transfer: noise restyled by another noise map (tiny, 2 levels, few iterations)
$T noise -o "$W/src.png" --size 64 --seed 9 --octaves 6 --frequency 8 --range 500 1500 > /dev/null 2>&1
if $T style --content "$W/noise.png" --style "$W/src.png" -o "$W/styled.png" --size 64 --iters 3 --levels 2 2> "$W/style.txt" &&
    $T info "$W/styled.png" > "$W/sinfo.txt" && grep -q "size: 64 x 64" "$W/sinfo.txt" && grep -q "style: 64 x 64" "$W/style.txt"; then ok;
else bad "style: $(head -c 300 "$W/style.txt")"; fi
# --no-drain is the drainage terms switched off by weight: same bytes as -1 / -1
if $T style --content "$W/noise.png" --style "$W/src.png" -o "$W/nd1.pfm" --size 48 --iters 2 --levels 2 --no-drain 2> /dev/null &&
    $T style --content "$W/noise.png" --style "$W/src.png" -o "$W/nd2.pfm" --size 48 --iters 2 --levels 2 --drain-weight -1 --valley-weight -1 2> /dev/null &&
    cmp -s "$W/nd1.pfm" "$W/nd2.pfm"; then ok; else bad "style --no-drain"; fi
# --like: a content map whose Perlin gain follows the source (rough source -> gain above 0.5)
$T noise -o "$W/rough.png" --size 64 --seed 4 --gain 0.85 > /dev/null 2>&1
if $T noise -o "$W/like.png" --size 64 --seed 5 --like "$W/rough.png" > "$W/like.txt" 2>&1 &&
    g=$(sed -n 's/^gain: //p' "$W/like.txt") && $T noise -o "$W/like2.png" --size 64 --seed 5 --gain "$g" > /dev/null 2>&1 &&
    cmp -s "$W/like.png" "$W/like2.png" && awk -v g="$g" 'BEGIN { exit !(g > 0.6) }'; then ok;
else bad "noise --like: $(head -c 200 "$W/like.txt")"; fi
expect_error "noise --like missing" "no such file" $T noise -o "$W/x.png" --like "$W/nonexistent.png"
expect_error "style no --style" "needs --content" $T style --content "$W/noise.png" -o "$W/x.png"
expect_error "style bad optimizer" "optimizer" $T style --content "$W/noise.png" --style "$W/src.png" -o "$W/x.png" --optimizer newton
expect_error "style missing weights" "no_such.tnw" $T style --content "$W/noise.png" --style "$W/src.png" -o "$W/x.png" --weights "$W/no_such.tnw"
expect_error "style weights not tnw" "not a terrainnet weights" $T style --content "$W/noise.png" --style "$W/src.png" -o "$W/x.png" --weights "$W/noise.png"

# sketches: .tns in, random enrichment, raster + preview, alignment map; clear errors on bad files
printf 'terrainnet-sketch 1\ncanvas 128 96\nridge start 0.9 rate -0.002\n10 50\n64 40\n120 60\nend\nvalley start 0.1 rate 0\n60 2\n70 90\nend\n' > "$W/user.tns"
if $T sketch-random --sketch "$W/user.tns" --seed 3 -o "$W/rnd.tns" --preview "$W/rnd.png" > /dev/null &&
    head -1 "$W/rnd.tns" | grep -q "terrainnet-sketch 1" && $T info "$W/rnd.png" | grep -q "size: 128 x 96"; then ok;
else bad "sketch-random"; fi
if $T sketch-random --sketch "$W/user.tns" --seed 3 -o "$W/rnd2.tns" > /dev/null && cmp -s "$W/rnd.tns" "$W/rnd2.tns"; then ok;
else bad "sketch-random is not deterministic"; fi
if $T sketch "$W/rnd.tns" --size 256 192 -o "$W/raster.png" --tns "$W/again.tns" > /dev/null &&
    $T info "$W/raster.png" | grep -q "size: 256 x 192" && $T info "$W/raster.png" | grep -q "channels: 3" &&
    cmp -s "$W/rnd.tns" "$W/again.tns"; then ok; else bad "sketch raster / tns round trip"; fi
$T sketch-random --size 128 96 --seed 9 --nodes 60 -o "$W/dem.tns" > /dev/null
if $T align "$W/user.tns" "$W/dem.tns" --cut-dem --seed 2 -o "$W/map.txt" --parts-out "$W/parts.tns" > /dev/null &&
    [ "$(grep -vc '^#' "$W/map.txt")" -eq "$(grep -c '^end' "$W/parts.tns")" ] && [ "$(grep -vc '^#' "$W/map.txt")" -gt 10 ] &&
    [ ! -e "$W/map.txt.tmp" ]; then ok;
else bad "align map"; fi
printf 'terrainnet-sketch 1\ncanvas 8 8\nridge\n1 1 0.5\n' > "$W/open.tns"
expect_error "sketch missing end" "open.tns:5: end of file inside the polyline opened at line 3" $T sketch "$W/open.tns" --tns "$W/x.tns"
printf 'terrainnet-sketch 1\ncanvas 8 8\nridge\n1 1 nan\nend\n' > "$W/nan.tns"
expect_error "sketch NaN" "nan.tns:4: height is NaN" $T sketch-random --sketch "$W/nan.tns" -o "$W/x.tns"
printf 'terrainnet-sketch 1\ncanvas 8 8\n' > "$W/empty.tns"
echo keep > "$W/m.txt"
expect_error "align empty sketch" "empty" $T align "$W/empty.tns" "$W/dem.tns" -o "$W/m.txt"
if [ "$(cat "$W/m.txt")" = keep ]; then ok; else bad "a failed align overwrote its output"; fi
expect_error "sketch-random no size" "size" $T sketch-random -o "$W/x.tns"
# a drawn sketch: a red stroke (P6 image) converts to a .tns ridge
printf 'P6\n16 8\n255\n' > "$W/drawn.ppm"
y=0; while [ $y -lt 8 ]; do x=0; while [ $x -lt 16 ]; do
    if [ $y -eq 4 ] && [ $x -gt 1 ] && [ $x -lt 14 ]; then printf '\310\000\000'; else printf '\377\377\377'; fi
    x=$((x + 1)); done; y=$((y + 1)); done >> "$W/drawn.ppm"
if $T sketch "$W/drawn.ppm" --tns "$W/drawn.tns" > /dev/null && grep -q '^ridge' "$W/drawn.tns" && grep -q '^canvas 16 8' "$W/drawn.tns"; then ok;
else bad "drawn sketch to tns"; fi
cp "$W/rnd.tns" "$W/keep.tns"
$T sketch-random --sketch "$W/nan.tns" -o "$W/keep.tns" > /dev/null 2>&1
if cmp -s "$W/rnd.tns" "$W/keep.tns"; then ok; else bad "a failed sketch-random changed the existing output"; fi


# texture GAN: a tiny model trained on a generated exemplar, resumed, synthesised, detail-mapped
TG="--patch 16 --stages 2 --gen-width 16 --disc-width 8 --batch 2 --local 4"
expect_error "texgan-train no -o" "missing -o" $T texgan-train "$W/noise.png"
expect_error "texgan-synth bad size" "size needs" $T texgan-synth m.tnw --size 0x5 -o "$W/x.pfm"
expect_error "texgan-synth not a model" "not a terrainnet weights" $T texgan-synth "$W/noise.png" --size 8x8 -o "$W/x.pfm"
expect_error "detail-maps one arg" "needs" $T detail-maps "$W/noise.png" -o "$W/dm"
expect_error "texgan-train negative feature weight" "non-negative" $T texgan-train "$W/noise.png" -o "$W/x.tnw" --feat-weight -1
if $T texgan-train "$W/noise.png" -o "$W/tgn.tnw" --iters 1 --nearest --feat-weight 0 $TG > /dev/null 2>&1 &&
    $T texgan-synth "$W/tgn.tnw" --size 40x30 -o "$W/sn.pfm" > /dev/null; then ok; else bad "texgan-train --nearest --feat-weight 0"; fi
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
# a checkpoint that cannot be written (its directory is missing, as a full disk would fail it) is a
# warning: the run ends, the model is saved to its own path, and the CLI says so (issue 33 item 8)
if $T texgan-train "$W/noise.png" -o "$W/tgc.tnw" --iters 2 --checkpoint "$W/no_such_dir/tgc.ckpt" $TG > "$W/tgc.txt" 2>&1 &&
    [ -f "$W/tgc.tnw" ] && grep -q "warning: no checkpoint could be written to $W/no_such_dir/tgc.ckpt" "$W/tgc.txt" &&
    $T texgan-train "$W/noise.png" -o "$W/tgc.tnw" --iters 2 --checkpoint "$W/tgc.ckpt" $TG > "$W/tgc2.txt" 2>&1 &&
    ! grep -q "warning" "$W/tgc2.txt"; then ok;
else bad "texgan-train failed checkpoint: $(head -c 400 "$W/tgc.txt")"; fi
# Ctrl-C: the run stops at its next iteration, saves its checkpoint and says how to resume
$T texgan-train "$W/noise.png" -o "$W/int.tnw" --iters 1000000 $TG > "$W/int.txt" 2>&1 &
pid=$!
n=0
while [ $n -lt 200 ] && ! grep -q "texgan-train:" "$W/int.txt" 2>/dev/null; do sleep 0.1; n=$((n + 1)); done
kill -INT $pid 2>/dev/null
wait $pid; rc=$?
if [ $rc -eq 130 ] && grep -q "interrupted after" "$W/int.txt" && [ -f "$W/int.tnw.ckpt" ] && [ ! -f "$W/int.tnw" ] &&
    $T texgan-train "$W/noise.png" -o "$W/int.tnw" --iters 1 --resume $TG > "$W/int2.txt" 2>&1 && grep -q "resumed at" "$W/int2.txt"; then ok;
else bad "texgan-train Ctrl-C (rc $rc): $(head -c 400 "$W/int.txt")"; fi
# meshes: glb (valid by the Khronos validator when it is installed: `.ci/run` puts it in
# build/gv) and obj with its material
if $T export "$W/noise.png" --to glb -o "$W/m.glb" --spacing 30 --preview-texture > /dev/null &&
    $T export "$W/noise.png" --to obj -o "$W/m.obj" --step 4 --texture "$W/noise.png" > /dev/null &&
    [ -f "$W/m.mtl" ] && [ -f "$W/m.png" ] && [ "$(grep -c '^f ' "$W/m.obj")" -eq $((2 * 24 * 16)) ]; then ok; else bad "export glb/obj"; fi
expect_usage "export without --to" "needs --to" $T export "$W/noise.png" -o "$W/m.glb"
if $T export "$W/noise.png" --to normal-dx -o "$W/nm.png" --spacing 30 > /dev/null && $T info "$W/nm.png" | grep -q "channels: 3" &&
    $T export "$W/noise.png" --to unity-raw -o "$W/u.raw" > "$W/u.txt" && [ "$(wc -c < "$W/u.raw")" -eq $((2 * 129 * 129)) ] &&
    grep -q "set the Unity terrain height" "$W/u.txt"; then ok; else bad "export normal map / unity raw"; fi
expect_usage "export unity-raw bad size" "--raw-size" $T export "$W/noise.png" --to unity-raw -o "$W/u.raw" --raw-size 20
if command -v node > /dev/null && [ -d build/gv/node_modules/gltf-validator ]; then
    if NODE_PATH=build/gv/node_modules node tests/gltf_validate.js "$W/m.glb" > "$W/gv.txt" 2>&1 && grep -q "errors 0 warnings 0" "$W/gv.txt"; then ok;
    else bad "glTF validator: $(head -c 400 "$W/gv.txt")"; fi
else skipped "glTF validator not installed (npm install --prefix build/gv gltf-validator)"; fi
# a model says what it is (loaded by its method: @@method); a checkpoint too; a model from before metadata still reads
if $T info "$W/tg.tnw" > "$W/tgi.txt" 2>&1 && grep -q "method: texgan" "$W/tgi.txt" && grep -q "iterations: 4" "$W/tgi.txt" &&
    grep -q "example: 96x64x1:" "$W/tgi.txt" && grep -q "kind: model" "$W/tgi.txt" &&
    grep -q "^summary: spatial GAN" "$W/tgi.txt" && grep -q "^channels: 1$" "$W/tgi.txt" &&
    $T info tests/refs/texgan_v1_checkpoint.tnw | grep -q "^loads: no: .*holds 41 tensors" &&
    $T info "$W/tg.tnw.ckpt" --tensors > "$W/tgc.txt" 2>&1 && grep -q "kind: checkpoint" "$W/tgc.txt" && grep -q "iteration: 4" "$W/tgc.txt" &&
    grep -q "tensor: am.g.w0 " "$W/tgc.txt" &&
    $T info tests/refs/texgan_v1_model.tnw | grep -q "before metadata"; then ok; else bad "info on models: $(head -c 400 "$W/tgi.txt")"; fi
expect_error "texgan-synth given a checkpoint" "checkpoint, not a model" $T texgan-synth "$W/tg.tnw.ckpt" --size 10x10 -o "$W/x.pfm"
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
# extract / realism: errors, then a procedural DEM (no data needed), then real DEMs
expect_error "extract no DEM" "missing DEM" $T extract
expect_error "extract bad threshold" "threshold" $T extract "$W/noise.png" --threshold -4
expect_error "extract missing file" "no_such_dem.png" $T extract no_such_dem.png
expect_error "realism one arg" "needs" $T realism "$W/noise.png"
expect_error "realism bad range" "LO < HI" $T realism "$W/noise.png" "$W/noise.png" --range-a 5 1
if $T extract "$W/noise.png" --threshold 20 --preview "$W/ex.png" --valleys "$W/v.png" --ridges "$W/r.png" \
        --accumulation "$W/acc.pfm" > "$W/ex.txt" 2>/dev/null &&
    grep -q "^threshold: 20$" "$W/ex.txt" && grep -q "^valley_contours: [1-9]" "$W/ex.txt" &&
    $T info "$W/ex.png" | grep -q "channels: 3" && $T info "$W/v.png" | grep -q "size: 96 x 64" &&
    $T info "$W/acc.pfm" | grep -q "format: pfm"; then ok; else bad "extract outputs: $(cat "$W/ex.txt")"; fi
# extract -> .tns -> sketch reads it back (the extract/edit/regenerate round trip)
if $T extract "$W/noise.png" --threshold 20 -o "$W/ex.tns" > /dev/null 2>&1 && head -n 1 "$W/ex.tns" | grep -q "^terrainnet-sketch 1" &&
    $T sketch "$W/ex.tns" -o "$W/ex_raster.pfm" > /dev/null 2>&1 && $T info "$W/ex_raster.pfm" | grep -q "channels: 3"; then ok;
else bad "extract -o .tns round trip"; fi
$T realism "$W/noise.png" "$W/noise.png" > "$W/re.txt" 2>/dev/null
if grep -q "^slope_distance: 0.000000$" "$W/re.txt" && grep -q "^distance: 0.000000$" "$W/re.txt" &&
    grep -q "^ssim: 1.000000$" "$W/re.txt"; then ok; else bad "realism identical: $(cat "$W/re.txt")"; fi
ALPS="$D/dem/alps_n47e009/alps_n47e009_256.png"; MB="$D/dem/alps_montblanc/alps_montblanc_256.png"
SAH="$D/dem/sahara_erg_oriental/sahara_erg_oriental_256.png"
if [ -f "$ALPS" ] && [ -f "$MB" ] && [ -f "$SAH" ]; then
    near=$($T realism "$ALPS" "$MB" --range-a 388 2937 --range-b 454 4810 --spacing 62.6 92.6 --spacing-b 92.7 2>/dev/null |
        sed -n 's/^distance: //p')
    far=$($T realism "$ALPS" "$SAH" --range-a 388 2937 --range-b 189 475 --spacing 62.6 92.6 --spacing-b 92.6 2>/dev/null |
        sed -n 's/^distance: //p')
    if [ -n "$near" ] && [ -n "$far" ] && awk "BEGIN { exit !($near < $far) }"; then ok;
    else bad "realism: alps-montblanc $near should be below alps-sahara $far"; fi
    if $T extract "$ALPS" > "$W/ex2.txt" 2>/dev/null && grep -q "^valley_max_strahler: [3-7]$" "$W/ex2.txt"; then ok;
    else bad "extract alps: $(cat "$W/ex2.txt")"; fi
else
    skipped "realism on real DEMs (absent)"
fi
# export --to splat: RGBA weights (8-bit), a cover summary, the colour preview; a mask of the wrong
# size is an error that writes nothing; --to normal is the OpenGL normal map
if $T export "$W/noise.png" --to splat -o "$W/splat.png" --spacing 2 --splat-preview "$W/splat_pv.png" > "$W/splat.txt" &&
    $T info "$W/splat.png" | grep -q "channels: 4" && $T info "$W/splat_pv.png" | grep -q "channels: 3" &&
    grep -q "^cover: vegetation [0-9.]* %, bare ground [0-9.]* %, rock [0-9.]* %, snow [0-9.]* %" "$W/splat.txt"; then ok;
else bad "export splat: $(cat "$W/splat.txt")"; fi
$T noise -o "$W/mask_small.png" --size 10 > /dev/null 2>&1
expect_error "export splat mask size" "mask is 10 x 10" $T export "$W/noise.png" --to splat -o "$W/splat2.png" --snow "$W/mask_small.png"
if [ ! -e "$W/splat2.png" ]; then ok; else bad "export splat wrote a file on error"; fi
if $T export "$W/noise.png" --to normal -o "$W/n1.png" --spacing 30 > /dev/null && $T export "$W/noise.png" --to normal-gl -o "$W/n2.png" --spacing 30 > /dev/null &&
    cmp -s "$W/n1.png" "$W/n2.png"; then ok; else bad "export --to normal is normal-gl"; fi
# make demo in its fast mode (seconds-long budgets): every picture and the page; then the page in
# headless Chromium (tests/demo_page.sh, skipped without chromium)
if DEMO_FAST=1 DEMO_DIR="$W/demo" sh examples/demo.sh > "$W/demo.log" 2>&1 && grep -q "^demo: wrote .*index.html ([1-9][0-9]* pictures" "$W/demo.log" &&
    [ -s "$W/demo/terrain.glb" ] && [ -s "$W/demo/splat.png" ] && [ -s "$W/demo/sketch_terrain.png" ] &&
    [ -s "$W/demo/sun_sheet.png" ] && [ -s "$W/demo/season_sheet.png" ] && grep -q "<p><b>[0-9]* pictures in [0-9]* s</b>" "$W/demo/index.html"; then ok;
else bad "fast demo: $(tail -n 3 "$W/demo.log")"; fi
sh tests/demo_page.sh "$W/demo" > "$W/demo_page.txt" 2>&1
if grep -q "^skipped demo_page" "$W/demo_page.txt"; then skipped "demo page in Chromium: $(sed -n 's/^skipped demo_page: //p' "$W/demo_page.txt")";
elif grep -q "^demo_page: [1-9][0-9]* passed, 0 failed" "$W/demo_page.txt"; then ok; else bad "demo page in Chromium: $(grep -v '^picture' "$W/demo_page.txt" | head -c 600)"; fi
# world: tiles resume, index, VRT read by GDAL (when installed), refusals; MPI (when installed)
if $T world --help | grep -q "usage: terrainnet world SPEC -o DIR"; then ok; else bad "world --help"; fi
printf 'world 300 200\nseed 4\nheight 50 1250\ncellsize 25\ntile 128\nperlin frequency=4\nhillshade\n' > "$W/shade.spec"
printf 'world 300 200\nseed 4\nheight 50 1250\ntile 128\nperlin frequency=4\n' > "$W/w.spec"
if $T world "$W/w.spec" -o "$W/world" --tiles 0:1,1:3 > "$W/wo1.txt" 2>/dev/null && grep -q "^tiles: 2 written, 0 already" "$W/wo1.txt" &&
    $T world "$W/w.spec" -o "$W/world" > "$W/wo2.txt" 2>/dev/null && grep -q "^tiles: 4 written, 2 already there" "$W/wo2.txt" &&
    grep -q "^tiles 6 of 6$" "$W/world/manifest.txt" && $T info "$W/world/r1_c2.png" | grep -q "size: 44 x 72"; then ok;
else bad "world tiles + resume: $(cat "$W/wo1.txt" "$W/wo2.txt")"; fi
if $T world "$W/shade.spec" -o "$W/shade" > /dev/null 2>&1 && $T info "$W/shade/r0_c0.png" | grep -q "bit_depth: 8"; then ok; else bad "world hillshade"; fi
printf 'world 160 120\nseed 2\nheight 200 3200\ncellsize 30\ntile 64\nperlin frequency=3\nseason koppen=Dfb latitude=46 time=1 distance=450\n' > "$W/season.spec"
if $T world "$W/season.spec" -o "$W/season" > "$W/wos.txt" 2>&1 && grep -q "halo 17 px" "$W/wos.txt" &&
    $T info "$W/season/r1_c2.png" | grep -q "channels: 3"; then ok; else bad "world season: $(cat "$W/wos.txt")"; fi
printf 'world 100 100\nperlin\nseason koppen=Dfb\n' > "$W/season0.spec"
expect_error "world season needs cellsize" "season needs .cellsize" $T world "$W/season0.spec" -o "$W/season0"
printf 'world 100 100\nperlin\nstyle\n' > "$W/style.spec"
expect_error "world refuses style" "style transfer optimises the whole map" $T world "$W/style.spec" -o "$W/style"
expect_error "world other world in DIR" "holds another world" $T world "$W/shade.spec" -o "$W/world"
expect_error "world bad --tiles" "I0:I1,J0:J1" $T world "$W/w.spec" -o "$W/world" --tiles 1:0,0:1
if command -v gdalinfo > /dev/null 2>&1; then
    if gdalinfo -stats "$W/world/world.vrt" > "$W/gdal.txt" 2>&1 && grep -q "Size is 300, 200" "$W/gdal.txt" &&
        awk -F= '/STATISTICS_MINIMUM/ { lo = $2 } /STATISTICS_MAXIMUM/ { hi = $2 } END { exit !(lo >= 50 && hi <= 1250 && hi - lo > 300) }' "$W/gdal.txt"
    then ok; else bad "gdalinfo -stats world.vrt: $(cat "$W/gdal.txt")"; fi
else
    skipped "gdalinfo -stats on world.vrt (gdal-bin absent)"
fi
if command -v mpirun > /dev/null 2>&1; then
    if sh tests/test_world_mpi.sh > "$W/mpi.txt" 2>&1; then ok; else bad "test_world_mpi.sh: $(cat "$W/mpi.txt")"; fi
else
    skipped "world with MPI (mpirun absent)"
fi
# gnn-train / gnn-generate: help, bad inputs, a tiny model from a procedural DEM, every SKETCH kind,
# seeded determinism, Ctrl-C checkpoint and resume
for c in gnn-train gnn-generate; do
    if $T $c --help 2>&1 | grep -q "usage: terrainnet $c" && $T --help | grep -q "^  $c "; then ok; else bad "$c --help"; fi
done
expect_usage "gnn-train no -o" "gnn-train: missing -o MODEL.tnw" $T gnn-train "$W/noise.png"
expect_usage "gnn-train bad size" "gnn-train: --size needs a whole number from 16 to 4096, not 8" $T gnn-train "$W/noise.png" -o "$W/g.tnw" --size 8
expect_usage "gnn-train crop outside" "does not fit" $T gnn-train "$W/noise.png" -o "$W/g.tnw" --crop 60 0 --size 48
expect_error "gnn-train missing DEM" "no_such_dem.png" $T gnn-train no_such_dem.png -o "$W/g.tnw"
{ echo "P2 32 32 255"; i=0; while [ $i -lt 1024 ]; do echo 7; i=$((i + 1)); done; } > "$W/flat.pgm"
expect_error "gnn-train flat DEM" "flat" $T gnn-train "$W/flat.pgm" -o "$W/g.tnw" --iters 1
GT="--iters 2 --size 48"
if $T --threads 2 gnn-train "$W/noise.png" -o "$W/g.tnw" $GT > "$W/gt.txt" 2>&1 && grep -q "^window: 48 x 48 at" "$W/gt.txt" &&
    grep -q "highest relief" "$W/gt.txt" && grep -q "^iterations: 2" "$W/gt.txt" && grep -q "^embed_phase_from: -1" "$W/gt.txt" &&
    $T info "$W/g.tnw" | grep -q "gnn"; then ok;
else bad "gnn-train: $(head -c 400 "$W/gt.txt")"; fi
expect_usage "gnn-train embed phase 1" "gnn-train: --embed-phase needs a number from -1 to 0.99, not 1" $T gnn-train "$W/noise.png" -o "$W/g2.tnw" --embed-phase 1
if $T gnn-train "$W/noise.png" -o "$W/g2.tnw" --iters 4 --size 48 --embed-phase 0.5 > "$W/gt2.txt" 2>&1 && grep -q "^embed_phase_from: 2" "$W/gt2.txt"; then ok;
else bad "gnn-train --embed-phase: $(head -c 400 "$W/gt2.txt")"; fi
# holdouts: the window beside a 48 px training window at (0, 0) of the 96 x 64 DEM checks the network
# (once, as the embedding phase starts); --holdout 0: none
if $T gnn-train "$W/noise.png" -o "$W/g5.tnw" --iters 4 --size 48 --crop 0 0 --embed-phase 0.5 > "$W/gt5.txt" 2>&1 &&
    grep -q "^holdout_windows: 1$" "$W/gt5.txt" && grep -Eq "^holdout_ssim: [0-9.-]+ \(iteration 2, the best of 1 checks" "$W/gt5.txt" &&
    grep -Eq "^gain_scale: [0-2]\.[0-9]{2} " "$W/gt5.txt" &&
    $T gnn-train "$W/noise.png" -o "$W/g6.tnw" --iters 2 --size 48 --crop 0 0 --holdout 0 > "$W/gt6.txt" 2>&1 &&
    grep -q "^holdout_windows: 0$" "$W/gt6.txt" && ! grep -q "^holdout_ssim" "$W/gt6.txt" && grep -q "^gain_scale: 1.00 " "$W/gt6.txt"; then ok;
else bad "gnn-train --holdout: $(grep -E "holdout|gain_scale" "$W/gt5.txt" "$W/gt6.txt")"; fi
expect_usage "gnn-generate no -o" "gnn-generate: missing -o OUT" $T gnn-generate "$W/g.tnw" "$W/ex.tns"
expect_usage "gnn-generate bad size" "gnn-generate: --size needs WxH" $T gnn-generate "$W/g.tnw" "$W/ex.tns" -o "$W/x.png" --size 8x8
expect_usage "gnn-generate bad choice" "must be one of auto|aligned|none" $T gnn-generate "$W/g.tnw" "$W/ex.tns" -o "$W/x.png" --embeddings all
expect_error "gnn-generate texgan model" "gnn" $T gnn-generate "$W/tg.tnw" "$W/ex.tns" -o "$W/x.png"
expect_error "gnn-generate missing sketch" "no_such.tns" $T gnn-generate "$W/g.tnw" no_such.tns -o "$W/x.png"
printf 'terrainnet-sketch 1\ncanvas 40 40\nridge\n3 3 0.5\n5 3 0.5\nend\n' > "$W/tiny.tns"
expect_error "gnn-generate no part of 5 px" "5 px" $T gnn-generate "$W/g.tnw" "$W/tiny.tns" -o "$W/x.png"
expect_error "gnn-generate flat DEM sketch" "extracted" $T gnn-generate "$W/g.tnw" "$W/flat.pgm" -o "$W/x.png"
cp "$W/noise.png" "$W/keep_g.png"
$T gnn-generate "$W/g.tnw" "$W/tiny.tns" -o "$W/keep_g.png" > /dev/null 2>&1
if cmp -s "$W/noise.png" "$W/keep_g.png"; then ok; else bad "a failed gnn-generate changed the existing output"; fi
if $T gnn-generate "$W/g.tnw" "$W/ex.tns" -o "$W/g1.png" --preview "$W/gp.png" > "$W/gg.txt" 2>&1 &&
    grep -q "^size: 96 x 64" "$W/gg.txt" && $T info "$W/g1.png" | grep -q "height_range_m" && $T info "$W/gp.png" | grep -q "channels: 3" &&
    $T --threads 1 gnn-generate "$W/g.tnw" "$W/ex.tns" -o "$W/g2.png" > /dev/null 2>&1 && cmp -s "$W/g1.png" "$W/g2.png"; then ok;
else bad "gnn-generate from .tns (same bytes for 1 and 2 threads): $(head -c 300 "$W/gg.txt")"; fi
# the residual gain: printed (tested on the sketch, in [0, 1]); --gain -1 gives the membrane, not the network's terrain
if $T gnn-generate "$W/g.tnw" "$W/ex.tns" -o "$W/gn1.pfm" --gain 1 > /dev/null 2>&1 && $T gnn-generate "$W/g.tnw" "$W/ex.tns" -o "$W/gn0.pfm" --gain -1 > /dev/null 2>&1 &&
    ! cmp -s "$W/gn1.pfm" "$W/gn0.pfm" && grep -Eq "^residual_gain: (0\.[0-9]+|1\.000)$" "$W/gg.txt"; then ok; else bad "gnn-generate --gain: $(grep gain "$W/gg.txt")"; fi
expect_usage "gnn-generate bad gain" "gnn-generate: --gain" $T gnn-generate "$W/g.tnw" "$W/ex.tns" -o "$W/x.png" --gain -2
if $T gnn-generate "$W/g.tnw" "$W/noise.png" -o "$W/g3.pfm" --size 120x80 --random 12 --finetune 2 --seed 4 > "$W/gg.txt" 2>&1 &&
    grep -q "DEM (its extracted network)" "$W/gg.txt" && $T info "$W/g3.pfm" | grep -q "size: 120 x 80"; then ok;
else bad "gnn-generate from a DEM with --random and --finetune: $(head -c 300 "$W/gg.txt")"; fi
if $T sketch-random --size 64 -o "$W/gr.tns" > /dev/null 2>&1 && $T sketch "$W/gr.tns" -o "$W/grr.pfm" > /dev/null 2>&1 &&
    $T gnn-generate "$W/g.tnw" "$W/gr.tns" -o "$W/g4.png" --heights unit > /dev/null 2>&1; then ok; else bad "gnn-generate --heights unit"; fi
$T gnn-train "$W/noise.png" -o "$W/gint.tnw" --iters 1000000 --size 48 > "$W/gint.txt" 2>&1 &
pid=$!
n=0
while [ $n -lt 300 ] && ! grep -q "gnn-train:" "$W/gint.txt" 2>/dev/null; do sleep 0.1; n=$((n + 1)); done
kill -INT $pid 2>/dev/null
wait $pid; rc=$?
if [ $rc -eq 130 ] && grep -q "interrupted after" "$W/gint.txt" && [ -f "$W/gint.tnw.ckpt" ] && [ ! -f "$W/gint.tnw" ] &&
    $T gnn-train "$W/noise.png" -o "$W/gint.tnw" --iters 1 --size 48 --resume > "$W/gint2.txt" 2>&1 && grep -q "resumed at" "$W/gint2.txt"; then ok;
else bad "gnn-train Ctrl-C (rc $rc): $(head -c 400 "$W/gint.txt")"; fi
# singan: a tiny model (2 scales, 8 channels) trains, checkpoints and resumes, samples (a window
# equals those pixels of a larger sample), refines and upscales in the example's units; errors
for c in singan-train singan-sample singan-refine singan-upscale; do
    if $T $c --help 2>&1 | grep -q "usage: terrainnet $c"; then ok; else bad "$c --help"; fi
done
expect_usage "singan-upscale needs factor" "--factor F" $T singan-upscale m.tnw a.png -o b.png
$T noise -o "$W/sg_dem.pfm" --size 32 32 --seed 5 --range 100 900 > /dev/null 2>&1
if $T singan-train "$W/sg_dem.pfm" -o "$W/sg.tnw" --coarsest 24 --channels 8 --scale-iters 2 --iters 3 > "$W/sg_train.txt" 2>/dev/null &&
    grep -q "^scales: 2 (trained 2)" "$W/sg_train.txt" && $T info "$W/sg.tnw" | grep -q "singan"; then ok;
else bad "singan-train: $(cat "$W/sg_train.txt")"; fi
if $T singan-train "$W/sg_dem.pfm" -o "$W/sg2.tnw" --coarsest 24 --channels 8 --iters 6 --resume > "$W/sg_res.txt" 2>&1 ||
    ! grep -q "sg2.tnw.ckpt" "$W/sg_res.txt"; then bad "singan-train --resume without a checkpoint: $(cat "$W/sg_res.txt")"; else ok; fi
if cp "$W/sg.tnw.ckpt" "$W/sg2.tnw.ckpt" && $T singan-train "$W/sg_dem.pfm" -o "$W/sg2.tnw" --iters 4 --resume \
        > "$W/sg_res.txt" 2>/dev/null && grep -q "^iterations: 4 (resumed at 3)" "$W/sg_res.txt" && grep -q "^per_scale: 2 2" "$W/sg_res.txt"; then ok;
else bad "singan-train --resume: $(cat "$W/sg_res.txt")"; fi
if $T singan-sample "$W/sg.tnw" -o "$W/sg_big.pfm" --size 40x30 --seed 2 2>/dev/null &&
    $T singan-sample "$W/sg.tnw" -o "$W/sg_big2.pfm" --size 40x30 --seed 2 2>/dev/null && cmp -s "$W/sg_big.pfm" "$W/sg_big2.pfm" &&
    $T singan-sample "$W/sg.tnw" -o "$W/sg_big3.pfm" --size 40x30 --seed 3 2>/dev/null && ! cmp -s "$W/sg_big.pfm" "$W/sg_big3.pfm" &&
    $T singan-sample "$W/sg.tnw" -o "$W/sg_win.pfm" --size 10x10 --origin -20 15 2>/dev/null &&
    $T info "$W/sg_big.pfm" | grep -q "size: 40 x 30"; then ok; else bad "singan-sample: same seed same bytes, seeds differ, windows"; fi
if $T singan-sample "$W/sg.tnw" -o "$W/sg_lay.pfm" --size 40x30 --seed 2 --layout 2>/dev/null && [ -s "$W/sg_lay.pfm" ] &&
    $T info "$W/sg_lay.pfm" | grep -q "size: 40 x 30"; then ok; else bad "singan-sample --layout: a file of the size asked"; fi
if $T singan-sample "$W/sg.tnw" -o "$W/sg_laym.pfm" --seed 2 --layout --map 40x30 2>/dev/null && cmp -s "$W/sg_lay.pfm" "$W/sg_laym.pfm" &&
    $T singan-sample "$W/sg.tnw" -o "$W/sg_layw.pfm" --seed 2 --layout --map 40x30 --origin 25 10 2>/dev/null &&
    $T info "$W/sg_layw.pfm" | grep -q "size: 15 x 20"; then ok; else bad "singan-sample --layout --map: the whole map, and a window of it"; fi
expect_error "singan-sample window outside its --map" "outside the 40 x 30 map" $T singan-sample "$W/sg.tnw" -o "$W/x.pfm" --map 40x30 --origin 30 0 --size 20x10
if $T singan-refine "$W/sg.tnw" "$W/sg_dem.pfm" -o "$W/sg_ref.pfm" --from-scale 1 2>/dev/null && $T info "$W/sg_ref.pfm" | grep -q "size: 32 x 32" &&
    $T singan-upscale "$W/sg.tnw" "$W/sg_dem.pfm" -o "$W/sg_up.pfm" --factor 1.5 --from-scale 2 2>/dev/null &&
    $T info "$W/sg_up.pfm" | grep -q "size: 48 x 48"; then ok; else bad "singan-refine / singan-upscale sizes"; fi
expect_error "singan-sample of a checkpoint" "checkpoint" $T singan-sample "$W/sg.tnw.ckpt" -o "$W/x.pfm"
$T noise -o "$W/sg_small.pfm" --size 16 16 --seed 5 > /dev/null 2>&1
expect_error "singan-train DEM below the coarsest scale" "smaller than the coarsest" $T singan-train "$W/sg_small.pfm" -o "$W/x.tnw"
# gnn-generate --detail: the SinGAN model adds detail to the network's terrain (same size, other
# values); a model of another method is refused
if $T gnn-generate "$W/g.tnw" "$W/ex.tns" -o "$W/gd0.pfm" --size 40x40 > /dev/null 2>&1 &&
    $T gnn-generate "$W/g.tnw" "$W/ex.tns" -o "$W/gd1.pfm" --size 40x40 --detail "$W/sg.tnw" --detail-from-scale 1 > /dev/null 2>&1 &&
    $T info "$W/gd1.pfm" | grep -q "size: 40 x 40" && ! cmp -s "$W/gd0.pfm" "$W/gd1.pfm"; then ok; else bad "gnn-generate --detail"; fi
expect_error "gnn-generate --detail with a gnn model" "singan" $T gnn-generate "$W/g.tnw" "$W/ex.tns" -o "$W/x.png" --detail "$W/g.tnw"
# GeoTIFF: read any command's DEM from .tif, write -o x.tif carrying the georeference; then GDAL
# as the reference (tests/gdal_geotiff.py) when python3-gdal and gdal-bin are installed
GT=tests/refs/tiff/int16_geographic_point.tif
if $T info "$GT" > "$W/gt_info.txt" 2>&1 && grep -q "^format: tiff$" "$W/gt_info.txt" && grep -q "^crs: geographic$" "$W/gt_info.txt" &&
    grep -q "^geotransform: 9.25 0.001 0 47.75 0 -0.00050000000000000001$" "$W/gt_info.txt" && grep -q "^spacing_m: 74.99" "$W/gt_info.txt"; then ok;
else bad "info of a GeoTIFF: $(cat "$W/gt_info.txt")"; fi
if $T convert "$GT" "$W/gt32.tif" 2>/dev/null && $T convert --bits 16 "$GT" "$W/gt16.tif" 2>/dev/null &&
    $T info "$W/gt32.tif" | grep -q "^bit_depth: 32$" && $T info "$W/gt16.tif" | grep -q "^bit_depth: 16$" &&
    [ "$($T info "$W/gt32.tif" | grep -v "^file\|^bit_depth")" = "$(grep -v "^file\|^bit_depth" "$W/gt_info.txt")" ]; then ok;
else bad "GeoTIFF -> float32 / int16 GeoTIFF keeps values and georeference"; fi
if $T render "$GT" -o "$W/gt_preview.tif" 2>/dev/null && $T info "$W/gt_preview.tif" | grep -q "^channels: 3$" &&
    $T info "$W/gt_preview.tif" | grep -q "^geotransform: 9.25 0.001"; then ok; else bad "render -o .tif keeps the georeference"; fi
if $T extract "$GT" --threshold 8 > /dev/null 2>&1 && $T export "$GT" --to glb -o "$W/gt.glb" > /dev/null 2>&1 &&
    $T convert "$W/noise.png" "$W/noise.tif" 2>/dev/null && $T metrics "$W/noise.png" "$W/noise.tif" | grep -q "^rmse: 0$"; then ok;
else bad "extract/export/metrics read .tif, convert writes it"; fi
expect_error "tiff truncated" "corrupt" sh -c "head -c 300 $GT > $W/cut.tif && $T info $W/cut.tif"
GDALPY=""
for py in python3 /usr/bin/python3; do
    if [ -z "$GDALPY" ] && command -v gdalinfo > /dev/null 2>&1 && $py -c "from osgeo import gdal" > /dev/null 2>&1; then GDALPY=$py; fi
done
if [ -n "$GDALPY" ]; then
    HGT="$D/dem/alps_n47e009/original/N47E009.hgt"
    if $GDALPY tests/gdal_geotiff.py "$T" "$W/gdal" "$HGT" > "$W/gdal.txt" 2>&1 && grep -q "gdal_geotiff: [0-9]* passed, 0 failed" "$W/gdal.txt"; then ok;
    else bad "GeoTIFF against GDAL: $(grep "FAIL\|passed\|Error" "$W/gdal.txt" | head -5)"; fi
else
    skipped "GeoTIFF against GDAL (python3-gdal / gdal-bin not installed)"
fi
# insolation / season (@@season): errors, a procedural DEM, then a real one
printf 'latitude,46\nelevation,300\nmonth,t_c,p_mm\n1,-0.3,69\n2,1.6,70\n3,6,89\n4,10.6,98\n5,15.6,109\n6,19.1,143\n7,21.1,113\n8,20.4,133\n9,15.6,147\n10,10.9,144\n11,5,129\n' > "$W/clim11.csv"
cp "$W/clim11.csv" "$W/clim.csv"; printf '12,0.8,100\n' >> "$W/clim.csv"
for c in insolation season; do
    if $T $c --help 2>&1 | grep -q "usage: terrainnet $c"; then ok; else bad "$c --help"; fi
done
expect_error "insolation no lat" "needs .*lat DEG" $T insolation "$W/noise.png" -o "$W/ins"
expect_error "insolation lat 91" "from -90 to 90" $T insolation "$W/noise.png" --lat 91 -o "$W/ins"
expect_error "season no climate" "exactly one of" $T season "$W/noise.png" -o "$W/sea"
expect_error "season 11 months" "month 12 is missing" $T season "$W/noise.png" --climate "$W/clim11.csv" -o "$W/sea"
expect_error "season unknown koppen" "unknown preset" $T season "$W/noise.png" --koppen Qxx -o "$W/sea"
if $T insolation "$W/noise.png" --lat 46 --spacing 30 -o "$W/ins" --step 30 > "$W/ins.txt" 2>/dev/null &&
    [ "$(grep -c 'pfm: month' "$W/ins.txt")" = 12 ] && $T info "$W/ins_07.pfm" | grep -q "size: 96 x 64"; then ok;
else bad "insolation year: $(cat "$W/ins.txt")"; fi
if $T season "$W/noise.png" --spacing 30 --climate "$W/clim.csv" --insolation "$W/ins" --frames 6 -o "$W/sea" > /dev/null 2>&1 &&
    [ -f "$W/sea_f005.png" ] && $T info "$W/sea_sheet.png" | grep -q "channels: 3"; then ok; else bad "season frames from a CSV"; fi
$T noise -o "$W/noise64.png" --size 64 64 --range 100 900 > /dev/null 2>&1
expect_error "season wrong-size insolation" "insolation must be 12 channels of 64 x 64" $T season "$W/noise64.png" --koppen Cfb --insolation "$W/ins" -o "$W/sea"
if [ -f "$MB" ]; then
    if $T season "$MB" --range 454 4810 --spacing 92.7 --koppen Cfb --month 2 -o "$W/mb" > /dev/null 2>&1 &&
        $T info "$W/mb_02.png" | grep -q "size: 256 x 256" && [ ! -f "$W/mb_sheet.png" ]; then ok; else bad "season --month on alps_montblanc"; fi
else
    skipped "season on a real DEM (absent)"
fi
# season-train / season --model: the KPD network on a procedural pair of months (no data needed)
$T season "$W/noise64.png" --spacing 30 --koppen Cfb --month 1 -o "$W/pa" > /dev/null 2>&1
$T season "$W/noise64.png" --spacing 30 --koppen Cfb --month 7 -o "$W/pa" > /dev/null 2>&1
printf 'dem,noise64.png\nspacing,30\nkoppen,Cfb\nframe,2017-01-15,pa_01.png\nframe,6,pa_07.png\n' > "$W/pair.csv"
if $T season-train "$W/pair.csv" -o "$W/kpd.tnw" --iters 3 --crop 32 --width 8 > "$W/kpd.txt" 2>&1 && grep -q "iterations: 3" "$W/kpd.txt" &&
    $T season "$W/noise64.png" --spacing 30 --koppen Cfb --model "$W/kpd.tnw" --frames 3 -o "$W/kf" > /dev/null 2>&1 &&
    $T info "$W/kf_f002.png" | grep -q "size: 64 x 64" && [ -f "$W/kf_sheet.png" ]; then ok; else bad "season-train + season --model: $(cat "$W/kpd.txt")"; fi
cp "$W/pair.csv" "$W/season.csv"
if $T season-train "$W" -o "$W/kpd.tnw" --iters 5 --crop 32 --width 8 --resume > "$W/kpd.txt" 2>&1 &&
    grep -q "resumed at 3" "$W/kpd.txt"; then ok; else bad "season-train --resume: $(cat "$W/kpd.txt")"; fi
expect_error "season --model of another method" "not a kpd\\|method" $T season "$W/noise64.png" --koppen Cfb --model "$W/sg.tnw" -o "$W/kx"
expect_error "season-train unknown condition" "unknown condition" $T season-train "$W/pair.csv" -o "$W/k2.tnw" --condition cond9
printf 'dem,noise64.png\nkoppen,Cfb\nframe,2017-13-01,pa_01.png\n' > "$W/bad.csv"
expect_error "season-train bad date" "neither YYYY-MM-DD" $T season-train "$W/bad.csv" -o "$W/k2.tnw"
if [ -f "$D/seasonal_slovenia/frames.csv" ]; then
    if $T season-train examples/data/slovenia_season.csv -o "$W/slo.tnw" --iters 2 --exclude 2015 > "$W/slo.txt" 2>&1 &&
        grep -q "32 usable frames, 27 for training" "$W/slo.txt"; then ok; else bad "season-train on Sentinel-2 NDVI: $(cat "$W/slo.txt")"; fi
else
    skipped "season-train on Sentinel-2 NDVI (absent)"
fi
# issue 34: the first hour of a new user
expect_usage "mistyped command" "unknown command 'rendr'; did you mean 'render'?" $T rendr a.png -o b.png
expect_usage "mistyped command, transposed" "did you mean 'singan-train'?" $T singan-trian a.png -o b.tnw
expect_error "no such file" "no_such_file.png: no such file" $T info no_such_file.png
if $T insolation --help | grep -q -- "--range LO HI" && ! $T insolation --help | grep -q -- "--heights" &&
    $T singan-train --help | grep -q -- "--range LO HI" && $T export --help | grep -q -- "--range LO HI"; then ok;
else bad "--range LO HI on insolation, singan-train and export, --heights hidden"; fi
$T noise -o "$W/unit.png" --size 48 > /dev/null 2>&1 # records no range
if $T insolation "$W/unit.png" --lat 46 --month 6 --heights 100 900 -o "$W/alias" > /dev/null 2> "$W/alias.txt" && ! grep -q "warning\|heights" "$W/alias.txt" &&
    $T insolation "$W/unit.png" --lat 46 --month 6 --range 100 900 -o "$W/alias2" > /dev/null 2>&1 && cmp -s "$W/alias_06.pfm" "$W/alias2_06.pfm"; then ok;
else bad "insolation --heights is a silent alias of --range: $(cat "$W/alias.txt")"; fi
if $T insolation "$W/unit.png" --lat 46 --month 6 -o "$W/u" 2>&1 >/dev/null | grep -q "records no height range.*give --range LO HI" &&
    $T season "$W/unit.png" --koppen Cfb --month 6 -o "$W/u" 2>&1 >/dev/null | grep -q "give --range LO HI"; then ok;
else bad "insolation/season on a unit-less DEM name --range"; fi
if $T export "$W/unit.png" --to glb -o "$W/u.glb" 2>&1 >/dev/null | grep -q "nearly flat" &&
    ! $T export "$W/unit.png" --to glb --spacing 30 --range 0 900 -o "$W/u.glb" 2>&1 >/dev/null | grep -q "warning"; then ok;
else bad "export of a unit-less DEM without --spacing warns"; fi
if $T singan-train "$W/unit.png" -o "$W/u_sg.tnw" --iters 2 --coarsest 12 > "$W/usg.txt" 2>/dev/null && grep -q "units: the file's \[0, 1\] codes" "$W/usg.txt" &&
    $T singan-train "$W/unit.png" -o "$W/m_sg.tnw" --iters 2 --coarsest 12 --range 100 900 > "$W/msg.txt" 2>/dev/null && grep -q "units: metres" "$W/msg.txt" &&
    $T singan-sample "$W/m_sg.tnw" -o "$W/m_s.pfm" > /dev/null 2>&1 && $T info "$W/m_s.pfm" | awk '/^min:/ { lo = $2 } /^max:/ { hi = $2 } END { exit !(lo > 50 && hi > 500) }'; then ok;
else bad "singan-train --range learns metres: $(cat "$W/usg.txt" "$W/msg.txt" | head -5)"; fi
# SinGAN's progress: one run, one clock, to 100 % when the scales finish before the budget
if $T singan-train "$W/unit.png" -o "$W/p_sg.tnw" --scale-iters 2 --coarsest 12 --channels 8 --minutes 5 2> "$W/psg.txt" > /dev/null &&
    grep -q "^singan-train scale [0-9]*/[0-9]*: 100%" "$W/psg.txt" && [ "$(grep -c "ETA" "$W/psg.txt")" -ge 1 ]; then ok;
else bad "singan-train progress reaches 100 %: $(tail -n 3 "$W/psg.txt")"; fi
if $T realism "$W/unit.png" "$W/noise64.png" 2>/dev/null | grep -q "^ssim: n/a (sizes differ)"; then ok; else bad "realism on two sizes: ssim n/a"; fi
if $T gnn-train "$W/noise64.png" -o "$W/h.tnw" --size 32 --iters 1 --crop 16 16 2>/dev/null | grep -q "^holdout_why: .*--crop 0 0 gives 3" ; then ok;
else bad "gnn-train says why holdout_windows is 0"; fi
if $T insolation "$W/noise64.png" --lat 46 --spacing 30 -o "$W/ip" > "$W/ip.txt" 2>/dev/null && $T info "$W/ip_03.png" | grep -q "channels: 3" &&
    $T info "$W/ip_sheet.png" | grep -q "channels: 3" && grep -q "^sheet: " "$W/ip.txt"; then ok; else bad "insolation PNG previews and year sheet"; fi
# the ramp: a DEM that records no sea paints no water; a sea level does
printf 'P2\n4 2\n9\n0 0 9 9\n0 0 9 9\n' > "$W/two.pgm"
$T render "$W/two.pgm" -o "$W/two_land.ppm" > /dev/null 2>&1
$T render "$W/two.pgm" --sea-level 0.5 -o "$W/two_sea.ppm" > /dev/null 2>&1
if [ -f "$W/two_land.ppm" ] && [ -f "$W/two_sea.ppm" ] &&
    od -An -tu1 -j 11 -N 3 "$W/two_land.ppm" | awk '{ exit !($2 > $3) }' && od -An -tu1 -j 11 -N 3 "$W/two_sea.ppm" | awk '{ exit !($3 > $1 && $3 > $2) }'; then ok;
else bad "render: green lowland without a sea level, blue below --sea-level"; fi
echo "test_cli: $pass passed, $fail failed, $skip skipped"
[ $fail -eq 0 ]
