#!/bin/sh
# The demo page in headless Chromium: every picture loads (the page's own report, read from the
# DOM) and shows in the screenshot (tests/check_demo_page.c). Also checks that a page with a
# missing picture and a flat grey one is caught. Run by tests/test_cli.sh on a fast demo (DEMO_FAST=1); by hand:
#   sh tests/demo_page.sh [DEMO_DIR]        (default demo/, e.g. after `make demo`)
# Prints "demo_page: N passed, N failed, N skipped"; exit status 1 on a failure.
set -u
DIR=${1:-demo}
W=build/test/demo_page
pass=0; fail=0; skip=0
say() { echo "demo_page: $pass passed, $fail failed, $skip skipped"; [ $fail -eq 0 ]; }
CHROME=""
for c in chromium chromium-browser google-chrome; do
    if command -v $c > /dev/null 2>&1; then CHROME=$c; break; fi
done
if [ -z "$CHROME" ]; then echo "skipped demo_page: no chromium (apt-get install chromium)"; skip=1; say; exit; fi
if [ ! -f "$DIR/index.html" ]; then echo "skipped demo_page: no $DIR/index.html (make demo)"; skip=1; say; exit; fi
rm -rf "$W"; mkdir -p "$W"
${CC:-cc} -std=c99 -O0 -DTN_IMPLEMENTATION_LINKED -I. tests/check_demo_page.c build/terrainnet.o -o "$W/check_demo_page" -lm -pthread || { echo "FAIL demo_page: build"; fail=1; say; exit; }

# chrome PAGE_DIR OUT_PREFIX: the DOM after load (OUT.dom) and a screenshot (OUT.png)
chrome() {
    url="file://$(cd "$1" && pwd)/index.html"
    flags="--headless --no-sandbox --disable-gpu --hide-scrollbars --force-device-scale-factor=1 --window-size=1440,2000
           --virtual-time-budget=10000 --user-data-dir=$W/profile --no-first-run --disable-extensions"
    # shellcheck disable=SC2086
    timeout 120 $CHROME $flags --dump-dom "$url" > "$2.dom" 2> "$2.err" &&
        timeout 120 $CHROME $flags --screenshot="$2.png" "$url" >> "$2.err" 2>&1 &&
        sed -n '/<pre id="demo-state"/,/<\/pre>/{ s/.*<pre[^>]*>//; s/<\/pre>.*//; p; }' "$2.dom" > "$2.txt"
}
check() { # name, page dir, expect pass (1) or fail (0)
    if chrome "$2" "$W/$1" && [ -s "$W/$1.png" ] && grep -q "^images: " "$W/$1.txt"; then
        "$W/check_demo_page" "$W/$1.png" "$W/$1.txt" > "$W/$1.out"; rc=$?
        if { [ "$3" = 1 ] && [ $rc -eq 0 ]; } || { [ "$3" = 0 ] && [ $rc -eq 1 ]; }; then pass=$((pass + 1));
        else echo "FAIL demo_page $1 (check exit $rc, wanted $3 = pass):"; cat "$W/$1.out"; fail=$((fail + 1)); fi
    else
        echo "FAIL demo_page $1: chromium gave no screenshot or DOM: $(tail -c 400 "$W/$1.err")"; fail=$((fail + 1))
    fi
}
check page "$DIR" 1
tail -n 1 "$W/page.out" 2>/dev/null
# the same page with its first picture gone and its second a flat grey must fail, naming both
mkdir -p "$W/broken"
cp "$DIR"/index.html "$DIR"/*.png "$W/broken/"
first=$(sed -n 's/.*<img src="\([^"]*\)".*/\1/p' "$DIR/index.html" | sed -n 1p)
second=$(sed -n 's/.*<img src="\([^"]*\)".*/\1/p' "$DIR/index.html" | sed -n 2p)
rm -f "$W/broken/$first"
{ printf 'P5 64 64 255\n'; head -c 4096 /dev/zero | tr '\000' '\200'; } > "$W/flat.pgm"
bin/terrainnet convert "$W/flat.pgm" "$W/broken/$second" > /dev/null 2>&1 || echo "FAIL demo_page: no flat picture"
check broken "$W/broken" 0
if grep -q "picture 1 did not load" "$W/broken.out" 2>/dev/null && grep -q "picture 2 shows no image" "$W/broken.out"; then pass=$((pass + 1));
else echo "FAIL demo_page: the missing $first or the flat $second was not named: $(cat "$W/broken.out" 2>/dev/null)"; fail=$((fail + 1)); fi
say
