// Runs studio/index.html?selftest=1 in headless Chromium through playwright-core and prints the
// page's "selftest: ..." line; exit 0 only for "selftest: ok". Serves studio/ itself (a worker
// and fetch() need http://). With --screenshots DIR it also draws a sketch of its own on the
// page, generates it and saves studio_drawing.png, studio_result.png, studio_3d.png and
// studio_page.png into DIR; with --exports DIR it saves the self-test's four exported files there;
// with --learn DEM it learns a style in the page (--learn-minutes M, default 0.5) and generates with it;
// --url BASE loads the page from another server (BASE ending in /).
//   NODE_PATH=build/pw/node_modules node studio/check.js [--chromium PATH] [--screenshots DIR] [--exports DIR] [--learn DEM] [--url BASE]
'use strict';
const http = require('http');
const fs = require('fs');
const path = require('path');
const { chromium } = require('playwright-core');

const args = process.argv.slice(2);
const opt = (name, dflt) => { const i = args.indexOf(name); return i >= 0 ? args[i + 1] : dflt; };
const root = path.resolve(__dirname);
const types = { '.html': 'text/html', '.js': 'text/javascript', '.wasm': 'application/wasm', '.json': 'application/json' };

const server = http.createServer((req, res) => {
    const rel = decodeURIComponent(req.url.split('?')[0]).replace(/^\/+/, '') || 'index.html';
    const file = path.join(root, rel);
    if (!file.startsWith(root) || !fs.existsSync(file) || fs.statSync(file).isDirectory()) { res.writeHead(404); res.end(); return; }
    res.writeHead(200, { 'Content-Type': types[path.extname(file)] || 'application/octet-stream' });
    fs.createReadStream(file).pipe(res);
});

async function main() {
    await new Promise((r) => server.listen(0, '127.0.0.1', r));
    // --url: the page from another server (e.g. python3 -m http.server -d studio), not our own
    const base = opt('--url', `http://127.0.0.1:${server.address().port}/`);
    const browser = await chromium.launch({
        executablePath: opt('--chromium', 'chromium'),
        args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist'],
    });
    let rc = 1;
    try {
        const page = await browser.newPage({ viewport: { width: 1480, height: 1000 } });
        page.on('console', (m) => { if (m.type() === 'error') console.log('console: ' + m.text()); });
        page.on('pageerror', (e) => console.log('pageerror: ' + e.message));
        await page.goto(base + 'index.html?selftest=1');
        await page.waitForSelector('body[data-selftest=done]', { timeout: 180000 });
        const line = (await page.textContent('#selftest')).trim();
        console.log(line);
        rc = line.startsWith('selftest: ok') ? 0 : 1;
        const exportDir = opt('--exports', null); // the self-test's exported files, to check natively
        if (exportDir) {
            fs.mkdirSync(exportDir, { recursive: true });
            const files = await page.evaluate(() => window.studioExports);
            for (const ext of Object.keys(files)) fs.writeFileSync(path.join(exportDir, 'selftest' + ext), Buffer.from(files[ext]));
        }
        const dir = opt('--screenshots', null);
        if (dir) {
            fs.mkdirSync(dir, { recursive: true });
            // a drawing of our own, with the mouse, in the default style
            await page.goto(base + 'index.html');
            await page.waitForFunction(() => /Draw ridges/.test(document.getElementById('status').textContent), null, { timeout: 60000 });
            const box = await page.locator('#draw').boundingBox();
            const stroke = async (tool, h0, h1, pts) => {
                await page.click('#tool-' + tool);
                await page.fill('#h0', String(h0));
                await page.fill('#h1', String(h1));
                await page.mouse.move(box.x + pts[0][0] * box.width, box.y + pts[0][1] * box.height);
                await page.mouse.down();
                for (const p of pts.slice(1)) await page.mouse.move(box.x + p[0] * box.width, box.y + p[1] * box.height, { steps: 8 });
                await page.mouse.up();
            };
            await stroke('ridge', 0.95, 0.55, [[0.2, 0.25], [0.35, 0.3], [0.5, 0.28], [0.65, 0.35], [0.8, 0.3]]);
            await stroke('ridge', 0.85, 0.45, [[0.5, 0.28], [0.48, 0.45], [0.52, 0.6]]);
            await stroke('valley', 0.35, 0.05, [[0.15, 0.55], [0.3, 0.62], [0.45, 0.75], [0.7, 0.72], [0.9, 0.85]]);
            await stroke('valley', 0.3, 0.15, [[0.75, 0.45], [0.72, 0.6], [0.7, 0.72]]);
            await page.locator('#draw').screenshot({ path: path.join(dir, 'studio_drawing.png') });
            fs.writeFileSync(path.join(dir, 'studio_drawing.tns'), await page.evaluate(() => toTns())); /* global toTns */
            await page.click('#generate');
            await page.waitForFunction(() => /in [0-9.]+ s \(WebAssembly/.test(document.getElementById('status').textContent), null, { timeout: 120000 });
            console.log('screenshots: ' + (await page.textContent('#status')).replace(/\n/g, '; '));
            await page.locator('#shade').screenshot({ path: path.join(dir, 'studio_result.png') });
            await page.locator('#view').screenshot({ path: path.join(dir, 'studio_3d.png') });
            await page.screenshot({ path: path.join(dir, 'studio_page.png') });
        }
        const learn = opt('--learn', null); // learn a style in the page from this DEM, then generate the test sketch with it
        if (learn) {
            await page.goto(base + 'index.html');
            await page.waitForFunction(() => /Draw ridges/.test(document.getElementById('status').textContent), null, { timeout: 60000 });
            await page.setInputFiles('#learn-dem', learn);
            await page.fill('#learn-minutes', opt('--learn-minutes', '0.5'));
            const t0 = Date.now();
            await page.click('#learn');
            await page.waitForFunction(() => /^learn(t)?:/.test(document.getElementById('status').textContent), null, { timeout: 900000 });
            console.log(`learn: ${((Date.now() - t0) / 1000).toFixed(1)} s: ` + (await page.textContent('#status')).replace(/\n/g, '; '));
            await page.setInputFiles('#load-sketch', path.join(root, 'styles', 'selftest_sketch.tns'));
            await page.waitForFunction(() => /strokes on/.test(document.getElementById('status').textContent), null, { timeout: 60000 });
            await page.click('#generate');
            await page.waitForFunction(() => /in [0-9.]+ s \(WebAssembly|^generate:/.test(document.getElementById('status').textContent), null, { timeout: 120000 });
            console.log('learnt style, generate: ' + (await page.textContent('#status')).replace(/\n/g, '; '));
            if (dir) await page.screenshot({ path: path.join(dir, 'studio_learnt.png') });
        }
    } finally {
        await browser.close();
        server.close();
    }
    return rc;
}
main().then((rc) => process.exit(rc), (e) => { console.log('selftest: FAIL ' + e.message); server.close(); process.exit(1); });
