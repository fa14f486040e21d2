#!/bin/sh
# make demo: learn from one real DEM (examples/data/alps_n47e009_256.png, an SRTM crop of the Alps)
# and write a one-page demo/index.html: each picture beside the command that made it.
#
#   sh examples/demo.sh                 minutes on 2 cores (GNN, texture GAN: DEMO_MINUTES=2 each;
#                                       SinGAN: SINGAN_MINUTES=10, its default budget)
#   DEMO_FAST=1 sh examples/demo.sh     seconds-long budgets, for tests (pictures are rough)
#   DEMO_DIR=out DEM=my.png DEM_SPACING="30 30" sh examples/demo.sh   another place, another example
#   KPD=slo.tnw sh examples/demo.sh    adds the seasons of a KPD network from season-train
#
# The page is data-driven: STEPS below lists one picture per line (`name  title`), and each name
# has a function step_<name> that runs its commands through `run` and names its picture in PIC
# (and an optional download in LINK). To show a new method, write its step_ function and add
# its line to STEPS; nothing else changes.
set -e
T=${T:-bin/terrainnet}
OUT=${DEMO_DIR:-demo}
DATA=examples/data
DEM=${DEM:-$DATA/alps_n47e009_256.png}
DEM_SPACING=${DEM_SPACING:-62.6 92.6}   # metres per pixel east-west, north-south (examples/data/README.md)
DEM_LAT=${DEM_LAT:-47.1}                # latitude of the example, for the sun
DEM_KOPPEN=${DEM_KOPPEN:-Dfb}           # its climate (Köppen): Vorarlberg's valleys Cfb, the heights Dfb
TEXTURE=${TEXTURE:-$DATA/grass_128.png}
DEM_ABOUT=${DEM_ABOUT:-'256 x 256 samples of the SRTM 3" tile N47E009 (NASA/USGS, public domain): Liechtenstein and
Vorarlberg, the Rhine valley and the northern Rätikon, 431-2908 m, 62.6 x 92.6 m per pixel.'}
TEXTURE_ABOUT=${TEXTURE_ABOUT:-'128 x 128 crop of three.js grasslight-big (CC BY 3.0, from opengameart.org).'}
if [ -n "${DEMO_FAST:-}" ]; then
    STYLE_ARGS="--size 64 --iters 3 --levels 1"; TEXGAN_ARGS="--iters 2 --patch 32 --gen-width 16 --disc-width 8"
    VIEW_SIZE="320 180"; DETAIL_SIZE=256x256; GNN_ARGS="--iters 3"; SINGAN_ARGS="--channels 8 --scale-iters 1 --iters 9"
else
    STYLE_ARGS=""; TEXGAN_ARGS="--minutes ${DEMO_MINUTES:-2}"; VIEW_SIZE="960 540"; DETAIL_SIZE=1024x1024
    GNN_ARGS="--minutes ${DEMO_MINUTES:-2}"; SINGAN_ARGS="--minutes ${SINGAN_MINUTES:-10}"
fi

# One line per picture, in page order: `name  title`.
STEPS='
example  The example: a real DEM (SRTM 3", Alps), hillshaded colour map
ridges   Its ridges (yellow) and valleys (blue), extracted
noise    Input for style transfer: Perlin noise (no learning)
style    Style transfer: that noise restyled by the example
gnn      Sketch to terrain: the letter A ridge in a circular valley (examples/data/sketch_a.tns), in the style of the example (densified by example, with its fine detail)
singan   SinGAN: new terrain like the example, 1.5 times its size, laid out by the example (a new sample, not a copy)
texture  Texture GAN: grass learnt from one photo over the example; left tiled, right detail-mapped; top far, bottom near
splat    Splat map: vegetation, bare ground, rock, snow weights
view3d   3D preview of the example
glb      Engine exports: glTF 2.0 mesh (splat colours draped), Unity RAW, normal map (shown)
sun      Insolation: direct sun per month with terrain shadows (paper 003), one scale for the year
seasons  Seasons: the example through the year, textured by the procedural model for its climate
'
[ -z "${KPD:-}" ] || STEPS="${STEPS}kpd      Seasons by the KPD network ($(basename "$KPD")), learnt from dated pictures
"
# ---- steps: each runs its commands with `run` and sets PIC (and LINK) ------------------------

step_example() {
    run $T info "$DEM"
    run $T render "$DEM" -o "$OUT/example.png"
    PIC=example.png
}
step_ridges() {
    run $T extract "$DEM" --preview "$OUT/ridges.png" -o "$OUT/ridges.tns"
    PIC=ridges.png; LINK=ridges.tns
}
step_noise() {
    run $T noise -o "$OUT/noise.png" --type perlin --size 256 --seed 7 --octaves 8 --frequency 3
    run $T render "$OUT/noise.png" -o "$OUT/noise_preview.png"
    PIC=noise_preview.png; LINK=noise.png
}
step_style() { # restyles the noise step's map
    run $T style --content "$OUT/noise.png" --style "$DEM" -o "$OUT/styled.png" $STYLE_ARGS
    run $T render "$OUT/styled.png" -o "$OUT/styled_preview.png"
    PIC=styled_preview.png; LINK=styled.png
}
step_gnn() {
    run $T gnn-train "$DEM" -o "$OUT/gnn.tnw" $GNN_ARGS
    run $T gnn-generate "$OUT/gnn.tnw" $DATA/sketch_a.tns -o "$OUT/sketch_terrain.png" --size 256x256 --preview "$OUT/sketch_terrain_preview.png"
    PIC=sketch_terrain_preview.png; LINK=sketch_terrain.png
}
step_singan() {
    run $T singan-train "$DEM" -o "$OUT/singan.tnw" $SINGAN_ARGS
    run $T singan-sample "$OUT/singan.tnw" -o "$OUT/singan_sample.png" --size 384x384 --seed 7 --layout
    run $T render "$OUT/singan_sample.png" -o "$OUT/singan_preview.png"
    PIC=singan_preview.png; LINK=singan_sample.png
}
step_texture() {
    run $T texgan-train "$TEXTURE" -o "$OUT/grass.tnw" $TEXGAN_ARGS
    run $T detail-maps "$OUT/grass.tnw" "$TEXTURE" -o "$OUT/grass" --size $DETAIL_SIZE --preview "$OUT/texture.png" --dem "$DEM"
    PIC=texture.png; LINK=grass.tnw
}
step_splat() {
    run $T export "$DEM" --to splat -o "$OUT/splat.png" --spacing $DEM_SPACING --splat-preview "$OUT/splat_preview.png"
    PIC=splat_preview.png; LINK=splat.png
}
step_view3d() {
    run $T render "$DEM" --3d --size $VIEW_SIZE --relief 0.18 -o "$OUT/view3d.png"
    PIC=view3d.png
}
step_glb() { # drapes the splat step's colours
    run $T export "$DEM" --to glb -o "$OUT/terrain.glb" --spacing $DEM_SPACING --texture "$OUT/splat_preview.png"
    run $T export "$DEM" --to unity-raw -o "$OUT/terrain.raw"
    run $T export "$DEM" --to normal -o "$OUT/normal.png" --spacing $DEM_SPACING
    PIC=normal.png; LINK=terrain.glb
}
step_sun() {
    run $T insolation "$DEM" --spacing $DEM_SPACING --lat $DEM_LAT -o "$OUT/sun"
    PIC=sun_sheet.png; LINK=sun_07.pfm
}
step_seasons() { # reads the sun step's insolation
    run $T season "$DEM" --spacing $DEM_SPACING --lat $DEM_LAT --koppen $DEM_KOPPEN --insolation "$OUT/sun" -o "$OUT/season" --columns 4
    PIC=season_sheet.png; LINK=season_07.png
}
step_kpd() {
    run $T season "$DEM" --spacing $DEM_SPACING --lat $DEM_LAT --koppen $DEM_KOPPEN --model "$KPD" -o "$OUT/kpd" --columns 4
    PIC=kpd_sheet.png
}

# ---- machinery: run the steps, collect commands, write the page ------------------------------

# Runs a command, echoing it, and keeps it for the picture's caption (with $OUT/ shortened).
run() {
    echo "+ $*" >&2
    CMDS="$CMDS$(echo "$*" | sed "s|$OUT/||g; s|&|\&amp;|g; s|<|\&lt;|g; s|>|\&gt;|g")
"
    "$@"
}

[ -x "$T" ] || { echo "demo: $T is missing (run make)" >&2; exit 1; }
[ -f "$DEM" ] || { echo "demo: $DEM is missing" >&2; exit 1; }
mkdir -p "$OUT"
t0=$(date +%s)
FIGS=""
n=0
echo "$STEPS" | while read -r name title; do
    [ -n "$name" ] || continue
    CMDS=""; PIC=""; LINK=""
    echo "== demo: $name" >&2
    s0=$(date +%s)
    "step_$name" > "$OUT/$name.log"
    s1=$(date +%s)
    [ -f "$OUT/$PIC" ] || { echo "demo: step $name made no picture $PIC" >&2; exit 1; }
    printf '<figure id="%s"><a href="%s"><img src="%s" alt="%s"></a><figcaption><b>%s</b> <i>(%d s)</i>' \
        "$name" "${LINK:-$PIC}" "$PIC" "$name" "$title" $((s1 - s0))
    [ -z "$LINK" ] || printf ' &middot; <a href="%s">%s</a>' "$LINK" "$LINK"
    printf '<pre>%s</pre></figcaption></figure>\n' "$CMDS"
done > "$OUT/figures.html"
t1=$(date +%s)

cat > "$OUT/index.html" <<EOF
<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>terrainnet demo</title>
<style>
body { margin: 16px; font: 14px/1.35 sans-serif; background: #f4f4f0; color: #222; }
header { max-width: 1400px; }
main { display: flex; flex-wrap: wrap; gap: 16px; }
figure { margin: 0; width: 320px; background: #fff; padding: 8px; box-shadow: 0 1px 3px #0003; }
figure img { width: 320px; height: 320px; object-fit: contain; background: #ddd; display: block; }
figcaption { margin-top: 6px; }
pre { white-space: pre-wrap; word-break: break-all; font-size: 11px; background: #f0f0f0; padding: 4px; margin: 4px 0 0; }
</style></head>
<body>
<header><h1>terrainnet: learning from one example</h1>
<p><b>$(grep -c '<figure' "$OUT/figures.html") pictures in $((t1 - t0)) s</b> ($(($((t1 - t0)) / 60)) min $(($((t1 - t0)) % 60)) s) on this machine,
each step's seconds under its picture$([ -n "${DEMO_FAST:-}" ] && echo ', in the fast mode (seconds-long budgets: rough pictures)').</p>
<p>The example is <code>$(basename "$DEM")</code>: $DEM_ABOUT The texture exemplar is <code>$(basename "$TEXTURE")</code>:
$TEXTURE_ABOUT (Sources: examples/data/README.md.) Each picture shows the commands that made it (click it for the full-size file or the download).</p></header>
<main>
$(cat "$OUT/figures.html")
</main>
<script>
// For tests: each picture's load state and box, read back by tests/demo_page.sh from the DOM.
window.addEventListener('load', function () {
  var out = [];
  document.querySelectorAll('figure img').forEach(function (im) {
    var r = im.getBoundingClientRect();
    out.push([im.complete && im.naturalWidth > 0 ? 1 : 0, Math.round(r.left), Math.round(r.top), Math.round(r.width), Math.round(r.height)].join(' '));
  });
  var p = document.createElement('pre'); p.id = 'demo-state'; p.hidden = true;
  p.textContent = 'images: ' + out.length + '\n' + out.join('\n');
  document.body.appendChild(p);
});
</script>
</body></html>
EOF
rm -f "$OUT/figures.html"
echo "demo: wrote $OUT/index.html ($(grep -c '<figure' "$OUT/index.html") pictures, $((t1 - t0)) s)"
