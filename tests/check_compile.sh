#!/bin/sh
# Compiles the whole header (declarations + implementation) in several configurations and fails on
# any warning. Prints one "compile_<config>: ok|FAIL" line each and a summary line.
set -u
mkdir -p build/check
tu=build/check/tu.c
printf '#define TERRAINNET_IMPLEMENTATION\n#include "terrainnet.h"\nint main(void) { return tn_get_threads() > 0 ? 0 : 1; }\n' > "$tu"
pass=0; fail=0
run() {
    name=$1; shift
    if out=$("$@" 2>&1) && [ -z "$out" ]; then echo "compile_$name: ok"; pass=$((pass + 1));
    else echo "compile_$name: FAIL"; echo "$out" | head -n 20; fail=$((fail + 1)); fi
}
run gcc_c99     gcc   -std=c99 -Wall -Wextra -pedantic -O2 -I. -c "$tu" -o build/check/gcc.o
if command -v clang >/dev/null 2>&1; then
run clang_c99   clang -std=c99 -Wall -Wextra -pedantic -O2 -I. -c "$tu" -o build/check/clang.o
fi
run gxx_cxx     g++   -x c++ -Wall -Wextra -pedantic -O2 -I. -c "$tu" -o build/check/gxx.o
run no_threads  gcc   -std=c99 -Wall -Wextra -pedantic -O2 -DTN_NO_THREADS -I. -c "$tu" -o build/check/nothreads.o
run no_tls      gcc   -std=c99 -Wall -Wextra -pedantic -O2 -DTN_NO_TLS -I. -c "$tu" -o build/check/notls.o
run portable    gcc   -std=c99 -Wall -Wextra -pedantic -O2 -march=x86-64 -I. -c "$tu" -o build/check/portable.o
echo "check_compile: $pass passed, $fail failed, 0 skipped"
[ "$fail" -eq 0 ]
