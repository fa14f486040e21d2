#!/bin/sh
# make demo: a built-in procedural terrain (no data files needed), rendered as pictures in demo/.
set -e
T=bin/terrainnet
mkdir -p demo
$T noise -o demo/terrain.png --type perlin --size 512 --seed 7 --octaves 8 --frequency 3 --range 200 2400
$T info demo/terrain.png
$T render demo/terrain.png -o demo/terrain_preview.png
$T render demo/terrain.png --3d --size 960 540 --relief 0.18 -o demo/terrain_view.png
echo "demo: wrote demo/terrain.png (16-bit heightmap, 200-2400 m), demo/terrain_preview.png, demo/terrain_view.png"
