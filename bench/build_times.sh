#!/bin/sh
# Build times against one -O2 compile of the implementation, all in one run (the machine's load
# changes from run to run; the ratios are what to compare). Run from the repository root.
# Prints `name: value unit` lines:
#   compile_impl_o2: one `cc -O2` compile of src/terrainnet.c (the whole implementation)
#   make_all_B / make_all_ratio: `make -B -j2 all` (CLI, examples, benches) and its ratio to it
#   make_test / make_test_ratio: `make test` from no test build, and its ratio (runs every test)
#   io_render_size: examples/preview_only.c, which loads, renders and saves with every other
#                   part compiled out (TN_NO_...); full_example_size: render_terrain beside it
set -eu
now() { date +%s.%N; }
el() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f", b - a }'; }
ratio() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", a / b }'; }
mkdir -p build/times
t0=$(now); ${CC:-cc} -std=c99 -O2 -march=native -c src/terrainnet.c -o build/times/impl.o; t1=$(now)
one=$(el "$t0" "$t1"); echo "compile_impl_o2: $one s"
t0=$(now); make -B -j2 all > build/times/all.log 2>&1; t1=$(now)
all=$(el "$t0" "$t1"); echo "make_all_B: $all s"; echo "make_all_ratio: $(ratio "$all" "$one") x"
make bin/preview_only bin/render_terrain > /dev/null
echo "io_render_size: $(wc -c < bin/preview_only) bytes"
echo "full_example_size: $(wc -c < bin/render_terrain) bytes"
rm -rf build/test build/terrainnet_san.o
t0=$(now); make test > build/times/test.log 2>&1 || echo "make test failed (build/times/test.log)"; t1=$(now)
tst=$(el "$t0" "$t1"); echo "make_test: $tst s"; echo "make_test_ratio: $(ratio "$tst" "$one") x"
