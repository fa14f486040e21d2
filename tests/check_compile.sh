#!/bin/sh
# Compiles the whole header (declarations + implementation) in several configurations and fails on
# any warning. Prints one "compile_<config>: ok|FAIL" line each and a summary line. -O2 where the
# optimiser's warnings can differ (by compiler or target); the front end alone for the rest.
set -u
mkdir -p build/check
tu=build/check/tu.c
printf '#define TERRAINNET_IMPLEMENTATION\n#include "terrainnet.h"\nint main(void) { return tn_get_threads() > 0 ? 0 : 1; }\n' > "$tu"
pass=0; fail=0
# Two compiles at a time (each is a whole implementation); results are read back in order.
names=""
run() {
    name=$1; shift
    names="$names $name"
    ( "$@" > "build/check/$name.log" 2>&1; echo $? > "build/check/$name.rc" ) &
    [ $(( $(echo $names | wc -w) % 2 )) -eq 0 ] && wait
    return 0
}
report() {
    wait
    for name in $names; do
        if [ "$(cat "build/check/$name.rc")" = 0 ] && [ ! -s "build/check/$name.log" ]; then
            echo "compile_$name: ok"; pass=$((pass + 1))
        else echo "compile_$name: FAIL"; head -n 20 "build/check/$name.log"; fail=$((fail + 1)); fi
    done
}
run gcc_c99     gcc   -std=c99 -Wall -Wextra -pedantic -O2 -I. -c "$tu" -o build/check/gcc.o
if command -v clang >/dev/null 2>&1; then
run clang_c99   clang -std=c99 -Wall -Wextra -pedantic -O2 -I. -c "$tu" -o build/check/clang.o
fi
run gxx_cxx     g++   -x c++ -Wall -Wextra -pedantic -fsyntax-only -I. "$tu"
run no_threads  gcc   -std=c99 -Wall -Wextra -pedantic -fsyntax-only -DTN_NO_THREADS -I. "$tu"
run no_tls      gcc   -std=c99 -Wall -Wextra -pedantic -fsyntax-only -DTN_NO_TLS -I. "$tu"
run portable    gcc   -std=c99 -Wall -Wextra -pedantic -O2 -march=x86-64 -I. -c "$tu" -o build/check/portable.o
# Compile-out switches: the learned methods out; everything but I/O and rendering out.
methods="-DTN_NO_STYLE -DTN_NO_TEXGAN -DTN_NO_SINGAN -DTN_NO_GNN -DTN_NO_SEASON -DTN_NO_WORLD"
base="$methods -DTN_NO_ENGINE -DTN_NO_NOISE -DTN_NO_FINEDETAIL -DTN_NO_SKETCH -DTN_NO_EXTRACT -DTN_NO_EXPORT"
run no_methods  gcc   -std=c99 -Wall -Wextra -pedantic -O2 $methods -I. -c "$tu" -o build/check/nomethods.o
run io_render   gcc   -std=c99 -Wall -Wextra -pedantic -O2 $base -I. -c "$tu" -o build/check/iorender.o
# TN_INTERNALS (the internals block, exported): whole and reduced, as C and C++.
run internals   gcc   -std=c99 -Wall -Wextra -pedantic -fsyntax-only -DTN_INTERNALS -I. "$tu"
run internals_cxx g++ -x c++ -Wall -Wextra -pedantic -fsyntax-only -DTN_INTERNALS -I. "$tu"
run internals_io_render gcc -std=c99 -Wall -Wextra -pedantic -fsyntax-only $base -DTN_INTERNALS -I. "$tu"
report
# A part whose dependency is compiled out stops with an #error that names the switch to add.
if out=$(gcc -std=c99 -DTN_NO_ENGINE -DTN_NO_STYLE -DTN_NO_TEXGAN -DTN_NO_SINGAN -DTN_NO_SEASON -DTN_NO_WORLD -I. \
        -fsyntax-only "$tu" 2>&1); then echo "compile_switch_error: FAIL (TN_NO_ENGINE without TN_NO_GNN compiled)"; fail=$((fail + 1))
elif echo "$out" | grep -q '@@gnn needs the tensor engine.*define TN_NO_GNN'; then echo "compile_switch_error: ok"; pass=$((pass + 1))
else echo "compile_switch_error: FAIL"; echo "$out" | head -n 5; fail=$((fail + 1)); fi
# A program without TN_INTERNALS sees none of the internals block.
printf '#include "terrainnet.h"\n#if defined(TN__INTERNALS_H) || defined(TN__TLS) || defined(TN__GNN_DIST)\n#error internals visible\n#endif\nint main(void) { return tn_get_threads() > 0 ? 0 : 1; }\n' > build/check/public.c
if out=$(gcc -std=c99 -Wall -Wextra -pedantic -fsyntax-only -I. build/check/public.c 2>&1) && [ -z "$out" ]; then
    echo "compile_no_internals: ok"; pass=$((pass + 1))
else echo "compile_no_internals: FAIL"; echo "$out" | head -n 5; fail=$((fail + 1)); fi
echo "check_compile: $pass passed, $fail failed, 0 skipped"
[ "$fail" -eq 0 ]
