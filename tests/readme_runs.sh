#!/bin/sh
# The README's quick start runs as written (issue 34 item 1): every command line of its "Quick
# start" section, in order, extracted from README.md itself (indented blocks that start with
# bin/terrainnet, printf, cat > or gdalinfo; a heredoc runs as one command), with D set to the
# shared data and every training budget cut by TERRAINNET_TRAIN_SECONDS. The lines run in a scratch
# directory that sees the repository's bin/ and examples/, so their outputs stay out of the tree.
# A line whose program is not installed (gdalinfo) is skipped. Prints each line's status and time;
# ends with "readme_runs: N passed, N failed, N skipped".
set -u
top=$(pwd)
data=${TN_SHARED_DATA:-../shared/data}
W=build/test/readme
pass=0; fail=0; skip=0
if [ ! -x bin/terrainnet ] || [ ! -f README.md ]; then echo "FAIL readme_runs: run from the repository root after make"; exit 1; fi
if [ ! -d "$data/dem" ]; then
    echo "skipped readme_runs: no shared data at $data"
    echo "readme_runs: 0 passed, 0 failed, 1 skipped"
    exit 0
fi
D=$(cd "$data" && pwd)
rm -rf "$W"; mkdir -p "$W/cmd"
ln -s "$top/bin" "$W/bin"
ln -s "$top/examples" "$W/examples"

# one file per command: cmd/NNN.sh
awk -v dir="$W/cmd" '
    /^## / { inq = ($0 ~ /^## Quick start/) ; next }
    !inq { next }
    /^```/ { fence = !fence; next }
    fence { next }
    heredoc { print substr($0, 5) >> file; if (substr($0, 5) == stop) { heredoc = 0; close(file) } ; next }
    /^    (bin\/terrainnet|printf|cat >|gdalinfo) / {
        line = substr($0, 5); n++; file = sprintf("%s/%03d.sh", dir, n)
        print line > file
        if (match(line, /<<.?[A-Z]+/)) { stop = substr(line, RSTART + 2, RLENGTH - 2); gsub(/[^A-Z]/, "", stop); heredoc = 1 }
        else close(file)
    }' README.md

count=$(ls "$W/cmd" | wc -l)
if [ "$count" -lt 20 ]; then echo "FAIL readme_runs: only $count command lines found in README.md's quick start"; fail=$((fail + 1)); fi
for f in "$W"/cmd/*.sh; do
    first=$(head -n 1 "$f")
    prog=${first%% *}
    if ! command -v "$prog" >/dev/null 2>&1 && [ ! -x "$W/$prog" ]; then
        printf "skipped readme_runs: %s (%s is not installed)\n" "$first" "$prog"; skip=$((skip + 1)); continue
    fi
    t0=$(date +%s)
    (cd "$W" && D="$D" TERRAINNET_TRAIN_SECONDS=${TERRAINNET_TRAIN_SECONDS:-4} sh -e "cmd/$(basename "$f")") > "$f.out" 2>&1
    rc=$?
    t1=$(date +%s)
    if [ $rc -eq 0 ]; then
        printf "ok (%s s): %s\n" "$((t1 - t0))" "$first"; pass=$((pass + 1))
    else
        printf "FAIL readme_runs (exit %s, %s s): %s\n" "$rc" "$((t1 - t0))" "$first"; tail -n 5 "$f.out"; fail=$((fail + 1))
    fi
done
echo "readme_runs: $pass passed, $fail failed, $skip skipped"
[ "$fail" -eq 0 ]
