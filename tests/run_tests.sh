#!/bin/sh
# Runs the compile checks, every test binary given, and the CLI tests; sums their
# "<name>: N passed, N failed, N skipped" lines into one closing line.
set -u
P=0; F=0; S=0; crashed=0
log=build/test/last_run.log
: > "$log"
tally() { # reads the summary line of one program's output
    line=$(grep -E '^[A-Za-z0-9_./-]+: [0-9]+ passed, [0-9]+ failed, [0-9]+ skipped$' "$1" | tail -n 1)
    if [ -z "$line" ]; then echo "$2: no summary line (crashed?)"; crashed=$((crashed + 1)); F=$((F + 1)); return; fi
    echo "$line"
    p=$(echo "$line" | sed -E 's/.*: ([0-9]+) passed.*/\1/')
    f=$(echo "$line" | sed -E 's/.* ([0-9]+) failed.*/\1/')
    s=$(echo "$line" | sed -E 's/.* ([0-9]+) skipped$/\1/')
    P=$((P + p)); F=$((F + f)); S=$((S + s))
}
out=build/test/out.txt
make --no-print-directory check-header > "$out" 2>&1
cat "$out" >> "$log"; grep '^FAIL' "$out" || true
tally "$out" check_header
sh tests/check_compile.sh > "$out" 2>&1; rc=$?
cat "$out" >> "$log"; grep -v '^check_compile:' "$out" | grep -v ': ok$' || true
tally "$out" check_compile
# The programs and the two CLI scripts run two at a time (most are single-threaded, and the
# machine this targets has two cores), each into its own file under build/test/par; their
# results are then read back in the order given.
par=build/test/par
rm -rf "$par"; mkdir -p "$par"
printf '%s\0' "sh tests/test_cli.sh" "$@" "sh tests/readme_runs.sh" |
    xargs -0 -P 2 -I {} sh -c 'n=$(printf %s "$1" | tr " /." "___"); $1 > "$0/$n.out" 2>&1; echo $? > "$0/$n.rc"' "$par" {}
for t in "sh tests/test_cli.sh" "$@" "sh tests/readme_runs.sh"; do
    n=$(printf %s "$t" | tr " /." "___"); rc=$(cat "$par/$n.rc" 2>/dev/null || echo 1)
    case $t in "sh tests/test_cli.sh") name=test_cli ;; "sh tests/readme_runs.sh") name=readme_runs ;; *) name=$t ;; esac
    cat "$par/$n.out" >> "$log"
    grep -E '^(FAIL|skipped)' "$par/$n.out" || true
    tally "$par/$n.out" "$name"
    if [ "$rc" -ne 0 ] && ! grep -qE ' [1-9][0-9]* failed' "$par/$n.out"; then
        echo "$t exited with status $rc"; tail -n 30 "$par/$n.out"; F=$((F + 1))
    fi
done
echo "(full output: $log)"
echo "$P passed, $F failed, $S skipped"
[ "$F" -eq 0 ]
