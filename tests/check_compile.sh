#!/bin/sh
# Compiles the whole header (declarations + implementation) in several configurations and fails on
# any warning. Prints one "compile_<config>: ok|FAIL" line each and a summary line.
#   sh tests/check_compile.sh          every configuration, two at a time, then the summary
#   sh tests/check_compile.sh NAME...  only these, no summary (`make test` runs each as its own job)
#   sh tests/check_compile.sh --list   the configurations' names
# -O2 only where the optimiser's warnings can differ (by target); elsewhere -O0 -c, which still
# reports unused static functions and variables (gcc's -fsyntax-only does not) and, for clang, the
# code generator's errors (an intrinsic outside its target); -fsyntax-only where the front end
# alone is the point (C++, the TN_INTERNALS configurations, whose internals are not static).
set -u
names="portable gcc_c99 clang_c99 gxx_cxx no_threads no_tls no_methods io_render internals internals_cxx internals_io_render switch_error no_internals"
if [ "${1:-}" = --list ]; then echo $names; exit 0; fi
mkdir -p build/check
tu=build/check/tu.c
# written whole, then renamed: jobs running side by side never read a half-written file
printf '#define TERRAINNET_IMPLEMENTATION\n#include "terrainnet.h"\nint main(void) { return tn_get_threads() > 0 ? 0 : 1; }\n' > "$tu.$$" && mv -f "$tu.$$" "$tu"
W="-std=c99 -Wall -Wextra -pedantic"
# Compile-out switches: the learned methods out; everything but I/O and rendering out.
methods="-DTN_NO_STYLE -DTN_NO_TEXGAN -DTN_NO_SINGAN -DTN_NO_GNN -DTN_NO_SEASON -DTN_NO_WORLD"
base="$methods -DTN_NO_ENGINE -DTN_NO_NOISE -DTN_NO_FINEDETAIL -DTN_NO_SKETCH -DTN_NO_EXTRACT -DTN_NO_EXPORT"

# Runs one configuration: 0 when it compiled without a word (or, for the last two, as expected).
one() {
    log=build/check/$1.log
    case $1 in
    # what `cc -O2 app.c` builds (the compiler's default target, x86-64 here): the optimiser's warnings
    portable)   gcc $W -O2 -march=x86-64 -I. -c "$tu" -o /dev/null ;;
    # the Makefile's build target (-march=native): its SIMD paths
    gcc_c99)    gcc $W -O0 ${ARCH:--march=native} -I. -c "$tu" -o /dev/null ;;
    clang_c99)  command -v clang > /dev/null 2>&1 || { echo "skipped: no clang"; return 0; }
                clang $W -O0 -I. -c "$tu" -o /dev/null ;;
    gxx_cxx)    g++ -x c++ -Wall -Wextra -pedantic -fsyntax-only -I. "$tu" ;;
    no_threads) gcc $W -O0 -DTN_NO_THREADS -I. -c "$tu" -o /dev/null ;;
    no_tls)     gcc $W -O0 -DTN_NO_TLS -I. -c "$tu" -o /dev/null ;;
    no_methods) gcc $W -O0 $methods -I. -c "$tu" -o /dev/null ;;
    io_render)  gcc $W -O2 $base -I. -c "$tu" -o /dev/null ;;
    # TN_INTERNALS (the internals block, exported): whole and reduced, as C and C++
    internals)  gcc $W -fsyntax-only -DTN_INTERNALS -I. "$tu" ;;
    internals_cxx) g++ -x c++ -Wall -Wextra -pedantic -fsyntax-only -DTN_INTERNALS -I. "$tu" ;;
    internals_io_render) gcc $W -fsyntax-only $base -DTN_INTERNALS -I. "$tu" ;;
    # A part whose dependency is compiled out stops with an #error that names the switch to add.
    switch_error)
        if gcc -std=c99 -DTN_NO_ENGINE -DTN_NO_STYLE -DTN_NO_TEXGAN -DTN_NO_SINGAN -DTN_NO_SEASON -DTN_NO_WORLD -I. \
                -fsyntax-only "$tu" > "$log.all" 2>&1; then echo "TN_NO_ENGINE without TN_NO_GNN compiled"; return 1; fi
        grep -q '@@gnn needs the tensor engine.*define TN_NO_GNN' "$log.all" || { head -n 5 "$log.all"; return 1; } ;;
    # A program without TN_INTERNALS sees none of the internals block.
    no_internals)
        printf '#include "terrainnet.h"\n#if defined(TN__INTERNALS_H) || defined(TN__TLS) || defined(TN__GNN_DIST)\n#error internals visible\n#endif\nint main(void) { return tn_get_threads() > 0 ? 0 : 1; }\n' > build/check/public.c
        gcc $W -fsyntax-only -I. build/check/public.c ;;
    *) echo "check_compile.sh: no configuration $1 (--list)"; return 1 ;;
    esac
}
# Prints compile_NAME: ok, or FAIL and the start of its messages; returns 1 on FAIL.
check() {
    one "$1" > "build/check/$1.log" 2>&1; rc=$?
    if [ $rc -eq 0 ] && [ ! -s "build/check/$1.log" ]; then echo "compile_$1: ok"; return 0; fi
    if [ $rc -eq 0 ] && grep -q '^skipped: ' "build/check/$1.log"; then echo "compile_$1: $(cat "build/check/$1.log")"; return 0; fi
    echo "compile_$1: FAIL"; head -n 20 "build/check/$1.log"; return 1
}

if [ $# -gt 0 ]; then
    fail=0
    for n in "$@"; do check "$n" || fail=1; done
    exit $fail
fi
# All of them, two at a time, results in order.
set -- $names
while [ $# -gt 0 ]; do
    check "$1" > "build/check/$1.out" & a=$!
    if [ $# -gt 1 ]; then check "$2" > "build/check/$2.out"; shift; fi
    wait $a
    shift
done
pass=0; fail=0; skip=0
for n in $names; do
    cat "build/check/$n.out"
    if grep -q "^compile_$n: FAIL" "build/check/$n.out"; then fail=$((fail + 1))
    elif grep -q "^compile_$n: skipped" "build/check/$n.out"; then skip=$((skip + 1)); else pass=$((pass + 1)); fi
done
echo "check_compile: $pass passed, $fail failed, $skip skipped"
[ "$fail" -eq 0 ]
