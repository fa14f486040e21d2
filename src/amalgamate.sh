#!/bin/sh
# Writes terrainnet.h to stdout from the files in src/: the manual and table of contents, every
# section's declarations in order, the implementation's prologue, every section's implementation
# in the same order, the epilogue. A section file holds its declarations, then its implementation
# from its first ">>" banner on. `make header` runs this; never edit terrainnet.h by hand.
set -eu
src=$(dirname "$0")
SECTIONS="core thread image io io_formats metrics gemm tensor ops loss optim train noise finedetail sketch
extract style texgan singan gnn gnn_membrane gnn_grow gnn_scale season method render export world"
part() { # part api|impl FILE
    awk -v part="$1" '
        { line[NR] = $0 }
        END {
            cut = NR + 1
            for (i = 1; i < NR; i++)
                if (line[i] ~ /^\/\* ----/ && line[i + 1] ~ /^   >>[a-z]/) { cut = i; break }
            if (part == "api") { for (i = 1; i < cut; i++) print line[i] }
            else { for (i = cut; i <= NR; i++) print line[i] }
        }' "$2"
}
cat "$src/manual.h"
for s in $SECTIONS; do part api "$src/$s.c"; done
# the internals block (TN_INTERNALS) right after "end header file", before the implementation
awk -v f="$src/internal.h" '{ print } /^\/\* \/\/\/\/ end header file/ { print ""; while ((getline l < f) > 0) print l }' "$src/impl_begin.h"
for s in $SECTIONS; do part impl "$src/$s.c"; done
cat "$src/impl_end.h"
