#!/bin/sh
# make demo: a built-in procedural terrain (no data files needed), rendered as pictures in demo/,
# then restyled (style transfer) with a source heightmap: $DEM if given (make demo DEM=path),
# otherwise a built-in high-frequency procedural "dune field".
set -e
T=bin/terrainnet
mkdir -p demo
$T noise -o demo/terrain.png --type perlin --size 512 --seed 7 --octaves 8 --frequency 3 --range 200 2400
$T info demo/terrain.png
$T render demo/terrain.png -o demo/terrain_preview.png
$T render demo/terrain.png --3d --size 960 540 --relief 0.18 -o demo/terrain_view.png
echo "demo: wrote demo/terrain.png (16-bit heightmap, 200-2400 m), demo/terrain_preview.png, demo/terrain_view.png"
# noise -> style transfer -> rendered preview
SRC=${DEM:-}
if [ -z "$SRC" ]; then
    SRC=demo/style_source.png
    $T noise -o "$SRC" --type perlin --size 256 --seed 11 --octaves 3 --frequency 14 --gain 0.7 --range 180 480
fi
$T noise -o demo/style_content.png --type perlin --size 256 --seed 7 --octaves 8 --frequency 3
$T style --content demo/style_content.png --style "$SRC" -o demo/styled.png
$T render demo/styled.png -o demo/styled_preview.png
$T render "$SRC" -o demo/style_source_preview.png
echo "demo: wrote demo/styled.png (content demo/style_content.png restyled by $SRC) and demo/styled_preview.png"
