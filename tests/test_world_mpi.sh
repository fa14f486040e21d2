#!/bin/sh
# The same world from one process (terrainnet world) and from 2 MPI ranks (bin/world_mpi): every
# tile must be byte-for-byte the same. test_cli.sh runs it when mpirun exists; prints
# "test_world_mpi: N passed, N failed, N skipped".
set -u
W=build/test/world_mpi
pass=0; fail=0; skip=0
if ! command -v mpirun >/dev/null 2>&1 || ! command -v mpicc >/dev/null 2>&1; then
    echo "skipped test_world_mpi: no mpirun/mpicc"; echo "test_world_mpi: 0 passed, 0 failed, 1 skipped"; exit 0
fi
rm -rf "$W"; mkdir -p "$W"
cat > "$W/w.spec" <<SPEC
world 700 500
seed 9
height 0 2000
cellsize 20
tile 128
perlin frequency=6 octaves=8
blur sigma=1.5
SPEC
if make -s mpi > "$W/make.txt" 2>&1 && [ -x bin/world_mpi ]; then pass=$((pass + 1)); else echo "FAIL test_world_mpi: make mpi"; cat "$W/make.txt"; fail=$((fail + 1)); fi
bin/terrainnet world "$W/w.spec" -o "$W/one" > "$W/one.txt" 2>&1 || { echo "FAIL test_world_mpi: single run"; fail=$((fail + 1)); }
if mpirun --allow-run-as-root --oversubscribe -np 2 bin/world_mpi "$W/w.spec" "$W/two" > "$W/two.txt" 2>&1 &&
    grep -q "rank 1 of 2: [1-9]" "$W/two.txt"; then pass=$((pass + 1));
else echo "FAIL test_world_mpi: mpirun -np 2"; cat "$W/two.txt"; fail=$((fail + 1)); fi
n=0
for f in "$W"/one/r*_c*.png; do
    n=$((n + 1))
    if cmp -s "$f" "$W/two/$(basename "$f")"; then :; else echo "FAIL test_world_mpi: $(basename "$f") differs"; fail=$((fail + 1)); fi
done
if [ "$n" -eq 24 ] && cmp -s "$W/one/manifest.txt" "$W/two/manifest.txt" && cmp -s "$W/one/world.vrt" "$W/two/world.vrt"; then pass=$((pass + 1));
else echo "FAIL test_world_mpi: $n tiles (want 24), or the manifests/VRTs differ"; fail=$((fail + 1)); fi
echo "test_world_mpi: $pass passed, $fail failed, $skip skipped"
[ $fail -eq 0 ]
