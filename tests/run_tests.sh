#!/bin/sh
# `make test`'s runner, in two parts:
#   sh tests/run_tests.sh --run NAME CMD...  runs CMD into build/test/par/NAME.out, its CPU and wall
#                                            seconds into NAME.time, then its exit status into
#                                            NAME.rc (the make target); always succeeds
#   sh tests/run_tests.sh NAME...            reads those back in the order given, sums their
#                                            "<name>: N passed, N failed, N skipped" lines into one
#                                            closing line (the compile_* jobs into one for
#                                            check_compile) and lists the slowest jobs
set -u
par=build/test/par
if [ "${1:-}" = --run ]; then
    n=$2; shift 2
    mkdir -p "$par"
    t0=$(date +%s)
    "$@" > "$par/$n.out" 2>&1
    rc=$?
    { times; echo "$t0 $(date +%s)"; } > "$par/$n.time"
    echo $rc > "$par/$n.rc"
    exit 0
fi
P=0; F=0; S=0
log=build/test/last_run.log
: > "$log"
tally() { # reads the summary line of one program's output
    line=$(grep -E '^[A-Za-z0-9_./-]+: [0-9]+ passed, [0-9]+ failed, [0-9]+ skipped$' "$1" | tail -n 1)
    if [ -z "$line" ]; then echo "$2: no summary line (crashed?)"; F=$((F + 1)); return; fi
    echo "$line"
    p=$(echo "$line" | sed -E 's/.*: ([0-9]+) passed.*/\1/')
    f=$(echo "$line" | sed -E 's/.* ([0-9]+) failed.*/\1/')
    s=$(echo "$line" | sed -E 's/.* ([0-9]+) skipped$/\1/')
    P=$((P + p)); F=$((F + f)); S=$((S + s))
}
# the compile_* jobs: one check_compile line where the first of them is named
cp=0; cf=0; cs=0; cmsg=build/test/compile_msgs.txt
: > "$cmsg"
for n in "$@"; do
    case $n in compile_*) ;; *) continue ;; esac
    [ -f "$par/$n.out" ] && cat "$par/$n.out" >> "$log"
    rc=$(cat "$par/$n.rc" 2>/dev/null || echo 1)
    if [ "$rc" = 0 ] && grep -q "^$n: ok$" "$par/$n.out"; then cp=$((cp + 1))
    elif [ "$rc" = 0 ] && grep -q "^$n: skipped" "$par/$n.out"; then cs=$((cs + 1)); cat "$par/$n.out" >> "$cmsg"
    else cf=$((cf + 1)); cat "$par/$n.out" >> "$cmsg" 2>/dev/null || echo "$n: did not run" >> "$cmsg"; fi
done
done_compile=0
for n in "$@"; do
    case $n in compile_*)
        if [ $done_compile -eq 0 ]; then
            cat "$cmsg"; echo "check_compile: $cp passed, $cf failed, $cs skipped"
            P=$((P + cp)); F=$((F + cf)); S=$((S + cs)); done_compile=1
        fi
        continue ;;
    esac
    if [ ! -f "$par/$n.rc" ]; then echo "$n: did not run (its build failed?)"; F=$((F + 1)); continue; fi
    cat "$par/$n.out" >> "$log"
    grep -E '^(FAIL|skipped)' "$par/$n.out" || true
    tally "$par/$n.out" "$n"
    rc=$(cat "$par/$n.rc")
    if [ "$rc" -ne 0 ] && ! grep -qE ' [1-9][0-9]* failed' "$par/$n.out"; then
        echo "$n exited with status $rc"; tail -n 30 "$par/$n.out"; F=$((F + 1))
    fi
done
# Each job's CPU seconds (user + system, its children included) and wall seconds, slowest first.
for t in "$par"/*.time; do
    [ -f "$t" ] || continue
    awk -v n="$(basename "$t" .time)" 'function s(t) { split(t, a, "m"); return a[1] * 60 + a[2] }
        NR == 2 { c = s($1) + s($2) } NR == 3 { printf "%.1f %d %s\n", c, $2 - $1, n }' "$t"
done | sort -rn > build/test/times.txt
echo "slowest (CPU s, wall s): $(head -n 8 build/test/times.txt | awk '{ printf "%s%s %s %s", (NR > 1 ? ", " : ""), $3, $1, $2 }')"
echo "(full output: $log; every job's times: build/test/times.txt)"
echo "$P passed, $F failed, $S skipped"
[ "$F" -eq 0 ]
