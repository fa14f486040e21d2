#!/bin/sh
# `make studio-check`: the studio's self-test (index.html?selftest=1) in headless Chromium.
# Needs chromium and playwright-core (npm install --prefix build/pw playwright-core); says which
# is missing and fails. Prints the page's line: "selftest: ok ms=T maxdiff=D ...".
set -u
cd "$(dirname "$0")/.."
CHROME=""
for c in chromium chromium-browser google-chrome; do
    if command -v $c > /dev/null 2>&1; then CHROME=$(command -v $c); break; fi
done
[ -n "$CHROME" ] || { echo "studio-check: no chromium (Debian: apt-get install chromium)"; exit 1; }
command -v node > /dev/null 2>&1 || { echo "studio-check: no node (Debian: apt-get install nodejs)"; exit 1; }
[ -d build/pw/node_modules/playwright-core ] ||
    { echo "studio-check: no playwright-core (npm install --prefix build/pw playwright-core)"; exit 1; }
[ -f studio/terrainnet.wasm ] && [ -f studio/styles/selftest.json ] || { echo "studio-check: run make studio first"; exit 1; }
NODE_PATH=build/pw/node_modules timeout 300 node studio/check.js --chromium "$CHROME" "$@"
rc=$?
[ $rc -eq 0 ] || echo "studio-check: FAIL (if generation changed on purpose, remake the native reference: REFERENCE_ONLY=1 sh studio/make_styles.sh, then make studio)"
exit $rc
