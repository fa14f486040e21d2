#!/bin/sh
# Trains the studio's bundled styles: one gnn-train model per region of ../shared/data on the
# 128 px crop the MANIFEST names (the _full DEM with --crop, so the holdout windows around it
# pick the early network drawings run on), MINUTES each on one thread, into
# examples/data/styles/. Then writes the self-test's native reference: the CLI's gnn-generate of
# the bundled test sketch (examples/data/sketch_summit.tns) at 256 x 256 with the selftest style,
# as float32 .pfm beside it, and styles.json, the list the page reads.
# Re-runnable: every output is rewritten (run it again when the model format changes), then
# `make studio` copies the styles into studio/styles/.
#   sh studio/make_styles.sh                        # every style, 3 minutes each (~16 min)
#   MINUTES=1 STYLES="alps moon" sh studio/make_styles.sh   # train these two again
#   REFERENCE_ONLY=1 sh studio/make_styles.sh       # the models as they are: only the reference
#                                                   # and styles.json (after a change to generation)
set -eu
cd "$(dirname "$0")/.."
DATA=${DATA:-../shared/data}
OUT=examples/data/styles
MINUTES=${MINUTES:-3}
ALL="alps grandcanyon himalaya moon dunes"
STYLES=${STYLES:-$ALL}               # the ones to train; styles.json lists every one there is
REFERENCE_ONLY=${REFERENCE_ONLY:-0}
SELFTEST=alps                        # the style the self-test generates with
TN=bin/terrainnet
[ -f "$DATA/dem_index.csv" ] || { echo "make_styles: no $DATA/dem_index.csv (set DATA=)"; exit 1; }
make --no-print-directory -j2 $TN
mkdir -p "$OUT" build/styles

# name: region, crop x y (the 128 crop of the MANIFEST: "rows Y-.. cols X-.."), label
spec() {
    case $1 in
    alps)        echo "alps_montblanc 176 224 Alps (Mont Blanc)" ;;
    grandcanyon) echo "grandcanyon_hoppe8bit 224 480 Grand Canyon (grey levels)" ;;
    himalaya)    echo "himalaya_everest 208 320 Himalaya (Everest)" ;;
    moon)        echo "moon_nearside_lola4ppd 432 192 Moon (near side)" ;;
    dunes)       echo "sahara_erg_oriental 64 456 Sahara dunes (Grand Erg Oriental)" ;;
    *) echo "make_styles: unknown style $1" >&2; exit 1 ;;
    esac
}
json="["
sep=""
for s in $ALL; do
    set -- $(spec "$s")
    region=$1; cx=$2; cy=$3; shift 3; label="$*"
    dem="$DATA/dem/$region/${region}_full.png"
    # the metre mapping of the 16-bit codes and the pixel spacing (dem_index.csv)
    row=$(awk -F, -v p="dem/$region/${region}_full.png" '$1 == p { print $8, $9, ($6 == "" ? "null" : $6); exit }' "$DATA/dem_index.csv")
    [ -n "$row" ] || { echo "make_styles: $region not in dem_index.csv"; exit 1; }
    set -- $row
    range="$1 $2"; dx=$3
    if [ "$REFERENCE_ONLY" != 1 ] && echo " $STYLES " | grep -q " $s "; then
        ckpt=build/styles/$s.tnw.ckpt
        rm -f "$ckpt"
        echo "== $s: $TN --threads 1 gnn-train $dem --crop $cx $cy --range $range --minutes $MINUTES -o $OUT/$s.tnw"
        # shellcheck disable=SC2086
        $TN --threads 1 gnn-train "$dem" --crop $cx $cy --range $range --minutes "$MINUTES" \
            --checkpoint "$ckpt" -o "$OUT/$s.tnw" > "build/styles/$s.log" 2>&1 || { tail -n 5 "build/styles/$s.log"; exit 1; }
        rm -f "$ckpt"
        grep -E '^(iterations|holdout_ssim|gain_scale)' "build/styles/$s.log" || tail -n 4 "build/styles/$s.log"
    fi
    [ -f "$OUT/$s.tnw" ] || continue
    echo "$s.tnw: $(wc -c < "$OUT/$s.tnw") bytes"
    json="$json$sep
  {\"id\": \"$s\", \"file\": \"$s.tnw\", \"label\": \"$label\", \"region\": \"$region\", \"range\": [$(echo $range | tr ' ' ',')], \"dx\": $dx, \"crop\": [$cx, $cy], \"minutes\": $MINUTES}"
    sep=","
done
printf '%s\n]\n' "$json" > "$OUT/styles.json"

# The self-test's reference: what the native CLI makes of the test sketch with the library's
# default options (--finetune 0: the CLI alone fine-tunes drawings that are not densified),
# built without -march, so with the portable kernels the wasm has: the AVX2/FMA ones round
# differently, and one flipped fine-detail match puts pixels 1e-3 of the range apart.
cp examples/data/sketch_summit.tns "$OUT/selftest_sketch.tns"
if [ -f "$OUT/$SELFTEST.tnw" ]; then
    TN=build/styles/terrainnet-portable
    echo "== $TN: ${CC:-cc} -std=c99 -O2 examples/cli/terrainnet.c (no -march)"
    ${CC:-cc} -std=c99 -O2 -I. examples/cli/terrainnet.c -o $TN -lm -pthread
    echo "== selftest reference: $TN --threads 1 gnn-generate $OUT/$SELFTEST.tnw $OUT/selftest_sketch.tns --size 256x256 --seed 1 --finetune 0 -o $OUT/$SELFTEST.selftest.pfm"
    $TN --threads 1 gnn-generate "$OUT/$SELFTEST.tnw" "$OUT/selftest_sketch.tns" --size 256x256 --seed 1 --finetune 0 \
        -o "$OUT/$SELFTEST.selftest.pfm" | grep -E '^(grown_lines|residual_gain|seconds|height_range)'
    printf '{"style": "%s", "sketch": "selftest_sketch.tns", "width": 256, "height": 256, "seed": 1, "reference": "%s.selftest.pfm"}\n' \
        "$SELFTEST" "$SELFTEST" > "$OUT/selftest.json"
fi
echo "make_styles: wrote $OUT: $(cd "$OUT" && ls | tr '\n' ' ')"
